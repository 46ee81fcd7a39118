//! The stored form of what secondary surveillance says: a plot's
//! [`Identity`] and a track's [`TrackIdentity`] (tracker format 6, lag
//! window format 3). Earlier formats carry none: their plots decode as
//! primary plots and their tracks with nothing learnt.
//!
//! A plot's identity: a byte of presence flags (bit 0 address, 1 Mode 3/A,
//! 2 Mode C, 3 callsign, 4 detection type, 5 SPI), then the fields present
//! in that order: address (u32), code (u32: the 12-bit code, bit 12
//! validated, bit 13 garbled), flight level (f64) and its flags (u8: bit 0
//! validated, bit 1 garbled), callsign (8 bytes), detection (u8: 0
//! primary, 1 secondary, 2 combined). A track's: each evidence optional
//! (address, code, pending code, callsign: value, plots, first and last
//! time), the pressure-altitude filter optional (time, state, covariance,
//! last measurement and its time, rejections in a row), then the SPI,
//! last secondary, last Mode S and last primary times, each optional.

use algo::tracking::identity::{Callsign, Evidence, PressureAltitude};
use algo::tracking::{Detection, Identity, Mode3A, ModeC, TrackIdentity};

use wire_formats::wire::{FormatError, Reader, Writer, corrupt};

/// The first tracker format that stores identities.
pub(crate) const TRACKER_FORMAT: u32 = 6;

pub(crate) fn write_identity(w: &mut Writer, id: &Identity) {
    let flags = u8::from(id.address.is_some())
        | u8::from(id.mode_3a.is_some()) << 1
        | u8::from(id.mode_c.is_some()) << 2
        | u8::from(id.callsign.is_some()) << 3
        | u8::from(id.detection.is_some()) << 4
        | u8::from(id.spi) << 5;
    w.u8(flags);
    if let Some(a) = id.address {
        w.u32(a);
    }
    if let Some(c) = id.mode_3a {
        w.u32(u32::from(c.code) | u32::from(c.validated) << 12 | u32::from(c.garbled) << 13);
    }
    if let Some(c) = id.mode_c {
        w.f64(c.flight_level);
        w.u8(u8::from(c.validated) | u8::from(c.garbled) << 1);
    }
    if let Some(cs) = id.callsign {
        w.buf.extend_from_slice(&cs);
    }
    if let Some(d) = id.detection {
        w.u8(match d {
            Detection::Primary => 0,
            Detection::Secondary => 1,
            Detection::Combined => 2,
        });
    }
}

pub(crate) fn read_identity(r: &mut Reader<'_>) -> Result<Identity, FormatError> {
    let flags = r.u8()?;
    if flags >> 6 != 0 {
        return Err(corrupt("identity flags"));
    }
    let has = |bit: u8| flags & (1 << bit) != 0;
    let address = if has(0) { Some(r.u32()?) } else { None };
    let mode_3a = if has(1) {
        let v = r.u32()?;
        if v >> 14 != 0 {
            return Err(corrupt("Mode 3/A code"));
        }
        Some(Mode3A {
            code: (v & 0o7777) as u16,
            validated: v & (1 << 12) != 0,
            garbled: v & (1 << 13) != 0,
        })
    } else {
        None
    };
    let mode_c = if has(2) {
        let flight_level = r.f64()?;
        let f = r.u8()?;
        if f >> 2 != 0 {
            return Err(corrupt("Mode C flags"));
        }
        Some(ModeC {
            flight_level,
            validated: f & 1 != 0,
            garbled: f & 2 != 0,
        })
    } else {
        None
    };
    let callsign = if has(3) { Some(callsign(r)?) } else { None };
    let detection = if has(4) {
        Some(match r.u8()? {
            0 => Detection::Primary,
            1 => Detection::Secondary,
            2 => Detection::Combined,
            _ => return Err(corrupt("detection type")),
        })
    } else {
        None
    };
    Ok(Identity {
        address,
        mode_3a,
        mode_c,
        callsign,
        detection,
        spi: has(5),
        // From tracker format 11, after the plot's report (tracker::plot_as).
        mmsi: None,
    })
}

fn callsign(r: &mut Reader) -> Result<Callsign, FormatError> {
    let mut cs = [0u8; 8];
    for c in &mut cs {
        *c = r.u8()?;
    }
    Ok(cs)
}

pub(crate) fn evidence<T: Copy>(
    w: &mut Writer,
    e: Option<Evidence<T>>,
    value: impl Fn(&mut Writer, T),
) {
    w.opt(e, |w, e| {
        value(w, e.value);
        w.u32(e.plots);
        w.f64(e.first_t);
        w.f64(e.last_t);
    });
}

pub(crate) fn read_evidence<'a, T>(
    r: &mut Reader<'a>,
    value: impl Fn(&mut Reader<'a>) -> Result<T, FormatError>,
) -> Result<Option<Evidence<T>>, FormatError> {
    r.opt(|r| {
        Ok(Evidence {
            value: value(r)?,
            plots: r.u32()?,
            first_t: r.f64()?,
            last_t: r.f64()?,
        })
    })
}

pub(crate) fn write_track_identity(w: &mut Writer, id: &TrackIdentity) {
    evidence(w, id.address, Writer::u32);
    evidence(w, id.mode_3a, |w, c| w.u32(u32::from(c)));
    evidence(w, id.pending_3a, |w, c| w.u32(u32::from(c)));
    evidence(w, id.callsign, |w, c| w.buf.extend_from_slice(&c));
    w.opt(id.altitude.as_ref(), |w, a| {
        w.f64(a.t);
        w.f64_run(&a.x);
        w.f64_run(&a.p);
        w.f64(a.measured.0);
        w.f64(a.measured.1);
        w.u32(a.rejected);
    });
    for t in [id.spi_t, id.last_secondary, id.last_mode_s, id.last_primary] {
        w.opt(t, Writer::f64);
    }
}

pub(crate) fn read_track_identity(r: &mut Reader<'_>) -> Result<TrackIdentity, FormatError> {
    let code = |r: &mut Reader| {
        let v = r.u32()?;
        u16::try_from(v)
            .ok()
            .filter(|&c| c <= 0o7777)
            .ok_or_else(|| corrupt("Mode 3/A code"))
    };
    Ok(TrackIdentity {
        address: read_evidence(r, Reader::u32)?,
        mode_3a: read_evidence(r, code)?,
        pending_3a: read_evidence(r, code)?,
        callsign: read_evidence(r, callsign)?,
        altitude: r.opt(|r| {
            let a = PressureAltitude {
                t: r.f64()?,
                x: [r.f64()?, r.f64()?],
                p: [r.f64()?, r.f64()?, r.f64()?],
                measured: (r.f64()?, r.f64()?),
                rejected: r.u32()?,
            };
            // A filter the tracker could not have made: not finite, or a
            // covariance that is not positive semi-definite.
            let values = [
                a.t,
                a.x[0],
                a.x[1],
                a.p[0],
                a.p[1],
                a.p[2],
                a.measured.0,
                a.measured.1,
            ];
            let psd =
                a.p[0] >= 0.0 && a.p[2] >= 0.0 && a.p[1] * a.p[1] <= a.p[0] * a.p[2] * (1.0 + 1e-9);
            if values.iter().all(|v| v.is_finite()) && psd {
                Ok(a)
            } else {
                Err(corrupt("pressure altitude"))
            }
        })?,
        spi_t: r.opt(Reader::f64)?,
        last_secondary: r.opt(Reader::f64)?,
        last_mode_s: r.opt(Reader::f64)?,
        last_primary: r.opt(Reader::f64)?,
        // Written after the track's detections (tracker format 10).
        last_mode_ac: None,
        // Read from format 11 on (tracker::track).
        validation: Default::default(),
        mmsi: None,
    })
}
