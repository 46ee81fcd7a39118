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
//!
//! The files, in the order a request goes through them: `input` (the
//! request as sent), `config` and `nodes` (parsed into a `plan::Plan` and
//! estimates, with `layout`), `alignment`, the pair correlation here,
//! `groups` (grouping and fusion) and `output` (the result and its wire
//! names).

use std::time::Instant;

use super::{ServiceError, Violations, micros_since};
use algo::{
    AlgoError,
    correlation::{
        engine::{Decision, Method, PairCorrelator, RuleSpec, Statistic},
        grouping::Grouping,
        scene::Scene,
    },
    motion::MotionModel,
};

mod alignment;
mod config;
mod groups;
mod input;
mod layout;
mod nodes;
mod output;
mod plan;

pub use alignment::{AlignmentReport, MAX_SCENE_CELLS, NodeAlignment};
pub(crate) use alignment::{coverage, grid_parameters, mode_name};
pub(crate) use config::validate_plan;
pub(crate) use groups::{Links, system_tracks};
pub use input::{
    AlignmentInput, CorrelateInput, METHODS, MethodInput, MotionModelInput, NodeInput, RuleInput,
    SampleInput, TrackInput,
};
pub(crate) use layout::Layout;
pub(crate) use nodes::check_sample;
pub(crate) use output::pair_output;
pub use output::{
    ConflictOutput, CorrelateOutput, CorrelateTiming, FusionKind, GroupOutput, PairOutput,
    Thresholds, TrackName, decision_name, fusion_name, reason_name, statistic_name,
};
pub use plan::DEFAULT_MAX_GAP_S;
pub(crate) use plan::{AlignMode, Plan};

/// Most nodes in one request.
pub const MAX_NODES: usize = 64;
/// Most samples (over all tracks and nodes) in one request.
pub const MAX_SAMPLES: usize = 4_000_000;
/// Default significance level of the first threshold.
pub const DEFAULT_ALPHA: f64 = 0.05;
/// Default alignment tolerance.
pub const DEFAULT_TOLERANCE_S: f64 = 0.5;
/// Most candidate pairs (pairs of tracks of two nodes inside the spatial
/// gate at some instant) one request, or one session, holds over all its
/// node pairs: each costs a few hundred bytes of state, so a million is a
/// few hundred MB. Real scenes hold a few per track (218 for 120 tracks a
/// node); co-located tracks would otherwise hold the product of the nodes'
/// track counts.
pub const MAX_CANDIDATE_PAIRS: usize = 1_000_000;

/// The invalid-input error of tracks that would form more than
/// [`MAX_CANDIDATE_PAIRS`] candidate pairs, against `field`; `scope` says
/// whose limit it is (`one request`, `one session`).
pub(crate) fn pair_budget_error(field: &str, scope: &str) -> ServiceError {
    ServiceError::InvalidInput(vec![crate::FieldViolation {
        field: field.into(),
        message: format!(
            "the tracks would form more than {MAX_CANDIDATE_PAIRS} candidate pairs (pairs of \
             tracks of two nodes inside the spatial gate), the limit of {scope} \
             (MAX_CANDIDATE_PAIRS): a smaller method.alpha narrows the gate, or send fewer \
             tracks at once"
        ),
    }])
}

/// Correlates the request's nodes.
pub fn correlate(input: CorrelateInput) -> Result<CorrelateOutput, ServiceError> {
    let start = Instant::now();
    let nodes::Parsed { plan, nodes } = nodes::validate(&input)?;
    let dim = plan.layout.dim;

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
        alignment::align(est, &node_ids, tolerance_given, &plan)?;
    let align_us = micros_since(t_align);

    let t_corr = Instant::now();
    let name = |node: usize, track: usize| TrackName {
        node: node_ids[node].clone(),
        track: track_ids[node][track].clone(),
    };
    let correlated = correlate_pairs(&scene, &plan, &name, &mut warnings)?;
    let correlate_us = micros_since(t_corr);

    crate::lanes::checkpoint()?;
    let t_fuse = Instant::now();
    let (grouping, grouped, groups) = system_tracks(&scene, &plan, &correlated.links, name);
    let fuse_us = micros_since(t_fuse);

    let n_nodes = scene.nodes().len();
    let unpaired = (0..n_nodes)
        .map(|n| {
            let ids = (0..scene.nodes()[n].len())
                .filter(|&t| !grouped.contains(&(n, t)))
                .map(|t| track_ids[n][t].clone())
                .collect();
            (node_ids[n].clone(), ids)
        })
        .collect();
    if n_nodes < 2 {
        warnings.push("only one node: there is nothing to correlate".into());
    }
    let mut delta = correlated.delta;
    if delta.is_nan() {
        delta = algo::gating::chi2_threshold(dim, plan.config.alpha)
            .map_err(|e| ServiceError::Internal(e.to_string()))?;
    }
    Ok(CorrelateOutput {
        method: plan.method_name.clone(),
        statistic: plan.config.statistic,
        thresholds: thresholds(&plan, delta),
        gains: match plan.config.statistic {
            Statistic::Weighted => "not_used",
            Statistic::Modified if gains_reported => "reported",
            Statistic::Modified => "recomputed",
        },
        instants: scene.times().to_vec(),
        alignment,
        pairs: correlated.pairs,
        omitted_pairs: correlated.omitted,
        unpaired,
        groups,
        conflicts: conflicts(&grouping, &node_ids, &track_ids, &name),
        timing: CorrelateTiming {
            compute_us: micros_since(start),
            align_us,
            correlate_us,
            fuse_us,
        },
        warnings,
    })
}

/// What correlating every node pair gave: the listed pairs, how many were
/// left out, the links to group and the first threshold δ (NaN without a
/// node pair).
struct Correlated {
    pairs: Vec<PairOutput>,
    omitted: u64,
    links: Links,
    delta: f64,
}

/// Correlates every node pair of the scene; lists the pairs that were
/// tested at least once, decided correlated or paired on trial.
fn correlate_pairs(
    scene: &Scene,
    plan: &Plan,
    name: &impl Fn(usize, usize) -> TrackName,
    warnings: &mut Vec<String>,
) -> Result<Correlated, ServiceError> {
    let model_ref: Option<&dyn MotionModel> = plan.model.as_ref().map(|m| m as &dyn MotionModel);
    let mut out = Correlated {
        pairs: Vec::new(),
        omitted: 0,
        links: Links::default(),
        delta: f64::NAN,
    };
    let mut singular = 0usize;
    let mut held = 0usize;
    let n_nodes = scene.nodes().len();
    for na in 0..n_nodes {
        for nb in na + 1..n_nodes {
            let mut correlator = PairCorrelator::new(scene, na, nb, &plan.config, model_ref)
                .map_err(|e| Violations::from_param("method.", e))?
                .with_pair_budget(MAX_CANDIDATE_PAIRS - held);
            out.delta = correlator.delta();
            // Instant by instant, so that an abandoned request stops.
            while {
                crate::lanes::checkpoint()?;
                correlator.step().map_err(|e| match e {
                    AlgoError::BudgetExceeded { .. } => pair_budget_error("nodes", "one request"),
                    other => Violations::from_param("method.", other),
                })?
            } {}
            held += correlator.pair_count();
            singular += correlator.singular_tests;
            let total = (scene.nodes()[na].len() * scene.nodes()[nb].len()) as u64;
            let reports = correlator.reports();
            let mut listed = 0u64;
            for r in reports {
                out.links.collect(&r, na, nb);
                if r.m >= 1 || r.decision == Decision::Correlated || r.trial {
                    listed += 1;
                    out.pairs
                        .push(pair_output(&r, name(na, r.a), name(nb, r.b)));
                }
            }
            out.omitted += total - listed;
        }
    }
    if singular > 0 {
        warnings.push(format!(
            "{singular} test(s) of the modified statistic had P_a + P_b − P_ab − P_ab' not \
             positive definite (the reported covariances, gains and motion model are not \
             consistent with one another); the weighted statistic was used for them"
        ));
    }
    Ok(out)
}

/// The thresholds the method used: α, δ and the rule, schedule, window or
/// k of its kind.
fn thresholds(plan: &Plan, delta: f64) -> Thresholds {
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
    Thresholds {
        alpha: plan.config.alpha,
        delta,
        dof: plan.layout.dim as u32,
        rule,
        schedule,
        window,
        k,
    }
}

/// The grouping's conflicts (two tracks of one node linked into a group)
/// under the request's ids.
fn conflicts(
    grouping: &Grouping,
    node_ids: &[String],
    track_ids: &[Vec<String>],
    name: &impl Fn(usize, usize) -> TrackName,
) -> Vec<ConflictOutput> {
    grouping
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
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_abandoned_request_stops_at_its_first_track() {
        // A track without samples: a violation when someone waits for the
        // answer, and stopped at the first track when nobody does.
        let input = || CorrelateInput {
            nodes: vec![NodeInput {
                id: Some("a".into()),
                tracks: vec![TrackInput::default()],
            }],
            ..CorrelateInput::default()
        };
        assert!(matches!(
            correlate(input()),
            Err(ServiceError::InvalidInput(_))
        ));
        let stopped = crate::lanes::as_abandoned(|| correlate(input()));
        assert!(
            matches!(stopped, Err(ServiceError::Cancelled)),
            "{stopped:?}"
        );
    }
}
