//! `/api/jobs`: create, list, show, cancel, resume.

use super::{ApiError, AppState, Job, JobKey, JobRequest, JobState};
use crate::render::SceneSource;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::Json;
use serde_json::{json, Value};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

pub fn job_json(state: &AppState, job: &Job) -> Value {
    json!({
        "id": job.id,
        "state": job.state.as_str(),
        "origin": job.origin(),
        "frames_done": job.frames_done,
        "frames_total": job.request.frames_total(),
        "scene": state.scene_name(&job.request.scene),
        "method": job.request.method.name(),
        "frames": format!("{}..{}", job.request.frames.start, job.request.frames.end),
        "size": format!("{}x{}", job.request.settings.width, job.request.settings.height),
        "spp": job.request.method.spp(),
        "settings": crate::method::settings::settings_json(&job.request.method),
        "error": job.error.as_deref().map(|e| state.without_scenes_dir(e)),
        "seconds_per_frame": (job.run_frames > 0).then(|| job.run_seconds / job.run_frames as f64),
        "eta_seconds": job.eta_seconds(),
        "cancelling": job.cancel,
    })
}

pub async fn create(
    State(state): State<Arc<AppState>>,
    body: Bytes,
) -> Result<(StatusCode, Json<Value>), ApiError> {
    let request = JobRequest::parse(&body, state.options.scenes.as_deref())?;
    check_scene_loads(&state, &request).await?;
    let id = {
        let mut jobs = state.jobs.lock().expect("job table lock");
        let last = jobs.keys().filter_map(|k| match k {
            JobKey::Served(n) => Some(*n),
            JobKey::Rendered(_) => None,
        });
        let n = last.max().map_or(1, |n| n + 1);
        let id = format!("job-{n}");
        // Into the store at once, so that a restart finds it queued.
        let spec = crate::render::job_spec(
            &id,
            &request.scene,
            &request.method,
            &request.settings,
            request.frames.clone(),
        )
        .map_err(ApiError::internal)?;
        state
            .store
            .begin_job(&spec, false)
            .map_err(ApiError::internal)?;
        jobs.insert(
            JobKey::Served(n),
            Job::new(id.clone(), request, JobState::Queued, 0),
        );
        id
    };
    state.wake.notify_one();
    Ok((StatusCode::CREATED, Json(json!({ "id": id }))))
}

/// A scene file is loaded once at submission, so that a malformed one is
/// a 400 now rather than a failed job later (built-in scenes always load).
async fn check_scene_loads(state: &AppState, request: &JobRequest) -> Result<(), ApiError> {
    if matches!(request.scene, SceneSource::Builtin(_)) {
        return Ok(());
    }
    let scene = request.scene.clone();
    let loaded = tokio::task::spawn_blocking(move || scene.load().map(drop))
        .await
        .map_err(ApiError::internal)?;
    loaded.map_err(|e| {
        ApiError::bad_request(format!(
            "scene {}: {}",
            state.scene_name(&request.scene),
            state.without_scenes_dir(&e.to_string())
        ))
    })
}

pub async fn list(State(state): State<Arc<AppState>>) -> Json<Value> {
    let jobs = state.jobs.lock().expect("job table lock");
    Json(Value::Array(
        jobs.values().map(|j| job_json(&state, j)).collect(),
    ))
}

pub async fn show(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Value>, ApiError> {
    Ok(Json(job_json(&state, &state.job(&id)?)))
}

pub async fn cancel(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Value>, ApiError> {
    let job = state.job(&id)?;
    if matches!(job.state, JobState::Queued | JobState::Running) {
        // Durable first: a restart keeps the job cancelled.
        state
            .store
            .set_job_cancelled(&id, true)
            .map_err(ApiError::internal)?;
    }
    match job.state {
        JobState::Queued => state.update(&id, |j| j.state = JobState::Cancelled),
        JobState::Running => {
            let mut changes = state.subscribe(&id)?;
            state.update(&id, |j| j.cancel = true);
            state.abandon_frame(Some(&id));
            wait_while_running(&state, &id, &mut changes).await;
        }
        s => {
            return Err(ApiError::conflict(format!(
                "job {id} is {}; only queued or running jobs can be cancelled",
                s.as_str()
            )))
        }
    }
    Ok(Json(job_json(&state, &state.job(&id)?)))
}

/// How long `cancel` waits for the worker to stop a running job, so that
/// its answer shows the job cancelled (the frame in progress is abandoned
/// within a path bounce; storing the last finished frame may take longer).
const CANCEL_WAIT: Duration = Duration::from_secs(10);

/// Waits (at most [`CANCEL_WAIT`]) until job `id` no longer runs.
async fn wait_while_running(state: &AppState, id: &str, changes: &mut watch::Receiver<u64>) {
    let stopped = async {
        while state.job(id).is_ok_and(|j| j.state == JobState::Running) {
            if changes.changed().await.is_err() {
                return;
            }
        }
    };
    let _ = tokio::time::timeout(CANCEL_WAIT, stopped).await;
}

pub async fn resume(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Value>, ApiError> {
    let job = state.job(&id)?;
    if matches!(job.state, JobState::Cancelled | JobState::Failed) {
        state
            .store
            .set_job_cancelled(&id, false)
            .map_err(ApiError::internal)?;
    }
    match job.state {
        JobState::Cancelled | JobState::Failed => state.update(&id, |j| {
            j.state = JobState::Queued;
            j.cancel = false;
            j.error = None;
        }),
        JobState::Stopped => {
            return Err(ApiError::conflict(format!(
                "job {id} was rendered by `radcache render --job {id}` and stopped after {} of {} \
                 frames; run that command again (with the same --db) to resume it",
                job.frames_done,
                job.request.frames_total()
            )))
        }
        s => {
            return Err(ApiError::conflict(format!(
                "job {id} is {}; only cancelled or failed jobs can be resumed",
                s.as_str()
            )))
        }
    }
    state.wake.notify_one();
    Ok(Json(job_json(&state, &state.job(&id)?)))
}
