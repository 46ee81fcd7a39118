//! Geometry of seed 003 on the ellipsoid: where a 2D radar's plot lies for an
//! assumed target height (it lies on the cone of its slant range and
//! azimuth, elevation unknown), the horizontal footprint used by dimension
//! lifting and the direction from the Earth's centre used by dimension
//! splitting.

use nalgebra::{Matrix3, Vector3};

use crate::{
    AlgoError,
    geo::{LocalFrame, ecef_to_geodetic, ecef_to_vertical, geodetic_to_ecef},
    polar::polar_to_enu_3d,
};

/// Mean Earth radius scaling the direction coordinates (m).
pub const DIRECTION_RADIUS_M: f64 = 6_371_008.8;

/// Elevation at which slant range ρ from a site at geocentric radius `r_site`
/// reaches geocentric radius `r_target` on a sphere (law of cosines):
/// sin E = (r_t² − r_s² − ρ²) / (2 r_s ρ).
pub fn sphere_elevation(range: f64, r_site: f64, r_target: f64) -> Result<f64, AlgoError> {
    let s = (r_target * r_target - r_site * r_site - range * range) / (2.0 * r_site * range);
    if !(s.is_finite() && (-1.0..=1.0).contains(&s)) {
        return Err(AlgoError::DegenerateGeometry {
            what: "2D plot",
            reason: "the slant range cannot reach the assumed height",
        });
    }
    Ok(s.asin())
}

/// ECEF position of a 2D plot (slant range, azimuth) of the radar whose
/// local frame is `radar`, placed at ellipsoidal height `height`: a start on
/// the sphere of the site's Gaussian radius √(M N), then Newton steps on the
/// ellipsoid (dh/dE by central difference) to 1 mm.
pub fn plot_at_height(
    radar: &LocalFrame,
    range: f64,
    azimuth: f64,
    height: f64,
) -> Result<([f64; 3], f64), AlgoError> {
    let ell = radar.ellipsoid();
    let (lat, _, hs) = radar.origin_geodetic();
    let e2 = ell.e2();
    let w = (1.0 - e2 * lat.sin().powi(2)).sqrt();
    let gauss = ell.a() * (1.0 - e2).sqrt() / (w * w);
    let mut el = sphere_elevation(range, gauss + hs, gauss + height)?;
    let h_of = |el: f64| -> Result<f64, AlgoError> {
        let p = radar.enu_to_ecef(polar_to_enu_3d(range, azimuth, el)?)?;
        Ok(ecef_to_geodetic(&ell, p)?.2)
    };
    for _ in 0..8 {
        let h = h_of(el)?;
        if (h - height).abs() < 1e-3 {
            break;
        }
        let d = 1e-6;
        let slope = (h_of(el + d)? - h_of(el - d)?) / (2.0 * d);
        if !(slope.is_finite() && slope.abs() > 1e-9) {
            return Err(AlgoError::DegenerateGeometry {
                what: "2D plot",
                reason: "the height does not change with elevation",
            });
        }
        el = (el - (h - height) / slope).clamp(-1.5, 1.5);
    }
    Ok((radar.enu_to_ecef(polar_to_enu_3d(range, azimuth, el)?)?, el))
}

/// A 2D plot (slant range, azimuth) of `radar` placed at ellipsoidal height
/// `height`, in the ENU frame of `centre`, with the Jacobian of that position
/// with respect to (ρ, θ, h): [`Cone::place`] for one plot.
pub fn place_2d(
    radar: &LocalFrame,
    centre: &LocalFrame,
    range: f64,
    azimuth: f64,
    height: f64,
) -> Result<([f64; 3], Matrix3<f64>), AlgoError> {
    Cone::new(radar, centre).place(range, azimuth, height)
}

/// What placing a 2D radar's plots in a centre frame needs of the radar
/// alone (its Gaussian radius, rotations), computed once per radar instead
/// of once per placement: the same numbers by the same operations, so the
/// placements keep their bits.
#[derive(Debug, Clone, Copy)]
pub struct Cone {
    radar: LocalFrame,
    centre: LocalFrame,
    /// The site's Gaussian radius √(M N) (m), and the site's geocentric
    /// radius on that sphere, √(M N) + h_site.
    gauss: f64,
    site_radius: f64,
    /// ECEF → the radar's ENU, and the radar's ENU → the centre's.
    rot: Matrix3<f64>,
    to_centre: Matrix3<f64>,
}

impl Cone {
    /// What placing plots of the 2D radar with frame `radar` in the ENU frame
    /// of `centre` needs.
    pub fn new(radar: &LocalFrame, centre: &LocalFrame) -> Self {
        let ell = radar.ellipsoid();
        let (lat, _, hs) = radar.origin_geodetic();
        let e2 = ell.e2();
        let w = (1.0 - e2 * lat.sin().powi(2)).sqrt();
        let gauss = ell.a() * (1.0 - e2).sqrt() / (w * w);
        Self {
            radar: *radar,
            centre: *centre,
            gauss,
            site_radius: gauss + hs,
            rot: radar.rotation(),
            to_centre: radar.rotation_to(centre),
        }
    }

    /// The plot (slant range, azimuth) placed at ellipsoidal height
    /// `height`, in the centre's ENU frame, with the Jacobian of that
    /// position with respect to (ρ, θ, h).
    ///
    /// The elevation E solves h(P(ρ, θ, E)) = height, from the sphere's
    /// answer, by Halley steps on the exact derivatives of the height along
    /// the cone. The gradient of the geodetic height is the unit normal n at
    /// the point and its Hessian the normal's turn, n̂ n̂'/(M + h) + ê ê'/(N + h)
    /// (north and east unit vectors, M and N the meridian and prime-vertical
    /// radii of curvature), so with P_E = ∂P/∂E and P_EE = −(P − site):
    /// h' = n·P_E and h'' = (n̂·P_E)²/(M + h) + (ê·P_E)²/(N + h) + n·P_EE.
    /// A Halley step ΔE = 2 r h' / (2 h'² − r h'') from residual r leaves a
    /// residual of the order of ρ ΔE³ (its error is cubic in the start's,
    /// with coefficients of order 1 for the cone's unit-ish derivatives);
    /// once ρ |ΔE|³ ≤ [`Cone::HALLEY_ACCEPT_M`] the stepped point is the
    /// answer, its normal moved by the Hessian times the step (a
    /// second-order error, ~1e-12), without another geodetic conversion.
    /// One conversion per placement instead of the two of Newton's steps
    /// to 1 mm, and a height residual below 1e-6 m (the test checks both
    /// on a sweep). The Jacobian follows by implicit differentiation of the
    /// same constraint: ∂E/∂ρ = −n·P_ρ / n·P_E, ∂E/∂θ = −n·P_θ / n·P_E,
    /// ∂E/∂h = 1 / n·P_E.
    pub fn place(
        &self,
        range: f64,
        azimuth: f64,
        height: f64,
    ) -> Result<([f64; 3], Matrix3<f64>), AlgoError> {
        let radar = &self.radar;
        let ell = radar.ellipsoid();
        let (a, e2) = (ell.a(), ell.e2());
        let mut el = sphere_elevation(range, self.site_radius, self.gauss + height)?;
        let (sa, ca) = azimuth.sin_cos();
        // The point at elevation `el` in the radar's ENU axes, ∂P/∂E, and
        // sin E and cos E.
        let cone = |el: f64| {
            let (se, ce) = el.sin_cos();
            let local = Vector3::new(range * ce * sa, range * ce * ca, range * se);
            let d_el = Vector3::new(-range * se * sa, -range * se * ca, range * ce);
            (local, d_el, (se, ce))
        };
        let degenerate = || AlgoError::DegenerateGeometry {
            what: "2D plot",
            reason: "the height does not change with elevation",
        };
        let mut done = None;
        for _ in 0..8 {
            let (local, d_el, _) = cone(el);
            let ecef = radar.enu_to_ecef(local.into())?;
            let v = ecef_to_vertical(&ell, ecef)?;
            // The normal, north and east in the radar's axes.
            let (sl, cl, so, co) = (v.sin_lat, v.cos_lat, v.sin_lon, v.cos_lon);
            let normal = self.rot * v.normal();
            let north = self.rot * Vector3::new(-sl * co, -sl * so, cl);
            let east = self.rot * Vector3::new(-so, co, 0.0);
            let w2 = 1.0 - e2 * sl * sl;
            let n_radius = a / w2.sqrt();
            let m_radius = n_radius * (1.0 - e2) / w2;
            let (km, kn) = (1.0 / (m_radius + v.h), 1.0 / (n_radius + v.h));
            let slope = normal.dot(&d_el);
            if !(slope.is_finite() && slope.abs() > 1e-9) {
                return Err(degenerate());
            }
            let curve =
                north.dot(&d_el).powi(2) * km + east.dot(&d_el).powi(2) * kn - normal.dot(&local);
            let r = v.h - height;
            // Halley's step, or Newton's when the residual is so large that
            // the curvature would dominate (not from the sphere's start).
            let step = if (r * curve).abs() < slope * slope {
                2.0 * r * slope / (2.0 * slope * slope - r * curve)
            } else {
                r / slope
            };
            let next = (el - step).clamp(-1.5, 1.5);
            if range * step.abs().powi(3) <= Self::HALLEY_ACCEPT_M {
                // The normal at the stepped point, to first order in the
                // move (the Hessian of h times it).
                let at = cone(next);
                let mv = at.0 - local;
                let normal = normal + north * (north.dot(&mv) * km) + east * (east.dot(&mv) * kn);
                done = Some((at, normal));
                break;
            }
            el = next;
        }
        let ((local, d_el, (se, ce)), normal) = done.ok_or(AlgoError::DegenerateGeometry {
            what: "2D plot",
            reason: "the elevation for the assumed height did not converge",
        })?;
        let ecef = radar.enu_to_ecef(local.into())?;
        let d_range = Vector3::new(ce * sa, ce * ca, se);
        let d_az = Vector3::new(range * ce * ca, -range * ce * sa, 0.0);
        let slope = normal.dot(&d_el);
        if !(slope.is_finite() && slope.abs() > 1e-9) {
            return Err(degenerate());
        }
        let local_jac = Matrix3::from_columns(&[
            d_range - d_el * (normal.dot(&d_range) / slope),
            d_az - d_el * (normal.dot(&d_az) / slope),
            d_el / slope,
        ]);
        let pos = self.centre.ecef_to_enu(ecef)?;
        Ok((pos, self.to_centre * local_jac))
    }

    /// The bound on ρ |ΔE|³ (m) under which [`Cone::place`] takes a Halley
    /// step's point as the answer: its height residual is then of the order
    /// of 1e-7 m.
    pub const HALLEY_ACCEPT_M: f64 = 2e-7;
}

/// The test coordinates of a method at a centre-ENU position, with their
/// exact Jacobian (rows beyond `dim` are zero):
/// - mapping: the position itself, J = I;
/// - lifting: the footprint; moving east or north by δ moves the footprint
///   by δ N/(N + h) or δ M/(M + h) (N, M the prime-vertical and meridian
///   radii of curvature), moving up does not move it;
/// - splitting: R₀ (ê·u, n̂·u) with u = p/|p|, ∂u/∂p = (I − u u')/|p|.
pub fn test_space(
    centre: &LocalFrame,
    method: super::Method,
    pos: [f64; 3],
) -> Result<(usize, Vector3<f64>, Matrix3<f64>), AlgoError> {
    use super::Method;
    let rot = centre.rotation();
    match method {
        Method::Mapping => Ok((3, Vector3::from(pos), Matrix3::identity())),
        Method::Lifting => {
            let ell = centre.ellipsoid();
            let ecef = centre.enu_to_ecef(pos)?;
            let v = ecef_to_vertical(&ell, ecef)?;
            let (sl, cl, so, co, h) = (v.sin_lat, v.cos_lat, v.sin_lon, v.cos_lon, v.h);
            let w2 = 1.0 - ell.e2() * sl * sl;
            let n = ell.a() / w2.sqrt();
            // The footprint: `geodetic_to_ecef(lat, lon, 0)`'s formula on
            // the sines and cosines of the point's latitude and longitude
            // (equal to [`footprint`]'s to rounding), with N shared.
            let fp = centre.ecef_to_enu([
                (n + 0.0) * cl * co,
                (n + 0.0) * cl * so,
                (n * (1.0 - ell.e2()) + 0.0) * sl,
            ])?;
            let m = ell.a() * (1.0 - ell.e2()) / (w2 * w2.sqrt());
            let east = Vector3::new(-so, co, 0.0);
            let north = Vector3::new(-sl * co, -sl * so, cl);
            let d_ecef =
                east * east.transpose() * (n / (n + h)) + north * north.transpose() * (m / (m + h));
            let mut j = rot * d_ecef * rot.transpose();
            j.row_mut(2).fill(0.0);
            Ok((2, Vector3::new(fp[0], fp[1], 0.0), j))
        }
        Method::Splitting => {
            let p = Vector3::from(centre.enu_to_ecef(pos)?);
            let r = p.norm();
            if !(r.is_finite() && r > 0.0) {
                return Err(AlgoError::DegenerateGeometry {
                    what: "position",
                    reason: "at the Earth's centre",
                });
            }
            let u = p / r;
            let e = rot.row(0).transpose();
            let nn = rot.row(1).transpose();
            let proj = (Matrix3::identity() - u * u.transpose()) * (DIRECTION_RADIUS_M / r);
            let mut j = Matrix3::zeros();
            j.set_row(0, &(e.transpose() * proj * rot.transpose()));
            j.set_row(1, &(nn.transpose() * proj * rot.transpose()));
            Ok((
                2,
                Vector3::new(
                    DIRECTION_RADIUS_M * e.dot(&u),
                    DIRECTION_RADIUS_M * nn.dot(&u),
                    0.0,
                ),
                j,
            ))
        }
    }
}

/// Horizontal footprint: the ENU `[e, n]` in `centre` of the point at height 0
/// below `ecef` (same latitude and longitude).
pub fn footprint(centre: &LocalFrame, ecef: [f64; 3]) -> Result<[f64; 2], AlgoError> {
    let ell = centre.ellipsoid();
    let (lat, lon, _) = ecef_to_geodetic(&ell, ecef)?;
    let p = centre.ecef_to_enu(geodetic_to_ecef(&ell, lat, lon, 0.0)?)?;
    Ok([p[0], p[1]])
}

/// Direction from the Earth's centre, as `R₀ (ê·u, n̂·u)` with u = p/|p| and
/// ê, n̂ the east and north axes of `centre` (metres of arc near the centre).
pub fn direction(centre: &LocalFrame, ecef: [f64; 3]) -> Result<[f64; 2], AlgoError> {
    let p = Vector3::from(ecef);
    let r = p.norm();
    if !(r.is_finite() && r > 0.0) {
        return Err(AlgoError::DegenerateGeometry {
            what: "position",
            reason: "at the Earth's centre",
        });
    }
    let u = p / r;
    let rot = centre.rotation();
    Ok([
        DIRECTION_RADIUS_M * rot.row(0).transpose().dot(&u),
        DIRECTION_RADIUS_M * rot.row(1).transpose().dot(&u),
    ])
}

/// The inverse of [`direction`] with a geocentric distance: the ECEF point.
pub fn from_direction(
    centre: &LocalFrame,
    d: [f64; 2],
    distance: f64,
) -> Result<[f64; 3], AlgoError> {
    let (a, b) = (d[0] / DIRECTION_RADIUS_M, d[1] / DIRECTION_RADIUS_M);
    let c2 = 1.0 - a * a - b * b;
    if c2.is_nan() || c2 < 0.0 {
        return Err(AlgoError::DegenerateGeometry {
            what: "direction",
            reason: "not a unit vector",
        });
    }
    let rot = centre.rotation();
    let u = rot.row(0).transpose() * a
        + rot.row(1).transpose() * b
        + rot.row(2).transpose() * c2.sqrt();
    Ok((u * distance).into())
}

/// The Jacobian of [`from_direction`] followed by `centre.ecef_to_enu`
/// with respect to (d₁, d₂, distance): with a = d₁/R₀, b = d₂/R₀ and
/// c = √(1 − a² − b²) the point is r (a, b, c) in the centre's axes, less
/// the centre itself, so
/// J = [[r/R₀, 0, a], [0, r/R₀, b], [−r a/(c R₀), −r b/(c R₀), c]].
pub fn from_direction_jacobian(d: [f64; 2], distance: f64) -> Result<Matrix3<f64>, AlgoError> {
    let (a, b) = (d[0] / DIRECTION_RADIUS_M, d[1] / DIRECTION_RADIUS_M);
    let c2 = 1.0 - a * a - b * b;
    if c2.is_nan() || c2 <= 0.0 {
        return Err(AlgoError::DegenerateGeometry {
            what: "direction",
            reason: "not a unit vector",
        });
    }
    let c = c2.sqrt();
    let k = distance / DIRECTION_RADIUS_M;
    #[rustfmt::skip]
    let j = Matrix3::new(
        k, 0.0, a,
        0.0, k, b,
        -k * a / c, -k * b / c, c,
    );
    Ok(j)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::Ellipsoid;

    #[test]
    fn sphere_elevation_closed_form() {
        // R = 6 371 000, site at R, target at R + 7000, ρ = 200 km:
        // sin E = ((R+7000)² − R² − 200000²)/(2 R 200000)
        //       = (2·7000·R + 7000² − 4e10)/(2.5484e12)
        //       = (8.9194e10 + 4.9e7 − 4e10)/2.5484e12 = 0.0193231.
        let r = 6_371_000.0;
        let e = sphere_elevation(200_000.0, r, r + 7000.0).unwrap();
        let expect = ((2.0 * 7000.0 * r + 7000.0f64.powi(2) - 4e10) / (2.0 * r * 2e5)).asin();
        assert!((e - expect).abs() < 1e-15);
        assert!((e.sin() - 0.019_323_1).abs() < 1e-7);
        assert!(sphere_elevation(1000.0, r, r + 7000.0).is_err());
    }

    #[test]
    fn two_d_plot_at_long_range_is_not_flat() {
        // Radar at (30°N, 120°E, 0), target at 7 km height, ρ = 200 km.
        // Flat Earth: ground range √(ρ² − h²) = √(4e10 − 4.9e7) = 199 877.5 m.
        // Sphere: central angle γ = acos((r_s² + r_t² − ρ²)/(2 r_s r_t)),
        // ground range at sea level R γ = 199 775.9 m (≈ 100 m shorter).
        let ell = Ellipsoid::WGS84;
        let radar = LocalFrame::new(ell, 30f64.to_radians(), 120f64.to_radians(), 0.0).unwrap();
        let (p, el) = plot_at_height(&radar, 200_000.0, 0.3, 7000.0).unwrap();
        let (_, _, h) = ecef_to_geodetic(&ell, p).unwrap();
        assert!((h - 7000.0).abs() < 1e-2, "height {h}");
        // Curvature drop ρ²/2R ≈ 3.14 km < 7 km: the elevation is small and
        // positive, sin E ≈ 0.0193 as on the sphere above.
        assert!((el.sin() - 0.0193).abs() < 2e-4, "{el}");
        let fp = footprint(&radar, p).unwrap();
        let ground = (fp[0].powi(2) + fp[1].powi(2)).sqrt();
        let flat = (4e10f64 - 4.9e7).sqrt();
        assert!((flat - 199_877.5).abs() < 0.1);
        let rs = 6_371_000.0f64;
        let rt = rs + 7000.0;
        let gamma = ((rs * rs + rt * rt - 4e10) / (2.0 * rs * rt)).acos();
        assert!((rs * gamma - 199_775.9).abs() < 0.1, "{}", rs * gamma);
        // The ellipsoid answer lies within a few tens of metres of the sphere's,
        // and ~100 m from the flat one.
        assert!((ground - rs * gamma).abs() < 60.0, "ground {ground}");
        assert!(flat - ground > 50.0);
    }

    #[test]
    fn placement_reaches_the_height_to_a_micrometre() {
        // Cone::place takes one Halley step's point without checking its
        // height: over radars around the centre, slant ranges 2–300 km, all
        // azimuths and heights from the sea to 15 km, the placed point's
        // geodetic height (exact conversion) is the asked one to 1e-6 m, and
        // the point is where Newton's method run to 1e-9 m puts it, to 1e-6 m
        // (measured: 1.2e-8 m for both, every placement from one conversion).
        let ell = Ellipsoid::WGS84;
        let centre = LocalFrame::new(ell, 30f64.to_radians(), 120f64.to_radians(), 0.0).unwrap();
        let mut worst: f64 = 0.0;
        for (lat, lon, hs) in [
            (30.1, 120.1, 100.0),
            (29.7, 119.6, 0.0),
            (60.0, 10.0, 500.0),
        ] {
            let radar =
                LocalFrame::new(ell, f64::to_radians(lat), f64::to_radians(lon), hs).unwrap();
            let cone = Cone::new(&radar, &centre);
            for range in [2_000.0, 15_000.0, 60_000.0, 150_000.0, 240_000.0, 300_000.0] {
                for k in 0..12 {
                    let az = f64::from(k) * 0.52 + 0.1;
                    for h in [0.0f64, 1_000.0, 5_000.0, 9_000.0, 15_000.0] {
                        let h = h.clamp(hs - 0.9 * range, hs + 0.9 * range);
                        let Ok((pos, _)) = cone.place(range, az, h) else {
                            // Out of reach on the ellipsoid (the sphere's
                            // answer already refused it).
                            continue;
                        };
                        let ecef = centre.enu_to_ecef(pos).unwrap();
                        let got = ecef_to_geodetic(&ell, ecef).unwrap().2;
                        worst = worst.max((got - h).abs());
                        // Newton to 1e-9 m with central-difference slopes.
                        let r0 = 6_371_000.0;
                        let mut el = sphere_elevation(range, r0 + hs, r0 + h).unwrap_or(0.0);
                        let h_of = |el: f64| {
                            let p = radar
                                .enu_to_ecef(polar_to_enu_3d(range, az, el).unwrap())
                                .unwrap();
                            (ecef_to_geodetic(&ell, p).unwrap().2, p)
                        };
                        for _ in 0..50 {
                            let (hh, _) = h_of(el);
                            if (hh - h).abs() < 1e-9 {
                                break;
                            }
                            let slope = (h_of(el + 1e-7).0 - h_of(el - 1e-7).0) / 2e-7;
                            el -= (hh - h) / slope;
                        }
                        let want = centre.ecef_to_enu(h_of(el).1).unwrap();
                        for i in 0..3 {
                            assert!(
                                (pos[i] - want[i]).abs() < 1e-6,
                                "ρ {range} θ {az} h {h}: {pos:?} vs {want:?}"
                            );
                        }
                    }
                }
            }
        }
        assert!(worst < 1e-6, "worst height residual {worst} m");
    }

    #[test]
    fn lifting_test_point_is_the_footprint() {
        // test_space takes the sines and cosines of the latitude and the
        // longitude from `ecef_to_vertical` (quotients of Vermeille's
        // quantities); `footprint` takes the angles from `ecef_to_geodetic`
        // and their sines and cosines: the same point up to a few ulps of
        // the sines and cosines, well below a micrometre (this compared the
        // bits while both went through the angles).
        let ell = Ellipsoid::WGS84;
        let centre = LocalFrame::new(ell, 30f64.to_radians(), 120f64.to_radians(), 0.0).unwrap();
        for k in 0..200 {
            let x = f64::from(k);
            let pos = [
                -150_000.0 + 1_537.3 * x,
                90_000.0 - 911.7 * x,
                500.0 + 61.1 * x,
            ];
            let (_, z, _) = test_space(&centre, super::super::Method::Lifting, pos).unwrap();
            let fp = footprint(&centre, centre.enu_to_ecef(pos).unwrap()).unwrap();
            assert!((z[0] - fp[0]).abs() < 1e-6, "{k}: {} {}", z[0], fp[0]);
            assert!((z[1] - fp[1]).abs() < 1e-6, "{k}: {} {}", z[1], fp[1]);
        }
    }

    #[test]
    fn from_direction_jacobian_matches_central_differences() {
        let ell = Ellipsoid::WGS84;
        let centre = LocalFrame::new(ell, 30f64.to_radians(), 120f64.to_radians(), 0.0).unwrap();
        for (e, n, u) in [
            (0.0, 0.0, 7000.0),
            (150_000.0, -90_000.0, 3000.0),
            (-220_000.0, 40_000.0, 11_000.0),
        ] {
            let ecef = centre.enu_to_ecef([e, n, u]).unwrap();
            let d = direction(&centre, ecef).unwrap();
            let r = Vector3::from(ecef).norm();
            let jac = from_direction_jacobian(d, r).unwrap();
            let at = |y: [f64; 3]| {
                centre
                    .ecef_to_enu(from_direction(&centre, [y[0], y[1]], y[2]).unwrap())
                    .unwrap()
            };
            for k in 0..3 {
                let (mut hi, mut lo) = ([d[0], d[1], r], [d[0], d[1], r]);
                hi[k] += 10.0;
                lo[k] -= 10.0;
                let (a, b) = (at(hi), at(lo));
                for i in 0..3 {
                    let num = (a[i] - b[i]) / 20.0;
                    assert!(
                        (jac[(i, k)] - num).abs() < 1e-7,
                        "∂{i}/∂{k}: {} vs {num}",
                        jac[(i, k)]
                    );
                }
            }
        }
        assert!(from_direction_jacobian([DIRECTION_RADIUS_M, 1.0], 7e6).is_err());
    }

    #[test]
    fn direction_round_trip_and_closed_form() {
        // A point straight above the centre has direction (0, 0); a point
        // 1° of longitude east on the equator: ê·u = sin 1°.
        let ell = Ellipsoid::WGS84;
        let centre = LocalFrame::new(ell, 0.0, 0.0, 0.0).unwrap();
        let up = geodetic_to_ecef(&ell, 0.0, 0.0, 7000.0).unwrap();
        let d = direction(&centre, up).unwrap();
        assert!(d[0].abs() < 1e-6 && d[1].abs() < 1e-6);
        let east = geodetic_to_ecef(&ell, 0.0, 1f64.to_radians(), 7000.0).unwrap();
        let d = direction(&centre, east).unwrap();
        assert!((d[0] - DIRECTION_RADIUS_M * 1f64.to_radians().sin()).abs() < 1e-6);
        let r = Vector3::from(east).norm();
        let back = from_direction(&centre, d, r).unwrap();
        for i in 0..3 {
            assert!((back[i] - east[i]).abs() < 1e-6);
        }
    }
}
