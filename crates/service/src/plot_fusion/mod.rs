//! Multi-radar plot fusion (seed 001): radar plots in, fused tracks out,
//! over the tracker of `algo::tracking`.
//!
//! This module owns the wire-level vocabulary of the tracker: radars named
//! by string ids with sites in WGS84 or as local offsets about the request's
//! `origin`, angles in degrees, the tracker's options with defaults, and
//! tracks with latitude and longitude. [`network`] validates a request into
//! a [`Network`] (the geometry and ids) and a `TrackerConfig`, and plots
//! into the core's [`Plot`]s; [`output`] turns the core's tracks back into
//! wire tracks. [`track`] is the batch endpoint; the session kind
//! (`service::session::plot_fusion`) uses the same pieces.

pub mod asterix;
pub mod cat062;
pub mod network;
pub mod nmea;
pub mod output;
pub mod report;
pub mod ssr;

use std::{ops::ControlFlow, time::Instant};

use super::{ServiceError, micros_since};
use algo::{
    AlgoError,
    tracking::{Counters, Mode, Plot, Tracker, TrackerConfig},
};
pub use network::Network;
pub use output::{
    DisagreementView, HistoryEntry, LastPlotView, ModeView, SelfReportedView, SourceView,
    TrackView, TrackerCounters, model_names,
};
pub use report::ReportInput;
pub use ssr::{IdentityItem, IdentityView, PressureAltitudeView, SsrInput};

/// Most radars in a network.
pub const MAX_RADARS: usize = 64;
/// Most plots in one batch request.
pub const MAX_PLOTS: usize = 1_000_000;
/// Default detection probability of a radar.
pub const DEFAULT_P_DETECTION: f64 = 0.9;
/// Default clutter density: false plots per m·rad (2D) or m·rad² (3D).
/// 1e-7 is about one false plot per scan over 250 km × 360° for a 2D radar.
pub const DEFAULT_CLUTTER_DENSITY: f64 = 1e-7;
/// Most track states a `history` may hold (the confirmed tracks summed over
/// the frames): each is about 1 kB of JSON, so the answer stays under
/// about 50 MB. A request whose history would hold more is refused, naming
/// `history`, rather than answered with gigabytes.
pub const MAX_HISTORY_TRACK_STATES: usize = 50_000;

/// A WGS84 position: the dimension service's site input, shared.
pub use super::dimension::SiteInput as GeoInput;

/// A radar site: WGS84 (`geodetic`) or a local offset `[e, n, u]` from the
/// request's origin; exactly one.
#[derive(Debug, Clone, Default)]
pub struct SiteInput {
    pub geodetic: Option<GeoInput>,
    pub position_m: Option<Vec<f64>>,
}

#[derive(Debug, Clone, Default)]
pub struct RadarInput {
    pub id: Option<String>,
    /// `2d` or `3d`.
    pub kind: Option<String>,
    pub site: Option<SiteInput>,
    pub sigma_range_m: Option<f64>,
    pub sigma_azimuth_deg: Option<f64>,
    pub sigma_elevation_deg: Option<f64>,
    /// Present: the radar measures the radial (Doppler) velocity.
    pub sigma_radial_velocity_mps: Option<f64>,
    pub scan_period_s: Option<f64>,
    pub p_detection: Option<f64>,
    pub clutter_density: Option<f64>,
    /// ASTERIX System Area Code and System Identification Code (I048/010):
    /// the radar's records in ASTERIX input. Both or neither, 0 to 255.
    pub sac: Option<u32>,
    pub sic: Option<u32>,
    /// A known bias (a survey, the AIS–radar endpoint): the registration's
    /// prior for this radar.
    pub bias: Option<BiasInput>,
}

/// A radar's known bias and its σ (each field optional: 0 bias, the
/// default σ of `algo::tracking::registration::BiasPrior`).
#[derive(Debug, Clone, Default)]
pub struct BiasInput {
    pub range_m: Option<f64>,
    pub azimuth_deg: Option<f64>,
    pub elevation_deg: Option<f64>,
    pub sigma_range_m: Option<f64>,
    pub sigma_azimuth_deg: Option<f64>,
    pub sigma_elevation_deg: Option<f64>,
}

/// `tracker.registration`.
#[derive(Debug, Clone, Default)]
pub struct RegistrationInput {
    /// Default: on with two radars or more.
    pub enabled: Option<bool>,
    /// Radar ids whose bias is held at its prior.
    pub reference: Option<Vec<String>>,
    pub min_pairs: Option<u32>,
    pub max_pair_dt_s: Option<f64>,
    pub time_constant_s: Option<f64>,
}

/// `tracker.mode_c_height`: Mode C as a measurement of the geometric
/// height, and the prior of the pressure-to-geometric offset
/// (`algo::tracking::height`).
#[derive(Debug, Clone, Default)]
pub struct ModeCHeightInput {
    /// Default true (3D trackers).
    pub enabled: Option<bool>,
    /// Learn the offset from 3D radars' plots (default true).
    pub learn: Option<bool>,
    pub offset_m: Option<f64>,
    pub sigma_offset_m: Option<f64>,
    pub slope: Option<f64>,
    pub sigma_slope: Option<f64>,
}

/// `tracker.accuracy`: each radar's σ learnt online
/// (`algo::tracking::accuracy`).
#[derive(Debug, Clone, Default)]
pub struct AccuracyInput {
    /// Default true.
    pub enabled: Option<bool>,
    /// Forgetting time constant (s); default 900.
    pub time_constant_s: Option<f64>,
    /// Radar ids whose declared σ are applied whatever the data say.
    pub pinned: Option<Vec<String>>,
}

/// One σ of a radar: declared, estimated online and applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SigmaView {
    pub declared: f64,
    /// `None` before any plot, or when the data do not identify it.
    pub estimated: Option<f64>,
    /// σ of the estimate; `None` with it.
    pub sigma: Option<f64>,
    /// Plots behind the estimate (decayed count).
    pub plots: f64,
    pub converged: bool,
    /// The σ the tracker applies now.
    pub applied: f64,
    /// Innovations winsorised (beyond 3σ).
    pub clipped: u64,
}

/// A radar's accuracy as the tracker learnt and applies it (σ in the wire
/// units: m, °, m/s).
#[derive(Debug, Clone, PartialEq)]
pub struct RadarAccuracyView {
    pub radar: String,
    pub range_m: SigmaView,
    pub azimuth_deg: SigmaView,
    /// 3D radars in a 3D tracker.
    pub elevation_deg: Option<SigmaView>,
    /// Doppler radars.
    pub radial_velocity_mps: Option<SigmaView>,
    /// The detection probability per scan (`plots`: the trials, scans
    /// between the radar's hits of established tracks; nothing clipped);
    /// `None` in an update kept by an earlier release.
    pub p_detection: Option<SigmaView>,
    /// Declared σ (and P_D) applied whatever the data say.
    pub pinned: bool,
}

impl RadarAccuracyView {
    /// Each σ by its wire name (`range_m`, `azimuth_deg`, `elevation_deg`,
    /// `radial_velocity_mps`: the radar's option is `sigma_` and the
    /// name), `None` for a component the radar does not measure.
    pub fn components(&self) -> [(&'static str, Option<&SigmaView>); 4] {
        [
            ("range_m", Some(&self.range_m)),
            ("azimuth_deg", Some(&self.azimuth_deg)),
            ("elevation_deg", self.elevation_deg.as_ref()),
            ("radial_velocity_mps", self.radial_velocity_mps.as_ref()),
        ]
    }
}

/// The pressure-to-geometric offset as a 3D tracker applies it to Mode C
/// (geometric height = h_p + offset_m + slope·h_p).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureOffsetView {
    pub offset_m: f64,
    pub slope: f64,
    pub sigma_offset_m: f64,
    pub sigma_slope: f64,
    /// Correlation of the offset's and the slope's errors.
    pub correlation: f64,
    /// 3D radar plots with Mode C learnt from, and refused by the gate.
    pub plots: u64,
    pub rejected: u64,
}

/// A radar's bias as the tracker applies it.
#[derive(Debug, Clone, PartialEq)]
pub struct RadarBiasView {
    pub radar: String,
    pub range_m: f64,
    pub azimuth_deg: f64,
    /// 3D radars.
    pub elevation_deg: Option<f64>,
    pub sigma_range_m: f64,
    pub sigma_azimuth_deg: f64,
    pub sigma_elevation_deg: Option<f64>,
    /// Common-target plot pairs behind the estimate (decayed count).
    pub pairs: f64,
    /// The estimate is applied (enough pairs); else the prior is.
    pub converged: bool,
    /// Held at its prior.
    pub reference: bool,
}

#[derive(Debug, Clone, Default)]
pub struct InitiationInput {
    pub m: Option<u32>,
    pub n: Option<u32>,
    pub v_min_mps: Option<f64>,
    pub v_max_mps: Option<f64>,
    /// Per-axis velocity gate `[e, n(, u)]`, instead of the speed band.
    pub v_min_axis_mps: Option<Vec<f64>>,
    pub v_max_axis_mps: Option<Vec<f64>>,
    pub gate_probability: Option<f64>,
    pub min_dt_s: Option<f64>,
    pub max_dt_s: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct DeletionInput {
    pub max_consecutive_misses: Option<u32>,
    /// M_d of the M_d-of-N_d miss rule.
    pub m: Option<u32>,
    pub n: Option<u32>,
    pub max_position_sigma_m: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct TrackerInput {
    /// 2 or 3; default 3 when any radar is 3D, else 2.
    pub dimensions: Option<u32>,
    /// `auto` (default), `parallel` or `serial`.
    pub mode: Option<String>,
    pub fusion_period_s: Option<f64>,
    pub fusion_epoch_s: Option<f64>,
    pub time_tolerance_s: Option<f64>,
    /// `exact` (default), `amsjpda`, `global_nearest_neighbour`, `nearest_neighbour`.
    pub association: Option<String>,
    pub max_exact_cluster_tracks: Option<u32>,
    pub plot_gate_probability: Option<f64>,
    pub track_gate_probability: Option<f64>,
    pub initiation: Option<InitiationInput>,
    pub deletion: Option<DeletionInput>,
    /// `cwna` (default) or `dwna`.
    pub process_noise: Option<String>,
    pub sigma_a_mps2: Option<f64>,
    pub sigma_a_vertical_mps2: Option<f64>,
    pub default_height_m: Option<f64>,
    pub default_height_sigma_m: Option<f64>,
    pub sigma_tangential_speed_mps: Option<f64>,
    pub duplicate_gate_probability: Option<f64>,
    /// `imm` (default) or `cv` (one constant-velocity model with
    /// `sigma_a_mps2`).
    pub motion: Option<String>,
    /// The IMM's models; absent: `algo::tracking::Imm::aircraft`.
    pub imm_models: Option<Vec<ImmModelInput>>,
    /// Sessions: plots are taken in any order within this lag (s) of the
    /// newest plot received; default 15, at most 120. The batch call
    /// sorts its plots and only checks it.
    pub max_lag_s: Option<f64>,
    /// Sessions: how a plot older than the newest is taken: `auto`
    /// (default: `reprocess` while the lag window holds at most
    /// `max_replay_plots`, `retrodict` beyond), `reprocess` (exact, the
    /// batch call's tracks bit for bit) or `retrodict` (the tracks it
    /// gates with updated where they stand; approximate; serial mode).
    pub late_plots: Option<String>,
    /// `auto`: most plots the lag window may hold for a replay (default
    /// 5,000).
    pub max_replay_plots: Option<u32>,
    /// Radar registration (bias estimation); default on with two radars.
    pub registration: Option<Box<RegistrationInput>>,
    pub mode_c_height: Option<ModeCHeightInput>,
    /// Each radar's σ learnt online; default on.
    pub accuracy: Option<AccuracyInput>,
}

/// One model of the IMM.
#[derive(Debug, Clone, Default)]
pub struct ImmModelInput {
    /// `cv` (constant velocity) or `ct` (coordinated turn).
    pub model: Option<String>,
    /// Noise per horizontal axis (√q for CWNA); default 0.5 (cv), 3 (ct).
    pub sigma_a_mps2: Option<f64>,
    /// Vertical noise; default `sigma_a_mps2`.
    pub sigma_a_vertical_mps2: Option<f64>,
    /// `ct`: turn rate (°/s, positive to the left), required.
    pub turn_rate_dps: Option<f64>,
    /// Mean time in the model (s); default 60 (cv), 20 (ct).
    pub mean_sojourn_s: Option<f64>,
    /// Mode probability of a new track; all or none (then equal shares).
    pub initial_probability: Option<f64>,
}

/// Everything that configures a tracker: the network and the options.
#[derive(Debug, Clone, Default)]
pub struct SpecInput {
    /// The fusion centre (ENU origin); absent: the first radar given in
    /// WGS84, or (all sites local) none, and tracks carry no lat/lon.
    pub origin: Option<GeoInput>,
    pub radars: Vec<RadarInput>,
    pub tracker: TrackerInput,
    /// ASTERIX CAT062 out: the tracks also as system track messages.
    pub cat062: Option<cat062::Cat062Input>,
}

#[derive(Debug, Clone, Default)]
pub struct PlotInput {
    pub radar_id: Option<String>,
    pub t: Option<f64>,
    pub range_m: Option<f64>,
    pub azimuth_deg: Option<f64>,
    pub elevation_deg: Option<f64>,
    pub radial_velocity_mps: Option<f64>,
    /// The plot's SSR and Mode S fields (none for a primary plot); a
    /// report's identity (address, callsign, Mode 3/A, barometric flight
    /// level).
    pub ssr: SsrInput,
    /// A cooperative report (ADS-B, multilateration, AIS) instead of a
    /// radar's plot: then `radar_id`, `range_m`, `azimuth_deg`,
    /// `elevation_deg` and `radial_velocity_mps` are not used.
    pub report: Option<ReportInput>,
}

/// A batch request: the network, its plots (any order) and whether to
/// return the confirmed tracks after every processing instant.
#[derive(Debug, Clone, Default)]
pub struct TrackInput {
    pub spec: SpecInput,
    pub plots: Vec<PlotInput>,
    /// Raw ASTERIX beside (or instead of) `plots`.
    pub asterix: Option<asterix::AsterixInput>,
    /// AIS over NMEA (`!AIVDM` lines) beside them.
    pub nmea: Option<nmea::NmeaInput>,
    pub history: bool,
}

/// The batch response.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackOutput {
    /// The resolved mode, `parallel` or `serial`.
    pub mode: &'static str,
    pub state_layout: &'static [&'static str],
    /// Confirmed then tentative tracks at the end of the data.
    pub tracks: Vec<TrackView>,
    /// Confirmed tracks deleted during the data, as they were when deleted.
    pub deleted: Vec<TrackView>,
    pub history: Option<Vec<HistoryEntry>>,
    pub counters: TrackerCounters,
    /// What the ASTERIX input gave, when there was one.
    pub asterix: Option<asterix::AsterixSummary>,
    /// `tracks` as CAT062 records, in the same order, when asked for.
    pub cat062: Option<cat062::Cat062Data>,
    /// Each radar's bias as applied at the end of the data.
    pub registration: Vec<RadarBiasView>,
    /// Each radar's σ, declared, learnt and applied, at the end of the
    /// data.
    pub accuracy: Vec<RadarAccuracyView>,
    /// The pressure offset a 3D tracker applies to Mode C.
    pub pressure_offset: Option<PressureOffsetView>,
    pub compute_us: f64,
    pub warnings: Vec<String>,
}

/// The name of a resolved mode.
pub fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Parallel => "parallel",
        Mode::Serial => "serial",
        Mode::Auto => "auto",
    }
}

/// Tracks every plot of the request from scratch and closes the last frame.
pub fn track(input: TrackInput) -> Result<TrackOutput, ServiceError> {
    let (network, config, mut warnings) = network::validate(&input.spec)?;
    let cat062_options = match &input.spec.cat062 {
        Some(c) => Some(cat062::validate(c, &network, "cat062")?),
        None => None,
    };
    let asterix_bound = input
        .asterix
        .as_ref()
        .map_or(0, |a| a.data.len() / asterix::MIN_PLOT_RECORD_BYTES);
    let nmea_lines = input.nmea.as_ref().map_or(0, |n| n.lines.len());
    if input.plots.len() + asterix_bound + nmea_lines > MAX_PLOTS {
        return Err(ServiceError::TooLarge(format!(
            "{} plots (ASTERIX counted as one per {} bytes, NMEA one per line); at most \
             {MAX_PLOTS} per request (stream larger data through a plot_fusion session)",
            input.plots.len() + asterix_bound + nmea_lines,
            asterix::MIN_PLOT_RECORD_BYTES
        )));
    }
    let clock = match &input.asterix {
        Some(a) => Some(asterix::clock(a, "asterix", None)?),
        None => None,
    };
    let mut plots = network.plots(&input.plots, &config, "plots")?;
    let start = Instant::now();
    let summary = match (&input.asterix, clock) {
        (Some(a), Some(clock)) => {
            let from = asterix::plots(&network, &config, &a.data, clock, a.reception);
            plots.extend(from.plots);
            warnings.extend(from.warnings);
            Some(from.summary)
        }
        _ => None,
    };
    if let Some(n) = &input.nmea {
        nmea::extend(n, (&network, &config), &mut plots, &mut warnings)?;
    }
    if plots.is_empty() {
        warnings.push(if input.asterix.is_some() {
            "no plot to track: `plots` is empty and the ASTERIX data gave no usable target \
             report (see asterix.errors and its counts)"
                .to_string()
        } else {
            "no plot to track: give `plots`, `cooperative` reports, an `asterix` or `nmea` \
             block"
                .to_string()
        });
    }
    // Stable: plots of equal time keep the request's order, as a session
    // fed the same plots in order would.
    plots.sort_by(|a, b| a.t.total_cmp(&b.t));
    let mut tracker = Tracker::with_config(config).map_err(|e| network::config_error(&e))?;
    let mut history = input.history.then(Vec::new);
    let mut states = 0usize;
    let mut cancelled = Ok(());
    let report = tracker
        .process_with(&plots, true, &mut |t: &Tracker| {
            // An abandoned request stops after the frame.
            cancelled = crate::lanes::checkpoint();
            if cancelled.is_err() {
                return ControlFlow::Break(());
            }
            if let Some(h) = history.as_mut() {
                let confirmed = t.confirmed_count();
                states += confirmed;
                if states > MAX_HISTORY_TRACK_STATES {
                    // Refused below: keep counting, stop collecting.
                    h.clear();
                    return ControlFlow::Continue(());
                }
                h.push((t.last_time().unwrap_or(f64::NAN), t.confirmed_tracks()));
            }
            ControlFlow::Continue(())
        })
        .map_err(computation_error)?;
    cancelled?;
    if states > MAX_HISTORY_TRACK_STATES {
        return Err(history_too_large(states, report.frames));
    }
    let compute_us = micros_since(start);
    let tracks = tracker.tracks();
    let counters = tracker.counters();
    let registration = network.bias_views(&tracker);
    warnings.extend(network::registration_warnings(
        tracker.config(),
        &registration,
    ));
    warnings.extend(outcome_warnings(
        &network,
        tracker.config(),
        &plots,
        &counters,
        &tracks,
    ));
    warnings.extend(ssr::warnings(&tracks));
    warnings.extend(output::self_reported_warnings(&tracks));
    let pressure_offset = network.pressure_offset_view(&tracker);
    let accuracy = network.accuracy_views(&tracker);
    warnings.extend(network::accuracy_warnings(tracker.config(), &accuracy));
    warnings.extend(ssr::height_warnings(&tracker, &tracks));
    warnings.extend(undefined_warning(&report.undefined));
    warnings.extend(failed_warning(&report.failed));
    let motion = &tracker.config().motion;
    let tracks: Vec<TrackView> = tracks
        .iter()
        .map(|t| network.track_view(motion, t))
        .collect();
    let cat062 = cat062_options.map(|o| {
        let items: Vec<_> = tracks
            .iter()
            .map(|t| (t, cat062::Life::Continuing))
            .collect();
        cat062::encode(&o, &network, &items, &mut warnings)
    });
    Ok(TrackOutput {
        mode: mode_name(tracker.mode()),
        state_layout: output::layout(tracker.config().axes),
        tracks,
        deleted: report
            .deleted
            .iter()
            .map(|t| network.track_view(motion, t))
            .collect(),
        history: history.map(|h| {
            h.into_iter()
                .map(|(t, tracks)| HistoryEntry {
                    t,
                    tracks: tracks
                        .iter()
                        .map(|tr| network.track_view(motion, tr))
                        .collect(),
                })
                .collect()
        }),
        counters: counters.into(),
        asterix: summary,
        cat062,
        registration,
        accuracy,
        pressure_offset,
        compute_us,
        warnings,
    })
}

/// The tracks whose numbers failed (a non-finite value, a covariance that
/// is not positive definite), each named once with what became of it
/// (`algo::tracking::FailedStep`: dropped, or coasted past an
/// out-of-sequence plot), where and when it first failed; the rest of the
/// data applied. A replay of late plots may report a failure again: each
/// track is named once.
pub fn failed_warning(failures: &[algo::tracking::TrackFailure]) -> Option<String> {
    use algo::tracking::FailedStep;
    let mut seen = std::collections::HashSet::new();
    let first: Vec<&algo::tracking::TrackFailure> =
        failures.iter().filter(|f| seen.insert(f.id)).collect();
    if first.is_empty() {
        return None;
    }
    let shown: Vec<String> = first
        .iter()
        .take(10)
        .map(|f| {
            let (kind, step) = match f.step {
                FailedStep::Predict => ("confirmed track", "its prediction"),
                FailedStep::Associate => ("confirmed track", "its association"),
                FailedStep::Update => ("confirmed track", "its update"),
                FailedStep::Carry => ("confirmed track", "a late plot's update"),
                FailedStep::Initiate => ("tentative track", "its start"),
            };
            let fate = if f.dropped() {
                "dropped"
            } else {
                "coasted (the late plot not applied)"
            };
            format!(
                "{kind} {} {fate} at t = {}: {step} failed ({})",
                f.id, f.t, f.error
            )
        })
        .collect();
    Some(format!(
        "{} track(s) whose numbers failed: {}{}; the rest of the data applied (a dropped \
         track's target starts a new track from its next plots)",
        first.len(),
        shown.join("; "),
        if first.len() > 10 { "; …" } else { "" }
    ))
}

/// The tracks a frame could not associate because their prediction lay at
/// a radar's site (an overflight: the azimuth is undefined there); they
/// coasted through those frames and the rest applied.
pub fn undefined_warning(ids: &[u64]) -> Option<String> {
    if ids.is_empty() {
        return None;
    }
    let mut unique = ids.to_vec();
    unique.sort_unstable();
    unique.dedup();
    let shown: Vec<String> = unique.iter().take(10).map(u64::to_string).collect();
    Some(format!(
        "{} frame(s) could not associate track(s) {}{} (predicted at a radar's site, \
         where its azimuth is undefined: an overflight): those tracks coasted through \
         those frames, the rest of the data applied",
        ids.len(),
        shown.join(", "),
        if unique.len() > 10 { ", …" } else { "" }
    ))
}

/// The error of a `history` larger than [`MAX_HISTORY_TRACK_STATES`].
fn history_too_large(states: usize, frames: usize) -> ServiceError {
    super::validate::Violations::single(
        "history",
        format!(
            "would hold {states} track states (confirmed tracks summed over {frames} frames); \
             at most {MAX_HISTORY_TRACK_STATES} per request: send fewer plots per request, \
             or push them to a plot_fusion session and read its updates"
        ),
    )
}

/// Warnings about what the data gave: radars without plots, nothing
/// confirmed.
pub fn outcome_warnings(
    network: &Network,
    config: &TrackerConfig,
    plots: &[Plot],
    counters: &Counters,
    tracks: &[algo::tracking::TrackOutput],
) -> Vec<String> {
    let mut warnings = Vec::new();
    let mut seen = vec![false; network.radar_ids.len()];
    // Radars only (a cooperative report's sensor is past them).
    for p in plots {
        if let Some(s) = seen.get_mut(p.radar) {
            *s = true;
        }
    }
    if !plots.is_empty() {
        let silent: Vec<&str> = network
            .radar_ids
            .iter()
            .zip(&seen)
            .filter(|(_, s)| !**s)
            .map(|(id, _)| id.as_str())
            .collect();
        if !silent.is_empty() {
            warnings.push(format!(
                "radar(s) {} gave no plot in this request",
                silent.join(", ")
            ));
        }
    }
    if counters.plots > 0 && counters.confirmed == 0 && tracks.is_empty() {
        warnings.push(format!(
            "no track was started from {} plots over {} frames: check the initiation \
             (tracker.initiation.v_max_mps, min_dt_s, max_dt_s) and the plots' times",
            counters.plots, counters.frames
        ));
    } else if counters.plots > 0 && counters.confirmed == 0 {
        warnings.push(format!(
            "no track was confirmed from {} plots over {} frames ({} tentative): \
             confirmation needs {} hits of the last {} frames; lower tracker.initiation.m \
             or send more scans",
            counters.plots,
            counters.frames,
            tracks.len(),
            config.initiation.confirm_m,
            config.initiation.confirm_n
        ));
    }
    warnings
}

/// An error of the tracker after validation: a geometry or conditioning
/// problem of the data, reported against the plots.
pub fn computation_error(e: AlgoError) -> ServiceError {
    let message = match &e {
        AlgoError::DegenerateGeometry { .. } => {
            "a plot or a predicted track lies at (or straight above) a radar's site".to_string()
        }
        other => format!("tracking failed numerically: {other}"),
    };
    ServiceError::InvalidInput(vec![super::FieldViolation {
        field: "plots".into(),
        message,
    }])
}

#[cfg(test)]
mod tests {
    use super::*;
    use algo::tracking::{FailedStep, TrackFailure};

    /// Each failed track named once (a replay reports it again), with what
    /// became of it and why.
    #[test]
    fn the_failure_warning_names_each_track_once_with_its_fate() {
        let failure = |id, step| TrackFailure {
            id,
            confirmed: step != FailedStep::Initiate,
            t: 12.5,
            step,
            error: algo::AlgoError::NotPositiveDefinite {
                what: "innovation covariance",
            },
        };
        assert_eq!(failed_warning(&[]), None);
        let w = failed_warning(&[
            failure(7, FailedStep::Associate),
            failure(9, FailedStep::Carry),
            failure(7, FailedStep::Associate),
            failure(11, FailedStep::Initiate),
        ])
        .unwrap();
        assert!(w.starts_with("3 track(s)"), "{w}");
        assert_eq!(w.matches("track 7 ").count(), 1, "{w}");
        assert!(
            w.contains(
                "confirmed track 7 dropped at t = 12.5: its association failed \
                 (innovation covariance is not positive definite)"
            ),
            "{w}"
        );
        assert!(w.contains("confirmed track 9 coasted"), "{w}");
        assert!(w.contains("tentative track 11 dropped"), "{w}");
    }
}
