//! The stored-state codecs of streaming sessions ([`state`]): the bytes a
//! session keeps of the numerical core's state (`algo`), written with the
//! byte `Reader`/`Writer` of [`wire_formats::wire`].
//!
//! The wire formats themselves (ASTERIX, CAT062, NMEA) are in the
//! `wire-formats` crate, which does not depend on `algo`.
//! Decoders never panic on any input: a corrupt stored session is a
//! [`wire_formats::wire::FormatError`].

pub mod state;

#[cfg(test)]
mod tests {
    /// The wire formats keep their own foot (they do not depend on `algo`);
    /// it is the numerical core's, exactly.
    #[test]
    fn the_wire_formats_foot_is_the_cores() {
        assert_eq!(
            wire_formats::asterix::FT_M.to_bits(),
            algo::tracking::height::FT_M.to_bits()
        );
    }
}
