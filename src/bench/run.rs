//! Running a bench: each scene's reference, then every run on every
//! backend, measured against it.

use super::charts::{chart_paths, plot_scene};
use super::reference::{ensure_reference, reference_seed};
use super::seeds::{seeds_from_csv, seeds_to_csv, SeedError, SEEDS_CSV};
use super::{sanitize, scene_label, to_csv, BenchOptions, BenchRow, MethodSweep, RunSpec};
use crate::backend::gpu::{AdapterPolicy, GpuBackend};
use crate::method::trc::estimate_error::{EstimateError, EstimateErrorTally};
use crate::method::trc::{TemporalRadianceCaching, TrcSettings};
use crate::method::Method;
use crate::metrics;
use crate::render::{
    self, memory, BackendChoice, FrameSettings, MethodSettings, Renderer, SceneSource,
};
use crate::scene::Scene;
use crate::store::Store;
use crate::system_memory;
use anyhow::{bail, Context, Result};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

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
/// is that run's peak rather than the whole process's. The current RSS
/// holds what the allocator kept of earlier runs, so a run after a larger
/// one reads at least that. Returns whether it worked; where it does not,
/// the figure stays the process peak so far.
pub fn reset_peak_memory() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// What a bench run produced.
#[derive(Clone, Debug)]
pub struct BenchReport {
    pub rows: Vec<BenchRow>,
    /// `DIR/bench.csv`, where it was written.
    pub csv: Option<PathBuf>,
    /// `DIR/bench_seeds.csv` ([`SEEDS_CSV`]), where the runs were rendered
    /// at several seeds and it was written.
    pub seeds_csv: Option<PathBuf>,
    /// The charts written.
    pub charts: Vec<PathBuf>,
    /// Why each file that could not be written was not: the CSV or a
    /// scene's charts. The rows are whole all the same.
    pub unwritten: Vec<String>,
    /// Whether peak memory is per run (true) or the process peak so far.
    pub peak_mem_per_run: bool,
    /// The runs not finished, in the order they would have rendered, when
    /// [`BenchOptions::stop`] stopped the bench (the first may have been
    /// abandoned half rendered): `<scene> <method> <settings>`, with ` on
    /// <backend>` when the bench has several. Empty when it ran them all.
    pub unfinished: Vec<String>,
    /// Per row, the seconds of each round it was rendered in
    /// ([`BenchOptions::repeat`]), in round order: the row's `seconds` is
    /// their median.
    pub round_seconds: Vec<Vec<f64>>,
    /// Per row, its errors at each seed it was rendered at
    /// ([`BenchOptions::seeds`]), in seed order: the row's are their means.
    /// One for each row of a bench of one seed.
    pub seed_errors: Vec<Vec<SeedError>>,
}

/// Runs the whole bench: references, runs, CSV, charts.
pub fn run(opts: &BenchOptions) -> Result<BenchReport> {
    run_with(opts, &mut |_| {})
}

/// [`run`], calling `after_run` with each run's row as the run finishes
/// (before the next starts: setting [`BenchOptions::stop`] there stops the
/// bench between two runs). By then `bench.csv` (and `bench_seeds.csv`)
/// hold every run finished so far, so that a bench killed outright (no
/// Ctrl-C: a crash, `kill -9`, the machine going down) keeps them.
pub fn run_with(opts: &BenchOptions, after_run: &mut dyn FnMut(&BenchRow)) -> Result<BenchReport> {
    let labels = check_bench(opts)?;
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("cannot create output directory {}", opts.out.display()))?;
    remove_earlier_outputs(&opts.out, &labels)?;
    let per_run = reset_peak_memory();
    let mut rows = Vec::new();
    let mut round_seconds = Vec::new();
    let mut seed_errors = Vec::new();
    let mut charts = Vec::new();
    let mut unplotted = Vec::new();
    let mut on_row = |finished: &[BenchRow], seeds: &[Vec<SeedError>]| {
        // A file not written here is said by the last write, at the end.
        let _ = write_tables(opts, finished, seeds);
        if let Some(row) = finished.last() {
            after_run(row);
        }
    };
    for (source, label) in opts.scenes.iter().zip(&labels) {
        let scene = BenchScene {
            source,
            label,
            scene: source.load()?,
        };
        let first = rows.len();
        let measured = (&mut rows, &mut round_seconds, &mut seed_errors);
        let stopped = match bench_scene(opts, &scene, per_run, measured, &mut on_row) {
            Ok(()) => false,
            Err(e) if e.is::<Stopped>() => true,
            Err(e) => return Err(e),
        };
        // Charts of the runs finished only: none for a scene with none.
        if rows.len() > first {
            match plot_scene(&opts.out, label, &rows[first..], &seed_errors[first..]) {
                Ok(written) => charts.extend(written),
                Err(e) => unplotted.push(format!("{e:#}")),
            }
        }
        if stopped {
            break;
        }
    }
    // A file that cannot be written (a full disk, a folder in its place)
    // does not lose the measurements: they are still printed.
    let (csv, seeds_csv, mut unwritten) = write_tables(opts, &rows, &seed_errors);
    unwritten.append(&mut unplotted);
    // Rows come in the order of the runs, so those after them are the
    // ones a stop left unfinished.
    let unfinished = run_names(opts, &labels).split_off(rows.len());
    Ok(BenchReport {
        rows,
        csv,
        seeds_csv,
        charts,
        unwritten,
        peak_mem_per_run: per_run,
        unfinished,
        round_seconds,
        seed_errors,
    })
}

/// Writes `bench.csv` of `rows` into the bench's folder, and beside it
/// `bench_seeds.csv` of their `seeds` where the runs are rendered at
/// several; each whole or not at all (a temporary file renamed), so that
/// the one an earlier call wrote stays until the new one is complete.
/// Returns the paths written and why each file not written was not.
fn write_tables(
    opts: &BenchOptions,
    rows: &[BenchRow],
    seeds: &[Vec<SeedError>],
) -> (Option<PathBuf>, Option<PathBuf>, Vec<String>) {
    let mut unwritten = Vec::new();
    let mut write = |name: &str, text: String| {
        let path = opts.out.join(name);
        match crate::film::write_atomically(&path, text.as_bytes()) {
            Ok(()) => Some(path),
            Err(e) => {
                unwritten.push(format!("cannot write {e}"));
                None
            }
        }
    };
    let csv = write("bench.csv", to_csv(rows));
    let seeds_csv = (opts.seeds > 1)
        .then(|| write(SEEDS_CSV, seeds_to_csv(rows, seeds)))
        .flatten();
    (csv, seeds_csv, unwritten)
}

/// `radcache bench --replot`: reads `dir/bench.csv` that an earlier bench
/// wrote and draws its scenes' charts into `dir` again, rendering nothing
/// (the charts' drawing may have changed since, or the CSV been edited or
/// merged from several benches). The report's rows are the CSV's, in its
/// order, with their seeds' errors where `dir/bench_seeds.csv` keeps
/// them; it has no round times and writes no CSV.
pub fn replot(dir: &Path) -> Result<BenchReport> {
    let csv = dir.join("bench.csv");
    let text =
        std::fs::read_to_string(&csv).with_context(|| format!("cannot read {}", csv.display()))?;
    let rows = super::from_csv(&text).with_context(|| format!("{}", csv.display()))?;
    if rows.is_empty() {
        bail!("{} holds no run: nothing to draw", csv.display());
    }
    let mut scenes: Vec<&str> = Vec::new();
    for row in &rows {
        // The scene names chart files: a name a bench gave it, never a path.
        if row.scene.is_empty() || sanitize(&row.scene) != row.scene {
            bail!(
                "{}: scene '{}' is not a name a bench gives (letters, digits, `._=-`)",
                csv.display(),
                row.scene
            );
        }
        if !scenes.contains(&row.scene.as_str()) {
            scenes.push(&row.scene);
        }
    }
    let seed_errors = read_seed_errors(dir, &rows)?;
    let (mut charts, mut unwritten) = (Vec::new(), Vec::new());
    for scene in scenes {
        let (of_scene, seeds): (Vec<BenchRow>, Vec<Vec<SeedError>>) = (rows.iter())
            .zip(&seed_errors)
            .filter(|(r, _)| r.scene == scene)
            .map(|(r, s)| (r.clone(), s.clone()))
            .unzip();
        match plot_scene(dir, scene, &of_scene, &seeds) {
            Ok(written) => charts.extend(written),
            Err(e) => unwritten.push(format!("{e:#}")),
        }
    }
    Ok(BenchReport {
        round_seconds: vec![Vec::new(); rows.len()],
        seed_errors,
        rows,
        csv: None,
        seeds_csv: None,
        charts,
        unwritten,
        // The CSV's figures are its bench's, which said so under its own
        // tables where they were not per run: nothing to add of this
        // process, which measured none.
        peak_mem_per_run: true,
        unfinished: Vec::new(),
    })
}

/// Each of `rows`' errors at its seeds from `dir/bench_seeds.csv`
/// ([`SEEDS_CSV`]), which a bench of several seeds wrote beside
/// `bench.csv`; none for any row where there is no such file.
fn read_seed_errors(dir: &Path, rows: &[BenchRow]) -> Result<Vec<Vec<SeedError>>> {
    let path = dir.join(SEEDS_CSV);
    match std::fs::read_to_string(&path) {
        Ok(text) => seeds_from_csv(&text, rows).with_context(|| {
            format!(
                "{} (move it away to draw the charts without the seeds' bars)",
                path.display()
            )
        }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(vec![Vec::new(); rows.len()]),
        Err(e) => Err(e).with_context(|| format!("cannot read {}", path.display())),
    }
}

/// Refuses, before anything renders, a bench that cannot run or would
/// fail on the way; returns the scenes' labels.
fn check_bench(opts: &BenchOptions) -> Result<Vec<String>> {
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
    if opts.seeds == 0 {
        bail!("--seeds 0: a run is rendered at one seed at least");
    }
    let reference = reference_seed(opts.seed);
    if (0..u64::from(opts.seeds)).any(|k| opts.seed.wrapping_add(k) == reference) {
        bail!(
            "--seed {} --seeds {}: a run's seed would be the reference's own ({reference})",
            opts.seed,
            opts.seeds
        );
    }
    if opts.estimate_error && !opts.methods.iter().any(|m| m.method == "trc") {
        bail!("--estimate-error measures the records of trc runs, and no method is trc");
    }
    for (i, b) in opts.backends.iter().enumerate() {
        if opts.backends[..i].contains(b) {
            bail!("backend '{}' is named twice", b.name());
        }
    }
    // A backend that cannot be made (`gpu` with no adapter) fails the
    // bench before the reference, the longest render of all, is made.
    // `cpu` always can be, and `auto` falls back to it.
    // (The GPU backend as `render::make_backend` makes it for `gpu`.)
    if opts.backends.contains(&BackendChoice::Gpu) {
        if let Err(e) = GpuBackend::new(AdapterPolicy::AllowSoftware) {
            bail!(
                "--backends {}: the gpu backend is unavailable: {e}; nothing was rendered \
                 (leave gpu out of --backends)",
                opts.backends
                    .iter()
                    .map(|b| b.name())
                    .collect::<Vec<_>>()
                    .join(",")
            );
        }
    }
    check_backends_differ(&opts.backends)?;
    check_runs_differ(opts)?;
    let labels: Vec<String> = opts.scenes.iter().map(scene_label).collect();
    for (i, l) in labels.iter().enumerate() {
        if labels[..i].contains(l) {
            bail!("two scenes are both named '{l}' in the output's file names; name each once");
        }
    }
    // Every scene loads before any is benched: a bad one named last must
    // not cost the minutes the others take, nor one whose runs would not
    // fit in memory on its triangles. Each is loaded again when its turn
    // comes rather than kept, so that a run's peak memory holds only its
    // own scene.
    let available = opts
        .check_memory
        .then(system_memory::available_bytes)
        .flatten();
    for (source, label) in opts.scenes.iter().zip(&labels) {
        let triangles = memory::scene_triangles(&source.load()?);
        check_scene_memory(opts, label, triangles, available)?;
    }
    Ok(labels)
}

/// Removes the `bench.csv` and `bench_seeds.csv` in `out`, and the charts
/// of the scenes `labels`, that an earlier bench wrote: beside this
/// bench's runs they would describe runs it did not make, if it is
/// stopped before writing its own (a second Ctrl-C), or, for a scene it
/// finishes no run of, at all. A folder in a file's place is left, to
/// fail when written.
fn remove_earlier_outputs(out: &Path, labels: &[String]) -> Result<()> {
    let charts = labels.iter().flat_map(|l| chart_paths(out, l));
    // Also the half-written CSVs of a bench killed while it wrote them.
    crate::film::remove_stale_temporaries_of(out, &["bench.csv", SEEDS_CSV]);
    let csvs = ["bench.csv", SEEDS_CSV].map(|name| out.join(name));
    for path in csvs.into_iter().chain(charts) {
        let is_dir = std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir());
        match std::fs::remove_file(&path) {
            Err(e) if !is_dir && e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| {
                    format!(
                        "cannot remove {}, which an earlier bench wrote; nothing was rendered",
                        path.display()
                    )
                });
            }
            _ => {}
        }
    }
    Ok(())
}

/// What [`BenchOptions::stop`] abandoned: not a failure; [`run_with`]
/// reports the runs finished before it.
#[derive(Debug, thiserror::Error)]
#[error("the bench was stopped")]
struct Stopped;

/// [`Stopped`] if [`BenchOptions::stop`] is set.
fn check_stop(opts: &BenchOptions) -> Result<()> {
    match opts.stop.load(Ordering::Relaxed) {
        true => Err(Stopped.into()),
        false => Ok(()),
    }
}

/// The runs of each scene in the order they render: every run of every
/// sweep, on every backend.
fn scene_runs(opts: &BenchOptions) -> Vec<(RunSpec, BackendChoice)> {
    let specs = opts.methods.iter().flat_map(|sweep| sweep.runs());
    specs
        .flat_map(|spec| opts.backends.iter().map(move |&b| (spec.clone(), b)))
        .collect()
}

/// Every run of the bench, in the order they render, named as in
/// [`BenchReport::unfinished`].
fn run_names(opts: &BenchOptions, labels: &[String]) -> Vec<String> {
    let runs = scene_runs(opts);
    let several = opts.backends.len() > 1;
    let name = |label: &String, (spec, backend): &(RunSpec, BackendChoice)| {
        let on = several.then(|| format!(" on {}", backend.name()));
        format!(
            "{label} {} {}{}",
            spec.method,
            spec.label(),
            on.unwrap_or_default()
        )
    };
    (labels.iter())
        .flat_map(|label| runs.iter().map(move |run| name(label, run)))
        .collect()
}

/// Refuses two backends that are one here: `auto` picks `cpu` where no
/// GPU is, and `gpu` where one is, and the two would be benched twice
/// under one name. (`cpu,cpu` is refused before.)
fn check_backends_differ(backends: &[BackendChoice]) -> Result<()> {
    if backends.len() < 2 || !backends.contains(&BackendChoice::Auto) {
        return Ok(());
    }
    let names = (backends.iter())
        .map(|&b| Ok((b, render::make_backend(b)?.name())))
        .collect::<Result<Vec<_>>>()?;
    for (i, (b, name)) in names.iter().enumerate() {
        if let Some((twin, _)) = names[..i].iter().find(|(_, n)| n == name) {
            bail!(
                "--backends: {} and {} are the same backend on this machine ({name}); name it once",
                twin.name(),
                b.name()
            );
        }
    }
    Ok(())
}

/// Refuses a run that `--methods` gives twice, by its settings, not their
/// spelling (`spp=2,02` is one run twice): it would be rendered twice
/// and shown as two identical rows.
fn check_runs_differ(opts: &BenchOptions) -> Result<()> {
    let mut seen: Vec<(String, MethodSettings, String)> = Vec::new();
    for spec in opts.methods.iter().flat_map(MethodSweep::runs) {
        let settings = spec.settings()?;
        let label = spec.label();
        if let Some((_, _, first)) = seen
            .iter()
            .find(|(method, s, _)| *method == spec.method && *s == settings)
        {
            bail!(
                "--methods gives the run {} {label} twice (as {first} too: the same settings); \
                 name each run once",
                spec.method
            );
        }
        seen.push((spec.method.clone(), settings, label));
    }
    Ok(())
}

/// Refuses the bench where one of its runs on scene `label`, of
/// `triangles` triangles, has an estimated peak memory over `available`
/// bytes (`None`: unknown, or not checked). The scene's reference, a `path`
/// render of the same size, needs no more than any run.
fn check_scene_memory(
    opts: &BenchOptions,
    label: &str,
    triangles: u64,
    available: Option<u64>,
) -> Result<()> {
    if available.is_none() {
        return Ok(());
    }
    for spec in opts.methods.iter().flat_map(MethodSweep::runs) {
        let size = (opts.width, opts.height);
        memory::check_fits(&spec.settings()?, size, triangles, available).map_err(|too_large| {
            anyhow::anyhow!(
                "{too_large}; for {} {} on scene {label} ({triangles} triangles), bench a \
                 smaller --size, or pass --no-memory-check to try anyway",
                spec.method,
                spec.label()
            )
        })?;
    }
    Ok(())
}

pub(super) fn frame_settings(opts: &BenchOptions, same_pattern: bool) -> FrameSettings {
    FrameSettings {
        width: opts.width,
        height: opts.height,
        fps: opts.fps,
        seed: opts.seed,
        same_pattern,
        ..FrameSettings::default()
    }
}

/// A scene being benched: where it came from, its name in the output's
/// file names, and the scene itself, loaded once for its reference and
/// every run.
pub(super) struct BenchScene<'a> {
    pub source: &'a SceneSource,
    pub label: &'a str,
    pub scene: Scene,
}

/// What [`bench_scene`] calls as each row is finished: with the rows
/// finished so far, the new one last, and their seeds' errors.
type RowsFinished<'a> = dyn FnMut(&[BenchRow], &[Vec<SeedError>]) + 'a;

/// Benches `scene`: its reference, then its runs, each row pushed onto
/// `rows` (with its rounds' seconds onto `rounds`) as its run finishes;
/// [`Stopped`] where [`BenchOptions::stop`] stopped it. With several
/// rounds ([`BenchOptions::repeat`]) the later rounds render every run
/// again for its time alone, and the rows (their times the medians of the
/// rounds done) are finished once the rounds are, or a stop ends them.
/// With several seeds ([`BenchOptions::seeds`]) the first round renders
/// each run at every seed, its row the means of their errors
/// ([`more_seeds`]), each seed's pushed onto `seed_errors`. As each row
/// is finished, `after_run` is given the rows finished so far (every
/// scene's).
fn bench_scene(
    opts: &BenchOptions,
    scene: &BenchScene,
    per_run: bool,
    (rows, rounds, seed_errors): (
        &mut Vec<BenchRow>,
        &mut Vec<Vec<f64>>,
        &mut Vec<Vec<SeedError>>,
    ),
    after_run: &mut RowsFinished,
) -> Result<()> {
    check_stop(opts)?;
    let ref_dir = opts.out.join("reference").join(scene.label);
    ensure_reference(opts, scene, &ref_dir)?;
    let first = rows.len();
    let mut times: Vec<Vec<RunTime>> = Vec::new();
    let runs = scene_runs(opts);
    let mut round = |r: u32, times: &mut Vec<Vec<RunTime>>| -> Result<()> {
        for (i, (spec, backend)) in runs.iter().enumerate() {
            check_stop(opts)?;
            let run = Run {
                spec,
                backend: *backend,
                // One folder per backend only when there are several,
                // so a one-backend bench keeps its folder names.
                backend_in_dir: opts.backends.len() > 1,
                seed: opts.seed,
            };
            if r > 0 {
                times[i].push(time_run(opts, scene, &run, rows[first + i].rays)?);
                continue;
            }
            let mut row = bench_run(opts, scene, &run, per_run)?;
            // A stop among the later seeds leaves the run unfinished:
            // nothing of it is pushed, so `times` stays beside `rows`.
            let at_seeds = more_seeds(opts, scene, &run, &mut row)?;
            times.push(vec![RunTime::of(&row)]);
            seed_errors.push(at_seeds);
            rows.push(row);
            if opts.repeat <= 1 {
                after_run(rows, seed_errors);
            }
        }
        Ok(())
    };
    let done = (0..opts.repeat.max(1)).try_for_each(|r| round(r, &mut times));
    for (i, times) in times.iter().enumerate() {
        RunTime::median_into(times, &mut rows[first + i]);
        rounds.push(times.iter().map(|t| t.seconds).collect());
        if opts.repeat > 1 {
            after_run(&rows[..=first + i], &seed_errors[..=first + i]);
        }
    }
    done
}

/// A run's times in one round.
#[derive(Clone, Copy)]
struct RunTime {
    seconds: f64,
    render_pass_seconds: Option<f64>,
}

impl RunTime {
    fn of(row: &BenchRow) -> Self {
        RunTime {
            seconds: row.seconds,
            render_pass_seconds: row.render_pass_seconds,
        }
    }

    /// Sets `row`'s times to the medians of `times` (each time its own
    /// median: the render pass's may come from another round).
    fn median_into(times: &[RunTime], row: &mut BenchRow) {
        row.seconds = median(times.iter().map(|t| t.seconds));
        let passes: Option<Vec<f64>> = times.iter().map(|t| t.render_pass_seconds).collect();
        row.render_pass_seconds = passes.map(|p| median(p.into_iter()));
    }
}

/// The median of `values` (the mean of the middle two of an even count);
/// NaN for none.
fn median(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

/// One run of a bench: a method's settings on one backend.
struct Run<'a> {
    spec: &'a RunSpec,
    backend: BackendChoice,
    backend_in_dir: bool,
    /// The seed its frames are rendered with.
    seed: u64,
}

impl Run<'_> {
    /// Where its frames go: `runs/<scene>/<folder>/`, and in it
    /// `seed-<seed>/` for a seed after the bench's first
    /// ([`BenchOptions::seeds`]).
    fn dir(&self, opts: &BenchOptions, label: &str) -> PathBuf {
        let dir = opts.out.join("runs").join(label).join(self.folder());
        match self.seed == opts.seed {
            true => dir,
            false => dir.join(format!("seed-{}", self.seed)),
        }
    }

    /// The run's folder under `runs/<scene>/`: `<method>-<settings>`, and
    /// `-<backend>` when the bench has several.
    fn folder(&self) -> String {
        Run::folder_of(self.spec, self.backend_in_dir.then_some(self.backend))
    }

    /// [`Run::folder`] of `spec`, with `backend` in the name if given.
    fn folder_of(spec: &RunSpec, backend: Option<BackendChoice>) -> String {
        let mut name = format!("{}-{}", spec.method, spec.label());
        if let Some(backend) = backend {
            name = format!("{name}-{}", backend.name());
        }
        sanitize(&name)
    }
}

/// Renders one run of `scene` into its folder and compares it with the
/// scene's reference.
fn bench_run(
    opts: &BenchOptions,
    scene: &BenchScene,
    run: &Run,
    per_run: bool,
) -> Result<BenchRow> {
    let (label, spec) = (scene.label, run.spec);
    let settings = spec.settings()?;
    let dir = run.dir(opts, label);
    let ref_dir = opts.out.join("reference").join(label);
    let Rendered {
        stats,
        backend,
        what,
        peak_mem_mb,
    } = render_run(opts, scene, run, (per_run, true))?;
    let cmp = metrics::compare_dirs(&ref_dir, &dir)
        .with_context(|| format!("comparing {} with {}", dir.display(), ref_dir.display()))?;
    let (next_error, store_bytes) = untimed_measures(opts, scene, run, &settings, &dir, &what)?;
    say_run_done(
        opts,
        &what,
        stats.render_time.as_secs_f64(),
        Some(cmp.rel_rmse),
    );
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
        store_bytes,
        rel_rmse: cmp.rel_rmse,
        rel_rmse_surfaces: cmp.rel_rmse_surfaces,
        block_bias: cmp.block_bias,
        flicker: cmp.flicker,
        flicker_surfaces: cmp.flicker_surfaces,
        next_error,
    })
}

/// `run` (rendered at the bench's first seed into `row`) rendered at the
/// bench's other seeds ([`BenchOptions::seeds`]) and compared with the
/// same reference: `row`'s errors and records become their means over
/// all seeds; returns each seed's errors, the first seed's first.
fn more_seeds(
    opts: &BenchOptions,
    scene: &BenchScene,
    run: &Run,
    row: &mut BenchRow,
) -> Result<Vec<SeedError>> {
    let mut seeds = vec![SeedError::of_row(run.seed, row)];
    if opts.seeds <= 1 {
        return Ok(seeds);
    }
    let ref_dir = opts.out.join("reference").join(scene.label);
    let mut records = row.records;
    for seed in (1..u64::from(opts.seeds)).map(|k| run.seed.wrapping_add(k)) {
        check_stop(opts)?;
        let at_seed = Run { seed, ..*run };
        let dir = at_seed.dir(opts, scene.label);
        let rendered = render_run(opts, scene, &at_seed, (false, true))?;
        let cmp = metrics::compare_dirs(&ref_dir, &dir)
            .with_context(|| format!("comparing {} with {}", dir.display(), ref_dir.display()))?;
        let seconds = rendered.stats.render_time.as_secs_f64();
        let what = format!("{} (seed {seed})", rendered.what);
        say_run_done(opts, &what, seconds, Some(cmp.rel_rmse));
        records += rendered.stats.records;
        seeds.push(SeedError::of_comparison(seed, &cmp));
    }
    SeedError::means_into(&seeds, row);
    row.records = (records as f64 / seeds.len() as f64).round() as u64;
    Ok(seeds)
}

/// A run rendered into its folder.
struct Rendered {
    stats: RunStats,
    /// The backend, as it names itself.
    backend: String,
    /// The run's name in progress messages.
    what: String,
    peak_mem_mb: Option<f64>,
}

/// Renders `run` of `scene`, timed, into its folder where `write` says
/// (`per_run`: its peak memory its own).
fn render_run(
    opts: &BenchOptions,
    scene: &BenchScene,
    run: &Run,
    (per_run, write): (bool, bool),
) -> Result<Rendered> {
    let (label, spec) = (scene.label, run.spec);
    let dir = run.dir(opts, label);
    if write {
        clear_frames(&dir)?;
    }
    let mut renderer = Renderer::new(
        scene.scene.clone(),
        spec.settings()?.instantiate(),
        render::make_backend(run.backend)?,
        FrameSettings {
            seed: run.seed,
            ..frame_settings(opts, opts.same_pattern)
        },
    );
    renderer.set_abandon_flag(opts.stop.clone());
    let backend = renderer.backend().name();
    if per_run {
        reset_peak_memory();
    }
    let what = format!("{label} {} {} on {backend}", spec.method, spec.label());
    let dir = write.then_some(dir.as_path());
    let stats = render_frames(&mut renderer, opts.frames.clone(), dir, &what, opts.quiet)?;
    Ok(Rendered {
        stats,
        backend,
        what,
        peak_mem_mb: peak_memory_mb(),
    })
}

/// `run` rendered again for its time alone (a later round of
/// [`BenchOptions::repeat`]), its frames not written: the first round's,
/// whose `rays` it traces again, are the same.
fn time_run(opts: &BenchOptions, scene: &BenchScene, run: &Run, rays: u64) -> Result<RunTime> {
    let Rendered { stats, what, .. } = render_run(opts, scene, run, (false, false))?;
    debug_assert_eq!(stats.rays, rays, "{what}: another round traced other rays");
    let seconds = stats.render_time.as_secs_f64();
    say_run_done(opts, &format!("{what} (again)"), seconds, None);
    Ok(RunTime {
        seconds,
        render_pass_seconds: stats.render_pass_seconds,
    })
}

/// Off a terminal (a log, `nohup`, CI), where the bars are not drawn, a
/// line a finished run, so that a bench of hours is seen to go on (as
/// `render` says each frame); on a terminal its bar shows it, and `quiet`
/// says nothing.
fn say_run_done(opts: &BenchOptions, what: &str, seconds: f64, rel_rmse: Option<f64>) {
    use std::io::{IsTerminal, Write};
    if opts.quiet || std::io::stderr().is_terminal() {
        return;
    }
    let error = rel_rmse.map_or(String::new(), |e| format!(", relative RMSE {e:.5}"));
    let line = format!("bench: {what}: {seconds:.3} s{error}");
    // Progress is not worth failing (or panicking) over a closed stderr.
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// What the options ask to measure in untimed passes after a run:
/// [`BenchRow::next_error`] (`trc` runs) and [`BenchRow::store_bytes`].
fn untimed_measures(
    opts: &BenchOptions,
    scene: &BenchScene,
    run: &Run,
    settings: &MethodSettings,
    dir: &Path,
    what: &str,
) -> Result<(Option<EstimateError>, Option<u64>)> {
    let next_error = match settings {
        MethodSettings::Trc(trc) if opts.estimate_error => {
            estimate_error(opts, scene, run.backend, trc, what)?
        }
        _ => None,
    };
    let store_bytes = opts
        .store_size
        .then(|| store_size(opts, scene, run.backend, settings, dir, what))
        .transpose()?;
    Ok((next_error, store_bytes))
}

/// [`BenchRow::next_error`] of a `trc` run with `settings`: the run's frames
/// rendered again (untimed) by a `trc` the bench holds, passes driven here
/// as [`Renderer::render_frame`] drives them, and after each pass the
/// records it computed (new ones and replacements) gathered again one
/// frame after their own.
fn estimate_error(
    opts: &BenchOptions,
    scene: &BenchScene,
    backend: BackendChoice,
    settings: &TrcSettings,
    what: &str,
) -> Result<Option<EstimateError>> {
    let mut renderer = Renderer::new(
        scene.scene.clone(),
        Box::new(render::NoMethod),
        render::make_backend(backend)?,
        frame_settings(opts, opts.same_pattern),
    );
    renderer.set_abandon_flag(opts.stop.clone());
    let mut trc = TemporalRadianceCaching::new(settings.clone());
    let mut measured = NextFrameMeasure {
        seen: Default::default(),
        tally: EstimateErrorTally::new(settings.temporal_accuracy, settings.max_life),
    };
    let bar = render::progress_bar(opts.frames.len() as u64, opts.quiet);
    let heartbeat = render::Heartbeat::for_logs(opts.quiet);
    heartbeat.begin(format!("bench: {what}: E(t0+1) estimates still running"));
    let end = opts.frames.end;
    for frame in opts.frames.clone() {
        bar.set_message(format!("{what}: E(t0+1) estimates, frame {frame}"));
        while let Some(f) = trc.next_frame_to_prepare(frame, end) {
            renderer.with_frame_context(f, |ctx| trc.prepare_frame(ctx));
            measured.add_new(&mut renderer, &trc);
        }
        renderer.with_frame_context(frame, |ctx| trc.render_frame(ctx));
        if renderer.abandoned() {
            bar.finish_and_clear();
            return Err(Stopped.into()); // Half measured: no figure.
        }
        measured.add_new(&mut renderer, &trc);
        if let Some(message) = renderer.backend().failure() {
            bail!("{what}: E(t0+1) estimates, frame {frame}: the backend failed: {message}");
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(measured.tally.summary())
}

/// [`BenchRow::store_bytes`] of a run with `settings`: its frames rendered
/// again (untimed, the same deterministic frames into the run's folder
/// `dir`) as a job of a new store in `dir/store`, as `radcache render
/// --job` would, and the bytes of the store's files once it is closed.
fn store_size(
    opts: &BenchOptions,
    scene: &BenchScene,
    backend: BackendChoice,
    settings: &MethodSettings,
    dir: &Path,
    what: &str,
) -> Result<u64> {
    let path = dir.join("store");
    if path.exists() {
        std::fs::remove_dir_all(&path)
            .with_context(|| format!("cannot remove the old store {}", path.display()))?;
    }
    let frame_settings = frame_settings(opts, opts.same_pattern);
    let store = Store::open(&path)?;
    let spec = render::job_spec(
        "bench",
        scene.source,
        settings,
        &frame_settings,
        opts.frames.clone(),
    )?;
    let mut job = render::StoreJob {
        job: store.begin_job(&spec, false)?,
        store: &store,
    };
    let mut renderer = Renderer::new(
        scene.scene.clone(),
        settings.instantiate(),
        render::make_backend(backend)?,
        frame_settings,
    );
    renderer.set_abandon_flag(opts.stop.clone());
    // A bar on a terminal, as the bench's other steps show; elsewhere
    // nothing, as they show (not the per-frame lines of `render`).
    let quiet = opts.quiet || !std::io::IsTerminal::is_terminal(&std::io::stderr());
    render::render_job_to_dir(
        &mut renderer,
        opts.frames.clone(),
        dir,
        quiet,
        Some(&mut job),
    )
    .with_context(|| format!("{what}: rendering into the store {}", path.display()))?;
    if renderer.abandoned() {
        return Err(Stopped.into()); // Frames missing: no size.
    }
    // Measured closed: sled sizes its files as it flushes and reopens.
    drop(job);
    drop(store);
    files_bytes(&path)
}

/// Bytes of the files under `dir` and its subfolders.
fn files_bytes(dir: &Path) -> Result<u64> {
    let mut total = 0;
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))? {
        let entry = entry?;
        let meta = entry.metadata()?;
        total += if meta.is_dir() {
            files_bytes(&entry.path())?
        } else {
            meta.len()
        };
    }
    Ok(total)
}

/// The records of a `trc` measured so far, and their errors.
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

/// Creates `dir` and removes the `frame_NNNN.{exr,png}` files in it.
pub(super) fn clear_frames(dir: &Path) -> Result<()> {
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

pub(super) struct RunStats {
    render_time: Duration,
    /// Summed "render" phases of the frames, where the method times one.
    render_pass_seconds: Option<f64>,
    rays: u64,
    /// Cache records computed over the run (0 for methods without a cache).
    records: u64,
}

/// Renders `frames` into `dir` (`None`: not written, a later round of
/// [`BenchOptions::repeat`]) with a progress bar (off a terminal, a line
/// every half minute the run lasts); the time counts rendering only, not
/// writing files. [`Stopped`] where the renderer's abandon flag
/// ([`BenchOptions::stop`]) abandoned a frame, which is not written, and
/// the frames written before it are removed: a folder holds a whole run
/// (or reference) or none of it, never a start that looks like one.
pub(super) fn render_frames(
    renderer: &mut Renderer,
    frames: Range<u32>,
    dir: Option<&Path>,
    what: &str,
    quiet: bool,
) -> Result<RunStats> {
    let bar = render::progress_bar(frames.len() as u64, quiet);
    let heartbeat = render::Heartbeat::for_logs(quiet);
    heartbeat.begin(format!("bench: {what} still running"));
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
        if renderer.abandoned() {
            bar.finish_and_clear();
            if let Some(dir) = dir {
                clear_frames(dir)?;
            }
            return Err(Stopped.into());
        }
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
        if let Some(dir) = dir {
            crate::film::write_frame(&film, dir, frame)?;
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The median of an odd count is its middle value, of an even count
    /// the mean of the middle two, whatever the order; of none NaN.
    #[test]
    fn median_of_rounds() {
        assert_eq!(median([3.0, 1.0, 2.0].into_iter()), 2.0);
        assert_eq!(median([4.0, 1.0, 3.0, 2.0].into_iter()), 2.5);
        assert_eq!(median([7.5].into_iter()), 7.5);
        assert!(median(std::iter::empty()).is_nan());
    }

    #[test]
    fn status_field() {
        let s = "Name:\tx\nVmPeak:\t  2000 kB\nVmHWM:\t   1536 kB\n";
        assert_eq!(status_kb(s, "VmHWM:"), Some(1536));
        assert_eq!(status_kb(s, "VmRSS:"), None);
    }

    /// A run is checked on its scene's triangles: one that fits on an
    /// empty scene is refused, naming the run and the scene, on a scene of
    /// a million triangles; nothing is refused where the memory is unknown.
    #[test]
    fn a_run_is_refused_on_its_scene_triangles() {
        let opts = BenchOptions {
            methods: vec![MethodSweep::parse("path:spp=1,4").unwrap()],
            width: 64,
            height: 64,
            ..BenchOptions::default()
        };
        let path = opts.methods[0].runs()[1].settings().unwrap();
        let empty = memory::peak_bytes(&path, 64, 64, 0);
        let million = memory::peak_bytes(&path, 64, 64, 1_000_000);
        assert!(million > empty + (100 << 20), "{empty} {million}");
        check_scene_memory(&opts, "big", 0, Some(empty)).unwrap();
        let err = check_scene_memory(&opts, "big", 1_000_000, Some(empty))
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("a 64x64 path render at 1 spp needs at least"),
            "{err}"
        );
        assert!(
            err.ends_with(
                "is available; for path spp=1 on scene big (1000000 triangles), bench a \
                 smaller --size, or pass --no-memory-check to try anyway"
            ),
            "{err}"
        );
        check_scene_memory(&opts, "big", 1_000_000, Some(million)).unwrap();
        check_scene_memory(&opts, "big", u64::MAX, None).unwrap();
    }
}
