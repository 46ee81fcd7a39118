//! Wire formats of the radar fusion service, with no dependency on the
//! numerical core: EUROCONTROL ASTERIX input ([`asterix`]: CAT048 target
//! reports, CAT034 service messages, CAT021 ADS-B and CAT020
//! multilateration target reports), ASTERIX CAT062 SDPS track output
//! ([`cat062`]), NMEA 0183 AIS sentences ([`nmea`]: `!AIVDM`/`!AIVDO`), and
//! the bounds-checked little-endian byte [`wire`] `Reader`/`Writer` on which
//! stored state is encoded (the stored-state codecs themselves are in
//! `formats`, which depends on the numerical core).
//!
//! Decoders never panic on any input: every error carries where it was
//! found and why, and decoding resumes at the next unit it can trust (the
//! next ASTERIX data block, the next NMEA line).
//! [`cat062`] encodes ASTERIX CAT062 SDPS track output, never panicking either.

pub mod asterix;
pub mod cat062;
pub mod nmea;
pub mod wire;

#[cfg(any(test, feature = "mutation"))]
#[doc(hidden)]
pub mod mutation;
