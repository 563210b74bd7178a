//! The emulated firmware's own over- and under-temperature cut ([`thermode_link::own::guard`]), without any I/O: a host
//! that commands a current and then goes silent (a 60 s watchdog, so only the device's own cut acts), on the
//! default display and on the lagging-sensor display (τ 1.5 s). The true plate, which the firmware never sees, must
//! not pass 48 °C (10 °C when cooling); the cut latches, is reported, keeps later drives from heating, and is
//! released by `ClearFault` only once the plate is back inside. Also the per-tick trace (`Emulator::trace_to`).
//!
//! Cases are drawn by a seeded RNG (ChaCha8); the peaks are printed (`cargo test -- --nocapture`).

use std::io::Write;
use std::sync::{Arc, Mutex};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use thermode_device::{DeviceConfig, Fault, SimulatedDisplay, LAGGING_SENSOR_DEVICE_TOML};
use thermode_link::own::codec::{ChannelFaults, DeviceMessage, DriveFrame, Frame, HostMessage, StreamDecoder};
use thermode_link::own::emulator::{Emulator, EmulatorConfig, TRACE_HEADER};
use thermode_link::own::guard::{PLATE_MAX_C, PLATE_MIN_C, RELEASE_HYSTERESIS_C};
use thermode_model::kron::KronModel;

const TICK_S: f64 = 1e-3;

/// How far the true plate may pass a line \[K\]: the bound's reading error is 4σ of the sensor noise, so a rarer
/// noise sample can let the cut come a few thousandths of a kelvin late.
const TOLERANCE_C: f64 = 0.02;

fn default_display() -> DeviceConfig {
    DeviceConfig::default()
}

fn lagging_display() -> DeviceConfig {
    DeviceConfig::from_toml_str(LAGGING_SENSOR_DEVICE_TOML, "lagging-sensor.toml").unwrap_or_else(|e| panic!("{e}"))
}

/// A running emulator of one channel with a 60 s watchdog: the host's silence does not switch anything off.
fn silent_host_emulator(config: &DeviceConfig, seed: u64) -> (Emulator<KronModel>, Host) {
    let display = SimulatedDisplay::<KronModel>::fingertips(config, 1, seed).unwrap_or_else(|e| panic!("{e}"));
    let mut emu = Emulator::new(
        display,
        EmulatorConfig {
            watchdog_ms: 60_000,
            ..EmulatorConfig::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut host = Host::default();
    host.send(&mut emu, HostMessage::Hello);
    host.send(&mut emu, HostMessage::ClearFault);
    (emu, host)
}

/// The host end: frames stamped with the emulator's time.
#[derive(Default)]
struct Host {
    seq: u16,
    decoder: StreamDecoder<DeviceMessage>,
    inbox: Vec<Frame<DeviceMessage>>,
}

impl Host {
    fn send(&mut self, emu: &mut Emulator<KronModel>, message: HostMessage) {
        let mut bytes = Vec::new();
        thermode_link::own::codec::encode_frame(self.seq, &message, &mut bytes).unwrap_or_else(|e| panic!("{e}"));
        self.seq = self.seq.wrapping_add(1);
        let mut out = Vec::new();
        emu.receive(&bytes, emu.time_s(), &mut out);
        self.take(&out);
    }

    fn drive(&mut self, emu: &mut Emulator<KronModel>, current_a: f64) {
        let ma = (current_a * 1e3).round() as i16;
        let frame = DriveFrame::new(0, &[ma]).unwrap_or_else(|e| panic!("{e}"));
        self.send(emu, HostMessage::Drive(frame));
    }

    /// Runs `duration_s` tick by tick; the highest and lowest true plate seen.
    fn run(&mut self, emu: &mut Emulator<KronModel>, duration_s: f64) -> (f64, f64) {
        let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
        let end_s = emu.time_s() + duration_s;
        while emu.time_s() < end_s - 1e-9 {
            let mut out = Vec::new();
            emu.advance_to(emu.time_s() + TICK_S, &mut out);
            self.take(&out);
            let plate_c = plate_c(emu);
            (low, high) = (low.min(plate_c), high.max(plate_c));
        }
        (low, high)
    }

    fn take(&mut self, bytes: &[u8]) {
        let inbox = &mut self.inbox;
        self.decoder.feed(bytes, |r| {
            if let Ok(frame) = r {
                inbox.push(frame);
            }
        });
    }

    fn last_faults(&self) -> ChannelFaults {
        self.inbox
            .iter()
            .rev()
            .find_map(|f| match f.message {
                DeviceMessage::SensorReport(r) => Some(r.channels()[0].faults),
                _ => None,
            })
            .unwrap_or_else(|| panic!("no report yet"))
    }
}

fn plate_c(emu: &Emulator<KronModel>) -> f64 {
    emu.display().channel(0).map(|c| c.state().plate_c).unwrap_or(f64::NAN)
}

/// Puts the plate (and the sensor, settled) at `plate_c` and runs 50 ms at 0 A so the firmware has samples of it.
fn start_at(emu: &mut Emulator<KronModel>, host: &mut Host, plate_c: f64) {
    emu.display_mut()
        .channel_mut(0)
        .and_then(|c| c.set_temperatures(plate_c, 25.0))
        .unwrap_or_else(|e| panic!("{e}"));
    host.drive(emu, 0.0);
    host.run(emu, 0.05);
}

/// A host that drives `first_a` for `first_s`, then `then_a`, and falls silent; the peak of the true plate over
/// `watch_s`.
fn heat_and_die(config: &DeviceConfig, seed: u64, start_c: f64, first_a: f64, first_s: f64, then_a: f64) -> f64 {
    let (mut emu, mut host) = silent_host_emulator(config, seed);
    start_at(&mut emu, &mut host, start_c);
    host.drive(&mut emu, first_a);
    let (_, peak_first) = host.run(&mut emu, first_s);
    host.drive(&mut emu, then_a);
    let (_, peak_then) = host.run(&mut emu, 4.0);
    peak_first.max(peak_then)
}

#[test]
fn a_dead_host_heating_at_any_current_and_temperature_never_takes_the_plate_past_48() {
    let mut rng = ChaCha8Rng::seed_from_u64(48);
    for (name, config) in [("default", default_display()), ("lagging sensor", lagging_display())] {
        let mut worst = f64::NEG_INFINITY;
        for case in 0..12 {
            let start_c = rng.gen_range(30.0..47.5);
            let first_a = rng.gen_range(0.2..=2.8);
            // Half the cases lower the current before dying (the host was slowing down): the bound remembers
            // the faster rise of the last few sensor time constants.
            let (first_s, then_a) = if case % 2 == 0 {
                (0.0, first_a)
            } else {
                (rng.gen_range(0.05..0.5), rng.gen_range(0.1..=first_a))
            };
            let peak = heat_and_die(&config, case, start_c, first_a, first_s, then_a);
            println!(
                "{name}: from {start_c:.2} °C, {first_a:.2} A for {first_s:.2} s then {then_a:.2} A: peak plate \
                 {peak:.3} °C"
            );
            assert!(
                peak <= PLATE_MAX_C + TOLERANCE_C,
                "{name}: from {start_c} °C at {first_a} A then {then_a} A: plate peaked at {peak} °C, line {PLATE_MAX_C}"
            );
            worst = worst.max(peak);
        }
        println!("{name}: highest plate over 12 cases {worst:.3} °C");
    }
}

#[test]
fn a_dead_host_cooling_never_takes_the_plate_past_10() {
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    for (name, config) in [("default", default_display()), ("lagging sensor", lagging_display())] {
        for case in 0..6 {
            let start_c = rng.gen_range(10.5..25.0);
            let current_a = -rng.gen_range(0.3..=2.8);
            let (mut emu, mut host) = silent_host_emulator(&config, case);
            start_at(&mut emu, &mut host, start_c);
            host.drive(&mut emu, current_a);
            let (low, _) = host.run(&mut emu, 4.0);
            println!("{name}: from {start_c:.2} °C at {current_a:.2} A: lowest plate {low:.3} °C");
            assert!(
                low >= PLATE_MIN_C - TOLERANCE_C,
                "{name}: from {start_c} °C at {current_a} A: plate fell to {low} °C, line {PLATE_MIN_C}"
            );
        }
    }
}

#[test]
fn the_cut_latches_is_reported_and_is_released_only_back_inside() {
    let (mut emu, mut host) = silent_host_emulator(&default_display(), 1);
    start_at(&mut emu, &mut host, 44.0);
    host.drive(&mut emu, 2.8);
    for _ in 0..500 {
        host.run(&mut emu, TICK_S);
        if emu.cuts(0).heating {
            break;
        }
    }
    // One report interval, so the host hears of it.
    host.run(&mut emu, 0.01);
    let trip = emu
        .stats()
        .last_guard_trip
        .unwrap_or_else(|| panic!("no cut within 0.5 s at 2.8 A from 44 °C"));
    println!("cut: {trip:?}");
    assert!(trip.trip.heating && emu.cuts(0).heating && !emu.cuts(0).cooling);
    assert_eq!(emu.commanded_current_a(0), 0.0, "the cut zeroes the command");
    let faults = host.last_faults();
    assert!(
        faults.has(ChannelFaults::OVER_TEMPERATURE) && !faults.has(ChannelFaults::UNDER_TEMPERATURE),
        "report faults {faults:?}"
    );
    // ClearFault while the plate may still be near the line does not release it.
    host.drive(&mut emu, 0.0);
    host.send(&mut emu, HostMessage::ClearFault);
    let (_, upper_c) = emu.plate_bounds_c(0).unwrap_or_else(|| panic!("no bounds"));
    assert!(
        upper_c > PLATE_MAX_C - RELEASE_HYSTERESIS_C && emu.cuts(0).heating,
        "released at an upper bound of {upper_c} °C"
    );
    // Latched: heating again is held at 0 A; cooling is allowed.
    host.drive(&mut emu, 1.0);
    host.run(&mut emu, 0.02);
    assert_eq!(emu.status().applied_a[0], 0.0, "heating after the cut");
    host.drive(&mut emu, -1.0);
    host.run(&mut emu, 0.02);
    assert_eq!(emu.status().applied_a[0], -1.0, "cooling after a heating cut");
    host.drive(&mut emu, 0.0);
    // Once the bound is back inside, ClearFault releases it and heating works again.
    let mut waited_s = 0.0;
    while emu
        .plate_bounds_c(0)
        .is_some_and(|(_, hi)| hi > PLATE_MAX_C - RELEASE_HYSTERESIS_C)
        && waited_s < 10.0
    {
        host.run(&mut emu, 0.1);
        waited_s += 0.1;
    }
    host.send(&mut emu, HostMessage::ClearFault);
    println!(
        "released after {waited_s:.1} s at 0 A; plate {:.2} °C, bounds {:?}",
        plate_c(&emu),
        emu.plate_bounds_c(0)
    );
    assert!(
        !emu.cuts(0).heating,
        "not released at bounds {:?}",
        emu.plate_bounds_c(0)
    );
    host.drive(&mut emu, 0.5);
    host.run(&mut emu, 0.05);
    assert_eq!(emu.status().applied_a[0], 0.5, "heating after the release");
    assert!(!host.last_faults().has(ChannelFaults::OVER_TEMPERATURE));
}

#[test]
fn an_invalid_reading_cuts_both_directions() {
    let (mut emu, mut host) = silent_host_emulator(&default_display(), 2);
    host.drive(&mut emu, 0.5);
    host.run(&mut emu, 0.05);
    emu.display_mut()
        .channel_mut(0)
        .and_then(|c| c.inject(Fault::SensorOpen))
        .unwrap_or_else(|e| panic!("{e}"));
    host.run(&mut emu, 0.05);
    let cuts = emu.cuts(0);
    assert!(cuts.heating && cuts.cooling, "{cuts:?}");
    assert_eq!(emu.status().applied_a[0], 0.0);
    host.drive(&mut emu, -0.5);
    host.run(&mut emu, 0.05);
    assert_eq!(emu.status().applied_a[0], 0.0, "cooling with an open sensor");
    let faults = host.last_faults();
    assert!(
        faults.has(ChannelFaults::OVER_TEMPERATURE | ChannelFaults::UNDER_TEMPERATURE)
            && faults.has(ChannelFaults::SENSOR_OPEN),
        "{faults:?}"
    );
    // Still latched while the reading stays invalid.
    host.send(&mut emu, HostMessage::ClearFault);
    assert!(emu.cuts(0).heating && emu.cuts(0).cooling);
}

/// A sink the test can read back.
#[derive(Clone, Default)]
struct Shared(Arc<Mutex<Vec<u8>>>);

impl Write for Shared {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .map_err(|_| std::io::Error::other("poisoned"))?
            .extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn the_trace_has_one_whole_row_per_channel_per_tick() {
    let display = SimulatedDisplay::<KronModel>::fingertips(&default_display(), 2, 3).unwrap_or_else(|e| panic!("{e}"));
    let mut emu = Emulator::new(display, EmulatorConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    let sink = Shared::default();
    emu.trace_to(Box::new(sink.clone()));
    let mut host = Host::default();
    host.send(&mut emu, HostMessage::Hello);
    host.send(&mut emu, HostMessage::ClearFault);
    let frame = DriveFrame::new(0, &[1000, -500]).unwrap_or_else(|e| panic!("{e}"));
    host.send(&mut emu, HostMessage::Drive(frame));
    host.run(&mut emu, 0.1);
    let text = String::from_utf8(sink.0.lock().map(|b| b.clone()).unwrap_or_default()).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.first().copied(), Some(TRACE_HEADER));
    assert!(text.ends_with('\n'), "last row not whole");
    let rows = &lines[1..];
    assert_eq!(rows.len(), 2 * 100, "100 ticks of 2 channels");
    for (k, row) in rows.iter().enumerate() {
        let fields: Vec<f64> = row.split(',').map(|f| f.parse().unwrap_or(f64::NAN)).collect();
        assert_eq!(fields.len(), 5, "row {k}: {row}");
        let tick = (k / 2 + 1) as f64;
        assert!((fields[0] - tick * TICK_S).abs() < 1e-9, "row {k}: time {}", fields[0]);
        assert_eq!(fields[1], (k % 2) as f64, "row {k}: channel");
        assert_eq!(fields[4], [1.0, -0.5][k % 2], "row {k}: current");
    }
    let last: Vec<f64> = rows[199].split(',').map(|f| f.parse().unwrap_or(f64::NAN)).collect();
    let plate = emu.display().channel(1).map(|c| c.state().plate_c).unwrap_or(f64::NAN);
    assert!(
        (last[2] - plate).abs() < 1e-4,
        "trace plate {} vs plant {plate}",
        last[2]
    );
}

#[test]
fn a_host_killed_mid_heat_while_another_client_feeds_the_watchdog_leaves_the_plate_below_48_5() {
    // The default 250 ms watchdog, fed every 50 ms by a second client's heartbeats after the host is gone: only
    // the firmware's own cut, which allows for the sensor's lag, stops the heating.
    let mut worst = f64::NEG_INFINITY;
    for (start_c, current_a) in [(30.0, 2.8), (38.0, 2.8), (44.0, 1.5), (46.5, 0.8)] {
        let display =
            SimulatedDisplay::<KronModel>::fingertips(&default_display(), 1, 23).unwrap_or_else(|e| panic!("{e}"));
        let mut emu = Emulator::new(display, EmulatorConfig::default()).unwrap_or_else(|e| panic!("{e}"));
        let (mut host, mut other) = (Host::default(), Host::default());
        host.send(&mut emu, HostMessage::Hello);
        host.send(&mut emu, HostMessage::ClearFault);
        start_at(&mut emu, &mut host, start_c);
        host.drive(&mut emu, current_a);
        let mut peak_c = f64::NEG_INFINITY;
        for _ in 0..80 {
            other.send(&mut emu, HostMessage::Heartbeat);
            peak_c = peak_c.max(host.run(&mut emu, 0.05).1);
        }
        let latched = emu.status().latched;
        println!("from {start_c} °C at {current_a} A, host killed, heartbeats of another client: peak {peak_c:.3} °C");
        assert!(
            !latched,
            "the other client's frames kept the watchdog fed (the case under test)"
        );
        assert!(
            peak_c <= 48.5,
            "from {start_c} °C at {current_a} A: true plate {peak_c:.3} °C"
        );
        worst = worst.max(peak_c);
    }
    assert!(worst <= PLATE_MAX_C + TOLERANCE_C, "worst true plate {worst:.3} °C");
}
