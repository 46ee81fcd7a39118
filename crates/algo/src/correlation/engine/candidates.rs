//! Candidate pairs: the conservative spatial gate (a uniform grid over
//! positions) or brute force, and the materialisation of a pair the first
//! time it may pass the χ² test, with the exact replay of its earlier common
//! instants.
//!
//! The pair budget ([`PairCorrelator::with_pair_budget`]) is checked where
//! pairs are collected and where they are stored, so a scene of many
//! co-located tracks is refused before it allocates more than the budget.

use std::collections::VecDeque;

use super::{Pair, PairCorrelator, PairStatus, Pruning, Reason, Statistic};
use crate::{AlgoError, correlation::scene::Track, small};

/// The candidates of one instant, at most `cap` of them: more means the
/// pairs would exceed the budget whatever was materialised before (the
/// pairs already held are at most the budget), so collecting stops there.
pub(super) struct Collected {
    pairs: Vec<(u32, u32)>,
    cap: usize,
}

impl Collected {
    fn push(&mut self, pair: (u32, u32)) -> Result<(), AlgoError> {
        if self.pairs.len() >= self.cap {
            return Err(over_budget(self.cap));
        }
        self.pairs.push(pair);
        Ok(())
    }
}

/// The error of a correlator whose candidate pairs would exceed `cap`.
fn over_budget(cap: usize) -> AlgoError {
    AlgoError::BudgetExceeded {
        what: "candidate pairs",
        limit: cap as u64,
    }
}

impl PairCorrelator<'_> {
    /// Creates the pairs that pass the spatial gate at instant `k` for the
    /// first time, replaying their earlier common instants.
    pub(super) fn materialise(&mut self, k: usize) -> Result<(), AlgoError> {
        let present_a: Vec<u32> = (0..self.adj_a.len() as u32)
            .filter(|&t| self.track_a(t).is_present(k))
            .collect();
        let present_b: Vec<u32> = (0..self.adj_b.len() as u32)
            .filter(|&t| self.track_b(t).is_present(k))
            .collect();
        let mut candidates = Collected {
            pairs: Vec::new(),
            cap: self.max_pairs,
        };
        match self.cfg.pruning {
            Pruning::None => self.all_pairs_candidates(k, &present_a, &present_b, &mut candidates),
            Pruning::Grid => self.spatial_candidates(k, &present_a, &present_b, &mut candidates),
        }?;
        for (a, b) in candidates.pairs {
            if self.pair_of(a, b).is_some() {
                continue;
            }
            if self.pairs.len() >= self.max_pairs {
                return Err(over_budget(self.max_pairs));
            }
            let pi = self.pairs.len() as u32;
            self.pairs.push(Pair {
                a,
                b,
                status: PairStatus::Testing,
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
        Ok(())
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
        out: &mut Collected,
    ) -> Result<(), AlgoError> {
        let dim = self.dim;
        let limit = self.gate_factor() * self.delta;
        for &a in present_a {
            for &b in present_b {
                let (d, s) = self.difference(a, b, k);
                if small::quad_form_inv(&s, &d, dim).is_some_and(|q| q <= limit) {
                    out.push((a, b))?;
                }
            }
        }
        Ok(())
    }

    /// The pairs (a, b) present at `k` that may pass the χ² test: those
    /// with ‖d_pos‖² ≤ g δ (tr P_a,pos + tr P_b,pos), found through a dense
    /// uniform grid over the second node's positions (cells as wide as the
    /// largest reach, widened when the grid would hold more than a few cells
    /// per track), stored as a counting sort: no hashing, no search.
    pub(super) fn spatial_candidates(
        &self,
        k: usize,
        present_a: &[u32],
        present_b: &[u32],
        out: &mut Collected,
    ) -> Result<(), AlgoError> {
        let dim = self.dim;
        let pos = self.scene.position_indices();
        let dims_used = pos.len();
        let factor = self.gate_factor();
        let point = |t: &Track| {
            let x = t.x(k, dim);
            let mut c = [0.0; 3];
            for (i, &j) in pos.iter().enumerate() {
                c[i] = x[j];
            }
            let reach2 = factor * self.delta * small::trace_bound(t.p(k, dim), dim, pos);
            (c, reach2)
        };
        let b_pts: Vec<([f64; 3], f64)> =
            present_b.iter().map(|&t| point(self.track_b(t))).collect();
        let a_pts: Vec<([f64; 3], f64)> =
            present_a.iter().map(|&t| point(self.track_a(t))).collect();
        if b_pts.is_empty() || a_pts.is_empty() {
            return Ok(());
        }
        let max_rb = b_pts.iter().map(|p| p.1.sqrt()).fold(0.0, f64::max);
        let max_ra = a_pts.iter().map(|p| p.1.sqrt()).fold(0.0, f64::max);
        let test = |ia: usize, ib: usize, out: &mut Collected| {
            let ((ca, ra2), (cb, rb2)) = (a_pts[ia], b_pts[ib]);
            let d2: f64 = (0..3).map(|j| (ca[j] - cb[j]).powi(2)).sum();
            if d2 <= ra2 + rb2 {
                out.push((present_a[ia], present_b[ib]))?;
            }
            Ok(())
        };
        let all_pairs = |out: &mut Collected| {
            for ia in 0..a_pts.len() {
                for ib in 0..b_pts.len() {
                    test(ia, ib, out)?;
                }
            }
            Ok(())
        };
        // A cell as wide as the largest reach: a typical query then spans
        // 3 cells per axis.
        let mut cell = (max_ra + max_rb).max(1e-6);
        let mut lo = [0.0f64; 3];
        let mut n = [1usize; 3];
        let limit = (4 * b_pts.len() + 1024) as f64;
        loop {
            if !cell.is_finite() {
                return all_pairs(out);
            }
            let mut cells = 1.0;
            for d in 0..dims_used {
                let (min, max) = b_pts
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |m, p| {
                        (m.0.min(p.0[d]), m.1.max(p.0[d]))
                    });
                lo[d] = (min / cell).floor();
                let span = (max / cell).floor() - lo[d] + 1.0;
                cells *= span;
                n[d] = span as usize;
            }
            if cells <= limit {
                break;
            }
            // Too sparse for a dense grid at this width: widen the cells
            // (the candidate set is the same, only more pairs are tested).
            cell *= (cells / limit).powf(1.0 / dims_used as f64).max(1.5);
        }
        let index = |c: &[f64; 3]| {
            let mut i = 0;
            for d in (0..3).rev() {
                let v = if d < dims_used {
                    ((c[d] / cell).floor() - lo[d]) as usize
                } else {
                    0
                };
                i = i * n[d] + v.min(n[d] - 1);
            }
            i
        };
        // Counting sort of the second node's tracks by cell (stable, so a
        // cell lists its tracks in ascending order).
        let total = n[0] * n[1] * n[2];
        let mut start = vec![0u32; total + 1];
        let cell_of: Vec<usize> = b_pts.iter().map(|p| index(&p.0)).collect();
        for &c in &cell_of {
            start[c + 1] += 1;
        }
        for c in 0..total {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut order = vec![0u32; b_pts.len()];
        for (ib, &c) in cell_of.iter().enumerate() {
            order[fill[c] as usize] = ib as u32;
            fill[c] += 1;
        }
        for (ia, (ca, ra2)) in a_pts.iter().enumerate() {
            let reach = ra2.sqrt() + max_rb;
            let span = (reach / cell).ceil();
            let visits = (2.0 * span + 1.0).powi(dims_used as i32);
            if !span.is_finite() || visits > b_pts.len() as f64 {
                for ib in 0..b_pts.len() {
                    test(ia, ib, out)?;
                }
                continue;
            }
            // Cell ranges per axis, clipped to the grid (positions are the
            // cell indices relative to `lo`, possibly outside it).
            let mut range = [(0usize, 0usize); 3];
            let mut empty = false;
            for d in 0..3 {
                if d >= dims_used {
                    continue;
                }
                let centre = (ca[d] / cell).floor() - lo[d];
                let (from, to) = (centre - span, centre + span);
                if to < 0.0 || from > (n[d] - 1) as f64 {
                    empty = true;
                    break;
                }
                range[d] = (from.max(0.0) as usize, (to as usize).min(n[d] - 1));
            }
            if empty {
                continue;
            }
            for z in range[2].0..=range[2].1 {
                for y in range[1].0..=range[1].1 {
                    let row = (z * n[1] + y) * n[0];
                    let (c0, c1) = (row + range[0].0, row + range[0].1);
                    for &ib in &order[start[c0] as usize..start[c1 + 1] as usize] {
                        test(ia, ib as usize, out)?;
                    }
                }
            }
        }
        Ok(())
    }
}
