//! Cell layout of the finite-volume model: fine cells at the contact face, growing geometrically away from it,
//! never straddling a layer boundary.
//!
//! The target width of a cell that starts at distance x from the contact face is
//! `w(x) = min(w₀ + (g − 1)·x, w_max)`; marching with it gives widths w₀, w₀g, w₀g², … (a geometric series) until
//! `w_max` is reached. Each layer is filled by marching from its top face; the last cell would overshoot the layer's
//! bottom face, so either that cell is dropped and the others are stretched, or all are shrunk — whichever changes
//! the widths less — by one common factor, so the cells fit the layer exactly. Halving `w(x)`
//! everywhere (w₀/2, 1 + (g − 1)/2, w_max/2) roughly doubles the number of cells: that is the refinement used by
//! [`super::FvConfig::refined`].

use crate::error::ParamError;

/// The largest number of cells a grid may have (skin and object together).
pub const MAX_CELLS: usize = 200_000;

/// The cell-width rule `w(x) = min(surface_m + (growth − 1)·x, max_m)`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SizeRule {
    /// Width at the contact face \[m\].
    pub surface_m: f64,
    /// Growth ratio of neighbouring widths \[-\].
    pub growth: f64,
    /// Largest width \[m\].
    pub max_m: f64,
}

impl SizeRule {
    fn width_at(&self, x_m: f64) -> f64 {
        (self.surface_m + (self.growth - 1.0) * x_m).min(self.max_m)
    }
}

/// The widths of the cells of a stack of slabs (thicknesses outermost first), with the slab index of every cell.
/// `budget` is the number of cells still allowed; exceeding it is an error.
pub(crate) fn stack_cells(
    rule: SizeRule,
    thicknesses_m: &[f64],
    budget: usize,
) -> Result<(Vec<f64>, Vec<usize>), ParamError> {
    let mut widths = Vec::new();
    let mut slab = Vec::new();
    let mut top_m = 0.0;
    for (index, &thickness_m) in thicknesses_m.iter().enumerate() {
        let first = widths.len();
        march(rule, top_m, thickness_m, &mut widths, budget)?;
        let mut sum: f64 = widths[first..].iter().sum();
        // Drop the overshooting last cell if stretching the others fits better than shrinking all.
        let last = widths[widths.len() - 1];
        if widths.len() - first > 1 && thickness_m / (sum - last) - 1.0 < 1.0 - thickness_m / sum {
            widths.pop();
            sum -= last;
        }
        let scale = thickness_m / sum;
        widths[first..].iter_mut().for_each(|w| *w *= scale);
        slab.resize(widths.len(), index);
        top_m += thickness_m;
    }
    Ok((widths, slab))
}

/// Appends cells of target width from `top_m` until they cover `thickness_m` (the last one overshoots).
fn march(rule: SizeRule, top_m: f64, thickness_m: f64, widths: &mut Vec<f64>, budget: usize) -> Result<(), ParamError> {
    let mut covered = 0.0;
    while covered < thickness_m {
        if widths.len() >= budget {
            return Err(ParamError::Invalid {
                origin: "fv grid".to_string(),
                message: format!("the grid would need more than {MAX_CELLS} cells; use larger or faster-growing cells"),
            });
        }
        let width = rule.width_at(top_m + covered);
        widths.push(width);
        covered += width;
    }
    Ok(())
}

/// Cell centres \[m\] from the contact face, given the widths.
pub(crate) fn centres_m(widths: &[f64]) -> Vec<f64> {
    let mut face = 0.0;
    widths
        .iter()
        .map(|w| {
            let centre = face + 0.5 * w;
            face += w;
            centre
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULE: SizeRule = SizeRule {
        surface_m: 1e-5,
        growth: 1.15,
        max_m: 5e-4,
    };

    #[test]
    fn cells_fill_every_layer_exactly_and_grow_geometrically() {
        let layers = [5e-4, 1.5e-3, 3e-3];
        let (widths, slab) = stack_cells(RULE, &layers, MAX_CELLS).unwrap();
        for (index, want) in layers.iter().enumerate() {
            let got: f64 = widths
                .iter()
                .zip(&slab)
                .filter(|(_, s)| **s == index)
                .map(|(w, _)| w)
                .sum();
            assert!(
                (got - want).abs() < 1e-15,
                "layer {index}: cells sum to {got}, layer is {want}"
            );
        }
        // Within a layer the widths never shrink and grow by at most the growth ratio.
        for i in 1..widths.len() {
            if slab[i] == slab[i - 1] {
                let ratio = widths[i] / widths[i - 1];
                assert!((1.0 - 1e-12..=1.15 + 1e-12).contains(&ratio), "cell {i}: ratio {ratio}");
            }
        }
        // The common factor that fits a layer stays close to 1.
        assert!((widths[0] / 1e-5 - 1.0).abs() < 0.1, "first cell {}", widths[0]);
        assert!(
            widths.iter().all(|w| *w <= 1.1 * 5e-4),
            "a cell is much wider than the maximum"
        );
    }

    #[test]
    fn halving_the_rule_about_doubles_the_cells() {
        let layers = [5e-4, 1.5e-3, 3e-3];
        let fine = SizeRule {
            surface_m: 5e-6,
            growth: 1.075,
            max_m: 2.5e-4,
        };
        let (coarse_w, _) = stack_cells(RULE, &layers, MAX_CELLS).unwrap();
        let (fine_w, _) = stack_cells(fine, &layers, MAX_CELLS).unwrap();
        let ratio = fine_w.len() as f64 / coarse_w.len() as f64;
        assert!(
            (1.8..=2.2).contains(&ratio),
            "{} fine cells vs {} coarse",
            fine_w.len(),
            coarse_w.len()
        );
    }

    #[test]
    fn too_many_cells_is_an_error() {
        let tiny = SizeRule {
            surface_m: 1e-9,
            growth: 1.0,
            max_m: 1e-9,
        };
        assert!(stack_cells(tiny, &[1.0], MAX_CELLS).is_err());
    }

    #[test]
    fn centres_are_mid_cell() {
        assert_eq!(centres_m(&[1.0, 2.0, 4.0]), vec![0.5, 2.0, 5.0]);
    }
}
