//! EUROCONTROL ASTERIX input: CAT048 monoradar target reports and CAT034
//! service messages (north markers, sector crossings) decoded from raw
//! bytes, as radars send them (usually one or more data blocks per UDP
//! datagram).
//!
//! A data block is `CAT (1 byte) | LEN (2 bytes, big-endian, the whole
//! block) | records`; a record is an FSPEC (bytes whose low bit FX says
//! another follows; bit 8 of the first byte is FRN 1, bit 2 FRN 7, bit 8
//! of the second FRN 8, …) and then the items it flags, in FRN order. An
//! item has no length of its own: it is known from the category's User
//! Application Profile (UAP), by one of the rules of [`Len`]: fixed,
//! extended (octets until FX = 0), repetitive (a count REP, then REP
//! fixed-size parts), explicit (its first byte is its length, SP and RE),
//! compound (a primary subfield, itself extended, flagging subfields of
//! their own rules: I048/130, I048/120, I034/050, I034/060). Every item of
//! the UAP is skipped by its rule, so items we do not use cost nothing and
//! never desynchronise the record.
//!
//! Items decoded: I048/010 SAC/SIC, /140 time of day (1/128 s), /020
//! target report descriptor (TYP, SIM, RDP, SPI, RAB; TST of the first
//! extension), /040 measured position (RHO 1/256 NM, THETA 360/2¹⁶ °),
//! /070 Mode 3/A with V, G, L, /090 flight level (V, G; 1/4 FL, two's
//! complement), /240 aircraft identification (8 × 6-bit ICAO), /110 3D
//! height (25 ft, two's complement), /120 calculated Doppler speed (D,
//! CAL: 10-bit two's complement, 1 m/s), /220 aircraft address, /161
//! track number; I034/010, /000 message type, /030 time of day, /020
//! sector (360/2⁸ °), /041 antenna rotation period (1/128 s). Values are
//! SI at this edge (1 NM = 1852 m, 1 ft = 0.3048 m, exactly), angles in
//! degrees as the wire gives them (they go into the service's plots,
//! whose azimuths are in degrees).
//!
//! Errors never stop the decoding of what is good: every one carries the
//! byte offset (from the start of the data) where it was found and a
//! reason. A bad record loses the rest of its block (a record has no
//! length: its end is only known by decoding it), and decoding resumes at
//! the next block by LEN. A block of another category is reported and
//! skipped by LEN. A LEN below 3 or beyond the data ends the decoding
//! there (the block boundary is lost).
//!
//! UAPs: CAT048 edition 1.32 and CAT034 edition 1.29 (EUROCONTROL ASTERIX
//! specifications), as libasterix's generated definitions give them;
//! checked against libasterix's encoder and decoder
//! (`checks/asterix_fixture.py`, `tests/api/asterix.rs`). Why not the
//! `asterix` crate: docs/plot-fusion.md, "ASTERIX input".

/// One nautical mile in metres (exact, by definition).
pub const NM_M: f64 = 1852.0;
/// One foot in metres (exact, by definition).
pub const FT_M: f64 = algo::tracking::height::FT_M;

/// The categories this decoder reads.
pub const CAT_TARGET_REPORTS: u8 = 48;
pub const CAT_SERVICE_MESSAGES: u8 = 34;

/// I034/000 message types.
pub const NORTH_MARKER: u8 = 1;
pub const SECTOR_CROSSING: u8 = 2;

/// Everything decoded from a run of bytes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Decoded {
    /// Data blocks read (of any category, including skipped ones).
    pub blocks: usize,
    pub target_reports: Vec<TargetReport>,
    pub service_messages: Vec<ServiceMessage>,
    pub errors: Vec<DecodeError>,
}

/// A problem in the data, where it was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeError {
    /// Byte offset from the start of the data.
    pub offset: usize,
    pub reason: String,
}

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

/// The validity bits a CAT048 reply item carries (I048/070, I048/090).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReplyFlags {
    /// V = 0: validated.
    pub validated: bool,
    /// G = 1: garbled.
    pub garbled: bool,
    /// L = 1 (I048/070 only): the code was not extracted during the last
    /// scan (smoothed).
    pub smoothed: bool,
}

impl ReplyFlags {
    fn of(word: u16, has_l: bool) -> Self {
        Self {
            validated: word & 0x8000 == 0,
            garbled: word & 0x4000 != 0,
            smoothed: has_l && word & 0x2000 != 0,
        }
    }
}

/// The ICAO 6-bit character set of I048/240 (Annex 10 vol. IV, table
/// 3-9): 1–26 are A–Z, 32 space, 48–57 the digits; anything else is not
/// a character of an identification.
fn ia5(c: u8) -> Option<char> {
    match c {
        1..=26 => Some((b'A' + c - 1) as char),
        32 => Some(' '),
        48..=57 => Some((b'0' + c - 48) as char),
        _ => None,
    }
}

/// I048/240: eight 6-bit characters in 48 bits, space-padded; `None`
/// when a character is outside the set or all are spaces.
fn callsign(v: &[u8]) -> Option<String> {
    let bits = v[..6].iter().fold(0u64, |acc, &b| acc << 8 | b as u64);
    let text: Option<String> = (0..8)
        .map(|i| ia5(((bits >> (42 - 6 * i)) & 0x3F) as u8))
        .collect();
    text.map(|t| t.trim_end().to_string())
        .filter(|t| !t.is_empty())
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

/// A CAT034 record: a service message of a radar's scan.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ServiceMessage {
    pub offset: usize,
    /// I034/010 (SAC, SIC).
    pub source: Option<(u8, u8)>,
    /// I034/000: 1 north marker, 2 sector crossing, 3 geographical
    /// filtering, 4 jamming strobe, …
    pub message_type: Option<u8>,
    /// I034/030, seconds since midnight UTC.
    pub time_of_day_s: Option<f64>,
    /// I034/020 (degrees).
    pub sector_deg: Option<f64>,
    /// I034/041 antenna rotation period (s).
    pub rotation_period_s: Option<f64>,
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
            CAT_TARGET_REPORTS | CAT_SERVICE_MESSAGES => decode_block(cat, block, pos, &mut out),
            other => out.errors.push(DecodeError {
                offset: pos,
                reason: format!(
                    "category {other:03} is not decoded (only CAT048 and CAT034): block of \
                     {len} bytes skipped"
                ),
            }),
        }
        pos += len;
    }
    out
}

/// The length rule of an item or subfield.
#[derive(Debug, Clone, Copy)]
enum Len {
    /// Always this many bytes.
    Fixed(usize),
    /// Octets until one with FX (bit 1) clear.
    Extended,
    /// A one-byte count, then that many parts of this size.
    Repetitive(usize),
    /// The first byte is the item's length, itself included.
    Explicit,
    /// A primary subfield (extended: 7 flags an octet) flagging these
    /// subfields; `None` is a spare flag (must be clear).
    Compound(&'static [Option<Len>]),
}

/// An item of a UAP.
#[derive(Debug, Clone, Copy)]
struct Item {
    name: &'static str,
    len: Len,
}

const fn item(name: &'static str, len: Len) -> Option<Item> {
    Some(Item { name, len })
}

use Len::{Compound, Explicit, Extended, Fixed, Repetitive};

/// CAT048 UAP, FRN 1..=28 (index 0 is FRN 1).
const UAP_048: [Option<Item>; 28] = [
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
    // CAL (2 bytes), RDS (REP × DOP, AMB, FRQ: 6 bytes).
    item("I048/120", Compound(&[Some(Fixed(2)), Some(Repetitive(6))])),
    item("I048/230", Fixed(2)),
    item("I048/260", Fixed(7)),
    item("I048/055", Fixed(1)),
    item("I048/050", Fixed(2)),
    item("I048/065", Fixed(1)),
    item("I048/060", Fixed(2)),
    item("I048/SP", Explicit),
    item("I048/RE", Explicit),
];

/// CAT034 UAP, FRN 1..=14.
const UAP_034: [Option<Item>; 14] = [
    item("I034/010", Fixed(2)),
    item("I034/000", Fixed(1)),
    item("I034/030", Fixed(3)),
    item("I034/020", Fixed(1)),
    item("I034/041", Fixed(2)),
    // COM, spare, spare, PSR, SSR, MDS (2 bytes), spare.
    item(
        "I034/050",
        Compound(&[
            Some(Fixed(1)),
            None,
            None,
            Some(Fixed(1)),
            Some(Fixed(1)),
            Some(Fixed(2)),
            None,
        ]),
    ),
    // COM, spare, spare, PSR, SSR, MDS (1 byte each), spare.
    item(
        "I034/060",
        Compound(&[
            Some(Fixed(1)),
            None,
            None,
            Some(Fixed(1)),
            Some(Fixed(1)),
            Some(Fixed(1)),
            None,
        ]),
    ),
    item("I034/070", Repetitive(2)),
    item("I034/100", Fixed(8)),
    item("I034/110", Fixed(1)),
    item("I034/120", Fixed(8)),
    item("I034/090", Fixed(2)),
    item("I034/RE", Explicit),
    item("I034/SP", Explicit),
];

/// Decodes the records of one block (`block` includes its header; `base`
/// is its offset in the data).
fn decode_block(cat: u8, block: &[u8], base: usize, out: &mut Decoded) {
    let uap: &[Option<Item>] = if cat == CAT_TARGET_REPORTS {
        &UAP_048
    } else {
        &UAP_034
    };
    let mut pos = 3usize;
    if pos == block.len() {
        out.errors.push(DecodeError {
            offset: base,
            reason: format!("data block (CAT {cat:03}) holds no record"),
        });
        return;
    }
    while pos < block.len() {
        match record(cat, uap, block, pos) {
            Ok((end, rec)) => {
                let offset = base + pos;
                match rec {
                    Record::Target(mut t) => {
                        t.offset = offset;
                        out.target_reports.push(t);
                    }
                    Record::Service(mut s) => {
                        s.offset = offset;
                        out.service_messages.push(s);
                    }
                }
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

enum Record {
    Target(TargetReport),
    Service(ServiceMessage),
}

type Failure = (usize, String);

/// Decodes the record at `start` of `block`: its end and contents, or the
/// offset (in the block) and reason of the first problem.
fn record(
    cat: u8,
    uap: &[Option<Item>],
    block: &[u8],
    start: usize,
) -> Result<(usize, Record), Failure> {
    // FSPEC.
    let mut pos = start;
    let mut frns: Vec<usize> = Vec::with_capacity(16);
    loop {
        let Some(&b) = block.get(pos) else {
            return Err((pos, "the FSPEC runs past the end of the block".into()));
        };
        let octet = pos - start;
        for bit in 0..7 {
            if b & (0x80 >> bit) != 0 {
                frns.push(octet * 7 + bit + 1);
            }
        }
        pos += 1;
        if b & 1 == 0 {
            break;
        }
        if octet * 7 + 7 >= uap.len() {
            return Err((
                pos - 1,
                format!(
                    "the FSPEC goes on past the CAT {cat:03} UAP ({} items)",
                    uap.len()
                ),
            ));
        }
    }
    if frns.is_empty() {
        return Err((start, "empty FSPEC (no item flagged)".into()));
    }
    let mut target = TargetReport::default();
    let mut service = ServiceMessage::default();
    for frn in frns {
        let Some(Some(it)) = uap.get(frn - 1) else {
            return Err((
                start,
                format!("the FSPEC flags FRN {frn}, which the CAT {cat:03} UAP does not define"),
            ));
        };
        let end = skip(it.name, it.len, block, pos)?;
        let v = &block[pos..end];
        if cat == CAT_TARGET_REPORTS {
            read_048(frn, v, &mut target);
        } else {
            read_034(frn, v, &mut service);
        }
        pos = end;
    }
    Ok((
        pos,
        if cat == CAT_TARGET_REPORTS {
            Record::Target(target)
        } else {
            Record::Service(service)
        },
    ))
}

/// The end of an item (or subfield) of rule `len` starting at `pos`.
fn skip(name: &str, len: Len, block: &[u8], pos: usize) -> Result<usize, Failure> {
    let past = |need: usize| {
        (
            pos,
            format!(
                "{name} needs {need} byte(s), {} left in the block",
                block.len() - pos
            ),
        )
    };
    match len {
        Fixed(n) => {
            if pos + n > block.len() {
                return Err(past(n));
            }
            Ok(pos + n)
        }
        Extended => {
            let mut p = pos;
            loop {
                let Some(&b) = block.get(p) else {
                    return Err((
                        p,
                        format!("{name}: its FX extension runs past the end of the block"),
                    ));
                };
                p += 1;
                if b & 1 == 0 {
                    return Ok(p);
                }
            }
        }
        Repetitive(part) => {
            let Some(&rep) = block.get(pos) else {
                return Err(past(1));
            };
            let n = 1 + rep as usize * part;
            if pos + n > block.len() {
                return Err((
                    pos,
                    format!(
                        "{name}: REP {rep} × {part} bytes runs past the end of the block ({} \
                         bytes left)",
                        block.len() - pos - 1
                    ),
                ));
            }
            Ok(pos + n)
        }
        Explicit => {
            let Some(&n) = block.get(pos) else {
                return Err(past(1));
            };
            if n == 0 {
                return Err((pos, format!("{name}: explicit length 0 (at least 1)")));
            }
            if pos + n as usize > block.len() {
                return Err(past(n as usize));
            }
            Ok(pos + n as usize)
        }
        Compound(subfields) => {
            // The primary subfield: 7 flags an octet, FX to go on.
            let mut p = pos;
            let mut flagged: Vec<usize> = Vec::with_capacity(8);
            loop {
                let Some(&b) = block.get(p) else {
                    return Err((
                        p,
                        format!("{name}: its primary subfield runs past the end of the block"),
                    ));
                };
                let octet = p - pos;
                for bit in 0..7 {
                    if b & (0x80 >> bit) != 0 {
                        flagged.push(octet * 7 + bit);
                    }
                }
                p += 1;
                if b & 1 == 0 {
                    break;
                }
                if octet * 7 + 7 >= subfields.len() {
                    return Err((
                        p - 1,
                        format!(
                            "{name}: the primary subfield goes on past its {} subfields",
                            subfields.len()
                        ),
                    ));
                }
            }
            for i in flagged {
                match subfields.get(i) {
                    Some(Some(rule)) => {
                        p = skip(name, *rule, block, p)?;
                    }
                    _ => {
                        return Err((
                            pos,
                            format!(
                                "{name}: the primary subfield flags subfield {}, which is \
                                 spare or undefined",
                                i + 1
                            ),
                        ));
                    }
                }
            }
            Ok(p)
        }
    }
}

fn u16_at(v: &[u8], i: usize) -> u16 {
    u16::from_be_bytes([v[i], v[i + 1]])
}

fn u24_at(v: &[u8], i: usize) -> u32 {
    (v[i] as u32) << 16 | (v[i + 1] as u32) << 8 | v[i + 2] as u32
}

/// The low `bits` of `raw` as a two's complement number.
fn signed(raw: u32, bits: u32) -> i32 {
    let shift = 32 - bits;
    ((raw << shift) as i32) >> shift
}

fn read_048(frn: usize, v: &[u8], t: &mut TargetReport) {
    match frn {
        1 => t.source = Some((v[0], v[1])),
        2 => t.time_of_day_s = Some(u24_at(v, 0) as f64 / 128.0),
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
        // Primary subfield bit 8: CAL present, right after the primary.
        20 if v[0] & 0x80 != 0 => {
            let mut p = 1;
            while v[p - 1] & 1 != 0 {
                p += 1;
            }
            let cal = u16_at(v, p);
            t.doppler_doubtful = cal & 0x8000 != 0;
            t.doppler_mps = Some(signed(cal as u32, 10) as f64);
        }
        _ => {}
    }
}

fn read_034(frn: usize, v: &[u8], s: &mut ServiceMessage) {
    match frn {
        1 => s.source = Some((v[0], v[1])),
        2 => s.message_type = Some(v[0]),
        3 => s.time_of_day_s = Some(u24_at(v, 0) as f64 / 128.0),
        4 => s.sector_deg = Some(v[0] as f64 * (360.0 / 256.0)),
        5 => s.rotation_period_s = Some(u16_at(v, 0) as f64 / 128.0),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block of `cat` around `records`.
    fn block(cat: u8, records: &[u8]) -> Vec<u8> {
        let len = (records.len() + 3) as u16;
        let mut b = vec![cat];
        b.extend_from_slice(&len.to_be_bytes());
        b.extend_from_slice(records);
        b
    }

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
        // A character outside the set (0) makes no identification.
        assert_eq!(callsign(&[0, 0, 0, 0, 0, 0]), None);
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
        // 0x0200 is −512 (the most negative 10-bit value), 0x01FF is +511.
        assert_eq!(signed(0x0200, 10), -512);
        assert_eq!(signed(0x01FF, 10), 511);
        assert_eq!(signed(0x2000, 14), -8192);
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

    /// Offsets lie in the data, records come in data order, and nothing
    /// panics.
    fn sound(data: &[u8], d: &Decoded) {
        assert!(d.errors.iter().all(|e| e.offset < data.len().max(1)));
        let mut offsets: Vec<usize> = d
            .target_reports
            .iter()
            .map(|t| t.offset)
            .chain(d.service_messages.iter().map(|s| s.offset))
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
}
