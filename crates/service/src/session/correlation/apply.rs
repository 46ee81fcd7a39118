//! One batch applied to a correlation session: validate every report, put
//! them into the open alignment instant, close the instants that can no
//! longer grow (filled and predicted to their time), retire silent tracks,
//! step every node pair's correlator over the new instants and report what
//! changed.

use std::collections::{BTreeSet, HashMap, HashSet};

use super::{
    BatchInput, BatchUpdate, ChangeKind, CorrelationSession, PairChange, ReportInput,
    state::{INTERVALS_KEPT, Pending, Slot, internal},
};
use crate::{
    Interval, ServiceError, Violations,
    correlation::{self, AlignMode, Links},
    session::Limits,
    validate::Listed,
};
use algo::{
    AlgoError,
    correlation::{
        align,
        engine::{PairCorrelator, Side, Statistic},
    },
    motion::MotionModel,
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
        let mut v = Violations::new();
        // Validate every report before touching the state.
        let mut accepted: Vec<(usize, String, f64, &ReportInput)> = Vec::new();
        let mut nodes = Listed::new();
        for (i, r) in batch.reports.iter().enumerate() {
            let field = format!("reports[{i}]");
            // The session's node ids are listed in the first violation of
            // an unknown node only.
            let node = match v.id(format!("{field}.node"), r.node.as_deref()) {
                Some(id) => match self.node_ids.iter().position(|n| n == id) {
                    Some(ni) => Some(ni),
                    None => {
                        let path = format!("{field}.node");
                        let known = nodes.ids(&self.node_ids, &path);
                        v.add(path, format!("must be one of {known}, got '{id}'"));
                        None
                    }
                },
                None => None,
            };
            let track = v
                .id(format!("{field}.track"), r.track.as_deref())
                .map(str::to_string);
            let t = v.number(format!("{field}.t"), r.sample.t, Interval::FINITE);
            let ok = correlation::check_sample(
                &mut v,
                &|| field.clone(),
                &r.sample,
                &self.plan.layout,
                self.plan.h.as_ref(),
                self.spec.config.measurement_matrix.is_some(),
            );
            if let (Some(n), Some(tr), Some(t), true) = (node, track, t, ok) {
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

        let before: Vec<Vec<(usize, usize, bool, bool)>> = self
            .correlators
            .iter()
            .map(|c| c.links().collect())
            .collect();
        let first_new = self.scene.end();
        let mut retire_at: Vec<(usize, usize, usize)> = Vec::new(); // (k, node, slot)
        let instants = if matches!(self.plan.alignment, AlignMode::Grid { .. }) {
            self.close_grid(accepted, batch.flush, limits, &mut retire_at, warnings)?
        } else {
            self.close_clusters(accepted, batch.flush, &mut retire_at, warnings)?
        };
        self.instants_processed += instants.len() as u64;

        // Correlate every node pair over the new instants, releasing the
        // pairs of retired tracks at the instant they retire.
        let model_ref: Option<&dyn MotionModel> =
            self.plan.model.as_ref().map(|m| m as &dyn MotionModel);
        let end = self.scene.end();
        let mut reports_out = Vec::new();
        let mut links = Links::default();
        let mut singular = 0usize;
        // The pair budget is the session's: what the other node pairs hold
        // is taken from it.
        let mut held: usize = self.correlators.iter().map(|c| c.pair_count()).sum();
        for (ci, (na, nb)) in self.node_pairs().into_iter().enumerate() {
            let mut state = std::mem::take(&mut self.correlators[ci]);
            held -= state.pair_count();
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
                .map_err(|e| Violations::from_param("method.", e))?
                .with_pair_budget(correlation::MAX_CANDIDATE_PAIRS.saturating_sub(held));
                c.run_until(cut).map_err(|e| match e {
                    AlgoError::BudgetExceeded { .. } => {
                        correlation::pair_budget_error("reports", "one session")
                    }
                    other => Violations::from_param("method.", other),
                })?;
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
                links.collect(&r, na, nb);
                if r.last_common >= first_new && r.last_common < end {
                    reports_out.push((na, nb, r));
                }
            }
            self.correlators[ci] = c.into_state();
            held += self.correlators[ci].pair_count();
        }
        if singular > 0 && self.plan.config.statistic == Statistic::Modified {
            warnings.push(format!(
                "{singular} test(s) of the modified statistic so far fell back to the weighted \
                 statistic (P_a + P_b − P_ab − P_ab' not positive definite)"
            ));
        }

        // Nodes that the alignment keeps apart, over the instants held.
        if !instants.is_empty() && self.scene.times().len() >= COVERAGE_MIN_INSTANTS {
            let mut report = correlation::AlignmentReport {
                mode: correlation::mode_name(self.plan.alignment),
                ..Default::default()
            };
            correlation::coverage(&self.scene, &self.node_ids, &mut report, warnings);
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
        let system_tracks = self.system_tracks(&links);

        // Free the retired slots and trim the history.
        let mut retired = Vec::new();
        for &(_, node, slot) in &retire_at {
            retired.push(self.name(node, slot));
            let id = std::mem::take(&mut self.slots[node][slot].id);
            self.by_id[node].remove(&id);
            self.slots[node][slot] = Slot::default();
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

/// Instants held before a session warns about nodes that never meet.
const COVERAGE_MIN_INSTANTS: usize = 4;

/// A validated report: node, track id, time, and the report.
type Accepted<'a> = (usize, String, f64, &'a ReportInput);

impl CorrelationSession {
    /// Marks the live tracks silent for longer than the retirement time at
    /// instant `k` (time `t_k`) for release.
    fn mark_silent(&mut self, k: usize, t_k: f64, retire_at: &mut Vec<(usize, usize, usize)>) {
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

    /// The cluster alignment (`predict`, `nearest`): reports wait in the open
    /// cluster; returns the instants closed.
    fn close_clusters(
        &mut self,
        accepted: Vec<Accepted<'_>>,
        flush: bool,
        retire_at: &mut Vec<(usize, usize, usize)>,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<f64>, ServiceError> {
        let tol = self.plan.tolerance;
        let horizon = self.closed_start.map(|s| s + tol);
        let mut late = 0u64;
        for (node, track, t, r) in accepted {
            if horizon.is_some_and(|h| t <= h) {
                late += 1;
                continue;
            }
            let slot = self.slot_for(node, &track);
            let est = self.plan.estimate(t, &r.sample);
            self.pending.push(Pending { node, slot, est });
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
        self.pending.sort_by(|a, b| a.est.t.total_cmp(&b.est.t));
        let times: Vec<f64> = self.pending.iter().map(|r| r.est.t).collect();
        // [from, to) of each cluster of the sorted reports, and its start.
        let mut clusters: Vec<(usize, usize, f64)> = Vec::new();
        for (start, end) in align::clusters(&times, tol) {
            let from = clusters.last().map_or(0, |c| c.1);
            let to = from + times[from..].partition_point(|&t| t <= end);
            clusters.push((from, to, start));
        }
        if !flush {
            clusters.pop();
        }
        let closed = clusters.last().map_or(0, |c| c.1);
        let reports: Vec<Pending> = self.pending.drain(..closed).collect();
        let mut instants = Vec::new();
        let mut superseded = 0usize;
        let mut predicted = 0usize;
        for &(from, to, start) in &clusters {
            let group = &reports[from..to];
            let t_k = group.last().expect("clusters are not empty").est.t;
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
                predicted += usize::from(self.fill(k, r.node, r.slot, &r.est, true)?);
                self.slots[r.node][r.slot].last_t = Some(t_k);
            }
            self.mark_silent(k, t_k, retire_at);
        }
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
        Ok(instants)
    }

    /// The grid alignment: instants on the fusion-time grid close once a
    /// report later than the instant plus the tolerance has arrived (or on
    /// a flush); each live track is brought to each from its latest report
    /// at or before it, within its node's staleness bound. A report for an
    /// instant already closed still serves the later ones. Returns the
    /// instants closed.
    fn close_grid(
        &mut self,
        mut accepted: Vec<Accepted<'_>>,
        flush: bool,
        limits: &Limits,
        retire_at: &mut Vec<(usize, usize, usize)>,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<f64>, ServiceError> {
        let AlignMode::Grid {
            epoch,
            max_staleness,
            ..
        } = self.plan.alignment
        else {
            unreachable!("the grid alignment");
        };
        let tol = self.plan.tolerance;
        let last_closed = self.scene.times().last().copied();
        accepted.sort_by(|a, b| a.2.total_cmp(&b.2));
        let mut late = 0u64;
        for (node, track, t, r) in accepted {
            let slot = self.slot_for(node, &track);
            let est = self.plan.estimate(t, &r.sample);
            let s = &mut self.slots[node][slot];
            if let Some(seen) = s.seen_t
                && t > seen
            {
                let iv = &mut self.intervals[node];
                if iv.len() == INTERVALS_KEPT {
                    iv.remove(0);
                }
                iv.push(t - seen);
            }
            s.seen_t = Some(s.seen_t.map_or(t, |seen| seen.max(t)));
            self.reports_accepted += 1;
            if last_closed.is_some_and(|c| t <= c) {
                late += 1;
                if s.latest.as_ref().is_none_or(|l| t > l.t) {
                    s.latest = Some(est);
                    s.used = false;
                }
            } else {
                self.pending.push(Pending { node, slot, est });
            }
        }
        if late > 0 {
            self.reports_late += late;
            warnings.push(format!(
                "{late} report(s) arrived after their instant closed (at or before {} s): \
                 they serve the later instants only",
                last_closed.unwrap_or(f64::NAN)
            ));
        }
        self.pending.sort_by(|a, b| a.est.t.total_cmp(&b.est.t));
        let Some(t_max) = self.pending.last().map(|r| r.est.t) else {
            return Ok(Vec::new());
        };

        // The period: fixed once known.
        let node_periods: Vec<Option<f64>> = self
            .intervals
            .iter()
            .map(|iv| align::median_interval(&mut iv.clone()))
            .collect();
        let (grid, bounds) =
            correlation::grid_parameters(self.grid_period, max_staleness, &node_periods);
        if let (None, Some(p)) = (self.grid_period, grid) {
            self.grid_period = Some(p);
            warnings.push(format!(
                "grid alignment: the fusion period was estimated at {p} s (the longest scan \
                 period of the nodes that have reported twice); give alignment.period_s to fix it"
            ));
        }
        let widest = bounds.iter().copied().fold(0.0, f64::max);
        let Some(period) = self.grid_period else {
            if !flush {
                warnings.push(
                    "grid alignment: waiting for a second report of some track to estimate the \
                     scan period; give alignment.period_s to start at once"
                        .to_string(),
                );
                return Ok(Vec::new());
            }
            // One instant at the latest report, as the batch endpoint does.
            self.take_reports_upto(t_max);
            return self
                .close_grid_instant(t_max, &bounds, retire_at)
                .map(|_| vec![t_max]);
        };
        let end = align::grid_at_or_after(t_max, period, epoch);
        let mut g = match last_closed {
            Some(c) => align::grid_after(c, period, epoch).unwrap_or(f64::INFINITY),
            None => align::grid_at_or_after(self.pending[0].est.t, period, epoch),
        };
        let mut instants = Vec::new();
        while if flush { g <= end } else { g + tol < t_max } {
            self.take_reports_upto(g);
            let newest = self
                .slots
                .iter()
                .flatten()
                .filter(|s| !s.id.is_empty())
                .filter_map(|s| s.latest.as_ref().map(|l| l.t))
                .fold(f64::NEG_INFINITY, f64::max);
            if g - newest > widest {
                // Nothing can be present: jump to the next report.
                match self.pending.first() {
                    Some(r) => g = align::grid_at_or_after(r.est.t, period, epoch),
                    None => break,
                }
                continue;
            }
            self.close_grid_instant(g, &bounds, retire_at)?;
            instants.push(g);
            if instants.len() > limits.max_batch_reports.max(1024) {
                return Err(ServiceError::TooLarge(format!(
                    "the batch would close more than {} grid instants of {period} s: give a \
                     longer alignment.period_s",
                    instants.len() - 1
                )));
            }
            let Some(next) = align::grid_after(g, period, epoch) else {
                return Err(Violations::single(
                    "alignment.period_s",
                    format!("{period} s is below the resolution of the report times"),
                ));
            };
            g = next;
        }
        Ok(instants)
    }

    /// The pending reports up to `t` become their tracks' latest (a report
    /// older than the latest already held is superseded).
    fn take_reports_upto(&mut self, t: f64) {
        let upto = self.pending.partition_point(|r| r.est.t <= t);
        for r in self.pending.drain(..upto) {
            let s = &mut self.slots[r.node][r.slot];
            if s.latest.as_ref().is_none_or(|l| r.est.t > l.t) {
                s.latest = Some(r.est);
                s.used = false;
            }
        }
    }

    /// Closes grid instant `t_k` (the reports up to it already taken):
    /// every live track whose latest report is
    /// within its node's staleness bound is brought to it.
    fn close_grid_instant(
        &mut self,
        t_k: f64,
        bounds: &[f64],
        retire_at: &mut Vec<(usize, usize, usize)>,
    ) -> Result<(), ServiceError> {
        let k = self.scene.push_instant(t_k).map_err(internal)?;
        for (node, &bound) in bounds.iter().enumerate() {
            for slot in 0..self.slots[node].len() {
                let s = &mut self.slots[node][slot];
                if s.id.is_empty() || !s.latest.as_ref().is_some_and(|l| t_k - l.t <= bound) {
                    continue;
                }
                // Taken out for the fill (which needs the whole session)
                // and put back: no copy of the estimate per instant.
                let (est, first_use) = (s.latest.take().expect("checked"), !s.used);
                let filled = self.fill(k, node, slot, &est, first_use);
                let s = &mut self.slots[node][slot];
                s.latest = Some(est);
                filled?;
                s.used = true;
                s.last_t = Some(t_k);
            }
        }
        self.mark_silent(k, t_k, retire_at);
        Ok(())
    }
}
