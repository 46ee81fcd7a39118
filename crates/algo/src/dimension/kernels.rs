//! The 6 × 6 operations of the system-track loop and the small solves of
//! the pair tests and the local filters, written out for the structure of
//! their operands.
//!
//! [`cholesky_solve`] (the local filters' residual tests),
//! [`transition_congruence`], [`interleaved_congruence`]
//! and [`interleaved_apply`] keep the order of operations of the nalgebra
//! calls they replace, so they give the same bits (the tests compare them
//! with nalgebra): nalgebra's fixed-size products sum `Σ_k a[i,k] b[k,j]`
//! from k = 0 up, its Cholesky factor is the column-by-column axpy form and
//! its triangular solves are column by column (forward: axpy; backward: a
//! dot product from zero). Terms that are zero by structure (the
//! interleaved transform, the constant-velocity transition) are left out:
//! adding an exact zero does not change a sum, so only the sign of a zero
//! result could differ. [`fuse_step`] computes the same fusion as its
//! nalgebra form by fewer operations (one forward solve, reciprocals), and
//! [`quadratic_form`] the pair test's statistic without square roots, so
//! they agree with their nalgebra forms to rounding, not to the bit.

// The loops index rows and columns as the formulas do.
#![allow(clippy::needless_range_loop)]

use nalgebra::{Matrix3, Matrix6, SMatrix, SVector, Vector3, Vector6};

/// Column-major storage of a 6 × 6 matrix: `m[c][r]` is row r, column c.
type Cols = [[f64; 6]; 6];

fn cols(m: &Matrix6<f64>) -> Cols {
    m.data.0
}

fn matrix(c: Cols) -> Matrix6<f64> {
    Matrix6::from_data(nalgebra::ArrayStorage(c))
}

/// One step of the Bar-Shalom–Campo fusion with zero cross-covariance
/// (Bar-Shalom & Campo 1986 with P₁₂ = 0, the information-weighted mean):
/// ```text
/// x ← x + P (P + Q)⁻¹ (y − x),   P ← P − P (P + Q)⁻¹ P
/// ```
/// by the Cholesky factor L L' = P + Q (its lower triangle read) and one
/// forward solve W = L⁻¹ P, g = L⁻¹ (y − x): P (P + Q)⁻¹ P = W'W and
/// P (P + Q)⁻¹ (y − x) = W'g, so no backward solve, no gain matrix, and
/// the update P − W'W comes out symmetric (the symmetric part of P minus
/// W'W, whose (i, j) and (j, i) are the same sum). Each pivot's reciprocal
/// is taken once and multiplied. `None` when P + Q is not positive
/// definite (a zero, negative or NaN pivot, as nalgebra's Cholesky).
///
/// This is the nalgebra form `gain = (P + Q).cholesky().solve(P)'`,
/// `x + gain (y − x)`, `(P − gain P)` symmetrised, up to rounding: about a
/// third of its operations and 6 divisions instead of 87, so the results
/// differ from it in the last bits (the test bounds the difference).
///
/// On x86-64 with AVX2 the same code is compiled for 4-wide registers. Each
/// operation is the same IEEE operation either way (Rust never contracts a
/// product and a sum into a fused multiply-add), so the bits are too.
pub(super) fn fuse_step(
    x: &Vector6<f64>,
    p: &Matrix6<f64>,
    y: &Vector6<f64>,
    q: &Matrix6<f64>,
) -> Option<(Vector6<f64>, Matrix6<f64>)> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { fuse_step_avx2(x, p, y, q) };
    }
    fuse_step_portable(x, p, y, q)
}

/// [`fuse_step_portable`] compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fuse_step_avx2(
    x: &Vector6<f64>,
    p: &Matrix6<f64>,
    y: &Vector6<f64>,
    q: &Matrix6<f64>,
) -> Option<(Vector6<f64>, Matrix6<f64>)> {
    fuse_step_portable(x, p, y, q)
}

/// The body of [`fuse_step`] for any target.
#[inline(always)]
fn fuse_step_portable(
    x: &Vector6<f64>,
    p: &Matrix6<f64>,
    y: &Vector6<f64>,
    q: &Matrix6<f64>,
) -> Option<(Vector6<f64>, Matrix6<f64>)> {
    let pc = cols(p);
    let qc = cols(q);
    // The Cholesky factor of P + Q, column by column in the lower triangle
    // of `l` (l[c][r]), with the reciprocals of its diagonal.
    let mut l: Cols = [[0.0; 6]; 6];
    for c in 0..6 {
        for r in c..6 {
            l[c][r] = pc[c][r] + qc[c][r];
        }
    }
    let mut inv = [0.0f64; 6];
    for j in 0..6 {
        for k in 0..j {
            let factor = l[k][j];
            for r in j..6 {
                l[j][r] -= factor * l[k][r];
            }
        }
        let diag = l[j][j];
        if diag.is_nan() || diag <= 0.0 {
            return None;
        }
        inv[j] = 1.0 / diag.sqrt();
        for r in j + 1..6 {
            l[j][r] *= inv[j];
        }
    }
    // Forward solve of L [W | g] = [P | y − x], row by row: b[r][c] is
    // W(r, c) for c < 6 and g(r) for c = 6 (the 8th column pads the rows
    // to two 4-wide registers).
    let mut b = [[0.0f64; 8]; 6];
    for (r, row) in b.iter_mut().enumerate() {
        for c in 0..6 {
            row[c] = pc[c][r];
        }
        row[6] = y[r] - x[r];
    }
    for i in 0..6 {
        let scale = inv[i];
        let bi: [f64; 8] = std::array::from_fn(|c| b[i][c] * scale);
        b[i] = bi;
        for r in i + 1..6 {
            let lri = l[i][r];
            for c in 0..8 {
                b[r][c] -= lri * bi[c];
            }
        }
    }
    // W'g and W'W, summed over the rows of W in order.
    let mut wtw = [[0.0f64; 8]; 6];
    for row in &b {
        for i in 0..6 {
            for c in 0..8 {
                wtw[i][c] += row[i] * row[c];
            }
        }
    }
    let xo = Vector6::from_fn(|i, _| x[i] + wtw[i][6]);
    let mut out: Cols = [[0.0; 6]; 6];
    for j in 0..6 {
        for i in 0..6 {
            out[j][i] = (pc[j][i] + pc[i][j]) * 0.5 - wtw[i][j];
        }
    }
    Some((xo, matrix(out)))
}

/// `a⁻¹ b` by Cholesky for a small fixed-size `a`, as nalgebra's
/// `a.cholesky()?.solve(b)`: the factor column by column in axpy form (only
/// the lower triangle of `a` is read), the forward solve in axpy form and
/// the backward one as dot products from zero, each in nalgebra's order.
/// nalgebra's generic code walks dynamic views for these few numbers (the
/// local filters' residual tests); this is the same arithmetic on an array.
/// A pivot of exactly 1 (a padded block) skips its square root and its
/// divisions: √1 = 1 and x / 1 = x exactly, so the bits are the same.
/// `None` when `a` is not positive definite (a zero, negative or NaN pivot).
pub(super) fn cholesky_solve<const M: usize>(
    a: &SMatrix<f64, M, M>,
    b: &SVector<f64, M>,
) -> Option<SVector<f64, M>> {
    // l[c][r]: row r, column c.
    let mut l = a.data.0;
    for j in 0..M {
        for k in 0..j {
            let factor = -l[k][j];
            for r in j..M {
                l[j][r] += factor * l[k][r];
            }
        }
        let diag = l[j][j];
        if diag.is_nan() || diag <= 0.0 {
            return None;
        }
        if diag == 1.0 {
            continue;
        }
        let denom = diag.sqrt();
        l[j][j] = denom;
        for r in j + 1..M {
            l[j][r] /= denom;
        }
    }
    let unit = |d: f64| d == 1.0;
    let mut x = b.data.0[0];
    for i in 0..M {
        let coeff = if unit(l[i][i]) { x[i] } else { x[i] / l[i][i] };
        x[i] = coeff;
        for r in i + 1..M {
            x[r] += -coeff * l[i][r];
        }
    }
    for i in (0..M).rev() {
        let mut dot = 0.0;
        for r in i + 1..M {
            dot += l[i][r] * x[r];
        }
        x[i] = if unit(l[i][i]) {
            x[i] - dot
        } else {
            (x[i] - dot) / l[i][i]
        };
    }
    Some(SVector::from_data(nalgebra::ArrayStorage([x])))
}

/// The pair test's statistic d' C⁻¹ d for the symmetric `c`'s top-left
/// `dim` × `dim` block (2 or 3; its lower triangle read) without square
/// roots: for 2 the closed form (c₁₁ d₀² − 2 c₁₀ d₀ d₁ + c₀₀ d₁²) / (c₀₀ c₁₁ − c₁₀²),
/// for 3 the LDL' factorisation, d' C⁻¹ d = Σ yᵢ² / Dᵢ with L y = d. The same
/// number as the Cholesky solve's d · (C⁻¹ d) to rounding. `None` when the
/// block is not positive definite (a pivot, or for 2 the determinant, not
/// positive, or NaN).
pub(super) fn quadratic_form(c: &Matrix3<f64>, d: &Vector3<f64>, dim: usize) -> Option<f64> {
    let positive = |v: f64| v > 0.0; // false for NaN
    if dim == 2 {
        let (c00, c10, c11) = (c[(0, 0)], c[(1, 0)], c[(1, 1)]);
        let det = c00 * c11 - c10 * c10;
        if !(positive(c00) && positive(det)) {
            return None;
        }
        let num = c11 * d[0] * d[0] - 2.0 * c10 * d[0] * d[1] + c00 * d[1] * d[1];
        return Some(num / det);
    }
    let d0 = c[(0, 0)];
    if !positive(d0) {
        return None;
    }
    let r0 = 1.0 / d0;
    let (l10, l20) = (c[(1, 0)] * r0, c[(2, 0)] * r0);
    let d1 = c[(1, 1)] - l10 * c[(1, 0)];
    if !positive(d1) {
        return None;
    }
    let r1 = 1.0 / d1;
    let l21 = (c[(2, 1)] - l20 * c[(1, 0)]) * r1;
    let d2 = c[(2, 2)] - l20 * c[(2, 0)] - l21 * l21 * d1;
    if !positive(d2) {
        return None;
    }
    let y1 = d[1] - l10 * d[0];
    let y2 = d[2] - l20 * d[0] - l21 * y1;
    Some(d[0] * d[0] * r0 + y1 * y1 * r1 + y2 * y2 / d2)
}

/// `F P F'` for the interleaved constant-velocity transition F (identity
/// with F(2i, 2i+1) = dt), as nalgebra's `f * p * f.transpose()`.
pub(super) fn transition_congruence(p: &Matrix6<f64>, dt: f64) -> Matrix6<f64> {
    let pc = cols(p);
    // (F P)(r, c): P(r, c) + dt P(r + 1, c) for even r, P(r, c) for odd r.
    let mut fp: Cols = [[0.0; 6]; 6];
    for c in 0..6 {
        for r in 0..6 {
            fp[c][r] = if r % 2 == 0 {
                pc[c][r] + dt * pc[c][r + 1]
            } else {
                pc[c][r]
            };
        }
    }
    // (F P F')(r, c) = Σ_k FP(r, k) F(c, k): FP(r, c) + FP(r, c + 1) dt for
    // even c, FP(r, c) for odd c.
    let mut out: Cols = [[0.0; 6]; 6];
    for c in 0..6 {
        for r in 0..6 {
            out[c][r] = if c % 2 == 0 {
                fp[c][r] + fp[c + 1][r] * dt
            } else {
                fp[c][r]
            };
        }
    }
    matrix(out)
}

/// `A Y A'` for the interleaved transform A of a 3 × 3 Jacobian
/// (A(r, c) = J(r/2, c/2) when r and c have the same parity, else 0), as
/// nalgebra's `a * y * a.transpose()`.
pub(super) fn interleaved_congruence(jac: &Matrix3<f64>, y: &Matrix6<f64>) -> Matrix6<f64> {
    let yc = cols(y);
    // (A Y)(r, c) = Σ_k J(r/2, k) Y(2k + r%2, c).
    let mut ay: Cols = [[0.0; 6]; 6];
    for c in 0..6 {
        for r in 0..6 {
            let (i, o) = (r / 2, r % 2);
            ay[c][r] =
                jac[(i, 0)] * yc[c][o] + jac[(i, 1)] * yc[c][o + 2] + jac[(i, 2)] * yc[c][o + 4];
        }
    }
    // (A Y A')(r, c) = Σ_k AY(r, 2k + c%2) J(c/2, k).
    let mut out: Cols = [[0.0; 6]; 6];
    for c in 0..6 {
        let (i, o) = (c / 2, c % 2);
        for r in 0..6 {
            out[c][r] =
                ay[o][r] * jac[(i, 0)] + ay[o + 2][r] * jac[(i, 1)] + ay[o + 4][r] * jac[(i, 2)];
        }
    }
    matrix(out)
}

/// `A y` for the interleaved transform A of a 3 × 3 Jacobian, as nalgebra's
/// `a * y`.
pub(super) fn interleaved_apply(jac: &Matrix3<f64>, y: &Vector6<f64>) -> Vector6<f64> {
    Vector6::from_fn(|r, _| {
        let (i, o) = (r / 2, r % 2);
        jac[(i, 0)] * y[o] + jac[(i, 1)] * y[o + 2] + jac[(i, 2)] * y[o + 4]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic sequence in (−1, 1) (a 64-bit LCG).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        }
        fn spd(&mut self, scale: f64) -> Matrix6<f64> {
            let g = Matrix6::from_fn(|_, _| self.next() * scale);
            g * g.transpose() + Matrix6::identity() * scale
        }
    }

    fn same_bits(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    #[test]
    fn fuse_step_agrees_with_the_nalgebra_form() {
        // The nalgebra form this replaced (Cholesky solve for the gain,
        // P − gain P symmetrised): the same fusion by other operations, so
        // equal to rounding. Differences are measured against the scale of
        // each entry: √(P_ii P_jj) for the covariance, the size of x and y
        // for the state.
        let mut g = Lcg(3);
        let (mut worst_x, mut worst_p): (f64, f64) = (0.0, 0.0);
        for case in 0..500 {
            let scale = [1.0, 1e3, 1e6][case % 3];
            let (p, q) = (g.spd(scale), g.spd(scale * 3.0));
            // Not exactly symmetric, as an extrapolated covariance may be.
            let p = p + Matrix6::from_fn(|r, c| if r < c { 1e-9 * scale } else { 0.0 });
            let x = Vector6::from_fn(|_, _| g.next() * 1e5);
            let y = Vector6::from_fn(|_, _| g.next() * 1e5);
            let chol = (p + q).cholesky().unwrap();
            let gain = chol.solve(&p).transpose();
            let xe = x + gain * (y - x);
            let mut pe = p;
            pe -= gain * p;
            let pe = (pe + pe.transpose()) * 0.5;
            let (xf, pf) = fuse_step(&x, &p, &y, &q).unwrap();
            for i in 0..6 {
                // x and y are of the order of 1e5.
                worst_x = worst_x.max((xe[i] - xf[i]).abs() / 1e5);
                for j in 0..6 {
                    let s = (pe[(i, i)] * pe[(j, j)]).sqrt();
                    worst_p = worst_p.max((pe[(i, j)] - pf[(i, j)]).abs() / s);
                    assert_eq!(pf[(i, j)], pf[(j, i)], "symmetric by construction");
                }
            }
        }
        // Measured: 5.5e-15 and 9.7e-15.
        assert!(worst_x < 1e-13 && worst_p < 1e-13, "{worst_x} {worst_p}");
        // Not positive definite: refused, as nalgebra's cholesky refuses it.
        let p = Matrix6::identity();
        let q = -Matrix6::identity() * 2.0;
        assert!((p + q).cholesky().is_none());
        assert!(fuse_step(&Vector6::zeros(), &p, &Vector6::zeros(), &q).is_none());
        let nan = Matrix6::identity() * f64::NAN;
        assert!(fuse_step(&Vector6::zeros(), &p, &Vector6::zeros(), &nan).is_none());
    }

    fn check_cholesky_solve<const M: usize>(g: &mut Lcg) {
        for case in 0..500 {
            let scale = [1.0, 1e3, 1e6][case % 3];
            let h = SMatrix::<f64, M, M>::from_fn(|_, _| g.next() * scale);
            let mut a = h * h.transpose() + SMatrix::<f64, M, M>::identity() * scale;
            // Only the lower triangle is read: garbage above must not matter.
            if M > 1 {
                a[(0, M - 1)] += 0.25 * scale;
            }
            let b = SVector::<f64, M>::from_fn(|_, _| g.next() * 1e4);
            let want = a.cholesky().unwrap().solve(&b);
            let got = cholesky_solve(&a, &b).unwrap();
            assert!(
                same_bits(want.as_slice(), got.as_slice()),
                "M {M} case {case}"
            );
        }
        let bad = -SMatrix::<f64, M, M>::identity();
        assert!(bad.cholesky().is_none());
        assert!(cholesky_solve(&bad, &SVector::<f64, M>::zeros()).is_none());
        let nan = SMatrix::<f64, M, M>::identity() * f64::NAN;
        assert!(cholesky_solve(&nan, &SVector::<f64, M>::zeros()).is_none());
    }

    #[test]
    fn cholesky_solve_gives_the_bits_of_nalgebra() {
        let mut g = Lcg(7);
        check_cholesky_solve::<1>(&mut g);
        check_cholesky_solve::<2>(&mut g);
        check_cholesky_solve::<3>(&mut g);
        // A padded 2 × 2 block: exact zeros and a 1 beside it.
        for _ in 0..200 {
            let h = nalgebra::Matrix2::from_fn(|_, _| g.next() * 1e3);
            let c = h * h.transpose() + nalgebra::Matrix2::identity();
            let mut a = Matrix3::zeros();
            a.fixed_view_mut::<2, 2>(0, 0).copy_from(&c);
            a[(2, 2)] = 1.0;
            let b = nalgebra::Vector3::new(g.next() * 1e3, g.next() * 1e3, 0.0);
            let want = a.cholesky().unwrap().solve(&b);
            let got = cholesky_solve(&a, &b).unwrap();
            assert!(same_bits(want.as_slice(), got.as_slice()));
        }
    }

    #[test]
    fn quadratic_form_agrees_with_the_cholesky_solve() {
        let mut g = Lcg(5);
        let mut worst: f64 = 0.0;
        for case in 0..600 {
            let scale: f64 = [1.0, 1e3, 1e6][case % 3];
            // s (G G' + I): a condition number of tens, as the pair tests'
            // sums of covariances (the two forms differ by the rounding the
            // condition number amplifies).
            let h = Matrix3::from_fn(|_, _| g.next() * 2.0 * scale.sqrt());
            let c = h * h.transpose() + Matrix3::identity() * scale;
            let d = nalgebra::Vector3::new(g.next(), g.next(), g.next()) * scale.sqrt();
            for dim in [2, 3] {
                let mut a = c;
                let mut dd = d;
                if dim == 2 {
                    // The pair test's padding: a unit third pivot, d₂ = 0.
                    for i in 0..2 {
                        a[(2, i)] = 0.0;
                        a[(i, 2)] = 0.0;
                    }
                    a[(2, 2)] = 1.0;
                    dd[2] = 0.0;
                }
                let want = dd.dot(&cholesky_solve(&a, &dd).unwrap());
                let got = quadratic_form(&a, &dd, dim).unwrap();
                worst = worst.max((got - want).abs() / want);
            }
        }
        assert!(worst < 1e-12, "{worst}");
        for dim in [2, 3] {
            let bad = -Matrix3::identity();
            assert!(quadratic_form(&bad, &nalgebra::Vector3::zeros(), dim).is_none());
            let nan = Matrix3::identity() * f64::NAN;
            assert!(quadratic_form(&nan, &nalgebra::Vector3::zeros(), dim).is_none());
        }
        // Singular: the determinant, then the last pivot, is zero.
        let sing = Matrix3::new(1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0);
        assert!(quadratic_form(&sing, &nalgebra::Vector3::zeros(), 2).is_none());
        assert!(quadratic_form(&sing, &nalgebra::Vector3::zeros(), 3).is_none());
    }

    #[test]
    fn fuse_step_gives_the_same_bits_with_and_without_avx2() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut g = Lcg(9);
            for case in 0..300 {
                let scale = [1.0, 1e3, 1e6][case % 3];
                let (p, q) = (g.spd(scale), g.spd(scale * 2.0));
                let x = Vector6::from_fn(|_, _| g.next() * 1e5);
                let y = Vector6::from_fn(|_, _| g.next() * 1e5);
                let (xa, pa) = unsafe { fuse_step_avx2(&x, &p, &y, &q) }.unwrap();
                let (xp, pp) = fuse_step_portable(&x, &p, &y, &q).unwrap();
                assert!(same_bits(xa.as_slice(), xp.as_slice()), "case {case}");
                assert!(same_bits(pa.as_slice(), pp.as_slice()), "case {case}");
            }
        }
    }

    #[test]
    fn structured_products_give_the_bits_of_the_dense_ones() {
        let mut g = Lcg(11);
        for case in 0..500 {
            let p = g.spd(1e4);
            let dt = g.next() * 20.0;
            let mut f = Matrix6::identity();
            for i in 0..3 {
                f[(2 * i, 2 * i + 1)] = dt;
            }
            let dense = f * p * f.transpose();
            let ours = transition_congruence(&p, dt);
            assert!(same_bits(dense.as_slice(), ours.as_slice()), "case {case}");

            let jac = Matrix3::from_fn(|_, _| g.next() * 2.0);
            let a = Matrix6::from_fn(|r, c| {
                if r % 2 == c % 2 {
                    jac[(r / 2, c / 2)]
                } else {
                    0.0
                }
            });
            let dense = a * p * a.transpose();
            let ours = interleaved_congruence(&jac, &p);
            assert!(same_bits(dense.as_slice(), ours.as_slice()), "case {case}");
            let y = Vector6::from_fn(|_, _| g.next() * 1e3);
            assert!(same_bits(
                (a * y).as_slice(),
                interleaved_apply(&jac, &y).as_slice()
            ));
        }
    }
}
