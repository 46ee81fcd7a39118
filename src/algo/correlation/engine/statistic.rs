//! The test statistics: weighted α = d'(P_a + P_b)⁻¹d (eq. 10) and modified
//! β with the cross-covariance recursion of eq. 13, the per-pair counters they
//! feed, and the filter factors I − K H the recursion needs. Everything here
//! runs on stack matrices ([`small`]); F and Q are computed once per step
//! length ([`Steps`]) when the model's process noise ignores the state.

use nalgebra::{DMatrix, DVector};

use super::{PairCorrelator, Reason, Sample, Statistic, Status};
use crate::algo::{
    AlgoError,
    correlation::scene::Scene,
    error::check_vector,
    motion::MotionModel,
    small::{self, MAX_DIM, Sq},
};

/// Most step lengths whose F and Q are kept.
const STEPS_KEPT: usize = 64;

/// F(dt) and, when the model's process noise ignores the state, Q(dt), by
/// the bits of dt (`None` when the model refused dt).
#[derive(Default)]
pub(super) struct Steps {
    entries: Vec<(u64, Option<(Sq, Option<Sq>)>)>,
}

impl Steps {
    /// Index of the entry of `dt`, computed on first use.
    fn index(&mut self, model: &dyn MotionModel, dt: f64, dim: usize) -> usize {
        let key = dt.to_bits();
        if let Some(i) = self.entries.iter().position(|e| e.0 == key) {
            return i;
        }
        let value = model.transition(dt).ok().and_then(|f| {
            if model.process_noise_ignores_state() {
                let q = model.process_noise(dt, &DVector::zeros(dim)).ok()?;
                Some((sq_of(&f), Some(sq_of(&q))))
            } else {
                Some((sq_of(&f), None))
            }
        });
        if self.entries.len() == STEPS_KEPT {
            // Irregular instants: forget the oldest step length.
            self.entries.remove(0);
        }
        self.entries.push((key, value));
        self.entries.len() - 1
    }

    /// F(dt) and Q(dt) at `state` (computed when it depends on the state);
    /// `None` when the model refuses dt or the state.
    fn get(
        &mut self,
        model: &dyn MotionModel,
        dt: f64,
        dim: usize,
        state: impl FnOnce() -> DVector<f64>,
    ) -> Option<(&Sq, Sq)> {
        let i = self.index(model, dt, dim);
        let (f, q) = self.entries[i].1.as_ref()?;
        let q = match q {
            Some(q) => *q,
            None => sq_of(&model.process_noise(dt, &state()).ok()?),
        };
        Some((f, q))
    }
}

/// A square matrix in a stack buffer, row-major, without a temporary.
fn sq_of(m: &DMatrix<f64>) -> Sq {
    let n = m.nrows();
    debug_assert!(n <= MAX_DIM && m.ncols() == n);
    let mut s = small::ZERO;
    for i in 0..n {
        for j in 0..n {
            s[i * n + j] = m[(i, j)];
        }
    }
    s
}

/// I − K H of every track of a node at every held instant, flat.
#[derive(Default)]
pub(super) struct Factors {
    instants: usize,
    dim2: usize,
    present: Vec<bool>,
    data: Vec<f64>,
}

impl Factors {
    /// The factor of track `t` at held instant `k` (relative to the
    /// scene's first), if any.
    pub(super) fn get(&self, t: u32, k: usize) -> Option<&[f64]> {
        let i = t as usize * self.instants + k;
        self.present[i].then(|| &self.data[i * self.dim2..(i + 1) * self.dim2])
    }
}

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
        if self.cfg.statistic == Statistic::Modified {
            self.update_cross(pi, k);
        }
        let p = &self.pairs[pi as usize];
        let (d, s) = self.difference(p.a, p.b, k);
        let mut stat = None;
        let mut singular = false;
        if let Some(cross) = &p.cross {
            let mut s_mod = s;
            for i in 0..dim {
                for j in 0..dim {
                    s_mod[i * dim + j] -= cross[i * dim + j] + cross[j * dim + i];
                }
            }
            stat = small::quad_form_inv(&s_mod, &d, dim);
            // P_a + P_b − P_ab − P_ab' is a covariance only when the
            // reported covariances, gains and model are consistent;
            // otherwise fall back to the weighted statistic.
            singular = stat.is_none();
        }
        if singular {
            self.singular_tests += 1;
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
        let p = &mut self.pairs[pi as usize];
        let (a, b, prev) = (p.a, p.b, p.last_common);
        let mut cross = p.cross.take();
        let new = match (prev, &cross) {
            // A last common instant before the held window restarts the
            // recursion from P_ab = 0 (streaming sessions only).
            (Some(kp), Some(c)) if kp >= self.scene.first() => self.propagated(a, b, kp, k, c),
            _ => small::ZERO,
        };
        match &mut cross {
            Some(c) => c.copy_from_slice(&new[..dim * dim]),
            None => cross = Some(new[..dim * dim].into()),
        }
        self.pairs[pi as usize].cross = cross;
    }

    /// A_a(k) [Φ P_ab(kp) Φ' + Q] A_b(k)' for the pair (a, b) whose last
    /// common instant was `kp`; zero when the model refuses the step.
    fn propagated(&mut self, a: u32, b: u32, kp: usize, k: usize, c: &[f64]) -> Sq {
        let dim = self.dim;
        let model = self.model.expect("checked in new");
        let dt = self.scene.time(k) - self.scene.time(kp);
        let (ta, tb) = (
            self.scene.track(self.na, a as usize),
            self.scene.track(self.nb, b as usize),
        );
        let mean = || {
            DVector::from_iterator(
                dim,
                (0..dim).map(|i| 0.5 * (ta.x(kp, dim)[i] + tb.x(kp, dim)[i])),
            )
        };
        let Some((f, q)) = self.steps.get(model, dt, dim, mean) else {
            return small::ZERO;
        };
        let fc = small::mul(f, c, dim);
        let mut mid = small::mul_t(&fc, f, dim);
        for i in 0..dim * dim {
            mid[i] += q[i];
        }
        let first = self.scene.first();
        let left = match self.factors_a.get(a, k - first) {
            Some(fa) => small::mul(fa, &mid, dim),
            None => mid,
        };
        match self.factors_b.get(b, k - first) {
            Some(fb) => small::mul_t(&left, fb, dim),
            None => left,
        }
    }
}

/// I − K H for every track of a node at every instant: reported, or
/// recomputed as P(k|k) P(k|k−1)⁻¹ with P(k|k−1) = Φ P(k⁻|k⁻) Φ' + Q from the
/// track's previous instant k⁻ (for the optimal gain, P(k|k) = (I − K H) P(k|k−1)).
/// None at a track's first instant, where no prediction exists.
pub(super) fn filter_factors(
    scene: &Scene,
    node: usize,
    model: Option<&dyn MotionModel>,
    steps: &mut Steps,
) -> Result<Factors, AlgoError> {
    let dim = scene.dim();
    let model = model.expect("checked by the caller");
    let (first, end) = (scene.first(), scene.end());
    let tracks = &scene.nodes()[node];
    let instants = end - first;
    let mut out = Factors {
        instants,
        dim2: dim * dim,
        present: vec![false; tracks.len() * instants],
        data: vec![0.0; tracks.len() * instants * dim * dim],
    };
    for (t, track) in tracks.iter().enumerate() {
        let mut prev: Option<usize> = None;
        for k in first..end {
            if !track.is_present(k) {
                continue;
            }
            let factor = if let Some(g) = track.gain_factor(k, dim) {
                let mut s = small::ZERO;
                s[..dim * dim].copy_from_slice(g);
                Some(s)
            } else if let Some(kp) = prev {
                let x_prev = track.x(kp, dim);
                let dt = scene.time(k) - scene.time(kp);
                let state = || DVector::from_column_slice(x_prev);
                match steps.get(model, dt, dim, state) {
                    Some((f, q)) => factor_from(f, &q, track.p(kp, dim), track.p(k, dim), dim)?,
                    // The model refuses the step: the error it gives.
                    None => filter_factor(model, x_prev, track.p(kp, dim), track.p(k, dim), dt)?,
                }
            } else {
                None
            };
            if let Some(a) = factor {
                let i = t * instants + (k - first);
                out.present[i] = true;
                out.data[i * dim * dim..(i + 1) * dim * dim].copy_from_slice(&a[..dim * dim]);
            }
            prev = Some(k);
        }
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
    check_vector("state", &x, model.state_dim())?;
    let f = sq_of(&model.transition(dt)?);
    let q = sq_of(&model.process_noise(dt, &x)?);
    factor_from(&f, &q, p_prev, p_now, dim)
}

/// A = P(k|k) P(k|k−1)⁻¹ with P(k|k−1) = F P_prev F' + Q, symmetrised and
/// checked as the Kalman prediction does, on the stack.
fn factor_from(
    f: &Sq,
    q: &Sq,
    p_prev: &[f64],
    p_now: &[f64],
    dim: usize,
) -> Result<Option<Sq>, AlgoError> {
    small::check_covariance("covariance", p_prev, dim)?;
    let fp = small::mul(f, p_prev, dim);
    let mut pred = small::mul_t(&fp, f, dim);
    for i in 0..dim * dim {
        pred[i] += q[i];
    }
    for j in 0..dim {
        for i in j + 1..dim {
            let m = 0.5 * (pred[i * dim + j] + pred[j * dim + i]);
            pred[i * dim + j] = m;
            pred[j * dim + i] = m;
        }
    }
    small::check_covariance("predicted covariance", &pred[..dim * dim], dim)?;
    // A = P(k|k) P⁻¹ = (P⁻¹ P(k|k))' since both are symmetric.
    Ok(small::solve_spd(&pred, p_now, dim).map(|at| small::transpose(&at, dim)))
}
