//! Cooperative reports at the service's edge: ADS-B, multilateration and
//! AIS positions as a client sends them ([`ReportInput`]), validated and
//! re-expressed in the fusion frame as the tracker's
//! [`algo::tracking::Report`], each with the σ its own quality fields
//! state.
//!
//! Accuracy. An ADS-B report's NACp bounds its horizontal position error:
//! the 95 % radius EPU (DO-260B / ED-102A, table 2-14: NACp 11 < 3 m,
//! 10 < 10 m, 9 < 30 m, 8 < 0.05 NM, 7 < 0.1 NM, 6 < 0.3 NM, 5 < 0.5 NM,
//! 4 < 1 NM, 3 < 2 NM, 2 < 4 NM, 1 < 10 NM, 0 unknown). For a circular
//! Gaussian of σ per axis the radius r holds P(|e| < r) = 1 − exp(−r²/2σ²),
//! so the 95 % radius is σ √(−2 ln 0.05) = 2.4477 σ and σ = EPU / 2.4477;
//! the bound taken as the error's 95 % radius (a conservative reading of
//! "less than"). NACv bounds the horizontal velocity error alike (95 %:
//! 4 < 0.3 m/s, 3 < 1, 2 < 3, 1 < 10 m/s, 0 unknown). NACp 9 to 11 also
//! bound the vertical error (VEPU 95 %: 9 < 45 m, 10 < 15 m, 11 < 4 m;
//! one-dimensional, so σ = VEPU / 1.96); a geometric height of a report
//! with a lower NACp is used only with `sigma_height_m`. A
//! multilateration report gives its σ (`sigma_m`, CAT020 I020/500). An
//! AIS report's position-accuracy flag says better than 10 m (DGNSS) or
//! worse; σ 4.1 m (10 m / 2.4477) and 41 m (100 m / 2.4477, an autonomous
//! GNSS fix) are taken. An explicit `sigma_m` always wins. NIC is
//! integrity (a containment radius), not accuracy, and is not used.

use super::PlotInput;
use super::network::Network;
use algo::tracking::{Identity, Plot, Report, ReportKind, TrackerConfig};
use wire_formats::wire::{FormatError, Reader, Writer};

pub use wire_formats::asterix::quality::{K95 as CIRCULAR_95, nacp_sigma_m, nacv_sigma_mps};

/// The σ of a one-dimensional 95 % bound: 1.96 σ.
const LINEAR_95: f64 = 1.959_963_984_540_054;

/// NACp's 95 % vertical bound VEPU (m) for NACp 9 to 11.
fn vepu_m(nacp: u8) -> Option<f64> {
    match nacp {
        9 => Some(45.0),
        10 => Some(15.0),
        11 => Some(4.0),
        _ => None,
    }
}

/// σ (m) of an AIS position by its accuracy flag (module documentation).
fn ais_sigma_m(accurate: bool) -> f64 {
    (if accurate { 10.0 } else { 100.0 }) / CIRCULAR_95
}

/// σ (m/s) of an AIS velocity per axis: SOG to 0.1 kn and COG to 0.1°
/// are quantisation; the ship's own sensors' error, about 0.5 m/s, rules.
const AIS_VELOCITY_SIGMA_MPS: f64 = 0.5;

/// A report's fields beside its identity (the SSR fields of the plot it
/// travels in: address, callsign, Mode 3/A, barometric flight level).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReportInput {
    /// `adsb`, `mlat` or `ais`.
    pub source: Option<String>,
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    /// Geometric (GNSS) height above the WGS84 ellipsoid (m).
    pub geometric_height_m: Option<f64>,
    /// Velocity east and north (m/s), both or neither.
    pub velocity_east_mps: Option<f64>,
    pub velocity_north_mps: Option<f64>,
    /// Geometric vertical rate (m/s).
    pub vertical_rate_mps: Option<f64>,
    /// AIS: speed over ground (knots) and course over ground (degrees
    /// from north), instead of the velocity's components.
    pub sog_kn: Option<f64>,
    pub cog_deg: Option<f64>,
    /// ADS-B navigation accuracy categories.
    pub nacp: Option<u8>,
    pub nacv: Option<u8>,
    /// AIS position-accuracy flag (true: better than 10 m).
    pub position_accurate: Option<bool>,
    /// σ per horizontal axis (m): a multilateration report's own; any
    /// report's, over what its quality fields say.
    pub sigma_m: Option<f64>,
    /// σ of the geometric height (m).
    pub sigma_height_m: Option<f64>,
    /// σ per axis of the velocity (m/s).
    pub sigma_velocity_mps: Option<f64>,
    /// AIS: the ship's MMSI (at most nine digits).
    pub mmsi: Option<u64>,
}

impl ReportInput {
    /// The report as a session's log stores it (every field, as given).
    pub fn encode(&self, w: &mut Writer) {
        // Destructured whole: a field added is a compile error here until
        // the log carries it.
        let ReportInput {
            source,
            lat_deg,
            lon_deg,
            geometric_height_m,
            velocity_east_mps,
            velocity_north_mps,
            vertical_rate_mps,
            sog_kn,
            cog_deg,
            nacp,
            nacv,
            position_accurate,
            sigma_m,
            sigma_height_m,
            sigma_velocity_mps,
            mmsi,
        } = self;
        w.opt(source.as_deref(), Writer::str);
        for x in [
            lat_deg,
            lon_deg,
            geometric_height_m,
            velocity_east_mps,
            velocity_north_mps,
            vertical_rate_mps,
            sog_kn,
            cog_deg,
            sigma_m,
            sigma_height_m,
            sigma_velocity_mps,
        ] {
            w.opt(*x, Writer::f64);
        }
        w.opt(*nacp, Writer::u8);
        w.opt(*nacv, Writer::u8);
        w.opt(*position_accurate, Writer::bool);
        w.opt(*mmsi, Writer::u64);
    }

    /// A report as [`ReportInput::encode`] stored it.
    pub fn decode(r: &mut Reader<'_>) -> Result<Self, FormatError> {
        let source = r.opt(Reader::str)?;
        let mut f = [None; 11];
        for x in &mut f {
            *x = r.opt(Reader::f64)?;
        }
        let [
            lat_deg,
            lon_deg,
            geometric_height_m,
            velocity_east_mps,
            velocity_north_mps,
            vertical_rate_mps,
            sog_kn,
            cog_deg,
            sigma_m,
            sigma_height_m,
            sigma_velocity_mps,
        ] = f;
        Ok(ReportInput {
            source,
            lat_deg,
            lon_deg,
            geometric_height_m,
            velocity_east_mps,
            velocity_north_mps,
            vertical_rate_mps,
            sog_kn,
            cog_deg,
            nacp: r.opt(Reader::u8)?,
            nacv: r.opt(Reader::u8)?,
            position_accurate: r.opt(Reader::bool)?,
            sigma_m,
            sigma_height_m,
            sigma_velocity_mps,
            mmsi: r.opt(Reader::u64)?,
        })
    }
}

/// A bad field (its name under the report) and why.
type Bad = (&'static str, String);

fn bad(name: &'static str, why: impl Into<String>) -> Bad {
    (name, why.into())
}

fn finite_in(name: &'static str, v: f64, lo: f64, hi: f64) -> Result<f64, Bad> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(bad(name, format!("must lie in [{lo}, {hi}], got {v}")))
    }
}

fn sigma(name: &'static str, v: Option<f64>) -> Result<Option<f64>, Bad> {
    v.map(|s| {
        if s.is_finite() && s > 0.0 && s <= 1.0e6 {
            Ok(s)
        } else {
            Err(bad(name, format!("must be > 0 and at most 1e6, got {s}")))
        }
    })
    .transpose()
}

impl ReportInput {
    fn kind(&self) -> Result<ReportKind, Bad> {
        let s = self
            .source
            .as_deref()
            .ok_or_else(|| bad("source", "is required: adsb, mlat or ais"))?;
        ReportKind::from_name(s)
            .ok_or_else(|| bad("source", format!("must be adsb, mlat or ais, got '{s}'")))
    }

    /// σ per horizontal axis (m).
    fn sigma_horizontal(&self, kind: ReportKind) -> Result<f64, Bad> {
        if let Some(s) = sigma("sigma_m", self.sigma_m)? {
            return Ok(s);
        }
        match kind {
            ReportKind::Adsb => {
                let nacp = self
                    .nacp
                    .ok_or_else(|| bad("nacp", "is required from ADS-B (or give sigma_m)"))?;
                nacp_sigma_m(nacp).ok_or_else(|| {
                    bad(
                        "nacp",
                        format!("must be 1 to 11 (0: accuracy unknown; give sigma_m), got {nacp}"),
                    )
                })
            }
            ReportKind::Mlat => Err(bad(
                "sigma_m",
                "is required from multilateration (its stated accuracy)",
            )),
            ReportKind::Ais => Ok(ais_sigma_m(self.position_accurate.unwrap_or(false))),
        }
    }

    /// The velocity east, north, up (m/s) and its σ per horizontal axis.
    fn velocity(&self, kind: ReportKind) -> Result<Option<([f64; 3], f64)>, Bad> {
        let horizontal = match (
            self.velocity_east_mps,
            self.velocity_north_mps,
            self.sog_kn,
            self.cog_deg,
        ) {
            (None, None, None, None) => return Ok(None),
            (Some(e), Some(n), None, None) => [
                finite_in("velocity_east_mps", e, -2000.0, 2000.0)?,
                finite_in("velocity_north_mps", n, -2000.0, 2000.0)?,
            ],
            (None, None, Some(sog), Some(cog)) => {
                let v =
                    finite_in("sog_kn", sog, 0.0, 102.2)? * wire_formats::asterix::NM_M / 3600.0;
                let c = finite_in("cog_deg", cog, 0.0, 360.0)?.to_radians();
                [v * c.sin(), v * c.cos()]
            }
            (Some(_), None, ..) => {
                return Err(bad(
                    "velocity_north_mps",
                    "given without velocity_east_mps's pair",
                ));
            }
            (None, Some(_), ..) => {
                return Err(bad(
                    "velocity_east_mps",
                    "given without velocity_north_mps's pair",
                ));
            }
            (None, None, Some(_), None) => return Err(bad("cog_deg", "is required with sog_kn")),
            (None, None, None, Some(_)) => return Err(bad("sog_kn", "is required with cog_deg")),
            _ => {
                return Err(bad(
                    "sog_kn",
                    "give the velocity as velocity_east_mps/velocity_north_mps or as sog_kn/cog_deg, not both",
                ));
            }
        };
        let s = match sigma("sigma_velocity_mps", self.sigma_velocity_mps)? {
            Some(s) => s,
            None => match (kind, self.nacv) {
                (ReportKind::Ais, _) => AIS_VELOCITY_SIGMA_MPS,
                (_, Some(n)) => nacv_sigma_mps(n).ok_or_else(|| {
                    bad(
                        "nacv",
                        format!("must be 1 to 4 (0: unknown; give sigma_velocity_mps), got {n}"),
                    )
                })?,
                (_, None) => {
                    return Err(bad(
                        "nacv",
                        "is required with a velocity (or give sigma_velocity_mps)",
                    ));
                }
            },
        };
        let up = self
            .vertical_rate_mps
            .map(|v| finite_in("vertical_rate_mps", v, -300.0, 300.0))
            .transpose()?
            .unwrap_or(0.0);
        Ok(Some(([horizontal[0], horizontal[1], up], s)))
    }

    /// σ of the geometric height (m), when it may be used.
    fn sigma_vertical(&self) -> Result<Option<f64>, Bad> {
        if self.geometric_height_m.is_none() {
            if self.sigma_height_m.is_some() {
                return Err(bad("sigma_height_m", "given without geometric_height_m"));
            }
            return Ok(None);
        }
        Ok(sigma("sigma_height_m", self.sigma_height_m)?
            .or_else(|| self.nacp.and_then(vepu_m).map(|v| v / LINEAR_95)))
    }
}

impl Network {
    /// One report validated and re-expressed in the fusion frame: the
    /// tracker's plot of the report's sensor, or the name of its bad field
    /// (under `report.` for the report's own fields) and why.
    pub(super) fn report(
        &self,
        p: &PlotInput,
        r: &ReportInput,
        config: &TrackerConfig,
        mut identity: Identity,
    ) -> Result<Plot, (&'static str, String)> {
        let t = super::network::checked_time(p.t)?;
        if config.is_parallel() {
            return Err(bad(
                "source",
                "cooperative reports need serial mode: tracker.mode parallel fuses radar \
                 plots at fusion instants (use auto or serial)",
            ));
        }
        let frame = self.frame.as_ref().ok_or_else(|| {
            bad(
                "lat_deg",
                "a report's WGS84 position needs the request's origin (or a radar site in WGS84)",
            )
        })?;
        let kind = r.kind()?;
        if let Some(m) = r.mmsi {
            identity.mmsi = Some(
                u32::try_from(m)
                    .ok()
                    .filter(|&m| m > 0 && m <= algo::tracking::identity::MAX_MMSI)
                    .ok_or_else(|| bad("mmsi", format!("must be 1 to 999999999, got {m}")))?,
            );
        }
        let lat = finite_in(
            "lat_deg",
            r.lat_deg.ok_or_else(|| bad("lat_deg", "is required"))?,
            -90.0,
            90.0,
        )?;
        let lon = finite_in(
            "lon_deg",
            r.lon_deg.ok_or_else(|| bad("lon_deg", "is required"))?,
            -180.0,
            360.0,
        )?;
        let h = r
            .geometric_height_m
            .map(|h| finite_in("geometric_height_m", h, -1000.0, 100_000.0))
            .transpose()?;
        let sigma_horizontal = r.sigma_horizontal(kind)?;
        let sigma_vertical = r.sigma_vertical()?;
        let velocity = r.velocity(kind)?;
        // A report without a height is placed at the targets' assumed
        // height (`tracker.default_height_m`): its horizontal position is
        // what the tracker uses.
        let position = frame
            .geodetic_to_enu(
                lat.to_radians(),
                lon.to_radians(),
                h.unwrap_or(self.target_height),
            )
            .map_err(|e| bad("lat_deg", e.to_string()))?;
        // Velocity: east and north at the report's position are the fusion
        // frame's to within the meridians' convergence (≈ 0.9° per 100 km
        // from the origin), as for a radar's angles.
        let report = Report {
            kind,
            position,
            sigma_horizontal,
            sigma_vertical: sigma_vertical.filter(|_| h.is_some()),
            velocity: velocity.map(|v| v.0),
            sigma_velocity: velocity.map_or(0.0, |v| v.1),
            sigma_vertical_velocity: velocity
                .filter(|_| r.vertical_rate_mps.is_some())
                .map(|v| v.1),
        };
        Ok(Plot::report(
            config.report_sensor(kind),
            t,
            report,
            identity,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_adsb_report_takes_the_sigma_of_its_nacp_and_nacv() {
        // NACp 9: EPU 30 m, σ = 30 / √(−2 ln 0.05) = 30 / 2.4477 =
        // 12.2562 m; NACv 2: 3 m/s, σ 1.2256 m/s; NACp 9's VEPU 45 m
        // (95 %, one-dimensional): σ = 45 / 1.96 = 22.96 m.
        let r = ReportInput {
            source: Some("adsb".into()),
            nacp: Some(9),
            nacv: Some(2),
            velocity_east_mps: Some(200.0),
            velocity_north_mps: Some(0.0),
            geometric_height_m: Some(10_000.0),
            ..Default::default()
        };
        let kind = r.kind().unwrap();
        assert!((r.sigma_horizontal(kind).unwrap() - 12.256_169).abs() < 1e-5);
        assert!((r.velocity(kind).unwrap().unwrap().1 - 1.225_617).abs() < 1e-5);
        assert!((r.sigma_vertical().unwrap().unwrap() - 22.959_605).abs() < 1e-5);
        // The radius holds 95 %: 1 − exp(−(2.4477)²/2) = 0.95.
        assert!((1.0 - (-CIRCULAR_95 * CIRCULAR_95 / 2.0).exp() - 0.95).abs() < 1e-12);
        // No NACp, no σ: refused naming the field.
        let none = ReportInput {
            nacp: None,
            ..r.clone()
        };
        assert_eq!(none.sigma_horizontal(kind).unwrap_err().0, "nacp");
        let zero = ReportInput { nacp: Some(0), ..r };
        assert_eq!(zero.sigma_horizontal(kind).unwrap_err().0, "nacp");
    }

    #[test]
    fn an_ais_velocity_from_sog_and_cog() {
        let r = ReportInput {
            source: Some("ais".into()),
            sog_kn: Some(10.0),
            cog_deg: Some(90.0),
            ..Default::default()
        };
        let (v, s) = r.velocity(ReportKind::Ais).unwrap().unwrap();
        // 10 kn = 18520 m / 3600 s = 5.1444 m/s, due east.
        assert!((v[0] - 5.144_444).abs() < 1e-5 && v[1].abs() < 1e-9);
        assert_eq!(s, AIS_VELOCITY_SIGMA_MPS);
    }
}
