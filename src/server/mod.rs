//! `radcache serve` (DESIGN.md "HTTP API"): an axum router over one
//! [`AppState`], and a background worker that renders queued jobs one at a
//! time through the same library path as `radcache render --db --job`
//! ([`crate::render::render_job_to_dir_with`]). Handlers are thin: parse,
//! call the library or the job table, map errors to a status.

mod error;
mod frames;
mod jobs;
mod request;
mod worker;

pub use error::ApiError;
pub use request::{JobRequest, MAX_FRAMES};

use crate::render::BackendChoice;
use crate::store::Store;
use anyhow::{bail, Context, Result};
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::Notify;

/// Largest accepted request body (a job request is a few hundred bytes).
pub const MAX_BODY_BYTES: usize = 16 * 1024;

/// What `radcache serve` is started with.
#[derive(Clone, Debug)]
pub struct ServeOptions {
    pub db: PathBuf,
    pub addr: SocketAddr,
    /// Scene files a job may name live under this directory.
    pub scenes: Option<PathBuf>,
    pub token: Option<String>,
    pub backend: BackendChoice,
    /// Where each job's frame files are written (`DIR/<job id>/`).
    pub out: PathBuf,
}

/// A job's lifecycle state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobState {
    Queued,
    Running,
    Done,
    Failed,
    Cancelled,
}

impl JobState {
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }
}

/// One job in the server's table; its frames and progress live in the store
/// under the store job named `id`.
#[derive(Clone, Debug)]
pub struct Job {
    pub id: String,
    pub request: JobRequest,
    pub state: JobState,
    pub frames_done: u32,
    pub error: Option<String>,
    /// Set by `cancel`; the worker stops after the current frame.
    pub cancel: bool,
}

/// The one shared state of the server.
pub struct AppState {
    pub store: Store,
    pub options: ServeOptions,
    /// Jobs by number (`job-N`), in creation order.
    pub jobs: Mutex<BTreeMap<u64, Job>>,
    /// Wakes the worker when a job is queued.
    pub wake: Notify,
    /// Ctrl-C / SIGTERM: stop after the current frame.
    pub shutdown: AtomicBool,
    pub frames_rendered: AtomicU64,
    pub render_micros: AtomicU64,
}

impl AppState {
    pub fn job(&self, id: &str) -> Result<Job, ApiError> {
        let n = parse_job_id(id).ok_or_else(|| ApiError::not_found(format!("no job {id:?}")))?;
        self.jobs
            .lock()
            .expect("job table lock")
            .get(&n)
            .cloned()
            .ok_or_else(|| ApiError::not_found(format!("no job {id:?}")))
    }

    pub fn update(&self, id: &str, f: impl FnOnce(&mut Job)) {
        if let Some(n) = parse_job_id(id) {
            if let Some(job) = self.jobs.lock().expect("job table lock").get_mut(&n) {
                f(job);
            }
        }
    }
}

/// `job-N` → N.
pub fn parse_job_id(id: &str) -> Option<u64> {
    id.strip_prefix("job-")?.parse().ok()
}

/// The API router over `state`.
pub fn router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/api/jobs", post(jobs::create).get(jobs::list))
        .route("/api/jobs/{id}", get(jobs::show))
        .route("/api/jobs/{id}/cancel", post(jobs::cancel))
        .route("/api/jobs/{id}/resume", post(jobs::resume))
        .route("/api/jobs/{id}/frames/{file}", get(frames::frame))
        .route("/api/jobs/{id}/stats", get(frames::stats))
        .route("/metrics", get(frames::metrics))
        .fallback(|| async { ApiError::not_found("no such route".into()) })
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .layer(middleware::from_fn_with_state(state.clone(), check_token))
        .with_state(state)
}

async fn index() -> impl IntoResponse {
    axum::response::Html(include_str!("../../web/index.html"))
}

/// With a token configured, every request must carry it as
/// `Authorization: Bearer TOKEN` or `?token=TOKEN`.
async fn check_token(State(state): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    if let Some(token) = &state.options.token {
        let bearer = req
            .headers()
            .get(axum::http::header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "));
        let query = req
            .uri()
            .query()
            .and_then(|q| q.split('&').find_map(|kv| kv.strip_prefix("token=")));
        if bearer != Some(token.as_str()) && query != Some(token.as_str()) {
            return ApiError::new(
                axum::http::StatusCode::UNAUTHORIZED,
                "unauthorized",
                "missing or wrong token".into(),
            )
            .into_response();
        }
    }
    next.run(req).await
}

/// Runs the server until Ctrl-C or SIGTERM; the job being rendered stops
/// after its current frame (and resumes on the next start).
pub fn serve(options: ServeOptions) -> Result<()> {
    if !options.addr.ip().is_loopback() && options.token.is_none() {
        bail!(
            "binding to non-loopback address {} requires --token (or RADCACHE_TOKEN)",
            options.addr
        );
    }
    let store = Store::open(&options.db)?;
    let state = Arc::new(AppState {
        store,
        options: options.clone(),
        jobs: Mutex::new(BTreeMap::new()),
        wake: Notify::new(),
        shutdown: AtomicBool::new(false),
        frames_rendered: AtomicU64::new(0),
        render_micros: AtomicU64::new(0),
    });
    worker::load_jobs(&state)?;
    let runtime = tokio::runtime::Runtime::new().context("cannot start the tokio runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(options.addr)
            .await
            .with_context(|| format!("cannot listen on {}", options.addr))?;
        let local = listener.local_addr()?;
        println!("listening on http://{local}");
        use std::io::Write;
        std::io::stdout().flush().ok();
        let worker = tokio::spawn(worker::run(state.clone()));
        let app = router(state.clone());
        let stopping = state.clone();
        axum::serve(listener, app)
            .with_graceful_shutdown(async move {
                shutdown_signal().await;
                stopping.shutdown.store(true, Ordering::SeqCst);
                stopping.wake.notify_one();
            })
            .await
            .context("server error")?;
        worker.await.context("worker panicked")?;
        state.store.flush()?;
        Ok(())
    })
}

async fn shutdown_signal() {
    let ctrl_c = async {
        tokio::signal::ctrl_c().await.ok();
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}
