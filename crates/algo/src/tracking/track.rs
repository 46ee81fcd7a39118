//! A track of the tracker (tentative or confirmed, seed 001 steps 7–8) with
//! its frame history, and the predictor: constant velocity with discrete
//! white-noise acceleration over a variable Δt (the patent's F₁, F₂ for
//! plot intervals T₁, T₂ − T₁ of serial processing).

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::gating::chi2_threshold;
use crate::kalman;
use crate::motion::cv_transition;
use crate::tracking::config::{Imm, NoiseModel, Plot, RadarSpec};
use crate::tracking::conversion::CartesianPlot;
use crate::tracking::identity::TrackIdentity;
use crate::tracking::predictor::{ModeState, Predictor, process_noise};

/// Where a track stands in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackStatus {
    /// Started by the logic-based initiation, not yet M-of-N confirmed.
    Tentative,
    /// Confirmed, maintained by JPDA.
    Confirmed,
    /// Deleted in this step (reported once).
    Deleted,
}

/// A track as the tracker reports it. The state is in the fusion ENU frame,
/// `[x, vx, y, vy]` or `[x, vx, y, vy, z, vz]`.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackOutput {
    /// Stable identifier, kept from tentative to confirmed.
    pub id: u64,
    /// Where the track stands in its life.
    pub status: TrackStatus,
    /// Time of the state (the last frame the track was predicted to) (s).
    pub t: f64,
    /// State vector in the fusion ENU frame (m, m/s).
    pub state: DVector<f64>,
    /// Covariance of the state.
    pub covariance: DMatrix<f64>,
    /// Radars whose plots updated the track at its last update, ascending.
    pub radars: Vec<usize>,
    /// Frames with an associated plot (times updated; the initiation's
    /// first two plots count).
    pub hits: u32,
    /// Frames without one.
    pub misses: u32,
    /// Misses since the last hit.
    pub consecutive_misses: u32,
    /// Frames since the track was started (its first two plots count as 2).
    pub age: u32,
    /// Time of the last update by a plot (s).
    pub last_update: f64,
    /// Mode probabilities of an IMM track, in the order of the
    /// configuration's models (empty for a single-model track).
    pub modes: Vec<f64>,
    /// Time of the track's first plot (s); `None` for a track stored by a
    /// release that did not keep it.
    pub started: Option<f64>,
    /// The radar plot of the track's last update, when that update was
    /// one radar's plot (serial frames; `None` after a fused plot of
    /// parallel mode, or for a track stored by a release that did not keep
    /// it).
    pub last_plot: Option<Plot>,
    /// What the track has learnt of its aircraft's identity (Mode S,
    /// Mode 3/A, callsign, pressure altitude), and the check of its
    /// self-reported positions.
    pub identity: TrackIdentity,
    /// Per sensor that has updated it (radars, then report kinds,
    /// ascending): the time of its last hit (its sources and their ages).
    pub detections: Vec<RadarHit>,
}

/// A track inside the tracker (tentative or confirmed), with what its life
/// so far has recorded. Public so that a codec outside this crate can store
/// a tracker ([`super::TrackerState`]); a tracker rebuilt from parts checks
/// every field ([`super::Tracker::from_parts`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// Stable identifier, kept from tentative to confirmed.
    pub id: u64,
    /// State in the fusion ENU frame, `[x, vx, y, vy(, z, vz)]` (m, m/s).
    pub x: DVector<f64>,
    /// Covariance of the state.
    pub p: DMatrix<f64>,
    /// Time of the state (s).
    pub t: f64,
    /// Bit i = 1 when the frame i frames ago was a hit (bit 0 = latest).
    pub history: u64,
    /// Frames since the track was started.
    pub age: u32,
    /// Frames with an associated plot.
    pub hits: u32,
    /// Frames without one.
    pub misses: u32,
    /// Misses since the last hit.
    pub consecutive_misses: u32,
    /// Radars whose plots updated the track at its last update, ascending.
    pub radars: Vec<usize>,
    /// Time of the last update by a plot (s).
    pub last_update: f64,
    /// An IMM track's models, in the order of [`Imm::models`], each with its
    /// mode probability and state; `x`, `p` are then their combination.
    /// Empty for a single constant-velocity Gaussian.
    pub modes: Vec<ModeState>,
    /// Time of the track's first plot (s); `None` when not known (a track
    /// stored by an earlier release).
    pub started: Option<f64>,
    /// The radar plot most likely associated at the last update, when it
    /// was one radar's plot (not a fused one); provenance only, the filter
    /// does not read it.
    pub last_plot: Option<Plot>,
    /// What the track has learnt of its aircraft's identity from the
    /// secondary plots that updated it.
    pub identity: TrackIdentity,
    /// Per radar that has updated it (ascending radar): the time of its
    /// last hit, for the radar's detection probability
    /// ([`super::accuracy`]). Empty for a track stored by a release that
    /// did not keep it.
    pub detections: Vec<RadarHit>,
}

/// A track's last hit by one radar.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarHit {
    /// The radar (index).
    pub radar: usize,
    /// Time of the latest hit (s).
    pub last: f64,
}

impl Track {
    /// A track at time 0 with no frames recorded (for tests).
    #[cfg(test)]
    pub(crate) fn fresh(id: u64, x: DVector<f64>, p: DMatrix<f64>) -> Self {
        Self {
            id,
            x,
            p,
            t: 0.0,
            history: 0,
            age: 0,
            hits: 0,
            misses: 0,
            consecutive_misses: 0,
            radars: vec![],
            last_update: 0.0,
            started: Some(0.0),
            last_plot: None,
            modes: Vec::new(),
            identity: TrackIdentity::default(),
            detections: Vec::new(),
        }
    }

    /// Records a hit by radar `radar` (scan period `period`) at time `t`
    /// and returns the scans since the radar's previous hit,
    /// round(Δt / period) ≥ 1, when this hit is a later scan's (Δt at
    /// least half a period; an earlier or the same scan's hit, a split
    /// plot, returns `None` and only moves the time forward).
    fn hit_by(&mut self, radar: usize, t: f64, period: f64) -> Option<u32> {
        match self.detections.binary_search_by_key(&radar, |h| h.radar) {
            Ok(i) => {
                let h = &mut self.detections[i];
                let dt = t - h.last;
                if dt > 0.0 {
                    h.last = t;
                }
                (dt >= 0.5 * period).then(|| (dt / period).round().clamp(1.0, 1e9) as u32)
            }
            Err(i) => {
                self.detections.insert(i, RadarHit { radar, last: t });
                None
            }
        }
    }

    /// Every sensor that has updated the track: those it keeps a hit of,
    /// then those of its last hit (a sensor may come twice).
    pub(crate) fn sensors(&self) -> impl Iterator<Item = usize> + '_ {
        self.detections
            .iter()
            .map(|h| h.radar)
            .chain(self.radars.iter().copied())
    }

    /// [`Track::hit_by`] of a frame's plot when it is one radar's plot
    /// (its own time; a fused plot of parallel mode records none): the
    /// scans since that radar's previous hit.
    pub(crate) fn hit_by_plot(
        &mut self,
        plot: &CartesianPlot,
        radars: &[RadarSpec],
    ) -> Option<u32> {
        let m = plot.measured.as_ref()?;
        if let Some(r) = &m.report {
            // A report's sensor: its time kept (the track's sources and
            // their ages); no scan, no detection trial.
            self.hit_by(m.radar, m.t, r.kind.coast_s());
            return None;
        }
        let spec = radars.get(m.radar)?;
        self.hit_by(m.radar, m.t, spec.scan_period)
    }

    /// Records a frame: a hit with the radars of the plot(s), or a miss.
    pub(crate) fn record(&mut self, hit: Option<Vec<usize>>) {
        self.history <<= 1;
        self.age = self.age.saturating_add(1);
        match hit {
            Some(radars) => {
                self.history |= 1;
                self.hits = self.hits.saturating_add(1);
                self.consecutive_misses = 0;
                self.radars = radars;
                self.last_update = self.t;
            }
            None => {
                self.misses = self.misses.saturating_add(1);
                self.consecutive_misses = self.consecutive_misses.saturating_add(1);
            }
        }
    }

    /// Hits among the last `n` frames (n ≤ 64).
    pub(crate) fn hits_in_last(&self, n: u32) -> u32 {
        (self.history & window(n)).count_ones()
    }

    /// Misses among the last `n` frames, counting only frames the track lived.
    pub(crate) fn misses_in_last(&self, n: u32) -> u32 {
        n.min(self.age) - self.hits_in_last(n)
    }

    /// Predicts the track to time `t` (Δt = t − self.t, any sign).
    pub(crate) fn predict(
        &mut self,
        t: f64,
        sigma_a: &[f64; 3],
        noise: NoiseModel,
    ) -> Result<(), AlgoError> {
        let (x, p) = predict(&self.x, &self.p, t - self.t, sigma_a, noise)?;
        self.x = x;
        self.p = p;
        self.t = t;
        Ok(())
    }

    /// Takes a prediction to time `t` as the track's state, by exchanging
    /// buffers: `prediction` is left with
    /// the track's previous state (of the same shapes, to be reused).
    pub(crate) fn commit_swap(&mut self, t: f64, prediction: &mut Prediction) {
        std::mem::swap(&mut self.x, &mut prediction.x);
        std::mem::swap(&mut self.p, &mut prediction.p);
        std::mem::swap(&mut self.modes, &mut prediction.modes);
        self.t = t;
    }

    /// The track as reported at time `t` (predicted there by `predictor`,
    /// the track left as it is; as it stands when the prediction fails or
    /// `t` is its own time).
    pub(crate) fn output_at(
        &self,
        t: f64,
        predictor: &mut dyn Predictor,
        status: TrackStatus,
    ) -> TrackOutput {
        let mut out = self.output(status);
        if t.to_bits() == self.t.to_bits() {
            return out;
        }
        let mut pr = Prediction::default();
        if predictor.predict_into(self, t, &mut pr).is_ok() {
            out.t = t;
            out.state = pr.x;
            out.covariance = pr.p;
            out.modes = pr.modes.iter().map(|m| m.probability).collect();
        }
        out
    }

    /// Starts the modes of a track just confirmed under an IMM: every model
    /// at the track's estimate, with the prior mode split.
    /// A confirmed track that lost its aircraft takes the state of the
    /// newly confirmed track that found it again (same Mode S address):
    /// its id, age, counts and identity stay, with the newer track's
    /// state, recent history, radars, last plot and pressure altitude
    /// (the IMM restarted from the new state).
    pub(crate) fn reacquire(&mut self, new: Track, motion: &super::Motion) {
        self.x = new.x;
        self.p = new.p;
        self.t = new.t;
        self.history = new.history;
        self.hits += new.hits;
        self.consecutive_misses = 0;
        self.radars = new.radars;
        self.last_update = new.last_update;
        self.last_plot = new.last_plot;
        // The radars' hits: the later of the two tracks' per radar.
        for h in new.detections {
            match self.detections.binary_search_by_key(&h.radar, |d| d.radar) {
                Ok(i) if self.detections[i].last < h.last => self.detections[i] = h,
                Ok(_) => {}
                Err(i) => self.detections.insert(i, h),
            }
        }
        let (mine, theirs) = (&mut self.identity, new.identity);
        if theirs.altitude.is_some() {
            mine.altitude = theirs.altitude;
        }
        let later = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(x), Some(y)) => Some(x.max(y)),
            (x, y) => x.or(y),
        };
        mine.last_secondary = later(mine.last_secondary, theirs.last_secondary);
        mine.last_mode_s = later(mine.last_mode_s, theirs.last_mode_s);
        mine.last_primary = later(mine.last_primary, theirs.last_primary);
        mine.last_mode_ac = later(mine.last_mode_ac, theirs.last_mode_ac);
        mine.spi_t = later(mine.spi_t, theirs.spi_t);
        match motion {
            super::Motion::Imm(imm) => self.start_modes(imm),
            super::Motion::ConstantVelocity => self.modes.clear(),
        }
    }

    pub(crate) fn start_modes(&mut self, imm: &Imm) {
        self.modes = imm
            .initial_probabilities
            .iter()
            .map(|&probability| ModeState {
                probability,
                x: self.x.clone(),
                p: self.p.clone(),
            })
            .collect();
    }

    pub(crate) fn output(&self, status: TrackStatus) -> TrackOutput {
        TrackOutput {
            modes: self.modes.iter().map(|m| m.probability).collect(),
            id: self.id,
            status,
            t: self.t,
            state: self.x.clone(),
            covariance: self.p.clone(),
            radars: self.radars.clone(),
            hits: self.hits,
            misses: self.misses,
            consecutive_misses: self.consecutive_misses,
            age: self.age,
            last_update: self.last_update,
            started: self.started,
            last_plot: self.last_plot,
            identity: self.identity.clone(),
            detections: self.detections.clone(),
        }
    }
}

/// `dst` = `src`, in place when the lengths agree.
pub(crate) fn copy_vector(dst: &mut DVector<f64>, src: &DVector<f64>) {
    if dst.len() == src.len() {
        dst.copy_from(src);
    } else {
        *dst = src.clone();
    }
}

/// `dst` = `src`, in place when the shapes agree.
pub(crate) fn copy_matrix(dst: &mut DMatrix<f64>, src: &DMatrix<f64>) {
    if dst.shape() == src.shape() {
        dst.copy_from(src);
    } else {
        *dst = src.clone();
    }
}

/// A track's predicted state, not yet taken ([`Track::predicted`]).
#[derive(Debug, Clone)]
pub(crate) struct Prediction {
    pub x: DVector<f64>,
    pub p: DMatrix<f64>,
    pub modes: Vec<ModeState>,
}

impl Default for Prediction {
    fn default() -> Self {
        Self {
            x: DVector::zeros(0),
            p: DMatrix::zeros(0, 0),
            modes: Vec::new(),
        }
    }
}

/// Constant-velocity prediction over `dt`, F = blockdiag([[1, Δt], [0, 1]]),
/// with per-axis process noise: DWNA of standard deviation σ_i,
/// Q = σ_i² [[Δt⁴/4, Δt³/2], [Δt³/2, Δt²]], or CWNA of spectral density
/// q_i = σ_i², Q = q_i [[Δt³/3, Δt²/2], [Δt²/2, Δt]].
pub(super) fn predict(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    dt: f64,
    sigma_a: &[f64; 3],
    noise: NoiseModel,
) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    let axes = x.len() / 2;
    let f = cv_transition(axes, dt)?;
    let q = process_noise(axes, dt, sigma_a, noise)?;
    kalman::predict(x, p, &f, &q)
}

/// The measurement matrix selecting the first `k` position components
/// (e, n(, u)) of an interleaved state with `axes` axes.
pub(super) fn position_selector(k: usize, axes: usize) -> DMatrix<f64> {
    DMatrix::from_fn(k, 2 * axes, |i, j| if j == 2 * i { 1.0 } else { 0.0 })
}

/// The χ² thresholds γ of a gate with probability `p` for 2 and 3 degrees
/// of freedom (positions in the plane or in space): index `dim − 2`.
pub(super) fn chi2_gates(p: f64) -> Result<[f64; 2], AlgoError> {
    Ok([chi2_threshold(2, 1.0 - p)?, chi2_threshold(3, 1.0 - p)?])
}

fn window(n: u32) -> u64 {
    if n >= 64 { u64::MAX } else { (1u64 << n) - 1 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dvector;

    #[test]
    fn history_counts_a_sliding_window() {
        let mut t = Track::fresh(1, dvector![0.0, 0.0], DMatrix::identity(2, 2));
        // Frames: hit, hit, miss, hit, miss, miss → newest first 0 0 1 0 1 1.
        for h in [true, true, false, true, false, false] {
            t.record(h.then(|| vec![0]));
        }
        assert_eq!(t.hits_in_last(4), 1); // miss, miss, hit, miss
        assert_eq!(t.misses_in_last(4), 3);
        assert_eq!(t.hits_in_last(64), 3);
        assert_eq!(t.misses_in_last(64), 3); // only 6 frames lived
        assert_eq!(
            (t.hits, t.misses, t.consecutive_misses, t.age),
            (3, 3, 2, 6)
        );
    }

    #[test]
    fn prediction_by_hand() {
        // 2 axes, Δt = 2, σ = (1, 0): x = [0, 10, 5, −1] → [20, 10, 3, −1];
        // P = I: F F' per axis = [[1 + 4, 2], [2, 1]], Q_x = [[4, 4], [4, 4]].
        let x = dvector![0.0, 10.0, 5.0, -1.0];
        let (x1, p1) = predict(
            &x,
            &DMatrix::identity(4, 4),
            2.0,
            &[1.0, 0.0, 0.0],
            NoiseModel::Dwna,
        )
        .unwrap();
        assert_eq!(x1, dvector![20.0, 10.0, 3.0, -1.0]);
        assert_eq!(p1[(0, 0)], 9.0);
        assert_eq!(p1[(0, 1)], 6.0);
        assert_eq!(p1[(1, 1)], 5.0);
        assert_eq!(p1[(2, 2)], 5.0);
        assert_eq!(p1[(2, 3)], 2.0);
        assert_eq!(p1[(0, 2)], 0.0);
        // CWNA, q = 1: Q_x = [[8/3, 2], [2, 2]] → P_xx = 5 + 8/3, P_xv = 4,
        // P_vv = 3.
        let (_, p2) = predict(
            &x,
            &DMatrix::identity(4, 4),
            2.0,
            &[1.0, 0.0, 0.0],
            NoiseModel::Cwna,
        )
        .unwrap();
        assert!((p2[(0, 0)] - (5.0 + 8.0 / 3.0)).abs() < 1e-12);
        assert!((p2[(0, 1)] - 4.0).abs() < 1e-12 && (p2[(1, 1)] - 3.0).abs() < 1e-12);
        assert_eq!(p2[(2, 2)], 5.0);
        let h = position_selector(2, 3);
        assert_eq!(h.ncols(), 6);
        assert_eq!((h[(0, 0)], h[(1, 2)], h[(1, 3)]), (1.0, 1.0, 0.0));
    }
}
