//! `radcache serve` (DESIGN.md "HTTP API"): an axum router over one
//! [`AppState`], and a background worker that renders queued jobs one at a
//! time through the same library path as `radcache render --db --job`
//! ([`crate::render::render_job_to_dir_with`]). Handlers are thin: parse,
//! call the library or the job table, map errors to a status.

mod alive;
mod connection;
mod error;
mod flight;
mod frames;
mod jobs;
mod layers;
mod movies;
mod records;
mod request;
mod stream;
mod web;
mod worker;

pub use web::OPENAPI;

pub use connection::MAX_CONNECTIONS_PER_PEER;
pub use error::ApiError;
pub use request::{JobRequest, MAX_FRAMES};

use crate::decimal::parse_canonical_u64;
use crate::render::{BackendChoice, SceneSource};
use crate::store::Store;
use anyhow::{bail, Context, Result};
use axum::body::Bytes;
use axum::extract::DefaultBodyLimit;
use axum::middleware;
use axum::routing::{get, post};
use axum::Router;
use flight::Flights;
use layers::{check_token, json_errors, read_bodies, refuse_query_params, stream_query_params};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{watch, Notify, Semaphore};

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
    /// A `radcache bench --out` directory whose charts the dashboard shows
    /// instead of the ones embedded from `web/charts`.
    pub bench: Option<PathBuf>,
    /// How long a client may take to send a request's head, then its
    /// body, and to take some of an answer being written; an idle
    /// kept-alive connection is closed after it too.
    pub client_timeout: Duration,
    /// Connections one peer may have open at once
    /// ([`connection::MAX_CONNECTIONS_PER_PEER`] by default).
    pub connections_per_peer: usize,
}

/// A job's lifecycle state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobState {
    Queued,
    Running,
    Done,
    Failed,
    Cancelled,
    /// A job `radcache render` left unfinished in the store (interrupted):
    /// shown, not rendered here; the same command resumes it.
    Stopped,
}

impl JobState {
    /// Done, failed, cancelled or stopped: nothing changes until a resume.
    pub fn is_final(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled | JobState::Stopped
        )
    }

    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
            JobState::Stopped => "stopped",
        }
    }
}

/// A job's place in the server's table: the server's own jobs (`job-N`)
/// by number, in creation order, then the jobs `radcache render --db
/// --job NAME` left in the store, by name. The server shows those with
/// their frames, statistics and records but does not render them: they
/// belong to the command that started them (whose scene path is relative
/// to where it ran), which resumes them.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum JobKey {
    Served(u64),
    Rendered(String),
}

impl JobKey {
    pub fn of(id: &str) -> JobKey {
        match parse_job_id(id) {
            Some(n) => JobKey::Served(n),
            None => JobKey::Rendered(id.to_string()),
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
    /// Frames of `request.frames` stored.
    pub frames_done: u32,
    /// Every frame stored, as runs: a job rendered over several ranges
    /// (`radcache render --job NAME --frames ...` again) holds frames
    /// outside `request.frames`, its last range.
    pub stored: Vec<std::ops::Range<u32>>,
    pub error: Option<String>,
    /// Set by `cancel` of a running job until the worker has stopped it
    /// (the frame in progress abandoned); shown as `cancelling`.
    pub cancel: bool,
    /// Frames rendered and seconds spent by the current run (the ETA).
    pub run_frames: u32,
    pub run_seconds: f64,
}

impl Job {
    /// Job `id`, whose store job has `stored` frames (ascending).
    pub fn new(id: String, request: JobRequest, state: JobState, stored: &[u32]) -> Job {
        let mut job = Job {
            id,
            request,
            state,
            frames_done: 0,
            stored: Vec::new(),
            error: None,
            cancel: false,
            run_frames: 0,
            run_seconds: 0.0,
        };
        job.set_stored(stored);
        job
    }

    /// Takes the frames its store job holds now (ascending).
    pub fn set_stored(&mut self, stored: &[u32]) {
        let range = &self.request.frames;
        self.frames_done = stored.iter().filter(|f| range.contains(f)).count() as u32;
        self.stored = crate::render::frame_runs(stored.iter().copied());
    }

    /// Frames stored, in all of the job's ranges.
    pub fn frames_stored(&self) -> u32 {
        self.stored.iter().map(|r| r.len() as u32).sum()
    }

    /// `serve` for the server's own jobs, `render` for those `radcache
    /// render` left in the store ([`JobKey`]).
    pub fn origin(&self) -> &'static str {
        match JobKey::of(&self.id) {
            JobKey::Served(_) => "serve",
            JobKey::Rendered(_) => "render",
        }
    }

    /// Seconds left at the current run's mean time per frame.
    pub fn eta_seconds(&self) -> Option<f64> {
        (self.state == JobState::Running && self.run_frames > 0).then(|| {
            let left = self.request.frames_total().saturating_sub(self.frames_done);
            left as f64 * self.run_seconds / self.run_frames as f64
        })
    }
}

/// Most bytes of PNG encodings [`AppState`] keeps (the stream and
/// `frames/N.png` encode a frame once, not once per client).
const PNG_CACHE_BYTES: usize = 64 * 1024 * 1024;

/// Recently encoded frame PNGs by (store job id, frame), oldest evicted
/// first.
#[derive(Default)]
pub struct PngCache {
    map: HashMap<(u64, u32), Bytes>,
    order: VecDeque<(u64, u32)>,
    bytes: usize,
}

impl PngCache {
    pub fn get(&self, key: (u64, u32)) -> Option<Bytes> {
        self.map.get(&key).cloned()
    }

    pub fn insert(&mut self, key: (u64, u32), png: Bytes) {
        if png.len() > PNG_CACHE_BYTES || self.map.contains_key(&key) {
            return;
        }
        self.bytes += png.len();
        self.map.insert(key, png);
        self.order.push_back(key);
        while self.bytes > PNG_CACHE_BYTES {
            let Some(old) = self.order.pop_front() else {
                break;
            };
            if let Some(b) = self.map.remove(&old) {
                self.bytes -= b.len();
            }
        }
    }
}

/// The one shared state of the server.
pub struct AppState {
    pub store: Store,
    pub options: ServeOptions,
    /// The server's jobs and those `radcache render` left in the store.
    pub jobs: Mutex<BTreeMap<JobKey, Job>>,
    /// Held by a job's creation from choosing its id to its insertion in
    /// `jobs`, so that two creations never choose the same id while the
    /// table's own lock is free during the creation's file and store work.
    pub creating: Mutex<()>,
    /// Held by `cancel` and `resume` from writing a job's cancel mark in
    /// the store to setting its state in `jobs`, so that the two agree
    /// however those requests interleave.
    pub controlling: Mutex<()>,
    /// Wakes the worker when a job is queued.
    pub wake: Notify,
    /// Ctrl-C / SIGTERM: stop now, abandoning the frame in progress (it is
    /// rendered again on the next start).
    pub shutdown: AtomicBool,
    pub frames_rendered: AtomicU64,
    pub render_micros: AtomicU64,
    /// Client connections being served (`/metrics`).
    pub open_connections: AtomicU64,
    /// Connections closed unserved, their peer having its share of them
    /// open already (`/metrics`).
    pub refused_connections: AtomicU64,
    /// One watch channel per followed job (stream, events), bumped on every
    /// change of the job: followers wake on changes, never poll.
    pub watchers: Mutex<HashMap<JobKey, watch::Sender<u64>>>,
    pub pngs: Mutex<PngCache>,
    /// The scene of the last `/records` query (its camera projects records).
    pub scene_cache: Mutex<Option<(String, Arc<crate::scene::Scene>)>>,
    /// The PNG encodings in progress, by (store job id, frame): a request
    /// for a frame being encoded awaits that encoding rather than starting
    /// its own (a hundred followers woken by one new frame encode it once).
    pub encoding: Arc<Flights<(u64, u32), PngResult>>,
    /// The `/records` queries in progress: the same query asked again
    /// while it runs awaits its answer (`records::RecordsKey`).
    pub records_queries: Arc<Flights<records::RecordsKey, Result<Bytes, ApiError>>>,
    /// Bounds the frame decodings (PNG encodings, EXR reads) run at once:
    /// each holds a whole frame's pixels, EXR and PNG (a 4096² frame: some
    /// 200 MB).
    pub decode_slots: Arc<Semaphore>,
    /// Bounds the `/records` queries run at once: each reads the record
    /// blocks of the frames after the nearest kept set (all of them up to
    /// the one asked, the first time).
    pub records_slots: Arc<Semaphore>,
    /// Bounds the reads of frame statistics and job entries from the store
    /// run at once: `/stats` (one row a frame) and the event streams'
    /// `frame` rows and store ids.
    pub stats_slots: Arc<Semaphore>,
    /// The records alive at some frames of jobs, kept for the `/records`
    /// queries that follow (`server::alive`); the worker says which frames it
    /// writes.
    pub alive_sets: Mutex<alive::AliveSets>,
    /// Frames decoded from the store and PNG-encoded (`/metrics`).
    pub frame_encodes: AtomicU64,
    /// `/records` queries answered from the store, not from another
    /// request's answer (`/metrics`).
    pub records_reads: AtomicU64,
    /// The job the worker renders and its renderer's
    /// [`crate::render::Renderer::abandon_flag`]: a cancel or a shutdown
    /// abandons the frame in progress rather than waiting for it.
    pub running_frame: Mutex<Option<(JobKey, Arc<AtomicBool>)>>,
}

/// A frame encoded as PNG (`None`: the frame is not stored).
pub type PngResult = Result<Option<Bytes>, ApiError>;

/// Work the server's CPU-bound requests may run at once: one a core.
fn cores() -> usize {
    std::thread::available_parallelism().map_or(4, |n| n.get())
}

impl AppState {
    /// The state of a server over `store`, with no jobs loaded yet.
    pub fn new(store: Store, options: ServeOptions) -> AppState {
        AppState {
            store,
            options,
            jobs: Mutex::new(BTreeMap::new()),
            creating: Mutex::new(()),
            controlling: Mutex::new(()),
            wake: Notify::new(),
            shutdown: AtomicBool::new(false),
            running_frame: Mutex::new(None),
            frames_rendered: AtomicU64::new(0),
            render_micros: AtomicU64::new(0),
            open_connections: AtomicU64::new(0),
            refused_connections: AtomicU64::new(0),
            watchers: Mutex::new(HashMap::new()),
            pngs: Mutex::new(PngCache::default()),
            scene_cache: Mutex::new(None),
            encoding: Arc::default(),
            records_queries: Arc::default(),
            decode_slots: Arc::new(Semaphore::new(cores())),
            records_slots: Arc::new(Semaphore::new(cores().min(4))),
            stats_slots: Arc::new(Semaphore::new(cores().min(4))),
            alive_sets: Mutex::new(alive::AliveSets::default()),
            frame_encodes: AtomicU64::new(0),
            records_reads: AtomicU64::new(0),
        }
    }

    pub fn job(&self, id: &str) -> Result<Job, ApiError> {
        self.jobs
            .lock()
            .expect("job table lock")
            .get(&JobKey::of(id))
            .cloned()
            .ok_or_else(|| ApiError::not_found(format!("no job {id:?}")))
    }

    /// Changes job `id` and wakes its followers.
    pub fn update(&self, id: &str, f: impl FnOnce(&mut Job)) {
        let key = JobKey::of(id);
        if let Some(job) = self.jobs.lock().expect("job table lock").get_mut(&key) {
            f(job);
        }
        self.notify(&key);
    }

    /// Wakes the followers of a deleted job (they find it gone and end)
    /// and drops its watch channel.
    pub fn forget(&self, key: &JobKey) {
        if let Some(tx) = self.watchers.lock().expect("watchers lock").remove(key) {
            tx.send_modify(|g| *g += 1);
        }
    }

    fn notify(&self, key: &JobKey) {
        if let Some(tx) = self.watchers.lock().expect("watchers lock").get(key) {
            tx.send_modify(|g| *g += 1);
        }
    }

    /// How a job's scene is shown: a file under `--scenes` by its path
    /// there (the server's own directories are none of a client's
    /// business), others as they are.
    pub fn scene_name(&self, scene: &SceneSource) -> String {
        scene_name_under(self.scenes_root().as_deref(), scene)
    }

    /// `text` (an error message) with the `--scenes` directory's path left
    /// out of the paths it names.
    pub fn without_scenes_dir(&self, text: &str) -> String {
        without_dir(self.scenes_root().as_deref(), text)
    }

    /// The directory a job's scene must read its files in: the `--scenes`
    /// directory, for a scene file inside it (every job request's, as
    /// [`JobRequest::parse`] resolves them; a job of `radcache render`
    /// whose file lies elsewhere reads where its file points, as there).
    /// Neither the scene's buffers nor the images hashed with it may then
    /// lie outside it, `..`, absolute paths and symbolic links included.
    pub fn scene_root(&self, scene: &SceneSource) -> Option<PathBuf> {
        let root = self.scenes_root()?;
        match scene {
            SceneSource::File(path) if path.starts_with(&root) => Some(root),
            _ => None,
        }
    }

    /// The `--scenes` directory as job requests resolve it (canonical: it
    /// reads the file system).
    pub fn scenes_root(&self) -> Option<PathBuf> {
        self.options.scenes.as_ref()?.canonicalize().ok()
    }

    /// Abandons the frame in progress of job `id` (`None`: of whichever job
    /// runs). Its renderer stops within a path bounce or a pixel tile, and
    /// the frame is neither stored nor written.
    pub fn abandon_frame(&self, id: Option<&str>) {
        let running = self.running_frame.lock().expect("running frame lock");
        if let Some((key, flag)) = running.as_ref() {
            if id.is_none_or(|id| JobKey::of(id) == *key) {
                flag.store(true, Ordering::Relaxed);
            }
        }
    }

    /// Wakes every follower (shutdown: they end their streams).
    pub fn notify_all(&self) {
        for tx in self.watchers.lock().expect("watchers lock").values() {
            tx.send_modify(|g| *g += 1);
        }
    }

    /// A receiver that changes whenever job `id` does (subscribe before
    /// reading the job, so that no change is missed).
    pub fn subscribe(&self, id: &str) -> Result<watch::Receiver<u64>, ApiError> {
        self.job(id)?;
        Ok(self
            .watchers
            .lock()
            .expect("watchers lock")
            .entry(JobKey::of(id))
            .or_insert_with(|| watch::channel(0).0)
            .subscribe())
    }

    /// The store id of job `id` (it has one once its render started).
    pub fn store_id(&self, id: &str) -> Result<Option<u64>, ApiError> {
        self.job(id)?;
        Ok(self
            .store
            .job(id)
            .map_err(ApiError::internal)?
            .map(|j| j.id))
    }

    /// Frame `frame` of store job `sid` as PNG (tone-mapped), encoded once
    /// and cached; `None` if the frame is not stored. Requests for a frame
    /// being encoded await that encoding, and at most
    /// [`AppState::decode_slots`] frames are decoded at once.
    pub async fn frame_png(
        self: &Arc<Self>,
        sid: u64,
        frame: u32,
    ) -> Result<Option<Bytes>, ApiError> {
        let cached = || {
            let png = self.pngs.lock().expect("png cache lock").get((sid, frame));
            png.map(|png| Ok(Some(png)))
        };
        let state = self.clone();
        let encode = |wanted: flight::Wanted<_, _>| async move {
            let png = state.encode_png(sid, frame, wanted).await;
            if let Ok(Some(png)) = &png {
                let mut pngs = state.pngs.lock().expect("png cache lock");
                pngs.insert((sid, frame), png.clone());
            }
            png
        };
        let flights = self.encoding.clone();
        flights
            .get((sid, frame), cached, encode)
            .await
            .map_err(|_| ApiError::internal(format!("encoding frame {frame} as PNG stopped")))?
    }

    /// Decodes frame `frame` of store job `sid` and encodes it as PNG
    /// (`None`: the frame is not stored), in one of the decode slots.
    async fn encode_png(
        self: &Arc<Self>,
        sid: u64,
        frame: u32,
        wanted: flight::Wanted<(u64, u32), PngResult>,
    ) -> PngResult {
        let state = self.clone();
        self.decoding(move || {
            if !wanted.still() {
                return Err(ApiError::abandoned());
            }
            let Some(exr) = state
                .store
                .frame_exr(sid, frame)
                .map_err(ApiError::internal)?
            else {
                return Ok(None);
            };
            state.frame_encodes.fetch_add(1, Ordering::Relaxed);
            let film = crate::film::decode_exr(&exr).map_err(ApiError::internal)?;
            let png = crate::film::encode_png(&film).map_err(ApiError::internal)?;
            Ok(Some(Bytes::from(png)))
        })
        .await
    }

    /// Runs `decode` (blocking: reads, decodes or encodes a frame) once one
    /// of the [`AppState::decode_slots`] is free.
    pub async fn decoding<T: Send + 'static>(
        &self,
        decode: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
    ) -> Result<T, ApiError> {
        blocking_in_slot(&self.decode_slots, decode).await
    }

    /// Runs `read` (blocking: reads frame statistics or job entries from
    /// the store) once one of the [`AppState::stats_slots`] is free.
    pub async fn reading_stats<T: Send + 'static>(
        &self,
        read: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
    ) -> Result<T, ApiError> {
        blocking_in_slot(&self.stats_slots, read).await
    }
}

/// Runs `work` (blocking) on the blocking pool once one of `slots` is
/// free. The work holds its slot until it is done, also when the request
/// that asked is dropped meanwhile (its client gone, or timed out): a
/// client that asks and hangs up at once cannot pile up work past the
/// slots.
pub async fn blocking_in_slot<T: Send + 'static>(
    slots: &Arc<Semaphore>,
    work: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    let slot = slots
        .clone()
        .acquire_owned()
        .await
        .map_err(ApiError::internal)?;
    tokio::task::spawn_blocking(move || {
        let _slot = slot;
        work()
    })
    .await
    .map_err(ApiError::internal)?
}

/// [`AppState::scene_name`] with the `--scenes` directory, `root`, known.
pub fn scene_name_under(root: Option<&std::path::Path>, scene: &SceneSource) -> String {
    match (scene, root) {
        (SceneSource::File(path), Some(root)) => match path.strip_prefix(root) {
            Ok(rel) => rel.display().to_string(),
            Err(_) => scene.to_string(),
        },
        _ => scene.to_string(),
    }
}

/// [`AppState::without_scenes_dir`] with the `--scenes` directory, `root`,
/// known.
pub fn without_dir(root: Option<&std::path::Path>, text: &str) -> String {
    match root {
        Some(root) => text.replace(&format!("{}/", root.display()), ""),
        None => text.to_string(),
    }
}

/// `job-N` → N, spelled as the server spells it (not `job-01` or
/// `job-+1`), so that one job has one id.
pub fn parse_job_id(id: &str) -> Option<u64> {
    parse_canonical_u64(id.strip_prefix("job-")?)
}

/// The API router over `state`.
pub fn router(state: Arc<AppState>) -> Router {
    // The API's routes that take no query parameters refuse them (but the
    // token), as those that take some refuse unknown ones
    // (`records::query_params`): `/stats?from=10` is a 400, not all of
    // the statistics quietly sent.
    let without_query = Router::new()
        .route("/api/charts", get(web::charts))
        .route("/api/openapi.json", get(web::openapi))
        .route("/api/jobs", post(jobs::create).get(jobs::list))
        .route("/api/jobs/{id}", get(jobs::show).delete(jobs::delete))
        .route("/api/jobs/{id}/cancel", post(jobs::cancel))
        .route("/api/jobs/{id}/resume", post(jobs::resume))
        .route("/api/jobs/{id}/frames/{file}", get(frames::frame))
        .route("/api/jobs/{id}/stats", get(frames::stats))
        .route("/api/jobs/{id}/events", get(stream::events))
        .route("/metrics", get(frames::metrics))
        .route_layer(middleware::from_fn(refuse_query_params));
    // `n`: a query the dashboard adds to tell a stream's URL from an
    // earlier one's, which a browser may answer with the image it has.
    let stream = Router::new()
        .route("/api/jobs/{id}/stream", get(stream::frames))
        .route_layer(middleware::from_fn(stream_query_params));
    let routes = Router::new()
        .route("/", get(web::index))
        .route("/web/{file}", get(web::file))
        .route("/web/charts/{file}", get(web::chart))
        .route("/api/jobs/{id}/records", get(records::records))
        .route("/api/jobs/{id}/movies", get(movies::movies))
        .merge(without_query)
        .merge(stream)
        .fallback(|| async { ApiError::not_found("no such route".into()) })
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .layer(middleware::from_fn_with_state(state.clone(), read_bodies))
        .layer(middleware::from_fn_with_state(state.clone(), check_token))
        .with_state(state);
    // Around the whole router, not layered on each route as `layer` does:
    // a route's 405 gets its Allow header outside the route's layers, and
    // `json_errors` names the methods from it.
    Router::new()
        .fallback_service(routes)
        .layer(middleware::map_response(json_errors))
}

impl ServeOptions {
    /// Refuses, before anything listens or is made, options the server
    /// could start with but not serve by: an empty token, none on an
    /// address others reach, a `--scenes` or `--bench` that is no
    /// directory, an `--out` that is a file (every job would fail making
    /// its directory there).
    pub fn check(&self) -> Result<()> {
        if self.token.as_deref() == Some("") {
            bail!("--token (or RADCACHE_TOKEN) is empty; give a secret, or no token on a loopback address");
        }
        if !self.addr.ip().is_loopback() && self.token.is_none() {
            bail!(
                "binding to non-loopback address {} requires --token (or RADCACHE_TOKEN)",
                self.addr
            );
        }
        for (flag, dir) in [("--scenes", &self.scenes), ("--bench", &self.bench)] {
            if let Some(dir) = dir.as_ref().filter(|d| !d.is_dir()) {
                bail!("{flag} {}: no such directory", dir.display());
            }
        }
        if self.out.exists() && !self.out.is_dir() {
            bail!(
                "--out {} is a file; the server writes each job's frames in a directory there",
                self.out.display()
            );
        }
        Ok(())
    }
}

/// Runs the server until Ctrl-C or SIGTERM; the job being rendered stops
/// at once, its frame in progress abandoned (and rendered again on the next
/// start).
pub fn serve(options: ServeOptions) -> Result<()> {
    options.check()?;
    let runtime = tokio::runtime::Runtime::new().context("cannot start the tokio runtime")?;
    // Listening first: a taken address leaves no new store behind.
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind(options.addr))
        .with_context(|| format!("cannot listen on {}", options.addr))?;
    // Said, so that an empty dashboard is not a mystery (a mistyped --db
    // makes a new store too); only now, as a server that does not start
    // makes none.
    if crate::store::no_store_at(&options.db) {
        eprintln!("{}", crate::store::new_store_note(&options.db));
    }
    let store = Store::open(&options.db)?;
    let state = Arc::new(AppState::new(store, options.clone()));
    worker::load_jobs(&state)?;
    let served = runtime.block_on(async move {
        let local = listener.local_addr()?;
        // Tests and scripts read the port from this line; a closed standard
        // output does not stop the server.
        use std::io::Write;
        let mut stdout = std::io::stdout().lock();
        let _ = writeln!(stdout, "listening on http://{local}").and_then(|()| stdout.flush());
        drop(stdout);
        let worker = tokio::spawn(worker::run(state.clone()));
        connection::serve(listener, router(state.clone()), &state).await;
        worker.await.context("worker panicked")?;
        state.store.flush()?;
        Ok(())
    });
    // Blocking work a request began (a scene load, a records query) is not
    // waited for, as dropping the runtime would: the store is flushed, and
    // such work only reads it.
    runtime.shutdown_timeout(std::time::Duration::from_millis(100));
    served
}

pub(super) async fn shutdown_signal() {
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

#[cfg(test)]
pub(crate) mod testing {
    use super::*;

    /// A server state over a new store in `dir`, with no jobs.
    pub fn state(dir: &std::path::Path) -> Arc<AppState> {
        let store = Store::open(&dir.join("db")).unwrap();
        Arc::new(AppState::new(
            store,
            ServeOptions {
                db: dir.join("db"),
                addr: "127.0.0.1:0".parse().unwrap(),
                scenes: None,
                token: None,
                backend: BackendChoice::Cpu,
                out: dir.join("out"),
                bench: None,
                client_timeout: Duration::from_secs(30),
                connections_per_peer: connection::MAX_CONNECTIONS_PER_PEER,
            },
        ))
    }

    /// Frames `frames` of job `id` stored, each with `records_alive` its
    /// number plus 10.
    pub fn store_frames(state: &AppState, id: &str, frames: &[u32]) {
        let mut spec = crate::store::schema::JobValue::for_test("ic", "Ic(..)".into()).spec;
        spec.name = id.into();
        let mut job = state.store.begin_job(&spec, false).unwrap();
        for &frame in frames {
            let stats = crate::method::FrameStats {
                frame,
                records_alive: 10 + u64::from(frame),
                ..Default::default()
            };
            let commit = crate::store::FrameCommit {
                frame,
                width: 8,
                height: 8,
                exr: &[1, 2, 3],
                records: Vec::new(),
                stats: &stats,
                state: None,
                movies: None,
                sources: None,
            };
            state.store.commit_frame(&mut job, commit).unwrap();
        }
    }

    /// Adds job `id` (a small `path` job over frames 0..2) to the table,
    /// `state`, with frames `stored` stored.
    pub fn add_job(state: &AppState, id: &str, job_state: JobState, stored: &[u32]) {
        let request = JobRequest::parse(
            br#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..2","size":"16x16","spp":1}"#,
            None,
        )
        .unwrap();
        state.jobs.lock().unwrap().insert(
            JobKey::of(id),
            Job::new(id.to_string(), request, job_state, stored),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    /// Work whose request was dropped while it ran keeps its slot until
    /// it ends: the next work waits for it.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dropped_requests_leave_their_work_its_slot() {
        let slots = Arc::new(Semaphore::new(1));
        let (started_tx, started) = std::sync::mpsc::channel();
        let (finish, finish_rx) = std::sync::mpsc::channel::<()>();
        let first = {
            let slots = slots.clone();
            tokio::spawn(async move {
                blocking_in_slot(&slots, move || {
                    started_tx.send(()).unwrap();
                    finish_rx.recv().unwrap();
                    Ok(())
                })
                .await
            })
        };
        tokio::task::spawn_blocking(move || started.recv().unwrap())
            .await
            .unwrap();
        first.abort(); // The request goes; its work runs on.
        let _ = first.await;
        assert_eq!(slots.available_permits(), 0, "the running work's slot");
        finish.send(()).unwrap();
        let second = blocking_in_slot(&slots, || Ok(()));
        tokio::time::timeout(Duration::from_secs(10), second)
            .await
            .expect("the slot comes back when the work ends")
            .unwrap();
        assert_eq!(slots.available_permits(), 1);
    }

    /// No more blocking work runs at once than there are slots, however
    /// many requests ask.
    #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
    async fn blocking_work_runs_in_its_slots_only() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        let slots = state.decode_slots.available_permits();
        assert_eq!(slots, cores());
        let running = Arc::new(AtomicUsize::new(0));
        let most = Arc::new(AtomicUsize::new(0));
        let tasks: Vec<_> = (0..slots * 3 + 2)
            .map(|_| {
                let (state, running, most) = (state.clone(), running.clone(), most.clone());
                tokio::spawn(async move {
                    state
                        .decoding(move || {
                            let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                            most.fetch_max(now, Ordering::SeqCst);
                            std::thread::sleep(Duration::from_millis(30));
                            running.fetch_sub(1, Ordering::SeqCst);
                            Ok(())
                        })
                        .await
                })
            })
            .collect();
        for t in tasks {
            t.await.unwrap().unwrap();
        }
        let most = most.load(Ordering::SeqCst);
        assert!(most <= slots, "{most} at once in {slots} slots");
        assert!(most > 1 || slots == 1, "the slots were not used at once");
        assert_eq!(state.decode_slots.available_permits(), slots);
    }
}
