//! The radar network of a plot-fusion request: validation of the radars,
//! the origin and the tracker's options into a [`Network`] and a
//! [`TrackerConfig`], and of the plots into the core's [`Plot`]s.
//!
//! Geometry. The fusion frame is the ENU frame at `origin`. A radar given
//! in WGS84 has its site converted exactly, and its own ENU axes differ
//! from the fusion frame's by a rotation (the meridians converge and the
//! horizon tilts, about 0.9° per 100 km). Each plot is therefore
//! re-expressed in the fusion axes at its radar's site: its line of sight
//! `u` (from azimuth and elevation; a 2D plot is taken as horizontal in
//! the radar's frame) is rotated, `u_f = M u` with `M` the rotation from
//! the radar's ENU to the fusion ENU, and the azimuth (and elevation) of
//! `u_f` replace the measured ones; the range and the radial velocity are
//! invariant. The angle noise is kept (the rotation is a few degrees at
//! most, so the error of keeping σ_θ, σ_φ is of second order). A radar
//! given as a local `position_m` is the patent's flat model: its axes are
//! the fusion frame's and its plots are used as measured.
//!
//! Slant range. A 2D radar measures the slant range ρ to a target at an
//! unknown height; the tracker's plane needs the horizontal position. The
//! targets are assumed at `tracker.default_height_m` H (default 0): for a
//! geodetic site H is the ellipsoidal height and the elevation of the line
//! of sight follows from the triangle centre–site–target on a sphere of
//! radius R = 6371 km, sin ε = ((R + H)² − (R + h)² − ρ²) / (2 (R + h) ρ)
//! (h the site's height); for a local site (flat model) sin ε = (H − u)/ρ,
//! so H = u gives the patent's horizontal range ρ exactly. The line of
//! sight is re-expressed in the fusion axes like a 3D plot's and its
//! horizontal part kept (range ρ cos ε_f, azimuth). ε is clamped to ±89°
//! (a target nearly overhead, or a slant range too short for H).

use std::collections::HashMap;

use nalgebra::Matrix3;

use super::{
    DEFAULT_CLUTTER_DENSITY, DEFAULT_P_DETECTION, GeoInput, MAX_RADARS, PlotInput,
    RadarAccuracyView, RadarBiasView, SigmaView, SpecInput, TrackView,
};
use crate::validate::{Listed, id_problem};
use crate::{Ids, Interval, ServiceError, Violations};
use algo::{
    AlgoError,
    geo::{Ellipsoid, LocalFrame},
    jpda::Method,
    polar::{enu_to_polar_3d, polar_to_enu_3d},
    tracking::{
        Deletion, Imm, Mode, Motion, MotionModel, NoiseModel, Plot, RadarSpec, Tracker,
        TrackerConfig, TrackerParameter, ValidTrackerConfig, VelocityGate,
        accuracy::AccuracyConfig,
        height::{HeightDatum, ModeCHeight, radii_of_curvature},
        registration::{BiasPrior, RegistrationConfig},
    },
};
use wire_formats::asterix::FT_M;
use wire_formats::wire::{FormatError, Reader, Writer, invalid};

/// Longest plot range accepted (m): far beyond any radar's horizon.
const MAX_RANGE_M: f64 = 1.0e7;
/// Largest |t| accepted (s): about 31,700 years, so Unix times fit.
const MAX_ABS_T_S: f64 = 1.0e12;

/// What the service keeps of a validated network besides the core's
/// configuration: the fusion frame, the radars' ids and their rotations.
#[derive(Debug, Clone, PartialEq)]
pub struct Network {
    /// The fusion frame; `None` when every site is local and no origin was
    /// given (tracks then carry no latitude and longitude).
    pub frame: Option<LocalFrame>,
    pub radar_ids: Vec<String>,
    /// Per radar: the rotation from its ENU axes to the fusion frame's
    /// (`None` for a local site: axes parallel) and its height (WGS84
    /// ellipsoidal for a geodetic site, the `up` offset for a local one).
    pub sites: Vec<RadarSite>,
    /// The height assumed for targets seen by 2D radars
    /// (`tracker.default_height_m`): ellipsoidal for geodetic sites and for
    /// the latitude/longitude of 2D tracks, fusion-frame `up` for local sites.
    pub target_height: f64,
    /// Per radar: its ASTERIX (SAC, SIC), if declared.
    pub sources: Vec<Option<(u8, u8)>>,
    index: HashMap<String, usize>,
    source_index: HashMap<(u8, u8), usize>,
}

/// A radar's site as the plot conversion needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarSite {
    pub rotation: Option<Matrix3<f64>>,
    pub height: f64,
}

/// Earth radius of the spherical slant-range geometry of 2D plots (m).
const EARTH_RADIUS_M: f64 = 6_371_000.0;
/// Largest elevation given to a 2D plot (a target nearly overhead).
const MAX_2D_ELEVATION_RAD: f64 = 89.0 * std::f64::consts::PI / 180.0;

/// The association method names.
pub const ASSOCIATIONS: &[&str] = &[
    "exact",
    "amsjpda",
    "global_nearest_neighbour",
    "nearest_neighbour",
];

/// The wire field of a tracker option. The radars' own options are parsed
/// (and their fields named) before the core sees them, as are the count of
/// radars and the height datum (derived from the frame): those name the
/// tracker as a whole.
fn option_field(parameter: TrackerParameter) -> &'static str {
    use TrackerParameter as P;
    match parameter {
        P::Axes => "tracker.dimensions",
        P::Mode => "tracker.mode",
        P::FusionPeriod => "tracker.fusion_period_s",
        P::FusionEpoch => "tracker.fusion_epoch_s",
        P::TimeTolerance => "tracker.time_tolerance_s",
        P::MaxExactTracks => "tracker.max_exact_cluster_tracks",
        P::PlotGateProbability => "tracker.plot_gate_probability",
        P::TrackGateProbability => "tracker.track_gate_probability",
        P::ConfirmMOfN => "tracker.initiation.m",
        P::VMin => "tracker.initiation.v_min_mps",
        P::VMax => "tracker.initiation.v_max_mps",
        P::InitiationGateProbability => "tracker.initiation.gate_probability",
        P::MinDt => "tracker.initiation.min_dt_s",
        P::MaxDt => "tracker.initiation.max_dt_s",
        P::MaxConsecutiveMisses => "tracker.deletion.max_consecutive_misses",
        P::DeletionMOfN => "tracker.deletion.m",
        P::MaxPositionSigma => "tracker.deletion.max_position_sigma_m",
        P::SigmaA => "tracker.sigma_a_mps2",
        P::DefaultHeight => "tracker.default_height_m",
        P::DefaultHeightSigma => "tracker.default_height_sigma_m",
        P::SigmaTangentialSpeed => "tracker.sigma_tangential_speed_mps",
        P::DuplicateGateProbability => "tracker.duplicate_gate_probability",
        P::MaxLag => "tracker.max_lag_s",
        P::RegistrationPriors => "radars[].bias",
        P::RegistrationReference => "tracker.registration.reference",
        P::RegistrationMaxPairDt => "tracker.registration.max_pair_dt_s",
        P::RegistrationTimeConstant => "tracker.registration.time_constant_s",
        P::ImmModels | P::TurnRate | P::MeanSojourn | P::InitialProbabilities => {
            "tracker.imm_models"
        }
        P::ModeCHeightOffset => "tracker.mode_c_height.offset_m",
        P::ModeCHeightSigmaOffset => "tracker.mode_c_height.sigma_offset_m",
        P::ModeCHeightSlope => "tracker.mode_c_height.slope",
        P::ModeCHeightSigmaSlope => "tracker.mode_c_height.sigma_slope",
        P::AccuracyTimeConstant => "tracker.accuracy.time_constant_s",
        P::AccuracyPinned => "tracker.accuracy.pinned",
        P::Radars
        | P::RadarSite
        | P::RadarSigmaRange
        | P::RadarSigmaAzimuth
        | P::RadarSigmaElevation
        | P::RadarSigmaRadialVelocity
        | P::RadarScanPeriod
        | P::RadarDetectionProbability
        | P::RadarClutterDensity
        | P::HeightDatum => "tracker",
    }
}

/// A plot's (or a report's) time, checked: given, finite, within
/// ±[`MAX_ABS_T_S`].
pub(super) fn checked_time(t: Option<f64>) -> Result<f64, (&'static str, String)> {
    let t = t.ok_or(("t", "is required".to_string()))?;
    if !(t.is_finite() && t.abs() <= MAX_ABS_T_S) {
        return Err((
            "t",
            format!("must be finite and within ±{MAX_ABS_T_S:e} s, got {t}"),
        ));
    }
    Ok(t)
}

/// The session's lag (`tracker.max_lag_s`, default
/// [`algo::tracking::window::DEFAULT_MAX_LAG_S`]), checked: finite, in
/// [0, [`algo::tracking::window::MAX_LAG_LIMIT_S`]].
pub fn max_lag(spec: &SpecInput) -> Result<f64, ServiceError> {
    let lag = spec
        .tracker
        .max_lag_s
        .unwrap_or(algo::tracking::window::DEFAULT_MAX_LAG_S);
    algo::tracking::window::validate_lag(lag).map_err(|e| config_error(&e))?;
    Ok(lag)
}

/// The session's policy for late plots (`tracker.late_plots`, default
/// `auto` with `tracker.max_replay_plots`, default
/// [`algo::tracking::window::DEFAULT_MAX_REPLAY_PLOTS`]).
pub fn late_policy(spec: &SpecInput) -> Result<algo::tracking::LatePolicy, ServiceError> {
    use algo::tracking::LatePolicy;
    let max_replay = spec
        .tracker
        .max_replay_plots
        .unwrap_or(algo::tracking::window::DEFAULT_MAX_REPLAY_PLOTS);
    let auto = LatePolicy::Auto { max_replay };
    let mut v = Violations::new();
    let policy = v.one_of(
        "tracker.late_plots",
        spec.tracker.late_plots.as_deref(),
        Some(auto),
        &[
            ("auto", auto),
            ("reprocess", LatePolicy::Reprocess),
            ("retrodict", LatePolicy::Retrodict),
        ],
    );
    let Some(policy) = policy else {
        return Err(v.finish_with(None::<()>).unwrap_err());
    };
    if spec.tracker.max_replay_plots.is_some() && !matches!(policy, LatePolicy::Auto { .. }) {
        return Err(Violations::single(
            "tracker.max_replay_plots",
            "is for tracker.late_plots \"auto\" (the default); remove it or the policy",
        ));
    }
    Ok(policy)
}

/// A configuration error of the core: an option outside its domain named
/// by its wire field; anything else (a non-finite option, a numeric
/// failure while the tracker is built) against the tracker as a whole.
pub fn config_error(e: &AlgoError) -> ServiceError {
    match e {
        AlgoError::InvalidOption { parameter, reason } => {
            Violations::single(option_field(*parameter), reason)
        }
        AlgoError::InvalidParameter { reason, .. } => Violations::single("tracker", reason),
        other @ (AlgoError::DimensionMismatch { .. }
        | AlgoError::NotSquare { .. }
        | AlgoError::NonFinite { .. }
        | AlgoError::NotSymmetric { .. }
        | AlgoError::NotPositiveDefinite { .. }
        | AlgoError::DegenerateGeometry { .. }
        | AlgoError::BudgetExceeded { .. }) => Violations::single("tracker", other.to_string()),
    }
}

fn geodetic(v: &mut Violations, f: &str, g: &GeoInput) -> Option<LocalFrame> {
    v.site(f, g.lat_deg, g.lon_deg, Some(g.height_m.unwrap_or(0.0)))
}

enum Site {
    Geodetic(LocalFrame),
    Local([f64; 3]),
}

/// Validates a network and the tracker's options; the warnings say what
/// was decided for the caller (the mode, a missing origin). Each nested
/// input has its parser ([`parse_radar`], [`parse_site`], the tracker's
/// choices, initiation, deletion), combined here in the order the
/// violations are reported.
pub fn validate(
    spec: &SpecInput,
) -> Result<(Network, ValidTrackerConfig, Vec<String>), ServiceError> {
    max_lag(spec)?;
    late_policy(spec)?;
    let mut v = Violations::new();
    let mut warnings = Vec::new();
    if !v.count_within("radars", spec.radars.len(), MAX_RADARS, "radar") && !spec.radars.is_empty()
    {
        return v.finish_with(None);
    }
    let mut radar_ids = Ids::new();
    let mut source_of: HashMap<(u8, u8), usize> = HashMap::new();
    let mut parsed_radars = Vec::with_capacity(spec.radars.len());
    for (i, r) in spec.radars.iter().enumerate() {
        parsed_radars.push(parse_radar(&mut v, i, r, &mut radar_ids, &mut source_of));
    }
    let ids: Vec<String> = parsed_radars.iter().map(|r| r.id.clone()).collect();
    let sources: Vec<Option<(u8, u8)>> = parsed_radars.iter().map(|r| r.source).collect();
    let frame = match &spec.origin {
        Some(o) => geodetic(&mut v, "origin", o),
        None => parsed_radars.iter().find_map(|r| match &r.site {
            Some(Site::Geodetic(f)) => Some(*f),
            _ => None,
        }),
    };
    let any_3d = spec.radars.iter().any(|r| r.kind.as_deref() == Some("3d"));
    let tracker = &spec.tracker;
    let axes = parse_axes(&mut v, tracker, any_3d);
    let (mode, noise, method) = parse_choices(&mut v, tracker);
    let mut specs = Vec::with_capacity(parsed_radars.len());
    let mut sites = Vec::with_capacity(parsed_radars.len());
    for r in parsed_radars {
        specs.extend(r.spec);
        sites.push(r.site);
    }
    // Every radar's site, when each parsed.
    let sites: Option<Vec<Site>> = sites.into_iter().collect();
    let parsed = (|| Some((axes?, mode?, method?, noise?, sites?)))();
    let (axes, mode, method, noise, sites) = v.finish_with(parsed)?;

    let radar_sites = place_sites(&mut specs, &sites, frame)?;
    if frame.is_none() {
        warnings.push(
            "no origin: every site is a local position_m, so tracks carry no lat_deg/lon_deg; \
             give origin (WGS84) to have them"
                .into(),
        );
    }

    let mut config = TrackerConfig::new(axes, specs);
    config.set_mode(mode);
    config.noise = noise;
    config.association.method = method;
    apply_scalars(&mut config, tracker);
    if let Some(i) = &tracker.initiation {
        apply_initiation(&mut config.initiation, i)?;
    }
    if let Some(d) = &tracker.deletion {
        config.deletion = parse_deletion(d)?;
    }
    config.motion = motion(tracker, &mut warnings)?;
    config.registration = registration(spec, &ids, &config)?;
    config.height_datum = height_datum(frame.as_ref());
    if let Some(m) = &tracker.mode_c_height {
        apply_mode_c_height(&mut config.mode_c_height, m);
    }
    if let Some(a) = &tracker.accuracy {
        config.accuracy = accuracy(a, &ids)?;
    }
    let config = config.validated().map_err(|e| config_error(&e))?;
    warnings.extend(fusion_period_warnings(&config, &ids));
    Ok((
        Network::from_parts(frame, ids, radar_sites, config.default_height).with_sources(sources),
        config,
        warnings,
    ))
}

/// One radar as parsed: its id (empty when bad), ASTERIX source, site and
/// core specification (each `None` when a violation was recorded).
struct ParsedRadar {
    id: String,
    source: Option<(u8, u8)>,
    site: Option<Site>,
    spec: Option<RadarSpec>,
}

/// `radars[i]`: id, kind, site, sigmas, scan period, P_D, clutter, SAC/SIC.
fn parse_radar<'a>(
    v: &mut Violations,
    i: usize,
    r: &'a super::RadarInput,
    radar_ids: &mut Ids<'a>,
    source_of: &mut HashMap<(u8, u8), usize>,
) -> ParsedRadar {
    let f = format!("radars[{i}]");
    let source = source(v, &f, r.sac, r.sic, i, source_of);
    let id = radar_ids.check(v, r.id.as_deref(), i, |j| format!("radars[{j}].id"));
    let id = id.unwrap_or_default().to_string();
    // A track's `sources` name radars and kinds of report alike.
    if algo::tracking::ReportKind::from_name(&id).is_some() {
        v.add(
            format!("{f}.id"),
            format!("'{id}' is reserved: tracks name their cooperative sources adsb, mlat and ais"),
        );
    }
    let three_d = v.one_of(
        format!("{f}.kind"),
        r.kind.as_deref(),
        None,
        &[("2d", false), ("3d", true)],
    );
    let site = parse_site(v, &f, r.site.as_ref());
    let sr = v.positive(format!("{f}.sigma_range_m"), r.sigma_range_m);
    let sa = v.number(
        format!("{f}.sigma_azimuth_deg"),
        r.sigma_azimuth_deg,
        Interval::open_closed(0.0, 90.0),
    );
    let se = match (three_d, r.sigma_elevation_deg) {
        (Some(true), s) => v.number(
            format!("{f}.sigma_elevation_deg"),
            s,
            Interval::open_closed(0.0, 90.0),
        ),
        (Some(false), Some(_)) => {
            v.add(
                format!("{f}.sigma_elevation_deg"),
                "a 2d radar has no elevation; declare kind 3d",
            );
            None
        }
        _ => None,
    };
    let sv = r
        .sigma_radial_velocity_mps
        .and_then(|s| v.positive(format!("{f}.sigma_radial_velocity_mps"), Some(s)));
    let period = v.positive(format!("{f}.scan_period_s"), r.scan_period_s);
    let pd = v.number_or(
        format!("{f}.p_detection"),
        r.p_detection,
        DEFAULT_P_DETECTION,
        Interval::open_closed(0.0, 1.0),
    );
    // False plots per m·rad.
    let clutter = v.number_or(
        format!("{f}.clutter_density"),
        r.clutter_density,
        DEFAULT_CLUTTER_DENSITY,
        Interval::POSITIVE,
    );
    let spec = (|| {
        let three_d = three_d?;
        Some(RadarSpec {
            site: [0.0; 3],
            sigma_range: sr?,
            sigma_azimuth: sa?.to_radians(),
            sigma_elevation: if three_d {
                se.map(f64::to_radians)
            } else {
                None
            },
            sigma_radial_velocity: sv,
            scan_period: period?,
            detection_probability: pd?,
            clutter_density: clutter?,
        })
    })();
    ParsedRadar {
        id,
        source,
        site,
        spec,
    }
}

/// `{f}.site`: WGS84 or a local `position_m`, exactly one.
fn parse_site(v: &mut Violations, f: &str, site: Option<&super::SiteInput>) -> Option<Site> {
    let Some(s) = site else {
        v.add(format!("{f}.site"), "is required");
        return None;
    };
    match (&s.geodetic, &s.position_m) {
        (Some(g), None) => geodetic(v, &format!("{f}.site"), g).map(Site::Geodetic),
        (None, Some(p)) => {
            if !(p.len() == 2 || p.len() == 3) || p.iter().any(|x| !x.is_finite()) {
                v.add(
                    format!("{f}.site.position_m"),
                    "must be 2 or 3 finite numbers [east, north(, up)] in m",
                );
                None
            } else {
                Some(Site::Local([p[0], p[1], p.get(2).copied().unwrap_or(0.0)]))
            }
        }
        _ => {
            v.add(
                format!("{f}.site"),
                "give either lat_deg/lon_deg/height_m or position_m",
            );
            None
        }
    }
}

/// `tracker.dimensions`: 3 when any radar is 3D, else 2; a 2D tracker
/// takes 2d radars only.
fn parse_axes(v: &mut Violations, tracker: &super::TrackerInput, any_3d: bool) -> Option<usize> {
    match tracker.dimensions {
        None => Some(if any_3d { 3 } else { 2 }),
        Some(d) => {
            let d = v.count_or("tracker.dimensions", Some(d), 3, 2, 3);
            if d == Some(2) && any_3d {
                v.add(
                    "tracker.dimensions",
                    "a 2D tracker takes 2d radars only; use 3 (or omit it)",
                );
            }
            d.map(|d| d as usize)
        }
    }
}

/// `tracker.mode`, `tracker.process_noise`, `tracker.association`.
fn parse_choices(
    v: &mut Violations,
    tracker: &super::TrackerInput,
) -> (Option<Mode>, Option<NoiseModel>, Option<Method>) {
    let mode = v.one_of(
        "tracker.mode",
        tracker.mode.as_deref(),
        Some(Mode::Auto),
        &[
            ("auto", Mode::Auto),
            ("parallel", Mode::Parallel),
            ("serial", Mode::Serial),
        ],
    );
    let noise = v.one_of(
        "tracker.process_noise",
        tracker.process_noise.as_deref(),
        Some(NoiseModel::Cwna),
        &[("cwna", NoiseModel::Cwna), ("dwna", NoiseModel::Dwna)],
    );
    let choices: Vec<(&str, Method)> = ASSOCIATIONS
        .iter()
        .copied()
        .zip([
            Method::Exact,
            Method::Amsjpda,
            Method::GlobalNearestNeighbour,
            Method::NearestNeighbour,
        ])
        .collect();
    let method = v.one_of(
        "tracker.association",
        tracker.association.as_deref(),
        Some(Method::Exact),
        &choices,
    );
    (mode, noise, method)
}

/// Each radar's site in the fusion frame (written into its spec), with its
/// rotation to the fusion axes and its height.
fn place_sites(
    specs: &mut [RadarSpec],
    sites: &[Site],
    frame: Option<LocalFrame>,
) -> Result<Vec<RadarSite>, ServiceError> {
    let mut radar_sites = Vec::with_capacity(specs.len());
    for (spec, site) in specs.iter_mut().zip(sites) {
        match site {
            Site::Local(p) => {
                spec.site = *p;
                radar_sites.push(RadarSite {
                    rotation: None,
                    height: p[2],
                });
            }
            Site::Geodetic(radar) => {
                // A geodetic site gives a frame (the origin, or else the
                // first geodetic site).
                let Some(fusion) = frame else {
                    return Err(ServiceError::Internal(
                        "a geodetic site without a frame".into(),
                    ));
                };
                let (lat, lon, h) = radar.origin_geodetic();
                spec.site = fusion
                    .geodetic_to_enu(lat, lon, h)
                    .map_err(|e| Violations::single("radars", e.to_string()))?;
                radar_sites.push(RadarSite {
                    rotation: Some(radar.rotation_to(&fusion)),
                    height: h,
                });
            }
        }
    }
    Ok(radar_sites)
}

/// The tracker's scalar options over the defaults (checked by
/// `TrackerConfig::validated` afterwards).
fn apply_scalars(config: &mut TrackerConfig, tracker: &super::TrackerInput) {
    if let Some(n) = tracker.max_exact_cluster_tracks {
        config.association.max_exact_tracks = n as usize;
    }
    if let Some(p) = tracker.fusion_period_s {
        config.fusion_period = p;
    }
    if let Some(e) = tracker.fusion_epoch_s {
        config.fusion_epoch = e;
    }
    if let Some(t) = tracker.time_tolerance_s {
        config.time_tolerance = t;
    }
    if let Some(p) = tracker.plot_gate_probability {
        config.plot_gate_probability = p;
    }
    if let Some(p) = tracker.track_gate_probability {
        config.track_gate_probability = p;
    }
    if let Some(s) = tracker.sigma_a_mps2 {
        config.sigma_a = [s; 3];
    }
    if let Some(s) = tracker.sigma_a_vertical_mps2 {
        config.sigma_a[2] = s;
    }
    if let Some(h) = tracker.default_height_m {
        config.default_height = h;
    }
    if let Some(s) = tracker.default_height_sigma_m {
        config.default_height_sigma = s;
    }
    if let Some(s) = tracker.sigma_tangential_speed_mps {
        config.sigma_tangential_speed = s;
    }
    if let Some(p) = tracker.duplicate_gate_probability {
        config.duplicate_gate_probability = p;
    }
}

/// How the fusion frame's `up` relates to the ellipsoidal height: the
/// tangent plane at the frame's origin, or flat for local sites (`up` is
/// the height; a constant difference of datum is part of the pressure
/// offset the tracker learns).
fn height_datum(frame: Option<&LocalFrame>) -> HeightDatum {
    match frame {
        None => HeightDatum::Flat,
        Some(f) => {
            let (lat, _, h) = f.origin_geodetic();
            let ell = f.ellipsoid();
            let (meridian, prime_vertical) = radii_of_curvature(ell.a(), ell.e2(), lat);
            HeightDatum::Tangent {
                origin_height: h,
                meridian,
                prime_vertical,
            }
        }
    }
}

/// `tracker.mode_c_height` over the defaults (checked by
/// `TrackerConfig::validated`).
fn apply_mode_c_height(m: &mut ModeCHeight, input: &super::ModeCHeightInput) {
    if let Some(v) = input.enabled {
        m.enabled = v;
    }
    if let Some(v) = input.learn {
        m.learn = v;
    }
    if let Some(v) = input.offset_m {
        m.offset = v;
    }
    if let Some(v) = input.sigma_offset_m {
        m.sigma_offset = v;
    }
    if let Some(v) = input.slope {
        m.slope = v;
    }
    if let Some(v) = input.sigma_slope {
        m.sigma_slope = v;
    }
}

/// `tracker.initiation` over the defaults: M-of-N, gate, Δt band, and the
/// speed band or the per-axis band (not both).
fn apply_initiation(
    init: &mut algo::tracking::Initiation,
    i: &super::InitiationInput,
) -> Result<(), ServiceError> {
    if let Some(m) = i.m {
        init.confirm_m = m;
    }
    if let Some(n) = i.n {
        init.confirm_n = n;
    }
    if let Some(p) = i.gate_probability {
        init.gate_probability = p;
    }
    if let Some(d) = i.min_dt_s {
        init.min_dt = d;
    }
    if let Some(d) = i.max_dt_s {
        init.max_dt = d;
    }
    match (&i.v_min_axis_mps, &i.v_max_axis_mps) {
        (None, None) => {
            if let VelocityGate::Speed { v_min, v_max } = &mut init.velocity {
                if let Some(x) = i.v_min_mps {
                    *v_min = x;
                }
                if let Some(x) = i.v_max_mps {
                    *v_max = x;
                }
            }
        }
        (Some(lo), Some(hi)) => {
            let axis = |field: &str, x: &[f64]| -> Result<[f64; 3], ServiceError> {
                match x {
                    [e, n] => Ok([*e, *n, f64::NAN]),
                    [e, n, u] => Ok([*e, *n, *u]),
                    _ => Err(Violations::single(
                        field,
                        "must be 2 or 3 numbers [east, north(, up)] in m/s",
                    )),
                }
            };
            let mut lo = axis("tracker.initiation.v_min_axis_mps", lo)?;
            let mut hi = axis("tracker.initiation.v_max_axis_mps", hi)?;
            if lo[2].is_nan() {
                // Vertical band not given: wide open.
                lo[2] = -1.0e6;
                hi[2] = 1.0e6;
            }
            if i.v_min_mps.is_some() || i.v_max_mps.is_some() {
                return Err(Violations::single(
                    "tracker.initiation",
                    "give either the speed band (v_min_mps, v_max_mps) or the per-axis \
                     band (v_min_axis_mps, v_max_axis_mps), not both",
                ));
            }
            init.velocity = VelocityGate::PerAxis {
                v_min: lo,
                v_max: hi,
            };
        }
        (Some(_), None) => {
            return Err(Violations::single(
                "tracker.initiation.v_max_axis_mps",
                "is required with v_min_axis_mps",
            ));
        }
        (None, Some(_)) => {
            return Err(Violations::single(
                "tracker.initiation.v_min_axis_mps",
                "is required with v_max_axis_mps",
            ));
        }
    }
    Ok(())
}

/// `tracker.deletion`: at least one rule; m and n together.
fn parse_deletion(d: &super::DeletionInput) -> Result<Deletion, ServiceError> {
    let misses_m_of_n = match (d.m, d.n) {
        (Some(m), Some(n)) => Some((m, n)),
        (None, None) => None,
        (Some(_), None) => {
            return Err(Violations::single(
                "tracker.deletion.n",
                "is required with deletion.m",
            ));
        }
        (None, Some(_)) => {
            return Err(Violations::single(
                "tracker.deletion.m",
                "is required with deletion.n",
            ));
        }
    };
    let rule = Deletion {
        max_consecutive_misses: d.max_consecutive_misses,
        misses_m_of_n,
        max_position_sigma: d.max_position_sigma_m,
    };
    if rule.max_consecutive_misses.is_none()
        && rule.misses_m_of_n.is_none()
        && rule.max_position_sigma.is_none()
    {
        return Err(Violations::single(
            "tracker.deletion",
            "set at least one rule (max_consecutive_misses, m and n, or \
             max_position_sigma_m): a track that is never deleted coasts forever",
        ));
    }
    Ok(rule)
}

/// Parallel mode: a fusion period longer than a radar's scan fuses two
/// plots of one target from that radar.
fn fusion_period_warnings(config: &TrackerConfig, ids: &[String]) -> Vec<String> {
    if !config.is_parallel() {
        return Vec::new();
    }
    config
        .radars
        .iter()
        .zip(ids)
        .filter(|(r, _)| config.fusion_period > r.scan_period)
        .map(|(r, id)| {
            format!(
                "tracker.fusion_period_s = {} exceeds radar {id}'s scan period {} s: two \
                 plots of one target from that radar can fall in one fusion instant and \
                 are then fused as if from two radars; use a period of at most {} s",
                config.fusion_period, r.scan_period, r.scan_period
            )
        })
        .collect()
}

/// `tracker.registration` and each radar's `bias`, checked and named.
fn registration(
    spec: &SpecInput,
    ids: &[String],
    config: &TrackerConfig,
) -> Result<RegistrationConfig, ServiceError> {
    let mut out = RegistrationConfig::for_radars(config.radars.len());
    let mut v = Violations::new();
    if spec.radars.iter().any(|r| r.bias.is_some()) {
        let d = BiasPrior::default();
        out.priors = spec
            .radars
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let Some(b) = &r.bias else {
                    return d;
                };
                let f = format!("radars[{i}].bias");
                let mut num = |name: &str, x: Option<f64>, default: f64, range: Interval| {
                    v.number_or(format!("{f}.{name}"), x, default, range)
                        .unwrap_or(default)
                };
                // Bounds in the wire units: a bias of more than 10 km or
                // 10° (5° in elevation) is a wrong site or configuration,
                // not a bias to register.
                BiasPrior {
                    range: num("range_m", b.range_m, 0.0, Interval::closed(-1e4, 1e4)),
                    azimuth: num(
                        "azimuth_deg",
                        b.azimuth_deg,
                        0.0,
                        Interval::closed(-10.0, 10.0),
                    )
                    .to_radians(),
                    elevation: num(
                        "elevation_deg",
                        b.elevation_deg,
                        0.0,
                        Interval::closed(-5.0, 5.0),
                    )
                    .to_radians(),
                    sigma_range: num(
                        "sigma_range_m",
                        b.sigma_range_m,
                        d.sigma_range,
                        Interval::closed(0.0, 1e4),
                    ),
                    sigma_azimuth: num(
                        "sigma_azimuth_deg",
                        b.sigma_azimuth_deg,
                        d.sigma_azimuth.to_degrees(),
                        Interval::closed(0.0, 10.0),
                    )
                    .to_radians(),
                    sigma_elevation: num(
                        "sigma_elevation_deg",
                        b.sigma_elevation_deg,
                        d.sigma_elevation.to_degrees(),
                        Interval::closed(0.0, 5.0),
                    )
                    .to_radians(),
                }
            })
            .collect();
    }
    if let Some(r) = &spec.tracker.registration {
        if let Some(e) = r.enabled {
            out.enabled = e;
        }
        if let Some(refs) = &r.reference {
            for (k, id) in refs.iter().enumerate() {
                match ids.iter().position(|x| x == id) {
                    Some(i) => out.reference.push(i),
                    None => v.add(
                        format!("tracker.registration.reference[{k}]"),
                        format!("no radar has the id {id:?}"),
                    ),
                }
            }
        }
        if let Some(n) = r.min_pairs {
            if n == 0 || n > 100_000 {
                v.add("tracker.registration.min_pairs", "must be in 1..=100000");
            }
            out.min_pairs = n;
        }
        if let Some(t) = r.max_pair_dt_s {
            if let Some(t) = v.within(
                "tracker.registration.max_pair_dt_s",
                t,
                Interval::open_closed(0.0, 600.0),
            ) {
                out.max_pair_dt = t;
            }
        }
        if let Some(t) = r.time_constant_s {
            if let Some(t) = v.within(
                "tracker.registration.time_constant_s",
                t,
                Interval::open_closed(0.0, 1e7),
            ) {
                out.time_constant = t;
            }
        }
    }
    v.finish_with(Some(out))
}

/// `tracker.accuracy` over the defaults: pinned radars by id, the time
/// constant in (0, 10⁷] s.
fn accuracy(input: &super::AccuracyInput, ids: &[String]) -> Result<AccuracyConfig, ServiceError> {
    let mut out = AccuracyConfig::default();
    let mut v = Violations::new();
    if let Some(e) = input.enabled {
        out.enabled = e;
    }
    if let Some(t) = input.time_constant_s {
        if let Some(t) = v.within(
            "tracker.accuracy.time_constant_s",
            t,
            Interval::open_closed(0.0, 1e7),
        ) {
            out.time_constant = t;
        }
    }
    for (k, id) in input.pinned.iter().flatten().enumerate() {
        match ids.iter().position(|x| x == id) {
            Some(i) => out.pinned.push(i),
            None => v.add(
                format!("tracker.accuracy.pinned[{k}]"),
                format!("no radar has the id {id:?}"),
            ),
        }
    }
    v.finish_with(Some(out))
}

/// A learnt σ differs from the declared one by more than this factor (up
/// or down): the warning names the radar's option to change.
pub const ACCURACY_WARNING_FACTOR: f64 = 1.5;

/// Warnings about the learnt accuracy: a converged σ more than
/// [`ACCURACY_WARNING_FACTOR`] from the declared one (naming the radar's
/// option), and one at the applied bound
/// (`algo::tracking::accuracy::LIMIT`).
pub fn accuracy_warnings(config: &TrackerConfig, views: &[RadarAccuracyView]) -> Vec<String> {
    let mut out = Vec::new();
    for (r, a) in views.iter().enumerate() {
        // In the order of `RadarAccuracyView::components`.
        let words = [
            ("range", " m"),
            ("azimuth", "°"),
            ("elevation", "°"),
            ("radial velocity", " m/s"),
        ];
        for ((name, s), (what, unit)) in a.components().into_iter().zip(words) {
            let Some(s) = s else { continue };
            let option = format!("sigma_{name}");
            let (Some(est), true) = (s.estimated, s.converged) else {
                continue;
            };
            let ratio = est / s.declared;
            if !(1.0 / ACCURACY_WARNING_FACTOR..=ACCURACY_WARNING_FACTOR).contains(&ratio) {
                let use_ = if a.pinned || !config.accuracy.enabled {
                    "the declared σ is applied (pinned or tracker.accuracy.enabled false)"
                } else {
                    "the learnt σ is applied"
                };
                out.push(format!(
                    "radar {}'s {what} σ is {est:.3}{unit} ± {:.3} from {:.0} plots, {ratio:.2}× the declared {:.3}{unit}: {use_}; set radars[{r}].{option} to the radar's real accuracy",
                    a.radar,
                    s.sigma.unwrap_or(f64::NAN),
                    s.plots,
                    s.declared,
                ));
            }
            let limit = algo::tracking::accuracy::LIMIT;
            if s.converged && !(s.declared / limit..=s.declared * limit).contains(&est) {
                out.push(format!(
                    "radar {}'s {what} σ estimate {est:.3}{unit} is beyond {limit}× the declared {:.3}{unit}: {:.3}{unit} is applied; check radars[{r}].{option} and the radar",
                    a.radar, s.declared, s.applied
                ));
            }
        }
        if let Some(w) = detection_warning(config, r, a) {
            out.push(w);
        }
    }
    out
}

/// A converged detection probability whose miss probability 1 − P_D is
/// more than [`ACCURACY_WARNING_FACTOR`] from the declared one's (either
/// way) and that differs from it by more than 0.02.
fn detection_warning(config: &TrackerConfig, r: usize, a: &RadarAccuracyView) -> Option<String> {
    let s = a.p_detection.as_ref()?;
    let est = s.estimated.filter(|_| s.converged)?;
    let ratio = (1.0 - est) / (1.0 - s.declared).max(1e-9);
    if (1.0 / ACCURACY_WARNING_FACTOR..=ACCURACY_WARNING_FACTOR).contains(&ratio)
        || (est - s.declared).abs() <= 0.02
    {
        return None;
    }
    let use_ = if a.pinned || !config.accuracy.enabled {
        "the declared one is applied (pinned or tracker.accuracy.enabled false)"
    } else {
        "the learnt one is applied"
    };
    Some(format!(
        "radar {}'s detection probability is {est:.3} ± {:.3} from {:.0} scans of its tracks, against the declared {:.3}: {use_}; set radars[{r}].p_detection to the radar's real one",
        a.radar,
        s.sigma.unwrap_or(f64::NAN),
        s.plots,
        s.declared,
    ))
}

/// Warnings about the registration's estimates: a bias beyond what a radar
/// usually has (1 km, 1°: its configuration or alignment is wrong), and a
/// converged bias the geometry leaves unobservable (its σ still above half
/// its prior's).
pub fn registration_warnings(config: &TrackerConfig, views: &[RadarBiasView]) -> Vec<String> {
    let mut out = Vec::new();
    for (r, b) in views.iter().enumerate() {
        if b.range_m.abs() > 1000.0 || b.azimuth_deg.abs() > 1.0 {
            out.push(format!(
                "radar {}'s estimated bias is {:.0} m in range and {:.2}° in azimuth (beyond 1 km or 1°): check its site, its north alignment and its range calibration",
                b.radar, b.range_m, b.azimuth_deg
            ));
        }
        let prior = config.registration.prior(r);
        // After five times the pairs convergence needs, a σ still above
        // half the prior's means the geometry does not fix the bias.
        if b.converged
            && b.pairs >= 5.0 * f64::from(config.registration.min_pairs)
            && (b.sigma_range_m > 0.5 * prior.sigma_range
                || b.sigma_azimuth_deg.to_radians() > 0.5 * prior.sigma_azimuth)
        {
            out.push(format!(
                "radar {}'s bias is poorly observable (σ {:.0} m, {:.3}° after {:.0} pairs, prior σ {:.0} m, {:.3}°): the common targets' geometry does not fix it; declare a surveyed radar in tracker.registration.reference or give radars[].bias",
                b.radar,
                b.sigma_range_m,
                b.sigma_azimuth_deg,
                b.pairs,
                prior.sigma_range,
                prior.sigma_azimuth.to_degrees()
            ));
        }
    }
    out
}

/// The predictor: `tracker.motion` and `tracker.imm_models`.
fn motion(
    tracker: &super::TrackerInput,
    warnings: &mut Vec<String>,
) -> Result<Motion, ServiceError> {
    let mut v = Violations::new();
    let kind = v.one_of(
        "tracker.motion",
        tracker.motion.as_deref(),
        Some(true),
        &[("imm", true), ("cv", false)],
    );
    let Some(imm) = kind else {
        return Err(v.finish_with(None::<()>).unwrap_err());
    };
    if !imm {
        if tracker.imm_models.is_some() {
            return Err(Violations::single(
                "tracker.imm_models",
                "is for tracker.motion \"imm\" (the default); remove it or the motion",
            ));
        }
        return Ok(Motion::ConstantVelocity);
    }
    if tracker.sigma_a_mps2.is_some() || tracker.sigma_a_vertical_mps2.is_some() {
        warnings.push(
            "tracker.sigma_a_mps2 sets the noise of tentative tracks; confirmed tracks follow \
             the IMM's models (tracker.imm_models), or set tracker.motion to \"cv\" for one \
             constant-velocity model with that noise"
                .into(),
        );
    }
    let Some(models) = &tracker.imm_models else {
        return Ok(Motion::Imm(Imm::aircraft()));
    };
    if !(2..=8).contains(&models.len()) {
        return Err(Violations::single(
            "tracker.imm_models",
            format!("an IMM needs 2 to 8 models, got {}", models.len()),
        ));
    }
    let given = models
        .iter()
        .filter(|m| m.initial_probability.is_some())
        .count();
    if given != 0 && given != models.len() {
        return Err(Violations::single(
            "tracker.imm_models",
            "give initial_probability for every model or for none (equal shares)",
        ));
    }
    let mut out = Imm {
        models: Vec::with_capacity(models.len()),
        mean_sojourn: Vec::with_capacity(models.len()),
        initial_probabilities: Vec::with_capacity(models.len()),
    };
    for (i, m) in models.iter().enumerate() {
        let f = |name: &str| format!("tracker.imm_models[{i}].{name}");
        let turn = v.one_of(
            f("model"),
            m.model.as_deref(),
            None,
            &[("cv", false), ("ct", true)],
        );
        let default_sigma = if turn == Some(true) { 3.0 } else { 0.5 };
        let sigma = v.number_or(
            f("sigma_a_mps2"),
            m.sigma_a_mps2,
            default_sigma,
            Interval::closed(0.0, 1.0e3),
        );
        let vertical = v.number_or(
            f("sigma_a_vertical_mps2"),
            m.sigma_a_vertical_mps2,
            sigma.unwrap_or(default_sigma),
            Interval::closed(0.0, 1.0e3),
        );
        let sojourn = v.number_or(
            f("mean_sojourn_s"),
            m.mean_sojourn_s,
            if turn == Some(true) { 20.0 } else { 60.0 },
            Interval::open_closed(0.0, 1.0e7),
        );
        let p = m
            .initial_probability
            .map(|x| v.within(f("initial_probability"), x, Interval::open_closed(0.0, 1.0)));
        let (Some(turn), Some(sigma), Some(vertical), Some(sojourn), None | Some(Some(_))) =
            (turn, sigma, vertical, sojourn, p)
        else {
            continue;
        };
        let p = p.flatten();
        let sigma_a = [sigma, sigma, vertical];
        let model = if turn {
            let rate = v.required(f("turn_rate_dps"), m.turn_rate_dps);
            match rate {
                Some(r) if r.is_finite() && r != 0.0 && r.abs() <= 28.0 => {
                    MotionModel::CoordinatedTurn {
                        turn_rate: r.to_radians(),
                        sigma_a,
                    }
                }
                Some(r) => {
                    v.add(
                        f("turn_rate_dps"),
                        format!("must be non-zero with |ω| ≤ 28 °/s, got {r}"),
                    );
                    continue;
                }
                None => continue,
            }
        } else {
            if m.turn_rate_dps.is_some() {
                v.add(f("turn_rate_dps"), "is for a \"ct\" model");
            }
            MotionModel::ConstantVelocity { sigma_a }
        };
        out.models.push(model);
        out.mean_sojourn.push(sojourn);
        out.initial_probabilities
            .push(p.unwrap_or(1.0 / models.len() as f64));
    }
    v.finish_with(Some(()))?;
    let sum: f64 = out.initial_probabilities.iter().sum();
    if (sum - 1.0).abs() > 1e-6 {
        return Err(Violations::single(
            "tracker.imm_models",
            format!("the initial_probability values must sum to 1, got {sum}"),
        ));
    }
    for p in &mut out.initial_probabilities {
        *p /= sum;
    }
    Ok(Motion::Imm(out))
}

impl Network {
    /// A network from its stored parts.
    pub fn from_parts(
        frame: Option<LocalFrame>,
        radar_ids: Vec<String>,
        sites: Vec<RadarSite>,
        target_height: f64,
    ) -> Self {
        let index = radar_ids
            .iter()
            .enumerate()
            .map(|(i, id)| (id.clone(), i))
            .collect();
        Self {
            frame,
            sources: vec![None; radar_ids.len()],
            radar_ids,
            sites,
            target_height,
            index,
            source_index: HashMap::new(),
        }
    }

    /// The network with the radars' ASTERIX (SAC, SIC), one per radar.
    pub fn with_sources(mut self, sources: Vec<Option<(u8, u8)>>) -> Self {
        self.source_index = sources
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.map(|s| (s, i)))
            .collect();
        self.sources = sources;
        self
    }

    /// The radar (index) of an ASTERIX (SAC, SIC).
    pub fn radar_of_source(&self, source: (u8, u8)) -> Option<usize> {
        self.source_index.get(&source).copied()
    }

    /// The elevation (degrees, in the radar's own frame) of a target at
    /// `height` seen at slant range `range` by radar `radar`: the geometry
    /// of the 2D plots' assumed height (module header), solved for a
    /// measured height. For a local site sin ε = (H − u)/ρ; for a geodetic
    /// site, on the sphere of radius R through it,
    /// sin ε = ((R + H)² − (R + h)² − ρ²) / (2 (R + h) ρ). `None` when no
    /// elevation fits (|sin ε| > 1).
    pub fn elevation_deg_at_height(&self, radar: usize, range: f64, height: f64) -> Option<f64> {
        let site = &self.sites[radar];
        let sin_el = match site.rotation {
            None => (height - site.height) / range,
            Some(_) => {
                let (rh, rt) = (EARTH_RADIUS_M + site.height, EARTH_RADIUS_M + height);
                (rt * rt - rh * rh - range * range) / (2.0 * rh * range)
            }
        };
        (sin_el.abs() < 1.0).then(|| sin_el.asin().to_degrees())
    }

    /// Whether any radar declares its SAC/SIC.
    pub fn has_sources(&self) -> bool {
        !self.source_index.is_empty()
    }

    /// Validates plots against the network and re-expresses their angles in
    /// the fusion axes; violations name `{field}[i].…` (the radars' ids
    /// are listed in the first violation of an unknown radar only). The
    /// cooperative reports among `inputs` (after the plots, as the
    /// adapters append a request's `cooperative` reports) are named
    /// `cooperative[i]` (under another `field` than `plots`, `{field}[i]`:
    /// the reports of an NMEA block).
    pub fn plots(
        &self,
        inputs: &[PlotInput],
        config: &TrackerConfig,
        field: &str,
    ) -> Result<Vec<Plot>, ServiceError> {
        let parallel = config.is_parallel();
        let mut out = Vec::with_capacity(inputs.len());
        let mut v = Violations::new();
        let mut radars = Listed::new();
        // Reports travel after the plots and are named in their own list.
        let mut counts = [0usize; 2];
        for p in inputs {
            let list = usize::from(p.report.is_some());
            let i = counts[list];
            counts[list] += 1;
            match self.plot(p, config, parallel) {
                Ok(plot) => out.push(plot),
                Err((name, mut message)) => {
                    let list_name = if list == 1 && field == "plots" {
                        "cooperative"
                    } else {
                        field
                    };
                    let path = format!("{list_name}[{i}].{name}");
                    if name == "radar_id" && self.is_unknown(p.radar_id.as_deref()) {
                        message =
                            format!("{message} (radars: {})", radars.ids(&self.radar_ids, &path));
                    }
                    v.add(path, message);
                }
            }
        }
        v.finish()?;
        Ok(out)
    }

    /// Whether `id` is a well-formed id that names no radar of the network.
    fn is_unknown(&self, id: Option<&str>) -> bool {
        id.is_some_and(|id| id_problem(id).is_none() && !self.index.contains_key(id))
    }

    /// One plot validated and re-expressed, or the name of its bad field
    /// and why.
    pub fn plot(
        &self,
        p: &PlotInput,
        config: &TrackerConfig,
        parallel: bool,
    ) -> Result<Plot, (&'static str, String)> {
        if let Some(r) = &p.report {
            let identity = p.ssr.parse()?;
            return self.report(p, r, config, identity);
        }
        let id = p
            .radar_id
            .as_deref()
            .ok_or(("radar_id", "is required".to_string()))?;
        if let Some(problem) = id_problem(id) {
            return Err(("radar_id", problem));
        }
        let &radar = self
            .index
            .get(id)
            .ok_or_else(|| ("radar_id", format!("no radar '{id}' in the network")))?;
        let spec = &config.radars[radar];
        let t = checked_time(p.t)?;
        let range = p.range_m.ok_or(("range_m", "is required".to_string()))?;
        if !(range.is_finite() && range > 0.0 && range <= MAX_RANGE_M) {
            return Err((
                "range_m",
                format!("must be > 0 and at most {MAX_RANGE_M:e} m, got {range}"),
            ));
        }
        let az = p
            .azimuth_deg
            .ok_or(("azimuth_deg", "is required".to_string()))?;
        if !(az.is_finite() && az.abs() <= 720.0) {
            return Err((
                "azimuth_deg",
                format!("must be finite, in [-720, 720], got {az}"),
            ));
        }
        let (elevation, radial_velocity) = elevation_and_doppler(p, spec, id, parallel)?;
        let identity = p.ssr.parse()?;
        let (range, azimuth, elevation, radial_velocity) = if spec.is_3d() {
            let (azimuth, elevation) = match &self.sites[radar].rotation {
                None => (az.to_radians(), elevation),
                Some(m) => rotate(m, az.to_radians(), elevation),
            };
            (range, azimuth, elevation, radial_velocity)
        } else {
            // A validated Mode C altitude is the target's height (pressure
            // altitude for geometric: within a few hundred feet, against
            // `target_height`'s guess of thousands).
            let height = identity
                .mode_c
                .filter(|c| c.validated && !c.garbled)
                .map_or(self.target_height, |c| c.flight_level * 100.0 * FT_M);
            let (range, azimuth, radial_velocity) =
                self.horizontal(radar, range, az.to_radians(), radial_velocity, height);
            (range, azimuth, None, radial_velocity)
        };
        Ok(Plot {
            radar,
            t,
            range,
            azimuth,
            elevation,
            radial_velocity,
            identity,
            report: None,
        })
    }

    /// A 2D radar's plot made horizontal: it measures the slant range ρ to
    /// a target at `height`, so its elevation is sin ε = Δh/ρ (flat, local
    /// sites) or, on a sphere of radius R through the site, ((R + H)² −
    /// (R + h)² − ρ²) / (2 (R + h) ρ). The line of sight at that elevation
    /// is re-expressed in the fusion axes and its horizontal part kept: the
    /// horizontal range ρ cos ε_f and azimuth in the fusion frame. In level
    /// flight the horizontal radial velocity is ṙ / cos ε.
    fn horizontal(
        &self,
        radar: usize,
        range: f64,
        azimuth: f64,
        radial_velocity: Option<f64>,
        height: f64,
    ) -> (f64, f64, Option<f64>) {
        let site = &self.sites[radar];
        let (h, big_h) = (site.height, height);
        let sin_el = match site.rotation {
            None => (big_h - h) / range,
            Some(_) => {
                let (rh, rt) = (EARTH_RADIUS_M + h, EARTH_RADIUS_M + big_h);
                (rt * rt - rh * rh - range * range) / (2.0 * rh * range)
            }
        };
        let el = sin_el
            .clamp(-1.0, 1.0)
            .asin()
            .clamp(-MAX_2D_ELEVATION_RAD, MAX_2D_ELEVATION_RAD);
        let (azimuth, el_f) = match &site.rotation {
            None => (azimuth, el),
            Some(m) => {
                let (a, e) = rotate(m, azimuth, Some(el));
                (a, e.expect("an elevation in, one out"))
            }
        };
        (
            range * el_f.cos(),
            azimuth,
            radial_velocity.map(|v| v / el.cos()),
        )
    }

    /// The wire name of a sensor: a radar's id, or a kind of report's
    /// (`adsb`, `mlat`, `ais`).
    pub fn sensor_name(&self, sensor: usize) -> String {
        match self.radar_ids.get(sensor) {
            Some(id) => id.clone(),
            None => algo::tracking::ReportKind::ALL
                .get(sensor - self.radar_ids.len())
                .map_or("unknown", |k| k.name())
                .to_string(),
        }
    }

    /// A core track as a wire track (ids, and lat/lon from the frame).
    /// Each radar's bias as `tracker` applies it, by radar id.
    pub fn bias_views(&self, tracker: &Tracker) -> Vec<RadarBiasView> {
        tracker
            .biases()
            .iter()
            .zip(&self.radar_ids)
            .zip(&tracker.config().radars)
            .map(|((b, id), r)| RadarBiasView {
                radar: id.clone(),
                range_m: b.bias[0],
                azimuth_deg: b.bias[1].to_degrees(),
                elevation_deg: r.is_3d().then(|| b.bias[2].to_degrees()),
                sigma_range_m: b.sigma[0],
                sigma_azimuth_deg: b.sigma[1].to_degrees(),
                sigma_elevation_deg: r.is_3d().then(|| b.sigma[2].to_degrees()),
                pairs: b.pairs,
                converged: b.converged,
                reference: b.reference,
            })
            .collect()
    }

    /// Each radar's accuracy (σ in the wire units).
    pub fn accuracy_views(&self, tracker: &Tracker) -> Vec<RadarAccuracyView> {
        let view = |s: algo::tracking::accuracy::SigmaEstimate, unit: f64| {
            let known = s.samples > 0.0 && s.sigma.is_finite();
            SigmaView {
                declared: s.declared * unit,
                estimated: known.then_some(s.estimate * unit),
                sigma: known.then_some(s.sigma * unit),
                plots: s.samples,
                converged: s.converged,
                applied: s.applied * unit,
                clipped: s.clipped,
            }
        };
        let deg = 1f64.to_degrees();
        tracker
            .accuracy()
            .into_iter()
            .zip(&self.radar_ids)
            .map(|(a, id)| RadarAccuracyView {
                radar: id.clone(),
                range_m: view(a.range, 1.0),
                azimuth_deg: view(a.azimuth, deg),
                elevation_deg: a
                    .elevation
                    .filter(|_| tracker.config().axes == 3)
                    .map(|s| view(s, deg)),
                radial_velocity_mps: a.radial_velocity.map(|s| view(s, 1.0)),
                p_detection: Some(view(a.detection_probability, 1.0)),
                pinned: a.pinned,
            })
            .collect()
    }

    /// The pressure offset a 3D tracker applies to Mode C, if it does.
    pub fn pressure_offset_view(&self, tracker: &Tracker) -> Option<super::PressureOffsetView> {
        tracker
            .pressure_offset()
            .map(|(e, data)| super::PressureOffsetView {
                offset_m: e.offset,
                slope: e.slope,
                sigma_offset_m: e.sigma_offset(),
                sigma_slope: e.sigma_slope(),
                correlation: e.covariance[1] / (e.covariance[0] * e.covariance[2]).sqrt(),
                plots: data.plots,
                rejected: data.rejected,
            })
    }

    pub fn track_view(
        &self,
        motion: &algo::tracking::Motion,
        t: &algo::tracking::TrackOutput,
    ) -> TrackView {
        super::output::view(self, motion, t)
    }

    /// The SAC/SIC pairs (the plot_fusion session payload's format 2).
    pub fn encode_sources(&self, w: &mut Writer) {
        for s in &self.sources {
            w.opt(s.as_ref(), |w, &(a, b)| {
                w.u8(a);
                w.u8(b);
            });
        }
    }

    pub fn decode_sources(self, r: &mut Reader<'_>) -> Result<Self, FormatError> {
        let sources = (0..self.radar_ids.len())
            .map(|_| r.opt(|r| Ok((r.u8()?, r.u8()?))))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(self.with_sources(sources))
    }

    pub fn encode(&self, w: &mut Writer) {
        w.opt(self.frame.as_ref(), |w, f| {
            let (lat, lon, h) = f.origin_geodetic();
            w.f64(lat);
            w.f64(lon);
            w.f64(h);
        });
        w.f64(self.target_height);
        w.usize(self.radar_ids.len());
        for (id, site) in self.radar_ids.iter().zip(&self.sites) {
            w.str(id);
            w.opt(site.rotation.as_ref(), |w, m| w.f64s(m.as_slice()));
            w.f64(site.height);
        }
    }

    pub fn decode(r: &mut Reader<'_>) -> Result<Self, FormatError> {
        let frame = r.opt(|r| {
            let (lat, lon, h) = (r.f64()?, r.f64()?, r.f64()?);
            LocalFrame::new(Ellipsoid::WGS84, lat, lon, h).map_err(invalid)
        })?;
        let target_height = r.f64()?;
        let n = r.len(17)?;
        let mut ids = Vec::with_capacity(n);
        let mut sites = Vec::with_capacity(n);
        for _ in 0..n {
            ids.push(r.str()?);
            let rotation = r.opt(|r| {
                let v = r.f64s()?;
                if v.len() != 9 {
                    return Err(wire_formats::wire::corrupt("radar rotation"));
                }
                Ok(Matrix3::from_column_slice(&v))
            })?;
            sites.push(RadarSite {
                rotation,
                height: r.f64()?,
            });
        }
        Ok(Self::from_parts(frame, ids, sites, target_height))
    }
}

/// A radar's ASTERIX (SAC, SIC): both or neither, each 0 to 255, no two
/// radars with the same pair.
fn source(
    v: &mut Violations,
    f: &str,
    sac: Option<u32>,
    sic: Option<u32>,
    i: usize,
    seen: &mut HashMap<(u8, u8), usize>,
) -> Option<(u8, u8)> {
    let (sac, sic) = match (sac, sic) {
        (None, None) => return None,
        (Some(_), None) => {
            v.add(format!("{f}.sic"), "is required with sac");
            return None;
        }
        (None, Some(_)) => {
            v.add(format!("{f}.sac"), "is required with sic");
            return None;
        }
        (Some(a), Some(b)) => (a, b),
    };
    let mut ok = true;
    for (name, x) in [("sac", sac), ("sic", sic)] {
        if x > 255 {
            v.add(format!("{f}.{name}"), format!("must be 0 to 255, got {x}"));
            ok = false;
        }
    }
    if !ok {
        return None;
    }
    let pair = (sac as u8, sic as u8);
    if let Some(j) = seen.insert(pair, i) {
        v.add(
            format!("{f}.sic"),
            format!("SAC/SIC {sac}/{sic} is also radars[{j}]'s"),
        );
    }
    Some(pair)
}

/// Azimuth (and elevation) of a line of sight re-expressed through `m`.
/// A 2D plot's line of sight is horizontal in its radar's frame; only the
/// azimuth of its rotated direction is kept.
/// A bad plot field and why.
type FieldError = (&'static str, String);

/// A plot's elevation (required from a 3D radar, refused from a 2D one;
/// radians) and radial velocity (only from a Doppler radar, required in
/// parallel mode), or the bad field and why.
fn elevation_and_doppler(
    p: &PlotInput,
    spec: &RadarSpec,
    id: &str,
    parallel: bool,
) -> Result<(Option<f64>, Option<f64>), FieldError> {
    let elevation = match (spec.is_3d(), p.elevation_deg) {
        (true, None) => {
            return Err(("elevation_deg", format!("radar '{id}' is 3d: required")));
        }
        (true, Some(el)) => {
            if !(el.is_finite() && el.abs() < 90.0) {
                return Err(("elevation_deg", format!("must lie in (-90, 90), got {el}")));
            }
            Some(el.to_radians())
        }
        (false, Some(_)) => {
            return Err((
                "elevation_deg",
                format!("radar '{id}' is 2d and gives no elevation"),
            ));
        }
        (false, None) => None,
    };
    let radial_velocity = match (spec.has_doppler(), p.radial_velocity_mps) {
        (false, Some(_)) => {
            return Err((
                "radial_velocity_mps",
                format!(
                    "radar '{id}' is declared without Doppler (give its \
                         sigma_radial_velocity_mps)"
                ),
            ));
        }
        (true, Some(v)) => {
            if !(v.is_finite() && v.abs() < 1.0e5) {
                return Err(("radial_velocity_mps", format!("must be finite, got {v}")));
            }
            Some(v)
        }
        (_, None) if parallel => {
            return Err((
                "radial_velocity_mps",
                "required in parallel mode (time registration)".to_string(),
            ));
        }
        (_, None) => None,
    };
    Ok((elevation, radial_velocity))
}

fn rotate(m: &Matrix3<f64>, azimuth: f64, elevation: Option<f64>) -> (f64, Option<f64>) {
    let u = polar_to_enu_3d(1.0, azimuth, elevation.unwrap_or(0.0))
        .expect("unit range and finite angles");
    let uf = m * nalgebra::Vector3::new(u[0], u[1], u[2]);
    let [_, az, el] = enu_to_polar_3d(uf[0], uf[1], uf[2]).expect("a unit vector");
    (az, elevation.map(|_| el))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_of_the_line_of_sight_keeps_angles_when_frames_coincide() {
        let (az, el) = rotate(&Matrix3::identity(), 0.3, Some(0.1));
        assert!((az - 0.3).abs() < 1e-12 && (el.unwrap() - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_radar_east_of_the_origin_sees_north_turned_by_the_meridian_convergence() {
        // Radar 1° of longitude east of the origin, both at latitude 45°:
        // the radar's north, seen in the origin's frame, is turned towards
        // the west by the meridian convergence Δλ·sin φ = 1°·sin 45° = 0.7071°
        // (spherical approximation; WGS84 agrees to ~1e-3°).
        let o = LocalFrame::new(Ellipsoid::WGS84, 45f64.to_radians(), 0.0, 0.0).unwrap();
        let r =
            LocalFrame::new(Ellipsoid::WGS84, 45f64.to_radians(), 1f64.to_radians(), 0.0).unwrap();
        let m = r.rotation_to(&o);
        let (az, _) = rotate(&m, 0.0, None);
        let want = -(1f64.to_radians() * 45f64.to_radians().sin());
        assert!(
            algo::polar::wrap_angle(az - want).abs() < 2e-5,
            "az {} want {}",
            az.to_degrees(),
            want.to_degrees()
        );
    }
}
