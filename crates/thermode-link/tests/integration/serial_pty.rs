//! End to end over a real pseudo-terminal: the emulator runs on the master side in a thread, [`SerialDevice`]
//! opens the slave path as a serial port, and a control loop drives it through safety envelopes. Covers the
//! handshake, drive commands reaching the plant, corrupted bytes, dropped frames, a device that stops answering,
//! a port that vanishes, and the device watchdog when the host goes silent.
//!
//! Timing assertions use generous bounds (scheduling on a loaded machine); exact properties (the watchdog's delay
//! on the emulator clock, the host's count of dropped frames) are asserted exactly. Tests that are not about timing
//! use a tolerant link timeout and stale-sensor timeout (1 s); the watchdog is the longest the host accepts (250 ms),
//! fed by the tests' own calls every 5–10 ms. Measured numbers are printed (`cargo test -- --nocapture`).
#![cfg(unix)]

use std::sync::Arc;
use std::time::{Duration, Instant};

use thermode_device::{Device, DeviceConfig, DeviceError, Reading, SimulatedDisplay};
use thermode_link::own::codec::DeviceMessage;
use thermode_link::own::emulator::{Emulator, EmulatorConfig, EmulatorStatus, LinkFaults, PtyEmulator, SentLog};
use thermode_link::own::host::{serial_path, SerialConfig, SerialDevice, MAX_DEVICE_WATCHDOG_MS};
use thermode_model::kron::KronModel;
use thermode_platform::{Clock, MonotonicClock};
use thermode_safety::{EnvelopeConfig, MeasuredOnly, SafetyEnvelope};

const WATCHDOG_S: f64 = 0.25;
const TICK_S: f64 = 1e-3;

/// Host settings for tests that are not about timing: a 1 s link timeout.
fn tolerant() -> SerialConfig {
    SerialConfig {
        link_timeout_s: 1.0,
        ..SerialConfig::default()
    }
}

/// Emulator settings for tests that are not about the watchdog: the longest period the host accepts
/// ([`MAX_DEVICE_WATCHDOG_MS`]); these tests call the device every 5–10 ms, which feeds it.
fn patient() -> EmulatorConfig {
    EmulatorConfig {
        watchdog_ms: MAX_DEVICE_WATCHDOG_MS,
        ..EmulatorConfig::default()
    }
}

fn emulator(channels: usize, config: EmulatorConfig) -> Emulator<KronModel> {
    let display = SimulatedDisplay::<KronModel>::fingertips(&DeviceConfig::default(), channels, 3)
        .unwrap_or_else(|e| panic!("display: {e}"));
    Emulator::new(display, config).unwrap_or_else(|e| panic!("emulator: {e}"))
}

/// An emulator on a pty and a host device on its path, sharing one clock.
fn link(emu: Emulator<KronModel>, config: &SerialConfig) -> (PtyEmulator, SerialDevice, Arc<dyn Clock>) {
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let pty = PtyEmulator::spawn(emu, Arc::clone(&clock)).unwrap_or_else(|e| panic!("pty: {e}"));
    let device = SerialDevice::open(pty.path(), config, Arc::clone(&clock)).unwrap_or_else(|e| panic!("open: {e}"));
    (pty, device, clock)
}

fn status(pty: &PtyEmulator) -> EmulatorStatus {
    pty.control()
        .status()
        .unwrap_or_else(|| panic!("emulator published no status"))
}

/// Waits (polling every millisecond, at most `limit_s`) until `done` holds; returns the time waited.
fn wait_for(limit_s: f64, mut done: impl FnMut() -> bool) -> Option<f64> {
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < limit_s {
        if done() {
            return Some(start.elapsed().as_secs_f64());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    None
}

/// A host control loop: per channel read → observe → gate → apply, as the runtime does.
struct ControlLoop {
    device: SerialDevice,
    envelopes: Vec<SafetyEnvelope>,
    clock: Arc<dyn Clock>,
}

impl ControlLoop {
    /// Envelopes with the default limits and a 1 s stale-sensor timeout (the default 0.2 s is about the runtime's
    /// timing, not the link's).
    fn new(device: SerialDevice, clock: Arc<dyn Clock>) -> Self {
        let limit_a = f64::from(device.identify().current_limit_ma) * 1e-3;
        let config = EnvelopeConfig {
            stale_timeout_s: 1.0,
            ..EnvelopeConfig::default()
        };
        let envelopes = (0..device.channel_count())
            .map(|_| SafetyEnvelope::new(config, limit_a).unwrap_or_else(|e| panic!("{e}")))
            .collect();
        ControlLoop {
            device,
            envelopes,
            clock,
        }
    }

    /// One tick requesting `currents_a`; the readings (or errors) per channel.
    fn tick(&mut self, currents_a: &[f64]) -> Vec<Result<Reading, DeviceError>> {
        let now = self.clock.now_s();
        let mut readings = Vec::new();
        for (ch, envelope) in self.envelopes.iter_mut().enumerate() {
            let reading = self.device.read(ch);
            if let Ok(r) = &reading {
                envelope.observe(&r.measurement());
            }
            let command = envelope.gate_drive(now, currents_a[ch], &MeasuredOnly);
            if let Err(e) = self.device.apply(ch, &command) {
                readings.push(Err(e));
                continue;
            }
            readings.push(reading);
        }
        readings
    }

    /// Ticks at about 100 Hz for `duration_s`; the last tick's results.
    fn run(&mut self, duration_s: f64, currents_a: &[f64]) -> Vec<Result<Reading, DeviceError>> {
        let start = Instant::now();
        let mut last = Vec::new();
        while start.elapsed().as_secs_f64() < duration_s {
            last = self.tick(currents_a);
            std::thread::sleep(Duration::from_millis(10));
        }
        last
    }
}

fn ok(reading: &Result<Reading, DeviceError>) -> Reading {
    match reading {
        Ok(r) => *r,
        Err(e) => panic!("reading failed: {e}"),
    }
}

/// The runtime moves the device into its control thread.
#[test]
fn the_serial_device_can_move_between_threads() {
    fn assert_send<T: Send>() {}
    assert_send::<SerialDevice>();
    assert_send::<Emulator<thermode_device::DefaultFinger>>();
}

#[test]
fn handshake_and_fresh_readings() {
    let (pty, mut device, clock) = link(emulator(2, patient()), &tolerant());
    let id = device.identify();
    assert_eq!((id.channel_count, id.current_limit_ma, id.watchdog_ms), (2, 2800, 250));
    assert!(pty.path().starts_with("/dev/"), "pty path {}", pty.path());
    let first = ok(&device.read(0));
    let mut later = first;
    let waited = wait_for(2.0, || {
        later = ok(&device.read(0));
        later.sample_seq >= first.sample_seq + 5
    });
    let now = clock.now_s();
    println!(
        "readings: seq {} → {} in {waited:?} s (100 Hz samples); sample age at read {:.4} s",
        first.sample_seq,
        later.sample_seq,
        now - later.time_s
    );
    assert!(
        waited.is_some(),
        "samples stuck: {} → {}",
        first.sample_seq,
        later.sample_seq
    );
    assert!(
        later.time_s > first.time_s && now - later.time_s < 0.5,
        "sample time {} at {now}",
        later.time_s
    );
    assert!(
        (later.sensor_c - 23.0).abs() < 3.0 && (later.hot_side_c - 23.0).abs() < 1.0,
        "{later:?}"
    );
    assert!(matches!(
        device.read(2),
        Err(DeviceError::NoSuchChannel { channel: 2, count: 2 })
    ));
}

#[test]
fn drive_commands_move_the_plant_the_right_way() {
    let (pty, device, clock) = link(emulator(2, patient()), &tolerant());
    let mut control = ControlLoop::new(device, clock);
    let mut start = Vec::new();
    let ready = wait_for(2.0, || {
        start = control.tick(&[0.0, 0.0]);
        start.iter().all(|r| r.is_ok())
    });
    assert!(ready.is_some(), "no readings: {start:?}");
    let start = start.iter().map(ok).collect::<Vec<_>>();
    // Ticks at 100 Hz until the current flows (a drive frame goes out at most every 5 ms, so a round that comes
    // sooner is sent with the next call).
    let t0 = Instant::now();
    let latency = wait_for(2.0, || {
        control.tick(&[1.0, -1.0]);
        std::thread::sleep(Duration::from_millis(10));
        status(&pty).applied_a[0] == 1.0
    });
    println!("first 1 A request to current in the plant: {latency:?} s");
    assert!(latency.is_some(), "1 A never reached the plant");
    let end = control.run(1.0, &[1.0, -1.0]).iter().map(ok).collect::<Vec<_>>();
    let s = status(&pty);
    println!(
        "after {:.2} s: ch0 {:.2} → {:.2} °C (+1 A), ch1 {:.2} → {:.2} °C (−1 A); plant applied {:?} A",
        t0.elapsed().as_secs_f64(),
        start[0].sensor_c,
        end[0].sensor_c,
        start[1].sensor_c,
        end[1].sensor_c,
        &s.applied_a[..2]
    );
    assert_eq!((s.applied_a[0], s.applied_a[1]), (1.0, -1.0));
    assert_eq!(
        (end[0].current_a, end[1].current_a),
        (1.0, -1.0),
        "reported drive currents"
    );
    assert!(end[0].sensor_c > start[0].sensor_c + 1.0, "heated channel");
    assert!(end[1].sensor_c < start[1].sensor_c - 1.0, "cooled channel");
    let stats = control.device.stats();
    assert_eq!(
        (stats.rx.errors(), stats.nacks, s.stats.rx.errors()),
        (0, 0, 0),
        "{stats:?}"
    );
}

#[test]
fn corrupted_bytes_are_survived_and_counted() {
    let config = SerialConfig {
        link_timeout_s: 1.0,
        ..SerialConfig::default()
    };
    let mut emu = emulator(1, patient());
    let log = SentLog::new(4096);
    emu.log_sent_to(Arc::clone(&log));
    let (pty, mut device, _) = link(emu, &config);
    pty.control().set_link_faults(LinkFaults {
        corrupt_byte_rate: 0.05,
        ..LinkFaults::default()
    });
    let start = Instant::now();
    let (mut checked, mut failed_reads) = (0, 0);
    while start.elapsed().as_secs_f64() < 2.0 {
        if device.read(0).is_err() {
            failed_reads += 1;
        }
        if let Some(snapshot) = device.last_report() {
            let sent = log.find(snapshot.seq).map(|f| f.message);
            assert_eq!(
                sent,
                Some(DeviceMessage::SensorReport(snapshot.report)),
                "report {}",
                snapshot.seq
            );
            checked += 1;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let (stats, emu_stats) = (device.stats(), status(&pty).stats);
    println!(
        "5 % corruption over 2 s: {} bytes corrupted; host took {} reports, dropped {} frames (crc {}, cobs {}), \
         counted {} lost; {checked} checks, {failed_reads} failed reads",
        emu_stats.bytes_corrupted,
        stats.reports,
        stats.rx.errors(),
        stats.rx.crc_errors,
        stats.rx.cobs_errors,
        stats.rx.lost
    );
    assert!(emu_stats.bytes_corrupted > 100, "{emu_stats:?}");
    assert!(stats.rx.errors() > 20 && stats.reports > 20, "{stats:?}");
    assert_eq!(emu_stats.rx.errors(), 0, "host → device was clean");
}

#[test]
fn dropped_frames_are_counted_exactly() {
    let (pty, mut device, _) = link(emulator(1, patient()), &tolerant());
    pty.control().set_link_faults(LinkFaults {
        drop_frame_rate: 0.2,
        ..LinkFaults::default()
    });
    let start = Instant::now();
    let mut failed_reads = 0;
    while start.elapsed().as_secs_f64() < 1.5 {
        failed_reads += usize::from(device.read(0).is_err());
        std::thread::sleep(Duration::from_millis(5));
    }
    // Stop the drops and let a few undropped frames show the last gap; then silence the device.
    pty.control().set_link_faults(LinkFaults::default());
    let mut sent_after = None;
    let clean = wait_for(2.0, || {
        let s = status(&pty);
        let base = *sent_after.get_or_insert(s.stats.frames_sent);
        s.link_faults == LinkFaults::default() && s.stats.frames_sent >= base + 3
    });
    assert!(clean.is_some(), "the emulator never sent clean frames");
    let mute = LinkFaults {
        mute: true,
        ..LinkFaults::default()
    };
    pty.control().set_link_faults(mute);
    assert!(
        wait_for(2.0, || status(&pty).link_faults == mute).is_some(),
        "never muted"
    );
    let dropped = status(&pty).stats.frames_dropped;
    // Every frame sent before the mute reaches the host: its count of gaps settles at the device's drops.
    let settled = wait_for(2.0, || device.stats().rx.lost >= dropped);
    let lost = device.stats().rx.lost;
    println!("20 % drops: device dropped {dropped}, host counted {lost} lost (settled after {settled:?} s); {failed_reads} failed reads");
    assert_eq!(lost, dropped, "host sequence gaps vs frames the device dropped");
    assert!(dropped > 10, "{dropped} drops");
    assert_eq!(device.stats().rx.errors(), 0);
}

#[test]
fn a_device_that_stops_answering_is_a_link_error_within_the_timeout() {
    let config = SerialConfig::default();
    let (pty, mut device, _) = link(emulator(1, patient()), &config);
    assert!(wait_for(2.0, || device.read(0).is_ok()).is_some(), "no reading");
    let muted_at = Instant::now();
    pty.control().set_link_faults(LinkFaults {
        mute: true,
        ..LinkFaults::default()
    });
    let mut error = None;
    let detected = wait_for(2.0, || match device.read(0) {
        Err(e) => {
            error = Some(e);
            true
        }
        Ok(_) => false,
    });
    let detected = detected.unwrap_or_else(|| panic!("no link error within 2 s of silence"));
    println!(
        "silent device detected {detected:.4} s after muting (timeout {} s): {error:?}",
        config.link_timeout_s
    );
    assert!(
        matches!(&error, Some(DeviceError::Link(m)) if m.to_string().contains("no sensor report")),
        "{error:?}"
    );
    assert!(
        detected >= config.link_timeout_s - 0.02,
        "detected after {detected} s, before the timeout"
    );
    assert!(detected < config.link_timeout_s + 0.5, "detected after {detected} s");
    // The device answers again: readings resume.
    pty.control().set_link_faults(LinkFaults::default());
    let recovered = wait_for(1.0, || device.read(0).is_ok());
    println!(
        "readings resumed {recovered:?} s after unmuting ({:.3} s muted)",
        muted_at.elapsed().as_secs_f64()
    );
    assert!(recovered.is_some(), "no recovery");
}

#[test]
fn a_vanished_port_is_a_link_error_not_a_panic() {
    let (pty, device, clock) = link(emulator(2, patient()), &tolerant());
    let mut control = ControlLoop::new(device, clock);
    control.run(0.1, &[0.5, 0.5]).iter().for_each(|r| {
        ok(r);
    });
    pty.control().close_port();
    let mut errors = Vec::new();
    let detected = wait_for(2.0, || {
        errors = control.tick(&[0.5, 0.5]);
        errors.iter().all(|r| r.is_err())
    });
    println!("vanished port detected after {detected:?} s: {:?}", errors.first());
    assert!(detected.is_some_and(|s| s < 1.0), "{errors:?}");
    assert!(
        errors.iter().all(|r| matches!(r, Err(DeviceError::Link(_)))),
        "{errors:?}"
    );
    drop(pty);
    // Every further call keeps failing cleanly; dropping the device does not hang or panic.
    assert!(matches!(control.device.read(0), Err(DeviceError::Link(_))));
    drop(control);
}

#[test]
fn the_watchdog_switches_drives_off_when_the_host_goes_silent() {
    let (pty, device, clock) = link(emulator(2, EmulatorConfig::default()), &tolerant());
    let mut control = ControlLoop::new(device, Arc::clone(&clock));
    let driven = wait_for(2.0, || {
        control.tick(&[1.0, -1.0]);
        std::thread::sleep(Duration::from_millis(10));
        status(&pty).applied_a[..2] == [1.0, -1.0]
    });
    assert!(driven.is_some(), "drives never on: {:?}", status(&pty).applied_a);
    control.run(0.1, &[1.0, -1.0]);
    let silent_from = clock.now_s();
    // The host goes silent (no read, no apply).
    let tripped = wait_for(2.0, || status(&pty).stats.watchdog_trips > 0);
    assert!(tripped.is_some(), "no watchdog trip within 2 s of silence");
    let trip = status(&pty)
        .stats
        .last_trip
        .unwrap_or_else(|| panic!("trip not recorded"));
    let delay = trip.time_s - trip.last_valid_s;
    println!(
        "watchdog: host silent from {silent_from:.4} s, last valid frame at {:.4} s, drives off at {:.4} s \
         ({delay:.4} s after it)",
        trip.last_valid_s, trip.time_s
    );
    assert!(
        delay > WATCHDOG_S && delay <= WATCHDOG_S + TICK_S + 1e-9,
        "drives off {delay} s after the last frame"
    );
    assert!(
        trip.last_valid_s <= silent_from + 0.5,
        "a frame after the host went silent?"
    );
    let off = wait_for(0.5, || {
        let s = status(&pty);
        s.applied_a[..2] == [0.0, 0.0] && s.commanded_a[..2] == [0.0, 0.0]
    });
    assert!(off.is_some(), "plant still driven: {:?}", status(&pty).applied_a);
    // The host learns of the latch from the next report.
    let mut after = control.device.read(0);
    wait_for(1.0, || {
        after = control.device.read(0);
        after.is_err()
    });
    println!("host after the trip: {after:?}");
    assert!(
        matches!(&after, Err(DeviceError::Link(m)) if m.to_string().contains("watchdog")),
        "{after:?}"
    );
    // Recovery: the host commands 0 A everywhere (as a faulted envelope does); the latch is released.
    let resumed = wait_for(1.0, || control.tick(&[0.0, 0.0]).iter().all(|r| r.is_ok()));
    println!("readings resumed {resumed:?} s after commanding 0 A");
    assert!(resumed.is_some(), "latch never released");
    assert!(!status(&pty).latched);
}

#[test]
fn a_missing_device_fails_the_handshake() {
    use serialport::{SerialPort, TTYPort};
    let (_master, slave) = TTYPort::pair().unwrap_or_else(|e| panic!("pty: {e}"));
    let path = slave.name().unwrap_or_else(|| panic!("no pty path"));
    let config = SerialConfig {
        handshake_timeout_s: 0.3,
        ..SerialConfig::default()
    };
    let started = Instant::now();
    let result = SerialDevice::open(&path, &config, Arc::new(MonotonicClock::new()));
    let waited = started.elapsed().as_secs_f64();
    println!("handshake with nobody: {result:?} after {waited:.3} s");
    assert!(
        matches!(&result, Err(DeviceError::Link(m)) if m.to_string().contains("no Identify")),
        "{result:?}"
    );
    assert!((0.29..2.0).contains(&waited), "gave up after {waited} s");
}

#[test]
fn bad_paths_and_settings_are_errors() {
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let missing = SerialDevice::open(
        "/dev/thermode-no-such-port",
        &SerialConfig::default(),
        Arc::clone(&clock),
    );
    assert!(matches!(missing, Err(DeviceError::Link(_))), "{missing:?}");
    let spec = SerialDevice::open_spec("sim", &SerialConfig::default(), Arc::clone(&clock));
    assert!(matches!(spec, Err(DeviceError::Link(_))), "{spec:?}");
    assert_eq!(serial_path("serial:/dev/ttyACM0"), Some("/dev/ttyACM0"));
    assert_eq!(serial_path("serial:"), None);
    assert_eq!(serial_path("sim"), None);
    let bad = SerialConfig {
        link_timeout_s: f64::NAN,
        ..SerialConfig::default()
    };
    assert!(matches!(
        SerialDevice::open("/dev/null", &bad, clock),
        Err(DeviceError::BadValue { .. })
    ));
}

/// The same link over a Unix socket pair instead of a pty (`SerialDevice::from_streams`, `Emulator::run` on any
/// `Read + Write`); dropping the host device sends `AllOff`, and the emulator ends when the host's end closes.
#[test]
fn runs_over_a_socket_pair_and_switches_off_on_drop() {
    use std::os::unix::net::UnixStream;
    use thermode_link::own::emulator::EmulatorControl;
    use thermode_link::runner::RunEnd;

    let (mut device_end, host_end) = UnixStream::pair().unwrap_or_else(|e| panic!("socket pair: {e}"));
    device_end
        .set_read_timeout(Some(Duration::from_millis(1)))
        .unwrap_or_else(|e| panic!("{e}"));
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let control = EmulatorControl::new();
    let emulator_thread = {
        let (clock, control) = (Arc::clone(&clock), Arc::clone(&control));
        let mut emu = emulator(1, patient());
        std::thread::spawn(move || emu.run(&mut device_end, clock.as_ref(), &control))
    };
    let reader = host_end.try_clone().unwrap_or_else(|e| panic!("{e}"));
    reader
        .set_read_timeout(Some(Duration::from_millis(5)))
        .unwrap_or_else(|e| panic!("{e}"));
    let device = SerialDevice::from_streams(
        "socket",
        Box::new(reader),
        Box::new(host_end),
        &tolerant(),
        Arc::clone(&clock),
    )
    .unwrap_or_else(|e| panic!("handshake over a socket: {e}"));
    let mut control_loop = ControlLoop::new(device, clock);
    let on = wait_for(2.0, || {
        control_loop.tick(&[0.8]);
        std::thread::sleep(Duration::from_millis(10));
        control.status().is_some_and(|s| s.commanded_a[0] == 0.8)
    });
    assert!(on.is_some(), "0.8 A never commanded");
    drop(control_loop);
    let off = wait_for(2.0, || control.status().is_some_and(|s| s.commanded_a[0] == 0.0));
    println!("AllOff on drop reached the device after {off:?} s");
    assert!(off.is_some(), "dropping the host left the drive on");
    let end = emulator_thread
        .join()
        .unwrap_or_else(|_| panic!("emulator thread panicked"));
    assert_eq!(end, Ok(RunEnd::HostClosed));
}

/// A device whose watchdog is longer than the host accepts is refused at the handshake, with one error naming both
/// periods, and its drives are never released.
#[test]
fn a_device_with_a_slow_watchdog_is_refused() {
    let config = EmulatorConfig {
        watchdog_ms: MAX_DEVICE_WATCHDOG_MS + 1,
        ..EmulatorConfig::default()
    };
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let pty = PtyEmulator::spawn(emulator(1, config), Arc::clone(&clock)).unwrap_or_else(|e| panic!("pty: {e}"));
    let result = SerialDevice::open(pty.path(), &SerialConfig::default(), clock);
    let message = result.as_ref().map_err(ToString::to_string).err().unwrap_or_default();
    println!("{message}");
    assert!(
        matches!(
            result,
            Err(DeviceError::WatchdogTooLong {
                device_ms: 251,
                max_ms: 250,
                ..
            })
        ),
        "{result:?}"
    );
    assert!(
        message.contains("251 ms") && message.contains("250 ms") && !message.contains('\n'),
        "{message}"
    );
    assert!(status(&pty).latched, "the refused device's drives were released");
}

/// The device's own over-temperature cut reaches the host as a typed error on that channel; the host holds 0 A,
/// sends `ClearFault`, and readings resume once the device released the cut (its plate back inside).
#[test]
fn the_device_cut_reaches_the_host_and_is_released_back_inside() {
    use thermode_device::DeviceCut;
    let mut emu = emulator(1, EmulatorConfig::default());
    emu.display_mut()
        .channel_mut(0)
        .and_then(|c| c.set_temperatures(45.0, 25.0))
        .unwrap_or_else(|e| panic!("{e}"));
    let (pty, device, clock) = link(emu, &tolerant());
    let mut control = ControlLoop::new(device, clock);
    let mut last = Vec::new();
    let cut = wait_for(3.0, || {
        last = control.tick(&[2.8]);
        std::thread::sleep(Duration::from_millis(5));
        matches!(last[0], Err(DeviceError::Cut { .. }))
    });
    let s = status(&pty);
    println!(
        "cut seen by the host after {cut:?} s: {:?}; device trip {:?}",
        last[0], s.stats.last_guard_trip
    );
    assert!(cut.is_some(), "no cut: {last:?}");
    assert!(
        matches!(
            last[0],
            Err(DeviceError::Cut {
                channel: 0,
                cut: DeviceCut::OverTemperature,
                reading: Some(_),
            })
        ),
        "{last:?}"
    );
    let peak = s.stats.last_guard_trip.map_or(f64::NAN, |t| t.plate_c);
    assert!(peak < 48.0, "plate at the cut {peak} °C");
    assert!(s.cuts[0].heating && s.applied_a[0] == 0.0, "{s:?}");
    // The host holds 0 A (as a faulted envelope does): ClearFault goes out and the device releases the cut once
    // its plate is back inside; readings resume.
    let resumed = wait_for(10.0, || {
        let r = control.tick(&[0.0]);
        std::thread::sleep(Duration::from_millis(5));
        r[0].is_ok()
    });
    let s = status(&pty);
    println!(
        "readings resumed {resumed:?} s later, plate {:.2} °C; host sent {} ClearFault",
        s.plate_c[0],
        control.device.stats().clear_faults
    );
    assert!(resumed.is_some() && !s.cuts[0].heating, "cut never released: {s:?}");
    assert!(s.plate_c[0] < 47.0, "released at {} °C", s.plate_c[0]);
}
