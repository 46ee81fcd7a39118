//! Parsing a request's nodes: each node's and track's id and each sample
//! as an estimate in canonical order.

use nalgebra::DMatrix;

use crate::{Ids, Increasing, Interval, ServiceError, Violations, at};
use algo::correlation::align::{self, Estimate};

use super::{
    CorrelateInput, Layout, MAX_NODES, MAX_SAMPLES, Plan, SampleInput,
    config::{plan_of, validate_config},
};

/// A node of a parsed request: its id, its tracks' ids and their samples
/// as estimates in canonical order.
pub(super) struct ParsedNode {
    pub(super) id: String,
    pub(super) track_ids: Vec<String>,
    pub(super) tracks: Vec<Vec<Estimate>>,
}

/// A parsed request.
pub(super) struct Parsed {
    pub(super) plan: Plan,
    pub(super) nodes: Vec<ParsedNode>,
}

pub(super) fn validate(input: &CorrelateInput) -> Result<Parsed, ServiceError> {
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
            // Track by track, so that an abandoned request stops (the batch
            // endpoint's parser only: sessions parse their reports apart).
            crate::lanes::checkpoint()?;
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
pub(crate) fn check_sample(
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

/// A reported sample (valid) at time `t` as an estimate in canonical
/// order, with its update factor I − K H when it carries a gain.
pub(super) fn estimate(
    layout: &Layout,
    h: Option<&DMatrix<f64>>,
    t: f64,
    s: &SampleInput,
) -> Estimate {
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
