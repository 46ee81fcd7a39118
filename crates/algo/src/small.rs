//! Small dense linear algebra on the stack, for the hot loops of correlation:
//! square matrices of dimension n ≤ [`MAX_DIM`] stored row-major in fixed
//! arrays, so that a test statistic costs no allocation.

use nalgebra::DMatrix;

use crate::AlgoError;

/// Calls `f::<N>(args)` with N the runtime dimension n, 1 to [`MAX_DIM`]
/// (one kernel per dimension, its matrices on the stack at their exact
/// size); any other n gives `None`, or the third argument when there is one.
macro_rules! by_dim {
    ($n:expr, $f:ident ( $($arg:expr),* )) => {
        $crate::small::by_dim!($n, $f($($arg),*), None)
    };
    ($n:expr, $f:ident ( $($arg:expr),* ), $other:expr) => {
        match $n {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            4 => $f::<4>($($arg),*),
            5 => $f::<5>($($arg),*),
            6 => $f::<6>($($arg),*),
            7 => $f::<7>($($arg),*),
            8 => $f::<8>($($arg),*),
            9 => $f::<9>($($arg),*),
            _ => $other,
        }
    };
}
pub(crate) use by_dim;

/// Largest state dimension the stack routines handle.
pub const MAX_DIM: usize = 9;

/// A row-major n×n matrix in a fixed buffer (only the leading n² entries are used).
pub type Sq = [f64; MAX_DIM * MAX_DIM];

/// The zero buffer.
pub const ZERO: Sq = [0.0; MAX_DIM * MAX_DIM];

/// d' S⁻¹ d for a symmetric positive definite S (n×n, row-major) by a
/// Cholesky factorisation; `None` when S is not positive definite or the
/// result is not finite.
pub fn quad_form_inv(s: &[f64], d: &[f64], n: usize) -> Option<f64> {
    debug_assert!(n <= MAX_DIM && s.len() >= n * n && d.len() >= n);
    // One monomorphised kernel per dimension keeps the factor on the stack
    // at its exact size (no zeroing of a 9×9 buffer for a 4×4 problem).
    by_dim!(n, quad_form_inv_n(s, d))
}

/// The lower Cholesky factor of a row-major N×N matrix, or `None` when it is
/// not positive definite.
#[allow(clippy::needless_range_loop)] // textbook index form of Cholesky
#[inline]
pub fn cholesky_n<const N: usize>(s: &[f64]) -> Option<[[f64; N]; N]> {
    let mut l = [[0.0f64; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut sum = s[i * N + j];
            for k in 0..j {
                sum -= l[i][k] * l[j][k];
            }
            if i == j {
                if sum.is_nan() || sum <= 0.0 {
                    return None;
                }
                l[i][i] = sum.sqrt();
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    Some(l)
}

/// d' S⁻¹ d for an N×N S (row-major), the kernel of [`quad_form_inv`].
#[allow(clippy::needless_range_loop)]
#[inline]
pub fn quad_form_inv_n<const N: usize>(s: &[f64], d: &[f64]) -> Option<f64> {
    let l = cholesky_n::<N>(s)?;
    // Forward substitution L y = d; then d' S⁻¹ d = ‖y‖².
    let mut y = [0.0f64; N];
    let mut q = 0.0;
    for i in 0..N {
        let mut sum = d[i];
        for k in 0..i {
            sum -= l[i][k] * y[k];
        }
        y[i] = sum / l[i][i];
        q += y[i] * y[i];
    }
    q.is_finite().then_some(q)
}

/// X = S⁻¹ B from the Cholesky factor L of S (S = L L') and a row-major
/// N×N B: forward then back substitution, column by column.
#[allow(clippy::needless_range_loop)]
#[inline]
pub fn cholesky_solve_n<const N: usize>(l: &[[f64; N]; N], b: &[f64]) -> [[f64; N]; N] {
    let mut x = [[0.0f64; N]; N];
    for c in 0..N {
        // L y = b_c, then L' x_c = y.
        let mut y = [0.0f64; N];
        for i in 0..N {
            let mut sum = b[i * N + c];
            for k in 0..i {
                sum -= l[i][k] * y[k];
            }
            y[i] = sum / l[i][i];
        }
        for i in (0..N).rev() {
            let mut sum = y[i];
            for k in i + 1..N {
                sum -= l[k][i] * x[k][c];
            }
            x[i][c] = sum / l[i][i];
        }
    }
    x
}

/// a · b for N×N row-major matrices, exactly as [`mul`] sums.
#[allow(clippy::needless_range_loop)]
#[inline]
pub fn mul_n<const N: usize>(a: &[f64], b: &[f64]) -> [[f64; N]; N] {
    let mut c = [[0.0f64; N]; N];
    for i in 0..N {
        for k in 0..N {
            let aik = a[i * N + k];
            if aik == 0.0 {
                continue;
            }
            for j in 0..N {
                c[i][j] += aik * b[k * N + j];
            }
        }
    }
    c
}

/// a · bᵀ for N×N row-major matrices, exactly as [`mul_t`] sums (each
/// entry accumulates its k terms in the same order from 0, so the bits are
/// the same), with the loops ordered so that the inner one vectorises.
#[allow(clippy::needless_range_loop)]
#[inline]
pub fn mul_t_n<const N: usize>(a: &[f64], b: &[f64]) -> [[f64; N]; N] {
    let mut bt = [[0.0f64; N]; N];
    for j in 0..N {
        for k in 0..N {
            bt[k][j] = b[j * N + k];
        }
    }
    let mut c = [[0.0f64; N]; N];
    for i in 0..N {
        for k in 0..N {
            let aik = a[i * N + k];
            for j in 0..N {
                c[i][j] += aik * bt[k][j];
            }
        }
    }
    c
}

/// trace(S⁻¹) of a symmetric positive definite S (n×n, row-major):
/// with S = L L', trace(S⁻¹) = ‖L⁻¹‖²_F. `None` when S is not positive definite.
pub fn trace_inverse(s: &[f64], n: usize) -> Option<f64> {
    debug_assert!(n <= MAX_DIM && s.len() >= n * n);
    by_dim!(n, trace_inverse_n(s))
}

#[allow(clippy::needless_range_loop)]
fn trace_inverse_n<const N: usize>(s: &[f64]) -> Option<f64> {
    let l = cholesky_n::<N>(s)?;
    // Column c of L⁻¹ solves L y = e_c (y_i = 0 for i < c).
    let mut total = 0.0;
    for c in 0..N {
        let mut y = [0.0f64; N];
        for i in c..N {
            let mut sum = if i == c { 1.0 } else { 0.0 };
            for k in c..i {
                sum -= l[i][k] * y[k];
            }
            y[i] = sum / l[i][i];
            total += y[i] * y[i];
        }
    }
    total.is_finite().then_some(total)
}

/// Checks that a row-major n×n matrix is a covariance: finite, symmetric
/// within [`SYMMETRY_RTOL`](crate::gaussian::SYMMETRY_RTOL) of its
/// largest entry, and positive definite (a Cholesky factorisation exists).
/// The flat counterpart of [`check_covariance`](crate::gaussian::check_covariance),
/// without allocation.
pub fn check_covariance(what: &'static str, p: &[f64], n: usize) -> Result<(), AlgoError> {
    if n == 0 || n > MAX_DIM || p.len() != n * n {
        return Err(AlgoError::DimensionMismatch {
            what,
            expected: n * n,
            found: p.len(),
        });
    }
    if p.iter().any(|v| !v.is_finite()) {
        return Err(AlgoError::NonFinite { what });
    }
    let scale = p.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut worst = 0.0f64;
    for i in 0..n {
        for j in 0..i {
            worst = worst.max((p[i * n + j] - p[j * n + i]).abs());
        }
    }
    if worst > crate::gaussian::SYMMETRY_RTOL * scale {
        return Err(AlgoError::NotSymmetric {
            what,
            max_abs_asymmetry: worst,
        });
    }
    // d'P⁻¹d with d = 0 succeeds exactly when the factorisation does.
    quad_form_inv(p, &[0.0; MAX_DIM], n)
        .map(|_| ())
        .ok_or(AlgoError::NotPositiveDefinite { what })
}

/// The entries of a matrix in row-major order (nalgebra stores columns).
pub fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    let (r, c) = m.shape();
    let mut out = Vec::with_capacity(r * c);
    for i in 0..r {
        out.extend((0..c).map(|j| m[(i, j)]));
    }
    out
}

/// A square matrix of dimension ≤ [`MAX_DIM`] in a stack buffer, row-major.
pub fn to_sq(m: &DMatrix<f64>) -> Sq {
    let mut s = ZERO;
    let n = m.nrows();
    debug_assert!(n <= MAX_DIM && m.ncols() == n);
    s[..n * n].copy_from_slice(&row_major(m));
    s
}

/// c = a · b (n×n, row-major).
pub fn mul(a: &[f64], b: &[f64], n: usize) -> Sq {
    let mut c = ZERO;
    for i in 0..n {
        for k in 0..n {
            let aik = a[i * n + k];
            if aik == 0.0 {
                continue;
            }
            for j in 0..n {
                c[i * n + j] += aik * b[k * n + j];
            }
        }
    }
    c
}

/// c = a · bᵀ (n×n, row-major).
pub fn mul_t(a: &[f64], b: &[f64], n: usize) -> Sq {
    let mut c = ZERO;
    for i in 0..n {
        for j in 0..n {
            let mut sum = 0.0;
            for k in 0..n {
                sum += a[i * n + k] * b[j * n + k];
            }
            c[i * n + j] = sum;
        }
    }
    c
}

/// The lower Cholesky factor L (L Lᵀ = s) of an n×n row-major matrix,
/// row-major in a stack buffer ([`cholesky_n`] at the exact size), or
/// `None` when it is not positive definite.
pub fn cholesky(s: &[f64], n: usize) -> Option<Sq> {
    fn flat<const N: usize>(s: &[f64]) -> Option<Sq> {
        let l = cholesky_n::<N>(s)?;
        let mut out = ZERO;
        for (i, row) in l.iter().enumerate() {
            out[i * N..(i + 1) * N].copy_from_slice(row);
        }
        Some(out)
    }
    by_dim!(n, flat(s))
}

/// Y with L Y = B, for a lower triangular L (n×n, row-major; B n×n).
pub fn solve_lower(l: &[f64], b: &[f64], n: usize) -> Sq {
    let mut y = ZERO;
    for c in 0..n {
        for i in 0..n {
            let mut sum = b[i * n + c];
            for k in 0..i {
                sum -= l[i * n + k] * y[k * n + c];
            }
            y[i * n + c] = sum / l[i * n + i];
        }
    }
    y
}

/// The inverse of a symmetric positive definite n×n matrix (row-major) by
/// its Cholesky factor, a⁻¹ = L⁻ᵀ L⁻¹ (exactly symmetric); `None` when it
/// is not positive definite.
pub fn inverse_spd(a: &[f64], n: usize) -> Option<Sq> {
    Some(inverse_from_cholesky(&cholesky(a, n)?, n))
}

/// a⁻¹ = L⁻ᵀ L⁻¹ from the lower Cholesky factor L of a (n×n, row-major),
/// exactly symmetric.
pub fn inverse_from_cholesky(l: &[f64], n: usize) -> Sq {
    let mut eye = ZERO;
    for i in 0..n {
        eye[i * n + i] = 1.0;
    }
    let li = solve_lower(l, &eye, n);
    let mut inv = ZERO;
    for i in 0..n {
        for j in i..n {
            let e: f64 = (j..n).map(|k| li[k * n + i] * li[k * n + j]).sum();
            inv[i * n + j] = e;
            inv[j * n + i] = e;
        }
    }
    inv
}

/// aᵀ (n×n, row-major).
pub fn transpose(a: &[f64], n: usize) -> Sq {
    let mut t = ZERO;
    for i in 0..n {
        for j in 0..n {
            t[j * n + i] = a[i * n + j];
        }
    }
    t
}

/// The eigenvalues λ and eigenvectors V (columns, row-major) of a symmetric
/// n×n matrix, a = V diag(λ) Vᵀ, by cyclic Jacobi rotations (Golub & Van
/// Loan, algorithm 8.5.3; the rotation of Numerical Recipes §11.1): sweeps
/// until every off-diagonal entry is below 1e-300 or negligible against its
/// diagonal pair (at most 100 sweeps; Jacobi converges quadratically, a 6×6
/// takes 5–7). Accurate to the rounding of the entries, for any spread of
/// eigenvalues.
pub fn symmetric_eigen(a: &[f64], n: usize) -> ([f64; MAX_DIM], Sq) {
    let mut m = ZERO;
    m[..n * n].copy_from_slice(&a[..n * n]);
    let mut v = ZERO;
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _ in 0..100 {
        let mut rotated = false;
        for p in 0..n {
            for q in p + 1..n {
                let apq = m[p * n + q];
                let (app, aqq) = (m[p * n + p], m[q * n + q]);
                // Negligible: below the rounding of both diagonal entries.
                if apq.abs() < 1e-300 || apq.abs() <= f64::EPSILON * 1e-3 * app.abs().min(aqq.abs())
                {
                    m[p * n + q] = 0.0;
                    m[q * n + p] = 0.0;
                    continue;
                }
                rotated = true;
                let theta = (aqq - app) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + theta.hypot(1.0));
                let c = 1.0 / t.hypot(1.0);
                let s = t * c;
                for k in 0..n {
                    let (mkp, mkq) = (m[k * n + p], m[k * n + q]);
                    m[k * n + p] = c * mkp - s * mkq;
                    m[k * n + q] = s * mkp + c * mkq;
                }
                for k in 0..n {
                    let (mpk, mqk) = (m[p * n + k], m[q * n + k]);
                    m[p * n + k] = c * mpk - s * mqk;
                    m[q * n + k] = s * mpk + c * mqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
                // The rotated pair exactly (NR eq. 11.1.14): the entry is
                // zero by construction, not the rounding noise of the sums.
                m[p * n + p] = app - t * apq;
                m[q * n + q] = aqq + t * apq;
                m[p * n + q] = 0.0;
                m[q * n + p] = 0.0;
            }
        }
        if !rotated {
            break;
        }
    }
    let mut lambda = [0.0; MAX_DIM];
    for i in 0..n {
        lambda[i] = m[i * n + i];
    }
    (lambda, v)
}

/// The largest eigenvalue of a symmetric positive semi-definite 2×2 or 3×3
/// block, bounded from above by its trace (exact enough for gating bounds:
/// the trace is never smaller than the largest eigenvalue).
pub fn trace_bound(s: &[f64], n: usize, idx: &[usize]) -> f64 {
    idx.iter().map(|&i| s[i * n + i]).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_eigen_by_hand_and_reconstructs() {
        // [[2, 1], [1, 2]]: eigenvalues 1 and 3, vectors (1, −1)/√2, (1, 1)/√2.
        let (l, v) = symmetric_eigen(&[2.0, 1.0, 1.0, 2.0], 2);
        let mut pairs = [(l[0], v[0], v[2]), (l[1], v[1], v[3])];
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert!((pairs[0].0 - 1.0).abs() < 1e-15 && (pairs[1].0 - 3.0).abs() < 1e-15);
        let r = std::f64::consts::FRAC_1_SQRT_2;
        assert!((pairs[0].1.abs() - r).abs() < 1e-15 && (pairs[0].1 + pairs[0].2).abs() < 1e-15);
        assert!((pairs[1].1 - pairs[1].2).abs() < 1e-15);
        // A 6×6 with eigenvalues spread over 12 decades: V diag(λ) Vᵀ gives
        // it back, V is orthonormal, and the λ match nalgebra's.
        let b = DMatrix::from_fn(6, 6, |i, j| {
            ((i * 7 + j * 3) % 5) as f64 - 2.0 + (i == j) as u8 as f64
        });
        let d = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![
            1e-6, 1e-3, 1.0, 10.0, 1e3, 1e6,
        ]));
        let a = &b * d * b.transpose();
        let (l, v) = symmetric_eigen(&row_major(&a), 6);
        let vm = DMatrix::from_row_slice(6, 6, &v[..36]);
        let back = &vm
            * DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&l[..6]))
            * vm.transpose();
        assert!(
            (&back - &a).abs().max() <= 1e-9 * a.abs().max(),
            "{back} vs {a}"
        );
        assert!((vm.transpose() * &vm - DMatrix::identity(6, 6)).abs().max() < 1e-13);
        let mut ours: Vec<f64> = l[..6].to_vec();
        let mut theirs: Vec<f64> = a
            .clone()
            .symmetric_eigen()
            .eigenvalues
            .iter()
            .copied()
            .collect();
        ours.sort_by(f64::total_cmp);
        theirs.sort_by(f64::total_cmp);
        for (o, t) in ours.iter().zip(&theirs) {
            assert!(
                (o - t).abs() <= 1e-9 * a.abs().max(),
                "{ours:?} vs {theirs:?}"
            );
        }
    }

    #[test]
    fn triangular_solves_by_hand() {
        // L = [[2, 0], [1, 3]]: L Lᵀ = [[4, 2], [2, 10]].
        let l = cholesky(&[4.0, 2.0, 2.0, 10.0], 2).unwrap();
        assert_eq!(&l[..4], &[2.0, 0.0, 1.0, 3.0]);
        // L Y = [[4, 2], [11, 4]]: columns (2, 3) and (1, 1).
        assert_eq!(
            &solve_lower(&l, &[4.0, 2.0, 11.0, 4.0], 2)[..4],
            &[2.0, 1.0, 3.0, 1.0]
        );
        assert_eq!(
            &transpose(&[1.0, 2.0, 3.0, 4.0], 2)[..4],
            &[1.0, 3.0, 2.0, 4.0]
        );
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }

    #[test]
    fn quadratic_form_by_hand() {
        // S = [[4, 2], [2, 3]], d = [1, 2]. S⁻¹ = [[3, −2], [−2, 4]] / 8, so
        // d' S⁻¹ d = (3·1 − 2·2·1·2 + 4·4) / 8 = (3 − 8 + 16) / 8 = 11/8.
        let q = quad_form_inv(&[4.0, 2.0, 2.0, 3.0], &[1.0, 2.0], 2).unwrap();
        assert!((q - 11.0 / 8.0).abs() < 1e-15);
        assert!(quad_form_inv(&[1.0, 2.0, 2.0, 1.0], &[1.0, 0.0], 2).is_none());
        assert!(quad_form_inv(&[f64::NAN, 0.0, 0.0, 1.0], &[1.0, 0.0], 2).is_none());
    }

    #[test]
    fn covariance_checks() {
        assert!(check_covariance("p", &[2.0, 1.0, 1.0, 2.0], 2).is_ok());
        assert!(matches!(
            check_covariance("p", &[2.0, 1.0, 1.5, 2.0], 2),
            Err(AlgoError::NotSymmetric { .. })
        ));
        assert!(matches!(
            check_covariance("p", &[1.0, 2.0, 2.0, 1.0], 2),
            Err(AlgoError::NotPositiveDefinite { .. })
        ));
        assert!(matches!(
            check_covariance("p", &[f64::NAN, 0.0, 0.0, 1.0], 2),
            Err(AlgoError::NonFinite { .. })
        ));
        assert!(check_covariance("p", &[1.0, 0.0, 0.0], 2).is_err());
    }

    #[test]
    fn trace_of_the_inverse_by_hand() {
        // S = [[4, 2], [2, 3]]: S⁻¹ = [[3, −2], [−2, 4]] / 8, trace 7/8.
        let t = trace_inverse(&[4.0, 2.0, 2.0, 3.0], 2).unwrap();
        assert!((t - 7.0 / 8.0).abs() < 1e-15);
        assert!(trace_inverse(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }

    #[test]
    fn cholesky_solve_by_hand() {
        // S = [[4, 2], [2, 3]], S⁻¹ = [[3, −2], [−2, 4]] / 8. B = [[1, 0], [2, 8]]:
        // S⁻¹B = [[3 − 4, −16], [−2 + 8, 32]] / 8 = [[−1/8, −2], [3/4, 4]].
        let l = cholesky_n::<2>(&[4.0, 2.0, 2.0, 3.0]).unwrap();
        let x = cholesky_solve_n(&l, &[1.0, 0.0, 2.0, 8.0]);
        let want = [-0.125, -2.0, 0.75, 4.0];
        for (g, w) in x.as_flattened().iter().zip(want) {
            assert!((g - w).abs() < 1e-15, "{x:?}");
        }
        assert!(cholesky_n::<2>(&[1.0, 2.0, 2.0, 1.0]).is_none());
        // The fixed-size products sum as the general ones.
        let (a, b) = ([1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]);
        assert_eq!(mul_n::<2>(&a, &b).as_flattened(), &mul(&a, &b, 2)[..4]);
        assert_eq!(mul_t_n::<2>(&a, &b).as_flattened(), &mul_t(&a, &b, 2)[..4]);
    }

    #[test]
    fn products_by_hand() {
        let a = [1.0, 2.0, 3.0, 4.0];
        let b = [5.0, 6.0, 7.0, 8.0];
        // a·b = [[1·5+2·7, 1·6+2·8], [3·5+4·7, 3·6+4·8]] = [[19, 22], [43, 50]]
        assert_eq!(&mul(&a, &b, 2)[..4], &[19.0, 22.0, 43.0, 50.0]);
        // a·bᵀ = [[1·5+2·6, 1·7+2·8], [3·5+4·6, 3·7+4·8]] = [[17, 23], [39, 53]]
        assert_eq!(&mul_t(&a, &b, 2)[..4], &[17.0, 23.0, 39.0, 53.0]);
    }
}
