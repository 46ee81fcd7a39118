//! χ² gating: thresholds, gate probabilities and the gate test itself.
//!
//! Under H0 (same target, Gaussian errors) the statistic τ = d' S⁻¹ d of
//! seed 000 (He You et al., double-threshold track correlation) eqs. 10 and
//! 12 is χ² distributed with `n_x` degrees of freedom, and the first
//! threshold δ is chosen by eq. 14: Pr{τ > δ | H0} = α.

use nalgebra::{DMatrix, DVector};
use statrs::distribution::{ChiSquared, Continuous, ContinuousCDF};

use crate::error::{AlgoError, non_negative};
use crate::gaussian::mahalanobis_sq;

/// The threshold δ with Pr{χ²_dof > δ} = `alpha` (seed 000 eq. 14), i.e. the
/// (1 − α) quantile of the χ² distribution, for any `dof >= 1` and
/// `alpha` in (0, 1).
///
/// The statrs quantile is used as a starting point and polished by a
/// safeguarded Newton iteration on the logarithm of whichever tail is
/// smaller (the survival function for α < 1/2, the CDF otherwise), so tiny
/// α do not suffer from the cancellation in `1 − α`. The result is accurate
/// to about 1e-13 relative.
pub fn chi2_threshold(dof: usize, alpha: f64) -> Result<f64, AlgoError> {
    // The trackers ask for the same few gates at every frame: the last
    // answers of this thread are kept (a pure function of its inputs).
    thread_local! {
        static RECENT: std::cell::RefCell<Vec<(usize, u64, f64)>> =
            const { std::cell::RefCell::new(Vec::new()) };
    }
    let key = (dof, alpha.to_bits());
    if let Some(v) = RECENT.with_borrow(|r| r.iter().find(|e| (e.0, e.1) == key).map(|e| e.2)) {
        return Ok(v);
    }
    let v = chi2_threshold_computed(dof, alpha)?;
    RECENT.with_borrow_mut(|r| {
        if r.len() >= 16 {
            r.remove(0);
        }
        r.push((dof, alpha.to_bits(), v));
    });
    Ok(v)
}

fn chi2_threshold_computed(dof: usize, alpha: f64) -> Result<f64, AlgoError> {
    let chi2 = chi_squared(dof)?;
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(AlgoError::InvalidParameter {
            what: "alpha",
            reason: format!("must lie in (0, 1), got {alpha}"),
        });
    }
    let upper = alpha < 0.5;
    // g(x) = ln(tail target) − ln(tail(x)) style residual, decreasing in x:
    //   upper tail: g(x) = ln sf(x) − ln α,      g'(x) = −pdf(x)/sf(x)
    //   lower tail: g(x) = ln(1−α) − ln cdf(x),  g'(x) = −pdf(x)/cdf(x)
    let ln_target = if upper {
        alpha.ln()
    } else {
        (1.0 - alpha).ln()
    };
    let residual = |x: f64| -> (f64, f64) {
        let pdf = chi2.pdf(x);
        if upper {
            let sf = chi2.sf(x);
            (sf.ln() - ln_target, -pdf / sf)
        } else {
            let cdf = chi2.cdf(x);
            (ln_target - cdf.ln(), -pdf / cdf)
        }
    };

    // Bracket [lo, hi] with g(lo) > 0 > g(hi); g(0+) > 0 always.
    let mut lo = 0.0_f64;
    let mut hi = (2.0 * dof as f64).max(1.0);
    while residual(hi).0 > 0.0 {
        lo = hi;
        hi *= 2.0;
        if !hi.is_finite() {
            return Err(AlgoError::NonFinite {
                what: "chi-square threshold",
            });
        }
    }

    let start = chi2.inverse_cdf(1.0 - alpha);
    let mut x = if start.is_finite() && start > lo && start < hi {
        start
    } else {
        0.5 * (lo + hi)
    };
    for _ in 0..200 {
        let (g, dg) = residual(x);
        if g == 0.0 {
            break;
        }
        if g > 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let mut next = x - g / dg;
        if !next.is_finite() || next <= lo || next >= hi {
            next = 0.5 * (lo + hi);
        }
        let done = (next - x).abs() <= 1e-15 * x.abs();
        x = next;
        if done || hi - lo <= 1e-15 * hi {
            break;
        }
    }
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(AlgoError::NonFinite {
            what: "chi-square threshold",
        })
    }
}

/// The gate probability P_G = Pr{χ²_dof ≤ threshold}, the probability that a
/// correct pairing passes the gate (the complement of α in seed 000 eq. 14).
pub fn chi2_gate_probability(dof: usize, threshold: f64) -> Result<f64, AlgoError> {
    let chi2 = chi_squared(dof)?;
    non_negative("threshold", threshold)?;
    Ok(chi2.cdf(threshold).clamp(0.0, 1.0))
}

/// Outcome of a gate test: the statistic and whether it passed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateOutcome {
    /// The squared Mahalanobis distance τ = d' S⁻¹ d (seed 000 eqs. 10, 12).
    pub distance_sq: f64,
    /// `true` if τ ≤ δ (seed 000 eq. 11: accept H0, same target).
    pub inside: bool,
}

/// Gate test of seed 000 eqs. 10–11: τ = d' S⁻¹ d and accept H0 if τ ≤ δ.
/// `d` is the difference (or innovation), `s` its covariance and `threshold`
/// δ, e.g. from [`chi2_threshold`]. A failed gate is `inside == false`, not
/// an error; errors are only for invalid inputs.
pub fn within_gate(
    d: &DVector<f64>,
    s: &DMatrix<f64>,
    threshold: f64,
) -> Result<GateOutcome, AlgoError> {
    non_negative("threshold", threshold)?;
    let distance_sq = mahalanobis_sq(d, s)?;
    Ok(GateOutcome {
        distance_sq,
        inside: distance_sq <= threshold,
    })
}

/// Points sorted by one coordinate, for exact gate pruning: since
/// ν′S⁻¹ν ≥ ν₀²/S₀₀ for any covariance S, only points whose first
/// coordinate lies within √(γ S₀₀) of the prediction can pass a χ² gate γ;
/// [`SortedByFirst::within`] finds them by binary search.
#[derive(Debug, Clone, Default)]
pub struct SortedByFirst(Vec<(f64, usize)>);

impl SortedByFirst {
    /// The points' first coordinates, indexed in iteration order.
    pub fn new(first: impl Iterator<Item = f64>) -> Self {
        let mut v: Vec<(f64, usize)> = first.enumerate().map(|(j, x)| (x, j)).collect();
        v.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        Self(v)
    }

    /// Replaces `out` with the indices, ascending, of the points within
    /// `reach` of `centre` (every point when `reach` is not finite).
    pub fn within(&self, centre: f64, reach: f64, out: &mut Vec<usize>) {
        out.clear();
        if reach.is_finite() {
            let lo = self.0.partition_point(|&(v, _)| v < centre - reach);
            let hi = self.0.partition_point(|&(v, _)| v <= centre + reach);
            out.extend(self.0[lo..hi].iter().map(|&(_, j)| j));
            out.sort_unstable();
        } else {
            out.extend(0..self.0.len());
        }
    }
}

fn chi_squared(dof: usize) -> Result<ChiSquared, AlgoError> {
    if dof == 0 {
        return Err(AlgoError::InvalidParameter {
            what: "dof",
            reason: "must be >= 1".to_owned(),
        });
    }
    ChiSquared::new(dof as f64).map_err(|e| AlgoError::InvalidParameter {
        what: "dof",
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{dmatrix, dvector};
    use proptest::prelude::*;

    fn assert_rel(got: f64, expected: f64, rtol: f64) {
        assert!(
            (got - expected).abs() <= rtol * expected.abs(),
            "got {got:e}, expected {expected:e}"
        );
    }

    /// Reference χ² upper quantiles to 16 digits (they agree with the printed
    /// NIST/SEMATECH e-Handbook table 1.3.6.7.4 to its three decimals:
    /// 3.841, 5.991, 9.488, 12.592, 9.210, 11.345; for dof = 1 also with
    /// the closed form z²_{0.975} = 1.959963984540054²), and the closed form
    /// δ = −2 ln α for two degrees of freedom.
    #[test]
    fn table_values() {
        let table = [
            (1, 0.05, 3.841458820694124),
            (2, 0.05, 5.991464547107979),
            (4, 0.05, 9.487729036781154),
            (6, 0.05, 12.591587243743977),
            (2, 0.01, 9.210340371976184),
            (3, 0.01, 11.344866730144373),
        ];
        for (dof, alpha, delta) in table {
            assert_rel(chi2_threshold(dof, alpha).unwrap(), delta, 1e-12);
        }
        for alpha in [0.5, 0.05, 1e-3, 1e-8, 1e-15, 1e-100] {
            // dof = 2: sf(x) = exp(−x/2), so δ = −2 ln α.
            assert_rel(chi2_threshold(2, alpha).unwrap(), -2.0 * alpha.ln(), 1e-12);
        }
        // dof = 2, alpha close to 1: δ = −2 ln α = −2 ln(1 − 1e-6) ≈ 2e-6 + 1e-12.
        let a: f64 = 1.0 - 1e-6;
        assert_rel(chi2_threshold(2, a).unwrap(), -2.0 * a.ln(), 1e-9);
    }

    #[test]
    fn rejects_bad_parameters() {
        assert!(chi2_threshold(0, 0.05).is_err());
        for alpha in [0.0, 1.0, -0.1, 1.5, f64::NAN] {
            assert!(chi2_threshold(2, alpha).is_err(), "{alpha}");
        }
        assert!(chi2_gate_probability(0, 1.0).is_err());
        assert!(chi2_gate_probability(2, f64::NAN).is_err());
        assert!(chi2_gate_probability(2, -1.0).is_err());
    }

    #[test]
    fn gate_probability_closed_form() {
        // dof = 2: CDF(x) = 1 − exp(−x/2); at x = 2 ln 20 it is 0.95.
        let p = chi2_gate_probability(2, 2.0 * 20f64.ln()).unwrap();
        assert!((p - 0.95).abs() < 1e-14);
        assert_eq!(chi2_gate_probability(3, 0.0).unwrap(), 0.0);
    }

    #[test]
    fn gate_by_hand() {
        // S = diag(4, 9), d = [2, 3]: τ = 4/4 + 9/9 = 2.
        let s = dmatrix![4.0, 0.0; 0.0, 9.0];
        let d = dvector![2.0, 3.0];
        let g = within_gate(&d, &s, 5.991464547107979).unwrap();
        assert!(g.inside && (g.distance_sq - 2.0).abs() < 1e-15);
        let g = within_gate(&d, &s, 1.5).unwrap();
        assert!(!g.inside);
        assert!(within_gate(&d, &s, f64::NAN).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn threshold_inverts_gate_probability(dof in 1usize..40, alpha in 1e-6..0.999f64) {
            let delta = chi2_threshold(dof, alpha).unwrap();
            prop_assert!(delta > 0.0);
            let pg = chi2_gate_probability(dof, delta).unwrap();
            prop_assert!((0.0..=1.0).contains(&pg));
            prop_assert!(((1.0 - pg) - alpha).abs() <= 1e-10 * alpha.max(1e-3));
        }

        #[test]
        fn threshold_monotone(dof in 1usize..20, a in 1e-6..0.5f64) {
            // Smaller α (fewer false rejections) needs a larger threshold;
            // more degrees of freedom need a larger threshold.
            prop_assert!(chi2_threshold(dof, a / 2.0).unwrap() > chi2_threshold(dof, a).unwrap());
            prop_assert!(chi2_threshold(dof + 1, a).unwrap() > chi2_threshold(dof, a).unwrap());
        }
    }
}
