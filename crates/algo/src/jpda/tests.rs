//! Tests of JPDA: a hand-computed cluster, a hand-computed scan, exact
//! against naive enumeration, AMSJPDA against exact, SPD covariances and the
//! sequential multi-sensor form.

use nalgebra::{DMatrix, DVector, dmatrix, dvector};
use proptest::prelude::*;

use super::*;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// Two targets, three measurements (the hand case of the issue):
/// track 1 gates m0 (a = 2) and m1 (a = 1), b_1 = 0.5;
/// track 2 gates m1 (a = 3) and m2 (a = 1), b_2 = 0.5; parametric (g ≡ 1).
fn two_targets_three_measurements() -> ClusterProblem {
    ClusterProblem {
        measurements: 3,
        gates: vec![vec![(0, 2.0), (1, 1.0)], vec![(1, 3.0), (2, 1.0)]],
        miss: vec![0.5, 0.5],
        count_factor: None,
    }
}

#[test]
fn hand_computed_two_targets_three_measurements() {
    // Feasible joint events (track 1 option, track 2 option) and eq. 4 weights:
    //   (0, 0)  0.5·0.5 = 0.25     (0, m1) 0.5·3 = 1.5    (0, m2) 0.5·1 = 0.5
    //   (m0, 0) 2·0.5  = 1         (m0, m1) 2·3 = 6       (m0, m2) 2·1 = 2
    //   (m1, 0) 1·0.5  = 0.5       (m1, m1) infeasible    (m1, m2) 1·1 = 1
    // C = 0.25 + 1.5 + 0.5 + 1 + 6 + 2 + 0.5 + 1 = 12.75.
    // β_10 = (0.25 + 1.5 + 0.5)/C = 2.25/C, β_1,m0 = (1 + 6 + 2)/C = 9/C,
    // β_1,m1 = (0.5 + 1)/C = 1.5/C;
    // β_20 = (0.25 + 1 + 0.5)/C = 1.75/C, β_2,m1 = (1.5 + 6)/C = 7.5/C,
    // β_2,m2 = (0.5 + 2 + 1)/C = 3.5/C.
    let c = 12.75;
    let expected = [
        vec![2.25 / c, 9.0 / c, 1.5 / c],
        vec![1.75 / c, 7.5 / c, 3.5 / c],
    ];
    let p = two_targets_three_measurements();
    for m in [exact_marginals(&p, 1_000).unwrap(), naive_marginals(&p)] {
        for (row, want) in m.beta.iter().zip(&expected) {
            for (got, want) in row.iter().zip(want) {
                assert!(close(*got, *want, 1e-15), "{got} vs {want}");
            }
        }
    }
    assert_eq!(naive_marginals(&p).hypotheses, 8);
}

/// For two targets Zhou's direct computation is exact, and the paper's F_tj
/// (printed as a sum over the neighbours with one P_0) coincides with the
/// product Π_i (P_i0 + Σ_{l≠j} P_il), since B^t has one member:
/// β_1j ∝ a_1j · (0.5 + 3 + 1 − a_2j): miss 0.5·4.5 = 2.25, m0 2·4.5 = 9,
/// m1 1·(4.5 − 3) = 1.5, as in the hand case. For three or more targets the
/// printed sum is a misprint (it is not Zhou's formula and is not even
/// invariant to the scale of the weights); we implement the product.
#[test]
fn amsjpda_two_targets_is_exact() {
    let p = two_targets_three_measurements();
    let a = amsjpda_marginals(&p);
    let e = exact_marginals(&p, 1_000).unwrap();
    for (ra, re) in a.beta.iter().zip(&e.beta) {
        for (x, y) in ra.iter().zip(re) {
            assert!(close(*x, *y, 1e-15));
        }
    }
}

#[test]
fn amsjpda_three_target_chain_is_an_approximation() {
    // t0 – m0 – t1 – m1 – t2: the middle track's two neighbours compete for
    // different measurements; exact and AMSJPDA differ for the end tracks
    // (AMSJPDA ignores that t1 may be busy with the other end's measurement).
    let p = ClusterProblem {
        measurements: 2,
        gates: vec![vec![(0, 1.0)], vec![(0, 1.0), (1, 1.0)], vec![(1, 1.0)]],
        miss: vec![1.0, 1.0, 1.0],
        count_factor: None,
    };
    let e = exact_marginals(&p, 1_000).unwrap();
    let a = amsjpda_marginals(&p);
    // Exact, by hand: events over (t0, t1, t2) with every weight 1:
    // t1 miss: t0 ∈ {0, m0}, t2 ∈ {0, m1} → 4; t1 = m0: t0 = 0, t2 ∈ {0, m1} → 2;
    // t1 = m1: t0 ∈ {0, m0}, t2 = 0 → 2. C = 8; β_1,m0 (middle) = 2/8.
    assert!(close(e.beta[1][1], 0.25, 1e-15));
    // t0 = m0 in 2 (t1 miss) + 1 (t1 = m1) = 3 events: β_0,m0 = 3/8.
    assert!(close(e.beta[0][1], 3.0 / 8.0, 1e-15));
    // AMSJPDA for t0: a·(b_1 + a_1,m1) = 2 vs miss 1·(1 + 1 + 1) = 3 → 2/5.
    assert!(close(a.beta[0][1], 2.0 / 5.0, 1e-15));
    // For the middle track the neighbours are independent: exact.
    assert!(close(a.beta[1][1], e.beta[1][1], 1e-15));
}

#[test]
fn nonparametric_count_factor_matches_factorials() {
    // m = 4: g(d) = 4^d (4 − d)!/4! = 1, 4·6/24 = 1, 16·2/24 = 4/3, 64/24 = 8/3, 256/24 = 32/3,
    // divided by g(2) = 4/3 when at most two detections are possible.
    let g = nonparametric_count_factor(4, 2);
    assert!(close(g[0], 0.75, 1e-15));
    assert!(close(g[1], 0.75, 1e-15));
    assert!(close(g[2], 1.0, 1e-15));
}

/// A scalar track x = 0, P = 1, H = 1, R = 1 (S = 2, K = 1/2) and one
/// measurement z = 1, λ = 0.1, P_D = 0.9, gate γ = 4 (P_G = erf(√2) =
/// 0.9544997361036416). N = e^{−1/4}/√(4π) = 0.21969564473386122,
/// a = 0.9·N/0.1 = 1.9772608026047511, b = 1 − 0.9·P_G = 0.14095023750672253,
/// β_1 = a/(a + b) = 0.9334578874164942; x⁺ = K β_1 ν = 0.4667289437082471;
/// P⁺ = β_0·1 + β_1·(1 − K S K' = 1/2) + K²(β_1 − β_1²) = 0.5487996212508603.
#[test]
fn hand_computed_single_target_scan() {
    let mut tracks = vec![TrackEstimate {
        x: dvector![0.0],
        p: dmatrix![1.0],
    }];
    let s = Scan {
        model: SensorModel::Linear {
            h: dmatrix![1.0],
            r: dmatrix![1.0],
        },
        measurements: vec![dvector![1.0]],
        detection_probability: 0.9,
        gate: Gate::from_threshold(1, 4.0).unwrap(),
        clutter: Clutter::Density(0.1),
    };
    assert!(close(s.gate.probability, 0.9544997361036416, 1e-13));
    let report = scan(&mut tracks, &s, &config(Method::Exact)).unwrap();
    assert!(close(
        report.associations[0].measurements[0].1,
        0.9334578874164942,
        1e-13
    ));
    assert!(close(tracks[0].x[0], 0.4667289437082471, 1e-13));
    assert!(close(tracks[0].p[(0, 0)], 0.5487996212508603, 1e-13));
}

fn config(method: Method) -> Config {
    Config {
        method,
        max_exact_tracks: 64,
        max_hypotheses: 10_000_000,
    }
}

/// A 2D constant-velocity track at (e, n) with a diagonal covariance.
fn cv_track(e: f64, n: f64) -> TrackEstimate {
    TrackEstimate {
        x: dvector![e, 10.0, n, -5.0],
        p: DMatrix::from_diagonal(&dvector![400.0, 25.0, 300.0, 25.0]),
    }
}

fn position_sensor(measurements: Vec<DVector<f64>>, clutter: Clutter) -> Scan {
    Scan {
        model: SensorModel::Linear {
            h: dmatrix![1.0, 0.0, 0.0, 0.0; 0.0, 0.0, 1.0, 0.0],
            r: dmatrix![100.0, 0.0; 0.0, 100.0],
        },
        measurements,
        detection_probability: 0.9,
        gate: Gate::from_probability(2, 0.99).unwrap(),
        clutter,
    }
}

fn random_problem() -> impl Strategy<Value = ClusterProblem> {
    (1usize..=5, 0usize..=6, any::<bool>()).prop_flat_map(|(n, m, nonparametric)| {
        let gate = proptest::collection::vec((any::<bool>(), 0.01f64..10.0), m);
        (
            proptest::collection::vec(gate, n),
            proptest::collection::vec(0.01f64..2.0, n),
        )
            .prop_map(move |(gates, miss)| ClusterProblem {
                measurements: m,
                gates: gates
                    .into_iter()
                    .map(|row| {
                        row.into_iter()
                            .enumerate()
                            .filter(|(_, (on, _))| *on)
                            .map(|(j, (_, a))| (j, a))
                            .collect()
                    })
                    .collect(),
                miss,
                count_factor: nonparametric.then(|| nonparametric_count_factor(m, n)),
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn exact_equals_naive_enumeration(p in random_problem()) {
        let e = exact_marginals(&p, u64::MAX).unwrap();
        let n = naive_marginals(&p);
        for (re, rn) in e.beta.iter().zip(&n.beta) {
            let sum: f64 = re.iter().sum();
            prop_assert!((sum - 1.0).abs() < 1e-12, "row sum {}", sum);
            for (x, y) in re.iter().zip(rn) {
                prop_assert!((x - y).abs() < 1e-12, "{} vs {}", x, y);
            }
        }
        // Merging never does more work than enumerating.
        prop_assert!(e.hypotheses <= n.hypotheses * p.gates.len() as u64);
    }

    #[test]
    fn amsjpda_equals_exact_when_clusters_hold_one_target(
        offsets in proptest::collection::vec((-30.0f64..30.0, -30.0f64..30.0), 1..6),
        clutter in proptest::collection::vec((-60.0f64..60.0, -60.0f64..60.0), 0..4),
        nonparametric in any::<bool>(),
    ) {
        // Targets 10 km apart: every gate (≈ 90 m) holds measurements of one target only.
        let k = offsets.len();
        let truth: Vec<(f64, f64)> = (0..k).map(|i| (10_000.0 * i as f64, 0.0)).collect();
        let mut z = Vec::new();
        for (i, &(dx, dy)) in offsets.iter().enumerate() {
            z.push(dvector![truth[i].0 + dx, truth[i].1 + dy]);
            if let Some(&(cx, cy)) = clutter.get(i) {
                z.push(dvector![truth[i].0 + cx, truth[i].1 + cy]);
            }
        }
        let c = if nonparametric { Clutter::GateVolume } else { Clutter::Density(1e-5) };
        let s = position_sensor(z, c);
        let mut exact: Vec<_> = truth.iter().map(|&(e, n)| cv_track(e, n)).collect();
        let mut approx = exact.clone();
        let re = scan(&mut exact, &s, &config(Method::Exact)).unwrap();
        let ra = scan(&mut approx, &s, &config(Method::Amsjpda)).unwrap();
        prop_assert!(re.clusters.iter().all(|c| c.tracks.len() == 1));
        for (a, b) in re.associations.iter().zip(&ra.associations) {
            prop_assert!((a.miss - b.miss).abs() < 1e-12);
            for (x, y) in a.measurements.iter().zip(&b.measurements) {
                prop_assert_eq!(x.0, y.0);
                prop_assert!((x.1 - y.1).abs() < 1e-12);
            }
        }
        for (a, b) in exact.iter().zip(&approx) {
            prop_assert!((&a.x - &b.x).amax() < 1e-9);
            prop_assert!((&a.p - &b.p).amax() < 1e-9);
        }
    }

    #[test]
    fn covariances_stay_symmetric_positive_definite(
        positions in proptest::collection::vec((-100.0f64..100.0, -100.0f64..100.0), 1..6),
        measurements in proptest::collection::vec((-150.0f64..150.0, -150.0f64..150.0), 0..8),
        method in prop_oneof![Just(Method::Exact), Just(Method::Amsjpda),
                              Just(Method::NearestNeighbour), Just(Method::GlobalNearestNeighbour)],
    ) {
        // A dense scene: every track gates many measurements.
        let mut tracks: Vec<_> = positions.iter().map(|&(e, n)| cv_track(e, n)).collect();
        let z = measurements.iter().map(|&(e, n)| dvector![e, n]).collect();
        let report = scan(&mut tracks, &position_sensor(z, Clutter::Density(1e-4)), &config(method)).unwrap();
        for (t, a) in tracks.iter().zip(&report.associations) {
            let sum: f64 = a.miss + a.measurements.iter().map(|m| m.1).sum::<f64>();
            prop_assert!((sum - 1.0).abs() < 1e-12);
            prop_assert!((&t.p - t.p.transpose()).amax() == 0.0);
            prop_assert!(t.p.clone().cholesky().is_some());
        }
    }
}

#[test]
fn sequential_with_one_sensor_equals_single_sensor() {
    let z = vec![
        dvector![5.0, -3.0],
        dvector![40.0, 10.0],
        dvector![90.0, 0.0],
    ];
    let s = position_sensor(z, Clutter::Density(1e-4));
    let start = vec![cv_track(0.0, 0.0), cv_track(60.0, 0.0)];
    let mut single = start.clone();
    let one = scan(&mut single, &s, &config(Method::Exact)).unwrap();
    let mut seq = start.clone();
    let reports = update(&mut seq, std::slice::from_ref(&s), &config(Method::Exact)).unwrap();
    assert_eq!(reports, vec![one]);
    assert_eq!(seq, single);
    // A second sensor without measurements: every track misses, nothing changes.
    let mut seq2 = start;
    let empty = position_sensor(Vec::new(), Clutter::Density(1e-4));
    let reports = update(&mut seq2, &[s, empty], &config(Method::Exact)).unwrap();
    assert_eq!(seq2, single);
    assert!(reports[1].associations.iter().all(|a| a.miss == 1.0));
}

#[test]
fn second_sensor_refines_the_first_estimate() {
    // Eqs. 8–10: sensor 2 starts from the estimate X̂_1 left by sensor 1
    // (not from the prediction), so the sequential update equals two
    // single-sensor scans applied one after the other.
    let z1 = vec![dvector![5.0, -3.0]];
    let z2 = vec![dvector![7.0, -1.0]];
    let s1 = position_sensor(z1, Clutter::Density(1e-4));
    let s2 = position_sensor(z2, Clutter::Density(1e-4));
    let mut by_hand = vec![cv_track(0.0, 0.0)];
    scan(&mut by_hand, &s1, &config(Method::Exact)).unwrap();
    scan(&mut by_hand, &s2, &config(Method::Exact)).unwrap();
    let mut seq = vec![cv_track(0.0, 0.0)];
    update(&mut seq, &[s1, s2], &config(Method::Exact)).unwrap();
    assert_eq!(seq, by_hand);
    assert!(seq[0].p[(0, 0)] < 400.0 * 0.5);
}

#[test]
fn nearest_and_global_nearest_neighbour() {
    // Tracks at e = 0 and e = 16 (same n); S = P_pos + R = 500 in e.
    let z = vec![dvector![14.0, 0.0], dvector![17.0, 0.0]];
    let s = position_sensor(z, Clutter::Density(1e-4));
    let start = vec![cv_track(0.0, 0.0), cv_track(16.0, 0.0)];
    let mut nn = start.clone();
    let r = scan(&mut nn, &s, &config(Method::NearestNeighbour)).unwrap();
    // NN: track 0 → 14 (|14| < |17|), track 1 → 17 (|1| < |2|).
    assert_eq!(r.associations[0].measurements, vec![(0, 1.0), (1, 0.0)]);
    assert_eq!(r.associations[1].measurements, vec![(0, 0.0), (1, 1.0)]);
    let s2 = position_sensor(
        vec![dvector![15.0, 0.0], dvector![40.0, 0.0]],
        Clutter::Density(1e-4),
    );
    let start = vec![cv_track(0.0, 0.0), cv_track(16.0, 0.0)];
    let mut nn = start.clone();
    let r = scan(&mut nn, &s2, &config(Method::NearestNeighbour)).unwrap();
    // Both take 15 under NN (distances 15 and 1; 40 is 40 and 24 away).
    assert_eq!(r.associations[0].measurements[0], (0, 1.0));
    assert_eq!(r.associations[1].measurements[0], (0, 1.0));
    let mut gnn = start;
    let r = scan(&mut gnn, &s2, &config(Method::GlobalNearestNeighbour)).unwrap();
    // GNN: d²/S with S = 500 (x): {0→15, 1→40}: (225 + 576)/500 = 1.6;
    // {0→40, 1→15}: (1600 + 1)/500 = 3.2 (and 40 may be outside track 0's gate);
    // so track 0 takes 15 and track 1 takes 40 (or misses).
    assert_eq!(r.associations[0].measurements[0], (0, 1.0));
    assert!(
        r.associations[1]
            .measurements
            .iter()
            .all(|&(j, b)| j != 0 || b == 0.0)
    );
}

#[test]
fn cluster_guard_falls_back_to_amsjpda() {
    let z = vec![
        dvector![5.0, -3.0],
        dvector![10.0, 10.0],
        dvector![20.0, 0.0],
    ];
    let s = position_sensor(z, Clutter::Density(1e-4));
    let mut tracks = vec![cv_track(0.0, 0.0), cv_track(15.0, 0.0), cv_track(30.0, 0.0)];
    let mut cfg = config(Method::Exact);
    cfg.max_exact_tracks = 2;
    let r = scan(&mut tracks, &s, &cfg).unwrap();
    assert_eq!(r.clusters.len(), 1);
    assert_eq!(r.clusters[0].method, Method::Amsjpda);
    assert_eq!(r.clusters[0].fallback, Some(Fallback::TooManyTracks));
    cfg.max_exact_tracks = 64;
    cfg.max_hypotheses = 3;
    let r = scan(&mut tracks, &s, &cfg).unwrap();
    assert_eq!(r.clusters[0].fallback, Some(Fallback::TooManyHypotheses));
}

#[test]
fn polar_sensor_updates_by_ekf() {
    // A target 10 km north of a radar at the origin; a plot exactly at the
    // prediction leaves the state unchanged and shrinks the covariance.
    let mut tracks = vec![TrackEstimate {
        x: dvector![0.0, 0.0, 10_000.0, 0.0],
        p: DMatrix::from_diagonal(&dvector![10_000.0, 100.0, 10_000.0, 100.0]),
    }];
    let s = Scan {
        model: SensorModel::Polar {
            site: [0.0, 0.0, 0.0],
            layout: PositionLayout::CV_2D,
            sigma_range: 50.0,
            sigma_azimuth: 0.002,
            sigma_elevation: None,
            sigma_range_rate: None,
        },
        measurements: vec![dvector![10_000.0, 2.0 * std::f64::consts::PI - 1e-12]],
        detection_probability: 0.9,
        gate: Gate::from_probability(2, 0.99).unwrap(),
        clutter: Clutter::GateVolume,
    };
    let r = scan(&mut tracks, &s, &config(Method::Exact)).unwrap();
    // Azimuth 2π − ε wraps to an innovation of −ε: gated, single measurement, one track.
    assert_eq!(r.associations[0].measurements.len(), 1);
    assert!(tracks[0].x[0].abs() < 1e-6 && (tracks[0].x[2] - 10_000.0).abs() < 1e-6);
    assert!(tracks[0].p[(2, 2)] < 10_000.0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The sorted first-component pruning of the gate never changes Ω:
    /// the gated sets equal a brute-force ν' S⁻¹ ν ≤ γ over every pair.
    #[test]
    fn pruned_gating_equals_brute_force(
        positions in proptest::collection::vec((-300.0f64..300.0, -300.0f64..300.0), 1..6),
        measurements in proptest::collection::vec((-400.0f64..400.0, -400.0f64..400.0), 0..20),
    ) {
        let tracks: Vec<_> = positions.iter().map(|&(e, n)| cv_track(e, n)).collect();
        let z: Vec<DVector<f64>> = measurements.iter().map(|&(e, n)| dvector![e, n]).collect();
        let s = position_sensor(z.clone(), Clutter::Density(1e-4));
        let mut updated = tracks.clone();
        let report = scan(&mut updated, &s, &config(Method::Amsjpda)).unwrap();
        let SensorModel::Linear { h, r } = &s.model else { unreachable!() };
        for (t, a) in tracks.iter().zip(&report.associations) {
            let cov = h * &t.p * h.transpose() + r;
            let inv = cov.try_inverse().unwrap();
            let brute: Vec<usize> = z
                .iter()
                .enumerate()
                .filter(|(_, zj)| {
                    let nu = *zj - h * &t.x;
                    (nu.transpose() * &inv * &nu)[(0, 0)] <= s.gate.threshold
                })
                .map(|(j, _)| j)
                .collect();
            let gated: Vec<usize> = a.measurements.iter().map(|m| m.0).collect();
            prop_assert_eq!(gated, brute);
        }
    }
}
