//! Joint probabilistic data association of one scan of measurements from one
//! or more sensors with a set of target tracks (seed 002: Liu Chengxia and
//! Wang Baoshu, approximate multi-sensor JPDA).
//!
//! Per sensor ([`scan`]): linearise every track's measurement model (linear
//! H, or the polar radar model by an EKF Jacobian), gate every measurement
//! with the χ² threshold (the validation matrix Ω of eq. 1), split tracks
//! into clusters that share measurements, compute β_tj per cluster by the
//! chosen [`Method`] (exact eqs. 4–5, AMSJPDA section 3.2, nearest
//! neighbour, global nearest neighbour), and update every track with the
//! combined innovation of eqs. 6–7 and its spread-of-innovations term.
//! Several sensors are processed sequentially in the order given (eqs. 8–10,
//! [`update`]): sensor i refines the estimate left by sensor i − 1, and is
//! linearised there.

pub mod marginals;

use nalgebra::{DMatrix, DVector};

use crate::assignment;
use crate::error::AlgoError;
use crate::gating::{SortedByFirst, chi2_gate_probability, chi2_threshold};
use crate::gaussian::{check_covariance, cholesky, symmetrize};
use crate::kalman::PositionLayout;
use crate::polar::{polar_measurement_model, wrap_angle};
pub use marginals::{
    ClusterProblem, ExactLimit, Marginals, amsjpda_marginals, exact_marginals, naive_marginals,
    nonparametric_count_factor,
};

/// A track's Gaussian estimate `x`, `P` (predicted on input, updated on output).
#[derive(Debug, Clone, PartialEq)]
pub struct TrackEstimate {
    /// State vector.
    pub x: DVector<f64>,
    /// State covariance.
    pub p: DMatrix<f64>,
}

/// How a sensor measures a target state.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorModel {
    /// z = H x + w, w ~ N(0, R).
    Linear {
        /// Measurement matrix H.
        h: DMatrix<f64>,
        /// Measurement noise covariance R.
        r: DMatrix<f64>,
    },
    /// z = [range, azimuth(, elevation)(, range rate)] of the target
    /// relative to `site` (local ENU metres), angles in radians, azimuth
    /// clockwise from north; updated by an extended Kalman filter. The
    /// range rate ṙ = (p − s)·v/r needs the interleaved layout (each
    /// velocity after its position; [`crate::kalman::update_polar_doppler`]).
    Polar {
        /// Sensor position (local ENU, m).
        site: [f64; 3],
        /// Where the position components lie in the track state.
        layout: PositionLayout,
        /// Range standard deviation (m).
        sigma_range: f64,
        /// Azimuth standard deviation (rad).
        sigma_azimuth: f64,
        /// Present for a 3D radar (then measurements have three components).
        sigma_elevation: Option<f64>,
        /// Present for a Doppler radar whose range rate is measured (then
        /// it is each measurement's last component).
        sigma_range_rate: Option<f64>,
    },
}

impl SensorModel {
    /// Dimension of a measurement.
    pub fn dim(&self) -> usize {
        match self {
            SensorModel::Linear { h, .. } => h.nrows(),
            SensorModel::Polar {
                sigma_elevation,
                sigma_range_rate,
                ..
            } => {
                2 + usize::from(sigma_elevation.is_some()) + usize::from(sigma_range_rate.is_some())
            }
        }
    }
}

/// The clutter model of eq. 4.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Clutter {
    /// Parametric: false measurements with spatial density λ > 0 per unit
    /// volume of the measurement space.
    Density(f64),
    /// Non-parametric: φ!/V^φ with V the summed gate volume of the cluster.
    GateVolume,
}

/// The gate: χ² threshold γ on ν' S⁻¹ ν and the probability P_G that the
/// target's own measurement falls inside it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gate {
    /// χ² threshold γ (∞ for an unbounded gate).
    pub threshold: f64,
    /// P_G, the probability that the target's own measurement falls inside.
    pub probability: f64,
}

impl Gate {
    /// The gate with P_G = `probability` in (0, 1] (1: an unbounded gate).
    pub fn from_probability(dim: usize, probability: f64) -> Result<Self, AlgoError> {
        if !(probability > 0.0 && probability <= 1.0) {
            return Err(AlgoError::InvalidParameter {
                what: "gate_probability",
                reason: format!("must lie in (0, 1], got {probability}"),
            });
        }
        let threshold = if probability == 1.0 {
            f64::INFINITY
        } else {
            chi2_threshold(dim, 1.0 - probability)?
        };
        Ok(Self {
            threshold,
            probability,
        })
    }

    /// The gate with threshold γ > 0 (P_G from the χ² CDF).
    pub fn from_threshold(dim: usize, threshold: f64) -> Result<Self, AlgoError> {
        if !(threshold > 0.0 && threshold.is_finite()) {
            return Err(AlgoError::InvalidParameter {
                what: "gate_threshold",
                reason: format!("must be finite and > 0, got {threshold}"),
            });
        }
        Ok(Self {
            threshold,
            probability: chi2_gate_probability(dim, threshold)?,
        })
    }
}

/// One sensor's scan.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// How the sensor measures a target state.
    pub model: SensorModel,
    /// The scan's measurements.
    pub measurements: Vec<DVector<f64>>,
    /// P_D in (0, 1].
    pub detection_probability: f64,
    /// The validation gate.
    pub gate: Gate,
    /// The clutter model.
    pub clutter: Clutter,
}

/// How β is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Exact JPDA (eqs. 4–5) per cluster, by [`exact_marginals`].
    Exact,
    /// AMSJPDA (section 3), by [`amsjpda_marginals`].
    Amsjpda,
    /// Each track takes its own nearest gated measurement (smallest ν' S⁻¹ ν).
    NearestNeighbour,
    /// Optimal one-to-one assignment minimising the summed ν' S⁻¹ ν.
    GlobalNearestNeighbour,
}

/// Limits of the exact computation; beyond them a cluster falls back to AMSJPDA.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// How β is computed.
    pub method: Method,
    /// Largest cluster (number of tracks) computed exactly.
    pub max_exact_tracks: usize,
    /// Largest number of merged hypothesis-tree edges per exact cluster.
    pub max_hypotheses: u64,
}

/// Why a cluster was not computed exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fallback {
    /// The cluster has more tracks than `max_exact_tracks`.
    TooManyTracks,
    /// The merged hypothesis tree would exceed `max_hypotheses` edges.
    TooManyHypotheses,
    /// More than 128 measurements are relevant at once to the partial
    /// hypotheses.
    FrontierTooWide,
}

/// One cluster of one scan: tracks sharing gated measurements.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterReport {
    /// Track indices (into the request's tracks), ascending.
    pub tracks: Vec<usize>,
    /// Measurement indices (into the scan's measurements), ascending.
    pub measurements: Vec<usize>,
    /// The method that produced β for this cluster.
    pub method: Method,
    /// Set when `Method::Exact` was asked for but AMSJPDA was used.
    pub fallback: Option<Fallback>,
    /// Work done: [`Marginals::hypotheses`] (exact, AMSJPDA), or the gated
    /// track–measurement pairs (nearest neighbour, global nearest neighbour).
    pub hypotheses: u64,
}

/// β of one track in one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct Association {
    /// β_t0, the probability that none of the measurements is the target's.
    pub miss: f64,
    /// (measurement index, β_tj) for the gated measurements.
    pub measurements: Vec<(usize, f64)>,
}

/// What one scan did.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanReport {
    /// One report per cluster.
    pub clusters: Vec<ClusterReport>,
    /// Per track.
    pub associations: Vec<Association>,
    /// Tracks whose polar measurement model is undefined at their
    /// prediction (within [`crate::polar::MIN_HORIZONTAL_RANGE`] of the
    /// site horizontally: azimuth undefined), ascending: they gated nothing
    /// ([`associate`] and [`associate_with`] only; [`scan`] fails).
    pub undefined: Vec<usize>,
}

/// Sequential multi-sensor JPDA (eqs. 8–10): X̂_0 = the prediction, sensor i
/// updates X̂_{i−1} into X̂_i, the result is X̂_N. Returns one report per scan.
pub fn update(
    tracks: &mut [TrackEstimate],
    scans: &[Scan],
    config: &Config,
) -> Result<Vec<ScanReport>, AlgoError> {
    scans.iter().map(|s| scan(tracks, s, config)).collect()
}

/// The linearised measurement model of one track for one sensor.
struct Linearised {
    /// Predicted measurement h(x).
    z_pred: DVector<f64>,
    h: DMatrix<f64>,
    r: DMatrix<f64>,
    /// S⁻¹, row-major.
    s_inv: Vec<f64>,
    /// S_00, for the pruning of the gate.
    s00: f64,
    gain: DMatrix<f64>,
    /// ln N(0; 0, S) = −½ ln det(2π S).
    ln_norm: f64,
    /// √det S, for the gate volume.
    sqrt_det: f64,
}

/// One gated pairing.
#[derive(Debug, Clone, Copy)]
struct Hit {
    measurement: usize,
    /// ν' S⁻¹ ν.
    d2: f64,
    /// ln of the evidence's likelihood ratio for the pairing (0 without).
    ln_evidence: f64,
}

/// Evidence beside the position for pairing track `t` with measurement
/// `j` (an identity, a pressure altitude): `Some(ln Λ)`, the log of its
/// likelihood ratio, Λ = p(evidence | j is t's) / p(evidence | j is
/// clutter or another target), which multiplies a_tj; `None` rules the
/// pairing out. Without evidence every gated pairing has Λ = 1.
pub type Evidence<'a> = &'a dyn Fn(usize, usize) -> Option<f64>;

/// The largest |ln Λ| an [`Evidence`] may give: larger values are clamped,
/// so that nearest-neighbour costs d² − 2 ln Λ stay bounded below.
pub const MAX_LN_EVIDENCE: f64 = 30.0;

impl Hit {
    /// The nearest neighbours' cost, d² − 2 ln Λ shifted by
    /// 2 [`MAX_LN_EVIDENCE`] to stay ≥ 0 (the unassigned cost shares the
    /// shift, so a pairing is worth taking when d² − 2 ln Λ < γ).
    fn cost(&self) -> f64 {
        self.d2 - 2.0 * self.ln_evidence + 2.0 * MAX_LN_EVIDENCE
    }
}

/// The linearised models, the validation matrix and the clusters of a scan.
struct Prepared {
    lin: Vec<Linearised>,
    hits: Vec<Vec<Hit>>,
    clusters: Vec<(Vec<usize>, Vec<usize>)>,
    /// Tracks whose measurement model is undefined at their prediction
    /// (tolerant scans only; see [`ScanReport::undefined`]).
    undefined: Vec<usize>,
}

impl Linearised {
    /// The stand-in of a track that gates nothing (its model undefined).
    fn inert(dim: usize, n: usize) -> Self {
        Self {
            z_pred: DVector::zeros(dim),
            h: DMatrix::zeros(dim, n),
            r: DMatrix::zeros(dim, dim),
            s_inv: vec![0.0; dim * dim],
            s00: 0.0,
            gain: DMatrix::zeros(n, dim),
            ln_norm: 0.0,
            sqrt_det: 0.0,
        }
    }
}

fn prepare(
    tracks: &[TrackEstimate],
    scan: &Scan,
    evidence: Option<Evidence<'_>>,
    tolerant: bool,
) -> Result<Prepared, AlgoError> {
    let dim = scan.model.dim();
    let mut undefined = Vec::new();
    let lin: Vec<Linearised> = tracks
        .iter()
        .enumerate()
        .map(|(t, track)| match linearise(track, &scan.model) {
            // A polar sensor's azimuth is undefined for a prediction at
            // (or straight above) its site: that track gates nothing in
            // this scan, the others go on.
            Err(AlgoError::DegenerateGeometry { .. }) if tolerant => {
                undefined.push(t);
                Ok(Linearised::inert(dim, track.x.len()))
            }
            other => other,
        })
        .collect::<Result<_, _>>()?;
    let polar = matches!(scan.model, SensorModel::Polar { .. });
    for z in &scan.measurements {
        if z.len() != dim {
            return Err(AlgoError::DimensionMismatch {
                what: "measurement",
                expected: dim,
                found: z.len(),
            });
        }
    }
    // The validation matrix Ω (eq. 1), as per-track lists. Exact pruning:
    // ν' S⁻¹ ν ≥ ν_0² / S_00, so only measurements whose first component
    // lies within √(γ S_00) of the prediction can pass; they are found by
    // binary search in the measurements sorted by that component.
    let by_first = SortedByFirst::new(scan.measurements.iter().map(|z| z[0]));
    let mut nu = DVector::zeros(dim);
    let mut candidates: Vec<usize> = Vec::new();
    let hits: Vec<Vec<Hit>> = lin
        .iter()
        .enumerate()
        .map(|(t, l)| {
            if undefined.binary_search(&t).is_ok() {
                return Vec::new();
            }
            let reach = (scan.gate.threshold * l.s00).sqrt() * (1.0 + 1e-9);
            by_first.within(l.z_pred[0], reach, &mut candidates);
            let mut row = Vec::new();
            for &j in &candidates {
                innovation(&mut nu, &scan.measurements[j], &l.z_pred, polar);
                let d2 = quad(&l.s_inv, nu.as_slice());
                if d2 <= scan.gate.threshold {
                    let ln_evidence = match evidence {
                        None => 0.0,
                        Some(f) => match f(t, j) {
                            None => continue,
                            Some(v) => v.clamp(-MAX_LN_EVIDENCE, MAX_LN_EVIDENCE),
                        },
                    };
                    row.push(Hit {
                        measurement: j,
                        d2,
                        ln_evidence,
                    });
                }
            }
            row
        })
        .collect();
    let clusters = clusters(&hits, scan.measurements.len(), |h| h.measurement);
    Ok(Prepared {
        lin,
        hits,
        clusters,
        undefined,
    })
}

/// The [`ClusterProblem`] of every cluster of `scan` (tracks and
/// measurements as in [`ClusterReport`], same order), without updating: for
/// benchmarks and offline comparisons of the marginal algorithms.
pub fn cluster_problems(
    tracks: &[TrackEstimate],
    scan: &Scan,
) -> Result<Vec<ClusterProblem>, AlgoError> {
    let Prepared {
        lin,
        hits,
        clusters,
        ..
    } = prepare(tracks, scan, None, false)?;
    let miss_weight = 1.0 - scan.detection_probability * scan.gate.probability;
    Ok(clusters
        .iter()
        .map(|(t, m)| cluster_problem(t, m, &hits, &lin, scan, miss_weight, scan.model.dim()))
        .collect())
}

/// Single-sensor JPDA (eqs. 1–7) of `scan`, updating `tracks` in place.
pub fn scan(
    tracks: &mut [TrackEstimate],
    scan: &Scan,
    config: &Config,
) -> Result<ScanReport, AlgoError> {
    let (report, lin) = weigh(tracks, scan, config, None, false)?;
    for (t, track) in tracks.iter_mut().enumerate() {
        combined_update(
            track,
            &lin[t],
            &report.associations[t],
            &scan.measurements,
            &scan.model,
        )?;
    }
    Ok(report)
}

/// The association of [`scan`] without its update: each track's β_0 and
/// β_j of its gated measurements, the tracks left as they are (for an
/// updater of its own, such as the tracker's IMM). A track whose polar
/// model is undefined at its prediction (at the sensor's site) gates
/// nothing and is listed in [`ScanReport::undefined`] (where [`scan`]
/// fails).
pub fn associate(
    tracks: &[TrackEstimate],
    scan: &Scan,
    config: &Config,
) -> Result<ScanReport, AlgoError> {
    weigh(tracks, scan, config, None, true).map(|(report, _)| report)
}

/// [`associate`] with evidence beside the position ([`Evidence`]): each
/// a_tj is multiplied by the pairing's likelihood ratio, pairings it rules
/// out are not gated; nearest neighbours minimise d² − 2 ln Λ.
pub fn associate_with(
    tracks: &[TrackEstimate],
    scan: &Scan,
    config: &Config,
    evidence: Evidence<'_>,
) -> Result<ScanReport, AlgoError> {
    weigh(tracks, scan, config, Some(evidence), true).map(|(report, _)| report)
}

/// The association of [`scan`] and each track's linearisation.
fn weigh(
    tracks: &[TrackEstimate],
    scan: &Scan,
    config: &Config,
    evidence: Option<Evidence<'_>>,
    tolerant: bool,
) -> Result<(ScanReport, Vec<Linearised>), AlgoError> {
    let dim = scan.model.dim();
    let Prepared {
        lin,
        hits,
        clusters,
        undefined,
    } = prepare(tracks, scan, evidence, tolerant)?;
    let mut associations: Vec<Association> = hits
        .iter()
        .map(|_| Association {
            miss: 1.0,
            measurements: Vec::new(),
        })
        .collect();
    let mut reports = Vec::with_capacity(clusters.len());
    let p_d = scan.detection_probability;
    let miss_weight = 1.0 - p_d * scan.gate.probability;
    for (cluster_tracks, cluster_meas) in clusters {
        let mut report = ClusterReport {
            tracks: cluster_tracks.clone(),
            measurements: cluster_meas.clone(),
            method: config.method,
            fallback: None,
            hypotheses: 0,
        };
        match config.method {
            Method::NearestNeighbour | Method::GlobalNearestNeighbour => {
                let chosen = if config.method == Method::NearestNeighbour {
                    cluster_tracks
                        .iter()
                        .map(|&t| {
                            hits[t]
                                .iter()
                                .min_by(|a, b| a.cost().total_cmp(&b.cost()))
                                .map(|h| (t, h.measurement))
                        })
                        .collect::<Vec<_>>()
                        .into_iter()
                        .flatten()
                        .collect::<Vec<_>>()
                } else {
                    let edges: Vec<(usize, usize, f64)> = cluster_tracks
                        .iter()
                        .flat_map(|&t| hits[t].iter().map(move |h| (t, h.measurement, h.cost())))
                        .collect();
                    let unassigned = if scan.gate.threshold.is_finite() {
                        (scan.gate.threshold + 2.0 * MAX_LN_EVIDENCE) * (1.0 + 1e-12) + 1e-12
                    } else {
                        1e300
                    };
                    assignment::solve(&edges, unassigned)
                };
                report.hypotheses = cluster_tracks.iter().map(|&t| hits[t].len() as u64).sum();
                for (t, j) in chosen {
                    associations[t] = Association {
                        miss: 0.0,
                        measurements: hits[t]
                            .iter()
                            .map(|h| (h.measurement, if h.measurement == j { 1.0 } else { 0.0 }))
                            .collect(),
                    };
                }
                for &t in &cluster_tracks {
                    if associations[t].miss == 1.0 {
                        associations[t].measurements =
                            hits[t].iter().map(|h| (h.measurement, 0.0)).collect();
                    }
                }
            }
            Method::Exact | Method::Amsjpda => {
                let problem = cluster_problem(
                    &cluster_tracks,
                    &cluster_meas,
                    &hits,
                    &lin,
                    scan,
                    miss_weight,
                    dim,
                );
                let marginals = if config.method == Method::Amsjpda {
                    amsjpda_marginals(&problem)
                } else if cluster_tracks.len() > config.max_exact_tracks {
                    report.fallback = Some(Fallback::TooManyTracks);
                    amsjpda_marginals(&problem)
                } else {
                    match exact_marginals(&problem, config.max_hypotheses) {
                        Ok(m) => m,
                        Err(limit) => {
                            report.fallback = Some(match limit {
                                ExactLimit::Frontier => Fallback::FrontierTooWide,
                                ExactLimit::Hypotheses => Fallback::TooManyHypotheses,
                            });
                            amsjpda_marginals(&problem)
                        }
                    }
                };
                if report.fallback.is_some() {
                    report.method = Method::Amsjpda;
                }
                report.hypotheses = marginals.hypotheses;
                for (local, &t) in cluster_tracks.iter().enumerate() {
                    let row = &marginals.beta[local];
                    associations[t] = Association {
                        miss: row[0],
                        measurements: hits[t]
                            .iter()
                            .zip(&row[1..])
                            .map(|(h, &b)| (h.measurement, b))
                            .collect(),
                    };
                }
            }
        }
        reports.push(report);
    }
    Ok((
        ScanReport {
            clusters: reports,
            associations,
            undefined,
        },
        lin,
    ))
}

/// The weights of one cluster (see [`marginals`]): a_tj = P_D N_tj / λ with
/// N_tj = exp(−d²/2 + ln_norm), b_t = 1 − P_D P_G, each track's options
/// scaled (in logs) to a largest weight of 1.
fn cluster_problem(
    cluster_tracks: &[usize],
    cluster_meas: &[usize],
    hits: &[Vec<Hit>],
    lin: &[Linearised],
    scan: &Scan,
    miss_weight: f64,
    dim: usize,
) -> ClusterProblem {
    let m = cluster_meas.len();
    let (ln_lambda, count_factor) = match scan.clutter {
        Clutter::Density(lambda) => (lambda.ln(), None),
        Clutter::GateVolume => {
            let volume: f64 = cluster_tracks
                .iter()
                .map(|&t| {
                    unit_ball_volume(dim)
                        * scan.gate.threshold.powf(dim as f64 / 2.0)
                        * lin[t].sqrt_det
                })
                .sum();
            let lambda = if m == 0 { 1.0 } else { m as f64 / volume };
            (
                lambda.ln(),
                Some(nonparametric_count_factor(m, cluster_tracks.len())),
            )
        }
    };
    let ln_pd = scan.detection_probability.ln();
    let ln_b = miss_weight.ln();
    let mut gates = Vec::with_capacity(cluster_tracks.len());
    let mut miss = Vec::with_capacity(cluster_tracks.len());
    for &t in cluster_tracks {
        let ln_a: Vec<f64> = hits[t]
            .iter()
            .map(|h| ln_pd - 0.5 * h.d2 + h.ln_evidence + lin[t].ln_norm - ln_lambda)
            .collect();
        let top = ln_a.iter().copied().fold(ln_b, f64::max);
        miss.push((ln_b - top).exp());
        gates.push(
            hits[t]
                .iter()
                .zip(&ln_a)
                .map(|(h, &la)| {
                    let local = cluster_meas
                        .binary_search(&h.measurement)
                        .expect("a gated measurement belongs to its cluster");
                    (local, (la - top).exp())
                })
                .collect(),
        );
    }
    ClusterProblem {
        measurements: m,
        gates,
        miss,
        count_factor,
    }
}

/// Volume of the unit ball in `dim` dimensions: c_1 = 2, c_2 = π, c_{n} = c_{n−2}·2π/n.
fn unit_ball_volume(dim: usize) -> f64 {
    match dim {
        0 => 1.0,
        1 => 2.0,
        n => unit_ball_volume(n - 2) * 2.0 * std::f64::consts::PI / n as f64,
    }
}

/// Connected components of tracks linked by shared gated measurements:
/// (tracks ascending, measurements ascending). `hits[t]` are track t's gated
/// hypotheses, `measurement` names the measurement of one. Tracks without
/// gated measurements form clusters of their own.
pub(crate) fn clusters<H>(
    hits: &[Vec<H>],
    measurements: usize,
    measurement: impl Fn(&H) -> usize,
) -> Vec<(Vec<usize>, Vec<usize>)> {
    let n = hits.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut owner = vec![usize::MAX; measurements];
    for (t, row) in hits.iter().enumerate() {
        for h in row {
            let j = measurement(h);
            if owner[j] == usize::MAX {
                owner[j] = t;
            } else {
                let (a, b) = (find(&mut parent, owner[j]), find(&mut parent, t));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut index_of_root = vec![usize::MAX; n];
    let mut out: Vec<(Vec<usize>, Vec<usize>)> = Vec::new();
    for t in 0..n {
        let r = find(&mut parent, t);
        if index_of_root[r] == usize::MAX {
            index_of_root[r] = out.len();
            out.push((Vec::new(), Vec::new()));
        }
        out[index_of_root[r]].0.push(t);
    }
    for (j, &t) in owner.iter().enumerate() {
        if t != usize::MAX {
            let r = find(&mut parent, t);
            out[index_of_root[r]].1.push(j);
        }
    }
    out
}

fn linearise(track: &TrackEstimate, model: &SensorModel) -> Result<Linearised, AlgoError> {
    let n = track.x.len();
    let (z_pred, h, r) = match model {
        SensorModel::Linear { h, r } => {
            if h.ncols() != n {
                return Err(AlgoError::DimensionMismatch {
                    what: "measurement matrix",
                    expected: n,
                    found: h.ncols(),
                });
            }
            (h * &track.x, h.clone(), r.clone())
        }
        SensorModel::Polar {
            site,
            layout,
            sigma_range,
            sigma_azimuth,
            sigma_elevation,
            sigma_range_rate,
        } => {
            layout.validate(n)?;
            let cols = [Some(layout.x), Some(layout.y), layout.z];
            if sigma_range_rate.is_some() && cols.iter().flatten().any(|&c| c + 1 >= n) {
                return Err(AlgoError::InvalidParameter {
                    what: "layout",
                    reason: "a range rate needs each position's velocity after it".into(),
                });
            }
            let rel = [
                track.x[layout.x] - site[0],
                track.x[layout.y] - site[1],
                layout.z.map_or(0.0, |k| track.x[k] - site[2]),
            ];
            let (z_pos, j) = polar_measurement_model(rel, sigma_elevation.is_some())?;
            let m = z_pos.len();
            let rows = m + usize::from(sigma_range_rate.is_some());
            let mut h = DMatrix::zeros(rows, n);
            let mut z_pred = DVector::zeros(rows);
            z_pred.rows_mut(0, m).copy_from(&z_pos);
            for (k, col) in cols.iter().enumerate() {
                if let Some(c) = col {
                    h.view_mut((0, *c), (m, 1)).copy_from(&j.column(k));
                }
            }
            if sigma_range_rate.is_some() {
                // ṙ = (p − s)·v / r: ∂ṙ/∂p = v/r − ṙ (p − s)/r², ∂ṙ/∂v = (p − s)/r.
                let vel = [
                    track.x[layout.x + 1],
                    track.x[layout.y + 1],
                    layout.z.map_or(0.0, |k| track.x[k + 1]),
                ];
                let r = z_pos[0];
                let rdot = (0..3).map(|k| rel[k] * vel[k]).sum::<f64>() / r;
                z_pred[m] = rdot;
                for (k, col) in cols.iter().enumerate() {
                    if let Some(c) = col {
                        h[(m, *c)] = vel[k] / r - rdot * rel[k] / (r * r);
                        h[(m, c + 1)] = rel[k] / r;
                    }
                }
            }
            let mut d = vec![sigma_range.powi(2), sigma_azimuth.powi(2)];
            d.extend(sigma_elevation.map(|s| s * s));
            d.extend(sigma_range_rate.map(|s| s * s));
            (z_pred, h, DMatrix::from_diagonal(&DVector::from_vec(d)))
        }
    };
    let hp = &h * &track.p;
    let mut s = &hp * h.transpose() + &r;
    symmetrize(&mut s);
    let chol = cholesky("innovation covariance", &s)?;
    let gain = chol.solve(&hp).transpose();
    let l = chol.l();
    let ln_det: f64 = (0..s.nrows()).map(|i| 2.0 * l[(i, i)].ln()).sum();
    let m = s.nrows();
    let s_inv_m = chol.inverse();
    let mut s_inv = Vec::with_capacity(m * m);
    for i in 0..m {
        for k in 0..m {
            s_inv.push(s_inv_m[(i, k)]);
        }
    }
    Ok(Linearised {
        z_pred,
        h,
        r,
        s_inv,
        s00: s[(0, 0)],
        gain,
        ln_norm: -0.5 * (ln_det + m as f64 * (2.0 * std::f64::consts::PI).ln()),
        sqrt_det: (0.5 * ln_det).exp(),
    })
}

fn innovation(out: &mut DVector<f64>, z: &DVector<f64>, z_pred: &DVector<f64>, polar: bool) {
    for i in 0..out.len() {
        out[i] = z[i] - z_pred[i];
    }
    if polar {
        out[1] = wrap_angle(out[1]);
    }
}

/// ν' A ν for a row-major square A.
fn quad(a: &[f64], v: &[f64]) -> f64 {
    let m = v.len();
    let mut sum = 0.0;
    for i in 0..m {
        let row = &a[i * m..(i + 1) * m];
        let mut acc = 0.0;
        for k in 0..m {
            acc += row[k] * v[k];
        }
        sum += v[i] * acc;
    }
    sum
}

/// Eqs. 6–7 with the spread of the innovations:
/// x⁺ = x + K ν̄, ν̄ = Σ_j β_j ν_j;
/// P⁺ = β_0 P + (1 − β_0) P_c + K (Σ_j β_j ν_j ν_j' − ν̄ ν̄') K',
/// P_c = (I − K H) P (I − K H)' + K R K' (Joseph form of P − K S K').
/// With β ∈ {0, 1} this is the Kalman update (NN, GNN) or no update (miss).
fn combined_update(
    track: &mut TrackEstimate,
    lin: &Linearised,
    assoc: &Association,
    measurements: &[DVector<f64>],
    model: &SensorModel,
) -> Result<(), AlgoError> {
    let m = lin.z_pred.len();
    let polar = matches!(model, SensorModel::Polar { .. });
    let mut nu_bar = DVector::zeros(m);
    let mut spread = DMatrix::zeros(m, m);
    let mut nu = DVector::zeros(m);
    let mut detected = 0.0;
    for &(j, b) in &assoc.measurements {
        if b == 0.0 {
            continue;
        }
        innovation(&mut nu, &measurements[j], &lin.z_pred, polar);
        nu_bar.axpy(b, &nu, 1.0);
        spread.ger(b, &nu, &nu, 1.0);
        detected += b;
    }
    if detected == 0.0 {
        return Ok(());
    }
    spread.ger(-1.0, &nu_bar, &nu_bar, 1.0);
    let k = &lin.gain;
    let n = track.x.len();
    let ikh = DMatrix::identity(n, n) - k * &lin.h;
    let p_c = &ikh * &track.p * ikh.transpose() + k * &lin.r * k.transpose();
    let beta0 = 1.0 - detected;
    let mut p = &track.p * beta0 + p_c * detected + k * spread * k.transpose();
    symmetrize(&mut p);
    let x = &track.x + k * nu_bar;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(AlgoError::NonFinite {
            what: "updated state",
        });
    }
    check_covariance("updated covariance", &p)?;
    track.x = x;
    track.p = p;
    Ok(())
}

#[cfg(test)]
mod tests;
