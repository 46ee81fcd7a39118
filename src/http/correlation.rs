//! REST route for batch track-to-track correlation (seed 000 and baselines).

use axum::{extract::State, response::Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::problem::{JsonBody, Problem};
use crate::state::AppState;
use service::{
    Rows,
    correlation::{self as svc, decision_name, fusion_name, reason_name, statistic_name},
};

/// Local tracks of M ≥ 1 radar nodes to correlate.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CorrelateTracksRequest {
    /// Names of the state components, a permutation of `[x, vx, y, vy]`,
    /// `[x, vx, y, vy, z, vz]`, `[x, y]` or `[x, y, z]` (metres, m/s; x east, y north, z up).
    #[schema(example = json!(["x", "vx", "y", "vy"]))]
    pub state_layout: Vec<String>,
    pub method: CorrelationMethod,
    /// The local filters' motion model: needed by the modified statistic and
    /// by alignment in `predict` mode.
    pub motion_model: Option<MotionModel>,
    pub alignment: Option<Alignment>,
    /// H of the local filters (measurement × state, in state_layout order),
    /// needed to use reported gains K as I − K H.
    pub measurement_matrix: Option<Vec<Vec<f64>>>,
    pub nodes: Vec<Node>,
    /// `grid` (default: exact spatial pruning of candidate pairs) or `none`
    /// (brute force over all pairs; the same result, for comparison).
    #[schema(example = "grid")]
    pub pruning: Option<String>,
    /// Fuse each correlated group into a system track (default true).
    pub fuse: Option<bool>,
}

/// The correlation method and its parameters.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CorrelationMethod {
    /// `weighted`, `modified` (classic tests, eqs. 10 and 12), `independent_double_threshold`,
    /// `dependent_double_threshold` (section 3), `double_threshold_assignment` (double threshold
    /// with a global assignment at decision time), `nearest_neighbour`, `k_nearest_neighbour`,
    /// `global_assignment`.
    #[schema(example = "independent_double_threshold")]
    pub kind: String,
    /// Significance level α of the first threshold (eq. 14), in (0, 1); default 0.05.
    #[schema(example = 0.05, exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub alpha: Option<f64>,
    /// Fixed L/R rule of the double-threshold methods; default 6/8.
    pub rule: Option<LrRule>,
    /// Dynamic rules: entry i applies after i + 1 samples (its r must be i + 1).
    pub schedule: Option<Vec<LrRule>>,
    /// Use the paper's dynamic schedule 1/1, 2/2, 2/3, 3/4, 4/5, 4/6, 5/7, 6/8.
    pub dynamic_schedule: Option<bool>,
    /// `weighted` or `modified`, for the baselines and double_threshold_assignment.
    pub statistic: Option<String>,
    /// Samples considered by the baselines (1 to 64; default 1, 5 for k-NN).
    #[schema(minimum = 1, maximum = 64)]
    pub window: Option<u32>,
    /// k-NN: mutual nearest neighbours in at least k of the window (default 3).
    #[schema(minimum = 1, maximum = 64)]
    pub k: Option<u32>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LrRule {
    /// Second threshold L, 1 ≤ l ≤ r.
    #[schema(example = 6, minimum = 1, maximum = 128)]
    pub l: u32,
    /// Window R, 1 ≤ r ≤ 128.
    #[schema(example = 8, minimum = 1, maximum = 128)]
    pub r: u32,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MotionModel {
    /// `constant_velocity` (the default).
    pub kind: Option<String>,
    /// `dwna` (needs sigma_a_mps2), `cwna` (needs q_m2ps3) or `velocity_proportional`
    /// (seed 000 eqs. 24 and 26, factor default 0.05).
    #[schema(example = "dwna")]
    pub process_noise: Option<String>,
    #[schema(example = 2.0)]
    pub sigma_a_mps2: Option<f64>,
    pub q_m2ps3: Option<f64>,
    pub factor: Option<f64>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Alignment {
    /// `grid` (default): a fusion-time grid, each track brought to each
    /// instant from its latest sample at or before it (predicted with the
    /// motion model; without one, along its velocity without process noise,
    /// or held when the state has no velocities). `predict` / `nearest`:
    /// clusters of report times no wider than `tolerance_s`, the latest
    /// sample of each track predicted / as reported. `interpolate`: linear
    /// interpolation at the cluster instants (batch only).
    #[schema(example = "grid")]
    pub mode: Option<String>,
    /// `predict`, `nearest`, `interpolate`: widest spread of report times
    /// merged into one instant (default 0.5 s). Sessions, every mode: how
    /// long after an instant reports for it may still arrive before it
    /// closes.
    #[schema(example = 0.5)]
    pub tolerance_s: Option<f64>,
    /// `interpolate`: the widest gap between two samples interpolated across
    /// (default 10 s); a track is never extrapolated.
    pub max_gap_s: Option<f64>,
    /// `grid`: the fusion period in seconds (default: the longest scan
    /// period of the nodes, each estimated as the median interval between
    /// consecutive samples of its tracks).
    pub period_s: Option<f64>,
    /// `grid`: instants are `epoch_s + k·period_s` (default 0).
    pub epoch_s: Option<f64>,
    /// `grid`: the oldest a sample may be at an instant (default 1.5 scan
    /// periods of its node, so a missed scan makes a track absent).
    pub max_staleness_s: Option<f64>,
}

/// What alignment did: test `node_pairs_without_common_instant` and
/// `tracks_without_partner_instant` to know whether the nodes could meet.
#[derive(Debug, Serialize, ToSchema)]
pub struct AlignmentReport {
    /// `grid`, `predict`, `nearest` or `interpolate`.
    pub mode: &'static str,
    /// `grid`: the fusion period used (absent: no track had two samples, so
    /// one instant at the latest sample time).
    pub period_s: Option<f64>,
    /// `grid`: the period was estimated from the data.
    pub period_estimated: bool,
    pub epoch_s: Option<f64>,
    pub tolerance_s: Option<f64>,
    pub max_gap_s: Option<f64>,
    pub nodes: Vec<NodeAlignment>,
    pub instants: usize,
    /// Node pairs (both with tracks) that share no instant where both hold a track.
    pub node_pairs_without_common_instant: usize,
    /// Tracks present at no instant where another node holds a track.
    pub tracks_without_partner_instant: usize,
    pub tracks: usize,
    /// Estimates brought across a gap to an instant (predicted, held or interpolated).
    pub brought: usize,
    /// Samples not used: a later sample of the same track came first.
    pub unused_samples: usize,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct NodeAlignment {
    pub node: String,
    pub tracks: usize,
    /// Median interval between consecutive samples of the node's tracks.
    pub scan_period_s: Option<f64>,
    /// `grid`: the oldest a sample may be at an instant.
    pub max_staleness_s: Option<f64>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Node {
    #[schema(example = "radar-1")]
    pub id: String,
    pub tracks: Vec<LocalTrack>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LocalTrack {
    #[schema(example = "17")]
    pub id: String,
    pub samples: Vec<TrackSample>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TrackSample {
    /// Time in seconds.
    #[schema(example = 0.0)]
    pub t: f64,
    #[schema(example = json!([1000.0, 100.0, 2000.0, -50.0]))]
    pub state: Vec<f64>,
    /// Symmetric positive definite, row-major nested arrays.
    #[schema(value_type = Vec<Vec<f64>>)]
    pub covariance: Rows,
    /// The local filter's gain K (state × measurement), optional.
    #[schema(value_type = Option<Vec<Vec<f64>>>)]
    pub gain: Option<Rows>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct CorrelateTracksResponse {
    pub method: String,
    /// `weighted` or `modified`.
    pub statistic: &'static str,
    pub thresholds: Thresholds,
    /// `reported`, `recomputed` (from the motion model and covariances) or `not_used`.
    pub gains: &'static str,
    /// The common instants after alignment.
    pub instants: Vec<f64>,
    pub alignment: AlignmentReport,
    /// Every pair with at least one sample inside the first threshold in its
    /// current cycle or window, or correlated, or a trial system track.
    pub pairs: Vec<PairResult>,
    /// Pairs not listed: never inside the first threshold in their current window.
    pub omitted_pairs: u64,
    pub unpaired: Vec<UnpairedTracks>,
    pub system_tracks: Vec<SystemTrack>,
    /// Correlations refused because they would put two tracks of one node in one group.
    pub conflicts: Vec<Conflict>,
    pub timing: CorrelateTiming,
    pub warnings: Vec<String>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Thresholds {
    pub alpha: f64,
    /// First threshold δ: the χ² quantile with `dof` degrees of freedom (eq. 14).
    pub delta: f64,
    pub dof: u32,
    pub rule: Option<RuleOut>,
    pub schedule: Vec<RuleOut>,
    pub window: Option<u32>,
    pub k: Option<u32>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct RuleOut {
    pub l: u32,
    pub r: u32,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct TrackRef {
    pub node: String,
    pub track: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct PairResult {
    pub a: TrackRef,
    pub b: TrackRef,
    /// `correlated`, `not_correlated` or `undecided`.
    pub decision: &'static str,
    /// `testing`, `threshold`, `early_decision`, `early_stop`, `ambiguity_max_m`,
    /// `ambiguity_min_mean_statistic`, `ambiguity_lost`, `assignment`, `below_rule`,
    /// `revoked`, `gate`, `nearest_neighbour`, `conflict`, `k_of_n`.
    pub reason: &'static str,
    /// A trial system track (eq. 21): undecided but provisionally paired.
    pub trial: bool,
    /// Correlation quality m (eq. 11).
    pub m: u32,
    /// Departure quality C (eq. 15).
    pub c: u32,
    pub samples: u32,
    pub mean_statistic: Option<f64>,
    pub last_statistic: Option<f64>,
    /// Time of the decision, when decided.
    pub decided_at_t: Option<f64>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct UnpairedTracks {
    pub node: String,
    pub tracks: Vec<String>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct SystemTrack {
    pub id: u32,
    pub members: Vec<TrackRef>,
    pub t: Option<f64>,
    /// Fused state in the request's state_layout.
    pub state: Vec<f64>,
    pub covariance: Vec<Vec<f64>>,
    /// `bar_shalom_campo`, `covariance_intersection`, `single` or `none`.
    pub fusion: &'static str,
    /// A trial system track (seed 000 eq. 21): its pairs are still
    /// undecided; it is output as the paper does, flagged.
    pub trial: bool,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Conflict {
    pub a: TrackRef,
    pub b: TrackRef,
    /// The node that would have held two tracks in one group, and those tracks.
    pub node: String,
    pub tracks: Vec<String>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct CorrelateTiming {
    pub compute_us: f64,
    pub align_us: f64,
    pub correlate_us: f64,
    pub fuse_us: f64,
}

/// Correlates the local tracks of M ≥ 1 nodes (seed 000 and classic baselines).
#[utoipa::path(
    post,
    path = "/v1/correlation/tracks",
    tag = "correlation",
    request_body = CorrelateTracksRequest,
    responses(
        (status = 200, description = "Pair decisions, groups and system tracks", body = CorrelateTracksResponse),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn correlate(
    State(_state): State<AppState>,
    body: JsonBody<CorrelateTracksRequest>,
) -> Result<Response, Problem> {
    body.compute(correlate_on_lane).await
}

pub fn correlate_on_lane(req: CorrelateTracksRequest) -> Result<CorrelateTracksResponse, Problem> {
    let nodes = req
        .nodes
        .into_iter()
        .map(|n| svc::NodeInput {
            id: Some(n.id),
            tracks: n
                .tracks
                .into_iter()
                .map(|t| svc::TrackInput {
                    id: Some(t.id),
                    samples: t.samples.into_iter().map(sample_in).collect(),
                })
                .collect(),
        })
        .collect();
    let input = config_in(
        req.state_layout,
        req.method,
        req.motion_model,
        req.alignment,
        req.measurement_matrix,
        nodes,
        req.pruning,
        req.fuse,
    );
    let out = svc::correlate(input)?;
    Ok(response(out))
}

pub(super) fn sample_in(s: TrackSample) -> svc::SampleInput {
    svc::SampleInput {
        t: Some(s.t),
        state: s.state,
        covariance: s.covariance,
        gain: s.gain,
    }
}

/// The service input of a correlation configuration (batch or session).
#[allow(clippy::too_many_arguments)]
pub(super) fn config_in(
    state_layout: Vec<String>,
    method: CorrelationMethod,
    motion_model: Option<MotionModel>,
    alignment: Option<Alignment>,
    measurement_matrix: Option<Vec<Vec<f64>>>,
    nodes: Vec<svc::NodeInput>,
    pruning: Option<String>,
    fuse: Option<bool>,
) -> svc::CorrelateInput {
    svc::CorrelateInput {
        state_layout,
        method: Some(svc::MethodInput {
            kind: Some(method.kind),
            alpha: method.alpha,
            rule: method.rule.map(rule_in),
            schedule: method
                .schedule
                .map(|s| s.into_iter().map(rule_in).collect()),
            dynamic_schedule: method.dynamic_schedule,
            statistic: method.statistic,
            window: method.window,
            k: method.k,
        }),
        motion_model: motion_model.map(|m| svc::MotionModelInput {
            kind: m.kind,
            process_noise: m.process_noise,
            sigma_a_mps2: m.sigma_a_mps2,
            q_m2ps3: m.q_m2ps3,
            factor: m.factor,
        }),
        alignment: alignment.map(|a| svc::AlignmentInput {
            mode: a.mode,
            tolerance_s: a.tolerance_s,
            max_gap_s: a.max_gap_s,
            period_s: a.period_s,
            epoch_s: a.epoch_s,
            max_staleness_s: a.max_staleness_s,
        }),
        measurement_matrix,
        nodes,
        pruning,
        fuse,
    }
}

fn rule_in(r: LrRule) -> svc::RuleInput {
    svc::RuleInput {
        l: Some(r.l),
        r: Some(r.r),
    }
}

pub(super) fn pair_result(p: svc::PairOutput) -> PairResult {
    PairResult {
        a: track_ref(p.a),
        b: track_ref(p.b),
        decision: decision_name(p.decision),
        reason: reason_name(p.reason),
        trial: p.trial,
        m: p.m,
        c: p.c,
        samples: p.samples,
        mean_statistic: finite(p.mean_statistic),
        last_statistic: finite(p.last_statistic),
        decided_at_t: p.decided_at,
    }
}

pub(super) fn system_track(g: svc::GroupOutput) -> SystemTrack {
    SystemTrack {
        id: g.id,
        members: g.members.into_iter().map(track_ref).collect(),
        t: finite(g.t),
        state: g.state,
        covariance: g.covariance,
        fusion: fusion_name(g.fusion),
        trial: g.trial,
    }
}

pub(super) fn track_ref(t: svc::TrackName) -> TrackRef {
    TrackRef {
        node: t.node,
        track: t.track,
    }
}

pub(super) fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

fn alignment_report(a: svc::AlignmentReport) -> AlignmentReport {
    AlignmentReport {
        mode: a.mode,
        period_s: a.period_s,
        period_estimated: a.period_estimated,
        epoch_s: a.epoch_s,
        tolerance_s: a.tolerance_s,
        max_gap_s: a.max_gap_s,
        nodes: a
            .nodes
            .into_iter()
            .map(|n| NodeAlignment {
                node: n.node,
                tracks: n.tracks,
                scan_period_s: n.scan_period_s,
                max_staleness_s: n.max_staleness_s,
            })
            .collect(),
        instants: a.instants,
        node_pairs_without_common_instant: a.node_pairs_without_common_instant,
        tracks_without_partner_instant: a.tracks_without_partner_instant,
        tracks: a.tracks,
        brought: a.brought,
        unused_samples: a.unused_samples,
    }
}

fn response(out: svc::CorrelateOutput) -> CorrelateTracksResponse {
    CorrelateTracksResponse {
        method: out.method,
        statistic: statistic_name(out.statistic),
        thresholds: Thresholds {
            alpha: out.thresholds.alpha,
            delta: out.thresholds.delta,
            dof: out.thresholds.dof,
            rule: out.thresholds.rule.map(|(l, r)| RuleOut { l, r }),
            schedule: out
                .thresholds
                .schedule
                .into_iter()
                .map(|(l, r)| RuleOut { l, r })
                .collect(),
            window: out.thresholds.window,
            k: out.thresholds.k,
        },
        gains: out.gains,
        instants: out.instants,
        alignment: alignment_report(out.alignment),
        pairs: out.pairs.into_iter().map(pair_result).collect(),
        omitted_pairs: out.omitted_pairs,
        unpaired: out
            .unpaired
            .into_iter()
            .map(|(node, tracks)| UnpairedTracks { node, tracks })
            .collect(),
        system_tracks: out.groups.into_iter().map(system_track).collect(),
        conflicts: out
            .conflicts
            .into_iter()
            .map(|c| Conflict {
                a: track_ref(c.a),
                b: track_ref(c.b),
                node: c.node,
                tracks: vec![c.tracks.0, c.tracks.1],
            })
            .collect(),
        timing: CorrelateTiming {
            compute_us: out.timing.compute_us,
            align_us: out.timing.align_us,
            correlate_us: out.timing.correlate_us,
            fuse_us: out.timing.fuse_us,
        },
        warnings: out.warnings,
    }
}
