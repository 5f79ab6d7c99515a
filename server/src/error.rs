//! Every failure becomes an HTTP status with a JSON [`ApiError`] body, so a client (or a person
//! with curl) always learns what was wrong; the server keeps serving everyone else. Internal
//! details (file paths, OS errors) go to the log, never into a body.

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

impl Error {
    /// A 500 whose detail goes to the log, not to the client (file paths, OS errors).
    pub fn internal(what: &str, detail: impl std::fmt::Display) -> Error {
        tracing::error!("{what}: {detail}");
        Error::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            format!("{what} (see the server log)"),
        )
    }
}

impl From<portico_data::DataError> for Error {
    fn from(e: portico_data::DataError) -> Error {
        use portico_data::DataError as D;
        match e {
            D::NotFound(m) => Error::not_found(m),
            D::Deadline(spent) => Error::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "busy",
                format!(
                    "the answer took longer than the server allows ({} ms); retry",
                    spent.as_millis()
                ),
            ),
            // The message names what is damaged (a segment, a stab list), never the file.
            D::Corrupt { path, what } => {
                tracing::error!("{}: corrupt: {what}", path.display());
                Error::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "damaged",
                    format!("damaged data on the server: {what}"),
                )
            }
            other => Error::internal("the server could not read its database", other),
        }
    }
}

/// Seconds a client is asked to wait after a 503 (the server is at capacity: sessions, compute
/// slots or an answer's deadline) before it tries again.
pub const RETRY_AFTER_S: u64 = 1;

impl IntoResponse for Error {
    /// The JSON body; a 503 also says when to retry (`Retry-After`), so clients past capacity
    /// back off instead of hammering the server while its sessions keep their frame rate.
    fn into_response(self) -> Response {
        let mut r = (self.status, Json(self.to_api())).into_response();
        if self.status == StatusCode::SERVICE_UNAVAILABLE {
            r.headers_mut().insert(
                axum::http::header::RETRY_AFTER,
                axum::http::HeaderValue::from(RETRY_AFTER_S),
            );
        }
        r
    }
}
