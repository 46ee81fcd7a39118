//! The predictor of the tracker: motion models over a variable Δt and the
//! interacting-multiple-model (IMM) predictor that mixes them (Blom and
//! Bar-Shalom 1988; Bar-Shalom, Li and Kirubarajan, *Estimation with
//! Applications to Tracking and Navigation*, §11.6.6).
//!
//! Every model works on the constant-velocity state `[x, vx, y, vy(, z,
//! vz)]`, so mixing needs no state conversion:
//! - constant velocity: F = blockdiag([[1, Δt], [0, 1]]);
//! - coordinated turn at a known rate ω in the horizontal plane
//!   (counter-clockwise for ω > 0), constant velocity vertically:
//!   x⁺ = x + (sin ωΔt / ω) vx − ((1 − cos ωΔt) / ω) vy,
//!   vx⁺ = cos ωΔt vx − sin ωΔt vy, and symmetrically for y
//!   (Bar-Shalom et al. eq. 11.7.1-4).
//!
//! The process noise of every model is per axis, CWNA or DWNA
//! ([`NoiseModel`]) with the model's σ (for a turn, the standard
//! approximation of the noise of a constant-velocity step).
//!
//! IMM prediction over Δt from mode probabilities μ_i and model states
//! (x_i, P_i), with the switching matrix π_ij(Δt) = P(model j after Δt |
//! model i) of a continuous-time Markov chain of mean sojourn times τ_i
//! ([`switching`]):
//! c_j = Σ_i π_ij μ_i, μ_{i|j} = π_ij μ_i / c_j,
//! x⁰_j = Σ_i μ_{i|j} x_i, P⁰_j = Σ_i μ_{i|j} (P_i + (x_i − x⁰_j)(x_i − x⁰_j)′),
//! then each model predicts (x⁰_j, P⁰_j) with its own F and Q, and its
//! predicted mode probability is c_j. The combined (moment-matched)
//! prediction x̄ = Σ c_j x_j, P̄ = Σ c_j (P_j + (x_j − x̄)(x_j − x̄)′) is what
//! the hypothesiser gates and associates with.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::error::AlgoError;
use crate::gaussian::moment_match_into;
use crate::motion::{cv_transition, cwna_process_noise, dwna_process_noise};
use crate::tracking::config::{Imm, MotionModel, NoiseModel};
use crate::tracking::config::{Motion, TrackerConfig};
use crate::tracking::track::{Prediction, Track, copy_matrix, copy_vector, predict};

/// A predictor (Stone Soup's `Predictor`): a track's state at another
/// time. The tracker predicts a track only when a plot may gate it, when
/// its miss is judged, or for an output.
pub(crate) trait Predictor {
    /// `track` predicted to `t` into `out` (whose buffers are reused when
    /// of the track's shapes: no allocation then), the track left as it
    /// is.
    fn predict_into(
        &mut self,
        track: &Track,
        t: f64,
        out: &mut Prediction,
    ) -> Result<(), AlgoError>;

    /// `track` predicted to `t` in place.
    fn predict(&mut self, track: &mut Track, t: f64) -> Result<(), AlgoError> {
        let mut out = Prediction::default();
        self.predict_into(track, t, &mut out)?;
        track.commit_swap(t, &mut out);
        Ok(())
    }
}

/// One constant-velocity model of the combined state, σ per axis
/// ([`NoiseModel`]): tentative tracks, and confirmed tracks without an
/// IMM.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CvPredictor {
    sigma_a: [f64; 3],
    noise: NoiseModel,
}

impl CvPredictor {
    /// The tracker's single model (`sigma_a`, `noise`).
    pub(crate) fn of(cfg: &TrackerConfig) -> Self {
        Self {
            sigma_a: cfg.sigma_a,
            noise: cfg.noise,
        }
    }
}

impl Predictor for CvPredictor {
    fn predict_into(
        &mut self,
        track: &Track,
        t: f64,
        out: &mut Prediction,
    ) -> Result<(), AlgoError> {
        let (x, p) = predict(&track.x, &track.p, t - track.t, &self.sigma_a, self.noise)?;
        out.x = x;
        out.p = p;
        out.modes.clear();
        Ok(())
    }
}

/// The IMM of the configuration's models over a track's modes, with the
/// steps built so far by Δt (a track without modes: [`CvPredictor`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ImmPredictor {
    imm: Imm,
    noise: NoiseModel,
    axes: usize,
    steps: ImmSteps,
    single: CvPredictor,
}

impl Predictor for ImmPredictor {
    fn predict_into(
        &mut self,
        track: &Track,
        t: f64,
        out: &mut Prediction,
    ) -> Result<(), AlgoError> {
        if track.modes.is_empty() {
            return self.single.predict_into(track, t, out);
        }
        copy_vector(&mut out.x, &track.x);
        copy_matrix(&mut out.p, &track.p);
        if out.modes.len() == track.modes.len() {
            for (o, m) in out.modes.iter_mut().zip(&track.modes) {
                o.probability = m.probability;
                copy_vector(&mut o.x, &m.x);
                copy_matrix(&mut o.p, &m.p);
            }
        } else {
            out.modes.clone_from(&track.modes);
        }
        let step = self
            .steps
            .get(&self.imm, self.noise, self.axes, t - track.t)?;
        predict_imm_step(step, &mut out.modes, &mut out.x, &mut out.p)
    }
}

/// The predictor of confirmed tracks the configuration names.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum TrackPredictor {
    /// One constant-velocity model.
    Single(CvPredictor),
    /// An IMM.
    Imm(ImmPredictor),
}

impl TrackPredictor {
    /// The predictor of `cfg.motion`.
    pub(crate) fn of(cfg: &TrackerConfig) -> Self {
        match &cfg.motion {
            Motion::ConstantVelocity => Self::Single(CvPredictor::of(cfg)),
            Motion::Imm(imm) => Self::Imm(ImmPredictor {
                imm: imm.clone(),
                noise: cfg.noise,
                axes: cfg.axes,
                steps: ImmSteps::default(),
                single: CvPredictor::of(cfg),
            }),
        }
    }
}

impl Predictor for TrackPredictor {
    fn predict_into(
        &mut self,
        track: &Track,
        t: f64,
        out: &mut Prediction,
    ) -> Result<(), AlgoError> {
        match self {
            Self::Single(p) => p.predict_into(track, t, out),
            Self::Imm(p) => p.predict_into(track, t, out),
        }
    }
}

/// One model's part of an IMM track: its mode probability and its state.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeState {
    /// Mode probability μ_j.
    pub probability: f64,
    /// The model-conditioned state.
    pub x: DVector<f64>,
    /// Its covariance.
    pub p: DMatrix<f64>,
}

/// Smallest mode probability held, so that a model that has not fitted for
/// a long time can come back (and mixing never divides by zero).
pub const MIN_PROBABILITY: f64 = 1e-9;

/// Per-axis process noise over `dt` with σ per axis.
pub fn process_noise(
    axes: usize,
    dt: f64,
    sigma_a: &[f64; 3],
    noise: NoiseModel,
) -> Result<DMatrix<f64>, AlgoError> {
    let mut q = DMatrix::zeros(2 * axes, 2 * axes);
    for (i, &s) in sigma_a.iter().enumerate().take(axes) {
        let block = match noise {
            NoiseModel::Dwna => dwna_process_noise(1, dt, s)?,
            NoiseModel::Cwna => cwna_process_noise(1, dt, s * s)?,
        };
        q.view_mut((2 * i, 2 * i), (2, 2)).copy_from(&block);
    }
    Ok(q)
}

/// The transition matrix of `model` over `dt` for `axes` axes.
pub fn transition(model: &MotionModel, axes: usize, dt: f64) -> Result<DMatrix<f64>, AlgoError> {
    let mut f = cv_transition(axes, dt)?;
    if let MotionModel::CoordinatedTurn { turn_rate: w, .. } = model {
        let (s, c) = (w * dt).sin_cos();
        // sin(ωΔt)/ω and (1 − cos ωΔt)/ω, written to stay exact as ωΔt → 0.
        let a = s / w;
        let b = 2.0 * (0.5 * w * dt).sin().powi(2) / w;
        // [x, vx, y, vy]
        f[(0, 1)] = a;
        f[(0, 3)] = -b;
        f[(1, 1)] = c;
        f[(1, 3)] = -s;
        f[(2, 1)] = b;
        f[(2, 3)] = a;
        f[(3, 1)] = s;
        f[(3, 3)] = c;
    }
    Ok(f)
}

/// x⁺ = F x, P⁺ = F P F′ + Q, into `x` and `p` (F′ given: the step
/// holds it; `fp` is scratch for F P). The products are nalgebra's `gemm`
/// with β = 0, which is what its `*` runs, so the result is bit for bit
/// that of `f * x0` and `f * p0 * f.transpose() + q`. F P F′ + Q of a
/// positive definite P and a positive semi-definite Q is positive
/// definite: no Cholesky check here (this runs per model, per track and
/// frame); the updates check what they produce.
fn predict_into(
    (f, ft, q): (&DMatrix<f64>, &DMatrix<f64>, &DMatrix<f64>),
    (x0, p0): (&DVector<f64>, &DMatrix<f64>),
    fp: &mut DMatrix<f64>,
    x: &mut DVector<f64>,
    p: &mut DMatrix<f64>,
) -> Result<(), AlgoError> {
    let n = f.nrows();
    if x.len() != n {
        *x = DVector::zeros(n);
    }
    if p.shape() != (n, n) {
        *p = DMatrix::zeros(n, n);
    }
    if fp.shape() != (n, n) {
        *fp = DMatrix::zeros(n, n);
    }
    x.gemm(1.0, f, x0, 0.0);
    fp.gemm(1.0, f, p0, 0.0);
    p.gemm(1.0, fp, ft, 0.0);
    *p += q;
    crate::gaussian::symmetrize(p);
    if x.iter().chain(p.iter()).any(|v| !v.is_finite()) {
        return Err(AlgoError::NonFinite {
            what: "predicted state",
        });
    }
    Ok(())
}

/// What an IMM step of length Δt needs whatever the track: the switching
/// matrix π(Δt) and each model's F and Q. Every confirmed track of a
/// frame is predicted over the same Δt (from the previous frame), so the
/// tracker builds one step per frame instead of one per track.
#[derive(Debug, Clone)]
pub struct ImmStep {
    dt: f64,
    axes: usize,
    pi: DMatrix<f64>,
    /// Per model: F, F′ and Q.
    models: Vec<(DMatrix<f64>, DMatrix<f64>, DMatrix<f64>)>,
    /// The same F and Q on the stack, for the states of 4 and 6.
    fixed: Fixed,
}

/// Per model, F and Q as fixed-size matrices.
#[derive(Debug, Clone)]
enum Fixed {
    Four(Vec<FixedModel<4>>),
    Six(Vec<FixedModel<6>>),
}

type FixedModel<const N: usize> = (SMatrix<f64, N, N>, SMatrix<f64, N, N>);

fn fixed_models<const N: usize>(
    models: &[(DMatrix<f64>, DMatrix<f64>, DMatrix<f64>)],
) -> Vec<FixedModel<N>> {
    models
        .iter()
        .map(|(f, _, q)| {
            (
                SMatrix::<f64, N, N>::from_column_slice(f.as_slice()),
                SMatrix::<f64, N, N>::from_column_slice(q.as_slice()),
            )
        })
        .collect()
}

impl ImmStep {
    /// The step of `imm` over `dt` for states of `axes` axes.
    pub fn new(imm: &Imm, noise: NoiseModel, axes: usize, dt: f64) -> Result<Self, AlgoError> {
        let models: Vec<_> = imm
            .models
            .iter()
            .map(|m| {
                let f = transition(m, axes, dt)?;
                let ft = f.transpose();
                Ok((f, ft, process_noise(axes, dt, &m.sigma_a(), noise)?))
            })
            .collect::<Result<_, AlgoError>>()?;
        let fixed = if axes == 2 {
            Fixed::Four(fixed_models::<4>(&models))
        } else {
            Fixed::Six(fixed_models::<6>(&models))
        };
        Ok(Self {
            dt,
            axes,
            pi: switching(&imm.mean_sojourn, dt),
            models,
            fixed,
        })
    }

    /// Whether this step is the one over `dt` for `axes` axes (bit for bit).
    pub fn is_for(&self, axes: usize, dt: f64) -> bool {
        self.axes == axes && self.dt.to_bits() == dt.to_bits()
    }
}

/// The IMM steps a tracker has built, by Δt: beam-timed plots give every
/// track its own Δt, but stamps of 1/128 s make the same few hundred
/// recur. At most [`ImmSteps::CAPACITY`] are kept (all dropped when full).
/// Derived data: equal whatever it holds.
#[derive(Debug, Clone, Default)]
pub struct ImmSteps {
    steps: std::collections::HashMap<(usize, u64), ImmStep>,
}

impl PartialEq for ImmSteps {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl ImmSteps {
    /// Steps kept at most.
    pub const CAPACITY: usize = 4096;

    /// The step of `imm` over `dt` for `axes` axes, built when missing.
    pub fn get(
        &mut self,
        imm: &Imm,
        noise: NoiseModel,
        axes: usize,
        dt: f64,
    ) -> Result<&ImmStep, AlgoError> {
        let key = (axes, dt.to_bits());
        if !self.steps.contains_key(&key) {
            if self.steps.len() >= Self::CAPACITY {
                self.steps.clear();
            }
            self.steps.insert(key, ImmStep::new(imm, noise, axes, dt)?);
        }
        Ok(&self.steps[&key])
    }
}

/// π(Δt) = exp(G |Δt|), row i = from, column j = to: the transition matrix
/// of the continuous-time Markov chain whose generator G leaves model i at
/// rate 1/τ_i into each other model equally (g_ii = −1/τ_i, g_ij =
/// 1/(τ_i (r − 1))). So π(Δt₁ + Δt₂) = π(Δt₁) π(Δt₂): two radars' scan
/// groups switch the modes as one step of the same total length would,
/// and a long gap tends to the chain's stationary split. Computed by
/// scaling and squaring with a Taylor series (r ≤ 8, entries ≤ 1).
pub fn switching(mean_sojourn: &[f64], dt: f64) -> DMatrix<f64> {
    let r = mean_sojourn.len();
    let dt = dt.abs();
    let mut a = DMatrix::from_fn(r, r, |i, j| {
        let rate = dt / mean_sojourn[i];
        if i == j { -rate } else { rate / (r - 1) as f64 }
    });
    // ‖A‖∞ = 2 max_i Δt/τ_i; halve until it is below 1/2.
    let norm = 2.0 * mean_sojourn.iter().map(|t| dt / t).fold(0.0, f64::max);
    let mut squarings = 0;
    let mut scaled = norm;
    while scaled > 0.5 && squarings < 64 {
        scaled /= 2.0;
        squarings += 1;
    }
    a /= 2f64.powi(squarings);
    let mut term = DMatrix::identity(r, r);
    let mut sum = DMatrix::identity(r, r);
    for k in 1..=16 {
        term = &term * &a / k as f64;
        sum += &term;
    }
    for _ in 0..squarings {
        sum = &sum * &sum;
    }
    // Rows are probabilities: clear rounding below zero and renormalise.
    for i in 0..r {
        let mut row_sum = 0.0;
        for j in 0..r {
            sum[(i, j)] = sum[(i, j)].max(0.0);
            row_sum += sum[(i, j)];
        }
        for j in 0..r {
            sum[(i, j)] /= row_sum;
        }
    }
    sum
}

/// IMM prediction of `modes` over `dt` (module documentation); returns the
/// combined prediction. The modes hold the predicted states and the
/// predicted probabilities c_j afterwards.
pub fn predict_imm(
    imm: &Imm,
    noise: NoiseModel,
    modes: &mut [ModeState],
    dt: f64,
) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    let axes = modes.first().map_or(0, |m| m.x.len() / 2);
    let (mut x, mut p) = (DVector::zeros(0), DMatrix::zeros(0, 0));
    predict_imm_step(&ImmStep::new(imm, noise, axes, dt)?, modes, &mut x, &mut p)?;
    Ok((x, p))
}

/// [`predict_imm`] with the step's matrices built already, the combined
/// estimate written into `x` and `p` (the track's, reused: this runs per
/// track and frame).
pub fn predict_imm_step(
    step: &ImmStep,
    modes: &mut [ModeState],
    x: &mut DVector<f64>,
    p: &mut DMatrix<f64>,
) -> Result<(), AlgoError> {
    let done = match &step.fixed {
        Fixed::Four(m) => predict_imm_fixed::<4>(&step.pi, m, modes, x, p)?,
        Fixed::Six(m) => predict_imm_fixed::<6>(&step.pi, m, modes, x, p)?,
    };
    if done {
        return Ok(());
    }
    predict_imm_dynamic(step, modes, x, p)
}

/// The most modes an IMM may have.
const MAX_MODES: usize = 8;

/// [`predict_imm_step`] on the stack for states of size `N` (the same
/// arithmetic as the heap version, but for the order of the sums in the
/// matrix products); `false` when the modes are not of size `N`.
fn predict_imm_fixed<const N: usize>(
    pi: &DMatrix<f64>,
    models: &[FixedModel<N>],
    modes: &mut [ModeState],
    x: &mut DVector<f64>,
    p: &mut DMatrix<f64>,
) -> Result<bool, AlgoError> {
    let r = modes.len();
    if r > MAX_MODES
        || models.len() != r
        || modes
            .iter()
            .any(|m| m.x.len() != N || m.p.shape() != (N, N))
    {
        return Ok(false);
    }
    use crate::gaussian::symmetrize_fixed as sym;
    let mut xs = [SVector::<f64, N>::zeros(); MAX_MODES];
    let mut ps = [SMatrix::<f64, N, N>::zeros(); MAX_MODES];
    // (Filled below from the modes.)
    let mut mu = [0.0; MAX_MODES];
    for (i, m) in modes.iter().enumerate() {
        xs[i] = SVector::from_column_slice(m.x.as_slice());
        ps[i] = SMatrix::from_column_slice(m.p.as_slice());
        mu[i] = m.probability;
    }
    let mut c = [0.0; MAX_MODES];
    for (j, cj) in c.iter_mut().enumerate().take(r) {
        *cj = (0..r).map(|i| pi[(i, j)] * mu[i]).sum();
    }
    // Every model mixes from the previous modes (`xs`, `ps`, read only);
    // the predictions go to `nx`, `np`.
    let mut nx = [SVector::<f64, N>::zeros(); MAX_MODES];
    let mut np = [SMatrix::<f64, N, N>::zeros(); MAX_MODES];
    for (j, mode) in modes.iter_mut().enumerate() {
        // Mixing: model j's start from every previous mode.
        let mut x0 = SVector::<f64, N>::zeros();
        for i in 0..r {
            x0.axpy(pi[(i, j)] * mu[i] / c[j], &xs[i], 1.0);
        }
        let mut p0 = SMatrix::<f64, N, N>::zeros();
        for i in 0..r {
            let w = pi[(i, j)] * mu[i] / c[j];
            let d = xs[i] - x0;
            p0 += ps[i] * w;
            p0.ger(w, &d, &d, 1.0);
        }
        sym(&mut p0);
        let (f, q) = &models[j];
        let xj = f * x0;
        let mut pj = f * p0 * f.transpose() + q;
        sym(&mut pj);
        if xj.iter().chain(pj.iter()).any(|v| !v.is_finite()) {
            return Err(AlgoError::NonFinite {
                what: "predicted state",
            });
        }
        mode.x.as_mut_slice().copy_from_slice(xj.as_slice());
        mode.p.as_mut_slice().copy_from_slice(pj.as_slice());
        mode.probability = c[j];
        nx[j] = xj;
        np[j] = pj;
    }
    // The combined (moment-matched) prediction.
    let mut xb = SVector::<f64, N>::zeros();
    for j in 0..r {
        xb.axpy(c[j], &nx[j], 1.0);
    }
    let mut pb = SMatrix::<f64, N, N>::zeros();
    for j in 0..r {
        let d = nx[j] - xb;
        pb += np[j] * c[j];
        pb.ger(c[j], &d, &d, 1.0);
    }
    sym(&mut pb);
    if x.len() != N {
        *x = DVector::zeros(N);
    }
    if p.shape() != (N, N) {
        *p = DMatrix::zeros(N, N);
    }
    x.as_mut_slice().copy_from_slice(xb.as_slice());
    p.as_mut_slice().copy_from_slice(pb.as_slice());
    Ok(true)
}

/// [`predict_imm_step`] on heap matrices (any state size).
fn predict_imm_dynamic(
    step: &ImmStep,
    modes: &mut [ModeState],
    x: &mut DVector<f64>,
    p: &mut DMatrix<f64>,
) -> Result<(), AlgoError> {
    let r = modes.len();
    let pi = &step.pi;
    let mut c = [0.0; MAX_MODES];
    let c = &mut c[..r.min(MAX_MODES)];
    if c.len() < r {
        return Err(AlgoError::InvalidParameter {
            what: "imm_models",
            reason: format!("{r} models: at most {MAX_MODES}"),
        });
    }
    for (j, cj) in c.iter_mut().enumerate() {
        *cj = (0..r).map(|i| pi[(i, j)] * modes[i].probability).sum();
    }
    // Mixing: every model's start from the previous modes, before any is
    // replaced.
    let mut mixed: Vec<(DVector<f64>, DMatrix<f64>)> = Vec::with_capacity(r);
    for (j, &cj) in c.iter().enumerate() {
        let mut x0 = DVector::zeros(0);
        let mut p0 = DMatrix::zeros(0, 0);
        moment_match_into(
            modes
                .iter()
                .enumerate()
                .map(|(i, m)| (pi[(i, j)] * m.probability / cj, &m.x, &m.p)),
            &mut x0,
            &mut p0,
        );
        mixed.push((x0, p0));
    }
    let n = mixed.first().map_or(0, |(x0, _)| x0.len());
    let mut fp = DMatrix::zeros(n, n);
    for (j, ((x0, p0), mode)) in mixed.iter().zip(modes.iter_mut()).enumerate() {
        let (f, ft, q) = &step.models[j];
        predict_into((f, ft, q), (x0, p0), &mut fp, &mut mode.x, &mut mode.p)?;
        mode.probability = c[j];
    }
    moment_match_into(modes.iter().map(|m| (m.probability, &m.x, &m.p)), x, p);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dvector;

    #[test]
    fn a_turn_rotates_the_velocity_and_tends_to_constant_velocity() {
        // A quarter turn: ω = π/20 rad/s for Δt = 10 s from (0, 0) heading
        // east at 100 m/s turns left (counter-clockwise) to heading north;
        // the centre of the circle is at (0, R), R = v/ω = 2000/π, so the
        // end point is (R, R).
        let w = std::f64::consts::PI / 20.0;
        let ct = MotionModel::CoordinatedTurn {
            turn_rate: w,
            sigma_a: [0.0; 3],
        };
        let f = transition(&ct, 2, 10.0).unwrap();
        let x = &f * dvector![0.0, 100.0, 0.0, 0.0];
        let radius = 100.0 / w;
        for (got, want) in x.iter().zip([radius, 0.0, radius, 100.0]) {
            assert!((got - want).abs() < 1e-9, "{x}");
        }
        // A tiny rate is constant velocity to rounding.
        let slow = MotionModel::CoordinatedTurn {
            turn_rate: 1e-12,
            sigma_a: [0.0; 3],
        };
        let f = transition(&slow, 3, 4.0).unwrap();
        let cv = cv_transition(3, 4.0).unwrap();
        assert!((f - cv).abs().max() < 1e-9);
    }

    #[test]
    fn switching_is_the_markov_chain_of_the_sojourn_times() {
        // Two models, rates a = 1/τ₀ (0 → 1) and b = 1/τ₁ (1 → 0): the
        // closed form π₀₀(Δt) = b/(a+b) + a/(a+b) e^{−(a+b)Δt},
        // π₁₁ = a/(a+b) + b/(a+b) e^{−(a+b)Δt}.
        let (t0, t1) = (60.0, 20.0);
        let (a, b) = (1.0 / t0, 1.0 / t1);
        for dt in [0.0, 0.5, 4.0, 30.0, 1e4] {
            let pi = switching(&[t0, t1], dt);
            let e = (-(a + b) * dt).exp();
            assert!(
                (pi[(0, 0)] - (b / (a + b) + a / (a + b) * e)).abs() < 1e-13,
                "{dt}"
            );
            assert!(
                (pi[(1, 1)] - (a / (a + b) + b / (a + b) * e)).abs() < 1e-13,
                "{dt}"
            );
        }
        // Three models: rows are probabilities, steps compose, and a long
        // gap tends to the stationary split (∝ τ_i for equal shares).
        let taus = [60.0, 20.0, 20.0];
        let (p1, p2) = (switching(&taus, 3.0), switching(&taus, 6.0));
        assert!((&p1 * &p1 - &p2).abs().max() < 1e-13);
        for i in 0..3 {
            let row: f64 = (0..3).map(|j| p2[(i, j)]).sum();
            assert!((row - 1.0).abs() < 1e-15);
        }
        let far = switching(&taus, 1e5);
        for i in 0..3 {
            assert!((far[(i, 0)] - 0.6).abs() < 1e-9);
            assert!((far[(i, 1)] - 0.2).abs() < 1e-9);
        }
        assert_eq!(switching(&taus, 0.0), DMatrix::identity(3, 3));
    }

    #[test]
    fn mixing_by_hand() {
        // 1D-like check on a 2-axis state, two CV models with no noise and
        // Δt = 0 (no motion): π = I, so mixing leaves each model alone and
        // the combination is the moment match: μ = (0.25, 0.75),
        // x₀ = 0, x₁ = 4 (first component) → x̄ = 3,
        // P̄₀₀ = 0.25 (1 + 9) + 0.75 (1 + 1) = 4.
        let imm = Imm {
            models: vec![
                MotionModel::ConstantVelocity { sigma_a: [0.0; 3] },
                MotionModel::ConstantVelocity { sigma_a: [0.0; 3] },
            ],
            mean_sojourn: vec![10.0, 10.0],
            initial_probabilities: vec![0.5, 0.5],
        };
        let mut modes = vec![
            ModeState {
                probability: 0.25,
                x: dvector![0.0, 0.0, 0.0, 0.0],
                p: DMatrix::identity(4, 4),
            },
            ModeState {
                probability: 0.75,
                x: dvector![4.0, 0.0, 0.0, 0.0],
                p: DMatrix::identity(4, 4),
            },
        ];
        let (x, p) = predict_imm(&imm, NoiseModel::Cwna, &mut modes, 0.0).unwrap();
        assert_eq!(x[0], 3.0);
        assert_eq!(p[(0, 0)], 4.0);
        assert_eq!(p[(1, 1)], 1.0);
        assert_eq!(modes[1].x[0], 4.0);
        // Δt → ∞ with equal sojourns: π_ij → 1/2 (the stationary split), so
        // both models mix to the same x⁰ = Σ μ_i x_i = 3.
        let (_, _) = predict_imm(&imm, NoiseModel::Cwna, &mut modes, 1e6).unwrap();
        assert!((modes[0].x[0] - modes[1].x[0]).abs() < 1e-9);
        assert!((modes[0].probability - 0.5).abs() < 1e-9);
    }

    #[test]
    fn the_stack_prediction_is_the_heap_prediction_to_rounding() {
        // Four models of the aircraft IMM, 2 and 3 axes, modes apart and
        // correlated: the fixed-size path equals the heap path (the same
        // arithmetic, sums in another order) to 1e-12 relative.
        let imm = Imm::aircraft();
        for axes in [2, 3] {
            let n = 2 * axes;
            let modes: Vec<ModeState> = (0..4)
                .map(|j| {
                    let x = DVector::from_fn(n, |i, _| 1000.0 * (i as f64 + 1.0) + 37.0 * j as f64);
                    let a = DMatrix::from_fn(n, n, |i, k| ((i * 7 + k * 3 + j) % 5) as f64 + 0.5);
                    let p = &a * a.transpose() + DMatrix::identity(n, n) * 10.0;
                    ModeState {
                        probability: [0.55, 0.2, 0.15, 0.1][j],
                        x,
                        p,
                    }
                })
                .collect();
            for dt in [0.0078125, 1.3, 4.0] {
                let step = ImmStep::new(&imm, NoiseModel::Cwna, axes, dt).unwrap();
                let (mut a, mut b) = (modes.clone(), modes.clone());
                let (mut xa, mut pa) = (DVector::zeros(0), DMatrix::zeros(0, 0));
                let (mut xb, mut pb) = (DVector::zeros(0), DMatrix::zeros(0, 0));
                predict_imm_step(&step, &mut a, &mut xa, &mut pa).unwrap();
                predict_imm_dynamic(&step, &mut b, &mut xb, &mut pb).unwrap();
                let close = |u: &[f64], v: &[f64]| {
                    u.iter()
                        .zip(v)
                        .all(|(p, q)| (p - q).abs() <= 1e-12 * p.abs().max(q.abs()).max(1.0))
                };
                assert!(close(xa.as_slice(), xb.as_slice()) && close(pa.as_slice(), pb.as_slice()));
                for (ma, mb) in a.iter().zip(&b) {
                    assert!(close(ma.x.as_slice(), mb.x.as_slice()));
                    assert!(close(ma.p.as_slice(), mb.p.as_slice()));
                    assert!((ma.probability - mb.probability).abs() < 1e-15);
                }
            }
        }
    }
}
