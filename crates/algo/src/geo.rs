//! Reference ellipsoids, geodetic ↔ ECEF conversion and local ENU frames.
//!
//! Puts radar sites and AIS positions into one Cartesian frame: geodetic
//! (latitude, longitude, ellipsoidal height) to Earth-centred Earth-fixed
//! (ECEF) and back, local east-north-up frames about a site, and the change
//! of a position and its covariance from one site's ENU frame to another's.
//! Angles in radians, lengths in metres.
//!
//! ECEF → geodetic uses the closed-form method of H. Vermeille,
//! "Direct transformation from geocentric coordinates to geodetic
//! coordinates", Journal of Geodesy 76 (2002) 451–454 (no iteration; exact
//! up to rounding, valid at the poles and the equator and for any point
//! outside a small region around the ellipsoid centre, which is rejected).

use std::f64::consts::{FRAC_PI_2, TAU};

use nalgebra::{DMatrix, Matrix3, Vector3};

use crate::error::{AlgoError, finite, finite_slice, same_dim};
use crate::gaussian::{check_covariance, symmetrize};

/// A reference ellipsoid of revolution given by its semi-major axis `a` (m)
/// and flattening `f`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    a: f64,
    f: f64,
}

impl Ellipsoid {
    /// WGS 84: a = 6 378 137 m, 1/f = 298.257 223 563 (NIMA TR8350.2).
    pub const WGS84: Self = Self {
        a: 6_378_137.0,
        f: 1.0 / 298.257_223_563,
    };
    /// GRS 80: a = 6 378 137 m, 1/f = 298.257 222 101 (Moritz 1980).
    pub const GRS80: Self = Self {
        a: 6_378_137.0,
        f: 1.0 / 298.257_222_101,
    };
    /// Krasovsky 1940: a = 6 378 245 m, 1/f = 298.3.
    pub const KRASOVSKY_1940: Self = Self {
        a: 6_378_245.0,
        f: 1.0 / 298.3,
    };

    /// An ellipsoid with `a > 0` and `0 <= f < 1`.
    pub fn new(a: f64, f: f64) -> Result<Self, AlgoError> {
        finite("semi_major_axis", a)?;
        finite("flattening", f)?;
        if a <= 0.0 {
            return Err(AlgoError::InvalidParameter {
                what: "semi_major_axis",
                reason: format!("must be > 0, got {a}"),
            });
        }
        if !(0.0..1.0).contains(&f) {
            return Err(AlgoError::InvalidParameter {
                what: "flattening",
                reason: format!("must lie in [0, 1), got {f}"),
            });
        }
        Ok(Self { a, f })
    }

    /// Semi-major axis a (m).
    pub fn a(&self) -> f64 {
        self.a
    }

    /// Flattening f = (a − b)/a.
    pub fn f(&self) -> f64 {
        self.f
    }

    /// Semi-minor axis b = a (1 − f) (m).
    pub fn b(&self) -> f64 {
        self.a * (1.0 - self.f)
    }

    /// First eccentricity squared e² = f (2 − f).
    pub fn e2(&self) -> f64 {
        self.f * (2.0 - self.f)
    }
}

/// Geodetic (latitude, longitude, ellipsoidal height) to ECEF `[x, y, z]`:
/// x = (N + h) cos φ cos λ, y = (N + h) cos φ sin λ, z = (N (1 − e²) + h) sin φ
/// with N = a / √(1 − e² sin² φ).
pub fn geodetic_to_ecef(
    ell: &Ellipsoid,
    lat: f64,
    lon: f64,
    h: f64,
) -> Result<[f64; 3], AlgoError> {
    check_geodetic(lat, lon, h)?;
    let e2 = ell.e2();
    let (sp, cp) = lat.sin_cos();
    let (sl, cl) = lon.sin_cos();
    let n = ell.a / (1.0 - e2 * sp * sp).sqrt();
    Ok([
        (n + h) * cp * cl,
        (n + h) * cp * sl,
        (n * (1.0 - e2) + h) * sp,
    ])
}

/// ECEF `[x, y, z]` to geodetic `(lat, lon, h)` by Vermeille's (2002) closed
/// form; lat in [−π/2, π/2], lon in (−π, π] (0 on the polar axis).
///
/// Fails for points within 2 a e² of the centre (about 85 km for WGS 84),
/// where the closed form is not valid.
pub fn ecef_to_geodetic(ell: &Ellipsoid, ecef: [f64; 3]) -> Result<(f64, f64, f64), AlgoError> {
    let Vermeille { k, d, .. } = vermeille(ell, ecef)?;
    let [x, y, z] = ecef;
    let dz = d.hypot(z);
    let lat = 2.0 * z.atan2(d + dz);
    let h = (k + ell.e2() - 1.0) / k * dz;
    let lon = y.atan2(x);
    if lat.is_finite() && h.is_finite() {
        Ok((lat, lon, h))
    } else {
        Err(AlgoError::NonFinite {
            what: "geodetic position",
        })
    }
}

/// The geodetic height of an ECEF point and the sines and cosines of its
/// latitude and longitude, without the angles: what a Newton step on the
/// height or a local frame at the point needs (the unit normal is
/// `(cos φ cos λ, cos φ sin λ, sin φ)`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vertical {
    /// Geodetic (ellipsoidal) height (m).
    pub h: f64,
    /// Sine of the geodetic latitude φ.
    pub sin_lat: f64,
    /// Cosine of the geodetic latitude φ.
    pub cos_lat: f64,
    /// Sine of the longitude λ.
    pub sin_lon: f64,
    /// Cosine of the longitude λ.
    pub cos_lon: f64,
}

impl Vertical {
    /// The outward unit normal of the ellipsoid below the point (ECEF), the
    /// gradient of the geodetic height.
    pub fn normal(&self) -> Vector3<f64> {
        Vector3::new(
            self.cos_lat * self.cos_lon,
            self.cos_lat * self.sin_lon,
            self.sin_lat,
        )
    }
}

/// [`ecef_to_geodetic`] without the angles, by the same closed form: in
/// Vermeille's notation the latitude is atan2(z, D) and the longitude
/// atan2(y, x), so their sines and cosines are z/√(D² + z²), D/√(D² + z²),
/// y/√(x² + y²) and x/√(x² + y²), and h = (k + e² − 1)/k · √(D² + z²). No
/// atan2, no sine or cosine and a plain square root for `hypot`: the height
/// agrees with [`ecef_to_geodetic`]'s to rounding (about 1e-9 m), the sines
/// and cosines with those of its angles to a few ulps. On the polar axis
/// the longitude is 0, as there.
pub fn ecef_to_vertical(ell: &Ellipsoid, ecef: [f64; 3]) -> Result<Vertical, AlgoError> {
    let Vermeille { k, d, rho } = vermeille(ell, ecef)?;
    let [x, y, z] = ecef;
    let dz = (d * d + z * z).sqrt();
    let h = (k + ell.e2() - 1.0) / k * dz;
    let (sin_lon, cos_lon) = if rho > 0.0 {
        (y / rho, x / rho)
    } else {
        (0.0, 1.0)
    };
    let v = Vertical {
        h,
        sin_lat: z / dz,
        cos_lat: d / dz,
        sin_lon,
        cos_lon,
    };
    if h.is_finite() && v.sin_lat.is_finite() && v.cos_lat.is_finite() {
        Ok(v)
    } else {
        Err(AlgoError::NonFinite {
            what: "geodetic position",
        })
    }
}

/// Vermeille's k, D = k ρ / (k + e²) and ρ = √(x² + y²) for an ECEF point.
struct Vermeille {
    k: f64,
    d: f64,
    rho: f64,
}

/// The steps of Vermeille's (2002) closed form that the latitude and the
/// height share, for [`ecef_to_geodetic`] and [`ecef_to_vertical`].
fn vermeille(ell: &Ellipsoid, ecef: [f64; 3]) -> Result<Vermeille, AlgoError> {
    finite_slice("ecef", &ecef)?;
    let [x, y, z] = ecef;
    let a = ell.a;
    let e2 = ell.e2();
    let e4 = e2 * e2;
    let rho2 = x * x + y * y;
    let rho = rho2.sqrt();
    let p = rho2 / (a * a);
    let q = (1.0 - e2) * z * z / (a * a);
    if p + q <= 4.0 * e4 || p + q == 0.0 {
        return Err(AlgoError::InvalidParameter {
            what: "ecef",
            reason: "too close to the ellipsoid centre for a geodetic conversion".to_owned(),
        });
    }
    let r = (p + q - e4) / 6.0;
    let s = e4 * p * q / (4.0 * r * r * r);
    let t = (1.0 + s + (s * (2.0 + s)).sqrt()).cbrt();
    let u = r * (1.0 + t + 1.0 / t);
    let v = (u * u + e4 * q).sqrt();
    let w = e2 * (u + v - q) / (2.0 * v);
    let k = (u + v + w * w).sqrt() - w;
    let d = k * rho / (k + e2);
    Ok(Vermeille { k, d, rho })
}

/// A local east-north-up frame about an origin on an ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    ellipsoid: Ellipsoid,
    lat: f64,
    lon: f64,
    h: f64,
    origin: Vector3<f64>,
    rot: Matrix3<f64>,
}

impl LocalFrame {
    /// The ENU frame at geodetic origin `(lat, lon, h)`.
    pub fn new(ellipsoid: Ellipsoid, lat: f64, lon: f64, h: f64) -> Result<Self, AlgoError> {
        let o = geodetic_to_ecef(&ellipsoid, lat, lon, h)?;
        let (sp, cp) = lat.sin_cos();
        let (sl, cl) = lon.sin_cos();
        #[rustfmt::skip]
        let rot = Matrix3::new(
            -sl, cl, 0.0,
            -sp * cl, -sp * sl, cp,
            cp * cl, cp * sl, sp,
        );
        Ok(Self {
            ellipsoid,
            lat,
            lon,
            h,
            origin: Vector3::from(o),
            rot,
        })
    }

    /// The ellipsoid of the frame.
    pub fn ellipsoid(&self) -> Ellipsoid {
        self.ellipsoid
    }

    /// Geodetic origin `(lat, lon, h)`.
    pub fn origin_geodetic(&self) -> (f64, f64, f64) {
        (self.lat, self.lon, self.h)
    }

    /// ECEF origin `[x, y, z]`.
    pub fn origin_ecef(&self) -> [f64; 3] {
        self.origin.into()
    }

    /// The rotation R from ECEF to ENU axes:
    /// rows east = (−sin λ, cos λ, 0), north = (−sin φ cos λ, −sin φ sin λ, cos φ),
    /// up = (cos φ cos λ, cos φ sin λ, sin φ).
    pub fn rotation(&self) -> Matrix3<f64> {
        self.rot
    }

    /// ECEF position to ENU: `R (p − origin)`.
    pub fn ecef_to_enu(&self, ecef: [f64; 3]) -> Result<[f64; 3], AlgoError> {
        finite_slice("ecef", &ecef)?;
        Ok((self.rot * (Vector3::from(ecef) - self.origin)).into())
    }

    /// ENU position to ECEF: `origin + R' e`.
    pub fn enu_to_ecef(&self, enu: [f64; 3]) -> Result<[f64; 3], AlgoError> {
        finite_slice("enu position", &enu)?;
        Ok((self.origin + self.rot.transpose() * Vector3::from(enu)).into())
    }

    /// Geodetic position to ENU.
    pub fn geodetic_to_enu(&self, lat: f64, lon: f64, h: f64) -> Result<[f64; 3], AlgoError> {
        self.ecef_to_enu(geodetic_to_ecef(&self.ellipsoid, lat, lon, h)?)
    }

    /// ENU position to geodetic `(lat, lon, h)` on the frame's ellipsoid.
    pub fn enu_to_geodetic(&self, enu: [f64; 3]) -> Result<(f64, f64, f64), AlgoError> {
        ecef_to_geodetic(&self.ellipsoid, self.enu_to_ecef(enu)?)
    }

    /// The rotation taking ENU vectors of `self` to ENU vectors of `to`:
    /// `R_to R_selfᵀ`.
    pub fn rotation_to(&self, to: &LocalFrame) -> Matrix3<f64> {
        to.rot * self.rot.transpose()
    }

    /// An ENU position of `self` expressed in the ENU frame `to`:
    /// `R_to (origin_self + R_selfᵀ e − origin_to)`.
    pub fn position_to(&self, to: &LocalFrame, enu: [f64; 3]) -> Result<[f64; 3], AlgoError> {
        to.ecef_to_enu(self.enu_to_ecef(enu)?)
    }

    /// A 3x3 ENU covariance of `self` expressed in the ENU frame `to`:
    /// `M P Mᵀ` with `M = R_to R_selfᵀ`.
    pub fn covariance_to(
        &self,
        to: &LocalFrame,
        cov: &DMatrix<f64>,
    ) -> Result<DMatrix<f64>, AlgoError> {
        same_dim("covariance", 3, cov.nrows())?;
        check_covariance("covariance", cov)?;
        let m = self.rotation_to(to);
        let m = DMatrix::from_column_slice(3, 3, m.as_slice());
        let mut out = &m * cov * m.transpose();
        symmetrize(&mut out);
        Ok(out)
    }
}

fn check_geodetic(lat: f64, lon: f64, h: f64) -> Result<(), AlgoError> {
    finite("latitude", lat)?;
    finite("longitude", lon)?;
    finite("height", h)?;
    if !(-FRAC_PI_2..=FRAC_PI_2).contains(&lat) {
        return Err(AlgoError::InvalidParameter {
            what: "latitude",
            reason: format!("must lie in [-pi/2, pi/2] rad, got {lat}"),
        });
    }
    if !(-TAU..=TAU).contains(&lon) {
        return Err(AlgoError::InvalidParameter {
            what: "longitude",
            reason: format!("must lie in [-2 pi, 2 pi] rad, got {lon}"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::polar::wrap_angle;
    use nalgebra::dmatrix;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_4, PI};

    const DEG: f64 = PI / 180.0;
    const WGS84: Ellipsoid = Ellipsoid::WGS84;

    fn close3(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn vertical_agrees_with_the_geodetic_angles() {
        // ecef_to_vertical's sines and cosines are those of
        // ecef_to_geodetic's angles to a few ulps, its height the same to
        // rounding (a square root for hypot); the polar axis has longitude 0.
        for (lat, lon, h) in [
            (30.0, 120.0, 7000.0),
            (-45.0, -170.0, 0.0),
            (0.0, 0.0, 12_000.0),
            (89.9, 10.0, -50.0),
            (31.2, 121.4, 150_000.0),
            (90.0, 0.0, 1000.0),
        ] {
            let p = geodetic_to_ecef(&WGS84, lat * DEG, lon * DEG, h).unwrap();
            let (la, lo, hh) = ecef_to_geodetic(&WGS84, p).unwrap();
            let v = ecef_to_vertical(&WGS84, p).unwrap();
            assert!((v.h - hh).abs() < 1e-8, "{lat} {lon}: {} {hh}", v.h);
            for (got, want) in [
                (v.sin_lat, la.sin()),
                (v.cos_lat, la.cos()),
                (v.sin_lon, lo.sin()),
                (v.cos_lon, lo.cos()),
            ] {
                assert!((got - want).abs() < 1e-15, "{lat} {lon}: {got} {want}");
            }
            assert!((v.normal().norm() - 1.0).abs() < 1e-15);
        }
        assert!(ecef_to_vertical(&WGS84, [1.0, 2.0, 3.0]).is_err());
        assert!(ecef_to_vertical(&WGS84, [f64::NAN, 0.0, 7e6]).is_err());
    }

    #[test]
    fn ellipsoid_constants() {
        // b = a (1 − f) = 6378137 (1 − 1/298.257223563) = 6356752.314245179 m (WGS 84).
        assert!((WGS84.b() - 6_356_752.314_245_179).abs() < 1e-6);
        // GRS 80 b = a (1 − f) = 6356752.314140356 m (Moritz 1980 prints 6356752.3141 m).
        assert!((Ellipsoid::GRS80.b() - 6_356_752.314_140_356).abs() < 1e-6);
        // Krasovsky b = 6378245 (1 − 1/298.3) = 6356863.018773047 m.
        assert!((Ellipsoid::KRASOVSKY_1940.b() - 6_356_863.018_773_047).abs() < 1e-6);
        // e² of WGS 84 = 0.00669437999014 (NIMA TR8350.2 table 3.3).
        assert!((WGS84.e2() - 0.006_694_379_990_14).abs() < 1e-14);
        assert!(Ellipsoid::new(0.0, 0.0).is_err());
        assert!(Ellipsoid::new(1.0, 1.0).is_err());
        assert_eq!(
            Ellipsoid::new(6_378_137.0, 1.0 / 298.257_223_563).unwrap(),
            WGS84
        );
    }

    #[test]
    fn closed_form_points() {
        let (a, b) = (WGS84.a(), WGS84.b());
        assert!(close3(
            geodetic_to_ecef(&WGS84, 0.0, 0.0, 0.0).unwrap(),
            [a, 0.0, 0.0],
            1e-9
        ));
        assert!(close3(
            geodetic_to_ecef(&WGS84, FRAC_PI_2, 1.234, 0.0).unwrap(),
            [0.0, 0.0, b],
            1e-6
        ));
        assert!(close3(
            geodetic_to_ecef(&WGS84, 0.0, FRAC_PI_2, 100.0).unwrap(),
            [0.0, a + 100.0, 0.0],
            1e-6
        ));
        // Lat 45°, lon 45°, h = 0: sin²φ = 1/2, N = a/√(1 − e²/2),
        // x = y = N cos45 cos45 = N/2, z = N (1 − e²) sin 45 = N (1 − e²)/√2.
        let f: f64 = 1.0 / 298.257_223_563;
        let e2 = 2.0 * f - f * f;
        let n = 6_378_137.0 / (1.0 - e2 / 2.0).sqrt();
        let p = geodetic_to_ecef(&WGS84, FRAC_PI_4, FRAC_PI_4, 0.0).unwrap();
        assert!(close3(
            p,
            [n / 2.0, n / 2.0, n * (1.0 - e2) / 2f64.sqrt()],
            1e-6
        ));

        // Inverse at the same points.
        let (lat, lon, h) = ecef_to_geodetic(&WGS84, [a, 0.0, 0.0]).unwrap();
        assert!(lat.abs() < 1e-15 && lon == 0.0 && h.abs() < 1e-6);
        let (lat, lon, h) = ecef_to_geodetic(&WGS84, [0.0, 0.0, -b - 10.0]).unwrap();
        assert!((lat + FRAC_PI_2).abs() < 1e-15 && lon == 0.0 && (h - 10.0).abs() < 1e-6);
        let (lat, lon, h) = ecef_to_geodetic(&WGS84, [0.0, a + 100.0, 0.0]).unwrap();
        assert!(lat.abs() < 1e-15 && (lon - FRAC_PI_2).abs() < 1e-15 && (h - 100.0).abs() < 1e-6);
        let (lat, lon, h) = ecef_to_geodetic(&WGS84, p).unwrap();
        assert!((lat - FRAC_PI_4).abs() < 1e-14 && (lon - FRAC_PI_4).abs() < 1e-15);
        assert!(h.abs() < 1e-6);
    }

    #[test]
    fn rejects_bad_inputs() {
        assert!(geodetic_to_ecef(&WGS84, 1.6, 0.0, 0.0).is_err());
        assert!(geodetic_to_ecef(&WGS84, 0.0, 7.0, 0.0).is_err());
        assert!(geodetic_to_ecef(&WGS84, 0.0, 0.0, f64::NAN).is_err());
        assert!(ecef_to_geodetic(&WGS84, [0.0, 0.0, 0.0]).is_err());
        assert!(ecef_to_geodetic(&WGS84, [1e4, 0.0, 0.0]).is_err());
        assert!(ecef_to_geodetic(&WGS84, [f64::NAN, 0.0, 0.0]).is_err());
        assert!(LocalFrame::new(WGS84, -2.0, 0.0, 0.0).is_err());
    }

    #[test]
    fn enu_axes_at_lat0_lon0() {
        // At (0°, 0°): up = ECEF x, east = ECEF y, north = ECEF z.
        let fr = LocalFrame::new(WGS84, 0.0, 0.0, 0.0).unwrap();
        let enu = fr.ecef_to_enu([WGS84.a() + 10.0, 20.0, 30.0]).unwrap();
        assert!(close3(enu, [20.0, 30.0, 10.0], 1e-9));
        let back = fr.enu_to_ecef(enu).unwrap();
        assert!(close3(back, [WGS84.a() + 10.0, 20.0, 30.0], 1e-9));
        let r = fr.rotation();
        assert!((r * r.transpose() - Matrix3::identity()).amax() < 1e-15);
    }

    /// A point on the ellipsoid Δφ = 1000/M north of the origin along the
    /// meridian. Integrating the meridian tangent, rotated by φ − φ0 from the
    /// origin's north, with M(φ) ≈ M0 + M'(φ − φ0):
    /// north = M0 sin Δφ + M' Δφ²/2, up = −M0 (1 − cos Δφ) − M' Δφ³/3
    /// (neglected terms ~1e-7 m), with M = a(1 − e²)/(1 − e² sin²φ)^{3/2} and
    /// M' = 3 a (1 − e²) e² sin φ cos φ / (1 − e² sin²φ)^{5/2}.
    /// At φ0 = 45° this is about (0, 1000.01, −0.0787): up ≈ −d²/(2M).
    #[test]
    fn one_km_north_along_meridian() {
        let (lat0, lon0) = (45.0 * DEG, 10.0 * DEG);
        let (a, f): (f64, f64) = (6_378_137.0, 1.0 / 298.257_223_563);
        let e2 = f * (2.0 - f);
        let w = 1.0 - e2 * lat0.sin().powi(2);
        let m0 = a * (1.0 - e2) / w.powf(1.5);
        let m1 = 3.0 * a * (1.0 - e2) * e2 * lat0.sin() * lat0.cos() / w.powf(2.5);
        let dphi = 1000.0 / m0;
        let north = m0 * dphi.sin() + m1 * dphi * dphi / 2.0;
        let up = -m0 * (1.0 - dphi.cos()) - m1 * dphi.powi(3) / 3.0;
        let fr = LocalFrame::new(WGS84, lat0, lon0, 0.0).unwrap();
        let enu = fr.geodetic_to_enu(lat0 + dphi, lon0, 0.0).unwrap();
        assert!(enu[0].abs() < 1e-8, "{enu:?}");
        assert!((enu[1] - north).abs() < 1e-6, "{enu:?} {north}");
        assert!((enu[2] - up).abs() < 1e-6, "{enu:?} {up}");
        assert!((enu[2] + 1000.0f64.powi(2) / (2.0 * m0)).abs() < 1e-4);
    }

    #[test]
    fn frame_change() {
        // Two sites 0.5° apart; a target 20 km east, 5 km up of site A.
        let fa = LocalFrame::new(WGS84, 38.0 * DEG, 121.0 * DEG, 50.0).unwrap();
        let fb = LocalFrame::new(WGS84, 38.5 * DEG, 121.2 * DEG, 10.0).unwrap();
        let pa = [20_000.0, 0.0, 5_000.0];
        let pb = fa.position_to(&fb, pa).unwrap();
        // Independent path through geodetic coordinates.
        let (lat, lon, h) = fa.enu_to_geodetic(pa).unwrap();
        let pb2 = fb.geodetic_to_enu(lat, lon, h).unwrap();
        assert!(close3(pb, pb2, 1e-6));
        // Distances are preserved: |pb − B's view of A's origin| = |pa|.
        let oa = fa.position_to(&fb, [0.0; 3]).unwrap();
        let d =
            ((pb[0] - oa[0]).powi(2) + (pb[1] - oa[1]).powi(2) + (pb[2] - oa[2]).powi(2)).sqrt();
        assert!((d - (pa[0].hypot(pa[2]))).abs() < 1e-6);
        // Rotation of a covariance keeps trace and determinant; isotropic stays isotropic.
        let p = dmatrix![100.0, 10.0, 0.0; 10.0, 400.0, 5.0; 0.0, 5.0, 900.0];
        let q = fa.covariance_to(&fb, &p).unwrap();
        assert!((q.trace() - p.trace()).abs() < 1e-9);
        assert!((q.determinant() / p.determinant() - 1.0).abs() < 1e-12);
        assert!((q.clone() - q.transpose()).amax() == 0.0);
        let iso = DMatrix::identity(3, 3) * 25.0;
        assert!((fa.covariance_to(&fb, &iso).unwrap() - &iso).amax() < 1e-12);
        // Same frame: identity.
        assert!((fa.rotation_to(&fa) - Matrix3::identity()).amax() < 1e-15);
        assert!(fa.covariance_to(&fb, &DMatrix::identity(2, 2)).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// geodetic → ECEF → geodetic, including the poles, the equator and
        /// heights from −10 km to 100 000 km, on three ellipsoids.
        #[test]
        fn geodetic_round_trip(
            lat in prop_oneof![
                Just(FRAC_PI_2), Just(-FRAC_PI_2), Just(0.0),
                -FRAC_PI_2..FRAC_PI_2,
                (FRAC_PI_2 - 1e-6)..FRAC_PI_2,
            ],
            lon in -PI..PI,
            h in prop_oneof![-1e4..1e4f64, 1e4..1e8f64],
            which in 0usize..3,
        ) {
            let ell = [Ellipsoid::WGS84, Ellipsoid::GRS80, Ellipsoid::KRASOVSKY_1940][which];
            let p = geodetic_to_ecef(&ell, lat, lon, h).unwrap();
            let (lat2, lon2, h2) = ecef_to_geodetic(&ell, p).unwrap();
            prop_assert!((lat2 - lat).abs() < 1e-12, "lat {lat} {lat2}");
            prop_assert!((h2 - h).abs() < 1e-6 * (1.0 + h.abs() / 1e7), "h {h} {h2}");
            // Longitude is undefined on the axis; compare the horizontal offset instead.
            let rho = p[0].hypot(p[1]);
            prop_assert!(rho * wrap_angle(lon2 - lon).abs() < 1e-6);
            // And back: ECEF agrees to well under a millimetre.
            let p2 = geodetic_to_ecef(&ell, lat2, lon2, h2).unwrap();
            prop_assert!(close3(p, p2, 1e-6 * (1.0 + h.abs() / 1e7)));
        }

        /// ENU ↔ ECEF round trip and norm preservation.
        #[test]
        fn enu_round_trip(
            lat in -FRAC_PI_2..FRAC_PI_2, lon in -PI..PI,
            e in -1e5..1e5f64, n in -1e5..1e5f64, u in -1e3..2e4f64,
        ) {
            let fr = LocalFrame::new(WGS84, lat, lon, 0.0).unwrap();
            let x = fr.enu_to_ecef([e, n, u]).unwrap();
            let back = fr.ecef_to_enu(x).unwrap();
            prop_assert!(close3(back, [e, n, u], 1e-6));
            let o = fr.origin_ecef();
            let d = ((x[0] - o[0]).powi(2) + (x[1] - o[1]).powi(2) + (x[2] - o[2]).powi(2)).sqrt();
            prop_assert!((d - (e * e + n * n + u * u).sqrt()).abs() < 1e-6);
        }
    }
}
