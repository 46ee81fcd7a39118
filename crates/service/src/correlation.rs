//! Batch track-to-track correlation (seed 000 and the classic baselines):
//! validates a request of M ≥ 1 nodes' local tracks, aligns them to common
//! instants, correlates every node pair with `algo::correlation::engine`,
//! groups the pairs consistently across nodes and fuses each group into a
//! system track.
//!
//! Alignment rule: all report times are sorted and cut into clusters no wider
//! than the tolerance; each cluster is one instant, at the cluster's latest
//! time. A track takes its latest sample inside the cluster and, in `predict`
//! mode, is predicted forward to the instant with the motion model (F, Q);
//! in `nearest` mode it is used as reported. A track without a sample in a
//! cluster is absent at that instant. In `interpolate` mode a track is present
//! at every instant between two of its samples at most `max_gap_s` apart,
//! with state and covariance interpolated linearly; it is never extrapolated.

use std::{collections::HashMap, time::Instant};

use nalgebra::{DMatrix, DVector};

use super::{Ids, Increasing, Interval, Rows, ServiceError, Violations, at, micros_since};
use algo::{
    AlgoError,
    correlation::{
        align::{self, Estimate},
        engine::{
            self, Config, Decision, Method, PairCorrelator, PairReport, Pruning, Reason,
            Resolution, RuleSpec, Statistic,
        },
        fusion,
        grouping::{self, Link},
        rules::LrRule,
        scene::{Scene, Track},
    },
    motion::{ConstantVelocity, MotionModel, ProcessNoise},
};

/// Most nodes in one request.
pub const MAX_NODES: usize = 64;
/// Most samples (over all tracks and nodes) in one request.
pub const MAX_SAMPLES: usize = 4_000_000;
/// Default significance level of the first threshold.
pub const DEFAULT_ALPHA: f64 = 0.05;
/// Default alignment tolerance.
pub const DEFAULT_TOLERANCE_S: f64 = 0.5;

/// A correlation request as a client sent it, before validation.
#[derive(Debug, Clone, Default)]
pub struct CorrelateInput {
    pub state_layout: Vec<String>,
    pub method: Option<MethodInput>,
    pub motion_model: Option<MotionModelInput>,
    pub alignment: Option<AlignmentInput>,
    /// H of the local filters, needed to turn reported gains K into I − K H.
    pub measurement_matrix: Option<Vec<Vec<f64>>>,
    pub nodes: Vec<NodeInput>,
    /// `grid` (default) or `none` (brute force over all pairs; same result).
    pub pruning: Option<String>,
    /// Fuse correlated groups into system tracks (default true).
    pub fuse: Option<bool>,
}

#[derive(Debug, Clone, Default)]
pub struct MethodInput {
    pub kind: Option<String>,
    pub alpha: Option<f64>,
    pub rule: Option<RuleInput>,
    pub schedule: Option<Vec<RuleInput>>,
    pub dynamic_schedule: Option<bool>,
    pub statistic: Option<String>,
    pub window: Option<u32>,
    pub k: Option<u32>,
}

#[derive(Debug, Clone, Default)]
pub struct RuleInput {
    pub l: Option<u32>,
    pub r: Option<u32>,
}

#[derive(Debug, Clone, Default)]
pub struct MotionModelInput {
    /// Only `constant_velocity` for now.
    pub kind: Option<String>,
    /// `dwna`, `cwna` or `velocity_proportional`.
    pub process_noise: Option<String>,
    pub sigma_a_mps2: Option<f64>,
    pub q_m2ps3: Option<f64>,
    pub factor: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct AlignmentInput {
    /// `grid` (default), `predict`, `interpolate` or `nearest`.
    pub mode: Option<String>,
    /// `interpolate`: the widest gap between two samples interpolated across.
    pub max_gap_s: Option<f64>,
    /// `predict`, `nearest`, `interpolate`: widest spread of report times
    /// merged into one instant. Sessions (every mode): how long after an
    /// instant reports for it may still arrive.
    pub tolerance_s: Option<f64>,
    /// `grid`: the fusion period (default: the longest scan period of the
    /// nodes, estimated from the data).
    pub period_s: Option<f64>,
    /// `grid`: instants are `epoch_s + k·period_s` (default 0).
    pub epoch_s: Option<f64>,
    /// `grid`: the oldest a sample may be at an instant (default 1.5 scan
    /// periods of its node, estimated from the data).
    pub max_staleness_s: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct NodeInput {
    pub id: Option<String>,
    pub tracks: Vec<TrackInput>,
}

#[derive(Debug, Clone, Default)]
pub struct TrackInput {
    pub id: Option<String>,
    pub samples: Vec<SampleInput>,
}

#[derive(Debug, Clone, Default)]
pub struct SampleInput {
    pub t: Option<f64>,
    pub state: Vec<f64>,
    pub covariance: Rows,
    pub gain: Option<Rows>,
}

/// The method names of the API.
pub const METHODS: &[&str] = &[
    "weighted",
    "modified",
    "independent_double_threshold",
    "dependent_double_threshold",
    "double_threshold_assignment",
    "nearest_neighbour",
    "k_nearest_neighbour",
    "global_assignment",
];

/// The result of a correlation request.
#[derive(Debug, Clone, PartialEq)]
pub struct CorrelateOutput {
    pub method: String,
    pub statistic: Statistic,
    pub thresholds: Thresholds,
    /// `reported`, `recomputed` or `not_used` (weighted statistic).
    pub gains: &'static str,
    pub instants: Vec<f64>,
    pub alignment: AlignmentReport,
    pub pairs: Vec<PairOutput>,
    /// Pairs never within the gate in their current window (not listed).
    pub omitted_pairs: u64,
    pub unpaired: Vec<(String, Vec<String>)>,
    pub groups: Vec<GroupOutput>,
    pub conflicts: Vec<ConflictOutput>,
    pub timing: CorrelateTiming,
    pub warnings: Vec<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Thresholds {
    pub alpha: f64,
    /// The first threshold δ, χ² quantile with `dof` degrees of freedom.
    pub delta: f64,
    pub dof: u32,
    pub rule: Option<(u32, u32)>,
    pub schedule: Vec<(u32, u32)>,
    pub window: Option<u32>,
    pub k: Option<u32>,
}

/// A track named by its node id and track id.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct TrackName {
    pub node: String,
    pub track: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PairOutput {
    pub a: TrackName,
    pub b: TrackName,
    pub decision: Decision,
    pub reason: Reason,
    pub trial: bool,
    pub m: u32,
    pub c: u32,
    pub samples: u32,
    pub mean_statistic: f64,
    pub last_statistic: f64,
    pub decided_at: Option<f64>,
}

/// How a system track's estimate was formed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusionKind {
    BarShalomCampo,
    CovarianceIntersection,
    Single,
    None,
}

#[derive(Debug, Clone, PartialEq)]
pub struct GroupOutput {
    pub id: u32,
    pub members: Vec<TrackName>,
    pub t: f64,
    /// In the request's state layout.
    pub state: Vec<f64>,
    pub covariance: Vec<Vec<f64>>,
    pub fusion: FusionKind,
    /// A trial system track (eq. 21): its pairs are undecided.
    pub trial: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ConflictOutput {
    pub a: TrackName,
    pub b: TrackName,
    pub node: String,
    pub tracks: (String, String),
}

#[derive(Debug, Clone, PartialEq)]
pub struct CorrelateTiming {
    pub compute_us: f64,
    pub align_us: f64,
    pub correlate_us: f64,
    pub fuse_us: f64,
}

/// Cross-covariance of each correlated pair ((node, track), (node, track)) at
/// its last common instant: (instant index, row-major P_ab).
pub(super) type CrossCovariances = HashMap<((usize, usize), (usize, usize)), (usize, Vec<f64>)>;

/// How a track's samples are carried to the common instants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum AlignMode {
    /// A fusion-time grid (`algo::correlation::align`): each track brought
    /// from its latest sample at or before each instant.
    Grid {
        period: Option<f64>,
        epoch: f64,
        max_staleness: Option<f64>,
    },
    /// The latest sample of the cluster, predicted forward with the model.
    Predict,
    /// The latest sample of the cluster, as reported.
    Nearest,
    /// Linear interpolation between the samples around the instant, at most
    /// this many seconds apart; never extrapolated.
    Interpolate { max_gap: f64 },
}

/// Default widest gap interpolated across.
pub const DEFAULT_MAX_GAP_S: f64 = 10.0;

/// A validated request.
pub(super) struct Plan {
    pub(super) layout: Layout,
    pub(super) method_name: String,
    pub(super) config: Config,
    pub(super) model: Option<ConstantVelocity>,
    /// The model that brings samples to instants: the motion model, or
    /// without one a constant-velocity model without process noise when the
    /// layout has velocities (positions are then held as reported).
    pub(super) align_model: Option<ConstantVelocity>,
    pub(super) alignment: AlignMode,
    pub(super) tolerance: f64,
    pub(super) h: Option<DMatrix<f64>>,
    pub(super) fuse: bool,
}

/// The request's state layout and its permutation to the canonical
/// interleaved order `[x, vx, y, vy(, z, vz)]` or `[x, y(, z)]`.
#[derive(Debug, Clone)]
pub(super) struct Layout {
    /// canonical[i] = index in the request's layout.
    pub(super) from_request: Vec<usize>,
    pub(super) dim: usize,
    pub(super) axes: usize,
    pub(super) has_velocity: bool,
}

impl Layout {
    fn parse(names: &[String]) -> Result<Self, String> {
        let canon_cv: &[&[&str]] = &[&["x", "vx", "y", "vy"], &["x", "vx", "y", "vy", "z", "vz"]];
        let canon_pos: &[&[&str]] = &[&["x", "y"], &["x", "y", "z"]];
        let mut sorted: Vec<&str> = names.iter().map(String::as_str).collect();
        sorted.sort_unstable();
        let mut dedup = sorted.clone();
        dedup.dedup();
        if dedup.len() != sorted.len() {
            return Err("names a component twice".into());
        }
        for (canon, has_velocity) in [(canon_cv, true), (canon_pos, false)] {
            for c in canon {
                let mut want: Vec<&str> = c.to_vec();
                want.sort_unstable();
                if want == sorted {
                    let from_request = c
                        .iter()
                        .map(|n| names.iter().position(|m| m == n).expect("same set"))
                        .collect();
                    let axes = if has_velocity { c.len() / 2 } else { c.len() };
                    return Ok(Self {
                        from_request,
                        dim: c.len(),
                        axes,
                        has_velocity,
                    });
                }
            }
        }
        Err(
            "must be a permutation of [x, vx, y, vy], [x, vx, y, vy, z, vz], [x, y] or [x, y, z]"
                .into(),
        )
    }

    /// Position indices in the canonical order.
    pub(super) fn positions(&self) -> Vec<usize> {
        if self.has_velocity {
            (0..self.axes).map(|a| 2 * a).collect()
        } else {
            (0..self.axes).collect()
        }
    }

    pub(super) fn vector_to_canonical(&self, v: &[f64]) -> Vec<f64> {
        self.from_request.iter().map(|&i| v[i]).collect()
    }

    pub(super) fn matrix_to_canonical(&self, m: &Rows) -> Vec<f64> {
        let n = self.dim;
        let m = m.values();
        let mut out = vec![0.0; n * n];
        for (i, &ri) in self.from_request.iter().enumerate() {
            for (j, &rj) in self.from_request.iter().enumerate() {
                out[i * n + j] = m[ri * n + rj];
            }
        }
        out
    }

    pub(super) fn vector_to_request(&self, v: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.dim];
        for (i, &ri) in self.from_request.iter().enumerate() {
            out[ri] = v[i];
        }
        out
    }

    pub(super) fn matrix_to_request(&self, m: &DMatrix<f64>) -> Vec<Vec<f64>> {
        let mut out = vec![vec![0.0; self.dim]; self.dim];
        for (i, &ri) in self.from_request.iter().enumerate() {
            for (j, &rj) in self.from_request.iter().enumerate() {
                out[ri][rj] = m[(i, j)];
            }
        }
        out
    }
}

/// Correlates the request's nodes.
pub fn correlate(input: CorrelateInput) -> Result<CorrelateOutput, ServiceError> {
    let start = Instant::now();
    let Parsed { plan, nodes } = validate(&input)?;
    let dim = plan.layout.dim;

    // Alignment.
    let t_align = Instant::now();
    let tolerance_given = input
        .alignment
        .as_ref()
        .is_some_and(|a| a.tolerance_s.is_some());
    drop(input);
    let mut node_ids = Vec::with_capacity(nodes.len());
    let mut track_ids = Vec::with_capacity(nodes.len());
    let mut est = Vec::with_capacity(nodes.len());
    for n in nodes {
        node_ids.push(n.id);
        track_ids.push(n.track_ids);
        est.push(n.tracks);
    }
    let (scene, gains_reported, mut warnings, alignment) =
        align(est, &node_ids, tolerance_given, &plan)?;
    let align_us = micros_since(t_align);

    // Correlation of every node pair.
    let t_corr = Instant::now();
    let name = |node: usize, track: usize| TrackName {
        node: node_ids[node].clone(),
        track: track_ids[node][track].clone(),
    };
    let model_ref: Option<&dyn MotionModel> = plan.model.as_ref().map(|m| m as &dyn MotionModel);
    let mut pairs = Vec::new();
    let mut links = Links::default();
    let mut omitted = 0u64;
    let mut delta = f64::NAN;
    let mut singular = 0usize;
    let n_nodes = scene.nodes().len();
    for na in 0..n_nodes {
        for nb in na + 1..n_nodes {
            let mut correlator = PairCorrelator::new(&scene, na, nb, &plan.config, model_ref)
                .map_err(|e| Violations::from_param("method.", e))?;
            delta = correlator.delta();
            correlator.run();
            singular += correlator.singular_tests;
            let total = (scene.nodes()[na].len() * scene.nodes()[nb].len()) as u64;
            let reports = correlator.reports();
            let mut listed = 0u64;
            for r in reports {
                links.collect(&r, na, nb);
                if r.m >= 1 || r.decision == Decision::Correlated || r.trial {
                    listed += 1;
                    pairs.push(pair_output(&r, name(na, r.a), name(nb, r.b)));
                }
            }
            omitted += total - listed;
        }
    }
    if singular > 0 {
        warnings.push(format!(
            "{singular} test(s) of the modified statistic had P_a + P_b − P_ab − P_ab' not \
             positive definite (the reported covariances, gains and motion model are not \
             consistent with one another); the weighted statistic was used for them"
        ));
    }
    let correlate_us = micros_since(t_corr);

    // System tracks.
    let t_fuse = Instant::now();
    let (grouping, grouped, groups) = system_tracks(&scene, &plan, &links, name);
    let fuse_us = micros_since(t_fuse);

    let unpaired = (0..n_nodes)
        .map(|n| {
            let ids = (0..scene.nodes()[n].len())
                .filter(|&t| !grouped.contains(&(n, t)))
                .map(|t| track_ids[n][t].clone())
                .collect();
            (node_ids[n].clone(), ids)
        })
        .collect();
    let conflicts = grouping
        .conflicts
        .iter()
        .map(|c| ConflictOutput {
            a: name(c.link.a.0, c.link.a.1),
            b: name(c.link.b.0, c.link.b.1),
            node: node_ids[c.node].clone(),
            tracks: (
                track_ids[c.node][c.tracks.0].clone(),
                track_ids[c.node][c.tracks.1].clone(),
            ),
        })
        .collect();
    if n_nodes < 2 {
        warnings.push("only one node: there is nothing to correlate".into());
    }

    let (rule, schedule, window, k) = match &plan.config.method {
        Method::DoubleThreshold { rules, .. } => match rules {
            RuleSpec::Fixed(r) => (Some((r.l(), r.r())), Vec::new(), None, None),
            RuleSpec::Schedule(s) => (None, s.iter().map(|r| (r.l(), r.r())).collect(), None, None),
        },
        Method::NearestNeighbour { window } | Method::GlobalAssignment { window } => {
            (None, Vec::new(), Some(*window as u32), None)
        }
        Method::KNearestNeighbour { k, window } => {
            (None, Vec::new(), Some(*window as u32), Some(*k as u32))
        }
    };
    if delta.is_nan() {
        delta = algo::gating::chi2_threshold(dim, plan.config.alpha)
            .map_err(|e| ServiceError::Internal(e.to_string()))?;
    }
    Ok(CorrelateOutput {
        method: plan.method_name.clone(),
        statistic: plan.config.statistic,
        thresholds: Thresholds {
            alpha: plan.config.alpha,
            delta,
            dof: dim as u32,
            rule,
            schedule,
            window,
            k,
        },
        gains: match plan.config.statistic {
            Statistic::Weighted => "not_used",
            Statistic::Modified if gains_reported => "reported",
            Statistic::Modified => "recomputed",
        },
        instants: scene.times().to_vec(),
        alignment,
        pairs,
        omitted_pairs: omitted,
        unpaired,
        groups,
        conflicts,
        timing: CorrelateTiming {
            compute_us: micros_since(start),
            align_us,
            correlate_us,
            fuse_us,
        },
        warnings,
    })
}

/// The correlated and trial pairs of every node pair, as grouping links,
/// with the cross-covariances of the correlated ones for the fusion.
#[derive(Debug, Default)]
pub(super) struct Links {
    pub(super) correlated: Vec<Link>,
    /// Trial system tracks (eq. 21): undecided pairs provisionally paired.
    pub(super) trial: Vec<Link>,
    pub(super) cross: CrossCovariances,
}

impl Links {
    /// Records pair report `r` of nodes `na`, `nb`.
    pub(super) fn collect(&mut self, r: &PairReport, na: usize, nb: usize) {
        let link = Link {
            a: (na, r.a),
            b: (nb, r.b),
            m: r.m,
            mean_statistic: r.mean_statistic,
        };
        if r.decision == Decision::Correlated {
            self.correlated.push(link);
            if let Some(c) = &r.cross_covariance {
                self.cross
                    .insert(((na, r.a), (nb, r.b)), (r.last_common, c.clone()));
            }
        } else if r.trial {
            self.trial.push(link);
        }
    }
}

/// The system tracks: the groups of correlated tracks, then the trial
/// groups (trial pairs among tracks in no correlated group, flagged
/// `trial`), each fused at its latest well-covered instant. Returns the
/// correlated grouping too (its conflicts), and every track in a group.
pub(super) fn system_tracks(
    scene: &Scene,
    plan: &Plan,
    links: &Links,
    name: impl Fn(usize, usize) -> TrackName,
) -> (
    grouping::Grouping,
    std::collections::HashSet<(usize, usize)>,
    Vec<GroupOutput>,
) {
    let dim = plan.layout.dim;
    let grouping = grouping::group(&links.correlated);
    let mut grouped: std::collections::HashSet<(usize, usize)> =
        grouping.groups.iter().flatten().copied().collect();
    let free: Vec<Link> = links
        .trial
        .iter()
        .filter(|l| !grouped.contains(&l.a) && !grouped.contains(&l.b))
        .cloned()
        .collect();
    let trial = grouping::group(&free);
    grouped.extend(trial.groups.iter().flatten().copied());
    let all = grouping
        .groups
        .iter()
        .map(|g| (g, false))
        .chain(trial.groups.iter().map(|g| (g, true)));
    let groups = all
        .enumerate()
        .map(|(id, (members, is_trial))| {
            let fused = if plan.fuse {
                fuse_group(scene, members, &links.cross, dim)
            } else {
                None
            };
            let (t, state, covariance, fusion) = match fused {
                Some((k, f, kind)) => (
                    scene.time(k),
                    plan.layout.vector_to_request(f.x.as_slice()),
                    plan.layout.matrix_to_request(&f.p),
                    kind,
                ),
                None => (f64::NAN, Vec::new(), Vec::new(), FusionKind::None),
            };
            GroupOutput {
                id: id as u32,
                members: members.iter().map(|&(n, t)| name(n, t)).collect(),
                t,
                state,
                covariance,
                fusion,
                trial: is_trial,
            }
        })
        .collect();
    (grouping, grouped, groups)
}

pub(super) fn pair_output(r: &PairReport, a: TrackName, b: TrackName) -> PairOutput {
    PairOutput {
        a,
        b,
        decision: r.decision,
        reason: r.reason,
        trial: r.trial,
        m: r.m,
        c: r.c,
        samples: r.samples,
        mean_statistic: r.mean_statistic,
        last_statistic: r.last_statistic,
        decided_at: r.decided_time,
    }
}

/// Fuses a group at the latest instant where most of its members are present:
/// Bar-Shalom–Campo for two members with a known cross-covariance at that
/// instant, covariance intersection otherwise.
pub(super) fn fuse_group(
    scene: &Scene,
    members: &[(usize, usize)],
    cross: &CrossCovariances,
    dim: usize,
) -> Option<(usize, fusion::Fused, FusionKind)> {
    let count = |k: usize| {
        members
            .iter()
            .filter(|&&(n, t)| scene.track(n, t).is_present(k))
            .count()
    };
    let best = (scene.first()..scene.end())
        .rev()
        .max_by_key(|&k| (count(k), k))?;
    let present: Vec<(usize, usize)> = members
        .iter()
        .copied()
        .filter(|&(n, t)| scene.track(n, t).is_present(best))
        .collect();
    let est = |&(n, t): &(usize, usize)| {
        let tr = scene.track(n, t);
        (
            DVector::from_column_slice(tr.x(best, dim)),
            DMatrix::from_row_slice(dim, dim, tr.p(best, dim)),
        )
    };
    match present.as_slice() {
        [] => None,
        [one] => {
            let (x, p) = est(one);
            Some((
                best,
                fusion::Fused {
                    x,
                    p,
                    weights: Vec::new(),
                },
                FusionKind::Single,
            ))
        }
        [a, b] => {
            let (xa, pa) = est(a);
            let (xb, pb) = est(b);
            if let Some((k, c)) = cross.get(&(*a, *b))
                && *k == best
            {
                let p12 = DMatrix::from_row_slice(dim, dim, c);
                if let Ok(f) = fusion::bar_shalom_campo(&xa, &pa, &xb, &pb, &p12) {
                    return Some((best, f, FusionKind::BarShalomCampo));
                }
            }
            fusion::covariance_intersection(&[(xa, pa), (xb, pb)])
                .ok()
                .map(|f| (best, f, FusionKind::CovarianceIntersection))
        }
        many => {
            let list: Vec<_> = many.iter().map(est).collect();
            fusion::covariance_intersection(&list)
                .ok()
                .map(|f| (best, f, FusionKind::CovarianceIntersection))
        }
    }
}

/// The parsed configuration of a request, before its nodes.
struct ConfigParts {
    layout: Option<Layout>,
    kind: &'static str,
    config_method: Option<Method>,
    statistic: Statistic,
    alpha: f64,
    pruning: Pruning,
    model: Option<ConstantVelocity>,
    align_model: Option<ConstantVelocity>,
    mode: AlignMode,
    tolerance: f64,
    h: Option<DMatrix<f64>>,
}

/// The wire names of the alignment modes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ModeName {
    Grid,
    Predict,
    Interpolate,
    Nearest,
}

fn validate_config(input: &CorrelateInput, v: &mut Violations) -> ConfigParts {
    let layout = match Layout::parse(&input.state_layout) {
        Ok(l) => Some(l),
        Err(e) => {
            v.add("state_layout", e);
            None
        }
    };
    let method = input.method.clone().unwrap_or_default();
    let choices: Vec<(&str, &'static str)> = METHODS.iter().map(|&m| (m, m)).collect();
    let kind = v
        .one_of("method.kind", method.kind.as_deref(), None, &choices)
        .unwrap_or("");
    let alpha = v
        .number_or(
            "method.alpha",
            method.alpha,
            DEFAULT_ALPHA,
            Interval::OPEN_UNIT,
        )
        .unwrap_or(DEFAULT_ALPHA);
    let statistics = [
        ("weighted", Statistic::Weighted),
        ("modified", Statistic::Modified),
    ];
    let statistic = match (kind, method.statistic.as_deref()) {
        ("modified" | "dependent_double_threshold", None | Some("modified")) => Statistic::Modified,
        ("weighted" | "independent_double_threshold", None | Some("weighted")) => {
            Statistic::Weighted
        }
        (
            "modified" | "dependent_double_threshold" | "weighted" | "independent_double_threshold",
            Some(_),
        ) => {
            v.add(
                "method.statistic",
                format!("'{kind}' fixes the statistic; leave it out"),
            );
            Statistic::Weighted
        }
        (_, given) => v
            .one_of(
                "method.statistic",
                given,
                Some(Statistic::Weighted),
                &statistics,
            )
            .unwrap_or(Statistic::Weighted),
    };
    let rules = if method.rule.is_some()
        && (method.schedule.is_some() || method.dynamic_schedule == Some(true))
    {
        v.add(
            "method.schedule",
            "give either rule or a schedule, not both",
        );
        None
    } else if let Some(r) = &method.rule {
        super::rules::parse_rule(v, "method.rule", r.l, r.r).map(RuleSpec::Fixed)
    } else if let Some(s) = &method.schedule {
        let parsed: Vec<Option<LrRule>> = s
            .iter()
            .enumerate()
            .map(|(i, r)| super::rules::parse_rule(v, &format!("method.schedule[{i}]"), r.l, r.r))
            .collect();
        if s.is_empty() {
            v.add("method.schedule", "must hold at least one rule");
        }
        parsed
            .into_iter()
            .collect::<Option<Vec<_>>>()
            .map(RuleSpec::Schedule)
    } else if method.dynamic_schedule == Some(true) {
        Some(RuleSpec::Schedule(engine::default_schedule()))
    } else {
        LrRule::new(6, 8).ok().map(RuleSpec::Fixed)
    };
    let default_window = match kind {
        "k_nearest_neighbour" => 5,
        _ => 1,
    };
    let window = v
        .count_or("method.window", method.window, default_window, 1, 64)
        .unwrap_or(default_window) as usize;
    let k = method.k.unwrap_or(3) as usize;
    let one = LrRule::new(1, 1).ok();
    let config_method = match kind {
        "weighted" | "modified" => one.map(|one| Method::DoubleThreshold {
            rules: RuleSpec::Fixed(one),
            resolution: Resolution::Greedy,
        }),
        "independent_double_threshold" | "dependent_double_threshold" => {
            rules.map(|rules| Method::DoubleThreshold {
                rules,
                resolution: Resolution::Greedy,
            })
        }
        "double_threshold_assignment" => rules.map(|rules| Method::DoubleThreshold {
            rules,
            resolution: Resolution::Assignment,
        }),
        "nearest_neighbour" => Some(Method::NearestNeighbour { window }),
        "global_assignment" => Some(Method::GlobalAssignment { window }),
        "k_nearest_neighbour" => Some(Method::KNearestNeighbour { k, window }),
        _ => None,
    };
    if matches!(kind, "weighted" | "modified")
        && (method.rule.is_some() || method.schedule.is_some())
    {
        v.add(
            "method.rule",
            format!("'{kind}' is the classic 1/1 test; use independent_double_threshold or dependent_double_threshold for an L/R rule"),
        );
    }
    if method.k.is_some() {
        v.count_or("method.k", method.k, 3, 1, window as u32);
    }

    // Motion model.
    let model = match (&input.motion_model, &layout) {
        (None, _) | (_, None) => None,
        (Some(m), Some(layout)) => motion_model(v, m, layout),
    };
    if statistic == Statistic::Modified && input.motion_model.is_none() {
        v.add(
            "motion_model",
            "is required by the modified statistic (the cross-covariance recursion of eq. 13)",
        );
    }
    let alignment = input.alignment.clone().unwrap_or_default();
    let tolerance = v
        .number_or(
            "alignment.tolerance_s",
            alignment.tolerance_s,
            DEFAULT_TOLERANCE_S,
            Interval::NON_NEGATIVE,
        )
        .unwrap_or(DEFAULT_TOLERANCE_S);
    let grid_only = [
        ("alignment.period_s", alignment.period_s.is_some()),
        ("alignment.epoch_s", alignment.epoch_s.is_some()),
        (
            "alignment.max_staleness_s",
            alignment.max_staleness_s.is_some(),
        ),
    ];
    let modes = [
        ("grid", ModeName::Grid),
        ("predict", ModeName::Predict),
        ("interpolate", ModeName::Interpolate),
        ("nearest", ModeName::Nearest),
    ];
    let mode_name = v.one_of(
        "alignment.mode",
        alignment.mode.as_deref(),
        Some(ModeName::Grid),
        &modes,
    );
    let mode = match mode_name {
        Some(ModeName::Grid) => {
            let period = alignment
                .period_s
                .and_then(|p| v.within("alignment.period_s", p, Interval::POSITIVE));
            let epoch = v.number_or(
                "alignment.epoch_s",
                alignment.epoch_s,
                0.0,
                Interval::closed(-1e12, 1e12),
            );
            let max_staleness = alignment
                .max_staleness_s
                .and_then(|s| v.within("alignment.max_staleness_s", s, Interval::NON_NEGATIVE));
            AlignMode::Grid {
                period,
                epoch: epoch.unwrap_or(0.0),
                max_staleness,
            }
        }
        Some(ModeName::Predict) => {
            if input.motion_model.is_none() {
                v.add("alignment.mode", "predict needs a motion_model");
            }
            AlignMode::Predict
        }
        Some(ModeName::Interpolate) => AlignMode::Interpolate {
            max_gap: v
                .number_or(
                    "alignment.max_gap_s",
                    alignment.max_gap_s,
                    DEFAULT_MAX_GAP_S,
                    Interval::POSITIVE,
                )
                .unwrap_or(DEFAULT_MAX_GAP_S),
        },
        Some(ModeName::Nearest) | None => AlignMode::Nearest,
    };
    if !matches!(mode, AlignMode::Grid { .. }) {
        for (field, given) in grid_only {
            if given {
                v.add(
                    field,
                    "applies to the grid alignment only (alignment.mode: grid)",
                );
            }
        }
    }
    // Without a motion model, samples with velocities are extrapolated
    // along them (F without Q); positions alone are held.
    let align_model = match (&model, &layout) {
        (Some(m), _) => Some(*m),
        (None, Some(l)) if l.has_velocity => {
            ConstantVelocity::new(l.axes, ProcessNoise::Cwna { q: 0.0 }).ok()
        }
        _ => None,
    };
    let prunings = [("grid", Pruning::Grid), ("none", Pruning::None)];
    let pruning = v
        .one_of(
            "pruning",
            input.pruning.as_deref(),
            Some(Pruning::Grid),
            &prunings,
        )
        .unwrap_or(Pruning::Grid);

    // H for gains.
    let h = match (&input.measurement_matrix, &layout) {
        (Some(rows), Some(layout)) => {
            if rows.is_empty() {
                v.add("measurement_matrix", "must hold at least one row");
                None
            } else {
                v.matrix("measurement_matrix", rows, rows.len(), layout.dim)
                    .map(|_| {
                        let flat: Vec<f64> = rows
                            .iter()
                            .flat_map(|r| layout.vector_to_canonical(r))
                            .collect();
                        DMatrix::from_row_slice(rows.len(), layout.dim, &flat)
                    })
            }
        }
        _ => None,
    };

    ConfigParts {
        layout,
        kind,
        config_method,
        statistic,
        alpha,
        pruning,
        model,
        align_model,
        mode,
        tolerance,
        h,
    }
}

fn plan_of(parts: ConfigParts, fuse: Option<bool>) -> Option<Plan> {
    let ConfigParts {
        layout,
        kind,
        config_method,
        statistic,
        alpha,
        pruning,
        model,
        align_model,
        mode,
        tolerance,
        h,
    } = parts;
    Some(Plan {
        layout: layout?,
        method_name: kind.to_string(),
        config: Config {
            method: config_method?,
            statistic,
            alpha,
            pruning,
        },
        model,
        align_model,
        alignment: mode,
        tolerance,
        h,
        fuse: fuse.unwrap_or(true),
    })
}

/// Parses the configuration of a request without its nodes (a streaming
/// session's configuration).
pub(super) fn validate_plan(input: &CorrelateInput) -> Result<Plan, ServiceError> {
    let mut v = Violations::new();
    let parts = validate_config(input, &mut v);
    v.finish_with(plan_of(parts, input.fuse))
}

/// A node of a parsed request: its id, its tracks' ids and their samples
/// as estimates in canonical order.
struct ParsedNode {
    id: String,
    track_ids: Vec<String>,
    tracks: Vec<Vec<Estimate>>,
}

/// A parsed request.
struct Parsed {
    plan: Plan,
    nodes: Vec<ParsedNode>,
}

fn validate(input: &CorrelateInput) -> Result<Parsed, ServiceError> {
    let mut v = Violations::new();
    let parts = validate_config(input, &mut v);
    let has_h = input.measurement_matrix.is_some();
    // Nodes and tracks.
    v.count_within("nodes", input.nodes.len(), MAX_NODES, "node");
    let total: usize = input
        .nodes
        .iter()
        .flat_map(|n| n.tracks.iter())
        .map(|t| t.samples.len())
        .sum();
    v.at_most("nodes", total, MAX_SAMPLES, "samples");
    let mut node_ids = Ids::new();
    let mut nodes = Vec::with_capacity(input.nodes.len());
    for (ni, node) in input.nodes.iter().enumerate() {
        let node_id = node_ids.check(&mut v, node.id.as_deref(), ni, |i| format!("nodes[{i}].id"));
        let mut track_ids = Ids::new();
        let mut parsed = ParsedNode {
            id: node_id.unwrap_or_default().to_string(),
            track_ids: Vec::with_capacity(node.tracks.len()),
            tracks: Vec::with_capacity(node.tracks.len()),
        };
        for (ti, track) in node.tracks.iter().enumerate() {
            let tfield = |t: usize| format!("nodes[{ni}].tracks[{t}]");
            let id = track_ids.check(&mut v, track.id.as_deref(), ti, |t| {
                format!("{}.id", tfield(t))
            });
            if track.samples.is_empty() {
                v.add(
                    format!("{}.samples", tfield(ti)),
                    "must hold at least one sample",
                );
            }
            let mut times = Increasing::new();
            let mut samples = Vec::with_capacity(track.samples.len());
            for (si, s) in track.samples.iter().enumerate() {
                // Built only when a violation needs it (this loop runs per sample).
                let sfield = || format!("{}.samples[{si}]", tfield(ti));
                let t = times.next(
                    &mut v,
                    at(|| format!("{}.t", sfield())),
                    s.t,
                    Interval::FINITE,
                );
                let ok = parts.layout.as_ref().is_some_and(|layout| {
                    check_sample(&mut v, &sfield, s, layout, parts.h.as_ref(), has_h)
                });
                if let (Some(t), true, Some(layout)) = (t, ok, &parts.layout) {
                    samples.push(estimate(layout, parts.h.as_ref(), t, s));
                }
            }
            parsed.track_ids.push(id.unwrap_or_default().to_string());
            parsed.tracks.push(samples);
        }
        nodes.push(parsed);
    }
    let plan = plan_of(parts, input.fuse);
    v.finish_with(plan.map(|plan| Parsed { plan, nodes }))
}

/// The checks of one reported sample besides its time: state length and
/// finiteness, covariance shape and definiteness, gain shape. `sfield`
/// builds the sample's field path. Answers whether the sample is valid.
pub(super) fn check_sample(
    v: &mut Violations,
    sfield: &dyn Fn() -> String,
    s: &SampleInput,
    layout: &Layout,
    h: Option<&DMatrix<f64>>,
    has_h: bool,
) -> bool {
    let n = layout.dim;
    let state = v.vector(at(|| format!("{}.state", sfield())), &s.state, n);
    let covariance = v.covariance(at(|| format!("{}.covariance", sfield())), &s.covariance, n);
    let gain = match (&s.gain, h) {
        (None, _) => true,
        (Some(_), None) if !has_h => {
            v.add(
                format!("{}.gain", sfield()),
                "a gain needs the request's measurement_matrix H",
            );
            false
        }
        // H was given but is invalid: its own violation says so.
        (Some(_), None) => false,
        (Some(g), Some(h)) => v
            .matrix(at(|| format!("{}.gain", sfield())), g, n, h.nrows())
            .is_some(),
    };
    state && covariance && gain
}

fn motion_model(
    v: &mut Violations,
    m: &MotionModelInput,
    layout: &Layout,
) -> Option<ConstantVelocity> {
    v.one_of(
        "motion_model.kind",
        m.kind.as_deref(),
        Some(()),
        &[("constant_velocity", ())],
    )?;
    if !layout.has_velocity {
        v.add(
            "motion_model",
            "a constant-velocity model needs velocities in state_layout",
        );
        return None;
    }
    #[derive(Clone, Copy)]
    enum Noise {
        Dwna,
        Cwna,
        VelocityProportional,
    }
    let noise = match v.one_of(
        "motion_model.process_noise",
        m.process_noise.as_deref(),
        Some(Noise::Dwna),
        &[
            ("dwna", Noise::Dwna),
            ("cwna", Noise::Cwna),
            ("velocity_proportional", Noise::VelocityProportional),
        ],
    )? {
        Noise::Dwna => ProcessNoise::Dwna {
            sigma_a: v.required("motion_model.sigma_a_mps2", m.sigma_a_mps2)?,
        },
        Noise::Cwna => ProcessNoise::Cwna {
            q: v.required("motion_model.q_m2ps3", m.q_m2ps3)?,
        },
        Noise::VelocityProportional => ProcessNoise::VelocityProportional {
            factor: m.factor.unwrap_or(0.05),
        },
    };
    v.param("motion_model.", ConstantVelocity::new(layout.axes, noise))
}

/// Most track-instants (tracks × instants) an aligned scene may hold.
pub const MAX_SCENE_CELLS: usize = 8_000_000;

/// What alignment did, for a client to test.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AlignmentReport {
    /// `grid`, `predict`, `nearest` or `interpolate`.
    pub mode: &'static str,
    /// `grid`: the fusion period used (`None`: no node had two samples of a
    /// track, so one instant at the latest time).
    pub period_s: Option<f64>,
    /// `grid`: whether the period was estimated from the data.
    pub period_estimated: bool,
    pub epoch_s: Option<f64>,
    /// `predict`, `nearest`, `interpolate`.
    pub tolerance_s: Option<f64>,
    pub max_gap_s: Option<f64>,
    pub nodes: Vec<NodeAlignment>,
    pub instants: usize,
    /// Node pairs that share no instant where both hold a track.
    pub node_pairs_without_common_instant: usize,
    /// Tracks present at no instant where another node holds a track.
    pub tracks_without_partner_instant: usize,
    pub tracks: usize,
    /// Estimates brought across a gap to an instant (predicted, or held).
    pub brought: usize,
    /// Samples not used (superseded by a later sample of the same track
    /// before the next instant).
    pub unused_samples: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NodeAlignment {
    pub node: String,
    pub tracks: usize,
    /// Median interval between consecutive samples of the node's tracks.
    pub scan_period_s: Option<f64>,
    /// `grid`: the oldest a sample may be at an instant.
    pub max_staleness_s: Option<f64>,
}

pub(super) fn mode_name(m: AlignMode) -> &'static str {
    match m {
        AlignMode::Grid { .. } => "grid",
        AlignMode::Predict => "predict",
        AlignMode::Nearest => "nearest",
        AlignMode::Interpolate { .. } => "interpolate",
    }
}

impl Plan {
    /// A reported sample (valid) at time `t` as an estimate in canonical
    /// order, with its update factor I − K H when it carries a gain.
    pub(super) fn estimate(&self, t: f64, s: &SampleInput) -> Estimate {
        estimate(&self.layout, self.h.as_ref(), t, s)
    }

    /// The model that brings samples to their instants: the alignment
    /// model in the `predict` and `grid` modes; none (as reported) else.
    pub(super) fn bring_model(&self) -> Option<&dyn MotionModel> {
        match self.alignment {
            AlignMode::Predict | AlignMode::Grid { .. } => {
                self.align_model.as_ref().map(|m| m as &dyn MotionModel)
            }
            AlignMode::Nearest | AlignMode::Interpolate { .. } => None,
        }
    }
}

/// A reported sample (valid) at time `t` as an estimate in canonical
/// order, with its update factor I − K H when it carries a gain.
fn estimate(layout: &Layout, h: Option<&DMatrix<f64>>, t: f64, s: &SampleInput) -> Estimate {
    Estimate {
        t,
        x: layout.vector_to_canonical(&s.state),
        p: layout.matrix_to_canonical(&s.covariance),
        factor: match (&s.gain, h) {
            (Some(g), Some(h)) => Some(align::gain_factor(g.values(), h, &layout.from_request)),
            _ => None,
        },
    }
}

/// The grid's period and each node's staleness bound: given, or estimated
/// from node scan periods (`None` period: nothing to estimate from).
pub(super) fn grid_parameters(
    period: Option<f64>,
    max_staleness: Option<f64>,
    node_periods: &[Option<f64>],
) -> (Option<f64>, Vec<f64>) {
    let grid = period.or_else(|| node_periods.iter().flatten().copied().reduce(f64::max));
    let staleness = node_periods
        .iter()
        .map(|p| {
            max_staleness.unwrap_or_else(|| match p.or(grid) {
                Some(p) => align::STALENESS_PERIODS * p,
                None => f64::INFINITY,
            })
        })
        .collect();
    (grid, staleness)
}

/// Builds the aligned scene; returns it, whether gains were reported,
/// warnings and the alignment report.
fn align(
    est: Vec<Vec<Vec<Estimate>>>,
    node_ids: &[String],
    tolerance_given: bool,
    plan: &Plan,
) -> Result<(Scene, bool, Vec<String>, AlignmentReport), ServiceError> {
    let layout = &plan.layout;
    let dim = layout.dim;
    let model = plan.bring_model();
    let gains_reported = est.iter().flatten().flatten().any(|e| e.factor.is_some());
    let mut times: Vec<f64> = est.iter().flatten().flatten().map(|e| e.t).collect();
    times.sort_by(f64::total_cmp);
    let node_periods: Vec<Option<f64>> = est
        .iter()
        .map(|tracks| {
            let mut iv: Vec<f64> = tracks
                .iter()
                .flat_map(|s| s.windows(2).map(|w| w[1].t - w[0].t))
                .collect();
            align::median_interval(&mut iv)
        })
        .collect();
    let mut report = AlignmentReport {
        mode: mode_name(plan.alignment),
        period_s: None,
        period_estimated: false,
        epoch_s: None,
        tolerance_s: None,
        max_gap_s: None,
        nodes: Vec::new(),
        instants: 0,
        node_pairs_without_common_instant: 0,
        tracks_without_partner_instant: 0,
        tracks: est.iter().map(Vec::len).sum(),
        brought: 0,
        unused_samples: 0,
    };
    let mut warnings = Vec::new();
    if matches!(plan.alignment, AlignMode::Grid { .. }) && tolerance_given {
        warnings.push(
            "alignment.tolerance_s has no effect on the grid alignment of a batch (it is a \
             session's lateness allowance); give alignment.mode predict or nearest for clusters \
             of report times"
                .to_string(),
        );
    }
    let mut staleness = vec![None; est.len()];
    let clustered;
    let instants: Vec<f64> = match plan.alignment {
        AlignMode::Grid {
            period,
            epoch,
            max_staleness,
        } => {
            let (grid, bounds) = grid_parameters(period, max_staleness, &node_periods);
            report.period_s = grid;
            report.period_estimated = period.is_none() && grid.is_some();
            report.epoch_s = Some(epoch);
            staleness = bounds.iter().copied().map(Some).collect();
            clustered = Vec::new();
            match grid {
                Some(g) => {
                    let widest = bounds.iter().copied().fold(0.0, f64::max);
                    let limit = MAX_SCENE_CELLS / report.tracks.max(1);
                    align::grid_instants(&times, g, epoch, widest, limit).ok_or_else(|| {
                        ServiceError::TooLarge(format!(
                            "the grid alignment with a period of {g} s gives more than {limit} \
                             instants for {} tracks (the limit is {MAX_SCENE_CELLS} \
                             track-instants), or the period is below the resolution of the \
                             times: give a longer alignment.period_s or split the request in time",
                            report.tracks
                        ))
                    })?
                }
                None => {
                    if times.len() > 1 {
                        warnings.push(
                            "no track has two samples, so no scan period can be estimated: \
                             every track was brought to one instant at the latest sample time; \
                             give alignment.period_s for a grid"
                                .to_string(),
                        );
                    }
                    times.last().map(|&t| vec![t]).unwrap_or_default()
                }
            }
        }
        _ => {
            report.tolerance_s = Some(plan.tolerance);
            if let AlignMode::Interpolate { max_gap } = plan.alignment {
                report.max_gap_s = Some(max_gap);
            }
            clustered = align::clusters(&times, plan.tolerance);
            clustered.iter().map(|c| c.1).collect()
        }
    };
    report.instants = instants.len();
    let cells = instants.len().saturating_mul(report.tracks);
    if cells > MAX_SCENE_CELLS {
        return Err(ServiceError::TooLarge(format!(
            "alignment gives {} instants for {} tracks ({cells} track-instants; the limit is \
             {MAX_SCENE_CELLS}): give a longer alignment.period_s or split the request in time",
            instants.len(),
            report.tracks
        )));
    }
    let mut scene = Scene::new(dim, layout.positions(), instants.clone())
        .map_err(|e| ServiceError::Internal(e.to_string()))?;
    for (ni, node) in est.iter().enumerate() {
        let mut tracks = Vec::with_capacity(node.len());
        for (ti, samples) in node.iter().enumerate() {
            let mut out = Track::new(instants.len(), dim);
            let at = |si: usize, e: AlgoError| {
                Violations::from_param(&format!("nodes[{ni}].tracks[{ti}].samples[{si}]."), e)
            };
            match plan.alignment {
                AlignMode::Grid { .. } => {
                    let bound = staleness[ni].unwrap_or(f64::INFINITY);
                    let stats = align::fill_grid(&mut out, samples, &instants, 0, model, bound)
                        .map_err(|(si, e)| at(si, e))?;
                    report.brought += stats.brought;
                    report.unused_samples += stats.unused;
                }
                AlignMode::Interpolate { max_gap } => {
                    report.brought += align::interpolate(&mut out, samples, &instants, max_gap);
                }
                AlignMode::Predict | AlignMode::Nearest => {
                    let mut ci = 0;
                    let mut si = 0;
                    while si < samples.len() {
                        while clustered[ci].1 < samples[si].t {
                            ci += 1;
                        }
                        // The latest sample of this track inside cluster ci.
                        let mut last = si;
                        while last + 1 < samples.len() && samples[last + 1].t <= clustered[ci].1 {
                            last += 1;
                        }
                        report.unused_samples += last - si;
                        let placed =
                            align::place(&mut out, ci, instants[ci], &samples[last], model, true)
                                .map_err(|e| at(last, e))?;
                        if placed == align::Placed::Brought && model.is_some() {
                            report.brought += 1;
                        }
                        si = last + 1;
                    }
                }
            }
            tracks.push(out);
        }
        scene
            .add_node(tracks)
            .map_err(|e| ServiceError::Internal(e.to_string()))?;
    }
    report.nodes = node_ids
        .iter()
        .zip(&est)
        .zip(&node_periods)
        .zip(&staleness)
        .map(|(((id, tracks), &p), &s)| NodeAlignment {
            node: id.clone(),
            tracks: tracks.len(),
            scan_period_s: p,
            max_staleness_s: s.filter(|s| s.is_finite()),
        })
        .collect();
    let empty: Vec<&str> = report
        .nodes
        .iter()
        .filter(|n| n.tracks == 0)
        .map(|n| n.node.as_str())
        .collect();
    if !empty.is_empty() {
        warnings.push(format!(
            "{} node(s) hold no tracks ({}): they take part in no pair",
            empty.len(),
            empty.join(", ")
        ));
    }
    coverage(&scene, node_ids, &mut report, &mut warnings);
    match plan.alignment {
        AlignMode::Predict if report.brought > 0 => warnings.push(format!(
            "{} sample(s) were predicted forward (at most {} s) to a common instant",
            report.brought, plan.tolerance
        )),
        AlignMode::Interpolate { .. } if report.brought > 0 => warnings.push(format!(
            "{} estimate(s) were interpolated linearly between two samples of their track to a \
             common instant",
            report.brought
        )),
        AlignMode::Grid { .. } if plan.model.is_none() && report.brought > 0 => {
            warnings.push(if layout.has_velocity {
                format!(
                    "no motion_model: {} estimate(s) were extrapolated to their instant along \
                     their velocity without process noise; give motion_model for Q",
                    report.brought
                )
            } else {
                format!(
                    "no velocities in state_layout: {} position(s) were held unchanged up to \
                     their staleness bound to reach an instant; moving targets may fail the test",
                    report.brought
                )
            })
        }
        _ => {}
    }
    if report.unused_samples > 0 && !matches!(plan.alignment, AlignMode::Grid { .. }) {
        warnings.push(format!(
            "{} sample(s) were superseded by a later sample of the same track within one \
             alignment instant (tolerance {} s) and ignored",
            report.unused_samples, plan.tolerance
        ));
    }
    Ok((scene, gains_reported, warnings, report))
}

/// Which nodes meet at which instants: counts the node pairs that never do
/// and the tracks that never meet another node, and warns when alignment
/// left the nodes apart.
pub(super) fn coverage(
    scene: &Scene,
    node_ids: &[String],
    report: &mut AlignmentReport,
    warnings: &mut Vec<String>,
) {
    let n = scene.nodes().len();
    if n < 2 {
        return;
    }
    let ks = scene.first()..scene.end();
    let node_at: Vec<Vec<bool>> = scene
        .nodes()
        .iter()
        .map(|tracks| {
            ks.clone()
                .map(|k| tracks.iter().any(|t| t.is_present(k)))
                .collect()
        })
        .collect();
    let busy: Vec<usize> = (0..ks.len())
        .map(|i| node_at.iter().filter(|v| v[i]).count())
        .collect();
    let mut apart = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            let has_tracks = |x: usize| node_at[x].iter().any(|&p| p);
            if has_tracks(a)
                && has_tracks(b)
                && !(0..ks.len()).any(|i| node_at[a][i] && node_at[b][i])
            {
                apart.push((a, b));
            }
        }
    }
    report.node_pairs_without_common_instant = apart.len();
    let present: Vec<&Track> = scene
        .nodes()
        .iter()
        .flatten()
        .filter(|t| ks.clone().any(|k| t.is_present(k)))
        .collect();
    let alone = present
        .iter()
        .filter(|t| {
            !ks.clone()
                .enumerate()
                .any(|(i, k)| t.is_present(k) && busy[i] >= 2)
        })
        .count();
    report.tracks_without_partner_instant = alone;
    let fix = match report.mode {
        "grid" => "raise alignment.max_staleness_s (or alignment.period_s)",
        "interpolate" => "raise alignment.max_gap_s, or use the default grid alignment",
        _ => {
            "use the default grid alignment (alignment.mode: grid), or raise alignment.tolerance_s to the scan offset"
        }
    };
    if !apart.is_empty() {
        let names: Vec<String> = apart
            .iter()
            .take(5)
            .map(|&(a, b)| format!("{}–{}", node_ids[a], node_ids[b]))
            .collect();
        warnings.push(format!(
            "{} node pair(s) share no instant where both hold a track ({}{}) under the {} \
             alignment, so they cannot correlate: {fix}",
            apart.len(),
            names.join(", "),
            if apart.len() > 5 { ", …" } else { "" },
            report.mode
        ));
    } else if alone * 2 > present.len() {
        warnings.push(format!(
            "{alone} of {} tracks are present at no instant where another node holds a track, \
             so they cannot correlate under the {} alignment: {fix}",
            present.len(),
            report.mode
        ));
    }
}

/// Wire name of a statistic: the one vocabulary of REST and gRPC.
pub fn statistic_name(s: Statistic) -> &'static str {
    match s {
        Statistic::Weighted => "weighted",
        Statistic::Modified => "modified",
    }
}

pub fn decision_name(d: Decision) -> &'static str {
    match d {
        Decision::Correlated => "correlated",
        Decision::NotCorrelated => "not_correlated",
        Decision::Undecided => "undecided",
    }
}

pub fn reason_name(r: Reason) -> &'static str {
    match r {
        Reason::Testing => "testing",
        Reason::Threshold => "threshold",
        Reason::EarlyDecision => "early_decision",
        Reason::EarlyStop => "early_stop",
        Reason::AmbiguityMaxM => "ambiguity_max_m",
        Reason::AmbiguityMinMeanStatistic => "ambiguity_min_mean_statistic",
        Reason::AmbiguityLost => "ambiguity_lost",
        Reason::Assignment => "assignment",
        Reason::BelowRule => "below_rule",
        Reason::Revoked => "revoked",
        Reason::Gate => "gate",
        Reason::NearestNeighbour => "nearest_neighbour",
        Reason::Conflict => "conflict",
        Reason::KOfN => "k_of_n",
    }
}

pub fn fusion_name(f: FusionKind) -> &'static str {
    match f {
        FusionKind::BarShalomCampo => "bar_shalom_campo",
        FusionKind::CovarianceIntersection => "covariance_intersection",
        FusionKind::Single => "single",
        FusionKind::None => "none",
    }
}
