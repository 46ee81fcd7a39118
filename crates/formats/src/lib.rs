//! Byte formats of the radar fusion service: EUROCONTROL ASTERIX input
//! ([`asterix`]: CAT048 target reports, CAT034 service messages, CAT021
//! ADS-B and CAT020 multilateration target reports), NMEA 0183
//! AIS sentences ([`nmea`]: `!AIVDM`/`!AIVDO`), and the stored-state codecs
//! of streaming sessions ([`wire`], [`state`]).
//!
//! Decoders never panic on any input: every error carries where it was
//! found and why, and decoding resumes at the next unit it can trust (the
//! next ASTERIX data block, the next NMEA line).
//! [`cat062`] encodes ASTERIX CAT062 SDPS track output, never panicking either.

pub mod asterix;
pub mod cat062;
pub mod nmea;
pub mod state;
pub mod wire;

#[cfg(test)]
mod mutation;
