//! Each radar's measurement accuracy learnt online: σ of the range, the
//! azimuth, the elevation and the radial velocity, estimated from the
//! innovations of the confirmed tracks its plots update, so that a radar
//! declared with a datasheet's optimistic (or pessimistic) σ still gives
//! consistent tracks.
//!
//! # The estimator: winsorised covariance matching
//!
//! A plot of radar r that updates a confirmed track has, per polar
//! component k, the innovation ν = z_k − h_k(x̂) against the track's
//! prediction (x̂, P), whose variance is E[ν²] = c + σ_k² with
//! c = (H P Hᵀ)_kk when the prediction is consistent: covariance matching
//! (Mehra 1970) gives σ̂² = mean(ν² − c). Over the plots of the last
//! time constant τ ([`AccuracyConfig::time_constant`], weights
//! w = exp(−(t − t_i)/τ), so a radar that degrades is followed):
//!
//!   σ̂² = Σ w g (y/ψ − c) / Σ w g,  y = min(ν², K² (c + s²)),
//!
//! the squared innovation winsorised at K = 3 standard deviations (at
//! the scale s of the moment's estimate, the declared σ before any plot),
//! and ψ = E[min(Z², K²)] = 0.99501 for a standard normal Z, which makes
//! y/ψ unbiased for c + σ² when s = σ; g = 1/(c + d²)² (d the converged
//! estimate, the declared σ before) weighs each plot by
//! the inverse variance of its y (2(c + σ²)²): one Fisher-scoring step of
//! the maximum-likelihood σ² per plot. Its variance is the sandwich
//! (Huber–White) Var(σ̂²) = Σ w² g² (e − σ̂²)² / (Σ w g)², e = y/ψ − c,
//! never below the Fisher bound 2 / Σ w g (the Fisher variance alone was
//! 1.2–3 times too small in the Monte Carlo: heavy tails, and a c that
//! is not the prediction's true variance), and σ(σ̂) = σ(σ̂²) / (2σ̂). The
//! weights' scale is the estimate once converged, the declared σ before
//! (at the running estimate, a plot taken while it was near 0 with a sharp
//! prediction, c of a few m² from a track ADS-B holds, weighed thousands
//! of times the others and alone made the estimate: σ_range 182 ± 0.2 m
//! for a 100-m radar); the winsorising's the estimate once converged,
//! before the larger of the estimate and the declared σ (so that an
//! estimate near 0 cannot hold itself there).
//!
//! Why winsorised: the innovations of real motion have heavy tails (a turn
//! that begins between two plots gives a radial-velocity innovation of
//! tens of m/s against a σ of 1: in the manoeuvre Monte Carlo half a
//! percent of the innovations made a third of Σ ν², and the plain mean
//! learnt σ_ṙ six times too large). Clipped at 3σ a stray innovation
//! counts at most 9(c + σ²), and a fixed point s² ≈ σ²/(1 − 9ε) holds
//! for a share ε of them. Clipped at the running estimate (not rejected)
//! the estimate still grows from a σ declared too small: every plot
//! counts, at most K² times the current variance. Why weighted: the
//! azimuth's c grows as a target nears its radar, and the unweighted mean
//! converged too slowly. The estimator needs four running sums per component,
//! stored with the tracker. Variational Bayes (Särkkä and
//! Nummenmaa 2009) estimates the same quantity per track with an inner
//! iteration per update; ML over residuals (post-update) needs the
//! updated covariance, which an IMM mixture does not give per plot.
//!
//! **Bias and noise.** The registrar removes each radar's estimated bias
//! before the update; what bias remains is constant over the time
//! constant, so the innovations are centred on their own running mean
//! before they are squared: the estimate is the noise about the bias,
//! never the bias. (The registration's own σ is added to the update's
//! variance separately, [`super::registration::inflated`].)
//!
//! **Which plots teach.** A plot that updates a confirmed track past its
//! start ([`LEARNING_HITS`]) and lies in no other track's gate: in dense
//! traffic the wrong associations and the young tracks' covariances made
//! the σ 15–28 % too large.
//!
//! **Noise and process noise.** An IMM track's plot is compared with its
//! most probable model's prediction, and only when that model's predicted
//! probability is at least [`MIN_MODE_PROBABILITY`] (a manoeuvre under
//! way is the IMM's); only plots associated without ambiguity (weight ≥
//! [`MIN_ASSOCIATION_WEIGHT`]) are used; the winsorising bounds what a
//! manoeuvre's onset adds. Where the tracks' own uncertainty c dominates
//! σ² the estimate's σ stays large and it is not used.
//!
//! **Feedback.** A converged estimate replaces the declared σ in the
//! gate, the association and the update. With σ too small the filter
//! trusts the plots too much, its c is too small and σ̂² too large, and
//! the other way round, so the estimate moves toward the true σ; at the
//! true σ the prediction is consistent and σ̂² is unbiased.
//!
//! **Convergence.** An estimate is applied after [`MIN_SAMPLES`] plots
//! once σ(σ̂) ≤ [`CONVERGED_RELATIVE_SIGMA`] σ̂, or once it lies more
//! than [`DECLARED_SIGMAS`] σ(σ̂) from the declared σ (a radar declared
//! three times too accurate is known to be wrong long before its σ is
//! known to 10 %). Before that, from [`EARLY_SAMPLES`] plots on, a σ
//! whose lower bound σ̂ − [`EARLY_SIGMAS`] σ(σ̂) exceeds the declared one
//! is applied at that bound: the two errors are not alike, since a σ
//! declared too small shrinks the gates and every scan starts false
//! tracks from the plots they miss, while one a little too large costs a
//! little accuracy. In the Monte Carlo this took the whole run's false
//! tracks with radars declared three times too accurate from 25 to 8 an
//! hour, those of the radars declared right (6 an hour) unchanged.
//!
//! # The detection probability
//!
//! Each confirmed track keeps, per radar, the time of that radar's last
//! hit ([`super::track::RadarHit`]). A hit by a later scan, k =
//! round(Δt / scan period) scans after the radar's previous hit of the
//! track, closes k trials of the radar's P_D with one detection: the
//! scans between the two hits are the misses. From a track's first hit by
//! the radar on, every scan is a Bernoulli trial of P_D whatever came
//! before, so the counts over the intervals estimate it without a
//! coverage map and without the sweeps' geometry (frames of a whole scan
//! and beam-timed plots alike). What they leave out is biased: the misses
//! after a track's last hit by the radar (it left the coverage, or the
//! track ended: (1 − P_D)/P_D scans on average, against the hundreds a
//! track lives), and an interval longer than [`MAX_GAP_SCANS`] (the track
//! was out of the radar's coverage and came back; a run of that many
//! misses has probability (1 − P_D)^10, 10⁻⁴ at P_D = 0.6). Both raise the
//! estimate a little; a hit whose plot arrived after a later one of the
//! radar (a late plot) closes no interval. The scan period is the declared
//! one: an interval of k scans is counted right while the declared period
//! is within 1/(2k) of the real one. The estimate is the posterior mean
//! under a uniform prior, (d + 1)/(n + 2) over the decayed counts n of
//! trials and d of detections, with σ² = P̂(1 − P̂)/(n + 3), of the
//! probability that a trial finds the track, P_D · P_G (P_G the track
//! gate's probability, `track_gate_probability`): divided by P_G, it is
//! applied (within [[`MIN_DETECTION`], [`MAX_DETECTION`]]) after
//! [`MIN_SAMPLES`] trials once σ ≤ [`CONVERGED_RELATIVE_SIGMA`] of the
//! smaller of P̂ and 1 − P̂, or once it lies more than
//! [`DECLARED_SIGMAS`] σ from the declared P_D, in the JPDA's weights of
//! the radar's plots. Trials count from the time the radar's σ have
//! converged (a σ declared too small makes the gates miss plots the
//! radar detected), and on tracks with more than [`ESTABLISHED_HITS`]
//! hits (a false track's misses are not the radar's).
//!
//! The clutter density is not estimated: a track's gate holds λV ≈ 10⁻⁶
//! false plots at the densities of surveillance radars, so the gates do
//! not identify it, and the plots no track takes mix clutter with new
//! aircraft over an area no coverage map bounds.

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::kalman::PositionLayout;
use crate::polar::{polar_measurement_model, wrap_angle};
use crate::tracking::config::{Plot, RadarSpec};

/// The components: range (m), azimuth (rad), elevation (rad), radial
/// velocity (m/s).
pub const COMPONENTS: usize = 4;
/// Index of the range in [`RadarAccuracyData::components`].
pub const RANGE: usize = 0;
/// Index of the azimuth.
pub const AZIMUTH: usize = 1;
/// Index of the elevation.
pub const ELEVATION: usize = 2;
/// Index of the radial velocity.
pub const RADIAL_VELOCITY: usize = 3;

/// Default forgetting time constant τ (s): a quarter of an hour holds
/// thousands of plots per radar in traffic and follows a radar that
/// degrades within the hour.
pub const DEFAULT_TIME_CONSTANT_S: f64 = 900.0;
/// Plots (decayed count) a component needs before its estimate is used.
pub const MIN_SAMPLES: f64 = 30.0;
/// The estimate is used once σ(σ̂) ≤ this share of σ̂ …
pub const CONVERGED_RELATIVE_SIGMA: f64 = 0.1;
/// … or once it lies more than this many σ(σ̂) from the declared σ.
pub const DECLARED_SIGMAS: f64 = 4.0;
/// Before convergence, after this many plots, a σ whose estimate minus
/// [`EARLY_SIGMAS`] of its σ exceeds the declared one is applied at that
/// lower bound.
pub const EARLY_SAMPLES: f64 = 5.0;
/// See [`EARLY_SAMPLES`].
pub const EARLY_SIGMAS: f64 = 1.0;
/// A plot's association weight (β) must be at least this to be learnt
/// from.
pub const MIN_ASSOCIATION_WEIGHT: f64 = 0.9;
/// An IMM track's plot is learnt from when its most probable model's
/// predicted probability is at least this, against that model's
/// prediction.
pub const MIN_MODE_PROBABILITY: f64 = 0.5;
/// Squared innovations are winsorised at this many σ of √(c + s²), s the
/// estimate of the moment.
pub const CLIP_SIGMAS: f64 = 3.0;
/// E[min(Z², K²)] for a standard normal Z and K = [`CLIP_SIGMAS`]:
/// erf(K/√2) − 2Kφ(K) + 2K²(1 − Φ(K)) = 0.997300 − 0.026591 + 0.024298.
const CLIPPED_MEAN: f64 = 0.995_007_278;
/// The applied σ stays within [declared / LIMIT, declared × LIMIT]: an
/// estimate at the bound says so in a warning.
pub const LIMIT: f64 = 10.0;
/// A track's plots teach the σ once it has had more than this many hits
/// (its start's covariance is not yet its error's), and only plots in no
/// other track's gate: among 4,000 aircraft under four radars declared
/// right, learning from every track and plot took σ_range to 57–64 m for
/// a true 50 (and the early lower bound then started 25 more tracks);
/// with both rules 0.2 % more tracks than with the estimator off.
pub const LEARNING_HITS: u32 = 4;
/// A track's hits count toward the detection probability once it has
/// had more than this many.
pub const ESTABLISHED_HITS: u32 = 10;
/// An interval between two hits of a track by a radar longer than this
/// many scans is not counted (the track was out of the radar's coverage).
pub const MAX_GAP_SCANS: u32 = 10;
/// The applied detection probability stays at or above this …
pub const MIN_DETECTION: f64 = 0.05;
/// … and at or below this (a P_D of 1 would rule a miss out).
pub const MAX_DETECTION: f64 = 0.999;

/// The accuracy estimator's options.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyConfig {
    /// Learn the radars' σ and apply them once converged (default true).
    pub enabled: bool,
    /// Forgetting time constant τ (s), > 0.
    pub time_constant: f64,
    /// Radars (indices) whose declared σ are applied whatever the data
    /// say (their estimates are still reported).
    pub pinned: Vec<usize>,
}

impl Default for AccuracyConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            time_constant: DEFAULT_TIME_CONSTANT_S,
            pinned: Vec::new(),
        }
    }
}

impl AccuracyConfig {
    /// Checks τ and the pinned radars' indices.
    pub fn validate(&self, radars: usize) -> Result<(), AlgoError> {
        use crate::tracking::parameter::{TrackerParameter as P, invalid};
        let tau = self.time_constant;
        if !(tau.is_finite() && tau > 0.0) {
            return Err(invalid(
                P::AccuracyTimeConstant,
                format!("must be finite and > 0, got {tau}"),
            ));
        }
        if let Some(&r) = self.pinned.iter().find(|&&r| r >= radars) {
            return Err(invalid(
                P::AccuracyPinned,
                format!("radar index {r} but {radars} radars"),
            ));
        }
        Ok(())
    }
}

/// Whether an estimate (`estimate` ± `sigma` from `samples`, declared
/// `declared`) is applied: after [`MIN_SAMPLES`], once precise enough
/// (σ ≤ [`CONVERGED_RELATIVE_SIGMA`] of `scale`) or already far (beyond
/// [`DECLARED_SIGMAS`] of its σ) from the declared value: a radar declared
/// three times too accurate is known to be wrong long before its σ is
/// known to 10 %, and every scan with the declared σ starts false tracks.
fn converged(samples: f64, estimate: f64, sigma: f64, scale: f64, declared: f64) -> bool {
    samples >= MIN_SAMPLES
        && (sigma <= CONVERGED_RELATIVE_SIGMA * scale
            || (estimate - declared).abs() > DECLARED_SIGMAS * sigma)
}

/// One component's running sums (each decayed by exp(−Δt/τ), the
/// squared weights by its square).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ComponentData {
    /// Σ w: the decayed count of plots learnt from.
    pub weight: f64,
    /// Σ w ν: the innovations' running mean times the count.
    pub sum: f64,
    /// Σ w g, g = 1/(c + s²)²: twice the Fisher information of σ².
    pub information: f64,
    /// Σ w g (y/ψ − c): y the centred innovation squared, winsorised.
    pub excess: f64,
    /// Σ w² g² e², Σ w² g² e and Σ w² g² (e = y/ψ − c; squared weights
    /// decayed by the factor's square): the sandwich variance's sums.
    pub sandwich: [f64; 3],
    /// Innovations winsorised (ever; 0.27 % of a Gaussian's).
    pub clipped: u64,
}

/// One radar's data: the four components and the time of its last plot
/// learnt from (the decay's reference), and its detections.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RadarAccuracyData {
    /// Range, azimuth, elevation, radial velocity ([`RANGE`] …).
    pub components: [ComponentData; COMPONENTS],
    /// Time of the last plot learnt from.
    pub t: Option<f64>,
    /// The detection probability's trials.
    pub detection: DetectionData,
}

/// A radar's detection trials (see the module header), each count decayed
/// by exp(−Δt/τ).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DetectionData {
    /// Σ w over the trials.
    pub trials: f64,
    /// Σ w over the trials that found the track.
    pub detections: f64,
    /// Time of the last trials (the decay's reference).
    pub t: Option<f64>,
}

impl DetectionData {
    /// Adds `trials`, `detections` of them, at time `t`.
    fn observe(&mut self, tau: f64, t: f64, trials: u32, detections: u32) {
        if let Some(t0) = self.t {
            if t > t0 {
                let factor = (-(t - t0) / tau).exp();
                self.trials *= factor;
                self.detections *= factor;
            }
        }
        self.t = Some(self.t.map_or(t, |t0| t0.max(t)));
        self.trials += f64::from(trials);
        self.detections += f64::from(detections);
    }

    /// The estimate against the declared P_D, for a tracker whose gates
    /// hold a detected plot with probability `gate` (a trial finds the
    /// track with probability P_D · P_G).
    fn estimate(&self, declared: f64, applies: bool, gate: f64) -> SigmaEstimate {
        let n = self.trials;
        let (estimate, sigma) = if n > 0.0 {
            let p = (self.detections + 1.0) / (n + 2.0);
            let sd = (p * (1.0 - p) / (n + 3.0)).sqrt();
            ((p / gate).min(1.0), sd / gate)
        } else {
            (declared, f64::INFINITY)
        };
        let converged = converged(n, estimate, sigma, estimate.min(1.0 - estimate), declared);
        let applied = if converged && applies {
            estimate.clamp(MIN_DETECTION, MAX_DETECTION)
        } else {
            declared
        };
        SigmaEstimate {
            declared,
            estimate,
            sigma,
            samples: n,
            converged,
            clipped: 0,
            applied,
        }
    }
}

/// A component's σ: declared, estimated, and the one applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SigmaEstimate {
    /// The declared σ.
    pub declared: f64,
    /// The estimate σ̂ (the declared σ before any plot).
    pub estimate: f64,
    /// Its standard deviation σ(σ̂) (infinite before any plot).
    pub sigma: f64,
    /// Plots behind it (decayed count).
    pub samples: f64,
    /// Enough data: σ̂ is applied (unless pinned or disabled).
    pub converged: bool,
    /// Innovations winsorised (beyond [`CLIP_SIGMAS`] σ).
    pub clipped: u64,
    /// The σ the tracker applies: σ̂ within [declared / [`LIMIT`],
    /// declared × LIMIT] once converged and not pinned, else the declared.
    pub applied: f64,
}

/// A radar's accuracy as learnt: `None` for a component the radar does not
/// measure (or the tracker does not use: the elevation in a 2D tracker).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarAccuracy {
    /// Range σ (m).
    pub range: SigmaEstimate,
    /// Azimuth σ (rad).
    pub azimuth: SigmaEstimate,
    /// Elevation σ (rad).
    pub elevation: Option<SigmaEstimate>,
    /// Radial-velocity σ (m/s).
    pub radial_velocity: Option<SigmaEstimate>,
    /// The detection probability (its `samples` are the trials; nothing
    /// is winsorised).
    pub detection_probability: SigmaEstimate,
    /// The declared σ are applied whatever the data say.
    pub pinned: bool,
}

impl ComponentData {
    /// σ̂² and its variance, or `None` before any plot.
    fn variance(&self) -> Option<(f64, f64)> {
        (self.information > 0.0).then(|| {
            let var = self.excess / self.information;
            // Σ w² g² (e − σ̂²)² / (Σ w g)²: the sandwich (Huber–White)
            // variance, which the innovations' heavy tails and a c that is
            // not the prediction's true variance leave honest; never below
            // the Fisher bound 2/Σ w g.
            let [e2, e1, e0] = self.sandwich;
            let spread = (e2 - 2.0 * var * e1 + var * var * e0).max(0.0);
            let sandwich = spread / (self.information * self.information);
            (var, sandwich.max(2.0 / self.information))
        })
    }

    /// The estimate against the declared σ (`applies`: learning on and the
    /// radar not pinned).
    fn estimate(&self, declared: f64, applies: bool) -> SigmaEstimate {
        let moments = self.variance();
        let (estimate, sigma) = match moments {
            Some((var, var_var)) => {
                // A variance at or below 0 (the tracks' own uncertainty
                // explains the innovations): σ not identified.
                let s = var.max(0.0).sqrt();
                let sd = if s > 0.0 {
                    var_var.sqrt() / (2.0 * s)
                } else {
                    f64::INFINITY
                };
                (s, sd)
            }
            None => (declared, f64::INFINITY),
        };
        let converged = converged(self.weight, estimate, sigma, estimate, declared);
        // Before convergence, a σ known (σ̂² less EARLY_SIGMAS of its σ) to
        // exceed the declared one is raised to that lower bound: a radar
        // declared three times too accurate starts false tracks every scan
        // until its estimate converges; the safe side is a wider gate. (On
        // the variance's scale: where the tracks' own uncertainty hides σ,
        // σ̂² is near 0 with a wide σ, and σ(σ̂) by the delta method is
        // no bound.)
        let floor = moments.map_or(0.0, |(var, var_var)| var - EARLY_SIGMAS * var_var.sqrt());
        let applied = if converged && applies {
            estimate.clamp(declared / LIMIT, declared * LIMIT)
        } else if applies && self.weight >= EARLY_SAMPLES && floor > declared * declared {
            floor.sqrt().min(declared * LIMIT)
        } else {
            declared
        };
        SigmaEstimate {
            declared,
            estimate,
            sigma,
            samples: self.weight,
            converged,
            clipped: self.clipped,
            applied,
        }
    }

    /// Learns from one innovation ν of prediction variance c, weighed at
    /// σ̂² = `var` and winsorised at `clip` (the scales of the moment).
    fn learn(&mut self, nu: f64, c: f64, var: f64, clip: f64) {
        let mean = if self.weight > 0.0 {
            self.sum / self.weight
        } else {
            0.0
        };
        let centred = nu - mean;
        let total = c + var;
        let bound = CLIP_SIGMAS * CLIP_SIGMAS * (c + clip);
        let mut y = centred * centred;
        if y > bound {
            y = bound;
            self.clipped += 1;
        }
        // Var(y) = 2(c + σ²)²: the plots whose prediction is sharp say
        // most of σ (the maximum-likelihood weights, at s).
        let g = 1.0 / (total * total);
        self.weight += 1.0;
        self.sum += nu;
        self.information += g;
        let e = y / CLIPPED_MEAN - c;
        self.excess += g * e;
        let g2 = g * g;
        self.sandwich[0] += g2 * e * e;
        self.sandwich[1] += g2 * e;
        self.sandwich[2] += g2;
    }

    fn decay(&mut self, factor: f64) {
        self.weight *= factor;
        self.sum *= factor;
        self.information *= factor;
        self.excess *= factor;
        for v in &mut self.sandwich {
            *v *= factor * factor;
        }
    }
}

/// A plot's innovation against a track's prediction, per component: ν and
/// c = (H P̄ Hᵀ)_kk; `None` for a component not measured.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Innovation {
    /// Per component: (ν, c).
    pub components: [Option<(f64, f64)>; COMPONENTS],
}

/// The innovation of `plot` (bias-corrected) of radar `radar` against the
/// prediction (`x`, `p`, interleaved layout `[x, vx, y, vy(, z, vz)]`),
/// seen as the updater sees it: with the elevation when `layout` has a
/// height and the plot one, the range horizontal otherwise, and the
/// radial velocity when `with_range_rate` and the plot has one. `None`
/// where the geometry is degenerate (at the site).
pub fn innovation(
    radar: &RadarSpec,
    plot: &Plot,
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    layout: PositionLayout,
    with_range_rate: bool,
) -> Option<Innovation> {
    let site = radar.site;
    let cols = [Some(layout.x), Some(layout.y), layout.z];
    let rel = [
        x[layout.x] - site[0],
        x[layout.y] - site[1],
        layout.z.map_or(0.0, |k| x[k] - site[2]),
    ];
    let with_elevation =
        plot.elevation.is_some() && radar.sigma_elevation.is_some() && layout.z.is_some();
    // The EKF's model: h = [r, az(, el)] and ∂h/∂(e, n, u); degenerate at
    // the site (azimuth undefined).
    let (h, j) = polar_measurement_model(rel, with_elevation).ok()?;
    // Rows of H over the state (sparse: position and velocity columns).
    let quad = |row: &[(usize, f64)]| -> f64 {
        row.iter()
            .map(|&(i, hi)| row.iter().map(|&(k, hk)| hi * p[(i, k)] * hk).sum::<f64>())
            .sum()
    };
    let mut out = Innovation::default();
    let mut row = Vec::with_capacity(6);
    let positions = || {
        cols.iter()
            .enumerate()
            .filter_map(|(k, c)| c.map(|c| (k, c)))
    };
    let mut row_of = |i: usize| {
        row.clear();
        row.extend(positions().map(|(k, c)| (c, j[(i, k)])));
        quad(&row)
    };
    out.components[RANGE] = Some((plot.range - h[0], row_of(0)));
    out.components[AZIMUTH] = Some((wrap_angle(plot.azimuth - h[1]), row_of(1)));
    if let (Some(el), true) = (plot.elevation, with_elevation) {
        out.components[ELEVATION] = Some((el - h[2], row_of(2)));
    }
    if let (Some(v), Some(_), true) = (
        plot.radial_velocity,
        radar.sigma_radial_velocity,
        with_range_rate,
    ) {
        let vel = [
            x[layout.x + 1],
            x[layout.y + 1],
            layout.z.map_or(0.0, |k| x[k + 1]),
        ];
        let r = h[0];
        let r2 = rel.iter().map(|v| v * v).sum::<f64>();
        let rdot = (0..3).map(|k| rel[k] * vel[k]).sum::<f64>() / r;
        row.clear();
        for (k, c) in positions() {
            row.push((c, vel[k] / r - rdot * rel[k] / r2));
            row.push((c + 1, rel[k] / r));
        }
        out.components[RADIAL_VELOCITY] = Some((v - rdot, quad(&row)));
    }
    out.components
        .iter()
        .flatten()
        .all(|(nu, c)| nu.is_finite() && c.is_finite())
        .then_some(out)
}

/// The estimator's data for every radar (stored with the tracker).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AccuracyState {
    /// Per radar.
    pub radars: Vec<RadarAccuracyData>,
}

impl AccuracyState {
    /// No data, for `radars` radars.
    pub fn new(radars: usize) -> Self {
        Self {
            radars: vec![RadarAccuracyData::default(); radars],
        }
    }

    /// Checks the parts read from storage: one entry per radar, finite
    /// sums, counts and information ≥ 0.
    pub fn check(&self, radars: usize) -> Result<(), AlgoError> {
        let bad = |reason: String| AlgoError::InvalidParameter {
            what: "tracker state",
            reason,
        };
        if self.radars.len() != radars {
            return Err(bad(format!(
                "accuracy data for {} radars but {radars} radars",
                self.radars.len()
            )));
        }
        for (r, d) in self.radars.iter().enumerate() {
            let ok = d.t.is_none_or(f64::is_finite)
                && d.components.iter().all(|c| {
                    c.weight.is_finite()
                        && c.weight >= 0.0
                        && c.sum.is_finite()
                        && c.information.is_finite()
                        && c.information >= 0.0
                        && c.excess.is_finite()
                        && c.sandwich.iter().all(|v| v.is_finite())
                        && c.sandwich[0] >= 0.0
                        && c.sandwich[2] >= 0.0
                })
                && d.detection.t.is_none_or(f64::is_finite)
                && d.detection.trials.is_finite()
                && (0.0..=d.detection.trials).contains(&d.detection.detections);
            if !ok {
                return Err(bad(format!("accuracy data of radar {r} not finite")));
            }
        }
        Ok(())
    }

    /// Radar `r`'s accuracy against its declared σ and P_D (`declared`),
    /// in a tracker of track gate probability `gate`.
    pub fn radar(
        &self,
        cfg: &AccuracyConfig,
        r: usize,
        declared: &RadarSpec,
        gate: f64,
    ) -> RadarAccuracy {
        let pinned = cfg.pinned.contains(&r);
        let applies = cfg.enabled && !pinned;
        let d = &self.radars[r].components;
        RadarAccuracy {
            range: d[RANGE].estimate(declared.sigma_range, applies),
            azimuth: d[AZIMUTH].estimate(declared.sigma_azimuth, applies),
            elevation: declared
                .sigma_elevation
                .map(|s| d[ELEVATION].estimate(s, applies)),
            radial_velocity: declared
                .sigma_radial_velocity
                .map(|s| d[RADIAL_VELOCITY].estimate(s, applies)),
            detection_probability: self.radars[r].detection.estimate(
                declared.detection_probability,
                applies,
                gate,
            ),
            pinned,
        }
    }

    /// Radar `r` as the tracker applies it: `declared` with the applied σ
    /// and P_D (track gate probability `gate`).
    pub fn applied(
        &self,
        cfg: &AccuracyConfig,
        r: usize,
        declared: &RadarSpec,
        gate: f64,
    ) -> RadarSpec {
        let a = self.radar(cfg, r, declared, gate);
        let mut spec = declared.clone();
        spec.sigma_range = a.range.applied;
        spec.sigma_azimuth = a.azimuth.applied;
        spec.sigma_elevation = a.elevation.map(|s| s.applied);
        spec.sigma_radial_velocity = a.radial_velocity.map(|s| s.applied);
        spec.detection_probability = a.detection_probability.applied;
        spec
    }

    /// Adds the intervals closed by radar `r`'s hits of a frame at time
    /// `t`: each the scans since the radar's previous hit of the track (k
    /// trials, one detection; none beyond [`MAX_GAP_SCANS`]). Not before
    /// every σ of the radar has converged (unless it is pinned): with a σ
    /// declared too small, the gates miss plots the radar detected.
    pub fn detections(
        &mut self,
        cfg: &AccuracyConfig,
        r: usize,
        declared: &RadarSpec,
        t: f64,
        scans: &[u32],
    ) {
        // The σ only: any gate probability.
        let a = self.radar(cfg, r, declared, 1.0);
        let sigmas = [
            Some(a.range),
            Some(a.azimuth),
            a.elevation,
            a.radial_velocity,
        ];
        if !a.pinned && !sigmas.iter().flatten().all(|s| s.converged) {
            return;
        }
        let counted = scans.iter().filter(|&&k| (1..=MAX_GAP_SCANS).contains(&k));
        let (trials, detections) = counted.fold((0, 0), |(n, d), &k| (n + k, d + 1));
        if trials > 0 {
            self.radars[r]
                .detection
                .observe(cfg.time_constant, t, trials, detections);
        }
    }

    /// Learns from radar `r`'s innovations at time `t` (the data decayed
    /// to `t` first); `declared` gives the σ² of a component not yet
    /// estimated.
    pub fn learn(
        &mut self,
        cfg: &AccuracyConfig,
        r: usize,
        declared: &RadarSpec,
        t: f64,
        innovations: &[Innovation],
    ) {
        if innovations.is_empty() {
            return;
        }
        // The σ only: any gate probability.
        let current = self.radar(cfg, r, declared, 1.0);
        let data = &mut self.radars[r];
        if let Some(t0) = data.t {
            if t > t0 {
                let factor = (-(t - t0) / cfg.time_constant).exp();
                for c in &mut data.components {
                    c.decay(factor);
                }
            }
        }
        data.t = Some(data.t.map_or(t, |t0| t0.max(t)));
        let estimates = [
            Some(current.range),
            Some(current.azimuth),
            current.elevation,
            current.radial_velocity,
        ];
        for innovation in innovations {
            for (k, est) in estimates.iter().enumerate() {
                let (Some((nu, c)), Some(est)) = (innovation.components[k], est) else {
                    continue;
                };
                // The winsorising's scale: the estimate once converged;
                // before, the larger of the estimate and the declared σ
                // (an estimate still near 0, where c hides σ, would clip
                // every later innovation and hold itself there). The
                // weights': the estimate once converged, the declared σ
                // before, not the running estimate: where the
                // tracks' own uncertainty c is small (tracks held by ADS-B,
                // a few metres) the weight 1/(c + s²)² of a plot taken
                // while the estimate was low was thousands of times the
                // later plots', and that one plot the estimate for a time
                // constant (σ_range 182 ± 0.2 m learnt for a 100-m
                // radar). Weights that do not depend on the data keep the
                // mean of the unbiased e unbiased.
                let s = if est.converged {
                    est.estimate.max(est.declared / LIMIT)
                } else {
                    est.declared
                };
                let clip = if est.converged {
                    est.estimate
                } else {
                    est.estimate.max(est.declared)
                };
                data.components[k].learn(nu, c, s * s, clip * clip);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kalman;
    use crate::tracking::conversion::polar_measurement;
    use crate::tracking::tests::Lcg;

    fn radar() -> RadarSpec {
        RadarSpec {
            site: [1000.0, -2000.0, 50.0],
            sigma_range: 50.0,
            sigma_azimuth: 0.1f64.to_radians(),
            sigma_elevation: Some(0.2f64.to_radians()),
            sigma_radial_velocity: Some(1.5),
            scan_period: 4.0,
            detection_probability: 0.9,
            clutter_density: 1e-9,
        }
    }

    /// ν and diag(H P Hᵀ) equal the EKF's: kalman's innovation and S − R
    /// (an independent computation through dense matrices).
    #[test]
    fn the_innovation_is_the_ekfs() {
        let radar = radar();
        let x = DVector::from_vec(vec![30_000.0, -150.0, 40_000.0, 90.0, 8000.0, 2.0]);
        let p = DMatrix::from_fn(6, 6, |i, k| {
            if i == k {
                [400.0, 100.0][i % 2]
            } else if i / 2 == k / 2 {
                60.0
            } else {
                5.0 * ((i + k) % 3) as f64
            }
        });
        let p = (&p + p.transpose()) * 0.5;
        let plot = Plot {
            radar: 0,
            t: 0.0,
            range: 50_100.0,
            azimuth: 0.6,
            elevation: Some(0.16),
            radial_velocity: Some(-30.0),
            identity: Default::default(),
            report: None,
        };
        let meas = polar_measurement(&radar, &plot);
        let u = kalman::update_polar_doppler(
            &x,
            &p,
            &meas,
            -30.0,
            1.5,
            PositionLayout::CV_3D,
            radar.site,
        )
        .unwrap();
        let got = innovation(&radar, &plot, &x, &p, PositionLayout::CV_3D, true).unwrap();
        let r = [
            50.0f64.powi(2),
            0.1f64.to_radians().powi(2),
            0.2f64.to_radians().powi(2),
            1.5f64.powi(2),
        ];
        for (k, r) in r.iter().enumerate() {
            let (nu, c) = got.components[k].unwrap();
            assert!(
                (nu - u.innovation[k]).abs() <= 1e-9 * nu.abs().max(1e-6),
                "{k}"
            );
            let expect = u.s[(k, k)] - r;
            assert!(
                (c - expect).abs() <= 1e-9 * expect.abs(),
                "{k}: {c} {expect}"
            );
        }
        // A 2D view: horizontal range, no elevation, no range rate.
        let got = innovation(&radar, &plot, &x, &p, PositionLayout::CV_2D, false);
        let got = got.unwrap();
        assert!(got.components[ELEVATION].is_none() && got.components[RADIAL_VELOCITY].is_none());
        let rho = (29_000.0f64).hypot(42_000.0);
        assert!((got.components[RANGE].unwrap().0 - (50_100.0 - rho)).abs() < 1e-6);
    }

    /// Innovations drawn with c known and σ² = 40² around a mean 7 (a
    /// residual bias): the estimate is within 3 of its own σ of 40, its σ
    /// is at least the closed form √(2/n)(c + σ²)/(2σ̂) (Fisher) and near it, and it converges; the mean
    /// is not taken for noise.
    #[test]
    fn the_estimate_is_the_variance_about_the_bias() {
        let mut rng = Lcg(7);
        let mut d = ComponentData::default();
        let truth = 40.0f64;
        let c = 30.0f64.powi(2);
        // Winsorised at the truth's scale (the fixed point).
        for _ in 0..4000 {
            let nu = 7.0 + (c + truth * truth).sqrt() * rng.normal();
            d.learn(nu, c, truth * truth, truth * truth);
        }
        let e = d.estimate(50.0, true);
        assert!(e.converged);
        assert!((e.estimate - truth).abs() < 3.0 * e.sigma, "{e:?}");
        // Fisher's closed form: Var(σ̂²) = 2/Σg = 2(c + σ²)²/n (every g
        // equal); for Gaussian innovations the sandwich is the same to
        // its sampling error (the fourth moment's, about 5 % at n = 4000
        // and winsorised), and never below it.
        let sd = (2.0 / 4000.0f64).sqrt() * (c + truth * truth) / (2.0 * e.estimate);
        assert!(
            e.sigma >= sd * (1.0 - 1e-12) && e.sigma < 1.1 * sd,
            "{} {sd}",
            e.sigma
        );
        // About 2·σ / √(2·4000)·(1 + c/σ²) ≈ 0.7 m.
        assert!(e.sigma < 1.0);
        assert_eq!(e.applied, e.estimate);
        // 0.27 % of a Gaussian's innovations lie beyond 3σ: 10.8 of 4000.
        assert!((2..30).contains(&e.clipped), "{e:?}");
    }

    /// ψ = E[min(Z², 9)] by quadrature of the normal density (an
    /// independent computation of the constant's closed form).
    #[test]
    fn the_winsorised_mean_is_the_closed_forms() {
        let k = CLIP_SIGMAS;
        let phi = |z: f64| (-0.5 * z * z).exp() / std::f64::consts::TAU.sqrt();
        // Simpson over [0, 12], doubled for the symmetric half.
        let n = 120_000;
        let h = 12.0 / n as f64;
        let f = |z: f64| z.powi(2).min(k * k) * phi(z);
        let mut sum = f(0.0) + f(12.0);
        for i in 1..n {
            let z = i as f64 * h;
            sum += if i % 2 == 1 { 4.0 } else { 2.0 } * f(z);
        }
        let psi = 2.0 * sum * h / 3.0;
        assert!((psi - CLIPPED_MEAN).abs() < 1e-6, "{psi}");
    }

    /// Half a percent of innovations fifty times too large (a manoeuvre's
    /// onset): the plain mean would be 1 + 0.005·2500 = 13.5 times σ²;
    /// winsorised the estimate stays within 10 % of σ.
    #[test]
    fn rare_huge_innovations_move_the_estimate_little() {
        let mut rng = Lcg(17);
        let mut d = ComponentData::default();
        let (truth, c) = (1.0f64, 0.3f64);
        for i in 0..20_000 {
            let scale = if i % 200 == 0 { 50.0 } else { 1.0 };
            let nu = scale * (c + truth * truth).sqrt() * rng.normal();
            let s = d.estimate(3.0, true).estimate;
            d.learn(nu, c, s * s, s * s);
        }
        let e = d.estimate(3.0, true);
        assert!((e.estimate / truth - 1.0).abs() < 0.1, "{e:?}");
    }

    /// Where the prediction's own variance dwarfs σ² the estimate is not
    /// identified: not converged. Its σ̂² is noise of σ ≈ √(2/200) (c +
    /// σ²) ≈ 25,000 m² about 400 m², so the early lower bound may raise
    /// the applied σ (here to 70 m: σ̂² ≈ 30,000 m²), which changes the
    /// innovation's variance c + σ² by under 2 %: immaterial while c hides
    /// σ, and learnt away as the tracks sharpen.
    #[test]
    fn an_unidentified_sigma_is_not_converged() {
        let mut rng = Lcg(11);
        let mut d = ComponentData::default();
        let c = 500.0f64.powi(2);
        for _ in 0..200 {
            let nu = (c + 20.0f64.powi(2)).sqrt() * rng.normal();
            d.learn(nu, c, 20.0 * 20.0, 20.0 * 20.0);
        }
        let e = d.estimate(20.0, true);
        assert!(!e.converged, "{e:?}");
        let inflation = (c + e.applied.powi(2)) / (c + 400.0);
        assert!((1.0..1.02).contains(&inflation), "{e:?}");
    }

    /// Before convergence a σ known at one σ of σ̂² to exceed the declared
    /// one is applied at that lower bound (never below the declared one,
    /// never before [`EARLY_SAMPLES`] plots). Five innovations 300, −300,
    /// 300, −300, 300 m with c = 0, declared 50 m, weighed and clipped at
    /// 50 m: the running mean is 300, 0, 100, 0, 60 before each plot, so
    /// the centred squares are 300², 300², 200², 400², 240², clipped at
    /// 9 · 50² = 150² each; every g = 1/50⁴, so σ̂² = 150²/ψ = 22,612.9
    /// m² (σ̂ = 150.376 m), with every e equal (no spread): the Fisher
    /// bound Var(σ̂²) = 2 · 50⁴ / 5, σ(σ̂²) = 1,581.1 m²; 30 plots are
    /// needed to converge, so √(22,612.9 − 1,581.1) = 145.02 m is applied.
    /// Four plots apply the declared 50 m.
    #[test]
    fn a_sigma_known_to_exceed_the_declared_one_is_raised_before_convergence() {
        let mut d = ComponentData::default();
        for (i, nu) in [300.0, -300.0, 300.0, -300.0, 300.0]
            .into_iter()
            .enumerate()
        {
            if i == 4 {
                assert_eq!(d.estimate(50.0, true).applied, 50.0);
            }
            d.learn(nu, 0.0, 50.0 * 50.0, 50.0 * 50.0);
        }
        let e = d.estimate(50.0, true);
        assert!(!e.converged, "{e:?}");
        let sigma_hat = 150.0 / CLIPPED_MEAN.sqrt();
        assert!((e.estimate - sigma_hat).abs() < 1e-9, "{e:?}");
        let sd_var = (2.0f64 / 5.0).sqrt() * 2500.0;
        assert!((e.sigma - sd_var / (2.0 * sigma_hat)).abs() < 1e-9, "{e:?}");
        let floor = (sigma_hat * sigma_hat - sd_var).sqrt();
        assert!((e.applied - floor).abs() < 1e-9, "{e:?}");
        assert!((e.applied - 145.02).abs() < 0.01, "{e:?}");
        // Pinned or disabled: the declared σ.
        assert_eq!(d.estimate(50.0, false).applied, 50.0);
    }

    /// Pinned or disabled: estimated and reported, the declared σ applied;
    /// an outlier winsorised; the decay halves the count after τ ln 2.
    #[test]
    fn pinned_radars_keep_their_declared_sigma_and_old_data_fade() {
        let declared = radar();
        let mut cfg = AccuracyConfig::default();
        let mut state = AccuracyState::new(1);
        let mut rng = Lcg(3);
        let c = 10.0f64.powi(2);
        let draw = |rng: &mut Lcg| Innovation {
            components: [
                Some(((c + 150.0f64.powi(2)).sqrt() * rng.normal(), c)),
                None,
                None,
                None,
            ],
        };
        for i in 0..400 {
            let batch: Vec<Innovation> = (0..5).map(|_| draw(&mut rng)).collect();
            state.learn(&cfg, 0, &declared, f64::from(i), &batch);
        }
        let a = state.radar(&cfg, 0, &declared, 0.99);
        assert!(a.range.converged);
        assert!(
            (a.range.estimate - 150.0).abs() < 3.0 * a.range.sigma,
            "{a:?}"
        );
        assert_eq!(a.range.applied, a.range.estimate);
        assert_eq!(
            state.applied(&cfg, 0, &declared, 0.99).sigma_range,
            a.range.estimate
        );
        cfg.pinned = vec![0];
        let p = state.radar(&cfg, 0, &declared, 0.99);
        assert!(p.pinned && p.range.converged);
        assert_eq!(p.range.applied, 50.0);
        cfg.pinned.clear();
        cfg.enabled = false;
        assert_eq!(state.applied(&cfg, 0, &declared, 0.99).sigma_range, 50.0);
        cfg.enabled = true;
        // An innovation at 10 σ counts as one at 3σ.
        let before = state.radars[0].components[RANGE];
        let far = Innovation {
            components: [
                Some((10.0 * (c + 150.0f64.powi(2)).sqrt(), c)),
                None,
                None,
                None,
            ],
        };
        state.learn(&cfg, 0, &declared, 399.0, &[far]);
        let after = state.radars[0].components[RANGE];
        assert_eq!(after.clipped, before.clipped + 1);
        assert_eq!(after.weight, before.weight + 1.0);
        // Clipped at 3σ of the converged estimate and weighed at it.
        let s2 = a.range.estimate.powi(2);
        let added = (9.0 * (c + s2) / CLIPPED_MEAN - c) / (c + s2).powi(2);
        assert!((after.excess - before.excess - added).abs() < 1e-9 * added);
        // Decay: τ ln 2 later the count is half (plus the one plot).
        let w = state.radars[0].components[RANGE].weight;
        let later = 399.0 + cfg.time_constant * std::f64::consts::LN_2;
        state.learn(&cfg, 0, &declared, later, &[draw(&mut rng)]);
        let w2 = state.radars[0].components[RANGE].weight;
        assert!((w2 - (w / 2.0 + 1.0)).abs() < 1e-9 * w, "{w} {w2}");
    }

    /// From σ declared three times too small, with c following the σ the
    /// filter applies (a steady-state filter of one scalar position: P⁻ as
    /// the Riccati recursion gives it for the applied R, the innovation's
    /// true variance from the true R), the estimate goes to the truth.
    #[test]
    fn the_feedback_converges_from_three_times_too_small() {
        let truth = 60.0f64;
        let q = 25.0f64; // position process noise per step (m²)
        let declared = RadarSpec {
            sigma_range: truth / 3.0,
            ..radar()
        };
        let cfg = AccuracyConfig::default();
        let mut state = AccuracyState::new(1);
        let mut rng = Lcg(5);
        // Random walk x_k = x_{k−1} + w, z = x + v: with gain K from the
        // applied R the filter's P⁻ and the true error variance differ.
        let (mut p_filter, mut p_true) = (1e4f64, 1e4f64);
        for step in 0..6000 {
            let r_applied = state.applied(&cfg, 0, &declared, 0.99).sigma_range.powi(2);
            let (pm, pt) = (p_filter + q, p_true + q);
            let k = pm / (pm + r_applied);
            p_filter = (1.0 - k) * pm;
            p_true = (1.0 - k).powi(2) * pt + k * k * truth * truth;
            let nu = (pt + truth * truth).sqrt() * rng.normal();
            let inn = Innovation {
                components: [Some((nu, pm)), None, None, None],
            };
            state.learn(&cfg, 0, &declared, f64::from(step), &[inn]);
        }
        let a = state.radar(&cfg, 0, &declared, 0.99);
        assert!(a.range.converged, "{a:?}");
        assert!(
            (a.range.estimate - truth).abs() < 0.05 * truth,
            "{} against {truth}",
            a.range.estimate
        );
    }

    /// For radars whose true σ are `truth` and declared `declared`: the
    /// tracker's accuracy at the end, the mean position NEES (2 dof) of
    /// the confirmed tracks against their nearest target after every
    /// instant of the last two minutes, its sample count, and the
    /// confirmed tracks at the end.
    fn misdeclared_run(
        truth: &[(f64, f64)],
        declared: &[(f64, f64)],
        enabled: bool,
    ) -> (Vec<RadarAccuracy>, f64, usize, usize) {
        use crate::tracking::tests::{feed_by_instants, scene, twelve_crossing};
        use crate::tracking::{Tracker, TrackerConfig};
        let sites = [
            [-30_000.0, 0.0, 0.0],
            [30_000.0, 0.0, 0.0],
            [0.0, 40_000.0, 0.0],
        ];
        let spec = |k: usize, (sr, sa): (f64, f64)| RadarSpec {
            site: sites[k],
            sigma_range: sr,
            sigma_azimuth: sa.to_radians(),
            sigma_elevation: None,
            sigma_radial_velocity: None,
            scan_period: [4.0, 4.5, 5.0][k],
            detection_probability: 0.95,
            clutter_density: 1e-9,
        };
        let real: Vec<RadarSpec> = truth.iter().enumerate().map(|(k, &s)| spec(k, s)).collect();
        let targets = twelve_crossing(600.0);
        let plots = scene(&real, &[0.0, 1.3, 2.9], &targets, 600.0, &mut Lcg(52));
        let mut cfg = TrackerConfig::new(
            2,
            declared
                .iter()
                .enumerate()
                .map(|(k, &s)| spec(k, s))
                .collect(),
        );
        cfg.accuracy.enabled = enabled;
        cfg.registration.enabled = false;
        let mut tracker = Tracker::new(cfg).unwrap();
        let (mut nees, mut n) = (0.0, 0usize);
        feed_by_instants(&mut tracker, &plots, |tracker, t| {
            if t < 480.0 {
                return;
            }
            for tr in tracker.confirmed_tracks() {
                let (k, _) = targets
                    .iter()
                    .map(|g| {
                        let p = g.at(tr.t);
                        (tr.state[0] - p[0]).hypot(tr.state[2] - p[1])
                    })
                    .enumerate()
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .unwrap();
                let p = targets[k].at(tr.t);
                let e = nalgebra::Vector2::new(tr.state[0] - p[0], tr.state[2] - p[1]);
                let cov = nalgebra::Matrix2::new(
                    tr.covariance[(0, 0)],
                    tr.covariance[(0, 2)],
                    tr.covariance[(2, 0)],
                    tr.covariance[(2, 2)],
                );
                nees += (e.transpose() * cov.try_inverse().unwrap() * e)[0];
                n += 1;
            }
        });
        let tracks = tracker.confirmed_count();
        (tracker.accuracy(), nees / n as f64, n, tracks)
    }

    /// Three radars: one declared three times too accurate, one three times
    /// too poor, one right. Learning, each estimate is within 15 % of the
    /// truth and the tracks' position NEES (2 dof) is near 2; with the
    /// declared σ it is far from it (the first radar's plots overweighted).
    #[test]
    fn misdeclared_radars_are_learnt_and_the_tracks_stay_consistent() {
        let truth = [(120.0, 0.15), (60.0, 0.10), (80.0, 0.12)];
        let declared = [(40.0, 0.05), (180.0, 0.30), (80.0, 0.12)];
        let (learnt, nees, n, tracks) = misdeclared_run(&truth, &declared, true);
        for a in &learnt {
            eprintln!(
                "range {:.1} ± {:.1}, azimuth {:.4} ± {:.4}",
                a.range.estimate,
                a.range.sigma,
                a.azimuth.estimate.to_degrees(),
                a.azimuth.sigma.to_degrees()
            );
        }
        for (k, a) in learnt.iter().enumerate() {
            assert!(a.range.converged && a.azimuth.converged, "radar {k}: {a:?}");
            let (sr, sa) = truth[k];
            assert!(
                (a.range.estimate / sr - 1.0).abs() < 0.15,
                "radar {k}: {a:?}"
            );
            assert!(
                (a.azimuth.estimate / sa.to_radians() - 1.0).abs() < 0.15,
                "radar {k}: {a:?}"
            );
        }
        let (_, nees_declared, _, tracks_declared) = misdeclared_run(&truth, &declared, false);
        eprintln!(
            "NEES learnt {nees} ({n} samples, {tracks} tracks), declared {nees_declared} ({tracks_declared} tracks)"
        );
        assert_eq!(tracks, 12);
        assert!(nees < 3.0, "{nees}");
        assert!(nees_declared > nees);
    }
}
