//! The plate guard: a Kalman observer of the device's thermal model ([`PlateObserver`]) that runs on every channel,
//! whatever its controller, and gives the safety envelope the estimate and one-tick forecast of the true plate
//! ([`PlateForecast`]). It is the envelope's own model, separate from any controller's, so a controller that
//! misjudges the plate (the paper's PID on a lagging sensor) cannot take the envelope's view with it.
//!
//! Per tick, before the drive is gated: the observer is updated over the interval since the previous tick with the
//! current the envelope let through then, the display's finger model, and both readings; the forecast then predicts
//! the plate at the end of the coming tick for any current ([`PlateObserver::predict_plate_c`]).

use thermode_control::{Finger, ObserverTick, PlantModel, PlateObserver};
use thermode_device::Reading;
use thermode_safety::{PlateForecast, PlateNow};

use crate::error::PipelineError;

/// The envelope's model of one channel's plate.
#[derive(Debug, Clone)]
pub struct PlateGuard {
    observer: PlateObserver,
    /// Time of the previous update \[s\] (`None` before the first).
    last_time_s: Option<f64>,
}

/// The plate guard's forecast over one tick.
#[derive(Debug, Clone, Copy)]
pub struct TickForecast<'a> {
    observer: &'a PlateObserver,
    /// Length of the tick \[s\].
    dt_s: f64,
    /// The finger model on the plate.
    finger: Finger,
}

impl PlateGuard {
    /// A guard of the display described by `plant` (validated), with no estimate yet.
    pub fn new(plant: PlantModel) -> Result<Self, PipelineError> {
        Ok(PlateGuard {
            observer: PlateObserver::new(plant)?,
            last_time_s: None,
        })
    }

    /// Updates the estimate at `now_s` \[s\] with `reading`, after `applied_current_a` \[A\] was applied since the
    /// previous update and with `finger` on the plate. A reading the observer refuses (non-finite numbers, time
    /// not moving forward) leaves the estimate as it was: the envelope latches its own fault on such a reading.
    pub fn update(&mut self, now_s: f64, reading: &Reading, applied_current_a: f64, finger: Finger) {
        let tick = ObserverTick {
            // The first update only initialises the estimate from the readings; its dt is not used.
            dt_s: self.last_time_s.map_or(1.0, |t| now_s - t),
            applied_current_a,
            finger,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
        };
        if self.observer.update(&tick).is_ok() {
            self.last_time_s = Some(now_s);
        }
    }

    /// The estimated true plate \[°C\] (NaN before the first reading).
    pub fn plate_estimate_c(&self) -> f64 {
        self.observer.estimate().map_or(f64::NAN, |e| e.plate_c)
    }

    /// The forecast over a tick of `dt_s` \[s\] with `finger` on the plate.
    pub fn forecast(&self, dt_s: f64, finger: Finger) -> TickForecast<'_> {
        TickForecast {
            observer: &self.observer,
            dt_s,
            finger,
        }
    }
}

impl PlateForecast for TickForecast<'_> {
    fn now(&self) -> Option<PlateNow> {
        self.observer.estimate().map(|e| PlateNow {
            plate_c: e.plate_c,
            sd_c: e.plate_sd_c,
        })
    }

    fn plate_after_c(&self, current_a: f64) -> f64 {
        self.observer
            .predict_plate_c(self.dt_s, current_a, self.finger)
            .unwrap_or(f64::NAN)
    }

    fn strongest_cooling_a(&self) -> f64 {
        let plate_c = self.observer.estimate().map_or(f64::NAN, |e| e.plate_c);
        self.observer.plant().most_useful_cooling_a(plate_c)
    }
}
