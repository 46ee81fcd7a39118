//! Performance measures: track-to-track correlation rates (E_c, E_e, E_s of
//! seed 000 §5.2), the correct association rate of measurement-to-track
//! association, position RMSE, NEES with its χ² consistency bounds, and the
//! OSPA and GOSPA distances between track sets.

use std::collections::{HashMap, HashSet};

use nalgebra::{DMatrix, DVector};

use super::SimError;
use algo::gating::chi2_threshold;
use algo::gaussian::mahalanobis_sq;

/// Counts of true pairs by outcome at one evaluation time (or summed over
/// several). The rates are `correct / pairs` etc.
///
/// Definition used throughout (seed 000 §5.2 names E_c, E_e, E_s without
/// defining them): at an evaluation time, every target held by both nodes is
/// one *true pair* (its node-1 track a, its node-2 track b). For the method's
/// output set of pairs:
/// - **error** if a or b is paired with a track of another target (or with a
///   track the truth does not know);
/// - otherwise **correct** if (a, b) is in the output;
/// - otherwise **missed** (neither a nor b is paired).
///
/// Each true pair falls in exactly one class, so E_c + E_e + E_s = 1.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CorrelationCounts {
    /// True pairs output exactly.
    pub correct: usize,
    /// True pairs with a track paired to another target's track.
    pub error: usize,
    /// True pairs left unpaired.
    pub missed: usize,
}

impl CorrelationCounts {
    /// Number of true pairs.
    pub fn pairs(&self) -> usize {
        self.correct + self.error + self.missed
    }

    /// E_c (0 when there are no pairs).
    pub fn correct_rate(&self) -> f64 {
        ratio(self.correct, self.pairs())
    }

    /// E_e.
    pub fn error_rate(&self) -> f64 {
        ratio(self.error, self.pairs())
    }

    /// E_s.
    pub fn missed_rate(&self) -> f64 {
        ratio(self.missed, self.pairs())
    }

    /// Adds another count.
    pub fn add(&mut self, o: &CorrelationCounts) {
        self.correct += o.correct;
        self.error += o.error;
        self.missed += o.missed;
    }
}

/// Scores one output of a correlator. `truth1` and `truth2` map the local
/// track ids present at this time in node 1 and node 2 to their targets;
/// `pairs` are the (node-1 id, node-2 id) pairs the method declared.
pub fn score_correlation(
    truth1: &HashMap<u32, usize>,
    truth2: &HashMap<u32, usize>,
    pairs: &[(u32, u32)],
) -> CorrelationCounts {
    let target_of_2: HashMap<usize, u32> = truth2.iter().map(|(&id, &k)| (k, id)).collect();
    // Tracks paired with a track of another (or an unknown) target.
    let mut wrong1: HashSet<u32> = HashSet::new();
    let mut wrong2: HashSet<u32> = HashSet::new();
    let mut right: HashSet<(u32, u32)> = HashSet::new();
    for &(a, b) in pairs {
        match (truth1.get(&a), truth2.get(&b)) {
            (Some(ka), Some(kb)) if ka == kb => {
                right.insert((a, b));
            }
            _ => {
                wrong1.insert(a);
                wrong2.insert(b);
            }
        }
    }
    let mut c = CorrelationCounts::default();
    for (&a, k) in truth1 {
        let Some(&b) = target_of_2.get(k) else {
            continue; // the target is not held by node 2: not a true pair
        };
        if wrong1.contains(&a) || wrong2.contains(&b) {
            c.error += 1;
        } else if right.contains(&(a, b)) {
            c.correct += 1;
        } else {
            c.missed += 1;
        }
    }
    c
}

/// Correct association rate of one scan of measurement-to-track
/// association: for each track (whose target was detected this scan), its
/// target and the origin of the plot it was given (`None` for no plot or a
/// false alarm). The rate is the fraction given their own target's plot;
/// 0 for an empty scan.
pub fn correct_association_rate(assignments: &[(usize, Option<usize>)]) -> f64 {
    let good = assignments.iter().filter(|(t, o)| Some(*t) == *o).count();
    ratio(good, assignments.len())
}

/// Root mean square of Euclidean errors: √(Σ|e|² / n); 0 for no samples.
pub fn rmse(squared_errors_sum: f64, samples: usize) -> f64 {
    if samples == 0 {
        0.0
    } else {
        (squared_errors_sum / samples as f64).sqrt()
    }
}

/// Normalised estimation error squared e' P⁻¹ e (Cholesky).
pub fn nees(error: &DVector<f64>, p: &DMatrix<f64>) -> Result<f64, SimError> {
    Ok(mahalanobis_sq(error, p)?)
}

/// Two-sided `confidence` interval of the average NEES of `samples`
/// independent `dim`-dimensional consistent estimates: the average is
/// χ²(dim·samples)/samples, so the bounds are its (1 ∓ confidence)/2
/// quantiles divided by `samples` (Bar-Shalom, Li & Kirubarajan §5.4).
pub fn nees_bounds(dim: usize, samples: usize, confidence: f64) -> Result<(f64, f64), SimError> {
    let dof = dim * samples;
    let tail = (1.0 - confidence) / 2.0;
    let lo = chi2_threshold(dof, 1.0 - tail)?;
    let hi = chi2_threshold(dof, tail)?;
    Ok((lo / samples as f64, hi / samples as f64))
}

/// OSPA distance (Schuhmacher, Vo & Vo 2008) between point sets `x` and `y`
/// with cut-off `c` > 0 and order `p` ≥ 1: with m = |x| ≤ n = |y| (else
/// swap), d = ((min_π Σ min(d(x_i, y_π(i)), c)^p + c^p (n − m)) / n)^{1/p};
/// 0 when both are empty.
pub fn ospa(x: &[Vec<f64>], y: &[Vec<f64>], c: f64, p: f64) -> f64 {
    let (small, big) = if x.len() <= y.len() { (x, y) } else { (y, x) };
    let n = big.len();
    if n == 0 {
        return 0.0;
    }
    let (cost, _) = optimal_cut_assignment(small, big, c, p);
    ((cost + c.powf(p) * (n - small.len()) as f64) / n as f64).powf(1.0 / p)
}

/// GOSPA with α = 2 and its decomposition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gospa {
    /// The distance.
    pub distance: f64,
    /// Σ d^p over the assigned pairs (the localisation part, before the 1/p root).
    pub localisation: f64,
    /// Truth points left unassigned.
    pub missed: usize,
    /// Estimates left unassigned.
    pub false_tracks: usize,
}

/// GOSPA (Rahmathullah, García-Fernández & Svensson 2017) with α = 2
/// between truth `x` and estimates `y`, cut-off `c`, order `p`:
/// d^p = min over assignments γ of Σ_{(i,j)∈γ} d(x_i, y_j)^p +
/// (c^p/2)(|x| + |y| − 2|γ|), where only pairs closer than `c` are assigned.
pub fn gospa(x: &[Vec<f64>], y: &[Vec<f64>], c: f64, p: f64) -> Gospa {
    let (small, big) = if x.len() <= y.len() { (x, y) } else { (y, x) };
    let (_, assignment) = optimal_cut_assignment(small, big, c, p);
    let mut localisation = 0.0;
    let mut assigned = 0usize;
    for (i, &j) in assignment.iter().enumerate() {
        let d = dist(&small[i], &big[j]);
        if d < c {
            localisation += d.powf(p);
            assigned += 1;
        }
    }
    let (nx, ny) = (x.len(), y.len());
    let missed = nx - assigned;
    let false_tracks = ny - assigned;
    let total = localisation + c.powf(p) / 2.0 * (missed + false_tracks) as f64;
    Gospa {
        distance: total.powf(1.0 / p),
        localisation,
        missed,
        false_tracks,
    }
}

/// Optimal assignment of `small` into `big` under min(d, c)^p; returns the
/// total cut cost and the column of each row.
fn optimal_cut_assignment(
    small: &[Vec<f64>],
    big: &[Vec<f64>],
    c: f64,
    p: f64,
) -> (f64, Vec<usize>) {
    let cols = big.len();
    let cost: Vec<f64> = small
        .iter()
        .flat_map(|s| big.iter().map(move |b| dist(s, b).min(c).powf(p)))
        .collect();
    let a = algo::assignment::dense(&cost, small.len(), cols);
    let total = a.iter().enumerate().map(|(i, &j)| cost[i * cols + j]).sum();
    (total, a)
}

fn dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 { 0.0 } else { a as f64 / b as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(v: &[[f64; 2]]) -> Vec<Vec<f64>> {
        v.iter().map(|p| p.to_vec()).collect()
    }

    #[test]
    fn correlation_classes_partition_the_true_pairs() {
        // Node 1 ids 10, 11, 12, 13 hold targets 0, 1, 2, 3; node 2 ids 20,
        // 21, 22, 24 hold targets 0, 1, 2, 4. True pairs: (10,20), (11,21),
        // (12,22); target 3 and 4 are held by one node only.
        let t1: HashMap<u32, usize> = [(10, 0), (11, 1), (12, 2), (13, 3)].into();
        let t2: HashMap<u32, usize> = [(20, 0), (21, 1), (22, 2), (24, 4)].into();
        // (10,20) right; (11,24) wrong → pair of target 1 is an error;
        // (13,22): node-2 track of target 2 taken by target 3's track → error.
        let c = score_correlation(&t1, &t2, &[(10, 20), (11, 24), (13, 22)]);
        assert_eq!(
            c,
            CorrelationCounts {
                correct: 1,
                error: 2,
                missed: 0
            }
        );
        // Nothing output: all three missed.
        let c = score_correlation(&t1, &t2, &[]);
        assert_eq!((c.missed, c.pairs()), (3, 3));
        // A right pair plus a second partner for the same track is an error.
        let c = score_correlation(&t1, &t2, &[(10, 20), (10, 21)]);
        assert_eq!((c.correct, c.error, c.missed), (0, 2, 1));
        assert!((c.correct_rate() + c.error_rate() + c.missed_rate() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn association_rate_counts_own_plots() {
        let a = [(0, Some(0)), (1, Some(2)), (2, None), (3, Some(3))];
        assert_eq!(correct_association_rate(&a), 0.5);
        assert_eq!(correct_association_rate(&[]), 0.0);
    }

    #[test]
    fn rmse_and_nees_by_hand() {
        // Errors (3,4) and (0,0): Σ|e|² = 25, n = 2, RMSE = √12.5.
        assert_eq!(rmse(25.0, 2), 12.5f64.sqrt());
        // e = (2, 1), P = diag(4, 1): 4/4 + 1/1 = 2.
        let p = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 1.0]));
        let v = nees(&DVector::from_vec(vec![2.0, 1.0]), &p).unwrap();
        assert!((v - 2.0).abs() < 1e-12);
    }

    #[test]
    fn nees_bounds_for_one_sample_are_chi2_quantiles() {
        // dim 2, one sample, 95 %: χ²₂ quantiles are −2 ln(1 − q):
        // q = 0.025 → 0.050636, q = 0.975 → 7.377759.
        let (lo, hi) = nees_bounds(2, 1, 0.95).unwrap();
        assert!((lo - 0.050_635_615_968_579_8).abs() < 1e-9, "{lo}");
        assert!((hi - 7.377_758_908_227_871).abs() < 1e-9, "{hi}");
    }

    #[test]
    fn ospa_and_gospa_on_hand_built_sets() {
        // One pair at distance 5 (3-4-5), c = 10, p = 1: both give 5.
        let x = pts(&[[0.0, 0.0]]);
        let y = pts(&[[3.0, 4.0]]);
        assert!((ospa(&x, &y, 10.0, 1.0) - 5.0).abs() < 1e-12);
        let g = gospa(&x, &y, 10.0, 1.0);
        assert!((g.distance - 5.0).abs() < 1e-12);
        assert_eq!((g.missed, g.false_tracks), (0, 0));

        // X = {(0,0), (10,0)}, Y = {(1,0)}, c = 5, p = 2.
        // OSPA: n = 2, best pair d = 1: ((1 + 25·1)/2)^{1/2} = √13.
        // GOSPA: 1 + (25/2)·(2 + 1 − 2) = 13.5 → √13.5; one missed.
        let x = pts(&[[0.0, 0.0], [10.0, 0.0]]);
        let y = pts(&[[1.0, 0.0]]);
        assert!((ospa(&x, &y, 5.0, 2.0) - 13f64.sqrt()).abs() < 1e-12);
        assert!((ospa(&y, &x, 5.0, 2.0) - 13f64.sqrt()).abs() < 1e-12);
        let g = gospa(&x, &y, 5.0, 2.0);
        assert!((g.distance - 13.5f64.sqrt()).abs() < 1e-12);
        assert_eq!((g.localisation, g.missed, g.false_tracks), (1.0, 1, 0));
        // Swapped roles: the extra point is now a false track.
        let g = gospa(&y, &x, 5.0, 2.0);
        assert_eq!((g.missed, g.false_tracks), (0, 1));

        // Beyond the cut-off: OSPA = c; GOSPA = (c/2·(1 + 1))^{1} = c, and
        // the pair counts as one missed and one false.
        let x = pts(&[[0.0, 0.0]]);
        let y = pts(&[[100.0, 0.0]]);
        assert!((ospa(&x, &y, 10.0, 1.0) - 10.0).abs() < 1e-12);
        let g = gospa(&x, &y, 10.0, 1.0);
        assert!((g.distance - 10.0).abs() < 1e-12);
        assert_eq!((g.localisation, g.missed, g.false_tracks), (0.0, 1, 1));

        // Empty sets: 0; one empty: OSPA = c, GOSPA = (c^p/2 · n)^{1/p}.
        assert_eq!(ospa(&[], &[], 10.0, 2.0), 0.0);
        assert_eq!(gospa(&[], &[], 10.0, 2.0).distance, 0.0);
        let y = pts(&[[0.0, 0.0], [1.0, 1.0]]);
        assert!((ospa(&[], &y, 10.0, 2.0) - 10.0).abs() < 1e-12);
        assert!((gospa(&[], &y, 10.0, 2.0).distance - 100f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn ospa_uses_the_optimal_not_the_greedy_assignment() {
        // X = {0, 2}, Y = {1.9, 4} on a line, c = 10, p = 2. Greedy takes the
        // closest pair (2, 1.9) then (0, 4): 0.01 + 16 = 16.01. The optimum
        // is (0, 1.9), (2, 4): 3.61 + 4 = 7.61, so OSPA = √(7.61/2).
        let x = pts(&[[0.0, 0.0], [2.0, 0.0]]);
        let y = pts(&[[1.9, 0.0], [4.0, 0.0]]);
        assert!((ospa(&x, &y, 10.0, 2.0) - (7.61f64 / 2.0).sqrt()).abs() < 1e-12);
        assert!((gospa(&x, &y, 10.0, 2.0).distance - 7.61f64.sqrt()).abs() < 1e-12);
    }
}
