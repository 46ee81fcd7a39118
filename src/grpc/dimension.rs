//! gRPC `DimensionService`: conversions from prost types to the service input
//! and back. The computation is the service layer's, shared with REST.

use tonic::{Request, Response, Status};

use super::{error::to_status, matrix};
use crate::proto::{self as pb, dimension_service_server::DimensionService};
use service::{self, dimension as svc};

#[derive(Debug, Clone, Default)]
pub struct DimensionGrpc;

#[tonic::async_trait]
impl DimensionService for DimensionGrpc {
    async fn fuse(
        &self,
        request: Request<pb::DimensionFuseRequest>,
    ) -> Result<Response<pb::DimensionFuseResponse>, Status> {
        let input = input(request.into_inner());
        // The answer is converted on the compute lane too.
        let out = service::offload(move || svc::fuse(input).map(response))
            .await
            .map_err(to_status)?;
        Ok(Response::new(out))
    }
}

fn site(s: pb::DimensionSite) -> svc::SiteInput {
    svc::SiteInput {
        lat_deg: s.lat_deg,
        lon_deg: s.lon_deg,
        height_m: s.height_m,
    }
}

fn input(req: pb::DimensionFuseRequest) -> svc::FuseInput {
    svc::FuseInput {
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
                id: r.id,
                kind: r.kind,
                site: r.site.map(site),
                sigma_range_m: r.sigma_range_m,
                sigma_azimuth_deg: r.sigma_azimuth_deg,
                sigma_elevation_deg: r.sigma_elevation_deg,
                scan_period_s: r.scan_period_s,
                tracks: r
                    .tracks
                    .into_iter()
                    .map(|t| svc::TrackInput {
                        id: t.id,
                        plots: t
                            .plots
                            .into_iter()
                            .map(|p| svc::PlotInput {
                                t: p.t,
                                range_m: p.range_m,
                                azimuth_deg: p.azimuth_deg,
                                elevation_deg: p.elevation_deg,
                            })
                            .collect(),
                    })
                    .collect(),
            })
            .collect(),
    }
}

fn track_ref(r: svc::TrackRef) -> pb::DimensionTrackRef {
    pb::DimensionTrackRef {
        radar: r.radar,
        track: r.track,
    }
}

fn response(out: svc::FuseOutput) -> pb::DimensionFuseResponse {
    pb::DimensionFuseResponse {
        state_layout: svc::STATE_LAYOUT.iter().map(|s| s.to_string()).collect(),
        results: out
            .results
            .into_iter()
            .map(|m| pb::DimensionMethodResult {
                method: m.method.into(),
                pairs: m
                    .pairs
                    .into_iter()
                    .map(|p| pb::DimensionPair {
                        a: Some(track_ref(p.a)),
                        b: Some(track_ref(p.b)),
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
                    .map(|s| pb::DimensionSystemTrack {
                        id: s.id,
                        members: s.members.into_iter().map(track_ref).collect(),
                        altitude_known: s.altitude_known,
                        samples: s
                            .samples
                            .into_iter()
                            .map(|x| pb::DimensionSample {
                                covariance: Some(matrix(&x.covariance)),
                                t: x.t,
                                state: x.state,
                                lat_deg: x.lat_deg,
                                lon_deg: x.lon_deg,
                                height_m: x.height_m,
                                altitude: x.altitude.to_string(),
                            })
                            .collect(),
                    })
                    .collect(),
                compute_us: m.compute_us,
            })
            .collect(),
        timing: Some(pb::Timing {
            compute_us: out.compute_us,
        }),
        warnings: out.warnings,
    }
}
