//! Eigenvalues and eigenvectors of a real symmetric tridiagonal matrix by the implicit QL method with Wilkinson
//! shifts (the `tql2` algorithm of EISPACK), for the modal fast path ([`super::modal`]).
//!
//! O(n²) for the eigenvalues and O(n³) with the eigenvectors; backward stable: the computed eigenpairs are exact for
//! a matrix within a few units of rounding (relative to its norm) of the given one, and the eigenvectors are
//! orthonormal to rounding. Small and self-contained on purpose (a dense linear-algebra crate is not wanted here).

/// Most QL sweeps spent on one eigenvalue before giving up (EISPACK allows 30; two or three are typical).
const MAX_SWEEPS: usize = 60;

/// The eigen decomposition `A = Q Λ Qᵀ` of a symmetric tridiagonal matrix.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SymmetricEigen {
    /// The eigenvalues λ_j, ascending.
    pub values: Vec<f64>,
    /// The orthonormal eigenvectors, row-major n × n: `vectors[k * n + j]` is component k of eigenvector j.
    pub vectors: Vec<f64>,
}

/// The QL iteration did not converge (only for non-finite input in practice).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the symmetric tridiagonal eigen solver did not converge for eigenvalue {index}")]
pub(crate) struct NoConvergence {
    /// Index of the eigenvalue that did not converge.
    pub index: usize,
}

/// Decomposes the symmetric tridiagonal matrix with diagonal `diagonal` (length n ≥ 1) and off-diagonal
/// `off_diagonal` (length n − 1: entry i couples rows i and i + 1). Errors if the iteration does not converge (a NaN
/// or infinite entry).
pub(crate) fn symmetric_tridiagonal_eigen(
    diagonal: &[f64],
    off_diagonal: &[f64],
) -> Result<SymmetricEigen, NoConvergence> {
    let n = diagonal.len();
    let mut d = diagonal.to_vec();
    let mut e = vec![0.0; n];
    e[..n.saturating_sub(1)].copy_from_slice(&off_diagonal[..n.saturating_sub(1)]);
    let mut v = vec![0.0; n * n];
    for k in 0..n {
        v[k * n + k] = 1.0;
    }
    if d.iter().chain(&e).any(|x| !x.is_finite()) {
        return Err(NoConvergence { index: 0 });
    }
    ql_implicit(&mut d, &mut e, &mut v)?;
    Ok(sorted(d, v))
}

/// The implicit QL iteration on (d, e) accumulating the rotations into the columns of `v` (EISPACK `tql2`).
fn ql_implicit(d: &mut [f64], e: &mut [f64], v: &mut [f64]) -> Result<(), NoConvergence> {
    let n = d.len();
    let eps = f64::EPSILON;
    let (mut shift_sum, mut scale) = (0.0, 0.0f64);
    for l in 0..n {
        scale = scale.max(d[l].abs() + e[l].abs());
        let m = (l..n).find(|&m| e[m].abs() <= eps * scale).unwrap_or(n - 1);
        if m > l {
            let mut sweeps = 0;
            loop {
                sweeps += 1;
                if sweeps > MAX_SWEEPS {
                    return Err(NoConvergence { index: l });
                }
                shift_sum += shift(d, e, l);
                ql_sweep(d, e, v, l, m);
                if e[l].abs() <= eps * scale {
                    break;
                }
            }
        }
        d[l] += shift_sum;
        e[l] = 0.0;
    }
    Ok(())
}

/// Wilkinson shift from the leading 2 × 2 block at `l`: moves it into d[l], d[l + 1] and subtracts it from the rest
/// of the diagonal; returns the shift.
fn shift(d: &mut [f64], e: &[f64], l: usize) -> f64 {
    let g = d[l];
    let p = (d[l + 1] - g) / (2.0 * e[l]);
    let r = p.hypot(1.0).copysign(p);
    d[l] = e[l] / (p + r);
    d[l + 1] = e[l] * (p + r);
    let h = g - d[l];
    for x in &mut d[l + 2..] {
        *x -= h;
    }
    h
}

/// One implicit QL sweep of plane rotations from m − 1 down to l, accumulated into `v`.
fn ql_sweep(d: &mut [f64], e: &mut [f64], v: &mut [f64], l: usize, m: usize) {
    let n = d.len();
    let dl1 = d[l + 1];
    let el1 = e[l + 1];
    let mut p = d[m];
    let (mut c, mut c2, mut c3) = (1.0, 1.0, 1.0);
    let (mut s, mut s2) = (0.0, 0.0);
    for i in (l..m).rev() {
        c3 = c2;
        c2 = c;
        s2 = s;
        let g = c * e[i];
        let h = c * p;
        let r = p.hypot(e[i]);
        e[i + 1] = s * r;
        s = e[i] / r;
        c = p / r;
        p = c * d[i] - s * g;
        d[i + 1] = h + s * (c * g + s * d[i]);
        for k in 0..n {
            let row = k * n;
            let (vi, vi1) = (v[row + i], v[row + i + 1]);
            v[row + i + 1] = s * vi + c * vi1;
            v[row + i] = c * vi - s * vi1;
        }
    }
    let p = -s * s2 * c3 * el1 * e[l] / dl1;
    e[l] = s * p;
    d[l] = c * p;
}

/// Eigenvalues ascending with their eigenvectors.
fn sorted(values: Vec<f64>, vectors: Vec<f64>) -> SymmetricEigen {
    let n = values.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let mut out = vec![0.0; n * n];
    for k in 0..n {
        for (j, &from) in order.iter().enumerate() {
            out[k * n + j] = vectors[k * n + from];
        }
    }
    SymmetricEigen {
        values: order.iter().map(|&j| values[j]).collect(),
        vectors: out,
    }
}

#[cfg(test)]
mod tests {
    //! Against closed forms (the second-difference matrix) and the defining identities A q = λ q, Qᵀ Q = I.

    use super::*;

    /// Largest |A q_j − λ_j q_j| and |Qᵀ Q − I| entry.
    fn residuals(d: &[f64], e: &[f64], eig: &SymmetricEigen) -> (f64, f64) {
        let n = d.len();
        let q = |k: usize, j: usize| eig.vectors[k * n + j];
        let (mut pair, mut ortho) = (0.0f64, 0.0f64);
        for j in 0..n {
            for k in 0..n {
                let mut aq = d[k] * q(k, j);
                if k > 0 {
                    aq += e[k - 1] * q(k - 1, j);
                }
                if k + 1 < n {
                    aq += e[k] * q(k + 1, j);
                }
                pair = pair.max((aq - eig.values[j] * q(k, j)).abs());
            }
            for i in 0..n {
                let dot: f64 = (0..n).map(|k| q(k, i) * q(k, j)).sum();
                ortho = ortho.max((dot - if i == j { 1.0 } else { 0.0 }).abs());
            }
        }
        (pair, ortho)
    }

    #[test]
    fn second_difference_matrix_has_its_closed_form_eigenvalues() {
        // tridiag(−1, 2, −1) of size n: λ_j = 2 − 2 cos(jπ/(n+1)), j = 1..n.
        let n = 40;
        let eig = symmetric_tridiagonal_eigen(&vec![2.0; n], &vec![-1.0; n - 1]).unwrap();
        for (j, got) in eig.values.iter().enumerate() {
            let want = 2.0 - 2.0 * ((j + 1) as f64 * std::f64::consts::PI / (n + 1) as f64).cos();
            assert!((got - want).abs() < 1e-13, "λ_{j}: {got} vs closed form {want}");
        }
        let (pair, ortho) = residuals(&vec![2.0; n], &vec![-1.0; n - 1], &eig);
        assert!(pair < 1e-13 && ortho < 1e-13, "residual {pair}, orthogonality {ortho}");
    }

    #[test]
    fn widely_scaled_matrix_keeps_small_residuals() {
        // Diagonal entries over nine decades, as in a graded finite-volume chain.
        let n = 60;
        let d: Vec<f64> = (0..n).map(|i| 10f64.powf(6.0 - 9.0 * i as f64 / n as f64)).collect();
        let e: Vec<f64> = (0..n - 1).map(|i| -0.4 * (d[i] * d[i + 1]).sqrt()).collect();
        let eig = symmetric_tridiagonal_eigen(&d, &e).unwrap();
        let (pair, ortho) = residuals(&d, &e, &eig);
        assert!(pair < 1e-8, "|A q − λ q| = {pair} against a norm of 1e6");
        assert!(ortho < 1e-13, "orthogonality {ortho}");
        let trace: f64 = d.iter().sum();
        let sum: f64 = eig.values.iter().sum();
        assert!((trace - sum).abs() < 1e-9 * trace, "trace {trace} vs Σλ {sum}");
    }

    #[test]
    fn one_by_one_and_non_finite_input() {
        let eig = symmetric_tridiagonal_eigen(&[3.5], &[]).unwrap();
        assert_eq!((eig.values, eig.vectors), (vec![3.5], vec![1.0]));
        assert!(symmetric_tridiagonal_eigen(&[1.0, f64::NAN], &[0.5]).is_err());
    }
}
