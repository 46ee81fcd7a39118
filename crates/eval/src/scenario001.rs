//! Scenes and scoring for the seed 001 experiments (the multi-radar plot
//! fusion patent): the simulated radars' plots as the tracker takes them,
//! one tracker run recorded frame by frame, and the per-frame scoring of
//! its confirmed tracks against the truth.
//!
//! Scoring, used by every seed 001 tracker experiment: at each frame the
//! tracker processed (its own times: a serial tracker's scan groups, a
//! parallel tracker's fusion instants), the confirmed tracks are assigned
//! to the targets alive at that time by the optimal assignment of GOSPA
//! with p = 1, α = 2 and cut-off c (a pair is assigned only when closer
//! than c; [`algo::assignment::solve`] on the pairs within c, which
//! for p = 1 is the same optimum as [`crate::metrics::gospa`]'s dense
//! one — checked in the tests). From the assignment:
//! - position error and NEES (2 dof, horizontal position block of P) of
//!   every assigned pair;
//! - GOSPA = Σ d + (c/2)(missed + false);
//! - whenever a target is assigned a track id other than the one it was
//!   last assigned (a gap in between does not reset it): an **ID switch**
//!   when that earlier track is still reported (the target moved to another
//!   track, or two tracks exchanged targets), a **track break** when it is
//!   gone (deleted, and the target picked up by a new track);
//! - a **false track**: a confirmed track id assigned in fewer than half of
//!   the frames in which it was reported;
//! - **time to confirm** of a target: the first frame time at which a
//!   confirmed track is assigned to it, minus its birth.

use std::collections::HashMap;

use super::sensor::{Origin, Radar};
use super::truth::Trajectory;
use super::{SimError, SimRng};
use algo::assignment;
use algo::tracking::{Counters, Plot, RadarSpec, Tracker, TrackerConfig};

/// The service's radar description of a simulated 2D radar. The tracker's
/// clutter density λ (per m·rad) spreads the radar's expected false plots
/// per scan evenly over its polar coverage (range × azimuth extent), floored
/// at `min_clutter_density` (the tracker needs λ > 0 even without clutter).
pub fn radar_spec(r: &Radar, min_clutter_density: f64) -> RadarSpec {
    let false_per_scan = r.clutter_per_km2 * r.coverage_area_km2();
    let width = 2.0 * r.azimuth_fov.map_or(std::f64::consts::PI, |(_, w)| w);
    let lambda = false_per_scan / ((r.max_range - r.min_range) * width);
    RadarSpec {
        site: r.site,
        sigma_range: r.sigma_range,
        sigma_azimuth: r.sigma_azimuth,
        sigma_elevation: None,
        sigma_radial_velocity: r.doppler.then_some(r.sigma_doppler),
        scan_period: r.period,
        detection_probability: r.pd.max(1e-6),
        clutter_density: lambda.max(min_clutter_density),
    }
}

/// Every scan of every radar in `[0, end]` over the targets alive at the
/// scan time, as the tracker's plots (radar = index in `radars`) with their
/// origins, sorted by time and, at equal times, by radar.
pub fn scan_plots(
    radars: &[Radar],
    truth: &[Trajectory],
    end: f64,
    rng: &mut SimRng,
) -> Result<(Vec<Plot>, Vec<Origin>), SimError> {
    let mut plots = Vec::new();
    for (i, radar) in radars.iter().enumerate() {
        for t in radar.scan_times(0.0, end) {
            let states: Vec<_> = truth
                .iter()
                .enumerate()
                .filter_map(|(k, tr)| tr.state_at(t).map(|s| (k, s)))
                .collect();
            for p in radar.scan(t, &states, rng)? {
                plots.push((
                    Plot {
                        radar: i,
                        t,
                        range: p.range,
                        azimuth: p.azimuth,
                        elevation: p.elevation,
                        radial_velocity: p.radial_velocity,
                        identity: Default::default(),
                        report: None,
                    },
                    p.origin,
                ));
            }
        }
    }
    // Stable: radar order, then the radar's own (shuffled) order.
    plots.sort_by(|a, b| a.0.t.total_cmp(&b.0.t).then(a.0.radar.cmp(&b.0.radar)));
    Ok(plots.into_iter().unzip())
}

/// The plots of radar `index` alone, renumbered as radar 0 (for a tracker
/// given that radar only).
pub fn only_radar(plots: &[Plot], index: usize) -> Vec<Plot> {
    plots
        .iter()
        .filter(|p| p.radar == index)
        .map(|p| Plot { radar: 0, ..*p })
        .collect()
}

/// A confirmed track's horizontal position and its covariance block.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackPoint {
    pub id: u64,
    /// `[e, n]` (m).
    pub position: [f64; 2],
    /// `[[P_ee, P_en], [P_ne, P_nn]]` (m²).
    pub covariance: [[f64; 2]; 2],
}

/// The confirmed tracks after one processed frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Time of the frame (s).
    pub t: f64,
    pub tracks: Vec<TrackPoint>,
}

/// Runs a tracker on `plots` (all at once, flushed) and records the
/// confirmed tracks after every frame.
pub fn run_tracker(
    config: TrackerConfig,
    plots: &[Plot],
) -> Result<(Vec<Frame>, Counters), SimError> {
    let mut tracker = Tracker::new(config)?;
    let mut frames = Vec::new();
    tracker.process_with(plots, true, &mut |tr: &Tracker| {
        frames.push(frame_of(tr));
        std::ops::ControlFlow::Continue(())
    })?;
    Ok((frames, tracker.counters()))
}

/// A tracker's confirmed tracks at its last frame, horizontally.
pub fn frame_of(tr: &Tracker) -> Frame {
    Frame {
        t: tr.last_time().unwrap_or(f64::NAN),
        tracks: tr
            .confirmed_tracks()
            .iter()
            .map(|o| TrackPoint {
                id: o.id,
                position: [o.state[0], o.state[2]],
                covariance: [
                    [o.covariance[(0, 0)], o.covariance[(0, 2)]],
                    [o.covariance[(2, 0)], o.covariance[(2, 2)]],
                ],
            })
            .collect(),
    }
}

/// One assigned (target, track) pair of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    pub target: usize,
    pub track: u64,
    /// Squared horizontal position error (m²).
    pub error_sq: f64,
    /// e′P⁻¹e of the horizontal position (2 dof).
    pub nees: f64,
}

/// A frame scored against the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameScore {
    pub t: f64,
    pub pairs: Vec<Pair>,
    /// Targets alive at `t`.
    pub targets: usize,
    /// Ids of the confirmed tracks at `t` assigned to no target.
    pub unassigned: Vec<u64>,
    /// How many of them lie within the cut-off of a target (which is then
    /// held by another track): duplicates rather than tracks of nothing.
    pub duplicates: usize,
    /// GOSPA (p = 1, α = 2, the scoring cut-off) (m).
    pub gospa: f64,
}

/// Horizontal truth position of target `k` at `t`, `None` before its birth.
pub fn truth_position(truth: &[Trajectory], k: usize, t: f64) -> Option<[f64; 2]> {
    truth[k].state_at(t).map(|s| [s[0], s[2]])
}

/// Scores every frame (see the module header) with cut-off `cutoff` (m).
pub fn score_frames(
    frames: &[Frame],
    truth: &[Trajectory],
    cutoff: f64,
) -> Result<Vec<FrameScore>, SimError> {
    frames
        .iter()
        .map(|f| {
            let alive: Vec<(usize, [f64; 2])> = (0..truth.len())
                .filter_map(|k| truth_position(truth, k, f.t).map(|p| (k, p)))
                .collect();
            let mut edges = Vec::new();
            for (i, (_, x)) in alive.iter().enumerate() {
                for (j, tr) in f.tracks.iter().enumerate() {
                    let d = (tr.position[0] - x[0]).hypot(tr.position[1] - x[1]);
                    if d < cutoff {
                        edges.push((i, j, d));
                    }
                }
            }
            let chosen = assignment::solve(&edges, cutoff);
            let mut used = vec![false; f.tracks.len()];
            let mut pairs = Vec::with_capacity(chosen.len());
            let mut localisation = 0.0;
            for (i, j) in chosen {
                let (k, x) = alive[i];
                let tr = &f.tracks[j];
                used[j] = true;
                let e = [tr.position[0] - x[0], tr.position[1] - x[1]];
                localisation += e[0].hypot(e[1]);
                pairs.push(Pair {
                    target: k,
                    track: tr.id,
                    error_sq: e[0] * e[0] + e[1] * e[1],
                    nees: nees_2d(&e, &tr.covariance)?,
                });
            }
            let unassigned = alive.len() + f.tracks.len() - 2 * pairs.len();
            let near_target = |j: usize| edges.iter().any(|e| e.1 == j);
            let duplicates = (0..f.tracks.len())
                .filter(|&j| !used[j] && near_target(j))
                .count();
            Ok(FrameScore {
                t: f.t,
                targets: alive.len(),
                unassigned: f
                    .tracks
                    .iter()
                    .zip(used)
                    .filter(|(_, u)| !u)
                    .map(|(tr, _)| tr.id)
                    .collect(),
                duplicates,
                gospa: localisation + cutoff / 2.0 * unassigned as f64,
                pairs,
            })
        })
        .collect()
}

/// e′P⁻¹e for a 2×2 covariance (closed form).
fn nees_2d(e: &[f64; 2], p: &[[f64; 2]; 2]) -> Result<f64, SimError> {
    let (a, b, c) = (p[0][0], 0.5 * (p[0][1] + p[1][0]), p[1][1]);
    let det = a * c - b * b;
    if !(a > 0.0 && det > 0.0) {
        return Err(SimError::InvalidConfig(format!(
            "track covariance not positive definite: {p:?}"
        )));
    }
    Ok((c * e[0] * e[0] - 2.0 * b * e[0] * e[1] + a * e[1] * e[1]) / det)
}

/// What one tracker run scored, summed over its frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Σ squared position errors and their number (assigned pairs).
    pub error_sq: f64,
    pub samples: usize,
    /// Σ NEES (2 dof) of the same pairs.
    pub nees: f64,
    /// Pairs whose NEES exceeds χ²₂(0.99) = 9.21 (1 % if consistent).
    pub nees_over_99: usize,
    /// Σ GOSPA over frames, and the number of frames.
    pub gospa: f64,
    pub frames: usize,
    /// Σ over frames of unassigned targets, of unassigned tracks, and of
    /// the unassigned tracks that are duplicates (see [`FrameScore`]).
    pub missed: usize,
    pub unassigned_tracks: usize,
    pub duplicates: usize,
    /// ID switches and track breaks (see the module header).
    pub switches: usize,
    pub breaks: usize,
    /// Distinct confirmed track ids, and how many of them were false.
    pub confirmed_tracks: usize,
    pub false_tracks: usize,
    /// Per target: time from birth to its first confirmed track, `None`
    /// when it never got one.
    pub confirm_delay: Vec<Option<f64>>,
}

/// χ²₂ 99 % quantile, −2 ln 0.01.
pub const CHI2_2_99: f64 = 9.210_340_371_976_184;

/// Sums the scores of one run (`truth`: its targets).
pub fn summarise(scores: &[FrameScore], truth: &[Trajectory]) -> Summary {
    let mut s = Summary {
        confirm_delay: vec![None; truth.len()],
        ..Summary::default()
    };
    let mut last: Vec<Option<u64>> = vec![None; truth.len()];
    // Per track id: (frames reported, frames assigned).
    let mut life: HashMap<u64, (usize, usize)> = HashMap::new();
    for f in scores {
        s.frames += 1;
        s.gospa += f.gospa;
        s.missed += f.targets - f.pairs.len();
        s.unassigned_tracks += f.unassigned.len();
        s.duplicates += f.duplicates;
        for &id in &f.unassigned {
            life.entry(id).or_default().0 += 1;
        }
        let reported =
            |id: u64| f.pairs.iter().any(|p| p.track == id) || f.unassigned.contains(&id);
        for p in &f.pairs {
            s.error_sq += p.error_sq;
            s.samples += 1;
            s.nees += p.nees;
            if p.nees > CHI2_2_99 {
                s.nees_over_99 += 1;
            }
            match last[p.target] {
                Some(id) if id != p.track && reported(id) => s.switches += 1,
                Some(id) if id != p.track => s.breaks += 1,
                _ => {}
            }
            last[p.target] = Some(p.track);
            if s.confirm_delay[p.target].is_none() {
                s.confirm_delay[p.target] = Some(f.t - truth[p.target].birth);
            }
            let l = life.entry(p.track).or_default();
            l.0 += 1;
            l.1 += 1;
        }
    }
    s.confirmed_tracks = life.len();
    s.false_tracks = life
        .values()
        .filter(|(reported, assigned)| 2 * assigned < *reported)
        .count();
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::gospa;
    use crate::montecarlo::run_rng;
    use crate::truth::{TargetPlan, simulate};
    use rand::RngExt;
    use std::f64::consts::TAU;

    fn still(points: &[[f64; 2]]) -> Vec<Trajectory> {
        let mut rng = run_rng(0, 0);
        points
            .iter()
            .map(|p| {
                let plan = TargetPlan::constant_velocity(0.0, [p[0], 0.0, p[1], 0.0, 0.0, 0.0]);
                simulate(&plan, 1.0, 10.0, &mut rng).unwrap()
            })
            .collect()
    }

    fn track(id: u64, x: f64, y: f64, var: f64) -> TrackPoint {
        TrackPoint {
            id,
            position: [x, y],
            covariance: [[var, 0.0], [0.0, var]],
        }
    }

    #[test]
    fn sparse_gospa_equals_the_dense_metric() {
        // Random sets within a few cut-offs of each other: same distance as
        // metrics::gospa with p = 1 (its dense assignment).
        let mut rng = run_rng(5, 0);
        for _ in 0..50 {
            let nx = rng.random_range(0..7);
            let ny = rng.random_range(0..7);
            let pts: Vec<[f64; 2]> = (0..nx)
                .map(|_| [rng.random_range(0.0..3000.0), rng.random_range(0.0..3000.0)])
                .collect();
            let tracks: Vec<TrackPoint> = (0..ny)
                .map(|j| {
                    let x = rng.random_range(0.0..3000.0);
                    track(j as u64, x, rng.random_range(0.0..3000.0), 1e4)
                })
                .collect();
            let truth = still(&pts);
            let frame = Frame { t: 3.0, tracks };
            let s = &score_frames(std::slice::from_ref(&frame), &truth, 1000.0).unwrap()[0];
            let x: Vec<Vec<f64>> = pts.iter().map(|p| p.to_vec()).collect();
            let y: Vec<Vec<f64>> = frame.tracks.iter().map(|t| t.position.to_vec()).collect();
            let g = gospa(&x, &y, 1000.0, 1.0);
            assert!(
                (s.gospa - g.distance).abs() < 1e-6,
                "{} {}",
                s.gospa,
                g.distance
            );
            assert_eq!(s.targets - s.pairs.len(), g.missed);
            assert_eq!(s.unassigned.len(), g.false_tracks);
        }
    }

    #[test]
    fn nees_switches_false_tracks_and_confirmation_by_hand() {
        // Targets at (0, 0) and (10 km, 0).
        let truth = still(&[[0.0, 0.0], [10_000.0, 0.0]]);
        let frames = vec![
            // t = 1: track 1 on target 0, 30 m east, P = 100 I → NEES 9.
            Frame {
                t: 1.0,
                tracks: vec![track(1, 30.0, 0.0, 100.0)],
            },
            // t = 2: track 2 takes target 0 (a switch), track 1 far from all
            // (unassigned), track 3 on target 1.
            Frame {
                t: 2.0,
                tracks: vec![
                    track(1, 5000.0, 0.0, 100.0),
                    track(2, 0.0, 40.0, 100.0),
                    track(3, 10_000.0, 0.0, 100.0),
                ],
            },
            // t = 3: track 1 reported once more, unassigned again.
            Frame {
                t: 3.0,
                tracks: vec![track(1, 5000.0, 0.0, 100.0), track(2, 0.0, 0.0, 100.0)],
            },
            // t = 4: track 3 is gone and track 4 holds target 1: a break.
            Frame {
                t: 4.0,
                tracks: vec![track(2, 0.0, 0.0, 100.0), track(4, 10_000.0, 0.0, 100.0)],
            },
        ];
        let scores = score_frames(&frames, &truth, 1000.0).unwrap();
        assert!((scores[0].pairs[0].nees - 9.0).abs() < 1e-12);
        assert_eq!(scores[0].pairs[0].error_sq, 900.0);
        // Frame 1: target 1 missed: GOSPA = 30 + 500.
        assert!((scores[0].gospa - 530.0).abs() < 1e-9);
        let s = summarise(&scores, &truth);
        // Target 0 moves from track 1 (still reported) to track 2: a switch.
        assert_eq!((s.switches, s.breaks), (1, 1));
        assert_eq!(s.confirmed_tracks, 4);
        // Track 1: 3 frames reported, 1 assigned → false.
        assert_eq!(s.false_tracks, 1);
        assert_eq!(s.confirm_delay, vec![Some(1.0), Some(2.0)]);
        // Target 1 is missed at t = 1 and t = 3.
        assert_eq!((s.samples, s.missed, s.unassigned_tracks), (6, 2, 2));
        // Track 1 at 5 km is 5 km from both targets: not a duplicate.
        assert_eq!(s.duplicates, 0);
        let twin = Frame {
            t: 1.0,
            tracks: vec![track(7, 10.0, 0.0, 100.0), track(8, 0.0, 500.0, 100.0)],
        };
        let d = score_frames(&[twin], &truth, 1000.0).unwrap();
        assert_eq!((d[0].pairs[0].track, d[0].duplicates), (7, 1));
        // A correlated covariance: e = (1, 1), P = [[2, 1], [1, 2]] → e'P⁻¹e = 2/3.
        let v = nees_2d(&[1.0, 1.0], &[[2.0, 1.0], [1.0, 2.0]]).unwrap();
        assert!((v - 2.0 / 3.0).abs() < 1e-12);
        assert!(nees_2d(&[1.0, 1.0], &[[1.0, 1.0], [1.0, 1.0]]).is_err());
    }

    #[test]
    fn radar_spec_spreads_the_clutter_over_the_polar_coverage() {
        let mut r = Radar::two_d([1.0, 2.0, 0.0], 50.0, 0.002, 5.0);
        r.max_range = 101_000.0;
        r.clutter_per_km2 = 3.0 / r.coverage_area_km2();
        r.doppler = true;
        r.sigma_doppler = 1.5;
        let s = radar_spec(&r, 1e-9);
        // 3 false plots over (101 − 1) km × 2π rad.
        assert!((s.clutter_density - 3.0 / (100_000.0 * TAU)).abs() < 1e-15);
        assert_eq!(s.sigma_radial_velocity, Some(1.5));
        assert_eq!((s.site, s.scan_period), ([1.0, 2.0, 0.0], 5.0));
        r.clutter_per_km2 = 0.0;
        assert_eq!(radar_spec(&r, 1e-9).clutter_density, 1e-9);
    }

    #[test]
    fn plots_are_sorted_and_single_radar_plots_renumbered() {
        let truth = still(&[[30_000.0, 40_000.0]]);
        let mut a = Radar::two_d([0.0; 3], 10.0, 1e-3, 2.0);
        a.phase = 0.5;
        let b = Radar::two_d([1000.0, 0.0, 0.0], 10.0, 1e-3, 3.0);
        let mut rng = run_rng(1, 0);
        let (plots, origins) = scan_plots(&[a, b], &truth, 10.0, &mut rng).unwrap();
        // a at 0.5, 2.5, …, 8.5 (5 scans), b at 0, 3, 6, 9 (4 scans).
        assert_eq!(plots.len(), 9);
        assert!(origins.iter().all(|o| *o == Origin::Target(0)));
        assert!(plots.windows(2).all(|w| w[0].t <= w[1].t));
        assert_eq!((plots[0].t, plots[0].radar), (0.0, 1));
        assert!((plots[0].range - 29_000f64.hypot(40_000.0)).abs() < 100.0);
        let only = only_radar(&plots, 1);
        assert_eq!(only.len(), 4);
        assert!(only.iter().all(|p| p.radar == 0));
    }
}
