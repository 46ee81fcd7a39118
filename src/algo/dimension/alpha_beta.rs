//! Local-track filters of seed 003 §2.1: the adaptive α-β filter (tracking
//! index from a sliding-window residual variance, gains by Kalata's
//! steady-state relations — the paper's printed eq. 10 is garbled) and a
//! constant-velocity Kalman filter as the alternative.
//!
//! Both filter a vector measurement `z` of dimension m (polar `[ρ, θ]` of a
//! 2D radar, local ENU `[e, n, u]` of a 3D radar) with the interleaved state
//! `[z₁, ż₁, …, z_m, ż_m]`.

use nalgebra::{DMatrix, DVector};

use crate::algo::{AlgoError, kalman, polar::wrap_angle};

/// Tracking index used until the residual window is full.
pub const INITIAL_TRACKING_INDEX: f64 = 0.5;
/// Bounds of the adaptive α (keeps 1 − α away from 0).
pub const ALPHA_MIN: f64 = 0.05;
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
    AlphaBeta { window: usize },
    /// Constant velocity, discrete white-noise acceleration of standard
    /// deviation `sigma_a` (m/s²; divided by the range for an azimuth).
    Kalman { sigma_a: f64 },
}

/// One filtered estimate in the measurement's coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    pub t: f64,
    pub x: DVector<f64>,
    pub p: DMatrix<f64>,
    /// α of the α-β filter at this point (1 at initialisation, NaN for Kalman).
    pub alpha: f64,
}

/// Filters one track. `wrap[i]` marks angular components (residuals wrapped
/// to (−π, π]); `scale[i]` converts the Kalman σ_a into that component's
/// units. The first plot only initialises: estimates start at the second
/// (two-point initialisation, P from R as in seed 000 eq. 30).
pub fn filter(
    filter: Filter,
    times: &[f64],
    z: &[DVector<f64>],
    r: &[DMatrix<f64>],
    wrap: &[bool],
    scale: &[f64],
) -> Result<Vec<Estimate>, AlgoError> {
    let m = wrap.len();
    let n = 2 * m;
    let mut out = Vec::with_capacity(times.len().saturating_sub(1));
    if times.len() < 2 {
        return Ok(out);
    }
    let diff = |a: &DVector<f64>, b: &DVector<f64>| -> DVector<f64> {
        DVector::from_fn(m, |i, _| {
            let d = a[i] - b[i];
            if wrap[i] { wrap_angle(d) } else { d }
        })
    };
    // Two-point initialisation.
    let t0 = times[1] - times[0];
    let d0 = diff(&z[1], &z[0]);
    let mut x = DVector::from_fn(n, |k, _| {
        if k % 2 == 0 {
            z[1][k / 2]
        } else {
            d0[k / 2] / t0
        }
    });
    let mut p = kron(&r[1], [1.0, 1.0 / t0, 2.0 / (t0 * t0)]);
    out.push(Estimate {
        t: times[1],
        x: x.clone(),
        p: p.clone(),
        alpha: 1.0,
    });
    let mut window: Vec<f64> = Vec::new();
    let mut alpha = kalata_gains(INITIAL_TRACKING_INDEX)?.0;
    for k in 2..times.len() {
        let t = times[k] - times[k - 1];
        let f = transition(m, t);
        match filter {
            Filter::AlphaBeta { window: w } => {
                let xp = &f * &x;
                let zp = DVector::from_fn(m, |i, _| xp[2 * i]);
                let res = diff(&z[k], &zp);
                let chol = r[k]
                    .clone()
                    .cholesky()
                    .ok_or(AlgoError::NotPositiveDefinite {
                        what: "plot covariance",
                    })?;
                let nis = res.dot(&chol.solve(&res)) / m as f64;
                window.push(nis);
                if window.len() > w {
                    window.remove(0);
                }
                if window.len() == w {
                    // Steady state: residual variance S = σ_v² / (1 − α).
                    let s = window.iter().sum::<f64>() / w as f64;
                    alpha = (1.0 - 1.0 / s).clamp(ALPHA_MIN, ALPHA_MAX);
                }
                let (beta, _) = gains_from_alpha(alpha);
                x = DVector::from_fn(n, |j, _| {
                    let i = j / 2;
                    if j % 2 == 0 {
                        xp[j] + alpha * res[i]
                    } else {
                        xp[j] + beta / t * res[i]
                    }
                });
                p = kron(&r[k], steady_covariance(alpha, beta, t));
                out.push(Estimate {
                    t: times[k],
                    x: x.clone(),
                    p: p.clone(),
                    alpha,
                });
            }
            Filter::Kalman { sigma_a } => {
                let mut q = DMatrix::zeros(n, n);
                for i in 0..m {
                    let s2 = (sigma_a * scale[i]).powi(2);
                    q[(2 * i, 2 * i)] = s2 * t.powi(4) / 4.0;
                    q[(2 * i, 2 * i + 1)] = s2 * t.powi(3) / 2.0;
                    q[(2 * i + 1, 2 * i)] = s2 * t.powi(3) / 2.0;
                    q[(2 * i + 1, 2 * i + 1)] = s2 * t * t;
                }
                let (xp, pp) = kalman::predict(&x, &p, &f, &q)?;
                let h = DMatrix::from_fn(m, n, |i, j| if j == 2 * i { 1.0 } else { 0.0 });
                // Wrap the measurement next to the prediction.
                let zp = DVector::from_fn(m, |i, _| xp[2 * i]);
                let zk = &zp + diff(&z[k], &zp);
                let u = kalman::update_linear(&xp, &pp, &zk, &h, &r[k])?;
                x = u.x;
                p = u.p;
                out.push(Estimate {
                    t: times[k],
                    x: x.clone(),
                    p: p.clone(),
                    alpha: f64::NAN,
                });
            }
        }
    }
    Ok(out)
}

/// Constant-velocity transition for the interleaved state of `m` components.
pub fn transition(m: usize, t: f64) -> DMatrix<f64> {
    let mut f = DMatrix::identity(2 * m, 2 * m);
    for i in 0..m {
        f[(2 * i, 2 * i + 1)] = t;
    }
    f
}

/// The interleaved covariance `R ⊗ [[c₁₁, c₁₂], [c₁₂, c₂₂]]`.
fn kron(r: &DMatrix<f64>, c: [f64; 3]) -> DMatrix<f64> {
    let m = r.nrows();
    DMatrix::from_fn(2 * m, 2 * m, |a, b| {
        let k = match (a % 2, b % 2) {
            (0, 0) => c[0],
            (1, 1) => c[2],
            _ => c[1],
        };
        r[(a / 2, b / 2)] * k
    })
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
}
