//! A `radcache serve` child process on a loopback port and a minimal
//! HTTP/1.1 client for it, shared by the server and browser tests.
#![allow(dead_code)]

use std::ffi::OsStr;
use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// The server; killed when dropped.
pub struct Server {
    pub child: Child,
    /// `127.0.0.1:PORT`.
    pub addr: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `radcache serve --addr 127.0.0.1:0 ARGS…` (no token from the
/// environment) and waits for its "listening on" line.
pub fn start_server<S: AsRef<OsStr>>(args: &[S]) -> Server {
    start_server_at("127.0.0.1:0", args, &[])
}

/// [`start_server`] on `addr` (a port of 0: any), with `env` set.
pub fn start_server_at<S: AsRef<OsStr>>(addr: &str, args: &[S], env: &[(&str, &str)]) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["serve", "--addr", addr])
        .args(args)
        .envs(env.iter().copied())
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

/// One request (`headers`: extra `Name: value\r\n` lines), read to the end
/// of the connection; returns (status, head, body), the body de-chunked.
pub fn request(
    addr: &str,
    method: &str,
    path: &str,
    headers: &str,
    body: &str,
) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let sent = write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n{headers}Content-Length: {}\r\n\r\n{body}",
        body.len()
    );
    // A server that refuses a body it has not read all of answers and
    // closes: the rest of the write meets a reset, and so may the read
    // after the answer. The answer is what counts.
    let reset =
        |e: &std::io::Error| matches!(e.kind(), ErrorKind::BrokenPipe | ErrorKind::ConnectionReset);
    if let Err(e) = sent {
        assert!(reset(&e), "sending {method} {path}: {e}");
    }
    let mut raw = Vec::new();
    if let Err(e) = s.read_to_end(&mut raw) {
        assert!(reset(&e) && !raw.is_empty(), "reading {method} {path}: {e}");
    }
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
    (status, head, body)
}

/// The payload of a `Transfer-Encoding: chunked` body.
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

/// A store in `dir/db` holding job `boxed`, which `radcache render`
/// rendered (`ic`, frame 0 at 8×8) from `box.glb` in `dir/work`, its
/// working directory; returns (store, working directory).
pub fn store_with_a_render_job(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let db = dir.join("db");
    let work = dir.join("work");
    std::fs::create_dir(&work).unwrap();
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/scenes/cube_in_box.glb"
        ),
        work.join("box.glb"),
    )
    .unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .current_dir(&work)
        .args(["render", "box.glb", "--method", "ic", "--size", "8x8"])
        .args(["--frames", "0..1", "--spp", "1", "--backend", "cpu", "-q"])
        .args(["--job", "boxed", "--out", "out", "--db"])
        .arg(&db)
        .status()
        .unwrap();
    assert!(status.success());
    (db, work)
}
