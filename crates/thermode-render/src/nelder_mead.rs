//! A small Nelder–Mead simplex minimiser (derivative-free; the tuner's objective is a simulation) with restarts.
//!
//! Standard coefficients: reflection 1, expansion 2, contraction ½, shrink ½ (Lagarias et al., SIAM J. Optim. 9
//! (1998) 112–147). The start simplex is the start point plus one point per coordinate, offset by `initial_step`.
//! A non-finite objective value counts as +∞, so a parameter set whose simulation fails is simply worse. It stops
//! when the spread of the values and the size of the simplex are both below their tolerances, or after
//! `max_evaluations`. Deterministic: no randomness.

/// Settings of one minimisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NelderMead {
    /// Offset of the start simplex's points along each coordinate. Default 0.5.
    pub initial_step: f64,
    /// Largest number of objective evaluations. Default 200.
    pub max_evaluations: usize,
    /// Stop when max f − min f over the simplex is at most this times (|min f| + 1e-12). Default 1e-4.
    pub f_tolerance: f64,
    /// … and the largest coordinate distance of any point from the best is at most this. Default 1e-3.
    pub x_tolerance: f64,
}

impl Default for NelderMead {
    fn default() -> Self {
        NelderMead {
            initial_step: 0.5,
            max_evaluations: 200,
            f_tolerance: 1e-4,
            x_tolerance: 1e-3,
        }
    }
}

/// The best point found.
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// Where.
    pub x: Vec<f64>,
    /// The objective there.
    pub value: f64,
    /// Objective evaluations spent.
    pub evaluations: usize,
}

/// Counts evaluations and maps non-finite values to +∞.
struct Counted<'a> {
    f: &'a mut dyn FnMut(&[f64]) -> f64,
    evaluations: usize,
}

impl Counted<'_> {
    fn eval(&mut self, x: &[f64]) -> f64 {
        self.evaluations += 1;
        let v = (self.f)(x);
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    }
}

/// Minimises `f` from `start` with `options`.
pub fn minimise(f: &mut dyn FnMut(&[f64]) -> f64, start: &[f64], options: &NelderMead) -> Minimum {
    let n = start.len();
    let mut counted = Counted { f, evaluations: 0 };
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    let value = counted.eval(start);
    simplex.push((start.to_vec(), value));
    for i in 0..n {
        let mut x = start.to_vec();
        x[i] += options.initial_step;
        let value = counted.eval(&x);
        simplex.push((x, value));
    }
    while counted.evaluations < options.max_evaluations && !converged(&simplex, options) {
        iterate(&mut simplex, &mut counted);
    }
    sort(&mut simplex);
    let (x, value) = simplex.swap_remove(0);
    Minimum {
        x,
        value,
        evaluations: counted.evaluations,
    }
}

/// Minimises `f` from `start`, then restarts from the best point with a fresh simplex until a restart improves the
/// value by less than `options.f_tolerance` (relative), `max_restarts` restarts are done, or the evaluations of all
/// runs together reach `options.max_evaluations` (the budget is shared; a run may overrun it by one iteration,
/// at most n + 2 evaluations).
pub fn minimise_with_restarts(
    f: &mut dyn FnMut(&[f64]) -> f64,
    start: &[f64],
    options: &NelderMead,
    max_restarts: usize,
) -> Minimum {
    let mut best = minimise(f, start, options);
    for _ in 0..max_restarts {
        // Room for at least the new simplex and a few iterations, else stop.
        let remaining = options.max_evaluations.saturating_sub(best.evaluations);
        if remaining < 2 * (start.len() + 1) {
            break;
        }
        let budget = NelderMead {
            max_evaluations: remaining,
            ..*options
        };
        let next = minimise(f, &best.x, &budget);
        let evaluations = best.evaluations + next.evaluations;
        let improved = next.value < best.value - options.f_tolerance * (best.value.abs() + 1e-12);
        if next.value < best.value {
            best = next;
        }
        best.evaluations = evaluations;
        if !improved {
            break;
        }
    }
    best
}

fn sort(simplex: &mut [(Vec<f64>, f64)]) {
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
}

fn converged(simplex: &[(Vec<f64>, f64)], options: &NelderMead) -> bool {
    let (lo, hi) = simplex
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, v)| {
            (lo.min(*v), hi.max(*v))
        });
    if !(hi.is_finite() && hi - lo <= options.f_tolerance * (lo.abs() + 1e-12)) {
        return false;
    }
    let best = simplex
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(x, _)| x.clone())
        .unwrap_or_default();
    simplex
        .iter()
        .all(|(x, _)| x.iter().zip(&best).all(|(a, b)| (a - b).abs() <= options.x_tolerance))
}

/// `a + t (b − a)`.
fn along(a: &[f64], b: &[f64], t: f64) -> Vec<f64> {
    a.iter().zip(b).map(|(a, b)| a + t * (b - a)).collect()
}

/// One Nelder–Mead iteration.
fn iterate(simplex: &mut [(Vec<f64>, f64)], f: &mut Counted<'_>) {
    sort(simplex);
    let n = simplex.len() - 1;
    let centroid: Vec<f64> = (0..n)
        .map(|i| simplex[..n].iter().map(|(x, _)| x[i]).sum::<f64>() / n as f64)
        .collect();
    let (worst, f_worst) = simplex[n].clone();
    let f_best = simplex[0].1;
    let f_second = simplex[n - 1].1;
    let reflected = along(&centroid, &worst, -1.0);
    let f_reflected = f.eval(&reflected);
    if f_reflected < f_best {
        let expanded = along(&centroid, &worst, -2.0);
        let f_expanded = f.eval(&expanded);
        simplex[n] = if f_expanded < f_reflected {
            (expanded, f_expanded)
        } else {
            (reflected, f_reflected)
        };
    } else if f_reflected < f_second {
        simplex[n] = (reflected, f_reflected);
    } else {
        let (candidate, reference) = if f_reflected < f_worst {
            (along(&centroid, &reflected, 0.5), f_reflected)
        } else {
            (along(&centroid, &worst, 0.5), f_worst)
        };
        let f_candidate = f.eval(&candidate);
        if f_candidate < reference {
            simplex[n] = (candidate, f_candidate);
        } else {
            shrink(simplex, f);
        }
    }
}

fn shrink(simplex: &mut [(Vec<f64>, f64)], f: &mut Counted<'_>) {
    let best = simplex[0].0.clone();
    for point in simplex.iter_mut().skip(1) {
        let x = along(&best, &point.0, 0.5);
        let value = f.eval(&x);
        *point = (x, value);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_minimum_of_a_shifted_quadratic_in_four_dimensions() {
        let centre = [0.3, -1.2, 2.0, 0.7];
        let mut f = |x: &[f64]| {
            x.iter()
                .zip(&centre)
                .enumerate()
                .map(|(i, (a, c))| (i + 1) as f64 * (a - c) * (a - c))
                .sum::<f64>()
                + 1.0
        };
        let options = NelderMead {
            max_evaluations: 2000,
            f_tolerance: 1e-12,
            x_tolerance: 1e-7,
            ..NelderMead::default()
        };
        let m = minimise_with_restarts(&mut f, &[0.0; 4], &options, 3);
        for (got, want) in m.x.iter().zip(&centre) {
            assert!((got - want).abs() < 1e-5, "x {got} vs {want}");
        }
        assert!((m.value - 1.0).abs() < 1e-9, "minimum {} vs 1", m.value);
    }

    #[test]
    fn finds_the_rosenbrock_valley_minimum() {
        let mut f = |x: &[f64]| (1.0 - x[0]).powi(2) + 100.0 * (x[1] - x[0] * x[0]).powi(2);
        let options = NelderMead {
            max_evaluations: 5000,
            f_tolerance: 1e-14,
            x_tolerance: 1e-9,
            ..NelderMead::default()
        };
        let m = minimise_with_restarts(&mut f, &[-1.2, 1.0], &options, 3);
        assert!(
            (m.x[0] - 1.0).abs() < 1e-4 && (m.x[1] - 1.0).abs() < 1e-4,
            "Rosenbrock minimum at {:?}, want (1, 1)",
            m.x
        );
    }

    #[test]
    fn restarts_share_one_budget() {
        let mut calls = 0usize;
        let mut f = |x: &[f64]| {
            calls += 1;
            (x[0] - 1.0).powi(2) + 10.0 * (x[1] + 2.0).powi(2)
        };
        let options = NelderMead {
            max_evaluations: 100,
            f_tolerance: 1e-300,
            x_tolerance: 0.0,
            ..NelderMead::default()
        };
        let m = minimise_with_restarts(&mut f, &[5.0, 5.0], &options, 10);
        assert_eq!(m.evaluations, calls);
        assert!(calls <= 100 + 4, "{calls} evaluations for a budget of 100");
    }

    #[test]
    fn non_finite_values_count_as_worse_and_the_budget_holds() {
        let mut calls = 0;
        let mut f = |x: &[f64]| {
            calls += 1;
            if x[0] < 0.0 {
                f64::NAN
            } else {
                (x[0] - 2.0).powi(2)
            }
        };
        let options = NelderMead {
            max_evaluations: 60,
            ..NelderMead::default()
        };
        let m = minimise(&mut f, &[0.5], &options);
        assert!((m.x[0] - 2.0).abs() < 0.05, "minimum at {}", m.x[0]);
        assert!(m.evaluations <= 62, "{} evaluations", m.evaluations);
        assert_eq!(m.evaluations, calls);
    }
}
