//! Fusion of correlated local tracks into a system track: Bar-Shalom–Campo
//! when the cross-covariance of the two estimates is known, covariance
//! intersection (Julier–Uhlmann) when it is not.

use nalgebra::{DMatrix, DVector};

use crate::{AlgoError, small};

/// A fused estimate and how it was obtained.
#[derive(Debug, Clone, PartialEq)]
pub struct Fused {
    /// Fused state.
    pub x: DVector<f64>,
    /// Fused covariance.
    pub p: DMatrix<f64>,
    /// Covariance-intersection weights of the successive fusions (empty for
    /// Bar-Shalom–Campo).
    pub weights: Vec<f64>,
}

/// Bar-Shalom–Campo fusion of two estimates with cross-covariance P₁₂:
/// S = P₁ + P₂ − P₁₂ − P₁₂', x = x₁ + (P₁ − P₁₂) S⁻¹ (x₂ − x₁),
/// P = P₁ − (P₁ − P₁₂) S⁻¹ (P₁ − P₁₂)'.
pub fn bar_shalom_campo(
    x1: &DVector<f64>,
    p1: &DMatrix<f64>,
    x2: &DVector<f64>,
    p2: &DMatrix<f64>,
    p12: &DMatrix<f64>,
) -> Result<Fused, AlgoError> {
    let s = p1 + p2 - p12 - p12.transpose();
    let chol = s.cholesky().ok_or(AlgoError::NotPositiveDefinite {
        what: "P1 + P2 - P12 - P21",
    })?;
    let w = p1 - p12;
    let gain = chol.solve(&w.transpose()).transpose();
    let x = x1 + &gain * (x2 - x1);
    let mut p = p1 - &gain * w.transpose();
    crate::gaussian::symmetrize(&mut p);
    check(&x, &p)?;
    Ok(Fused {
        x,
        p,
        weights: Vec::new(),
    })
}

/// Covariance intersection of any number of estimates, fused one after the
/// other, each weight ω chosen to minimise the trace of the fused covariance
/// (Julier–Uhlmann):
/// P⁻¹ = ω P₁⁻¹ + (1 − ω) P₂⁻¹, x = P (ω P₁⁻¹ x₁ + (1 − ω) P₂⁻¹ x₂).
/// Consistent whatever the unknown correlation between the estimates.
///
/// The trace is minimised exactly rather than searched. With P₁ = L Lᵀ and
/// the eigendecomposition L⁻¹ P₂ L⁻ᵀ = V D Vᵀ (D = diag dᵢ > 0), T = L V
/// diagonalises both: P₁ = T Tᵀ, P₂ = T D Tᵀ, so
/// P(ω) = T S(ω) Tᵀ with S = diag(sᵢ), sᵢ = dᵢ / (1 + ω (dᵢ − 1)), and
/// tr P(ω) = Σ gᵢ sᵢ(ω) with gᵢ = ‖T₍:,ᵢ₎‖². Each term is convex in ω on
/// [0, 1], so the minimum is ω = 0 or 1 when the derivative
/// −Σ gᵢ dᵢ (dᵢ − 1) / (1 + ω (dᵢ − 1))² does not change sign there, and its
/// root (found by bisection to the resolution of a double) otherwise. The
/// fused estimate is then formed from the inverses at that ω, as defined.
/// Dimensions up to [`small::MAX_DIM`].
pub fn covariance_intersection(
    members: &[(DVector<f64>, DMatrix<f64>)],
) -> Result<Fused, AlgoError> {
    let (first, rest) = members.split_first().ok_or(AlgoError::InvalidParameter {
        what: "members",
        reason: "need at least one estimate".into(),
    })?;
    let n = first.0.len();
    if n == 0 || n > small::MAX_DIM {
        return Err(AlgoError::InvalidParameter {
            what: "members",
            reason: format!("state dimension {n} is not within 1..={}", small::MAX_DIM),
        });
    }
    let mut x = [0.0; small::MAX_DIM];
    x[..n].copy_from_slice(first.0.as_slice());
    let mut p = small::to_sq(&first.1);
    let mut weights = Vec::with_capacity(rest.len());
    for (x2, p2) in rest {
        if x2.len() != n || p2.nrows() != n || p2.ncols() != n {
            return Err(AlgoError::InvalidParameter {
                what: "members",
                reason: format!("a member of dimension {} among members of {n}", x2.len()),
            });
        }
        let w;
        (x, p, w) = ci_pair(&x, &p, x2.as_slice(), &small::to_sq(p2), n)?;
        weights.push(w);
    }
    let x = DVector::from_column_slice(&x[..n]);
    let p = DMatrix::from_row_slice(n, n, &p[..n * n]);
    check(&x, &p)?;
    Ok(Fused { x, p, weights })
}

/// One covariance intersection of (x₁, P₁) and (x₂, P₂), n ≤ MAX_DIM,
/// row-major: the fused state, covariance and weight ω of the first.
#[allow(clippy::needless_range_loop)] // index form of the matrix formulas
fn ci_pair(
    x1: &[f64],
    p1: &small::Sq,
    x2: &[f64],
    p2: &small::Sq,
    n: usize,
) -> Result<([f64; small::MAX_DIM], small::Sq, f64), AlgoError> {
    let l = small::cholesky(p1, n).ok_or(AlgoError::NotPositiveDefinite {
        what: "fused covariance",
    })?;
    // B = L⁻¹ P₂ L⁻ᵀ: solve L Y = P₂, then L Bᵀ = Yᵀ; symmetrised.
    let y = small::solve_lower(&l, p2, n);
    let mut b = small::solve_lower(&l, &small::transpose(&y, n), n);
    for i in 0..n {
        for j in 0..i {
            let m = 0.5 * (b[i * n + j] + b[j * n + i]);
            b[i * n + j] = m;
            b[j * n + i] = m;
        }
    }
    let (d, v) = small::symmetric_eigen(&b, n);
    if d[..n].iter().any(|&di| !(di.is_finite() && di > 0.0)) {
        return Err(AlgoError::NotPositiveDefinite {
            what: "member covariance",
        });
    }
    // T = L V and its column norms gᵢ.
    let t = small::mul(&l, &v, n);
    let mut g = [0.0; small::MAX_DIM];
    for i in 0..n {
        g[i] = (0..n).map(|k| t[k * n + i] * t[k * n + i]).sum();
    }
    let slope = |w: f64| -> f64 {
        -(0..n)
            .map(|i| {
                let a = d[i] - 1.0;
                let q = 1.0 + w * a;
                g[i] * d[i] * a / (q * q)
            })
            .sum::<f64>()
    };
    let w = if slope(0.0) >= 0.0 {
        0.0
    } else if slope(1.0) <= 0.0 {
        1.0
    } else {
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        loop {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break mid;
            }
            if slope(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
    };
    // The fused estimate from the inverses at that ω: accurate whatever the
    // spread of the dᵢ (T S Tᵀ is not, when they span many decades).
    let i1 = small::inverse_from_cholesky(&l, n);
    let i2 = small::inverse_spd(p2, n).ok_or(AlgoError::NotPositiveDefinite {
        what: "member covariance",
    })?;
    let mut m = small::ZERO;
    let mut info = [0.0; small::MAX_DIM];
    for r in 0..n {
        for col in 0..n {
            m[r * n + col] = w * i1[r * n + col] + (1.0 - w) * i2[r * n + col];
        }
        info[r] = (0..n)
            .map(|k| w * i1[r * n + k] * x1[k] + (1.0 - w) * i2[r * n + k] * x2[k])
            .sum();
    }
    let p = small::inverse_spd(&m, n).ok_or(AlgoError::NotPositiveDefinite {
        what: "covariance intersection",
    })?;
    let mut x = [0.0; small::MAX_DIM];
    for r in 0..n {
        x[r] = (0..n).map(|k| p[r * n + k] * info[k]).sum();
    }
    Ok((x, p, w))
}

fn check(x: &DVector<f64>, p: &DMatrix<f64>) -> Result<(), AlgoError> {
    if x.iter().chain(p.iter()).all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(AlgoError::NonFinite {
            what: "fused estimate",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(a: &[f64]) -> DVector<f64> {
        DVector::from_column_slice(a)
    }

    fn m(n: usize, a: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(n, n, a)
    }

    #[test]
    fn bar_shalom_campo_by_hand() {
        // Independent (P12 = 0), x1 = 0, x2 = 2, P1 = P2 = 1: the average,
        // x = 1, P = 1 − 1·(1/2)·1 = 0.5.
        let f = bar_shalom_campo(
            &v(&[0.0]),
            &m(1, &[1.0]),
            &v(&[2.0]),
            &m(1, &[1.0]),
            &m(1, &[0.0]),
        )
        .unwrap();
        assert!((f.x[0] - 1.0).abs() < 1e-15 && (f.p[(0, 0)] - 0.5).abs() < 1e-15);
        // P12 = 0.5: S = 1 + 1 − 1 = 1, gain (1 − 0.5)/1 = 0.5, x = 1,
        // P = 1 − 0.5·0.5 = 0.75 (common process noise makes fusion gain less).
        let f = bar_shalom_campo(
            &v(&[0.0]),
            &m(1, &[1.0]),
            &v(&[2.0]),
            &m(1, &[1.0]),
            &m(1, &[0.5]),
        )
        .unwrap();
        assert!((f.x[0] - 1.0).abs() < 1e-15 && (f.p[(0, 0)] - 0.75).abs() < 1e-15);
        // Fully correlated estimates cannot be fused: S = 0.
        assert!(
            bar_shalom_campo(
                &v(&[0.0]),
                &m(1, &[1.0]),
                &v(&[2.0]),
                &m(1, &[1.0]),
                &m(1, &[1.0])
            )
            .is_err()
        );
    }

    #[test]
    fn covariance_intersection_by_hand() {
        // P1 = diag(1, 4), P2 = diag(4, 1), x1 = (0, 0), x2 = (2, 2).
        // tr P(ω) = 1/(0.25 + 0.75ω) + 1/(1 − 0.75ω), symmetric about ω = 1/2,
        // where P = diag(1.6, 1.6) and x = 1.6·(0.5·(0, 0) + 0.5·(0.5, 2))
        // = 1.6·(0.25, 1) = (0.4, 1.6).
        let f = covariance_intersection(&[
            (v(&[0.0, 0.0]), m(2, &[1.0, 0.0, 0.0, 4.0])),
            (v(&[2.0, 2.0]), m(2, &[4.0, 0.0, 0.0, 1.0])),
        ])
        .unwrap();
        // The minimum is found exactly (no search tolerance left).
        assert!((f.weights[0] - 0.5).abs() < 1e-15, "{:?}", f.weights);
        assert!((f.p[(0, 0)] - 1.6).abs() < 1e-14 && (f.p[(1, 1)] - 1.6).abs() < 1e-14);
        assert!(f.p[(0, 1)].abs() < 1e-15 && f.p[(1, 0)].abs() < 1e-15);
        assert!((f.x[0] - 0.4).abs() < 1e-14 && (f.x[1] - 1.6).abs() < 1e-14);
        // A dominated estimate gets weight 0 (ω = 1 keeps the better one):
        // P1 = 1, P2 = 4 in 1-D: P(ω)⁻¹ = ω + (1 − ω)/4 is largest at ω = 1.
        let f = covariance_intersection(&[(v(&[0.0]), m(1, &[1.0])), (v(&[2.0]), m(1, &[4.0]))])
            .unwrap();
        assert!((f.weights[0] - 1.0).abs() < 1e-12 && f.x[0].abs() < 1e-12);
    }

    /// A random symmetric positive definite n×n matrix, A Aᵀ + n I scaled
    /// over several decades per axis.
    fn spd(rng: &mut impl rand::RngExt, n: usize) -> DMatrix<f64> {
        let a = DMatrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
        let scale = DMatrix::from_diagonal(&DVector::from_fn(n, |_, _| {
            10f64.powf(rng.random_range(-1.0..3.0))
        }));
        let m = &scale * (&a * a.transpose() + DMatrix::identity(n, n) * 0.1) * &scale;
        (&m + m.transpose()) * 0.5
    }

    #[test]
    fn covariance_intersection_meets_its_definition_on_random_pairs() {
        // Independent check with nalgebra's inverses: P = (ω P₁⁻¹ +
        // (1 − ω) P₂⁻¹)⁻¹ and x = P (ω P₁⁻¹ x₁ + (1 − ω) P₂⁻¹ x₂) at the
        // returned ω, and no ω on a fine grid gives a smaller trace.
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [2, 4, 6] {
            for _ in 0..50 {
                let (p1, p2) = (spd(&mut rng, n), spd(&mut rng, n));
                let x1 = DVector::from_fn(n, |_, _| rng.random_range(-100.0..100.0));
                let x2 = DVector::from_fn(n, |_, _| rng.random_range(-100.0..100.0));
                let f =
                    covariance_intersection(&[(x1.clone(), p1.clone()), (x2.clone(), p2.clone())])
                        .unwrap();
                let w = f.weights[0];
                let (i1, i2) = (
                    p1.clone().try_inverse().unwrap(),
                    p2.clone().try_inverse().unwrap(),
                );
                let trace = |w: f64| (&i1 * w + &i2 * (1.0 - w)).try_inverse().unwrap().trace();
                let p = (&i1 * w + &i2 * (1.0 - w)).try_inverse().unwrap();
                let x = &p * (&i1 * &x1 * w + &i2 * &x2 * (1.0 - w));
                assert!(
                    (&f.p - &p).abs().max() <= 1e-9 * p.abs().max(),
                    "n {n}: ω {w}: {} vs {p}",
                    f.p
                );
                assert!(
                    (&f.x - &x).abs().max() <= 1e-9 * (1.0 + x.abs().max()),
                    "n {n}: {} vs {x}",
                    f.x
                );
                assert_eq!(f.p, f.p.transpose());
                let best = trace(w);
                for k in 0..=1000 {
                    let other = trace(k as f64 / 1000.0);
                    assert!(
                        best <= other * (1.0 + 1e-12),
                        "n {n}: ω {w} trace {best} > {other} at {k}/1000"
                    );
                }
            }
        }
        // Three members fuse one after the other, one weight per step.
        let m = |v: f64, p: f64| (DVector::from_element(2, v), DMatrix::identity(2, 2) * p);
        let f = covariance_intersection(&[m(0.0, 1.0), m(1.0, 2.0), m(2.0, 4.0)]).unwrap();
        assert_eq!(f.weights, vec![1.0, 1.0]);
        assert_eq!(f.x, DVector::from_element(2, 0.0));
    }
}
