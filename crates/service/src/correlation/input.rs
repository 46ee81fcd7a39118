//! The correlation request as a client sent it, before validation: what
//! REST and gRPC convert their wire types into.

use crate::Rows;

/// A correlation request as a client sent it, before validation.
#[derive(Debug, Clone, Default)]
pub struct CorrelateInput {
    pub state_layout: Vec<String>,
    pub method: Option<MethodInput>,
    pub motion_model: Option<MotionModelInput>,
    pub alignment: Option<AlignmentInput>,
    /// H of the local filters, needed to turn reported gains K into I − K H.
    pub measurement_matrix: Option<Vec<Vec<f64>>>,
    pub nodes: Vec<NodeInput>,
    /// `grid` (default) or `none` (brute force over all pairs; same result).
    pub pruning: Option<String>,
    /// Fuse correlated groups into system tracks (default true).
    pub fuse: Option<bool>,
}

#[derive(Debug, Clone, Default)]
pub struct MethodInput {
    pub kind: Option<String>,
    pub alpha: Option<f64>,
    pub rule: Option<RuleInput>,
    pub schedule: Option<Vec<RuleInput>>,
    pub dynamic_schedule: Option<bool>,
    pub statistic: Option<String>,
    pub window: Option<u32>,
    pub k: Option<u32>,
}

#[derive(Debug, Clone, Default)]
pub struct RuleInput {
    pub l: Option<u32>,
    pub r: Option<u32>,
}

#[derive(Debug, Clone, Default)]
pub struct MotionModelInput {
    /// Only `constant_velocity` for now.
    pub kind: Option<String>,
    /// `dwna`, `cwna` or `velocity_proportional`.
    pub process_noise: Option<String>,
    pub sigma_a_mps2: Option<f64>,
    pub q_m2ps3: Option<f64>,
    pub factor: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct AlignmentInput {
    /// `grid` (default), `predict`, `interpolate` or `nearest`.
    pub mode: Option<String>,
    /// `interpolate`: the widest gap between two samples interpolated across.
    pub max_gap_s: Option<f64>,
    /// `predict`, `nearest`, `interpolate`: widest spread of report times
    /// merged into one instant. Sessions (every mode): how long after an
    /// instant reports for it may still arrive.
    pub tolerance_s: Option<f64>,
    /// `grid`: the fusion period (default: the longest scan period of the
    /// nodes, estimated from the data).
    pub period_s: Option<f64>,
    /// `grid`: instants are `epoch_s + k·period_s` (default 0).
    pub epoch_s: Option<f64>,
    /// `grid`: the oldest a sample may be at an instant (default 1.5 scan
    /// periods of its node, estimated from the data).
    pub max_staleness_s: Option<f64>,
}

#[derive(Debug, Clone, Default)]
pub struct NodeInput {
    pub id: Option<String>,
    pub tracks: Vec<TrackInput>,
}

#[derive(Debug, Clone, Default)]
pub struct TrackInput {
    pub id: Option<String>,
    pub samples: Vec<SampleInput>,
}

#[derive(Debug, Clone, Default)]
pub struct SampleInput {
    pub t: Option<f64>,
    pub state: Vec<f64>,
    pub covariance: Rows,
    pub gain: Option<Rows>,
}

/// The method names of the API.
pub const METHODS: &[&str] = &[
    "weighted",
    "modified",
    "independent_double_threshold",
    "dependent_double_threshold",
    "double_threshold_assignment",
    "nearest_neighbour",
    "k_nearest_neighbour",
    "global_assignment",
];
