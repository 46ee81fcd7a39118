//! Geometric height from Mode C: a plot's pressure altitude as a
//! measurement of the track's height, through a pressure-to-geometric
//! offset the tracker learns online from its 3D radars.
//!
//! A Mode C (or Mode S) reply gives the pressure altitude h_p: the height
//! of the 1013.25 hPa standard atmosphere's isobar the aircraft flies on,
//! quantised to 25 or 100 ft. The geometric height above the ellipsoid
//! differs from it by the sea-level pressure (QNH, tens of metres per 10
//! hPa), the air's temperature (a colder or warmer column is shorter or
//! taller in proportion, a few per cent of the height) and the geoid. Over
//! a region and an hour both are nearly constant, so
//!
//!   H = h_p + a + b·h_p,
//!
//! a linear model whose offset a and slope b the tracker learns by
//! recursive least squares from the plots of its 3D radars that carry a
//! validated Mode C: each gives the geometric height H_r of its range,
//! azimuth and elevation (variance ≈ (ρ cos ε σ_ε)² + (sin ε σ_ρ)²), so
//! y = H_r − h_p = a + b·h_p + noise. Thousands of plots of hundreds of
//! metres' noise each pin a and b to metres; old plots are forgotten with
//! a time constant of [`MEMORY_S`] (the weather changes). The prior
//! ([`ModeCHeight`]) is what a user knows (by default a = 0 ± 150 m,
//! b = 0 ± 0.04, an ISA deviation of about ±12 °C).
//!
//! A track's height is then updated with z = h_p + a + b·h_p, of variance
//! the quantisation's q²/12 plus the offset's own variance at h_p, through
//! H(x): the height above the ellipsoid of the ENU position x
//! ([`HeightDatum`]). The offset's error is common to every track (not
//! noise that averages out), so after the update the track's height
//! variance is kept at least the offset's variance at h_p (adding it back
//! to the height alone keeps P positive semi-definite: a Schmidt-style
//! consider update). The pressure altitude a track reports stays as the
//! reply gave it ([`super::identity::PressureAltitude`]), apart from the
//! geometric height, as air traffic control keeps them.

use crate::error::AlgoError;

/// One foot (m).
pub const FT_M: f64 = 0.3048;

/// Time constant of forgetting old offset observations (s): one hour.
pub const MEMORY_S: f64 = 3600.0;

/// Gate of an offset observation against the current estimate (σ of the
/// residual): a plot further off (a false reply, a wrong association) is
/// not learnt from.
const OFFSET_GATE_SIGMAS: f64 = 4.0;

/// Model error of the linear offset (m): what the straight line misses of
/// a real atmosphere's profile.
const MODEL_SIGMA_M: f64 = 5.0;

/// How the fusion frame's `up` relates to the height above the ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HeightDatum {
    /// Local sites: `up` is the height.
    Flat,
    /// East-north-up at an origin of ellipsoidal height `origin_height`,
    /// with the ellipsoid's radii of curvature there: `meridian` (M) and
    /// `prime_vertical` (N), metres.
    Tangent {
        /// Ellipsoidal height of the origin (m).
        origin_height: f64,
        /// Meridian radius of curvature M at the origin (m).
        meridian: f64,
        /// Prime-vertical radius of curvature N at the origin (m).
        prime_vertical: f64,
    },
}

impl HeightDatum {
    /// The height above the ellipsoid of the ENU point (e, n, u) and its
    /// gradient in (e, n, u). In a tangent frame the earth along the
    /// point's azimuth α is the sphere of Euler's normal-section radius
    /// 1/R = cos²α/M + sin²α/N through the origin, so with ρ² = e² + n²,
    /// D = √(ρ² + (R + h₀ + u)²): H = D − R, ∂H/∂e = e/D, ∂H/∂n = n/D,
    /// ∂H/∂u = (R + h₀ + u)/D (R's change with α neglected: a relative
    /// ρ²/2R² of the gradient).
    pub fn height(&self, e: f64, n: f64, u: f64) -> (f64, [f64; 3]) {
        match *self {
            Self::Flat => (u, [0.0, 0.0, 1.0]),
            Self::Tangent {
                origin_height,
                meridian,
                prime_vertical,
            } => {
                let rho2 = e * e + n * n;
                let r = if rho2 > 0.0 {
                    rho2 / (n * n / meridian + e * e / prime_vertical)
                } else {
                    meridian
                };
                let c = r + origin_height + u;
                let d = (rho2 + c * c).sqrt();
                (d - r, [e / d, n / d, c / d])
            }
        }
    }
}

impl HeightDatum {
    /// Checks a tangent datum's numbers (radii of an earth-sized
    /// ellipsoid, a height on or near it).
    pub fn validate(&self) -> Result<(), AlgoError> {
        if let Self::Tangent {
            origin_height,
            meridian,
            prime_vertical,
        } = *self
        {
            let radius = 5.0e6..=8.0e6;
            if !(origin_height.is_finite()
                && origin_height.abs() <= 1.0e5
                && radius.contains(&meridian)
                && radius.contains(&prime_vertical))
            {
                return Err(crate::tracking::parameter::invalid(
                    crate::tracking::TrackerParameter::HeightDatum,
                    format!(
                        "an origin height within ±100 km and radii of curvature in [5000, 8000] km, got {origin_height} m, {meridian} m, {prime_vertical} m"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// What the user knows of the pressure-to-geometric offset (the prior of
/// the learnt one) and whether Mode C feeds the tracks' heights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeCHeight {
    /// Mode C updates the geometric height (default true).
    pub enabled: bool,
    /// Prior offset a (m) at pressure altitude 0.
    pub offset: f64,
    /// Its σ (m), > 0.
    pub sigma_offset: f64,
    /// Prior slope b (dimensionless: metres of geometric height per metre
    /// of pressure altitude, beyond 1).
    pub slope: f64,
    /// Its σ, > 0.
    pub sigma_slope: f64,
    /// The offset is learnt from 3D radars' plots (default true); false
    /// keeps the prior.
    pub learn: bool,
}

impl Default for ModeCHeight {
    fn default() -> Self {
        Self {
            enabled: true,
            offset: 0.0,
            sigma_offset: 150.0,
            slope: 0.0,
            sigma_slope: 0.04,
            learn: true,
        }
    }
}

impl ModeCHeight {
    /// Checks the prior.
    pub fn validate(&self) -> Result<(), AlgoError> {
        use crate::tracking::parameter::{TrackerParameter as P, invalid as bad};
        if !(self.offset.is_finite() && self.offset.abs() <= 2000.0) {
            return Err(bad(P::ModeCHeightOffset, "must be finite, within ±2000 m"));
        }
        if !(self.sigma_offset.is_finite()
            && self.sigma_offset > 0.0
            && self.sigma_offset <= 2000.0)
        {
            return Err(bad(P::ModeCHeightSigmaOffset, "must be in (0, 2000] m"));
        }
        if !(self.slope.is_finite() && self.slope.abs() <= 0.5) {
            return Err(bad(P::ModeCHeightSlope, "must be finite, within ±0.5"));
        }
        if !(self.sigma_slope.is_finite() && self.sigma_slope > 0.0 && self.sigma_slope <= 0.5) {
            return Err(bad(P::ModeCHeightSigmaSlope, "must be in (0, 0.5]"));
        }
        Ok(())
    }
}

/// The data part of the offset's least squares (the prior is the
/// configuration's): Σ w hhᵀ and Σ w h y over the observations, h = (1,
/// h_p in km), y = H_r − h_p, w = 1/σ², each decayed by exp(−Δt/τ).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PressureOffset {
    /// Σ w hhᵀ: [(1,1), (1,2), (2,2)], h_p in km.
    pub information: [f64; 3],
    /// Σ w h y: [1, 2] (m).
    pub vector: [f64; 2],
    /// Time of the last observation (decay reference), if any.
    pub t: Option<f64>,
    /// Observations learnt from (ever).
    pub plots: u64,
    /// Observations refused by the gate (ever).
    pub rejected: u64,
}

/// The offset's estimate: a + b·h_p (h_p in m) and its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetEstimate {
    /// a (m).
    pub offset: f64,
    /// b.
    pub slope: f64,
    /// Covariance of (a, b in m per km): [(1,1), (1,2), (2,2)].
    pub covariance: [f64; 3],
}

impl OffsetEstimate {
    /// The offset at pressure altitude `h_p` (m) and its variance (m²).
    pub fn at(&self, h_p: f64) -> (f64, f64) {
        let k = h_p / 1000.0;
        let [caa, cab, cbb] = self.covariance;
        (
            self.offset + self.slope * h_p,
            (caa + 2.0 * k * cab + k * k * cbb).max(0.0),
        )
    }

    /// σ of the offset (m) at pressure altitude 0.
    pub fn sigma_offset(&self) -> f64 {
        self.covariance[0].sqrt()
    }

    /// σ of the slope.
    pub fn sigma_slope(&self) -> f64 {
        self.covariance[2].sqrt() / 1000.0
    }
}

impl PressureOffset {
    /// The estimate: prior plus data, (I₀ + I)⁻¹ (I₀ θ₀ + v).
    pub fn estimate(&self, prior: &ModeCHeight) -> OffsetEstimate {
        // The slope in m per km of pressure altitude keeps the 2×2 well
        // scaled.
        let (s0, s1) = (prior.sigma_offset, prior.sigma_slope * 1000.0);
        let (t0, t1) = (prior.offset, prior.slope * 1000.0);
        let i11 = 1.0 / (s0 * s0) + self.information[0];
        let i12 = self.information[1];
        let i22 = 1.0 / (s1 * s1) + self.information[2];
        let v1 = t0 / (s0 * s0) + self.vector[0];
        let v2 = t1 / (s1 * s1) + self.vector[1];
        let det = i11 * i22 - i12 * i12;
        let covariance = [i22 / det, -i12 / det, i11 / det];
        let a = covariance[0] * v1 + covariance[1] * v2;
        let b = covariance[1] * v1 + covariance[2] * v2;
        OffsetEstimate {
            offset: a,
            slope: b / 1000.0,
            covariance,
        }
    }

    /// Learns from one observation at time `t`: the geometric height `h_r`
    /// (m) a 3D radar measured with variance `var` (m²) of a target whose
    /// reply said pressure altitude `h_p` (m). Refused (counted) when its
    /// residual is beyond the gate. Returns whether it was learnt.
    pub fn learn(&mut self, prior: &ModeCHeight, t: f64, h_p: f64, h_r: f64, var: f64) -> bool {
        if !(h_p.is_finite() && h_r.is_finite() && var.is_finite() && var > 0.0) {
            return false;
        }
        if let Some(t0) = self.t {
            if t > t0 {
                let decay = (-(t - t0) / MEMORY_S).exp();
                for v in &mut self.information {
                    *v *= decay;
                }
                for v in &mut self.vector {
                    *v *= decay;
                }
            }
        }
        self.t = Some(self.t.map_or(t, |t0| t0.max(t)));
        let est = self.estimate(prior);
        let (off, off_var) = est.at(h_p);
        let y = h_r - h_p;
        if (y - off).powi(2) > OFFSET_GATE_SIGMAS * OFFSET_GATE_SIGMAS * (var + off_var) {
            self.rejected += 1;
            return false;
        }
        let k = h_p / 1000.0;
        let w = 1.0 / var;
        self.information[0] += w;
        self.information[1] += w * k;
        self.information[2] += w * k * k;
        self.vector[0] += w * y;
        self.vector[1] += w * k * y;
        self.plots += 1;
        true
    }
}

/// The Mode C measurement of a track's height, ready for the updater: the
/// datum and the offset's estimate at the frame's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeightMeasurement {
    /// How `up` relates to the ellipsoidal height.
    pub datum: HeightDatum,
    /// The offset's estimate.
    pub offset: OffsetEstimate,
}

impl HeightMeasurement {
    /// The sequential scalar update of a state (column-major `p`, n × n)
    /// with a plot's pressure altitude `h_p` (m) of quantisation variance
    /// `var_q` (m²): x, p updated in place, the height variance kept at
    /// least the offset's variance; returns ln N(ν; 0, s). `cols` are the
    /// state's (east, north, up) indices.
    pub fn update(
        &self,
        x: &mut [f64],
        p: &mut [f64],
        cols: [usize; 3],
        h_p: f64,
        var_q: f64,
    ) -> Result<f64, AlgoError> {
        let n = x.len();
        let (off, off_var) = self.offset.at(h_p);
        let z = h_p + off;
        let (h, grad) = self.datum.height(x[cols[0]], x[cols[1]], x[cols[2]]);
        let nu = z - h;
        let r = var_q + off_var + MODEL_SIGMA_M * MODEL_SIGMA_M;
        // ph = P hᵀ (h has three non-zero entries).
        let mut ph = vec![0.0; n];
        for (i, v) in ph.iter_mut().enumerate() {
            *v = (0..3).map(|k| p[cols[k] * n + i] * grad[k]).sum();
        }
        let s: f64 = (0..3).map(|k| grad[k] * ph[cols[k]]).sum::<f64>() + r;
        if !(s.is_finite() && s > 0.0 && nu.is_finite()) {
            return Err(AlgoError::NonFinite {
                what: "Mode C height innovation",
            });
        }
        for i in 0..n {
            x[i] += ph[i] / s * nu;
        }
        for c in 0..n {
            for i in 0..n {
                p[c * n + i] -= ph[i] * ph[c] / s;
            }
        }
        for c in 0..n {
            for i in 0..c {
                let m = 0.5 * (p[c * n + i] + p[i * n + c]);
                p[c * n + i] = m;
                p[i * n + c] = m;
            }
        }
        let zz = cols[2] * n + cols[2];
        if p[zz] < off_var {
            p[zz] = off_var;
        }
        Ok(-0.5 * ((2.0 * std::f64::consts::PI * s).ln() + nu * nu / s))
    }
}

/// A plot's pressure altitude (m) when it carries a validated, ungarbled
/// Mode C: the value a height update uses.
pub fn pressure_altitude_m(identity: &super::identity::Identity) -> Option<f64> {
    identity
        .mode_c
        .filter(|c| c.validated && !c.garbled && c.flight_level.is_finite())
        .map(|c| c.flight_level * 100.0 * FT_M)
}

/// A plot's Mode C quantisation variance (m²): q²/12 with q its quantum.
pub fn quantisation_variance_m2(identity: &super::identity::Identity) -> f64 {
    super::identity::altitude_variance(identity) * FT_M * FT_M
}

/// The ellipsoid's radii of curvature (M, N) at geodetic latitude `lat`
/// (rad) for semi-major axis `a` and first eccentricity squared `e2`.
pub fn radii_of_curvature(a: f64, e2: f64, lat: f64) -> (f64, f64) {
    let w2 = 1.0 - e2 * lat.sin().powi(2);
    (a * (1.0 - e2) / (w2 * w2.sqrt()), a / w2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::{Ellipsoid, LocalFrame};

    /// The datum's height against the exact ellipsoidal conversion
    /// (`geo::LocalFrame`, an independent ENU → ECEF → geodetic path):
    /// within 3 m out to 250 km from the origin in every direction, from
    /// the ground to 13 km (the sphere of Euler's radius is exact to
    /// second order in ρ/R; the neglected terms are ~ρ³e²/R² ≈ 1 m at
    /// 250 km). A flat earth (u as height) is off by ρ²/2R ≈ 4.9 km there.
    #[test]
    fn the_tangent_datum_is_the_ellipsoids_height() {
        let (lat, lon, h0) = (47.0f64, 8.0f64, 450.0);
        let frame =
            LocalFrame::new(Ellipsoid::WGS84, lat.to_radians(), lon.to_radians(), h0).unwrap();
        let ell = Ellipsoid::WGS84;
        let (m, n) = radii_of_curvature(ell.a(), ell.e2(), lat.to_radians());
        let datum = HeightDatum::Tangent {
            origin_height: h0,
            meridian: m,
            prime_vertical: n,
        };
        let mut worst: f64 = 0.0;
        for az in (0..360).step_by(15) {
            let a = (az as f64).to_radians();
            for rho in [0.0, 10e3, 100e3, 250e3] {
                for h in [0.0, 3000.0, 13_000.0] {
                    let (e, nn) = (rho * a.sin(), rho * a.cos());
                    // The ENU point at ellipsoidal height h above (e, n):
                    // find u by the exact conversion (Newton on u).
                    let mut u = h - h0 - rho * rho / (2.0 * m);
                    for _ in 0..6 {
                        let (_, _, hh) = frame.enu_to_geodetic([e, nn, u]).unwrap();
                        u += h - hh;
                    }
                    let (got, grad) = datum.height(e, nn, u);
                    worst = worst.max((got - h).abs());
                    // The gradient against a central difference of the
                    // exact height along u.
                    let dh = |du: f64| frame.enu_to_geodetic([e, nn, u + du]).unwrap().2;
                    let du = (dh(1.0) - dh(-1.0)) / 2.0;
                    assert!(
                        (grad[2] - du).abs() < 1e-3,
                        "{az} {rho} {h}: {grad:?} vs {du}"
                    );
                }
            }
        }
        assert!(worst < 3.0, "worst {worst} m");
    }

    /// The recursive least squares equals the batch weighted least squares
    /// with the prior as two pseudo-observations, solved by hand with the
    /// normal equations (no decay: every observation at one time).
    #[test]
    fn the_offset_is_the_weighted_least_squares_fit() {
        let prior = ModeCHeight {
            sigma_offset: 100.0,
            sigma_slope: 0.05,
            ..ModeCHeight::default()
        };
        let mut est = PressureOffset::default();
        // Truth a = 60 m, b = 0.03; noise deterministic ±200 m.
        let obs: Vec<(f64, f64, f64)> = (0..400)
            .map(|i| {
                let hp = 1000.0 + 25.0 * i as f64;
                let noise = if i % 2 == 0 { 200.0 } else { -200.0 } * ((i % 7) as f64 / 6.0);
                (hp, hp + 60.0 + 0.03 * hp + noise, 300.0 * 300.0)
            })
            .collect();
        for &(hp, hr, var) in &obs {
            assert!(est.learn(&prior, 0.0, hp, hr, var));
        }
        // Normal equations in (a, b) with b per metre.
        let (mut s11, mut s12, mut s22, mut r1, mut r2) =
            (1.0 / 100.0f64.powi(2), 0.0, 1.0 / 0.05f64.powi(2), 0.0, 0.0);
        for &(hp, hr, var) in &obs {
            let y = hr - hp;
            s11 += 1.0 / var;
            s12 += hp / var;
            s22 += hp * hp / var;
            r1 += y / var;
            r2 += hp * y / var;
        }
        let det = s11 * s22 - s12 * s12;
        let a = (s22 * r1 - s12 * r2) / det;
        let b = (s11 * r2 - s12 * r1) / det;
        let got = est.estimate(&prior);
        assert!(
            (got.offset - a).abs() < 1e-6 * a.abs().max(1.0),
            "{got:?} {a}"
        );
        assert!((got.slope - b).abs() < 1e-9, "{got:?} {b}");
        // σ_a from the inverse: s22/det.
        assert!((got.sigma_offset() - (s22 / det).sqrt()).abs() < 1e-6);
        // Near the truth (400 plots of ~150 m noise: a within 30 m).
        assert!((got.offset - 60.0).abs() < 30.0 && (got.slope - 0.03).abs() < 0.005);
    }

    /// Forgetting: an observation an hour old weighs e⁻¹ of a new one, so
    /// after a step change of the offset the estimate follows it; a far
    /// outlier is refused and counted.
    #[test]
    fn old_observations_fade_and_outliers_are_refused() {
        let prior = ModeCHeight::default();
        // A radar height's variance: (100 km · 0.2°)² ≈ (350 m)², here 300².
        let var = 300.0 * 300.0;
        let mut est = PressureOffset::default();
        est.learn(&prior, 0.0, 5000.0, 5100.0, var);
        let info = est.information[0];
        est.learn(&prior, MEMORY_S, 5000.0, 5100.0, var);
        // e⁻¹ of the first plus the new one.
        assert!((est.information[0] - (info * (-1.0f64).exp() + 1.0 / var)).abs() < 1e-15);
        for k in 0..200 {
            est.learn(&prior, MEMORY_S + k as f64, 5000.0, 5100.0, var);
        }
        // 201 plots of 100 m against a prior worth 1.4 of them at 0.
        let before = est.estimate(&prior).at(5000.0).0;
        assert!((before - 100.0).abs() < 2.0, "{before}");
        // 3.9 km off against a gate of 4 · 300 m: refused.
        assert!(!est.learn(&prior, MEMORY_S + 300.0, 5000.0, 9000.0, var));
        assert_eq!(est.rejected, 1);
        // Three hours of the new offset (150 m), a plot per 5 s: about 680
        // plots' worth of it against 5 of the old: it follows.
        for k in 0..2000 {
            est.learn(&prior, 2.0 * MEMORY_S + 5.0 * k as f64, 5000.0, 5150.0, var);
        }
        let after = est.estimate(&prior).at(5000.0).0;
        assert!((after - 150.0).abs() < 2.0, "{after}");
    }

    /// The scalar update by hand: x = (e, ve, n, vn, u, vu), P diagonal,
    /// flat datum (h = u): s = P_uu + r, K = P_u·/s, the height moves by
    /// P_uu/s of the innovation and nothing else moves.
    #[test]
    fn the_height_update_by_hand() {
        let m = HeightMeasurement {
            datum: HeightDatum::Flat,
            offset: OffsetEstimate {
                offset: 20.0,
                slope: 0.0,
                covariance: [100.0, 0.0, 0.0],
            },
        };
        let mut x = vec![1000.0, 100.0, 2000.0, 0.0, 3000.0, 0.0];
        let mut p = vec![0.0; 36];
        for (i, v) in [400.0, 25.0, 400.0, 25.0, 10_000.0, 25.0]
            .iter()
            .enumerate()
        {
            p[i * 6 + i] = *v;
        }
        // z = 3100 + 20 = 3120, ν = 120, r = 4 + 100 + 25 = 129,
        // s = 10 000 + 129 = 10 129; u⁺ = 3000 + 120·10 000/10 129.
        let ln = m.update(&mut x, &mut p, [0, 2, 4], 3100.0, 4.0).unwrap();
        let s = 10_129.0f64;
        assert!((x[4] - (3000.0 + 120.0 * 10_000.0 / s)).abs() < 1e-9);
        assert_eq!((x[0], x[2], x[5]), (1000.0, 2000.0, 0.0));
        assert!((p[4 * 6 + 4] - (10_000.0 - 1e8 / s)).abs() < 1e-9);
        assert!(
            (ln + 0.5 * ((2.0 * std::f64::consts::PI * s).ln() + 120.0 * 120.0 / s)).abs() < 1e-12
        );
        // Again and again: the variance stops at the offset's 100 m².
        for _ in 0..50 {
            m.update(&mut x, &mut p, [0, 2, 4], 3100.0, 4.0).unwrap();
        }
        assert!((p[4 * 6 + 4] - 100.0).abs() < 1e-9, "{}", p[4 * 6 + 4]);
    }
}
