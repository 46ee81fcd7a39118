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

use std::{
    collections::{HashMap, VecDeque},
    hash::{BuildHasherDefault, Hasher},
};

use nalgebra::{DMatrix, DVector};

use super::{
    rules::LrRule,
    scene::{Scene, Track},
};
use crate::algo::{
    AlgoError, assignment,
    gating::chi2_threshold,
    motion::MotionModel,
    small::{self, MAX_DIM, Sq},
    wire::{Reader, Writer},
};

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
    Fixed(LrRule),
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
        rules: RuleSpec,
        resolution: Resolution,
    },
    /// Greedy nearest neighbour on the mean statistic over the last `window`
    /// common samples, gated by χ²(n·w).
    NearestNeighbour { window: usize },
    /// Global optimal assignment on the same cost and gate.
    GlobalAssignment { window: usize },
    /// K-nearest-neighbour: correlated when the two tracks were each other's
    /// nearest gated neighbour in at least `k` of the last `window` instants.
    KNearestNeighbour { k: usize, window: usize },
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
    pub method: Method,
    pub statistic: Statistic,
    /// Significance level α of the first threshold (eq. 14).
    pub alpha: f64,
    pub pruning: Pruning,
}

/// A pair's decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    Correlated,
    NotCorrelated,
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
    pub decision: Decision,
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
    index: HashMap<(u32, u32), u32, FastHash>,
    adj_a: Vec<Vec<u32>>,
    adj_b: Vec<Vec<u32>>,
    partner_a: Vec<Option<u32>>,
    partner_b: Vec<Option<u32>>,
    /// I − K H per track and instant for the modified statistic.
    factors_a: Vec<Vec<Option<Sq>>>,
    factors_b: Vec<Vec<Option<Sq>>>,
    next: usize,
    /// Tests whose modified S was not positive definite: the weighted
    /// statistic was used for them instead.
    pub singular_tests: usize,
}

#[derive(Debug, Clone)]
struct Sample {
    k: u32,
    stat: f64,
    posdiff: f64,
    hit: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Status {
    Testing,
    Stopped,
    Decided,
}

#[derive(Debug, Clone)]
struct Pair {
    a: u32,
    b: u32,
    status: Status,
    reason: Reason,
    trial: bool,
    l: u32,
    m: u32,
    c: u32,
    sum_stat: f64,
    sum_posdiff: f64,
    cycle_done: bool,
    decided_at: Option<usize>,
    decided_time: Option<f64>,
    hist: VecDeque<Sample>,
    cross: Option<Sq>,
    last_common: Option<usize>,
}

/// The evolving state of a [`PairCorrelator`] (its candidate pairs with
/// their counters, history windows and cross-covariances, the decided
/// partners and the next instant), detached from the scene so that a
/// streaming session can keep it between batches and persist it.
#[derive(Debug, Clone, Default)]
pub struct CorrelatorState {
    pairs: Vec<Pair>,
    partner_a: Vec<Option<u32>>,
    partner_b: Vec<Option<u32>>,
    next: usize,
    singular_tests: usize,
}

/// Which node of a correlated pair a track belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    A,
    B,
}

const STATUSES: [Status; 3] = [Status::Testing, Status::Stopped, Status::Decided];
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

fn bad(reason: &str) -> AlgoError {
    AlgoError::InvalidParameter {
        what: "state",
        reason: format!("corrupt correlator state: {reason}"),
    }
}

impl CorrelatorState {
    /// The next instant (global index) the correlator will process.
    pub fn next(&self) -> usize {
        self.next
    }

    /// Every candidate pair as (track in a, track in b, decided correlated,
    /// trial system track), in the order held.
    pub fn links(&self) -> impl Iterator<Item = (usize, usize, bool, bool)> + '_ {
        self.pairs.iter().map(|p| {
            (
                p.a as usize,
                p.b as usize,
                p.status == Status::Decided,
                p.trial,
            )
        })
    }

    /// Candidate pairs held.
    pub fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// Forgets every pair of track `t` on `side` (a retired track): its
    /// decided partner, if any, becomes free.
    pub fn release(&mut self, side: Side, t: usize) {
        let t = t as u32;
        let gone = |p: &Pair| match side {
            Side::A => p.a == t,
            Side::B => p.b == t,
        };
        if !self.pairs.iter().any(gone) {
            return;
        }
        let mut remap = vec![None; self.pairs.len()];
        let mut kept = Vec::with_capacity(self.pairs.len());
        for (i, p) in std::mem::take(&mut self.pairs).into_iter().enumerate() {
            if !gone(&p) {
                remap[i] = Some(kept.len() as u32);
                kept.push(p);
            }
        }
        self.pairs = kept;
        for slot in self.partner_a.iter_mut().chain(self.partner_b.iter_mut()) {
            *slot = slot.and_then(|pi| remap[pi as usize]);
        }
    }

    /// Appends the state to `w` (the format of [`CorrelatorState::decode`]);
    /// matrices hold `dim` × `dim` values.
    pub fn encode(&self, w: &mut Writer, dim: usize) {
        w.usize(self.next);
        w.usize(self.singular_tests);
        for partners in [&self.partner_a, &self.partner_b] {
            w.usize(partners.len());
            for p in partners {
                w.opt(*p, |w, v| w.u32(v));
            }
        }
        w.usize(self.pairs.len());
        for p in &self.pairs {
            w.u32(p.a);
            w.u32(p.b);
            w.u8(STATUSES
                .iter()
                .position(|&s| s == p.status)
                .expect("listed") as u8);
            w.u8(REASONS.iter().position(|&r| r == p.reason).expect("listed") as u8);
            w.bool(p.trial);
            w.u32(p.l);
            w.u32(p.m);
            w.u32(p.c);
            w.f64(p.sum_stat);
            w.f64(p.sum_posdiff);
            w.bool(p.cycle_done);
            w.opt(p.decided_at, Writer::usize);
            w.opt(p.decided_time, Writer::f64);
            w.usize(p.hist.len());
            for h in &p.hist {
                w.u32(h.k);
                w.f64(h.stat);
                w.f64(h.posdiff);
                w.bool(h.hit);
            }
            w.opt(p.cross.as_ref(), |w, c| {
                for &v in &c[..dim * dim] {
                    w.f64(v);
                }
            });
            w.opt(p.last_common, Writer::usize);
        }
    }

    /// Reads a state written by [`CorrelatorState::encode`], checking every
    /// index so that a corrupt buffer cannot make the engine panic later.
    pub fn decode(r: &mut Reader<'_>, dim: usize) -> Result<Self, AlgoError> {
        let next = r.usize()?;
        let singular_tests = r.usize()?;
        let mut partners = [Vec::new(), Vec::new()];
        for list in &mut partners {
            let n = r.len(1)?;
            *list = (0..n)
                .map(|_| r.opt(Reader::u32))
                .collect::<Result<_, _>>()?;
        }
        let [partner_a, partner_b] = partners;
        let n = r.len(40)?;
        let mut pairs = Vec::with_capacity(n);
        for _ in 0..n {
            let a = r.u32()?;
            let b = r.u32()?;
            let status = *STATUSES
                .get(r.u8()? as usize)
                .ok_or_else(|| bad("status"))?;
            let reason = *REASONS.get(r.u8()? as usize).ok_or_else(|| bad("reason"))?;
            let trial = r.bool()?;
            let (l, m, c) = (r.u32()?, r.u32()?, r.u32()?);
            let (sum_stat, sum_posdiff) = (r.f64()?, r.f64()?);
            let cycle_done = r.bool()?;
            let decided_at = r.opt(Reader::usize)?;
            let decided_time = r.opt(Reader::f64)?;
            let h = r.len(21)?;
            let mut hist = VecDeque::with_capacity(h);
            for _ in 0..h {
                hist.push_back(Sample {
                    k: r.u32()?,
                    stat: r.f64()?,
                    posdiff: r.f64()?,
                    hit: r.bool()?,
                });
            }
            let cross = r.opt(|r| {
                let mut c = small::ZERO;
                for v in &mut c[..dim * dim] {
                    *v = r.f64()?;
                }
                Ok(c)
            })?;
            let last_common = r.opt(Reader::usize)?;
            if a as usize >= partner_a.len() || b as usize >= partner_b.len() {
                return Err(bad("pair names an unknown track"));
            }
            pairs.push(Pair {
                a,
                b,
                status,
                reason,
                trial,
                l,
                m,
                c,
                sum_stat,
                sum_posdiff,
                cycle_done,
                decided_at,
                decided_time,
                hist,
                cross,
                last_common,
            });
        }
        let n_pairs = pairs.len();
        if partner_a
            .iter()
            .chain(&partner_b)
            .flatten()
            .any(|&pi| pi as usize >= n_pairs)
        {
            return Err(bad("partner names an unknown pair"));
        }
        Ok(Self {
            pairs,
            partner_a,
            partner_b,
            next,
            singular_tests,
        })
    }
}

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
            index: HashMap::default(),
            adj_a: vec![Vec::new(); ta],
            adj_b: vec![Vec::new(); tb],
            partner_a: vec![None; ta],
            partner_b: vec![None; tb],
            factors_a: Vec::new(),
            factors_b: Vec::new(),
            next: 0,
            singular_tests: 0,
        };
        if cfg.statistic == Statistic::Modified {
            me.factors_a = filter_factors(scene, na, me.model)?;
            me.factors_b = filter_factors(scene, nb, me.model)?;
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
            me.index.insert((p.a, p.b), pi as u32);
            me.adj_a[p.a as usize].push(pi as u32);
            me.adj_b[p.b as usize].push(pi as u32);
        }
        me.pairs = state.pairs;
        Ok(me)
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
    pub fn run(&mut self) {
        while self.step() {}
    }

    /// Processes the instants before global index `end`.
    pub fn run_until(&mut self, end: usize) {
        while self.next < end && self.step() {}
    }

    /// Processes the next instant; false when there is none.
    pub fn step(&mut self) -> bool {
        let k = self.next;
        if k >= self.scene.end() {
            return false;
        }
        self.materialise(k);
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
        true
    }

    /// Pairs currently decided correlated, as (track in a, track in b).
    pub fn correlated(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.pairs
            .iter()
            .filter(|p| p.status == Status::Decided)
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
            Status::Decided => Decision::Correlated,
            Status::Stopped => Decision::NotCorrelated,
            Status::Testing => match p.reason {
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
            cross_covariance: p.cross.map(|c| c[..self.dim * self.dim].to_vec()),
        }
    }

    fn track_a(&self, t: u32) -> &Track {
        self.scene.track(self.na, t as usize)
    }

    fn track_b(&self, t: u32) -> &Track {
        self.scene.track(self.nb, t as usize)
    }

    fn both_present(&self, pi: u32, k: usize) -> bool {
        let p = &self.pairs[pi as usize];
        self.track_a(p.a).is_present(k) && self.track_b(p.b).is_present(k)
    }

    /// Creates the pairs that pass the spatial gate at instant `k` for the
    /// first time, replaying their earlier common instants.
    fn materialise(&mut self, k: usize) {
        let present_a: Vec<u32> = (0..self.adj_a.len() as u32)
            .filter(|&t| self.track_a(t).is_present(k))
            .collect();
        let present_b: Vec<u32> = (0..self.adj_b.len() as u32)
            .filter(|&t| self.track_b(t).is_present(k))
            .collect();
        let candidates = match self.cfg.pruning {
            Pruning::None => self.all_pairs_candidates(k, &present_a, &present_b),
            Pruning::Grid => self.spatial_candidates(k, &present_a, &present_b),
        };
        for (a, b) in candidates {
            if self.index.contains_key(&(a, b)) {
                continue;
            }
            let pi = self.pairs.len() as u32;
            self.pairs.push(Pair {
                a,
                b,
                status: Status::Testing,
                reason: Reason::Testing,
                trial: false,
                l: 0,
                m: 0,
                c: 0,
                sum_stat: 0.0,
                sum_posdiff: 0.0,
                cycle_done: false,
                decided_at: None,
                decided_time: None,
                hist: VecDeque::with_capacity(self.hist_len + 1),
                cross: None,
                last_common: None,
            });
            self.index.insert((a, b), pi);
            self.adj_a[a as usize].push(pi);
            self.adj_b[b as usize].push(pi);
            // Instants before the scene's window are gone (a streaming
            // session keeps a bounded history): the replay starts there.
            for j in self.scene.first()..k {
                if self.both_present(pi, j) {
                    self.advance(pi, j);
                    self.close_cycle(pi);
                }
            }
        }
    }

    /// d = x_a − x_b and S = P_a + P_b at instant `k` (eq. 10), on the stack.
    fn difference(&self, a: u32, b: u32, k: usize) -> ([f64; MAX_DIM], Sq) {
        let dim = self.dim;
        let (ta, tb) = (self.track_a(a), self.track_b(b));
        let (xa, xb, pa, pb) = (ta.x(k, dim), tb.x(k, dim), ta.p(k, dim), tb.p(k, dim));
        let mut d = [0.0; MAX_DIM];
        for i in 0..dim {
            d[i] = xa[i] - xb[i];
        }
        let mut s = small::ZERO;
        for i in 0..dim * dim {
            s[i] = pa[i] + pb[i];
        }
        (d, s)
    }

    /// How far the weighted bound may be exceeded by a pair that can still
    /// pass: 1 for the weighted statistic, 2 for the modified one (S_mod ≤
    /// 2 (P_a + P_b)).
    fn gate_factor(&self) -> f64 {
        match self.cfg.statistic {
            Statistic::Weighted => 1.0,
            Statistic::Modified => 2.0,
        }
    }

    /// Brute force: the weighted statistic of every pair present at `k`; a
    /// pair may pass when α ≤ δ (weighted) or α ≤ 2δ (modified, since
    /// S_mod ≤ 2 (P_a + P_b) makes β ≥ α / 2).
    fn all_pairs_candidates(
        &self,
        k: usize,
        present_a: &[u32],
        present_b: &[u32],
    ) -> Vec<(u32, u32)> {
        let dim = self.dim;
        let limit = self.gate_factor() * self.delta;
        let mut out = Vec::new();
        for &a in present_a {
            for &b in present_b {
                let (d, s) = self.difference(a, b, k);
                if small::quad_form_inv(&s, &d, dim).is_some_and(|q| q <= limit) {
                    out.push((a, b));
                }
            }
        }
        out
    }

    /// The pairs (a, b) present at `k` that may pass the χ² test.
    fn spatial_candidates(
        &self,
        k: usize,
        present_a: &[u32],
        present_b: &[u32],
    ) -> Vec<(u32, u32)> {
        let dim = self.dim;
        let pos = self.scene.position_indices();
        let factor = self.gate_factor();
        let reach2 = |t: &Track| factor * self.delta * small::trace_bound(t.p(k, dim), dim, pos);
        let point = |t: &Track| {
            let x = t.x(k, dim);
            let mut c = [0.0; 3];
            for (i, &j) in pos.iter().enumerate() {
                c[i] = x[j];
            }
            c
        };
        let b_pts: Vec<([f64; 3], f64)> = present_b
            .iter()
            .map(|&t| {
                let tr = self.track_b(t);
                (point(tr), reach2(tr))
            })
            .collect();
        let max_rb = b_pts.iter().map(|p| p.1.sqrt()).fold(0.0, f64::max);
        let max_ra = present_a
            .iter()
            .map(|&t| reach2(self.track_a(t)).sqrt())
            .fold(0.0, f64::max);
        // A cell as wide as the largest reach: a typical query then spans
        // 3 cells per axis.
        let cell = (max_ra + max_rb).max(1e-6);
        let key = |c: &[f64; 3]| {
            [
                (c[0] / cell).floor() as i64,
                (c[1] / cell).floor() as i64,
                (c[2] / cell).floor() as i64,
            ]
        };
        // The grid as a sorted list of (cell, track): one allocation, and a
        // cell's tracks are a contiguous run found by binary search.
        let mut grid: Vec<([i64; 3], u32)> = b_pts
            .iter()
            .enumerate()
            .map(|(i, (c, _))| (key(c), i as u32))
            .collect();
        grid.sort_unstable();
        let occupied = grid.windows(2).filter(|w| w[0].0 != w[1].0).count() + 1;
        let dims_used = pos.len();
        let mut out = Vec::new();
        for &a in present_a {
            let ta = self.track_a(a);
            let (ca, ra2) = (point(ta), reach2(ta));
            let reach = ra2.sqrt() + max_rb;
            let span = (reach / cell).ceil();
            let test = |i: u32, out: &mut Vec<(u32, u32)>| {
                let (cb, rb2) = b_pts[i as usize];
                let d2: f64 = (0..3).map(|j| (ca[j] - cb[j]).powi(2)).sum();
                if d2 <= ra2 + rb2 {
                    out.push((a, present_b[i as usize]));
                }
            };
            let cells = (2.0 * span + 1.0).powi(dims_used as i32);
            if !span.is_finite() || cells > occupied as f64 {
                for i in 0..b_pts.len() as u32 {
                    test(i, &mut out);
                }
                continue;
            }
            let (span, base) = (span as i64, key(&ca));
            let range = |d: usize| {
                if d < dims_used {
                    (base[d] - span)..=(base[d] + span)
                } else {
                    base[d]..=base[d]
                }
            };
            for x in range(0) {
                for y in range(1) {
                    for z in range(2) {
                        let cell = [x, y, z];
                        let from = grid.partition_point(|e| e.0 < cell);
                        for &(c, i) in &grid[from..] {
                            if c != cell {
                                break;
                            }
                            test(i, &mut out);
                        }
                    }
                }
            }
        }
        out
    }

    /// Computes the statistic of pair `pi` at instant `k` and updates its
    /// counters (or, once decided, its monitoring window).
    fn advance(&mut self, pi: u32, k: usize) {
        let dim = self.dim;
        let (a, b) = {
            let p = &self.pairs[pi as usize];
            (p.a, p.b)
        };
        if self.cfg.statistic == Statistic::Modified {
            self.update_cross(pi, k);
        }
        let (d, s) = self.difference(a, b, k);
        let mut stat = None;
        if let Some(cross) = &self.pairs[pi as usize].cross {
            let mut s_mod = s;
            for i in 0..dim {
                for j in 0..dim {
                    s_mod[i * dim + j] -= cross[i * dim + j] + cross[j * dim + i];
                }
            }
            stat = small::quad_form_inv(&s_mod, &d, dim);
            if stat.is_none() {
                // P_a + P_b − P_ab − P_ab' is a covariance only when the
                // reported covariances, gains and model are consistent;
                // otherwise fall back to the weighted statistic.
                self.singular_tests += 1;
            }
        }
        let stat = stat
            .or_else(|| small::quad_form_inv(&s, &d, dim))
            .unwrap_or(f64::INFINITY);
        let posdiff = self
            .scene
            .position_indices()
            .iter()
            .map(|&i| d[i] * d[i])
            .sum::<f64>()
            .sqrt();
        let pass = stat <= self.delta;
        let (hist_len, rf) = (self.hist_len, self.final_rule());
        let p = &mut self.pairs[pi as usize];
        p.last_common = Some(k);
        if p.cycle_done {
            p.l = 0;
            p.m = 0;
            p.c = 0;
            p.sum_stat = 0.0;
            p.sum_posdiff = 0.0;
            p.cycle_done = false;
            if p.status == Status::Stopped {
                p.status = Status::Testing;
            }
            p.reason = Reason::Testing;
        }
        p.hist.push_back(Sample {
            k: k as u32,
            stat,
            posdiff,
            hit: false,
        });
        if p.hist.len() > hist_len {
            p.hist.pop_front();
        }
        p.l += 1;
        if pass {
            p.m += 1;
        } else {
            p.c += 1;
        }
        p.sum_stat += stat;
        p.sum_posdiff += posdiff;
        if let Some((l_final, r_final)) = rf
            && p.status == Status::Testing
            && p.c > r_final - l_final
        {
            p.status = Status::Stopped;
            p.reason = Reason::EarlyStop;
        }
    }

    /// The final rule (L, R) of a double-threshold method.
    fn final_rule(&self) -> Option<(u32, u32)> {
        match &self.cfg.method {
            Method::DoubleThreshold { rules, .. } => {
                let r = final_rule(rules);
                Some((r.l(), r.r()))
            }
            _ => None,
        }
    }

    /// Ends the cycle of a pair that has used R samples without a decision
    /// (seed 000 §3.3: such tracks enter the next cycle).
    fn close_cycle(&mut self, pi: u32) {
        let Some((l_final, r_final)) = self.final_rule() else {
            return;
        };
        let p = &mut self.pairs[pi as usize];
        if p.status != Status::Decided && p.l >= r_final {
            p.cycle_done = true;
            if p.status == Status::Testing && p.m < l_final && p.reason == Reason::Testing {
                p.reason = Reason::BelowRule;
            }
        }
    }

    /// Eq. 13: P_ab(k) = A_a(k) [Φ P_ab(k⁻) Φ' + G Q G'] A_b(k)', A = I − K H,
    /// from P_ab = 0 at the pair's first common instant. (The paper prints the
    /// last factor without the transpose; the covariance of the two filters'
    /// errors needs it.)
    fn update_cross(&mut self, pi: u32, k: usize) {
        let dim = self.dim;
        let (a, b, prev, cross) = {
            let p = &self.pairs[pi as usize];
            (p.a, p.b, p.last_common, p.cross)
        };
        let new = match (prev, cross) {
            // A last common instant before the held window restarts the
            // recursion from P_ab = 0 (streaming sessions only).
            (Some(kp), Some(c)) if kp >= self.scene.first() => {
                let dt = self.scene.time(k) - self.scene.time(kp);
                let (ta, tb) = (self.track_a(a), self.track_b(b));
                let mean: DVector<f64> = DVector::from_iterator(
                    dim,
                    (0..dim).map(|i| 0.5 * (ta.x(kp, dim)[i] + tb.x(kp, dim)[i])),
                );
                let model = self.model.expect("checked in new");
                let (Ok(f), Ok(q)) = (model.transition(dt), model.process_noise(dt, &mean)) else {
                    self.pairs[pi as usize].cross = Some(small::ZERO);
                    return;
                };
                let f = small::to_sq(&f);
                let q = small::to_sq(&q);
                let fc = small::mul(&f, &c, dim);
                let mut mid = small::mul_t(&fc, &f, dim);
                for i in 0..dim * dim {
                    mid[i] += q[i];
                }
                let first = self.scene.first();
                let fa = self.factors_a[a as usize][k - first];
                let fb = self.factors_b[b as usize][k - first];
                let left = match fa {
                    Some(fa) => small::mul(&fa, &mid, dim),
                    None => mid,
                };
                match fb {
                    Some(fb) => small::mul_t(&left, &fb, dim),
                    None => left,
                }
            }
            _ => small::ZERO,
        };
        self.pairs[pi as usize].cross = Some(new);
    }

    fn is_free(&self, pi: u32) -> bool {
        let p = &self.pairs[pi as usize];
        self.partner_a[p.a as usize].is_none() && self.partner_b[p.b as usize].is_none()
    }

    fn decide(&mut self, pi: u32, k: usize, reason: Reason) {
        let p = &mut self.pairs[pi as usize];
        p.status = Status::Decided;
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
        p.status = Status::Testing;
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

    fn decide_double_threshold(
        &mut self,
        active: &[u32],
        k: usize,
        rules: &RuleSpec,
        resolution: Resolution,
    ) {
        let last = final_rule(rules);
        let (lf, rf) = (last.l(), last.r());
        // Decided pairs keep being tested; a pair whose recent samples no
        // longer meet the rule is revoked and both tracks are freed.
        for &pi in active {
            let p = &self.pairs[pi as usize];
            if p.status != Status::Decided || p.decided_at == Some(k) {
                continue;
            }
            let window = monitor_window(p, rf as usize);
            let w = window.len();
            let fails = window.iter().filter(|s| s.stat > self.delta).count() as u32;
            let allowed = match rules {
                RuleSpec::Fixed(_) => rf - lf,
                RuleSpec::Schedule(s) => {
                    let r = s[w.min(s.len()) - 1];
                    r.r() - r.l()
                }
            };
            if fails > allowed {
                self.undecide(pi, Reason::Revoked);
            }
        }

        let rule_at = |l: u32| -> LrRule {
            match rules {
                RuleSpec::Fixed(r) => *r,
                RuleSpec::Schedule(s) => s[(l as usize).clamp(1, s.len()) - 1],
            }
        };
        let qualified = |me: &Self, pi: u32| {
            let p = &me.pairs[pi as usize];
            p.status == Status::Testing
                && !p.cycle_done
                && p.l > 0
                && p.m >= rule_at(p.l).l()
                && me.is_free(pi)
        };
        let competitors = |me: &Self, pi: u32| -> Vec<u32> {
            let p = &me.pairs[pi as usize];
            me.adj_a[p.a as usize]
                .iter()
                .chain(me.adj_b[p.b as usize].iter())
                .copied()
                .filter(|&q| q != pi && qualified(me, q))
                .collect()
        };
        let key = |me: &Self, pi: u32| {
            let p = &me.pairs[pi as usize];
            (
                std::cmp::Reverse(p.m),
                OrdF64(p.sum_stat / f64::from(p.l.max(1))),
                p.a,
                p.b,
            )
        };
        let is_schedule = matches!(rules, RuleSpec::Schedule(_));
        let mut ready: Vec<u32> = active
            .iter()
            .copied()
            .filter(|&pi| {
                qualified(self, pi)
                    && (is_schedule
                        || self.pairs[pi as usize].l >= rf
                        || competitors(self, pi).is_empty())
            })
            .collect();
        ready.sort_by_key(|&pi| key(self, pi));

        match resolution {
            Resolution::Greedy => {
                for pi in ready {
                    if !qualified(self, pi) {
                        // A better-ranked pair took one of its tracks.
                        self.pairs[pi as usize].reason = Reason::AmbiguityLost;
                        continue;
                    }
                    let rivals = competitors(self, pi);
                    let mine = key(self, pi);
                    if rivals.iter().any(|&q| key(self, q) < mine) {
                        self.pairs[pi as usize].reason = Reason::AmbiguityLost;
                        continue;
                    }
                    let p = &self.pairs[pi as usize];
                    let reason = if rivals.is_empty() {
                        if !is_schedule && p.l < rf {
                            Reason::EarlyDecision
                        } else {
                            Reason::Threshold
                        }
                    } else if rivals.iter().all(|&q| self.pairs[q as usize].m < p.m) {
                        Reason::AmbiguityMaxM
                    } else {
                        Reason::AmbiguityMinMeanStatistic
                    };
                    self.decide(pi, k, reason);
                }
            }
            Resolution::Assignment => {
                let edges: Vec<(usize, usize, f64)> = ready
                    .iter()
                    .map(|&pi| {
                        let p = &self.pairs[pi as usize];
                        let mean = p.sum_stat / f64::from(p.l.max(1));
                        // Lexicographic: fewer misses first, then a smaller
                        // mean statistic (mapped into [0, 1)).
                        let cost = f64::from(rf.saturating_sub(p.m)) + mean / (1.0 + mean);
                        (p.a as usize, p.b as usize, cost)
                    })
                    .collect();
                let chosen = assignment::solve(&edges, f64::from(rf) + 2.0);
                for (a, b) in chosen {
                    let pi = self.index[&(a as u32, b as u32)];
                    let reason = if competitors(self, pi).is_empty() {
                        if !is_schedule && self.pairs[pi as usize].l < rf {
                            Reason::EarlyDecision
                        } else {
                            Reason::Threshold
                        }
                    } else {
                        Reason::Assignment
                    };
                    self.decide(pi, k, reason);
                }
                for pi in ready {
                    if self.pairs[pi as usize].status != Status::Decided {
                        self.pairs[pi as usize].reason = Reason::AmbiguityLost;
                    }
                }
            }
        }

        for &pi in active {
            self.close_cycle(pi);
        }

        // Trial system tracks (eq. 21): among undecided pairs of free tracks,
        // the largest m, then the smallest C, then the smallest mean norm of
        // the position difference.
        for p in &mut self.pairs {
            p.trial = false;
        }
        let mut trial: Vec<u32> = active
            .iter()
            .copied()
            .filter(|&pi| {
                let p = &self.pairs[pi as usize];
                p.status == Status::Testing && !p.cycle_done && p.m >= 1 && self.is_free(pi)
            })
            .collect();
        trial.sort_by_key(|&pi| {
            let p = &self.pairs[pi as usize];
            (
                std::cmp::Reverse(p.m),
                p.c,
                OrdF64(p.sum_posdiff / f64::from(p.l.max(1))),
                p.a,
                p.b,
            )
        });
        let mut used_a = vec![false; self.adj_a.len()];
        let mut used_b = vec![false; self.adj_b.len()];
        for pi in trial {
            let (a, b) = {
                let p = &self.pairs[pi as usize];
                (p.a as usize, p.b as usize)
            };
            if !used_a[a] && !used_b[b] {
                used_a[a] = true;
                used_b[b] = true;
                self.pairs[pi as usize].trial = true;
            }
        }
    }

    /// Memoryless baselines over the last `window` common samples: nearest
    /// neighbour (greedy) or global optimal assignment.
    fn decide_window(&mut self, active: &[u32], k: usize, window: usize, optimal: bool) {
        for &pi in active {
            if self.pairs[pi as usize].status == Status::Decided {
                self.undecide(pi, Reason::Testing);
            }
            self.pairs[pi as usize].cycle_done = false;
        }
        // (pair, normalised cost = sum / gate(w)); gated when cost ≤ 1.
        let mut gated: Vec<(u32, f64)> = Vec::new();
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let w: Vec<&Sample> = p.hist.iter().rev().take(window).collect();
            let sum: f64 = w.iter().map(|s| s.stat).sum();
            let cost = sum / self.window_gate[w.len()];
            if cost <= 1.0 {
                gated.push((pi, cost));
            } else {
                self.pairs[pi as usize].reason = Reason::Gate;
                self.pairs[pi as usize].status = Status::Testing;
            }
        }
        let chosen: Vec<u32> = if optimal {
            let edges: Vec<_> = gated
                .iter()
                .map(|&(pi, c)| {
                    let p = &self.pairs[pi as usize];
                    (p.a as usize, p.b as usize, c)
                })
                .collect();
            // Normalised costs are ≤ 1 inside the gate: leaving a track
            // unpaired costs 1, as much as the worst gated pair.
            assignment::solve(&edges, 1.0 + 1e-12)
                .into_iter()
                .map(|(a, b)| self.index[&(a as u32, b as u32)])
                .collect()
        } else {
            gated.sort_by_key(|&(pi, c)| {
                let p = &self.pairs[pi as usize];
                (OrdF64(c), p.a, p.b)
            });
            let mut used_a = vec![false; self.adj_a.len()];
            let mut used_b = vec![false; self.adj_b.len()];
            let mut out = Vec::new();
            for (pi, _) in &gated {
                let p = &self.pairs[*pi as usize];
                if !used_a[p.a as usize] && !used_b[p.b as usize] {
                    used_a[p.a as usize] = true;
                    used_b[p.b as usize] = true;
                    out.push(*pi);
                }
            }
            out
        };
        for &(pi, _) in &gated {
            self.pairs[pi as usize].reason = Reason::Conflict;
        }
        let reason = if optimal {
            Reason::Assignment
        } else {
            Reason::NearestNeighbour
        };
        for pi in chosen {
            self.decide(pi, k, reason);
        }
    }

    /// K-nearest-neighbour: mutual nearest gated neighbours in ≥ k of the
    /// last `window` instants.
    fn decide_knn(&mut self, active: &[u32], k: usize, need: usize, window: usize) {
        for &pi in active {
            if self.pairs[pi as usize].status == Status::Decided {
                self.undecide(pi, Reason::Testing);
            }
            self.pairs[pi as usize].cycle_done = false;
        }
        let mut best_a: HashMap<u32, (f64, u32)> = HashMap::new();
        let mut best_b: HashMap<u32, (f64, u32)> = HashMap::new();
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let stat = p.hist.back().map_or(f64::INFINITY, |s| s.stat);
            if stat > self.delta {
                continue;
            }
            for (map, t) in [(&mut best_a, p.a), (&mut best_b, p.b)] {
                let e = map.entry(t).or_insert((f64::INFINITY, u32::MAX));
                if (stat, pi) < *e {
                    *e = (stat, pi);
                }
            }
        }
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let hit = best_a.get(&p.a).is_some_and(|e| e.1 == pi)
                && best_b.get(&p.b).is_some_and(|e| e.1 == pi);
            if let Some(s) = self.pairs[pi as usize].hist.back_mut() {
                s.hit = hit;
            }
        }
        let mut cands: Vec<(u32, usize, f64)> = Vec::new();
        for &pi in active {
            let p = &self.pairs[pi as usize];
            let w: Vec<&Sample> = p.hist.iter().rev().take(window).collect();
            let hits = w.iter().filter(|s| s.hit).count();
            let mean = w.iter().map(|s| s.stat).sum::<f64>() / w.len().max(1) as f64;
            if hits >= need {
                cands.push((pi, hits, mean));
            } else {
                self.pairs[pi as usize].reason = Reason::Gate;
            }
        }
        cands.sort_by_key(|&(pi, hits, mean)| {
            let p = &self.pairs[pi as usize];
            (std::cmp::Reverse(hits), OrdF64(mean), p.a, p.b)
        });
        for (pi, _, _) in cands {
            if self.is_free(pi) {
                self.decide(pi, k, Reason::KOfN);
            } else {
                self.pairs[pi as usize].reason = Reason::Conflict;
            }
        }
    }
}

/// The last rule of a rule specification (the one in force after R samples).
pub fn final_rule(rules: &RuleSpec) -> LrRule {
    match rules {
        RuleSpec::Fixed(r) => *r,
        RuleSpec::Schedule(s) => *s.last().expect("validated non-empty"),
    }
}

/// The default dynamic schedule of seed 000 §3.3 (1/1, 2/2, 2/3, 3/4, 4/5,
/// 4/6, 5/7, 6/8). The paper lists both 3/5 and 4/5 for five samples; one
/// rule per sample count is needed, and 4/5 keeps L/R ≥ 0.75 like 3/4 and 6/8.
pub fn default_schedule() -> Vec<LrRule> {
    [
        (1, 1),
        (2, 2),
        (2, 3),
        (3, 4),
        (4, 5),
        (4, 6),
        (5, 7),
        (6, 8),
    ]
    .into_iter()
    .map(|(l, r)| LrRule::new(l, r).expect("valid rules"))
    .collect()
}

fn check_rules(rules: &RuleSpec) -> Result<(), AlgoError> {
    if let RuleSpec::Schedule(s) = rules {
        if s.is_empty() {
            return Err(AlgoError::InvalidParameter {
                what: "schedule",
                reason: "must hold at least one rule".into(),
            });
        }
        for (i, r) in s.iter().enumerate() {
            if r.r() as usize != i + 1 {
                return Err(AlgoError::InvalidParameter {
                    what: "schedule",
                    reason: format!(
                        "entry {i} is used after {} samples, so its r must be {}",
                        i + 1,
                        i + 1
                    ),
                });
            }
        }
    }
    Ok(())
}

fn check_window(window: usize) -> Result<(), AlgoError> {
    if window == 0 || window > 64 {
        return Err(AlgoError::InvalidParameter {
            what: "window",
            reason: "must be between 1 and 64".into(),
        });
    }
    Ok(())
}

/// The samples after the decision, at most the last `r`.
fn monitor_window(p: &Pair, r: usize) -> Vec<&Sample> {
    let since = p.decided_at.unwrap_or(0) as u32;
    p.hist
        .iter()
        .rev()
        .filter(|s| s.k >= since)
        .take(r)
        .collect()
}

/// (m, C, samples, mean statistic, mean position difference) of a window.
fn window_counts(w: &[&Sample], delta: f64) -> (u32, u32, u32, f64, f64) {
    let n = w.len() as u32;
    let m = w.iter().filter(|s| s.stat <= delta).count() as u32;
    let denom = f64::from(n.max(1));
    let mean = w.iter().map(|s| s.stat).sum::<f64>() / denom;
    let mean_pos = w.iter().map(|s| s.posdiff).sum::<f64>() / denom;
    (m, n - m, n, mean, mean_pos)
}

/// I − K H for every track of a node at every instant: reported, or
/// recomputed as P(k|k) P(k|k−1)⁻¹ with P(k|k−1) = Φ P(k⁻|k⁻) Φ' + Q from the
/// track's previous instant k⁻ (for the optimal gain, P(k|k) = (I − K H) P(k|k−1)).
/// `None` at a track's first instant, where no prediction exists.
fn filter_factors(
    scene: &Scene,
    node: usize,
    model: Option<&dyn MotionModel>,
) -> Result<Vec<Vec<Option<Sq>>>, AlgoError> {
    let dim = scene.dim();
    let model = model.expect("checked by the caller");
    let (first, end) = (scene.first(), scene.end());
    let mut out = Vec::with_capacity(scene.nodes()[node].len());
    for track in &scene.nodes()[node] {
        let mut per = vec![None; end - first];
        let mut prev: Option<usize> = None;
        for (k, slot) in (first..end).zip(per.iter_mut()) {
            if !track.is_present(k) {
                continue;
            }
            if let Some(g) = track.gain_factor(k, dim) {
                let mut s = small::ZERO;
                s[..dim * dim].copy_from_slice(g);
                *slot = Some(s);
            } else if let Some(kp) = prev {
                *slot = filter_factor(
                    model,
                    track.x(kp, dim),
                    track.p(kp, dim),
                    track.p(k, dim),
                    scene.time(k) - scene.time(kp),
                )?;
            }
            prev = Some(k);
        }
        out.push(per);
    }
    Ok(out)
}

/// The filter factor A = I − K H of a track at one sample, recovered from
/// its covariances when the gain was not reported: P(k|k) = A P(k|k−1), so
/// A = P(k|k) P(k|k−1)⁻¹ with P(k|k−1) the previous covariance `p_prev`
/// (at state `x_prev`) predicted over `dt`. `None` when the prediction is
/// not positive definite.
pub fn filter_factor(
    model: &dyn MotionModel,
    x_prev: &[f64],
    p_prev: &[f64],
    p_now: &[f64],
    dt: f64,
) -> Result<Option<Sq>, AlgoError> {
    let dim = x_prev.len();
    let x = DVector::from_column_slice(x_prev);
    let p_prev = DMatrix::from_row_slice(dim, dim, p_prev);
    let (_, p_pred) = model.predict(&x, &p_prev, dt)?;
    let p_now = DMatrix::from_row_slice(dim, dim, p_now);
    // A = P(k|k) P⁻¹ = (P⁻¹ P(k|k))' since both are symmetric.
    Ok(p_pred.cholesky().map(|chol| {
        let at = chol.solve(&p_now);
        small::to_sq(&at.transpose())
    }))
}

/// A multiplicative hasher for the engine's small integer keys (pair and
/// grid-cell indices, never attacker-chosen strings), much cheaper than SipHash.
type FastHash = BuildHasherDefault<MulHasher>;

#[derive(Default)]
struct MulHasher(u64);

impl Hasher for MulHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u32(&mut self, i: u32) {
        self.write_u64(u64::from(i));
    }

    fn write_i64(&mut self, i: i64) {
        self.write_u64(i as u64);
    }

    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
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
mod tests {
    use super::*;
    use crate::algo::motion::{ConstantVelocity, ProcessNoise};
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
        c.run();
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
        c.step();
        let r = c.reports();
        assert_eq!((r[0].m, r[0].c, r[0].reason), (1, 0, Reason::Testing));
        assert!(
            r[0].trial,
            "the only pair with m ≥ 1 is a trial system track"
        );
        c.step();
        let r = c.reports();
        assert_eq!((r[0].m, r[0].c, r[0].decision), (1, 1, Decision::Undecided));
        c.step();
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
        c.step();
        assert_eq!(c.correlated().collect::<Vec<_>>(), vec![(0, 0)]);
        c.step();
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
        c.step();
        assert!((c.reports()[0].last_statistic - 0.05).abs() < 1e-15);
        c.step();
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
            c.run();
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
        c.run();
        assert_eq!(c.correlated().collect::<Vec<_>>(), vec![(0, 0)]);
        let optimal = Config {
            method: Method::GlobalAssignment { window: 1 },
            ..dt(1, 1)
        };
        let mut c = PairCorrelator::new(&s, 0, 1, &optimal, None).unwrap();
        c.run();
        let mut got: Vec<_> = c.correlated().collect();
        got.sort();
        assert_eq!(got, vec![(0, 1), (1, 0)]);
    }

    fn decisions(s: &Scene, cfg: &Config) -> Vec<Vec<(usize, usize)>> {
        let mut c = PairCorrelator::new(s, 0, 1, cfg, None).unwrap();
        let mut out = Vec::new();
        while c.step() {
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
}
