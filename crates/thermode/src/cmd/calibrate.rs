//! `thermode calibrate`: checks the plate sensor against a reference thermometer, as labs do before a study. With no
//! finger on the plate, the display is driven (through the control loop, every drive through its channel's safety
//! envelope) to each set point in turn; once the sensor's reading has settled (a plateau), the sensor and the
//! reference are averaged over a few seconds. A straight line through the pairs gives the sensor's gain and offset
//! (reading = gain · T + offset at a true plate temperature T) with their standard errors, written into the device
//! file's `[calibration]` section; every command that reads that file then takes the calibrated plate temperature.
//!
//! The reference is `prompt` (the operator types each reading) or `serial:PATH`, a thermometer that writes one
//! temperature in °C per line (many USB lab thermometers; `thermode emulate --reference-channel N` offers one).
//!
//! A mounted PT-100 reads within a few tenths of a degree: a fit whose offset is beyond ±[`PLAIN_OFFSET_C`] or whose
//! gain is beyond 1 ± [`PLAIN_GAIN_ERROR`] says a lying reference or a wrong mount, and is refused (nothing written)
//! unless the operator confirms the very figure with `--accept-offset-c C` or `--accept-gain G`. A fit that would
//! move a device's fixed cut beyond its margin (thermode's own firmware,
//! [`thermode_link::own::guard::own_cut_allows`]) is refused whatever is confirmed. What the envelope will act on,
//! and where the device's own lines go, is printed with the result.

use std::io::BufRead;
use std::path::PathBuf;
use std::sync::mpsc::{channel, Receiver};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use thermode_device::config::CalibrationConfig;
use thermode_link::own::guard::own_cut_allows;
use thermode_link::spec::mecom_thresholds_on_reading_c;
use thermode_pipeline::pipeline::render_envelope;
use thermode_platform::{Clock, MonotonicClock};
use thermode_runtime::{Command, LoopConfig, LoopHandle, Owner};

use crate::controller::ControllerArg;
use crate::display::{build_display, DisplayArgs};
use crate::resolve;

/// Arguments of `thermode calibrate`.
#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// The display, one device as `serve --device` takes it (current-commanded: a device that regulates its plate
    /// itself does so on its own sensor).
    #[arg(long, value_name = "DEVICE")]
    device: String,
    /// The display's device file (TOML); default: the built-in default display. Its other values are kept.
    #[arg(long = "device-file", value_name = "FILE")]
    device_file: Option<PathBuf>,
    /// The reference thermometer: `prompt` (type each reading) or `serial:PATH` (one temperature in °C per line).
    #[arg(long, value_name = "prompt|serial:PATH")]
    reference: String,
    /// The calibrated device file to write (replaced if it exists).
    #[arg(long, value_name = "FILE.toml")]
    out: PathBuf,
    /// The channel whose sensor is calibrated (no finger on it).
    #[arg(long, value_name = "N", default_value_t = 0)]
    channel: usize,
    /// The set points [°C], at least two; each is held within what the device allows.
    #[arg(long, value_name = "C,C,…", value_delimiter = ',', default_value = "15,25,35,45")]
    setpoints: Vec<f64>,
    /// The longest wait for a plateau at a set point [s].
    #[arg(long = "settle-max-s", value_name = "S", default_value_t = 180.0)]
    settle_max_s: f64,
    /// How long the sensor and the reference are averaged at a plateau [s].
    #[arg(long = "average-s", value_name = "S", default_value_t = 3.0)]
    average_s: f64,
    /// Confirms a fitted offset beyond ±1 °C [°C]: the figure the refusal printed (the fit must lie within
    /// ±0.25 °C of it). Default: none (such a fit is refused).
    #[arg(long = "accept-offset-c", value_name = "C", allow_negative_numbers = true)]
    accept_offset_c: Option<f64>,
    /// Confirms a fitted gain beyond 1 ± 0.02 [-]: the figure the refusal printed (the fit must lie within ±0.005
    /// of it). Default: none (such a fit is refused).
    #[arg(long = "accept-gain", value_name = "G")]
    accept_gain: Option<f64>,
}

/// The largest offset a fit may have without the operator's confirmation \[°C\]: 1 (a mounted PT-100 reads within a
/// few tenths; more means a lying reference, a wrong channel or a sensor off the plate).
const PLAIN_OFFSET_C: f64 = 1.0;
/// The largest gain error (|gain − 1|) a fit may have without the operator's confirmation \[-\]: 0.02 (2 %).
const PLAIN_GAIN_ERROR: f64 = 0.02;
/// How close a fitted offset must be to the one the operator confirmed \[°C\]: 0.25 (the figure as printed, 0.1 °C,
/// and what a second run of the same calibration may differ by).
const ACCEPT_OFFSET_TOLERANCE_C: f64 = 0.25;
/// How close a fitted gain must be to the one the operator confirmed \[-\]: 0.005.
const ACCEPT_GAIN_TOLERANCE: f64 = 0.005;

/// The largest drift of the sensor's mean reading over half of [`PLATEAU_WINDOW_S`] at a plateau \[°C\] (the
/// sensor's lag then hides less than a thousandth of a degree).
const PLATEAU_DRIFT_C: f64 = 0.005;
/// The window over which a plateau is judged \[s\].
const PLATEAU_WINDOW_S: f64 = 3.0;
/// The rate at which the set point is approached \[°C/s\].
const APPROACH_C_PER_S: f64 = 5.0;

/// Where the reference readings come from.
enum Reference {
    /// The operator types them.
    Prompt,
    /// A thermometer's lines, each with the time it arrived.
    Serial(Receiver<(Instant, f64)>),
}

impl Reference {
    /// Opens `spec` (`prompt` or `serial:PATH`).
    fn open(spec: &str) -> Result<Reference> {
        if spec == "prompt" {
            return Ok(Reference::Prompt);
        }
        let Some(path) = spec.strip_prefix("serial:") else {
            bail!("--reference must be `prompt` or `serial:PATH`, not {spec:?}");
        };
        let file = std::fs::File::open(path).with_context(|| format!("cannot open the reference {path}"))?;
        let (send, receive) = channel();
        std::thread::Builder::new()
            .name("thermode-reference".into())
            .spawn(move || {
                for line in std::io::BufReader::new(file).lines() {
                    let Ok(line) = line else { return };
                    if let Ok(value) = line.trim().parse::<f64>() {
                        if value.is_finite() && send.send((Instant::now(), value)).is_err() {
                            return;
                        }
                    }
                }
            })
            .context("cannot start the reference reader")?;
        Ok(Reference::Serial(receive))
    }

    /// The reference's mean over the readings that arrived within `window` (the sensor's averaging window moved
    /// back by the sensor's lag, so both see the same plate even if it still creeps), waiting for the first reading
    /// after it; or the operator's reading at a plate the display reads `display_c` \[°C\].
    fn reading(&self, window: (Instant, Instant), display_c: f64) -> Result<f64> {
        match self {
            Reference::Prompt => {
                eprint!("the display reads {display_c:.2} °C: type the reference thermometer's reading in °C: ");
                let mut line = String::new();
                std::io::stdin().lock().read_line(&mut line)?;
                line.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .with_context(|| format!("not a temperature: {:?}", line.trim()))
            }
            Reference::Serial(lines) => {
                let (from, to) = window;
                let mut values = Vec::new();
                loop {
                    match lines.recv_timeout(Duration::from_secs(5)) {
                        Ok((at, _)) if at > to && !values.is_empty() => break,
                        Ok((at, value)) if at >= from && at <= to => values.push(value),
                        Ok((at, _)) if at > to => bail!(
                            "the reference thermometer sent no reading during the {:.1} s the sensor was averaged",
                            to.duration_since(from).as_secs_f64()
                        ),
                        Ok(_) => {}
                        Err(_) => bail!("the reference thermometer sent no reading for 5 s"),
                    }
                }
                Ok(values.iter().sum::<f64>() / values.len() as f64)
            }
        }
    }
}

/// One plateau: the reference and the sensor's raw reading \[°C\].
#[derive(Debug, Clone, Copy)]
struct Pair {
    reference_c: f64,
    sensor_c: f64,
}

/// The straight line `sensor = gain · reference + offset` through `pairs`, with the standard errors of both (0 with
/// two pairs).
fn fit(pairs: &[Pair]) -> CalibrationConfig {
    let n = pairs.len() as f64;
    let mean_x = pairs.iter().map(|p| p.reference_c).sum::<f64>() / n;
    let mean_y = pairs.iter().map(|p| p.sensor_c).sum::<f64>() / n;
    let sxx: f64 = pairs.iter().map(|p| (p.reference_c - mean_x).powi(2)).sum();
    let sxy: f64 = pairs
        .iter()
        .map(|p| (p.reference_c - mean_x) * (p.sensor_c - mean_y))
        .sum();
    let gain = sxy / sxx;
    let offset_c = mean_y - gain * mean_x;
    let residual: f64 = pairs
        .iter()
        .map(|p| (p.sensor_c - offset_c - gain * p.reference_c).powi(2))
        .sum();
    let variance = if pairs.len() > 2 { residual / (n - 2.0) } else { 0.0 };
    CalibrationConfig {
        sensor_gain: gain,
        sensor_offset_c: offset_c,
        gain_uncertainty: (variance / sxx).sqrt(),
        offset_uncertainty_c: (variance * (1.0 / n + mean_x * mean_x / sxx)).sqrt(),
    }
}

/// Runs `thermode calibrate`.
pub fn run(args: &CalibrateArgs) -> Result<()> {
    let distinct = args.setpoints.iter().any(|&c| (c - args.setpoints[0]).abs() > 1.0);
    if args.setpoints.len() < 2 || !distinct || args.setpoints.iter().any(|c| !c.is_finite()) {
        bail!("--setpoints needs at least two finite set points at least 1 °C apart");
    }
    if !(args.average_s > 0.0 && args.settle_max_s > PLATEAU_WINDOW_S) {
        bail!("--average-s must be positive and --settle-max-s longer than {PLATEAU_WINDOW_S} s");
    }
    let finite = |v: Option<f64>| v.is_none_or(f64::is_finite);
    if !(finite(args.accept_offset_c) && finite(args.accept_gain)) {
        bail!("--accept-offset-c and --accept-gain must be finite numbers");
    }
    crate::output::check_outputs(&[("--out", Some(&args.out))])?;
    let device = resolve::device_config(args.device_file.as_deref())?;
    let before = device.calibration;
    let reference = Reference::open(&args.reference)?;
    let setpoints = held_setpoints(args, &device)?;
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let display = DisplayArgs::one(&args.device, args.device_file.clone(), ControllerArg::Model, 1);
    let display = build_display(&display, &clock, None)?;
    if args.channel >= display.device.channel_count() {
        bail!(
            "--channel {}: {} has {} channels",
            args.channel,
            display.label,
            display.device.channel_count()
        );
    }
    let mut control = LoopHandle::spawn(
        LoopConfig::default(),
        display.device,
        display.engines,
        clock,
        Vec::new(),
        Arc::default(),
    )?;
    let pairs = (|| {
        let mut pairs = Vec::new();
        for &setpoint_c in &setpoints {
            let pair = plateau(&control, args, setpoint_c, device.sensor.time_constant_s, &reference)?;
            // Back to what the sensor reads without the file's calibration.
            let sensor_c = before.sensor_gain * pair.sensor_c + before.sensor_offset_c;
            eprintln!(
                "calibrate: set point {setpoint_c:.1} °C: reference {:.3} °C, sensor {sensor_c:.3} °C",
                pair.reference_c
            );
            pairs.push(Pair { sensor_c, ..pair });
        }
        Ok::<_, anyhow::Error>(pairs)
    })();
    let _ = control.commands().send(Command::StopAll);
    let stopped = control.stop();
    let pairs = pairs?;
    if let Some(Err(e)) = stopped {
        bail!("the device did not take the all-off command: {e}");
    }
    write_calibration(args, device, &pairs)
}

/// How far inside the display's range \[°C\] a set point is held: 1. At the envelope's edge its forecast holds the
/// plate short of the set point, where it creeps (measured at 15 °C on the MeCom emulator: the reading stopped at
/// 15.33–15.36 °C and the pair fell 0.03–0.05 °C off the line).
const INSIDE_RANGE_C: f64 = 1.0;

/// The set points of `args`, each held `INSIDE_RANGE_C` inside the display's envelope and within what the device
/// allows (a MeCom controller's own error thresholds on its reading, through the file's calibration, with 1 °C to
/// spare).
fn held_setpoints(args: &CalibrateArgs, device: &thermode_device::DeviceConfig) -> Result<Vec<f64>> {
    let envelope = render_envelope(device);
    let (mut low_c, mut high_c, mut why) = (
        envelope.min_display_c + INSIDE_RANGE_C,
        envelope.max_display_c - INSIDE_RANGE_C,
        "the display's range",
    );
    if args.device.starts_with("mecom") {
        let (cut_low_c, cut_high_c) = mecom_thresholds_on_reading_c(device)?;
        let calibration = device.calibration;
        low_c = low_c.max(calibration.plate_c(cut_low_c) + 1.0);
        high_c = high_c.min(calibration.plate_c(cut_high_c) - 1.0);
        why = "the display's range and the controller's own thresholds";
    }
    let held: Vec<f64> = args.setpoints.iter().map(|c| c.clamp(low_c, high_c)).collect();
    if held != args.setpoints {
        let shown: Vec<String> = held.iter().map(|c| format!("{c:.1}")).collect();
        eprintln!(
            "calibrate: {why} allow {low_c:.1} to {high_c:.1} °C: set points {} °C",
            shown.join(", ")
        );
    }
    Ok(held)
}

/// Drives `args.channel` to `setpoint_c` \[°C\], waits for the sensor's plateau, and averages the sensor over
/// `args.average_s` and the reference over the same window `sensor_lag_s` \[s\] earlier.
fn plateau(
    control: &LoopHandle,
    args: &CalibrateArgs,
    setpoint_c: f64,
    sensor_lag_s: f64,
    reference: &Reference,
) -> Result<Pair> {
    let command = Command::direct(args.channel, setpoint_c, APPROACH_C_PER_S, Owner::Script);
    control
        .commands()
        .request(command)
        .context("the loop refused the set point")?;
    let start = Instant::now();
    let mut history: Vec<(Instant, f64)> = Vec::new();
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let now = Instant::now();
        history.push((now, sensor_c(control, args.channel)?));
        history.retain(|(t, _)| now.duration_since(*t).as_secs_f64() <= PLATEAU_WINDOW_S);
        // The drift over the window: the second half's mean less the first's (the noise averages out).
        let half = history.len() / 2;
        let mean = |part: &[(Instant, f64)]| part.iter().map(|(_, c)| c).sum::<f64>() / part.len().max(1) as f64;
        let drift_c = mean(&history[half..]) - mean(&history[..half]);
        let waited_s = start.elapsed().as_secs_f64();
        if waited_s > PLATEAU_WINDOW_S + 2.0 && drift_c.abs() < PLATEAU_DRIFT_C {
            break;
        }
        if waited_s > args.settle_max_s {
            bail!(
                "no plateau at {setpoint_c} °C within {} s (the reading drifted {drift_c:.3} °C over {} s)",
                args.settle_max_s,
                PLATEAU_WINDOW_S / 2.0
            );
        }
    }
    let since = Instant::now();
    let mut readings = Vec::new();
    while since.elapsed().as_secs_f64() < args.average_s {
        readings.push(sensor_c(control, args.channel)?);
        std::thread::sleep(Duration::from_millis(20));
    }
    let until = Instant::now();
    let sensor_c = readings.iter().sum::<f64>() / readings.len().max(1) as f64;
    // The sensor shows the plate of its lag ago; the reference (a thermometer on the plate) is taken as immediate.
    let lag = Duration::from_secs_f64(sensor_lag_s.max(0.0));
    let window = (
        since.checked_sub(lag).unwrap_or(since),
        until.checked_sub(lag).unwrap_or(until),
    );
    let reference_c = reference.reading(window, sensor_c)?;
    Ok(Pair { reference_c, sensor_c })
}

/// The newest sensor reading of `channel` \[°C\]; an error once the channel faulted or its link failed.
fn sensor_c(control: &LoopHandle, channel: usize) -> Result<f64> {
    let snapshot = control.snapshot();
    let status = snapshot.channels.get(channel).context("no such channel")?;
    if let Some(fault) = status.telemetry.fault {
        let cut = status
            .device_cut
            .map(|c| format!(", device cut {c:?}"))
            .unwrap_or_default();
        bail!(
            "channel {channel} faulted ({fault:?}{cut}; sensor {:.2} °C): calibration stopped",
            status.telemetry.sensor_c
        );
    }
    if !status.link_ok {
        bail!("channel {channel}: the device link failed: calibration stopped");
    }
    Ok(status.telemetry.sensor_c)
}

/// `Ok` if the fit `calibration` is what a mounted sensor can be off by (offset within ±[`PLAIN_OFFSET_C`], gain
/// within 1 ± [`PLAIN_GAIN_ERROR`]), or the operator confirmed its figures (`accept_offset_c`, `accept_gain`); else
/// the refusal, which names the figures to confirm.
fn check_plausible(
    calibration: &CalibrationConfig,
    accept_offset_c: Option<f64>,
    accept_gain: Option<f64>,
) -> Result<()> {
    let (gain, offset_c) = (calibration.sensor_gain, calibration.sensor_offset_c);
    let plain_offset = format!("±{PLAIN_OFFSET_C} °C");
    let plain_gain = format!("1 ± {PLAIN_GAIN_ERROR}");
    let checks = [
        (
            "offset",
            "--accept-offset-c",
            offset_c,
            0.0,
            PLAIN_OFFSET_C,
            plain_offset,
            accept_offset_c,
            ACCEPT_OFFSET_TOLERANCE_C,
        ),
        (
            "gain",
            "--accept-gain",
            gain,
            1.0,
            PLAIN_GAIN_ERROR,
            plain_gain,
            accept_gain,
            ACCEPT_GAIN_TOLERANCE,
        ),
    ];
    for (what, flag, fitted, nominal, plain, limit, accepted, tolerance) in checks {
        if (fitted - nominal).abs() <= plain {
            continue;
        }
        match accepted {
            Some(accepted) if (fitted - accepted).abs() <= tolerance => {}
            Some(accepted) => bail!(
                "the fitted {what} {fitted:.4} is not the {accepted} confirmed with {flag} (it must lie within \
                 ±{tolerance}): nothing written; check the reference and the mount, and run again"
            ),
            None => bail!(
                "the fit (offset {offset_c:.3} °C, gain {gain:.5}) has its {what} beyond {limit}, more than a \
                 mounted PT-100 is off (a few tenths of a degree): a lying reference thermometer, a wrong channel or a \
                 sensor off the plate; nothing written. Check them; if this is the sensor's true error, run again with \
                 {flag} {fitted:.prec$}",
                prec = if what == "gain" { 3 } else { 1 }
            ),
        }
    }
    Ok(())
}

/// What the envelope will act on under `calibration` and where `args.device`'s own lines go, in one line; an error
/// if the device's own lines cannot follow it (a cut fixed in its firmware).
fn acts_on(args: &CalibrateArgs, device: &thermode_device::DeviceConfig) -> Result<String> {
    let calibration = &device.calibration;
    let max_c = thermode_safety::ABSOLUTE_MAX_C;
    let lines = if args.device.starts_with(thermode_link::own::host::SERIAL_PREFIX) {
        own_cut_allows(calibration)?;
        "its firmware's own cut stays at 48 °C on its own reading (within its margin)".to_string()
    } else if args.device.starts_with("mecom") {
        let (low_c, high_c) = mecom_thresholds_on_reading_c(device)?;
        format!("the controller's object thresholds go to {low_c:.2}–{high_c:.2} °C on its own reading")
    } else {
        "the device's own lines go on the more cautious of the calibrated and the raw reading".to_string()
    };
    Ok(format!(
        "the envelope, the controller and the records act on the calibrated plate, (reading − offset) / gain: the \
         display's {max_c} °C is a reading of {:.2} °C; {lines}",
        calibration.reading_c(max_c)
    ))
}

/// Fits the pairs, writes the device file with the calibration and prints the result.
fn write_calibration(args: &CalibrateArgs, mut device: thermode_device::DeviceConfig, pairs: &[Pair]) -> Result<()> {
    let calibration = fit(pairs);
    let ok = |rule_min: f64, rule_max: f64, v: f64| v.is_finite() && (rule_min..=rule_max).contains(&v);
    if !ok(0.5, 2.0, calibration.sensor_gain) || !ok(-10.0, 10.0, calibration.sensor_offset_c) {
        bail!(
            "the fit (gain {}, offset {} °C) is outside what a plate sensor can be off (gain 0.5 to 2, offset ±10 °C): \
             check the reference and its channel",
            calibration.sensor_gain,
            calibration.sensor_offset_c
        );
    }
    check_plausible(&calibration, args.accept_offset_c, args.accept_gain)?;
    device.calibration = calibration;
    let acts_on = acts_on(args, &device).map_err(|e| anyhow::anyhow!("{e}; nothing written"))?;
    crate::output::create_folder_of(&args.out)?;
    let text = device.to_toml_string();
    crate::output::write_atomically(&args.out, |out| Ok(out.write_all(text.as_bytes())?))?;
    let (low, high) = pairs.iter().fold((f64::MAX, f64::MIN), |(l, h), p| {
        (l.min(p.reference_c), h.max(p.reference_c))
    });
    let largest_c = [low, high]
        .iter()
        .map(|&t| (calibration.plate_c(t) - t).abs())
        .fold(0.0, f64::max);
    println!(
        "calibrated: gain {:.5} ± {:.5}, offset {:.3} ± {:.3} °C; the correction is at most {largest_c:.3} °C over \
         {low:.1}–{high:.1} °C; written to {}",
        calibration.sensor_gain,
        calibration.gain_uncertainty,
        calibration.sensor_offset_c,
        calibration.offset_uncertainty_c,
        args.out.display()
    );
    println!("{acts_on}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn calibration(offset_c: f64, gain: f64) -> CalibrationConfig {
        CalibrationConfig {
            sensor_gain: gain,
            sensor_offset_c: offset_c,
            ..CalibrationConfig::default()
        }
    }

    fn refusal(result: Result<()>) -> String {
        match result {
            Ok(()) => panic!("accepted"),
            Err(e) => e.to_string(),
        }
    }

    /// A fit 5 °C off is refused with the flag and figure that would confirm it; that figure confirms it, another
    /// does not; a gain 3 % off likewise; a fit within a few tenths needs nothing.
    #[test]
    fn a_fit_beyond_what_a_mounted_sensor_is_off_needs_its_figure_confirmed() {
        let off = calibration(-5.004, 1.00008);
        let refused = refusal(check_plausible(&off, None, None));
        assert!(
            refused.contains("--accept-offset-c -5.0") && refused.contains("nothing written"),
            "{refused}"
        );
        assert!(check_plausible(&off, Some(-5.0), None).is_ok());
        let wrong = refusal(check_plausible(&off, Some(-3.0), None));
        assert!(wrong.contains("-3") && wrong.contains("nothing written"), "{wrong}");
        let steep = calibration(0.2, 1.03);
        let refused = refusal(check_plausible(&steep, None, None));
        assert!(refused.contains("--accept-gain 1.030"), "{refused}");
        assert!(check_plausible(&steep, None, Some(1.03)).is_ok());
        assert!(
            check_plausible(&steep, Some(0.2), None).is_err(),
            "an offset confirmed is not a gain"
        );
        assert!(check_plausible(&calibration(0.3, 1.01), None, None).is_ok());
        assert!(check_plausible(&calibration(-0.99, 0.981), None, None).is_ok());
    }
}
