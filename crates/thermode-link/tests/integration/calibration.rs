//! A device file's calibration on every backend's own lines (issue 35, finding 2): each device compares only its own
//! reading, so each line it holds is put on that reading's scale, the more cautious of the line as calibrated and as
//! it stands (MeCom: object thresholds, largest change, temperature mode's target range; TCS II: the warmest and
//! coolest set-point streamed and `Om`), and thermode's own firmware, whose cut is fixed, refuses a calibration that
//! would move it beyond its margin. The true-plate tests on the emulators are `thermode`'s
//! `cli::calibrated_lines`.

use thermode_device::config::CalibrationConfig;
use thermode_device::{CalibrationRefusal, DeviceConfig, DeviceError};
use thermode_link::own::guard::CALIBRATION_MARGIN_C;
use thermode_link::spec::{mecom_config, open_hardware, tcs2_config, HardwareContext};
use thermode_platform::{Clock, MonotonicClock};
use thermode_safety::EnvelopeConfig;

/// The default display with `[calibration]` gain `gain`, offset `offset_c` \[°C\].
fn context(offset_c: f64, gain: f64) -> HardwareContext {
    HardwareContext {
        device: DeviceConfig {
            calibration: CalibrationConfig {
                sensor_gain: gain,
                sensor_offset_c: offset_c,
                ..CalibrationConfig::default()
            },
            ..DeviceConfig::default()
        },
        envelope: EnvelopeConfig::default(),
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

/// MeCom: a sensor reading 5 °C low, honestly calibrated, has its upper threshold and warmest target 5 °C lower on
/// its reading (so the controller cuts and regulates at the true lines); a lying calibration of an honest sensor
/// (+5) leaves them as uncalibrated and raises the lower ones by 5 (the cautious side there); a gain of 0.98 slows
/// the largest change by 2 %.
#[test]
fn mecom_lines_go_on_the_more_cautious_scale() {
    let spec = "mecom:/dev/null";
    let plain = mecom_config(spec, &[], &context(0.0, 1.0)).unwrap_or_else(|e| panic!("{e}"));
    let low5 = mecom_config(spec, &[("mode", "temperature")], &context(-5.0, 1.0)).unwrap_or_else(|e| panic!("{e}"));
    let high5 = mecom_config(spec, &[], &context(5.0, 1.0)).unwrap_or_else(|e| panic!("{e}"));
    let gain = mecom_config(spec, &[], &context(0.0, 0.98)).unwrap_or_else(|e| panic!("{e}"));
    println!(
        "MeCom thresholds on the reading: uncalibrated {:.2}–{:.2} °C, reading 5 °C low {:.2}–{:.2} °C (targets \
         {:.1}–{:.1}), lying +5 {:.2}–{:.2} °C (targets {:.1}–{:.1})",
        plain.lower_error_c,
        plain.upper_error_c,
        low5.lower_error_c,
        low5.upper_error_c,
        low5.target_min_c,
        low5.target_max_c,
        high5.lower_error_c,
        high5.upper_error_c,
        high5.target_min_c,
        high5.target_max_c
    );
    assert!(
        close(low5.upper_error_c, plain.upper_error_c - 5.0) && close(low5.lower_error_c, plain.lower_error_c),
        "reading 5 low: {:.3}–{:.3} °C, uncalibrated {:.3}–{:.3} °C",
        low5.lower_error_c,
        low5.upper_error_c,
        plain.lower_error_c,
        plain.upper_error_c
    );
    assert!(
        close(low5.target_max_c, 43.0) && close(low5.target_min_c, 15.0),
        "reading 5 low: targets {}–{} °C, want 15–43",
        low5.target_min_c,
        low5.target_max_c
    );
    assert!(
        close(high5.upper_error_c, plain.upper_error_c) && close(high5.lower_error_c, plain.lower_error_c + 5.0),
        "lying +5: {:.3}–{:.3} °C",
        high5.lower_error_c,
        high5.upper_error_c
    );
    assert!(
        close(high5.target_max_c, 48.0) && close(high5.target_min_c, 20.0),
        "lying +5: targets {}–{} °C, want 20–48",
        high5.target_min_c,
        high5.target_max_c
    );
    assert!(
        close(gain.max_change_c_per_s, 0.98 * plain.max_change_c_per_s),
        "gain 0.98: {} °C/s against {} °C/s",
        gain.max_change_c_per_s,
        plain.max_change_c_per_s
    );
}

/// TCS II: a zone reading 5 °C low, honestly calibrated, streams at most 38 °C on its reading (a true 43 °C, what a
/// finger can rest on when the host is gone), `Om` at 43; a lying +5 on an honest zone keeps 43 and 48; a neutral
/// temperature that would rest above the held maximum under the calibration is refused, saying so.
#[test]
fn tcs2_hold_max_and_om_go_on_the_more_cautious_scale() {
    let spec = "tcs2:/dev/null";
    let low5 = tcs2_config(spec, &[], &context(-5.0, 1.0)).unwrap_or_else(|e| panic!("{e}"));
    let high5 = tcs2_config(spec, &[], &context(5.0, 1.0)).unwrap_or_else(|e| panic!("{e}"));
    println!(
        "TCS II on the zone's reading: reading 5 °C low: hold {:.1}–{:.1} °C, Om {:.1}; lying +5: hold {:.1}–{:.1} °C, \
         Om {:.1}",
        low5.hold_min_c, low5.hold_max_c, low5.max_c, high5.hold_min_c, high5.hold_max_c, high5.max_c
    );
    assert!(close(low5.hold_max_c, 38.0) && close(low5.max_c, 43.0), "{low5:?}");
    assert!(
        close(high5.hold_max_c, 43.0) && close(high5.max_c, 48.0) && close(high5.hold_min_c, 20.0),
        "{high5:?}"
    );
    match tcs2_config(spec, &[("neutral", "40")], &context(-5.0, 1.0)) {
        Err(DeviceError::Calibration(CalibrationRefusal::NeutralAboveHold { neutral_c, hold_max_c })) => {
            assert!(
                close(neutral_c, 40.0) && close(hold_max_c, 38.0),
                "{neutral_c} {hold_max_c}"
            );
        }
        other => panic!("neutral 40 °C under a −5 °C calibration: {other:?}"),
    }
}

/// Thermode's own firmware cuts at 48 °C and 10 °C on its own reading and the protocol cannot move that: a
/// calibration that puts the cut beyond its margin (a sensor reading 0.6 °C low at 48 °C, or 0.6 °C high at 10 °C)
/// is refused when the display is opened, before the port is touched, with a message naming the true plate at the
/// cut; 0.4 °C either way, or any error on the cautious side, is allowed.
#[test]
fn the_own_firmware_refuses_a_calibration_beyond_its_fixed_cut() {
    let clock: std::sync::Arc<dyn Clock> = std::sync::Arc::new(MonotonicClock::new());
    let spec = "serial:/nonexistent/thermode-calibration-test";
    for (offset_c, gain, refused) in [
        (-5.0, 1.0, true),
        (-0.6, 1.0, true),
        (0.6, 1.0, true),
        (-0.4, 1.0, false),
        (0.4, 1.0, false),
        (0.0, 0.985, true),
        (0.0, 1.0, false),
    ] {
        let error = match open_hardware(spec, &context(offset_c, gain), clock.clone()) {
            Ok(_) => panic!("{spec} opened"),
            Err(e) => e,
        };
        match (&error, refused) {
            (DeviceError::Calibration(CalibrationRefusal::BeyondFixedCut { true_c, line_c, .. }), true) => {
                let beyond_c = (true_c - line_c).abs();
                println!("offset {offset_c} °C, gain {gain}: refused: {error}");
                assert!(beyond_c > CALIBRATION_MARGIN_C, "{error}");
                assert!(error.to_string().contains("fixed in its firmware"), "{error}");
            }
            (DeviceError::Calibration(_), false) | (_, true) => {
                panic!("offset {offset_c} °C, gain {gain}: want refused {refused}, got {error}")
            }
            // Allowed: the open went on to the port, which does not exist.
            (_, false) => {}
        }
    }
}
