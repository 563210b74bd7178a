//! The staircase against PsychoPy's `StairHandler` rules (psychopy/data/staircase.py: `addResponse`,
//! `calculateNextIntensity`, `_intensityInc`, `_intensityDec`, `__next__`). Each expected sequence below was worked
//! out by hand from those rules, trial by trial (the traces are in the comments), not produced by this code.

use thermode_procedures::staircase::{Staircase, StaircaseConfig, StepType};
use thermode_procedures::stimulus::StimulusConfig;

/// Presents until finished, answering from `responses`; returns the presented intensities.
fn run(config: StaircaseConfig, responses: &[u8]) -> (Staircase, Vec<f64>) {
    let mut stairs = Staircase::new(config, StimulusConfig::default()).expect("valid staircase");
    let mut presented = Vec::new();
    for &r in responses {
        let Some(intensity) = stairs.next_intensity() else {
            break;
        };
        presented.push(intensity);
        stairs.add_response(r == 1);
    }
    assert!(
        stairs.next_intensity().is_none(),
        "the staircase should have finished after {presented:?}"
    );
    (stairs, presented)
}

fn assert_close(name: &str, got: &[f64], expected: &[f64]) {
    let same = got.len() == expected.len() && got.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12);
    assert!(same, "{name}: got {got:?}, PsychoPy's rules give {expected:?}");
}

#[test]
fn three_down_one_up_with_the_initial_rule_and_two_step_sizes() {
    // T0 10 yes: initial 1-up/1-down, start→down, no reversal; 10−2 = 8.   T1 8 yes: down again; 6.
    // T2 6 no: down→up, the first reversal (trial 2, at 6); step → step_sizes[1] = 1; initial rule's last step: 7.
    // T3–T4 7 yes, yes: counter 1, 2 (< 3): stay.   T5 7 yes: counter 3, up→down, reversal (5, at 7); 6.
    // T6–T7 6 yes, yes: counter 1, 2.   T8 6 yes: counter 3, down (no reversal); 5.
    // T9 5 no: counter −1, down→up, reversal (9, at 5); 6.   T10 6 no: counter −1 (reset by the step), up; 7.
    // T11–T12 7 yes, yes.   T13 7 yes: counter 3, up→down, reversal (13, at 7); 4 reversals ≥ 2 and 14 trials ≥ 14:
    // finished.
    let config = StaircaseConfig {
        start_val: 10.0,
        step_sizes: vec![2.0, 1.0],
        step_type: StepType::Lin,
        n_up: 1,
        n_down: 3,
        n_reversals: None,
        n_trials: 14,
        apply_initial_rule: true,
        min_val: None,
        max_val: None,
        ..StaircaseConfig::default()
    };
    let responses = [1, 1, 0, 1, 1, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1, 1];
    let (stairs, presented) = run(config, &responses);
    assert_close(
        "intensities",
        &presented,
        &[10.0, 8.0, 6.0, 7.0, 7.0, 7.0, 6.0, 6.0, 6.0, 5.0, 6.0, 7.0, 7.0, 7.0],
    );
    assert_eq!(stairs.reversal_points(), &[2, 5, 9, 13], "reversal points");
    assert_close(
        "reversal intensities",
        stairs.reversal_intensities(),
        &[6.0, 7.0, 5.0, 7.0],
    );
}

#[test]
fn decibel_steps_without_the_initial_rule_clip_at_max_val() {
    // f = 10^(6/20). T0 1.0 no: counter −1, start→up (the start is no reversal); 1.0·f clipped to max_val 1.0.
    // T1 1.0 yes: counter 1.   T2 1.0 yes: counter 2 = n_down, up→down, reversal (2, at 1.0); 1/f.
    // T3 1/f yes: counter 1.   T4 1/f no: counter −1, down→up, reversal (4, at 1/f); 1/f·f.
    // T5 yes: counter 1.   T6 yes: counter 2, up→down, reversal (6); 3 reversals ≥ 3 and 7 trials ≥ 6: finished.
    let f = 10f64.powf(6.0 / 20.0);
    let config = StaircaseConfig {
        start_val: 1.0,
        step_sizes: vec![6.0],
        step_type: StepType::Db,
        n_up: 1,
        n_down: 2,
        n_reversals: Some(3),
        n_trials: 6,
        apply_initial_rule: false,
        min_val: None,
        max_val: Some(1.0),
        ..StaircaseConfig::default()
    };
    let (stairs, presented) = run(config, &[0, 1, 1, 1, 0, 1, 1, 1, 1]);
    let back = 1.0 / f * f;
    assert_close(
        "intensities",
        &presented,
        &[1.0, 1.0, 1.0, 1.0 / f, 1.0 / f, back, back],
    );
    assert_eq!(stairs.reversal_points(), &[2, 4, 6], "reversal points");
}

#[test]
fn fewer_reversals_than_step_sizes_are_raised_to_their_number() {
    // n_reversals 1 < 3 step sizes: PsychoPy raises it to 3. T0 1 yes: 0.6. T1 0.6 no: first reversal, step 0.2
    // (step_sizes[1]); 0.8. T2 0.8 yes: reversal, step 0.1; 0.7. T3 0.7 no: third reversal: finished (not after T1).
    let config = StaircaseConfig {
        start_val: 1.0,
        step_sizes: vec![0.4, 0.2, 0.1],
        step_type: StepType::Lin,
        n_up: 1,
        n_down: 1,
        n_reversals: Some(1),
        n_trials: 0,
        apply_initial_rule: true,
        min_val: None,
        max_val: None,
        ..StaircaseConfig::default()
    };
    let (stairs, presented) = run(config, &[1, 0, 1, 0, 1, 0]);
    assert_close("intensities", &presented, &[1.0, 0.6, 0.8, 0.7]);
    assert_close("reversal intensities", stairs.reversal_intensities(), &[0.6, 0.8, 0.7]);
}

#[test]
fn log_steps_clip_at_min_val_and_keep_the_clipped_value() {
    // f = 10^0.5. T0 1 yes: initial rule, start→down; 1/f. T1 1/f yes: down; 1/f² = 0.1, clipped to min_val 0.2.
    // T2 0.2 no: down→up, the first reversal (at 0.2); the initial rule's last step: 0.2·f.
    // T3 0.2·f yes: counter 1 = n_down, up→down, reversal; 2 reversals ≥ 1 and 4 trials ≥ 4: finished.
    let f = 10f64.powf(0.5);
    let config = StaircaseConfig {
        start_val: 1.0,
        step_sizes: vec![0.5],
        step_type: StepType::Log,
        n_up: 1,
        n_down: 1,
        n_reversals: None,
        n_trials: 4,
        apply_initial_rule: true,
        min_val: Some(0.2),
        max_val: None,
        ..StaircaseConfig::default()
    };
    let (stairs, presented) = run(config, &[1, 1, 0, 1, 1]);
    assert_close("intensities", &presented, &[1.0, 1.0 / f, 0.2, 0.2 * f]);
    assert_close("reversal intensities", stairs.reversal_intensities(), &[0.2, 0.2 * f]);
}
