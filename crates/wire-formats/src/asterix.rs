//! EUROCONTROL ASTERIX input decoded from raw bytes, as sensors send them
//! (usually one or more data blocks per UDP datagram): CAT048 monoradar
//! target reports and CAT034 service messages (north markers, sector
//! crossings) of the radars, CAT021 ADS-B target reports and CAT020
//! multilateration target reports of the cooperative sensors.
//!
//! A data block is `CAT (1 byte) | LEN (2 bytes, big-endian, the whole
//! block) | records`; a record is an FSPEC and the items it flags, each of
//! a length given by the category's User Application Profile (UAP): one
//! walker (`asterix/uap.rs`) reads the records of every category by its
//! UAP, and a category only says how its items fill its record. Every item
//! of a UAP is skipped by its rule (fixed, extended, repetitive,
//! explicit, compound), so items we do not use cost nothing and never
//! desynchronise the record.
//!
//! Editions (UAPs and item layouts as libasterix's generated definitions,
//! from the `zoranbosnjak/asterix-specs` repository, give them):
//! - CAT048 1.32 and CAT034 1.29 ([`TargetReport`], [`ServiceMessage`]);
//! - CAT021 2.7 ([`cat021`], [`AdsbReport`]): the UAP and every item
//!   length are the same in editions 2.4 to 2.7, which therefore decode
//!   alike (2.7 adds octets to extended items, which 2.4 senders never
//!   set);
//! - CAT020 1.11 ([`cat020`], [`MlatReport`]): UAP and lengths as 1.10.
//!
//! Values are SI at this edge (1 NM = 1852 m, 1 ft = 0.3048 m, 1 kt =
//! 1852/3600 m/s, exactly), angles and WGS-84 coordinates in degrees as
//! the wire gives them. [`CooperativeReport`] is what a tracker takes
//! from either cooperative kind; [`quality`] turns the ADS-B quality
//! indicators into σ.
//!
//! Errors never stop the decoding of what is good: every one carries the
//! byte offset (from the start of the data) where it was found and a
//! reason. A bad record loses the rest of its block (a record has no
//! length: its end is only known by decoding it), and decoding resumes at
//! the next block by LEN. A block of another category is reported and
//! skipped by LEN. A LEN below 3 or beyond the data ends the decoding
//! there (the block boundary is lost).
//!
//! Checked against libasterix's encoder and decoder
//! (`checks/asterix_fixture.py`, `tests/api/asterix.rs` for CAT048/034;
//! `checks/cat021_fixture.py`, `crates/wire-formats/tests/cooperative_fixture.rs`
//! for CAT021/020). Why not the `asterix` crate: docs/plot-fusion.md,
//! "ASTERIX input".

pub mod cat020;
pub mod cat021;
mod cat034;
mod cat048;
mod fields;
pub mod quality;
mod uap;

pub use cat020::MlatReport;
pub use cat021::AdsbReport;
pub use cat034::ServiceMessage;
pub use cat048::{Descriptor, TargetReport};
pub use fields::ReplyFlags;

use uap::Item;

/// One nautical mile in metres (exact, by definition).
pub const NM_M: f64 = 1852.0;
/// One foot in metres (exact, by definition).
pub const FT_M: f64 = 0.3048;
/// One knot in metres per second (exact: 1852 m per 3600 s).
pub const KT_MPS: f64 = NM_M / 3600.0;

/// The categories this decoder reads.
pub const CAT_TARGET_REPORTS: u8 = 48;
pub const CAT_SERVICE_MESSAGES: u8 = 34;
pub const CAT_ADSB: u8 = 21;
pub const CAT_MLAT: u8 = 20;

/// I034/000 message types.
pub const NORTH_MARKER: u8 = 1;
pub const SECTOR_CROSSING: u8 = 2;

/// Everything decoded from a run of bytes; each list in data order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Decoded {
    /// Data blocks read (of any category, including skipped ones).
    pub blocks: usize,
    /// CAT048 records.
    pub target_reports: Vec<TargetReport>,
    /// CAT034 records.
    pub service_messages: Vec<ServiceMessage>,
    /// CAT021 records.
    pub adsb_reports: Vec<AdsbReport>,
    /// CAT020 records.
    pub mlat_reports: Vec<MlatReport>,
    pub errors: Vec<DecodeError>,
}

/// A problem in the data, where it was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeError {
    /// Byte offset from the start of the data.
    pub offset: usize,
    pub reason: String,
}

/// What a tracker takes from a cooperative report, ADS-B ([`AdsbReport`])
/// or multilateration ([`MlatReport`]): SI units, WGS-84 degrees, times
/// of day in seconds since midnight UTC. Each implementation says which
/// items it reads; `None` when the record lacks them.
pub trait CooperativeReport {
    /// Offset of the record (its FSPEC) in the data.
    fn offset(&self) -> usize;
    /// (SAC, SIC) of the ground station or system.
    fn source(&self) -> Option<(u8, u8)>;
    /// When the position is valid (s since midnight UTC).
    fn time_of_applicability_s(&self) -> Option<f64>;
    /// WGS-84 (latitude, longitude), degrees, north and east positive.
    fn lat_lon_deg(&self) -> Option<(f64, f64)>;
    /// Geometric height above the WGS-84 ellipsoid (m).
    fn geometric_height_m(&self) -> Option<f64>;
    /// Barometric flight level (FL: hundreds of feet of pressure
    /// altitude, not QNH-corrected).
    fn flight_level(&self) -> Option<f64>;
    /// Horizontal velocity over the ground (east, north), m/s.
    fn velocity_en_mps(&self) -> Option<(f64, f64)>;
    /// The 24-bit target address.
    fn address(&self) -> Option<u32>;
    /// The target identification, trailing spaces removed.
    fn callsign(&self) -> Option<&str>;
    /// The Mode 3/A code, 12 bits (four octal digits).
    fn mode_3a(&self) -> Option<u16>;
    /// 1σ of the horizontal position error per axis (east, north), m,
    /// as the report states it.
    fn position_sigma_m(&self) -> Option<(f64, f64)>;
    /// A simulated or test target (not for a tracker).
    fn simulated_or_test(&self) -> bool;
}

/// One category: its UAP, how its items fill its record, where its
/// records go.
trait Category: Default {
    const CAT: u8;
    /// FRN 1.. (index 0 is FRN 1), `None` a spare FRN.
    const UAP: &'static [Option<Item>];
    /// Fills in item `frn` from its bytes `v`, which have the length the
    /// UAP's rule gives (a fixed item its size, an extended one its
    /// octets up to FX = 0, …).
    fn read(&mut self, frn: usize, v: &[u8]);
    /// Keeps a decoded record found at `offset`.
    fn store(self, offset: usize, out: &mut Decoded);
}

/// Decodes every data block of `data`.
pub fn decode(data: &[u8]) -> Decoded {
    let mut out = Decoded::default();
    let mut pos = 0usize;
    while pos < data.len() {
        let left = data.len() - pos;
        if left < 3 {
            out.errors.push(DecodeError {
                offset: pos,
                reason: format!("{left} byte(s) left, too few for a data block header (3)"),
            });
            break;
        }
        let cat = data[pos];
        let len = u16::from_be_bytes([data[pos + 1], data[pos + 2]]) as usize;
        if len < 3 {
            out.errors.push(DecodeError {
                offset: pos,
                reason: format!(
                    "data block LEN {len} is below its own header (3 bytes): the rest of \
                     the data ({left} bytes) is skipped"
                ),
            });
            break;
        }
        if len > left {
            out.errors.push(DecodeError {
                offset: pos,
                reason: format!(
                    "data block (CAT {cat:03}) LEN {len} runs past the end of the data \
                     ({left} bytes left): the block is skipped"
                ),
            });
            break;
        }
        out.blocks += 1;
        let block = &data[pos..pos + len];
        match cat {
            CAT_TARGET_REPORTS => decode_block::<TargetReport>(block, pos, &mut out),
            CAT_SERVICE_MESSAGES => decode_block::<ServiceMessage>(block, pos, &mut out),
            CAT_ADSB => decode_block::<AdsbReport>(block, pos, &mut out),
            CAT_MLAT => decode_block::<MlatReport>(block, pos, &mut out),
            other => out.errors.push(DecodeError {
                offset: pos,
                reason: format!(
                    "category {other:03} is not decoded (only CAT048, CAT034, CAT021 and \
                     CAT020): block of {len} bytes skipped"
                ),
            }),
        }
        pos += len;
    }
    out
}

/// Decodes the records of one block of category `C` (`block` includes
/// its header; `base` is its offset in the data).
fn decode_block<C: Category>(block: &[u8], base: usize, out: &mut Decoded) {
    let cat = C::CAT;
    let mut pos = 3usize;
    if pos == block.len() {
        out.errors.push(DecodeError {
            offset: base,
            reason: format!("data block (CAT {cat:03}) holds no record"),
        });
        return;
    }
    while pos < block.len() {
        let mut record = C::default();
        match uap::walk(cat, C::UAP, block, pos, |frn, v| record.read(frn, v)) {
            Ok(end) => {
                record.store(base + pos, out);
                pos = end;
            }
            Err((at, reason)) => {
                out.errors.push(DecodeError {
                    // A record cut by the end of its block is reported at
                    // the block's last byte, not one past it (which, for
                    // the last block, would lie outside the data).
                    offset: base + at.min(block.len() - 1),
                    reason: format!(
                        "{reason} (record at offset {}; the rest of its CAT {cat:03} block, \
                         {} bytes, is skipped)",
                        base + pos,
                        block.len() - pos
                    ),
                });
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block of `cat` around `records`.
    pub(super) fn block(cat: u8, records: &[u8]) -> Vec<u8> {
        let len = (records.len() + 3) as u16;
        let mut b = vec![cat];
        b.extend_from_slice(&len.to_be_bytes());
        b.extend_from_slice(records);
        b
    }

    #[test]
    fn an_unknown_category_is_reported_and_skipped_by_len() {
        let mut data = block(1, &[0x80, 1, 2]);
        let at = data.len();
        data.extend(block(34, &[0xE0, 25, 1, 1, 0x00, 0x01, 0x00]));
        let d = decode(&data);
        assert_eq!(d.errors.len(), 1);
        assert_eq!(d.errors[0].offset, 0);
        assert!(d.errors[0].reason.contains("category 001"));
        let s = &d.service_messages[0];
        assert_eq!(s.offset, at + 3);
        assert_eq!(s.source, Some((25, 1)));
        assert_eq!(s.message_type, Some(NORTH_MARKER));
        assert_eq!(s.time_of_day_s, Some(2.0));
        assert_eq!(d.blocks, 2);
    }

    #[test]
    fn a_mixed_datagram_gives_each_category_its_records() {
        // CAT048 (I048/010 25/1), CAT021 (I021/010 30/1, I021/080
        // 0xABCDEF: FSPEC 0x81 0x10, FRN 1 and FRN 11), CAT020 (I020/010
        // 40/1), CAT034 (I034/010 25/1, I034/000 north marker), an
        // unknown CAT001 block, and a second CAT021 record in its own
        // block.
        let mut data = block(48, &[0x80, 25, 1]);
        let at_021 = data.len();
        data.extend(block(21, &[0x81, 0x10, 30, 1, 0xAB, 0xCD, 0xEF]));
        let at_020 = data.len();
        data.extend(block(20, &[0x80, 40, 1]));
        let at_034 = data.len();
        data.extend(block(34, &[0xC0, 25, 1, NORTH_MARKER]));
        let at_001 = data.len();
        data.extend(block(1, &[0x80, 1, 2]));
        data.extend(block(21, &[0x80, 30, 2]));
        let d = decode(&data);
        assert_eq!(d.blocks, 6);
        assert_eq!(d.errors.len(), 1);
        assert_eq!(d.errors[0].offset, at_001);
        assert_eq!(d.target_reports[0].source, Some((25, 1)));
        assert_eq!(d.adsb_reports.len(), 2);
        let a = &d.adsb_reports[0];
        assert_eq!(
            (a.offset, a.source, a.address),
            (at_021 + 3, Some((30, 1)), Some(0xABCDEF))
        );
        assert_eq!(d.adsb_reports[1].source, Some((30, 2)));
        assert_eq!(d.mlat_reports[0].offset, at_020 + 3);
        assert_eq!(d.mlat_reports[0].source, Some((40, 1)));
        let m = &d.service_messages[0];
        assert_eq!((m.offset, m.message_type), (at_034 + 3, Some(NORTH_MARKER)));
        sound(&data, &d);
    }

    #[test]
    fn a_bad_record_loses_its_block_but_not_the_next() {
        // Record 1 fine (FRN 1), record 2 flags I048/040 but is cut short.
        let mut data = block(48, &[0x80, 1, 2, 0x10, 0x00]);
        let second = data.len();
        data.extend(block(48, &[0x80, 3, 4]));
        let d = decode(&data);
        assert_eq!(d.target_reports.len(), 2);
        assert_eq!(d.target_reports[1].source, Some((3, 4)));
        assert_eq!(d.errors.len(), 1);
        assert_eq!(d.errors[0].offset, 7, "{:?}", d.errors);
        assert!(d.errors[0].reason.contains("I048/040"), "{:?}", d.errors);
        assert!(second > 7);
    }

    #[test]
    fn lengths_that_cannot_hold_are_reported_where_they_are() {
        let d = decode(&[48, 0, 2, 0x80]);
        assert_eq!(d.errors[0].offset, 0);
        assert!(d.errors[0].reason.contains("LEN 2"));
        let d = decode(&[48, 0, 40, 0x80, 1, 2]);
        assert!(d.errors[0].reason.contains("runs past the end"));
        let d = decode(&[48, 0]);
        assert!(d.errors[0].reason.contains("header"));
        // An FSPEC flagging an undefined FRN of CAT034 (FRN 15 does not exist:
        // third octet).
        let d = decode(&block(34, &[0x01, 0x01, 0x80]));
        assert!(!d.errors.is_empty());
        // A spare flag of I034/050's primary subfield.
        let d = decode(&block(34, &[0x04, 0x40]));
        assert!(d.errors[0].reason.contains("spare"), "{:?}", d.errors);
    }

    const SCENE: &[u8] = include_bytes!("../../../tests/fixtures/asterix/scene.bin");
    /// libasterix's CAT021, CAT020 and mixed fixtures
    /// (`checks/cat021_fixture.py`).
    const COOPERATIVE: [&[u8]; 3] = [
        include_bytes!("../../../tests/fixtures/cat021/adsb.bin"),
        include_bytes!("../../../tests/fixtures/cat021/mlat.bin"),
        include_bytes!("../../../tests/fixtures/cat021/mixed.bin"),
    ];

    /// Every number of the tracker's view of a cooperative report is
    /// finite (they are made from integers: no NaN may travel).
    fn finite_view(r: &impl CooperativeReport) {
        let pairs = [r.lat_lon_deg(), r.velocity_en_mps(), r.position_sigma_m()];
        let singles = [
            r.time_of_applicability_s(),
            r.geometric_height_m(),
            r.flight_level(),
        ];
        let all = pairs
            .iter()
            .flatten()
            .flat_map(|&(a, b)| [a, b])
            .chain(singles.iter().flatten().copied());
        for x in all {
            assert!(x.is_finite(), "{x}");
        }
        let _ = (
            r.address(),
            r.callsign(),
            r.mode_3a(),
            r.simulated_or_test(),
        );
    }

    /// Offsets lie in the data, records come in data order, and nothing
    /// panics.
    fn sound(data: &[u8], d: &Decoded) {
        assert!(d.errors.iter().all(|e| e.offset < data.len().max(1)));
        let mut offsets: Vec<usize> = d
            .target_reports
            .iter()
            .map(|t| t.offset)
            .chain(d.service_messages.iter().map(|s| s.offset))
            .chain(d.adsb_reports.iter().map(|r| r.offset))
            .chain(d.mlat_reports.iter().map(|r| r.offset))
            .collect();
        let n = offsets.len();
        offsets.sort_unstable();
        offsets.dedup();
        assert_eq!(offsets.len(), n);
        assert!(offsets.iter().all(|&o| o < data.len()));
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(64))]

        #[test]
        fn random_bytes_up_to_64_kb_give_errors_never_a_panic(
            data in proptest::collection::vec(proptest::num::u8::ANY, 0..65_536)
        ) {
            let d = decode(&data);
            sound(&data, &d);
        }

        #[test]
        fn a_truncated_scene_keeps_every_record_before_the_cut(cut in 0..SCENE.len()) {
            let whole = decode(SCENE);
            let d = decode(&SCENE[..cut]);
            sound(&SCENE[..cut], &d);
            // Records of complete blocks are decoded as in the whole data
            // (the cut block is reported, not decoded).
            for t in &d.target_reports {
                let same = whole.target_reports.iter().find(|w| w.offset == t.offset);
                proptest::prop_assert_eq!(Some(t), same);
            }
        }

        #[test]
        fn corrupted_bytes_and_lengths_give_errors_never_a_panic(
            at in 0..SCENE.len(),
            value in proptest::num::u8::ANY,
            len_at in 0..SCENE.len(),
        ) {
            let mut data = SCENE.to_vec();
            data[at] = value;
            data[len_at] ^= 0x5A;
            let d = decode(&data);
            sound(&data, &d);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(512))]

        #[test]
        fn mutated_cooperative_fixtures_give_errors_never_a_panic(
            which in 0..3usize,
            edits in crate::mutation::edits(),
        ) {
            let data = crate::mutation::apply(COOPERATIVE[which], &edits);
            let d = decode(&data);
            sound(&data, &d);
            for r in &d.adsb_reports {
                finite_view(r);
                let _ = (r.tomr_position_precise_s(), r.tomr_velocity_precise_s());
            }
            for r in &d.mlat_reports {
                finite_view(r);
            }
        }

        #[test]
        fn a_truncated_mixed_datagram_keeps_every_record_before_the_cut(
            cut in 0..COOPERATIVE[2].len()
        ) {
            let mixed = COOPERATIVE[2];
            let whole = decode(mixed);
            let d = decode(&mixed[..cut]);
            sound(&mixed[..cut], &d);
            for r in &d.adsb_reports {
                let same = whole.adsb_reports.iter().find(|w| w.offset == r.offset);
                proptest::prop_assert_eq!(Some(r), same);
            }
            for r in &d.mlat_reports {
                let same = whole.mlat_reports.iter().find(|w| w.offset == r.offset);
                proptest::prop_assert_eq!(Some(r), same);
            }
        }
    }
}
