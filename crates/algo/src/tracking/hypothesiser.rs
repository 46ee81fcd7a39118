//! The hypothesiser's spatial index: which tracks a plot can touch, found
//! without a scan of the whole picture.
//!
//! Tracks keep their own time (the time of their last update or judged
//! miss) and are predicted only when something needs them. Whether a
//! track is *tested* against a plot at time t is decided by a cheap,
//! deterministic pre-test that does not depend on the index
//! ([`Reach::may_gate`]): with Δt = t − t_i, the track's constant-velocity
//! extrapolation p_i + v_i Δt must lie within
//!
//! k (σ_i(Δt) + σ_z) + |v_i| ω_max Δt²/2 + 50 m
//!
//! of the plot horizontally, where σ_i(Δt)² = Σ_axes (P_kk + 2Δt P_kv +
//! Δt² P_vv) + 2 q_max c(Δt) is the horizontal variance of the constant
//! velocity prediction with the largest process noise of any model (c =
//! Δt³/3 for CWNA, Δt⁴/4 for DWNA), σ_z² the trace of the plot's
//! horizontal covariance, ω_max the largest turn rate of the IMM (a turn
//! departs from the straight line by v ω Δt²/2) and k = 1.5 √γ with γ
//! the χ² gate of the widest measurement (position and range rate). A
//! gate d′S⁻¹d ≤ γ bounds every component of the position residual by
//! √(γ (P_kk + R_kk)), so the pre-test keeps every pair the gate can
//! pass with a factor 1.5 to spare for the polar linearisation and the
//! IMM's spread; only pairs that pass it are predicted and gated.
//!
//! The index ([`Grid`]) holds each track in a square cell of side
//! [`CELL_M`] by its position at its own time. A plot's query covers every
//! cell within a radius that bounds the pre-test for every track at once
//! ([`Reach::radius`]: the largest speed, σ and σ_v of any track and the
//! oldest track time, kept as running bounds between rebuilds), so the
//! index finds a superset of the pre-test's pairs and never changes an
//! answer (property test `the_index_finds_every_pair_the_pre_test_passes`).

use std::hash::{BuildHasherDefault, Hasher};
use std::{borrow::Borrow, collections::HashMap};

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::gating::chi2_threshold;
use crate::tracking::config::{Motion, NoiseModel, TrackerConfig};
use crate::tracking::conversion::CartesianPlot;
use crate::tracking::track::Track;

/// Side of a cell of the index (m).
pub(crate) const CELL_M: f64 = 4000.0;

/// Absolute slack of the pre-test (m).
const SLACK_M: f64 = 50.0;

/// FxHash-style hasher for cell keys (two i32).
#[derive(Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_i32(&mut self, i: i32) {
        self.write_u64(u64::from(i as u32));
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
}

type Cells = HashMap<(i32, i32), Vec<u32>, BuildHasherDefault<CellHasher>>;

fn key(cell: f64, e: f64, n: f64) -> (i32, i32) {
    let k = |v: f64| (v / cell).floor().clamp(-1.0e9, 1.0e9) as i32;
    (k(e), k(n))
}

/// A uniform grid of slots (indices into a list kept by the caller) by
/// horizontal position. Derived data: rebuilt from the list whenever it is
/// `invalid` (after a removal shifted the slots, or a decode).
#[derive(Debug, Clone, Default)]
pub(crate) struct Grid {
    /// Side of a cell (m); [`CELL_M`] when 0.
    cell: f64,
    cells: Cells,
    /// Per slot, its cell.
    of: Vec<Option<(i32, i32)>>,
    valid: bool,
}

impl PartialEq for Grid {
    /// Derived data: two trackers in the same state are equal whatever
    /// their indices hold.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Grid {
    /// An empty grid of cells of side `cell` (m), out of date.
    pub(crate) fn with_cell(cell: f64) -> Self {
        Self {
            cell,
            ..Self::default()
        }
    }

    fn side(&self) -> f64 {
        if self.cell > 0.0 { self.cell } else { CELL_M }
    }

    /// Whether the grid matches the list it indexes.
    pub(crate) fn is_valid(&self) -> bool {
        self.valid
    }

    /// Marks the grid out of date (the caller's slots moved).
    pub(crate) fn invalidate(&mut self) {
        self.valid = false;
    }

    /// Empties the grid and marks it valid for an empty list; the caller
    /// then [`Grid::set`]s every slot.
    pub(crate) fn clear(&mut self) {
        self.cells.clear();
        self.of.clear();
        self.valid = true;
    }

    /// Puts slot `slot` at (e, n), moving it when it is already in.
    pub(crate) fn set(&mut self, slot: usize, e: f64, n: f64) {
        if !self.valid {
            return;
        }
        let k = key(self.side(), e, n);
        if self.of.len() <= slot {
            self.of.resize(slot + 1, None);
        }
        if let Some(old) = self.of[slot] {
            if old == k {
                return;
            }
            if let Some(v) = self.cells.get_mut(&old) {
                if let Some(i) = v.iter().position(|&s| s as usize == slot) {
                    v.swap_remove(i);
                }
            }
        }
        self.cells.entry(k).or_default().push(slot as u32);
        self.of[slot] = Some(k);
    }

    /// Takes slot `slot` out of the grid (when it is in).
    pub(crate) fn remove(&mut self, slot: usize) {
        if let Some(old) = self.of.get_mut(slot).and_then(Option::take) {
            if let Some(v) = self.cells.get_mut(&old) {
                if let Some(i) = v.iter().position(|&s| s as usize == slot) {
                    v.swap_remove(i);
                }
            }
        }
    }

    /// Slot `from` is now slot `to` (which held nothing in the grid).
    pub(crate) fn rename(&mut self, from: usize, to: usize) {
        if let Some(k) = self.of.get_mut(from).and_then(Option::take) {
            if let Some(v) = self.cells.get_mut(&k) {
                if let Some(i) = v.iter().position(|&s| s as usize == from) {
                    v[i] = to as u32;
                }
            }
            if self.of.len() <= to {
                self.of.resize(to + 1, None);
            }
            self.of[to] = Some(k);
        }
    }

    /// Every slot in a cell that meets the square of half-side `radius`
    /// about (e, n), appended to `out` (unsorted).
    pub(crate) fn within(&self, e: f64, n: f64, radius: f64, out: &mut Vec<u32>) {
        let c = self.side();
        let (lo, hi) = (
            key(c, e - radius, n - radius),
            key(c, e + radius, n + radius),
        );
        let span =
            (i64::from(hi.0) - i64::from(lo.0) + 1) * (i64::from(hi.1) - i64::from(lo.1) + 1);
        if span > self.cells.len() as i64 {
            for (k, v) in &self.cells {
                if (lo.0..=hi.0).contains(&k.0) && (lo.1..=hi.1).contains(&k.1) {
                    out.extend_from_slice(v);
                }
            }
            return;
        }
        for i in lo.0..=hi.0 {
            for j in lo.1..=hi.1 {
                if let Some(v) = self.cells.get(&(i, j)) {
                    out.extend_from_slice(v);
                }
            }
        }
    }
}

/// The constants of the pre-test.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Reach {
    /// k = 1.5 √γ.
    k: f64,
    /// The largest horizontal process noise (q of CWNA, σ² of DWNA).
    q: f64,
    noise: NoiseModel,
    /// The largest turn rate of the predictor (rad/s).
    omega: f64,
}

/// What the pre-test reads of a track.
pub(crate) struct Kinematics {
    pub(crate) t: f64,
    pub(crate) e: f64,
    pub(crate) n: f64,
    pub(crate) ve: f64,
    pub(crate) vn: f64,
    /// P_ee, P_e·ve, P_ve·ve, P_nn, P_n·vn, P_vn·vn.
    pub(crate) p: [f64; 6],
}

impl Kinematics {
    /// The horizontal part of an interleaved state.
    pub(crate) fn of(t: f64, x: &DVector<f64>, p: &DMatrix<f64>) -> Self {
        Self {
            t,
            e: x[0],
            n: x[2],
            ve: x[1],
            vn: x[3],
            p: [
                p[(0, 0)],
                p[(0, 1)],
                p[(1, 1)],
                p[(2, 2)],
                p[(2, 3)],
                p[(3, 3)],
            ],
        }
    }

    fn speed(&self) -> f64 {
        (self.ve * self.ve + self.vn * self.vn).sqrt()
    }

    fn sigma(&self) -> f64 {
        (self.p[0] + self.p[3]).max(0.0).sqrt()
    }

    fn sigma_v(&self) -> f64 {
        (self.p[2] + self.p[5]).max(0.0).sqrt()
    }
}

impl Reach {
    /// The pre-test's constants for `cfg`; no track yet.
    pub(crate) fn new(cfg: &TrackerConfig) -> Result<Self, AlgoError> {
        // The widest measurement: a 3D position and a range rate.
        let gamma = chi2_threshold(4, 1.0 - cfg.track_gate_probability)?
            .max(chi2_threshold(3, 1.0 - cfg.initiation.gate_probability)?);
        let tentative = cfg.sigma_a[0].max(cfg.sigma_a[1]).powi(2);
        let omega = match &cfg.motion {
            Motion::Imm(imm) => imm
                .models
                .iter()
                .map(|m| m.turn_rate().abs())
                .fold(0.0, f64::max),
            Motion::ConstantVelocity => 0.0,
        };
        Ok(Self {
            k: 1.5 * gamma.sqrt(),
            q: cfg.largest_process_noise().max(tentative),
            noise: cfg.noise,
            omega,
        })
    }

    /// The position variance a noise of spectral density (or σ²) q adds
    /// on one axis over Δt.
    fn noise_variance(&self, dt: f64) -> f64 {
        let dt = dt.abs();
        match self.noise {
            NoiseModel::Cwna => self.q * dt.powi(3) / 3.0,
            NoiseModel::Dwna => self.q * dt.powi(4) / 4.0,
        }
    }

    /// The pre-test: whether a track may gate a plot at `t` at (e, n)
    /// whose horizontal σ (√ of the trace) is `sigma_z` (module header).
    pub(crate) fn may_gate(&self, tr: &Kinematics, t: f64, e: f64, n: f64, sigma_z: f64) -> bool {
        let dt = t - tr.t;
        let (de, dn) = (tr.e + tr.ve * dt - e, tr.n + tr.vn * dt - n);
        let p = &tr.p;
        let var = p[0]
            + 2.0 * dt * p[1]
            + dt * dt * p[2]
            + p[3]
            + 2.0 * dt * p[4]
            + dt * dt * p[5]
            + 2.0 * self.noise_variance(dt);
        let bound = self.k * (var.max(0.0).sqrt() + sigma_z)
            + tr.speed() * self.omega * dt * dt / 2.0
            + SLACK_M;
        de * de + dn * dn <= bound * bound
    }

    /// A bound of the pre-test's radius, but for the plot's own k σ_z,
    /// for this track at any Δt in [0, `dt`]: k (σ + σ_v Δt + √(2 q c(Δt))),
    /// plus |v| ω Δt²/2 and the slack; monotone in Δt, since σ_i(Δt) ≤ σ +
    /// σ_v Δt + √(2 q c(Δt)) by Minkowski's inequality and |P_kv| ≤
    /// √(P_kk P_vv).
    pub(crate) fn reach(&self, tr: &Kinematics, dt: f64) -> f64 {
        let dt = dt.abs();
        self.k * (tr.sigma() + tr.sigma_v() * dt + (2.0 * self.noise_variance(dt)).max(0.0).sqrt())
            + tr.speed() * self.omega * dt * dt / 2.0
            + SLACK_M
    }
}

/// How long a grid serves (s of frame time) before it is rebuilt.
pub(crate) const GRID_HORIZON_S: f64 = 1.0;

/// The levels of the index: a track of reach up to `LEVELS[l]` (m) over
/// the grid's horizon ([`Reach::reach`]) is held in level l, whose cells
/// are that wide; a wider one is tested by every query.
const LEVELS: [f64; 3] = [2_000.0, 8_000.0, 32_000.0];

/// Where a slot of the index is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Place {
    Out,
    Level(usize),
    Wide,
}

/// The index of a list of tracks. Built at a time t_g, it holds each track
/// at its constant-velocity position at t_g and serves queries at t in
/// [t_g, t_g + [`GRID_HORIZON_S`]]: a track the pre-test can pass at t lies
/// within |v| (t − t_g) + reach + k σ_z of the plot, reach being the
/// pre-test's bound at the end of the horizon (monotone in Δt by
/// Minkowski's inequality). Tracks are held in a level of cells as wide
/// as their reach ([`LEVELS`]: a confirmed track in the finest, a
/// tentative track straight after its two-point start in a coarser one),
/// so a query visits a few cells of each level; tracks wider than the
/// coarsest (a long coast) are tested by every query. Derived data (never
/// stored, equal whatever it holds).
#[derive(Debug, Clone, Default)]
pub(crate) struct TrackIndex {
    levels: Vec<Grid>,
    reach: Option<Reach>,
    /// The grid's time t_g.
    t_g: f64,
    /// The largest speed of a track in the grid.
    speed: f64,
    /// Per slot, where it is; and the wide slots.
    place: Vec<Place>,
    wide_slots: Vec<u32>,
    scratch: Vec<u32>,
}

impl PartialEq for TrackIndex {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl TrackIndex {
    /// Marks the index out of date: the list's slots moved.
    pub(crate) fn invalidate(&mut self) {
        if let Some(g) = self.levels.first_mut() {
            g.invalidate();
        }
    }

    fn is_valid(&self) -> bool {
        self.reach.is_some() && self.levels.first().is_some_and(Grid::is_valid)
    }

    /// Rebuilds the index at time `t` when it is out of date or `t` is
    /// outside its horizon.
    pub(crate) fn refresh<T: Borrow<Track>>(
        &mut self,
        tracks: &[T],
        t: f64,
        cfg: &TrackerConfig,
    ) -> Result<(), AlgoError> {
        if self.is_valid() && t >= self.t_g && t <= self.t_g + GRID_HORIZON_S {
            return Ok(());
        }
        if self.reach.is_none() {
            self.reach = Some(Reach::new(cfg)?);
        }
        if self.levels.is_empty() {
            self.levels = LEVELS.iter().map(|&c| Grid::with_cell(c)).collect();
        }
        for g in &mut self.levels {
            g.clear();
        }
        self.t_g = t;
        self.speed = 0.0;
        self.place.clear();
        self.wide_slots.clear();
        for (i, tr) in tracks.iter().enumerate() {
            self.put(i, tr.borrow());
        }
        Ok(())
    }

    /// Puts slot `slot` in its level or among the wide tracks.
    fn put(&mut self, slot: usize, track: &Track) {
        let reach = self.reach.as_ref().expect("built");
        let k = Kinematics::of(track.t, &track.x, &track.p);
        if self.place.len() <= slot {
            self.place.resize(slot + 1, Place::Out);
        }
        let r = reach.reach(&k, self.t_g + GRID_HORIZON_S - k.t);
        let new = LEVELS
            .iter()
            .position(|&w| r <= w)
            .map_or(Place::Wide, Place::Level);
        let old = self.place[slot];
        if old != new {
            match old {
                Place::Level(l) => self.levels[l].remove(slot),
                Place::Wide => self.wide_slots.retain(|&s| s as usize != slot),
                Place::Out => {}
            }
            if new == Place::Wide {
                self.wide_slots.push(slot as u32);
            }
        }
        if let Place::Level(l) = new {
            let dt = self.t_g - k.t;
            self.levels[l].set(slot, k.e + k.ve * dt, k.n + k.vn * dt);
            self.speed = self.speed.max(k.speed());
        }
        self.place[slot] = new;
    }

    /// Slot `slot` of the list changed state (or was appended).
    pub(crate) fn moved(&mut self, slot: usize, track: &Track) {
        if self.is_valid() {
            self.put(slot, track);
        }
    }

    /// The list did `swap_remove(slot)` from `len` slots: the last slot
    /// is now `slot`.
    pub(crate) fn swap_removed(&mut self, slot: usize, len: usize) {
        if !self.is_valid() || self.place.len() < len || slot >= len {
            self.invalidate();
            return;
        }
        match self.place[slot] {
            Place::Level(l) => self.levels[l].remove(slot),
            Place::Wide => self.wide_slots.retain(|&s| s as usize != slot),
            Place::Out => {}
        }
        let last = len - 1;
        if slot != last {
            match self.place[last] {
                Place::Level(l) => self.levels[l].rename(last, slot),
                Place::Wide => {
                    for s in &mut self.wide_slots {
                        if *s as usize == last {
                            *s = slot as u32;
                        }
                    }
                }
                Place::Out => {}
            }
            self.place[slot] = self.place[last];
        }
        self.place.truncate(last);
    }
}

/// What [`swap_remove_all`] did: the removed items by ascending slot, and
/// the moves (from, to) of the items that took their places, in order.
pub(crate) type Removed<T> = (Vec<(usize, T)>, Vec<(usize, usize)>);

/// Removes `slots` (any order, distinct) from `list` by `swap_remove`,
/// mirrored in `index`.
pub(crate) fn swap_remove_all<T>(
    list: &mut Vec<T>,
    mut slots: Vec<usize>,
    index: &mut TrackIndex,
) -> Removed<T> {
    slots.sort_unstable_by(|a, b| b.cmp(a));
    slots.dedup();
    let mut removed = Vec::with_capacity(slots.len());
    let mut moves = Vec::new();
    for slot in slots {
        let len = list.len();
        removed.push((slot, list.swap_remove(slot)));
        index.swap_removed(slot, len);
        if slot != len - 1 {
            moves.push((len - 1, slot));
        }
    }
    removed.reverse();
    (removed, moves)
}

impl TrackIndex {
    /// The slots of `tracks` that pass the pre-test with any of `plots`
    /// (at time `t`), ascending.
    pub(crate) fn candidates<T: Borrow<Track>>(
        &mut self,
        tracks: &[T],
        plots: &[CartesianPlot],
        t: f64,
        cfg: &TrackerConfig,
    ) -> Result<Vec<usize>, AlgoError> {
        self.refresh(tracks, t, cfg)?;
        let reach = self.reach.as_ref().expect("refreshed");
        let mut out: Vec<usize> = Vec::new();
        for plot in plots {
            let sz = plot_sigma(&plot.r);
            self.scratch.clear();
            for (grid, &w) in self.levels.iter().zip(&LEVELS) {
                let radius = self.speed * (t - self.t_g) + w + reach.k * sz + 1.0;
                grid.within(plot.z[0], plot.z[1], radius, &mut self.scratch);
            }
            self.scratch.extend_from_slice(&self.wide_slots);
            for &s in &self.scratch {
                let tr: &Track = tracks[s as usize].borrow();
                if reach.may_gate(
                    &Kinematics::of(tr.t, &tr.x, &tr.p),
                    t,
                    plot.z[0],
                    plot.z[1],
                    sz,
                ) {
                    out.push(s as usize);
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        Ok(out)
    }
}

/// The horizontal σ of a plot's covariance: √(R_ee + R_nn).
pub(crate) fn plot_sigma(r: &DMatrix<f64>) -> f64 {
    (r[(0, 0)] + r[(1, 1)]).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracking::config::RadarSpec;
    use crate::tracking::tests::Lcg;

    fn cfg() -> TrackerConfig {
        let radar = RadarSpec {
            site: [0.0; 3],
            sigma_range: 50.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: None,
            sigma_radial_velocity: None,
            scan_period: 4.0,
            detection_probability: 0.9,
            clutter_density: 1e-9,
        };
        TrackerConfig::new(2, vec![radar])
    }

    #[test]
    fn the_index_finds_every_pair_the_pre_test_passes() {
        // Random tracks (positions over 100 km, speeds to 400 m/s, σ from
        // 10 m to 6 km so that some are wide, σ_v to 300 m/s, times up to
        // 8 s before the grid's), indexed at t_g = 10 s, then moved (a
        // fifth re-placed as if updated at 10.5 s); plots queried at 10.5
        // and 11 s: the index's candidates are exactly the tracks the
        // brute-force pre-test passes, for every plot.
        let c = cfg();
        let mut rng = Lcg(7);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
        let mut tracks: Vec<Track> = (0..400)
            .map(|i| {
                let (s, sv) = (u(10.0, 9000.0), u(1.0, 300.0));
                let rho = u(-0.9, 0.9);
                let x = nalgebra::dvector![
                    u(-50_000.0, 50_000.0),
                    u(-300.0, 300.0),
                    u(-50_000.0, 50_000.0),
                    u(-300.0, 300.0)
                ];
                let p = nalgebra::dmatrix![
                    s * s, rho * s * sv, 0.0, 0.0;
                    rho * s * sv, sv * sv, 0.0, 0.0;
                    0.0, 0.0, s * s, -rho * s * sv;
                    0.0, 0.0, -rho * s * sv, sv * sv
                ];
                let mut t = Track::fresh(i, x, p);
                t.t = u(2.0, 10.0);
                t
            })
            .collect();
        let mut index = TrackIndex::default();
        index.refresh(&tracks, 10.0, &c).unwrap();
        for i in (0..tracks.len()).step_by(5) {
            let tr = &mut tracks[i];
            tr.x[0] += u(-2000.0, 2000.0);
            tr.x[1] += u(-50.0, 50.0);
            tr.t = 10.5;
            index.moved(i, &tracks[i]);
        }
        // A tenth removed by swap_remove (the last ones take their places).
        let doomed: Vec<usize> = (0..tracks.len()).filter(|i| i % 10 == 3).collect();
        let (removed, moves) = swap_remove_all(&mut tracks, doomed, &mut index);
        assert_eq!(removed.len(), 40);
        assert!(removed.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(!moves.is_empty());
        let reach = Reach::new(&c).unwrap();
        let mut tested = 0;
        for q in 0..2000 {
            let t = if q % 2 == 0 { 10.5 } else { 11.0 };
            let sz = u(10.0, 500.0);
            let plot = CartesianPlot {
                t,
                z: nalgebra::dvector![u(-60_000.0, 60_000.0), u(-60_000.0, 60_000.0)],
                r: DMatrix::identity(2, 2) * (sz * sz / 2.0),
                radars: vec![0],
                measured: None,
                range_rates: Vec::new(),
                velocity: Vec::new(),
            };
            let found = index
                .candidates(&tracks, std::slice::from_ref(&plot), t, &c)
                .unwrap();
            let want: Vec<usize> = (0..tracks.len())
                .filter(|&i| {
                    let tr = &tracks[i];
                    reach.may_gate(
                        &Kinematics::of(tr.t, &tr.x, &tr.p),
                        t,
                        plot.z[0],
                        plot.z[1],
                        plot_sigma(&plot.r),
                    )
                })
                .collect();
            tested += want.len();
            assert_eq!(found, want, "plot {q}");
        }
        assert!(tested > 100, "{tested}");
        // Tracks in every level and some too wide for any.
        for l in 0..LEVELS.len() {
            assert!(index.place.contains(&Place::Level(l)), "level {l}");
        }
        assert!(!index.wide_slots.is_empty());
    }

    #[test]
    fn a_moved_slot_is_found_at_its_new_cell_only() {
        let mut g = Grid::default();
        g.clear();
        g.set(0, 100.0, 100.0);
        g.set(1, 50_000.0, 0.0);
        g.set(0, 20_000.0, 20_000.0);
        let mut out = Vec::new();
        g.within(100.0, 100.0, 10.0, &mut out);
        assert!(out.is_empty());
        g.within(20_000.0, 20_000.0, 10.0, &mut out);
        assert_eq!(out, vec![0]);
        // A radius wider than the occupied cells: every occupied cell in
        // the square, by a walk over the cells.
        out.clear();
        g.within(0.0, 0.0, 1e8, &mut out);
        out.sort_unstable();
        assert_eq!(out, vec![0, 1]);
    }
}
