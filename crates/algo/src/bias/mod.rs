//! AIS–radar association and radar bias estimation (seed 004: Qi Lin et al.,
//! anti-bias association of AIS and sea radar tracks by bias detection):
//! `projection` (Gauss–Krüger about the radar's meridian), `nmea` (AIVDM
//! decoding), `cfar` (eqs. 7–10), `associate` (alignment, eq. 6, estimation,
//! re-association, robust seeding).

pub mod associate;
pub mod cfar;
pub mod projection;
