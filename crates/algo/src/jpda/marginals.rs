//! Association probabilities β_tj of one cluster (seed 002 eqs. 4–5 and
//! section 3.2), from per-track option weights.
//!
//! A [`ClusterProblem`] holds, for every track t of a cluster, the weight
//! `a_tj` of "measurement j is the target's" for each gated j and the weight
//! `b_t` of "the target was missed". The probability of a feasible joint
//! event (every measurement used at most once, every track one option) is
//! proportional to the product of the chosen weights times a factor `g(d)`
//! of the number d of detections, so the parametric and the non-parametric
//! clutter models of eq. 4 both fit:
//! - parametric (clutter density λ): a_tj = P_D N_tj / λ, b_t = 1 − P_D P_G,
//!   g ≡ 1;
//! - non-parametric (eq. 4 as printed, φ false measurements in volume V):
//!   φ!/V^φ with φ = m − d gives a_tj = P_D N_tj V/m and
//!   g(d) = m^d (m − d)!/m! (the same events, divided by the constant m!/V^m).
//!
//! Scaling all options of one track by a constant does not change β, so the
//! builder scales each track's options to a largest weight of 1.
//!
//! Three ways to get β:
//! - [`exact_marginals`]: exact, by a forward–backward pass over the tracks
//!   in which partial hypotheses that used the same still-relevant
//!   measurements and the same number of detections are merged (see the
//!   function's documentation);
//! - [`naive_marginals`]: the reference, enumerating every feasible joint
//!   event (exponential; tests and benchmarks only);
//! - [`amsjpda_marginals`]: seed 002 section 3, β_tj = P_tj · F_tj over the
//!   target-centred cluster of t, normalised.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// The weights of one cluster; track and measurement indices are local.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterProblem {
    /// Number of measurements of the cluster (local indices `0..measurements`).
    pub measurements: usize,
    /// Per track, its gated measurements with their weights a_tj (> 0).
    pub gates: Vec<Vec<(usize, f64)>>,
    /// Per track, the weight b_t of a miss (> 0).
    pub miss: Vec<f64>,
    /// g(d) for d = 0..=measurements (non-parametric clutter), or `None` for g ≡ 1.
    pub count_factor: Option<Vec<f64>>,
}

/// β of every track of a cluster: `beta[t][0]` is the miss probability β_t0,
/// `beta[t][1 + k]` the probability of the k-th gated measurement of track t
/// (in the order of `ClusterProblem::gates[t]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Marginals {
    /// Per track, β_t0 followed by β_tj of each gated measurement.
    pub beta: Vec<Vec<f64>>,
    /// Work done: merged hypothesis-tree edges (exact), joint events (naive)
    /// or products P_tj · F_tj (AMSJPDA).
    pub hypotheses: u64,
}

/// Why [`exact_marginals`] gave up (the caller falls back to AMSJPDA).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExactLimit {
    /// More than 128 measurements are relevant at once to the partial hypotheses.
    Frontier,
    /// The merged hypothesis tree would exceed the edge budget (found
    /// before the edge over the budget is stored).
    Hypotheses,
}

/// The non-parametric g(d) = m^d (m − d)!/m! for d = 0..=m, divided by its
/// largest value needed (d = `max_detections`), computed by the ratio
/// g(d)/g(d − 1) = m/(m − d + 1) so that nothing overflows.
pub fn nonparametric_count_factor(m: usize, max_detections: usize) -> Vec<f64> {
    let top = max_detections.min(m);
    let mut g = vec![0.0; m + 1];
    g[top] = 1.0;
    for d in (1..=top).rev() {
        g[d - 1] = g[d] * (m - d + 1) as f64 / m as f64;
    }
    // d > top cannot happen; keep them defined.
    for value in g.iter_mut().skip(top + 1) {
        *value = 1.0;
    }
    g
}

/// Exact β by a forward–backward pass over a hypothesis tree with merged
/// equivalent nodes.
///
/// The tracks are processed in a greedy order that keeps the set of "live"
/// measurements small (a measurement is live between the first and the last
/// processed track that gates it). A partial hypothesis over the first k
/// tracks matters to the rest only through (the live measurements it used,
/// the number of detections d), so all partial hypotheses with the same key
/// are merged into one node whose forward weight is their sum. Keys are
/// 128-bit masks over slots that are reused once a measurement is dead, so
/// the width needed is the largest live set, not the cluster's size. The
/// backward pass gives each node the summed weight of all completions, and
/// β_tj = Σ over the edges of step t choosing j of forward · a_tj · backward,
/// normalised per step. Cost: O(edges), which for the chains and small
/// blocks of real scenes grows polynomially, against the exponential number
/// of joint events. Each layer is rescaled to a maximum of 1 to avoid
/// overflow and underflow; the scale cancels in the per-step normalisation.
pub fn exact_marginals(p: &ClusterProblem, max_edges: u64) -> Result<Marginals, ExactLimit> {
    let n = p.gates.len();
    if n == 1 {
        // One track: every option is an event of its own (g(0) = g(1) with
        // the cluster's own m, see `nonparametric_count_factor`), β ∝ weight.
        let g = |d: usize| p.count_factor.as_ref().map_or(1.0, |g| g[d]);
        let mut row = vec![p.miss[0] * g(0)];
        row.extend(p.gates[0].iter().map(|&(_, a)| a * g(1)));
        normalise(&mut row);
        return Ok(Marginals {
            hypotheses: row.len() as u64,
            beta: vec![row],
        });
    }
    let order = processing_order(p);
    let m = p.measurements;
    let mut first = vec![usize::MAX; m];
    let mut last = vec![0usize; m];
    for (step, &t) in order.iter().enumerate() {
        for &(j, _) in &p.gates[t] {
            first[j] = first[j].min(step);
            last[j] = step;
        }
    }
    // Slots: assigned at first use, freed after last use.
    let mut slot = vec![u8::MAX; m];
    let mut free: Vec<u8> = (0..128u8).rev().collect();
    let mut dead_masks = vec![0u128; n];
    for (step, &t) in order.iter().enumerate() {
        for &(j, _) in &p.gates[t] {
            if first[j] == step {
                slot[j] = free.pop().ok_or(ExactLimit::Frontier)?;
            }
        }
        for &(j, _) in &p.gates[t] {
            if last[j] == step && dead_masks[step] & (1u128 << slot[j]) == 0 {
                dead_masks[step] |= 1u128 << slot[j];
                free.push(slot[j]);
            }
        }
    }

    // Forward: layers of merged nodes, and the edges between them.
    type Key = (u128, u32);
    let mut layers: Vec<Vec<Key>> = vec![vec![(0, 0)]];
    let mut forward: Vec<Vec<f64>> = vec![vec![1.0]];
    // Per step: (parent, child, option) with option 0 = miss, 1 + k = gate k.
    let mut edges: Vec<Vec<(u32, u32, u32)>> = Vec::with_capacity(n);
    let mut total_edges = 0u64;
    for (step, &t) in order.iter().enumerate() {
        let dead = !dead_masks[step];
        let mut index: HashMap<Key, u32, BuildHasherDefault<MixHasher>> = HashMap::default();
        let mut keys: Vec<Key> = Vec::new();
        let mut f_next: Vec<f64> = Vec::new();
        let mut step_edges = Vec::new();
        let prev_keys = &layers[step];
        let prev_f = &forward[step];
        // The budget is checked before each edge (and the node it may make)
        // is stored, so that one step never holds more than the budget: a
        // layer of many nodes times many gated measurements could otherwise
        // allocate gigabytes before a check between steps saw it.
        let mut budget_left = max_edges.saturating_sub(total_edges);
        for (parent, &(mask, d)) in prev_keys.iter().enumerate() {
            let mut visit = |child_key: Key, option: u32, w: f64| {
                if budget_left == 0 {
                    return Err(ExactLimit::Hypotheses);
                }
                budget_left -= 1;
                let child = *index.entry(child_key).or_insert_with(|| {
                    keys.push(child_key);
                    f_next.push(0.0);
                    (keys.len() - 1) as u32
                });
                f_next[child as usize] += prev_f[parent] * w;
                step_edges.push((parent as u32, child, option));
                Ok(())
            };
            visit((mask & dead, d), 0, p.miss[t])?;
            for (k, &(j, a)) in p.gates[t].iter().enumerate() {
                let bit = 1u128 << slot[j];
                if mask & bit == 0 {
                    visit(((mask | bit) & dead, d + 1), 1 + k as u32, a)?;
                }
            }
        }
        total_edges += step_edges.len() as u64;
        rescale(&mut f_next);
        layers.push(keys);
        forward.push(f_next);
        edges.push(step_edges);
    }

    // Backward: b over the final layer is g(d); then step by step.
    let mut backward: Vec<f64> = layers[n]
        .iter()
        .map(|&(_, d)| p.count_factor.as_ref().map_or(1.0, |g| g[d as usize]))
        .collect();
    let mut beta: Vec<Vec<f64>> = p.gates.iter().map(|g| vec![0.0; g.len() + 1]).collect();
    for step in (0..n).rev() {
        let t = order[step];
        let weight = |option: u32| {
            if option == 0 {
                p.miss[t]
            } else {
                p.gates[t][option as usize - 1].1
            }
        };
        let mut b_prev = vec![0.0; layers[step].len()];
        let row = &mut beta[t];
        for &(parent, child, option) in &edges[step] {
            let wb = weight(option) * backward[child as usize];
            b_prev[parent as usize] += wb;
            row[option as usize] += forward[step][parent as usize] * wb;
        }
        normalise(row);
        rescale(&mut b_prev);
        backward = b_prev;
    }
    Ok(Marginals {
        beta,
        hypotheses: total_edges,
    })
}

/// Reference β by enumerating every feasible joint event of eq. 4 (each
/// measurement used by at most one track) and summing eq. 5 directly.
/// Exponential in the cluster size: for tests and benchmarks only.
pub fn naive_marginals(p: &ClusterProblem) -> Marginals {
    struct Walk<'a> {
        p: &'a ClusterProblem,
        used: Vec<bool>,
        choice: Vec<usize>,
        beta: Vec<Vec<f64>>,
        events: u64,
    }
    impl Walk<'_> {
        fn go(&mut self, t: usize, weight: f64, d: usize) {
            if t == self.p.gates.len() {
                let w = weight * self.p.count_factor.as_ref().map_or(1.0, |g| g[d]);
                for (tt, &c) in self.choice.iter().enumerate() {
                    self.beta[tt][c] += w;
                }
                self.events += 1;
                return;
            }
            self.choice[t] = 0;
            self.go(t + 1, weight * self.p.miss[t], d);
            for k in 0..self.p.gates[t].len() {
                let (j, a) = self.p.gates[t][k];
                if !self.used[j] {
                    self.used[j] = true;
                    self.choice[t] = 1 + k;
                    self.go(t + 1, weight * a, d + 1);
                    self.used[j] = false;
                }
            }
        }
    }
    let mut walk = Walk {
        p,
        used: vec![false; p.measurements],
        choice: vec![0; p.gates.len()],
        beta: p.gates.iter().map(|g| vec![0.0; g.len() + 1]).collect(),
        events: 0,
    };
    walk.go(0, 1.0, 0);
    let mut beta = walk.beta;
    for row in &mut beta {
        normalise(row);
    }
    Marginals {
        beta,
        hypotheses: walk.events,
    }
}

/// AMSJPDA (seed 002 section 3): for every track t, its target-centred
/// cluster (3.1) is t plus the tracks B^t sharing at least one gated
/// measurement with it, and (3.2)
///
///   β_tj ∝ P_tj · F_tj,  F_tj = Π_{i ∈ B^t} (P_i0 + Σ_{l ≠ j} P_il),
///   β_t0 ∝ P_t0 · Π_{i ∈ B^t} (P_i0 + Σ_l P_il),
///
/// normalised over j = 0..m. Here P_tj = a_tj, P_t0 = b_t. This is
/// B. Zhou and N. K. Bose's direct computation, exact for clusters of one
/// and two targets, approximate beyond (it ignores conflicts among the
/// neighbours). The paper prints F_tj as a *sum* over the neighbours with a
/// single P_0; for one neighbour the two agree, for more the sum is not
/// Zhou's formula (a misprint; see the unit test `amsjpda_two_targets_is_exact`).
/// The non-parametric g(d) is not used: with one target it only contributes
/// the λ = m/V already folded into a_tj.
pub fn amsjpda_marginals(p: &ClusterProblem) -> Marginals {
    let n = p.gates.len();
    let mut tracks_of: Vec<Vec<usize>> = vec![Vec::new(); p.measurements];
    for (t, gate) in p.gates.iter().enumerate() {
        for &(j, _) in gate {
            tracks_of[j].push(t);
        }
    }
    let totals: Vec<f64> = (0..n)
        .map(|t| p.miss[t] + p.gates[t].iter().map(|&(_, a)| a).sum::<f64>())
        .collect();
    let mut beta = Vec::with_capacity(n);
    let mut work = 0u64;
    let mut neighbours: Vec<usize> = Vec::new();
    for t in 0..n {
        neighbours.clear();
        for &(j, _) in &p.gates[t] {
            neighbours.extend(tracks_of[j].iter().copied().filter(|&i| i != t));
        }
        neighbours.sort_unstable();
        neighbours.dedup();
        // ln F / Π S_i: each factor (S_i − a_ij)/S_i in (0, 1].
        let ln_f = |j: Option<usize>| -> f64 {
            neighbours
                .iter()
                .map(|&i| {
                    let a_ij = j.map_or(0.0, |j| {
                        p.gates[i]
                            .iter()
                            .find(|&&(l, _)| l == j)
                            .map_or(0.0, |&(_, a)| a)
                    });
                    ((totals[i] - a_ij) / totals[i]).ln()
                })
                .sum()
        };
        let mut ln_row = Vec::with_capacity(p.gates[t].len() + 1);
        ln_row.push(p.miss[t].ln() + ln_f(None));
        for &(j, a) in &p.gates[t] {
            ln_row.push(a.ln() + ln_f(Some(j)));
        }
        work += (ln_row.len() * neighbours.len().max(1)) as u64;
        let top = ln_row.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut row: Vec<f64> = ln_row.iter().map(|&l| (l - top).exp()).collect();
        normalise(&mut row);
        beta.push(row);
    }
    Marginals {
        beta,
        hypotheses: work,
    }
}

/// Greedy order: repeatedly the unprocessed track whose gate overlaps the
/// live measurements most, net of the new measurements it opens, so that
/// chains are walked end to end and the live set stays narrow.
fn processing_order(p: &ClusterProblem) -> Vec<usize> {
    let n = p.gates.len();
    let mut remaining_users = vec![0usize; p.measurements];
    for gate in &p.gates {
        for &(j, _) in gate {
            remaining_users[j] += 1;
        }
    }
    let mut touched = vec![false; p.measurements];
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    for _ in 0..n {
        let mut best = (i64::MIN, usize::MAX);
        for t in (0..n).filter(|&t| !done[t]) {
            // + live measurements it closes or shares, − new ones it opens.
            let score: i64 = p.gates[t]
                .iter()
                .map(|&(j, _)| {
                    if touched[j] {
                        if remaining_users[j] == 1 { 2 } else { 1 }
                    } else if remaining_users[j] == 1 {
                        0
                    } else {
                        -1
                    }
                })
                .sum();
            if score > best.0 {
                best = (score, t);
            }
        }
        let t = best.1;
        done[t] = true;
        order.push(t);
        for &(j, _) in &p.gates[t] {
            touched[j] = true;
            remaining_users[j] -= 1;
        }
    }
    order
}

fn normalise(row: &mut [f64]) {
    let sum: f64 = row.iter().sum();
    if sum > 0.0 && sum.is_finite() {
        for v in row.iter_mut() {
            *v /= sum;
        }
    }
}

fn rescale(values: &mut [f64]) {
    let top = values.iter().copied().fold(0.0, f64::max);
    if top > 0.0 && top.is_finite() {
        for v in values.iter_mut() {
            *v /= top;
        }
    }
}

/// A fast hasher for the (mask, count) keys (a 64-bit multiply–xorshift mix).
#[derive(Default)]
struct MixHasher(u64);

impl Hasher for MixHasher {
    fn finish(&self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^ (h >> 33)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    fn write_u128(&mut self, i: u128) {
        self.write_u64(i as u64);
        self.write_u64((i >> 64) as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
    fn write_u32(&mut self, i: u32) {
        self.write_u64(u64::from(i));
    }
}
