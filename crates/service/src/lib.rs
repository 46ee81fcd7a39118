//! The application layer: requests parsed into typed inputs ([`validate`]), results out. Both
//! adapters (`http`, `grpc`) call these functions and nothing else; this is the
//! only place that orchestrates the numerical core.

pub mod ais_radar;
pub mod correlation;
pub mod dimension;
pub mod jpda;
pub mod lanes;
pub mod plot_fusion;
pub mod rows;
/// The JSON form of [`Rows`] (nested arrays), for the REST adapter.
#[cfg(feature = "serde")]
mod rows_json;
pub mod rules;
pub mod session;
pub mod validate;

pub use lanes::offload;
pub use rows::Rows;
pub use validate::{Ids, Increasing, Interval, Violations, at};

use std::time::Instant;

use algo::AlgoError;

/// One thing wrong with a request, named by its field path
/// (`rules[2].l`, `nodes[1].tracks[3].samples[0].covariance`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldViolation {
    pub field: String,
    pub message: String,
}

/// An error of the application layer. Every adapter matches on every variant,
/// so a new variant forces a decision about its status code.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The request is well-formed but its values are not acceptable.
    #[error("the request has {} invalid field(s)", .0.len())]
    InvalidInput(Vec<FieldViolation>),
    /// A bug or an unexpected failure; the detail is logged, never sent.
    #[error("internal error: {0}")]
    Internal(String),
    /// The resource named does not exist (or belongs to another tenant).
    #[error("not found: {0}")]
    NotFound(String),
    /// The request conflicts with the resource's state (a batch sequence
    /// number that skips ahead).
    #[error("conflict: {0}")]
    Conflict(String),
    /// A quota is used up (sessions per tenant, tracks per session).
    #[error("quota exceeded: {0}")]
    QuotaExceeded(String),
    /// The request is larger than a limit allows (reports per batch).
    #[error("too large: {0}")]
    TooLarge(String),
    /// A backend the request needs (the session store) is unreachable; the
    /// client may retry after the given number of seconds.
    #[error("unavailable: {0}")]
    Unavailable(String),
    /// The service is too busy to take the request's computation now (a
    /// bound of the compute lanes, named in the message); retry shortly.
    #[error("overloaded: {0}")]
    Overloaded(String),
    /// The request was abandoned (its timeout passed, or its client left)
    /// and its computation stopped at a checkpoint: nobody reads the answer.
    #[error("cancelled: the request was abandoned")]
    Cancelled,
}

/// The message for a matrix that is not a covariance, without the
/// matrix's own name (the field path names it).
pub fn covariance_message(e: &AlgoError) -> String {
    match e {
        AlgoError::NonFinite { .. } => "contains a non-finite value".into(),
        AlgoError::NotSymmetric {
            max_abs_asymmetry, ..
        } => format!("is not symmetric (largest |p_ij − p_ji| = {max_abs_asymmetry:e})"),
        AlgoError::NotPositiveDefinite { .. } => "is not positive definite".into(),
        other => other.to_string(),
    }
}

pub(crate) fn param_violation(prefix: &str, e: AlgoError) -> FieldViolation {
    match e {
        AlgoError::InvalidParameter { what, reason } => FieldViolation {
            field: format!("{prefix}{what}"),
            message: reason,
        },
        AlgoError::InvalidOption { parameter, reason } => FieldViolation {
            field: format!("{prefix}{parameter}"),
            message: reason,
        },
        // These name a quantity ("innovation covariance"), not a parameter:
        // the field is the prefix, and the message says which quantity.
        other @ (AlgoError::DimensionMismatch { .. }
        | AlgoError::NotSquare { .. }
        | AlgoError::NonFinite { .. }
        | AlgoError::NotSymmetric { .. }
        | AlgoError::NotPositiveDefinite { .. }
        | AlgoError::DegenerateGeometry { .. }
        | AlgoError::BudgetExceeded { .. }) => FieldViolation {
            field: prefix.trim_end_matches('.').to_string(),
            message: other.to_string(),
        },
    }
}

/// Microseconds elapsed since `start`, for the `timing.compute_us` of a response.
pub fn micros_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e6
}
