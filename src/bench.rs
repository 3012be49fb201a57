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
//! ([`metrics::light_mask_path`]: the pixels that see a light source
//! directly, or border one), so every run also gets `rel_rmse_surfaces`, the
//! error of the lit surfaces without the rim of a directly seen light, whose
//! anti-aliasing noise is the same for every method and can weigh heavily
//! in an all-pixel RMSE at low sample counts, and likewise
//! `flicker_surfaces`;
//! `DIR/<scene>_surface_error_vs_time.svg` and
//! `DIR/<scene>_surface_flicker_vs_time.svg` chart them.
//!
//! # Adding a method
//! A method becomes benchable by one row in [`METHODS`] (its name, the keys
//! it sweeps with an example value each) and one arm in [`method_settings`]
//! turning `(key, value)` into its [`MethodSettings`]; a unit test checks
//! that the two agree. Record counts come from the method's frame statistics.

use crate::backend::{Hit, Ray};
use crate::cache::gather::Strata;
use crate::method::ic::IcSettings;
use crate::method::path::PathSettings;
use crate::method::trc::estimate_error::{percent, EstimateError, EstimateErrorTally};
use crate::method::trc::{TemporalGradients, TemporalRadianceCaching, TrcSettings};
use crate::method::{FrameContext, Method};
use crate::metrics;
use crate::render::{self, BackendChoice, FrameSettings, MethodSettings, Renderer, SceneSource};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

// ---------------------------------------------------------------- methods

/// A method the bench knows, and the settings a sweep may vary.
pub struct MethodInfo {
    pub name: &'static str,
    /// `(key, example value)`: every key [`method_settings`] accepts for
    /// this method, with a value it accepts (checked by a unit test).
    pub keys: &'static [(&'static str, &'static str)],
}

/// Every method `radcache bench --methods` accepts. Keep in step with
/// [`method_settings`].
pub const METHODS: &[MethodInfo] = &[
    MethodInfo {
        name: "path",
        keys: &[("spp", "16"), ("max_depth", "8"), ("rr_start", "3")],
    },
    MethodInfo {
        name: "ic",
        keys: &[
            ("accuracy", "0.2"),
            ("spp", "4"),
            ("strata", "16x48"),
            ("min_spacing", "2"),
            ("max_spacing", "64"),
            ("gradients", "1"),
        ],
    },
    MethodInfo {
        name: "trc",
        keys: &[
            ("at", "0.05"),
            ("max_life", "20"),
            ("gradients", "extrapolated"),
            ("reprojection", "1"),
            ("next_direct", "0"),
            ("spp", "4"),
            ("accuracy", "0.2"),
            ("strata", "16x48"),
            ("min_spacing", "2"),
            ("max_spacing", "64"),
        ],
    },
];

/// Errors of method specifications; each names what is known.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MethodError {
    #[error("unknown method '{name}'; known methods: {known}")]
    UnknownMethod { name: String, known: String },
    #[error("method '{method}' has no setting '{key}'; its settings: {known}")]
    UnknownKey {
        method: String,
        key: String,
        known: String,
    },
    #[error("{method}: bad value '{value}' for {key}: {problem}")]
    BadValue {
        method: String,
        key: String,
        value: String,
        problem: String,
    },
    #[error("bad method specification '{spec}': {problem} (expected NAME or NAME:KEY=V1,V2,…, e.g. path:spp=4,16,64)")]
    BadSpec { spec: String, problem: String },
}

fn known_methods() -> String {
    METHODS
        .iter()
        .map(|m| m.name)
        .collect::<Vec<_>>()
        .join(", ")
}

fn known_keys(method: &str) -> String {
    METHODS
        .iter()
        .find(|m| m.name == method)
        .map(|m| {
            m.keys
                .iter()
                .map(|(k, _)| *k)
                .collect::<Vec<_>>()
                .join(", ")
        })
        .unwrap_or_default()
}

/// Parses `value` of setting `key` of `method` as a `T` in `range`.
fn value<T>(method: &str, key: &str, value: &str, range: Range<T>) -> Result<T, MethodError>
where
    T: std::str::FromStr + PartialOrd + std::fmt::Display + Copy,
{
    let bad = |problem: String| MethodError::BadValue {
        method: method.into(),
        key: key.into(),
        value: value.into(),
        problem,
    };
    let v: T = value
        .trim()
        .parse()
        .map_err(|_| bad("not a number of the right kind".into()))?;
    if !(range.start <= v && v < range.end) {
        return Err(bad(format!(
            "out of range {}..{} (end exclusive)",
            range.start, range.end
        )));
    }
    Ok(v)
}

/// Applies `ic`'s setting `key = v` to `s` (also for `trc`, whose records
/// are `ic`'s); `false` when `key` is none of them.
fn ic_setting(method: &str, key: &str, v: &str, s: &mut IcSettings) -> Result<bool, MethodError> {
    match key {
        "accuracy" => s.accuracy = value(method, key, v, 0.001..2.001)?,
        "spp" => s.spp = value(method, key, v, 1..1_000_001)?,
        "strata" => {
            let (m, n) = v.split_once('x').ok_or_else(|| MethodError::BadValue {
                method: method.into(),
                key: key.into(),
                value: v.into(),
                problem: "expected MxN, e.g. 16x48".into(),
            })?;
            s.strata = Strata {
                theta: value(method, key, m, 1..1025)?,
                phi: value(method, key, n, 1..4097)?,
            };
        }
        "min_spacing" => s.min_spacing_px = value(method, key, v, 0.001..1e6)?,
        "max_spacing" => s.max_spacing_px = value(method, key, v, 0.001..1e6)?,
        "gradients" => s.gradients = value::<u8>(method, key, v, 0..2)? == 1,
        _ => return Ok(false),
    }
    Ok(true)
}

/// The settings of `method` with its defaults, and `setting = (key, value)`
/// applied when given. **The one place that maps names to
/// [`MethodSettings`]**: a new method adds an arm here and a row to
/// [`METHODS`].
pub fn method_settings(
    method: &str,
    setting: Option<(&str, &str)>,
) -> Result<MethodSettings, MethodError> {
    let unknown_key = |key: &str| MethodError::UnknownKey {
        method: method.into(),
        key: key.into(),
        known: known_keys(method),
    };
    match method {
        "path" => {
            let mut s = PathSettings::default();
            if let Some((key, v)) = setting {
                match key {
                    "spp" => s.spp = value(method, key, v, 1..1_000_001)?,
                    "max_depth" => s.length.max_depth = Some(value(method, key, v, 0..10_001)?),
                    "rr_start" => s.length.rr_start = value(method, key, v, 0..10_001)?,
                    _ => return Err(unknown_key(key)),
                }
            }
            Ok(MethodSettings::Path(s))
        }
        "ic" => {
            let mut s = IcSettings::default();
            if let Some((key, v)) = setting {
                if !ic_setting(method, key, v, &mut s)? {
                    return Err(unknown_key(key));
                }
            }
            Ok(MethodSettings::Ic(s))
        }
        "trc" => {
            let mut s = TrcSettings::default();
            if let Some((key, v)) = setting {
                match key {
                    "at" => s.temporal_accuracy = value(method, key, v, 1e-6..1e6)?,
                    "max_life" => s.max_life = value(method, key, v, 1..100_001)?,
                    "gradients" => {
                        s.gradients = match v.trim() {
                            "none" => TemporalGradients::None,
                            "extrapolated" => TemporalGradients::Extrapolated,
                            "interpolated" => TemporalGradients::Interpolated,
                            _ => {
                                return Err(MethodError::BadValue {
                                    method: method.into(),
                                    key: key.into(),
                                    value: v.into(),
                                    problem: "expected none, extrapolated or interpolated".into(),
                                })
                            }
                        }
                    }
                    "reprojection" => s.reprojection = value::<u8>(method, key, v, 0..2)? == 1,
                    "next_direct" => s.next_direct = value::<u8>(method, key, v, 0..2)? == 1,
                    // `gradients` above names the temporal ones; the
                    // rest are `ic`'s, whose records `trc` makes.
                    _ => {
                        if !ic_setting(method, key, v, &mut s.ic)? {
                            return Err(unknown_key(key));
                        }
                    }
                }
            }
            Ok(MethodSettings::Trc(s))
        }
        _ => Err(MethodError::UnknownMethod {
            name: method.into(),
            known: known_methods(),
        }),
    }
}

/// Records (irradiance or radiance records, texture movies, …) a method
/// computed during the last run; 0 for methods without records (`path`).
/// A method with records reports them here.
/// One method with an optional sweep of one setting:
/// `path` (defaults) or `path:spp=4,16,64` (one run per value).
#[derive(Clone, Debug, PartialEq)]
pub struct MethodSweep {
    pub method: String,
    /// `None`: one run with the defaults.
    pub key: Option<String>,
    pub values: Vec<String>,
}

impl MethodSweep {
    /// Parses `NAME` or `NAME:KEY=V1,V2,…` and checks every value against
    /// [`method_settings`], so a typo fails before anything renders.
    pub fn parse(spec: &str) -> Result<Self, MethodError> {
        let bad = |problem: &str| MethodError::BadSpec {
            spec: spec.into(),
            problem: problem.into(),
        };
        let (method, sweep) = match spec.split_once(':') {
            Some((m, s)) => (m.trim(), Some(s)),
            None => (spec.trim(), None),
        };
        if method.is_empty() {
            return Err(bad("no method name"));
        }
        let sweep = match sweep {
            None => MethodSweep {
                method: method.into(),
                key: None,
                values: Vec::new(),
            },
            Some(s) => {
                let (key, values) = s
                    .split_once('=')
                    .ok_or_else(|| bad("no '=' after the setting"))?;
                let key = key.trim();
                if key.is_empty() {
                    return Err(bad("no setting name before '='"));
                }
                let values: Vec<String> = values.split(',').map(|v| v.trim().to_string()).collect();
                if values.iter().any(String::is_empty) {
                    return Err(bad("empty value in the list"));
                }
                MethodSweep {
                    method: method.into(),
                    key: Some(key.into()),
                    values,
                }
            }
        };
        for run in sweep.runs() {
            run.settings()?;
        }
        Ok(sweep)
    }

    /// The runs of the sweep, in the order given.
    pub fn runs(&self) -> Vec<RunSpec> {
        match &self.key {
            None => vec![RunSpec {
                method: self.method.clone(),
                setting: None,
            }],
            Some(key) => self
                .values
                .iter()
                .map(|v| RunSpec {
                    method: self.method.clone(),
                    setting: Some((key.clone(), v.clone())),
                })
                .collect(),
        }
    }
}

/// One run: a method and at most one setting changed from its defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    pub method: String,
    pub setting: Option<(String, String)>,
}

impl RunSpec {
    pub fn settings(&self) -> Result<MethodSettings, MethodError> {
        method_settings(
            &self.method,
            self.setting.as_ref().map(|(k, v)| (k.as_str(), v.as_str())),
        )
    }

    /// `spp=4`, or `default`.
    pub fn label(&self) -> String {
        match &self.setting {
            Some((k, v)) => format!("{k}={v}"),
            None => "default".into(),
        }
    }
}

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
    /// The ray backends every run is rendered with, one run per backend
    /// (`--backends cpu,gpu`: GPU against CPU in one invocation, the
    /// ratio read off one table). The reference is rendered with `auto`.
    pub backends: Vec<BackendChoice>,
}

impl Default for BenchOptions {
    /// The small default run: `cube-in-box`, frames 0..4 at 64×64, `path`
    /// at 4, 16, 64 and 256 spp and `ic` at 16 and 64 spp against a
    /// 1024-spp reference.
    fn default() -> Self {
        BenchOptions {
            scenes: vec![SceneSource::Builtin("cube-in-box".into())],
            methods: vec![
                MethodSweep::parse("path:spp=4,16,64,256").expect("valid default"),
                MethodSweep::parse("ic:spp=16,64").expect("valid default"),
            ],
            frames: 0..4,
            width: 64,
            height: 64,
            fps: crate::scene::DEFAULT_FPS,
            reference_spp: 1024,
            seed: 0,
            out: PathBuf::from("bench-out"),
            same_pattern: false,
            quiet: false,
            estimate_error: false,
            backends: vec![BackendChoice::Auto],
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

// ---------------------------------------------------------------- results

/// One row of `bench.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchRow {
    pub scene: String,
    pub method: String,
    /// `key=value` or `default`.
    pub settings: String,
    /// The ray backend the run was rendered with, as it names itself
    /// (`cpu (2 threads)`, `gpu (<adapter>, Vulkan)`).
    pub backend: String,
    pub frames: u32,
    /// Wall time of rendering, all frames, file writing excluded.
    pub seconds: f64,
    /// Of `seconds`, the time of the render pass that `ic` and `trc` share
    /// (their [`crate::method::RENDER_PHASE`]: direct light, cache lookups, glossy lobes);
    /// the rest is the method's own work on its records. `None` for
    /// methods without a cache.
    pub render_pass_seconds: Option<f64>,
    pub rays: u64,
    pub records: u64,
    /// Peak resident memory of the process during the run (MB), where the
    /// platform tells it.
    pub peak_mem_mb: Option<f64>,
    pub rel_rmse: f64,
    /// Relative RMSE without the pixels at directly seen lights
    /// ([`metrics::CompareReport::rel_rmse_surfaces`]).
    pub rel_rmse_surfaces: Option<f64>,
    pub block_bias: f64,
    /// `None` with a single frame.
    pub flicker: Option<f64>,
    /// Flicker without the pixels at directly seen lights
    /// ([`metrics::CompareReport::flicker_surfaces`]).
    pub flicker_surfaces: Option<f64>,
    /// With [`BenchOptions::estimate_error`], for `trc` runs: the error of
    /// the `E(t0+1)` estimate of the records the run computed, against
    /// `E(t0+1)` gathered again (TRC Table 1). Records of the run's last
    /// frame are measured too (their `t0 + 1` is past the range, but a
    /// frame of the scene all the same).
    pub next_error: Option<EstimateError>,
}

/// `bench.csv`'s header line.
pub const CSV_HEADER: &str =
    "scene,method,settings,backend,frames,seconds,render_pass_seconds,rays,records,peak_mem_mb,rel_rmse,rel_rmse_surfaces,block_bias,flicker,flicker_surfaces,\
estimated_records,estimate_err_mean,estimate_err_median,constant_err_mean,constant_err_median";

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or(String::new(), |v| format!("{v:.decimals$}"))
}

/// The five CSV fields of [`BenchRow::next_error`], empty where not measured.
fn next_error_fields(e: Option<EstimateError>) -> String {
    match e {
        Some(e) => format!(
            "{},{:.6},{:.6},{:.6},{:.6}",
            e.records, e.estimate.0, e.estimate.1, e.constant.0, e.constant.1
        ),
        None => ",,,,".into(),
    }
}

/// The CSV text: [`CSV_HEADER`] and one line per row. Missing values
/// (flicker of a single frame, memory where unknown) are empty fields.
pub fn to_csv(rows: &[BenchRow]) -> String {
    let mut out = format!("{CSV_HEADER}\n");
    for r in rows {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{:.4},{},{},{},{},{:.6},{},{:.6},{},{},{}",
            csv_field(&r.scene),
            csv_field(&r.method),
            csv_field(&r.settings),
            csv_field(&r.backend),
            r.frames,
            r.seconds,
            opt(r.render_pass_seconds, 4),
            r.rays,
            r.records,
            opt(r.peak_mem_mb, 1),
            r.rel_rmse,
            opt(r.rel_rmse_surfaces, 6),
            r.block_bias,
            opt(r.flicker, 6),
            opt(r.flicker_surfaces, 6),
            next_error_fields(r.next_error),
        );
    }
    out
}

/// The rows as an aligned table for the terminal.
pub fn to_table(rows: &[BenchRow]) -> String {
    let header = [
        "scene",
        "method",
        "settings",
        "backend",
        "frames",
        "seconds",
        "render s",
        "Mrays",
        "records",
        "peak MB",
        "rel_rmse",
        "rmse surf",
        "block_bias",
        "flicker",
        "flicker surf",
    ];
    let cells: Vec<[String; 15]> = rows
        .iter()
        .map(|r| {
            [
                r.scene.clone(),
                r.method.clone(),
                r.settings.clone(),
                r.backend.clone(),
                r.frames.to_string(),
                format!("{:.3}", r.seconds),
                r.render_pass_seconds
                    .map_or("-".into(), |v| format!("{v:.3}")),
                format!("{:.2}", r.rays as f64 / 1e6),
                r.records.to_string(),
                r.peak_mem_mb.map_or("-".into(), |v| format!("{v:.0}")),
                format!("{:.5}", r.rel_rmse),
                r.rel_rmse_surfaces
                    .map_or("-".into(), |v| format!("{v:.5}")),
                format!("{:.5}", r.block_bias),
                r.flicker.map_or("-".into(), |v| format!("{v:.5}")),
                r.flicker_surfaces.map_or("-".into(), |v| format!("{v:.5}")),
            ]
        })
        .collect();
    let mut widths = header.map(str::len);
    for row in &cells {
        for (w, c) in widths.iter_mut().zip(row) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cols: Vec<&str>| {
        let mut s = String::new();
        for (i, (c, w)) in cols.iter().zip(widths).enumerate() {
            // Text columns left-aligned, numbers right-aligned.
            if i < 4 {
                let _ = write!(s, "{c:<w$}  ");
            } else {
                let _ = write!(s, "{c:>w$}  ");
            }
        }
        s.trim_end().to_string() + "\n"
    };
    let mut out = line(header.to_vec());
    for row in &cells {
        out += &line(row.iter().map(String::as_str).collect());
    }
    out
}

// ---------------------------------------------------------------- equal error

/// Time at which a sweep reaches relative RMSE `target`, interpolating
/// linearly in log(seconds)–log(error) between the two consecutive points
/// (ordered by time) whose errors bracket it. `None` when the sweep does not
/// bracket the target (no extrapolation) or has no usable points (values
/// must be positive and finite). With several brackets (a noisy sweep) the
/// fastest wins.
pub fn interpolate_time_at_error(points: &[(f64, f64)], target: f64) -> Option<f64> {
    if !(target.is_finite() && target > 0.0) {
        return None;
    }
    let mut pts: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|&(t, e)| t.is_finite() && t > 0.0 && e.is_finite() && e > 0.0)
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some(&(t, _)) = pts.iter().find(|&&(_, e)| e == target) {
        return Some(t);
    }
    let lt = target.ln();
    pts.windows(2).find_map(|w| {
        let ((t0, e0), (t1, e1)) = (w[0], w[1]);
        let (l0, l1) = (e0.ln(), e1.ln());
        if (l0 - lt) * (l1 - lt) > 0.0 || l0 == l1 {
            return None;
        }
        let s = (lt - l0) / (l1 - l0);
        Some((t0.ln() + s * (t1.ln() - t0.ln())).exp())
    })
}

/// Which error an equal-error comparison holds equal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorMeasure {
    /// Relative RMSE over all pixels ([`BenchRow::rel_rmse`]).
    AllPixels,
    /// Relative RMSE without the pixels at directly seen lights
    /// ([`BenchRow::rel_rmse_surfaces`]).
    Surfaces,
}

impl ErrorMeasure {
    pub fn of(self, row: &BenchRow) -> Option<f64> {
        match self {
            ErrorMeasure::AllPixels => Some(row.rel_rmse),
            ErrorMeasure::Surfaces => row.rel_rmse_surfaces,
        }
    }

    fn name(self) -> &'static str {
        match self {
            ErrorMeasure::AllPixels => "rel_rmse",
            ErrorMeasure::Surfaces => "rel_rmse_surfaces",
        }
    }
}

/// For a run of another method: how long `path` takes to reach the same
/// error on the same scene, and the ratio (path time ÷ run time).
#[derive(Clone, Debug, PartialEq)]
pub struct EqualError {
    pub scene: String,
    pub method: String,
    pub settings: String,
    /// The backend of the run and of the `path` runs it is held against.
    pub backend: String,
    pub measure: ErrorMeasure,
    pub error: f64,
    pub seconds: f64,
    /// `None` where the path sweep does not bracket the error.
    pub path_seconds: Option<f64>,
}

impl EqualError {
    pub fn speedup(&self) -> Option<f64> {
        self.path_seconds.map(|p| p / self.seconds)
    }
}

/// [`EqualError`] under `measure` for every run whose method is not `path`
/// (and that has the measure), against the `path` runs of its scene and
/// backend that vary only the sample count (`spp=…` or the defaults), or
/// all those `path` runs when there are none such. Runs without `path` runs
/// of their scene and backend have no rows.
pub fn equal_error_table(rows: &[BenchRow], measure: ErrorMeasure) -> Vec<EqualError> {
    let path_curve = |of: &BenchRow| -> Vec<(f64, f64)> {
        let runs: Vec<&BenchRow> = rows
            .iter()
            .filter(|p| p.method == "path" && p.scene == of.scene && p.backend == of.backend)
            .collect();
        let spp: Vec<&BenchRow> = runs
            .iter()
            .copied()
            .filter(|p| p.settings.starts_with("spp=") || p.settings == "default")
            .collect();
        let chosen = if spp.is_empty() { runs } else { spp };
        chosen
            .iter()
            .filter_map(|p| Some((p.seconds, measure.of(p)?)))
            .collect()
    };
    rows.iter()
        .filter(|r| r.method != "path")
        .filter_map(|r| {
            let error = measure.of(r)?;
            let path = path_curve(r);
            if path.is_empty() {
                return None; // Nothing to compare with on this scene.
            }
            Some(EqualError {
                scene: r.scene.clone(),
                method: r.method.clone(),
                settings: r.settings.clone(),
                backend: r.backend.clone(),
                measure,
                error,
                seconds: r.seconds,
                path_seconds: interpolate_time_at_error(&path, error),
            })
        })
        .collect()
}

/// Lines for people: one per [`EqualError`].
pub fn equal_error_text(table: &[EqualError]) -> String {
    let mut out = String::new();
    let several_backends = table.iter().any(|e| e.backend != table[0].backend);
    for e in table {
        let on = if several_backends {
            format!(" on {}", e.backend)
        } else {
            String::new()
        };
        let what = format!(
            "{} {} {}{on}: {} {:.5} in {:.3} s",
            e.scene,
            e.method,
            e.settings,
            e.measure.name(),
            e.error,
            e.seconds
        );
        let _ = match (e.path_seconds, e.speedup()) {
            (Some(p), Some(x)) => writeln!(
                out,
                "{what}; path needs {p:.3} s for it → {x:.2}× faster than path"
            ),
            _ => writeln!(
                out,
                "{what}; the path sweep does not bracket this error (widen it)"
            ),
        };
    }
    out
}

/// Lines for people: one per run with [`BenchRow::next_error`].
pub fn estimate_error_text(rows: &[BenchRow]) -> String {
    let mut out = String::new();
    for r in rows {
        let Some(e) = r.next_error else { continue };
        let _ = writeln!(
            out,
            "{} {} {}: {} records: estimate {}, constant E {}",
            r.scene,
            r.method,
            r.settings,
            e.records,
            percent(e.estimate),
            percent(e.constant)
        );
    }
    out
}

// ---------------------------------------------------------------- backends

/// Pairs of the same run (scene, method, settings) on the bench's first
/// backend and on each later one (`--backends cpu,gpu`), in row order:
/// the ratio of their times is read off one invocation.
pub fn backend_pairs(rows: &[BenchRow]) -> Vec<(&BenchRow, &BenchRow)> {
    let Some(first) = rows.first().map(|r| &r.backend) else {
        return Vec::new();
    };
    rows.iter()
        .filter(|r| r.backend != *first)
        .filter_map(|other| {
            let base = rows.iter().find(|r| {
                r.backend == *first
                    && (&r.scene, &r.method, &r.settings)
                        == (&other.scene, &other.method, &other.settings)
            })?;
            Some((base, other))
        })
        .collect()
}

/// Lines for people: one per [`backend_pairs`] pair, the later backend's
/// speed-up over the first (first's seconds ÷ its own) and the change of
/// the error, which the backends should leave alone (the same hits).
pub fn backend_text(rows: &[BenchRow]) -> String {
    let mut out = String::new();
    for (base, other) in backend_pairs(rows) {
        let _ = writeln!(
            out,
            "{} {} {}: {} {:.3} s against {} {:.3} s → {:.2}× (rel_rmse {:.5} against {:.5})",
            other.scene,
            other.method,
            other.settings,
            other.backend,
            other.seconds,
            base.backend,
            base.seconds,
            base.seconds / other.seconds,
            other.rel_rmse,
            base.rel_rmse,
        );
    }
    out
}

// ---------------------------------------------------------------- memory

/// Peak resident set size of this process in MB (`VmHWM` of
/// /proc/self/status); `None` where there is no such file.
pub fn peak_memory_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status_kb(&status, "VmHWM:").map(|kb| kb as f64 / 1024.0)
}

fn status_kb(status: &str, field: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with(field))?;
    line[field.len()..].split_whitespace().next()?.parse().ok()
}

/// Resets the process's peak RSS to its current RSS (Linux ≥ 4.0,
/// `echo 5 > /proc/self/clear_refs`), so that [`peak_memory_mb`] after a run
/// is that run's peak rather than the whole process's. Returns whether it
/// worked; where it does not, the figure stays the process peak so far.
pub fn reset_peak_memory() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

// ---------------------------------------------------------------- running

/// What a bench run produced.
#[derive(Clone, Debug)]
pub struct BenchReport {
    pub rows: Vec<BenchRow>,
    pub csv: PathBuf,
    pub charts: Vec<PathBuf>,
    /// Whether peak memory is per run (true) or the process peak so far.
    pub peak_mem_per_run: bool,
}

/// What `DIR/reference/<scene>/reference.json` records; a reference is
/// reused only when all of it matches.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ReferenceInfo {
    scene: String,
    /// FNV-1a of the scene file's bytes (0 for built-in scenes).
    scene_hash: u64,
    frames: [u32; 2],
    width: u32,
    height: u32,
    spp: u32,
    seed: u64,
    fps: f32,
    method: String,
    same_pattern: bool,
    /// The folder holds a light mask per frame (written since the surface
    /// error exists; an older reference is rendered again).
    #[serde(default)]
    light_masks: bool,
    /// Coverage-only camera rays of pixels on a seen light's edge, in units
    /// of `spp` (`method::pixels`; 0 in references made before the edge
    /// pixels were post-stratified, which are rendered again).
    #[serde(default)]
    edge_coverage_factor: u32,
}

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn scene_hash(source: &SceneSource) -> Result<u64> {
    match source {
        SceneSource::Builtin(_) => Ok(0),
        SceneSource::File(p) => {
            let bytes =
                std::fs::read(p).with_context(|| format!("cannot read scene {}", p.display()))?;
            Ok(fnv1a(&bytes))
        }
    }
}

/// Runs the whole bench: references, runs, CSV, charts.
pub fn run(opts: &BenchOptions) -> Result<BenchReport> {
    if opts.scenes.is_empty() {
        bail!("no scenes to bench");
    }
    if opts.methods.is_empty() {
        bail!("no methods to bench");
    }
    if opts.frames.is_empty() {
        bail!(
            "frame range {}..{} is empty",
            opts.frames.start,
            opts.frames.end
        );
    }
    if opts.backends.is_empty() {
        bail!("no backends to bench on");
    }
    if opts.estimate_error && !opts.methods.iter().any(|m| m.method == "trc") {
        bail!("--estimate-error measures the records of trc runs, and no method is trc");
    }
    for (i, b) in opts.backends.iter().enumerate() {
        if opts.backends[..i].contains(b) {
            bail!("backend '{}' is named twice", b.name());
        }
    }
    let labels: Vec<String> = opts.scenes.iter().map(scene_label).collect();
    for (i, l) in labels.iter().enumerate() {
        if labels[..i].contains(l) {
            bail!("two scenes are both named '{l}' in file names; rename one");
        }
    }
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("cannot create output directory {}", opts.out.display()))?;
    let per_run = reset_peak_memory();
    let mut rows = Vec::new();
    let mut charts = Vec::new();
    for (source, label) in opts.scenes.iter().zip(&labels) {
        let scene_rows = bench_scene(opts, source, label, per_run)?;
        charts.extend(plot_scene(&opts.out, label, &scene_rows)?);
        rows.extend(scene_rows);
    }
    let csv = opts.out.join("bench.csv");
    std::fs::write(&csv, to_csv(&rows))
        .with_context(|| format!("cannot write {}", csv.display()))?;
    Ok(BenchReport {
        rows,
        csv,
        charts,
        peak_mem_per_run: per_run,
    })
}

fn frame_settings(opts: &BenchOptions, same_pattern: bool) -> FrameSettings {
    FrameSettings {
        width: opts.width,
        height: opts.height,
        fps: opts.fps,
        seed: opts.seed,
        same_pattern,
        ..FrameSettings::default()
    }
}

fn bench_scene(
    opts: &BenchOptions,
    source: &SceneSource,
    label: &str,
    per_run: bool,
) -> Result<Vec<BenchRow>> {
    let ref_dir = opts.out.join("reference").join(label);
    ensure_reference(opts, source, &ref_dir)?;
    let mut rows = Vec::new();
    for sweep in &opts.methods {
        for spec in sweep.runs() {
            for &backend in &opts.backends {
                let run = Run {
                    spec: &spec,
                    backend,
                    // One folder per backend only when there are several,
                    // so a one-backend bench keeps its folder names.
                    backend_in_dir: opts.backends.len() > 1,
                };
                rows.push(bench_run(opts, source, label, &run, per_run)?);
            }
        }
    }
    Ok(rows)
}

/// One run of a bench: a method's settings on one backend.
struct Run<'a> {
    spec: &'a RunSpec,
    backend: BackendChoice,
    backend_in_dir: bool,
}

impl Run<'_> {
    /// The run's folder under `runs/<scene>/`: `<method>-<settings>`, and
    /// `-<backend>` when the bench has several.
    fn folder(&self) -> String {
        let mut name = format!("{}-{}", self.spec.method, self.spec.label());
        if self.backend_in_dir {
            name = format!("{name}-{}", self.backend.name());
        }
        sanitize(&name)
    }
}

/// Renders one run of `source` into its folder and compares it with the
/// scene's reference.
fn bench_run(
    opts: &BenchOptions,
    source: &SceneSource,
    label: &str,
    run: &Run,
    per_run: bool,
) -> Result<BenchRow> {
    let spec = run.spec;
    let settings = spec.settings()?;
    let dir = opts.out.join("runs").join(label).join(run.folder());
    let ref_dir = opts.out.join("reference").join(label);
    clear_frames(&dir)?;
    let mut renderer = Renderer::new(
        source.load()?,
        settings.instantiate(),
        render::make_backend(run.backend)?,
        frame_settings(opts, opts.same_pattern),
    );
    let backend = renderer.backend().name();
    if per_run {
        reset_peak_memory();
    }
    let what = format!("{label} {} {} on {backend}", spec.method, spec.label());
    let stats = render_frames(&mut renderer, opts.frames.clone(), &dir, &what, opts.quiet)?;
    let peak_mem_mb = peak_memory_mb();
    drop(renderer);
    let cmp = metrics::compare_dirs(&ref_dir, &dir)
        .with_context(|| format!("comparing {} with {}", dir.display(), ref_dir.display()))?;
    let next_error = match &settings {
        MethodSettings::Trc(trc) if opts.estimate_error => {
            estimate_error(opts, source, run.backend, trc, &what)?
        }
        _ => None,
    };
    Ok(BenchRow {
        scene: label.into(),
        method: spec.method.clone(),
        settings: spec.label(),
        backend,
        frames: opts.frames.len() as u32,
        seconds: stats.render_time.as_secs_f64(),
        render_pass_seconds: stats.render_pass_seconds,
        rays: stats.rays,
        records: stats.records,
        peak_mem_mb,
        rel_rmse: cmp.rel_rmse,
        rel_rmse_surfaces: cmp.rel_rmse_surfaces,
        block_bias: cmp.block_bias,
        flicker: cmp.flicker,
        flicker_surfaces: cmp.flicker_surfaces,
        next_error,
    })
}

/// [`BenchRow::next_error`] of a `trc` run with `settings`: the run's frames
/// rendered again (untimed) by a `trc` the bench holds, passes driven here
/// as [`Renderer::render_frame`] drives them, and after each pass the
/// records it computed (new ones and replacements) gathered again one
/// frame after their own.
fn estimate_error(
    opts: &BenchOptions,
    source: &SceneSource,
    backend: BackendChoice,
    settings: &TrcSettings,
    what: &str,
) -> Result<Option<EstimateError>> {
    let mut renderer = Renderer::new(
        source.load()?,
        Box::new(render::NoMethod),
        render::make_backend(backend)?,
        frame_settings(opts, opts.same_pattern),
    );
    let mut trc = TemporalRadianceCaching::new(settings.clone());
    let mut measured = NextFrameMeasure::default();
    let bar = render::progress_bar(opts.frames.len() as u64, opts.quiet);
    let end = opts.frames.end;
    for frame in opts.frames.clone() {
        bar.set_message(format!("{what}: E(t0+1) estimates, frame {frame}"));
        while let Some(f) = trc.next_frame_to_prepare(frame, end) {
            renderer.with_frame_context(f, |ctx| trc.prepare_frame(ctx));
            measured.add_new(&mut renderer, &trc);
        }
        renderer.with_frame_context(frame, |ctx| trc.render_frame(ctx));
        measured.add_new(&mut renderer, &trc);
        if let Some(message) = renderer.backend().failure() {
            bail!("{what}: E(t0+1) estimates, frame {frame}: the backend failed: {message}");
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(measured.tally.summary())
}

/// The records of a `trc` measured so far, and their errors.
#[derive(Default)]
struct NextFrameMeasure {
    /// `(id, t0)` of every record measured: a replacement keeps the id of
    /// the record it replaces, at a later `t0`.
    seen: std::collections::HashSet<(crate::cache::RecordId, u32)>,
    tally: EstimateErrorTally,
}

impl NextFrameMeasure {
    /// Measures the records of `trc` not measured yet, each gathered again
    /// at its `t0 + 1`.
    fn add_new(&mut self, renderer: &mut Renderer, trc: &TemporalRadianceCaching) {
        let mut new: Vec<_> = trc
            .records()
            .iter()
            .filter(|k| self.seen.insert((k.record.id, k.record.created_frame)))
            .cloned()
            .collect();
        new.sort_by_key(|k| k.record.created_frame);
        for same_t0 in new.chunk_by(|a, b| a.record.created_frame == b.record.created_frame) {
            let t1 = same_t0[0].record.created_frame + 1;
            let actual = renderer.with_frame_context(t1, |ctx| trc.regather(ctx, same_t0));
            self.tally.add(same_t0, &actual);
        }
    }
}

/// Renders the reference of `source` into `dir` unless a matching one is
/// there already.
fn ensure_reference(opts: &BenchOptions, source: &SceneSource, dir: &Path) -> Result<()> {
    let info = ReferenceInfo {
        scene: source.to_string(),
        scene_hash: scene_hash(source)?,
        frames: [opts.frames.start, opts.frames.end],
        width: opts.width,
        height: opts.height,
        spp: opts.reference_spp,
        seed: opts.seed,
        fps: opts.fps,
        method: "path".into(),
        same_pattern: true,
        light_masks: true,
        edge_coverage_factor: frame_settings(opts, true).edge_coverage_factor,
    };
    let json = dir.join("reference.json");
    let have = std::fs::read_to_string(&json)
        .ok()
        .and_then(|s| serde_json::from_str::<ReferenceInfo>(&s).ok());
    let complete = opts
        .frames
        .clone()
        .all(|f| crate::film::frame_path(dir, f, "exr").is_file());
    if have.as_ref() == Some(&info) && complete {
        if !opts.quiet {
            eprintln!("reference {}: reusing {}", source, dir.display());
        }
        return Ok(());
    }
    // Stale or partial: start again, so no frame of another reference stays.
    let _ = std::fs::remove_file(&json);
    clear_frames(dir)?;
    if !opts.quiet {
        eprintln!(
            "reference {}: rendering frames {}..{} at {}x{}, path {} spp, same pattern → {}",
            source,
            opts.frames.start,
            opts.frames.end,
            opts.width,
            opts.height,
            opts.reference_spp,
            dir.display()
        );
    }
    let settings = MethodSettings::Path(PathSettings {
        spp: opts.reference_spp,
        ..PathSettings::default()
    });
    let mut renderer = Renderer::new(
        source.load()?,
        settings.instantiate(),
        render::make_backend(BackendChoice::Auto)?,
        frame_settings(opts, true),
    );
    let what = format!("reference {}", scene_label(source));
    render_frames(&mut renderer, opts.frames.clone(), dir, &what, opts.quiet)?;
    for frame in opts.frames.clone() {
        let mask = renderer.with_frame_context(frame, seen_lights);
        metrics::write_light_mask(
            &metrics::light_mask_path(dir, frame),
            opts.width,
            opts.height,
            &mask,
        )?;
    }
    // Written last: its presence says the frames are complete.
    std::fs::write(&json, serde_json::to_string_pretty(&info)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    Ok(())
}

/// Which pixels of the frame see a light source directly or border a pixel
/// that does (the light mask of [`metrics::light_mask_path`]): 8×8 primary
/// rays per pixel on a regular grid over its square, then a one-pixel
/// dilation, so that a rim pixel the grid misses is left out as well. An
/// emissive triangle counts from either side: leaving out a few more pixels
/// only narrows the surface error, it does not bias it.
fn seen_lights(ctx: &FrameContext) -> Vec<bool> {
    const GRID: u32 = 8;
    let (w, h) = (ctx.width, ctx.height);
    let camera = &ctx.snapshot.camera;
    let emissive = |hit: &Hit| {
        hit.is_hit() && {
            let material = ctx.snapshot.tri_material[hit.triangle as usize];
            ctx.scene.materials[material as usize].is_emissive()
        }
    };
    let mut lit = vec![false; (w * h) as usize];
    for y in 0..h {
        let rays: Vec<Ray> = (0..w * GRID * GRID)
            .map(|i| {
                let (x, s) = (i / (GRID * GRID), i % (GRID * GRID));
                let sx = (x as f32 + ((s % GRID) as f32 + 0.5) / GRID as f32) / w as f32;
                let sy = (y as f32 + ((s / GRID) as f32 + 0.5) / GRID as f32) / h as f32;
                let dir = camera.direction(sx, sy, ctx.aspect());
                Ray::new(camera.position, dir, 0.0, f32::INFINITY)
            })
            .collect();
        let mut hits = vec![Hit::MISS; rays.len()];
        ctx.backend.closest_hit(&rays, &mut hits);
        for (x, pixel_hits) in hits.chunks(GRID as usize * GRID as usize).enumerate() {
            lit[(y * w) as usize + x] = pixel_hits.iter().any(emissive);
        }
    }
    dilate(&lit, w, h)
}

/// `mask` grown by one pixel in the eight directions.
fn dilate(mask: &[bool], w: u32, h: u32) -> Vec<bool> {
    let at = |x: i64, y: i64| {
        (0..w as i64).contains(&x)
            && (0..h as i64).contains(&y)
            && mask[(y * w as i64 + x) as usize]
    };
    (0..(w * h) as i64)
        .map(|i| {
            let (x, y) = (i % w as i64, i / w as i64);
            (-1..=1).any(|dy| (-1..=1).any(|dx| at(x + dx, y + dy)))
        })
        .collect()
}

/// Creates `dir` and removes the `frame_NNNN.{exr,png}` files in it.
fn clear_frames(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create directory {}", dir.display()))?;
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))? {
        let entry = entry?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with("frame_") && (name.ends_with(".exr") || name.ends_with(".png")) {
            std::fs::remove_file(entry.path())
                .with_context(|| format!("cannot remove {}", entry.path().display()))?;
        }
    }
    Ok(())
}

struct RunStats {
    render_time: Duration,
    /// Summed "render" phases of the frames, where the method times one.
    render_pass_seconds: Option<f64>,
    rays: u64,
    /// Cache records computed over the run (0 for methods without a cache).
    records: u64,
}

/// Renders `frames` into `dir` with a progress bar; the time counts
/// rendering only, not writing files.
fn render_frames(
    renderer: &mut Renderer,
    frames: Range<u32>,
    dir: &Path,
    what: &str,
    quiet: bool,
) -> Result<RunStats> {
    let bar = render::progress_bar(frames.len() as u64, quiet);
    let rays_before = renderer.backend().ray_counts().total();
    let mut render_time = Duration::ZERO;
    let mut render_pass_seconds = None;
    let mut records = 0;
    renderer.set_frame_end(Some(frames.end));
    for frame in frames {
        bar.set_message(format!("{what}, frame {frame}"));
        let start = Instant::now();
        let film = renderer
            .try_render_frame(frame)
            .map_err(|e| anyhow::anyhow!("{what}: {e}"))?;
        render_time += start.elapsed();
        let stats = renderer.last_frame_stats();
        // Records computed: new ones and replacements at the same point (trc).
        records += stats.records_created + stats.records_replaced;
        for (_, secs) in stats
            .phase_seconds
            .iter()
            .filter(|(name, _)| name == crate::method::RENDER_PHASE)
        {
            *render_pass_seconds.get_or_insert(0.0) += secs;
        }
        crate::film::write_frame(&film, dir, frame)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(RunStats {
        render_time,
        render_pass_seconds,
        rays: renderer.backend().ray_counts().total() - rays_before,
        records,
    })
}

// ---------------------------------------------------------------- charts

/// `1234` → "1234", `0.5` → "0.5", `0.0123` → "0.0123": short tick labels.
fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Axis range covering `values` (positive, finite) with a margin on a log
/// scale; a fallback when there are none.
fn log_range(values: impl Iterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return 0.1..10.0;
    }
    // At least a factor of 4 end to end so that a single point has ticks.
    let span = (hi / lo).max(4.0);
    let pad = span.powf(0.12);
    let mid = (hi * lo).sqrt();
    let half = span.sqrt();
    (mid / half / pad)..(mid * half * pad)
}

/// Tick positions of a log axis over `range`: `(labelled, grid only)`.
/// Labelled ticks are 1, 2, 5 × 10^k, or every 1…9 × 10^k when that gives
/// fewer than three; grid lines are the other 1…9 × 10^k.
fn log_ticks(range: &Range<f64>) -> (Vec<f64>, Vec<f64>) {
    let (lo, hi) = (range.start, range.end);
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    let mut all = Vec::new();
    for k in first..=last {
        for m in 1..=9 {
            let v = f64::from(m) * 10f64.powi(k);
            if v >= lo && v <= hi {
                all.push((m, v));
            }
        }
    }
    let main: Vec<f64> = all
        .iter()
        .filter(|(m, _)| [1, 2, 5].contains(m))
        .map(|&(_, v)| v)
        .collect();
    if main.len() >= 3 {
        let grid = all
            .iter()
            .filter(|(m, _)| ![1, 2, 5].contains(m))
            .map(|&(_, v)| v)
            .collect();
        (main, grid)
    } else {
        (all.into_iter().map(|(_, v)| v).collect(), Vec::new())
    }
}

/// The method sweeps of `rows` in order of appearance: (series name, rows).
fn series(rows: &[BenchRow]) -> Vec<(String, Vec<&BenchRow>)> {
    let several_backends = rows.iter().any(|r| r.backend != rows[0].backend);
    let mut out: Vec<(String, Vec<&BenchRow>)> = Vec::new();
    for r in rows {
        let key = r.settings.split_once('=').map_or("", |(k, _)| k);
        let mut name = if key.is_empty() {
            r.method.clone()
        } else {
            format!("{} ({key})", r.method)
        };
        if several_backends {
            // "cpu" or "gpu": the backend's name up to its details.
            let kind = r.backend.split(" (").next().unwrap_or(&r.backend);
            name = format!("{name} on {kind}");
        }
        match out.iter_mut().find(|(n, _)| *n == name) {
            Some((_, v)) => v.push(r),
            None => out.push((name, vec![r])),
        }
    }
    out
}

/// Short label of a point: the swept value, or nothing for defaults.
fn point_label(r: &BenchRow) -> String {
    r.settings
        .split_once('=')
        .map_or(String::new(), |(_, v)| v.to_string())
}

/// Writes the four charts of one scene; returns their paths.
pub fn plot_scene(out: &Path, scene: &str, rows: &[BenchRow]) -> Result<Vec<PathBuf>> {
    let error = out.join(format!("{scene}_error_vs_time.svg"));
    let surfaces = out.join(format!("{scene}_surface_error_vs_time.svg"));
    let flicker = out.join(format!("{scene}_flicker_vs_time.svg"));
    let surface_flicker = out.join(format!("{scene}_surface_flicker_vs_time.svg"));
    plot(
        &error,
        &format!("{scene}: error against time"),
        "relative RMSE against the reference",
        rows,
        |r| Some(r.rel_rmse),
    )?;
    plot(
        &surfaces,
        &format!("{scene}: error of lit surfaces against time"),
        "relative RMSE without the pixels at seen lights",
        rows,
        |r| r.rel_rmse_surfaces,
    )?;
    plot(
        &flicker,
        &format!("{scene}: flicker against time"),
        "flicker (RMS of frame-difference error / mean radiance)",
        rows,
        |r| r.flicker,
    )?;
    plot(
        &surface_flicker,
        &format!("{scene}: flicker of lit surfaces against time"),
        "flicker without the pixels at seen lights",
        rows,
        |r| r.flicker_surfaces,
    )?;
    Ok(vec![error, surfaces, flicker, surface_flicker])
}

/// A chart of `y_of` against time on log axes, one line per method sweep
/// ([`series`]), written as SVG to `path`.
fn plot(
    path: &Path,
    title: &str,
    y_desc: &str,
    rows: &[BenchRow],
    y_of: impl Fn(&BenchRow) -> Option<f64>,
) -> Result<()> {
    use plotters::prelude::*;
    let draw_err = |e: &dyn std::fmt::Display| anyhow::anyhow!("drawing {}: {e}", path.display());
    let usable = |r: &&BenchRow| {
        let y = y_of(r);
        r.seconds.is_finite() && r.seconds > 0.0 && y.is_some_and(|y| y.is_finite() && y > 0.0)
    };
    let frames = rows.first().map_or(0, |r| r.frames);
    let x_range = log_range(rows.iter().filter(usable).map(|r| r.seconds));
    let y_range = log_range(rows.iter().filter(usable).filter_map(&y_of));

    let root = SVGBackend::new(path, (820, 580)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(&e))?;
    let mut chart = log_log_chart(&root, title, x_range, y_range).map_err(|e| draw_err(&e))?;
    chart
        .configure_mesh()
        .x_desc(format!(
            "render time, seconds for {frames} frame{} (log scale)",
            if frames == 1 { "" } else { "s" }
        ))
        .y_desc(format!("{y_desc} (log scale)"))
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 15))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(|e| draw_err(&e))?;

    let mut any = false;
    for (i, (name, sweep)) in series(rows).into_iter().enumerate() {
        let mut points: Vec<(f64, f64, String)> = sweep
            .iter()
            .copied()
            .filter(usable)
            .map(|r| (r.seconds, y_of(r).unwrap_or(f64::NAN), point_label(r)))
            .collect();
        if points.is_empty() {
            continue;
        }
        any = true;
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        draw_sweep(&mut chart, name, Palette99::pick(i).to_rgba(), &points)
            .map_err(|e| draw_err(&e))?;
    }
    if any {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| draw_err(&e))?;
    } else {
        root.draw(&Text::new(
            "no data (flicker needs two frames; the surface error, light masks)",
            (260, 290),
            ("sans-serif", 16),
        ))
        .map_err(|e| draw_err(&e))?;
    }
    root.present().map_err(|e| draw_err(&e))?;
    Ok(())
}

/// The SVG chart area, its axes logarithmic over the ranges, with ticks at
/// 1–2–5 steps ([`log_ticks`]).
type LogLogChart<'a> = plotters::chart::ChartContext<
    'a,
    plotters::backend::SVGBackend<'a>,
    plotters::coord::cartesian::Cartesian2d<
        plotters::coord::combinators::WithKeyPoints<plotters::coord::combinators::LogCoord<f64>>,
        plotters::coord::combinators::WithKeyPoints<plotters::coord::combinators::LogCoord<f64>>,
    >,
>;

/// Builds [`LogLogChart`] on `root` with a caption.
fn log_log_chart<'a>(
    root: &plotters::drawing::DrawingArea<
        plotters::backend::SVGBackend<'a>,
        plotters::coord::Shift,
    >,
    title: &str,
    x_range: std::ops::Range<f64>,
    y_range: std::ops::Range<f64>,
) -> Result<LogLogChart<'a>, plotters::drawing::DrawingAreaErrorKind<std::io::Error>> {
    use plotters::prelude::*;
    let (x_ticks, x_grid) = log_ticks(&x_range);
    let (y_ticks, y_grid) = log_ticks(&y_range);
    ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(18)
        .x_label_area_size(52)
        .y_label_area_size(78)
        .build_cartesian_2d(
            x_range
                .log_scale()
                .with_key_points(x_ticks)
                .with_light_points(x_grid),
            y_range
                .log_scale()
                .with_key_points(y_ticks)
                .with_light_points(y_grid),
        )
}

/// One method sweep: its points `(seconds, y, label)` joined in time
/// order, each marked and labelled with its swept value, and a legend
/// entry `name`.
fn draw_sweep(
    chart: &mut LogLogChart,
    name: String,
    color: plotters::style::RGBAColor,
    points: &[(f64, f64, String)],
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<std::io::Error>> {
    use plotters::prelude::*;
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|p| (p.0, p.1)),
            color.stroke_width(2),
        ))?
        .label(name)
        .legend(move |(x, y)| {
            EmptyElement::at((x, y))
                + PathElement::new(vec![(0, 0), (22, 0)], color.stroke_width(2))
                + Circle::new((11, 0), 4, color.filled())
        });
    chart.draw_series(points.iter().map(|(x, y, label)| {
        EmptyElement::at((*x, *y))
            + Circle::new((0, 0), 4, color.filled())
            + Text::new(label.clone(), (6, -16), ("sans-serif", 13))
    }))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_key_is_accepted() {
        for m in METHODS {
            method_settings(m.name, None).unwrap();
            for (key, example) in m.keys {
                method_settings(m.name, Some((key, example)))
                    .unwrap_or_else(|e| panic!("{}:{key}={example}: {e}", m.name));
            }
        }
    }

    /// `trc` takes `ic`'s record settings into the `ic` settings it makes
    /// its records with, while its `gradients` stays the temporal one.
    #[test]
    fn trc_takes_the_record_settings_of_ic() {
        let trc = |key, v| match method_settings("trc", Some((key, v))).unwrap() {
            MethodSettings::Trc(s) => s,
            other => panic!("{other:?}"),
        };
        let strata = trc("strata", "64x32").ic.strata;
        assert_eq!((strata.theta, strata.phi), (64, 32));
        assert_eq!(trc("max_spacing", "8").ic.max_spacing_px, 8.0);
        assert_eq!(trc("min_spacing", "3").ic.min_spacing_px, 3.0);
        let gradients = trc("gradients", "none");
        assert_eq!(gradients.gradients, TemporalGradients::None);
        assert!(gradients.ic.gradients, "spatial gradients stay on");
        assert!(matches!(
            method_settings("trc", Some(("strata", "64"))),
            Err(MethodError::BadValue { .. })
        ));
    }

    #[test]
    fn sweep_parses_and_applies_values() {
        let s = MethodSweep::parse("path:spp=4, 16,64").unwrap();
        assert_eq!(s.values, ["4", "16", "64"]);
        let spps: Vec<u32> = s
            .runs()
            .iter()
            .map(|r| {
                #[allow(unreachable_patterns)]
                match r.settings().unwrap() {
                    MethodSettings::Path(p) => p.spp,
                    other => panic!("{other:?}"),
                }
            })
            .collect();
        assert_eq!(spps, [4, 16, 64]);
        assert_eq!(s.runs()[0].label(), "spp=4");
        let d = MethodSweep::parse("path").unwrap();
        assert_eq!(d.runs().len(), 1);
        assert_eq!(d.runs()[0].label(), "default");
    }

    #[test]
    fn bad_specs_are_errors() {
        for spec in [
            "",
            ":spp=4",
            "path:spp",
            "path:=4",
            "path:spp=4,,8",
            "path:spp=0",
        ] {
            assert!(MethodSweep::parse(spec).is_err(), "{spec}");
        }
        let e = MethodSweep::parse("path:spp=lots").unwrap_err().to_string();
        assert!(e.contains("lots") && e.contains("spp"), "{e}");
    }

    #[test]
    fn status_field() {
        let s = "Name:\tx\nVmPeak:\t  2000 kB\nVmHWM:\t   1536 kB\n";
        assert_eq!(status_kb(s, "VmHWM:"), Some(1536));
        assert_eq!(status_kb(s, "VmRSS:"), None);
    }

    #[test]
    fn ticks_are_short() {
        assert_eq!(tick(1234.0), "1234");
        assert_eq!(tick(0.5), "0.5");
        assert_eq!(tick(2.0), "2");
        assert_eq!(tick(0.0123), "0.0123");
        assert_eq!(tick(0.2), "0.2");
    }

    #[test]
    fn log_ticks_label_an_axis_within_a_decade() {
        let (main, _) = log_ticks(&(1.3..4.6));
        assert_eq!(main, [2.0, 3.0, 4.0]);
        let (main, grid) = log_ticks(&(0.05..30.0));
        assert_eq!(main, [0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0]);
        assert!(grid.contains(&3.0) && !grid.contains(&2.0));
    }

    #[test]
    fn log_range_covers_points() {
        let r = log_range([0.5, 8.0].into_iter());
        assert!(r.start < 0.5 && r.end > 8.0);
        let one = log_range([3.0].into_iter());
        assert!(one.start < 3.0 && one.end > 3.0 && one.end / one.start >= 4.0);
        assert_eq!(log_range(std::iter::empty()), 0.1..10.0);
    }

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
