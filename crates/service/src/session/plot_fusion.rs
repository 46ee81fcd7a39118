//! The plot-fusion kind of session (seed 001 as a stream): the tracker of
//! `algo::tracking` kept between batches of radar plots.
//!
//! A batch is plots as they arrive, in any order, late ones included: the
//! tracker is an `algo::tracking::LagWindow`, which takes plots in any
//! order within `tracker.max_lag_s` (default 15 s) of the newest plot
//! received. After every batch the session's tracks are those of the batch
//! endpoint over every plot received so far, sorted by time: a frame is
//! processed as soon as its plots arrive (no `flush` needed, no scan of
//! delay), and a plot that arrives late (within the lag) is processed in
//! its place by replaying the plots after it from a snapshot (exact
//! reprocessing, tested against the batch endpoint with shuffled
//! arrival). Tracks whose history the replay recomputed are listed with
//! `change: corrected`; a track the replay removed (a late plot can merge
//! or end one) is listed in `deleted`.
//!
//! A plot older than the newest plot received minus the lag is *late
//! beyond the lag*: it is dropped, counted, and named in the update and a
//! warning. `flush` is accepted and changes nothing (the tracks always
//! include the open frame).
//!
//! A batch may carry raw ASTERIX beside its plots (`asterix`,
//! `service::plot_fusion::asterix`): its plots follow the JSON plots, its
//! late plots are named by record offset in `asterix.late_offsets`, and a
//! batch without a date takes the times of day nearest to the session's
//! last processed frame.
//!
//! Each update lists the tracks the batch touched: every live track when a
//! frame was processed (each frame predicts every track), with what
//! happened to it (`initiated`, `confirmed`, `updated`), the tracks
//! deleted, and the ids of tentative tracks dropped.
//!
//! A session created with `cat062` also carries, in each update, those
//! tracks as CAT062 records (`crate::plot_fusion::cat062`): one per listed
//! track, in order, the first record of a track flagged TSB (`initiated`),
//! then one track-end record (TSE) per deleted track. A dropped tentative
//! track gets no end record (its id is in `dropped`).

use std::collections::HashSet;

use super::{Fnv, Limits, PlotMark, SessionKind};
use crate::{
    ServiceError,
    plot_fusion::{
        DisagreementView, LastPlotView, ModeView, Network, PlotInput, RadarAccuracyView,
        RadarBiasView, ReportInput, SelfReportedView, SigmaView, SourceView, SpecInput, SsrInput,
        TrackView, TrackerCounters,
        asterix::{self, AsterixInput, AsterixSummary},
        cat062::{self, Cat062Data, Cat062Options, Life},
        computation_error, mode_name, network,
        nmea::{self, NmeaInput},
        output,
    },
};
use algo::tracking::{LagWindow, TrackOutput, TrackStatus, Tracker};
use formats::state::{
    tracker::{decode_counters, decode_tracker, encode_counters},
    window::{decode_lag_window, encode_lag_window},
};
use wire_formats::wire::{FormatError, Reader, Writer, corrupt, invalid};

/// Format of the kind's payload: 2 = format 1 (the network and the
/// tracker) plus the radars' ASTERIX SAC/SIC; 3 adds the `cat062` option;
/// 4 stores a lag window (two trackers and the plots between them) in
/// place of the tracker. Format 1 is read as radars without SAC/SIC,
/// formats 1 and 2 as sessions without CAT062 out, formats 1 to 3 as a
/// window over the stored tracker with the default lag.
pub const FORMAT_VERSION: u8 = 4;

/// Bit 31 of an encoded update's `frames` flags the ASTERIX summary after
/// its counters (a batch never processes 2³¹ frames), so kept updates of
/// earlier releases read unchanged.
const ASTERIX_FLAG: u32 = 1 << 31;
/// Set in the frame count of a kept update whose tracks carry their IMM
/// modes and turn rate (every update this release writes; updates kept by
/// earlier releases have none).
const MODES_FLAG: u32 = 1 << 30;
/// Set in the frame count of a kept update whose tracks carry their start
/// time and last plot.
const PROVENANCE_FLAG: u32 = 1 << 29;
/// Set in the frame count of a kept update that carries CAT062 data (after
/// the ASTERIX summary).
const CAT062_FLAG: u32 = 1 << 28;
/// Set in the frame count of a kept update that carries what late plots
/// within the lag did (after the CAT062 data).
const LATE_FLAG: u32 = 1 << 27;
/// Set in the frame count of a kept update that carries the radars'
/// biases (after the late fields).
const REGISTRATION_FLAG: u32 = 1 << 26;
/// Set in the frame count of a kept update whose tracks carry their
/// identity (SSR and Mode S).
const IDENTITY_FLAG: u32 = 1 << 25;
/// Set in the frame count of a kept update that carries the radars'
/// accuracy (after the biases).
const ACCURACY_FLAG: u32 = 1 << 24;
/// Set in the frame count of a kept update whose radars' accuracy carries
/// the detection probability (after each radar's σ).
const DETECTION_FLAG: u32 = 1 << 23;
/// Set in the frame count of a kept update whose tracks carry their
/// sources and the check of their self-reported positions.
const SOURCES_FLAG: u32 = 1 << 22;
/// The flags every update this release writes carries.
const WRITTEN_FLAGS: u32 = SOURCES_FLAG
    | MODES_FLAG
    | PROVENANCE_FLAG
    | LATE_FLAG
    | REGISTRATION_FLAG
    | IDENTITY_FLAG
    | ACCURACY_FLAG
    | DETECTION_FLAG;
const FLAGS: u32 = ASTERIX_FLAG | CAT062_FLAG | WRITTEN_FLAGS;

/// A batch of plots.
#[derive(Debug, Clone, Default)]
pub struct BatchInput {
    pub plots: Vec<PlotInput>,
    /// Raw ASTERIX; its plots follow `plots`.
    pub asterix: Option<AsterixInput>,
    /// AIS over NMEA; its reports follow the ASTERIX plots.
    pub nmea: Option<NmeaInput>,
    /// Accepted for clients of earlier releases; changes nothing (the
    /// tracks always include the open frame).
    pub flush: bool,
}

/// What happened to a track in a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackChange {
    /// Started (tentative) in this batch.
    Initiated,
    /// Confirmed in this batch (possibly started in it too).
    Confirmed,
    /// Predicted and, if a plot was associated, updated.
    Updated,
    /// Recomputed because of late plots: the batch held plots older than
    /// the newest received (within the lag), and the track had been
    /// updated at or after the earliest of them, so its history from
    /// there was processed again with them.
    Corrected,
}

pub const TRACK_CHANGES: [TrackChange; 4] = [
    TrackChange::Initiated,
    TrackChange::Confirmed,
    TrackChange::Updated,
    TrackChange::Corrected,
];

pub fn track_change_name(c: TrackChange) -> &'static str {
    match c {
        TrackChange::Initiated => "initiated",
        TrackChange::Confirmed => "confirmed",
        TrackChange::Updated => "updated",
        TrackChange::Corrected => "corrected",
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct ChangedTrack {
    pub change: TrackChange,
    pub track: TrackView,
}

/// What one batch changed.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchUpdate {
    /// Frames processed by this batch.
    pub frames: u32,
    /// Plots of the open frame (in the tracks; processed again when more
    /// of the frame arrives).
    pub pending_plots: u32,
    /// Indices (into the batch's plots) of the plots late beyond the lag,
    /// dropped.
    pub late_plots: Vec<u32>,
    /// Plots of the batch older than the newest plot received before it,
    /// but within the lag: used (the tracks were corrected for them).
    pub late_within_lag: u32,
    /// Time of the earliest of them: the tracks were recomputed from it.
    pub corrected_from_t: Option<f64>,
    pub tracks: Vec<ChangedTrack>,
    /// Confirmed tracks deleted, as they were when deleted.
    pub deleted: Vec<TrackView>,
    /// Tentative tracks dropped without being confirmed.
    pub dropped: Vec<u64>,
    pub counters: TrackerCounters,
    /// What the batch's ASTERIX gave, when it had some.
    pub asterix: Option<AsterixSummary>,
    /// The listed tracks as CAT062 records, for a session created with
    /// `cat062`.
    pub cat062: Option<Cat062Data>,
    /// Each radar's bias as applied after the batch.
    pub registration: Vec<RadarBiasView>,
    /// Each radar's σ, declared, learnt and applied, after the batch.
    pub accuracy: Vec<RadarAccuracyView>,
}

/// The session as a client reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionView {
    pub mode: &'static str,
    pub state_layout: &'static [&'static str],
    pub radars: Vec<String>,
    /// The fusion frame's origin (latitude °, longitude °, height m), when
    /// it has one.
    pub origin: Option<[f64; 3]>,
    /// Per radar, in the order of `radars`: its site.
    pub sites: Vec<SiteView>,
    /// Time of the last processed frame.
    pub last_frame_t: Option<f64>,
    pub pending_plots: u32,
    /// The lag (s): plots older than the newest received minus it are late.
    pub max_lag_s: f64,
    /// How a plot older than the newest is taken: `reprocess` or
    /// `retrodict` (`tracker.late_plots`; a parallel-mode session
    /// reprocesses).
    pub late_plots: &'static str,
    /// Under `auto`: the tracks are approximate from this time (a late
    /// plot was taken by retrodiction, its replay over the bound); `None`
    /// when exact.
    pub approximate_from: Option<f64>,
    /// Plots older than this are late beyond the lag (dropped); none
    /// before the first plot.
    pub late_before_t: Option<f64>,
    pub counters: TrackerCounters,
    /// Confirmed then tentative tracks.
    pub tracks: Vec<TrackView>,
    /// Each radar's bias as applied now.
    pub registration: Vec<RadarBiasView>,
    /// Each radar's σ, declared, learnt and applied now.
    pub accuracy: Vec<RadarAccuracyView>,
    /// The pressure offset a 3D tracker applies to Mode C.
    pub pressure_offset: Option<Box<crate::plot_fusion::PressureOffsetView>>,
}

/// Where a plot is, for display: its ENU position from its radar's site; a
/// 2D plot at its slant range on the horizontal plane, at the 2D target
/// height.
fn plot_mark(p: &algo::tracking::Plot, sites: &[[f64; 3]], target_height: f64) -> PlotMark {
    let Some(site) = sites.get(p.radar).copied() else {
        // A cooperative report: where it says.
        return PlotMark {
            radar: p.radar as u32,
            t: p.t,
            position: p.report.map_or([0.0; 3], |r| r.position),
        };
    };
    let (ground, up) = match p.elevation {
        Some(el) => (p.range * el.cos(), site[2] + p.range * el.sin()),
        None => (p.range, target_height),
    };
    PlotMark {
        radar: p.radar as u32,
        t: p.t,
        position: [
            site[0] + ground * p.azimuth.sin(),
            site[1] + ground * p.azimuth.cos(),
            up,
        ],
    }
}

/// A radar's site as a client sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct SiteView {
    /// In the fusion ENU frame (m).
    pub position: [f64; 3],
    /// Latitude and longitude (°), when the frame has an origin.
    pub lat_lon_deg: Option<[f64; 2]>,
    pub three_d: bool,
    pub doppler: bool,
}

/// The state: the network (ids, frame, rotations) and the tracker in its
/// lag window.
pub struct PlotFusionSession {
    /// Where the last applied batch's plots are, for watchers (not stored).
    marks: Vec<PlotMark>,
    /// The picture's tracks as the last batch left them (not stored: a
    /// decoded session asks the tracker), so a batch computes them once.
    last_tracks: Option<Vec<TrackOutput>>,
    network: Network,
    window: LagWindow,
    cat062: Option<Cat062Options>,
}

impl PlotFusionSession {
    /// The tracks with every plot received so far.
    fn tracker(&self) -> &Tracker {
        self.window.picture()
    }

    /// One batch; `views`: the update's track views are built (else it
    /// carries none: [`SessionKind::apply_unread`]).
    fn apply_with(
        &mut self,
        batch: &BatchInput,
        limits: &Limits,
        warnings: &mut Vec<String>,
        views: bool,
    ) -> Result<BatchUpdate, ServiceError> {
        let config = self.tracker().config().clone();
        let mut plots = self.network.plots(&batch.plots, &config, "plots")?;
        let json_plots = plots.len();
        let mut summary = None;
        let mut offsets = Vec::new();
        if let Some(a) = &batch.asterix {
            let reference = self.window.newest().or(a.reference_t);
            let clock = asterix::clock(a, "asterix", reference)?;
            let from = asterix::plots(&self.network, &config, &a.data, clock, a.reception);
            plots.extend(from.plots);
            offsets = from.offsets;
            warnings.extend(from.warnings);
            summary = Some(from.summary);
        }
        if let Some(n) = &batch.nmea {
            nmea::extend(n, (&self.network, &config), &mut plots, warnings)?;
        }
        let before: Vec<TrackOutput> = self
            .last_tracks
            .take()
            .unwrap_or_else(|| self.tracker().tracks());
        let biases_before = self.network.bias_views(self.tracker());
        let horizon = self.window.horizon();
        self.window.set_max_tracks(Some(limits.max_tracks));
        let push = self.window.push(&plots).map_err(computation_error)?;
        let late_json: Vec<usize> = push
            .late
            .iter()
            .copied()
            .filter(|&i| i < json_plots)
            .collect();
        if let Some(s) = summary.as_mut() {
            s.late_offsets = push
                .late
                .iter()
                .filter(|&&i| i >= json_plots)
                .map(|&i| offsets[i - json_plots])
                .collect();
            s.late = s.late_offsets.len();
        }
        let late: HashSet<usize> = push.late.iter().copied().collect();
        let sites: Vec<[f64; 3]> = config.radars.iter().map(|r| r.site).collect();
        self.marks = plots
            .iter()
            .enumerate()
            .filter(|(i, _)| !late.contains(i))
            .map(|(_, p)| plot_mark(p, &sites, self.network.target_height))
            .collect();
        let live = self.tracker().tracks();
        if push.refused > 0 {
            warnings.push(format!(
                "the session holds its limit of {} tracks (confirmed and tentative): {} \
                 track start(s) refused in this batch's frames; the tracks held go on, and \
                 new ones start as others end (lower the clutter's effect with \
                 tracker.initiation, or split the radars over more sessions)",
                limits.max_tracks, push.refused
            ));
        }
        if !push.late.is_empty() {
            let first = match (late_json.first(), &summary) {
                (Some(i), _) => format!("plots[{i}]"),
                (None, Some(s)) => format!(
                    "the ASTERIX record at offset {}",
                    s.late_offsets.first().copied().unwrap_or(0)
                ),
                (None, None) => "plots".into(),
            };
            warnings.push(format!(
                "{} late plot(s) dropped: older than t = {} (the newest plot received minus \
                 tracker.max_lag_s = {} s; first {first}): a larger tracker.max_lag_s (at \
                 most {} s) keeps plots that arrive later",
                push.late.len(),
                horizon.unwrap_or(f64::NAN),
                self.window.max_lag(),
                algo::tracking::window::MAX_LAG_LIMIT_S,
            ));
        }
        if let (true, algo::tracking::LatePolicy::Auto { max_replay }) =
            (push.retrodicted > 0, self.window.policy())
        {
            warnings.push(format!(
                "{} late plot(s) taken by retrodiction, not replayed: the lag window held \
                 more than tracker.max_replay_plots = {max_replay} plots, and the session \
                 retrodicts late plots from then on; the tracks are approximate from t = {} \
                 (a larger tracker.max_replay_plots, or tracker.late_plots \"reprocess\", \
                 keeps them exact at the cost of a replay)",
                push.retrodicted,
                self.window.approximate_from().unwrap_or(f64::NAN),
            ));
        }
        if let Some(h) = push.bounded_horizon {
            warnings.push(format!(
                "the lag window reached its bound of {} plots: plots older than t = {h} are \
                 now late, though within tracker.max_lag_s = {} s (the feed brings more plots \
                 than the lag can hold: a smaller tracker.max_lag_s, or the radars split over \
                 more sessions)",
                self.window.max_plots(),
                self.window.max_lag(),
            ));
        }
        let registration = self.network.bias_views(self.tracker());
        warnings.extend(network::registration_warnings(&config, &registration));
        let accuracy = self.network.accuracy_views(self.tracker());
        warnings.extend(network::accuracy_warnings(&config, &accuracy));
        warnings.extend(realigned(&biases_before, &registration));
        warnings.extend(crate::plot_fusion::ssr::warnings(&live));
        warnings.extend(crate::plot_fusion::output::self_reported_warnings(&live));
        warnings.extend(crate::plot_fusion::ssr::height_warnings(
            self.tracker(),
            &live,
        ));
        warnings.extend(crate::plot_fusion::undefined_warning(&push.undefined));
        warnings.extend(crate::plot_fusion::failed_warning(&push.failed));
        let changes = if views {
            diff(&before, &live, &push)
        } else {
            Changes::default()
        };
        let view = |t: &TrackOutput| self.network.track_view(&config.motion, t);
        let tracks: Vec<ChangedTrack> = if push.frames == 0 || !views {
            Vec::new()
        } else {
            live.iter()
                .zip(&changes.live)
                .map(|(t, &change)| ChangedTrack {
                    change,
                    track: view(t),
                })
                .collect()
        };
        let deleted: Vec<TrackView> = changes.deleted.iter().map(view).collect();
        let known: HashSet<u64> = before.iter().map(|t| t.id).collect();
        let cat062 = self.cat062.as_ref().filter(|_| views).map(|o| {
            let items: Vec<(&TrackView, Life)> = tracks
                .iter()
                .map(|c| {
                    // A track's first record (TSB) is the first one sent:
                    // a new track, even one confirmed in the batch that
                    // started it.
                    let life = if known.contains(&c.track.id) {
                        Life::Continuing
                    } else {
                        Life::First
                    };
                    (&c.track, life)
                })
                .chain(deleted.iter().map(|t| (t, Life::End)))
                .collect();
            cat062::encode(o, &self.network, &items, warnings)
        });
        self.last_tracks = Some(live);
        Ok(BatchUpdate {
            frames: push.frames as u32,
            pending_plots: self.window.pending() as u32,
            late_plots: late_json.into_iter().map(|i| i as u32).collect(),
            late_within_lag: push.within_lag as u32,
            corrected_from_t: push.earliest_within_lag,
            tracks,
            deleted,
            dropped: changes.dropped,
            counters: self.window.counters().into(),
            asterix: summary,
            cat062,
            registration,
            accuracy,
        })
    }
}

fn status_code(s: &str) -> u8 {
    match s {
        "tentative" => 0,
        "confirmed" => 1,
        _ => 2,
    }
}

fn status_of(code: u8) -> Result<&'static str, FormatError> {
    match code {
        0 => Ok("tentative"),
        1 => Ok("confirmed"),
        2 => Ok("deleted"),
        _ => Err(corrupt("track status")),
    }
}

fn encode_track(w: &mut Writer, t: &TrackView) {
    w.u64(t.id);
    w.u8(status_code(t.status));
    w.f64(t.t);
    w.f64s(&t.state);
    for row in &t.covariance {
        w.f64_run(row);
    }
    w.opt(t.lat_deg, Writer::f64);
    w.opt(t.lon_deg, Writer::f64);
    w.opt(t.height_m, Writer::f64);
    w.usize(t.radars.len());
    for r in &t.radars {
        w.str(r);
    }
    w.u32(t.hits);
    w.u32(t.misses);
    w.u32(t.consecutive_misses);
    w.u32(t.age);
    w.f64(t.last_update_t);
    w.usize(t.modes.len());
    for m in &t.modes {
        w.str(&m.model);
        w.f64(m.probability);
    }
    w.opt(t.turn_rate_dps, Writer::f64);
    w.opt(t.start_t, Writer::f64);
    w.opt(t.last_plot.as_ref(), |w, p| {
        w.str(&p.radar);
        w.f64(p.t);
        w.f64(p.range_m);
        w.f64(p.azimuth_deg);
        w.opt(p.elevation_deg, Writer::f64);
        w.opt(p.radial_velocity_mps, Writer::f64);
    });
    crate::plot_fusion::ssr::encode_view(w, t.identity.as_ref());
    w.usize(t.sources.len());
    for s in &t.sources {
        w.str(&s.sensor);
        w.f64(s.last_t);
    }
    w.opt(t.self_reported.as_ref(), |w, v| {
        w.bool(v.trusted);
        w.bool(v.validated);
        for x in [
            v.distrusted_since_t,
            v.last_self_reported_t,
            v.last_independent_t,
        ] {
            w.opt(x, Writer::f64);
        }
        w.opt(v.disagreement.as_ref(), |w, d| {
            w.f64(d.t);
            w.f64(d.distance_m);
            w.f64(d.stated_sigma_m);
        });
    });
    w.opt(t.mmsi, Writer::u32);
}

/// A kept track's sources, self-reported check and MMSI.
type Sources = (Vec<SourceView>, Option<SelfReportedView>, Option<u32>);

/// A kept track's [`Sources`] (after its identity).
fn decode_sources(r: &mut Reader<'_>) -> Result<Sources, FormatError> {
    let k = r.len(16)?;
    let sources = (0..k)
        .map(|_| {
            Ok(SourceView {
                sensor: r.str()?,
                last_t: r.f64()?,
            })
        })
        .collect::<Result<_, FormatError>>()?;
    let self_reported = r.opt(|r| {
        Ok(SelfReportedView {
            trusted: r.bool()?,
            validated: r.bool()?,
            distrusted_since_t: r.opt(Reader::f64)?,
            last_self_reported_t: r.opt(Reader::f64)?,
            last_independent_t: r.opt(Reader::f64)?,
            disagreement: r.opt(|r| {
                Ok(DisagreementView {
                    t: r.f64()?,
                    distance_m: r.f64()?,
                    stated_sigma_m: r.f64()?,
                })
            })?,
        })
    })?;
    Ok((sources, self_reported, r.opt(Reader::u32)?))
}

/// What a kept update's tracks carry, by the release that kept it.
#[derive(Clone, Copy)]
struct TrackFields {
    modes: bool,
    provenance: bool,
    identity: bool,
    sources: bool,
}

fn decode_track(r: &mut Reader<'_>, fields: TrackFields) -> Result<TrackView, FormatError> {
    let id = r.u64()?;
    let status = status_of(r.u8()?)?;
    let t = r.f64()?;
    let state = r.f64s()?;
    let n = state.len();
    if !(n == 4 || n == 6) {
        return Err(corrupt("track state size"));
    }
    let mut covariance = Vec::with_capacity(n);
    for _ in 0..n {
        let mut row = Vec::with_capacity(n);
        for _ in 0..n {
            row.push(r.f64()?);
        }
        covariance.push(row);
    }
    let lat_deg = r.opt(Reader::f64)?;
    let lon_deg = r.opt(Reader::f64)?;
    let height_m = r.opt(Reader::f64)?;
    let k = r.len(8)?;
    let radars = (0..k).map(|_| r.str()).collect::<Result<_, _>>()?;
    let (hits, misses, consecutive_misses, age) = (r.u32()?, r.u32()?, r.u32()?, r.u32()?);
    let last_update_t = r.f64()?;
    let (modes, turn_rate_dps) = if fields.modes {
        let k = r.len(16)?;
        let modes = (0..k)
            .map(|_| {
                Ok(ModeView {
                    model: r.str()?,
                    probability: r.f64()?,
                })
            })
            .collect::<Result<_, FormatError>>()?;
        (modes, r.opt(Reader::f64)?)
    } else {
        (Vec::new(), None)
    };
    let (start_t, last_plot) = if fields.provenance {
        let start_t = r.opt(Reader::f64)?;
        let last_plot = r.opt(|r| {
            Ok(LastPlotView {
                radar: r.str()?,
                t: r.f64()?,
                range_m: r.f64()?,
                azimuth_deg: r.f64()?,
                elevation_deg: r.opt(Reader::f64)?,
                radial_velocity_mps: r.opt(Reader::f64)?,
            })
        })?;
        (start_t, last_plot)
    } else {
        (None, None)
    };
    let identity = if fields.identity {
        crate::plot_fusion::ssr::decode_view(r)?
    } else {
        None
    };
    let (sources, self_reported, mmsi) = if fields.sources {
        decode_sources(r)?
    } else {
        (Vec::new(), None, None)
    };
    Ok(TrackView {
        id,
        status,
        t,
        state,
        covariance,
        lat_deg,
        lon_deg,
        height_m,
        radars,
        hits,
        misses,
        consecutive_misses,
        age,
        last_update_t,
        modes,
        turn_rate_dps,
        start_t,
        last_plot,
        identity,
        sources,
        self_reported,
        mmsi,
    })
}

fn stored(e: FormatError) -> ServiceError {
    ServiceError::Internal(format!("stored plot_fusion session: {e}"))
}

impl SessionKind for PlotFusionSession {
    const TAG: u8 = 2;
    const NAME: &'static str = "plot_fusion";
    const BATCH_FIELD: &'static str = "plots";

    type Spec = SpecInput;
    type Batch = BatchInput;
    type Update = BatchUpdate;
    type View = SessionView;

    fn create(spec: SpecInput, warnings: &mut Vec<String>) -> Result<Self, ServiceError> {
        let (network, config, decided) = network::validate(&spec)?;
        warnings.extend(decided);
        let cat062 = match &spec.cat062 {
            Some(c) => Some(cat062::validate(c, &network, "cat062")?),
            None => None,
        };
        let tracker = Tracker::with_config(config).map_err(|e| network::config_error(&e))?;
        let window = LagWindow::with_policy(
            tracker,
            network::max_lag(&spec)?,
            network::late_policy(&spec)?,
        )
        .map_err(|e| network::config_error(&e))?;
        Ok(Self {
            marks: Vec::new(),
            last_tracks: None,
            network,
            window,
            cat062,
        })
    }

    fn check_size(batch: &BatchInput, limits: &Limits) -> Result<(), ServiceError> {
        let asterix = batch
            .asterix
            .as_ref()
            .map_or(0, |a| a.data.len() / asterix::MIN_PLOT_RECORD_BYTES);
        let nmea = batch.nmea.as_ref().map_or(0, |n| n.lines.len());
        match (asterix, nmea) {
            (0, 0) => limits.check_batch(batch.plots.len(), "plots"),
            _ => limits.check_batch(
                batch.plots.len() + asterix + nmea,
                "plots (ASTERIX counted as one per 10 bytes, NMEA one per line)",
            ),
        }
    }

    fn apply(
        &mut self,
        batch: &BatchInput,
        limits: &Limits,
        warnings: &mut Vec<String>,
    ) -> Result<BatchUpdate, ServiceError> {
        self.apply_with(batch, limits, warnings, true)
    }

    /// A replayed batch's update is not read: the state after it is the
    /// same, but the update has no track views (`tracks`, `deleted`,
    /// `dropped`, `cat062` empty), which at 4,000 tracks cost a replay
    /// more than the batch's own tracking.
    fn apply_unread(
        &mut self,
        batch: &BatchInput,
        limits: &Limits,
        warnings: &mut Vec<String>,
    ) -> Result<BatchUpdate, ServiceError> {
        self.apply_with(batch, limits, warnings, false)
    }

    fn stored_copy(&self) -> Option<Self> {
        Some(Self {
            marks: Vec::new(),
            last_tracks: None,
            network: self.network.clone(),
            window: self.window.stored_copy(),
            cat062: self.cat062,
        })
    }

    fn take_marks(&mut self) -> Vec<PlotMark> {
        std::mem::take(&mut self.marks)
    }

    fn radar_biases(update: &BatchUpdate) -> &[RadarBiasView] {
        &update.registration
    }

    fn radar_accuracy(update: &BatchUpdate) -> &[RadarAccuracyView] {
        &update.accuracy
    }

    fn acknowledgement(&self) -> BatchUpdate {
        BatchUpdate {
            frames: 0,
            pending_plots: self.window.pending() as u32,
            late_plots: Vec::new(),
            late_within_lag: 0,
            corrected_from_t: None,
            tracks: Vec::new(),
            deleted: Vec::new(),
            dropped: Vec::new(),
            counters: self.window.counters().into(),
            asterix: None,
            cat062: self.cat062.map(|_| Cat062Data::default()),
            registration: self.network.bias_views(self.tracker()),
            accuracy: self.network.accuracy_views(self.tracker()),
        }
    }

    fn fingerprint(batch: &BatchInput) -> Option<u64> {
        let asterix = batch.asterix.as_ref().filter(|a| !a.data.is_empty());
        let nmea = batch.nmea.as_ref().filter(|n| !n.lines.is_empty());
        if batch.plots.is_empty() && asterix.is_none() && nmea.is_none() {
            return None;
        }
        let mut h = Fnv::default();
        h.bytes(&[u8::from(batch.flush)]);
        if let Some(a) = asterix {
            h.bytes(&a.data);
            h.str(a.date.as_deref());
            h.opt_f64(a.day_start_t);
        }
        if let Some(n) = nmea {
            for line in &n.lines {
                h.str(Some(line));
            }
            h.opt_f64(n.time_offset_s);
        }
        for p in &batch.plots {
            h.str(p.radar_id.as_deref());
            for x in [
                p.t,
                p.range_m,
                p.azimuth_deg,
                p.elevation_deg,
                p.radial_velocity_mps,
            ] {
                h.opt_f64(x);
            }
            // A plot's secondary fields and a report's, as the log writes
            // them (a primary plot hashes as it did before they existed,
            // so a retry across the upgrade is still known).
            if !p.ssr.is_empty() || p.report.is_some() {
                let mut w = Writer::default();
                p.ssr.encode(&mut w);
                w.opt(p.report.as_ref(), |w, r| r.encode(w));
                h.bytes(&w.buf);
            }
        }
        Some(h.0)
    }

    fn view(&self) -> Result<SessionView, ServiceError> {
        let tracker = self.tracker();
        Ok(SessionView {
            mode: mode_name(tracker.mode()),
            state_layout: output::layout(tracker.config().axes),
            radars: self.network.radar_ids.clone(),
            origin: self.network.frame.as_ref().map(|f| {
                let (lat, lon, h) = f.origin_geodetic();
                [lat.to_degrees(), lon.to_degrees(), h]
            }),
            sites: tracker
                .config()
                .radars
                .iter()
                .map(|r| SiteView {
                    position: r.site,
                    lat_lon_deg: self.network.frame.as_ref().and_then(|f| {
                        f.enu_to_geodetic(r.site)
                            .ok()
                            .map(|(lat, lon, _)| [lat.to_degrees(), lon.to_degrees()])
                    }),
                    three_d: r.sigma_elevation.is_some(),
                    doppler: r.sigma_radial_velocity.is_some(),
                })
                .collect(),
            last_frame_t: tracker.last_time(),
            pending_plots: self.window.pending() as u32,
            max_lag_s: self.window.max_lag(),
            late_plots: match self.window.policy() {
                algo::tracking::LatePolicy::Reprocess => "reprocess",
                algo::tracking::LatePolicy::Retrodict => "retrodict",
                algo::tracking::LatePolicy::Auto { .. } => "auto",
            },
            approximate_from: self.window.approximate_from(),
            late_before_t: self.window.horizon(),
            counters: self.window.counters().into(),
            tracks: tracker
                .tracks()
                .iter()
                .map(|t| self.network.track_view(&tracker.config().motion, t))
                .collect(),
            registration: self.network.bias_views(tracker),
            accuracy: self.network.accuracy_views(tracker),
            pressure_offset: self.network.pressure_offset_view(tracker).map(Box::new),
        })
    }

    fn encode_batch(batch: &BatchInput, w: &mut Writer) -> bool {
        // Destructured whole: a field added to the input is a compile error
        // here until the log carries it.
        let BatchInput {
            plots,
            asterix,
            nmea,
            flush,
        } = batch;
        w.usize(plots.len());
        for p in plots {
            let PlotInput {
                radar_id,
                t,
                range_m,
                azimuth_deg,
                elevation_deg,
                radial_velocity_mps,
                ssr: _,
                report: _,
            } = p;
            w.opt(radar_id.as_deref(), Writer::str);
            for x in [t, range_m, azimuth_deg, elevation_deg, radial_velocity_mps] {
                w.opt(*x, Writer::f64);
            }
        }
        w.opt(asterix.as_ref(), |w, a| {
            let AsterixInput {
                data,
                date,
                day_start_t,
                reference_t,
                reception,
            } = a;
            w.bytes(data);
            w.opt(date.as_deref(), Writer::str);
            w.opt(*day_start_t, Writer::f64);
            w.opt(*reference_t, Writer::f64);
            w.opt(*reception, |w, r| {
                w.f64(r.t);
                w.f64(r.max_offset_s);
            });
        });
        w.bool(*flush);
        // Since SSR: each plot's secondary fields, after the batch (an
        // entry of an earlier release ends at `flush` and reads as
        // primary plots).
        let reports = plots.iter().any(|p| p.report.is_some());
        if reports || plots.iter().any(|p| !p.ssr.is_empty()) {
            for p in plots {
                p.ssr.encode(w);
            }
        }
        // Since cooperative reports: each plot's report, after the SSR
        // fields (an entry without reports ends there).
        if reports || nmea.is_some() {
            if !reports && plots.iter().all(|p| p.ssr.is_empty()) {
                for p in plots {
                    p.ssr.encode(w);
                }
            }
            for p in plots {
                w.opt(p.report.as_ref(), |w, r| r.encode(w));
            }
        }
        // Since NMEA: its block, after the reports (an entry without one
        // ends there).
        if let Some(n) = nmea {
            let NmeaInput {
                lines,
                time_offset_s,
            } = n;
            w.usize(lines.len());
            for l in lines {
                w.str(l);
            }
            w.opt(*time_offset_s, Writer::f64);
        }
        true
    }

    fn decode_batch(r: &mut Reader<'_>) -> Result<BatchInput, FormatError> {
        // A plot takes at least six bytes (six option tags).
        let n = r.len(6)?;
        let plots = (0..n)
            .map(|_| {
                Ok(PlotInput {
                    radar_id: r.opt(Reader::str)?,
                    t: r.opt(Reader::f64)?,
                    range_m: r.opt(Reader::f64)?,
                    azimuth_deg: r.opt(Reader::f64)?,
                    elevation_deg: r.opt(Reader::f64)?,
                    radial_velocity_mps: r.opt(Reader::f64)?,
                    ssr: SsrInput::default(),
                    report: None,
                })
            })
            .collect::<Result<_, FormatError>>()?;
        let asterix = r.opt(|r| {
            Ok(AsterixInput {
                data: r.bytes()?,
                date: r.opt(Reader::str)?,
                day_start_t: r.opt(Reader::f64)?,
                reference_t: r.opt(Reader::f64)?,
                reception: r.opt(|r| {
                    Ok(asterix::Reception {
                        t: r.f64()?,
                        max_offset_s: r.f64()?,
                    })
                })?,
            })
        })?;
        let flush = r.bool()?;
        let mut plots: Vec<PlotInput> = plots;
        if !r.is_empty() {
            for p in &mut plots {
                p.ssr = SsrInput::decode(r)?;
            }
        }
        if !r.is_empty() {
            for p in &mut plots {
                p.report = r.opt(ReportInput::decode)?;
            }
        }
        let nmea = if r.is_empty() {
            None
        } else {
            // A line takes at least its length's bytes.
            let n = r.len(1)?;
            let lines = (0..n)
                .map(|_| r.str())
                .collect::<Result<Vec<_>, FormatError>>()?;
            Some(NmeaInput {
                lines,
                time_offset_s: r.opt(Reader::f64)?,
            })
        };
        Ok(BatchInput {
            plots,
            asterix,
            nmea,
            flush,
        })
    }

    fn encode(&self, w: &mut Writer) {
        w.u8(FORMAT_VERSION);
        self.network.encode(w);
        w.bytes(&encode_lag_window(&self.window));
        self.network.encode_sources(w);
        w.opt(self.cat062.as_ref(), cat062::encode_options);
    }

    fn decode(r: &mut Reader<'_>) -> Result<Self, ServiceError> {
        let format = r.u8().map_err(stored)?;
        if !(1..=FORMAT_VERSION).contains(&format) {
            return Err(ServiceError::Internal(format!(
                "stored plot_fusion session has format {format}; this release reads 1 to \
                 {FORMAT_VERSION}"
            )));
        }
        let network = Network::decode(r).map_err(stored)?;
        let bytes = r.bytes().map_err(stored)?;
        let window = if format >= 4 {
            decode_lag_window(&bytes).map_err(stored)?
        } else {
            let tracker = decode_tracker(&bytes).map_err(stored)?;
            LagWindow::new(tracker, algo::tracking::window::DEFAULT_MAX_LAG_S)
                .map_err(|e| stored(invalid(e)))?
        };
        let network = if format >= 2 {
            network.decode_sources(r).map_err(stored)?
        } else {
            network
        };
        if window.picture().config().radars.len() != network.radar_ids.len() {
            return Err(stored(corrupt("radar count")));
        }
        let cat062 = if format >= 3 {
            r.opt(cat062::decode_options).map_err(stored)?
        } else {
            None
        };
        Ok(Self {
            marks: Vec::new(),
            last_tracks: None,
            network,
            window,
            cat062,
        })
    }

    fn encode_update(u: &BatchUpdate, w: &mut Writer) {
        let optional = if u.asterix.is_some() { ASTERIX_FLAG } else { 0 }
            | if u.cat062.is_some() { CAT062_FLAG } else { 0 };
        w.u32(u.frames | WRITTEN_FLAGS | optional);
        w.u32(u.pending_plots);
        w.usize(u.late_plots.len());
        for &i in &u.late_plots {
            w.u32(i);
        }
        w.usize(u.tracks.len());
        for c in &u.tracks {
            w.u8(TRACK_CHANGES
                .iter()
                .position(|k| *k == c.change)
                .unwrap_or(0) as u8);
            encode_track(w, &c.track);
        }
        w.usize(u.deleted.len());
        for t in &u.deleted {
            encode_track(w, t);
        }
        w.usize(u.dropped.len());
        for &id in &u.dropped {
            w.u64(id);
        }
        encode_counters(w, &u.counters.into());
        if let Some(a) = &u.asterix {
            encode_summary(w, a);
        }
        if let Some(c) = &u.cat062 {
            w.bytes(&c.data);
            for n in [c.blocks, c.records, c.skipped, c.saturated] {
                w.usize(n);
            }
        }
        w.u32(u.late_within_lag);
        w.opt(u.corrected_from_t, Writer::f64);
        w.usize(u.registration.len());
        for b in &u.registration {
            w.str(&b.radar);
            w.f64_run(&[
                b.range_m,
                b.azimuth_deg,
                b.sigma_range_m,
                b.sigma_azimuth_deg,
                b.pairs,
            ]);
            w.opt(b.elevation_deg, Writer::f64);
            w.opt(b.sigma_elevation_deg, Writer::f64);
            w.u8(u8::from(b.converged) | u8::from(b.reference) << 1);
        }
        w.usize(u.accuracy.len());
        for a in &u.accuracy {
            w.str(&a.radar);
            w.bool(a.pinned);
            for (_, s) in a.components() {
                encode_sigma(w, s.copied());
            }
            encode_sigma(w, a.p_detection);
        }
    }

    fn decode_update(r: &mut Reader<'_>) -> Result<BatchUpdate, FormatError> {
        let frames = r.u32()?;
        let has_asterix = frames & ASTERIX_FLAG != 0;
        let has_cat062 = frames & CAT062_FLAG != 0;
        let has_late = frames & LATE_FLAG != 0;
        let has_registration = frames & REGISTRATION_FLAG != 0;
        let has_accuracy = frames & ACCURACY_FLAG != 0;
        let has_detection = frames & DETECTION_FLAG != 0;
        let fields = TrackFields {
            modes: frames & MODES_FLAG != 0,
            provenance: frames & PROVENANCE_FLAG != 0,
            identity: frames & IDENTITY_FLAG != 0,
            sources: frames & SOURCES_FLAG != 0,
        };
        let frames = frames & !FLAGS;
        let pending_plots = r.u32()?;
        let n = r.len(4)?;
        let late_plots = (0..n).map(|_| r.u32()).collect::<Result<_, _>>()?;
        let n = r.len(8)?;
        let mut tracks = Vec::with_capacity(n);
        for _ in 0..n {
            let change = *TRACK_CHANGES
                .get(r.u8()? as usize)
                .ok_or_else(|| corrupt("track change"))?;
            tracks.push(ChangedTrack {
                change,
                track: decode_track(r, fields)?,
            });
        }
        let n = r.len(8)?;
        let deleted = (0..n)
            .map(|_| decode_track(r, fields))
            .collect::<Result<_, _>>()?;
        let n = r.len(8)?;
        let dropped = (0..n).map(|_| r.u64()).collect::<Result<_, _>>()?;
        let counters = decode_counters(r)?.into();
        let asterix = if has_asterix {
            Some(decode_summary(r)?)
        } else {
            None
        };
        let cat062 = if has_cat062 {
            let data = r.bytes()?;
            let mut n = [0usize; 4];
            for x in &mut n {
                *x = r.usize()?;
            }
            Some(Cat062Data {
                data,
                blocks: n[0],
                records: n[1],
                skipped: n[2],
                saturated: n[3],
            })
        } else {
            None
        };
        let (late_within_lag, corrected_from_t) = if has_late {
            (r.u32()?, r.opt(Reader::f64)?)
        } else {
            (0, None)
        };
        let registration = if has_registration {
            let n = r.len(8)?;
            (0..n)
                .map(|_| {
                    let radar = r.str()?;
                    let mut v = [0.0; 5];
                    for x in &mut v {
                        *x = r.f64()?;
                    }
                    let elevation_deg = r.opt(Reader::f64)?;
                    let sigma_elevation_deg = r.opt(Reader::f64)?;
                    let flags = r.u8()?;
                    Ok(RadarBiasView {
                        radar,
                        range_m: v[0],
                        azimuth_deg: v[1],
                        elevation_deg,
                        sigma_range_m: v[2],
                        sigma_azimuth_deg: v[3],
                        sigma_elevation_deg,
                        pairs: v[4],
                        converged: flags & 1 != 0,
                        reference: flags & 2 != 0,
                    })
                })
                .collect::<Result<_, FormatError>>()?
        } else {
            Vec::new()
        };
        let accuracy = if has_accuracy {
            let n = r.len(8)?;
            (0..n)
                .map(|_| {
                    let radar = r.str()?;
                    let pinned = r.bool()?;
                    let missing = || corrupt("a radar's range or azimuth accuracy");
                    Ok(RadarAccuracyView {
                        radar,
                        range_m: decode_sigma(r)?.ok_or_else(missing)?,
                        azimuth_deg: decode_sigma(r)?.ok_or_else(missing)?,
                        elevation_deg: decode_sigma(r)?,
                        radial_velocity_mps: decode_sigma(r)?,
                        p_detection: if has_detection {
                            decode_sigma(r)?
                        } else {
                            None
                        },
                        pinned,
                    })
                })
                .collect::<Result<_, FormatError>>()?
        } else {
            Vec::new()
        };
        Ok(BatchUpdate {
            frames,
            pending_plots,
            late_plots,
            late_within_lag,
            corrected_from_t,
            tracks,
            deleted,
            dropped,
            counters,
            asterix,
            cat062,
            registration,
            accuracy,
        })
    }
}

/// One σ of a radar's accuracy in an update (or none).
fn encode_sigma(w: &mut Writer, s: Option<SigmaView>) {
    w.opt(s, |w, s| {
        w.f64_run(&[s.declared, s.plots, s.applied]);
        w.opt(s.estimated, Writer::f64);
        w.opt(s.sigma, Writer::f64);
        w.bool(s.converged);
        w.u64(s.clipped);
    });
}

fn decode_sigma(r: &mut Reader<'_>) -> Result<Option<SigmaView>, FormatError> {
    r.opt(|r| {
        let [declared, plots, applied] = r.f64_run::<3>()?;
        Ok(SigmaView {
            declared,
            plots,
            applied,
            estimated: r.opt(Reader::f64)?,
            sigma: r.opt(Reader::f64)?,
            converged: r.bool()?,
            clipped: r.u64()?,
        })
    })
}

/// A warning for each radar whose applied bias moved by more than 3σ
/// (of the estimate before) in one batch: the radar was realigned, or a
/// prior was wrong.
fn realigned(before: &[RadarBiasView], after: &[RadarBiasView]) -> Vec<String> {
    before
        .iter()
        .zip(after)
        .filter(|(b, a)| {
            b.converged
                && ((a.range_m - b.range_m).abs() > 3.0 * b.sigma_range_m.max(1.0)
                    || (a.azimuth_deg - b.azimuth_deg).abs() > 3.0 * b.sigma_azimuth_deg.max(1e-3))
        })
        .map(|(b, a)| {
            format!(
                "radar {}'s bias changed from {:.0} m, {:.3}° to {:.0} m, {:.3}° in this batch (beyond 3σ): was the radar realigned?",
                b.radar, b.range_m, b.azimuth_deg, a.range_m, a.azimuth_deg
            )
        })
        .collect()
}

/// What changed between the picture before a batch and after it.
#[derive(Default)]
struct Changes {
    /// Per live track after the batch, in order.
    live: Vec<TrackChange>,
    /// Confirmed tracks gone: deleted by the batch's frames (as they were
    /// when deleted), or removed by a correction (as they were before it).
    deleted: Vec<TrackOutput>,
    /// Tentative tracks gone, ids ascending.
    dropped: Vec<u64>,
}

/// The changes from the tracks `before` a batch to the tracks `after` it,
/// given what the push did (see [`TrackChange::Corrected`]).
fn diff(before: &[TrackOutput], after: &[TrackOutput], push: &algo::tracking::Push) -> Changes {
    use std::collections::HashMap;
    let old: HashMap<u64, &TrackOutput> = before.iter().map(|t| (t.id, t)).collect();
    let now: HashSet<u64> = after.iter().map(|t| t.id).collect();
    let live = after
        .iter()
        .map(|t| match old.get(&t.id) {
            None if t.status == TrackStatus::Confirmed => TrackChange::Confirmed,
            None => TrackChange::Initiated,
            Some(o) if o.status != TrackStatus::Confirmed && t.status == TrackStatus::Confirmed => {
                TrackChange::Confirmed
            }
            Some(o) if push.earliest_within_lag.is_some_and(|e| o.last_update >= e) => {
                TrackChange::Corrected
            }
            Some(_) => TrackChange::Updated,
        })
        .collect();
    // The last report of each deleted track (a replay reports again).
    let reported: HashMap<u64, &TrackOutput> = push.deleted.iter().map(|t| (t.id, t)).collect();
    let mut deleted = Vec::new();
    let mut dropped = Vec::new();
    for t in before.iter().filter(|t| !now.contains(&t.id)) {
        if t.status == TrackStatus::Confirmed {
            let mut gone = (*reported.get(&t.id).unwrap_or(&t)).clone();
            gone.status = TrackStatus::Deleted;
            deleted.push(gone);
        } else {
            dropped.push(t.id);
        }
    }
    dropped.sort_unstable();
    Changes {
        live,
        deleted,
        dropped,
    }
}

fn encode_summary(w: &mut Writer, a: &AsterixSummary) {
    for n in [
        a.bytes,
        a.blocks,
        a.records,
        a.target_reports,
        a.plots,
        a.north_markers,
        a.sector_crossings,
        a.other_service_messages,
        a.unmapped,
        a.test_targets,
        a.incomplete,
        a.rejected,
        a.late,
        a.errors_not_listed,
    ] {
        w.usize(n);
    }
    w.usize(a.late_offsets.len());
    a.late_offsets.iter().for_each(|&o| w.usize(o));
    w.opt(a.first_t, Writer::f64);
    w.opt(a.last_t, Writer::f64);
    w.usize(a.errors.len());
    for e in &a.errors {
        w.usize(e.offset);
        w.str(&e.reason);
    }
}

fn decode_summary(r: &mut Reader<'_>) -> Result<AsterixSummary, FormatError> {
    let mut n = [0usize; 14];
    for x in &mut n {
        *x = r.usize()?;
    }
    let k = r.len(8)?;
    let late_offsets = (0..k).map(|_| r.usize()).collect::<Result<_, _>>()?;
    let first_t = r.opt(Reader::f64)?;
    let last_t = r.opt(Reader::f64)?;
    let k = r.len(9)?;
    let mut errors = Vec::with_capacity(k);
    for _ in 0..k {
        errors.push(wire_formats::asterix::DecodeError {
            offset: r.usize()?,
            reason: r.str()?,
        });
    }
    Ok(AsterixSummary {
        bytes: n[0],
        blocks: n[1],
        records: n[2],
        target_reports: n[3],
        plots: n[4],
        north_markers: n[5],
        sector_crossings: n[6],
        other_service_messages: n[7],
        unmapped: n[8],
        test_targets: n[9],
        incomplete: n[10],
        rejected: n[11],
        late: n[12],
        errors_not_listed: n[13],
        late_offsets,
        first_t,
        last_t,
        errors,
    })
}

// The batch endpoint's types, for the equality test below.
#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::plot_fusion::{self as pf, RadarInput, SiteInput, TrackInput};
    use formats::state::tracker::encode_tracker;

    pub(crate) fn spec() -> SpecInput {
        SpecInput {
            origin: None,
            radars: [("a", -200.0, 10.0), ("b", 200.0, 8.0)]
                .into_iter()
                .map(|(id, x, period)| RadarInput {
                    id: Some(id.into()),
                    kind: Some("2d".into()),
                    site: Some(SiteInput {
                        geodetic: None,
                        position_m: Some(vec![x, 0.0]),
                    }),
                    sigma_range_m: Some(100.0),
                    sigma_azimuth_deg: Some(0.1),
                    scan_period_s: Some(period),
                    ..Default::default()
                })
                .collect(),
            tracker: Default::default(),
            cat062: None,
        }
    }

    /// Two crossing targets seen every 10 s and 8 s, with a deterministic
    /// wobble standing in for noise.
    pub(crate) fn plots() -> Vec<PlotInput> {
        let mut out = Vec::new();
        for (id, x, period) in [("a", -200.0, 10.0), ("b", 200.0, 8.0)] {
            let mut t: f64 = 0.0;
            let mut k = 0.0;
            while t <= 120.0 {
                for (e0, n0, ve, vn) in [
                    (-25_000.0, 35_000.0, 30.0, -50.0),
                    (-26_000.0, 31_000.0, 50.0, 20.0),
                ] {
                    let (e, n): (f64, f64) = (e0 + ve * t - x, n0 + vn * t);
                    k += 1.0;
                    out.push(PlotInput {
                        radar_id: Some(id.into()),
                        t: Some(t),
                        range_m: Some(e.hypot(n) + 60.0 * (k * 1.7f64).sin()),
                        azimuth_deg: Some(e.atan2(n).to_degrees() + 0.05 * (k * 2.3f64).cos()),
                        ..Default::default()
                    });
                }
                t += period;
            }
        }
        out.sort_by(|a, b| a.t.unwrap().total_cmp(&b.t.unwrap()));
        out
    }

    #[test]
    fn batches_in_time_order_give_the_batch_endpoints_tracks_across_encode_and_decode() {
        let all = plots();
        let whole = pf::track(TrackInput {
            spec: spec(),
            plots: all.clone(),
            asterix: None,
            nmea: None,
            history: false,
        })
        .unwrap();
        let limits = Limits {
            max_tracks: 100,
            max_batch_reports: 1000,
        };
        let mut session = PlotFusionSession::create(spec(), &mut Vec::new()).unwrap();
        let chunks: Vec<&[PlotInput]> = all.chunks(7).collect();
        let n = chunks.len();
        for (i, chunk) in chunks.into_iter().enumerate() {
            let mut w = Writer::default();
            session.encode(&mut w);
            session = PlotFusionSession::decode(&mut Reader::new(&w.buf)).unwrap();
            let mut warnings = Vec::new();
            let update = session
                .apply(
                    &BatchInput {
                        plots: chunk.to_vec(),
                        flush: i + 1 == n,
                        ..Default::default()
                    },
                    &limits,
                    &mut warnings,
                )
                .unwrap();
            assert!(warnings.is_empty(), "{warnings:?}");
            let mut w = Writer::default();
            PlotFusionSession::encode_update(&update, &mut w);
            let back = PlotFusionSession::decode_update(&mut Reader::new(&w.buf)).unwrap();
            assert_eq!(back, update);
        }
        let view = session.view().unwrap();
        assert_eq!(view.tracks, whole.tracks);
        assert_eq!(view.counters, whole.counters);
        assert_eq!(view.max_lag_s, 15.0);
        assert_eq!(whole.tracks.len(), 2);
    }

    /// At its limit of tracks a session applies the batch and refuses new
    /// track starts with a warning, instead of refusing every batch from
    /// then on (which wedged a session fed by a listener).
    #[test]
    fn a_session_at_its_track_limit_goes_on_and_says_so() {
        let limits = Limits {
            max_tracks: 1,
            max_batch_reports: 1000,
        };
        let mut session = PlotFusionSession::create(spec(), &mut Vec::new()).unwrap();
        let mut said = Vec::new();
        let mut applied = 0;
        for chunk in plots().chunks(7) {
            let mut warnings = Vec::new();
            let batch = BatchInput {
                plots: chunk.to_vec(),
                ..Default::default()
            };
            session.apply(&batch, &limits, &mut warnings).unwrap();
            applied += 1;
            assert!(session.tracker().tracks().len() <= 1);
            said.extend(warnings);
        }
        assert!(applied > 5);
        // Two targets, one track allowed: the other's starts are refused.
        assert!(
            said.iter()
                .any(|w| w.contains("limit of 1 tracks") && w.contains("refused")),
            "{said:?}"
        );
        assert_eq!(session.view().unwrap().tracks.len(), 1);
    }

    #[test]
    fn a_window_at_its_bound_of_plots_says_so() {
        let limits = Limits {
            max_tracks: 100,
            max_batch_reports: 1000,
        };
        let mut session = PlotFusionSession::create(spec(), &mut Vec::new()).unwrap();
        session.window.set_max_plots(3);
        let all = plots();
        let mut said = Vec::new();
        for chunk in all.chunks(7) {
            let mut warnings = Vec::new();
            let batch = BatchInput {
                plots: chunk.to_vec(),
                ..Default::default()
            };
            session.apply(&batch, &limits, &mut warnings).unwrap();
            said.extend(warnings);
        }
        assert!(
            said.iter()
                .any(|w| w.contains("bound of 3 plots") && w.contains("tracker.max_lag_s")),
            "{said:?}"
        );
    }

    #[test]
    fn a_late_plot_is_dropped_and_named_and_a_failed_batch_is_an_error() {
        let limits = Limits {
            max_tracks: 100,
            max_batch_reports: 1000,
        };
        let all = plots();
        // A lag of 2 s: the plot at t = 0 is late beyond it.
        let mut short = spec();
        short.tracker.max_lag_s = Some(2.0);
        let mut session = PlotFusionSession::create(short, &mut Vec::new()).unwrap();
        let mut warnings = Vec::new();
        session
            .apply(
                &BatchInput {
                    plots: all[..20].to_vec(),
                    flush: true,
                    ..Default::default()
                },
                &limits,
                &mut warnings,
            )
            .unwrap();
        let mut late = all[0].clone();
        late.t = Some(0.0);
        let update = session
            .apply(
                &BatchInput {
                    plots: vec![all[20].clone(), late],
                    flush: false,
                    ..Default::default()
                },
                &limits,
                &mut warnings,
            )
            .unwrap();
        assert_eq!(update.late_plots, vec![1]);
        assert_eq!(update.counters.late, 1);
        assert!(warnings[0].contains("late"), "{warnings:?}");
        let mut bad = all[21].clone();
        bad.radar_id = Some("zz".into());
        let err = session
            .apply(
                &BatchInput {
                    plots: vec![bad],
                    flush: false,
                    ..Default::default()
                },
                &limits,
                &mut warnings,
            )
            .unwrap_err();
        match err {
            ServiceError::InvalidInput(v) => assert_eq!(v[0].field, "plots[0].radar_id"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn format_1_payloads_read_without_sac_sic_and_asterix_updates_round_trip() {
        let mut with_sources = spec();
        with_sources.radars[0].sac = Some(25);
        with_sources.radars[0].sic = Some(1);
        let session = PlotFusionSession::create(with_sources, &mut Vec::new()).unwrap();
        let mut w = Writer::default();
        session.encode(&mut w);
        let back = PlotFusionSession::decode(&mut Reader::new(&w.buf)).unwrap();
        assert_eq!(back.network.radar_of_source((25, 1)), Some(0));
        // Format 1, as the release before ASTERIX wrote it: no SAC/SIC.
        let mut old = Writer::default();
        old.u8(1);
        session.network.encode(&mut old);
        old.bytes(&encode_tracker(session.tracker()));
        let back = PlotFusionSession::decode(&mut Reader::new(&old.buf)).unwrap();
        assert_eq!(back.network.radar_of_source((25, 1)), None);
        assert_eq!(back.network.radar_ids, session.network.radar_ids);
        // Format 2, as the release before CAT062 out wrote it: no option.
        let mut v2 = Writer::default();
        v2.u8(2);
        session.network.encode(&mut v2);
        v2.bytes(&encode_tracker(session.tracker()));
        session.network.encode_sources(&mut v2);
        let back = PlotFusionSession::decode(&mut Reader::new(&v2.buf)).unwrap();
        assert_eq!(back.network.radar_of_source((25, 1)), Some(0));
        assert_eq!(back.cat062, None);
        // An update with an ASTERIX summary round-trips; one without has
        // bit 31 of frames clear (bit 30 says its tracks carry modes).
        let mut update = session.acknowledgement();
        update.frames = 3;
        let mut plain = Writer::default();
        PlotFusionSession::encode_update(&update, &mut plain);
        assert_eq!(
            plain.buf[..4],
            (3u32
                | MODES_FLAG
                | PROVENANCE_FLAG
                | LATE_FLAG
                | REGISTRATION_FLAG
                | IDENTITY_FLAG
                | ACCURACY_FLAG
                | DETECTION_FLAG
                | SOURCES_FLAG)
                .to_le_bytes()
        );
        // An update kept by the release before the IMM (no bit 30, tracks
        // without modes) still reads.
        let mut before = plain.buf.clone();
        before[..4].copy_from_slice(&3u32.to_le_bytes());
        let read = PlotFusionSession::decode_update(&mut Reader::new(&before)).unwrap();
        assert_eq!(read.frames, 3);
        update.asterix = Some(AsterixSummary {
            bytes: 40,
            records: 3,
            late: 1,
            late_offsets: vec![17],
            first_t: Some(1.5),
            errors: vec![wire_formats::asterix::DecodeError {
                offset: 30,
                reason: "cut".into(),
            }],
            ..Default::default()
        });
        let mut w = Writer::default();
        PlotFusionSession::encode_update(&update, &mut w);
        let back = PlotFusionSession::decode_update(&mut Reader::new(&w.buf)).unwrap();
        assert_eq!(back, update);
    }

    /// A batch's NMEA block is logged and read back with its plots and
    /// reports, with and without SSR fields before it.
    #[test]
    fn nmea_blocks_round_trip_through_the_log() {
        let nmea = NmeaInput {
            lines: vec![
                "\\c:1700000003*5C\\!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C".into(),
            ],
            time_offset_s: Some(1.7e9),
        };
        let primary = PlotInput {
            radar_id: Some("coast".into()),
            t: Some(1.0),
            range_m: Some(5000.0),
            azimuth_deg: Some(10.0),
            ..Default::default()
        };
        let report = PlotInput {
            t: Some(2.0),
            report: Some(ReportInput {
                source: Some("ais".into()),
                lat_deg: Some(50.7),
                lon_deg: Some(-1.1),
                mmsi: Some(235_070_762),
                ..Default::default()
            }),
            ..Default::default()
        };
        for plots in [vec![], vec![primary.clone()], vec![primary, report]] {
            let batch = BatchInput {
                plots,
                asterix: None,
                nmea: Some(nmea.clone()),
                flush: false,
            };
            let mut w = Writer::default();
            assert!(PlotFusionSession::encode_batch(&batch, &mut w));
            let back = PlotFusionSession::decode_batch(&mut Reader::new(&w.buf)).unwrap();
            assert_eq!(back.nmea, batch.nmea);
            assert_eq!(back.plots.len(), batch.plots.len());
            for (a, b) in back.plots.iter().zip(&batch.plots) {
                assert_eq!((a.t, &a.radar_id, &a.ssr), (b.t, &b.radar_id, &b.ssr));
                assert_eq!(a.report, b.report);
            }
        }
    }

    /// Two unsequenced batches that differ only in a report's position or
    /// a plot's Mode S address are two batches, not a retry.
    #[test]
    fn fingerprints_cover_reports_and_secondary_fields() {
        let report = |lat: f64| PlotInput {
            t: Some(5.0),
            report: Some(ReportInput {
                source: Some("adsb".into()),
                lat_deg: Some(lat),
                lon_deg: Some(2.0),
                nacp: Some(9),
                ..Default::default()
            }),
            ..Default::default()
        };
        let batch = |plots: Vec<PlotInput>| BatchInput {
            plots,
            ..Default::default()
        };
        let f = |b: &BatchInput| PlotFusionSession::fingerprint(b).unwrap();
        assert_eq!(f(&batch(vec![report(48.0)])), f(&batch(vec![report(48.0)])));
        assert_ne!(f(&batch(vec![report(48.0)])), f(&batch(vec![report(48.1)])));
        let plot = |address: &str| PlotInput {
            radar_id: Some("a".into()),
            t: Some(5.0),
            range_m: Some(1e4),
            azimuth_deg: Some(10.0),
            ssr: SsrInput {
                mode_s_address: Some(address.into()),
                ..Default::default()
            },
            ..Default::default()
        };
        assert_ne!(
            f(&batch(vec![plot("4CA2D1")])),
            f(&batch(vec![plot("4CA2D2")]))
        );
    }
}
