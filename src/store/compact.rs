//! `radcache compact`: rewrites the sample log ([`super::samples`]) without
//! the bytes no value references any more, and reclaims them.
//!
//! The log is append-only: a job deleted (`radcache delete`) or restarted
//! with `--force` leaves its frames' EXRs, record blocks and samples
//! there, unreferenced (its keys are deleted), and so does a frame written
//! again (its former EXR and record block). Nothing else reclaims them.
//! A kill while a job's keys are being deleted leaves keys of a job id no
//! job holds; compaction removes those first
//! ([`Store::remove_orphaned_job_data`]).
//!
//! What references the log (every kind; see `schema.rs`):
//! - `frames`: a frame's compressed EXR ([`FrameValue`] `exr_offset`,
//!   `exr_stored_len`);
//! - `records`: a frame's record block ([`FrameRecordsValue`] `offset`,
//!   `stored_len`), and through it, in the block, each record's samples
//!   (`RecordValue` `samples_offset`, `samples_len`);
//! - `meta.samples_log_len`: the committed length.
//!
//! Nothing else does: `state` holds a stateful method's own bytes (for
//! `trc`, its records' cache fields and the next id, no offsets), `stats`
//! the frames' statistics, `jobs` the jobs, `movies` each frame's texture
//! movies with their texels inline.
//!
//! How (crash safety): the referenced blocks are copied, in log order, to
//! the log of the next generation (`samples.N.log`, created empty); a
//! record block is rewritten (its records' sample offsets move), the
//! others are copied byte for byte. The new file and the directory are
//! synced; then ONE sled transaction writes every `frames` and `records`
//! value with its new offsets, `meta.samples_log_len` (the new length) and
//! `meta.samples_log_generation` (the new file); then sled is flushed;
//! only then is the old file removed. The old file is never written to. A
//! kill before the transaction is durable leaves the store reading the old
//! file with the old offsets (the new file is a leftover); after it, the
//! new file with the new offsets (the old file is the leftover). Opening a
//! store removes the leftover ([`super::samples::remove_stale_logs`]).
//! The generation in `meta` is what made this schema 5
//! (`migrations/0005_log_generations.md`): a schema-4 build knows only
//! `samples.log` and would read a compacted store's offsets in the wrong
//! file, so it must refuse such a store.
//!
//! A store holds the sled lock of its directory: compacting a store a
//! `render` or `serve` has open fails as opening it does
//! ([`StoreError::Locked`]), touching nothing; within a process,
//! [`compact`] takes the [`Store`] mutably, so no frame commits meanwhile.

use super::samples::{self, SampleLog, MAGIC};
use super::schema::{FrameRecordsValue, FrameValue, RecordBlock};
use super::{append_record_block, encode, keys, Store, StoreError};
use serde::Serialize;
use sled::transaction::{ConflictableTransactionError, TransactionError};
use sled::Transactional;
use std::collections::hash_map::{Entry, HashMap};
use std::path::{Path, PathBuf};

/// How the committed bytes of a store's sample log are used.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct LogUsage {
    /// Committed length, header included.
    pub committed: u64,
    /// Bytes some value references (a block referenced twice counts once).
    pub referenced: u64,
    /// Bytes none does (`committed` − header − `referenced`).
    pub unreferenced: u64,
    /// Runs of unreferenced bytes between (or after) referenced blocks.
    pub unreferenced_ranges: u64,
    /// Referenced blocks by kind.
    pub exr_blocks: u64,
    pub record_blocks: u64,
    pub sample_blocks: u64,
}

/// What references a block of the log, with the key that names it.
enum Owner {
    /// A frame's EXR: its `frames` key and value.
    Exr(sled::IVec, FrameValue),
    /// A frame's record block: its `records` key and value.
    Records(sled::IVec, FrameRecordsValue),
    /// A record's samples (`job · frame · id`, for messages).
    Samples([u8; 20]),
}

impl Owner {
    fn key(&self) -> &[u8] {
        match self {
            Owner::Exr(k, _) | Owner::Records(k, _) => k,
            Owner::Samples(k) => k,
        }
    }
}

/// A referenced block: `len` bytes at `offset` of the log.
struct Block {
    offset: u64,
    len: u32,
    owner: Owner,
}

/// The step after which [`compact_with`] stops, leaving the store as a
/// kill right after it would (tests reopen it and check).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// The new log is written, not synced.
    Copied,
    /// The new log and the directory are synced; sled is untouched.
    Synced,
    /// The transaction that switches to the new log is committed, not
    /// flushed.
    Switched,
    /// sled is flushed; the old log is still there.
    Flushed,
}

/// What a compaction did.
#[derive(Clone, Debug, Serialize)]
pub struct CompactReport {
    pub path: PathBuf,
    /// The log before, and how it was used.
    pub old_file: PathBuf,
    pub before: LogUsage,
    /// The log after (the old one when there was nothing to reclaim).
    pub new_file: PathBuf,
    pub bytes_after: u64,
    /// Job ids whose keys no job held (a kill during a job's deletion or
    /// restart left them), removed first: their log bytes are then
    /// unreferenced.
    pub orphaned_jobs_removed: usize,
    /// Set when a test stopped it early ([`compact_with`]).
    #[serde(skip)]
    pub stopped_after: Option<Step>,
}

/// How the store's sample log is used: what `inspect` shows and what
/// [`compact`] would reclaim. Reads every record block (not the samples
/// or EXRs).
pub fn log_usage(store: &Store) -> Result<LogUsage, StoreError> {
    let blocks = referenced_blocks(store)?;
    usage(store, &blocks)
}

/// Compacts the store's sample log (see the module comment); `progress`
/// counts the bytes copied.
pub fn compact(
    store: &mut Store,
    progress: &indicatif::ProgressBar,
) -> Result<CompactReport, StoreError> {
    compact_with(store, progress, None)
}

/// [`compact`], stopping after `stop_after` if given. A store stopped
/// after [`Step::Switched`] or [`Step::Flushed`] must be dropped and
/// opened again: like a killed process's, its open log is the old one.
#[doc(hidden)]
pub fn compact_with(
    store: &mut Store,
    progress: &indicatif::ProgressBar,
    stop_after: Option<Step>,
) -> Result<CompactReport, StoreError> {
    // The new log would leave out the frames past the old one's end.
    store.refuse_if_frames_lost()?;
    let orphaned_jobs_removed = store.remove_orphaned_job_data()?;
    let blocks = referenced_blocks(store)?;
    let before = usage(store, &blocks)?;
    let mut report = CompactReport {
        path: store.path.clone(),
        old_file: store.sample_log_file(),
        new_file: store.sample_log_file(),
        bytes_after: before.committed,
        orphaned_jobs_removed,
        before: before.clone(),
        stopped_after: None,
    };
    if before.unreferenced == 0 {
        return Ok(report); // already compact: nothing is written
    }
    let generation = store.log_generation + 1;
    let path = store.path.clone();
    let new_error = |detail: String| StoreError::SampleLog {
        path: path.clone(),
        file: path.join(samples::file_name(generation)),
        detail,
    };
    // Created empty (a leftover of the same name was removed on open).
    // Until the switch, nothing references it: a failure removes it.
    let new_file = path.join(samples::file_name(generation));
    let unwritten = |e: StoreError| remove_unswitched(&new_file, e);
    let mut new = SampleLog::open(&path, generation, None)
        .map_err(new_error)
        .map_err(unwritten)?;
    report.new_file = new.path().to_owned();
    progress.set_length(before.referenced);
    let values = copy_blocks(store, &blocks, &mut new, progress).map_err(unwritten)?;
    report.bytes_after = new.end();
    let stop = |step: Step, mut report: CompactReport| {
        report.stopped_after = Some(step);
        Ok(report)
    };
    if stop_after == Some(Step::Copied) {
        return stop(Step::Copied, report);
    }
    new.sync()
        .map_err(|e| new_error(format!("cannot sync it: {e}")))
        .map_err(unwritten)?;
    samples::sync_dir(&path)
        .map_err(new_error)
        .map_err(unwritten)?;
    if stop_after == Some(Step::Synced) {
        return stop(Step::Synced, report);
    }
    // Kept if the switch fails: sled may have applied it before failing,
    // and then the store references the new log (the next open removes
    // whichever log is the leftover).
    switch(store, &values, generation, new.end())?;
    if stop_after == Some(Step::Switched) {
        return stop(Step::Switched, report);
    }
    store.flush()?;
    if stop_after == Some(Step::Flushed) {
        return stop(Step::Flushed, report);
    }
    new.commit();
    *store.log.get_mut().unwrap_or_else(|e| e.into_inner()) = new;
    store.log_generation = generation;
    // The old file, now referenced by nothing (a failure here leaves it
    // for the next open to remove).
    samples::remove_stale_logs(&path, generation).map_err(new_error)?;
    Ok(report)
}

/// `error`, having removed `file`, the new log of a compaction that failed
/// before the store switched to it: no value references it, and a disk
/// that filled up should not stay full until the store is next opened
/// (which removes it too, should removing it fail here).
fn remove_unswitched(file: &Path, error: StoreError) -> StoreError {
    let _ = std::fs::remove_file(file);
    error
}

/// Every block of the log some value references, in log order.
fn referenced_blocks(store: &Store) -> Result<Vec<Block>, StoreError> {
    let sled_err = |e| StoreError::sled(&store.path, e);
    let mut blocks = Vec::new();
    for item in store.frames.iter() {
        let (k, v) = item.map_err(sled_err)?;
        let value: FrameValue = store.decode("frames", &k, &v)?;
        blocks.push(Block {
            offset: value.exr_offset,
            len: value.exr_stored_len,
            owner: Owner::Exr(k, value),
        });
    }
    for item in store.records.iter() {
        let (k, v) = item.map_err(sled_err)?;
        let value: FrameRecordsValue = store.decode("records", &k, &v)?;
        // Checked against its key and the log as any reader does.
        let records = store.record_block(&k, &value)?;
        let (job, frame) = keys::parse_frame(&k).unwrap_or_default();
        for r in records.iter().filter(|r| r.samples_count > 0) {
            blocks.push(Block {
                offset: r.samples_offset,
                len: r.samples_len,
                owner: Owner::Samples(keys::record(job, frame, r.id)),
            });
        }
        blocks.push(Block {
            offset: value.offset,
            len: value.stored_len,
            owner: Owner::Records(k, value),
        });
    }
    blocks.sort_by_key(|b| (b.offset, b.len));
    Ok(blocks)
}

/// Sums `blocks` (sorted) against the committed log; a block outside it,
/// or overlapping another one (other than the same block referenced
/// twice), is an error naming its key: compacting would lose bytes.
fn usage(store: &Store, blocks: &[Block]) -> Result<LogUsage, StoreError> {
    let committed = store.sample_log_bytes();
    let header = MAGIC.len() as u64;
    let mut u = LogUsage {
        committed,
        ..LogUsage::default()
    };
    let mut covered = header;
    let mut last = None;
    for b in blocks {
        if last == Some((b.offset, b.len)) {
            continue; // shared: counted once
        }
        let stop = b.offset.saturating_add(u64::from(b.len));
        let problem = if b.offset < header || stop > committed {
            Some(format!("lie outside its committed {committed} bytes"))
        } else if b.offset < covered {
            Some(format!("overlap another block (ending at {covered})"))
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(store.log_error(format!(
                "bytes {}..{stop} of {} {problem}",
                b.offset,
                store.describe_key(b.owner.key())
            )));
        }
        u.unreferenced_ranges += u64::from(b.offset > covered);
        u.referenced += u64::from(b.len);
        match b.owner {
            Owner::Exr(..) => u.exr_blocks += 1,
            Owner::Records(..) => u.record_blocks += 1,
            Owner::Samples(_) => u.sample_blocks += 1,
        }
        covered = stop;
        last = Some((b.offset, b.len));
    }
    u.unreferenced_ranges += u64::from(committed > covered);
    u.unreferenced = committed - header - u.referenced;
    Ok(u)
}

/// The `frames` and `records` values to write, with their new offsets.
#[derive(Default)]
struct NewValues {
    frames: Vec<(sled::IVec, Vec<u8>)>,
    records: Vec<(sled::IVec, Vec<u8>)>,
}

/// Copies `blocks` (sorted) into `new`, in log order: EXRs and samples as
/// they are, once each; a record block rewritten with its records' new
/// sample offsets (after its samples, as a frame's commit writes them:
/// should a block come before one of its samples, it goes at the end).
fn copy_blocks(
    store: &Store,
    blocks: &[Block],
    new: &mut SampleLog,
    progress: &indicatif::ProgressBar,
) -> Result<NewValues, StoreError> {
    let mut moved: HashMap<(u64, u32), u64> = HashMap::new();
    let mut out = NewValues::default();
    let mut deferred = Vec::new();
    for b in blocks {
        match &b.owner {
            Owner::Records(key, value) => {
                let block = read_record_block(store, key, value)?;
                let ready = block.records.iter().all(|r| {
                    r.samples_count == 0 || moved.contains_key(&(r.samples_offset, r.samples_len))
                });
                if ready {
                    out.records
                        .push((key.clone(), rewrite_block(store, block, &moved, new)?));
                } else {
                    deferred.push((key.clone(), block));
                }
                progress.inc(u64::from(b.len));
            }
            Owner::Exr(..) | Owner::Samples(_) => {
                let at = match moved.entry((b.offset, b.len)) {
                    Entry::Occupied(e) => *e.get(), // shared: copied once
                    Entry::Vacant(e) => {
                        progress.inc(u64::from(b.len));
                        *e.insert(copy_raw(store, b, new)?)
                    }
                };
                if let Owner::Exr(key, value) = &b.owner {
                    let value = FrameValue {
                        exr_offset: at,
                        ..value.clone()
                    };
                    out.frames.push((key.clone(), encode(&value)));
                }
            }
        }
    }
    for (key, block) in deferred {
        out.records
            .push((key, rewrite_block(store, block, &moved, new)?));
    }
    Ok(out)
}

/// A record block, read and checked as any reader does.
fn read_record_block(
    store: &Store,
    key: &[u8],
    value: &FrameRecordsValue,
) -> Result<RecordBlock, StoreError> {
    let (job, frame) = keys::parse_frame(key).unwrap_or_default();
    Ok(RecordBlock {
        job,
        frame,
        records: store.record_block(key, value)?,
    })
}

/// Appends block `b`'s bytes, read from the store's log, to `new`; returns
/// their new offset.
fn copy_raw(store: &Store, b: &Block, new: &mut SampleLog) -> Result<u64, StoreError> {
    let bytes = store
        .lock_log()
        .read(b.offset, b.len)
        .map_err(|e| store.log_error(format!("{}: {e}", store.describe_key(b.owner.key()))))?;
    new.append(&bytes)
        .map_err(|e| store.log_error(format!("cannot write the new log: {e}")))
}

/// Appends `block` to `new` with its records' samples at their new
/// offsets; returns its new `records` value.
fn rewrite_block(
    store: &Store,
    mut block: RecordBlock,
    moved: &HashMap<(u64, u32), u64>,
    new: &mut SampleLog,
) -> Result<Vec<u8>, StoreError> {
    for r in block.records.iter_mut().filter(|r| r.samples_count > 0) {
        r.samples_offset = moved[&(r.samples_offset, r.samples_len)];
    }
    let value = append_record_block(new, &block)
        .map_err(|e| store.log_error(format!("cannot write the new log: {e}")))?;
    Ok(encode(&value))
}

/// The one transaction that switches the store to the new log: every
/// `frames` and `records` value with its new offsets, the new log's
/// length and generation.
fn switch(store: &Store, values: &NewValues, generation: u64, len: u64) -> Result<(), StoreError> {
    let (len, generation) = (len.to_be_bytes(), generation.to_be_bytes());
    let result: Result<(), TransactionError<()>> = (&store.frames, &store.records, &store.meta)
        .transaction(|(frames, records, meta)| {
            for (k, v) in &values.frames {
                frames.insert(&k[..], &v[..])?;
            }
            for (k, v) in &values.records {
                records.insert(&k[..], &v[..])?;
            }
            meta.insert(keys::META_SAMPLES_LOG_LEN, &len[..])?;
            meta.insert(keys::META_SAMPLES_LOG_GENERATION, &generation[..])?;
            Ok::<(), ConflictableTransactionError<()>>(())
        });
    result.map_err(|e| match e {
        TransactionError::Storage(s) => StoreError::sled(&store.path, s),
        TransactionError::Abort(()) => unreachable!("the transaction never aborts"),
    })
}

/// A progress bar over the bytes copied (hidden with `quiet`, and by
/// indicatif when stderr is not a terminal).
pub fn progress_bar(quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {bytes}/{total_bytes} copied, eta {eta}",
        )
        .expect("static progress template is valid"),
    );
    bar
}

/// The report as text: bytes before and after, what was dropped.
pub fn to_text(r: &CompactReport) -> String {
    let u = &r.before;
    let name = |p: &PathBuf| {
        p.file_name()
            .map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into())
    };
    let orphans = match r.orphaned_jobs_removed {
        0 => String::new(),
        n => format!(
            "removed the keys of {n} job id(s) no job holds (a deletion or --force restart cut short)\n"
        ),
    };
    if u.unreferenced == 0 {
        return format!(
            "{orphans}store {}: sample log {} is compact ({} bytes, all referenced); nothing to do\n",
            r.path.display(),
            name(&r.old_file),
            u.committed
        );
    }
    orphans
        + &format!(
        "store {}: sample log {} → {}: {} → {} bytes\n\
         dropped {} unreferenced bytes in {} range(s); kept {} frame EXRs, {} record blocks and {} sample blocks ({} bytes before, as they were encoded)\n",
        r.path.display(),
        name(&r.old_file),
        name(&r.new_file),
        u.committed,
        r.bytes_after,
        u.unreferenced,
        u.unreferenced_ranges,
        u.exr_blocks,
        u.record_blocks,
        u.sample_blocks,
        u.referenced,
    )
}
