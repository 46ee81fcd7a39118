//! Fusion of 2D and 3D radar tracks (seed 003): local filtering
//! ([`alpha_beta`]), the modified K-nearest-neighbour association
//! ([`knn`]) and the three methods of §1 on the ellipsoid ([`geometry`]).
//!
//! Every local track is filtered in its radar's measurement coordinates
//! (2D: slant range and azimuth; 3D: local ENU), then expressed as a
//! constant-velocity state `[x, vx, y, vy, z, vz]` in the fusion centre's ENU
//! frame. A 2D estimate needs a height: it is placed on its cone of slant
//! range and azimuth at an assumed height h with standard deviation σ_h, the
//! spread along the cone entering its covariance through the Jacobian of
//! (ρ, θ, h) → ENU. The methods differ in h and in the test space:
//! - mapping: h = the preset altitude (σ_h = 300 m); 3D test;
//! - lifting: h = preset with σ_h = `altitude_sigma`; test on the horizontal
//!   footprint; fusion puts the 2D track at the correlated 3D tracks' height;
//! - splitting: as lifting, test on the direction from the Earth's centre;
//!   fusion of the direction from all tracks and of the geocentric distance
//!   from 3D tracks only.

pub mod alpha_beta;
pub mod geometry;
pub mod knn;

use nalgebra::{DMatrix, DVector};

use crate::algo::{
    AlgoError, assignment,
    correlation::fusion::bar_shalom_campo,
    geo::{LocalFrame, ecef_to_geodetic},
    polar::{PolarMeasurement, plot_to_local},
};
pub use alpha_beta::Filter;
pub use knn::{KnnParams, PairState, Period};

/// σ of the climb rate given to a 2D track (level flight assumed), m/s.
pub const CLIMB_SIGMA_MPS: f64 = 10.0;
/// σ_h of the mapping method's preset altitude: the preset is explicit, with a
/// tolerance of the order of a flight level.
pub const MAPPING_ALTITUDE_SIGMA_M: f64 = 300.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    Mapping,
    Lifting,
    Splitting,
}

#[derive(Debug, Clone)]
pub struct Radar {
    pub frame: LocalFrame,
    pub three_d: bool,
    pub sigma_range: f64,
    pub sigma_azimuth: f64,
    pub sigma_elevation: f64,
    pub scan_period: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plot {
    pub t: f64,
    pub range: f64,
    pub azimuth: f64,
    pub elevation: Option<f64>,
}

#[derive(Debug, Clone)]
pub struct LocalTrack {
    pub radar: usize,
    pub plots: Vec<Plot>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    pub filter: Filter,
    pub knn: KnnParams,
    /// Mapping's preset altitude and the nominal height of 2D tracks (m).
    pub preset_altitude: f64,
    /// σ_h of a 2D track's unknown height under lifting and splitting (m).
    pub altitude_sigma: f64,
    /// A component of the difference is a hit within this many σ.
    pub gate_sigmas: f64,
    /// χ² thresholds of the check period for 2 and 3 degrees of freedom.
    pub chi2_2: f64,
    pub chi2_3: f64,
}

/// A centre-ENU estimate `[x, vx, y, vy, z, vz]`.
#[derive(Debug, Clone, PartialEq)]
pub struct State6 {
    pub t: f64,
    pub x: DVector<f64>,
    pub p: DMatrix<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PairReport {
    pub a: usize,
    pub b: usize,
    pub state: PairState,
    /// Mean test statistic d'S⁻¹d over all tests.
    pub mean_statistic: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SystemTrack {
    /// Local track indices, sorted.
    pub members: Vec<usize>,
    pub samples: Vec<State6>,
    /// False when no 3D radar sees the track (and the method is not mapping):
    /// the height is the nominal one and must not be trusted.
    pub altitude_known: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    pub pairs: Vec<PairReport>,
    pub system_tracks: Vec<SystemTrack>,
    /// Groups that would hold two tracks of one radar (links dropped).
    pub conflicts: usize,
}

/// Filtered local track in its radar's coordinates.
struct Filtered {
    radar: usize,
    est: Vec<alpha_beta::Estimate>,
}

/// Runs one method over the scene: filter, correlate pairs of tracks of
/// different radars, group, fuse.
pub fn fuse(
    centre: &LocalFrame,
    radars: &[Radar],
    tracks: &[LocalTrack],
    method: Method,
    cfg: &Config,
) -> Result<Outcome, AlgoError> {
    let filtered = tracks
        .iter()
        .map(|t| {
            filter_track(&radars[t.radar], t, cfg.filter).map(|est| Filtered {
                radar: t.radar,
                est,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let sigma_h = match method {
        Method::Mapping => MAPPING_ALTITUDE_SIGMA_M,
        _ => cfg.altitude_sigma,
    };
    let centred: Vec<Vec<State6>> = filtered
        .iter()
        .map(|f| {
            f.est
                .iter()
                .map(|e| to_centre(centre, &radars[f.radar], e, cfg.preset_altitude, sigma_h))
                .collect()
        })
        .collect::<Result<_, _>>()?;

    // Pairwise modified K-NN.
    let mut pairs = Vec::new();
    for a in 0..tracks.len() {
        for b in a + 1..tracks.len() {
            if tracks[a].radar == tracks[b].radar || centred[a].is_empty() || centred[b].is_empty()
            {
                continue;
            }
            pairs.push(correlate_pair(
                centre, radars, tracks, &centred, a, b, method, cfg,
            )?);
        }
    }

    // Exclusive links per radar pair by optimal assignment, then groups.
    let mut parent: Vec<usize> = (0..tracks.len()).collect();
    let mut radar_pairs: Vec<(usize, usize)> = pairs
        .iter()
        .filter(|p| p.state.correlated())
        .map(|p| (tracks[p.a].radar, tracks[p.b].radar))
        .collect();
    radar_pairs.sort_unstable();
    radar_pairs.dedup();
    let mut conflicts = 0;
    for (ra, rb) in radar_pairs {
        let links: Vec<&PairReport> = pairs
            .iter()
            .filter(|p| p.state.correlated() && tracks[p.a].radar == ra && tracks[p.b].radar == rb)
            .collect();
        let edges: Vec<(usize, usize, f64)> = links
            .iter()
            .map(|p| (p.a, p.b, p.mean_statistic.min(1e6)))
            .collect();
        for (a, b) in assignment::solve(&edges, 2e6) {
            let (x, y) = (find(&mut parent, a), find(&mut parent, b));
            if x == y {
                continue;
            }
            let radars_x: Vec<usize> = members_of(&mut parent, x)
                .iter()
                .map(|&i| tracks[i].radar)
                .collect();
            let clash = members_of(&mut parent, y)
                .iter()
                .any(|&i| radars_x.contains(&tracks[i].radar));
            if clash {
                conflicts += 1;
            } else {
                parent[x] = y;
            }
        }
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in 0..tracks.len() {
        if find(&mut parent, i) == i {
            groups.push(members_of(&mut parent, i));
        }
    }
    let system_tracks = groups
        .into_iter()
        .filter(|g| g.iter().any(|&i| !centred[i].is_empty()))
        .map(|g| system_track(centre, radars, &filtered, &centred, g, method, cfg))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Outcome {
        pairs,
        system_tracks,
        conflicts,
    })
}

fn find(parent: &mut [usize], i: usize) -> usize {
    let mut r = i;
    while parent[r] != r {
        r = parent[r];
    }
    parent[i] = r;
    r
}

fn members_of(parent: &mut [usize], root: usize) -> Vec<usize> {
    (0..parent.len())
        .filter(|&i| find(parent, i) == root)
        .collect()
}

fn filter_track(
    radar: &Radar,
    track: &LocalTrack,
    filter: Filter,
) -> Result<Vec<alpha_beta::Estimate>, AlgoError> {
    let times: Vec<f64> = track.plots.iter().map(|p| p.t).collect();
    if radar.three_d {
        let mut z = Vec::new();
        let mut r = Vec::new();
        for p in &track.plots {
            let g = plot_to_local(
                [0.0; 3],
                &PolarMeasurement {
                    range: p.range,
                    azimuth: p.azimuth,
                    elevation: p.elevation,
                    sigma_range: radar.sigma_range,
                    sigma_azimuth: radar.sigma_azimuth,
                    sigma_elevation: Some(radar.sigma_elevation),
                },
            )?;
            z.push(g.mean().clone());
            r.push(g.cov().clone());
        }
        alpha_beta::filter(filter, &times, &z, &r, &[false; 3], &[1.0; 3])
    } else {
        let z: Vec<_> = track
            .plots
            .iter()
            .map(|p| DVector::from_vec(vec![p.range, p.azimuth]))
            .collect();
        let r = vec![
            DMatrix::from_diagonal(&DVector::from_vec(vec![
                radar.sigma_range.powi(2),
                radar.sigma_azimuth.powi(2)
            ]));
            z.len()
        ];
        let mean_range =
            track.plots.iter().map(|p| p.range).sum::<f64>() / track.plots.len().max(1) as f64;
        alpha_beta::filter(
            filter,
            &times,
            &z,
            &r,
            &[false, true],
            &[1.0, 1.0 / mean_range.max(1.0)],
        )
    }
}

/// A local estimate as a centre-ENU state. 2D estimates `[ρ, ρ̇, θ, θ̇]` are
/// placed at height `h` (σ_h) with level flight (climb σ `CLIMB_SIGMA_MPS`).
fn to_centre(
    centre: &LocalFrame,
    radar: &Radar,
    e: &alpha_beta::Estimate,
    h: f64,
    sigma_h: f64,
) -> Result<State6, AlgoError> {
    let (pos, jac, py) = if radar.three_d {
        let pos = radar.frame.position_to(centre, [e.x[0], e.x[2], e.x[4]])?;
        let m = radar.frame.rotation_to(centre);
        let jac = DMatrix::from_fn(3, 3, |i, j| m[(i, j)]);
        (pos, jac, e.p.clone())
    } else {
        let at = |rho: f64, th: f64, hh: f64| -> Result<[f64; 3], AlgoError> {
            centre.ecef_to_enu(geometry::plot_at_height(&radar.frame, rho, th, hh)?.0)
        };
        let (rho, th) = (e.x[0], e.x[2]);
        // A slant range too short to reach the assumed height: the plot is
        // placed at the nearest reachable one, the site's height ± 0.9 ρ.
        let hs = radar.frame.origin_geodetic().2;
        let h = h.clamp(hs - 0.9 * rho, hs + 0.9 * rho);
        let pos = at(rho, th, h)?;
        let steps = [1.0, 1e-6, 1.0];
        let jac = jacobian(
            |y| at(y[0], y[1], y[2]).map(|p| p.to_vec()),
            [rho, th, h],
            steps,
        )?;
        let mut py = DMatrix::zeros(6, 6);
        py.view_mut((0, 0), (4, 4)).copy_from(&e.p);
        py[(4, 4)] = sigma_h * sigma_h;
        py[(5, 5)] = CLIMB_SIGMA_MPS * CLIMB_SIGMA_MPS;
        (pos, jac, py)
    };
    // Interleaved block transform: positions and rates through the same J.
    let a = DMatrix::from_fn(6, 6, |r, c| {
        if r % 2 == c % 2 {
            jac[(r / 2, c / 2)]
        } else {
            0.0
        }
    });
    let mut y = DVector::zeros(6);
    for i in 0..e.x.len() {
        y[i] = e.x[i];
    }
    let v = &a * &y;
    let x = DVector::from_vec(vec![pos[0], v[1], pos[1], v[3], pos[2], v[5]]);
    let mut p = &a * py * a.transpose();
    crate::algo::gaussian::symmetrize(&mut p);
    Ok(State6 { t: e.t, x, p })
}

/// The estimate of a track at `t`: its latest at or before `t`, extrapolated
/// (constant velocity, no process noise) when at most `max_gap` old.
fn at_time(track: &[State6], t: f64, max_gap: f64) -> Option<State6> {
    let k = track.partition_point(|s| s.t <= t);
    let s = track.get(k.checked_sub(1)?)?;
    let dt = t - s.t;
    if dt > max_gap {
        return None;
    }
    let f = alpha_beta::transition(3, dt);
    Some(State6 {
        t,
        x: &f * &s.x,
        p: &f * &s.p * f.transpose(),
    })
}

/// The test coordinates of a method and their Jacobian (rows × 6).
fn test_space(
    centre: &LocalFrame,
    method: Method,
    s: &State6,
) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    let pos = [s.x[0], s.x[2], s.x[4]];
    let g = |p: [f64; 3]| -> Result<Vec<f64>, AlgoError> {
        let ecef = centre.enu_to_ecef(p)?;
        Ok(match method {
            Method::Mapping => p.to_vec(),
            Method::Lifting => geometry::footprint(centre, ecef)?.to_vec(),
            Method::Splitting => geometry::direction(centre, ecef)?.to_vec(),
        })
    };
    let z = g(pos)?;
    let m = z.len();
    // Only the positions enter: the columns of the rates stay zero.
    let j3 = jacobian(g, pos, [1.0; 3])?;
    let mut jac = DMatrix::zeros(m, 6);
    for k in 0..3 {
        jac.set_column(2 * k, &j3.column(k));
    }
    Ok((DVector::from_vec(z), jac))
}

#[allow(clippy::too_many_arguments)]
fn correlate_pair(
    centre: &LocalFrame,
    radars: &[Radar],
    tracks: &[LocalTrack],
    centred: &[Vec<State6>],
    a: usize,
    b: usize,
    method: Method,
    cfg: &Config,
) -> Result<PairReport, AlgoError> {
    // The track of the slower radar drives the test instants.
    let (ra, rb) = (&radars[tracks[a].radar], &radars[tracks[b].radar]);
    let (driver, other, gap) = if ra.scan_period >= rb.scan_period {
        (a, b, 1.5 * rb.scan_period)
    } else {
        (b, a, 1.5 * ra.scan_period)
    };
    let mut state = PairState::new();
    let (mut sum, mut n) = (0.0, 0u32);
    for s in &centred[driver] {
        if !state.wants_test() {
            break;
        }
        let Some(o) = at_time(&centred[other], s.t, gap) else {
            continue;
        };
        let (za, ja) = test_space(centre, method, s)?;
        let (zb, jb) = test_space(centre, method, &o)?;
        let d = za - zb;
        let cov = &ja * &s.p * ja.transpose() + &jb * &o.p * jb.transpose();
        let chol = cov
            .clone()
            .cholesky()
            .ok_or(AlgoError::NotPositiveDefinite {
                what: "pair difference covariance",
            })?;
        let stat = d.dot(&chol.solve(&d));
        let hit = (0..d.len()).all(|i| d[i].abs() <= cfg.gate_sigmas * cov[(i, i)].sqrt());
        let threshold = if d.len() == 3 { cfg.chi2_3 } else { cfg.chi2_2 };
        state.step(cfg.knn, hit, stat <= threshold);
        sum += stat;
        n += 1;
    }
    Ok(PairReport {
        a: a.min(b),
        b: a.max(b),
        state,
        mean_statistic: if n > 0 { sum / n as f64 } else { f64::INFINITY },
    })
}

/// Central-difference Jacobian of `f` at `x` with steps `h`
/// (rows: outputs, columns: the three inputs).
fn jacobian(
    f: impl Fn([f64; 3]) -> Result<Vec<f64>, AlgoError>,
    x: [f64; 3],
    h: [f64; 3],
) -> Result<DMatrix<f64>, AlgoError> {
    let m = f(x)?.len();
    let mut jac = DMatrix::zeros(m, 3);
    for k in 0..3 {
        let (mut hi, mut lo) = (x, x);
        hi[k] += h[k];
        lo[k] -= h[k];
        let (a, b) = (f(hi)?, f(lo)?);
        for i in 0..m {
            jac[(i, k)] = (a[i] - b[i]) / (2.0 * h[k]);
        }
    }
    Ok(jac)
}

/// Independent estimates fused by Bar-Shalom–Campo with zero cross-covariance
/// (the information-weighted mean).
fn fuse_independent(members: &[State6]) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    let mut x = members[0].x.clone();
    let mut p = members[0].p.clone();
    let n = x.len();
    for m in &members[1..] {
        let f = bar_shalom_campo(&x, &p, &m.x, &m.p, &DMatrix::zeros(n, n))?;
        x = f.x;
        p = f.p;
    }
    Ok((x, p))
}

fn system_track(
    centre: &LocalFrame,
    radars: &[Radar],
    filtered: &[Filtered],
    centred: &[Vec<State6>],
    members: Vec<usize>,
    method: Method,
    cfg: &Config,
) -> Result<SystemTrack, AlgoError> {
    let has_3d = members.iter().any(|&i| radars[filtered[i].radar].three_d);
    let mut times: Vec<f64> = members
        .iter()
        .flat_map(|&i| centred[i].iter().map(|s| s.t))
        .collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let mut samples = Vec::with_capacity(times.len());
    for t in times {
        let gap = |i: usize| 1.5 * radars[filtered[i].radar].scan_period;
        let three: Vec<State6> = members
            .iter()
            .filter(|&&i| radars[filtered[i].radar].three_d)
            .filter_map(|&i| at_time(&centred[i], t, gap(i)))
            .collect();
        let mut all = three.clone();
        // 2D members: under lifting and splitting, at the 3D tracks' height.
        let lift = if method != Method::Mapping && !three.is_empty() {
            let (x3, p3) = fuse_independent(&three)?;
            let ecef = centre.enu_to_ecef([x3[0], x3[2], x3[4]])?;
            let (_, _, h) = ecef_to_geodetic(&centre.ellipsoid(), ecef)?;
            Some((h, p3[(4, 4)].sqrt().max(MAPPING_ALTITUDE_SIGMA_M)))
        } else {
            None
        };
        for &i in members
            .iter()
            .filter(|&&i| !radars[filtered[i].radar].three_d)
        {
            let f = &filtered[i];
            let k = f.est.partition_point(|e| e.t <= t);
            let Some(e) = k.checked_sub(1).map(|k| &f.est[k]) else {
                continue;
            };
            if t - e.t > gap(i) {
                continue;
            }
            let (h, sh) = match (method, lift) {
                (Method::Mapping, _) => (cfg.preset_altitude, MAPPING_ALTITUDE_SIGMA_M),
                (_, Some(l)) => l,
                (_, None) => (cfg.preset_altitude, cfg.altitude_sigma),
            };
            let s = to_centre(centre, &radars[f.radar], e, h, sh)?;
            if let Some(s) = at_time(std::slice::from_ref(&s), t, gap(i)) {
                all.push(s);
            }
        }
        if all.is_empty() {
            continue;
        }
        let (mut x, mut p) = fuse_independent(&all)?;
        if method == Method::Splitting && !three.is_empty() {
            // Direction from every track, geocentric distance from 3D tracks.
            let mut info_d = DMatrix::<f64>::zeros(2, 2);
            let mut vec_d = DVector::<f64>::zeros(2);
            for s in &all {
                let (z, j) = test_space(centre, Method::Splitting, s)?;
                let c = &j * &s.p * j.transpose();
                let inv = c.try_inverse().ok_or(AlgoError::NotPositiveDefinite {
                    what: "direction covariance",
                })?;
                vec_d += &inv * z;
                info_d += inv;
            }
            let cd = info_d.try_inverse().ok_or(AlgoError::NotPositiveDefinite {
                what: "direction information",
            })?;
            let d = &cd * vec_d;
            let (mut info_r, mut sum_r) = (0.0, 0.0);
            for s in &three {
                let ecef = nalgebra::Vector3::from(centre.enu_to_ecef([s.x[0], s.x[2], s.x[4]])?);
                let u = ecef / ecef.norm();
                let rot = centre.rotation();
                let u_enu = rot * u;
                let var = (0..3)
                    .map(|i| {
                        (0..3)
                            .map(|j| u_enu[i] * s.p[(2 * i, 2 * j)] * u_enu[j])
                            .sum::<f64>()
                    })
                    .sum::<f64>();
                info_r += 1.0 / var;
                sum_r += ecef.norm() / var;
            }
            let r = sum_r / info_r;
            let pos = |dd: [f64; 2], rr: f64| -> Result<[f64; 3], AlgoError> {
                centre.ecef_to_enu(geometry::from_direction(centre, dd, rr)?)
            };
            let p0 = pos([d[0], d[1]], r)?;
            let jac = jacobian(
                |y| pos([y[0], y[1]], y[2]).map(|p| p.to_vec()),
                [d[0], d[1], r],
                [1.0; 3],
            )?;
            let mut cy = DMatrix::zeros(3, 3);
            cy.view_mut((0, 0), (2, 2)).copy_from(&cd);
            cy[(2, 2)] = 1.0 / info_r;
            let cp = &jac * cy * jac.transpose();
            for i in 0..3 {
                x[2 * i] = p0[i];
                for j in 0..3 {
                    p[(2 * i, 2 * j)] = cp[(i, j)];
                    p[(2 * i, 2 * j + 1)] = 0.0;
                    p[(2 * j + 1, 2 * i)] = 0.0;
                }
            }
            crate::algo::gaussian::symmetrize(&mut p);
        }
        samples.push(State6 { t, x, p });
    }
    Ok(SystemTrack {
        members,
        samples,
        altitude_known: has_3d || method == Method::Mapping,
    })
}

#[cfg(test)]
mod tests;
