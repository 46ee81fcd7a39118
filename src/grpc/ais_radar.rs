//! gRPC `AisRadarService`: prost → service input and back. The computation
//! is the service layer's, shared with REST.

use tonic::{Request, Response, Status};

use super::error::to_status;
use crate::proto::{self as pb, ais_radar_service_server::AisRadarService};
use service::{self, ais_radar as svc};

#[derive(Debug, Clone, Default)]
pub struct AisRadarGrpc;

#[tonic::async_trait]
impl AisRadarService for AisRadarGrpc {
    async fn associate(
        &self,
        request: Request<pb::AssociateRequest>,
    ) -> Result<Response<pb::AssociateResponse>, Status> {
        let input = associate_input(request.into_inner());
        // The answer is converted on the compute lane too.
        let out = service::offload(move || svc::associate(input).map(associate_response))
            .await
            .map_err(to_status)?;
        Ok(Response::new(out))
    }
}

fn associate_input(req: pb::AssociateRequest) -> svc::AssociateInput {
    svc::AssociateInput {
        site: req.site.map(|s| svc::SiteInput {
            lat_deg: s.lat_deg,
            lon_deg: s.lon_deg,
        }),
        ellipsoid: req.ellipsoid,
        radar_tracks: req
            .radar_tracks
            .into_iter()
            .map(|t| svc::TrackInput {
                id: (!t.id.is_empty()).then_some(t.id),
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
        options: req.options.map(|o| svc::OptionsInput {
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
    }
}

fn associate_response(out: svc::AssociateOutput) -> pb::AssociateResponse {
    let n = |x: usize| u32::try_from(x).unwrap_or(u32::MAX);
    pb::AssociateResponse {
        path: out.path.to_string(),
        s1_m: out.s1_m,
        s2_m: out.s2_m,
        credible_pairs: out
            .credible_pairs
            .into_iter()
            .map(|p| pb::TrackPair {
                radar_track_id: p.radar_track_id,
                mmsi: p.mmsi,
                distance_m: p.distance_m,
            })
            .collect(),
        bias: out.bias.map(|b| pb::BiasEstimate {
            range_m: b.range_m,
            azimuth_deg: b.azimuth_deg,
            covariance: Some(pb::Matrix {
                rows: 2,
                cols: 2,
                values: b.covariance.iter().flatten().copied().collect(),
            }),
            pairs_used: n(b.pairs_used),
            samples_used: n(b.samples_used),
            effective_pairs: b.effective_pairs,
        }),
        iterations: n(out.iterations),
        converged: out.converged,
        associations: out
            .associations
            .into_iter()
            .map(|a| pb::AisAssociation {
                radar_track_id: a.radar_track_id,
                mmsi: a.mmsi,
                distance_before_m: a.distance_before_m,
                distance_after_m: a.distance_after_m,
                common_samples: n(a.common_samples),
            })
            .collect(),
        unassociated_radar_tracks: out.unassociated_radar_tracks,
        unassociated_mmsis: out.unassociated_mmsis,
        unassociable_mmsis: out.unassociable_mmsis,
        quality: Some(pb::AssociationQuality {
            reliable: out.quality.reliable,
            at_bound: out.quality.at_bound,
            search_widened: out.quality.search_widened,
            ambiguous: out.quality.ambiguous,
            inconsistent: out.quality.inconsistent,
            residual_ratio: out.quality.residual_ratio,
            alternative: out.quality.alternative.map(|a| pb::AlternativeBias {
                range_m: a.range_m,
                azimuth_deg: a.azimuth_deg,
                pairs: n(a.pairs),
                mean_distance_m: a.mean_distance_m,
            }),
            hypotheses_ranked: n(out.quality.hypotheses_ranked),
            hypotheses_scored: n(out.quality.hypotheses_scored),
        }),
        compensated_tracks: out
            .compensated_tracks
            .into_iter()
            .map(|t| pb::CompensatedTrack {
                id: t.id,
                samples: t
                    .samples
                    .into_iter()
                    .map(|s| pb::CompensatedSample {
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
        nmea: Some(pb::NmeaSummary {
            lines: n(out.nmea.lines),
            sentences: n(out.nmea.sentences),
            messages: n(out.nmea.messages),
            positions: n(out.nmea.positions),
            skipped: out
                .nmea
                .skipped_by_type
                .into_iter()
                .map(|(t, c)| pb::SkippedType {
                    message_type: u32::from(t),
                    count: n(c),
                })
                .collect(),
            errors: out
                .nmea
                .errors
                .into_iter()
                .map(|(l, m)| pb::NmeaLineError {
                    line: n(l),
                    message: m,
                })
                .collect(),
        }),
        timing: Some(pb::Timing {
            compute_us: out.compute_us,
        }),
        warnings: out.warnings,
    }
}
