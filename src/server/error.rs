//! API errors: JSON `{error, detail}` with a status code.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;

#[derive(Clone, Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub error: &'static str,
    pub detail: String,
}

impl ApiError {
    pub fn new(status: StatusCode, error: &'static str, detail: String) -> Self {
        ApiError {
            status,
            error,
            detail,
        }
    }
    pub fn bad_request(detail: String) -> Self {
        Self::new(StatusCode::BAD_REQUEST, "bad request", detail)
    }
    pub fn not_found(detail: String) -> Self {
        Self::new(StatusCode::NOT_FOUND, "not found", detail)
    }
    pub fn conflict(detail: String) -> Self {
        Self::new(StatusCode::CONFLICT, "conflict", detail)
    }
    /// The answer of work that every client that asked for has left
    /// (`flight::Wanted::still`): it reaches no one.
    pub fn abandoned() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "abandoned",
            "every client that asked for this has gone".into(),
        )
    }
    pub fn internal(err: impl std::fmt::Display) -> Self {
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal error",
            format!("{err:#}"),
        )
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::json!({ "error": self.error, "detail": self.detail });
        (self.status, Json(body)).into_response()
    }
}
