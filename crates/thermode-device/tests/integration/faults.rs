//! Fault injection: each fault does what the hardware would do, from the next sample instant or step, and clearing
//! restores normal behaviour.

use thermode_device::channel::PUMP_FAILURE_REMAINING_FRACTION;
use thermode_device::{
    DeviceConfig, Fault, PlateFinger, Polarity, SimulatedChannel, SENSOR_OPEN_READING_C, SENSOR_SHORT_READING_C,
};
use thermode_model::kron::KronModel;

fn channel() -> SimulatedChannel<KronModel> {
    let finger = <KronModel as PlateFinger>::fingertip().unwrap_or_else(|e| panic!("{e}"));
    let mut ch = SimulatedChannel::seeded(&DeviceConfig::default(), finger, 9).unwrap_or_else(|e| panic!("{e}"));
    ch.set_temperatures(32.0, 23.0).unwrap_or_else(|e| panic!("{e}"));
    for _ in 0..100 {
        ch.step(0.001, 0.5);
    }
    ch
}

fn inject(ch: &mut SimulatedChannel<KronModel>, fault: Fault) {
    ch.inject(fault).unwrap_or_else(|e| panic!("{fault:?}: {e}"));
}

#[test]
fn open_and_shorted_sensors_read_their_fault_values_from_the_next_sample() {
    for (fault, value) in [
        (Fault::SensorOpen, SENSOR_OPEN_READING_C),
        (Fault::SensorShort, SENSOR_SHORT_READING_C),
    ] {
        let mut ch = channel();
        let before = ch.state().sensor;
        inject(&mut ch, fault);
        // 100 Hz: the next sample is due within 10 ms; the 4 ms step before it still holds the old reading.
        assert_eq!(
            ch.step(0.004, 0.0).sensor,
            before,
            "{fault:?}: changed before the next sample"
        );
        let s = ch.step(0.01, 0.0).sensor;
        assert_eq!(s.value_c, value, "{fault:?}");
        assert!(s.seq > before.seq, "{fault:?}: the fault value is a fresh sample");
        ch.clear_faults();
        let s = ch.step(0.01, 0.0).sensor;
        assert!(
            (s.value_c - ch.state().plate_c).abs() < 0.5,
            "{fault:?}: reading {} after clearing",
            s.value_c
        );
    }
}

#[test]
fn a_frozen_sensor_stops_sampling_while_the_plate_moves() {
    let mut ch = channel();
    let frozen = ch.step(0.01, 0.0).sensor;
    inject(&mut ch, Fault::SensorFrozen);
    for _ in 0..200 {
        ch.step(0.01, -2.8);
    }
    let s = ch.state();
    assert_eq!(s.sensor, frozen, "the frozen reading changed");
    assert!(
        s.plate_c < frozen.value_c - 5.0,
        "the plate did not move: {} vs {}",
        s.plate_c,
        frozen.value_c
    );
    ch.clear_faults();
    let s = ch.step(0.01, 0.0).sensor;
    assert!(
        s.seq > frozen.seq + 200 && s.time_s > frozen.time_s + 2.0,
        "no fresh sample after clearing: {s:?}"
    );
}

#[test]
fn a_pump_failure_lowers_the_water_conductance_and_heats_the_hot_side() {
    let mut healthy = channel();
    let mut failed = channel();
    inject(
        &mut failed,
        Fault::PumpFailure {
            remaining_fraction: PUMP_FAILURE_REMAINING_FRACTION,
        },
    );
    let want = DeviceConfig::default().hot_side.water_conductance_w_k * PUMP_FAILURE_REMAINING_FRACTION;
    assert!(
        (failed.water_conductance_w_k() - want).abs() < 1e-15,
        "{} vs {want}",
        failed.water_conductance_w_k()
    );
    for _ in 0..3000 {
        healthy.step(0.01, -2.0);
        failed.step(0.01, -2.0);
    }
    let (h, f) = (healthy.state().hot_side_c, failed.state().hot_side_c);
    assert!(f > h + 10.0, "hot side {f} °C with a failed pump vs {h} °C");
    for bad in [-0.1, 1.5, f64::NAN] {
        assert!(
            failed
                .inject(Fault::PumpFailure {
                    remaining_fraction: bad
                })
                .is_err(),
            "fraction {bad} accepted"
        );
    }
    failed.clear_faults();
    assert_eq!(
        failed.water_conductance_w_k(),
        DeviceConfig::default().hot_side.water_conductance_w_k
    );
}

#[test]
fn a_stuck_drive_delivers_its_limit_whatever_is_commanded() {
    for (polarity, want) in [(Polarity::Heating, 2.8), (Polarity::Cooling, -2.8)] {
        let mut ch = channel();
        inject(&mut ch, Fault::DriveStuck { polarity });
        for command in [0.0, -1.0, 1.0, f64::NAN] {
            let s = *ch.step(0.001, command);
            assert_eq!(s.applied_current_a, want, "{polarity:?}, command {command}");
            assert!(s.commanded_current_a.is_nan() || s.commanded_current_a == command);
        }
        ch.clear_faults();
        assert_eq!(ch.step(0.001, 0.3).applied_current_a, 0.3);
    }
}
