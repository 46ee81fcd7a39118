//! REST route for the JPDA update of seed 002: `POST /v1/jpda/update`.

use axum::{extract::State, response::Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{
    Timing,
    problem::{JsonBody, Problem},
};
use crate::state::AppState;
use service::{Rows, jpda as svc};

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JpdaUpdateRequest {
    /// Names of the state components (`x`, `vx`, `y`, `vy`, `z`, `vz`); default
    /// `[x, vx, y, vy]` for 4 and `[x, vx, y, vy, z, vz]` for 6 components.
    #[serde(default)]
    #[schema(example = json!(["x", "vx", "y", "vy"]))]
    pub state_layout: Vec<String>,
    /// `exact` (default), `amsjpda`, `nearest_neighbour` or `global_nearest_neighbour`.
    #[schema(example = "exact")]
    pub method: Option<String>,
    /// Clusters with more tracks are computed by AMSJPDA (default 24, 1 to 128).
    #[schema(minimum = 1, maximum = 128)]
    pub max_exact_cluster_tracks: Option<u32>,
    /// Predict every track over `dt_s` first (constant velocity, DWNA noise).
    pub prediction: Option<JpdaPrediction>,
    /// Tracks (predicted unless `prediction` is given).
    pub tracks: Vec<JpdaTrack>,
    /// Sensors, processed sequentially in this order (seed 002 eqs. 8–10).
    pub sensors: Vec<JpdaSensor>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JpdaPrediction {
    #[schema(example = 8.0)]
    pub dt_s: f64,
    /// Standard deviation of the white-noise acceleration.
    #[schema(example = 1.0)]
    pub sigma_a_mps2: f64,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JpdaTrack {
    pub id: String,
    pub state: Vec<f64>,
    /// Symmetric positive definite, row-major nested rows.
    #[schema(value_type = Vec<Vec<f64>>)]
    pub covariance: Rows,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JpdaSensor {
    pub id: Option<String>,
    /// `linear` (z = H x + w) or `polar` (range, azimuth[, elevation]; EKF update).
    #[schema(example = "linear")]
    pub kind: String,
    /// Linear sensors: measurement matrix H (rows × state dimension).
    #[schema(value_type = Option<Vec<Vec<f64>>>)]
    pub h: Option<Rows>,
    /// Linear sensors: measurement noise covariance R.
    #[schema(value_type = Option<Vec<Vec<f64>>>)]
    pub r: Option<Rows>,
    /// Polar sensors: site `[east, north, up]` in the local frame.
    pub site_m: Option<Vec<f64>>,
    pub sigma_range_m: Option<f64>,
    pub sigma_azimuth_deg: Option<f64>,
    /// Present for a 3D radar.
    pub sigma_elevation_deg: Option<f64>,
    /// P_D in (0, 1].
    #[schema(example = 0.9, exclusive_minimum = 0.0, maximum = 1.0)]
    pub detection_probability: f64,
    /// P_G in (0, 1], default 0.99; or give `gate_threshold` (χ²) instead.
    #[schema(exclusive_minimum = 0.0, maximum = 1.0)]
    pub gate_probability: Option<f64>,
    pub gate_threshold: Option<f64>,
    /// Clutter density λ per unit volume of the measurement space (m² for
    /// a 2D position, m·rad for range–azimuth); absent: non-parametric
    /// clutter estimated from the gate volumes.
    pub clutter_density: Option<f64>,
    /// May be empty: every track then misses.
    pub measurements: Vec<JpdaMeasurement>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JpdaMeasurement {
    /// Linear sensors: the measurement vector.
    pub z: Option<Vec<f64>>,
    pub range_m: Option<f64>,
    pub azimuth_deg: Option<f64>,
    pub elevation_deg: Option<f64>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JpdaUpdateResponse {
    pub method: String,
    pub tracks: Vec<JpdaTrackResult>,
    pub sensors: Vec<JpdaSensorResult>,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JpdaTrackResult {
    pub id: String,
    pub state: Vec<f64>,
    #[schema(value_type = Vec<Vec<f64>>)]
    pub covariance: Rows,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JpdaSensorResult {
    pub id: String,
    pub clusters: Vec<JpdaCluster>,
    pub associations: Vec<JpdaAssociation>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JpdaCluster {
    /// Track ids.
    pub tracks: Vec<String>,
    /// Measurement indices into the sensor's `measurements`.
    pub measurements: Vec<u32>,
    /// The method that produced β for this cluster.
    pub method: String,
    /// Why an exact cluster fell back to AMSJPDA: `too_many_tracks`,
    /// `too_many_hypotheses` or `frontier_too_wide`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fallback: Option<String>,
    /// Merged hypothesis-tree edges (exact), products (AMSJPDA) or gated pairs (NN, GNN).
    pub hypotheses: u64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JpdaAssociation {
    pub track: String,
    /// β_t0: no measurement is the target's.
    pub miss_probability: f64,
    /// β_tj over the gated measurements.
    pub measurements: Vec<JpdaBeta>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JpdaBeta {
    pub measurement: u32,
    pub beta: f64,
}

/// JPDA update of tracks with one scan from one or more sensors (seed 002).
#[utoipa::path(
    post,
    path = "/v1/jpda/update",
    tag = "jpda",
    request_body = JpdaUpdateRequest,
    responses(
        (status = 200, description = "Updated tracks, β per sensor, clusters", body = JpdaUpdateResponse),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn update(
    State(_state): State<AppState>,
    body: JsonBody<JpdaUpdateRequest>,
) -> Result<Response, Problem> {
    body.compute(update_on_lane).await
}

/// The endpoint's work on the compute lane between parsing and encoding
/// (public for the request-path benchmark, `benches/jpda.rs`).
pub fn update_on_lane(req: JpdaUpdateRequest) -> Result<JpdaUpdateResponse, Problem> {
    let input = svc::JpdaInput {
        state_layout: req.state_layout,
        method: req.method,
        max_exact_cluster_tracks: req.max_exact_cluster_tracks,
        prediction: req.prediction.map(|p| svc::PredictionInput {
            dt_s: Some(p.dt_s),
            sigma_a_mps2: Some(p.sigma_a_mps2),
        }),
        tracks: req
            .tracks
            .into_iter()
            .map(|t| svc::TrackInput {
                id: Some(t.id),
                state: t.state,
                covariance: t.covariance,
            })
            .collect(),
        sensors: req
            .sensors
            .into_iter()
            .map(|s| svc::SensorInput {
                id: s.id,
                kind: Some(s.kind),
                h: s.h,
                r: s.r,
                site_m: s.site_m,
                sigma_range_m: s.sigma_range_m,
                sigma_azimuth_deg: s.sigma_azimuth_deg,
                sigma_elevation_deg: s.sigma_elevation_deg,
                detection_probability: Some(s.detection_probability),
                gate_probability: s.gate_probability,
                gate_threshold: s.gate_threshold,
                clutter_density: s.clutter_density,
                measurements: s
                    .measurements
                    .into_iter()
                    .map(|m| svc::MeasurementInput {
                        z: m.z,
                        range_m: m.range_m,
                        azimuth_deg: m.azimuth_deg,
                        elevation_deg: m.elevation_deg,
                    })
                    .collect(),
            })
            .collect(),
    };
    let out = svc::update(input)?;
    Ok(JpdaUpdateResponse {
        method: out.method.into(),
        tracks: out
            .tracks
            .into_iter()
            .map(|t| JpdaTrackResult {
                id: t.id,
                state: t.state,
                covariance: t.covariance,
            })
            .collect(),
        sensors: out
            .sensors
            .into_iter()
            .map(|s| JpdaSensorResult {
                id: s.id,
                clusters: s
                    .clusters
                    .into_iter()
                    .map(|c| JpdaCluster {
                        tracks: c.tracks,
                        measurements: c.measurements,
                        method: c.method.into(),
                        fallback: c.fallback.map(Into::into),
                        hypotheses: c.hypotheses,
                    })
                    .collect(),
                associations: s
                    .associations
                    .into_iter()
                    .map(|a| JpdaAssociation {
                        track: a.track,
                        miss_probability: a.miss_probability,
                        measurements: a
                            .measurements
                            .into_iter()
                            .map(|(measurement, beta)| JpdaBeta { measurement, beta })
                            .collect(),
                    })
                    .collect(),
            })
            .collect(),
        timing: Timing {
            compute_us: out.compute_us,
        },
        warnings: out.warnings,
    })
}
