//! The frame loop: evaluate the animation at `t = frame / fps`, hand the
//! frame's geometry to the ray backend, let the method render, write the
//! files. [`Renderer`] is the library entry point (tests and the server use
//! it); [`render_to_dir`] adds files, a progress bar and a summary for the CLI.

use crate::backend::cpu::CpuBackend;
use crate::backend::gpu::{AdapterPolicy, GpuBackend, GpuError};
use crate::backend::RayBackend;
use crate::film::{self, Film};
use crate::light::LightSampler;
use crate::method::ic::{IcSettings, IrradianceCaching};
use crate::method::path::{PathSettings, PathTracer};
use crate::method::trc::{TemporalRadianceCaching, TrcSettings};
use crate::method::{FrameContext, FrameStats, Method};
use crate::scene::{Scene, SceneError};
use anyhow::{bail, Context, Result};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Where a scene comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    Builtin(String),
    File(PathBuf),
}

impl SceneSource {
    pub fn load(&self) -> Result<Scene, SceneError> {
        match self {
            SceneSource::Builtin(name) => Scene::builtin(name),
            SceneSource::File(path) => Scene::load(path),
        }
    }
}

impl std::fmt::Display for SceneSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SceneSource::Builtin(name) => write!(f, "builtin:{name}"),
            SceneSource::File(path) => write!(f, "{}", path.display()),
        }
    }
}

/// Which rendering method, with its settings.
#[derive(Clone, Debug, PartialEq)]
pub enum MethodSettings {
    Path(PathSettings),
    Ic(IcSettings),
    Trc(TrcSettings),
}

impl MethodSettings {
    /// The method's command-line name.
    pub fn name(&self) -> &'static str {
        match self {
            MethodSettings::Path(_) => "path",
            MethodSettings::Ic(_) => "ic",
            MethodSettings::Trc(_) => "trc",
        }
    }

    /// Pixel samples per frame.
    pub fn spp(&self) -> u32 {
        match self {
            MethodSettings::Path(s) => s.spp,
            MethodSettings::Ic(s) => s.spp,
            MethodSettings::Trc(s) => s.ic.spp,
        }
    }

    pub fn instantiate(&self) -> Box<dyn Method> {
        match self {
            MethodSettings::Path(s) => Box::new(PathTracer::new(s.clone())),
            MethodSettings::Ic(s) => Box::new(IrradianceCaching::new(s.clone())),
            MethodSettings::Trc(s) => Box::new(TemporalRadianceCaching::new(s.clone())),
        }
    }
}

/// Which ray backend to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BackendChoice {
    /// The GPU when one is usable, else the CPU.
    #[default]
    Auto,
    Cpu,
    Gpu,
}

/// Picks the backend:
/// - `auto`: a real GPU adapter (device type other than `Cpu`) when one
///   exists, else the CPU backend. A GPU that is found but cannot be used
///   (no device, shaders rejected) falls back to the CPU with a warning on
///   stderr;
/// - `cpu`: the CPU backend;
/// - `gpu`: any adapter, the software one (lavapipe) included; none is an
///   error, never a panic.
///
/// `WGPU_BACKEND` (e.g. `vulkan`) restricts the wgpu backends searched.
/// The caller prints `backend.name()`, which names the adapter picked.
pub fn make_backend(choice: BackendChoice) -> Result<Box<dyn RayBackend>> {
    match choice {
        BackendChoice::Cpu => Ok(Box::new(CpuBackend::new())),
        BackendChoice::Auto => match GpuBackend::new(AdapterPolicy::HardwareOnly) {
            Ok(gpu) => Ok(Box::new(gpu)),
            Err(GpuError::NoAdapter) => Ok(Box::new(CpuBackend::new())),
            Err(e) => {
                eprintln!("warning: {e}; using the CPU backend");
                Ok(Box::new(CpuBackend::new()))
            }
        },
        BackendChoice::Gpu => match GpuBackend::new(AdapterPolicy::AllowSoftware) {
            Ok(gpu) => Ok(Box::new(gpu)),
            Err(e) => bail!("--backend gpu: {e}"),
        },
    }
}

/// Settings of a render that do not depend on the method.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSettings {
    pub width: u32,
    pub height: u32,
    pub fps: f32,
    pub seed: u64,
    /// Same random sequence in every frame (`--same-pattern`).
    pub same_pattern: bool,
}

impl Default for FrameSettings {
    fn default() -> Self {
        FrameSettings {
            width: 256,
            height: 256,
            fps: crate::scene::DEFAULT_FPS,
            seed: 0,
            same_pattern: false,
        }
    }
}

/// Renders frames of one scene with one method and one backend.
pub struct Renderer {
    pub scene: Scene,
    pub settings: FrameSettings,
    method: Box<dyn Method>,
    backend: Box<dyn RayBackend>,
    last_frame: Option<u32>,
    last_frame_rays: u64,
    /// The frame after the last one to render (two-pass methods look
    /// ahead no further); `None`: the scene's last frame.
    frame_end: Option<u32>,
}

impl Renderer {
    pub fn new(
        scene: Scene,
        method: Box<dyn Method>,
        backend: Box<dyn RayBackend>,
        settings: FrameSettings,
    ) -> Self {
        Renderer {
            scene,
            settings,
            method,
            backend,
            last_frame: None,
            last_frame_rays: 0,
            frame_end: None,
        }
    }

    pub fn backend(&self) -> &dyn RayBackend {
        self.backend.as_ref()
    }

    pub fn method_name(&self) -> &'static str {
        self.method.name()
    }

    /// Statistics of the last rendered frame, rays included.
    pub fn last_frame_stats(&self) -> FrameStats {
        let mut stats = self.method.last_frame_stats();
        stats.frame = self.last_frame.unwrap_or(0);
        stats.rays = self.last_frame_rays;
        stats
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
    /// trace count in this frame).
    pub fn render_frame(&mut self, frame: u32) -> Film {
        let rays_before = self.backend.ray_counts().total();
        let film = self.render_frame_uncounted(frame);
        self.last_frame_rays = self.backend.ray_counts().total() - rays_before;
        self.last_frame = Some(frame);
        film
    }

    fn render_frame_uncounted(&mut self, frame: u32) -> Film {
        let mut method = std::mem::replace(&mut self.method, Box::new(NoMethod));
        let end = self
            .frame_end
            .unwrap_or(self.scene.frame_count)
            .max(frame + 1);
        while let Some(f) = method.next_frame_to_prepare(frame, end) {
            self.with_frame_context(f, |ctx| method.prepare_frame(ctx));
        }
        let film = self.with_frame_context(frame, |ctx| method.render_frame(ctx));
        self.method = method;
        film
    }

    /// Evaluates frame `frame` (geometry, lights, backend) and runs `f` on
    /// its context: what a method sees. Tests use it to probe a method's
    /// stages directly.
    pub fn with_frame_context<R>(&mut self, frame: u32, f: impl FnOnce(&FrameContext) -> R) -> R {
        let t = frame as f32 / self.settings.fps;
        let snapshot = self.scene.snapshot(t);
        self.backend.set_geometry(&snapshot);
        let lights = LightSampler::new(&snapshot, &self.scene.materials);
        let ctx = FrameContext {
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
        };
        f(&ctx)
    }
}

/// Placeholder while the real method is borrowed out of the renderer.
struct NoMethod;

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
    pub frames: u32,
    /// Statistics of every rendered frame, in order.
    pub frame_stats: Vec<FrameStats>,
    pub elapsed: Duration,
    pub rays: u64,
    pub out_dir: PathBuf,
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
        Some(format!(
            "records created {created} ({:.0}/frame), lookups {lookups}, {:.1} records/lookup, {fallbacks} path-traced fallbacks; {}",
            created as f64 / self.frames.max(1) as f64,
            used as f64 / lookups as f64,
            phases.join(", ")
        ))
    }

    /// For temporal methods (records with lifespans): records reused,
    /// replaced and dropped, the mean lifespan of the records computed, and
    /// their lifespan histogram, one line per lifespan in frames.
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
        let computed: u64 = histogram.iter().sum();
        if computed == 0 {
            return None;
        }
        let sum = |f: fn(&FrameStats) -> u64| self.frame_stats.iter().map(f).sum::<u64>();
        let total: u64 = histogram
            .iter()
            .enumerate()
            .map(|(life, n)| life as u64 * n)
            .sum();
        let widest = histogram.iter().copied().max().unwrap_or(1).max(1);
        let mut out = format!(
            "records reused {} times, replaced {}, dropped {}; mean lifespan {:.2} frames over {computed} records computed\nlifespan histogram (frames: records):",
            sum(|s| s.records_reused),
            sum(|s| s.records_replaced),
            sum(|s| s.records_dropped),
            total as f64 / computed as f64,
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

/// Renders `frames` into `out_dir` as `frame_NNNN.exr` and `.png`, with a
/// progress bar on stderr unless `quiet`.
pub fn render_to_dir(
    renderer: &mut Renderer,
    frames: Range<u32>,
    out_dir: &Path,
    quiet: bool,
) -> Result<RenderSummary> {
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create output directory {}", out_dir.display()))?;
    let progress = progress_bar(frames.len() as u64, quiet);
    let start = Instant::now();
    let rays_before = renderer.backend().ray_counts().total();
    let mut frame_stats = Vec::with_capacity(frames.len());
    renderer.set_frame_end(Some(frames.end));
    for frame in frames.clone() {
        progress.set_message(format!("frame {frame}"));
        let film = renderer.render_frame(frame);
        film::write_frame(&film, out_dir, frame)?;
        frame_stats.push(renderer.last_frame_stats());
        progress.inc(1);
    }
    progress.finish_and_clear();
    Ok(RenderSummary {
        frames: frames.len() as u32,
        frame_stats,
        elapsed: start.elapsed(),
        rays: renderer.backend().ray_counts().total() - rays_before,
        out_dir: out_dir.to_path_buf(),
    })
}

fn progress_bar(len: u64, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} frames, eta {eta} {msg}",
        )
        .expect("static progress template is valid"),
    );
    bar
}
