//! Local-track filters of seed 003 §2.1: the adaptive α-β filter (tracking
//! index from a sliding-window residual variance, gains by Kalata's
//! steady-state relations — the paper's printed eq. 10 is garbled) and a
//! constant-velocity Kalman filter as the alternative.
//!
//! Both filter a vector measurement `z` of dimension m (polar `[ρ, θ]` of a
//! 2D radar, local ENU `[e, n, u]` of a 3D radar) with the interleaved state
//! `[z₁, ż₁, …, z_m, ż_m]`.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, SMatrix, SVector, Vector6};

use super::kernels;
use crate::motion::{cv_transition_fixed, dwna_factor};
use crate::{AlgoError, polar::wrap_angle};

/// Tracking index used until the residual window is full.
pub const INITIAL_TRACKING_INDEX: f64 = 0.5;
/// Bounds of the adaptive α (keeps 1 − α away from 0).
pub const ALPHA_MIN: f64 = 0.05;
/// Upper bound of the adaptive α.
pub const ALPHA_MAX: f64 = 0.95;

/// Kalata's steady-state gains for tracking index λ = σ_w T² / σ_v:
/// α = −(λ² + 8λ − (λ + 4)√(λ² + 8λ)) / 8, β = (λ² + 4λ − λ√(λ² + 8λ)) / 4.
pub fn kalata_gains(lambda: f64) -> Result<(f64, f64), AlgoError> {
    if !(lambda.is_finite() && lambda > 0.0) {
        return Err(AlgoError::InvalidParameter {
            what: "tracking_index",
            reason: format!("must be finite and > 0, got {lambda}"),
        });
    }
    let r = (lambda * lambda + 8.0 * lambda).sqrt();
    let alpha = -(lambda * lambda + 8.0 * lambda - (lambda + 4.0) * r) / 8.0;
    let beta = (lambda * lambda + 4.0 * lambda - lambda * r) / 4.0;
    Ok((alpha, beta))
}

/// The other Kalata relations: given α, β = 2(2 − α) − 4√(1 − α) and the
/// tracking index λ = β / √(1 − α).
pub fn gains_from_alpha(alpha: f64) -> (f64, f64) {
    let s = (1.0 - alpha).sqrt();
    let beta = 2.0 * (2.0 - alpha) - 4.0 * s;
    (beta, beta / s)
}

/// Steady-state covariance multipliers of σ_v² (Kalata):
/// P₁₁ = α, P₁₂ = β/T, P₂₂ = β(2α − β) / (2(1 − α) T²).
pub fn steady_covariance(alpha: f64, beta: f64, t: f64) -> [f64; 3] {
    [
        alpha,
        beta / t,
        beta * (2.0 * alpha - beta) / (2.0 * (1.0 - alpha) * t * t),
    ]
}

/// Which filter runs on every local track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Filter {
    /// Adaptive α-β with a residual window of `window` (3 to 5) points.
    AlphaBeta {
        /// Residual window (points).
        window: usize,
    },
    /// Constant velocity, discrete white-noise acceleration of standard
    /// deviation `sigma_a` (m/s²; divided by the range for an azimuth).
    Kalman {
        /// Standard deviation of the white-noise acceleration (m/s²).
        sigma_a: f64,
    },
}

/// One filtered estimate in the measurement's coordinates, on fixed-size
/// storage (no heap allocation per estimate): of the m measured components
/// (`dim`), `x` holds the 2m interleaved states and `p` their covariance in
/// its top-left 2m × 2m block, `acceleration` and `lag_ahead` in their
/// top-left m × m block; the rest is zero.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Time of the plot the estimate is at (s).
    pub t: f64,
    /// The measured components m (2: range and azimuth, 3: local ENU).
    pub dim: usize,
    /// The interleaved state `[z₁, ż₁, …, z_m, ż_m]` in the first 2m
    /// entries.
    pub x: Vector6<f64>,
    /// The covariance of the estimate's error for the gains actually used
    /// (see [`filter`]).
    pub p: Matrix6<f64>,
    /// α of the α-β filter at this point (1 at initialisation, NaN for Kalman).
    pub alpha: f64,
    /// The covariance (m × m, measurement units per s²) of the white
    /// acceleration the filter's model assumes from this point on: Kalman
    /// σ_a² (scaled), α-β λ² R / T⁴ for the tracking index λ of its gains.
    /// Extrapolations add it as process noise.
    pub acceleration: Matrix3<f64>,
    /// True when the residual of this point was a manoeuvre (see [`filter`]).
    pub manoeuvre: bool,
    /// The velocity-change covariance (m × m) that the next point's
    /// manoeuvre lag Δ reveals for the interval after this point, Δ/T²
    /// (zero when the next residual was within its gate): a velocity change
    /// at the start of the interval that would leave that lag by the next
    /// point. An extrapolation by dt from this point adds it (Δ (dt/T)² in
    /// position), so a sample between the start of a manoeuvre and its
    /// detection carries the lag.
    pub lag_ahead: Matrix3<f64>,
}

/// The discrete white-noise acceleration factor: the process noise of one
/// step of `t` seconds is `A ⊗ [[t⁴/4, t³/2], [t³/2, t²]]` for an
/// acceleration covariance A (the motion model's [`dwna_factor`], shared
/// with the tracker and the simulator).
pub fn white_acceleration(t: f64) -> [f64; 3] {
    dwna_factor(t)
}

/// The α-β filter's process-noise model (Kalata): the tracking index
/// λ = σ_w T² / σ_v of the gains says σ_w = λ σ_v / T² per component, so the
/// acceleration covariance is A = λ² R / T⁴.
pub fn alpha_beta_acceleration<const M: usize>(
    r: &SMatrix<f64, M, M>,
    lambda: f64,
    t: f64,
) -> SMatrix<f64, M, M> {
    r * (lambda * lambda / t.powi(4))
}

/// One step of the exact covariance of a filter with constant-velocity
/// transition and position measurements, for any gain (Joseph form):
/// P⁺ = (I − KH)(F P F' + Q)(I − KH)' + K R K'. `pp` is F P F' + Q.
pub fn joseph<const N: usize, const M: usize>(
    pp: &SMatrix<f64, N, N>,
    k: &SMatrix<f64, N, M>,
    r: &SMatrix<f64, M, M>,
) -> SMatrix<f64, N, N> {
    let a = SMatrix::<f64, N, N>::identity() - k * position_rows::<M, N>();
    let p = a * pp * a.transpose() + k * r * k.transpose();
    (p + p.transpose()) * 0.5
}

/// H: the positions of the interleaved state.
fn position_rows<const M: usize, const N: usize>() -> SMatrix<f64, M, N> {
    SMatrix::from_fn(|i, j| if j == 2 * i { 1.0 } else { 0.0 })
}

/// The α-β gain matrix `I_m ⊗ [α, β/T]'` (N × M).
pub fn alpha_beta_gain<const N: usize, const M: usize>(
    alpha: f64,
    beta: f64,
    t: f64,
) -> SMatrix<f64, N, M> {
    SMatrix::from_fn(|j, i| {
        if j / 2 != i {
            0.0
        } else if j % 2 == 0 {
            alpha
        } else {
            beta / t
        }
    })
}

/// The interleaved covariance `A ⊗ [[c₁₁, c₁₂], [c₁₂, c₂₂]]`.
fn kron<const M: usize, const N: usize>(a: &SMatrix<f64, M, M>, c: [f64; 3]) -> SMatrix<f64, N, N> {
    SMatrix::from_fn(|i, j| {
        let k = match (i % 2, j % 2) {
            (0, 0) => c[0],
            (1, 1) => c[2],
            _ => c[1],
        };
        a[(i / 2, j / 2)] * k
    })
}

/// Filters one track. `wrap[i]` marks angular components (residuals wrapped
/// to (−π, π]); `scale[i]` converts the Kalman σ_a into that component's
/// units. The first plot only initialises: estimates start at the second
/// (two-point initialisation, P from R as in seed 000 eq. 30).
///
/// Covariance. Both filters propagate P through the same prediction
/// F P F' + Q and the Joseph update with the gain actually used, so P is the
/// error covariance of the estimate whatever the gain. Q is white
/// acceleration: σ_a for Kalman, and for the α-β filter the acceleration its
/// current gains assume (Kalata's tracking index, [`alpha_beta_acceleration`];
/// with a fixed gain this recursion converges to Kalata's steady-state
/// covariance, [`steady_covariance`]).
///
/// Manoeuvres. A target that manoeuvres harder than Q says leaves a lag the
/// recursion cannot know. When a residual ν is beyond the 99 % gate of its
/// predicted covariance S (NIS n = ν'S⁻¹ν > χ²_m(0.01)), the excess
/// Δ = (1 − 1/n) ν ν' is taken as lag: the prediction's covariance gains
/// Δ ⊗ [[1, 2/T], [2/T, 4/T²]] (the position and velocity errors of a
/// constant acceleration 2ν/T² over the scan), which makes the residual
/// look like one σ along its own direction. Kalman's gain follows the
/// inflated covariance; the α-β gains stay those of the window.
pub fn filter(
    filter: Filter,
    times: &[f64],
    z: &[DVector<f64>],
    r: &[DMatrix<f64>],
    wrap: &[bool],
    scale: &[f64],
) -> Result<Vec<Estimate>, AlgoError> {
    if times.len() < 2 {
        return Ok(Vec::new());
    }
    match wrap.len() {
        1 => filter_fixed::<1, 2>(
            filter,
            times,
            |k| SVector::from_fn(|i, _| z[k][i]),
            |k| SMatrix::from_fn(|i, j| r[k][(i, j)]),
            &[wrap[0]],
            &[scale[0]],
        ),
        2 => filter_fixed::<2, 4>(
            filter,
            times,
            |k| SVector::from_fn(|i, _| z[k][i]),
            |k| SMatrix::from_fn(|i, j| r[k][(i, j)]),
            &[wrap[0], wrap[1]],
            &[scale[0], scale[1]],
        ),
        3 => filter_fixed::<3, 6>(
            filter,
            times,
            |k| SVector::from_fn(|i, _| z[k][i]),
            |k| SMatrix::from_fn(|i, j| r[k][(i, j)]),
            &[wrap[0], wrap[1], wrap[2]],
            &[scale[0], scale[1], scale[2]],
        ),
        m => Err(AlgoError::InvalidParameter {
            what: "measurement dimension",
            reason: format!("must be 1, 2 or 3, got {m}"),
        }),
    }
}

/// [`filter`] for `M` measured components and `N = 2M` states, on
/// fixed-size matrices (no heap allocation per plot); `z(k)` and `r(k)` give
/// the k-th plot's measurement and its covariance.
pub fn filter_fixed<const M: usize, const N: usize>(
    filter: Filter,
    times: &[f64],
    z: impl Fn(usize) -> SVector<f64, M>,
    r: impl Fn(usize) -> SMatrix<f64, M, M>,
    wrap: &[bool; M],
    scale: &[f64; M],
) -> Result<Vec<Estimate>, AlgoError> {
    if times.len() < 2 {
        return Ok(Vec::new());
    }
    let gate = crate::gating::chi2_threshold(M, 0.01)?;
    type V<const D: usize> = SVector<f64, D>;
    type Mx<const R: usize, const C: usize> = SMatrix<f64, R, C>;
    let diff = |a: &V<M>, b: &V<M>| -> V<M> {
        V::<M>::from_fn(|i, _| {
            let d = a[i] - b[i];
            if wrap[i] { wrap_angle(d) } else { d }
        })
    };
    let zf = z;
    let rf = r;
    let kron_f = kron::<M, N>;
    let h = position_rows::<M, N>();
    let kalman_acc = |sigma_a: f64| {
        Mx::<M, M>::from_diagonal(&V::<M>::from_fn(|i, _| (sigma_a * scale[i]).powi(2)))
    };
    // The m × m block of a 3 × 3 (zero beyond it).
    let pad3 = |a: &Mx<M, M>| Matrix3::from_fn(|i, j| if i < M && j < M { a[(i, j)] } else { 0.0 });
    let mut out = Vec::with_capacity(times.len() - 1);
    let t0 = times[1] - times[0];
    let d0 = diff(&zf(1), &zf(0));
    let z1 = zf(1);
    let mut x = V::<N>::from_fn(|k, _| {
        if k % 2 == 0 {
            z1[k / 2]
        } else {
            d0[k / 2] / t0
        }
    });
    let mut p = kron_f(&rf(1), [1.0, 1.0 / t0, 2.0 / (t0 * t0)]);
    let mut alpha = kalata_gains(INITIAL_TRACKING_INDEX)?.0;
    let acc0 = match filter {
        Filter::AlphaBeta { .. } => alpha_beta_acceleration(&rf(1), INITIAL_TRACKING_INDEX, t0),
        Filter::Kalman { sigma_a } => kalman_acc(sigma_a),
    };
    let push = |out: &mut Vec<Estimate>,
                t: f64,
                x: &V<N>,
                p: &Mx<N, N>,
                alpha: f64,
                acc: &Mx<M, M>,
                manoeuvre: bool| {
        out.push(Estimate {
            t,
            dim: M,
            x: Vector6::from_fn(|i, _| if i < N { x[i] } else { 0.0 }),
            p: Matrix6::from_fn(|i, j| if i < N && j < N { p[(i, j)] } else { 0.0 }),
            alpha,
            acceleration: pad3(acc),
            manoeuvre,
            lag_ahead: Matrix3::zeros(),
        });
    };
    push(&mut out, times[1], &x, &p, 1.0, &acc0, false);
    let mut window: Vec<f64> = Vec::new();
    for k in 2..times.len() {
        let t = times[k] - times[k - 1];
        let f = cv_transition_fixed::<N>(t);
        let rk = rf(k);
        let xp = f * x;
        let zp = V::<M>::from_fn(|i, _| xp[2 * i]);
        let res = diff(&zf(k), &zp);
        let (gain, a_used, alpha_k) = match filter {
            Filter::AlphaBeta { window: w } => {
                let solved =
                    kernels::cholesky_solve(&rk, &res).ok_or(AlgoError::NotPositiveDefinite {
                        what: "plot covariance",
                    })?;
                let nis = res.dot(&solved) / M as f64;
                window.push(nis);
                if window.len() > w {
                    window.remove(0);
                }
                if window.len() == w {
                    // Steady state: residual variance S = σ_v² / (1 − α).
                    let s = window.iter().sum::<f64>() / w as f64;
                    alpha = (1.0 - 1.0 / s).clamp(ALPHA_MIN, ALPHA_MAX);
                }
                let (beta, lambda) = gains_from_alpha(alpha);
                (
                    Some(alpha_beta_gain::<N, M>(alpha, beta, t)),
                    alpha_beta_acceleration(&rk, lambda, t),
                    alpha,
                )
            }
            Filter::Kalman { sigma_a } => (None, kalman_acc(sigma_a), f64::NAN),
        };
        let mut pp = f * p * f.transpose() + kron_f(&a_used, white_acceleration(t));
        let s = h * pp * h.transpose() + rk;
        let nis = kernels::cholesky_solve(&s, &res)
            .map(|x| res.dot(&x))
            .ok_or(AlgoError::NotPositiveDefinite {
                what: "residual covariance",
            })?;
        let manoeuvre = nis > gate;
        if manoeuvre {
            let lag = res * res.transpose() * (1.0 - 1.0 / nis);
            pp += kron_f(&lag, [1.0, 2.0 / t, 4.0 / (t * t)]);
            if let Some(prev) = out.last_mut() {
                prev.lag_ahead = pad3(&(lag / (t * t)));
            }
        }
        pp = (pp + pp.transpose()) * 0.5;
        let gain = match gain {
            Some(g) => g,
            None => {
                let s = h * pp * h.transpose() + rk;
                let inv = s.try_inverse().ok_or(AlgoError::NotPositiveDefinite {
                    what: "residual covariance",
                })?;
                pp * h.transpose() * inv
            }
        };
        x = xp + gain * res;
        p = joseph(&pp, &gain, &rk);
        push(&mut out, times[k], &x, &p, alpha_k, &a_used, manoeuvre);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kalata_gains_match_the_closed_form() {
        // λ = 1: √(1 + 8) = 3, α = −(9 − 5·3)/8 = 0.75, β = (5 − 3)/4 = 0.5.
        // λ = 0.5: √(0.25 + 4) = 2.0615528, α = −(4.25 − 4.5·2.0615528)/8
        //   = 0.6283735, β = (2.25 − 0.5·2.0615528)/4 = 0.3048059.
        // λ = 4: √(16 + 32) = 6.9282032, α = −(48 − 8·6.9282032)/8 = 0.9282032,
        //   β = (32 − 4·6.9282032)/4 = 1.0717968.
        for (lambda, a, b) in [
            (1.0, 0.75, 0.5),
            (0.5, 0.628_373_5, 0.304_805_9),
            (4.0, 0.928_203_2, 1.071_796_8),
        ] {
            let (alpha, beta) = kalata_gains(lambda).unwrap();
            assert!((alpha - a).abs() < 1e-7, "λ={lambda}: α={alpha}");
            assert!((beta - b).abs() < 1e-7, "λ={lambda}: β={beta}");
            // The inverse relations give β and λ back from α.
            let (beta2, lambda2) = gains_from_alpha(alpha);
            assert!((beta2 - beta).abs() < 1e-12);
            assert!((lambda2 - lambda).abs() < 1e-9);
        }
        assert!(kalata_gains(0.0).is_err());
        assert!(kalata_gains(f64::NAN).is_err());
    }

    #[test]
    fn joseph_recursion_with_kalata_gains_converges_to_kalata_covariance() {
        // A fixed α-β gain for tracking index λ, the white acceleration that
        // λ assumes (σ_w = λ σ_v / T²) and the Joseph recursion from a large
        // P: the limit is Kalata's closed form σ_v² [[α, β/T], [β/T,
        // β(2α − β)/(2(1 − α)T²)]] (the gain is the Kalman gain of that model).
        let (sigma_v, t) = (870.0f64, 10.0);
        let r = SMatrix::<f64, 1, 1>::new(sigma_v * sigma_v);
        for lambda in [0.1, 0.5, 1.0, 4.0] {
            let (alpha, beta) = kalata_gains(lambda).unwrap();
            let k = alpha_beta_gain::<2, 1>(alpha, beta, t);
            let q: SMatrix<f64, 2, 2> = kron(
                &alpha_beta_acceleration(&r, lambda, t),
                white_acceleration(t),
            );
            // σ_w = λ σ_v / T²: Q₂₂ = σ_w² T².
            let sw = lambda * sigma_v / (t * t);
            assert!((q[(1, 1)] - sw * sw * t * t).abs() < 1e-9 * q[(1, 1)]);
            let f = cv_transition_fixed::<2>(t);
            let mut p = SMatrix::<f64, 2, 2>::identity() * 1e8;
            for _ in 0..500 {
                p = joseph(&(f * p * f.transpose() + q), &k, &r);
            }
            let c = steady_covariance(alpha, beta, t);
            let v = sigma_v * sigma_v;
            for (got, want) in [
                (p[(0, 0)], c[0] * v),
                (p[(0, 1)], c[1] * v),
                (p[(1, 1)], c[2] * v),
            ] {
                assert!(
                    (got - want).abs() < 1e-6 * want.abs(),
                    "λ={lambda}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn joseph_with_zero_process_noise_matches_the_noise_reduction_ratio() {
        // Fixed gains, no process noise: the steady position variance is
        // σ_v² (2α² + 2β − 3αβ) / (α(4 − 2α − β)) (Benedict–Bordner / Kalata
        // noise reduction ratio), below Kalata's α σ_v² for the same gains.
        // α = 0.5, β = 0.2: (0.5 + 0.4 − 0.3)/(0.5·2.8) = 0.6/1.4 = 0.4285714.
        let (alpha, beta, t) = (0.5, 0.2, 5.0);
        let r = SMatrix::<f64, 1, 1>::new(1.0);
        let k = alpha_beta_gain::<2, 1>(alpha, beta, t);
        let f = cv_transition_fixed::<2>(t);
        let mut p = SMatrix::<f64, 2, 2>::identity() * 100.0;
        for _ in 0..2000 {
            p = joseph(&(f * p * f.transpose()), &k, &r);
        }
        assert!((p[(0, 0)] - 0.6 / 1.4).abs() < 1e-9, "{}", p[(0, 0)]);
    }

    #[test]
    fn steady_covariance_for_lambda_one() {
        // α = 0.75, β = 0.5, T = 2: P₁₁ = 0.75, P₁₂ = 0.25,
        // P₂₂ = 0.5·(1.5 − 0.5)/(2·0.25·4) = 0.25.
        let c = steady_covariance(0.75, 0.5, 2.0);
        assert_eq!(c, [0.75, 0.25, 0.25]);
    }

    #[test]
    fn alpha_beta_follows_a_straight_line_exactly() {
        // Noise-free constant velocity: residuals are zero after the two-point
        // start, so every estimate equals the truth whatever α.
        let times: Vec<f64> = (0..8).map(|k| k as f64 * 2.0).collect();
        let z: Vec<_> = times
            .iter()
            .map(|t| DVector::from_vec(vec![100.0 + 5.0 * t, -3.0 * t]))
            .collect();
        let r = vec![DMatrix::identity(2, 2) * 4.0; 8];
        let est = filter(
            Filter::AlphaBeta { window: 3 },
            &times,
            &z,
            &r,
            &[false, false],
            &[1.0, 1.0],
        )
        .unwrap();
        assert_eq!(est.len(), 7);
        for e in &est {
            assert!((e.x[0] - (100.0 + 5.0 * e.t)).abs() < 1e-9);
            assert!((e.x[1] - 5.0).abs() < 1e-9);
            assert!((e.x[3] + 3.0).abs() < 1e-9);
        }
        // Zero residuals: the window's mean NIS is 0, so α sits at its floor.
        assert_eq!(est.last().unwrap().alpha, ALPHA_MIN);
        assert!(est.iter().all(|e| !e.manoeuvre));
        let kal = filter(
            Filter::Kalman { sigma_a: 1.0 },
            &times,
            &z,
            &r,
            &[false, false],
            &[1.0, 1.0],
        )
        .unwrap();
        assert!((kal.last().unwrap().x[1] - 5.0).abs() < 1e-9);
    }

    #[test]
    fn a_residual_beyond_the_gate_inflates_the_covariance_along_it() {
        // 1D track, R = 1, T = 1, the target jumps 100 ahead at the last plot
        // (a manoeuvre no model foresaw): the NIS is far beyond χ²₁(0.01) =
        // 6.63, the prediction gains (1 − 1/n) ν² ≈ ν² and the reported
        // variance covers the lag that remains. α-β: α = 0.95 (window NIS
        // 3333), error (1 − α)·100 = 5, P = 0.05²·(ν² + …) + 0.95² ≈ 25.9,
        // σ 5.09; without the rule P ≈ 0.9 and the error would be 5.3 σ.
        let times: Vec<f64> = (0..8).map(f64::from).collect();
        let mut z: Vec<_> = times.iter().map(|&t| DVector::from_vec(vec![t])).collect();
        z[7][0] += 100.0;
        let r = vec![DMatrix::identity(1, 1); 8];
        for f in [
            Filter::AlphaBeta { window: 3 },
            Filter::Kalman { sigma_a: 0.1 },
        ] {
            let est = filter(f, &times, &z, &r, &[false], &[1.0]).unwrap();
            let last = est.last().unwrap();
            assert!(last.manoeuvre, "{f:?}");
            assert!(est[..est.len() - 1].iter().all(|e| !e.manoeuvre));
            // The truth is 107: the estimate's error over its σ stays modest.
            let err = last.x[0] - 107.0;
            assert!(
                err.abs() / last.p[(0, 0)].sqrt() < 3.0,
                "{f:?}: {err} {}",
                last.p[(0, 0)]
            );
        }
    }
}
