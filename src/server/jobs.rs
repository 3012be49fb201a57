//! `/api/jobs`: create, list, show, cancel, resume.

use super::{ApiError, AppState, Job, JobKey, JobRequest, JobState};
use crate::render::memory;
use anyhow::Context;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::Json;
use serde_json::{json, Value};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

pub fn job_json(state: &AppState, job: &Job) -> Value {
    job_json_under(state.scenes_root().as_deref(), job)
}

/// [`job_json`] with the `--scenes` directory, `root`, known (finding it
/// reads the file system).
fn job_json_under(root: Option<&std::path::Path>, job: &Job) -> Value {
    json!({
        "id": job.id,
        "state": job.state.as_str(),
        "origin": job.origin(),
        "frames_done": job.frames_done,
        "frames_total": job.request.frames_total(),
        "scene": super::scene_name_under(root, &job.request.scene),
        "method": job.request.method.name(),
        "frames": format!("{}..{}", job.request.frames.start, job.request.frames.end),
        "frames_stored": job.frames_stored(),
        "stored_ranges": job.stored.iter().map(|r| format!("{}..{}", r.start, r.end)).collect::<Vec<_>>(),
        "size": format!("{}x{}", job.request.settings.width, job.request.settings.height),
        "spp": job.request.method.spp(),
        "seed": job.request.settings.seed,
        "fps": job.request.settings.fps,
        "same_pattern": job.request.settings.same_pattern,
        "settings": crate::method::settings::named_settings(&job.request.method),
        "error": job.error.as_deref().map(|e| super::without_dir(root, e)),
        "seconds_per_frame": (job.run_frames > 0).then(|| job.run_seconds / job.run_frames as f64),
        "eta_seconds": job.eta_seconds(),
        "cancelling": job.cancel,
    })
}

pub async fn create(
    State(state): State<Arc<AppState>>,
    body: Bytes,
) -> Result<(StatusCode, Json<Value>), ApiError> {
    create_checked(state, &body, JobRequest::check_memory).await
}

/// [`create`], the request's memory checked by `check_memory` on its
/// scene's triangles ([`JobRequest::check_memory`]: against the memory the
/// server's next job may take) once the scene has loaded, before the job
/// is stored.
async fn create_checked(
    state: Arc<AppState>,
    body: &[u8],
    check_memory: impl Fn(&JobRequest, u64) -> Result<(), ApiError>,
) -> Result<(StatusCode, Json<Value>), ApiError> {
    let request = JobRequest::parse(body, state.options.scenes.as_deref())?;
    // Its pixels and samples alone first: a job too large whatever its
    // scene is refused before the scene is read.
    check_memory(&request, 0)?;
    let loaded = check_scene_loads(&state, &request).await?;
    check_memory(&request, loaded.triangles)?;
    let identity = loaded.identity;
    // Off the async workers and outside the job table's lock, which every
    // request and the render worker take: the store is written and
    // flushed. All of it in the blocking task, so that
    // a client gone meanwhile cannot leave a job stored but not listed.
    let s = state.clone();
    let id = tokio::task::spawn_blocking(move || add_queued_job(&s, request, identity))
        .await
        .map_err(ApiError::internal)?
        .map_err(ApiError::internal)?;
    Ok((StatusCode::CREATED, Json(json!({ "id": id }))))
}

/// Stores `request` (its scene's identity, [`check_scene_loads`]'s) as the
/// next `job-N`, queued, lists it and wakes the worker; its id. Into the
/// store first, so that a restart finds it queued.
fn add_queued_job(
    state: &AppState,
    request: JobRequest,
    identity: (String, String),
) -> anyhow::Result<String> {
    let _creating = state.creating.lock().expect("job creation lock");
    let n = {
        let jobs = state.jobs.lock().expect("job table lock");
        let served = jobs.keys().filter_map(|k| match k {
            JobKey::Served(n) => Some(*n),
            JobKey::Rendered(_) => None,
        });
        served.max().unwrap_or(0)
    };
    // Past any number given before, also to a job deleted since (a client
    // may still hold its URLs), and past any `job-N` of the store that the
    // table left out (a method or frame range this build cannot run): a new
    // job must not take over its frames, nor fail on it for good.
    let next = |n: u64| {
        n.checked_add(1)
            .context("job numbers are used up (past u64::MAX)")
    };
    let mut n = next(n.max(state.store.served_jobs_high()?))?;
    while state.store.job(&format!("job-{n}"))?.is_some() {
        n = next(n)?;
    }
    let id = format!("job-{n}");
    state.store.set_served_jobs_high(n)?;
    let r = &request;
    let spec = crate::render::job_spec_of(&id, identity, &r.method, &r.settings, r.frames.clone())?;
    state.store.begin_job(&spec, false)?;
    state.jobs.lock().expect("job table lock").insert(
        JobKey::Served(n),
        Job::new(id.clone(), request, JobState::Queued, &[]),
    );
    state.wake.notify_one();
    Ok(id)
}

/// A job's scene as [`check_scene_loads`] found it.
struct LoadedScene {
    /// Its name and hash, as the job stores them.
    identity: (String, String),
    /// Its triangles ([`memory::scene_triangles`]), which the job's memory
    /// check counts.
    triangles: u64,
}

/// A scene is loaded (a built-in one built) and hashed once at submission,
/// as the worker will, a file confined to the scenes directory
/// ([`AppState::scene_root`]), so that a malformed one, or one whose
/// buffers or images lie outside the directory, is a 400 now rather than a
/// failed job later (built-in scenes always load). Its identity (name and
/// hash) as the job stores it: the worker hashes the file again when it
/// starts, and a file changed since fails the job, naming the hash. And
/// its triangles, for the job's memory check.
async fn check_scene_loads(
    state: &AppState,
    request: &JobRequest,
) -> Result<LoadedScene, ApiError> {
    let scene = request.scene.clone();
    let root = state.scene_root(&scene);
    let loaded = tokio::task::spawn_blocking(move || -> anyhow::Result<LoadedScene> {
        // Dropped before the memory check reads what the server holds.
        let triangles = memory::scene_triangles(&scene.load_confined(root.as_deref())?);
        let identity = crate::render::scene_identity_confined(&scene, root.as_deref())?;
        Ok(LoadedScene {
            identity,
            triangles,
        })
    })
    .await
    .map_err(ApiError::internal)?;
    loaded.map_err(|e| {
        ApiError::bad_request(format!(
            "scene {}: {}",
            state.scene_name(&request.scene),
            state.without_scenes_dir(&format!("{e:#}"))
        ))
    })
}

pub async fn list(State(state): State<Arc<AppState>>) -> Json<Value> {
    // Copied out of the table, whose lock every request and the worker
    // take: naming the jobs' scenes reads the file system (the `--scenes`
    // directory, once for all of them).
    let jobs: Vec<Job> = state
        .jobs
        .lock()
        .expect("job table lock")
        .values()
        .cloned()
        .collect();
    let root = state.scenes_root();
    Json(Value::Array(
        jobs.iter()
            .map(|j| job_json_under(root.as_deref(), j))
            .collect(),
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
    if !matches!(job.state, JobState::Queued | JobState::Running) {
        return Err(ApiError::conflict(format!(
            "job {id} is {}; only queued or running jobs can be cancelled",
            job.state.as_str()
        )));
    }
    let (mut changes, running) = {
        // Held from the cancel mark to the table's state, as `resume` holds
        // it: the store's mark and the table agree however cancels and
        // resumes interleave.
        let _control = state.controlling.lock().expect("job control lock");
        // Durable first: a restart keeps the job cancelled.
        state
            .store
            .set_job_cancelled(&id, true)
            .map_err(ApiError::internal)?;
        let changes = state.subscribe(&id)?;
        // Decided on the state as it is under the table's lock, not on the copy
        // above: the worker may have started the job in between, and a running
        // job must be stopped by the worker, not only shown cancelled.
        let mut running = false;
        let mut ended = None;
        state.update(&id, |j| match j.state {
            JobState::Queued => j.state = JobState::Cancelled,
            JobState::Running => {
                j.cancel = true;
                running = true;
            }
            s => ended = Some(s),
        });
        if let Some(s) = ended {
            // It ended meanwhile (done, failed, or cancelled by another
            // request): unless cancelled, not marked so, and a failed job is
            // queued again on the next start as before.
            if s != JobState::Cancelled {
                state
                    .store
                    .set_job_cancelled(&id, false)
                    .map_err(ApiError::internal)?;
            }
            return Err(ApiError::conflict(format!(
                "job {id} is {}; only queued or running jobs can be cancelled",
                s.as_str()
            )));
        }
        (changes, running)
    };
    if running {
        state.abandon_frame(Some(&id));
        wait_while_running(&state, &id, &mut changes).await;
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

/// `DELETE /api/jobs/{id}`: a job that is neither queued nor running goes,
/// with its frames, statistics and records (their bytes in the sample log
/// stay until `radcache compact`) and, for the server's own jobs, the
/// frame files it wrote under `--out`. Its followers' streams end.
pub async fn delete(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Value>, ApiError> {
    let key = JobKey::of(&id);
    let job = {
        // Decided and removed under the table's lock: the worker starts
        // only jobs it finds there, queued.
        let mut jobs = state.jobs.lock().expect("job table lock");
        let job = jobs
            .get(&key)
            .ok_or_else(|| ApiError::not_found(format!("no job {id:?}")))?;
        if matches!(job.state, JobState::Queued | JobState::Running) {
            return Err(ApiError::conflict(format!(
                "job {id} is {}; cancel it first",
                job.state.as_str()
            )));
        }
        jobs.remove(&key).expect("found above")
    };
    let s = state.clone();
    let name = id.clone();
    let deleted = tokio::task::spawn_blocking(move || s.store.delete_job(&name))
        .await
        .map_err(ApiError::internal)
        .and_then(|r| r.map_err(ApiError::internal));
    let deleted = match deleted {
        Ok(deleted) => deleted,
        Err(e) => {
            // Still in the store: listed again, as a restart would list it.
            state.jobs.lock().expect("job table lock").insert(key, job);
            return Err(e);
        }
    };
    if let Some(stored) = deleted {
        // Its records' kept sets: no query asks for them any more.
        let mut sets = state.alive_sets.lock().expect("alive sets lock");
        sets.forget(stored.id);
    }
    // Gone from the store: its followers end whatever happens to its files.
    state.forget(&key);
    if let JobKey::Served(_) = key {
        let dir = state.options.out.join(&id);
        let name = id.clone();
        let removed = tokio::task::spawn_blocking(move || match std::fs::remove_dir_all(&dir) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(anyhow::anyhow!(
                "job {name} deleted, but not its frame files: {}: {e}",
                dir.display()
            )),
            _ => Ok(()),
        });
        removed
            .await
            .map_err(ApiError::internal)?
            .map_err(ApiError::internal)?;
    }
    Ok(Json(json!({ "id": id, "deleted": true })))
}

/// The 409 of a resume of a job in state `s`.
fn not_resumable(id: &str, s: JobState) -> ApiError {
    ApiError::conflict(format!(
        "job {id} is {}; only cancelled or failed jobs can be resumed",
        s.as_str()
    ))
}

pub async fn resume(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Value>, ApiError> {
    let job = state.job(&id)?;
    match job.state {
        JobState::Cancelled | JobState::Failed => {}
        JobState::Stopped => {
            return Err(ApiError::conflict(format!(
                "job {id} was rendered by `radcache render --job {id}` and stopped after {} of {} \
                 frames; run that command again (with the same --db) to resume it",
                job.frames_done,
                job.request.frames_total()
            )))
        }
        s => return Err(not_resumable(&id, s)),
    }
    // The cancel mark and the table's state change together, under the
    // control lock (as `cancel`'s), and on the state as it is then, not on
    // the copy above: another resume may have queued the job meanwhile and
    // the worker started it. Queued again, a running job showed as queued,
    // a cancel then left it running, and a delete let it write on. (The
    // worker never moves a job out of cancelled or failed.)
    let _control = state.controlling.lock().expect("job control lock");
    match state.job(&id)?.state {
        JobState::Cancelled | JobState::Failed => {}
        s => return Err(not_resumable(&id, s)),
    }
    // Durable first: a restart queues the job again. With its attempt
    // mark gone, it gets two fresh attempts however often the server died
    // in it before (`worker::crash_loop`).
    state
        .store
        .set_job_cancelled(&id, false)
        .map_err(ApiError::internal)?;
    state
        .store
        .clear_job_attempts(&id)
        .map_err(ApiError::internal)?;
    state.update(&id, |j| {
        j.state = JobState::Queued;
        j.cancel = false;
        j.error = None;
    });
    drop(_control);
    state.wake.notify_one();
    Ok(Json(job_json(&state, &state.job(&id)?)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::server::testing;

    /// A job's memory is checked on its scene's triangles, a built-in
    /// scene's too: a `spheres` job that would fit on an empty scene is a
    /// 400 that counts them, and nothing is queued; with their memory
    /// available it is created.
    #[tokio::test]
    async fn a_job_is_checked_on_its_scene_triangles() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        let body = br#"{"scene":"builtin:spheres","method":"path","frames":"0..1","size":"32x32","spp":1}"#;
        let triangles = memory::scene_triangles(&crate::scene::Scene::builtin("spheres").unwrap());
        assert!(triangles > 10_000, "{triangles}");
        let fits_empty = |r: &JobRequest, t: u64| {
            r.check_memory_within(t, Some(memory::peak_bytes(&r.method, 32, 32, 0)))
        };
        let err = create_checked(state.clone(), body, fits_empty)
            .await
            .unwrap_err();
        assert_eq!(err.status, StatusCode::BAD_REQUEST);
        assert!(
            err.detail
                .contains(&format!("(its scene has {triangles} triangles)")),
            "{}",
            err.detail
        );
        assert!(state.jobs.lock().unwrap().is_empty());
        let fits_scene = |r: &JobRequest, t: u64| {
            let need = memory::peak_bytes(&r.method, 32, 32, triangles);
            r.check_memory_within(t, Some(need))
        };
        let (status, _) = create_checked(state.clone(), body, fits_scene)
            .await
            .unwrap();
        assert_eq!(status, StatusCode::CREATED);
        assert_eq!(state.jobs.lock().unwrap().len(), 1);
    }
}
