//! The DFNS analysis maths on hand-computed runs, and the method of limits' state machine (the plans it hands out
//! for the DFNS tests, TSL's alternating ramps and the return rates).

use thermode_procedures::analysis::{parse_reference, thresholds, z_scores};
use thermode_procedures::limits::{LimitsConfig, LimitsProcedure, LimitsTest};
use thermode_procedures::{Procedure, Response, Segment, Until};

fn close(name: &str, got: f64, expected: f64) {
    assert!((got - expected).abs() < 1e-9, "{name}: got {got}, expected {expected}");
}

/// Runs the DFNS battery answering each ramp with the next of `delivered` (NaN: no response, the cut-off).
fn session(delivered: &[f64], phs_on: usize) -> LimitsProcedure {
    let mut procedure = LimitsProcedure::new(LimitsConfig::default()).expect("DFNS defaults");
    let mut k = 0;
    while let Some(plan) = procedure.next_trial() {
        let at = delivered[k];
        let response = Response {
            detected: !at.is_nan(),
            delivered_c: at,
            paradoxical_heat: k == phs_on,
        };
        procedure.record(response).expect("pending");
        k += 1;
        assert!(k <= delivered.len(), "more ramps than the battery has: {plan:?}");
    }
    assert_eq!(k, delivered.len(), "ramps in the battery");
    procedure
}

const DELIVERED: [f64; 18] = [
    30.5,
    30.0,
    30.9, // CDT: −1.5, −2.0, −1.1
    34.0,
    35.0,
    34.5, // WDT: 2.0, 3.0, 2.5
    34.0,
    30.0,
    35.0,
    31.0,
    33.0,
    30.0, // TSL: warm/cold pairs, limens 4, 4, 3
    10.0,
    12.0,
    f64::NAN, // CPT: the third run reaches the 0 °C cut-off
    44.0,
    45.0,
    46.0, // HPT
];

#[test]
fn dfns_thresholds_average_the_runs_and_log_transform_cdt_wdt_tsl() {
    let procedure = session(&DELIVERED, 9);
    let t = thresholds(procedure.runs());
    let tests: Vec<LimitsTest> = t.iter().map(|x| x.test).collect();
    assert_eq!(
        tests,
        [
            LimitsTest::Cdt,
            LimitsTest::Wdt,
            LimitsTest::Tsl,
            LimitsTest::Cpt,
            LimitsTest::Hpt
        ]
    );
    close("CDT", t[0].value_c, -4.6 / 3.0);
    close("log10 CDT", t[0].compared, (4.6f64 / 3.0).log10());
    close("WDT", t[1].value_c, 2.5);
    close("log10 WDT", t[1].compared, 2.5f64.log10());
    close("TSL", t[2].value_c, 11.0 / 3.0);
    assert_eq!(t[2].phs, Some(1), "PHS count (the second TSL cold ramp)");
    close("CPT (cut-off counted at 0 °C)", t[3].value_c, 22.0 / 3.0);
    assert_eq!(
        (t[3].cutoffs, t[3].log_transformed),
        (1, false),
        "CPT cut-offs, not log-transformed"
    );
    close("HPT", t[4].compared, 45.0);
}

#[test]
fn z_scores_are_signed_as_gain_of_function() {
    let procedure = session(&DELIVERED, usize::MAX);
    let reference = parse_reference(
        "test,site,sex,age_band,mean,sd\n\
         CDT,hand,female,20-40,0.10,0.20\n\
         CPT,hand,female,20-40,10.0,4.0\n\
         HPT,hand,female,20-40,43.0,2.0\n\
         HPT,foot,female,20-40,40.0,2.0\n",
    )
    .expect("valid table");
    let z = z_scores(&thresholds(procedure.runs()), &reference, "Hand", "female", "20-40");
    assert_eq!(z.len(), 3, "three tests have a reference row: {z:?}");
    close("z CDT (inverted)", z[0].z, -(((4.6f64 / 3.0).log10() - 0.10) / 0.20));
    close("z CPT (as is)", z[1].z, (22.0 / 3.0 - 10.0) / 4.0);
    close("z HPT (inverted)", z[2].z, -(45.0 - 43.0) / 2.0);
}

#[test]
fn a_bad_reference_table_names_its_line() {
    let cases = [
        ("test,site,sex,mean,sd\n", "missing column `age_band`"),
        ("test,site,sex,age_band,mean,sd\nCDT,hand,f,20-40,x,1\n", "line 2"),
        (
            "test,site,sex,age_band,mean,sd\nCDT,hand,f,20-40,0,1\nMDT,hand,f,20-40,0,1\n",
            "line 3: unknown test",
        ),
        ("test,site,sex,age_band,mean,sd\nCDT,hand,f,20-40,0,0\n", "not positive"),
    ];
    for (text, expected) in cases {
        let error = parse_reference(text).expect_err(text).to_string();
        assert!(error.contains(expected), "`{error}` should mention `{expected}`");
    }
}

#[test]
fn the_limits_plans_are_the_dfns_ramps() {
    let mut procedure = LimitsProcedure::new(LimitsConfig::default()).expect("DFNS defaults");
    let cdt = procedure.next_trial().expect("a first trial");
    let expected = [
        Segment::Ramp {
            to_c: 0.0,
            rate_c_per_s: 1.0,
            until: Some(Until::Response),
        },
        Segment::Ramp {
            to_c: 32.0,
            rate_c_per_s: 1.0,
            until: None,
        },
        Segment::Hold {
            hold_s: 10.0,
            until: None,
        },
    ];
    assert_eq!(cdt.segments(), expected, "CDT run 1");
    assert_eq!(
        procedure.next_trial(),
        Some(cdt.clone()),
        "the pending trial is handed out again"
    );
    let mut plans = vec![cdt];
    for at in DELIVERED {
        procedure
            .record(Response {
                detected: !at.is_nan(),
                delivered_c: at,
                paradoxical_heat: false,
            })
            .expect("pending");
        plans.extend(procedure.next_trial());
    }
    assert_eq!(
        procedure.record(Response::yes_no(true, 30.0)),
        Err(thermode_procedures::ProcedureError::NoTrialPending)
    );
    // TSL: the cold ramp starts where the warm one stopped (34 °C), with no return between; the last one returns.
    let tsl: Vec<_> = plans.iter().filter(|p| p.label == "TSL").collect();
    assert_eq!(tsl.len(), 6, "three warm–cold pairs");
    assert_eq!(
        (tsl[1].baseline_c, tsl[1].target_c(), tsl[1].return_c),
        (34.0, 0.0, None),
        "TSL cold ramp 1"
    );
    assert!(
        tsl[1].continues_previous && !tsl[0].continues_previous,
        "TSL continuity"
    );
    assert_eq!(
        (tsl[2].baseline_c, tsl[2].target_c()),
        (30.0, 50.0),
        "TSL warm ramp 2 starts at the cold limen"
    );
    assert_eq!(tsl[5].return_c, Some(32.0), "the last TSL ramp returns to the baseline");
    let hpt = plans.iter().find(|p| p.label == "HPT").expect("HPT");
    assert_eq!(
        (hpt.target_c(), hpt.return_rate_c_per_s, hpt.pain),
        (50.0, 5.0, true),
        "HPT: cut-off, fast return, pain"
    );
}

#[test]
fn a_display_narrower_than_the_protocol_cuts_off_at_its_limit() {
    let mut procedure = LimitsProcedure::new(LimitsConfig::default()).expect("DFNS defaults");
    let mut cdt = procedure.next_trial().expect("CDT");
    assert_eq!(
        cdt.clip_to_range(15.0, 48.0),
        Some(15.0),
        "the display's cut-off is reported"
    );
    assert_eq!(cdt.target_c(), 15.0, "the ramp ends at the display's limit");
    assert_eq!(
        cdt.clone().clip_to_range(15.0, 48.0),
        None,
        "a target within the range is left alone"
    );
    // Nobody responds: the ramp ends at the display's 15 °C, which the run records (not the protocol's 0 °C).
    procedure.record(Response::yes_no(false, 15.0)).expect("pending");
    let run = procedure.runs()[0];
    assert_eq!((run.delivered_c, run.cutoff_reached), (15.0, true), "{run:?}");
}
