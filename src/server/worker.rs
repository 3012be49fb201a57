//! The background worker: one queued job at a time, rendered in
//! `spawn_blocking` through [`render::render_job_to_dir_with`], the same
//! store job and resume logic as `radcache render --db --job`.

use super::{AppState, Job, JobKey, JobRequest, JobState};
use crate::render::{self, Renderer, StoreJob};
use anyhow::Result;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Fills the job table from the store's jobs. Of the server's own (`job-N`)
/// finished ones are done, cancelled ones stay cancelled, other unfinished
/// ones (interrupted by a stop or a crash) are queued again. Those of
/// `radcache render --job NAME` are done or stopped ([`JobKey`]).
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
        let job = Job::new(stored.name.clone(), request, JobState::Queued, &frames);
        let job_state = if job.frames_done == job.request.frames_total() {
            JobState::Done
        } else if matches!(key, JobKey::Rendered(_)) {
            JobState::Stopped
        } else if state.store.job_cancelled(&stored.name)? {
            JobState::Cancelled
        } else {
            JobState::Queued
        };
        jobs.insert(
            key,
            Job {
                state: job_state,
                ..job
            },
        );
    }
    Ok(())
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
    let spec = render::job_spec_confined(
        id,
        &request.scene,
        root.as_deref(),
        &request.method,
        &request.settings,
        request.frames.clone(),
    )?;
    let stored = state.store.begin_job(&spec, false).map_err(|e| match e {
        // The API has no `--force`: a job this build cannot resume (its
        // scene file changed, or it was stored by a build whose algorithm
        // differs) is resubmitted.
        crate::store::StoreError::JobDiffers { differences, .. } => anyhow::anyhow!(
            "this build cannot resume the job as stored: {differences}; delete it and submit it again"
        ),
        e => e.into(),
    })?;
    let store_id = stored.id;
    let frames = stored_frames(state, store_id);
    state.update(id, |j| j.set_stored(&frames));
    let mut renderer = Renderer::new(
        scene,
        request.method.instantiate(),
        backend,
        request.settings.clone(),
    );
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
    use crate::server::{alive, testing};
    use crate::store::schema::RecordValue;
    use std::cell::Cell;

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
