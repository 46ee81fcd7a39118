//! gRPC `JpdaService`: conversions from prost types to the service input and
//! back. The computation is the service layer's, shared with REST.

use tonic::{Request, Response, Status};

use super::{error::to_status, flat_matrix, flat_rows};
use crate::proto::{self as pb, jpda_service_server::JpdaService};
use service::{self, Rows, ServiceError, Violations, at, jpda as svc, validate::Field};

#[derive(Debug, Clone, Default)]
pub struct JpdaGrpc;

#[tonic::async_trait]
impl JpdaService for JpdaGrpc {
    async fn update(
        &self,
        request: Request<pb::JpdaUpdateRequest>,
    ) -> Result<Response<pb::JpdaUpdateResponse>, Status> {
        let req = request.into_inner();
        // The answer is converted on the compute lane too.
        let out = service::offload(move || update_on_lane(req))
            .await
            .map_err(to_status)?;
        Ok(Response::new(out))
    }
}

/// The method's work on the compute lane between decoding and encoding
/// (public for the request-path benchmark, `benches/jpda.rs`).
pub fn update_on_lane(req: pb::JpdaUpdateRequest) -> Result<pb::JpdaUpdateResponse, ServiceError> {
    svc::update(input(req)?).map(response)
}

fn input(req: pb::JpdaUpdateRequest) -> Result<svc::JpdaInput, ServiceError> {
    let mut v = Violations::new();
    let tracks = req
        .tracks
        .into_iter()
        .enumerate()
        .map(|(i, t)| svc::TrackInput {
            id: t.id,
            state: t.state,
            covariance: required_rows(
                &mut v,
                at(|| format!("tracks[{i}].covariance")),
                t.covariance,
            ),
        })
        .collect();
    let sensors = req
        .sensors
        .into_iter()
        .enumerate()
        .map(|(i, s)| svc::SensorInput {
            id: s.id,
            kind: s.kind,
            h: s.h
                .map(|m| flat_rows(&mut v, format!("sensors[{i}].h"), m).unwrap_or_default()),
            r: s.r
                .map(|m| flat_rows(&mut v, format!("sensors[{i}].r"), m).unwrap_or_default()),
            site_m: (!s.site_m.is_empty()).then_some(s.site_m),
            sigma_range_m: s.sigma_range_m,
            sigma_azimuth_deg: s.sigma_azimuth_deg,
            sigma_elevation_deg: s.sigma_elevation_deg,
            detection_probability: s.detection_probability,
            gate_probability: s.gate_probability,
            gate_threshold: s.gate_threshold,
            clutter_density: s.clutter_density,
            measurements: s
                .measurements
                .into_iter()
                .map(|m| svc::MeasurementInput {
                    z: (!m.z.is_empty()).then_some(m.z),
                    range_m: m.range_m,
                    azimuth_deg: m.azimuth_deg,
                    elevation_deg: m.elevation_deg,
                })
                .collect(),
        })
        .collect();
    v.finish()?;
    Ok(svc::JpdaInput {
        state_layout: req.state_layout,
        method: req.method,
        max_exact_cluster_tracks: req.max_exact_cluster_tracks,
        prediction: req.prediction.map(|p| svc::PredictionInput {
            dt_s: p.dt_s,
            sigma_a_mps2: p.sigma_a_mps2,
        }),
        tracks,
        sensors,
    })
}

/// A required `Matrix` as request rows (empty, with a violation, when
/// missing or when its values do not fill rows × cols).
fn required_rows(v: &mut Violations, field: impl Field, m: Option<pb::Matrix>) -> Rows {
    match m {
        None => {
            v.add(field, "is required");
            Rows::default()
        }
        Some(m) => flat_rows(v, field, m).unwrap_or_default(),
    }
}

fn response(out: svc::JpdaOutput) -> pb::JpdaUpdateResponse {
    pb::JpdaUpdateResponse {
        method: out.method.into(),
        tracks: out
            .tracks
            .into_iter()
            .map(|t| pb::JpdaTrackResult {
                covariance: Some(flat_matrix(t.covariance)),
                id: t.id,
                state: t.state,
            })
            .collect(),
        sensors: out
            .sensors
            .into_iter()
            .map(|s| pb::JpdaSensorResult {
                id: s.id,
                clusters: s
                    .clusters
                    .into_iter()
                    .map(|c| pb::JpdaCluster {
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
                    .map(|a| pb::JpdaAssociation {
                        track: a.track,
                        miss_probability: a.miss_probability,
                        measurements: a
                            .measurements
                            .into_iter()
                            .map(|(measurement, beta)| pb::JpdaBeta { measurement, beta })
                            .collect(),
                    })
                    .collect(),
            })
            .collect(),
        timing: Some(pb::Timing {
            compute_us: out.compute_us,
        }),
        warnings: out.warnings,
    }
}
