//! `radcache serve` against a real server on a loopback port.

mod serve_client;
mod store_fixtures;

use serve_client::{request, start_server, Server};
use std::process::Command;
use std::time::{Duration, Instant};

/// A temporary folder for a test's store, with an empty `scenes/` folder
/// in it for `--scenes`.
fn workspace() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    std::fs::create_dir(&scenes).unwrap();
    (dir, scenes)
}

fn start(db: &std::path::Path, scenes: &std::path::Path) -> Server {
    start_with(db, scenes, &[])
}

fn start_with(db: &std::path::Path, scenes: &std::path::Path, extra: &[&str]) -> Server {
    let mut args: Vec<&std::ffi::OsStr> = ["--backend", "cpu", "--db"]
        .iter()
        .map(|a| a.as_ref())
        .collect();
    args.extend([db.as_os_str(), "--scenes".as_ref(), scenes.as_os_str()]);
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    start_server(&args)
}

/// One HTTP/1.1 request; returns (status, body).
fn http(server: &Server, method: &str, path: &str, body: &str) -> (u16, Vec<u8>) {
    let (status, _, body) = http_full(&server.addr, method, path, body);
    (status, body)
}

/// One HTTP/1.1 request with a JSON body, read to the end; returns
/// (status, head, body).
fn http_full(addr: &str, method: &str, path: &str, body: &str) -> (u16, String, Vec<u8>) {
    request(
        addr,
        method,
        path,
        "Content-Type: application/json\r\n",
        body,
    )
}

/// `radcache render --builtin cube-in-box ARGS… --backend cpu -q --out OUT`
/// in one go: the frames a server job must equal.
fn render_with_cli(method: &[&str], size: &[&str], out: &std::path::Path) {
    let ok = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["render", "--builtin", "cube-in-box"])
        .args(method)
        .args(size)
        .args(["--backend", "cpu", "-q", "--out"])
        .arg(out)
        .status()
        .unwrap();
    assert!(ok.success());
}

/// Frames `0..frames` of job `id`, as EXR from the server, equal the CLI's
/// byte for byte.
fn assert_frames_equal_cli(server: &Server, id: &str, frames: u64, out: &std::path::Path) {
    for f in 0..frames {
        let (status, exr) = http(server, "GET", &format!("/api/jobs/{id}/frames/{f}.exr"), "");
        assert_eq!(status, 200);
        let cli = std::fs::read(out.join(format!("frame_{f:04}.exr"))).unwrap();
        assert!(
            exr == cli,
            "frame {f}: the server's EXR differs from the CLI's"
        );
    }
}

fn json(body: &[u8]) -> serde_json::Value {
    serde_json::from_slice(body)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(body)))
}

fn wait_done(server: &Server, id: &str) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let (status, body) = http(server, "GET", &format!("/api/jobs/{id}"), "");
        assert_eq!(status, 200);
        let job = json(&body);
        match job["state"].as_str().unwrap() {
            "done" => return job,
            "failed" | "cancelled" => panic!("job ended {job}"),
            _ => {}
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "job not done: {job}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn job_renders_and_frames_match_the_cli() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    let (status, body) = http(
        &server,
        "POST",
        "/api/jobs",
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..2","size":"16x16","spp":1}"#,
    );
    assert_eq!(status, 201, "{}", String::from_utf8_lossy(&body));
    let id = json(&body)["id"].as_str().unwrap().to_string();
    let job = wait_done(&server, &id);
    assert_eq!(job["frames_done"], 2);
    assert_eq!(job["frames_total"], 2);

    let (status, list) = http(&server, "GET", "/api/jobs", "");
    assert_eq!(status, 200);
    assert_eq!(json(&list).as_array().unwrap().len(), 1);

    let (status, png) = http(&server, "GET", &format!("/api/jobs/{id}/frames/1.png"), "");
    assert_eq!(status, 200);
    let img = image::load_from_memory(&png).unwrap();
    assert_eq!((img.width(), img.height()), (16, 16));
    // The same frame by the name `radcache render` gives its file.
    let (status, named) = http(
        &server,
        "GET",
        &format!("/api/jobs/{id}/frames/frame_0001.png"),
        "",
    );
    assert_eq!(status, 200);
    assert_eq!(named, png);
    let (status, _) = http(
        &server,
        "GET",
        &format!("/api/jobs/{id}/frames/frame_x.png"),
        "",
    );
    assert_eq!(status, 404);

    let out = dir.path().join("cli");
    render_with_cli(
        &["--method", "path", "--frames", "0..2"],
        &["--size", "16x16", "--spp", "1"],
        &out,
    );
    assert_frames_equal_cli(&server, &id, 2, &out);

    let (status, stats) = http(&server, "GET", &format!("/api/jobs/{id}/stats"), "");
    assert_eq!(status, 200);
    let stats = json(&stats);
    let frames: Vec<u64> = stats["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(frames, [0, 1]);
    // `path` keeps no records: none alive, none living, no cache held;
    // each frame stored its image at least.
    for f in stats["frames"].as_array().unwrap() {
        assert_eq!(f["records_alive"], 0, "{f}");
        assert!(f["mean_lifespan"].is_null(), "{f}");
        assert_eq!(
            (&f["cache_bytes"], &f["samples_reshot"]),
            (&serde_json::json!(0), &serde_json::json!(0)),
            "{f}"
        );
        assert!(
            f["stored_bytes"].as_u64().unwrap() >= f["exr_bytes"].as_u64().unwrap(),
            "{f}"
        );
    }

    let (status, metrics) = http(&server, "GET", "/metrics", "");
    assert_eq!(status, 200);
    let text = String::from_utf8(metrics).unwrap();
    let mut seen = 0;
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let (name, value) = line.rsplit_once(' ').unwrap();
        assert!(name.starts_with("radcache_"), "{line}");
        value.parse::<f64>().unwrap();
        seen += 1;
    }
    assert!(seen >= 5);
    assert!(text.contains("radcache_frames_rendered_total 2"), "{text}");
    assert!(text.contains("radcache_jobs{state=\"done\"} 1"), "{text}");
}

/// A job's `fps` and `same_pattern` are the CLI's `--fps` and
/// `--same-pattern` (a scene keyed at another rate than 24 fps, reference
/// sequences for flicker), and the job shows them.
#[test]
fn a_jobs_frame_rate_and_same_pattern_are_the_clis_flags() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..2","size":"16x16","spp":1,
            "fps":12,"same_pattern":true}"#,
    );
    let job = wait_done(&server, &id);
    assert_eq!(
        (&job["fps"], &job["same_pattern"]),
        (&12.0.into(), &true.into()),
        "{job}"
    );
    let out = dir.path().join("cli");
    render_with_cli(
        &[
            "--method",
            "path",
            "--frames",
            "0..2",
            "--fps",
            "12",
            "--same-pattern",
        ],
        &["--size", "16x16", "--spp", "1"],
        &out,
    );
    assert_frames_equal_cli(&server, &id, 2, &out);
    for fps in ["0", "-1", "1e9"] {
        let body = format!(
            r#"{{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"8x8","fps":{fps}}}"#
        );
        let (status, err) = http(&server, "POST", "/api/jobs", &body);
        assert_eq!(status, 400, "fps {fps}");
        assert!(
            json(&err)["detail"].to_string().contains("fps"),
            "fps {fps}"
        );
    }
}

/// A job's `settings` are the method's settings by the bench's names: the
/// frames are those of the CLI given the same settings as flags, and the
/// job shows them.
#[test]
fn job_settings_are_the_clis_flags() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"ic","frames":"0..2","size":"16x16","spp":1,
            "settings":{"accuracy":0.3,"strata":"8x24","gradients":false,"max_depth":2}}"#,
    );
    let job = wait_done(&server, &id);
    let settings = &job["settings"];
    assert_eq!(settings["accuracy"], 0.3, "{job}");
    assert_eq!(settings["strata"], "8x24", "{job}");
    assert_eq!(settings["gradients"], false, "{job}");
    assert_eq!(settings["spp"], 1, "{job}");
    assert_eq!(settings["max_depth"], 2, "{job}");
    // A job's settings as shown, posted again, make the same job.
    let again = create_job(
        &server,
        &serde_json::json!({"scene":"builtin:cube-in-box","method":"ic","frames":"0..1",
            "size":"16x16","settings":settings})
        .to_string(),
    );
    let (_, shown) = http(&server, "GET", &format!("/api/jobs/{again}"), "");
    assert_eq!(&json(&shown)["settings"], settings);
    let out = dir.path().join("cli");
    render_with_cli(
        &[
            "--method",
            "ic",
            "--frames",
            "0..2",
            "--ic-accuracy",
            "0.3",
            "--ic-strata",
            "8x24",
            "--ic-no-gradients",
            "--max-depth",
            "2",
        ],
        &["--size", "16x16", "--spp", "1"],
        &out,
    );
    assert_frames_equal_cli(&server, &id, 2, &out);

    // `tcg`'s own settings and `ic`'s, which make its records.
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"tcg","frames":"0..3","size":"16x16","spp":1,
            "settings":{"tau_min":0.2,"tau_max":0.5,"max_neighbours":4,"strata":"4x12"}}"#,
    );
    let job = wait_done(&server, &id);
    let settings = &job["settings"];
    assert_eq!(settings["tau_min"], 0.2, "{job}");
    assert_eq!(settings["max_neighbours"], 4, "{job}");
    assert_eq!(settings["strata"], "4x12", "{job}");
    let out = dir.path().join("cli-tcg");
    render_with_cli(
        &[
            "--method",
            "tcg",
            "--frames",
            "0..3",
            "--tcg-tau-min",
            "0.2",
            "--tcg-tau-max",
            "0.5",
            "--tcg-max-neighbours",
            "4",
            "--ic-strata",
            "4x12",
        ],
        &["--size", "16x16", "--spp", "1"],
        &out,
    );
    assert_frames_equal_cli(&server, &id, 3, &out);

    // `movies`' settings, its global pass's among them.
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"movies","frames":"0..2","size":"16x16","spp":1,
            "settings":{"shadow_samples":4,"texels_per_pixel":0.5,"links":16,"bounces":3}}"#,
    );
    let job = wait_done(&server, &id);
    let settings = &job["settings"];
    assert_eq!(settings["shadow_samples"], 4, "{job}");
    assert_eq!(settings["links"], 16, "{job}");
    let out = dir.path().join("cli-movies");
    render_with_cli(
        &[
            "--method",
            "movies",
            "--frames",
            "0..2",
            "--movies-shadow-samples",
            "4",
            "--movies-texels-per-pixel",
            "0.5",
            "--movies-links",
            "16",
            "--movies-bounces",
            "3",
        ],
        &["--size", "16x16", "--spp", "1"],
        &out,
    );
    assert_frames_equal_cli(&server, &id, 2, &out);
    // Its texture movies, from the store, frame by frame.
    let (status, body) = http(
        &server,
        "GET",
        &format!("/api/jobs/{id}/movies?frame=1"),
        "",
    );
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let m = json(&body);
    let movies = m["movies"].as_array().unwrap();
    assert!(!movies.is_empty() && m["count"] == movies.len(), "{m}");
    assert!(m["global_vertices"].as_u64().unwrap() > 0, "{m}");
    for movie in movies {
        let (start, stored_at) = (
            movie["start"].as_u64().unwrap(),
            movie["stored_at"].as_u64().unwrap(),
        );
        assert!(
            start <= 1 && start <= stored_at && stored_at <= 1,
            "{movie}"
        );
        let r = movie["resolution"].as_u64().unwrap();
        assert!(r >= 1 && movie["texels"].as_u64().unwrap() >= 1, "{movie}");
        let mean = movie["mean_direct"].as_array().unwrap();
        assert!(mean.iter().all(|c| c.as_f64().unwrap() >= 0.0), "{movie}");
    }
    assert!(movies
        .iter()
        .any(|m| m["mean_direct"][0].as_f64().unwrap() > 0.0));
    let (status, _) = http(
        &server,
        "GET",
        &format!("/api/jobs/{id}/movies?frame=7"),
        "",
    );
    assert_eq!(status, 404);
    let (status, _) = http(&server, "GET", &format!("/api/jobs/{id}/movies"), "");
    assert_eq!(status, 400);
}

#[test]
fn bad_requests_get_json_errors_and_the_server_keeps_serving() {
    let (dir, scenes) = workspace();
    std::fs::write(dir.path().join("secret.gltf"), "{}").unwrap();
    let server = start(&dir.path().join("db"), &scenes);
    let check = |method: &str, path: &str, body: &str, want: u16| {
        let (status, resp) = http(&server, method, path, body);
        assert_eq!(
            status,
            want,
            "{method} {path} {body}: {}",
            String::from_utf8_lossy(&resp)
        );
        let err = json(&resp);
        assert!(
            err["error"].is_string() && err["detail"].is_string(),
            "{err}"
        );
    };
    check("GET", "/api/jobs/job-999", "", 404);
    check("GET", "/api/jobs/nonsense", "", 404);
    check("GET", "/api/jobs/job-1/frames/0.png", "", 404);
    check("POST", "/api/jobs/job-7/cancel", "", 404);
    check("POST", "/api/jobs", "{not json", 400);
    // Routes that take no query parameters refuse them, as `/records`
    // refuses unknown ones, rather than quietly answer something else.
    for path in [
        "/api/jobs?state=done",
        "/api/jobs/job-1/stats?from=3",
        "/api/jobs/job-1/events?since=2",
        "/metrics?job=job-1",
    ] {
        check("GET", path, "", 400);
        let detail = json(&http(&server, "GET", path, "").1)["detail"].to_string();
        assert!(detail.contains("this route takes none"), "{path}: {detail}");
    }
    let job = |scene: &str, frames: &str| {
        format!(
            r#"{{"scene":"{scene}","method":"path","frames":"{frames}","size":"16x16","spp":1}}"#
        )
    };
    // A field or a setting given twice is refused, not one of its values
    // quietly kept.
    for (body, says) in [
        (
            r#"{"scene":"x","scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"8x8"}"#,
            "duplicate field `scene`",
        ),
        (
            r#"{"scene":"builtin:cube-in-box","method":"trc","frames":"0..1","size":"8x8","settings":{"at":0.1,"at":0.5}}"#,
            "setting `at` given twice",
        ),
    ] {
        let (status, resp) = http(&server, "POST", "/api/jobs", body);
        assert_eq!(status, 400, "{body}");
        let detail = json(&resp)["detail"].as_str().unwrap().to_string();
        assert!(detail.contains(says), "{detail}");
    }
    check("POST", "/api/jobs", &job("../secret.gltf", "0..1"), 400);
    check("POST", "/api/jobs", &job("/etc/passwd", "0..1"), 400);
    check(
        "POST",
        "/api/jobs",
        &job("builtin:cube-in-box", "0..4000000000"),
        400,
    );
    check(
        "POST",
        "/api/jobs",
        &job("builtin:no-such-scene", "0..1"),
        400,
    );
    check(
        "POST",
        "/api/jobs",
        r#"{"scene":"builtin:cube-in-box","method":"nope","frames":"0..1","size":"16x16"}"#,
        400,
    );
    let with_settings = |settings: &str| {
        format!(
            r#"{{"scene":"builtin:cube-in-box","method":"trc","frames":"0..1","size":"16x16","spp":1,"settings":{settings}}}"#
        )
    };
    for bad in [
        r#"{"no_such_setting":1}"#,
        r#"{"at":"fast"}"#,
        r#"{"max_life":0}"#,
        r#"{"strata":"16"}"#,
        r#"{"gradients":"sideways"}"#,
        r#"{"at":[0.1]}"#,
        r#"{"spp":2}"#,
        r#"{"spp_":2}"#,
        r#"{"strata":"512x512"}"#,
        r#"[1]"#,
        // A boolean is for on/off settings only (it ran as a life of 1).
        r#"{"max_life":true}"#,
        r#"{"at":false}"#,
        r#"{"gradients":true}"#,
    ] {
        check("POST", "/api/jobs", &with_settings(bad), 400);
    }
    for bad in [
        r#"{"tau_min":1.5}"#,
        r#"{"max_neighbours":-1}"#,
        r#"{"at":0.1}"#,
    ] {
        let body = with_settings(bad).replace(r#""method":"trc""#, r#""method":"tcg""#);
        check("POST", "/api/jobs", &body, 400);
    }
    for bad in [
        r#"{"shadow_samples":65}"#,
        r#"{"max_resolution":100000}"#,
        r#"{"links":0}"#,
        r#"{"at":0.1}"#,
    ] {
        let body = with_settings(bad).replace(r#""method":"trc""#, r#""method":"movies""#);
        check("POST", "/api/jobs", &body, 400);
    }
    check(
        "POST",
        "/api/jobs",
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"16x16","settings":{"spp":100000}}"#,
        400,
    );
    // One frame over the server's pixel samples (4096² at 17 spp).
    check(
        "POST",
        "/api/jobs",
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"4096x4096","spp":17}"#,
        400,
    );
    // Frame numbers past the last one (temporal methods add lifespans to
    // them), and a body that is no object.
    check(
        "POST",
        "/api/jobs",
        &job("builtin:cube-in-box", "999990..1000001"),
        400,
    );
    let (_, resp) = http(&server, "POST", "/api/jobs", "[]");
    let detail = json(&resp)["detail"].as_str().unwrap().to_string();
    assert!(detail.contains("JSON object"), "{detail}");
    // A scene file that does not load is refused at once, named as sent
    // (not by the server's own path).
    std::fs::write(scenes.join("broken.gltf"), r#"{"asset":{"version":"2.0"},"#).unwrap();
    let (status, resp) = http(&server, "POST", "/api/jobs", &job("broken.gltf", "0..1"));
    assert_eq!(status, 400);
    let detail = json(&resp)["detail"].as_str().unwrap().to_string();
    assert!(detail.starts_with("scene broken.gltf: "), "{detail}");
    assert!(
        !detail.contains(&dir.path().display().to_string()),
        "{detail}"
    );
    // A scene file that loads is shown by the name it was sent with.
    std::fs::create_dir(scenes.join("sub")).unwrap();
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/scenes/cube_in_box.glb"
        ),
        scenes.join("sub/box.glb"),
    )
    .unwrap();
    let (status, resp) = http(&server, "POST", "/api/jobs", &job("sub/box.glb", "0..1"));
    assert_eq!(status, 201, "{}", String::from_utf8_lossy(&resp));
    let id = json(&resp)["id"].as_str().unwrap().to_string();
    assert_eq!(wait_done(&server, &id)["scene"], "sub/box.glb");
    // One URL per frame: its number, or the name `radcache render` gives
    // its file; other spellings of the number are no frame.
    for (file, want) in [
        ("0.png", 200),
        ("frame_0000.exr", 200),
        ("+0.png", 404),
        ("00.png", 404),
        ("frame_0.png", 404),
        ("0.jpg", 404),
    ] {
        let (status, _) = http(&server, "GET", &format!("/api/jobs/{id}/frames/{file}"), "");
        assert_eq!(status, want, "{file}");
    }
    // Errors axum answers itself are JSON too: a body over the limit, a
    // wrong method (with its Allow header).
    let huge = format!(r#"{{"scene":"{}"}}"#, "a".repeat(100_000));
    check("POST", "/api/jobs", &huge, 413);
    // A body announced over the limit is refused before it comes.
    {
        use std::io::{Read, Write};
        let mut s = std::net::TcpStream::connect(&server.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        write!(
            s,
            "POST /api/jobs HTTP/1.1\r\nHost: x\r\nConnection: close\r\nContent-Length: 100000000\r\n\r\n{{"
        )
        .unwrap();
        let mut head = [0u8; 12];
        s.read_exact(&mut head).expect("an answer without the body");
        assert_eq!(&head, b"HTTP/1.1 413");
    }
    check("DELETE", "/api/jobs", "", 405);
    let (_, head, body) = http_full(&server.addr, "PUT", "/api/jobs/job-1/cancel", "");
    assert!(head.to_ascii_lowercase().contains("allow: post"), "{head}");
    let detail = json(&body)["detail"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(detail.contains("this route takes POST"), "{detail}");
    // Still serving.
    let (status, body) = http(&server, "GET", "/api/jobs", "");
    assert_eq!(status, 200);
    assert_eq!(json(&body).as_array().map(Vec::len), Some(1), "the box job");
    // Cancel a queued/running job, then resume it: 409 for a wrong state.
    let (status, body) = http(
        &server,
        "POST",
        "/api/jobs",
        &job("builtin:cube-in-box", "0..2"),
    );
    assert_eq!(status, 201);
    let id = json(&body)["id"].as_str().unwrap().to_string();
    check("POST", &format!("/api/jobs/{id}/resume"), "", 409);
    // One job, one id: `job-02` is not `job-2`.
    let padded = id.replace("job-", "job-0");
    check("GET", &format!("/api/jobs/{padded}"), "", 404);
    check("GET", &format!("/api/jobs/{padded}/stats"), "", 404);
    let job = wait_done(&server, &id);
    assert_eq!(job["frames_done"], 2);
    check("POST", &format!("/api/jobs/{id}/cancel"), "", 409);
}

fn create_job(server: &Server, body: &str) -> String {
    let (status, resp) = http(server, "POST", "/api/jobs", body);
    assert_eq!(status, 201, "{}", String::from_utf8_lossy(&resp));
    json(&resp)["id"].as_str().unwrap().to_string()
}

/// Creates job `first`, then job `then` (queued behind it while `first`
/// renders); returns `then`'s id.
fn create_job_behind(server: &Server, first: &str, then: &str) -> String {
    create_job(server, first);
    create_job(server, then)
}

/// A job's state once it is no longer queued or running.
fn wait_ended(server: &Server, id: &str) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let job = job_state(server, id);
        if !matches!(job["state"].as_str(), Some("queued" | "running")) {
            return job;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "job not ended: {job}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A scene under `--scenes` reads its files there only: a buffer (or an
/// image, which the scene's hash reads) named `../outside.bin`, by an
/// absolute path, or through a symbolic link out of the directory (a file
/// or a folder) is a 400 naming the scene and the URI, not the directory's
/// path; a buffer in a subdirectory loads and renders. The worker loads
/// the job confined too: a buffer turned into a link out of the directory
/// after the job was accepted fails the job, naming the URI.
#[test]
fn scene_files_are_read_only_inside_the_scenes_directory() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    let glb = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/scenes/cube_in_box.glb"
    ))
    .unwrap();
    let glb = gltf::binary::Glb::from_slice(&glb).unwrap();
    let bin = glb.bin.as_deref().unwrap().to_vec();
    let doc: serde_json::Value = serde_json::from_slice(&glb.json).unwrap();
    let write_scene = |name: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        let mut doc = doc.clone();
        edit(&mut doc);
        std::fs::write(scenes.join(name), serde_json::to_vec(&doc).unwrap()).unwrap();
    };
    let outside = dir.path().join("outside.bin");
    std::fs::write(&outside, &bin).unwrap();
    std::fs::create_dir(scenes.join("bins")).unwrap();
    std::fs::write(scenes.join("bins/inside.bin"), &bin).unwrap();
    std::os::unix::fs::symlink(&outside, scenes.join("link.bin")).unwrap();
    std::os::unix::fs::symlink(dir.path(), scenes.join("out")).unwrap();
    let job = |scene: &str| {
        format!(r#"{{"scene":"{scene}","method":"path","frames":"0..1","size":"8x8","spp":1}}"#)
    };
    let absolute = outside.display().to_string();
    for (scene, uri) in [
        ("up.gltf", "../outside.bin"),
        ("absolute.gltf", absolute.as_str()),
        ("linked.gltf", "link.bin"),
        ("through.gltf", "out/outside.bin"),
        ("missing.gltf", "../no-such.bin"),
    ] {
        write_scene(scene, &|d| d["buffers"][0]["uri"] = serde_json::json!(uri));
        let (status, resp) = http(&server, "POST", "/api/jobs", &job(scene));
        assert_eq!(status, 400, "{scene}: {}", String::from_utf8_lossy(&resp));
        let detail = json(&resp)["detail"].as_str().unwrap().to_string();
        assert!(detail.starts_with(&format!("scene {scene}: ")), "{detail}");
        assert!(detail.contains(&format!("URI '{uri}'")), "{detail}");
        if uri != absolute {
            assert!(
                !detail.contains(&dir.path().display().to_string()),
                "{detail}"
            );
        }
    }
    // An image outside: the loader ignores it, the scene's hash reads it.
    write_scene("image.gltf", &|d| {
        d["buffers"][0]["uri"] = serde_json::json!("bins/inside.bin");
        d["images"] = serde_json::json!([{ "uri": "../outside.bin" }]);
    });
    let (status, resp) = http(&server, "POST", "/api/jobs", &job("image.gltf"));
    assert_eq!(status, 400, "{}", String::from_utf8_lossy(&resp));
    let detail = json(&resp)["detail"].as_str().unwrap().to_string();
    assert!(detail.contains("URI '../outside.bin'"), "{detail}");
    assert!(
        !detail.contains(&dir.path().display().to_string()),
        "{detail}"
    );
    let (_, body) = http(&server, "GET", "/api/jobs", "");
    assert_eq!(json(&body).as_array().map(Vec::len), Some(0));
    // Inside, in a subdirectory: accepted and rendered.
    write_scene("sub.gltf", &|d| {
        d["buffers"][0]["uri"] = serde_json::json!("bins/inside.bin")
    });
    let id = create_job(&server, &job("sub.gltf"));
    assert_eq!(wait_done(&server, &id)["scene"], "sub.gltf");
    // Accepted, then its buffer becomes a link out before the worker
    // loads it.
    std::fs::write(scenes.join("bins/later.bin"), &bin).unwrap();
    write_scene("later.gltf", &|d| {
        d["buffers"][0]["uri"] = serde_json::json!("bins/later.bin")
    });
    let long = r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..10000","size":"64x64","spp":4}"#;
    let first = create_job(&server, long);
    let later = create_job(&server, &job("later.gltf"));
    std::fs::remove_file(scenes.join("bins/later.bin")).unwrap();
    std::os::unix::fs::symlink(&outside, scenes.join("bins/later.bin")).unwrap();
    let (status, _) = http(&server, "POST", &format!("/api/jobs/{first}/cancel"), "");
    assert_eq!(status, 200);
    let ended = wait_ended(&server, &later);
    assert_eq!(ended["state"], "failed", "{ended}");
    let error = ended["error"].as_str().unwrap();
    assert!(error.contains("URI 'bins/later.bin'"), "{error}");
    assert!(
        !error.contains(&dir.path().display().to_string()),
        "{error}"
    );
}

/// The parts of a `multipart/x-mixed-replace` body: (X-Frame, bytes).
fn multipart_parts(head: &str, body: &[u8]) -> Vec<(u32, Vec<u8>)> {
    let ct = head
        .lines()
        .find_map(|l| {
            l.to_ascii_lowercase()
                .strip_prefix("content-type: ")
                .map(str::to_string)
        })
        .expect("content-type");
    assert!(ct.starts_with("multipart/x-mixed-replace"), "{ct}");
    let boundary = format!("--{}", ct.split("boundary=").nth(1).unwrap().trim());
    let mut parts = Vec::new();
    let mut rest = body;
    loop {
        assert!(
            rest.starts_with(boundary.as_bytes()),
            "part does not start with the boundary"
        );
        rest = &rest[boundary.len()..];
        if rest.starts_with(b"--") {
            return parts;
        }
        let end = rest.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
        let headers = String::from_utf8_lossy(&rest[..end]).to_ascii_lowercase();
        let field = |name: &str| -> String {
            headers
                .lines()
                .find_map(|l| l.strip_prefix(name).map(|v| v.trim().to_string()))
                .unwrap_or_else(|| panic!("no {name} in {headers}"))
        };
        assert_eq!(field("content-type:"), "image/png");
        let len: usize = field("content-length:").parse().unwrap();
        let frame: u32 = field("x-frame:").parse().unwrap();
        let data = &rest[end + 4..end + 4 + len];
        parts.push((frame, data.to_vec()));
        rest = &rest[end + 4 + len..];
        assert!(rest.starts_with(b"\r\n"));
        rest = &rest[2..];
    }
}

/// Server-sent events: (event, data) pairs.
fn sse_events(body: &[u8]) -> Vec<(String, serde_json::Value)> {
    let text = String::from_utf8(body.to_vec()).unwrap();
    text.split("\n\n")
        .filter_map(|block| {
            let mut event = None;
            let mut data = String::new();
            for line in block.lines() {
                if let Some(e) = line.strip_prefix("event:") {
                    event = Some(e.trim().to_string());
                } else if let Some(d) = line.strip_prefix("data:") {
                    data.push_str(d.trim_start());
                }
            }
            Some((event?, json(data.as_bytes())))
        })
        .collect()
}

#[test]
fn stream_and_events_deliver_every_frame_in_order_to_two_clients() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    // A slower job first, so that the followed job is still queued when
    // its clients connect: they then see every frame live.
    let id = create_job_behind(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..2","size":"48x48","spp":32}"#,
        r#"{"scene":"builtin:cube-in-box","method":"trc","frames":"0..4","size":"16x16","spp":1}"#,
    );
    let clients: Vec<_> = (0..2)
        .map(|_| {
            let addr = server.addr.clone();
            let path = format!("/api/jobs/{id}/stream");
            std::thread::spawn(move || http_full(&addr, "GET", &path, ""))
        })
        .collect();
    let events = {
        let addr = server.addr.clone();
        let path = format!("/api/jobs/{id}/events");
        std::thread::spawn(move || http_full(&addr, "GET", &path, ""))
    };
    for client in clients {
        let (status, head, body) = client.join().unwrap();
        assert_eq!(status, 200, "{head}");
        let parts = multipart_parts(&head, &body);
        let frames: Vec<u32> = parts.iter().map(|p| p.0).collect();
        assert_eq!(frames, [0, 1, 2, 3]);
        for (frame, png) in parts {
            let (status, want) = http(
                &server,
                "GET",
                &format!("/api/jobs/{id}/frames/{frame}.png"),
                "",
            );
            assert_eq!(status, 200);
            assert!(png == want, "frame {frame}: streamed PNG differs");
            let img = image::load_from_memory(&png).unwrap();
            assert_eq!((img.width(), img.height()), (16, 16));
        }
    }
    let (status, head, body) = events.join().unwrap();
    assert_eq!(status, 200);
    assert!(
        head.to_ascii_lowercase().contains("text/event-stream"),
        "{head}"
    );
    let events = sse_events(&body);
    let frames: Vec<u64> = events
        .iter()
        .filter(|e| e.0 == "frame")
        .map(|e| e.1["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(frames, [0, 1, 2, 3]);
    assert!(events
        .iter()
        .any(|e| e.0 == "progress" && e.1["frames_done"] == 4));
    let states: Vec<&str> = events
        .iter()
        .filter(|e| e.0 == "state")
        .map(|e| e.1["state"].as_str().unwrap())
        .collect();
    assert!(states.len() >= 2, "{states:?}");
    assert_eq!(states.last(), Some(&"done"));

    // A finished job streams all its frames at once, then ends.
    let (status, head, body) =
        http_full(&server.addr, "GET", &format!("/api/jobs/{id}/stream"), "");
    assert_eq!(status, 200);
    let frames: Vec<u32> = multipart_parts(&head, &body).iter().map(|p| p.0).collect();
    assert_eq!(frames, [0, 1, 2, 3]);
    let (status, _) = http(&server, "GET", "/api/jobs/job-99/stream", "");
    assert_eq!(status, 404);
}

#[test]
fn records_match_the_store_and_inspect() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let server = start(&db, &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"ic","frames":"0..2","size":"16x16","spp":1}"#,
    );
    wait_done(&server, &id);
    let get = |q: &str| {
        let (status, body) = http(&server, "GET", &format!("/api/jobs/{id}/records?{q}"), "");
        (status, json(&body))
    };
    let (status, all) = get("frame=1");
    assert_eq!(status, 200, "{all}");
    let records = all["records"].as_array().unwrap();
    assert!(!records.is_empty());
    assert_eq!(all["count"].as_u64().unwrap() as usize, records.len());
    for r in records {
        assert_eq!(r["created"], 1, "{r}");
        assert_eq!(r["lifespan"], 1, "ic records live one frame: {r}");
        let s = r["screen"].as_array().expect("a record in view projects");
        let (x, y) = (s[0].as_f64().unwrap(), s[1].as_f64().unwrap());
        assert!(
            (-0.5..=16.5).contains(&x) && (-0.5..=16.5).contains(&y),
            "{r}"
        );
    }
    // The statistics say so too.
    let (_, stats) = http(&server, "GET", &format!("/api/jobs/{id}/stats"), "");
    for f in json(&stats)["frames"].as_array().unwrap() {
        assert_eq!(f["mean_lifespan"], 1.0, "{f}");
    }
    // A box around the lower half (in y) of the records.
    let ys: Vec<f64> = records
        .iter()
        .map(|r| r["position"][1].as_f64().unwrap())
        .collect();
    let mid = (ys.iter().cloned().fold(f64::INFINITY, f64::min)
        + ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
        / 2.0;
    let (status, half) = get(&format!("frame=1&bbox=-1000,-1000,-1000,1000,{mid},1000"));
    assert_eq!(status, 200, "{half}");
    let want = ys.iter().filter(|&&y| y as f32 <= mid as f32).count();
    assert_eq!(half["count"].as_u64().unwrap() as usize, want);
    assert!(want > 0 && want < records.len());
    let (status, limited) = get("frame=1&limit=3");
    assert_eq!(status, 200);
    assert_eq!(limited["records"].as_array().unwrap().len(), 3);
    assert_eq!(limited["truncated"], true);
    for bad in [
        "frame=1&bbox=1,2,3",
        "frame=1&bbox=a,b,c,d,e,f",
        "frame=1&bbox=1,1,1,0,0,0",
        "frame=1&bbox=NaN,0,0,1,1,1",
        "frame=1&bbox=0,0,0,inf,1,1",
        "frame=x",
        "bbox=0,0,0,1,1,1",
        "frame=1&limit=0",
        "frame=0&frame=1",
        // One spelling of a frame, as its file name has; a misspelt
        // parameter is not quietly ignored.
        "frame=01",
        "frame=+1",
        "frame=1&limit=03",
        "frame=1&limt=3",
    ] {
        let (status, err) = get(bad);
        assert_eq!(status, 400, "{bad}: {err}");
        assert!(err["detail"].is_string());
    }
    assert_eq!(get("frame=7").0, 404);
    // An unknown job is a 404 whatever the query (a missing frame was a
    // 400 first).
    for path in [
        "/api/jobs/job-42/records?frame=0",
        "/api/jobs/job-42/records",
        "/api/jobs/job-42/movies",
    ] {
        let (status, _) = http(&server, "GET", path, "");
        assert_eq!(status, 404, "{path}");
    }
    let frame0 = get("frame=0").1["count"].as_u64().unwrap();

    // A trc job: records live across frames.
    let trc_frames = 6u32;
    let trc = create_job(
        &server,
        &format!(
            r#"{{"scene":"builtin:cube-in-box","method":"trc","frames":"0..{trc_frames}","size":"16x16","spp":1}}"#
        ),
    );
    wait_done(&server, &trc);
    let mut trc_counts = Vec::new();
    for f in 0..trc_frames {
        let (status, r) = http(
            &server,
            "GET",
            &format!("/api/jobs/{trc}/records?frame={f}"),
            "",
        );
        assert_eq!(status, 200);
        let r = json(&r);
        for rec in r["records"].as_array().unwrap() {
            let (c, l) = (
                rec["created"].as_u64().unwrap(),
                rec["last_frame"].as_u64().unwrap(),
            );
            assert!(c <= f as u64 && f as u64 <= l, "{rec}");
            assert_eq!(rec["reused"].as_u64().unwrap(), f as u64 - c);
        }
        trc_counts.push(r["count"].as_u64().unwrap());
    }
    assert!(trc_counts[0] > 0);
    // Frame 0 computed every record alive in it: the stats' mean lifespan
    // is theirs, from the records' own first and last frames.
    let (_, r) = http(
        &server,
        "GET",
        &format!("/api/jobs/{trc}/records?frame=0"),
        "",
    );
    let lives: Vec<f64> = json(&r)["records"]
        .as_array()
        .unwrap()
        .iter()
        .map(|rec| {
            (rec["last_frame"].as_u64().unwrap() - rec["created"].as_u64().unwrap() + 1) as f64
        })
        .collect();
    let (_, stats) = http(&server, "GET", &format!("/api/jobs/{trc}/stats"), "");
    let trc_rows = json(&stats)["frames"].clone();
    let mean = trc_rows[0]["mean_lifespan"].as_f64().unwrap();
    let expected = lives.iter().sum::<f64>() / lives.len() as f64;
    assert!(
        (mean - expected).abs() < 1e-9 * expected,
        "{mean} vs {expected}"
    );
    let trc_sid = |store: &radcache::store::Store| store.job(&trc).unwrap().unwrap().id;

    // The same job as the store and `inspect` see it (the server holds the
    // store's lock: stop it first).
    drop(server);
    let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["inspect", &id, "--json", "--db"])
        .arg(&db)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = json(&out.stdout);
    let frames = report["jobs"][0]["frame_details"].as_array().unwrap();
    for (f, n) in [(0, frame0), (1, records.len() as u64)] {
        assert_eq!(frames[f]["records_written"], n, "frame {f}");
        assert_eq!(frames[f]["records_alive"], n, "frame {f}");
    }
    let store = radcache::store::Store::open_existing(&db).unwrap();
    // trc: the records alive at each frame are as many as its statistics say.
    for f in 0..trc_frames {
        let stats = store.frame_stats(trc_sid(&store), f).unwrap().unwrap();
        assert_eq!(
            trc_counts[f as usize], stats.records_alive,
            "trc frame {f}: records alive vs stats"
        );
        // `/stats` serves what the store measured of the frame.
        let row = &trc_rows[f as usize];
        assert!(stats.cache_bytes > 0 && stats.stored_bytes > 0, "{stats:?}");
        assert_eq!(row["cache_bytes"], stats.cache_bytes, "{row}");
        assert_eq!(row["stored_bytes"], stats.stored_bytes, "{row}");
        assert_eq!(row["samples_reshot"], stats.samples_reshot, "{row}");
    }
    let sid = store.job(&id).unwrap().unwrap().id;
    let stored = store.frame_records(sid, 1).unwrap();
    assert_eq!(stored.len(), records.len());
    for (s, r) in stored.iter().zip(records) {
        assert_eq!(r["id"], s.id);
        let p: Vec<f32> = r["position"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        assert_eq!(p, s.position);
        assert_eq!(r["radius"].as_f64().unwrap() as f32, s.radius);
    }
}

/// `/records` keeps the records alive at some frames of a job between
/// queries and starts each query from the nearest: over 40 frames of a
/// `trc` job (records rewritten, living a few frames) and a `tcg` job
/// (records living for ever, written again every frame), queries in any
/// order give as many records as each frame's statistics say are alive,
/// and the same answers as a restarted server, which keeps none yet, gives
/// them in another order.
#[test]
fn records_are_the_same_in_any_order_of_queries() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let server = start(&db, &scenes);
    let frames = 40u32;
    let jobs: Vec<String> = ["trc", "tcg"]
        .iter()
        .map(|method| {
            create_job(
                &server,
                &format!(
                    r#"{{"scene":"builtin:cube-in-box","method":"{method}","frames":"0..{frames}","size":"8x8","spp":1}}"#
                ),
            )
        })
        .collect();
    let records = |server: &Server, id: &str, f: u32| {
        let path = format!("/api/jobs/{id}/records?frame={f}");
        let (status, body) = http(server, "GET", &path, "");
        assert_eq!(status, 200, "{path}");
        json(&body)
    };
    // Late frames first, then back and forth.
    let scrambled: Vec<u32> = (0..frames)
        .map(|i| (frames - 1 + 17 * i) % frames)
        .collect();
    let mut answers = Vec::new();
    for id in &jobs {
        wait_done(&server, id);
        let (_, stats) = http(&server, "GET", &format!("/api/jobs/{id}/stats"), "");
        let rows = json(&stats)["frames"].clone();
        let mut by_frame = std::collections::BTreeMap::new();
        for &f in &scrambled {
            let r = records(&server, id, f);
            assert_eq!(
                r["count"], rows[f as usize]["records_alive"],
                "{id} frame {f}"
            );
            by_frame.insert(f, r);
        }
        assert!(by_frame[&(frames - 1)]["count"].as_u64().unwrap() > 0);
        answers.push(by_frame);
    }
    drop(server);
    let server = start(&db, &scenes);
    for (id, by_frame) in jobs.iter().zip(&answers) {
        for f in 0..frames {
            assert!(records(&server, id, f) == by_frame[&f], "{id} frame {f}");
        }
    }
}

/// An `ic` job with radiance records: `/records?sources=true` gives each
/// radiance record its stored sources (their irradiance sums to the
/// record's) and each irradiance record `null`; without it, only how many
/// (`source_count`).
#[test]
fn records_show_the_sources_of_radiance_records() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"builtin:glossy-cornell","method":"ic","frames":"0..1","size":"16x16","spp":1,"settings":{"glossy":"eas","strata":"4x12"}}"#,
    );
    wait_done(&server, &id);
    let get = |q: &str| {
        let (status, body) = http(&server, "GET", &format!("/api/jobs/{id}/records?{q}"), "");
        (status, json(&body))
    };
    let (status, body) = get("frame=0&sources=true");
    assert_eq!(status, 200, "{body}");
    let records = body["records"].as_array().unwrap();
    let (_, counted) = get("frame=0");
    for (full, short) in records.iter().zip(counted["records"].as_array().unwrap()) {
        assert_eq!(full["id"], short["id"]);
        let listed = full["sources"].as_array().map(Vec::len);
        assert_eq!(short["source_count"].as_u64(), listed.map(|n| n as u64));
        assert!(short.get("sources").is_none(), "{short}");
    }
    let (status, _) = get("frame=0&sources=maybe");
    assert_eq!(status, 400);
    let (radiance, irradiance): (Vec<_>, Vec<_>) =
        records.iter().partition(|r| !r["sources"].is_null());
    assert!(!radiance.is_empty() && !irradiance.is_empty(), "{body}");
    let v3 =
        |v: &serde_json::Value| -> [f64; 3] { std::array::from_fn(|i| v[i].as_f64().unwrap()) };
    for r in radiance {
        let sources = r["sources"].as_array().unwrap();
        let mut sum = [0.0; 3];
        for s in sources {
            assert!(s["solid_angle"].as_f64().unwrap() > 0.0, "{s}");
            assert!(v3(&s["offset"]).iter().all(|x| x.is_finite()), "{s}");
            for (acc, e) in sum.iter_mut().zip(v3(&s["irradiance"])) {
                *acc += e;
            }
        }
        let want = v3(&r["irradiance"]);
        let scale = want.iter().cloned().fold(0.0, f64::max);
        for (a, b) in sum.iter().zip(want) {
            assert!((a - b).abs() <= 1e-4 * scale + 1e-6, "{r}");
        }
    }
}

fn job_state(server: &Server, id: &str) -> serde_json::Value {
    let (status, body) = http(server, "GET", &format!("/api/jobs/{id}"), "");
    assert_eq!(status, 200);
    json(&body)
}

#[test]
fn killed_server_resumes_its_job_and_frames_equal_an_uninterrupted_run() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let frames = 24;
    // Settings other than the defaults: the restarted server must resume
    // the job with them (the store refuses other settings).
    let request = format!(
        r#"{{"scene":"builtin:cube-in-box","method":"trc","frames":"0..{frames}","size":"24x24","spp":2,"settings":{{"max_life":5,"at":0.02}}}}"#
    );
    let mut server = start(&db, &scenes);
    let id = create_job(&server, &request);
    // Queued behind it, then cancelled: must stay cancelled after the restart.
    let cancelled = create_job(&server, &request);
    let (status, body) = http(
        &server,
        "POST",
        &format!("/api/jobs/{cancelled}/cancel"),
        "",
    );
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    assert_eq!(json(&body)["state"], "cancelled");
    let start_time = Instant::now();
    let done_at_kill = loop {
        let done = job_state(&server, &id)["frames_done"].as_u64().unwrap();
        if done >= 2 {
            break done;
        }
        assert!(start_time.elapsed() < Duration::from_secs(120));
        std::thread::sleep(Duration::from_millis(5));
    };
    // SIGKILL: no chance to finish the frame or flush anything.
    server.child.kill().unwrap();
    server.child.wait().unwrap();
    assert!(done_at_kill < frames, "the job finished before the kill");

    let server = start(&db, &scenes);
    assert_eq!(job_state(&server, &cancelled)["state"], "cancelled");
    let job = wait_done(&server, &id);
    assert_eq!(job["frames_done"], frames);
    assert_eq!(job_state(&server, &cancelled)["state"], "cancelled");

    // The same job rendered in one go by the CLI.
    let out = dir.path().join("cli");
    let range = format!("0..{frames}");
    render_with_cli(
        &[
            "--method",
            "trc",
            "--frames",
            &range,
            "--trc-max-life",
            "5",
            "--trc-at",
            "0.02",
        ],
        &["--size", "24x24", "--spp", "2"],
        &out,
    );
    assert_frames_equal_cli(&server, &id, frames, &out);
    assert_eq!(job["settings"]["max_life"], 5, "{job}");
    // The cancelled job resumes on request, once however many ask at once
    // (a double click): the others are 409s, decided on the state as it
    // is, not as it was when they came. Queued again once the worker had
    // started it, a running job showed as queued, and a cancel then let it
    // run on.
    let resume = format!("/api/jobs/{cancelled}/resume");
    let statuses: Vec<u16> = std::thread::scope(|s| {
        let asks: Vec<_> = (0..8)
            .map(|_| s.spawn(|| http(&server, "POST", &resume, "").0))
            .collect();
        asks.into_iter().map(|a| a.join().unwrap()).collect()
    });
    assert_eq!(
        statuses.iter().filter(|&&s| s == 200).count(),
        1,
        "{statuses:?}"
    );
    assert!(
        statuses.iter().all(|&s| s == 200 || s == 409),
        "{statuses:?}"
    );
    assert_eq!(wait_done(&server, &cancelled)["frames_done"], frames);
}

/// (method, path) of every `.route(…)` in the router's source.
fn router_routes() -> Vec<(String, String)> {
    let src =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/src/server/mod.rs")).unwrap();
    let mut routes = Vec::new();
    for line in src
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with(".route(\""))
    {
        let rest = &line[".route(\"".len()..];
        let (path, handlers) = rest.split_once('"').unwrap();
        for method in ["get", "post", "put", "delete", "patch"] {
            if handlers.contains(&format!(" {method}("))
                || handlers.contains(&format!(".{method}("))
            {
                routes.push((method.to_string(), path.to_string()));
            }
        }
    }
    routes
}

#[test]
fn openapi_documents_every_route() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    let (status, body) = http(&server, "GET", "/api/openapi.json", "");
    assert_eq!(status, 200);
    let doc = json(&body);
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    let routes = router_routes();
    assert!(routes.len() >= 15, "{routes:?}");
    for (method, path) in &routes {
        assert!(
            doc["paths"][path][method].is_object(),
            "{} {path} is not in web/openapi.json",
            method.to_uppercase()
        );
    }
    let paths = doc["paths"].as_object().unwrap();
    for (path, ops) in paths {
        for method in ops.as_object().unwrap().keys() {
            assert!(
                routes.contains(&(method.clone(), path.clone())),
                "web/openapi.json documents {method} {path}, which the router lacks"
            );
            // Every documented route reaches a handler (not the fallback).
            let concrete = path.replace("{id}", "job-1").replace("{file}", "x");
            let (_, body) = http(&server, &method.to_uppercase(), &concrete, "");
            assert!(
                !String::from_utf8_lossy(&body).contains("no such route"),
                "{method} {concrete} hits the fallback"
            );
        }
    }
    // Every `$ref` resolves.
    let text = String::from_utf8(body).unwrap();
    for r in text.split("\"$ref\": \"#/").skip(1) {
        let pointer = format!("/{}", r.split('"').next().unwrap());
        assert!(doc.pointer(&pointer).is_some(), "unresolved $ref {pointer}");
    }
}

#[test]
fn bench_charts_come_from_the_bench_directory_when_given() {
    let (dir, scenes) = workspace();
    // Embedded charts by default.
    let server = start(&dir.path().join("db"), &scenes);
    let (status, body) = http(&server, "GET", "/api/charts", "");
    assert_eq!(status, 200);
    let charts = json(&body);
    assert!(charts
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["name"] == "cube-in-box_error_vs_time.svg"));
    let (status, svg) = http(
        &server,
        "GET",
        "/web/charts/cube-in-box_error_vs_time.svg",
        "",
    );
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&svg).contains("<svg"));
    // The embedded 400-frame bench sweeps `trc`'s `a_t` and `δt_max`.
    let (status, csv) = http(
        &server,
        "GET",
        "/web/charts/cube-in-box-400-frames_bench.csv",
        "",
    );
    assert_eq!(status, 200);
    let csv = String::from_utf8_lossy(&csv);
    for setting in ["at=", "max_life="] {
        let runs = csv
            .lines()
            .filter(|l| l.contains(",trc,") && l.contains(setting))
            .count();
        assert!(runs >= 3, "{runs} trc runs with {setting} in\n{csv}");
    }
    // Every method is charted where things move too, and where everything
    // does.
    for scene in ["moving-light", "spheres", "many-cubes"] {
        let name = format!("{scene}_error_vs_time.svg");
        assert!(
            charts.as_array().unwrap().iter().any(|c| c["name"] == name),
            "no {name} in {charts}"
        );
        let (status, csv) = http(
            &server,
            "GET",
            &format!("/web/charts/{scene}_bench.csv"),
            "",
        );
        assert_eq!(status, 200);
        let csv = String::from_utf8_lossy(&csv);
        for method in ["path", "ic", "trc", "tcg", "movies"] {
            let row = format!("{scene},{method},");
            assert!(
                csv.lines().any(|l| l.starts_with(&row)),
                "no {row} in\n{csv}"
            );
        }
    }
    drop(server);

    let bench = dir.path().join("bench-out");
    std::fs::create_dir(&bench).unwrap();
    std::fs::write(bench.join("s_error_vs_time.svg"), "<svg id='mine'></svg>").unwrap();
    std::fs::write(bench.join("bench.csv"), "scene,method\n").unwrap();
    std::fs::write(bench.join("notes.txt"), "no").unwrap();
    std::fs::write(dir.path().join("secret.svg"), "<svg id='secret'></svg>").unwrap();
    // A link in the directory that leads out of it is neither listed nor served.
    std::os::unix::fs::symlink(dir.path().join("secret.svg"), bench.join("link.svg")).unwrap();
    let server = start_with(
        &dir.path().join("db"),
        &scenes,
        &["--bench", bench.to_str().unwrap()],
    );
    let (status, body) = http(&server, "GET", "/api/charts", "");
    assert_eq!(status, 200);
    let names: Vec<String> = json(&body)
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(names, ["bench.csv", "s_error_vs_time.svg"]);
    let (status, svg) = http(&server, "GET", "/web/charts/s_error_vs_time.svg", "");
    assert_eq!(status, 200);
    assert_eq!(svg, b"<svg id='mine'></svg>");
    for bad in [
        "notes.txt",
        "..%2Fsecret.svg",
        "%2E%2E%2Fsecret.svg",
        "missing.svg",
        ".hidden.svg",
        "link.svg",
    ] {
        let (status, body) = http(&server, "GET", &format!("/web/charts/{bad}"), "");
        assert_eq!(status, 404, "{bad}: {}", String::from_utf8_lossy(&body));
        assert!(!String::from_utf8_lossy(&body).contains("id='secret'"));
    }
}

/// A GET with extra header lines; returns (status, body).
fn get_with(addr: &str, path: &str, headers: &str) -> (u16, Vec<u8>) {
    let (status, _, body) = request(addr, "GET", path, headers, "");
    (status, body)
}

#[test]
fn a_token_is_required_on_every_request_and_the_dashboard_carries_it() {
    let (dir, scenes) = workspace();
    // A non-loopback address without a token is refused.
    let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["serve", "--addr", "0.0.0.0:0", "--db"])
        .arg(dir.path().join("db0"))
        .env_remove("RADCACHE_TOKEN")
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--token"));

    // Non-ASCII too: a header carries it as its UTF-8 bytes.
    let token = "s3cret/+ &xü";
    let encoded = "s3cret%2F%2B%20%26x%C3%BC";
    let server = start_with(&dir.path().join("db"), &scenes, &["--token", token]);
    let addr = server.addr.clone();
    let (status, head, body) = request(&addr, "GET", "/api/jobs", "", "");
    assert_eq!(status, 401);
    assert!(json(&body)["detail"].is_string());
    assert!(
        head.to_ascii_lowercase()
            .contains("www-authenticate: bearer"),
        "{head}"
    );
    // The scheme's case does not matter (RFC 7235).
    assert_eq!(
        get_with(
            &addr,
            "/api/jobs",
            &format!("authorization: bearer {token}\r\n")
        )
        .0,
        200
    );
    assert_eq!(
        get_with(&addr, "/api/jobs", "Authorization: Bearer wrong\r\n").0,
        401
    );
    assert_eq!(get_with(&addr, "/api/jobs?token=wrong", "").0, 401);
    assert_eq!(get_with(&addr, "/", "").0, 401);
    assert_eq!(get_with(&addr, "/web/app.js", "").0, 401);
    let (status, _) = get_with(
        &addr,
        "/api/jobs",
        &format!("Authorization: Bearer {token}\r\n"),
    );
    assert_eq!(status, 200);
    assert_eq!(
        get_with(&addr, &format!("/api/jobs?token={encoded}"), "").0,
        200
    );
    let (status, html) = get_with(&addr, &format!("/?token={encoded}"), "");
    assert_eq!(status, 200);
    let html = String::from_utf8(html).unwrap();
    assert!(
        html.contains(&format!("/web/app.js?token={encoded}")),
        "{html}"
    );
    assert!(
        html.contains(&format!("/web/app.css?token={encoded}")),
        "{html}"
    );
    assert_eq!(
        get_with(&addr, &format!("/web/app.js?token={encoded}"), "").0,
        200
    );
    assert_eq!(get_with(&addr, "/api/jobs?token=%zz", "").0, 401);
    // Of two tokens, neither is taken, whichever comes first.
    for query in [
        format!("token={encoded}&token=x"),
        format!("token=x&token={encoded}"),
    ] {
        assert_eq!(get_with(&addr, &format!("/api/jobs?{query}"), "").0, 401);
    }
}

/// `radcache render --builtin cube-in-box ARGS… --backend cpu -q --db DB
/// --job NAME --out OUT`, not yet waited for.
fn render_job_with_cli(
    args: &[&str],
    db: &std::path::Path,
    name: &str,
    out: &std::path::Path,
) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["render", "--builtin", "cube-in-box"])
        .args(args)
        .args(["--backend", "cpu", "-q", "--db"])
        .arg(db)
        .args(["--job", name, "--out"])
        .arg(out)
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap()
}

/// The jobs `radcache render --db --job NAME` left in the store are listed
/// after the server's own (origin `render`), done or stopped, with their
/// frames, statistics, records and stream; the server neither runs nor
/// resumes them, and numbers its own jobs as before.
#[test]
fn jobs_of_radcache_render_are_shown_and_not_run() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let walk_out = dir.path().join("walk");
    let status = render_job_with_cli(
        &[
            "--method", "trc", "--size", "8x8", "--frames", "0..2", "--spp", "2",
        ],
        &db,
        "walk",
        &walk_out,
    )
    .wait()
    .unwrap();
    assert!(status.success());
    // An interrupted render: killed once its first frame is out.
    let part_out = dir.path().join("part");
    let mut part = render_job_with_cli(
        &[
            "--method", "ic", "--size", "16x16", "--frames", "0..500", "--spp", "1",
        ],
        &db,
        "part",
        &part_out,
    );
    let started = Instant::now();
    while !part_out.join("frame_0000.png").exists() {
        assert!(started.elapsed() < Duration::from_secs(120), "no frame");
        std::thread::sleep(Duration::from_millis(10));
    }
    part.kill().unwrap();
    part.wait().unwrap();

    let server = start(&db, &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"8x8","spp":1}"#,
    );
    assert_eq!(id, "job-1");
    wait_done(&server, &id);
    let (status, body) = http(&server, "GET", "/api/jobs", "");
    assert_eq!(status, 200);
    let jobs = json(&body);
    let summary: Vec<(&str, &str, &str)> = jobs
        .as_array()
        .unwrap()
        .iter()
        .map(|j| {
            let field = |k: &str| j[k].as_str().unwrap();
            (field("id"), field("origin"), field("state"))
        })
        .collect();
    assert_eq!(
        summary,
        [
            ("job-1", "serve", "done"),
            ("part", "render", "stopped"),
            ("walk", "render", "done"),
        ]
    );
    let part_done = jobs[1]["frames_done"].as_u64().unwrap();
    assert!(part_done < 500, "{}", jobs[1]);

    // The finished job: frames, statistics, records and stream.
    assert_frames_equal_cli(&server, "walk", 2, &walk_out);
    let (status, body) = http(&server, "GET", "/api/jobs/walk/stats", "");
    assert_eq!(status, 200);
    let stats = json(&body);
    assert_eq!(stats["frames"].as_array().unwrap().len(), 2);
    let (status, body) = http(&server, "GET", "/api/jobs/walk/records?frame=1", "");
    assert_eq!(status, 200);
    assert_eq!(
        json(&body)["count"],
        stats["frames"][1]["records_alive"],
        "records alive at frame 1"
    );
    let (status, head, body) = http_full(&server.addr, "GET", "/api/jobs/walk/stream", "");
    assert_eq!(status, 200);
    let frames: Vec<u32> = multipart_parts(&head, &body).iter().map(|p| p.0).collect();
    assert_eq!(frames, [0, 1], "the stream ends with the job's frames");

    // Neither is run or resumed here; the error names the command.
    let (status, body) = http(&server, "POST", "/api/jobs/part/resume", "");
    assert_eq!(status, 409);
    let detail = json(&body)["detail"].as_str().unwrap().to_string();
    assert!(detail.contains("radcache render --job part"), "{detail}");
    let (status, _) = http(&server, "POST", "/api/jobs/walk/cancel", "");
    assert_eq!(status, 409);
    std::thread::sleep(Duration::from_millis(300));
    let (_, body) = http(&server, "GET", "/api/jobs/part", "");
    let job = json(&body);
    assert_eq!(job["state"], "stopped");
    assert_eq!(job["frames_done"].as_u64().unwrap(), part_done);
}

/// A job `radcache render --job NAME` rendered over two ranges shows both:
/// its last range with its progress, every stored frame as runs, and its
/// stream and events carry all of them in order (they showed the last
/// range only).
#[test]
fn a_job_rendered_over_two_ranges_shows_and_streams_both() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let out = dir.path().join("out");
    for frames in ["0..2", "3..5"] {
        let args = [
            "--method", "ic", "--size", "8x8", "--spp", "1", "--frames", frames,
        ];
        let status = render_job_with_cli(&args, &db, "walk", &out)
            .wait()
            .unwrap();
        assert!(status.success());
    }
    let server = start(&db, &scenes);
    let (status, body) = http(&server, "GET", "/api/jobs/walk", "");
    assert_eq!(status, 200);
    let job = json(&body);
    assert_eq!(job["frames"], "3..5", "{job}");
    assert_eq!(
        (job["frames_done"].as_u64(), job["frames_total"].as_u64()),
        (Some(2), Some(2))
    );
    assert_eq!(job["frames_stored"], 4, "{job}");
    assert_eq!(
        job["stored_ranges"],
        serde_json::json!(["0..2", "3..5"]),
        "{job}"
    );
    assert_eq!(job["state"], "done");
    let (status, head, body) = http_full(&server.addr, "GET", "/api/jobs/walk/stream", "");
    assert_eq!(status, 200);
    let frames: Vec<u32> = multipart_parts(&head, &body).iter().map(|p| p.0).collect();
    assert_eq!(frames, [0, 1, 3, 4]);
    let (status, _, body) = http_full(&server.addr, "GET", "/api/jobs/walk/events", "");
    assert_eq!(status, 200);
    let events: Vec<u64> = sse_events(&body)
        .iter()
        .filter(|e| e.0 == "frame")
        .map(|e| e.1["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(events, [0, 1, 3, 4]);
}

/// `DELETE /api/jobs/{id}`: a queued job is refused (cancel it first); an
/// ended one goes with its frames and frame files, its number is not
/// given again (also after a restart), and a `radcache render` job goes
/// from the store too.
#[test]
fn ended_jobs_are_deleted_with_their_frames_and_their_numbers_stay_taken() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let status = render_job_with_cli(
        &[
            "--method", "ic", "--size", "8x8", "--frames", "0..1", "--spp", "1",
        ],
        &db,
        "walk",
        &dir.path().join("walk"),
    )
    .wait()
    .unwrap();
    assert!(status.success());
    let mut server = start(&db, &scenes);
    let fast =
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..2","size":"8x8","spp":1}"#;
    let done = create_job(&server, fast);
    wait_done(&server, &done);
    let files = dir.path().join("db.frames").join(&done);
    assert!(files.join("frame_0001.png").exists());
    let queued = create_job_behind(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..2","size":"48x48","spp":32}"#,
        fast,
    );
    let (status, body) = http(&server, "DELETE", &format!("/api/jobs/{queued}"), "");
    assert_eq!(status, 409, "{}", String::from_utf8_lossy(&body));
    assert!(String::from_utf8_lossy(&body).contains("cancel it first"));

    let (status, body) = http(&server, "DELETE", &format!("/api/jobs/{done}"), "");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    assert_eq!(json(&body)["deleted"], true);
    for path in ["", "/stats", "/frames/0.png", "/stream"] {
        let (status, _) = http(&server, "GET", &format!("/api/jobs/{done}{path}"), "");
        assert_eq!(status, 404, "{path}");
    }
    assert!(
        !files.exists(),
        "the server's frame files of {done} are gone"
    );
    let (status, _) = http(&server, "DELETE", &format!("/api/jobs/{done}"), "");
    assert_eq!(status, 404);
    let (status, _) = http(&server, "DELETE", "/api/jobs/walk", "");
    assert_eq!(status, 200);
    assert!(
        dir.path().join("walk").join("frame_0000.png").exists(),
        "render's own files stay"
    );

    // Numbers given once stay taken, across a restart too.
    wait_done(&server, &queued);
    let next = create_job(&server, fast);
    assert_eq!((done.as_str(), next.as_str()), ("job-1", "job-4"));
    wait_done(&server, &next);
    terminate(&mut server, Duration::from_secs(10));
    drop(server);
    let server = start(&db, &scenes);
    let (_, body) = http(&server, "GET", "/api/jobs", "");
    let ids: Vec<String> = json(&body)
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        ids,
        ["job-2", "job-3", "job-4"],
        "job-1 and walk are gone from the store"
    );
    let (status, body) = http(&server, "DELETE", "/api/jobs/job-4", "");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    assert_eq!(create_job(&server, fast), "job-5");
}

/// A stored `job-N` that the server leaves out of its table (here a frame
/// range no request gives, as a damaged store might hold) keeps its name:
/// a new job is numbered past it, rather than taking over its frames or
/// failing on it for good.
#[test]
fn new_jobs_are_numbered_past_stored_jobs_the_server_left_out() {
    use radcache::render::{self, FrameSettings, MethodSettings, SceneSource};
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    {
        let store = radcache::store::Store::open(&db).unwrap();
        let method = MethodSettings::Path(Default::default());
        let source = SceneSource::Builtin("cube-in-box".into());
        let mut spec =
            render::job_spec("job-1", &source, &method, &FrameSettings::default(), 0..1).unwrap();
        spec.frame_end = spec.frame_start;
        store.begin_job(&spec, false).unwrap();
    }
    let server = start(&db, &scenes);
    let (_, listed) = http(&server, "GET", "/api/jobs", "");
    assert_eq!(json(&listed), serde_json::json!([]));
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"8x8","spp":1}"#,
    );
    assert_eq!(id, "job-2");
    wait_done(&server, &id);
}

/// A served `trc` job stored by a build whose `trc` algorithm was another
/// (here: before revisions were recorded) is not resumed on restart: it
/// fails, saying to submit it again (the API has no `--force`).
#[test]
fn a_served_job_of_another_algorithm_revision_fails_saying_to_resubmit() {
    use radcache::render::{self, FrameSettings, MethodSettings, SceneSource};
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let id = {
        let store = radcache::store::Store::open(&db).unwrap();
        let method = MethodSettings::Trc(Default::default());
        let source = SceneSource::Builtin("cube-in-box".into());
        let frames = FrameSettings {
            width: 8,
            height: 8,
            ..FrameSettings::default()
        };
        let spec = render::job_spec("job-1", &source, &method, &frames, 0..2).unwrap();
        store.begin_job(&spec, false).unwrap().id
    };
    {
        // The store just closed: its lock is released a moment later.
        let db = store_fixtures::open_raw(&db);
        let meta = db.open_tree("meta").unwrap();
        let key = radcache::store::keys::meta_revision(id);
        assert!(meta.remove(key).unwrap().is_some());
        db.flush().unwrap();
    }
    let server = start(&db, &scenes);
    let start = Instant::now();
    let job = loop {
        let job = job_state(&server, "job-1");
        if job["state"] != "queued" && job["state"] != "running" {
            break job;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "{job}");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(job["state"], "failed", "{job}");
    let error = job["error"].as_str().unwrap();
    assert!(
        error.contains("algorithm revision (stored 1")
            && error.contains("delete it and submit it again")
            && !error.contains("--force"),
        "{error}"
    );
}

/// A job of `radcache render` stores its scene file by its absolute path,
/// so the server finds it from its own working directory; one whose file
/// it cannot find (moved since) still lists and serves its frames; only
/// its records, whose screen positions need the scene's camera, are a 409
/// that says why.
#[test]
fn a_render_jobs_scene_the_server_cannot_find_is_a_clear_conflict() {
    let (dir, scenes) = workspace();
    let (db, work) = serve_client::store_with_a_render_job(dir.path());
    {
        let server = start(&db, &scenes);
        let (status, body) = http(&server, "GET", "/api/jobs/boxed/records?frame=0", "");
        assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    }
    std::fs::rename(work.join("box.glb"), work.join("moved.glb")).unwrap();
    let server = start(&db, &scenes);
    let (status, body) = http(&server, "GET", "/api/jobs/boxed", "");
    assert_eq!(status, 200);
    assert_eq!(json(&body)["state"], "done");
    let (status, _) = http(&server, "GET", "/api/jobs/boxed/frames/0.png", "");
    assert_eq!(status, 200);
    let (status, body) = http(&server, "GET", "/api/jobs/boxed/records?frame=0", "");
    assert_eq!(status, 409);
    let detail = json(&body)["detail"].as_str().unwrap().to_string();
    assert!(
        detail.contains("box.glb") && detail.contains("cannot load"),
        "{detail}"
    );
}

/// Waits until job `id` is running (its first frame under way).
fn wait_running(server: &Server, id: &str) {
    let start = Instant::now();
    while job_state(server, id)["state"] != "running" {
        assert!(start.elapsed() < Duration::from_secs(60), "never ran");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A frame of this job is an hour of work or more (64² pixels at 65,536 paths
/// each): a cancel, and then a SIGTERM, must not wait for it.
const ENDLESS_FRAME: &str =
    r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..2","size":"64x64","spp":65536}"#;

#[test]
fn a_cancel_or_a_sigterm_abandons_a_long_frame_at_once() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let mut server = start(&db, &scenes);
    let long = create_job(&server, ENDLESS_FRAME);
    let small =
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"8x8","spp":1}"#;
    let after = create_job(&server, small);
    wait_running(&server, &long);
    std::thread::sleep(Duration::from_millis(300));
    let (status, answer) = http(&server, "POST", &format!("/api/jobs/{long}/cancel"), "");
    assert_eq!(status, 200);
    // The answer comes once the job has stopped.
    let answer = json(&answer);
    assert_eq!(
        (answer["state"].as_str(), answer["cancelling"].as_bool()),
        (Some("cancelled"), Some(false)),
        "{answer}"
    );
    let cancelled_at = Instant::now();
    // The job queued behind it runs once the frame is abandoned.
    let done = wait_done(&server, &after);
    let cancelled = job_state(&server, &long);
    assert_eq!(cancelled["state"], "cancelled", "{cancelled}");
    assert_eq!(
        cancelled["frames_done"], 0,
        "the abandoned frame is no frame"
    );
    assert_eq!(done["frames_done"], 1);
    assert!(
        cancelled_at.elapsed() < Duration::from_secs(30),
        "cancel took {:?}",
        cancelled_at.elapsed()
    );

    // Resumed, then SIGTERM in the middle of its first frame: the server
    // exits at once and the job is queued again for the next start.
    let (status, _) = http(&server, "POST", &format!("/api/jobs/{long}/resume"), "");
    assert_eq!(status, 200);
    wait_running(&server, &long);
    let events = {
        let addr = server.addr.clone();
        let path = format!("/api/jobs/{long}/events");
        std::thread::spawn(move || http_full(&addr, "GET", &path, ""))
    };
    std::thread::sleep(Duration::from_millis(300));
    terminate(&mut server, Duration::from_secs(30));
    // Its events end with a state that is not final: the job goes on
    // after a restart.
    let (_, _, body) = events.join().unwrap();
    let events = sse_events(&body);
    let (kind, last) = events.last().expect("events");
    assert_eq!(kind, "state");
    assert_eq!(last["final"], false, "{last}");
    assert!(last["closing"].is_string(), "{last}");
    let server = start_with(&db, &scenes, &[]);
    let again = job_state(&server, &long);
    assert!(
        matches!(again["state"].as_str(), Some("queued" | "running")),
        "{again}"
    );
    assert_eq!(again["frames_done"], 0);
}

/// A server that dies twice while rendering a job, with no frame stored in
/// between (a job too large for the machine: an aborted allocation, the
/// OOM killer), does not start it a third time, which under a supervisor
/// that restarts it would crash it for ever: the job fails saying why, the
/// job behind it runs, and a resume starts it again.
#[test]
fn a_job_the_server_died_in_twice_is_not_started_a_third_time() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let mut server = start(&db, &scenes);
    let small =
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"8x8","spp":1}"#;
    let long = create_job(&server, ENDLESS_FRAME);
    let after = create_job(&server, small);
    // The render makes the job's frame folder once its start is marked in
    // the store: made, the server dies as a render killed it would.
    let frames_dir = dir.path().join("db.frames").join(&long);
    for death in 0..2 {
        let start_time = Instant::now();
        while !frames_dir.is_dir() {
            assert!(start_time.elapsed() < Duration::from_secs(60), "never ran");
            std::thread::sleep(Duration::from_millis(20));
        }
        server.child.kill().unwrap(); // SIGKILL
        server.child.wait().unwrap();
        std::fs::remove_dir_all(&frames_dir).unwrap();
        server = start(&db, &scenes);
        if death == 0 {
            // Once is no crash loop (a power cut): the job runs again.
            let again = job_state(&server, &long);
            assert!(
                matches!(again["state"].as_str(), Some("queued" | "running")),
                "{again}"
            );
        }
    }
    let failed = job_state(&server, &long);
    assert_eq!(failed["state"], "failed", "{failed}");
    let error = failed["error"].as_str().unwrap();
    assert!(
        error.contains("stopped twice") && error.contains(&format!("/api/jobs/{long}/resume")),
        "{error}"
    );
    assert_eq!(wait_done(&server, &after)["frames_done"], 1);
    assert!(!frames_dir.exists(), "started a third time");
    let (status, _) = http(&server, "POST", &format!("/api/jobs/{long}/resume"), "");
    assert_eq!(status, 200);
    wait_running(&server, &long);
}

/// Bytes read from `s` until the server closes it, and how long that took;
/// panics if it stays open past `limit`.
fn read_until_closed(s: &mut std::net::TcpStream, limit: Duration) -> (Vec<u8>, Duration) {
    use std::io::Read;
    s.set_read_timeout(Some(limit)).unwrap();
    let started = Instant::now();
    let mut got = Vec::new();
    match s.read_to_end(&mut got) {
        Ok(_) => {}
        // A reset also closes it.
        Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => {}
        Err(e) => panic!(
            "still open after {:?} ({e}); read {got:?}",
            started.elapsed()
        ),
    }
    (got, started.elapsed())
}

/// A client that never finishes its request's head, one that never sends
/// the body it announced, and one that stays idle on a kept-alive
/// connection are each let go after `--client-timeout` (they held a
/// connection, and with enough of them the process's file descriptors,
/// for ever); the server goes on serving.
#[test]
fn clients_too_slow_to_send_their_request_are_let_go() {
    use std::io::Write;
    let (dir, scenes) = workspace();
    let server = start_with(&dir.path().join("db"), &scenes, &["--client-timeout", "1"]);
    let connect = || std::net::TcpStream::connect(&server.addr).unwrap();
    let limit = Duration::from_secs(20);
    let mut head = connect();
    write!(head, "GET /api/jobs HTTP/1.1\r\nHost: x\r\n").unwrap();
    let mut body = connect();
    write!(
        body,
        "POST /api/jobs HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{{\"scene\""
    )
    .unwrap();
    let mut idle = connect();
    write!(idle, "GET /api/jobs HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    let (_, waited) = read_until_closed(&mut head, limit);
    assert!(waited < Duration::from_secs(10), "head: {waited:?}");
    let (answer, waited) = read_until_closed(&mut body, limit);
    let answer = String::from_utf8_lossy(&answer);
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert!(answer.contains("not sent within 1 s"), "{answer}");
    assert!(waited < Duration::from_secs(10), "body: {waited:?}");
    let (answer, _) = read_until_closed(&mut idle, limit);
    assert!(
        String::from_utf8_lossy(&answer).starts_with("HTTP/1.1 200"),
        "the idle client's request was answered"
    );
    let (status, _) = http(&server, "GET", "/api/jobs", "");
    assert_eq!(status, 200);
}

/// SIGTERM while a client holds a request it never finishes (here with a
/// client timeout of an hour): the server stops within its grace period
/// of 5 s (it waited for the client, holding the store's lock), and
/// refuses new clients in the meantime.
#[test]
fn a_shutdown_does_not_wait_for_a_client_that_never_finishes() {
    use std::io::Write;
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let mut server = start_with(&db, &scenes, &["--client-timeout", "3600"]);
    let mut stuck = std::net::TcpStream::connect(&server.addr).unwrap();
    write!(
        stuck,
        "POST /api/jobs HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{{"
    )
    .unwrap();
    let mut half = std::net::TcpStream::connect(&server.addr).unwrap();
    write!(half, "GET /api/jobs HTTP/1.1\r\n").unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let addr = server.addr.clone();
    terminate_then(&mut server, Duration::from_secs(20), || {
        // Within the grace period, a new client is refused, not queued.
        std::thread::sleep(Duration::from_secs(1));
        let late = std::net::TcpStream::connect(&addr);
        assert!(late.is_err(), "a client connected after SIGTERM");
    });
    drop((stuck, half));
}

/// `/metrics`' store bytes hold the sample log's, most of a caching
/// method's store (they were sled's database alone), and the log's own
/// gauge is its file's length.
#[test]
fn metrics_count_the_sample_log_in_the_store_bytes() {
    let (dir, scenes) = workspace();
    let db = dir.path().join("db");
    let server = start(&db, &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"ic","frames":"0..1","size":"16x16","spp":1}"#,
    );
    wait_done(&server, &id);
    let (status, metrics) = http(&server, "GET", "/metrics", "");
    assert_eq!(status, 200);
    let log = std::fs::metadata(db.join("samples.log")).unwrap().len();
    let database = std::fs::metadata(db.join("db")).unwrap().len();
    assert!(
        log > database,
        "the job's samples: {log} bytes, database {database}"
    );
    assert_eq!(gauge(&metrics, "radcache_store_sample_log_bytes"), log);
    assert!(gauge(&metrics, "radcache_store_bytes") > log);
}

/// Waits (10 s at most) until the server's open connections, as
/// `/metrics` counts them with its own, are as `want` says, once `after`.
fn wait_for_connections(server: &Server, want: impl Fn(u64) -> bool, after: &str) {
    let waited = Instant::now();
    loop {
        let (_, metrics) = http(server, "GET", "/metrics", "");
        let open = gauge(&metrics, "radcache_http_connections");
        if want(open) {
            return;
        }
        assert!(
            waited.elapsed() < Duration::from_secs(10),
            "{open} connections open 10 s after {after}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// One client address may hold 64 connections at once (the server's
/// `MAX_CONNECTIONS_PER_PEER`): one more from it is closed unanswered,
/// while another address is still served, and so is the first once one of
/// its connections closes. Before, one address without the token could
/// hold all 512 of the server's connections, and no one else was served.
#[test]
fn one_address_cannot_take_all_the_connections() {
    use std::io::Write;
    const PER_PEER: usize = 64;
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    let ask = |s: &mut std::net::TcpStream, path: &str| {
        write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        read_one_answer(s)
    };
    // Each answered, so each is served before the next connects.
    let mut held: Vec<_> = (0..PER_PEER)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(&server.addr).unwrap();
            ask(&mut s, "/api/jobs");
            s
        })
        .collect();
    let mut over = std::net::TcpStream::connect(&server.addr).unwrap();
    // The server may have closed it already (then this write fails).
    let _ = write!(over, "GET /api/jobs HTTP/1.1\r\nHost: x\r\n\r\n");
    let (got, waited) = read_until_closed(&mut over, Duration::from_secs(10));
    assert!(
        got.is_empty(),
        "a connection over the cap was answered: {:?}",
        String::from_utf8_lossy(&got)
    );
    assert!(waited < Duration::from_secs(5), "closed after {waited:?}");
    let metrics = ask(&mut held[0], "/metrics");
    assert_eq!(
        gauge(&metrics, "radcache_http_connections"),
        PER_PEER as u64
    );
    assert_eq!(
        gauge(&metrics, "radcache_http_connections_refused_total"),
        1
    );
    // Another address (on Linux all of 127.0.0.0/8 is the loopback) is
    // served meanwhile.
    #[cfg(target_os = "linux")]
    {
        let to: std::net::SocketAddr = server.addr.parse().unwrap();
        let socket =
            socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
        let from: std::net::SocketAddr = "127.0.0.2:0".parse().unwrap();
        socket.bind(&from.into()).unwrap();
        socket.connect(&to.into()).unwrap();
        let mut other: std::net::TcpStream = socket.into();
        let metrics = ask(&mut other, "/metrics");
        assert_eq!(
            gauge(&metrics, "radcache_http_connections"),
            PER_PEER as u64 + 1
        );
    }
    drop(held.pop());
    // Once the server has seen that one close, the first address is
    // served again.
    let waited = Instant::now();
    loop {
        let mut s = std::net::TcpStream::connect(&server.addr).unwrap();
        let _ = write!(
            s,
            "GET /api/jobs HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
        );
        let (got, _) = read_until_closed(&mut s, Duration::from_secs(10));
        if got.starts_with(b"HTTP/1.1 200") {
            break;
        }
        assert!(
            waited.elapsed() < Duration::from_secs(10),
            "not served again 10 s after one of its connections closed"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Reads one answer with a `Content-Length` from a kept-alive connection.
fn read_one_answer(s: &mut std::net::TcpStream) -> Vec<u8> {
    use std::io::Read;
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut got = Vec::new();
    let mut byte = [0u8; 1];
    while !got.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut byte).unwrap();
        got.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&got).to_ascii_lowercase();
    let length: usize = head
        .lines()
        .find_map(|l| l.strip_prefix("content-length: "))
        .unwrap_or_else(|| panic!("no content-length: {head}"))
        .trim()
        .parse()
        .unwrap();
    let mut body = vec![0u8; length];
    s.read_exact(&mut body).unwrap();
    body
}

/// The value of gauge `name` in a `/metrics` answer.
fn gauge(metrics: &[u8], name: &str) -> u64 {
    let text = String::from_utf8_lossy(metrics);
    let line = text
        .lines()
        .find(|l| l.starts_with(&format!("{name} ")))
        .unwrap_or_else(|| panic!("no {name}: {text}"));
    line.rsplit_once(' ').unwrap().1.parse().unwrap()
}

/// Sends SIGTERM to the server and waits for it to exit, successfully,
/// within `limit`.
fn terminate(server: &mut Server, limit: Duration) {
    terminate_then(server, limit, || {});
}

/// [`terminate`], calling `meanwhile` once SIGTERM is sent.
fn terminate_then(server: &mut Server, limit: Duration, meanwhile: impl FnOnce()) {
    let pid = server.child.id().to_string();
    let term = Command::new("kill").args(["-TERM", &pid]).status().unwrap();
    assert!(term.success());
    let asked = Instant::now();
    meanwhile();
    let exit = loop {
        if let Some(exit) = server.child.try_wait().unwrap() {
            break exit;
        }
        assert!(
            asked.elapsed() < limit,
            "the server did not stop within {limit:?} of SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(exit.success(), "{exit:?}");
}

/// A connection to the server with a 4 KiB receive buffer: an answer of a
/// few megabytes stays mostly unsent while the client does not read.
fn connect_with_small_buffer(addr: &str) -> std::net::TcpStream {
    let addr: std::net::SocketAddr = addr.parse().unwrap();
    let socket = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    socket.connect(&addr.into()).unwrap();
    socket.into()
}

/// A client that asks for a large answer and stops reading is let go once
/// nothing of the answer has left for `--client-timeout` (it held its
/// connection slot and the answer's bytes for as long as it liked: 512 of
/// them stopped the server answering anyone); clients that closed their
/// frame streams are let go within `--client-timeout` though no frame
/// comes (they were kept until the job's next frame); a client that shuts
/// its sending side after its request still gets the answer (hyper
/// dropped those not ready at once); a broken chunked body is a 400, not a 413; a request head
/// over 64 KiB is a 431.
#[test]
fn clients_that_stop_reading_or_half_close_are_served_as_they_should() {
    use std::io::{Read, Write};
    let (dir, scenes) = workspace();
    let server = start_with(&dir.path().join("db"), &scenes, &["--client-timeout", "1"]);
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"1024x1024","spp":1}"#,
    );
    wait_done(&server, &id);
    let path = format!("/api/jobs/{id}/frames/0.exr");
    let (status, _, exr) = http_full(&server.addr, "GET", &path, "");
    assert_eq!(status, 200);
    assert!(
        exr.len() > 4 << 20,
        "{} bytes: too few to fill the socket buffers",
        exr.len()
    );
    let mut stalled = connect_with_small_buffer(&server.addr);
    write!(stalled, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    std::thread::sleep(Duration::from_secs(4));
    let (got, _) = read_until_closed(&mut stalled, Duration::from_secs(20));
    assert!(
        got.len() < exr.len(),
        "the whole answer ({} bytes) waited for a client that stopped reading",
        got.len()
    );
    // A client that half-closes after asking for the large answer, and
    // reads it, gets all of it: the answer is done when written, not when
    // hyper holds the last of it.
    for _ in 0..3 {
        let mut s = connect_with_small_buffer(&server.addr);
        write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        s.shutdown(std::net::Shutdown::Write).unwrap();
        let (got, _) = read_until_closed(&mut s, Duration::from_secs(20));
        assert!(
            got.len() > exr.len(),
            "{} bytes of the {}-byte frame for a half-closed client",
            got.len(),
            exr.len()
        );
    }
    // Streams of a job queued behind a long one write nothing for as long.
    let queued = create_job_behind(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..10000","size":"64x64","spp":4}"#,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"8x8","spp":1}"#,
    );
    let streams: Vec<_> = (0..20)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(&server.addr).unwrap();
            write!(
                s,
                "GET /api/jobs/{queued}/stream HTTP/1.1\r\nHost: x\r\n\r\n"
            )
            .unwrap();
            s
        })
        .collect();
    wait_for_connections(&server, |open| open >= 21, "the frame streams served");
    drop(streams);
    wait_for_connections(&server, |open| open == 1, "the frame streams' clients left");
    // Half-closing clients, of a server that gives them long enough to be
    // answered on a busy machine.
    let patient = start(&dir.path().join("db2"), &scenes);
    let ic = create_job(
        &patient,
        r#"{"scene":"builtin:cube-in-box","method":"ic","frames":"0..1","size":"16x16","spp":1}"#,
    );
    wait_done(&patient, &ic);
    // Answers made at once, and one that takes a moment (records read from
    // the store and projected), which hyper's default closed on.
    for target in [
        "/metrics".to_string(),
        format!("/api/jobs/{ic}/records?frame=0"),
    ]
    .iter()
    .cycle()
    .take(10)
    {
        let mut s = std::net::TcpStream::connect(&patient.addr).unwrap();
        write!(
            s,
            "GET {target} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        s.shutdown(std::net::Shutdown::Write).unwrap();
        let (got, _) = read_until_closed(&mut s, Duration::from_secs(20));
        assert!(
            got.starts_with(b"HTTP/1.1 200"),
            "{:?}",
            String::from_utf8_lossy(&got)
        );
    }
    // Clients that close a kept-alive connection after their answer (a
    // `curl` in a loop) are let go at once, not after the client timeout.
    let kept: Vec<_> = (0..5)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(&patient.addr).unwrap();
            write!(s, "GET /api/jobs HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
            read_one_answer(&mut s);
            s
        })
        .collect();
    drop(kept);
    wait_for_connections(&patient, |open| open == 1, "their clients closed them");
    let mut s = std::net::TcpStream::connect(&server.addr).unwrap();
    write!(
        s,
        "POST /api/jobs HTTP/1.1\r\nHost: x\r\nConnection: close\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\nabc\r\n0\r\n\r\n"
    )
    .unwrap();
    let (got, _) = read_until_closed(&mut s, Duration::from_secs(20));
    assert!(
        got.starts_with(b"HTTP/1.1 400"),
        "{:?}",
        String::from_utf8_lossy(&got)
    );
    let mut s = std::net::TcpStream::connect(&server.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let long = "a".repeat(100 * 1024);
    // The server stops reading at 64 KiB, answers and closes with the rest
    // unread, so the end of this write may meet a reset (EPIPE): what
    // counts is the answer, which Linux still hands over after the reset.
    let _ = write!(
        s,
        "GET /api/jobs HTTP/1.1\r\nHost: x\r\nX-Long: {long}\r\n\r\n"
    );
    let mut head = [0u8; 12];
    s.read_exact(&mut head).unwrap();
    assert_eq!(&head, b"HTTP/1.1 431");
}

/// Clients asking at once for a frame that no one asked for before share
/// one decoding and PNG encoding of it (`radcache_frame_encodes_total`)
/// and get the same PNG; asked again, it comes from the cache. So the
/// followers of a job, all woken by its new frame, encode it once.
#[test]
fn concurrent_requests_for_a_frame_share_one_encoding() {
    let (dir, scenes) = workspace();
    let server = start(&dir.path().join("db"), &scenes);
    // Large enough that encoding it takes a while for the requests to
    // meet in.
    let id = create_job(
        &server,
        r#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"512x512","spp":1,"settings":{"max_depth":1}}"#,
    );
    wait_done(&server, &id);
    let encodes = || {
        let (status, metrics) = http(&server, "GET", "/metrics", "");
        assert_eq!(status, 200);
        gauge(&metrics, "radcache_frame_encodes_total")
    };
    assert_eq!(encodes(), 0);
    const CLIENTS: usize = 24;
    let start = std::sync::Barrier::new(CLIENTS);
    let path = format!("/api/jobs/{id}/frames/0.png");
    let pngs: Vec<(u16, Vec<u8>)> = std::thread::scope(|s| {
        let clients: Vec<_> = (0..CLIENTS)
            .map(|_| {
                s.spawn(|| {
                    start.wait();
                    http(&server, "GET", &path, "")
                })
            })
            .collect();
        clients.into_iter().map(|c| c.join().unwrap()).collect()
    });
    for (status, png) in &pngs {
        assert_eq!(*status, 200);
        assert!(*png == pngs[0].1, "the clients got different PNGs");
    }
    let img = image::load_from_memory(&pngs[0].1).unwrap();
    assert_eq!((img.width(), img.height()), (512, 512));
    assert_eq!(encodes(), 1);
    let (status, again) = http(&server, "GET", &path, "");
    assert_eq!(status, 200);
    assert!(again == pngs[0].1);
    assert_eq!(encodes(), 1);
    // The EXR is read as it was stored, in a decode slot too.
    let (status, exr) = http(&server, "GET", &format!("/api/jobs/{id}/frames/0.exr"), "");
    assert_eq!(status, 200);
    assert!(exr.starts_with(&[0x76, 0x2f, 0x31, 0x01]), "not an EXR");
}

/// `--connections-per-peer` sets one address's share (a reverse proxy on
/// the same host needs more than the default): at 2, a third connection
/// is closed unanswered; out of its range the flag is refused.
#[test]
fn the_connections_of_one_address_follow_the_flag() {
    use std::io::Write;
    let (dir, scenes) = workspace();
    let server = start_with(
        &dir.path().join("db"),
        &scenes,
        &["--connections-per-peer", "2"],
    );
    let held: Vec<_> = (0..2)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(&server.addr).unwrap();
            write!(s, "GET /api/jobs HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
            read_one_answer(&mut s);
            s
        })
        .collect();
    let mut over = std::net::TcpStream::connect(&server.addr).unwrap();
    let _ = write!(over, "GET /api/jobs HTTP/1.1\r\nHost: x\r\n\r\n");
    let (got, _) = read_until_closed(&mut over, Duration::from_secs(10));
    assert!(got.is_empty(), "{:?}", String::from_utf8_lossy(&got));
    drop(held);
    for bad in ["0", "513", "many"] {
        let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
            .args(["serve", "--connections-per-peer", bad])
            .output()
            .unwrap();
        assert!(!out.status.success(), "{bad}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("from 1 to 512"), "{bad}: {err}");
    }
}

/// `tests/data/scenes/cube_in_box.glb` written into `scenes` as glTF JSON
/// `name`, its buffer in `box.bin` beside it, naming the image `image` (a
/// texture the renderer ignores).
fn box_scene_naming_an_image(scenes: &std::path::Path, name: &str, image: &str) {
    let glb = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/scenes/cube_in_box.glb"
    ))
    .unwrap();
    let glb = gltf::binary::Glb::from_slice(&glb).unwrap();
    std::fs::write(scenes.join("box.bin"), glb.bin.as_deref().unwrap()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&glb.json).unwrap();
    doc["buffers"][0]["uri"] = serde_json::json!("box.bin");
    doc["images"] = serde_json::json!([{ "uri": image }]);
    doc["textures"] = serde_json::json!([{ "source": 0 }]);
    std::fs::write(scenes.join(name), serde_json::to_vec(&doc).unwrap()).unwrap();
}

/// A scene whose image is missing is accepted and rendered, as `radcache
/// render` renders it (the renderer ignores textures; the job's hash counts
/// the image as missing). An image outside `--scenes` is still refused
/// (`scene_files_are_read_only_inside_the_scenes_directory`).
#[test]
fn a_scene_whose_ignored_image_is_missing_is_accepted_and_rendered() {
    let (dir, scenes) = workspace();
    box_scene_naming_an_image(&scenes, "s.gltf", "missing.png");
    let server = start(&dir.path().join("db"), &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"s.gltf","method":"path","frames":"0..1","size":"8x8","spp":1}"#,
    );
    assert_eq!(wait_done(&server, &id)["frames_done"], 1);
}

/// A queued job whose scene file changed after it was submitted fails
/// saying so, naming the scene as the API does (not the build), and to
/// submit it again.
#[test]
fn a_served_job_whose_scene_changed_since_it_was_submitted_says_so() {
    use radcache::render::{self, FrameSettings, MethodSettings, SceneSource};
    let (dir, scenes) = workspace();
    box_scene_naming_an_image(&scenes, "s.gltf", "tex.png");
    std::fs::write(scenes.join("tex.png"), b"png").unwrap();
    let db = dir.path().join("db");
    {
        // Stored as `POST /api/jobs` stores it (the scene by its canonical
        // path), not yet run.
        let store = radcache::store::Store::open(&db).unwrap();
        let source = SceneSource::File(scenes.join("s.gltf").canonicalize().unwrap());
        let frames = FrameSettings {
            width: 8,
            height: 8,
            ..FrameSettings::default()
        };
        let method = MethodSettings::Path(Default::default());
        let spec = render::job_spec("job-1", &source, &method, &frames, 0..1).unwrap();
        store.begin_job(&spec, false).unwrap();
    }
    std::fs::write(scenes.join("tex.png"), b"PNG").unwrap();
    let server = start(&db, &scenes);
    let job = wait_ended(&server, "job-1");
    assert_eq!(job["state"], "failed", "{job}");
    let error = job["error"].as_str().unwrap();
    assert!(
        error.starts_with(
            "its scene changed since the job was submitted: s.gltf (the file, or a file it \
             references) is not as it was (scene hash stored "
        ) && error.ends_with("; delete it and submit it again"),
        "{error}"
    );
    assert!(!error.contains("this build"), "{error}");
}

/// A scene far from the origin is rendered moved to it
/// (`Scene::move_to_origin`), but its records are given, and picked by
/// `bbox`, in the file's coordinates; their places on the image are where
/// they show.
#[test]
fn records_of_a_scene_far_from_the_origin_are_in_the_file_coordinates() {
    let (dir, scenes) = workspace();
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/scenes/cube_in_box.glb"
    );
    let (lo, hi) = radcache::scene::Scene::load(std::path::Path::new(path))
        .unwrap()
        .bounds_at(0.0)
        .unwrap();
    let glb = std::fs::read(path).unwrap();
    let glb = gltf::binary::Glb::from_slice(&glb).unwrap();
    std::fs::write(scenes.join("box.bin"), glb.bin.as_deref().unwrap()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&glb.json).unwrap();
    doc["buffers"][0]["uri"] = serde_json::json!("box.bin");
    let far = [2000.0f32, 0.0, -1000.0];
    let roots = doc["scenes"][0]["nodes"].clone();
    let nodes = doc["nodes"].as_array_mut().unwrap();
    nodes.push(serde_json::json!({"name": "far", "translation": far, "children": roots}));
    doc["scenes"][0]["nodes"] = serde_json::json!([nodes.len() - 1]);
    std::fs::write(scenes.join("far.gltf"), serde_json::to_vec(&doc).unwrap()).unwrap();

    let server = start(&dir.path().join("db"), &scenes);
    let id = create_job(
        &server,
        r#"{"scene":"far.gltf","method":"ic","frames":"0..1","size":"16x16","spp":1}"#,
    );
    wait_done(&server, &id);
    let get = |q: &str| {
        let (status, body) = http(&server, "GET", &format!("/api/jobs/{id}/records?{q}"), "");
        assert_eq!(status, 200);
        json(&body)
    };
    let all = get("frame=0");
    let records = all["records"].as_array().unwrap();
    assert!(!records.is_empty());
    for r in records {
        let p: Vec<f32> = (0..3)
            .map(|a| r["position"][a].as_f64().unwrap() as f32 - far[a])
            .collect();
        for a in 0..3 {
            assert!(lo[a] - 1e-2 <= p[a] && p[a] <= hi[a] + 1e-2, "{r}");
        }
        let s = r["screen"].as_array().expect("a record in view projects");
        for c in s {
            assert!((-0.5..=16.5).contains(&c.as_f64().unwrap()), "{r}");
        }
    }
    let around = |o: [f32; 3]| {
        let (a, b) = (lo.to_array(), hi.to_array());
        let corner = |c: [f32; 3], d: f32| (0..3).map(move |i| (c[i] + o[i] + d).to_string());
        let bbox: Vec<String> = corner(a, -0.1).chain(corner(b, 0.1)).collect();
        get(&format!("frame=0&bbox={}", bbox.join(",")))["count"].clone()
    };
    assert_eq!(around(far), records.len());
    assert_eq!(around([0.0; 3]), 0);
}
