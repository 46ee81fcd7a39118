//! The scene of the correlation benchmarks (criterion, the REST load test and
//! `examples/correlation_payload.rs`): two nodes, n targets each, 8 samples
//! per track, as a service request, so every benchmark measures the same thing.
//!
//! Targets are uniform in a square of side 2 km·√n (one per 4 km², the same
//! density at every n), speeds 4–1200 m/s, headings uniform, T = 4 s; each
//! node reports the truth plus Gaussian errors of σ = 200 m (position) and
//! 30 m/s (velocity) with that diagonal covariance. Method: independent double
//! threshold 6/8 at α = 0.05.

use rand::RngExt;
use rand_distr::StandardNormal;

use super::montecarlo::run_rng;
use crate::service::correlation::{
    CorrelateInput, MethodInput, NodeInput, RuleInput, SampleInput, TrackInput,
};

/// Position and velocity error σ of the benchmark's local tracks.
pub const SIGMA_POSITION_M: f64 = 200.0;
pub const SIGMA_VELOCITY_MPS: f64 = 30.0;

/// The benchmark request for `n` targets, with `pruning` = `grid` or `none`.
pub fn correlation_request(n: usize, pruning: &str) -> CorrelateInput {
    let mut rng = run_rng(42, n as u64);
    let normal = |rng: &mut super::SimRng| -> f64 { rng.sample(StandardNormal) };
    let side = 2000.0 * (n as f64).sqrt();
    let targets: Vec<[f64; 4]> = (0..n)
        .map(|_| {
            let speed = rng.random_range(4.0..1200.0);
            let heading: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            [
                rng.random_range(0.0..side),
                speed * heading.sin(),
                rng.random_range(0.0..side),
                speed * heading.cos(),
            ]
        })
        .collect();
    let (sp, sv) = (SIGMA_POSITION_M, SIGMA_VELOCITY_MPS);
    let cov = vec![
        vec![sp * sp, 0.0, 0.0, 0.0],
        vec![0.0, sv * sv, 0.0, 0.0],
        vec![0.0, 0.0, sp * sp, 0.0],
        vec![0.0, 0.0, 0.0, sv * sv],
    ];
    let nodes = ["n1", "n2"]
        .iter()
        .map(|id| NodeInput {
            id: Some(id.to_string()),
            tracks: targets
                .iter()
                .enumerate()
                .map(|(i, x)| TrackInput {
                    id: Some(i.to_string()),
                    samples: (0..8)
                        .map(|k| {
                            let t = 4.0 * k as f64;
                            SampleInput {
                                t: Some(t),
                                state: vec![
                                    x[0] + x[1] * t + sp * normal(&mut rng),
                                    x[1] + sv * normal(&mut rng),
                                    x[2] + x[3] * t + sp * normal(&mut rng),
                                    x[3] + sv * normal(&mut rng),
                                ],
                                covariance: cov.clone(),
                                gain: None,
                            }
                        })
                        .collect(),
                })
                .collect(),
        })
        .collect();
    CorrelateInput {
        state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
        method: Some(MethodInput {
            kind: Some("independent_double_threshold".into()),
            rule: Some(RuleInput {
                l: Some(6),
                r: Some(8),
            }),
            ..Default::default()
        }),
        nodes,
        pruning: Some(pruning.into()),
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_benchmark_scene_is_deterministic_and_correlates() {
        let a = correlation_request(20, "grid");
        let b = correlation_request(20, "grid");
        assert_eq!(
            a.nodes[0].tracks[3].samples[5].state,
            b.nodes[0].tracks[3].samples[5].state
        );
        let out = crate::service::correlation::correlate(a).unwrap();
        // Targets 2 km apart on average against 200 m errors: nearly all the
        // 20 true pairs correlate (a loose bound, not a tuned figure).
        let correlated = out
            .pairs
            .iter()
            .filter(|p| p.decision == crate::algo::correlation::engine::Decision::Correlated)
            .count();
        assert!(correlated >= 15, "{correlated}");
    }
}
