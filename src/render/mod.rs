//! The frame loop: evaluate the animation at `t = frame / fps`, hand the
//! frame's geometry to the ray backend, let the method render, write the
//! files. [`Renderer`] is the library entry point (tests and the server use
//! it); [`render_to_dir`] adds files, a progress bar and a summary for the CLI,
//! and [`render_job_to_dir`] checkpoints each frame to a store job (`job`).

use crate::backend::RayBackend;
use crate::film::{self, Film};
use crate::integrator::RayOffset;
use crate::light::LightSampler;
use crate::method::{FrameContext, FrameRecords, FrameStats, Method};
use crate::scene::{Scene, Snapshot};
use anyhow::{bail, Context, Result};
use glam::Vec3;
use std::collections::BTreeSet;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, SyncSender};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

mod job;
pub mod memory;
mod progress;
mod settings;
mod writer;

use job::resume;
pub use job::{
    job_spec, job_spec_confined, job_spec_of, scene_identity, scene_identity_confined, StoreJob,
};
use progress::FrameProgress;
pub(crate) use progress::{progress_bar, Heartbeat};
pub use settings::{
    frame_runs, make_backend, parse_frame_range, parse_image_size, BackendChoice, FrameSettings,
    MethodSettings, SceneSource, FPS_RANGE, FRAME_LIMIT,
};
use writer::{FrameWriter, RenderedFrame};

/// Renders frames of one scene with one method and one backend.
pub struct Renderer {
    pub scene: Scene,
    pub settings: FrameSettings,
    method: Box<dyn Method>,
    backend: Box<dyn RayBackend>,
    last_frame: Option<u32>,
    last_frame_rays: u64,
    counts: MethodCalls,
    /// The frame after the last one to render (two-pass methods look
    /// ahead no further); `None`: the scene's last frame.
    frame_end: Option<u32>,
    /// [`Self::abandon_flag`].
    abandon: Arc<AtomicBool>,
    /// [`FrameContext::render_stopped`]: set by the writer of
    /// [`render_job_to_dir_with`] when it stops, cleared as that returns.
    render_stopped: Arc<AtomicBool>,
    /// The last frame's snapshot, whose static triangles the next frame
    /// takes ([`Scene::snapshot_from`]): `scene` must not change between
    /// frames.
    last_snapshot: Option<Snapshot>,
    /// A snapshot a method made of a later frame's time
    /// ([`FrameContext::next_snapshot`]), taken as that frame's if it comes
    /// next.
    offered_snapshot: OnceLock<Snapshot>,
    /// The box around the scene's vertices at time 0, which with each
    /// frame's camera sizes its [`RayOffset`] (found once: a large mesh
    /// takes milliseconds to bound).
    scene_bounds: Option<(Vec3, Vec3)>,
}

impl Renderer {
    pub fn new(
        scene: Scene,
        method: Box<dyn Method>,
        backend: Box<dyn RayBackend>,
        settings: FrameSettings,
    ) -> Self {
        Renderer {
            settings,
            method,
            backend,
            last_frame: None,
            last_frame_rays: 0,
            counts: MethodCalls::default(),
            frame_end: None,
            abandon: Arc::default(),
            render_stopped: Arc::default(),
            last_snapshot: None,
            offered_snapshot: OnceLock::new(),
            scene_bounds: scene.bounds_at(0.0),
            scene,
        }
    }

    /// A flag that, once set (from any thread), abandons the frame in
    /// progress: its loops skip what is left of their work
    /// ([`FrameContext::abandoned`]) and [`render_job_to_dir_with`] throws
    /// the frame away and stops. The server sets it to cancel a running
    /// job or to shut down without waiting for a frame that may take
    /// hours. The method's state is then garbage: like after a backend
    /// failure, only a fresh renderer (a resume from the store) goes on.
    pub fn abandon_flag(&self) -> Arc<AtomicBool> {
        self.abandon.clone()
    }

    /// Makes `flag` this renderer's [`Self::abandon_flag`], so that one
    /// flag abandons the frame in progress of whichever renderer holds it
    /// (a bench stopped by Ctrl-C, which makes a renderer per run).
    pub fn set_abandon_flag(&mut self, flag: Arc<AtomicBool>) {
        self.abandon = flag;
    }

    /// Whether [`Self::abandon_flag`] is set.
    pub fn abandoned(&self) -> bool {
        self.abandon.load(Ordering::Relaxed)
    }

    pub fn backend(&self) -> &dyn RayBackend {
        self.backend.as_ref()
    }

    /// What the method's statistics count ([`Method::cache_unit`]).
    pub fn cache_unit(&self) -> &'static str {
        self.method.cache_unit()
    }

    /// Which records its lifespans count ([`Method::lifespans_counted`]).
    pub fn lifespans_counted(&self) -> &'static str {
        self.method.lifespans_counted()
    }

    pub fn method_name(&self) -> &'static str {
        self.method.name()
    }

    /// How often this renderer ran its method's passes (tests check that a
    /// resume renders no finished frame again).
    pub fn method_calls(&self) -> MethodCalls {
        self.counts
    }

    /// Whether the method carries state from frame to frame
    /// ([`Method::carries_state`]).
    pub fn carries_state(&self) -> bool {
        self.method.carries_state()
    }

    /// Whether the method's frames depend on the end of the rendered range
    /// ([`Method::looks_ahead`]).
    pub fn looks_ahead(&self) -> bool {
        self.method.looks_ahead()
    }

    /// Whether the method's state refers to its records' stored samples
    /// ([`Method::state_refers_to_record_samples`]).
    pub fn state_refers_to_record_samples(&self) -> bool {
        self.method.state_refers_to_record_samples()
    }

    /// Continues the method from a stored state ([`Method::restore_state`]).
    pub fn restore_state(
        &mut self,
        state: crate::method::MethodState,
    ) -> Result<(), crate::method::StateError> {
        let frame = state.frame;
        self.method.restore_state(state)?;
        self.last_frame = Some(frame);
        Ok(())
    }

    /// Statistics of the last rendered frame, rays included.
    pub fn last_frame_stats(&self) -> FrameStats {
        let mut stats = self.method.last_frame_stats();
        stats.frame = self.last_frame.unwrap_or(0);
        stats.rays = self.last_frame_rays;
        stats
    }

    /// Asks the method to keep each frame's records with their samples
    /// (for the store); see [`Method::keep_frame_records`].
    pub fn keep_frame_records(&mut self, keep: bool) {
        self.method.keep_frame_records(keep);
    }

    /// The records the method created or changed in the last frame, if kept.
    pub fn take_frame_records(&mut self) -> Option<FrameRecords> {
        self.method.take_frame_records()
    }

    /// Tells the renderer that no frame at or after `end` will be
    /// rendered: a two-pass method (`trc` with interpolated gradients)
    /// looks no further ahead. Without it, it may look ahead to the
    /// scene's last frame.
    pub fn set_frame_end(&mut self, end: Option<u32>) {
        self.frame_end = end;
    }

    /// Renders frame `frame` (time `frame / fps`). A two-pass method first
    /// gets the frames it asks for through its first pass (the rays they
    /// trace count in this frame). Panics if the backend fails (tests);
    /// `render`, `bench` and `serve` use [`Self::try_render_frame`].
    pub fn render_frame(&mut self, frame: u32) -> Film {
        self.try_render_frame(frame)
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Self::render_frame`], or why it cannot be rendered: the error
    /// that stopped the backend ([`RayBackend::failure`]; the frame is then
    /// discarded, and so is every later one: the method's carried state
    /// may hold the failed frame's garbage, so only a fresh renderer (a
    /// resume from the store) goes on), or a camera carried out of reach
    /// at this frame or at one a two-pass method prepares for it.
    pub fn try_render_frame(&mut self, frame: u32) -> Result<Film, FrameFailed> {
        self.check_backend(frame)?;
        self.check_camera(frame, frame)?;
        let rays_before = self.backend.ray_counts().total();
        let film = self.render_frame_uncounted(frame)?;
        self.check_backend(frame)?;
        self.last_frame_rays = self.backend.ray_counts().total() - rays_before;
        self.last_frame = Some(frame);
        Ok(film)
    }

    fn check_backend(&self, frame: u32) -> Result<(), FrameFailed> {
        match self.backend.failure() {
            Some(message) => Err(FrameFailed::Backend {
                frame,
                backend: self.backend.name(),
                message,
            }),
            None => Ok(()),
        }
    }

    /// The camera at frame `at` (rendered, or prepared for `frame`) is
    /// checked here because the loader checks it only at key times and at
    /// the first frames at 24 fps: another rate reaches other times.
    fn check_camera(&self, frame: u32, at: u32) -> Result<(), FrameFailed> {
        let t = at as f32 / self.settings.fps;
        let when = if at == frame {
            format!("t = {t:.4} s (frame {at})")
        } else {
            format!("t = {t:.4} s (frame {at}, which the method prepares ahead)")
        };
        (self.scene.check_camera(t, &when))
            .map_err(|message| FrameFailed::Camera { frame, message })
    }

    fn render_frame_uncounted(&mut self, frame: u32) -> Result<Film, FrameFailed> {
        let mut method = std::mem::replace(&mut self.method, Box::new(NoMethod));
        let end = self
            .frame_end
            .unwrap_or(self.scene.frame_count)
            .max(frame + 1);
        let mut prepared = Ok(());
        while let Some(f) = method.next_frame_to_prepare(frame, end) {
            prepared = self.check_camera(frame, f);
            if prepared.is_err() {
                break;
            }
            self.with_frame_context(f, |ctx| method.prepare_frame(ctx));
            self.counts.prepared += 1;
        }
        let film = prepared.map(|()| {
            let film = self.with_frame_context(frame, |ctx| method.render_frame(ctx));
            self.counts.rendered += 1;
            film
        });
        self.method = method;
        film
    }

    /// Evaluates frame `frame` (geometry, lights, backend) and runs `f` on
    /// its context: what a method sees. Tests use it to probe a method's
    /// stages directly.
    pub fn with_frame_context<R>(&mut self, frame: u32, f: impl FnOnce(&FrameContext) -> R) -> R {
        let t = frame as f32 / self.settings.fps;
        // The scene's snapshot at `t` however it was made (bit for bit:
        // `Scene::snapshot_from`).
        let offered = (self.offered_snapshot.take()).filter(|s| s.time.to_bits() == t.to_bits());
        let snapshot = match (offered, self.last_snapshot.take()) {
            (Some(offered), _) => offered,
            (None, Some(earlier)) => self.scene.snapshot_from(t, &earlier),
            (None, None) => self.scene.snapshot(t),
        };
        self.backend.set_geometry(&snapshot);
        let lights = LightSampler::new(&snapshot, &self.scene.materials);
        let mut ctx = FrameContext {
            scene: &self.scene,
            snapshot: &snapshot,
            lights: &lights,
            backend: self.backend.as_ref(),
            frame,
            fps: self.settings.fps,
            width: self.settings.width,
            height: self.settings.height,
            seed: self.settings.seed,
            same_pattern: self.settings.same_pattern,
            edge_coverage_factor: self.settings.edge_coverage_factor,
            emitters_in_view: Vec::new(),
            abandon: &self.abandon,
            render_stopped: &self.render_stopped,
            ray_offset: RayOffset::around(self.scene_bounds, snapshot.camera.position),
            next_snapshot: &self.offered_snapshot,
        };
        ctx.emitters_in_view =
            crate::method::pixels::emitters_in_view(&snapshot, &lights, ctx.aspect());
        let result = f(&ctx);
        drop(ctx);
        self.last_snapshot = Some(snapshot);
        result
    }
}

/// Why a frame was not rendered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameFailed {
    /// The ray backend stopped working; it stays failed for every later
    /// frame of this renderer.
    Backend {
        frame: u32,
        /// [`RayBackend::name`].
        backend: String,
        message: String,
    },
    /// The scene cannot be rendered at the frame's time, or at a frame a
    /// two-pass method prepares for it: its camera is carried past what can
    /// be traced ([`Scene::check_camera`]).
    Camera { frame: u32, message: String },
}

impl FrameFailed {
    /// The frame that was not rendered.
    pub fn frame(&self) -> u32 {
        match self {
            Self::Backend { frame, .. } | Self::Camera { frame, .. } => *frame,
        }
    }

    /// What went wrong, without the frame.
    pub fn message(&self) -> &str {
        match self {
            Self::Backend { message, .. } | Self::Camera { message, .. } => message,
        }
    }
}

impl std::fmt::Display for FrameFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Backend {
                frame,
                backend,
                message,
            } => write!(f, "frame {frame}: the {backend} backend failed: {message}"),
            Self::Camera { frame, message } => write!(f, "frame {frame}: {message}"),
        }
    }
}

impl std::error::Error for FrameFailed {}

/// Calls of a method's passes by one [`Renderer`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MethodCalls {
    /// [`Method::render_frame`] calls.
    pub rendered: u32,
    /// [`Method::prepare_frame`] calls (first passes of two-pass methods).
    pub prepared: u32,
}

/// Placeholder while the real method is borrowed out of the renderer, and
/// the method of a renderer only used for its frame contexts
/// ([`Renderer::with_frame_context`]).
pub(crate) struct NoMethod;

impl Method for NoMethod {
    fn name(&self) -> &'static str {
        "none"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        Film::new(ctx.width, ctx.height)
    }
}

/// What a finished render reports.
#[derive(Clone, Debug)]
pub struct RenderSummary {
    /// Frames rendered by this run (resumed frames not counted).
    pub frames: u32,
    /// Frames a store job had already finished, skipped by this run.
    pub resumed: u32,
    /// Statistics of every rendered frame, in order.
    pub frame_stats: Vec<FrameStats>,
    pub elapsed: Duration,
    pub rays: u64,
    /// Backend calls the rays took (on a GPU, dispatches).
    pub ray_calls: u64,
    pub out_dir: PathBuf,
    /// What the frames' record statistics count ([`Method::cache_unit`]).
    pub cache_unit: &'static str,
    /// Which records the lifespans count ([`Method::lifespans_counted`]).
    pub lifespans_counted: &'static str,
}

impl RenderSummary {
    /// Totals over frames, for caching methods: records created, lookups,
    /// mean records per lookup, fallbacks and seconds per phase.
    pub fn cache_report(&self) -> Option<String> {
        let created: u64 = self.frame_stats.iter().map(|s| s.records_created).sum();
        let lookups: u64 = self.frame_stats.iter().map(|s| s.lookups).sum();
        if lookups == 0 {
            return None;
        }
        let used: u64 = self.frame_stats.iter().map(|s| s.lookup_records).sum();
        let fallbacks: u64 = self.frame_stats.iter().map(|s| s.fallback_lookups).sum();
        let mut phases: Vec<(String, f64)> = Vec::new();
        for (name, secs) in self.frame_stats.iter().flat_map(|s| s.phase_seconds.iter()) {
            match phases.iter_mut().find(|p| &p.0 == name) {
                Some(p) => p.1 += secs,
                None => phases.push((name.clone(), *secs)),
            }
        }
        let phases: Vec<String> = phases
            .iter()
            .map(|(n, s)| format!("{n} {s:.2} s"))
            .collect();
        // Lookups that interpolate records say how many each used; those
        // of texture movies read texels, and fall back to nothing.
        let interpolated = match used + fallbacks {
            0 => String::new(),
            _ => format!(
                ", {:.1} records/lookup, {fallbacks} path-traced fallbacks",
                used as f64 / lookups as f64
            ),
        };
        Some(format!(
            "{} created {created} ({:.0}/frame), lookups {lookups}{interpolated}; {}",
            self.cache_unit,
            created as f64 / self.frames.max(1) as f64,
            phases.join(", ")
        ))
    }

    /// The method's time per frame (the sum of its phases, file writing
    /// excluded): median and slowest, so that uneven frames show — `trc`
    /// regathers every record of a frame's cohort together, `δt_max`
    /// frames after it was made.
    pub fn frame_time_report(&self) -> Option<String> {
        let mut times: Vec<(f64, u32)> = self
            .frame_stats
            .iter()
            .map(|s| (s.phase_seconds.iter().map(|(_, t)| t).sum(), s.frame))
            .collect();
        if times.len() < 2 {
            return None;
        }
        let (slowest, frame) =
            times
                .iter()
                .copied()
                .fold((f64::NEG_INFINITY, 0), |a, b| if b.0 > a.0 { b } else { a });
        times.sort_by(|a, b| a.0.total_cmp(&b.0));
        let median = times[times.len() / 2].0;
        (slowest > 0.0).then(|| {
            format!("time per frame: median {median:.3} s, slowest {slowest:.3} s (frame {frame})")
        })
    }

    /// What the method's cache held and carried: its largest size in
    /// memory at the end of a frame (and which frame), and the samples
    /// traced again for carried records. `None` for methods without a
    /// cache (`path`).
    pub fn footprint_report(&self) -> Option<String> {
        let (peak, frame) = self
            .frame_stats
            .iter()
            .map(|s| (s.cache_bytes, s.frame))
            .fold((0, 0), |a, b| if b.0 > a.0 { b } else { a });
        if peak == 0 {
            return None;
        }
        let reshot: u64 = self.frame_stats.iter().map(|s| s.samples_reshot).sum();
        let mut out = format!(
            "cache in memory: peak {:.2} MB (frame {frame})",
            peak as f64 / 1e6
        );
        if reshot > 0 {
            out.push_str(&format!(", {reshot} samples re-shot for carried records"));
        }
        Some(out)
    }

    /// For temporal methods (records with lifespans): records reused,
    /// replaced and dropped, the mean lifespan of the records counted
    /// ([`Self::lifespans_counted`]), and their lifespan histogram, one
    /// line per lifespan in frames.
    pub fn lifespan_report(&self) -> Option<String> {
        let mut histogram: Vec<u64> = Vec::new();
        for s in &self.frame_stats {
            if histogram.len() < s.lifespan_histogram.len() {
                histogram.resize(s.lifespan_histogram.len(), 0);
            }
            for (h, n) in histogram.iter_mut().zip(&s.lifespan_histogram) {
                *h += n;
            }
        }
        let counted: u64 = histogram.iter().sum();
        if counted == 0 {
            return None;
        }
        let sum = |f: fn(&FrameStats) -> u64| self.frame_stats.iter().map(f).sum::<u64>();
        let widest = histogram.iter().copied().max().unwrap_or(1).max(1);
        let unit = self.cache_unit;
        let mut out = format!(
            "{unit} reused {} times, replaced {}, dropped {}; mean lifespan {:.2} frames over {counted} {unit} {}\nlifespan histogram (frames: {unit}):",
            sum(|s| s.records_reused),
            sum(|s| s.records_replaced),
            sum(|s| s.records_dropped),
            crate::method::mean_lifespan(&histogram),
            self.lifespans_counted,
        );
        for (life, &n) in histogram.iter().enumerate().filter(|(_, n)| **n > 0) {
            let bar = "#".repeat(((n * 40).div_ceil(widest)) as usize);
            out.push_str(&format!("\n  {life:>4}: {n:>8} {bar}"));
        }
        Some(out)
    }

    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }
}

/// Renders `frames` into `out_dir` as `frame_NNNN.exr` and `.png`, with
/// progress on stderr unless `quiet` (a bar on a terminal, else a line per
/// frame).
pub fn render_to_dir(
    renderer: &mut Renderer,
    frames: Range<u32>,
    out_dir: &Path,
    quiet: bool,
) -> Result<RenderSummary> {
    render_job_to_dir(renderer, frames, out_dir, quiet, None)
}

/// [`render_to_dir`] with an optional store job: frames the job already
/// finished are skipped (shown as done; their files are restored from the
/// store if missing in `out_dir`), and after each new frame one atomic
/// store batch writes the frame, its records with samples, its stats, the
/// changes of a stateful method's carried state and the job's progress,
/// then flushes. Only then is the frame acknowledged and written to
/// `out_dir`.
///
/// A method that carries state ([`Method::carries_state`], `trc`) makes
/// each frame depend on the frames before it in the range: a resume
/// continues after the finished prefix of the range from the stored state
/// of its last frame, when that state belongs to the same chain (started
/// at the same first frame, and for methods that look ahead with the same
/// range end). Otherwise the range starts over from its first frame (its
/// frames are rendered and written again). A range whose frames are all
/// done renders nothing, for such a method only if they were rendered by
/// that range's own chain.
pub fn render_job_to_dir(
    renderer: &mut Renderer,
    frames: Range<u32>,
    out_dir: &Path,
    quiet: bool,
    job: Option<&mut StoreJob>,
) -> Result<RenderSummary> {
    render_job_to_dir_with(renderer, frames, out_dir, quiet, job, &mut |_| true)
}

/// [`render_job_to_dir`] calling `after_frame(frame)` once each new frame is
/// acknowledged and written; returning `false` stops the render there (the
/// server's cancel and shutdown). So does [`Renderer::abandon_flag`], in the
/// middle of a frame, which is then neither stored nor written. A stopped
/// render is resumed like a crashed one.
///
/// Frames are stored and written on a thread of their own while the next
/// one renders (module `writer`); `after_frame` runs there. A stop
/// abandons the frame then rendering, which leaves the method's state
/// garbage, as any abandoned frame does: only a fresh renderer (a resume)
/// goes on.
pub fn render_job_to_dir_with(
    renderer: &mut Renderer,
    frames: Range<u32>,
    out_dir: &Path,
    quiet: bool,
    job: Option<&mut StoreJob>,
    after_frame: &mut (dyn FnMut(u32) -> bool + Send),
) -> Result<RenderSummary> {
    prepare_out_dir(out_dir)?;
    let done = match job.as_deref() {
        Some(j) => resume(renderer, j, &frames, out_dir)?,
        None => BTreeSet::new(),
    };
    check_frame_files_writable(out_dir, &frames, &done)?;
    renderer.keep_frame_records(job.is_some());
    let progress = Mutex::new(FrameProgress::new(
        frames.len() as u64,
        done.len() as u64,
        quiet,
    ));
    let start = Instant::now();
    let counts_before = renderer.backend().ray_counts();
    renderer.set_frame_end(Some(frames.end));
    let stopped = renderer.render_stopped.clone();
    let frame_writer = FrameWriter {
        out_dir,
        job,
        chain: (frames.start, renderer.looks_ahead().then_some(frames.end)),
        stateful_method: renderer.carries_state().then(|| renderer.method_name()),
        progress: &progress,
        after_frame,
        stopped: &stopped,
    };
    let to_render = frames.clone().filter(|f| !done.contains(f));
    let written = render_and_write(renderer, to_render, frame_writer);
    // Only the frame in progress when the writer stopped is abandoned.
    renderer.render_stopped.store(false, Ordering::Relaxed);
    let progress = progress.into_inner().unwrap_or_else(|p| p.into_inner());
    let frame_stats = written.inspect_err(|_| progress.abandon())?;
    progress.finish_and_clear();
    let counts = renderer.backend().ray_counts();
    Ok(RenderSummary {
        frames: frame_stats.len() as u32,
        resumed: done.len() as u32,
        frame_stats,
        elapsed: start.elapsed(),
        rays: counts.total() - counts_before.total(),
        ray_calls: counts.calls - counts_before.calls,
        out_dir: out_dir.to_path_buf(),
        cache_unit: renderer.cache_unit(),
        lifespans_counted: renderer.lifespans_counted(),
    })
}

/// Renders `frames` on this thread while `frame_writer` stores and writes
/// them on another; the statistics of the frames written, or the first
/// error: the writer's, as it names the first frame not kept.
fn render_and_write(
    renderer: &mut Renderer,
    frames: impl Iterator<Item = u32>,
    frame_writer: FrameWriter,
) -> Result<Vec<FrameStats>> {
    let (progress, in_job) = (frame_writer.progress, frame_writer.job.is_some());
    let (rendered, written) = std::thread::scope(|scope| {
        // No queue: a rendered frame waits until the one before it is
        // written, so at most two are held.
        let (hand_over, rendered_frames) = mpsc::sync_channel(0);
        let writing = std::thread::Builder::new()
            .name("radcache-writer".into())
            .spawn_scoped(scope, move || frame_writer.write_all(rendered_frames))
            .context("cannot start the thread that writes the frames")?;
        let rendered = render_frames(renderer, frames, progress, hand_over, in_job);
        let written = writing
            .join()
            .unwrap_or_else(|p| std::panic::resume_unwind(p));
        anyhow::Ok((rendered, written))
    })?;
    written.and_then(|stats| rendered.map(|()| stats))
}

/// Renders `frames` in order and hands each to the writer, until one fails
/// (its error, for a job saying that the frames before it are kept), the
/// writer stops, or the renderer is abandoned (the frame in progress is
/// then thrown away).
fn render_frames(
    renderer: &mut Renderer,
    frames: impl Iterator<Item = u32>,
    progress: &Mutex<FrameProgress>,
    hand_over: SyncSender<RenderedFrame>,
    in_job: bool,
) -> Result<()> {
    for frame in frames {
        let started = Instant::now();
        writer::lock(progress).start_frame(frame);
        let film = renderer.try_render_frame(frame);
        writer::lock(progress).end_render();
        let film = film.map_err(|e| frame_failed_error(&e, in_job))?;
        if renderer.abandoned() || renderer.render_stopped.load(Ordering::Relaxed) {
            break; // Half rendered: neither stored nor written.
        }
        warn_if_not_finite(&writer::lock(progress), frame, &film);
        let rendered = RenderedFrame {
            frame,
            film,
            stats: renderer.last_frame_stats(),
            kept: renderer.take_frame_records(),
            started,
        };
        if hand_over.send(rendered).is_err() {
            break; // The writer stopped; it says why.
        }
    }
    Ok(())
}

/// Makes `out_dir` (a file there is an error) and clears the temporaries
/// an interrupted write left in it.
fn prepare_out_dir(out_dir: &Path) -> Result<()> {
    if out_dir.exists() && !out_dir.is_dir() {
        bail!("output directory {} is a file", out_dir.display());
    }
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create output directory {}", out_dir.display()))?;
    film::remove_stale_temporaries(out_dir);
    Ok(())
}

/// A directory in the place of a frame file still to be written is an
/// error before any frame renders, rather than at that frame's write.
fn check_frame_files_writable(
    out_dir: &Path,
    frames: &Range<u32>,
    done: &BTreeSet<u32>,
) -> Result<()> {
    match film::frame_paths_taken_by_directories(out_dir)
        .into_iter()
        .find(|(f, _)| frames.contains(f) && !done.contains(f))
    {
        Some((frame, path)) => bail!(
            "cannot write frame {frame}: {} is a directory",
            path.display()
        ),
        None => Ok(()),
    }
}

/// A frame that failed to render, saying for a store job (`in_job`) that
/// the frames before it are kept and how to go on.
fn frame_failed_error(e: &FrameFailed, in_job: bool) -> anyhow::Error {
    match (in_job, e) {
        (true, FrameFailed::Camera { .. }) => {
            anyhow::anyhow!("{e}\nevery frame before it is saved in the store")
        }
        (true, FrameFailed::Backend { .. }) => anyhow::anyhow!(
            "{e}\nevery frame before it is saved in the store: running the job \
             again resumes there (with --backend cpu if the GPU keeps failing)"
        ),
        (false, _) => anyhow::anyhow!("{e}"),
    }
}

/// Never expected; but a NaN spreads through every later use of the frame
/// (compare's sums, a tone-mapped preview), so it is said.
fn warn_if_not_finite(progress: &FrameProgress, frame: u32, film: &Film) {
    let not_finite = film.pixels.iter().filter(|p| !p.is_finite()).count();
    if not_finite > 0 {
        progress.warn(&format!(
            "warning: frame {frame}: {not_finite} of {} pixels are NaN or infinite \
             (a defect of the renderer: please report it with the scene and the command)",
            film.pixels.len()
        ));
    }
}

/// A CPU renderer of built-in `scene` at `size × size`, for unit tests
/// that need a frame context (its own method is never run).
#[cfg(test)]
pub(crate) fn test_renderer(scene: &str, size: u32) -> Renderer {
    Renderer::new(
        crate::scene::Scene::builtin(scene).expect("a built-in scene"),
        Box::new(crate::method::path::PathTracer::new(Default::default())),
        Box::new(crate::backend::cpu::CpuBackend::new()),
        FrameSettings {
            width: size,
            height: size,
            ..Default::default()
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A render that `after_frame` stops writes the frames up to the stop,
    /// and abandons only the frame then rendering: the renderer's next
    /// frame is whole (path tracing keeps no state, so it equals a fresh
    /// renderer's).
    #[test]
    fn a_stopped_render_abandons_only_the_frame_then_rendering() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = test_renderer("cube-in-box", 8);
        let s = render_job_to_dir_with(&mut r, 0..4, dir.path(), true, None, &mut |f| f < 1);
        assert_eq!(s.unwrap().frames, 2);
        assert!(film::frame_path(dir.path(), 1, "exr").exists());
        assert!(!film::frame_path(dir.path(), 2, "exr").exists());
        let fresh = test_renderer("cube-in-box", 8).render_frame(3);
        assert_eq!(r.render_frame(3).pixels, fresh.pixels);
    }

    fn summary(phase_times: &[f64]) -> RenderSummary {
        RenderSummary {
            frames: phase_times.len() as u32,
            resumed: 0,
            frame_stats: phase_times
                .iter()
                .enumerate()
                .map(|(f, &t)| FrameStats {
                    frame: 10 + f as u32,
                    phase_seconds: vec![("fill".into(), t / 4.0), ("render".into(), 0.75 * t)],
                    ..FrameStats::default()
                })
                .collect(),
            elapsed: Duration::from_secs(1),
            rays: 0,
            ray_calls: 0,
            cache_unit: "records",
            lifespans_counted: "computed",
            out_dir: PathBuf::from("out"),
        }
    }

    /// A snapshot a method offers for the next frame's time is taken as
    /// that frame's (marked here by a camera moved away, which no offer
    /// would do), and not for a frame of another time; `trc` offers the one
    /// it made of t0+1 under a moving light, and its frames are those of a
    /// renderer that takes no offer.
    #[test]
    fn the_next_frames_snapshot_is_taken_only_at_its_time() {
        let mut renderer = test_renderer("moving-light", 4);
        let marked = |ctx: &FrameContext, frame: u32| {
            let mut s = ctx.scene.snapshot_from(ctx.time_of(frame), ctx.snapshot);
            s.camera.position.x += 100.0;
            ctx.next_snapshot.set(s).unwrap();
        };
        let x = |ctx: &FrameContext| ctx.snapshot.camera.position.x;
        let unmarked = renderer.with_frame_context(1, x);
        renderer.with_frame_context(0, |ctx| marked(ctx, 1));
        assert_eq!(renderer.with_frame_context(1, x), unmarked + 100.0);
        renderer.with_frame_context(0, |ctx| marked(ctx, 2));
        assert_eq!(renderer.with_frame_context(1, x), unmarked);
        assert!(renderer.offered_snapshot.get().is_none(), "let go");

        let trc_renderer = || {
            let mut r = test_renderer("moving-light", 4);
            r.method = MethodSettings::Trc(Default::default()).instantiate();
            r
        };
        let (mut taking, mut taking_none) = (trc_renderer(), trc_renderer());
        for frame in 0..3 {
            let film = taking.render_frame(frame);
            let offered = taking.offered_snapshot.get().map(|s| s.time);
            assert_eq!(offered, Some((frame + 1) as f32 / taking.settings.fps));
            taking_none.offered_snapshot.take();
            assert_eq!(film, taking_none.render_frame(frame), "frame {frame}");
        }
    }

    #[test]
    fn frame_time_report_names_the_median_and_the_slowest_frame() {
        let report = summary(&[0.02, 0.03, 0.2, 0.01, 0.04]).frame_time_report();
        assert_eq!(
            report.as_deref(),
            Some("time per frame: median 0.030 s, slowest 0.200 s (frame 12)")
        );
        // One frame, or methods that time no phases (`path`): nothing to say.
        assert_eq!(summary(&[0.5]).frame_time_report(), None);
        assert_eq!(summary(&[0.0, 0.0]).frame_time_report(), None);
    }

    /// Records that interpolate say how many a lookup used; texture
    /// movies, whose lookups read texels, are named as such instead.
    #[test]
    fn cache_report_names_what_the_method_caches() {
        let mut s = summary(&[0.1, 0.1]);
        for st in &mut s.frame_stats {
            (st.records_created, st.lookups, st.lookup_records) = (3, 10, 20);
        }
        let records = s.cache_report().unwrap();
        assert!(
            records.starts_with("records created 6 (3/frame), lookups 20, 2.0 records/lookup"),
            "{records}"
        );
        for st in &mut s.frame_stats {
            st.lookup_records = 0;
        }
        s.cache_unit = "texture movies";
        let movies = s.cache_report().unwrap();
        assert!(
            movies.starts_with("texture movies created 6 (3/frame), lookups 20; fill"),
            "{movies}"
        );
    }

    #[test]
    fn lifespan_report_says_which_records_its_lifespans_count() {
        let mut s = summary(&[0.1, 0.1]);
        assert_eq!(s.lifespan_report(), None, "no lifespans, nothing to say");
        s.frame_stats[0].lifespan_histogram = vec![0, 1, 0, 1];
        s.frame_stats[1].lifespan_histogram = vec![0, 0, 1];
        let records = s.lifespan_report().unwrap();
        assert!(
            records.contains("mean lifespan 2.00 frames over 3 records computed"),
            "{records}"
        );
        (s.cache_unit, s.lifespans_counted) = ("texture movies", "that ended");
        let movies = s.lifespan_report().unwrap();
        assert!(
            movies.contains("over 3 texture movies that ended\n"),
            "{movies}"
        );
    }

    #[test]
    fn footprint_report_names_the_peak_frame_and_sums_the_reshot_samples() {
        let mut s = summary(&[0.1, 0.1, 0.1]);
        assert_eq!(s.footprint_report(), None, "no cache, nothing to say");
        for (st, (bytes, reshot)) in
            s.frame_stats
                .iter_mut()
                .zip([(1000, 0), (2_500_000, 7), (2_000_000, 5)])
        {
            st.cache_bytes = bytes;
            st.samples_reshot = reshot;
        }
        assert_eq!(
            s.footprint_report().as_deref(),
            Some(
                "cache in memory: peak 2.50 MB (frame 11), 12 samples re-shot for carried records"
            )
        );
    }
}
