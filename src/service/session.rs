//! Streaming correlation sessions (seed 000 §3.3: local tracks arrive "one by
//! one or batch by batch"). A session carries the correlation state of every
//! node pair (quality counters m and C, decided pairs, trial system tracks,
//! cross-covariances) from one batch of track reports to the next.
//!
//! This module is the session's domain: its configuration, its state, the
//! application of one batch and the compact versioned binary encoding of the
//! state. It reuses the batch correlation's validation, alignment rule,
//! engine ([`PairCorrelator::resume`]), grouping and fusion; persistence and
//! concurrency live in [`super::sessions`].
//!
//! Alignment is the batch endpoint's, made incremental: reports are sorted by
//! time and clustered greedily, a cluster starting at s holding the reports up
//! to s + tolerance, its instant being its latest time. A cluster is closed
//! (and correlated) once a report later than s + tolerance has arrived, or when
//! a batch asks for a flush; a report that falls in a closed cluster arrives
//! too late and is dropped with a warning. For reports pushed in time order,
//! N batches and a final flush give exactly the instants, and so the decisions,
//! of the batch endpoint over the same data.
//!
//! The scene keeps the last `history_instants` instants (up to twice that
//! between trims): a pair that enters the χ² gate late replays its common
//! instants from that window only, and the cross-covariance recursion of a
//! pair whose tracks were both absent for longer restarts from zero. Within
//! the window the results equal the batch endpoint's.

use std::collections::{BTreeSet, HashMap, HashSet};

use nalgebra::{DMatrix, DVector};

use super::{
    FieldViolation, ServiceError, Violations,
    correlation::{
        self, AlignMode, AlignmentInput, CorrelateInput, CrossCovariances, FusionKind, GroupOutput,
        MethodInput, MotionModelInput, NodeInput, PairOutput, Plan, RuleInput, SampleInput,
        TrackName,
    },
};
use crate::algo::{
    AlgoError,
    correlation::{
        engine::{self, CorrelatorState, Decision, PairCorrelator, Side, Statistic},
        grouping::{self, Link},
        scene::Scene,
    },
    motion::MotionModel,
    small,
    wire::{self, Reader, Writer},
};

/// First byte of every encoded session; a later release that changes the
/// format bumps it and keeps a decoder for the older ones. Format 1: the
/// first release. Format 2: covariances stored as upper triangles when
/// symmetric (scene format 2), and the last sequenced batch's update kept
/// for the replay of a retried batch.
pub const FORMAT_VERSION: u8 = 2;
/// Default idle expiry of a session.
pub const DEFAULT_IDLE_EXPIRY_S: f64 = 3600.0;
/// Default time (data time) after which a silent track is retired.
pub const DEFAULT_RETIRE_AFTER_S: f64 = 60.0;
/// Default number of instants kept for the replay of late-gated pairs.
pub const DEFAULT_HISTORY_INSTANTS: u32 = 32;
/// Largest history a session may ask for.
pub const MAX_HISTORY_INSTANTS: u32 = 1024;
/// Longest idle expiry a session may ask for (30 days).
pub const MAX_IDLE_EXPIRY_S: f64 = 30.0 * 86400.0;

/// A session as a client asks for it.
#[derive(Debug, Clone, Default)]
pub struct SessionSpec {
    /// The correlation configuration; `nodes` carry only their ids.
    pub config: CorrelateInput,
    pub idle_expiry_s: Option<f64>,
    pub retire_after_s: Option<f64>,
    pub history_instants: Option<u32>,
}

/// One batch of track reports.
#[derive(Debug, Clone, Default)]
pub struct BatchInput {
    /// The client's sequence number: 1, 2, 3, …; a batch already applied is
    /// acknowledged again without being applied.
    pub sequence: Option<u64>,
    pub reports: Vec<ReportInput>,
    /// Close the open instant now instead of waiting for a later report.
    pub flush: bool,
}

/// One track report: a local track's estimate at one time.
#[derive(Debug, Clone, Default)]
pub struct ReportInput {
    pub node: Option<String>,
    pub track: Option<String>,
    pub sample: SampleInput,
}

/// Limits of one session, from the service settings.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub max_tracks: usize,
    pub max_batch_reports: usize,
}

/// How a pair's published state changed in a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChangeKind {
    /// Decided correlated.
    Correlated,
    /// No longer correlated (revoked, or a track retired).
    Released,
    /// Became a trial system track (eq. 21).
    TrialFormed,
    /// Stopped being a trial system track without being decided.
    TrialEnded,
}

/// The API word of a change.
pub fn change_name(c: ChangeKind) -> &'static str {
    match c {
        ChangeKind::Correlated => "correlated",
        ChangeKind::Released => "released",
        ChangeKind::TrialFormed => "trial_formed",
        ChangeKind::TrialEnded => "trial_ended",
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct PairChange {
    pub a: TrackName,
    pub b: TrackName,
    pub change: ChangeKind,
}

/// What one batch changed.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchUpdate {
    pub session_id: String,
    pub sequence: Option<u64>,
    /// The session's version after the batch.
    pub version: u64,
    /// The batch had been applied before: nothing was applied now.
    pub duplicate: bool,
    /// Instants closed and correlated in this batch.
    pub instants: Vec<f64>,
    /// Reports waiting in the open instant.
    pub pending_reports: u32,
    pub changes: Vec<PairChange>,
    /// Pairs whose counters moved in this batch.
    pub pairs: Vec<PairOutput>,
    /// Every current system track (correlated group), fused at its latest
    /// instant.
    pub system_tracks: Vec<GroupOutput>,
    pub retired: Vec<TrackName>,
    pub warnings: Vec<String>,
}

/// A whole session, as a client reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionView {
    pub id: String,
    pub version: u64,
    pub created_unix_ms: u64,
    pub last_sequence: Option<u64>,
    pub batches: u64,
    pub instants_processed: u64,
    pub last_instant: Option<f64>,
    pub pending_reports: u32,
    pub reports_accepted: u64,
    pub reports_late: u64,
    pub idle_expiry_s: f64,
    pub retire_after_s: f64,
    pub history_instants: u32,
    pub method: String,
    pub nodes: Vec<NodeView>,
    pub pairs: Vec<PairOutput>,
    pub system_tracks: Vec<GroupOutput>,
    pub encoded_bytes: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NodeView {
    pub id: String,
    pub tracks: Vec<TrackView>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TrackView {
    pub id: String,
    /// Time of the last instant where the track was present.
    pub last_t: Option<f64>,
}

/// A track slot of a node: a live track, or free for reuse.
#[derive(Debug, Clone)]
struct Slot {
    /// Empty when free.
    id: String,
    last_t: Option<f64>,
    /// Retired in the current batch: freed at its end.
    retiring: bool,
}

#[derive(Debug, Clone)]
struct Pending {
    node: usize,
    slot: usize,
    t: f64,
    /// Canonical order.
    x: Vec<f64>,
    p: Vec<f64>,
    factor: Option<Vec<f64>>,
}

/// The state of a session.
pub struct Session {
    spec: SessionSpec,
    plan: Plan,
    idle_expiry_s: f64,
    retire_after_s: f64,
    history: usize,
    created_unix_ms: u64,
    scene: Scene,
    node_ids: Vec<String>,
    slots: Vec<Vec<Slot>>,
    by_id: Vec<HashMap<String, usize>>,
    /// One per node pair (na < nb), in the order of [`Session::node_pairs`].
    correlators: Vec<CorrelatorState>,
    pending: Vec<Pending>,
    /// Start of the last closed cluster: reports up to start + tolerance are late.
    closed_start: Option<f64>,
    last_sequence: Option<u64>,
    batches: u64,
    instants_processed: u64,
    reports_accepted: u64,
    reports_late: u64,
    /// The update of the last batch when it carried a sequence number: the
    /// answer replayed to a retry of that batch (its `version` is not kept).
    last_update: Option<BatchUpdate>,
}

fn internal(e: AlgoError) -> ServiceError {
    ServiceError::Internal(e.to_string())
}

impl Session {
    /// A new, empty session; validates the configuration.
    pub fn create(spec: SessionSpec, created_unix_ms: u64) -> Result<Self, ServiceError> {
        let plan = plan_of(&spec)?;
        let mut v = Violations::new();
        let idle = spec.idle_expiry_s.unwrap_or(DEFAULT_IDLE_EXPIRY_S);
        if !(idle.is_finite() && idle > 0.0 && idle <= MAX_IDLE_EXPIRY_S) {
            v.add(
                "idle_expiry_s",
                format!("must be a number of seconds in (0, {MAX_IDLE_EXPIRY_S}]"),
            );
        }
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
        let node_ids: Vec<String> = spec
            .config
            .nodes
            .iter()
            .map(|n| n.id.clone().unwrap_or_default())
            .collect();
        let mut scene =
            Scene::new(plan.layout.dim, plan.layout.positions(), Vec::new()).map_err(internal)?;
        for _ in &node_ids {
            scene.push_node();
        }
        let n = node_ids.len();
        Ok(Self {
            idle_expiry_s: idle,
            retire_after_s: retire,
            history: history as usize,
            created_unix_ms,
            scene,
            slots: vec![Vec::new(); n],
            by_id: vec![HashMap::new(); n],
            correlators: vec![CorrelatorState::default(); n * (n - 1) / 2],
            node_ids,
            pending: Vec::new(),
            closed_start: None,
            last_sequence: None,
            batches: 0,
            instants_processed: 0,
            reports_accepted: 0,
            reports_late: 0,
            last_update: None,
            plan,
            spec,
        })
    }

    pub fn idle_expiry_s(&self) -> f64 {
        self.idle_expiry_s
    }

    pub fn last_sequence(&self) -> Option<u64> {
        self.last_sequence
    }

    fn node_pairs(&self) -> Vec<(usize, usize)> {
        let n = self.node_ids.len();
        (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .collect()
    }

    fn name(&self, node: usize, slot: usize) -> TrackName {
        TrackName {
            node: self.node_ids[node].clone(),
            track: self.slots[node][slot].id.clone(),
        }
    }

    fn live_tracks(&self) -> usize {
        self.slots
            .iter()
            .flatten()
            .filter(|s| !s.id.is_empty())
            .count()
    }

    /// Whether a batch with this sequence number was applied already
    /// (`Ok(true)`), is next (`Ok(false)`), or skips ahead (a conflict naming
    /// the expected number). Sequences start at 1, so that the first batch of
    /// two concurrent writers cannot be mistaken for a duplicate; 0 is invalid.
    pub fn check_sequence(&self, sequence: Option<u64>) -> Result<bool, ServiceError> {
        let Some(s) = sequence else {
            return Ok(false);
        };
        if s == 0 {
            return Err(ServiceError::InvalidInput(vec![FieldViolation {
                field: "sequence".into(),
                message: "must be at least 1 (the first batch carries 1)".into(),
            }]));
        }
        let last = self.last_sequence.unwrap_or(0);
        if s <= last {
            Ok(true)
        } else if s == last + 1 {
            Ok(false)
        } else {
            Err(ServiceError::Conflict(format!(
                "batch sequence {s} skips ahead: the session has applied {}, so the next \
                 batch must carry {}",
                if last == 0 {
                    "no sequenced batch".to_string()
                } else {
                    last.to_string()
                },
                last + 1
            )))
        }
    }

    /// Applies one batch. On error the session is unchanged only if the
    /// caller discards it: the caller works on a decoded copy.
    pub fn apply(
        &mut self,
        id: &str,
        batch: BatchInput,
        limits: &Limits,
    ) -> Result<BatchUpdate, ServiceError> {
        if batch.reports.len() > limits.max_batch_reports {
            return Err(ServiceError::TooLarge(format!(
                "the batch holds {} reports; the limit is {} per batch",
                batch.reports.len(),
                limits.max_batch_reports
            )));
        }
        let tol = self.plan.tolerance;
        let mut v = Violations::new();
        // Validate every report before touching the state.
        let mut accepted: Vec<(usize, String, f64, &ReportInput)> = Vec::new();
        for (i, r) in batch.reports.iter().enumerate() {
            let field = format!("reports[{i}]");
            let node = match r.node.as_deref() {
                None | Some("") => {
                    v.add(format!("{field}.node"), "is required");
                    None
                }
                Some(n) => match self.node_ids.iter().position(|x| x == n) {
                    Some(ni) => Some(ni),
                    None => {
                        v.add(
                            format!("{field}.node"),
                            format!(
                                "unknown node '{n}': the session has {}",
                                self.node_ids.join(", ")
                            ),
                        );
                        None
                    }
                },
            };
            let track = match r.track.as_deref() {
                None | Some("") => {
                    v.add(format!("{field}.track"), "is required");
                    None
                }
                Some(t) if t.len() > 256 => {
                    v.add(format!("{field}.track"), "is longer than 256 bytes");
                    None
                }
                Some(t) => Some(t.to_string()),
            };
            let t = match r.sample.t {
                None => {
                    v.add(format!("{field}.t"), "is required");
                    None
                }
                Some(t) if !t.is_finite() => {
                    v.add(format!("{field}.t"), "must be finite");
                    None
                }
                Some(t) => Some(t),
            };
            correlation::check_sample(
                &mut v,
                &field,
                &r.sample,
                &self.plan.layout,
                self.plan.h.as_ref(),
                self.spec.config.measurement_matrix.is_some(),
            );
            if let (Some(n), Some(tr), Some(t)) = (node, track, t) {
                accepted.push((n, tr, t, r));
            }
        }
        v.finish()?;
        let new_ids: HashSet<(usize, &str)> = accepted
            .iter()
            .filter(|(n, tr, ..)| !self.by_id[*n].contains_key(tr.as_str()))
            .map(|(n, tr, ..)| (*n, tr.as_str()))
            .collect();
        if self.live_tracks() + new_ids.len() > limits.max_tracks {
            return Err(ServiceError::QuotaExceeded(format!(
                "the batch would bring the session to {} tracks; the limit is {} per session",
                self.live_tracks() + new_ids.len(),
                limits.max_tracks
            )));
        }

        let mut warnings = Vec::new();
        let horizon = self.closed_start.map(|s| s + tol);
        let mut late = 0u64;
        for (node, track, t, r) in accepted {
            if horizon.is_some_and(|h| t <= h) {
                late += 1;
                continue;
            }
            let slot = self.slot_for(node, &track);
            let layout = &self.plan.layout;
            let x = layout.vector_to_canonical(&r.sample.state);
            let p = layout.matrix_to_canonical(&r.sample.covariance);
            let factor = match (&r.sample.gain, &self.plan.h) {
                (Some(g), Some(h)) => Some(gain_factor(g, h, layout)),
                _ => None,
            };
            self.pending.push(Pending {
                node,
                slot,
                t,
                x,
                p,
                factor,
            });
            self.reports_accepted += 1;
        }
        if late > 0 {
            self.reports_late += late;
            warnings.push(format!(
                "{late} report(s) fell in an instant already closed (at or before {} s) and \
                 were dropped",
                horizon.unwrap_or(f64::NAN)
            ));
        }

        // Close the clusters that can no longer grow.
        self.pending.sort_by(|a, b| a.t.total_cmp(&b.t));
        let mut clusters: Vec<(usize, usize, f64)> = Vec::new(); // [from, to), start
        for (i, r) in self.pending.iter().enumerate() {
            match clusters.last_mut() {
                Some((_, to, start)) if r.t - *start <= tol => *to = i + 1,
                _ => clusters.push((i, i + 1, r.t)),
            }
        }
        if !batch.flush {
            clusters.pop();
        }
        let closed = clusters.last().map_or(0, |c| c.1);
        let reports: Vec<Pending> = self.pending.drain(..closed).collect();
        let before: Vec<Vec<(usize, usize, bool, bool)>> = self
            .correlators
            .iter()
            .map(|c| c.links().collect())
            .collect();
        let first_new = self.scene.end();
        let mut instants = Vec::new();
        let mut retire_at: Vec<(usize, usize, usize)> = Vec::new(); // (k, node, slot)
        let mut superseded = 0usize;
        let mut predicted = 0usize;
        for &(from, to, start) in &clusters {
            let group = &reports[from..to];
            let t_k = group.last().expect("clusters are not empty").t;
            let k = self.scene.push_instant(t_k).map_err(internal)?;
            instants.push(t_k);
            self.closed_start = Some(start);
            // The latest report of each track (stable sort: ties keep arrival order).
            let mut latest: HashMap<(usize, usize), &Pending> = HashMap::new();
            for r in group {
                if latest.insert((r.node, r.slot), r).is_some() {
                    superseded += 1;
                }
            }
            let mut keys: Vec<_> = latest.keys().copied().collect();
            keys.sort_unstable();
            for key in keys {
                let r = latest[&key];
                predicted += usize::from(self.fill(k, r)?);
                self.slots[r.node][r.slot].last_t = Some(t_k);
            }
            for (node, slots) in self.slots.iter_mut().enumerate() {
                for (slot, s) in slots.iter_mut().enumerate() {
                    if !s.id.is_empty()
                        && !s.retiring
                        && s.last_t.is_some_and(|lt| t_k - lt > self.retire_after_s)
                    {
                        s.retiring = true;
                        retire_at.push((k, node, slot));
                    }
                }
            }
        }
        self.instants_processed += instants.len() as u64;
        if superseded > 0 {
            warnings.push(format!(
                "{superseded} report(s) were superseded by a later report of the same track \
                 within one alignment instant (tolerance {tol} s) and ignored"
            ));
        }
        if predicted > 0 {
            warnings.push(format!(
                "{predicted} report(s) were predicted forward (at most {tol} s) to a common instant"
            ));
        }

        // Correlate every node pair over the new instants, releasing the
        // pairs of retired tracks at the instant they retire.
        let model_ref: Option<&dyn MotionModel> =
            self.plan.model.as_ref().map(|m| m as &dyn MotionModel);
        let end = self.scene.end();
        let mut reports_out = Vec::new();
        let mut links = Vec::new();
        let mut cross: CrossCovariances = HashMap::new();
        let mut singular = 0usize;
        for (ci, (na, nb)) in self.node_pairs().into_iter().enumerate() {
            let mut state = std::mem::take(&mut self.correlators[ci]);
            let mut cuts: Vec<usize> = retire_at
                .iter()
                .filter(|r| r.1 == na || r.1 == nb)
                .map(|r| r.0)
                .collect();
            cuts.dedup();
            cuts.push(end);
            for cut in cuts {
                let mut c = PairCorrelator::resume(
                    &self.scene,
                    na,
                    nb,
                    &self.plan.config,
                    model_ref,
                    state,
                )
                .map_err(|e| super::Violations::from_param("method.", e))?;
                c.run_until(cut);
                state = c.into_state();
                for &(k, node, slot) in &retire_at {
                    if k == cut && (node == na || node == nb) {
                        state.release(if node == na { Side::A } else { Side::B }, slot);
                    }
                }
            }
            let c =
                PairCorrelator::resume(&self.scene, na, nb, &self.plan.config, model_ref, state)
                    .map_err(internal)?;
            singular += c.singular_tests;
            for r in c.reports() {
                correlation::collect_link(&r, na, nb, &mut links, &mut cross);
                if r.last_common >= first_new && r.last_common < end {
                    reports_out.push((na, nb, r));
                }
            }
            self.correlators[ci] = c.into_state();
        }
        if singular > 0 && self.plan.config.statistic == Statistic::Modified {
            warnings.push(format!(
                "{singular} test(s) of the modified statistic so far fell back to the weighted \
                 statistic (P_a + P_b − P_ab − P_ab' not positive definite)"
            ));
        }

        // What changed.
        let mut changes = Vec::new();
        let pairs = self.node_pairs();
        for (ci, &(na, nb)) in pairs.iter().enumerate() {
            let old: HashMap<(usize, usize), (bool, bool)> = before[ci]
                .iter()
                .map(|&(a, b, d, t)| ((a, b), (d, t)))
                .collect();
            let new: HashMap<(usize, usize), (bool, bool)> = self.correlators[ci]
                .links()
                .map(|(a, b, d, t)| ((a, b), (d, t)))
                .collect();
            let keys: BTreeSet<(usize, usize)> = old.keys().chain(new.keys()).copied().collect();
            for key in keys {
                let (od, ot) = old.get(&key).copied().unwrap_or((false, false));
                let (nd, nt) = new.get(&key).copied().unwrap_or((false, false));
                let kind = match (od, nd, ot, nt) {
                    (false, true, ..) => Some(ChangeKind::Correlated),
                    (true, false, ..) => Some(ChangeKind::Released),
                    (false, false, false, true) => Some(ChangeKind::TrialFormed),
                    (false, false, true, false) => Some(ChangeKind::TrialEnded),
                    _ => None,
                };
                if let Some(change) = kind {
                    changes.push(PairChange {
                        a: self.name(na, key.0),
                        b: self.name(nb, key.1),
                        change,
                    });
                }
            }
        }
        let pairs_out = reports_out
            .iter()
            .map(|(na, nb, r)| {
                correlation::pair_output(r, self.name(*na, r.a), self.name(*nb, r.b))
            })
            .collect();
        let system_tracks = self.system_tracks(&links, &cross);

        // Free the retired slots and trim the history.
        let mut retired = Vec::new();
        for &(_, node, slot) in &retire_at {
            retired.push(self.name(node, slot));
            let id = std::mem::take(&mut self.slots[node][slot].id);
            self.by_id[node].remove(&id);
            self.slots[node][slot] = Slot {
                id: String::new(),
                last_t: None,
                retiring: false,
            };
            self.scene.clear_track(node, slot);
        }
        if self.scene.times().len() > 2 * self.history {
            self.scene.trim_before(self.scene.end() - self.history);
        }
        if batch.sequence.is_some() {
            self.last_sequence = batch.sequence;
        }
        self.batches += 1;
        let update = BatchUpdate {
            session_id: id.to_string(),
            sequence: batch.sequence,
            version: 0,
            duplicate: false,
            instants,
            pending_reports: self.pending.len() as u32,
            changes,
            pairs: pairs_out,
            system_tracks,
            retired,
            warnings,
        };
        self.last_update = batch.sequence.map(|_| update.clone());
        Ok(update)
    }

    /// The answer to a batch whose sequence number was applied before
    /// ([`Session::check_sequence`] said so): nothing is applied. A retry of
    /// the last batch gets that batch's update again (the same changes,
    /// pairs and system tracks), so a client whose answer was lost loses
    /// nothing; an older number gets an empty acknowledgement. `version` is
    /// the session's current version.
    pub fn duplicate_ack(&self, id: &str, sequence: u64, version: u64) -> BatchUpdate {
        let last = self.last_sequence.unwrap_or_default();
        // `last_update` is kept only for a sequenced batch, so its sequence
        // is the session's last one.
        let replay = self
            .last_update
            .as_ref()
            .filter(|u| u.sequence == Some(sequence));
        let mut update = match replay {
            Some(u) => {
                let mut u = u.clone();
                u.warnings.push(format!(
                    "batch {sequence} was applied before: this is its update again; \
                     it was not applied twice"
                ));
                u
            }
            None => BatchUpdate {
                session_id: String::new(),
                sequence: Some(sequence),
                version,
                duplicate: true,
                instants: Vec::new(),
                pending_reports: self.pending.len() as u32,
                changes: Vec::new(),
                pairs: Vec::new(),
                system_tracks: Vec::new(),
                retired: Vec::new(),
                warnings: vec![format!(
                    "batch {sequence} was applied before (the session has applied up to \
                     {last}): acknowledged, not applied again"
                )],
            },
        };
        update.session_id = id.to_string();
        update.version = version;
        update.duplicate = true;
        update
    }

    /// The slot of a track, allocating one (reusing a freed slot) for a new id.
    fn slot_for(&mut self, node: usize, track: &str) -> usize {
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
    fn fill(&mut self, k: usize, r: &Pending) -> Result<bool, ServiceError> {
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

    fn system_tracks(&self, links: &[Link], cross: &CrossCovariances) -> Vec<GroupOutput> {
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
    pub fn view(
        &self,
        id: &str,
        version: u64,
        encoded_bytes: usize,
    ) -> Result<SessionView, ServiceError> {
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
            id: id.to_string(),
            version,
            created_unix_ms: self.created_unix_ms,
            last_sequence: self.last_sequence,
            batches: self.batches,
            instants_processed: self.instants_processed,
            last_instant: self.scene.times().last().copied(),
            pending_reports: self.pending.len() as u32,
            reports_accepted: self.reports_accepted,
            reports_late: self.reports_late,
            idle_expiry_s: self.idle_expiry_s,
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
            encoded_bytes,
        })
    }

    /// The compact versioned binary form of the session.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.u8(FORMAT_VERSION);
        encode_spec(&mut w, &self.spec);
        w.f64(self.idle_expiry_s);
        w.f64(self.retire_after_s);
        w.usize(self.history);
        w.u64(self.created_unix_ms);
        w.opt(self.last_sequence, Writer::u64);
        w.u64(self.batches);
        w.u64(self.instants_processed);
        w.u64(self.reports_accepted);
        w.u64(self.reports_late);
        w.opt(self.closed_start, Writer::f64);
        self.scene.encode(&mut w);
        for slots in &self.slots {
            w.usize(slots.len());
            for s in slots {
                w.str(&s.id);
                w.opt(s.last_t, Writer::f64);
            }
        }
        let dim = self.plan.layout.dim;
        for c in &self.correlators {
            c.encode(&mut w, dim);
        }
        w.usize(self.pending.len());
        for p in &self.pending {
            w.usize(p.node);
            w.usize(p.slot);
            w.f64(p.t);
            w.f64s(&p.x);
            w.f64s(&p.p);
            w.opt(p.factor.as_deref(), Writer::f64s);
        }
        w.opt(self.last_update.as_ref(), encode_update);
        w.buf
    }

    /// Reads a session written by [`Session::encode`] (any format version
    /// this release knows).
    pub fn decode(buf: &[u8]) -> Result<Self, ServiceError> {
        let corrupt = |e: AlgoError| ServiceError::Internal(format!("stored session: {e}"));
        let mut r = Reader::new(buf);
        let version = r.u8().map_err(corrupt)?;
        if !(1..=FORMAT_VERSION).contains(&version) {
            return Err(ServiceError::Internal(format!(
                "stored session has format {version}; this release reads 1 to {FORMAT_VERSION}"
            )));
        }
        let spec = decode_spec(&mut r).map_err(corrupt)?;
        let plan = plan_of(&spec)?;
        let node_ids: Vec<String> = spec
            .config
            .nodes
            .iter()
            .map(|n| n.id.clone().unwrap_or_default())
            .collect();
        let n = node_ids.len();
        let (idle_expiry_s, retire_after_s) =
            (r.f64().map_err(corrupt)?, r.f64().map_err(corrupt)?);
        let history = r.usize().map_err(corrupt)?;
        let created_unix_ms = r.u64().map_err(corrupt)?;
        let last_sequence = r.opt(Reader::u64).map_err(corrupt)?;
        let batches = r.u64().map_err(corrupt)?;
        let instants_processed = r.u64().map_err(corrupt)?;
        let reports_accepted = r.u64().map_err(corrupt)?;
        let reports_late = r.u64().map_err(corrupt)?;
        let closed_start = r.opt(Reader::f64).map_err(corrupt)?;
        // Session format 1 holds scene format 1, format 2 scene format 2.
        let scene = Scene::decode(&mut r, version).map_err(corrupt)?;
        if scene.nodes().len() != n || scene.dim() != plan.layout.dim {
            return Err(ServiceError::Internal("stored session: scene shape".into()));
        }
        let mut slots = Vec::with_capacity(n);
        let mut by_id = Vec::with_capacity(n);
        for node in 0..n {
            let count = r.len(9).map_err(corrupt)?;
            if count != scene.nodes()[node].len() {
                return Err(ServiceError::Internal("stored session: track slots".into()));
            }
            let mut list = Vec::with_capacity(count);
            let mut ids = HashMap::new();
            for i in 0..count {
                let id = r.str().map_err(corrupt)?;
                let last_t = r.opt(Reader::f64).map_err(corrupt)?;
                if !id.is_empty() {
                    ids.insert(id.clone(), i);
                }
                list.push(Slot {
                    id,
                    last_t,
                    retiring: false,
                });
            }
            slots.push(list);
            by_id.push(ids);
        }
        let dim = plan.layout.dim;
        let mut correlators = Vec::new();
        for _ in 0..n * (n - 1) / 2 {
            correlators.push(CorrelatorState::decode(&mut r, dim).map_err(corrupt)?);
        }
        let np = r.len(24).map_err(corrupt)?;
        let mut pending = Vec::with_capacity(np);
        for _ in 0..np {
            let node = r.usize().map_err(corrupt)?;
            let slot = r.usize().map_err(corrupt)?;
            let t = r.f64().map_err(corrupt)?;
            let x = r.f64s().map_err(corrupt)?;
            let p = r.f64s().map_err(corrupt)?;
            let factor = r.opt(Reader::f64s).map_err(corrupt)?;
            if node >= n || slot >= slots[node].len() || x.len() != dim || p.len() != dim * dim {
                return Err(ServiceError::Internal(
                    "stored session: pending report".into(),
                ));
            }
            pending.push(Pending {
                node,
                slot,
                t,
                x,
                p,
                factor,
            });
        }
        let last_update = if version >= 2 {
            r.opt(decode_update).map_err(corrupt)?
        } else {
            None
        };
        if !r.is_empty() {
            return Err(ServiceError::Internal(
                "stored session: trailing bytes".into(),
            ));
        }
        Ok(Self {
            spec,
            plan,
            idle_expiry_s,
            retire_after_s,
            history,
            created_unix_ms,
            scene,
            node_ids,
            slots,
            by_id,
            correlators,
            pending,
            closed_start,
            last_sequence,
            batches,
            instants_processed,
            reports_accepted,
            reports_late,
            last_update,
        })
    }
}

fn plan_of(spec: &SessionSpec) -> Result<Plan, ServiceError> {
    correlation::validate_plan(&spec.config)
}

/// I − K H in canonical order from a gain K in the request's row order.
fn gain_factor(g: &[Vec<f64>], h: &DMatrix<f64>, layout: &correlation::Layout) -> Vec<f64> {
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

fn opt_str(w: &mut Writer, v: &Option<String>) {
    w.opt(v.as_deref(), Writer::str);
}

/// Stable codes of the enums kept in an encoded update (append only).
const DECISIONS: [Decision; 3] = [
    Decision::Correlated,
    Decision::NotCorrelated,
    Decision::Undecided,
];
const FUSION_KINDS: [FusionKind; 4] = [
    FusionKind::BarShalomCampo,
    FusionKind::CovarianceIntersection,
    FusionKind::Single,
    FusionKind::None,
];
const CHANGE_KINDS: [ChangeKind; 4] = [
    ChangeKind::Correlated,
    ChangeKind::Released,
    ChangeKind::TrialFormed,
    ChangeKind::TrialEnded,
];

fn code_of<T: PartialEq>(list: &[T], v: &T) -> u8 {
    list.iter()
        .position(|x| x == v)
        .expect("every variant is listed") as u8
}

fn of_code<T: Copy>(list: &[T], r: &mut Reader<'_>, what: &str) -> Result<T, AlgoError> {
    let c = r.u8()?;
    list.get(usize::from(c))
        .copied()
        .ok_or_else(|| wire::corrupt(&format!("unknown {what} code {c}")))
}

fn encode_name(w: &mut Writer, n: &TrackName) {
    w.str(&n.node);
    w.str(&n.track);
}

fn decode_name(r: &mut Reader<'_>) -> Result<TrackName, AlgoError> {
    Ok(TrackName {
        node: r.str()?,
        track: r.str()?,
    })
}

fn decode_list<'a, T>(
    r: &mut Reader<'a>,
    f: impl Fn(&mut Reader<'a>) -> Result<T, AlgoError>,
) -> Result<Vec<T>, AlgoError> {
    let n = r.len(1)?;
    (0..n).map(|_| f(r)).collect()
}

/// Appends a batch update (all but its session id, version and duplicate flag).
fn encode_update(w: &mut Writer, u: &BatchUpdate) {
    w.opt(u.sequence, Writer::u64);
    w.f64s(&u.instants);
    w.u32(u.pending_reports);
    w.usize(u.changes.len());
    for c in &u.changes {
        encode_name(w, &c.a);
        encode_name(w, &c.b);
        w.u8(code_of(&CHANGE_KINDS, &c.change));
    }
    w.usize(u.pairs.len());
    for p in &u.pairs {
        encode_name(w, &p.a);
        encode_name(w, &p.b);
        w.u8(code_of(&DECISIONS, &p.decision));
        w.u8(code_of(&engine::REASONS, &p.reason));
        w.bool(p.trial);
        w.u32(p.m);
        w.u32(p.c);
        w.u32(p.samples);
        w.f64(p.mean_statistic);
        w.f64(p.last_statistic);
        w.opt(p.decided_at, Writer::f64);
    }
    w.usize(u.system_tracks.len());
    for g in &u.system_tracks {
        w.u32(g.id);
        w.usize(g.members.len());
        g.members.iter().for_each(|m| encode_name(w, m));
        w.f64(g.t);
        w.f64s(&g.state);
        w.usize(g.covariance.len());
        g.covariance.iter().for_each(|row| w.f64s(row));
        w.u8(code_of(&FUSION_KINDS, &g.fusion));
    }
    w.usize(u.retired.len());
    u.retired.iter().for_each(|n| encode_name(w, n));
    w.usize(u.warnings.len());
    u.warnings.iter().for_each(|s| w.str(s));
}

/// Reads a batch update written by [`encode_update`].
fn decode_update(r: &mut Reader<'_>) -> Result<BatchUpdate, AlgoError> {
    let sequence = r.opt(Reader::u64)?;
    let instants = r.f64s()?;
    let pending_reports = r.u32()?;
    let changes = decode_list(r, |r| {
        Ok(PairChange {
            a: decode_name(r)?,
            b: decode_name(r)?,
            change: of_code(&CHANGE_KINDS, r, "change")?,
        })
    })?;
    let pairs = decode_list(r, |r| {
        Ok(PairOutput {
            a: decode_name(r)?,
            b: decode_name(r)?,
            decision: of_code(&DECISIONS, r, "decision")?,
            reason: of_code(&engine::REASONS, r, "reason")?,
            trial: r.bool()?,
            m: r.u32()?,
            c: r.u32()?,
            samples: r.u32()?,
            mean_statistic: r.f64()?,
            last_statistic: r.f64()?,
            decided_at: r.opt(Reader::f64)?,
        })
    })?;
    let system_tracks = decode_list(r, |r| {
        Ok(GroupOutput {
            id: r.u32()?,
            members: decode_list(r, decode_name)?,
            t: r.f64()?,
            state: r.f64s()?,
            covariance: decode_list(r, Reader::f64s)?,
            fusion: of_code(&FUSION_KINDS, r, "fusion")?,
        })
    })?;
    Ok(BatchUpdate {
        session_id: String::new(),
        sequence,
        version: 0,
        duplicate: false,
        instants,
        pending_reports,
        changes,
        pairs,
        system_tracks,
        retired: decode_list(r, decode_name)?,
        warnings: decode_list(r, Reader::str)?,
    })
}

fn encode_spec(w: &mut Writer, spec: &SessionSpec) {
    let c = &spec.config;
    w.usize(c.state_layout.len());
    c.state_layout.iter().for_each(|s| w.str(s));
    w.opt(c.method.as_ref(), |w, m| {
        opt_str(w, &m.kind);
        w.opt(m.alpha, Writer::f64);
        let rule = |w: &mut Writer, r: &RuleInput| {
            w.opt(r.l, Writer::u32);
            w.opt(r.r, Writer::u32);
        };
        w.opt(m.rule.as_ref(), rule);
        w.opt(m.schedule.as_ref(), |w, s| {
            w.usize(s.len());
            s.iter().for_each(|r| rule(w, r));
        });
        w.opt(m.dynamic_schedule, Writer::bool);
        opt_str(w, &m.statistic);
        w.opt(m.window, Writer::u32);
        w.opt(m.k, Writer::u32);
    });
    w.opt(c.motion_model.as_ref(), |w, m| {
        opt_str(w, &m.kind);
        opt_str(w, &m.process_noise);
        w.opt(m.sigma_a_mps2, Writer::f64);
        w.opt(m.q_m2ps3, Writer::f64);
        w.opt(m.factor, Writer::f64);
    });
    w.opt(c.alignment.as_ref(), |w, a| {
        opt_str(w, &a.mode);
        w.opt(a.max_gap_s, Writer::f64);
        w.opt(a.tolerance_s, Writer::f64);
    });
    w.opt(c.measurement_matrix.as_ref(), |w, h| {
        w.usize(h.len());
        h.iter().for_each(|row| w.f64s(row));
    });
    w.usize(c.nodes.len());
    c.nodes.iter().for_each(|n| opt_str(w, &n.id));
    opt_str(w, &c.pruning);
    w.opt(c.fuse, Writer::bool);
    w.opt(spec.idle_expiry_s, Writer::f64);
    w.opt(spec.retire_after_s, Writer::f64);
    w.opt(spec.history_instants, Writer::u32);
}

fn decode_spec(r: &mut Reader<'_>) -> Result<SessionSpec, AlgoError> {
    let n = r.len(8)?;
    let state_layout = (0..n).map(|_| r.str()).collect::<Result<_, _>>()?;
    let s = |r: &mut Reader<'_>| r.opt(Reader::str);
    let method = r.opt(|r| {
        let rule = |r: &mut Reader<'_>| {
            Ok(RuleInput {
                l: r.opt(Reader::u32)?,
                r: r.opt(Reader::u32)?,
            })
        };
        Ok(MethodInput {
            kind: s(r)?,
            alpha: r.opt(Reader::f64)?,
            rule: r.opt(rule)?,
            schedule: r.opt(|r| {
                let n = r.len(2)?;
                (0..n).map(|_| rule(r)).collect()
            })?,
            dynamic_schedule: r.opt(Reader::bool)?,
            statistic: s(r)?,
            window: r.opt(Reader::u32)?,
            k: r.opt(Reader::u32)?,
        })
    })?;
    let motion_model = r.opt(|r| {
        Ok(MotionModelInput {
            kind: s(r)?,
            process_noise: s(r)?,
            sigma_a_mps2: r.opt(Reader::f64)?,
            q_m2ps3: r.opt(Reader::f64)?,
            factor: r.opt(Reader::f64)?,
        })
    })?;
    let alignment = r.opt(|r| {
        Ok(AlignmentInput {
            mode: s(r)?,
            max_gap_s: r.opt(Reader::f64)?,
            tolerance_s: r.opt(Reader::f64)?,
        })
    })?;
    let measurement_matrix = r.opt(|r| {
        let n = r.len(8)?;
        (0..n).map(|_| r.f64s()).collect()
    })?;
    let n = r.len(1)?;
    let nodes = (0..n)
        .map(|_| {
            Ok(NodeInput {
                id: s(r)?,
                tracks: Vec::new(),
            })
        })
        .collect::<Result<_, AlgoError>>()?;
    let pruning = s(r)?;
    let fuse = r.opt(Reader::bool)?;
    Ok(SessionSpec {
        config: CorrelateInput {
            state_layout,
            method,
            motion_model,
            alignment,
            measurement_matrix,
            nodes,
            pruning,
            fuse,
        },
        idle_expiry_s: r.opt(Reader::f64)?,
        retire_after_s: r.opt(Reader::f64)?,
        history_instants: r.opt(Reader::u32)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::correlation::{TrackInput, correlate};

    /// A small deterministic generator (xorshift) for test noise.
    struct Noise(u64);

    impl Noise {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    /// Two radars, eight targets (two pairs of them crossing, so that some
    /// pairs enter the gate late), radar b reporting 0.2 s after radar a,
    /// with one track of b starting late and one of a ending early.
    fn scenario() -> CorrelateInput {
        let mut noise = Noise(0x9e37_79b9_7f4a_7c15);
        let mut nodes = Vec::new();
        for (ni, (node, offset)) in [("a", 0.0), ("b", 0.2)].into_iter().enumerate() {
            let mut tracks = Vec::new();
            for target in 0..8 {
                let (x0, y0, vx, vy) = match target {
                    0 => (0.0, 0.0, 100.0, 0.0),
                    1 => (3000.0, 0.0, -100.0, 0.0),
                    2 => (0.0, 2000.0, 50.0, 50.0),
                    3 => (0.0, 2600.0, 50.0, -50.0),
                    t => (t as f64 * 4000.0, 9000.0, 0.0, 80.0),
                };
                let mut samples = Vec::new();
                for scan in 0..30 {
                    if (ni == 1 && target == 5 && scan < 12)
                        || (ni == 0 && target == 6 && scan > 20)
                    {
                        continue;
                    }
                    let t = scan as f64 * 2.0 + offset;
                    let e = 30.0;
                    samples.push(SampleInput {
                        t: Some(t),
                        state: vec![
                            x0 + vx * t + e * noise.next(),
                            vx + noise.next(),
                            y0 + vy * t + e * noise.next(),
                            vy + noise.next(),
                        ],
                        covariance: vec![
                            vec![400.0, 10.0, 0.0, 0.0],
                            vec![10.0, 25.0, 0.0, 0.0],
                            vec![0.0, 0.0, 400.0, 10.0],
                            vec![0.0, 0.0, 10.0, 25.0],
                        ],
                        gain: None,
                    });
                }
                tracks.push(TrackInput {
                    id: Some(format!("{node}{target}")),
                    samples,
                });
            }
            nodes.push(NodeInput {
                id: Some(node.into()),
                tracks,
            });
        }
        CorrelateInput {
            state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
            method: Some(MethodInput {
                kind: Some("dependent_double_threshold".into()),
                rule: Some(RuleInput {
                    l: Some(3),
                    r: Some(4),
                }),
                ..Default::default()
            }),
            motion_model: Some(MotionModelInput {
                process_noise: Some("dwna".into()),
                sigma_a_mps2: Some(1.0),
                ..Default::default()
            }),
            alignment: Some(AlignmentInput {
                tolerance_s: Some(0.5),
                ..Default::default()
            }),
            nodes,
            ..Default::default()
        }
    }

    fn reports_of(input: &CorrelateInput) -> Vec<ReportInput> {
        let mut out: Vec<ReportInput> = input
            .nodes
            .iter()
            .flat_map(|n| {
                n.tracks.iter().flat_map(move |t| {
                    t.samples.iter().map(move |s| ReportInput {
                        node: n.id.clone(),
                        track: t.id.clone(),
                        sample: s.clone(),
                    })
                })
            })
            .collect();
        out.sort_by(|a, b| a.sample.t.unwrap().total_cmp(&b.sample.t.unwrap()));
        out
    }

    fn session_of(input: &CorrelateInput, history: u32) -> Session {
        let mut config = input.clone();
        for n in &mut config.nodes {
            n.tracks.clear();
        }
        Session::create(
            SessionSpec {
                config,
                history_instants: Some(history),
                retire_after_s: Some(1e6),
                ..Default::default()
            },
            0,
        )
        .unwrap()
    }

    const LIMITS: Limits = Limits {
        max_tracks: 1000,
        max_batch_reports: 10_000,
    };

    /// Pushes the reports in batches of `size`, through an encode/decode
    /// round trip between batches (as the store does), then flushes.
    fn run_session(input: &CorrelateInput, size: usize, history: u32) -> SessionView {
        let reports = reports_of(input);
        let mut bytes = session_of(input, history).encode();
        for (i, chunk) in reports.chunks(size).enumerate() {
            let mut s = Session::decode(&bytes).unwrap();
            s.apply(
                "s",
                BatchInput {
                    sequence: Some(i as u64 + 1),
                    reports: chunk.to_vec(),
                    flush: false,
                },
                &LIMITS,
            )
            .unwrap();
            bytes = s.encode();
        }
        let mut s = Session::decode(&bytes).unwrap();
        s.apply(
            "s",
            BatchInput {
                flush: true,
                ..Default::default()
            },
            &LIMITS,
        )
        .unwrap();
        s.view("s", 0, 0).unwrap()
    }

    #[test]
    fn batches_give_the_decisions_of_the_batch_endpoint() {
        let input = scenario();
        let batch = correlate(input.clone()).unwrap();
        assert!(
            batch
                .pairs
                .iter()
                .filter(|p| p.decision == Decision::Correlated)
                .count()
                >= 6,
            "the scenario must correlate most targets: {:?}",
            batch.pairs
        );
        // History 64 covers the 30 instants: exact whatever the batching.
        for size in [1, 7, 16, 1000] {
            let view = run_session(&input, size, 64);
            assert_eq!(view.instants_processed as usize, batch.instants.len());
            assert_eq!(view.pairs, batch.pairs, "batches of {size}");
            assert_eq!(view.system_tracks, batch.groups, "batches of {size}");
        }
    }

    #[test]
    fn a_short_history_keeps_the_decided_pairs_of_well_separated_targets() {
        let input = scenario();
        let batch = correlate(input.clone()).unwrap();
        let view = run_session(&input, 5, 4);
        let decided = |pairs: &[PairOutput]| -> Vec<(String, String)> {
            pairs
                .iter()
                .filter(|p| p.decision == Decision::Correlated)
                .map(|p| (p.a.track.clone(), p.b.track.clone()))
                .collect()
        };
        assert_eq!(decided(&view.pairs), decided(&batch.pairs));
    }

    #[test]
    fn late_reports_are_dropped_and_silent_tracks_retire() {
        let input = scenario();
        let mut s = session_of(&input, 8);
        s.retire_after_s = 5.0;
        let reports = reports_of(&input);
        let early: Vec<_> = reports
            .iter()
            .filter(|r| r.sample.t.unwrap() < 20.0)
            .cloned()
            .collect();
        s.apply(
            "s",
            BatchInput {
                reports: early.clone(),
                flush: true,
                sequence: None,
            },
            &LIMITS,
        )
        .unwrap();
        let again = s
            .apply(
                "s",
                BatchInput {
                    reports: early[..3].to_vec(),
                    ..Default::default()
                },
                &LIMITS,
            )
            .unwrap();
        assert!(
            again.warnings.iter().any(|w| w.contains("dropped")),
            "{again:?}"
        );
        assert_eq!(s.reports_late, 3);
        // Node a's track 6 stops after scan 20 (t = 40): retired once an
        // instant more than 5 s later is closed.
        let rest: Vec<_> = reports
            .iter()
            .filter(|r| r.sample.t.unwrap() >= 20.0)
            .cloned()
            .collect();
        let u = s
            .apply(
                "s",
                BatchInput {
                    reports: rest,
                    flush: true,
                    sequence: None,
                },
                &LIMITS,
            )
            .unwrap();
        assert!(
            u.retired.iter().any(|t| t.node == "a" && t.track == "a6"),
            "{:?}",
            u.retired
        );
        let view = s.view("s", 0, 0).unwrap();
        assert!(view.nodes[0].tracks.iter().all(|t| t.id != "a6"));
        assert!(view.pairs.iter().all(|p| p.a.track != "a6"));
    }

    #[test]
    fn sequences_are_checked() {
        let mut s = session_of(&scenario(), 8);
        // A new session expects 1: a later number is a gap, 0 is invalid.
        assert!(matches!(
            s.check_sequence(Some(2)),
            Err(ServiceError::Conflict(_))
        ));
        assert!(matches!(
            s.check_sequence(Some(0)),
            Err(ServiceError::InvalidInput(ref v)) if v[0].field == "sequence"
        ));
        assert!(!s.check_sequence(Some(1)).unwrap());
        assert!(!s.check_sequence(None).unwrap());
        for sequence in 1..=10 {
            s.apply(
                "s",
                BatchInput {
                    sequence: Some(sequence),
                    ..Default::default()
                },
                &LIMITS,
            )
            .unwrap();
        }
        assert!(s.check_sequence(Some(10)).unwrap());
        assert!(s.check_sequence(Some(3)).unwrap());
        assert!(!s.check_sequence(Some(11)).unwrap());
        assert!(matches!(
            s.check_sequence(Some(12)),
            Err(ServiceError::Conflict(_))
        ));
    }

    #[test]
    fn limits_and_bad_reports_are_refused_without_change() {
        let input = scenario();
        let mut s = session_of(&input, 8);
        let reports = reports_of(&input);
        let small = Limits {
            max_tracks: 3,
            max_batch_reports: 10,
        };
        assert!(matches!(
            s.apply(
                "s",
                BatchInput {
                    reports: reports[..11].to_vec(),
                    ..Default::default()
                },
                &small
            ),
            Err(ServiceError::TooLarge(_))
        ));
        assert!(matches!(
            s.apply(
                "s",
                BatchInput {
                    reports: reports[..10].to_vec(),
                    ..Default::default()
                },
                &small
            ),
            Err(ServiceError::QuotaExceeded(_))
        ));
        let mut bad = reports[0].clone();
        bad.node = Some("zz".into());
        bad.sample.covariance[0][0] = -1.0;
        let Err(ServiceError::InvalidInput(v)) = s.apply(
            "s",
            BatchInput {
                reports: vec![bad],
                ..Default::default()
            },
            &LIMITS,
        ) else {
            panic!("bad report accepted");
        };
        let fields: Vec<_> = v.iter().map(|f| f.field.as_str()).collect();
        assert_eq!(fields, ["reports[0].node", "reports[0].covariance"]);
        assert_eq!(s.batches, 0);
        assert_eq!(s.pending.len(), 0);
    }

    #[test]
    fn corrupt_state_is_an_error_not_a_panic() {
        let input = scenario();
        let mut s = session_of(&input, 8);
        let reports = reports_of(&input);
        s.apply(
            "s",
            BatchInput {
                reports: reports[..40].to_vec(),
                ..Default::default()
            },
            &LIMITS,
        )
        .unwrap();
        let bytes = s.encode();
        assert!(Session::decode(&bytes).is_ok());
        for cut in (0..bytes.len()).step_by(97) {
            assert!(Session::decode(&bytes[..cut]).is_err());
        }
        let mut wrong = bytes.clone();
        wrong[0] = 99;
        assert!(Session::decode(&wrong).is_err());
    }

    /// A session written by the first release (format 1) — the scenario's
    /// first half in sequenced batches of 16, history 8 — still reads, and
    /// continues exactly as a session that never left this release.
    #[test]
    fn a_format_1_session_reads_and_continues_like_a_current_one() {
        let old = include_bytes!("../../tests/fixtures/session_v1.bin");
        assert_eq!(old[0], 1);
        let input = scenario();
        let reports = reports_of(&input);
        let half = reports.len() / 2;
        let push = |s: &mut Session, i: usize, chunk: &[ReportInput]| {
            s.apply(
                "s",
                BatchInput {
                    sequence: Some(i as u64 + 1),
                    reports: chunk.to_vec(),
                    flush: false,
                },
                &LIMITS,
            )
            .unwrap();
        };
        let mut now = session_of(&input, 8);
        for (i, chunk) in reports[..half].chunks(16).enumerate() {
            push(&mut now, i, chunk);
        }
        let mut read = Session::decode(old).unwrap();
        assert_eq!(read.view("s", 0, 0).unwrap(), now.view("s", 0, 0).unwrap());
        assert!(read.last_update.is_none(), "format 1 kept no update");
        // Re-encoded in the current format: smaller (covariance triangles),
        // and equal to the current session's encoding but for the update
        // the current one kept.
        let current = now.encode();
        assert_eq!(current[0], FORMAT_VERSION);
        assert!(
            current.len() < old.len(),
            "{} vs {}",
            current.len(),
            old.len()
        );
        for (j, chunk) in reports[half..].chunks(16).enumerate() {
            push(&mut read, half.div_ceil(16) + j, chunk);
            push(&mut now, half.div_ceil(16) + j, chunk);
        }
        assert_eq!(read.encode(), now.encode());
        assert_eq!(read.view("s", 0, 0).unwrap(), now.view("s", 0, 0).unwrap());
    }

    #[test]
    fn a_retried_last_batch_gets_its_update_again() {
        let input = scenario();
        let reports = reports_of(&input);
        let mut s = session_of(&input, 8);
        let mut updates = Vec::new();
        for (i, chunk) in reports[..64].chunks(16).enumerate() {
            let u = s
                .apply(
                    "s",
                    BatchInput {
                        sequence: Some(i as u64 + 1),
                        reports: chunk.to_vec(),
                        flush: false,
                    },
                    &LIMITS,
                )
                .unwrap();
            updates.push(u);
            // Through the store's round trip.
            s = Session::decode(&s.encode()).unwrap();
        }
        let last = updates.last().unwrap();
        assert!(!last.pairs.is_empty() && !last.system_tracks.is_empty());
        assert!(s.check_sequence(Some(4)).unwrap());
        let replay = s.duplicate_ack("s", 4, 9);
        assert!(replay.duplicate);
        assert_eq!(replay.version, 9);
        assert_eq!(replay.sequence, Some(4));
        assert_eq!(replay.instants, last.instants);
        assert_eq!(replay.changes, last.changes);
        assert_eq!(replay.pairs, last.pairs);
        assert_eq!(replay.system_tracks, last.system_tracks);
        assert_eq!(replay.retired, last.retired);
        assert_eq!(replay.pending_reports, last.pending_reports);
        assert_eq!(replay.warnings.len(), last.warnings.len() + 1);
        // An older batch: an empty acknowledgement.
        let older = s.duplicate_ack("s", 2, 9);
        assert!(older.duplicate && older.changes.is_empty() && older.pairs.is_empty());
        // After a batch without a sequence number there is nothing to replay.
        s.apply(
            "s",
            BatchInput {
                reports: reports[64..70].to_vec(),
                ..Default::default()
            },
            &LIMITS,
        )
        .unwrap();
        let s = Session::decode(&s.encode()).unwrap();
        assert!(s.duplicate_ack("s", 4, 10).pairs.is_empty());
    }
}
