//! The state of a correlation session: its configuration and plan, the
//! windowed scene, the track slots of every node, one correlator state per
//! node pair and the reports of the open alignment instant.

use std::collections::HashMap;

use super::{
    DEFAULT_HISTORY_INSTANTS, DEFAULT_RETIRE_AFTER_S, MAX_HISTORY_INSTANTS, NodeView, SessionSpec,
    SessionView, TrackView,
};
use crate::{
    Ids, Interval, ServiceError, Violations,
    correlation::{self, AlignMode, GroupOutput, Links, Plan, TrackName},
};
use algo::{
    AlgoError,
    correlation::{
        align::{self, Estimate},
        engine::{self, CorrelatorState, Decision, PairCorrelator, Statistic},
        scene::Scene,
    },
    motion::MotionModel,
};

/// A track slot of a node: a live track, or free for reuse.
#[derive(Debug, Clone, Default)]
pub(super) struct Slot {
    /// Empty when free.
    pub(super) id: String,
    pub(super) last_t: Option<f64>,
    /// Retired in the current batch: freed at its end.
    pub(super) retiring: bool,
    /// Grid alignment: the track's latest report at or before the last
    /// closed instant, and whether it was already placed at an instant.
    pub(super) latest: Option<Estimate>,
    pub(super) used: bool,
    /// Grid alignment: the time of the newest report accepted (pending
    /// included), for the scan-period estimate.
    pub(super) seen_t: Option<f64>,
}

/// Most recent sample intervals kept per node for its scan-period estimate.
pub(super) const INTERVALS_KEPT: usize = 64;

#[derive(Debug, Clone)]
pub(super) struct Pending {
    pub(super) node: usize,
    pub(super) slot: usize,
    /// Canonical order.
    pub(super) est: Estimate,
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
    /// Grid alignment: the fusion period once fixed (given, or estimated
    /// when the first instant closes) and each node's recent intervals.
    pub(super) grid_period: Option<f64>,
    pub(super) intervals: Vec<Vec<f64>>,
}

pub(super) fn internal(e: AlgoError) -> ServiceError {
    ServiceError::Internal(e.to_string())
}

impl CorrelationSession {
    /// A new, empty session; validates the configuration.
    pub fn new(spec: SessionSpec) -> Result<Self, ServiceError> {
        let plan = plan_of(&spec)?;
        let mut v = Violations::new();
        // Seconds.
        let retire = v.number_or(
            "retire_after_s",
            spec.retire_after_s,
            DEFAULT_RETIRE_AFTER_S,
            Interval::POSITIVE,
        );
        let history = v.count_or(
            "history_instants",
            spec.history_instants,
            DEFAULT_HISTORY_INSTANTS,
            1,
            MAX_HISTORY_INSTANTS,
        );
        if let AlignMode::Interpolate { .. } = plan.alignment {
            v.add(
                "alignment.mode",
                "a session aligns causally: grid, predict or nearest (interpolate needs later \
                 samples)",
            );
        }
        if spec.config.nodes.len() < 2 {
            v.add("nodes", "a session needs at least two nodes");
        } else {
            v.at_most(
                "nodes",
                spec.config.nodes.len(),
                correlation::MAX_NODES,
                "nodes",
            );
        }
        let mut ids = Ids::new();
        for (i, n) in spec.config.nodes.iter().enumerate() {
            ids.check(&mut v, n.id.as_deref(), i, |j| format!("nodes[{j}].id"));
            if !n.tracks.is_empty() {
                v.add(
                    format!("nodes[{i}].tracks"),
                    "a session's tracks arrive in batches: leave this out",
                );
            }
        }
        let (retire, history) = v.finish_with(retire.zip(history))?;
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
            grid_period: match plan.alignment {
                AlignMode::Grid { period, .. } => period,
                _ => None,
            },
            intervals: vec![Vec::new(); n],
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
                self.slots[node].push(Slot::default());
                s
            }
        };
        self.slots[node][slot].id = track.to_string();
        self.by_id[node].insert(track.to_string(), slot);
        slot
    }

    /// Puts estimate `est` of track `slot` of `node` at instant `k`
    /// (brought to it in the predict and grid modes) with its filter factor
    /// for the modified statistic (I when `first_use` is false: the estimate
    /// was placed before and no update happened since); true when brought
    /// across a gap.
    pub(super) fn fill(
        &mut self,
        k: usize,
        node: usize,
        slot: usize,
        est: &Estimate,
        first_use: bool,
    ) -> Result<bool, ServiceError> {
        let dim = self.plan.layout.dim;
        let t_k = self.scene.time(k);
        let model = self.plan.bring_model();
        let prev = self.scene.track(node, slot).previous(k);
        let track = self.scene.track_mut(node, slot);
        let placed = align::place(track, k, t_k, est, model, first_use)
            .map_err(|e| Violations::from_param("reports.", e))?;
        if let (None, Some(kp), Statistic::Modified) =
            (&est.factor, prev, self.plan.config.statistic)
        {
            let model = self.plan.model.as_ref().expect("modified needs a model");
            let tr = self.scene.track(node, slot);
            let factor = engine::filter_factor(
                model,
                tr.x(kp, dim),
                tr.p(kp, dim),
                tr.p(k, dim),
                t_k - self.scene.time(kp),
            )
            .map_err(|e| Violations::from_param("reports.", e))?;
            if let Some(f) = factor {
                self.scene
                    .track_mut(node, slot)
                    .set_gain_factor(k, &f[..dim * dim]);
            }
        }
        Ok(placed == align::Placed::Brought && model.is_some())
    }

    pub(super) fn system_tracks(&self, links: &Links) -> Vec<GroupOutput> {
        correlation::system_tracks(&self.scene, &self.plan, links, |n, t| self.name(n, t)).2
    }

    /// The whole session as a client reads it.
    pub(super) fn view_state(&self) -> Result<SessionView, ServiceError> {
        let model_ref: Option<&dyn MotionModel> =
            self.plan.model.as_ref().map(|m| m as &dyn MotionModel);
        let mut pairs = Vec::new();
        let mut links = Links::default();
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
                links.collect(&r, na, nb);
                if r.m >= 1 || r.decision == Decision::Correlated || r.trial {
                    pairs.push(correlation::pair_output(
                        &r,
                        self.name(na, r.a),
                        self.name(nb, r.b),
                    ));
                }
            }
        }
        let system_tracks = self.system_tracks(&links);
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
