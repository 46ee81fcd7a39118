//! AIS–radar association with joint estimation of the radar's range and
//! azimuth bias (seed 004): time alignment by interpolation (§2.2), the
//! mean-distance matrix (eq. 6), credible pairs by CA-CFAR (eqs. 7–10),
//! least-squares bias estimation, compensation, and re-association by
//! optimal 2D assignment with a gate until the association is stable.
//!
//! Robust seeding where the paper fails (its table 4: 64 % correct at 2–3 km
//! range bias): every radar–AIS pair with common times implies a bias (its
//! mean range and azimuth residuals). A common bias leaves every true pair
//! implying the same bias, so the true hypothesis gathers all true pairs
//! whatever the bias's size, which the distance-ordering argument of CA-CFAR
//! cannot promise.
//!
//! Cost. One pass over every pair's common instants gives the eq. 6 matrix
//! and each pair's implied bias with two lower bounds of its mean distance
//! under any bias h: the mean range residual minus h's range, and the mean
//! cross-range residual (AIS range × azimuth residual) minus h's (a point's
//! distance from another is at least their range difference, and at least
//! its distance from the other's bearing line). Only pairs whose bounds are
//! within the gate (with a 10 % margin for the sine and the interpolation
//! chord) can be gated, so the distances under h are computed for those
//! alone, from interpolation brackets built on first use. Hypotheses are
//! ranked by how many distinct radar tracks and AIS ships imply a bias
//! within a tenth of the gate of them (a true bias gathers every true pair),
//! near-duplicates are skipped, and at most `max_evaluations` are scored
//! exactly (gated pairs, then total distance), as the exhaustive search
//! scored every one; a hypothesis whose upper bound (distinct rows and
//! columns within the gate's bounds) cannot beat the best is never scored.
//!
//! Never silently wrong: when `widen` is set, pair-implied biases beyond the
//! bounds (up to four times them) are scored too, and one that gates more
//! pairs than the best within the bounds wins (`widened`). The result says
//! when its bias lies on or beyond a bound (`at_bound`), when a distinct
//! bias associates as many pairs nearly as well (`ambiguous`), and when the
//! residuals after compensation are far larger than the stated radar and
//! AIS errors (`inconsistent`, `residual_ratio`).
//!
//! Bias model: measured range ρ_m = ρ + Δρ, measured azimuth θ_m = θ + Δθ
//! (clockwise from north); compensation subtracts both. The plane is x east,
//! y north, so eq. 1 reads x = ρ sin θ, y = ρ cos θ.

use crate::bias::cfar::{self, CfarConfig, Thresholds};
use crate::error::AlgoError;

mod alignment;
mod estimate;
mod problem;
mod search;
#[cfg(test)]
mod tests;

use problem::Problem;
use search::{distinct, median_rho, search};

/// A raw radar plot of a track: time, range (m), azimuth (rad, from north).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarSample {
    /// Time of the plot (s).
    pub t: f64,
    /// Measured range (m).
    pub range: f64,
    /// Measured azimuth (rad, clockwise from north).
    pub azimuth: f64,
}

/// An AIS report in the radar's local plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AisPoint {
    /// Time of the report (s).
    pub t: f64,
    /// Position (east, north) in the radar's local plane (m).
    pub position: [f64; 2],
    /// Standard deviation of the report's time (s): a whole-second time
    /// stamp taken at the middle of its second is uniform within ±0.5 s,
    /// σ = 1/√12 s; 0 when the time is exact. Times speed enters the
    /// report's position variance along its course.
    pub time_sigma: f64,
}

impl AisPoint {
    /// A report with an exact time.
    pub fn exact(t: f64, position: [f64; 2]) -> Self {
        Self {
            t,
            position,
            time_sigma: 0.0,
        }
    }
}

/// Standard deviation of a time uniformly distributed over a `resolution`
/// interval (the time stamp at its middle): resolution / √12.
pub fn quantisation_sigma(resolution: f64) -> f64 {
    resolution / 12f64.sqrt()
}

/// A range and azimuth bias (m, rad).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Bias {
    /// Range bias Δρ (m).
    pub range: f64,
    /// Azimuth bias Δθ (rad).
    pub azimuth: f64,
}

/// How the initial bias is found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seeding {
    /// The paper: credible pairs from CA-CFAR thresholds.
    Cfar,
    /// The bias search over pair-implied hypotheses.
    Search,
    /// Both; the result that gates more pairs (then the smaller mean
    /// distance) wins, CA-CFAR on a tie.
    Auto,
}

/// The path that produced the reported result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Path {
    /// Seeded by the CA-CFAR credible pairs (the paper's path).
    Cfar,
    /// Seeded by the bias search over pair-implied hypotheses.
    BiasSearch,
    /// Nothing could be associated; no bias was estimated.
    None,
}

/// Residuals after compensation above this many stated standard deviations
/// (root mean square over both axes) flag the result as inconsistent.
pub const INCONSISTENT_RATIO: f64 = 3.0;
/// A distinct bias whose association gates as many pairs with a mean
/// distance at most this many times the chosen one's makes it ambiguous.
pub const AMBIGUOUS_DISTANCE_RATIO: f64 = 1.5;
/// The widened search looks this many times past the bounds.
pub const WIDEN_FACTOR: f64 = 4.0;

/// Parameters of [`associate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Longest gap between two radar samples interpolated across (s); no
    /// extrapolation beyond a track's first or last sample.
    pub max_gap: f64,
    /// The CA-CFAR detector of the credible pairs (eqs. 7–10).
    pub cfar: CfarConfig,
    /// Gate on the mean distance of an associated pair (m).
    pub gate: f64,
    /// How the initial bias is found.
    pub seeding: Seeding,
    /// Most rounds of compensation, assignment and re-estimation in a
    /// refinement (1 to 1000).
    pub max_iterations: usize,
    /// Bounds of the bias search.
    pub max_range_bias: f64,
    /// Largest azimuth bias searched (rad).
    pub max_azimuth_bias: f64,
    /// Most hypotheses ranked (the most time-consistent pairs first).
    pub max_hypotheses: usize,
    /// Most hypotheses scored exactly (gated assignment) on each side of
    /// the bounds.
    pub max_evaluations: usize,
    /// Score pair-implied biases up to `WIDEN_FACTOR` times past the bounds
    /// and take one that gates more pairs than any within them.
    pub widen: bool,
    /// The radar's stated errors (m, rad) and the AIS position error per
    /// axis (m): the model of the residuals' spread.
    pub sigma_range: f64,
    /// The radar's stated azimuth error, one standard deviation (rad).
    pub sigma_azimuth: f64,
    /// The AIS position error per axis, one standard deviation (m).
    pub sigma_ais: f64,
    /// Fewest common instants for a pair to enter the distance matrix
    /// (at least 2: one instant implies any bias exactly).
    pub min_common: usize,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            max_gap: 30.0,
            cfar: CfarConfig::default(),
            gate: 500.0,
            seeding: Seeding::Auto,
            max_iterations: 20,
            max_range_bias: 5000.0,
            max_azimuth_bias: 5f64.to_radians(),
            max_hypotheses: 2000,
            max_evaluations: 4,
            widen: true,
            sigma_range: 50.0,
            sigma_azimuth: 0.2f64.to_radians(),
            sigma_ais: 10.0,
            min_common: 2,
        }
    }
}

/// A bias estimate with its covariance (rows/cols: range m, azimuth rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiasEstimate {
    /// The estimated bias: the mean range and azimuth residuals over all
    /// samples.
    pub bias: Bias,
    /// The reported covariance: cluster-robust CR2 over pairs scaled to the
    /// small-sample 95 % quantile (Hotelling T² with the effective number of
    /// pairs − 1 degrees of freedom), at least the model covariance of the
    /// stated errors on each axis.
    pub covariance: [[f64; 2]; 2],
    /// The plain cluster-robust (CR1) covariance, for comparison.
    pub covariance_cr1: [[f64; 2]; 2],
    /// (Σ n_k)² / Σ n_k² over the pairs' sample counts n_k.
    pub effective_pairs: f64,
    /// Root mean square of the residuals after compensation in units of
    /// their stated standard deviations (1 when the stated errors hold).
    pub residual_ratio: f64,
    /// Pairs with residuals in the estimate.
    pub pairs: usize,
    /// Residual samples in the estimate (N: the pairs' common instants).
    pub samples: usize,
}

/// One associated pair: radar track index, AIS ship index, eq. 6 distances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Association {
    /// Radar track index.
    pub radar: usize,
    /// AIS ship index.
    pub ais: usize,
    /// Eq. 6 mean distance before compensation (m).
    pub distance_before: f64,
    /// Eq. 6 mean distance after compensation by the estimated bias (m).
    pub distance_after: f64,
    /// Common instants of the pair (AIS report times within the track).
    pub common: usize,
}

/// A distinct bias that associates as many pairs nearly as well.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alternative {
    /// The alternative bias, refined.
    pub bias: Bias,
    /// Pairs it gates.
    pub pairs: usize,
    /// Mean eq. 6 distance of those pairs after compensation by it (m).
    pub mean_distance: f64,
}

/// The result of [`associate`]: the path taken, the bias estimate, the
/// associated pairs and the diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The path that produced the result.
    pub path: Path,
    /// CA-CFAR thresholds S1 and S2, when the detector ran and found them.
    pub thresholds: Option<Thresholds>,
    /// Credible pairs of eq. 7 (radar, AIS, raw eq. 6 distance).
    pub credible_pairs: Vec<(usize, usize, f64)>,
    /// The bias estimate; `None` when nothing could be associated.
    pub estimate: Option<BiasEstimate>,
    /// Refinement rounds of the chosen path.
    pub iterations: usize,
    /// Whether the refinement ended with an unchanged association.
    pub converged: bool,
    /// The associated pairs after refinement with the estimated bias.
    pub associations: Vec<Association>,
    /// Mean distance radar–AIS over the associated pairs' common instants,
    /// before and after compensation.
    pub mean_error_before: Option<f64>,
    /// Mean distance radar–AIS over the associated pairs' common instants
    /// after compensation (m).
    pub mean_error_after: Option<f64>,
    /// Gated pairs reached from each seed, when it ran: (CA-CFAR, search).
    pub gated_by_seed: (Option<usize>, Option<usize>),
    /// Pair-implied biases ranked, and scored exactly, by the search.
    pub hypotheses: usize,
    /// Pair-implied biases scored exactly by the search.
    pub evaluated: usize,
    /// The search went past the bounds: (gated pairs there, best within).
    pub widened: Option<(usize, usize)>,
    /// The estimate lies on or beyond a search bound.
    pub at_bound: bool,
    /// A distinct bias associating as many pairs nearly as well.
    pub ambiguous: Option<Alternative>,
    /// Residuals after compensation above `INCONSISTENT_RATIO` stated σ.
    pub inconsistent: bool,
    /// AIS ships sharing fewer than `min_common` instants with every track:
    /// they can never be associated.
    pub unassociable_ais: Vec<usize>,
}

/// Eq. 1 with azimuth from north: (east, north) of (range, azimuth).
pub fn polar_to_plane(range: f64, azimuth: f64) -> [f64; 2] {
    [range * azimuth.sin(), range * azimuth.cos()]
}

/// (range, azimuth in [0, 2π)) of a plane point.
pub fn plane_to_polar(p: [f64; 2]) -> (f64, f64) {
    (
        p[0].hypot(p[1]),
        p[0].atan2(p[1]).rem_euclid(std::f64::consts::TAU),
    )
}

/// A sample with `bias` removed.
pub fn compensate(s: &RadarSample, bias: Bias) -> RadarSample {
    RadarSample {
        t: s.t,
        range: s.range - bias.range,
        azimuth: (s.azimuth - bias.azimuth).rem_euclid(std::f64::consts::TAU),
    }
}

/// Hotelling's T²(2, ν) 95 % quantile over χ²₂'s: with F(2, m) in closed
/// form (its CDF is 1 − (1 + 2x/m)^(−m/2)), T² = 2ν/(ν − 1) F(2, ν − 1) =
/// ν (0.05^(−2/(ν − 1)) − 1), and χ²₂ = −2 ln 0.05. ν is clamped to 2 (the
/// fewest for a finite quantile): 133 there, 1.25 at ν = 19, → 1.
pub fn small_sample_factor(nu: f64) -> f64 {
    let nu = nu.max(2.0);
    let alpha: f64 = 0.05;
    let t2 = nu * (alpha.powf(-2.0 / (nu - 1.0)) - 1.0);
    t2 / (-2.0 * alpha.ln())
}

/// Checks the configuration's ranges.
pub fn validate_config(cfg: &Config) -> Result<(), AlgoError> {
    cfg.cfar.validate()?;
    let bad = |what, reason: &str| {
        Err(AlgoError::InvalidParameter {
            what,
            reason: reason.into(),
        })
    };
    if !(cfg.max_gap.is_finite() && cfg.max_gap > 0.0) {
        return bad("max_gap_s", "must be a finite number > 0");
    }
    if !(cfg.gate.is_finite() && cfg.gate > 0.0) {
        return bad("gate_m", "must be a finite number > 0");
    }
    if cfg.max_iterations == 0 || cfg.max_iterations > 1000 {
        return bad("max_iterations", "must be between 1 and 1000");
    }
    if !(cfg.max_range_bias.is_finite() && cfg.max_range_bias >= 0.0) {
        return bad("max_range_bias_m", "must be a finite number >= 0");
    }
    if !(cfg.max_azimuth_bias.is_finite()
        && (0.0..=std::f64::consts::PI).contains(&cfg.max_azimuth_bias))
    {
        return bad("max_azimuth_bias_deg", "must be between 0 and 180");
    }
    if cfg.max_hypotheses == 0 {
        return bad("max_hypotheses", "must be at least 1");
    }
    if cfg.max_evaluations == 0 || cfg.max_evaluations > 1000 {
        return bad("max_evaluations", "must be between 1 and 1000");
    }
    if !(cfg.sigma_range.is_finite() && cfg.sigma_range > 0.0) {
        return bad("radar_sigma_range_m", "must be a finite number > 0");
    }
    if !(cfg.sigma_azimuth.is_finite() && cfg.sigma_azimuth > 0.0) {
        return bad("radar_sigma_azimuth_deg", "must be a finite number > 0");
    }
    if !(cfg.sigma_ais.is_finite() && cfg.sigma_ais >= 0.0) {
        return bad("ais_sigma_m", "must be a finite number >= 0");
    }
    if cfg.min_common < 2 {
        return bad(
            "min_common",
            "must be at least 2: one common instant fits any bias exactly",
        );
    }
    Ok(())
}

/// Associates radar tracks (raw polar samples in time order) with AIS ships
/// (plane positions in time order) and estimates the radar bias.
pub fn associate(radar: &[Vec<RadarSample>], ais: &[Vec<AisPoint>], cfg: &Config) -> Outcome {
    let problem = Problem::new(radar, ais, cfg);
    let mut raw_matrix = problem.raw_matrix();
    let cols = problem.cols;
    let unassociable_ais: Vec<usize> = (0..cols)
        .filter(|&j| (0..problem.rows).all(|i| problem.summary[i * cols + j].n == 0))
        .collect();

    // The paper's path: CA-CFAR thresholds, credible pairs, estimate.
    let mut thresholds = None;
    let mut credible = Vec::new();
    let mut from_cfar = None;
    if matches!(cfg.seeding, Seeding::Cfar | Seeding::Auto) {
        let (m, t) = problem.cfar();
        raw_matrix = m;
        thresholds = t;
        if let Some(t) = &thresholds {
            credible = cfar::credible_pairs(&raw_matrix, radar.len(), cols, t);
            if let Some(e) = problem.estimate(&credible) {
                from_cfar = Some(problem.refine(e.bias));
            }
        }
    }
    let searched = matches!(cfg.seeding, Seeding::Search | Seeding::Auto).then(|| search(&problem));
    let from_search = searched
        .as_ref()
        .and_then(|s| s.best)
        .map(|b| problem.refine(b.bias));
    let gated_by_seed = (
        from_cfar.as_ref().map(|r| r.pairs.len()),
        from_search.as_ref().map(|r| r.pairs.len()),
    );
    let (path, chosen) = match (from_cfar, from_search) {
        (Some(c), Some(s)) if s.better_than(&c) => (Path::BiasSearch, Some(s)),
        (Some(c), _) => (Path::Cfar, Some(c)),
        (None, Some(s)) => (Path::BiasSearch, Some(s)),
        (None, None) => (Path::None, None),
    };
    let (path, chosen) = match chosen {
        Some(r) if r.estimate.is_some() && !r.pairs.is_empty() => (path, Some(r)),
        _ => (Path::None, None),
    };
    let credible_pairs = credible
        .iter()
        .map(|&(i, j)| (i, j, raw_matrix[i * cols + j]))
        .collect();
    let (hypotheses, evaluated) = searched
        .as_ref()
        .map_or((0, 0), |s| (s.hypotheses, s.evaluated));
    let widened = searched
        .as_ref()
        .and_then(|s| s.widened)
        .filter(|_| path == Path::BiasSearch);
    let Some(r) = chosen else {
        return Outcome {
            path,
            thresholds,
            credible_pairs,
            estimate: None,
            iterations: 0,
            converged: true,
            associations: Vec::new(),
            mean_error_before: None,
            mean_error_after: None,
            gated_by_seed,
            hypotheses,
            evaluated,
            widened: None,
            at_bound: false,
            ambiguous: None,
            inconsistent: false,
            unassociable_ais,
        };
    };
    let estimate = r.estimate.expect("checked above");
    // A distinct bias that gated as many pairs: refine it and compare.
    let ambiguous = searched
        .as_ref()
        .and_then(|s| s.runner_up)
        .map(|alt| problem.refine(alt.bias))
        .and_then(|alt| {
            let b = alt.estimate?.bias;
            let distinct = distinct(
                b,
                estimate.bias,
                median_rho(&problem, &r.pairs),
                cfg.gate / 2.0,
            );
            (distinct
                && alt.pairs.len() >= r.pairs.len()
                && alt.pairs != r.pairs
                && alt.mean() <= AMBIGUOUS_DISTANCE_RATIO * r.mean() + 1e-3)
                .then(|| Alternative {
                    bias: b,
                    pairs: alt.pairs.len(),
                    mean_distance: alt.mean(),
                })
        });
    let comp = problem.positions(estimate.bias);
    let associations: Vec<Association> = r
        .pairs
        .iter()
        .map(|&(i, j)| Association {
            radar: i,
            ais: j,
            distance_before: raw_matrix[i * cols + j],
            distance_after: problem.distance(&comp, i * cols + j),
            common: problem.summary[i * cols + j].n,
        })
        .collect();
    let n: usize = associations.iter().map(|a| a.common).sum();
    let weighted = |f: fn(&Association) -> f64| {
        associations
            .iter()
            .map(|a| f(a) * a.common as f64)
            .sum::<f64>()
            / n as f64
    };
    Outcome {
        path,
        thresholds,
        credible_pairs,
        estimate: Some(estimate),
        iterations: r.iterations,
        converged: r.converged,
        mean_error_before: (n > 0).then(|| weighted(|a| a.distance_before)),
        mean_error_after: (n > 0).then(|| weighted(|a| a.distance_after)),
        associations,
        gated_by_seed,
        hypotheses,
        evaluated,
        widened,
        at_bound: estimate.bias.range.abs() >= cfg.max_range_bias
            || estimate.bias.azimuth.abs() >= cfg.max_azimuth_bias,
        ambiguous,
        inconsistent: estimate.residual_ratio > INCONSISTENT_RATIO,
        unassociable_ais,
    }
}
