//! The correlation result: the pairs, the system tracks and their wire
//! names (the one vocabulary of REST and gRPC).

use algo::correlation::engine::{Decision, PairReport, Reason, Statistic};

use super::AlignmentReport;

/// The result of a correlation request.
#[derive(Debug, Clone, PartialEq)]
pub struct CorrelateOutput {
    pub method: String,
    pub statistic: Statistic,
    pub thresholds: Thresholds,
    /// `reported`, `recomputed` or `not_used` (weighted statistic).
    pub gains: &'static str,
    pub instants: Vec<f64>,
    pub alignment: AlignmentReport,
    pub pairs: Vec<PairOutput>,
    /// Pairs never within the gate in their current window (not listed).
    pub omitted_pairs: u64,
    pub unpaired: Vec<(String, Vec<String>)>,
    pub groups: Vec<GroupOutput>,
    pub conflicts: Vec<ConflictOutput>,
    pub timing: CorrelateTiming,
    pub warnings: Vec<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Thresholds {
    pub alpha: f64,
    /// The first threshold δ, χ² quantile with `dof` degrees of freedom.
    pub delta: f64,
    pub dof: u32,
    pub rule: Option<(u32, u32)>,
    pub schedule: Vec<(u32, u32)>,
    pub window: Option<u32>,
    pub k: Option<u32>,
}

/// A track named by its node id and track id.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct TrackName {
    pub node: String,
    pub track: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PairOutput {
    pub a: TrackName,
    pub b: TrackName,
    pub decision: Decision,
    pub reason: Reason,
    pub trial: bool,
    pub m: u32,
    pub c: u32,
    pub samples: u32,
    pub mean_statistic: f64,
    pub last_statistic: f64,
    pub decided_at: Option<f64>,
}

/// How a system track's estimate was formed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusionKind {
    BarShalomCampo,
    CovarianceIntersection,
    Single,
    None,
}

#[derive(Debug, Clone, PartialEq)]
pub struct GroupOutput {
    pub id: u32,
    pub members: Vec<TrackName>,
    pub t: f64,
    /// In the request's state layout.
    pub state: Vec<f64>,
    pub covariance: Vec<Vec<f64>>,
    pub fusion: FusionKind,
    /// A trial system track (eq. 21): its pairs are undecided.
    pub trial: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ConflictOutput {
    pub a: TrackName,
    pub b: TrackName,
    pub node: String,
    pub tracks: (String, String),
}

#[derive(Debug, Clone, PartialEq)]
pub struct CorrelateTiming {
    pub compute_us: f64,
    pub align_us: f64,
    pub correlate_us: f64,
    pub fuse_us: f64,
}

pub(crate) fn pair_output(r: &PairReport, a: TrackName, b: TrackName) -> PairOutput {
    PairOutput {
        a,
        b,
        decision: r.decision,
        reason: r.reason,
        trial: r.trial,
        m: r.m,
        c: r.c,
        samples: r.samples,
        mean_statistic: r.mean_statistic,
        last_statistic: r.last_statistic,
        decided_at: r.decided_time,
    }
}

/// Wire name of a statistic: the one vocabulary of REST and gRPC.
pub fn statistic_name(s: Statistic) -> &'static str {
    match s {
        Statistic::Weighted => "weighted",
        Statistic::Modified => "modified",
    }
}

pub fn decision_name(d: Decision) -> &'static str {
    match d {
        Decision::Correlated => "correlated",
        Decision::NotCorrelated => "not_correlated",
        Decision::Undecided => "undecided",
    }
}

pub fn reason_name(r: Reason) -> &'static str {
    match r {
        Reason::Testing => "testing",
        Reason::Threshold => "threshold",
        Reason::EarlyDecision => "early_decision",
        Reason::EarlyStop => "early_stop",
        Reason::AmbiguityMaxM => "ambiguity_max_m",
        Reason::AmbiguityMinMeanStatistic => "ambiguity_min_mean_statistic",
        Reason::AmbiguityLost => "ambiguity_lost",
        Reason::Assignment => "assignment",
        Reason::BelowRule => "below_rule",
        Reason::Revoked => "revoked",
        Reason::Gate => "gate",
        Reason::NearestNeighbour => "nearest_neighbour",
        Reason::Conflict => "conflict",
        Reason::KOfN => "k_of_n",
    }
}

pub fn fusion_name(f: FusionKind) -> &'static str {
    match f {
        FusionKind::BarShalomCampo => "bar_shalom_campo",
        FusionKind::CovarianceIntersection => "covariance_intersection",
        FusionKind::Single => "single",
        FusionKind::None => "none",
    }
}
