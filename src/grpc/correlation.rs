//! gRPC `CorrelationService`: conversions from prost types to service inputs
//! and back. The computation is the service layer's, shared with REST.

use tonic::{Request, Response, Status};

use super::{error::to_status, flat_rows, matrix, rows};
use crate::proto::{self as pb, correlation_service_server::CorrelationService};
use service::{
    self, ServiceError, Violations, at,
    correlation::{self as corr, decision_name, fusion_name, reason_name, statistic_name},
    rules as svc,
};

#[derive(Debug, Clone, Default)]
pub struct CorrelationGrpc;

#[tonic::async_trait]
impl CorrelationService for CorrelationGrpc {
    async fn evaluate_rules(
        &self,
        request: Request<pb::EvaluateRulesRequest>,
    ) -> Result<Response<pb::EvaluateRulesResponse>, Status> {
        let req = request.into_inner();
        let input = svc::EvaluateRulesInput {
            alpha: req.alpha,
            rules: req
                .rules
                .into_iter()
                .map(|r| svc::RuleInput { l: r.l, r: r.r })
                .collect(),
        };
        let out = service::offload(move || svc::evaluate(input))
            .await
            .map_err(to_status)?;
        Ok(Response::new(pb::EvaluateRulesResponse {
            evaluations: out.evaluations.into_iter().map(Into::into).collect(),
            timing: Some(pb::Timing {
                compute_us: out.compute_us,
            }),
            warnings: out.warnings,
        }))
    }

    async fn recommend_rule(
        &self,
        request: Request<pb::RecommendRuleRequest>,
    ) -> Result<Response<pb::RecommendRuleResponse>, Status> {
        let req = request.into_inner();
        let input = svc::RecommendRuleInput {
            alpha: req.alpha,
            max_miss_probability: req.max_miss_probability,
            min_l_over_r: req.min_l_over_r,
            max_r: req.max_r,
        };
        let out = service::offload(move || svc::recommend(input))
            .await
            .map_err(to_status)?;
        Ok(Response::new(pb::RecommendRuleResponse {
            recommended: out.recommended.map(Into::into),
            considered: out.considered.into_iter().map(Into::into).collect(),
            timing: Some(pb::Timing {
                compute_us: out.compute_us,
            }),
            warnings: out.warnings,
        }))
    }

    async fn correlate_tracks(
        &self,
        request: Request<pb::CorrelateTracksRequest>,
    ) -> Result<Response<pb::CorrelateTracksResponse>, Status> {
        let req = request.into_inner();
        // The answer is converted on the compute lane too.
        let out = service::offload(move || {
            corr::correlate(correlate_input(req)?).map(correlate_response)
        })
        .await
        .map_err(to_status)?;
        Ok(Response::new(out))
    }
}

/// Converts a request; a malformed matrix is reported by its field path.
pub(super) fn correlate_input(
    req: pb::CorrelateTracksRequest,
) -> Result<corr::CorrelateInput, ServiceError> {
    let mut v = Violations::new();
    let method = req.method.map(|m| corr::MethodInput {
        kind: m.kind,
        alpha: m.alpha,
        rule: m.rule.map(rule_in),
        schedule: (!m.schedule.is_empty()).then(|| m.schedule.into_iter().map(rule_in).collect()),
        dynamic_schedule: m.dynamic_schedule,
        statistic: m.statistic,
        window: m.window,
        k: m.k,
    });
    let measurement_matrix = req
        .measurement_matrix
        .as_ref()
        .and_then(|m| rows(&mut v, "measurement_matrix", m));
    let nodes = req
        .nodes
        .into_iter()
        .enumerate()
        .map(|(ni, n)| corr::NodeInput {
            id: (!n.id.is_empty()).then_some(n.id),
            tracks: n
                .tracks
                .into_iter()
                .enumerate()
                .map(|(ti, t)| corr::TrackInput {
                    id: (!t.id.is_empty()).then_some(t.id),
                    samples: t
                        .samples
                        .into_iter()
                        .enumerate()
                        .map(|(si, s)| {
                            sample_in(
                                &mut v,
                                &|| format!("nodes[{ni}].tracks[{ti}].samples[{si}]"),
                                s,
                            )
                        })
                        .collect(),
                })
                .collect(),
        })
        .collect();
    v.finish()?;
    Ok(corr::CorrelateInput {
        state_layout: req.state_layout,
        method,
        motion_model: req.motion_model.map(|m| corr::MotionModelInput {
            kind: m.kind,
            process_noise: m.process_noise,
            sigma_a_mps2: m.sigma_a_mps2,
            q_m2ps3: m.q_m2ps3,
            factor: m.factor,
        }),
        alignment: req.alignment.map(|a| corr::AlignmentInput {
            mode: a.mode,
            tolerance_s: a.tolerance_s,
            max_gap_s: a.max_gap_s,
            period_s: a.period_s,
            epoch_s: a.epoch_s,
            max_staleness_s: a.max_staleness_s,
        }),
        measurement_matrix,
        nodes,
        pruning: req.pruning,
        fuse: req.fuse,
    })
}

fn rule_in(r: pb::LrRule) -> corr::RuleInput {
    corr::RuleInput { l: r.l, r: r.r }
}

pub(super) fn track_ref(t: corr::TrackName) -> pb::TrackRef {
    pb::TrackRef {
        node: t.node,
        track: t.track,
    }
}

pub(super) fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

pub(super) fn pair_result(p: corr::PairOutput) -> pb::PairResult {
    pb::PairResult {
        a: Some(track_ref(p.a)),
        b: Some(track_ref(p.b)),
        decision: decision_name(p.decision).into(),
        reason: reason_name(p.reason).into(),
        trial: p.trial,
        m: p.m,
        c: p.c,
        samples: p.samples,
        mean_statistic: finite(p.mean_statistic),
        last_statistic: finite(p.last_statistic),
        decided_at_t: p.decided_at,
    }
}

pub(super) fn system_track(g: corr::GroupOutput) -> pb::SystemTrack {
    pb::SystemTrack {
        id: g.id,
        members: g.members.into_iter().map(track_ref).collect(),
        t: finite(g.t),
        state: g.state,
        covariance: Some(matrix(&g.covariance)),
        fusion: fusion_name(g.fusion).into(),
        trial: g.trial,
    }
}

fn correlate_response(out: corr::CorrelateOutput) -> pb::CorrelateTracksResponse {
    let rule = |(l, r): (u32, u32)| pb::LrRule {
        l: Some(l),
        r: Some(r),
    };
    pb::CorrelateTracksResponse {
        method: out.method,
        statistic: statistic_name(out.statistic).into(),
        thresholds: Some(pb::CorrelationThresholds {
            alpha: out.thresholds.alpha,
            delta: out.thresholds.delta,
            dof: out.thresholds.dof,
            rule: out.thresholds.rule.map(rule),
            schedule: out.thresholds.schedule.into_iter().map(rule).collect(),
            window: out.thresholds.window,
            k: out.thresholds.k,
        }),
        gains: out.gains.into(),
        instants: out.instants,
        alignment: Some(pb::AlignmentReport {
            mode: out.alignment.mode.into(),
            period_s: out.alignment.period_s,
            period_estimated: out.alignment.period_estimated,
            epoch_s: out.alignment.epoch_s,
            tolerance_s: out.alignment.tolerance_s,
            max_gap_s: out.alignment.max_gap_s,
            nodes: out
                .alignment
                .nodes
                .into_iter()
                .map(|n| pb::NodeAlignment {
                    node: n.node,
                    tracks: n.tracks as u64,
                    scan_period_s: n.scan_period_s,
                    max_staleness_s: n.max_staleness_s,
                })
                .collect(),
            instants: out.alignment.instants as u64,
            node_pairs_without_common_instant: out.alignment.node_pairs_without_common_instant
                as u64,
            tracks_without_partner_instant: out.alignment.tracks_without_partner_instant as u64,
            tracks: out.alignment.tracks as u64,
            brought: out.alignment.brought as u64,
            unused_samples: out.alignment.unused_samples as u64,
        }),
        pairs: out.pairs.into_iter().map(pair_result).collect(),
        omitted_pairs: out.omitted_pairs,
        unpaired: out
            .unpaired
            .into_iter()
            .map(|(node, tracks)| pb::UnpairedTracks { node, tracks })
            .collect(),
        system_tracks: out.groups.into_iter().map(system_track).collect(),
        conflicts: out
            .conflicts
            .into_iter()
            .map(|c| pb::CorrelationConflict {
                a: Some(track_ref(c.a)),
                b: Some(track_ref(c.b)),
                node: c.node,
                tracks: vec![c.tracks.0, c.tracks.1],
            })
            .collect(),
        timing: Some(pb::CorrelationTiming {
            compute_us: out.timing.compute_us,
            align_us: out.timing.align_us,
            correlate_us: out.timing.correlate_us,
            fuse_us: out.timing.fuse_us,
        }),
        warnings: out.warnings,
    }
}

impl From<svc::RuleEvaluation> for pb::RuleEvaluation {
    fn from(e: svc::RuleEvaluation) -> Self {
        Self {
            l: e.l,
            r: e.r,
            misses_from: e.misses_from,
            miss_probability: e.miss_probability,
        }
    }
}

/// A track sample as the service's input; its field paths (`field()` is the
/// sample's) are formatted only for a violation.
pub(super) fn sample_in(
    v: &mut Violations,
    field: &dyn Fn() -> String,
    s: pb::TrackSample,
) -> corr::SampleInput {
    let covariance = match s.covariance {
        Some(m) => flat_rows(v, at(|| format!("{}.covariance", field())), m),
        None => {
            v.add(format!("{}.covariance", field()), "is required");
            None
        }
    };
    let gain = s
        .gain
        .and_then(|m| flat_rows(v, at(|| format!("{}.gain", field())), m));
    corr::SampleInput {
        t: s.t,
        state: s.state,
        covariance: covariance.unwrap_or_default(),
        gain,
    }
}
