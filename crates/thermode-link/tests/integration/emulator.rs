//! The emulated firmware without any I/O: bytes in at chosen times, reports out. Checks the handshake state
//! machine, the report schedule, that reports carry the plant's own values, the watchdog's timing (off within one
//! period plus one tick), refusal of bad input, fault flags, link-fault injection, catching up, and the real-time
//! loop over an in-memory port with a manual clock.

use std::io::{self, Read, Write};
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use thermode_device::{DeviceConfig, Fault, Polarity, SimulatedDisplay};
use thermode_link::own::codec::{
    encode_frame, to_milli_c, write_frame, ChannelFaults, DeviceMessage, DriveFrame, Frame, HostMessage, LinkCounters,
    NackCode, ReportFlags, SensorReport, StreamDecoder,
};
use thermode_link::own::emulator::{Emulator, EmulatorConfig, EmulatorControl, LinkFaults, SentLog, EMULATOR_FIRMWARE};
use thermode_link::runner::{EmulatorError, RunEnd};
use thermode_model::kron::KronModel;
use thermode_platform::{Clock, ManualClock};

const TICK_S: f64 = 1e-3;
const WATCHDOG_S: f64 = 0.25;

fn emulator(channels: usize, config: EmulatorConfig) -> Emulator<KronModel> {
    let display = SimulatedDisplay::<KronModel>::fingertips(&DeviceConfig::default(), channels, 7)
        .unwrap_or_else(|e| panic!("display: {e}"));
    Emulator::new(display, config).unwrap_or_else(|e| panic!("emulator: {e}"))
}

/// The host end of an in-memory link.
#[derive(Default)]
struct Host {
    seq: u16,
    decoder: StreamDecoder<DeviceMessage>,
    inbox: Vec<Frame<DeviceMessage>>,
}

impl Host {
    fn send(&mut self, emu: &mut Emulator<KronModel>, message: HostMessage, now_s: f64) -> u16 {
        let mut bytes = Vec::new();
        encode_frame(self.seq, &message, &mut bytes).unwrap_or_else(|e| panic!("{e}"));
        self.seq = self.seq.wrapping_add(1);
        self.raw(emu, &bytes, now_s);
        self.seq.wrapping_sub(1)
    }

    fn raw(&mut self, emu: &mut Emulator<KronModel>, bytes: &[u8], now_s: f64) {
        let mut out = Vec::new();
        emu.receive(bytes, now_s, &mut out);
        self.take(&out);
    }

    fn run(&mut self, emu: &mut Emulator<KronModel>, now_s: f64) {
        let mut out = Vec::new();
        emu.advance_to(now_s, &mut out);
        self.take(&out);
    }

    /// Runs to `until_s` in 10 ms steps, as a real-time loop would (never far enough behind to catch up).
    fn run_to(&mut self, emu: &mut Emulator<KronModel>, until_s: f64) {
        let mut t = emu.time_s();
        while t < until_s {
            t = (t + 0.01).min(until_s);
            self.run(emu, t);
        }
    }

    fn take(&mut self, bytes: &[u8]) {
        let inbox = &mut self.inbox;
        self.decoder.feed(bytes, |r| {
            if let Ok(frame) = r {
                inbox.push(frame);
            }
        });
    }

    fn reports(&self) -> Vec<(u16, SensorReport)> {
        self.inbox
            .iter()
            .filter_map(|f| match f.message {
                DeviceMessage::SensorReport(r) => Some((f.seq, r)),
                _ => None,
            })
            .collect()
    }

    fn last_report(&self) -> SensorReport {
        self.reports()
            .last()
            .map(|r| r.1)
            .unwrap_or_else(|| panic!("no report yet"))
    }

    fn replies(&self) -> Vec<DeviceMessage> {
        self.inbox
            .iter()
            .map(|f| f.message)
            .filter(|m| !matches!(m, DeviceMessage::SensorReport(_)))
            .collect()
    }

    fn counters(&self) -> LinkCounters {
        *self.decoder.counters()
    }
}

fn drive(first: usize, currents_ma: &[i16]) -> HostMessage {
    HostMessage::Drive(DriveFrame::new(first, currents_ma).unwrap_or_else(|e| panic!("{e}")))
}

/// Hello, ClearFault at t = 0: a running emulator.
fn running(channels: usize, config: EmulatorConfig) -> (Emulator<KronModel>, Host) {
    let mut emu = emulator(channels, config);
    let mut host = Host::default();
    host.send(&mut emu, HostMessage::Hello, 0.0);
    host.send(&mut emu, HostMessage::ClearFault, 0.0);
    (emu, host)
}

#[test]
fn hello_is_answered_with_identify() {
    let mut emu = emulator(3, EmulatorConfig::default());
    let mut host = Host::default();
    host.send(&mut emu, HostMessage::Hello, 0.0);
    let DeviceMessage::Identify(id) = host.replies()[0] else {
        panic!("no identify: {:?}", host.replies());
    };
    assert_eq!(id.channel_count, 3);
    assert_eq!(id.firmware, EMULATOR_FIRMWARE);
    assert_eq!(id.current_limit_ma, 2800, "the default drive limit is 2.8 A");
    assert_eq!((id.watchdog_ms, id.report_interval_ms), (250, 10));
}

#[test]
fn starts_latched_and_refuses_drives_until_cleared() {
    let mut emu = emulator(2, EmulatorConfig::default());
    let mut host = Host::default();
    let seq = host.send(&mut emu, drive(0, &[1000, 1000]), 0.001);
    assert_eq!(
        host.replies(),
        vec![DeviceMessage::Nack {
            seq,
            code: NackCode::Latched
        }]
    );
    host.run(&mut emu, 0.05);
    let report = host.last_report();
    assert_eq!(
        report.flags,
        ReportFlags(ReportFlags::LATCHED),
        "power-up latch, not the watchdog"
    );
    for ch in report.channels() {
        assert_eq!(ch.applied_ma, 0);
        assert!(ch.faults.has(ChannelFaults::LATCHED_OFF));
    }
    let clear = host.send(&mut emu, HostMessage::ClearFault, 0.05);
    assert_eq!(host.replies().last(), Some(&DeviceMessage::Ack { seq: clear }));
    let last = host.send(&mut emu, drive(0, &[1000, -500]), 0.05);
    host.run(&mut emu, 0.07);
    let report = host.last_report();
    assert_eq!(report.flags, ReportFlags(0));
    assert_eq!(report.last_command_seq, last);
    let applied: Vec<i16> = report.channels().iter().map(|c| c.applied_ma).collect();
    assert_eq!(applied, vec![1000, -500]);
}

/// Reports come every 10 ms with a new 100 Hz sample each, and carry exactly what the plant's own sensor reads: a
/// twin display stepped with the same currents and 1 ms steps gives the same readings.
#[test]
fn reports_carry_the_plant_readings_at_the_report_rate() {
    let config = EmulatorConfig {
        watchdog_ms: 60_000,
        ..EmulatorConfig::default()
    };
    let (mut emu, mut host) = running(3, config);
    host.send(&mut emu, drive(0, &[1000, -1000, 0]), 0.0);
    let mut twin =
        SimulatedDisplay::<KronModel>::fingertips(&DeviceConfig::default(), 3, 7).unwrap_or_else(|e| panic!("{e}"));
    let mut twin_readings = Vec::new();
    for tick in 1..=1000u32 {
        for (i, current_a) in [1.0, -1.0, 0.0].into_iter().enumerate() {
            twin.channel_mut(i)
                .unwrap_or_else(|e| panic!("{e}"))
                .step(TICK_S, current_a);
        }
        if tick % 10 == 0 {
            let c: Vec<i32> = (0..3)
                .map(|i| to_milli_c(twin.channel(i).map(|c| c.state().sensor.value_c).unwrap_or(f64::NAN)))
                .collect();
            twin_readings.push(c);
        }
    }
    host.run_to(&mut emu, 1.0);
    let reports = host.reports();
    assert_eq!(reports.len(), 100, "reports in 1 s at 10 ms");
    for (k, (_, report)) in reports.iter().enumerate() {
        assert_eq!(report.device_time_ms, 10 * (k as u32 + 1), "report {k}");
        let sensors: Vec<i32> = report.channels().iter().map(|c| c.sensor_milli_c).collect();
        assert_eq!(sensors, twin_readings[k], "report {k}: emulator vs twin plant");
        for ch in report.channels() {
            assert!(ch.sample_age_ms <= 1, "report {k}: sample age {} ms", ch.sample_age_ms);
        }
        if k > 0 {
            for (now, before) in report.channels().iter().zip(reports[k - 1].1.channels()) {
                assert_eq!(
                    now.sample_seq.wrapping_sub(before.sample_seq),
                    1,
                    "report {k}: one new sample"
                );
            }
        }
    }
    let last = reports[99].1.channels().to_vec();
    let first = reports[0].1.channels().to_vec();
    // The undriven plate drifts towards the finger; heating and cooling move the others apart from it.
    let (heated, cooled, undriven) = (last[0].sensor_c(), last[1].sensor_c(), last[2].sensor_c());
    assert!(
        heated > first[0].sensor_c() + 1.0,
        "heated: {} → {heated}",
        first[0].sensor_c()
    );
    assert!(
        cooled < first[1].sensor_c() - 1.0,
        "cooled: {} → {cooled}",
        first[1].sensor_c()
    );
    assert!(
        heated > undriven + 1.0 && cooled < undriven - 1.0,
        "{heated}, {cooled} vs undriven {undriven}"
    );
}

#[test]
fn watchdog_switches_drives_off_within_one_period_and_a_tick() {
    let (mut emu, mut host) = running(2, EmulatorConfig::default());
    host.send(&mut emu, drive(0, &[2000, -2000]), 0.0);
    // Heartbeats every 80 ms (< 250 ms / 3) for 1 s keep the drives on.
    let mut t = 0.0;
    while t < 1.0 {
        t += 0.08;
        host.send(&mut emu, HostMessage::Heartbeat, t);
    }
    let last_valid = t;
    assert_eq!(emu.stats().watchdog_trips, 0);
    assert_eq!(emu.commanded_current_a(0), 2.0);
    // Silence: tick by tick until the trip.
    let mut tick = (last_valid / TICK_S).round() as u64;
    while !emu.latched() {
        tick += 1;
        host.run(&mut emu, tick as f64 * TICK_S);
        assert!(tick as f64 * TICK_S < last_valid + 1.0, "no trip within 1 s");
    }
    let trip = emu.stats().last_trip.unwrap_or_else(|| panic!("trip not recorded"));
    let delay = trip.time_s - trip.last_valid_s;
    println!(
        "watchdog: last valid frame {:.4} s, trip {:.4} s, delay {delay:.4} s",
        trip.last_valid_s, trip.time_s
    );
    assert!((trip.last_valid_s - last_valid).abs() < 1e-12);
    assert!(
        delay > WATCHDOG_S && delay <= WATCHDOG_S + TICK_S + 1e-9,
        "trip {delay} s after the last frame"
    );
    assert_eq!((emu.commanded_current_a(0), emu.commanded_current_a(1)), (0.0, 0.0));
    // From the trip on no current flows: the plant's next step delivers 0 A.
    host.run(&mut emu, trip.time_s + TICK_S);
    for ch in 0..2 {
        let applied = emu
            .display()
            .channel(ch)
            .map(|c| c.state().applied_current_a)
            .unwrap_or(f64::NAN);
        assert_eq!(applied, 0.0, "channel {ch} after the trip");
    }
    host.run(&mut emu, trip.time_s + 0.02);
    let report = host.last_report();
    assert_eq!(
        report.flags,
        ReportFlags(ReportFlags::LATCHED | ReportFlags::WATCHDOG_EXPIRED)
    );
    assert!(report
        .channels()
        .iter()
        .all(|c| c.applied_ma == 0 && c.faults.has(ChannelFaults::LATCHED_OFF)));
    // Drives stay refused until ClearFault.
    let now = trip.time_s + 0.03;
    let seq = host.send(&mut emu, drive(0, &[500, 500]), now);
    assert_eq!(
        host.replies().last(),
        Some(&DeviceMessage::Nack {
            seq,
            code: NackCode::Latched
        })
    );
    host.send(&mut emu, HostMessage::ClearFault, now);
    host.send(&mut emu, drive(0, &[500, 500]), now);
    assert_eq!(emu.commanded_current_a(1), 0.5);
}

#[test]
fn heartbeats_slower_than_the_period_trip_the_watchdog() {
    let (mut emu, mut host) = running(1, EmulatorConfig::default());
    for k in 1..=10 {
        host.send(&mut emu, HostMessage::Heartbeat, k as f64 * 0.2);
    }
    assert_eq!(
        emu.stats().watchdog_trips,
        0,
        "200 ms heartbeats keep a 250 ms watchdog fed"
    );
    host.run_to(&mut emu, 2.0 + 0.3);
    assert_eq!(emu.stats().watchdog_trips, 1, "a 300 ms gap trips it");
}

#[test]
fn bad_input_is_dropped_counted_and_answered() {
    let (mut emu, mut host) = running(3, EmulatorConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let noise: Vec<u8> = (0..20_000)
        .map(|_| if rng.gen_bool(0.05) { 0 } else { rng.gen() })
        .collect();
    host.raw(&mut emu, &noise, 0.01);
    let rx = emu.stats().rx;
    println!("noise: {rx:?}");
    assert!(rx.errors() > 100, "noise frames counted: {rx:?}");
    assert_eq!(rx.frames, 2, "only Hello and ClearFault were valid");
    assert!((0..3).all(|ch| emu.commanded_current_a(ch) == 0.0));

    // A drive frame with one byte flipped is dropped without an answer.
    let mut bytes = Vec::new();
    encode_frame(100, &drive(0, &[1000, 1000, 1000]), &mut bytes).unwrap_or_else(|e| panic!("{e}"));
    bytes[5] ^= 0x40;
    let replies = host.replies().len();
    host.raw(&mut emu, &bytes, 0.02);
    assert_eq!(emu.commanded_current_a(0), 0.0);
    assert_eq!(host.replies().len(), replies, "no answer to a corrupted frame");

    // CRC-valid frames with a bad version, type, body or channel are refused with a Nack naming them.
    let cases: [(Vec<u8>, u16, NackCode); 4] = [
        (vec![2, 0x02, 0x10, 0x00], 0x10, NackCode::UnsupportedVersion),
        (vec![1, 0x42, 0x11, 0x00], 0x11, NackCode::UnknownType),
        (vec![1, 0x02, 0x12, 0x00, 0xFF], 0x12, NackCode::Malformed),
        (
            vec![1, 0x03, 0x13, 0x00, 2, 2, 0xE8, 0x03, 0xE8, 0x03],
            0x13,
            NackCode::BadChannel,
        ),
    ];
    for (payload, seq, code) in cases {
        let mut bytes = Vec::new();
        write_frame(&payload, &mut bytes).unwrap_or_else(|e| panic!("{e}"));
        host.raw(&mut emu, &bytes, 0.03);
        assert_eq!(
            host.replies().last(),
            Some(&DeviceMessage::Nack { seq, code }),
            "payload {payload:02x?}"
        );
    }
    assert!(
        (0..3).all(|ch| emu.commanded_current_a(ch) == 0.0),
        "nothing refused was applied"
    );
}

#[test]
fn garbage_does_not_feed_the_watchdog() {
    let (mut emu, mut host) = running(1, EmulatorConfig::default());
    host.send(&mut emu, drive(0, &[1000]), 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for k in 1..=40 {
        let noise: Vec<u8> = (0..64).map(|_| rng.gen()).collect();
        host.raw(&mut emu, &noise, k as f64 * 0.01);
    }
    let trip = emu.stats().last_trip.unwrap_or_else(|| panic!("no trip under garbage"));
    assert_eq!(trip.last_valid_s, 0.0);
    assert!(trip.time_s <= WATCHDOG_S + TICK_S + 1e-9, "trip at {} s", trip.time_s);
}

#[test]
fn over_limit_and_plant_faults_are_flagged() {
    let (mut emu, mut host) = running(3, EmulatorConfig::default());
    host.send(&mut emu, drive(0, &[5000, 0, 0]), 0.0);
    let display = emu.display_mut();
    display
        .channel_mut(1)
        .unwrap_or_else(|e| panic!("{e}"))
        .inject(Fault::SensorOpen)
        .ok();
    display
        .channel_mut(2)
        .unwrap_or_else(|e| panic!("{e}"))
        .inject(Fault::DriveStuck {
            polarity: Polarity::Cooling,
        })
        .ok();
    for k in 1..=5 {
        host.send(&mut emu, HostMessage::Heartbeat, k as f64 * 0.01);
    }
    let report = host.last_report();
    let ch = report.channels();
    assert_eq!(ch[0].applied_ma, 2800, "clamped to the limit");
    assert!(ch[0].faults.has(ChannelFaults::CURRENT_LIMITED) && !ch[0].faults.has(ChannelFaults::DRIVE_FAULT));
    assert!(
        ch[1].faults.has(ChannelFaults::SENSOR_OPEN),
        "faults {:?}",
        ch[1].faults
    );
    assert!(ch[1].sensor_c() >= 400.0, "open sensor reads {}", ch[1].sensor_c());
    assert!(
        ch[2].faults.has(ChannelFaults::DRIVE_FAULT),
        "faults {:?}",
        ch[2].faults
    );
    assert_eq!(ch[2].applied_ma, -2800, "stuck drive delivers its limit");
}

#[test]
fn dropped_frames_are_exactly_the_host_sequence_gaps() {
    let config = EmulatorConfig {
        watchdog_ms: 60_000,
        fault_seed: 3,
        ..EmulatorConfig::default()
    };
    let (mut emu, mut host) = running(2, config);
    emu.set_link_faults(LinkFaults {
        drop_frame_rate: 0.2,
        ..LinkFaults::default()
    })
    .unwrap_or_else(|e| panic!("{e}"));
    host.run_to(&mut emu, 5.0);
    // The frame after the last drop shows the gap; end with an undropped frame.
    emu.set_link_faults(LinkFaults::default())
        .unwrap_or_else(|e| panic!("{e}"));
    host.run(&mut emu, 5.01);
    let stats = emu.stats();
    let fraction = stats.frames_dropped as f64 / stats.reports as f64;
    println!(
        "dropped {} of {} reports ({fraction:.3}), host counted {} lost",
        stats.frames_dropped,
        stats.reports,
        host.counters().lost
    );
    assert_eq!(host.counters().lost, stats.frames_dropped, "host gaps vs device drops");
    assert!((0.15..0.25).contains(&fraction), "drop fraction {fraction} vs 0.2");
    assert_eq!(host.counters().errors(), 0);
}

#[test]
fn corrupted_bytes_never_pass_as_wrong_reports() {
    let config = EmulatorConfig {
        watchdog_ms: 60_000,
        fault_seed: 9,
        ..EmulatorConfig::default()
    };
    let (mut emu, mut host) = running(1, config);
    let log = SentLog::new(1024);
    emu.log_sent_to(Arc::clone(&log));
    emu.set_link_faults(LinkFaults {
        corrupt_byte_rate: 0.05,
        ..LinkFaults::default()
    })
    .unwrap_or_else(|e| panic!("{e}"));
    host.inbox.clear();
    host.run_to(&mut emu, 5.0);
    let stats = emu.stats();
    let counters = host.counters();
    println!(
        "corrupted {} bytes; host took {} frames, dropped {} (crc {}, cobs {}, short {}), lost {}",
        stats.bytes_corrupted,
        counters.frames,
        counters.errors(),
        counters.crc_errors,
        counters.cobs_errors,
        counters.too_short,
        counters.lost
    );
    assert!(counters.errors() > 100 && host.inbox.len() > 50, "{counters:?}");
    for frame in &host.inbox {
        assert_eq!(
            log.find(frame.seq).map(|f| f.message),
            Some(frame.message),
            "frame {}",
            frame.seq
        );
    }
    let byte_rate = stats.bytes_corrupted as f64 / counters.bytes as f64;
    assert!((0.04..0.06).contains(&byte_rate), "corrupted fraction {byte_rate}");
}

#[test]
fn a_muted_device_sends_nothing_but_keeps_its_watchdog() {
    let (mut emu, mut host) = running(1, EmulatorConfig::default());
    host.send(&mut emu, drive(0, &[1000]), 0.0);
    emu.set_link_faults(LinkFaults {
        mute: true,
        ..LinkFaults::default()
    })
    .unwrap_or_else(|e| panic!("{e}"));
    let before = host.inbox.len();
    host.send(&mut emu, HostMessage::Hello, 0.1);
    host.run_to(&mut emu, 1.0);
    assert_eq!(host.inbox.len(), before, "nothing sent while muted");
    assert_eq!(emu.stats().watchdog_trips, 1);
    emu.set_link_faults(LinkFaults::default())
        .unwrap_or_else(|e| panic!("{e}"));
    host.run(&mut emu, 1.02);
    assert_eq!(host.counters().lost, 0, "muting uses up no sequence numbers");
}

/// Falling 10 s behind in one call: plant steps are merged at the report ticks, old reports skipped, and the plant
/// ends where tick-by-tick stepping takes it (first-order implicit scheme: 10 ms vs 1 ms steps).
#[test]
fn catching_up_merges_plant_steps() {
    let config = EmulatorConfig {
        watchdog_ms: 60_000,
        ..EmulatorConfig::default()
    };
    let (mut fast, mut host_fast) = running(1, config);
    let (mut slow, mut host_slow) = running(1, config);
    host_fast.send(&mut fast, drive(0, &[800]), 0.0);
    host_slow.send(&mut slow, drive(0, &[800]), 0.0);
    host_fast.run(&mut fast, 10.0);
    for k in 1..=10_000 {
        host_slow.run(&mut slow, k as f64 * TICK_S);
    }
    let stats = fast.stats();
    let plate = |e: &Emulator<KronModel>| e.display().channel(0).map(|c| c.state().plate_c).unwrap_or(f64::NAN);
    let (merged, stepped) = (plate(&fast), plate(&slow));
    println!(
        "catch-up: skipped {} reports, merged {} ticks; plate {merged:.4} vs {stepped:.4} °C",
        stats.reports_skipped, stats.merged_ticks
    );
    assert_eq!(
        stats.reports_skipped, 989,
        "only the reports of the last 0.1 s are sent"
    );
    assert_eq!(host_fast.reports().len(), 11);
    assert_eq!(stats.merged_ticks, 9000, "9 of every 10 ticks merged");
    assert!(
        (merged - stepped).abs() < 0.02,
        "merged {merged} vs stepped {stepped} °C"
    );
    assert!(stepped > 30.0, "0.8 A for 10 s heats the plate: {stepped} °C");
}

#[test]
fn settings_are_validated() {
    let display =
        || SimulatedDisplay::<KronModel>::fingertips(&DeviceConfig::default(), 1, 0).unwrap_or_else(|e| panic!("{e}"));
    for config in [
        EmulatorConfig {
            watchdog_ms: 5,
            ..EmulatorConfig::default()
        },
        EmulatorConfig {
            report_interval_ms: 0,
            ..EmulatorConfig::default()
        },
        EmulatorConfig {
            tick_s: f64::NAN,
            ..EmulatorConfig::default()
        },
        EmulatorConfig {
            max_catch_up_s: 0.0,
            ..EmulatorConfig::default()
        },
    ] {
        assert!(
            matches!(Emulator::new(display(), config), Err(EmulatorError::BadSetting { .. })),
            "{config:?} accepted"
        );
    }
    let mut emu = emulator(1, EmulatorConfig::default());
    for faults in [
        LinkFaults {
            corrupt_byte_rate: 1.5,
            ..LinkFaults::default()
        },
        LinkFaults {
            drop_frame_rate: f64::NAN,
            ..LinkFaults::default()
        },
    ] {
        assert!(emu.set_link_faults(faults).is_err(), "{faults:?} accepted");
    }
}

/// An in-memory port for [`Emulator::run`]: each read hands over the next scripted chunk and moves the manual
/// clock by a millisecond; what the emulator writes is kept.
struct ScriptedPort {
    clock: Arc<ManualClock>,
    script: Vec<Vec<u8>>,
    reads: usize,
    written: Vec<u8>,
    control: Arc<EmulatorControl>,
    end: End,
}

/// How a scripted port ends after 500 reads.
#[derive(Clone, Copy)]
enum End {
    /// Asks the emulator to stop.
    Stop,
    /// Reads 0 bytes (end of file).
    Eof,
    /// Fails with an I/O error (EIO, as a vanished USB device).
    Fail,
    /// The other end closed (a broken pipe).
    Gone,
}

impl Read for ScriptedPort {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.clock.advance(TICK_S);
        self.reads += 1;
        if let Some(chunk) = self.script.get(self.reads - 1) {
            buf[..chunk.len()].copy_from_slice(chunk);
            return Ok(chunk.len());
        }
        if self.reads >= 500 {
            return match self.end {
                End::Stop => {
                    self.control.stop();
                    Err(io::Error::new(io::ErrorKind::TimedOut, "idle"))
                }
                End::Eof => Ok(0),
                End::Fail => Err(io::Error::other("input/output error")),
                End::Gone => Err(io::Error::new(io::ErrorKind::BrokenPipe, "broken pipe")),
            };
        }
        Err(io::Error::new(io::ErrorKind::TimedOut, "idle"))
    }
}

impl Write for ScriptedPort {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.written.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

fn scripted(end: End) -> (ScriptedPort, Arc<EmulatorControl>) {
    let mut script = Vec::new();
    for (seq, message) in [
        (0u16, HostMessage::Hello),
        (1, HostMessage::ClearFault),
        (2, drive(0, &[700])),
    ] {
        let mut bytes = Vec::new();
        encode_frame(seq, &message, &mut bytes).unwrap_or_else(|e| panic!("{e}"));
        script.push(bytes);
    }
    let control = EmulatorControl::new();
    let port = ScriptedPort {
        clock: Arc::new(ManualClock::new()),
        script,
        reads: 0,
        written: Vec::new(),
        control: Arc::clone(&control),
        end,
    };
    (port, control)
}

#[test]
fn runs_over_an_in_memory_port_on_a_manual_clock() {
    let (mut port, control) = scripted(End::Stop);
    let mut emu = emulator(1, EmulatorConfig::default());
    let clock = port.clock.clone();
    let end = emu.run(&mut port, clock.as_ref(), &control);
    assert_eq!(end, Ok(RunEnd::Stopped));
    let status = control.status().unwrap_or_else(|| panic!("no status published"));
    assert!(
        (status.time_s - 0.5).abs() < 1e-9,
        "emulator time {} after 500 reads of 1 ms",
        status.time_s
    );
    // The watchdog ran on the manual clock: the drive frame came at 3 ms, the trip one period and a tick later.
    let trip = status.stats.last_trip.unwrap_or_else(|| panic!("no trip"));
    assert!(
        (trip.last_valid_s - 0.003).abs() < 1e-9,
        "last valid frame at {} s",
        trip.last_valid_s
    );
    assert!((trip.time_s - 0.254).abs() < 1e-9, "trip at {} s", trip.time_s);
    assert!(status.latched && status.commanded_a[0] == 0.0);
    let mut decoder = StreamDecoder::<DeviceMessage>::new();
    let mut reports = 0;
    decoder.feed(&port.written, |r| {
        if let Ok(Frame {
            message: DeviceMessage::SensorReport(_),
            ..
        }) = r
        {
            reports += 1;
        }
    });
    assert_eq!(reports, 50, "reports at 10, 20, …, 500 ms");
    assert!(clock.now_s() > 0.49);
}

#[test]
fn a_failing_port_ends_the_run_with_an_error() {
    let (mut port, control) = scripted(End::Fail);
    let mut emu = emulator(1, EmulatorConfig::default());
    let clock = port.clock.clone();
    assert!(matches!(
        emu.run(&mut port, clock.as_ref(), &control),
        Err(EmulatorError::Io(_))
    ));
    let (mut port, control) = scripted(End::Eof);
    assert_eq!(emu.run(&mut port, clock.as_ref(), &control), Ok(RunEnd::HostClosed));
    let (mut port, _) = scripted(End::Gone);
    assert_eq!(emu.run(&mut port, clock.as_ref(), &control), Ok(RunEnd::HostClosed));
    control.close_port();
    assert_eq!(emu.run(&mut port, clock.as_ref(), &control), Ok(RunEnd::PortClosed));
}
