//! `radcache bench`: CSV layout, equal-error interpolation, method errors and
//! a tiny end-to-end run.

use radcache::bench::{
    self, equal_error_table, from_csv, interpolate_time_at_error, method_settings, temporal_pairs,
    temporal_text, to_csv, BenchOptions, BenchRow, ErrorMeasure, MethodError, MethodSweep,
    SeedError, CSV_HEADER,
};
use radcache::method::trc::estimate_error::EstimateError;
use radcache::method::trc::TrcSettings;
use radcache::render::SceneSource;

mod common;

fn row(method: &str, settings: &str, seconds: f64, rel_rmse: f64) -> BenchRow {
    BenchRow {
        scene: "s".into(),
        method: method.into(),
        settings: settings.into(),
        backend: "cpu (2 threads)".into(),
        frames: 2,
        seconds,
        render_pass_seconds: None,
        rays: 100,
        records: 0,
        peak_mem_mb: Some(12.5),
        store_bytes: None,
        rel_rmse,
        rel_rmse_surfaces: Some(rel_rmse / 2.0),
        block_bias: 0.01,
        flicker: None,
        flicker_surfaces: None,
        next_error: None,
    }
}

/// A bench of `methods` on cube-in-box, frames 0..2 at 12×12 against a
/// 4-spp reference, writing into `out`.
fn tiny_bench(out: &std::path::Path, methods: &[&str]) -> BenchOptions {
    BenchOptions {
        scenes: vec![SceneSource::Builtin("cube-in-box".into())],
        methods: methods
            .iter()
            .map(|m| MethodSweep::parse(m).unwrap())
            .collect(),
        frames: 0..2,
        width: 12,
        height: 12,
        reference_spp: 4,
        out: out.to_path_buf(),
        quiet: true,
        ..BenchOptions::default()
    }
}

/// `radcache bench ARGS --out DIR`, run to its end.
fn bench_cli(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .arg("bench")
        .args(args)
        .arg("--out")
        .arg(dir)
        .output()
        .unwrap()
}

#[test]
fn csv_has_header_and_one_line_per_run() {
    let rows = vec![
        row("path", "spp=1", 0.5, 0.4),
        row("path", "spp=4", 2.0, 0.2),
    ];
    let csv = to_csv(&rows);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "scene,method,settings,backend,frames,seconds,render_pass_seconds,rays,records,peak_mem_mb,rel_rmse,rel_rmse_surfaces,block_bias,flicker,flicker_surfaces,\
estimated_records,estimate_err_mean,estimate_err_median,constant_err_mean,constant_err_median,\
estimate_lifespan_mean,actual_lifespan_mean,store_bytes"
    );
    assert_eq!(lines[0], CSV_HEADER);
    assert_eq!(lines.len(), 3, "{csv}");
    for l in &lines[1..] {
        assert_eq!(l.split(',').count(), 23, "{l}");
    }
    assert!(
        lines[1].starts_with("s,path,spp=1,cpu (2 threads),2,"),
        "{}",
        lines[1]
    );
    // A missing flicker or estimate error is an empty field.
    assert!(lines[1].ends_with(",,,,,,,,"), "{}", lines[1]);
}

#[test]
fn csv_quotes_fields_with_commas() {
    let mut r = row("path", "spp=1", 0.5, 0.4);
    r.scene = "a,b".into();
    let csv = to_csv(&[r]);
    assert!(
        csv.lines().nth(1).unwrap().starts_with("\"a,b\",path"),
        "{csv}"
    );
}

/// `bench.csv` reads back into the rows that wrote it (`--replot`): every
/// field, the optional ones empty or not, and names with commas, quotes
/// and a newline.
#[test]
fn csv_reads_back_into_its_rows() {
    let mut rows = vec![
        row("path", "spp=4", 1.5, 0.25),
        row("trc", "at=0.05 max_life=5", 0.75, 0.125),
    ];
    rows[0].scene = "a, \"quoted\"\nscene".into();
    rows[1].render_pass_seconds = Some(0.5);
    rows[1].records = 1234;
    rows[1].peak_mem_mb = None;
    rows[1].store_bytes = Some(987_654_321);
    rows[1].flicker = Some(0.03125);
    rows[1].flicker_surfaces = Some(0.0625);
    rows[1].next_error = Some(EstimateError {
        records: 77,
        estimate: (0.5, 0.25),
        constant: (0.75, 0.125),
        lifespan: (3.5, 2.25),
    });
    assert_eq!(from_csv(&to_csv(&rows)).unwrap(), rows);
    // Windows line ends read as well.
    let crlf = to_csv(&rows[1..]).replace('\n', "\r\n");
    assert_eq!(from_csv(&crlf).unwrap(), rows[1..]);
}

/// A CSV that is not what this build writes is refused, naming the line
/// and the field, not read into the wrong fields.
#[test]
fn a_csv_that_does_not_read_is_a_clear_error() {
    let good = to_csv(&[row("path", "spp=4", 1.5, 0.25)]);
    let cases = [
        (good.replace("rel_rmse,", "error,"), "line 1"),
        (
            good.replace(",1.500000,", ",fast,"),
            "line 2: seconds is not a number: 'fast'",
        ),
        (
            good.replace(",1.500000,", ",NaN,"),
            "seconds is not a number",
        ),
        (good.replace(",100,", ",-3,"), "rays is not a whole number"),
        (good.replace(",0.250000,", ",,"), "rel_rmse is empty"),
        (
            good.replace("cpu (2 threads)", "cpu, (2 threads)"),
            "24 fields, the header has 23",
        ),
        // An unclosed quote runs to the end of the file: one field.
        (
            good.replace("\ns,", "\n\"s,"),
            "line 2: 1 fields, the header has 23",
        ),
    ];
    for (text, expected) in cases {
        let e = format!("{:#}", from_csv(&text).unwrap_err());
        assert!(e.contains(expected), "{e} (expected {expected})");
    }
}

/// `radcache bench --replot` draws an earlier bench's charts again from
/// its CSV alone and prints its tables; a scene that is not a bench's
/// name (it names chart files) and options that would render are refused.
#[test]
fn replot_draws_the_charts_of_a_csv_again() {
    let dir = tempfile::tempdir().unwrap();
    let rows = [
        row("path", "spp=4", 1.5, 0.25),
        row("path", "spp=16", 6.0, 0.125),
        row("ic", "default", 2.0, 0.1),
    ];
    std::fs::write(dir.path().join("bench.csv"), to_csv(&rows)).unwrap();
    let replot = |extra: &[&str]| bench_cli(dir.path(), &[&["--replot"], extra].concat());
    let out = replot(&[]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("spp=16") && stdout.contains("faster than path"),
        "{stdout}"
    );
    for chart in ["error", "surface_error", "flicker", "surface_flicker"] {
        let path = dir.path().join(format!("s_{chart}_vs_time.svg"));
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("<svg"), "{}", path.display());
    }
    assert!(
        !stdout.contains("wrote") || !stdout.contains("bench.csv"),
        "{stdout}"
    );

    let out = replot(&["--frames", "0..2"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("cannot be used with"), "{stderr}");

    std::fs::write(dir.path().join("bench.csv"), to_csv(&[])).unwrap();
    let out = replot(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("holds no run"), "{stderr}");

    let mut outside = rows[0].clone();
    outside.scene = "../escaped".into();
    std::fs::write(dir.path().join("bench.csv"), to_csv(&[outside])).unwrap();
    let out = replot(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("scene '../escaped' is not a name"),
        "{stderr}"
    );
    let parent = dir.path().parent().unwrap();
    assert!(!parent.join("escaped_error_vs_time.svg").exists());
}

#[test]
fn interpolation_is_exact_on_a_power_law() {
    // Monte Carlo: error ∝ time^-1/2. Sample the law at three times; any
    // error between them maps back to the time of the law.
    let law = |t: f64| 0.8 * t.powf(-0.5);
    let pts: Vec<(f64, f64)> = [0.25, 1.0, 16.0].iter().map(|&t| (t, law(t))).collect();
    for t in [0.25, 0.3, 0.5, 1.0, 2.0, 7.5, 16.0] {
        let got = interpolate_time_at_error(&pts, law(t)).unwrap();
        assert!((got - t).abs() < 1e-9 * t, "t={t}: {got}");
    }
    // Order of the points does not matter.
    let mut rev = pts.clone();
    rev.reverse();
    assert!((interpolate_time_at_error(&rev, law(3.0)).unwrap() - 3.0).abs() < 1e-9);
    // Outside the sweep: no extrapolation.
    assert_eq!(interpolate_time_at_error(&pts, law(0.1)), None);
    assert_eq!(interpolate_time_at_error(&pts, law(20.0)), None);
    assert_eq!(interpolate_time_at_error(&[], 0.1), None);
    assert_eq!(interpolate_time_at_error(&pts, 0.0), None);
    assert_eq!(interpolate_time_at_error(&pts, f64::NAN), None);
}

#[test]
fn equal_error_ratio_for_non_path_runs() {
    // path: error 0.8·t^-½. "other" reaches 0.2 (path's error at t = 16) in 2 s.
    let rows = vec![
        row("path", "spp=1", 1.0, 0.8),
        row("path", "spp=64", 64.0, 0.1),
        row("other", "a=0.2", 2.0, 0.2),
        row("other", "a=0.01", 2.0, 0.01),
    ];
    let table = equal_error_table(&rows, ErrorMeasure::AllPixels);
    assert_eq!(table.len(), 2);
    assert!((table[0].path_seconds.unwrap() - 16.0).abs() < 1e-9);
    assert!((table[0].speedup().unwrap() - 8.0).abs() < 1e-9);
    assert_eq!(table[1].path_seconds, None);
    // Below path's lowest error (0.1 in 64 s): path would need more than
    // 64 s, so the 2-s run is at least 32× faster.
    let bound = table[1].path_bound.as_ref().unwrap();
    assert!(bound.more_accurate);
    assert_eq!((bound.settings.as_str(), bound.seconds), ("spp=64", 64.0));
    let text = bench::equal_error_text(&table);
    assert!(
        text.contains(
            "more accurate than path's most accurate run (spp=64: 0.10000 in 64.000 s) \
             → at least 32.00× faster than path"
        ),
        "{text}"
    );
    assert!(table[0].path_bound.is_none());

    // Above path's highest error (0.8 in 1 s): path needs less than 1 s,
    // so a 4-s run is at least 4× slower; a 0.5-s one at most 2× faster.
    let mut worse = rows[..2].to_vec(); // The same path sweep.
    worse.extend([
        row("other", "slow", 4.0, 0.9),
        row("other", "quick", 0.5, 0.9),
    ]);
    let table = equal_error_table(&worse, ErrorMeasure::AllPixels);
    assert!(table
        .iter()
        .all(|e| e.path_bound.as_ref().is_some_and(|b| !b.more_accurate)));
    let text = bench::equal_error_text(&table);
    assert!(
        text.contains("less accurate than path's least accurate run (spp=1: 0.80000 in 1.000 s) → at least 4.00× slower than path"),
        "{text}"
    );
    assert!(text.contains("→ at most 2.00× faster than path"), "{text}");

    // The surface error (half the all-pixel one in `row`) follows the same
    // path curve, halved: "other" at 0.1 is path's surface error at t = 16.
    let surfaces = equal_error_table(&rows, ErrorMeasure::Surfaces);
    assert!((surfaces[0].error - 0.1).abs() < 1e-12);
    assert!((surfaces[0].speedup().unwrap() - 8.0).abs() < 1e-9);
    assert!(bench::equal_error_text(&surfaces).contains("rel_rmse_surfaces"));
    // A run without light masks has no surface row.
    let mut unmasked = rows.clone();
    unmasked[2].rel_rmse_surfaces = None;
    assert_eq!(
        equal_error_table(&unmasked, ErrorMeasure::Surfaces).len(),
        1
    );
    // A scene without path runs has nothing to compare with.
    let mut elsewhere = rows[2].clone();
    elsewhere.scene = "other scene".into();
    assert!(equal_error_table(&[elsewhere], ErrorMeasure::AllPixels).is_empty());
}

/// With several backends a run is held against the `path` runs of its own
/// backend: here the GPU's path is 4× as fast, so the same error is 4× as
/// cheap for path there and the GPU run's speed-up is a quarter.
#[test]
fn equal_error_compares_within_one_backend() {
    let on_gpu = |mut r: BenchRow| {
        r.backend = "gpu (test adapter, Vulkan)".into();
        r
    };
    let rows = vec![
        row("path", "spp=1", 1.0, 0.8),
        row("path", "spp=64", 64.0, 0.1),
        on_gpu(row("path", "spp=1", 0.25, 0.8)),
        on_gpu(row("path", "spp=64", 16.0, 0.1)),
        row("other", "default", 2.0, 0.2),
        on_gpu(row("other", "default", 2.0, 0.2)),
    ];
    let table = equal_error_table(&rows, ErrorMeasure::AllPixels);
    assert_eq!(table.len(), 2);
    assert!((table[0].speedup().unwrap() - 8.0).abs() < 1e-9);
    assert!((table[1].speedup().unwrap() - 2.0).abs() < 1e-9);
    let text = bench::equal_error_text(&table);
    assert!(text.contains("default on gpu (test adapter"), "{text}");
    // The same run on the later backend against the first: 1× here.
    let pairs = bench::backend_pairs(&rows);
    assert_eq!(pairs.len(), 3);
    assert!(pairs
        .iter()
        .all(|(a, b)| a.backend.starts_with("cpu") && b.backend.starts_with("gpu")));
    assert!(bench::backend_text(&rows).contains("→ 4.00×"));
    assert!(bench::backend_pairs(&rows[..2]).is_empty());
}

#[test]
fn unknown_method_and_key_are_clear_errors() {
    let e = method_settings("nope", None).unwrap_err();
    assert!(matches!(e, MethodError::UnknownMethod { .. }));
    assert!(
        e.to_string().contains("nope") && e.to_string().contains("path"),
        "{e}"
    );
    let e = method_settings("path", Some(("colour", "red"))).unwrap_err();
    assert!(matches!(e, MethodError::UnknownKey { .. }));
    assert!(
        e.to_string().contains("colour") && e.to_string().contains("spp"),
        "{e}"
    );
    let e = method_settings("path", Some(("spp", "0"))).unwrap_err();
    assert!(matches!(e, MethodError::BadValue { .. }), "{e}");
    assert!(MethodSweep::parse("nope:x=1").is_err());
    assert!(MethodSweep::parse("path:colour=1,2").is_err());
}

#[test]
fn tiny_end_to_end_run() {
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        scenes: vec![SceneSource::Builtin("cube-in-box".into())],
        methods: vec![MethodSweep::parse("path:spp=1,4").unwrap()],
        frames: 0..2,
        width: 16,
        height: 16,
        reference_spp: 64,
        out: dir.path().to_path_buf(),
        quiet: true,
        ..BenchOptions::default()
    };
    let report = bench::run(&opts).unwrap();
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], CSV_HEADER);
    assert_eq!(lines.len(), 3, "{csv}");
    for chart in [
        "cube-in-box_error_vs_time.svg",
        "cube-in-box_surface_error_vs_time.svg",
        "cube-in-box_flicker_vs_time.svg",
        "cube-in-box_surface_flicker_vs_time.svg",
    ] {
        let svg = std::fs::read_to_string(dir.path().join(chart)).unwrap();
        assert!(svg.contains("<svg") && svg.contains("path"), "{chart}");
    }
    let (one, four) = (&report.rows[0], &report.rows[1]);
    assert_eq!(
        (one.settings.as_str(), four.settings.as_str()),
        ("spp=1", "spp=4")
    );
    assert!(
        four.rel_rmse < one.rel_rmse,
        "4 spp {} vs 1 spp {}",
        four.rel_rmse,
        one.rel_rmse
    );
    assert!(four.rays > one.rays && one.rays > 0);
    // The reference folder has a light mask per frame: the ceiling light of
    // cube-in-box is in view, so some pixels are left out, most are kept,
    // and the surface error exists and falls with the sample count.
    let mask = radcache::metrics::read_light_mask(
        &radcache::metrics::light_mask_path(&dir.path().join("reference/cube-in-box"), 0),
        (16, 16),
    )
    .unwrap()
    .expect("a light mask beside the reference frame");
    let lit = mask.iter().filter(|&&m| m).count();
    assert!(
        lit > 0 && lit < mask.len() / 2,
        "{lit} of {} pixels",
        mask.len()
    );
    let (s1, s4) = (
        one.rel_rmse_surfaces.unwrap(),
        four.rel_rmse_surfaces.unwrap(),
    );
    assert!(s4 < s1, "surface error 4 spp {s4} vs 1 spp {s1}");
    assert!(one.flicker_surfaces.is_some_and(|f| f > 0.0));
    assert!(one.flicker.is_some() && one.seconds > 0.0);
    assert!(dir
        .path()
        .join("runs/cube-in-box/path-spp=4/frame_0001.exr")
        .is_file());

    // A second run reuses the reference (same reference.json, same files).
    let json = dir.path().join("reference/cube-in-box/reference.json");
    let stamp = std::fs::metadata(dir.path().join("reference/cube-in-box/frame_0000.exr"))
        .unwrap()
        .modified()
        .unwrap();
    assert!(json.is_file());
    let again = bench::run(&opts).unwrap();
    let stamp2 = std::fs::metadata(dir.path().join("reference/cube-in-box/frame_0000.exr"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(stamp, stamp2, "the reference was rendered again");
    assert_eq!(again.rows[0].rel_rmse, one.rel_rmse, "deterministic runs");

    // Another reference sample count renders a new reference.
    let other = BenchOptions {
        reference_spp: 32,
        ..opts.clone()
    };
    bench::run(&other).unwrap();
    let info = std::fs::read_to_string(&json).unwrap();
    assert!(info.contains("\"spp\": 32"), "{info}");
    // Rendered on the CPU whatever the runs use: a GPU's defect would
    // otherwise be in its own reference too.
    assert!(info.contains("\"backend\": \"cpu\""), "{info}");

    // One an earlier `path` rendered (no revision recorded) is rendered
    // again: only a render writes reference.json.
    let mut old: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert!(old
        .as_object_mut()
        .unwrap()
        .remove("path_revision")
        .is_some());
    std::fs::write(&json, serde_json::to_string_pretty(&old).unwrap()).unwrap();
    bench::run(&other).unwrap();
    let info = std::fs::read_to_string(&json).unwrap();
    assert!(info.contains("path_revision"), "{info}");
}

/// A reference is kept for the scene it was rendered of: editing the
/// `.bin` beside a `.gltf` (the triangle moved) renders it again, as it
/// changes the scene a job records.
#[test]
fn an_edited_buffer_file_renders_the_reference_again() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = dir.path().join("tri.gltf");
    let json = serde_json::to_vec(&common::tri_json("tri.bin")).unwrap();
    std::fs::write(&gltf, json).unwrap();
    let write_bin = |x: f32| {
        let corners = common::TRI.map(|[a, b, c]| [a - x, b - 0.5, c]);
        std::fs::write(
            dir.path().join("tri.bin"),
            common::tri_bin(corners, [0, 1, 2]),
        )
        .unwrap();
    };
    write_bin(0.0);
    let opts = BenchOptions {
        scenes: vec![SceneSource::File(gltf)],
        frames: 0..1,
        ..tiny_bench(&dir.path().join("bench"), &["path:spp=1"])
    };
    let reference = dir.path().join("bench/reference/tri/frame_0000.exr");
    bench::run(&opts).unwrap();
    let first = std::fs::read(&reference).unwrap();
    bench::run(&opts).unwrap();
    assert_eq!(
        std::fs::read(&reference).unwrap(),
        first,
        "same scene, same reference"
    );
    write_bin(0.8);
    bench::run(&opts).unwrap();
    assert_ne!(
        std::fs::read(&reference).unwrap(),
        first,
        "the reference of the old triangle was kept"
    );
}

/// `--backends cpu,gpu`: every run once on each backend, in its own
/// folder, with the same error (both trace the same hits); a backend named
/// twice is an error. Needs a wgpu adapter, as the GPU tests do (Mesa's
/// software Vulkan driver where there is no GPU; `.ci/run` installs it).
#[test]
fn each_run_is_rendered_on_each_backend() {
    use radcache::render::BackendChoice;
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        backends: vec![BackendChoice::Cpu, BackendChoice::Gpu],
        ..tiny_bench(dir.path(), &["path:spp=2", "trc:spp=1"])
    };
    let rows = bench::run(&opts).unwrap().rows;
    let runs: Vec<(&str, &str)> = rows
        .iter()
        .map(|r| (r.method.as_str(), &r.backend[..3]))
        .collect();
    assert_eq!(
        runs,
        [
            ("path", "cpu"),
            ("path", "gpu"),
            ("trc", "cpu"),
            ("trc", "gpu")
        ]
    );
    for pair in rows.chunks(2) {
        let (cpu, gpu) = (&pair[0], &pair[1]);
        assert!(
            (cpu.rel_rmse - gpu.rel_rmse).abs() <= 1e-3 * cpu.rel_rmse,
            "{}: cpu {} gpu {}",
            cpu.method,
            cpu.rel_rmse,
            gpu.rel_rmse
        );
        assert_eq!(cpu.records, gpu.records, "{}", cpu.method);
    }
    for folder in ["path-spp=2-cpu", "path-spp=2-gpu", "trc-spp=1-gpu"] {
        let frame = dir
            .path()
            .join("runs/cube-in-box")
            .join(folder)
            .join("frame_0001.exr");
        assert!(frame.is_file(), "{}", frame.display());
    }
    let svg = std::fs::read_to_string(dir.path().join("cube-in-box_error_vs_time.svg")).unwrap();
    assert!(svg.contains("trc (spp) on gpu") && svg.contains("trc (spp) on cpu"));
    let twice = BenchOptions {
        backends: vec![BackendChoice::Cpu, BackendChoice::Cpu],
        ..opts.clone()
    };
    let e = bench::run(&twice).unwrap_err().to_string();
    assert!(e.contains("'cpu' is named twice"), "{e}");
    // `auto` is `cpu` where no hardware GPU is (CI, with Mesa's software
    // driver only): then the two are one backend, benched twice before.
    let auto = radcache::render::make_backend(BackendChoice::Auto)
        .unwrap()
        .name();
    if auto
        == radcache::render::make_backend(BackendChoice::Cpu)
            .unwrap()
            .name()
    {
        let same = BenchOptions {
            backends: vec![BackendChoice::Cpu, BackendChoice::Auto],
            ..opts
        };
        let e = bench::run(&same).unwrap_err().to_string();
        assert!(
            e.contains("cpu and auto are the same backend on this machine"),
            "{e}"
        );
    }
}

/// `--estimate-error`: every `trc` run also gets the error of its records'
/// E(t0+1) estimates (TRC Table 1), over exactly the records the timed run
/// computed (the untimed pass is the same deterministic run); without
/// reprojection the estimate is the constant one; other methods get none.
#[test]
fn trc_runs_measure_their_next_frame_estimates() {
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        estimate_error: true,
        frames: 0..3,
        fps: 6.0,
        ..tiny_bench(dir.path(), &["ic:spp=1", "trc:spp=1", "trc:reprojection=0"])
    };
    let rows = bench::run(&opts).unwrap().rows;
    assert_eq!(rows[0].next_error, None, "ic");
    for r in &rows[1..] {
        let e = r.next_error.expect("a trc run measures its estimates");
        assert_eq!(e.records, r.records, "{}", r.settings);
        for (mean, median) in [e.estimate, e.constant] {
            assert!(mean.is_finite() && mean > 0.0 && median.is_finite() && median >= 0.0);
        }
    }
    let (with, without) = (rows[1].next_error.unwrap(), rows[2].next_error.unwrap());
    assert_ne!(with.estimate, with.constant, "cube-in-box's cube moves");
    assert_eq!(without.estimate, without.constant);
    // Lifespans (Eq. 9–11, δt_max = 20): the constant estimate predicts no
    // change, so it grants every record the whole 20 frames; gathered
    // again, records that see the cube move (and their noise) change.
    let max_life = TrcSettings::default().max_life as f32;
    assert_eq!(without.lifespan.0, max_life);
    for e in [with, without] {
        let (by_estimate, by_actual) = e.lifespan;
        assert!((1.0..=max_life).contains(&by_estimate), "{e:?}");
        assert!((1.0..max_life).contains(&by_actual), "{e:?}");
    }
    let text = bench::estimate_error_text(&rows);
    assert_eq!(text.lines().count(), 2, "{text}");
    let no_trc = BenchOptions {
        estimate_error: true,
        ..tiny_bench(dir.path(), &["ic:spp=1"])
    };
    let e = bench::run(&no_trc).unwrap_err().to_string();
    assert!(e.contains("no method is trc"), "{e}");
    // A run named twice (here once alone, once in a sweep) would render
    // twice: refused before anything renders.
    let twice = tiny_bench(dir.path(), &["trc:max_life=5", "ic", "trc:max_life=2,5"]);
    let e = bench::run(&twice).unwrap_err().to_string();
    assert!(
        e.contains("gives the run trc max_life=5 twice (as max_life=5 too"),
        "{e}"
    );
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let trc_line = csv.lines().nth(2).unwrap();
    let fields: Vec<&str> = trc_line.split(',').collect();
    assert_eq!(fields[15], rows[1].records.to_string(), "{trc_line}");
}

#[test]
fn same_pattern_runs_flicker_less() {
    // With the same random sequence in every frame a run's pixel noise is
    // correlated from frame to frame, so its frame differences (hence
    // flicker) shrink; its error against the reference does not vanish.
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        scenes: vec![SceneSource::Builtin("cube-in-box".into())],
        methods: vec![MethodSweep::parse("path:spp=2").unwrap()],
        frames: 0..3,
        width: 16,
        height: 16,
        reference_spp: 32,
        out: dir.path().to_path_buf(),
        quiet: true,
        ..BenchOptions::default()
    };
    let fresh = bench::run(&opts).unwrap().rows[0].clone();
    let same = bench::run(&BenchOptions {
        same_pattern: true,
        ..opts
    })
    .unwrap()
    .rows[0]
        .clone();
    let (f, s) = (fresh.flicker.unwrap(), same.flicker.unwrap());
    assert!(s < 0.8 * f, "same pattern {s} vs fresh {f}");
    assert!(same.rel_rmse > 0.0);
}

/// The reference draws random numbers no run draws: a same-pattern `path`
/// run at the reference's own spp (both keyed without the frame) is
/// another render of the same image, not the reference again, and its
/// error is that of a run at another seed, in the mean over seeds.
#[test]
fn no_run_draws_the_references_random_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let error_at = |seed: u64| {
        let opts = BenchOptions {
            same_pattern: true,
            seed,
            ..tiny_bench(dir.path(), &["path:spp=4"])
        };
        bench::run(&opts).unwrap().rows[0].rel_rmse
    };
    let errors: Vec<f64> = (0..4).map(error_at).collect();
    // Each seed has its own reference; its runs are as far from it as
    // two independent 4-spp renders are from each other.
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    for (seed, e) in errors.iter().enumerate() {
        assert!(
            *e > 0.5 * mean,
            "seed {seed}: {e} against a mean of {mean} ({errors:?})"
        );
    }
}

/// With several seeds a run's row holds the means of its errors over
/// them, each seed's against the one reference, and each seed's run is
/// what `radcache render --seed S` renders (compared here with that
/// reference independently of the bench); the seeds' errors differ.
#[test]
fn a_run_at_several_seeds_reports_their_mean_error() {
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        seeds: 3,
        ..tiny_bench(dir.path(), &["trc"])
    };
    let report = bench::run(&opts).unwrap();
    let (row, seeds) = (&report.rows[0], &report.seed_errors[0]);
    let reference = dir.path().join("reference/cube-in-box");
    let rendered_at = |seed: u64| {
        let out = dir.path().join(format!("cli-{seed}"));
        let status = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
            .args([
                "render", "--method", "trc", "--size", "12x12", "--frames", "0..2", "-q",
            ])
            .args(["--seed", &seed.to_string(), "--out"])
            .arg(&out)
            .status()
            .unwrap();
        assert!(status.success());
        radcache::metrics::compare_dirs(&reference, &out).unwrap()
    };
    let by_seed: Vec<_> = (0..3).map(rendered_at).collect();
    assert_eq!(seeds.iter().map(|s| s.seed).collect::<Vec<_>>(), [0, 1, 2]);
    for (s, cli) in seeds.iter().zip(&by_seed) {
        assert_eq!(
            (s.rel_rmse, s.block_bias),
            (cli.rel_rmse, cli.block_bias),
            "seed {}",
            s.seed
        );
    }
    let mean =
        |f: fn(&radcache::metrics::CompareReport) -> f64| by_seed.iter().map(f).sum::<f64>() / 3.0;
    assert!((row.rel_rmse - mean(|c| c.rel_rmse)).abs() < 1e-12);
    assert!((row.block_bias - mean(|c| c.block_bias)).abs() < 1e-12);
    let flicker = by_seed.iter().map(|c| c.flicker.unwrap()).sum::<f64>() / 3.0;
    assert!((row.flicker.unwrap() - flicker).abs() < 1e-12);
    assert!(seeds[0].rel_rmse != seeds[1].rel_rmse && seeds[1].rel_rmse != seeds[2].rel_rmse);
    let text = bench::seeds_text(&report.rows, &report.seed_errors);
    assert!(text.contains("seeds 0, 1, 2"), "{text}");
}

/// `radcache bench --seeds N` prints each run's errors at each seed after
/// the tables, the tables giving their means; `--seeds 0` and `--seeds`
/// with `--replot` are refused.
#[test]
fn bench_seeds_flag_prints_the_errors_at_each_seed() {
    let dir = tempfile::tempdir().unwrap();
    let tiny = ["--size", "8x8", "--frames", "0..2", "--reference-spp", "2"];
    let tiny = [&tiny[..], &["--methods", "path:spp=1", "-q"]].concat();
    let bench = |extra: &[&str]| bench_cli(dir.path(), &[&tiny[..], extra].concat());
    let out = bench(&["--seeds", "2"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, after) = stdout
        .split_once("errors at each seed (the tables give their means):\n")
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(
        after.starts_with("cube-in-box path spp=1 on cpu")
            && after.contains("seeds 0, 1: rel_rmse"),
        "{stdout}"
    );
    assert!(dir
        .path()
        .join("runs/cube-in-box/path-spp=1/seed-1/frame_0001.exr")
        .exists());
    // Each seed's errors are kept beside bench.csv, a line per seed, and
    // the error chart bars their range.
    let seeds_csv = dir.path().join("bench_seeds.csv");
    assert!(
        stdout.contains(&format!("wrote {}", seeds_csv.display())),
        "{stdout}"
    );
    let lines = std::fs::read_to_string(&seeds_csv).unwrap();
    let lines: Vec<&str> = lines.lines().collect();
    assert_eq!(lines.len(), 3, "{lines:?}");
    assert!(lines[1].starts_with("cube-in-box,path,spp=1,") && lines[2].contains(",1,"));
    let chart = dir.path().join("cube-in-box_error_vs_time.svg");
    assert!(std::fs::read_to_string(&chart)
        .unwrap()
        .contains("its bar: their range"));
    let out = bench(&["--seeds", "0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--seeds"));
    // `--replot` renders nothing, so it takes no seeds (its other flags
    // alone are accepted: the bench above wrote the CSV).
    let replot = |extra: &[&str]| bench_cli(dir.path(), &[&["--replot", "-q"], extra].concat());
    // `--replot` reads the seeds back: the same lines, the same bars.
    std::fs::remove_file(&chart).unwrap();
    let out = replot(&[]);
    assert!(out.status.success());
    let replotted = String::from_utf8_lossy(&out.stdout);
    let seed_lines = after.split("\n\n").next().unwrap();
    assert!(replotted.contains(seed_lines), "{replotted}\n---\n{after}");
    assert!(std::fs::read_to_string(&chart)
        .unwrap()
        .contains("its bar: their range"));
    // A seeds file that does not read stops the replot, naming it, its
    // line and the way out.
    let text = std::fs::read_to_string(&seeds_csv).unwrap();
    std::fs::write(&seeds_csv, text.replacen(",0,", ",zero,", 1)).unwrap();
    let out = replot(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("bench_seeds.csv")
            && stderr.contains("line 2: seed is not a whole number: 'zero'")
            && stderr.contains("move it away"),
        "{stderr}"
    );
    let out = replot(&["--seeds", "2"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
    // A bench of one seed leaves no earlier bench's seeds beside its CSV.
    assert!(bench(&[]).status.success());
    assert!(!seeds_csv.exists());
    assert!(!std::fs::read_to_string(&chart).unwrap().contains("its bar"));
}

/// The render pass's share of a run: timed for the cache methods (their
/// "render" phase, a part of their time), absent for `path`, which has no
/// cache to set apart from it.
#[test]
fn cache_methods_report_their_render_pass_time() {
    let dir = tempfile::tempdir().unwrap();
    let opts = tiny_bench(
        dir.path(),
        &["path:spp=1", "ic:spp=1", "trc:spp=1", "movies:spp=1"],
    );
    let rows = bench::run(&opts).unwrap().rows;
    assert_eq!(rows.len(), 4);
    assert_eq!(rows[0].render_pass_seconds, None, "path");
    for r in &rows[1..] {
        let pass = r
            .render_pass_seconds
            .expect("a cache method times its render pass");
        assert!(
            pass > 0.0 && pass < r.seconds,
            "{}: render pass {pass} s of {} s",
            r.method,
            r.seconds
        );
    }
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let ic_line = csv
        .lines()
        .find(|l| l.starts_with("cube-in-box,ic,"))
        .unwrap();
    let fields: Vec<&str> = ic_line.split(',').collect();
    assert!(fields[6].parse::<f64>().is_ok(), "{ic_line}");
}

/// Each `trc`, `tcg` and `movies` run is set against the `ic` run with its settings
/// label, or else `ic` at its defaults, on its own scene and backend; the
/// ratios are the targets' (ic's time and records over the temporal run's,
/// its error and flicker over ic's).
#[test]
fn temporal_runs_are_set_against_ic_with_the_same_settings_or_the_defaults() {
    let with = |mut r: BenchRow, records: u64, flicker: f64| {
        r.records = records;
        r.flicker = Some(flicker);
        r.flicker_surfaces = Some(2.0 * flicker);
        r
    };
    let mut elsewhere = with(row("ic", "default", 1.0, 0.1), 10, 0.1);
    elsewhere.scene = "other".into();
    let rows = vec![
        with(row("ic", "default", 40.0, 0.020), 1000, 0.020),
        with(row("ic", "strata=64x64", 90.0, 0.018), 990, 0.015),
        with(row("trc", "default", 10.0, 0.021), 100, 0.010),
        with(row("trc", "strata=64x64", 10.0, 0.018), 90, 0.012),
        with(row("trc", "max_life=5", 20.0, 0.020), 250, 0.010),
        with(row("tcg", "tau_min=0.2", 8.0, 0.022), 50, 0.011),
        with(row("movies", "shadow_samples=4", 80.0, 0.019), 25, 0.005),
        elsewhere,
        with(row("path", "spp=4", 5.0, 0.2), 0, 0.3),
    ];
    let pairs: Vec<(&str, &str)> = temporal_pairs(&rows)
        .iter()
        .map(|(ic, trc)| (ic.settings.as_str(), trc.settings.as_str()))
        .collect();
    assert_eq!(
        pairs,
        [
            ("default", "default"),
            ("strata=64x64", "strata=64x64"),
            ("default", "max_life=5"),
            ("default", "tau_min=0.2"),
            ("default", "shadow_samples=4"),
        ]
    );
    let text = temporal_text(&rows);
    let first = text.lines().next().unwrap();
    assert_eq!(
        first,
        "s trc default against ic default: 4.00× faster, 10.00× fewer records; \
         error 1.05× (1.05× lit surfaces), flicker 0.50× (0.50× lit surfaces)"
    );
    assert!(
        text.lines()
            .nth(1)
            .unwrap()
            .contains("9.00× faster, 11.00× fewer records"),
        "{text}"
    );
    assert_eq!(
        text.lines().nth(3).unwrap(),
        "s tcg tau_min=0.2 against ic default: 5.00× faster, 20.00× fewer records; \
         error 1.10× (1.10× lit surfaces), flicker 0.55× (0.55× lit surfaces)"
    );
    // A run slower than ic's is said to be so, not "0.50× faster".
    let movies = text.lines().nth(4).unwrap();
    assert!(
        movies.contains("ic default: 2.00× slower, 40.00× fewer records"),
        "{movies}"
    );
    // On two backends each pair names its own.
    let on = |r: &BenchRow, backend: &str| BenchRow {
        backend: backend.into(),
        ..r.clone()
    };
    let two = [
        on(&rows[0], "cpu"),
        on(&rows[2], "cpu"),
        on(&rows[0], "gpu"),
        on(&rows[2], "gpu"),
    ];
    let lines: Vec<String> = temporal_text(&two).lines().map(str::to_owned).collect();
    assert_eq!(lines.len(), 2, "{lines:?}");
    assert!(lines[0].starts_with("s trc default against ic default on cpu: 4.00× faster"));
    assert!(lines[1].starts_with("s trc default against ic default on gpu: 4.00× faster"));
    // A trc run with no ic run on its scene is set against nothing.
    let mut alone = rows[2].clone();
    alone.scene = "third".into();
    assert!(temporal_pairs(&[alone]).is_empty());
}

/// `--store-size`: every run is also rendered into a store of its own,
/// left in its folder; its size is that of the store's files (as `find`
/// lists them); it holds the run's frames and records; without the option
/// no store is made.
#[test]
fn store_size_is_the_runs_own_store() {
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        store_size: true,
        ..tiny_bench(dir.path(), &["ic:spp=1", "trc:spp=1"])
    };
    let rows = bench::run(&opts).unwrap().rows;
    for (r, folder) in rows.iter().zip(["ic-spp=1", "trc-spp=1"]) {
        let run = dir.path().join("runs/cube-in-box").join(folder);
        let find = std::process::Command::new("find")
            .arg(run.join("store"))
            .args(["-type", "f", "-printf", "%s\\n"])
            .output()
            .unwrap();
        let files: u64 = String::from_utf8_lossy(&find.stdout)
            .lines()
            .map(|l| l.parse::<u64>().unwrap())
            .sum();
        assert_eq!(r.store_bytes, Some(files), "{}", r.method);
        let store = radcache::store::Store::open_existing(&run.join("store")).unwrap();
        let job = store.job("bench").unwrap().expect("the run's job");
        assert_eq!(job.frames_done, 2, "{}", r.method);
        let stored = store.frame_exr(job.id, 1).unwrap().expect("frame 1");
        let written = std::fs::read(run.join("frame_0001.exr")).unwrap();
        assert_eq!(
            stored, written,
            "{}: the store holds the run's frames",
            r.method
        );
        // Every record computed is in it, with its samples.
        let records: usize = (0..2)
            .map(|f| store.frame_records(job.id, f).unwrap().len())
            .sum();
        assert_eq!(records as u64, r.records, "{}", r.method);
    }
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let last = |line: &str| line.rsplit(',').next().unwrap().to_string();
    assert_eq!(
        last(csv.lines().nth(1).unwrap()),
        rows[0].store_bytes.unwrap().to_string()
    );

    let plain = tempfile::tempdir().unwrap();
    let rows = bench::run(&tiny_bench(plain.path(), &["ic:spp=1"]))
        .unwrap()
        .rows;
    assert_eq!(rows[0].store_bytes, None);
    assert!(!plain
        .path()
        .join("runs/cube-in-box/ic-spp=1/store")
        .exists());
}

/// Where no `ic` run is labelled `default`, a temporal run is set against
/// the `ic` run whose settings are `ic`'s defaults, whatever its label
/// says (`spp=16`, as in the default sweep `ic:spp=16,64`), never against
/// another `ic` run.
#[test]
fn temporal_runs_find_ic_at_its_defaults_under_another_label() {
    let rows = vec![
        row("ic", "spp=64", 4.0, 0.1),
        row("ic", "spp=16", 2.0, 0.1),
        row("trc", "max_life=5", 1.0, 0.1),
    ];
    let pairs: Vec<(&str, &str)> = temporal_pairs(&rows)
        .iter()
        .map(|(ic, trc)| (ic.settings.as_str(), trc.settings.as_str()))
        .collect();
    assert_eq!(pairs, [("spp=16", "max_life=5")]);
    // No ic run at the defaults: nothing to set the temporal run against.
    let rows = vec![
        row("ic", "spp=64", 4.0, 0.1),
        row("trc", "default", 1.0, 0.1),
    ];
    assert!(temporal_pairs(&rows).is_empty());
}

/// `radcache bench` with its default methods prints the temporal methods
/// against per-frame `ic` (README, "Benchmarks"): its `ic` sweep holds
/// `ic` at its defaults.
#[test]
fn default_bench_sets_temporal_methods_against_ic() {
    let dir = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["bench", "--size", "8x8", "--frames", "0..2"])
        .args(["--reference-spp", "2", "-q", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains("temporal methods against per-frame ic"),
        "{stdout}"
    );
    for run in [
        "trc max_life=5",
        "tcg tau_min=0.05",
        "movies shadow_samples=16",
    ] {
        assert!(
            stdout.contains(&format!("cube-in-box {run} against ic spp=16:")),
            "{run}: {stdout}"
        );
    }
}

/// `--backends cpu,gpu` where no GPU adapter is found (Vulkan pointed at a
/// driver list that does not exist) fails before anything renders: no
/// reference, no run, and the message names the flag and the way out.
#[test]
fn a_missing_gpu_backend_fails_before_the_reference_renders() {
    let dir = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .env("VK_ICD_FILENAMES", "/nonexistent/radcache-icd.json")
        .env("WGPU_BACKEND", "vulkan")
        .args(["bench", "--size", "8x8", "--frames", "0..2"])
        .args(["--reference-spp", "2", "--methods", "path:spp=1"])
        .args(["--backends", "cpu,gpu", "-q", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("--backends cpu,gpu: the gpu backend is unavailable")
            && stderr.contains("nothing was rendered"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("reference").exists(),
        "a reference was rendered"
    );
    assert!(!dir.path().join("runs").exists(), "a run was rendered");
}

/// A file the bench cannot write (here a folder where `bench.csv` goes)
/// loses no measurement: the table is printed, the error names the file,
/// and the exit status says it failed. Before, the error came alone once
/// every run had rendered.
#[test]
fn a_file_that_cannot_be_written_keeps_the_table() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("bench.csv")).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["bench", "--size", "8x8", "--frames", "0..2", "--methods"])
        .args(["path:spp=1", "--reference-spp", "2", "-q", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stdout.contains("spp=1"), "no table: {stdout}");
    assert!(
        !stdout.contains("wrote") || !stdout.contains("bench.csv"),
        "{stdout}"
    );
    assert!(stdout.contains("cube-in-box_error_vs_time.svg"), "{stdout}");
    assert!(
        stderr.contains("not every file was written") && stderr.contains("bench.csv"),
        "{stderr}"
    );
}

/// A reused reference whose frame no longer reads (a truncated copy) is
/// rendered again, rather than failing the bench once every run has
/// rendered.
#[test]
fn a_damaged_reference_is_rendered_again() {
    let dir = tempfile::tempdir().unwrap();
    let opts = tiny_bench(dir.path(), &["path:spp=1"]);
    bench::run(&opts).unwrap();
    let frame = dir.path().join("reference/cube-in-box/frame_0001.exr");
    let whole = std::fs::read(&frame).unwrap();
    std::fs::write(&frame, &whole[..100]).unwrap();
    let again = bench::run(&opts).expect("the reference is rendered again");
    assert_eq!(std::fs::read(&frame).unwrap(), whole);
    assert_eq!(again.rows.len(), 1);
}

/// One run spelled twice (`spp=2,02`, or a setting at its default beside
/// the default run) is refused: it would render twice as identical rows.
#[test]
fn a_run_spelled_twice_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    for methods in [&["path:spp=2,02"][..], &["trc", "trc:at=0.05"]] {
        let err = bench::run(&tiny_bench(dir.path(), methods)).unwrap_err();
        assert!(
            err.to_string().contains("twice") && err.to_string().contains("the same settings"),
            "{methods:?}: {err}"
        );
    }
}

/// A run at exactly 0 (no flicker) has no place on a log axis: the chart
/// names it rather than leaving it out without a word, and a chart with no
/// point says why.
#[test]
fn charts_name_runs_at_zero_and_say_why_they_are_empty() {
    let dir = tempfile::tempdir().unwrap();
    let mut still = row("trc", "default", 1.0, 0.1);
    still.flicker = Some(0.0);
    let mut moving = row("ic", "default", 2.0, 0.1);
    moving.flicker = Some(0.02);
    let charts = bench::plot_scene(dir.path(), "s", &[still, moving], &[]).unwrap();
    let svg = |name: &str| std::fs::read_to_string(dir.path().join(name)).unwrap();
    assert!(charts.contains(&dir.path().join("s_flicker_vs_time.svg")));
    assert!(
        svg("s_flicker_vs_time.svg").contains("not drawn, at 0 (a log axis has none): trc default"),
        "{}",
        svg("s_flicker_vs_time.svg")
    );
    assert!(!svg("s_error_vs_time.svg").contains("not drawn"));
    assert!(svg("s_surface_flicker_vs_time.svg")
        .contains("no data: flicker needs two frames or more, and light masks in the reference"));
}

/// A run rendered at several seeds is drawn on each chart at its mean
/// with a bar from its least to its greatest seed's value, the axis
/// reaching both ends; a run of one seed has no bar, nor a chart of a
/// value its seeds lack.
#[test]
fn the_charts_bar_each_runs_spread_over_its_seeds() {
    let dir = tempfile::tempdir().unwrap();
    let mut rows = [
        row("ic", "default", 2.0, 0.1),
        row("trc", "default", 1.0, 0.1),
    ];
    for r in &mut rows {
        r.flicker = Some(0.05);
    }
    let at = |seed, rel_rmse: f64| SeedError {
        seed,
        rel_rmse,
        rel_rmse_surfaces: None,
        block_bias: 0.01,
        flicker: Some(rel_rmse / 2.0),
        flicker_surfaces: None,
    };
    // trc's seeds spread far beyond both means: the axis must stretch.
    let seeds = [vec![at(0, 0.1)], vec![at(0, 0.02), at(1, 0.28)]];
    bench::plot_scene(dir.path(), "s", &rows, &seeds).unwrap();
    let svg = |chart: &str| std::fs::read_to_string(dir.path().join(chart)).unwrap();
    for chart in ["s_error_vs_time.svg", "s_flicker_vs_time.svg"] {
        let svg = svg(chart);
        assert!(
            svg.contains("a point: the mean over seeds, its bar: their range"),
            "{svg}"
        );
        let bars = vertical_lines(&svg);
        assert_eq!(bars.len(), 1, "{chart}: {bars:?}");
        // The bar stands at trc's point (1 s), ic's (2 s) has none.
        let circles = circle_centres(&svg);
        let (x, top, bottom) = bars[0];
        let trc = circles.iter().min_by_key(|c| c.0).unwrap();
        assert_eq!(trc.0, x, "{chart}: {circles:?}");
        // Its ends lie on either side of the mean, inside the chart's area.
        assert!(
            top < trc.1 && trc.1 < bottom && top > 18 && bottom < 580 - 52,
            "{chart}: {bars:?}"
        );
    }
    // The seeds have no surface error: its chart has no bar.
    let surfaces = svg("s_surface_error_vs_time.svg");
    assert!(vertical_lines(&surfaces).is_empty() && !surfaces.contains("its bar"));
    // Without the seeds, the same rows draw no bar.
    bench::plot_scene(dir.path(), "s", &rows, &[]).unwrap();
    let error = svg("s_error_vs_time.svg");
    assert!(vertical_lines(&error).is_empty() && !error.contains("its bar"));
}

/// The coloured polylines of an SVG (not the axes' and ticks' black or
/// the grid's greys) of two points one above the other: (x, top y, bottom
/// y) in pixels.
fn vertical_lines(svg: &str) -> Vec<(i32, i32, i32)> {
    let grey = |p: &str| {
        let Some((_, hex)) = p.split_once("stroke=\"#") else {
            return true;
        };
        hex.get(0..2) == hex.get(2..4) && hex.get(2..4) == hex.get(4..6)
    };
    let numbers = |s: &str| -> Vec<i32> {
        (s.split([' ', ',']))
            .filter_map(|n| n.parse::<f64>().ok())
            .map(|n| n.round() as i32)
            .collect()
    };
    (svg.split("<polyline").skip(1))
        .map(|p| p.split_once("/>").map_or(p, |(p, _)| p))
        .filter(|p| !grey(p))
        .filter_map(|p| Some(numbers(p.split_once("points=\"")?.1.split_once('"')?.0)))
        .filter(|n| n.len() == 4 && n[0] == n[2] && n[1] != n[3])
        .map(|n| (n[0], n[1].min(n[3]), n[1].max(n[3])))
        .collect()
}

/// The centres of an SVG's circles, in pixels.
fn circle_centres(svg: &str) -> Vec<(i32, i32)> {
    let attr = |c: &str, name: &str| -> Option<i32> {
        let v = c.split_once(&format!(" {name}=\""))?.1.split_once('"')?.0;
        Some(v.parse::<f64>().ok()?.round() as i32)
    };
    (svg.split("<circle").skip(1))
        .filter_map(|c| Some((attr(c, "cx")?, attr(c, "cy")?)))
        .collect()
}

/// A sweep's points are labelled with their swept values; a default run's
/// point has no label, and no empty text element stands for one.
#[test]
fn a_default_runs_point_has_no_empty_label() {
    let dir = tempfile::tempdir().unwrap();
    let rows = [
        row("ic", "default", 2.0, 0.1),
        row("path", "spp=4", 1.0, 0.2),
        row("path", "spp=16", 3.0, 0.1),
    ];
    bench::plot_scene(dir.path(), "s", &rows, &[]).unwrap();
    let svg = std::fs::read_to_string(dir.path().join("s_error_vs_time.svg")).unwrap();
    let texts: Vec<&str> = (svg.split("<text").skip(1))
        .filter_map(|t| Some(t.split_once('>')?.1.split_once("</text>")?.0.trim()))
        .collect();
    assert!(texts.contains(&"4") && texts.contains(&"16"), "{texts:?}");
    assert!(!texts.contains(&""), "{texts:?}");
}

/// A bench stopped between two runs (its stop flag set as the first run
/// finishes, as Ctrl-C sets it) writes `bench.csv` and the charts of the
/// runs it finished, names the others in order, and starts none of them.
/// The `bench.csv` and charts an earlier bench left are gone, also those
/// of the scene it reached no run of.
/// With `repeat`, every run is rendered once a round: its seconds are the
/// median of its rounds, its errors, records, rays and frames those of a
/// one-round bench (the later rounds trace the same rays, checked in debug
/// builds, and write no frames); one CSV line a run, each row handed on
/// once its rounds are done.
#[test]
fn repeated_runs_report_the_median_of_their_rounds() {
    let dir = tempfile::tempdir().unwrap();
    let (once_dir, thrice_dir) = (dir.path().join("once"), dir.path().join("thrice"));
    let once = bench::run(&tiny_bench(&once_dir, &["ic", "trc"])).unwrap();
    let opts = BenchOptions {
        repeat: 3,
        ..tiny_bench(&thrice_dir, &["ic", "trc"])
    };
    let mut handed = Vec::new();
    let report = bench::run_with(&opts, &mut |row| handed.push(row.seconds)).unwrap();
    assert_eq!(report.rows.len(), 2);
    assert_eq!(report.round_seconds.len(), 2);
    let rows = report.rows.iter().zip(&report.round_seconds);
    for ((row, rounds), one) in rows.zip(&once.rows) {
        assert_eq!(rounds.len(), 3, "{rounds:?}");
        assert!(rounds.iter().all(|&s| s > 0.0), "{rounds:?}");
        let mut sorted = rounds.clone();
        sorted.sort_by(f64::total_cmp);
        assert_eq!(row.seconds, sorted[1], "{rounds:?}");
        let measured = |r: &BenchRow| (r.rel_rmse, r.flicker, r.records, r.rays);
        assert_eq!(measured(row), measured(one), "{}", row.method);
        let frame = format!("runs/cube-in-box/{}-default/frame_0001.exr", row.method);
        let bytes = |d: &std::path::Path| std::fs::read(d.join(&frame)).unwrap();
        assert!(bytes(&thrice_dir) == bytes(&once_dir), "{frame}");
    }
    let medians: Vec<f64> = report.rows.iter().map(|r| r.seconds).collect();
    assert_eq!(handed, medians);
    assert!(once.round_seconds.iter().all(|r| r.len() == 1));
    let csv = std::fs::read_to_string(thrice_dir.join("bench.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    let text = bench::rounds_text(&report.rows, &report.round_seconds);
    assert_eq!(text.lines().count(), 2, "{text}");
    assert!(bench::rounds_text(&once.rows, &once.round_seconds).is_empty());
}

#[test]
fn a_stopped_bench_writes_the_runs_it_finished_and_names_the_others() {
    use std::sync::atomic::Ordering;
    let dir = tempfile::tempdir().unwrap();
    let earlier = ["bench.csv", "spheres_error_vs_time.svg"];
    for file in earlier {
        std::fs::write(dir.path().join(file), "an earlier bench's").unwrap();
    }
    let opts = BenchOptions {
        scenes: vec![
            SceneSource::Builtin("cube-in-box".into()),
            SceneSource::Builtin("spheres".into()),
        ],
        ..tiny_bench(dir.path(), &["path:spp=1,2"])
    };
    let mut finished = Vec::new();
    let report = bench::run_with(&opts, &mut |row| {
        finished.push(row.settings.clone());
        opts.stop.store(true, Ordering::Relaxed);
    })
    .unwrap();
    assert_eq!(finished, ["spp=1"]);
    assert_eq!(report.rows.len(), 1);
    assert_eq!(
        report.unfinished,
        [
            "cube-in-box path spp=2",
            "spheres path spp=1",
            "spheres path spp=2"
        ]
    );
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "{csv}");
    assert_eq!(lines[0], CSV_HEADER);
    assert!(lines[1].starts_with("cube-in-box,path,spp=1,"), "{csv}");
    assert_eq!(report.charts.len(), 4, "{:?}", report.charts);
    assert!(report.charts.iter().all(|c| c.is_file()));
    assert!(!dir.path().join("spheres_error_vs_time.svg").exists());
    // Neither the next run nor the next scene's reference was started.
    assert!(!dir.path().join("runs/cube-in-box/path-spp=2").exists());
    assert!(!dir.path().join("reference/spheres").exists());
}

/// While a bench goes on, `bench.csv` and `bench_seeds.csv` on disk hold
/// every run finished so far (as the callback of each sees them), so that
/// a bench killed outright keeps them; no temporary file is left beside
/// them.
#[test]
fn the_csvs_hold_every_finished_run_while_the_bench_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        seeds: 2,
        ..tiny_bench(dir.path(), &["path:spp=1,2", "ic"])
    };
    let read = |name: &str| std::fs::read_to_string(dir.path().join(name)).unwrap();
    let mut finished = Vec::new();
    let report = bench::run_with(&opts, &mut |row| {
        finished.push(row.clone());
        assert_eq!(read("bench.csv"), to_csv(&finished));
        let seeds = read("bench_seeds.csv");
        assert_eq!(seeds.lines().count(), 1 + 2 * finished.len(), "{seeds}");
    })
    .unwrap();
    assert_eq!(finished.len(), 3);
    assert_eq!(read("bench.csv"), to_csv(&report.rows));
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("tmp"))
        .collect();
    assert!(names.is_empty(), "{names:?}");
}

/// A run stopped mid-way (its stop flag set once its first frame is
/// written, as Ctrl-C sets it) is named unfinished and leaves none of its
/// frames: a run's folder holds a whole run or nothing.
#[test]
fn a_run_stopped_mid_way_leaves_no_frames() {
    use std::sync::atomic::Ordering;
    let dir = tempfile::tempdir().unwrap();
    let opts = BenchOptions {
        frames: 0..40,
        ..tiny_bench(dir.path(), &["path:spp=256"])
    };
    let run = dir.path().join("runs/cube-in-box/path-spp=256");
    let (first, stop) = (run.join("frame_0000.exr"), opts.stop.clone());
    let watcher = std::thread::spawn(move || {
        let start = std::time::Instant::now();
        while !first.exists() && start.elapsed().as_secs() < 120 {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        stop.store(true, Ordering::Relaxed);
    });
    let report = bench::run(&opts).unwrap();
    watcher.join().unwrap();
    assert!(report.rows.is_empty(), "the run finished before the stop");
    assert_eq!(report.unfinished, ["cube-in-box path spp=256"]);
    let left: Vec<_> = std::fs::read_dir(&run)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().starts_with("frame_"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    // The reference, finished before the run began, is whole.
    assert!(dir
        .path()
        .join("reference/cube-in-box/reference.json")
        .is_file());
}

/// A bench stopped before it starts renders nothing and writes a
/// `bench.csv` of no run in place of an earlier bench's.
#[test]
fn a_bench_stopped_before_it_starts_renders_nothing() {
    use std::sync::atomic::Ordering;
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bench.csv"), "an earlier bench's").unwrap();
    let opts = tiny_bench(dir.path(), &["path:spp=1"]);
    opts.stop.store(true, Ordering::Relaxed);
    let report = bench::run(&opts).unwrap();
    assert!(report.rows.is_empty() && report.charts.is_empty());
    assert_eq!(report.unfinished, ["cube-in-box path spp=1"]);
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    assert_eq!(csv.trim_end(), CSV_HEADER);
    assert!(!dir.path().join("reference").exists());
}

/// When [`interrupt_bench`] sends its SIGINT.
#[cfg(unix)]
enum Cue<'a> {
    /// Once this path exists under the bench's `--out` (the bench runs
    /// with `-q`).
    Made(&'a str),
    /// Once the bench has said a line containing this on stderr (it runs
    /// without `-q`, so that it says each run finished: off a terminal a
    /// line a run).
    Said(&'a str),
}

/// Runs `radcache bench` of cube-in-box's frames 0..2 at 16×16 on the CPU
/// with `--reference-spp REFERENCE_SPP --methods METHODS`, then `more`,
/// into `out`; sends it one SIGINT (Ctrl-C) at `cue`, checks that it exits
/// with status 130 and returns its output and how long it took after the
/// signal.
#[cfg(unix)]
fn interrupt_bench(
    (reference_spp, methods): (&str, &str),
    more: &[&str],
    out: &std::path::Path,
    cue: Cue,
) -> Interrupted {
    use std::io::BufRead;
    use std::time::{Duration, Instant};
    let tiny = ["--size", "16x16", "--frames", "0..2", "--backends", "cpu"];
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .arg("bench")
        .args(tiny)
        .args(["--reference-spp", reference_spp, "--methods", methods])
        .args(more)
        .args(matches!(cue, Cue::Made(_)).then_some("-q"))
        .arg("--out")
        .arg(out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Stderr is read as it comes, so that a line can be the cue and a full
    // pipe never stalls the bench.
    let said = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
    let reader = {
        let (said, stderr) = (said.clone(), child.stderr.take().unwrap());
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines() {
                let line = line.unwrap();
                let mut said = said.lock().unwrap();
                said.push_str(&line);
                said.push('\n');
            }
        })
    };
    let cued = || match cue {
        Cue::Made(path) => out.join(path).exists(),
        Cue::Said(words) => said.lock().unwrap().contains(words),
    };
    let start = Instant::now();
    while !cued() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no cue under {out:?}; the bench said:\n{}",
            said.lock().unwrap()
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let pid = child.id().to_string();
    let kill = std::process::Command::new("kill")
        .args(["-INT", &pid])
        .status()
        .unwrap();
    assert!(kill.success());
    let signalled = Instant::now();
    let output = child.wait_with_output().unwrap();
    reader.join().unwrap();
    let stderr = said.lock().unwrap().clone();
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    Interrupted {
        stdout: String::from_utf8_lossy(&output.stdout).into_owned(),
        stderr,
        after: signalled.elapsed(),
    }
}

/// How a bench that [`interrupt_bench`] stopped (with status 130) ended:
/// its output, and how long after the signal it stopped.
#[cfg(unix)]
struct Interrupted {
    stdout: String,
    stderr: String,
    after: std::time::Duration,
}

/// Ctrl-C during a run abandons it in the middle of its frame (one frame
/// of it takes about a minute on 2 cores), prints the table of the run
/// finished before and writes it to `bench.csv` in place of an earlier
/// bench's, says how many finished and which did not, not as an error,
/// and exits with status 130.
#[cfg(unix)]
#[test]
fn ctrl_c_during_a_run_keeps_the_runs_finished() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bench.csv"), "an earlier bench's").unwrap();
    // The second run's folder is made once the first run is measured.
    let Interrupted {
        stdout,
        stderr,
        after,
    } = interrupt_bench(
        ("2", "path:spp=1,100000"),
        &[],
        dir.path(),
        Cue::Made("runs/cube-in-box/path-spp=100000"),
    );
    assert!(!stderr.contains("error:"), "{stderr}");
    assert!(stderr.contains("Ctrl-C again to stop now"), "{stderr}");
    assert!(
        stderr.lines().any(|l| l
            .starts_with("interrupted: 1 of 2 runs finished (measured above and in")
            && l.ends_with("; not finished: cube-in-box path spp=100000")),
        "{stderr}"
    );
    assert!(after.as_secs() < 30, "stopped {after:?} after Ctrl-C");
    assert!(
        stdout.contains("spp=1 ") && !stdout.contains("spp=100000"),
        "{stdout}"
    );
    assert!(stdout.contains("bench.csv"), "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "{csv}");
    assert!(lines[1].starts_with("cube-in-box,path,spp=1,"), "{csv}");
    // The frame abandoned is not written.
    assert!(!dir
        .path()
        .join("runs/cube-in-box/path-spp=100000/frame_0000.exr")
        .exists());
}

/// Ctrl-C during the reference abandons it, leaving no `reference.json`
/// (the next bench renders it again), and the bench ends with no run
/// finished: status 130, no table, a `bench.csv` of no run.
#[cfg(unix)]
#[test]
fn ctrl_c_during_the_reference_finishes_no_run() {
    let dir = tempfile::tempdir().unwrap();
    let Interrupted {
        stdout,
        stderr,
        after,
    } = interrupt_bench(
        ("100000", "path:spp=1"),
        &[],
        dir.path(),
        Cue::Made("reference/cube-in-box"),
    );
    assert!(
        stderr.contains("interrupted: 0 of 1 runs finished")
            && stderr.contains("not finished: cube-in-box path spp=1"),
        "{stderr}"
    );
    assert!(after.as_secs() < 30, "stopped {after:?} after Ctrl-C");
    assert!(!stdout.contains("rel_rmse"), "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    assert_eq!(csv.trim_end(), CSV_HEADER);
    let reference = dir.path().join("reference/cube-in-box");
    assert!(!reference.join("reference.json").exists());
    assert!(!reference.join("frame_0000.exr").exists());
    assert!(!dir.path().join("runs").exists());
}

/// Ctrl-C in a later round of `--repeat` (every run measured in the
/// first) keeps the rounds done: each run's table row with its seconds the
/// median of the rounds it finished (fewer than asked), written to
/// `bench.csv`, and every round printed; the bench says every run was
/// measured over fewer rounds than asked, and exits with status 130.
#[cfg(unix)]
#[test]
fn ctrl_c_in_a_later_round_keeps_the_rounds_done() {
    let dir = tempfile::tempdir().unwrap();
    // Said once the first run is timed again, in the second round; a
    // round takes about a tenth of a second (the second run's), so the
    // hundred would take seconds.
    let Interrupted {
        stdout,
        stderr,
        after,
    } = interrupt_bench(
        ("2", "path:spp=1,256"),
        &["--repeat", "100"],
        dir.path(),
        Cue::Said("(again)"),
    );
    assert!(!stderr.contains("error:"), "{stderr}");
    assert!(
        stderr.contains(
            "interrupted: every run was measured (above), some over fewer rounds than \
             --repeat asked"
        ),
        "{stderr}"
    );
    assert!(after.as_secs() < 30, "stopped {after:?} after Ctrl-C");
    // Each run's rounds, printed after the table: "… spp=1 on cpu …:
    // 0.010 / 0.009 s → 0.010 s". The first run finished at least two, and
    // no run all a hundred.
    let rounds = |settings: &str| -> Vec<f64> {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("cube-in-box path {settings} on cpu")))
            .unwrap_or_else(|| panic!("no rounds of {settings}:\n{stdout}"));
        let (_, times) = line.split_once(": ").unwrap();
        let (times, _) = times.split_once(" s →").unwrap();
        times.split(" / ").map(|t| t.parse().unwrap()).collect()
    };
    let (first, second) = (rounds("spp=1"), rounds("spp=256"));
    assert!((2..100).contains(&first.len()), "{stdout}");
    assert!((1..100).contains(&second.len()), "{stdout}");
    assert!(first.len().abs_diff(second.len()) <= 1, "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 3, "{csv}");
    assert!(lines[1].starts_with("cube-in-box,path,spp=1,"), "{csv}");
    assert!(lines[2].starts_with("cube-in-box,path,spp=256,"), "{csv}");
    // The table's seconds are the median of the rounds done.
    let median = |mut t: Vec<f64>| {
        t.sort_by(f64::total_cmp);
        let n = t.len();
        (t[(n - 1) / 2] + t[n / 2]) / 2.0
    };
    let seconds: f64 = lines[2].split(',').nth(5).unwrap().parse().unwrap();
    assert!((seconds - median(second)).abs() < 1e-3, "{csv}\n{stdout}");
}
