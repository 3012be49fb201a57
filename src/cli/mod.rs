//! The `radcache` command line (DESIGN.md "Command line"). Every verb parses
//! its arguments, calls the library and maps errors to a message and a
//! non-zero exit status; no input makes it panic. The verbs' arguments are
//! in `args`, the `render` verb in `render`, the others here.

mod args;
mod interrupt;
mod output;
mod render;

use crate::bench;
use crate::metrics;
use crate::render::{BackendChoice, SceneSource};
use crate::store::{self, Store};
use anyhow::{bail, Context, Result};
pub use args::{
    BackendArg, BenchArgs, CompactArgs, CompareArgs, DeleteArgs, GlossyArg, IcArgs, InspectArgs,
    MethodName, MoviesArgs, NextDirectArg, OnOff, RenderArgs, ServeArgs, TcgArgs, TrcArgs,
    TrcGradientsArg, DEFAULT_DB,
};
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use output::{out, outln};
use render::run_render;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "radcache",
    version,
    about = "Global illumination for animations, reusing lighting work across frames"
)]
pub struct Cli {
    /// Worker threads for rendering (render, bench, serve), 1 to 1024
    /// [default: one per CPU core, or RAYON_NUM_THREADS]; one more stores
    /// and writes finished frames. The other commands take the flag and
    /// render nothing. Frames are the same, bit for bit, for any count.
    #[arg(long, global = true, allow_negative_numbers = true,
          value_parser = clap::value_parser!(u16).range(1..=MAX_THREADS as i64))]
    pub threads: Option<u16>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render frames of an animated scene to DIR/frame_NNNN.{exr,png}.
    Render(RenderArgs),
    /// Compare two directories of frame_NNNN.exr: RMSE, relative RMSE, block bias, flicker.
    Compare(CompareArgs),
    /// Run methods over scenes against a converged path reference; write bench.csv and charts.
    Bench(BenchArgs),
    /// Show what a store holds: jobs, frames done, records, bytes per tree, lifespans.
    Inspect(InspectArgs),
    /// Serve the HTTP API and dashboard; render queued jobs in the background.
    Serve(ServeArgs),
    /// Rewrite a store's sample log without the bytes nothing references any more (jobs restarted with --force, frames written again).
    Compact(CompactArgs),
    /// Delete jobs from a store: their frames, statistics, records and state (`compact` then reclaims their bytes).
    Delete(DeleteArgs),
}

/// Runs the CLI on the process arguments.
pub fn main() -> ExitCode {
    // As `Cli::parse`, keeping the matches to tell the flags given from
    // their defaults.
    let matches = Cli::command().get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(err) => err.format(&mut Cli::command()).exit(),
    };
    if let (Command::Render(args), Some(("render", given))) = (&cli.command, matches.subcommand()) {
        for warning in render::flags_of_other_methods(given, args.method) {
            eprintln!("warning: {warning}");
        }
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) if err.is::<output::StdoutClosed>() => ExitCode::SUCCESS,
        Err(err) if err.is::<interrupt::Interrupted>() => {
            eprintln!("{err:#}");
            ExitCode::from(130)
        }
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

pub fn run(cli: Cli) -> Result<()> {
    if let Some(threads) = cli.threads {
        start_worker_threads(usize::from(threads))?;
    } else {
        check_rayon_num_threads()?;
    }
    match cli.command {
        Command::Render(args) => run_render(args),
        Command::Compare(args) => run_compare(args),
        Command::Bench(args) => run_bench(args),
        Command::Inspect(args) => run_inspect(args),
        Command::Serve(args) => run_serve(args),
        Command::Compact(args) => run_compact(args),
        Command::Delete(args) => run_delete(args),
    }
}

/// Starts the process's pool of `threads` worker threads (rayon's global
/// pool, which every parallel stage uses). The pool starts once per
/// process: a second call asking for the count it already has is fine.
fn start_worker_threads(threads: usize) -> Result<()> {
    let started = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global();
    if started.is_err() && rayon::current_num_threads() != threads {
        bail!(
            "--threads {threads}: the worker threads are already started, {} of them",
            rayon::current_num_threads()
        );
    }
    Ok(())
}

/// Most worker threads `--threads` and `RAYON_NUM_THREADS` may ask for.
const MAX_THREADS: usize = 1024;

/// `RAYON_NUM_THREADS`, which rayon reads where `--threads` is not given,
/// held to `--threads`' range: tens of thousands of threads would swamp the
/// machine. 0 is rayon's "one per core".
fn check_rayon_num_threads() -> Result<()> {
    let Some(value) = std::env::var_os("RAYON_NUM_THREADS") else {
        return Ok(());
    };
    let text = value.to_string_lossy();
    if text.trim().is_empty() {
        return Ok(());
    }
    match text.trim().parse::<usize>() {
        Ok(n) if n <= MAX_THREADS => Ok(()),
        Ok(n) => bail!("RAYON_NUM_THREADS={n}: at most {MAX_THREADS} worker threads"),
        Err(_) => bail!("RAYON_NUM_THREADS={text:?} is not a number of worker threads"),
    }
}

/// The bench's options as the command line gives them.
fn bench_options(args: BenchArgs) -> bench::BenchOptions {
    bench::BenchOptions {
        scenes: args.scenes,
        methods: args.methods,
        frames: args.frames,
        width: args.size.0,
        height: args.size.1,
        fps: args.fps,
        reference_spp: args.reference_spp,
        seed: args.seed,
        out: args.out,
        same_pattern: args.same_pattern,
        quiet: args.quiet,
        estimate_error: args.estimate_error,
        store_size: args.store_size,
        backends: args.backends.into_iter().map(backend_choice).collect(),
        check_memory: !args.no_memory_check,
        repeat: args.repeat,
        seeds: args.seeds,
        stop: Default::default(),
    }
}

/// Runs the bench, prints its tables and the files it wrote, and fails
/// with [`interrupt::Interrupted`] where a Ctrl-C stopped it before its
/// last run.
fn run_bench(args: BenchArgs) -> Result<()> {
    if args.replot {
        let report = bench::replot(&args.out)?;
        print_bench(&report)?;
        if !report.unwritten.is_empty() {
            bail!(
                "not every chart was written:\n  {}",
                report.unwritten.join("\n  ")
            );
        }
        return Ok(());
    }
    let mut opts = bench_options(args);
    opts.stop = interrupt::stop_on_ctrl_c(interrupt::CtrlCWords {
        first: "stopping: the run in progress is abandoned; the runs finished are printed \
                and written",
        second: "the tables, bench.csv and charts not yet written are lost; the frames \
                 rendered are kept",
    });
    let report = bench::run(&opts)?;
    let printed = print_bench(&report);
    // An interrupted bench says so whatever became of its tables (a Ctrl-C
    // in `radcache bench | tee log` also ends `tee`).
    if !report.unfinished.is_empty() {
        return Err(bench_interrupted(&report).into());
    }
    // Stopped in a later round of --repeat: every run was measured, over
    // fewer rounds than asked.
    if opts.stop.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(interrupt::Interrupted(
            "interrupted: every run was measured (above), some over fewer rounds than --repeat asked"
                .into(),
        )
        .into());
    }
    printed?;
    if !report.unwritten.is_empty() {
        bail!(
            "the measurements above are whole, but not every file was written:\n  {}",
            report.unwritten.join("\n  ")
        );
    }
    Ok(())
}

/// What an interrupted bench says: how many runs finished, where they
/// are, which did not, and any file not written.
fn bench_interrupted(report: &bench::BenchReport) -> interrupt::Interrupted {
    let finished = report.rows.len();
    let total = finished + report.unfinished.len();
    let written = match &report.csv {
        Some(csv) if finished > 0 => format!(" (measured above and in {})", csv.display()),
        _ => String::new(),
    };
    let mut text = format!(
        "interrupted: {finished} of {total} runs finished{written}; not finished: {}",
        report.unfinished.join(", ")
    );
    if !report.unwritten.is_empty() {
        text += &format!(
            "\nnot every file was written:\n  {}",
            report.unwritten.join("\n  ")
        );
    }
    interrupt::Interrupted(text)
}

/// Prints the bench's tables (none without a finished run) and the files
/// it wrote.
fn print_bench(report: &bench::BenchReport) -> Result<()> {
    if !report.rows.is_empty() {
        print_bench_tables(report)?;
        outln!()?;
    }
    for written in (report.csv.iter())
        .chain(&report.seeds_csv)
        .chain(&report.charts)
    {
        outln!("wrote {}", written.display())?;
    }
    Ok(())
}

/// The table of the runs, and the comparisons between them it holds.
fn print_bench_tables(report: &bench::BenchReport) -> Result<()> {
    out!("{}", bench::to_table(&report.rows))?;
    let rounds = bench::rounds_text(&report.rows, &report.round_seconds);
    if !rounds.is_empty() {
        outln!("\nseconds in each round (the tables give their median):")?;
        out!("{rounds}")?;
    }
    let seeds = bench::seeds_text(&report.rows, &report.seed_errors);
    if !seeds.is_empty() {
        outln!("\nerrors at each seed (the tables give their means):")?;
        out!("{seeds}")?;
    }
    for (measure, what) in [
        (bench::ErrorMeasure::AllPixels, "all pixels"),
        (
            bench::ErrorMeasure::Surfaces,
            "without the pixels at directly seen lights",
        ),
    ] {
        let equal = bench::equal_error_table(&report.rows, measure);
        if !equal.is_empty() {
            outln!("\nequal error, {what} (path time interpolated along its sweep, log-log):")?;
            out!("{}", bench::equal_error_text(&equal))?;
        }
    }
    let temporal = bench::temporal_text(&report.rows);
    if !temporal.is_empty() {
        outln!("\ntemporal methods against per-frame ic (ic's time and records over theirs; their error and flicker over ic's):")?;
        out!("{temporal}")?;
    }
    let estimates = bench::estimate_error_text(&report.rows);
    if !estimates.is_empty() {
        outln!(
            "\nerror of the records' E(t0+1) estimate against E(t0+1) gathered again \
             (TRC Table 1; relative to their mean E(t0+1)):"
        )?;
        out!("{estimates}")?;
    }
    let backends = bench::backend_text(&report.rows);
    if !backends.is_empty() {
        outln!("\nspeed-up of each later backend over the first (the first's seconds ÷ its own):")?;
        out!("{backends}")?;
    }
    if !report.peak_mem_per_run {
        outln!("(peak memory is the process peak so far, not per run)")?;
    }
    Ok(())
}

fn run_serve(args: ServeArgs) -> Result<()> {
    let out = args.out.unwrap_or_else(|| {
        let mut p = args.db.clone().into_os_string();
        p.push(".frames");
        PathBuf::from(p)
    });
    let options = crate::server::ServeOptions {
        db: args.db,
        addr: args.addr,
        scenes: args.scenes,
        token: args.token,
        backend: backend_choice(args.backend),
        out,
        bench: args.bench,
        client_timeout: std::time::Duration::from_secs_f64(args.client_timeout),
        connections_per_peer: args.connections_per_peer,
    };
    crate::server::serve(options)
}

fn backend_choice(b: BackendArg) -> BackendChoice {
    match b {
        BackendArg::Auto => BackendChoice::Auto,
        BackendArg::Cpu => BackendChoice::Cpu,
        BackendArg::Gpu => BackendChoice::Gpu,
    }
}

fn run_inspect(args: InspectArgs) -> Result<()> {
    let store = Store::open_existing(&args.db)?;
    let mut report = store::inspect::report(&store, args.job.as_deref(), args.frame)?;
    for job in &mut report.jobs {
        job.moving_objects = moving_objects(&job.scene, &job.scene_hash);
    }
    // One job asked for one frame it has not finished is an error (exit
    // status 1), as a job it does not hold is; across jobs, a job without
    // the frame is a row of the answer.
    if let (Some(name), Some(frame), [job]) = (&args.job, args.frame, &report.jobs[..]) {
        if let Some(missing) = store::inspect::frame_not_done(job, frame) {
            return Err(store::StoreError::Job {
                path: args.db.clone(),
                job: name.clone(),
                detail: missing,
            }
            .into());
        }
    }
    if args.json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        out!(
            "{}",
            store::inspect::to_text(&report, args.job.is_some() || args.frame.is_some())
        )?;
    }
    Ok(())
}

/// The animated objects of a job's scene (`builtin:NAME` or a file path as
/// stored), where it still loads and is the scene the job rendered (same
/// hash); `None` otherwise: `inspect` then only lists records by object.
fn moving_objects(scene: &str, hash: &str) -> Option<std::collections::BTreeSet<u32>> {
    let source = match scene.strip_prefix("builtin:") {
        Some(name) => SceneSource::Builtin(name.to_string()),
        None => SceneSource::File(PathBuf::from(scene)),
    };
    let (_, stored_as) = crate::render::scene_identity(&source).ok()?;
    if stored_as != hash {
        return None;
    }
    let scene = source.load().ok()?;
    let dynamic = scene.dynamic_objects();
    let moving = (0..dynamic.len()).filter(|&o| dynamic[o]);
    Some(moving.map(|o| o as u32).collect())
}

fn run_compact(args: CompactArgs) -> Result<()> {
    let mut store = Store::open_existing(&args.db)?;
    let bar = store::compact::progress_bar(args.quiet);
    let report = store::compact::compact(&mut store, &bar)?;
    bar.finish_and_clear();
    out!("{}", store::compact::to_text(&report))?;
    Ok(())
}

/// Deletes the jobs named, once all of them are found. The frame files a
/// render wrote under its `--out` are the user's and stay.
fn run_delete(args: DeleteArgs) -> Result<()> {
    let store = Store::open_existing(&args.db)?;
    for name in &args.jobs {
        if store.job(name)?.is_none() {
            bail!(
                "store {}: no job {name:?} (jobs: {}); nothing deleted",
                args.db.display(),
                store.job_names()?
            );
        }
    }
    // One write for all of them: a kill deletes all or none.
    for job in store.delete_jobs(&args.jobs)? {
        outln!("deleted job {} ({} frames)", job.spec.name, job.frames_done)?;
    }
    outln!(
        "their bytes in the sample log are unreferenced now; `radcache compact --db {}` reclaims them",
        args.db.display()
    )?;
    Ok(())
}

fn run_compare(args: CompareArgs) -> Result<()> {
    for (what, dir) in [("reference", &args.reference), ("test", &args.test)] {
        if dir.is_file() {
            bail!(
                "{what} directory {} is a file; expected a directory of frame_NNNN.exr",
                dir.display()
            );
        }
        if !dir.is_dir() {
            bail!("{what} directory {} does not exist", dir.display());
        }
    }
    let maps = args.error_maps.as_deref();
    let report =
        metrics::compare_dirs_with(&args.reference, &args.test, maps).with_context(|| {
            format!(
                "comparing {} with {}",
                args.test.display(),
                args.reference.display()
            )
        })?;
    if args.json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        out!("{}", report.to_text())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `radcache bench` with no options runs what `BenchOptions::default()`
    /// documents (clap needs the frames as text, so they are written twice).
    #[test]
    fn bench_defaults_are_the_library_defaults() {
        let cli = Cli::try_parse_from(["radcache", "bench"]).expect("parses");
        let Command::Bench(args) = cli.command else {
            panic!("not the bench command");
        };
        let (cli, lib) = (bench_options(args), bench::BenchOptions::default());
        assert_eq!(cli.methods, lib.methods);
        assert_eq!(cli.frames, lib.frames);
        assert_eq!((cli.width, cli.height), (lib.width, lib.height));
        assert_eq!(cli.reference_spp, lib.reference_spp);
        assert_eq!((cli.fps, cli.seed), (lib.fps, lib.seed));
        assert_eq!(cli.out, lib.out);
    }
}
