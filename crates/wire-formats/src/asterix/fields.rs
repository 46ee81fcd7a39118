//! Field encodings shared by the categories: big-endian integers, two's
//! complement, the ICAO 6-bit character set of identifications, the
//! validity bits of SSR reply items.

pub(super) fn u16_at(v: &[u8], i: usize) -> u16 {
    u16::from_be_bytes([v[i], v[i + 1]])
}

pub(super) fn u24_at(v: &[u8], i: usize) -> u32 {
    (v[i] as u32) << 16 | (v[i + 1] as u32) << 8 | v[i + 2] as u32
}

pub(super) fn u32_at(v: &[u8], i: usize) -> u32 {
    u32::from_be_bytes([v[i], v[i + 1], v[i + 2], v[i + 3]])
}

/// The low `bits` of `raw` as a two's complement number.
pub(super) fn signed(raw: u32, bits: u32) -> i32 {
    let shift = 32 - bits;
    ((raw << shift) as i32) >> shift
}

/// A time of day of 3 bytes, 1/128 s (I048/140, I021/071, I020/140, …),
/// in seconds since midnight UTC.
pub(super) fn time_of_day(v: &[u8], i: usize) -> f64 {
    u24_at(v, i) as f64 / 128.0
}

/// The ICAO 6-bit character set of identifications (Annex 10 vol. IV,
/// table 3-9): 1–26 are A–Z, 32 space, 48–57 the digits; anything else is
/// not a character of an identification.
fn ia5(c: u8) -> Option<char> {
    match c {
        1..=26 => Some((b'A' + c - 1) as char),
        32 => Some(' '),
        48..=57 => Some((b'0' + c - 48) as char),
        _ => None,
    }
}

/// Eight 6-bit characters in the 48 bits `v[..6]` (I048/240, I021/170,
/// I020/245), space-padded; `None` when a character is outside the set or
/// all are spaces. Trailing spaces are removed.
pub(super) fn callsign(v: &[u8]) -> Option<String> {
    let bits = v[..6].iter().fold(0u64, |acc, &b| acc << 8 | b as u64);
    let text: Option<String> = (0..8)
        .map(|i| ia5(((bits >> (42 - 6 * i)) & 0x3F) as u8))
        .collect();
    text.map(|t| t.trim_end().to_string())
        .filter(|t| !t.is_empty())
}

/// The validity bits of an SSR reply item (I048/070, I048/090, I020/070,
/// I020/090).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReplyFlags {
    /// V = 0: validated.
    pub validated: bool,
    /// G = 1: garbled.
    pub garbled: bool,
    /// L = 1 (Mode 3/A items only): the code was not extracted during
    /// the last scan (smoothed).
    pub smoothed: bool,
}

impl ReplyFlags {
    pub(super) fn of(word: u16, has_l: bool) -> Self {
        Self {
            validated: word & 0x8000 == 0,
            garbled: word & 0x4000 != 0,
            smoothed: has_l && word & 0x2000 != 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_fields_are_twos_complement() {
        // 0x0200 is −512 (the most negative 10-bit value), 0x01FF is +511.
        assert_eq!(signed(0x0200, 10), -512);
        assert_eq!(signed(0x01FF, 10), 511);
        assert_eq!(signed(0x2000, 14), -8192);
        assert_eq!(signed(0xFFFF_FFFF, 32), -1);
        assert_eq!(signed(0x80_0000, 24), -8_388_608);
    }

    #[test]
    fn identifications_use_the_icao_six_bit_set() {
        // "EZY1" + 4 spaces: E = 5, Z = 26, Y = 25, '1' = 49, ' ' = 32:
        // 000101 011010 011001 110001 100000 ×4 = 0x15 0xA6 0x71 0x82
        // 0x08 0x20.
        assert_eq!(
            callsign(&[0x15, 0xA6, 0x71, 0x82, 0x08, 0x20]).as_deref(),
            Some("EZY1")
        );
        // A character outside the set (0) makes no identification, and
        // eight spaces (0x82 0x08 0x20 twice) none either.
        assert_eq!(callsign(&[0, 0, 0, 0, 0, 0]), None);
        assert_eq!(callsign(&[0x82, 0x08, 0x20, 0x82, 0x08, 0x20]), None);
    }
}
