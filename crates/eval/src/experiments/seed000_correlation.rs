//! `seed000-correlation`: seed 000 §5 in full. Two nodes with 2D radars
//! (σρ = 170 m and 180 m, σθ = 1°), 60 and 120 targets, T = 4 s, speeds
//! 4–1200 m/s, process noise of eq. 26, L/R = 6/8; the weighted and modified
//! tests against the independent and dependent double-threshold methods, plus
//! the classic baselines the paper names (nearest neighbour, K-NN, global
//! assignment) and the double-threshold + assignment combination. Every
//! method is the service's own engine (`algo::correlation::engine`), stepped
//! once per scan; its output at a scan is its correlated pairs plus, for the
//! double-threshold methods, its trial system tracks (eq. 21), since those
//! are output as system tracks too.

use crate::{
    SimError,
    experiments::{EvalOptions, correlation::correlation_report},
    report::Report,
    scenario000::{Driver, Method, Seed000Scene, TwoNodeRun},
};
use algo::{
    correlation::{
        engine::{
            Config, Method as EngineMethod, PairCorrelator, Pruning, Resolution, RuleSpec,
            Statistic,
        },
        rules::LrRule,
        scene::{Scene, Track},
    },
    motion::{ConstantVelocity, MotionModel, ProcessNoise},
};

/// Runs the experiment (60 and 120 targets unless overridden).
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    let methods = [
        Method {
            name: "weighted",
            driver: Driver::Batch(&|s, r| drive(s, r, classic(Statistic::Weighted))),
        },
        Method {
            name: "modified",
            driver: Driver::Batch(&|s, r| drive(s, r, classic(Statistic::Modified))),
        },
        Method {
            name: "independent double threshold 6/8",
            driver: Driver::Batch(&|s, r| {
                drive(
                    s,
                    r,
                    double_threshold(Statistic::Weighted, Resolution::Greedy),
                )
            }),
        },
        Method {
            name: "dependent double threshold 6/8",
            driver: Driver::Batch(&|s, r| {
                drive(
                    s,
                    r,
                    double_threshold(Statistic::Modified, Resolution::Greedy),
                )
            }),
        },
        Method {
            name: "double threshold 6/8 + assignment",
            driver: Driver::Batch(&|s, r| {
                drive(
                    s,
                    r,
                    double_threshold(Statistic::Weighted, Resolution::Assignment),
                )
            }),
        },
        Method {
            name: "nearest neighbour",
            driver: Driver::Batch(&|s, r| {
                drive(s, r, baseline(EngineMethod::NearestNeighbour { window: 1 }))
            }),
        },
        Method {
            name: "k-NN 3 of 5",
            driver: Driver::Batch(&|s, r| {
                drive(
                    s,
                    r,
                    baseline(EngineMethod::KNearestNeighbour { k: 3, window: 5 }),
                )
            }),
        },
        Method {
            name: "global assignment",
            driver: Driver::Batch(&|s, r| {
                drive(s, r, baseline(EngineMethod::GlobalAssignment { window: 1 }))
            }),
        },
    ];
    // Rates from scan 8 on: the paper's 6/8 rule needs 8 samples.
    correlation_report("seed000-correlation", opts, &[60, 120], 8, &methods)
}

fn config(method: EngineMethod, statistic: Statistic) -> Config {
    Config {
        method,
        statistic,
        alpha: 0.05,
        pruning: Pruning::Grid,
    }
}

/// The classic tests: the 1/1 rule (seed 000 §3.3).
fn classic(statistic: Statistic) -> Config {
    let one = LrRule::new(1, 1).expect("valid rule");
    config(
        EngineMethod::DoubleThreshold {
            rules: RuleSpec::Fixed(one),
            resolution: Resolution::Greedy,
        },
        statistic,
    )
}

fn double_threshold(statistic: Statistic, resolution: Resolution) -> Config {
    let rule = LrRule::new(6, 8).expect("valid rule");
    config(
        EngineMethod::DoubleThreshold {
            rules: RuleSpec::Fixed(rule),
            resolution,
        },
        statistic,
    )
}

fn baseline(method: EngineMethod) -> Config {
    config(method, Statistic::Weighted)
}

/// The run as a scene of the engine: node n's track `id` is track index
/// `id`, present at the scans where the node reports it, with I − K H from
/// the reported gain (H of eq. 25 picks x and y).
fn to_scene(run: &TwoNodeRun) -> Result<Scene, SimError> {
    let instants = run.times.len();
    let mut scene = Scene::new(4, vec![0, 2], run.times.clone())
        .map_err(|e| SimError::InvalidConfig(e.to_string()))?;
    for node in &run.nodes {
        let count = node
            .iter()
            .flatten()
            .map(|t| t.id as usize + 1)
            .max()
            .unwrap_or(0);
        let mut tracks: Vec<Track> = (0..count).map(|_| Track::new(instants, 4)).collect();
        for (l, scan) in node.iter().enumerate() {
            for tr in scan {
                let e = &tr.estimate;
                let p: Vec<f64> = (0..4)
                    .flat_map(|i| (0..4).map(move |j| (i, j)))
                    .map(|(i, j)| e.p[(i, j)])
                    .collect();
                let track = &mut tracks[tr.id as usize];
                track.set(l, e.x.as_slice(), &p);
                if let Some(k) = &e.gain {
                    // I − K H with H = [[1,0,0,0],[0,0,1,0]]: column 0 of K
                    // goes to state column 0, column 1 to state column 2.
                    let mut f = [0.0; 16];
                    for i in 0..4 {
                        f[i * 4 + i] = 1.0;
                        f[i * 4] -= k[(i, 0)];
                        f[i * 4 + 2] -= k[(i, 1)];
                    }
                    track.set_gain_factor(l, &f);
                }
            }
        }
        scene
            .add_node(tracks)
            .map_err(|e| SimError::InvalidConfig(e.to_string()))?;
    }
    Ok(scene)
}

/// Steps the engine once per scan and returns each scan's output pairs.
fn drive(
    scene000: &Seed000Scene,
    run: &TwoNodeRun,
    cfg: Config,
) -> Result<Vec<Vec<(u32, u32)>>, SimError> {
    let scene = to_scene(run)?;
    let model = ConstantVelocity::new(
        2,
        ProcessNoise::VelocityProportional {
            factor: scene000.noise_factor,
        },
    )
    .map_err(|e| SimError::InvalidConfig(e.to_string()))?;
    let model_ref: Option<&dyn MotionModel> = Some(&model);
    let mut engine = PairCorrelator::new(&scene, 0, 1, &cfg, model_ref)
        .map_err(|e| SimError::InvalidConfig(e.to_string()))?;
    let mut out = Vec::with_capacity(run.times.len());
    while engine
        .step()
        .map_err(|e| SimError::InvalidConfig(e.to_string()))?
    {
        let mut pairs: Vec<(u32, u32)> = engine
            .correlated()
            .chain(engine.trials())
            .map(|(a, b)| (a as u32, b as u32))
            .collect();
        pairs.sort_unstable();
        out.push(pairs);
    }
    Ok(out)
}
