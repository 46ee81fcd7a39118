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
use crate::service::plot_fusion;

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

/// The plot-fusion benchmark scene (`examples/plot_fusion_load.rs`): `n`
/// targets in straight flight uniform in a square of side 6 km·√n (one per
/// 36 km²: 1,000 targets over 190 km × 190 km) at 100–300 m/s, seen by
/// `radars` 2D radars spread on a 60 km circle about the centre, scan
/// periods 4, 4.5, 5, 5.5 s with phases 0, 1.1, 2.3, 3.7 s, σ_ρ = 50 m,
/// σ_θ = 0.1°, P_D = 0.9, `false_per_scan` clutter plots per scan
/// (uniform in range 1–200 km and azimuth); with `doppler` every radar
/// also gives the radial velocity (σ 1 m/s). Plots are in time order.
pub fn plot_fusion_scene(
    n: usize,
    radars: usize,
    duration_s: f64,
    false_per_scan: usize,
    doppler: bool,
) -> (plot_fusion::SpecInput, Vec<plot_fusion::PlotInput>) {
    use std::f64::consts::TAU;
    let mut rng = run_rng(43, n as u64);
    let normal = |rng: &mut super::SimRng| -> f64 { rng.sample(StandardNormal) };
    let side = 6000.0 * (n as f64).sqrt();
    let targets: Vec<[f64; 4]> = (0..n)
        .map(|_| {
            let speed = rng.random_range(100.0..300.0);
            let heading: f64 = rng.random_range(0.0..TAU);
            [
                rng.random_range(-side / 2.0..side / 2.0),
                speed * heading.sin(),
                rng.random_range(-side / 2.0..side / 2.0),
                speed * heading.cos(),
            ]
        })
        .collect();
    let sites: Vec<[f64; 2]> = (0..radars)
        .map(|i| {
            let a = TAU * i as f64 / radars as f64;
            [60_000.0 * a.sin(), 60_000.0 * a.cos()]
        })
        .collect();
    let periods = [4.0, 4.5, 5.0, 5.5];
    let phases = [0.0, 1.1, 2.3, 3.7];
    let (sr, sa, sv) = (50.0, 0.1f64.to_radians(), 1.0);
    let mut plots: Vec<plot_fusion::PlotInput> = Vec::new();
    for (r, site) in sites.iter().enumerate() {
        let mut t = phases[r % 4];
        while t <= duration_s {
            for x in &targets {
                if rng.random::<f64>() >= 0.9 {
                    continue;
                }
                let (e, nn) = (x[0] + x[1] * t - site[0], x[2] + x[3] * t - site[1]);
                let range = e.hypot(nn);
                let rv = (e * x[1] + nn * x[3]) / range;
                plots.push(plot_fusion::PlotInput {
                    radar_id: Some(format!("r{r}")),
                    t: Some(t),
                    range_m: Some(range + sr * normal(&mut rng)),
                    azimuth_deg: Some((e.atan2(nn) + sa * normal(&mut rng)).to_degrees()),
                    elevation_deg: None,
                    radial_velocity_mps: doppler.then(|| rv + sv * normal(&mut rng)),
                });
            }
            for _ in 0..false_per_scan {
                plots.push(plot_fusion::PlotInput {
                    radar_id: Some(format!("r{r}")),
                    t: Some(t),
                    range_m: Some(rng.random_range(1_000.0..200_000.0)),
                    azimuth_deg: Some(rng.random_range(0.0..360.0)),
                    elevation_deg: None,
                    radial_velocity_mps: doppler.then(|| rng.random_range(-300.0..300.0)),
                });
            }
            t += periods[r % 4];
        }
    }
    plots.sort_by(|a, b| a.t.unwrap_or(0.0).total_cmp(&b.t.unwrap_or(0.0)));
    let spec = plot_fusion::SpecInput {
        origin: Some(plot_fusion::GeoInput {
            lat_deg: Some(52.0),
            lon_deg: Some(4.0),
            height_m: Some(0.0),
        }),
        radars: sites
            .iter()
            .enumerate()
            .map(|(r, site)| plot_fusion::RadarInput {
                id: Some(format!("r{r}")),
                kind: Some("2d".into()),
                site: Some(plot_fusion::SiteInput {
                    geodetic: None,
                    position_m: Some(site.to_vec()),
                }),
                sigma_range_m: Some(sr),
                sigma_azimuth_deg: Some(0.1),
                sigma_radial_velocity_mps: doppler.then_some(sv),
                scan_period_s: Some(periods[r % 4]),
                p_detection: Some(0.9),
                // false_per_scan over 199 km × 2π rad.
                clutter_density: Some((false_per_scan.max(1) as f64) / (199_000.0 * TAU)),
                ..Default::default()
            })
            .collect(),
        tracker: Default::default(),
    };
    (spec, plots)
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
