//! Throughput of the store's record writes and reads, and its bytes per
//! sample on disk (README "Resumable renders and the store"):
//!
//! ```sh
//! cargo bench --bench store                          # 20 frames of 400 records, 768 samples each
//! STORE_FRAMES=100 STORE_RECORDS=1000 cargo bench --bench store
//! ```
//!
//! Each frame commits `STORE_RECORDS` records with 768 samples each (a
//! 16 × 48 hemisphere), as `ic` does at 64×64, with a 64 KiB frame image:
//! one log append and sync, one transaction and one flush a frame, as a
//! render commits. Packing the samples to RGBE is timed with the writes,
//! as the methods pack them when they gather. Reads take each frame's
//! records, then each record's samples. The samples are synthetic (eight
//! hemispheres of `store_fixtures::samples`); bytes on disk are sled's
//! directory plus the sample log.

#[path = "../tests/store_fixtures/mod.rs"]
mod store_fixtures;

use radcache::cache::gather::{HemisphereSamples, Strata};
use radcache::method::FrameStats;
use radcache::store::{FrameCommit, JobSpec, RecordCommit, SampleBlock, Store};
use std::time::Instant;
use store_fixtures::{record, samples, spec};

fn env_or(name: &str, default: u64) -> u64 {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v}: expected a whole number")),
        Err(_) => default,
    }
}

fn main() {
    let frames = env_or("STORE_FRAMES", 20) as u32;
    let per_frame = env_or("STORE_RECORDS", 400);
    let strata = Strata { theta: 16, phi: 48 };
    let dir = tempfile::tempdir().expect("a temporary directory");
    let store = Store::open(&dir.path().join("db")).expect("a new store");
    let mut job = store
        .begin_job(
            &JobSpec {
                width: 64,
                height: 64,
                spp: 16,
                frame_end: frames,
                ..spec("bench")
            },
            false,
        )
        .expect("a new job");
    let hemis: Vec<HemisphereSamples> = (0..8).map(|i| samples(strata.count(), i)).collect();
    let exr = vec![0u8; 64 * 1024];
    let stats = FrameStats::default();

    let t0 = Instant::now();
    for frame in 0..frames {
        let records = (0..per_frame)
            .map(|id| {
                let samples = SampleBlock::pack(&hemis[(id % 8) as usize], &[]);
                RecordCommit::from_record(&record(id, frame), samples, strata, frame)
            })
            .collect();
        let commit = FrameCommit {
            frame,
            width: 64,
            height: 64,
            exr: &exr,
            records,
            stats: &stats,
            state: None,
            movies: None,
            sources: None,
        };
        store.commit_frame(&mut job, commit).expect("a commit");
    }
    let write = t0.elapsed().as_secs_f64();

    let t0 = Instant::now();
    let (mut records, mut samples) = (0u64, 0u64);
    for frame in 0..frames {
        for r in store
            .frame_records(job.id, frame)
            .expect("a frame's records")
        {
            records += 1;
            let block = store
                .samples_of_record(job.id, frame, &r)
                .expect("a record's samples");
            samples += block.len() as u64;
        }
    }
    let read = t0.elapsed().as_secs_f64();
    let total = u64::from(frames) * per_frame;
    assert_eq!(records, total, "every record written is read back");
    assert_eq!(samples, total * strata.count() as u64);

    let sled_bytes = store.size_on_disk().expect("the store's size");
    let log_bytes = store.sample_log_bytes();
    let disk = sled_bytes + log_bytes;
    let per_s = |n: u64, s: f64| n as f64 / s;
    println!(
        "{frames} frames × {per_frame} records × {} samples",
        strata.count()
    );
    println!(
        "write: {:.0} records/s ({:.1} M samples/s; pack, log append, transaction, flush per frame)",
        per_s(total, write),
        per_s(samples, write) / 1e6
    );
    println!(
        "read:  {:.0} records/s ({:.1} M samples/s; a frame's records, then each record's samples)",
        per_s(records, read),
        per_s(samples, read) / 1e6
    );
    println!(
        "disk:  {disk} B ({sled_bytes} sled + {log_bytes} sample log) = {:.2} B/sample",
        disk as f64 / samples as f64
    );
}
