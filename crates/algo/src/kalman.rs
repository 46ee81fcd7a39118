//! Kalman filter predict and update steps, without hidden state.
//!
//! Following adskalman-rs and Stone Soup, the state `x` and covariance `P`
//! are passed in and returned. The covariance update uses the Joseph form
//! `P⁺ = (I − K H) P (I − K H)' + K R K'`, which keeps `P⁺` symmetric positive
//! definite under rounding and for any gain. The gain is obtained by a
//! Cholesky solve with the innovation covariance `S`, never by inverting it.
//! These are the filter equations behind the local tracks of seed 000
//! (He You et al., double-threshold track correlation, eqs. 13 and 24–27).
//! An extended Kalman update handles radar plots in polar coordinates.

use nalgebra::{DMatrix, DVector};

use crate::error::{AlgoError, check_matrix, check_vector, finite_slice};
use crate::gaussian::{
    check_covariance, check_symmetric, cholesky, mahalanobis_sq_chol, symmetrize,
};
use crate::polar::{PolarMeasurement, polar_measurement_model, wrap_angle};

/// Result of a measurement update.
#[derive(Debug, Clone, PartialEq)]
pub struct Update {
    /// Updated state x⁺ = x + K ν.
    pub x: DVector<f64>,
    /// Updated covariance (Joseph form), symmetric positive definite.
    pub p: DMatrix<f64>,
    /// Innovation ν = z − h(x) (azimuth component wrapped into (−π, π]).
    pub innovation: DVector<f64>,
    /// Innovation covariance S = H P H' + R.
    pub s: DMatrix<f64>,
    /// Kalman gain K = P H' S⁻¹.
    pub gain: DMatrix<f64>,
    /// Normalised innovation squared ν' S⁻¹ ν (χ² with dim z degrees of freedom).
    pub nis: f64,
    /// ln det S, from the Cholesky factor of S (for the likelihood
    /// ln N(ν; 0, S) = −½ (ln det S + m ln 2π + `nis`)).
    pub ln_det_s: f64,
}

/// Where the position components live in a state vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PositionLayout {
    /// Index of east.
    pub x: usize,
    /// Index of north.
    pub y: usize,
    /// Index of up, if the state has a height.
    pub z: Option<usize>,
}

impl PositionLayout {
    /// The 2D constant-velocity layout `[x, vx, y, vy]`.
    pub const CV_2D: Self = Self {
        x: 0,
        y: 2,
        z: None,
    };
    /// The 3D constant-velocity layout `[x, vx, y, vy, z, vz]`.
    pub const CV_3D: Self = Self {
        x: 0,
        y: 2,
        z: Some(4),
    };

    /// Checks that the indices are distinct and inside a state of length `n`.
    pub fn validate(&self, n: usize) -> Result<(), AlgoError> {
        let idx = [Some(self.x), Some(self.y), self.z];
        let out = idx.iter().flatten().any(|&i| i >= n);
        let dup = self.x == self.y || self.z == Some(self.x) || self.z == Some(self.y);
        if out || dup {
            return Err(AlgoError::InvalidParameter {
                what: "layout",
                reason: format!("indices {idx:?} must be distinct and < state dimension {n}"),
            });
        }
        Ok(())
    }
}

/// Prediction x⁺ = F x, P⁺ = F P F' + Q (seed 000 eq. 13 middle factor, with
/// Q already mapped into the state space, e.g. `G Q G'`).
///
/// `P` must be symmetric positive definite, `Q` symmetric (it may be only
/// positive semi-definite). The returned covariance is symmetrized and checked
/// to be positive definite.
pub fn predict(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    f: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    let n = x.len();
    check_vector("state", x, n)?;
    check_matrix("covariance", p, n, n)?;
    check_covariance("covariance", p)?;
    check_matrix("transition matrix", f, n, n)?;
    check_matrix("process noise", q, n, n)?;
    check_symmetric("process noise", q)?;
    let x_pred = f * x;
    finite_slice("predicted state", x_pred.as_slice())?;
    let mut p_pred = f * p * f.transpose() + q;
    symmetrize(&mut p_pred);
    check_covariance("predicted covariance", &p_pred)?;
    Ok((x_pred, p_pred))
}

/// Linear update with measurement `z = H x + w`, `w ~ N(0, R)`:
/// ν = z − H x, S = H P H' + R, K = P H' S⁻¹ (Cholesky solve),
/// x⁺ = x + K ν, P⁺ = (I − K H) P (I − K H)' + K R K' (Joseph form).
/// The position measurement of seed 000 uses H of eq. 25 and R of eq. 27.
pub fn update_linear(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    z: &DVector<f64>,
    h: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<Update, AlgoError> {
    let n = x.len();
    let m = z.len();
    check_vector("state", x, n)?;
    check_matrix("covariance", p, n, n)?;
    check_covariance("covariance", p)?;
    check_vector("measurement", z, m)?;
    check_matrix("measurement matrix", h, m, n)?;
    check_matrix("measurement covariance", r, m, m)?;
    check_covariance("measurement covariance", r)?;
    let innovation = z - h * x;
    update_with_innovation(x, p, innovation, h, r, true)
}

/// Kalman update with a linearised measurement given by its innovation
/// ν = z − h(x) and Jacobian H (an EKF step): S = H P H′ + R, K = P H′ S⁻¹,
/// x⁺ = x + K ν, P⁺ in Joseph form; every input and output checked as in
/// [`update_linear`].
pub fn update_linearised(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    innovation: DVector<f64>,
    h: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<Update, AlgoError> {
    let n = x.len();
    let m = innovation.len();
    check_vector("state", x, n)?;
    check_matrix("covariance", p, n, n)?;
    check_covariance("covariance", p)?;
    check_matrix("measurement matrix", h, m, n)?;
    check_matrix("measurement covariance", r, m, m)?;
    check_covariance("measurement covariance", r)?;
    update_with_innovation(x, p, innovation, h, r, true)
}

/// Extended Kalman update with a radar plot in polar coordinates from a
/// radar at local ENU position `site` (m).
///
/// The measurement model is `h(x) = [r, az]` or, with elevation,
/// `[r, az, el]`, evaluated at the target position relative to the site,
/// `rel = (x[layout.x] − site[0], x[layout.y] − site[1], x[layout.z] − site[2])`.
/// For a 2D plot (no elevation) and a state with a height (`layout.z` given)
/// the range is the slant range from the site; for a state without height the
/// range is horizontal and `site[2]` is ignored. A 3D plot requires
/// `layout.z`. The Jacobian is that of
/// [`polar_measurement_model`]; the azimuth innovation is wrapped into
/// (−π, π]; R = diag(σ_ρ², σ_θ²(, σ_el²)).
///
/// Fails with [`AlgoError::DegenerateGeometry`] when the predicted target is
/// at the site or straight above it.
pub fn update_polar(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    meas: &PolarMeasurement,
    layout: PositionLayout,
    site: [f64; 3],
) -> Result<Update, AlgoError> {
    polar(x, p, meas, layout, site, true)
}

/// [`update_polar`] or, with `range_rate` = (ṙ, σ_ṙ),
/// [`update_polar_doppler`], for a filter whose own covariances are
/// symmetric positive definite by construction (a tracker's states): the
/// Cholesky checks of P and of the Joseph-form P⁺ are skipped (every other
/// check stays, and a non-positive-definite S is still an error).
pub fn update_polar_trusted(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    meas: &PolarMeasurement,
    range_rate: Option<(f64, f64)>,
    layout: PositionLayout,
    site: [f64; 3],
) -> Result<Update, AlgoError> {
    match range_rate {
        Some((v, sigma)) => polar_doppler(x, p, meas, v, sigma, layout, site, false),
        None => polar(x, p, meas, layout, site, false),
    }
}

fn polar(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    meas: &PolarMeasurement,
    layout: PositionLayout,
    site: [f64; 3],
    checked: bool,
) -> Result<Update, AlgoError> {
    let n = x.len();
    let (rel, with_elevation) = polar_inputs(x, p, meas, layout, site, checked)?;
    let (h_pred, j) = polar_measurement_model(rel, with_elevation)?;
    let m = h_pred.len();
    let mut h = DMatrix::zeros(m, n);
    let cols = [Some(layout.x), Some(layout.y), layout.z];
    for (k, col) in cols.iter().enumerate() {
        if let Some(c) = col {
            h.set_column(*c, &j.column(k));
        }
    }
    let mut innovation = meas.vector() - h_pred;
    innovation[1] = wrap_angle(innovation[1]);
    update_with_innovation(x, p, innovation, &h, &meas.noise_covariance(), checked)
}

/// The checks of a polar update's inputs, and the target's position
/// relative to the site with whether the plot has an elevation.
fn polar_inputs(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    meas: &PolarMeasurement,
    layout: PositionLayout,
    site: [f64; 3],
    checked: bool,
) -> Result<([f64; 3], bool), AlgoError> {
    let n = x.len();
    check_vector("state", x, n)?;
    check_matrix("covariance", p, n, n)?;
    if checked {
        check_covariance("covariance", p)?;
    }
    layout.validate(n)?;
    meas.validate()?;
    finite_slice("site", &site)?;
    let with_elevation = meas.elevation.is_some();
    if with_elevation && layout.z.is_none() {
        return Err(AlgoError::InvalidParameter {
            what: "layout",
            reason: "a measurement with elevation needs a state with a height (layout.z)"
                .to_owned(),
        });
    }
    let rel = [
        x[layout.x] - site[0],
        x[layout.y] - site[1],
        layout.z.map_or(0.0, |k| x[k] - site[2]),
    ];
    Ok((rel, with_elevation))
}

/// [`update_polar`] with the plot's range rate as a further measurement
/// (a Doppler radar): z = [r, az(, el), ṙ] with ṙ = (p − s)·v / r, the
/// velocity v of each position component being the state component after
/// it (the interleaved layout `[x, vx, y, vy(, z, vz)]`). The range rate's
/// Jacobian is ∂ṙ/∂p = v/r − ṙ (p − s)/r², ∂ṙ/∂v = (p − s)/r, over the
/// same components as the range (horizontal for a layout without height);
/// R = diag(σ_ρ², σ_θ²(, σ_el²), σ_ṙ²).
pub fn update_polar_doppler(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    meas: &PolarMeasurement,
    range_rate: f64,
    sigma_range_rate: f64,
    layout: PositionLayout,
    site: [f64; 3],
) -> Result<Update, AlgoError> {
    polar_doppler(x, p, meas, range_rate, sigma_range_rate, layout, site, true)
}

#[allow(clippy::too_many_arguments)]
fn polar_doppler(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    meas: &PolarMeasurement,
    range_rate: f64,
    sigma_range_rate: f64,
    layout: PositionLayout,
    site: [f64; 3],
    checked: bool,
) -> Result<Update, AlgoError> {
    let n = x.len();
    let (rel, with_elevation) = polar_inputs(x, p, meas, layout, site, checked)?;
    if !range_rate.is_finite() {
        return Err(AlgoError::NonFinite { what: "range rate" });
    }
    if !(sigma_range_rate.is_finite() && sigma_range_rate > 0.0) {
        return Err(AlgoError::InvalidParameter {
            what: "sigma_range_rate",
            reason: format!("must be finite and > 0, got {sigma_range_rate}"),
        });
    }
    let cols = [Some(layout.x), Some(layout.y), layout.z];
    if cols.iter().flatten().any(|&c| c + 1 >= n) {
        return Err(AlgoError::InvalidParameter {
            what: "layout",
            reason: "each position needs its velocity after it".to_owned(),
        });
    }
    let vel = [
        x[layout.x + 1],
        x[layout.y + 1],
        layout.z.map_or(0.0, |k| x[k + 1]),
    ];
    let (h_pos, j) = polar_measurement_model(rel, with_elevation)?;
    let m = h_pos.len();
    let r = h_pos[0];
    let rdot = (0..3).map(|k| rel[k] * vel[k]).sum::<f64>() / r;
    let mut h = DMatrix::zeros(m + 1, n);
    for (k, col) in cols.iter().enumerate() {
        if let Some(c) = col {
            for row in 0..m {
                h[(row, *c)] = j[(row, k)];
            }
            h[(m, *c)] = vel[k] / r - rdot * rel[k] / (r * r);
            h[(m, c + 1)] = rel[k] / r;
        }
    }
    let mut z = meas.vector().iter().copied().collect::<Vec<_>>();
    z.push(range_rate);
    let mut innovation = DVector::from_vec(z);
    for row in 0..m {
        innovation[row] -= h_pos[row];
    }
    innovation[m] -= rdot;
    innovation[1] = wrap_angle(innovation[1]);
    let mut noise = vec![0.0; m + 1];
    let rp = meas.noise_covariance();
    for k in 0..m {
        noise[k] = rp[(k, k)];
    }
    noise[m] = sigma_range_rate * sigma_range_rate;
    let r = DMatrix::from_diagonal(&DVector::from_vec(noise));
    update_with_innovation(x, p, innovation, &h, &r, checked)
}

/// The shared update once ν, H (or its Jacobian) and R are known and valid.
fn update_with_innovation(
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    innovation: DVector<f64>,
    h: &DMatrix<f64>,
    r: &DMatrix<f64>,
    checked: bool,
) -> Result<Update, AlgoError> {
    finite_slice("innovation", innovation.as_slice())?;
    let n = x.len();
    let hp = h * p;
    let mut s = &hp * h.transpose() + r;
    symmetrize(&mut s);
    let chol = cholesky("innovation covariance", &s)?;
    // K = P H' S⁻¹  ⇔  S K' = H P (S and P symmetric).
    let gain = chol.solve(&hp).transpose();
    finite_slice("kalman gain", gain.as_slice())?;
    let x_new = x + &gain * &innovation;
    let i_kh = DMatrix::identity(n, n) - &gain * h;
    let mut p_new = &i_kh * p * i_kh.transpose() + &gain * r * gain.transpose();
    symmetrize(&mut p_new);
    finite_slice("updated state", x_new.as_slice())?;
    if checked {
        check_covariance("updated covariance", &p_new)?;
    } else {
        finite_slice("updated covariance", p_new.as_slice())?;
    }
    let nis = mahalanobis_sq_chol(&innovation, &chol)?;
    let ln_det_s = chol.l().diagonal().iter().map(|v| 2.0 * v.ln()).sum();
    Ok(Update {
        x: x_new,
        p: p_new,
        innovation,
        s,
        gain,
        nis,
        ln_det_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{dmatrix, dvector};
    use proptest::prelude::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn the_range_rate_jacobian_matches_finite_differences_and_the_update_uses_it() {
        // 3D state [x, vx, y, vy, z, vz] 30 km east, 40 km north, 8 km up
        // from a radar at (100, −50, 20), flying at (−120, 80, 5) m/s.
        let x = dvector![30_000.0, -120.0, 40_000.0, 80.0, 8000.0, 5.0];
        let site = [100.0, -50.0, 20.0];
        let rdot = |x: &DVector<f64>| {
            let rel = [x[0] - site[0], x[2] - site[1], x[4] - site[2]];
            let v = [x[1], x[3], x[5]];
            let r = (rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]).sqrt();
            (rel[0] * v[0] + rel[1] * v[1] + rel[2] * v[2]) / r
        };
        let p = DMatrix::from_diagonal(&dvector![1e4, 100.0, 1e4, 100.0, 1e4, 100.0]);
        let meas = PolarMeasurement {
            range: 50_000.0,
            azimuth: 0.64,
            elevation: Some(0.16),
            sigma_range: 50.0,
            sigma_azimuth: 0.002,
            sigma_elevation: Some(0.003),
        };
        let u = update_polar_doppler(
            &x,
            &p,
            &meas,
            rdot(&x) + 2.0,
            1.0,
            PositionLayout::CV_3D,
            site,
        )
        .unwrap();
        // The innovation of the range rate is the 2 m/s added.
        assert!((u.innovation[3] - 2.0).abs() < 1e-9);
        // K = P H' S⁻¹, so H = recovered from S − R = H P H' is not unique;
        // check H's last row by finite differences through S instead:
        // S_33 − σ² = Σ_k h_k² P_kk for a diagonal P.
        let mut h = [0.0; 6];
        for (k, hk) in h.iter_mut().enumerate() {
            let d = if k % 2 == 0 { 1e-3 } else { 1e-4 };
            let mut xp = x.clone();
            xp[k] += d;
            let mut xm = x.clone();
            xm[k] -= d;
            *hk = (rdot(&xp) - rdot(&xm)) / (2.0 * d);
        }
        let s33: f64 = (0..6).map(|k| h[k] * h[k] * p[(k, k)]).sum::<f64>() + 1.0;
        assert!(
            (u.s[(3, 3)] - s33).abs() < 1e-6 * s33,
            "{} vs {s33}",
            u.s[(3, 3)]
        );
        // The velocity moved towards the measured range rate.
        assert!(rdot(&u.x) > rdot(&x) + 0.5);
        // Without height (2D layout) the range rate is horizontal.
        let x2 = dvector![30_000.0, -120.0, 40_000.0, 80.0];
        let p2 = DMatrix::from_diagonal(&dvector![1e4, 100.0, 1e4, 100.0]);
        let m2 = PolarMeasurement {
            elevation: None,
            sigma_elevation: None,
            ..meas
        };
        let want = ((30_000.0 - 100.0) * -120.0 + (40_000.0 + 50.0) * 80.0)
            / (29_900.0f64).hypot(40_050.0);
        let u2 =
            update_polar_doppler(&x2, &p2, &m2, want, 1.0, PositionLayout::CV_2D, site).unwrap();
        assert!(u2.innovation[2].abs() < 1e-9);
        // The trusted path skips only the Cholesky checks of P and P⁺: the
        // same bits on valid inputs.
        let t2 = update_polar_trusted(
            &x2,
            &p2,
            &m2,
            Some((want, 1.0)),
            PositionLayout::CV_2D,
            site,
        )
        .unwrap();
        assert_eq!((t2.x, t2.p), (u2.x, u2.p));
        let plain = update_polar(&x, &p, &meas, PositionLayout::CV_3D, site).unwrap();
        let trusted =
            update_polar_trusted(&x, &p, &meas, None, PositionLayout::CV_3D, site).unwrap();
        assert_eq!(
            (trusted.x, trusted.p, trusted.ln_det_s),
            (plain.x, plain.p, plain.ln_det_s)
        );
    }

    #[test]
    fn predict_by_hand() {
        // F = [[1, 4], [0, 1]] (T = 4 s), P = I, Q = diag(0, 1), x = [10, 2]:
        // F x = [10 + 8, 2] = [18, 2];
        // F P F' = F F' = [[1 + 16, 4], [4, 1]] = [[17, 4], [4, 1]], + Q → [[17, 4], [4, 2]].
        let f = dmatrix![1.0, 4.0; 0.0, 1.0];
        let (x, p) = predict(
            &dvector![10.0, 2.0],
            &DMatrix::identity(2, 2),
            &f,
            &dmatrix![0.0, 0.0; 0.0, 1.0],
        )
        .unwrap();
        assert_eq!(x, dvector![18.0, 2.0]);
        assert_eq!(p, dmatrix![17.0, 4.0; 4.0, 2.0]);
    }

    #[test]
    fn predict_rejects_bad_inputs() {
        let i2 = DMatrix::<f64>::identity(2, 2);
        let x = dvector![0.0, 0.0];
        assert!(matches!(
            predict(&dvector![0.0], &i2, &i2, &i2),
            Err(AlgoError::DimensionMismatch { .. })
        ));
        assert!(matches!(
            predict(&x, &dmatrix![1.0, 0.0; 0.0, -1.0], &i2, &i2),
            Err(AlgoError::NotPositiveDefinite { what: "covariance" })
        ));
        assert!(matches!(
            predict(&x, &i2, &dmatrix![1.0, f64::NAN; 0.0, 1.0], &i2),
            Err(AlgoError::NonFinite { .. })
        ));
        assert!(matches!(
            predict(&x, &i2, &i2, &dmatrix![1.0, 1.0; 0.0, 1.0]),
            Err(AlgoError::NotSymmetric { .. })
        ));
        // Singular F and no noise: predicted covariance singular.
        assert!(matches!(
            predict(&x, &i2, &DMatrix::zeros(2, 2), &DMatrix::zeros(2, 2)),
            Err(AlgoError::NotPositiveDefinite {
                what: "predicted covariance"
            })
        ));
    }

    #[test]
    fn scalar_update_by_hand() {
        // x = 0, P = 4, z = 2, H = 1, R = 1:
        // S = 4 + 1 = 5, K = 4/5 = 0.8, x⁺ = 0.8 · 2 = 1.6,
        // P⁺ = (1 − 0.8)² · 4 + 0.8² · 1 = 0.16 + 0.64 = 0.8, NIS = 2²/5 = 0.8.
        let u = update_linear(
            &dvector![0.0],
            &dmatrix![4.0],
            &dvector![2.0],
            &dmatrix![1.0],
            &dmatrix![1.0],
        )
        .unwrap();
        assert!(close(u.x[0], 1.6, 1e-15));
        assert!(close(u.p[(0, 0)], 0.8, 1e-15));
        assert!(close(u.s[(0, 0)], 5.0, 0.0));
        assert!(close(u.gain[(0, 0)], 0.8, 1e-15));
        assert!(close(u.nis, 0.8, 1e-15));
        assert_eq!(u.innovation, dvector![2.0]);
    }

    #[test]
    fn two_state_update_by_hand() {
        // x = [0, 1], P = [[4, 2], [2, 3]], H = [1, 0], R = 1, z = 2:
        // ν = 2, S = 4 + 1 = 5, K = P H'/S = [4, 2]/5 = [0.8, 0.4],
        // x⁺ = [0 + 1.6, 1 + 0.8] = [1.6, 1.8],
        // P⁺ = P − K S K' = [[4 − 3.2, 2 − 1.6], [2 − 1.6, 3 − 0.8]] = [[0.8, 0.4], [0.4, 2.2]].
        let u = update_linear(
            &dvector![0.0, 1.0],
            &dmatrix![4.0, 2.0; 2.0, 3.0],
            &dvector![2.0],
            &dmatrix![1.0, 0.0],
            &dmatrix![1.0],
        )
        .unwrap();
        assert!((u.x - dvector![1.6, 1.8]).amax() < 1e-15);
        assert!((u.p - dmatrix![0.8, 0.4; 0.4, 2.2]).amax() < 1e-14);
        assert!((u.gain - dmatrix![0.8; 0.4]).amax() < 1e-15);
    }

    #[test]
    fn update_rejects_bad_inputs() {
        let x = dvector![0.0, 0.0];
        let p = DMatrix::<f64>::identity(2, 2);
        let h = dmatrix![1.0, 0.0];
        assert!(matches!(
            update_linear(&x, &p, &dvector![1.0], &h, &dmatrix![0.0]),
            Err(AlgoError::NotPositiveDefinite {
                what: "measurement covariance"
            })
        ));
        assert!(matches!(
            update_linear(&x, &p, &dvector![1.0, 2.0], &h, &dmatrix![1.0]),
            Err(AlgoError::DimensionMismatch { .. })
        ));
        assert!(update_linear(&x, &p, &dvector![f64::NAN], &h, &dmatrix![1.0]).is_err());
    }

    fn cv2_target_north() -> (DVector<f64>, DMatrix<f64>) {
        // Target 10 km due north of the radar, at rest; σ = 100 m per position, 10 m/s per velocity.
        let x = dvector![0.0, 0.0, 10_000.0, 0.0];
        let p = DMatrix::from_diagonal(&dvector![1e4, 100.0, 1e4, 100.0]);
        (x, p)
    }

    /// Target due north at 10 km; plot at the predicted range and azimuth 0.01 rad.
    /// At (e, n) = (0, 10⁴): ∂r/∂(e, n) = (0, 1), ∂az/∂(e, n) = (n/ρ², −e/ρ²) = (1e-4, 0),
    /// so H = [[0, 0, 1, 0], [1e-4, 0, 0, 0]], ν = [0, 0.01].
    /// σ_ρ = 10 m, σ_θ = 1e-3 rad: S = diag(1e4 + 100, 1e-8·1e4 + 1e-6) = diag(10100, 1.01e-4).
    /// K column 2 = P H'[:,2]/S_22 = [1e-4 · 1e4, 0, 0, 0]/1.01e-4 = [1/1.01e-4, 0, 0, 0],
    /// Δx = 0.01/1.01e-4 = 10000/101 ≈ 99.0099 m east; north unchanged.
    /// P_xx⁺ = 1e4 − (1e4·1e-4)²/1.01e-4 = 1e4 − 1e4/1.01 = 1e4/101;
    /// P_yy⁺ = 1e4 − 1e8/10100 = 1e6/10100 = 1e4/101. NIS = 0.01²/1.01e-4 = 1/1.01.
    #[test]
    fn polar_update_due_north_by_hand() {
        let (x, p) = cv2_target_north();
        let meas = PolarMeasurement {
            range: 10_000.0,
            azimuth: 0.01,
            elevation: None,
            sigma_range: 10.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: None,
        };
        let u = update_polar(&x, &p, &meas, PositionLayout::CV_2D, [0.0; 3]).unwrap();
        assert!(close(u.x[0], 10_000.0 / 101.0, 1e-9));
        assert!(close(u.x[2], 10_000.0, 1e-9));
        assert!(close(u.x[1], 0.0, 1e-12) && close(u.x[3], 0.0, 1e-12));
        assert!(close(u.p[(0, 0)], 1e4 / 101.0, 1e-9));
        assert!(close(u.p[(2, 2)], 1e4 / 101.0, 1e-9));
        assert!(close(u.s[(0, 0)], 10_100.0, 1e-9));
        assert!(close(u.s[(1, 1)], 1.01e-4, 1e-18));
        assert!(close(u.nis, 1.0 / 1.01, 1e-12));
    }

    /// The same geometry from a radar at (0, 0, 300) on a 3D state at height 400:
    /// dz = 100 m, slant range √(10⁸ + 10⁴). A plot at exactly the predicted
    /// (slant range, azimuth, elevation) leaves the state unchanged.
    #[test]
    fn polar_update_slant_range_and_site_height() {
        let x = dvector![0.0, 0.0, 10_000.0, 0.0, 400.0, 0.0];
        let p = DMatrix::from_diagonal(&dvector![1e4, 100.0, 1e4, 100.0, 1e4, 100.0]);
        let slant = (1e8f64 + 1e4).sqrt();
        let el = (100.0f64 / 10_000.0).atan();
        let meas = PolarMeasurement {
            range: slant,
            azimuth: 0.0,
            elevation: Some(el),
            sigma_range: 10.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: Some(1e-3),
        };
        let site = [0.0, 0.0, 300.0];
        let u = update_polar(&x, &p, &meas, PositionLayout::CV_3D, site).unwrap();
        assert!((&u.x - &x).amax() < 1e-9);
        assert!(u.nis < 1e-20);
        for i in 0..6 {
            assert!(u.p[(i, i)] <= p[(i, i)]);
        }
        // A 2D plot with the slant range on the 3D state also leaves it unchanged.
        let meas2 = PolarMeasurement {
            elevation: None,
            sigma_elevation: None,
            ..meas
        };
        let u2 = update_polar(&x, &p, &meas2, PositionLayout::CV_3D, site).unwrap();
        assert!((&u2.x - &x).amax() < 1e-9);
        // A 3D plot needs a height in the state.
        let (x2, p2) = cv2_target_north();
        assert!(update_polar(&x2, &p2, &meas, PositionLayout::CV_2D, site).is_err());
    }

    #[test]
    fn polar_update_wraps_azimuth() {
        // Target slightly west of north (az = 2π − 0.001), plot at az = +0.001:
        // the wrapped innovation is +0.002, not 0.002 − 2π.
        let (mut x, p) = cv2_target_north();
        x[0] = -10_000.0 * 0.001f64.tan();
        let meas = PolarMeasurement {
            range: x[0].hypot(x[2]),
            azimuth: 0.001,
            elevation: None,
            sigma_range: 10.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: None,
        };
        let u = update_polar(&x, &p, &meas, PositionLayout::CV_2D, [0.0; 3]).unwrap();
        assert!(close(u.innovation[1], 0.002, 1e-12));
        assert!(u.x[0] > x[0]);
    }

    #[test]
    fn polar_update_rejects_target_at_site() {
        let x = dvector![5.0, 0.0, 7.0, 0.0];
        let p = DMatrix::identity(4, 4);
        let meas = PolarMeasurement {
            range: 10.0,
            azimuth: 0.0,
            elevation: None,
            sigma_range: 1.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: None,
        };
        assert!(matches!(
            update_polar(&x, &p, &meas, PositionLayout::CV_2D, [5.0, 7.0, 0.0]),
            Err(AlgoError::DegenerateGeometry { .. })
        ));
        let bad = PositionLayout {
            x: 0,
            y: 0,
            z: None,
        };
        assert!(update_polar(&x, &p, &meas, bad, [0.0; 3]).is_err());
        let bad = PositionLayout {
            x: 0,
            y: 2,
            z: Some(4),
        };
        assert!(update_polar(&x, &p, &meas, bad, [0.0; 3]).is_err());
    }

    fn spd(n: usize, entries: &[f64], jitter: f64) -> DMatrix<f64> {
        let a = DMatrix::from_column_slice(n, n, &entries[..n * n]);
        &a * a.transpose() + DMatrix::identity(n, n) * jitter
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// For the optimal gain the Joseph form equals the standard form
        /// P⁺ = (I − K H) P, and P⁺ stays symmetric positive definite after
        /// predict and update, whatever the (random) SPD inputs.
        #[test]
        fn joseph_equals_standard_and_stays_spd(
            n in 1usize..6,
            m in 1usize..4,
            a in proptest::collection::vec(-3.0..3.0f64, 36),
            b in proptest::collection::vec(-3.0..3.0f64, 16),
            f in proptest::collection::vec(-2.0..2.0f64, 36),
            h in proptest::collection::vec(-2.0..2.0f64, 18),
            xz in proptest::collection::vec(-10.0..10.0f64, 9),
        ) {
            let p = spd(n, &a, 0.1);
            let q = spd(n, &b.iter().chain(&a).copied().collect::<Vec<_>>(), 0.0) * 0.01;
            let fm = DMatrix::from_column_slice(n, n, &f[..n * n]) + DMatrix::identity(n, n);
            let r = spd(m, &b, 0.5);
            let hm = DMatrix::from_column_slice(m, n, &h[..m * n]);
            let x = DVector::from_column_slice(&xz[..n]);
            let z = DVector::from_column_slice(&xz[n..n + m]);
            let (xp, pp) = match predict(&x, &p, &fm, &q) {
                Ok(v) => v,
                // A random F may be singular; then Q = 0-ish gives a singular P⁺.
                Err(AlgoError::NotPositiveDefinite { .. }) => return Ok(()),
                Err(e) => return Err(TestCaseError::fail(e.to_string())),
            };
            prop_assert!(check_covariance("pp", &pp).is_ok());
            let u = update_linear(&xp, &pp, &z, &hm, &r).unwrap();
            prop_assert!(check_covariance("p", &u.p).is_ok());
            let standard = (DMatrix::identity(n, n) - &u.gain * &hm) * &pp;
            let scale = pp.amax().max(1.0);
            prop_assert!((&u.p - standard).amax() <= 1e-8 * scale);
            prop_assert!(u.nis >= 0.0);
            // Information can only be gained: diag(P⁺) ≤ diag(P).
            for i in 0..n {
                prop_assert!(u.p[(i, i)] <= pp[(i, i)] * (1.0 + 1e-9));
            }
        }

        /// EKF polar update of a 3D CV state keeps P SPD.
        #[test]
        fn polar_update_stays_spd(
            e in -1e5..1e5f64, n in 1e3..1e5f64, u in 0.0..1e4f64,
            dr in -100.0..100.0f64, daz in -0.02..0.02f64, del in -0.02..0.02f64,
            sd in 1.0..1e3f64,
        ) {
            let x = dvector![e, 100.0, n, -50.0, u, 0.0];
            let p = DMatrix::from_diagonal(&dvector![sd * sd, 100.0, sd * sd, 100.0, sd * sd, 25.0]);
            let rho = e.hypot(n);
            let meas = PolarMeasurement {
                range: rho.hypot(u) + dr,
                azimuth: e.atan2(n) + daz,
                elevation: Some((u.atan2(rho) + del).clamp(-1.5, 1.5)),
                sigma_range: 50.0,
                sigma_azimuth: 0.005,
                sigma_elevation: Some(0.005),
            };
            let up = update_polar(&x, &p, &meas, PositionLayout::CV_3D, [0.0; 3]).unwrap();
            prop_assert!(check_covariance("p", &up.p).is_ok());
            prop_assert!(up.innovation[1].abs() <= 0.02 + 1e-12);
        }
    }
}
