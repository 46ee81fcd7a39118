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
    /// φ − χ = Σ δⱼ sin 2jχ, geodetic from conformal latitude.
    delta: [f64; 6],
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
        // Geodetic from conformal latitude: the classical series in n to n⁶
        // (Krüger 1912); the n⁷ terms are ~1e-19 rad. The test checks it
        // against Newton's method on the exact relation (Karney eqs. 19–21).
        let delta = [
            2.0 * n - 2.0 / 3.0 * n2 - 2.0 * n3 + 116.0 / 45.0 * n4 + 26.0 / 45.0 * n5
                - 2854.0 / 675.0 * n6,
            7.0 / 3.0 * n2 - 8.0 / 5.0 * n3 - 227.0 / 45.0 * n4
                + 2704.0 / 315.0 * n5
                + 2323.0 / 945.0 * n6,
            56.0 / 15.0 * n3 - 136.0 / 35.0 * n4 - 1262.0 / 105.0 * n5 + 73814.0 / 2835.0 * n6,
            4279.0 / 630.0 * n4 - 332.0 / 35.0 * n5 - 399_572.0 / 14175.0 * n6,
            4174.0 / 315.0 * n5 - 144_838.0 / 6237.0 * n6,
            601_676.0 / 22275.0 * n6,
        ];
        Ok(Self {
            ellipsoid,
            lon0,
            k0,
            big_a,
            e: ellipsoid.e2().sqrt(),
            alpha,
            beta,
            delta,
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
        let sec = tau.hypot(1.0);
        let sigma = (self.e * (self.e * tau / sec).atanh()).sinh();
        let tau_p = tau * sigma.hypot(1.0) - sigma * sec;
        let (xi_p, eta_p) = if lat.abs() >= std::f64::consts::FRAC_PI_2 {
            (std::f64::consts::FRAC_PI_2.copysign(lat), 0.0)
        } else {
            (
                tau_p.atan2(lam.cos()),
                (lam.sin() / tau_p.hypot(lam.cos())).asinh(),
            )
        };
        // Krüger series (eq. 11).
        let (dxi, deta) = krueger_series(&self.alpha, xi_p, eta_p);
        let (xi, eta) = (xi_p + dxi, eta_p + deta);
        (self.k0 * self.big_a * eta, self.k0 * self.big_a * xi)
    }

    /// Geodetic (lat, lon) of (`easting`, `northing`).
    ///
    /// One sine and cosine (of ξ) and one `expm1` (for sinh η and cosh η)
    /// serve the whole inverse: the Krüger series reads the double angles
    /// of ξ and η, the sines of ξ′ = ξ − Δξ and η′ = η − Δη follow by the
    /// angle-sum formulas with short series of the small Δ (|Δ| ≤ 2e-3 on
    /// the Earth: the series' error is below 1e-20), and the conformal
    /// latitude's double angle is algebraic in them. Before issue 54's
    /// second part it took four sines and cosines and three hyperbolic
    /// functions; the test holds it to that form (`inverse_reference`).
    pub fn inverse(&self, easting: f64, northing: f64) -> (f64, f64) {
        let xi = northing / (self.k0 * self.big_a);
        let eta = easting / (self.k0 * self.big_a);
        let (s1, c1) = xi.sin_cos();
        let (sh1, ch1) = sinh_cosh(eta);
        // sin 2ξ, cos 2ξ, sinh 2η, cosh 2η.
        let (s2, c2) = (2.0 * s1 * c1, (c1 - s1) * (c1 + s1));
        let (sh2, ch2) = (2.0 * sh1 * ch1, sh1.mul_add(sh1, ch1 * ch1));
        let (dxi, deta) = krueger_sum(&self.beta, s2, c2, sh2, ch2);
        // sin ξ′, cos ξ′, sinh η′ of ξ′ = ξ − Δξ, η′ = η − Δη.
        let (sd, cd) = small_sin_cos(dxi);
        let (shd, chd) = small_sinh_cosh(deta);
        let sin_xi = s1.mul_add(cd, -(c1 * sd));
        let cos_xi = c1.mul_add(cd, s1 * sd);
        let sinh_eta = sh1.mul_add(chd, -(ch1 * shd));
        // The conformal latitude χ (tan χ = τ′); both terms
        // of the root are at most a few units.
        let q2 = sinh_eta.mul_add(sinh_eta, cos_xi * cos_xi);
        let q = q2.sqrt();
        let chi = sin_xi.atan2(q);
        let lam = sinh_eta.atan2(cos_xi);
        // sin 2χ and cos 2χ from sin χ ∝ sin ξ′ and cos χ ∝ q.
        let r2 = sin_xi.mul_add(sin_xi, q2);
        let (s2chi, c2chi) = (2.0 * sin_xi * q / r2, (q2 - sin_xi * sin_xi) / r2);
        let lat = chi + clenshaw_sine(&self.delta, s2chi, c2chi);
        (lat, crate::polar::wrap_angle(self.lon0 + lam))
    }

    /// The inverse as it was before issue 54's second part (a sine and
    /// cosine or a hyperbolic function per angle): the test's reference.
    #[cfg(test)]
    fn inverse_reference(&self, easting: f64, northing: f64) -> (f64, f64) {
        let xi = northing / (self.k0 * self.big_a);
        let eta = easting / (self.k0 * self.big_a);
        let (dxi, deta) = krueger_series(&self.beta, xi, eta);
        let (xi_p, eta_p) = (xi - dxi, eta - deta);
        let (sin_xi, cos_xi) = xi_p.sin_cos();
        let sinh_eta = eta_p.sinh();
        let chi = sin_xi.atan2(sinh_eta.mul_add(sinh_eta, cos_xi * cos_xi).sqrt());
        let lam = sinh_eta.atan2(cos_xi);
        let lat = chi + sine_series(&self.delta, chi);
        (lat, crate::polar::wrap_angle(self.lon0 + lam))
    }

    /// The reference for the χ → φ series, the inverse's method before
    /// issue 54: τ = tan φ from τ′ = tan χ by Newton's method (Karney eqs.
    /// 19–21).
    #[cfg(test)]
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

/// Σⱼ cⱼ sin(2jx) by Clenshaw's recurrence (one sine and cosine).
#[cfg(test)]
fn sine_series(c: &[f64; 6], x: f64) -> f64 {
    let (s, co) = (2.0 * x).sin_cos();
    clenshaw_sine(c, s, co)
}

/// Σⱼ cⱼ sin(2jx) from `s` = sin 2x and `co` = cos 2x (Clenshaw).
#[inline(always)]
fn clenshaw_sine(c: &[f64; 6], s: f64, co: f64) -> f64 {
    let a = 2.0 * co;
    let (mut y1, mut y2) = (0.0, 0.0);
    for &ck in c.iter().rev() {
        (y2, y1) = (y1, ck + a * y1 - y2);
    }
    s * y1
}

/// (sinh x, cosh x) from one `expm1`, without the cancellation of
/// (eˣ − e⁻ˣ)/2 near 0.
fn sinh_cosh(x: f64) -> (f64, f64) {
    let em = x.exp_m1();
    let inv = 1.0 / (1.0 + em);
    (0.5 * em * (1.0 + inv), 0.5 * (1.0 + em + inv))
}

/// (sin d, cos d): Taylor series for |d| ≤ 0.01 (truncated after d⁸: the
/// rest is below d⁹/9! ≈ 3e-24, 3e-22 of d), else the library's.
fn small_sin_cos(d: f64) -> (f64, f64) {
    if d.abs() > 0.01 {
        return d.sin_cos();
    }
    taylor_sin_cos(d)
}

/// The series of [`small_sin_cos`], for any d (accurate for |d| ≤ 0.01).
#[inline(always)]
fn taylor_sin_cos(d: f64) -> (f64, f64) {
    let d2 = d * d;
    // The reciprocals are constants: multiplications, not divisions.
    let s = d * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0) * (1.0 - d2 * (1.0 / 42.0))));
    let c = 1.0
        - d2 * 0.5
            * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0) * (1.0 - d2 * (1.0 / 56.0))));
    (s, c)
}

/// (sinh d, cosh d): Taylor series for |d| ≤ 0.01, else [`sinh_cosh`].
fn small_sinh_cosh(d: f64) -> (f64, f64) {
    if d.abs() > 0.01 {
        return sinh_cosh(d);
    }
    taylor_sinh_cosh(d)
}

/// The series of [`small_sinh_cosh`], for any d (accurate for |d| ≤ 0.01).
#[inline(always)]
fn taylor_sinh_cosh(d: f64) -> (f64, f64) {
    let d2 = d * d;
    let s = d * (1.0 + d2 * (1.0 / 6.0) * (1.0 + d2 * (1.0 / 20.0) * (1.0 + d2 * (1.0 / 42.0))));
    let c = 1.0
        + d2 * 0.5
            * (1.0 + d2 * (1.0 / 12.0) * (1.0 + d2 * (1.0 / 30.0) * (1.0 + d2 * (1.0 / 56.0))));
    (s, c)
}

/// atan u by its Taylor series, for |u| ≤ 0.02 (the first term left out,
/// u¹³/13, is below 3e-22 of u).
#[inline(always)]
fn atan_small(u: f64) -> f64 {
    let u2 = u * u;
    u * (1.0
        - u2 * (1.0 / 3.0
            - u2 * (1.0 / 5.0 - u2 * (1.0 / 7.0 - u2 * (1.0 / 9.0 - u2 * (1.0 / 11.0))))))
}

/// Σⱼ cⱼ sin(2jζ) for ζ = ξ + iη as (real, imaginary) parts: Karney (2011)
/// eq. (11) and its inverse, by Clenshaw's recurrence in complex arithmetic,
/// so one sine, cosine, sinh and cosh serve all six terms instead of six of
/// each. Agrees with the term-by-term sum to rounding (test).
fn krueger_series(c: &[f64; 6], xi: f64, eta: f64) -> (f64, f64) {
    let (s, co) = (2.0 * xi).sin_cos();
    let (sh, ch) = ((2.0 * eta).sinh(), (2.0 * eta).cosh());
    krueger_sum(c, s, co, sh, ch)
}

/// [`krueger_series`] from sin 2ξ, cos 2ξ, sinh 2η and cosh 2η.
#[inline(always)]
fn krueger_sum(c: &[f64; 6], s: f64, co: f64, sh: f64, ch: f64) -> (f64, f64) {
    // 2 cos 2ζ and sin 2ζ.
    let (ar, ai) = (2.0 * co * ch, -2.0 * s * sh);
    let (sr, si) = (s * ch, co * sh);
    // y_k = c_k + 2 cos(2ζ) y_{k+1} − y_{k+2}, from k = 6 down to 1.
    let (mut y1r, mut y1i, mut y2r, mut y2i) = (0.0, 0.0, 0.0, 0.0);
    for &ck in c.iter().rev() {
        let y0r = ck + ar * y1r - ai * y1i - y2r;
        let y0i = ar * y1i + ai * y1r - y2i;
        (y2r, y2i, y1r, y1i) = (y1r, y1i, y0r, y0i);
    }
    (sr * y1r - si * y1i, sr * y1i + si * y1r)
}

/// Seed 004 §2.1's local plane: the Gauss–Krüger projection (scale 1) about
/// the radar's meridian, origin at the radar site; x east, y north (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalPlane {
    tm: TransverseMercator,
    origin_northing: f64,
    near: Near,
}

/// What [`LocalPlane::inverse`] needs of the site for points near it: the
/// reciprocal of the projection's scale k0·A, the sine and cosine of the
/// site's ξ₀ = northing / (k0·A), and a reference conformal latitude χ₀
/// (the site's) with its sine and cosine.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Near {
    inv_scale: f64,
    sin_xi0: f64,
    cos_xi0: f64,
    chi0: f64,
    sin_chi0: f64,
    cos_chi0: f64,
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
        let scale = tm.k0 * tm.big_a;
        let xi0 = origin_northing / scale;
        let (sin_xi0, cos_xi0) = xi0.sin_cos();
        // On the central meridian (η = 0) χ = ξ′ = ξ − Δξ.
        let chi0 = xi0 - krueger_series(&tm.beta, xi0, 0.0).0;
        let (sin_chi0, cos_chi0) = chi0.sin_cos();
        Ok(Self {
            tm,
            origin_northing,
            near: Near {
                inv_scale: 1.0 / scale,
                sin_xi0,
                cos_xi0,
                chi0,
                sin_chi0,
                cos_chi0,
            },
        })
    }

    /// (east, north) of geodetic (`lat`, `lon`) relative to the radar.
    pub fn forward(&self, lat: f64, lon: f64) -> [f64; 2] {
        let (e, n) = self.tm.forward(lat, lon);
        [e, n - self.origin_northing]
    }

    /// Geodetic (lat, lon) of plane point [east, north].
    ///
    /// [`TransverseMercator::inverse`] in a form local to the site, for
    /// points within about 60 km of it (east and north under 0.01 of the
    /// scale k0·A, and latitude and longitude under 0.02 rad from the
    /// site's): sin ξ and cos ξ by the angle-sum formulas from the site's
    /// and Taylor series of the small ξ − ξ₀ and η, the conformal latitude
    /// as χ₀ + atan(tan(χ − χ₀)) and the longitude as atan(sinh η′ / cos ξ′),
    /// each small atan by its series: the same relations to rounding
    /// without a call to the library (no sine, hyperbolic function or
    /// atan2), equal to the general inverse to a few units of the last
    /// place (test). Points further out take the general inverse.
    pub fn inverse(&self, p: [f64; 2]) -> (f64, f64) {
        match self.near_inverse(p) {
            (lat, lon, true) => (lat, wrap_longitude(lon)),
            _ => self.tm.inverse(p[0], p[1] + self.origin_northing),
        }
    }

    /// [`LocalPlane::inverse`] of every point, in order, with the same bits:
    /// the local form runs over all of them without a branch (on x86-64
    /// with AVX2 in 4-wide registers, each operation the same IEEE one), then
    /// the points beyond its reach take the general inverse.
    pub fn inverse_many(&self, points: &[[f64; 2]]) -> Vec<(f64, f64)> {
        let mut out = vec![(0.0, 0.0); points.len()];
        let mut near = vec![false; points.len()];
        self.near_batch(points, &mut out, &mut near);
        for ((o, &ok), p) in out.iter_mut().zip(&near).zip(points) {
            *o = if ok {
                (o.0, wrap_longitude(o.1))
            } else {
                self.tm.inverse(p[0], p[1] + self.origin_northing)
            };
        }
        out
    }

    fn near_batch(&self, points: &[[f64; 2]], out: &mut [(f64, f64)], near: &mut [bool]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { self.near_batch_avx2(points, out, near) };
        }
        self.near_batch_portable(points, out, near);
    }

    /// [`LocalPlane::near_batch_portable`] compiled with AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn near_batch_avx2(
        &self,
        points: &[[f64; 2]],
        out: &mut [(f64, f64)],
        near: &mut [bool],
    ) {
        self.near_batch_portable(points, out, near);
    }

    #[inline(always)]
    fn near_batch_portable(&self, points: &[[f64; 2]], out: &mut [(f64, f64)], near: &mut [bool]) {
        for ((p, o), ok) in points.iter().zip(out.iter_mut()).zip(near.iter_mut()) {
            let (lat, lon, n) = self.near_inverse(*p);
            (*o, *ok) = ((lat, lon), n);
        }
    }

    /// The local form of [`LocalPlane::inverse`] (longitude not wrapped)
    /// and whether `p` is within its reach; branch-free, so that a loop of
    /// it vectorises.
    #[inline(always)]
    fn near_inverse(&self, p: [f64; 2]) -> (f64, f64, bool) {
        let nr = &self.near;
        let (d, eta) = (p[1] * nr.inv_scale, p[0] * nr.inv_scale);
        // sin ξ, cos ξ of ξ = ξ₀ + d; sinh η, cosh η.
        let (sd, cd) = taylor_sin_cos(d);
        let s1 = nr.sin_xi0 * cd + nr.cos_xi0 * sd;
        let c1 = nr.cos_xi0 * cd - nr.sin_xi0 * sd;
        let (sh1, ch1) = taylor_sinh_cosh(eta);
        // The rest as in `TransverseMercator::inverse`.
        let (s2, c2) = (2.0 * s1 * c1, (c1 - s1) * (c1 + s1));
        let (sh2, ch2) = (2.0 * sh1 * ch1, sh1 * sh1 + ch1 * ch1);
        let (dxi, deta) = krueger_sum(&self.tm.beta, s2, c2, sh2, ch2);
        let (sd, cd) = taylor_sin_cos(dxi);
        let (shd, chd) = taylor_sinh_cosh(deta);
        let sin_xi = s1 * cd - c1 * sd;
        let cos_xi = c1 * cd + s1 * sd;
        let sinh_eta = sh1 * chd - ch1 * shd;
        let q2 = sinh_eta * sinh_eta + cos_xi * cos_xi;
        let q = q2.sqrt();
        // tan(χ − χ₀) (sin χ ∝ sin ξ′, cos χ ∝ q) and tan λ.
        let den = q * nr.cos_chi0 + sin_xi * nr.sin_chi0;
        let u = (sin_xi * nr.cos_chi0 - q * nr.sin_chi0) / den;
        let v = sinh_eta / cos_xi;
        let chi = nr.chi0 + atan_small(u);
        let inv_r2 = 1.0 / (sin_xi * sin_xi + q2);
        let (s2chi, c2chi) = (2.0 * sin_xi * q * inv_r2, (q2 - sin_xi * sin_xi) * inv_r2);
        let lat = chi + clenshaw_sine(&self.tm.delta, s2chi, c2chi);
        let lon = self.tm.lon0 + atan_small(v);
        // Non-finite input fails every comparison.
        let small = |x: f64, r: f64| x.abs() <= r;
        let near = small(d, 0.01)
            & small(eta, 0.01)
            & small(dxi, 0.01)
            & small(deta, 0.01)
            & (den > 0.0)
            & (cos_xi > 0.0)
            & small(u, 0.02)
            & small(v, 0.02);
        (lat, lon, near)
    }
}

/// A longitude in (−π, π]: as it is when it already is (no rounding by
/// the wrap), else [`crate::polar::wrap_angle`].
fn wrap_longitude(lon: f64) -> f64 {
    if lon > -std::f64::consts::PI && lon <= std::f64::consts::PI {
        lon
    } else {
        crate::polar::wrap_angle(lon)
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

    /// The Clenshaw sum against the series summed term by term (the code
    /// before issue 54), over the plane's reach and beyond (ξ to ±1.4 rad,
    /// η to ±0.5, ~3,000 km off the meridian): equal to 1e-14 of the
    /// coefficients' scale, i.e. well under a nanometre on the Earth.
    #[test]
    fn clenshaw_series_matches_the_term_by_term_sum() {
        let tm = TransverseMercator::new(Ellipsoid::WGS84, 0.0, 1.0).unwrap();
        for c in [&tm.alpha, &tm.beta] {
            for i in -14..=14 {
                for j in -10..=10 {
                    let (xi, eta) = (0.1 * i as f64, 0.05 * j as f64);
                    let (mut re, mut im) = (0.0, 0.0);
                    for (k, a) in c.iter().enumerate() {
                        let m = 2.0 * (k + 1) as f64;
                        re += a * (m * xi).sin() * (m * eta).cosh();
                        im += a * (m * xi).cos() * (m * eta).sinh();
                    }
                    let (cr, ci) = krueger_series(c, xi, eta);
                    assert!((cr - re).abs() < 1e-14 * c[0], "{xi} {eta}: {cr} vs {re}");
                    assert!((ci - im).abs() < 1e-14 * c[0], "{xi} {eta}: {ci} vs {im}");
                }
            }
        }
    }

    /// The χ → φ series against Newton's method on the exact relation, from
    /// the equator to 89.99° on three ellipsoids: equal to 1e-15 rad (6 nm).
    #[test]
    fn conformal_series_matches_newton() {
        for ell in [
            Ellipsoid::WGS84,
            Ellipsoid::KRASOVSKY_1940,
            Ellipsoid::GRS80,
        ] {
            let tm = TransverseMercator::new(ell, 0.0, 1.0).unwrap();
            for i in -1000..=1000 {
                let chi = i as f64 * 1.5706 / 1000.0;
                let newton = tm.tau_from_conformal(chi.tan()).atan();
                let series = chi + sine_series(&tm.delta, chi);
                assert!(
                    (newton - series).abs() < 1e-15,
                    "{chi}: {newton} vs {series}"
                );
            }
        }
    }

    /// The inverse by one sine, cosine and `expm1` against its form before
    /// issue 54's second part (the library's sine, cosine, sinh and cosh of
    /// every angle) on three ellipsoids, over ξ to ±1.55 rad (88.8°) and η to
    /// ±0.5 (~3,000 km off the meridian) and out to η = ±3, where the
    /// corrections pass 0.01 and take the library's functions: equal to
    /// 2e-15 rad (13 nm) in latitude and in longitude times the cosine of
    /// the latitude (the arc on the ground; near the pole the longitude
    /// itself is ill-conditioned), a few units of the last place.
    #[test]
    fn inverse_matches_the_reference_form() {
        for ell in [
            Ellipsoid::WGS84,
            Ellipsoid::KRASOVSKY_1940,
            Ellipsoid::GRS80,
        ] {
            let tm = TransverseMercator::new(ell, 0.4, 1.0).unwrap();
            let scale = tm.big_a;
            let mut worst = 0.0f64;
            let etas = (-50..=50)
                .map(|j| 0.01 * j as f64)
                .chain([-3.0, -2.2, -1.3, 1.3, 2.2, 3.0]);
            for eta in etas {
                for i in -155..=155 {
                    let xi = 0.01 * i as f64;
                    let (e, n) = (eta * scale, xi * scale);
                    let (lat, lon) = tm.inverse(e, n);
                    let (lat_r, lon_r) = tm.inverse_reference(e, n);
                    // The longitude's difference as an arc on the parallel.
                    let dlon = (lon - lon_r).abs() * lat_r.cos();
                    worst = worst.max((lat - lat_r).abs()).max(dlon);
                    assert!(
                        (lat - lat_r).abs() < 2e-15 && dlon < 2e-15,
                        "{xi} {eta}: ({lat}, {lon}) vs ({lat_r}, {lon_r})"
                    );
                }
            }
            assert!(worst > 0.0, "the two forms are not the same code");
        }
        for d in [-0.02, -0.01, -1e-3, -1e-9, 0.0, 1e-7, 2e-3, 0.01, 0.03] {
            let (s, c) = small_sin_cos(d);
            let (sh, ch) = small_sinh_cosh(d);
            // Within an ulp or two of the library's.
            let ok = |a: f64, b: f64| (a - b).abs() <= 3e-16 * b.abs();
            assert!(ok(s, d.sin()) && ok(c, d.cos()), "{d}: {s} {c}");
            assert!(ok(sh, d.sinh()) && ok(ch, d.cosh()), "{d}: {sh} {ch}");
        }
        for x in [-3.0, -0.5, -1e-6, 0.0, 1e-12, 0.02, 1.0, 4.0] {
            let (sh, ch) = sinh_cosh(x);
            assert!((sh - x.sinh()).abs() <= 4e-16 * x.sinh().abs());
            assert!((ch - x.cosh()).abs() <= 4e-16 * x.cosh());
        }
    }

    /// The plane's inverse (local to the site within ~60 km, general beyond)
    /// against the general inverse's form before issue 54's second part, for
    /// sites on the equator, at 37°N, 52°S and 88.8°N, on a grid out to
    /// 150 km east and north (both forms are taken): equal to 2e-15 rad
    /// (13 nm) in latitude and in longitude times the cosine of the latitude.
    #[test]
    fn plane_inverse_matches_the_reference_form() {
        for (lat0, lon0) in [(0.0, 0.1), (0.65, -0.02), (-0.9, 3.1), (1.55, 0.3)] {
            let plane = LocalPlane::new(Ellipsoid::WGS84, lat0, lon0).unwrap();
            for i in -30..=30 {
                for j in -30..=30 {
                    let p = [5_000.0 * i as f64, 5_000.0 * j as f64 + 17.0];
                    let (lat, lon) = plane.inverse(p);
                    let (lat_r, lon_r) = plane
                        .tm
                        .inverse_reference(p[0], p[1] + plane.origin_northing);
                    let dlon = (crate::polar::wrap_angle(lon - lon_r)).abs() * lat_r.cos();
                    assert!(
                        (lat - lat_r).abs() < 2e-15 && dlon < 2e-15,
                        "site {lat0}: {p:?}: ({lat}, {lon}) vs ({lat_r}, {lon_r})"
                    );
                }
            }
        }
    }

    /// `inverse_many` gives the bits of `inverse` point by point, with AVX2
    /// and without, on both sides of the local form's reach (out to 150 km
    /// and across the antimeridian).
    #[test]
    fn inverse_many_gives_the_bits_of_inverse() {
        for (lat0, lon0) in [(0.65, -0.02), (-0.9, 3.13), (1.55, 0.3)] {
            let plane = LocalPlane::new(Ellipsoid::WGS84, lat0, lon0).unwrap();
            let points: Vec<[f64; 2]> = (-30..=30)
                .flat_map(|i| {
                    (-30..=30).map(move |j| [5_000.0 * i as f64 + 0.3, 5_000.0 * j as f64])
                })
                .chain([[f64::NAN, 0.0], [1e7, 1e6]])
                .collect();
            let many = plane.inverse_many(&points);
            let (mut lat_p, mut near_p) =
                (vec![(0.0, 0.0); points.len()], vec![false; points.len()]);
            plane.near_batch_portable(&points, &mut lat_p, &mut near_p);
            assert!(near_p.iter().any(|&n| n) && near_p.iter().any(|&n| !n));
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                let (mut lat_a, mut near_a) =
                    (vec![(0.0, 0.0); points.len()], vec![false; points.len()]);
                unsafe { plane.near_batch_avx2(&points, &mut lat_a, &mut near_a) };
                assert_eq!(near_a, near_p);
                for (a, b) in lat_a.iter().zip(&lat_p) {
                    assert!(a.0.to_bits() == b.0.to_bits() && a.1.to_bits() == b.1.to_bits());
                }
            }
            for (p, m) in points.iter().zip(&many) {
                let one = plane.inverse(*p);
                assert!(
                    one.0.to_bits() == m.0.to_bits() && one.1.to_bits() == m.1.to_bits(),
                    "{p:?}: {one:?} vs {m:?}"
                );
            }
        }
    }

    /// Near the pole (latitudes 88.8°–89.98°) the round trip holds too.
    #[test]
    fn inverse_round_trips_near_the_pole() {
        let plane = LocalPlane::new(Ellipsoid::WGS84, 1.55, 0.3).unwrap();
        for (lat, dlon) in [(1.55, 0.01), (1.565, -0.2), (1.5704, 0.4)] {
            let p = plane.forward(lat, 0.3 + dlon);
            let (lat2, lon2) = plane.inverse(p);
            assert!((lat - lat2).abs() < 1e-14, "{lat} vs {lat2}");
            assert!((0.3 + dlon - lon2).abs() < 1e-11, "{dlon}: {lon2}");
        }
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
