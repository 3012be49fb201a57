//! Frames streamed per second from `radcache serve` to 1 and to 50
//! concurrent loopback clients, for a finished job, and the server's memory
//! meanwhile (README "Serving"):
//!
//! ```sh
//! cargo bench --bench stream            # default: trc, cube-in-box, 128x128, 48 frames
//! STREAM_SIZE=256x256 STREAM_FRAMES=24 STREAM_CLIENTS=1,10,50 STREAM_REPEAT=5 cargo bench --bench stream
//! ```
//!
//! It starts the release `radcache serve` on a temporary store, renders the
//! job, then has N clients read `GET /api/jobs/ID/stream` to the end at the
//! same time, each `STREAM_REPEAT` times in a row (each read receives every
//! frame). A first single read is cold (each frame is PNG-encoded once, on
//! first request); the rounds after it are served from the server's PNG
//! cache. Memory is the server's resident set (`/proc/PID/status`: VmRSS
//! sampled every 2 ms, and VmHWM, the peak since the server started).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

fn env_or(name: &str, default: &str) -> String {
    std::env::var(name).unwrap_or_else(|_| default.to_string())
}

fn request(addr: &str, method: &str, path: &str, body: &str) -> Vec<u8> {
    let mut s = TcpStream::connect(addr).expect("connect");
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    raw
}

fn status_kb(pid: u32, field: &str) -> u64 {
    let text = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    text.lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// Reads one stream to the end: (frames received, bytes).
fn read_stream(addr: &str, id: &str) -> (usize, usize) {
    let raw = request(addr, "GET", &format!("/api/jobs/{id}/stream"), "");
    let needle = b"\r\nX-Frame: ";
    let frames = raw.windows(needle.len()).filter(|w| w == needle).count();
    (frames, raw.len())
}

fn main() {
    // `cargo bench` passes --bench; nothing else to parse.
    let size = env_or("STREAM_SIZE", "128x128");
    let frames: u32 = env_or("STREAM_FRAMES", "48").parse().unwrap();
    let clients: Vec<usize> = env_or("STREAM_CLIENTS", "1,50")
        .split(',')
        .map(|c| c.parse().unwrap())
        .collect();
    let rounds: usize = env_or("STREAM_ROUNDS", "3").parse().unwrap();
    // Each client reads the whole stream this many times in a row per round.
    let repeat: usize = env_or("STREAM_REPEAT", "20").parse().unwrap();
    let dir = std::env::temp_dir().join(format!("radcache-stream-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut child = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["serve", "--addr", "127.0.0.1:0", "--backend", "cpu", "--db"])
        .arg(dir.join("db"))
        // All the clients come from one address.
        .args(["--connections-per-peer", "512"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("start radcache serve");
    let pid = child.id();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .unwrap()
        .to_string();
    let body = format!(
        r#"{{"scene":"builtin:cube-in-box","method":"trc","frames":"0..{frames}","size":"{size}","spp":4}}"#
    );
    let raw = request(&addr, "POST", "/api/jobs", &body);
    let text = String::from_utf8_lossy(&raw);
    let id = text
        .split("\"id\":\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .unwrap_or_else(|| panic!("no job id in {text}"))
        .to_string();
    let t = Instant::now();
    loop {
        let raw = request(&addr, "GET", &format!("/api/jobs/{id}"), "");
        let text = String::from_utf8_lossy(&raw);
        if text.contains("\"state\":\"done\"") {
            break;
        }
        assert!(!text.contains("\"state\":\"failed\""), "{text}");
        std::thread::sleep(Duration::from_millis(100));
    }
    println!(
        "job {id}: trc cube-in-box {size}, {frames} frames, spp 4, rendered in {:.1} s; server RSS {} kB",
        t.elapsed().as_secs_f64(),
        status_kb(pid, "VmRSS:")
    );
    // Cold: one client, every frame PNG-encoded on first request.
    let t = Instant::now();
    let (got, bytes) = read_stream(&addr, &id);
    let secs = t.elapsed().as_secs_f64();
    assert_eq!(got, frames as usize);
    println!(
        "  1 client, cold PNG cache: {got} frames in {secs:.3} s = {:.0} frames/s, {:.1} MB/s; server RSS {} kB",
        got as f64 / secs,
        bytes as f64 / secs / 1e6,
        status_kb(pid, "VmRSS:")
    );
    for &n in &clients {
        for round in 0..rounds {
            let rss_before = status_kb(pid, "VmRSS:");
            let barrier = Arc::new(Barrier::new(n + 1));
            let handles: Vec<_> = (0..n)
                .map(|_| {
                    let (addr, id, barrier) = (addr.clone(), id.clone(), barrier.clone());
                    std::thread::spawn(move || {
                        barrier.wait();
                        (0..repeat)
                            .map(|_| read_stream(&addr, &id))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            // Peak resident memory while the clients read.
            let sampling = Arc::new(std::sync::atomic::AtomicBool::new(true));
            let sampler = {
                let sampling = sampling.clone();
                std::thread::spawn(move || {
                    let mut peak = 0;
                    while sampling.load(std::sync::atomic::Ordering::Relaxed) {
                        peak = peak.max(status_kb(pid, "VmRSS:"));
                        std::thread::sleep(Duration::from_millis(2));
                    }
                    peak
                })
            };
            barrier.wait();
            let t = Instant::now();
            let results: Vec<(usize, usize)> = handles
                .into_iter()
                .flat_map(|h| h.join().unwrap())
                .collect();
            let secs = t.elapsed().as_secs_f64();
            sampling.store(false, std::sync::atomic::Ordering::Relaxed);
            let peak = sampler.join().unwrap();
            let got: usize = results.iter().map(|r| r.0).sum();
            let bytes: usize = results.iter().map(|r| r.1).sum();
            assert!(
                results.iter().all(|r| r.0 == frames as usize),
                "a client missed frames: {results:?}"
            );
            println!(
                "{n:>3} clients x {repeat} streams, round {round}: {got} frames in {secs:.3} s = {:.0} frames/s in all, {:.0} frames/s per client, {:.0} MB/s; server RSS {rss_before} kB before, {peak} kB peak sampled, VmHWM {} kB",
                got as f64 / secs,
                got as f64 / secs / n as f64,
                bytes as f64 / secs / 1e6,
                status_kb(pid, "VmHWM:"),
            );
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
}
