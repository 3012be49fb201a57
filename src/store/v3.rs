//! Schema 3 (`migrations/0003_sample_log.md`): one `records` key per
//! record (`job · frame · record id`, 20 bytes), its
//! `schema::RecordValue` as the value. Schema 4
//! (`migrations/0004_record_blocks.md`) keeps the same record values but
//! moves them, one zstd block per frame, into the sample log, leaving one
//! small `records` key per frame. This module holds the 0003 → 0004
//! migration step.

use super::meta::read_meta_u64;
use super::samples::{SampleLog, FILE_NAME as LOG_FILE};
use super::schema::{RecordBlock, RecordValue};
use super::{append_record_block, encode, keys};
use sled::transaction::ConflictableTransactionError;
use sled::{IVec, Transactional};
use std::ops::Bound;
use std::path::Path;

/// Records converted per transaction of the migration (whole frames: a
/// batch ends at the first frame boundary at or after this many records).
const BATCH: usize = 1024;

/// A frame's schema-3 record keys and values, in id order.
struct OldFrame {
    key: [u8; 12],
    job: u64,
    frame: u32,
    rows: Vec<(IVec, RecordValue)>,
}

/// Migration 0003 → 0004 (`migrations/0004_record_blocks.md`): in batches
/// of whole frames (about `BATCH` records), in key order, appends each
/// frame's records as one block to `samples.log` (synced), then in one
/// transaction over `records` and `meta` removes the frame's per-record
/// keys, writes its one `job · frame` key (`FrameRecordsValue`), and
/// records the log's committed length and the last frame converted
/// (`meta.migrate_0004_through`); then flushes. A crash mid-step resumes
/// after the last batch committed (the log's uncommitted tail is cut off
/// first).
pub fn migrate_to_v4(db: &sled::Db, dir: &Path) -> Result<(), String> {
    migrate_to_v4_batches(db, dir, BATCH, None)
}

/// [`migrate_to_v4`] in batches of `batch` records (rounded up to whole
/// frames), stopping after `max_batches` of them if given (what a crash
/// after that batch leaves: tests resume from it).
#[doc(hidden)]
pub fn migrate_to_v4_batches(
    db: &sled::Db,
    dir: &Path,
    batch: usize,
    max_batches: Option<usize>,
) -> Result<(), String> {
    let tree = |name: &str| db.open_tree(name).map_err(|e| e.to_string());
    let (meta, records) = (tree("meta")?, tree("records")?);
    let committed = read_meta_u64(&meta, keys::META_SAMPLES_LOG_LEN)?;
    // Generation 0: logs of other generations came with schema 5.
    let mut log = SampleLog::open(dir, 0, committed).map_err(|e| format!("{LOG_FILE}: {e}"))?;
    let log_err = |e: std::io::Error| format!("{LOG_FILE}: {e}");
    let mut through = meta
        .get(keys::META_MIGRATE_0004_THROUGH)
        .map_err(|e| e.to_string())?
        .map(|v| v.to_vec());
    let mut budget = max_batches.unwrap_or(usize::MAX);
    loop {
        if budget == 0 {
            return Ok(()); // stopped after `max_batches`
        }
        let frames = next_frames(&records, through.as_deref(), batch)?;
        let Some(last) = frames.last().map(|f| f.key) else {
            break;
        };
        budget -= 1;
        let mut values = Vec::with_capacity(frames.len());
        for f in &frames {
            let block = RecordBlock {
                job: f.job,
                frame: f.frame,
                records: f.rows.iter().map(|(_, r)| r.clone()).collect(),
            };
            let value = append_record_block(&mut log, &block).map_err(log_err)?;
            values.push(encode(&value));
        }
        log.sync().map_err(log_err)?;
        let end = log.end().to_be_bytes();
        (&meta, &records)
            .transaction(|(meta, records)| {
                for (f, value) in frames.iter().zip(&values) {
                    for (k, _) in &f.rows {
                        records.remove(k)?;
                    }
                    records.insert(&f.key[..], &value[..])?;
                }
                meta.insert(keys::META_SAMPLES_LOG_LEN, &end[..])?;
                meta.insert(keys::META_MIGRATE_0004_THROUGH, &last[..])?;
                Ok::<(), ConflictableTransactionError<()>>(())
            })
            .map_err(|e| format!("{e:?}"))?;
        db.flush().map_err(|e| e.to_string())?;
        log.commit();
        through = Some(last.to_vec());
    }
    if read_meta_u64(&meta, keys::META_SAMPLES_LOG_LEN)?.is_none() {
        // Nothing was ever written to the log: say so in `meta`.
        meta.insert(keys::META_SAMPLES_LOG_LEN, &log.end().to_be_bytes())
            .map_err(|e| e.to_string())?;
        db.flush().map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The next whole frames of schema-3 record keys after `through`, at least
/// `batch` records' worth if there are that many (empty: none left).
/// Schema-4 keys (12 bytes, frames already converted) are skipped.
fn next_frames(
    records: &sled::Tree,
    through: Option<&[u8]>,
    batch: usize,
) -> Result<Vec<OldFrame>, String> {
    let start = match through {
        Some(k) => Bound::Excluded(k.to_vec()),
        None => Bound::Unbounded,
    };
    let mut frames: Vec<OldFrame> = Vec::new();
    let mut n = 0usize;
    for item in records.range::<Vec<u8>, _>((start, Bound::Unbounded)) {
        let (k, v) = item.map_err(|e| e.to_string())?;
        if k.len() == 12 {
            continue;
        }
        let at = || format!("tree `records` key {}", keys::describe(&k));
        let (job, frame, _) = keys::parse_record(&k).ok_or_else(|| at() + ": malformed key")?;
        let key = keys::frame(job, frame);
        if frames.last().map(|f| f.key) != Some(key) {
            if n >= batch.max(1) {
                break;
            }
            frames.push(OldFrame {
                key,
                job,
                frame,
                rows: Vec::new(),
            });
        }
        let r: RecordValue = super::decode_value(&v).map_err(|e| format!("{}: {e}", at()))?;
        frames.last_mut().expect("pushed above").rows.push((k, r));
        n += 1;
    }
    Ok(frames)
}
