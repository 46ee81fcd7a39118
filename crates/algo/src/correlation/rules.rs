//! L/R double-threshold rules (seed 000, section 4): the missed-correlation
//! probability of a rule (eq. 23) and the choice of a rule from it.
//!
//! A rule L/R declares two local tracks correlated when at least L of R
//! per-sample χ² tests pass the first threshold δ. For the same target each
//! test fails independently with probability α (eq. 14), so the rule misses
//! when at least R − L + 1 of the R samples exceed δ: the upper tail of a
//! Binomial(R, α) distribution,
//!
//! ```text
//! P̂_c(L/R) = Σ_{k=R−L+1}^{R} C(R,k) α^k (1 − α)^{R−k}        (eq. 23)
//! ```

use crate::error::AlgoError;

/// The largest window R the service evaluates. C(128, 64) ≈ 2.4e37 still fits a
/// `u128`, so every binomial coefficient is exact before it is rounded once to
/// `f64`.
pub const MAX_WINDOW: u32 = 128;

/// An L/R double-threshold rule with 1 ≤ L ≤ R ≤ [`MAX_WINDOW`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LrRule {
    l: u32,
    r: u32,
}

impl LrRule {
    /// Validates 1 ≤ `l` ≤ `r` ≤ [`MAX_WINDOW`].
    pub fn new(l: u32, r: u32) -> Result<Self, AlgoError> {
        if r == 0 || r > MAX_WINDOW {
            return Err(AlgoError::InvalidParameter {
                what: "r",
                reason: format!("must be between 1 and {MAX_WINDOW}"),
            });
        }
        if l == 0 || l > r {
            return Err(AlgoError::InvalidParameter {
                what: "l",
                reason: format!("must be between 1 and r = {r}"),
            });
        }
        Ok(Self { l, r })
    }

    /// The second threshold L: the number of passed tests that confirms.
    pub fn l(self) -> u32 {
        self.l
    }

    /// The window R: the number of samples tested.
    pub fn r(self) -> u32 {
        self.r
    }

    /// R − L + 1: the number of exceedances that makes the rule miss.
    pub fn misses_from(self) -> u32 {
        self.r - self.l + 1
    }
}

/// Validates a significance level α ∈ (0, 1).
pub fn check_alpha(alpha: f64) -> Result<(), AlgoError> {
    if alpha.is_finite() && alpha > 0.0 && alpha < 1.0 {
        Ok(())
    } else {
        Err(AlgoError::InvalidParameter {
            what: "alpha",
            reason: "must be strictly between 0 and 1".into(),
        })
    }
}

/// Missed-correlation probability of `rule` at significance `alpha` (eq. 23).
///
/// Every term is formed in double-double arithmetic (about 106 bits) from the
/// exact binomial coefficient, the exact 1 − α and exact powers, and the sum
/// is rounded to `f64` once: the result is the correctly rounded value of
/// eq. 23 for the binary `alpha` given, barring a tie within 2⁻¹⁰⁰.
pub fn miss_probability(rule: LrRule, alpha: f64) -> Result<f64, AlgoError> {
    check_alpha(alpha)?;
    let r = rule.r;
    let a = Dd::from(alpha);
    let q = Dd::from(1.0).sub(a);
    let mut sum = Dd::from(0.0);
    for k in (rule.misses_from()..=r).rev() {
        let term = Dd::from_u128(binomial(r, k))
            .mul(a.powu(k))
            .mul(q.powu(r - k));
        sum = sum.add(term);
    }
    Ok(sum.to_f64().min(1.0))
}

/// What [`recommend`] found: the strictest rule for every window, and the first
/// of them that meets the bound.
#[derive(Debug, Clone, PartialEq)]
pub struct Recommendation {
    /// The smallest R (with its largest admissible L) whose miss probability is
    /// at most the bound; `None` when no R up to the limit meets it.
    pub recommended: Option<(LrRule, f64)>,
    /// For each R = 1..=max_r, the largest L with L/R ≥ the minimum ratio, and
    /// its miss probability.
    pub considered: Vec<(LrRule, f64)>,
}

/// Chooses an L/R rule as seed 000 section 4 suggests: eq. 23 bounds the miss
/// probability, and among the rules that meet `max_miss` the shortest window
/// wins (a decision comes soonest), with the largest L for that window (the
/// strictest confirmation, which best rejects false pairs).
///
/// `min_l_over_r` keeps the rule meaningful: without it 1/R always meets any
/// bound for large enough R while confirming almost nothing.
pub fn recommend(
    alpha: f64,
    max_miss: f64,
    min_l_over_r: f64,
    max_r: u32,
) -> Result<Recommendation, AlgoError> {
    check_alpha(alpha)?;
    if !(max_miss.is_finite() && max_miss > 0.0 && max_miss < 1.0) {
        return Err(AlgoError::InvalidParameter {
            what: "max_miss_probability",
            reason: "must be strictly between 0 and 1".into(),
        });
    }
    if !(min_l_over_r.is_finite() && min_l_over_r > 0.0 && min_l_over_r <= 1.0) {
        return Err(AlgoError::InvalidParameter {
            what: "min_l_over_r",
            reason: "must be in (0, 1]".into(),
        });
    }
    if max_r == 0 || max_r > MAX_WINDOW {
        return Err(AlgoError::InvalidParameter {
            what: "max_r",
            reason: format!("must be between 1 and {MAX_WINDOW}"),
        });
    }
    let mut considered = Vec::with_capacity(max_r as usize);
    let mut recommended = None;
    for r in 1..=max_r {
        // The smallest admissible L is ceil(ratio · R); guard the product
        // against rounding up past an exact integer (0.75 · 4 = 3).
        let min_l = ((min_l_over_r * f64::from(r)) - 1e-9).ceil().max(1.0) as u32;
        // The miss probability falls as L falls, so the strictest rule that
        // can still meet the bound is found by walking L down to min_l.
        let mut best = None;
        for l in (min_l..=r).rev() {
            let rule = LrRule::new(l, r)?;
            let p = miss_probability(rule, alpha)?;
            best = Some((rule, p));
            if p <= max_miss {
                break;
            }
        }
        let (rule, p) = best.expect("min_l <= r because min_l_over_r <= 1");
        considered.push((rule, p));
        if recommended.is_none() && p <= max_miss {
            recommended = Some((rule, p));
        }
    }
    Ok(Recommendation {
        recommended,
        considered,
    })
}

/// A double-double number hi + lo with |lo| ≤ ulp(hi)/2 (Dekker, Knuth):
/// enough precision that a sum of a few hundred terms rounds correctly.
#[derive(Debug, Clone, Copy)]
struct Dd {
    hi: f64,
    lo: f64,
}

impl From<f64> for Dd {
    fn from(x: f64) -> Self {
        Self { hi: x, lo: 0.0 }
    }
}

impl Dd {
    fn from_u128(n: u128) -> Self {
        let hi = n as f64;
        // hi is n rounded to 53 bits; the remainder is exact in i128 and fits
        // an f64 exactly (it has at most 53 significant bits).
        let lo = (n as i128 - hi as i128) as f64;
        Self::normalise(hi, lo)
    }

    fn normalise(hi: f64, lo: f64) -> Self {
        let s = hi + lo;
        Self {
            hi: s,
            lo: lo - (s - hi),
        }
    }

    fn add(self, o: Self) -> Self {
        let s = self.hi + o.hi;
        let bb = s - self.hi;
        let e = (self.hi - (s - bb)) + (o.hi - bb);
        Self::normalise(s, e + self.lo + o.lo)
    }

    fn sub(self, o: Self) -> Self {
        self.add(Self {
            hi: -o.hi,
            lo: -o.lo,
        })
    }

    fn mul(self, o: Self) -> Self {
        let p = self.hi * o.hi;
        let e = self.hi.mul_add(o.hi, -p);
        Self::normalise(p, e + self.hi * o.lo + self.lo * o.hi)
    }

    fn powu(self, mut n: u32) -> Self {
        let (mut base, mut acc) = (self, Self::from(1.0));
        while n > 0 {
            if n & 1 == 1 {
                acc = acc.mul(base);
            }
            base = base.mul(base);
            n >>= 1;
        }
        acc
    }

    fn to_f64(self) -> f64 {
        self.hi + self.lo
    }
}

/// C(n, k), exact for n ≤ [`MAX_WINDOW`].
fn binomial(n: u32, k: u32) -> u128 {
    let k = k.min(n - k);
    // After step i the accumulator is C(n − k + i, i) = acc · m / i with
    // m = n − k + i. Cancelling g = gcd(acc, i) first keeps every intermediate
    // at most the final value: (i / g) divides m because acc·m/i is an integer
    // and acc/g is coprime to i/g.
    (1..=k).fold(1u128, |acc, i| {
        let (m, i) = (u128::from(n - k + i), u128::from(i));
        let g = gcd(acc, i);
        (acc / g) * (m / (i / g))
    })
}

fn gcd(mut a: u128, mut b: u128) -> u128 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule(l: u32, r: u32) -> LrRule {
        LrRule::new(l, r).unwrap()
    }

    #[test]
    fn binomial_coefficients_are_exact() {
        assert_eq!(binomial(4, 2), 6);
        assert_eq!(binomial(8, 3), 56);
        // C(128, 64), computed in arbitrary precision (Python's math.comb).
        assert_eq!(
            binomial(128, 64),
            23_951_146_041_928_082_866_135_587_776_380_551_750
        );
    }

    #[test]
    fn miss_probability_of_3_of_4_at_alpha_005() {
        // Misses when at least 4 − 3 + 1 = 2 of 4 samples exceed δ:
        //   C(4,2)·0.05²·0.95² = 6·0.0025·0.9025 = 0.0135375
        //   C(4,3)·0.05³·0.95  = 4·0.000125·0.95 = 0.000475
        //   C(4,4)·0.05⁴       =                  0.00000625
        //   sum                                 = 0.01401875
        // Seed 000 prints P̂_c(3/4) = 0.002256, which its own eq. 23 does not give.
        let p = miss_probability(rule(3, 4), 0.05).unwrap();
        assert!((p - 0.01401875).abs() <= 4e-18, "{p}");
        // The f64 nearest 0.05 is 0.05000000000000000277…; eq. 23 evaluated
        // exactly at that binary value (Python fractions.Fraction(0.05)) rounds
        // to 0.014018750000000002, one ulp above the f64 nearest 0.01401875.
        assert_eq!(p, 0.014018750000000002);
    }

    #[test]
    fn miss_probability_of_6_of_8_at_alpha_005() {
        // Misses when at least 3 of 8 exceed: 1 − P(0) − P(1) − P(2) with
        //   P(0) = 0.95⁸, P(1) = 8·0.05·0.95⁷, P(2) = 28·0.05²·0.95⁶.
        // Summing the tail exactly in rational arithmetic (α = 1/20) gives
        //   1 − (19⁸ + 8·19⁷ + 28·19⁶)/20⁸ = 148178379/25600000000
        //   = 0.0057882179296875 exactly (20⁸ = 2^16·5^8, a terminating decimal).
        // Seed 000 prints P̂_c(6/8) = 0.000102, again not what eq. 23 gives.
        let p = miss_probability(rule(6, 8), 0.05).unwrap();
        assert!((p - 0.0057882179296875).abs() <= 2e-18, "{p}");
        // Exactly at the binary α (as above): 0.005788217929687501.
        assert_eq!(p, 0.005788217929687501);
    }

    #[test]
    fn one_of_one_is_alpha_and_r_of_r_is_the_complement_of_all_passing() {
        // 1/1 reduces to the classic single test: it misses with probability α.
        assert_eq!(miss_probability(rule(1, 1), 0.05).unwrap(), 0.05);
        // R/R misses when any sample exceeds: 1 − (1 − α)^R.
        let p = miss_probability(rule(5, 5), 0.1).unwrap();
        assert!((p - (1.0 - 0.9f64.powi(5))).abs() < 1e-15);
        // 1/R misses only when all R exceed: α^R.
        let p = miss_probability(rule(1, 6), 0.2).unwrap();
        assert!((p / 0.2f64.powi(6) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn tail_of_a_large_window_stays_a_probability() {
        let p = miss_probability(rule(64, 128), 0.5).unwrap();
        // Symmetric binomial: P(K ≥ 65) = (1 − P(K = 64)) / 2 with
        // P(K = 64) = C(128,64)/2^128 ≈ 0.0703861, so P = 0.464806953914992…
        // (evaluated in exact rational arithmetic).
        assert!((p - 0.464_806_953_914_992_4).abs() < 1e-14, "{p}");
    }

    #[test]
    fn rules_and_parameters_are_validated() {
        assert!(LrRule::new(0, 3).is_err());
        assert!(LrRule::new(4, 3).is_err());
        assert!(LrRule::new(1, 129).is_err());
        assert!(miss_probability(rule(1, 1), 0.0).is_err());
        assert!(miss_probability(rule(1, 1), 1.0).is_err());
        assert!(miss_probability(rule(1, 1), f64::NAN).is_err());
        assert!(recommend(0.05, 0.0, 0.75, 8).is_err());
        assert!(recommend(0.05, 0.01, 0.0, 8).is_err());
        assert!(recommend(0.05, 0.01, 0.75, 0).is_err());
    }

    #[test]
    fn recommendation_takes_the_shortest_window_then_the_largest_l() {
        // α = 0.05, bound 0.001, L/R ≥ 0.5:
        //   R=1: L=1 → 0.05; R=2: L=1 → 0.0025; R=3: L=2 → 3·0.05²·0.95 + 0.05³
        //   = 0.007125 + 0.000125 = 0.00725; R=4: L=3 → 0.01401875 (too high),
        //   L=2 → P(K ≥ 3) = 4·0.05³·0.95 + 0.05⁴ = 0.000475 + 0.00000625
        //   = 0.00048125 ≤ 0.001. So 2/4.
        let rec = recommend(0.05, 0.001, 0.5, 8).unwrap();
        let (rule, p) = rec.recommended.unwrap();
        assert_eq!((rule.l(), rule.r()), (2, 4));
        assert_eq!(p, 0.00048125000000000007); // exact at the binary α, as above
        assert_eq!(rec.considered.len(), 8);
        assert_eq!(rec.considered[2].0, LrRule::new(2, 3).unwrap());
    }

    #[test]
    fn recommendation_reports_none_when_the_bound_is_out_of_reach() {
        // With L = R forced (ratio 1), every rule misses with 1 − 0.95^R ≥ 0.05.
        let rec = recommend(0.05, 0.01, 1.0, 16).unwrap();
        assert!(rec.recommended.is_none());
        assert!(rec.considered.iter().all(|(r, _)| r.l() == r.r()));
    }

    #[test]
    fn probabilities_fall_as_l_falls_for_any_window() {
        for r in 1..=40 {
            let mut last = 0.0;
            for l in 1..=r {
                let p = miss_probability(rule(l, r), 0.07).unwrap();
                assert!((0.0..=1.0).contains(&p));
                assert!(p >= last, "l={l} r={r}");
                last = p;
            }
        }
    }
}
