//! `render` and `bench` refuse, before anything renders, a frame whose
//! estimated peak memory is over what the process may take
//! (`radcache::render::memory`): a clear error and status 1, not the
//! runtime's `memory allocation of N bytes failed` abort (134) or the OOM
//! killer, and `--no-memory-check` renders anyway.

use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn run(command: &mut Command) -> (i32, String) {
    let Output { status, stderr, .. } = command.output().expect("the command runs");
    (
        status.code().unwrap_or(-1),
        String::from_utf8_lossy(&stderr).into_owned(),
    )
}

fn radcache(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_radcache"));
    command.args(args);
    command
}

/// A refusal: status 1, the estimate and what is available said, and the
/// way round named; no abort.
fn assert_refused(code: i32, stderr: &str, flag_hint: &str) {
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.starts_with("error: a "), "{stderr}");
    assert!(
        stderr.contains("needs at least") && stderr.contains("is available;"),
        "{stderr}"
    );
    assert!(stderr.contains(flag_hint), "{stderr}");
    assert!(!stderr.contains("memory allocation"), "{stderr}");
}

/// 16384² `movies` at 65536 spp needs 16 TiB by the estimate (its item
/// buffer holds a flag for every camera sample of the frame): it is refused at
/// once, whatever the machine, and nothing is written.
#[cfg(target_os = "linux")]
#[test]
fn a_render_past_the_memory_available_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let started = Instant::now();
    let (code, stderr) = run(&mut radcache(&[
        "render",
        "--method",
        "movies",
        "--size",
        "16384x16384",
        "--spp",
        "65536",
        "--frames",
        "0..1",
        "-q",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert_refused(
        code,
        &stderr,
        "render a smaller --size or fewer --spp, or pass --no-memory-check",
    );
    assert!(
        stderr.contains("a 16384x16384 movies render at 65536 spp needs at least"),
        "{stderr}"
    );
    assert!(started.elapsed() < Duration::from_secs(60));
    assert!(!out.exists(), "nothing is written");
}

/// Under `ulimit -v` the room left in the address space is what is
/// available: an 8192² `ic` frame (7.3 GiB by the estimate) is refused
/// under 2 GB, where it would otherwise end in an allocation failure.
#[cfg(target_os = "linux")]
#[test]
fn a_render_past_the_address_space_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (code, stderr) = run(Command::new("sh").args([
        "-c",
        "ulimit -v 2000000 && exec \"$0\" \"$@\"",
        env!("CARGO_BIN_EXE_radcache"),
        "render",
        "--method",
        "ic",
        "--size",
        "8192x8192",
        "--frames",
        "0..1",
        "--backend",
        "cpu",
        "-q",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert_refused(code, &stderr, "--no-memory-check");
    let available = stderr
        .split("and ")
        .last()
        .and_then(|s| s.split(" is available").next())
        .unwrap_or_default();
    assert!(
        available.ends_with(" MiB") || available.starts_with("1."),
        "{stderr}"
    );
}

/// `--no-memory-check` is a flag of `render` (and `bench`), and a render
/// that fits renders with or without it.
#[test]
fn no_memory_check_is_taken_and_a_render_that_fits_renders() {
    let dir = tempfile::tempdir().unwrap();
    for check in [&[][..], &["--no-memory-check"][..]] {
        let out = dir.path().join(format!("out{}", check.len()));
        let mut args = vec![
            "render",
            "--method",
            "ic",
            "--size",
            "8x8",
            "--spp",
            "1",
            "--frames",
            "0..1",
            "--backend",
            "cpu",
            "-q",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(check);
        let (code, stderr) = run(&mut radcache(&args));
        assert_eq!(code, 0, "{check:?}: {stderr}");
        assert!(out.join("frame_0000.exr").is_file(), "{check:?}");
    }
    let (code, stdout) = {
        let out = radcache(&["render", "--help"]).output().unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
        )
    };
    assert_eq!(code, Some(0));
    assert!(stdout.contains("--no-memory-check"), "{stdout}");
}

/// `bench` refuses the same way, before its reference renders, naming
/// its run and the scene whose triangles it counted; `--no-memory-check`
/// is its flag too.
#[cfg(target_os = "linux")]
#[test]
fn a_bench_run_past_the_memory_available_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let (code, stderr) = run(&mut radcache(&[
        "bench",
        "--size",
        "16384x16384",
        "--methods",
        "path",
        "movies:spp=65536",
        "--frames",
        "0..1",
        "-q",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert_refused(
        code,
        &stderr,
        "bench a smaller --size, or pass --no-memory-check",
    );
    assert!(
        stderr.contains("16384x16384 movies render at 65536 spp"),
        "{stderr}"
    );
    let triangles = radcache::render::memory::scene_triangles(
        &radcache::scene::Scene::builtin("cube-in-box").unwrap(),
    );
    assert!(triangles > 0);
    assert!(
        stderr.contains(&format!(
            "is available; for movies spp=65536 on scene cube-in-box ({triangles} triangles), \
             bench a smaller --size"
        )),
        "{stderr}"
    );
    assert!(!out.exists(), "nothing is written");
    let help = radcache(&["bench", "--help"]).output().unwrap();
    assert!(String::from_utf8_lossy(&help.stdout).contains("--no-memory-check"));
}
