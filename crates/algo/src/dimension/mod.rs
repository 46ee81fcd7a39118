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
mod kernels;
pub mod knn;

use nalgebra::{Matrix2, Matrix3, Matrix6, Vector3, Vector6};

use crate::{
    AlgoError, assignment,
    geo::{LocalFrame, ecef_to_vertical},
    polar::{PolarMeasurement, plot_to_local},
};
pub use alpha_beta::Filter;
pub use knn::{KnnParams, PairState, Period};

/// σ of the climb rate given to a 2D track (level flight assumed), m/s.
pub const CLIMB_SIGMA_MPS: f64 = 10.0;
/// σ_h of the mapping method's preset altitude: the preset is explicit, with a
/// tolerance of the order of a flight level.
pub const MAPPING_ALTITUDE_SIGMA_M: f64 = 300.0;

/// The fusion method of seed 003 §1: where a 2D track's height comes from
/// and in which space pairs are tested.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// 2D tracks at the preset altitude (σ_h = 300 m); 3D test.
    Mapping,
    /// 2D tracks at the preset altitude with σ_h = `altitude_sigma`; test on
    /// the horizontal footprint; fusion puts a 2D track at the correlated 3D
    /// tracks' height.
    Lifting,
    /// As lifting, test on the direction from the Earth's centre; fusion of
    /// the direction from all tracks and of the geocentric distance from 3D
    /// tracks only.
    Splitting,
}

/// Which samples of each system track [`fuse_methods_with`] fuses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Samples {
    /// Every instant of its members, in time order (the whole history).
    All,
    /// Only its latest sample: the last one [`Samples::All`] gives, by the
    /// same operations on the same numbers (so the same bits), without
    /// fusing the instants before it. The pair tests and the groups do not
    /// depend on the system tracks' samples (a sample fuses its members'
    /// estimates at its instant, nothing of the samples before), so they
    /// are the same too; only the height lifting and splitting borrow from
    /// the 3D members reaches back, to the latest instant they cover.
    Latest,
}

/// A radar of the scene: its site, whether it measures elevation, its
/// measurement errors and its scan period.
#[derive(Debug, Clone)]
pub struct Radar {
    /// The radar's local ENU frame, at its site.
    pub frame: LocalFrame,
    /// Whether the radar measures elevation (3D); a 2D radar measures slant
    /// range and azimuth only.
    pub three_d: bool,
    /// Slant-range standard deviation (m).
    pub sigma_range: f64,
    /// Azimuth standard deviation (rad).
    pub sigma_azimuth: f64,
    /// Elevation standard deviation (rad); read for 3D radars only.
    pub sigma_elevation: f64,
    /// Scan period (s).
    pub scan_period: f64,
}

/// A plot of a local track in its radar's measurement coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plot {
    /// Time of the plot (s).
    pub t: f64,
    /// Slant range (m).
    pub range: f64,
    /// Azimuth (rad, clockwise from north).
    pub azimuth: f64,
    /// Elevation above the radar's local horizontal (rad); `None` from a 2D
    /// radar.
    pub elevation: Option<f64>,
}

/// A local track: the plots one radar reported for one target.
#[derive(Debug, Clone)]
pub struct LocalTrack {
    /// Index of the radar (into the scene's radars).
    pub radar: usize,
    /// The plots, in time order.
    pub plots: Vec<Plot>,
}

/// Parameters of the fusion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// The filter run on every local track.
    pub filter: Filter,
    /// Parameters of the modified K-NN association.
    pub knn: KnnParams,
    /// Mapping's preset altitude and the nominal height of 2D tracks (m).
    pub preset_altitude: f64,
    /// σ_h of a 2D track's unknown height under lifting and splitting (m).
    pub altitude_sigma: f64,
    /// A component of the difference is a hit within this many σ.
    pub gate_sigmas: f64,
    /// χ² thresholds of the check period for 2 and 3 degrees of freedom.
    pub chi2_2: f64,
    /// χ² threshold of the check period for 3 degrees of freedom (mapping's
    /// test).
    pub chi2_3: f64,
}

/// A centre-ENU estimate `[x, vx, y, vy, z, vz]`.
#[derive(Debug, Clone, PartialEq)]
pub struct State6 {
    /// Time of the estimate (s).
    pub t: f64,
    /// The state `[x, vx, y, vy, z, vz]` in centre ENU (m, m/s).
    pub x: Vector6<f64>,
    /// Covariance of `x`.
    pub p: Matrix6<f64>,
    /// The white-acceleration covariance (centre ENU, 3 × 3) of the local
    /// filter's model: an extrapolation by dt adds `A ⊗ [[dt⁴/4, dt³/2],
    /// [dt³/2, dt²]]`.
    pub acceleration: Matrix3<f64>,
    /// The velocity-change covariance (centre ENU) that the manoeuvre lag
    /// of the local track's next point revealed (`Estimate::lag_ahead`): an
    /// extrapolation by dt adds `V ⊗ [[dt², dt], [dt, 1]]`.
    pub velocity_jump: Matrix3<f64>,
}

/// Where the height of a system-track sample comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AltitudeSource {
    /// A 3D member contributed to this sample.
    Measured,
    /// No 3D member at this instant, but the system track has one: the 2D
    /// members sit at the height the 3D members fused at the nearest instant,
    /// its σ grown by `CLIMB_SIGMA_MPS` per second of distance (lifting and
    /// splitting).
    Lifted,
    /// Only 2D members and no height to borrow: the preset altitude with its
    /// σ (`MAPPING_ALTITUDE_SIGMA_M` under mapping, `altitude_sigma` otherwise).
    Assumed,
}

/// A system-track sample: the fused state and where its height comes from.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Time of the sample (s).
    pub t: f64,
    /// The fused state `[x, vx, y, vy, z, vz]` in centre ENU (m, m/s).
    pub x: Vector6<f64>,
    /// Covariance of `x`.
    pub p: Matrix6<f64>,
    /// Where the height comes from.
    pub altitude: AltitudeSource,
}

/// The modified K-NN result of one pair of local tracks of different
/// radars.
#[derive(Debug, Clone, PartialEq)]
pub struct PairReport {
    /// The smaller local track index.
    pub a: usize,
    /// The larger local track index.
    pub b: usize,
    /// The pair's K-NN counters after its last test.
    pub state: PairState,
    /// Mean test statistic d'S⁻¹d over all tests.
    pub mean_statistic: f64,
}

/// A system track: a group of correlated local tracks (or one track
/// alone), fused.
#[derive(Debug, Clone, PartialEq)]
pub struct SystemTrack {
    /// Local track indices, sorted.
    pub members: Vec<usize>,
    /// The fused samples, in time order.
    pub samples: Vec<Sample>,
    /// False when no 3D radar sees the track (and the method is not mapping):
    /// the height is the nominal one and must not be trusted.
    pub altitude_known: bool,
}

/// What one method made of the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Every pair of local tracks of different radars that was tested.
    pub pairs: Vec<PairReport>,
    /// The system tracks.
    pub system_tracks: Vec<SystemTrack>,
    /// Groups that would hold two tracks of one radar (links dropped).
    pub conflicts: usize,
    /// Wall time of this method (µs); the first method of
    /// [`fuse_methods`] includes the local filters and the centre-frame
    /// states that all methods share, of lifting and splitting the second
    /// to run reuses the groups the first fused, and the first of them
    /// reuses the 3D members' fusion of the groups mapping formed too.
    pub compute_us: f64,
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
    let mut out = fuse_methods(centre, radars, tracks, &[method], cfg)?;
    Ok(out.remove(0))
}

/// Runs several methods over the scene; the local filters run once, every
/// estimate is placed in the centre frame once (mapping's states and the
/// others' differ only in a 2D estimate's σ_h), a group that lifting and
/// splitting both form is fused once, and its 3D members' fusion is
/// mapping's when mapping forms it too (see `Share`).
pub fn fuse_methods(
    centre: &LocalFrame,
    radars: &[Radar],
    tracks: &[LocalTrack],
    methods: &[Method],
    cfg: &Config,
) -> Result<Vec<Outcome>, AlgoError> {
    fuse_methods_with(centre, radars, tracks, methods, cfg, Samples::All)
}

/// [`fuse_methods`] fusing `samples` of each system track: with
/// [`Samples::Latest`] each system track holds its latest sample only (what
/// an answer without history shows), and the pairs, groups and conflicts
/// are those of [`Samples::All`].
pub fn fuse_methods_with(
    centre: &LocalFrame,
    radars: &[Radar],
    tracks: &[LocalTrack],
    methods: &[Method],
    cfg: &Config,
    samples: Samples,
) -> Result<Vec<Outcome>, AlgoError> {
    let mut started = std::time::Instant::now();
    let filtered = tracks
        .iter()
        .map(|t| {
            filter_track(&radars[t.radar], t, cfg.filter).map(|est| Filtered {
                radar: t.radar,
                est,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    // Mapping and the other methods place a 2D estimate at the same preset
    // height and differ only in its σ_h; a 3D estimate does not depend on it.
    let sites: Vec<Site> = radars.iter().map(|r| Site::new(centre, r)).collect();
    let need_mapped = methods.contains(&Method::Mapping);
    let need_lifted = methods.iter().any(|&m| m != Method::Mapping);
    let (mut mapped, mut lifted) = (Vec::new(), Vec::new());
    for f in &filtered {
        let (radar, site) = (&radars[f.radar], &sites[f.radar]);
        let (mut m, mut l) = (
            Vec::with_capacity(if need_mapped { f.est.len() } else { 0 }),
            Vec::with_capacity(if need_lifted { f.est.len() } else { 0 }),
        );
        for e in &f.est {
            let at = place(centre, radar, site, e, cfg.preset_altitude)?;
            if need_mapped {
                m.push(centred_state(radar, e, &at, MAPPING_ALTITUDE_SIGMA_M));
            }
            if need_lifted {
                l.push(if radar.three_d && need_mapped {
                    m[m.len() - 1].clone()
                } else {
                    centred_state(radar, e, &at, cfg.altitude_sigma)
                });
            }
        }
        mapped.push(m);
        lifted.push(l);
    }
    let mut share = Share::default();
    let mut outs = Vec::with_capacity(methods.len());
    for (n, &method) in methods.iter().enumerate() {
        let centred = if method == Method::Mapping {
            &mapped
        } else {
            &lifted
        };
        let other = match method {
            Method::Lifting => Some(Method::Splitting),
            Method::Splitting => Some(Method::Lifting),
            Method::Mapping => None,
        };
        share.pending_other = other.is_some_and(|o| methods[n + 1..].contains(&o));
        share.pending_lifted =
            method == Method::Mapping && methods[n + 1..].iter().any(|&m| m != Method::Mapping);
        let mut out = fuse_one_sharing(
            centre, radars, &sites, tracks, &filtered, centred, method, cfg, samples, &mut share,
        )?;
        out.compute_us = started.elapsed().as_secs_f64() * 1e6;
        started = std::time::Instant::now();
        outs.push(out);
    }
    Ok(outs)
}

/// The test coordinates of a centred sample and the pieces of their
/// covariance after an extrapolation by dt: z(dt) = z + dt·J v and
/// J P_pos(dt) J' = c0 + dt c1 + dt² c2 + dt⁴ c4 (the position block P_pp + dt (P_pv + P_vp) + dt² (P_vv + V) + dt⁴ A/4 of
/// an extrapolation, through J).
struct TestPoint {
    z: Vector3<f64>,
    jv: Vector3<f64>,
    c0: Matrix3<f64>,
    c1: Matrix3<f64>,
    c2: Matrix3<f64>,
    c4: Matrix3<f64>,
}

impl TestPoint {
    fn new(s: &State6, z: Vector3<f64>, jac: Matrix3<f64>) -> Self {
        let block = |r: usize, c: usize| Matrix3::from_fn(|i, j| s.p[(2 * i + r, 2 * j + c)]);
        let t = |m: Matrix3<f64>| jac * m * jac.transpose();
        Self {
            z,
            jv: jac * Vector3::new(s.x[1], s.x[3], s.x[5]),
            c0: t(block(0, 0)),
            c1: t(block(0, 1) + block(1, 0)),
            c2: t(block(1, 1) + s.velocity_jump),
            c4: t(s.acceleration / 4.0),
        }
    }

    /// [`TestPoint::new`] with J = I (mapping), without the products by I
    /// (each adds only exact zeros).
    fn identity(s: &State6, z: Vector3<f64>) -> Self {
        let block = |r: usize, c: usize| Matrix3::from_fn(|i, j| s.p[(2 * i + r, 2 * j + c)]);
        Self {
            z,
            jv: Vector3::new(s.x[1], s.x[3], s.x[5]),
            c0: block(0, 0),
            c1: block(0, 1) + block(1, 0),
            c2: block(1, 1) + s.velocity_jump,
            c4: s.acceleration / 4.0,
        }
    }

    fn at(&self, dt: f64) -> (Vector3<f64>, Matrix3<f64>) {
        let dt2 = dt * dt;
        (
            self.z + self.jv * dt,
            self.c0 + self.c1 * dt + self.c2 * dt2 + self.c4 * (dt2 * dt2),
        )
    }
}

/// One method on its own (what [`fuse_methods`] does for it, without
/// another method to share system tracks with).
#[cfg(test)]
fn fuse_one(
    centre: &LocalFrame,
    radars: &[Radar],
    tracks: &[LocalTrack],
    filtered: &[Filtered],
    centred: &[Vec<State6>],
    method: Method,
    cfg: &Config,
) -> Result<Outcome, AlgoError> {
    let mut share = Share::default();
    let sites: Vec<Site> = radars.iter().map(|r| Site::new(centre, r)).collect();
    fuse_one_sharing(
        centre,
        radars,
        &sites,
        tracks,
        filtered,
        centred,
        method,
        cfg,
        Samples::All,
        &mut share,
    )
}

/// The system tracks that lifting and splitting have in common. Both place
/// 2D members alike and fuse alike; splitting then redoes the position of a
/// sample with a 3D member from the direction and the geocentric distance.
/// So when both methods run and form the same group, the group is fused
/// once: the first of the two keeps it here (with the positions splitting
/// needs) and the second takes it.
///
/// Mapping fuses the 3D members of a group as the other two do (a 3D
/// estimate does not depend on σ_h): when lifting or splitting runs after
/// it, mapping keeps the 3D pass of each group here ([`ThreePass`]) and the
/// first of them to form the same group takes it.
#[derive(Default)]
struct Share {
    /// The other method of the two runs later in this call.
    pending_other: bool,
    /// Lifting or splitting runs later in this call (set for mapping).
    pending_lifted: bool,
    tracks: std::collections::HashMap<Vec<usize>, Fused>,
    three: std::collections::HashMap<Vec<usize>, ThreePass>,
}

#[allow(clippy::too_many_arguments)]
fn fuse_one_sharing(
    centre: &LocalFrame,
    radars: &[Radar],
    sites: &[Site],
    tracks: &[LocalTrack],
    filtered: &[Filtered],
    centred: &[Vec<State6>],
    method: Method,
    cfg: &Config,
    samples: Samples,
    share: &mut Share,
) -> Result<Outcome, AlgoError> {
    let mut points: Vec<Vec<TestPoint>> = Vec::with_capacity(centred.len());
    for tr in centred {
        let mut row = Vec::with_capacity(tr.len());
        for s in tr {
            let pos = [s.x[0], s.x[2], s.x[4]];
            row.push(if method == Method::Mapping {
                // J = I: the pieces are the blocks themselves.
                TestPoint::identity(s, Vector3::from(pos))
            } else {
                let (_, z, jac) = geometry::test_space(centre, method, pos)?;
                TestPoint::new(s, z, jac)
            });
        }
        points.push(row);
    }

    // Pairwise modified K-NN.
    let mut pairs = Vec::with_capacity(tracks.len() * tracks.len() / 2);
    for a in 0..tracks.len() {
        for b in a + 1..tracks.len() {
            if tracks[a].radar == tracks[b].radar || centred[a].is_empty() || centred[b].is_empty()
            {
                continue;
            }
            pairs.push(correlate_pair(
                radars, tracks, centred, &points, a, b, method, cfg,
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
        .map(|g| {
            let fuse = |g: Vec<usize>, three: &ThreePass, spots: bool| {
                let track = |g: Vec<usize>, three: &ThreePass, samples: Samples| {
                    fused_track(
                        centre,
                        radars,
                        sites,
                        filtered,
                        centred,
                        g,
                        three,
                        method,
                        cfg.altitude_sigma,
                        spots,
                        samples,
                    )
                };
                let fused = track(g, three, samples)?;
                if samples == Samples::All || !fused.track.samples.is_empty() {
                    return Ok(fused);
                }
                // No sample at the last instant, which only a negative scan
                // period can do (a member's own instant out of its gap; the
                // service refuses it): the latest of the whole history.
                let g = fused.track.members;
                let all = three_pass(radars, filtered, centred, &g, spots, Samples::All)?;
                let mut fused = track(g, &all, Samples::All)?;
                keep_latest(&mut fused);
                Ok(fused)
            };
            if method == Method::Mapping {
                // The 3D pass kept for lifting or splitting keeps the spots
                // that splitting reads.
                let three =
                    three_pass(radars, filtered, centred, &g, share.pending_lifted, samples)?;
                let track = fuse(g.clone(), &three, false)?.track;
                if share.pending_lifted {
                    share.three.insert(g, three);
                }
                return Ok(track);
            }
            let mut fused = match share.tracks.remove(&g) {
                Some(f) => f,
                None => {
                    let spots = method == Method::Splitting || share.pending_other;
                    let three = match share.three.remove(&g) {
                        Some(three) => three,
                        None => three_pass(radars, filtered, centred, &g, spots, samples)?,
                    };
                    fuse(g.clone(), &three, spots)?
                }
            };
            // The fused track is kept for the other method, or moved out.
            if share.pending_other {
                let track = fused.track.clone();
                let track = if method == Method::Splitting {
                    split_track(centre, track, &fused)?
                } else {
                    track
                };
                share.tracks.insert(g, fused);
                Ok(track)
            } else if method == Method::Splitting {
                let track = std::mem::replace(
                    &mut fused.track,
                    SystemTrack {
                        members: Vec::new(),
                        samples: Vec::new(),
                        altitude_known: false,
                    },
                );
                split_track(centre, track, &fused)
            } else {
                Ok(fused.track)
            }
        })
        .collect::<Result<Vec<_>, AlgoError>>()?;
    Ok(Outcome {
        pairs,
        system_tracks,
        conflicts,
        compute_us: 0.0,
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

/// The local filter of one track, fed from the plots directly on fixed-size
/// measurements (a 3D plot's local ENU position and covariance as
/// `plot_to_local` gives them; a 2D plot's range and azimuth).
fn filter_track(
    radar: &Radar,
    track: &LocalTrack,
    filter: Filter,
) -> Result<Vec<alpha_beta::Estimate>, AlgoError> {
    let times: Vec<f64> = track.plots.iter().map(|p| p.t).collect();
    if radar.three_d {
        let mut z = Vec::with_capacity(track.plots.len());
        let mut r = Vec::with_capacity(track.plots.len());
        for p in &track.plots {
            let (mean, cov) = local_3d(radar, p)?;
            z.push(mean);
            r.push(cov);
        }
        alpha_beta::filter_fixed::<3, 6>(filter, &times, |k| z[k], |k| r[k], &[false; 3], &[1.0; 3])
    } else {
        let r = Matrix2::from_diagonal(&nalgebra::Vector2::new(
            radar.sigma_range.powi(2),
            radar.sigma_azimuth.powi(2),
        ));
        let mean_range =
            track.plots.iter().map(|p| p.range).sum::<f64>() / track.plots.len().max(1) as f64;
        alpha_beta::filter_fixed::<2, 4>(
            filter,
            &times,
            |k| nalgebra::Vector2::new(track.plots[k].range, track.plots[k].azimuth),
            |_| r,
            &[false, true],
            &[1.0, 1.0 / mean_range.max(1.0)],
        )
    }
}

/// A 3D plot's local ENU position and covariance J R J' (symmetrised), the
/// numbers `plot_to_local` gives for a site at the origin, by the same
/// operations on fixed-size matrices instead of heap-allocated ones. A plot
/// that is not plainly valid (a non-finite or negative value, an elevation
/// beyond ±π/2, a covariance its checks would refuse) goes through
/// `plot_to_local` itself, for its checks and its error.
fn local_3d(radar: &Radar, p: &Plot) -> Result<(Vector3<f64>, Matrix3<f64>), AlgoError> {
    let (sr, sa, se) = (
        radar.sigma_range,
        radar.sigma_azimuth,
        radar.sigma_elevation,
    );
    let fast = || -> Option<(Vector3<f64>, Matrix3<f64>)> {
        let (r, az, el) = (p.range, p.azimuth, p.elevation?);
        let plain = r.is_finite()
            && r >= 0.0
            && az.is_finite()
            && el.is_finite()
            && (-std::f64::consts::FRAC_PI_2..=std::f64::consts::FRAC_PI_2).contains(&el)
            && [sr, sa, se].iter().all(|s| s.is_finite() && *s > 0.0);
        if !plain {
            return None;
        }
        let (s_az, c_az) = az.sin_cos();
        let (s_el, c_el) = el.sin_cos();
        let pos = [r * c_el * s_az, r * c_el * c_az, r * s_el];
        // The site (the origin) plus the offset, as `plot_to_local` adds it.
        let mean = Vector3::from_fn(|i, _| 0.0 + pos[i]);
        #[rustfmt::skip]
        let j = Matrix3::new(
            c_el * s_az, r * c_el * c_az, -r * s_el * s_az,
            c_el * c_az, -r * c_el * s_az, -r * s_el * c_az,
            s_el, 0.0, r * c_el,
        );
        let rm = Matrix3::from_diagonal(&Vector3::new(sr * sr, sa * sa, se * se));
        let mut c = j * rm * j.transpose();
        for col in 0..3 {
            for row in col + 1..3 {
                let m = 0.5 * (c[(row, col)] + c[(col, row)]);
                c[(row, col)] = m;
                c[(col, row)] = m;
            }
        }
        // `Gaussian::new`'s checks: finite, and a Cholesky factor with a
        // positive finite diagonal (exactly symmetric after the above).
        if !(mean.iter().all(|v| v.is_finite()) && c.iter().all(|v| v.is_finite())) {
            return None;
        }
        let l = c.cholesky()?.unpack_dirty();
        (0..3)
            .all(|i| l[(i, i)] > 0.0 && l[(i, i)].is_finite())
            .then_some((mean, c))
    };
    if let Some(v) = fast() {
        return Ok(v);
    }
    let g = plot_to_local(
        [0.0; 3],
        &PolarMeasurement {
            range: p.range,
            azimuth: p.azimuth,
            elevation: p.elevation,
            sigma_range: sr,
            sigma_azimuth: sa,
            sigma_elevation: Some(se),
        },
    )?;
    let (mean, cov) = (g.mean(), g.cov());
    Ok((
        Vector3::from_fn(|i, _| mean[i]),
        Matrix3::from_fn(|i, j| cov[(i, j)]),
    ))
}

/// A local estimate as a centre-ENU state. 2D estimates `[ρ, ρ̇, θ, θ̇]` are
/// placed at height `h` (σ_h) with level flight (climb σ `CLIMB_SIGMA_MPS`).
fn to_centre(
    centre: &LocalFrame,
    radar: &Radar,
    site: &Site,
    e: &alpha_beta::Estimate,
    h: f64,
    sigma_h: f64,
) -> Result<State6, AlgoError> {
    Ok(centred_state(
        radar,
        e,
        &place(centre, radar, site, e, h)?,
        sigma_h,
    ))
}

/// What [`place`] needs of a radar alone, computed once per call of
/// [`fuse_methods`] rather than once per estimate (same operations, same
/// bits).
struct Site {
    /// A 2D radar's cone of slant range and azimuth.
    cone: Option<geometry::Cone>,
    /// The rotation from the radar's ENU axes to the centre's.
    to_centre: Matrix3<f64>,
}

impl Site {
    fn new(centre: &LocalFrame, radar: &Radar) -> Self {
        Self {
            cone: (!radar.three_d).then(|| geometry::Cone::new(&radar.frame, centre)),
            to_centre: radar.frame.rotation_to(centre),
        }
    }
}

/// Where [`to_centre`] puts an estimate, before σ_h enters: the position,
/// the Jacobian to centre ENU, and the filter's acceleration and
/// velocity-jump covariances in centre ENU.
struct Placed {
    pos: [f64; 3],
    jac: Matrix3<f64>,
    acceleration: Matrix3<f64>,
    velocity_jump: Matrix3<f64>,
}

fn place(
    centre: &LocalFrame,
    radar: &Radar,
    site: &Site,
    e: &alpha_beta::Estimate,
    h: f64,
) -> Result<Placed, AlgoError> {
    let (pos, jac, acceleration, velocity_jump) = if radar.three_d {
        let pos = radar.frame.position_to(centre, [e.x[0], e.x[2], e.x[4]])?;
        let jac = site.to_centre;
        let (a, v) = (e.acceleration, e.lag_ahead);
        (
            pos,
            jac,
            jac * a * jac.transpose(),
            jac * v * jac.transpose(),
        )
    } else {
        let (rho, th) = (e.x[0], e.x[2]);
        // A slant range too short to reach the assumed height: the plot is
        // placed at the nearest reachable one, the site's height ± 0.9 ρ.
        let hs = radar.frame.origin_geodetic().2;
        let h = h.clamp(hs - 0.9 * rho, hs + 0.9 * rho);
        let cone = site.cone.as_ref().ok_or(AlgoError::DegenerateGeometry {
            what: "2D radar",
            reason: "no cone for a 3D radar",
        })?;
        let (pos, jac) = cone.place(rho, th, h)?;
        // Range and azimuth accelerations through the cone; none in height.
        let a: Matrix2<f64> = e.acceleration.fixed_view::<2, 2>(0, 0).into_owned();
        let v: Matrix2<f64> = e.lag_ahead.fixed_view::<2, 2>(0, 0).into_owned();
        let j2 = jac.fixed_columns::<2>(0);
        (pos, jac, j2 * a * j2.transpose(), j2 * v * j2.transpose())
    };
    Ok(Placed {
        pos,
        jac,
        acceleration,
        velocity_jump,
    })
}

/// The centre-ENU state of an estimate [`place`]d, with σ_h for a 2D one.
fn centred_state(radar: &Radar, e: &alpha_beta::Estimate, at: &Placed, sigma_h: f64) -> State6 {
    // A 2D estimate's state and covariance fill the first 4 rows (the rest
    // of its fixed-size storage is zero).
    let y = e.x;
    let mut py = e.p;
    if !radar.three_d {
        py[(4, 4)] = sigma_h * sigma_h;
        py[(5, 5)] = CLIMB_SIGMA_MPS * CLIMB_SIGMA_MPS;
    }
    let v = kernels::interleaved_apply(&at.jac, &y);
    let x = Vector6::new(at.pos[0], v[1], at.pos[1], v[3], at.pos[2], v[5]);
    let p = kernels::interleaved_congruence(&at.jac, &py);
    State6 {
        t: e.t,
        x,
        p: (p + p.transpose()) * 0.5,
        acceleration: at.acceleration,
        velocity_jump: at.velocity_jump,
    }
}

/// The estimate of a track at `t`: its latest at or before `t`, extrapolated
/// (constant velocity, with the filter's white acceleration) when at most
/// `max_gap` old.
#[cfg(test)]
fn at_time(track: &[State6], t: f64, max_gap: f64) -> Option<State6> {
    let k = track.partition_point(|s| s.t <= t);
    let s = track.get(k.checked_sub(1)?)?;
    extrapolate(s, t, max_gap)
}

fn extrapolate(s: &State6, t: f64, max_gap: f64) -> Option<State6> {
    let dt = t - s.t;
    if dt > max_gap {
        return None;
    }
    let q = alpha_beta::white_acceleration(dt);
    let mut p = kernels::transition_congruence(&s.p, dt);
    for i in 0..3 {
        for j in 0..3 {
            let (a, v) = (s.acceleration[(i, j)], s.velocity_jump[(i, j)]);
            p[(2 * i, 2 * j)] += a * q[0] + v * dt * dt;
            p[(2 * i, 2 * j + 1)] += a * q[1] + v * dt;
            p[(2 * i + 1, 2 * j)] += a * q[1] + v * dt;
            p[(2 * i + 1, 2 * j + 1)] += a * q[2] + v;
        }
    }
    let mut x = s.x;
    for i in 0..3 {
        x[2 * i] = s.x[2 * i] + dt * s.x[2 * i + 1];
    }
    Some(State6 {
        t,
        x,
        p,
        acceleration: s.acceleration,
        velocity_jump: s.velocity_jump,
    })
}

/// One pair of tracks through the modified K-NN. The test coordinates of
/// every sample are computed once per method (`points`); the other track's
/// at a test instant are its latest sample's moved by the Jacobian times the
/// displacement (at most 1.5 scans of flight: the second-order term is
/// metres against σ of hundreds).
#[allow(clippy::too_many_arguments)]
fn correlate_pair(
    radars: &[Radar],
    tracks: &[LocalTrack],
    centred: &[Vec<State6>],
    points: &[Vec<TestPoint>],
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
    let dim = if method == Method::Mapping { 3 } else { 2 };
    let threshold = if dim == 3 { cfg.chi2_3 } else { cfg.chi2_2 };
    let mut state = PairState::new();
    let (mut sum, mut n) = (0.0, 0u32);
    let (ot, op) = (&centred[other], &points[other]);
    let (first, last) = (ot[0].t, ot[ot.len() - 1].t + gap);
    let mut next = 0;
    for (s, sp) in centred[driver].iter().zip(&points[driver]) {
        if !state.wants_test() {
            break;
        }
        if s.t < first || s.t > last {
            continue;
        }
        // The other track's latest sample at or before s.t (a forward scan:
        // the driver's instants increase).
        while next < ot.len() && ot[next].t <= s.t {
            next += 1;
        }
        let Some(k) = next.checked_sub(1) else {
            continue;
        };
        let dt = s.t - ot[k].t;
        if dt > gap {
            continue;
        }
        let (zb, cb) = op[k].at(dt);
        let d = sp.z - zb;
        let cov = sp.c0 + cb;
        let stat =
            kernels::quadratic_form(&cov, &d, dim).ok_or(AlgoError::NotPositiveDefinite {
                what: "pair difference covariance",
            })?;
        let hit = (0..dim).all(|i| d[i].abs() <= cfg.gate_sigmas * cov[(i, i)].sqrt());
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

/// Independent estimates fused by Bar-Shalom–Campo with zero cross-covariance
/// (the information-weighted mean): x = x₁ + P₁ (P₁ + P₂)⁻¹ (x₂ − x₁),
/// P = P₁ − P₁ (P₁ + P₂)⁻¹ P₁, one member after the other.
fn fuse_independent(members: &[State6]) -> Result<(Vector6<f64>, Matrix6<f64>), AlgoError> {
    fuse_into(members[0].x, members[0].p, &members[1..])
}

/// [`fuse_independent`] of a fused estimate `(x, p)` followed by `members`.
fn fuse_into(
    mut x: Vector6<f64>,
    mut p: Matrix6<f64>,
    members: &[State6],
) -> Result<(Vector6<f64>, Matrix6<f64>), AlgoError> {
    for m in members {
        (x, p) = kernels::fuse_step(&x, &p, &m.x, &m.p).ok_or(AlgoError::NotPositiveDefinite {
            what: "P1 + P2 - P12 - P21",
        })?;
    }
    if !all_finite(x.as_slice()) || !all_finite(p.as_slice()) {
        return Err(AlgoError::NotPositiveDefinite {
            what: "fused covariance",
        });
    }
    Ok((x, p))
}

/// Whether every value is finite, without a branch per value: an OR of
/// `!is_finite` over the values (an integer test of the exponent bits,
/// which the compiler vectorises; a sum of `x · 0`, as this was, is a chain
/// of dependent floating-point additions that it may not reorder).
fn all_finite(v: &[f64]) -> bool {
    !v.iter().fold(false, |bad, x| bad | !x.is_finite())
}

/// Position and position covariance of a member's state at a system-track
/// instant: what splitting's direction and distance fusion reads.
#[derive(Debug, Clone, Copy)]
struct Spot {
    pos: [f64; 3],
    cov: Matrix3<f64>,
}

impl Spot {
    fn of(s: &State6) -> Self {
        Self {
            pos: [s.x[0], s.x[2], s.x[4]],
            cov: Matrix3::from_fn(|i, k| s.p[(2 * i, 2 * k)]),
        }
    }
}

/// A system track fused as lifting fuses it (mapping: as mapping does),
/// and, when asked for, the members' [`Spot`]s of every sample with a 3D
/// member (3D members first), from which [`split_track`] makes splitting's.
struct Fused {
    track: SystemTrack,
    /// Per sample: `(start, three, end)`, the sample's spots are
    /// `spots[start..end]`, the first `three` of them 3D members'.
    split: Vec<Option<(usize, usize, usize)>>,
    spots: Vec<Spot>,
}

/// The 3D members' part of a group's system track, the same under every
/// method: the instants of all members, and at each the fusion of the 3D
/// members' estimates (extrapolated to it, `None` when none covers it),
/// with, when asked for, their [`Spot`]s (`spots3[ranges3[n]]` for the n-th
/// instant with a 3D fusion).
struct ThreePass {
    times: Vec<f64>,
    fused3: Vec<Option<(Vector6<f64>, Matrix6<f64>)>>,
    spots3: Vec<Spot>,
    ranges3: Vec<std::ops::Range<usize>>,
}

/// The 3D pass of a group over every instant of its members, or with
/// [`Samples::Latest`] over the instants from the latest that a 3D member
/// covers (the height lifting and splitting borrow at the last instant) to
/// the last; none covered: the last instant alone.
fn three_pass(
    radars: &[Radar],
    filtered: &[Filtered],
    centred: &[Vec<State6>],
    members: &[usize],
    keep_spots: bool,
    samples: Samples,
) -> Result<ThreePass, AlgoError> {
    let mut times: Vec<f64> = members
        .iter()
        .flat_map(|&i| centred[i].iter().map(|s| s.t))
        .collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let three_d: Vec<usize> = members
        .iter()
        .copied()
        .filter(|&i| radars[filtered[i].radar].three_d)
        .collect();
    if samples == Samples::Latest {
        // A member covers t when its latest sample at or before t is at
        // most its gap old (`extrapolate`'s test).
        let covers = |t: f64| {
            three_d.iter().any(|&i| {
                let tr = &centred[i];
                let k = tr.partition_point(|s| s.t <= t);
                let gap = 1.5 * radars[filtered[i].radar].scan_period;
                k.checked_sub(1).is_some_and(|k| {
                    let stale = t - tr[k].t > gap;
                    !stale
                })
            })
        };
        let last = times.len().saturating_sub(1);
        let from = (0..times.len()).rev().find(|&n| covers(times[n]));
        times.drain(..from.unwrap_or(last));
    }
    // `at_time` for non-decreasing t: each member's latest sample at or
    // before t found by a forward scan from the previous instant's.
    let mut cursor = vec![0; three_d.len()];
    let mut all: Vec<State6> = Vec::with_capacity(three_d.len());
    let mut fused3 = Vec::with_capacity(times.len());
    let (mut spots3, mut ranges3) = if keep_spots {
        (
            Vec::with_capacity(times.len() * three_d.len()),
            Vec::with_capacity(times.len()),
        )
    } else {
        (Vec::new(), Vec::new())
    };
    for &t in &times {
        all.clear();
        for (&i, k) in three_d.iter().zip(cursor.iter_mut()) {
            let tr = &centred[i];
            while *k < tr.len() && tr[*k].t <= t {
                *k += 1;
            }
            let gap = 1.5 * radars[filtered[i].radar].scan_period;
            if let Some(s) = k.checked_sub(1).and_then(|k| extrapolate(&tr[k], t, gap)) {
                all.push(s);
            }
        }
        if all.is_empty() {
            fused3.push(None);
            continue;
        }
        if keep_spots {
            let start = spots3.len();
            spots3.extend(all.iter().map(Spot::of));
            ranges3.push(start..spots3.len());
        }
        fused3.push(Some(fuse_independent(&all)?));
    }
    Ok(ThreePass {
        times,
        fused3,
        spots3,
        ranges3,
    })
}

/// The system track of a group: at every instant of its members, the 3D
/// members' fusion (`three`, from [`three_pass`] with the spots when
/// `keep_spots`), then the 2D members (under lifting and splitting at the
/// 3D members' height) fused into it one by one. With [`Samples::Latest`]
/// (and `three` from [`three_pass`] under it) only the last instant's
/// sample, the instants before it read for the height they give alone.
#[allow(clippy::too_many_arguments)]
fn fused_track(
    centre: &LocalFrame,
    radars: &[Radar],
    sites: &[Site],
    filtered: &[Filtered],
    centred: &[Vec<State6>],
    members: Vec<usize>,
    three: &ThreePass,
    method: Method,
    altitude_sigma: f64,
    keep_spots: bool,
    wanted: Samples,
) -> Result<Fused, AlgoError> {
    let has_3d = members.iter().any(|&i| radars[filtered[i].radar].three_d);
    let (times, fused3) = (&three.times, &three.fused3);
    let gap = |i: usize| 1.5 * radars[filtered[i].radar].scan_period;
    let two_d: Vec<usize> = members
        .iter()
        .copied()
        .filter(|&i| !radars[filtered[i].radar].three_d)
        .collect();
    // The height the 3D members give at each instant they cover (t, h, σ_h).
    let mut heights: Vec<(f64, f64, f64)> = Vec::with_capacity(times.len());
    if method != Method::Mapping {
        for (&t, f3) in times.iter().zip(fused3) {
            if let Some((x3, p3)) = f3 {
                let ecef = centre.enu_to_ecef([x3[0], x3[2], x3[4]])?;
                let h = ecef_to_vertical(&centre.ellipsoid(), ecef)?.h;
                heights.push((t, h, p3[(4, 4)].sqrt().max(MAPPING_ALTITUDE_SIGMA_M)));
            }
        }
    }
    let mut all: Vec<State6> = Vec::with_capacity(members.len());
    let mut samples = Vec::with_capacity(times.len());
    let (mut split, mut spots) = if keep_spots {
        (
            Vec::with_capacity(times.len()),
            Vec::with_capacity(times.len() * members.len()),
        )
    } else {
        (Vec::new(), Vec::new())
    };
    // The first instant fused: the last one under `Samples::Latest`.
    let first = match wanted {
        Samples::All => 0,
        Samples::Latest => times.len().saturating_sub(1),
    };
    // `ranges3` holds one range per instant with a 3D fusion (those skipped
    // included).
    let mut ranges3 = three.ranges3.iter().skip(if keep_spots {
        fused3[..first].iter().filter(|f| f.is_some()).count()
    } else {
        0
    });
    let mut cursor2 = vec![0; two_d.len()];
    let mut next_height = 0;
    for (&t, f3) in times.iter().zip(fused3).skip(first) {
        all.clear();
        while next_height + 1 < heights.len() && heights[next_height + 1].0 <= t {
            next_height += 1;
        }
        // 2D members: under lifting and splitting, at the 3D tracks' height,
        // now or at the nearest instant they gave one (`None`: as centred).
        let nearest = [next_height, next_height + 1]
            .into_iter()
            .filter_map(|k| heights.get(k))
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()));
        let (placement, altitude) = if method == Method::Mapping {
            let alt = if f3.is_none() {
                AltitudeSource::Assumed
            } else {
                AltitudeSource::Measured
            };
            (None, alt)
        } else {
            match nearest {
                // The 3D members are fused in this sample too: the 2D
                // members sit at their height but keep σ_h = altitude_sigma
                // along the cone, or that height would count twice.
                Some(&(t3, h, _)) if t3 == t => {
                    (Some((h, altitude_sigma)), AltitudeSource::Measured)
                }
                Some(&(t3, h, sh)) => {
                    let grown = (sh * sh + (CLIMB_SIGMA_MPS * (t - t3)).powi(2)).sqrt();
                    (Some((h, grown)), AltitudeSource::Lifted)
                }
                None => (None, AltitudeSource::Assumed),
            }
        };
        for (&i, k) in two_d.iter().zip(cursor2.iter_mut()) {
            let f = &filtered[i];
            while *k < f.est.len() && f.est[*k].t <= t {
                *k += 1;
            }
            let Some(k) = k.checked_sub(1) else {
                continue;
            };
            if t - f.est[k].t > gap(i) {
                continue;
            }
            let s = match placement {
                Some((h, sh)) => extrapolate(
                    &to_centre(centre, &radars[f.radar], &sites[f.radar], &f.est[k], h, sh)?,
                    t,
                    gap(i),
                ),
                None => extrapolate(&centred[i][k], t, gap(i)),
            };
            all.extend(s);
        }
        // The 3D members' fusion first, then the 2D members one by one (the
        // order of `fuse_independent` over 3D then 2D members).
        let (x, p) = match (f3, all.is_empty()) {
            (None, true) => continue,
            (None, false) => fuse_independent(&all)?,
            (Some((x3, p3)), _) => fuse_into(*x3, *p3, &all)?,
        };

        if keep_spots {
            split.push(match f3.as_ref().and_then(|_| ranges3.next()) {
                Some(r) => {
                    let start = spots.len();
                    spots.extend_from_slice(&three.spots3[r.clone()]);
                    spots.extend(all.iter().map(Spot::of));
                    Some((start, r.len(), spots.len()))
                }
                None => None,
            });
        }
        samples.push(Sample { t, x, p, altitude });
    }
    Ok(Fused {
        track: SystemTrack {
            members,
            samples,
            altitude_known: has_3d || method == Method::Mapping,
        },
        split,
        spots,
    })
}

/// Keeps the latest sample of a fused track (and its spots' entry).
fn keep_latest(fused: &mut Fused) {
    let n = fused.track.samples.len().saturating_sub(1);
    fused.track.samples.drain(..n);
    if !fused.split.is_empty() {
        fused.split.drain(..n);
    }
}

/// Splitting's system track from the one lifting fuses: at every sample with
/// a 3D member, the direction from the Earth's centre fused from all members
/// and the geocentric distance from the 3D members replace the position.
/// `track` is the lifted track of `fused` (moved out of it or a copy).
fn split_track(
    centre: &LocalFrame,
    mut track: SystemTrack,
    fused: &Fused,
) -> Result<SystemTrack, AlgoError> {
    for (sample, split) in track.samples.iter_mut().zip(&fused.split) {
        let Some(&(start, n3, end)) = split.as_ref() else {
            continue;
        };
        let (all, three) = (&fused.spots[start..end], &fused.spots[start..start + n3]);
        let (x, p) = (&mut sample.x, &mut sample.p);
        // Direction from every track, geocentric distance from 3D tracks.
        let mut info_d = Matrix2::<f64>::zeros();
        let mut vec_d = nalgebra::Vector2::<f64>::zeros();
        for s in all {
            let (_, z, j) = geometry::test_space(centre, Method::Splitting, s.pos)?;
            let pos = s.cov;
            let j2 = j.fixed_rows::<2>(0);
            let c = j2 * pos * j2.transpose();
            let inv = c.try_inverse().ok_or(AlgoError::NotPositiveDefinite {
                what: "direction covariance",
            })?;
            vec_d += inv * z.fixed_rows::<2>(0);
            info_d += inv;
        }
        let cd = info_d.try_inverse().ok_or(AlgoError::NotPositiveDefinite {
            what: "direction information",
        })?;
        let d = cd * vec_d;
        let (mut info_r, mut sum_r) = (0.0, 0.0);
        for s in three {
            let ecef = Vector3::from(centre.enu_to_ecef(s.pos)?);
            let u = ecef / ecef.norm();
            let u_enu = centre.rotation() * u;
            let var = (0..3)
                .map(|i| {
                    (0..3)
                        .map(|j| u_enu[i] * s.cov[(i, j)] * u_enu[j])
                        .sum::<f64>()
                })
                .sum::<f64>();
            info_r += 1.0 / var;
            sum_r += ecef.norm() / var;
        }
        let r = sum_r / info_r;
        let p0 = centre.ecef_to_enu(geometry::from_direction(centre, [d[0], d[1]], r)?)?;
        let jac = geometry::from_direction_jacobian([d[0], d[1]], r)?;
        let mut cy = Matrix3::zeros();
        cy.fixed_view_mut::<2, 2>(0, 0).copy_from(&cd);
        cy[(2, 2)] = 1.0 / info_r;
        let cp = jac * cy * jac.transpose();
        for i in 0..3 {
            x[2 * i] = p0[i];
            for j in 0..3 {
                p[(2 * i, 2 * j)] = cp[(i, j)];
                p[(2 * i, 2 * j + 1)] = 0.0;
                p[(2 * j + 1, 2 * i)] = 0.0;
            }
        }
        *p = (*p + p.transpose()) * 0.5;
    }
    Ok(track)
}

#[cfg(test)]
mod tests;
