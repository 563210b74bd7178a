//! The `Device` trait on the simulated display: channel counts, independent channels and noise streams, readings
//! as the envelope takes them, gated commands from the real safety envelope, and the recording wrapper.

use thermode_device::{Device, DeviceConfig, DeviceError, RecordingDevice, SimulatedDisplay, MAX_CHANNELS};
use thermode_model::kron::KronModel;
use thermode_safety::{EnvelopeConfig, MeasuredOnly, SafetyEnvelope};

fn display(count: usize) -> SimulatedDisplay<KronModel> {
    SimulatedDisplay::fingertips(&DeviceConfig::default(), count, 21).unwrap_or_else(|e| panic!("{e}"))
}

fn envelope() -> SafetyEnvelope {
    SafetyEnvelope::new(EnvelopeConfig::default(), 2.8).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn channel_counts_are_checked() {
    for bad in [0, MAX_CHANNELS + 1] {
        let result = SimulatedDisplay::<KronModel>::fingertips(&DeviceConfig::default(), bad, 1);
        assert_eq!(
            result.map(|d| d.channel_count()).err(),
            Some(DeviceError::ChannelCount { count: bad, max: 10 })
        );
    }
    let mut d = display(MAX_CHANNELS);
    assert_eq!(d.channel_count(), 10);
    assert_eq!(
        d.read(10).err(),
        Some(DeviceError::NoSuchChannel { channel: 10, count: 10 })
    );
    let command = envelope().gate_drive(0.0, 1.0, &MeasuredOnly);
    assert_eq!(
        d.apply(12, &command).err(),
        Some(DeviceError::NoSuchChannel { channel: 12, count: 10 })
    );
}

#[test]
fn gated_commands_drive_only_their_channel_and_the_recorder_sees_every_one() {
    let mut device = RecordingDevice::new(display(3));
    let mut envelopes = [envelope(), envelope(), envelope()];
    let dt = 0.01;
    let mut sent = Vec::new();
    for n in 0..300 {
        let now = n as f64 * dt;
        for (channel, env) in envelopes.iter_mut().enumerate() {
            let reading = device.read(channel).unwrap_or_else(|e| panic!("{e}"));
            env.observe(&reading.measurement());
            // Channel 0 heats, channel 1 cools, channel 2 is asked for nothing.
            let request = [1.0, -1.0, 0.0][channel];
            let command = env.gate_drive(now, request, &MeasuredOnly);
            sent.push((now, channel, command.current_a()));
            device.apply(channel, &command).unwrap_or_else(|e| panic!("{e}"));
        }
        device.poll((n + 1) as f64 * dt);
    }
    let record = device.commands();
    assert_eq!(record.len(), 900);
    assert!(record.iter().all(|c| c.accepted && c.fault.is_none()));
    assert_eq!(
        (
            record[0].channel,
            record[1].channel,
            record[2].channel,
            record[3].channel
        ),
        (0, 1, 2, 0)
    );
    assert!(
        (record[899].time_s - 2.99).abs() < 1e-9,
        "time of the last command {}",
        record[899].time_s
    );
    for (c, &(now, channel, current_a)) in record.iter().zip(&sent) {
        assert_eq!((c.channel, c.current_a), (channel, current_a), "command at {now} s");
        assert!(
            (c.time_s - now).abs() < 1e-9,
            "recorded at {} s, sent at {now} s",
            c.time_s
        );
    }
    // The envelope passed the requests until the cooled channel reached its 15 °C minimum.
    assert_eq!(
        (record[0].current_a, record[1].current_a, record[2].current_a),
        (1.0, -1.0, 0.0)
    );
    let (inner, _) = device.into_parts();
    let plates: Vec<f64> = (0..3)
        .map(|i| inner.channel(i).map_or(f64::NAN, |c| c.state().plate_c))
        .collect();
    assert!(
        plates[0] > plates[2] + 1.0 && plates[1] < plates[2] - 1.0,
        "plates {plates:?}"
    );
    let applied: Vec<f64> = (0..3)
        .map(|i| inner.channel(i).map_or(f64::NAN, |c| c.state().applied_current_a))
        .collect();
    let last: Vec<f64> = sent[897..].iter().map(|s| s.2).collect();
    assert_eq!(applied, last);
}

#[test]
fn readings_match_the_channel_and_channels_have_their_own_noise() {
    let mut d = display(2);
    for _ in 0..50 {
        d.advance(0.01);
    }
    let r = d.read(0).unwrap_or_else(|e| panic!("{e}"));
    let state = *d.channel(0).map(|c| c.state()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        (r.sensor_c, r.time_s, r.sample_seq),
        (state.sensor.value_c, state.sensor.time_s, state.sensor.seq)
    );
    assert!(
        (r.hot_side_c - state.hot_side_c).abs() <= 0.005 + 1e-12,
        "hot side {} vs {}",
        r.hot_side_c,
        state.hot_side_c
    );
    assert!(
        (r.time_s - 0.5).abs() < 1e-9 && r.sample_seq == 50,
        "sample {} at {}",
        r.sample_seq,
        r.time_s
    );
    let m = r.measurement();
    assert_eq!(
        (m.time_s, m.sensor_c, m.hot_side_c, m.sample_seq),
        (r.time_s, r.sensor_c, r.hot_side_c, r.sample_seq)
    );
    // Identical channels with identical inputs differ only by their noise streams.
    let noise = |d: &SimulatedDisplay<KronModel>, i: usize| {
        d.channel(i)
            .map_or(f64::NAN, |c| c.state().sensor.value_c - c.sensor().element_c())
    };
    let mut differ = 0;
    for _ in 0..100 {
        d.advance(0.01);
        differ += usize::from(noise(&d, 0) != noise(&d, 1));
        let (a, b) = (
            d.channel(0).map(|c| c.state().plate_c),
            d.channel(1).map(|c| c.state().plate_c),
        );
        assert_eq!(a, b, "identical channels drifted apart");
    }
    assert!(
        differ > 80,
        "the channels' noise coincided {} times of 100",
        100 - differ
    );
}

#[test]
fn a_faulted_envelope_switches_the_drive_off() {
    let mut d = RecordingDevice::new(display(1));
    let mut env = envelope();
    d.inner_mut()
        .channel_mut(0)
        .and_then(|c| c.inject(thermode_device::Fault::SensorOpen))
        .unwrap_or_else(|e| panic!("{e}"));
    for n in 0..20 {
        let reading = d.read(0).unwrap_or_else(|e| panic!("{e}"));
        env.observe(&reading.measurement());
        let command = env.gate_drive(n as f64 * 0.01, -2.0, &MeasuredOnly);
        d.apply(0, &command).unwrap_or_else(|e| panic!("{e}"));
        d.poll((n + 1) as f64 * 0.01);
    }
    let last = d
        .commands()
        .last()
        .copied()
        .unwrap_or_else(|| panic!("no command recorded"));
    assert!(last.fault.is_some() && last.current_a == 0.0, "last command {last:?}");
    assert_eq!(d.inner().channel(0).map(|c| c.state().applied_current_a), Ok(0.0));
}

/// A composite of three simulated displays (2 + 1 + 2 channels): its channels are theirs in order, a command to
/// channel k reaches only the member holding it (heated there, the others' plates untouched), a stop reaches every
/// member, its parts say which channels each holds, and bad channel counts are refused.
#[test]
fn a_composite_device_routes_each_channel_to_its_member_and_stops_them_all() {
    use thermode_device::CompositeDevice;
    let members: Vec<(String, Box<dyn Device + Send>)> = [2, 1, 2]
        .iter()
        .enumerate()
        .map(|(i, &n)| (format!("member-{i}"), Box::new(display(n)) as Box<dyn Device + Send>))
        .collect();
    let mut glove = CompositeDevice::new(members).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(glove.channel_count(), 5);
    let parts = glove.parts();
    let spans: Vec<(String, usize, usize)> = parts
        .iter()
        .map(|p| (p.label.clone(), p.first_channel, p.channel_count))
        .collect();
    assert_eq!(
        spans,
        [
            ("member-0".into(), 0, 2),
            ("member-1".into(), 2, 1),
            ("member-2".into(), 3, 2)
        ]
    );
    let mut envelopes: Vec<SafetyEnvelope> = (0..5).map(|_| envelope()).collect();
    let start: Vec<f64> = (0..5).map(|c| ok(glove.read(c)).sensor_c).collect();
    for n in 0..2000 {
        let t = n as f64 * 1e-3;
        for (channel, envelope) in envelopes.iter_mut().enumerate() {
            envelope.observe(&ok(glove.read(channel)).measurement());
            let wanted_a = if channel == 3 { 1.5 } else { 0.0 };
            let command = envelope.gate_drive(t, wanted_a, &MeasuredOnly);
            glove.apply(channel, &command).unwrap_or_else(|e| panic!("{e}"));
        }
        glove.poll(t + 1e-3);
    }
    let end: Vec<f64> = (0..5).map(|c| ok(glove.read(c)).sensor_c).collect();
    // The undriven plates warm alike under their fingers (the same physics in every member); the driven one
    // leaves them behind.
    let undriven = [0, 1, 2, 4].map(|c| end[c] - start[c]);
    let (low, high) = undriven
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), &d| (l.min(d), h.max(d)));
    assert!(high - low < 0.2, "undriven channels moved apart: {undriven:?} °C");
    assert!(
        end[3] - start[3] > high + 1.0,
        "channel 3 (member 2's first): {} → {} °C, the undriven moved {undriven:?} °C",
        start[3],
        end[3]
    );
    assert!(ok(glove.read(3)).current_a > 1.0, "{:?}", ok(glove.read(3)));
    glove.all_off().unwrap_or_else(|e| panic!("{e}"));
    glove.poll(2.1);
    assert_eq!(ok(glove.read(3)).current_a, 0.0, "after all_off");
    assert_eq!(
        glove.read(5).err(),
        Some(DeviceError::NoSuchChannel { channel: 5, count: 5 })
    );
    let too_many: Vec<(String, Box<dyn Device + Send>)> = (0..2)
        .map(|i| (format!("d{i}"), Box::new(display(6)) as Box<dyn Device + Send>))
        .collect();
    assert_eq!(
        CompositeDevice::new(too_many).err(),
        Some(DeviceError::ChannelCount {
            count: 12,
            max: MAX_CHANNELS
        })
    );
    assert!(CompositeDevice::new(Vec::new()).is_err(), "an empty composite");
}

fn ok(reading: Result<thermode_device::Reading, DeviceError>) -> thermode_device::Reading {
    reading.unwrap_or_else(|e| panic!("{e}"))
}
