//! The associator of confirmed tracks (seed 001 steps 5 and 6): JPDA (or
//! NN, GNN) weights of a frame's plots for the tracks the hypothesiser
//! found, from their predictions. It never updates a track: the
//! [`super::updater`] does, with these weights.
//!
//! Serial mode (step 6): one radar's scan group is one [`jpda::Scan`] with
//! the polar [`SensorModel::Polar`] at the radar's site, so the update is
//! the patent's EKF on (ρ, θ(, φ)), with the range rate ṙ of a Doppler
//! radar's plots as a further component, and all of `jpda` (exact / AMSJPDA /
//! NN / GNN, clusters, eqs. 6–7) is reused unchanged. A 2D radar measures
//! the horizontal range (layout without z, also in a 3D tracker).
//!
//! Parallel mode (step 5): the fused plots of one instant are Cartesian
//! positions with a covariance of their own (it depends on range, on the
//! radars fused and on the extrapolation), which `jpda::Scan` (one R per
//! scan) cannot express. [`associate_cartesian`] therefore builds the same
//! per-cluster [`ClusterProblem`] as `jpda` — a_tj = P_D N(ν_tj; 0, S_tj)/λ_j,
//! b_t = 1 − P_D P_G — with S_tj = H_j P H_j′ + R_j per pair, gets β from
//! [`exact_marginals`] / [`amsjpda_marginals`] (or NN / GNN), and updates
//! by Gaussian-mixture reduction of the per-measurement Kalman updates
//! (Joseph form): x⁺ = Σ_j β_j x_j, P⁺ = Σ_j β_j (P_j + (x_j − x⁺)(x_j − x⁺)′)
//! with j = 0 the prediction. With a common R this equals eqs. 6–7 of seed
//! 002 exactly. λ_j is the sum over the instant's radars of the same
//! dimension of their polar clutter density divided by the Jacobian
//! determinant of the polar → Cartesian map at z_j (ρ for 2D, r² cos φ for
//! 3D). The fused scan's P_D is 1 − Π(1 − P_D,i) over the radars that
//! delivered plots in the instant.

use nalgebra::DVector;

use crate::assignment;
use crate::error::AlgoError;
use crate::gating::SortedByFirst;
use crate::gating::chi2_threshold;
use crate::gaussian::{cholesky, symmetrize};
use crate::jpda::{
    self, ClusterProblem, Clutter, Config, Gate, Method, Scan, SensorModel, TrackEstimate,
    amsjpda_marginals, exact_marginals,
};
use crate::kalman::PositionLayout;
use crate::tracking::config::{Plot, RadarSpec};
use crate::tracking::conversion::CartesianPlot;

/// What the association of one frame decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Per track: the measurement with the largest β when the track was
    /// detected (β_miss < 1), else `None`.
    pub hit: Vec<Option<usize>>,
    /// Per measurement: inside the gate of at least one track (such plots
    /// take part in track association and are not used for initiation).
    pub used: Vec<bool>,
    /// Per track: β_0 and β_m of its gated measurements, for the updater of
    /// IMM tracks.
    pub associations: Vec<jpda::Association>,
    /// Tracks whose polar model is undefined at their prediction (at the
    /// radar's site): they gated nothing ([`jpda::ScanReport::undefined`]).
    pub undefined: Vec<usize>,
}

/// Serial mode: the JPDA weights of the polar plots of one radar for
/// `tracks` (predicted to the scan time), through the EKF's linearisation.
pub fn associate_polar(
    tracks: &[TrackEstimate],
    radar: &RadarSpec,
    plots: &[Plot],
    axes: usize,
    gate_probability: f64,
    config: &Config,
    evidence: Option<jpda::Evidence<'_>>,
) -> Result<Outcome, AlgoError> {
    let layout = polar_layout(radar, axes);
    let range_rate = range_rate_sigma(radar, plots);
    let model = SensorModel::Polar {
        site: radar.site,
        layout,
        sigma_range: radar.sigma_range,
        sigma_azimuth: radar.sigma_azimuth,
        sigma_elevation: radar.sigma_elevation,
        sigma_range_rate: range_rate,
    };
    let dim = model.dim();
    let measurements = plots
        .iter()
        .map(|p| {
            let mut v = vec![p.range, p.azimuth];
            v.extend(p.elevation);
            if range_rate.is_some() {
                v.extend(p.radial_velocity);
            }
            DVector::from_vec(v)
        })
        .collect();
    let scan = Scan {
        model,
        measurements,
        detection_probability: radar.detection_probability,
        gate: Gate::from_probability(dim, gate_probability)?,
        clutter: Clutter::Density(radar.clutter_density),
    };
    let report = match evidence {
        Some(e) => jpda::associate_with(tracks, &scan, config, e)?,
        None => jpda::associate(tracks, &scan, config)?,
    };
    let mut used = vec![false; plots.len()];
    let hit = report
        .associations
        .iter()
        .map(|a| {
            for &(j, _) in &a.measurements {
                used[j] = true;
            }
            best(a.miss, &a.measurements)
        })
        .collect();
    Ok(Outcome {
        hit,
        used,
        associations: report.associations,
        undefined: report.undefined,
    })
}

/// σ_ṙ when the range rate joins a scan group's measurement: the radar
/// gives it and every plot of the group has one (so it also decides β: two
/// crossing targets of different radial speeds are told apart). The
/// updater of IMM tracks follows the same decision.
pub fn range_rate_sigma(radar: &RadarSpec, plots: &[Plot]) -> Option<f64> {
    radar
        .sigma_radial_velocity
        .filter(|_| plots.iter().all(|p| p.radial_velocity.is_some()))
}

/// Where a radar's polar plots see the state: with the height for a 3D
/// radar in a 3D tracker, horizontally otherwise (a 2D radar measures the
/// horizontal range, also in a 3D tracker).
pub fn polar_layout(radar: &RadarSpec, axes: usize) -> PositionLayout {
    if radar.is_3d() && axes == 3 {
        PositionLayout::CV_3D
    } else {
        PositionLayout::CV_2D
    }
}

/// Parallel mode: the JPDA weights of Cartesian plots of their own
/// covariance for `tracks`; `clutter[j]` is λ_j > 0 in the space of plot
/// j. (The update, a mixture of the per-plot Kalman updates moment
/// matched, is the updater's.)
pub fn associate_cartesian(
    tracks: &[TrackEstimate],
    plots: &[CartesianPlot],
    clutter: &[f64],
    detection_probability: f64,
    gate_probability: f64,
    config: &Config,
    evidence: Option<jpda::Evidence<'_>>,
) -> Result<Outcome, AlgoError> {
    // γ per measurement dimension (a position of 2 or 3 components, then
    // one per range rate of a moved plot, one per velocity component of a
    // report).
    let max_dim = plots
        .iter()
        .map(|p| p.z.len() + p.range_rates.len() + p.velocity.len())
        .max()
        .unwrap_or(2)
        .max(3);
    let gates = (0..=max_dim)
        .map(|k| {
            if k == 0 {
                Ok(0.0)
            } else {
                chi2_threshold(k, 1.0 - gate_probability)
            }
        })
        .collect::<Result<Vec<f64>, AlgoError>>()?;
    // Hypothesise: every gated (track, plot) pair with its Kalman update.
    // Exact pruning: ν'S⁻¹ν ≥ ν_0²/S_00 with S_00 = P_00 + R_00, so only
    // plots whose first component (east) lies within √(γ S_00) of the
    // track's can pass; found by binary search in the plots sorted by it.
    let by_first = SortedByFirst::new(plots.iter().map(|p| p.z[0]));
    let max_r00 = plots.iter().map(|p| p.r[(0, 0)]).fold(0.0, f64::max);
    let gate_max = gates.iter().copied().fold(0.0, f64::max);
    let mut candidates: Vec<usize> = Vec::new();
    let mut hyps: Vec<Vec<Hypothesis>> = Vec::with_capacity(tracks.len());
    for (c, track) in tracks.iter().enumerate() {
        let mut row = Vec::new();
        let reach = (gate_max * (track.p[(0, 0)] + max_r00)).sqrt() * (1.0 + 1e-9);
        by_first.within(track.x[0], reach, &mut candidates);
        for &j in &candidates {
            // Identity beside the position: Λ multiplies the pairing's
            // likelihood (its cost d² − 2 ln Λ for NN and GNN); `None`
            // rules it out.
            let ln_evidence = match evidence {
                Some(e) => match e(c, j) {
                    Some(l) => l.clamp(-jpda::MAX_LN_EVIDENCE, jpda::MAX_LN_EVIDENCE),
                    None => continue,
                },
                None => 0.0,
            };
            let lin = plots[j].linearise(&track.x);
            let k = lin.innovation.len();
            let mut s = &lin.h * &track.p * lin.h.transpose() + &lin.r;
            symmetrize(&mut s);
            let chol = cholesky("innovation covariance", &s)?;
            let w = chol.l().solve_lower_triangular(&lin.innovation).ok_or(
                AlgoError::NotPositiveDefinite {
                    what: "innovation covariance",
                },
            )?;
            let d2 = w.norm_squared();
            if d2 <= gates[k] {
                let ln_det: f64 = chol.l().diagonal().iter().map(|v| 2.0 * v.ln()).sum();
                let ln_norm = -0.5 * (ln_det + k as f64 * (2.0 * std::f64::consts::PI).ln());
                row.push(Hypothesis {
                    measurement: j,
                    d2: d2 - 2.0 * ln_evidence,
                    ln_likelihood: ln_norm - 0.5 * d2 + ln_evidence,
                });
            }
        }
        hyps.push(row);
    }
    let mut used = vec![false; plots.len()];
    for h in hyps.iter().flatten() {
        used[h.measurement] = true;
    }
    // Associate: β per track (row 0 = miss, then its hypotheses in order).
    let beta = match config.method {
        Method::NearestNeighbour => hard(&hyps, nearest(&hyps)),
        Method::GlobalNearestNeighbour => {
            let edges: Vec<(usize, usize, f64)> = hyps
                .iter()
                .enumerate()
                .flat_map(|(t, row)| row.iter().map(move |h| (t, h.measurement, h.d2)))
                .collect();
            let unassigned = gate_max * (1.0 + 1e-12) + 1e-12;
            hard(&hyps, assignment::solve(&edges, unassigned))
        }
        Method::Exact | Method::Amsjpda => soft(
            &hyps,
            plots.len(),
            clutter,
            detection_probability,
            gate_probability,
            config,
        ),
    };
    let mut hit = Vec::with_capacity(tracks.len());
    let mut associations = Vec::with_capacity(tracks.len());
    for (row, b) in hyps.iter().zip(&beta) {
        let pairs: Vec<(usize, f64)> = row
            .iter()
            .map(|h| h.measurement)
            .zip(b[1..].iter().copied())
            .collect();
        hit.push(best(b[0], &pairs));
        associations.push(jpda::Association {
            miss: b[0],
            measurements: pairs,
        });
    }
    Ok(Outcome {
        hit,
        used,
        associations,
        undefined: Vec::new(),
    })
}

/// The clutter density of a fused plot (see the module header).
pub fn cartesian_clutter(plot: &CartesianPlot, radars: &[&RadarSpec]) -> f64 {
    let three = plot.z.len() == 3;
    radars
        .iter()
        .filter(|r| r.is_3d() == three)
        .map(|r| {
            let e = plot.z[0] - r.site[0];
            let n = plot.z[1] - r.site[1];
            let rho = e.hypot(n).max(1.0);
            let det = if three {
                let u = plot.z[2] - r.site[2];
                // r² cos φ = (ρ² + u²)·ρ/√(ρ² + u²) = ρ √(ρ² + u²).
                rho * rho.hypot(u)
            } else {
                rho
            };
            r.clutter_density / det
        })
        .sum::<f64>()
        .max(f64::MIN_POSITIVE)
}

struct Hypothesis {
    measurement: usize,
    d2: f64,
    /// ln N(ν; 0, S).
    ln_likelihood: f64,
}

/// The measurement of largest β (ties: lowest index) when β_miss < 1.
fn best(miss: f64, betas: &[(usize, f64)]) -> Option<usize> {
    if miss >= 1.0 {
        return None;
    }
    betas
        .iter()
        .filter(|(_, b)| *b > 0.0)
        .fold(None, |acc: Option<(usize, f64)>, &(j, b)| match acc {
            Some((_, bb)) if bb >= b => acc,
            _ => Some((j, b)),
        })
        .map(|(j, _)| j)
}

fn nearest(hyps: &[Vec<Hypothesis>]) -> Vec<(usize, usize)> {
    hyps.iter()
        .enumerate()
        .filter_map(|(t, row)| {
            row.iter()
                .min_by(|a, b| a.d2.total_cmp(&b.d2))
                .map(|h| (t, h.measurement))
        })
        .collect()
}

/// β ∈ {0, 1} from chosen (track, measurement) pairs.
fn hard(hyps: &[Vec<Hypothesis>], chosen: Vec<(usize, usize)>) -> Vec<Vec<f64>> {
    let mut beta: Vec<Vec<f64>> = hyps
        .iter()
        .map(|row| {
            let mut b = vec![0.0; row.len() + 1];
            b[0] = 1.0;
            b
        })
        .collect();
    for (t, j) in chosen {
        let k = hyps[t]
            .iter()
            .position(|h| h.measurement == j)
            .expect("a gated pair");
        beta[t][0] = 0.0;
        beta[t][k + 1] = 1.0;
    }
    beta
}

/// JPDA β per connected cluster of tracks sharing gated plots.
fn soft(
    hyps: &[Vec<Hypothesis>],
    measurements: usize,
    clutter: &[f64],
    p_d: f64,
    p_g: f64,
    config: &Config,
) -> Vec<Vec<f64>> {
    let mut beta: Vec<Vec<f64>> = hyps.iter().map(|row| vec![0.0; row.len() + 1]).collect();
    let ln_b = (1.0 - p_d * p_g).ln();
    for (tracks, meas) in jpda::clusters(hyps, measurements, |h| h.measurement) {
        let mut gates = Vec::with_capacity(tracks.len());
        let mut miss = Vec::with_capacity(tracks.len());
        for &t in &tracks {
            let ln_a: Vec<f64> = hyps[t]
                .iter()
                .map(|h| p_d.ln() + h.ln_likelihood - clutter[h.measurement].ln())
                .collect();
            let top = ln_a.iter().copied().fold(ln_b, f64::max);
            miss.push((ln_b - top).exp());
            gates.push(
                hyps[t]
                    .iter()
                    .zip(&ln_a)
                    .map(|(h, &la)| {
                        let local = meas.binary_search(&h.measurement).expect("in cluster");
                        (local, (la - top).exp())
                    })
                    .collect(),
            );
        }
        let problem = ClusterProblem {
            measurements: meas.len(),
            gates,
            miss,
            count_factor: None,
        };
        let marginals =
            if config.method == Method::Amsjpda || tracks.len() > config.max_exact_tracks {
                amsjpda_marginals(&problem)
            } else {
                exact_marginals(&problem, config.max_hypotheses)
                    .unwrap_or_else(|_| amsjpda_marginals(&problem))
            };
        for (local, &t) in tracks.iter().enumerate() {
            beta[t].clone_from(&marginals.beta[local]);
        }
    }
    beta
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracking::predictor::ModeState;
    use crate::tracking::updater::{CartesianUpdater, Updater};
    use nalgebra::{DMatrix, dmatrix, dvector};

    /// The updater's update of one track with the association's weights
    /// (one mode: the PDA update).
    fn updated(
        track: &TrackEstimate,
        assoc: &jpda::Association,
        plots: &[CartesianPlot],
    ) -> TrackEstimate {
        let mut one = [ModeState {
            probability: 1.0,
            x: track.x.clone(),
            p: track.p.clone(),
        }];
        let (x, p) = CartesianUpdater { plots }.update(&mut one, assoc).unwrap();
        TrackEstimate { x, p }
    }

    fn cfg(method: Method) -> Config {
        Config {
            method,
            max_exact_tracks: 10,
            max_hypotheses: 100_000,
        }
    }

    fn plot(x: f64, y: f64, var: f64) -> CartesianPlot {
        CartesianPlot {
            t: 0.0,
            z: dvector![x, y],
            r: DMatrix::from_diagonal(&dvector![var, var]),
            radars: vec![0],
            measured: None,
            range_rates: Vec::new(),
            velocity: Vec::new(),
        }
    }

    #[test]
    fn one_track_one_plot_is_the_kalman_update_weighted_by_beta() {
        // Track at 0 with P = diag(100, 1, 100, 1), plot at (10, 0), R = 100 I:
        // S = 200 I, d² = 100/200 = 0.5, N = exp(−0.25)/(2π·200).
        // a = P_D N/λ, b = 1 − P_D P_G; β_1 = a/(a + b).
        // Kalman: K_pos = 100/200 = 0.5 → x_1 = 5, P_1,xx = 50.
        // Mixture: x = β₁·5, P_xx = β₀·100 + β₁·50 + β₀β₁·25.
        let (p_d, p_g, lambda) = (0.9, 0.99, 1e-5);
        let tracks = vec![TrackEstimate {
            x: dvector![0.0, 0.0, 0.0, 0.0],
            p: DMatrix::from_diagonal(&dvector![100.0, 1.0, 100.0, 1.0]),
        }];
        let plots = [plot(10.0, 0.0, 100.0)];
        let out = associate_cartesian(
            &tracks,
            &plots,
            &[lambda],
            p_d,
            p_g,
            &cfg(Method::Exact),
            None,
        )
        .unwrap();
        let n = (-0.25f64).exp() / (2.0 * std::f64::consts::PI * 200.0);
        let a = p_d * n / lambda;
        let b = 1.0 - p_d * p_g;
        let b1 = a / (a + b);
        let b0 = 1.0 - b1;
        assert_eq!(out.hit, vec![Some(0)]);
        assert_eq!(out.used, vec![true]);
        assert!((out.associations[0].measurements[0].1 - b1).abs() < 1e-12);
        // The tracks are left as they were; the updater updates them.
        assert_eq!(tracks[0].x[0], 0.0);
        let tracks = [updated(&tracks[0], &out.associations[0], &plots)];
        assert!((tracks[0].x[0] - 5.0 * b1).abs() < 1e-9);
        let want = b0 * 100.0 + b1 * 50.0 + b0 * b1 * 25.0;
        assert!(
            (tracks[0].p[(0, 0)] - want).abs() < 1e-9,
            "{}",
            tracks[0].p[(0, 0)]
        );
    }

    #[test]
    fn gnn_gives_each_track_its_own_plot_and_ignores_the_far_plot() {
        let tracks = vec![
            TrackEstimate {
                x: dvector![0.0, 0.0, 0.0, 0.0],
                p: DMatrix::identity(4, 4) * 100.0,
            },
            TrackEstimate {
                x: dvector![40.0, 0.0, 0.0, 0.0],
                p: DMatrix::identity(4, 4) * 100.0,
            },
        ];
        let plots = [
            plot(35.0, 0.0, 100.0),
            plot(5.0, 0.0, 100.0),
            plot(1e4, 0.0, 100.0),
        ];
        let out = associate_cartesian(
            &tracks,
            &plots,
            &[1e-6; 3],
            0.9,
            0.99,
            &cfg(Method::GlobalNearestNeighbour),
            None,
        )
        .unwrap();
        assert_eq!(out.hit, vec![Some(1), Some(0)]);
        assert_eq!(out.used, vec![true, true, false]);
        let tracks: Vec<TrackEstimate> = tracks
            .iter()
            .zip(&out.associations)
            .map(|(t, a)| updated(t, a, &plots))
            .collect();
        // Kalman with gain 1/2: 0 → 2.5 and 40 → 37.5.
        assert!((tracks[0].x[0] - 2.5).abs() < 1e-12);
        assert!((tracks[1].x[0] - 37.5).abs() < 1e-12);
        assert!((tracks[0].p.view((0, 0), (1, 1)) - dmatrix![50.0]).amax() < 1e-12);
    }

    #[test]
    fn clutter_density_is_converted_by_the_jacobian() {
        // 2D radar at the origin, λ = 2e-3 per m·rad; plot at (300, 400): ρ = 500,
        // λ_cart = 2e-3/500 = 4e-6 per m².
        let radar = RadarSpec {
            site: [0.0; 3],
            sigma_range: 1.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: None,
            sigma_radial_velocity: Some(1.0),
            scan_period: 1.0,
            detection_probability: 1.0,
            clutter_density: 2e-3,
        };
        let l = cartesian_clutter(&plot(300.0, 400.0, 1.0), &[&radar]);
        assert!((l - 4e-6).abs() < 1e-18);
    }
}
