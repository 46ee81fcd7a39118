use super::*;
use crate::motion::{ConstantVelocity, ProcessNoise};
use proptest::prelude::*;

/// Position-only 2-D tracks with P = I: S = 2I for the weighted statistic,
/// so α = ‖d‖²/2, and δ = χ²₂(0.05) = −2 ln 0.05 = 5.991…: a pair passes
/// when ‖d‖² ≤ 11.98.
fn scene(instants: usize, a: &[Vec<Option<[f64; 2]>>], b: &[Vec<Option<[f64; 2]>>]) -> Scene {
    let times: Vec<f64> = (0..instants).map(|k| 4.0 * k as f64).collect();
    let mut s = Scene::new(2, vec![0, 1], times).unwrap();
    for node in [a, b] {
        let tracks = node
            .iter()
            .map(|samples| {
                let mut t = Track::new(instants, 2);
                for (k, x) in samples.iter().enumerate() {
                    if let Some(x) = x {
                        t.set(k, x, &[1.0, 0.0, 0.0, 1.0]);
                    }
                }
                t
            })
            .collect();
        s.add_node(tracks).unwrap();
    }
    s
}

const NEAR: Option<[f64; 2]> = Some([1.0, 0.0]); // α = 0.5, passes
const FAR: Option<[f64; 2]> = Some([10.0, 0.0]); // α = 50, fails
const ORIGIN: Option<[f64; 2]> = Some([0.0, 0.0]);

fn dt(l: u32, r: u32) -> Config {
    Config {
        method: Method::DoubleThreshold {
            rules: RuleSpec::Fixed(LrRule::new(l, r).unwrap()),
            resolution: Resolution::Greedy,
        },
        statistic: Statistic::Weighted,
        alpha: 0.05,
        pruning: Pruning::Grid,
    }
}

fn run(s: &Scene, cfg: &Config) -> Vec<PairReport> {
    let mut c = PairCorrelator::new(s, 0, 1, cfg, None).unwrap();
    c.run().unwrap();
    c.reports()
}

#[test]
fn weighted_statistic_by_hand() {
    // x_a = (0, 0), x_b = (1, 2), P = I each: α = (1² + 2²)/2 = 2.5.
    let s = scene(1, &[vec![ORIGIN]], &[vec![Some([1.0, 2.0])]]);
    let r = run(&s, &dt(1, 1));
    assert!((r[0].last_statistic - 2.5).abs() < 1e-15);
    assert_eq!(r[0].decision, Decision::Correlated);
    assert_eq!(r[0].reason, Reason::Threshold);
}

#[test]
fn counting_and_early_stop_step_by_step() {
    // Rule 3/4 allows R − L = 1 failure. Samples: pass, fail, fail.
    // l=1: m=1, C=0; l=2: m=1, C=1; l=3: C=2 > 1 → early stop (eq. 16).
    let s = scene(3, &[vec![ORIGIN; 3]], &[vec![NEAR, FAR, FAR]]);
    let cfg = dt(3, 4);
    let mut c = PairCorrelator::new(&s, 0, 1, &cfg, None).unwrap();
    c.step().unwrap();
    let r = c.reports();
    assert_eq!((r[0].m, r[0].c, r[0].reason), (1, 0, Reason::Testing));
    assert!(
        r[0].trial,
        "the only pair with m ≥ 1 is a trial system track"
    );
    c.step().unwrap();
    let r = c.reports();
    assert_eq!((r[0].m, r[0].c, r[0].decision), (1, 1, Decision::Undecided));
    c.step().unwrap();
    let r = c.reports();
    assert_eq!((r[0].m, r[0].c, r[0].samples), (1, 2, 3));
    assert_eq!(
        (r[0].decision, r[0].reason),
        (Decision::NotCorrelated, Reason::EarlyStop)
    );
}

#[test]
fn early_decision_when_m_reaches_l_without_competitor() {
    // Rule 2/4: pass, pass → m = 2 ≥ L at l = 2 < R (eq. 17), unique.
    let s = scene(2, &[vec![ORIGIN; 2]], &[vec![NEAR, NEAR]]);
    let r = run(&s, &dt(2, 4));
    assert_eq!(
        (r[0].decision, r[0].reason),
        (Decision::Correlated, Reason::EarlyDecision)
    );
    assert_eq!(r[0].decided_at, Some(1));
}

#[test]
fn ambiguity_at_l_equals_r_by_max_m() {
    // Rule 3/4. a0–b0: 4 passes; a0–b1: 3 passes then a failure. Both
    // reach m = 3 at l = 3 (not unique: no early decision). At l = 4,
    // m = 4 beats m = 3 (eq. 18).
    let s = scene(
        4,
        &[vec![ORIGIN; 4]],
        &[
            vec![NEAR; 4],
            vec![Some([0.0, 1.0]), Some([0.0, 1.0]), Some([0.0, 1.0]), FAR],
        ],
    );
    let r = run(&s, &dt(3, 4));
    assert_eq!(
        (r[0].decision, r[0].reason),
        (Decision::Correlated, Reason::AmbiguityMaxM)
    );
    assert_eq!(
        (r[1].decision, r[1].reason),
        (Decision::NotCorrelated, Reason::AmbiguityLost)
    );
}

#[test]
fn ambiguity_at_l_equals_r_by_min_mean_statistic() {
    // Rule 2/2, both pairs pass twice (m = 2). Mean statistics: b0 at
    // distance 1 → α = 0.5; b1 at distance 2 → α = 2 (eq. 19): b0 wins.
    let s = scene(
        2,
        &[vec![ORIGIN; 2]],
        &[vec![Some([2.0, 0.0]); 2], vec![NEAR; 2]],
    );
    let r = run(&s, &dt(2, 2));
    assert_eq!((r[1].b, r[1].decision), (1, Decision::Correlated));
    assert_eq!(r[1].reason, Reason::AmbiguityMinMeanStatistic);
    assert!((r[1].mean_statistic - 0.5).abs() < 1e-15);
    assert_eq!(r[0].reason, Reason::AmbiguityLost);
    assert!((r[0].mean_statistic - 2.0).abs() < 1e-15);
}

#[test]
fn trial_system_track_by_max_m_then_min_c_then_position() {
    // Rule 6/8 after three samples: a0–b0 passes 3 times (m=3),
    // a0–b1 passes twice (m=2): the trial pair is a0–b0 (max m, eq. 21).
    let s = scene(
        3,
        &[vec![ORIGIN; 3]],
        &[vec![NEAR; 3], vec![NEAR, NEAR, FAR]],
    );
    let r = run(&s, &dt(6, 8));
    assert!(r[0].trial && !r[1].trial);
    assert_eq!(r[0].decision, Decision::Undecided);
    // Equal m and C: the smaller mean position difference wins.
    let s = scene(
        2,
        &[vec![ORIGIN; 2]],
        &[vec![Some([2.0, 0.0]); 2], vec![NEAR; 2]],
    );
    let r = run(&s, &dt(6, 8));
    assert!(!r[0].trial && r[1].trial);
}

#[test]
fn trial_system_track_prefers_the_smaller_departure_quality_on_equal_m() {
    // Rule 6/8 after three instants. a0–b0: passes at d = 0.5, 0.5 and
    // fails at d = 4 (α = 8 > 5.99): m = 2, C = 1, mean ‖Δpos‖ = 5/3.
    // a0–b1 (b1 appears at instant 1): passes twice at d = 3 (α = 4.5):
    // m = 2, C = 0, mean ‖Δpos‖ = 3. Equal m, so the smaller C wins
    // (eq. 21's second criterion) although b0 is closer on average.
    let half = Some([0.5, 0.0]);
    let three = Some([3.0, 0.0]);
    let s = scene(
        3,
        &[vec![ORIGIN; 3]],
        &[vec![half, half, Some([4.0, 0.0])], vec![None, three, three]],
    );
    let r = run(&s, &dt(6, 8));
    assert_eq!((r[0].m, r[0].c, r[1].m, r[1].c), (2, 1, 2, 0));
    assert!(!r[0].trial && r[1].trial);
}

#[test]
fn classic_test_is_one_of_one_and_revokes_at_the_first_failure() {
    let s = scene(2, &[vec![ORIGIN; 2]], &[vec![NEAR, FAR]]);
    let cfg = dt(1, 1);
    let mut c = PairCorrelator::new(&s, 0, 1, &cfg, None).unwrap();
    c.step().unwrap();
    assert_eq!(c.correlated().collect::<Vec<_>>(), vec![(0, 0)]);
    c.step().unwrap();
    assert!(c.correlated().next().is_none());
    assert_eq!(c.reports()[0].reason, Reason::Revoked);
}

#[test]
fn schedule_decides_as_samples_accumulate() {
    // Default schedule: after one sample 1/1 applies, so a passing pair
    // is correlated at once.
    let s = scene(1, &[vec![ORIGIN]], &[vec![NEAR]]);
    let cfg = Config {
        method: Method::DoubleThreshold {
            rules: RuleSpec::Schedule(default_schedule()),
            resolution: Resolution::Greedy,
        },
        ..dt(1, 1)
    };
    let r = run(&s, &cfg);
    assert_eq!(
        (r[0].decision, r[0].reason),
        (Decision::Correlated, Reason::Threshold)
    );
}

#[test]
fn modified_statistic_uses_the_cross_covariance_recursion() {
    // State [x, vx], P_a = P_b = 10 I, reported I − K H = I (no update),
    // CV model with DWNA σ_a = 1 over dt = 2: Γ = [2, 2]', Q = [[4, 4], [4, 4]].
    // First instant: P_ab = 0, so β = α = d'(20 I)⁻¹d = 1/20 for d = (1, 0).
    // Second instant: P_ab = I (Φ·0·Φ' + Q) I = Q, S = 20 I − 2Q
    // = [[12, −8], [−8, 12]], S⁻¹₁₁ = 12/(144 − 64) = 0.15, so β = 0.15.
    let times = vec![0.0, 2.0];
    let mut s = Scene::new(2, vec![0], times).unwrap();
    for x in [[0.0, 0.0], [1.0, 0.0]] {
        let mut t = Track::new(2, 2);
        for k in 0..2 {
            t.set(k, &x, &[10.0, 0.0, 0.0, 10.0]);
            t.set_gain_factor(k, &[1.0, 0.0, 0.0, 1.0]);
        }
        s.add_node(vec![t]).unwrap();
    }
    let model = ConstantVelocity::new(1, ProcessNoise::Dwna { sigma_a: 1.0 }).unwrap();
    let cfg = Config {
        statistic: Statistic::Modified,
        ..dt(2, 2)
    };
    let mut c = PairCorrelator::new(&s, 0, 1, &cfg, Some(&model)).unwrap();
    c.step().unwrap();
    assert!((c.reports()[0].last_statistic - 0.05).abs() < 1e-15);
    c.step().unwrap();
    let r = &c.reports()[0];
    assert!(
        (r.last_statistic - 0.15).abs() < 1e-14,
        "{}",
        r.last_statistic
    );
    let p12 = r.cross_covariance.as_ref().unwrap();
    assert_eq!(p12, &vec![4.0, 4.0, 4.0, 4.0]);
}

#[test]
fn baselines_pick_the_closest_consistent_pairs() {
    // a0 at 0, a1 at 3; b0 at 1, b1 at 2.2 (all on the x axis).
    // α: a0–b0 0.5, a0–b1 2.42, a1–b0 2, a1–b1 0.32.
    let s = scene(
        1,
        &[vec![ORIGIN], vec![Some([3.0, 0.0])]],
        &[vec![NEAR], vec![Some([2.2, 0.0])]],
    );
    for method in [
        Method::NearestNeighbour { window: 1 },
        Method::GlobalAssignment { window: 1 },
        Method::KNearestNeighbour { k: 1, window: 1 },
    ] {
        let cfg = Config { method, ..dt(1, 1) };
        let mut c = PairCorrelator::new(&s, 0, 1, &cfg, None).unwrap();
        c.run().unwrap();
        let mut got: Vec<_> = c.correlated().collect();
        got.sort();
        assert_eq!(got, vec![(0, 0), (1, 1)], "{:?}", cfg.method);
    }
}

#[test]
fn global_assignment_beats_greedy_when_greedy_is_trapped() {
    // a0 at 0; a1 at 2.4. b0 at 1.2, b1 at −1.3. Greedy takes the
    // smallest α first: a0–b0 (0.72) then a1 has only b1 at 3.7
    // (α = 6.845 > δ): one pair. Assignment: a0–b1 (0.845) + a1–b0
    // (0.72) = 1.565 in normalised form beats a0–b0 alone plus two
    // unassigned tracks.
    let s = scene(
        1,
        &[vec![ORIGIN], vec![Some([2.4, 0.0])]],
        &[vec![Some([1.2, 0.0])], vec![Some([-1.3, 0.0])]],
    );
    let greedy = Config {
        method: Method::NearestNeighbour { window: 1 },
        ..dt(1, 1)
    };
    let mut c = PairCorrelator::new(&s, 0, 1, &greedy, None).unwrap();
    c.run().unwrap();
    assert_eq!(c.correlated().collect::<Vec<_>>(), vec![(0, 0)]);
    let optimal = Config {
        method: Method::GlobalAssignment { window: 1 },
        ..dt(1, 1)
    };
    let mut c = PairCorrelator::new(&s, 0, 1, &optimal, None).unwrap();
    c.run().unwrap();
    let mut got: Vec<_> = c.correlated().collect();
    got.sort();
    assert_eq!(got, vec![(0, 1), (1, 0)]);
}

#[test]
fn the_pair_budget_refuses_co_located_tracks_while_they_are_collected() {
    // Three tracks a node, all at the origin: every one of the 3 × 3 = 9
    // pairs is inside the gate (d = 0) at the one instant.
    let node = vec![vec![ORIGIN]; 3];
    let s = scene(1, &node, &node);
    for pruning in [Pruning::Grid, Pruning::None] {
        let cfg = Config {
            pruning,
            ..dt(1, 1)
        };
        let mut c = PairCorrelator::new(&s, 0, 1, &cfg, None)
            .unwrap()
            .with_pair_budget(8);
        assert_eq!(
            c.step(),
            Err(AlgoError::BudgetExceeded {
                what: "candidate pairs",
                limit: 8
            })
        );
        assert_eq!(c.pair_count(), 0, "refused before any pair was stored");
        let mut c = PairCorrelator::new(&s, 0, 1, &cfg, None)
            .unwrap()
            .with_pair_budget(9);
        c.run().unwrap();
        assert_eq!(c.pair_count(), 9);
    }
}

#[test]
fn the_pair_budget_counts_the_pairs_of_earlier_instants() {
    // Instant 0: a0 at the origin and b0 at (1, 0) form the one candidate
    // (a1 at (100, 0) and b1 at (200, 0) are far from everything). Instant
    // 1: a0 and b0 are gone, b1 has come to (101, 0): (a1, b1) is the one
    // candidate of that instant, the second pair of the correlator.
    let a = [vec![ORIGIN, None], vec![Some([100.0, 0.0]); 2]];
    let b = [
        vec![NEAR, None],
        vec![Some([200.0, 0.0]), Some([101.0, 0.0])],
    ];
    let s = scene(2, &a, &b);
    let cfg = dt(1, 1);
    let mut c = PairCorrelator::new(&s, 0, 1, &cfg, None)
        .unwrap()
        .with_pair_budget(1);
    assert_eq!(c.step(), Ok(true));
    assert_eq!(c.pair_count(), 1);
    assert!(matches!(
        c.step(),
        Err(AlgoError::BudgetExceeded { limit: 1, .. })
    ));
    assert_eq!(c.pair_count(), 1);
    let mut c = PairCorrelator::new(&s, 0, 1, &cfg, None)
        .unwrap()
        .with_pair_budget(2);
    c.run().unwrap();
    assert_eq!(c.pair_count(), 2);
}

fn decisions(s: &Scene, cfg: &Config) -> Vec<Vec<(usize, usize)>> {
    let mut c = PairCorrelator::new(s, 0, 1, cfg, None).unwrap();
    let mut out = Vec::new();
    while c.step().unwrap() {
        let mut d: Vec<_> = c.correlated().collect();
        d.sort();
        out.push(d);
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// The spatial gate never changes a decision: the same decisions at
    /// every instant as the brute-force computation over all pairs.
    #[test]
    fn grid_pruning_equals_brute_force(
        seed_a in prop::collection::vec((0.0f64..60.0, 0.0f64..60.0, 0.5f64..3.0), 1..12),
        seed_b in prop::collection::vec((0.0f64..60.0, 0.0f64..60.0, 0.5f64..3.0), 1..12),
        jitter in prop::collection::vec(-2.0f64..2.0, 200),
        method_pick in 0usize..5,
    ) {
        let instants = 6;
        let times: Vec<f64> = (0..instants).map(|k| k as f64).collect();
        let mut s = Scene::new(2, vec![0, 1], times).unwrap();
        let mut j = 0;
        for seeds in [&seed_a, &seed_b] {
            let tracks = seeds.iter().map(|&(x, y, var)| {
                let mut t = Track::new(instants, 2);
                for k in 0..instants {
                    let (dx, dy) = (jitter[j % 200], jitter[(j + 7) % 200]);
                    j += 3;
                    t.set(k, &[x + dx, y + dy], &[var, 0.1, 0.1, var]);
                }
                t
            }).collect();
            s.add_node(tracks).unwrap();
        }
        let method = match method_pick {
            0 => Method::DoubleThreshold { rules: RuleSpec::Fixed(LrRule::new(3, 4).unwrap()), resolution: Resolution::Greedy },
            1 => Method::DoubleThreshold { rules: RuleSpec::Schedule(default_schedule()), resolution: Resolution::Assignment },
            2 => Method::NearestNeighbour { window: 3 },
            3 => Method::GlobalAssignment { window: 2 },
            _ => Method::KNearestNeighbour { k: 2, window: 3 },
        };
        let grid = Config { method: method.clone(), statistic: Statistic::Weighted, alpha: 0.05, pruning: Pruning::Grid };
        let brute = Config { pruning: Pruning::None, ..grid.clone() };
        prop_assert_eq!(decisions(&s, &grid), decisions(&s, &brute));
    }
}
