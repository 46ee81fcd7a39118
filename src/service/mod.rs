//! The application layer: validated domain requests in, results out. Both
//! adapters (`http`, `grpc`) call these functions and nothing else; this is the
//! only place that orchestrates the numerical core.

pub mod ais_radar;
pub mod correlation;
pub mod dimension;
pub mod jpda;
pub mod plot_fusion;
pub mod rules;
pub mod session;

use std::time::Instant;

use crate::algo::AlgoError;

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
}

/// Collects field violations while a request is validated, so that a client
/// learns of every bad field at once.
#[derive(Debug, Default)]
pub struct Violations(Vec<FieldViolation>);

impl Violations {
    pub fn new() -> Self {
        Self::default()
    }

    /// The invalid-input error of one violation of `field`.
    pub fn single(field: impl Into<String>, message: impl Into<String>) -> ServiceError {
        ServiceError::InvalidInput(vec![FieldViolation {
            field: field.into(),
            message: message.into(),
        }])
    }

    /// Records a violation of `field`.
    pub fn add(&mut self, field: impl Into<String>, message: impl Into<String>) {
        self.0.push(FieldViolation {
            field: field.into(),
            message: message.into(),
        });
    }

    /// Returns the value of a required field, or records that it is missing.
    pub fn required<T>(&mut self, field: &str, value: Option<T>) -> Option<T> {
        self.required_at(value, || field.to_string())
    }

    /// As [`required`](Self::required), with the field path built only when
    /// the value is missing (for loops over many elements).
    pub fn required_at<T>(
        &mut self,
        value: Option<T>,
        field: impl FnOnce() -> String,
    ) -> Option<T> {
        if value.is_none() {
            self.add(field(), "is required");
        }
        value
    }

    /// A required number in [lo, hi], or a recorded violation.
    pub fn number_in(&mut self, field: &str, x: Option<f64>, lo: f64, hi: f64) -> Option<f64> {
        let x = self.required(field, x)?;
        if !(x.is_finite() && x >= lo && x <= hi) {
            self.add(field, format!("must lie in [{lo}, {hi}], got {x}"));
            return None;
        }
        Some(x)
    }

    /// A required finite number > 0, or a recorded violation.
    pub fn positive(&mut self, field: &str, x: Option<f64>) -> Option<f64> {
        let x = self.required(field, x)?;
        if !(x.is_finite() && x > 0.0) {
            self.add(field, format!("must be finite and > 0, got {x}"));
            return None;
        }
        Some(x)
    }

    /// Records `result`'s error, if any, against `field`, and passes the value on.
    pub fn check<T, E: std::fmt::Display>(
        &mut self,
        field: &str,
        result: Result<T, E>,
    ) -> Option<T> {
        result.map_err(|e| self.add(field, e.to_string())).ok()
    }

    /// Records a parameter error of the numerical core against the field
    /// `prefix` + the parameter's name (`rules[2].` + `l`), and passes the value on.
    pub fn param<T>(&mut self, prefix: &str, result: Result<T, AlgoError>) -> Option<T> {
        match result {
            Ok(value) => Some(value),
            Err(e) => {
                let violation = param_violation(prefix, e);
                self.0.push(violation);
                None
            }
        }
    }

    /// The invalid-input error for one parameter error of the numerical core.
    pub fn from_param(prefix: &str, e: AlgoError) -> ServiceError {
        ServiceError::InvalidInput(vec![param_violation(prefix, e)])
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// `Ok(())` when nothing was recorded, otherwise the invalid-input error.
    pub fn finish(self) -> Result<(), ServiceError> {
        if self.0.is_empty() {
            Ok(())
        } else {
            Err(ServiceError::InvalidInput(self.0))
        }
    }
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

fn param_violation(prefix: &str, e: AlgoError) -> FieldViolation {
    match e {
        AlgoError::InvalidParameter { what, reason } => FieldViolation {
            field: format!("{prefix}{what}"),
            message: reason,
        },
        // These name a quantity ("innovation covariance"), not a parameter:
        // the field is the prefix, and the message says which quantity.
        other @ (AlgoError::DimensionMismatch { .. }
        | AlgoError::NotSquare { .. }
        | AlgoError::NonFinite { .. }
        | AlgoError::NotSymmetric { .. }
        | AlgoError::NotPositiveDefinite { .. }
        | AlgoError::DegenerateGeometry { .. }) => FieldViolation {
            field: prefix.trim_end_matches('.').to_string(),
            message: other.to_string(),
        },
    }
}

/// Runs CPU-bound work on tokio's blocking pool, so that a large request never
/// stalls the async workers that serve other requests. The number of requests
/// in flight, and so of blocking tasks, is bounded by the concurrency limit in
/// front of both servers.
pub async fn offload<T, F>(work: F) -> Result<T, ServiceError>
where
    F: FnOnce() -> Result<T, ServiceError> + Send + 'static,
    T: Send + 'static,
{
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| ServiceError::Internal(format!("compute task failed: {e}")))?
}

/// Microseconds elapsed since `start`, for the `timing.compute_us` of a response.
pub fn micros_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e6
}
