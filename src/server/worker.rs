//! The background worker: one queued job at a time, rendered in
//! `spawn_blocking` through [`render::render_job_to_dir_with`], the same
//! store job and resume logic as `radcache render --db --job`.

use super::{AppState, Job, JobKey, JobRequest, JobState};
use crate::render::{self, Renderer, StoreJob};
use crate::store::schema::JobValue;
use anyhow::{Context, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Fills the job table from the store's jobs. Of the server's own (`job-N`)
/// finished ones are done, cancelled ones stay cancelled, other unfinished
/// ones (interrupted by a stop or a crash) are queued again, but for one
/// the server died in twice with no frame stored in between
/// ([`crash_loop`]), which fails. Those of `radcache render --job NAME`
/// are done or stopped ([`JobKey`]).
pub fn load_jobs(state: &AppState) -> Result<()> {
    let mut jobs = state.jobs.lock().expect("job table lock");
    for stored in state.store.jobs()? {
        let Some(request) = JobRequest::from_stored(&stored) else {
            eprintln!(
                "warning: job {:?} in the store names no method or frames this server can render; left out",
                stored.name
            );
            continue;
        };
        let key = JobKey::of(&stored.name);
        let frames = stored_frames(state, stored.id);
        let mut job = Job::new(stored.name.clone(), request, JobState::Queued, &frames);
        job.state = if job.frames_done == job.request.frames_total() {
            JobState::Done
        } else if matches!(key, JobKey::Rendered(_)) {
            JobState::Stopped
        } else if state.store.job_cancelled(&stored.name)? {
            JobState::Cancelled
        } else if let Some(error) = crash_loop(state, &job)? {
            job.error = Some(error);
            JobState::Failed
        } else {
            JobState::Queued
        };
        jobs.insert(key, job);
    }
    Ok(())
}

/// How often the server may die while rendering a job, with no frame
/// stored in between, before a start no longer runs it. One death (a
/// power cut, a kill) resumes by itself; a second on the same frame says
/// the job itself kills it (an allocation that aborts the process, the
/// OOM killer), and a third start would make a crash loop of a
/// supervisor that restarts the server.
const DEATHS_BEFORE_FAILING: u32 = 2;

/// Why unfinished job `job` is not started again: the server died while
/// rendering it [`DEATHS_BEFORE_FAILING`] times with no frame stored in
/// between ([`crate::store::JobAttempt`]). Says so on standard error, as
/// it does for a single death.
fn crash_loop(state: &AppState, job: &Job) -> Result<Option<String>> {
    let Some(attempt) = state.store.job_attempt(&job.id)? else {
        return Ok(None);
    };
    let deaths = attempt.died_without_progress(job.frames_stored());
    let at_frame = first_frame_not_stored(job).map_or(String::new(), |f| format!(" at frame {f}"));
    if deaths < DEATHS_BEFORE_FAILING {
        eprintln!(
            "note: job {}: the server stopped while rendering it{at_frame} (no orderly end); \
             rendering it again",
            job.id
        );
        return Ok(None);
    }
    let times = match deaths {
        2 => "twice".to_string(),
        n => format!("{n} times"),
    };
    let error = format!(
        "the server stopped {times} while rendering this job{at_frame}, with no frame stored in \
         between (perhaps it needs more memory than this machine has); it was not started \
         again: POST /api/jobs/{}/resume to try again",
        job.id
    );
    eprintln!("warning: job {}: {error}", job.id);
    Ok(Some(error))
}

/// The frame of `job`'s range a render starts with: the first not stored.
fn first_frame_not_stored(job: &Job) -> Option<u32> {
    let stored = |f: &u32| job.stored.iter().any(|r| r.contains(f));
    job.request.frames.clone().find(|f| !stored(f))
}

/// The frames store job `store_id` holds (none if the store cannot say:
/// progress is then shown as none, and the render itself reports the
/// store's error).
fn stored_frames(state: &AppState, store_id: u64) -> Vec<u32> {
    state.store.frames_done(store_id).unwrap_or_default()
}

/// Runs queued jobs until shutdown.
pub async fn run(state: Arc<AppState>) {
    loop {
        if state.shutdown.load(Ordering::SeqCst) {
            return;
        }
        let next = {
            let mut jobs = state.jobs.lock().expect("job table lock");
            jobs.values_mut()
                .find(|j| j.state == JobState::Queued)
                .map(|j| {
                    j.state = JobState::Running;
                    j.run_frames = 0;
                    j.run_seconds = 0.0;
                    j.id.clone()
                })
        };
        if let Some(id) = &next {
            state.update(id, |_| {});
        }
        let Some(id) = next else {
            state.wake.notified().await;
            continue;
        };
        let s = state.clone();
        let job_id = id.clone();
        let result = tokio::task::spawn_blocking(move || render_job(&s, &job_id)).await;
        let result = match result {
            Ok(r) => r,
            Err(e) => Err(anyhow::anyhow!("render panicked: {e}")),
        };
        state.update(&id, |j| {
            j.state = match result {
                Err(e) => {
                    j.error = Some(format!("{e:#}"));
                    JobState::Failed
                }
                Ok(()) if j.frames_done == j.request.frames_total() => JobState::Done,
                Ok(()) if j.cancel => JobState::Cancelled,
                // Stopped by shutdown: resumed on the next start.
                Ok(()) => JobState::Queued,
            };
            // A cancel that came as the job ended is over either way.
            j.cancel = false;
        });
    }
}

/// Renders job `id` until it is finished, cancelled or the server stops.
fn render_job(state: &AppState, id: &str) -> Result<()> {
    let request = state
        .job(id)
        .map_err(|e| anyhow::anyhow!("{}", e.detail))?
        .request;
    let root = state.scene_root(&request.scene);
    let scene = request.scene.load_confined(root.as_deref())?;
    let backend = render::make_backend(state.options.backend)?;
    let (stored, _attempt) = start_attempt(state, id, &request, root.as_deref())?;
    let renderer = Renderer::new(
        scene,
        request.method.instantiate(),
        backend,
        request.settings.clone(),
    );
    render_frames(state, id, &request, renderer, stored)
}

/// Begins (or resumes) store job `id` for `request`, shows its stored
/// frames and marks the attempt in the store, before anything of the
/// render itself is allocated ([`Attempt`]).
fn start_attempt<'a>(
    state: &'a AppState,
    id: &'a str,
    request: &JobRequest,
    root: Option<&std::path::Path>,
) -> Result<(JobValue, Attempt<'a>)> {
    let spec = render::job_spec_confined(
        id,
        &request.scene,
        root,
        &request.method,
        &request.settings,
        request.frames.clone(),
    )?;
    let stored = state.store.begin_job(&spec, false).map_err(|e| match e {
        // The API has no `--force`: a job whose scene file changed since
        // it was submitted, or that this build cannot resume (stored by a
        // build whose algorithm differs), is resubmitted.
        crate::store::StoreError::JobDiffers {
            scene_changed,
            differences,
            ..
        } => {
            let why = crate::store::job_differs_text(
                scene_changed.as_deref(),
                &differences,
                "submitted",
                |d| format!("this build cannot resume the job as stored: {d}"),
            );
            anyhow::anyhow!("{why}; delete it and submit it again")
        }
        e => e.into(),
    })?;
    let frames = stored_frames(state, stored.id);
    state.update(id, |j| j.set_stored(&frames));
    let attempt = Attempt::begin(state, id, frames.len() as u32)?;
    Ok((stored, attempt))
}

/// Renders the frames of `request` that store job `stored` lacks with
/// `renderer`, until done, cancelled or the server stops.
fn render_frames(
    state: &AppState,
    id: &str,
    request: &JobRequest,
    mut renderer: Renderer,
    stored: JobValue,
) -> Result<()> {
    let store_id = stored.id;
    let _running = RunningFrame::new(state, id, renderer.abandon_flag());
    let mut job = StoreJob {
        store: &state.store,
        job: stored,
    };
    let out = state.options.out.join(id);
    let mut last = Instant::now();
    let mut written = FramesWritten {
        state,
        sid: store_id,
        next: request.frames.start,
    };
    let mut after_frame = |frame: u32| {
        written.acknowledged(frame);
        let micros = last.elapsed().as_micros() as u64;
        last = Instant::now();
        state.frames_rendered.fetch_add(1, Ordering::Relaxed);
        state.render_micros.fetch_add(micros, Ordering::Relaxed);
        let frames = stored_frames(state, store_id);
        let mut go_on = !state.shutdown.load(Ordering::SeqCst);
        state.update(id, |j| {
            j.set_stored(&frames);
            j.run_frames += 1;
            j.run_seconds += micros as f64 / 1e6;
            go_on &= !j.cancel;
        });
        go_on
    };
    render::render_job_to_dir_with(
        &mut renderer,
        request.frames.clone(),
        &out,
        true,
        Some(&mut job),
        &mut after_frame,
    )?;
    Ok(())
}

/// The store's mark of the worker's render of a job
/// ([`crate::store::Store::begin_job_attempt`]), removed when the render
/// ends in any orderly way: done, cancelled, failed, stopped by a shutdown
/// or panicked (unwinding drops it). Only a death of the process leaves
/// it, for the next start to count ([`crash_loop`]).
struct Attempt<'a> {
    state: &'a AppState,
    id: &'a str,
}

impl<'a> Attempt<'a> {
    /// Marks the attempt, job `id` having `frames_stored` frames stored.
    fn begin(state: &'a AppState, id: &'a str, frames_stored: u32) -> Result<Self> {
        state
            .store
            .begin_job_attempt(id, frames_stored)
            .context("cannot mark the start of the job's render in the store")?;
        Ok(Attempt { state, id })
    }
}

impl Drop for Attempt<'_> {
    fn drop(&mut self) {
        if let Err(e) = self.state.store.clear_job_attempts(self.id) {
            // The next start then counts this render as one the server
            // died in; at worst the job fails there, and a resume clears it.
            eprintln!(
                "warning: job {}: the mark of its render could not be removed from the store: {e}",
                self.id
            );
        }
    }
}

/// Tells the kept alive sets of `/records` ([`AppState::alive_sets`]) of
/// each frame a run writes, once it is stored, and, when the run ends, of
/// the frames from the one after the last acknowledged: a frame stored
/// whose files could not be written ends the run unacknowledged, and a
/// set that read the block it replaced would be served on.
struct FramesWritten<'a> {
    state: &'a AppState,
    sid: u64,
    /// The frame after the last acknowledged (the run's first, before).
    next: u32,
}

impl FramesWritten<'_> {
    fn acknowledged(&mut self, frame: u32) {
        self.tell(frame);
        self.next = frame.saturating_add(1);
    }

    fn tell(&self, frame: u32) {
        let mut sets = self.state.alive_sets.lock().expect("alive sets lock");
        sets.written(self.sid, frame);
    }
}

impl Drop for FramesWritten<'_> {
    fn drop(&mut self) {
        self.tell(self.next);
    }
}

/// Registers the worker's renderer as [`AppState::running_frame`] while it
/// renders a job; a cancel or shutdown that came before it did abandons
/// the first frame at once.
struct RunningFrame<'a> {
    state: &'a AppState,
}

impl<'a> RunningFrame<'a> {
    fn new(state: &'a AppState, id: &str, abandon: Arc<AtomicBool>) -> Self {
        *state.running_frame.lock().expect("running frame lock") = Some((JobKey::of(id), abandon));
        let cancelled = state.job(id).is_ok_and(|j| j.cancel);
        if cancelled || state.shutdown.load(Ordering::SeqCst) {
            state.abandon_frame(Some(id));
        }
        RunningFrame { state }
    }
}

impl Drop for RunningFrame<'_> {
    fn drop(&mut self) {
        *self.state.running_frame.lock().expect("running frame lock") = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::BackendChoice;
    use crate::server::{alive, jobs, testing};
    use crate::store::schema::RecordValue;
    use std::cell::Cell;

    /// What a death of the server as it renders job `id` leaves: the
    /// worker's start of the render, and no orderly end.
    fn die_rendering(state: &AppState, id: &str) {
        let request = state.job(id).unwrap().request;
        let (_, attempt) = start_attempt(state, id, &request, None).unwrap();
        std::mem::forget(attempt);
    }

    /// Job `id` as the next start of the server over the same store finds
    /// it.
    fn restarted(state: &AppState, id: &str) -> Job {
        state.jobs.lock().unwrap().clear();
        load_jobs(state).unwrap();
        state.job(id).unwrap()
    }

    /// A server that died once while rendering a job renders it again on
    /// its next start; one that died twice on it with no frame stored in
    /// between fails it, saying why, on every start until a resume, which
    /// gives it two fresh attempts.
    #[tokio::test]
    async fn a_job_the_server_died_in_twice_is_not_started_again_until_resumed() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        testing::add_job(&state, "job-1", JobState::Queued, &[]);
        die_rendering(&state, "job-1");
        let job = restarted(&state, "job-1");
        assert_eq!((job.state, job.error), (JobState::Queued, None));
        die_rendering(&state, "job-1");
        for _ in 0..2 {
            let job = restarted(&state, "job-1");
            assert_eq!(job.state, JobState::Failed);
            let error = job.error.unwrap();
            assert!(
                error.starts_with("the server stopped twice while rendering this job at frame 0, with no frame stored in between")
                    && error.ends_with("POST /api/jobs/job-1/resume to try again"),
                "{error}"
            );
        }
        let path = axum::extract::Path("job-1".to_string());
        let resumed = jobs::resume(axum::extract::State(state.clone()), path).await;
        assert_eq!(resumed.unwrap()["state"], "queued");
        assert_eq!(state.store.job_attempt("job-1").unwrap(), None);
        assert_eq!(restarted(&state, "job-1").state, JobState::Queued);
        die_rendering(&state, "job-1");
        assert_eq!(restarted(&state, "job-1").state, JobState::Queued);
        die_rendering(&state, "job-1");
        assert_eq!(restarted(&state, "job-1").state, JobState::Failed);
    }

    /// Deaths with a frame stored in between are no crash loop: the job
    /// moves on, and is started again until the server dies twice on one
    /// frame.
    #[test]
    fn deaths_with_a_frame_stored_in_between_do_not_fail_the_job() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        testing::add_job(&state, "job-1", JobState::Queued, &[]);
        die_rendering(&state, "job-1");
        // The second attempt stores frame 0, then the server dies.
        let mut request = state.job("job-1").unwrap().request;
        let (stored, attempt) = start_attempt(&state, "job-1", &request, None).unwrap();
        let scene = request.scene.load_confined(None).unwrap();
        let backend = render::make_backend(BackendChoice::Cpu).unwrap();
        let method = request.method.instantiate();
        let renderer = Renderer::new(scene, method, backend, request.settings.clone());
        request.frames = 0..1;
        render_frames(&state, "job-1", &request, renderer, stored).unwrap();
        std::mem::forget(attempt);
        assert_eq!(restarted(&state, "job-1").state, JobState::Queued);
        die_rendering(&state, "job-1");
        assert_eq!(restarted(&state, "job-1").state, JobState::Queued);
        die_rendering(&state, "job-1");
        let job = restarted(&state, "job-1");
        assert_eq!(job.state, JobState::Failed);
        assert!(job.error.unwrap().contains(" at frame 1,"));
    }

    /// A render that ends in any orderly way (done, failed, stopped by a
    /// shutdown) leaves no mark for the next start to count.
    #[test]
    fn renders_that_end_in_order_leave_no_attempt_mark() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        for id in ["job-1", "job-2", "job-3"] {
            testing::add_job(&state, id, JobState::Running, &[]);
        }
        render_job(&state, "job-1").unwrap();
        assert_eq!(state.job("job-1").unwrap().frames_done, 2, "done");
        state.shutdown.store(true, Ordering::SeqCst);
        render_job(&state, "job-2").unwrap();
        assert_eq!(state.job("job-2").unwrap().frames_done, 0, "stopped");
        state.shutdown.store(false, Ordering::SeqCst);
        // Its frames cannot be written.
        std::fs::write(state.options.out.join("job-3"), "").unwrap();
        assert!(render_job(&state, "job-3").is_err(), "failed");
        for id in ["job-1", "job-2", "job-3"] {
            assert!(state.store.job(id).unwrap().is_some(), "{id} began");
            assert_eq!(state.store.job_attempt(id).unwrap(), None, "{id}");
        }
    }

    /// Blocks of `/records` read for frame `frame` of store job 1, whose
    /// every frame wrote one record.
    fn blocks_read(state: &AppState, frame: u32) -> usize {
        let read = Cell::new(0);
        let mut blocks = |frames: std::ops::RangeInclusive<u32>,
                          f: &mut dyn FnMut(u32, Vec<RecordValue>)| {
            for written in frames {
                read.set(read.get() + 1);
                f(written, vec![record(written)]);
            }
            Ok(())
        };
        alive::alive_at(&state.alive_sets, 1, frame, &mut blocks).unwrap();
        read.get()
    }

    fn record(frame: u32) -> RecordValue {
        alive::tests::version(u64::from(frame), frame, frame)
    }

    /// A run tells the kept sets of `/records` of each frame it writes and,
    /// as it ends, of those from the one after its last acknowledged (one
    /// stored whose files failed to be written): the sets from there on
    /// are read again.
    #[test]
    fn a_run_tells_the_kept_sets_of_the_frames_it_writes() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        assert_eq!(blocks_read(&state, 39), 40);
        assert_eq!(blocks_read(&state, 39), 0, "kept");
        let mut run = FramesWritten {
            state: &state,
            sid: 1,
            next: 0,
        };
        run.acknowledged(36);
        // From the set kept at frame 32.
        assert_eq!(blocks_read(&state, 39), 7);
        assert_eq!(blocks_read(&state, 39), 0, "kept again");
        run.acknowledged(37);
        assert_eq!(blocks_read(&state, 39), 7);
        // Frame 38 may have been stored, unacknowledged.
        drop(run);
        assert_eq!(blocks_read(&state, 39), 7);
    }
}
