//! The state of a correlation session: its configuration and plan, the
//! windowed scene, the track slots of every node, one correlator state per
//! node pair and the reports of the open alignment instant.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector};

use super::{
    DEFAULT_HISTORY_INSTANTS, DEFAULT_RETIRE_AFTER_S, MAX_HISTORY_INSTANTS, NodeView, SessionSpec,
    SessionView, TrackView,
};
use crate::{
    algo::{
        AlgoError,
        correlation::{
            engine::{self, CorrelatorState, Decision, PairCorrelator, Statistic},
            grouping::{self, Link},
            scene::Scene,
        },
        motion::MotionModel,
        small,
    },
    service::{
        ServiceError, Violations,
        correlation::{self, AlignMode, CrossCovariances, GroupOutput, Plan, TrackName},
    },
};

/// A track slot of a node: a live track, or free for reuse.
#[derive(Debug, Clone)]
pub(super) struct Slot {
    /// Empty when free.
    pub(super) id: String,
    pub(super) last_t: Option<f64>,
    /// Retired in the current batch: freed at its end.
    pub(super) retiring: bool,
}

#[derive(Debug, Clone)]
pub(super) struct Pending {
    pub(super) node: usize,
    pub(super) slot: usize,
    pub(super) t: f64,
    /// Canonical order.
    pub(super) x: Vec<f64>,
    pub(super) p: Vec<f64>,
    pub(super) factor: Option<Vec<f64>>,
}

/// The state of a session.
pub struct CorrelationSession {
    pub(super) spec: SessionSpec,
    pub(super) plan: Plan,
    pub(super) retire_after_s: f64,
    pub(super) history: usize,
    pub(super) scene: Scene,
    pub(super) node_ids: Vec<String>,
    pub(super) slots: Vec<Vec<Slot>>,
    pub(super) by_id: Vec<HashMap<String, usize>>,
    /// One per node pair (na < nb), in the order of [`CorrelationSession::node_pairs`].
    pub(super) correlators: Vec<CorrelatorState>,
    pub(super) pending: Vec<Pending>,
    /// Start of the last closed cluster: reports up to start + tolerance are late.
    pub(super) closed_start: Option<f64>,
    pub(super) instants_processed: u64,
    pub(super) reports_accepted: u64,
    pub(super) reports_late: u64,
}

pub(super) fn internal(e: AlgoError) -> ServiceError {
    ServiceError::Internal(e.to_string())
}

impl CorrelationSession {
    /// A new, empty session; validates the configuration.
    pub fn new(spec: SessionSpec) -> Result<Self, ServiceError> {
        let plan = plan_of(&spec)?;
        let mut v = Violations::new();
        let retire = spec.retire_after_s.unwrap_or(DEFAULT_RETIRE_AFTER_S);
        if !(retire.is_finite() && retire > 0.0) {
            v.add("retire_after_s", "must be a finite number of seconds > 0");
        }
        let history = spec.history_instants.unwrap_or(DEFAULT_HISTORY_INSTANTS);
        if history == 0 || history > MAX_HISTORY_INSTANTS {
            v.add(
                "history_instants",
                format!("must be between 1 and {MAX_HISTORY_INSTANTS}"),
            );
        }
        if plan.alignment != AlignMode::Predict && plan.alignment != AlignMode::Nearest {
            v.add(
                "alignment.mode",
                "a session aligns causally: predict or nearest (interpolate needs later samples)",
            );
        }
        let mut seen = HashMap::new();
        if spec.config.nodes.len() < 2 {
            v.add("nodes", "a session needs at least two nodes");
        } else if spec.config.nodes.len() > correlation::MAX_NODES {
            v.add("nodes", format!("at most {} nodes", correlation::MAX_NODES));
        }
        for (i, n) in spec.config.nodes.iter().enumerate() {
            match n.id.as_deref() {
                None | Some("") => v.add(format!("nodes[{i}].id"), "is required"),
                Some(id) => {
                    if let Some(prev) = seen.insert(id.to_string(), i) {
                        v.add(
                            format!("nodes[{i}].id"),
                            format!("duplicates nodes[{prev}].id '{id}'"),
                        );
                    }
                }
            }
            if !n.tracks.is_empty() {
                v.add(
                    format!("nodes[{i}].tracks"),
                    "a session's tracks arrive in batches: leave this out",
                );
            }
        }
        v.finish()?;
        let node_ids = node_ids(&spec);
        let mut scene =
            Scene::new(plan.layout.dim, plan.layout.positions(), Vec::new()).map_err(internal)?;
        for _ in &node_ids {
            scene.push_node();
        }
        let n = node_ids.len();
        Ok(Self {
            retire_after_s: retire,
            history: history as usize,
            scene,
            slots: vec![Vec::new(); n],
            by_id: vec![HashMap::new(); n],
            correlators: vec![CorrelatorState::default(); n * (n - 1) / 2],
            node_ids,
            pending: Vec::new(),
            closed_start: None,
            instants_processed: 0,
            reports_accepted: 0,
            reports_late: 0,
            plan,
            spec,
        })
    }

    /// Reports waiting in the open instant.
    pub fn pending_reports(&self) -> u32 {
        self.pending.len() as u32
    }

    pub(super) fn node_pairs(&self) -> Vec<(usize, usize)> {
        let n = self.node_ids.len();
        (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .collect()
    }

    pub(super) fn name(&self, node: usize, slot: usize) -> TrackName {
        TrackName {
            node: self.node_ids[node].clone(),
            track: self.slots[node][slot].id.clone(),
        }
    }

    pub(super) fn live_tracks(&self) -> usize {
        self.slots
            .iter()
            .flatten()
            .filter(|s| !s.id.is_empty())
            .count()
    }

    /// The slot of a track, allocating one (reusing a freed slot) for a new id.
    pub(super) fn slot_for(&mut self, node: usize, track: &str) -> usize {
        if let Some(&s) = self.by_id[node].get(track) {
            return s;
        }
        let slot = match self.slots[node]
            .iter()
            .position(|s| s.id.is_empty() && !s.retiring)
        {
            Some(s) => s,
            None => {
                let s = self.scene.push_track(node);
                self.slots[node].push(Slot {
                    id: String::new(),
                    last_t: None,
                    retiring: false,
                });
                s
            }
        };
        self.slots[node][slot].id = track.to_string();
        self.by_id[node].insert(track.to_string(), slot);
        slot
    }

    /// Puts report `r` at instant `k` (predicted to it in predict mode) and
    /// its filter factor for the modified statistic; true when predicted.
    pub(super) fn fill(&mut self, k: usize, r: &Pending) -> Result<bool, ServiceError> {
        let dim = self.plan.layout.dim;
        let t_k = self.scene.time(k);
        let (mut x, mut p) = (r.x.clone(), r.p.clone());
        let mut predicted = false;
        let dt = t_k - r.t;
        if dt > 0.0 && self.plan.alignment == AlignMode::Predict {
            let model = self.plan.model.as_ref().expect("predict needs a model");
            let (xp, pp) = model
                .predict(
                    &DVector::from_column_slice(&x),
                    &DMatrix::from_row_slice(dim, dim, &p),
                    dt,
                )
                .map_err(|e| Violations::from_param("reports.", e))?;
            x = xp.as_slice().to_vec();
            p = small::row_major(&pp);
            predicted = true;
        }
        let prev = self.scene.track(r.node, r.slot).previous(k);
        let factor = match (&r.factor, prev, self.plan.config.statistic) {
            (Some(f), ..) => Some(f.clone()),
            (None, Some(kp), Statistic::Modified) => {
                let model = self.plan.model.as_ref().expect("modified needs a model");
                let tr = self.scene.track(r.node, r.slot);
                engine::filter_factor(
                    model,
                    tr.x(kp, dim),
                    tr.p(kp, dim),
                    &p,
                    t_k - self.scene.time(kp),
                )
                .map_err(|e| Violations::from_param("reports.", e))?
                .map(|f| f[..dim * dim].to_vec())
            }
            _ => None,
        };
        let track = self.scene.track_mut(r.node, r.slot);
        track.set(k, &x, &p);
        if let Some(f) = factor {
            track.set_gain_factor(k, &f);
        }
        Ok(predicted)
    }

    pub(super) fn system_tracks(
        &self,
        links: &[Link],
        cross: &CrossCovariances,
    ) -> Vec<GroupOutput> {
        let grouping = grouping::group(links);
        let dim = self.plan.layout.dim;
        grouping
            .groups
            .iter()
            .enumerate()
            .map(|(id, members)| {
                let fused = if self.plan.fuse {
                    correlation::fuse_group(&self.scene, members, cross, dim)
                } else {
                    None
                };
                let (t, state, covariance, fusion) = match fused {
                    Some((k, f, kind)) => (
                        self.scene.time(k),
                        self.plan.layout.vector_to_request(f.x.as_slice()),
                        self.plan.layout.matrix_to_request(&f.p),
                        kind,
                    ),
                    None => (
                        f64::NAN,
                        Vec::new(),
                        Vec::new(),
                        correlation::FusionKind::None,
                    ),
                };
                GroupOutput {
                    id: id as u32,
                    members: members.iter().map(|&(n, t)| self.name(n, t)).collect(),
                    t,
                    state,
                    covariance,
                    fusion,
                }
            })
            .collect()
    }

    /// The whole session as a client reads it.
    pub(super) fn view_state(&self) -> Result<SessionView, ServiceError> {
        let model_ref: Option<&dyn MotionModel> =
            self.plan.model.as_ref().map(|m| m as &dyn MotionModel);
        let mut pairs = Vec::new();
        let mut links = Vec::new();
        let mut cross: CrossCovariances = HashMap::new();
        for (ci, (na, nb)) in self.node_pairs().into_iter().enumerate() {
            let c = PairCorrelator::resume(
                &self.scene,
                na,
                nb,
                &self.plan.config,
                model_ref,
                self.correlators[ci].clone(),
            )
            .map_err(internal)?;
            for r in c.reports() {
                correlation::collect_link(&r, na, nb, &mut links, &mut cross);
                if r.m >= 1 || r.decision == Decision::Correlated || r.trial {
                    pairs.push(correlation::pair_output(
                        &r,
                        self.name(na, r.a),
                        self.name(nb, r.b),
                    ));
                }
            }
        }
        let system_tracks = self.system_tracks(&links, &cross);
        Ok(SessionView {
            instants_processed: self.instants_processed,
            last_instant: self.scene.times().last().copied(),
            pending_reports: self.pending.len() as u32,
            reports_accepted: self.reports_accepted,
            reports_late: self.reports_late,
            retire_after_s: self.retire_after_s,
            history_instants: self.history as u32,
            method: self.plan.method_name.clone(),
            nodes: self
                .node_ids
                .iter()
                .enumerate()
                .map(|(n, id)| NodeView {
                    id: id.clone(),
                    tracks: self.slots[n]
                        .iter()
                        .filter(|s| !s.id.is_empty())
                        .map(|s| TrackView {
                            id: s.id.clone(),
                            last_t: s.last_t,
                        })
                        .collect(),
                })
                .collect(),
            pairs,
            system_tracks,
        })
    }
}

/// The node ids of a configuration, in order.
pub(super) fn node_ids(spec: &SessionSpec) -> Vec<String> {
    spec.config
        .nodes
        .iter()
        .map(|n| n.id.clone().unwrap_or_default())
        .collect()
}

pub(super) fn plan_of(spec: &SessionSpec) -> Result<Plan, ServiceError> {
    correlation::validate_plan(&spec.config)
}

/// I − K H in canonical order from a gain K in the request's row order.
pub(super) fn gain_factor(
    g: &[Vec<f64>],
    h: &DMatrix<f64>,
    layout: &correlation::Layout,
) -> Vec<f64> {
    let dim = layout.dim;
    let m = h.nrows();
    let k_flat: Vec<f64> = g.iter().flatten().copied().collect();
    let k_req = DMatrix::from_row_slice(dim, m, &k_flat);
    let mut k = DMatrix::zeros(dim, m);
    for (i, &ri) in layout.from_request.iter().enumerate() {
        k.set_row(i, &k_req.row(ri));
    }
    let factor = DMatrix::<f64>::identity(dim, dim) - &k * h;
    small::row_major(&factor)
}
