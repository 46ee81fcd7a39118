//! A CAT048 encoder for load tests and simulations: monoradar target
//! reports of a 2D primary radar as EUROCONTROL ASTERIX data blocks, the
//! bytes a radar multicasts (`examples/asterix_load.rs` sends them to the
//! service's UDP listener).
//!
//! A data block is `CAT = 48 | LEN (2 bytes, big-endian, the whole block)
//! | records`. Every record flags FRN 1–4 of the CAT048 edition 1.32 UAP in
//! a one-octet FSPEC (`0xF0`: bits 8, 7, 6, 5; FX clear) and carries, in
//! that order:
//!
//! - I048/010 data source identifier: SAC, SIC (1 byte each);
//! - I048/140 time of day: seconds since midnight UTC in units of 1/128 s,
//!   3 bytes unsigned;
//! - I048/020 target report descriptor, one octet: TYP = 001 (single PSR
//!   detection) in bits 8–6, SIM, RDP, SPI, RAB clear, FX clear (`0x20`);
//! - I048/040 measured position in polar coordinates: RHO in 1/256 NM
//!   (2 bytes, at most 65,535: just under 256 NM) and THETA in 360/2¹⁶
//!   degrees clockwise from north (2 bytes).
//!
//! So a record is 11 bytes, and a block of at most `max` bytes holds
//! ⌊(max − 3)/11⌋ records: 127 in 1,400 bytes (3 + 127·11 = 1,400).
//! Values are rounded to the nearest unit of their item; a value an item
//! cannot hold (a range beyond 256 NM, a time of day outside a day) is an
//! [`EncodeError`], never a wrapped or saturated field.
//!
//! The decoder this is tested against is `wire_formats::asterix::decode` (itself
//! checked against libasterix's encoder, `checks/asterix_fixture.py`); the
//! expected bytes of one record are also worked out by hand in the tests.

/// The category of monoradar target reports.
pub const CATEGORY: u8 = 48;
/// Bytes of a data block's header (CAT, LEN).
pub const HEADER_BYTES: usize = 3;
/// Bytes of one record: FSPEC 1, I048/010 2, /140 3, /020 1, /040 4.
pub const RECORD_BYTES: usize = 11;
/// The default largest block: one per datagram, well inside a 1,500-byte
/// Ethernet MTU.
pub const DEFAULT_MAX_BLOCK_BYTES: usize = 1400;
/// Seconds in a day: I048/140 counts from midnight.
pub const DAY_S: f64 = 86_400.0;

/// One nautical mile in metres (exact).
const NM_M: f64 = 1852.0;
/// FRN 1, 2, 3, 4 flagged, FX clear.
const FSPEC: u8 = 0b1111_0000;
/// I048/020: TYP = 1 (single PSR detection), every flag clear, FX clear.
const DESCRIPTOR_SINGLE_PSR: u8 = 0b0010_0000;
/// Most records in one block: LEN is 16 bits.
const MAX_RECORDS_PER_BLOCK: usize = (u16::MAX as usize - HEADER_BYTES) / RECORD_BYTES;

/// A target report of a 2D primary radar.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Report {
    /// I048/010 system area code.
    pub sac: u8,
    /// I048/010 system identification code.
    pub sic: u8,
    /// I048/140: seconds since midnight UTC, in [0, 86,400).
    pub time_of_day_s: f64,
    /// I048/040 RHO: slant range (m), 0 to just under 256 NM.
    pub range_m: f64,
    /// I048/040 THETA: azimuth clockwise from north (degrees, any finite
    /// value; taken modulo 360).
    pub azimuth_deg: f64,
}

/// A value that the record's items cannot hold.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum EncodeError {
    /// I048/140 holds a time of day in [0, 86,400) s.
    #[error("time of day {0} s is not in [0, 86400): I048/140 counts from midnight")]
    TimeOfDay(f64),
    /// I048/040's RHO holds 0 to 65,535/256 NM.
    #[error("range {0} m is outside I048/040 RHO (0 to 65535/256 NM)")]
    Range(f64),
    /// The azimuth is NaN or infinite.
    #[error("azimuth {0}° is not finite")]
    Azimuth(f64),
    /// A block limit too small for its header and one record.
    #[error("a data block of at most {0} bytes cannot hold one record (3 + 11 bytes)")]
    BlockTooSmall(usize),
}

/// The time of day (s since midnight, in [0, 86,400)) of a time `t` on a
/// scale whose day starts are multiples of 86,400 s (Unix time).
pub fn time_of_day(t: f64) -> f64 {
    t.rem_euclid(DAY_S)
}

/// Records of at most `max_block_bytes` per block.
pub fn records_per_block(max_block_bytes: usize) -> usize {
    (max_block_bytes.saturating_sub(HEADER_BYTES) / RECORD_BYTES).min(MAX_RECORDS_PER_BLOCK)
}

/// The 11 bytes of one record.
pub fn record(r: &Report) -> Result<[u8; RECORD_BYTES], EncodeError> {
    if !(r.time_of_day_s.is_finite() && (0.0..DAY_S).contains(&r.time_of_day_s)) {
        return Err(EncodeError::TimeOfDay(r.time_of_day_s));
    }
    // A time just under midnight rounds to 86,400 s: 00:00:00 of the next day.
    let day_units = (DAY_S * 128.0) as u32;
    let tod = ((r.time_of_day_s * 128.0).round() as u32) % day_units;
    let rho = (r.range_m / NM_M * 256.0).round();
    if !(rho.is_finite() && (0.0..=f64::from(u16::MAX)).contains(&rho) && r.range_m >= 0.0) {
        return Err(EncodeError::Range(r.range_m));
    }
    if !r.azimuth_deg.is_finite() {
        return Err(EncodeError::Azimuth(r.azimuth_deg));
    }
    // 359.999…° rounds to 2¹⁶: north again.
    let theta =
        ((r.azimuth_deg.rem_euclid(360.0) / 360.0 * 65_536.0).round() as u32 % 65_536) as u16;
    let rho = rho as u16;
    let [_, t1, t2, t3] = tod.to_be_bytes();
    let [r1, r2] = rho.to_be_bytes();
    let [a1, a2] = theta.to_be_bytes();
    Ok([
        FSPEC,
        r.sac,
        r.sic,
        t1,
        t2,
        t3,
        DESCRIPTOR_SINGLE_PSR,
        r1,
        r2,
        a1,
        a2,
    ])
}

/// One data block holding `reports` (at most 5,957 of them: LEN is 16
/// bits; more is the error of a block too small for them).
pub fn block(reports: &[Report]) -> Result<Vec<u8>, EncodeError> {
    if reports.len() > MAX_RECORDS_PER_BLOCK {
        return Err(EncodeError::BlockTooSmall(u16::MAX as usize));
    }
    let len = HEADER_BYTES + RECORD_BYTES * reports.len();
    let mut out = Vec::with_capacity(len);
    out.push(CATEGORY);
    out.extend_from_slice(&(len as u16).to_be_bytes());
    for r in reports {
        out.extend_from_slice(&record(r)?);
    }
    Ok(out)
}

/// `reports` as consecutive data blocks of at most `max_block_bytes` each,
/// split at record boundaries (every block full but the last).
pub fn blocks(reports: &[Report], max_block_bytes: usize) -> Result<Vec<Vec<u8>>, EncodeError> {
    let per_block = records_per_block(max_block_bytes);
    if per_block == 0 {
        return Err(EncodeError::BlockTooSmall(max_block_bytes));
    }
    reports.chunks(per_block).map(block).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;
    use wire_formats::asterix;

    fn report(time_of_day_s: f64, range_m: f64, azimuth_deg: f64) -> Report {
        Report {
            sac: 25,
            sic: 1,
            time_of_day_s,
            range_m,
            azimuth_deg,
        }
    }

    #[test]
    fn a_record_is_the_bytes_worked_out_by_hand() {
        // SAC 25 = 0x19, SIC 1.
        // 12:34:56.5 = 45,296.5 s; × 128 = 5,797,952 = 88·65,536 + 30,784
        //   = 0x58_7840.
        // 50,000 m = 26.9978… NM; × 256 = 6,911.447 → 6,911 = 0x1AFF.
        // −30° = 330°; 330/360 · 65,536 = 60,074.67 → 60,075 = 0xEAAB.
        // FSPEC FRN 1–4 = 0xF0; I048/020 TYP 1 (single PSR) = 0x20.
        // LEN = 3 + 11 = 14 = 0x000E.
        let r = report(45_296.5, 50_000.0, -30.0);
        assert_eq!(
            record(&r).unwrap(),
            [
                0xF0, 0x19, 0x01, 0x58, 0x78, 0x40, 0x20, 0x1A, 0xFF, 0xEA, 0xAB
            ]
        );
        assert_eq!(
            block(&[r]).unwrap(),
            vec![
                0x30, 0x00, 0x0E, 0xF0, 0x19, 0x01, 0x58, 0x78, 0x40, 0x20, 0x1A, 0xFF, 0xEA, 0xAB
            ]
        );
    }

    #[test]
    fn records_round_trip_through_the_decoder_to_their_resolutions() {
        let mut rng = crate::montecarlo::run_rng(48, 0);
        let reports: Vec<Report> = (0..2_000)
            .map(|i| Report {
                sac: rng.random_range(0..=255),
                sic: rng.random_range(0..=255),
                time_of_day_s: if i == 0 {
                    DAY_S - 1e-4
                } else {
                    rng.random_range(0.0..DAY_S)
                },
                range_m: if i == 1 {
                    65_535.0 / 256.0 * 1852.0
                } else {
                    rng.random_range(0.0..470_000.0)
                },
                azimuth_deg: if i == 2 {
                    359.9999
                } else {
                    rng.random_range(-720.0..720.0)
                },
            })
            .collect();
        let data: Vec<u8> = blocks(&reports, DEFAULT_MAX_BLOCK_BYTES).unwrap().concat();
        let decoded = asterix::decode(&data);
        assert!(decoded.errors.is_empty(), "{:?}", decoded.errors);
        assert_eq!(decoded.target_reports.len(), reports.len());
        for (r, d) in reports.iter().zip(&decoded.target_reports) {
            assert_eq!(d.source, Some((r.sac, r.sic)));
            // Half a unit of each item: 1/256 s, 1852/512 m, 360/2¹⁷ °,
            // times and azimuths compared modulo a day and a turn.
            let dt = (d.time_of_day_s.unwrap() - r.time_of_day_s).abs();
            assert!(dt.min(DAY_S - dt) <= 1.0 / 256.0 + 1e-9, "{r:?} {d:?}");
            assert!(
                (d.range_m.unwrap() - r.range_m).abs() <= 1852.0 / 512.0 + 1e-9,
                "{r:?} {d:?}"
            );
            let da = (d.azimuth_deg.unwrap() - r.azimuth_deg).rem_euclid(360.0);
            assert!(
                da.min(360.0 - da) <= 360.0 / 131_072.0 + 1e-9,
                "{r:?} {d:?}"
            );
            let descriptor = d.descriptor.unwrap();
            assert_eq!(descriptor.typ, 1);
            assert!(!descriptor.sim && !descriptor.rdp && !descriptor.spi && !descriptor.rab);
            assert_eq!(descriptor.tst, None);
            assert_eq!(d.height_m, None);
            assert_eq!(d.doppler_mps, None);
        }
        // The edges: just before midnight is midnight, just below 360° north.
        assert_eq!(decoded.target_reports[0].time_of_day_s, Some(0.0));
        assert_eq!(
            decoded.target_reports[1].range_m,
            Some(65_535.0 / 256.0 * 1852.0)
        );
        assert_eq!(decoded.target_reports[2].azimuth_deg, Some(0.0));
    }

    #[test]
    fn blocks_split_at_records_and_fit_their_limit() {
        // 1,400 bytes hold (1,400 − 3)/11 = 127 records exactly; 300
        // reports are blocks of 127, 127 and 46 (3 + 46·11 = 509 bytes).
        assert_eq!(records_per_block(1400), 127);
        let reports: Vec<Report> = (0..300)
            .map(|i| report(i as f64, 1000.0 * i as f64, i as f64))
            .collect();
        let out = blocks(&reports, 1400).unwrap();
        let lens: Vec<usize> = out.iter().map(Vec::len).collect();
        assert_eq!(lens, vec![1400, 1400, 509]);
        for b in &out {
            assert_eq!(b[0], CATEGORY);
            assert_eq!(usize::from(u16::from_be_bytes([b[1], b[2]])), b.len());
            let d = asterix::decode(b);
            assert!(d.errors.is_empty(), "{:?}", d.errors);
        }
        let all = asterix::decode(&out.concat());
        let times: Vec<f64> = all
            .target_reports
            .iter()
            .map(|t| t.time_of_day_s.unwrap())
            .collect();
        assert_eq!(times, (0..300).map(f64::from).collect::<Vec<_>>());
        // 14 bytes hold one record; 13 none.
        assert_eq!(blocks(&reports[..2], 14).unwrap().len(), 2);
        assert_eq!(blocks(&reports, 13), Err(EncodeError::BlockTooSmall(13)));
        assert_eq!(blocks(&[], 1400).unwrap(), Vec::<Vec<u8>>::new());
    }

    #[test]
    fn values_an_item_cannot_hold_are_errors() {
        // 256 NM = 474,112 m rounds to RHO 65,536: one unit too many.
        let beyond = 256.0 * 1852.0;
        assert_eq!(
            record(&report(0.0, beyond, 0.0)),
            Err(EncodeError::Range(beyond))
        );
        assert_eq!(
            record(&report(0.0, -1.0, 0.0)),
            Err(EncodeError::Range(-1.0))
        );
        assert_eq!(
            record(&report(DAY_S, 1.0, 0.0)),
            Err(EncodeError::TimeOfDay(DAY_S))
        );
        assert_eq!(
            record(&report(-0.5, 1.0, 0.0)),
            Err(EncodeError::TimeOfDay(-0.5))
        );
        assert!(matches!(
            record(&report(0.0, 1.0, f64::NAN)),
            Err(EncodeError::Azimuth(_))
        ));
        assert!(matches!(
            record(&report(f64::NAN, 1.0, 0.0)),
            Err(EncodeError::TimeOfDay(_))
        ));
    }

    #[test]
    fn times_of_day_count_from_unix_midnights() {
        // 2026-12-02 00:00:00 UTC is Unix day 20,789; an hour and a half
        // later is 5,400 s of its day, and 1 s before it 86,399 s.
        let midnight = 20_789.0 * DAY_S;
        assert_eq!(time_of_day(midnight + 5_400.0), 5_400.0);
        assert_eq!(time_of_day(midnight - 1.0), 86_399.0);
        assert_eq!(time_of_day(midnight), 0.0);
    }
}
