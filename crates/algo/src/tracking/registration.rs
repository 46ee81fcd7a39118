//! Radar registration: each radar's range, azimuth (and, for a 3D radar,
//! elevation) bias estimated online from the tracker's own data, and its
//! plots corrected before association.
//!
//! **Method: a sliding-window least squares over common-target plot
//! pairs, in information form.** A confirmed track updated by a plot z_i
//! of radar a, whose previous update was a plot z_j of another radar b at
//! most [`RegistrationConfig::max_pair_dt`] earlier, gives a pair. With
//! p(z) the plot's position in the fusion frame (the tracker's own
//! conversion: a 2D radar's range is horizontal), the pair's residual
//! d = p_a(z_i) − p_b(z_j) − v̂ (t_i − t_j) (v̂ the track's velocity) is,
//! to first order, d = J_a b_a − J_b b_b + w, where J = ∂p/∂(ρ, θ(, φ))
//! at the plot and b_r the radar's bias (a plot measures ρ + b_ρ, θ + b_θ,
//! φ + b_φ). The noise w has covariance S = J_a R_a J_a′ + J_b R_b J_b′ +
//! P_v Δt² + q|Δt|³/3 (the plots' errors, the velocity's, the motion's). A
//! pair of a 2D and a 3D radar (or a 2D tracker) uses the horizontal
//! components. Each pair adds H′S⁻¹H and H′S⁻¹d to the information of
//! the joint bias vector (H = [… J_a … −J_b …]); the information decays
//! with the time constant [`RegistrationConfig::time_constant`] so a
//! radar that is realigned is followed. The estimate is
//! b̂ = (Λ₀ + Λ)⁻¹ (Λ₀ b₀ + η) with the prior (b₀, Λ₀ = P₀⁻¹) of each radar.
//!
//! Why this and not a bias-augmented tracking filter: the pairs use only
//! the raw plots and a track's velocity, so the estimate does not feed on
//! tracks that already absorbed the bias, it needs no change to the track
//! state or to the IMM, its cost is one small solve per frame (at most 3
//! components per radar), and its covariance says directly how well the
//! geometry observes each bias. Its approximation: successive pairs share
//! plots, so they are not independent; each pair's S is doubled to keep
//! the reported σ honest.
//!
//! **Observability.** Only differences between radars are seen by common
//! targets, through geometry: with targets spread over the coverage, two
//! radars' range and azimuth biases are all observable; a radar can be
//! declared a `reference` (its bias held at its prior, e.g. a surveyed
//! radar). Without one, the weak prior [`BiasPrior::default`] fixes what
//! the geometry leaves free, and a bias whose σ stays near its prior's is
//! reported as unobservable.
//!
//! **Compensation.** A radar's plots are corrected by its current estimate
//! (ρ − b̂_ρ, θ − b̂_θ, φ − b̂_φ) and the estimate's variance is added to
//! the radar's measurement variances (σ_ρ² + P_ρρ, …; the cross terms are
//! left out), so while a bias is uncertain its plots are trusted less and
//! still associate with the tracks of the other radars. Before a radar has
//! [`RegistrationConfig::min_pairs`] pairs, an estimate that has not
//! converged is not applied: a prior the caller gave (a known bias) is
//! applied with its σ, the default prior nothing.

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::gaussian::{cholesky, symmetrize};
use crate::tracking::config::{Plot, RadarSpec};

/// A radar's bias prior: mean and σ per component (a known bias from a
/// survey or from the AIS–radar endpoint, or zero with a weak σ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiasPrior {
    /// Range bias (m).
    pub range: f64,
    /// Azimuth bias (rad).
    pub azimuth: f64,
    /// Elevation bias (rad; 3D radars).
    pub elevation: f64,
    /// σ of the range bias (m), ≥ 0.
    pub sigma_range: f64,
    /// σ of the azimuth bias (rad), ≥ 0.
    pub sigma_azimuth: f64,
    /// σ of the elevation bias (rad), ≥ 0.
    pub sigma_elevation: f64,
}

impl Default for BiasPrior {
    /// Zero with σ 150 m, 0.15°, 0.1°: ordinary radar biases (tens to
    /// hundreds of metres, a few tenths of a degree) lie within 2–3σ, so
    /// the plots of a radar still associate with the other radars' tracks
    /// before its bias is known.
    fn default() -> Self {
        Self {
            range: 0.0,
            azimuth: 0.0,
            elevation: 0.0,
            sigma_range: 150.0,
            sigma_azimuth: 0.15f64.to_radians(),
            sigma_elevation: 0.1f64.to_radians(),
        }
    }
}

/// How the tracker registers its radars.
#[derive(Debug, Clone, PartialEq)]
pub struct RegistrationConfig {
    /// Estimate the biases (default on: two radars' common targets, or
    /// one radar's targets that also send ADS-B, MLAT or AIS reports).
    /// Off, each radar's prior mean is still applied as a known bias.
    pub enabled: bool,
    /// Per radar (empty: [`BiasPrior::default`] for every radar).
    pub priors: Vec<BiasPrior>,
    /// Radars whose bias is held at their prior (σ taken as 0).
    pub reference: Vec<usize>,
    /// Pairs a radar needs before its estimate replaces its prior
    /// (default 20).
    pub min_pairs: u32,
    /// Longest time between the two plots of a pair (s; default 10).
    pub max_pair_dt: f64,
    /// Time constant of the information's decay (s; default 1800).
    pub time_constant: f64,
}

impl RegistrationConfig {
    /// The defaults for `radars` radars: on. A lone radar learns only
    /// against cooperative reports; until it has any, nothing of its prior
    /// is applied ([`applied`]), so a lone radar without reports tracks as
    /// it would unregistered.
    pub fn for_radars(_radars: usize) -> Self {
        Self {
            enabled: true,
            priors: Vec::new(),
            reference: Vec::new(),
            min_pairs: 20,
            max_pair_dt: 10.0,
            time_constant: 1800.0,
        }
    }

    /// Radar `r`'s prior.
    pub fn prior(&self, r: usize) -> BiasPrior {
        self.priors.get(r).copied().unwrap_or_default()
    }

    /// Checks the options for `radars` radars; the error names the option.
    pub fn validate(&self, radars: usize) -> Result<(), AlgoError> {
        use crate::tracking::parameter::{TrackerParameter as P, invalid as bad};
        if !self.priors.is_empty() && self.priors.len() != radars {
            return Err(bad(
                P::RegistrationPriors,
                format!(
                    "one per radar ({radars}) or none, got {}",
                    self.priors.len()
                ),
            ));
        }
        for p in &self.priors {
            for (v, s) in [
                (p.range, p.sigma_range),
                (p.azimuth, p.sigma_azimuth),
                (p.elevation, p.sigma_elevation),
            ] {
                if !v.is_finite() || !s.is_finite() || s < 0.0 {
                    return Err(bad(
                        P::RegistrationPriors,
                        format!("biases must be finite and σ finite and ≥ 0, got {v} ± {s}"),
                    ));
                }
            }
        }
        for &r in &self.reference {
            if r >= radars {
                return Err(bad(
                    P::RegistrationReference,
                    format!("radar {r} does not exist ({radars} radars)"),
                ));
            }
        }
        if self.enabled && radars >= 2 && (0..radars).all(|r| self.reference.contains(&r)) {
            return Err(bad(
                P::RegistrationReference,
                "every radar is a reference: nothing to estimate (turn registration off)",
            ));
        }
        if !(self.max_pair_dt.is_finite() && self.max_pair_dt > 0.0) {
            return Err(bad(
                P::RegistrationMaxPairDt,
                format!("must be finite and > 0, got {}", self.max_pair_dt),
            ));
        }
        if !(self.time_constant.is_finite() && self.time_constant > 0.0) {
            return Err(bad(
                P::RegistrationTimeConstant,
                format!("must be finite and > 0, got {}", self.time_constant),
            ));
        }
        Ok(())
    }
}

/// A radar's current bias as the tracker applies it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarBias {
    /// Range, azimuth, elevation bias (m, rad, rad; elevation 0 for 2D).
    pub bias: [f64; 3],
    /// Their σ (m, rad, rad).
    pub sigma: [f64; 3],
    /// Common-target pairs behind the estimate (decayed count).
    pub pairs: f64,
    /// The estimate is applied (enough pairs); else the prior is.
    pub converged: bool,
    /// Held at its prior.
    pub reference: bool,
}

/// The estimator's state: the data's information of the joint bias vector
/// (the prior is added when solving).
#[derive(Debug, Clone, PartialEq)]
pub struct RegistrationState {
    /// Λ (n × n), n = Σ over radars of their components (2 or 3).
    pub information: DMatrix<f64>,
    /// η (n).
    pub vector: DVector<f64>,
    /// Decayed pair count per radar.
    pub pairs: Vec<f64>,
    /// Time of the last pair (s).
    pub last_t: Option<f64>,
}

impl RegistrationState {
    /// An empty state for `radars`.
    pub fn new(radars: &[RadarSpec]) -> Self {
        let n = layout(radars).1;
        Self {
            information: DMatrix::zeros(n, n),
            vector: DVector::zeros(n),
            pairs: vec![0.0; radars.len()],
            last_t: None,
        }
    }

    /// Checks the sizes against `radars`.
    pub fn check(&self, radars: &[RadarSpec]) -> Result<(), AlgoError> {
        let n = layout(radars).1;
        let ok = self.information.shape() == (n, n)
            && self.vector.len() == n
            && self.pairs.len() == radars.len()
            && self
                .information
                .iter()
                .chain(self.vector.iter())
                .all(|v| v.is_finite())
            && self.pairs.iter().all(|p| p.is_finite() && *p >= 0.0);
        if ok {
            Ok(())
        } else {
            Err(AlgoError::InvalidParameter {
                what: "registration",
                reason: "state sizes do not match the radars".into(),
            })
        }
    }
}

/// Per radar the offset of its components in the joint vector, and n.
fn layout(radars: &[RadarSpec]) -> (Vec<usize>, usize) {
    let mut offsets = Vec::with_capacity(radars.len());
    let mut n = 0;
    for r in radars {
        offsets.push(n);
        n += dims(r);
    }
    (offsets, n)
}

fn dims(r: &RadarSpec) -> usize {
    if r.is_3d() { 3 } else { 2 }
}

/// The estimate of every radar's bias: (b̂, P) of the joint vector, from
/// the prior and the data. A reference radar's components are held at
/// their prior mean (variance 0) and the others solved given them.
pub fn solve(
    cfg: &RegistrationConfig,
    radars: &[RadarSpec],
    state: &RegistrationState,
) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    let (offsets, n) = layout(radars);
    let mut b = DVector::zeros(n);
    let mut free = Vec::with_capacity(n);
    let mut prior_info = DVector::zeros(n);
    for (r, radar) in radars.iter().enumerate() {
        let p = cfg.prior(r);
        let means = [p.range, p.azimuth, p.elevation];
        let sigmas = [p.sigma_range, p.sigma_azimuth, p.sigma_elevation];
        for k in 0..dims(radar) {
            let i = offsets[r] + k;
            b[i] = means[k];
            if !cfg.reference.contains(&r) {
                // σ 0 is held by a prior far stronger than any data.
                let floor = if k == 0 { 1e-3 } else { 1e-6 };
                prior_info[i] = 1.0 / sigmas[k].max(floor).powi(2);
                free.push(i);
            }
        }
    }
    let m = free.len();
    let mut cov = DMatrix::zeros(n, n);
    if m == 0 {
        return Ok((b, cov));
    }
    // Λ_FF b_F = Λ₀ b₀ + η_F − Λ_FX b_X.
    let mut info = DMatrix::from_fn(m, m, |a, c| state.information[(free[a], free[c])]);
    let mut rhs = DVector::from_fn(m, |a, _| {
        let i = free[a];
        let fixed: f64 = (0..n)
            .filter(|x| !free.contains(x))
            .map(|x| state.information[(i, x)] * b[x])
            .sum();
        state.vector[i] + prior_info[i] * b[i] - fixed
    });
    for a in 0..m {
        info[(a, a)] += prior_info[free[a]];
    }
    symmetrize(&mut info);
    // Scaled to unit diagonal: ranges (m) and angles (rad) differ by 10⁵.
    let scale: Vec<f64> = (0..m).map(|a| info[(a, a)].sqrt()).collect();
    let scaled = DMatrix::from_fn(m, m, |a, c| info[(a, c)] / (scale[a] * scale[c]));
    for a in 0..m {
        rhs[a] /= scale[a];
    }
    let chol = cholesky("registration information", &scaled)?;
    let x = chol.solve(&rhs);
    let inv = chol.inverse();
    for a in 0..m {
        b[free[a]] = x[a] / scale[a];
        for c in 0..m {
            cov[(free[a], free[c])] = inv[(a, c)] / (scale[a] * scale[c]);
        }
    }
    symmetrize(&mut cov);
    Ok((b, cov))
}

/// Every radar's bias as applied, from the solved estimate; `references`:
/// cooperative reports (a bias-free reference) have reached the tracker.
pub fn applied(
    cfg: &RegistrationConfig,
    radars: &[RadarSpec],
    state: &RegistrationState,
    solved: &(DVector<f64>, DMatrix<f64>),
    references: bool,
) -> Vec<RadarBias> {
    let (offsets, _) = layout(radars);
    radars
        .iter()
        .enumerate()
        .map(|(r, radar)| {
            let p = cfg.prior(r);
            let reference = cfg.reference.contains(&r);
            let converged = cfg.enabled && !reference && state.pairs[r] >= f64::from(cfg.min_pairs);
            // Before convergence a prior the caller gave is applied (a
            // known bias, its σ added to the plots'); the default prior is
            // only the estimator's regularisation: nothing is applied.
            // The prior's σ widens the plots while the bias is unknown and
            // there is something to be biased against: another radar, or
            // cooperative reports (a lone radar's tracks are otherwise its
            // own frame, and widening its plots would only cost accuracy).
            let given = !cfg.priors.is_empty();
            let compared = radars.len() >= 2 || references;
            let mut bias = if given {
                [p.range, p.azimuth, p.elevation]
            } else {
                [0.0; 3]
            };
            let mut sigma = if reference || !given && (!cfg.enabled || !compared) {
                [0.0; 3]
            } else {
                [p.sigma_range, p.sigma_azimuth, p.sigma_elevation]
            };
            if converged {
                for k in 0..dims(radar) {
                    let i = offsets[r] + k;
                    bias[k] = solved.0[i];
                    sigma[k] = solved.1[(i, i)].max(0.0).sqrt();
                }
            }
            if !radar.is_3d() {
                bias[2] = 0.0;
                sigma[2] = 0.0;
            }
            RadarBias {
                bias,
                sigma,
                pairs: state.pairs[r],
                converged,
                reference,
            }
        })
        .collect()
}

/// The plot corrected by its radar's bias. A plot nearer its radar than
/// the range bias (a target overhead) keeps its range, and an elevation
/// that the correction would take past the vertical keeps its own: their
/// conversion would be degenerate.
pub fn correct(plot: &Plot, bias: &RadarBias) -> Plot {
    let mut p = *plot;
    let range = p.range - bias.bias[0];
    if range >= 1.0 {
        p.range = range;
    }
    p.azimuth -= bias.bias[1];
    if let Some(el) = p.elevation.as_mut() {
        let corrected = *el - bias.bias[2];
        if corrected.abs() < std::f64::consts::FRAC_PI_2 - 1e-6 {
            *el = corrected;
        }
    }
    p
}

/// The radar with the bias's variance added to its measurement variances.
pub fn inflated(radar: &RadarSpec, bias: &RadarBias) -> RadarSpec {
    let mut r = radar.clone();
    r.sigma_range = radar.sigma_range.hypot(bias.sigma[0]);
    r.sigma_azimuth = radar.sigma_azimuth.hypot(bias.sigma[1]);
    r.sigma_elevation = radar.sigma_elevation.map(|s| s.hypot(bias.sigma[2]));
    r
}

/// One pair's position and Jacobian of a plot: p(z) in the fusion frame
/// and ∂p/∂(ρ, θ(, φ)), `rows` components (2: horizontal).
fn position(radar: &RadarSpec, plot: &Plot, rows: usize) -> (DVector<f64>, DMatrix<f64>) {
    let (st, ct) = plot.azimuth.sin_cos();
    let rho = plot.range;
    match plot.elevation {
        Some(el) if radar.is_3d() => {
            let (se, ce) = el.sin_cos();
            let p = [
                radar.site[0] + rho * ce * st,
                radar.site[1] + rho * ce * ct,
                radar.site[2] + rho * se,
            ];
            let j = [
                [ce * st, rho * ce * ct, -rho * se * st],
                [ce * ct, -rho * ce * st, -rho * se * ct],
                [se, 0.0, rho * ce],
            ];
            (
                DVector::from_fn(rows, |i, _| p[i]),
                DMatrix::from_fn(rows, 3, |i, k| j[i][k]),
            )
        }
        _ => {
            let p = [radar.site[0] + rho * st, radar.site[1] + rho * ct];
            let j = [[st, rho * ct], [ct, -rho * st]];
            (
                DVector::from_fn(rows, |i, _| p[i]),
                DMatrix::from_fn(rows, 2, |i, k| j[i][k]),
            )
        }
    }
}

/// The plot's measurement covariance in (ρ, θ(, φ)).
fn polar_r(radar: &RadarSpec) -> DMatrix<f64> {
    let mut d = vec![radar.sigma_range.powi(2), radar.sigma_azimuth.powi(2)];
    if let Some(s) = radar.sigma_elevation {
        d.push(s * s);
    }
    DMatrix::from_diagonal(&DVector::from_vec(d))
}

/// A common-target pair: the newer plot (radar a, or a cooperative
/// report), the older plot (radar b), the track's velocity at the newer
/// plot's time and its covariance (per axis of the tracker's state), and
/// the motion's spectral density q.
pub struct Pair<'a> {
    /// The plot (or report) that updated the track now.
    pub newer: &'a Plot,
    /// The track's last plot of another radar before it.
    pub older: &'a Plot,
    /// The track's velocity `[ve, vn(, vu)]`.
    pub velocity: &'a [f64],
    /// Its covariance.
    pub velocity_cov: &'a DMatrix<f64>,
    /// Process noise spectral density (m²/s³) for the motion between the
    /// plots.
    pub q: f64,
    /// Whether the pair's plots are in other pairs too (serial mode: each
    /// plot is the newer of one pair and the older of the next; a parallel
    /// cluster of three radars or more): its noise covariance is then
    /// doubled, so that the σ stays honest. A cluster of two radars' plots
    /// is one pair of plots used nowhere else.
    pub shares_plots: bool,
}

/// Pairs a tracker frame learns from at most (every k-th of more). The
/// information of a few hundred pairs a frame fixes biases to metres and
/// thousandths of a degree within seconds; a thousand targets would cost
/// a thousand small solves a frame for no visible gain. The registration
/// experiment (50 targets, up to 150 pairs an instant in parallel mode)
/// stays below the bound; at 64 its 3- and 4-radar parallel σ grew from
/// 3.4 to 4.3 m.
pub const MAX_PAIRS_PER_FRAME: usize = 256;

/// χ² gate of a pair against the current estimate (probability 0.999 for
/// 2 or 3 components): a pair of two targets (a wrong association) is not
/// learned from.
const PAIR_GATE: [f64; 2] = [13.8155, 16.2662];

/// One end of a pair as the estimator sees it: the position in the fusion
/// frame, its columns in the joint bias vector with the Jacobian there
/// (none for a cooperative report: its position carries no radar bias),
/// and its noise covariance.
struct End {
    position: DVector<f64>,
    columns: Option<(usize, DMatrix<f64>)>,
    noise: DMatrix<f64>,
}

/// A pair's end from its plot, linearised about the plot corrected by the
/// current estimate b̂ (an iterated linearisation: p(z − b̂) + J (b − b̂)).
/// A report's end is its own position with its stated σ.
fn end(
    radars: &[RadarSpec],
    offsets: &[usize],
    solved: &(DVector<f64>, DMatrix<f64>),
    plot: &Plot,
    rows: usize,
) -> End {
    if let Some(rep) = &plot.report {
        let mut noise = DMatrix::from_diagonal_element(rows, rows, rep.sigma_horizontal.powi(2));
        if rows == 3 {
            noise[(2, 2)] = rep.sigma_vertical.map_or(0.0, |s| s * s);
        }
        return End {
            position: DVector::from_fn(rows, |i, _| rep.position[i]),
            columns: None,
            noise,
        };
    }
    let r = plot.radar;
    let radar = &radars[r];
    let mut bias = [0.0; 3];
    for (k, v) in bias.iter_mut().enumerate().take(dims(radar)) {
        *v = solved.0[offsets[r] + k];
    }
    let current = RadarBias {
        bias,
        sigma: [0.0; 3],
        pairs: 0.0,
        converged: true,
        reference: false,
    };
    let (position, j) = position(radar, &correct(plot, &current), rows);
    let noise = &j * polar_r(radar) * j.transpose();
    End {
        position,
        columns: Some((offsets[r], j)),
        noise,
    }
}

/// The rows a pair compares: the vertical too when both ends measure it
/// (two 3D radars, or a 3D radar and a report with a geometric height)
/// and the track has a vertical velocity.
fn pair_rows(radars: &[RadarSpec], pair: &Pair<'_>) -> usize {
    let vertical = |p: &Plot| match &p.report {
        Some(rep) => rep.sigma_vertical.is_some(),
        None => radars[p.radar].is_3d(),
    };
    if vertical(pair.newer) && vertical(pair.older) && pair.velocity.len() >= 3 {
        3
    } else {
        2
    }
}

/// Adds a pair to the state (decaying the information to the newer plot's
/// time first). Returns whether it was used (inside the gate).
///
/// A pair of two radars' plots relates their biases; a pair of a radar's
/// plot and a cooperative report of the same track (an ADS-B, MLAT or AIS
/// position, which carries no radar bias; the caller passes only reports
/// the track trusts) measures that radar's bias against a reference: the
/// same residual with the report's side of H zero and its stated σ in S.
/// One radar and reports are then enough to register it.
pub fn add_pair(
    cfg: &RegistrationConfig,
    radars: &[RadarSpec],
    state: &mut RegistrationState,
    solved: &(DVector<f64>, DMatrix<f64>),
    pair: &Pair<'_>,
) -> Result<bool, AlgoError> {
    let is_radar = |p: &Plot| p.report.is_none() && p.radar < radars.len();
    let (newer, older) = (pair.newer, pair.older);
    let usable = match (is_radar(newer), is_radar(older)) {
        (true, true) => newer.radar != older.radar,
        (true, false) => older.report.is_some(),
        (false, true) => newer.report.is_some(),
        (false, false) => false,
    };
    if !usable {
        return Ok(false);
    }
    let dt = newer.t - older.t;
    if !(0.0..=cfg.max_pair_dt).contains(&dt) {
        return Ok(false);
    }
    let rows = pair_rows(radars, pair);
    // d = p(z_a − b̂_a) − p(z_b − b̂_b) − vΔt ≈ J_a (b_a − b̂_a) − J_b (b_b −
    // b̂_b), so y = d + J_a b̂_a − J_b b̂_b = H b. About the raw plots
    // instead, the second-order terms (Δρ·Δθ across the beam: 6 m for
    // 600 m and 0.6° at 50 km) made the azimuth σ overconfident for large
    // biases.
    let (offsets, _) = layout(radars);
    let (ea, eb) = (
        end(radars, &offsets, solved, newer, rows),
        end(radars, &offsets, solved, older, rows),
    );
    let mut d = &ea.position - &eb.position;
    for i in 0..rows {
        d[i] -= pair.velocity[i] * dt;
    }
    // H = [J_a at radar a's columns, −J_b at radar b's, 0 elsewhere]: kept
    // as its non-zero columns `cols` only (≤ 6 of up to 3 × radars), so
    // every product below is over the two radars' blocks.
    let blocks: Vec<(usize, DMatrix<f64>)> = [(1.0, &ea), (-1.0, &eb)]
        .into_iter()
        .filter_map(|(sign, e)| e.columns.as_ref().map(|(o, j)| (*o, j * sign)))
        .collect();
    let cols: Vec<usize> = blocks
        .iter()
        .flat_map(|(o, j)| *o..*o + j.ncols())
        .collect();
    let m = cols.len();
    let mut h = DMatrix::zeros(rows, m);
    let mut c0 = 0;
    for (_, j) in &blocks {
        h.view_mut((0, c0), (rows, j.ncols())).copy_from(j);
        c0 += j.ncols();
    }
    let x = DVector::from_fn(m, |i, _| solved.0[cols[i]]);
    let p = DMatrix::from_fn(m, m, |i, k| solved.1[(cols[i], cols[k])]);
    let hx = &h * &x;
    d += &hx;
    let mut s = &ea.noise + &eb.noise;
    for i in 0..rows {
        for k in 0..rows {
            s[(i, k)] += pair.velocity_cov[(i, k)] * dt * dt;
        }
        s[(i, i)] += pair.q * dt.powi(3) / 3.0;
    }
    // Pairs that share plots are correlated: doubled so the σ stays
    // honest (the registration experiment's normalised errors: 0.57–0.96
    // doubled in serial mode; 0.44–0.58 in parallel mode when doubled for
    // two-radar clusters too).
    if pair.shares_plots {
        s *= 2.0;
    }
    symmetrize(&mut s);
    // Gate against the current estimate.
    let nu = &d - &hx;
    let mut g = &s + &h * &p * h.transpose();
    symmetrize(&mut g);
    let d2 = crate::gaussian::mahalanobis_sq(&nu, &g)?;
    if d2 > PAIR_GATE[rows - 2] {
        return Ok(false);
    }
    // Decay to now, then add.
    if let Some(last) = state.last_t {
        let f = (-(newer.t - last).max(0.0) / cfg.time_constant).exp();
        state.information *= f;
        state.vector *= f;
        for p in &mut state.pairs {
            *p *= f;
        }
    }
    state.last_t = Some(state.last_t.map_or(newer.t, |l| l.max(newer.t)));
    let chol = cholesky("pair covariance", &s)?;
    let si_h = chol.solve(&h);
    let information = h.transpose() * &si_h;
    let vector = si_h.transpose() * &d;
    for (i, &ci) in cols.iter().enumerate() {
        for (k, &ck) in cols.iter().enumerate() {
            state.information[(ci, ck)] += information[(i, k)];
        }
        state.vector[ci] += vector[i];
    }
    symmetrize(&mut state.information);
    for p in [newer, older] {
        if is_radar(p) {
            state.pairs[p.radar] += 1.0;
        }
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn radar(site: [f64; 3], three_d: bool) -> RadarSpec {
        RadarSpec {
            site,
            sigma_range: 30.0,
            sigma_azimuth: 0.1f64.to_radians(),
            sigma_elevation: three_d.then_some(0.1f64.to_radians()),
            sigma_radial_velocity: None,
            scan_period: 5.0,
            detection_probability: 1.0,
            clutter_density: 1e-9,
        }
    }

    /// The plot a radar with `bias` (ρ, θ) sees of a target at `p` (2D).
    fn plot_2d(r: usize, site: [f64; 3], p: [f64; 2], t: f64, bias: [f64; 2]) -> Plot {
        let (e, n) = (p[0] - site[0], p[1] - site[1]);
        Plot {
            radar: r,
            t,
            range: e.hypot(n) + bias[0],
            azimuth: e.atan2(n) + bias[1],
            elevation: None,
            radial_velocity: None,
            identity: Default::default(),
            report: None,
        }
    }

    #[test]
    fn the_position_jacobian_matches_finite_differences() {
        let r3 = radar([100.0, -50.0, 20.0], true);
        let p = Plot {
            radar: 0,
            t: 0.0,
            range: 40_000.0,
            azimuth: 0.7,
            elevation: Some(0.1),
            radial_velocity: None,
            identity: Default::default(),
            report: None,
        };
        let (_, j) = position(&r3, &p, 3);
        for k in 0..3 {
            let e = [1e-3, 1e-8, 1e-8][k];
            let shift = |s: f64| {
                let mut q = p;
                match k {
                    0 => q.range += s,
                    1 => q.azimuth += s,
                    _ => q.elevation = Some(q.elevation.unwrap() + s),
                }
                position(&r3, &q, 3).0
            };
            let numeric = (shift(e) - shift(-e)) / (2.0 * e);
            for i in 0..3 {
                assert!((j[(i, k)] - numeric[i]).abs() < 1e-5 * (1.0 + numeric[i].abs()));
            }
        }
    }

    /// Noise-free pairs of many targets seen by two 2D radars, radar 1 with
    /// a bias of +300 m and +0.3°, radar 0 the reference: the estimate is
    /// the bias (first-order model, exact data: to within a metre and
    /// 0.001°), with a small σ.
    #[test]
    fn noise_free_pairs_give_the_bias_against_a_reference() {
        let radars = [radar([0.0; 3], false), radar([40_000.0, 0.0, 0.0], false)];
        // A vague prior (10 km, 10°) so that the data decide: with the
        // default prior (150 m, 0.15°) these 60 pairs carry about 30 times
        // its azimuth information and the posterior mean sits 3 % nearer 0.
        let vague = BiasPrior {
            sigma_range: 10_000.0,
            sigma_azimuth: 10f64.to_radians(),
            ..BiasPrior::default()
        };
        let cfg = RegistrationConfig {
            reference: vec![0],
            priors: vec![vague; 2],
            ..RegistrationConfig::for_radars(2)
        };
        let mut state = RegistrationState::new(&radars);
        let bias = [300.0, 0.3f64.to_radians()];
        let v = [150.0, -80.0];
        let vc = DMatrix::identity(2, 2) * 1.0;
        for k in 0..60 {
            let a = 0.4 + 0.05 * k as f64;
            let p0 = [20_000.0 + 50_000.0 * a.sin(), 50_000.0 * a.cos()];
            let older = plot_2d(0, radars[0].site, p0, 10.0 * k as f64, [0.0, 0.0]);
            let p1 = [p0[0] + v[0] * 2.0, p0[1] + v[1] * 2.0];
            let newer = plot_2d(1, radars[1].site, p1, 10.0 * k as f64 + 2.0, bias);
            // Iterate the linearisation as the tracker does (corrected
            // plots would be nearer); here the estimate is solved before
            // each pair.
            let solved = solve(&cfg, &radars, &state).unwrap();
            let used = add_pair(
                &cfg,
                &radars,
                &mut state,
                &solved,
                &Pair {
                    newer: &newer,
                    older: &older,
                    velocity: &v,
                    velocity_cov: &vc,
                    q: 0.0,
                    shares_plots: true,
                },
            )
            .unwrap();
            assert!(used, "pair {k}");
        }
        let solved = solve(&cfg, &radars, &state).unwrap();
        let out = applied(&cfg, &radars, &state, &solved, false);
        assert!(out[0].reference && !out[0].converged);
        assert_eq!(out[0].bias, [0.0; 3]);
        let b = out[1];
        // 60 pairs 10 s apart, decayed with τ = 1800 s: Σ e^{−10k/1800} ≈ 51.
        assert!(b.converged && (b.pairs - 51.0).abs() < 1.0, "{}", b.pairs);
        // The linearisation is about the biased plot; its second-order
        // terms at 50 km: ρΔθ²/2 ≈ 0.7 m along, Δρ·Δθ ≈ 1.6 m across the
        // line of sight, i.e. 3·10⁻⁵ rad (0.002°) of azimuth.
        assert!((b.bias[0] - 300.0).abs() < 2.0, "{:?}", b.bias);
        assert!(
            (b.bias[1] - 0.3f64.to_radians()).abs() < 5e-5,
            "{:?}",
            b.bias
        );
        assert!(
            b.sigma[0] < 20.0 && b.sigma[1] < 0.05f64.to_radians(),
            "{:?}",
            b.sigma
        );
    }

    #[test]
    fn corrections_and_inflation() {
        let r = radar([0.0; 3], true);
        let b = RadarBias {
            bias: [100.0, 0.01, -0.002],
            sigma: [40.0, 0.001, 0.0],
            pairs: 30.0,
            converged: true,
            reference: false,
        };
        let p = Plot {
            radar: 0,
            t: 0.0,
            range: 10_000.0,
            azimuth: 1.0,
            elevation: Some(0.05),
            radial_velocity: None,
            identity: Default::default(),
            report: None,
        };
        let c = correct(&p, &b);
        assert_eq!((c.range, c.azimuth), (9_900.0, 0.99));
        assert!((c.elevation.unwrap() - 0.052).abs() < 1e-12);
        let i = inflated(&r, &b);
        assert!((i.sigma_range - 50.0).abs() < 1e-9); // √(30² + 40²)
        assert!((i.sigma_azimuth - (r.sigma_azimuth.powi(2) + 1e-6).sqrt()).abs() < 1e-12);
        assert_eq!(i.sigma_elevation, r.sigma_elevation);
    }

    #[test]
    fn bad_options_are_named() {
        let mut c = RegistrationConfig::for_radars(2);
        c.reference = vec![2];
        assert!(
            c.validate(2)
                .unwrap_err()
                .to_string()
                .contains("registration_reference")
        );
        c.reference = vec![0, 1];
        assert!(
            c.validate(2)
                .unwrap_err()
                .to_string()
                .contains("every radar")
        );
        c.reference = vec![];
        c.priors = vec![
            BiasPrior {
                sigma_range: -1.0,
                ..BiasPrior::default()
            };
            2
        ];
        assert!(
            c.validate(2)
                .unwrap_err()
                .to_string()
                .contains("registration_priors")
        );
        c.priors = vec![BiasPrior::default()];
        assert!(c.validate(2).is_err());
        c.priors = vec![];
        c.time_constant = 0.0;
        assert!(c.validate(2).is_err());
    }
}
