//! CAT048 monoradar target reports, UAP of edition 1.32 (EUROCONTROL
//! ASTERIX Part 4), as libasterix's generated definitions give it.
//!
//! Items decoded: I048/010 SAC/SIC, /140 time of day (1/128 s), /020
//! target report descriptor (TYP, SIM, RDP, SPI, RAB; TST of the first
//! extension), /040 measured position (RHO 1/256 NM, THETA 360/2¹⁶ °),
//! /070 Mode 3/A with V, G, L, /090 flight level (V, G; 1/4 FL, two's
//! complement), /240 aircraft identification (8 × 6-bit ICAO), /110 3D
//! height (25 ft, two's complement), /120 calculated Doppler speed (D,
//! CAL: 10-bit two's complement, 1 m/s), /220 aircraft address, /161
//! track number. Every other item of the UAP is skipped by its rule.

use super::fields::{ReplyFlags, callsign, signed, time_of_day, u16_at, u24_at};
use super::uap::{Item, Len, each_subfield, item};
use super::{CAT_TARGET_REPORTS, Category, Decoded, FT_M, NM_M};

/// I048/020, the parts the tracker looks at.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Descriptor {
    /// 0 no detection, 1 single PSR, 2 single SSR, 3 SSR + PSR, 4 Mode S
    /// all-call, 5 Mode S roll-call, 6 all-call + PSR, 7 roll-call + PSR.
    pub typ: u8,
    /// Simulated target report.
    pub sim: bool,
    /// RDP chain 2.
    pub rdp: bool,
    /// Special position identification.
    pub spi: bool,
    /// Report from a field monitor (fixed transponder).
    pub rab: bool,
    /// Test target (first extension; `None` when absent).
    pub tst: Option<bool>,
}

/// A CAT048 record: a monoradar target report.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TargetReport {
    /// Offset of the record (its FSPEC) in the data.
    pub offset: usize,
    /// I048/010 (SAC, SIC).
    pub source: Option<(u8, u8)>,
    /// I048/140, seconds since midnight UTC.
    pub time_of_day_s: Option<f64>,
    pub descriptor: Option<Descriptor>,
    /// I048/040 RHO, slant range (m).
    pub range_m: Option<f64>,
    /// I048/040 THETA, clockwise from north (degrees, [0, 360)).
    pub azimuth_deg: Option<f64>,
    /// I048/070 Mode 3/A code, 12 bits (four octal digits).
    pub mode_3a: Option<u16>,
    /// I048/070 V, G (and L) of the code.
    pub mode_3a_flags: Option<ReplyFlags>,
    /// I048/090 flight level (FL, 1/4 resolution).
    pub flight_level: Option<f64>,
    /// I048/090 V and G of the flight level (`smoothed` unused).
    pub flight_level_flags: Option<ReplyFlags>,
    /// I048/240 aircraft identification (callsign), trailing spaces
    /// removed.
    pub callsign: Option<String>,
    /// I048/110 height measured by a 3D radar (m).
    pub height_m: Option<f64>,
    /// I048/120 subfield 1 (CAL), calculated Doppler speed (m/s).
    pub doppler_mps: Option<f64>,
    /// I048/120 subfield 1, D: the Doppler speed is doubtful.
    pub doppler_doubtful: bool,
    /// I048/220 Mode S address (24 bits).
    pub aircraft_address: Option<u32>,
    /// I048/161 track number (12 bits).
    pub track_number: Option<u16>,
}

/// I048/120: CAL (2 bytes), RDS (REP × DOP, AMB, FRQ: 6 bytes).
const I048_120: &[Option<Len>] = &[Some(Len::Fixed(2)), Some(Len::Repetitive(6))];

/// CAT048 UAP, FRN 1..=28 (index 0 is FRN 1).
const UAP_048: [Option<Item>; 28] = {
    use Len::{Compound, Explicit, Extended, Fixed, Repetitive};
    [
        item("I048/010", Fixed(2)),
        item("I048/140", Fixed(3)),
        item("I048/020", Extended),
        item("I048/040", Fixed(4)),
        item("I048/070", Fixed(2)),
        item("I048/090", Fixed(2)),
        // SRL, SRR, SAM, PRL, PAM, RPD, APD: one octet each.
        item("I048/130", Compound(&[Some(Fixed(1)); 7])),
        item("I048/220", Fixed(3)),
        item("I048/240", Fixed(6)),
        // REP × (MB data 7 bytes + BDS1/BDS2 1 byte).
        item("I048/250", Repetitive(8)),
        item("I048/161", Fixed(2)),
        item("I048/042", Fixed(4)),
        item("I048/200", Fixed(4)),
        item("I048/170", Extended),
        item("I048/210", Fixed(4)),
        item("I048/030", Extended),
        item("I048/080", Fixed(2)),
        item("I048/100", Fixed(4)),
        item("I048/110", Fixed(2)),
        item("I048/120", Compound(I048_120)),
        item("I048/230", Fixed(2)),
        item("I048/260", Fixed(7)),
        item("I048/055", Fixed(1)),
        item("I048/050", Fixed(2)),
        item("I048/065", Fixed(1)),
        item("I048/060", Fixed(2)),
        item("I048/SP", Explicit),
        item("I048/RE", Explicit),
    ]
};

impl Category for TargetReport {
    const CAT: u8 = CAT_TARGET_REPORTS;
    const UAP: &'static [Option<Item>] = &UAP_048;

    fn read(&mut self, frn: usize, v: &[u8]) {
        let t = self;
        match frn {
            1 => t.source = Some((v[0], v[1])),
            2 => t.time_of_day_s = Some(time_of_day(v, 0)),
            3 => {
                let b = v[0];
                t.descriptor = Some(Descriptor {
                    typ: b >> 5,
                    sim: b & 0x10 != 0,
                    rdp: b & 0x08 != 0,
                    spi: b & 0x04 != 0,
                    rab: b & 0x02 != 0,
                    tst: v.get(1).map(|e| e & 0x80 != 0),
                });
            }
            4 => {
                t.range_m = Some(u16_at(v, 0) as f64 / 256.0 * NM_M);
                t.azimuth_deg = Some(u16_at(v, 2) as f64 * (360.0 / 65536.0));
            }
            5 => {
                t.mode_3a = Some(u16_at(v, 0) & 0x0FFF);
                t.mode_3a_flags = Some(ReplyFlags::of(u16_at(v, 0), true));
            }
            6 => {
                t.flight_level = Some(signed(u16_at(v, 0) as u32, 14) as f64 / 4.0);
                t.flight_level_flags = Some(ReplyFlags::of(u16_at(v, 0), false));
            }
            8 => t.aircraft_address = Some(u24_at(v, 0)),
            9 => t.callsign = callsign(v),
            11 => t.track_number = Some(u16_at(v, 0) & 0x0FFF),
            19 => t.height_m = Some(signed(u16_at(v, 0) as u32, 14) as f64 * 25.0 * FT_M),
            20 => each_subfield(I048_120, v, |i, cal| {
                if i == 0 {
                    let cal = u16_at(cal, 0);
                    t.doppler_doubtful = cal & 0x8000 != 0;
                    t.doppler_mps = Some(signed(cal as u32, 10) as f64);
                }
            }),
            _ => {}
        }
    }

    fn store(mut self, offset: usize, out: &mut Decoded) {
        self.offset = offset;
        out.target_reports.push(self);
    }
}

#[cfg(test)]
mod tests {
    use super::super::decode;
    use super::super::tests::block;

    #[test]
    fn a_hand_encoded_target_report_decodes_to_its_values() {
        // FSPEC 0xF1 0x04: FRN 1-4 (010, 140, 020, 040) and FX; in the
        // second octet bit 3 is FRN 13 (I048/200, 4 bytes), FX clear.
        // Hand values: SAC 7, SIC 9; time 0x3F_FF_80 / 128 = 32767 s;
        // 020 0x40 = TYP 2, no FX; RHO 0x1000 = 16 NM = 29,632 m; THETA
        // 0x4000 = 90°; I048/200 4 bytes skipped.
        let rec = [
            0xF1, 0x04, 7, 9, 0x3F, 0xFF, 0x80, 0x40, 0x10, 0x00, 0x40, 0x00, 1, 2, 3, 4,
        ];
        let d = decode(&block(48, &rec));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let t = &d.target_reports[0];
        assert_eq!(t.offset, 3);
        assert_eq!(t.source, Some((7, 9)));
        assert_eq!(t.time_of_day_s, Some(32767.0));
        assert_eq!(t.descriptor.unwrap().typ, 2);
        assert_eq!(t.descriptor.unwrap().tst, None);
        assert_eq!(t.range_m, Some(16.0 * 1852.0));
        assert_eq!(t.azimuth_deg, Some(90.0));
    }

    #[test]
    fn secondary_items_decode_with_their_flags() {
        // FSPEC 0x0D 0xC0: octet 1 bits 4 and 3 are FRN 5 (070) and 6
        // (090), bit 1 FX; octet 2 bits 8 and 7 are FRN 8 (220) and 9
        // (240), FX clear.
        // I048/070 0xE1FF: V = 1 (not validated), G = 1, L = 1, code
        // 0x1FF = octal 0777. I048/090 0x4578: V = 0, G = 1, FL bits
        // 0x0578 = 1400 quarter-FL = FL 350. I048/220 0x4CA2D1.
        // I048/240 "EZY1" + 4 spaces: E = 5, Z = 26, Y = 25, '1' = 49,
        // ' ' = 32: bits 000101 011010 011001 110001 100000 ×4, in
        // octets 00010101 10100110 01110001 10000010 00001000 00100000 =
        // 0x15 0xA6 0x71 0x82 0x08 0x20.
        let rec = [
            0x0D, 0xC0, 0xE1, 0xFF, 0x45, 0x78, 0x4C, 0xA2, 0xD1, 0x15, 0xA6, 0x71, 0x82, 0x08,
            0x20,
        ];
        let d = decode(&block(48, &rec));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let t = &d.target_reports[0];
        assert_eq!(t.mode_3a, Some(0o777));
        let f = t.mode_3a_flags.unwrap();
        assert!(!f.validated && f.garbled && f.smoothed);
        assert_eq!(t.flight_level, Some(350.0));
        let f = t.flight_level_flags.unwrap();
        assert!(f.validated && f.garbled && !f.smoothed);
        assert_eq!(t.aircraft_address, Some(0x4CA2D1));
        assert_eq!(t.callsign.as_deref(), Some("EZY1"));
    }

    #[test]
    fn signed_fields_are_twos_complement() {
        // FSPEC: octet 1 0x01 (FX), octet 2 0x01 (FX), octet 3 0x0C: FRN
        // 19 (bit 4) and 20 (bit 3). I048/110 0x3FFF = −1 × 25 ft; I048/120
        // primary 0x80 (CAL), CAL 0x83FF: D = 1, 10-bit 0x3FF = −1 m/s.
        let rec = [0x01, 0x01, 0x0C, 0x3F, 0xFF, 0x80, 0x83, 0xFF];
        let d = decode(&block(48, &rec));
        assert!(d.errors.is_empty(), "{:?}", d.errors);
        let t = &d.target_reports[0];
        assert_eq!(t.height_m, Some(-25.0 * 0.3048));
        assert_eq!(t.doppler_mps, Some(-1.0));
        assert!(t.doppler_doubtful);
    }
}
