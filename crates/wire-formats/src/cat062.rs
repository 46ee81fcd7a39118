//! EUROCONTROL ASTERIX CAT062 output: SDPS system track messages encoded
//! from the service's tracks (a pure encoder: bytes in memory, no I/O).
//!
//! Edition: CAT062 **1.20** (2023-02-13), as the machine-readable
//! definition of `zoranbosnjak/asterix-specs` (`specs/cat062/cat-1.20.ast`)
//! gives it. libasterix decodes editions 1.16 to 1.21; the UAP and every
//! item written here are the same in all of them, but for I062/340
//! HEIGHT, unsigned before 1.19 (a receiver of 1.16–1.18 reads a negative
//! measured height as a large positive one). Checked against libasterix's
//! decoder: `checks/cat062_oracle.sh`, the fixtures under
//! `tests/fixtures/cat062/`.
//!
//! A data block is `CAT = 62 | LEN (2 bytes, big-endian, the whole block)
//! | records`. [`encode_records`] fills blocks of at most `max_block` bytes
//! (at most 65,535, LEN's range), split at record boundaries; a record
//! that does not fit in an empty block (`max_block` below 3 + its size)
//! is still emitted, alone in its block, which is then larger than
//! `max_block`. An empty track list gives no block.
//!
//! A record is an FSPEC (octets whose bit 1, FX, says another follows;
//! bit 8 of the first octet is FRN 1, bit 2 FRN 7, bit 8 of the second
//! FRN 8, …; only the octets up to the last item present are written)
//! and then the items in FRN order. The 1.20 UAP: FRN 1 I062/010, 2
//! spare, 3 /015, 4 /070, 5 /105, 6 /100, 7 /185, 8 /210, 9 /060, 10
//! /245, 11 /380, 12 /040, 13 /080, 14 /290, 15 /200, 16 /295, 17 /136,
//! 18 /130, 19 /135, 20 /220, 21 /390, 22 /270, 23 /300, 24 /110, 25
//! /120, 26 /510, 27 /500, 28 /340, 29–33 spare, 34 RE, 35 SP.
//!
//! Items written (inputs in SI; 1 ft = 0.3048 m, 1 NM = 1852 m exactly):
//! - I062/010 SAC/SIC and I062/015 service identification, from
//!   [`Cat062Config`];
//! - I062/070 time of track information, 1/128 s, 3 bytes;
//! - I062/105 WGS-84 latitude/longitude, 180/2²⁵ °, 4 + 4 bytes signed,
//!   latitude in [-90°, 90°], longitude in [-180°, 180°);
//! - I062/100 Cartesian x/y, 0.5 m, 3 + 3 bytes signed;
//! - I062/185 velocity vx/vy, 0.25 m/s, 2 + 2 bytes signed;
//! - I062/040 track number, 16 bits, as given (every `u16` is valid: the
//!   item has no range narrower than its 16 bits, so nothing wraps);
//! - I062/080 track status, extensible (see [`TrackStatusFlags`]): MON,
//!   SPI, MRH, SRC, CNF; SIM, TSE, TSB, AFF; CST, PSR, SSR, MDS, ADS;
//! - I062/290 system track update ages (compound: TRK, PSR, SSR, MDS, ES,
//!   MLT; see [`UpdateAges`]);
//! - I062/060 track Mode 3/A code (V, G, CH, the code);
//! - I062/245 target identification (STI 0, downlinked, and 8 ICAO 6-bit
//!   characters). The 1.20 remark asks that it not be used beside I062/380
//!   ID; both are written with the same characters, for receivers that
//!   read one or the other;
//! - I062/380 aircraft derived data: ADR (Mode S address) and ID;
//! - I062/136 measured flight level, 1/4 FL signed, in [-15, 1,500] FL;
//! - I062/130 calculated track **geometric** altitude, 6.25 ft signed, in
//!   [-1,500 ft, 150,000 ft]: the height above the WGS-84 ellipsoid. The
//!   calculated barometric altitude (I062/135) is not written;
//! - I062/220 rate of climb/descent, 6.25 ft/min signed (the service
//!   gives the pressure altitude's rate when it has one, else the
//!   geometric);
//! - I062/500 estimated accuracies (compound: APC, COV, APW, AGA, ATV, AA,
//!   ARC; not ABA, barometric);
//! - I062/340 measured information (compound: SID, POS, HEIGHT).
//!
//! Quantisation: every value is divided by its LSB (in the input's unit)
//! and rounded to the nearest integer, ties away from zero, the same for
//! negatives (-2468.5 LSB → -2469); signed values are written in two's
//! complement. The range check is on the rounded integer, against the
//! item's bits and the range the specification states.
//!
//! Out of range: a value that is not finite, or whose rounded integer is
//! outside the item's range, leaves that item (for a compound item: that
//! subfield) out of the record, and a [`Skip`] in [`Encoded::skipped`]
//! says which track, which item, the value and the range. Nothing is
//! wrapped or clamped silently. Three exceptions, each the
//! specification's own rule for its quantity:
//! - I062/070 is the time since the last midnight and "is reset to zero
//!   at every midnight": a finite time is taken modulo 86,400 s
//!   (86,400.5 s is written as 0.5 s, -1 s as 86,399 s), also after
//!   rounding (86,399.999 s → 0).
//! - I062/340 THETA is an azimuth in [0°, 360°): it is taken modulo 360°
//!   (-90° is 270°).
//! - I062/290 ages and I062/500 accuracies: "maximum value means maximum
//!   value or above", so a value above the maximum is written as the
//!   maximum and reported in [`Encoded::saturated`] (a negative one is
//!   left out, as usual; COV, signed, saturates in magnitude at
//!   ±16,383.5 m).
//!
//! Records: I062/010, /040, /070 and /080 are always written and a record
//! needs a position (I062/100 or /105). A record whose time is not finite
//! or which has neither position is not written at all: its [`Skip`]s
//! have `record_dropped` set. Nothing in this module panics, whatever the
//! input (checked by a property test).

use crate::asterix::{FT_M, NM_M};

/// The category written.
pub const CAT_SYSTEM_TRACKS: u8 = 62;

/// A usual data block size limit, in bytes (fits a UDP datagram on any
/// Ethernet path).
pub const DEFAULT_MAX_BLOCK: usize = 1024;

/// The largest data block LEN can describe.
pub const MAX_BLOCK_LEN: usize = 65_535;

/// Seconds in a UTC day as Unix time counts them (no leap seconds).
pub const SECONDS_PER_DAY: f64 = 86_400.0;

/// The sending system: I062/010 and I062/015.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Cat062Config {
    /// I062/010 System Area Code.
    pub sac: u8,
    /// I062/010 System Identification Code.
    pub sic: u8,
    /// I062/015 Service Identification; the item is left out when `None`.
    pub service_id: Option<u8>,
}

/// I062/080 SRC: the source of the calculated track altitude of I062/130.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum AltitudeSource {
    /// 0: no source.
    #[default]
    NoSource = 0,
    /// 1: GNSS.
    Gnss = 1,
    /// 2: 3D radar.
    Radar3d = 2,
    /// 3: triangulation.
    Triangulation = 3,
    /// 4: height from coverage.
    HeightFromCoverage = 4,
    /// 5: speed look-up table.
    SpeedLookUpTable = 5,
    /// 6: default height.
    DefaultHeight = 6,
    /// 7: multilateration.
    Multilateration = 7,
}

/// I062/080 track status, the bits the service can know. All `false` is
/// a confirmed multisensor track, actual, neither first nor last message,
/// not coasting.
///
/// Octets written: the first always (MON, SPI, MRH, SRC, CNF); the first
/// extension (SIM, TSE, TSB, AFF; FPC, STP, KOS written 0) when one of
/// its flags is set; the third extension (CST, PSR, SSR, MDS, ADS; SUC,
/// AAC written 0) when one of its flags is set, with the second
/// extension then written as zeros (AMA 0, MD4/MD5 "no interrogation",
/// ME 0, MI 0) to reach it by FX.
///
/// Later extensions are never written. The fourth (SDS, EMS, PFT, FPLT)
/// has no value for "not known" in SDS and EMS (0 says "combined" and
/// "no emergency"), so the fifth, whose MLAT bit (1.20; spare in
/// 1.18–1.19) says the last multilateration update is aged, cannot be
/// reached without claiming them: an aged MLAT update is not flagged
/// (I062/290 MLT carries its age). Edition 1.20 has no bit for a track
/// held by ADS-B alone (unvalidated).
///
/// MRH and SRC are not set by the caller: MRH is 1 (geometric altitude
/// more reliable) exactly when I062/130 is written, as the specification
/// asks of a system that sends a calculated altitude in I062/130 only,
/// and SRC is [`TrackStatusFlags::altitude_source`] then, 0 (no source)
/// otherwise.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackStatusFlags {
    /// MON: a monosensor track (`false`: multisensor).
    pub monosensor: bool,
    /// SPI present in the last report of a sensor that can decode it.
    pub spi: bool,
    /// SRC, written when I062/130 is written.
    pub altitude_source: AltitudeSource,
    /// CNF: tentative track (`false`: confirmed).
    pub tentative: bool,
    /// SIM: simulated track.
    pub simulated: bool,
    /// TSE: the last message transmitted to the user for the track
    /// (track service end).
    pub last_message: bool,
    /// TSB: the first message transmitted to the user for the track.
    pub first_message: bool,
    /// AFF: "ADS-B data inconsistent with other surveillance
    /// information" (first extension, bit 4).
    pub adsb_inconsistent: bool,
    /// CST: the age of the last track update is above the system's
    /// threshold (coasting).
    pub coasting: bool,
    /// PSR: the age of the last PSR update is above the threshold.
    pub psr_aged: bool,
    /// SSR: the age of the last SSR update is above the threshold.
    pub ssr_aged: bool,
    /// MDS: the age of the last Mode S update is above the threshold.
    pub mode_s_aged: bool,
    /// ADS: the age of the last ADS-B update is above the threshold
    /// (third extension, bit 4).
    pub adsb_aged: bool,
}

/// I062/290 system track update ages, seconds (each written subfield one
/// octet, LSB 1/4 s, 0 to 63.75 s; above is written as 63.75 s). `None`:
/// the subfield is not sent (the specification: "if the data has never
/// been received, the corresponding subfield is not sent"). The item is
/// left out when no subfield is written.
///
/// The 1.20 subfields, in order: 1 TRK, 2 PSR, 3 SSR, 4 MDS, 5 ADS (ADS-C,
/// two octets), 6 ES, 7 VDL, then in the primary subfield's second octet
/// 8 UAT, 9 LOP, 10 MLT. Written: TRK, PSR, SSR, MDS, ES and MLT; ADS-C,
/// VDL Mode 4, UAT and loop ages never are.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UpdateAges {
    /// TRK: the track's age since it began.
    pub track: Option<f64>,
    /// PSR: age of the last primary detection used to update the track
    /// (counted from I062/070).
    pub psr: Option<f64>,
    /// SSR: age of the last secondary detection used to update the track.
    pub ssr: Option<f64>,
    /// MDS: age of the last Mode S detection used to update the track.
    pub mode_s: Option<f64>,
    /// ES: age of the last 1090 MHz Extended Squitter ADS-B report used to
    /// update the track (subfield 6).
    pub adsb_es: Option<f64>,
    /// MLT: age of the last multilateration detection (subfield 10).
    pub mlat: Option<f64>,
}

/// I062/500 estimated accuracies (standard deviations), each subfield
/// written when `Some`; a value above a subfield's maximum is written as
/// the maximum ("maximum value or above"). The item is left out when no
/// subfield is written.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Accuracy {
    /// APC: std dev of x and y (m; LSB 0.5 m, up to 32,767.5 m).
    pub xy: Option<(f64, f64)>,
    /// COV: the x-y covariance Cov(X, Y) in m², written as the
    /// specification's "XY covariance component" sign(Cov) · √|Cov| (m;
    /// LSB 0.5 m, signed 16 bits; the magnitude saturates at 16,383.5 m).
    pub xy_covariance_m2: Option<f64>,
    /// APW: std dev of latitude and longitude (degrees; LSB 180/2²⁵ °, up
    /// to 65,535 LSB ≈ 0.35°).
    pub wgs84: Option<(f64, f64)>,
    /// AGA: std dev of the geometric altitude of I062/130 (m; LSB
    /// 6.25 ft, up to 1,593.75 ft).
    pub geometric_altitude: Option<f64>,
    /// ATV: std dev of vx and vy (m/s; LSB 0.25 m/s, up to 63.75 m/s).
    pub velocity: Option<(f64, f64)>,
    /// AA: std dev of ax and ay (m/s²; LSB 0.25 m/s², up to 63.75).
    pub acceleration: Option<(f64, f64)>,
    /// ARC: std dev of the rate of climb/descent (m/s; LSB 6.25 ft/min,
    /// up to 1,593.75 ft/min).
    pub vertical_rate: Option<f64>,
}

/// I062/340 measured information: the last sensor report used to update
/// the track. Each subfield written when `Some`; the item is left out when
/// no subfield is written. MDC, MDA and TYP are not written.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LastMeasurement {
    /// SID: the sensor's (SAC, SIC).
    pub sensor: Option<(u8, u8)>,
    /// POS: measured (range m, azimuth degrees clockwise from north).
    /// RHO: LSB 1/256 NM, 0 to 65,535 LSB (≈ 256 NM); THETA: LSB
    /// 360/2¹⁶ °, taken modulo 360°.
    pub polar: Option<(f64, f64)>,
    /// HEIGHT: measured 3-D height (m; LSB 25 ft, signed 16 bits), at the
    /// reference level of the sensor.
    pub height: Option<f64>,
}

/// One system track, as one CAT062 record. Units are SI.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SystemTrack {
    /// I062/040, the track's stable number (16 bits, written as given).
    pub track_number: u16,
    /// I062/070: seconds since midnight UTC of the track state (see
    /// [`time_of_day`]); taken modulo 86,400 s.
    pub time_of_day: f64,
    /// I062/105 (latitude, longitude), degrees, WGS-84; left out when
    /// `None`.
    pub wgs84: Option<(f64, f64)>,
    /// I062/100 (x, y), metres in the system's reference frame (x east,
    /// y north).
    pub xy: (f64, f64),
    /// I062/185 (vx, vy), m/s.
    pub velocity: (f64, f64),
    /// I062/080.
    pub status: TrackStatusFlags,
    /// I062/290.
    pub ages: UpdateAges,
    /// I062/500; left out when `None`.
    pub accuracy: Option<Accuracy>,
    /// I062/130: height above the WGS-84 ellipsoid, metres (not a
    /// barometric altitude); left out when `None`.
    pub height: Option<f64>,
    /// I062/220: rate of climb (positive) or descent, m/s; left out when
    /// `None`.
    pub vertical_rate: Option<f64>,
    /// I062/340; left out when `None`.
    pub last_measurement: Option<LastMeasurement>,
    /// I062/060; left out when `None`.
    pub mode_3a: Option<TrackMode3A>,
    /// I062/245 (STI 0: downlinked from the target) and I062/380 ID: the
    /// aircraft identification, up to 8 characters of the ICAO 6-bit set
    /// (A–Z, 0–9, space), space-padded; left out when `None` or when a
    /// character is outside the set.
    pub callsign: Option<[u8; 8]>,
    /// I062/380 ADR: the Mode S address (24 bits); left out when `None`.
    pub address: Option<u32>,
    /// I062/136: the last valid flight level used to update the track
    /// (FL; LSB 1/4 FL, −15 to 1,500 FL); left out when `None`.
    pub measured_flight_level: Option<f64>,
}

/// I062/060 track Mode 3/A code.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackMode3A {
    /// The code, 12 bits (four octal digits: `0o7000`).
    pub code: u16,
    /// V = 0: validated.
    pub validated: bool,
    /// G = 1: garbled.
    pub garbled: bool,
    /// CH = 1: the code has changed.
    pub changed: bool,
}

/// A value the encoder did not write as given: out of range or not finite
/// (in [`Encoded::skipped`]: the item or subfield left out), or above a
/// maximum that stands for "or above" (in [`Encoded::saturated`]: written
/// as the maximum).
#[derive(Debug, Clone, PartialEq)]
pub struct Skip {
    /// Index of the track in the slice given to [`encode_records`].
    pub track_index: usize,
    /// The item and field, e.g. `"I062/100 X"`, `"I062/500 APC X"`.
    pub item: &'static str,
    /// The value as given, in the input's unit.
    pub value: f64,
    /// The smallest value the item can carry (in the input's unit).
    pub min: f64,
    /// The largest value the item can carry (in the input's unit).
    pub max: f64,
    /// The input's unit.
    pub unit: &'static str,
    /// What and why, in words.
    pub reason: String,
    /// The whole record was not written (its time was not finite or it
    /// had no position left); set on every skip of that record.
    pub record_dropped: bool,
}

/// The result of [`encode_records`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Encoded {
    /// Data blocks, each `62 | LEN | records`, in the order of the tracks.
    pub blocks: Vec<Vec<u8>>,
    /// Items (or subfields) left out, and records not written.
    pub skipped: Vec<Skip>,
    /// Values written as the maximum of their subfield (for I062/500 COV,
    /// a negative one as the minimum).
    pub saturated: Vec<Skip>,
}

/// Seconds since midnight UTC of a Unix time (seconds since 1970-01-01
/// 00:00 UTC; Unix days are 86,400 s, so this is the UTC time of day).
/// Negative times count back from midnight; not finite gives NaN.
pub fn time_of_day(unix_seconds: f64) -> f64 {
    unix_seconds.rem_euclid(SECONDS_PER_DAY)
}

/// Encodes one record a track into data blocks of at most `max_block`
/// bytes (capped at [`MAX_BLOCK_LEN`]; a record too big for an empty block
/// is emitted alone). Never panics.
pub fn encode_records(cfg: &Cat062Config, tracks: &[SystemTrack], max_block: usize) -> Encoded {
    let limit = max_block.min(MAX_BLOCK_LEN);
    let mut out = Encoded::default();
    let mut block: Vec<u8> = Vec::new();
    let mut rec: Vec<u8> = Vec::with_capacity(128);
    for (index, track) in tracks.iter().enumerate() {
        rec.clear();
        let mut notes = Notes {
            index,
            first_skip: out.skipped.len(),
            skipped: &mut out.skipped,
            saturated: &mut out.saturated,
        };
        if !encode_record(cfg, track, &mut notes, &mut rec) {
            continue;
        }
        if !block.is_empty() && block.len() + rec.len() > limit {
            finish_block(&mut block, &mut out.blocks);
        }
        if block.is_empty() {
            block.reserve(limit.clamp(3 + rec.len(), 4096));
            block.extend_from_slice(&[CAT_SYSTEM_TRACKS, 0, 0]);
        }
        block.extend_from_slice(&rec);
    }
    finish_block(&mut block, &mut out.blocks);
    out
}

/// Writes LEN and moves the block out. A block is at most 65,535 bytes
/// or one record (under 100 bytes) and its header, so LEN always fits.
fn finish_block(block: &mut Vec<u8>, blocks: &mut Vec<Vec<u8>>) {
    if block.len() < 3 {
        return;
    }
    let len = u16::try_from(block.len()).unwrap_or(u16::MAX);
    block[1..3].copy_from_slice(&len.to_be_bytes());
    blocks.push(std::mem::take(block));
}

/// Where the skips of one record go.
struct Notes<'a> {
    index: usize,
    /// `skipped.len()` when the record began (to mark a dropped record).
    first_skip: usize,
    skipped: &'a mut Vec<Skip>,
    saturated: &'a mut Vec<Skip>,
}

impl Notes<'_> {
    fn skip(&mut self, q: &Quantity, value: f64, why: &str) {
        let (min, max) = q.range();
        self.skipped.push(Skip {
            track_index: self.index,
            item: q.item,
            value,
            min,
            max,
            unit: q.unit,
            reason: format!(
                "{}: {value} {} {why} (LSB {} {}, range {min}..={max} {}): left out",
                q.item, q.unit, q.lsb, q.unit, q.unit
            ),
            record_dropped: false,
        });
    }

    fn saturate(&mut self, q: &Quantity, value: f64) {
        let (min, max) = q.range();
        let bound = if value < 0.0 { min } else { max };
        self.saturated.push(Skip {
            track_index: self.index,
            item: q.item,
            value,
            min,
            max,
            unit: q.unit,
            reason: format!(
                "{}: {value} {} is beyond {bound} {}: written as {bound} {} \
                 (\"maximum value means maximum value or above\")",
                q.item, q.unit, q.unit, q.unit
            ),
            record_dropped: false,
        });
    }

    /// The record is not written: marks its skips, adding `why` if none.
    fn drop_record(&mut self, q: &Quantity, value: f64, why: &str) {
        if self.skipped.len() == self.first_skip {
            self.skip(q, value, why);
        }
        for s in &mut self.skipped[self.first_skip..] {
            s.record_dropped = true;
            s.reason.push_str("; record not written");
        }
    }
}

/// What a value above the range becomes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Above {
    /// Left out (a skip).
    Omit,
    /// Written as the maximum (the specification's "or above").
    Saturate,
    /// Signed, the magnitude saturates: above the maximum is written as
    /// the maximum, below the minimum (= -maximum) as the minimum.
    SaturateMagnitude,
}

/// A quantity of the wire: its LSB in the input's unit and its range in
/// LSBs.
#[derive(Debug, Clone, Copy)]
struct Quantity {
    item: &'static str,
    unit: &'static str,
    lsb: f64,
    min: i64,
    max: i64,
    above: Above,
}

impl Quantity {
    const fn new(item: &'static str, unit: &'static str, lsb: f64, min: i64, max: i64) -> Self {
        Self {
            item,
            unit,
            lsb,
            min,
            max,
            above: Above::Omit,
        }
    }

    const fn saturating(self) -> Self {
        Self {
            above: Above::Saturate,
            ..self
        }
    }

    const fn saturating_magnitude(self) -> Self {
        Self {
            above: Above::SaturateMagnitude,
            ..self
        }
    }

    fn range(&self) -> (f64, f64) {
        (self.min as f64 * self.lsb, self.max as f64 * self.lsb)
    }

    /// The value in LSBs, rounded to nearest (ties away from zero), or
    /// `None` (and a skip) when it is not finite or out of range.
    fn quantise(&self, value: f64, notes: &mut Notes<'_>) -> Option<i64> {
        if !value.is_finite() {
            notes.skip(self, value, "is not a finite number");
            return None;
        }
        let r = (value / self.lsb).round();
        if r < self.min as f64 {
            if self.above == Above::SaturateMagnitude {
                notes.saturate(self, value);
                return Some(self.min);
            }
            notes.skip(self, value, "is below the range after rounding");
            return None;
        }
        if r > self.max as f64 {
            if self.above != Above::Omit {
                notes.saturate(self, value);
                return Some(self.max);
            }
            notes.skip(self, value, "is above the range after rounding");
            return None;
        }
        // In range, so the cast is exact.
        Some(r as i64)
    }
}

const M_PER_FT: f64 = FT_M;
/// 6.25 ft in metres.
const LSB_6_25_FT: f64 = 6.25 * M_PER_FT;
/// 6.25 ft/min in m/s.
const LSB_6_25_FT_MIN: f64 = 6.25 * M_PER_FT / 60.0;
/// 180/2²⁵ degrees.
const LSB_WGS84: f64 = 180.0 / 33_554_432.0;

const I24_MIN: i64 = -(1 << 23);
const I24_MAX: i64 = (1 << 23) - 1;
const I16_MIN: i64 = i16::MIN as i64;
const I16_MAX: i64 = i16::MAX as i64;
const U16_MAX: i64 = u16::MAX as i64;
const U8_MAX: i64 = u8::MAX as i64;

const TIME: Quantity = Quantity::new("I062/070", "s", 1.0 / 128.0, 0, 86_400 * 128 - 1);
/// ±90° = ±2²⁴ LSB.
const LAT: Quantity = Quantity::new("I062/105 LAT", "°", LSB_WGS84, -(1 << 24), 1 << 24);
/// [-180°, 180°) = [-2²⁵, 2²⁵ - 1] LSB.
const LON: Quantity = Quantity::new("I062/105 LON", "°", LSB_WGS84, -(1 << 25), (1 << 25) - 1);
const X: Quantity = Quantity::new("I062/100 X", "m", 0.5, I24_MIN, I24_MAX);
const Y: Quantity = Quantity::new("I062/100 Y", "m", 0.5, I24_MIN, I24_MAX);
const VX: Quantity = Quantity::new("I062/185 VX", "m/s", 0.25, I16_MIN, I16_MAX);
const VY: Quantity = Quantity::new("I062/185 VY", "m/s", 0.25, I16_MIN, I16_MAX);
/// -1,500 ft = -240 LSB, 150,000 ft = 24,000 LSB.
const HEIGHT: Quantity = Quantity::new("I062/130", "m", LSB_6_25_FT, -240, 24_000);
const MFL: Quantity = Quantity::new("I062/136", "FL", 0.25, -60, 6_000);
const ROCD: Quantity = Quantity::new("I062/220", "m/s", LSB_6_25_FT_MIN, I16_MIN, I16_MAX);

const AGE_TRK: Quantity = Quantity::new("I062/290 TRK", "s", 0.25, 0, U8_MAX).saturating();
const AGE_PSR: Quantity = Quantity::new("I062/290 PSR", "s", 0.25, 0, U8_MAX).saturating();
const AGE_SSR: Quantity = Quantity::new("I062/290 SSR", "s", 0.25, 0, U8_MAX).saturating();
const AGE_MDS: Quantity = Quantity::new("I062/290 MDS", "s", 0.25, 0, U8_MAX).saturating();
const AGE_ES: Quantity = Quantity::new("I062/290 ES", "s", 0.25, 0, U8_MAX).saturating();
const AGE_MLT: Quantity = Quantity::new("I062/290 MLT", "s", 0.25, 0, U8_MAX).saturating();

const APC_X: Quantity = Quantity::new("I062/500 APC X", "m", 0.5, 0, U16_MAX).saturating();
const APC_Y: Quantity = Quantity::new("I062/500 APC Y", "m", 0.5, 0, U16_MAX).saturating();
/// The covariance component sign(Cov)·√|Cov| in metres; its magnitude
/// saturates at 32,767 LSB = 16,383.5 m (the specification: "the maximum
/// value for the (unsigned) XY covariance component is 16.383 km").
const COV: Quantity =
    Quantity::new("I062/500 COV", "m", 0.5, -I16_MAX, I16_MAX).saturating_magnitude();
const APW_LAT: Quantity =
    Quantity::new("I062/500 APW LAT", "°", LSB_WGS84, 0, U16_MAX).saturating();
const APW_LON: Quantity =
    Quantity::new("I062/500 APW LON", "°", LSB_WGS84, 0, U16_MAX).saturating();
const AGA: Quantity = Quantity::new("I062/500 AGA", "m", LSB_6_25_FT, 0, U8_MAX).saturating();
const ATV_X: Quantity = Quantity::new("I062/500 ATV X", "m/s", 0.25, 0, U8_MAX).saturating();
const ATV_Y: Quantity = Quantity::new("I062/500 ATV Y", "m/s", 0.25, 0, U8_MAX).saturating();
const AA_X: Quantity = Quantity::new("I062/500 AA X", "m/s²", 0.25, 0, U8_MAX).saturating();
const AA_Y: Quantity = Quantity::new("I062/500 AA Y", "m/s²", 0.25, 0, U8_MAX).saturating();
const ARC: Quantity = Quantity::new("I062/500 ARC", "m/s", LSB_6_25_FT_MIN, 0, U8_MAX).saturating();

const RHO: Quantity = Quantity::new("I062/340 POS RHO", "m", NM_M / 256.0, 0, U16_MAX);
const THETA: Quantity = Quantity::new("I062/340 POS THETA", "°", 360.0 / 65_536.0, 0, U16_MAX);
const HEIGHT_3D: Quantity =
    Quantity::new("I062/340 HEIGHT", "m", 25.0 * M_PER_FT, I16_MIN, I16_MAX);

/// FRNs of the items written (UAP of edition 1.20).
mod frn {
    pub(super) const I010: u32 = 1;
    pub(super) const I015: u32 = 3;
    pub(super) const I070: u32 = 4;
    pub(super) const I105: u32 = 5;
    pub(super) const I100: u32 = 6;
    pub(super) const I185: u32 = 7;
    pub(super) const I040: u32 = 12;
    pub(super) const I080: u32 = 13;
    pub(super) const I060: u32 = 9;
    pub(super) const I245: u32 = 10;
    pub(super) const I380: u32 = 11;
    pub(super) const I136: u32 = 17;
    pub(super) const I290: u32 = 14;
    pub(super) const I130: u32 = 18;
    pub(super) const I220: u32 = 20;
    pub(super) const I500: u32 = 27;
    pub(super) const I340: u32 = 28;
}

/// A record being built: the FSPEC bits (bit `frn - 1`) and the items.
struct RecordBuf {
    fspec: u32,
    items: [u8; 128],
    len: usize,
}

impl RecordBuf {
    fn new() -> Self {
        Self {
            fspec: 0,
            items: [0; 128],
            len: 0,
        }
    }

    fn put(&mut self, bytes: &[u8]) {
        // Items are added in a bounded number (under 100 bytes in all).
        if let Some(dst) = self.items.get_mut(self.len..self.len + bytes.len()) {
            dst.copy_from_slice(bytes);
            self.len += bytes.len();
        }
    }

    fn item(&mut self, frn: u32, bytes: &[u8]) {
        self.fspec |= 1 << (frn - 1);
        self.put(bytes);
    }

    /// FSPEC then items into `out`.
    fn write(&self, out: &mut Vec<u8>) {
        let (head, n) = fspec(self.fspec);
        out.extend_from_slice(&head[..n]);
        out.extend_from_slice(&self.items[..self.len]);
    }
}

/// An FSPEC (or a compound item's primary subfield) from flag bits (bit
/// `i` is the `i + 1`th flag): 7 flags an octet, FX on all but the last
/// octet, only up to the octet of the last flag set (one octet at least).
/// Returns the octets and how many are used.
fn fspec(flags: u32) -> ([u8; 5], usize) {
    let octets = ((32 - flags.leading_zeros()) as usize).div_ceil(7).max(1);
    let mut out = [0u8; 5];
    for (k, o) in out.iter_mut().enumerate().take(octets) {
        for bit in 0..7 {
            if flags & (1 << (7 * k + bit)) != 0 {
                *o |= 0x80 >> bit;
            }
        }
        if k + 1 < octets {
            *o |= 1;
        }
    }
    (out, octets)
}

/// A compound item being built: its subfield flags and their bytes.
struct CompoundBuf {
    flags: u32,
    data: [u8; 32],
    len: usize,
}

impl CompoundBuf {
    fn new() -> Self {
        Self {
            flags: 0,
            data: [0; 32],
            len: 0,
        }
    }

    /// Subfield number `n` (1-based, in the item's order) with its bytes.
    fn sub(&mut self, n: u32, bytes: &[u8]) {
        if let Some(dst) = self.data.get_mut(self.len..self.len + bytes.len()) {
            dst.copy_from_slice(bytes);
            self.len += bytes.len();
            self.flags |= 1 << (n - 1);
        }
    }

    /// Adds the item to the record when a subfield is present.
    fn finish(&self, frn: u32, rec: &mut RecordBuf) {
        if self.flags == 0 {
            return;
        }
        let (head, n) = fspec(self.flags);
        rec.item(frn, &head[..n]);
        rec.put(&self.data[..self.len]);
    }
}

/// The low `N` bytes of `v`, big-endian (two's complement for negatives);
/// `N` is at most 8.
fn be<const N: usize>(v: i64) -> [u8; N] {
    let b = v.to_be_bytes();
    let mut out = [0u8; N];
    out.copy_from_slice(&b[8 - N..]);
    out
}

/// Two values of `N` bytes each, one after the other.
fn pair<const N: usize>(a: i64, b: i64) -> [u8; 8] {
    let mut out = [0u8; 8];
    out[..N].copy_from_slice(&be::<N>(a));
    out[N..2 * N].copy_from_slice(&be::<N>(b));
    out
}

/// Encodes one record into `out`; false (nothing written) when the record
/// is dropped.
fn encode_record(
    cfg: &Cat062Config,
    t: &SystemTrack,
    notes: &mut Notes<'_>,
    out: &mut Vec<u8>,
) -> bool {
    let mut rec = RecordBuf::new();

    // I062/070 first: without it there is no record.
    let time = if t.time_of_day.is_finite() {
        let raw = (t.time_of_day.rem_euclid(SECONDS_PER_DAY) / TIME.lsb).round() as i64;
        // 86,399.999 s rounds to 86,400 s, which is midnight: 0.
        Some(if raw > TIME.max {
            raw - (TIME.max + 1)
        } else {
            raw
        })
    } else {
        notes.skip(&TIME, t.time_of_day, "is not a finite number");
        None
    };

    let wgs84 = t.wgs84.and_then(|(lat, lon)| {
        let la = LAT.quantise(lat, notes);
        let lo = LON.quantise(lon, notes);
        Some((la?, lo?))
    });
    let xy = {
        let x = X.quantise(t.xy.0, notes);
        let y = Y.quantise(t.xy.1, notes);
        x.zip(y)
    };
    let Some(time) = time else {
        notes.drop_record(&TIME, t.time_of_day, "is not a finite number");
        return false;
    };
    if wgs84.is_none() && xy.is_none() {
        notes.drop_record(&X, t.xy.0, "leaves the record without a position");
        return false;
    }

    rec.item(frn::I010, &[cfg.sac, cfg.sic]);
    if let Some(s) = cfg.service_id {
        rec.item(frn::I015, &[s]);
    }
    rec.item(frn::I070, &be::<3>(time));
    if let Some((lat, lon)) = wgs84 {
        rec.item(frn::I105, &pair::<4>(lat, lon));
    }
    if let Some((x, y)) = xy {
        rec.item(frn::I100, &pair::<3>(x, y)[..6]);
    }
    let vx = VX.quantise(t.velocity.0, notes);
    let vy = VY.quantise(t.velocity.1, notes);
    if let (Some(vx), Some(vy)) = (vx, vy) {
        rec.item(frn::I185, &pair::<2>(vx, vy)[..4]);
    }
    if let Some(c) = t.mode_3a {
        let bit = |b: bool, shift: u16| u16::from(b) << shift;
        let word =
            bit(!c.validated, 15) | bit(c.garbled, 14) | bit(c.changed, 13) | (c.code & 0o7777);
        rec.item(frn::I060, &word.to_be_bytes());
    }
    let callsign = t.callsign.and_then(|c| icao_chars(&c));
    if let Some(chars) = callsign {
        let mut item = [0u8; 7];
        // STI 0 (downlinked from the target), 6 spare bits.
        item[1..].copy_from_slice(&chars);
        rec.item(frn::I245, &item);
    }
    let mut derived = CompoundBuf::new();
    if let Some(a) = t.address.filter(|&a| a <= 0xFF_FFFF) {
        derived.sub(1, &be::<3>(i64::from(a)));
    }
    if let Some(chars) = callsign {
        derived.sub(2, &chars);
    }
    derived.finish(frn::I380, &mut rec);
    // Items go in FRN order: 040 (12) after 060, 245, 380 (9–11).
    rec.item(frn::I040, &t.track_number.to_be_bytes());

    let height = t.height.and_then(|h| HEIGHT.quantise(h, notes));
    let (status, n) = track_status(&t.status, height.is_some());
    rec.item(frn::I080, &status[..n]);

    // Subfields in order: 5 (ADS-C), 7 (VDL), 8 (UAT), 9 (loop) never.
    let mut ages = CompoundBuf::new();
    for (n, q, v) in [
        (1, &AGE_TRK, t.ages.track),
        (2, &AGE_PSR, t.ages.psr),
        (3, &AGE_SSR, t.ages.ssr),
        (4, &AGE_MDS, t.ages.mode_s),
        (6, &AGE_ES, t.ages.adsb_es),
        (10, &AGE_MLT, t.ages.mlat),
    ] {
        if let Some(raw) = v.and_then(|v| q.quantise(v, notes)) {
            ages.sub(n, &be::<1>(raw));
        }
    }
    ages.finish(frn::I290, &mut rec);

    if let Some(fl) = t.measured_flight_level.and_then(|v| MFL.quantise(v, notes)) {
        rec.item(frn::I136, &be::<2>(fl));
    }
    if let Some(h) = height {
        rec.item(frn::I130, &be::<2>(h));
    }
    if let Some(r) = t.vertical_rate.and_then(|v| ROCD.quantise(v, notes)) {
        rec.item(frn::I220, &be::<2>(r));
    }
    if let Some(a) = &t.accuracy {
        accuracy(a, notes).finish(frn::I500, &mut rec);
    }
    if let Some(m) = &t.last_measurement {
        measured(m, notes).finish(frn::I340, &mut rec);
    }
    rec.write(out);
    true
}

/// Eight characters in the ICAO 6-bit set (Annex 10 vol. IV table 3-9:
/// A–Z 1–26, space 32, digits 48–57), 48 bits big-endian; `None` when a
/// character is outside the set.
fn icao_chars(c: &[u8; 8]) -> Option<[u8; 6]> {
    let mut bits = 0u64;
    for &ch in c {
        let code = match ch {
            b'A'..=b'Z' => ch - b'A' + 1,
            b' ' => 32,
            b'0'..=b'9' => ch - b'0' + 48,
            _ => return None,
        };
        bits = bits << 6 | u64::from(code);
    }
    let b = bits.to_be_bytes();
    let mut out = [0u8; 6];
    out.copy_from_slice(&b[2..]);
    Some(out)
}

/// I062/080: the first octet, and the extensions up to the last one with
/// a flag set (the octets and how many are used).
fn track_status(s: &TrackStatusFlags, height_written: bool) -> ([u8; 4], usize) {
    let bit = |b: bool, shift: u8| u8::from(b) << shift;
    let src = if height_written {
        s.altitude_source as u8
    } else {
        0
    };
    let mut octets = [
        // MON SPI MRH SRC(3) CNF FX
        bit(s.monosensor, 7)
            | bit(s.spi, 6)
            | bit(height_written, 5)
            | src << 2
            | bit(s.tentative, 1),
        // SIM TSE TSB FPC AFF STP KOS FX
        bit(s.simulated, 7)
            | bit(s.last_message, 6)
            | bit(s.first_message, 5)
            | bit(s.adsb_inconsistent, 3),
        // AMA MD4(2) ME MI MD5(2) FX
        0,
        // CST PSR SSR MDS ADS SUC AAC FX
        bit(s.coasting, 7)
            | bit(s.psr_aged, 6)
            | bit(s.ssr_aged, 5)
            | bit(s.mode_s_aged, 4)
            | bit(s.adsb_aged, 3),
    ];
    let n = octets.iter().rposition(|&o| o != 0).map_or(1, |i| i + 1);
    for o in octets.iter_mut().take(n - 1) {
        *o |= 1;
    }
    (octets, n)
}

/// I062/500 subfields: 1 APC, 2 COV, 3 APW, 4 AGA, 5 ABA (never), 6 ATV,
/// 7 AA, 8 ARC.
fn accuracy(a: &Accuracy, notes: &mut Notes<'_>) -> CompoundBuf {
    let mut c = CompoundBuf::new();
    // Both components or neither: the subfield is a group.
    let mut both = |v: Option<(f64, f64)>, qx: &Quantity, qy: &Quantity| {
        let (x, y) = v?;
        let rx = qx.quantise(x, notes);
        let ry = qy.quantise(y, notes);
        rx.zip(ry)
    };
    let apc = both(a.xy, &APC_X, &APC_Y);
    let apw = both(a.wgs84, &APW_LAT, &APW_LON);
    let atv = both(a.velocity, &ATV_X, &ATV_Y);
    let aa = both(a.acceleration, &AA_X, &AA_Y);
    if let Some((x, y)) = apc {
        c.sub(1, &pair::<2>(x, y)[..4]);
    }
    if let Some(cov) = a.xy_covariance_m2 {
        // sign(Cov)·√|Cov| (0 for 0; a NaN stays NaN and is skipped).
        let component = if cov == 0.0 {
            0.0
        } else {
            cov.signum() * cov.abs().sqrt()
        };
        if let Some(r) = COV.quantise(component, notes) {
            c.sub(2, &be::<2>(r));
        }
    }
    if let Some((lat, lon)) = apw {
        c.sub(3, &pair::<2>(lat, lon)[..4]);
    }
    if let Some(r) = a.geometric_altitude.and_then(|v| AGA.quantise(v, notes)) {
        c.sub(4, &be::<1>(r));
    }
    if let Some((x, y)) = atv {
        c.sub(6, &pair::<1>(x, y)[..2]);
    }
    if let Some((x, y)) = aa {
        c.sub(7, &pair::<1>(x, y)[..2]);
    }
    if let Some(r) = a.vertical_rate.and_then(|v| ARC.quantise(v, notes)) {
        c.sub(8, &be::<1>(r));
    }
    c
}

/// I062/340 subfields: 1 SID, 2 POS, 3 HEIGHT (MDC, MDA, TYP never).
fn measured(m: &LastMeasurement, notes: &mut Notes<'_>) -> CompoundBuf {
    let mut c = CompoundBuf::new();
    if let Some((sac, sic)) = m.sensor {
        c.sub(1, &[sac, sic]);
    }
    if let Some((rho, theta)) = m.polar {
        let r = RHO.quantise(rho, notes);
        let th = if theta.is_finite() {
            // Modulo 360°; 359.999° rounds to 65,536 LSB, which is 0°.
            let raw = (theta.rem_euclid(360.0) / THETA.lsb).round() as i64;
            Some(if raw > THETA.max {
                raw - (THETA.max + 1)
            } else {
                raw
            })
        } else {
            notes.skip(&THETA, theta, "is not a finite number");
            None
        };
        if let Some((r, th)) = r.zip(th) {
            c.sub(2, &pair::<2>(r, th)[..4]);
        }
    }
    if let Some(h) = m.height.and_then(|h| HEIGHT_3D.quantise(h, notes)) {
        c.sub(3, &be::<2>(h));
    }
    c
}

#[cfg(test)]
mod tests;
