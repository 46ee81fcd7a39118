//! The two-node scene of seed 000 §5.1 and the harness that scores a
//! track-to-track correlator on it.
//!
//! Two nodes, each a 2D radar with its own local Kalman filters
//! ([`super::tracker::LocalKalman`]); targets start normal in a common
//! region with speeds uniform in 4–1200 m/s and headings uniform in
//! [0, 2π), and manoeuvre by the eq. 26 process noise; both radars scan
//! every T = 4 s at the same instants, so the nodes' estimates are
//! synchronous as the paper's tests assume. The paper gives neither the
//! sites nor the region; [`Seed000Scene::paper`] places the radars 100 km
//! apart on an east–west baseline and the region 80 km north of its
//! midpoint (docs/RESULTS.md states the choice).
//!
//! Local track ids are a random permutation per node, so a correlator
//! cannot match ids; the truth (`track_target`) stays with the harness.
//! Plugging in a correlator is: implement [`Correlator`] (fed scan by scan)
//! or write a causal batch function over the whole [`TwoNodeRun`], wrap it
//! in a [`Method`] with the matching [`Driver`], and hand it to
//! [`score_correlators`], which scores each scan's pairs with
//! [`super::metrics::score_correlation`].

use std::collections::HashMap;

use rand::seq::SliceRandom;

use super::metrics::{CorrelationCounts, score_correlation};
use super::sensor::{Origin, Plot, Radar};
use super::tracker::{LocalKalman, TrackEstimate};
use super::truth::{InitialConditions, TargetPlan, Trajectory, simulate};
use super::{SimError, SimRng};

/// Parameters of the seed 000 scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed000Scene {
    /// Number of targets (60 or 120 in the paper).
    pub targets: usize,
    /// Number of scans, the first at t = 0; tracks exist from scan 1 on.
    pub scans: usize,
    /// Scan period T (s).
    pub period: f64,
    /// Centre of the common region `[east, north]` (m).
    pub region_centre: [f64; 2],
    /// Standard deviation of the initial positions per axis (m).
    pub region_sigma: f64,
    /// Speed range (m/s).
    pub speed: (f64, f64),
    /// Process-noise factor of eq. 26 (0.05).
    pub noise_factor: f64,
    /// The two radars (sites, σρ, σθ, period).
    pub radars: [Radar; 2],
    /// Keep the Kalman gains in the local estimates (for the modified test).
    pub keep_gains: bool,
}

impl Seed000Scene {
    /// The paper's scene with `targets` targets: σρ = 170 m / 180 m, σθ = 1°,
    /// T = 4 s, speeds 4–1200 m/s, eq. 26 factor 0.05; our geometry: radars
    /// at (−50 km, 0) and (+50 km, 0), targets normal about (0, 80 km) with
    /// σ = 10 km per axis, 40 scans (160 s).
    pub fn paper(targets: usize) -> Self {
        let t = 4.0;
        let deg = 1f64.to_radians();
        Self {
            targets,
            scans: 40,
            period: t,
            region_centre: [0.0, 80_000.0],
            region_sigma: 10_000.0,
            speed: (4.0, 1200.0),
            noise_factor: 0.05,
            radars: [
                Radar::two_d([-50_000.0, 0.0, 0.0], 170.0, deg, t),
                Radar::two_d([50_000.0, 0.0, 0.0], 180.0, deg, t),
            ],
            keep_gains: false,
        }
    }

    /// Scan times `l·T`, l = 0 … scans − 1.
    pub fn times(&self) -> Vec<f64> {
        (0..self.scans).map(|l| l as f64 * self.period).collect()
    }
}

/// A local track as a node sends it to the fusion centre.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalTrack {
    /// The node's track number (a random permutation of 0..targets).
    pub id: u32,
    /// Estimate, covariance (and gain when kept).
    pub estimate: TrackEstimate,
}

/// One simulated run of the scene.
#[derive(Debug, Clone)]
pub struct TwoNodeRun {
    /// Scan times.
    pub times: Vec<f64>,
    /// Ground truth per target, sampled at the scan times.
    pub truth: Vec<Trajectory>,
    /// `nodes[n][l]`: node n's tracks at scan l (empty at l = 0).
    pub nodes: [Vec<Vec<LocalTrack>>; 2],
    /// `track_target[n][id]`: the target of node n's track `id`.
    pub track_target: [Vec<usize>; 2],
    /// `plots[n][l][k]`: node n's plot of target k at scan l (`None` if the
    /// target was at the site).
    pub plots: [Vec<Vec<Option<Plot>>>; 2],
}

impl TwoNodeRun {
    /// The truth of node `n`'s tracks present at scan `l`: id → target.
    pub fn truth_at(&self, n: usize, l: usize) -> HashMap<u32, usize> {
        self.nodes[n][l]
            .iter()
            .map(|tr| (tr.id, self.track_target[n][tr.id as usize]))
            .collect()
    }
}

/// Simulates one run: truth, plots of both radars, local filters.
pub fn generate(scene: &Seed000Scene, rng: &mut SimRng) -> Result<TwoNodeRun, SimError> {
    if scene.targets == 0 || scene.scans < 2 {
        return Err(SimError::InvalidConfig(
            "seed 000 scene needs at least 1 target and 2 scans".into(),
        ));
    }
    for r in &scene.radars {
        r.validate()?;
    }
    let times = scene.times();
    let end = *times.last().expect("scans >= 2");
    let ic = InitialConditions {
        speed: scene.speed,
        ..InitialConditions::seed000(scene.region_centre, scene.region_sigma)
    };
    let mut truth = Vec::with_capacity(scene.targets);
    for _ in 0..scene.targets {
        let plan = TargetPlan {
            noise_factor: scene.noise_factor,
            ..TargetPlan::constant_velocity(0.0, ic.sample(rng)?)
        };
        truth.push(simulate(&plan, scene.period, end, rng)?);
    }
    let mut nodes: [Vec<Vec<LocalTrack>>; 2] = [Vec::new(), Vec::new()];
    let mut track_target: [Vec<usize>; 2] = [Vec::new(), Vec::new()];
    let mut plots: [Vec<Vec<Option<Plot>>>; 2] = [Vec::new(), Vec::new()];
    for (n, radar) in scene.radars.iter().enumerate() {
        // ids[k] = track id of target k; track_target is its inverse.
        let mut ids: Vec<u32> = (0..scene.targets as u32).collect();
        ids.shuffle(rng);
        let mut inverse = vec![0usize; scene.targets];
        for (k, &id) in ids.iter().enumerate() {
            inverse[id as usize] = k;
        }
        track_target[n] = inverse;
        let mut filters = (0..scene.targets)
            .map(|_| LocalKalman::new(radar, scene.noise_factor, scene.keep_gains))
            .collect::<Result<Vec<_>, _>>()?;
        for (l, &t) in times.iter().enumerate() {
            let mut tracks = Vec::with_capacity(scene.targets);
            let mut scan_plots = Vec::with_capacity(scene.targets);
            for (k, kf) in filters.iter_mut().enumerate() {
                let s = truth[k].states[l];
                // Outside the coverage (inside the blind range, or beyond
                // the instrumented range) there is no plot; the filter coasts.
                let plot = if radar.covers([s[0], s[2], s[4]]) {
                    radar.measure(t, &s, Origin::Target(k), rng)?
                } else {
                    None
                };
                scan_plots.push(plot);
                let est = match plot {
                    Some(plot) => kf.process(&plot)?.cloned(),
                    None => kf.coast(t)?.cloned(),
                };
                if let Some(estimate) = est {
                    tracks.push(LocalTrack {
                        id: ids[k],
                        estimate,
                    });
                }
            }
            tracks.sort_by_key(|tr| tr.id);
            nodes[n].push(tracks);
            plots[n].push(scan_plots);
        }
    }
    Ok(TwoNodeRun {
        times,
        truth,
        nodes,
        track_target,
        plots,
    })
}

/// A track-to-track correlation method under test. One instance serves one
/// run: it is called once per scan, in time order, with both nodes' local
/// tracks at time `t`, and may keep state between scans (hit counts of the
/// double-threshold rules, decided pairs, cross-covariances).
pub trait Correlator {
    /// The pairs `(node-1 track id, node-2 track id)` the method outputs at
    /// this scan (confirmed pairs and trial system tracks alike: every pair
    /// it would fuse into a system track now).
    fn correlate(
        &mut self,
        t: f64,
        node1: &[LocalTrack],
        node2: &[LocalTrack],
    ) -> Result<Vec<(u32, u32)>, SimError>;
}

/// Builds a fresh per-scan correlator for one run of the scene.
pub type CorrelatorFactory<'a> = &'a (dyn Fn(&Seed000Scene) -> Box<dyn Correlator> + Sync);

/// A causal batch method: given the whole run, returns `out[l]`, the pairs
/// output at scan `l`, which must depend on scans ≤ `l` only (for example
/// an engine over all instants stepped once per instant, its decisions read
/// after every step).
pub type CausalBatch<'a> =
    &'a (dyn Fn(&Seed000Scene, &TwoNodeRun) -> Result<Vec<Vec<(u32, u32)>>, SimError> + Sync);

/// How a method under test is driven.
#[derive(Clone, Copy)]
pub enum Driver<'a> {
    /// Fed scan by scan through [`Correlator`].
    PerScan(CorrelatorFactory<'a>),
    /// Given the whole run at once (see [`CausalBatch`]).
    Batch(CausalBatch<'a>),
}

/// A named method under test.
#[derive(Clone, Copy)]
pub struct Method<'a> {
    /// Name in tables and legends.
    pub name: &'a str,
    /// How to run it.
    pub driver: Driver<'a>,
}

/// Runs `correlator` over every scan of `run` and scores each scan's output;
/// entry `l` is scan `l` (scan 0, before any track exists, scores nothing).
pub fn score_run(
    run: &TwoNodeRun,
    correlator: &mut dyn Correlator,
) -> Result<Vec<CorrelationCounts>, SimError> {
    let mut outputs = Vec::with_capacity(run.times.len());
    for (l, &t) in run.times.iter().enumerate() {
        outputs.push(correlator.correlate(t, &run.nodes[0][l], &run.nodes[1][l])?);
    }
    score_outputs(run, &outputs)
}

/// Scores per-scan outputs: `outputs[l]` are the pairs declared at scan `l`.
pub fn score_outputs(
    run: &TwoNodeRun,
    outputs: &[Vec<(u32, u32)>],
) -> Result<Vec<CorrelationCounts>, SimError> {
    if outputs.len() != run.times.len() {
        return Err(SimError::InvalidConfig(format!(
            "a method returned {} scans of pairs for a run of {} scans",
            outputs.len(),
            run.times.len()
        )));
    }
    Ok(outputs
        .iter()
        .enumerate()
        .map(|(l, pairs)| score_correlation(&run.truth_at(0, l), &run.truth_at(1, l), pairs))
        .collect())
}

/// Scores every method on the same simulated run: `result[m][l]`.
pub fn score_correlators(
    scene: &Seed000Scene,
    methods: &[Method<'_>],
    rng: &mut SimRng,
) -> Result<Vec<Vec<CorrelationCounts>>, SimError> {
    let run = generate(scene, rng)?;
    methods
        .iter()
        .map(|m| match m.driver {
            Driver::PerScan(build) => score_run(&run, build(scene).as_mut()),
            Driver::Batch(f) => score_outputs(&run, &f(scene, &run)?),
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::montecarlo::run_rng;

    /// Pairs by the truth: the best a correlator can do.
    pub(crate) struct Oracle {
        pub(crate) truth: [HashMap<u32, usize>; 2],
    }

    fn small() -> Seed000Scene {
        Seed000Scene {
            scans: 6,
            ..Seed000Scene::paper(5)
        }
    }

    #[test]
    fn run_has_tracks_from_the_second_scan_and_a_consistent_truth() {
        let scene = small();
        let run = generate(&scene, &mut run_rng(18, 0)).unwrap();
        assert_eq!(run.times, vec![0.0, 4.0, 8.0, 12.0, 16.0, 20.0]);
        for n in 0..2 {
            assert!(run.nodes[n][0].is_empty());
            for l in 1..6 {
                assert_eq!(run.nodes[n][l].len(), 5);
                for tr in &run.nodes[n][l] {
                    assert_eq!(tr.estimate.t, run.times[l]);
                    // The track follows its target within 20 km.
                    let k = run.track_target[n][tr.id as usize];
                    let s = run.truth[k].states[l];
                    let d = (tr.estimate.x[0] - s[0]).hypot(tr.estimate.x[2] - s[2]);
                    assert!(d < 20_000.0, "track {} of node {n} is {d} m off", tr.id);
                }
            }
            let mut seen = run.track_target[n].clone();
            seen.sort();
            assert_eq!(seen, (0..5).collect::<Vec<_>>());
        }
    }

    #[test]
    fn same_seed_same_run() {
        let scene = small();
        let a = generate(&scene, &mut run_rng(18, 3)).unwrap();
        let b = generate(&scene, &mut run_rng(18, 3)).unwrap();
        assert_eq!(a.track_target, b.track_target);
        assert_eq!(a.nodes, b.nodes);
    }

    impl Correlator for Oracle {
        fn correlate(
            &mut self,
            _t: f64,
            n1: &[LocalTrack],
            n2: &[LocalTrack],
        ) -> Result<Vec<(u32, u32)>, SimError> {
            let by_target: HashMap<usize, u32> =
                n2.iter().map(|tr| (self.truth[1][&tr.id], tr.id)).collect();
            Ok(n1
                .iter()
                .filter_map(|tr| by_target.get(&self.truth[0][&tr.id]).map(|&b| (tr.id, b)))
                .collect())
        }
    }

    #[test]
    fn harness_scores_oracle_silent_and_shifted_correlators() {
        let scene = small();
        let run = generate(&scene, &mut run_rng(1, 0)).unwrap();
        let truth = [run.truth_at(0, 1), run.truth_at(1, 1)];
        let mut oracle = Oracle {
            truth: truth.clone(),
        };
        let c = score_run(&run, &mut oracle).unwrap();
        assert_eq!(c[0].pairs(), 0);
        for counts in &c[1..] {
            assert_eq!((counts.correct, counts.pairs()), (5, 5));
        }

        struct Silent;
        impl Correlator for Silent {
            fn correlate(
                &mut self,
                _: f64,
                _: &[LocalTrack],
                _: &[LocalTrack],
            ) -> Result<Vec<(u32, u32)>, SimError> {
                Ok(Vec::new())
            }
        }
        let c = score_run(&run, &mut Silent).unwrap();
        assert!(c[1..].iter().all(|x| x.missed == 5));

        // Every node-1 track paired with the node-2 track of the *next*
        // target: all five true pairs are errors.
        struct Shifted([HashMap<u32, usize>; 2]);
        impl Correlator for Shifted {
            fn correlate(
                &mut self,
                _: f64,
                n1: &[LocalTrack],
                n2: &[LocalTrack],
            ) -> Result<Vec<(u32, u32)>, SimError> {
                let by_target: HashMap<usize, u32> =
                    n2.iter().map(|tr| (self.0[1][&tr.id], tr.id)).collect();
                let k = by_target.len();
                Ok(n1
                    .iter()
                    .map(|tr| (tr.id, by_target[&((self.0[0][&tr.id] + 1) % k)]))
                    .collect())
            }
        }
        let c = score_run(&run, &mut Shifted(truth)).unwrap();
        assert!(c[1..].iter().all(|x| x.error == 5 && x.error_rate() == 1.0));
    }
}
