//! Fusion of correlated local tracks into a system track: Bar-Shalom–Campo
//! when the cross-covariance of the two estimates is known, covariance
//! intersection (Julier–Uhlmann) when it is not.

use nalgebra::{DMatrix, DVector};

use crate::algo::{AlgoError, small};

/// A fused estimate and how it was obtained.
#[derive(Debug, Clone, PartialEq)]
pub struct Fused {
    pub x: DVector<f64>,
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
    crate::algo::gaussian::symmetrize(&mut p);
    check(&x, &p)?;
    Ok(Fused {
        x,
        p,
        weights: Vec::new(),
    })
}

/// Covariance intersection of any number of estimates, fused one after the
/// other, each weight ω chosen to minimise the trace of the fused covariance
/// (golden-section search on [0, 1]):
/// P⁻¹ = ω P₁⁻¹ + (1 − ω) P₂⁻¹, x = P (ω P₁⁻¹ x₁ + (1 − ω) P₂⁻¹ x₂).
/// Consistent whatever the unknown correlation between the estimates.
pub fn covariance_intersection(
    members: &[(DVector<f64>, DMatrix<f64>)],
) -> Result<Fused, AlgoError> {
    let (first, rest) = members.split_first().ok_or(AlgoError::InvalidParameter {
        what: "members",
        reason: "need at least one estimate".into(),
    })?;
    let (mut x, mut p) = first.clone();
    let mut weights = Vec::new();
    for (x2, p2) in rest {
        let i1 = inverse(&p, "fused covariance")?;
        let i2 = inverse(p2, "member covariance")?;
        let fuse = |w: f64| -> Option<DMatrix<f64>> { (&i1 * w + &i2 * (1.0 - w)).try_inverse() };
        // The search evaluates tr P(ω) = tr (ω I₁ + (1 − ω) I₂)⁻¹ on the stack.
        let n = i1.nrows();
        let (f1, f2) = (small::row_major(&i1), small::row_major(&i2));
        let trace = |w: f64| {
            if n > small::MAX_DIM {
                return fuse(w).map_or(f64::INFINITY, |m| m.trace());
            }
            let mut m = small::ZERO;
            for k in 0..n * n {
                m[k] = w * f1[k] + (1.0 - w) * f2[k];
            }
            small::trace_inverse(&m, n).unwrap_or(f64::INFINITY)
        };
        let w = golden_min(trace, 0.0, 1.0);
        let pf = fuse(w).ok_or(AlgoError::NotPositiveDefinite {
            what: "covariance intersection",
        })?;
        x = &pf * (&i1 * &x * w + &i2 * x2 * (1.0 - w));
        p = pf;
        crate::algo::gaussian::symmetrize(&mut p);
        weights.push(w);
    }
    check(&x, &p)?;
    Ok(Fused { x, p, weights })
}

fn inverse(p: &DMatrix<f64>, what: &'static str) -> Result<DMatrix<f64>, AlgoError> {
    p.clone()
        .cholesky()
        .map(|c| c.inverse())
        .ok_or(AlgoError::NotPositiveDefinite { what })
}

/// Minimum of a unimodal function on [a, b] by golden-section search (one
/// new evaluation per step, the interval shrinking by 0.618 each time, so 26
/// steps leave it below 4e-6; the trace is stationary at the optimum, so the
/// fused trace is then within ~1e-11 relative of its minimum), comparing the end points too (the optimum of
/// CI is often ω = 0 or 1).
fn golden_min(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let (lo, hi) = (a, b);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..26 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    let mid = 0.5 * (a + b);
    [(lo, f(lo)), (mid, f(mid)), (hi, f(hi))]
        .into_iter()
        .min_by(|x, y| x.1.total_cmp(&y.1))
        .map(|(x, _)| x)
        .expect("three candidates")
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
        assert!((f.weights[0] - 0.5).abs() < 1e-5, "{:?}", f.weights);
        // The trace is stationary at the optimum but the entries are not
        // (dP₁₁/dω = −0.75/0.625² ≈ −1.9), so they carry the search tolerance.
        assert!((f.p[(0, 0)] - 1.6).abs() < 1e-4 && (f.p[(1, 1)] - 1.6).abs() < 1e-4);
        assert!((f.p.trace() - 3.2).abs() < 1e-9);
        assert!((f.x[0] - 0.4).abs() < 1e-4 && (f.x[1] - 1.6).abs() < 1e-4);
        // A dominated estimate gets weight 0 (ω = 1 keeps the better one):
        // P1 = 1, P2 = 4 in 1-D: P(ω)⁻¹ = ω + (1 − ω)/4 is largest at ω = 1.
        let f = covariance_intersection(&[(v(&[0.0]), m(1, &[1.0])), (v(&[2.0]), m(1, &[4.0]))])
            .unwrap();
        assert!((f.weights[0] - 1.0).abs() < 1e-12 && f.x[0].abs() < 1e-12);
    }
}
