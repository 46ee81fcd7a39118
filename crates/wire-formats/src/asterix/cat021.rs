//! CAT021 ADS-B target reports, UAP of edition **2.7** (2025-07-02,
//! EUROCONTROL ASTERIX Part 12) as libasterix's generated definitions
//! (`Cat_021_2_7`, from `asterix-specs/specs/cat021/cat-2.7.ast`) give
//! it. The UAP and the length of every item are the same in editions 2.4
//! (2015) to 2.7, so reports of those editions decode alike; 2.7 only
//! adds octets to the extended items I021/040 and I021/090, read when
//! present.
//!
//! UAP (FRN: item): 1 I021/010, 2 /040, 3 /161, 4 /015, 5 /071, 6 /130,
//! 7 /131, 8 /072, 9 /150, 10 /151, 11 /080, 12 /073, 13 /074, 14 /075,
//! 15 /076, 16 /140, 17 /090, 18 /210, 19 /070, 20 /230, 21 /145, 22
//! /152, 23 /200, 24 /155, 25 /157, 26 /160, 27 /165, 28 /077, 29 /170,
//! 30 /020, 31 /220, 32 /146, 33 /148, 34 /110, 35 /016, 36 /008, 37
//! /271, 38 /132, 39 /250, 40 /260, 41 /400, 42 /295, 43–47 spare, 48
//! RE, 49 SP.
//!
//! Items decoded (SI at this edge; angles in degrees):
//! - I021/010 SAC/SIC; /040 target report descriptor ([`AdsbDescriptor`]:
//!   ATP, ARC, RC, RAB; first extension DCR, GBS, SIM, TST, SAA, CL;
//!   second extension LLC, IPC, NOGO, CPR, LDPJ, RCF);
//! - /080 target address (24 bits); /170 target identification (8 ×
//!   6-bit ICAO); /070 Mode 3/A (12 bits); /161 track number (12 bits);
//!   /020 emitter category;
//! - times of day (s since midnight UTC, 1/128 s): /071 time of
//!   applicability of the position, /072 of the velocity, /073 and /075
//!   time of message reception of position and velocity, /077 time of
//!   report transmission; /074 and /076 the high-precision reception
//!   times (FSI, 2⁻³⁰ s: [`PreciseTime`]);
//! - /130 position (WGS-84, 180/2²³ °, 3 + 3 bytes two's complement),
//!   /131 high-resolution position (180/2³⁰ °, 4 + 4 bytes);
//! - /140 geometric height (6.25 ft, two's complement; 0x7FFF means
//!   "greater than" the largest value: [`Capped::exceeded`]); /145 flight
//!   level (1/4 FL, two's complement);
//! - /090 quality indicators ([`Quality`]: NUCr/NACv, NUCp/NIC, NIC baro,
//!   SIL, NACp, SIL supplement, SDA, GVA, PIC, as far as the extensions
//!   go); /210 MOPS version;
//! - /150 air speed (IAS 2⁻¹⁴ NM/s or Mach 0.001); /151 true airspeed
//!   (1 kt, RE); /155 barometric and /157 geometric vertical rate (6.25
//!   ft/min, two's complement, RE); /160 airborne ground vector (ground
//!   speed 2⁻¹⁴ NM/s, track angle 360/2¹⁶ °, RE);
//! - /200 target status (ICF, LNAV, ME, PS priority status, SS
//!   surveillance status).
//!
//! Every other item is skipped by its rule: /015, /016, /008 (1 byte),
//! /132, /400, /230, /152, /165, /146, /148, /260 (fixed), /271 (extended),
//! /220 (compound, 4 subfields), /110 (compound: TIS extended, TID
//! repetitive of 15 bytes), /295 (compound, 23 one-byte ages), /250
//! (repetitive, 8 bytes), RE and SP (explicit).

use super::fields::{callsign, signed, time_of_day, u16_at, u24_at, u32_at};
use super::quality::nacp_sigma_m;
use super::uap::{Item, Len, item};
use super::{CAT_ADSB, Category, CooperativeReport, Decoded, FT_M, KT_MPS, NM_M};

/// A CAT021 record: an ADS-B target report. Every item is optional.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AdsbReport {
    /// Offset of the record (its FSPEC) in the data.
    pub offset: usize,
    /// I021/010 (SAC, SIC) of the ground station.
    pub source: Option<(u8, u8)>,
    /// I021/040.
    pub descriptor: Option<AdsbDescriptor>,
    /// I021/161 track number (12 bits).
    pub track_number: Option<u16>,
    /// I021/071 time of applicability of the position (s since midnight).
    pub toa_position_s: Option<f64>,
    /// I021/072 time of applicability of the velocity (s).
    pub toa_velocity_s: Option<f64>,
    /// I021/073 time of message reception of the position (s).
    pub tomr_position_s: Option<f64>,
    /// I021/074 high-precision time of reception of the position.
    pub tomr_position_precise: Option<PreciseTime>,
    /// I021/075 time of message reception of the velocity (s).
    pub tomr_velocity_s: Option<f64>,
    /// I021/076 high-precision time of reception of the velocity.
    pub tomr_velocity_precise: Option<PreciseTime>,
    /// I021/077 time of ASTERIX report transmission (s).
    pub tort_s: Option<f64>,
    /// I021/130 WGS-84 (latitude, longitude), degrees (LSB 180/2²³ °,
    /// about 2.1 m).
    pub position_deg: Option<(f64, f64)>,
    /// I021/131 WGS-84 (latitude, longitude), degrees (LSB 180/2³⁰ °,
    /// about 1.9 cm).
    pub position_high_res_deg: Option<(f64, f64)>,
    /// I021/150.
    pub air_speed: Option<AirSpeed>,
    /// I021/151 true airspeed (m/s).
    pub true_airspeed_mps: Option<Capped>,
    /// I021/080 target address (24 bits; its kind is the descriptor's
    /// ATP).
    pub address: Option<u32>,
    /// I021/140 geometric height above the WGS-84 ellipsoid (m).
    pub geometric_height_m: Option<Capped>,
    /// I021/090.
    pub quality: Option<Quality>,
    /// I021/210.
    pub mops: Option<Mops>,
    /// I021/070 Mode 3/A code, 12 bits (four octal digits).
    pub mode_3a: Option<u16>,
    /// I021/145 flight level (FL, 1/4 resolution).
    pub flight_level: Option<f64>,
    /// I021/200.
    pub status: Option<TargetStatus>,
    /// I021/155 barometric vertical rate (m/s, up positive).
    pub barometric_vertical_rate_mps: Option<Capped>,
    /// I021/157 geometric vertical rate (m/s, up positive).
    pub geometric_vertical_rate_mps: Option<Capped>,
    /// I021/160.
    pub ground_vector: Option<GroundVector>,
    /// I021/170 target identification, trailing spaces removed.
    pub callsign: Option<String>,
    /// I021/020 emitter category (1 light, 3 medium, 5 heavy, 10
    /// rotorcraft, 13 UAV, 20 surface emergency vehicle, …).
    pub emitter_category: Option<u8>,
}

/// A value whose item has a range-exceeded indication (the RE bit of
/// I021/151, /155, /157; the 0x7FFF of I021/140): when `exceeded`, the
/// true value lies beyond `value`, the largest the item can carry.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Capped {
    pub value: f64,
    pub exceeded: bool,
}

/// I021/040 target report descriptor. Fields of an extension are `None`
/// when the extension is absent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AdsbDescriptor {
    /// ATP address type: 0 24-bit ICAO, 1 duplicate, 2 surface vehicle,
    /// 3 anonymous, 4–7 reserved.
    pub atp: u8,
    /// ARC altitude reporting capability: 0 25 ft, 1 100 ft, 2 unknown,
    /// 3 invalid.
    pub arc: u8,
    /// RC: range check passed, CPR validation pending.
    pub rc: bool,
    /// RAB: report from a field monitor (fixed transponder).
    pub rab: bool,
    /// DCR: differential correction.
    pub dcr: Option<bool>,
    /// GBS: the ground bit is set (the target says it is on the surface).
    pub ground_bit: Option<bool>,
    /// SIM: simulated target report.
    pub simulated: Option<bool>,
    /// TST: test target.
    pub test: Option<bool>,
    /// SAA: equipment **not** capable of providing the selected altitude.
    pub saa_not_capable: Option<bool>,
    /// CL confidence level: 0 valid, 1 suspect, 2 no information.
    pub confidence: Option<u8>,
    /// LLC: a black/white list lookup failed (suspect target).
    pub list_lookup_failed: Option<bool>,
    /// IPC: an independent position check failed.
    pub position_check_failed: Option<bool>,
    /// NOGO bit set (I023/100).
    pub nogo: Option<bool>,
    /// CPR: compact position reporting validation failed.
    pub cpr_failed: Option<bool>,
    /// LDPJ: a local decoding position jump was detected.
    pub position_jump: Option<bool>,
    /// RCF: range check failed (outside the station's credible range).
    pub range_check_failed: Option<bool>,
}

/// I021/074 or I021/076: the fraction of the second at which the latest
/// position (velocity) message was received, and FSI, which says how
/// its whole second relates to I021/073 (I021/075).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PreciseTime {
    /// FSI: 0 same whole second as the coarse item, 1 one more, 2 one
    /// less, 3 reserved.
    pub fsi: u8,
    /// The fraction of the second (s, LSB 2⁻³⁰ s, [0, 1)).
    pub fraction_s: f64,
}

impl PreciseTime {
    /// The full time of day (s since midnight, [0, 86400)): the whole
    /// seconds of the coarse time `coarse_s` (I021/073 or /075) adjusted
    /// by FSI, plus the fraction; wrapped across midnight. `None` for
    /// FSI 3 (reserved).
    pub fn with_coarse(&self, coarse_s: f64) -> Option<f64> {
        let whole = coarse_s.floor()
            + match self.fsi {
                0 => 0.0,
                1 => 1.0,
                2 => -1.0,
                _ => return None,
            };
        Some((whole + self.fraction_s).rem_euclid(86_400.0))
    }
}

/// I021/150 air speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AirSpeed {
    /// Indicated airspeed (m/s; LSB 2⁻¹⁴ NM/s).
    Ias { mps: f64 },
    /// Mach number (LSB 0.001).
    Mach(f64),
}

/// I021/160 airborne ground vector.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GroundVector {
    /// Ground speed (m/s; LSB 2⁻¹⁴ NM/s, about 0.11 m/s).
    pub speed_mps: f64,
    /// Track angle, clockwise from true north (degrees, [0, 360)).
    pub track_deg: f64,
    /// RE: the true ground speed exceeds `speed_mps`.
    pub exceeded: bool,
}

impl GroundVector {
    /// (east, north) m/s: (gs·sin θ, gs·cos θ) for track angle θ.
    pub fn east_north_mps(&self) -> (f64, f64) {
        let (s, c) = self.track_deg.to_radians().sin_cos();
        (self.speed_mps * s, self.speed_mps * c)
    }
}

/// I021/090 quality indicators, as far as the item's extensions go (a
/// field of an absent extension is `None`). Whether the first two are
/// NUC (MOPS version 0) or NAC/NIC (version 1 and later) is I021/210's
/// version.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Quality {
    /// NUCr or NACv (3 bits): [`super::quality::nacv_bound_mps`].
    pub nucr_nacv: u8,
    /// NUCp or NIC (4 bits): [`super::quality::nic_containment_m`].
    pub nucp_nic: u8,
    /// NIC for barometric altitude (1 bit).
    pub nic_baro: Option<bool>,
    /// SIL (2 bits).
    pub sil: Option<u8>,
    /// NACp (4 bits): [`super::quality::nacp_sigma_m`].
    pub nacp: Option<u8>,
    /// SIL supplement: `true` per sample, `false` per flight hour.
    pub sil_per_sample: Option<bool>,
    /// SDA, system design assurance (2 bits).
    pub sda: Option<u8>,
    /// GVA, geometric altitude accuracy (2 bits).
    pub gva: Option<u8>,
    /// PIC, position integrity category (4 bits).
    pub pic: Option<u8>,
}

/// I021/210 MOPS version.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Mops {
    /// VNS: the version is not supported by the ground station.
    pub not_supported: bool,
    /// VN: 0 DO-260, 1 DO-260A, 2 DO-260B, 3 DO-260C.
    pub version: u8,
    /// LTT: 0 other, 1 UAT, 2 1090 ES, 3 VDL 4.
    pub link: u8,
}

/// I021/200 target status.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TargetStatus {
    /// ICF: intent change flag raised.
    pub intent_change: bool,
    /// LNAV: LNAV mode **not** engaged.
    pub lnav_not_engaged: bool,
    /// ME: military emergency.
    pub military_emergency: bool,
    /// PS priority status: 0 none, 1 general emergency, 2 medical, 3
    /// minimum fuel, 4 no communications, 5 unlawful interference, 6
    /// downed aircraft.
    pub priority: u8,
    /// SS surveillance status: 0 none, 1 permanent alert (emergency), 2
    /// temporary alert (Mode 3/A change), 3 SPI.
    pub surveillance: u8,
}

/// I021/220 MET: WS, WD, TMP (2 bytes each), TRB (1 byte).
const I021_220: &[Option<Len>] = &[
    Some(Len::Fixed(2)),
    Some(Len::Fixed(2)),
    Some(Len::Fixed(2)),
    Some(Len::Fixed(1)),
];
/// I021/110 trajectory intent: TIS (extended), TID (REP × 15 bytes: TCA,
/// NC, TCPN, ALT, LAT, LON, PT, TD, TRA, TOA, TOV, TTR = 120 bits).
const I021_110: &[Option<Len>] = &[Some(Len::Extended), Some(Len::Repetitive(15))];
/// I021/295 data ages: 23 subfields of one byte (AOS … SCC).
const I021_295: &[Option<Len>] = &[Some(Len::Fixed(1)); 23];

/// CAT021 UAP, FRN 1..=49 (index 0 is FRN 1).
const UAP_021: [Option<Item>; 49] = {
    use Len::{Compound, Explicit, Extended, Fixed, Repetitive};
    [
        item("I021/010", Fixed(2)),
        item("I021/040", Extended),
        item("I021/161", Fixed(2)),
        item("I021/015", Fixed(1)),
        item("I021/071", Fixed(3)),
        item("I021/130", Fixed(6)),
        item("I021/131", Fixed(8)),
        item("I021/072", Fixed(3)),
        item("I021/150", Fixed(2)),
        item("I021/151", Fixed(2)),
        item("I021/080", Fixed(3)),
        item("I021/073", Fixed(3)),
        item("I021/074", Fixed(4)),
        item("I021/075", Fixed(3)),
        item("I021/076", Fixed(4)),
        item("I021/140", Fixed(2)),
        item("I021/090", Extended),
        item("I021/210", Fixed(1)),
        item("I021/070", Fixed(2)),
        item("I021/230", Fixed(2)),
        item("I021/145", Fixed(2)),
        item("I021/152", Fixed(2)),
        item("I021/200", Fixed(1)),
        item("I021/155", Fixed(2)),
        item("I021/157", Fixed(2)),
        item("I021/160", Fixed(4)),
        item("I021/165", Fixed(2)),
        item("I021/077", Fixed(3)),
        item("I021/170", Fixed(6)),
        item("I021/020", Fixed(1)),
        item("I021/220", Compound(I021_220)),
        item("I021/146", Fixed(2)),
        item("I021/148", Fixed(2)),
        item("I021/110", Compound(I021_110)),
        item("I021/016", Fixed(1)),
        item("I021/008", Fixed(1)),
        item("I021/271", Extended),
        item("I021/132", Fixed(1)),
        // REP × 8 bytes (MB data 56 bits, BDS1, BDS2).
        item("I021/250", Repetitive(8)),
        item("I021/260", Fixed(7)),
        item("I021/400", Fixed(1)),
        item("I021/295", Compound(I021_295)),
        None,
        None,
        None,
        None,
        None,
        item("I021/RE", Explicit),
        item("I021/SP", Explicit),
    ]
};

/// LSB of I021/130 (degrees).
const LSB_130: f64 = 180.0 / (1u64 << 23) as f64;
/// LSB of I021/131 (degrees).
const LSB_131: f64 = 180.0 / (1u64 << 30) as f64;
/// LSB of the speeds in NM/s (2⁻¹⁴), in m/s.
const LSB_NM_S: f64 = NM_M / 16384.0;
/// 6.25 ft/min in m/s.
const LSB_VERTICAL_RATE: f64 = 6.25 * FT_M / 60.0;

/// A 16-bit word whose bit 16 is RE and the 15 others a value.
fn capped(word: u16, value: f64) -> Capped {
    Capped {
        value,
        exceeded: word & 0x8000 != 0,
    }
}

fn precise(v: &[u8]) -> PreciseTime {
    let w = u32_at(v, 0);
    PreciseTime {
        fsi: (w >> 30) as u8,
        fraction_s: (w & 0x3FFF_FFFF) as f64 / (1u64 << 30) as f64,
    }
}

fn descriptor(v: &[u8]) -> AdsbDescriptor {
    let bit = |octet: usize, mask: u8| v.get(octet).map(|b| b & mask != 0);
    AdsbDescriptor {
        atp: v[0] >> 5,
        arc: (v[0] >> 3) & 3,
        rc: v[0] & 0x04 != 0,
        rab: v[0] & 0x02 != 0,
        dcr: bit(1, 0x80),
        ground_bit: bit(1, 0x40),
        simulated: bit(1, 0x20),
        test: bit(1, 0x10),
        saa_not_capable: bit(1, 0x08),
        confidence: v.get(1).map(|b| (b >> 1) & 3),
        list_lookup_failed: bit(2, 0x40),
        position_check_failed: bit(2, 0x20),
        nogo: bit(2, 0x10),
        cpr_failed: bit(2, 0x08),
        position_jump: bit(2, 0x04),
        range_check_failed: bit(2, 0x02),
    }
}

fn quality(v: &[u8]) -> Quality {
    let e1 = v.get(1).copied();
    let e2 = v.get(2).copied();
    Quality {
        nucr_nacv: v[0] >> 5,
        nucp_nic: (v[0] >> 1) & 0x0F,
        nic_baro: e1.map(|b| b & 0x80 != 0),
        sil: e1.map(|b| (b >> 5) & 3),
        nacp: e1.map(|b| (b >> 1) & 0x0F),
        sil_per_sample: e2.map(|b| b & 0x20 != 0),
        sda: e2.map(|b| (b >> 3) & 3),
        gva: e2.map(|b| (b >> 1) & 3),
        pic: v.get(3).map(|b| b >> 4),
    }
}

impl Category for AdsbReport {
    const CAT: u8 = CAT_ADSB;
    const UAP: &'static [Option<Item>] = &UAP_021;

    fn read(&mut self, frn: usize, v: &[u8]) {
        let r = self;
        match frn {
            1 => r.source = Some((v[0], v[1])),
            2 => r.descriptor = Some(descriptor(v)),
            3 => r.track_number = Some(u16_at(v, 0) & 0x0FFF),
            5 => r.toa_position_s = Some(time_of_day(v, 0)),
            6 => {
                let lat = signed(u24_at(v, 0), 24) as f64 * LSB_130;
                let lon = signed(u24_at(v, 3), 24) as f64 * LSB_130;
                r.position_deg = Some((lat, lon));
            }
            7 => {
                let lat = u32_at(v, 0) as i32 as f64 * LSB_131;
                let lon = u32_at(v, 4) as i32 as f64 * LSB_131;
                r.position_high_res_deg = Some((lat, lon));
            }
            8 => r.toa_velocity_s = Some(time_of_day(v, 0)),
            9 => {
                let w = u16_at(v, 0);
                let value = (w & 0x7FFF) as f64;
                r.air_speed = Some(if w & 0x8000 == 0 {
                    AirSpeed::Ias {
                        mps: value * LSB_NM_S,
                    }
                } else {
                    AirSpeed::Mach(value / 1000.0)
                });
            }
            10 => {
                let w = u16_at(v, 0);
                r.true_airspeed_mps = Some(capped(w, (w & 0x7FFF) as f64 * KT_MPS));
            }
            11 => r.address = Some(u24_at(v, 0)),
            12 => r.tomr_position_s = Some(time_of_day(v, 0)),
            13 => r.tomr_position_precise = Some(precise(v)),
            14 => r.tomr_velocity_s = Some(time_of_day(v, 0)),
            15 => r.tomr_velocity_precise = Some(precise(v)),
            16 => {
                let w = u16_at(v, 0);
                r.geometric_height_m = Some(Capped {
                    value: w as i16 as f64 * 6.25 * FT_M,
                    exceeded: w == 0x7FFF,
                });
            }
            17 => r.quality = Some(quality(v)),
            18 => {
                r.mops = Some(Mops {
                    not_supported: v[0] & 0x40 != 0,
                    version: (v[0] >> 3) & 7,
                    link: v[0] & 7,
                })
            }
            19 => r.mode_3a = Some(u16_at(v, 0) & 0x0FFF),
            21 => r.flight_level = Some(u16_at(v, 0) as i16 as f64 / 4.0),
            23 => {
                r.status = Some(TargetStatus {
                    intent_change: v[0] & 0x80 != 0,
                    lnav_not_engaged: v[0] & 0x40 != 0,
                    military_emergency: v[0] & 0x20 != 0,
                    priority: (v[0] >> 2) & 7,
                    surveillance: v[0] & 3,
                })
            }
            24 | 25 => {
                let w = u16_at(v, 0);
                let rate = capped(w, signed(w as u32, 15) as f64 * LSB_VERTICAL_RATE);
                if frn == 24 {
                    r.barometric_vertical_rate_mps = Some(rate);
                } else {
                    r.geometric_vertical_rate_mps = Some(rate);
                }
            }
            26 => {
                let w = u16_at(v, 0);
                r.ground_vector = Some(GroundVector {
                    speed_mps: (w & 0x7FFF) as f64 * LSB_NM_S,
                    track_deg: u16_at(v, 2) as f64 * (360.0 / 65536.0),
                    exceeded: w & 0x8000 != 0,
                });
            }
            28 => r.tort_s = Some(time_of_day(v, 0)),
            29 => r.callsign = callsign(v),
            30 => r.emitter_category = Some(v[0]),
            _ => {}
        }
    }

    fn store(mut self, offset: usize, out: &mut Decoded) {
        self.offset = offset;
        out.adsb_reports.push(self);
    }
}

impl AdsbReport {
    /// The time of reception of the position at the high precision of
    /// I021/074 (s since midnight), when both I021/073 and /074 are
    /// present and FSI is not reserved.
    pub fn tomr_position_precise_s(&self) -> Option<f64> {
        self.tomr_position_precise?
            .with_coarse(self.tomr_position_s?)
    }

    /// As [`Self::tomr_position_precise_s`] for the velocity (I021/075,
    /// /076).
    pub fn tomr_velocity_precise_s(&self) -> Option<f64> {
        self.tomr_velocity_precise?
            .with_coarse(self.tomr_velocity_s?)
    }
}

/// CAT021 as a tracker reads it:
/// - time of applicability: I021/071; without it the precise time of
///   reception of the position (I021/073 + /074), else I021/073 (the
///   position is then older than that time by the latency of the link);
/// - position: I021/131, else I021/130;
/// - geometric height: I021/140, `None` when it says "greater than";
/// - velocity: I021/160, `None` when its RE bit is set;
/// - σ of the position: from I021/090's NACp ([`nacp_sigma_m`]), the same
///   on both axes.
impl CooperativeReport for AdsbReport {
    fn offset(&self) -> usize {
        self.offset
    }

    fn source(&self) -> Option<(u8, u8)> {
        self.source
    }

    fn time_of_applicability_s(&self) -> Option<f64> {
        self.toa_position_s
            .or_else(|| self.tomr_position_precise_s())
            .or(self.tomr_position_s)
    }

    fn lat_lon_deg(&self) -> Option<(f64, f64)> {
        self.position_high_res_deg.or(self.position_deg)
    }

    fn geometric_height_m(&self) -> Option<f64> {
        self.geometric_height_m
            .filter(|h| !h.exceeded)
            .map(|h| h.value)
    }

    fn flight_level(&self) -> Option<f64> {
        self.flight_level
    }

    fn velocity_en_mps(&self) -> Option<(f64, f64)> {
        self.ground_vector
            .filter(|g| !g.exceeded)
            .map(|g| g.east_north_mps())
    }

    fn address(&self) -> Option<u32> {
        self.address
    }

    fn callsign(&self) -> Option<&str> {
        self.callsign.as_deref()
    }

    fn mode_3a(&self) -> Option<u16> {
        self.mode_3a
    }

    fn position_sigma_m(&self) -> Option<(f64, f64)> {
        let s = nacp_sigma_m(self.quality?.nacp?)?;
        Some((s, s))
    }

    fn simulated_or_test(&self) -> bool {
        self.descriptor
            .is_some_and(|d| d.simulated == Some(true) || d.test == Some(true))
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::block;
    use super::super::{CooperativeReport, decode};
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * b.abs().max(1.0)
    }

    #[test]
    fn special_values_and_range_exceeded_bits_are_kept_and_not_used() {
        // FSPEC 0x01 0x01 0x43 0x18: octet 3 bits 7 and 2 are FRN 16
        // (I021/140) and 21 (/145), FX; octet 4 bits 5 and 4 are FRN 25
        // (/157) and 26 (/160).
        // 140 0x7FFF: "greater than" 32767 × 6.25 ft. 145 0xFFEC = −20
        // quarter FL = FL −5. 157 0xFFF0: RE = 1, 15-bit 0x7FF0 = −16 ×
        // 6.25 ft/min = −100 ft/min = −0.508 m/s. 160 0xC000 0x4000: RE =
        // 1, GS 0x4000 × 2⁻¹⁴ NM/s = 1 NM/s = 1852 m/s, TA 0x4000 = 90°.
        let rec = [
            0x01, 0x01, 0x43, 0x18, 0x7F, 0xFF, 0xFF, 0xEC, 0xFF, 0xF0, 0xC0, 0x00, 0x40, 0x00,
        ];
        let d = decode(&block(21, &rec));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let r = &d.adsb_reports[0];
        let h = r.geometric_height_m.unwrap();
        assert!(h.exceeded);
        assert!(close(h.value, 32767.0 * 6.25 * 0.3048));
        assert_eq!(CooperativeReport::geometric_height_m(r), None);
        assert_eq!(r.flight_level, Some(-5.0));
        let g = r.geometric_vertical_rate_mps.unwrap();
        assert!(g.exceeded && close(g.value, -0.508), "{g:?}");
        let v = r.ground_vector.unwrap();
        assert!(v.exceeded && v.speed_mps == 1852.0 && v.track_deg == 90.0);
        assert_eq!(r.velocity_en_mps(), None);
        // Without RE the same vector is (1852, 0) east, north.
        let (e, n) = GroundVector {
            exceeded: false,
            ..v
        }
        .east_north_mps();
        assert!(close(e, 1852.0) && n.abs() < 1e-9);
    }

    #[test]
    fn positions_precise_times_and_nacp_make_the_trackers_view() {
        // FSPEC 0x07 0x0D 0x20: FRN 6 (I021/130), 7 (/131); 12 (/073),
        // 13 (/074); 17 (/090).
        // 130: lat 0x200000 = 2²¹ × 180/2²³ = 45°, lon 0xE00000 = −45°.
        // 131: lat 0x10000001 = 45° + 180/2³⁰, lon 0xF0000000 = −45°.
        // 073: 0x000040 = 0.5 s. 074: FSI 2 (one second less), fraction
        // 0x30000000 × 2⁻³⁰ = 0.75 s: −1 + 0.75 = −0.25 s, 86,399.75 s of
        // the day before.
        // 090: 0x57 = NACv 2, NIC 11, FX; 0xF4 = NIC baro 1, SIL 3, NACp
        // 10 (EPU < 10 m: σ = 10 / 2.4477 = 4.0854 m).
        let rec = [
            0x07, 0x0D, 0x20, // FSPEC
            0x20, 0x00, 0x00, 0xE0, 0x00, 0x00, // 130
            0x10, 0x00, 0x00, 0x01, 0xF0, 0x00, 0x00, 0x00, // 131
            0x00, 0x00, 0x40, // 073
            0xB0, 0x00, 0x00, 0x00, // 074
            0x57, 0xF4, // 090
        ];
        let d = decode(&block(21, &rec));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let r = &d.adsb_reports[0];
        assert_eq!(r.position_deg, Some((45.0, -45.0)));
        let hr = 45.0 + 180.0 / 1073741824.0;
        assert_eq!(r.position_high_res_deg, Some((hr, -45.0)));
        assert_eq!(r.lat_lon_deg(), Some((hr, -45.0)));
        let p = r.tomr_position_precise.unwrap();
        assert_eq!((p.fsi, p.fraction_s), (2, 0.75));
        assert_eq!(r.tomr_position_precise_s(), Some(86_399.75));
        // No I021/071: the precise reception time stands in.
        assert_eq!(r.time_of_applicability_s(), Some(86_399.75));
        let q = r.quality.unwrap();
        assert_eq!((q.nucr_nacv, q.nucp_nic), (2, 11));
        assert_eq!((q.nic_baro, q.sil, q.nacp), (Some(true), Some(3), Some(10)));
        assert_eq!((q.sda, q.pic), (None, None));
        let (sx, sy) = r.position_sigma_m().unwrap();
        assert!((sx - 4.0854).abs() < 1e-4 && sx == sy);
    }

    #[test]
    fn fsi_moves_the_whole_second_and_wraps_at_midnight() {
        let t = |fsi, fraction_s| PreciseTime { fsi, fraction_s };
        // Coarse 100.9921875 s (whole 100): FSI 0 → 100.25, 1 → 101.25,
        // 2 → 99.25, 3 reserved.
        assert_eq!(t(0, 0.25).with_coarse(100.992_187_5), Some(100.25));
        assert_eq!(t(1, 0.25).with_coarse(100.992_187_5), Some(101.25));
        assert_eq!(t(2, 0.25).with_coarse(100.992_187_5), Some(99.25));
        assert_eq!(t(3, 0.25).with_coarse(100.0), None);
        // 86,399.5 + one second: 0.5 s of the next day.
        assert_eq!(t(1, 0.5).with_coarse(86_399.5), Some(0.5));
    }

    #[test]
    fn descriptor_extensions_are_read_when_present() {
        // I021/040 0x43 0x71 0x0A: ATP 2, ARC 0, RC 0, RAB 1, FX; DCR 0,
        // GBS 1, SIM 1, TST 1, SAA 0, CL 0, FX; spare, LLC 0, IPC 0, NOGO
        // 0, CPR 1, LDPJ 0, RCF 1.
        let d = decode(&block(21, &[0x40, 0x43, 0x71, 0x0A]));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let r = &d.adsb_reports[0];
        let x = r.descriptor.unwrap();
        assert_eq!((x.atp, x.arc, x.rc, x.rab), (2, 0, false, true));
        assert_eq!(
            (x.ground_bit, x.simulated, x.test, x.confidence),
            (Some(true), Some(true), Some(true), Some(0))
        );
        assert_eq!(
            (x.cpr_failed, x.range_check_failed),
            (Some(true), Some(true))
        );
        assert_eq!(x.nogo, Some(false));
        assert!(r.simulated_or_test());
        // One octet only: the extensions' fields are unknown.
        let d = decode(&block(21, &[0x40, 0x02]));
        let x = d.adsb_reports[0].descriptor.unwrap();
        assert_eq!((x.simulated, x.test, x.cpr_failed), (None, None, None));
        assert!(!d.adsb_reports[0].simulated_or_test());
    }

    #[test]
    fn a_spare_frn_loses_its_block_and_skipped_items_keep_the_record_in_step() {
        // Record 1: FSPEC six octets with FX, then 0x80 in octet 7: FRN
        // 43, a spare of the 2.7 UAP.
        let mut data = block(21, &[0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x80, 0, 0]);
        let next = data.len();
        // Record 2: FRN 34 (I021/110, octet 5 bit 3: 0x04): primary 0xC0
        // (TIS, TID), TIS 0x00, TID REP 1 × 15 bytes. Record 3: FRN 1.
        let mut rec = vec![0x01, 0x01, 0x01, 0x01, 0x04, 0xC0, 0x00, 1];
        rec.extend([0xAA; 15]);
        rec.extend([0x80, 9, 8]);
        data.extend(block(21, &rec));
        let d = decode(&data);
        assert_eq!(d.errors.len(), 1, "{:?}", d.errors);
        assert_eq!(d.errors[0].offset, 3);
        assert!(d.errors[0].reason.contains("FRN 43"), "{:?}", d.errors);
        assert_eq!(d.adsb_reports.len(), 2);
        assert_eq!(d.adsb_reports[0].offset, next + 3);
        assert_eq!(d.adsb_reports[1].source, Some((9, 8)));
    }

    #[test]
    fn a_truncated_item_is_reported_where_the_block_ends() {
        // FRN 7 (I021/131, 8 bytes) with 3 bytes left, then a CAT020
        // block with I020/010.
        let mut data = block(21, &[0x02, 1, 2, 3]);
        data.extend(block(20, &[0x80, 5, 6]));
        let d = decode(&data);
        assert_eq!(d.errors.len(), 1);
        assert_eq!(d.errors[0].offset, 4, "{:?}", d.errors);
        assert!(
            d.errors[0].reason.contains("I021/131 needs 8"),
            "{:?}",
            d.errors
        );
        assert_eq!(d.mlat_reports[0].source, Some((5, 6)));
    }
}
