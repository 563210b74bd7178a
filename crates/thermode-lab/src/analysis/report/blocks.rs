//! The content of the reports, independent of the output format: the paper's tables (rates, confusion matrices, the
//! Table 2 ratio table with correct cells bold and false cells italic, Table 3, the Figure 4 shares, the Figure 3
//! curve comparison) and the sentences that state the χ² test and the confusion correlation; beyond the paper, the
//! comparison of the confusions over the cells not zero in both conditions and the just-noticeable differences.

use thermode_model::numbers::p_value_text;

use crate::analysis::curves::CurveAnalysis;
use crate::analysis::tables::{ConditionRates, Confusion};
use crate::analysis::Analysis;

/// Emphasis of a table cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Emphasis {
    /// Plain text.
    None,
    /// Bold (correct cells of Table 2).
    Bold,
    /// Italic (false cells of Table 2).
    Italic,
}

/// One table cell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cell {
    /// The text (plain; escaped by the renderers).
    pub text: String,
    /// Its emphasis.
    pub emphasis: Emphasis,
}

impl Cell {
    /// A plain cell.
    pub fn plain(text: impl Into<String>) -> Cell {
        Cell {
            text: text.into(),
            emphasis: Emphasis::None,
        }
    }
}

/// A table with a caption, a header row and body rows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Table {
    /// Caption printed above the table.
    pub caption: String,
    /// Column headings.
    pub header: Vec<String>,
    /// Body rows (as many cells as headings).
    pub rows: Vec<Vec<Cell>>,
}

/// A piece of a report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Block {
    /// A heading of level 1 to 3.
    Heading(u8, String),
    /// A paragraph of plain text.
    Paragraph(String),
    /// A table.
    Table(Table),
    /// A figure written as `<stem>.svg` and `<stem>.png` beside the report.
    Figure {
        /// File stem (`figure4`).
        stem: String,
        /// Caption.
        caption: String,
    },
}

/// Formats an optional number with `digits` decimals, or `--`.
fn num(value: Option<f64>, digits: usize) -> String {
    value.map_or_else(|| "--".to_string(), |v| format!("{v:.digits$}"))
}

/// Formats an optional share as a percentage without decimals, or `--`.
fn pct(value: Option<f64>) -> String {
    value.map_or_else(|| "--".to_string(), |v| format!("{:.0} %", v * 100.0))
}

/// The whole report of `analysis`.
pub fn report_blocks(analysis: &Analysis) -> Vec<Block> {
    let mut blocks = vec![
        Block::Heading(1, "Material identification: analysis".to_string()),
        overview(analysis),
    ];
    blocks.push(Block::Heading(2, "Identification rates".to_string()));
    blocks.push(Block::Table(rates_table(analysis)));
    blocks.push(Block::Paragraph(rates_sentence(analysis)));
    blocks.push(Block::Heading(2, "Confusion matrices".to_string()));
    blocks.push(Block::Table(confusion_table("Real contact", &analysis.confusion.real)));
    blocks.push(Block::Table(confusion_table(
        "Simulated contact",
        &analysis.confusion.simulated,
    )));
    blocks.push(Block::Heading(
        2,
        "Validity: probability ratios (eq. 8, Table 2)".to_string(),
    ));
    blocks.push(Block::Table(ratio_table(analysis)));
    blocks.push(Block::Paragraph(ratio_sentence(analysis)));
    blocks.push(Block::Paragraph(correlation_sentence(analysis)));
    blocks.push(Block::Paragraph(comparison_sentence(analysis)));
    blocks.push(Block::Heading(2, "Homogeneity: χ² test (Table 3)".to_string()));
    blocks.push(Block::Table(table3(analysis)));
    blocks.push(Block::Paragraph(chi_square_sentence(analysis)));
    blocks.push(Block::Heading(2, "Discrimination (Figure 4)".to_string()));
    blocks.push(Block::Table(figure4_table(analysis)));
    blocks.push(Block::Figure {
        stem: "figure4".to_string(),
        caption: "Figure 4: classification probability against Δc and Δk (identified − presented); correct \
                  classifications at zero (dashed line)."
            .to_string(),
    });
    blocks.push(Block::Heading(
        2,
        "Just-noticeable differences (beyond the paper)".to_string(),
    ));
    blocks.push(Block::Table(jnd_table(analysis)));
    if let Some(curves) = &analysis.curves {
        blocks.push(Block::Heading(2, "Objective assessment (Figure 3)".to_string()));
        blocks.push(Block::Table(curves_table(curves)));
        blocks.push(Block::Figure {
            stem: "figure3".to_string(),
            caption: "Figure 3: mean finger temperature over repetitions, real (solid) and simulated (dashed)."
                .to_string(),
        });
    }
    blocks
}

fn overview(analysis: &Analysis) -> Block {
    let options: Vec<&str> = analysis.materials.iter().map(|m| m.name.as_str()).collect();
    Block::Paragraph(format!(
        "Input: {}. {} participants, {} trials analysed, {} excluded trials left out. Response options (the presented \
         materials): {}; chance level {:.0} % (1:{}).",
        analysis.input_files.join(", "),
        analysis.participants,
        analysis.trials,
        analysis.excluded_trials,
        options.join(", "),
        analysis.chance * 100.0,
        options.len()
    ))
}

fn rates_table(analysis: &Analysis) -> Table {
    let (real, sim) = (&analysis.rates.real, &analysis.rates.simulated);
    let cell = |r: &ConditionRates, i: Option<usize>| -> [Cell; 2] {
        let (correct, trials, rate) = match i {
            Some(i) => (
                r.per_material[i].correct,
                r.per_material[i].trials,
                r.per_material[i].rate,
            ),
            None => (r.correct, r.trials, r.rate),
        };
        [Cell::plain(format!("{correct}/{trials}")), Cell::plain(pct(rate))]
    };
    let mut rows: Vec<Vec<Cell>> = analysis
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let mut row = vec![Cell::plain(&m.name)];
            row.extend(cell(real, Some(i)));
            row.extend(cell(sim, Some(i)));
            row
        })
        .collect();
    let mut all = vec![Cell::plain("all")];
    all.extend(cell(real, None));
    all.extend(cell(sim, None));
    rows.push(all);
    Table {
        caption: "Correct identifications per presented material.".to_string(),
        header: [
            "material",
            "real correct",
            "real rate",
            "simulated correct",
            "simulated rate",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    }
}

fn rates_sentence(analysis: &Analysis) -> String {
    format!(
        "{} of the real and {} of the simulated stimuli were identified correctly; guessing would give {:.0} %.",
        pct(analysis.rates.real.rate),
        pct(analysis.rates.simulated.rate),
        analysis.chance * 100.0
    )
}

fn confusion_table(title: &str, confusion: &Confusion) -> Table {
    let mut header = vec!["presented ↓ / identified →".to_string()];
    header.extend(confusion.materials.iter().cloned());
    let rows = confusion
        .materials
        .iter()
        .enumerate()
        .map(|(p, name)| {
            let mut row = vec![Cell::plain(name)];
            for (i, n) in confusion.counts[p].iter().enumerate() {
                row.push(Cell::plain(format!("{n} ({})", pct(confusion.probabilities[p][i]))));
            }
            row
        })
        .collect();
    Table {
        caption: format!("{title}: trials (row share), rows presented, columns identified."),
        header,
        rows,
    }
}

/// Table 2 in the paper's orientation: rows identified, columns presented.
fn ratio_table(analysis: &Analysis) -> Table {
    let table = &analysis.ratio_table;
    let mut header = vec!["identified ↓ / presented →".to_string()];
    header.extend(table.materials.iter().cloned());
    let rows = table
        .materials
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let mut row = vec![Cell::plain(name)];
            for p in 0..table.materials.len() {
                let ratio = table.ratios[p][i];
                let emphasis = match (ratio, p == i) {
                    (None, _) => Emphasis::None,
                    (Some(_), true) => Emphasis::Bold,
                    (Some(_), false) => Emphasis::Italic,
                };
                row.push(Cell {
                    text: num(ratio, 2),
                    emphasis,
                });
            }
            row
        })
        .collect();
    Table {
        caption: "Probability ratios P(simulated) / P(real) per cell (eq. 8); correct classifications bold, false \
                  ones italic; -- where the real probability is zero."
            .to_string(),
        header,
        rows,
    }
}

fn ratio_sentence(analysis: &Analysis) -> String {
    format!(
        "On average simulated materials were identified {} times as often as their real counterparts (mean over {} \
         correct cells), whereas false classifications occurred {} times as often (mean over {} false cells).",
        num(analysis.mean_ratio_correct, 2),
        analysis.ratio_table.correct_cells,
        num(analysis.mean_ratio_false, 2),
        analysis.ratio_table.false_cells
    )
}

fn correlation_sentence(analysis: &Analysis) -> String {
    let all = &analysis.confusion_correlation_all_cells;
    let main = match analysis.confusion_correlation {
        Some(r) => format!("r = {r:.2}"),
        None => format!(
            "r {}",
            analysis.confusion_correlation_note.as_deref().unwrap_or("undefined")
        ),
    };
    let over_all = match all.r {
        Some(r) => format!("r = {r:.2}"),
        None => format!("r {}", all.note.as_deref().unwrap_or("undefined")),
    };
    format!(
        "Kind of mistakes, as the paper computed it (its r = 0.90): Pearson correlation between the real and \
         simulated probabilities of identification over the {} off-diagonal cells (false classifications): {main}. \
         Over all {} cells: {over_all}.",
        analysis.confusion_correlation_pairs, all.pairs
    )
}

/// The honest comparison of the confusions: r over the cells not zero in both conditions, with its permutation
/// p-value, beside the paper's r (which counts the pairs neither condition confused as agreement).
fn comparison_sentence(analysis: &Analysis) -> String {
    let c = &analysis.confusion_comparison;
    let r = match (c.r, c.p_value) {
        (Some(r), Some(p)) => format!(
            "r = {r:.2}, one-sided permutation p = {p:.4} ({} over {} permutations{})",
            c.p_method,
            c.permutations,
            if c.p_method == "exact" {
                String::new()
            } else {
                format!(", seed {}", c.seed)
            }
        ),
        _ => format!("r {}", c.note.as_deref().unwrap_or("undefined")),
    };
    format!(
        "Real against simulated confusions, over the {} off-diagonal cells not zero in both conditions ({} cells \
         where neither condition confused the pair are left out): {r}. The r above, like the paper's, counts those \
         empty cells as agreement.",
        c.pairs, c.zero_in_both
    )
}

/// The just-noticeable differences: one row per (condition, quantity).
fn jnd_table(analysis: &Analysis) -> Table {
    let j = &analysis.jnd;
    let estimate = |e: Option<crate::analysis::jnd::Estimate>| {
        e.map_or_else(
            || "--".to_string(),
            |e| format!("{:.4} [{:.4}, {:.4}]", e.value, e.ci_low, e.ci_high),
        )
    };
    let mut rows = Vec::new();
    for (condition, group) in [("real", &j.real), ("simulated", &j.simulated), ("overall", &j.overall)] {
        for (quantity, unit, fit) in [("|Δk|", j.k_unit, &group.k), ("|Δc|", j.c_unit, &group.c)] {
            rows.push(vec![
                Cell::plain(condition),
                Cell::plain(format!("{quantity} [{unit}]")),
                Cell::plain(fit.mistakes.to_string()),
                Cell::plain(estimate(fit.mu)),
                Cell::plain(estimate(fit.sigma)),
                Cell::plain(match fit.note.as_deref() {
                    Some(note) => note.to_string(),
                    None => estimate(fit.jnd_75),
                }),
            ]);
        }
    }
    Table {
        caption: format!(
            "Just-noticeable differences of k and c: {}; {} resamples, seed {}. Estimate [95 % interval]; the \
             JND is the 75 % point μ + 0.674 σ.",
            j.method, j.bootstrap_resamples, j.bootstrap_seed
        ),
        header: [
            "condition",
            "quantity",
            "mistakes",
            "μ (50 % point)",
            "σ",
            "JND (75 % point)",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    }
}

fn table3(analysis: &Analysis) -> Table {
    let rows = analysis
        .chi_square
        .table
        .iter()
        .map(|r| {
            vec![
                Cell::plain(&r.material),
                Cell::plain(pct(Some(r.true_share))),
                Cell::plain(pct(Some(r.false_share))),
                Cell::plain(r.true_count.to_string()),
                Cell::plain(r.false_count.to_string()),
            ]
        })
        .collect();
    Table {
        caption: "Conditional frequencies of true and false classifications for simulations.".to_string(),
        header: [
            "material",
            "true classifications",
            "false classifications",
            "true n",
            "false n",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    }
}

fn chi_square_sentence(analysis: &Analysis) -> String {
    let chi = &analysis.chi_square;
    let mut text = match (chi.statistic, chi.df, chi.critical_95, chi.p_value) {
        (Some(s), Some(df), Some(c), Some(p)) => format!(
            "H0: correct classification is independent of the simulated material. χ²({df}) = {s:.2}, 95 % quantile \
             χ²(0.95; {df}) = {c:.2}, {}. {}.",
            p_value_text(p),
            chi.decision
        ),
        _ => format!("χ² test {}.", chi.decision),
    };
    for note in &chi.notes {
        text.push_str(&format!(" Note: {note}."));
    }
    text
}

fn figure4_table(analysis: &Analysis) -> Table {
    let f = &analysis.figure4;
    let row = |name: &str, d: &crate::analysis::figure4::Discrimination| {
        vec![
            Cell::plain(name),
            Cell::plain(format!("{}/{}", d.mistakes, d.trials)),
            Cell::plain(format!("{} ({})", d.mistakes_within_c, pct(d.share_mistakes_within_c))),
            Cell::plain(format!("{} ({})", d.mistakes_within_k, pct(d.share_mistakes_within_k))),
        ]
    };
    Table {
        caption: format!(
            "Mistakes within Δc = ±{} {} and within Δk = ±{} {}.",
            f.c_half_width, f.c_unit, f.k_half_width, f.k_unit
        ),
        header: vec![
            "condition".to_string(),
            "mistakes/trials".to_string(),
            format!("|Δc| ≤ {}", f.c_half_width),
            format!("|Δk| ≤ {}", f.k_half_width),
        ],
        rows: vec![
            row("real", &f.real),
            row("simulated", &f.simulated),
            row("overall", &f.overall),
        ],
    }
}

fn curves_table(curves: &CurveAnalysis) -> Table {
    let rows = curves
        .materials
        .iter()
        .map(|m| {
            let reps = |c: &Option<crate::analysis::curves::ConditionCurve>| c.as_ref().map_or(0, |c| c.repetitions);
            let slope = |c: &Option<crate::analysis::curves::ConditionCurve>| {
                num(c.as_ref().and_then(|c| c.initial_slope_c_per_s), 3)
            };
            vec![
                Cell::plain(&m.material),
                Cell::plain(format!("{}/{}", reps(&m.real), reps(&m.simulated))),
                Cell::plain(format!("{:.1}–{:.1}", m.start_s, m.end_s)),
                Cell::plain(slope(&m.real)),
                Cell::plain(slope(&m.simulated)),
                Cell::plain(num(m.endpoint_difference_c, 2)),
                Cell::plain(num(m.rms_difference_c, 2)),
            ]
        })
        .collect();
    Table {
        caption: format!(
            "Real versus simulated mean curves; initial slope over the first {} s; differences simulated − real.",
            curves.initial_slope_window_s
        ),
        header: [
            "material",
            "repetitions real/sim",
            "span [s]",
            "initial slope real [°C/s]",
            "initial slope sim [°C/s]",
            "endpoint difference [°C]",
            "RMS difference [°C]",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    }
}
