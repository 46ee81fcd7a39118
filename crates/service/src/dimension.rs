//! Dimension fusion of seed 003: local tracks of 2D and 3D radars correlated
//! by the modified K-nearest-neighbour test and fused into 3D system tracks,
//! by mapping, dimension lifting and/or dimension splitting
//! (`algo::dimension`).

use std::time::Instant;

use super::{
    FieldViolation, Ids, Increasing, Interval, ServiceError, Violations, at, micros_since,
};
use algo::{
    AlgoError,
    dimension::{
        self, AltitudeSource, Config, Filter, KnnParams, LocalTrack, Method, Period, Plot, Radar,
        Samples,
    },
    gating::chi2_threshold,
    geo::LocalFrame,
};

/// Most radars per request.
pub const MAX_RADARS: usize = 64;
/// Most local tracks per request, over all radars.
pub const MAX_TRACKS: usize = 2_000;
/// Most plots per request, over all tracks.
pub const MAX_PLOTS: usize = 200_000;
/// Most pair samples to test per request: Σ over pairs of tracks of
/// different radars of their plot counts (the K-NN tests are exhaustive).
pub const MAX_PAIR_SAMPLES: usize = 5_000_000;
/// The method names of the API.
pub const METHODS: &[&str] = &["mapping", "lifting", "splitting"];
/// The filter names of the API.
pub const FILTERS: &[&str] = &["alpha_beta", "kalman"];
/// The state layout of every system-track sample.
pub const STATE_LAYOUT: [&str; 6] = ["x", "vx", "y", "vy", "z", "vz"];

pub const DEFAULT_WINDOW: u32 = 4;
pub const DEFAULT_SIGMA_A_MPS2: f64 = 5.0;
pub const DEFAULT_N0: u32 = 5;
pub const DEFAULT_K: u32 = 3;
pub const DEFAULT_PRESET_ALTITUDE_M: f64 = 5_000.0;
pub const DEFAULT_ALTITUDE_SIGMA_M: f64 = 5_000.0;
pub const DEFAULT_GATE_SIGMAS: f64 = 3.0;
pub const DEFAULT_SIGNIFICANCE: f64 = 0.01;

/// A dimension-fusion request as a client sent it, before validation.
#[derive(Debug, Clone, Default)]
pub struct FuseInput {
    /// The fusion centre (ENU origin); absent: the first radar's site.
    pub origin: Option<SiteInput>,
    /// Empty: all three methods.
    pub methods: Vec<String>,
    pub filter: Option<String>,
    pub window: Option<u32>,
    pub sigma_a_mps2: Option<f64>,
    pub n0: Option<u32>,
    pub k: Option<u32>,
    pub preset_altitude_m: Option<f64>,
    pub altitude_sigma_m: Option<f64>,
    pub gate_sigmas: Option<f64>,
    pub significance: Option<f64>,
    /// Every sample of each system track; `false` (the default): only its
    /// latest, so the answer does not repeat the request's history.
    pub history: bool,
    /// Every pair tested; `false` (the default): the pairs without a hit,
    /// a check or a revocation are counted in `omitted_pairs` instead.
    pub all_pairs: bool,
    pub radars: Vec<RadarInput>,
}

#[derive(Debug, Clone, Default)]
pub struct SiteInput {
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    pub height_m: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct RadarInput {
    pub id: Option<String>,
    /// `2d` or `3d`.
    pub kind: Option<String>,
    pub site: Option<SiteInput>,
    pub sigma_range_m: Option<f64>,
    pub sigma_azimuth_deg: Option<f64>,
    pub sigma_elevation_deg: Option<f64>,
    pub scan_period_s: Option<f64>,
    pub tracks: Vec<TrackInput>,
}

#[derive(Debug, Clone, Default)]
pub struct TrackInput {
    pub id: Option<String>,
    pub plots: Vec<PlotInput>,
}

#[derive(Debug, Clone, Default)]
pub struct PlotInput {
    pub t: Option<f64>,
    pub range_m: Option<f64>,
    pub azimuth_deg: Option<f64>,
    pub elevation_deg: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FuseOutput {
    pub results: Vec<MethodOutput>,
    pub compute_us: f64,
    pub warnings: Vec<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MethodOutput {
    pub method: &'static str,
    pub pairs: Vec<PairOutput>,
    /// Pairs not listed (without `all_pairs`): no hit in their current
    /// association period, never checked, never revoked.
    pub omitted_pairs: u64,
    /// Tracks in no system track with another radar's track.
    pub uncorrelated: Vec<TrackRef>,
    pub system_tracks: Vec<SystemTrackOutput>,
    pub compute_us: f64,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrackRef {
    pub radar: String,
    pub track: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PairOutput {
    pub a: TrackRef,
    pub b: TrackRef,
    /// `association`, `check`, `hold` or `rejected`.
    pub period: &'static str,
    pub correlated: bool,
    pub tests: u32,
    pub hits: u32,
    pub misses: u32,
    pub check_counter: i32,
    pub check_tests: u32,
    pub revocations: u32,
    /// Mean d'S⁻¹d; `None` when the tracks never overlapped in time.
    pub mean_statistic: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SystemTrackOutput {
    pub id: String,
    pub members: Vec<TrackRef>,
    /// False: only 2D radars see it, its height is the nominal preset.
    pub altitude_known: bool,
    /// Every fused instant with `history`, else the latest one.
    pub samples: Vec<SystemSample>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SystemSample {
    pub t: f64,
    /// `[x, vx, y, vy, z, vz]` in the centre's ENU frame.
    pub state: Vec<f64>,
    pub covariance: Vec<Vec<f64>>,
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// `None` when the altitude is assumed and the method is not mapping.
    pub height_m: Option<f64>,
    /// `measured`, `lifted` or `assumed` ([`altitude_name`]).
    pub altitude: &'static str,
}

/// The wire name of where a sample's height comes from.
pub fn altitude_name(a: AltitudeSource) -> &'static str {
    match a {
        AltitudeSource::Measured => "measured",
        AltitudeSource::Lifted => "lifted",
        AltitudeSource::Assumed => "assumed",
    }
}

/// The wire name of a period.
pub fn period_name(p: Period) -> &'static str {
    match p {
        Period::Association => "association",
        Period::Check => "check",
        Period::Hold => "hold",
        Period::Rejected => "rejected",
    }
}

fn method_name(m: Method) -> &'static str {
    match m {
        Method::Mapping => "mapping",
        Method::Lifting => "lifting",
        Method::Splitting => "splitting",
    }
}

struct Plan {
    centre: LocalFrame,
    methods: Vec<Method>,
    config: Config,
    radars: Vec<Radar>,
    tracks: Vec<LocalTrack>,
    refs: Vec<TrackRef>,
    warnings: Vec<String>,
}

/// Validates, then runs every requested method.
pub fn fuse(input: FuseInput) -> Result<FuseOutput, ServiceError> {
    let plan = validate(&input)?;
    let (history, all_pairs) = (input.history, input.all_pairs);
    drop(input);
    // Between the steps (the filters and methods run as one call of
    // `algo`), so that an abandoned request stops.
    crate::lanes::checkpoint()?;
    let start = Instant::now();
    let mut results = Vec::new();
    // The local filters run once for all methods: their time is in the
    // first method's compute_us. Without history only the samples answered
    // are fused (the latest of each system track).
    let outs = dimension::fuse_methods_with(
        &plan.centre,
        &plan.radars,
        &plan.tracks,
        &plan.methods,
        &plan.config,
        if history {
            Samples::All
        } else {
            Samples::Latest
        },
    )
    .map_err(computation_error)?;
    for (&method, out) in plan.methods.iter().zip(outs) {
        crate::lanes::checkpoint()?;
        results.push(method_output(&plan, method, &out, history, all_pairs)?);
    }
    let compute_us = micros_since(start);
    let mut warnings = plan.warnings;
    let results = results
        .into_iter()
        .map(|(r, w)| {
            warnings.extend(w);
            r
        })
        .collect();
    Ok(FuseOutput {
        results,
        compute_us,
        warnings,
    })
}

/// One method's answer, under the request's ids, with its own warnings.
fn method_output(
    plan: &Plan,
    method: Method,
    out: &dimension::Outcome,
    history: bool,
    all_pairs: bool,
) -> Result<(MethodOutput, Vec<String>), ServiceError> {
    let t0 = Instant::now();
    let r = |i: usize| plan.refs[i].clone();
    // A pair that never hit, was never checked nor revoked says only
    // that two tracks are apart: counted, listed on request.
    let listed = |p: &&dimension::PairReport| {
        all_pairs
            || p.state.hits > 0
            || p.state.check_tests > 0
            || p.state.revocations > 0
            || p.state.correlated()
    };
    let pairs: Vec<PairOutput> = out
        .pairs
        .iter()
        .filter(listed)
        .map(|p| PairOutput {
            a: r(p.a),
            b: r(p.b),
            period: period_name(p.state.period),
            correlated: p.state.correlated(),
            tests: p.state.tests,
            hits: p.state.hits,
            misses: p.state.misses,
            check_counter: p.state.counter,
            check_tests: p.state.check_tests,
            revocations: p.state.revocations,
            mean_statistic: p.mean_statistic.is_finite().then_some(p.mean_statistic),
        })
        .collect();
    let mut uncorrelated = Vec::new();
    let mut system_tracks = Vec::new();
    for (n, st) in out.system_tracks.iter().enumerate() {
        if st.members.len() == 1 {
            uncorrelated.push(r(st.members[0]));
        }
        // Without history only the latest sample is answered (and
        // converted): the answer stays small against the request.
        let shown = if history {
            &st.samples[..]
        } else {
            &st.samples[st.samples.len().saturating_sub(1)..]
        };
        let samples = system_samples(plan, method, shown)?;
        system_tracks.push(SystemTrackOutput {
            id: format!("S{}", n + 1),
            members: st.members.iter().map(|&i| r(i)).collect(),
            altitude_known: st.altitude_known,
            samples,
        });
    }
    let mut warnings_here = Vec::new();
    if out.conflicts > 0 {
        warnings_here.push(format!(
            "{}: {} correlated link(s) dropped because they would put two tracks of one radar \
             in one system track",
            method_name(method),
            out.conflicts
        ));
    }
    Ok((
        MethodOutput {
            method: method_name(method),
            omitted_pairs: (out.pairs.len() - pairs.len()) as u64,
            pairs,
            uncorrelated,
            system_tracks,
            compute_us: out.compute_us + micros_since(t0),
        },
        warnings_here,
    ))
}

/// A system track's samples as answered: state, covariance and the
/// geodetic position (its height where it is known, or mapped).
fn system_samples(
    plan: &Plan,
    method: Method,
    shown: &[dimension::Sample],
) -> Result<Vec<SystemSample>, ServiceError> {
    let mut samples = Vec::with_capacity(shown.len());
    for s in shown {
        let (lat, lon, h) = plan
            .centre
            .enu_to_geodetic([s.x[0], s.x[2], s.x[4]])
            .map_err(computation_error)?;
        samples.push(SystemSample {
            t: s.t,
            state: s.x.iter().copied().collect(),
            covariance: (0..6)
                .map(|i| s.p.row(i).iter().copied().collect())
                .collect(),
            lat_deg: lat.to_degrees(),
            lon_deg: lon.to_degrees(),
            height_m: (method == Method::Mapping || s.altitude != AltitudeSource::Assumed)
                .then_some(h),
            altitude: altitude_name(s.altitude),
        });
    }
    Ok(samples)
}

/// A failure of the numerical core after validation: the geometry of the data
/// (a 2D slant range that cannot reach the assumed height, a covariance that
/// lost definiteness), reported against the request.
fn computation_error(e: AlgoError) -> ServiceError {
    let message = match &e {
        AlgoError::DegenerateGeometry { .. } => format!(
            "a 2D plot's slant range cannot reach the assumed height, or a position is degenerate: {e}"
        ),
        other => format!("the fusion failed numerically: {other}"),
    };
    ServiceError::InvalidInput(vec![FieldViolation {
        field: "radars".into(),
        message,
    }])
}

fn site(v: &mut Violations, f: &str, s: &SiteInput) -> Option<LocalFrame> {
    v.site(f, s.lat_deg, s.lon_deg, s.height_m)
}

/// The filter names of the API, before the window or σ_a is attached.
#[derive(Debug, Clone, Copy)]
enum FilterName {
    AlphaBeta,
    Kalman,
}

fn validate(input: &FuseInput) -> Result<Plan, ServiceError> {
    let mut v = Violations::new();
    let mut warnings = Vec::new();
    let methods = parse_methods(&mut v, &input.methods);
    let config = parse_config(&mut v, input);
    check_sizes(&mut v, &input.radars, &mut warnings);
    let mut radars = Vec::new();
    let mut tracks = Vec::new();
    let mut refs = Vec::new();
    let mut radar_ids = Ids::new();
    for (ri, r) in input.radars.iter().enumerate().take(MAX_RADARS) {
        // Radar by radar, so that an abandoned request stops.
        crate::lanes::checkpoint()?;
        let id = radar_ids
            .check(&mut v, r.id.as_deref(), ri, |i| format!("radars[{i}].id"))
            .unwrap_or_default();
        let (three_d, radar) = parse_radar(&mut v, ri, r);
        let mut track_ids = Ids::new();
        for (ti, t) in r.tracks.iter().enumerate() {
            let tid = track_ids
                .check(&mut v, t.id.as_deref(), ti, |i| {
                    format!("radars[{ri}].tracks[{i}].id")
                })
                .unwrap_or_default();
            if t.plots.is_empty() {
                v.add(
                    format!("radars[{ri}].tracks[{ti}].plots"),
                    "must hold at least one plot",
                );
            } else if t.plots.len() < 3 {
                warnings.push(format!(
                    "radar '{id}' track '{tid}': fewer than 3 plots, too short to be tested"
                ));
            }
            let plots = parse_plots(&mut v, &format!("radars[{ri}].tracks[{ti}]"), three_d, t);
            tracks.push(LocalTrack { radar: ri, plots });
            refs.push(TrackRef {
                radar: id.to_string(),
                track: tid.to_string(),
            });
        }
        radars.extend(radar);
    }
    let centre = match &input.origin {
        Some(o) => site(&mut v, "origin", o),
        None => radars.first().map(|r| r.frame),
    };
    let parsed = (|| {
        Some(Plan {
            centre: centre?,
            methods,
            config: config?,
            radars,
            tracks,
            refs,
            warnings,
        })
    })();
    v.finish_with(parsed)
}

/// `methods`: each named once; none named means all three.
fn parse_methods(v: &mut Violations, input: &[String]) -> Vec<Method> {
    let choices = [
        ("mapping", Method::Mapping),
        ("lifting", Method::Lifting),
        ("splitting", Method::Splitting),
    ];
    let mut methods: Vec<(usize, Method)> = Vec::new();
    for (i, m) in input.iter().enumerate() {
        let Some(method) = v.one_of(format!("methods[{i}]"), Some(m), None, &choices) else {
            continue;
        };
        match methods.iter().find(|(_, x)| *x == method) {
            Some((j, _)) => v.add(
                format!("methods[{i}]"),
                format!("duplicates methods[{j}] '{m}'"),
            ),
            None => methods.push((i, method)),
        }
    }
    if input.is_empty() {
        return vec![Method::Mapping, Method::Lifting, Method::Splitting];
    }
    methods.into_iter().map(|(_, m)| m).collect()
}

/// The fusion's options: the local filter, the K-NN test, the altitude
/// and the gates.
fn parse_config(v: &mut Violations, input: &FuseInput) -> Option<Config> {
    let filter = parse_filter(v, input);
    let n0 = v.count_or("n0", input.n0, DEFAULT_N0, 2, 1000);
    let k = n0.and_then(|n0| v.count_or("k", input.k, DEFAULT_K, n0.div_ceil(2), n0));
    let preset = v.number_or(
        "preset_altitude_m",
        input.preset_altitude_m,
        DEFAULT_PRESET_ALTITUDE_M,
        Interval::closed(-1000.0, 100_000.0),
    );
    let altitude_sigma = v.number_or(
        "altitude_sigma_m",
        input.altitude_sigma_m,
        DEFAULT_ALTITUDE_SIGMA_M,
        Interval::POSITIVE,
    );
    let gate_sigmas = v.number_or(
        "gate_sigmas",
        input.gate_sigmas,
        DEFAULT_GATE_SIGMAS,
        Interval::POSITIVE,
    );
    let chi2 = v
        .number_or(
            "significance",
            input.significance,
            DEFAULT_SIGNIFICANCE,
            Interval::OPEN_UNIT,
        )
        .and_then(|significance| {
            v.param(
                "",
                chi2_threshold(2, significance)
                    .and_then(|a| Ok((a, chi2_threshold(3, significance)?))),
            )
        });
    let (chi2_2, chi2_3) = chi2?;
    Some(Config {
        filter: filter?,
        knn: KnnParams { n0: n0?, k: k? },
        preset_altitude: preset?,
        altitude_sigma: altitude_sigma?,
        gate_sigmas: gate_sigmas?,
        chi2_2,
        chi2_3,
    })
}

/// `filter` with its `window` (α-β) or `sigma_a_mps2` (Kalman); both are
/// checked whichever filter is named.
fn parse_filter(v: &mut Violations, input: &FuseInput) -> Option<Filter> {
    let window = v.count_or("window", input.window, DEFAULT_WINDOW, 3, 5);
    let sigma_a = v.number_or(
        "sigma_a_mps2",
        input.sigma_a_mps2,
        DEFAULT_SIGMA_A_MPS2,
        Interval::POSITIVE,
    );
    let filters = [
        ("alpha_beta", FilterName::AlphaBeta),
        ("kalman", FilterName::Kalman),
    ];
    match v.one_of(
        "filter",
        input.filter.as_deref(),
        Some(FilterName::AlphaBeta),
        &filters,
    ) {
        Some(FilterName::AlphaBeta) => window.map(|w| Filter::AlphaBeta { window: w as usize }),
        Some(FilterName::Kalman) => sigma_a.map(|sigma_a| Filter::Kalman { sigma_a }),
        None => None,
    }
}

/// The request's size: radars, tracks, plots and the plots the pairs of
/// tracks of different radars test.
fn check_sizes(v: &mut Violations, radars: &[RadarInput], warnings: &mut Vec<String>) {
    v.count_within("radars", radars.len(), MAX_RADARS, "radar");
    let n_tracks: usize = radars.iter().map(|r| r.tracks.len()).sum();
    if n_tracks == 0 && !radars.is_empty() {
        warnings.push(format!(
            "none of the {} radar(s) holds a track: there is nothing to fuse",
            radars.len()
        ));
    }
    v.at_most("radars", n_tracks, MAX_TRACKS, "tracks");
    let n_plots: usize = radars
        .iter()
        .flat_map(|r| &r.tracks)
        .map(|t| t.plots.len())
        .sum();
    v.at_most("radars", n_plots, MAX_PLOTS, "plots");
    if n_tracks <= MAX_TRACKS {
        let lens: Vec<(usize, usize)> = radars
            .iter()
            .enumerate()
            .flat_map(|(ri, r)| r.tracks.iter().map(move |t| (ri, t.plots.len())))
            .collect();
        let mut total = 0usize;
        for (i, a) in lens.iter().enumerate() {
            for b in &lens[i + 1..] {
                if a.0 != b.0 {
                    total = total.saturating_add(a.1 + b.1);
                }
            }
        }
        v.at_most(
            "radars",
            total,
            MAX_PAIR_SAMPLES,
            "plots to test in the pairs of tracks of different radars",
        );
    }
}

/// `radars[ri]` but its id and tracks: kind, site and accuracies. The
/// kind (whether 3D) comes back on its own too: the plots need it when
/// something else of the radar is invalid.
fn parse_radar(v: &mut Violations, ri: usize, r: &RadarInput) -> (Option<bool>, Option<Radar>) {
    let f = format!("radars[{ri}]");
    let three_d = v.one_of(
        format!("{f}.kind"),
        r.kind.as_deref(),
        None,
        &[("2d", false), ("3d", true)],
    );
    let frame = match &r.site {
        None => {
            v.add(format!("{f}.site"), "is required");
            None
        }
        Some(s) => site(v, &format!("{f}.site"), s),
    };
    let sr = v.positive(format!("{f}.sigma_range_m"), r.sigma_range_m);
    let sa = v.positive(format!("{f}.sigma_azimuth_deg"), r.sigma_azimuth_deg);
    let se = match (three_d, r.sigma_elevation_deg) {
        (Some(true), s) => v.positive(format!("{f}.sigma_elevation_deg"), s),
        (Some(false), Some(_)) => {
            v.add(
                format!("{f}.sigma_elevation_deg"),
                "a 2D radar measures no elevation",
            );
            None
        }
        _ => Some(0.0),
    };
    let scan = v.positive(format!("{f}.scan_period_s"), r.scan_period_s);
    let radar = (|| {
        Some(Radar {
            frame: frame?,
            three_d: three_d?,
            sigma_range: sr?,
            sigma_azimuth: sa?.to_radians(),
            sigma_elevation: se?.to_radians(),
            scan_period: scan?,
        })
    })();
    (three_d, radar)
}

/// `{ft}.plots` of one track (`ft` its field path): the valid plots.
fn parse_plots(v: &mut Violations, ft: &str, three_d: Option<bool>, t: &TrackInput) -> Vec<Plot> {
    let mut plots = Vec::with_capacity(t.plots.len());
    let mut times = Increasing::new();
    for (pi, p) in t.plots.iter().enumerate() {
        let fp = || format!("{ft}.plots[{pi}]");
        let time = times.next(v, at(|| format!("{}.t", fp())), p.t, Interval::FINITE);
        let range = v.number(
            at(|| format!("{}.range_m", fp())),
            p.range_m,
            Interval::open_closed(0.0, 1e7),
        );
        let az = v.number(
            at(|| format!("{}.azimuth_deg", fp())),
            p.azimuth_deg,
            Interval::closed(-360.0, 360.0),
        );
        let el = match (three_d, p.elevation_deg) {
            (Some(false), Some(_)) => {
                v.add(
                    format!("{}.elevation_deg", fp()),
                    "a 2D radar measures no elevation",
                );
                None
            }
            (Some(true), e) => v
                .number(
                    at(|| format!("{}.elevation_deg", fp())),
                    e,
                    Interval::closed(-90.0, 90.0),
                )
                .map(Some),
            _ => Some(None),
        };
        if let (Some(time), Some(range), Some(az), Some(el)) = (time, range, az, el) {
            plots.push(Plot {
                t: time,
                range,
                azimuth: az.to_radians(),
                elevation: el.map(f64::to_radians),
            });
        }
    }
    plots
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_abandoned_request_stops_at_its_first_radar() {
        // A radar without its fields: violations when someone waits for the
        // answer, and stopped at the first radar when nobody does.
        let input = || FuseInput {
            radars: vec![RadarInput::default()],
            ..FuseInput::default()
        };
        assert!(matches!(fuse(input()), Err(ServiceError::InvalidInput(_))));
        let stopped = crate::lanes::as_abandoned(|| fuse(input()));
        assert!(
            matches!(stopped, Err(ServiceError::Cancelled)),
            "{stopped:?}"
        );
    }
}
