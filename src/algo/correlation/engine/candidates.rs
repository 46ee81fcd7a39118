//! Candidate pairs: the conservative spatial gate (a uniform grid over
//! positions) or brute force, and the materialisation of a pair the first
//! time it may pass the χ² test, with the exact replay of its earlier common
//! instants.

use std::collections::VecDeque;

use super::{Pair, PairCorrelator, Pruning, Reason, Statistic, Status};
use crate::algo::{correlation::scene::Track, small};

impl PairCorrelator<'_> {
    /// Creates the pairs that pass the spatial gate at instant `k` for the
    /// first time, replaying their earlier common instants.
    pub(super) fn materialise(&mut self, k: usize) {
        let present_a: Vec<u32> = (0..self.adj_a.len() as u32)
            .filter(|&t| self.track_a(t).is_present(k))
            .collect();
        let present_b: Vec<u32> = (0..self.adj_b.len() as u32)
            .filter(|&t| self.track_b(t).is_present(k))
            .collect();
        let candidates = match self.cfg.pruning {
            Pruning::None => self.all_pairs_candidates(k, &present_a, &present_b),
            Pruning::Grid => self.spatial_candidates(k, &present_a, &present_b),
        };
        for (a, b) in candidates {
            if self.index.contains_key(&(a, b)) {
                continue;
            }
            let pi = self.pairs.len() as u32;
            self.pairs.push(Pair {
                a,
                b,
                status: Status::Testing,
                reason: Reason::Testing,
                trial: false,
                l: 0,
                m: 0,
                c: 0,
                sum_stat: 0.0,
                sum_posdiff: 0.0,
                cycle_done: false,
                decided_at: None,
                decided_time: None,
                hist: VecDeque::with_capacity(self.hist_len + 1),
                cross: None,
                last_common: None,
            });
            self.index.insert((a, b), pi);
            self.adj_a[a as usize].push(pi);
            self.adj_b[b as usize].push(pi);
            // Instants before the scene's window are gone (a streaming
            // session keeps a bounded history): the replay starts there.
            for j in self.scene.first()..k {
                if self.both_present(pi, j) {
                    self.advance(pi, j);
                    self.close_cycle(pi);
                }
            }
        }
    }

    /// How far the weighted bound may be exceeded by a pair that can still
    /// pass: 1 for the weighted statistic, 2 for the modified one (S_mod ≤
    /// 2 (P_a + P_b)).
    pub(super) fn gate_factor(&self) -> f64 {
        match self.cfg.statistic {
            Statistic::Weighted => 1.0,
            Statistic::Modified => 2.0,
        }
    }

    /// Brute force: the weighted statistic of every pair present at `k`; a
    /// pair may pass when α ≤ δ (weighted) or α ≤ 2δ (modified, since
    /// S_mod ≤ 2 (P_a + P_b) makes β ≥ α / 2).
    pub(super) fn all_pairs_candidates(
        &self,
        k: usize,
        present_a: &[u32],
        present_b: &[u32],
    ) -> Vec<(u32, u32)> {
        let dim = self.dim;
        let limit = self.gate_factor() * self.delta;
        let mut out = Vec::new();
        for &a in present_a {
            for &b in present_b {
                let (d, s) = self.difference(a, b, k);
                if small::quad_form_inv(&s, &d, dim).is_some_and(|q| q <= limit) {
                    out.push((a, b));
                }
            }
        }
        out
    }

    /// The pairs (a, b) present at `k` that may pass the χ² test.
    pub(super) fn spatial_candidates(
        &self,
        k: usize,
        present_a: &[u32],
        present_b: &[u32],
    ) -> Vec<(u32, u32)> {
        let dim = self.dim;
        let pos = self.scene.position_indices();
        let factor = self.gate_factor();
        let reach2 = |t: &Track| factor * self.delta * small::trace_bound(t.p(k, dim), dim, pos);
        let point = |t: &Track| {
            let x = t.x(k, dim);
            let mut c = [0.0; 3];
            for (i, &j) in pos.iter().enumerate() {
                c[i] = x[j];
            }
            c
        };
        let b_pts: Vec<([f64; 3], f64)> = present_b
            .iter()
            .map(|&t| {
                let tr = self.track_b(t);
                (point(tr), reach2(tr))
            })
            .collect();
        let max_rb = b_pts.iter().map(|p| p.1.sqrt()).fold(0.0, f64::max);
        let max_ra = present_a
            .iter()
            .map(|&t| reach2(self.track_a(t)).sqrt())
            .fold(0.0, f64::max);
        // A cell as wide as the largest reach: a typical query then spans
        // 3 cells per axis.
        let cell = (max_ra + max_rb).max(1e-6);
        let key = |c: &[f64; 3]| {
            [
                (c[0] / cell).floor() as i64,
                (c[1] / cell).floor() as i64,
                (c[2] / cell).floor() as i64,
            ]
        };
        // The grid as a sorted list of (cell, track): one allocation, and a
        // cell's tracks are a contiguous run found by binary search.
        let mut grid: Vec<([i64; 3], u32)> = b_pts
            .iter()
            .enumerate()
            .map(|(i, (c, _))| (key(c), i as u32))
            .collect();
        grid.sort_unstable();
        let occupied = grid.windows(2).filter(|w| w[0].0 != w[1].0).count() + 1;
        let dims_used = pos.len();
        let mut out = Vec::new();
        for &a in present_a {
            let ta = self.track_a(a);
            let (ca, ra2) = (point(ta), reach2(ta));
            let reach = ra2.sqrt() + max_rb;
            let span = (reach / cell).ceil();
            let test = |i: u32, out: &mut Vec<(u32, u32)>| {
                let (cb, rb2) = b_pts[i as usize];
                let d2: f64 = (0..3).map(|j| (ca[j] - cb[j]).powi(2)).sum();
                if d2 <= ra2 + rb2 {
                    out.push((a, present_b[i as usize]));
                }
            };
            let cells = (2.0 * span + 1.0).powi(dims_used as i32);
            if !span.is_finite() || cells > occupied as f64 {
                for i in 0..b_pts.len() as u32 {
                    test(i, &mut out);
                }
                continue;
            }
            let (span, base) = (span as i64, key(&ca));
            let range = |d: usize| {
                if d < dims_used {
                    (base[d] - span)..=(base[d] + span)
                } else {
                    base[d]..=base[d]
                }
            };
            for x in range(0) {
                for y in range(1) {
                    for z in range(2) {
                        let cell = [x, y, z];
                        let from = grid.partition_point(|e| e.0 < cell);
                        for &(c, i) in &grid[from..] {
                            if c != cell {
                                break;
                            }
                            test(i, &mut out);
                        }
                    }
                }
            }
        }
        out
    }
}
