//! The dashboard in headless Chromium (Debian package `chromium`, which
//! `.ci/run` installs): a server on a loopback port renders a tiny job
//! (`trc`; `movies`; `ic` with radiance records), then Chromium loads the
//! dashboard for it. The test fails, never
//! skips, without Chromium (set `CHROMIUM` to use another binary). The
//! screenshot is kept at `target/tmp/browser/dashboard.png`.

mod serve_client;

use serve_client::{request, start_server, Server};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn start(db: &Path, extra: &[&str]) -> Server {
    let mut args: Vec<&std::ffi::OsStr> = ["--backend", "cpu", "--db"]
        .iter()
        .map(|a| a.as_ref())
        .collect();
    args.push(db.as_os_str());
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    start_server(&args)
}

fn http(addr: &str, method: &str, path: &str, body: &str) -> (u16, String) {
    let (status, _, body) = request(addr, method, path, "", body);
    (status, String::from_utf8_lossy(&body).into_owned())
}

fn chromium() -> PathBuf {
    let path = std::env::var_os("CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    assert!(
        path.exists(),
        "{} not found: install Chromium (Debian: apt-get install chromium; .ci/run does) or set CHROMIUM",
        path.display()
    );
    path
}

/// Runs headless Chromium on `url` with `action` (`--dump-dom` or
/// `--screenshot=…`); returns (stdout, stderr).
fn run_chromium(url: &str, action: &str, profile: &Path) -> (String, String) {
    let out = Command::new(chromium())
        .args([
            "--headless=new",
            "--disable-gpu",
            "--no-sandbox",
            "--no-first-run",
            "--disable-extensions",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--window-size=1300,1500",
            "--virtual-time-budget=15000",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(action)
        .arg(url)
        .output()
        .expect("run chromium");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "chromium failed: {stderr}");
    (stdout, stderr)
}

/// Console messages Chromium logged (`…:CONSOLE(…)] "message", source: …`).
fn console_lines(stderr: &str) -> Vec<&str> {
    stderr.lines().filter(|l| l.contains("CONSOLE")).collect()
}

#[test]
fn dashboard_shows_frame_charts_and_overlay_without_console_errors() {
    check_dashboard(None, true);
}

/// With --token, the page opened as /?token=… passes it on to every request.
#[test]
fn dashboard_works_behind_a_token() {
    check_dashboard(Some("tok/en +1"), false);
}

/// The `d` of the chart path of series `name` in the dumped DOM.
fn series_path<'a>(dom: &'a str, name: &str) -> &'a str {
    let tag = dom
        .split("<path ")
        .find(|tag| tag.contains(&format!("data-series=\"{name}\"")))
        .unwrap_or_else(|| panic!("no chart path of {name}:\n{dom}"));
    let d = tag.split(" d=\"").nth(1).expect("a path with d");
    &d[..d.find('"').expect("a quoted d")]
}

/// Renders a tiny job and checks the dashboard for it in Chromium; keeps a
/// screenshot when `screenshot`.
fn check_dashboard(token: Option<&str>, screenshot: bool) {
    let chromium_path = chromium();
    let dir = tempfile::tempdir().unwrap();
    let extra: Vec<&str> = token.map(|t| vec!["--token", t]).unwrap_or_default();
    let server = start(&dir.path().join("db"), &extra);
    // `?token=…` on every request (percent-encoded).
    let q = token
        .map(|t| {
            let enc: String = t
                .bytes()
                .map(|b| {
                    if b.is_ascii_alphanumeric() {
                        (b as char).to_string()
                    } else {
                        format!("%{b:02X}")
                    }
                })
                .collect();
            format!("token={enc}")
        })
        .unwrap_or_default();
    let with_q = |path: &str| {
        if q.is_empty() {
            path.to_string()
        } else if path.contains('?') {
            format!("{path}&{q}")
        } else {
            format!("{path}?{q}")
        }
    };
    let (status, body) = http(
        &server.addr,
        "POST",
        &with_q("/api/jobs"),
        r#"{"scene":"builtin:cube-in-box","method":"trc","frames":"0..3","size":"16x16","spp":1}"#,
    );
    assert_eq!(status, 201, "{body}");
    let id = serde_json::from_str::<serde_json::Value>(&body).unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    wait_until_done(|| http(&server.addr, "GET", &with_q(&format!("/api/jobs/{id}")), "").1);
    let url = format!("http://{}{}", server.addr, with_q(&format!("/?job={id}")));

    let (dom, stderr) = run_chromium(&url, "--dump-dom", &dir.path().join("profile1"));
    let console = console_lines(&stderr);
    assert!(
        console.is_empty(),
        "console messages (chromium {}):\n{}",
        chromium_path.display(),
        console.join("\n")
    );
    let has = |needle: &str| dom.contains(needle);
    assert!(
        has("data-ready=\"1\""),
        "the page did not finish loading:\n{dom}"
    );
    assert!(!has("data-errors="), "the page reported errors:\n{dom}");
    // The live frame: the stream, shown at the job's size.
    let stream_src = with_q(&format!("/api/jobs/{id}/stream")).replace('&', "&amp;");
    assert!(
        has(&format!("src=\"{stream_src}\"")),
        "no live stream image:\n{dom}"
    );
    assert!(
        has("data-loaded=\"16x16\""),
        "the live frame did not load:\n{dom}"
    );
    // Progress from the events.
    assert!(has("3/3 frames"), "{dom}");
    // The title names the job's temporal settings (trc's defaults here).
    assert!(has("a 0.2, a_t 0.05, δt_max 20, frames 0..3"), "{dom}");
    // Charts: the paths the script drew (5 record series, lifespan,
    // samples re-shot, time, 4 byte series).
    let paths = dom.matches("class=\"series\"").count();
    assert!(paths >= 12, "{paths} chart paths:\n{dom}");
    assert!(has("samples re-shot"), "{dom}");
    // The mean lifespan: a point for each frame that computed records,
    // none (a gap, not a zero) for the others.
    let get_json = |path: &str| -> serde_json::Value {
        let (_, body) = http(&server.addr, "GET", &with_q(path), "");
        serde_json::from_str(&body).unwrap_or_else(|e| panic!("{path}: {e}: {body}"))
    };
    let stats = get_json(&format!("/api/jobs/{id}/stats"));
    let computing = stats["frames"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["mean_lifespan"].as_f64().unwrap() > 0.0)
        .count();
    assert!(computing > 0, "no frame computed records: {stats}");
    let lifespan = series_path(&dom, "mean lifespan");
    let points = lifespan.matches(['M', 'L']).count();
    assert_eq!(
        points, computing,
        "lifespan path {lifespan:?} against {stats}"
    );
    // The record overlay: one dot per record alive in the last frame.
    let dots = dom.matches("class=\"record\"").count();
    let records = get_json(&format!("/api/jobs/{id}/records?frame=2"));
    let in_view = in_view(&records["records"], 16.0);
    assert!(in_view > 0, "no records to show: {records}");
    assert_eq!(dots, in_view, "overlay dots vs records in view");
    // The bench chart.
    let chart_src = with_q("/web/charts/cube-in-box_error_vs_time.svg").replace('&', "&amp;");
    assert!(has(&format!("src=\"{chart_src}\"")), "{dom}");
    if !screenshot {
        return;
    }

    let shots = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("browser");
    std::fs::create_dir_all(&shots).unwrap();
    let shot = shots.join("dashboard.png");
    let _ = std::fs::remove_file(&shot);
    let (_, stderr) = run_chromium(
        &url,
        &format!("--screenshot={}", shot.display()),
        &dir.path().join("profile2"),
    );
    let console = console_lines(&stderr);
    assert!(
        console.is_empty(),
        "console messages:\n{}",
        console.join("\n")
    );
    let png = image::open(&shot).expect("screenshot written");
    assert!(
        png.width() >= 1000,
        "screenshot {}x{}",
        png.width(),
        png.height()
    );
}

/// The server (with its store in `dir`) after it rendered the job of
/// request `body`, the job's id, and the dashboard's DOM for it, loaded
/// without console messages or reported errors.
fn dashboard_for_job(dir: &Path, body: &str) -> (Server, String, String) {
    chromium();
    let server = start(&dir.join("db"), &[]);
    let (status, body) = http(&server.addr, "POST", "/api/jobs", body);
    assert_eq!(status, 201, "{body}");
    let id = serde_json::from_str::<serde_json::Value>(&body).unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    wait_until_done(|| http(&server.addr, "GET", &format!("/api/jobs/{id}"), "").1);
    let url = format!("http://{}/?job={id}", server.addr);
    let (dom, stderr) = run_chromium(&url, "--dump-dom", &dir.join("profile"));
    let console = console_lines(&stderr);
    assert!(
        console.is_empty(),
        "console messages:\n{}",
        console.join("\n")
    );
    assert!(dom.contains("data-ready=\"1\""), "not loaded:\n{dom}");
    assert!(
        !dom.contains("data-errors="),
        "the page reported errors:\n{dom}"
    );
    (server, id, dom)
}

/// A `movies` job's overlay draws its texture movies: one square per
/// movie whose patch centre `/movies` places in the image.
#[test]
fn dashboard_draws_the_texture_movies_of_a_movies_job() {
    let dir = tempfile::tempdir().unwrap();
    let (server, id, dom) = dashboard_for_job(
        dir.path(),
        r#"{"scene":"builtin:cube-in-box","method":"movies","frames":"0..2","size":"16x16","spp":1}"#,
    );
    let (_, movies) = http(
        &server.addr,
        "GET",
        &format!("/api/jobs/{id}/movies?frame=1"),
        "",
    );
    let movies: serde_json::Value = serde_json::from_str(&movies).unwrap();
    let in_view = in_view(&movies["movies"], 16.0);
    assert!(in_view > 0, "no movies in view: {movies}");
    let squares = dom.matches("class=\"movie\"").count();
    assert_eq!(squares, in_view, "overlay squares vs movies in view");
    assert!(dom.contains("movies open"), "{dom}");
}

/// A job with radiance records (`--ic-glossy eas`): the overlay rings
/// each radiance record in view, and only those.
#[test]
fn dashboard_rings_the_radiance_records() {
    let dir = tempfile::tempdir().unwrap();
    let (server, id, dom) = dashboard_for_job(
        dir.path(),
        r#"{"scene":"builtin:glossy-cornell","method":"ic","frames":"0..1","size":"16x16","spp":1,"settings":{"glossy":"eas","strata":"4x12"}}"#,
    );
    let (_, records) = http(
        &server.addr,
        "GET",
        &format!("/api/jobs/{id}/records?frame=0"),
        "",
    );
    let records: serde_json::Value = serde_json::from_str(&records).unwrap();
    let radiance: Vec<serde_json::Value> = records["records"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| !r["source_count"].is_null())
        .cloned()
        .collect();
    let ringed = in_view(&serde_json::Value::Array(radiance), 16.0);
    assert!(ringed > 0, "no radiance record in view: {records}");
    assert_eq!(dom.matches("data-sources=").count(), ringed, "{dom}");
    assert!(dom.contains("radiance records (ringed)"), "{dom}");
}

/// Polls `job` (the job's JSON) until the job is done; fails on a failed
/// job or after two minutes.
fn wait_until_done(job: impl Fn() -> String) {
    let start = Instant::now();
    loop {
        let job = job();
        if job.contains("\"state\":\"done\"") {
            return;
        }
        assert!(!job.contains("failed"), "{job}");
        assert!(start.elapsed() < Duration::from_secs(120), "{job}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// How many of `items` (each with a `screen` [x, y] or null) lie on a
/// `size`×`size` image.
fn in_view(items: &serde_json::Value, size: f64) -> usize {
    items
        .as_array()
        .unwrap()
        .iter()
        .filter(|item| {
            item["screen"].as_array().is_some_and(|s| {
                let (x, y) = (s[0].as_f64().unwrap(), s[1].as_f64().unwrap());
                (0.0..=size).contains(&x) && (0.0..=size).contains(&y)
            })
        })
        .count()
}

/// A job that `radcache render --job` named with URL characters (`?`, `#`,
/// `/`, a space) is shown like any other: every URL the dashboard builds
/// for it encodes the name.
#[test]
fn dashboard_shows_a_job_named_with_url_characters() {
    chromium();
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("db");
    let name = "we?ird #1/a";
    let ok = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["render", "--builtin", "cube-in-box", "--method", "trc"])
        .args(["--frames", "0..2", "--size", "16x16", "--spp", "1"])
        .args(["--backend", "cpu", "-q", "--job", name, "--db"])
        .arg(&db)
        .arg("--out")
        .arg(dir.path().join("out"))
        .status()
        .unwrap();
    assert!(ok.success());
    let server = start(&db, &[]);
    let encoded = "we%3Fird%20%231%2Fa";
    let url = format!("http://{}/?job={encoded}", server.addr);
    let (dom, stderr) = run_chromium(&url, "--dump-dom", &dir.path().join("profile"));
    let console = console_lines(&stderr);
    assert!(console.is_empty(), "console:\n{}", console.join("\n"));
    assert!(dom.contains("data-ready=\"1\""), "not loaded:\n{dom}");
    assert!(!dom.contains("data-errors="), "errors:\n{dom}");
    assert!(
        dom.contains(&format!("src=\"/api/jobs/{encoded}/stream\"")),
        "no live stream for the job:\n{dom}"
    );
    assert!(dom.contains("data-loaded=\"16x16\""), "no frame:\n{dom}");
    assert!(dom.contains("2/2 frames"), "{dom}");
}
