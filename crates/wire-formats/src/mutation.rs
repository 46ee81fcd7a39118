//! Test-only (this crate's tests, and `formats`' through the `mutation`
//! feature): proptest strategies that mutate valid encodings, so that the
//! never-panics properties of the decoders reach past their first checks
//! (magic, version, lengths) into the fields behind them. A mutation is a
//! short list of edits of the kinds a corrupt store or a hostile sender
//! makes: bytes set or flipped, a length-sized word overwritten with an
//! extreme value, bytes inserted or removed, the end cut off.

use proptest::prelude::*;

/// One edit of a byte string; positions are taken modulo its length.
#[derive(Debug, Clone)]
pub enum Edit {
    Set(usize, u8),
    Xor(usize, u8),
    /// A little-endian u64 written over 8 bytes (a length, a count, an
    /// index, an f64's bits).
    Word(usize, u64),
    Insert(usize, Vec<u8>),
    Remove(usize, usize),
    Truncate(usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    let extreme = prop_oneof![
        Just(0u64),
        Just(1),
        Just(u64::from(u32::MAX)),
        Just(1 << 32),
        Just(u64::MAX),
        Just(f64::NAN.to_bits()),
        Just(f64::INFINITY.to_bits()),
        Just((-1.0f64).to_bits()),
        any::<u64>(),
    ];
    prop_oneof![
        3 => (any::<usize>(), any::<u8>()).prop_map(|(i, v)| Edit::Set(i, v)),
        3 => (any::<usize>(), 1..=255u8).prop_map(|(i, v)| Edit::Xor(i, v)),
        3 => (any::<usize>(), extreme).prop_map(|(i, v)| Edit::Word(i, v)),
        1 => (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(i, v)| Edit::Insert(i, v)),
        1 => (any::<usize>(), 1..16usize).prop_map(|(i, n)| Edit::Remove(i, n)),
        1 => any::<usize>().prop_map(Edit::Truncate),
    ]
}

/// 1 to 6 edits.
pub fn edits() -> impl Strategy<Value = Vec<Edit>> {
    proptest::collection::vec(edit(), 1..=6)
}

/// `bytes` with `edits` applied in order.
pub fn apply(bytes: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    for e in edits {
        let at = |i: usize, b: &Vec<u8>| if b.is_empty() { 0 } else { i % b.len() };
        match e {
            Edit::Set(i, v) if !b.is_empty() => {
                let i = at(*i, &b);
                b[i] = *v;
            }
            Edit::Xor(i, v) if !b.is_empty() => {
                let i = at(*i, &b);
                b[i] ^= *v;
            }
            Edit::Word(i, v) if b.len() >= 8 => {
                let i = i % (b.len() - 7);
                b[i..i + 8].copy_from_slice(&v.to_le_bytes());
            }
            Edit::Insert(i, v) => {
                let i = if b.is_empty() { 0 } else { i % (b.len() + 1) };
                b.splice(i..i, v.iter().copied());
            }
            Edit::Remove(i, n) if !b.is_empty() => {
                let i = at(*i, &b);
                let end = (i + n).min(b.len());
                b.drain(i..end);
            }
            Edit::Truncate(i) => {
                let n = if b.is_empty() { 0 } else { i % b.len() };
                b.truncate(n);
            }
            _ => {}
        }
    }
    b
}
