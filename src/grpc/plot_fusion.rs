//! gRPC `PlotFusionService`: conversions from prost types to the service
//! input and back. The tracking is the service layer's, shared with REST.

use tonic::{Request, Response, Status};

use super::{error::to_status, matrix};
use crate::proto::{self as pb, plot_fusion_service_server::PlotFusionService};
use service::plot_fusion::TrackerCounters as Counters;
use service::{self, plot_fusion as svc};

#[derive(Debug, Clone, Default)]
pub struct PlotFusionGrpc;

#[tonic::async_trait]
impl PlotFusionService for PlotFusionGrpc {
    async fn track(
        &self,
        request: Request<pb::PlotFusionRequest>,
    ) -> Result<Response<pb::PlotFusionResponse>, Status> {
        let req = request.into_inner();
        let input = svc::TrackInput {
            spec: spec_in(req.origin, req.radars, req.tracker, req.cat062),
            plots: plots_in(req.plots, req.cooperative),
            asterix: req.asterix.map(asterix_in),
            nmea: req.nmea.map(nmea_in),
            history: req.history,
        };
        let out = service::offload(move || svc::track(input))
            .await
            .map_err(to_status)?;
        Ok(Response::new(pb::PlotFusionResponse {
            mode: out.mode.into(),
            state_layout: out.state_layout.iter().map(|s| s.to_string()).collect(),
            tracks: out.tracks.into_iter().map(track_out).collect(),
            deleted: out.deleted.into_iter().map(track_out).collect(),
            history: out
                .history
                .unwrap_or_default()
                .into_iter()
                .map(|e| pb::TrackHistoryEntry {
                    t: e.t,
                    tracks: e.tracks.into_iter().map(track_out).collect(),
                })
                .collect(),
            counters: Some(counters_out(out.counters)),
            asterix: out.asterix.map(asterix_out),
            cat062: out.cat062.map(|c| c.data),
            registration: out.registration.into_iter().map(bias_out).collect(),
            accuracy: out.accuracy.into_iter().map(accuracy_out).collect(),
            pressure_offset: out.pressure_offset.map(pressure_offset_out),
            timing: Some(pb::Timing {
                compute_us: out.compute_us,
            }),
            warnings: out.warnings,
        }))
    }
}

fn sigma_out(s: svc::SigmaView) -> pb::SigmaState {
    pb::SigmaState {
        declared: s.declared,
        estimated: s.estimated,
        sigma: s.sigma,
        plots: s.plots,
        converged: s.converged,
        applied: s.applied,
        clipped: s.clipped,
    }
}

pub(crate) fn accuracy_out(a: svc::RadarAccuracyView) -> pb::RadarAccuracyState {
    pb::RadarAccuracyState {
        radar: a.radar,
        range_m: Some(sigma_out(a.range_m)),
        azimuth_deg: Some(sigma_out(a.azimuth_deg)),
        elevation_deg: a.elevation_deg.map(sigma_out),
        radial_velocity_mps: a.radial_velocity_mps.map(sigma_out),
        p_detection: a.p_detection.map(sigma_out),
        pinned: a.pinned,
    }
}

pub(crate) fn bias_out(b: svc::RadarBiasView) -> pb::RadarBiasState {
    pb::RadarBiasState {
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

fn geo_in(g: pb::GeoPoint) -> svc::GeoInput {
    svc::GeoInput {
        lat_deg: g.lat_deg,
        lon_deg: g.lon_deg,
        height_m: g.height_m,
    }
}

pub(crate) fn spec_in(
    origin: Option<pb::GeoPoint>,
    radars: Vec<pb::PlotRadar>,
    tracker: Option<pb::TrackerOptions>,
    cat062: Option<pb::Cat062Options>,
) -> svc::SpecInput {
    let t = tracker.unwrap_or_default();
    let nonempty = |v: Vec<f64>| (!v.is_empty()).then_some(v);
    svc::SpecInput {
        cat062: cat062.map(|c| svc::cat062::Cat062Input {
            sac: Some(c.sac),
            sic: Some(c.sic),
            service_id: c.service_id,
            day_start_t: c.day_start_t,
            max_block_bytes: c.max_block_bytes,
        }),
        origin: origin.map(geo_in),
        radars: radars
            .into_iter()
            .map(|r| svc::RadarInput {
                id: Some(r.id),
                kind: (!r.kind.is_empty()).then_some(r.kind),
                site: r.site.map(|s| svc::SiteInput {
                    geodetic: (s.lat_deg.is_some() || s.lon_deg.is_some()).then_some(
                        svc::GeoInput {
                            lat_deg: s.lat_deg,
                            lon_deg: s.lon_deg,
                            height_m: s.height_m,
                        },
                    ),
                    position_m: nonempty(s.position_m),
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
                v_min_axis_mps: nonempty(i.v_min_axis_mps),
                v_max_axis_mps: nonempty(i.v_max_axis_mps),
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
            imm_models: (!t.imm_models.is_empty()).then(|| {
                t.imm_models
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
                    reference: (!r.reference.is_empty()).then_some(r.reference),
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
                pinned: (!a.pinned.is_empty()).then_some(a.pinned),
            }),
        },
    }
}

pub(crate) fn pressure_offset_out(o: svc::PressureOffsetView) -> pb::PressureOffsetState {
    pb::PressureOffsetState {
        offset_m: o.offset_m,
        slope: o.slope,
        sigma_offset_m: o.sigma_offset_m,
        sigma_slope: o.sigma_slope,
        correlation: o.correlation,
        plots: o.plots,
        rejected: o.rejected,
    }
}

/// A request's plots, then its cooperative reports (the service names
/// them `cooperative[i]` in its errors).
pub(crate) fn plots_in(
    plots: Vec<pb::RadarPlot>,
    cooperative: Vec<pb::CooperativeReport>,
) -> Vec<svc::PlotInput> {
    let mut out = radar_plots_in(plots);
    out.extend(cooperative.into_iter().map(report_in));
    out
}

/// A protobuf `uint32` category as the service's `u8` (a value past 255
/// is out of every category's range and kept out of it).
fn category(v: Option<u32>) -> Option<u8> {
    v.map(|v| u8::try_from(v).unwrap_or(u8::MAX))
}

fn report_in(r: pb::CooperativeReport) -> svc::PlotInput {
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
            nacp: category(r.nacp),
            nacv: category(r.nacv),
            position_accurate: r.position_accurate,
            sigma_m: r.sigma_m,
            sigma_height_m: r.sigma_height_m,
            sigma_velocity_mps: r.sigma_velocity_mps,
            mmsi: r.mmsi,
        }),
        ..Default::default()
    }
}

fn radar_plots_in(plots: Vec<pb::RadarPlot>) -> Vec<svc::PlotInput> {
    plots
        .into_iter()
        .map(|p| svc::PlotInput {
            radar_id: Some(p.radar_id),
            t: p.t,
            range_m: p.range_m,
            azimuth_deg: p.azimuth_deg,
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

pub(crate) fn nmea_in(n: pb::NmeaData) -> svc::nmea::NmeaInput {
    svc::nmea::NmeaInput {
        lines: n.lines,
        time_offset_s: n.time_offset_s,
    }
}

pub(crate) fn asterix_in(a: pb::AsterixData) -> svc::asterix::AsterixInput {
    svc::asterix::AsterixInput {
        data: a.data,
        date: a.date,
        day_start_t: a.day_start_t,
        reference_t: None,
        reception: None,
    }
}

pub(crate) fn asterix_out(s: svc::asterix::AsterixSummary) -> pb::AsterixSummary {
    let n = |x: usize| x as u64;
    pb::AsterixSummary {
        bytes: n(s.bytes),
        blocks: n(s.blocks),
        records: n(s.records),
        target_reports: n(s.target_reports),
        plots: n(s.plots),
        north_markers: n(s.north_markers),
        sector_crossings: n(s.sector_crossings),
        other_service_messages: n(s.other_service_messages),
        unmapped: n(s.unmapped),
        test_targets: n(s.test_targets),
        incomplete: n(s.incomplete),
        rejected: n(s.rejected),
        late: n(s.late),
        late_offsets: s.late_offsets.into_iter().map(n).collect(),
        first_t: s.first_t,
        last_t: s.last_t,
        errors: s
            .errors
            .into_iter()
            .map(|e| pb::AsterixError {
                offset: n(e.offset),
                reason: e.reason,
            })
            .collect(),
        errors_not_listed: n(s.errors_not_listed),
    }
}

pub(crate) fn track_out(t: svc::TrackView) -> pb::FusedTrack {
    pb::FusedTrack {
        id: t.id,
        status: t.status.into(),
        t: t.t,
        state: t.state,
        covariance: Some(matrix(&t.covariance)),
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
            .map(|m| pb::TrackMode {
                model: m.model,
                probability: m.probability,
            })
            .collect(),
        turn_rate_dps: t.turn_rate_dps,
        start_t: t.start_t,
        last_plot: t.last_plot.map(|p| pb::LastPlot {
            radar: p.radar,
            t: p.t,
            range_m: p.range_m,
            azimuth_deg: p.azimuth_deg,
            elevation_deg: p.elevation_deg,
            radial_velocity_mps: p.radial_velocity_mps,
        }),
        identity: t.identity.map(identity_out),
        sources: t
            .sources
            .into_iter()
            .map(|s| pb::TrackSource {
                sensor: s.sensor,
                last_t: s.last_t,
            })
            .collect(),
        self_reported: t.self_reported.map(|v| pb::SelfReported {
            trusted: v.trusted,
            validated: v.validated,
            distrusted_since_t: v.distrusted_since_t,
            last_self_reported_t: v.last_self_reported_t,
            last_independent_t: v.last_independent_t,
            disagreement_t: v.disagreement.as_ref().map(|d| d.t),
            disagreement_distance_m: v.disagreement.as_ref().map(|d| d.distance_m),
            disagreement_stated_sigma_m: v.disagreement.as_ref().map(|d| d.stated_sigma_m),
        }),
        mmsi: t.mmsi,
    }
}

fn item_out(i: svc::IdentityItem) -> pb::IdentityItem {
    pb::IdentityItem {
        value: i.value,
        plots: i.plots,
        first_t: i.first_t,
        last_t: i.last_t,
    }
}

fn identity_out(v: svc::IdentityView) -> pb::TrackIdentity {
    pb::TrackIdentity {
        mode_s_address: v.mode_s_address.map(item_out),
        mode_3a: v.mode_3a.map(item_out),
        pending_mode_3a: v.pending_mode_3a.map(item_out),
        callsign: v.callsign.map(item_out),
        pressure_altitude: v.pressure_altitude.map(|a| pb::PressureAltitude {
            t: a.t,
            flight_level: a.flight_level,
            flight_level_sigma: a.flight_level_sigma,
            rate_of_climb_ftpm: a.rate_of_climb_ftpm,
            rate_of_climb_sigma_ftpm: a.rate_of_climb_sigma_ftpm,
            measured_flight_level: a.measured_flight_level,
            measured_t: a.measured_t,
        }),
        emergency: v.emergency.map(str::to_string),
        spi: v.spi,
        last_secondary_t: v.last_secondary_t,
        last_mode_s_t: v.last_mode_s_t,
        last_primary_t: v.last_primary_t,
    }
}

pub(crate) fn counters_out(c: Counters) -> pb::TrackerCounters {
    pb::TrackerCounters {
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
