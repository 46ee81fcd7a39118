//! The record walker shared by every category: an FSPEC, then the items
//! it flags in FRN order, each of a length known only from the category's
//! User Application Profile (UAP) by one of the rules of [`Len`].
//!
//! An FSPEC is octets whose low bit FX says another follows; bit 8 of the
//! first octet is FRN 1, bit 2 FRN 7, bit 8 of the second FRN 8, … The
//! walker hands each item's bytes to the category's reader and returns
//! where the record ends, or the offset and reason of the first problem
//! (a record has no length of its own: a problem loses the rest of its
//! block). Readers are given exactly the bytes the rule allows, so they
//! index fixed items freely and reach optional octets (extensions,
//! subfields) through [`each_subfield`] or `get`.

/// The length rule of an item or subfield.
#[derive(Debug, Clone, Copy)]
pub(super) enum Len {
    /// Always this many bytes.
    Fixed(usize),
    /// Octets until one with FX (bit 1) clear; also the rule of a
    /// "repetitive FX" item of one-octet parts (I020/030).
    Extended,
    /// A one-byte count REP, then REP parts of this size.
    Repetitive(usize),
    /// The first byte is the item's length, itself included (SP, RE).
    Explicit,
    /// A primary subfield (extended: 7 flags an octet) flagging these
    /// subfields, in order; `None` is a spare flag (must be clear).
    Compound(&'static [Option<Len>]),
}

/// An item of a UAP.
#[derive(Debug, Clone, Copy)]
pub(super) struct Item {
    pub(super) name: &'static str,
    pub(super) len: Len,
}

pub(super) const fn item(name: &'static str, len: Len) -> Option<Item> {
    Some(Item { name, len })
}

/// The offset (in the block) and reason of a problem.
pub(super) type Failure = (usize, String);

/// Walks the record at `start` of `block` by the `uap` of category `cat`
/// (index 0 is FRN 1, `None` a spare FRN): calls `read(frn, bytes)` for
/// each item flagged, in FRN order, and returns the offset just past the
/// record.
pub(super) fn walk(
    cat: u8,
    uap: &[Option<Item>],
    block: &[u8],
    start: usize,
    mut read: impl FnMut(usize, &[u8]),
) -> Result<usize, Failure> {
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
    for frn in frns {
        let Some(Some(it)) = uap.get(frn - 1) else {
            return Err((
                start,
                format!("the FSPEC flags FRN {frn}, which the CAT {cat:03} UAP does not define"),
            ));
        };
        let end = skip(it.name, it.len, block, pos)?;
        read(frn, &block[pos..end]);
        pos = end;
    }
    Ok(pos)
}

/// Calls `each(index, bytes)` for the subfields (index 0 is the first)
/// of a compound item `v` of `rules`, as [`walk`] handed it over (so its
/// lengths are already checked).
pub(super) fn each_subfield(
    rules: &'static [Option<Len>],
    v: &[u8],
    each: impl FnMut(usize, &[u8]),
) {
    // `v` passed `skip` with these rules: this cannot fail, and if it
    // could, the reader would only miss the subfields after the problem.
    let _ = compound("compound item", rules, v, 0, each);
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
        Len::Fixed(n) => {
            if pos + n > block.len() {
                return Err(past(n));
            }
            Ok(pos + n)
        }
        Len::Extended => {
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
        Len::Repetitive(part) => {
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
        Len::Explicit => {
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
        Len::Compound(rules) => compound(name, rules, block, pos, |_, _| {}),
    }
}

/// Walks the compound item at `pos`: its primary subfield (7 flags an
/// octet, FX to go on), then each flagged subfield by its rule, handed to
/// `each(index, bytes)`. Returns the end of the item.
fn compound(
    name: &str,
    rules: &[Option<Len>],
    block: &[u8],
    pos: usize,
    mut each: impl FnMut(usize, &[u8]),
) -> Result<usize, Failure> {
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
        if octet * 7 + 7 >= rules.len() {
            return Err((
                p - 1,
                format!(
                    "{name}: the primary subfield goes on past its {} subfields",
                    rules.len()
                ),
            ));
        }
    }
    for i in flagged {
        let Some(Some(rule)) = rules.get(i) else {
            return Err((
                pos,
                format!(
                    "{name}: the primary subfield flags subfield {}, which is spare or undefined",
                    i + 1
                ),
            ));
        };
        let end = skip(name, *rule, block, p)?;
        each(i, &block[p..end]);
        p = end;
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SUBFIELDS: &[Option<Len>] = &[
        Some(Len::Fixed(2)),
        None,
        Some(Len::Extended),
        Some(Len::Repetitive(3)),
        Some(Len::Explicit),
        Some(Len::Fixed(1)),
        Some(Len::Fixed(1)),
        Some(Len::Fixed(1)),
    ];

    #[test]
    fn a_compound_item_hands_over_each_subfield_in_order() {
        // Primary 0xA9 0x00: subfields 1 (bit 8), 3 (bit 6), 5 (bit 4),
        // FX; second octet none. Then 2 bytes, an extended 0x01 0x00,
        // an explicit of length 2.
        let v = [0xA9, 0x00, 7, 8, 0x01, 0x00, 2, 9];
        let mut seen = Vec::new();
        let end = compound("I000/000", SUBFIELDS, &v, 0, |i, b| {
            seen.push((i, b.to_vec()))
        });
        assert_eq!(end, Ok(v.len()));
        assert_eq!(
            seen,
            vec![(0, vec![7, 8]), (2, vec![0x01, 0x00]), (4, vec![2, 9])]
        );
        // A repetitive subfield (flag bit 5 of the first octet: 0x10):
        // REP 2 × 3 bytes.
        let v = [0x10, 2, 1, 2, 3, 4, 5, 6];
        assert_eq!(compound("x", SUBFIELDS, &v, 0, |_, _| {}), Ok(8));
    }

    #[test]
    fn a_compound_item_refuses_spare_flags_and_overlong_primaries() {
        // Subfield 2 is spare (bit 7 of the first octet).
        let e = compound("I000/000", SUBFIELDS, &[0x40], 0, |_, _| {}).unwrap_err();
        assert!(e.1.contains("spare"), "{e:?}");
        // Eight subfields take two primary octets; a third is too many.
        let e = compound("I000/000", SUBFIELDS, &[0x01, 0x01, 0x00], 0, |_, _| {}).unwrap_err();
        assert_eq!(e.0, 1);
        assert!(e.1.contains("goes on past"), "{e:?}");
        // Subfield 8 (second octet, bit 8) is flagged but cut.
        let e = compound("I000/000", SUBFIELDS, &[0x01, 0x80], 0, |_, _| {}).unwrap_err();
        assert!(e.1.contains("needs 1 byte"), "{e:?}");
    }
}
