//! `GET /api/jobs/{id}/movies?frame=N`: the texture movies of a `movies`
//! job at frame N, read from the store (`movies` tree): for each, which
//! side of which patch of which triangle it covers, its resolution, the
//! frame it opened at, the frame whose value holds its texels, and the
//! mean of its texels' direct irradiance; and where the centre of its
//! patch lies on the image at that frame (`screen`, pixels; `null` behind
//! the camera or where the server cannot load the job's scene), for the
//! dashboard's overlay. A job of another method has none (an empty list).

use super::records::{frame_param, query_params, scene, stored_frame};
use super::{ApiError, AppState};
use crate::method::movies::patch::Patch;
use crate::scene::Snapshot;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::Json;
use glam::Vec3;
use serde_json::{json, Value};
use std::sync::Arc;

pub async fn movies(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    query: Result<Query<Vec<(String, String)>>, QueryRejection>,
) -> Result<Json<Value>, ApiError> {
    // An unknown job is a 404 whatever its query.
    let job = state.job(&id)?;
    let q = query_params(query, &["frame"])?;
    let frame = frame_param(&q)?;
    let sid = stored_frame(&state, &id, frame)?;
    let s = state.clone();
    // In a records slot: like a records query, it reads a frame's bulk
    // values and projects them with the job's scene.
    super::blocking_in_slot(&state.records_slots, move || {
        let global_vertices = s
            .store
            .frame_movies(sid, frame)
            .map_err(ApiError::internal)?
            .map_or(0, |v| v.global_vertices);
        let movies = s
            .store
            .frame_movie_texels(sid, frame)
            .map_err(ApiError::internal)?;
        let settings = &job.request.settings;
        let (w, h) = (settings.width as f32, settings.height as f32);
        // Screen positions are a convenience: a scene the server cannot
        // load leaves them out rather than failing the list.
        let view = scene(&s, &job.request.scene.to_string(), &job.request.scene)
            .ok()
            .map(|scene| {
                let t = frame as f32 / settings.fps;
                (scene.snapshot(t), scene.camera_at(t))
            });
        let out: Vec<Value> = movies
            .iter()
            .map(|(m, texels)| {
                let mean = texels.iter().copied().sum::<Vec3>() / texels.len().max(1) as f32;
                let screen = view.as_ref().and_then(|(snapshot, camera)| {
                    let centre = patch_centre(snapshot, m.triangle, m.patch)?;
                    let (sx, sy) = camera.project(centre, w / h)?;
                    Some([sx * w, sy * h])
                });
                json!({
                    "triangle": m.triangle,
                    "back": m.back,
                    "patch": m.patch,
                    "resolution": m.resolution,
                    "start": m.start,
                    "stored_at": m.stored_at,
                    "texels": texels.len(),
                    "mean_direct": mean.to_array(),
                    "screen": screen,
                })
            })
            .collect();
        Ok(Json(json!({
            "id": id,
            "frame": frame,
            "width": settings.width,
            "height": settings.height,
            "count": out.len(),
            "global_vertices": global_vertices,
            "movies": out,
        })))
    })
    .await
}

/// The centre of patch `code` of `triangle` in `snapshot` (`None` for a
/// triangle or patch the scene does not have: a store written for another
/// version of the scene file).
fn patch_centre(snapshot: &Snapshot, triangle: u32, code: u32) -> Option<Vec3> {
    let patch = Patch::from_code(code)?;
    let (u, v) = patch.to_triangle((1.0 / 3.0, 1.0 / 3.0));
    Some(snapshot.triangles.get(triangle as usize)?.point(u, v))
}
