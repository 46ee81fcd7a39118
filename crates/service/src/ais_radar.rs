//! AIS–radar association and radar bias estimation (seed 004): validates a
//! request (radar site, radar tracks in polar or local Cartesian form, AIS as
//! decoded reports and/or raw NMEA lines), projects AIS positions onto the
//! radar's Gauss–Krüger plane, runs `algo::bias::associate`, and returns the
//! association, the bias with its covariance and the compensated tracks.

use std::{collections::BTreeMap, time::Instant};

use super::validate::{Bound, LATITUDE, LONGITUDE};
use super::{Ids, Increasing, Interval, ServiceError, Violations, at, micros_since};
use algo::{
    bias::{
        associate::{self, AisPoint, Config, Path, RadarSample, Seeding},
        cfar::CfarConfig,
        projection::LocalPlane,
    },
    geo::Ellipsoid,
};
use wire_formats::nmea;

/// Below this many associated ships the response warns that the bias is
/// barely determined: one ship fits any (Δρ, Δθ) exactly, two fit it with no
/// redundancy across ships.
pub const MIN_PAIRS_FOR_A_SEPARABLE_BIAS: usize = 3;
/// Most radar samples plus AIS reports in one request.
pub const MAX_POINTS: usize = 1_000_000;
/// Most radar tracks × AIS reports (the time-alignment table) in one request.
pub const MAX_PAIR_SAMPLES: usize = 20_000_000;
/// Most NMEA lines in one request.
pub const MAX_NMEA_LINES: usize = 200_000;

#[derive(Debug, Clone, Default)]
pub struct AssociateInput {
    pub site: Option<SiteInput>,
    /// `wgs84` (default), `grs80` or `krasovsky_1940`.
    pub ellipsoid: Option<String>,
    pub radar_tracks: Vec<TrackInput>,
    pub ais_reports: Vec<AisReportInput>,
    pub nmea: Vec<String>,
    pub options: Option<OptionsInput>,
}

#[derive(Debug, Clone, Default)]
pub struct SiteInput {
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct TrackInput {
    pub id: Option<String>,
    pub samples: Vec<SampleInput>,
}

/// A radar sample: either (range_m, azimuth_deg) or (east_m, north_m).
#[derive(Debug, Clone, Default)]
pub struct SampleInput {
    pub t: Option<f64>,
    pub range_m: Option<f64>,
    pub azimuth_deg: Option<f64>,
    pub east_m: Option<f64>,
    pub north_m: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct AisReportInput {
    pub mmsi: Option<u32>,
    pub t: Option<f64>,
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct OptionsInput {
    pub max_gap_s: Option<f64>,
    pub gate_m: Option<f64>,
    /// `auto` (default), `cfar` or `search`.
    pub seeding: Option<String>,
    pub max_iterations: Option<u32>,
    pub max_range_bias_m: Option<f64>,
    pub max_azimuth_bias_deg: Option<f64>,
    pub cfar_window: Option<u32>,
    pub cfar_guard: Option<u32>,
    pub cfar_k: Option<f64>,
    pub cfar_h: Option<f64>,
    pub widen_search: Option<bool>,
    pub radar_sigma_range_m: Option<f64>,
    pub radar_sigma_azimuth_deg: Option<f64>,
    pub ais_sigma_m: Option<f64>,
    /// Time uncertainty (s, standard deviation) of the decoded `ais_reports`.
    pub ais_time_sigma_s: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PairOut {
    pub radar_track_id: String,
    pub mmsi: u32,
    pub distance_m: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct AssociationOut {
    pub radar_track_id: String,
    pub mmsi: u32,
    pub distance_before_m: f64,
    pub distance_after_m: f64,
    pub common_samples: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BiasOut {
    pub range_m: f64,
    pub azimuth_deg: f64,
    /// [[m², m·deg], [m·deg, deg²]].
    pub covariance: [[f64; 2]; 2],
    pub pairs_used: usize,
    pub samples_used: usize,
    /// (Σ n_k)² / Σ n_k² over the pairs' sample counts.
    pub effective_pairs: f64,
}

/// A distinct bias that associates as many pairs nearly as well.
#[derive(Debug, Clone, PartialEq)]
pub struct AlternativeOut {
    pub range_m: f64,
    pub azimuth_deg: f64,
    pub pairs: usize,
    pub mean_distance_m: f64,
}

/// What a client tests before trusting the result.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct QualityOut {
    /// No flag below is raised and a bias was estimated from at least
    /// `MIN_PAIRS_FOR_A_SEPARABLE_BIAS` pairs.
    pub reliable: bool,
    pub at_bound: bool,
    pub search_widened: bool,
    pub ambiguous: bool,
    pub inconsistent: bool,
    pub residual_ratio: Option<f64>,
    pub alternative: Option<AlternativeOut>,
    pub hypotheses_ranked: usize,
    pub hypotheses_scored: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct CompensatedSample {
    pub t: f64,
    pub range_m: f64,
    pub azimuth_deg: f64,
    pub east_m: f64,
    pub north_m: f64,
    pub lat_deg: f64,
    pub lon_deg: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct CompensatedTrack {
    pub id: String,
    pub samples: Vec<CompensatedSample>,
}

#[derive(Debug, Clone, PartialEq, Default)]
pub struct NmeaSummary {
    pub lines: usize,
    pub sentences: usize,
    pub messages: usize,
    pub positions: usize,
    /// (message type, count) of the messages that carry no position.
    pub skipped_by_type: Vec<(u8, usize)>,
    /// (0-based line, message).
    pub errors: Vec<(usize, String)>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct AssociateOutput {
    /// `cfar`, `bias_search` or `none`.
    pub path: &'static str,
    pub s1_m: Option<f64>,
    pub s2_m: Option<f64>,
    pub credible_pairs: Vec<PairOut>,
    pub bias: Option<BiasOut>,
    pub iterations: usize,
    pub converged: bool,
    pub associations: Vec<AssociationOut>,
    pub unassociated_radar_tracks: Vec<String>,
    pub unassociated_mmsis: Vec<u32>,
    /// MMSIs sharing fewer than 2 instants with every radar track (a single
    /// report, or outside every track's time span): never associable.
    pub unassociable_mmsis: Vec<u32>,
    pub quality: QualityOut,
    pub compensated_tracks: Vec<CompensatedTrack>,
    pub mean_error_before_m: Option<f64>,
    pub mean_error_after_m: Option<f64>,
    pub nmea: NmeaSummary,
    pub compute_us: f64,
    pub warnings: Vec<String>,
}

/// One AIS report before projection: `rank` 0 for positions of types
/// 1/2/3/18/19 and decoded reports, 1 for type 27's coarse 1/10′ positions.
#[derive(Debug, Clone, Copy)]
struct Report {
    mmsi: u32,
    t: f64,
    lat: f64,
    lon: f64,
    rank: u8,
    time_sigma: f64,
}

/// Type 27 (long-range broadcast) carries 1/10′ positions (about 185 m);
/// every other position report 1/10000′.
fn report_rank(message_type: u8) -> u8 {
    u8::from(message_type == 27)
}

/// One report per time: of reports with the same time the best rank is
/// kept; equally ranked ones are averaged (position and time σ), so the
/// result never depends on their order.
fn best_per_time(mut pts: Vec<(AisPoint, u8)>) -> Vec<AisPoint> {
    pts.sort_by(|a, b| a.0.t.total_cmp(&b.0.t).then(a.1.cmp(&b.1)));
    let mut out: Vec<AisPoint> = Vec::with_capacity(pts.len());
    let mut k = 0;
    while k < pts.len() {
        let (t, rank) = (pts[k].0.t, pts[k].1);
        let group: Vec<&AisPoint> = pts[k..]
            .iter()
            .take_while(|p| p.0.t == t && p.1 == rank)
            .map(|p| &p.0)
            .collect();
        let n = group.len() as f64;
        out.push(AisPoint {
            t,
            position: [
                group.iter().map(|p| p.position[0]).sum::<f64>() / n,
                group.iter().map(|p| p.position[1]).sum::<f64>() / n,
            ],
            time_sigma: group.iter().map(|p| p.time_sigma).fold(0.0, f64::max),
        });
        k += pts[k..].iter().take_while(|p| p.0.t == t).count();
    }
    out
}

/// The wire word of a path.
pub fn path_name(p: Path) -> &'static str {
    match p {
        Path::Cfar => "cfar",
        Path::BiasSearch => "bias_search",
        Path::None => "none",
    }
}

/// Times of radar samples and AIS reports, in s.
const TIME: Interval = Interval::closed(-1e12, 1e12);
/// Positions in the radar's plane, in m.
const PLANE: Interval = Interval::closed(-1e7, 1e7);

/// The options, each checked at its own wire field; absent ones take the
/// defaults of the numerical core.
fn config(v: &mut Violations, o: &Option<OptionsInput>) -> Option<Config> {
    let o = o.clone().unwrap_or_default();
    let d = Config::default();
    let seeding = v.one_of(
        "options.seeding",
        o.seeding.as_deref(),
        Some(Seeding::Auto),
        &[
            ("auto", Seeding::Auto),
            ("cfar", Seeding::Cfar),
            ("search", Seeding::Search),
        ],
    );
    let max_gap = positive_option(v, "max_gap_s", o.max_gap_s, d.max_gap);
    let gate = positive_option(v, "gate_m", o.gate_m, d.gate);
    let max_iterations = v.count_or(
        "options.max_iterations",
        o.max_iterations,
        d.max_iterations as u32,
        1,
        1000,
    );
    let max_range_bias = v.number_or(
        "options.max_range_bias_m",
        o.max_range_bias_m,
        d.max_range_bias,
        Interval::NON_NEGATIVE,
    );
    let max_azimuth_bias = v.number_or(
        "options.max_azimuth_bias_deg",
        o.max_azimuth_bias_deg,
        d.max_azimuth_bias.to_degrees(),
        Interval::closed(0.0, 180.0),
    );
    let sigma_range = positive_option(
        v,
        "radar_sigma_range_m",
        o.radar_sigma_range_m,
        d.sigma_range,
    );
    let sigma_azimuth = positive_option(
        v,
        "radar_sigma_azimuth_deg",
        o.radar_sigma_azimuth_deg,
        d.sigma_azimuth.to_degrees(),
    );
    let sigma_ais = v.number_or(
        "options.ais_sigma_m",
        o.ais_sigma_m,
        d.sigma_ais,
        Interval::NON_NEGATIVE,
    );
    let cfar = cfar_config(v, &o, &d.cfar);
    // Given values keep their exact radians; a default is the core's own.
    let radians = |given: Option<f64>, checked: Option<f64>, default: f64| {
        checked.map(|_| given.map_or(default, f64::to_radians))
    };
    Some(Config {
        max_gap: max_gap?,
        gate: gate?,
        seeding: seeding?,
        max_iterations: max_iterations? as usize,
        max_range_bias: max_range_bias?,
        max_azimuth_bias: radians(o.max_azimuth_bias_deg, max_azimuth_bias, d.max_azimuth_bias)?,
        widen: o.widen_search.unwrap_or(d.widen),
        sigma_range: sigma_range?,
        sigma_azimuth: radians(o.radar_sigma_azimuth_deg, sigma_azimuth, d.sigma_azimuth)?,
        sigma_ais: sigma_ais?,
        cfar: cfar?,
        ..d
    })
}

/// `options.{name}`, positive, or the core's default.
fn positive_option(v: &mut Violations, name: &str, x: Option<f64>, default: f64) -> Option<f64> {
    v.number_or(format!("options.{name}"), x, default, Interval::POSITIVE)
}

/// The CA-CFAR options (`options.cfar_*`).
fn cfar_config(v: &mut Violations, o: &OptionsInput, d: &CfarConfig) -> Option<CfarConfig> {
    let window = v.count_or(
        "options.cfar_window",
        o.cfar_window,
        d.window as u32,
        1,
        1000,
    );
    let guard = v.count_or("options.cfar_guard", o.cfar_guard, d.guard as u32, 0, 100);
    let k = positive_option(v, "cfar_k", o.cfar_k, d.k);
    let h = v.number_or(
        "options.cfar_h",
        o.cfar_h,
        d.h,
        Interval {
            lo: Bound::Closed(1.0),
            hi: Bound::Unbounded,
        },
    );
    Some(CfarConfig {
        window: window? as usize,
        guard: guard? as usize,
        k: k?,
        h: h?,
    })
}

/// A request parsed into the numerical core's terms: the radar's plane,
/// the options, the radar tracks in polar form (with their ids), the
/// decoded AIS reports and the NMEA lines decoded.
struct Parsed {
    plane: LocalPlane,
    cfg: Config,
    ids: Vec<String>,
    tracks: Vec<Vec<RadarSample>>,
    reports: Vec<Report>,
    decoded: nmea::Decoded,
}

/// Validates the whole request: every violation, each at its field.
fn parse(input: AssociateInput) -> Result<Parsed, ServiceError> {
    let mut v = Violations::new();
    let site = parse_site(&mut v, input.site);
    let ellipsoid = v.one_of(
        "ellipsoid",
        input.ellipsoid.as_deref(),
        Some(Ellipsoid::WGS84),
        &[
            ("wgs84", Ellipsoid::WGS84),
            ("grs80", Ellipsoid::GRS80),
            ("krasovsky_1940", Ellipsoid::KRASOVSKY_1940),
        ],
    );
    let cfg = config(&mut v, &input.options);
    let ais_time_sigma = v
        .number_or(
            "options.ais_time_sigma_s",
            input.options.as_ref().and_then(|o| o.ais_time_sigma_s),
            0.0,
            Interval::closed(0.0, 3600.0),
        )
        .unwrap_or(0.0);
    let points = input
        .radar_tracks
        .iter()
        .map(|t| t.samples.len())
        .sum::<usize>()
        + input.ais_reports.len();
    v.at_most(
        "radar_tracks",
        points,
        MAX_POINTS,
        "samples and AIS reports",
    );
    v.at_most("nmea", input.nmea.len(), MAX_NMEA_LINES, "lines");
    // Between the steps, so that an abandoned request stops.
    crate::lanes::checkpoint()?;
    let (ids, tracks) = parse_tracks(&mut v, &input.radar_tracks);
    crate::lanes::checkpoint()?;
    let decoded = nmea::decode(&input.nmea);
    crate::lanes::checkpoint()?;
    let reports = parse_reports(&mut v, &input.ais_reports, ais_time_sigma);
    let ais_total = reports.len() + decoded.positions.len();
    if tracks.len().saturating_mul(ais_total) > MAX_PAIR_SAMPLES {
        v.add(
            "radar_tracks",
            format!(
                "{} tracks × {ais_total} AIS reports exceed {MAX_PAIR_SAMPLES}; split the request by area or time",
                tracks.len()
            ),
        );
    }
    let parsed = (|| Some((site?, ellipsoid?, cfg?)))();
    let ((lat0, lon0), ellipsoid, cfg) = v.finish_with(parsed)?;
    // The core checks its own ranges too; every one of them is parsed
    // above, so this only catches a core whose ranges changed.
    associate::validate_config(&cfg).map_err(|e| ServiceError::Internal(e.to_string()))?;
    let plane = LocalPlane::new(ellipsoid, lat0.to_radians(), lon0.to_radians())
        .map_err(|e| Violations::from_param("site.", e))?;
    Ok(Parsed {
        plane,
        cfg,
        ids,
        tracks,
        reports,
        decoded,
    })
}

/// `site`: the radar's latitude and longitude, in degrees.
fn parse_site(v: &mut Violations, site: Option<SiteInput>) -> Option<(f64, f64)> {
    let s = v.required("site", site)?;
    let lat = v.number("site.lat_deg", s.lat_deg, LATITUDE);
    let lon = v.number("site.lon_deg", s.lon_deg, LONGITUDE);
    lat.zip(lon)
}

/// `radar_tracks`: their ids (an invalid one as "") and their samples in
/// polar form (the valid ones).
fn parse_tracks(v: &mut Violations, input: &[TrackInput]) -> (Vec<String>, Vec<Vec<RadarSample>>) {
    let mut track_ids = Ids::new();
    let mut ids = Vec::with_capacity(input.len());
    let mut tracks = Vec::with_capacity(input.len());
    for (i, t) in input.iter().enumerate() {
        let id = track_ids.check(v, t.id.as_deref(), i, |j| format!("radar_tracks[{j}].id"));
        ids.push(id.unwrap_or_default().to_string());
        if t.samples.len() < 2 {
            v.add(
                format!("radar_tracks[{i}].samples"),
                "must hold at least 2 samples",
            );
        }
        let mut samples = Vec::with_capacity(t.samples.len());
        let mut times = Increasing::new();
        for (k, s) in t.samples.iter().enumerate() {
            if let Some(sample) = parse_sample(v, &mut times, i, k, s) {
                samples.push(sample);
            }
        }
        tracks.push(samples);
    }
    (ids, tracks)
}

/// `radar_tracks[i].samples[k]`: a time after the previous one and either
/// a polar (range, azimuth) or a plane (east, north) position.
fn parse_sample(
    v: &mut Violations,
    times: &mut Increasing,
    i: usize,
    k: usize,
    s: &SampleInput,
) -> Option<RadarSample> {
    // Field paths are built only for a violation (this runs per sample).
    let sf = |name: &str| format!("radar_tracks[{i}].samples[{k}]{name}");
    let time = times.next(v, at(|| sf(".t")), s.t, TIME);
    let polar = s.range_m.is_some() || s.azimuth_deg.is_some();
    let cart = s.east_m.is_some() || s.north_m.is_some();
    let pos = match (polar, cart) {
        (true, false) => {
            let r = v.number_in(at(|| sf(".range_m")), s.range_m, 0.0, 1e7);
            let a = v.number_in(at(|| sf(".azimuth_deg")), s.azimuth_deg, -360.0, 360.0);
            r.zip(a)
                .map(|(r, a)| (r, a.to_radians().rem_euclid(std::f64::consts::TAU)))
        }
        (false, true) => {
            let e = v.number(at(|| sf(".east_m")), s.east_m, PLANE);
            let n = v.number(at(|| sf(".north_m")), s.north_m, PLANE);
            e.zip(n).map(|(e, n)| associate::plane_to_polar([e, n]))
        }
        _ => {
            v.add(
                sf(""),
                "give either range_m and azimuth_deg, or east_m and north_m",
            );
            None
        }
    };
    let (t, (range, azimuth)) = time.zip(pos)?;
    Some(RadarSample { t, range, azimuth })
}

/// `ais_reports`: the decoded reports (the valid ones), each with the
/// request's time σ.
fn parse_reports(v: &mut Violations, input: &[AisReportInput], time_sigma: f64) -> Vec<Report> {
    let mut reports = Vec::with_capacity(input.len());
    for (k, r) in input.iter().enumerate() {
        let f = |name: &str| format!("ais_reports[{k}].{name}");
        let mmsi = v.required(at(|| f("mmsi")), r.mmsi);
        let t = v.number(at(|| f("t")), r.t, TIME);
        let lat = v.number_in(at(|| f("lat_deg")), r.lat_deg, -90.0, 90.0);
        let lon = v.number(at(|| f("lon_deg")), r.lon_deg, LONGITUDE);
        if let (Some(mmsi), Some(t), Some(lat), Some(lon)) = (mmsi, t, lat, lon) {
            reports.push(Report {
                mmsi,
                t,
                lat,
                lon,
                rank: 0,
                time_sigma,
            });
        }
    }
    reports
}

/// Validates, decodes, projects and associates.
pub fn associate(input: AssociateInput) -> Result<AssociateOutput, ServiceError> {
    let Parsed {
        plane,
        cfg,
        ids,
        tracks,
        mut reports,
        decoded,
    } = parse(input)?;
    let start = Instant::now();
    let mut warnings = Vec::new();
    let nmea_errors = add_nmea_reports(&decoded, &mut reports, &mut warnings);
    let (mmsis, ships) = ships(&plane, &reports, &mut warnings);
    crate::lanes::checkpoint()?;
    if ships.is_empty() {
        warnings.push("no AIS positions: nothing to associate, the bias is not estimated".into());
    }
    if tracks.is_empty() {
        warnings.push("no radar tracks: nothing to associate".into());
    }
    let out = associate::associate(&tracks, &ships, &cfg);
    if out.path == Path::None && !ships.is_empty() && !tracks.is_empty() {
        warnings.push("no radar track could be associated with an AIS ship; the bias is not estimated and the tracks are returned uncompensated".into());
    }
    let unassociable_mmsis: Vec<u32> = out.unassociable_ais.iter().map(|&j| mmsis[j]).collect();
    warn_about_result(&out, &cfg, &ships, &mut warnings);
    let bias = out.estimate.map(|e| e.bias).unwrap_or_default();
    crate::lanes::checkpoint()?;
    let compensated_tracks = compensated_tracks(&plane, &tracks, &ids, bias);
    let nmea = NmeaSummary {
        lines: decoded.lines,
        sentences: decoded.sentences,
        messages: decoded.messages,
        positions: decoded.positions.len(),
        skipped_by_type: decoded.skipped_by_type.into_iter().collect(),
        errors: nmea_errors,
    };
    Ok(AssociateOutput {
        unassociable_mmsis,
        compensated_tracks,
        nmea,
        warnings,
        ..output(&out, &ids, &mmsis, start)
    })
}

/// Adds the NMEA position reports that carry a receive time to `reports`;
/// returns the NMEA lines that could not be used (decoding errors and
/// untimed reports), in line order.
fn add_nmea_reports(
    decoded: &nmea::Decoded,
    reports: &mut Vec<Report>,
    warnings: &mut Vec<String>,
) -> Vec<(usize, String)> {
    let mut nmea_errors: Vec<(usize, String)> = decoded
        .errors
        .iter()
        .map(|e| (e.line, e.message.clone()))
        .collect();
    let mut untimed = 0;
    for p in &decoded.positions {
        match p.t {
            Some(t) => {
                // A time stamp of resolution r stands for the interval
                // [t, t + r): its middle, uniform within ±r/2.
                let r = p.t_resolution.unwrap_or(0.0);
                reports.push(Report {
                    mmsi: p.mmsi,
                    t: t + r / 2.0,
                    lat: p.lat_deg,
                    lon: p.lon_deg,
                    rank: report_rank(p.message_type),
                    time_sigma: associate::quantisation_sigma(r),
                })
            }
            None => {
                untimed += 1;
                nmea_errors.push((
                    p.line,
                    "position report without a receive time (tag block c:) is not used".into(),
                ));
            }
        }
    }
    nmea_errors.sort_by_key(|e| e.0);
    if untimed > 0 {
        warnings.push(format!(
            "{untimed} NMEA position report(s) had no tag-block time and were not used"
        ));
    }
    if !nmea_errors.is_empty() {
        warnings.push(format!(
            "{} NMEA line(s) could not be used; see nmea.errors",
            nmea_errors.len()
        ));
    }
    nmea_errors
}

/// The reports projected onto the radar's plane and grouped by MMSI (in
/// MMSI order), one report per time (`best_per_time`).
fn ships(
    plane: &LocalPlane,
    reports: &[Report],
    warnings: &mut Vec<String>,
) -> (Vec<u32>, Vec<Vec<AisPoint>>) {
    let mut by_mmsi: BTreeMap<u32, Vec<(AisPoint, u8)>> = BTreeMap::new();
    for r in reports {
        let position = plane.forward(r.lat.to_radians(), r.lon.to_radians());
        by_mmsi.entry(r.mmsi).or_default().push((
            AisPoint {
                t: r.t,
                position,
                time_sigma: r.time_sigma,
            },
            r.rank,
        ));
    }
    let mut duplicates = 0;
    let by_mmsi: BTreeMap<u32, Vec<AisPoint>> = by_mmsi
        .into_iter()
        .map(|(m, pts)| {
            let before = pts.len();
            let kept = best_per_time(pts);
            duplicates += before - kept.len();
            (m, kept)
        })
        .collect();
    if duplicates > 0 {
        warnings.push(format!(
            "{duplicates} AIS report(s) repeated an MMSI's time stamp (whole-second tag-block times do): \
             of each group the best kind was kept (types 1/2/3/18/19 and decoded reports over the \
             coarse type 27) and equally good ones averaged"
        ));
    }
    (
        by_mmsi.keys().copied().collect(),
        by_mmsi.into_values().collect(),
    )
}

/// The warnings a client reads before trusting the association's result.
fn warn_about_result(
    out: &associate::Outcome,
    cfg: &Config,
    ships: &[Vec<AisPoint>],
    warnings: &mut Vec<String>,
) {
    let deg = 180.0 / std::f64::consts::PI;
    if !out.converged {
        warnings.push(format!(
            "the association still changed after {} iterations",
            out.iterations
        ));
    }
    if let (Some(c), Some(s)) = out.gated_by_seed
        && s > c
    {
        warnings.push(format!(
            "CA-CFAR credible pairs led to {c} associations, the bias search to {s}; the search result is reported"
        ));
    }
    if !out.unassociable_ais.is_empty() {
        let single = out
            .unassociable_ais
            .iter()
            .filter(|&&j| ships[j].len() == 1)
            .count();
        warnings.push(format!(
            "{} AIS ship(s) can never be associated ({single} with a single report): a pair needs \
             at least 2 instants in common with a radar track; send more reports or a longer \
             window (unassociable_mmsis)",
            out.unassociable_ais.len()
        ));
    }
    if let Some((there, within)) = out.widened {
        warnings.push(format!(
            "the bias search widened past max_range_bias_m = {} / max_azimuth_bias_deg = {}: a bias \
             there gates {there} pairs against {within} within the bounds; raise the bounds if the \
             radar's bias can be this large",
            cfg.max_range_bias,
            cfg.max_azimuth_bias * deg
        ));
    }
    if let Some(e) = out.estimate.filter(|_| out.at_bound) {
        warnings.push(format!(
            "the bias ({:.1} m, {:.4}°) lies on or beyond a search bound (max_range_bias_m = {}, \
             max_azimuth_bias_deg = {}); the true bias may lie further out: raise the bounds",
            e.bias.range,
            e.bias.azimuth * deg,
            cfg.max_range_bias,
            cfg.max_azimuth_bias * deg
        ));
    }
    if let Some(e) = out.estimate.filter(|_| out.inconsistent) {
        warnings.push(format!(
            "the residuals after compensation are {:.1} times the stated errors (radar_sigma_range_m \
             = {}, radar_sigma_azimuth_deg = {}, ais_sigma_m = {}): the association or the bias is \
             likely wrong, or the stated errors too small",
            e.residual_ratio,
            cfg.sigma_range,
            cfg.sigma_azimuth * deg,
            cfg.sigma_ais
        ));
    }
    if let Some(a) = &out.ambiguous {
        warnings.push(format!(
            "ambiguous: a distinct bias ({:.1} m, {:.4}°) associates {} pairs with a mean distance of \
             {:.1} m, nearly as well as the reported one; more ships with AIS or a smaller gate_m \
             would separate them",
            a.bias.range,
            a.bias.azimuth * deg,
            a.pairs,
            a.mean_distance
        ));
    }
    if let Some(e) = &out.estimate
        && e.pairs < MIN_PAIRS_FOR_A_SEPARABLE_BIAS
    {
        warnings.push(format!(
            "the bias rests on {} associated ship(s): with fewer than {MIN_PAIRS_FOR_A_SEPARABLE_BIAS} a \
             common radar bias cannot be told apart from the ships' own AIS or radar errors, and \
             the association is only as good as the bias search's first guess",
            e.pairs
        ));
    }
}

/// Every radar track with the bias taken out, in polar, plane and
/// geodetic form.
fn compensated_tracks(
    plane: &LocalPlane,
    tracks: &[Vec<RadarSample>],
    ids: &[String],
    bias: associate::Bias,
) -> Vec<CompensatedTrack> {
    tracks
        .iter()
        .zip(ids)
        .map(|(t, id)| {
            let compensated: Vec<RadarSample> =
                t.iter().map(|s| associate::compensate(s, bias)).collect();
            let plane_points: Vec<[f64; 2]> = compensated
                .iter()
                .map(|c| associate::polar_to_plane(c.range, c.azimuth))
                .collect();
            // The track's samples at once: the local inverse vectorises.
            let geodetic = plane.inverse_many(&plane_points);
            CompensatedTrack {
                id: id.clone(),
                samples: compensated
                    .iter()
                    .zip(&plane_points)
                    .zip(geodetic)
                    .map(|((c, p), (la, lo))| CompensatedSample {
                        t: c.t,
                        range_m: c.range,
                        azimuth_deg: c.azimuth.to_degrees(),
                        east_m: p[0],
                        north_m: p[1],
                        lat_deg: la.to_degrees(),
                        lon_deg: lo.to_degrees(),
                    })
                    .collect(),
            }
        })
        .collect()
}

/// What a client tests before trusting the result.
fn quality(out: &associate::Outcome) -> QualityOut {
    let deg = 180.0 / std::f64::consts::PI;
    QualityOut {
        reliable: out
            .estimate
            .is_some_and(|e| e.pairs >= MIN_PAIRS_FOR_A_SEPARABLE_BIAS)
            && !out.at_bound
            && out.widened.is_none()
            && out.ambiguous.is_none()
            && !out.inconsistent
            && out.converged,
        at_bound: out.at_bound,
        search_widened: out.widened.is_some(),
        ambiguous: out.ambiguous.is_some(),
        inconsistent: out.inconsistent,
        residual_ratio: out.estimate.map(|e| e.residual_ratio),
        alternative: out.ambiguous.map(|a| AlternativeOut {
            range_m: a.bias.range,
            azimuth_deg: a.bias.azimuth * deg,
            pairs: a.pairs,
            mean_distance_m: a.mean_distance,
        }),
        hypotheses_ranked: out.hypotheses,
        hypotheses_scored: out.evaluated,
    }
}

/// The association's result under the request's ids and MMSIs; the
/// caller fills in the compensated tracks, the NMEA summary and the
/// warnings.
fn output(
    out: &associate::Outcome,
    ids: &[String],
    mmsis: &[u32],
    start: Instant,
) -> AssociateOutput {
    let deg = 180.0 / std::f64::consts::PI;
    let associated_r: Vec<usize> = out.associations.iter().map(|a| a.radar).collect();
    let associated_a: Vec<usize> = out.associations.iter().map(|a| a.ais).collect();
    AssociateOutput {
        path: path_name(out.path),
        s1_m: out.thresholds.map(|t| t.s1),
        s2_m: out.thresholds.map(|t| t.s2),
        credible_pairs: out
            .credible_pairs
            .iter()
            .map(|&(i, j, d)| PairOut {
                radar_track_id: ids[i].clone(),
                mmsi: mmsis[j],
                distance_m: d,
            })
            .collect(),
        bias: out.estimate.map(|e| BiasOut {
            range_m: e.bias.range,
            azimuth_deg: e.bias.azimuth * deg,
            covariance: [
                [e.covariance[0][0], e.covariance[0][1] * deg],
                [e.covariance[1][0] * deg, e.covariance[1][1] * deg * deg],
            ],
            pairs_used: e.pairs,
            samples_used: e.samples,
            effective_pairs: e.effective_pairs,
        }),
        iterations: out.iterations,
        converged: out.converged,
        associations: out
            .associations
            .iter()
            .map(|a| AssociationOut {
                radar_track_id: ids[a.radar].clone(),
                mmsi: mmsis[a.ais],
                distance_before_m: a.distance_before,
                distance_after_m: a.distance_after,
                common_samples: a.common,
            })
            .collect(),
        unassociated_radar_tracks: (0..ids.len())
            .filter(|i| !associated_r.contains(i))
            .map(|i| ids[i].clone())
            .collect(),
        unassociated_mmsis: (0..mmsis.len())
            .filter(|j| !associated_a.contains(j))
            .map(|j| mmsis[j])
            .collect(),
        unassociable_mmsis: Vec::new(),
        quality: quality(out),
        compensated_tracks: Vec::new(),
        mean_error_before_m: out.mean_error_before,
        mean_error_after_m: out.mean_error_after,
        nmea: NmeaSummary::default(),
        compute_us: micros_since(start),
        warnings: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(t: f64, x: f64) -> AisPoint {
        AisPoint {
            t,
            position: [x, 0.0],
            time_sigma: 0.3,
        }
    }

    #[test]
    fn an_abandoned_request_stops_before_its_tracks_are_parsed() {
        // A request without a site: a violation when someone waits for
        // the answer, and stopped at the first checkpoint when nobody does.
        let input = || AssociateInput::default();
        assert!(matches!(
            associate(input()),
            Err(ServiceError::InvalidInput(_))
        ));
        let stopped = crate::lanes::as_abandoned(|| associate(input()));
        assert!(
            matches!(stopped, Err(ServiceError::Cancelled)),
            "{stopped:?}"
        );
    }

    /// Issue 17: of reports sharing a whole-second time the position report
    /// (rank 0) wins over the coarse type 27 (rank 1) in either order, and
    /// equal ones are averaged: never the first by accident.
    #[test]
    fn repeated_times_keep_the_better_report_in_any_order() {
        let a = vec![
            (point(10.5, 185.0), 1),
            (point(10.5, 3.0), 0),
            (point(11.5, 7.0), 0),
        ];
        let mut b = a.clone();
        b.reverse();
        for pts in [a, b] {
            let kept = best_per_time(pts);
            assert_eq!(kept.len(), 2);
            assert_eq!(kept[0].position, [3.0, 0.0]);
            assert_eq!(kept[1].position, [7.0, 0.0]);
        }
        let kept = best_per_time(vec![(point(4.5, 2.0), 0), (point(4.5, 6.0), 0)]);
        assert_eq!(kept, vec![point(4.5, 4.0)]);
        assert_eq!(report_rank(27), 1);
        assert_eq!(report_rank(1), 0);
        assert_eq!(report_rank(18), 0);
    }
}
