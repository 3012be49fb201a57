//! Crash test (issue 4): a child `radcache render --db … --job …` is killed
//! with SIGKILL at random moments, again and again; after each kill the
//! store reopens, no acknowledged frame is lost, no partial frame is
//! visible, and the finished frames equal an uninterrupted run byte for
//! byte. Once with `path`, once with `trc`, whose cache state is
//! checkpointed with every frame and restored on resume, and whose records'
//! samples go to the sample log before each frame's batch.

use radcache::film;
use radcache::store::Store;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const FRAMES: u32 = 200;

fn radcache_frames(args: &[&str], dir: &Path, frames: u32) -> Command {
    let range = format!("0..{frames}");
    let mut c = Command::new(env!("CARGO_BIN_EXE_radcache"));
    c.args(args)
        .args(["--size", "16x16", "--spp", "1", "--frames", &range, "-q"])
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    c
}

fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// Checks the store after a kill; returns the frames it holds.
fn check_store(dir: &Path, reference: &[Vec<u8>], acknowledged_before: usize) -> usize {
    let frames = reference.len() as u32;
    let store = Store::open(&dir.join("db")).expect("the store reopens after SIGKILL");
    let Some(job) = store.job("crash").unwrap() else {
        return 0; // killed before the job was recorded
    };
    let done = store.frames_done(job.id).unwrap();
    assert_eq!(
        job.frames_done as usize,
        done.len(),
        "progress matches the frames"
    );
    assert!(
        done.len() >= acknowledged_before,
        "an acknowledged frame was lost"
    );
    for &f in &done {
        // Whole frames only, equal to the uninterrupted run.
        let exr = store.frame_exr(job.id, f).unwrap().unwrap();
        assert_eq!(exr, reference[f as usize], "frame {f} differs");
        assert!(
            store.frame_stats(job.id, f).unwrap().is_some(),
            "frame {f} without stats"
        );
        // Every record's samples read back whole from the sample log.
        for r in store.frame_records(job.id, f).unwrap() {
            let samples = store.record_samples(job.id, f, r.id).unwrap();
            assert_eq!(samples.len(), (r.strata_theta * r.strata_phi) as usize);
        }
    }
    // The sample log holds what the store committed, and maybe a torn
    // tail after it, which the store's next write cuts off
    // (`tests/store.rs`, `torn_sample_log_tail_is_cut_by_the_next_write`).
    assert!(
        std::fs::metadata(dir.join("db").join("samples.log"))
            .unwrap()
            .len()
            >= store.sample_log_bytes()
    );
    // A stateful method's stored state is that of the last frame: the
    // frames are the range's prefix, and the head names its last one.
    if let Some(head) = store.state_head(job.id).unwrap() {
        assert_eq!(done, (0..done.len() as u32).collect::<Vec<_>>());
        assert_eq!(
            Some(head.frame),
            done.last().copied(),
            "state not of the last frame"
        );
        assert!(store.load_state(job.id).unwrap().is_some());
    }
    // Every frame acknowledged to --out is in the store.
    for f in 0..frames {
        if film::frame_path(&dir.join("out"), f, "exr").exists() {
            assert!(
                done.contains(&f),
                "frame {f} written to --out but not in the store"
            );
        }
    }
    done.len()
}

#[test]
fn sigkilled_renders_resume_without_losing_or_tearing_frames() {
    crash_and_resume(&[], FRAMES, 20);
}

#[test]
fn sigkilled_trc_renders_resume_from_stored_state() {
    crash_and_resume(&["--method", "trc", "--trc-max-life", "6"], 120, 12);
}

/// The kills are timed from measured start-up and frame times: one crash
/// test at a time, so that the other does not skew them.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Kills `radcache render ARGS --frames 0..FRAMES` at random moments at
/// least `min_kills` times (over more than one job where one finishes
/// first), checking the store after each kill and each finished job.
fn crash_and_resume(method: &[&str], frames: u32, min_kills: u32) {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let radcache = |args: &[&str], dir: &Path| {
        let all: Vec<&str> = args.iter().chain(method).copied().collect();
        radcache_frames(&all, dir, frames)
    };
    let radcache_frames = |args: &[&str], dir: &Path, n: u32| {
        let all: Vec<&str> = args.iter().chain(method).copied().collect();
        radcache_frames(&all, dir, n)
    };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let status = radcache(&["render", "--out", "ref"], dir).status().unwrap();
    assert!(status.success());
    let reference: Vec<Vec<u8>> = (0..frames)
        .map(|f| std::fs::read(film::frame_path(&dir.join("ref"), f, "exr")).unwrap())
        .collect();
    // Start-up time and time per frame with the store, to place the kills
    // between start-up and a few frames in (so that most land mid-frame or
    // mid-batch, and the job does not finish before 20 kills).
    let job = ["render", "--db", "db", "--job", "crash", "--out", "out"];
    let timing_dir = tempfile::tempdir().unwrap();
    let t0 = Instant::now();
    let status = radcache_frames(&job, timing_dir.path(), 1).status();
    assert!(status.unwrap().success());
    let startup = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let status = radcache_frames(&job, timing_dir.path(), 41).status();
    assert!(status.unwrap().success());
    let per_frame = (t0.elapsed().as_secs_f64() - startup).max(0.0) / 40.0;
    // Adapted after each kill (below): timings measured on a busy machine
    // can be off several times, and a window that lets a run get far
    // would finish the job before enough kills landed.
    let mut window = startup * 1.5 + 6.0 * per_frame;

    let mut rng = 0x5eed_u64;
    let mut kills = 0;
    let mut progressed = 0;
    let mut attempts = 0;
    let mut jobs = 0;
    // Rounds of one job each, in a store of its own: where a busy machine
    // let runs get so far that a job finished before enough kills landed,
    // it is checked and another is killed, rather than the test failing
    // on the machine's load.
    for round in 0.. {
        assert!(round < 5, "{kills} kills in {round} jobs");
        jobs += 1;
        let dir = dir.join(format!("round_{round}"));
        std::fs::create_dir(&dir).unwrap();
        let mut acknowledged = 0;
        while kills < min_kills + 5 {
            attempts += 1;
            assert!(attempts < 200, "too many attempts");
            let mut child = radcache(&job, &dir).spawn().unwrap();
            let delay = lcg(&mut rng) * window;
            std::thread::sleep(Duration::from_secs_f64(delay));
            if child.try_wait().unwrap().is_some() {
                break; // finished before the kill
            }
            child.kill().unwrap(); // SIGKILL
            child.wait().unwrap();
            kills += 1;
            let now = check_store(&dir, &reference, acknowledged);
            if now > acknowledged {
                progressed += 1;
            }
            match now - acknowledged {
                0 => window *= 1.2,
                1..=4 => {}
                _ => window *= 0.7,
            }
            acknowledged = now;
            if acknowledged == frames as usize {
                break;
            }
        }
        // Finish the job; everything equals the uninterrupted run.
        assert!(radcache(&job, &dir).status().unwrap().success());
        assert_eq!(check_store(&dir, &reference, acknowledged), frames as usize);
        for f in 0..frames {
            let out = std::fs::read(film::frame_path(&dir.join("out"), f, "exr")).unwrap();
            assert_eq!(out, reference[f as usize], "--out frame {f} differs");
        }
        if kills >= min_kills {
            break;
        }
        window *= 0.5; // runs got too far: kill the next job sooner
    }
    eprintln!(
        "{kills} kills in {jobs} jobs, {progressed} after new frames; start-up {startup:.3} s, {per_frame:.4} s/frame"
    );
    assert!(
        progressed >= 5,
        "only {progressed} kills landed after frames were written"
    );
}
