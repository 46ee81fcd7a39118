//! Plot-to-plot association and fusion across radars (seed 001 step 4).
//!
//! Association: global nearest neighbour with the χ² gate
//! (z₂ − z₁)′ (R₁ + R₂)⁻¹ (z₂ − z₁) ≤ γ. The patent prints the gate with
//! R(i) between the differences (`(z2(j)−z1(i))HR(i)(z2(j)−z1(i))≤γ`); a χ²
//! statistic needs the inverse of the covariance of the difference, which
//! for independent radars is R₁ + R₂, so that is what is implemented.
//! The patent describes two radars; for more we proceed sequentially: the
//! plots of the lowest radar index start the clusters, and each further
//! radar's plots are assigned to the clusters fused so far by
//! [`assignment::solve`] with cost d² (the patent's statistic, no
//! log-determinant term) and unassigned cost γ (an edge is taken only when
//! it is inside the gate). A plot left alone starts its own cluster, so
//! every plot appears in exactly one output, and a cluster never holds two
//! plots of one radar.
//!
//! Fusion: the maximum-likelihood ("parallel compression") estimate
//! x̂ = (Σ C_i⁻¹)⁻¹ Σ C_i⁻¹ z_i with covariance (Σ C_i⁻¹)⁻¹, the
//! minimum-variance unbiased combination of independent plots. A 2D plot
//! in a cluster with 3D plots contributes H′C⁻¹H with H selecting (e, n);
//! plots are compared in their common (horizontal) subspace.

use nalgebra::{DMatrix, DVector};

use crate::assignment;
use crate::error::AlgoError;
use crate::gating::SortedByFirst;
use crate::gaussian::{cholesky, mahalanobis_sq, symmetrize};
use crate::tracking::conversion::{CartesianPlot, RangeRate};
use crate::tracking::track::chi2_gates;

/// Associates the plots of one fusion instant across radars and fuses the
/// associated ones. `plots` each come from one radar; the output lists the
/// fused clusters in the order they were started, each with the union of
/// their radars.
pub fn associate_and_fuse(
    plots: &[CartesianPlot],
    gate_probability: f64,
) -> Result<Vec<CartesianPlot>, AlgoError> {
    Ok(associate_and_fuse_members(plots, gate_probability)?.0)
}

/// [`associate_and_fuse`], with each cluster's members: the indices in
/// `plots` of the plots fused into it (one per radar, in the order they
/// joined). Registration in parallel mode learns from them.
pub fn associate_and_fuse_members(
    plots: &[CartesianPlot],
    gate_probability: f64,
) -> Result<(Vec<CartesianPlot>, Vec<Vec<usize>>), AlgoError> {
    let mut radars: Vec<usize> = plots
        .iter()
        .flat_map(|p| p.radars.iter().copied())
        .collect();
    radars.sort_unstable();
    radars.dedup();
    let gates = chi2_gates(gate_probability)?;
    let mut clusters: Vec<CartesianPlot> = Vec::new();
    let mut members: Vec<Vec<usize>> = Vec::new();
    for radar in radars {
        let (index, batch): (Vec<usize>, Vec<&CartesianPlot>) = plots
            .iter()
            .enumerate()
            .filter(|(_, p)| p.radars[0] == radar)
            .unzip();
        // Exact pruning: d'S⁻¹d ≥ d_0²/S_00, so only plots whose first
        // component lies within √(γ S_00) of the cluster's can pass; they
        // are found by binary search in the batch sorted by it.
        let by_first = SortedByFirst::new(batch.iter().map(|p| p.z[0]));
        let max_r00 = batch.iter().map(|p| p.r[(0, 0)]).fold(0.0, f64::max);
        let gate_max = gates[0].max(gates[1]);
        let mut candidates = Vec::new();
        let mut edges = Vec::new();
        for (c, cluster) in clusters.iter().enumerate() {
            let reach = (gate_max * (cluster.r[(0, 0)] + max_r00)).sqrt() * (1.0 + 1e-9);
            by_first.within(cluster.z[0], reach, &mut candidates);
            for &j in &candidates {
                let p = batch[j];
                let d2 = distance_sq(cluster, p)?;
                let k = cluster.z.len().min(p.z.len());
                if d2 <= gates[k - 2] {
                    // Normalise so that one unassigned cost fits both dimensions.
                    edges.push((c, j, d2 / gates[k - 2]));
                }
            }
        }
        let chosen = assignment::solve(&edges, 1.0 + 1e-12);
        let mut taken = vec![false; batch.len()];
        for (c, j) in chosen {
            clusters[c] = fuse(&clusters[c], batch[j])?;
            members[c].push(index[j]);
            taken[j] = true;
        }
        for (j, p) in batch.into_iter().enumerate() {
            if !taken[j] {
                clusters.push(p.clone());
                members.push(vec![index[j]]);
            }
        }
    }
    Ok((clusters, members))
}

/// d′ (R_a + R_b)⁻¹ d with d = z_b − z_a over the components both have.
pub fn distance_sq(a: &CartesianPlot, b: &CartesianPlot) -> Result<f64, AlgoError> {
    let k = a.z.len().min(b.z.len());
    let d = DVector::from_fn(k, |i, _| b.z[i] - a.z[i]);
    let mut s = DMatrix::from_fn(k, k, |i, j| a.r[(i, j)] + b.r[(i, j)]);
    symmetrize(&mut s);
    mahalanobis_sq(&d, &s)
}

/// The ML fusion of two independent Gaussian positions (information form);
/// the result has the larger dimension.
pub fn fuse(a: &CartesianPlot, b: &CartesianPlot) -> Result<CartesianPlot, AlgoError> {
    let n = a.z.len().max(b.z.len());
    let mut info = DMatrix::zeros(n, n);
    let mut vec = DVector::zeros(n);
    // Per input range rate: R_i⁻¹ Cov(z_i, ṙ), padded to n.
    let mut weighted_cross = Vec::new();
    for p in [a, b] {
        let k = p.z.len();
        let inv = cholesky("plot covariance", &p.r)?.inverse();
        let iz = &inv * &p.z;
        for i in 0..k {
            vec[i] += iz[i];
            for j in 0..k {
                info[(i, j)] += inv[(i, j)];
            }
        }
        for rr in &p.range_rates {
            let ic = &inv * &rr.cross;
            weighted_cross.push((
                rr,
                DVector::from_fn(n, |i, _| if i < k { ic[i] } else { 0.0 }),
            ));
        }
    }
    symmetrize(&mut info);
    let mut r = cholesky("fused information", &info)?.inverse();
    symmetrize(&mut r);
    let z = &r * vec;
    // z_f = R_f Σ R_i⁻¹ z_i, so Cov(z_f, ṙ) = R_f R_i⁻¹ Cov(z_i, ṙ).
    let range_rates = weighted_cross
        .into_iter()
        .map(|(rr, wc)| RangeRate {
            cross: &r * wc,
            ..rr.clone()
        })
        .collect();
    let mut radars = a.radars.clone();
    radars.extend(&b.radars);
    radars.sort_unstable();
    radars.dedup();
    Ok(CartesianPlot {
        t: a.t.max(b.t),
        z,
        r,
        radars,
        measured: None,
        range_rates,
        velocity: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{dmatrix, dvector};

    fn p2(radar: usize, x: f64, y: f64, var: [f64; 2]) -> CartesianPlot {
        CartesianPlot {
            t: 0.0,
            z: dvector![x, y],
            r: DMatrix::from_diagonal(&dvector![var[0], var[1]]),
            radars: vec![radar],
            measured: None,
            range_rates: Vec::new(),
            velocity: Vec::new(),
        }
    }

    #[test]
    fn two_radars_two_targets_fuse_by_inverse_variance() {
        // Target A: radar 0 at (0, 0) var (100, 400); radar 1 at (30, −20) var (300, 100).
        // Per axis x̂ = (x0/σ0² + x1/σ1²)/(1/σ0² + 1/σ1²):
        //   x: (0/100 + 30/300)/(1/100 + 1/300) = 0.1/(4/300) = 7.5, var 1/(4/300) = 75;
        //   y: (0/400 − 20/100)/(1/400 + 1/100) = −0.2/(5/400) = −16, var 80.
        // Target B 5 km away pairs with its own plot: x̂ = (5000 + 5010)/2, var 50.
        // d² of the A pair = 30²/400 + 20²/500 = 2.25 + 0.8 = 3.05 < γ(2, 0.01) = 9.21.
        let plots = vec![
            p2(0, 0.0, 0.0, [100.0, 400.0]),
            p2(0, 5000.0, 0.0, [100.0, 100.0]),
            p2(1, 5010.0, 0.0, [100.0, 100.0]),
            p2(1, 30.0, -20.0, [300.0, 100.0]),
        ];
        let fused = associate_and_fuse(&plots, 0.99).unwrap();
        assert_eq!(fused.len(), 2);
        let a = &fused[0];
        assert_eq!(a.radars, vec![0, 1]);
        assert!((&a.z - dvector![7.5, -16.0]).amax() < 1e-9);
        assert!((&a.r - dmatrix![75.0, 0.0; 0.0, 80.0]).amax() < 1e-9);
        let b = &fused[1];
        assert!((&b.z - dvector![5005.0, 0.0]).amax() < 1e-9);
        assert!((&b.r - dmatrix![50.0, 0.0; 0.0, 50.0]).amax() < 1e-9);
    }

    #[test]
    fn a_plot_outside_the_gate_stays_alone() {
        // d² = 50²/(100 + 100) = 12.5 > 9.21: two clusters, unchanged.
        let plots = vec![
            p2(0, 0.0, 0.0, [100.0, 100.0]),
            p2(1, 50.0, 0.0, [100.0, 100.0]),
        ];
        let fused = associate_and_fuse(&plots, 0.99).unwrap();
        assert_eq!(fused, plots);
    }

    #[test]
    fn three_radars_fuse_sequentially() {
        // Same target, variances 100, 200, 400 per axis, x = 0, 10, 20:
        // x̂ = (0/100 + 10/200 + 20/400)/(1/100 + 1/200 + 1/400)
        //   = 0.1/(7/400) = 40/7, var 400/7; y = 0.
        let plots = vec![
            p2(2, 20.0, 0.0, [400.0, 400.0]),
            p2(0, 0.0, 0.0, [100.0, 100.0]),
            p2(1, 10.0, 0.0, [200.0, 200.0]),
        ];
        let fused = associate_and_fuse(&plots, 0.99).unwrap();
        assert_eq!(fused.len(), 1);
        assert_eq!(fused[0].radars, vec![0, 1, 2]);
        assert!((fused[0].z[0] - 40.0 / 7.0).abs() < 1e-9);
        assert!((fused[0].r[(0, 0)] - 400.0 / 7.0).abs() < 1e-9);
        assert!((fused[0].r[(1, 1)] - 400.0 / 7.0).abs() < 1e-9);
    }

    #[test]
    fn gnn_gives_each_plot_to_the_nearer_cluster() {
        // Radar 0 plots at x = 0 and x = 40, radar 1 plots at x = 5 and x = 35
        // (var 100 each, d² = 25/200 or 1225/200 = 6.125, 1225/200 and 25/200):
        // the optimal pairing is (0, 5), (40, 35) with total 0.25, not crossed.
        let plots = vec![
            p2(0, 0.0, 0.0, [100.0, 100.0]),
            p2(0, 40.0, 0.0, [100.0, 100.0]),
            p2(1, 35.0, 0.0, [100.0, 100.0]),
            p2(1, 5.0, 0.0, [100.0, 100.0]),
        ];
        let fused = associate_and_fuse(&plots, 0.99).unwrap();
        assert_eq!(fused.len(), 2);
        assert!((fused[0].z[0] - 2.5).abs() < 1e-9);
        assert!((fused[1].z[0] - 37.5).abs() < 1e-9);
    }

    #[test]
    fn a_2d_plot_fuses_into_a_3d_plot_horizontally() {
        // 3D plot (0, 0, 1000) var 100 each; 2D plot (10, 0) var 100:
        // horizontal x̂ = 5 (var 50), y 0 (var 50); height from the 3D plot alone.
        let a = CartesianPlot {
            t: 0.0,
            z: dvector![0.0, 0.0, 1000.0],
            r: DMatrix::from_diagonal(&dvector![100.0, 100.0, 100.0]),
            radars: vec![0],
            measured: None,
            range_rates: Vec::new(),
            velocity: Vec::new(),
        };
        let b = p2(1, 10.0, 0.0, [100.0, 100.0]);
        let f = fuse(&a, &b).unwrap();
        assert!((f.z - dvector![5.0, 0.0, 1000.0]).amax() < 1e-9);
        assert!((f.r - DMatrix::from_diagonal(&dvector![50.0, 50.0, 100.0])).amax() < 1e-9);
    }

    #[test]
    fn fusion_carries_each_range_rate_with_its_weighted_correlation() {
        // Two plots with the same covariance R: z_f = (z_a + z_b)/2, so
        // Cov(z_f, ṙ_a) = Cov(z_a, ṙ_a)/2 = R_f R_a⁻¹ c_a with R_f = R/2.
        let rr = |site: f64, c: [f64; 2]| RangeRate {
            site: [site, 0.0, 0.0],
            value: site,
            sigma: 1.0,
            dt: 1.0,
            horizontal: true,
            cross: dvector![c[0], c[1]],
        };
        let mut a = p2(0, 0.0, 0.0, [4.0, 9.0]);
        a.range_rates.push(rr(1.0, [2.0, 0.0]));
        let mut b = p2(1, 1.0, 1.0, [4.0, 9.0]);
        b.range_rates.push(rr(2.0, [0.0, 3.0]));
        let f = fuse(&a, &b).unwrap();
        assert_eq!(f.range_rates.len(), 2);
        assert!((f.range_rates[0].cross[0] - 1.0).abs() < 1e-12);
        assert!(f.range_rates[0].cross[1].abs() < 1e-12);
        assert!((f.range_rates[1].cross[1] - 1.5).abs() < 1e-12);
        assert_eq!(f.range_rates[1].value, 2.0);
    }
}
