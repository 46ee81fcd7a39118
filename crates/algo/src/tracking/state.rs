//! A [`Tracker`] taken apart and put back together, so that a codec outside
//! this crate (the `formats` crate's stored-state codec) can keep a tracker
//! in a session without this crate doing any serialisation.
//!
//! [`Tracker::state`] lends every field; [`Tracker::from_parts`] rebuilds a
//! tracker from owned parts and checks them as it would check a request, so
//! that parts read from corrupt bytes give an error here, never a panic in
//! a later call.

use super::registrar::Registrar;
use super::registration::RegistrationState;
use super::{CartesianPlot, Counters, Motion, Plot, ReportKind, Track, Tracker, TrackerConfig};
use crate::error::AlgoError;
use crate::gaussian::check_covariance;
use crate::tracking::accuracy::AccuracyState;
use crate::tracking::height::PressureOffset;
use crate::tracking::initiator::Initiator;

/// Everything a tracker carries between calls, borrowed.
#[derive(Debug, Clone, Copy)]
pub struct TrackerState<'a> {
    /// The validated configuration.
    pub config: &'a TrackerConfig,
    /// Confirmed tracks.
    pub tracks: &'a [std::sync::Arc<Track>],
    /// The initiator's roots: plots that may start a track.
    pub roots: &'a [CartesianPlot],
    /// The initiator's tentative tracks.
    pub tentatives: &'a [Track],
    /// Accepted plots of frames not yet complete, in time order.
    pub pending: &'a [Plot],
    /// The identifier the next track will get.
    pub next_id: u64,
    /// Time of the last processed frame.
    pub last_time: Option<f64>,
    /// Parallel mode: index of the last processed fusion instant.
    pub last_instant: Option<i64>,
    /// The running counters.
    pub counters: Counters,
    /// Serial mode, per radar: time and azimuth of the last plot of its
    /// last frame (`None` before its first).
    pub beams: &'a [Option<(f64, f64)>],
    /// Serial mode, per radar: where its beam was when misses were last
    /// judged from its sweep.
    pub judged: &'a [Option<(f64, f64)>],
    /// The registration estimator's data.
    pub registration: &'a RegistrationState,
    /// The pressure-to-geometric offset's data.
    pub pressure_offset: &'a PressureOffset,
    /// Per radar: it has given a Mode S address.
    pub mode_s_radars: &'a [bool],
    /// The accuracy estimator's data.
    pub accuracy: &'a AccuracyState,
}

/// Everything a tracker carries between calls, owned: what
/// [`Tracker::from_parts`] rebuilds a tracker from.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerParts {
    /// The configuration (validated again).
    pub config: TrackerConfig,
    /// Confirmed tracks.
    pub tracks: Vec<Track>,
    /// The initiator's roots.
    pub roots: Vec<CartesianPlot>,
    /// The initiator's tentative tracks.
    pub tentatives: Vec<Track>,
    /// Pending plots, in time order.
    pub pending: Vec<Plot>,
    /// The identifier the next track will get.
    pub next_id: u64,
    /// Time of the last processed frame.
    pub last_time: Option<f64>,
    /// Parallel mode: index of the last processed fusion instant.
    pub last_instant: Option<i64>,
    /// The running counters.
    pub counters: Counters,
    /// Per radar, where its beam was at its last frame (empty: none yet).
    pub beams: Vec<Option<(f64, f64)>>,
    /// Per radar, where its beam was when misses were last judged (empty:
    /// as `beams`, which is where a tracker of an earlier release judged
    /// them).
    pub judged: Vec<Option<(f64, f64)>>,
    /// The registration estimator's data (`None`: none yet).
    pub registration: Option<RegistrationState>,
    /// The pressure-to-geometric offset's data (default: none yet).
    pub pressure_offset: PressureOffset,
    /// Per radar: it has given a Mode S address (empty: none has).
    pub mode_s_radars: Vec<bool>,
    /// The accuracy estimator's data (`None`: none yet, as a tracker of
    /// an earlier release).
    pub accuracy: Option<AccuracyState>,
}

impl TrackerState<'_> {
    /// The same state, owned.
    pub fn to_parts(&self) -> TrackerParts {
        TrackerParts {
            config: self.config.clone(),
            tracks: self.tracks.iter().map(|t| Track::clone(t)).collect(),
            roots: self.roots.to_vec(),
            tentatives: self.tentatives.to_vec(),
            pending: self.pending.to_vec(),
            next_id: self.next_id,
            last_time: self.last_time,
            last_instant: self.last_instant,
            counters: self.counters,
            beams: self.beams.to_vec(),
            judged: self.judged.to_vec(),
            registration: Some(self.registration.clone()),
            pressure_offset: *self.pressure_offset,
            mode_s_radars: self.mode_s_radars.to_vec(),
            accuracy: Some(self.accuracy.clone()),
        }
    }
}

fn bad(reason: impl Into<String>) -> AlgoError {
    AlgoError::InvalidParameter {
        what: "tracker state",
        reason: reason.into(),
    }
}

/// Per radar, a beam position (time, azimuth) or none: one per radar,
/// finite.
fn check_beams(what: &str, beams: &[Option<(f64, f64)>], radars: usize) -> Result<(), AlgoError> {
    if beams.len() != radars {
        return Err(bad(format!("{} {what} for {radars} radars", beams.len())));
    }
    if beams
        .iter()
        .flatten()
        .any(|(t, az)| !(t.is_finite() && az.is_finite()))
    {
        return Err(bad(format!("one of the {what} is not finite")));
    }
    Ok(())
}

/// An IMM track's modes: one per model of the configuration's IMM (none
/// without one, and none for a tentative track, checked by the caller),
/// each of the track's dimension, finite, positive definite, probabilities
/// in (0, 1] summing to 1.
fn check_modes(t: &Track, c: &TrackerConfig) -> Result<(), AlgoError> {
    if t.modes.is_empty() {
        return Ok(());
    }
    let r = match &c.motion {
        Motion::Imm(imm) => imm.models.len(),
        Motion::ConstantVelocity => 0,
    };
    if t.modes.len() != r {
        return Err(bad(format!(
            "track {} has {} modes, the configuration {r} models",
            t.id,
            t.modes.len()
        )));
    }
    let n = t.x.len();
    for m in &t.modes {
        if m.x.len() != n || m.p.shape() != (n, n) || m.x.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("track {} has a malformed mode", t.id)));
        }
        check_covariance("mode covariance", &m.p)?;
        if !(m.probability > 0.0 && m.probability <= 1.0) {
            return Err(bad(format!(
                "track {} has mode probability {}",
                t.id, m.probability
            )));
        }
    }
    let sum: f64 = t.modes.iter().map(|m| m.probability).sum();
    if (sum - 1.0).abs() > 1e-6 {
        return Err(bad(format!(
            "track {}'s mode probabilities sum to {sum}",
            t.id
        )));
    }
    Ok(())
}

impl Tracker {
    /// Every field the tracker carries between calls, borrowed.
    pub fn state(&self) -> TrackerState<'_> {
        TrackerState {
            config: &self.config,
            tracks: &self.tracks,
            roots: &self.initiator.roots,
            tentatives: &self.initiator.tentatives,
            pending: &self.pending,
            next_id: self.next_id,
            last_time: self.last_time,
            last_instant: self.last_instant,
            counters: self.counters,
            beams: &self.beams,
            judged: &self.judged,
            registration: &self.registrar.state,
            pressure_offset: &self.pressure_offset,
            mode_s_radars: &self.mode_s_radars,
            accuracy: &self.accuracy,
        }
    }

    /// A tracker from its parts, which continues exactly as the tracker
    /// they were taken from. Checks the configuration as [`Tracker::new`]
    /// does, every plot as a request's, every track's dimension (2 × axes),
    /// finiteness and covariance (symmetric positive definite), every
    /// root's, every radar index, that pending plots are in time order and
    /// that no track id reaches `next_id`.
    pub fn from_parts(parts: TrackerParts) -> Result<Self, AlgoError> {
        let mut tr = Tracker::new(parts.config)?;
        let c = &tr.config;
        // Radars, then one sensor per kind of cooperative report.
        let radars = |v: &[usize]| -> Result<(), AlgoError> {
            match v.iter().find(|&&i| i >= c.sensors()) {
                Some(i) => Err(bad(format!(
                    "sensor index {i} with {} radars and {} kinds of report",
                    c.radars.len(),
                    ReportKind::ALL.len()
                ))),
                None => Ok(()),
            }
        };
        let n = 2 * c.axes;
        for t in parts.tracks.iter().chain(&parts.tentatives) {
            if t.x.len() != n || t.p.shape() != (n, n) {
                return Err(bad(format!(
                    "track {} has dimension {} ({}×{} covariance), the configuration {n}",
                    t.id,
                    t.x.len(),
                    t.p.nrows(),
                    t.p.ncols()
                )));
            }
            if t.x.iter().any(|v| !v.is_finite()) || !t.t.is_finite() {
                return Err(bad(format!("track {} is not finite", t.id)));
            }
            check_covariance("track covariance", &t.p)?;
            radars(&t.radars)?;
            check_modes(t, c)?;
            if t.started.is_some_and(|s| !s.is_finite()) {
                return Err(bad(format!("track {} start time is not finite", t.id)));
            }
            let hits = &t.detections;
            radars(&hits.iter().map(|h| h.radar).collect::<Vec<_>>())?;
            if hits.windows(2).any(|w| w[1].radar <= w[0].radar)
                || hits.iter().any(|h| !h.last.is_finite())
            {
                return Err(bad(format!(
                    "track {}'s hits per radar are not ascending by radar, or not finite",
                    t.id
                )));
            }
            if let Some(p) = &t.last_plot {
                c.validate_plot(p)?;
            }
            if t.id >= parts.next_id {
                return Err(bad(format!(
                    "track id {} not below the next id {}",
                    t.id, parts.next_id
                )));
            }
        }
        if parts.tentatives.iter().any(|t| !t.modes.is_empty()) {
            return Err(bad("a tentative track with IMM modes"));
        }
        for r in &parts.roots {
            let k = r.z.len();
            if !(2..=c.axes).contains(&k) || r.r.shape() != (k, k) {
                return Err(bad(format!("root plot of dimension {k}")));
            }
            if r.z.iter().any(|v| !v.is_finite()) || !r.t.is_finite() {
                return Err(bad("root plot is not finite"));
            }
            check_covariance("plot covariance", &r.r)?;
            radars(&r.radars)?;
            if let Some(p) = &r.measured {
                c.validate_plot(p)?;
            }
        }
        for p in &parts.pending {
            c.validate_plot(p)?;
        }
        if parts.pending.windows(2).any(|w| w[1].t < w[0].t) {
            return Err(bad("pending plots out of time order"));
        }
        if parts.last_time.is_some_and(|t| !t.is_finite()) {
            return Err(bad("last time is not finite"));
        }
        let radars = tr.config.radars.len();
        tr.reports_seen.0 = parts.pending.iter().any(|p| p.report.is_some())
            || parts.tracks.iter().chain(&parts.tentatives).any(|t| {
                t.identity.validation.last_self_reported.is_some()
                    || t.detections.iter().any(|h| h.radar >= radars)
            });
        tr.tracks = parts.tracks.into_iter().map(std::sync::Arc::new).collect();
        tr.initiator = Initiator::from_parts(parts.roots, parts.tentatives);
        tr.pending = parts.pending;
        tr.next_id = parts.next_id;
        tr.last_time = parts.last_time;
        tr.last_instant = parts.last_instant;
        tr.counters = parts.counters;
        if !parts.beams.is_empty() {
            check_beams("beam positions", &parts.beams, tr.config.radars.len())?;
            tr.beams = parts.beams;
        }
        tr.judged = if parts.judged.is_empty() {
            tr.beams.clone()
        } else {
            check_beams(
                "judged beam positions",
                &parts.judged,
                tr.config.radars.len(),
            )?;
            parts.judged
        };
        let po = &parts.pressure_offset;
        if po
            .information
            .iter()
            .chain(&po.vector)
            .chain(po.t.as_ref())
            .any(|v| !v.is_finite())
            || po.information[0] < 0.0
            || po.information[2] < 0.0
            || po.information[1].powi(2) > po.information[0] * po.information[2] * (1.0 + 1e-9)
        {
            return Err(bad(
                "pressure offset data not finite or not positive semi-definite",
            ));
        }
        tr.pressure_offset = parts.pressure_offset;
        if !parts.mode_s_radars.is_empty() {
            if parts.mode_s_radars.len() != tr.config.radars.len() {
                return Err(bad(format!(
                    "{} Mode S flags for {} radars",
                    parts.mode_s_radars.len(),
                    tr.config.radars.len()
                )));
            }
            tr.mode_s_radars = parts.mode_s_radars;
        }
        if let Some(state) = parts.accuracy {
            state.check(tr.config.radars.len())?;
            tr.accuracy = state;
            tr.refresh_applied();
        }
        if let Some(state) = parts.registration {
            state.check(&tr.config.radars)?;
            tr.registrar = Registrar::new(&tr.config, state, tr.reports_seen.0)?;
        } else if tr.reports_seen.0 {
            tr.registrar.refer(&tr.config)?;
        }
        Ok(tr)
    }
}
