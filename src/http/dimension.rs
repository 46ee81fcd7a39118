//! REST route for the dimension fusion of seed 003: `POST /v1/dimension/fuse`.

use axum::{extract::State, response::Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{
    Timing,
    problem::{JsonBody, Problem, answer_json},
};
use crate::state::AppState;
use service::dimension as svc;

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DimensionFuseRequest {
    /// The fusion centre, origin of the ENU frame of the system tracks;
    /// default: the first radar's site.
    pub origin: Option<DimensionSite>,
    /// Any of `mapping`, `lifting`, `splitting` (default: all three, to compare).
    #[serde(default)]
    #[schema(example = json!(["lifting", "splitting"]))]
    pub methods: Vec<String>,
    /// Local filter: `alpha_beta` (adaptive, default) or `kalman`.
    pub filter: Option<String>,
    /// Residual window N of the adaptive α-β filter, 3 to 5 (default 4).
    #[schema(minimum = 3, maximum = 5)]
    pub window: Option<u32>,
    /// Kalman filter: white-noise acceleration σ (default 5 m/s²).
    pub sigma_a_mps2: Option<f64>,
    /// Association tests N₀, 2 to 1000 (default 5).
    #[schema(minimum = 2, maximum = 1000)]
    pub n0: Option<u32>,
    /// Hits K required among N₀, ⌈N₀/2⌉ ≤ K ≤ N₀ (default 3).
    #[schema(minimum = 1, maximum = 1000)]
    pub k: Option<u32>,
    /// Mapping's preset altitude, and the nominal height of 2D tracks (default 5000 m).
    pub preset_altitude_m: Option<f64>,
    /// σ of a 2D track's unknown height under lifting and splitting (default 5000 m).
    pub altitude_sigma_m: Option<f64>,
    /// Association-period hit: every component within this many σ (default 3).
    pub gate_sigmas: Option<f64>,
    /// Significance α of the check period's χ² test, in (0, 1) (default 0.01).
    #[schema(exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub significance: Option<f64>,
    /// Also return every fused sample of each system track; default: only
    /// its latest sample (`samples` holds one), so the answer stays small.
    #[serde(default)]
    pub history: bool,
    /// List every pair of tracks tested; default: pairs without a hit, a
    /// check or a revocation are only counted (`omitted_pairs`).
    #[serde(default)]
    pub all_pairs: bool,
    pub radars: Vec<DimensionRadar>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DimensionSite {
    #[schema(example = 30.0)]
    pub lat_deg: f64,
    #[schema(example = 120.0)]
    pub lon_deg: f64,
    /// WGS84 ellipsoidal height.
    #[schema(example = 0.0)]
    pub height_m: f64,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DimensionRadar {
    pub id: String,
    /// `2d` (range, azimuth) or `3d` (range, azimuth, elevation).
    #[schema(example = "3d")]
    pub kind: String,
    pub site: DimensionSite,
    #[schema(example = 100.0)]
    pub sigma_range_m: f64,
    #[schema(example = 0.5)]
    pub sigma_azimuth_deg: f64,
    /// 3D radars only.
    pub sigma_elevation_deg: Option<f64>,
    #[schema(example = 10.0)]
    pub scan_period_s: f64,
    pub tracks: Vec<DimensionTrack>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DimensionTrack {
    pub id: String,
    /// Plots in increasing time.
    pub plots: Vec<DimensionPlot>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DimensionPlot {
    pub t: f64,
    /// Slant range.
    pub range_m: f64,
    /// Clockwise from true north.
    pub azimuth_deg: f64,
    /// 3D radars only.
    pub elevation_deg: Option<f64>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct DimensionFuseResponse {
    /// The layout of every system-track state: `[x, vx, y, vy, z, vz]` (ENU about the origin).
    pub state_layout: Vec<String>,
    pub results: Vec<DimensionMethodResult>,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct DimensionMethodResult {
    pub method: String,
    /// The pairs of tracks of different radars that hit in their current
    /// association period, were checked or revoked (every pair tested with
    /// `all_pairs`), with their K-NN period.
    pub pairs: Vec<DimensionPair>,
    /// Pairs tested but not listed (none with `all_pairs`).
    pub omitted_pairs: u64,
    /// Tracks correlated with no other radar's track.
    pub uncorrelated: Vec<DimensionTrackRef>,
    pub system_tracks: Vec<DimensionSystemTrack>,
    pub compute_us: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct DimensionTrackRef {
    pub radar: String,
    pub track: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct DimensionPair {
    pub a: DimensionTrackRef,
    pub b: DimensionTrackRef,
    /// `association`, `check`, `hold` or `rejected`.
    pub period: String,
    /// In the check or hold period: part of one system track.
    pub correlated: bool,
    /// Tests, hits and misses of the current association period.
    pub tests: u32,
    pub hits: u32,
    pub misses: u32,
    /// T_ij of the check period and its number of tests.
    pub check_counter: i32,
    pub check_tests: u32,
    pub revocations: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_statistic: Option<f64>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct DimensionSystemTrack {
    pub id: String,
    pub members: Vec<DimensionTrackRef>,
    /// False when only 2D radars see the track (not under mapping): the height is unknown.
    pub altitude_known: bool,
    /// The fused samples in time order: only the latest unless the request
    /// asked for `history`.
    pub samples: Vec<DimensionSample>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct DimensionSample {
    pub t: f64,
    pub state: Vec<f64>,
    pub covariance: Vec<Vec<f64>>,
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Absent when the altitude is assumed (only 2D members, preset height)
    /// and the method is not mapping.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f64>,
    /// Where this sample's height comes from: `measured` (a 3D member
    /// contributed), `lifted` (2D members placed at the height the system
    /// track's 3D members gave at the nearest instant, its σ grown by 10 m/s
    /// per second of distance) or `assumed` (the preset altitude).
    pub altitude: &'static str,
}

fn site(s: DimensionSite) -> svc::SiteInput {
    svc::SiteInput {
        lat_deg: Some(s.lat_deg),
        lon_deg: Some(s.lon_deg),
        height_m: Some(s.height_m),
    }
}

fn track_ref(r: svc::TrackRef) -> DimensionTrackRef {
    DimensionTrackRef {
        radar: r.radar,
        track: r.track,
    }
}

/// Correlates and fuses 2D and 3D radar tracks by mapping, dimension lifting
/// and/or dimension splitting (seed 003).
#[utoipa::path(
    post,
    path = "/v1/dimension/fuse",
    tag = "dimension",
    request_body = DimensionFuseRequest,
    responses(
        (status = 200, description = "Per method: pairs with their periods, system tracks", body = DimensionFuseResponse),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn fuse(
    State(_state): State<AppState>,
    body: JsonBody<DimensionFuseRequest>,
) -> Result<Response, Problem> {
    body.compute(fuse_on_lane).await
}

/// The route's whole job (parse, the three methods, encode) on its
/// documented example, a 3D and a 2D radar: what the start-up warm-up runs
/// on every compute lane (`super::warm_up`). Returns the answer's length.
pub fn warm_up() -> Result<usize, Problem> {
    warm_up_answer().map(|answer| answer.len())
}

/// The answer [`warm_up`] encodes.
pub(super) fn warm_up_answer() -> Result<Vec<u8>, Problem> {
    let body = super::request_example_text("/v1/dimension/fuse").unwrap_or_default();
    answer_json(body.as_bytes(), fuse_on_lane)
}

fn fuse_on_lane(req: DimensionFuseRequest) -> Result<DimensionFuseResponse, Problem> {
    let input = svc::FuseInput {
        origin: req.origin.map(site),
        methods: req.methods,
        filter: req.filter,
        window: req.window,
        sigma_a_mps2: req.sigma_a_mps2,
        n0: req.n0,
        k: req.k,
        preset_altitude_m: req.preset_altitude_m,
        altitude_sigma_m: req.altitude_sigma_m,
        gate_sigmas: req.gate_sigmas,
        significance: req.significance,
        history: req.history,
        all_pairs: req.all_pairs,
        radars: req
            .radars
            .into_iter()
            .map(|r| svc::RadarInput {
                id: Some(r.id),
                kind: Some(r.kind),
                site: Some(site(r.site)),
                sigma_range_m: Some(r.sigma_range_m),
                sigma_azimuth_deg: Some(r.sigma_azimuth_deg),
                sigma_elevation_deg: r.sigma_elevation_deg,
                scan_period_s: Some(r.scan_period_s),
                tracks: r
                    .tracks
                    .into_iter()
                    .map(|t| svc::TrackInput {
                        id: Some(t.id),
                        plots: t
                            .plots
                            .into_iter()
                            .map(|p| svc::PlotInput {
                                t: Some(p.t),
                                range_m: Some(p.range_m),
                                azimuth_deg: Some(p.azimuth_deg),
                                elevation_deg: p.elevation_deg,
                            })
                            .collect(),
                    })
                    .collect(),
            })
            .collect(),
    };
    let out = svc::fuse(input)?;
    Ok(DimensionFuseResponse {
        state_layout: svc::STATE_LAYOUT.iter().map(|s| s.to_string()).collect(),
        results: out
            .results
            .into_iter()
            .map(|m| DimensionMethodResult {
                method: m.method.into(),
                pairs: m
                    .pairs
                    .into_iter()
                    .map(|p| DimensionPair {
                        a: track_ref(p.a),
                        b: track_ref(p.b),
                        period: p.period.into(),
                        correlated: p.correlated,
                        tests: p.tests,
                        hits: p.hits,
                        misses: p.misses,
                        check_counter: p.check_counter,
                        check_tests: p.check_tests,
                        revocations: p.revocations,
                        mean_statistic: p.mean_statistic,
                    })
                    .collect(),
                omitted_pairs: m.omitted_pairs,
                uncorrelated: m.uncorrelated.into_iter().map(track_ref).collect(),
                system_tracks: m
                    .system_tracks
                    .into_iter()
                    .map(|s| DimensionSystemTrack {
                        id: s.id,
                        members: s.members.into_iter().map(track_ref).collect(),
                        altitude_known: s.altitude_known,
                        samples: s
                            .samples
                            .into_iter()
                            .map(|x| DimensionSample {
                                t: x.t,
                                state: x.state,
                                covariance: x.covariance,
                                lat_deg: x.lat_deg,
                                lon_deg: x.lon_deg,
                                height_m: x.height_m,
                                altitude: x.altitude,
                            })
                            .collect(),
                    })
                    .collect(),
                compute_us: m.compute_us,
            })
            .collect(),
        timing: Timing {
            compute_us: out.compute_us,
        },
        warnings: out.warnings,
    })
}
