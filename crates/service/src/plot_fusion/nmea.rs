//! AIS over NMEA 0183 into a plot-fusion batch (`nmea`): the `!AIVDM`
//! lines a coastal receiver sends, decoded by `wire_formats::nmea`, each
//! position report (types 1–3, 18, 19, 27) made a cooperative AIS report
//! ([`ReportInput`] with source `ais`, MMSI, SOG/COG and the
//! position-accuracy flag) that follows the batch's JSON plots and
//! reports.
//!
//! Time. A position holds at its time of applicability: the receive time
//! of its tag block (`\c:<Unix s>*hh\`) taken back to the UTC second the
//! report gives (the fix's second; ITU-R M.1371), minus `time_offset_s`,
//! so that the reports join the plots' time base (0 by default: plots in
//! Unix seconds). A line without a receive time cannot be placed in time
//! and is skipped, counted in a warning.
//!
//! Bad lines (checksum, framing, a fragment missing) are skipped and
//! counted with the first one's line number and reason; decoding never
//! fails a batch.

use super::PlotInput;
use super::network::Network;
use super::report::ReportInput;
use crate::ServiceError;
use crate::validate::{Interval, Violations};
use algo::tracking::identity::MAX_MMSI;
use algo::tracking::{Plot, TrackerConfig};
use wire_formats::nmea::{self, AisPosition};

/// AIVDM lines and the offset of their times.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NmeaInput {
    /// NMEA 0183 lines, each an `!xxVDM`/`!xxVDO` sentence with its tag
    /// block.
    pub lines: Vec<String>,
    /// Subtracted from the tag blocks' Unix times (s; default 0).
    pub time_offset_s: Option<f64>,
}

/// The reports of an NMEA block, and what was not used.
#[derive(Debug, Clone, Default)]
pub struct NmeaReports {
    /// One cooperative AIS report per usable position report.
    pub plots: Vec<PlotInput>,
    pub warnings: Vec<String>,
}

/// The block's AIS reports (`field` names the block in errors).
pub fn reports(input: &NmeaInput, field: &str) -> Result<NmeaReports, ServiceError> {
    let mut v = Violations::new();
    let offset = match input.time_offset_s {
        Some(x) => v
            .within(
                format!("{field}.time_offset_s"),
                x,
                Interval::closed(-1e10, 1e10),
            )
            .unwrap_or(0.0),
        None => 0.0,
    };
    v.finish()?;
    let decoded = nmea::decode(&input.lines);
    let mut out = NmeaReports::default();
    let (mut untimed, mut bad_mmsi) = (Vec::new(), Vec::new());
    for p in &decoded.positions {
        let Some(t) = p.time_of_applicability() else {
            untimed.push(p.line);
            continue;
        };
        if p.mmsi == 0 || p.mmsi > MAX_MMSI {
            bad_mmsi.push((p.line, p.mmsi));
            continue;
        }
        out.plots.push(plot(p, t - offset));
    }
    if let Some(e) = decoded.errors.first() {
        out.warnings.push(format!(
            "{} {field} line(s) skipped (first: {field}.lines[{}]: {})",
            decoded.errors.len(),
            e.line,
            e.message
        ));
    }
    if let Some(first) = untimed.first() {
        out.warnings.push(format!(
            "{} AIS position report(s) in {field} have no receive time and were not used \
             (first: {field}.lines[{first}]): give each line its tag block's c:<Unix time>",
            untimed.len()
        ));
    }
    if let Some((line, mmsi)) = bad_mmsi.first() {
        out.warnings.push(format!(
            "{} AIS position report(s) in {field} have an MMSI outside 1..={MAX_MMSI} and were \
             not used (first: {field}.lines[{line}], MMSI {mmsi})",
            bad_mmsi.len()
        ));
    }
    if decoded.positions.is_empty() && decoded.messages > 0 {
        let types: Vec<String> = decoded
            .skipped_by_type
            .iter()
            .map(|(k, n)| format!("type {k}: {n}"))
            .collect();
        out.warnings.push(format!(
            "{} AIS message(s) in {field}, none a position report ({})",
            decoded.messages,
            types.join(", ")
        ));
    }
    Ok(out)
}

/// The block's AIS reports as the tracker's plots of `network` (appended
/// to `plots`), its warnings appended to `warnings`: what the batch call
/// and a session batch do with an `nmea` block.
pub fn extend(
    input: &NmeaInput,
    (network, config): (&Network, &TrackerConfig),
    plots: &mut Vec<Plot>,
    warnings: &mut Vec<String>,
) -> Result<(), ServiceError> {
    let from = reports(input, "nmea")?;
    plots.extend(network.plots(&from.plots, config, "nmea")?);
    warnings.extend(from.warnings);
    Ok(())
}

/// A position report as a cooperative AIS report at `t`.
fn plot(p: &AisPosition, t: f64) -> PlotInput {
    // Both or neither: a moored ship's COG is often not available.
    let (sog_kn, cog_deg) = match (p.sog_knots, p.cog_deg) {
        (Some(s), Some(c)) => (Some(s), Some(c)),
        _ => (None, None),
    };
    PlotInput {
        t: Some(t),
        report: Some(ReportInput {
            source: Some("ais".into()),
            lat_deg: Some(p.lat_deg),
            lon_deg: Some(p.lon_deg),
            sog_kn,
            cog_deg,
            position_accurate: Some(p.position_accurate),
            mmsi: Some(u64::from(p.mmsi)),
            ..Default::default()
        }),
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wire_formats::nmea::checksum;

    /// A line with a tag block at Unix time `c`.
    fn tagged(c: u64, sentence: &str) -> String {
        let body = format!("c:{c}");
        format!("\\{body}*{:02X}\\{sentence}", checksum(&body))
    }

    /// gpsd's type 1 example (MMSI 477553000, second 15, accuracy 0).
    const TYPE1: &str = "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C";

    #[test]
    fn a_tagged_position_becomes_an_ais_report_at_its_fix_time() {
        // 1 700 000 003 mod 60 = 23: received at :23, fixed at :15, so
        // 8 s before, mid-second: 1 699 999 995.5; offset 1.7e9 → −4.5.
        let input = NmeaInput {
            lines: vec![tagged(1_700_000_003, TYPE1)],
            time_offset_s: Some(1.7e9),
        };
        let out = reports(&input, "nmea").unwrap();
        assert_eq!(out.warnings, Vec::<String>::new());
        assert_eq!(out.plots.len(), 1);
        let p = &out.plots[0];
        assert_eq!(p.t, Some(-4.5));
        let r = p.report.as_ref().unwrap();
        assert_eq!(r.source.as_deref(), Some("ais"));
        assert_eq!(r.mmsi, Some(477_553_000));
        assert_eq!(r.position_accurate, Some(false));
        assert_eq!((r.sog_kn, r.cog_deg), (Some(0.0), Some(51.0)));
        assert!((r.lat_deg.unwrap() - 47.582833).abs() < 1e-6);
    }

    #[test]
    fn untimed_and_bad_lines_are_counted_in_warnings() {
        let input = NmeaInput {
            lines: vec![
                TYPE1.to_string(),
                "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5D".into(),
            ],
            time_offset_s: None,
        };
        let out = reports(&input, "nmea").unwrap();
        assert!(out.plots.is_empty());
        assert_eq!(out.warnings.len(), 2, "{:?}", out.warnings);
        assert!(
            out.warnings[0].contains("nmea.lines[1]"),
            "{:?}",
            out.warnings
        );
        assert!(
            out.warnings[1].contains("no receive time"),
            "{:?}",
            out.warnings
        );
    }

    #[test]
    fn a_bad_offset_is_named() {
        let input = NmeaInput {
            lines: vec![],
            time_offset_s: Some(f64::NAN),
        };
        let e = reports(&input, "batch.nmea").unwrap_err();
        assert!(
            format!("{e:?}").contains("batch.nmea.time_offset_s"),
            "{e:?}"
        );
    }
}
