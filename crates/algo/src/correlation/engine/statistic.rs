//! The test statistics: weighted α = d'(P_a + P_b)⁻¹d (eq. 10) and modified
//! β with the cross-covariance recursion of eq. 13, the per-pair counters they
//! feed, and the filter factors I − K H the recursion needs. Everything here
//! runs on stack matrices ([`small`]); F and Q are computed once per step
//! length ([`Steps`]) when the model's process noise ignores the state.

use nalgebra::DVector;

use super::{PairCorrelator, PairStatus, Reason, Sample, Statistic};
use crate::{
    AlgoError,
    correlation::scene::Scene,
    error::check_vector,
    motion::MotionModel,
    small::{self, MAX_DIM, Sq},
};

/// Most step lengths whose F and Q are kept.
const STEPS_KEPT: usize = 64;

/// F(dt) and, when the model's process noise ignores the state, Q(dt)
/// (row-major), by the bits of dt (`None` when the model refused dt).
#[derive(Default)]
pub(super) struct Steps {
    entries: Vec<(u64, Option<Step>)>,
}

struct Step {
    f: Vec<f64>,
    q: Option<Vec<f64>>,
}

impl Steps {
    /// F(dt) and Q(dt) (Q only when it ignores the state), computed on
    /// first use; `None` when the model refuses dt.
    fn get(
        &mut self,
        model: &dyn MotionModel,
        dt: f64,
        dim: usize,
    ) -> Option<(&[f64], Option<&[f64]>)> {
        let key = dt.to_bits();
        let i = match self.entries.iter().position(|e| e.0 == key) {
            Some(i) => i,
            None => {
                let step = model.transition(dt).ok().and_then(|f| {
                    let q = if model.process_noise_ignores_state() {
                        Some(small::row_major(
                            &model.process_noise(dt, &DVector::zeros(dim)).ok()?,
                        ))
                    } else {
                        None
                    };
                    Some(Step {
                        f: small::row_major(&f),
                        q,
                    })
                });
                if self.entries.len() == STEPS_KEPT {
                    // Irregular instants: forget the oldest step length.
                    self.entries.remove(0);
                }
                self.entries.push((key, step));
                self.entries.len() - 1
            }
        };
        let step = self.entries[i].1.as_ref()?;
        Some((&step.f, step.q.as_deref()))
    }
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
        let scene = self.scene;
        let (ta, tb) = (
            scene.track(self.na, p.a as usize),
            scene.track(self.nb, p.b as usize),
        );
        let (xa, xb) = (ta.x(k, dim), tb.x(k, dim));
        let (pa, pb) = (ta.p(k, dim), tb.p(k, dim));
        let cross = p.cross.as_deref();
        let (stat, singular) = small::by_dim!(
            dim,
            statistic_n(xa, xb, pa, pb, cross),
            unreachable!("the scene checks the dimension")
        );
        if singular {
            // P_a + P_b − P_ab − P_ab' is a covariance only when the
            // reported covariances, gains and model are consistent;
            // otherwise the weighted statistic was used.
            self.singular_tests += 1;
        }
        let posdiff = scene
            .position_indices()
            .iter()
            .map(|&i| (xa[i] - xb[i]) * (xa[i] - xb[i]))
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
            if p.status == PairStatus::Stopped {
                p.status = PairStatus::Testing;
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
            && p.status == PairStatus::Testing
            && p.c > r_final - l_final
        {
            p.status = PairStatus::Stopped;
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
        match (prev, &mut cross) {
            // A last common instant before the held window restarts the
            // recursion from P_ab = 0 (streaming sessions only).
            (Some(kp), Some(c)) if kp >= self.scene.first() => {
                if !self.propagate(a, b, kp, k, c) {
                    c.fill(0.0);
                }
            }
            (_, Some(c)) => c.fill(0.0),
            (_, None) => cross = Some(vec![0.0; dim * dim].into()),
        }
        self.pairs[pi as usize].cross = cross;
    }

    /// P_ab ← A_a(k) [Φ P_ab Φ' + Q] A_b(k)' in place, for the pair (a, b)
    /// whose last common instant was `kp`; false when the model refuses the
    /// step.
    fn propagate(&mut self, a: u32, b: u32, kp: usize, k: usize, c: &mut [f64]) -> bool {
        let dim = self.dim;
        let model = self.model.expect("checked in new");
        let dt = self.scene.time(k) - self.scene.time(kp);
        let (ta, tb) = (
            self.scene.track(self.na, a as usize),
            self.scene.track(self.nb, b as usize),
        );
        let Some((f, q)) = self.steps.get(model, dt, dim) else {
            return false;
        };
        let q_here;
        let q = match q {
            Some(q) => q,
            None => {
                let mean = DVector::from_iterator(
                    dim,
                    (0..dim).map(|i| 0.5 * (ta.x(kp, dim)[i] + tb.x(kp, dim)[i])),
                );
                match model.process_noise(dt, &mean) {
                    Ok(q) => {
                        q_here = small::row_major(&q);
                        &q_here
                    }
                    Err(_) => return false,
                }
            }
        };
        let first = self.scene.first();
        let fa = self.factors_a.get(a, k - first);
        let fb = self.factors_b.get(b, k - first);
        small::by_dim!(
            dim,
            cross_step_n(f, q, fa, fb, c),
            unreachable!("the scene checks the dimension")
        );
        true
    }
}

/// The test statistic of one pair at one instant and whether the modified
/// S = P_a + P_b − P_ab − P_ab' was not positive definite (then the weighted
/// statistic is used); ∞ when neither S is positive definite.
#[allow(clippy::needless_range_loop)] // index form of the matrix algebra
fn statistic_n<const N: usize>(
    xa: &[f64],
    xb: &[f64],
    pa: &[f64],
    pb: &[f64],
    cross: Option<&[f64]>,
) -> (f64, bool) {
    let mut d = [0.0; N];
    for i in 0..N {
        d[i] = xa[i] - xb[i];
    }
    let mut s = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..N {
            s[i][j] = pa[i * N + j] + pb[i * N + j];
        }
    }
    let mut singular = false;
    if let Some(c) = cross {
        let mut s_mod = s;
        for i in 0..N {
            for j in 0..N {
                s_mod[i][j] -= c[i * N + j] + c[j * N + i];
            }
        }
        if let Some(q) = small::quad_form_inv_n::<N>(s_mod.as_flattened(), &d) {
            return (q, false);
        }
        singular = true;
    }
    let stat = small::quad_form_inv_n::<N>(s.as_flattened(), &d).unwrap_or(f64::INFINITY);
    (stat, singular)
}

/// c ← A_a [F c F' + Q] A_b' (each factor only when known).
#[allow(clippy::needless_range_loop)] // index form of the matrix algebra
fn cross_step_n<const N: usize>(
    f: &[f64],
    q: &[f64],
    fa: Option<&[f64]>,
    fb: Option<&[f64]>,
    c: &mut [f64],
) {
    let fc = small::mul_n::<N>(f, c);
    let mut mid = small::mul_t_n::<N>(fc.as_flattened(), f);
    for i in 0..N {
        for j in 0..N {
            mid[i][j] += q[i * N + j];
        }
    }
    let left = match fa {
        Some(fa) => small::mul_n::<N>(fa, mid.as_flattened()),
        None => mid,
    };
    let out = match fb {
        Some(fb) => small::mul_t_n::<N>(left.as_flattened(), fb),
        None => left,
    };
    c.copy_from_slice(out.as_flattened());
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
            let i = t * instants + (k - first);
            let slot = &mut out.data[i * dim * dim..(i + 1) * dim * dim];
            if let Some(g) = track.gain_factor(k, dim) {
                slot.copy_from_slice(g);
                out.present[i] = true;
            } else if let Some(kp) = prev {
                let x_prev = track.x(kp, dim);
                let dt = scene.time(k) - scene.time(kp);
                let (p_prev, p_now) = (track.p(kp, dim), track.p(k, dim));
                match steps.get(model, dt, dim) {
                    Some((f, Some(q))) => {
                        small::by_dim!(
                            dim,
                            factor_n(f, q, p_prev, p_now, slot),
                            unreachable!("the scene checks the dimension")
                        )?;
                    }
                    // Q depends on the state, or the model refuses the
                    // step (the error it gives).
                    _ => {
                        let a = filter_factor(model, x_prev, p_prev, p_now, dt)?
                            .expect("an error otherwise");
                        slot.copy_from_slice(&a[..dim * dim]);
                    }
                }
                out.present[i] = true;
            }
            prev = Some(k);
        }
    }
    Ok(out)
}

/// The filter factor A = I − K H of a track at one sample, recovered from
/// its covariances when the gain was not reported: P(k|k) = A P(k|k−1), so
/// A = P(k|k) P(k|k−1)⁻¹ with P(k|k−1) the previous covariance `p_prev`
/// (at state `x_prev`) predicted over `dt`. An error when `p_prev` or the
/// prediction is not a covariance (the result is then always `Some`).
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
    small::check_covariance("covariance", p_prev, dim)?;
    let f = small::row_major(&model.transition(dt)?);
    let q = small::row_major(&model.process_noise(dt, &x)?);
    let mut a = small::ZERO;
    small::by_dim!(
        dim,
        factor_n(&f, &q, p_prev, p_now, &mut a[..dim * dim]),
        unreachable!("the scene checks the dimension")
    )?;
    Ok(Some(a))
}

/// `out` ← P_now P⁻¹ with P = F P_prev F' + Q symmetrised (the Kalman
/// prediction), which must be a covariance.
#[allow(clippy::needless_range_loop)] // index form of the matrix algebra
fn factor_n<const N: usize>(
    f: &[f64],
    q: &[f64],
    p_prev: &[f64],
    p_now: &[f64],
    out: &mut [f64],
) -> Result<(), AlgoError> {
    let fp = small::mul_n::<N>(f, p_prev);
    let mut pred = small::mul_t_n::<N>(fp.as_flattened(), f);
    for i in 0..N {
        for j in 0..N {
            pred[i][j] += q[i * N + j];
        }
    }
    for j in 0..N {
        for i in j + 1..N {
            let m = 0.5 * (pred[i][j] + pred[j][i]);
            pred[i][j] = m;
            pred[j][i] = m;
        }
    }
    let what = "predicted covariance";
    if pred.as_flattened().iter().any(|v| !v.is_finite()) {
        return Err(AlgoError::NonFinite { what });
    }
    let l = small::cholesky_n::<N>(pred.as_flattened())
        .ok_or(AlgoError::NotPositiveDefinite { what })?;
    // A = P(k|k) P⁻¹ = (P⁻¹ P(k|k))' since both are symmetric.
    let at = small::cholesky_solve_n(&l, p_now);
    for i in 0..N {
        for j in 0..N {
            out[i * N + j] = at[j][i];
        }
    }
    Ok(())
}
