//! What the bench prints and writes: `bench.csv`, the terminal table, the
//! speed-up over `path` at equal error, TRC Table 1 per `trc` run, and
//! the speed-up of each backend over the first.

use crate::method::trc::estimate_error::{percent, EstimateError};
use std::fmt::Write as _;

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
    /// Of `seconds`, the time of the render pass of `ic`, `trc`, `tcg` (shared) or `movies`
    /// (their [`crate::method::RENDER_PHASE`]: direct light, cache lookups, glossy lobes);
    /// the rest is the method's own work on its records. `None` for
    /// methods without a cache.
    pub render_pass_seconds: Option<f64>,
    pub rays: u64,
    pub records: u64,
    /// Peak resident memory of the process during the run (MB), where the
    /// platform tells it.
    pub peak_mem_mb: Option<f64>,
    /// With [`super::BenchOptions::store_size`]: bytes of the files of the
    /// run's store once closed (sled's files and the sample log: records,
    /// their samples, the frames' EXR and the carried state).
    pub store_bytes: Option<u64>,
    pub rel_rmse: f64,
    /// Relative RMSE without the pixels at directly seen lights
    /// ([`crate::metrics::CompareReport::rel_rmse_surfaces`]).
    pub rel_rmse_surfaces: Option<f64>,
    pub block_bias: f64,
    /// `None` with a single frame.
    pub flicker: Option<f64>,
    /// Flicker without the pixels at directly seen lights
    /// ([`crate::metrics::CompareReport::flicker_surfaces`]).
    pub flicker_surfaces: Option<f64>,
    /// With [`super::BenchOptions::estimate_error`], for `trc` runs: the error of
    /// the `E(t0+1)` estimate of the records the run computed, against
    /// `E(t0+1)` gathered again (TRC Table 1). Records of the run's last
    /// frame are measured too (their `t0 + 1` is past the range, but a
    /// frame of the scene all the same).
    pub next_error: Option<EstimateError>,
}

/// `bench.csv`'s header line.
pub const CSV_HEADER: &str =
    "scene,method,settings,backend,frames,seconds,render_pass_seconds,rays,records,peak_mem_mb,rel_rmse,rel_rmse_surfaces,block_bias,flicker,flicker_surfaces,\
estimated_records,estimate_err_mean,estimate_err_median,constant_err_mean,constant_err_median,\
estimate_lifespan_mean,actual_lifespan_mean,store_bytes";

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

pub(super) fn opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or(String::new(), |v| format!("{v:.decimals$}"))
}

/// The seven CSV fields of [`BenchRow::next_error`], empty where not measured.
fn next_error_fields(e: Option<EstimateError>) -> String {
    match e {
        Some(e) => format!(
            "{},{:.6},{:.6},{:.6},{:.6},{:.3},{:.3}",
            e.records,
            e.estimate.0,
            e.estimate.1,
            e.constant.0,
            e.constant.1,
            e.lifespan.0,
            e.lifespan.1
        ),
        None => ",,,,,,".into(),
    }
}

/// The CSV text: [`CSV_HEADER`] and one line per row. Missing values
/// (flicker of a single frame, memory where unknown) are empty fields.
pub fn to_csv(rows: &[BenchRow]) -> String {
    let mut out = format!("{CSV_HEADER}\n");
    for r in rows {
        let _ = writeln!(
            out,
            "{},{},{:.6},{},{},{},{},{:.6},{},{:.6},{},{},{},{}",
            run_fields(r),
            r.frames,
            r.seconds,
            opt(r.render_pass_seconds, 6),
            r.rays,
            r.records,
            opt(r.peak_mem_mb, 1),
            r.rel_rmse,
            opt(r.rel_rmse_surfaces, 6),
            r.block_bias,
            opt(r.flicker, 6),
            opt(r.flicker_surfaces, 6),
            next_error_fields(r.next_error),
            r.store_bytes.map_or(String::new(), |b| b.to_string()),
        );
    }
    out
}

/// The rows of a `bench.csv` that [`to_csv`] wrote, for `radcache bench
/// --replot` (read by the `csv` crate: quoted fields may hold commas,
/// quotes and newlines, as [`to_csv`] writes them). Its first line must
/// be [`CSV_HEADER`] (a CSV of another version is refused rather than read
/// into the wrong fields); a field that does not read is an error naming
/// its line and column.
pub fn from_csv(text: &str) -> anyhow::Result<Vec<BenchRow>> {
    let lines = csv_lines(text, CSV_HEADER)?;
    (lines.into_iter())
        .map(|(line, fields)| row_of(&fields).map_err(|e| anyhow::anyhow!("line {line}: {e}")))
        .collect()
}

/// The lines after the first of a CSV that this build wrote with `header`,
/// each as (its line number, its fields), read by the `csv` crate; an
/// error where the first line is not `header` (a file of another version
/// is refused rather than read into the wrong fields).
pub(super) fn csv_lines(text: &str, header: &str) -> anyhow::Result<Vec<(u64, Vec<String>)>> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(text.as_bytes());
    let mut records = reader.records();
    let first = records.next().transpose().map_err(csv_error)?;
    if first
        .as_ref()
        .is_none_or(|h| h.iter().ne(header.split(',')))
    {
        anyhow::bail!(
            "line 1 is not the header this build writes (a file of another version?): \
             expected {header}"
        );
    }
    let mut lines = Vec::new();
    for record in records {
        let record = record.map_err(csv_error)?;
        let line = record.position().map_or(0, |p| p.line());
        lines.push((line, record.iter().map(str::to_string).collect()));
    }
    Ok(lines)
}

/// The four fields that name a row's run in the CSVs,
/// `scene,method,settings,backend`, quoted where they must be.
pub(super) fn run_fields(r: &BenchRow) -> String {
    [&r.scene, &r.method, &r.settings, &r.backend]
        .map(|f| csv_field(f))
        .join(",")
}

/// A CSV reading error as the `csv` crate says it (it names the line).
fn csv_error(e: csv::Error) -> anyhow::Error {
    anyhow::anyhow!("{e}")
}

/// One row from its CSV fields, in [`CSV_HEADER`]'s order.
fn row_of(fields: &[String]) -> anyhow::Result<BenchRow> {
    let columns: Vec<&str> = CSV_HEADER.split(',').collect();
    if fields.len() != columns.len() {
        anyhow::bail!("{} fields, the header has {}", fields.len(), columns.len());
    }
    let parse = |i: usize| -> anyhow::Result<Option<f64>> {
        let f = fields[i].trim();
        if f.is_empty() {
            return Ok(None);
        }
        match f.parse::<f64>() {
            Ok(v) if !v.is_nan() => Ok(Some(v)),
            _ => anyhow::bail!("{} is not a number: '{f}'", columns[i]),
        }
    };
    let need = |i: usize| parse(i)?.ok_or_else(|| anyhow::anyhow!("{} is empty", columns[i]));
    let whole = |i: usize| -> anyhow::Result<Option<u64>> {
        let f = fields[i].trim();
        if f.is_empty() {
            return Ok(None);
        }
        f.parse()
            .map(Some)
            .map_err(|_| anyhow::anyhow!("{} is not a whole number: '{f}'", columns[i]))
    };
    let need_whole = |i: usize| whole(i)?.ok_or_else(|| anyhow::anyhow!("{} is empty", columns[i]));
    let next_error = match whole(15)? {
        None => None,
        Some(records) => {
            let pair = |a: usize, b: usize| -> anyhow::Result<(f32, f32)> {
                Ok((need(a)? as f32, need(b)? as f32))
            };
            Some(EstimateError {
                records,
                estimate: pair(16, 17)?,
                constant: pair(18, 19)?,
                lifespan: pair(20, 21)?,
            })
        }
    };
    Ok(BenchRow {
        scene: fields[0].clone(),
        method: fields[1].clone(),
        settings: fields[2].clone(),
        backend: fields[3].clone(),
        frames: u32::try_from(need_whole(4)?)
            .map_err(|_| anyhow::anyhow!("frames is out of range: '{}'", fields[4]))?,
        seconds: need(5)?,
        render_pass_seconds: parse(6)?,
        rays: need_whole(7)?,
        records: need_whole(8)?,
        peak_mem_mb: parse(9)?,
        rel_rmse: need(10)?,
        rel_rmse_surfaces: parse(11)?,
        block_bias: need(12)?,
        flicker: parse(13)?,
        flicker_surfaces: parse(14)?,
        next_error,
        store_bytes: whole(22)?,
    })
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
        "store MB",
        "rel_rmse",
        "rmse surf",
        "block_bias",
        "flicker",
        "flicker surf",
    ];
    let cells: Vec<[String; 16]> = rows
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
                r.store_bytes
                    .map_or("-".into(), |b| format!("{:.2}", b as f64 / 1e6)),
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
    /// Where the error lies beyond the path sweep, the run at its nearer
    /// end, whose time bounds `path`'s.
    pub path_bound: Option<PathBound>,
}

impl EqualError {
    pub fn speedup(&self) -> Option<f64> {
        self.path_seconds.map(|p| p / self.seconds)
    }
}

/// A run's error beyond every `path` run's: the `path` run at the nearer
/// end of the sweep, whose time bounds what `path` would need for that
/// error, as `path`'s error falls as its time grows (more samples). A
/// sweep that stops at 256 spp still says that a method more accurate
/// than its last run is at least so much faster.
#[derive(Clone, Debug, PartialEq)]
pub struct PathBound {
    /// The `path` run's settings, time and error.
    pub settings: String,
    pub seconds: f64,
    pub error: f64,
    /// Whether the run is more accurate than every `path` run (`path`
    /// needs more than `seconds`), or less accurate than all (less).
    pub more_accurate: bool,
}

impl PathBound {
    /// The run at the end of the `path` sweep (each run with its error)
    /// that `error` lies beyond; `None` within the sweep.
    fn of(path: &[(&BenchRow, f64)], error: f64) -> Option<PathBound> {
        let by_error = |a: &&(&BenchRow, f64), b: &&(&BenchRow, f64)| a.1.total_cmp(&b.1);
        let usable = || {
            path.iter().filter(|(p, e)| {
                p.seconds.is_finite() && p.seconds > 0.0 && e.is_finite() && *e > 0.0
            })
        };
        let best = usable().min_by(by_error)?;
        let worst = usable().max_by(by_error)?;
        let (end, more_accurate) = if error < best.1 {
            (best, true)
        } else if error > worst.1 {
            (worst, false)
        } else {
            return None;
        };
        Some(PathBound {
            settings: end.0.settings.clone(),
            seconds: end.0.seconds,
            error: end.1,
            more_accurate,
        })
    }

    /// What the bound says of a run that took `seconds`: "at least 4.00×
    /// faster than path", "at most 2.00× slower than path", ….
    fn ratio_text(&self, seconds: f64) -> String {
        let x = self.seconds / seconds;
        // More accurate: path needs more time, so the run is faster than x.
        let (faster, slower) = match self.more_accurate {
            true => ("at least", "at most"),
            false => ("at most", "at least"),
        };
        match x >= 1.0 {
            true => format!("{faster} {x:.2}× faster than path"),
            false => format!("{slower} {:.2}× slower than path", 1.0 / x),
        }
    }
}

/// [`EqualError`] under `measure` for every run whose method is not `path`
/// (and that has the measure), against the `path` runs of its scene and
/// backend that vary only the sample count (`spp=…` or the defaults), or
/// all those `path` runs when there are none such. Runs without `path` runs
/// of their scene and backend have no rows.
pub fn equal_error_table(rows: &[BenchRow], measure: ErrorMeasure) -> Vec<EqualError> {
    let path_curve = |of: &BenchRow| -> Vec<(&BenchRow, f64)> {
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
            .into_iter()
            .filter_map(|p| Some((p, measure.of(p)?)))
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
            let points: Vec<(f64, f64)> = path.iter().map(|(p, e)| (p.seconds, *e)).collect();
            let path_seconds = interpolate_time_at_error(&points, error);
            Some(EqualError {
                scene: r.scene.clone(),
                method: r.method.clone(),
                settings: r.settings.clone(),
                backend: r.backend.clone(),
                measure,
                error,
                seconds: r.seconds,
                path_seconds,
                path_bound: path_seconds
                    .is_none()
                    .then(|| PathBound::of(&path, error))
                    .flatten(),
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
        let _ = match (e.path_seconds, e.speedup(), &e.path_bound) {
            (Some(p), Some(x), _) => writeln!(
                out,
                "{what}; path needs {p:.3} s for it → {} than path",
                faster_or_slower(x)
            ),
            (_, _, Some(b)) => writeln!(
                out,
                "{what}; {} accurate than path's {} accurate run ({}: {:.5} in {:.3} s) → {}",
                if b.more_accurate { "more" } else { "less" },
                if b.more_accurate { "most" } else { "least" },
                b.settings,
                b.error,
                b.seconds,
                b.ratio_text(e.seconds)
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
            "{} {} {}: {} records: estimate {}, constant E {}; mean lifespan {:.2} frames \
             by the estimated change, {:.2} by the change gathered again",
            r.scene,
            r.method,
            r.settings,
            e.records,
            percent(e.estimate),
            percent(e.constant),
            e.lifespan.0,
            e.lifespan.1
        );
    }
    out
}

// ------------------------------------------------- temporal vs per-frame

/// The methods that reuse their work across frames, each measured against
/// per-frame `ic`.
const TEMPORAL_METHODS: [&str; 3] = ["trc", "tcg", "movies"];

/// Pairs of a temporal method's run (`trc`, `tcg`, `movies`) and the `ic` run it is
/// measured against (issue 5, DESIGN "How we measure"): on the same scene
/// and backend, the `ic` run with the same settings label where there is
/// one (`ic:strata=64x64` for `trc:strata=64x64`), else the `ic` run whose
/// settings are `ic`'s defaults, labelled `default` or naming them
/// (`spp=16`, as the default sweep `ic:spp=16,64` does); in row order.
pub fn temporal_pairs(rows: &[BenchRow]) -> Vec<(&BenchRow, &BenchRow)> {
    let same_place =
        |r: &BenchRow, run: &BenchRow| (&r.scene, &r.backend) == (&run.scene, &run.backend);
    let ic_with = |run: &BenchRow, settings: &str| {
        rows.iter()
            .find(|r| r.method == "ic" && r.settings == settings && same_place(r, run))
    };
    let ic_at_defaults = |run: &BenchRow| {
        ic_with(run, "default").or_else(|| {
            rows.iter().find(|r| {
                r.method == "ic" && same_place(r, run) && label_is_defaults("ic", &r.settings)
            })
        })
    };
    rows.iter()
        .filter(|r| TEMPORAL_METHODS.contains(&r.method.as_str()))
        .filter_map(|run| {
            let ic = ic_with(run, &run.settings).or_else(|| ic_at_defaults(run))?;
            Some((ic, run))
        })
        .collect()
}

/// Whether a run label ([`super::RunSpec::label`]: `default`, or
/// `key=value` pairs separated by spaces) gives `method` the settings it
/// has by default (`spp=16` for `ic`); a label that does not parse does
/// not.
fn label_is_defaults(method: &str, label: &str) -> bool {
    if label == "default" {
        return true;
    }
    let Some(pairs) = label
        .split_whitespace()
        .map(|pair| pair.split_once('='))
        .collect::<Option<Vec<_>>>()
    else {
        return false;
    };
    let defaults = super::method_settings(method, std::iter::empty());
    let these = super::method_settings(method, pairs);
    matches!((defaults, these), (Ok(d), Ok(t)) if d == t)
}

/// "2.00× faster" for a speed ratio `x` (the other's time over this
/// one's) of at least 1, "1.96× slower" below it, rather than "0.51×
/// faster".
fn faster_or_slower(x: f64) -> String {
    if x >= 1.0 {
        format!("{x:.2}× faster")
    } else {
        format!("{:.2}× slower", 1.0 / x)
    }
}

/// `a / b`, or "-" where either is missing or `b` is zero.
fn ratio_of(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.2}×", a / b),
        _ => "-".into(),
    }
}

/// Lines for people: one per [`temporal_pairs`] pair (naming its backend
/// where the rows have several), with the ratios the
/// temporal method's targets are stated in: `ic`'s time over the temporal
/// run's, `ic`'s records over its records, and its error and flicker (all
/// pixels, and without the pixels at directly seen lights) over `ic`'s.
pub fn temporal_text(rows: &[BenchRow]) -> String {
    // With several backends (`--backends cpu,gpu`) a pair is on one of
    // them, which the line names.
    let several = rows.iter().any(|r| r.backend != rows[0].backend);
    let mut out = String::new();
    for (ic, trc) in temporal_pairs(rows) {
        let _ = writeln!(
            out,
            "{} {} {} against ic {}{}: {}, {} fewer records; error {} ({} lit surfaces), flicker {} ({} lit surfaces)",
            trc.scene,
            trc.method,
            trc.settings,
            ic.settings,
            match several {
                true => format!(" on {}", trc.backend),
                false => String::new(),
            },
            match trc.seconds > 0.0 {
                true => faster_or_slower(ic.seconds / trc.seconds),
                false => "- faster".into(),
            },
            ratio_of(Some(ic.records as f64), Some(trc.records as f64)),
            ratio_of(Some(trc.rel_rmse), Some(ic.rel_rmse)),
            ratio_of(trc.rel_rmse_surfaces, ic.rel_rmse_surfaces),
            ratio_of(trc.flicker, ic.flicker),
            ratio_of(trc.flicker_surfaces, ic.flicker_surfaces),
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

/// Lines for people where the runs were timed in several rounds
/// ([`super::BenchOptions::repeat`]): one per row, its seconds in each
/// round, in order, and the median the tables give (a bench stopped in a
/// later round has fewer rounds for its later runs). Empty for one round.
pub fn rounds_text(rows: &[BenchRow], rounds: &[Vec<f64>]) -> String {
    let mut out = String::new();
    if rounds.iter().all(|t| t.len() <= 1) {
        return out;
    }
    for (row, times) in rows.iter().zip(rounds) {
        let times: Vec<String> = times.iter().map(|t| format!("{t:.3}")).collect();
        let _ = writeln!(
            out,
            "{} {} {} on {}: {} s → {:.3} s",
            row.scene,
            row.method,
            row.settings,
            row.backend,
            times.join(" / "),
            row.seconds,
        );
    }
    out
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
