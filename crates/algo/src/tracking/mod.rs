//! Multi-radar plot-fusion tracking (seed 001, the multi-radar plot fusion
//! patent, steps 1–8): a [`Tracker`] fed with polar plots of several radars
//! that keeps confirmed and tentative tracks in the fusion centre's ENU frame.
//!
//! The loop, per frame, reads like Stone Soup's `tracker/simple.py`, over
//! components ([`Tracker::run_frame`]): hypothesise (`hypothesiser`: the
//! tracks a plot may gate, from a spatial index), predict (`predictor`,
//! trait `Predictor`: CV or IMM), associate (`associator`: JPDA weights
//! through the EKF's linearisation), update (`updater`, trait `Updater`:
//! polar or fused Cartesian measurements, one IMM update path), delete
//! (`deleter`), initiate (`initiator`, the logic method), learn the
//! radars' biases (`registrar`). Tracks keep their own time: a track is
//! predicted only when a plot may gate it, when its miss is judged, or for
//! an output, so a plot costs the tracks it can touch, not the picture.
//! What a frame is depends on the mode (step 2):
//! - **parallel** (every radar gives Doppler): fusion instants
//!   t_k = epoch + k·T. The plots with τ ∈ (t_{k−1}, t_k] are registered
//!   (`conversion`, step 1), extrapolated to t_k along their line of
//!   sight (step 3), associated across radars by GNN and fused by ML
//!   weights (`plot_association`, step 4), then associated with the tracks
//!   (step 5). Instants without plots are skipped (no prediction, no miss).
//! - **serial** (step 6): plots in time order; each run of consecutive
//!   plots of one radar within `time_tolerance` of its first plot is a scan
//!   group, processed at the time of its last plot with that radar's polar
//!   EKF, tracks predicted over the variable Δt. Misses come from the
//!   beam, in bulk every 1/16 scan of a radar ([`Tracker::judge_sweep`]).
//!   Every track is judged by parallel instants.
//!
//! Streaming: plots are buffered and a frame is processed only once it is
//! complete — a later frame's plot has arrived, or [`Tracker::flush`] is
//! called. So feeding plots in chunks that arrive in time order (every
//! plot of a later chunk no earlier than every plot of an earlier one)
//! gives bit-for-bit the state of one call with all plots, also when the
//! tracker is taken apart and rebuilt between chunks ([`Tracker::state`],
//! [`Tracker::from_parts`]; the `formats` crate stores those parts as bytes).
//! Within a call plots are sorted by time, stably. A plot older than the
//! last processed frame (serial: t < its time; parallel: τ ≤ the last
//! processed instant) is *late*: it is dropped, counted, and its index
//! returned in [`StepReport::late`] (no out-of-sequence update).
//!
//! Errors: plots are validated before the tracker changes. A track whose
//! numbers fail in a frame (its prediction, IMM mixing, association
//! likelihood or update non-finite or not positive definite; a tentative
//! track's likewise) is dropped, or coasts past an out-of-sequence plot,
//! and is named in [`StepReport::failed`] ([`FailedStep`] says which and
//! why): the frame and the call go on. Any other numerical error leaves
//! the tracker part-way through the call, so a caller that must stay
//! consistent keeps the stored state and retries from it.

pub mod accuracy;
pub mod associator;
pub mod config;
pub mod conversion;
mod deleter;
pub mod height;
mod hypothesiser;
pub mod identity;
pub mod initiator;
pub mod parameter;
pub mod plot_association;
pub mod predictor;
mod registrar;
pub mod registration;
mod retrodiction;
mod state;
mod sweep;
mod track;
pub mod updater;
mod validation;
pub mod window;

#[cfg(test)]
mod failure_tests;
#[cfg(test)]
mod report_tests;
#[cfg(test)]
mod tests;

pub use config::{
    Deletion, Imm, Initiation, Mode, Motion, MotionModel, NoiseModel, Plot, RadarSpec, Report,
    ReportKind, TrackerConfig, ValidTrackerConfig, VelocityGate,
};
pub use conversion::{CartesianPlot, Doppler, Linearised, RangeRate, VelocityComponent};
pub use identity::{
    Detection, Disagreement, Emergency, Identity, Mode3A, ModeC, TrackIdentity, Validation,
};
pub use parameter::TrackerParameter;
pub use state::{TrackerParts, TrackerState};
pub use track::{RadarHit, Track, TrackOutput, TrackStatus};
pub use window::{LagWindow, LagWindowParts, LagWindowState, LatePolicy, Push};

use std::{ops::ControlFlow, sync::Arc};

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::jpda::{self, TrackEstimate};
use associator::{
    Outcome, associate_cartesian, associate_polar, cartesian_clutter, polar_layout,
    range_rate_sigma,
};
use conversion::{extrapolate, register, report_plot};
use hypothesiser::TrackIndex;
use initiator::{Initiated, Initiator, Misses};
use plot_association::associate_and_fuse_members;
use predictor::{CvPredictor, ModeState, Predictor, TrackPredictor};
use registrar::{Hit, Registrar};
use registration::{RadarBias, RegistrationState};
use sweep::View;
use track::Prediction;
use updater::{CartesianUpdater, PolarUpdater, Updater};

/// Running totals since the tracker was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Plots accepted (not late).
    pub plots: u64,
    /// Late plots dropped.
    pub late: u64,
    /// Frames processed (scan groups or fusion instants).
    pub frames: u64,
    /// Fused plots produced by parallel mode (one per associated group).
    pub fused_plots: u64,
    /// Tentative tracks started.
    pub started: u64,
    /// Tentative tracks confirmed.
    pub confirmed: u64,
    /// Tentative tracks dropped without being confirmed.
    pub dropped: u64,
    /// Confirmed tracks deleted.
    pub deleted: u64,
    /// Confirmed tracks deleted as duplicates of another (see
    /// [`TrackerConfig::duplicate_gate_probability`]).
    pub merged: u64,
}

/// What one call of [`Tracker::process`] or [`Tracker::flush`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepReport {
    /// Frames processed.
    pub frames: usize,
    /// Indices (into the call's plots) of the late plots, dropped.
    pub late: Vec<usize>,
    /// Ids of the tracks confirmed, in order.
    pub confirmed: Vec<u64>,
    /// The tracks deleted, as they were when deleted (status `Deleted`).
    pub deleted: Vec<TrackOutput>,
    /// Plots buffered for a frame not yet complete.
    pub pending: usize,
    /// Tentative tracks not started because the tracker held its bound
    /// of tracks ([`Tracker::set_max_tracks`]).
    pub refused: usize,
    /// Ids of confirmed tracks a frame could not associate: their
    /// prediction lay at (or straight above) the radar's site, where its
    /// azimuth is undefined (an overflight within
    /// [`crate::polar::MIN_HORIZONTAL_RANGE`]); they coast through that
    /// frame, the rest of the frame applies. One entry per such frame.
    pub undefined: Vec<u64>,
    /// Tracks whose numbers failed in a frame (a non-finite value, a
    /// covariance that is not positive definite): each dropped or coasted
    /// as [`FailedStep`] says, the rest of the frame applied. A confirmed
    /// track dropped so is not in `deleted` (its numbers are what failed):
    /// its last good report is the caller's.
    pub failed: Vec<TrackFailure>,
}

/// A track whose numbers failed in a frame ([`StepReport::failed`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TrackFailure {
    /// The track's id.
    pub id: u64,
    /// Whether it was confirmed (else tentative).
    pub confirmed: bool,
    /// The frame's time.
    pub t: f64,
    /// Where it failed, and so what became of it.
    pub step: FailedStep,
    /// What failed.
    pub error: AlgoError,
}

impl TrackFailure {
    /// Whether the track was dropped (else it coasted).
    pub fn dropped(&self) -> bool {
        self.step != FailedStep::Carry
    }
}

/// Where a track's numbers failed, and what the tracker does about it.
///
/// The rule: a failure that shows the track's own state broken is final,
/// so the track is dropped; a failure of an approximation applied to a
/// sound track is that step's, so the track coasts. The inputs of a
/// track's prediction, association and update other than the track's
/// state and covariance are checked before they reach the tracker (plots,
/// radars: every R positive definite) or come from the frame's
/// association (weights in [0, 1]). A prediction is F x, F P F′ + Q (IMM:
/// mixing, then each model's step) of the track alone; an innovation
/// covariance H P H′ + R with R positive definite fails only when P is no
/// covariance; an update of a sound prediction by a valid plot (the polar
/// EKF in Joseph form, the IMM's model probabilities) stays finite and
/// positive definite. So a failure at any of them means the track's
/// numbers are broken, and a coast would try the same numbers again at
/// the next frame (and gate the plots of its target, which could then
/// start no new track), so the track is dropped, like a track the
/// deleter removes, and its target's next plots start a new one. The one
/// approximation is the carry of an out-of-sequence plot's update back to
/// a newer track (retrodiction, `retrodiction.rs`): its covariance
/// reduction can lose positive definiteness for a sound track, so there
/// the late plot is not applied and the track coasts as it was. A
/// tentative track is dropped whatever failed: it has no history worth a
/// coast, and its plots start it again. (Degenerate geometry at a radar's
/// site is no failure of numbers: that track coasts, listed in
/// [`StepReport::undefined`].)
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailedStep {
    /// The prediction (a confirmed track's, IMM mixing included, or its
    /// retrodiction to an out-of-sequence plot; also for a miss judged
    /// from the beam): dropped.
    Predict,
    /// The association's likelihood (the innovation covariance of its
    /// prediction): dropped.
    Associate,
    /// The update with the frame's plots: dropped.
    Update,
    /// The carry of an out-of-sequence plot's update back to the track's
    /// time: the plot is not applied, the track coasts.
    Carry,
    /// A tentative track's prediction, gating or update: dropped.
    Initiate,
}

/// The tracker: configuration plus everything carried between calls.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracker {
    config: TrackerConfig,
    parallel: bool,
    /// Confirmed tracks, shared copy-on-write: a clone of the tracker (the
    /// lag window keeps several a batch) copies a track only when one of
    /// the two changes it.
    tracks: Vec<Arc<Track>>,
    initiator: Initiator,
    /// Accepted plots of frames not yet complete, sorted by time (stable).
    pending: Vec<Plot>,
    next_id: u64,
    /// Time of the last processed frame.
    last_time: Option<f64>,
    /// Parallel mode: index k of the last processed fusion instant.
    last_instant: Option<i64>,
    counters: Counters,
    /// Serial mode, per radar: time and azimuth of the last plot of its
    /// last frame (where its beam was; [`sweep`]).
    beams: Vec<Option<(f64, f64)>>,
    /// Serial mode, per radar: where its beam was when misses were last
    /// judged from its sweep ([`Tracker::judge_sweep`]).
    judged: Vec<Option<(f64, f64)>>,
    /// The hypothesiser's index of the confirmed tracks (derived, never
    /// stored).
    index: TrackIndex,
    /// The predictor of confirmed tracks (with its cache of IMM steps).
    predictor: TrackPredictor,
    /// The registrar: the radars' biases learnt online.
    registrar: Registrar,
    /// The pressure-to-geometric offset learnt online
    /// ([`height`]).
    pressure_offset: height::PressureOffset,
    /// Per radar: it has given a Mode S address (so a secondary plot of
    /// it without one is a Mode A/C transponder's,
    /// [`identity::without_mode_s`]).
    mode_s_radars: Vec<bool>,
    /// Each radar's accuracy learnt online ([`accuracy`]).
    accuracy: accuracy::AccuracyState,
    /// Each radar as the tracker applies it: the declared radar with the
    /// σ of [`accuracy`] (derived from `accuracy`, never stored).
    applied: Vec<RadarSpec>,
    /// Buffers a frame reuses (derived, never stored).
    scratch: Derived<Scratch>,
    /// Most live tracks, confirmed and tentative: no tentative track is
    /// started beyond it (a session's limit; set by its owner, not stored).
    max_tracks: Derived<Option<usize>>,
    /// Serial mode: plots older than the last frame are processed as
    /// frames of their own, the tracks newer than them updated by
    /// retrodiction ([`Tracker::set_out_of_sequence`]; set by the owner,
    /// not stored).
    out_of_sequence: Derived<bool>,
    /// A cooperative report (ADS-B, MLAT, AIS) has reached the tracker
    /// (the check of [`validation`] runs only then, and a lone radar is
    /// registered against reports; derived from the tracks).
    reports_seen: Derived<bool>,
}

/// A frame's plots as the associator needs them.
enum Source {
    /// Serial mode: one radar's plots, corrected for its bias, with the
    /// radar as the update sees it (variances grown by the bias's) and the
    /// Mode C height measurement of a 3D tracker ([`height`]).
    Radar {
        spec: RadarSpec,
        plots: Vec<Plot>,
        height: Option<height::HeightMeasurement>,
    },
    /// Parallel mode: fused Cartesian plots with their clutter densities.
    Fused {
        clutter: Vec<f64>,
        detection_probability: f64,
    },
    /// Serial mode: cooperative reports of one kind ([`ReportKind`]), as
    /// they came (their identities beside their positions).
    Reports {
        kind: ReportKind,
        plots: Vec<Plot>,
        clutter: Vec<f64>,
    },
}

/// Whether only cooperative reports (sensors past the `radars`), and
/// never radar `radar`, have updated `track`: that radar's sweep says
/// nothing of it (a ship an air surveillance radar does not see, an
/// aircraft below its coverage), and the reports judge its misses
/// ([`report_coasted`]). A track no report has updated is judged as ever.
fn reports_only_for(track: &Track, radar: usize, radars: usize) -> bool {
    track.sensors().any(|i| i >= radars) && !track.sensors().any(|i| i == radar)
}

/// Whether cooperative reports (sensors past the `radars`) have updated `track` (its last hit, or a
/// hit it keeps per sensor) and nothing has updated it for the shortest
/// [`ReportKind::coast_s`] of their kinds by `t` (nor has a miss been
/// judged since: a judged miss predicts the track to its time).
fn report_coasted(radars: usize, track: &Track, t: f64) -> bool {
    track
        .sensors()
        .filter_map(|i| ReportKind::ALL.get(i.checked_sub(radars)?).copied())
        .map(ReportKind::coast_s)
        .reduce(f64::min)
        .is_some_and(|c| t - track.last_update.max(track.t) >= c)
}

/// Density of false cooperative reports (per unit of the report's
/// measurement space: m² or m³, times (m/s)² per velocity component):
/// a report is an aircraft's or a ship's own, so clutter is negligible;
/// small but positive, so that a report far in its gate still weighs
/// against the miss.
const REPORT_CLUTTER_DENSITY: f64 = 1e-12;
/// Detection probability of a cooperative sensor within a frame: reports
/// are lost on the air and at the ground station.
const REPORT_DETECTION_PROBABILITY: f64 = 0.9;

impl Tracker {
    /// A tracker without tracks; fails when the configuration is invalid.
    pub fn new(config: TrackerConfig) -> Result<Self, AlgoError> {
        Self::with_config(config.validated()?)
    }

    /// A tracker without tracks over a configuration already checked.
    pub fn with_config(config: ValidTrackerConfig) -> Result<Self, AlgoError> {
        let config = config.into_inner();
        let beams = vec![None; config.radars.len()];
        let registrar = Registrar::new(&config, RegistrationState::new(&config.radars), false)?;
        Ok(Self {
            registrar,
            pressure_offset: height::PressureOffset::default(),
            mode_s_radars: vec![false; config.radars.len()],
            accuracy: accuracy::AccuracyState::new(config.radars.len()),
            applied: config.radars.clone(),
            predictor: TrackPredictor::of(&config),
            parallel: config.is_parallel(),
            config,
            tracks: Vec::new(),
            initiator: Initiator::default(),
            pending: Vec::new(),
            next_id: 1,
            last_time: None,
            last_instant: None,
            counters: Counters::default(),
            judged: beams.clone(),
            beams,
            index: TrackIndex::default(),
            scratch: Derived::default(),
            max_tracks: Derived::default(),
            out_of_sequence: Derived::default(),
            reports_seen: Derived::default(),
        })
    }

    /// The validated configuration.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// A copy of the configuration, as checked when the tracker was made.
    pub fn valid_config(&self) -> ValidTrackerConfig {
        ValidTrackerConfig::trusted(self.config.clone())
    }

    /// The resolved mode: `Mode::Parallel` or `Mode::Serial`.
    pub fn mode(&self) -> Mode {
        if self.parallel {
            Mode::Parallel
        } else {
            Mode::Serial
        }
    }

    /// Running totals since the tracker was created.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Time of the last processed frame.
    pub fn last_time(&self) -> Option<f64> {
        self.last_time
    }

    /// Each radar's bias as the tracker applies it now (estimate and σ
    /// once converged, else the prior).
    pub fn biases(&self) -> &[RadarBias] {
        &self.registrar.biases
    }

    /// The pressure-to-geometric offset a 3D tracker applies to Mode C
    /// ([`height`]), with its data; `None` when Mode C heights are off or
    /// the tracker is 2D.
    pub fn pressure_offset(&self) -> Option<(height::OffsetEstimate, &height::PressureOffset)> {
        self.height_measurement()
            .map(|m| (m.offset, &self.pressure_offset))
    }

    /// Each radar's accuracy: declared, estimated and applied σ
    /// ([`accuracy`]), by radar index.
    pub fn accuracy(&self) -> Vec<accuracy::RadarAccuracy> {
        let c = &self.config;
        (0..c.radars.len())
            .map(|r| {
                self.accuracy
                    .radar(&c.accuracy, r, &c.radars[r], c.track_gate_probability)
            })
            .collect()
    }

    /// Every radar as applied recomputed from the accuracy data.
    fn refresh_applied(&mut self) {
        let c = &self.config;
        self.applied = (0..c.radars.len())
            .map(|r| {
                self.accuracy
                    .applied(&c.accuracy, r, &c.radars[r], c.track_gate_probability)
            })
            .collect();
    }

    /// Number of buffered plots.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Confirmed tracks then tentative tracks, each by ascending id, every
    /// one predicted to the time of the last frame (a track keeps its own
    /// time, that of its last update or miss; [`Track::t`]).
    pub fn tracks(&self) -> Vec<TrackOutput> {
        let tentatives = &self.initiator.tentatives;
        let mut out = Vec::with_capacity(self.tracks.len() + tentatives.len());
        self.push_confirmed(&mut out);
        let mut cv = CvPredictor::of(&self.config);
        // Ordered by id before the outputs are made (ids are unique): the
        // outputs are large, the references small.
        let mut order: Vec<&Track> = tentatives.iter().collect();
        order.sort_unstable_by_key(|t| t.id);
        out.extend(
            order
                .into_iter()
                .map(|t| self.output(t, TrackStatus::Tentative, &mut cv)),
        );
        out
    }

    /// Accepts plots (any order; sorted by time inside, stably), processes
    /// every frame that is complete, and buffers the rest.
    pub fn process(&mut self, plots: &[Plot]) -> Result<StepReport, AlgoError> {
        self.process_with(plots, false, &mut |_| ControlFlow::Continue(()))
    }

    /// [`Tracker::process`], then [`Tracker::flush`] when `flush`, calling
    /// `after_frame` with the tracker after every processed frame (for a
    /// track history). Plots already sorted by time are inserted in O(1).
    /// `after_frame` answering `Break` stops there: the plots of the later
    /// frames stay buffered, as if they had not come yet (a caller that was
    /// abandoned stops its work).
    pub fn process_with(
        &mut self,
        plots: &[Plot],
        flush: bool,
        after_frame: &mut dyn FnMut(&Self) -> ControlFlow<()>,
    ) -> Result<StepReport, AlgoError> {
        for plot in plots {
            self.config.validate_plot(plot)?;
            if self.parallel {
                self.instant_of(plot.t)?;
            }
        }
        let mut report = StepReport::default();
        self.pending.reserve(plots.len());
        for (i, plot) in plots.iter().enumerate() {
            if self.is_late(plot)? {
                report.late.push(i);
                self.counters.late += 1;
                continue;
            }
            self.counters.plots += 1;
            if self.pending.last().is_none_or(|p| p.t <= plot.t) {
                self.pending.push(*plot);
            } else {
                let at = self.pending.partition_point(|p| p.t <= plot.t);
                self.pending.insert(at, *plot);
            }
        }
        self.drain(flush, &mut report, after_frame)?;
        Ok(report)
    }

    /// Whether `plot`, at or after every buffered plot, would close the
    /// buffered frame without joining it (a later scan group or another
    /// radar in serial mode, a later fusion instant in parallel mode): then
    /// processing it gives the same tracker as [`Tracker::flush`] first.
    /// `false` when nothing is buffered.
    pub fn closes_pending(&self, plot: &Plot) -> Result<bool, AlgoError> {
        let Some(first) = self.pending.first() else {
            return Ok(false);
        };
        Ok(if self.parallel {
            self.instant_of(plot.t)? != self.instant_of(first.t)?
        } else {
            !(plot.radar == first.radar && plot.t - first.t <= self.config.time_tolerance)
        })
    }

    /// Bounds the live tracks (confirmed and tentative): at `max`, a frame
    /// starts no tentative track and counts the starts it refused
    /// ([`StepReport::refused`]); tracks already held go on. Not stored.
    pub fn set_max_tracks(&mut self, max: Option<usize>) {
        self.max_tracks.0 = max;
    }

    /// Out-of-sequence plots (serial mode): when on, a plot older than the
    /// last processed frame is not late but processed as a frame at its
    /// own time; a track newer than it is updated where it stands by
    /// retrodiction (`retrodiction.rs`: the plot's update at its time
    /// carried to the track's), a track older predicted forward as usual,
    /// a tentative track likewise, an unused plot a root. Nothing is
    /// replayed: the cost is the tracks the plot may gate. Registration
    /// learns from in-sequence hits only, and the beam's misses are judged
    /// in each radar's own time (a late plot judges none). Parallel mode
    /// ignores it (its late plots stay late). Not stored.
    pub fn set_out_of_sequence(&mut self, on: bool) {
        self.out_of_sequence.0 = on;
    }

    /// Processes every buffered plot, closing the last frame. Plots that
    /// arrive later for that frame will be late.
    pub fn flush(&mut self) -> Result<StepReport, AlgoError> {
        self.process_with(&[], true, &mut |_| ControlFlow::Continue(()))
    }

    /// The ids of every live track, confirmed and tentative (no copies of
    /// their states).
    pub fn track_ids(&self) -> impl Iterator<Item = u64> + '_ {
        self.tracks
            .iter()
            .map(|t| t.id)
            .chain(self.initiator.tentatives.iter().map(|t| t.id))
    }

    /// The number of confirmed tracks ([`Tracker::confirmed_tracks`]'s
    /// length, without building them).
    pub fn confirmed_count(&self) -> usize {
        self.tracks.len()
    }

    /// The confirmed tracks by ascending id, predicted to the time of the
    /// last frame.
    pub fn confirmed_tracks(&self) -> Vec<TrackOutput> {
        let mut out = Vec::with_capacity(self.tracks.len());
        self.push_confirmed(&mut out);
        out
    }

    /// The confirmed tracks' outputs by id, pushed onto `out`.
    fn push_confirmed(&self, out: &mut Vec<TrackOutput>) {
        // One predictor for all (its IMM steps are asked again and again).
        let mut predictor = TrackPredictor::of(&self.config);
        let mut order: Vec<&Track> = self.tracks.iter().map(|t| &**t).collect();
        order.sort_unstable_by_key(|t| t.id);
        out.extend(
            order
                .into_iter()
                .map(|t| self.output(t, TrackStatus::Confirmed, &mut predictor)),
        );
    }

    /// A track predicted to the last frame's time by `predictor` (a
    /// confirmed track's, or a tentative track's constant velocity).
    fn output(
        &self,
        track: &Track,
        status: TrackStatus,
        predictor: &mut dyn Predictor,
    ) -> TrackOutput {
        match self.last_time {
            Some(t) => track.output_at(t, predictor, status),
            None => track.output(status),
        }
    }

    fn is_late(&self, plot: &Plot) -> Result<bool, AlgoError> {
        Ok(if self.parallel {
            let k = self.instant_of(plot.t)?;
            self.last_instant.is_some_and(|last| k <= last)
        } else {
            !self.out_of_sequence.0 && self.last_time.is_some_and(|last| plot.t < last)
        })
    }

    /// Index k of the fusion instant of a plot at τ: the smallest k with
    /// τ ≤ epoch + k·T.
    fn instant_of(&self, tau: f64) -> Result<i64, AlgoError> {
        let k = ((tau - self.config.fusion_epoch) / self.config.fusion_period).ceil();
        if k.abs() < 9.0e15 {
            Ok(k as i64)
        } else {
            Err(AlgoError::InvalidParameter {
                what: "t",
                reason: format!("{tau} is too far from fusion_epoch for fusion_period"),
            })
        }
    }

    fn instant_time(&self, k: i64) -> f64 {
        self.config.fusion_epoch + k as f64 * self.config.fusion_period
    }

    /// Processes the complete frames at the head of `pending` (all with `flush`).
    fn drain(
        &mut self,
        flush: bool,
        report: &mut StepReport,
        after_frame: &mut dyn FnMut(&Self) -> ControlFlow<()>,
    ) -> Result<(), AlgoError> {
        // Frames are taken from the front by a cursor, the buffer cut
        // once at the end (draining each frame from the front would move
        // every later plot: quadratic in a call's plots).
        let pending = std::mem::take(&mut self.pending);
        let mut head = 0;
        let result = self.drain_frames(&pending, &mut head, flush, report, after_frame);
        self.pending = pending;
        self.pending.drain(..head);
        result?;
        self.initiator.compact();
        report.pending = self.pending.len();
        Ok(())
    }

    /// The frames of `pending[*head..]` that are complete (all with
    /// `flush`), `head` advanced past each one processed.
    fn drain_frames(
        &mut self,
        pending: &[Plot],
        head: &mut usize,
        flush: bool,
        report: &mut StepReport,
        after_frame: &mut dyn FnMut(&Self) -> ControlFlow<()>,
    ) -> Result<(), AlgoError> {
        while *head < pending.len() {
            let rest = &pending[*head..];
            let first = rest[0];
            let len = if self.parallel {
                let k = self.instant_of(first.t)?;
                let mut n = 0;
                while n < rest.len() && self.instant_of(rest[n].t)? == k {
                    n += 1;
                }
                n
            } else {
                let tol = self.config.time_tolerance;
                rest.iter()
                    .take_while(|p| p.radar == first.radar && p.t - first.t <= tol)
                    .count()
            };
            if len == rest.len() && !flush {
                break;
            }
            let frame: Vec<Plot> = rest[..len].to_vec();
            *head += len;
            if self.parallel {
                self.parallel_frame(self.instant_of(first.t)?, frame, report)?;
            } else {
                self.serial_frame(frame, report)?;
            }
            if after_frame(self).is_break() {
                break;
            }
        }
        Ok(())
    }

    /// Step 6: one radar's scan group at the time of its last plot; then
    /// the misses of the sector its beam swept, when due.
    fn serial_frame(&mut self, frame: Vec<Plot>, report: &mut StepReport) -> Result<(), AlgoError> {
        let index = frame[0].radar;
        if let Some(kind) = self.config.report_kind(index) {
            return self.report_frame(kind, frame, report);
        }
        if frame.iter().any(|p| p.identity.address.is_some()) {
            self.mode_s_radars[index] = true;
        }
        let bias = self.registrar.biases[index];
        let spec = registration::inflated(&self.applied[index], &bias);
        let corrected: Vec<Plot> = frame
            .iter()
            .map(|p| registration::correct(p, &bias))
            .collect();
        let last = corrected[corrected.len() - 1];
        let t = last.t;
        if self.beams[index].is_none_or(|(t0, _)| t >= t0) {
            self.beams[index] = Some((t, last.azimuth));
        }
        // The measured plot a track reports (and registration pairs) is
        // the raw one.
        let mut plots = corrected
            .iter()
            .zip(&frame)
            .map(|(p, raw)| {
                register(&spec, index, p).map(|mut c| {
                    c.measured = Some(*raw);
                    c
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        // A 3D radar's plot with Mode C: what it says of the pressure
        // offset (learnt from the plots that update a track), and its
        // height made the Mode C one (for the initiator and the index).
        let height = self.height_measurement();
        let offset_observations = self.mode_c_plots(height.as_ref(), &corrected, &mut plots)?;
        let source = Source::Radar {
            spec: spec.clone(),
            plots: corrected,
            height,
        };
        // Out of sequence, a frame at or before its radar's last judged
        // sweep: its hits replace the misses that sweep judged (in
        // sequence a radar's frames follow its judgements).
        self.scratch.0.behind_sweep =
            self.out_of_sequence.0 && self.judged[index].is_some_and(|(tj, _)| t <= tj);
        let hits = self.run_frame(t, source, plots, report)?;
        self.scratch.0.behind_sweep = false;
        if Registrar::learns(&self.config) {
            self.registrar
                .learn_serial(&self.config, &self.applied, &self.tracks, index, &hits)?;
        }
        // The frame's detection trials (judged against the σ as they stood
        // before it) and innovations; the radar as applied, once.
        let (scans, innovations) = (&self.scratch.0.scans_since_hit, &self.scratch.0.innovations);
        let cfg = &self.config;
        let learns_detection = cfg.accuracy.enabled && !scans.is_empty();
        if learns_detection {
            self.accuracy
                .detections(&cfg.accuracy, index, &cfg.radars[index], t, scans);
        }
        if !innovations.is_empty() {
            self.accuracy
                .learn(&cfg.accuracy, index, &cfg.radars[index], t, innovations);
        }
        if learns_detection || !innovations.is_empty() {
            self.applied[index] = self.accuracy.applied(
                &cfg.accuracy,
                index,
                &cfg.radars[index],
                cfg.track_gate_probability,
            );
        }
        if !offset_observations.is_empty() {
            let prior = self.config.mode_c_height;
            for hit in &hits {
                if let Some((t, h_p, h_r, var)) = offset_observations[hit.plot] {
                    self.pressure_offset.learn(&prior, t, h_p, h_r, var);
                }
            }
        }
        self.judge_sweep(index, &spec, t, last.azimuth, report)
    }

    /// Cooperative reports of one kind ([`ReportKind`]) at the time of the
    /// last: each its own position (and velocity) with its stated σ, the
    /// linear update; no bias, no beam. Then, once per second of the
    /// tracker's time, the tracks reports have updated and nothing has
    /// updated for their kind's [`ReportKind::coast_s`] are judged missed
    /// ([`Tracker::judge_reports`]).
    fn report_frame(
        &mut self,
        kind: ReportKind,
        frame: Vec<Plot>,
        report: &mut StepReport,
    ) -> Result<(), AlgoError> {
        let t = frame[frame.len() - 1].t;
        let before = self.last_time;
        let axes = self.config.axes;
        let plots: Vec<CartesianPlot> = frame.iter().map(|p| report_plot(p, axes)).collect();
        let clutter = vec![REPORT_CLUTTER_DENSITY; plots.len()];
        let source = Source::Reports {
            kind,
            plots: frame.clone(),
            clutter,
        };
        let hits = self.run_frame(t, source, plots, report)?;
        if Registrar::learns(&self.config) {
            let hits = self.reference_hits(t, &frame, hits)?;
            self.registrar.learn_reports(
                &self.config,
                &self.applied,
                &self.tracks,
                &frame,
                &hits,
            )?;
        }
        if before.is_none_or(|b| b.floor() < t.floor()) {
            self.judge_reports(t, report);
        }
        Ok(())
    }

    /// The hits of a report frame (reports `frame`) that registration
    /// learns from: the track trusts its self-reported positions with no
    /// disagreement pending, has a last radar plot, and is isolated: no
    /// other confirmed track passes the gate's pre-test at the report with
    /// that radar's covariance as applied (its bias's σ included). In a
    /// crowd (moored ships a few tens of metres apart, a bias of the same
    /// size) the plot a track took may be a neighbour's, and the nearer of
    /// two plots is chosen, which would pull the estimate towards zero.
    fn reference_hits(
        &mut self,
        t: f64,
        frame: &[Plot],
        hits: Vec<Hit>,
    ) -> Result<Vec<Hit>, AlgoError> {
        let radars = self.config.radars.len();
        let mut out = Vec::with_capacity(hits.len());
        for h in hits {
            let v = &self.tracks[h.slot].identity.validation;
            if !v.trusted() || v.disagreements > 0 {
                continue;
            }
            let Some(older) = h
                .previous
                .filter(|p| p.report.is_none() && p.radar < radars)
            else {
                continue;
            };
            let bias = self.registrar.biases[older.radar];
            let spec = registration::inflated(&self.applied[older.radar], &bias);
            let radar_plot = register(&spec, older.radar, &registration::correct(&older, &bias))?;
            let mut probe = report_plot(&frame[h.plot], self.config.axes);
            probe.r = radar_plot.r;
            let near = self.index.candidates(
                &self.tracks,
                std::slice::from_ref(&probe),
                t,
                &self.config,
            )?;
            if near.iter().all(|&s| s == h.slot) {
                out.push(h);
            }
        }
        Ok(out)
    }

    /// The misses of tracks that cooperative reports have updated: one when
    /// nothing has updated the track for the shortest
    /// [`ReportKind::coast_s`] of the kinds that did (a radar's own sweeps
    /// judge it where a radar covers it), and again after as long.
    fn judge_reports(&mut self, t: f64, report: &mut StepReport) {
        let radars = self.config.radars.len();
        self.judge_misses(t, &|tr: &Track| report_coasted(radars, tr, t), report);
    }

    /// The Mode C height measurement of this tracker's frames: a 3D
    /// tracker's with Mode C heights on ([`height`]).
    fn height_measurement(&self) -> Option<height::HeightMeasurement> {
        let c = &self.config;
        (c.axes == 3 && c.mode_c_height.enabled).then(|| height::HeightMeasurement {
            datum: c.height_datum,
            offset: self.pressure_offset.estimate(&c.mode_c_height),
        })
    }

    /// Per plot of a serial frame (radar plots `raw`, converted `plots`),
    /// with the frame's height measurement `m`: for a 3D radar's plot with
    /// a validated Mode C, the offset observation (t, h_p, H_r, var) its
    /// converted position gives (when learning; empty otherwise), and the
    /// converted position updated with the Mode C height.
    #[allow(clippy::type_complexity)]
    fn mode_c_plots(
        &self,
        m: Option<&height::HeightMeasurement>,
        raw: &[Plot],
        plots: &mut [CartesianPlot],
    ) -> Result<Vec<Option<(f64, f64, f64, f64)>>, AlgoError> {
        let Some(m) = m else {
            return Ok(Vec::new());
        };
        let learn = self.config.mode_c_height.learn;
        let mut out = Vec::new();
        for (k, (p, c)) in raw.iter().zip(plots.iter_mut()).enumerate() {
            let Some(h_p) = height::pressure_altitude_m(&p.identity) else {
                continue;
            };
            if c.z.len() != 3 {
                continue;
            }
            if learn {
                let (h_r, g) = m.datum.height(c.z[0], c.z[1], c.z[2]);
                let var: f64 = (0..3)
                    .map(|i| (0..3).map(|j| g[i] * c.r[(i, j)] * g[j]).sum::<f64>())
                    .sum();
                if out.is_empty() {
                    out = vec![None; raw.len()];
                }
                out[k] = Some((p.t, h_p, h_r, var));
            }
            let var_q = height::quantisation_variance_m2(&p.identity);
            m.update(
                c.z.as_mut_slice(),
                c.r.as_mut_slice(),
                [0, 1, 2],
                h_p,
                var_q,
            )?;
        }
        Ok(out)
    }

    /// Misses from the beam of radar `index` (serial mode), judged in
    /// bulk once it has swept 1/[`JUDGE_SLICES`] of its period since the
    /// last judgement (and at its first frame): every track, confirmed or
    /// tentative, that the swept sector judges ([`View`]: in the sector,
    /// and no update in the last half scan) is predicted to `t` and gets a
    /// miss; the deletion rules then apply to it. A whole-turn view
    /// (a radar's first frame, or a gap) judges every track not updated
    /// at `t`.
    fn judge_sweep(
        &mut self,
        index: usize,
        spec: &RadarSpec,
        t: f64,
        azimuth: f64,
        report: &mut StepReport,
    ) -> Result<(), AlgoError> {
        if let Some((t0, _)) = self.judged[index] {
            if t - t0 < spec.scan_period / JUDGE_SLICES {
                return Ok(());
            }
        }
        let view = View::of_frame(spec, self.judged[index], t, azimuth);
        self.judged[index] = Some((t, azimuth));
        let radars = self.config.radars.len();
        let judge = |tr: &Track| -> bool {
            if tr.last_update >= t || reports_only_for(tr, index, radars) {
                return false;
            }
            let dt = t - tr.t;
            view.misses_at(
                tr.x[0] + tr.x[1] * dt,
                tr.x[2] + tr.x[3] * dt,
                tr.last_update,
            )
        };
        self.judge_misses(t, &judge, report);
        Ok(())
    }

    /// Records a miss at `t` of every track `judge` says missed (confirmed:
    /// predicted to `t` unless newer, an out-of-sequence radar's later plot
    /// having updated it; deleted by the rule or when its prediction fails;
    /// tentative: the initiator's judgement).
    fn judge_misses(&mut self, t: f64, judge: &dyn Fn(&Track) -> bool, report: &mut StepReport) {
        let cfg = &self.config;
        let mut doomed = Vec::new();
        for (k, track) in self.tracks.iter_mut().enumerate() {
            if !judge(track) {
                continue;
            }
            let track = Arc::make_mut(track);
            if track.t <= t {
                if let Err(error) = self.predictor.predict(track, t) {
                    // Its prediction failed: dropped (see `FailedStep`).
                    report.failed.push(TrackFailure {
                        id: track.id,
                        confirmed: true,
                        t,
                        step: FailedStep::Predict,
                        error,
                    });
                    doomed.push((k, Doom::Failed));
                    continue;
                }
            }
            track.record(None);
            self.index.moved(k, track);
            if deleter::should_delete(track, &cfg.deletion) {
                doomed.push((k, Doom::Rule));
            }
        }
        self.delete(doomed, report);
        let mut dropped = Initiated::default();
        self.initiator.judge(t, &self.config, judge, &mut dropped);
        self.counters.dropped += dropped.dropped as u64;
        report.failed.extend(dropped.failed);
    }

    /// Removes tracks (slot, why), reporting each as it was in
    /// [`StepReport::deleted`] (but those whose numbers failed: their
    /// failure is reported), by ascending slot (others take their places:
    /// `swap_remove`). Returns the moves (from, to) of the tracks that
    /// took their places.
    fn delete(
        &mut self,
        doomed: Vec<(usize, Doom)>,
        report: &mut StepReport,
    ) -> Vec<(usize, usize)> {
        if doomed.is_empty() {
            return Vec::new();
        }
        let why: std::collections::HashMap<usize, Doom> = doomed.iter().copied().collect();
        let slots = doomed.into_iter().map(|d| d.0).collect();
        let (removed, moves) =
            hypothesiser::swap_remove_all(&mut self.tracks, slots, &mut self.index);
        for (slot, track) in removed {
            match why[&slot] {
                Doom::Duplicate => self.counters.merged += 1,
                Doom::Rule => self.counters.deleted += 1,
                Doom::Failed => {
                    self.counters.deleted += 1;
                    continue;
                }
            }
            report.deleted.push(track.output(TrackStatus::Deleted));
        }
        moves
    }

    /// Steps 3–5: the plots of fusion instant k.
    fn parallel_frame(
        &mut self,
        k: i64,
        frame: Vec<Plot>,
        report: &mut StepReport,
    ) -> Result<(), AlgoError> {
        let t = self.instant_time(k);
        let manoeuvre_q = self.config.largest_process_noise();
        let specs: Vec<RadarSpec> = self
            .applied
            .iter()
            .zip(&self.registrar.biases)
            .map(|(r, b)| registration::inflated(r, b))
            .collect();
        let registered = frame
            .iter()
            .map(|p| {
                extrapolate(
                    &specs[p.radar],
                    p.radar,
                    &registration::correct(p, &self.registrar.biases[p.radar]),
                    t,
                    self.config.sigma_tangential_speed,
                    manoeuvre_q,
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let (fused, members) =
            associate_and_fuse_members(&registered, self.config.plot_gate_probability)?;
        let mut radars: Vec<usize> = frame.iter().map(|p| p.radar).collect();
        radars.sort_unstable();
        radars.dedup();
        let specs: Vec<&RadarSpec> = radars.iter().map(|&i| &self.applied[i]).collect();
        let miss: f64 = specs
            .iter()
            .map(|r| 1.0 - r.detection_probability)
            .product();
        let clutter = fused.iter().map(|f| cartesian_clutter(f, &specs)).collect();
        self.counters.fused_plots += fused.len() as u64;
        let source = Source::Fused {
            clutter,
            detection_probability: 1.0 - miss,
        };
        let hits = self.run_frame(t, source, fused, report)?;
        self.last_instant = Some(k);
        if Registrar::learns(&self.config) {
            self.registrar.learn_parallel(
                &self.config,
                &self.applied,
                &self.tracks,
                &frame,
                &members,
                &hits,
            )?;
        }
        Ok(())
    }

    /// The tracking loop of one frame, over its components (Stone Soup's
    /// `tracker/simple.py`): the hypothesiser finds the tracks a plot may
    /// gate (every track in parallel mode), the predictor predicts them,
    /// the associator weighs plots against them, the updater updates the
    /// tracks a plot gated (every track in parallel mode, where a track not
    /// detected misses), the deleter removes duplicates and lost tracks,
    /// the initiator starts tracks from the plots no track used. In serial
    /// mode a track no plot gates is left as it was: its misses come from
    /// the beam ([`Tracker::judge_sweep`]). Returns the tracks a plot
    /// updated (slots after the frame's deletions).
    fn run_frame(
        &mut self,
        t: f64,
        source: Source,
        plots: Vec<CartesianPlot>,
        report: &mut StepReport,
    ) -> Result<Vec<Hit>, AlgoError> {
        let mut slots = self.hypothesise(t, &plots)?;
        let mut scratch = std::mem::take(&mut self.scratch.0);
        // Confirmed tracks whose numbers failed before their update (slots):
        // dropped with the deleter's.
        let mut failed = Vec::new();
        let outcome = loop {
            let bad = scratch.predict(
                &self.config,
                &mut self.predictor,
                &self.tracks,
                &mut slots,
                t,
            );
            for (k, error) in bad {
                self.failure(k, t, FailedStep::Predict, error, report);
                failed.push(k);
            }
            let estimates = &scratch.estimates[..slots.len()];
            match self.associate(&source, &plots, &slots, estimates) {
                Ok(outcome) => break outcome,
                Err(e) => {
                    // The tracks whose likelihood fails on their own
                    // leave the frame, which is associated again without
                    // them; an error no single track makes is the frame's.
                    let culprits: Vec<(usize, AlgoError)> = (0..slots.len())
                        .filter_map(|c| {
                            let one = (&slots[c..=c], &estimates[c..=c]);
                            self.associate(&source, &plots, one.0, one.1)
                                .err()
                                .map(|e| (c, e))
                        })
                        .collect();
                    if culprits.is_empty() {
                        self.scratch.0 = scratch;
                        return Err(e);
                    }
                    for (c, error) in culprits.into_iter().rev() {
                        let k = slots.remove(c);
                        self.failure(k, t, FailedStep::Associate, error, report);
                        failed.push(k);
                    }
                }
            }
        };
        let cfg = &self.config;
        let updater: Box<dyn Updater + '_> = match &source {
            Source::Radar {
                spec,
                plots: raw,
                height,
            } => Box::new(PolarUpdater {
                radar: spec,
                layout: polar_layout(spec, cfg.axes),
                plots: raw,
                range_rate: range_rate_sigma(spec, raw),
                height: *height,
            }),
            Source::Fused { .. } | Source::Reports { .. } => {
                Box::new(CartesianUpdater { plots: &plots })
            }
        };
        report
            .undefined
            .extend(outcome.undefined.iter().map(|&c| self.tracks[slots[c]].id));
        scratch.innovations.clear();
        scratch.scans_since_hit.clear();
        if let (
            Source::Radar {
                spec, plots: raw, ..
            },
            true,
        ) = (&source, cfg.accuracy.enabled)
        {
            let tracks = &self.tracks;
            innovations(
                (spec, raw, cfg.axes),
                &outcome,
                slots.len(),
                &|c| tracks[slots[c]].hits > accuracy::LEARNING_HITS,
                &mut scratch,
            );
        }
        let (hits, touched) = self.update(
            t,
            &slots,
            &mut scratch,
            (&outcome, &*updater),
            &plots,
            &mut failed,
            report,
        )?;
        drop(updater);
        self.scratch.0 = scratch;
        let hits = self.delete_after_update(hits, &touched, &failed, report)?;
        let mut used = outcome.used;
        if matches!(source, Source::Reports { .. }) && !self.reports_seen.0 {
            self.reports_seen.0 = true;
            self.registrar.refer(&self.config)?;
        }
        if self.reports_seen.0 {
            self.check_leftovers(&plots, &mut used);
        }
        self.initiate(t, plots, &used, report)?;
        self.last_time = Some(self.last_time.map_or(t, |last| last.max(t)));
        self.counters.frames += 1;
        report.frames += 1;
        Ok(hits)
    }

    /// The associator's part of a frame: the weights of the frame's plots
    /// for the tracks `slots` predicted as `estimates` (JPDA through the
    /// polar EKF's linearisation for one radar's plots, or against fused
    /// Cartesian plots), with each plot's identity beside its position.
    fn associate(
        &self,
        source: &Source,
        plots: &[CartesianPlot],
        slots: &[usize],
        estimates: &[TrackEstimate],
    ) -> Result<Outcome, AlgoError> {
        let cfg = &self.config;
        match source {
            Source::Radar {
                spec, plots: raw, ..
            } => {
                // Identity beside the position, when a plot carries one
                // (identity::TrackIdentity::ln_ratio).
                let tracks = &self.tracks;
                let mode_s = self.mode_s_radars[raw[0].radar];
                let evidence = |c: usize, j: usize| {
                    tracks[slots[c]]
                        .identity
                        .ln_ratio(&raw[j].identity, raw[j].t, mode_s)
                };
                let any = raw.iter().any(|p| !p.identity.is_empty());
                associate_polar(
                    estimates,
                    spec,
                    raw,
                    cfg.axes,
                    cfg.track_gate_probability,
                    &cfg.association,
                    any.then_some(&evidence as jpda::Evidence<'_>),
                )
            }
            Source::Fused {
                clutter,
                detection_probability,
            } => associate_cartesian(
                estimates,
                plots,
                clutter,
                *detection_probability,
                cfg.track_gate_probability,
                &cfg.association,
                None,
            ),
            Source::Reports {
                kind,
                plots: raw,
                clutter,
            } => {
                // Identity beside the position; a track that distrusts
                // its aircraft's own positions takes none of its address.
                let tracks = &self.tracks;
                let self_reported = kind.is_self_reported();
                let evidence = |c: usize, j: usize| {
                    let id = &tracks[slots[c]].identity;
                    let own = id
                        .address
                        .is_some_and(|a| Some(a.value) == raw[j].identity.address);
                    if self_reported && own && !id.validation.trusted() {
                        return None;
                    }
                    id.ln_ratio(&raw[j].identity, raw[j].t, true)
                };
                associate_cartesian(
                    estimates,
                    plots,
                    clutter,
                    REPORT_DETECTION_PROBABILITY,
                    cfg.track_gate_probability,
                    &cfg.association,
                    Some(&evidence),
                )
            }
        }
    }

    /// Reports that confirmed track `k`'s numbers failed at `step` of the
    /// frame at `t` ([`StepReport::failed`]).
    fn failure(
        &self,
        k: usize,
        t: f64,
        step: FailedStep,
        error: AlgoError,
        report: &mut StepReport,
    ) {
        report.failed.push(TrackFailure {
            id: self.tracks[k].id,
            confirmed: true,
            t,
            step,
            error,
        });
    }

    /// The hypothesiser: the tracks a frame's plots may gate, from the
    /// index in serial mode, every track in parallel mode.
    fn hypothesise(&mut self, t: f64, plots: &[CartesianPlot]) -> Result<Vec<usize>, AlgoError> {
        if self.parallel {
            Ok((0..self.tracks.len()).collect())
        } else if plots.is_empty() {
            Ok(Vec::new())
        } else {
            self.index.candidates(&self.tracks, plots, t, &self.config)
        }
    }

    /// The updater's part of a frame: the predictions of the tracks a plot
    /// gated (every one in parallel mode) taken and updated with the
    /// association's weights, one update path for single-model and IMM
    /// tracks; hits and misses recorded. Returns the hits and every track
    /// whose life this frame recorded. A track whose update cannot be made
    /// is left as it was, as if it had gated nothing, and the rest of the
    /// frame applies: one of whose IMM models is predicted at a radar's
    /// site (its polar model undefined there, while the combined
    /// prediction the association used was not) is listed in
    /// [`StepReport::undefined`]; one whose update failed numerically (an
    /// error, or a result that is not finite) in [`StepReport::failed`]:
    /// its slot is pushed to `failed` (dropped, [`FailedStep::Update`]),
    /// but when the carry of an out-of-sequence plot's update failed (it
    /// coasts, [`FailedStep::Carry`]).
    #[allow(clippy::too_many_arguments)]
    fn update(
        &mut self,
        t: f64,
        slots: &[usize],
        scratch: &mut Scratch,
        (outcome, updater): (&Outcome, &dyn Updater),
        plots: &[CartesianPlot],
        failed: &mut Vec<usize>,
        report: &mut StepReport,
    ) -> Result<(Vec<Hit>, Vec<usize>), AlgoError> {
        let lazy = !self.parallel;
        let mut hits = Vec::new();
        let mut touched = Vec::new();
        // A track whose update could not be made: listed where its reason
        // says.
        let mut coast = |id: u64, why: Coast, step: FailedStep| match why {
            Coast::Undefined => report.undefined.push(id),
            Coast::Failed(error) => report.failed.push(TrackFailure {
                id,
                confirmed: true,
                t,
                step,
                error,
            }),
        };
        for (c, &k) in slots.iter().enumerate() {
            let assoc = &outcome.associations[c];
            if lazy && assoc.measurements.is_empty() {
                continue;
            }
            let track = Arc::make_mut(&mut self.tracks[k]);
            if let Some(retro) = scratch.retro[c].take() {
                // A plot older than the track: its update at t carried to
                // the track's time; the hit recorded, the track's time and
                // last update kept; no registration pair.
                let pred = &mut scratch.predictions[c];
                // What the carry changes, kept to restore when it fails.
                let kept = (track.x.clone(), track.p.clone(), track.modes.clone());
                let carried = if pred.modes.is_empty() {
                    let single = single_mode(&mut scratch.single);
                    std::mem::swap(&mut single[0].x, &mut pred.x);
                    std::mem::swap(&mut single[0].p, &mut pred.p);
                    coasts(updater.update(single, assoc)).and_then(|_| {
                        retrodiction::carry(track, &retro, single).map_err(Coast::Failed)
                    })
                } else {
                    coasts(updater.update(&mut pred.modes, assoc)).and_then(|_| {
                        retrodiction::carry(track, &retro, &pred.modes).map_err(Coast::Failed)
                    })
                };
                if let Err(why) = carried {
                    (track.x, track.p, track.modes) = kept;
                    coast(track.id, why, FailedStep::Carry);
                    continue;
                }
                if let Some(j) = outcome.hit[c] {
                    track.record_late_hit(scratch.behind_sweep);
                    scratch.scans_since_hit.extend(detection_trials(
                        track,
                        &plots[j],
                        &self.config.radars,
                    ));
                    validation::note_hit(&self.config, track, &plots[j]);
                    track
                        .identity
                        .observe_measured(plots[j].measured.as_ref(), &self.mode_s_radars);
                }
                self.index.moved(k, track);
                touched.push(k);
                continue;
            }
            let before = track.t;
            track.commit_swap(t, &mut scratch.predictions[c]);
            let updated = if track.modes.is_empty() {
                let single = single_mode(&mut scratch.single);
                std::mem::swap(&mut single[0].x, &mut track.x);
                std::mem::swap(&mut single[0].p, &mut track.p);
                let updated = coasts(updater.update(single, assoc));
                if updated.is_err() {
                    // The track's buffers back (what the update left in
                    // them is dropped below).
                    std::mem::swap(&mut single[0].x, &mut track.x);
                    std::mem::swap(&mut single[0].p, &mut track.p);
                }
                updated
            } else {
                coasts(updater.update(&mut track.modes, assoc))
            };
            let (x, p) = match updated {
                Ok(u) => u,
                Err(why) => {
                    // Back to the track as it was before the frame (its
                    // state, covariance and modes, whatever the update
                    // changed of the prediction): an overflight's track
                    // coasts, predicted when needed; one whose numbers
                    // failed is dropped with the deleter's.
                    track.commit_swap(before, &mut scratch.predictions[c]);
                    if matches!(why, Coast::Failed(_)) {
                        failed.push(k);
                    }
                    coast(track.id, why, FailedStep::Update);
                    continue;
                }
            };
            track.x = x;
            track.p = p;
            match outcome.hit[c] {
                Some(j) => {
                    hits.push(Hit {
                        slot: k,
                        plot: j,
                        previous: track.last_plot,
                    });
                    validation::note_hit(&self.config, track, &plots[j]);
                    if scratch.behind_sweep && track.replace_miss() {
                        // Its radar's sweep judged it missed before the
                        // plot arrived: that miss was this hit.
                        track.radars = plots[j].radars.clone();
                        track.last_update = t;
                    } else {
                        track.record(Some(plots[j].radars.clone()));
                    }
                    scratch.scans_since_hit.extend(detection_trials(
                        track,
                        &plots[j],
                        &self.config.radars,
                    ));
                    // A report is not a radar's plot (I062/340, the
                    // registration's pairs): the last radar plot stays.
                    if plots[j].measured.is_none_or(|m| m.report.is_none()) {
                        track.last_plot = plots[j].measured;
                    }
                    track
                        .identity
                        .observe_measured(plots[j].measured.as_ref(), &self.mode_s_radars);
                }
                None if !lazy => track.record(None),
                None => {}
            }
            self.index.moved(k, track);
            touched.push(k);
        }
        Ok((hits, touched))
    }

    /// The deleter's part of a frame: duplicates among the tracks a plot
    /// updated, every touched track its rule deletes, and the tracks whose
    /// numbers failed before their update (`failed`, dropped: see
    /// [`FailedStep`]). Returns the hits of the tracks kept, at their
    /// slots after the deletions.
    fn delete_after_update(
        &mut self,
        hits: Vec<Hit>,
        touched: &[usize],
        failed: &[usize],
        report: &mut StepReport,
    ) -> Result<Vec<Hit>, AlgoError> {
        let cfg = &self.config;
        let hit_plots: Vec<(usize, usize)> = hits.iter().map(|h| (h.slot, h.plot)).collect();
        let mut doomed: Vec<(usize, Doom)> =
            deleter::duplicates(&self.tracks, &hit_plots, cfg.duplicate_gate_probability)?
                .into_iter()
                .map(|k| (k, Doom::Duplicate))
                .collect();
        for &k in touched {
            if !doomed.iter().any(|d| d.0 == k)
                && deleter::should_delete(&self.tracks[k], &cfg.deletion)
            {
                doomed.push((k, Doom::Rule));
            }
        }
        doomed.extend(failed.iter().map(|&k| (k, Doom::Failed)));
        let gone: std::collections::HashSet<usize> = doomed.iter().map(|d| d.0).collect();
        let moves = self.delete(doomed, report);
        Ok(hits
            .into_iter()
            .filter(|h| !gone.contains(&h.slot))
            .map(|h| Hit {
                slot: moves
                    .iter()
                    .fold(h.slot, |s, &(from, to)| if s == from { to } else { s }),
                ..h
            })
            .collect())
    }

    /// The initiator's part of a frame: the plots no track used (`used`),
    /// their positions only (what the stored state holds); tracks it
    /// confirms join the confirmed tracks.
    fn initiate(
        &mut self,
        t: f64,
        plots: Vec<CartesianPlot>,
        used: &[bool],
        report: &mut StepReport,
    ) -> Result<(), AlgoError> {
        let leftovers = plots
            .into_iter()
            .zip(used)
            .filter_map(|(p, used)| {
                (!used).then_some(CartesianPlot {
                    range_rates: Vec::new(),
                    ..p
                })
            })
            .collect();
        let misses = if self.parallel {
            Misses::Judge(View::All)
        } else {
            Misses::Lazy
        };
        let live = self.tracks.len() + self.initiator.tentatives.len();
        let room = self
            .max_tracks
            .0
            .map_or(usize::MAX, |m| m.saturating_sub(live));
        let initiated = self.initiator.step(
            t,
            leftovers,
            &self.config,
            misses,
            &mut self.next_id,
            room,
            &self.mode_s_radars,
        )?;
        report.refused += initiated.refused;
        report.failed.extend(initiated.failed);
        self.counters.started += initiated.started as u64;
        self.counters.dropped += initiated.dropped as u64;
        for mut track in initiated.confirmed {
            match self.same_aircraft(&track) {
                Some(SameAircraft::Here) => {
                    // A second track of an aircraft already tracked under
                    // its Mode S address: merged into that track (not
                    // confirmed).
                    self.counters.dropped += 1;
                    continue;
                }
                Some(SameAircraft::Lost(slot)) => {
                    // The track of its address lost the aircraft (no
                    // update since this one's first plot): it takes this
                    // one's state and goes on under its own id.
                    self.counters.dropped += 1;
                    let old = Arc::make_mut(&mut self.tracks[slot]);
                    old.reacquire(track, &self.config.motion);
                    self.index.moved(slot, old);
                    continue;
                }
                None => {}
            }
            if let Motion::Imm(imm) = &self.config.motion {
                track.start_modes(imm);
            }
            report.confirmed.push(track.id);
            self.counters.confirmed += 1;
            self.index.moved(self.tracks.len(), &track);
            self.tracks.push(Arc::new(track));
        }
        Ok(())
    }
}

impl Tracker {
    /// Whether a confirmed track already carries `new`'s Mode S address
    /// (one address, one aircraft): [`SameAircraft::Here`] where `new` is
    /// (their horizontal positions, the old one extrapolated to `new`'s
    /// time, within the χ²₂ gate at 0.999 of their summed covariances,
    /// 13.8: one aircraft tracked twice); [`SameAircraft::Lost`] where the
    /// old track had no update by a plot or report of its address since
    /// `new`'s first plot (it lost the aircraft, which `new` found again: a
    /// manoeuvre it did not follow, a gap in coverage; primary plots may
    /// have kept it going elsewhere). Otherwise both are kept and named by the
    /// duplicate-address warning (both updated at once: a misconfigured
    /// transponder, or two aircraft on one address), but where either was
    /// updated by the aircraft's own reports (ADS-B, AIS): then
    /// [`SameAircraft::Here`] (its reports split over two tracks, one
    /// aircraft).
    fn same_aircraft(&self, new: &Track) -> Option<SameAircraft> {
        let address = new.identity.address.map(|a| a.value)?;
        let cfg = &self.config;
        let self_reported = |tr: &Track| tr.sensors().any(|i| cfg.is_self_reported(i));
        let mut lost = None;
        let mut merged = None;
        for (slot, old) in self.tracks.iter().enumerate() {
            if old.identity.address.is_none_or(|a| a.value != address) {
                continue;
            }
            let dt = new.t - old.t;
            let d = [
                new.x[0] - (old.x[0] + old.x[1] * dt),
                new.x[2] - (old.x[2] + old.x[3] * dt),
            ];
            let s = [
                old.p[(0, 0)] + new.p[(0, 0)],
                old.p[(0, 2)] + new.p[(0, 2)],
                old.p[(2, 2)] + new.p[(2, 2)],
            ];
            let det = s[0] * s[2] - s[1] * s[1];
            if det > 0.0
                && (d[0] * d[0] * s[2] - 2.0 * d[0] * d[1] * s[1] + d[1] * d[1] * s[0]) / det
                    <= SAME_AIRCRAFT_CHI2
            {
                return Some(SameAircraft::Here);
            }
            // Lost: no update by a plot or report of its address since
            // the new track's first plot (primary plots may have kept it
            // going, on another target or on clutter). The address's
            // evidence is dated by both, `last_mode_s` by radar plots only
            // but kept through a reacquisition (Track::reacquire).
            let addressed = old.identity.address.map(|a| a.last_t);
            let since = match (addressed, old.identity.last_mode_s) {
                (Some(a), Some(m)) => Some(a.max(m)),
                (a, m) => a.or(m),
            }
            .map_or(old.last_update, |t| t.min(old.last_update));
            if new.started.is_some_and(|t0| since < t0) && lost.is_none() {
                lost = Some(SameAircraft::Lost(slot));
            } else if self_reported(new) || self_reported(old) {
                // An address the aircraft reports itself (ADS-B): its own
                // positions made (or hold) one of the two, one aircraft;
                // the new one is merged away, and a disagreement between
                // the old and the radar is the check's
                // ([`validation`]).
                merged = Some(SameAircraft::Here);
            }
        }
        lost.or(merged)
    }
}

/// Why the deleter removes a confirmed track.
#[derive(Debug, Clone, Copy)]
enum Doom {
    /// A deletion rule (misses, σ).
    Rule,
    /// A duplicate of another track.
    Duplicate,
    /// Its numbers failed ([`FailedStep`]).
    Failed,
}

/// A newly confirmed track's aircraft already has a track
/// ([`Tracker::same_aircraft`]).
enum SameAircraft {
    /// Where the new track is: the new one is merged away.
    Here,
    /// At this slot, lost: it takes the new track's state.
    Lost(usize),
}

/// χ²₂ at 0.999 (−2 ln 0.001 = 13.8155): see [`Tracker::has_its_address`].
const SAME_AIRCRAFT_CHI2: f64 = 13.815_510_557_964_274;

/// A serial radar's sweep is judged for misses every 1/`JUDGE_SLICES` of
/// its scan period (a 4-s scan: every 0.25 s): often enough that a track's
/// miss is counted soon after the beam passed it, rarely enough that the
/// pass over every track costs about as much per plot whatever the size
/// of the picture.
const JUDGE_SLICES: f64 = 16.0;

/// Data derived from the tracker's state and kept to save work: two
/// trackers in the same state are equal whatever it holds.
#[derive(Debug, Clone, Default)]
struct Derived<T>(T);

impl<T> PartialEq for Derived<T> {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Buffers a frame reuses: the candidate tracks' predictions, the
/// estimates the associator reads, and the one mode of a single-model
/// track's update.
#[derive(Debug, Clone, Default)]
struct Scratch {
    predictions: Vec<Prediction>,
    estimates: Vec<TrackEstimate>,
    single: Vec<ModeState>,
    /// Per candidate, what carries its update back to its own time when it
    /// is newer than the frame (retrodicted).
    retro: Vec<Option<retrodiction::Retro>>,
    /// The frame is older than its radar's last judged sweep (out of
    /// sequence within the radar): a hit replaces the miss that sweep
    /// judged.
    behind_sweep: bool,
    /// Serial mode: the frame's innovations the accuracy estimator learns
    /// from (plots that updated a confirmed track without ambiguity).
    innovations: Vec<accuracy::Innovation>,
    /// The frame's hits of confirmed tracks by a later scan than the
    /// radar's previous hit of the track: the scans since (the detection
    /// probability's trials, [`accuracy`]).
    scans_since_hit: Vec<u32>,
    /// Per plot of the frame, the tracks whose gates hold it (the
    /// accuracy estimator's buffer).
    gated: Vec<u32>,
}

/// Serial mode: the innovations of the radar's plots (`spec`, corrected
/// plots `raw`, in a tracker of `axes` axes) that updated a confirmed track without ambiguity
/// (association weight at least [`accuracy::MIN_ASSOCIATION_WEIGHT`]), for
/// the accuracy estimator (into `scratch.innovations`), against the
/// track's prediction (the first `candidates` of `scratch.predictions`):
/// an IMM track's most probable model's when its predicted probability is
/// at least [`accuracy::MIN_MODE_PROBABILITY`]
/// (else the plot is not learnt from: the motion is in transition). Only
/// tracks past their start (`established(c)`: more than
/// [`accuracy::LEARNING_HITS`] hits; a young track's covariance is not
/// yet its error's) and plots in no other track's gate teach.
fn innovations(
    (spec, raw, axes): (&RadarSpec, &[Plot], usize),
    outcome: &Outcome,
    candidates: usize,
    established: &dyn Fn(usize) -> bool,
    scratch: &mut Scratch,
) {
    let Scratch {
        predictions,
        gated,
        innovations: out,
        ..
    } = scratch;
    let predictions = &predictions[..candidates];
    let layout = polar_layout(spec, axes);
    let with_range_rate = range_rate_sigma(spec, raw).is_some();
    gated.clear();
    gated.resize(raw.len(), 0);
    for a in &outcome.associations {
        for &(j, _) in &a.measurements {
            gated[j] += 1;
        }
    }
    for (c, hit) in outcome.hit.iter().enumerate() {
        let Some(j) = *hit else { continue };
        if gated[j] > 1 || !established(c) {
            continue;
        }
        let beta = outcome.associations[c]
            .measurements
            .iter()
            .find(|m| m.0 == j)
            .map_or(0.0, |m| m.1);
        if beta < accuracy::MIN_ASSOCIATION_WEIGHT {
            continue;
        }
        let pred = &predictions[c];
        let (x, p) = match pred
            .modes
            .iter()
            .max_by(|a, b| a.probability.total_cmp(&b.probability))
        {
            None => (&pred.x, &pred.p),
            Some(m) if m.probability >= accuracy::MIN_MODE_PROBABILITY => (&m.x, &m.p),
            Some(_) => continue,
        };
        out.extend(accuracy::innovation(
            spec,
            &raw[j],
            x,
            p,
            layout,
            with_range_rate,
        ));
    }
}

/// Records a hit of `track` by `plot` (its radar's last hit) and returns
/// the scans since that radar's previous hit of the track, the detection
/// probability's trials, when the track is established (more than
/// [`accuracy::ESTABLISHED_HITS`] hits, this one counted: a false track of
/// clutter or a duplicate, with its few hits, would count its misses).
fn detection_trials(track: &mut Track, plot: &CartesianPlot, radars: &[RadarSpec]) -> Option<u32> {
    let established = track.hits > accuracy::ESTABLISHED_HITS;
    let scans = track.hit_by_plot(plot, radars)?;
    established.then_some(scans)
}

/// The one mode of a single-model track's update in `single` (a
/// [`Scratch`] buffer), probability 1, its state buffers whatever the last
/// update left.
fn single_mode(single: &mut Vec<ModeState>) -> &mut Vec<ModeState> {
    single.resize_with(1, || ModeState {
        probability: 1.0,
        x: nalgebra::DVector::zeros(0),
        p: nalgebra::DMatrix::zeros(0, 0),
    });
    single[0].probability = 1.0;
    single
}

impl Scratch {
    /// The predictor's part of a frame: the tracks `slots` predicted to
    /// `t` into `predictions` (and copied into `estimates`), in order; a
    /// track newer than `t` retrodicted there. A track whose prediction
    /// fails is taken out of `slots` (the others keep their order, so
    /// candidate c is `slots[c]` after the call) and returned with its
    /// error, by slot.
    fn predict(
        &mut self,
        cfg: &TrackerConfig,
        predictor: &mut dyn Predictor,
        tracks: &[Arc<Track>],
        slots: &mut Vec<usize>,
        t: f64,
    ) -> Vec<(usize, AlgoError)> {
        if self.predictions.len() < slots.len() {
            self.predictions
                .resize_with(slots.len(), Prediction::default);
        }
        while self.estimates.len() < slots.len() {
            self.estimates.push(TrackEstimate {
                x: nalgebra::DVector::zeros(0),
                p: nalgebra::DMatrix::zeros(0, 0),
            });
        }
        self.retro.clear();
        self.retro.resize(slots.len(), None);
        let mut failed = Vec::new();
        let mut c = 0;
        for i in 0..slots.len() {
            let k = slots[i];
            let pred = &mut self.predictions[c];
            let predicted = if tracks[k].t > t {
                retrodiction::retrodict(cfg, &tracks[k], t, pred).map(Some)
            } else {
                predictor.predict_into(&tracks[k], t, pred).map(|()| None)
            };
            match predicted {
                Ok(retro) => self.retro[c] = retro,
                Err(e) => {
                    failed.push((k, e));
                    continue;
                }
            }
            track::copy_vector(&mut self.estimates[c].x, &pred.x);
            track::copy_matrix(&mut self.estimates[c].p, &pred.p);
            slots[c] = k;
            c += 1;
        }
        slots.truncate(c);
        self.retro.truncate(c);
        failed
    }
}

/// Why a track's update was not made.
enum Coast {
    /// A model's polar measurement model is undefined where that model
    /// predicts the target (at a radar's site).
    Undefined,
    /// The update failed numerically.
    Failed(AlgoError),
}

/// An update (the combined state and covariance) as made, or why the
/// track coasts instead: degenerate geometry, any other error, or a
/// result that is not finite (which no later step could use).
fn coasts(
    updated: Result<(DVector<f64>, DMatrix<f64>), AlgoError>,
) -> Result<(DVector<f64>, DMatrix<f64>), Coast> {
    match updated {
        Ok((x, p)) if x.iter().chain(p.iter()).all(|v| v.is_finite()) => Ok((x, p)),
        Ok(_) => Err(Coast::Failed(AlgoError::NonFinite {
            what: "updated state",
        })),
        Err(AlgoError::DegenerateGeometry { .. }) => Err(Coast::Undefined),
        Err(e) => Err(Coast::Failed(e)),
    }
}
