//! Late plots within a lag: exact reprocessing.
//!
//! A [`LagWindow`] wraps a [`Tracker`] for a stream whose plots arrive late
//! and out of order. It keeps
//! - `base`: the tracker after every plot older than the window,
//! - `window`: the accepted plots since, sorted by time (stably: at equal
//!   times in arrival order),
//! - `head`: `base` fed the window (a frame still open is buffered),
//! - the **picture**: `head` flushed, the tracks as they stand with every
//!   plot received so far (what a client is shown).
//!
//! A push whose plots are all at or after the window's newest continues
//! `head` (the tracker's streaming rule: feeding plots in time order in
//! chunks equals one call). A push with an older plot (late, but within the
//! lag) merges it into the window and replays from the newest kept
//! snapshot of `head` taken before it (snapshots are taken after each push,
//! in memory only), or from `base`. So the picture after any sequence of
//! pushes is bit for bit the picture of one [`Tracker`] call given every
//! accepted plot in arrival order and flushed: arrival order within the lag
//! does not matter (only the order of plots with equal times, which keep
//! their arrival order as in one call).
//!
//! The lag is measured in data time: the **horizon** is the newest plot
//! time received minus `max_lag` (never moving back). A plot older than the
//! horizon is late beyond the lag: dropped and counted, nothing else
//! changes. Plots older than the horizon move from the window into `base`
//! (by adopting a snapshot that holds exactly them, or, when none does and
//! the window reaches back more than two lags, by feeding them to `base`),
//! so memory grows with the lag, not with the stream's history.
//!
//! Why exact reprocessing rather than retrodiction (an out-of-sequence
//! update of the affected tracks): it is exact for association,
//! initiation and deletion as well as for the states (a late plot may start
//! a track or keep one alive), needs no approximation of the cross
//! covariance between the late plot and later updates, and its cost is the
//! replay of the plots after the late one, bounded by the lag.

use super::{Counters, Plot, StepReport, TrackOutput, Tracker};
use crate::error::AlgoError;

/// The default lag (s): ordinary radar network delays (processing and
/// links, a few seconds) and a hiccup of about two scans.
pub const DEFAULT_MAX_LAG_S: f64 = 15.0;
/// The largest lag accepted (s): memory and replay cost grow with it.
pub const MAX_LAG_LIMIT_S: f64 = 120.0;
/// Most plots a window holds by default (a plot takes 64 bytes in memory,
/// about 50 stored): at 4,000 aircraft under four radars (4,000 plots/s)
/// that is 250 s, more than the largest lag, so the bound acts only on
/// denser feeds. Beyond it the oldest plots move into `base` before their
/// lag is over: the horizon moves up, and the push says so.
pub const DEFAULT_MAX_WINDOW_PLOTS: usize = 1_000_000;
/// Snapshots of `head` kept in memory at most; beyond it the one whose
/// neighbours are closest in time goes.
const MAX_SNAPSHOTS: usize = 16;
/// Besides the snapshot after each push, one is taken this long (s of
/// data time) before the push's newest plot. A live feed's plots arrive a
/// little out of order (several radars' datagrams overlap by tens of
/// milliseconds), so nearly every push holds a plot older than the
/// previous push's newest: without it a replay went back to whatever
/// older snapshot had survived, seconds back (the ASTERIX check at 4,000
/// aircraft × 4 radars replayed about 19,000 plots a push for 30 late
/// ones); with it, about this much.
const RECENT_SNAPSHOT_S: f64 = 0.5;

/// A tracker that takes plots in any order within a lag; see the module
/// header.
#[derive(Debug, Clone)]
pub struct LagWindow {
    max_lag: f64,
    base: Tracker,
    window: Vec<Plot>,
    head: Tracker,
    picture: Tracker,
    /// Plots older than this are late beyond the lag.
    horizon: Option<f64>,
    /// Newest plot time accepted.
    newest: Option<f64>,
    /// Plots dropped as late beyond the lag.
    late: u64,
    /// `(n, head after window[..n])`, ascending n; not stored.
    snapshots: Vec<(usize, Tracker)>,
    /// Most plots held ([`DEFAULT_MAX_WINDOW_PLOTS`]; not stored).
    max_plots: usize,
    /// How plots older than the newest are taken.
    policy: LatePolicy,
    /// [`LatePolicy::Auto`]: the time of the earliest plot taken by
    /// retrodiction (stored).
    approximate_from: Option<f64>,
    /// [`LatePolicy::Auto`]: the window has held more than its bound of
    /// plots; it keeps no plots and no base since, and late plots are
    /// retrodicted (stored).
    past_bound: bool,
    /// Most live tracks of every tracker the window holds
    /// ([`LagWindow::set_max_tracks`]; stored, since the picture's open
    /// frame was flushed under it).
    max_tracks: Option<usize>,
}

/// How a [`LagWindow`] takes a plot older than the newest it has received
/// (within the lag).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LatePolicy {
    /// Exact reprocessing: the picture equals one call over every plot in
    /// time order, bit for bit, at the cost of replaying every plot
    /// received after the late one (module header).
    Reprocess,
    /// Retrodiction (serial mode; `late_plots: "retrodict"` of a
    /// session): the plot is a frame of its own and updates the tracks it
    /// gates with where they stand ([`Tracker::set_out_of_sequence`]);
    /// nothing is replayed, so its cost is the tracks it may touch. The
    /// picture equals one call over the plots in time order within a
    /// tolerance (association, initiation and deletion may differ where
    /// the order mattered; docs/RESULTS.md). The window keeps no plots and
    /// no base. A parallel-mode tracker reprocesses whatever the policy.
    Retrodict,
    /// Reprocessing while the window holds at most `max_replay` plots
    /// (what a replay from `base` costs at most), retrodiction beyond
    /// (the default, with [`DEFAULT_MAX_REPLAY_PLOTS`]): exact for
    /// networks whose lag holds few plots, bounded for those where a replay
    /// would cost more. Once a push leaves the window holding more than
    /// `max_replay` plots, it keeps no plots and no base from then on, as
    /// under `Retrodict` ([`LagWindow::past_bound`], stored): every late
    /// plot after is taken by retrodiction, and the head is approximate
    /// from the first one's time ([`LagWindow::approximate_from`]). (The
    /// plots and base could serve an exact replay again only once the lag
    /// held fewer plots than the bound; at the rates that pass it that is
    /// rare, and keeping them cost a tracker clone a push, a `base` fed
    /// every plot once approximate, and twice the stored state: issue 49,
    /// docs/RESULTS.md.)
    Auto {
        /// Most plots a push replays.
        max_replay: u32,
    },
}

impl Default for LatePolicy {
    fn default() -> Self {
        Self::Auto {
            max_replay: DEFAULT_MAX_REPLAY_PLOTS,
        }
    }
}

/// The default bound of [`LatePolicy::Auto`]: a replay of at most about
/// 35 ms at the tracker's 140 k plots/s (docs/RESULTS.md). A 15-s lag
/// holds that many plots up to about 330 plots/s (some 80 aircraft under
/// four 4-s radars): such sessions are exact; larger ones retrodict.
pub const DEFAULT_MAX_REPLAY_PLOTS: u32 = 5_000;

/// What one [`LagWindow::push`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Push {
    /// Indices (into the call's plots) of the plots late beyond the lag,
    /// dropped.
    /// Plots dropped as late beyond the lag.
    pub late: Vec<usize>,
    /// Accepted plots older than the newest plot already received: late,
    /// but within the lag (the picture was corrected for them).
    pub within_lag: usize,
    /// Time of the earliest of them.
    pub earliest_within_lag: Option<f64>,
    /// Plots received earlier that were processed again because a late
    /// plot came before them.
    pub replayed: usize,
    /// Frames processed by the call (replayed ones included, and the open
    /// frame of the picture).
    pub frames: usize,
    /// Tracks deleted by the frames the call processed (replayed ones
    /// included, so a deletion already reported may come again), as they
    /// were when deleted.
    pub deleted: Vec<TrackOutput>,
    /// Set when the window held more plots than its bound: the horizon
    /// was moved up to this time (plots older than it are now late,
    /// though within the lag).
    pub bounded_horizon: Option<f64>,
    /// Tentative tracks not started because the tracker held its bound of
    /// tracks, in the frames the call processed (replayed ones included).
    pub refused: usize,
    /// [`LatePolicy::Auto`]: late plots taken by retrodiction because
    /// their replay would have exceeded the bound.
    pub retrodicted: usize,
    /// Ids of tracks a frame could not associate (at a radar's site:
    /// [`super::StepReport::undefined`]), replayed frames included.
    pub undefined: Vec<u64>,
    /// Tracks whose numbers failed ([`super::StepReport::failed`]: dropped
    /// or coasted), replayed frames included (so a failure already
    /// reported may come again).
    pub failed: Vec<super::TrackFailure>,
}

impl Push {
    /// Counts what one tracker call did (frames, refused starts, deleted
    /// tracks).
    fn add(&mut self, report: StepReport) {
        self.frames += report.frames;
        self.refused += report.refused;
        self.deleted.extend(report.deleted);
        self.undefined.extend(report.undefined);
        self.failed.extend(report.failed);
    }
}

/// Everything a [`LagWindow`] stores, owned (the snapshots are not kept).
/// Under [`LatePolicy::Retrodict`] `base` is unused (a tracker of the
/// configuration without frames) and `window` empty.
#[derive(Debug, Clone, PartialEq)]
pub struct LagWindowParts {
    /// How late plots are taken.
    pub policy: LatePolicy,
    /// The lag (s).
    pub max_lag: f64,
    /// The tracker after every plot older than the window.
    pub base: Tracker,
    /// The accepted plots since `base`, sorted by time.
    pub window: Vec<Plot>,
    /// `base` fed the window, not flushed.
    pub head: Tracker,
    /// Plots older than this are late beyond the lag.
    pub horizon: Option<f64>,
    /// Newest plot time accepted.
    pub newest: Option<f64>,
    /// Plots dropped as late beyond the lag.
    pub late: u64,
    /// The head is approximate from this time ([`LatePolicy::Auto`]).
    pub approximate_from: Option<f64>,
    /// [`LatePolicy::Auto`] past its bound: no plots and no base kept,
    /// late plots retrodicted.
    pub past_bound: bool,
    /// Most live tracks ([`LagWindow::set_max_tracks`]).
    pub max_tracks: Option<usize>,
}

/// What a [`LagWindow`] stores, borrowed.
#[derive(Debug, Clone, Copy)]
pub struct LagWindowState<'a> {
    /// How late plots are taken.
    pub policy: LatePolicy,
    /// The lag (s).
    pub max_lag: f64,
    /// The tracker after every plot older than the window.
    pub base: &'a Tracker,
    /// The accepted plots since `base`, sorted by time.
    pub window: &'a [Plot],
    /// `base` fed the window, not flushed.
    pub head: &'a Tracker,
    /// Plots older than this are late beyond the lag.
    pub horizon: Option<f64>,
    /// Newest plot time accepted.
    pub newest: Option<f64>,
    /// Plots dropped as late beyond the lag.
    pub late: u64,
    /// The head is approximate from this time ([`LatePolicy::Auto`]).
    pub approximate_from: Option<f64>,
    /// [`LatePolicy::Auto`] past its bound: no plots and no base kept,
    /// late plots retrodicted.
    pub past_bound: bool,
    /// Most live tracks ([`LagWindow::set_max_tracks`]).
    pub max_tracks: Option<usize>,
}

/// Checks a lag (s): finite, in [0, [`MAX_LAG_LIMIT_S`]].
pub fn validate_lag(max_lag: f64) -> Result<(), AlgoError> {
    if max_lag.is_finite() && (0.0..=MAX_LAG_LIMIT_S).contains(&max_lag) {
        Ok(())
    } else {
        Err(crate::tracking::parameter::invalid(
            crate::tracking::TrackerParameter::MaxLag,
            format!("must be finite and in [0, {MAX_LAG_LIMIT_S}] s, got {max_lag}"),
        ))
    }
}

impl LagWindow {
    /// A window over `tracker` (usually new) with lag `max_lag` (s). A
    /// tracker that has processed frames keeps its own rule for what is
    /// late before them: the horizon starts at its last frame.
    pub fn new(tracker: Tracker, max_lag: f64) -> Result<Self, AlgoError> {
        Self::with_policy(tracker, max_lag, LatePolicy::default())
    }

    /// [`LagWindow::new`] with the policy for late plots (a parallel-mode
    /// tracker reprocesses whatever the policy).
    pub fn with_policy(
        mut tracker: Tracker,
        max_lag: f64,
        policy: LatePolicy,
    ) -> Result<Self, AlgoError> {
        validate_lag(max_lag)?;
        let policy = effective(&tracker, policy);
        tracker.set_out_of_sequence(policy == LatePolicy::Retrodict);
        let mut picture = tracker.clone();
        picture.flush()?;
        let base = match policy {
            LatePolicy::Retrodict => Tracker::with_config(tracker.valid_config())?,
            _ => tracker.clone(),
        };
        Ok(Self {
            max_lag,
            horizon: tracker.last_time(),
            newest: tracker.last_time(),
            base,
            head: tracker,
            picture,
            window: Vec::new(),
            late: 0,
            snapshots: Vec::new(),
            max_plots: DEFAULT_MAX_WINDOW_PLOTS,
            policy,
            approximate_from: None,
            past_bound: false,
            max_tracks: None,
        })
    }

    /// How late plots are taken.
    pub fn policy(&self) -> LatePolicy {
        self.policy
    }

    /// [`LatePolicy::Auto`]: the window has held more plots than its bound,
    /// so it keeps none and no base, and late plots are retrodicted.
    pub fn past_bound(&self) -> bool {
        self.past_bound
    }

    /// [`LatePolicy::Auto`]: the head (and the picture) is approximate from
    /// this time, a late plot having been taken by retrodiction (and every
    /// late plot since); `None` when exact.
    pub fn approximate_from(&self) -> Option<f64> {
        self.approximate_from
    }

    /// Rebuilds a window from its parts, checking them: the window's plots
    /// valid for the configuration and sorted, and `head` and `base` of the
    /// same configuration. (The window may reach back before the horizon:
    /// `base` moves in steps.)
    pub fn from_parts(parts: LagWindowParts) -> Result<Self, AlgoError> {
        validate_lag(parts.max_lag)?;
        let bad = |reason: &str| AlgoError::InvalidParameter {
            what: "lag window",
            reason: reason.into(),
        };
        if parts.base.config() != parts.head.config() {
            return Err(bad("base and head differ in configuration"));
        }
        for p in &parts.window {
            parts.head.config().validate_plot(p)?;
        }
        if !parts.window.windows(2).all(|w| w[0].t <= w[1].t) {
            return Err(bad("window plots out of time order"));
        }
        let policy = effective(&parts.head, parts.policy);
        if policy != parts.policy {
            return Err(bad("retrodiction needs a serial-mode tracker"));
        }
        if policy == LatePolicy::Retrodict && !parts.window.is_empty() {
            return Err(bad("a retrodicting window holds no plots"));
        }
        let auto = matches!(policy, LatePolicy::Auto { .. });
        if (parts.approximate_from.is_some() || parts.past_bound) && !auto {
            return Err(bad("only an auto window is approximate or past its bound"));
        }
        // An approximate auto window, or one holding more plots than its
        // bound, is past it (an earlier release's kept its plots and base:
        // dropped here).
        let past_bound = parts.past_bound
            || parts.approximate_from.is_some()
            || matches!(policy, LatePolicy::Auto { max_replay } if parts.window.len() > max_replay as usize);
        if parts.past_bound && !parts.window.is_empty() {
            return Err(bad("a window past its bound holds no plots"));
        }
        let mut head = parts.head;
        head.set_out_of_sequence(policy == LatePolicy::Retrodict || past_bound);
        // The picture is the head's open frame flushed under the limit the
        // window held, as the window that stored these parts flushed it.
        head.set_max_tracks(parts.max_tracks);
        let mut picture = head.clone();
        picture.flush()?;
        let (mut base, window) = if past_bound {
            (Tracker::new(head.config().clone())?, Vec::new())
        } else {
            (parts.base, parts.window)
        };
        base.set_max_tracks(parts.max_tracks);
        Ok(Self {
            policy,
            past_bound,
            approximate_from: parts.approximate_from,
            max_lag: parts.max_lag,
            base,
            window,
            head,
            picture,
            horizon: parts.horizon,
            newest: parts.newest,
            late: parts.late,
            snapshots: Vec::new(),
            max_plots: DEFAULT_MAX_WINDOW_PLOTS,
            max_tracks: parts.max_tracks,
        })
    }

    /// Holds at most `max_plots` plots from the next push on (at least 1;
    /// not stored: a decoded window has the default).
    pub fn set_max_plots(&mut self, max_plots: usize) {
        self.max_plots = max_plots.max(1);
    }

    /// Bounds the live tracks of every tracker the window holds (see
    /// [`Tracker::set_max_tracks`]). Stored with the window: the picture
    /// flushes the open frame under the limit, so a window rebuilt from
    /// its parts must flush it under the same one to show the same tracks
    /// (and, when the next plots close that frame, to continue from the
    /// same tracker).
    pub fn set_max_tracks(&mut self, max: Option<usize>) {
        self.max_tracks = max;
        self.base.set_max_tracks(max);
        self.head.set_max_tracks(max);
        self.picture.set_max_tracks(max);
        for (_, t) in &mut self.snapshots {
            t.set_max_tracks(max);
        }
    }

    /// Most plots the window holds.
    pub fn max_plots(&self) -> usize {
        self.max_plots
    }

    /// The stored parts (without the snapshots).
    pub fn to_parts(&self) -> LagWindowParts {
        LagWindowParts {
            policy: self.policy,
            approximate_from: self.approximate_from,
            past_bound: self.past_bound,
            max_lag: self.max_lag,
            base: self.base.clone(),
            window: self.window.clone(),
            head: self.head.clone(),
            horizon: self.horizon,
            newest: self.newest,
            late: self.late,
            max_tracks: self.max_tracks,
        }
    }

    /// A copy of what the window stores and its picture, without the
    /// in-memory snapshots of `head`: for encoding off the caller's path
    /// while the window goes on. The trackers share their tracks
    /// copy-on-write, so this costs the window's plots and the trackers'
    /// indices, not the tracks.
    pub fn stored_copy(&self) -> Self {
        Self {
            max_lag: self.max_lag,
            base: self.base.clone(),
            window: self.window.clone(),
            head: self.head.clone(),
            picture: self.picture.clone(),
            horizon: self.horizon,
            newest: self.newest,
            late: self.late,
            snapshots: Vec::new(),
            max_plots: self.max_plots,
            policy: self.policy,
            approximate_from: self.approximate_from,
            past_bound: self.past_bound,
            max_tracks: self.max_tracks,
        }
    }

    /// The stored parts, borrowed (for an encoder).
    pub fn state(&self) -> LagWindowState<'_> {
        LagWindowState {
            policy: self.policy,
            approximate_from: self.approximate_from,
            past_bound: self.past_bound,
            max_lag: self.max_lag,
            base: &self.base,
            window: &self.window,
            head: &self.head,
            horizon: self.horizon,
            newest: self.newest,
            late: self.late,
            max_tracks: self.max_tracks,
        }
    }

    /// The tracks with every plot received so far (`head` flushed).
    pub fn picture(&self) -> &Tracker {
        &self.picture
    }

    /// The lag (s).
    pub fn max_lag(&self) -> f64 {
        self.max_lag
    }

    /// Plots older than this time are late beyond the lag.
    pub fn horizon(&self) -> Option<f64> {
        self.horizon
    }

    /// Newest plot time accepted.
    pub fn newest(&self) -> Option<f64> {
        self.newest
    }

    /// Plots of the open frame (buffered in `head`; in the picture).
    pub fn pending(&self) -> usize {
        self.head.pending()
    }

    /// Plots held in the window (received within the lag).
    pub fn window_len(&self) -> usize {
        self.window.len()
    }

    /// The picture's counters, with the plots late beyond the lag in
    /// `late`.
    pub fn counters(&self) -> Counters {
        let mut c = self.picture.counters();
        c.late += self.late;
        c
    }

    /// Takes plots in any order: those older than the horizon are dropped
    /// as late; the others join the window and the picture is brought up to
    /// date (see the module header). Plots are validated before anything
    /// changes; a numerical error later leaves the window part-way, so a
    /// caller that must stay consistent keeps its stored copy.
    pub fn push(&mut self, plots: &[Plot]) -> Result<Push, AlgoError> {
        for p in plots {
            self.head.config().validate_plot(p)?;
        }
        let mut out = Push::default();
        let mut accepted = Vec::with_capacity(plots.len());
        for (i, p) in plots.iter().enumerate() {
            if self.horizon.is_some_and(|h| p.t < h) {
                out.late.push(i);
                self.late += 1;
            } else {
                accepted.push(*p);
            }
        }
        if accepted.is_empty() {
            return Ok(out);
        }
        accepted.sort_by(|a, b| a.t.total_cmp(&b.t));
        if let Some(newest) = self.newest {
            let older: Vec<f64> = accepted
                .iter()
                .map(|p| p.t)
                .filter(|&t| t < newest)
                .collect();
            out.within_lag = older.len();
            out.earliest_within_lag = older.first().copied();
        }
        if self.policy == LatePolicy::Retrodict {
            return self.push_retrodicting(&accepted, out);
        }
        if self.past_bound {
            // Auto past its bound: retrodiction.
            out.retrodicted = out.within_lag;
            if let Some(earliest) = out.earliest_within_lag {
                self.approximate_from =
                    Some(self.approximate_from.map_or(earliest, |a| a.min(earliest)));
            }
            return self.push_retrodicting(&accepted, out);
        }
        let at = self.window.partition_point(|p| p.t <= accepted[0].t);
        if at == self.window.len() {
            // The picture is the head with its open frame closed; when the
            // new plots close that frame without joining it, the head
            // continues from the picture instead of processing the frame
            // again (the same tracker, bit for bit: see
            // `Tracker::closes_pending`).
            if self.head.closes_pending(&accepted[0])? {
                std::mem::swap(&mut self.head, &mut self.picture);
            }
            let start = self.window.len();
            self.window.extend_from_slice(&accepted);
            self.feed(start, &mut out)?;
        } else {
            // A late plot: replay from the newest snapshot before it, or
            // from `base`. (Under auto the window holds at most its bound
            // here: past it, it keeps none.)
            let tail = merge(&self.window[at..], &accepted);
            self.window.truncate(at);
            self.window.extend(tail);
            self.snapshots.retain(|(n, _)| *n <= at);
            let (start, from) = match self.snapshots.last() {
                Some((n, tr)) => (*n, tr.clone()),
                None => (0, self.base.clone()),
            };
            self.head = from;
            self.feed(start, &mut out)?;
            out.replayed = self.window.len() - start - accepted.len();
        }
        self.advance(accepted[accepted.len() - 1].t);
        self.snapshots.push((self.window.len(), self.head.clone()));
        self.commit()?;
        out.bounded_horizon = self.bound()?;
        if let LatePolicy::Auto { max_replay } = self.policy
            && self.window.len() > max_replay as usize
        {
            // No late plot can be replayed within the bound now: the next
            // one is retrodicted, and so is every one after it.
            self.drop_window()?;
            self.refresh_picture(&mut out)?;
            return Ok(out);
        }
        self.thin();
        self.refresh_picture(&mut out)?;
        Ok(out)
    }

    /// Keeps no plots and no base from here on (as under
    /// [`LatePolicy::Retrodict`]: `base` a tracker of the configuration
    /// without frames); the head takes late plots by retrodiction.
    fn drop_window(&mut self) -> Result<(), AlgoError> {
        self.past_bound = true;
        self.window = Vec::new();
        self.snapshots = Vec::new();
        self.base = Tracker::new(self.head.config().clone())?;
        self.base.set_max_tracks(self.max_tracks);
        self.head.set_out_of_sequence(true);
        Ok(())
    }

    /// [`LagWindow::push`] under [`LatePolicy::Retrodict`]: the accepted
    /// plots (sorted by time) go to `head`, which takes the older ones by
    /// retrodiction; the picture is `head` flushed.
    fn push_retrodicting(&mut self, accepted: &[Plot], mut out: Push) -> Result<Push, AlgoError> {
        if self.head.closes_pending(&accepted[0])? {
            std::mem::swap(&mut self.head, &mut self.picture);
        }
        let report = self.head.process(accepted)?;
        out.add(report);
        self.advance(accepted[accepted.len() - 1].t);
        self.refresh_picture(&mut out)?;
        Ok(out)
    }

    /// The picture: `head` flushed (its open frame closed), what the
    /// flush did counted in `out`.
    fn refresh_picture(&mut self, out: &mut Push) -> Result<(), AlgoError> {
        let mut picture = self.head.clone();
        out.add(picture.flush()?);
        self.picture = picture;
        Ok(())
    }

    /// The newest plot time and the horizon after plots up to `last`.
    fn advance(&mut self, last: f64) {
        let newest = self.newest.map_or(last, |n| n.max(last));
        self.newest = Some(newest);
        let horizon = newest - self.max_lag;
        self.horizon = Some(self.horizon.map_or(horizon, |h| h.max(horizon)));
    }

    /// Feeds `window[start..]` to `head` (which holds `window[..start]`),
    /// keeping a snapshot [`RECENT_SNAPSHOT_S`] before the newest plot on
    /// the way (two calls in time order equal one: the tracker's
    /// streaming rule).
    fn feed(&mut self, start: usize, out: &mut Push) -> Result<(), AlgoError> {
        let newest = self.window[self.window.len() - 1].t;
        let cut =
            start + self.window[start..].partition_point(|p| p.t <= newest - RECENT_SNAPSHOT_S);
        let mut from = start;
        if cut > start && cut < self.window.len() {
            let report = self.head.process(&self.window[start..cut])?;
            out.add(report);
            self.snapshots.push((cut, self.head.clone()));
            from = cut;
        }
        let report = self.head.process(&self.window[from..])?;
        out.add(report);
        Ok(())
    }

    /// Moves the plots older than the horizon from the window into `base`.
    fn commit(&mut self) -> Result<(), AlgoError> {
        let Some(h) = self.horizon else {
            return Ok(());
        };
        let window = &self.window;
        let adoptable = self
            .snapshots
            .iter()
            .rposition(|(n, _)| *n > 0 && window[*n - 1].t < h);
        if let Some(i) = adoptable {
            let mut kept = self.snapshots.split_off(i);
            let (n, tracker) = kept.remove(0);
            self.base = tracker;
            self.window.drain(..n);
            self.snapshots = kept.into_iter().map(|(m, t)| (m - n, t)).collect();
        }
        if self.window.first().is_some_and(|p| p.t < h - self.max_lag) {
            self.feed_base_before(h)?;
        }
        Ok(())
    }

    /// Feeds the window's plots older than `h` to `base` and drops them
    /// (and the snapshots within them) from the window.
    fn feed_base_before(&mut self, h: f64) -> Result<(), AlgoError> {
        let n = self.window.partition_point(|p| p.t < h);
        self.base.process(&self.window[..n])?;
        self.window.drain(..n);
        self.snapshots = std::mem::take(&mut self.snapshots)
            .into_iter()
            .filter(|(m, _)| *m >= n)
            .map(|(m, t)| (m - n, t))
            .collect();
        Ok(())
    }

    /// Holds the window to `max_plots`: the oldest plots beyond it go into
    /// `base` and the horizon moves up to the oldest plot kept; that time.
    fn bound(&mut self) -> Result<Option<f64>, AlgoError> {
        if self.window.len() <= self.max_plots {
            return Ok(None);
        }
        let h = self.window[self.window.len() - self.max_plots].t;
        self.horizon = Some(self.horizon.map_or(h, |x| x.max(h)));
        self.feed_base_before(h)?;
        Ok(Some(h))
    }

    /// Keeps at most [`MAX_SNAPSHOTS`]: drops the inner snapshot whose
    /// neighbours are closest in time, until few enough.
    fn thin(&mut self) {
        while self.snapshots.len() > MAX_SNAPSHOTS {
            let time = |k: usize| {
                let n = self.snapshots[k].0;
                if n == 0 {
                    f64::NEG_INFINITY
                } else {
                    self.window[n - 1].t
                }
            };
            let drop = (1..self.snapshots.len() - 1)
                .min_by(|&a, &b| {
                    let gap = |k: usize| time(k + 1) - time(k - 1);
                    gap(a).total_cmp(&gap(b))
                })
                .unwrap_or(0);
            self.snapshots.remove(drop);
        }
    }
}

/// The policy a window over `tracker` applies: a parallel-mode tracker's
/// fusion instants reprocess.
fn effective(tracker: &Tracker, policy: LatePolicy) -> LatePolicy {
    if tracker.mode() == super::Mode::Parallel {
        LatePolicy::Reprocess
    } else {
        policy
    }
}

/// Stable merge of two time-sorted runs: at equal times `earlier` first.
fn merge(earlier: &[Plot], later: &[Plot]) -> Vec<Plot> {
    let mut out = Vec::with_capacity(earlier.len() + later.len());
    let (mut i, mut j) = (0, 0);
    while i < earlier.len() && j < later.len() {
        if earlier[i].t <= later[j].t {
            out.push(earlier[i]);
            i += 1;
        } else {
            out.push(later[j]);
            j += 1;
        }
    }
    out.extend_from_slice(&earlier[i..]);
    out.extend_from_slice(&later[j..]);
    out
}
