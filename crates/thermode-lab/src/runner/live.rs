//! The lab on a real display: [`LiveStimulus`] presents each trial on a running display through a [`DisplayLink`]
//! (the daemon's WebSocket API, [`super::ws_link`]) and measures the finger on it.
//!
//! **The finger temperature is measured on the display**, at rest, before and after each trial: the finger rests on
//! the plate while the display renders air, and the runner averages the telemetry's `finger_c` — the plate's heat
//! balance: the controller's finger model plus the heat the real finger gives the plate beyond the model's (the
//! observer's unknown heat) over the receptor-to-plate conductance (`thermode_pipeline::Telemetry::finger_c`) —
//! over a window of [`LiveSettings::window_s`]. The measurement is taken once [`SETTLE_WINDOWS`] consecutive windows
//! agree within [`LiveSettings::settled_c`] (after at least [`LiveSettings::min_rest_s`]), or at
//! [`LiveSettings::max_rest_s`] with a note that it had not settled. Four windows, not two: a finger still
//! recovering from a cold touch at 0.01 °C/s changes by only 0.01 °C between two 1 s windows, which two windows
//! would call settled; over four (3 s apart) it changes by 0.03 °C. A display whose controller has no observer (pid) or that does not publish
//! `finger_c` cannot measure the finger: the run stops with an error that says so.
//!
//! **A simulated trial** is a `touch` of the material on the channel for the presentation time, every telemetry
//! sample of the channel kept as the trial's curve ([`TrialTrace`]: time since the touch, the daemon's loop time,
//! target, skin model, finger, sensor, set-point, current), then a `release`. **A real trial** leaves the display on
//! air while the finger touches the real sample (the display cannot measure a finger that is not on it): its curve
//! is the display's rest, for the record. Markers (`trial N start …`, `trial N end`) go to the daemon's marker
//! stream (LSL with `serve --lsl`). A fault, a refused command or a silent link ends the trial with an error; the
//! runner keeps the completed trials and the same command resumes.

use serde_json::json;
use thermode_model::materials::Material;
use thermode_model::params::BadValue;

use super::stimulus::{SkinCurve, Stimulus, StimulusError, StimulusRequest, TrialMeasurement};
pub use super::trace::{DisplaySample, TrialTrace, TRACE_COLUMNS};
use crate::design::Condition;

/// A running display, one channel of it: what [`LiveStimulus`] needs.
pub trait DisplayLink {
    /// Touches `material` (at room temperature, 23 °C) on the channel; returns the loop time of the touch \[s\].
    fn touch(&mut self, material: &Material) -> Result<f64, StimulusError>;
    /// Releases the channel (the display renders air); returns the loop time \[s\].
    fn release(&mut self) -> Result<f64, StimulusError>;
    /// Sends an event marker (the daemon's marker stream); returns the LSL clock minus the loop clock at the
    /// marker \[s\] when the daemon publishes LSL (`serve --lsl`), else `None`.
    fn marker(&mut self, text: &str) -> Result<Option<f64>, StimulusError>;
    /// The channel's next telemetry sample (blocks until it comes; an error when the link is silent).
    fn next_sample(&mut self) -> Result<DisplaySample, StimulusError>;
    /// What the display is, for the session sidecar.
    fn describe(&self) -> serde_json::Value;
}

/// How the finger is measured at rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveSettings {
    /// Averaging window of one measurement \[s\]. Default 1.
    pub window_s: f64,
    /// [`SETTLE_WINDOWS`] consecutive windows within this of each other count as settled \[°C\]. Default 0.02 (a
    /// finger recovering from a cold touch changes by more).
    pub settled_c: f64,
    /// Shortest rest before a measurement \[s\] (the plate and the finger come to terms). Default 3.
    pub min_rest_s: f64,
    /// Longest rest: the measurement is then taken as it stands and noted as unsettled \[s\]. Default 30.
    pub max_rest_s: f64,
}

impl Default for LiveSettings {
    fn default() -> Self {
        LiveSettings {
            window_s: 1.0,
            settled_c: 0.02,
            min_rest_s: 3.0,
            max_rest_s: 30.0,
        }
    }
}

/// Consecutive windows whose means must agree within [`LiveSettings::settled_c`] for a rest to count as settled: 4
/// (the first and the last 3 windows apart).
pub const SETTLE_WINDOWS: usize = 4;

/// A finger temperature measured at rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestMeasurement {
    /// The mean `finger_c` of the last window \[°C\].
    pub finger_c: f64,
    /// Whether two consecutive windows agreed before the longest rest.
    pub settled: bool,
    /// How long the rest took \[s\].
    pub rest_s: f64,
}

/// Presents trials on a running display and measures the finger on it (see the module documentation).
pub struct LiveStimulus<L: DisplayLink> {
    link: L,
    settings: LiveSettings,
    /// With a simulated participant: the model of real contact that stands for what it feels in a real trial (a
    /// simulated participant cannot touch the sample); used for its answer only, never written as measured.
    real_contact: Option<super::stimulus::FvContact>,
    /// Rests that had not settled, as notes for the operator.
    pub notes: Vec<String>,
    /// Told of a rest measurement as it goes (see [`LiveStimulus::with_rest_progress`]).
    rest_progress: Option<Box<RestProgress>>,
}

/// A listener to rest measurements: `Some(rest_s)` (seconds rested so far, at most
/// [`LiveSettings::max_rest_s`]) after every window, `None` when the measurement is done.
pub type RestProgress = dyn FnMut(Option<f64>);

impl<L: DisplayLink> LiveStimulus<L> {
    /// A live stimulus over `link`.
    pub fn new(link: L, settings: LiveSettings) -> Result<Self, StimulusError> {
        let s = &settings;
        let ok = [s.window_s, s.settled_c, s.min_rest_s, s.max_rest_s]
            .iter()
            .all(|v| v.is_finite() && *v > 0.0)
            && s.min_rest_s <= s.max_rest_s
            && 2.0 * s.window_s <= s.max_rest_s;
        if !ok {
            let requirement =
                "windows, tolerance and rests must be positive, min_rest_s ≤ max_rest_s, 2 windows ≤ max_rest_s";
            return Err(BadValue::custom("live settings", s.window_s, requirement).into());
        }
        Ok(LiveStimulus {
            link,
            settings,
            real_contact: None,
            notes: Vec::new(),
            rest_progress: None,
        })
    }

    /// Tells `listener` how each rest measurement goes (a progress bar on the operator's terminal: a rest can take
    /// up to [`LiveSettings::max_rest_s`] twice per trial).
    pub fn with_rest_progress(mut self, listener: impl FnMut(Option<f64>) + 'static) -> Self {
        self.rest_progress = Some(Box::new(listener));
        self
    }

    fn tell_rest(&mut self, rest_s: Option<f64>) {
        if let Some(listener) = &mut self.rest_progress {
            listener(rest_s);
        }
    }

    /// For a simulated participant: real trials get the skin curve of `contact` (real contact under the fv model,
    /// from the finger's measured start) as what the participant feels; the finger temperatures stay measured.
    pub fn with_modelled_real_contact(mut self, contact: super::stimulus::FvContact) -> Self {
        self.real_contact = Some(contact);
        self
    }

    /// The display and the measurement, for the session sidecar.
    pub fn describe(&self) -> serde_json::Value {
        json!({
            "stimulus": "LiveStimulus",
            "display": self.link.describe(),
            "finger_measurement": "finger_c (plate heat balance) averaged at rest on the display rendering air",
            "window_s": self.settings.window_s,
            "settled_c": self.settings.settled_c,
            "min_rest_s": self.settings.min_rest_s,
            "max_rest_s": self.settings.max_rest_s,
        })
    }

    /// The next sample, refused when the display has faulted.
    fn sample(&mut self) -> Result<DisplaySample, StimulusError> {
        let sample = self.link.next_sample()?;
        if sample.fault != 0 {
            return Err(StimulusError::Device(format!(
                "the display faulted (code {}; docs/api.md): the drive is off; clear the fault on the daemon, then \
                 run the same command to resume",
                sample.fault
            )));
        }
        Ok(sample)
    }

    /// Releases the channel and measures the resting finger.
    pub fn measure_at_rest(&mut self) -> Result<RestMeasurement, StimulusError> {
        let released_s = self.link.release()?;
        // Telemetry from before the release (it may have arrived while the reply was awaited) is not the rest.
        let mut first = self.sample()?;
        while first.loop_time_s < released_s {
            first = self.sample()?;
        }
        let start_s = first.loop_time_s;
        let (mut recent, mut window): (Vec<f64>, Vec<f64>) = (Vec::with_capacity(SETTLE_WINDOWS), Vec::new());
        let (mut window_start_s, mut last_finite_s) = (start_s, start_s);
        loop {
            let sample = self.sample()?;
            let now_s = sample.loop_time_s;
            if sample.contact {
                return Err(StimulusError::Device(
                    "the channel was touched while the finger rested on it (another client?): the finger cannot be \
                     measured; the trial is not recorded"
                        .into(),
                ));
            }
            if !sample.finger_c.is_finite() {
                if now_s - last_finite_s > 2.0 * self.settings.window_s {
                    return Err(StimulusError::Device(
                        "the display does not measure the finger (no `finger_c` in its telemetry): the lab on a \
                         real display needs the model controller (`serve --controller model`, the default)"
                            .into(),
                    ));
                }
                continue;
            }
            last_finite_s = now_s;
            window.push(sample.finger_c);
            if now_s - window_start_s < self.settings.window_s {
                continue;
            }
            let mean_c = window.iter().sum::<f64>() / window.len() as f64;
            let rest_s = now_s - start_s;
            if recent.len() == SETTLE_WINDOWS {
                recent.remove(0);
            }
            recent.push(mean_c);
            let spread_c = recent.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b))
                - recent.iter().fold(f64::INFINITY, |a, &b| a.min(b));
            let settled = recent.len() == SETTLE_WINDOWS && spread_c <= self.settings.settled_c;
            self.tell_rest(Some(rest_s.min(self.settings.max_rest_s)));
            if (settled && rest_s >= self.settings.min_rest_s) || rest_s >= self.settings.max_rest_s {
                self.tell_rest(None);
                return Ok(RestMeasurement {
                    finger_c: mean_c,
                    settled,
                    rest_s,
                });
            }
            window.clear();
            window_start_s = now_s;
        }
    }

    /// Records the channel for `duration_s` of loop time from `start_s`.
    fn trace(&mut self, request: &StimulusRequest, start_s: f64) -> Result<TrialTrace, StimulusError> {
        let contact = request.condition == Condition::Simulated;
        let mut trace = TrialTrace {
            trial: request.trial,
            condition: request.condition,
            material: request.material.name.clone(),
            time_s: Vec::new(),
            samples: Vec::new(),
            contact,
            lsl_minus_loop_s: None,
        };
        let duration_s = request.duration_s;
        loop {
            let sample = self.sample()?;
            let t_s = sample.loop_time_s - start_s;
            // Before the touch, or the same tick again (a subscriber gets the newest snapshot at its rate: a late
            // loop publishes one tick twice).
            if t_s < 0.0 || trace.time_s.last().is_some_and(|&last| t_s <= last) {
                continue;
            }
            if sample.contact != contact {
                return Err(StimulusError::Device(format!(
                    "trial {}: the channel {} at {t_s:.2} s of the presentation (a stop all, another client or the \
                     dose limit); the trial is not recorded; run the same command to repeat it",
                    request.trial,
                    if contact { "left the touch" } else { "was touched" }
                )));
            }
            trace.time_s.push(t_s);
            trace.samples.push(sample);
            if t_s >= duration_s {
                return Ok(trace);
            }
        }
    }

    fn note_unsettled(&mut self, what: &str, trial: usize, rest: &RestMeasurement) {
        if !rest.settled {
            self.notes.push(format!(
                "trial {trial}: the finger {what} had not settled after {:.0} s; measured {:.2} °C as it stood",
                rest.rest_s, rest.finger_c
            ));
        }
    }
}

impl<L: DisplayLink> Stimulus for LiveStimulus<L> {
    fn present(&mut self, request: &StimulusRequest) -> Result<TrialMeasurement, StimulusError> {
        let trial = request.trial;
        let before = self.measure_at_rest()?;
        self.note_unsettled("before", trial, &before);
        let name = &request.material.name;
        let condition = request.condition.name();
        let lsl_minus_loop_s = self.link.marker(&format!("trial {trial} start {condition} {name}"))?;
        let mut trace = match request.condition {
            Condition::Simulated => {
                let touch_s = self.link.touch(request.material)?;
                let trace = self.trace(request, touch_s);
                let released = self.link.release();
                let trace = trace?;
                released?;
                trace
            }
            Condition::Real => {
                let start_s = self.sample()?.loop_time_s;
                self.trace(request, start_s)?
            }
        };
        trace.lsl_minus_loop_s = lsl_minus_loop_s;
        self.link.marker(&format!("trial {trial} end"))?;
        let after = self.measure_at_rest()?;
        self.note_unsettled("after", trial, &after);
        let curve = match request.condition {
            // What the simulated participant feels: the measured finger, its time from the first sample.
            Condition::Simulated => {
                let measured = trace
                    .time_s
                    .iter()
                    .zip(&trace.samples)
                    .filter(|(_, s)| s.finger_c.is_finite());
                let (time_s, skin_c): (Vec<f64>, Vec<f64>) = measured.map(|(t, s)| (*t, s.finger_c)).unzip();
                let first_s = time_s.first().copied().unwrap_or(0.0);
                let curve = SkinCurve {
                    time_s: time_s.iter().map(|t| t - first_s).collect(),
                    skin_c,
                };
                curve.validate()?;
                Some(curve)
            }
            Condition::Real => match &self.real_contact {
                Some(contact) => Some(contact.curve(request.material, Some(before.finger_c), request.duration_s)?),
                None => None,
            },
        };
        Ok(TrialMeasurement {
            finger_start_c: before.finger_c,
            finger_end_c: after.finger_c,
            curve,
            measured: true,
            trace: Some(trace),
        })
    }

    fn finger_at_rest(&mut self) -> Option<Result<(f64, f64), StimulusError>> {
        Some(self.measure_at_rest().map(|rest| (rest.finger_c, rest.rest_s)))
    }

    fn take_notes(&mut self) -> Vec<String> {
        std::mem::take(&mut self.notes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_model::materials::find;

    /// A display whose finger relaxes exponentially to `rest_c` at rest and follows `contact_c` in contact.
    struct FakeDisplay {
        time_s: f64,
        finger_c: f64,
        rest_c: f64,
        contact: bool,
        markers: Vec<String>,
        fault_at_s: Option<f64>,
        interrupt_at_s: Option<f64>,
        /// Publishes no `finger_c` (a pid display).
        blind: bool,
    }

    impl DisplayLink for FakeDisplay {
        fn touch(&mut self, _material: &Material) -> Result<f64, StimulusError> {
            self.contact = true;
            Ok(self.time_s)
        }
        fn release(&mut self) -> Result<f64, StimulusError> {
            self.contact = false;
            Ok(self.time_s)
        }
        fn marker(&mut self, text: &str) -> Result<Option<f64>, StimulusError> {
            self.markers.push(text.to_string());
            Ok(Some(1000.0))
        }
        fn next_sample(&mut self) -> Result<DisplaySample, StimulusError> {
            self.time_s += 0.01;
            let goal_c = if self.contact { 25.0 } else { self.rest_c };
            self.finger_c += (goal_c - self.finger_c) * 0.01 / 2.0;
            let fault = self.fault_at_s.is_some_and(|t| self.time_s >= t);
            Ok(DisplaySample {
                loop_time_s: self.time_s,
                target_skin_c: f64::NAN,
                skin_c: self.finger_c,
                finger_c: if self.blind { f64::NAN } else { self.finger_c },
                sensor_c: self.finger_c,
                display_setpoint_c: self.finger_c,
                current_a: 0.0,
                fault: if fault { 104 } else { 0 },
                contact: self.contact && self.time_s < self.interrupt_at_s.unwrap_or(f64::INFINITY),
            })
        }
        fn describe(&self) -> serde_json::Value {
            json!("fake")
        }
    }

    fn fake(finger_c: f64) -> FakeDisplay {
        FakeDisplay {
            time_s: 0.0,
            finger_c,
            rest_c: 32.0,
            contact: false,
            markers: Vec::new(),
            fault_at_s: None,
            interrupt_at_s: None,
            blind: false,
        }
    }

    fn request(material: &Material, condition: Condition) -> StimulusRequest<'_> {
        StimulusRequest {
            material,
            condition,
            duration_s: 5.0,
            participant_index: 0,
            trial: 3,
        }
    }

    #[test]
    fn the_rest_settles_on_the_fingers_own_temperature() {
        let mut live = LiveStimulus::new(fake(30.0), LiveSettings::default()).expect("settings");
        let rest = live.measure_at_rest().expect("measured");
        // τ = 2 s: two 1 s windows agree within 0.05 °C once the remaining gap is below about 0.1 °C.
        assert!(rest.settled, "{rest:?}");
        assert!(
            (rest.finger_c - 32.0).abs() < 0.15,
            "measured {} vs 32 °C",
            rest.finger_c
        );
        let slow = FakeDisplay {
            rest_c: 40.0,
            ..fake(20.0)
        };
        let settings = LiveSettings {
            max_rest_s: 4.0,
            ..LiveSettings::default()
        };
        let mut live = LiveStimulus::new(slow, settings).expect("settings");
        let rest = live.measure_at_rest().expect("measured");
        assert!(!rest.settled && rest.rest_s >= 4.0, "{rest:?}");
    }

    /// A finger at rest that still recovers at a steady `rate_c_per_s` (a slow finger after a cold touch).
    struct RecoveringFinger {
        time_s: f64,
        finger_c: f64,
        rate_c_per_s: f64,
    }

    impl DisplayLink for RecoveringFinger {
        fn touch(&mut self, _material: &Material) -> Result<f64, StimulusError> {
            Ok(self.time_s)
        }
        fn release(&mut self) -> Result<f64, StimulusError> {
            Ok(self.time_s)
        }
        fn marker(&mut self, _text: &str) -> Result<Option<f64>, StimulusError> {
            Ok(None)
        }
        fn next_sample(&mut self) -> Result<DisplaySample, StimulusError> {
            self.time_s += 0.01;
            self.finger_c += self.rate_c_per_s * 0.01;
            let mut sample = fake(self.finger_c).next_sample()?;
            (sample.loop_time_s, sample.finger_c) = (self.time_s, self.finger_c);
            Ok(sample)
        }
        fn describe(&self) -> serde_json::Value {
            json!("recovering")
        }
    }

    #[test]
    fn a_finger_still_recovering_at_a_hundredth_of_a_degree_per_second_has_not_settled() {
        // Two 1 s windows differ by 0.01 °C (within 0.02: "settled" by a two-window rule, 30.72 against 32.13 °C);
        // four windows 3 s apart differ by 0.03 °C.
        let finger = RecoveringFinger {
            time_s: 0.0,
            finger_c: 30.72,
            rate_c_per_s: 0.01,
        };
        let mut live = LiveStimulus::new(finger, LiveSettings::default()).expect("settings");
        let rest = live.measure_at_rest().expect("measured");
        assert!(!rest.settled, "a recovering finger called settled: {rest:?}");
        assert!(rest.rest_s >= LiveSettings::default().max_rest_s, "{rest:?}");
        // At 0.005 °C/s the four windows agree within 0.015 °C: settled after the shortest rest.
        let slow = RecoveringFinger {
            time_s: 0.0,
            finger_c: 31.9,
            rate_c_per_s: 0.005,
        };
        let rest = LiveStimulus::new(slow, LiveSettings::default())
            .expect("settings")
            .measure_at_rest()
            .expect("measured");
        assert!(rest.settled && rest.rest_s < 5.0, "{rest:?}");
    }

    #[test]
    fn a_rest_measurement_reports_its_progress_and_its_end() {
        let told = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
        let sink = std::rc::Rc::clone(&told);
        let mut live = LiveStimulus::new(fake(30.0), LiveSettings::default())
            .expect("settings")
            .with_rest_progress(move |rest_s| sink.borrow_mut().push(rest_s));
        let rest = live.measure_at_rest().expect("measured");
        let told = told.borrow();
        let (last, rests) = told.split_last().expect("told at least once");
        assert_eq!(*last, None, "the end is told: {told:?}");
        let rests: Vec<f64> = rests.iter().map(|r| r.expect("a rest before the end")).collect();
        assert!(rests.len() >= 2 && rests.windows(2).all(|w| w[0] < w[1]), "{rests:?}");
        assert!(
            (rests[rests.len() - 1] - rest.rest_s).abs() < 1e-12,
            "{rests:?} vs {rest:?}"
        );
        assert!(
            rests
                .iter()
                .all(|&r| r > 0.0 && r <= LiveSettings::default().max_rest_s),
            "{rests:?}"
        );
    }

    #[test]
    fn a_simulated_trial_is_traced_from_the_touch_and_marked() {
        let aluminium = find("aluminium").expect("library");
        let mut live = LiveStimulus::new(fake(32.0), LiveSettings::default()).expect("settings");
        let m = live
            .present(&request(&aluminium, Condition::Simulated))
            .expect("presented");
        let trace = m.trace.expect("a trace");
        assert!(trace.contact && trace.time_s[0] >= 0.0 && *trace.time_s.last().expect("rows") >= 5.0);
        assert!(
            m.finger_start_c > 31.9 && m.finger_end_c > 31.0,
            "{} {}",
            m.finger_start_c,
            m.finger_end_c
        );
        let curve = m.curve.expect("the finger's curve");
        assert!(
            curve.skin_c.last().copied().unwrap_or(f64::NAN) < 28.0,
            "the finger cooled in contact"
        );
        assert_eq!(live.link.markers, ["trial 3 start simulated aluminium", "trial 3 end"]);
        let csv = trace.to_csv();
        assert!(
            csv.starts_with("trial,condition,material,time_s,loop_time_s,lsl_time_s,target_skin_c,"),
            "{csv}"
        );
        assert!(
            csv.lines()
                .nth(1)
                // The first sample after the rest: four 1 s windows of the fake's 0.01 s steps (SETTLE_WINDOWS; two
                // windows put it at 3.03 s).
                .is_some_and(|l| l.starts_with("3,simulated,aluminium,0.01,4.039999999999958,1004.04,")),
            "{csv}"
        );
        assert_eq!(csv.lines().count(), trace.time_s.len() + 1);
        assert!(
            csv.lines()
                .nth(1)
                .is_some_and(|l| l.contains(",,") && l.ends_with(",true")),
            "{csv}"
        );
    }

    #[test]
    fn a_real_trial_leaves_the_display_on_air_and_a_fault_stops_the_trial() {
        let wood = find("wood").expect("library");
        let mut live = LiveStimulus::new(fake(32.0), LiveSettings::default()).expect("settings");
        let m = live.present(&request(&wood, Condition::Real)).expect("presented");
        assert!(m.curve.is_none() && !m.trace.expect("a trace").contact);
        let faulty = FakeDisplay {
            fault_at_s: Some(2.0),
            ..fake(32.0)
        };
        let mut live = LiveStimulus::new(faulty, LiveSettings::default()).expect("settings");
        let error = live
            .present(&request(&wood, Condition::Simulated))
            .expect_err("faulted");
        assert!(error.to_string().contains("code 104"), "{error}");
        let stopped = FakeDisplay {
            interrupt_at_s: Some(6.0),
            ..fake(32.0)
        };
        let mut live = LiveStimulus::new(stopped, LiveSettings::default()).expect("settings");
        let error = live
            .present(&request(&wood, Condition::Simulated))
            .expect_err("interrupted");
        assert!(error.to_string().contains("left the touch"), "{error}");
    }

    #[test]
    fn a_display_without_a_finger_measurement_is_refused() {
        let blind = FakeDisplay {
            blind: true,
            ..fake(32.0)
        };
        let mut live = LiveStimulus::new(blind, LiveSettings::default()).expect("settings");
        let error = live.measure_at_rest().expect_err("refused");
        assert!(error.to_string().contains("model controller"), "{error}");
    }
}
