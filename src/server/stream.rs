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
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// Multipart boundary of `/stream`.
const BOUNDARY: &str = "radcache-frame";

/// What a follower sees next.
enum Step {
    /// A frame was stored (frames come in frame order).
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
    /// Next frame to report.
    next: u32,
    /// Store id, once the job has one.
    sid: Option<u64>,
    /// Last (state, frames done) reported by `Changed`.
    seen: Option<(super::JobState, u32)>,
    ended: bool,
}

impl Follower {
    fn new(state: Arc<AppState>, id: String) -> Result<Follower, ApiError> {
        // Subscribe first: a change after this point wakes us.
        let rx = state.subscribe(&id)?;
        let next = state.job(&id)?.request.frames.start;
        Ok(Follower {
            state,
            id,
            rx,
            next,
            sid: None,
            seen: None,
            ended: false,
        })
    }

    /// The next stored frame at or after `self.next` within the job's range.
    fn next_frame(&mut self, job: &Job, final_scan: bool) -> Result<Option<u32>, ApiError> {
        if self.sid.is_none() {
            self.sid = self.state.store_id(&self.id)?;
        }
        let Some(sid) = self.sid else {
            return Ok(None);
        };
        let range = &job.request.frames;
        if self.next >= range.end {
            return Ok(None);
        }
        // Frames are rendered in order, so the next one is the one to look
        // for; once the job ended, anything left (out of order) is reported.
        if self
            .state
            .store
            .frame_done(sid, self.next)
            .map_err(ApiError::internal)?
        {
            return Ok(Some(self.next));
        }
        if final_scan {
            let done = self
                .state
                .store
                .frames_done(sid)
                .map_err(ApiError::internal)?;
            return Ok(done.into_iter().find(|f| *f >= self.next && *f < range.end));
        }
        Ok(None)
    }

    async fn step(&mut self) -> Result<Step, ApiError> {
        loop {
            self.rx.borrow_and_update();
            // State before frames: a job seen ended has stored all its frames.
            let job = self.state.job(&self.id)?;
            let over = job.state.is_final() || self.state.shutdown.load(Ordering::SeqCst);
            if let Some(frame) = self.next_frame(&job, over)? {
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
}

/// A `state` event: `final` when the job has ended (done, failed,
/// cancelled); a stream that closes while the job has not (the server
/// stops) says so in `closing`, and the client reconnects later.
fn state_event(job: &Job, closing: bool) -> Event {
    let ended = job.state.is_final();
    let mut s = serde_json::json!({ "id": job.id, "state": job.state.as_str(), "final": ended });
    if closing && !ended {
        s["closing"] = "the server is stopping".into();
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
                    Err(_) => Step::End(f.state.job(&f.id).ok()?),
                };
                let job = match step {
                    Step::Frame(frame) => {
                        let row = f
                            .sid
                            .and_then(|sid| frame_stats_json(&f.state, sid, frame).ok().flatten())
                            .unwrap_or_else(|| serde_json::json!({ "frame": frame }));
                        queue.push_back(Event::default().event("frame").data(row.to_string()));
                        continue;
                    }
                    Step::Changed(job) | Step::End(job) => job,
                };
                queue.push_back(
                    Event::default()
                        .event("progress")
                        .data(job_json(&f.state, &job).to_string()),
                );
                if last_state != Some(job.state) || f.ended {
                    last_state = Some(job.state);
                    queue.push_back(state_event(&job, f.ended));
                }
            }
        },
    );
    Ok(Sse::new(events).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}
