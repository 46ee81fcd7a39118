//! Two-node track-to-track correlation over aligned instants (seed 000): the
//! weighted and modified statistics (eqs. 10, 12–13), the independent and
//! dependent double-threshold rules with correlation and departure quality
//! (eqs. 15–17), ambiguity handling at l = R (eqs. 18–20) and trial system
//! tracks at l < R (eq. 21), and the classic baselines (nearest neighbour,
//! K-nearest-neighbour, global optimal assignment).
//!
//! The engine is causal: [`PairCorrelator::step`] processes one instant using
//! only that instant and earlier ones, so a batch is a loop over instants and
//! an experiment can read the decisions after every step.
//!
//! Candidate pairs are pruned by a conservative spatial gate before the χ²
//! test: for positive definite S, d'S⁻¹d ≥ ‖d_pos‖² / λ_max(S_pos) ≥
//! ‖d_pos‖² / (tr P_a,pos + tr P_b,pos), so a pair with ‖d_pos‖² > δ (tr_a + tr_b)
//! fails the test for sure (for the modified statistic S ≤ 2 (P_a + P_b), so the
//! bound takes a factor 2). A pair is materialised the first time it passes the
//! spatial gate, and its earlier common instants are replayed exactly, so the
//! result equals the brute-force computation over all pairs.

use std::collections::VecDeque;

use super::{
    rules::LrRule,
    scene::{Scene, Track},
};
use crate::{AlgoError, gating::chi2_threshold, motion::MotionModel};

/// The test statistic compared with the first threshold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Statistic {
    /// α = d'(P_a + P_b)⁻¹d, Singer–Kanyuch (eq. 10).
    Weighted,
    /// β = d'(P_a + P_b − P_ab − P_ab')⁻¹d with the cross-covariance of eq. 13,
    /// Bar-Shalom (eq. 12).
    Modified,
}

/// The second threshold: one L/R rule, or a schedule of rules indexed by the
/// number of samples accumulated in the cycle (entry l − 1 has r = l).
#[derive(Debug, Clone, PartialEq)]
pub enum RuleSpec {
    /// One L/R rule for every cycle.
    Fixed(LrRule),
    /// A rule per number of accumulated samples; the last one holds from
    /// then on.
    Schedule(Vec<LrRule>),
}

/// How competing candidates are resolved at decision time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resolution {
    /// Eqs. 18–20: the largest m wins, then the smallest mean statistic.
    Greedy,
    /// A global optimal assignment over the candidates, maximising the total
    /// m and then minimising the mean statistics (for dense scenes).
    Assignment,
}

/// The correlation method.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    /// Independent (weighted statistic) or dependent (modified statistic)
    /// double-threshold correlation; with the fixed rule 1/1 it reduces to the
    /// classic weighted or modified test (seed 000 §3.3).
    DoubleThreshold {
        /// The second threshold.
        rules: RuleSpec,
        /// How competing candidates are resolved.
        resolution: Resolution,
    },
    /// Greedy nearest neighbour on the mean statistic over the last `window`
    /// common samples, gated by χ²(n·w).
    NearestNeighbour {
        /// Common samples the mean statistic is taken over (1 to 64).
        window: usize,
    },
    /// Global optimal assignment on the same cost and gate.
    GlobalAssignment {
        /// Common samples the mean statistic is taken over (1 to 64).
        window: usize,
    },
    /// K-nearest-neighbour: correlated when the two tracks were each other's
    /// nearest gated neighbour in at least `k` of the last `window` instants.
    KNearestNeighbour {
        /// Instants as mutual nearest gated neighbours needed (1 to `window`).
        k: usize,
        /// Most recent common instants looked at (1 to 64).
        window: usize,
    },
}

/// How candidate pairs are found at each instant (the decisions are the same
/// either way).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pruning {
    /// A uniform grid over positions with a conservative radius per track.
    Grid,
    /// Brute force: the statistic of every pair of present tracks.
    None,
}

/// Everything the engine needs besides the data.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// The correlation method.
    pub method: Method,
    /// The test statistic compared with the first threshold.
    pub statistic: Statistic,
    /// Significance level α of the first threshold (eq. 14).
    pub alpha: f64,
    /// How candidate pairs are found at each instant.
    pub pruning: Pruning,
}

/// A pair's decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// The two tracks are one target.
    Correlated,
    /// The two tracks are not one target.
    NotCorrelated,
    /// No decision yet.
    Undecided,
}

/// Why a pair holds its decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    /// Still being tested in the current cycle.
    Testing,
    /// m ≥ L at l = R, without a competitor (eqs. 10–12).
    Threshold,
    /// m ≥ L before l = R, the only candidate of both tracks (eq. 17).
    EarlyDecision,
    /// Departure quality C > R − L: the rule can no longer be met (eq. 16).
    EarlyStop,
    /// Won an ambiguity on the larger m (eq. 18).
    AmbiguityMaxM,
    /// Won an ambiguity on equal m by the smaller mean statistic (eqs. 19–20).
    AmbiguityMinMeanStatistic,
    /// Met the rule but a competitor ranked higher.
    AmbiguityLost,
    /// Chosen by the global assignment among competing candidates.
    Assignment,
    /// The cycle ended with m < L.
    BelowRule,
    /// A decided pair failed the rule over its most recent samples.
    Revoked,
    /// Baselines: the statistic over the window is outside the χ² gate.
    Gate,
    /// Baselines: inside the gate and chosen.
    NearestNeighbour,
    /// Baselines: inside the gate but another pairing was preferred.
    Conflict,
    /// K-NN: mutual nearest neighbours in at least K of the last N instants.
    KOfN,
}

/// The state of one candidate pair after the last processed instant.
#[derive(Debug, Clone, PartialEq)]
pub struct PairReport {
    /// Track index in the first node.
    pub a: usize,
    /// Track index in the second node.
    pub b: usize,
    /// The pair's decision.
    pub decision: Decision,
    /// Why the pair holds its decision.
    pub reason: Reason,
    /// A trial system track of eq. 21 (undecided, provisionally paired).
    pub trial: bool,
    /// Correlation quality m: samples passing the first threshold in the
    /// current cycle (for a decided pair, since the cycle that decided it).
    pub m: u32,
    /// Departure quality C: samples failing it (eq. 15).
    pub c: u32,
    /// Samples behind m and C.
    pub samples: u32,
    /// Mean statistic over those samples.
    pub mean_statistic: f64,
    /// Mean norm of the position difference over those samples (eq. 21).
    pub mean_position_difference: f64,
    /// The statistic at the last common instant.
    pub last_statistic: f64,
    /// Instant index at which the current decision was taken.
    pub decided_at: Option<usize>,
    /// Time of that instant.
    pub decided_time: Option<f64>,
    /// Last common instant of the two tracks.
    pub last_common: usize,
    /// Cross-covariance P_ab at the last common instant (modified statistic),
    /// row-major.
    pub cross_covariance: Option<Vec<f64>>,
}

/// Correlates the tracks of two nodes of a scene.
pub struct PairCorrelator<'a> {
    scene: &'a Scene,
    na: usize,
    nb: usize,
    cfg: &'a Config,
    model: Option<&'a dyn MotionModel>,
    dim: usize,
    delta: f64,
    /// χ² gate for a sum of w samples, index w (baselines).
    window_gate: Vec<f64>,
    hist_len: usize,
    pairs: Vec<Pair>,
    adj_a: Vec<Vec<u32>>,
    adj_b: Vec<Vec<u32>>,
    partner_a: Vec<Option<u32>>,
    partner_b: Vec<Option<u32>>,
    /// I − K H per track and instant for the modified statistic.
    factors_a: Factors,
    factors_b: Factors,
    /// F and Q per step length (modified statistic).
    steps: Steps,
    next: usize,
    /// Most candidate pairs this correlator may hold ([`Self::with_pair_budget`]).
    max_pairs: usize,
    /// Tests whose modified S was not positive definite: the weighted
    /// statistic was used for them instead.
    pub singular_tests: usize,
}

/// One test of a candidate pair, kept in its history window (for the
/// sliding-window baselines and K-of-N).
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Instant of the test (global index).
    pub k: u32,
    /// The test statistic.
    pub stat: f64,
    /// Norm of the position difference.
    pub posdiff: f64,
    /// Whether the statistic passed the first threshold.
    pub hit: bool,
}

/// Where a candidate pair stands in its test cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PairStatus {
    /// Being tested in the current cycle.
    Testing,
    /// Stopped early (the rule can no longer be met) until the next cycle.
    Stopped,
    /// Decided correlated.
    Decided,
}

/// Every [`PairStatus`]; a status's index here is its one-byte code when a
/// [`CorrelatorState`] is stored.
pub const PAIR_STATUSES: [PairStatus; 3] = [
    PairStatus::Testing,
    PairStatus::Stopped,
    PairStatus::Decided,
];

/// The whole state of one candidate pair between instants (public so that
/// a codec outside this crate can store a [`CorrelatorState`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Pair {
    /// Track index in the first node.
    pub a: u32,
    /// Track index in the second node.
    pub b: u32,
    /// Where the pair stands in its cycle.
    pub status: PairStatus,
    /// Why it holds its decision.
    pub reason: Reason,
    /// A trial system track of eq. 21.
    pub trial: bool,
    /// Samples tested in the current cycle (l).
    pub l: u32,
    /// Correlation quality m.
    pub m: u32,
    /// Departure quality C.
    pub c: u32,
    /// Sum of the statistics behind m and C.
    pub sum_stat: f64,
    /// Sum of the position-difference norms behind m and C.
    pub sum_posdiff: f64,
    /// Whether the current cycle has completed (l = R reached).
    pub cycle_done: bool,
    /// Instant at which the current decision was taken.
    pub decided_at: Option<usize>,
    /// Time of that instant.
    pub decided_time: Option<f64>,
    /// The recent tests, oldest first.
    pub hist: VecDeque<Sample>,
    /// P_ab, dim × dim row-major (modified statistic).
    pub cross: Option<Box<[f64]>>,
    /// Last instant at which both tracks were present.
    pub last_common: Option<usize>,
}

/// Which node of a correlated pair a track belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The first node of the pair (`na`).
    A,
    /// The second node of the pair (`nb`).
    B,
}

/// Every [`Reason`]; a reason's index here is its one-byte code when a
/// [`CorrelatorState`] is encoded.
pub const REASONS: [Reason; 14] = [
    Reason::Testing,
    Reason::Threshold,
    Reason::EarlyDecision,
    Reason::EarlyStop,
    Reason::AmbiguityMaxM,
    Reason::AmbiguityMinMeanStatistic,
    Reason::AmbiguityLost,
    Reason::Assignment,
    Reason::BelowRule,
    Reason::Revoked,
    Reason::Gate,
    Reason::NearestNeighbour,
    Reason::Conflict,
    Reason::KOfN,
];

mod baselines;
mod candidates;
mod double_threshold;
mod state;
mod statistic;

use baselines::{check_window, window_counts};
use double_threshold::check_rules;
pub use double_threshold::{default_schedule, final_rule};
pub use state::CorrelatorState;
use state::bad;
pub use statistic::filter_factor;
use statistic::{Factors, Steps, filter_factors};

impl<'a> PairCorrelator<'a> {
    /// A correlator of nodes `na` and `nb`. The modified statistic needs the
    /// motion model of the local filters (for eq. 13).
    pub fn new(
        scene: &'a Scene,
        na: usize,
        nb: usize,
        cfg: &'a Config,
        model: Option<&'a dyn MotionModel>,
    ) -> Result<Self, AlgoError> {
        let dim = scene.dim();
        let delta = chi2_threshold(dim, cfg.alpha)?;
        let (window, rule_len) = match &cfg.method {
            Method::DoubleThreshold { rules, .. } => {
                check_rules(rules)?;
                (1, final_rule(rules).r() as usize)
            }
            Method::NearestNeighbour { window } | Method::GlobalAssignment { window } => {
                check_window(*window)?;
                (*window, 1)
            }
            Method::KNearestNeighbour { k, window } => {
                check_window(*window)?;
                if *k == 0 || k > window {
                    return Err(AlgoError::InvalidParameter {
                        what: "k",
                        reason: format!("must be between 1 and window = {window}"),
                    });
                }
                (*window, 1)
            }
        };
        let mut window_gate = vec![0.0];
        if matches!(
            cfg.method,
            Method::NearestNeighbour { .. } | Method::GlobalAssignment { .. }
        ) {
            for w in 1..=window {
                window_gate.push(chi2_threshold(dim * w, cfg.alpha)?);
            }
        }
        if cfg.statistic == Statistic::Modified {
            let Some(m) = model else {
                return Err(AlgoError::InvalidParameter {
                    what: "motion_model",
                    reason: "the modified statistic needs the local filters' motion model".into(),
                });
            };
            if m.state_dim() != dim {
                return Err(AlgoError::DimensionMismatch {
                    what: "motion model state",
                    expected: dim,
                    found: m.state_dim(),
                });
            }
        }
        let (ta, tb) = (scene.nodes()[na].len(), scene.nodes()[nb].len());
        let mut me = Self {
            scene,
            na,
            nb,
            cfg,
            model,
            dim,
            delta,
            window_gate,
            hist_len: window.max(rule_len),
            pairs: Vec::new(),
            adj_a: vec![Vec::new(); ta],
            adj_b: vec![Vec::new(); tb],
            partner_a: vec![None; ta],
            partner_b: vec![None; tb],
            factors_a: Factors::default(),
            factors_b: Factors::default(),
            steps: Steps::default(),
            next: 0,
            max_pairs: usize::MAX,
            singular_tests: 0,
        };
        if cfg.statistic == Statistic::Modified {
            me.factors_a = filter_factors(scene, na, me.model, &mut me.steps)?;
            me.factors_b = filter_factors(scene, nb, me.model, &mut me.steps)?;
        }
        Ok(me)
    }

    /// A correlator that continues from `state` over `scene`, which holds
    /// the instants from `state.next()` on (and possibly earlier ones, for
    /// the replay of newly gated pairs) and may have gained tracks.
    pub fn resume(
        scene: &'a Scene,
        na: usize,
        nb: usize,
        cfg: &'a Config,
        model: Option<&'a dyn MotionModel>,
        state: CorrelatorState,
    ) -> Result<Self, AlgoError> {
        let mut me = Self::new(scene, na, nb, cfg, model)?;
        let (ta, tb) = (me.adj_a.len(), me.adj_b.len());
        if state.partner_a.len() > ta || state.partner_b.len() > tb {
            return Err(bad("more tracks than the scene holds"));
        }
        if state.next < scene.first() {
            return Err(bad("instants missing from the scene"));
        }
        me.partner_a = state.partner_a;
        me.partner_a.resize(ta, None);
        me.partner_b = state.partner_b;
        me.partner_b.resize(tb, None);
        me.next = state.next;
        me.singular_tests = state.singular_tests;
        for (pi, p) in state.pairs.iter().enumerate() {
            me.adj_a[p.a as usize].push(pi as u32);
            me.adj_b[p.b as usize].push(pi as u32);
        }
        me.pairs = state.pairs;
        Ok(me)
    }

    /// Bounds the candidate pairs this correlator holds (those it resumed
    /// with included) to `max_pairs`: an instant whose pairs would exceed
    /// it is an [`AlgoError::BudgetExceeded`], found while they are
    /// collected, before they are stored. Unbounded by default.
    pub fn with_pair_budget(mut self, max_pairs: usize) -> Self {
        self.max_pairs = max_pairs;
        self
    }

    /// Candidate pairs held so far.
    pub fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// The state to resume from later.
    pub fn into_state(self) -> CorrelatorState {
        CorrelatorState {
            pairs: self.pairs,
            partner_a: self.partner_a,
            partner_b: self.partner_b,
            next: self.next,
            singular_tests: self.singular_tests,
        }
    }

    /// The χ² first threshold δ (eq. 14) with n_x degrees of freedom.
    pub fn delta(&self) -> f64 {
        self.delta
    }

    /// Instants processed so far.
    pub fn processed(&self) -> usize {
        self.next
    }

    /// Processes every remaining instant.
    pub fn run(&mut self) -> Result<(), AlgoError> {
        while self.step()? {}
        Ok(())
    }

    /// Processes the instants before global index `end`.
    pub fn run_until(&mut self, end: usize) -> Result<(), AlgoError> {
        while self.next < end && self.step()? {}
        Ok(())
    }

    /// Processes the next instant; false when there is none. An instant
    /// whose candidate pairs would exceed the pair budget is an error, and
    /// the correlator is then left in the middle of that instant (discard it).
    pub fn step(&mut self) -> Result<bool, AlgoError> {
        let k = self.next;
        if k >= self.scene.end() {
            return Ok(false);
        }
        self.materialise(k)?;
        let active: Vec<u32> = (0..self.pairs.len() as u32)
            .filter(|&i| self.both_present(i, k))
            .collect();
        for &pi in &active {
            self.advance(pi, k);
        }
        let cfg: &'a Config = self.cfg;
        match &cfg.method {
            Method::DoubleThreshold { rules, resolution } => {
                self.decide_double_threshold(&active, k, rules, *resolution);
            }
            Method::NearestNeighbour { window } => self.decide_window(&active, k, *window, false),
            Method::GlobalAssignment { window } => self.decide_window(&active, k, *window, true),
            Method::KNearestNeighbour { k: need, window } => {
                self.decide_knn(&active, k, *need, *window)
            }
        }
        self.next += 1;
        Ok(true)
    }

    /// Pairs currently decided correlated, as (track in a, track in b).
    pub fn correlated(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.pairs
            .iter()
            .filter(|p| p.status == PairStatus::Decided)
            .map(|p| (p.a as usize, p.b as usize))
    }

    /// Trial system tracks of eq. 21 (undecided pairs provisionally output),
    /// as (track in a, track in b).
    pub fn trials(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.pairs
            .iter()
            .filter(|p| p.trial)
            .map(|p| (p.a as usize, p.b as usize))
    }

    /// Every candidate pair with its state, sorted by (a, b).
    pub fn reports(&self) -> Vec<PairReport> {
        let mut out: Vec<PairReport> = self.pairs.iter().map(|p| self.report(p)).collect();
        out.sort_unstable_by_key(|r| (r.a, r.b));
        out
    }

    fn report(&self, p: &Pair) -> PairReport {
        let (m, c, samples, mean, mean_pos) = match (&self.cfg.method, p.status) {
            (Method::DoubleThreshold { .. }, _) => {
                let n = f64::from(p.l.max(1));
                (p.m, p.c, p.l, p.sum_stat / n, p.sum_posdiff / n)
            }
            (
                Method::NearestNeighbour { window }
                | Method::GlobalAssignment { window }
                | Method::KNearestNeighbour { window, .. },
                _,
            ) => {
                let w: Vec<&Sample> = p.hist.iter().rev().take(*window).collect();
                window_counts(&w, self.delta)
            }
        };
        let decision = match p.status {
            PairStatus::Decided => Decision::Correlated,
            PairStatus::Stopped => Decision::NotCorrelated,
            PairStatus::Testing => match p.reason {
                Reason::Testing | Reason::Revoked => Decision::Undecided,
                _ => Decision::NotCorrelated,
            },
        };
        PairReport {
            a: p.a as usize,
            b: p.b as usize,
            decision,
            reason: p.reason,
            trial: p.trial,
            m,
            c,
            samples,
            mean_statistic: if samples == 0 { f64::NAN } else { mean },
            mean_position_difference: if samples == 0 { f64::NAN } else { mean_pos },
            last_statistic: p.hist.back().map_or(f64::NAN, |s| s.stat),
            decided_at: p.decided_at,
            decided_time: p.decided_time,
            last_common: p.last_common.unwrap_or(0),
            cross_covariance: p.cross.as_deref().map(<[f64]>::to_vec),
        }
    }

    fn track_a(&self, t: u32) -> &Track {
        self.scene.track(self.na, t as usize)
    }

    fn track_b(&self, t: u32) -> &Track {
        self.scene.track(self.nb, t as usize)
    }

    /// The pair of tracks (a, b), if it is a candidate.
    fn pair_of(&self, a: u32, b: u32) -> Option<u32> {
        self.adj_a[a as usize]
            .iter()
            .copied()
            .find(|&pi| self.pairs[pi as usize].b == b)
    }

    fn both_present(&self, pi: u32, k: usize) -> bool {
        let p = &self.pairs[pi as usize];
        self.track_a(p.a).is_present(k) && self.track_b(p.b).is_present(k)
    }

    fn is_free(&self, pi: u32) -> bool {
        let p = &self.pairs[pi as usize];
        self.partner_a[p.a as usize].is_none() && self.partner_b[p.b as usize].is_none()
    }

    fn decide(&mut self, pi: u32, k: usize, reason: Reason) {
        let p = &mut self.pairs[pi as usize];
        p.status = PairStatus::Decided;
        p.reason = reason;
        p.trial = false;
        p.decided_at = Some(k);
        p.decided_time = Some(self.scene.time(k));
        let (a, b) = (p.a as usize, p.b as usize);
        self.partner_a[a] = Some(pi);
        self.partner_b[b] = Some(pi);
    }

    fn undecide(&mut self, pi: u32, reason: Reason) {
        let p = &mut self.pairs[pi as usize];
        p.status = PairStatus::Testing;
        p.reason = reason;
        p.decided_at = None;
        p.decided_time = None;
        p.cycle_done = true;
        let (a, b) = (p.a as usize, p.b as usize);
        if self.partner_a[a] == Some(pi) {
            self.partner_a[a] = None;
        }
        if self.partner_b[b] == Some(pi) {
            self.partner_b[b] = None;
        }
    }
}

/// A total order on f64 for sort keys (NaN last).
#[derive(Debug, Clone, Copy, PartialEq)]
struct OrdF64(f64);

impl Eq for OrdF64 {}

impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for OrdF64 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests;
