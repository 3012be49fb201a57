//! Following a job live: `/stream` (its frames as they complete, as
//! `multipart/x-mixed-replace` PNG parts, which an `<img>` tag and `curl`
//! both read) and `/events` (server-sent events: `frame`, `progress`,
//! `state`). Both start with what is already done and end when the job
//! does. A follower sleeps on the job's watch channel
//! ([`AppState::subscribe`]), which the worker bumps after every frame and
//! state change: no polling.

use super::frames::frame_stats_json;
use super::jobs::job_json;
use super::{ApiError, AppState, Job};
use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::stream;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::ops::Range;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// Multipart boundary of `/stream`.
const BOUNDARY: &str = "radcache-frame";

/// What a follower sees next.
enum Step {
    /// A frame is stored (frames come in frame order, over all of the
    /// job's ranges).
    Frame(u32),
    /// The job changed (progress or state), no new frame.
    Changed(Job),
    /// The job ended (done, failed, cancelled) or the server is stopping;
    /// every stored frame has been reported.
    End(Job),
}

/// Walks a job's frames in order and its changes.
struct Follower {
    state: Arc<AppState>,
    id: String,
    rx: watch::Receiver<u64>,
    /// Frames before this one have been reported (or are not stored).
    next: u32,
    /// Store id, once the job has one.
    sid: Option<u64>,
    /// Last (state, frames done) reported by `Changed`.
    seen: Option<(super::JobState, u32)>,
    ended: bool,
    /// Why the follower ended before the job did, when not for a shutdown
    /// (the store failed).
    failure: Option<String>,
}

impl Follower {
    fn new(state: Arc<AppState>, id: String) -> Result<Follower, ApiError> {
        // Subscribe first: a change after this point wakes us.
        let rx = state.subscribe(&id)?;
        Ok(Follower {
            state,
            id,
            rx,
            next: 0,
            sid: None,
            seen: None,
            ended: false,
            failure: None,
        })
    }

    async fn step(&mut self) -> Result<Step, ApiError> {
        loop {
            self.rx.borrow_and_update();
            // State before frames: a job seen ended has stored all its frames.
            let job = self.state.job(&self.id)?;
            let over = job.state.is_final() || self.state.shutdown.load(Ordering::SeqCst);
            if let Some(frame) = next_to_report(&job.stored, &job.request.frames, self.next, over) {
                if self.sid.is_none() {
                    // A store read: off the async threads.
                    let (state, id) = (self.state.clone(), self.id.clone());
                    self.sid = self
                        .state
                        .reading_stats(move || state.store_id(&id))
                        .await?;
                }
                self.next = frame + 1;
                return Ok(Step::Frame(frame));
            }
            if over {
                self.ended = true;
                return Ok(Step::End(job));
            }
            let now = (job.state, job.frames_done);
            if self.seen != Some(now) {
                self.seen = Some(now);
                return Ok(Step::Changed(job));
            }
            if self.rx.changed().await.is_err() {
                self.ended = true;
                return Ok(Step::End(job));
            }
        }
    }

    /// Ends the follower on a failed read, saying why.
    fn fail(&mut self, e: &ApiError) {
        self.ended = true;
        self.failure = Some(format!("reading the job failed: {}", e.detail));
    }
}

/// The `frame` event of stored frame `frame`: its statistics row (the
/// frame number alone where none can be read), read from the store off the
/// async threads, in a stats slot, as `/stats` reads it.
async fn frame_event(f: &Follower, frame: u32) -> Result<Event, ApiError> {
    let (state, sid) = (f.state.clone(), f.sid);
    let row = f
        .state
        .reading_stats(move || {
            Ok(sid.and_then(|sid| frame_stats_json(&state, sid, frame).ok().flatten()))
        })
        .await?
        .unwrap_or_else(|| serde_json::json!({ "frame": frame }));
    Ok(Event::default().event("frame").data(row.to_string()))
}

/// The `progress` event of `job`: naming its scene reads the file system
/// (the `--scenes` directory), off the async threads too.
async fn progress_event(state: &Arc<AppState>, job: &Job) -> Result<Event, ApiError> {
    let (s, job) = (state.clone(), job.clone());
    let data = state
        .reading_stats(move || Ok(job_json(&s, &job).to_string()))
        .await?;
    Ok(Event::default().event("progress").data(data))
}

/// The next frame to report of a job whose stored frames are the runs
/// `stored` and which renders `range`: the first stored frame at or after
/// `next`, over all of the job's ranges (frames of earlier renders of it
/// may lie outside `range`), unless the job may still render an earlier
/// frame of `range`. Frames come in frame order, and a job renders its
/// range in order. Once the job is `over`, every stored frame left is
/// reported.
fn next_to_report(stored: &[Range<u32>], range: &Range<u32>, next: u32, over: bool) -> Option<u32> {
    let next_stored = stored
        .iter()
        .find(|r| r.end > next)
        .map(|r| r.start.max(next))?;
    if over {
        return Some(next_stored);
    }
    let from = range.start.max(next);
    // Runs are maximal, so the end of the one holding `from` is not stored.
    let unrendered = stored
        .iter()
        .find(|r| r.contains(&from))
        .map_or(from, |r| r.end);
    (next_stored < unrendered || unrendered >= range.end).then_some(next_stored)
}

/// A `state` event: `final` when the job has ended (done, failed,
/// cancelled); a stream that closes while the job has not (the server
/// stops, or the store failed: `failure`) says why in `closing`, and the
/// client reconnects later.
fn state_event(job: &Job, closing: bool, failure: Option<&str>) -> Event {
    let ended = job.state.is_final();
    let mut s = serde_json::json!({ "id": job.id, "state": job.state.as_str(), "final": ended });
    if closing && !ended {
        s["closing"] = failure.unwrap_or("the server is stopping").into();
    }
    Event::default().event("state").data(s.to_string())
}

/// `GET /api/jobs/{id}/stream`.
pub async fn frames(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let follower = Follower::new(state, id)?;
    let parts = stream::unfold(follower, |mut f| async move {
        if f.ended {
            return None;
        }
        loop {
            let step = match f.step().await {
                Ok(s) => s,
                // The job vanished or the store failed: end the stream.
                Err(_) => Step::End(f.state.job(&f.id).ok()?),
            };
            match step {
                Step::Frame(frame) => {
                    let sid = f.sid?;
                    let Ok(Some(png)) = f.state.frame_png(sid, frame).await else {
                        continue;
                    };
                    let mut part = format!(
                        "--{BOUNDARY}\r\nContent-Type: image/png\r\nContent-Length: {}\r\nX-Frame: {frame}\r\n\r\n",
                        png.len()
                    )
                    .into_bytes();
                    part.extend_from_slice(&png);
                    part.extend_from_slice(b"\r\n");
                    return Some((Ok::<_, Infallible>(Bytes::from(part)), f));
                }
                Step::Changed(_) => continue,
                Step::End(_) => {
                    f.ended = true;
                    let end = Bytes::from(format!("--{BOUNDARY}--\r\n"));
                    return Some((Ok(end), f));
                }
            }
        }
    });
    Ok((
        [
            (
                header::CONTENT_TYPE,
                format!("multipart/x-mixed-replace; boundary={BOUNDARY}"),
            ),
            (header::CACHE_CONTROL, "no-cache, no-store".to_string()),
        ],
        Body::from_stream(parts),
    )
        .into_response())
}

/// `GET /api/jobs/{id}/events`: `progress` (the job, as `GET /api/jobs/{id}`,
/// with `eta_seconds`) at the start and on every change; `frame` (the
/// frame's statistics, as a `/stats` row) for every stored frame in order;
/// `state` (`{"id","state"}`) when the state changes; the stream closes after
/// the job's final `state` event.
pub async fn events(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<impl IntoResponse, ApiError> {
    let follower = Follower::new(state, id)?;
    let queue: VecDeque<Event> = VecDeque::new();
    let events = stream::unfold(
        (follower, queue, None::<super::JobState>),
        |(mut f, mut queue, mut last_state)| async move {
            loop {
                if let Some(e) = queue.pop_front() {
                    return Some((Ok::<_, Infallible>(e), (f, queue, last_state)));
                }
                if f.ended {
                    return None;
                }
                let step = match f.step().await {
                    Ok(s) => s,
                    // The job vanished or the store failed: end the stream
                    // (after its `progress` and `state` events), or the
                    // failing step would be taken again and again.
                    Err(e) => {
                        f.fail(&e);
                        Step::End(f.state.job(&f.id).ok()?)
                    }
                };
                let job = match step {
                    Step::Frame(frame) => match frame_event(&f, frame).await {
                        Ok(event) => {
                            queue.push_back(event);
                            continue;
                        }
                        Err(e) => {
                            f.fail(&e);
                            f.state.job(&f.id).ok()?
                        }
                    },
                    Step::Changed(job) | Step::End(job) => job,
                };
                match progress_event(&f.state, &job).await {
                    Ok(event) => queue.push_back(event),
                    Err(e) => f.fail(&e),
                }
                if last_state != Some(job.state) || f.ended {
                    last_state = Some(job.state);
                    queue.push_back(state_event(&job, f.ended, f.failure.as_deref()));
                }
            }
        },
    );
    Ok(Sse::new(events).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}

#[cfg(test)]
mod tests {
    use super::next_to_report;
    use crate::server::testing;
    use crate::server::JobState;
    use axum::extract::{Path, State};
    use axum::response::IntoResponse;

    /// A job whose store entry cannot be read (its store id fails) ends
    /// its event stream with a `state` event saying why, rather than
    /// sending `progress` events for ever.
    #[tokio::test]
    async fn events_end_when_the_store_fails() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        testing::add_job(&state, "job-1", JobState::Running, &[0]);
        state
            .store
            .raw_insert("jobs", b"job-1", b"not a job")
            .unwrap();
        assert!(state.store_id("job-1").is_err());
        let response = super::events(State(state), Path("job-1".to_string()))
            .await
            .unwrap()
            .into_response();
        // Without an end, the body would run past any limit.
        let body = axum::body::to_bytes(response.into_body(), 1 << 20)
            .await
            .expect("the event stream ends");
        let text = String::from_utf8(body.to_vec()).unwrap();
        assert_eq!(text.matches("event: progress").count(), 1, "{text}");
        assert_eq!(text.matches("event: state").count(), 1, "{text}");
        assert!(text.contains("reading the job failed"), "{text}");
    }

    /// The whole event stream of job `id`, as (event, data) pairs.
    async fn events_of(
        state: std::sync::Arc<crate::server::AppState>,
        id: &str,
    ) -> Vec<(String, serde_json::Value)> {
        let response = super::events(State(state), Path(id.to_string()))
            .await
            .unwrap()
            .into_response();
        let body = tokio::time::timeout(
            std::time::Duration::from_secs(30),
            axum::body::to_bytes(response.into_body(), 1 << 20),
        )
        .await
        .expect("the event stream ends")
        .unwrap();
        let text = String::from_utf8(body.to_vec()).unwrap();
        text.split("\n\n")
            .filter_map(|block| {
                let event = block.lines().find_map(|l| l.strip_prefix("event: "))?;
                let data = block.lines().find_map(|l| l.strip_prefix("data: "))?;
                Some((event.to_string(), serde_json::from_str(data).unwrap()))
            })
            .collect()
    }

    /// A finished job's events: each stored frame's statistics row as the
    /// store holds it, in frame order, then the job's progress and its
    /// final state.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn events_come_in_order_with_the_stored_rows() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        testing::store_frames(&state, "job-1", &[0, 1]);
        testing::add_job(&state, "job-1", JobState::Done, &[0, 1]);
        let events = events_of(state, "job-1").await;
        let kinds: Vec<&str> = events.iter().map(|(e, _)| e.as_str()).collect();
        assert_eq!(kinds, ["frame", "frame", "progress", "state"], "{events:?}");
        for (f, (_, row)) in events[..2].iter().enumerate() {
            assert_eq!(row["frame"], f, "{row}");
            assert_eq!(row["records_alive"], 10 + f, "{row}");
        }
        assert_eq!(events[2].1["frames_done"], 2);
        assert_eq!(events[3].1["state"], "done");
        assert_eq!(events[3].1["final"], true);
    }

    /// The event streams read the store in the stats slots (on blocking
    /// threads, as `/stats` does), not on the async threads: with no slot
    /// to be had, a running job's stream ends at its first read, saying
    /// why, and sends no row (it read none).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn events_read_the_store_in_the_stats_slots() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        testing::store_frames(&state, "job-1", &[0]);
        testing::add_job(&state, "job-1", JobState::Running, &[0]);
        state.stats_slots.close();
        let events = events_of(state, "job-1").await;
        let kinds: Vec<&str> = events.iter().map(|(e, _)| e.as_str()).collect();
        assert_eq!(kinds, ["state"], "{events:?}");
        let closing = events[0].1["closing"].as_str().unwrap_or_default();
        assert!(closing.contains("reading the job failed"), "{events:?}");
    }

    #[test]
    fn frames_are_reported_in_order_over_all_stored_ranges() {
        // Rendering 10..20: frames 0..3 of an earlier range come first, then
        // 10 and 11 as stored; 12 is awaited, though 15..20 (stored by an
        // earlier render of that range) are there already.
        let stored = [0..3, 10..12, 15..20];
        let report = |next, over| next_to_report(&stored, &(10..20), next, over);
        assert_eq!(report(0, false), Some(0));
        assert_eq!(report(3, false), Some(10));
        assert_eq!(report(12, false), None);
        assert_eq!(report(12, true), Some(15));
        assert_eq!(report(20, false), None);
        // Once 12..15 are stored, the runs merge and 15.. follow.
        let stored = [0..3, 10..20];
        assert_eq!(next_to_report(&stored, &(10..20), 12, false), Some(12));
        assert_eq!(next_to_report(&stored, &(10..20), 15, false), Some(15));
        // Frames stored past the range are reported after it.
        let stored = [5..8, 30..32];
        assert_eq!(next_to_report(&stored, &(5..8), 8, false), Some(30));
        assert_eq!(next_to_report(&stored, &(5..10), 8, false), None);
    }
}
