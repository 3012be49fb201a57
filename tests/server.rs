//! `radcache serve` against a real server on a loopback port.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Server {
    child: Child,
    addr: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start(db: &std::path::Path, scenes: &std::path::Path) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["serve", "--addr", "127.0.0.1:0", "--backend", "cpu", "--db"])
        .arg(db)
        .arg("--scenes")
        .arg(scenes)
        .env_remove("RADCACHE_TOKEN")
        .stdout(Stdio::piped())
        .spawn()
        .expect("start radcache serve");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_string();
    Server { child, addr }
}

/// One HTTP/1.1 request; returns (status, body).
fn http(server: &Server, method: &str, path: &str, body: &str) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(&server.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&raw[..split]).to_string();
    let status: u16 = head.split(' ').nth(1).unwrap().parse().unwrap();
    let mut body = raw[split + 4..].to_vec();
    if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        body = dechunk(&body);
    }
    (status, body)
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let nl = b.windows(2).position(|w| w == b"\r\n").unwrap();
        let len = usize::from_str_radix(std::str::from_utf8(&b[..nl]).unwrap().trim(), 16).unwrap();
        if len == 0 {
            return out;
        }
        out.extend_from_slice(&b[nl + 2..nl + 2 + len]);
        b = &b[nl + 4 + len..];
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
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    std::fs::create_dir(&scenes).unwrap();
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

    let out = dir.path().join("cli");
    let ok = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args([
            "render",
            "--builtin",
            "cube-in-box",
            "--method",
            "path",
            "--frames",
            "0..2",
        ])
        .args([
            "--size",
            "16x16",
            "--spp",
            "1",
            "--backend",
            "cpu",
            "-q",
            "--out",
        ])
        .arg(&out)
        .status()
        .unwrap();
    assert!(ok.success());
    for f in 0..2 {
        let (status, exr) = http(
            &server,
            "GET",
            &format!("/api/jobs/{id}/frames/{f}.exr"),
            "",
        );
        assert_eq!(status, 200);
        let cli = std::fs::read(out.join(format!("frame_{f:04}.exr"))).unwrap();
        assert!(exr == cli, "frame {f}: server EXR differs from the CLI's");
    }

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

#[test]
fn bad_requests_get_json_errors_and_the_server_keeps_serving() {
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    std::fs::create_dir(&scenes).unwrap();
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
    let job = |scene: &str, frames: &str| {
        format!(
            r#"{{"scene":"{scene}","method":"path","frames":"{frames}","size":"16x16","spp":1}}"#
        )
    };
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
    let huge = format!(r#"{{"scene":"{}"}}"#, "a".repeat(100_000));
    let (status, _) = http(&server, "POST", "/api/jobs", &huge);
    assert_eq!(status, 413);
    // Still serving.
    let (status, body) = http(&server, "GET", "/api/jobs", "");
    assert_eq!(status, 200);
    assert_eq!(json(&body), serde_json::json!([]));
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
    let job = wait_done(&server, &id);
    assert_eq!(job["frames_done"], 2);
    check("POST", &format!("/api/jobs/{id}/cancel"), "", 409);
}
