//! The trial plan of an experiment: which material every participant is presented with, in which condition and
//! order (`thermode lab plan`).
//!
//! Construction (the paper: a within-subject design, half the participants real-first, "sequential effects were
//! balanced by varying the materials systematically"):
//!
//! - **Condition order**: participants alternate — the 1st, 3rd, 5th, … start with the first condition listed in the
//!   design (`real` by default), the 2nd, 4th, … with the second. With an odd count the first-listed condition gets
//!   the extra participant (the paper's 15: 8 real-first, 7 simulated-first). Each condition is one run of
//!   `repetitions` successive blocks; every block presents each material once.
//! - **Material order**: balanced Latin squares (Williams designs) over the n materials: one n × n square for even n,
//!   the square and its mirror image (2n rows) for odd n. Across a complete set of rows every material appears in
//!   every position equally often and immediately follows every other material equally often.
//! - **Rows to blocks**: block (condition c, repetition r) of participant p uses row `(p + c·R + r) mod N` (c the
//!   condition's index in the design, R repetitions, N rows): a rotation, so that for every (condition, repetition)
//!   N consecutive participants use every row once (a complete square), and a participant's blocks use fresh rows
//!   (all distinct when 2R ≤ N).
//! - **Seeded choices** (ChaCha8 from the design's `seed`): which material stands for which symbol of the square, and
//!   the order of the square's rows. Both keep every balance property; nothing else depends on the seed.
//!
//! Trials are numbered 1.. within a participant; the plan is a pure function of the design (same file →
//! bit-identical plan).

use std::io::Write;

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::design::Condition;
use crate::design::Experiment;

/// One planned trial of one participant.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlannedTrial {
    /// Trial number within the participant, 1-based.
    pub trial: usize,
    /// Block number within the participant, 1-based (one block = every material once).
    pub block: usize,
    /// The condition.
    pub condition: Condition,
    /// Repetition of the condition, 1-based.
    pub repetition: usize,
    /// Position within the block, 1-based.
    pub position: usize,
    /// Library name of the presented material.
    pub presented: String,
    /// Row of the (seed-shuffled) Williams design used by this block, 0-based.
    pub williams_row: usize,
}

/// The trials of one participant, in order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParticipantPlan {
    /// 0-based index of the participant in the design.
    pub index: usize,
    /// Participant identifier.
    pub id: String,
    /// The conditions in the order this participant meets them.
    pub condition_order: Vec<Condition>,
    /// Every trial, in presentation order.
    pub trials: Vec<PlannedTrial>,
}

/// The whole plan of an experiment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    /// Experiment name.
    pub experiment: String,
    /// The seed used.
    pub seed: u64,
    /// The Williams design after the seeded row shuffle, as material names (N rows of n materials).
    pub rows: Vec<Vec<String>>,
    /// One plan per participant, in the design's order.
    pub participants: Vec<ParticipantPlan>,
}

/// Columns of the plan CSV.
pub const PLAN_COLUMNS: [&str; 12] = [
    "experiment",
    "seed",
    "participant",
    "participant_index",
    "condition_order",
    "trial",
    "block",
    "condition",
    "repetition",
    "position",
    "presented",
    "williams_row",
];

/// A balanced Latin square (Williams design) on the symbols 0..n: n rows for even n, 2n rows (the square and its
/// mirror image) for odd n. Empty for n = 0.
///
/// First row 0, 1, n−1, 2, n−2, …; row i adds i (mod n) to every entry.
pub fn williams_rows(n: usize) -> Vec<Vec<usize>> {
    if n == 0 {
        return Vec::new();
    }
    let first: Vec<usize> = (0..n)
        .map(|j| if j % 2 == 1 { j.div_ceil(2) } else { (n - j / 2) % n })
        .collect();
    let mut rows: Vec<Vec<usize>> = (0..n).map(|i| first.iter().map(|&s| (s + i) % n).collect()).collect();
    if n % 2 == 1 {
        let mirrored: Vec<Vec<usize>> = rows.iter().map(|r| r.iter().rev().copied().collect()).collect();
        rows.extend(mirrored);
    }
    rows
}

/// The plan of `design` (see the module documentation).
pub fn make_plan(design: &Experiment) -> Plan {
    let mut rng = ChaCha8Rng::seed_from_u64(design.seed);
    let mut symbols = design.materials.clone();
    symbols.shuffle(&mut rng);
    let mut rows = williams_rows(symbols.len());
    rows.shuffle(&mut rng);
    let rows: Vec<Vec<String>> = rows
        .iter()
        .map(|row| row.iter().map(|&s| symbols[s].clone()).collect())
        .collect();
    let participants = design
        .participant_ids
        .iter()
        .enumerate()
        .map(|(index, id)| participant_plan(design, &rows, index, id))
        .collect();
    Plan {
        experiment: design.name.clone(),
        seed: design.seed,
        rows,
        participants,
    }
}

/// The conditions in the order participant `index` meets them: alternating, the first-listed one first for even
/// indexes (the 1st, 3rd, … participant).
pub fn condition_order(conditions: &[Condition], index: usize) -> Vec<Condition> {
    let mut order = conditions.to_vec();
    if index % 2 == 1 {
        order.reverse();
    }
    order
}

fn participant_plan(design: &Experiment, rows: &[Vec<String>], index: usize, id: &str) -> ParticipantPlan {
    let order = condition_order(&design.conditions, index);
    let mut trials = Vec::with_capacity(design.trials_per_participant());
    let mut block = 0;
    for &condition in &order {
        let c = design.conditions.iter().position(|&x| x == condition).unwrap_or(0);
        for repetition in 1..=design.repetitions {
            block += 1;
            let row = (index + c * design.repetitions + repetition - 1) % rows.len();
            for (p, material) in rows[row].iter().enumerate() {
                trials.push(PlannedTrial {
                    trial: trials.len() + 1,
                    block,
                    condition,
                    repetition,
                    position: p + 1,
                    presented: material.clone(),
                    williams_row: row,
                });
            }
        }
    }
    ParticipantPlan {
        index,
        id: id.to_string(),
        condition_order: order,
        trials,
    }
}

impl Plan {
    /// The plan of the participant called `id`.
    pub fn participant(&self, id: &str) -> Option<&ParticipantPlan> {
        self.participants.iter().find(|p| p.id == id)
    }

    /// Writes the plan as CSV ([`PLAN_COLUMNS`], one row per trial, `\n` line ends).
    pub fn write_csv(&self, out: impl Write) -> Result<(), csv::Error> {
        let mut writer = csv::WriterBuilder::new()
            .terminator(csv::Terminator::Any(b'\n'))
            .from_writer(out);
        writer.write_record(PLAN_COLUMNS)?;
        for p in &self.participants {
            let order = p.condition_order.iter().map(|c| c.name()).collect::<Vec<_>>().join("-");
            for t in &p.trials {
                writer.write_record([
                    self.experiment.clone(),
                    self.seed.to_string(),
                    p.id.clone(),
                    p.index.to_string(),
                    order.clone(),
                    t.trial.to_string(),
                    t.block.to_string(),
                    t.condition.name().to_string(),
                    t.repetition.to_string(),
                    t.position.to_string(),
                    t.presented.clone(),
                    t.williams_row.to_string(),
                ])?;
            }
        }
        writer.flush()?;
        Ok(())
    }

    /// The plan CSV as a string.
    pub fn to_csv_string(&self) -> String {
        let mut bytes = Vec::new();
        // Writing to memory cannot fail, and every field is UTF-8.
        let _ = self.write_csv(&mut bytes);
        String::from_utf8_lossy(&bytes).into_owned()
    }

    /// How many participants start with each condition, in the design's condition order.
    pub fn first_condition_counts(&self) -> Vec<(Condition, usize)> {
        let mut counts: Vec<(Condition, usize)> = Vec::new();
        for p in &self.participants {
            if let Some(&first) = p.condition_order.first() {
                match counts.iter_mut().find(|(c, _)| *c == first) {
                    Some((_, n)) => *n += 1,
                    None => counts.push((first, 1)),
                }
            }
        }
        counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts of (earlier, later) immediate successions in a set of rows.
    fn successions(rows: &[Vec<usize>], n: usize) -> Vec<Vec<usize>> {
        let mut counts = vec![vec![0; n]; n];
        for row in rows {
            for pair in row.windows(2) {
                counts[pair[0]][pair[1]] += 1;
            }
        }
        counts
    }

    #[test]
    fn williams_designs_are_latin_and_carryover_balanced() {
        for n in 2..=9 {
            let rows = williams_rows(n);
            let expected_rows = if n % 2 == 0 { n } else { 2 * n };
            assert_eq!(rows.len(), expected_rows, "n = {n}");
            let per_cell = expected_rows / n;
            for pos in 0..n {
                for s in 0..n {
                    let count = rows.iter().filter(|r| r[pos] == s).count();
                    assert_eq!(count, per_cell, "n = {n}: symbol {s} at position {pos} {count} times");
                }
            }
            for row in &rows {
                let mut sorted = row.clone();
                sorted.sort_unstable();
                assert_eq!(
                    sorted,
                    (0..n).collect::<Vec<_>>(),
                    "n = {n}: row {row:?} is not a permutation"
                );
            }
            let counts = successions(&rows, n);
            for (a, row) in counts.iter().enumerate() {
                for (b, &count) in row.iter().enumerate() {
                    let want = if a == b { 0 } else { per_cell };
                    assert_eq!(count, want, "n = {n}: {b} follows {a} {count} times");
                }
            }
        }
    }

    #[test]
    fn williams_for_four_is_the_textbook_square() {
        // Williams (1949): 0 1 3 2 / 1 2 0 3 / 2 3 1 0 / 3 0 2 1.
        let want = vec![vec![0, 1, 3, 2], vec![1, 2, 0, 3], vec![2, 3, 1, 0], vec![3, 0, 2, 1]];
        assert_eq!(williams_rows(4), want);
        assert!(williams_rows(0).is_empty());
        assert_eq!(williams_rows(1), vec![vec![0], vec![0]]);
    }

    #[test]
    fn condition_orders_alternate() {
        let both = [Condition::Real, Condition::Simulated];
        assert_eq!(condition_order(&both, 0), both.to_vec());
        assert_eq!(condition_order(&both, 1), vec![Condition::Simulated, Condition::Real]);
        assert_eq!(condition_order(&[Condition::Simulated], 1), vec![Condition::Simulated]);
    }
}
