//! REST route of the multi-radar plot-fusion tracker (seed 001):
//! `POST /v1/plot-fusion/track`. The network and tracker DTOs are shared
//! with `plot_fusion` sessions (`http::sessions`).

use axum::{extract::State, response::Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{
    Timing,
    problem::{JsonBody, Problem},
};
use crate::state::AppState;
use service::plot_fusion::TrackerCounters as Counters;
use service::{self, plot_fusion as svc};

/// A WGS84 position (height above the ellipsoid, default 0).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GeoPoint {
    #[schema(example = 52.0)]
    pub lat_deg: f64,
    #[schema(example = 4.0)]
    pub lon_deg: f64,
    pub height_m: Option<f64>,
}

/// A radar site: WGS84 (`lat_deg`, `lon_deg`, `height_m`) or a local
/// `position_m: [east, north(, up)]` about `origin` (the radar's axes are
/// then taken as the fusion frame's).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlotRadarSite {
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    pub height_m: Option<f64>,
    #[schema(example = json!([-200.0, 0.0, 0.0]))]
    pub position_m: Option<Vec<f64>>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlotRadar {
    #[schema(example = "r1")]
    pub id: String,
    /// `2d` or `3d`.
    #[schema(example = "2d")]
    pub kind: String,
    pub site: PlotRadarSite,
    #[schema(example = 100.0)]
    pub sigma_range_m: Option<f64>,
    #[schema(example = 0.2)]
    pub sigma_azimuth_deg: Option<f64>,
    /// 3D radars.
    pub sigma_elevation_deg: Option<f64>,
    /// Present for a radar that measures the radial (Doppler) velocity.
    pub sigma_radial_velocity_mps: Option<f64>,
    #[schema(example = 4.0)]
    pub scan_period_s: Option<f64>,
    /// P_D in (0, 1], default 0.9.
    pub p_detection: Option<f64>,
    /// False plots per m·rad (2D) or m·rad² (3D), default 1e-7.
    pub clutter_density: Option<f64>,
    /// ASTERIX System Area Code (I048/010) of the radar's records; with `sic`.
    #[schema(maximum = 255, example = 25)]
    pub sac: Option<u32>,
    /// ASTERIX System Identification Code; with `sac`.
    #[schema(maximum = 255, example = 1)]
    pub sic: Option<u32>,
    /// A known bias of the radar (a survey, or `/v1/ais-radar/associate`'s
    /// estimate): the registration's prior, applied from the start.
    pub bias: Option<RadarBiasIn>,
}

/// A radar's known bias: what it adds to each measurement. Every field
/// optional: bias 0, σ 150 m, 0.15°, 0.1°.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RadarBiasIn {
    #[schema(example = 120.0)]
    pub range_m: Option<f64>,
    #[schema(example = 0.2)]
    pub azimuth_deg: Option<f64>,
    pub elevation_deg: Option<f64>,
    #[schema(example = 20.0)]
    pub sigma_range_m: Option<f64>,
    #[schema(example = 0.02)]
    pub sigma_azimuth_deg: Option<f64>,
    pub sigma_elevation_deg: Option<f64>,
}

/// `tracker.registration`: each radar's range, azimuth (and elevation)
/// bias estimated from common targets and corrected (docs/plot-fusion.md).
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RegistrationOptions {
    /// Default: on with two radars or more.
    pub enabled: Option<bool>,
    /// Radar ids whose bias is held at its prior (surveyed radars).
    pub reference: Option<Vec<String>>,
    /// Pairs a radar needs before its estimate is applied (default 20).
    pub min_pairs: Option<u32>,
    /// Longest time between the two plots of a pair (s, default 10).
    pub max_pair_dt_s: Option<f64>,
    /// Time constant of the estimate's memory (s, default 1800).
    pub time_constant_s: Option<f64>,
}

/// `tracker.mode_c_height`: a plot's validated Mode C as a measurement of
/// its track's geometric height (3D trackers), through the
/// pressure-to-geometric offset geometric = h_p + offset_m + slope·h_p,
/// learnt online from the 3D radars' plots that carry Mode C, from this
/// prior (docs/plot-fusion.md#mode-c-and-geometric-height).
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ModeCHeightOptions {
    /// Default true.
    pub enabled: Option<bool>,
    /// Learn the offset from 3D radars' plots (default true); false keeps
    /// the prior.
    pub learn: Option<bool>,
    /// Prior offset at pressure altitude 0 (m, default 0; from QNH: about
    /// 8.3 m per hPa above 1013.25).
    pub offset_m: Option<f64>,
    /// Its σ (m, default 150).
    pub sigma_offset_m: Option<f64>,
    /// Prior slope: metres of geometric height per metre of pressure
    /// altitude beyond 1 (default 0; ISA + ΔT: about ΔT / 288 K).
    pub slope: Option<f64>,
    /// Its σ (default 0.04).
    pub sigma_slope: Option<f64>,
}

/// The pressure-to-geometric offset a 3D tracker applies to Mode C:
/// geometric height = h_p + offset_m + slope·h_p.
#[derive(Debug, Serialize, ToSchema)]
pub struct PressureOffsetOut {
    pub offset_m: f64,
    pub slope: f64,
    pub sigma_offset_m: f64,
    pub sigma_slope: f64,
    /// Correlation of the offset's and the slope's errors (σ at pressure
    /// altitude h: √(σ_o² + 2ρ σ_o σ_s h + σ_s² h²)).
    pub correlation: f64,
    /// 3D radar plots with Mode C learnt from.
    pub plots: u64,
    /// Plots refused by the offset's gate (false replies, wrong
    /// associations).
    pub rejected: u64,
}

pub(crate) fn pressure_offset_out(o: svc::PressureOffsetView) -> PressureOffsetOut {
    PressureOffsetOut {
        offset_m: o.offset_m,
        slope: o.slope,
        sigma_offset_m: o.sigma_offset_m,
        sigma_slope: o.sigma_slope,
        correlation: o.correlation,
        plots: o.plots,
        rejected: o.rejected,
    }
}

/// `tracker.accuracy`: each radar's σ (range, azimuth, elevation, radial
/// velocity) learnt online from the innovations of the confirmed tracks
/// its plots update, and applied once converged instead of the declared
/// one (docs/plot-fusion.md#accuracy-learnt-online).
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AccuracyOptions {
    /// Default true.
    pub enabled: Option<bool>,
    /// Time constant of the estimates' memory (s, default 900).
    pub time_constant_s: Option<f64>,
    /// Radar ids whose declared σ are applied whatever the data say
    /// (still estimated and reported).
    pub pinned: Option<Vec<String>>,
}

/// One σ of a radar: declared, learnt online, applied.
#[derive(Debug, Serialize, ToSchema)]
pub struct SigmaOut {
    pub declared: f64,
    /// The estimate (absent before any plot, or while the tracks' own
    /// uncertainty hides the radar's noise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimated: Option<f64>,
    /// σ of the estimate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<f64>,
    /// Plots behind the estimate (decayed count).
    pub plots: f64,
    /// Enough plots: the estimate is applied (unless pinned).
    pub converged: bool,
    /// The σ the tracker applies now.
    pub applied: f64,
    /// Innovations winsorised: counted at 3σ of the estimate (a
    /// Gaussian has 0.27 % beyond; a manoeuvre's onset, a wrong
    /// association more).
    pub clipped: u64,
}

/// A radar's accuracy: each σ declared, learnt and applied, in m, ° and
/// m/s.
#[derive(Debug, Serialize, ToSchema)]
pub struct RadarAccuracyOut {
    pub radar: String,
    pub range_m: SigmaOut,
    pub azimuth_deg: SigmaOut,
    /// 3D radars in a 3D tracker.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub elevation_deg: Option<SigmaOut>,
    /// Doppler radars.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radial_velocity_mps: Option<SigmaOut>,
    /// The detection probability per scan (`p_detection`), learnt from
    /// the scans between the radar's hits of the confirmed tracks
    /// (`plots`: those trials; nothing clipped).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p_detection: Option<SigmaOut>,
    /// `tracker.accuracy.pinned`: the declared σ and P_D are applied.
    pub pinned: bool,
}

fn sigma_out(s: svc::SigmaView) -> SigmaOut {
    SigmaOut {
        declared: s.declared,
        estimated: s.estimated,
        sigma: s.sigma,
        plots: s.plots,
        converged: s.converged,
        applied: s.applied,
        clipped: s.clipped,
    }
}

pub(crate) fn accuracy_out(a: svc::RadarAccuracyView) -> RadarAccuracyOut {
    RadarAccuracyOut {
        radar: a.radar,
        range_m: sigma_out(a.range_m),
        azimuth_deg: sigma_out(a.azimuth_deg),
        elevation_deg: a.elevation_deg.map(sigma_out),
        radial_velocity_mps: a.radial_velocity_mps.map(sigma_out),
        p_detection: a.p_detection.map(sigma_out),
        pinned: a.pinned,
    }
}

/// A radar's bias as the tracker applies it (subtracted from its plots).
#[derive(Debug, Serialize, ToSchema)]
pub struct RadarBiasOut {
    pub radar: String,
    pub range_m: f64,
    pub azimuth_deg: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub elevation_deg: Option<f64>,
    pub sigma_range_m: f64,
    pub sigma_azimuth_deg: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma_elevation_deg: Option<f64>,
    /// Common-target plot pairs behind the estimate (decayed count).
    pub pairs: f64,
    /// The estimate is applied; before, the radar's known bias (or none).
    pub converged: bool,
    /// Held at its prior (`tracker.registration.reference`).
    pub reference: bool,
}

pub(crate) fn bias_out(b: svc::RadarBiasView) -> RadarBiasOut {
    RadarBiasOut {
        radar: b.radar,
        range_m: b.range_m,
        azimuth_deg: b.azimuth_deg,
        elevation_deg: b.elevation_deg,
        sigma_range_m: b.sigma_range_m,
        sigma_azimuth_deg: b.sigma_azimuth_deg,
        sigma_elevation_deg: b.sigma_elevation_deg,
        pairs: b.pairs,
        converged: b.converged,
        reference: b.reference,
    }
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlotIn {
    #[schema(example = "r1")]
    pub radar_id: String,
    #[schema(example = 0.0)]
    pub t: f64,
    #[schema(example = 42000.0)]
    pub range_m: f64,
    /// Clockwise from north at the radar.
    #[schema(example = 37.5)]
    pub azimuth_deg: f64,
    /// Required from a 3D radar, absent from a 2D radar.
    pub elevation_deg: Option<f64>,
    /// Positive receding; only from a radar with `sigma_radial_velocity_mps`.
    pub radial_velocity_mps: Option<f64>,
    /// Mode 3/A code, four octal digits (SSR).
    #[schema(example = "7000")]
    pub mode_3a: Option<String>,
    /// The code was validated (default true; I048/070 V = 0).
    pub mode_3a_validated: Option<bool>,
    /// The code is garbled (default false; I048/070 G): it weighs nothing.
    pub mode_3a_garbled: Option<bool>,
    /// Mode C flight level, hundreds of feet (−12 to 1270; FL 350.25 =
    /// 35,025 ft).
    #[schema(example = 350.0)]
    pub flight_level: Option<f64>,
    /// The flight level was validated (default true; I048/090 V = 0).
    pub flight_level_validated: Option<bool>,
    /// The flight level is garbled (default false; I048/090 G).
    pub flight_level_garbled: Option<bool>,
    /// Mode S address, six hexadecimal digits (24 bits).
    #[schema(example = "4CA2D1")]
    pub mode_s_address: Option<String>,
    /// Aircraft identification: 1 to 8 of A–Z, 0–9, space.
    #[schema(example = "EZY12AB")]
    pub callsign: Option<String>,
    /// `primary`, `secondary` or `combined` (I048/020 TYP).
    pub detection: Option<String>,
    /// Special position identification (I048/020 SPI).
    pub spi: Option<bool>,
}

/// Logic-based track initiation (seed 001 step 7).
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlotInitiation {
    /// Confirmation M of M-of-N (default 3).
    pub m: Option<u32>,
    /// Confirmation N (default 4).
    pub n: Option<u32>,
    /// Speed band between a root plot and its second plot (default 0–600 m/s).
    pub v_min_mps: Option<f64>,
    pub v_max_mps: Option<f64>,
    /// Per-axis band `[east, north(, up)]` instead of the speed band.
    pub v_min_axis_mps: Option<Vec<f64>>,
    pub v_max_axis_mps: Option<Vec<f64>>,
    /// χ² gate probability of the initiation tests, in (0, 1) (default 0.99).
    #[schema(exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub gate_probability: Option<f64>,
    /// Shortest time from a root to its second plot (default 1 s).
    pub min_dt_s: Option<f64>,
    /// Longest (default twice the longest scan period).
    pub max_dt_s: Option<f64>,
}

/// Track deletion: any rule given deletes (default: 2 × radars (at least 3) consecutive
/// missed frames in serial mode, 3 in parallel mode).
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlotDeletion {
    pub max_consecutive_misses: Option<u32>,
    /// M_d of an M_d-of-N_d miss rule.
    pub m: Option<u32>,
    pub n: Option<u32>,
    /// Delete when √(P_xx + P_yy) exceeds this.
    pub max_position_sigma_m: Option<f64>,
}

/// The tracker's options; every one has a default.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TrackerOptions {
    /// 2 or 3 (default 3 when any radar is 3d, else 2).
    #[schema(minimum = 2, maximum = 3)]
    pub dimensions: Option<u32>,
    /// `auto` (default: serial, with the range rate of Doppler radars), `parallel` (the patent's mode; every radar must give Doppler) or `serial`.
    #[schema(example = "auto")]
    pub mode: Option<String>,
    /// Parallel mode: period of the fusion instants (default the shortest scan period).
    pub fusion_period_s: Option<f64>,
    /// Parallel mode: time of fusion instant 0 (default 0).
    pub fusion_epoch_s: Option<f64>,
    /// Serial mode: plots of one radar within this time are one scan group (default 0).
    pub time_tolerance_s: Option<f64>,
    /// Plot-to-track association: `exact` JPDA (default), `amsjpda`,
    /// `global_nearest_neighbour` or `nearest_neighbour`.
    pub association: Option<String>,
    /// Clusters with more tracks are computed by AMSJPDA (default 12, 1 to 128).
    #[schema(minimum = 1, maximum = 128)]
    pub max_exact_cluster_tracks: Option<u32>,
    /// χ² gate probability of plot-to-plot association, in (0, 1) (default 0.99).
    #[schema(exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub plot_gate_probability: Option<f64>,
    /// Gate probability P_G of plot-to-track association, in (0, 1) (default 0.99).
    #[schema(exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub track_gate_probability: Option<f64>,
    pub initiation: Option<PlotInitiation>,
    pub deletion: Option<PlotDeletion>,
    /// `cwna` (default: continuous white-noise acceleration, q =
    /// sigma_a_mps2² m²/s³, consistent whatever the radars' sampling) or
    /// `dwna` (discrete, σ per prediction interval).
    pub process_noise: Option<String>,
    /// Acceleration noise per horizontal axis (default 3): √q for cwna, σ
    /// (m/s²) for dwna. The noise of tentative tracks, and of confirmed
    /// ones with `motion` `cv`; under the IMM confirmed tracks use
    /// `imm_models`' noise.
    pub sigma_a_mps2: Option<f64>,
    /// Vertical σ (default `sigma_a_mps2`).
    pub sigma_a_vertical_mps2: Option<f64>,
    /// Height (fusion frame) assumed for targets seen by 2D radars: their
    /// slant ranges are made horizontal with it, and 3D tracks started from
    /// 2D plots get it (default 0 m; set it to the traffic's height for
    /// aircraft, or 2D ranges are too long by about Δh²/2ρ).
    pub default_height_m: Option<f64>,
    /// Its σ (default 1000 m).
    pub default_height_sigma_m: Option<f64>,
    /// Parallel mode: σ of the target speed across the line of sight, for
    /// the plots moved to a fusion instant with their angles held (default
    /// 300 m/s; 0 is the patent's covariance).
    pub sigma_tangential_speed_mps: Option<f64>,
    /// Two confirmed tracks updated by the same plot whose states differ by
    /// less than the χ² gate of this probability are one target: the
    /// younger is deleted (counted in `merged`). In [0, 1): default 0.99; 0 disables.
    #[schema(minimum = 0.0, exclusive_maximum = 1.0)]
    pub duplicate_gate_probability: Option<f64>,
    /// The predictor of confirmed tracks: `imm` (default: an interacting
    /// multiple model of `imm_models`) or `cv` (one constant-velocity model
    /// with `sigma_a_mps2`).
    #[schema(example = "imm")]
    pub motion: Option<String>,
    /// The IMM's models (2 to 8). Default, chosen on the seed-001 Monte
    /// Carlo: `cv` √q 0.5 (mean sojourn 60 s, initial probability 0.7),
    /// `ct` +3 °/s and −3 °/s √q 3 (20 s, 0.1 each: standard-rate turns),
    /// `cv` √q 5 (20 s, 0.1: other manoeuvres).
    pub imm_models: Option<Vec<ImmModel>>,
    /// Sessions: plots are taken in any order within this lag (s) of the
    /// newest plot received, and the tracks always equal the batch call's
    /// over every plot received, sorted by time; older plots are late
    /// (dropped, counted, warned). Default 15 s (link and processing
    /// delays of a few seconds plus a hiccup of about two scans), at most
    /// 120. The batch call sorts its plots and only checks the value.
    #[schema(minimum = 0.0, maximum = 120.0, example = 15.0)]
    pub max_lag_s: Option<f64>,
    /// Sessions: how a plot older than the newest received (within the
    /// lag) is taken. `reprocess`: every plot after it is processed again,
    /// so the tracks equal the batch call's bit for bit. `retrodict`: it
    /// updates the tracks it gates with where they stand (Bar-Shalom's
    /// out-of-sequence update, per IMM model), nothing is replayed: about
    /// a sixth of the compute, but approximate (docs/RESULTS.md). `auto`
    /// (default): `reprocess` while the lag window holds at most
    /// `max_replay_plots` plots, `retrodict` from the first late plot
    /// beyond it on (the update's `warnings` say so, the session's
    /// `approximate_from` since when its tracks are approximate). Serial
    /// mode only (parallel mode reprocesses).
    #[schema(example = "auto")]
    pub late_plots: Option<String>,
    /// `late_plots: "auto"`: most plots the lag window may hold for late
    /// plots to be replayed; default 5,000 (a replay of about 35 ms).
    #[schema(example = 5000)]
    pub max_replay_plots: Option<u32>,
    /// Radar registration: on by default with two radars or more.
    pub registration: Option<RegistrationOptions>,
    /// Mode C as geometric height: on by default in 3D.
    pub mode_c_height: Option<ModeCHeightOptions>,
    /// Each radar's σ learnt online: on by default.
    pub accuracy: Option<AccuracyOptions>,
}

/// One model of the IMM.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ImmModel {
    /// `cv` (constant velocity) or `ct` (coordinated turn at a known rate
    /// in the horizontal plane, constant velocity vertically).
    #[schema(example = "ct")]
    pub model: String,
    /// Noise per horizontal axis, as `sigma_a_mps2` (default 0.5 for cv,
    /// 3 for ct).
    pub sigma_a_mps2: Option<f64>,
    /// Vertical noise (default the horizontal one).
    pub sigma_a_vertical_mps2: Option<f64>,
    /// `ct` only, required: turn rate (°/s, positive to the left), non-zero, |ω| ≤ 28.
    pub turn_rate_dps: Option<f64>,
    /// Mean time the target stays in this model (s, > 0; default 60 for
    /// cv, 20 for ct). Switching between models follows the
    /// continuous-time Markov chain of these times.
    pub mean_sojourn_s: Option<f64>,
    /// Mode probability of a newly confirmed track, in (0, 1]; give it for
    /// every model (summing to 1) or for none (equal shares).
    pub initial_probability: Option<f64>,
}

/// Raw ASTERIX (CAT048 target reports, CAT034 north markers and sector
/// crossings), as a radar sends it. Each radar's records are those of its
/// `sac`/`sic`. Times of day are seconds since midnight UTC: the first
/// record is on `date` (or the day starting at `day_start_t`), every later
/// one at the instant nearest the record before it (so 23:59:59 then
/// 00:00:01 rolls to the next day).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AsterixIn {
    /// The data blocks, base64 (RFC 4648, with or without padding).
    #[schema(example = "IgAU6BkBAQAAAAUA8BkBAgACgIA=")]
    pub data: String,
    /// UTC date of the first record, `YYYY-MM-DD` (times are then Unix seconds).
    #[schema(example = "2026-12-02")]
    pub date: Option<String>,
    /// Instead of `date`: the start of the first record's day in the
    /// request's own time scale (s).
    pub day_start_t: Option<f64>,
}

/// AIS over NMEA 0183: `!AIVDM` lines (any talker), each with its tag
/// block's receive time `\c:<Unix s>*hh\`. Each position report (types
/// 1–3, 18, 19, 27) becomes an AIS report (`source` `ais`, its MMSI, SOG/COG
/// and position-accuracy flag) at its fix time: the receive time taken
/// back to the report's UTC second. Lines that cannot be used are counted
/// in `warnings` with the first one's index and reason.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NmeaIn {
    #[schema(example = json!(["\\c:1700000003*5C\\!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C"]))]
    pub lines: Vec<String>,
    /// Subtracted from the tag blocks' Unix times, so that the reports
    /// join the plots' time scale (s; default 0: plots in Unix seconds).
    pub time_offset_s: Option<f64>,
}

pub(crate) fn nmea_in(n: Option<NmeaIn>) -> Option<svc::nmea::NmeaInput> {
    n.map(|n| svc::nmea::NmeaInput {
        lines: n.lines,
        time_offset_s: n.time_offset_s,
    })
}

/// An ASTERIX record that could not be decoded or used.
#[derive(Debug, Serialize, ToSchema)]
pub struct AsterixError {
    /// Byte offset in the data.
    pub offset: usize,
    pub reason: String,
}

/// What the ASTERIX input gave.
#[derive(Debug, Serialize, ToSchema)]
pub struct AsterixSummary {
    pub bytes: usize,
    /// Data blocks read (of any category).
    pub blocks: usize,
    /// CAT048 and CAT034 records decoded.
    pub records: usize,
    pub target_reports: usize,
    /// Target reports used as plots.
    pub plots: usize,
    pub north_markers: usize,
    pub sector_crossings: usize,
    pub other_service_messages: usize,
    /// Target reports of a SAC/SIC no radar declares (skipped).
    pub unmapped: usize,
    /// Test targets (I048/020 TST), skipped.
    pub test_targets: usize,
    /// Without I048/010, /140 or /040, or from a 3D radar without /110 (skipped).
    pub incomplete: usize,
    /// Refused by the plot checks (listed in `errors`).
    pub rejected: usize,
    /// Sessions: plots older than the last processed frame, dropped.
    pub late: usize,
    /// Their records' offsets.
    pub late_offsets: Vec<usize>,
    /// Time of the first and last plot (after the date and roll-over).
    pub first_t: Option<f64>,
    pub last_t: Option<f64>,
    /// Decoding errors and refused records, by offset (at most 100; a bad
    /// record loses the rest of its data block; decoding goes on at the next).
    pub errors: Vec<AsterixError>,
    /// Errors beyond the 100 listed.
    pub errors_not_listed: usize,
}

pub(crate) fn asterix_in(
    a: Option<AsterixIn>,
) -> Result<Option<svc::asterix::AsterixInput>, Problem> {
    use base64::Engine as _;
    let Some(a) = a else { return Ok(None) };
    let engine = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new()
            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
    );
    let data = engine.decode(a.data.trim()).map_err(|e| {
        Problem::from(service::Violations::single(
            "asterix.data",
            format!("is not base64: {e}"),
        ))
    })?;
    Ok(Some(svc::asterix::AsterixInput {
        data,
        date: a.date,
        day_start_t: a.day_start_t,
        reference_t: None,
        reception: None,
    }))
}

pub(crate) fn asterix_out(s: svc::asterix::AsterixSummary) -> AsterixSummary {
    AsterixSummary {
        bytes: s.bytes,
        blocks: s.blocks,
        records: s.records,
        target_reports: s.target_reports,
        plots: s.plots,
        north_markers: s.north_markers,
        sector_crossings: s.sector_crossings,
        other_service_messages: s.other_service_messages,
        unmapped: s.unmapped,
        test_targets: s.test_targets,
        incomplete: s.incomplete,
        rejected: s.rejected,
        late: s.late,
        late_offsets: s.late_offsets,
        first_t: s.first_t,
        last_t: s.last_t,
        errors: s
            .errors
            .into_iter()
            .map(|e| AsterixError {
                offset: e.offset,
                reason: e.reason,
            })
            .collect(),
        errors_not_listed: s.errors_not_listed,
    }
}

/// A cooperative report: an aircraft's ADS-B position (ASTERIX CAT021's
/// content), a multilateration position (CAT020's), or a ship's AIS
/// position report. Its σ comes from its own quality fields: `nacp` (ADS-B:
/// σ = EPU / 2.448), `sigma_m` (multilateration's stated accuracy; any
/// report's, over its quality fields), `position_accurate` (AIS).
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ReportIn {
    /// `adsb`, `mlat` or `ais`.
    #[schema(example = "adsb")]
    pub source: String,
    /// Time of applicability of the position (s, the plots' time scale).
    #[schema(example = 12.5)]
    pub t: f64,
    #[schema(example = 48.71)]
    pub lat_deg: f64,
    #[schema(example = 2.37)]
    pub lon_deg: f64,
    /// Geometric (GNSS) height above the WGS84 ellipsoid (m).
    pub geometric_height_m: Option<f64>,
    /// Velocity east and north (m/s), both or neither (ADS-B's ground
    /// vector).
    pub velocity_east_mps: Option<f64>,
    pub velocity_north_mps: Option<f64>,
    /// Geometric vertical rate (m/s).
    pub vertical_rate_mps: Option<f64>,
    /// AIS: speed over ground (kn) and course over ground (° from north),
    /// instead of the velocity's components.
    pub sog_kn: Option<f64>,
    pub cog_deg: Option<f64>,
    /// ADS-B navigation accuracy category for position, 1 to 11 (required
    /// from ADS-B unless `sigma_m` is given).
    #[schema(example = 9, maximum = 11)]
    pub nacp: Option<u8>,
    /// ADS-B navigation accuracy category for velocity, 1 to 4 (required
    /// with an ADS-B velocity unless `sigma_velocity_mps` is given).
    #[schema(maximum = 4)]
    pub nacv: Option<u8>,
    /// AIS position-accuracy flag: true better than 10 m (default false).
    pub position_accurate: Option<bool>,
    /// σ per horizontal axis (m): required from multilateration.
    pub sigma_m: Option<f64>,
    /// σ of the geometric height (m); absent: from NACp 9–11, else the
    /// height is not used.
    pub sigma_height_m: Option<f64>,
    /// σ per axis of the velocity (m/s).
    pub sigma_velocity_mps: Option<f64>,
    /// Mode S (ICAO 24-bit) address, six hexadecimal digits.
    #[schema(example = "4CA2D1")]
    pub mode_s_address: Option<String>,
    /// Aircraft identification (callsign).
    pub callsign: Option<String>,
    /// Mode 3/A code, four octal digits.
    pub mode_3a: Option<String>,
    /// Barometric flight level (hundreds of feet).
    pub flight_level: Option<f64>,
    /// AIS: the ship's MMSI (1 to 999999999).
    #[schema(example = 227006760)]
    pub mmsi: Option<u64>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlotFusionRequest {
    /// The fusion centre: the ENU frame of the tracks; absent: the first
    /// radar site given in WGS84 (none: tracks carry no lat/lon).
    pub origin: Option<GeoPoint>,
    pub radars: Vec<PlotRadar>,
    /// In any order; the service sorts them by time.
    #[serde(default)]
    pub plots: Vec<PlotIn>,
    /// Cooperative reports (ADS-B, multilateration, AIS) beside the plots,
    /// in any order.
    #[serde(default)]
    pub cooperative: Vec<ReportIn>,
    /// Raw ASTERIX beside (or instead of) `plots`.
    pub asterix: Option<AsterixIn>,
    /// AIS over NMEA 0183 beside `plots`.
    pub nmea: Option<NmeaIn>,
    pub tracker: Option<TrackerOptions>,
    /// Also answer `tracks` as ASTERIX CAT062 records (`cat062`).
    pub cat062: Option<Cat062Options>,
    /// Also return the confirmed tracks after every processing instant.
    #[serde(default)]
    pub history: bool,
}

/// ASTERIX CAT062 (edition 1.20) out: the tracks as system track messages
/// of this fusion centre. Needs WGS-84 positions (`origin`, or a radar in
/// `geodetic`).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Cat062Options {
    /// I062/010 System Area Code of the fusion centre, 0 to 255.
    #[schema(example = 25, maximum = 255)]
    pub sac: u32,
    /// I062/010 System Identification Code, 0 to 255.
    #[schema(example = 100, maximum = 255)]
    pub sic: u32,
    /// I062/015 Service Identification, 0 to 255; absent: not sent.
    #[schema(maximum = 255)]
    pub service_id: Option<u32>,
    /// Midnight UTC in the plots' time scale (s), for I062/070's time of
    /// day; default 0: plot times are Unix seconds.
    pub day_start_t: Option<f64>,
    /// Largest data block (bytes, 64 to 65,535; default 1,024): blocks
    /// split at record boundaries.
    #[schema(minimum = 64, maximum = 65535)]
    pub max_block_bytes: Option<u32>,
}

pub(crate) fn cat062_in(c: Option<Cat062Options>) -> Option<svc::cat062::Cat062Input> {
    c.map(|c| svc::cat062::Cat062Input {
        sac: Some(c.sac),
        sic: Some(c.sic),
        service_id: c.service_id,
        day_start_t: c.day_start_t,
        max_block_bytes: c.max_block_bytes,
    })
}

/// CAT062 data blocks as base64, or absent.
pub(crate) fn cat062_out(c: Option<svc::cat062::Cat062Data>) -> Option<String> {
    use base64::Engine as _;
    c.map(|c| base64::engine::general_purpose::STANDARD.encode(c.data))
}

/// The radar plot of a track's last update.
#[derive(Debug, Serialize, ToSchema)]
pub struct LastPlot {
    pub radar: String,
    pub t: f64,
    pub range_m: f64,
    /// Clockwise from north, [0, 360).
    pub azimuth_deg: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub elevation_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radial_velocity_mps: Option<f64>,
}

/// A track at the end of the data (or when deleted).
#[derive(Debug, Serialize, ToSchema)]
pub struct FusedTrack {
    pub id: u64,
    /// `tentative`, `confirmed` or `deleted`.
    pub status: &'static str,
    pub t: f64,
    /// In the fusion ENU frame, layout `state_layout`.
    pub state: Vec<f64>,
    pub covariance: Vec<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lat_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lon_deg: Option<f64>,
    /// 3D trackers only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f64>,
    /// Radars whose plots updated the track at its last update.
    pub radars: Vec<String>,
    pub hits: u32,
    pub misses: u32,
    pub consecutive_misses: u32,
    /// Frames since the track started.
    pub age: u32,
    pub last_update_t: f64,
    /// A confirmed IMM track's mode probabilities, one per model of
    /// `tracker.imm_models` in order (models named `cv`, `ct_left`,
    /// `ct_right`, with `_2`, … for repeats); absent for tentative tracks
    /// and with `motion` `cv`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub modes: Vec<TrackMode>,
    /// A confirmed IMM track's turn rate Σ μ_j ω_j (°/s, positive to the
    /// left), when the models include a turn.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub turn_rate_dps: Option<f64>,
    /// Time of the track's first plot.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub start_t: Option<f64>,
    /// The plot of the track's last update, when it was one radar's plot
    /// (serial mode; absent after a fused plot of parallel mode).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_plot: Option<LastPlot>,
    /// What the track knows of its aircraft from SSR and Mode S plots
    /// (absent when none updated it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub identity: Option<super::identity::TrackIdentity>,
    /// Per sensor that has updated the track (radar ids, then `adsb`,
    /// `mlat`, `ais`): the time of its last update.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sources: Vec<TrackSource>,
    /// The check of its self-reported positions (ADS-B, AIS) against
    /// radar and multilateration (absent when none updated it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub self_reported: Option<SelfReported>,
    /// A ship's AIS MMSI, from its reports.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mmsi: Option<u32>,
}

/// One sensor's last update of a track.
#[derive(Debug, Serialize, ToSchema)]
pub struct TrackSource {
    #[schema(example = "adsb")]
    pub sensor: String,
    pub last_t: f64,
}

/// A track's self-reported positions against independent evidence.
#[derive(Debug, Serialize, ToSchema)]
pub struct SelfReported {
    /// Its self-reported positions are used (false: they disagreed with
    /// radar or multilateration beyond their stated quality, and are not
    /// used until 5 in a row agree).
    pub trusted: bool,
    /// Radar or multilateration updated it within the last 30 s (false:
    /// an ADS-B-only stretch, unvalidated).
    pub validated: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distrusted_since_t: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_self_reported_t: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_independent_t: Option<f64>,
    /// The last disagreement.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub disagreement: Option<Disagreement>,
}

/// A self-reported position against independent evidence.
#[derive(Debug, Serialize, ToSchema)]
pub struct Disagreement {
    pub t: f64,
    /// Horizontal distance between the two (m).
    pub distance_m: f64,
    /// The self-reported position's stated σ per axis (m).
    pub stated_sigma_m: f64,
}

/// One model's probability in an IMM track.
#[derive(Debug, Serialize, ToSchema)]
pub struct TrackMode {
    #[schema(example = "ct_left")]
    pub model: String,
    pub probability: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct TrackHistoryEntry {
    pub t: f64,
    /// The confirmed tracks after this processing instant.
    pub tracks: Vec<FusedTrack>,
}

/// Running totals.
#[derive(Debug, Serialize, ToSchema)]
pub struct TrackerCounters {
    /// Plots accepted.
    pub plots: u64,
    /// Late plots dropped.
    pub late: u64,
    /// Processing instants (scan groups or fusion instants).
    pub frames: u64,
    /// Fused plots made by parallel mode.
    pub fused_plots: u64,
    /// Tentative tracks started, confirmed and dropped; confirmed tracks deleted.
    pub started: u64,
    pub confirmed: u64,
    pub dropped: u64,
    pub deleted: u64,
    /// Confirmed tracks deleted as duplicates of an older track.
    pub merged: u64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct PlotFusionResponse {
    /// The mode used: `parallel` or `serial`.
    pub mode: &'static str,
    pub state_layout: Vec<&'static str>,
    /// Confirmed then tentative tracks at the end of the data.
    pub tracks: Vec<FusedTrack>,
    /// Confirmed tracks deleted during the data, as they were when deleted.
    pub deleted: Vec<FusedTrack>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub history: Option<Vec<TrackHistoryEntry>>,
    pub counters: TrackerCounters,
    /// Present when the request had `asterix`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub asterix: Option<AsterixSummary>,
    /// With the `cat062` option: base64 of CAT062 data blocks, one record
    /// per entry of `tracks` in the same order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cat062: Option<String>,
    /// Each radar's bias as applied at the end of the data (estimated by
    /// registration, or the radar's known bias).
    pub registration: Vec<RadarBiasOut>,
    /// Each radar's σ at the end of the data: declared, learnt, applied.
    pub accuracy: Vec<RadarAccuracyOut>,
    /// The pressure offset a 3D tracker applies to Mode C (absent: Mode C
    /// heights off, or a 2D tracker).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pressure_offset: Option<PressureOffsetOut>,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

pub(crate) fn spec_in(
    origin: Option<GeoPoint>,
    radars: Vec<PlotRadar>,
    tracker: Option<TrackerOptions>,
    cat062: Option<Cat062Options>,
) -> svc::SpecInput {
    let t = tracker.unwrap_or_default();
    svc::SpecInput {
        cat062: cat062_in(cat062),
        origin: origin.map(geo_in),
        radars: radars
            .into_iter()
            .map(|r| svc::RadarInput {
                id: Some(r.id),
                kind: Some(r.kind),
                site: Some(svc::SiteInput {
                    geodetic: (r.site.lat_deg.is_some() || r.site.lon_deg.is_some()).then_some(
                        svc::GeoInput {
                            lat_deg: r.site.lat_deg,
                            lon_deg: r.site.lon_deg,
                            height_m: r.site.height_m,
                        },
                    ),
                    position_m: r.site.position_m,
                }),
                sigma_range_m: r.sigma_range_m,
                sigma_azimuth_deg: r.sigma_azimuth_deg,
                sigma_elevation_deg: r.sigma_elevation_deg,
                sigma_radial_velocity_mps: r.sigma_radial_velocity_mps,
                scan_period_s: r.scan_period_s,
                p_detection: r.p_detection,
                clutter_density: r.clutter_density,
                sac: r.sac,
                sic: r.sic,
                bias: r.bias.map(|b| svc::BiasInput {
                    range_m: b.range_m,
                    azimuth_deg: b.azimuth_deg,
                    elevation_deg: b.elevation_deg,
                    sigma_range_m: b.sigma_range_m,
                    sigma_azimuth_deg: b.sigma_azimuth_deg,
                    sigma_elevation_deg: b.sigma_elevation_deg,
                }),
            })
            .collect(),
        tracker: svc::TrackerInput {
            dimensions: t.dimensions,
            mode: t.mode,
            fusion_period_s: t.fusion_period_s,
            fusion_epoch_s: t.fusion_epoch_s,
            time_tolerance_s: t.time_tolerance_s,
            association: t.association,
            max_exact_cluster_tracks: t.max_exact_cluster_tracks,
            plot_gate_probability: t.plot_gate_probability,
            track_gate_probability: t.track_gate_probability,
            initiation: t.initiation.map(|i| svc::InitiationInput {
                m: i.m,
                n: i.n,
                v_min_mps: i.v_min_mps,
                v_max_mps: i.v_max_mps,
                v_min_axis_mps: i.v_min_axis_mps,
                v_max_axis_mps: i.v_max_axis_mps,
                gate_probability: i.gate_probability,
                min_dt_s: i.min_dt_s,
                max_dt_s: i.max_dt_s,
            }),
            deletion: t.deletion.map(|d| svc::DeletionInput {
                max_consecutive_misses: d.max_consecutive_misses,
                m: d.m,
                n: d.n,
                max_position_sigma_m: d.max_position_sigma_m,
            }),
            process_noise: t.process_noise,
            sigma_a_mps2: t.sigma_a_mps2,
            sigma_a_vertical_mps2: t.sigma_a_vertical_mps2,
            default_height_m: t.default_height_m,
            default_height_sigma_m: t.default_height_sigma_m,
            sigma_tangential_speed_mps: t.sigma_tangential_speed_mps,
            duplicate_gate_probability: t.duplicate_gate_probability,
            motion: t.motion,
            late_plots: t.late_plots,
            max_replay_plots: t.max_replay_plots,
            imm_models: t.imm_models.map(|models| {
                models
                    .into_iter()
                    .map(|m| svc::ImmModelInput {
                        model: Some(m.model),
                        sigma_a_mps2: m.sigma_a_mps2,
                        sigma_a_vertical_mps2: m.sigma_a_vertical_mps2,
                        turn_rate_dps: m.turn_rate_dps,
                        mean_sojourn_s: m.mean_sojourn_s,
                        initial_probability: m.initial_probability,
                    })
                    .collect()
            }),
            max_lag_s: t.max_lag_s,
            registration: t.registration.map(|r| {
                Box::new(svc::RegistrationInput {
                    enabled: r.enabled,
                    reference: r.reference,
                    min_pairs: r.min_pairs,
                    max_pair_dt_s: r.max_pair_dt_s,
                    time_constant_s: r.time_constant_s,
                })
            }),
            mode_c_height: t.mode_c_height.map(|m| svc::ModeCHeightInput {
                enabled: m.enabled,
                learn: m.learn,
                offset_m: m.offset_m,
                sigma_offset_m: m.sigma_offset_m,
                slope: m.slope,
                sigma_slope: m.sigma_slope,
            }),
            accuracy: t.accuracy.map(|a| svc::AccuracyInput {
                enabled: a.enabled,
                time_constant_s: a.time_constant_s,
                pinned: a.pinned,
            }),
        },
    }
}

fn geo_in(g: GeoPoint) -> svc::GeoInput {
    svc::GeoInput {
        lat_deg: Some(g.lat_deg),
        lon_deg: Some(g.lon_deg),
        height_m: g.height_m,
    }
}

/// A request's plots, then its cooperative reports (the service names
/// them `cooperative[i]` in its errors).
pub(crate) fn plots_in(plots: Vec<PlotIn>, cooperative: Vec<ReportIn>) -> Vec<svc::PlotInput> {
    let mut out = radar_plots_in(plots);
    out.extend(cooperative.into_iter().map(report_in));
    out
}

fn report_in(r: ReportIn) -> svc::PlotInput {
    svc::PlotInput {
        t: Some(r.t),
        ssr: svc::SsrInput {
            mode_3a: r.mode_3a,
            flight_level: r.flight_level,
            mode_s_address: r.mode_s_address,
            callsign: r.callsign,
            ..Default::default()
        },
        report: Some(svc::ReportInput {
            source: Some(r.source),
            lat_deg: Some(r.lat_deg),
            lon_deg: Some(r.lon_deg),
            geometric_height_m: r.geometric_height_m,
            velocity_east_mps: r.velocity_east_mps,
            velocity_north_mps: r.velocity_north_mps,
            vertical_rate_mps: r.vertical_rate_mps,
            sog_kn: r.sog_kn,
            cog_deg: r.cog_deg,
            nacp: r.nacp,
            nacv: r.nacv,
            position_accurate: r.position_accurate,
            sigma_m: r.sigma_m,
            sigma_height_m: r.sigma_height_m,
            sigma_velocity_mps: r.sigma_velocity_mps,
            mmsi: r.mmsi,
        }),
        ..Default::default()
    }
}

fn radar_plots_in(plots: Vec<PlotIn>) -> Vec<svc::PlotInput> {
    plots
        .into_iter()
        .map(|p| svc::PlotInput {
            radar_id: Some(p.radar_id),
            t: Some(p.t),
            range_m: Some(p.range_m),
            azimuth_deg: Some(p.azimuth_deg),
            elevation_deg: p.elevation_deg,
            radial_velocity_mps: p.radial_velocity_mps,
            ssr: svc::SsrInput {
                mode_3a: p.mode_3a,
                mode_3a_validated: p.mode_3a_validated,
                mode_3a_garbled: p.mode_3a_garbled,
                flight_level: p.flight_level,
                flight_level_validated: p.flight_level_validated,
                flight_level_garbled: p.flight_level_garbled,
                mode_s_address: p.mode_s_address,
                callsign: p.callsign,
                detection: p.detection,
                spi: p.spi,
            },
            report: None,
        })
        .collect()
}

pub(crate) fn track_out(t: svc::TrackView) -> FusedTrack {
    FusedTrack {
        id: t.id,
        status: t.status,
        t: t.t,
        state: t.state,
        covariance: t.covariance,
        lat_deg: t.lat_deg,
        lon_deg: t.lon_deg,
        height_m: t.height_m,
        radars: t.radars,
        hits: t.hits,
        misses: t.misses,
        consecutive_misses: t.consecutive_misses,
        age: t.age,
        last_update_t: t.last_update_t,
        modes: t
            .modes
            .into_iter()
            .map(|m| TrackMode {
                model: m.model,
                probability: m.probability,
            })
            .collect(),
        turn_rate_dps: t.turn_rate_dps,
        start_t: t.start_t,
        last_plot: t.last_plot.map(|p| LastPlot {
            radar: p.radar,
            t: p.t,
            range_m: p.range_m,
            azimuth_deg: p.azimuth_deg,
            elevation_deg: p.elevation_deg,
            radial_velocity_mps: p.radial_velocity_mps,
        }),
        identity: t.identity.map(super::identity::identity_out),
        sources: t
            .sources
            .into_iter()
            .map(|s| TrackSource {
                sensor: s.sensor,
                last_t: s.last_t,
            })
            .collect(),
        self_reported: t.self_reported.map(|v| SelfReported {
            trusted: v.trusted,
            validated: v.validated,
            distrusted_since_t: v.distrusted_since_t,
            last_self_reported_t: v.last_self_reported_t,
            last_independent_t: v.last_independent_t,
            disagreement: v.disagreement.map(|d| Disagreement {
                t: d.t,
                distance_m: d.distance_m,
                stated_sigma_m: d.stated_sigma_m,
            }),
        }),
        mmsi: t.mmsi,
    }
}

pub(crate) fn counters_out(c: Counters) -> TrackerCounters {
    TrackerCounters {
        plots: c.plots,
        late: c.late,
        frames: c.frames,
        fused_plots: c.fused_plots,
        started: c.started,
        confirmed: c.confirmed,
        dropped: c.dropped,
        deleted: c.deleted,
        merged: c.merged,
    }
}

/// Tracks targets from the plots of several radars (seed 001): spatial
/// registration, parallel (Doppler) or serial fusion, JPDA/EKF, logic
/// initiation and deletion.
#[utoipa::path(
    post,
    path = "/v1/plot-fusion/track",
    tag = "plot-fusion",
    request_body = PlotFusionRequest,
    responses(
        (status = 200, description = "Tracks at the end of the data", body = PlotFusionResponse),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Too many plots", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn track(
    State(_state): State<AppState>,
    body: JsonBody<PlotFusionRequest>,
) -> Result<Response, Problem> {
    body.compute(track_on_lane).await
}

fn track_on_lane(req: PlotFusionRequest) -> Result<PlotFusionResponse, Problem> {
    let input = svc::TrackInput {
        spec: spec_in(req.origin, req.radars, req.tracker, req.cat062),
        plots: plots_in(req.plots, req.cooperative),
        asterix: asterix_in(req.asterix)?,
        nmea: nmea_in(req.nmea),
        history: req.history,
    };
    let out = svc::track(input)?;
    Ok(PlotFusionResponse {
        mode: out.mode,
        state_layout: out.state_layout.to_vec(),
        tracks: out.tracks.into_iter().map(track_out).collect(),
        deleted: out.deleted.into_iter().map(track_out).collect(),
        history: out.history.map(|h| {
            h.into_iter()
                .map(|e| TrackHistoryEntry {
                    t: e.t,
                    tracks: e.tracks.into_iter().map(track_out).collect(),
                })
                .collect()
        }),
        counters: counters_out(out.counters),
        asterix: out.asterix.map(asterix_out),
        cat062: cat062_out(out.cat062),
        registration: out.registration.into_iter().map(bias_out).collect(),
        accuracy: out.accuracy.into_iter().map(accuracy_out).collect(),
        pressure_offset: out.pressure_offset.map(pressure_offset_out),
        timing: Timing {
            compute_us: out.compute_us,
        },
        warnings: out.warnings,
    })
}
