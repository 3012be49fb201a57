//! What a render is asked for: the scene, the method and its settings,
//! the ray backend, the frames and their size, and the parsing of the
//! frame ranges and image sizes the CLI and the API take.

use crate::backend::cpu::CpuBackend;
use crate::backend::gpu::{AdapterPolicy, GpuBackend, GpuError};
use crate::backend::RayBackend;
use crate::method::ic::{IcSettings, IrradianceCaching};
use crate::method::movies::{MoviesSettings, TextureMovies};
use crate::method::path::{PathSettings, PathTracer};
use crate::method::tcg::{TcgSettings, TemporallyCoherentGathering};
use crate::method::trc::{TemporalRadianceCaching, TrcSettings};
use crate::method::Method;
use crate::scene::{Scene, SceneError};
use anyhow::{bail, Result};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Where a scene comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    Builtin(String),
    File(PathBuf),
}

impl SceneSource {
    /// The scene, a file's read with every file its URIs name wherever
    /// they are (the command line's).
    pub fn load(&self) -> Result<Scene, SceneError> {
        self.load_confined(None)
    }

    /// The scene; a file and the files its URIs name read only inside
    /// `root` when it is given (`radcache serve --scenes DIR`).
    pub fn load_confined(&self, root: Option<&Path>) -> Result<Scene, SceneError> {
        match self {
            SceneSource::Builtin(name) => Scene::builtin(name),
            SceneSource::File(path) => Scene::load_confined(path, root),
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

/// Which rendering method, with its settings. Its serde JSON is a job's
/// settings identity in the store.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum MethodSettings {
    Path(PathSettings),
    Ic(IcSettings),
    Trc(TrcSettings),
    Tcg(TcgSettings),
    Movies(MoviesSettings),
}

impl MethodSettings {
    /// The method's command-line name.
    pub fn name(&self) -> &'static str {
        match self {
            MethodSettings::Path(_) => "path",
            MethodSettings::Ic(_) => "ic",
            MethodSettings::Trc(_) => "trc",
            MethodSettings::Tcg(_) => "tcg",
            MethodSettings::Movies(_) => "movies",
        }
    }

    /// Pixel samples per frame.
    pub fn spp(&self) -> u32 {
        match self {
            MethodSettings::Path(s) => s.spp,
            MethodSettings::Ic(s) => s.spp,
            MethodSettings::Trc(s) => s.ic.spp,
            MethodSettings::Tcg(s) => s.ic.spp,
            MethodSettings::Movies(s) => s.spp,
        }
    }

    pub fn instantiate(&self) -> Box<dyn Method> {
        match self {
            MethodSettings::Path(s) => Box::new(PathTracer::new(s.clone())),
            MethodSettings::Ic(s) => Box::new(IrradianceCaching::new(s.clone())),
            MethodSettings::Trc(s) => Box::new(TemporalRadianceCaching::new(s.clone())),
            MethodSettings::Tcg(s) => Box::new(TemporallyCoherentGathering::new(s.clone())),
            MethodSettings::Movies(s) => Box::new(TextureMovies::new(s.clone())),
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

impl BackendChoice {
    /// The choice as the command line spells it.
    pub fn name(self) -> &'static str {
        match self {
            BackendChoice::Auto => "auto",
            BackendChoice::Cpu => "cpu",
            BackendChoice::Gpu => "gpu",
        }
    }
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
/// `RADCACHE_GPU_BVH` (`cwbvh`, the default, or `bvh2`) picks the BVH
/// layout the GPU traverses; an unknown value is an error like a missing
/// adapter.
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

/// The frame rates a render takes (`--fps`, a job's `fps`): frame f is at
/// t = f / fps, and past these t overflows or stops moving.
pub const FPS_RANGE: std::ops::RangeInclusive<f32> = 0.001..=100_000.0;

/// Settings of a render that do not depend on the method.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSettings {
    pub width: u32,
    pub height: u32,
    pub fps: f32,
    pub seed: u64,
    /// Same random sequence in every frame (`--same-pattern`).
    pub same_pattern: bool,
    /// Coverage-only camera rays of a pixel on the edge of a directly seen
    /// light, in units of the method's samples per pixel (`method::pixels`).
    pub edge_coverage_factor: u32,
}

impl Default for FrameSettings {
    fn default() -> Self {
        FrameSettings {
            width: 256,
            height: 256,
            fps: crate::scene::DEFAULT_FPS,
            seed: 0,
            same_pattern: false,
            edge_coverage_factor: crate::method::pixels::DEFAULT_EDGE_COVERAGE_FACTOR,
        }
    }
}

/// Frame numbers lie below this. Frame `f` is at time `f / fps`, an `f32`:
/// up to a million frames (11.6 hours at 24 fps) that time is still exact
/// to a tenth of a frame; and temporal methods add lifespans (at most
/// 100,000 frames) to frame numbers, which must not overflow.
pub const FRAME_LIMIT: u32 = 1_000_000;

/// Runs of consecutive frames in `frames` (ascending), as ranges: what a
/// job has stored after renders of several ranges, e.g. `[0..10, 15..20]`.
pub fn frame_runs(frames: impl IntoIterator<Item = u32>) -> Vec<Range<u32>> {
    let mut runs: Vec<Range<u32>> = Vec::new();
    for f in frames {
        match runs.last_mut() {
            Some(r) if r.end == f => r.end = f.saturating_add(1),
            // A damaged store's frame u32::MAX ends its run one short.
            _ => runs.push(f..f.saturating_add(1)),
        }
    }
    runs
}

/// Parses a frame range `START..END` (END exclusive, below
/// [`FRAME_LIMIT`]), as the CLI's `--frames` and the API's `frames` take
/// it. The error says what is wrong with `s`.
pub fn parse_frame_range(s: &str) -> Result<Range<u32>, String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("'{s}' is not a frame range; expected START..END, e.g. 0..24"))?;
    let number = |n: &str| match (n.parse::<u32>(), n.parse::<u64>()) {
        _ if !all_digits(n) => Err(format!("frame range '{s}': '{n}' is not a frame number")),
        (Ok(n), _) => Ok(n),
        (Err(_), Ok(_)) => Err(format!(
            "frame range '{s}': {n} is past the last frame number, {}",
            FRAME_LIMIT - 1
        )),
        _ => Err(format!("frame range '{s}': '{n}' is not a frame number")),
    };
    let (start, end) = (number(a)?, number(b)?);
    if end <= start {
        return Err(format!("frame range '{s}' is empty (END is exclusive)"));
    }
    if end > FRAME_LIMIT {
        return Err(format!(
            "frame range '{s}' ends past the last frame number, {}",
            FRAME_LIMIT - 1
        ));
    }
    Ok(start..end)
}

/// Whether `n` is a plain decimal number: `str::parse` also takes a
/// leading `+`, which no frame number or side is written with.
fn all_digits(n: &str) -> bool {
    !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit())
}

/// Parses an image size `WxH` with sides in `1..=max_side`, as the CLI's
/// `--size` and the API's `size` take it.
pub fn parse_image_size(s: &str, max_side: u32) -> Result<(u32, u32), String> {
    let bad = || format!("'{s}' is not an image size; expected WxH, e.g. 256x256");
    let (w_text, h_text) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = match (w_text.parse(), h_text.parse()) {
        (Ok(w), Ok(h)) if all_digits(w_text) && all_digits(h_text) => (w, h),
        _ => return Err(bad()),
    };
    if w == 0 || h == 0 || w > max_side || h > max_side {
        return Err(format!(
            "image size {w}x{h} is out of range (1..={max_side} per side)"
        ));
    }
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_runs_merge_consecutive_frames_only() {
        assert_eq!(frame_runs([]), Vec::<Range<u32>>::new());
        assert_eq!(frame_runs([3]), vec![3..4]);
        assert_eq!(frame_runs([0, 1, 2, 5, 6, 9]), vec![0..3, 5..7, 9..10]);
        // A damaged store's last frame number does not overflow.
        assert_eq!(
            frame_runs([u32::MAX - 1, u32::MAX]),
            vec![u32::MAX - 1..u32::MAX]
        );
    }

    #[test]
    fn frame_ranges_and_sizes_parse_strictly() {
        assert_eq!(parse_frame_range("0..24"), Ok(0..24));
        assert_eq!(
            parse_frame_range("999999..1000000"),
            Ok(999_999..FRAME_LIMIT)
        );
        for (bad, says) in [
            ("0-24", "not a frame range"),
            (" 0..1", "' 0' is not a frame number"),
            ("0..x", "'x' is not a frame number"),
            ("+0..+1", "'+0' is not a frame number"),
            ("5..2", "is empty"),
            ("0..1000001", "ends past the last frame number, 999999"),
            (
                "0..99999999999",
                "99999999999 is past the last frame number",
            ),
        ] {
            let e = parse_frame_range(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
        assert_eq!(parse_image_size("16x8", 64), Ok((16, 8)));
        assert_eq!(parse_image_size("16X8", 64), Ok((16, 8)));
        for (bad, says) in [
            ("16", "not an image size"),
            ("16 x8", "not an image size"),
            ("+16x8", "not an image size"),
            ("0x8", "out of range (1..=64 per side)"),
            ("65x8", "out of range"),
        ] {
            let e = parse_image_size(bad, 64).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
