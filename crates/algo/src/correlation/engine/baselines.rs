//! The classic baselines: nearest neighbour and global optimal assignment
//! on the mean statistic over a window, and K-nearest-neighbour.

use std::collections::HashMap;

use super::{OrdF64, PairCorrelator, PairStatus, Reason, Sample};
use crate::{AlgoError, assignment};

impl PairCorrelator<'_> {
    /// Memoryless baselines over the last `window` common samples: nearest
    /// neighbour (greedy) or global optimal assignment.
    pub(super) fn decide_window(&mut self, active: &[u32], k: usize, window: usize, optimal: bool) {
        for &pi in active {
            if self.pairs[pi as usize].status == PairStatus::Decided {
                self.undecide(pi, Reason::Testing);
            }
            self.pairs[pi as usize].cycle_done = false;
        }
        // (pair, normalised cost = sum / gate(w)); gated when cost ≤ 1.
        let mut gated: Vec<(u32, f64)> = Vec::new();
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let w: Vec<&Sample> = p.hist.iter().rev().take(window).collect();
            let sum: f64 = w.iter().map(|s| s.stat).sum();
            let cost = sum / self.window_gate[w.len()];
            if cost <= 1.0 {
                gated.push((pi, cost));
            } else {
                self.pairs[pi as usize].reason = Reason::Gate;
                self.pairs[pi as usize].status = PairStatus::Testing;
            }
        }
        let chosen: Vec<u32> = if optimal {
            let edges: Vec<_> = gated
                .iter()
                .map(|&(pi, c)| {
                    let p = &self.pairs[pi as usize];
                    (p.a as usize, p.b as usize, c)
                })
                .collect();
            // Normalised costs are ≤ 1 inside the gate: leaving a track
            // unpaired costs 1, as much as the worst gated pair.
            assignment::solve(&edges, 1.0 + 1e-12)
                .into_iter()
                .map(|(a, b)| self.pair_of(a as u32, b as u32).expect("a candidate"))
                .collect()
        } else {
            gated.sort_by_key(|&(pi, c)| {
                let p = &self.pairs[pi as usize];
                (OrdF64(c), p.a, p.b)
            });
            let mut used_a = vec![false; self.adj_a.len()];
            let mut used_b = vec![false; self.adj_b.len()];
            let mut out = Vec::new();
            for (pi, _) in &gated {
                let p = &self.pairs[*pi as usize];
                if !used_a[p.a as usize] && !used_b[p.b as usize] {
                    used_a[p.a as usize] = true;
                    used_b[p.b as usize] = true;
                    out.push(*pi);
                }
            }
            out
        };
        for &(pi, _) in &gated {
            self.pairs[pi as usize].reason = Reason::Conflict;
        }
        let reason = if optimal {
            Reason::Assignment
        } else {
            Reason::NearestNeighbour
        };
        for pi in chosen {
            self.decide(pi, k, reason);
        }
    }

    /// K-nearest-neighbour: mutual nearest gated neighbours in ≥ k of the
    /// last `window` instants.
    pub(super) fn decide_knn(&mut self, active: &[u32], k: usize, need: usize, window: usize) {
        for &pi in active {
            if self.pairs[pi as usize].status == PairStatus::Decided {
                self.undecide(pi, Reason::Testing);
            }
            self.pairs[pi as usize].cycle_done = false;
        }
        let mut best_a: HashMap<u32, (f64, u32)> = HashMap::new();
        let mut best_b: HashMap<u32, (f64, u32)> = HashMap::new();
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let stat = p.hist.back().map_or(f64::INFINITY, |s| s.stat);
            if stat > self.delta {
                continue;
            }
            for (map, t) in [(&mut best_a, p.a), (&mut best_b, p.b)] {
                let e = map.entry(t).or_insert((f64::INFINITY, u32::MAX));
                if (stat, pi) < *e {
                    *e = (stat, pi);
                }
            }
        }
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let hit = best_a.get(&p.a).is_some_and(|e| e.1 == pi)
                && best_b.get(&p.b).is_some_and(|e| e.1 == pi);
            if let Some(s) = self.pairs[pi as usize].hist.back_mut() {
                s.hit = hit;
            }
        }
        let mut cands: Vec<(u32, usize, f64)> = Vec::new();
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let w: Vec<&Sample> = p.hist.iter().rev().take(window).collect();
            let hits = w.iter().filter(|s| s.hit).count();
            let mean = w.iter().map(|s| s.stat).sum::<f64>() / w.len().max(1) as f64;
            if hits >= need {
                cands.push((pi, hits, mean));
            } else {
                self.pairs[pi as usize].reason = Reason::Gate;
            }
        }
        cands.sort_by_key(|&(pi, hits, mean)| {
            let p = &self.pairs[pi as usize];
            (std::cmp::Reverse(hits), OrdF64(mean), p.a, p.b)
        });
        for (pi, _, _) in cands {
            if self.is_free(pi) {
                self.decide(pi, k, Reason::KOfN);
            } else {
                self.pairs[pi as usize].reason = Reason::Conflict;
            }
        }
    }
}

pub(super) fn check_window(window: usize) -> Result<(), AlgoError> {
    if window == 0 || window > 64 {
        return Err(AlgoError::InvalidParameter {
            what: "window",
            reason: "must be between 1 and 64".into(),
        });
    }
    Ok(())
}

/// (m, C, samples, mean statistic, mean position difference) of a window.
pub(super) fn window_counts(w: &[&Sample], delta: f64) -> (u32, u32, u32, f64, f64) {
    let n = w.len() as u32;
    let m = w.iter().filter(|s| s.stat <= delta).count() as u32;
    let denom = f64::from(n.max(1));
    let mean = w.iter().map(|s| s.stat).sum::<f64>() / denom;
    let mean_pos = w.iter().map(|s| s.posdiff).sum::<f64>() / denom;
    (m, n - m, n, mean, mean_pos)
}
