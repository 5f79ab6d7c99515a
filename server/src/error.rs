//! Every failure becomes an HTTP status with a JSON [`ApiError`] body, so a client (or a person
//! with curl) always learns what was wrong; the server keeps serving everyone else.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use portico_protocol::ApiError;

/// An error answer.
#[derive(Debug, Clone)]
pub struct Error {
    status: StatusCode,
    code: &'static str,
    message: String,
}

impl Error {
    /// A 400: the request is malformed.
    pub fn bad_request(message: impl Into<String>) -> Error {
        Error::new(StatusCode::BAD_REQUEST, "bad_request", message)
    }

    /// A 404: no such thing.
    pub fn not_found(message: impl Into<String>) -> Error {
        Error::new(StatusCode::NOT_FOUND, "not_found", message)
    }

    /// Any status with a machine-readable code.
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Error {
        Error {
            status,
            code,
            message: message.into(),
        }
    }

    /// The HTTP status.
    pub fn status(&self) -> StatusCode {
        self.status
    }

    /// The wire form.
    pub fn to_api(&self) -> ApiError {
        ApiError {
            status: self.status.as_u16(),
            code: self.code.into(),
            message: self.message.clone(),
        }
    }
}

impl From<portico_data::DataError> for Error {
    fn from(e: portico_data::DataError) -> Error {
        match e {
            portico_data::DataError::NotFound(m) => Error::not_found(m),
            other => {
                tracing::error!("database error: {other}");
                Error::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "database",
                    other.to_string(),
                )
            }
        }
    }
}

impl IntoResponse for Error {
    fn into_response(self) -> Response {
        (self.status, Json(self.to_api())).into_response()
    }
}
