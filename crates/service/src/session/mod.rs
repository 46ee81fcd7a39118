//! Streaming sessions of every kind: one envelope, many kinds.
//!
//! A session is a piece of state that lives between requests: a client
//! creates it, pushes batches to it (in order, each applied exactly once) and
//! reads it. What the state *is* belongs to its kind (a [`SessionKind`]: the
//! correlation of local tracks, [`correlation`]); everything else is generic
//! and lives here once:
//! - the [`Envelope`] around a kind's state: creation time, idle expiry,
//!   the sequence protocol (the first sequenced batch carries 1, each next
//!   one the previous + 1; a number applied before is acknowledged without
//!   being applied, a retry of the last one gets that batch's update again;
//!   a number that skips ahead is a conflict naming the expected one);
//! - the stored bytes: `[ENVELOPE_FORMAT][kind tag][envelope fields][kept
//!   update][kind payload]`, so a reader knows the kind before decoding it;
//!   the correlation sessions written before kinds existed (formats 1 and 2,
//!   whose first byte is their format) still read, as correlation sessions;
//! - [`persist`]: create, read, list, delete and push over the store, the
//!   compare-and-set retry loop, the decoded-session [`cache`], limits,
//!   idle expiry and tenants.
//!
//! The generic modules (this one, [`events`], [`persist`]) name no kind;
//! [`registry`] names them all. A new kind is one module implementing
//! [`SessionKind`], its entries in [`registry`] and its DTOs in the
//! adapters.

pub mod cache;
pub mod correlation;
pub mod events;
pub mod gauges;
pub mod persist;
pub mod plot_fusion;
pub mod registry;

use std::fmt;

use super::{ServiceError, Violations};
use wire_formats::wire::{FormatError, Reader, Writer};

/// First byte of every session written by this release: the envelope's
/// format. Correlation sessions of earlier releases start with their own
/// format, 1 or 2, and are read as correlation sessions.
pub const ENVELOPE_FORMAT: u8 = 4;
/// The kind tag of the sessions written before the envelope (formats 1
/// and 2): the first kind's, correlation's.
pub const LEGACY_KIND_TAG: u8 = 1;
/// Format of a log entry ([`Envelope::encode_entry`]).
pub const ENTRY_FORMAT: u8 = 1;
/// Unsequenced batches remembered by their fingerprint, so that a retry of
/// one whose outcome the client could not know is not applied twice.
pub const RECENT_BATCHES: usize = 64;
/// Default idle expiry of a session.
pub const DEFAULT_IDLE_EXPIRY_S: f64 = 3600.0;
/// Longest idle expiry a session may ask for (30 days).
pub const MAX_IDLE_EXPIRY_S: f64 = 30.0 * 86400.0;

/// Limits of one session, from the service settings.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Most live tracks a session may hold.
    pub max_tracks: usize,
    /// Most items (reports, plots) in one batch.
    pub max_batch_reports: usize,
}

impl Limits {
    /// Refuses a batch of `n` items (`what`: reports, plots) over the limit.
    pub fn check_batch(&self, n: usize, what: &str) -> Result<(), ServiceError> {
        if n > self.max_batch_reports {
            return Err(ServiceError::TooLarge(format!(
                "the batch holds {n} {what}; the limit is {} per batch",
                self.max_batch_reports
            )));
        }
        Ok(())
    }
}

/// A plot of a batch, where it is, for display: the fusion frame's ENU
/// position (m), its radar (index into the session's radars; a
/// cooperative report's sensor past them) and time. 2D plots are placed at
/// their slant range on the horizontal plane, reports where they say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlotMark {
    pub radar: u32,
    pub t: f64,
    pub position: [f64; 3],
}

/// What a kind of session is: its configuration, batch, update and view
/// types and how its state is created, changed, shown and stored. The
/// generic [`Envelope`] and [`persist`] do the rest.
pub trait SessionKind: Sized + Send + 'static {
    /// The kind's tag in the stored bytes (never reused).
    const TAG: u8;
    /// The kind's name on the wire (`kind` of `POST /v1/sessions`).
    const NAME: &'static str;
    /// The name of the batch field that carries this kind's items
    /// (`reports`), named when a batch meets a session of another kind.
    const BATCH_FIELD: &'static str;

    /// The kind's configuration, as a client asks for it (unvalidated).
    type Spec: Send + 'static;
    /// One batch, without the envelope's sequence number.
    type Batch: Send + Sync + 'static;
    /// What one batch changed, without the envelope's fields.
    type Update: Clone + fmt::Debug + PartialEq + Send + 'static;
    /// The kind's state as a client reads it.
    type View: fmt::Debug + PartialEq + Send + 'static;

    /// A new, empty state; validates the configuration (violations name the
    /// fields of the create request) and pushes what the caller should know
    /// of what was decided for it (a mode chosen, a missing origin).
    fn create(spec: Self::Spec, warnings: &mut Vec<String>) -> Result<Self, ServiceError>;
    /// Refuses a batch larger than the limits before any work is done.
    fn check_size(batch: &Self::Batch, limits: &Limits) -> Result<(), ServiceError>;
    /// Applies one batch, pushing its warnings. On error the state may be
    /// half changed: the caller discards it (it works on a decoded copy).
    fn apply(
        &mut self,
        batch: &Self::Batch,
        limits: &Limits,
        warnings: &mut Vec<String>,
    ) -> Result<Self::Update, ServiceError>;
    /// [`SessionKind::apply`] of a batch replayed from the log whose update
    /// nobody reads (a later entry's replaces it): the same state after it,
    /// bit for bit, but the update may leave out what only a client reads
    /// (plot fusion: the tracks' views). The default applies it.
    fn apply_unread(
        &mut self,
        batch: &Self::Batch,
        limits: &Limits,
        warnings: &mut Vec<String>,
    ) -> Result<Self::Update, ServiceError> {
        self.apply(batch, limits, warnings)
    }
    /// A copy of the stored state (what [`SessionKind::encode`] writes),
    /// cheap enough to take on the request path (shared copy-on-write where
    /// the state allows), so that a snapshot is encoded and written off it.
    /// `None` (the default): the kind has none, and its snapshots are
    /// encoded and written inline.
    fn stored_copy(&self) -> Option<Self> {
        None
    }
    /// The update of a batch that changed nothing (the acknowledgement of an
    /// old duplicate): empty, but with the state's current counters.
    fn acknowledgement(&self) -> Self::Update;
    /// A fingerprint of a batch's content (64-bit FNV-1a of its items, bit
    /// for bit), by which an unsequenced batch applied recently is known
    /// again when a client retries it. For kinds whose identical items are
    /// the same data (a track report, a plot: sent twice, they are one
    /// measurement), so that content identifies a batch. `None` (the
    /// default) for a batch that changes nothing when applied twice (a
    /// flush alone), or a kind whose identical batches are distinct events.
    fn fingerprint(batch: &Self::Batch) -> Option<u64> {
        let _ = batch;
        None
    }
    fn view(&self) -> Result<Self::View, ServiceError>;
    /// What watchers are shown of the last applied batch besides its update
    /// (plot fusion: where its plots are), taken once; none by default.
    fn take_marks(&mut self) -> Vec<PlotMark> {
        Vec::new()
    }
    /// The radars' registration after a batch, for `/metrics`
    /// ([`gauges`]); none by default.
    fn radar_biases(update: &Self::Update) -> &[crate::plot_fusion::RadarBiasView] {
        let _ = update;
        &[]
    }
    /// The radars' accuracy after a batch, for `/metrics` ([`gauges`]);
    /// none by default.
    fn radar_accuracy(update: &Self::Update) -> &[crate::plot_fusion::RadarAccuracyView] {
        let _ = update;
        &[]
    }
    /// Appends the kind's state; it writes its own format byte first.
    fn encode(&self, w: &mut Writer);
    /// Reads what [`SessionKind::encode`] wrote (any format this release knows).
    fn decode(r: &mut Reader<'_>) -> Result<Self, ServiceError>;
    fn encode_update(u: &Self::Update, w: &mut Writer);
    fn decode_update(r: &mut Reader<'_>) -> Result<Self::Update, FormatError>;
    /// Writes a batch as the payload of a log entry (see [`persist`]): every
    /// field, exactly, so that applying the decoded batch to the same state
    /// gives the same state. `false`: this batch (or this kind) has no such
    /// form, and the session stores a snapshot instead.
    fn encode_batch(batch: &Self::Batch, w: &mut Writer) -> bool {
        let _ = (batch, w);
        false
    }
    /// Reads what [`SessionKind::encode_batch`] wrote.
    fn decode_batch(r: &mut Reader<'_>) -> Result<Self::Batch, FormatError> {
        let _ = r;
        Err(wire_formats::wire::corrupt(
            "this session kind keeps no log",
        ))
    }
    /// A session this kind wrote before the envelope existed (its first byte
    /// is below [`ENVELOPE_FORMAT`]); only the first kind has one.
    fn decode_legacy(buf: &[u8]) -> Result<Envelope<Self>, ServiceError> {
        let _ = buf;
        Err(ServiceError::Internal(format!(
            "stored session: a {} session has no format before the envelope",
            Self::NAME
        )))
    }
}

/// The kind tag of stored session bytes, without decoding them.
pub fn stored_kind(buf: &[u8]) -> Result<u8, ServiceError> {
    match buf {
        [1 | 2, ..] => Ok(LEGACY_KIND_TAG),
        [3 | ENVELOPE_FORMAT, tag, ..] => Ok(*tag),
        [f, ..] => Err(ServiceError::Internal(format!(
            "stored session has format {f}; this release reads 1 to {ENVELOPE_FORMAT}"
        ))),
        [] => Err(ServiceError::Internal("stored session: empty".into())),
    }
}

/// A session as a client asks for it: the envelope's settings and the
/// kind's configuration.
#[derive(Debug, Clone, Default)]
pub struct Spec<S> {
    pub idle_expiry_s: Option<f64>,
    pub body: S,
}

/// One batch: the envelope's sequence number and the kind's items.
#[derive(Debug, Clone, Default)]
pub struct Batch<B> {
    /// The client's sequence number: 1, 2, 3, …; a batch applied before is
    /// acknowledged again without being applied.
    pub sequence: Option<u64>,
    pub body: B,
}

/// What one batch changed.
#[derive(Debug, Clone, PartialEq)]
pub struct Update<U> {
    pub session_id: String,
    pub sequence: Option<u64>,
    /// The session's version after the batch (for a duplicate, its current one).
    pub version: u64,
    /// The batch had been applied before: nothing was applied now.
    pub duplicate: bool,
    pub body: U,
    pub warnings: Vec<String>,
}

/// A whole session, as a client reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct View<V> {
    pub id: String,
    pub kind: &'static str,
    pub version: u64,
    pub created_unix_ms: u64,
    pub last_sequence: Option<u64>,
    pub batches: u64,
    pub idle_expiry_s: f64,
    /// Size of the stored session.
    pub encoded_bytes: usize,
    pub body: V,
    /// What the creation decided that the caller should know (only in the
    /// answer to a create request).
    pub warnings: Vec<String>,
}

/// The update of the last sequenced batch, replayed to a retry of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Kept<U> {
    pub sequence: u64,
    pub body: U,
    pub warnings: Vec<String>,
}

/// A session of kind `K`: the kind's state and the generic protocol state.
pub struct Envelope<K: SessionKind> {
    pub state: K,
    pub created_unix_ms: u64,
    pub idle_expiry_s: f64,
    pub last_sequence: Option<u64>,
    pub batches: u64,
    pub last_update: Option<Kept<K::Update>>,
    /// Fingerprints of the last [`RECENT_BATCHES`] unsequenced batches
    /// applied, oldest first.
    pub recent: Vec<u64>,
}

/// 64-bit FNV-1a, the batches' fingerprint.
#[derive(Debug, Clone, Copy)]
pub struct Fnv(pub u64);

impl Default for Fnv {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    pub fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    pub fn f64(&mut self, x: f64) {
        self.bytes(&x.to_bits().to_le_bytes());
    }

    pub fn opt_f64(&mut self, x: Option<f64>) {
        match x {
            None => self.bytes(&[0]),
            Some(x) => {
                self.bytes(&[1]);
                self.f64(x);
            }
        }
    }

    pub fn str(&mut self, s: Option<&str>) {
        match s {
            None => self.bytes(&[0]),
            Some(s) => {
                self.bytes(&[1]);
                self.bytes(&(s.len() as u64).to_le_bytes());
                self.bytes(s.as_bytes());
            }
        }
    }
}

/// What the envelope says of a batch before it is applied.
pub enum Admission<U> {
    /// Apply it.
    Apply,
    /// Applied before: answer this, apply nothing.
    Duplicate(Update<U>),
}

fn corrupt(e: FormatError) -> ServiceError {
    ServiceError::Internal(format!("stored session: {e}"))
}

impl<K: SessionKind> Envelope<K> {
    /// A new session; validates the envelope's settings and the kind's
    /// configuration together, so that a client learns of every bad field.
    pub fn create(
        spec: Spec<K::Spec>,
        created_unix_ms: u64,
        warnings: &mut Vec<String>,
    ) -> Result<Self, ServiceError> {
        let idle = spec.idle_expiry_s.unwrap_or(DEFAULT_IDLE_EXPIRY_S);
        let mut v = Violations::new();
        if !(idle.is_finite() && idle > 0.0 && idle <= MAX_IDLE_EXPIRY_S) {
            v.add(
                "idle_expiry_s",
                format!("must be a number of seconds in (0, {MAX_IDLE_EXPIRY_S}]"),
            );
        }
        let state = match (K::create(spec.body, warnings), v.finish()) {
            (Ok(state), Ok(())) => state,
            (Err(ServiceError::InvalidInput(mut kind)), Err(ServiceError::InvalidInput(env))) => {
                kind.splice(0..0, env);
                return Err(ServiceError::InvalidInput(kind));
            }
            (Err(e), _) | (_, Err(e)) => return Err(e),
        };
        Ok(Self {
            state,
            created_unix_ms,
            idle_expiry_s: idle,
            last_sequence: None,
            batches: 0,
            last_update: None,
            recent: Vec::new(),
        })
    }

    /// Whether a batch with this sequence number is next (`Apply`), was
    /// applied before (`Duplicate`, with the answer to give), or skips ahead
    /// (a conflict naming the expected number). Sequences start at 1, so that
    /// the first batch of two concurrent writers cannot be mistaken for a
    /// duplicate; 0 is invalid. `version` is the session's current version.
    ///
    /// An unsequenced batch whose `fingerprint` is one of the last
    /// [`RECENT_BATCHES`] unsequenced batches applied is taken for a retry
    /// (of a batch whose answer was lost, or answered 503 or timed out
    /// after the store had written it): acknowledged, not applied twice.
    pub fn admit(
        &self,
        id: &str,
        sequence: Option<u64>,
        fingerprint: Option<u64>,
        version: u64,
    ) -> Result<Admission<K::Update>, ServiceError> {
        let Some(s) = sequence else {
            if let Some(f) = fingerprint
                && self.recent.contains(&f)
            {
                return Ok(Admission::Duplicate(Update {
                    session_id: id.to_string(),
                    sequence: None,
                    version,
                    duplicate: true,
                    body: self.state.acknowledgement(),
                    warnings: vec![format!(
                        "an identical unsequenced batch is among the last {RECENT_BATCHES} \
                         applied: taken for a retry, acknowledged and not applied twice (give \
                         batches sequence numbers to send identical content on purpose)"
                    )],
                }));
            }
            return Ok(Admission::Apply);
        };
        if s == 0 {
            return Err(Violations::single(
                "sequence",
                "must be at least 1 (the first batch carries 1)",
            ));
        }
        let last = self.last_sequence.unwrap_or(0);
        if s == last + 1 {
            Ok(Admission::Apply)
        } else if s <= last {
            Ok(Admission::Duplicate(self.duplicate_ack(id, s, version)))
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

    /// The answer to a batch applied before: a retry of the last batch gets
    /// that batch's update again (so a client whose answer was lost loses
    /// nothing); an older number gets an empty acknowledgement.
    fn duplicate_ack(&self, id: &str, sequence: u64, version: u64) -> Update<K::Update> {
        let last = self.last_sequence.unwrap_or_default();
        let (body, warnings) = match self.last_update.as_ref().filter(|u| u.sequence == sequence) {
            Some(kept) => {
                let mut warnings = kept.warnings.clone();
                warnings.push(format!(
                    "batch {sequence} was applied before: this is its update again; \
                     it was not applied twice"
                ));
                (kept.body.clone(), warnings)
            }
            None => (
                self.state.acknowledgement(),
                vec![format!(
                    "batch {sequence} was applied before (the session has applied up to \
                     {last}): acknowledged, not applied again"
                )],
            ),
        };
        Update {
            session_id: id.to_string(),
            sequence: Some(sequence),
            version,
            duplicate: true,
            body,
            warnings,
        }
    }

    /// Applies a batch that [`Envelope::admit`] let through. The update's
    /// `version` is 0 until the store has it.
    pub fn apply(
        &mut self,
        id: &str,
        batch: &Batch<K::Batch>,
        limits: &Limits,
    ) -> Result<Update<K::Update>, ServiceError> {
        self.apply_as(id, batch, limits, true)
    }

    /// [`Envelope::apply`]; with `read` false the update (and so the kept
    /// one) may lack what only a client reads ([`SessionKind::apply_unread`]):
    /// for log entries a later one follows.
    fn apply_as(
        &mut self,
        id: &str,
        batch: &Batch<K::Batch>,
        limits: &Limits,
        read: bool,
    ) -> Result<Update<K::Update>, ServiceError> {
        K::check_size(&batch.body, limits)?;
        let mut warnings = Vec::new();
        let body = if read {
            self.state.apply(&batch.body, limits, &mut warnings)?
        } else {
            self.state
                .apply_unread(&batch.body, limits, &mut warnings)?
        };
        if batch.sequence.is_some() {
            self.last_sequence = batch.sequence;
        } else if let Some(f) = K::fingerprint(&batch.body) {
            if self.recent.len() == RECENT_BATCHES {
                self.recent.remove(0);
            }
            self.recent.push(f);
        }
        self.batches += 1;
        self.last_update = batch.sequence.map(|sequence| Kept {
            sequence,
            body: body.clone(),
            warnings: warnings.clone(),
        });
        Ok(Update {
            session_id: id.to_string(),
            sequence: batch.sequence,
            version: 0,
            duplicate: false,
            body,
            warnings,
        })
    }

    pub fn view(
        &self,
        id: &str,
        version: u64,
        encoded_bytes: usize,
    ) -> Result<View<K::View>, ServiceError> {
        Ok(View {
            id: id.to_string(),
            kind: K::NAME,
            version,
            created_unix_ms: self.created_unix_ms,
            last_sequence: self.last_sequence,
            batches: self.batches,
            idle_expiry_s: self.idle_expiry_s,
            encoded_bytes,
            body: self.state.view()?,
            warnings: Vec::new(),
        })
    }

    /// The stored bytes: envelope format, kind tag, envelope fields, the
    /// kept update, then the kind's payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.u8(ENVELOPE_FORMAT);
        w.u8(K::TAG);
        w.u64(self.created_unix_ms);
        w.f64(self.idle_expiry_s);
        w.opt(self.last_sequence, Writer::u64);
        w.u64(self.batches);
        w.opt(self.last_update.as_ref(), |w, kept| {
            w.u64(kept.sequence);
            w.usize(kept.warnings.len());
            kept.warnings.iter().for_each(|s| w.str(s));
            K::encode_update(&kept.body, w);
        });
        w.usize(self.recent.len());
        self.recent.iter().for_each(|&f| w.u64(f));
        self.state.encode(&mut w);
        // The store keeps this buffer as it is: no spare capacity.
        w.buf.shrink_to_fit();
        w.buf
    }

    /// A batch this session applied as a log entry: `[ENTRY_FORMAT]
    /// [sequence] [limits] [the kind's batch]`; `None` when the kind has no
    /// encoding for it (the session then stores a snapshot).
    pub fn encode_entry(batch: &Batch<K::Batch>, limits: &Limits) -> Option<Vec<u8>> {
        let mut w = Writer::default();
        w.u8(ENTRY_FORMAT);
        w.opt(batch.sequence, Writer::u64);
        w.usize(limits.max_tracks);
        w.usize(limits.max_batch_reports);
        K::encode_batch(&batch.body, &mut w).then(|| {
            w.buf.shrink_to_fit();
            w.buf
        })
    }

    /// A copy of the session as stored ([`SessionKind::stored_copy`]), to
    /// encode off the request path; `None` when the kind has none.
    pub fn stored_copy(&self) -> Option<Self> {
        Some(Self {
            state: self.state.stored_copy()?,
            created_unix_ms: self.created_unix_ms,
            idle_expiry_s: self.idle_expiry_s,
            last_sequence: self.last_sequence,
            batches: self.batches,
            last_update: self.last_update.clone(),
            recent: self.recent.clone(),
        })
    }

    /// Applies a log entry (a batch the serving replica applied to this
    /// state, with its limits): the same state as that replica's after it.
    /// An entry that does not read or apply is a corrupt stored session.
    /// `last`: no later entry follows, so the kept update is built whole
    /// (for the others it is replaced, and what only a client reads of it
    /// is not built).
    pub fn replay(&mut self, id: &str, entry: &[u8], last: bool) -> Result<(), ServiceError> {
        let bad = |e: String| ServiceError::Internal(format!("stored session: log entry: {e}"));
        let mut r = Reader::new(entry);
        let format = r.u8().map_err(|e| bad(e.to_string()))?;
        if format != ENTRY_FORMAT {
            return Err(bad(format!(
                "format {format}; this release reads {ENTRY_FORMAT}"
            )));
        }
        let read = |r: &mut Reader<'_>| -> Result<_, FormatError> {
            let sequence = r.opt(Reader::u64)?;
            let limits = Limits {
                max_tracks: r.usize()?,
                max_batch_reports: r.usize()?,
            };
            let body = K::decode_batch(r)?;
            Ok((Batch { sequence, body }, limits))
        };
        let (batch, limits) = read(&mut r).map_err(|e| bad(e.to_string()))?;
        if !r.is_empty() {
            return Err(bad("trailing bytes".into()));
        }
        self.apply_as(id, &batch, &limits, last)
            .map_err(|e| bad(format!("did not apply again: {e}")))?;
        // What a batch marks for watchers went out when it was applied.
        self.state.take_marks();
        Ok(())
    }

    /// Reads stored bytes of kind `K`; bytes of another kind are
    /// [`DecodeError::WrongKind`].
    pub fn decode(buf: &[u8]) -> Result<Self, DecodeError> {
        let tag = stored_kind(buf)?;
        if tag != K::TAG {
            return Err(DecodeError::WrongKind { stored: tag });
        }
        if buf[0] < ENVELOPE_FORMAT {
            return Ok(K::decode_legacy(buf)?);
        }
        let mut r = Reader::new(&buf[2..]);
        let created_unix_ms = r.u64().map_err(corrupt)?;
        let idle_expiry_s = r.f64().map_err(corrupt)?;
        let last_sequence = r.opt(Reader::u64).map_err(corrupt)?;
        let batches = r.u64().map_err(corrupt)?;
        let last_update = r
            .opt(|r| {
                let sequence = r.u64()?;
                let n = r.len(8)?;
                let warnings = (0..n).map(|_| r.str()).collect::<Result<_, _>>()?;
                Ok(Kept {
                    sequence,
                    body: K::decode_update(r)?,
                    warnings,
                })
            })
            .map_err(corrupt)?;
        // Format 3 kept no fingerprints.
        let recent = if buf[0] >= 4 {
            let n = r.len(8).map_err(corrupt)?;
            (0..n)
                .map(|_| r.u64())
                .collect::<Result<Vec<_>, _>>()
                .map_err(corrupt)?
        } else {
            Vec::new()
        };
        let state = K::decode(&mut r)?;
        if !r.is_empty() {
            return Err(ServiceError::Internal("stored session: trailing bytes".into()).into());
        }
        Ok(Self {
            state,
            created_unix_ms,
            idle_expiry_s,
            last_sequence,
            batches,
            last_update,
            recent,
        })
    }
}

/// Why stored bytes did not decode as a session of the kind asked for.
#[derive(Debug)]
pub enum DecodeError {
    /// The bytes are a session of another kind (this tag).
    WrongKind {
        stored: u8,
    },
    Other(ServiceError),
}

impl From<ServiceError> for DecodeError {
    fn from(e: ServiceError) -> Self {
        Self::Other(e)
    }
}
