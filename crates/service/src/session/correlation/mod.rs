//! The correlation kind of session (seed 000 §3.3: local tracks arrive "one by
//! one or batch by batch"). A session carries the correlation state of every
//! node pair (quality counters m and C, decided pairs, trial system tracks,
//! cross-covariances) from one batch of track reports to the next.
//!
//! This module is the session's domain: its configuration, its state, the
//! application of one batch and the compact versioned binary encoding of the
//! state. It reuses the batch correlation's validation, alignment rule,
//! engine ([`PairCorrelator::resume`]), grouping and fusion; persistence and
//! concurrency live in the envelope ([`super`]) and [`super::persist`].
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

mod apply;
mod codec;
mod state;
#[cfg(test)]
mod tests;

pub use state::CorrelationSession;

use super::{Envelope, Fnv, Limits, SessionKind};
use crate::{
    Rows, ServiceError,
    correlation::{CorrelateInput, GroupOutput, PairOutput, SampleInput, TrackName},
};
use wire_formats::wire::{FormatError, Reader, Writer};

/// First byte of a correlation session's payload inside the envelope; a
/// later release that changes it bumps it and keeps a decoder for the older
/// ones. Formats 1 and 2 are the sessions of the releases before the
/// envelope (whole sessions, read by [`codec::decode_legacy`]); format 3 is
/// format 2 without what the envelope now holds; format 4 adds the grid
/// alignment (its options, the fixed period, node intervals and each
/// track's latest report).
pub const FORMAT_VERSION: u8 = 4;
/// Default time (data time) after which a silent track is retired.
pub const DEFAULT_RETIRE_AFTER_S: f64 = 60.0;
/// Default number of instants kept for the replay of late-gated pairs.
pub const DEFAULT_HISTORY_INSTANTS: u32 = 32;
/// Largest history a session may ask for.
pub const MAX_HISTORY_INSTANTS: u32 = 1024;

/// A correlation session's configuration, as a client asks for it.
#[derive(Debug, Clone, Default)]
pub struct SessionSpec {
    /// The correlation configuration; `nodes` carry only their ids.
    pub config: CorrelateInput,
    pub retire_after_s: Option<f64>,
    pub history_instants: Option<u32>,
}

/// One batch of track reports.
#[derive(Debug, Clone, Default)]
pub struct BatchInput {
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

/// What one batch changed (the envelope adds the sequence, version and
/// warnings).
#[derive(Debug, Clone, PartialEq)]
pub struct BatchUpdate {
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
}

/// A correlation session's state, as a client reads it (the envelope adds
/// id, version, sequence and expiry).
#[derive(Debug, Clone, PartialEq)]
pub struct SessionView {
    pub instants_processed: u64,
    pub last_instant: Option<f64>,
    pub pending_reports: u32,
    pub reports_accepted: u64,
    pub reports_late: u64,
    pub retire_after_s: f64,
    pub history_instants: u32,
    pub method: String,
    pub nodes: Vec<NodeView>,
    pub pairs: Vec<PairOutput>,
    pub system_tracks: Vec<GroupOutput>,
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

impl SessionKind for CorrelationSession {
    const TAG: u8 = super::LEGACY_KIND_TAG;
    const NAME: &'static str = "correlation";
    const BATCH_FIELD: &'static str = "reports";

    type Spec = SessionSpec;
    type Batch = BatchInput;
    type Update = BatchUpdate;
    type View = SessionView;

    fn create(spec: SessionSpec, _warnings: &mut Vec<String>) -> Result<Self, ServiceError> {
        CorrelationSession::new(spec)
    }

    fn check_size(batch: &BatchInput, limits: &Limits) -> Result<(), ServiceError> {
        limits.check_batch(batch.reports.len(), "reports")
    }

    fn apply(
        &mut self,
        batch: &BatchInput,
        limits: &Limits,
        warnings: &mut Vec<String>,
    ) -> Result<BatchUpdate, ServiceError> {
        self.apply_batch(batch, limits, warnings)
    }

    fn acknowledgement(&self) -> BatchUpdate {
        BatchUpdate {
            instants: Vec::new(),
            pending_reports: self.pending_reports(),
            changes: Vec::new(),
            pairs: Vec::new(),
            system_tracks: Vec::new(),
            retired: Vec::new(),
        }
    }

    fn fingerprint(batch: &BatchInput) -> Option<u64> {
        if batch.reports.is_empty() {
            return None;
        }
        let mut h = Fnv::default();
        h.bytes(&[u8::from(batch.flush)]);
        for r in &batch.reports {
            h.str(r.node.as_deref());
            h.str(r.track.as_deref());
            let s = &r.sample;
            h.opt_f64(s.t);
            s.state.iter().for_each(|&x| h.f64(x));
            // Row after row, as when the rows were nested: a retry keeps
            // its fingerprint across versions.
            s.covariance.values().iter().for_each(|&x| h.f64(x));
            h.bytes(&[u8::from(s.gain.is_some())]);
            s.gain.iter().flat_map(Rows::values).for_each(|&x| h.f64(x));
        }
        Some(h.0)
    }

    fn view(&self) -> Result<SessionView, ServiceError> {
        self.view_state()
    }

    fn encode_batch(batch: &BatchInput, w: &mut Writer) -> bool {
        let BatchInput { reports, flush } = batch;
        w.usize(reports.len());
        for report in reports {
            let ReportInput {
                node,
                track,
                sample:
                    SampleInput {
                        t,
                        state,
                        covariance,
                        gain,
                    },
            } = report;
            w.opt(node.as_deref(), Writer::str);
            w.opt(track.as_deref(), Writer::str);
            w.opt(*t, Writer::f64);
            w.f64s(state);
            // A ragged matrix has no exact form here: the batch is stored
            // as a snapshot (such a batch is refused anyway).
            for m in std::iter::once(Some(covariance)).chain([gain.as_ref()]) {
                let Some(m) = m else {
                    w.bool(false);
                    continue;
                };
                let Some((rows, cols)) = m.shape() else {
                    return false;
                };
                w.bool(true);
                w.usize(rows);
                w.usize(cols);
                w.f64s(m.values());
            }
        }
        w.bool(*flush);
        true
    }

    fn decode_batch(r: &mut Reader<'_>) -> Result<BatchInput, FormatError> {
        let matrix = |r: &mut Reader<'_>| -> Result<Option<Rows>, FormatError> {
            if !r.bool()? {
                return Ok(None);
            }
            let (rows, cols) = (r.usize()?, r.usize()?);
            let values = r.f64s()?;
            Rows::from_flat(values, rows, cols)
                .map(Some)
                .ok_or_else(|| {
                    wire_formats::wire::corrupt("a matrix's values do not fill its shape")
                })
        };
        // A report takes at least five bytes.
        let n = r.len(5)?;
        let reports = (0..n)
            .map(|_| {
                let node = r.opt(Reader::str)?;
                let track = r.opt(Reader::str)?;
                let t = r.opt(Reader::f64)?;
                let state = r.f64s()?;
                let covariance = matrix(r)?.ok_or_else(|| {
                    wire_formats::wire::corrupt("a report without its covariance")
                })?;
                let gain = matrix(r)?;
                Ok(ReportInput {
                    node,
                    track,
                    sample: SampleInput {
                        t,
                        state,
                        covariance,
                        gain,
                    },
                })
            })
            .collect::<Result<_, FormatError>>()?;
        Ok(BatchInput {
            reports,
            flush: r.bool()?,
        })
    }

    fn encode(&self, w: &mut Writer) {
        codec::encode(self, w);
    }

    fn decode(r: &mut Reader<'_>) -> Result<Self, ServiceError> {
        codec::decode(r)
    }

    fn encode_update(u: &BatchUpdate, w: &mut Writer) {
        codec::encode_update(w, u);
    }

    fn decode_update(r: &mut Reader<'_>) -> Result<BatchUpdate, FormatError> {
        codec::decode_update(r)
    }

    fn decode_legacy(buf: &[u8]) -> Result<Envelope<Self>, ServiceError> {
        codec::decode_legacy(buf)
    }
}
