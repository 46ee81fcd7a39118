//! Logic-based track initiation (seed 001 step 7, 7a–7c).
//!
//! Frames are the tracker's processing frames (a radar scan group in
//! serial mode, a fusion instant in parallel mode); only plots that fell in
//! no confirmed track's gate reach the initiator. Per frame:
//!
//! 1. (7b) Every tentative track is predicted to the frame and takes the
//!    nearest plot inside its χ² gate ν′(H P H′ + R)⁻¹ν ≤ γ; competing
//!    tentatives are resolved by global nearest neighbour
//!    ([`assignment::solve`] on d²/γ). A hit is a linear Kalman update.
//! 2. (7c) A tentative with ≥ M hits among its last N frames is confirmed;
//!    one with more than N − M misses among them can no longer be and is
//!    dropped. Its first two plots count as two hits.
//! 3. (7a) Roots (unused plots of earlier frames, at most `max_dt` old) are
//!    paired with this frame's free plots at least `min_dt` later that pass
//!    the velocity gate: with Δ = z_j − z_i over the axes both plots have,
//!    d is the part of Δ outside the allowed displacement
//!    ([v_min Δt, v_max Δt] on |Δ| for a speed band, per component for
//!    per-axis bands, signed), and the pair passes when
//!    D = d′(R_i + R_j)⁻¹d ≤ γ (χ² with p degrees of freedom). This is the
//!    patent's reading: "the gate restricts the speed to [v_min, v_max],
//!    R expressing the tolerated position error". The patent sums two
//!    non-negative max terms per component; the signed excess used here
//!    gives the same D for uncorrelated components. Every passing pair
//!    starts a tentative track by two-point initialisation in Cartesian
//!    coordinates: x = z_j, v = (z_j − z_i)/Δt, P = [[R_j, R_j/Δt],
//!    [R_j/Δt, (R_i + R_j)/Δt²]] per axis pair (seed 000 eq. 30 with
//!    R_i ≠ R_j). In a 3D tracker a 2D plot is given the configured
//!    default height and its σ first.
//! 4. Paired roots are consumed; plots used by neither a tentative nor a
//!    pair become roots.

use nalgebra::{DMatrix, DVector};

use crate::assignment;
use crate::error::AlgoError;
use crate::gaussian::{mahalanobis_sq, symmetrize};
use crate::kalman;
use crate::tracking::config::{Plot, RadarSpec};
use crate::tracking::config::{TrackerConfig, VelocityGate};
use crate::tracking::conversion::CartesianPlot;
use crate::tracking::hypothesiser::{Grid, TrackIndex, swap_remove_all};
use crate::tracking::identity::{TrackIdentity, is_mode_s, without_mode_s};
use crate::tracking::predictor::ModeState;
use crate::tracking::retrodiction::{Retro, carry, retrodict};
use crate::tracking::sweep::View;
use crate::tracking::track::{Prediction, Track, chi2_gates, position_selector, predict};
use crate::tracking::{FailedStep, TrackFailure};

/// Roots and tentative tracks, carried between frames.
#[derive(Debug, Clone, Default)]
pub(crate) struct Initiator {
    /// Unused plots of earlier frames, in time order. Within a call of
    /// the tracker, roots that expired or were paired are only flagged
    /// (`dead`); [`Initiator::compact`] removes them.
    pub roots: Vec<CartesianPlot>,
    pub tentatives: Vec<Track>,
    /// Per root, paired or expired (empty: none). Derived.
    dead: Vec<bool>,
    dead_count: usize,
    /// Roots before this index are known expired. Derived.
    expired: usize,
    /// The roots by position (slots = indices in `roots`). Derived.
    root_grid: RootGrid,
    /// The tentative tracks by position. Derived.
    pub(crate) index: TrackIndex,
}

/// The roots' grid and the largest trace of a root's covariance.
#[derive(Debug, Clone, Default)]
struct RootGrid {
    grid: Grid,
    max_trace: f64,
}

impl PartialEq for Initiator {
    /// The live roots and the tentatives (derived data and flagged roots
    /// not yet removed aside).
    fn eq(&self, other: &Self) -> bool {
        self.tentatives == other.tentatives && self.live_roots().eq(other.live_roots())
    }
}

impl PartialEq for RootGrid {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// What one frame of initiation did.
#[derive(Debug, Default)]
pub(crate) struct Initiated {
    /// Tentative tracks that reached M of N (removed from the initiator).
    pub confirmed: Vec<Track>,
    /// Number of tentative tracks dropped.
    pub dropped: usize,
    /// Number of tentative tracks started.
    pub started: usize,
    /// Starts refused: the tracker held its bound of tracks.
    pub refused: usize,
    /// Tentative tracks whose numbers failed (prediction, gating or
    /// update), dropped (counted in `dropped`).
    pub failed: Vec<TrackFailure>,
}

/// How a frame treats the tentative tracks no plot extends.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Misses {
    /// Every tentative is predicted to the frame, and a miss is counted
    /// where the view says (parallel mode: every instant judges all).
    Judge(View),
    /// Only the tentatives a plot may extend are predicted; misses are
    /// judged apart, from the beam ([`Initiator::judge`]).
    Lazy,
}

impl Initiator {
    /// Removes the roots flagged dead (keeping the order) and rebuilds
    /// the roots' grid.
    pub(crate) fn compact(&mut self) {
        if self.dead_count > 0 {
            let mut dead = self.dead.iter();
            self.roots
                .retain(|_| !*dead.next().expect("one flag per root"));
        }
        self.dead.clear();
        self.dead_count = 0;
        self.expired = 0;
        self.root_grid.grid.invalidate();
    }

    /// The roots not flagged dead.
    pub(crate) fn live_roots(&self) -> impl Iterator<Item = &CartesianPlot> {
        self.roots
            .iter()
            .enumerate()
            .filter(|(i, _)| !self.is_dead(*i))
            .map(|(_, r)| r)
    }

    /// An initiator of these roots and tentatives.
    pub(crate) fn from_parts(roots: Vec<CartesianPlot>, tentatives: Vec<Track>) -> Self {
        Self {
            roots,
            tentatives,
            ..Self::default()
        }
    }

    fn refresh_roots(&mut self) {
        if self.root_grid.grid.is_valid() {
            return;
        }
        self.root_grid.grid.clear();
        self.root_grid.max_trace = 0.0;
        for (i, r) in self.roots.iter().enumerate() {
            self.root_grid.grid.set(i, r.z[0], r.z[1]);
            self.root_grid.max_trace = self.root_grid.max_trace.max(r.r.trace());
        }
    }

    fn kill_root(&mut self, i: usize) {
        if self.dead.len() < self.roots.len() {
            self.dead.resize(self.roots.len(), false);
        }
        if !self.dead[i] {
            self.dead[i] = true;
            self.dead_count += 1;
        }
    }

    fn is_dead(&self, i: usize) -> bool {
        self.dead.get(i).copied().unwrap_or(false)
    }

    /// One frame at time `t` with the plots no confirmed track used;
    /// `room`: most tracks it may start; `mode_s`: per radar, whether it
    /// gives Mode S addresses (the tracker's frame context, passed whole).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn step(
        &mut self,
        t: f64,
        plots: Vec<CartesianPlot>,
        cfg: &TrackerConfig,
        misses: Misses,
        next_id: &mut u64,
        room: usize,
        mode_s: &[bool],
    ) -> Result<Initiated, AlgoError> {
        let init = &cfg.initiation;
        let gates = chi2_gates(init.gate_probability)?;
        let mut out = Initiated::default();
        let mut taken = vec![false; plots.len()];

        // 7b: extend the tentative tracks (those a plot may reach, when
        // misses are judged apart), each predicted to the frame.
        let lazy = matches!(misses, Misses::Lazy);
        let slots: Vec<usize> = if lazy {
            if plots.is_empty() {
                Vec::new()
            } else {
                self.index.candidates(&self.tentatives, &plots, t, cfg)?
            }
        } else {
            (0..self.tentatives.len()).collect()
        };
        let mut predicted = Vec::with_capacity(slots.len());
        // Per candidate newer than the frame (an out-of-sequence plot):
        // what carries its update back to its time.
        let mut retros: Vec<Option<Retro>> = Vec::with_capacity(slots.len());
        let mut edges = Vec::new();
        // The candidates predicted and gated (a tentative whose numbers
        // fail there is dropped: `failed`, slots).
        let mut kept = Vec::with_capacity(slots.len());
        let mut failed = Vec::new();
        for &i in &slots {
            let c = kept.len();
            match self.predict_and_gate(i, t, (&plots, &gates), cfg, mode_s, c, &mut edges) {
                Ok((x, p, retro)) => {
                    predicted.push((x, p));
                    retros.push(retro);
                    kept.push(i);
                }
                Err(e) => failed.push((i, e)),
            }
        }
        let slots = kept;
        let mut hit = vec![None; slots.len()];
        for (c, j) in assignment::solve(&edges, 1.0 + 1e-12) {
            hit[c] = Some(j);
            taken[j] = true;
        }
        // The tentatives whose life this frame recorded.
        let mut touched = Vec::new();
        for (((&i, hit), (x, p)), retro) in slots.iter().zip(hit).zip(predicted).zip(retros) {
            if let Some(retro) = retro {
                // An older plot: its update at t carried to the track's
                // time (no miss judged: a later frame did that).
                if let Some(j) = hit {
                    let plot = &plots[j];
                    let h = position_selector(plot.z.len(), cfg.axes);
                    let track = &mut self.tentatives[i];
                    let carried =
                        kalman::update_linear(&x, &p, &plot.z, &h, &plot.r).and_then(|u| {
                            let up = [ModeState {
                                probability: 1.0,
                                x: u.x,
                                p: u.p,
                            }];
                            carry(track, &retro, &up)
                        });
                    if let Err(e) = carried {
                        failed.push((i, e));
                        continue;
                    }
                    track.record_late_hit(false);
                    track
                        .identity
                        .observe_measured(plot.measured.as_ref(), mode_s);
                    self.index.moved(i, track);
                    touched.push(i);
                }
                continue;
            }
            if lazy && hit.is_none() {
                continue;
            }
            let track = &mut self.tentatives[i];
            track.x = x;
            track.p = p;
            track.t = t;
            match hit {
                Some(j) => {
                    let plot = &plots[j];
                    let h = position_selector(plot.z.len(), cfg.axes);
                    let u = match kalman::update_linear(&track.x, &track.p, &plot.z, &h, &plot.r) {
                        Ok(u) => u,
                        Err(e) => {
                            failed.push((i, e));
                            continue;
                        }
                    };
                    track.x = u.x;
                    track.p = u.p;
                    track.record(Some(plot.radars.clone()));
                    track.hit_by_plot(plot, &cfg.radars);
                    track.last_plot = plot.measured;
                    track
                        .identity
                        .observe_measured(plot.measured.as_ref(), mode_s);
                }
                None => {
                    if let Misses::Judge(view) = misses {
                        if view.misses(&track.x, track.last_update) {
                            track.record(None);
                        }
                    }
                }
            }
            self.index.moved(i, track);
            touched.push(i);
        }

        // 7a: pair the roots with the free plots (roots within reach of a
        // plot found by the roots' grid; pairs in root-then-plot order).
        self.refresh_roots();
        let v_reach = match init.velocity {
            VelocityGate::Speed { v_max, .. } => v_max,
            VelocityGate::PerAxis { v_min, v_max } => {
                2.0 * (0..3)
                    .map(|i| v_min[i].abs().max(v_max[i].abs()).powi(2))
                    .sum::<f64>()
                    .sqrt()
            }
        };
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        let mut near = Vec::new();
        for (j, plot) in plots.iter().enumerate() {
            if taken[j] {
                continue;
            }
            let radius = 2.0
                * (v_reach * init.max_dt
                    + (gates[1] * (plot.r.trace() + self.root_grid.max_trace)).sqrt())
                + 1.0;
            near.clear();
            self.root_grid
                .grid
                .within(plot.z[0], plot.z[1], radius, &mut near);
            pairs.extend(near.iter().map(|&i| (i as usize, j)));
        }
        pairs.sort_unstable();
        let mut paired_plot = vec![false; plots.len()];
        let mut paired_roots = Vec::new();
        let first_new = self.tentatives.len();
        for (i, j) in pairs {
            if self.is_dead(i) {
                continue;
            }
            // The earlier and the later plot of the pair: a root newer
            // than the frame (an out-of-sequence plot's) is the later.
            let (early, late, at) = if self.roots[i].t <= t {
                (&self.roots[i], &plots[j], t)
            } else {
                (&plots[j], &self.roots[i], self.roots[i].t)
            };
            let dt = if at == t { t - early.t } else { at - t };
            if dt < init.min_dt || dt > init.max_dt || !roots_fit(early, late, dt, mode_s) {
                continue;
            }
            let k = early.z.len().min(late.z.len());
            if velocity_bound(early, late, dt, &init.velocity) > gates[k - 2] {
                continue;
            }
            if velocity_statistic(early, late, dt, &init.velocity)? <= gates[k - 2] {
                if out.started >= room {
                    out.refused += 1;
                    continue;
                }
                let state = two_point(early, late, dt, cfg);
                let track = new_tentative(next_id, state, at, early, late, &cfg.radars, mode_s);
                self.index.moved(self.tentatives.len(), &track);
                self.tentatives.push(track);
                out.started += 1;
                paired_plot[j] = true;
                paired_roots.push(i);
            }
        }
        // A root pairs with every plot it passes with, then is consumed;
        // roots older than max_dt expire (they are in time order).
        for i in paired_roots {
            self.kill_root(i);
        }
        while self.expired < self.roots.len() && t - self.roots[self.expired].t > init.max_dt {
            self.kill_root(self.expired);
            self.expired += 1;
        }
        for (j, plot) in plots.into_iter().enumerate() {
            if !taken[j] && !paired_plot[j] {
                let i = self.roots.len();
                self.root_grid.grid.set(i, plot.z[0], plot.z[1]);
                self.root_grid.max_trace = self.root_grid.max_trace.max(plot.r.trace());
                self.roots.push(plot);
                if !self.dead.is_empty() {
                    self.dead.push(false);
                }
            }
        }
        if self.dead_count > 64 && 2 * self.dead_count > self.roots.len() {
            self.compact();
        }

        // 7c: confirm or drop the tentatives this frame recorded (the
        // ones created now have two hits of at most N).
        let judged = if lazy {
            touched.extend(first_new..self.tentatives.len());
            touched
        } else {
            (0..self.tentatives.len()).collect()
        };
        let mut gone = Vec::new();
        let mut failed_slots: Vec<usize> = failed.iter().map(|f| f.0).collect();
        failed_slots.sort_unstable();
        for (i, error) in failed {
            out.failed.push(self.failure(i, t, error));
            gone.push((i, false));
        }
        for i in judged {
            if failed_slots.binary_search(&i).is_ok() {
                continue;
            }
            match self.verdict(i, cfg) {
                Verdict::Confirm => gone.push((i, true)),
                Verdict::Drop => gone.push((i, false)),
                Verdict::Keep => {}
            }
        }
        self.remove(gone, &mut out);
        Ok(out)
    }

    /// Tentative `i` predicted to the frame at `t` (or retrodicted there,
    /// with what carries its update back), its gated pairs with the
    /// frame's plots pushed to `edges` as candidate `c`. Fails when a
    /// number of the tentative does (then no edge of it is pushed).
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn predict_and_gate(
        &self,
        i: usize,
        t: f64,
        (plots, gates): (&[CartesianPlot], &[f64]),
        cfg: &TrackerConfig,
        mode_s: &[bool],
        c: usize,
        edges: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(DVector<f64>, DMatrix<f64>, Option<Retro>), AlgoError> {
        let track = &self.tentatives[i];
        let (x, p, retro) = if track.t > t {
            let mut pred = Prediction::default();
            let retro = retrodict(cfg, track, t, &mut pred)?;
            (pred.x, pred.p, Some(retro))
        } else {
            let (x, p) = predict(&track.x, &track.p, t - track.t, &cfg.sigma_a, cfg.noise)?;
            (x, p, None)
        };
        let first = edges.len();
        for (j, plot) in plots.iter().enumerate() {
            if !identity_fits(&track.identity, plot, mode_s) {
                continue;
            }
            let k = plot.z.len();
            // Exact pruning: ν'S⁻¹ν ≥ ν_0²/S_00 for any S > 0.
            let nu0 = plot.z[0] - x[0];
            if nu0 * nu0 > gates[k - 2] * (p[(0, 0)] + plot.r[(0, 0)]) {
                continue;
            }
            let h = position_selector(k, cfg.axes);
            let s = &h * &p * h.transpose() + &plot.r;
            match mahalanobis_sq(&(&plot.z - &h * &x), &s) {
                Ok(d2) if d2 <= gates[k - 2] => edges.push((c, j, d2 / gates[k - 2])),
                Ok(_) => {}
                Err(e) => {
                    edges.truncate(first);
                    return Err(e);
                }
            }
        }
        Ok((x, p, retro))
    }

    /// The report of tentative `i`, whose numbers failed at `t` (dropped).
    fn failure(&self, i: usize, t: f64, error: AlgoError) -> TrackFailure {
        TrackFailure {
            id: self.tentatives[i].id,
            confirmed: false,
            t,
            step: FailedStep::Initiate,
            error,
        }
    }

    /// Whether tentative `i` is confirmed, dropped or kept (7c).
    fn verdict(&self, i: usize, cfg: &TrackerConfig) -> Verdict {
        let (m, n) = (cfg.initiation.confirm_m, cfg.initiation.confirm_n);
        let track = &self.tentatives[i];
        if track.hits_in_last(n) >= m {
            Verdict::Confirm
        } else if track.misses_in_last(n) > n - m {
            Verdict::Drop
        } else {
            Verdict::Keep
        }
    }

    /// Removes tentatives (slot, confirmed), the confirmed ones into `out`
    /// by ascending slot (the others take their places: `swap_remove`).
    fn remove(&mut self, gone: Vec<(usize, bool)>, out: &mut Initiated) {
        if gone.is_empty() {
            return;
        }
        let confirmed: std::collections::HashSet<usize> =
            gone.iter().filter(|g| g.1).map(|g| g.0).collect();
        let slots = gone.into_iter().map(|g| g.0).collect();
        let (removed, _) = swap_remove_all(&mut self.tentatives, slots, &mut self.index);
        for (slot, track) in removed {
            if confirmed.contains(&slot) {
                out.confirmed.push(track);
            } else {
                out.dropped += 1;
            }
        }
    }

    /// Misses judged from the beam (serial mode): every tentative `judge`
    /// says missed the sweep is predicted to `t` and gets a miss; those
    /// that can no longer be confirmed are dropped.
    /// A tentative whose prediction fails is dropped (`out.failed`).
    pub(crate) fn judge(
        &mut self,
        t: f64,
        cfg: &TrackerConfig,
        judge: &dyn Fn(&Track) -> bool,
        out: &mut Initiated,
    ) {
        let mut gone = Vec::new();
        for i in 0..self.tentatives.len() {
            if !judge(&self.tentatives[i]) {
                continue;
            }
            let track = &mut self.tentatives[i];
            if track.t <= t {
                if let Err(error) = track.predict(t, &cfg.sigma_a, cfg.noise) {
                    out.failed.push(self.failure(i, t, error));
                    gone.push((i, false));
                    continue;
                }
            }
            track.record(None);
            self.index.moved(i, &self.tentatives[i]);
            if let Verdict::Drop = self.verdict(i, cfg) {
                gone.push((i, false));
            }
        }
        self.remove(gone, out);
    }
}

enum Verdict {
    Confirm,
    Drop,
    Keep,
}

/// A lower bound of [`velocity_statistic`] without allocation, for
/// pruning: D = d'S⁻¹d ≥ |d|²/λ_max(S) ≥ |d|²/tr(S), and per axis
/// D ≥ d_i²/S_ii.
pub fn velocity_bound(a: &CartesianPlot, b: &CartesianPlot, dt: f64, gate: &VelocityGate) -> f64 {
    let k = a.z.len().min(b.z.len());
    match *gate {
        VelocityGate::Speed { v_min, v_max } => {
            let mut s2 = 0.0;
            let mut trace = 0.0;
            for i in 0..k {
                let d = b.z[i] - a.z[i];
                s2 += d * d;
                trace += a.r[(i, i)] + b.r[(i, i)];
            }
            let s = s2.sqrt();
            let excess = if s > v_max * dt {
                s - v_max * dt
            } else if s < v_min * dt {
                v_min * dt - s
            } else {
                0.0
            };
            excess * excess / trace
        }
        VelocityGate::PerAxis { v_min, v_max } => (0..k)
            .map(|i| {
                let delta = b.z[i] - a.z[i];
                let d = (delta - v_max[i] * dt).max(0.0) - (v_min[i] * dt - delta).max(0.0);
                d * d / (a.r[(i, i)] + b.r[(i, i)])
            })
            .fold(0.0, f64::max),
    }
}

/// D = d′(R_i + R_j)⁻¹d of the velocity gate (see the module header).
pub fn velocity_statistic(
    a: &CartesianPlot,
    b: &CartesianPlot,
    dt: f64,
    gate: &VelocityGate,
) -> Result<f64, AlgoError> {
    let k = a.z.len().min(b.z.len());
    let delta = DVector::from_fn(k, |i, _| b.z[i] - a.z[i]);
    let d = match *gate {
        VelocityGate::Speed { v_min, v_max } => {
            let s = delta.norm();
            let (lo, hi) = (v_min * dt, v_max * dt);
            let excess = if s > hi {
                s - hi
            } else if s < lo {
                s - lo
            } else {
                0.0
            };
            if s > 0.0 {
                &delta * (excess / s)
            } else {
                DVector::from_fn(k, |i, _| if i == 0 { excess } else { 0.0 })
            }
        }
        VelocityGate::PerAxis { v_min, v_max } => DVector::from_fn(k, |i, _| {
            let (lo, hi) = (v_min[i] * dt, v_max[i] * dt);
            (delta[i] - hi).max(0.0) - (lo - delta[i]).max(0.0)
        }),
    };
    let mut s = DMatrix::from_fn(k, k, |i, j| a.r[(i, j)] + b.r[(i, j)]);
    symmetrize(&mut s);
    mahalanobis_sq(&d, &s)
}

/// Two-point initialisation from plots `a` then `b`, `dt` apart.
fn two_point(
    a: &CartesianPlot,
    b: &CartesianPlot,
    dt: f64,
    cfg: &TrackerConfig,
) -> (DVector<f64>, DMatrix<f64>) {
    let (za, ra) = lift(a, cfg);
    let (zb, rb) = lift(b, cfg);
    let n = cfg.axes;
    let mut x = DVector::zeros(2 * n);
    let mut p = DMatrix::zeros(2 * n, 2 * n);
    for i in 0..n {
        x[2 * i] = zb[i];
        x[2 * i + 1] = (zb[i] - za[i]) / dt;
        for j in 0..n {
            p[(2 * i, 2 * j)] = rb[(i, j)];
            p[(2 * i, 2 * j + 1)] = rb[(i, j)] / dt;
            p[(2 * i + 1, 2 * j)] = rb[(i, j)] / dt;
            p[(2 * i + 1, 2 * j + 1)] = (ra[(i, j)] + rb[(i, j)]) / (dt * dt);
        }
    }
    symmetrize(&mut p);
    (x, p)
}

/// A plot's position in the tracker's axes: a 2D plot in a 3D tracker at
/// the default height (independent σ), a 3D plot in a 2D tracker marginalised.
fn lift(plot: &CartesianPlot, cfg: &TrackerConfig) -> (DVector<f64>, DMatrix<f64>) {
    let n = cfg.axes;
    let k = plot.z.len();
    let mut z = DVector::from_element(n, cfg.default_height);
    let mut r = DMatrix::zeros(n, n);
    for i in 0..n {
        if i < k {
            z[i] = plot.z[i];
            for j in 0..n.min(k) {
                r[(i, j)] = plot.r[(i, j)];
            }
        } else {
            r[(i, i)] = cfg.default_height_sigma.powi(2);
        }
    }
    (z, r)
}

fn new_tentative(
    next_id: &mut u64,
    (x, p): (DVector<f64>, DMatrix<f64>),
    t: f64,
    root: &CartesianPlot,
    plot: &CartesianPlot,
    radars_spec: &[RadarSpec],
    mode_s: &[bool],
) -> Track {
    let id = *next_id;
    *next_id += 1;
    let mut radars = root.radars.clone();
    radars.extend(&plot.radars);
    radars.sort_unstable();
    radars.dedup();
    let mut track = Track {
        id,
        x,
        p,
        t,
        history: 0b11,
        age: 2,
        hits: 2,
        misses: 0,
        consecutive_misses: 0,
        radars,
        last_update: t,
        modes: Vec::new(),
        started: Some(root.t),
        last_plot: plot.measured,
        identity: {
            let mut identity = TrackIdentity::default();
            identity.observe_measured(root.measured.as_ref(), mode_s);
            identity.observe_measured(plot.measured.as_ref(), mode_s);
            identity
        },
        detections: Vec::new(),
    };
    track.hit_by_plot(root, radars_spec);
    track.hit_by_plot(plot, radars_spec);
    track
}

/// Whether a plot may extend a tentative track: not another Mode S
/// address than the track's, and not a Mode A/C-only aircraft's reply to
/// a Mode S radar against a track with an address, nor the reverse.
fn identity_fits(track: &TrackIdentity, plot: &CartesianPlot, mode_s: &[bool]) -> bool {
    let Some(m) = plot.measured else {
        return true;
    };
    match (track.address, m.identity.address) {
        (Some(a), Some(b)) => a.value == b,
        (Some(_), None) => !without_mode_s(&m.identity, is_mode_s(mode_s, m.radar)),
        (None, Some(_)) => track.last_mode_ac.is_none(),
        (None, None) => true,
    }
}

/// Whether two plots `dt` apart may be one aircraft's by what they say of
/// it: not two Mode S addresses, and not a climb or descent faster than
/// [`MAX_VERTICAL_RATE_FTPS`] between two validated Mode C values.
fn roots_fit(a: &CartesianPlot, b: &CartesianPlot, dt: f64, mode_s: &[bool]) -> bool {
    let (Some(a), Some(b)) = (a.measured, b.measured) else {
        return true;
    };
    if !TrackIdentity::compatible(&a.identity, &b.identity) {
        return false;
    }
    // A Mode S address and a Mode S radar's reply without one: two
    // aircraft.
    let no_address = |p: &Plot| without_mode_s(&p.identity, is_mode_s(mode_s, p.radar));
    if (a.identity.address.is_some() && no_address(&b))
        || (b.identity.address.is_some() && no_address(&a))
    {
        return false;
    }
    let valid =
        |c: Option<crate::tracking::identity::ModeC>| c.filter(|c| c.validated && !c.garbled);
    match (valid(a.identity.mode_c), valid(b.identity.mode_c)) {
        (Some(x), Some(y)) => {
            // Both quantised to at most 100 ft: allow one quantum each.
            (x.flight_level - y.flight_level).abs() * 100.0
                <= MAX_VERTICAL_RATE_FTPS * dt.abs() + 200.0
        }
        _ => true,
    }
}

/// The fastest climb or descent two plots of one aircraft may show
/// (ft/s): 10,000 ft/min.
const MAX_VERTICAL_RATE_FTPS: f64 = 10_000.0 / 60.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracking::config::RadarSpec;
    use crate::tracking::identity::{Detection, Identity, Mode3A};
    use crate::tracking::tests::Lcg;
    use nalgebra::dvector;

    fn cfg() -> TrackerConfig {
        let radar = RadarSpec {
            site: [0.0; 3],
            sigma_range: 10.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: None,
            sigma_radial_velocity: None,
            scan_period: 1.0,
            detection_probability: 1.0,
            clutter_density: 1e-6,
        };
        let mut c = TrackerConfig::new(2, vec![radar]);
        c.initiation.velocity = VelocityGate::Speed {
            v_min: 0.0,
            v_max: 50.0,
        };
        c.initiation.min_dt = 0.5;
        c.initiation.max_dt = 2.0;
        c.sigma_a = [0.1; 3];
        c
    }

    fn plot(t: f64, x: f64, y: f64) -> CartesianPlot {
        CartesianPlot {
            t,
            z: dvector![x, y],
            r: DMatrix::from_diagonal(&dvector![1.0, 1.0]),
            radars: vec![0],
            measured: None,
            range_rates: Vec::new(),
            velocity: Vec::new(),
        }
    }

    #[test]
    fn a_straight_target_confirms_at_the_third_scan_with_3_of_4() {
        // Scan 1: root (1 hit). Scan 2: pair → tentative with 2 hits.
        // Scan 3: gated hit → 3 hits among the last 4 frames → confirmed.
        let c = cfg();
        let mut ini = Initiator::default();
        let mut id = 7;
        let mut confirmed_at = None;
        for k in 0..5 {
            let t = k as f64;
            let out = ini
                .step(
                    t,
                    vec![plot(t, 10.0 * t, 100.0)],
                    &c,
                    Misses::Judge(View::All),
                    &mut id,
                    usize::MAX,
                    &[],
                )
                .unwrap();
            if k == 1 {
                assert_eq!(out.started, 1);
                assert_eq!(ini.tentatives.len(), 1);
                // Two-point init: x = z₂, v = (z₂ − z₁)/1 = (10, 0), P_vv = (1 + 1)/1.
                let tr = &ini.tentatives[0];
                assert_eq!(tr.x, dvector![10.0, 10.0, 100.0, 0.0]);
                assert_eq!(tr.p[(1, 1)], 2.0);
                assert_eq!(tr.p[(0, 1)], 1.0);
            }
            if !out.confirmed.is_empty() {
                assert!(confirmed_at.is_none());
                confirmed_at = Some(k);
                assert_eq!(out.confirmed[0].id, 7);
                assert_eq!(out.confirmed[0].hits, 3);
            }
        }
        assert_eq!(confirmed_at, Some(2));
    }

    /// A plot at `(10 t, 100)` from radar 0 with a secondary reply.
    fn reply(t: f64, identity: Identity) -> CartesianPlot {
        let mut p = plot(t, 10.0 * t, 100.0);
        p.measured = Some(Plot {
            radar: 0,
            t,
            range: 100.0,
            azimuth: 0.0,
            elevation: None,
            radial_velocity: None,
            identity,
            report: None,
        });
        p
    }

    /// A Mode S radar's replies without an address (a Mode A/C
    /// transponder squawking 7000) start a tentative track; a reply with
    /// an address exactly where that track predicts is another aircraft's
    /// and does not extend it (it waits as a root), while from a radar
    /// that gives no addresses the same replies make one track.
    #[test]
    fn a_mode_a_c_tentative_does_not_take_a_mode_s_reply() {
        let mode_a = Identity {
            mode_3a: Some(Mode3A {
                code: 0o7000,
                validated: true,
                garbled: false,
            }),
            detection: Some(Detection::Secondary),
            ..Identity::default()
        };
        let mode_s = Identity {
            address: Some(0x394A0A),
            ..mode_a
        };
        let c = cfg();
        for radar_gives_addresses in [true, false] {
            let flags = [radar_gives_addresses];
            let mut ini = Initiator::default();
            let mut id = 0;
            let mut step = |ini: &mut Initiator, t: f64, identity: Identity| {
                ini.step(
                    t,
                    vec![reply(t, identity)],
                    &c,
                    Misses::Judge(View::All),
                    &mut id,
                    usize::MAX,
                    &flags,
                )
                .unwrap()
            };
            step(&mut ini, 0.0, mode_a);
            assert_eq!(step(&mut ini, 1.0, mode_a).started, 1);
            assert_eq!(
                ini.tentatives[0].identity.last_mode_ac.is_some(),
                radar_gives_addresses
            );
            let out = step(&mut ini, 2.0, mode_s);
            if radar_gives_addresses {
                assert!(out.confirmed.is_empty());
                assert_eq!(ini.tentatives[0].hits, 2);
                assert_eq!(ini.live_roots().count(), 1);
            } else {
                assert_eq!(out.confirmed.len(), 1);
                assert_eq!(out.confirmed[0].identity.address.unwrap().value, 0x394A0A);
            }
        }
    }

    #[test]
    fn misses_drop_a_tentative_that_cannot_reach_m() {
        // Root, pair (2 hits), then two empty frames: misses 2 > N − M = 1 → dropped.
        let c = cfg();
        let mut ini = Initiator::default();
        let mut id = 0;
        ini.step(
            0.0,
            vec![plot(0.0, 0.0, 0.0)],
            &c,
            Misses::Judge(View::All),
            &mut id,
            usize::MAX,
            &[],
        )
        .unwrap();
        ini.step(
            1.0,
            vec![plot(1.0, 10.0, 0.0)],
            &c,
            Misses::Judge(View::All),
            &mut id,
            usize::MAX,
            &[],
        )
        .unwrap();
        let a = ini
            .step(
                2.0,
                vec![],
                &c,
                Misses::Judge(View::All),
                &mut id,
                usize::MAX,
                &[],
            )
            .unwrap();
        assert_eq!((a.dropped, ini.tentatives.len()), (0, 1));
        let b = ini
            .step(
                3.0,
                vec![],
                &c,
                Misses::Judge(View::All),
                &mut id,
                usize::MAX,
                &[],
            )
            .unwrap();
        assert_eq!((b.dropped, ini.tentatives.len()), (1, 0));
    }

    #[test]
    fn the_velocity_gate_rejects_pairs_outside_the_speed_band() {
        // 1000 m in 1 s with v_max = 50: excess 950 m, D = 950²/2 ≫ γ.
        let g = VelocityGate::Speed {
            v_min: 0.0,
            v_max: 50.0,
        };
        let d = velocity_statistic(&plot(0.0, 0.0, 0.0), &plot(1.0, 1000.0, 0.0), 1.0, &g).unwrap();
        assert!((d - 950.0f64.powi(2) / 2.0).abs() < 1e-6);
        // Inside the band: D = 0.
        let d = velocity_statistic(&plot(0.0, 0.0, 0.0), &plot(1.0, 30.0, 40.0), 1.0, &g).unwrap();
        assert_eq!(d, 0.0);
        // Too slow for v_min = 100: |Δ| = 5, shortfall −95 along Δ: D = 95²/2.
        let slow = VelocityGate::Speed {
            v_min: 100.0,
            v_max: 200.0,
        };
        let d = velocity_statistic(&plot(0.0, 0.0, 0.0), &plot(1.0, 3.0, 4.0), 1.0, &slow).unwrap();
        assert!((d - 95.0f64.powi(2) / 2.0).abs() < 1e-6);
        // Per-axis band of the patent's Fig. 6 (x ∈ [100, 800], y ∈ [−100, 100], 5 s):
        // Δ = (2500, 0) inside; Δ = (2500, 600) exceeds y by 100 → D = 100²/2.
        let axis = VelocityGate::PerAxis {
            v_min: [100.0, -100.0, 0.0],
            v_max: [800.0, 100.0, 0.0],
        };
        let d =
            velocity_statistic(&plot(0.0, 0.0, 0.0), &plot(5.0, 2500.0, 0.0), 5.0, &axis).unwrap();
        assert_eq!(d, 0.0);
        let d = velocity_statistic(&plot(0.0, 0.0, 0.0), &plot(5.0, 2500.0, 600.0), 5.0, &axis)
            .unwrap();
        assert!((d - 5000.0).abs() < 1e-9);

        // And no tentative is started from such a pair.
        let c = cfg();
        let mut ini = Initiator::default();
        let mut id = 0;
        ini.step(
            0.0,
            vec![plot(0.0, 0.0, 0.0)],
            &c,
            Misses::Judge(View::All),
            &mut id,
            usize::MAX,
            &[],
        )
        .unwrap();
        let out = ini
            .step(
                1.0,
                vec![plot(1.0, 1000.0, 0.0)],
                &c,
                Misses::Judge(View::All),
                &mut id,
                usize::MAX,
                &[],
            )
            .unwrap();
        assert_eq!(out.started, 0);
        assert_eq!(ini.roots.len(), 2); // the new plot is a root; the old one waits
    }

    #[test]
    fn the_pruning_bound_never_exceeds_the_statistic() {
        // Random-ish pairs, correlated covariances: bound ≤ D always.
        let gates = [
            VelocityGate::Speed {
                v_min: 50.0,
                v_max: 300.0,
            },
            VelocityGate::PerAxis {
                v_min: [100.0, -100.0, -50.0],
                v_max: [800.0, 100.0, 50.0],
            },
        ];
        for k in 0..200 {
            let f = k as f64;
            let mut a = plot(0.0, 900.0 * (f * 0.7).sin(), 700.0 * (f * 1.3).cos());
            let b = plot(2.0, 1200.0 * (f * 0.3).cos(), 500.0 * (f * 0.9).sin());
            a.r = DMatrix::from_row_slice(2, 2, &[100.0, 0.0, 0.0, 400.0]);
            a.r[(0, 1)] = 150.0 * (f * 0.2).sin();
            a.r[(1, 0)] = a.r[(0, 1)];
            for g in &gates {
                let bound = velocity_bound(&a, &b, 2.0, g);
                let d = velocity_statistic(&a, &b, 2.0, g).unwrap();
                assert!(bound <= d * (1.0 + 1e-12) + 1e-12, "k {k}: {bound} > {d}");
            }
        }
    }

    #[test]
    fn clutter_alone_confirms_nothing() {
        // Uniform pseudo-clutter, 5 plots per 1 s frame over 10 km × 10 km,
        // 30 frames, speed band [0, 600] m/s, σ = 10 m.
        let mut c = cfg();
        c.initiation.velocity = VelocityGate::Speed {
            v_min: 0.0,
            v_max: 600.0,
        };
        let mut rng = Lcg(12345);
        let mut ini = Initiator::default();
        let mut id = 0;
        let (mut started, mut confirmed) = (0, 0);
        for k in 0..30 {
            let t = k as f64;
            let plots = (0..5)
                .map(|_| {
                    let mut p = plot(t, 1e4 * rng.uniform(), 1e4 * rng.uniform());
                    p.r *= 100.0;
                    p
                })
                .collect();
            let out = ini
                .step(
                    t,
                    plots,
                    &c,
                    Misses::Judge(View::All),
                    &mut id,
                    usize::MAX,
                    &[],
                )
                .unwrap();
            started += out.started;
            confirmed += out.confirmed.len();
        }
        assert!(started > 0, "the clutter should start some candidates");
        assert_eq!(confirmed, 0);
    }
}
