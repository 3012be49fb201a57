//! `GET /api/jobs/{id}/movies?frame=N`: the texture movies of a `movies`
//! job at frame N, read from the store (`movies` tree): for each, which
//! side of which patch of which triangle it covers, its resolution, the
//! frame it opened at, the frame whose value holds its texels, and the
//! mean of its texels' direct irradiance. A job of another method has
//! none (an empty list).

use super::records::{frame_param, stored_frame};
use super::{ApiError, AppState};
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::Json;
use glam::Vec3;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::sync::Arc;

pub async fn movies(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    query: Result<Query<HashMap<String, String>>, QueryRejection>,
) -> Result<Json<Value>, ApiError> {
    let Query(q) = query.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let frame = frame_param(&q)?;
    let sid = stored_frame(&state, &id, frame)?;
    let s = state.clone();
    tokio::task::spawn_blocking(move || {
        let global_vertices = s
            .store
            .frame_movies(sid, frame)
            .map_err(ApiError::internal)?
            .map_or(0, |v| v.global_vertices);
        let movies = s
            .store
            .frame_movie_texels(sid, frame)
            .map_err(ApiError::internal)?;
        let out: Vec<Value> = movies
            .iter()
            .map(|(m, texels)| {
                let mean = texels.iter().copied().sum::<Vec3>() / texels.len().max(1) as f32;
                json!({
                    "triangle": m.triangle,
                    "back": m.back,
                    "patch": m.patch,
                    "resolution": m.resolution,
                    "start": m.start,
                    "stored_at": m.stored_at,
                    "texels": texels.len(),
                    "mean_direct": mean.to_array(),
                })
            })
            .collect();
        Ok(Json(json!({
            "id": id,
            "frame": frame,
            "count": out.len(),
            "global_vertices": global_vertices,
            "movies": out,
        })))
    })
    .await
    .map_err(ApiError::internal)?
}
