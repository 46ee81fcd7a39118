//! REST route for AIS–radar association and radar bias estimation (seed 004).

use axum::{extract::State, response::Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{
    Timing,
    problem::{JsonBody, Problem},
};
use crate::state::AppState;
use service::ais_radar as svc;

/// The radar site (WGS84).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RadarSite {
    #[schema(example = 37.5)]
    pub lat_deg: Option<f64>,
    #[schema(example = 121.4)]
    pub lon_deg: Option<f64>,
}

/// A radar sample: `range_m` and `azimuth_deg` (clockwise from north), or
/// `east_m` and `north_m` in the radar's local plane.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RadarSample {
    pub t: Option<f64>,
    pub range_m: Option<f64>,
    pub azimuth_deg: Option<f64>,
    pub east_m: Option<f64>,
    pub north_m: Option<f64>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RadarTrack {
    pub id: Option<String>,
    /// At least 2 samples, times strictly increasing.
    pub samples: Vec<RadarSample>,
}

/// A decoded AIS position report.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AisReport {
    pub mmsi: Option<u32>,
    pub t: Option<f64>,
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    /// Accepted for completeness; the association uses positions only.
    pub sog_mps: Option<f64>,
    /// Accepted for completeness; the association uses positions only.
    pub cog_deg: Option<f64>,
}

#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AssociateOptions {
    /// Longest radar gap interpolated across (default 30 s); never extrapolated.
    pub max_gap_s: Option<f64>,
    /// Gate on a pair's mean distance after compensation (default 500 m).
    pub gate_m: Option<f64>,
    /// `auto` (default: CA-CFAR and the bias search, the better wins), `cfar` (the paper) or `search`.
    pub seeding: Option<String>,
    /// Refinement iterations at most (default 20).
    pub max_iterations: Option<u32>,
    /// Bounds of the bias search (defaults 5000 m and 5°).
    pub max_range_bias_m: Option<f64>,
    pub max_azimuth_bias_deg: Option<f64>,
    /// CA-CFAR reference window N (default 5), guard cells (1), weighting K (5), ratio h (3).
    pub cfar_window: Option<u32>,
    pub cfar_guard: Option<u32>,
    pub cfar_k: Option<f64>,
    pub cfar_h: Option<f64>,
    /// Let the bias search look up to 4 times past the bounds when a bias there gates more pairs (default true); `quality.search_widened` says when it did.
    pub widen_search: Option<bool>,
    /// The radar's stated range error σ (default 50 m): with the azimuth and AIS errors, the yardstick of `quality.residual_ratio`.
    pub radar_sigma_range_m: Option<f64>,
    /// The radar's stated azimuth error σ (default 0.2°).
    pub radar_sigma_azimuth_deg: Option<f64>,
    /// AIS position error σ per axis (default 10 m).
    pub ais_sigma_m: Option<f64>,
    /// Time uncertainty σ of the decoded `ais_reports` (default 0 s). NMEA tag-block times of whole seconds are taken at the middle of their second with σ = 1/√12 s on their own.
    pub ais_time_sigma_s: Option<f64>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AssociateRequest {
    pub site: Option<RadarSite>,
    /// `wgs84` (default), `grs80` or `krasovsky_1940`.
    pub ellipsoid: Option<String>,
    #[serde(default)]
    pub radar_tracks: Vec<RadarTrack>,
    #[serde(default)]
    pub ais_reports: Vec<AisReport>,
    /// Raw `!AIVDM`/`!AIVDO` lines, with NMEA 4.0 tag blocks (`\c:<unix time>*hh\`) for the time.
    #[serde(default)]
    pub nmea: Vec<String>,
    pub options: Option<AssociateOptions>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct TrackPair {
    pub radar_track_id: String,
    pub mmsi: u32,
    pub distance_m: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct BiasEstimate {
    /// Δρ: measured range minus true range.
    pub range_m: f64,
    /// Δθ: measured azimuth minus true azimuth.
    pub azimuth_deg: f64,
    /// Covariance of (range_m, azimuth_deg), row-major: [[m², m·deg], [m·deg, deg²]].
    pub covariance: Vec<Vec<f64>>,
    pub pairs_used: usize,
    pub samples_used: usize,
    /// (Σ n_k)² / Σ n_k² over the pairs' sample counts n_k: the pairs' weight in the covariance's small-sample scaling.
    pub effective_pairs: f64,
}

/// A distinct bias that associates as many pairs nearly as well (within 1.5 times the mean distance).
#[derive(Debug, Serialize, ToSchema)]
pub struct AlternativeBias {
    pub range_m: f64,
    pub azimuth_deg: f64,
    pub pairs: usize,
    pub mean_distance_m: f64,
}

/// What a client tests before trusting the result; every raised flag also has a warning.
#[derive(Debug, Serialize, ToSchema)]
pub struct AssociationQuality {
    /// A bias from at least 3 pairs, converged, and none of the flags below.
    pub reliable: bool,
    /// The bias lies on or beyond `max_range_bias_m` or `max_azimuth_bias_deg`.
    pub at_bound: bool,
    /// The search went past the bounds, where a bias gates more pairs.
    pub search_widened: bool,
    /// A distinct bias associates as many pairs nearly as well (`alternative`).
    pub ambiguous: bool,
    /// The residuals after compensation exceed 3 times the stated errors.
    pub inconsistent: bool,
    /// RMS of the residuals after compensation in units of the stated errors (≈ 1 when they hold).
    pub residual_ratio: Option<f64>,
    pub alternative: Option<AlternativeBias>,
    /// Pair-implied biases ranked by the search, and scored by a gated assignment.
    pub hypotheses_ranked: usize,
    pub hypotheses_scored: usize,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct AisAssociation {
    pub radar_track_id: String,
    pub mmsi: u32,
    /// Eq. 6 mean distance before compensation.
    pub distance_before_m: f64,
    /// Eq. 6 mean distance after compensation.
    pub distance_after_m: f64,
    pub common_samples: usize,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct CompensatedSample {
    pub t: f64,
    pub range_m: f64,
    pub azimuth_deg: f64,
    pub east_m: f64,
    pub north_m: f64,
    pub lat_deg: f64,
    pub lon_deg: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct CompensatedTrack {
    pub id: String,
    pub samples: Vec<CompensatedSample>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct SkippedType {
    pub message_type: u8,
    pub count: usize,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct NmeaLineError {
    /// 0-based index into `nmea`.
    pub line: usize,
    pub message: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct NmeaSummary {
    pub lines: usize,
    pub sentences: usize,
    pub messages: usize,
    pub positions: usize,
    pub skipped: Vec<SkippedType>,
    pub errors: Vec<NmeaLineError>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct AssociateResponse {
    /// `cfar` (the paper's credible pairs seeded the estimate), `bias_search` or `none`.
    pub path: String,
    /// Same-source threshold S1 (eq. 9); null when CA-CFAR found none.
    pub s1_m: Option<f64>,
    /// Different-source threshold S2 = h S1 (eq. 10).
    pub s2_m: Option<f64>,
    pub credible_pairs: Vec<TrackPair>,
    pub bias: Option<BiasEstimate>,
    pub iterations: usize,
    pub converged: bool,
    pub associations: Vec<AisAssociation>,
    pub unassociated_radar_tracks: Vec<String>,
    pub unassociated_mmsis: Vec<u32>,
    /// MMSIs sharing fewer than 2 instants with every radar track (a single report, or outside every track's time span): never associable.
    pub unassociable_mmsis: Vec<u32>,
    pub quality: AssociationQuality,
    pub compensated_tracks: Vec<CompensatedTrack>,
    pub mean_error_before_m: Option<f64>,
    pub mean_error_after_m: Option<f64>,
    pub nmea: NmeaSummary,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

/// Associates radar tracks with AIS ships despite a radar bias, estimates the bias (seed 004).
#[utoipa::path(
    post,
    path = "/v1/ais-radar/associate",
    tag = "ais-radar",
    request_body = AssociateRequest,
    responses(
        (status = 200, description = "Association, bias estimate, compensated tracks", body = AssociateResponse),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn associate(
    State(_state): State<AppState>,
    body: JsonBody<AssociateRequest>,
) -> Result<Response, Problem> {
    body.compute(associate_on_lane).await
}

fn associate_on_lane(req: AssociateRequest) -> Result<AssociateResponse, Problem> {
    let o = req.options.unwrap_or_default();
    let input = svc::AssociateInput {
        site: req.site.map(|s| svc::SiteInput {
            lat_deg: s.lat_deg,
            lon_deg: s.lon_deg,
        }),
        ellipsoid: req.ellipsoid,
        radar_tracks: req
            .radar_tracks
            .into_iter()
            .map(|t| svc::TrackInput {
                id: t.id,
                samples: t
                    .samples
                    .into_iter()
                    .map(|s| svc::SampleInput {
                        t: s.t,
                        range_m: s.range_m,
                        azimuth_deg: s.azimuth_deg,
                        east_m: s.east_m,
                        north_m: s.north_m,
                    })
                    .collect(),
            })
            .collect(),
        ais_reports: req
            .ais_reports
            .into_iter()
            .map(|r| svc::AisReportInput {
                mmsi: r.mmsi,
                t: r.t,
                lat_deg: r.lat_deg,
                lon_deg: r.lon_deg,
            })
            .collect(),
        nmea: req.nmea,
        options: Some(svc::OptionsInput {
            max_gap_s: o.max_gap_s,
            gate_m: o.gate_m,
            seeding: o.seeding,
            max_iterations: o.max_iterations,
            max_range_bias_m: o.max_range_bias_m,
            max_azimuth_bias_deg: o.max_azimuth_bias_deg,
            cfar_window: o.cfar_window,
            cfar_guard: o.cfar_guard,
            cfar_k: o.cfar_k,
            cfar_h: o.cfar_h,
            widen_search: o.widen_search,
            radar_sigma_range_m: o.radar_sigma_range_m,
            radar_sigma_azimuth_deg: o.radar_sigma_azimuth_deg,
            ais_sigma_m: o.ais_sigma_m,
            ais_time_sigma_s: o.ais_time_sigma_s,
        }),
    };
    let out = svc::associate(input)?;
    Ok(AssociateResponse {
        path: out.path.to_string(),
        s1_m: out.s1_m,
        s2_m: out.s2_m,
        credible_pairs: out
            .credible_pairs
            .into_iter()
            .map(|p| TrackPair {
                radar_track_id: p.radar_track_id,
                mmsi: p.mmsi,
                distance_m: p.distance_m,
            })
            .collect(),
        bias: out.bias.map(|b| BiasEstimate {
            range_m: b.range_m,
            azimuth_deg: b.azimuth_deg,
            covariance: b.covariance.iter().map(|r| r.to_vec()).collect(),
            pairs_used: b.pairs_used,
            samples_used: b.samples_used,
            effective_pairs: b.effective_pairs,
        }),
        iterations: out.iterations,
        converged: out.converged,
        associations: out
            .associations
            .into_iter()
            .map(|a| AisAssociation {
                radar_track_id: a.radar_track_id,
                mmsi: a.mmsi,
                distance_before_m: a.distance_before_m,
                distance_after_m: a.distance_after_m,
                common_samples: a.common_samples,
            })
            .collect(),
        unassociated_radar_tracks: out.unassociated_radar_tracks,
        unassociated_mmsis: out.unassociated_mmsis,
        unassociable_mmsis: out.unassociable_mmsis,
        quality: AssociationQuality {
            reliable: out.quality.reliable,
            at_bound: out.quality.at_bound,
            search_widened: out.quality.search_widened,
            ambiguous: out.quality.ambiguous,
            inconsistent: out.quality.inconsistent,
            residual_ratio: out.quality.residual_ratio,
            alternative: out.quality.alternative.map(|a| AlternativeBias {
                range_m: a.range_m,
                azimuth_deg: a.azimuth_deg,
                pairs: a.pairs,
                mean_distance_m: a.mean_distance_m,
            }),
            hypotheses_ranked: out.quality.hypotheses_ranked,
            hypotheses_scored: out.quality.hypotheses_scored,
        },
        compensated_tracks: out
            .compensated_tracks
            .into_iter()
            .map(|t| CompensatedTrack {
                id: t.id,
                samples: t
                    .samples
                    .into_iter()
                    .map(|s| CompensatedSample {
                        t: s.t,
                        range_m: s.range_m,
                        azimuth_deg: s.azimuth_deg,
                        east_m: s.east_m,
                        north_m: s.north_m,
                        lat_deg: s.lat_deg,
                        lon_deg: s.lon_deg,
                    })
                    .collect(),
            })
            .collect(),
        mean_error_before_m: out.mean_error_before_m,
        mean_error_after_m: out.mean_error_after_m,
        nmea: NmeaSummary {
            lines: out.nmea.lines,
            sentences: out.nmea.sentences,
            messages: out.nmea.messages,
            positions: out.nmea.positions,
            skipped: out
                .nmea
                .skipped_by_type
                .into_iter()
                .map(|(message_type, count)| SkippedType {
                    message_type,
                    count,
                })
                .collect(),
            errors: out
                .nmea
                .errors
                .into_iter()
                .map(|(line, message)| NmeaLineError { line, message })
                .collect(),
        },
        timing: Timing {
            compute_us: out.compute_us,
        },
        warnings: out.warnings,
    })
}
