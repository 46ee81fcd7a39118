//! The double-threshold decision (seed 000 eqs. 15–21): counting cycles,
//! early stop and early decision, ambiguity resolution (greedy or by global
//! assignment), revocation of decided pairs and trial system tracks; and the
//! rule schedules.

use super::{
    Method, OrdF64, Pair, PairCorrelator, PairStatus, Reason, Resolution, RuleSpec, Sample,
};
use crate::{AlgoError, assignment, correlation::rules::LrRule};

impl PairCorrelator<'_> {
    /// The final rule (L, R) of a double-threshold method.
    pub(super) fn final_rule(&self) -> Option<(u32, u32)> {
        match &self.cfg.method {
            Method::DoubleThreshold { rules, .. } => {
                let r = final_rule(rules);
                Some((r.l(), r.r()))
            }
            _ => None,
        }
    }

    /// Ends the cycle of a pair that has used R samples without a decision
    /// (seed 000 §3.3: such tracks enter the next cycle).
    pub(super) fn close_cycle(&mut self, pi: u32) {
        let Some((l_final, r_final)) = self.final_rule() else {
            return;
        };
        let p = &mut self.pairs[pi as usize];
        if p.status != PairStatus::Decided && p.l >= r_final {
            p.cycle_done = true;
            if p.status == PairStatus::Testing && p.m < l_final && p.reason == Reason::Testing {
                p.reason = Reason::BelowRule;
            }
        }
    }

    pub(super) fn decide_double_threshold(
        &mut self,
        active: &[u32],
        k: usize,
        rules: &RuleSpec,
        resolution: Resolution,
    ) {
        let last = final_rule(rules);
        let (lf, rf) = (last.l(), last.r());
        // Decided pairs keep being tested; a pair whose recent samples no
        // longer meet the rule is revoked and both tracks are freed.
        for &pi in active {
            let p = &self.pairs[pi as usize];
            if p.status != PairStatus::Decided || p.decided_at == Some(k) {
                continue;
            }
            let window = monitor_window(p, rf as usize);
            let w = window.len();
            let fails = window.iter().filter(|s| s.stat > self.delta).count() as u32;
            let allowed = match rules {
                RuleSpec::Fixed(_) => rf - lf,
                RuleSpec::Schedule(s) => {
                    let r = s[w.min(s.len()) - 1];
                    r.r() - r.l()
                }
            };
            if fails > allowed {
                self.undecide(pi, Reason::Revoked);
            }
        }

        let rule_at = |l: u32| -> LrRule {
            match rules {
                RuleSpec::Fixed(r) => *r,
                RuleSpec::Schedule(s) => s[(l as usize).clamp(1, s.len()) - 1],
            }
        };
        let qualified = |me: &Self, pi: u32| {
            let p = &me.pairs[pi as usize];
            p.status == PairStatus::Testing
                && !p.cycle_done
                && p.l > 0
                && p.m >= rule_at(p.l).l()
                && me.is_free(pi)
        };
        let competitors = |me: &Self, pi: u32| -> Vec<u32> {
            let p = &me.pairs[pi as usize];
            me.adj_a[p.a as usize]
                .iter()
                .chain(me.adj_b[p.b as usize].iter())
                .copied()
                .filter(|&q| q != pi && qualified(me, q))
                .collect()
        };
        let key = |me: &Self, pi: u32| {
            let p = &me.pairs[pi as usize];
            (
                std::cmp::Reverse(p.m),
                OrdF64(p.sum_stat / f64::from(p.l.max(1))),
                p.a,
                p.b,
            )
        };
        let is_schedule = matches!(rules, RuleSpec::Schedule(_));
        let mut ready: Vec<u32> = active
            .iter()
            .copied()
            .filter(|&pi| {
                qualified(self, pi)
                    && (is_schedule
                        || self.pairs[pi as usize].l >= rf
                        || competitors(self, pi).is_empty())
            })
            .collect();
        ready.sort_by_key(|&pi| key(self, pi));

        match resolution {
            Resolution::Greedy => {
                for pi in ready {
                    if !qualified(self, pi) {
                        // A better-ranked pair took one of its tracks.
                        self.pairs[pi as usize].reason = Reason::AmbiguityLost;
                        continue;
                    }
                    let rivals = competitors(self, pi);
                    let mine = key(self, pi);
                    if rivals.iter().any(|&q| key(self, q) < mine) {
                        self.pairs[pi as usize].reason = Reason::AmbiguityLost;
                        continue;
                    }
                    let p = &self.pairs[pi as usize];
                    let reason = if rivals.is_empty() {
                        if !is_schedule && p.l < rf {
                            Reason::EarlyDecision
                        } else {
                            Reason::Threshold
                        }
                    } else if rivals.iter().all(|&q| self.pairs[q as usize].m < p.m) {
                        Reason::AmbiguityMaxM
                    } else {
                        Reason::AmbiguityMinMeanStatistic
                    };
                    self.decide(pi, k, reason);
                }
            }
            Resolution::Assignment => {
                let edges: Vec<(usize, usize, f64)> = ready
                    .iter()
                    .map(|&pi| {
                        let p = &self.pairs[pi as usize];
                        let mean = p.sum_stat / f64::from(p.l.max(1));
                        // Lexicographic: fewer misses first, then a smaller
                        // mean statistic (mapped into [0, 1)).
                        let cost = f64::from(rf.saturating_sub(p.m)) + mean / (1.0 + mean);
                        (p.a as usize, p.b as usize, cost)
                    })
                    .collect();
                let chosen = assignment::solve(&edges, f64::from(rf) + 2.0);
                for (a, b) in chosen {
                    let pi = self.pair_of(a as u32, b as u32).expect("a candidate");
                    let reason = if competitors(self, pi).is_empty() {
                        if !is_schedule && self.pairs[pi as usize].l < rf {
                            Reason::EarlyDecision
                        } else {
                            Reason::Threshold
                        }
                    } else {
                        Reason::Assignment
                    };
                    self.decide(pi, k, reason);
                }
                for pi in ready {
                    if self.pairs[pi as usize].status != PairStatus::Decided {
                        self.pairs[pi as usize].reason = Reason::AmbiguityLost;
                    }
                }
            }
        }

        for &pi in active {
            self.close_cycle(pi);
        }

        // Trial system tracks (eq. 21): among undecided pairs of free tracks,
        // the largest m, then the smallest C, then the smallest mean norm of
        // the position difference.
        for p in &mut self.pairs {
            p.trial = false;
        }
        let mut trial: Vec<u32> = active
            .iter()
            .copied()
            .filter(|&pi| {
                let p = &self.pairs[pi as usize];
                p.status == PairStatus::Testing && !p.cycle_done && p.m >= 1 && self.is_free(pi)
            })
            .collect();
        trial.sort_by_key(|&pi| {
            let p = &self.pairs[pi as usize];
            (
                std::cmp::Reverse(p.m),
                p.c,
                OrdF64(p.sum_posdiff / f64::from(p.l.max(1))),
                p.a,
                p.b,
            )
        });
        let mut used_a = vec![false; self.adj_a.len()];
        let mut used_b = vec![false; self.adj_b.len()];
        for pi in trial {
            let (a, b) = {
                let p = &self.pairs[pi as usize];
                (p.a as usize, p.b as usize)
            };
            if !used_a[a] && !used_b[b] {
                used_a[a] = true;
                used_b[b] = true;
                self.pairs[pi as usize].trial = true;
            }
        }
    }
}

/// The last rule of a rule specification (the one in force after R samples).
pub fn final_rule(rules: &RuleSpec) -> LrRule {
    match rules {
        RuleSpec::Fixed(r) => *r,
        RuleSpec::Schedule(s) => *s.last().expect("validated non-empty"),
    }
}

/// The default dynamic schedule of seed 000 §3.3 (1/1, 2/2, 2/3, 3/4, 4/5,
/// 4/6, 5/7, 6/8). The paper lists both 3/5 and 4/5 for five samples; one
/// rule per sample count is needed, and 4/5 keeps L/R ≥ 0.75 like 3/4 and 6/8.
pub fn default_schedule() -> Vec<LrRule> {
    [
        (1, 1),
        (2, 2),
        (2, 3),
        (3, 4),
        (4, 5),
        (4, 6),
        (5, 7),
        (6, 8),
    ]
    .into_iter()
    .map(|(l, r)| LrRule::new(l, r).expect("valid rules"))
    .collect()
}

pub(super) fn check_rules(rules: &RuleSpec) -> Result<(), AlgoError> {
    if let RuleSpec::Schedule(s) = rules {
        if s.is_empty() {
            return Err(AlgoError::InvalidParameter {
                what: "schedule",
                reason: "must hold at least one rule".into(),
            });
        }
        for (i, r) in s.iter().enumerate() {
            if r.r() as usize != i + 1 {
                return Err(AlgoError::InvalidParameter {
                    what: "schedule",
                    reason: format!(
                        "entry {i} is used after {} samples, so its r must be {}",
                        i + 1,
                        i + 1
                    ),
                });
            }
        }
    }
    Ok(())
}

/// The samples after the decision, at most the last `r`.
fn monitor_window(p: &Pair, r: usize) -> Vec<&Sample> {
    let since = p.decided_at.unwrap_or(0) as u32;
    p.hist
        .iter()
        .rev()
        .filter(|s| s.k >= since)
        .take(r)
        .collect()
}
