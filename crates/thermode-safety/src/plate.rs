//! What the envelope needs to know about the true plate to keep it inside the display limits: an estimate of the
//! plate now and a one-interval prediction of it at any drive current ([`PlateForecast`]).
//!
//! The PT-100 lags the plate (0.3 s on the default display, 1.5 s on a poorly bonded one), so an envelope that
//! acts on the reading alone lets a fast controller heat the plate past 48 °C before the reading gets there. With
//! a forecast, [`crate::SafetyEnvelope::gate_drive`] limits the drive so that the plate predicted at the end of the
//! interval the command is held stays within `[min + margin, effective max − margin]`, where the margin grows with
//! the estimate's uncertainty ([`plate_margin_c`]). The forecast comes from a model of the display (the pipeline
//! runs a Kalman observer of the device's thermal model on every channel, whatever its controller); this crate
//! only defines what it must answer, so the envelope stays free of any plant model.

/// The plate as a model estimates it now. Temperatures in °C.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateNow {
    /// Estimated true plate temperature, °C.
    pub plate_c: f64,
    /// Standard deviation of that estimate, °C (≥ 0).
    pub sd_c: f64,
}

/// A model of the plate for the interval the next drive command is held.
pub trait PlateForecast {
    /// The plate now (`None` while the model has no estimate yet: the envelope then acts on the reading alone).
    fn now(&self) -> Option<PlateNow>;

    /// The plate at the end of the interval the next command is held, if `current_a` \[A\] (positive heats) is
    /// applied over it, °C.
    fn plate_after_c(&self, current_a: f64) -> f64;

    /// The lowest and highest plate the forecast allows at the end of that interval, °C: the envelope keeps the
    /// lowest above its minimum and the highest below its maximum. Default: [`PlateForecast::plate_after_c`] for
    /// both (a forecast that knows no error of its own).
    fn plate_after_range_c(&self, current_a: f64) -> (f64, f64) {
        let plate_c = self.plate_after_c(current_a);
        (plate_c, plate_c)
    }

    /// The strongest cooling current worth applying, A (≤ 0): between it and the drive limit
    /// [`PlateForecast::plate_after_c`] increases with the current (more cooling current than this only adds
    /// Joule heat).
    fn strongest_cooling_a(&self) -> f64;
}

/// No model: the envelope acts on the measured display alone (test engines, tools without a device model).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MeasuredOnly;

impl PlateForecast for MeasuredOnly {
    fn now(&self) -> Option<PlateNow> {
        None
    }

    fn plate_after_c(&self, _current_a: f64) -> f64 {
        f64::NAN
    }

    fn strongest_cooling_a(&self) -> f64 {
        0.0
    }
}

/// Standard deviations of the plate estimate kept between the predicted plate and a display limit: 2 (a plate
/// estimate within 2σ of the truth 97.7 % of the time, on one side).
pub const PLATE_MARGIN_SDS: f64 = 2.0;
/// Smallest margin between the predicted plate and a display limit \[°C\]: 0.3. The estimate's standard deviation
/// covers noise, not the model's bias: the finger on a real display is not the finger model, and a lagging sensor
/// reveals the difference only slowly. Across the judged displays, controllers and materials (see
/// `docs/security.md`) the estimate was off by at most 0.28 °C in the direction of a limit while the plate was
/// within 1 °C of it.
pub const MIN_PLATE_MARGIN_C: f64 = 0.3;
/// Largest margin \[°C\]: 1. An estimate this uncertain (a sensor that has just been reconnected, a model far from
/// the device) must not take the display's whole range away; the measured-display limits still hold.
pub const MAX_PLATE_MARGIN_C: f64 = 1.0;

/// The margin kept between the predicted plate and a display limit for an estimate of standard deviation `sd_c`
/// \[°C\]: `PLATE_MARGIN_SDS · sd`, within [`MIN_PLATE_MARGIN_C`, `MAX_PLATE_MARGIN_C`] (NaN gives the largest).
pub fn plate_margin_c(sd_c: f64) -> f64 {
    let margin_c = PLATE_MARGIN_SDS * sd_c;
    if margin_c.is_nan() {
        MAX_PLATE_MARGIN_C
    } else {
        margin_c.clamp(MIN_PLATE_MARGIN_C, MAX_PLATE_MARGIN_C)
    }
}

/// Bisection steps of the current search: 2.8 A / 2³² is far below any drive's resolution.
const SEARCH_STEPS: usize = 32;

/// The current in `[low_a, high_a]` nearest to `high_a` whose predicted plate is at most `ceiling_c` (if
/// `want_below`) or nearest to `low_a` whose predicted plate is at least `floor` (if not), for a prediction that
/// increases with the current. Returns the far end if no current in the interval satisfies the bound.
pub(crate) fn search_current_a(
    forecast: &dyn PlateForecast,
    mut low_a: f64,
    mut high_a: f64,
    bound_c: f64,
    want_below: bool,
) -> f64 {
    for _ in 0..SEARCH_STEPS {
        let mid_a = 0.5 * (low_a + high_a);
        let (lowest_c, highest_c) = forecast.plate_after_range_c(mid_a);
        let ok = if want_below {
            highest_c <= bound_c
        } else {
            lowest_c >= bound_c
        };
        // Keep the satisfying end on the side the answer lies: below the bound, `low_a` satisfies.
        if ok == want_below {
            low_a = mid_a;
        } else {
            high_a = mid_a;
        }
    }
    if want_below {
        low_a
    } else {
        high_a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plate that moves linearly with the current: `after = start + slope · I`.
    struct Linear {
        start_c: f64,
        slope_c_per_a: f64,
    }

    impl PlateForecast for Linear {
        fn now(&self) -> Option<PlateNow> {
            Some(PlateNow {
                plate_c: self.start_c,
                sd_c: 0.0,
            })
        }
        fn plate_after_c(&self, current_a: f64) -> f64 {
            self.start_c + self.slope_c_per_a * current_a
        }
        fn strongest_cooling_a(&self) -> f64 {
            -3.0
        }
    }

    #[test]
    fn the_search_finds_the_current_that_lands_on_the_bound() {
        let plate = Linear {
            start_c: 47.5,
            slope_c_per_a: 0.2,
        };
        // 47.5 + 0.2·I = 47.9 → I = 2.
        let heat_a = search_current_a(&plate, -3.0, 2.8, 47.9, true);
        assert!(
            (heat_a - 2.0).abs() < 1e-8,
            "largest current below 47.9 °C: {heat_a} A, want 2 A"
        );
        // 47.5 + 0.2·I = 47.3 → I = −1 (the smallest current above 47.3 °C).
        let cool_a = search_current_a(&plate, -3.0, 2.8, 47.3, false);
        assert!(
            (cool_a + 1.0).abs() < 1e-8,
            "smallest current above 47.3 °C: {cool_a} A, want −1 A"
        );
        // Unreachable bound: the far end.
        assert_eq!(search_current_a(&plate, -3.0, 2.8, 40.0, true), -3.0);
    }

    #[test]
    fn the_margin_follows_the_uncertainty_within_its_bounds() {
        assert_eq!(plate_margin_c(0.0), MIN_PLATE_MARGIN_C);
        assert!((plate_margin_c(0.2) - 0.4).abs() < 1e-12, "{}", plate_margin_c(0.2));
        assert_eq!(plate_margin_c(5.0), MAX_PLATE_MARGIN_C);
        assert_eq!(plate_margin_c(f64::NAN), MAX_PLATE_MARGIN_C);
        assert_eq!(MeasuredOnly.now(), None);
    }
}
