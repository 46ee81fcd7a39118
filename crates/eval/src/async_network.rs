//! Unsynchronised radar networks for the track-to-track correlation
//! endpoint: radars with their own scan periods and phases, each running
//! local Kalman filters ([`super::tracker::LocalKalman`]) on its plots, with
//! missed detections (the filter coasts), lost reports on the data link and
//! one node outage, sent to the fusion centre as a correlation request.
//! [`score`] compares the endpoint's final decisions with the truth.
//!
//! Targets are aircraft well apart (a sparse scene): normal about a point
//! 80 km north of the network with σ = 25 km per axis, 100–300 m/s, with
//! gentle eq. 26 process noise ([`TRUTH_NOISE`]). The truth is sampled every second and every
//! scan time of the cases is a whole second.

use rand::{RngExt, seq::SliceRandom};

use super::{
    SimError, SimRng,
    sensor::{Origin, Radar},
    tracker::LocalKalman,
    truth::{InitialConditions, TargetPlan, Trajectory, simulate},
};
use algo::correlation::engine::Decision;
use service::{
    Rows,
    correlation::{
        AlignmentInput, CorrelateInput, CorrelateOutput, MethodInput, MotionModelInput, NodeInput,
        SampleInput, TrackInput,
    },
};

/// Truth step (s): every scan time is a multiple.
const STEP: f64 = 1.0;
/// Eq. 26 noise factor of the truth: 0.01 (σ_a ≈ 2 m/s² at 200 m/s, an
/// airliner's gentle manoeuvres). The paper's 0.05 random-walks speeds from
/// 300 to 1000 m/s within five minutes; the local filters and the
/// request's motion model keep the paper's 0.05.
const TRUTH_NOISE: f64 = 0.01;

/// One network: its radars and the scene.
#[derive(Debug, Clone)]
pub struct Network {
    pub name: &'static str,
    /// Radars with their periods and phases.
    pub radars: Vec<Radar>,
    pub targets: usize,
    /// Duration (s) from t = 0.
    pub duration: f64,
    /// Probability that a track report is lost on the way.
    pub report_loss: f64,
    /// One node silent over an interval: (node, from, to).
    pub outage: Option<(usize, f64, f64)>,
}

/// The networks of the issue: 4 s / 4 s offset 2 s; 4 s / 5 s; 10 s / 12 s
/// offset 3 s; three radars (4 s, 5 s offset 1 s, 10 s offset 7 s). Each has
/// P_D = 0.9, 3 % lost reports and node 1 silent for 20 s.
pub fn cases() -> Vec<Network> {
    let deg = 1f64.to_radians();
    let radar = |x: f64, y: f64, period: f64, phase: f64| {
        let mut r = Radar::two_d([x, y, 0.0], 150.0, 0.2 * deg, period);
        r.phase = phase;
        r.pd = 0.9;
        r.max_range = 400_000.0;
        r
    };
    let two = |name, a: (f64, f64), b: (f64, f64)| Network {
        name,
        radars: vec![
            radar(-50_000.0, 0.0, a.0, a.1),
            radar(50_000.0, 0.0, b.0, b.1),
        ],
        targets: 20,
        duration: 300.0,
        report_loss: 0.03,
        outage: Some((1, 100.0, 120.0)),
    };
    vec![
        two("4 s / 4 s, offset 2 s", (4.0, 0.0), (4.0, 2.0)),
        two("4 s / 5 s", (4.0, 0.0), (5.0, 0.0)),
        two("10 s / 12 s, offset 3 s", (10.0, 0.0), (12.0, 3.0)),
        Network {
            name: "three radars: 4 s, 5 s offset 1 s, 10 s offset 7 s",
            radars: vec![
                radar(-50_000.0, 0.0, 4.0, 0.0),
                radar(50_000.0, 0.0, 5.0, 1.0),
                radar(0.0, 160_000.0, 10.0, 7.0),
            ],
            targets: 20,
            duration: 300.0,
            report_loss: 0.03,
            outage: Some((1, 100.0, 120.0)),
        },
    ]
}

/// A generated run: the request (alignment and method left to the caller)
/// and, per node, the target of each track (`truth[node][track index]`).
#[derive(Debug, Clone)]
pub struct NetworkRun {
    pub request: CorrelateInput,
    pub truth: Vec<Vec<usize>>,
}

/// Simulates one run of `net`.
pub fn generate(net: &Network, rng: &mut SimRng) -> Result<NetworkRun, SimError> {
    let ic = InitialConditions {
        speed: (100.0, 300.0),
        ..InitialConditions::seed000([0.0, 80_000.0], 25_000.0)
    };
    let truth: Vec<Trajectory> = (0..net.targets)
        .map(|_| {
            let plan = TargetPlan {
                noise_factor: TRUTH_NOISE,
                ..TargetPlan::constant_velocity(0.0, ic.sample(rng)?)
            };
            simulate(&plan, STEP, net.duration, rng)
        })
        .collect::<Result<_, _>>()?;
    let mut nodes = Vec::new();
    let mut node_truth = Vec::new();
    for (n, radar) in net.radars.iter().enumerate() {
        radar.validate()?;
        let mut ids: Vec<usize> = (0..net.targets).collect();
        ids.shuffle(rng);
        let mut tracks: Vec<(usize, TrackInput)> = Vec::new();
        for (k, target) in truth.iter().enumerate() {
            let mut kf = LocalKalman::new(radar, 0.05, false)?;
            let mut samples = Vec::new();
            for t in radar.scan_times(0.0, net.duration) {
                let s = target.states[(t / STEP).round() as usize];
                let detected = rng.random::<f64>() < radar.pd;
                let plot = if detected && radar.covers([s[0], s[2], s[4]]) {
                    radar.measure(t, &s, Origin::Target(k), rng)?
                } else {
                    None
                };
                let est = match plot {
                    Some(p) => kf.process(&p)?.cloned(),
                    None => kf.coast(t)?.cloned(),
                };
                let silent = net
                    .outage
                    .is_some_and(|(node, a, b)| node == n && (a..=b).contains(&t));
                let lost = rng.random::<f64>() < net.report_loss;
                if let Some(e) = est.filter(|_| !silent && !lost) {
                    samples.push(SampleInput {
                        t: Some(t),
                        state: e.x.as_slice().to_vec(),
                        covariance: Rows::from_matrix(&e.p),
                        gain: None,
                    });
                }
            }
            if !samples.is_empty() {
                tracks.push((
                    ids[k],
                    TrackInput {
                        id: Some(format!("T{:03}", ids[k])),
                        samples,
                    },
                ));
            }
        }
        // Tracks in the node's id order, so that order tells nothing.
        let order: Vec<usize> = {
            let mut idx: Vec<usize> = (0..tracks.len()).collect();
            idx.sort_by_key(|&i| tracks[i].0);
            idx
        };
        node_truth.push(
            order
                .iter()
                .map(|&i| ids.iter().position(|&id| id == tracks[i].0).expect("an id"))
                .collect(),
        );
        let mut slots: Vec<Option<TrackInput>> = tracks.into_iter().map(|(_, t)| Some(t)).collect();
        nodes.push(NodeInput {
            id: Some(format!("radar-{}", n + 1)),
            tracks: order
                .iter()
                .map(|&i| slots[i].take().expect("once"))
                .collect(),
        });
    }
    Ok(NetworkRun {
        request: CorrelateInput {
            state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
            method: Some(MethodInput {
                kind: Some("independent_double_threshold".into()),
                ..Default::default()
            }),
            motion_model: Some(MotionModelInput {
                process_noise: Some("velocity_proportional".into()),
                factor: Some(0.05),
                ..Default::default()
            }),
            nodes,
            ..Default::default()
        },
        truth: node_truth,
    })
}

/// The previous default alignment (clusters of 0.5 s, predicted), for
/// comparison.
pub fn old_default() -> AlignmentInput {
    AlignmentInput {
        mode: Some("predict".into()),
        tolerance_s: Some(0.5),
        ..Default::default()
    }
}

/// Final decisions against the truth, over every node pair.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Score {
    /// Same-target track pairs (both nodes have a track of the target).
    pub true_pairs: usize,
    pub correct: usize,
    /// Correlated pairs of different targets.
    pub wrong: usize,
    pub missed: usize,
}

impl Score {
    pub fn add(&mut self, o: Score) {
        self.true_pairs += o.true_pairs;
        self.correct += o.correct;
        self.wrong += o.wrong;
        self.missed += o.missed;
    }

    /// Correct over true pairs.
    pub fn rate(&self) -> f64 {
        self.correct as f64 / self.true_pairs.max(1) as f64
    }
}

/// Scores the correlated pairs of `out` against `run`'s truth.
pub fn score(run: &NetworkRun, out: &CorrelateOutput) -> Score {
    let index = |node: &str, track: &str| -> (usize, usize) {
        let n = run
            .request
            .nodes
            .iter()
            .position(|x| x.id.as_deref() == Some(node))
            .expect("a node of the request");
        let t = run.request.nodes[n]
            .tracks
            .iter()
            .position(|x| x.id.as_deref() == Some(track))
            .expect("a track of the node");
        (n, t)
    };
    let mut s = Score::default();
    let nodes = run.truth.len();
    for a in 0..nodes {
        for b in a + 1..nodes {
            s.true_pairs += run.truth[a]
                .iter()
                .filter(|k| run.truth[b].contains(k))
                .count();
        }
    }
    for p in out
        .pairs
        .iter()
        .filter(|p| p.decision == Decision::Correlated)
    {
        let (na, ta) = index(&p.a.node, &p.a.track);
        let (nb, tb) = index(&p.b.node, &p.b.track);
        if run.truth[na][ta] == run.truth[nb][tb] {
            s.correct += 1;
        } else {
            s.wrong += 1;
        }
    }
    s.missed = s.true_pairs - s.correct;
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use service::{
        correlation::{PairOutput, correlate},
        session::{
            Limits, SessionKind,
            correlation::{BatchInput, CorrelationSession, ReportInput, SessionSpec, SessionView},
        },
    };

    /// Runs `request` through a correlation session with the same
    /// configuration, its reports in time order in batches of `size`, then
    /// a flush.
    fn session_view(request: &CorrelateInput, size: usize, history: Option<u32>) -> SessionView {
        let mut config = request.clone();
        let mut reports: Vec<ReportInput> = Vec::new();
        for n in &mut config.nodes {
            for t in n.tracks.drain(..) {
                for s in t.samples {
                    reports.push(ReportInput {
                        node: n.id.clone(),
                        track: t.id.clone(),
                        sample: s,
                    });
                }
            }
        }
        reports.sort_by(|a, b| a.sample.t.unwrap().total_cmp(&b.sample.t.unwrap()));
        let mut s = CorrelationSession::new(SessionSpec {
            config,
            retire_after_s: None,
            history_instants: history,
        })
        .unwrap();
        let limits = Limits {
            max_tracks: 10_000,
            max_batch_reports: 10_000,
        };
        let mut w = Vec::new();
        for chunk in reports.chunks(size) {
            let batch = BatchInput {
                reports: chunk.to_vec(),
                flush: false,
            };
            s.apply(&batch, &limits, &mut w).unwrap();
        }
        let flush = BatchInput {
            reports: Vec::new(),
            flush: true,
        };
        s.apply(&flush, &limits, &mut w).unwrap();
        s.view().unwrap()
    }

    /// With the defaults (grid alignment, period and staleness estimated)
    /// every network correlates ≥ 97 % of the same-target pairs with no
    /// wrong pair; the old default (clusters of 0.5 s) finds nothing on the
    /// offset networks and says so.
    #[test]
    fn unsynchronised_networks_correlate_with_the_defaults() {
        for (i, net) in cases().iter().enumerate() {
            let mut rng = SimRng::seed_from_u64(14 + i as u64);
            let run = generate(net, &mut rng).unwrap();
            let out = correlate(run.request.clone()).unwrap();
            let s = score(&run, &out);
            assert!(s.true_pairs >= 20 * (net.radars.len() - 1), "{s:?}");
            assert_eq!(s.wrong, 0, "{}: {s:?}", net.name);
            assert!(s.rate() >= 0.97, "{}: {s:?} {:?}", net.name, out.warnings);
            assert_eq!(out.alignment.node_pairs_without_common_instant, 0);
            if i == 0 || i == 3 {
                // A streaming session with the same defaults, fed in time
                // order in batches of 30 reports, meets the same bar (its
                // period is estimated from the first reports, so it may be
                // finer than the batch's) …
                let session = |request: &CorrelateInput| {
                    let view = session_view(request, 30, None);
                    score(
                        &run,
                        &CorrelateOutput {
                            pairs: view.pairs,
                            ..out.clone()
                        },
                    )
                };
                let streamed = session(&run.request);
                assert_eq!(streamed.wrong, 0, "{}: {streamed:?}", net.name);
                assert!(streamed.rate() >= 0.97, "{}: {streamed:?}", net.name);
                // … and with the period and staleness fixed, and a history
                // that holds every instant, decides exactly as the batch call.
                let mut fixed = run.request.clone();
                fixed.alignment = Some(AlignmentInput {
                    period_s: out.alignment.period_s,
                    max_staleness_s: Some(1.5 * out.alignment.period_s.unwrap()),
                    ..Default::default()
                });
                let batch = correlate(fixed.clone()).unwrap();
                // (Listed in the order of the session's track slots.)
                let sorted = |mut v: Vec<PairOutput>| {
                    v.sort_by(|x, y| (&x.a, &x.b).cmp(&(&y.a, &y.b)));
                    v
                };
                assert_eq!(
                    sorted(session_view(&fixed, 30, Some(1024)).pairs),
                    sorted(batch.pairs)
                );
            }
            if i == 0 {
                let mut old = run.request.clone();
                old.alignment = Some(old_default());
                let out = correlate(old).unwrap();
                assert_eq!(score(&run, &out).correct, 0);
                assert_eq!(out.alignment.node_pairs_without_common_instant, 1);
                assert!(out.warnings.iter().any(|w| w.contains("share no instant")));
            }
        }
    }
}
