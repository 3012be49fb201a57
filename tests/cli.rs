//! The `radcache` binary end to end: a tiny render writes its frames, and
//! bad input of every kind ends in a clear message and a non-zero status,
//! never a panic.

use std::process::Command;

fn radcache(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(args)
        .output()
        .expect("the binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn tiny_render_writes_exr_and_png_per_frame() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    for method in ["path", "ic"] {
        let (code, stdout, stderr) = radcache(&[
            "render", "--method", method, "--frames", "2..4", "--size", "12x10", "--spp", "2",
            "--out", out, "-q",
        ]);
        assert_eq!(code, 0, "{method}: {stderr}");
        assert!(stdout.contains("rendered 2 frames"), "{stdout}");
        for f in [2, 3] {
            for ext in ["exr", "png"] {
                let path = dir.path().join(format!("frame_{f:04}.{ext}"));
                assert!(path.is_file(), "{method}: missing {}", path.display());
            }
        }
        let film = radcache::film::read_exr(&dir.path().join("frame_0003.exr")).unwrap();
        assert_eq!((film.width, film.height), (12, 10));
        assert!(film.mean() > 0.0, "{method}: black frame");
    }
}

/// `render` without `--method` renders with `trc`, the method the product
/// is built around (the README's first command relies on it).
#[test]
fn render_defaults_to_trc() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let (code, stdout, stderr) = radcache(&[
        "render", "--frames", "0..2", "--size", "8x8", "--spp", "1", "--out", out,
    ]);
    assert_eq!(code, 0, "{stderr}");
    let said = format!("{stdout}{stderr}");
    assert!(said.contains("method trc"), "{said}");
    assert!(said.contains("records reused"), "trc's statistics: {said}");
}

/// `--threads N` sets how many worker threads render, and the frames do
/// not depend on it: `trc` and `tcg` on the moving cube (their records
/// live across frames; their render tiles and gather tasks are cut per
/// thread, here 192, 96 and 64 pixels a tile, and `tcg`'s shots are made
/// in parallel) write the same EXR bytes on 1, 2 and 3 threads.
#[test]
fn frames_are_the_same_on_any_number_of_threads() {
    let dir = tempfile::tempdir().unwrap();
    for method in ["trc", "tcg"] {
        let mut frames = Vec::new();
        for threads in ["1", "2", "3"] {
            let out = dir.path().join(method).join(threads);
            let (code, stdout, stderr) = radcache(&[
                "render",
                "--method",
                method,
                "--threads",
                threads,
                "--backend",
                "cpu",
                "--frames",
                "0..3",
                "--size",
                "24x16",
                "--spp",
                "2",
                "--out",
                out.to_str().unwrap(),
            ]);
            assert_eq!(code, 0, "{method} on {threads} threads: {stderr}");
            let noun = if threads == "1" { "thread" } else { "threads" };
            let said = format!("{stdout}{stderr}");
            assert!(said.contains(&format!("cpu ({threads} {noun})")), "{said}");
            let bytes: Vec<Vec<u8>> = (0..3)
                .map(|f| std::fs::read(out.join(format!("frame_{f:04}.exr"))).unwrap())
                .collect();
            frames.push(bytes);
        }
        assert!(frames[0] == frames[1], "{method}: 1 and 2 threads differ");
        assert!(frames[0] == frames[2], "{method}: 1 and 3 threads differ");
    }
}

#[test]
fn bad_input_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("broken.glb");
    std::fs::write(&garbage, b"glTF\x02\x00\x00\x00garbage").unwrap();
    let garbage = garbage.to_str().unwrap();
    let cases: &[(&[&str], &str)] = &[
        (&["render", "missing.glb"], "missing.glb"),
        (&["render", garbage], "broken.glb"),
        (&["render", "--builtin", "nope"], "unknown built-in scene"),
        (&["render", "--size", "0x4"], "out of range"),
        (&["render", "--size", "abc"], "not an image size"),
        (&["render", "--frames", "5..2"], "empty"),
        (&["render", "--fps", "nan"], "fps"),
        (&["render", "--threads", "0"], "--threads"),
        (&["render", "--threads", "many"], "--threads"),
        (&["render", "--threads", "5000"], "1..=1024"),
        (
            &[
                "render",
                "--method",
                "movies",
                "--movies-texels-per-pixel",
                "1e9",
            ],
            "expected a number from 0.01 to 16",
        ),
        (
            &["render", "--method", "ic", "--ic-accuracy", "0"],
            "accuracy",
        ),
        (
            &["render", "--method", "ic", "--ic-strata", "1000x1000"],
            "too many",
        ),
        (&["render", "--method", "teleport"], "invalid value"),
        (
            &["bench", "--methods", "ic:glossy=mirror"],
            "expected path or eas",
        ),
        (&["bench", "--methods", "movies:glossy=eas"], "glossy"),
        (
            &["compare", "/nonexistent/ref", "/nonexistent/test"],
            "does not exist",
        ),
        (&["bench", "--methods", "path:warp=9"], "warp"),
        (
            &["render", "--job", "job-3"],
            "radcache serve gives its own jobs",
        ),
        (&["render", "--fps", "1e-40"], "0.001..=100000"),
        (
            &[
                "render", "--size", "8x8", "--frames", "0..1", "--out", garbage,
            ],
            "broken.glb is a file",
        ),
        (
            &["render", "--frames", "0..1000001"],
            "last frame number, 999999",
        ),
        (
            &[
                "render",
                "--method",
                "ic",
                "--ic-min-spacing",
                "100",
                "--ic-max-spacing",
                "2",
            ],
            "--ic-min-spacing 100 is over --ic-max-spacing 2",
        ),
        (
            &[
                "render",
                "--method",
                "tcg",
                "--tcg-tau-min",
                "0.5",
                "--tcg-tau-max",
                "0.1",
            ],
            "--tcg-tau-min 0.5 is over --tcg-tau-max 0.1",
        ),
        (
            &["bench", "--methods", "tcg:tau_min=0.5:tau_max=0.1"],
            "tau_min 0.5 is over tau_max 0.1",
        ),
        (
            &["serve", "--scenes", "/nonexistent/scenes"],
            "no such directory",
        ),
        (
            &["render", "/"],
            "is a directory; expected a .gltf or .glb file",
        ),
        (
            &["render", "--method", "ic", "--ic-strata", "1x65537"],
            "1x65537 cells per record is too many",
        ),
        (
            &["render", "--method", "ic", "--ic-strata", "+4x4"],
            "is not MxN",
        ),
        (
            &["compare", "/", "/nonexistent/test"],
            "test directory /nonexistent/test does not exist",
        ),
        (
            &["compare", garbage, "/"],
            "broken.glb is a file; expected a directory",
        ),
        (
            &["compare", "/", "/", "--error-maps", garbage],
            "cannot make the error maps' folder",
        ),
        (
            &["serve", "--addr", "0.0.0.0:1", "--token", ""],
            "--token (or RADCACHE_TOKEN) is empty",
        ),
        (
            &["serve", "--out", garbage],
            "is a file; the server writes each job's frames in a directory there",
        ),
        // Past the range `POST /api/jobs` takes too: each flag has the
        // range of its name, and says it.
        (
            &[
                "render",
                "--method",
                "movies",
                "--movies-spacing",
                "2",
                "--out",
                garbage,
            ],
            "invalid value '2' for '--movies-spacing <MOVIES_SPACING>': expected a number from 0.001 to 1",
        ),
        (
            &[
                "render",
                "--method",
                "ic",
                "--max-depth",
                "20000",
                "--out",
                garbage,
            ],
            "invalid value '20000' for '--max-depth <MAX_DEPTH>': expected a number from 0 to 10000",
        ),
    ];
    for (args, expected) in cases {
        let (code, _, stderr) = radcache(args);
        assert_ne!(code, 0, "{args:?} succeeded");
        assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
        assert!(
            stderr.contains(expected),
            "{args:?}: expected '{expected}' in: {stderr}"
        );
    }
}

/// A server that refuses its options makes no store and does not say it
/// makes one (it said "a new, empty one is made there", then refused).
#[test]
fn a_refused_serve_makes_no_store_and_says_none() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("db");
    let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["serve", "--addr", "0.0.0.0:0", "--db"])
        .arg(&db)
        .env_remove("RADCACHE_TOKEN")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("requires --token"), "{stderr}");
    assert!(!stderr.contains("new, empty one"), "{stderr}");
    assert!(!db.exists());
}

/// `RAYON_NUM_THREADS`, which stands for `--threads` where that is not
/// given, is held to the same range (99,999 threads swamped the machine).
#[test]
fn rayon_num_threads_is_held_to_the_threads_range() {
    for (value, expected) in [
        ("1100", "RAYON_NUM_THREADS=1100: at most 1024"),
        ("lots", "is not a number of worker threads"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
            .args(["render", "--size", "4x4", "--frames", "0..1"])
            .env("RAYON_NUM_THREADS", value)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{value}: {stderr}");
        assert!(stderr.contains(expected), "{value}: {stderr}");
    }
}

/// Standard output closed by its reader (`radcache … | head -1`) ends the
/// output quietly once the work is done; a full one is a clear error. Both
/// panicked in `println!`.
#[test]
fn a_closed_or_full_standard_output_is_no_panic() {
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let render = [
        "render", "--size", "4x4", "--frames", "0..1", "--spp", "1", "--out",
    ];
    let mut child = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(render)
        .arg(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(dir.path().join("frame_0000.exr").is_file());

    let full = std::fs::OpenOptions::new().write(true).open("/dev/full");
    if let Ok(full) = full {
        let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
            .args(render)
            .arg(dir.path())
            .stdout(full)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains("cannot write to standard output"),
            "{stderr}"
        );
    }
}

/// `serve` on an address another program holds fails before it makes a
/// store, so no empty store is left where `--db` pointed, nor said to be
/// made.
#[test]
fn serve_on_a_taken_address_leaves_no_store() {
    let dir = tempfile::tempdir().unwrap();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let db = dir.path().join("db");
    let (code, _, stderr) = radcache(&["serve", "--addr", &addr, "--db", db.to_str().unwrap()]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains(&format!("cannot listen on {addr}")),
        "{stderr}"
    );
    assert!(!db.exists(), "a store was made at {}", db.display());
    assert!(!stderr.contains("new, empty one"), "{stderr}");
}

/// A bench whose last scene does not load fails before it benches the
/// first: no reference rendered, no minutes lost.
#[test]
fn bench_checks_every_scene_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let out_arg = out.to_str().unwrap();
    let (code, _, stderr) = radcache(&[
        "bench",
        "--scenes",
        "cube-in-box,/nonexistent/later.glb",
        "--size",
        "8x8",
        "--frames",
        "0..1",
        "--reference-spp",
        "4",
        "--methods",
        "path:spp=1",
        "--out",
        out_arg,
    ]);
    assert_ne!(code, 0);
    assert!(stderr.contains("later.glb"), "{stderr}");
    assert!(!out.join("reference").exists(), "a reference was rendered");
}

/// Off a terminal a bench says each run as it ends (its bars are drawn on
/// terminals only); with `-q` it says nothing.
#[test]
fn bench_progress_is_a_line_per_run_off_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    for quiet in [false, true] {
        let out = dir.path().join(format!("bench-{quiet}"));
        let mut args = vec![
            "bench",
            "--scenes",
            "cube-in-box",
            "--size",
            "8x8",
            "--frames",
            "0..2",
            "--reference-spp",
            "2",
            "--methods",
            "path:spp=1,2",
            "--backends",
            "cpu",
            "--out",
            out.to_str().unwrap(),
        ];
        if quiet {
            args.push("-q");
        }
        let (code, _, stderr) = radcache(&args);
        assert_eq!(code, 0, "{stderr}");
        let lines: Vec<&str> = stderr
            .lines()
            .filter(|l| l.starts_with("bench: "))
            .collect();
        let expected = if quiet { 0 } else { 2 };
        assert_eq!(lines.len(), expected, "{stderr}");
        for (line, spp) in lines.iter().zip(["spp=1", "spp=2"]) {
            assert!(line.starts_with("bench: cube-in-box path "), "{line}");
            assert!(
                line.contains(spp) && line.contains("relative RMSE"),
                "{line}"
            );
        }
    }
}

/// `inspect` lists a job's records by object and, where the job's scene
/// still loads as it was rendered, splits them between the objects that
/// move and those that do not (here against the scene's own animation);
/// once the scene file is gone only the list by object is left.
#[test]
fn inspect_splits_records_between_moving_and_static_objects() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("cube_in_box.glb");
    let src =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scenes/cube_in_box.glb");
    std::fs::copy(&src, &scene).unwrap();
    let db = dir.path().join("db");
    let (db, scene_arg) = (db.to_str().unwrap(), scene.to_str().unwrap());
    let out = dir.path().join("frames");
    let (code, _, stderr) = radcache(&[
        "render",
        scene_arg,
        "--method",
        "trc",
        "--frames",
        "0..3",
        "--size",
        "16x16",
        "--spp",
        "1",
        "--db",
        db,
        "--job",
        "j",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");

    let (code, json, stderr) = radcache(&["inspect", "--db", db, "j", "--json"]);
    assert_eq!(code, 0, "{stderr}");
    let report: serde_json::Value = serde_json::from_str(&json).unwrap();
    let job = &report["jobs"][0];
    let by_object = job["records_by_object"].as_object().unwrap();
    let count = |f: &dyn Fn(&str) -> bool| -> u64 {
        by_object
            .iter()
            .filter(|(object, _)| f(object))
            .map(|(_, r)| r["records"].as_u64().unwrap())
            .sum()
    };
    assert_eq!(count(&|_| true), job["records"].as_u64().unwrap());
    let lifespans: u64 = by_object
        .values()
        .map(|r| r["lifespan_frames"].as_u64().unwrap())
        .sum();
    let histogram: u64 = job["lifespan_histogram"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(life, n)| life.parse::<u64>().unwrap() * n.as_u64().unwrap())
        .sum();
    assert_eq!(lifespans, histogram);
    let loaded = radcache::scene::Scene::load(&scene).unwrap();
    let animated: Vec<u64> = (0..loaded.objects.len())
        .filter(|&o| loaded.object_is_dynamic(o))
        .map(|o| o as u64)
        .collect();
    let listed: Vec<u64> = job["moving_objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o.as_u64().unwrap())
        .collect();
    assert_eq!(listed, animated);
    let on_moving = count(&|o| animated.contains(&o.parse().unwrap()));
    assert!(on_moving > 0, "the cube holds records: {by_object:?}");

    let (code, text, _) = radcache(&["inspect", "--db", db, "j"]);
    assert_eq!(code, 0);
    let split = format!("records on moving objects: {on_moving} ");
    assert!(text.contains(&split), "{text}");
    assert!(text.contains("records by object"), "{text}");

    // One frame of the job: a finished one is shown, one not finished is
    // an error (with or without --json), as a job the store lacks is.
    let (code, _, stderr) = radcache(&["inspect", "--db", db, "j", "--frame", "2"]);
    assert_eq!(code, 0, "{stderr}");
    for json in [false, true] {
        let mut args = vec!["inspect", "--db", db, "j", "--frame", "7"];
        if json {
            args.push("--json");
        }
        let (code, out, stderr) = radcache(&args);
        assert_eq!(code, 1, "{out}");
        assert!(
            stderr.contains("frame 7 is not among this job's finished frames (3 of frames 0..3 done, the last 2)"),
            "{stderr}"
        );
    }

    std::fs::remove_file(&scene).unwrap();
    let (code, text, stderr) = radcache(&["inspect", "--db", db, "j"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(!text.contains("records on moving objects"), "{text}");
    assert!(text.contains("records by object"), "{text}");
}

/// Runs `radcache ARGS`, sends it one SIGINT (Ctrl-C) `settle` after
/// `file` appears, and returns what it printed and how it ended.
#[cfg(unix)]
fn interrupt_once_written(
    args: &[&str],
    file: &std::path::Path,
    settle: std::time::Duration,
) -> std::process::Output {
    interrupt_once_written_times(args, file, settle, 1)
}

/// [`interrupt_once_written`] with `times` SIGINTs, 200 ms apart.
#[cfg(unix)]
fn interrupt_once_written_times(
    args: &[&str],
    file: &std::path::Path,
    settle: std::time::Duration,
    times: u32,
) -> std::process::Output {
    use std::time::{Duration, Instant};
    let child = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !file.exists() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no {file:?} written"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    std::thread::sleep(settle);
    let pid = child.id().to_string();
    for k in 0..times {
        if k > 0 {
            std::thread::sleep(Duration::from_millis(200));
        }
        let kill = Command::new("kill").args(["-INT", &pid]).status().unwrap();
        assert!(kill.success());
    }
    child.wait_with_output().unwrap()
}

/// A second Ctrl-C stops a render at once (status 130) and says what it
/// leaves: the frame in progress is lost, those written are kept.
#[cfg(unix)]
#[test]
fn a_second_ctrl_c_stops_at_once_and_says_so() {
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    // Frames long enough that the second Ctrl-C, 200 ms after the first,
    // comes while one is in progress; where a machine finishes the frame
    // first (stopped after it), larger frames are tried.
    for size in ["256x256", "512x512", "1024x1024"] {
        let out = dir.path().join(size);
        let args = [
            "render",
            "--backend",
            "cpu",
            "--method",
            "path",
            "--frames",
            "0..50",
            "--size",
            size,
            "--spp",
            "64",
            "--out",
            out.to_str().unwrap(),
            "-q",
        ];
        let output =
            interrupt_once_written_times(&args, &out.join("frame_0000.exr"), Duration::ZERO, 2);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains("Ctrl-C again to stop now"), "{stderr}");
        if stderr.contains("interrupted after frame") {
            continue;
        }
        assert_eq!(output.status.code(), Some(130), "{stderr}");
        assert!(
            stderr.contains("stopped at once: the frame in progress is lost"),
            "{stderr}"
        );
        assert!(out.join("frame_0000.exr").exists());
        return;
    }
    panic!("every frame ended before the second Ctrl-C came");
}

/// Ctrl-C (SIGINT) stops a render once the frame in progress is written
/// and saved, says where it stopped and how to go on, and the same command
/// then renders the rest from the store.
#[cfg(unix)]
#[test]
fn ctrl_c_stops_after_a_saved_frame_and_the_same_command_resumes() {
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    let (db, out) = (dir.path().join("db"), dir.path().join("out"));
    let args = [
        "render",
        "--backend",
        "cpu",
        "--frames",
        "0..200",
        "--size",
        "24x24",
        "--spp",
        "2",
        "--db",
        db.to_str().unwrap(),
        "--job",
        "long",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ];
    let output = interrupt_once_written(&args, &out.join("frame_0001.exr"), Duration::ZERO);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // Said as what it is, not as an error.
    assert!(
        stderr
            .lines()
            .any(|l| l.starts_with("interrupted after frame")),
        "{stderr}"
    );
    assert!(
        stderr.contains("the same command renders the rest"),
        "{stderr}"
    );
    let written = (0..200)
        .take_while(|f| out.join(format!("frame_{f:04}.exr")).exists())
        .count();
    assert!((2..200).contains(&written), "{written} frames written");
    assert!(
        (written..200).all(|f| !out.join(format!("frame_{f:04}.exr")).exists()),
        "the frames written are a prefix of the range"
    );
    assert!(
        stderr.contains(&format!("{written} of 200 frames")),
        "{written}: {stderr}"
    );

    let (code, stdout, stderr) = radcache(&args);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains(&format!("{written} frames resumed from the store")),
        "{stdout}"
    );
    assert!(out.join("frame_0199.exr").exists());
}

/// A `trc` job's finished frames that a run over another range renders
/// again (its cache runs from that range's first frame) are not replaced
/// without a word.
#[test]
fn frames_a_stateful_job_renders_again_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let (db, out) = (dir.path().join("db"), dir.path().join("out"));
    let run = |frames: &str| {
        radcache(&[
            "render",
            "--backend",
            "cpu",
            "--method",
            "trc",
            "--frames",
            frames,
            "--size",
            "8x8",
            "--spp",
            "1",
            "--db",
            db.to_str().unwrap(),
            "--job",
            "t",
            "--out",
            out.to_str().unwrap(),
            "-q",
        ])
    };
    let (code, _, stderr) = run("0..3");
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains("rendered again"), "{stderr}");
    let (code, _, stderr) = run("1..3");
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains(
            "job \"t\": 2 of the 2 finished frames of 1..3 are rendered again (and replaced), 0 skipped"
        ),
        "{stderr}"
    );
    let (code, _, stderr) = run("1..3");
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains("rendered again"), "{stderr}");
}

/// A job's scene file is stored by its absolute path: run again from
/// another directory by another relative name it resumes and the stored
/// name stays the same file; a changed file is refused for its content
/// alone, not also for its name.
#[test]
fn a_jobs_scene_is_stored_by_its_absolute_path() {
    let dir = tempfile::tempdir().unwrap();
    let sc = dir.path().join("sc");
    std::fs::create_dir(&sc).unwrap();
    let src =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scenes/block_jumps.gltf");
    std::fs::copy(&src, sc.join("s.gltf")).unwrap();
    let db = dir.path().join("db");
    let run = |cwd: &std::path::Path, scene: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
            .current_dir(cwd)
            .args(["render", scene, "--method", "path", "--frames", "0..1"])
            .args(["--size", "8x8", "--spp", "1", "--backend", "cpu", "-q"])
            .args(["--job", "j", "--out", "out", "--db"])
            .arg(&db)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            stderr,
        )
    };
    let (code, _, stderr) = run(dir.path(), "sc/s.gltf");
    assert_eq!(code, Some(0), "{stderr}");
    let (code, stdout, stderr) = run(&sc, "./s.gltf");
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stdout.contains("1 frames resumed from the store"),
        "{stdout}"
    );
    let (_, inspect, _) = radcache(&["inspect", "--db", db.to_str().unwrap(), "j"]);
    let absolute = sc.join("s.gltf");
    assert!(inspect.contains(absolute.to_str().unwrap()), "{inspect}");
    let mut text = std::fs::read_to_string(sc.join("s.gltf")).unwrap();
    text.push('\n');
    std::fs::write(sc.join("s.gltf"), text).unwrap();
    let (code, _, stderr) = run(dir.path(), "sc/s.gltf");
    assert_ne!(code, Some(0), "{stderr}");
    assert!(stderr.contains("scene hash"), "{stderr}");
    assert!(!stderr.contains("scene (stored"), "{stderr}");
}

/// A Ctrl-C during the range's last frame stops nothing: the frame is
/// finished and written, and the render ends as one that was never
/// interrupted (exit 0, no "interrupted" error). The signal is sent just
/// after frame 0 of two is written; should it land before frame 0 is done
/// (the render then rightly stops after it), the try is made again.
#[cfg(unix)]
#[test]
fn ctrl_c_during_the_last_frame_lets_the_render_finish() {
    use std::time::Duration;
    for _try in 0..3 {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let args = [
            "render",
            "--backend",
            "cpu",
            "--method",
            "path",
            "--spp",
            "64",
            "--size",
            "128x128",
            "--frames",
            "0..2",
            "--out",
            out.to_str().unwrap(),
        ];
        // The PNG file exists before it is whole: give its writing time
        // to end (a frame takes about ten times as long).
        let settle = Duration::from_millis(100);
        let output = interrupt_once_written(&args, &out.join("frame_0000.png"), settle);
        let stderr = String::from_utf8_lossy(&output.stderr);
        if stderr.contains("interrupted after frame 0:") {
            continue; // the signal came before frame 0 was done
        }
        assert_eq!(output.status.code(), Some(0), "{stderr}");
        assert!(
            stderr.contains("stopping once the frame in progress"),
            "{stderr}"
        );
        assert!(!stderr.contains("interrupted"), "{stderr}");
        assert!(out.join("frame_0001.exr").exists() && out.join("frame_0001.png").exists());
        return;
    }
    panic!("in three tries the signal never came during the last frame");
}

/// `cube_in_box.glb` with its JSON chunk edited by `edit`, written to
/// `path` (the binary chunk kept as it is).
fn edited_cube_in_box(path: &std::path::Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let glb = std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scenes/cube_in_box.glb"),
    )
    .unwrap();
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    let json_len = word(12);
    let mut json: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    edit(&mut json);
    let mut text = serde_json::to_vec(&json).unwrap();
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let rest = &glb[20 + json_len..];
    let mut out = Vec::new();
    out.extend_from_slice(&glb[..8]);
    out.extend_from_slice(&((20 + text.len() + rest.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(&glb[16..20]);
    out.extend_from_slice(&text);
    out.extend_from_slice(rest);
    std::fs::write(path, out).unwrap();
}

/// What a file from Blender needs said: which of its cameras renders, that
/// its point lights' intensities may be in candela, and what it holds that
/// is not rendered (a material extension, a line primitive).
#[test]
fn a_blender_file_is_told_its_camera_and_light_units() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("from_blender.glb");
    edited_cube_in_box(&file, |j| {
        j["asset"]["generator"] = serde_json::json!("Khronos glTF Blender I/O v3.4.50");
        j["extensionsUsed"] =
            serde_json::json!(["KHR_lights_punctual", "KHR_materials_transmission"]);
        let mut line = j["meshes"][0]["primitives"][0].clone();
        line["mode"] = serde_json::json!(1);
        j["meshes"][0]["primitives"]
            .as_array_mut()
            .unwrap()
            .push(line);
        j["extensions"] = serde_json::json!({"KHR_lights_punctual": {"lights": [
            {"type": "point", "intensity": 1.0}
        ]}});
        let nodes = j["nodes"].as_array_mut().unwrap();
        let camera = nodes
            .iter()
            .position(|n| n.get("camera").is_some())
            .unwrap();
        let mut second = nodes[camera].clone();
        second["name"] = serde_json::json!("second camera");
        nodes.push(second);
        nodes.push(
            serde_json::json!({"name": "bulb", "translation": [0.0, 1.0, 0.0],
                                      "extensions": {"KHR_lights_punctual": {"light": 0}}}),
        );
        let n = nodes.len();
        let roots = j["scenes"][0]["nodes"].as_array_mut().unwrap();
        roots.extend([serde_json::json!(n - 2), serde_json::json!(n - 1)]);
    });
    let stderr = one_tiny_frame(&[file.to_str().unwrap()], &dir.path().join("out"));
    assert!(stderr.contains("2 cameras in the scene"), "{stderr}");
    assert!(stderr.contains("683 times too bright"), "{stderr}");
    assert!(
        stderr.contains("extension(s) ignored: KHR_materials_transmission"),
        "{stderr}"
    );
    assert!(
        stderr.contains("1 point or line primitive(s) ignored"),
        "{stderr}"
    );
}

/// A size whose ratio is not the camera's `aspectRatio` renders (the
/// vertical field of view kept) with a note; the file's own ratio without.
#[test]
fn an_image_ratio_other_than_the_cameras_is_noted() {
    let dir = tempfile::tempdir().unwrap();
    let scene =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scenes/l_hall.glb");
    let render = |size: &str| {
        let out = dir.path().join(size);
        one_tiny_frame(&[scene.to_str().unwrap(), "--size", size], &out)
    };
    let square = render("8x8");
    assert!(
        square.contains("camera's aspectRatio is 1.600 and the image's 1.000"),
        "{square}"
    );
    let own = render("16x10");
    assert!(!own.contains("aspectRatio"), "{own}");
}

/// Keys that fall on the frames of another rate than `--fps` (a 30 fps
/// export rendered at the default 24) are noted with the rate they fit.
#[test]
fn keys_on_another_frame_rate_are_noted() {
    let dir = tempfile::tempdir().unwrap();
    let render = |fps: &str| {
        let out = dir.path().join(fps);
        one_tiny_frame(&["--builtin", "cube-in-box", "--fps", fps], &out)
    };
    let other = render("30");
    assert!(
        other.contains("keys fall on frames of 1/24 s, not of 1/30 s"),
        "{other}"
    );
    let own = render("24");
    assert!(!own.contains("keys fall"), "{own}");
}

/// `radcache render` of one 4×4 frame (`path`, 1 spp; `scene` may also
/// give another `--size` or `--fps`) into `out`, which must succeed; its
/// stderr.
fn one_tiny_frame(scene: &[&str], out: &std::path::Path) -> String {
    one_tiny_frame_with(&[&["--method", "path"], scene].concat(), out)
}

/// `inspect --json` shows a job's `settings` as an object of every setting
/// by the names a served job shows and `POST /api/jobs` takes (flags as
/// booleans), not as their JSON text in a string.
#[test]
fn inspect_json_shows_settings_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("db");
    let out = dir.path().join("frames");
    let (code, _, stderr) = radcache(&[
        "render",
        "--method",
        "ic",
        "--ic-accuracy",
        "0.3",
        "--ic-strata",
        "4x12",
        "--ic-no-gradients",
        "--frames",
        "0..1",
        "--size",
        "8x8",
        "--spp",
        "1",
        "--db",
        db.to_str().unwrap(),
        "--job",
        "j",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (code, json, stderr) = radcache(&["inspect", "--db", db.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{stderr}");
    let report: serde_json::Value = serde_json::from_str(&json).unwrap();
    let settings = &report["jobs"][0]["settings"];
    assert!(settings.is_object(), "{settings}");
    assert_eq!(settings["accuracy"], 0.3, "{settings}");
    assert_eq!(settings["strata"], "4x12", "{settings}");
    assert_eq!(settings["gradients"], false, "{settings}");
    assert_eq!(settings["spp"], 1, "{settings}");
}

/// `radcache render` of one 4×4 frame (1 spp) with `args` (a `--method`
/// among them; they may give another `--size`) into `out`, which must
/// succeed; its stderr.
fn one_tiny_frame_with(args: &[&str], out: &std::path::Path) -> String {
    let fixed = ["--spp", "1", "--frames", "0..1", "-q"];
    let size: &[&str] = if args.contains(&"--size") {
        &[]
    } else {
        &["--size", "4x4"]
    };
    let out = ["--out", out.to_str().unwrap()];
    let args = [&["render"], args, &fixed, size, &out].concat();
    let (code, _, stderr) = radcache(&args);
    assert_eq!(code, 0, "{stderr}");
    stderr
}

/// A flag of a method other than the one rendered is not dropped without a
/// word: each is named with the methods it applies to. `ic`'s flags, with
/// which `trc` and `tcg` make their records, and the flags every method
/// takes (`--spp`, `--max-depth`) are not.
#[test]
fn flags_of_another_method_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let ic = one_tiny_frame_with(
        &[
            "--method",
            "ic",
            "--trc-at",
            "5",
            "--movies-links",
            "4",
            "--ic-accuracy",
            "0.3",
            "--max-depth",
            "3",
        ],
        &dir.path().join("ic"),
    );
    assert!(
        ic.contains("warning: --trc-at applies to --method trc only; --method ic ignores it"),
        "{ic}"
    );
    assert!(
        ic.contains("warning: --movies-links applies to --method movies only"),
        "{ic}"
    );
    assert!(!ic.contains("--ic-accuracy"), "{ic}");
    assert!(!ic.contains("--max-depth"), "{ic}");
    let path = one_tiny_frame_with(
        &[
            "--method",
            "path",
            "--ic-no-gradients",
            "--tcg-tau-min",
            "0.1",
        ],
        &dir.path().join("path"),
    );
    assert!(
        path.contains(
            "warning: --ic-no-gradients applies to --method ic, trc or tcg; --method path ignores it"
        ),
        "{path}"
    );
    assert!(
        path.contains("warning: --tcg-tau-min applies to --method tcg only"),
        "{path}"
    );
    // Glossy records asked of a method that keeps none: warned of, not
    // also refused (as it once was, after the warning had said "ignores").
    let path_eas = one_tiny_frame_with(
        &["--method", "path", "--ic-glossy", "eas"],
        &dir.path().join("path_eas"),
    );
    assert!(
        path_eas.contains(
            "warning: --ic-glossy applies to --method ic, trc or tcg; --method path ignores it"
        ),
        "{path_eas}"
    );
    let tau = one_tiny_frame_with(
        &["--method", "ic", "--ic-eas-tau", "0.5"],
        &dir.path().join("tau"),
    );
    assert!(
        tau.contains("warning: --ic-eas-tau applies with --ic-glossy eas only"),
        "{tau}"
    );
    let tau_eas = one_tiny_frame_with(
        &[
            "--method",
            "ic",
            "--ic-glossy",
            "eas",
            "--ic-eas-tau",
            "0.5",
        ],
        &dir.path().join("tau_eas"),
    );
    assert!(!tau_eas.contains("warning"), "{tau_eas}");
    for method in ["trc", "tcg"] {
        let said = one_tiny_frame_with(
            &[
                "--method",
                method,
                "--ic-strata",
                "4x12",
                "--ic-accuracy",
                "0.5",
            ],
            &dir.path().join(method),
        );
        assert!(!said.contains("warning"), "{method}: {said}");
    }
}

/// A material's factors outside [0, 1] (the range glTF gives them) are
/// clamped with a warning naming the file, the material (index and name)
/// and the value; so is an alpha below 1 that blending would need, which
/// the renderer, drawing every surface opaque, ignores.
#[test]
fn material_factors_out_of_range_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("overbright.glb");
    edited_cube_in_box(&file, |j| {
        let red = &mut j["materials"][1];
        assert_eq!(red["name"], "red");
        red["pbrMetallicRoughness"]["baseColorFactor"] = serde_json::json!([1.5, 0.5, -0.25, 1.0]);
        red["pbrMetallicRoughness"]["metallicFactor"] = serde_json::json!(2.0);
        red["pbrMetallicRoughness"]["roughnessFactor"] = serde_json::json!(-1.0);
        let green = &mut j["materials"][2];
        green["pbrMetallicRoughness"]["baseColorFactor"] = serde_json::json!([0.1, 0.4, 0.1, 0.5]);
        green["alphaMode"] = serde_json::json!("BLEND");
        j["materials"][3]["emissiveFactor"] = serde_json::json!([3.0, 0.9, 0.75]);
    });
    let stderr = one_tiny_frame(&[file.to_str().unwrap()], &dir.path().join("out"));
    for said in [
        "material 1 'red': baseColorFactor [1.5, 0.5, -0.25, 1] is outside [0, 1]; clamped to [1, 0.5, 0, 1]",
        "material 1 'red': metallicFactor 2 is outside [0, 1]; clamped to 1",
        "material 1 'red': roughnessFactor -1 is outside [0, 1]; clamped to 0",
        "material 2 'green': baseColorFactor alpha 0.5 (alphaMode BLEND) is ignored",
        "material 3 'light': emissiveFactor [3, 0.9, 0.75] is outside [0, 1]; clamped to [1, 0.9, 0.75]",
    ] {
        assert!(stderr.contains(said), "expected {said:?} in: {stderr}");
    }
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("material ")).collect();
    assert_eq!(warnings.len(), 5, "{stderr}");
    assert!(
        warnings
            .iter()
            .all(|l| l.starts_with("warning: ") && l.contains(file.to_str().unwrap())),
        "{stderr}"
    );
}

/// A store whose sled files were damaged (a bit flipped in `db`) is called
/// damaged, not "not a radcache store": the message names the store, says
/// what to do and holds none of sled's debug text. Both ways sled fails
/// on it: with a snapshot beside `db` (a store opened again after its
/// render) sled reports corrupt data; without one it recovers nothing,
/// though the sample log holds samples.
#[test]
fn a_damaged_store_is_called_damaged_and_told_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("db");
    let (code, _, stderr) = radcache(&[
        "render",
        "--db",
        db.to_str().unwrap(),
        "--job",
        "j1",
        "--method",
        "ic",
        "--frames",
        "0..2",
        "--size",
        "8x8",
        "--spp",
        "1",
        "--out",
        dir.path().join("out").to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");
    for reopened in [false, true] {
        let copy = dir.path().join(format!("copy-{reopened}"));
        std::fs::create_dir_all(copy.join("blobs")).unwrap();
        for name in ["conf", "db", "samples.log"] {
            std::fs::copy(db.join(name), copy.join(name)).unwrap();
        }
        let copy_arg = copy.to_str().unwrap();
        if reopened {
            let (code, _, stderr) = radcache(&["inspect", "--db", copy_arg]);
            assert_eq!(code, 0, "{stderr}");
        }
        let mut bytes = std::fs::read(copy.join("db")).unwrap();
        bytes[100] ^= 0x10;
        std::fs::write(copy.join("db"), &bytes).unwrap();
        let (code, _, stderr) = radcache(&["inspect", "--db", copy_arg]);
        assert_eq!(code, 1, "{stderr}");
        assert!(
            stderr.contains(&format!("store {copy_arg}: damaged: ")),
            "reopened {reopened}: {stderr}"
        );
        assert!(
            stderr.contains("restore the directory from a copy, or remove it to start over"),
            "{stderr}"
        );
        for noise in ["not a radcache store", "backtrace", "offset None"] {
            assert!(!stderr.contains(noise), "{noise}: {stderr}");
        }
    }
}

/// A store path whose directory cannot be made (under /proc) is one
/// error naming the path, the OS's reason said once.
#[cfg(target_os = "linux")]
#[test]
fn a_store_directory_that_cannot_be_made_is_said_once() {
    let dir = tempfile::tempdir().unwrap();
    let (code, _, stderr) = radcache(&[
        "render",
        "--db",
        "/proc/radcache-no-such/db",
        "--job",
        "j",
        "--frames",
        "0..1",
        "--size",
        "8x8",
        "--spp",
        "1",
        "--out",
        dir.path().to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains("store /proc/radcache-no-such/db: cannot open or create"),
        "{stderr}"
    );
    assert_eq!(stderr.matches("os error").count(), 1, "{stderr}");
}

/// A negative number given to a number flag reaches the flag's parser,
/// which says the value is out of its range, rather than clap taking it
/// for a flag (`unexpected argument '-1'`, or `'-2'` of `-24`).
#[test]
fn negative_numbers_are_out_of_range_not_flags() {
    let cases: &[(&[&str], &str)] = &[
        (
            &["render", "--spp", "-1"],
            "invalid value '-1' for '--spp <SPP>': expected a number from 1 to 1000000",
        ),
        (
            &["render", "--fps", "-24"],
            "invalid value '-24' for '--fps <FPS>': fps must lie in 0.001..=100000",
        ),
        (
            &["render", "--method", "trc", "--trc-max-life", "-5"],
            "invalid value '-5' for '--trc-max-life <TRC_MAX_LIFE>': expected a number from 1 to 100000",
        ),
        (
            &["render", "--method", "ic", "--ic-accuracy", "-0.2"],
            "invalid value '-0.2' for '--ic-accuracy <IC_ACCURACY>': expected a number from 0.001 to 2",
        ),
        (
            &["render", "--max-depth", "-3"],
            "invalid value '-3' for '--max-depth <MAX_DEPTH>': expected a number from 0 to 10000",
        ),
        (
            &["render", "--seed", "-1"],
            "invalid value '-1' for '--seed <SEED>': expected a whole number from 0 to",
        ),
        (
            &["render", "--threads", "-2"],
            "invalid value '-2' for '--threads <THREADS>'",
        ),
        (
            &["bench", "--reference-spp", "-16"],
            "invalid value '-16' for '--reference-spp <REFERENCE_SPP>'",
        ),
        (
            &["bench", "--fps", "-1"],
            "invalid value '-1' for '--fps <FPS>'",
        ),
        (
            &["inspect", "--frame", "-1"],
            "invalid value '-1' for '--frame <FRAME>': expected a frame number",
        ),
        (
            &["serve", "--client-timeout", "-5"],
            "invalid value '-5' for '--client-timeout <CLIENT_TIMEOUT>'",
        ),
        (
            &["render", "--frames", "-1..5"],
            "invalid value '-1..5' for '--frames <FRAMES>': frame range '-1..5': '-1' is not a frame number",
        ),
        (
            &["bench", "--frames", "-3..-1"],
            "invalid value '-3..-1' for '--frames <FRAMES>'",
        ),
    ];
    for (args, expected) in cases {
        let (code, _, stderr) = radcache(args);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(
            !stderr.contains("unexpected argument"),
            "{args:?}: {stderr}"
        );
    }
}

/// `render --job` says when it makes a new store (a mistyped --db), and,
/// before anything renders, how many of the range's frames the job has
/// finished in the store: a resume that then fails still said it.
#[test]
fn render_says_it_made_a_store_and_what_it_resumes_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("typo");
    let out = dir.path().join("out");
    let args = |frames: &'static str, out: &std::path::Path| {
        let mut v = vec![
            "render", "--method", "ic", "--frames", frames, "--size", "8x8",
        ];
        v.extend(["--spp", "1", "--job", "j", "-q"]);
        v.extend(["--db", db.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let run = |argv: Vec<String>| {
        let argv: Vec<&str> = argv.iter().map(String::as_str).collect();
        radcache(&argv)
    };
    let (code, _, stderr) = run(args("0..2", &out));
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains(&format!(
            "note: no store at {}: a new, empty one is made there",
            db.display()
        )),
        "{stderr}"
    );
    assert!(!stderr.contains("resuming"), "{stderr}");
    // Resumed into an --out that is a file: the render fails before its
    // first frame, having said what it resumes; no new store is made.
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let (code, _, stderr) = run(args("0..3", &file));
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains(&format!(
            "job \"j\" in {}: resuming: 2 of the 3 frames of 0..3 are finished in the store",
            db.display()
        )),
        "{stderr}"
    );
    assert!(!stderr.contains("no store at"), "{stderr}");
}

/// `serve --db PATH` where no store is says that it makes a new one there;
/// on an existing store it says nothing of the kind.
#[test]
fn serve_says_it_makes_a_new_store() {
    use std::io::BufRead;
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("typo");
    for new in [true, false] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_radcache"))
            .args(["serve", "--addr", "127.0.0.1:0", "--db"])
            .arg(&db)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.starts_with("listening on"), "{line}");
        child.kill().unwrap();
        let output = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        let note = format!(
            "note: no store at {}: a new, empty one is made",
            db.display()
        );
        assert_eq!(stderr.contains(&note), new, "new {new}: {stderr}");
        assert!(db.join("db").is_file(), "the store was made");
    }
}

/// A directory where a frame file goes is refused before the frame renders
/// (no file of it is written), naming the path and saying why once.
#[test]
fn a_directory_in_the_way_of_a_frame_file_is_said_once_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("dd");
    std::fs::create_dir_all(out.join("frame_0000.exr").join("x")).unwrap();
    let (code, _, stderr) = radcache(&[
        "render",
        "--method",
        "path",
        "--size",
        "8x8",
        "--spp",
        "1",
        "--frames",
        "0..2",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("frame_0000.exr"), "{stderr}");
    let said = stderr.to_lowercase();
    assert_eq!(said.matches("is a directory").count(), 1, "{stderr}");
    assert!(said.matches("os error").count() <= 1, "{stderr}");
    assert!(!out.join("frame_0000.png").exists(), "frame 0 was rendered");
}

/// Where stderr is not a terminal (a log, `nohup`, CI; these tests pipe
/// it) a render says each finished frame on a line of its own, which the
/// bar would not; `-q` says none.
#[test]
fn render_progress_is_a_line_per_frame_off_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let args = [
        "render", "--method", "path", "--size", "8x8", "--spp", "1", "--frames", "3..5", "--out",
        out,
    ];
    let (code, _, stderr) = radcache(&args);
    assert_eq!(code, 0, "{stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| l.contains(" done (")).collect();
    assert_eq!(lines.len(), 2, "{stderr}");
    assert!(lines[0].starts_with("frame 3 done (1/2) in "), "{stderr}");
    assert!(lines[0].contains(", eta "), "{stderr}");
    assert!(lines[1].starts_with("frame 4 done (2/2) in "), "{stderr}");
    assert!(
        !lines[1].contains("eta"),
        "the last frame has no ETA: {stderr}"
    );
    let (code, _, stderr) = radcache(&[&args[..], &["-q"]].concat());
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains(" done ("), "{stderr}");
}

/// `--threads` is one flag of every command: its help says which commands
/// render on the worker threads, not only `render`'s ("Worker threads
/// that render, trace and shade" in `compare --help`).
#[test]
fn threads_help_fits_every_command() {
    for command in [
        "render", "compare", "bench", "inspect", "serve", "compact", "delete",
    ] {
        let (code, stdout, stderr) = radcache(&[command, "--help"]);
        assert_eq!(code, 0, "{command}: {stderr}");
        let help = stdout.split_whitespace().collect::<Vec<_>>().join(" ");
        let threads = &help[help.find("--threads").expect("--threads is listed")..];
        assert!(
            threads.contains("(render, bench, serve)") && threads.contains("1 to 1024"),
            "{command}: {threads}"
        );
        assert!(!help.contains("threads that render"), "{command}: {help}");
    }
}
