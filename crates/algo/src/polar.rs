//! Radar polar measurements and the local east-north-up (ENU) plane.
//!
//! Conversions between a radar's polar coordinates (range, azimuth clockwise
//! from true north, elevation above the local horizontal) and local ENU
//! metres, the converted-measurement covariance `J R J'` (seed 000, He You
//! et al., eqs. 27–28, rewritten for azimuth from north), the polar
//! measurement model and its Jacobian used by the extended Kalman update,
//! radar-site offsets, and the two-point track initialisation of seed 000
//! eqs. 29–30.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{DMatrix, DVector};

use crate::error::{AlgoError, finite, finite_slice, non_negative, positive, same_dim};
use crate::gaussian::{Gaussian, check_covariance, symmetrize};

/// Horizontal distance (m) below which azimuth is undefined: the Jacobian
/// of azimuth grows like 1/ρ and the target is treated as at the site.
pub const MIN_HORIZONTAL_RANGE: f64 = 1e-3;

/// One radar plot in polar coordinates with its standard deviations.
///
/// A 2D radar gives `(range, azimuth)`; a 3D radar also gives `elevation`
/// (and then `sigma_elevation` is required). Angles in radians, range in
/// metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolarMeasurement {
    /// Range ρ (m), ≥ 0.
    pub range: f64,
    /// Azimuth θ (rad), clockwise from true north; any finite value.
    pub azimuth: f64,
    /// Elevation (rad) above the local horizontal, in [−π/2, π/2], 3D radars only.
    pub elevation: Option<f64>,
    /// Range standard deviation σ_ρ (m), > 0.
    pub sigma_range: f64,
    /// Azimuth standard deviation σ_θ (rad), > 0.
    pub sigma_azimuth: f64,
    /// Elevation standard deviation (rad), > 0; present iff `elevation` is.
    pub sigma_elevation: Option<f64>,
}

impl PolarMeasurement {
    /// Checks ranges, finiteness and that elevation and its sigma come together.
    pub fn validate(&self) -> Result<(), AlgoError> {
        non_negative("range", self.range)?;
        finite("azimuth", self.azimuth)?;
        positive("sigma_range", self.sigma_range)?;
        positive("sigma_azimuth", self.sigma_azimuth)?;
        match (self.elevation, self.sigma_elevation) {
            (None, None) => Ok(()),
            (Some(el), Some(sel)) => {
                check_elevation(el)?;
                positive("sigma_elevation", sel)?;
                Ok(())
            }
            (Some(_), None) => Err(AlgoError::InvalidParameter {
                what: "sigma_elevation",
                reason: "required when elevation is given".to_owned(),
            }),
            (None, Some(_)) => Err(AlgoError::InvalidParameter {
                what: "elevation",
                reason: "sigma_elevation given without elevation".to_owned(),
            }),
        }
    }

    /// Measurement dimension: 2 for (range, azimuth), 3 with elevation.
    pub fn dim(&self) -> usize {
        if self.elevation.is_some() { 3 } else { 2 }
    }

    /// The measurement vector `[range, azimuth(, elevation)]`.
    pub fn vector(&self) -> DVector<f64> {
        let mut v = vec![self.range, self.azimuth];
        v.extend(self.elevation);
        DVector::from_vec(v)
    }

    /// The measurement noise `R = diag(σ_ρ², σ_θ²(, σ_el²))`.
    pub fn noise_covariance(&self) -> DMatrix<f64> {
        let mut d = vec![self.sigma_range.powi(2), self.sigma_azimuth.powi(2)];
        d.extend(self.sigma_elevation.map(|s| s * s));
        DMatrix::from_diagonal(&DVector::from_vec(d))
    }
}

/// Wraps an angle into (−π, π] (for azimuth innovations). A non-finite input
/// gives NaN; callers validate first.
pub fn wrap_angle(a: f64) -> f64 {
    let r = a.rem_euclid(TAU);
    if r > PI { r - TAU } else { r }
}

/// Polar to local plane for a 2D radar, azimuth from north:
/// `[east, north] = ρ [sin θ, cos θ]`.
pub fn polar_to_enu_2d(range: f64, azimuth: f64) -> Result<[f64; 2], AlgoError> {
    non_negative("range", range)?;
    finite("azimuth", azimuth)?;
    let (s, c) = azimuth.sin_cos();
    Ok([range * s, range * c])
}

/// Polar to ENU for a 3D radar:
/// `[e, n, u] = r [cos el sin az, cos el cos az, sin el]`.
pub fn polar_to_enu_3d(range: f64, azimuth: f64, elevation: f64) -> Result<[f64; 3], AlgoError> {
    non_negative("range", range)?;
    finite("azimuth", azimuth)?;
    check_elevation(elevation)?;
    let (sa, ca) = azimuth.sin_cos();
    let (se, ce) = elevation.sin_cos();
    Ok([range * ce * sa, range * ce * ca, range * se])
}

/// ENU plane to `[range, azimuth]` with azimuth in [0, 2π); azimuth is 0 at
/// the origin.
pub fn enu_to_polar_2d(east: f64, north: f64) -> Result<[f64; 2], AlgoError> {
    finite_slice("position", &[east, north])?;
    Ok([east.hypot(north), azimuth_of(east, north)])
}

/// ENU to `[range, azimuth, elevation]`, azimuth in [0, 2π), elevation in
/// [−π/2, π/2]; azimuth is 0 straight above or below the site.
pub fn enu_to_polar_3d(east: f64, north: f64, up: f64) -> Result<[f64; 3], AlgoError> {
    finite_slice("position", &[east, north, up])?;
    let rho = east.hypot(north);
    Ok([rho.hypot(up), azimuth_of(east, north), up.atan2(rho)])
}

/// Jacobian ∂(e, n)/∂(ρ, θ) of [`polar_to_enu_2d`]:
/// `[[sin θ, ρ cos θ], [cos θ, −ρ sin θ]]`.
pub fn polar_jacobian_2d(range: f64, azimuth: f64) -> Result<DMatrix<f64>, AlgoError> {
    non_negative("range", range)?;
    finite("azimuth", azimuth)?;
    let (s, c) = azimuth.sin_cos();
    Ok(DMatrix::from_row_slice(
        2,
        2,
        &[s, range * c, c, -range * s],
    ))
}

/// Jacobian ∂(e, n, u)/∂(r, az, el) of [`polar_to_enu_3d`].
pub fn polar_jacobian_3d(
    range: f64,
    azimuth: f64,
    elevation: f64,
) -> Result<DMatrix<f64>, AlgoError> {
    non_negative("range", range)?;
    finite("azimuth", azimuth)?;
    check_elevation(elevation)?;
    let (sa, ca) = azimuth.sin_cos();
    let (se, ce) = elevation.sin_cos();
    let r = range;
    #[rustfmt::skip]
    let j = DMatrix::from_row_slice(3, 3, &[
        ce * sa, r * ce * ca, -r * se * sa,
        ce * ca, -r * ce * sa, -r * se * ca,
        se, 0.0, r * ce,
    ]);
    Ok(j)
}

/// Covariance of the converted 2D measurement, `J diag(σ_ρ², σ_θ²) J'`.
///
/// This is seed 000 eqs. 27–28 with θ measured from north instead of from the
/// x axis (x = east, y = north), so sine and cosine swap roles:
/// σ_x² = σ_ρ² sin²θ + ρ²σ_θ² cos²θ, σ_y² = σ_ρ² cos²θ + ρ²σ_θ² sin²θ,
/// σ_xy = (σ_ρ² − ρ²σ_θ²) sin θ cos θ. Positive definite for ρ > 0.
pub fn polar_covariance_2d(
    range: f64,
    azimuth: f64,
    sigma_range: f64,
    sigma_azimuth: f64,
) -> Result<DMatrix<f64>, AlgoError> {
    positive("sigma_range", sigma_range)?;
    positive("sigma_azimuth", sigma_azimuth)?;
    let j = polar_jacobian_2d(range, azimuth)?;
    let r = DMatrix::from_diagonal(&DVector::from_vec(vec![
        sigma_range * sigma_range,
        sigma_azimuth * sigma_azimuth,
    ]));
    Ok(sandwich(&j, &r))
}

/// Covariance of the converted 3D measurement, `J diag(σ_r², σ_az², σ_el²) J'`.
/// Positive definite for r > 0 and |el| < π/2.
pub fn polar_covariance_3d(
    range: f64,
    azimuth: f64,
    elevation: f64,
    sigma_range: f64,
    sigma_azimuth: f64,
    sigma_elevation: f64,
) -> Result<DMatrix<f64>, AlgoError> {
    positive("sigma_range", sigma_range)?;
    positive("sigma_azimuth", sigma_azimuth)?;
    positive("sigma_elevation", sigma_elevation)?;
    let j = polar_jacobian_3d(range, azimuth, elevation)?;
    let r = DMatrix::from_diagonal(&DVector::from_vec(vec![
        sigma_range * sigma_range,
        sigma_azimuth * sigma_azimuth,
        sigma_elevation * sigma_elevation,
    ]));
    Ok(sandwich(&j, &r))
}

/// The polar measurement model `h` at a target whose position relative to
/// the radar is `rel = [e, n, u]` (m), and its Jacobian ∂h/∂(e, n, u).
///
/// With `with_elevation` it is `h = [r, az, el]` (3x3 Jacobian), otherwise
/// `h = [r, az]` (2x3), where r = |rel| is the slant range; pass `u = 0`
/// for a horizontal range. Azimuth is returned in [0, 2π). Rows:
/// ∂r = [e, n, u]/r, ∂az = [n, −e, 0]/ρ², ∂el = [−e u/ρ, −n u/ρ, ρ]/r²
/// with ρ = √(e² + n²).
///
/// Fails with [`AlgoError::DegenerateGeometry`] when ρ < [`MIN_HORIZONTAL_RANGE`]
/// (target at the site or straight above it: azimuth undefined).
pub fn polar_measurement_model(
    rel: [f64; 3],
    with_elevation: bool,
) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    finite_slice("relative position", &rel)?;
    let [e, n, u] = rel;
    let rho2 = e * e + n * n;
    let rho = rho2.sqrt();
    if rho < MIN_HORIZONTAL_RANGE {
        return Err(AlgoError::DegenerateGeometry {
            what: "target position",
            reason: "target at or directly above/below the radar site, azimuth undefined",
        });
    }
    let r2 = rho2 + u * u;
    let r = r2.sqrt();
    let az = azimuth_of(e, n);
    let mut h = vec![r, az];
    let mut j = vec![e / r, n / r, u / r, n / rho2, -e / rho2, 0.0];
    if with_elevation {
        h.push(u.atan2(rho));
        j.extend([-e * u / (r2 * rho), -n * u / (r2 * rho), rho / r2]);
    }
    let m = h.len();
    Ok((DVector::from_vec(h), DMatrix::from_row_slice(m, 3, &j)))
}

/// A plot from a radar at local ENU offset `site` (m) as a Gaussian position
/// in the local frame: `site + polar_to_enu` with covariance `J R J'`.
///
/// A 3D plot (with elevation) gives `[e, n, u]` and a 3x3 covariance. A 2D
/// plot gives `[e, n]` and a 2x2 covariance, treating the range as
/// horizontal (no height information; `site[2]` is not used).
/// Fails with `NotPositiveDefinite` for a zero range (the azimuth error then
/// has no extent) or a 3D plot at the zenith.
pub fn plot_to_local(site: [f64; 3], meas: &PolarMeasurement) -> Result<Gaussian, AlgoError> {
    finite_slice("site", &site)?;
    meas.validate()?;
    let (mean, cov) = match (meas.elevation, meas.sigma_elevation) {
        (Some(el), Some(sel)) => {
            let p = polar_to_enu_3d(meas.range, meas.azimuth, el)?;
            let cov = polar_covariance_3d(
                meas.range,
                meas.azimuth,
                el,
                meas.sigma_range,
                meas.sigma_azimuth,
                sel,
            )?;
            let mean = DVector::from_fn(3, |i, _| site[i] + p[i]);
            (mean, cov)
        }
        _ => {
            let p = polar_to_enu_2d(meas.range, meas.azimuth)?;
            let cov = polar_covariance_2d(
                meas.range,
                meas.azimuth,
                meas.sigma_range,
                meas.sigma_azimuth,
            )?;
            let mean = DVector::from_fn(2, |i, _| site[i] + p[i]);
            (mean, cov)
        }
    };
    Gaussian::new(mean, cov).map_err(|e| match e {
        AlgoError::NotPositiveDefinite { .. } => AlgoError::NotPositiveDefinite {
            what: "converted plot covariance",
        },
        other => other,
    })
}

/// Two-point track initialisation of seed 000 eqs. 29–30 for the 2D
/// constant-velocity state `[x, vx, y, vy]`.
///
/// From positions `z0 = z(0)`, `z1 = z(1)` taken `t` seconds apart and the
/// 2x2 position covariance `r = R(1) = [[σx², σxy], [σxy, σy²]]` (eq. 27):
/// x̂(1/1) = [z1(1), (z1(1) − z1(0))/T, z2(1), (z2(1) − z2(0))/T] (eq. 29) and
/// P(1/1) with blocks `r_ab · [[1, 1/T], [1/T, 2/T²]]` (eq. 30).
pub fn two_point_init(
    z0: [f64; 2],
    z1: [f64; 2],
    r: &DMatrix<f64>,
    t: f64,
) -> Result<Gaussian, AlgoError> {
    finite_slice("z0", &z0)?;
    finite_slice("z1", &z1)?;
    positive("t", t)?;
    same_dim("measurement covariance", 2, r.nrows())?;
    check_covariance("measurement covariance", r)?;
    let x = DVector::from_vec(vec![z1[0], (z1[0] - z0[0]) / t, z1[1], (z1[1] - z0[1]) / t]);
    // Per-axis block for a covariance entry c: c · [[1, 1/T], [1/T, 2/T²]].
    let block = [[1.0, 1.0 / t], [1.0 / t, 2.0 / (t * t)]];
    let p = DMatrix::from_fn(4, 4, |i, j| r[(i / 2, j / 2)] * block[i % 2][j % 2]);
    Gaussian::new(x, p)
}

fn check_elevation(el: f64) -> Result<f64, AlgoError> {
    finite("elevation", el)?;
    if (-FRAC_PI_2..=FRAC_PI_2).contains(&el) {
        Ok(el)
    } else {
        Err(AlgoError::InvalidParameter {
            what: "elevation",
            reason: format!("must lie in [-pi/2, pi/2], got {el}"),
        })
    }
}

/// Azimuth clockwise from north in [0, 2π).
pub(crate) fn azimuth_of(east: f64, north: f64) -> f64 {
    let a = east.atan2(north);
    if a < 0.0 { a + TAU } else { a }
}

/// `J R J'`, symmetrized.
fn sandwich(j: &DMatrix<f64>, r: &DMatrix<f64>) -> DMatrix<f64> {
    let mut c = j * r * j.transpose();
    symmetrize(&mut c);
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;
    use proptest::prelude::*;

    const DEG: f64 = PI / 180.0;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn wrap_angle_range() {
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
        assert!(close(wrap_angle(3.0 * PI / 2.0), -PI / 2.0, 1e-15));
        assert!(close(wrap_angle(-0.1 - TAU), -0.1, 1e-14));
        assert!(close(wrap_angle(TAU - 0.002), -0.002, 1e-15));
    }

    #[test]
    fn polar_to_enu_by_hand() {
        // Due east at 1000 m: az = 90°.
        let [e, n] = polar_to_enu_2d(1000.0, 90.0 * DEG).unwrap();
        assert!(close(e, 1000.0, 1e-9) && close(n, 0.0, 1e-9));
        // az = 30°: e = 1000 · 1/2, n = 1000 · √3/2.
        let [e, n] = polar_to_enu_2d(1000.0, 30.0 * DEG).unwrap();
        assert!(close(e, 500.0, 1e-9) && close(n, 500.0 * 3f64.sqrt(), 1e-9));
        // 3D, az = 45°, el = 30°, r = 2: horizontal 2 cos 30° = √3, up 1.
        let [e, n, u] = polar_to_enu_3d(2.0, 45.0 * DEG, 30.0 * DEG).unwrap();
        let h = 3f64.sqrt() / 2f64.sqrt();
        assert!(close(e, h, 1e-15) && close(n, h, 1e-15) && close(u, 1.0, 1e-15));
        // Inverses: az of due west is 270°.
        let [r, az] = enu_to_polar_2d(-5.0, 0.0).unwrap();
        assert!(close(r, 5.0, 0.0) && close(az, 270.0 * DEG, 1e-15));
        let [r, az, el] = enu_to_polar_3d(0.0, 3.0, 4.0).unwrap();
        assert!(close(r, 5.0, 1e-15) && az == 0.0 && close(el, (4.0f64 / 3.0).atan(), 1e-15));
    }

    #[test]
    fn rejects_bad_inputs() {
        assert!(polar_to_enu_2d(-1.0, 0.0).is_err());
        assert!(polar_to_enu_2d(1.0, f64::NAN).is_err());
        assert!(polar_to_enu_3d(1.0, 0.0, 2.0).is_err());
        assert!(enu_to_polar_3d(f64::INFINITY, 0.0, 0.0).is_err());
        assert!(polar_covariance_2d(1.0, 0.0, 0.0, 1.0).is_err());
        let mut m = PolarMeasurement {
            range: 1.0,
            azimuth: 0.0,
            elevation: Some(0.1),
            sigma_range: 1.0,
            sigma_azimuth: 0.01,
            sigma_elevation: None,
        };
        assert!(m.validate().is_err());
        m.sigma_elevation = Some(0.01);
        assert!(m.validate().is_ok());
        assert!(matches!(
            polar_measurement_model([0.0, 0.0, 100.0], true),
            Err(AlgoError::DegenerateGeometry { .. })
        ));
    }

    /// Seed 000 eq. 28 with σ_ρ = 170 m, σ_θ = 1°, written for azimuth from
    /// north (x = east, y = north): sin and cos swap roles.
    #[test]
    fn covariance_matches_seed000_eq28() {
        let (sr, st) = (170.0, 1.0 * DEG);
        for (rho, az_deg) in [
            (50_000.0, 0.0),
            (50_000.0, 30.0),
            (120_000.0, 135.0),
            (80_000.0, 250.0),
            (10_000.0, 359.0),
        ] {
            let az: f64 = az_deg * DEG;
            let (s, c) = (az.sin(), az.cos());
            let sx2 = sr * sr * s * s + rho * rho * st * st * c * c;
            let sy2 = sr * sr * c * c + rho * rho * st * st * s * s;
            let sxy = (sr * sr - rho * rho * st * st) * s * c;
            let p = polar_covariance_2d(rho, az, sr, st).unwrap();
            let tol = 1e-9 * sx2.max(sy2);
            assert!(close(p[(0, 0)], sx2, tol), "{az_deg}");
            assert!(close(p[(1, 1)], sy2, tol), "{az_deg}");
            assert!(
                close(p[(0, 1)], sxy, tol) && p[(0, 1)] == p[(1, 0)],
                "{az_deg}"
            );
            check_covariance("p", &p).unwrap();
        }
        // Due north (az = 0): along-range error is north, cross-range is east:
        // P = diag((ρ σ_θ)², σ_ρ²).
        let p = polar_covariance_2d(50_000.0, 0.0, sr, st).unwrap();
        assert!(close(p[(0, 0)], (50_000.0 * st).powi(2), 1e-6));
        assert!(close(p[(1, 1)], sr * sr, 1e-9));
    }

    #[test]
    fn covariance_3d_level_target_matches_2d() {
        // At zero elevation the horizontal block equals the 2D result and the
        // vertical variance is (r σ_el)² (∂u/∂el = r cos 0 = r), uncorrelated.
        let (r, az, sr, sa, se) = (30_000.0, 40.0 * DEG, 170.0, DEG, 0.5 * DEG);
        let p3 = polar_covariance_3d(r, az, 0.0, sr, sa, se).unwrap();
        let p2 = polar_covariance_2d(r, az, sr, sa).unwrap();
        for i in 0..2 {
            for j in 0..2 {
                assert!(close(p3[(i, j)], p2[(i, j)], 1e-9 * p2.amax()));
            }
            assert!(close(p3[(i, 2)], 0.0, 1e-9));
        }
        assert!(close(p3[(2, 2)], (r * se).powi(2), 1e-6));
    }

    #[test]
    fn plot_at_site_offset() {
        // 3D plot due east, level, 1000 m, from a site at (100, 200, 30).
        let m = PolarMeasurement {
            range: 1000.0,
            azimuth: 90.0 * DEG,
            elevation: Some(0.0),
            sigma_range: 10.0,
            sigma_azimuth: 0.001,
            sigma_elevation: Some(0.002),
        };
        let g = plot_to_local([100.0, 200.0, 30.0], &m).unwrap();
        assert!(close(g.mean()[0], 1100.0, 1e-9));
        assert!(close(g.mean()[1], 200.0, 1e-9));
        assert!(close(g.mean()[2], 30.0, 1e-9));
        // East is along range: σ² = 100; north is cross-range: (1000 · 0.001)² = 1;
        // up: (1000 · 0.002)² = 4.
        assert!(close(g.cov()[(0, 0)], 100.0, 1e-9));
        assert!(close(g.cov()[(1, 1)], 1.0, 1e-9));
        assert!(close(g.cov()[(2, 2)], 4.0, 1e-9));
        // 2D plot: position in the plane.
        let m2 = PolarMeasurement {
            elevation: None,
            sigma_elevation: None,
            ..m
        };
        let g2 = plot_to_local([100.0, 200.0, 30.0], &m2).unwrap();
        assert_eq!(g2.dim(), 2);
        assert!(close(g2.mean()[0], 1100.0, 1e-9));
        // Zero range: singular covariance.
        let m0 = PolarMeasurement { range: 0.0, ..m2 };
        assert!(matches!(
            plot_to_local([0.0; 3], &m0),
            Err(AlgoError::NotPositiveDefinite { .. })
        ));
    }

    /// Seed 000 eqs. 29–30 with T = 4 s, z(0) = (1000, 2000), z(1) = (1040, 1980),
    /// R = [[400, 100], [100, 900]]:
    /// x̂ = [1040, 40/4 = 10, 1980, −20/4 = −5];
    /// P row 1 = [400, 100, 100, 25], row 2 = [100, 50, 25, 12.5],
    /// row 3 = [100, 25, 900, 225], row 4 = [25, 12.5, 225, 112.5].
    #[test]
    fn two_point_init_by_hand() {
        let r = dmatrix![400.0, 100.0; 100.0, 900.0];
        let g = two_point_init([1000.0, 2000.0], [1040.0, 1980.0], &r, 4.0).unwrap();
        assert_eq!(g.mean().as_slice(), &[1040.0, 10.0, 1980.0, -5.0]);
        #[rustfmt::skip]
        let expected = dmatrix![
            400.0, 100.0, 100.0, 25.0;
            100.0, 50.0, 25.0, 12.5;
            100.0, 25.0, 900.0, 225.0;
            25.0, 12.5, 225.0, 112.5
        ];
        assert!((g.cov() - expected).amax() < 1e-12);
        assert!(two_point_init([0.0; 2], [1.0; 2], &r, 0.0).is_err());
        assert!(two_point_init([0.0; 2], [1.0; 2], &dmatrix![1.0], 1.0).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn round_trip_3d(r in 1.0..5e5f64, az in 0.0..TAU, el in -1.5..1.5f64) {
            let [e, n, u] = polar_to_enu_3d(r, az, el).unwrap();
            let [r2, az2, el2] = enu_to_polar_3d(e, n, u).unwrap();
            prop_assert!((r2 - r).abs() <= 1e-9 * r);
            prop_assert!(wrap_angle(az2 - az).abs() <= 1e-9);
            prop_assert!((el2 - el).abs() <= 1e-12);
        }

        #[test]
        fn converted_covariance_is_spd(
            r in 100.0..5e5f64, az in -10.0..10.0f64, el in -1.5..1.5f64,
            sr in 1.0..500.0f64, sa in 1e-4..0.05f64, se in 1e-4..0.05f64,
        ) {
            prop_assert!(check_covariance("p", &polar_covariance_2d(r, az, sr, sa).unwrap()).is_ok());
            prop_assert!(
                check_covariance("p", &polar_covariance_3d(r, az, el, sr, sa, se).unwrap()).is_ok()
            );
        }

        /// The measurement Jacobian is the inverse of the conversion Jacobian
        /// (inverse function theorem), and matches central differences.
        #[test]
        fn measurement_jacobian(r in 100.0..5e5f64, az in 0.0..TAU, el in -1.4..1.4f64) {
            let p = polar_to_enu_3d(r, az, el).unwrap();
            let (h, jm) = polar_measurement_model(p, true).unwrap();
            prop_assert!((h[0] - r).abs() <= 1e-9 * r);
            let jp = polar_jacobian_3d(r, az, el).unwrap();
            let id = &jm * &jp;
            prop_assert!((id - DMatrix::identity(3, 3)).amax() < 1e-9);
            for k in 0..3 {
                let step = 1e-5 * r;
                let mut a = p;
                let mut b = p;
                a[k] += step;
                b[k] -= step;
                let ha = enu_to_polar_3d(a[0], a[1], a[2]).unwrap();
                let hb = enu_to_polar_3d(b[0], b[1], b[2]).unwrap();
                for i in 0..3 {
                    let d = if i == 1 { wrap_angle(ha[i] - hb[i]) } else { ha[i] - hb[i] };
                    let fd = d / (2.0 * step);
                    prop_assert!((fd - jm[(i, k)]).abs() <= 1e-6 * jm.row(i).amax(), "{i} {k} {fd} {}", jm[(i, k)]);
                }
            }
        }
    }
}
