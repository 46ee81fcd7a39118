//! ASTERIX input of the plot-fusion tracker: raw CAT048/CAT034 bytes
//! (decoded by `wire_formats::asterix`) made into the tracker's plots, and
//! CAT021 (ADS-B) and CAT020 (MLAT) records into its cooperative reports
//! ([`cooperative`]).
//!
//! Mapping. A radar declares its `sac`/`sic`; a target report of another
//! SAC/SIC is counted `unmapped` (with a warning naming the pairs) and
//! skipped. A report without I048/010, /140 or /040, or from a 3D radar
//! without I048/110 (the elevation comes from the measured height), is
//! `incomplete`; a test target (I048/020 TST) is `test_targets`; both are
//! skipped. Simulated reports (SIM) are used. The Doppler speed (I048/120
//! CAL, positive receding) is used for a radar declared with
//! `sigma_radial_velocity_mps` unless its D bit says it is doubtful. Each
//! plot then goes through the same validation as a JSON plot; one that
//! fails is `rejected` and listed in `errors` with its record's offset,
//! never failing the request.
//!
//! Time. ASTERIX gives the time of day (s since midnight UTC). The first
//! record's time is `day_start_t + time of day`, the day given by `date`
//! (`YYYY-MM-DD`, UTC, Unix seconds) or `day_start_t`; every later record's
//! time is the one (time of day + k days) nearest to the previous record's
//! time, so a time of day far below the one before (23:59:59 → 00:00:01)
//! rolls to the next day, and a slightly late record just before midnight
//! stays on its day. Without a date, a session batch takes the instant
//! nearest to the session's last processed frame, and the UDP listener the
//! one nearest to the time of reception.

use std::collections::BTreeSet;

use super::{Network, PlotInput};
use crate::{ServiceError, Violations};
use algo::tracking::{Plot, TrackerConfig};
use wire_formats::asterix::{
    self, DecodeError, NORTH_MARKER, SECTOR_CROSSING, quality::nacv_sigma_mps,
};

/// Seconds in a day.
const DAY_S: f64 = 86_400.0;
/// Most errors listed in a response (the rest are counted).
pub const MAX_LISTED_ERRORS: usize = 100;
/// Smallest CAT048 record the tracker can use: FSPEC 1, I048/010 2,
/// /140 3, /040 4 bytes. Bounds the plots of `n` bytes by `n / 10`.
pub const MIN_PLOT_RECORD_BYTES: usize = 10;

/// Raw ASTERIX of a request and the day its times of day refer to.
#[derive(Debug, Clone, Default)]
pub struct AsterixInput {
    pub data: Vec<u8>,
    /// `YYYY-MM-DD` (UTC).
    pub date: Option<String>,
    /// The day's midnight in the request's time scale (s); for Unix time,
    /// what `date` gives.
    pub day_start_t: Option<f64>,
    /// Not on the wire: the instant a session batch without a date falls
    /// back to when the session has processed no frame yet (the UDP
    /// listener's time of reception).
    pub reference_t: Option<f64>,
    /// Not on the wire: the UDP listener's check of every report's time
    /// against the time of reception.
    pub reception: Option<Reception>,
}

/// A report whose time lies more than `max_offset_s` from the time of
/// reception `t` is refused (a radar clock glitch or a forged datagram
/// would otherwise move a session's newest time, and its lag horizon with
/// it, hours ahead: every good plot after it late).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reception {
    /// Time of reception (the session's time scale: Unix seconds).
    pub t: f64,
    /// Largest |report time − t| accepted (s), > 0.
    pub max_offset_s: f64,
}

/// How times of day become times.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Clock {
    /// The first record is on the day starting at this time.
    DayStart(f64),
    /// The first record is the instant with its time of day nearest to
    /// this time.
    Near(f64),
}

/// What the ASTERIX input gave.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AsterixSummary {
    pub bytes: usize,
    pub blocks: usize,
    /// Records decoded (CAT048 and CAT034).
    pub records: usize,
    pub target_reports: usize,
    /// Target reports made into plots.
    pub plots: usize,
    pub north_markers: usize,
    pub sector_crossings: usize,
    pub other_service_messages: usize,
    /// Target reports of a SAC/SIC no radar declares.
    pub unmapped: usize,
    pub test_targets: usize,
    /// Without I048/010, /140 or /040, or from a 3D radar without /110.
    pub incomplete: usize,
    /// Refused by the plot validation (listed in `errors`).
    pub rejected: usize,
    /// Plots older than the session's last processed frame (sessions).
    pub late: usize,
    /// Offsets of the late plots' records.
    pub late_offsets: Vec<usize>,
    /// Time of the first and the last plot.
    pub first_t: Option<f64>,
    pub last_t: Option<f64>,
    /// Decoding errors and rejected records, in data order (at most
    /// [`MAX_LISTED_ERRORS`]).
    pub errors: Vec<DecodeError>,
    pub errors_not_listed: usize,
}

/// Plots from ASTERIX and what became of every record.
#[derive(Debug, Clone, Default)]
pub struct AsterixPlots {
    pub plots: Vec<Plot>,
    /// Per plot, its record's offset.
    pub offsets: Vec<usize>,
    pub summary: AsterixSummary,
    pub warnings: Vec<String>,
}

/// The clock of a request: its `date` or `day_start_t` (not both), else
/// `fallback` (a session's last frame, the time of reception); neither is
/// a violation of `{field}.date`.
pub fn clock(
    input: &AsterixInput,
    field: &str,
    fallback: Option<f64>,
) -> Result<Clock, ServiceError> {
    match (&input.date, input.day_start_t) {
        (Some(_), Some(_)) => Err(Violations::single(
            format!("{field}.day_start_t"),
            "give date or day_start_t, not both",
        )),
        (Some(d), None) => match parse_date(d) {
            Some(t) => Ok(Clock::DayStart(t)),
            None => Err(Violations::single(
                format!("{field}.date"),
                format!(
                    "must be a UTC date YYYY-MM-DD (1970 to 9999), got '{}'",
                    crate::validate::quoted(d)
                ),
            )),
        },
        (None, Some(t)) => {
            if t.is_finite() && t.abs() <= 1.0e12 {
                Ok(Clock::DayStart(t))
            } else {
                Err(Violations::single(
                    format!("{field}.day_start_t"),
                    format!("must be finite and within ±1e12 s, got {t}"),
                ))
            }
        }
        (None, None) => match fallback {
            Some(t) => Ok(Clock::Near(t)),
            None => Err(Violations::single(
                format!("{field}.date"),
                "is required (or day_start_t): ASTERIX gives only the time of day",
            )),
        },
    }
}

/// Unix time of midnight UTC starting `YYYY-MM-DD`.
pub fn parse_date(s: &str) -> Option<f64> {
    let b = s.as_bytes();
    if b.len() != 10 || b[4] != b'-' || b[7] != b'-' {
        return None;
    }
    let num = |r: std::ops::Range<usize>| -> Option<i64> {
        let part = &s[r];
        part.bytes()
            .all(|c| c.is_ascii_digit())
            .then(|| part.parse().ok())?
    };
    let (y, m, d) = (num(0..4)?, num(5..7)?, num(8..10)?);
    if y < 1970 || !(1..=12).contains(&m) {
        return None;
    }
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let days_in = [
        31,
        if leap { 29 } else { 28 },
        31,
        30,
        31,
        30,
        31,
        31,
        30,
        31,
        30,
        31,
    ];
    if !(1..=days_in[(m - 1) as usize]).contains(&d) {
        return None;
    }
    Some(days_from_civil(y, m, d) as f64 * DAY_S)
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's
/// `days_from_civil`).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The time of a time of day nearest to `reference` (ties go forward).
pub fn nearest(time_of_day: f64, reference: f64) -> f64 {
    let k = ((reference - time_of_day) / DAY_S).round();
    time_of_day + k * DAY_S
}

/// Decodes `data` and makes plots of the target reports of declared radars.
pub fn plots(
    network: &Network,
    config: &TrackerConfig,
    data: &[u8],
    clock: Clock,
    reception: Option<Reception>,
) -> AsterixPlots {
    let mut decoded = asterix::decode(data);
    let mut s = AsterixSummary {
        bytes: data.len(),
        blocks: decoded.blocks,
        records: decoded.target_reports.len() + decoded.service_messages.len(),
        target_reports: decoded.target_reports.len(),
        ..Default::default()
    };
    for m in &decoded.service_messages {
        match m.message_type {
            Some(NORTH_MARKER) => s.north_markers += 1,
            Some(SECTOR_CROSSING) => s.sector_crossings += 1,
            _ => s.other_service_messages += 1,
        }
    }
    let parallel = config.is_parallel();
    let mut errors: Vec<DecodeError> = std::mem::take(&mut decoded.errors);
    let mut out = AsterixPlots::default();
    let mut unmapped: BTreeSet<(u8, u8)> = BTreeSet::new();
    let mut previous: Option<f64> = None;
    for r in &decoded.target_reports {
        let (Some(source), Some(tod), Some(range), Some(azimuth)) =
            (r.source, r.time_of_day_s, r.range_m, r.azimuth_deg)
        else {
            s.incomplete += 1;
            continue;
        };
        let Some(radar) = network.radar_of_source(source) else {
            s.unmapped += 1;
            unmapped.insert(source);
            continue;
        };
        if r.descriptor.and_then(|d| d.tst) == Some(true) {
            s.test_targets += 1;
            continue;
        }
        let spec = &config.radars[radar];
        let elevation_deg = if spec.is_3d() {
            let Some(h) = r.height_m else {
                s.incomplete += 1;
                continue;
            };
            match network.elevation_deg_at_height(radar, range, h) {
                Some(e) => Some(e),
                None => {
                    s.rejected += 1;
                    errors.push(DecodeError {
                        offset: r.offset,
                        reason: format!(
                            "target report of radar '{}': height {h} m is out of reach at \
                             slant range {range} m",
                            network.radar_ids[radar]
                        ),
                    });
                    continue;
                }
            }
        } else {
            None
        };
        let t = match (previous, clock) {
            (Some(p), _) => nearest(tod, p),
            (None, Clock::DayStart(d)) => d + tod,
            (None, Clock::Near(n)) => nearest(tod, n),
        };
        if let Some(rx) = reception {
            let off = t - rx.t;
            if off.is_nan() || off.abs() > rx.max_offset_s {
                s.rejected += 1;
                errors.push(DecodeError {
                    offset: r.offset,
                    reason: format!(
                        "target report of radar '{}' refused: its time of day is {:.1} s from the time of reception, beyond {} s (--asterix-max-clock-offset-s; a radar clock glitch or a forged datagram)",
                        network.radar_ids[radar],
                        off,
                        rx.max_offset_s
                    ),
                });
                continue;
            }
        }
        let input = PlotInput {
            radar_id: Some(network.radar_ids[radar].clone()),
            t: Some(t),
            range_m: Some(range),
            azimuth_deg: Some(azimuth),
            elevation_deg,
            radial_velocity_mps: if spec.has_doppler() && !r.doppler_doubtful {
                r.doppler_mps
            } else {
                None
            },
            ssr: super::SsrInput::from_asterix(r),
            report: None,
        };
        match network.plot(&input, config, parallel) {
            Ok(p) => {
                previous = Some(t);
                s.first_t.get_or_insert(t);
                s.last_t = Some(t);
                out.plots.push(p);
                out.offsets.push(r.offset);
            }
            Err((name, message)) => {
                s.rejected += 1;
                errors.push(DecodeError {
                    offset: r.offset,
                    reason: format!(
                        "target report of radar '{}' refused: {name} {message}",
                        network.radar_ids[radar]
                    ),
                });
            }
        }
    }
    cooperative(
        &decoded,
        (network, config),
        (&mut previous, clock, reception),
        &mut s,
        &mut errors,
        &mut out,
    );
    s.plots = out.plots.len();
    errors.sort_by_key(|e| e.offset);
    if !unmapped.is_empty() {
        let pairs: Vec<String> = unmapped.iter().map(|(a, b)| format!("{a}/{b}")).collect();
        out.warnings.push(format!(
            "{} ASTERIX target report(s) of SAC/SIC {} skipped: no radar declares them \
             (radars[i].sac, radars[i].sic)",
            s.unmapped,
            pairs.join(", ")
        ));
    }
    if !errors.is_empty() {
        out.warnings.push(format!(
            "{} ASTERIX error(s): see asterix.errors (first at offset {}: {})",
            errors.len(),
            errors[0].offset,
            errors[0].reason
        ));
    }
    if s.target_reports > 0 && s.plots == 0 && !network.has_sources() {
        out.warnings.push(
            "no radar declares its SAC/SIC (radars[i].sac, radars[i].sic): ASTERIX target \
             reports cannot be used"
                .into(),
        );
    }
    if errors.len() > MAX_LISTED_ERRORS {
        s.errors_not_listed = errors.len() - MAX_LISTED_ERRORS;
        errors.truncate(MAX_LISTED_ERRORS);
    }
    s.errors = errors;
    out.summary = s;
    out
}

/// The ADS-B (CAT021) and multilateration (CAT020) records of `decoded`
/// made into the tracker's cooperative reports: timed like CAT048 records
/// (their time of applicability, nearest the previous record's time), a
/// simulated or test target skipped (`test_targets`), one without a time
/// or a position `incomplete`, one that fails validation (an ADS-B report
/// without NACp, say) `rejected` and listed in `errors`. They count among
/// `target_reports` and, used, among `plots`. The velocity of an ADS-B
/// report is used with its NACv; a multilateration report's is not (CAT020
/// states no accuracy for it).
fn cooperative(
    decoded: &asterix::Decoded,
    (network, config): (&Network, &TrackerConfig),
    (previous, clock, reception): (&mut Option<f64>, Clock, Option<Reception>),
    s: &mut AsterixSummary,
    errors: &mut Vec<DecodeError>,
    out: &mut AsterixPlots,
) {
    use wire_formats::asterix::CooperativeReport;
    let adsb = decoded.adsb_reports.iter().map(|r| {
        let nacv = r.quality.and_then(|q| nacv_sigma_mps(q.nucr_nacv));
        (r as &dyn CooperativeReport, "adsb", nacv)
    });
    let mlat = decoded
        .mlat_reports
        .iter()
        .map(|r| (r as &dyn CooperativeReport, "mlat", None));
    for (r, source, sigma_velocity) in adsb.chain(mlat) {
        s.records += 1;
        s.target_reports += 1;
        if r.simulated_or_test() {
            s.test_targets += 1;
            continue;
        }
        let (Some(tod), Some((lat, lon))) = (r.time_of_applicability_s(), r.lat_lon_deg()) else {
            s.incomplete += 1;
            continue;
        };
        let t = match (*previous, clock) {
            (Some(p), _) => nearest(tod, p),
            (None, Clock::DayStart(d)) => d + tod,
            (None, Clock::Near(n)) => nearest(tod, n),
        };
        if let Some(rx) = reception {
            let off = t - rx.t;
            if off.is_nan() || off.abs() > rx.max_offset_s {
                s.rejected += 1;
                errors.push(DecodeError {
                    offset: r.offset(),
                    reason: format!(
                        "{source} report refused: its time of day is {off:.1} s from the time \
                         of reception, beyond {} s (--asterix-max-clock-offset-s)",
                        rx.max_offset_s
                    ),
                });
                continue;
            }
        }
        let velocity = r.velocity_en_mps().zip(sigma_velocity);
        let input = PlotInput {
            t: Some(t),
            ssr: super::SsrInput {
                mode_3a: r.mode_3a().map(|c| format!("{c:04o}")),
                flight_level: r.flight_level(),
                mode_s_address: r.address().map(|a| format!("{a:06X}")),
                callsign: r.callsign().map(str::to_string),
                ..Default::default()
            },
            report: Some(super::ReportInput {
                source: Some(source.to_string()),
                lat_deg: Some(lat),
                lon_deg: Some(lon),
                geometric_height_m: r.geometric_height_m(),
                velocity_east_mps: velocity.map(|v| v.0.0),
                velocity_north_mps: velocity.map(|v| v.0.1),
                sigma_velocity_mps: velocity.map(|v| v.1),
                // The larger axis's σ: the report's error ellipse taken
                // as a circle that holds it.
                sigma_m: r.position_sigma_m().map(|(e, n)| e.max(n)),
                ..Default::default()
            }),
            ..Default::default()
        };
        match network.plot(&input, config, config.is_parallel()) {
            Ok(p) => {
                *previous = Some(t);
                s.first_t.get_or_insert(t);
                s.last_t = Some(t);
                out.plots.push(p);
                out.offsets.push(r.offset());
            }
            Err((name, message)) => {
                s.rejected += 1;
                errors.push(DecodeError {
                    offset: r.offset(),
                    reason: format!("{source} report refused: {name} {message}"),
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_unix_midnights() {
        // 2026-12-02: 20,789 days after 1970-01-01 (56 years of 365 days =
        // 20,440, plus 14 leap days 1972..2024 = 20,454, plus Jan–Nov 2026
        // = 334, plus 1).
        assert_eq!(parse_date("2026-12-02"), Some(20_789.0 * 86_400.0));
        assert_eq!(parse_date("1970-01-01"), Some(0.0));
        // 2000 is a leap year (divisible by 400): 2000-03-01 is day 11,017.
        assert_eq!(parse_date("2000-03-01"), Some(11_017.0 * 86_400.0));
        assert_eq!(parse_date("2000-02-29"), Some(11_016.0 * 86_400.0));
        assert_eq!(parse_date("2100-02-29"), None);
        assert_eq!(parse_date("2026-13-01"), None);
        assert_eq!(parse_date("2026-1-01"), None);
        assert_eq!(parse_date("+026-01-01"), None);
    }

    #[test]
    fn cooperative_records_without_time_or_position_are_incomplete() {
        // A CAT021 record (I021/010 1/2 only) at offset 3 and a CAT020
        // record (I020/010 3/4) at offset 9: no time, no position.
        let data = [21, 0, 6, 0x80, 1, 2, 20, 0, 6, 0x80, 3, 4];
        let network = Network::from_parts(None, vec![], vec![], 0.0);
        let config = TrackerConfig::new(2, vec![]);
        let out = plots(&network, &config, &data, Clock::DayStart(0.0), None);
        assert!(out.summary.errors.is_empty(), "{:?}", out.summary.errors);
        assert_eq!(out.summary.incomplete, 2);
        assert_eq!(out.summary.target_reports, 2);
        assert_eq!(out.summary.blocks, 2);
        assert!(out.plots.is_empty());
    }

    /// libasterix's CAT021 fixture (checks/cat021_fixture.py): its first
    /// record, at 47.12345677° N 8.65432207° E (I021/131), time of
    /// applicability 43,210.0078125 s, NACp 9, address 4B1A2C (4,921,900),
    /// becomes an ADS-B report of the fusion frame at that point, σ =
    /// 30 m / 2.4477 = 12.26 m.
    #[test]
    fn an_adsb_record_becomes_a_cooperative_report() {
        let data = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../tests/fixtures/cat021/adsb.bin"
        ))
        .unwrap();
        let frame = algo::geo::LocalFrame::new(
            algo::geo::Ellipsoid::WGS84,
            47.12345676496625f64.to_radians(),
            8.654322065412998f64.to_radians(),
            10_706.1,
        )
        .unwrap();
        let network = Network::from_parts(Some(frame), vec![], vec![], 0.0);
        let config = TrackerConfig::new(2, vec![]);
        let out = plots(&network, &config, &data, Clock::DayStart(0.0), None);
        let first = out
            .plots
            .first()
            .unwrap_or_else(|| panic!("{:?}", out.summary));
        let r = first.report.expect("a report");
        assert_eq!(r.kind, algo::tracking::ReportKind::Adsb);
        assert_eq!(first.radar, config.report_sensor(r.kind));
        assert!((first.t - 43_210.007_812_5).abs() < 1e-9);
        assert!(
            r.position.iter().all(|v| v.abs() < 0.01),
            "{:?}",
            r.position
        );
        assert!((r.sigma_horizontal - 30.0 / 2.447_746_830_680_816).abs() < 1e-9);
        assert_eq!(first.identity.address, Some(4_921_900));
    }

    #[test]
    fn the_nearest_instant_rolls_over_midnight_both_ways() {
        let day = 86_400.0;
        // 00:00:01 after 23:59:59 of day 10 is day 11.
        assert_eq!(nearest(1.0, 10.0 * day + 86_399.0), 11.0 * day + 1.0);
        // 23:59:59 just after 00:00:01 of day 11 is day 10 (a late record).
        assert_eq!(nearest(86_399.0, 11.0 * day + 1.0), 10.0 * day + 86_399.0);
        assert_eq!(
            nearest(43_000.0, 10.0 * day + 43_100.0),
            10.0 * day + 43_000.0
        );
    }
}
