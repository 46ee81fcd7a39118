//! The modified K-nearest-neighbour track association of seed 003 §2.2: a
//! pair of local tracks passes through an association period, a check period
//! and a hold period.
//!
//! - Association period (the first N₀ tests): a test is a hit when every
//!   component of the difference lies within its threshold. More than
//!   N₀ − K misses reject the pair (no further tests, as in the paper); at
//!   the N₀-th test the pair has ≥ K hits and enters the check period.
//! - Check period: χ² tests with the counter T_ij (+1 pass, −1 fail, from
//!   T_ij(N₀) = 0). After 3 tests: T = 3 → hold; T ≤ −1 → revoked (the system
//!   track is withdrawn and the pair restarts its association period);
//!   T = 1 → 2 more tests, then T ≥ 1 (3 passes of 5) → hold, else revoked.
//!   The paper leaves the final rule at N₀ + 5 unstated; majority is ours.
//! - Hold period: no more tests.

/// The association state of a pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Period {
    /// The first N₀ tests: component-threshold hits are counted.
    Association,
    /// χ² tests with the counter T_ij; the pair forms a system track.
    Check,
    /// The pair stays correlated; no more tests.
    Hold,
    /// Rejected in the association period; never tested again.
    Rejected,
}

/// Parameters of the modified K-NN test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnnParams {
    /// N₀ ≥ 2 association tests.
    pub n0: u32,
    /// K hits, ⌈N₀/2⌉ ≤ K ≤ N₀.
    pub k: u32,
}

/// The counters of one pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairState {
    /// The period the pair is in.
    pub period: Period,
    /// Tests in the current association period.
    pub tests: u32,
    /// Hits among those tests.
    pub hits: u32,
    /// Misses among those tests.
    pub misses: u32,
    /// T_ij of the check period.
    pub counter: i32,
    /// Tests in the current check period.
    pub check_tests: u32,
    /// Times the pair was revoked back to the association period.
    pub revocations: u32,
}

impl PairState {
    /// A pair at the start of its association period, every counter zero.
    pub fn new() -> Self {
        Self {
            period: Period::Association,
            tests: 0,
            hits: 0,
            misses: 0,
            counter: 0,
            check_tests: 0,
            revocations: 0,
        }
    }

    /// Whether the pair currently forms a system track (check or hold period).
    pub fn correlated(&self) -> bool {
        matches!(self.period, Period::Check | Period::Hold)
    }

    /// Whether the next instant needs a test.
    pub fn wants_test(&self) -> bool {
        matches!(self.period, Period::Association | Period::Check)
    }

    /// One instant: `hit` is the component-threshold test (association
    /// period), `pass` the χ² test (check period).
    pub fn step(&mut self, params: KnnParams, hit: bool, pass: bool) {
        match self.period {
            Period::Association => {
                self.tests += 1;
                if hit {
                    self.hits += 1;
                } else {
                    self.misses += 1;
                }
                if self.misses > params.n0 - params.k {
                    self.period = Period::Rejected;
                } else if self.tests >= params.n0 {
                    self.period = Period::Check;
                    self.counter = 0;
                    self.check_tests = 0;
                }
            }
            Period::Check => {
                self.check_tests += 1;
                self.counter += if pass { 1 } else { -1 };
                match self.check_tests {
                    3 if self.counter == 3 => self.period = Period::Hold,
                    3 if self.counter <= -1 => self.revoke(),
                    5 if self.counter >= 1 => self.period = Period::Hold,
                    5 => self.revoke(),
                    _ => {}
                }
            }
            Period::Hold | Period::Rejected => {}
        }
    }

    fn revoke(&mut self) {
        *self = Self {
            revocations: self.revocations + 1,
            ..Self::new()
        };
    }
}

impl Default for PairState {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: KnnParams = KnnParams { n0: 4, k: 3 };

    #[test]
    fn association_then_check_then_hold() {
        let mut s = PairState::new();
        // N₀ = 4, K = 3: one miss is allowed (N₀ − K = 1).
        for (hit, tests, period) in [
            (true, 1, Period::Association),
            (false, 2, Period::Association),
            (true, 3, Period::Association),
            (true, 4, Period::Check),
        ] {
            s.step(P, hit, false);
            assert_eq!((s.tests, s.period), (tests, period));
        }
        assert_eq!((s.hits, s.misses), (3, 1));
        // Three χ² passes: T = 1, 2, 3 → hold.
        for (t, period) in [(1, Period::Check), (2, Period::Check), (3, Period::Hold)] {
            s.step(P, false, true);
            assert_eq!((s.counter, s.period), (t, period));
        }
        // Hold: nothing changes any more.
        s.step(P, false, false);
        assert_eq!((s.counter, s.period, s.check_tests), (3, Period::Hold, 3));
    }

    #[test]
    fn early_rejection_in_the_association_period() {
        let mut s = PairState::new();
        s.step(P, false, false); // 1 miss = N₀ − K: still associating
        assert_eq!(s.period, Period::Association);
        s.step(P, false, false); // 2 misses > 1: rejected after 2 of 4 tests
        assert_eq!((s.period, s.tests), (Period::Rejected, 2));
        s.step(P, true, true);
        assert_eq!((s.period, s.tests), (Period::Rejected, 2));
    }

    fn checking() -> PairState {
        let mut s = PairState::new();
        for _ in 0..4 {
            s.step(P, true, false);
        }
        assert_eq!(s.period, Period::Check);
        s
    }

    #[test]
    fn revocation_after_three_checks() {
        // pass, fail, fail: T = 1, 0, −1 → revoked back to association.
        let mut s = checking();
        for pass in [true, false, false] {
            s.step(P, false, pass);
        }
        assert_eq!(s.period, Period::Association);
        assert_eq!((s.tests, s.hits, s.counter, s.revocations), (0, 0, 0, 1));
    }

    #[test]
    fn two_more_checks_when_the_counter_is_one() {
        // pass, pass, fail: T = 1 after 3 → two more; pass, fail: T = 1 ≥ 1 → hold.
        let mut s = checking();
        for pass in [true, true, false] {
            s.step(P, false, pass);
        }
        assert_eq!((s.period, s.counter), (Period::Check, 1));
        s.step(P, false, true);
        s.step(P, false, false);
        assert_eq!((s.period, s.counter), (Period::Hold, 1));
        // pass, pass, fail, fail, fail: T = 1 then 0, −1 → revoked.
        let mut s = checking();
        for pass in [true, true, false, false, false] {
            s.step(P, false, pass);
        }
        assert_eq!((s.period, s.revocations), (Period::Association, 1));
    }
}
