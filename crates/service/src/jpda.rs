//! JPDA update of seed 002: a set of tracks updated with one scan of
//! measurements from one or more sensors, by exact JPDA, AMSJPDA, nearest
//! neighbour or global nearest neighbour (`algo::jpda`).

use std::time::Instant;

use nalgebra::{DMatrix, DVector};

use super::{Ids, Rows, ServiceError, Violations, at, covariance_message, micros_since};
use algo::{
    AlgoError,
    jpda::{self, Clutter, Config, Fallback, Gate, Method, Scan, SensorModel, TrackEstimate},
    kalman::PositionLayout,
    motion::{ConstantVelocity, MotionModel, ProcessNoise},
    small,
};

/// Most tracks per request.
pub const MAX_TRACKS: usize = 10_000;
/// Most sensors per request.
pub const MAX_SENSORS: usize = 32;
/// Most measurements per request, over all sensors.
pub const MAX_MEASUREMENTS: usize = 200_000;
/// Most track–measurement pairs to gate per request (Σ over sensors of
/// tracks × measurements): gating is exhaustive, so this bounds its cost.
pub const MAX_PAIRS: usize = 50_000_000;
/// Largest state and linear measurement dimension.
pub const MAX_DIM: usize = 9;
/// Default largest cluster computed exactly.
pub const DEFAULT_MAX_EXACT_CLUSTER_TRACKS: u32 = 24;
/// Upper bound of `max_exact_cluster_tracks`.
pub const MAX_EXACT_CLUSTER_TRACKS: u32 = 128;
/// Merged hypothesis-tree edges allowed per exact cluster before the fallback.
pub const MAX_HYPOTHESES: u64 = 2_000_000;
/// Default gate probability P_G.
pub const DEFAULT_GATE_PROBABILITY: f64 = 0.99;

/// The method names of the API.
pub const METHODS: &[&str] = &[
    "exact",
    "amsjpda",
    "nearest_neighbour",
    "global_nearest_neighbour",
];

/// A JPDA request as a client sent it, before validation.
#[derive(Debug, Clone, Default)]
pub struct JpdaInput {
    /// Names of the state components; empty: `[x, vx, y, vy]` for 4 and
    /// `[x, vx, y, vy, z, vz]` for 6 components.
    pub state_layout: Vec<String>,
    pub method: Option<String>,
    pub max_exact_cluster_tracks: Option<u32>,
    /// Predict every track over `dt_s` first (constant velocity, DWNA noise).
    pub prediction: Option<PredictionInput>,
    pub tracks: Vec<TrackInput>,
    pub sensors: Vec<SensorInput>,
}

#[derive(Debug, Clone, Default)]
pub struct PredictionInput {
    pub dt_s: Option<f64>,
    pub sigma_a_mps2: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct TrackInput {
    pub id: Option<String>,
    pub state: Vec<f64>,
    pub covariance: Rows,
}

#[derive(Debug, Clone, Default)]
pub struct SensorInput {
    pub id: Option<String>,
    /// `linear` or `polar`.
    pub kind: Option<String>,
    pub h: Option<Rows>,
    pub r: Option<Rows>,
    pub site_m: Option<Vec<f64>>,
    pub sigma_range_m: Option<f64>,
    pub sigma_azimuth_deg: Option<f64>,
    pub sigma_elevation_deg: Option<f64>,
    pub detection_probability: Option<f64>,
    pub gate_probability: Option<f64>,
    pub gate_threshold: Option<f64>,
    /// λ; absent: non-parametric clutter from the gate volumes.
    pub clutter_density: Option<f64>,
    pub measurements: Vec<MeasurementInput>,
}

#[derive(Debug, Clone, Default)]
pub struct MeasurementInput {
    /// Linear sensors.
    pub z: Option<Vec<f64>>,
    /// Polar sensors.
    pub range_m: Option<f64>,
    pub azimuth_deg: Option<f64>,
    pub elevation_deg: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct JpdaOutput {
    pub method: &'static str,
    pub tracks: Vec<TrackOutput>,
    pub sensors: Vec<SensorOutput>,
    pub compute_us: f64,
    pub warnings: Vec<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TrackOutput {
    pub id: String,
    pub state: Vec<f64>,
    pub covariance: Rows,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SensorOutput {
    pub id: String,
    pub clusters: Vec<ClusterOutput>,
    pub associations: Vec<AssociationOutput>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ClusterOutput {
    pub tracks: Vec<String>,
    pub measurements: Vec<u32>,
    pub method: &'static str,
    /// Why an exact cluster was computed by AMSJPDA instead.
    pub fallback: Option<&'static str>,
    pub hypotheses: u64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct AssociationOutput {
    pub track: String,
    pub miss_probability: f64,
    /// (measurement index, β).
    pub measurements: Vec<(u32, f64)>,
}

/// Validates, predicts if asked, and runs the sequential JPDA update.
pub fn update(input: JpdaInput) -> Result<JpdaOutput, ServiceError> {
    let plan = validate(input)?;
    let start = Instant::now();
    let mut tracks = plan.tracks;
    if let Some((model, dt)) = plan.prediction {
        for (i, t) in tracks.iter_mut().enumerate() {
            let (x, p) = model
                .predict(&t.x, &t.p, dt)
                .map_err(|e| Violations::from_param(&format!("tracks[{i}].covariance."), e))?;
            t.x = x;
            t.p = p;
        }
    }
    // Sequential multi-sensor JPDA (`jpda::update`) scan by scan, so that
    // an abandoned request stops between scans.
    let mut reports = Vec::with_capacity(plan.scans.len());
    for scan in &plan.scans {
        crate::lanes::checkpoint()?;
        reports.push(jpda::scan(&mut tracks, scan, &plan.config).map_err(computation_error)?);
    }
    let compute_us = micros_since(start);
    let mut warnings = Vec::new();
    if plan.sensor_ids.is_empty() {
        warnings.push(
            "no sensors: no measurement updated the tracks (they are returned as given, or \
             predicted when `prediction` is set)"
                .to_string(),
        );
    }
    let sensors = reports
        .into_iter()
        .zip(&plan.sensor_ids)
        .map(|(report, sensor)| {
            let clusters = report
                .clusters
                .into_iter()
                .map(|c| {
                    if let Some(f) = c.fallback {
                        warnings.push(format!(
                            "sensor '{sensor}': a cluster of {} tracks was computed by AMSJPDA \
                             instead of exact JPDA ({})",
                            c.tracks.len(),
                            fallback_text(f)
                        ));
                    }
                    ClusterOutput {
                        tracks: c
                            .tracks
                            .iter()
                            .map(|&t| plan.track_ids[t].clone())
                            .collect(),
                        measurements: c.measurements.iter().map(|&j| j as u32).collect(),
                        method: method_name(c.method),
                        fallback: c.fallback.map(fallback_name),
                        hypotheses: c.hypotheses,
                    }
                })
                .collect();
            let associations = report
                .associations
                .into_iter()
                .enumerate()
                .map(|(t, a)| AssociationOutput {
                    track: plan.track_ids[t].clone(),
                    miss_probability: a.miss,
                    measurements: a
                        .measurements
                        .into_iter()
                        .map(|(j, b)| (j as u32, b))
                        .collect(),
                })
                .collect();
            SensorOutput {
                id: sensor.clone(),
                clusters,
                associations,
            }
        })
        .collect();
    Ok(JpdaOutput {
        method: method_name(plan.config.method),
        tracks: tracks
            .into_iter()
            .zip(plan.track_ids)
            .map(|(t, id)| TrackOutput {
                id,
                state: t.x.iter().copied().collect(),
                covariance: Rows::from_matrix(&t.p),
            })
            .collect(),
        sensors,
        compute_us,
        warnings,
    })
}

/// The wire name of a method.
pub fn method_name(m: Method) -> &'static str {
    match m {
        Method::Exact => "exact",
        Method::Amsjpda => "amsjpda",
        Method::NearestNeighbour => "nearest_neighbour",
        Method::GlobalNearestNeighbour => "global_nearest_neighbour",
    }
}

fn fallback_name(f: Fallback) -> &'static str {
    match f {
        Fallback::TooManyTracks => "too_many_tracks",
        Fallback::TooManyHypotheses => "too_many_hypotheses",
        Fallback::FrontierTooWide => "frontier_too_wide",
    }
}

fn fallback_text(f: Fallback) -> &'static str {
    match f {
        Fallback::TooManyTracks => "more tracks than max_exact_cluster_tracks",
        Fallback::TooManyHypotheses => "the merged hypothesis tree exceeded its budget",
        Fallback::FrontierTooWide => "more than 128 measurements were live at once",
    }
}

/// An error of the numerical core after validation: the inputs were checked,
/// so what remains is a geometry or conditioning problem of the data (a
/// target at a radar site, an updated covariance that lost definiteness),
/// reported against the request rather than as a bug.
fn computation_error(e: AlgoError) -> ServiceError {
    let message = match &e {
        AlgoError::DegenerateGeometry { .. } => {
            "a predicted target lies at or straight above a polar sensor's site".to_string()
        }
        other => format!("the update failed numerically: {other}"),
    };
    ServiceError::InvalidInput(vec![super::FieldViolation {
        field: "sensors".into(),
        message,
    }])
}

struct Plan {
    tracks: Vec<TrackEstimate>,
    track_ids: Vec<String>,
    sensor_ids: Vec<String>,
    scans: Vec<Scan>,
    config: Config,
    prediction: Option<(ConstantVelocity, f64)>,
}

/// Canonical layouts: interleaved `[x, vx, y, vy(, z, vz)]`.
const CV_2D: [&str; 4] = ["x", "vx", "y", "vy"];
const CV_3D: [&str; 6] = ["x", "vx", "y", "vy", "z", "vz"];
const NAMES: [&str; 6] = ["x", "vx", "y", "vy", "z", "vz"];

fn validate(mut input: JpdaInput) -> Result<Plan, ServiceError> {
    let mut v = Violations::new();
    let method = v.one_of(
        "method",
        input.method.as_deref(),
        Some(Method::Exact),
        &[
            ("exact", Method::Exact),
            ("amsjpda", Method::Amsjpda),
            ("nearest_neighbour", Method::NearestNeighbour),
            ("global_nearest_neighbour", Method::GlobalNearestNeighbour),
        ],
    );
    let max_exact = v.count_or(
        "max_exact_cluster_tracks",
        input.max_exact_cluster_tracks,
        DEFAULT_MAX_EXACT_CLUSTER_TRACKS,
        1,
        MAX_EXACT_CLUSTER_TRACKS,
    );
    v.count_within("tracks", input.tracks.len(), MAX_TRACKS, "track");
    let n = input.tracks.first().map_or(0, |t| t.state.len());
    let n_tracks = input.tracks.len();
    let (tracks, track_ids) = parse_tracks(&mut v, std::mem::take(&mut input.tracks), n);
    let (layout_names, position) = parse_layout(&mut v, &input.state_layout, n);
    let prediction = input
        .prediction
        .as_ref()
        .and_then(|p| parse_prediction(&mut v, p, &layout_names));
    let (sensor_ids, scans) = parse_sensors(&mut v, &mut input.sensors, n_tracks, n, position);
    let parsed = method.zip(max_exact).map(|(method, max_exact)| Plan {
        tracks,
        track_ids,
        sensor_ids,
        scans,
        config: Config {
            method,
            max_exact_tracks: max_exact as usize,
            max_hypotheses: MAX_HYPOTHESES,
        },
        prediction,
    });
    v.finish_with(parsed)
}

/// `tracks`: their ids (checked first, as they borrow the request) and
/// each state with its covariance, `n` components like the first one's.
fn parse_tracks(
    v: &mut Violations,
    input: Vec<TrackInput>,
    n: usize,
) -> (Vec<TrackEstimate>, Vec<String>) {
    {
        let mut ids = Ids::with_capacity(input.len().min(MAX_TRACKS));
        for (i, t) in input.iter().enumerate().take(MAX_TRACKS) {
            ids.check(v, t.id.as_deref(), i, |j| format!("tracks[{j}].id"));
        }
    }
    let mut tracks = Vec::with_capacity(input.len().min(MAX_TRACKS));
    let mut track_ids = Vec::with_capacity(tracks.capacity());
    for (i, mut t) in input.into_iter().enumerate().take(MAX_TRACKS) {
        // A missing or repeated id is a violation above: the request then
        // fails whatever is kept here.
        track_ids.push(t.id.take().unwrap_or_default());
        if let Some(track) = parse_track(v, i, t, n) {
            tracks.push(track);
        }
    }
    (tracks, track_ids)
}

/// `tracks[i]`: its state and covariance.
fn parse_track(v: &mut Violations, i: usize, t: TrackInput, n: usize) -> Option<TrackEstimate> {
    // Paths are formatted only for a violation: this runs per track.
    let f = |rest: &str| format!("tracks[{i}].{rest}");
    if t.state.is_empty() || t.state.len() > MAX_DIM {
        v.add(f("state"), format!("must have 1 to {MAX_DIM} components"));
        return None;
    }
    if t.state.len() != n {
        v.add(
            f("state"),
            format!("has {} components, tracks[0].state has {n}", t.state.len()),
        );
        return None;
    }
    if t.state.iter().any(|x| !x.is_finite()) {
        v.add(f("state"), "contains a non-finite value");
        return None;
    }
    let p = matrix(v, || f("covariance"), &t.covariance, n, n)?;
    if let Err(e) = small::check_covariance("covariance", p.as_slice(), n) {
        v.add(f("covariance"), covariance_message(&e));
        return None;
    }
    Some(TrackEstimate {
        x: DVector::from_vec(t.state),
        p,
    })
}

/// `state_layout`: the names of the state's components (the canonical
/// constant-velocity ones for 4 or 6 when absent) and where the position
/// lies in it.
fn parse_layout(
    v: &mut Violations,
    state_layout: &[String],
    n: usize,
) -> (Vec<String>, Option<PositionLayout>) {
    let layout_names: Vec<String> = if state_layout.is_empty() {
        match n {
            4 => CV_2D.iter().map(|s| s.to_string()).collect(),
            6 => CV_3D.iter().map(|s| s.to_string()).collect(),
            _ => Vec::new(),
        }
    } else {
        state_layout.to_vec()
    };
    if !state_layout.is_empty() {
        let mut names = std::collections::HashSet::new();
        for (i, name) in state_layout.iter().enumerate() {
            if !NAMES.contains(&name.as_str()) {
                v.add(
                    format!("state_layout[{i}]"),
                    format!(
                        "must be one of {}, got '{}'",
                        NAMES.join(", "),
                        crate::validate::quoted(name)
                    ),
                );
            } else if !names.insert(name.as_str()) {
                v.add(
                    format!("state_layout[{i}]"),
                    format!("names '{name}' twice"),
                );
            }
        }
        if n > 0 && state_layout.len() != n {
            v.add(
                "state_layout",
                format!(
                    "names {} components, the states have {n}",
                    state_layout.len()
                ),
            );
        }
    }
    let index_of = |name: &str| layout_names.iter().position(|s| s == name);
    let position = match (index_of("x"), index_of("y")) {
        (Some(x), Some(y)) => Some(PositionLayout {
            x,
            y,
            z: index_of("z"),
        }),
        _ => None,
    };
    (layout_names, position)
}

/// `prediction`: a constant-velocity step of `dt_s` with white
/// acceleration noise, on a canonical layout.
fn parse_prediction(
    v: &mut Violations,
    p: &PredictionInput,
    layout_names: &[String],
) -> Option<(ConstantVelocity, f64)> {
    let dt = v.required("prediction.dt_s", p.dt_s);
    let sigma_a = v.required("prediction.sigma_a_mps2", p.sigma_a_mps2);
    if dt.is_some_and(|dt| !(dt.is_finite() && dt >= 0.0)) {
        // A negative step would predict backwards (retrodiction needs a
        // smoother, not F(−dt) with process noise added).
        v.add(
            "prediction.dt_s",
            "must be a finite number of seconds ≥ 0 (a prediction goes forward)",
        );
    }
    let axes = if layout_names == CV_2D {
        Some(2)
    } else if layout_names == CV_3D {
        Some(3)
    } else {
        v.add(
            "prediction",
            "a constant-velocity prediction needs state_layout [x, vx, y, vy] or \
             [x, vx, y, vy, z, vz]",
        );
        None
    };
    let sigma_a = sigma_a?;
    if !(sigma_a >= 0.0 && sigma_a.is_finite()) {
        v.add(
            "prediction.sigma_a_mps2",
            format!("must be finite and ≥ 0, got {sigma_a}"),
        );
        return None;
    }
    let model = v.param(
        "prediction.",
        ConstantVelocity::new(axes?, ProcessNoise::Dwna { sigma_a }),
    );
    Some((model?, dt.filter(|d| d.is_finite())?))
}

/// `sensors`: their ids (the index when absent) and their scans.
fn parse_sensors(
    v: &mut Violations,
    sensors: &mut [SensorInput],
    n_tracks: usize,
    n: usize,
    position: Option<PositionLayout>,
) -> (Vec<String>, Vec<Scan>) {
    v.at_most("sensors", sensors.len(), MAX_SENSORS, "sensors");
    let total: usize = sensors.iter().map(|s| s.measurements.len()).sum();
    v.at_most("sensors", total, MAX_MEASUREMENTS, "measurements");
    if total.saturating_mul(n_tracks) > MAX_PAIRS {
        v.add(
            "sensors",
            format!(
                "{n_tracks} tracks × {total} measurements exceed {MAX_PAIRS} pairs to gate per request"
            ),
        );
    }
    let mut scans = Vec::new();
    let mut sensor_ids = Vec::new();
    for (si, s) in sensors.iter_mut().enumerate().take(MAX_SENSORS) {
        let f = format!("sensors[{si}]");
        sensor_ids.push(s.id.take().unwrap_or_else(|| si.to_string()));
        if let Some(scan) = sensor(v, &f, s, n, position) {
            scans.push(scan);
        }
    }
    (sensor_ids, scans)
}

/// `sensors[si]` (`f`): its model, detection probability, clutter, gate
/// and measurements.
fn sensor(
    v: &mut Violations,
    f: &str,
    s: &mut SensorInput,
    n: usize,
    position: Option<PositionLayout>,
) -> Option<Scan> {
    let p_d = v.required(
        format!("{f}.detection_probability"),
        s.detection_probability,
    );
    if let Some(p) = p_d
        && !(p > 0.0 && p <= 1.0)
    {
        v.add(
            format!("{f}.detection_probability"),
            format!("must lie in (0, 1], got {p}"),
        );
    }
    if let Some(l) = s.clutter_density
        && !(l > 0.0 && l.is_finite())
    {
        v.add(
            format!("{f}.clutter_density"),
            format!(
                "must be finite and > 0, got {l} (omit it for non-parametric clutter from the \
                 gate volumes)"
            ),
        );
    }
    let model = match s.kind.as_deref() {
        Some("linear") => linear_model(v, f, s, n),
        Some("polar") => polar_model(v, f, s, position),
        Some(other) => {
            v.add(
                format!("{f}.kind"),
                format!(
                    "must be one of linear, polar, got '{}'",
                    crate::validate::quoted(other)
                ),
            );
            None
        }
        None => {
            v.add(format!("{f}.kind"), "is required: one of linear, polar");
            None
        }
    };
    let dim = model.as_ref().map(SensorModel::dim);
    let gate = gate(v, f, s, dim, p_d);
    let mut measurements = Vec::with_capacity(s.measurements.len());
    for (j, z) in s.measurements.iter_mut().enumerate() {
        // Formatted only for a violation: this loop runs per measurement.
        let mf = |rest: &str| format!("{f}.measurements[{j}].{rest}");
        let value = match (&model, dim) {
            (Some(SensorModel::Linear { .. }), Some(dim)) => linear_measurement(v, mf, z, dim),
            (Some(SensorModel::Polar { .. }), Some(dim)) => polar_measurement(v, mf, z, dim),
            _ => None,
        };
        measurements.extend(value);
    }
    Some(Scan {
        model: model?,
        measurements,
        detection_probability: p_d.filter(|p| *p > 0.0 && *p <= 1.0)?,
        gate: gate?,
        clutter: match s.clutter_density {
            Some(l) => Clutter::Density(l),
            None => Clutter::GateVolume,
        },
    })
}

/// A linear sensor: `h` (m × n) and `r` (m × m); none of the polar fields.
fn linear_model(v: &mut Violations, f: &str, s: &SensorInput, n: usize) -> Option<SensorModel> {
    let h_rows = v.required(format!("{f}.h"), s.h.as_ref());
    let m = h_rows.map_or(0, Rows::nrows);
    if h_rows.is_some() && !(1..=MAX_DIM).contains(&m) {
        v.add(format!("{f}.h"), format!("must have 1 to {MAX_DIM} rows"));
    }
    let h = h_rows
        .filter(|_| (1..=MAX_DIM).contains(&m) && n > 0)
        .and_then(|rows| matrix(v, || format!("{f}.h"), rows, m, n));
    let r = v
        .required(format!("{f}.r"), s.r.as_ref())
        .filter(|_| (1..=MAX_DIM).contains(&m))
        .and_then(|rows| matrix(v, || format!("{f}.r"), rows, m, m));
    if let Some(r) = &r
        && let Err(e) = small::check_covariance("r", r.as_slice(), m)
    {
        v.add(format!("{f}.r"), covariance_message(&e));
    }
    for (k, field) in [
        ("site_m", s.site_m.is_some()),
        ("sigma_range_m", s.sigma_range_m.is_some()),
        ("sigma_azimuth_deg", s.sigma_azimuth_deg.is_some()),
        ("sigma_elevation_deg", s.sigma_elevation_deg.is_some()),
    ] {
        if field {
            v.add(format!("{f}.{k}"), "only for polar sensors");
        }
    }
    Some(SensorModel::Linear { h: h?, r: r? })
}

/// `{f}.{name}`, required, finite and > 0.
fn positive_sigma(v: &mut Violations, f: &str, name: &str, x: Option<f64>) -> Option<f64> {
    let x = v.required(format!("{f}.{name}"), x)?;
    if !(x > 0.0 && x.is_finite()) {
        v.add(
            format!("{f}.{name}"),
            format!("must be finite and > 0, got {x}"),
        );
        return None;
    }
    Some(x)
}

/// A polar radar: its site and accuracies; 3D when it has an elevation σ,
/// which needs z in the state layout.
fn polar_model(
    v: &mut Violations,
    f: &str,
    s: &SensorInput,
    position: Option<PositionLayout>,
) -> Option<SensorModel> {
    let site = v.required(format!("{f}.site_m"), s.site_m.as_ref());
    if let Some(site) = site
        && (site.len() != 3 || site.iter().any(|x| !x.is_finite()))
    {
        v.add(
            format!("{f}.site_m"),
            "must be three finite numbers [east, north, up]",
        );
    }
    let sr = positive_sigma(v, f, "sigma_range_m", s.sigma_range_m);
    let sa = positive_sigma(v, f, "sigma_azimuth_deg", s.sigma_azimuth_deg);
    let se = match s.sigma_elevation_deg {
        None => Some(None),
        Some(x) => positive_sigma(v, f, "sigma_elevation_deg", Some(x)).map(Some),
    };
    if s.h.is_some() || s.r.is_some() {
        v.add(format!("{f}.h"), "only for linear sensors");
    }
    let layout = match position {
        None => {
            v.add(
                "state_layout",
                "a polar sensor needs x and y in state_layout",
            );
            None
        }
        Some(l) if se.flatten().is_some() && l.z.is_none() => {
            v.add(
                format!("{f}.sigma_elevation_deg"),
                "a 3D radar needs z in state_layout",
            );
            None
        }
        Some(l) => Some(l),
    };
    let site = site.filter(|s| s.len() == 3 && s.iter().all(|x| x.is_finite()))?;
    Some(SensorModel::Polar {
        site: [site[0], site[1], site[2]],
        layout: layout?,
        sigma_range: sr?,
        sigma_azimuth: sa?.to_radians(),
        sigma_elevation: se?.map(f64::to_radians),
        sigma_range_rate: None,
    })
}

/// The sensor's gate, from `gate_probability` (default P_G) or
/// `gate_threshold`, and what it needs of the detection probability and
/// the clutter.
fn gate(
    v: &mut Violations,
    f: &str,
    s: &SensorInput,
    dim: Option<usize>,
    p_d: Option<f64>,
) -> Option<Gate> {
    let gate = match (s.gate_probability, s.gate_threshold, dim) {
        (Some(_), Some(_), _) => {
            v.add(
                format!("{f}.gate_threshold"),
                "give gate_probability or gate_threshold, not both",
            );
            None
        }
        (_, _, None) => None,
        (_, Some(g), Some(dim)) => v.param(&format!("{f}."), Gate::from_threshold(dim, g)),
        (p, None, Some(dim)) => v.param(
            &format!("{f}."),
            Gate::from_probability(dim, p.unwrap_or(DEFAULT_GATE_PROBABILITY)),
        ),
    };
    if let (Some(gate), Some(p_d)) = (gate, p_d)
        && gate.probability == 1.0
        && p_d == 1.0
    {
        v.add(
            format!("{f}.gate_probability"),
            "with detection_probability 1 the gate probability must be < 1 (a target could \
             then never be missed, and a scan with fewer measurements than tracks would have \
             no feasible joint event)",
        );
    }
    if let Some(gate) = gate
        && !gate.threshold.is_finite()
        && s.clutter_density.is_none()
    {
        v.add(
            format!("{f}.gate_probability"),
            "non-parametric clutter (no clutter_density) needs a bounded gate: \
             gate_probability < 1",
        );
    }
    gate
}

/// A linear sensor's measurement: `z`, `dim` finite values.
fn linear_measurement(
    v: &mut Violations,
    mf: impl Fn(&str) -> String,
    z: &mut MeasurementInput,
    dim: usize,
) -> Option<DVector<f64>> {
    let values = v.required_at(z.z.take(), || mf("z"))?;
    if values.len() != dim {
        v.add(
            mf("z"),
            format!("has {} components, h has {dim} rows", values.len()),
        );
    } else if values.iter().any(|x| !x.is_finite()) {
        v.add(mf("z"), "contains a non-finite value");
    } else {
        return Some(DVector::from_vec(values));
    }
    None
}

/// A polar sensor's measurement: range, azimuth and, for a 3D radar
/// (`dim` 3), elevation.
fn polar_measurement(
    v: &mut Violations,
    mf: impl Fn(&str) -> String,
    z: &MeasurementInput,
    dim: usize,
) -> Option<DVector<f64>> {
    let range = v.required_at(z.range_m, || mf("range_m"));
    let az = v.required_at(z.azimuth_deg, || mf("azimuth_deg"));
    if let Some(r) = range
        && !(r >= 0.0 && r.is_finite())
    {
        v.add(mf("range_m"), format!("must be finite and ≥ 0, got {r}"));
    }
    if let Some(a) = az
        && !a.is_finite()
    {
        v.add(mf("azimuth_deg"), format!("must be finite, got {a}"));
    }
    let el = match (dim, z.elevation_deg) {
        (3, None) => {
            v.add(mf("elevation_deg"), "is required for a 3D radar");
            None
        }
        (3, Some(e)) if !(-90.0..=90.0).contains(&e) => {
            v.add(
                mf("elevation_deg"),
                format!("must lie in [-90, 90], got {e}"),
            );
            None
        }
        (3, Some(e)) => Some(e),
        (_, Some(_)) => {
            v.add(
                mf("elevation_deg"),
                "a 2D radar (no sigma_elevation_deg) gives no elevation",
            );
            None
        }
        (_, None) => None,
    };
    let (r, a) = range.zip(az)?;
    if !(r.is_finite() && r >= 0.0 && a.is_finite()) {
        return None;
    }
    let mut values = vec![r, a.to_radians()];
    values.extend(el.map(f64::to_radians));
    (values.len() == dim).then(|| DVector::from_vec(values))
}

/// Request rows as an `rows × cols` matrix, or a violation naming `field`.
fn matrix(
    v: &mut Violations,
    field: impl Fn() -> String,
    rows: &Rows,
    nrows: usize,
    ncols: usize,
) -> Option<DMatrix<f64>> {
    let flat = v.matrix_values(at(field), rows, nrows, ncols)?;
    Some(DMatrix::from_row_slice(nrows, ncols, &flat))
}
