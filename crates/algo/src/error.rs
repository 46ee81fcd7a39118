//! The single error type of the numerical core.
//!
//! Every variant is numeric: a shape that does not fit, a value that is not
//! finite, a matrix that is not a covariance, a parameter outside its domain,
//! a geometry where the measurement model is undefined, or a budget of work
//! or memory a computation would exceed. Each variant names the
//! offending quantity in `what` (a tracker option by its typed
//! [`TrackerParameter`]) so that the service layer can map it to a field
//! path and a message such as "covariance is not positive definite". A
//! failed gate is a result, never an error.

use nalgebra::{DMatrix, DVector};

use crate::tracking::TrackerParameter;

/// Errors of the `algo` layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AlgoError {
    /// A vector or matrix has the wrong number of rows or columns.
    #[error("{what} has dimension {found}, expected {expected}")]
    DimensionMismatch {
        /// Name of the quantity.
        what: &'static str,
        /// Dimension required by the other operands.
        expected: usize,
        /// Dimension actually supplied.
        found: usize,
    },
    /// A matrix that must be square is not.
    #[error("{what} is not square ({rows}x{cols})")]
    NotSquare {
        /// Name of the matrix.
        what: &'static str,
        /// Number of rows supplied.
        rows: usize,
        /// Number of columns supplied.
        cols: usize,
    },
    /// A value is NaN or infinite (on input, or an intermediate overflowed).
    #[error("{what} contains a non-finite value")]
    NonFinite {
        /// Name of the quantity.
        what: &'static str,
    },
    /// A matrix that must be symmetric is not, beyond the relative tolerance.
    #[error("{what} is not symmetric (max |a_ij - a_ji| = {max_abs_asymmetry:e})")]
    NotSymmetric {
        /// Name of the matrix.
        what: &'static str,
        /// Largest absolute difference between mirrored entries.
        max_abs_asymmetry: f64,
    },
    /// A matrix that must be a covariance is not positive definite.
    #[error("{what} is not positive definite")]
    NotPositiveDefinite {
        /// Name of the matrix.
        what: &'static str,
    },
    /// The measurement geometry is singular (e.g. a target at the radar site).
    #[error("{what}: degenerate geometry, {reason}")]
    DegenerateGeometry {
        /// Name of the quantity.
        what: &'static str,
        /// Why the geometry is singular.
        reason: &'static str,
    },
    /// A computation would exceed its budget (candidate pairs): refused
    /// before the memory it would take is allocated.
    #[error("{what}: more than {limit}")]
    BudgetExceeded {
        /// Name of what is counted.
        what: &'static str,
        /// The budget.
        limit: u64,
    },
    /// A scalar parameter is outside its domain.
    #[error("invalid {what}: {reason}")]
    InvalidParameter {
        /// Name of the parameter.
        what: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// A tracker option is outside its domain: the option is typed, so a
    /// caller names its own field for it by a total `match`.
    #[error("invalid {parameter}: {reason}")]
    InvalidOption {
        /// The option.
        parameter: TrackerParameter,
        /// What is wrong with it.
        reason: String,
    },
}

impl AlgoError {
    /// Name of the offending quantity, for building field paths.
    pub fn what(&self) -> &'static str {
        match self {
            AlgoError::DimensionMismatch { what, .. }
            | AlgoError::NotSquare { what, .. }
            | AlgoError::NonFinite { what }
            | AlgoError::NotSymmetric { what, .. }
            | AlgoError::NotPositiveDefinite { what }
            | AlgoError::DegenerateGeometry { what, .. }
            | AlgoError::BudgetExceeded { what, .. }
            | AlgoError::InvalidParameter { what, .. } => what,
            AlgoError::InvalidOption { parameter, .. } => parameter.name(),
        }
    }
}

// Validation helpers shared by the algo modules. They only build the errors
// above; they live here so that every module reports violations the same way.

/// `Ok(v)` if `v` is finite.
pub(crate) fn finite(what: &'static str, v: f64) -> Result<f64, AlgoError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(AlgoError::NonFinite { what })
    }
}

/// `Ok(v)` if `v` is finite and strictly positive.
pub(crate) fn positive(what: &'static str, v: f64) -> Result<f64, AlgoError> {
    finite(what, v)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(AlgoError::InvalidParameter {
            what,
            reason: format!("must be > 0, got {v}"),
        })
    }
}

/// `Ok(v)` if `v` is finite and not negative.
pub(crate) fn non_negative(what: &'static str, v: f64) -> Result<f64, AlgoError> {
    finite(what, v)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(AlgoError::InvalidParameter {
            what,
            reason: format!("must be >= 0, got {v}"),
        })
    }
}

/// `Ok(())` if every entry of `v` is finite.
pub(crate) fn finite_slice(what: &'static str, v: &[f64]) -> Result<(), AlgoError> {
    if v.iter().all(|e| e.is_finite()) {
        Ok(())
    } else {
        Err(AlgoError::NonFinite { what })
    }
}

/// `Ok(())` if `found == expected`.
pub(crate) fn same_dim(what: &'static str, expected: usize, found: usize) -> Result<(), AlgoError> {
    if expected == found {
        Ok(())
    } else {
        Err(AlgoError::DimensionMismatch {
            what,
            expected,
            found,
        })
    }
}

/// A finite vector of length `len`.
pub(crate) fn check_vector(
    what: &'static str,
    v: &DVector<f64>,
    len: usize,
) -> Result<(), AlgoError> {
    same_dim(what, len, v.len())?;
    finite_slice(what, v.as_slice())
}

/// A finite `rows x cols` matrix.
pub(crate) fn check_matrix(
    what: &'static str,
    m: &DMatrix<f64>,
    rows: usize,
    cols: usize,
) -> Result<(), AlgoError> {
    same_dim(what, rows, m.nrows())?;
    same_dim(what, cols, m.ncols())?;
    finite_slice(what, m.as_slice())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_quantity() {
        let e = AlgoError::NotPositiveDefinite { what: "covariance" };
        assert_eq!(e.to_string(), "covariance is not positive definite");
        assert_eq!(e.what(), "covariance");
        let e = AlgoError::DimensionMismatch {
            what: "measurement",
            expected: 2,
            found: 3,
        };
        assert_eq!(e.to_string(), "measurement has dimension 3, expected 2");
    }

    #[test]
    fn scalar_helpers() {
        assert!(finite("x", f64::NAN).is_err());
        assert!(positive("x", 0.0).is_err());
        assert!(positive("x", 1.0).is_ok());
        assert!(non_negative("x", 0.0).is_ok());
        assert!(non_negative("x", -1e-300).is_err());
        assert!(non_negative("x", f64::INFINITY).is_err());
    }
}
