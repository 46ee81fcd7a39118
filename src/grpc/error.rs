//! Mapping of service errors to gRPC statuses, with `BadRequest` field
//! violations that use the same field paths as the REST problem bodies.

use tonic::{Code, Status};
use tonic_types::{ErrorDetails, FieldViolation, StatusExt};

use service::ServiceError;

pub fn to_status(e: ServiceError) -> Status {
    match e {
        ServiceError::InvalidInput(violations) => {
            let summary = violations
                .iter()
                .map(|v| format!("{}: {}", v.field, v.message))
                .collect::<Vec<_>>()
                .join("; ");
            let details = ErrorDetails::with_bad_request(
                violations
                    .into_iter()
                    .map(|v| FieldViolation::new(v.field, v.message))
                    .collect::<Vec<_>>(),
            );
            Status::with_error_details(Code::InvalidArgument, summary, details)
        }
        ServiceError::Internal(detail) => {
            // Logged once here, never sent.
            tracing::error!(%detail, "internal error");
            Status::internal("the service failed unexpectedly; the incident is logged")
        }
        ServiceError::NotFound(detail) => Status::not_found(detail),
        ServiceError::Conflict(detail) => Status::failed_precondition(detail),
        ServiceError::QuotaExceeded(detail) | ServiceError::TooLarge(detail) => {
            Status::resource_exhausted(detail)
        }
        ServiceError::Unavailable(detail) | ServiceError::Overloaded(detail) => {
            Status::unavailable(detail)
        }
        ServiceError::Cancelled => Status::deadline_exceeded(
            "the call was abandoned (FUSION_REQUEST_TIMEOUT_S passed) and its computation stopped",
        ),
    }
}
