//! The device protocol's framing and codec: published COBS and CRC values, the worked examples of
//! `docs/protocol.md` (computed independently with Python's zlib CRC-32 and a separate COBS implementation),
//! round trips of every message (proptest), and robustness: random noise, corrupted and truncated frames,
//! oversized frames, sequence-gap counting.

use proptest::prelude::*;
use thermode_link::own::codec::{
    cobs_decode, cobs_encode, crc32, decode_payload, encode_frame, to_centi_c, to_milli_c, to_milliamps, ChannelFaults,
    ChannelReport, DecodeError, DeviceMessage, DriveFrame, FirmwareVersion, Frame, FrameDecoder, FrameError,
    HostMessage, Identify, NackCode, ReportFlags, SensorReport, StreamDecoder, WireMessage, MAX_ENCODED_LEN,
    MAX_PAYLOAD_LEN,
};

/// Bitwise CRC-32/ISO-HDLC straight from its definition (reflected polynomial 0xEDB88320), independent of the
/// table-driven implementation under test.
fn reference_crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in bytes {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap_or_else(|e| panic!("bad hex {b}: {e}")))
        .collect()
}

fn wire<M: WireMessage>(seq: u16, message: &M) -> Vec<u8> {
    let mut out = Vec::new();
    encode_frame(seq, message, &mut out).unwrap_or_else(|e| panic!("encode: {e}"));
    out
}

fn decode_all<M: WireMessage>(bytes: &[u8]) -> (Vec<Result<Frame<M>, DecodeError>>, StreamDecoder<M>) {
    let mut decoder = StreamDecoder::<M>::new();
    let mut results = Vec::new();
    decoder.feed(bytes, |r| results.push(r));
    (results, decoder)
}

fn drive(first: usize, currents: &[i16]) -> HostMessage {
    HostMessage::Drive(DriveFrame::new(first, currents).unwrap_or_else(|e| panic!("{e}")))
}

/// The worked examples of docs/protocol.md: (sequence number, message, bytes on the wire).
fn host_examples() -> Vec<(u16, HostMessage, &'static str)> {
    vec![
        (0, HostMessage::Hello, "03 01 01 01 05 4e d2 3a 98 00"),
        (1, HostMessage::ClearFault, "04 01 05 01 05 d3 4b 28 86 00"),
        (
            7,
            drive(0, &[1500, -250]),
            "04 01 03 07 01 0a 02 dc 05 06 ff 35 e9 d1 54 00",
        ),
    ]
}

fn device_examples() -> Vec<(u16, DeviceMessage, &'static str)> {
    let identify = Identify {
        channel_count: 5,
        firmware: FirmwareVersion {
            major: 0,
            minor: 1,
            patch: 0,
        },
        current_limit_ma: 2800,
        watchdog_ms: 250,
        report_interval_ms: 10,
    };
    let channel = ChannelReport {
        sensor_milli_c: 32_150,
        hot_side_centi_c: 2301,
        applied_ma: 1500,
        sample_seq: 123,
        sample_age_ms: 0,
        faults: ChannelFaults(0),
    };
    let report = SensorReport::new(1234, ReportFlags(0), 7, &[channel]).unwrap_or_else(|e| panic!("{e}"));
    vec![
        (
            0,
            DeviceMessage::Identify(identify),
            "03 01 81 01 02 05 02 01 04 f0 0a fa 02 0a 05 08 b0 dd 57 00",
        ),
        (
            42,
            DeviceMessage::SensorReport(report),
            "04 01 82 2a 03 d2 04 01 01 02 07 04 01 96 7d 01 06 fd 08 dc 05 7b 01 01 01 05 04 c0 f8 78 00",
        ),
        (
            3,
            DeviceMessage::Nack {
                seq: 9,
                code: NackCode::Latched,
            },
            "04 01 84 03 02 09 06 04 42 07 26 f1 00",
        ),
    ]
}

#[test]
fn crc_is_crc32_iso_hdlc() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926, "standard check value");
    assert_eq!(reference_crc32(b"123456789"), 0xCBF4_3926, "reference implementation");
}

#[test]
fn documented_examples_encode_and_decode() {
    for (seq, message, bytes) in host_examples() {
        assert_eq!(wire(seq, &message), hex(bytes), "encoding of {message:?}");
        let (results, _) = decode_all::<HostMessage>(&hex(bytes));
        assert_eq!(results, vec![Ok(Frame { seq, message })], "decoding of {bytes}");
    }
    for (seq, message, bytes) in device_examples() {
        assert_eq!(wire(seq, &message), hex(bytes), "encoding of {message:?}");
        let (results, _) = decode_all::<DeviceMessage>(&hex(bytes));
        assert_eq!(results, vec![Ok(Frame { seq, message })], "decoding of {bytes}");
    }
}

#[test]
fn documented_report_fields_read_back_in_si_units() {
    let (_, DeviceMessage::SensorReport(report), _) = device_examples()[1] else {
        panic!("example 1 is a report");
    };
    let ch = report.channels()[0];
    assert!(
        (ch.sensor_c() - 32.15).abs() < 1e-12,
        "sensor {} vs 32.15 °C",
        ch.sensor_c()
    );
    assert!(
        (ch.hot_side_c() - 23.01).abs() < 1e-12,
        "hot side {} vs 23.01 °C",
        ch.hot_side_c()
    );
    assert!(
        (ch.applied_a() - 1.5).abs() < 1e-12,
        "current {} vs 1.5 A",
        ch.applied_a()
    );
}

#[test]
fn fixed_point_conversions() {
    assert_eq!(to_milli_c(32.1504), 32_150);
    assert_eq!(to_milli_c(-242.0), -242_000);
    assert_eq!(to_milli_c(f64::NAN), i32::MIN);
    assert_eq!(to_milli_c(f64::INFINITY), i32::MAX);
    assert_eq!(
        to_milli_c(f64::NEG_INFINITY),
        i32::MIN + 1,
        "−∞ saturates, it is not the NaN code"
    );
    assert_eq!(to_centi_c(850.0), i16::MAX, "beyond ±327.67 °C saturates");
    assert_eq!(to_centi_c(f64::NAN), i16::MIN);
    assert_eq!(to_milliamps(2.8), Some(2800));
    assert_eq!(to_milliamps(-0.0004), Some(0));
    assert_eq!(to_milliamps(f64::NAN), None);
    assert_eq!(to_milliamps(32.768), None);
    let nan_report = ChannelReport {
        sensor_milli_c: i32::MIN,
        hot_side_centi_c: i16::MIN,
        ..ChannelReport::default()
    };
    assert!(nan_report.sensor_c().is_nan() && nan_report.hot_side_c().is_nan());
}

#[test]
fn readings_print_at_the_sensors_resolution() {
    // Every reading the protocol can carry prints with no more digits than its resolution (m°C, c°C, mA):
    // -39989 × 1e-3 would be -39.989000000000004.
    let decimals = |v: f64| v.to_string().split_once('.').map_or(0, |(_, f)| f.len());
    for raw in (-50_000..150_000).step_by(7) {
        let report = ChannelReport {
            sensor_milli_c: raw,
            hot_side_centi_c: (raw / 10) as i16,
            applied_ma: (raw.rem_euclid(32_768)) as i16,
            ..ChannelReport::default()
        };
        let (sensor, hot, current) = (report.sensor_c(), report.hot_side_c(), report.applied_a());
        assert!(decimals(sensor) <= 3, "{raw} m°C read as {sensor}");
        assert!(decimals(hot) <= 2, "{} c°C read as {hot}", raw / 10);
        assert!(
            decimals(current) <= 3,
            "{} mA read as {current}",
            raw.rem_euclid(32_768)
        );
        assert_eq!(to_milli_c(sensor), raw, "{sensor} does not write back as {raw}");
    }
}

#[test]
fn messages_refuse_bad_channel_ranges() {
    assert!(DriveFrame::new(0, &[]).is_err(), "no channels");
    assert!(DriveFrame::new(0, &[0; 11]).is_err(), "11 channels");
    assert!(DriveFrame::new(9, &[0, 0]).is_err(), "channels 9 and 10");
    assert!(DriveFrame::new(9, &[0]).is_ok());
    assert!(SensorReport::new(0, ReportFlags(0), 0, &[]).is_err());
    assert!(SensorReport::new(0, ReportFlags(0), 0, &[ChannelReport::default(); 11]).is_err());
}

/// Builds a frame with a good CRC around an arbitrary payload.
fn raw_frame(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    thermode_link::own::codec::write_frame(payload, &mut out).unwrap_or_else(|e| panic!("{e}"));
    out
}

#[test]
fn crc_valid_frames_with_bad_contents_are_named_and_counted() {
    let cases: Vec<(Vec<u8>, DecodeError)> = vec![
        (vec![2, 0x01, 5, 0], DecodeError::Version { seq: 5, got: 2 }),
        (vec![1, 0x7F, 6, 0], DecodeError::UnknownType { seq: 6, code: 0x7F }),
        (vec![1, 0x81, 6, 0], DecodeError::UnknownType { seq: 6, code: 0x81 }),
        (
            vec![1, 0x01, 7, 0, 0xAA],
            DecodeError::Length {
                seq: 7,
                code: 0x01,
                expected: 0,
                got: 1,
            },
        ),
        (
            vec![1, 0x03, 8, 0, 0, 2, 1, 0],
            DecodeError::Length {
                seq: 8,
                code: 0x03,
                expected: 6,
                got: 4,
            },
        ),
        (
            vec![1, 0x03, 9, 0, 9, 2, 1, 0, 1, 0],
            DecodeError::Value {
                seq: 9,
                what: "drive channel range",
            },
        ),
        (vec![1, 0x03, 2], DecodeError::TooShort { len: 3 }),
    ];
    for (payload, want) in cases {
        let (results, decoder) = decode_all::<HostMessage>(&raw_frame(&payload));
        assert_eq!(results, vec![Err(want)], "payload {payload:02x?}");
        assert_eq!(decoder.counters().errors(), 1, "payload {payload:02x?} counted once");
        assert_eq!(decoder.counters().frames, 0);
    }
    // A Nack with an unknown code and an Identify of 0 channels are refused on the host side.
    let (results, _) = decode_all::<DeviceMessage>(&raw_frame(&[1, 0x84, 1, 0, 9, 0, 99]));
    assert_eq!(
        results,
        vec![Err(DecodeError::Value {
            seq: 1,
            what: "nack code"
        })]
    );
    let (results, _) = decode_all::<DeviceMessage>(&raw_frame(&[1, 0x81, 2, 0, 0, 0, 1, 0, 1, 0, 1, 0, 1, 0]));
    assert_eq!(
        results,
        vec![Err(DecodeError::Value {
            seq: 2,
            what: "identify channel count"
        })]
    );
}

#[test]
fn oversized_garbage_is_dropped_and_the_stream_resynchronises() {
    let mut bytes = vec![0x55u8; 2 * MAX_ENCODED_LEN];
    bytes.push(0);
    bytes.extend(wire(3, &HostMessage::Heartbeat));
    let (results, decoder) = decode_all::<HostMessage>(&bytes);
    assert_eq!(
        results,
        vec![
            Err(DecodeError::Frame(FrameError::Oversized { max: MAX_ENCODED_LEN })),
            Ok(Frame {
                seq: 3,
                message: HostMessage::Heartbeat
            })
        ]
    );
    assert_eq!((decoder.counters().oversized, decoder.counters().frames), (1, 1));
    // A frame cut short by a reset: its tail joins the next frame, which is then lost; the one after it is fine.
    let frame = wire(4, &drive(0, &[100; 10]));
    let mut bytes = frame[..frame.len() / 2].to_vec();
    bytes.extend(wire(5, &HostMessage::Heartbeat));
    bytes.extend(wire(6, &HostMessage::AllOff));
    let (results, decoder) = decode_all::<HostMessage>(&bytes);
    assert_eq!(results.len(), 2, "{results:?}");
    assert!(results[0].is_err(), "the joined frame is refused: {:?}", results[0]);
    assert_eq!(
        results[1],
        Ok(Frame {
            seq: 6,
            message: HostMessage::AllOff
        })
    );
    assert_eq!(decoder.counters().errors(), 1);
}

#[test]
fn writing_refuses_oversized_payloads() {
    let mut out = Vec::new();
    assert_eq!(
        thermode_link::own::codec::write_frame(&[1; MAX_PAYLOAD_LEN + 1], &mut out),
        Err(FrameError::Oversized { max: MAX_PAYLOAD_LEN })
    );
    assert!(out.is_empty());
    assert!(thermode_link::own::codec::write_frame(&[1; MAX_PAYLOAD_LEN], &mut out).is_ok());
    let mut decoder = FrameDecoder::new();
    let results: Vec<_> = out
        .iter()
        .filter_map(|&b| decoder.push(b).map(|r| r.map(<[u8]>::len)))
        .collect();
    assert_eq!(
        results,
        vec![Ok(MAX_PAYLOAD_LEN)],
        "the longest frame passes the decoder"
    );
}

#[test]
fn sequence_gaps_and_restarts_are_counted() {
    let mut bytes = Vec::new();
    for seq in [0u16, 1, 3, 4, 10, 2, 3, 65535, 0] {
        bytes.extend(wire(seq, &HostMessage::Heartbeat));
    }
    let (_, decoder) = decode_all::<HostMessage>(&bytes);
    let c = decoder.counters();
    // Gaps: 1→3 (1), 4→10 (5), 3→65535 (65531 ≥ 2¹⁵: a restart), 65535→0 wraps without a gap; 10→2 is a restart.
    assert_eq!((c.frames, c.lost, c.sequence_restarts), (9, 6, 2), "{c:?}");
}

fn channel_report() -> impl Strategy<Value = ChannelReport> {
    (
        any::<i32>(),
        any::<i16>(),
        any::<i16>(),
        any::<u16>(),
        any::<u16>(),
        any::<u8>(),
    )
        .prop_map(|(sensor, hot, current, seq, age, faults)| ChannelReport {
            sensor_milli_c: sensor,
            hot_side_centi_c: hot,
            applied_ma: current,
            sample_seq: seq,
            sample_age_ms: age,
            faults: ChannelFaults(faults),
        })
}

fn device_message() -> impl Strategy<Value = DeviceMessage> {
    prop_oneof![
        (1u8..=10, any::<[u8; 3]>(), any::<u16>(), any::<u16>(), any::<u16>()).prop_map(|(n, fw, limit, wd, rep)| {
            DeviceMessage::Identify(Identify {
                channel_count: n,
                firmware: FirmwareVersion {
                    major: fw[0],
                    minor: fw[1],
                    patch: fw[2],
                },
                current_limit_ma: limit,
                watchdog_ms: wd,
                report_interval_ms: rep,
            })
        }),
        (
            any::<u32>(),
            any::<u8>(),
            any::<u16>(),
            prop::collection::vec(channel_report(), 1..=10)
        )
            .prop_map(|(time, flags, last, channels)| {
                let report = SensorReport::new(time, ReportFlags(flags), last, &channels);
                DeviceMessage::SensorReport(report.unwrap_or_else(|e| panic!("{e}")))
            }),
        any::<u16>().prop_map(|seq| DeviceMessage::Ack { seq }),
        (any::<u16>(), prop::sample::select(NackCode::ALL.to_vec()))
            .prop_map(|(seq, code)| DeviceMessage::Nack { seq, code }),
    ]
}

fn host_message() -> impl Strategy<Value = HostMessage> {
    prop_oneof![
        Just(HostMessage::Hello),
        Just(HostMessage::Heartbeat),
        Just(HostMessage::AllOff),
        Just(HostMessage::ClearFault),
        (0usize..10)
            .prop_flat_map(|first| (Just(first), prop::collection::vec(any::<i16>(), 1..=10 - first)))
            .prop_map(|(first, currents)| drive(first, &currents)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn crc_matches_the_bitwise_definition(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        prop_assert_eq!(crc32(&bytes), reference_crc32(&bytes));
    }

    #[test]
    fn cobs_round_trips_without_zeros(bytes in prop::collection::vec(
        prop_oneof![Just(0u8), 1u8..=255, 1u8..=255, 1u8..=255], 0..800)) {
        let mut enc = Vec::new();
        cobs_encode(&bytes, &mut enc);
        prop_assert!(!enc.contains(&0), "stuffed bytes contain 0x00");
        prop_assert!(enc.len() <= bytes.len() + bytes.len() / 254 + 1, "{} bytes for {}", enc.len(), bytes.len());
        let mut back = Vec::new();
        prop_assert_eq!(cobs_decode(&enc, &mut back), Ok(()));
        prop_assert_eq!(back, bytes);
    }

    #[test]
    fn host_messages_round_trip(seq in any::<u16>(), message in host_message()) {
        let bytes = wire(seq, &message);
        prop_assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1, "one delimiter, at the end");
        prop_assert!(bytes.len() <= MAX_ENCODED_LEN + 1);
        let (results, _) = decode_all::<HostMessage>(&bytes);
        prop_assert_eq!(results, vec![Ok(Frame { seq, message })]);
    }

    #[test]
    fn device_messages_round_trip(seq in any::<u16>(), message in device_message()) {
        let bytes = wire(seq, &message);
        prop_assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1, "one delimiter, at the end");
        let (results, _) = decode_all::<DeviceMessage>(&bytes);
        prop_assert_eq!(results, vec![Ok(Frame { seq, message })]);
    }

    /// Random noise never panics, every frame the noise delimits is counted once, and whatever it decodes to is a
    /// message that re-encodes to the same payload (no half-parsed values).
    #[test]
    fn noise_never_panics(bytes in prop::collection::vec(
        prop_oneof![Just(0u8), any::<u8>(), any::<u8>(), any::<u8>()], 0..2000)) {
        let (host, dh) = decode_all::<HostMessage>(&bytes);
        let (device, dd) = decode_all::<DeviceMessage>(&bytes);
        for (results, counters) in [(host.len(), dh.counters()), (device.len(), dd.counters())] {
            prop_assert_eq!(counters.bytes, bytes.len() as u64);
            prop_assert_eq!(counters.frames + counters.errors(), results as u64);
        }
        for frame in host.into_iter().flatten() {
            let (again, _) = decode_all::<HostMessage>(&wire(frame.seq, &frame.message));
            prop_assert_eq!(again, vec![Ok(frame)]);
        }
    }

    /// Frames with corrupted bytes are dropped (and counted); a frame that is accepted is exactly a frame that was
    /// sent, with its own sequence number — the CRC lets no wrong content through.
    #[test]
    fn corrupted_frames_never_yield_wrong_content(
        messages in prop::collection::vec(device_message(), 1..12),
        flips in prop::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 1..8),
    ) {
        let mut bytes = Vec::new();
        for (seq, message) in messages.iter().enumerate() {
            bytes.extend(wire(seq as u16, message));
        }
        let original = bytes.clone();
        for (at, mask) in &flips {
            let i = at.index(bytes.len());
            bytes[i] ^= mask;
        }
        let (results, decoder) = decode_all::<DeviceMessage>(&bytes);
        for frame in results.iter().flatten() {
            let sent = messages.get(frame.seq as usize);
            prop_assert_eq!(Some(&frame.message), sent, "accepted frame {} differs from the one sent", frame.seq);
        }
        prop_assert!(decoder.counters().frames < messages.len() as u64 || bytes == original,
            "{} flips left all {} frames intact", flips.len(), messages.len());
    }

    /// Every truncation of a frame is refused; the next frame is decoded.
    #[test]
    fn truncated_frames_are_refused(message in device_message(), cut in any::<prop::sample::Index>()) {
        let frame = wire(1, &message);
        let stuffed = &frame[..frame.len() - 1];
        let keep = 1 + cut.index(stuffed.len() - 1);
        let mut bytes = stuffed[..keep].to_vec();
        bytes.push(0);
        bytes.extend(wire(2, &DeviceMessage::Ack { seq: 5 }));
        let (results, _) = decode_all::<DeviceMessage>(&bytes);
        prop_assert_eq!(results.len(), 2);
        prop_assert!(results[0].is_err(), "{} of {} bytes accepted: {:?}", keep, stuffed.len(), results[0]);
        prop_assert_eq!(results[1], Ok(Frame { seq: 2, message: DeviceMessage::Ack { seq: 5 } }));
    }
}

#[test]
fn decode_payload_refuses_short_payloads() {
    assert_eq!(
        decode_payload::<HostMessage>(&[1, 2]),
        Err(DecodeError::TooShort { len: 2 })
    );
}
