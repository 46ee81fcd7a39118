//! CAT062 out: the service's tracks as ASTERIX system track messages
//! (`wire_formats::cat062`, edition 1.20), for the batch call (`cat062`), the
//! `plot_fusion` session's updates and the ASTERIX UDP output.
//!
//! What each item holds, from a [`TrackView`] and the [`Network`]:
//! - I062/010 the request's `cat062.sac`/`sic`; I062/015 its `service_id`.
//! - I062/040 track number: the track id modulo 2¹⁶, stable for the
//!   track's life; numbers are reused only after 65,536 later tracks.
//! - I062/070 time of track information: `(t − day_start_t) mod 86,400 s`,
//!   where `t` is the track's time (its last frame) and `day_start_t`
//!   (default 0) the midnight UTC of the plots' time scale: plot times in
//!   Unix seconds need no option.
//! - I062/105 WGS-84 latitude/longitude as the JSON's `lat_deg`/`lon_deg`;
//!   I062/100 x, y and I062/185 vx, vy in the fusion frame (ENU about the
//!   origin: x east, y north), the JSON's state.
//! - I062/130 geometric altitude: the 3D track's `height_m` (WGS-84
//!   ellipsoidal, not barometric; 2D tracks send none), with I062/080 SRC
//!   "3D radar"; I062/220 the rate of change of that height, dh/dt = ∇h·v
//!   (the local vertical, not the fusion frame's `vz`, which differs by the
//!   angle d/R at distance d from the origin).
//! - I062/080: CNF for a tentative track, TSB on a session's first record
//!   of a track, TSE on its last (deletion), CST when the track missed its
//!   last frame (`consecutive_misses > 0`), MON when the network has a
//!   single radar, SPI from the identity; PSR, SSR, MDS and ADS when that
//!   kind's I062/290 age is above [`AGED_AFTER_S`]; AFF ("ADS-B data
//!   inconsistent with other surveillance information") while the track
//!   distrusts its self-reported positions (`self_reported.trusted`
//!   false) and ADS-B is among its sources (AIS is not ADS-B: a track
//!   whose self-reports are AIS only is never flagged).
//!   `self_reported.validated` (ADS-B alone for 30 s) has no bit in 1.20;
//!   MLAT's aged bit is not reached (`wire_formats::cat062::TrackStatusFlags`).
//! - I062/290, each t − the time of the last update of its kind, and
//!   absent when no update of that kind has come: TRK from `start_t`;
//!   PSR, SSR, MDS from the identity's `last_primary_t`,
//!   `last_secondary_t`, `last_mode_s_t`, which radar plots date (never a
//!   report). A track without an identity was updated by primary plots
//!   only: PSR from `last_update_t`. A track a report has updated and no
//!   radar's secondary plot has: PSR from its latest radar in `sources`
//!   (its radar plots were primary; none: no PSR). ES from the `adsb`
//!   source's `last_t`, MLT from the `mlat` source's (AIS has no
//!   subfield).
//! - I062/500 from the covariance P: APC √P_xx, √P_yy; COV P_xy; ATV √P_vxvx,
//!   √P_vyvy; APW and AGA by first-order propagation J P Jᵀ through the
//!   Jacobian J of (lat, lon, h) by (e, n, u) at the track's position
//!   (central differences over ±1 m); ARC likewise for dh/dt (3D only).
//! - I062/340: SID (the radar's `sac`/`sic`, when declared) and POS (the
//!   plot's range and azimuth) of `last_plot`, when the last update was one
//!   radar's plot. HEIGHT is not written.
//!
//! A value outside its item's range is left out and counted (the encoder's
//! `skipped`); the warnings say how many, with the first reason.

use algo::tracking::ReportKind;
use wire_formats::asterix::FT_M;
use wire_formats::cat062::{
    self, Accuracy, AltitudeSource, Cat062Config, Encoded, LastMeasurement, SystemTrack,
    TrackMode3A, TrackStatusFlags, UpdateAges,
};

/// I062/080 PSR, SSR, MDS and ADS say a kind of update is aged beyond
/// this (s): two scans of a 6-s en-route radar, as the track's I062/290
/// ages show them.
pub const AGED_AFTER_S: f64 = 12.0;
use wire_formats::wire::{FormatError, Reader, Writer};

use super::{Network, TrackView};
use crate::{ServiceError, validate::Violations};

/// Smallest `max_block_bytes`: a block header and a small record.
pub const MIN_BLOCK_BYTES: u32 = 64;
/// Default `max_block_bytes`: [`cat062::DEFAULT_MAX_BLOCK`], which fits a
/// UDP datagram on any Ethernet path.
pub const DEFAULT_BLOCK_BYTES: u32 = cat062::DEFAULT_MAX_BLOCK as u32;

/// The `cat062` option as given.
#[derive(Debug, Clone, Default)]
pub struct Cat062Input {
    pub sac: Option<u32>,
    pub sic: Option<u32>,
    pub service_id: Option<u32>,
    /// Midnight UTC in the plots' time scale (s); default 0 (Unix time).
    pub day_start_t: Option<f64>,
    /// Largest data block (bytes); default 1,024.
    pub max_block_bytes: Option<u32>,
}

/// The `cat062` option, checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cat062Options {
    pub config: Cat062Config,
    pub day_start_t: f64,
    pub max_block_bytes: usize,
}

/// What a record says of its track's life (I062/080 TSB, TSE).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Life {
    /// Neither the first nor the last message.
    Continuing,
    /// The first record of the track sent to this receiver.
    First,
    /// The last record: the track is deleted.
    End,
}

/// Encoded records: the data blocks concatenated (each is self-delimiting
/// by its LEN), and what the encoder could not write as given.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Cat062Data {
    pub data: Vec<u8>,
    pub blocks: usize,
    pub records: usize,
    /// Values left out (out of range or not finite).
    pub skipped: usize,
    /// Values written as their subfield's maximum ("or above").
    pub saturated: usize,
}

/// Checks the option (`field` is its path, `cat062`): SAC and SIC
/// required, each 0 to 255; service id 0 to 255; `day_start_t` finite;
/// `max_block_bytes` 64 to 65,535; and the network must have a WGS-84
/// frame (I062/105).
pub fn validate(
    input: &Cat062Input,
    network: &Network,
    field: &str,
) -> Result<Cat062Options, ServiceError> {
    let mut v = Violations::new();
    let mut byte = |name: &str, x: Option<u32>, required: bool| -> Option<u8> {
        let path = format!("{field}.{name}");
        match x {
            None if required => {
                v.add(path, "is required (0 to 255)");
                None
            }
            None => None,
            Some(x) => match u8::try_from(x) {
                Ok(b) => Some(b),
                Err(_) => {
                    v.add(path, format!("must be 0 to 255, got {x}"));
                    None
                }
            },
        }
    };
    let sac = byte("sac", input.sac, true);
    let sic = byte("sic", input.sic, true);
    let service_id = byte("service_id", input.service_id, false);
    let day_start_t = input.day_start_t.unwrap_or(0.0);
    if !day_start_t.is_finite() {
        v.add(format!("{field}.day_start_t"), "must be finite");
    }
    let max_block = input.max_block_bytes.unwrap_or(DEFAULT_BLOCK_BYTES);
    if !(MIN_BLOCK_BYTES..=cat062::MAX_BLOCK_LEN as u32).contains(&max_block) {
        v.add(
            format!("{field}.max_block_bytes"),
            format!(
                "must be {MIN_BLOCK_BYTES} to {} (a data block's LEN), got {max_block}",
                cat062::MAX_BLOCK_LEN
            ),
        );
    }
    if network.frame.is_none() {
        v.add(
            field,
            "CAT062 needs WGS-84 positions (I062/105): give `origin`, or a radar site in \
             `geodetic`",
        );
    }
    v.finish()?;
    let (Some(sac), Some(sic)) = (sac, sic) else {
        return Err(ServiceError::Internal(
            "cat062 checked without SAC/SIC".into(),
        ));
    };
    Ok(Cat062Options {
        config: Cat062Config {
            sac,
            sic,
            service_id,
        },
        day_start_t,
        max_block_bytes: max_block as usize,
    })
}

/// Encodes one record per track, in order, into blocks of at most
/// `max_block_bytes`; the warnings say what was left out or saturated.
pub fn encode(
    options: &Cat062Options,
    network: &Network,
    tracks: &[(&TrackView, Life)],
    warnings: &mut Vec<String>,
) -> Cat062Data {
    let records: Vec<SystemTrack> = tracks
        .iter()
        .map(|(t, life)| system_track(options, network, t, *life))
        .collect();
    let encoded = cat062::encode_records(&options.config, &records, options.max_block_bytes);
    let out = summarise(&encoded, tracks, warnings);
    Cat062Data {
        data: encoded.blocks.concat(),
        blocks: encoded.blocks.len(),
        ..out
    }
}

fn summarise(e: &Encoded, tracks: &[(&TrackView, Life)], warnings: &mut Vec<String>) -> Cat062Data {
    let dropped: std::collections::BTreeSet<usize> = e
        .skipped
        .iter()
        .filter(|s| s.record_dropped)
        .map(|s| s.track_index)
        .collect();
    let first_of = |list: &[cat062::Skip]| {
        list.first().map(|s| {
            let id = tracks.get(s.track_index).map_or(0, |(t, _)| t.id);
            format!("track {id}: {}", s.reason)
        })
    };
    if let Some(first) = first_of(&e.skipped) {
        warnings.push(format!(
            "cat062: {} value(s) outside their item's range left out, {} track(s) without a \
             record; first: {first}",
            e.skipped.len(),
            dropped.len()
        ));
    }
    if let Some(first) = first_of(&e.saturated) {
        warnings.push(format!(
            "cat062: {} value(s) above their subfield's maximum written as the maximum; first: \
             {first}",
            e.saturated.len()
        ));
    }
    Cat062Data {
        data: Vec::new(),
        blocks: 0,
        records: tracks.len() - dropped.len(),
        skipped: e.skipped.len(),
        saturated: e.saturated.len(),
    }
}

/// The CAT062 record of one track (see the module header for each item).
pub fn system_track(
    options: &Cat062Options,
    network: &Network,
    t: &TrackView,
    life: Life,
) -> SystemTrack {
    let three_d = t.state.len() == 6;
    let position = [
        t.state[0],
        t.state[2],
        if three_d { t.state[4] } else { 0.0 },
    ];
    let velocity = [
        t.state[1],
        t.state[3],
        if three_d { t.state[5] } else { 0.0 },
    ];
    let cov = |i: usize, j: usize| t.covariance[i][j];
    // Indices of e, n, u and their velocities in the state.
    let pos_ix: &[usize] = if three_d { &[0, 2, 4] } else { &[0, 2] };
    let vel_ix: &[usize] = if three_d { &[1, 3, 5] } else { &[1, 3] };
    let jac = network
        .frame
        .as_ref()
        .and_then(|f| geodetic_jacobian(f, position));
    // σ of a row g of J over the covariance block `ix`: √(g P gᵀ).
    let spread = |g: &[f64; 3], ix: &[usize]| -> f64 {
        let mut s = 0.0;
        for (a, &i) in ix.iter().enumerate() {
            for (b, &j) in ix.iter().enumerate() {
                s += g[a] * cov(i, j) * g[b];
            }
        }
        s.max(0.0).sqrt()
    };
    let vertical_rate = jac
        .filter(|_| three_d)
        .map(|j| (0..3).map(|k| j[2][k] * velocity[k]).sum::<f64>());
    let height = t.height_m.filter(|_| three_d);
    let accuracy = Accuracy {
        xy: Some((cov(0, 0).max(0.0).sqrt(), cov(2, 2).max(0.0).sqrt())),
        xy_covariance_m2: Some(cov(0, 2)),
        wgs84: jac.map(|j| (spread(&j[0], pos_ix), spread(&j[1], pos_ix))),
        geometric_altitude: jac
            .filter(|_| height.is_some())
            .map(|j| spread(&j[2], pos_ix)),
        velocity: Some((cov(1, 1).max(0.0).sqrt(), cov(3, 3).max(0.0).sqrt())),
        acceleration: None,
        vertical_rate: jac
            .filter(|_| vertical_rate.is_some())
            .map(|j| spread(&j[2], vel_ix)),
    };
    let last_measurement = t.last_plot.as_ref().map(|p| LastMeasurement {
        sensor: network
            .radar_ids
            .iter()
            .position(|id| *id == p.radar)
            .and_then(|i| network.sources[i]),
        polar: Some((p.range_m, p.azimuth_deg)),
        height: None,
    });
    let sources = Sources::of(t, network);
    let id = SecondaryItems::of(t, &sources);
    let adsb_age = sources.adsb.map(|l| t.t - l);
    // The rate of climb of the pressure altitude when the track has one
    // (Mode C: what ATC reads), else the geometric one of a 3D track.
    let vertical_rate = id.vertical_rate.or(vertical_rate);
    SystemTrack {
        mode_3a: id.mode_3a,
        callsign: id.callsign,
        address: id.address,
        measured_flight_level: id.measured_flight_level,
        track_number: (t.id % 65_536) as u16,
        time_of_day: cat062::time_of_day(t.t - options.day_start_t),
        wgs84: t.lat_deg.zip(t.lon_deg),
        xy: (t.state[0], t.state[2]),
        velocity: (t.state[1], t.state[3]),
        status: TrackStatusFlags {
            monosensor: network.radar_ids.len() == 1,
            altitude_source: if height.is_some() {
                AltitudeSource::Radar3d
            } else {
                AltitudeSource::NoSource
            },
            tentative: t.status == "tentative",
            first_message: life == Life::First,
            last_message: life == Life::End,
            coasting: t.consecutive_misses > 0,
            spi: id.spi,
            psr_aged: id.psr_age.is_some_and(|a| a > AGED_AFTER_S),
            ssr_aged: id.ssr_age.is_some_and(|a| a > AGED_AFTER_S),
            mode_s_aged: id.mds_age.is_some_and(|a| a > AGED_AFTER_S),
            adsb_aged: adsb_age.is_some_and(|a| a > AGED_AFTER_S),
            adsb_inconsistent: sources.adsb.is_some()
                && t.self_reported.as_ref().is_some_and(|v| !v.trusted),
            ..TrackStatusFlags::default()
        },
        ages: UpdateAges {
            track: t.start_t.map(|s| t.t - s),
            psr: id.psr_age,
            ssr: id.ssr_age,
            mode_s: id.mds_age,
            adsb_es: adsb_age,
            mlat: sources.mlat.map(|l| t.t - l),
        },
        accuracy: Some(accuracy),
        height,
        vertical_rate,
        last_measurement,
    }
}

/// When a track's sensors last updated it, from its `sources` (radars by
/// id in the network's order, then `adsb`, `mlat`, `ais`).
struct Sources {
    /// The latest radar's.
    radar: Option<f64>,
    /// Whether a cooperative report (any kind) has updated the track.
    reports: bool,
    adsb: Option<f64>,
    mlat: Option<f64>,
}

impl Sources {
    /// An entry named `adsb`, `mlat` or `ais` is that report sensor's,
    /// unless a radar has that id and no earlier entry had the name (the
    /// radars come first: a radar named `adsb` and the ADS-B reports are
    /// two entries of one name).
    fn of(t: &TrackView, network: &Network) -> Self {
        let mut out = Self {
            radar: None,
            reports: false,
            adsb: None,
            mlat: None,
        };
        for (i, s) in t.sources.iter().enumerate() {
            let report = ReportKind::from_name(&s.sensor).filter(|_| {
                !network.radar_ids.contains(&s.sensor)
                    || t.sources[..i].iter().any(|e| e.sensor == s.sensor)
            });
            let latest = |x: Option<f64>| Some(x.map_or(s.last_t, |x| x.max(s.last_t)));
            match report {
                None => out.radar = latest(out.radar),
                Some(kind) => {
                    out.reports = true;
                    match kind {
                        ReportKind::Adsb => out.adsb = latest(out.adsb),
                        ReportKind::Mlat => out.mlat = latest(out.mlat),
                        ReportKind::Ais => {}
                    }
                }
            }
        }
        out
    }
}

/// What a track's identity puts in its record: I062/060, /245 and /380,
/// /136, the pressure altitude's rate for /220, SPI and the PSR, SSR and
/// Mode S ages of /290 and /080.
struct SecondaryItems {
    mode_3a: Option<TrackMode3A>,
    callsign: Option<[u8; 8]>,
    address: Option<u32>,
    measured_flight_level: Option<f64>,
    /// m/s.
    vertical_rate: Option<f64>,
    spi: bool,
    psr_age: Option<f64>,
    ssr_age: Option<f64>,
    mds_age: Option<f64>,
}

impl SecondaryItems {
    fn of(t: &TrackView, sources: &Sources) -> Self {
        let identity = t.identity.as_ref();
        let pressure = identity.and_then(|i| i.pressure_altitude.as_ref());
        let age = |last: Option<f64>| last.map(|l| t.t - l);
        Self {
            mode_3a: identity.and_then(|i| {
                let c = i.mode_3a.as_ref()?;
                Some(TrackMode3A {
                    code: super::ssr::parse_code(&c.value)?,
                    validated: true,
                    garbled: false,
                    // CH: a new code pending, or adopted within the aged
                    // threshold by a track that had another.
                    changed: i.pending_mode_3a.is_some()
                        || (c.first_t > t.start_t.unwrap_or(f64::NEG_INFINITY)
                            && t.t - c.first_t <= AGED_AFTER_S),
                })
            }),
            callsign: identity
                .and_then(|i| i.callsign.as_ref())
                .and_then(|c| super::ssr::parse_callsign(&c.value)),
            address: identity
                .and_then(|i| i.mode_s_address.as_ref())
                .and_then(|a| super::ssr::parse_address(&a.value)),
            measured_flight_level: pressure.map(|a| a.measured_flight_level),
            vertical_rate: pressure.map(|a| a.rate_of_climb_ftpm * FT_M / 60.0),
            spi: identity.is_some_and(|i| i.spi),
            // A track that has had a radar's secondary plot knows whether
            // its radar updates were primary; one that never has was
            // updated by primary plots only: its last update, or with
            // reports (which are no primary plot) its latest radar's.
            psr_age: match identity {
                Some(i) if i.last_secondary_t.is_some() || !sources.reports => {
                    age(i.last_primary_t)
                }
                None if !sources.reports => Some(t.t - t.last_update_t),
                _ => age(sources.radar),
            },
            ssr_age: age(identity.and_then(|i| i.last_secondary_t)),
            mds_age: age(identity.and_then(|i| i.last_mode_s_t)),
        }
    }
}

/// ∂(lat °, lon °, h m)/∂(e, n, u) at `enu`, by central differences of
/// ±1 m (the second derivatives are of order 1/R ≈ 1.6·10⁻⁷ per metre, so
/// the truncation error is far below the quantisation of I062/500).
fn geodetic_jacobian(frame: &algo::geo::LocalFrame, enu: [f64; 3]) -> Option<[[f64; 3]; 3]> {
    const STEP: f64 = 1.0;
    let mut j = [[0.0; 3]; 3];
    for k in 0..3 {
        let mut plus = enu;
        let mut minus = enu;
        plus[k] += STEP;
        minus[k] -= STEP;
        let a = frame.enu_to_geodetic(plus).ok()?;
        let b = frame.enu_to_geodetic(minus).ok()?;
        let mut dlon = a.1 - b.1;
        // Across the antimeridian.
        if dlon > std::f64::consts::PI {
            dlon -= std::f64::consts::TAU;
        } else if dlon < -std::f64::consts::PI {
            dlon += std::f64::consts::TAU;
        }
        j[0][k] = (a.0 - b.0).to_degrees() / (2.0 * STEP);
        j[1][k] = dlon.to_degrees() / (2.0 * STEP);
        j[2][k] = (a.2 - b.2) / (2.0 * STEP);
    }
    Some(j)
}

/// Stores the checked option (a session's state).
pub fn encode_options(w: &mut Writer, o: &Cat062Options) {
    w.u8(o.config.sac);
    w.u8(o.config.sic);
    w.opt(o.config.service_id, Writer::u8);
    w.f64(o.day_start_t);
    w.u32(o.max_block_bytes as u32);
}

/// Reads what [`encode_options`] wrote.
pub fn decode_options(r: &mut Reader<'_>) -> Result<Cat062Options, FormatError> {
    let sac = r.u8()?;
    let sic = r.u8()?;
    let service_id = r.opt(Reader::u8)?;
    let day_start_t = r.f64()?;
    let max_block_bytes = r.u32()? as usize;
    if !day_start_t.is_finite()
        || !(MIN_BLOCK_BYTES as usize..=cat062::MAX_BLOCK_LEN).contains(&max_block_bytes)
    {
        return Err(wire_formats::wire::corrupt("cat062 options"));
    }
    Ok(Cat062Options {
        config: Cat062Config {
            sac,
            sic,
            service_id,
        },
        day_start_t,
        max_block_bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot_fusion::output::{SelfReportedView, SourceView};
    use crate::plot_fusion::{IdentityItem, IdentityView};

    fn options() -> Cat062Options {
        Cat062Options {
            config: Cat062Config {
                sac: 1,
                sic: 2,
                service_id: None,
            },
            day_start_t: 0.0,
            max_block_bytes: DEFAULT_BLOCK_BYTES as usize,
        }
    }

    fn network(radars: &[&str]) -> Network {
        let sites = radars
            .iter()
            .map(|_| super::super::network::RadarSite {
                rotation: None,
                height: 0.0,
            })
            .collect();
        Network::from_parts(
            None,
            radars.iter().map(|r| r.to_string()).collect(),
            sites,
            0.0,
        )
    }

    /// A confirmed 2D track at t = 100 s, last updated at 99 s, with the
    /// sources given (sensor, last time).
    fn track(sources: &[(&str, f64)]) -> TrackView {
        TrackView {
            id: 7,
            status: "confirmed",
            t: 100.0,
            state: vec![0.0; 4],
            covariance: vec![vec![0.0; 4]; 4],
            lat_deg: None,
            lon_deg: None,
            height_m: None,
            radars: Vec::new(),
            hits: 10,
            misses: 0,
            consecutive_misses: 0,
            age: 10,
            last_update_t: 99.0,
            modes: Vec::new(),
            turn_rate_dps: None,
            start_t: Some(50.0),
            last_plot: None,
            identity: None,
            sources: sources
                .iter()
                .map(|&(sensor, last_t)| SourceView {
                    sensor: sensor.to_string(),
                    last_t,
                })
                .collect(),
            self_reported: None,
            mmsi: None,
        }
    }

    /// The identity an ADS-B report gives: an address, and no radar time.
    fn adsb_identity() -> IdentityView {
        IdentityView {
            mode_s_address: Some(IdentityItem {
                value: "4CA2D1".into(),
                plots: 30,
                first_t: 70.0,
                last_t: 99.0,
            }),
            mode_3a: None,
            pending_mode_3a: None,
            callsign: None,
            pressure_altitude: None,
            emergency: None,
            spi: false,
            last_secondary_t: None,
            last_mode_s_t: None,
            last_primary_t: None,
        }
    }

    fn record(network: &Network, t: &TrackView) -> SystemTrack {
        system_track(&options(), network, t, Life::Continuing)
    }

    #[test]
    fn adsb_and_mlat_sources_give_es_and_mlt_ages_and_no_radar_age() {
        let mut t = track(&[("adsb", 99.5), ("mlat", 97.0)]);
        t.identity = Some(adsb_identity());
        let r = record(&network(&["west"]), &t);
        // ES 100 − 99.5 = 0.5 s, MLT 100 − 97 = 3 s; no radar plot: no
        // PSR, SSR or MDS age.
        assert_eq!(r.ages.adsb_es, Some(0.5));
        assert_eq!(r.ages.mlat, Some(3.0));
        assert_eq!((r.ages.psr, r.ages.ssr, r.ages.mode_s), (None, None, None));
        assert_eq!(r.ages.track, Some(50.0));
        assert!(!r.status.adsb_aged && !r.status.adsb_inconsistent);
    }

    #[test]
    fn a_radar_only_track_has_no_es_or_mlt_age() {
        // No identity, no report: primary plots only, PSR from the last
        // update (100 − 99 = 1 s).
        let t = track(&[("west", 99.0)]);
        let r = record(&network(&["west"]), &t);
        assert_eq!((r.ages.adsb_es, r.ages.mlat), (None, None));
        assert_eq!(r.ages.psr, Some(1.0));
    }

    #[test]
    fn a_primary_radar_beside_reports_dates_the_psr_age_by_the_radar() {
        // Primary plots of `west` until 90 s, then AIS (no identity): PSR
        // 100 − 90 = 10 s, not the last update's 1 s; AIS has no subfield.
        let t = track(&[("west", 90.0), ("ais", 99.0)]);
        let r = record(&network(&["west"]), &t);
        assert_eq!(r.ages.psr, Some(10.0));
        assert_eq!((r.ages.adsb_es, r.ages.mlat), (None, None));
        // ADS-B alone (an identity without radar times, no radar source):
        // no PSR age at all.
        let mut t = track(&[("adsb", 99.0)]);
        t.identity = Some(adsb_identity());
        assert_eq!(record(&network(&["west"]), &t).ages.psr, None);
        // With a Mode S radar's combined plots (radar times in the
        // identity), the identity's times: PSR 100 − 96 = 4 s, SSR 4 s,
        // MDS 100 − 95 = 5 s.
        let mut t = track(&[("west", 96.0), ("adsb", 99.0)]);
        t.identity = Some(IdentityView {
            last_primary_t: Some(96.0),
            last_secondary_t: Some(96.0),
            last_mode_s_t: Some(95.0),
            ..adsb_identity()
        });
        let r = record(&network(&["west"]), &t);
        assert_eq!(
            (r.ages.psr, r.ages.ssr, r.ages.mode_s, r.ages.adsb_es),
            (Some(4.0), Some(4.0), Some(5.0), Some(1.0))
        );
    }

    #[test]
    fn distrusted_adsb_sets_aff_and_an_old_adsb_update_sets_ads() {
        let mut t = track(&[("west", 99.0), ("adsb", 80.0)]);
        t.identity = Some(adsb_identity());
        t.self_reported = Some(SelfReportedView {
            trusted: false,
            validated: true,
            distrusted_since_t: Some(79.0),
            last_self_reported_t: Some(80.0),
            last_independent_t: Some(99.0),
            disagreement: None,
        });
        let r = record(&network(&["west"]), &t);
        // ES 100 − 80 = 20 s > 12 s: ADS aged.
        assert_eq!(r.ages.adsb_es, Some(20.0));
        assert!(r.status.adsb_inconsistent && r.status.adsb_aged);
        // Trusted again, ADS-B 12 s old (not above the threshold).
        t.sources[1].last_t = 88.0;
        t.self_reported.as_mut().unwrap().trusted = true;
        let r = record(&network(&["west"]), &t);
        assert!(!r.status.adsb_inconsistent && !r.status.adsb_aged);
        // Distrusted self-reports without ADS-B (AIS) are not ADS-B's.
        let mut t = track(&[("west", 99.0), ("ais", 98.0)]);
        t.self_reported = Some(SelfReportedView {
            trusted: false,
            validated: true,
            distrusted_since_t: Some(90.0),
            last_self_reported_t: Some(98.0),
            last_independent_t: Some(99.0),
            disagreement: None,
        });
        assert!(!record(&network(&["west"]), &t).status.adsb_inconsistent);
    }

    #[test]
    fn a_radar_named_like_a_report_sensor_is_told_apart_by_order() {
        // The radars come first: a radar `adsb` alone is a radar.
        let net = network(&["adsb"]);
        let r = record(&net, &track(&[("adsb", 99.0)]));
        assert_eq!((r.ages.adsb_es, r.ages.psr), (None, Some(1.0)));
        // Two entries `adsb`: the radar's (90 s), then the reports' (99.5 s).
        let r = record(&net, &track(&[("adsb", 90.0), ("adsb", 99.5)]));
        assert_eq!((r.ages.adsb_es, r.ages.psr), (Some(0.5), Some(10.0)));
    }
}
