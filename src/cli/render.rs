//! `radcache render`: renders a range of frames to a directory, checkpointed
//! to a store job when `--db`/`--job` are given, and stops cleanly on
//! Ctrl-C once the frame in progress is written.

use super::interrupt::{stop_on_ctrl_c, CtrlCWords, Interrupted};
use super::output::outln;
use super::{
    backend_choice, GlossyArg, IcArgs, MethodName, MoviesArgs, NextDirectArg, OnOff, RenderArgs,
    TcgArgs, TrcArgs, TrcGradientsArg, DEFAULT_DB,
};
use crate::integrator::PathLength;
use crate::method::ic::{GlossyLobe, IcSettings};
use crate::method::movies::global::GlobalSettings;
use crate::method::movies::MoviesSettings;
use crate::method::path::PathSettings;
use crate::method::tcg::TcgSettings;
use crate::method::trc::{NextDirect, TemporalGradients, TrcSettings};
use crate::render::{self, memory, FrameSettings, MethodSettings, Renderer, SceneSource};
use crate::store::{self, Store};
use crate::system_memory;
use anyhow::{bail, Result};
use std::path::PathBuf;
use std::sync::atomic::Ordering;

/// Renders the frames `args` name, prints the summary, and fails with an
/// "interrupted after frame N" error when a Ctrl-C stopped it before the
/// range's end (the frames written so far stay, and a job resumes there).
pub(super) fn run_render(args: RenderArgs) -> Result<()> {
    let source = match (&args.scene, &args.builtin) {
        (Some(path), _) => SceneSource::File(path.clone()),
        (None, Some(name)) => SceneSource::Builtin(name.clone()),
        (None, None) => SceneSource::Builtin("cube-in-box".into()),
    };
    let scene = source.load()?;
    let method = render_method(&args)?;
    if !args.no_memory_check {
        check_memory(&args, &method, &scene)?;
    }
    let backend = render::make_backend(backend_choice(args.backend))?;
    let settings = FrameSettings {
        width: args.size.0,
        height: args.size.1,
        fps: args.fps,
        seed: args.seed,
        same_pattern: args.same_pattern,
        ..FrameSettings::default()
    };
    note_where_the_scene_and_flags_differ(&scene, &args);
    if !args.quiet {
        let (w, h) = args.size;
        eprintln!(
            "rendering {source} frames {}..{} at {w}x{h}, method {}, {} spp, backend {}",
            args.frames.start,
            args.frames.end,
            method.name(),
            method.spp(),
            backend.name()
        );
    }
    let store_and_job = open_job(&args, &source, &method, &settings)?;
    if let Some((store, job)) = &store_and_job {
        note_the_frames_to_resume(store, job, &args.frames)?;
    }
    let mut renderer = Renderer::new(scene, method.instantiate(), backend, settings);
    let mut store_job = store_and_job.as_ref().map(|(store, job)| render::StoreJob {
        store,
        job: job.clone(),
    });
    // A second Ctrl-C stops at once: a job still resumes from its last
    // saved frame, as each frame is saved in one atomic batch.
    let stop = stop_on_ctrl_c(CtrlCWords {
        first: "stopping once the frame in progress is written",
        second: "the frame in progress is lost; frames already written are kept",
    });
    let summary = render::render_job_to_dir_with(
        &mut renderer,
        args.frames.clone(),
        &args.out,
        args.quiet,
        store_job.as_mut(),
        &mut |_| !stop.load(Ordering::Relaxed),
    )?;
    report_render(&args, method.spp(), &summary, store_job.as_ref(), &stop)
}

/// Prints what `run_render` did (the job's resumed and rendered frames,
/// then the summary), and fails with an "interrupted after frame N" error
/// when `stop` (Ctrl-C) ended the range early.
fn report_render(
    args: &RenderArgs,
    spp: u32,
    summary: &render::RenderSummary,
    store_job: Option<&render::StoreJob>,
    stop: &std::sync::atomic::AtomicBool,
) -> Result<()> {
    // A Ctrl-C during the range's last frame stops nothing.
    let done = summary.resumed + summary.frames;
    let interrupted = stop.load(Ordering::Relaxed) && (done as usize) < args.frames.len();
    // Interrupted, the files end at the last frame rendered.
    let last = match summary.frame_stats.last() {
        Some(s) if interrupted => s.frame,
        _ => args.frames.end - 1,
    };
    let printed = store_job
        .map_or(Ok(()), |j| {
            outln!(
                "job {:?} in {}: {} frames resumed from the store, {} rendered, {} done in all",
                j.job.name,
                j.store.path().display(),
                summary.resumed,
                summary.frames,
                j.job.frames_done
            )
        })
        .and_then(|()| print_render_summary(args, spp, summary, last));
    // An interrupted render says so whatever became of its summary (a
    // Ctrl-C in `radcache render | tee log` also ends `tee`).
    if !interrupted {
        return printed;
    }
    let rest = match store_job {
        Some(j) => format!(
            "they are saved in job {:?}: the same command renders the rest",
            j.job.name
        ),
        None => "without --job, running it again renders every frame again".into(),
    };
    Err(Interrupted(format!(
        "interrupted after frame {last}: {done} of {} frames are in {}; {rest}",
        args.frames.len(),
        args.out.display()
    ))
    .into())
}

/// Refuses, before anything renders, a render whose estimated peak memory
/// is over what this process may take: it would end in an abort or the
/// OOM killer, maybe hours in.
fn check_memory(
    args: &RenderArgs,
    method: &MethodSettings,
    scene: &crate::scene::Scene,
) -> Result<()> {
    let triangles = memory::scene_triangles(scene);
    let available = system_memory::available_bytes();
    memory::check_fits(method, args.size, triangles, available).map_err(|too_large| {
        anyhow::anyhow!(
            "{too_large}; render a smaller --size or fewer --spp, or pass --no-memory-check \
             to try anyway"
        )
    })
}

/// Notes (not warnings: the render is right for what was asked) where
/// the scene seems made for other flags: its animation keyed at another
/// frame rate than `--fps`, its camera for another aspect than `--size`.
fn note_where_the_scene_and_flags_differ(scene: &crate::scene::Scene, args: &RenderArgs) {
    if let Some(rate) = key_rate_other_than(scene, args.fps) {
        eprintln!(
            "note: the animation's keys fall on frames of 1/{rate} s, not of 1/{} s (--fps): \
             exporters key every frame, so the scene may have been made at --fps {rate}",
            args.fps
        );
    }
    if let Some(file) = scene.camera.aspect_ratio {
        let (w, h) = args.size;
        let image = w as f32 / h as f32;
        if (image / file - 1.0).abs() > 0.01 {
            eprintln!(
                "note: the camera's aspectRatio is {file:.3} and the image's {image:.3}: the \
                 vertical field of view is kept, so the image shows more or less at its sides"
            );
        }
    }
}

/// The method `render`'s flags ask for, with the papers' defaults for
/// what they leave out.
fn render_method(args: &RenderArgs) -> Result<MethodSettings> {
    let length = PathLength {
        max_depth: args.max_depth,
        ..PathLength::default()
    };
    let ic_settings = ic_settings(args, length);
    let method = match args.method {
        MethodName::Path => MethodSettings::Path(PathSettings {
            spp: args.spp.unwrap_or(PathSettings::default().spp),
            length,
        }),
        MethodName::Ic => MethodSettings::Ic(ic_settings),
        MethodName::Trc => MethodSettings::Trc(TrcSettings {
            ic: ic_settings,
            temporal_accuracy: args.trc.trc_at,
            max_life: args.trc.trc_max_life,
            gradients: match args.trc.trc_gradients {
                TrcGradientsArg::None => TemporalGradients::None,
                TrcGradientsArg::Extrapolated => TemporalGradients::Extrapolated,
                TrcGradientsArg::Interpolated => TemporalGradients::Interpolated,
            },
            reprojection: args.trc.trc_reprojection == OnOff::On,
            next_direct: match args.trc.trc_next_direct {
                NextDirectArg::Off => NextDirect::Off,
                NextDirectArg::MovingLights => NextDirect::MovingLights,
                NextDirectArg::LongLives => NextDirect::LongLives,
                NextDirectArg::On => NextDirect::On,
            },
            keep_paths: args.trc.trc_keep_paths == OnOff::On,
            history: args.trc.trc_history == OnOff::On,
        }),
        MethodName::Tcg => MethodSettings::Tcg(TcgSettings {
            ic: ic_settings,
            tau_min: args.tcg.tcg_tau_min,
            tau_max: args.tcg.tcg_tau_max,
            max_neighbours: args.tcg.tcg_max_neighbours,
            light_refresh: args.tcg.tcg_light_refresh == OnOff::On,
            occlusion_refresh: args.tcg.tcg_occlusion_refresh == OnOff::On,
            arrivals: args.tcg.tcg_arrivals == OnOff::On,
        }),
        MethodName::Movies => MethodSettings::Movies(MoviesSettings {
            spp: args.spp.unwrap_or(MoviesSettings::default().spp),
            shadow_samples: args.movies.movies_shadow_samples,
            texels_per_pixel: args.movies.movies_texels_per_pixel,
            max_resolution: args.movies.movies_max_resolution,
            memory_mib: args.movies.movies_memory_mib,
            global: GlobalSettings {
                spacing: args.movies.movies_spacing,
                links: args.movies.movies_links,
                bounces: args.movies.movies_bounces,
                ..GlobalSettings::default()
            },
            length,
        }),
    };
    check_flags_agree(args)?;
    crate::method::settings::check_consistent(&method)?;
    Ok(method)
}

/// The records' settings (`ic`'s, and those `trc` and `tcg` build on) the
/// `--ic-*` flags, `--spp` and `length` ask for.
fn ic_settings(args: &RenderArgs, length: PathLength) -> IcSettings {
    IcSettings {
        accuracy: args.ic.ic_accuracy,
        strata: args.ic.ic_strata,
        spp: args.spp.unwrap_or(IcSettings::default().spp),
        min_spacing_px: args.ic.ic_min_spacing,
        max_spacing_px: args.ic.ic_max_spacing,
        gradients: !args.ic.ic_no_gradients,
        length,
        glossy: match args.ic.ic_glossy {
            GlossyArg::Path => GlossyLobe::Path,
            GlossyArg::Eas => GlossyLobe::Eas,
        },
        eas_tau: args.ic.ic_eas_tau,
        ..IcSettings::default()
    }
}

/// The flags that contradict each other, by their names (the settings'
/// names, which `check_consistent` gives, are for `bench --methods` and
/// the API).
fn check_flags_agree(args: &RenderArgs) -> Result<()> {
    if matches!(
        args.method,
        MethodName::Ic | MethodName::Trc | MethodName::Tcg
    ) && args.ic.ic_min_spacing > args.ic.ic_max_spacing
    {
        bail!(
            "--ic-min-spacing {} is over --ic-max-spacing {}; give a --ic-min-spacing no larger \
             than --ic-max-spacing",
            args.ic.ic_min_spacing,
            args.ic.ic_max_spacing
        );
    }
    if args.method == MethodName::Tcg && args.tcg.tcg_tau_min > args.tcg.tcg_tau_max {
        bail!(
            "--tcg-tau-min {} is over --tcg-tau-max {}; give a --tcg-tau-min no larger than \
             --tcg-tau-max",
            args.tcg.tcg_tau_min,
            args.tcg.tcg_tau_max
        );
    }
    Ok(())
}

/// The groups of `render`'s method flags (an `Args` struct each, as
/// [`render_method`] reads them) with the methods that read them: `ic`'s
/// flags make the records of `trc` and `tcg` too. Every method reads
/// `--spp` and `--max-depth`.
fn method_flag_groups() -> [(clap::Command, &'static [MethodName]); 4] {
    use clap::Args;
    let flags = |augment: fn(clap::Command) -> clap::Command| augment(clap::Command::new("flags"));
    [
        (
            flags(IcArgs::augment_args),
            &[MethodName::Ic, MethodName::Trc, MethodName::Tcg],
        ),
        (flags(TrcArgs::augment_args), &[MethodName::Trc]),
        (flags(TcgArgs::augment_args), &[MethodName::Tcg]),
        (flags(MoviesArgs::augment_args), &[MethodName::Movies]),
    ]
}

/// The flags `given` on the command line that `method` does not read, each
/// said with the methods that do: "--trc-at applies to --method trc only;
/// --method ic ignores it"; and `--ic-eas-tau` without `--ic-glossy eas`.
///
/// A warning, not an error: `render`'s flags are not tied to the method
/// they set (where `bench --methods trc:at=0.1` gives a setting to a
/// method by name, and a name that method lacks is an error), a script may
/// render a scene with each method in turn under the same flags, and the
/// frames are still what `--method` asks for. So is `--ic-glossy eas` with
/// `path` or `movies`, which keep no records to make glossy.
pub(super) fn flags_of_other_methods(given: &clap::ArgMatches, method: MethodName) -> Vec<String> {
    let name = |m: MethodName| {
        use clap::ValueEnum;
        m.to_possible_value()
            .map_or_else(|| format!("{m:?}"), |v| v.get_name().to_string())
    };
    let mut warnings = Vec::new();
    for (group, methods) in method_flag_groups() {
        if methods.contains(&method) {
            continue;
        }
        let names: Vec<String> = methods.iter().map(|&m| name(m)).collect();
        let applies = match names.split_last() {
            Some((last, [])) => format!("{last} only"),
            Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
            None => continue,
        };
        for arg in group.get_arguments() {
            let id = arg.get_id().as_str();
            if given.value_source(id) != Some(clap::parser::ValueSource::CommandLine) {
                continue;
            }
            let flag = arg
                .get_long()
                .map_or_else(|| id.to_string(), |l| format!("--{l}"));
            warnings.push(format!(
                "{flag} applies to --method {applies}; --method {} ignores it",
                name(method)
            ));
        }
    }
    warnings.extend(eas_tau_unread(given, method));
    warnings
}

/// `--ic-eas-tau` given where the records are made without `--ic-glossy
/// eas`, which alone reads it (a method that makes no records is warned
/// of by [`flags_of_other_methods`] already).
fn eas_tau_unread(given: &clap::ArgMatches, method: MethodName) -> Option<String> {
    let records = matches!(method, MethodName::Ic | MethodName::Trc | MethodName::Tcg);
    let tau_given =
        given.value_source("ic_eas_tau") == Some(clap::parser::ValueSource::CommandLine);
    let eas = given.get_one::<GlossyArg>("ic_glossy") == Some(&GlossyArg::Eas);
    (records && tau_given && !eas).then(|| {
        "--ic-eas-tau applies with --ic-glossy eas only; --ic-glossy path ignores it".into()
    })
}

/// With `--job`, the store (`--db`, or the default) and the job begun or
/// resumed in it.
fn open_job(
    args: &RenderArgs,
    source: &SceneSource,
    method: &MethodSettings,
    settings: &FrameSettings,
) -> Result<Option<(Store, store::schema::JobValue)>> {
    let Some(name) = &args.job else {
        return Ok(None);
    };
    let db = args.db.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_DB));
    let new = crate::store::no_store_at(&db);
    let store = Store::open(&db)?;
    if new {
        eprintln!("{}", crate::store::new_store_note(&db));
    }
    // A scene file is stored by its absolute path: `inspect` and `serve`
    // then find it from any directory, and a resume from another directory
    // names the same path (a changed file is refused for its content, not
    // also for its name). Symbolic links stay as given: the files a
    // `.gltf` references lie beside the name it was given by.
    let source = match source {
        SceneSource::File(path) => SceneSource::File(std::path::absolute(path).map_err(|e| {
            anyhow::anyhow!(
                "cannot make the scene path {} absolute: {e}",
                path.display()
            )
        })?),
        builtin => builtin.clone(),
    };
    let spec = render::job_spec(name, &source, method, settings, args.frames.clone())?;
    let job = store.begin_job(&spec, args.force)?;
    Ok(Some((store, job)))
}

/// Says, before anything renders, how many of the range's frames job
/// `job` has finished in the store, which the render then skips (a method
/// that carries its cache from frame to frame may render some again, and
/// warns of it). The summary after the render counts those it skipped.
fn note_the_frames_to_resume(
    store: &Store,
    job: &store::schema::JobValue,
    frames: &std::ops::Range<u32>,
) -> Result<()> {
    let stored = store
        .frames_done(job.id)?
        .into_iter()
        .filter(|f| frames.contains(f))
        .count();
    if stored > 0 {
        eprintln!(
            "job {:?} in {}: resuming: {stored} of the {} frames of {}..{} are finished in the store",
            job.spec.name,
            store.path().display(),
            frames.len(),
            frames.start,
            frames.end
        );
    }
    Ok(())
}

/// Prints what `render` did: frames, speed, where the frames went (from
/// the range's first frame to `last`), and the method's own statistics.
fn print_render_summary(
    args: &RenderArgs,
    spp: u32,
    summary: &render::RenderSummary,
    last: u32,
) -> Result<()> {
    let secs = summary.elapsed.as_secs_f64();
    let (w, h) = args.size;
    let samples = u64::from(w) * u64::from(h) * u64::from(spp) * u64::from(summary.frames);
    outln!(
        "rendered {} frame{} in {:.2} s ({:.3} s/frame, {:.2} Mrays/s in {} backend calls, {:.2} M samples/s) → {}/frame_{:04}..{:04}.{{exr,png}}",
        summary.frames,
        if summary.frames == 1 { "" } else { "s" },
        secs,
        secs / summary.frames.max(1) as f64,
        summary.rays_per_second() / 1e6,
        summary.ray_calls,
        samples as f64 / secs.max(1e-9) / 1e6,
        summary.out_dir.display(),
        args.frames.start,
        last,
    )?;
    let reports = [
        summary.frame_time_report(),
        summary.cache_report(),
        summary.footprint_report(),
        summary.lifespan_report(),
    ];
    for report in reports.into_iter().flatten() {
        outln!("{report}")?;
    }
    Ok(())
}

/// The frame rate the animation's key times fall on (exporters key every
/// frame), among the usual ones, where they do not fall on frames of
/// `fps`; `None` when they do, or fall on none, or are too few to tell.
fn key_rate_other_than(scene: &crate::scene::Scene, fps: f32) -> Option<u32> {
    let times: Vec<f32> = (scene.animation.channels.iter())
        .flat_map(|c| c.times.iter().copied())
        .filter(|&t| t > 0.0)
        .collect();
    let on_frames = |rate: f32| {
        times
            .iter()
            .all(|&t| ((t * rate).round() - t * rate).abs() < 1e-3)
    };
    if times.len() < 3 || on_frames(fps) {
        return None;
    }
    [24u32, 25, 30, 48, 50, 60]
        .into_iter()
        .find(|&rate| on_frames(rate as f32))
}

#[cfg(test)]
mod tests {
    use super::render_method;
    use crate::cli::{Cli, Command};
    use crate::method::settings::{method_settings, named_settings};
    use clap::Parser;

    /// Every value a method's flag takes can be posted back by its name
    /// (`POST /api/jobs`, `--methods`): at the ends of each flag's range,
    /// and just past them, the flag and the name take the same values, to
    /// the same settings, and what a flag sets, shown by name
    /// ([`named_settings`], as a job shows it), makes those settings again.
    #[test]
    fn every_value_a_flag_takes_posts_back_by_name() {
        // (method, flag, name, values, other settings (flag, name, value))
        type Case = (
            &'static str,
            &'static str,
            &'static str,
            &'static [&'static str],
            &'static [(&'static str, &'static str, &'static str)],
        );
        #[rustfmt::skip]
        let cases: &[Case] = &[
            ("path", "--spp", "spp", &["0", "1", "1000000", "1000001"], &[]),
            ("ic", "--spp", "spp", &["1", "1000000", "1000001"], &[]),
            ("movies", "--spp", "spp", &["1", "1000000", "1000001"], &[]),
            ("path", "--max-depth", "max_depth", &["0", "10000", "10001", "4294967295"], &[]),
            ("trc", "--max-depth", "max_depth", &["0", "10000", "10001"], &[]),
            ("movies", "--max-depth", "max_depth", &["0", "10000", "10001"], &[]),
            ("ic", "--ic-accuracy", "accuracy", &["0", "0.0001", "0.001", "0.2", "2", "2.0005", "2.1"], &[]),
            ("ic", "--ic-strata", "strata",
             &["1x1", "0x4", "2048x32", "32x2048", "1x65536", "65536x1", "1024x64", "1024x4096",
               "1x65537", "2048x33", "4096x4096"], &[]),
            ("tcg", "--ic-strata", "strata", &["2048x32", "1024x4096"], &[]),
            ("ic", "--ic-min-spacing", "min_spacing", &["0.0001", "0.001", "1", "64"],
             &[("--ic-max-spacing", "max_spacing", "1000000")]),
            ("ic", "--ic-max-spacing", "max_spacing", &["0.001", "1000000", "10000000"],
             &[("--ic-min-spacing", "min_spacing", "0.001")]),
            ("ic", "--ic-min-spacing", "min_spacing", &["1000000", "10000000"],
             &[("--ic-max-spacing", "max_spacing", "1000000")]),
            ("trc", "--ic-eas-tau", "eas_tau", &["0.0000001", "0.000001", "1000000", "10000000"], &[]),
            ("trc", "--trc-at", "at", &["0.0000001", "0.000001", "1000000", "10000000"], &[]),
            ("trc", "--trc-max-life", "max_life", &["0", "1", "100000", "100001"], &[]),
            ("tcg", "--tcg-tau-min", "tau_min", &["-0.1", "0", "1", "1.1"], &[]),
            ("tcg", "--tcg-tau-max", "tau_max", &["0", "1", "1.1"], &[("--tcg-tau-min", "tau_min", "0")]),
            ("tcg", "--tcg-max-neighbours", "max_neighbours", &["0", "1000000", "1000001"], &[]),
            ("movies", "--movies-shadow-samples", "shadow_samples", &["0", "1", "64", "65"], &[]),
            ("movies", "--movies-texels-per-pixel", "texels_per_pixel",
             &["0.009", "0.01", "16", "16.1"], &[]),
            ("movies", "--movies-max-resolution", "max_resolution", &["0", "1", "1024", "1025"], &[]),
            ("movies", "--movies-memory-mib", "memory_mib", &["0", "1048576", "1048577"], &[]),
            ("movies", "--movies-spacing", "spacing", &["0.0001", "0.001", "1", "2"], &[]),
            ("movies", "--movies-links", "links", &["0", "1", "1024", "1025"], &[]),
            ("movies", "--movies-bounces", "bounces", &["0", "64", "65"], &[]),
        ];
        let as_text = |v: &serde_json::Value| match v {
            serde_json::Value::String(s) => s.clone(),
            other => other.to_string(),
        };
        for &(method, flag, name, values, others) in cases {
            for &value in values {
                let mut argv = vec!["radcache", "render", "--method", method, flag, value];
                let mut names = vec![];
                for &(flag, name, value) in others {
                    argv.extend([flag, value]);
                    names.push((name, value));
                }
                names.push((name, value));
                let by_flag = Cli::try_parse_from(&argv)
                    .map_err(|e| e.to_string())
                    .and_then(|cli| match cli.command {
                        Command::Render(args) => render_method(&args).map_err(|e| e.to_string()),
                        _ => unreachable!(),
                    });
                let by_name = method_settings(method, names.iter().copied());
                let case = format!("{method} {flag} {value} / {name}={value}");
                match (by_flag, by_name) {
                    (Ok(by_flag), Ok(by_name)) => {
                        assert_eq!(by_flag, by_name, "{case}");
                        let shown = named_settings(&by_flag);
                        let pairs: Vec<(String, String)> =
                            shown.iter().map(|(k, v)| (k.clone(), as_text(v))).collect();
                        let again =
                            method_settings(method, pairs.iter().map(|(k, v)| (&k[..], &v[..])));
                        assert_eq!(again.as_ref(), Ok(&by_flag), "{case}: {shown:?}");
                    }
                    (Err(_), Err(_)) => {}
                    (by_flag, by_name) => panic!(
                        "{case}: by flag {:?}, by name {:?}",
                        by_flag.map(|_| "taken"),
                        by_name.map(|_| "taken")
                    ),
                }
            }
        }
    }
}
