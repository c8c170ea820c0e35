//! Reloading the models directory (also done on SIGHUP).

use axum::Json;
use axum::extract::State;

use crate::server::{ApiError, AppState, ReloadReport};

/// Re-reads the models directory and swaps the new set in atomically; a model
/// that fails to load keeps its previous version.
#[utoipa::path(post, path = "/v1/admin/reload", tag = "admin",
    responses((status = 200, description = "Success", body = ReloadReport)))]
pub async fn reload(State(state): State<AppState>) -> Result<Json<ReloadReport>, ApiError> {
    let registry = state.registry.clone();
    Ok(Json(state.compute(move |_| Ok(registry.reload())).await?))
}
