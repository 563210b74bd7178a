//! Small dense linear solves for the least-squares fits (`identify`'s Levenberg–Marquardt steps and the standard
//! deviations of every fit's parameters): Gaussian elimination with partial pivoting on an N × N system, and one
//! diagonal entry of the inverse (a parameter's variance from the normal equations, `(JᵀJ)⁻¹`) without forming the
//! whole inverse. N is the number of fitted parameters (3 to 8), so everything lives on the stack.

/// Solves `a x = b` by Gaussian elimination with partial pivoting; `None` when `a` is singular or the solution is
/// not finite.
pub fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() <= 1e-300 || a[pivot][col].is_nan() {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..N {
            let f = a[row][col] / pivot_row[col];
            for (value, above) in a[row].iter_mut().zip(pivot_row).skip(col) {
                *value -= f * above;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let s: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The diagonal entry `k` of `a⁻¹` (the k-th component of the solution of `a x = e_k`); `None` when `a` is
/// singular.
pub fn inverse_diagonal<const N: usize>(a: [[f64; N]; N], k: usize) -> Option<f64> {
    let mut unit = [0.0; N];
    unit[k] = 1.0;
    solve(a, unit).map(|column| column[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A system with a known answer that needs a row swap (zero on the first pivot), its inverse's diagonal
    /// against the hand-computed inverse, and a singular matrix refused.
    #[test]
    fn solves_a_pivoting_system_and_refuses_a_singular_one() {
        let a = [[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [2.0, 0.0, 3.0]];
        // x = (1, 2, 3): a x = (2·2 + 3, 1 + 2, 2 + 9).
        let x = solve(a, [7.0, 3.0, 11.0]).expect("regular");
        for (got, want) in x.iter().zip([1.0, 2.0, 3.0]) {
            assert!((got - want).abs() < 1e-12, "solution {x:?}, want (1, 2, 3)");
        }
        // det a = 0·(3) − 2·(3) + 1·(−2) = −8; (a⁻¹)₀₀ = (1·3 − 0·0)/−8 = −3/8, (a⁻¹)₂₂ = (0·1 − 2·1)/−8 = 1/4.
        let d0 = inverse_diagonal(a, 0).expect("regular");
        let d2 = inverse_diagonal(a, 2).expect("regular");
        assert!((d0 + 0.375).abs() < 1e-12, "(a⁻¹)₀₀ = {d0}, want −0.375");
        assert!((d2 - 0.25).abs() < 1e-12, "(a⁻¹)₂₂ = {d2}, want 0.25");
        assert_eq!(solve([[1.0, 2.0], [2.0, 4.0]], [1.0, 2.0]), None, "singular");
    }
}
