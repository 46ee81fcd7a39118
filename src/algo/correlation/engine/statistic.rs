//! The test statistics: weighted α = d'(P_a + P_b)⁻¹d (eq. 10) and modified
//! β with the cross-covariance recursion of eq. 13, the per-pair counters they
//! feed, and the filter factors I − K H the recursion needs.

use nalgebra::{DMatrix, DVector};

use super::{PairCorrelator, Reason, Sample, Statistic, Status};
use crate::algo::{
    AlgoError,
    correlation::scene::Scene,
    motion::MotionModel,
    small::{self, MAX_DIM, Sq},
};

impl PairCorrelator<'_> {
    /// d = x_a − x_b and S = P_a + P_b at instant `k` (eq. 10), on the stack.
    pub(super) fn difference(&self, a: u32, b: u32, k: usize) -> ([f64; MAX_DIM], Sq) {
        let dim = self.dim;
        let (ta, tb) = (self.track_a(a), self.track_b(b));
        let (xa, xb, pa, pb) = (ta.x(k, dim), tb.x(k, dim), ta.p(k, dim), tb.p(k, dim));
        let mut d = [0.0; MAX_DIM];
        for i in 0..dim {
            d[i] = xa[i] - xb[i];
        }
        let mut s = small::ZERO;
        for i in 0..dim * dim {
            s[i] = pa[i] + pb[i];
        }
        (d, s)
    }

    /// Computes the statistic of pair `pi` at instant `k` and updates its
    /// counters (or, once decided, its monitoring window).
    pub(super) fn advance(&mut self, pi: u32, k: usize) {
        let dim = self.dim;
        let (a, b) = {
            let p = &self.pairs[pi as usize];
            (p.a, p.b)
        };
        if self.cfg.statistic == Statistic::Modified {
            self.update_cross(pi, k);
        }
        let (d, s) = self.difference(a, b, k);
        let mut stat = None;
        if let Some(cross) = &self.pairs[pi as usize].cross {
            let mut s_mod = s;
            for i in 0..dim {
                for j in 0..dim {
                    s_mod[i * dim + j] -= cross[i * dim + j] + cross[j * dim + i];
                }
            }
            stat = small::quad_form_inv(&s_mod, &d, dim);
            if stat.is_none() {
                // P_a + P_b − P_ab − P_ab' is a covariance only when the
                // reported covariances, gains and model are consistent;
                // otherwise fall back to the weighted statistic.
                self.singular_tests += 1;
            }
        }
        let stat = stat
            .or_else(|| small::quad_form_inv(&s, &d, dim))
            .unwrap_or(f64::INFINITY);
        let posdiff = self
            .scene
            .position_indices()
            .iter()
            .map(|&i| d[i] * d[i])
            .sum::<f64>()
            .sqrt();
        let pass = stat <= self.delta;
        let (hist_len, rf) = (self.hist_len, self.final_rule());
        let p = &mut self.pairs[pi as usize];
        p.last_common = Some(k);
        if p.cycle_done {
            p.l = 0;
            p.m = 0;
            p.c = 0;
            p.sum_stat = 0.0;
            p.sum_posdiff = 0.0;
            p.cycle_done = false;
            if p.status == Status::Stopped {
                p.status = Status::Testing;
            }
            p.reason = Reason::Testing;
        }
        p.hist.push_back(Sample {
            k: k as u32,
            stat,
            posdiff,
            hit: false,
        });
        if p.hist.len() > hist_len {
            p.hist.pop_front();
        }
        p.l += 1;
        if pass {
            p.m += 1;
        } else {
            p.c += 1;
        }
        p.sum_stat += stat;
        p.sum_posdiff += posdiff;
        if let Some((l_final, r_final)) = rf
            && p.status == Status::Testing
            && p.c > r_final - l_final
        {
            p.status = Status::Stopped;
            p.reason = Reason::EarlyStop;
        }
    }

    /// Eq. 13: P_ab(k) = A_a(k) [Φ P_ab(k⁻) Φ' + G Q G'] A_b(k)', A = I − K H,
    /// from P_ab = 0 at the pair's first common instant. (The paper prints the
    /// last factor without the transpose; the covariance of the two filters'
    /// errors needs it.)
    pub(super) fn update_cross(&mut self, pi: u32, k: usize) {
        let dim = self.dim;
        let (a, b, prev, cross) = {
            let p = &self.pairs[pi as usize];
            (p.a, p.b, p.last_common, p.cross)
        };
        let new = match (prev, cross) {
            // A last common instant before the held window restarts the
            // recursion from P_ab = 0 (streaming sessions only).
            (Some(kp), Some(c)) if kp >= self.scene.first() => {
                let dt = self.scene.time(k) - self.scene.time(kp);
                let (ta, tb) = (self.track_a(a), self.track_b(b));
                let mean: DVector<f64> = DVector::from_iterator(
                    dim,
                    (0..dim).map(|i| 0.5 * (ta.x(kp, dim)[i] + tb.x(kp, dim)[i])),
                );
                let model = self.model.expect("checked in new");
                let (Ok(f), Ok(q)) = (model.transition(dt), model.process_noise(dt, &mean)) else {
                    self.pairs[pi as usize].cross = Some(small::ZERO);
                    return;
                };
                let f = small::to_sq(&f);
                let q = small::to_sq(&q);
                let fc = small::mul(&f, &c, dim);
                let mut mid = small::mul_t(&fc, &f, dim);
                for i in 0..dim * dim {
                    mid[i] += q[i];
                }
                let first = self.scene.first();
                let fa = self.factors_a[a as usize][k - first];
                let fb = self.factors_b[b as usize][k - first];
                let left = match fa {
                    Some(fa) => small::mul(&fa, &mid, dim),
                    None => mid,
                };
                match fb {
                    Some(fb) => small::mul_t(&left, &fb, dim),
                    None => left,
                }
            }
            _ => small::ZERO,
        };
        self.pairs[pi as usize].cross = Some(new);
    }
}

/// I − K H for every track of a node at every instant: reported, or
/// recomputed as P(k|k) P(k|k−1)⁻¹ with P(k|k−1) = Φ P(k⁻|k⁻) Φ' + Q from the
/// track's previous instant k⁻ (for the optimal gain, P(k|k) = (I − K H) P(k|k−1)).
/// `None` at a track's first instant, where no prediction exists.
pub(super) fn filter_factors(
    scene: &Scene,
    node: usize,
    model: Option<&dyn MotionModel>,
) -> Result<Vec<Vec<Option<Sq>>>, AlgoError> {
    let dim = scene.dim();
    let model = model.expect("checked by the caller");
    let (first, end) = (scene.first(), scene.end());
    let mut out = Vec::with_capacity(scene.nodes()[node].len());
    for track in &scene.nodes()[node] {
        let mut per = vec![None; end - first];
        let mut prev: Option<usize> = None;
        for (k, slot) in (first..end).zip(per.iter_mut()) {
            if !track.is_present(k) {
                continue;
            }
            if let Some(g) = track.gain_factor(k, dim) {
                let mut s = small::ZERO;
                s[..dim * dim].copy_from_slice(g);
                *slot = Some(s);
            } else if let Some(kp) = prev {
                *slot = filter_factor(
                    model,
                    track.x(kp, dim),
                    track.p(kp, dim),
                    track.p(k, dim),
                    scene.time(k) - scene.time(kp),
                )?;
            }
            prev = Some(k);
        }
        out.push(per);
    }
    Ok(out)
}

/// The filter factor A = I − K H of a track at one sample, recovered from
/// its covariances when the gain was not reported: P(k|k) = A P(k|k−1), so
/// A = P(k|k) P(k|k−1)⁻¹ with P(k|k−1) the previous covariance `p_prev`
/// (at state `x_prev`) predicted over `dt`. `None` when the prediction is
/// not positive definite.
pub fn filter_factor(
    model: &dyn MotionModel,
    x_prev: &[f64],
    p_prev: &[f64],
    p_now: &[f64],
    dt: f64,
) -> Result<Option<Sq>, AlgoError> {
    let dim = x_prev.len();
    let x = DVector::from_column_slice(x_prev);
    let p_prev = DMatrix::from_row_slice(dim, dim, p_prev);
    let (_, p_pred) = model.predict(&x, &p_prev, dt)?;
    let p_now = DMatrix::from_row_slice(dim, dim, p_now);
    // A = P(k|k) P⁻¹ = (P⁻¹ P(k|k))' since both are symmetric.
    Ok(p_pred.cholesky().map(|chol| {
        let at = chol.solve(&p_now);
        small::to_sq(&at.transpose())
    }))
}
