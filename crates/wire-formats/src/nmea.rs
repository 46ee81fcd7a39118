//! NMEA 0183 `!AIVDM`/`!AIVDO` decoding (ITU-R M.1371 over IEC 61162-1):
//! checksums, NMEA 4.0 tag blocks (`\c:<unix time>*hh\` gives the receive
//! time), multi-fragment reassembly by (sequential id, channel), the 6-bit
//! armour, and the position fields of message types 1, 2, 3 (class A),
//! 18, 19 (class B) and 27 (long-range, its own coarser scaling). Other
//! types are counted as skipped. A bad line is reported by its number and
//! skipped; decoding never fails as a whole.
//!
//! The armour and bit writer are shared with the AIS encoder of the
//! simulation (`sim::ais`), so the codec exists once.

use std::collections::{BTreeMap, HashMap};

/// A decoded position report.
#[derive(Debug, Clone, PartialEq)]
pub struct AisPosition {
    /// Index (0-based) of the line that completed the message.
    pub line: usize,
    pub message_type: u8,
    pub mmsi: u32,
    /// Receive time from the tag block (s), if any fragment carried one.
    pub t: Option<f64>,
    /// Resolution of that time (s): 1 for whole seconds (the usual `c:`),
    /// 0.001 for milliseconds, 10^−d for d written decimals.
    pub t_resolution: Option<f64>,
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Speed over ground in knots, when available.
    pub sog_knots: Option<f64>,
    /// Course over ground in degrees, when available.
    pub cog_deg: Option<f64>,
    /// The position-accuracy flag: true for better than 10 m (DGNSS),
    /// false for worse (an autonomous GNSS fix).
    pub position_accurate: bool,
    /// The UTC second of the position's fix (0–59), when the message
    /// gives it (types 1–3, 18, 19; 60–63 mean not available).
    pub utc_second: Option<u8>,
}

impl AisPosition {
    /// The time the position holds (s, the receive time's scale): the
    /// latest instant at or before the receive time `t` whose UTC second
    /// is the report's, at the middle of that second (the field truncates
    /// the fix time to the second), never after the receive time. The
    /// receive time without a UTC second (type 27, or not available).
    /// `None` without a receive time.
    pub fn time_of_applicability(&self) -> Option<f64> {
        let t = self.t?;
        let Some(second) = self.utc_second else {
            return Some(t);
        };
        // Unix time has no leap seconds: t mod 60 is the UTC second.
        let late = (t.rem_euclid(60.0) - f64::from(second)).rem_euclid(60.0);
        Some((t - late + 0.5).min(t))
    }
}

/// A line that could not be used, with its 0-based index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LineError {
    pub line: usize,
    pub message: String,
}

/// Everything the decoder found in a batch of lines.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Decoded {
    pub lines: usize,
    /// Sentences whose checksum and framing were valid.
    pub sentences: usize,
    /// Complete messages (after reassembly).
    pub messages: usize,
    pub positions: Vec<AisPosition>,
    /// Messages of other types, by type.
    pub skipped_by_type: BTreeMap<u8, usize>,
    pub errors: Vec<LineError>,
}

/// A complete AIS message: its payload bits and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub bits: Vec<u8>,
    /// Receive time and its resolution (s).
    pub t: Option<(f64, f64)>,
    pub line: usize,
}

/// Decodes `lines` (blank lines are ignored but counted).
pub fn decode(lines: &[String]) -> Decoded {
    let mut out = Decoded {
        lines: lines.len(),
        ..Decoded::default()
    };
    // Pending fragments by (sequential id, channel): (count, next number, bits, t, lines).
    let mut pending: HashMap<(String, String), Pending> = HashMap::new();
    for (i, raw) in lines.iter().enumerate() {
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        let sentence = match parse_line(line) {
            Ok(s) => s,
            Err(e) => {
                out.errors.push(LineError {
                    line: i,
                    message: e,
                });
                continue;
            }
        };
        out.sentences += 1;
        let key = (sentence.seq_id.clone(), sentence.channel.clone());
        let msg = if sentence.count == 1 {
            Some(Message {
                bits: sentence.bits,
                t: sentence.t,
                line: i,
            })
        } else if sentence.number == 1 {
            if let Some(old) = pending.insert(
                key,
                Pending {
                    count: sentence.count,
                    next: 2,
                    bits: sentence.bits,
                    t: sentence.t,
                    lines: vec![i],
                },
            ) {
                report_incomplete(&mut out, &old);
            }
            None
        } else {
            match pending.remove(&key) {
                Some(mut p) if p.count == sentence.count && p.next == sentence.number => {
                    p.bits.extend(sentence.bits);
                    p.t = p.t.or(sentence.t);
                    p.lines.push(i);
                    if p.next == p.count {
                        Some(Message {
                            bits: p.bits,
                            t: p.t,
                            line: i,
                        })
                    } else {
                        p.next += 1;
                        pending.insert(key, p);
                        None
                    }
                }
                other => {
                    if let Some(p) = other {
                        report_incomplete(&mut out, &p);
                    }
                    out.errors.push(LineError {
                        line: i,
                        message: format!(
                            "fragment {} of {} without its preceding fragments",
                            sentence.number, sentence.count
                        ),
                    });
                    None
                }
            }
        };
        if let Some(m) = msg {
            out.messages += 1;
            interpret(&mut out, &m);
        }
    }
    let mut left: Vec<Pending> = pending.into_values().collect();
    left.sort_by_key(|p| p.lines[0]);
    for p in &left {
        report_incomplete(&mut out, p);
    }
    out.errors.sort_by_key(|e| e.line);
    out
}

struct Pending {
    count: u32,
    next: u32,
    bits: Vec<u8>,
    t: Option<(f64, f64)>,
    lines: Vec<usize>,
}

fn report_incomplete(out: &mut Decoded, p: &Pending) {
    for &l in &p.lines {
        out.errors.push(LineError {
            line: l,
            message: format!(
                "incomplete multi-fragment message ({} fragments expected)",
                p.count
            ),
        });
    }
}

struct Sentence {
    count: u32,
    number: u32,
    seq_id: String,
    channel: String,
    bits: Vec<u8>,
    t: Option<(f64, f64)>,
}

/// Parses one line: optional tag block, then an AIVDM/AIVDO sentence.
fn parse_line(line: &str) -> Result<Sentence, String> {
    let mut t = None;
    let mut rest = line;
    if let Some(after) = rest.strip_prefix('\\') {
        let end = after
            .find('\\')
            .ok_or("tag block is not closed by a backslash")?;
        t = parse_tag_block(&after[..end])?;
        rest = &after[end + 1..];
    }
    let body = rest
        .strip_prefix('!')
        .ok_or("an AIS sentence starts with '!'")?;
    let (body, sum) = body.rsplit_once('*').ok_or("no checksum ('*hh')")?;
    check_sum(body, sum)?;
    let f: Vec<&str> = body.split(',').collect();
    if f.len() != 7 {
        return Err(format!("expected 7 fields, found {}", f.len()));
    }
    if !(f[0].len() == 5 && (f[0].ends_with("VDM") || f[0].ends_with("VDO"))) {
        return Err(format!("not an AIVDM/AIVDO sentence: {}", f[0]));
    }
    let count: u32 = f[1].parse().map_err(|_| "bad fragment count")?;
    let number: u32 = f[2].parse().map_err(|_| "bad fragment number")?;
    if !(1..=9).contains(&count) || !(1..=count).contains(&number) {
        return Err(format!("fragment {number} of {count} is out of range"));
    }
    let fill: usize = f[6].parse().map_err(|_| "bad fill-bit count")?;
    if fill > 5 {
        return Err(format!("fill bits must be 0 to 5, got {fill}"));
    }
    let mut bits = dearmour(f[5])?;
    if fill > bits.len() {
        return Err("fill bits exceed the payload".into());
    }
    bits.truncate(bits.len() - fill);
    Ok(Sentence {
        count,
        number,
        seq_id: f[3].to_string(),
        channel: f[4].to_string(),
        bits,
        t,
    })
}

/// The `c:` (receive time, Unix seconds) of a tag block `…*hh` and its
/// resolution: 1 s for an integer (0.001 s when it is in milliseconds),
/// 10^−d s for d decimals.
fn parse_tag_block(block: &str) -> Result<Option<(f64, f64)>, String> {
    let (body, sum) = block.rsplit_once('*').ok_or("tag block has no checksum")?;
    check_sum(body, sum).map_err(|e| format!("tag block: {e}"))?;
    let mut t = None;
    for item in body.split(',') {
        if let Some(v) = item.strip_prefix("c:") {
            let v: f64 = v
                .parse()
                .map_err(|_| format!("tag block time c:{v} is not a number"))?;
            if !v.is_finite() {
                return Err("tag block time is not finite".into());
            }
            let decimals = v_text_decimals(v_text(item));
            let resolution = 10f64.powi(-(decimals as i32));
            // Some receivers write milliseconds: more than 10¹¹ s is after year 5000.
            t = Some(if v > 1e11 {
                (v / 1000.0, resolution / 1000.0)
            } else {
                (v, resolution)
            });
        }
    }
    Ok(t)
}

/// The text of a `c:` item.
fn v_text(item: &str) -> &str {
    item.strip_prefix("c:").unwrap_or(item)
}

/// Decimals written after the point of a number (0 for an integer).
fn v_text_decimals(v: &str) -> usize {
    let mantissa = v.split(['e', 'E']).next().unwrap_or(v);
    mantissa.split_once('.').map_or(0, |(_, d)| d.len())
}

fn check_sum(body: &str, sum: &str) -> Result<(), String> {
    // Two hex digits: `from_str_radix` alone would take "+F".
    if !(sum.len() == 2 && sum.bytes().all(|b| b.is_ascii_hexdigit())) {
        return Err(format!("bad checksum field {sum:?}"));
    }
    let want = u8::from_str_radix(sum, 16).map_err(|_| format!("bad checksum field {sum:?}"))?;
    let got = checksum(body);
    if got != want {
        return Err(format!(
            "checksum mismatch: computed {got:02X}, sentence says {want:02X}"
        ));
    }
    Ok(())
}

fn interpret(out: &mut Decoded, m: &Message) {
    let r = BitReader(&m.bits);
    let Some(kind) = r.u(0, 6) else {
        out.errors.push(LineError {
            line: m.line,
            message: "empty payload".into(),
        });
        return;
    };
    let kind = kind as u8;
    // (needed bits, lon start, lon bits, lat start, lat bits, scale per degree,
    //  sog start, sog bits, sog scale, cog start, cog bits, cog scale);
    // the accuracy flag is the bit before the longitude, and types 1–3 and
    // 18/19 end their position block with the UTC second (6 bits after the
    // 9-bit heading: 137 and 133), ITU-R M.1371-5 tables 48, 60, 62, 79.
    let layout = match kind {
        1..=3 => (168, 61, 28, 89, 27, 600_000.0, 50, 10, 10.0, 116, 12, 10.0),
        18 | 19 => (168, 57, 28, 85, 27, 600_000.0, 46, 10, 10.0, 112, 12, 10.0),
        27 => (96, 44, 18, 62, 17, 600.0, 79, 6, 1.0, 85, 9, 1.0),
        _ => {
            *out.skipped_by_type.entry(kind).or_default() += 1;
            return;
        }
    };
    let (need, lo0, lon_n, la0, lat_n, scale, s0, sn, ss, c0, cn, cs) = layout;
    let short = || LineError {
        line: m.line,
        message: format!(
            "type {kind} message has {} bits, needs {need}",
            m.bits.len()
        ),
    };
    let second_at = match kind {
        1..=3 => Some(137),
        18 | 19 => Some(133),
        _ => None,
    };
    let read = (|| {
        Some((
            r.u(8, 30)? as u32,
            r.i(lo0, lon_n)?,
            r.i(la0, lat_n)?,
            r.u(s0, sn)?,
            r.u(c0, cn)?,
            r.u(lo0 - 1, 1)? == 1,
            match second_at {
                Some(at) => Some(r.u(at, 6)? as u8),
                None => None,
            },
        ))
    })();
    let Some((mmsi, lon, lat, sog, cog, position_accurate, second)) =
        read.filter(|_| m.bits.len() >= need)
    else {
        out.errors.push(short());
        return;
    };
    let (lon_deg, lat_deg) = (lon as f64 / scale, lat as f64 / scale);
    if lon_deg.abs() > 180.0 || lat_deg.abs() > 90.0 {
        out.errors.push(LineError {
            line: m.line,
            message: format!("type {kind} report of MMSI {mmsi} has no position (not available)"),
        });
        return;
    }
    let sog_na = if kind == 27 { 63 } else { 1023 };
    let cog_na = if kind == 27 { 511 } else { 3600 };
    out.positions.push(AisPosition {
        line: m.line,
        message_type: kind,
        mmsi,
        t: m.t.map(|t| t.0),
        t_resolution: m.t.map(|t| t.1),
        lat_deg,
        lon_deg,
        sog_knots: (sog != sog_na).then(|| sog as f64 / ss),
        cog_deg: (cog < cog_na).then(|| cog as f64 / cs),
        position_accurate,
        utc_second: second.filter(|s| *s < 60),
    });
}

/// NMEA 0183 checksum: XOR of every character between `!`/`$` and `*`
/// (also of a tag block between `\` and `*`).
pub fn checksum(body: &str) -> u8 {
    body.bytes().fold(0, |acc, b| acc ^ b)
}

/// One 6-bit value as an AIS armour character: 0–39 → '0'..'W' (v + 48),
/// 40–63 → '`'..'w' (v + 56).
pub fn armour_char(v: u8) -> char {
    debug_assert!(v < 64);
    char::from(if v < 40 { v + 48 } else { v + 56 })
}

/// The payload's bits (one u8 of 0/1 per bit), six per armour character.
pub fn dearmour(payload: &str) -> Result<Vec<u8>, String> {
    let mut bits = Vec::with_capacity(payload.len() * 6);
    for c in payload.bytes() {
        let v = match c {
            b'0'..=b'W' => c - 48,
            b'`'..=b'w' => c - 56,
            _ => return Err(format!("invalid payload character {:?}", char::from(c))),
        };
        bits.extend((0..6).rev().map(|i| (v >> i) & 1));
    }
    Ok(bits)
}

/// Bits written most significant first, armoured six at a time.
#[derive(Debug, Default, Clone)]
pub struct BitWriter {
    bits: Vec<u8>,
}

impl BitWriter {
    /// Appends the low `n` bits of `v`, most significant first.
    pub fn put(&mut self, v: u64, n: u32) {
        for i in (0..n).rev() {
            self.bits.push(((v >> i) & 1) as u8);
        }
    }

    /// Appends `v` as an `n`-bit two's complement field.
    pub fn put_signed(&mut self, v: i64, n: u32) {
        self.put((v as u64) & ((1u64 << n) - 1), n);
    }

    pub fn len(&self) -> usize {
        self.bits.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bits.is_empty()
    }

    /// The armoured payload and its fill-bit count.
    pub fn armoured(&self) -> (String, usize) {
        let fill = (6 - self.bits.len() % 6) % 6;
        let s = self
            .bits
            .chunks(6)
            .map(|c| {
                let mut v = 0u8;
                for i in 0..6 {
                    v |= c.get(i).copied().unwrap_or(0) << (5 - i);
                }
                armour_char(v)
            })
            .collect();
        (s, fill)
    }
}

/// Reads unsigned and two's-complement fields of a bit vector.
#[derive(Debug, Clone, Copy)]
pub struct BitReader<'a>(pub &'a [u8]);

impl BitReader<'_> {
    /// `len` bits from `start` as an unsigned value, or `None` past the end.
    pub fn u(&self, start: usize, len: usize) -> Option<u64> {
        let s = self.0.get(start..start + len)?;
        Some(s.iter().fold(0, |acc, &b| (acc << 1) | u64::from(b)))
    }

    /// `len` bits from `start` as a two's-complement value.
    pub fn i(&self, start: usize, len: usize) -> Option<i64> {
        let v = self.u(start, len)? as i64;
        Some(if v >> (len - 1) == 1 {
            v - (1 << len)
        } else {
            v
        })
    }

    /// `chars` six-bit ASCII characters from `start` (AIS text, '@' padding removed).
    pub fn text(&self, start: usize, chars: usize) -> Option<String> {
        let mut s = String::new();
        for k in 0..chars {
            let v = self.u(start + 6 * k, 6)? as u8;
            s.push(char::from(if v < 32 { v + 64 } else { v }));
        }
        Some(s.trim_end_matches('@').trim_end().to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 17: tag-block times carry their resolution: whole seconds
    /// (the usual `c:`), written decimals, or milliseconds.
    #[test]
    fn tag_block_time_resolution() {
        let block = |v: &str| {
            let body = format!("c:{v}");
            format!("{body}*{:02X}", checksum(&body))
        };
        assert_eq!(
            parse_tag_block(&block("1700000003")).unwrap(),
            Some((1_700_000_003.0, 1.0))
        );
        let (t, r) = parse_tag_block(&block("1700000003.25")).unwrap().unwrap();
        assert_eq!(t, 1_700_000_003.25);
        assert!((r - 0.01).abs() < 1e-15);
        let (t, r) = parse_tag_block(&block("1700000003250")).unwrap().unwrap();
        assert!((t - 1_700_000_003.25).abs() < 1e-6);
        assert!((r - 0.001).abs() < 1e-15);
    }

    fn lines(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    /// gpsd's "AIVDM/AIVDO protocol decoding" example: MMSI 477553000,
    /// lon −122.345833°, lat 47.582833°, COG 51.0°, SOG 0.
    const TYPE1: &str = "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C";

    #[test]
    fn type_1_published_example() {
        let d = decode(&lines(&[TYPE1]));
        assert_eq!((d.sentences, d.messages, d.errors.len()), (1, 1, 0));
        let p = &d.positions[0];
        assert_eq!((p.message_type, p.mmsi), (1, 477_553_000));
        assert!((p.lon_deg + 122.345833).abs() < 1e-6);
        assert!((p.lat_deg - 47.582833).abs() < 1e-6);
        assert_eq!(p.cog_deg, Some(51.0));
        assert_eq!(p.sog_knots, Some(0.0));
        assert_eq!(p.t, None);
        // Checked with pyais 3.3.1: accuracy 0, second 15.
        assert!(!p.position_accurate);
        assert_eq!(p.utc_second, Some(15));
        assert_eq!(p.time_of_applicability(), None);
    }

    /// A class B (type 18) report, decoded independently with pyais 3.3.1:
    /// MMSI 423302100, accuracy 1, second 34, lon 53.010997°, lat
    /// 40.005283°.
    #[test]
    fn type_18_accuracy_and_utc_second() {
        let d = decode(&lines(&["!AIVDM,1,1,,A,B6CdCm0t3`tba35f@V9faHi7kP06,0*58"]));
        let p = &d.positions[0];
        assert_eq!((p.message_type, p.mmsi), (18, 423_302_100));
        assert!(p.position_accurate);
        assert_eq!(p.utc_second, Some(34));
        assert!((p.lon_deg - 53.010997).abs() < 1e-6);
        assert!((p.lat_deg - 40.005283).abs() < 1e-6);
    }

    /// The time a position holds from its UTC second and the receive time.
    #[test]
    fn time_of_applicability_from_the_utc_second() {
        let at = |t: f64, second: Option<u8>| {
            AisPosition {
                line: 0,
                message_type: 1,
                mmsi: 1,
                t: Some(t),
                t_resolution: Some(1.0),
                lat_deg: 0.0,
                lon_deg: 0.0,
                sog_knots: None,
                cog_deg: None,
                position_accurate: false,
                utc_second: second,
            }
            .time_of_applicability()
            .unwrap()
        };
        // 1 700 000 003 s is 22:13:23 UTC (1 700 000 003 mod 60 = 23).
        // Fixed at second 20: 3 s before, mid-second: 20.5 s.
        assert_eq!(at(1_700_000_003.0, Some(20)), 1_700_000_000.5);
        // Fixed in the same second: the receive time (never after it).
        assert_eq!(at(1_700_000_003.0, Some(23)), 1_700_000_003.0);
        // Across the minute: received at :23, fixed at :59 of the minute
        // before (24 s earlier), mid-second.
        assert_eq!(at(1_700_000_003.0, Some(59)), 1_699_999_979.5);
        // No second: the receive time.
        assert_eq!(at(1_700_000_003.0, None), 1_700_000_003.0);
    }

    /// gpsd's two-fragment type 5 example (static and voyage data of
    /// MMSI 351759000, "EVER DIADEM", call sign "3FOF8", IMO 9134270,
    /// destination "NEW YORK"); 424 bits after the 2 fill bits.
    #[test]
    fn two_fragment_type_5_is_reassembled_and_skipped() {
        let src = lines(&[
            "!AIVDM,2,1,1,A,55?MbV02;H;s<HtKR20EHE:0@T4@Dn2222222216L961O5Gf0NSQEp6ClRp8,0*1C",
            "!AIVDM,2,2,1,A,88888888880,2*25",
        ]);
        let d = decode(&src);
        assert_eq!(d.errors, vec![]);
        assert_eq!((d.sentences, d.messages), (2, 1));
        assert_eq!(d.skipped_by_type.get(&5), Some(&1));
        assert!(d.positions.is_empty());
        // The same reassembly by hand, to read the static fields.
        let mut bits =
            dearmour("55?MbV02;H;s<HtKR20EHE:0@T4@Dn2222222216L961O5Gf0NSQEp6ClRp8").unwrap();
        let mut b2 = dearmour("88888888880").unwrap();
        b2.truncate(b2.len() - 2);
        bits.extend(b2);
        assert_eq!(bits.len(), 424);
        let r = BitReader(&bits);
        assert_eq!(r.u(8, 30), Some(351_759_000));
        assert_eq!(r.u(40, 30), Some(9_134_270));
        assert_eq!(r.text(70, 7).as_deref(), Some("3FOF8"));
        assert_eq!(r.text(112, 20).as_deref(), Some("EVER DIADEM"));
        assert_eq!(r.text(302, 20).as_deref(), Some("NEW YORK"));
    }

    /// A NMEA 4.0 tag block with source and receive time; its checksum 0x74
    /// is the XOR of "s:r3669961,c:1712345678" (computed by hand with
    /// Python: functools.reduce(operator.xor, map(ord, s))).
    #[test]
    fn tag_block_gives_the_receive_time() {
        let line = format!(
            "\\s:r3669961,c:1712345678*{:02X}\\{TYPE1}",
            checksum("s:r3669961,c:1712345678")
        );
        assert_eq!(checksum("s:r3669961,c:1712345678"), 0x74);
        let d = decode(&[line]);
        assert_eq!(d.positions[0].t, Some(1_712_345_678.0));
        let bad = format!("\\c:1712345678*00\\{TYPE1}");
        let d = decode(&[bad]);
        assert!(d.positions.is_empty());
        assert!(d.errors[0].message.contains("tag block"));
    }

    #[test]
    fn bad_lines_are_reported_by_number_and_skipped() {
        let src = lines(&[
            "garbage",
            "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5D", // checksum off by one
            TYPE1,
            "",
            "!AIVDM,2,2,7,A,88888888880,2*23", // orphan fragment
            "!AIVDM,1,1,,B,1~~,0*00",
        ]);
        let d = decode(&src);
        assert_eq!(d.lines, 6);
        // A checksum field of two characters that are not two hex digits:
        // "+6" would parse as 0x06, this body's checksum (XOR by hand with
        // Python: functools.reduce(operator.xor, map(ord, body))).
        let body = "AIVDM,1,1,,,1P,0";
        assert_eq!(checksum(body), 0x06);
        assert_eq!(decode(&[format!("!{body}*06")]).sentences, 1);
        let d = decode(&[format!("!{body}*+6")]);
        assert!(d.errors[0].message.contains("bad checksum field"), "{d:?}");
        let d = decode(&src);
        assert_eq!(d.positions.len(), 1);
        let bad: Vec<usize> = d.errors.iter().map(|e| e.line).collect();
        assert_eq!(bad, vec![0, 1, 4, 5]);
        assert!(d.errors[1].message.contains("checksum"));
    }

    #[test]
    fn type_18_and_27_positions_with_their_scalings() {
        // Type 18: MMSI 123456789, SOG 12.3 kn, lon 4.5°, lat 52.1°, COG 45.6°.
        let mut w = BitWriter::default();
        w.put(18, 6);
        w.put(0, 2);
        w.put(123_456_789, 30);
        w.put(0, 8);
        w.put(123, 10);
        w.put(0, 1);
        w.put_signed(2_700_000, 28); // 4.5° × 600 000
        w.put_signed(31_260_000, 27); // 52.1° × 600 000
        w.put(456, 12);
        w.put(511, 9);
        while w.len() < 168 {
            w.put(0, 1);
        }
        // Type 27: lon −70.5° = −42 300 tenths of a minute, lat −33.25° = −19 950.
        let mut l = BitWriter::default();
        l.put(27, 6);
        l.put(0, 2);
        l.put(987_654_321, 30);
        l.put(0, 1);
        l.put(0, 1);
        l.put(0, 4);
        l.put_signed(-42_300, 18);
        l.put_signed(-19_950, 17);
        l.put(9, 6);
        l.put(270, 9);
        l.put(0, 1);
        l.put(0, 1);
        let src: Vec<String> = [w, l]
            .iter()
            .map(|w| {
                let (p, fill) = w.armoured();
                let body = format!("AIVDO,1,1,,A,{p},{fill}");
                format!("!{body}*{:02X}", checksum(&body))
            })
            .collect();
        let d = decode(&src);
        assert_eq!(d.errors, vec![]);
        let (a, b) = (&d.positions[0], &d.positions[1]);
        assert_eq!((a.message_type, a.mmsi), (18, 123_456_789));
        assert!((a.lon_deg - 4.5).abs() < 1e-12 && (a.lat_deg - 52.1).abs() < 1e-12);
        assert_eq!((a.sog_knots, a.cog_deg), (Some(12.3), Some(45.6)));
        assert_eq!((b.message_type, b.mmsi), (27, 987_654_321));
        assert!((b.lon_deg + 70.5).abs() < 1e-12 && (b.lat_deg + 33.25).abs() < 1e-12);
        assert_eq!((b.sog_knots, b.cog_deg), (Some(9.0), Some(270.0)));
    }

    /// What any decode must satisfy: counts within the lines, every error
    /// and position at a line that exists, errors in line order.
    fn sound(src: &[String], d: &Decoded) -> Result<(), proptest::test_runner::TestCaseError> {
        use proptest::prop_assert;
        prop_assert!(d.lines == src.len());
        let nonblank = src.iter().filter(|l| !l.trim().is_empty()).count();
        prop_assert!(d.sentences <= nonblank);
        prop_assert!(d.messages <= d.sentences);
        prop_assert!(d.positions.len() + d.skipped_by_type.values().sum::<usize>() <= d.messages);
        prop_assert!(d.errors.iter().all(|e| e.line < src.len()));
        prop_assert!(d.errors.windows(2).all(|w| w[0].line <= w[1].line));
        for p in &d.positions {
            prop_assert!(p.line < src.len());
            prop_assert!(p.lat_deg.abs() <= 90.0 && p.lon_deg.abs() <= 180.0);
        }
        Ok(())
    }

    /// `!{body}*hh` with the right checksum.
    fn sentence(body: &str) -> String {
        format!("!{body}*{:02X}", checksum(body))
    }

    /// Sentences whose checksum is right but whose fields are anything of
    /// the right shape or near it: talker, fragment numbers, ids, payload
    /// characters (a few outside the armour), fill bits, and a tag block
    /// whose time may not be a number.
    fn arb_framed_line() -> impl proptest::strategy::Strategy<Value = String> {
        use proptest::prelude::*;
        (
            prop_oneof![
                Just("AIVDM".to_string()),
                Just("AIVDO".to_string()),
                "[A-Z]{0,6}"
            ],
            0u32..12,
            0u32..12,
            "[0-9]{0,2}",
            "[AB12]?",
            "[0-W`-w~ ]{0,90}",
            0usize..8,
            proptest::option::of("[-+.eE0-9a-z:]{0,24}"),
            "(,[^,*]{0,4}){0,2}",
        )
            .prop_map(
                |(talker, count, number, seq, channel, payload, fill, tag, extra)| {
                    let body = format!(
                        "{talker},{count},{number},{seq},{channel},{payload},{fill}{extra}"
                    );
                    let line = sentence(&body);
                    match tag {
                        Some(t) => {
                            let tag = format!("c:{t}");
                            format!("\\{tag}*{:02X}\\{line}", checksum(&tag))
                        }
                        None => line,
                    }
                },
            )
    }

    /// A position report to encode: (type, MMSI, raw lon, raw lat, raw
    /// SOG, raw COG) in the units of its type's fields (ITU-R M.1371-5
    /// Tables 45 (types 1–3), 70 (18), 88 (27)), "not available" values
    /// included.
    fn arb_report() -> impl proptest::strategy::Strategy<Value = (u8, u32, i64, i64, u64, u64)> {
        use proptest::prelude::*;
        prop_oneof![
            (
                prop_oneof![Just(1u8), Just(2), Just(3), Just(18), Just(19)],
                any::<u32>().prop_map(|m| m % 1_000_000_000),
                -108_000_000i64..=108_000_000, // ±180° in 1/10 000 min
                -54_000_000i64..=54_000_000,   // ±90°
                0u64..=1023,                   // 1/10 kn, 1023: n/a
                0u64..=3600,                   // 1/10°, 3600: n/a
            ),
            (
                Just(27u8),
                any::<u32>().prop_map(|m| m % 1_000_000_000),
                -108_000i64..=108_000, // ±180° in 1/10 min
                -54_000i64..=54_000,
                0u64..=63,                          // kn, 63: n/a
                prop_oneof![0u64..=359, Just(511)], // °, 511: n/a
            ),
        ]
    }

    /// The payload bits of a report, field by field as the tables lay them
    /// out (spare and unused fields zero).
    fn report_bits(r: &(u8, u32, i64, i64, u64, u64)) -> BitWriter {
        let &(kind, mmsi, lon, lat, sog, cog) = r;
        let mut w = BitWriter::default();
        w.put(u64::from(kind), 6);
        w.put(0, 2); // repeat indicator
        w.put(u64::from(mmsi), 30);
        match kind {
            27 => {
                w.put(0, 1 + 1 + 4); // accuracy, RAIM, status
                w.put_signed(lon, 18);
                w.put_signed(lat, 17);
                w.put(sog, 6);
                w.put(cog, 9);
                w.put(0, 2); // GNSS status, spare: 96 bits
            }
            18 | 19 => {
                w.put(0, 8); // regional reserved
                w.put(sog, 10);
                w.put(0, 1); // accuracy
                w.put_signed(lon, 28);
                w.put_signed(lat, 27);
                w.put(cog, 12);
                w.put(511, 9); // heading n/a
                while w.len() < 168 {
                    w.put(0, 1);
                }
            }
            _ => {
                w.put(0, 4 + 8); // status, rate of turn
                w.put(sog, 10);
                w.put(0, 1); // accuracy
                w.put_signed(lon, 28);
                w.put_signed(lat, 27);
                w.put(cog, 12);
                w.put(511, 9); // heading n/a
                while w.len() < 168 {
                    w.put(0, 1);
                }
            }
        }
        w
    }

    /// The report as lines: its armoured payload cut into `parts` fragments
    /// (fill bits on the last), sequential id `seq`, a tag block with time
    /// `t` on the first when given.
    fn report_lines(w: &BitWriter, parts: usize, seq: usize, t: Option<u32>) -> Vec<String> {
        let (payload, fill) = w.armoured();
        let chars: Vec<char> = payload.chars().collect();
        let parts = parts.clamp(1, chars.len());
        let size = chars.len().div_ceil(parts);
        let pieces: Vec<String> = chars.chunks(size).map(|c| c.iter().collect()).collect();
        let n = pieces.len();
        let seq = if n == 1 {
            String::new()
        } else {
            seq.to_string()
        };
        pieces
            .iter()
            .enumerate()
            .map(|(k, piece)| {
                let fill = if k + 1 == n { fill } else { 0 };
                let line = sentence(&format!("AIVDM,{n},{},{seq},A,{piece},{fill}", k + 1));
                match t.filter(|_| k == 0) {
                    Some(t) => {
                        let tag = format!("c:{t}");
                        format!("\\{tag}*{:02X}\\{line}", checksum(&tag))
                    }
                    None => line,
                }
            })
            .collect()
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(256))]

        /// Any lines at all (any Unicode, any bytes read as text): a count
        /// of what was found and errors by line, never a panic.
        #[test]
        fn arbitrary_lines_never_panic(
            src in proptest::collection::vec(".{0,120}", 0..24),
            bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..2_048),
        ) {
            let d = decode(&src);
            sound(&src, &d)?;
            let text: Vec<String> = String::from_utf8_lossy(&bytes)
                .split('\n')
                .map(str::to_string)
                .collect();
            let d = decode(&text);
            sound(&text, &d)?;
        }

        /// Lines that pass the checksum with fields of any value: deeper
        /// into framing, fragments and payloads, still never a panic.
        #[test]
        fn framed_lines_with_odd_fields_never_panic(
            src in proptest::collection::vec(arb_framed_line(), 0..24),
        ) {
            let d = decode(&src);
            sound(&src, &d)?;
        }

        /// Position reports encoded field by field, in 1 to 3 fragments,
        /// some with a receive time, are decoded to the values encoded:
        /// degrees = raw / scale, "not available" SOG and COG as `None`.
        #[test]
        fn encoded_position_reports_round_trip(
            reports in proptest::collection::vec(
                (arb_report(), 1usize..=3, proptest::option::of(1_000_000_000u32..2_000_000_000)),
                1..6,
            ),
        ) {
            use proptest::prop_assert_eq;
            let mut src = Vec::new();
            for (i, (r, parts, t)) in reports.iter().enumerate() {
                src.extend(report_lines(&report_bits(r), *parts, i % 10, *t));
            }
            let d = decode(&src);
            sound(&src, &d)?;
            prop_assert_eq!(&d.errors, &vec![]);
            prop_assert_eq!(d.positions.len(), reports.len());
            for (p, ((kind, mmsi, lon, lat, sog, cog), _, t)) in d.positions.iter().zip(&reports) {
                let (scale, sog_na, sog_scale, cog_na, cog_scale) = if *kind == 27 {
                    (600.0, 63, 1.0, 511, 1.0)
                } else {
                    (600_000.0, 1023, 10.0, 3600, 10.0)
                };
                prop_assert_eq!((p.message_type, p.mmsi), (*kind, *mmsi));
                prop_assert_eq!(p.lon_deg, *lon as f64 / scale);
                prop_assert_eq!(p.lat_deg, *lat as f64 / scale);
                prop_assert_eq!(p.sog_knots, (*sog != sog_na).then(|| *sog as f64 / sog_scale));
                prop_assert_eq!(p.cog_deg, (*cog != cog_na).then(|| *cog as f64 / cog_scale));
                prop_assert_eq!(p.t, t.map(f64::from));
            }
        }
    }
}
