//! The stored form of a correlation session: the payload the envelope
//! carries (format 3), the formats 1 and 2 of the releases before the
//! envelope (whole sessions, read as an envelope and a payload), and the
//! encoding of a batch update kept for replay.

use std::collections::HashMap;

use super::{
    BatchUpdate, ChangeKind, CorrelationSession, FORMAT_VERSION, PairChange, SessionSpec,
    state::{Pending, Slot, node_ids, plan_of},
};
use crate::{
    ServiceError,
    correlation::{
        AlignmentInput, CorrelateInput, FusionKind, GroupOutput, MethodInput, MotionModelInput,
        NodeInput, PairOutput, RuleInput, TrackName,
    },
    session::{Envelope, Kept, corrupt},
};
use algo::correlation::{
    align::Estimate,
    engine::{self, Decision},
};
use formats::state::{
    correlator::{decode_correlator, encode_correlator},
    scene::{decode_scene, encode_scene},
};
use wire_formats::wire::{self, FormatError, Reader, Writer};

/// Appends the session's payload (format 3).
pub(super) fn encode(s: &CorrelationSession, w: &mut Writer) {
    // Format 4: format 3 with the grid alignment's fields and state.
    w.u8(FORMAT_VERSION);
    encode_spec(w, &s.spec);
    w.f64(s.retire_after_s);
    w.usize(s.history);
    w.u64(s.instants_processed);
    w.u64(s.reports_accepted);
    w.u64(s.reports_late);
    w.opt(s.closed_start, Writer::f64);
    encode_tail(s, w);
    encode_grid(s, w);
}

/// The scene, the slots, the correlators and the pending reports: the same
/// in every format (the scene says its own format).
fn encode_tail(s: &CorrelationSession, w: &mut Writer) {
    encode_scene(&s.scene, w);
    for slots in &s.slots {
        w.usize(slots.len());
        for slot in slots {
            w.str(&slot.id);
            w.opt(slot.last_t, Writer::f64);
        }
    }
    let dim = s.plan.layout.dim;
    for c in &s.correlators {
        encode_correlator(c, w, dim);
    }
    w.usize(s.pending.len());
    for p in &s.pending {
        w.usize(p.node);
        w.usize(p.slot);
        encode_estimate(w, &p.est);
    }
}

fn encode_estimate(w: &mut Writer, e: &Estimate) {
    w.f64(e.t);
    w.f64s(&e.x);
    w.f64s(&e.p);
    w.opt(e.factor.as_deref(), Writer::f64s);
}

fn decode_estimate(r: &mut Reader<'_>, dim: usize) -> Result<Estimate, FormatError> {
    let t = r.f64()?;
    let x = r.f64s()?;
    let p = r.f64s()?;
    let factor = r.opt(Reader::f64s)?;
    if x.len() != dim
        || p.len() != dim * dim
        || factor.as_ref().is_some_and(|f| f.len() != dim * dim)
    {
        return Err(wire::corrupt("estimate shape"));
    }
    Ok(Estimate { t, x, p, factor })
}

/// The grid alignment's state (format 4 on): the fixed period, each node's
/// recent intervals, and each slot's latest report.
fn encode_grid(s: &CorrelationSession, w: &mut Writer) {
    w.opt(s.grid_period, Writer::f64);
    for iv in &s.intervals {
        w.f64s(iv);
    }
    for slots in &s.slots {
        for slot in slots {
            w.opt(slot.latest.as_ref(), encode_estimate);
            w.bool(slot.used);
            w.opt(slot.seen_t, Writer::f64);
        }
    }
}

fn decode_grid(r: &mut Reader<'_>, s: &mut CorrelationSession) -> Result<(), FormatError> {
    let dim = s.plan.layout.dim;
    s.grid_period = r.opt(Reader::f64)?;
    for iv in s.intervals.iter_mut() {
        *iv = r.f64s()?;
    }
    for slots in s.slots.iter_mut() {
        for slot in slots.iter_mut() {
            slot.latest = r.opt(|r| decode_estimate(r, dim))?;
            slot.used = r.bool()?;
            slot.seen_t = r.opt(Reader::f64)?;
        }
    }
    Ok(())
}

/// Reads a payload written by [`encode`].
pub(super) fn decode(r: &mut Reader<'_>) -> Result<CorrelationSession, ServiceError> {
    let format = r.u8().map_err(corrupt)?;
    if !(3..=FORMAT_VERSION).contains(&format) {
        return Err(ServiceError::Internal(format!(
            "stored correlation payload has format {format}; this release reads 3 to \
             {FORMAT_VERSION}"
        )));
    }
    let spec = decode_spec(r, Spec::of_format(format)).map_err(corrupt)?;
    let retire_after_s = r.f64().map_err(corrupt)?;
    let history = r.usize().map_err(corrupt)?;
    let counters = [
        r.u64().map_err(corrupt)?,
        r.u64().map_err(corrupt)?,
        r.u64().map_err(corrupt)?,
    ];
    let closed_start = r.opt(Reader::f64).map_err(corrupt)?;
    // Payload formats 3 and 4 hold scene format 2.
    let mut s = decode_tail(r, 2, spec, retire_after_s, history, counters, closed_start)?;
    if format >= 4 {
        decode_grid(r, &mut s).map_err(corrupt)?;
    }
    Ok(s)
}

/// Reads a whole session of format 1 or 2 (before the envelope).
pub(super) fn decode_legacy(buf: &[u8]) -> Result<Envelope<CorrelationSession>, ServiceError> {
    let mut r = Reader::new(buf);
    let version = r.u8().map_err(corrupt)?;
    if !(1..=2).contains(&version) {
        return Err(ServiceError::Internal(format!(
            "stored session has format {version}, not 1 or 2"
        )));
    }
    let spec = decode_spec(&mut r, Spec::Legacy).map_err(corrupt)?;
    let idle_expiry_s = r.f64().map_err(corrupt)?;
    let retire_after_s = r.f64().map_err(corrupt)?;
    let history = r.usize().map_err(corrupt)?;
    let created_unix_ms = r.u64().map_err(corrupt)?;
    let last_sequence = r.opt(Reader::u64).map_err(corrupt)?;
    let batches = r.u64().map_err(corrupt)?;
    let counters = [
        r.u64().map_err(corrupt)?,
        r.u64().map_err(corrupt)?,
        r.u64().map_err(corrupt)?,
    ];
    let closed_start = r.opt(Reader::f64).map_err(corrupt)?;
    // Session format 1 holds scene format 1, format 2 scene format 2.
    let state = decode_tail(
        &mut r,
        version,
        spec,
        retire_after_s,
        history,
        counters,
        closed_start,
    )?;
    let last_update = if version >= 2 {
        r.opt(decode_legacy_update).map_err(corrupt)?
    } else {
        None
    };
    if !r.is_empty() {
        return Err(ServiceError::Internal(
            "stored session: trailing bytes".into(),
        ));
    }
    Ok(Envelope {
        recent: Vec::new(),
        state,
        created_unix_ms,
        idle_expiry_s,
        last_sequence,
        batches,
        last_update,
    })
}

/// Reads what [`encode_tail`] wrote and builds the session.
fn decode_tail(
    r: &mut Reader<'_>,
    scene_format: u8,
    spec: SessionSpec,
    retire_after_s: f64,
    history: usize,
    [instants_processed, reports_accepted, reports_late]: [u64; 3],
    closed_start: Option<f64>,
) -> Result<CorrelationSession, ServiceError> {
    let plan = plan_of(&spec)?;
    let node_ids = node_ids(&spec);
    let n = node_ids.len();
    let scene = decode_scene(r, scene_format).map_err(corrupt)?;
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
                ..Slot::default()
            });
        }
        slots.push(list);
        by_id.push(ids);
    }
    let dim = plan.layout.dim;
    let mut correlators = Vec::new();
    for _ in 0..n * (n - 1) / 2 {
        correlators.push(decode_correlator(r, dim).map_err(corrupt)?);
    }
    let np = r.len(24).map_err(corrupt)?;
    let mut pending = Vec::with_capacity(np);
    for _ in 0..np {
        let node = r.usize().map_err(corrupt)?;
        let slot = r.usize().map_err(corrupt)?;
        let est = decode_estimate(r, dim).map_err(corrupt)?;
        if node >= n || slot >= slots[node].len() {
            return Err(ServiceError::Internal(
                "stored session: pending report".into(),
            ));
        }
        pending.push(Pending { node, slot, est });
    }
    Ok(CorrelationSession {
        spec,
        plan,
        retire_after_s,
        history,
        scene,
        node_ids,
        slots,
        by_id,
        correlators,
        pending,
        closed_start,
        instants_processed,
        reports_accepted,
        reports_late,
        grid_period: None,
        intervals: vec![Vec::new(); n],
    })
}

fn opt_str(w: &mut Writer, v: &Option<String>) {
    w.opt(v.as_deref(), Writer::str);
}

/// Set in a system track's fusion code when it is a trial system track.
const TRIAL_BIT: u8 = 0x80;

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

fn of_code<T: Copy>(list: &[T], r: &mut Reader<'_>, what: &str) -> Result<T, FormatError> {
    let c = r.u8()?;
    list.get(usize::from(c))
        .copied()
        .ok_or_else(|| wire::corrupt(&format!("unknown {what} code {c}")))
}

fn encode_name(w: &mut Writer, n: &TrackName) {
    w.str(&n.node);
    w.str(&n.track);
}

fn decode_name(r: &mut Reader<'_>) -> Result<TrackName, FormatError> {
    Ok(TrackName {
        node: r.str()?,
        track: r.str()?,
    })
}

fn decode_list<'a, T>(
    r: &mut Reader<'a>,
    f: impl Fn(&mut Reader<'a>) -> Result<T, FormatError>,
) -> Result<Vec<T>, FormatError> {
    let n = r.len(1)?;
    (0..n).map(|_| f(r)).collect()
}

/// Appends a batch update (the envelope keeps its sequence and warnings).
pub(super) fn encode_update(w: &mut Writer, u: &BatchUpdate) {
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
        // The trial flag rides in the fusion code's high bit, so that the
        // updates kept by earlier releases read unchanged.
        w.u8(code_of(&FUSION_KINDS, &g.fusion) | if g.trial { TRIAL_BIT } else { 0 });
    }
    w.usize(u.retired.len());
    u.retired.iter().for_each(|n| encode_name(w, n));
}

/// Reads a batch update written by [`encode_update`].
pub(super) fn decode_update(r: &mut Reader<'_>) -> Result<BatchUpdate, FormatError> {
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
        let id = r.u32()?;
        let members = decode_list(r, decode_name)?;
        let t = r.f64()?;
        let state = r.f64s()?;
        let covariance = decode_list(r, Reader::f64s)?;
        let code = r.u8()?;
        Ok(GroupOutput {
            id,
            members,
            t,
            state,
            covariance,
            fusion: of_code(
                &FUSION_KINDS,
                &mut Reader::new(&[code & !TRIAL_BIT]),
                "fusion",
            )?,
            trial: code & TRIAL_BIT != 0,
        })
    })?;
    Ok(BatchUpdate {
        instants,
        pending_reports,
        changes,
        pairs,
        system_tracks,
        retired: decode_list(r, decode_name)?,
    })
}

/// Reads the update kept by a session of format 2: its sequence number, the
/// body of [`decode_update`], then its warnings.
fn decode_legacy_update(r: &mut Reader<'_>) -> Result<Kept<BatchUpdate>, FormatError> {
    let sequence = r.opt(Reader::u64)?;
    let body = decode_update(r)?;
    let warnings = decode_list(r, Reader::str)?;
    Ok(Kept {
        // Format 2 kept an update only for a sequenced batch.
        sequence: sequence.ok_or_else(|| wire::corrupt("kept update without a sequence"))?,
        body,
        warnings,
    })
}

/// Appends a configuration (format 3: the idle expiry is the envelope's).
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
        w.opt(a.period_s, Writer::f64);
        w.opt(a.epoch_s, Writer::f64);
        w.opt(a.max_staleness_s, Writer::f64);
    });
    w.opt(c.measurement_matrix.as_ref(), |w, h| {
        w.usize(h.len());
        h.iter().for_each(|row| w.f64s(row));
    });
    w.usize(c.nodes.len());
    c.nodes.iter().for_each(|n| opt_str(w, &n.id));
    opt_str(w, &c.pruning);
    w.opt(c.fuse, Writer::bool);
    w.opt(spec.retire_after_s, Writer::f64);
    w.opt(spec.history_instants, Writer::u32);
}

/// The configuration formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Spec {
    /// Formats 1 and 2: with the requested idle expiry.
    Legacy,
    /// Format 3: without it.
    Three,
    /// Format 4: the grid alignment's fields.
    Four,
}

impl Spec {
    fn of_format(format: u8) -> Self {
        if format >= 4 { Spec::Four } else { Spec::Three }
    }
}

/// Reads a configuration; formats 1 and 2 also held the requested idle
/// expiry, read and dropped here (the envelope holds the effective one).
/// Before format 4 an omitted alignment mode meant `predict` with a motion
/// model and `nearest` without: such sessions keep it.
fn decode_spec(r: &mut Reader<'_>, format: Spec) -> Result<SessionSpec, FormatError> {
    let legacy = format == Spec::Legacy;
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
    let mut alignment = r.opt(|r| {
        let mut a = AlignmentInput {
            mode: s(r)?,
            max_gap_s: r.opt(Reader::f64)?,
            tolerance_s: r.opt(Reader::f64)?,
            ..AlignmentInput::default()
        };
        if format == Spec::Four {
            a.period_s = r.opt(Reader::f64)?;
            a.epoch_s = r.opt(Reader::f64)?;
            a.max_staleness_s = r.opt(Reader::f64)?;
        }
        Ok(a)
    })?;
    if format != Spec::Four {
        let a = alignment.get_or_insert_with(AlignmentInput::default);
        if a.mode.is_none() {
            a.mode = Some(
                if motion_model.is_some() {
                    "predict"
                } else {
                    "nearest"
                }
                .into(),
            );
        }
    }
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
        .collect::<Result<_, FormatError>>()?;
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
        retire_after_s: {
            if legacy {
                r.opt(Reader::f64)?;
            }
            r.opt(Reader::f64)?
        },
        history_instants: r.opt(Reader::u32)?,
    })
}
