//! Tracks as the wire shows them: the core's track with radar ids instead
//! of indices, nested covariance rows, and WGS84 latitude/longitude (and
//! height for a 3D tracker) of its position.

use super::Network;
use algo::geo::LocalFrame;
use algo::tracking::{Motion, MotionModel, TrackOutput, TrackStatus};

/// State layouts of the 2D and 3D trackers.
pub const LAYOUT_2D: [&str; 4] = ["x", "vx", "y", "vy"];
pub const LAYOUT_3D: [&str; 6] = ["x", "vx", "y", "vy", "z", "vz"];

/// The layout of a tracker with `axes` spatial axes.
pub fn layout(axes: usize) -> &'static [&'static str] {
    if axes == 3 { &LAYOUT_3D } else { &LAYOUT_2D }
}

/// One track.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackView {
    pub id: u64,
    /// `tentative`, `confirmed` or `deleted`.
    pub status: &'static str,
    pub t: f64,
    pub state: Vec<f64>,
    pub covariance: Vec<Vec<f64>>,
    /// Absent when the request has no origin. A 2D track's is the point
    /// above its (e, n) at `tracker.default_height_m`.
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    /// 3D trackers only (WGS84 ellipsoidal height).
    pub height_m: Option<f64>,
    /// Radars whose plots updated the track at its last update.
    pub radars: Vec<String>,
    pub hits: u32,
    pub misses: u32,
    pub consecutive_misses: u32,
    /// Frames since the track started.
    pub age: u32,
    pub last_update_t: f64,
    /// An IMM track's mode probabilities by model, in the configuration's
    /// order (empty for a single-model or tentative track).
    pub modes: Vec<ModeView>,
    /// An IMM track's turn rate Σ μ_j ω_j (°/s, positive to the left),
    /// when its models include a turn.
    pub turn_rate_dps: Option<f64>,
    /// Time of the track's first plot; absent for a track kept by a
    /// release that did not record it.
    pub start_t: Option<f64>,
    /// The radar plot of the track's last update, when that update was
    /// one radar's plot (serial mode); absent after a fused plot (parallel
    /// mode).
    pub last_plot: Option<LastPlotView>,
    /// What the track knows of its aircraft from SSR and Mode S (absent
    /// when no secondary plot has updated it).
    pub identity: Option<super::ssr::IdentityView>,
    /// Per sensor that has updated the track (radars in the network's
    /// order, then `adsb`, `mlat`, `ais`): the time of its last update
    /// (its sources and their ages).
    pub sources: Vec<SourceView>,
    /// The check of its self-reported positions (ADS-B, AIS) against
    /// independent evidence (radar plots, multilateration); absent when no
    /// self-reported position has updated it.
    pub self_reported: Option<SelfReportedView>,
    /// A ship's AIS MMSI, from its reports.
    pub mmsi: Option<u32>,
}

/// One sensor's last update of a track.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceView {
    pub sensor: String,
    pub last_t: f64,
}

/// A track's self-reported positions checked against independent evidence
/// (`algo::tracking::identity::Validation`).
#[derive(Debug, Clone, PartialEq)]
pub struct SelfReportedView {
    /// Its self-reported positions are used (false: they disagreed with
    /// the independent evidence and are not, until they agree again).
    pub trusted: bool,
    /// Independent evidence updated it within the last 30 s (false: an
    /// ADS-B-only stretch, unvalidated).
    pub validated: bool,
    pub distrusted_since_t: Option<f64>,
    pub last_self_reported_t: Option<f64>,
    pub last_independent_t: Option<f64>,
    /// The last disagreement.
    pub disagreement: Option<DisagreementView>,
}

/// A self-reported position against independent evidence.
#[derive(Debug, Clone, PartialEq)]
pub struct DisagreementView {
    pub t: f64,
    /// Horizontal distance between the two (m).
    pub distance_m: f64,
    /// The self-reported position's stated σ per axis (m).
    pub stated_sigma_m: f64,
}

/// The self-reported check of a core track, when it has one.
pub fn self_reported_view(t: &TrackOutput) -> Option<SelfReportedView> {
    let v = &t.identity.validation;
    v.last_self_reported.map(|_| SelfReportedView {
        trusted: v.trusted(),
        validated: v.validated(t.t),
        distrusted_since_t: v.distrusted_since,
        last_self_reported_t: v.last_self_reported,
        last_independent_t: v.last_independent,
        disagreement: v.last_disagreement.map(|d| DisagreementView {
            t: d.t,
            distance_m: d.distance,
            stated_sigma_m: d.sigma,
        }),
    })
}

/// The warnings of tracks whose self-reported positions are distrusted
/// (one line each, with the numbers) and of confirmed tracks on
/// self-reported positions alone (one line for all).
pub fn self_reported_warnings(tracks: &[TrackOutput]) -> Vec<String> {
    let mut out = Vec::new();
    let mut unvalidated = Vec::new();
    for t in tracks.iter().filter(|t| t.status == TrackStatus::Confirmed) {
        let Some(v) = self_reported_view(t) else {
            continue;
        };
        let address = match (t.identity.address, t.identity.mmsi) {
            (Some(a), _) => format!("address {:06X}", a.value),
            (None, Some(m)) => format!("MMSI {:09}", m.value),
            (None, None) => "no address".to_string(),
        };
        if let (false, Some(d)) = (v.trusted, v.disagreement) {
            out.push(format!(
                "track {} ({address}): its ADS-B/AIS positions disagree with independent evidence (radar, multilateration) by {:.0} m against a stated σ of {:.0} m, since t = {:.1} s; they are not used until {} in a row agree (faulty avionics or spoofing)",
                t.id,
                d.distance_m,
                d.stated_sigma_m,
                v.distrusted_since_t.unwrap_or(d.t),
                algo::tracking::identity::AGREEMENTS_TO_TRUST
            ));
        } else if !v.validated {
            unvalidated.push(t.id);
        }
    }
    if !unvalidated.is_empty() {
        let shown: Vec<String> = unvalidated.iter().take(10).map(u64::to_string).collect();
        out.push(format!(
            "{} confirmed tracks are held by ADS-B/AIS alone, unvalidated (no radar or multilateration update in the last {} s): {}{}",
            unvalidated.len(),
            algo::tracking::identity::INDEPENDENT_WINDOW_S,
            shown.join(", "),
            if unvalidated.len() > 10 { ", …" } else { "" }
        ));
    }
    out
}

/// The plot that last updated a track, as the radar measured it.
#[derive(Debug, Clone, PartialEq)]
pub struct LastPlotView {
    pub radar: String,
    pub t: f64,
    pub range_m: f64,
    /// Clockwise from north, in [0, 360).
    pub azimuth_deg: f64,
    pub elevation_deg: Option<f64>,
    pub radial_velocity_mps: Option<f64>,
}

/// One model's probability in an IMM track.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeView {
    /// The model's name ([`model_names`]).
    pub model: String,
    pub probability: f64,
}

/// The names of an IMM's models: `cv` for constant velocity, `ct_left` /
/// `ct_right` for a turn to the left (ω > 0) / right, with `_2`, `_3`, …
/// after a name already taken. Empty for a single model.
pub fn model_names(motion: &Motion) -> Vec<String> {
    let Motion::Imm(imm) = motion else {
        return Vec::new();
    };
    let mut names: Vec<String> = Vec::with_capacity(imm.models.len());
    for m in &imm.models {
        let base = match m {
            MotionModel::ConstantVelocity { .. } => "cv",
            MotionModel::CoordinatedTurn { turn_rate, .. } if *turn_rate > 0.0 => "ct_left",
            MotionModel::CoordinatedTurn { .. } => "ct_right",
        };
        let taken = names
            .iter()
            .filter(|n| n.as_str() == base || n.starts_with(&format!("{base}_")))
            .count();
        names.push(if taken == 0 {
            base.to_string()
        } else {
            format!("{base}_{}", taken + 1)
        });
    }
    names
}

/// The confirmed tracks after one processing instant.
#[derive(Debug, Clone, PartialEq)]
pub struct HistoryEntry {
    pub t: f64,
    pub tracks: Vec<TrackView>,
}

pub fn status_name(s: TrackStatus) -> &'static str {
    match s {
        TrackStatus::Tentative => "tentative",
        TrackStatus::Confirmed => "confirmed",
        TrackStatus::Deleted => "deleted",
    }
}

/// The geodetic position of the point above the fusion plane's (e, n) at
/// ellipsoidal height `h` (a 2D track's targets are assumed there): up is
/// found by fixed-point iteration u ← u + (h − height(u)), which converges
/// in a few steps because the fusion up and the local vertical differ by
/// the small angle d/R.
fn at_height(f: &LocalFrame, e: f64, n: f64, h: f64) -> Option<(f64, f64, f64)> {
    let mut u = h;
    let mut geo = f.enu_to_geodetic([e, n, u]).ok()?;
    for _ in 0..4 {
        u += h - geo.2;
        geo = f.enu_to_geodetic([e, n, u]).ok()?;
    }
    Some(geo)
}

pub(super) fn view(network: &Network, motion: &Motion, t: &TrackOutput) -> TrackView {
    let n = t.state.len();
    let three_d = n == 6;
    let position = [
        t.state[0],
        t.state[2],
        if three_d { t.state[4] } else { 0.0 },
    ];
    let geo = network.frame.as_ref().and_then(|f| {
        if three_d {
            f.enu_to_geodetic(position).ok()
        } else {
            at_height(f, position[0], position[1], network.target_height)
        }
    });
    TrackView {
        id: t.id,
        status: status_name(t.status),
        t: t.t,
        state: t.state.iter().copied().collect(),
        covariance: (0..n)
            .map(|i| (0..n).map(|j| t.covariance[(i, j)]).collect())
            .collect(),
        lat_deg: geo.map(|g| g.0.to_degrees()),
        lon_deg: geo.map(|g| g.1.to_degrees()),
        height_m: geo.filter(|_| three_d).map(|g| g.2),
        radars: t.radars.iter().map(|&r| network.sensor_name(r)).collect(),
        hits: t.hits,
        misses: t.misses,
        consecutive_misses: t.consecutive_misses,
        age: t.age,
        last_update_t: t.last_update,
        modes: model_names(motion)
            .into_iter()
            .zip(&t.modes)
            .map(|(model, &probability)| ModeView { model, probability })
            .collect(),
        turn_rate_dps: match motion {
            Motion::Imm(imm)
                if !t.modes.is_empty()
                    && imm
                        .models
                        .iter()
                        .any(|m| matches!(m, MotionModel::CoordinatedTurn { .. })) =>
            {
                Some(
                    imm.models
                        .iter()
                        .zip(&t.modes)
                        .map(|(m, mu)| mu * m.turn_rate())
                        .sum::<f64>()
                        .to_degrees(),
                )
            }
            _ => None,
        },
        start_t: t.started,
        last_plot: t.last_plot.map(|p| LastPlotView {
            radar: network.sensor_name(p.radar),
            t: p.t,
            range_m: p.range,
            azimuth_deg: p.azimuth.to_degrees().rem_euclid(360.0),
            elevation_deg: p.elevation.map(f64::to_degrees),
            radial_velocity_mps: p.radial_velocity,
        }),
        identity: super::ssr::view(&t.identity, t.t),
        sources: t
            .detections
            .iter()
            .map(|h| SourceView {
                sensor: network.sensor_name(h.radar),
                last_t: h.last,
            })
            .collect(),
        self_reported: self_reported_view(t),
        mmsi: t.identity.mmsi.map(|m| m.value),
    }
}

/// The tracker's running totals since it was created, as a client reads
/// them (the service's own type: the adapters do not see `algo`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackerCounters {
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
    /// Confirmed tracks deleted as duplicates of another.
    pub merged: u64,
}

impl From<algo::tracking::Counters> for TrackerCounters {
    fn from(c: algo::tracking::Counters) -> Self {
        let algo::tracking::Counters {
            plots,
            late,
            frames,
            fused_plots,
            started,
            confirmed,
            dropped,
            deleted,
            merged,
        } = c;
        Self {
            plots,
            late,
            frames,
            fused_plots,
            started,
            confirmed,
            dropped,
            deleted,
            merged,
        }
    }
}

impl From<TrackerCounters> for algo::tracking::Counters {
    fn from(c: TrackerCounters) -> Self {
        let TrackerCounters {
            plots,
            late,
            frames,
            fused_plots,
            started,
            confirmed,
            dropped,
            deleted,
            merged,
        } = c;
        Self {
            plots,
            late,
            frames,
            fused_plots,
            started,
            confirmed,
            dropped,
            deleted,
            merged,
        }
    }
}
