//! One batch applied to a correlation session: validate every report, put
//! them into the open alignment instant, close the instants that can no
//! longer grow (filled and predicted to their time), retire silent tracks,
//! step every node pair's correlator over the new instants and report what
//! changed.

use std::collections::{BTreeSet, HashMap, HashSet};

use super::{
    BatchInput, BatchUpdate, ChangeKind, CorrelationSession, PairChange, ReportInput,
    state::{Pending, Slot, gain_factor, internal},
};
use crate::{
    algo::{
        correlation::engine::{PairCorrelator, Side, Statistic},
        motion::MotionModel,
    },
    service::{
        ServiceError, Violations,
        correlation::{self, CrossCovariances},
        session::Limits,
    },
};

impl CorrelationSession {
    /// Applies one batch (its size already checked by the envelope). On
    /// error the session is unchanged only if the caller discards it: the
    /// caller works on a decoded copy.
    pub(super) fn apply_batch(
        &mut self,
        batch: &BatchInput,
        limits: &Limits,
        warnings: &mut Vec<String>,
    ) -> Result<BatchUpdate, ServiceError> {
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
                .map_err(|e| Violations::from_param("method.", e))?;
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
        Ok(BatchUpdate {
            instants,
            pending_reports: self.pending.len() as u32,
            changes,
            pairs: pairs_out,
            system_tracks,
            retired,
        })
    }
}
