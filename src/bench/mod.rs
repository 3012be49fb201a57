//! `radcache bench`: runs methods over scenes, measures them against a
//! converged `path` reference and charts speed against accuracy
//! (DESIGN.md "Measuring").
//!
//! For each scene the bench renders (or reuses) a reference sequence with
//! `path --same-pattern` at a high sample count into
//! `DIR/reference/<scene>/`, then renders every run — one method at one value
//! of one swept setting, on one ray backend — into
//! `DIR/runs/<scene>/<method>-<key>=<value>/` (with `-<backend>` appended
//! when the bench has several, [`BenchOptions::backends`]), and compares it
//! with the reference through [`crate::metrics`]. It writes
//! `DIR/bench.csv` (one row per run) and two SVG charts per scene:
//! `DIR/<scene>_error_vs_time.svg` (relative RMSE against seconds, log-log,
//! one line per method sweep, so the Pareto front shows) and
//! `DIR/<scene>_flicker_vs_time.svg`.
//!
//! Beside each reference frame it writes the frame's light mask
//! ([`crate::metrics::light_mask_path`]: the pixels that see a light source
//! directly, or border one), so every run also gets `rel_rmse_surfaces`, the
//! error of the lit surfaces without the rim of a directly seen light, whose
//! anti-aliasing noise is the same for every method and can weigh heavily
//! in an all-pixel RMSE at low sample counts, and likewise
//! `flicker_surfaces`;
//! `DIR/<scene>_surface_error_vs_time.svg` and
//! `DIR/<scene>_surface_flicker_vs_time.svg` chart them.
//!
//! With [`BenchOptions::repeat`] above 1 a scene's runs are rendered in
//! rounds, each run once a round, and each run's time is the median of
//! its rounds: a ratio of two runs then leans less on the minute each
//! happened to run in (the machine drifts: the same `ic` run took
//! 54.6 s and 68.9 s within an hour, `benches/HISTORY.md`).
//!
//! With [`BenchOptions::seeds`] above 1 every run is rendered at that many
//! seeds, its errors the means; each seed's go to `DIR/bench_seeds.csv`,
//! and the charts bar their range through the run's point.
//!
//! A bench begins by removing the `bench.csv` and charts an earlier bench
//! left in `DIR`, so that none describes runs this one did not make; one
//! stopped early ([`BenchOptions::stop`]) writes them for the runs it
//! finished. The CSVs are written again as each run finishes, each whole
//! or not at all, so one killed outright keeps the runs it finished too.
//!
//! # Parts
//! - `methods`: the methods and settings `--methods` accepts;
//! - `reference`: a scene's converged reference and its light masks;
//! - `run`: the runs, each timed and compared with the reference (and, with
//!   `--estimate-error`, `trc`'s E(t0+1) estimates measured);
//! - `report`: the CSV, the table and the ratios printed after it;
//! - `seeds`: each seed's errors, printed, in `bench_seeds.csv` and as
//!   the bars of the charts;
//! - `charts`: the SVG charts.
//!
//! # Adding a method
//! A method becomes benchable by one row in [`METHODS`] (its name, the keys
//! it sweeps with an example value each) and one arm in [`method_settings`]
//! turning `(key, value)` into its [`crate::render::MethodSettings`]; a unit
//! test checks that the two agree. Record counts come from the method's frame statistics.

mod charts;
mod methods;
mod reference;
mod report;
mod run;
mod seeds;

pub use charts::plot_scene;
pub use methods::{method_settings, MethodError, MethodInfo, MethodSweep, RunSpec, METHODS};
pub use report::{
    backend_pairs, backend_text, equal_error_table, equal_error_text, estimate_error_text,
    from_csv, interpolate_time_at_error, rounds_text, temporal_pairs, temporal_text, to_csv,
    to_table, BenchRow, EqualError, ErrorMeasure, PathBound, CSV_HEADER,
};
pub use run::{peak_memory_mb, replot, reset_peak_memory, run, run_with, BenchReport};
pub use seeds::{seeds_text, SeedError, SEEDS_CSV};

use crate::render::{BackendChoice, SceneSource};
use anyhow::{bail, Result};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

// ---------------------------------------------------------------- options

/// What `radcache bench` runs.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub scenes: Vec<SceneSource>,
    pub methods: Vec<MethodSweep>,
    pub frames: Range<u32>,
    pub width: u32,
    pub height: u32,
    pub fps: f32,
    pub reference_spp: u32,
    pub seed: u64,
    pub out: PathBuf,
    /// Render the runs, not only the reference, with the same random
    /// sequence in every frame: pixel noise then stays put from frame to
    /// frame, so flicker shows what the method itself changes between
    /// frames (records appearing and moving), not its per-frame noise.
    pub same_pattern: bool,
    /// No progress bars or messages on stderr.
    pub quiet: bool,
    /// For `trc` runs, also measure the error of the records' `E(t0+1)`
    /// estimate over every record the run computes (TRC Table 1), in a
    /// second, untimed pass that gathers each record again one frame
    /// later ([`BenchRow::next_error`]).
    pub estimate_error: bool,
    /// Also render every run, untimed, into a store of its own
    /// (`runs/<scene>/<run>/store`, left for `radcache inspect`) and report
    /// its bytes on disk ([`BenchRow::store_bytes`]).
    pub store_size: bool,
    /// The ray backends every run is rendered with, one run per backend
    /// (`--backends cpu,gpu`: GPU against CPU in one invocation, the
    /// ratio read off one table). The reference is rendered on the CPU
    /// (`reference::REFERENCE_BACKEND`).
    pub backends: Vec<BackendChoice>,
    /// Refuse, before anything renders, a bench one of whose runs has an
    /// estimated peak memory (`render::memory::peak_bytes`, on its scene's
    /// triangles) over what this process may take (`radcache bench`
    /// without `--no-memory-check`).
    pub check_memory: bool,
    /// Rounds of a scene's runs (at least 1): each run is rendered once a
    /// round and its reported times are the medians over the rounds
    /// ([`BenchReport::round_seconds`] keeps them all); everything else is
    /// measured in the first round.
    pub repeat: u32,
    /// Seeds every run is rendered at (at least 1): `seed`, `seed + 1`, …,
    /// against the one reference. A run's errors and records are their
    /// means over the seeds ([`BenchReport::seed_errors`] keeps each
    /// seed's); its time, rays, memory and the untimed measures are the
    /// first seed's. Why: `trc` and `tcg` keep their pixel samples'
    /// streams from frame to frame, so their frames share one draw of
    /// pixel noise, and where it is most of the error one seed's figure
    /// is a wide sample (`glossy-cornell`: 0.104–0.127 over six seeds,
    /// `benches/RESULTS.md`, "`trc`'s error over seeds").
    pub seeds: u32,
    /// Set (from any thread: Ctrl-C in `radcache bench`) to stop the bench
    /// early: the run or reference in progress is abandoned mid-frame, and
    /// [`run()`] returns the runs finished before, with their CSV and charts,
    /// naming the others ([`BenchReport::unfinished`]).
    pub stop: Arc<AtomicBool>,
}

/// The methods of the default run: every method, each as a sweep so that
/// it draws a curve on the charts (`trc`'s over `δt_max`, TRC Eq. 10: the
/// longest a record may live, which trades time against stale light;
/// `tcg`'s over `τ_min`, Eq. 2: the least share of samples shot again each
/// frame; `movies`' over the shadow samples a texel takes, the paper's `N`).
pub const DEFAULT_METHODS: [&str; 5] = [
    "path:spp=4,16,64,256",
    "ic:spp=16,64",
    "trc:max_life=2,5,20",
    "tcg:tau_min=0.02,0.05,0.2",
    "movies:shadow_samples=4,16,64",
];

/// The frames of the default run: those `radcache render` renders by
/// default, enough for `trc`'s records to live out a lifespan.
pub const DEFAULT_FRAMES: Range<u32> = 0..24;

impl Default for BenchOptions {
    /// The default run: `cube-in-box`, [`DEFAULT_FRAMES`] at 64×64,
    /// [`DEFAULT_METHODS`], against a 1024-spp reference.
    fn default() -> Self {
        BenchOptions {
            scenes: vec![SceneSource::Builtin("cube-in-box".into())],
            methods: DEFAULT_METHODS
                .iter()
                .map(|m| MethodSweep::parse(m).expect("valid default"))
                .collect(),
            frames: DEFAULT_FRAMES,
            width: 64,
            height: 64,
            fps: crate::scene::DEFAULT_FPS,
            reference_spp: 1024,
            seed: 0,
            out: PathBuf::from("bench-out"),
            same_pattern: false,
            quiet: false,
            estimate_error: false,
            store_size: false,
            backends: vec![BackendChoice::Auto],
            check_memory: true,
            repeat: 1,
            seeds: 1,
            stop: Arc::default(),
        }
    }
}

/// A scene argument: a built-in name, or a `.gltf`/`.glb` file.
pub fn parse_scene(s: &str) -> Result<SceneSource> {
    let s = s.trim();
    if crate::scene::builtin::NAMES.contains(&s) {
        return Ok(SceneSource::Builtin(s.into()));
    }
    let lower = s.to_ascii_lowercase();
    if lower.ends_with(".gltf") || lower.ends_with(".glb") || Path::new(s).is_file() {
        return Ok(SceneSource::File(PathBuf::from(s)));
    }
    bail!(
        "'{s}' is neither a built-in scene ({}) nor a .gltf/.glb file",
        crate::scene::builtin::NAMES.join(", ")
    )
}

/// The name of a scene in file and folder names: the built-in name, or the
/// file's stem.
pub fn scene_label(source: &SceneSource) -> String {
    let raw = match source {
        SceneSource::Builtin(name) => name.clone(),
        SceneSource::File(path) => path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
    };
    sanitize(&raw)
}

/// Keeps `[A-Za-z0-9._=-]`, replaces the rest with `_`.
fn sanitize(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._=-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_labels() {
        assert_eq!(
            scene_label(&SceneSource::Builtin("cube-in-box".into())),
            "cube-in-box"
        );
        assert_eq!(
            scene_label(&SceneSource::File("/a/b/my scene.glb".into())),
            "my_scene"
        );
        assert!(parse_scene("nonsense").is_err());
        assert_eq!(
            parse_scene("spheres").unwrap(),
            SceneSource::Builtin("spheres".into())
        );
    }
}
