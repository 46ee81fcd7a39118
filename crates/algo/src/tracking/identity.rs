//! Secondary surveillance in the tracker: what an SSR or Mode S reply tells
//! about the aircraft (its Mode 3/A code, Mode C pressure altitude, Mode S
//! address and identification), what a track has learnt of it, and the
//! evidence it gives the association.
//!
//! Association (operational trackers put identity first: OpenATS COMPASS's
//! reconstructor associates by Mode S address, then by Mode A/C and
//! position, then by position alone). Here each pairing of a plot with a
//! track gets a likelihood ratio Λ = p(identity | the plot is the track's)
//! / p(identity | the plot is clutter or another aircraft's), which
//! multiplies the JPDA weight a_tj (`jpda::Evidence`); the position gate
//! still applies:
//! - **Mode S address.** The same address: Λ = (1 − ε_A) / ε_A with
//!   ε_A = 10⁻⁴ (an address is unique; the reply's parity protects it). A
//!   different address rules the pairing out. Without an address on
//!   either side, Λ = 1.
//! - **Mode 3/A code** (when neither side's address decides): a validated,
//!   ungarbled code equal to the track's gives Λ = (1 − p_c) / f(c), with
//!   p_c = 0.02 the chance of a code change or an undetected garble
//!   between two replies and f(c) the chance that another aircraft
//!   squawks c: 1/1000 for a discrete code, 1/4 for the conspicuity codes
//!   7000, 2000 and 1200 (so two aircraft squawking 7000 side by side are
//!   told apart by position, not by their code). A different code gives
//!   Λ = p_c / (1 − f(c)): a code change is unlikely, not a new aircraft.
//!   An unvalidated code counts half (ln Λ / 2); a garbled one not at all.
//! - **Mode C.** The track's pressure altitude predicted to the plot's
//!   time, N(ν; 0, S) with S = P_hh + R, against a uniform altitude over
//!   [`ALTITUDE_SPAN_FT`]: Λ = (1 − ε_C) N(ν; 0, S) H + ε_C, with ε_C = 0.05
//!   (0.2 unvalidated) for a wrong or garbled altitude. Aircraft that cross
//!   1,000 ft apart are told apart even where their plots overlap.
//!
//! A track keeps its identity with its evidence ([`Evidence`]: the plots
//! that gave it, when first and last seen). A new Mode 3/A code is adopted
//! after [`CODE_CHANGE_REPLIES`] replies agree on it (a garbled reply
//! does not change a track's code). The pressure altitude is its own
//! filter ([`PressureAltitude`], flight level and rate of climb, constant
//! vertical rate with white acceleration), kept apart from the geometric
//! height as air traffic control does. The quantisation of Mode C (100 ft
//! for Gillham-coded replies, 25 ft for Mode S) is part of its
//! measurement noise, q²/12.

use crate::error::AlgoError;

/// The largest Mode S address (24 bits).
pub const MAX_ADDRESS: u32 = 0xFF_FFFF;
/// The largest Mode 3/A code (four octal digits, 12 bits).
pub const MAX_CODE: u16 = 0o7777;
/// Flight levels a Mode C or Mode S reply can carry (I048/090: −12 to
/// 1,270 FL).
pub const FLIGHT_LEVEL_RANGE: (f64, f64) = (-12.0, 1270.0);
/// The altitude span the Mode C evidence compares against (ft).
pub const ALTITUDE_SPAN_FT: f64 = 60_000.0;
/// Replies with a new Mode 3/A code before a track adopts it.
pub const CODE_CHANGE_REPLIES: u32 = 2;
/// How long a track shows the SPI flag after the last reply that set it
/// (s; the transponder holds it about 18 s).
pub const SPI_HOLD_S: f64 = 18.0;

const ADDRESS_ERROR: f64 = 1e-4;
const CODE_CHANGE: f64 = 0.02;
const DISCRETE_CODE_SHARE: f64 = 1e-3;
const CONSPICUITY_CODE_SHARE: f64 = 0.25;
const ALTITUDE_ERROR: f64 = 0.05;
const UNVALIDATED_ALTITUDE_ERROR: f64 = 0.2;
/// Spectral density of the vertical acceleration (ft²/s³): a level-off
/// or a change of climb rate of about 2 ft/s² (0.6 m/s²).
const VERTICAL_Q: f64 = 4.0;
/// A Mode C value further than this many σ from the prediction is not
/// used to update the pressure altitude (a wrong reply); after
/// [`RESTART_AFTER`] in a row the filter starts again from the reply.
const ALTITUDE_GATE_SIGMAS: f64 = 5.0;
const RESTART_AFTER: u32 = 3;
/// Prior σ of the rate of climb of a new pressure-altitude filter (ft/s):
/// 3,000 ft/min.
const PRIOR_RATE_SIGMA: f64 = 50.0;

/// How a radar detected a plot (I048/020 TYP).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Detection {
    /// Primary radar only: position, no identity.
    Primary,
    /// Secondary (SSR or Mode S) only.
    Secondary,
    /// Primary and secondary together.
    Combined,
}

/// A Mode 3/A code as a reply gave it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mode3A {
    /// The code, 12 bits (four octal digits: 7000 is `0o7000`).
    pub code: u16,
    /// Validated by the radar (I048/070 V = 0).
    pub validated: bool,
    /// Garbled (I048/070 G = 1).
    pub garbled: bool,
}

/// A Mode C (or Mode S) pressure altitude as a reply gave it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeC {
    /// Flight level (hundreds of feet above the 1013.25 hPa isobar).
    pub flight_level: f64,
    /// Validated by the radar (I048/090 V = 0).
    pub validated: bool,
    /// Garbled (I048/090 G = 1).
    pub garbled: bool,
}

/// An aircraft identification (callsign): up to 8 characters of the
/// ICAO 6-bit set (A–Z, 0–9, space), space-padded.
pub type Callsign = [u8; 8];

/// What a plot says of the aircraft beside its position. Empty (the
/// default) for a primary plot.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Identity {
    /// Mode S address (24 bits).
    pub address: Option<u32>,
    /// Mode 3/A code.
    pub mode_3a: Option<Mode3A>,
    /// Mode C pressure altitude.
    pub mode_c: Option<ModeC>,
    /// Aircraft identification.
    pub callsign: Option<Callsign>,
    /// How the plot was detected, when the radar says.
    pub detection: Option<Detection>,
    /// Special position identification pulse.
    pub spi: bool,
    /// A ship's AIS MMSI (nine digits, at most 999,999,999).
    pub mmsi: Option<u32>,
}

impl Identity {
    /// No identity at all (a primary plot).
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// The plot came (at least partly) from a secondary reply.
    pub fn is_secondary(&self) -> bool {
        matches!(
            self.detection,
            Some(Detection::Secondary | Detection::Combined)
        ) || self.address.is_some()
            || self.mode_3a.is_some()
            || self.mode_c.is_some()
    }

    /// The plot came (at least partly) from the primary radar: said so,
    /// or said nothing and carries no secondary field.
    pub fn is_primary(&self) -> bool {
        match self.detection {
            Some(d) => d != Detection::Secondary,
            None => !self.is_secondary(),
        }
    }

    /// The Mode C measurement's quantum (ft): 25 ft from Mode S replies
    /// (or a value off the 100-ft grid), 100 ft for Gillham-coded Mode C.
    pub fn altitude_quantum_ft(&self) -> f64 {
        match self.mode_c {
            Some(c)
                if self.address.is_none()
                    && (c.flight_level - c.flight_level.round()).abs() < 1e-9 =>
            {
                100.0
            }
            _ => 25.0,
        }
    }
}

/// The emergency a special Mode 3/A code declares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Emergency {
    /// 7500: unlawful interference.
    UnlawfulInterference,
    /// 7600: radio failure.
    RadioFailure,
    /// 7700: general emergency.
    General,
}

impl Emergency {
    /// The emergency `code` declares, if any.
    pub fn of(code: u16) -> Option<Self> {
        match code {
            0o7500 => Some(Self::UnlawfulInterference),
            0o7600 => Some(Self::RadioFailure),
            0o7700 => Some(Self::General),
            _ => None,
        }
    }

    /// The wire name.
    pub fn name(self) -> &'static str {
        match self {
            Self::UnlawfulInterference => "unlawful_interference",
            Self::RadioFailure => "radio_failure",
            Self::General => "emergency",
        }
    }
}

/// A conspicuity code (7000 in Europe, 1200 in America, 2000 entering
/// SSR airspace): many aircraft squawk it at once.
pub fn is_conspicuity(code: u16) -> bool {
    matches!(code, 0o7000 | 0o2000 | 0o1200)
}

/// One identity a track holds and the evidence for it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evidence<T> {
    /// The value.
    pub value: T,
    /// Plots associated with the track that gave it.
    pub plots: u32,
    /// Time of the first of them (s).
    pub first_t: f64,
    /// Time of the last of them (s).
    pub last_t: f64,
}

impl<T: PartialEq + Copy> Evidence<T> {
    fn new(value: T, t: f64) -> Self {
        Self {
            value,
            plots: 1,
            first_t: t,
            last_t: t,
        }
    }

    fn seen(&mut self, t: f64) {
        self.plots = self.plots.saturating_add(1);
        self.first_t = self.first_t.min(t);
        self.last_t = self.last_t.max(t);
    }
}

/// The pressure altitude of a track: flight level h (ft) and rate of
/// climb ḣ (ft/s) at time `t`, constant vertical rate with white
/// acceleration of spectral density [`VERTICAL_Q`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureAltitude {
    /// Time of the estimate (s).
    pub t: f64,
    /// `[h, ḣ]` (ft, ft/s).
    pub x: [f64; 2],
    /// Covariance `[P_hh, P_hḣ, P_ḣḣ]`.
    pub p: [f64; 3],
    /// The last Mode C value used (ft) and its time (s).
    pub measured: (f64, f64),
    /// Mode C values in a row that fell outside the gate.
    pub rejected: u32,
}

impl PressureAltitude {
    fn start(feet: f64, r: f64, t: f64) -> Self {
        Self {
            t,
            x: [feet, 0.0],
            p: [r, 0.0, PRIOR_RATE_SIGMA * PRIOR_RATE_SIGMA],
            measured: (feet, t),
            rejected: 0,
        }
    }

    /// `[h, ḣ]` and covariance predicted to `t` (backwards too, for a late
    /// plot's evidence; the process noise grows with |Δt|).
    pub fn predicted(&self, t: f64) -> ([f64; 2], [f64; 3]) {
        let dt = t - self.t;
        let a = dt.abs();
        let q = VERTICAL_Q;
        let [p00, p01, p11] = self.p;
        (
            [self.x[0] + dt * self.x[1], self.x[1]],
            [
                p00 + 2.0 * dt * p01 + dt * dt * p11 + q * a * a * a / 3.0,
                p01 + dt * p11 + q * a * a / 2.0 * dt.signum(),
                p11 + q * a,
            ],
        )
    }

    /// The Kalman update with a Mode C value `z` (ft) of variance `r` at
    /// `t` (≥ the estimate's time), or a rejection when it lies beyond the
    /// gate.
    fn update(&mut self, z: f64, r: f64, t: f64) {
        let (x, p) = self.predicted(t);
        let s = p[0] + r;
        let nu = z - x[0];
        if nu * nu > ALTITUDE_GATE_SIGMAS * ALTITUDE_GATE_SIGMAS * s {
            self.rejected += 1;
            if self.rejected >= RESTART_AFTER {
                *self = Self::start(z, r, t);
            }
            return;
        }
        let (k0, k1) = (p[0] / s, p[1] / s);
        self.x = [x[0] + k0 * nu, x[1] + k1 * nu];
        self.p = [(1.0 - k0) * p[0], (1.0 - k0) * p[1], p[2] - k1 * p[1]];
        self.t = t;
        self.measured = (z, t);
        self.rejected = 0;
    }
}

/// What a track has learnt of its aircraft's identity.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrackIdentity {
    /// Mode S address.
    pub address: Option<Evidence<u32>>,
    /// AIS MMSI (a ship's).
    pub mmsi: Option<Evidence<u32>>,
    /// Mode 3/A code.
    pub mode_3a: Option<Evidence<u16>>,
    /// A code replies have given since the adopted one, not yet adopted.
    pub pending_3a: Option<Evidence<u16>>,
    /// Aircraft identification.
    pub callsign: Option<Evidence<Callsign>>,
    /// Pressure altitude (from validated, ungarbled Mode C).
    pub altitude: Option<PressureAltitude>,
    /// Time of the last reply with SPI set (s).
    pub spi_t: Option<f64>,
    /// Time of the last update by a radar's secondary plot (s).
    /// Cooperative reports (ADS-B, multilateration, AIS) date none of
    /// these three ([`TrackIdentity::observe_report`]).
    pub last_secondary: Option<f64>,
    /// Time of the last update by a radar's plot with a Mode S address
    /// (s).
    pub last_mode_s: Option<f64>,
    /// Time of the last update by a radar's primary (or combined) plot
    /// (s).
    pub last_primary: Option<f64>,
    /// Time of the last update by a Mode S radar's secondary plot without
    /// an address (s): the track's aircraft answers in Mode A/C only
    /// ([`without_mode_s`]), so a reply with an address is another's.
    pub last_mode_ac: Option<f64>,
    /// What independent evidence (radars, multilateration) says of the
    /// positions the aircraft reports itself (ADS-B, AIS).
    pub validation: Validation,
}

/// Reports disagreeing in a row with a track held by independent evidence
/// before its self-reported positions are distrusted: two (a radar scan or
/// two, a few seconds), so that one bad report or one false reply does not
/// flag an aircraft.
pub const DISAGREEMENTS_TO_DISTRUST: u32 = 2;
/// Self-reported positions agreeing in a row with the track before they
/// are trusted again (about 5 s of ADS-B).
pub const AGREEMENTS_TO_TRUST: u32 = 5;
/// An independent update this recent (s) makes a track independently held:
/// its self-reported positions can be checked, and are validated.
pub const INDEPENDENT_WINDOW_S: f64 = 30.0;

/// The check of a track's self-reported positions (ADS-B, AIS) against
/// independent evidence (radar plots, multilateration): see
/// docs/plot-fusion.md, "Cooperative reports".
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Validation {
    /// Time of the last update by an independent sensor (a radar's plot,
    /// a multilateration report) (s).
    pub last_independent: Option<f64>,
    /// Time of the last update by a self-reported position (s).
    pub last_self_reported: Option<f64>,
    /// Since when the self-reported positions are distrusted (they
    /// disagreed with the independent evidence); `None`: trusted.
    pub distrusted_since: Option<f64>,
    /// Disagreements in a row (an independent plot of the track's address
    /// outside the gate of its self-reported state, or a self-reported
    /// position outside the gate of its independently held state).
    pub disagreements: u32,
    /// Self-reported positions agreeing in a row while distrusted.
    pub agreements: u32,
    /// The last disagreement.
    pub last_disagreement: Option<Disagreement>,
}

/// One disagreement between a self-reported position and independent
/// evidence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disagreement {
    /// When (s).
    pub t: f64,
    /// Horizontal distance between the self-reported position and the
    /// independent evidence (m).
    pub distance: f64,
    /// The self-reported position's stated σ (m, per horizontal axis).
    pub sigma: f64,
}

impl Validation {
    /// Whether the track's self-reported positions are used.
    pub fn trusted(&self) -> bool {
        self.distrusted_since.is_none()
    }

    /// Whether an independent update at most [`INDEPENDENT_WINDOW_S`] old
    /// at `t` holds the track.
    pub fn independently_held(&self, t: f64) -> bool {
        self.last_independent
            .is_some_and(|s| t - s <= INDEPENDENT_WINDOW_S)
    }

    /// Records a disagreement; returns `true` when it makes the track
    /// distrust its self-reported positions (it did not before).
    pub fn disagree(&mut self, d: Disagreement) -> bool {
        self.last_disagreement = Some(d);
        self.agreements = 0;
        self.disagreements = self.disagreements.saturating_add(1);
        if self.trusted() && self.disagreements >= DISAGREEMENTS_TO_DISTRUST {
            self.distrusted_since = Some(d.t);
            return true;
        }
        false
    }

    /// Records a self-reported position that agrees with the track while
    /// distrusted; returns `true` when trust is restored.
    pub fn agree(&mut self) -> bool {
        self.disagreements = 0;
        if self.trusted() {
            return false;
        }
        self.agreements = self.agreements.saturating_add(1);
        if self.agreements >= AGREEMENTS_TO_TRUST {
            self.distrusted_since = None;
            self.agreements = 0;
            return true;
        }
        false
    }
}

impl TrackIdentity {
    /// `true` when the track has learnt nothing of its identity.
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// The emergency the track's code declares.
    pub fn emergency(&self) -> Option<Emergency> {
        self.mode_3a.and_then(|c| Emergency::of(c.value))
    }

    /// The SPI flag at `t`.
    pub fn spi(&self, t: f64) -> bool {
        self.spi_t.is_some_and(|s| t - s <= SPI_HOLD_S)
    }

    /// ln Λ of pairing a plot of identity `plot` at `t` with this track
    /// (see the module's documentation); `None` rules the pairing out.
    /// `mode_s_radar`: the plot's radar gives Mode S addresses, so a
    /// secondary plot of it without one is a Mode A/C transponder's
    /// ([`without_mode_s`]): against a track with an address it weighs
    /// [`NO_ADDRESS_FROM_MODE_S`], and so does a plot with an address
    /// against a track whose aircraft answered a Mode S radar without one
    /// (`last_mode_ac`).
    pub fn ln_ratio(&self, plot: &Identity, t: f64, mode_s_radar: bool) -> Option<f64> {
        let mut ln = 0.0;
        // An MMSI is a ship's as an address is an aircraft's.
        match (self.mmsi, plot.mmsi) {
            (Some(a), Some(b)) if a.value != b => return None,
            (Some(_), Some(_)) => ln += ((1.0 - ADDRESS_ERROR) / ADDRESS_ERROR).ln(),
            _ => {}
        }
        match (self.address, plot.address) {
            (Some(a), Some(b)) if a.value != b => return None,
            (Some(_), Some(_)) => ln += ((1.0 - ADDRESS_ERROR) / ADDRESS_ERROR).ln(),
            (address, reply) => {
                ln += self.code_ln_ratio(plot);
                let mode_ac_against_mode_s = match address {
                    Some(_) => without_mode_s(plot, mode_s_radar),
                    None => reply.is_some() && self.last_mode_ac.is_some(),
                };
                if mode_ac_against_mode_s {
                    ln += NO_ADDRESS_FROM_MODE_S.ln();
                }
            }
        }
        ln += self.altitude_ln_ratio(plot, t);
        Some(ln)
    }

    fn code_ln_ratio(&self, plot: &Identity) -> f64 {
        let (Some(track), Some(reply)) = (self.mode_3a, plot.mode_3a) else {
            return 0.0;
        };
        if reply.garbled {
            return 0.0;
        }
        let share = if is_conspicuity(reply.code) {
            CONSPICUITY_CODE_SHARE
        } else {
            DISCRETE_CODE_SHARE
        };
        let matches =
            reply.code == track.value || self.pending_3a.is_some_and(|p| p.value == reply.code);
        let ln = if matches {
            ((1.0 - CODE_CHANGE) / share).ln()
        } else {
            (CODE_CHANGE / (1.0 - share)).ln()
        };
        if reply.validated { ln } else { ln / 2.0 }
    }

    fn altitude_ln_ratio(&self, plot: &Identity, t: f64) -> f64 {
        let (Some(alt), Some(c)) = (self.altitude, plot.mode_c) else {
            return 0.0;
        };
        if c.garbled {
            return 0.0;
        }
        let eps = if c.validated {
            ALTITUDE_ERROR
        } else {
            UNVALIDATED_ALTITUDE_ERROR
        };
        let (x, p) = alt.predicted(t);
        let s = p[0] + altitude_variance(plot);
        let nu = c.flight_level * 100.0 - x[0];
        let density = (-0.5 * nu * nu / s).exp() / (2.0 * std::f64::consts::PI * s).sqrt();
        ((1.0 - eps) * density * ALTITUDE_SPAN_FT + eps).ln()
    }

    /// Learns from a radar plot of identity `plot` at `t` that updated the
    /// track (its most likely plot): its identity, and the time of the
    /// track's last primary, secondary and Mode S update. A plot older
    /// than the pressure altitude (out of sequence) adds its evidence but
    /// does not move the filter.
    pub fn observe(&mut self, plot: &Identity, t: f64) {
        let later = |s: Option<f64>| Some(s.map_or(t, |s| s.max(t)));
        if plot.is_empty() {
            // A plot that says nothing of itself is a primary radar's: it
            // dates the track's last primary update once the track has
            // heard a secondary reply (a track that never has keeps an
            // empty identity: a primary-only tracker's state is as before).
            if !self.is_empty() {
                self.last_primary = later(self.last_primary);
            }
            return;
        }
        if plot.is_secondary() {
            self.last_secondary = later(self.last_secondary);
        }
        if plot.is_primary() {
            self.last_primary = later(self.last_primary);
        }
        if plot.address.is_some() {
            self.last_mode_s = later(self.last_mode_s);
        }
        self.observe_report(plot, t);
    }

    /// Learns the identity of a cooperative report (ADS-B,
    /// multilateration, AIS) at `t` that updated the track: its address
    /// or MMSI, code, callsign, SPI and flight level, as a radar plot's
    /// ([`TrackIdentity::observe`]), but not the times of the last
    /// primary, secondary and Mode S update, which are radar plots' (a
    /// report is none of them: CAT062 I062/290 has its own ages).
    pub fn observe_report(&mut self, plot: &Identity, t: f64) {
        if let Some(m) = plot.mmsi {
            match &mut self.mmsi {
                Some(e) if e.value == m => e.seen(t),
                _ => self.mmsi = Some(Evidence::new(m, t)),
            }
        }
        if let Some(a) = plot.address {
            match &mut self.address {
                Some(e) if e.value == a => e.seen(t),
                // A different address never pairs (ln_ratio), except where
                // evidence was not asked (parallel mode): the newer wins.
                _ => self.address = Some(Evidence::new(a, t)),
            }
        }
        if let Some(c) = plot.mode_3a.filter(|c| c.validated && !c.garbled) {
            self.observe_code(c.code, t);
        }
        if let Some(cs) = plot.callsign {
            match &mut self.callsign {
                Some(e) if e.value == cs => e.seen(t),
                _ => self.callsign = Some(Evidence::new(cs, t)),
            }
        }
        if plot.spi {
            self.spi_t = Some(self.spi_t.map_or(t, |s| s.max(t)));
        }
        if let Some(c) = plot.mode_c.filter(|c| c.validated && !c.garbled) {
            let z = c.flight_level * 100.0;
            let r = altitude_variance(plot);
            match &mut self.altitude {
                None => self.altitude = Some(PressureAltitude::start(z, r, t)),
                Some(alt) if t >= alt.t => alt.update(z, r, t),
                Some(_) => {}
            }
        }
    }

    /// [`TrackIdentity::observe`], and whether the plot's radar gives Mode
    /// S addresses (`mode_s_radar`): its secondary plot without one dates
    /// `last_mode_ac`.
    pub fn observe_from(&mut self, plot: &Identity, t: f64, mode_s_radar: bool) {
        self.observe(plot, t);
        if without_mode_s(plot, mode_s_radar) {
            self.last_mode_ac = Some(self.last_mode_ac.map_or(t, |s| s.max(t)));
        }
    }

    /// [`TrackIdentity::observe_from`] with the radar plot a Cartesian plot
    /// was converted from, when it is one radar's (a fused plot says
    /// nothing); `mode_s`: which radars give Mode S addresses. A
    /// cooperative report teaches its identity only
    /// ([`TrackIdentity::observe_report`]).
    pub(crate) fn observe_measured(&mut self, measured: Option<&super::Plot>, mode_s: &[bool]) {
        match measured {
            Some(m) if m.report.is_some() => self.observe_report(&m.identity, m.t),
            Some(m) => self.observe_from(&m.identity, m.t, is_mode_s(mode_s, m.radar)),
            None => {}
        }
    }

    fn observe_code(&mut self, code: u16, t: f64) {
        match (&mut self.mode_3a, &mut self.pending_3a) {
            (None, _) => self.mode_3a = Some(Evidence::new(code, t)),
            (Some(e), _) if e.value == code => {
                e.seen(t);
                self.pending_3a = None;
            }
            (Some(_), Some(p)) if p.value == code => {
                p.seen(t);
                if p.plots >= CODE_CHANGE_REPLIES {
                    self.mode_3a = self.pending_3a.take();
                }
            }
            (Some(_), _) => self.pending_3a = Some(Evidence::new(code, t)),
        }
    }

    /// Whether two identities can be the same aircraft's: not two
    /// different Mode S addresses.
    pub fn compatible(a: &Identity, b: &Identity) -> bool {
        !matches!((a.address, b.address), (Some(x), Some(y)) if x != y)
    }
}

/// Likelihood ratio of a Mode S radar's secondary plot without an address
/// against a track with one: a Mode S transponder answers a Mode S radar
/// with its address (roll-call or all-call), so such a plot is nearly
/// always a Mode A/C-only aircraft's (1 in 20 allowed for a radar's
/// fallback to Mode A/C).
pub const NO_ADDRESS_FROM_MODE_S: f64 = 0.05;

/// Whether a plot says its aircraft has no Mode S transponder: a secondary
/// plot without an address from a radar that gives addresses
/// (`mode_s_radar`: the tracker has seen an address from it).
pub fn without_mode_s(plot: &Identity, mode_s_radar: bool) -> bool {
    mode_s_radar && plot.address.is_none() && plot.is_secondary()
}

/// Whether radar `i` has given a Mode S address (`mode_s`: per radar).
pub(crate) fn is_mode_s(mode_s: &[bool], i: usize) -> bool {
    mode_s.get(i).copied().unwrap_or(false)
}

/// Variance of a plot's Mode C value (ft²): its quantisation, q²/12.
pub(crate) fn altitude_variance(plot: &Identity) -> f64 {
    let q = plot.altitude_quantum_ft();
    q * q / 12.0
}

/// The largest MMSI: nine digits.
pub const MAX_MMSI: u32 = 999_999_999;

/// Checks a plot's identity fields (the service reports them by name
/// first; this guards the library's own callers).
pub fn validate(identity: &Identity) -> Result<(), AlgoError> {
    if identity.address.is_some_and(|a| a > MAX_ADDRESS) {
        return Err(AlgoError::InvalidParameter {
            what: "address",
            reason: "must fit in 24 bits".to_string(),
        });
    }
    if identity.mmsi.is_some_and(|m| m > MAX_MMSI) {
        return Err(AlgoError::InvalidParameter {
            what: "mmsi",
            reason: "must have at most nine digits".to_string(),
        });
    }
    if identity.mode_3a.is_some_and(|c| c.code > MAX_CODE) {
        return Err(AlgoError::InvalidParameter {
            what: "mode_3a",
            reason: "must be four octal digits".to_string(),
        });
    }
    if let Some(c) = identity.mode_c {
        let (lo, hi) = FLIGHT_LEVEL_RANGE;
        if !(c.flight_level.is_finite() && (lo..=hi).contains(&c.flight_level)) {
            return Err(AlgoError::InvalidParameter {
                what: "flight_level",
                reason: format!("must lie in [{lo}, {hi}]"),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An MMSI is a ship's as an address is an aircraft's: another rules
    /// the pairing out, the same weighs (1 − 10⁻⁴)/10⁻⁴ (ln 9.21).
    #[test]
    fn an_mmsi_pairs_only_with_its_own_ship() {
        let mut track = TrackIdentity::default();
        let ship = |m| Identity {
            mmsi: Some(m),
            ..Identity::default()
        };
        track.observe(&ship(227_006_760), 1.0);
        assert_eq!(track.mmsi.map(|e| e.value), Some(227_006_760));
        assert_eq!(track.ln_ratio(&ship(244_630_000), 2.0, false), None);
        let same = track.ln_ratio(&ship(227_006_760), 2.0, false).unwrap();
        assert!((same - (0.9999f64 / 1e-4).ln()).abs() < 1e-9, "{same}");
        assert!(validate(&ship(MAX_MMSI + 1)).is_err());
    }

    fn reply(address: Option<u32>, code: Option<u16>, fl: Option<f64>) -> Identity {
        Identity {
            address,
            mode_3a: code.map(|code| Mode3A {
                code,
                validated: true,
                garbled: false,
            }),
            mode_c: fl.map(|flight_level| ModeC {
                flight_level,
                validated: true,
                garbled: false,
            }),
            detection: Some(Detection::Combined),
            ..Identity::default()
        }
    }

    #[test]
    fn addresses_decide_and_codes_weigh_by_how_common_they_are() {
        let mut track = TrackIdentity::default();
        track.observe(&reply(Some(0x4CA2D1), Some(0o1234), None), 0.0);
        // A different address: ruled out; the same: ln((1 − 1e-4)/1e-4)
        // = ln 9999 = 9.2102.
        assert_eq!(
            track.ln_ratio(&reply(Some(0x4CA2D2), None, None), 1.0, false),
            None
        );
        let same = track
            .ln_ratio(&reply(Some(0x4CA2D1), None, None), 1.0, false)
            .unwrap();
        assert!((same - 9999f64.ln()).abs() < 1e-12, "{same}");
        // Without an address on the plot, the code: a discrete match is
        // ln(0.98 / 0.001) = ln 980 = 6.8876; a mismatch ln(0.02 / 0.999)
        // = −3.9110; unvalidated, half; garbled, nothing.
        let m = track
            .ln_ratio(&reply(None, Some(0o1234), None), 1.0, false)
            .unwrap();
        assert!((m - 980f64.ln()).abs() < 1e-12, "{m}");
        let x = track
            .ln_ratio(&reply(None, Some(0o4321), None), 1.0, false)
            .unwrap();
        assert!((x - (0.02f64 / 0.999).ln()).abs() < 1e-12, "{x}");
        let mut half = reply(None, Some(0o1234), None);
        half.mode_3a.as_mut().unwrap().validated = false;
        let h = track.ln_ratio(&half, 1.0, false).unwrap();
        assert!((h - 980f64.ln() / 2.0).abs() < 1e-12);
        half.mode_3a.as_mut().unwrap().garbled = true;
        assert_eq!(track.ln_ratio(&half, 1.0, false), Some(0.0));
        // A conspicuity code matches weakly: ln(0.98 / 0.25) = 1.3661.
        let mut vfr = TrackIdentity::default();
        vfr.observe(&reply(None, Some(0o7000), None), 0.0);
        let c = vfr
            .ln_ratio(&reply(None, Some(0o7000), None), 1.0, false)
            .unwrap();
        assert!((c - (0.98f64 / 0.25).ln()).abs() < 1e-12, "{c}");
        // A primary plot says nothing.
        assert_eq!(track.ln_ratio(&Identity::default(), 1.0, false), Some(0.0));
    }

    /// A Mode S radar's secondary plot without an address is a Mode A/C
    /// transponder's: against a track with an address it weighs 0.05
    /// (ln = −3.0), beside the code's own ratio; from a radar that gives
    /// no addresses, or a primary plot, it weighs nothing.
    #[test]
    fn a_mode_s_radars_reply_without_address_is_another_aircraft() {
        let mut track = TrackIdentity::default();
        track.observe(&reply(Some(0x4CA2D1), None, None), 0.0);
        let mode_a = reply(None, Some(0o7000), None);
        let ln = track.ln_ratio(&mode_a, 1.0, true).unwrap();
        assert!((ln - 0.05f64.ln()).abs() < 1e-12, "{ln}");
        assert_eq!(track.ln_ratio(&mode_a, 1.0, false), Some(0.0));
        let primary = Identity::default();
        assert_eq!(track.ln_ratio(&primary, 1.0, true), Some(0.0));
        assert!(without_mode_s(&mode_a, true) && !without_mode_s(&primary, true));
    }

    /// The reverse: a track whose aircraft answered a Mode S radar without
    /// an address (a Mode A/C transponder) weighs a reply with an address
    /// 0.05 (ln = −3.0), beside the code's own ratio (the discrete 0676
    /// against the track's 7000: ln(0.02 / 0.999)); the same reply from a radar that gives no
    /// addresses teaches nothing of the kind.
    #[test]
    fn a_mode_a_c_aircraft_is_not_the_one_that_gives_an_address() {
        let mode_a = reply(None, Some(0o7000), None);
        let mode_s = reply(Some(0x394A0A), Some(0o0676), None);
        let mut ssr_only = TrackIdentity::default();
        ssr_only.observe_from(&mode_a, 0.0, false);
        assert_eq!(ssr_only.last_mode_ac, None);
        let code = (0.02f64 / 0.999).ln();
        let ln = ssr_only.ln_ratio(&mode_s, 1.0, true).unwrap();
        assert!((ln - code).abs() < 1e-12, "{ln}");
        let mut mode_ac = TrackIdentity::default();
        mode_ac.observe_from(&mode_a, 0.0, true);
        assert_eq!(mode_ac.last_mode_ac, Some(0.0));
        let ln = mode_ac.ln_ratio(&mode_s, 1.0, true).unwrap();
        assert!((ln - (code + 0.05f64.ln())).abs() < 1e-12, "{ln}");
        // Its own replies and primary plots are unaffected.
        let own = mode_ac.ln_ratio(&mode_a, 1.0, true).unwrap();
        assert!((own - (0.98f64 / 0.25).ln()).abs() < 1e-12, "{own}");
        assert_eq!(mode_ac.ln_ratio(&Identity::default(), 1.0, true), Some(0.0));
    }

    #[test]
    fn a_plain_plot_dates_the_last_primary_update_of_a_secondary_track_only() {
        let mut t = TrackIdentity::default();
        t.observe(&Identity::default(), 1.0);
        assert!(t.is_empty());
        let mut ssr = reply(Some(1), Some(0o1234), None);
        ssr.detection = Some(Detection::Secondary);
        t.observe(&ssr, 2.0);
        assert_eq!((t.last_secondary, t.last_primary), (Some(2.0), None));
        t.observe(&Identity::default(), 3.0);
        assert_eq!(t.last_primary, Some(3.0));
    }

    #[test]
    fn a_report_teaches_its_identity_but_dates_no_radar_update() {
        // An ADS-B report: address, code and flight level, no detection.
        let mut adsb = reply(Some(0x4CA2D1), Some(0o1234), Some(350.0));
        adsb.detection = None;
        let mut t = TrackIdentity::default();
        t.observe_report(&adsb, 5.0);
        assert_eq!(
            t.address.map(|a| (a.value, a.last_t)),
            Some((0x4CA2D1, 5.0))
        );
        assert_eq!(t.mode_3a.map(|c| c.value), Some(0o1234));
        assert!(t.altitude.is_some());
        let radar_times = |t: &TrackIdentity| (t.last_primary, t.last_secondary, t.last_mode_s);
        assert_eq!(radar_times(&t), (None, None, None));
        // An AIS report (no identity) on that track is no primary plot.
        t.observe_report(&Identity::default(), 6.0);
        assert_eq!(radar_times(&t), (None, None, None));
        // The radar's combined Mode S plot dates all three; a later
        // report moves none of them, only the address's evidence.
        t.observe(&reply(Some(0x4CA2D1), None, None), 7.0);
        assert_eq!(radar_times(&t), (Some(7.0), Some(7.0), Some(7.0)));
        t.observe_report(&adsb, 8.0);
        assert_eq!(radar_times(&t), (Some(7.0), Some(7.0), Some(7.0)));
        assert_eq!(t.address.map(|a| (a.plots, a.last_t)), Some((3, 8.0)));
    }

    #[test]
    fn a_code_change_needs_two_agreeing_replies_and_a_garbled_one_changes_nothing() {
        let mut t = TrackIdentity::default();
        t.observe(&reply(None, Some(0o1234), None), 0.0);
        let mut garbled = reply(None, Some(0o7777), None);
        garbled.mode_3a.as_mut().unwrap().garbled = true;
        t.observe(&garbled, 1.0);
        assert_eq!(t.mode_3a.unwrap().value, 0o1234);
        assert!(t.pending_3a.is_none());
        t.observe(&reply(None, Some(0o5501), None), 2.0);
        assert_eq!(t.mode_3a.unwrap().value, 0o1234);
        assert_eq!(t.pending_3a.unwrap().value, 0o5501);
        // The pending code counts as a match meanwhile (no new aircraft).
        assert!(
            t.ln_ratio(&reply(None, Some(0o5501), None), 3.0, false)
                .unwrap()
                > 6.0
        );
        t.observe(&reply(None, Some(0o5501), None), 3.0);
        let code = t.mode_3a.unwrap();
        assert_eq!((code.value, code.plots, code.first_t), (0o5501, 2, 2.0));
        assert!(t.pending_3a.is_none());
        t.observe(&reply(None, Some(0o7700), None), 4.0);
        t.observe(&reply(None, Some(0o7700), None), 5.0);
        assert_eq!(t.emergency(), Some(Emergency::General));
    }

    #[test]
    fn the_pressure_altitude_follows_a_climb_and_tells_levels_apart() {
        // A climb of 1,500 ft/min (25 ft/s) from FL 100, Mode S replies
        // every 2 s quantised to 25 ft.
        let mut t = TrackIdentity::default();
        for k in 0..60 {
            let time = 2.0 * k as f64;
            let feet = 10_000.0 + 25.0 * time;
            let fl = (feet / 25.0).round() * 25.0 / 100.0;
            t.observe(&reply(Some(1), None, Some(fl)), time);
        }
        let alt = t.altitude.unwrap();
        let truth = 10_000.0 + 25.0 * 118.0;
        assert!((alt.x[0] - truth).abs() < 25.0, "{:?}", alt.x);
        assert!((alt.x[1] - 25.0).abs() < 2.0, "{:?}", alt.x);
        // A reply 1,000 ft away is evidence against (ln(0.05) = −3.0);
        // one at the predicted level for (the density at the peak
        // times the 60,000-ft span, well above 1).
        let at = |fl: f64| {
            t.ln_ratio(&reply(None, None, Some(fl)), 120.0, false)
                .unwrap()
        };
        let level = (truth + 50.0) / 100.0;
        assert!(at(level) > 4.0, "{}", at(level));
        assert!(
            (at(level + 10.0) - 0.05f64.ln()).abs() < 0.01,
            "{}",
            at(level + 10.0)
        );
        // A single wild reply is not used; three in a row restart the
        // filter there.
        for k in 0..3 {
            t.observe(&reply(Some(1), None, Some(400.0)), 122.0 + k as f64);
            assert_eq!(t.altitude.unwrap().x[0] == 40_000.0, k == 2);
        }
    }
}
