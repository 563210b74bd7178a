//! What a channel is asked to display: air, the touch of a virtual object, or a direct display temperature
//! (psychophysics), and the checks every stimulus passes before the pipeline accepts it.

use thermode_model::limits::SETPOINT_RATE;
use thermode_model::{Material, Range};
use thermode_safety::{ABSOLUTE_MAX_C, ABSOLUTE_MIN_C};

use crate::error::PipelineError;

/// The temperature a virtual object may have: the one physical range of object temperatures,
/// [`thermode_model::limits::OBJECT_TEMPERATURE`] (−50 to 150 °C). The safety envelope, not this range, limits
/// what the display shows.
pub use thermode_model::limits::OBJECT_TEMPERATURE;

/// The display temperature a direct stimulus may ask for: the safety envelope's absolute limits.
pub const DIRECT_TEMPERATURE: Range = Range {
    name: "direct display temperature [°C]",
    min: ABSOLUTE_MIN_C,
    max: ABSOLUTE_MAX_C,
};

/// The rate a direct stimulus may ask for: the one physical range of set-point rates,
/// [`thermode_model::limits::SETPOINT_RATE`] (0.01 to 300 °C/s, whose maximum is the safety envelope's absolute
/// rate limit). The channel's own envelope may allow less (see its `max_setpoint_rate_c_per_s`).
pub const DIRECT_RATE: Range = SETPOINT_RATE;

/// What the display renders.
#[derive(Debug, Clone, PartialEq)]
pub enum Stimulus {
    /// The finger touches nothing: the display renders still air at the pipeline's ambient temperature (the
    /// default at start).
    Air,
    /// The finger touches a fresh object of `material` (its thickness is used) that is uniform at `object_c`.
    /// Every `Touch` starts a new contact with a fresh object, also when the finger already touches one.
    Touch {
        /// The touched material (validated: finite, positive properties).
        material: Material,
        /// Temperature of the object at the moment of touch \[°C\], in [`OBJECT_TEMPERATURE`].
        object_c: f64,
    },
    /// Psychophysics: the display set-point goes to `temp_c` at `rate_c_s`, bypassing the renderer (still through
    /// the safety envelope, which may clamp and slow it further).
    Direct {
        /// Display temperature to approach \[°C\], within the compiled-in absolute limits
        /// [[`ABSOLUTE_MIN_C`], [`ABSOLUTE_MAX_C`]].
        temp_c: f64,
        /// Rate of approach \[°C/s\], in [`DIRECT_RATE`].
        rate_c_per_s: f64,
    },
}

impl Stimulus {
    /// Checks every number of the stimulus (see the variants); NaN and out-of-range values are errors, never
    /// clamped.
    pub fn validate(&self) -> Result<(), PipelineError> {
        match self {
            Stimulus::Air => Ok(()),
            Stimulus::Touch { material, object_c } => {
                material.validate(&format!("stimulus material `{}`", material.name))?;
                OBJECT_TEMPERATURE.check(*object_c)?;
                Ok(())
            }
            Stimulus::Direct { temp_c, rate_c_per_s } => {
                DIRECT_TEMPERATURE.check(*temp_c)?;
                DIRECT_RATE.check(*rate_c_per_s)?;
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_and_out_of_range_stimuli_are_refused() {
        let aluminium = thermode_model::materials::find("aluminium").unwrap_or_else(|e| panic!("{e}"));
        let touch = |object_c| Stimulus::Touch {
            material: aluminium.clone(),
            object_c,
        };
        assert!(touch(23.0).validate().is_ok());
        for bad in [f64::NAN, f64::INFINITY, -51.0, 151.0] {
            assert!(touch(bad).validate().is_err(), "object at {bad} °C accepted");
        }
        let mut broken = aluminium.clone();
        broken.density_kg_m3 = f64::NAN;
        let stimulus = Stimulus::Touch {
            material: broken,
            object_c: 23.0,
        };
        assert!(stimulus.validate().is_err(), "material with NaN density accepted");
        let direct = |temp_c, rate_c_per_s| Stimulus::Direct { temp_c, rate_c_per_s };
        assert!(direct(30.0, 2.0).validate().is_ok());
        for (t, r) in [
            (f64::NAN, 1.0),
            (30.0, f64::NAN),
            (9.0, 1.0),
            (49.0, 1.0),
            (30.0, 0.0),
            (30.0, 301.0),
        ] {
            assert!(direct(t, r).validate().is_err(), "direct {t} °C at {r} °C/s accepted");
        }
        assert!(Stimulus::Air.validate().is_ok());
    }
}
