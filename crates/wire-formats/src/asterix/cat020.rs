//! CAT020 multilateration (MLAT, WAM) target reports, UAP of edition
//! **1.11** (2025-07-02, EUROCONTROL ASTERIX Part 14) as libasterix's
//! generated definitions (`Cat_020_1_11`, from
//! `asterix-specs/specs/cat020/cat-1.11.ast`) give it; the UAP and the
//! item lengths are those of 1.10 (1.11 only names two spare bits of
//! I020/230).
//!
//! UAP (FRN: item): 1 I020/010, 2 /020, 3 /140, 4 /041, 5 /042, 6 /161,
//! 7 /170, 8 /070, 9 /202, 10 /090, 11 /100, 12 /220, 13 /245, 14 /110,
//! 15 /105, 16 /210, 17 /300, 18 /310, 19 /500, 20 /400, 21 /250, 22
//! /230, 23 /260, 24 /030, 25 /055, 26 /050, 27 RE, 28 SP.
//!
//! Items decoded (SI at this edge; angles in degrees):
//! - I020/010 SAC/SIC; /020 target report descriptor ([`MlatDescriptor`]:
//!   the technologies SSR, MS, HF, VDL4, UAT, DME, OT; first extension
//!   RAB, SPI, CHN, GBS, CRT, SIM, TST; second extension CF);
//! - /140 time of day (1/128 s);
//! - /041 position in WGS-84 (180/2²⁵ °, 4 + 4 bytes two's complement);
//!   /042 position in the system's Cartesian plane (x, y: 0.5 m, 3 + 3
//!   bytes two's complement);
//! - /202 track velocity in that plane (vx, vy: 0.25 m/s, two's
//!   complement);
//! - /161 track number (12 bits); /070 Mode 3/A (V, G, L, 12 bits); /090
//!   flight level (V, G, 1/4 FL two's complement); /105 geometric height
//!   (6.25 ft, two's complement); /220 target address (24 bits); /245
//!   target identification (STI, 8 × 6-bit ICAO);
//! - /500 position accuracy ([`PositionAccuracy`], compound: DOP, SDP,
//!   SDH).
//!
//! Every other item is skipped by its rule: /170 and /030 (extended; /030
//! is "repetitive with FX", one-octet parts), /100, /110, /210, /230,
//! /260, /300, /310, /055, /050 (fixed), /400 (repetitive, 1 byte), /250
//! (repetitive, 8 bytes), RE and SP (explicit).

use super::fields::{ReplyFlags, callsign, signed, time_of_day, u16_at, u24_at, u32_at};
use super::uap::{Item, Len, each_subfield, item};
use super::{CAT_MLAT, Category, CooperativeReport, Decoded, FT_M};

/// A CAT020 record: a multilateration target report. Every item is
/// optional.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MlatReport {
    /// Offset of the record (its FSPEC) in the data.
    pub offset: usize,
    /// I020/010 (SAC, SIC) of the system.
    pub source: Option<(u8, u8)>,
    /// I020/020.
    pub descriptor: Option<MlatDescriptor>,
    /// I020/140 time of the report (s since midnight UTC).
    pub time_of_day_s: Option<f64>,
    /// I020/041 WGS-84 (latitude, longitude), degrees (LSB 180/2²⁵ °,
    /// about 0.6 m).
    pub position_deg: Option<(f64, f64)>,
    /// I020/042 (x, y) in the system's Cartesian plane (m; x east, y
    /// north at its reference point, I019/610).
    pub position_xy_m: Option<(f64, f64)>,
    /// I020/161 track number (12 bits).
    pub track_number: Option<u16>,
    /// I020/070 Mode 3/A code, 12 bits (four octal digits).
    pub mode_3a: Option<u16>,
    /// I020/070 V, G, L.
    pub mode_3a_flags: Option<ReplyFlags>,
    /// I020/202 (vx, vy) in the Cartesian plane (m/s).
    pub velocity_xy_mps: Option<(f64, f64)>,
    /// I020/090 flight level (FL, 1/4 resolution).
    pub flight_level: Option<f64>,
    /// I020/090 V, G (`smoothed` unused).
    pub flight_level_flags: Option<ReplyFlags>,
    /// I020/220 target address (24 bits; its kind is the descriptor's
    /// CF).
    pub address: Option<u32>,
    /// I020/245 target identification, trailing spaces removed.
    pub callsign: Option<String>,
    /// I020/245 STI: 0 callsign or registration downlinked, 1 callsign
    /// not downlinked, 2 registration not downlinked, 3 invalid.
    pub callsign_source: Option<u8>,
    /// I020/105 geometric height above the WGS-84 ellipsoid (m).
    pub geometric_height_m: Option<f64>,
    /// I020/500.
    pub accuracy: Option<PositionAccuracy>,
}

/// I020/020 target report descriptor. The technology bits are the bits as
/// sent, `true` when set; set means the technology contributed to the
/// report (the reading of SDDL, jASTERIX and most decoders: an all-zero
/// octet then says "no technology named"; the tables of asterix-specs
/// 1.10 and 1.11 print the opposite wording, "0: … multilateration, 1:
/// no … multilateration", which we take for a transcription slip).
/// Fields of an extension are `None` when it is absent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MlatDescriptor {
    /// SSR: non-Mode S 1090 MHz multilateration.
    pub ssr: bool,
    /// MS: Mode S 1090 MHz multilateration.
    pub mode_s: bool,
    /// HF multilateration.
    pub hf: bool,
    /// VDL Mode 4 multilateration.
    pub vdl4: bool,
    /// UAT multilateration.
    pub uat: bool,
    /// DME/TACAN multilateration.
    pub dme: bool,
    /// OT: other technology multilateration.
    pub other: bool,
    /// RAB: report from a field monitor (element transponder).
    pub rab: Option<bool>,
    /// SPI: special position identification.
    pub spi: Option<bool>,
    /// CHN: chain 2.
    pub chain_2: Option<bool>,
    /// GBS: the transponder's ground bit is set.
    pub ground_bit: Option<bool>,
    /// CRT: corrupted replies in the multilateration.
    pub corrupted: Option<bool>,
    /// SIM: simulated target report.
    pub simulated: Option<bool>,
    /// TST: test target.
    pub test: Option<bool>,
    /// CF (second extension): 0 ADS-B with an ICAO address, 1 ADS-B with
    /// another address, 2 non-ADS-B message, 3 not available.
    pub cf: Option<u8>,
}

/// I020/500 position accuracy; each subfield `None` when absent.
///
/// The third element of DOP and of SDP is kept as sent (`*_xy_raw`): the
/// definitions disagree on it. asterix-specs (1.10, 1.11) has an unsigned
/// quantity of LSB 0.25 without unit, and its note on the REF item's
/// accuracy calls I020/500's term a correlation (the REF replaced it by a
/// covariance); other decoders (SDDL) read a two's complement
/// "correlation coefficient, LSB 0.25". A coefficient in steps of 0.25 is
/// of little use either way, so [`MlatReport::position_sigma_m`] gives σx
/// and σy only and no cross term.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PositionAccuracy {
    /// DOP subfield.
    pub dop: Option<Dop>,
    /// SDP subfield: standard deviations of the position.
    pub sdp: Option<Sdp>,
    /// SDH subfield: standard deviation of the geometric height (m, LSB
    /// 0.5 m).
    pub sigma_height_m: Option<f64>,
}

/// I020/500 subfield 1: dilution of precision (dimensionless).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Dop {
    /// DOP of x (LSB 0.25).
    pub x: f64,
    /// DOP of y (LSB 0.25).
    pub y: f64,
    /// The xy element as sent (see [`PositionAccuracy`]).
    pub xy_raw: u16,
}

/// I020/500 subfield 2: standard deviation of the position, in the
/// system's Cartesian axes (x east, y north at its reference point).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sdp {
    /// σ of x (m, LSB 0.25 m).
    pub sigma_x_m: f64,
    /// σ of y (m, LSB 0.25 m).
    pub sigma_y_m: f64,
    /// The xy element as sent (see [`PositionAccuracy`]).
    pub xy_raw: u16,
}

/// I020/500: DOP (3 × 2 bytes), SDP (3 × 2 bytes), SDH (2 bytes).
const I020_500: &[Option<Len>] = &[
    Some(Len::Fixed(6)),
    Some(Len::Fixed(6)),
    Some(Len::Fixed(2)),
];

/// CAT020 UAP, FRN 1..=28 (index 0 is FRN 1).
const UAP_020: [Option<Item>; 28] = {
    use Len::{Compound, Explicit, Extended, Fixed, Repetitive};
    [
        item("I020/010", Fixed(2)),
        item("I020/020", Extended),
        item("I020/140", Fixed(3)),
        item("I020/041", Fixed(8)),
        item("I020/042", Fixed(6)),
        item("I020/161", Fixed(2)),
        item("I020/170", Extended),
        item("I020/070", Fixed(2)),
        item("I020/202", Fixed(4)),
        item("I020/090", Fixed(2)),
        item("I020/100", Fixed(4)),
        item("I020/220", Fixed(3)),
        item("I020/245", Fixed(7)),
        item("I020/110", Fixed(2)),
        item("I020/105", Fixed(2)),
        item("I020/210", Fixed(2)),
        item("I020/300", Fixed(1)),
        item("I020/310", Fixed(1)),
        item("I020/500", Compound(I020_500)),
        // REP × one octet of receiver contribution bits.
        item("I020/400", Repetitive(1)),
        // REP × 8 bytes (BDS data 56 bits, BDS1, BDS2).
        item("I020/250", Repetitive(8)),
        item("I020/230", Fixed(2)),
        item("I020/260", Fixed(7)),
        // Repetitive with FX: one-octet parts while FX is set.
        item("I020/030", Extended),
        item("I020/055", Fixed(1)),
        item("I020/050", Fixed(2)),
        item("I020/RE", Explicit),
        item("I020/SP", Explicit),
    ]
};

/// LSB of I020/041 (degrees).
const LSB_041: f64 = 180.0 / (1u64 << 25) as f64;

fn descriptor(v: &[u8]) -> MlatDescriptor {
    let bit = |octet: usize, mask: u8| v.get(octet).map(|b| b & mask != 0);
    MlatDescriptor {
        ssr: v[0] & 0x80 != 0,
        mode_s: v[0] & 0x40 != 0,
        hf: v[0] & 0x20 != 0,
        vdl4: v[0] & 0x10 != 0,
        uat: v[0] & 0x08 != 0,
        dme: v[0] & 0x04 != 0,
        other: v[0] & 0x02 != 0,
        rab: bit(1, 0x80),
        spi: bit(1, 0x40),
        chain_2: bit(1, 0x20),
        ground_bit: bit(1, 0x10),
        corrupted: bit(1, 0x08),
        simulated: bit(1, 0x04),
        test: bit(1, 0x02),
        cf: v.get(2).map(|b| b >> 6),
    }
}

fn accuracy(v: &[u8]) -> PositionAccuracy {
    let mut a = PositionAccuracy::default();
    each_subfield(I020_500, v, |i, s| match i {
        0 => {
            a.dop = Some(Dop {
                x: u16_at(s, 0) as f64 / 4.0,
                y: u16_at(s, 2) as f64 / 4.0,
                xy_raw: u16_at(s, 4),
            })
        }
        1 => {
            a.sdp = Some(Sdp {
                sigma_x_m: u16_at(s, 0) as f64 / 4.0,
                sigma_y_m: u16_at(s, 2) as f64 / 4.0,
                xy_raw: u16_at(s, 4),
            })
        }
        _ => a.sigma_height_m = Some(u16_at(s, 0) as f64 / 2.0),
    });
    a
}

impl Category for MlatReport {
    const CAT: u8 = CAT_MLAT;
    const UAP: &'static [Option<Item>] = &UAP_020;

    fn read(&mut self, frn: usize, v: &[u8]) {
        let r = self;
        match frn {
            1 => r.source = Some((v[0], v[1])),
            2 => r.descriptor = Some(descriptor(v)),
            3 => r.time_of_day_s = Some(time_of_day(v, 0)),
            4 => {
                let lat = u32_at(v, 0) as i32 as f64 * LSB_041;
                let lon = u32_at(v, 4) as i32 as f64 * LSB_041;
                r.position_deg = Some((lat, lon));
            }
            5 => {
                let x = signed(u24_at(v, 0), 24) as f64 / 2.0;
                let y = signed(u24_at(v, 3), 24) as f64 / 2.0;
                r.position_xy_m = Some((x, y));
            }
            6 => r.track_number = Some(u16_at(v, 0) & 0x0FFF),
            8 => {
                r.mode_3a = Some(u16_at(v, 0) & 0x0FFF);
                r.mode_3a_flags = Some(ReplyFlags::of(u16_at(v, 0), true));
            }
            9 => {
                let vx = u16_at(v, 0) as i16 as f64 / 4.0;
                let vy = u16_at(v, 2) as i16 as f64 / 4.0;
                r.velocity_xy_mps = Some((vx, vy));
            }
            10 => {
                r.flight_level = Some(signed(u16_at(v, 0) as u32, 14) as f64 / 4.0);
                r.flight_level_flags = Some(ReplyFlags::of(u16_at(v, 0), false));
            }
            12 => r.address = Some(u24_at(v, 0)),
            13 => {
                r.callsign_source = Some(v[0] >> 6);
                r.callsign = callsign(&v[1..]);
            }
            15 => r.geometric_height_m = Some(u16_at(v, 0) as i16 as f64 * 6.25 * FT_M),
            19 => r.accuracy = Some(accuracy(v)),
            _ => {}
        }
    }

    fn store(mut self, offset: usize, out: &mut Decoded) {
        self.offset = offset;
        out.mlat_reports.push(self);
    }
}

/// CAT020 as a tracker reads it: time of applicability I020/140;
/// position I020/041 (`None` with only the Cartesian I020/042); height
/// I020/105; velocity I020/202 (the system's x, y taken as east, north:
/// exact at its reference point, turned away from it by the meridian
/// convergence Δλ·sin φ, 0.09° 10 km east of a reference at 45° N); σ of
/// the position I020/500's SDP (σx, σy), in the same axes.
impl CooperativeReport for MlatReport {
    fn offset(&self) -> usize {
        self.offset
    }

    fn source(&self) -> Option<(u8, u8)> {
        self.source
    }

    fn time_of_applicability_s(&self) -> Option<f64> {
        self.time_of_day_s
    }

    fn lat_lon_deg(&self) -> Option<(f64, f64)> {
        self.position_deg
    }

    fn geometric_height_m(&self) -> Option<f64> {
        self.geometric_height_m
    }

    fn flight_level(&self) -> Option<f64> {
        self.flight_level
    }

    fn velocity_en_mps(&self) -> Option<(f64, f64)> {
        self.velocity_xy_mps
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
        let s = self.accuracy?.sdp?;
        Some((s.sigma_x_m, s.sigma_y_m))
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

    #[test]
    fn position_velocity_height_and_accuracy_decode_with_their_signs() {
        // FSPEC 0x19 0x41 0x88: FRN 4 (I020/041), 5 (/042), FX; 9 (/202),
        // FX; 15 (/105), 19 (/500).
        // 041: lat 0x00800000 = 2²³ × 180/2²⁵ = 45°, lon 0xFF800000 = −45°.
        // 042: x 0xFFFFFE = −2 × 0.5 = −1 m, y 0x000003 = 1.5 m.
        // 202: vx 0xFFFC = −4 × 0.25 = −1 m/s, vy 0x0008 = 2 m/s.
        // 105: 0xFFF0 = −16 × 6.25 ft = −100 ft = −30.48 m.
        // 500: primary 0xE0 (DOP, SDP, SDH); DOP x 8/4 = 2, y 12/4 = 3,
        // xy raw 1; SDP σx 20/4 = 5 m, σy 40/4 = 10 m, xy raw 2; SDH 7/2 =
        // 3.5 m.
        let rec = [
            0x19, 0x41, 0x88, // FSPEC
            0x00, 0x80, 0x00, 0x00, 0xFF, 0x80, 0x00, 0x00, // 041
            0xFF, 0xFF, 0xFE, 0x00, 0x00, 0x03, // 042
            0xFF, 0xFC, 0x00, 0x08, // 202
            0xFF, 0xF0, // 105
            0xE0, 0, 8, 0, 12, 0, 1, 0, 20, 0, 40, 0, 2, 0, 7, // 500
        ];
        let d = decode(&block(20, &rec));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let r = &d.mlat_reports[0];
        assert_eq!(r.position_deg, Some((45.0, -45.0)));
        assert_eq!(r.position_xy_m, Some((-1.0, 1.5)));
        assert_eq!(r.velocity_en_mps(), Some((-1.0, 2.0)));
        assert_eq!(r.geometric_height_m, Some(-100.0 * 0.3048));
        let a = r.accuracy.unwrap();
        let dop = a.dop.unwrap();
        assert_eq!((dop.x, dop.y, dop.xy_raw), (2.0, 3.0, 1));
        let sdp = a.sdp.unwrap();
        assert_eq!((sdp.sigma_x_m, sdp.sigma_y_m, sdp.xy_raw), (5.0, 10.0, 2));
        assert_eq!(a.sigma_height_m, Some(3.5));
        assert_eq!(r.position_sigma_m(), Some((5.0, 10.0)));
    }

    #[test]
    fn accuracy_subfields_are_found_whichever_are_present() {
        // FRN 19 alone: FSPEC 0x01 0x01 0x08. 500 primary 0x20: SDH only,
        // 0x0010 = 16 × 0.5 = 8 m; no SDP, so no σ of the position.
        let d = decode(&block(20, &[0x01, 0x01, 0x08, 0x20, 0x00, 0x10]));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let r = &d.mlat_reports[0];
        let a = r.accuracy.unwrap();
        assert_eq!((a.dop, a.sdp, a.sigma_height_m), (None, None, Some(8.0)));
        assert_eq!(r.position_sigma_m(), None);
        // SDP only (0x40): σx 0x0001 = 0.25 m, σy 0xFFFF = 16,383.75 m.
        let d = decode(&block(
            20,
            &[0x01, 0x01, 0x08, 0x40, 0x00, 0x01, 0xFF, 0xFF, 0x80, 0x00],
        ));
        let r = &d.mlat_reports[0];
        assert_eq!(r.position_sigma_m(), Some((0.25, 16_383.75)));
        assert_eq!(r.accuracy.unwrap().sdp.unwrap().xy_raw, 0x8000);
        // A spare flag of the primary (0x10, a fourth subfield) is an
        // error.
        let d = decode(&block(20, &[0x01, 0x01, 0x08, 0x10, 0, 0]));
        assert!(d.errors[0].reason.contains("I020/500"), "{:?}", d.errors);
    }

    #[test]
    fn descriptor_and_identification() {
        // FSPEC 0x41 0x04: FRN 2 (I020/020), FX; FRN 13 (/245).
        // 020 0x41 0x07 0xC0: MS, FX; SIM, TST, FX; CF 3.
        // 245: STI 1 (0x40), "EZY1" + 4 spaces.
        let rec = [
            0x41, 0x04, 0x41, 0x07, 0xC0, 0x40, 0x15, 0xA6, 0x71, 0x82, 0x08, 0x20,
        ];
        let d = decode(&block(20, &rec));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let r = &d.mlat_reports[0];
        let x = r.descriptor.unwrap();
        assert!(x.mode_s && !x.ssr && !x.other);
        assert_eq!(
            (x.simulated, x.test, x.spi, x.cf),
            (Some(true), Some(true), Some(false), Some(3))
        );
        assert!(r.simulated_or_test());
        assert_eq!(r.callsign(), Some("EZY1"));
        assert_eq!(r.callsign_source, Some(1));
    }
}
