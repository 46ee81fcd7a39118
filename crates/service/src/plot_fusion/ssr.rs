//! Secondary surveillance at the service's edge: a plot's SSR and Mode S
//! fields as a client sends them ([`SsrInput`], flat beside the plot's
//! position on the wire), parsed into the tracker's
//! [`algo::tracking::Identity`], and what a track has learnt of its
//! aircraft as a client reads it ([`IdentityView`]), with the warnings
//! that identity calls for (emergency codes, two tracks of one address).
//!
//! Wire forms: a Mode 3/A code is four octal digits (`"7000"`); a Mode S
//! address six hexadecimal digits (`"4CA2D1"`, any case); a flight level
//! a number of hundreds of feet (FL 350.25 = 35,025 ft, −12 to 1,270 as
//! I048/090 carries it); a callsign up to eight of A–Z, 0–9 and space
//! (the ICAO character set of I048/240); the detection type `primary`,
//! `secondary` or `combined`. The validated flags default to true (a radar
//! that does not say has validated), the garbled flags to false.

use algo::tracking::identity::{Evidence, FLIGHT_LEVEL_RANGE, MAX_ADDRESS};
use algo::tracking::{Detection, Emergency, Identity, Mode3A, ModeC, TrackIdentity, TrackOutput};
use wire_formats::asterix::FT_M;
use wire_formats::wire::{FormatError, Reader, Writer};

/// A plot's secondary fields as received (every one optional).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SsrInput {
    /// Mode 3/A code, four octal digits.
    pub mode_3a: Option<String>,
    pub mode_3a_validated: Option<bool>,
    pub mode_3a_garbled: Option<bool>,
    /// Mode C flight level (hundreds of feet).
    pub flight_level: Option<f64>,
    pub flight_level_validated: Option<bool>,
    pub flight_level_garbled: Option<bool>,
    /// Mode S address, six hexadecimal digits.
    pub mode_s_address: Option<String>,
    /// Aircraft identification.
    pub callsign: Option<String>,
    /// `primary`, `secondary` or `combined`.
    pub detection: Option<String>,
    /// Special position identification.
    pub spi: Option<bool>,
}

impl SsrInput {
    /// Nothing given.
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// The fields of a decoded ASTERIX target report.
    pub fn from_asterix(r: &wire_formats::asterix::TargetReport) -> Self {
        Self {
            mode_3a: r.mode_3a.map(|c| format!("{c:04o}")),
            // A code not extracted in this scan (L = 1: the radar's
            // smoothed code, as a primary-only report may carry) is
            // not taken as validated.
            mode_3a_validated: r.mode_3a_flags.map(|f| f.validated && !f.smoothed),
            mode_3a_garbled: r.mode_3a_flags.map(|f| f.garbled),
            flight_level: r.flight_level,
            flight_level_validated: r.flight_level_flags.map(|f| f.validated),
            flight_level_garbled: r.flight_level_flags.map(|f| f.garbled),
            mode_s_address: r.aircraft_address.map(|a| format!("{a:06X}")),
            callsign: r.callsign.clone(),
            detection: r.descriptor.and_then(|d| match d.typ {
                1 => Some("primary".to_string()),
                2 | 4 | 5 => Some("secondary".to_string()),
                3 | 6 | 7 => Some("combined".to_string()),
                _ => None,
            }),
            spi: r.descriptor.map(|d| d.spi).filter(|&s| s),
        }
    }

    /// The tracker's identity, or the name of the bad field and why.
    pub fn parse(&self) -> Result<Identity, (&'static str, String)> {
        let mode_3a = match &self.mode_3a {
            None => None,
            Some(s) => Some(Mode3A {
                code: parse_code(s).ok_or_else(|| {
                    (
                        "mode_3a",
                        format!("must be four octal digits (0000 to 7777), got '{s}'"),
                    )
                })?,
                validated: self.mode_3a_validated.unwrap_or(true),
                garbled: self.mode_3a_garbled.unwrap_or(false),
            }),
        };
        if mode_3a.is_none() && (self.mode_3a_validated.is_some() || self.mode_3a_garbled.is_some())
        {
            let name = if self.mode_3a_validated.is_some() {
                "mode_3a_validated"
            } else {
                "mode_3a_garbled"
            };
            return Err((name, "given without mode_3a".to_string()));
        }
        let mode_c = match self.flight_level {
            None => None,
            Some(fl) => {
                let (lo, hi) = FLIGHT_LEVEL_RANGE;
                if !(fl.is_finite() && (lo..=hi).contains(&fl)) {
                    return Err((
                        "flight_level",
                        format!("must lie in [{lo}, {hi}] (hundreds of feet), got {fl}"),
                    ));
                }
                Some(ModeC {
                    flight_level: fl,
                    validated: self.flight_level_validated.unwrap_or(true),
                    garbled: self.flight_level_garbled.unwrap_or(false),
                })
            }
        };
        if mode_c.is_none()
            && (self.flight_level_validated.is_some() || self.flight_level_garbled.is_some())
        {
            let name = if self.flight_level_validated.is_some() {
                "flight_level_validated"
            } else {
                "flight_level_garbled"
            };
            return Err((name, "given without flight_level".to_string()));
        }
        let address = match &self.mode_s_address {
            None => None,
            Some(s) => Some(parse_address(s).ok_or_else(|| {
                (
                    "mode_s_address",
                    format!("must be six hexadecimal digits (24 bits), got '{s}'"),
                )
            })?),
        };
        let callsign = match &self.callsign {
            None => None,
            Some(s) => Some(parse_callsign(s).ok_or_else(|| {
                (
                    "callsign",
                    format!("must be 1 to 8 characters of A-Z, 0-9 and space (ICAO), got '{s}'"),
                )
            })?),
        };
        let detection = match self.detection.as_deref() {
            None => None,
            Some("primary") => Some(Detection::Primary),
            Some("secondary") => Some(Detection::Secondary),
            Some("combined") => Some(Detection::Combined),
            Some(other) => {
                return Err((
                    "detection",
                    format!("must be primary, secondary or combined, got '{other}'"),
                ));
            }
        };
        Ok(Identity {
            address,
            mode_3a,
            mode_c,
            callsign,
            detection,
            spi: self.spi.unwrap_or(false),
            // A ship's, from its AIS report (report::ReportInput::mmsi).
            mmsi: None,
        })
    }

    /// Appends the fields to a session's log entry.
    pub fn encode(&self, w: &mut Writer) {
        for s in [
            &self.mode_3a,
            &self.mode_s_address,
            &self.callsign,
            &self.detection,
        ] {
            w.opt(s.as_deref(), Writer::str);
        }
        w.opt(self.flight_level, Writer::f64);
        for b in [
            self.mode_3a_validated,
            self.mode_3a_garbled,
            self.flight_level_validated,
            self.flight_level_garbled,
            self.spi,
        ] {
            w.opt(b, Writer::bool);
        }
    }

    /// Reads what [`SsrInput::encode`] wrote.
    pub fn decode(r: &mut Reader<'_>) -> Result<Self, FormatError> {
        let mode_3a = r.opt(Reader::str)?;
        let mode_s_address = r.opt(Reader::str)?;
        let callsign = r.opt(Reader::str)?;
        let detection = r.opt(Reader::str)?;
        let flight_level = r.opt(Reader::f64)?;
        Ok(Self {
            mode_3a,
            mode_3a_validated: r.opt(Reader::bool)?,
            mode_3a_garbled: r.opt(Reader::bool)?,
            flight_level,
            flight_level_validated: r.opt(Reader::bool)?,
            flight_level_garbled: r.opt(Reader::bool)?,
            mode_s_address,
            callsign,
            detection,
            spi: r.opt(Reader::bool)?,
        })
    }
}

/// Four octal digits.
pub fn parse_code(s: &str) -> Option<u16> {
    (s.len() == 4 && s.bytes().all(|b| (b'0'..=b'7').contains(&b)))
        .then(|| u16::from_str_radix(s, 8).ok())
        .flatten()
}

/// Six hexadecimal digits (24 bits).
pub fn parse_address(s: &str) -> Option<u32> {
    (s.len() == 6 && s.bytes().all(|b| b.is_ascii_hexdigit()))
        .then(|| u32::from_str_radix(s, 16).ok())
        .flatten()
        .filter(|&a| a <= MAX_ADDRESS)
}

/// 1 to 8 characters of the ICAO set, stored space-padded; trailing
/// spaces are padding.
pub fn parse_callsign(s: &str) -> Option<[u8; 8]> {
    let trimmed = s.trim_end();
    if trimmed.is_empty()
        || s.len() > 8
        || !s
            .bytes()
            .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b' ')
    {
        return None;
    }
    let mut out = [b' '; 8];
    out[..s.len()].copy_from_slice(s.as_bytes());
    Some(out)
}

/// A callsign without its padding.
pub fn callsign_text(c: &[u8; 8]) -> String {
    String::from_utf8_lossy(c).trim_end().to_string()
}

/// One identity of a track and its evidence.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentityItem {
    pub value: String,
    /// Plots associated with the track that gave it.
    pub plots: u32,
    pub first_t: f64,
    pub last_t: f64,
}

/// The pressure altitude of a track (its own filter, apart from the
/// geometric height).
#[derive(Debug, Clone, PartialEq)]
pub struct PressureAltitudeView {
    /// Time of the estimate: the track's (predicted from the last Mode C
    /// used).
    pub t: f64,
    /// Filtered flight level (hundreds of feet).
    pub flight_level: f64,
    pub flight_level_sigma: f64,
    /// Rate of climb (ft/min, positive up).
    pub rate_of_climb_ftpm: f64,
    pub rate_of_climb_sigma_ftpm: f64,
    /// The last Mode C flight level used, and its time.
    pub measured_flight_level: f64,
    pub measured_t: f64,
}

/// What a track knows of its aircraft.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentityView {
    pub mode_s_address: Option<IdentityItem>,
    pub mode_3a: Option<IdentityItem>,
    /// A new code replies have given, not yet adopted.
    pub pending_mode_3a: Option<IdentityItem>,
    pub callsign: Option<IdentityItem>,
    pub pressure_altitude: Option<PressureAltitudeView>,
    /// `unlawful_interference` (7500), `radio_failure` (7600) or
    /// `emergency` (7700).
    pub emergency: Option<&'static str>,
    /// SPI set by a reply in the last 18 s.
    pub spi: bool,
    /// Times of the last update by a radar's secondary plot, Mode S plot
    /// and primary (or combined) plot (a cooperative report dates none:
    /// `TrackView::sources` has its time).
    pub last_secondary_t: Option<f64>,
    pub last_mode_s_t: Option<f64>,
    pub last_primary_t: Option<f64>,
}

fn item<T: Copy>(e: Option<Evidence<T>>, text: impl Fn(T) -> String) -> Option<IdentityItem> {
    e.map(|e| IdentityItem {
        value: text(e.value),
        plots: e.plots,
        first_t: e.first_t,
        last_t: e.last_t,
    })
}

/// A track's identity as a client reads it at the track's time `t`;
/// `None` when it has learnt nothing.
pub fn view(id: &TrackIdentity, t: f64) -> Option<IdentityView> {
    if id.is_empty() {
        return None;
    }
    let code = |c: u16| format!("{c:04o}");
    Some(IdentityView {
        mode_s_address: item(id.address, |a| format!("{a:06X}")),
        mode_3a: item(id.mode_3a, code),
        pending_mode_3a: item(id.pending_3a, code),
        callsign: item(id.callsign, |c| callsign_text(&c)),
        // At the track's time, like its position (the filter's own time
        // is its last Mode C: seconds earlier when later plots had none).
        pressure_altitude: id.altitude.map(|a| {
            let (x, p) = a.predicted(t.max(a.t));
            PressureAltitudeView {
                t: t.max(a.t),
                flight_level: x[0] / 100.0,
                flight_level_sigma: p[0].max(0.0).sqrt() / 100.0,
                rate_of_climb_ftpm: x[1] * 60.0,
                rate_of_climb_sigma_ftpm: p[2].max(0.0).sqrt() * 60.0,
                measured_flight_level: a.measured.0 / 100.0,
                measured_t: a.measured.1,
            }
        }),
        emergency: id.emergency().map(Emergency::name),
        spi: id.spi(t),
        last_secondary_t: id.last_secondary,
        last_mode_s_t: id.last_mode_s,
        last_primary_t: id.last_primary,
    })
}

fn encode_item(w: &mut Writer, i: Option<&IdentityItem>) {
    w.opt(i, |w, i| {
        w.str(&i.value);
        w.u32(i.plots);
        w.f64(i.first_t);
        w.f64(i.last_t);
    });
}

fn decode_item(r: &mut Reader<'_>) -> Result<Option<IdentityItem>, FormatError> {
    r.opt(|r| {
        Ok(IdentityItem {
            value: r.str()?,
            plots: r.u32()?,
            first_t: r.f64()?,
            last_t: r.f64()?,
        })
    })
}

/// A kept update's track identity, for [`decode_view`].
pub fn encode_view(w: &mut Writer, v: Option<&IdentityView>) {
    w.opt(v, |w, v| {
        encode_item(w, v.mode_s_address.as_ref());
        encode_item(w, v.mode_3a.as_ref());
        encode_item(w, v.pending_mode_3a.as_ref());
        encode_item(w, v.callsign.as_ref());
        w.opt(v.pressure_altitude.as_ref(), |w, a| {
            for x in [
                a.t,
                a.flight_level,
                a.flight_level_sigma,
                a.rate_of_climb_ftpm,
                a.rate_of_climb_sigma_ftpm,
                a.measured_flight_level,
                a.measured_t,
            ] {
                w.f64(x);
            }
        });
        w.opt(v.emergency, Writer::str);
        w.bool(v.spi);
        for t in [v.last_secondary_t, v.last_mode_s_t, v.last_primary_t] {
            w.opt(t, Writer::f64);
        }
    });
}

/// Reads what [`encode_view`] wrote.
pub fn decode_view(r: &mut Reader<'_>) -> Result<Option<IdentityView>, FormatError> {
    r.opt(|r| {
        Ok(IdentityView {
            mode_s_address: decode_item(r)?,
            mode_3a: decode_item(r)?,
            pending_mode_3a: decode_item(r)?,
            callsign: decode_item(r)?,
            pressure_altitude: r.opt(|r| {
                Ok(PressureAltitudeView {
                    t: r.f64()?,
                    flight_level: r.f64()?,
                    flight_level_sigma: r.f64()?,
                    rate_of_climb_ftpm: r.f64()?,
                    rate_of_climb_sigma_ftpm: r.f64()?,
                    measured_flight_level: r.f64()?,
                    measured_t: r.f64()?,
                })
            })?,
            emergency: r
                .opt(Reader::str)?
                .map(|e| {
                    [
                        Emergency::UnlawfulInterference,
                        Emergency::RadioFailure,
                        Emergency::General,
                    ]
                    .into_iter()
                    .map(Emergency::name)
                    .find(|n| *n == e)
                    .ok_or_else(|| wire_formats::wire::corrupt("emergency"))
                })
                .transpose()?,
            spi: r.bool()?,
            last_secondary_t: r.opt(Reader::f64)?,
            last_mode_s_t: r.opt(Reader::f64)?,
            last_primary_t: r.opt(Reader::f64)?,
        })
    })
}

/// Warnings identity calls for among confirmed `tracks`: a special code
/// (7500, 7600, 7700) and two tracks that carry one Mode S address.
pub fn warnings(tracks: &[TrackOutput]) -> Vec<String> {
    let mut out = Vec::new();
    let confirmed = || {
        tracks
            .iter()
            .filter(|t| t.status == algo::tracking::TrackStatus::Confirmed)
    };
    for t in confirmed() {
        if let Some(e) = t.identity.emergency() {
            out.push(format!(
                "track {} squawks {:04o} ({}): an emergency code",
                t.id,
                t.identity.mode_3a.map_or(0, |c| c.value),
                e.name()
            ));
        }
    }
    let mut by_address: Vec<(u32, u64)> = confirmed()
        .filter_map(|t| t.identity.address.map(|a| (a.value, t.id)))
        .collect();
    by_address.sort_unstable();
    for w in by_address.windows(2) {
        if w[0].0 == w[1].0 {
            out.push(format!(
                "tracks {} and {} both carry Mode S address {:06X}: one aircraft tracked \
                 twice (they are merged when a plot updates both and they are duplicates by \
                 tracker.duplicate_gate_probability), or a transponder misconfigured",
                w[0].1, w[1].1, w[0].0
            ));
        }
    }
    out
}

/// Largest σ (m) of the pressure offset at which a track's geometric
/// height from Mode C passes without a warning.
pub const OFFSET_SIGMA_WARN_M: f64 = 100.0;

/// When Mode C sets the geometric heights of tracks through an offset the
/// tracker could not learn (no 3D radar plot with Mode C yet), a warning
/// with the offset's σ at the highest track's level and the options that
/// fix it.
pub fn height_warnings(
    tracker: &algo::tracking::Tracker,
    tracks: &[TrackOutput],
) -> Option<String> {
    let (estimate, data) = tracker.pressure_offset()?;
    let top = tracks
        .iter()
        .filter_map(|t| t.identity.altitude.as_ref())
        .map(|p| p.x[0])
        .fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() {
        return None;
    }
    let sigma = estimate.at(top * FT_M).1.sqrt();
    (sigma > OFFSET_SIGMA_WARN_M).then(|| {
        format!(
            "tracks' geometric heights come from Mode C through a pressure-to-geometric offset \
             known to σ {sigma:.0} m at FL{:.0} ({} 3D radar plots with Mode C learnt from): \
             give tracker.mode_c_height.offset_m and slope (from QNH and temperature) with \
             smaller sigma_offset_m / sigma_slope, add a 3D radar, or set \
             tracker.mode_c_height.enabled false",
            top / 100.0,
            data.plots
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_addresses_and_callsigns_parse_as_the_standards_write_them() {
        // 7700 octal = 7·512 + 7·64 = 4032.
        assert_eq!(parse_code("7700"), Some(4032));
        assert_eq!(parse_code("0000"), Some(0));
        for bad in ["8000", "770", "77000", "7a00", "+700"] {
            assert_eq!(parse_code(bad), None, "{bad}");
        }
        // 0x4CA2D1 = 5,022,417.
        assert_eq!(parse_address("4ca2d1"), Some(5_022_417));
        for bad in ["4CA2D", "4CA2D10", "4CA2DG", "+CA2D1"] {
            assert_eq!(parse_address(bad), None, "{bad}");
        }
        assert_eq!(parse_callsign("RYR12AB"), Some(*b"RYR12AB "));
        assert_eq!(callsign_text(b"RYR12AB "), "RYR12AB");
        for bad in ["", "   ", "ryr12ab", "RYR-12", "ABCDEFGHI"] {
            assert_eq!(parse_callsign(bad), None, "{bad}");
        }
    }

    #[test]
    fn bad_fields_are_named() {
        let bad = |s: SsrInput| s.parse().unwrap_err().0;
        assert_eq!(
            bad(SsrInput {
                mode_3a: Some("8000".into()),
                ..Default::default()
            }),
            "mode_3a"
        );
        assert_eq!(
            bad(SsrInput {
                flight_level: Some(1300.0),
                ..Default::default()
            }),
            "flight_level"
        );
        assert_eq!(
            bad(SsrInput {
                mode_s_address: Some("1000000".into()),
                ..Default::default()
            }),
            "mode_s_address"
        );
        assert_eq!(
            bad(SsrInput {
                mode_3a_garbled: Some(true),
                ..Default::default()
            }),
            "mode_3a_garbled"
        );
        assert_eq!(
            bad(SsrInput {
                detection: Some("psr".into()),
                ..Default::default()
            }),
            "detection"
        );
        // A primary detection may carry the radar's code for its track.
        assert!(
            SsrInput {
                detection: Some("primary".into()),
                mode_3a: Some("1234".into()),
                ..Default::default()
            }
            .parse()
            .is_ok()
        );
    }

    #[test]
    fn the_log_form_round_trips() {
        let s = SsrInput {
            mode_3a: Some("7000".into()),
            mode_3a_validated: Some(false),
            mode_3a_garbled: None,
            flight_level: Some(350.25),
            flight_level_validated: None,
            flight_level_garbled: Some(true),
            mode_s_address: Some("4CA2D1".into()),
            callsign: Some("EZY1".into()),
            detection: Some("combined".into()),
            spi: Some(true),
        };
        let mut w = Writer::default();
        s.encode(&mut w);
        let mut r = Reader::new(&w.buf);
        assert_eq!(SsrInput::decode(&mut r).unwrap(), s);
        assert!(r.is_empty());
    }
}
