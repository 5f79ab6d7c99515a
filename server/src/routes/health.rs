//! `GET /healthz`.

use super::Shared;
use axum::extract::State;
use axum::response::IntoResponse;

/// `GET /healthz`.
pub async fn healthz(State(s): Shared) -> impl IntoResponse {
    let db = s.db();
    axum::Json(serde_json::json!({
        "status": "ok",
        "database_id": s.database_id,
        "model": db.header().name,
        "segments": db.segments().len(),
    }))
}
