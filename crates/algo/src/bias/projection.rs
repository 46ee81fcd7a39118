//! Transverse Mercator (Gauss–Krüger) projection by Krüger's series in the
//! third flattening n, to order n⁶, as given by C. F. F. Karney,
//! "Transverse Mercator with an accuracy of a few nanometers", Journal of
//! Geodesy 85 (2011) 475–485, eqs. (7)–(11), (35) and (36). Within a few
//! thousand kilometres of the central meridian the error is far below a
//! millimetre, so this replaces seed 004's truncated eq. 2.
//!
//! [`LocalPlane`] is seed 004 §2.1's "sea-surface local plane": the
//! projection about the radar's meridian with scale 1, its origin moved to
//! the radar site, axes east and north (m). Angles in radians.

use crate::error::{AlgoError, finite};
use crate::geo::Ellipsoid;

/// A transverse Mercator projection of one ellipsoid about a central
/// meridian, with scale k0 on that meridian and no false origin: x is the
/// easting, y the northing from the equator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransverseMercator {
    ellipsoid: Ellipsoid,
    lon0: f64,
    k0: f64,
    /// Rectifying radius A (Karney eq. 14).
    big_a: f64,
    e: f64,
    alpha: [f64; 6],
    beta: [f64; 6],
}

impl TransverseMercator {
    /// The projection about central meridian `lon0` with scale `k0 > 0`.
    pub fn new(ellipsoid: Ellipsoid, lon0: f64, k0: f64) -> Result<Self, AlgoError> {
        finite("central_meridian", lon0)?;
        finite("scale_factor", k0)?;
        if k0 <= 0.0 {
            return Err(AlgoError::InvalidParameter {
                what: "scale_factor",
                reason: format!("must be > 0, got {k0}"),
            });
        }
        let f = ellipsoid.f();
        let n = f / (2.0 - f);
        let n2 = n * n;
        let n3 = n2 * n;
        let n4 = n3 * n;
        let n5 = n4 * n;
        let n6 = n5 * n;
        let big_a = ellipsoid.a() / (1.0 + n) * (1.0 + n2 / 4.0 + n4 / 64.0 + n6 / 256.0);
        // Karney (2011) eq. (35).
        let alpha = [
            n / 2.0 - 2.0 / 3.0 * n2 + 5.0 / 16.0 * n3 + 41.0 / 180.0 * n4 - 127.0 / 288.0 * n5
                + 7891.0 / 37800.0 * n6,
            13.0 / 48.0 * n2 - 3.0 / 5.0 * n3 + 557.0 / 1440.0 * n4 + 281.0 / 630.0 * n5
                - 1_983_433.0 / 1_935_360.0 * n6,
            61.0 / 240.0 * n3 - 103.0 / 140.0 * n4
                + 15061.0 / 26880.0 * n5
                + 167_603.0 / 181_440.0 * n6,
            49561.0 / 161_280.0 * n4 - 179.0 / 168.0 * n5 + 6_601_661.0 / 7_257_600.0 * n6,
            34729.0 / 80640.0 * n5 - 3_418_889.0 / 1_995_840.0 * n6,
            212_378_941.0 / 319_334_400.0 * n6,
        ];
        // Karney (2011) eq. (36).
        let beta = [
            n / 2.0 - 2.0 / 3.0 * n2 + 37.0 / 96.0 * n3 - 1.0 / 360.0 * n4 - 81.0 / 512.0 * n5
                + 96199.0 / 604_800.0 * n6,
            n2 / 48.0 + n3 / 15.0 - 437.0 / 1440.0 * n4 + 46.0 / 105.0 * n5
                - 1_118_711.0 / 3_870_720.0 * n6,
            17.0 / 480.0 * n3 - 37.0 / 840.0 * n4 - 209.0 / 4480.0 * n5 + 5569.0 / 90720.0 * n6,
            4397.0 / 161_280.0 * n4 - 11.0 / 504.0 * n5 - 830_251.0 / 7_257_600.0 * n6,
            4583.0 / 161_280.0 * n5 - 108_847.0 / 3_991_680.0 * n6,
            20_648_693.0 / 638_668_800.0 * n6,
        ];
        Ok(Self {
            ellipsoid,
            lon0,
            k0,
            big_a,
            e: ellipsoid.e2().sqrt(),
            alpha,
            beta,
        })
    }

    /// The ellipsoid projected.
    pub fn ellipsoid(&self) -> Ellipsoid {
        self.ellipsoid
    }

    /// (easting, northing) in metres of geodetic (`lat`, `lon`).
    pub fn forward(&self, lat: f64, lon: f64) -> (f64, f64) {
        let lam = crate::polar::wrap_angle(lon - self.lon0);
        let tau = lat.tan();
        // Conformal latitude (Karney eqs. 7–9), valid up to the poles.
        let sigma = (self.e * (self.e * tau / tau.hypot(1.0)).atanh()).sinh();
        let tau_p = tau * sigma.hypot(1.0) - sigma * tau.hypot(1.0);
        let (xi_p, eta_p) = if lat.abs() >= std::f64::consts::FRAC_PI_2 {
            (std::f64::consts::FRAC_PI_2.copysign(lat), 0.0)
        } else {
            (
                tau_p.atan2(lam.cos()),
                (lam.sin() / tau_p.hypot(lam.cos())).asinh(),
            )
        };
        // Krüger series (eq. 11).
        let (mut xi, mut eta) = (xi_p, eta_p);
        for (j, a) in self.alpha.iter().enumerate() {
            let k = 2.0 * (j + 1) as f64;
            xi += a * (k * xi_p).sin() * (k * eta_p).cosh();
            eta += a * (k * xi_p).cos() * (k * eta_p).sinh();
        }
        (self.k0 * self.big_a * eta, self.k0 * self.big_a * xi)
    }

    /// Geodetic (lat, lon) of (`easting`, `northing`).
    pub fn inverse(&self, easting: f64, northing: f64) -> (f64, f64) {
        let xi = northing / (self.k0 * self.big_a);
        let eta = easting / (self.k0 * self.big_a);
        let (mut xi_p, mut eta_p) = (xi, eta);
        for (j, b) in self.beta.iter().enumerate() {
            let k = 2.0 * (j + 1) as f64;
            xi_p -= b * (k * xi).sin() * (k * eta).cosh();
            eta_p -= b * (k * xi).cos() * (k * eta).sinh();
        }
        let tau_p = xi_p.sin() / eta_p.sinh().hypot(xi_p.cos());
        let lam = eta_p.sinh().atan2(xi_p.cos());
        let tau = self.tau_from_conformal(tau_p);
        (tau.atan(), crate::polar::wrap_angle(self.lon0 + lam))
    }

    /// τ = tan φ from τ′ = tan χ by Newton's method (Karney eqs. 19–21).
    fn tau_from_conformal(&self, tau_p: f64) -> f64 {
        let e2 = self.ellipsoid.e2();
        let mut tau = tau_p;
        for _ in 0..8 {
            let sigma = (self.e * (self.e * tau / tau.hypot(1.0)).atanh()).sinh();
            let tau_i = tau * sigma.hypot(1.0) - sigma * tau.hypot(1.0);
            let d = (tau_p - tau_i) / tau_i.hypot(1.0) * (1.0 + (1.0 - e2) * tau * tau)
                / ((1.0 - e2) * tau.hypot(1.0));
            tau += d;
            if d.abs() <= 1e-15 * tau.abs().max(1.0) {
                break;
            }
        }
        tau
    }
}

/// Seed 004 §2.1's local plane: the Gauss–Krüger projection (scale 1) about
/// the radar's meridian, origin at the radar site; x east, y north (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalPlane {
    tm: TransverseMercator,
    origin_northing: f64,
}

impl LocalPlane {
    /// The plane of a radar at geodetic (`lat0`, `lon0`) (radians).
    pub fn new(ellipsoid: Ellipsoid, lat0: f64, lon0: f64) -> Result<Self, AlgoError> {
        finite("latitude", lat0)?;
        if lat0.abs() >= std::f64::consts::FRAC_PI_2 {
            return Err(AlgoError::InvalidParameter {
                what: "latitude",
                reason: "the radar must not stand on a pole".into(),
            });
        }
        let tm = TransverseMercator::new(ellipsoid, lon0, 1.0)?;
        let (_, origin_northing) = tm.forward(lat0, lon0);
        Ok(Self {
            tm,
            origin_northing,
        })
    }

    /// (east, north) of geodetic (`lat`, `lon`) relative to the radar.
    pub fn forward(&self, lat: f64, lon: f64) -> [f64; 2] {
        let (e, n) = self.tm.forward(lat, lon);
        [e, n - self.origin_northing]
    }

    /// Geodetic (lat, lon) of plane point [east, north].
    pub fn inverse(&self, p: [f64; 2]) -> (f64, f64) {
        self.tm.inverse(p[0], p[1] + self.origin_northing)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// GeographicLib's GeoConvert manual (C. F. F. Karney), example
    /// `echo 33.3 44.4 | GeoConvert -u` → `38n 444140.54 3684706.36`:
    /// WGS84 UTM zone 38 (central meridian 45°E, k0 = 0.9996, false easting
    /// 500 000 m), printed to the centimetre.
    #[test]
    fn wgs84_utm_matches_geoconvert() {
        let tm = TransverseMercator::new(Ellipsoid::WGS84, 45f64.to_radians(), 0.9996).unwrap();
        let (x, y) = tm.forward(33.3f64.to_radians(), 44.4f64.to_radians());
        assert!(
            (x + 500_000.0 - 444_140.54).abs() < 0.006,
            "{}",
            x + 500_000.0
        );
        assert!((y - 3_684_706.36).abs() < 0.006, "{y}");
    }

    /// Krasovsky 1940: seed 004 eq. 2 publishes the Gauss–Krüger meridian
    /// arc of that ellipsoid as S(φ) = a(1 − e²)(Aφ − B/2 sin 2φ + C/4 sin 4φ
    /// − D/6 sin 6φ) with A = 1.0050517739, B = 0.005062377, C = 0.0000106245,
    /// D = 0.0000000208, e² = 0.006693421623. On the central meridian the
    /// northing is S(φ); the coefficients carry ~10 significant digits, so
    /// agreement to 1 cm over 6 000 km is what they allow.
    #[test]
    fn krasovsky_meridian_arc_matches_the_published_series() {
        let tm = TransverseMercator::new(Ellipsoid::KRASOVSKY_1940, 0.0, 1.0).unwrap();
        let (a, e2) = (6_378_245.0, 0.006_693_421_623);
        let (ca, cb, cc, cd) = (
            1.005_051_773_9,
            0.005_062_377,
            0.000_010_624_5,
            0.000_000_020_8,
        );
        for deg in [10.0f64, 30.0, 37.5, 45.0, 60.0] {
            let p = deg.to_radians();
            let s = a
                * (1.0 - e2)
                * (ca * p - cb / 2.0 * (2.0 * p).sin() + cc / 4.0 * (4.0 * p).sin()
                    - cd / 6.0 * (6.0 * p).sin());
            let (x, y) = tm.forward(p, 0.0);
            assert!(x.abs() < 1e-9);
            assert!((y - s).abs() < 0.01, "{deg}: {y} vs {s}");
        }
    }

    /// Krasovsky 1940 off the meridian: eq. 2's second line, the easting
    /// N cos φ Δλ (N = a/√(1 − e² sin² φ)), is the first term of the series,
    /// exact to O(Δλ³): at 37.5°N and Δλ = 0.01° (≈ 880 m) the cubic term is
    /// N cos φ Δλ³ (cos² φ)(1 − t² + η²)/6 ≈ 1e-7 m.
    #[test]
    fn krasovsky_easting_matches_eq_2_near_the_meridian() {
        let (lat, dl) = (37.5f64.to_radians(), 0.01f64.to_radians());
        let tm = TransverseMercator::new(Ellipsoid::KRASOVSKY_1940, 0.0, 1.0).unwrap();
        let (x, _) = tm.forward(lat, dl);
        let e2 = Ellipsoid::KRASOVSKY_1940.e2();
        let n = 6_378_245.0 / (1.0 - e2 * lat.sin().powi(2)).sqrt();
        assert!((x - n * lat.cos() * dl).abs() < 1e-5, "{x}");
    }

    #[test]
    fn inverse_round_trips_to_nanometres() {
        for ell in [
            Ellipsoid::WGS84,
            Ellipsoid::KRASOVSKY_1940,
            Ellipsoid::GRS80,
        ] {
            let plane = LocalPlane::new(ell, 0.6, 2.1).unwrap();
            for (dlat, dlon) in [(0.0, 0.0), (0.01, -0.02), (-0.2, 0.3), (0.5, 0.05)] {
                let (lat, lon) = (0.6 + dlat, 2.1 + dlon);
                let p = plane.forward(lat, lon);
                let (lat2, lon2) = plane.inverse(p);
                assert!((lat - lat2).abs() < 1e-14 && (lon - lon2).abs() < 1e-14);
            }
            assert_eq!(plane.forward(0.6, 2.1), [0.0, 0.0]);
        }
    }
}
