//! The bias search: every pair's implied bias is a hypothesis, ranked by
//! the distinct tracks and ships that vote for it, the best few scored
//! exactly (gated pairs, then total distance).

use super::problem::Problem;
use super::{Bias, WIDEN_FACTOR};
use crate::polar::wrap_angle;

/// Median mean AIS range of the pairs (m).
pub(super) fn median_rho(problem: &Problem, pairs: &[(usize, usize)]) -> f64 {
    let mut r: Vec<f64> = pairs
        .iter()
        .map(|&(i, j)| problem.summary[i * problem.cols + j].rho)
        .collect();
    r.sort_by(f64::total_cmp);
    r.get(r.len() / 2).copied().unwrap_or(0.0)
}

/// Whether two biases differ by more than `by` metres in range or across
/// it at range `rho`.
pub(super) fn distinct(a: Bias, b: Bias, rho: f64, by: f64) -> bool {
    (a.range - b.range).abs() > by || (wrap_angle(a.azimuth - b.azimuth) * rho).abs() > by
}

/// A hypothesis scored exactly.
#[derive(Debug, Clone, Copy)]
pub(super) struct Scored {
    pub(super) bias: Bias,
    pub(super) rho: f64,
    pub(super) count: usize,
    pub(super) total: f64,
}

impl Scored {
    fn beats(&self, other: &Scored) -> bool {
        self.count > other.count || (self.count == other.count && self.total < other.total)
    }
}

pub(super) struct SearchResult {
    pub(super) best: Option<Scored>,
    /// The best scored hypothesis distinct from `best` with as many pairs.
    pub(super) runner_up: Option<Scored>,
    pub(super) hypotheses: usize,
    pub(super) evaluated: usize,
    pub(super) widened: Option<(usize, usize)>,
}

/// A hypothesis: the implied bias of a pair, its spread and AIS range.
#[derive(Debug, Clone, Copy)]
struct Hypothesis {
    pub(super) spread: f64,
    pub(super) bias: Bias,
    pub(super) rho: f64,
}

/// The bias search: pair-implied biases within the bounds ranked by their
/// agreement with other pairs, the best few scored by gated assignments
/// then total distance; beyond the bounds when `widen` is set and a
/// hypothesis there could gate more pairs.
pub(super) fn search(problem: &Problem) -> SearchResult {
    let cfg = problem.cfg;
    let outer_range = WIDEN_FACTOR * cfg.max_range_bias.max(cfg.gate);
    let outer_azimuth = (WIDEN_FACTOR * cfg.max_azimuth_bias).min(std::f64::consts::PI);
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    for s in problem.summary.iter().filter(|s| s.n > 0) {
        let h = Hypothesis {
            spread: s.spread,
            bias: Bias {
                range: s.range,
                azimuth: s.azimuth,
            },
            rho: s.rho,
        };
        let (r, a) = (s.range.abs(), s.azimuth.abs());
        if r <= cfg.max_range_bias && a <= cfg.max_azimuth_bias {
            inside.push(h);
        } else if cfg.widen && r <= outer_range && a <= outer_azimuth {
            outside.push(h);
        }
    }
    let mut voter = Voter::new(problem);
    let within = voter.best_of(&mut inside, None);
    let mut result = SearchResult {
        best: within.best,
        runner_up: within.runner_up,
        hypotheses: inside.len(),
        evaluated: within.evaluated,
        widened: None,
    };
    let count_within = within.best.map_or(0, |b| b.count);
    // No bias can gate more pairs than there are tracks or ships with any.
    let rows_with = (0..problem.rows)
        .filter(|&i| (0..problem.cols).any(|j| problem.summary[i * problem.cols + j].n > 0))
        .count();
    let cols_with = (0..problem.cols)
        .filter(|&j| (0..problem.rows).any(|i| problem.summary[i * problem.cols + j].n > 0))
        .count();
    if cfg.widen && !outside.is_empty() && count_within < rows_with.min(cols_with) {
        let beyond = voter.best_of(&mut outside, Some(count_within));
        result.hypotheses += outside.len();
        result.evaluated += beyond.evaluated;
        if let Some(b) = beyond.best.filter(|b| b.count > count_within) {
            result.best = Some(b);
            result.runner_up = beyond.runner_up;
            result.widened = Some((b.count, count_within));
        }
    }
    result.best = result.best.filter(|b| b.count > 0);
    result
}

struct Ranked {
    pub(super) best: Option<Scored>,
    pub(super) runner_up: Option<Scored>,
    pub(super) evaluated: usize,
}

/// Counts distinct rows and columns of the pairs near a hypothesis.
struct Voter<'p, 'a> {
    pub(super) problem: &'p Problem<'a>,
    pub(super) stamp: Vec<usize>,
    generation: usize,
}

impl<'p, 'a> Voter<'p, 'a> {
    pub(super) fn new(problem: &'p Problem<'a>) -> Self {
        Self {
            problem,
            stamp: vec![0; 2 * (problem.rows + problem.cols)],
            generation: 0,
        }
    }

    /// (upper bound of the gated pairs, agreeing rows/columns within a
    /// tenth of the gate) of hypothesis `h`.
    fn vote(&mut self, h: Bias) -> (usize, usize) {
        let p = self.problem;
        let tight = 0.1 * p.cfg.gate;
        self.generation += 1;
        let g = self.generation;
        let (rows, cols) = (p.rows, p.cols);
        let mut counts = [0usize; 4];
        let sc = h.azimuth.sin_cos();
        for ij in p.candidates(h) {
            let (i, j) = (ij / cols, ij % cols);
            let (dr, dx) = p.summary[ij].offsets(h, sc);
            let near = dr <= tight && dx <= tight;
            let slots = [i, rows + j, rows + cols + i, 2 * rows + cols + j];
            for (s, &slot) in slots.iter().enumerate() {
                if (s < 2 || near) && self.stamp[slot] != g {
                    self.stamp[slot] = g;
                    counts[s] += 1;
                }
            }
        }
        (counts[0].min(counts[1]), counts[2].min(counts[3]))
    }

    /// Ranks `hyps` (most agreeing first, then the least spread) and scores
    /// up to `max_evaluations` distinct ones whose bound can reach the best
    /// (and exceed `must_beat`).
    fn best_of(&mut self, hyps: &mut [Hypothesis], must_beat: Option<usize>) -> Ranked {
        let cfg = self.problem.cfg;
        hyps.sort_by(|a, b| a.spread.total_cmp(&b.spread));
        let hyps = &hyps[..hyps.len().min(cfg.max_hypotheses)];
        // One hypothesis (the least spread) per cell of a tenth of the gate
        // in range and cross-range: the rest would seed the same result.
        let tight = 0.1 * cfg.gate;
        let mut cells = std::collections::HashSet::new();
        let hyps: Vec<Hypothesis> = hyps
            .iter()
            .filter(|h| {
                cells.insert((
                    (h.bias.range / tight).floor() as i64,
                    (h.bias.azimuth * h.rho / tight).floor() as i64,
                ))
            })
            .copied()
            .collect();
        let votes: Vec<(usize, usize)> = hyps.iter().map(|h| self.vote(h.bias)).collect();
        let mut order: Vec<usize> = (0..hyps.len()).collect();
        order.sort_by_key(|&k| std::cmp::Reverse(votes[k].1));
        let mut scored: Vec<Scored> = Vec::new();
        let mut best: Option<Scored> = None;
        for k in order {
            if scored.len() >= cfg.max_evaluations {
                break;
            }
            let (h, ub) = (hyps[k], votes[k].0);
            let floor = best
                .map_or(0, |b| b.count)
                .max(must_beat.map_or(0, |m| m + 1));
            if ub < floor.max(1)
                || scored
                    .iter()
                    .any(|s| !distinct(s.bias, h.bias, h.rho, tight))
            {
                continue;
            }
            let (pairs, total) = self.problem.assign(h.bias);
            let s = Scored {
                bias: h.bias,
                rho: h.rho,
                count: pairs.len(),
                total,
            };
            if best.is_none_or(|b| s.beats(&b)) {
                best = Some(s);
            }
            scored.push(s);
        }
        let runner_up = best.and_then(|b| {
            scored
                .iter()
                .filter(|s| s.count >= b.count && distinct(s.bias, b.bias, b.rho, cfg.gate / 2.0))
                .copied()
                .reduce(|x, y| if y.beats(&x) { y } else { x })
        });
        Ranked {
            best,
            runner_up,
            evaluated: scored.len(),
        }
    }
}
