//! Integration tests of experiment designs and plans: every participant gets every (material, condition,
//! repetition) once; material orders are balanced (positions and immediate successions, counted on the plan itself);
//! condition orders split half/half; plans are bit-identical for the same file; a new seed changes only the
//! material labels and row order of the squares.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use thermode_lab::design::Condition;
use thermode_lab::design::{Experiment, ExperimentFile};
use thermode_lab::plan::{make_plan, Plan, PLAN_COLUMNS};

fn paper_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/paper.toml")
}

fn design(materials: &[&str], participants: usize, repetitions: usize, extra: &str) -> Experiment {
    let list: Vec<String> = materials.iter().map(|m| format!("\"{m}\"")).collect();
    let text = format!(
        "name = \"t\"\nmaterials = [{}]\nparticipants = {participants}\nrepetitions = {repetitions}\nseed = 11\n{extra}",
        list.join(", ")
    );
    Experiment::from_toml_str(&text, Path::new("t.toml")).expect("valid design")
}

/// The material sequences of block (condition, repetition) for participants `from..from + count`.
fn sequences(plan: &Plan, condition: Condition, repetition: usize, from: usize, count: usize) -> Vec<Vec<String>> {
    plan.participants[from..from + count]
        .iter()
        .map(|p| {
            p.trials
                .iter()
                .filter(|t| t.condition == condition && t.repetition == repetition)
                .map(|t| t.presented.clone())
                .collect()
        })
        .collect()
}

/// Checks the Williams balance of a set of sequences over `materials`: every material `per_cell` times in every
/// position, every ordered pair of distinct materials `per_cell` times as immediate successors.
fn assert_balanced(seqs: &[Vec<String>], materials: &[String], per_cell: usize, what: &str) {
    let n = materials.len();
    for pos in 0..n {
        for m in materials {
            let count = seqs.iter().filter(|s| s[pos] == *m).count();
            assert_eq!(
                count,
                per_cell,
                "{what}: {m} at position {} {count} times, want {per_cell}",
                pos + 1
            );
        }
    }
    let mut pairs: BTreeMap<(String, String), usize> = BTreeMap::new();
    for s in seqs {
        for w in s.windows(2) {
            *pairs.entry((w[0].clone(), w[1].clone())).or_default() += 1;
        }
    }
    for a in materials {
        for b in materials {
            let count = pairs.get(&(a.clone(), b.clone())).copied().unwrap_or(0);
            let want = if a == b { 0 } else { per_cell };
            assert_eq!(count, want, "{what}: {b} right after {a} {count} times, want {want}");
        }
    }
}

#[test]
fn the_paper_design_loads_with_its_documented_values() {
    let file = ExperimentFile::load(&paper_path()).expect("paper.toml is valid");
    let e = &file.experiment;
    assert_eq!(e.name, "paper");
    assert_eq!(e.materials, vec!["aluminium", "steel", "stone", "wood", "rubber"]);
    assert_eq!(e.conditions, vec![Condition::Real, Condition::Simulated]);
    assert_eq!(e.participants(), 15);
    assert_eq!(e.repetitions, 2);
    assert_eq!(e.presentation_s, 30.0);
    assert_eq!(e.exclusion_max_drift_c, 1.0);
    assert_eq!(e.trials_per_participant(), 20);
}

#[test]
fn every_participant_gets_every_material_condition_and_repetition_once() {
    let paper = ExperimentFile::load(&paper_path()).expect("valid").experiment;
    let designs = [
        paper,
        design(&["aluminium", "steel", "stone", "wood"], 9, 3, ""),
        design(&["aluminium", "wood", "glass"], 4, 1, "conditions = [\"simulated\"]\n"),
    ];
    for d in &designs {
        let plan = make_plan(d);
        assert_eq!(plan.participants.len(), d.participants());
        for p in &plan.participants {
            assert_eq!(p.trials.len(), d.trials_per_participant(), "{}", p.id);
            let mut seen = BTreeMap::new();
            for (i, t) in p.trials.iter().enumerate() {
                assert_eq!(t.trial, i + 1, "{}: trial numbers run 1..", p.id);
                *seen
                    .entry((t.presented.clone(), t.condition, t.repetition))
                    .or_insert(0) += 1;
            }
            for m in &d.materials {
                for &c in &d.conditions {
                    for r in 1..=d.repetitions {
                        let count = seen.get(&(m.clone(), c, r)).copied().unwrap_or(0);
                        assert_eq!(count, 1, "{}: ({m}, {}, {r}) {count} times", p.id, c.name());
                    }
                }
            }
        }
    }
}

#[test]
fn material_orders_are_williams_balanced_over_every_complete_rotation() {
    // Even (4 materials: one square, N = 4) and odd (5: the pair of squares, N = 10); 2N + 3 participants so that
    // several complete rotations and shifted windows exist.
    for materials in [
        vec!["aluminium", "steel", "stone", "wood"],
        vec!["aluminium", "steel", "stone", "wood", "rubber"],
    ] {
        let n = materials.len();
        let rows = if n % 2 == 0 { n } else { 2 * n };
        let d = design(&materials, 2 * rows + 3, 2, "");
        let plan = make_plan(&d);
        for &c in &d.conditions {
            for r in 1..=d.repetitions {
                for from in [0, rows, 3] {
                    let seqs = sequences(&plan, c, r, from, rows);
                    let what = format!("n = {n}, {} rep {r}, participants {from}..{}", c.name(), from + rows);
                    assert_balanced(&seqs, &d.materials, rows / n, &what);
                }
            }
        }
    }
}

#[test]
fn the_paper_plan_is_balanced_over_its_first_complete_rotation() {
    let d = ExperimentFile::load(&paper_path()).expect("valid").experiment;
    let plan = make_plan(&d);
    for &c in &d.conditions {
        for r in 1..=2 {
            let seqs = sequences(&plan, c, r, 0, 10);
            assert_balanced(&seqs, &d.materials, 2, &format!("paper, {} rep {r}", c.name()));
        }
    }
}

#[test]
fn blocks_of_a_participant_use_fresh_rows() {
    let d = ExperimentFile::load(&paper_path()).expect("valid").experiment;
    for p in &make_plan(&d).participants {
        let mut blocks: Vec<Vec<String>> = Vec::new();
        for chunk in p.trials.chunks(d.materials.len()) {
            blocks.push(chunk.iter().map(|t| t.presented.clone()).collect());
        }
        for i in 0..blocks.len() {
            for j in 0..i {
                assert_ne!(
                    blocks[i],
                    blocks[j],
                    "{}: blocks {} and {} repeat an order",
                    p.id,
                    j + 1,
                    i + 1
                );
            }
        }
    }
}

#[test]
fn condition_orders_split_half_and_half_with_the_extra_to_the_first_listed() {
    for (participants, first, second) in [(15, 8, 7), (14, 7, 7), (1, 1, 0)] {
        let d = design(&["aluminium", "wood"], participants, 2, "");
        let plan = make_plan(&d);
        let real_first = plan
            .participants
            .iter()
            .filter(|p| p.condition_order[0] == Condition::Real)
            .count();
        assert_eq!(real_first, first, "{participants} participants: real-first");
        assert_eq!(
            participants - real_first,
            second,
            "{participants} participants: simulated-first"
        );
        for p in &plan.participants {
            let half = p.trials.len() / 2;
            assert!(
                p.trials[..half].iter().all(|t| t.condition == p.condition_order[0]),
                "{}",
                p.id
            );
            assert!(
                p.trials[half..].iter().all(|t| t.condition == p.condition_order[1]),
                "{}",
                p.id
            );
        }
    }
    let swapped = design(&["aluminium", "wood"], 3, 1, "conditions = [\"simulated\", \"real\"]\n");
    let plan = make_plan(&swapped);
    assert_eq!(
        plan.first_condition_counts(),
        vec![(Condition::Simulated, 2), (Condition::Real, 1)]
    );
}

#[test]
fn the_same_file_gives_a_bit_identical_plan_with_the_seed_recorded() {
    let a = ExperimentFile::load(&paper_path()).expect("valid");
    let b = ExperimentFile::load(&paper_path()).expect("valid");
    let csv_a = make_plan(&a.experiment).to_csv_string();
    let csv_b = make_plan(&b.experiment).to_csv_string();
    assert_eq!(csv_a, csv_b);
    let mut lines = csv_a.lines();
    assert_eq!(lines.next(), Some(PLAN_COLUMNS.join(",").as_str()));
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 15 * 20);
    assert!(
        rows.iter().all(|r| r.starts_with("paper,2008,")),
        "seed recorded on every row"
    );
    assert!(
        rows[0].starts_with("paper,2008,P01,0,real-simulated,1,1,real,1,1,"),
        "{}",
        rows[0]
    );
}

/// All permutations of 0..n.
fn permutations(n: usize) -> Vec<Vec<usize>> {
    if n == 0 {
        return vec![Vec::new()];
    }
    let mut out = Vec::new();
    for p in permutations(n - 1) {
        for i in 0..=p.len() {
            let mut q = p.clone();
            q.insert(i, n - 1);
            out.push(q);
        }
    }
    out
}

#[test]
fn a_different_seed_changes_only_material_labels_and_row_order() {
    let base = ExperimentFile::load(&paper_path()).expect("valid").experiment;
    let other = Experiment {
        seed: 99,
        ..base.clone()
    };
    let (pa, pb) = (make_plan(&base), make_plan(&other));
    assert_ne!(
        pa.to_csv_string(),
        pb.to_csv_string(),
        "the seed must change the orders"
    );
    // Structure: identical participant, trial, block, condition, repetition and position columns.
    for (a, b) in pa.participants.iter().zip(&pb.participants) {
        assert_eq!(a.condition_order, b.condition_order, "{}", a.id);
        for (x, y) in a.trials.iter().zip(&b.trials) {
            assert_eq!(
                (x.trial, x.block, x.condition, x.repetition, x.position),
                (y.trial, y.block, y.condition, y.repetition, y.position),
                "{} trial {}",
                a.id,
                x.trial
            );
        }
    }
    // Orders: over a complete rotation, seed B's set of sequences is seed A's with the materials relabelled by one
    // permutation, the same for every block.
    let names = &base.materials;
    let multiset = |plan: &Plan, c: Condition, r: usize, relabel: &dyn Fn(&str) -> String| {
        let mut seqs: Vec<Vec<String>> = sequences(plan, c, r, 0, 10)
            .into_iter()
            .map(|s| s.iter().map(|m| relabel(m)).collect())
            .collect();
        seqs.sort();
        seqs
    };
    let fits = |perm: &[usize]| {
        let relabel = |m: &str| names[perm[names.iter().position(|x| x == m).unwrap_or(0)]].clone();
        base.conditions
            .iter()
            .all(|&c| (1..=2).all(|r| multiset(&pa, c, r, &relabel) == multiset(&pb, c, r, &|m: &str| m.to_string())))
    };
    let found = permutations(names.len()).into_iter().filter(|p| fits(p)).count();
    assert!(
        found >= 1,
        "no relabelling of the materials maps the seed-2008 plan onto the seed-99 plan"
    );
}
