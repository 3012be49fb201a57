//! The persistent space-time store (DESIGN.md "The store"): a sled 0.34
//! database directory with one tree per kind — `meta`, `records`,
//! `movies`, `frames`, `jobs`, `stats`, `state` — and, beside it in the
//! same directory, the append-only sample log `samples.log` (after a
//! [`compact`]ion, `samples.N.log`: `meta` names it) ([`samples`]).
//!
//! - Keys: big-endian, built only by [`keys`] (layout there and in
//!   `migrations/0001_initial.md`, `migrations/0002_state_and_identity.md`,
//!   `migrations/0003_sample_log.md`, `migrations/0004_record_blocks.md`,
//!   `migrations/0005_log_generations.md`).
//! - Values: rkyv archives ([`schema`]), validated on every read; a value
//!   that fails validation is [`StoreError::Corrupt`] naming tree and key.
//! - Bulk values are zstd-compressed and live in the sample log, whose
//!   location the sled value holds: a frame's EXR file (`frames`), a
//!   frame's records (`records`: one block of [`schema::RecordValue`]s per
//!   frame), a record's samples (the record value; the 8-byte RGBE records
//!   of [`rgbe::PackedSample`], one block per record). They thus stay out
//!   of sled, whose memory grows with the bytes and keys it has written:
//!   sled sees a few small values per frame, however many records it has.
//! - A job checkpoints each frame with [`Store::commit_frame`]: the frame's
//!   EXR, sample blocks and record block are appended to the log and
//!   synced, then one sled transaction over `frames`, `records`, `stats`,
//!   `state`, `jobs` and `meta` (the log's committed length), then `flush`;
//!   the frame counts as acknowledged only after that returns. A log tail
//!   beyond the committed length (a crash in between) is cut off when the
//!   store is opened.
//! - `state` holds the cache a stateful method (`trc`) carries to the next
//!   frame, as of the job's last frame: each frame writes only its changes
//!   (records put and removed, and the head), and a resume loads it
//!   ([`Store::load_state`]) instead of rendering the finished frames again.
//! - Bytes of the log no value references any more (a job restarted with
//!   `--force`, a frame written again) stay until [`compact`] rewrites the
//!   log without them.
//! - The schema version lives in `meta`; see [`migrate`].

pub mod compact;
pub mod inspect;
pub mod keys;
pub mod migrate;
pub mod rgbe;
pub mod samples;
pub mod schema;
pub mod v1;
pub mod v2;
pub mod v3;
pub mod v4;

use rkyv::api::high::{HighDeserializer, HighSerializer, HighValidator};
use rkyv::bytecheck::CheckBytes;
use rkyv::rancor;
use rkyv::ser::allocator::ArenaHandle;
use rkyv::util::AlignedVec;
use samples::{compress, decompress, SampleLog};
use schema::{
    FrameRecordsValue, FrameValue, JobValue, RecordBlock, RecordValue, StateHeadValue,
    StateRecordValue, StatsValue,
};
use sled::transaction::{ConflictableTransactionError, TransactionError};
use sled::Transactional;
use std::path::{Path, PathBuf};

pub use rgbe::PackedSample;
pub use samples::SampleBlock;
pub use schema::JobSpec;

/// The trees, in the order `inspect` lists them.
pub const TREES: [&str; 7] = [
    "meta", "jobs", "frames", "stats", "records", "state", "movies",
];

/// sled's page cache. Its default (1 GiB) made a render's memory grow
/// with the size of the store; the renderer reads little back. Since the
/// samples moved to the sample log, sled holds only small values, and a
/// 16 MiB cache took hundreds of frames to fill: a 16×16 `ic` render
/// peaked at 22 MB for 100 frames and 32 MB for 400 with it, 21 and 24 MB
/// with 2 MiB (README, "Peak memory").
const CACHE_BYTES: u64 = 2 * 1024 * 1024;

/// The most records one frame's block may hold (a sanity bound on a
/// `records` value read back: far above any frame's, ≈ 200 bytes each).
const MAX_BLOCK_RECORDS: u32 = 1 << 24;

/// Store errors; every message names the store path and the problem.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("store {}: no store here (create one with `radcache render --db PATH --job NAME`)", path.display())]
    Missing { path: PathBuf },
    #[error("store {}: locked by another process (is a render or inspect still running?): {detail}", path.display())]
    Locked { path: PathBuf, detail: String },
    #[error("store {}: not a radcache store: {detail}", path.display())]
    NotAStore { path: PathBuf, detail: String },
    #[error("store {}: schema version {found} is newer than this radcache supports (version {supported}); use a newer radcache", path.display())]
    NewerSchema {
        path: PathBuf,
        found: u32,
        supported: u32,
    },
    #[error("store {}: corrupt value in tree `{tree}` at key {key}: {detail}", path.display())]
    Corrupt {
        path: PathBuf,
        tree: &'static str,
        key: String,
        detail: String,
    },
    #[error("store {}: migration from schema {from} failed: {detail}", path.display())]
    Migration {
        path: PathBuf,
        from: u32,
        detail: String,
    },
    #[error("store {}: job {job:?}: {detail}", path.display())]
    Job {
        path: PathBuf,
        job: String,
        detail: String,
    },
    #[error("store {}: sample log {}: {detail}", path.display(), file.display())]
    SampleLog {
        path: PathBuf,
        file: PathBuf,
        detail: String,
    },
    #[error("store {}: {source}", path.display())]
    Sled { path: PathBuf, source: sled::Error },
}

impl StoreError {
    fn sled(path: &Path, source: sled::Error) -> Self {
        StoreError::Sled {
            path: path.to_owned(),
            source,
        }
    }
}

/// An open store. Only one process (and one `Store` per process) can hold
/// a store directory at a time: sled locks it.
pub struct Store {
    path: PathBuf,
    db: sled::Db,
    meta: sled::Tree,
    jobs: sled::Tree,
    frames: sled::Tree,
    stats: sled::Tree,
    records: sled::Tree,
    state: sled::Tree,
    movies: sled::Tree,
    /// The sample log's generation (`meta.samples_log_generation`): its
    /// file is [`samples::file_name`] of it.
    log_generation: u64,
    /// The sample log; locked over a whole [`Store::commit_frame`] (its
    /// appends and the transaction that commits them).
    log: std::sync::Mutex<SampleLog>,
}

/// One record of a frame with its samples, ready to store.
pub struct RecordCommit {
    pub record: RecordValue,
    /// The record's samples in cell order, stored form (may be empty).
    /// [`Store::commit_frame`] fills in the record's sample location.
    pub samples: SampleBlock,
}

/// Everything one frame writes.
pub struct FrameCommit<'a> {
    pub frame: u32,
    pub width: u32,
    pub height: u32,
    /// The frame's EXR file bytes.
    pub exr: &'a [u8],
    pub records: Vec<RecordCommit>,
    pub stats: &'a crate::method::FrameStats,
    /// The frame's changes of a stateful method's carried state.
    pub state: Option<StateCommit<'a>>,
}

/// A stateful method's state changes of one frame, with the chain they
/// belong to (see [`StateHeadValue`]).
pub struct StateCommit<'a> {
    pub chain_start: u32,
    pub chain_end: Option<u32>,
    pub changes: &'a crate::method::StateChanges,
}

/// A frame's bulk values once in the sample log ([`Store::append_frame`]).
struct LoggedFrame {
    frame: FrameValue,
    /// The encoded [`FrameRecordsValue`] of the frame's record block, if it
    /// has records.
    records: Option<Vec<u8>>,
    /// The samples' size before compression, for the frame's statistics.
    samples_raw: u64,
}

/// A frame's changes of the `state` tree, encoded: rows put, rows removed
/// and the new head.
#[derive(Default)]
struct StateRows {
    put: Vec<([u8; 16], Vec<u8>)>,
    removed: Vec<[u8; 16]>,
    head: Option<Vec<u8>>,
}

impl StateRows {
    fn new(job: u64, frame: u32, sc: &StateCommit) -> Self {
        let put = sc
            .changes
            .put
            .iter()
            .map(|(id, data)| {
                let value = StateRecordValue {
                    frame,
                    data: data.clone(),
                };
                (keys::state_record(job, *id), encode(&value))
            })
            .collect();
        let removed = sc
            .changes
            .removed
            .iter()
            .map(|&id| keys::state_record(job, id))
            .collect();
        let head = StateHeadValue {
            frame,
            chain_start: sc.chain_start,
            chain_end: sc.chain_end,
            global: sc.changes.global.clone(),
        };
        StateRows {
            put,
            removed,
            head: Some(encode(&head)),
        }
    }
}

/// FNV-1a 64 of `bytes`, in hex: the scene content hash of a job (stable
/// across builds and platforms, unlike `std`'s hasher).
pub fn content_hash(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Appends a frame's records to the sample log as one zstd block (schema
/// 4) and returns the frame's `records` value, which says where it is.
fn append_record_block(
    log: &mut SampleLog,
    block: &RecordBlock,
) -> std::io::Result<FrameRecordsValue> {
    let raw = encode(block);
    let zstd = compress(&raw);
    Ok(FrameRecordsValue {
        count: block.records.len() as u32,
        first_id: block.records.first().map_or(0, |r| r.id),
        last_id: block.records.last().map_or(0, |r| r.id),
        offset: log.append(&zstd)?,
        stored_len: zstd.len() as u32,
        raw_len: raw.len() as u32,
    })
}

fn now_unix() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0)
}

/// Reads an rkyv archive (validated) of a `T`.
pub(crate) fn decode_value<T>(bytes: &[u8]) -> Result<T, String>
where
    T: rkyv::Archive,
    T::Archived: for<'a> CheckBytes<HighValidator<'a, rancor::Error>>
        + rkyv::Deserialize<T, HighDeserializer<rancor::Error>>,
{
    // sled values carry no alignment guarantee; rkyv needs 16.
    let mut aligned = AlignedVec::<16>::with_capacity(bytes.len());
    aligned.extend_from_slice(bytes);
    rkyv::from_bytes::<T, rancor::Error>(&aligned).map_err(|e| e.to_string())
}

/// An rkyv archive of `value`.
pub(crate) fn encode<T>(value: &T) -> Vec<u8>
where
    T: for<'a> rkyv::Serialize<HighSerializer<AlignedVec, ArenaHandle<'a>, rancor::Error>>,
{
    rkyv::to_bytes::<rancor::Error>(value)
        .expect("serialising plain data to memory cannot fail")
        .into_vec()
}

impl Store {
    /// Opens the store at `path`, creating it if the directory does not
    /// exist (or is empty). Runs pending migrations.
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        Self::open_with(path, true, migrate::CURRENT_VERSION, migrate::MIGRATIONS)
    }

    /// Opens an existing store; [`StoreError::Missing`] if there is none.
    pub fn open_existing(path: &Path) -> Result<Store, StoreError> {
        Self::open_with(path, false, migrate::CURRENT_VERSION, migrate::MIGRATIONS)
    }

    /// [`Self::open`] with an explicit target version and migration list
    /// (tests exercise the runner with synthetic steps).
    pub fn open_with(
        path: &Path,
        create: bool,
        target: u32,
        steps: &[migrate::Migration],
    ) -> Result<Store, StoreError> {
        let existing = check_directory(path, create)?;
        let db = open_sled(path)?;
        let tree = |name: &str| db.open_tree(name).map_err(|e| StoreError::sled(path, e));
        let meta = tree("meta")?;
        let version = match migrate::read_version(path, &meta)? {
            Some(found) => Some(migrate::migrate(path, &db, &meta, found, target, steps)?),
            None => None,
        };
        let (log_generation, log) = open_sample_log(path, &meta)?;
        let store = Store {
            path: path.to_owned(),
            meta,
            jobs: tree("jobs")?,
            frames: tree("frames")?,
            stats: tree("stats")?,
            records: tree("records")?,
            state: tree("state")?,
            movies: tree("movies")?,
            log_generation,
            log: std::sync::Mutex::new(log),
            db,
        };
        if version.is_none() {
            store.initialize(existing, target)?;
        }
        Ok(store)
    }

    /// Makes a store without a schema version one of schema `target`: a
    /// new directory (`existing` false), or an existing sled database with
    /// nothing in it; anything else is not ours to take over.
    fn initialize(&self, existing: bool, target: u32) -> Result<(), StoreError> {
        let empty = TREES
            .iter()
            .all(|t| self.tree(t).map(|tree| tree.is_empty()).unwrap_or(false));
        if existing && !empty {
            return Err(StoreError::NotAStore {
                path: self.path.clone(),
                detail: "sled database without a schema version in `meta`".into(),
            });
        }
        migrate::write_version(&self.path, &self.meta, target)?;
        self.meta
            .insert(
                keys::META_CREATED_BY,
                concat!("radcache ", env!("CARGO_PKG_VERSION")).as_bytes(),
            )
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn schema_version(&self) -> Result<u32, StoreError> {
        Ok(migrate::read_version(&self.path, &self.meta)?.unwrap_or(0))
    }

    /// A tree by name (one of [`TREES`]).
    pub fn tree(&self, name: &str) -> Option<&sled::Tree> {
        Some(match name {
            "meta" => &self.meta,
            "jobs" => &self.jobs,
            "frames" => &self.frames,
            "stats" => &self.stats,
            "records" => &self.records,
            "state" => &self.state,
            "movies" => &self.movies,
            _ => return None,
        })
    }

    /// Bytes of the sled database's files (the sample log aside: see
    /// [`Self::sample_log_bytes`]).
    pub fn size_on_disk(&self) -> Result<u64, StoreError> {
        self.db
            .size_on_disk()
            .map_err(|e| StoreError::sled(&self.path, e))
    }

    /// The sample log's file (`samples.log`, or `samples.N.log` after a
    /// compaction).
    pub fn sample_log_file(&self) -> PathBuf {
        self.path.join(samples::file_name(self.log_generation))
    }

    /// Committed bytes of the sample log ([`Self::sample_log_file`]).
    pub fn sample_log_bytes(&self) -> u64 {
        self.lock_log().committed()
    }

    fn lock_log(&self) -> std::sync::MutexGuard<'_, SampleLog> {
        // A panic while holding it leaves the log as consistent as a crash.
        self.log.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn log_error(&self, detail: impl ToString) -> StoreError {
        StoreError::SampleLog {
            path: self.path.clone(),
            file: self.sample_log_file(),
            detail: detail.to_string(),
        }
    }

    pub fn flush(&self) -> Result<(), StoreError> {
        self.db
            .flush()
            .map(|_| ())
            .map_err(|e| StoreError::sled(&self.path, e))
    }

    fn decode<T>(&self, tree: &'static str, key: &[u8], bytes: &[u8]) -> Result<T, StoreError>
    where
        T: rkyv::Archive,
        T::Archived: for<'a> CheckBytes<HighValidator<'a, rancor::Error>>
            + rkyv::Deserialize<T, HighDeserializer<rancor::Error>>,
    {
        decode_value(bytes).map_err(|e| self.corrupt(tree, key, e))
    }

    fn corrupt(&self, tree: &'static str, key: &[u8], detail: impl ToString) -> StoreError {
        StoreError::Corrupt {
            path: self.path.clone(),
            tree,
            key: keys::describe(key),
            detail: detail.to_string(),
        }
    }

    fn get<T>(&self, tree: &'static str, key: &[u8]) -> Result<Option<T>, StoreError>
    where
        T: rkyv::Archive,
        T::Archived: for<'a> CheckBytes<HighValidator<'a, rancor::Error>>
            + rkyv::Deserialize<T, HighDeserializer<rancor::Error>>,
    {
        let t = self.tree(tree).expect("known tree");
        match t.get(key).map_err(|e| StoreError::sled(&self.path, e))? {
            Some(v) => self.decode(tree, key, &v).map(Some),
            None => Ok(None),
        }
    }

    // ------------------------------------------------------------ jobs

    pub fn job(&self, name: &str) -> Result<Option<JobValue>, StoreError> {
        self.get("jobs", &keys::job(name))
    }

    pub fn jobs(&self) -> Result<Vec<JobValue>, StoreError> {
        let mut out = Vec::new();
        for item in self.jobs.iter() {
            let (k, v) = item.map_err(|e| StoreError::sled(&self.path, e))?;
            out.push(self.decode("jobs", &k, &v)?);
        }
        Ok(out)
    }

    /// Marks job `name` cancelled (or not) for `radcache serve`, durably
    /// (a `meta` key; no schema change).
    pub fn set_job_cancelled(&self, name: &str, cancelled: bool) -> Result<(), StoreError> {
        let key = keys::meta_cancelled(name);
        let r = if cancelled {
            self.meta.insert(key, &[] as &[u8]).map(|_| ())
        } else {
            self.meta.remove(key).map(|_| ())
        };
        r.map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()
    }

    /// Whether job `name` is marked cancelled ([`Self::set_job_cancelled`]).
    pub fn job_cancelled(&self, name: &str) -> Result<bool, StoreError> {
        self.meta
            .contains_key(keys::meta_cancelled(name))
            .map_err(|e| StoreError::sled(&self.path, e))
    }

    /// Starts or resumes job `spec.name`. A job of that name with another
    /// scene or other settings is refused unless `force`, which starts it
    /// over under a new id (the old id's data is then deleted).
    pub fn begin_job(&self, spec: &JobSpec, force: bool) -> Result<JobValue, StoreError> {
        let key = keys::job(&spec.name);
        let now = now_unix();
        if let Some(mut job) = self.job(&spec.name)? {
            let diffs = job_differences(&job.spec, spec);
            if diffs.is_empty() {
                // Same job: the new range, and the spec as this build
                // writes it (a schema-1 job's settings and hash upgraded).
                job.spec = spec.clone();
                job.updated_unix = now;
                self.jobs
                    .insert(&key, encode(&job))
                    .map_err(|e| StoreError::sled(&self.path, e))?;
                self.flush()?;
                return Ok(job);
            }
            if !force {
                return Err(StoreError::Job {
                    path: self.path.clone(),
                    job: spec.name.clone(),
                    detail: format!(
                        "exists with a different {}; use another --job name, or --force to start it over",
                        diffs.join(", ")
                    ),
                });
            }
            let fresh = self.new_job_value(spec, now)?;
            // The name now points at a fresh id: atomic by construction.
            self.jobs
                .insert(&key, encode(&fresh))
                .map_err(|e| StoreError::sled(&self.path, e))?;
            self.flush()?;
            self.delete_job_data(job.id)?;
            return Ok(fresh);
        }
        let fresh = self.new_job_value(spec, now)?;
        self.jobs
            .insert(&key, encode(&fresh))
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()?;
        Ok(fresh)
    }

    fn new_job_value(&self, spec: &JobSpec, now: u64) -> Result<JobValue, StoreError> {
        // Ids are unique over the store's life (sled persists the counter
        // and skips ahead after a crash), so a restarted job never sees
        // keys of its former self.
        let id = self
            .db
            .generate_id()
            .map_err(|e| StoreError::sled(&self.path, e))?
            + 1;
        Ok(JobValue {
            id,
            spec: spec.clone(),
            frames_done: 0,
            last_frame: None,
            created_unix: now,
            updated_unix: now,
        })
    }

    /// Deletes every key of job id `job` in the per-job trees.
    fn delete_job_data(&self, job: u64) -> Result<(), StoreError> {
        let prefix = keys::job_prefix(job);
        // Their bytes stay in the log, unreferenced (it is append-only),
        // until `radcache compact` ([`compact`]).
        for tree in [&self.frames, &self.stats, &self.records, &self.state] {
            for key in tree.scan_prefix(prefix).keys() {
                let key = key.map_err(|e| StoreError::sled(&self.path, e))?;
                tree.remove(key)
                    .map_err(|e| StoreError::sled(&self.path, e))?;
            }
        }
        self.flush()
    }

    // ------------------------------------------------------------ frames

    pub fn frame_done(&self, job: u64, frame: u32) -> Result<bool, StoreError> {
        self.frames
            .contains_key(keys::frame(job, frame))
            .map_err(|e| StoreError::sled(&self.path, e))
    }

    /// Frames of `job` that are stored, in order.
    pub fn frames_done(&self, job: u64) -> Result<Vec<u32>, StoreError> {
        let mut out = Vec::new();
        for key in self.frames.scan_prefix(keys::job_prefix(job)).keys() {
            let key = key.map_err(|e| StoreError::sled(&self.path, e))?;
            let (_, frame) = keys::parse_frame(&key)
                .ok_or_else(|| self.corrupt("frames", &key, "malformed key"))?;
            out.push(frame);
        }
        Ok(out)
    }

    /// Writes one finished frame of `job` — image, records with samples,
    /// stats and progress: the records' sample blocks appended to the
    /// sample log and synced, then everything else and the log's new
    /// committed length in one atomic transaction, then a flush. Only
    /// when this returns `Ok` is the frame acknowledged; `job` is updated
    /// to the stored progress.
    pub fn commit_frame(&self, job: &mut JobValue, c: FrameCommit) -> Result<(), StoreError> {
        let mut log = self.lock_log();
        let result = self.commit_frame_locked(&mut log, job, c);
        match &result {
            // The transaction references the appends, flushed or not.
            Ok(_) => log.commit(),
            // No transaction references them: cut them off now (a crash
            // before this is handled on the next open).
            Err(_) => log.rollback().map_err(|e| self.log_error(e))?,
        }
        let progressed = result?;
        self.flush()?;
        *job = progressed;
        Ok(())
    }

    fn commit_frame_locked(
        &self,
        log: &mut SampleLog,
        job: &JobValue,
        c: FrameCommit,
    ) -> Result<JobValue, StoreError> {
        let frame_key = keys::frame(job.id, c.frame);
        // A frame written again (by another chain of a stateful method)
        // replaces the record block of its former self (or, writing none,
        // removes it).
        let already = self.frame_done(job.id, c.frame)?;
        let logged =
            self.append_frame(log, job.id, c.frame, (c.width, c.height), c.exr, c.records)?;
        let log_len = log.end().to_be_bytes();
        let stats_bytes = encode(&StatsValue::from_stats(c.stats, logged.samples_raw));
        let state = c
            .state
            .as_ref()
            .map(|sc| StateRows::new(job.id, c.frame, sc))
            .unwrap_or_default();
        let state_head_key = keys::state_head(job.id);
        let mut progressed = job.clone();
        if !already {
            progressed.frames_done += 1;
        }
        progressed.last_frame = Some(c.frame);
        progressed.updated_unix = now_unix();
        let frame_bytes = encode(&logged.frame);
        let job_bytes = encode(&progressed);
        let job_key = keys::job(&job.name);
        let result: Result<(), TransactionError<()>> = (
            &self.frames,
            &self.records,
            &self.meta,
            &self.stats,
            &self.state,
            &self.jobs,
        )
            .transaction(|(frames, records, meta, stats, state_tree, jobs)| {
                for k in &state.removed {
                    state_tree.remove(&k[..])?;
                }
                for (k, v) in &state.put {
                    state_tree.insert(&k[..], &v[..])?;
                }
                if let Some(head) = &state.head {
                    state_tree.insert(&state_head_key[..], &head[..])?;
                }
                match &logged.records {
                    Some(v) => {
                        records.insert(&frame_key[..], &v[..])?;
                    }
                    None if already => {
                        records.remove(&frame_key[..])?;
                    }
                    None => {}
                }
                meta.insert(keys::META_SAMPLES_LOG_LEN, &log_len[..])?;
                stats.insert(&frame_key[..], &stats_bytes[..])?;
                frames.insert(&frame_key[..], &frame_bytes[..])?;
                jobs.insert(&job_key[..], &job_bytes[..])?;
                Ok::<(), ConflictableTransactionError<()>>(())
            });
        result.map_err(|e| match e {
            TransactionError::Storage(s) => StoreError::sled(&self.path, s),
            TransactionError::Abort(()) => unreachable!("the transaction never aborts"),
        })?;
        Ok(progressed)
    }

    /// Appends frame `frame`'s bulk values to the sample log and syncs it:
    /// its EXR file, each record's samples, then the records as one block
    /// (in id order, after their samples: it says where they lie). What
    /// the frame's transaction then points at.
    fn append_frame(
        &self,
        log: &mut SampleLog,
        job: u64,
        frame: u32,
        (width, height): (u32, u32),
        exr: &[u8],
        commits: Vec<RecordCommit>,
    ) -> Result<LoggedFrame, StoreError> {
        let exr_zstd = compress(exr);
        let frame_value = FrameValue {
            width,
            height,
            exr_len: exr.len() as u64,
            exr_offset: log.append(&exr_zstd).map_err(|e| self.log_error(e))?,
            exr_stored_len: exr_zstd.len() as u32,
        };
        drop(exr_zstd);
        let mut records = Vec::with_capacity(commits.len());
        let mut samples_raw = 0u64;
        for rc in commits {
            let mut record = rc.record;
            (
                record.samples_count,
                record.samples_offset,
                record.samples_len,
            ) = if rc.samples.is_empty() {
                (0, 0, 0)
            } else {
                samples_raw += rc.samples.raw_bytes();
                let offset = log
                    .append(&rc.samples.zstd)
                    .map_err(|e| self.log_error(e))?;
                (rc.samples.count, offset, rc.samples.zstd.len() as u32)
            };
            records.push(record);
        }
        // A record given twice keeps its last version, as a second insert
        // under its key did in schema 3.
        records.sort_by_key(|r| r.id);
        records.reverse();
        records.dedup_by_key(|r| r.id);
        records.reverse();
        let records_value = if records.is_empty() {
            None
        } else {
            let block = RecordBlock {
                job,
                frame,
                records,
            };
            let value = append_record_block(log, &block).map_err(|e| self.log_error(e))?;
            Some(encode(&value))
        };
        if log.end() > log.committed() {
            log.sync().map_err(|e| self.log_error(e))?;
        }
        Ok(LoggedFrame {
            frame: frame_value,
            records: records_value,
            samples_raw,
        })
    }

    pub fn frame(&self, job: u64, frame: u32) -> Result<Option<FrameValue>, StoreError> {
        self.get("frames", &keys::frame(job, frame))
    }

    /// The EXR bytes of a stored frame.
    pub fn frame_exr(&self, job: u64, frame: u32) -> Result<Option<Vec<u8>>, StoreError> {
        let key = keys::frame(job, frame);
        let Some(v) = self.frame(job, frame)? else {
            return Ok(None);
        };
        let in_log = |d: String| {
            self.log_error(format!(
                "EXR of {} at offset {}: {d}",
                keys::describe(&key),
                v.exr_offset
            ))
        };
        let stored = self
            .lock_log()
            .read(v.exr_offset, v.exr_stored_len)
            .map_err(in_log)?;
        let exr = decompress(&stored, v.exr_len as usize).map_err(in_log)?;
        Ok(Some(exr))
    }

    pub fn frame_stats(&self, job: u64, frame: u32) -> Result<Option<StatsValue>, StoreError> {
        self.get("stats", &keys::frame(job, frame))
    }

    /// Where the records written in `frame` of `job` lie in the sample log
    /// (`None`: the frame wrote none, or is not stored).
    pub fn frame_records_value(
        &self,
        job: u64,
        frame: u32,
    ) -> Result<Option<FrameRecordsValue>, StoreError> {
        self.get("records", &keys::frame(job, frame))
    }

    /// Checks that `records` value `v` (under `key`) can describe a block
    /// in a log of `committed` bytes: rkyv accepts any bytes of the right
    /// length for a struct of integers, so a damaged value is caught here,
    /// as a corrupt `records` value, before anything is read or allocated
    /// for it.
    fn check_records_value(
        &self,
        key: &[u8],
        v: &FrameRecordsValue,
        committed: u64,
    ) -> Result<(), StoreError> {
        let end = v.offset.checked_add(u64::from(v.stored_len));
        let max_raw = (v.count as usize)
            .saturating_mul(std::mem::size_of::<rkyv::Archived<RecordValue>>())
            .saturating_add(256);
        let problem = if v.count == 0 || v.count > MAX_BLOCK_RECORDS {
            Some(format!(
                "{} records (1..={MAX_BLOCK_RECORDS} expected)",
                v.count
            ))
        } else if v.first_id > v.last_id || v.last_id - v.first_id < u64::from(v.count - 1) {
            Some(format!(
                "{} records cannot have ids {}..={}",
                v.count, v.first_id, v.last_id
            ))
        } else if v.raw_len as usize > max_raw {
            Some(format!(
                "{} bytes before zstd for {} records (at most {max_raw})",
                v.raw_len, v.count
            ))
        } else if v.offset < samples::MAGIC.len() as u64 || end.is_none_or(|e| e > committed) {
            Some(format!(
                "its block, {} bytes at offset {}, lies outside the sample log's committed {} bytes",
                v.stored_len,
                v.offset,
                committed
            ))
        } else {
            None
        };
        match problem {
            Some(problem) => Err(self.corrupt("records", key, problem)),
            None => Ok(()),
        }
    }

    /// The records of the block `v` (the `records` value under `key`),
    /// read from the log and checked against `v`.
    fn record_block(
        &self,
        key: &[u8],
        v: &FrameRecordsValue,
    ) -> Result<Vec<RecordValue>, StoreError> {
        let in_log = |d: String| {
            self.log_error(format!(
                "records of {} at offset {}: {d}",
                keys::describe(key),
                v.offset
            ))
        };
        let log = self.lock_log();
        self.check_records_value(key, v, log.committed())?;
        let stored = log.read(v.offset, v.stored_len).map_err(in_log)?;
        drop(log);
        let raw = decompress(&stored, v.raw_len as usize).map_err(in_log)?;
        drop(stored);
        let block: RecordBlock = decode_value(&raw).map_err(in_log)?;
        let (job, frame) = keys::parse_frame(key).unwrap_or_default();
        if (block.job, block.frame) != (job, frame) {
            return Err(in_log(format!(
                "the block is job {} frame {}'s",
                block.job, block.frame
            )));
        }
        let ids_ok = block.records.windows(2).all(|w| w[0].id < w[1].id)
            && block.records.first().map_or(0, |r| r.id) == v.first_id
            && block.records.last().map_or(0, |r| r.id) == v.last_id;
        if block.records.len() != v.count as usize || !ids_ok {
            return Err(in_log(format!(
                "expected {} records, ids {}..={} increasing; found {}",
                v.count,
                v.first_id,
                v.last_id,
                block.records.len()
            )));
        }
        Ok(block.records)
    }

    /// Records written in `frame` of `job`, in id order.
    pub fn frame_records(&self, job: u64, frame: u32) -> Result<Vec<RecordValue>, StoreError> {
        let key = keys::frame(job, frame);
        match self.get::<FrameRecordsValue>("records", &key)? {
            Some(v) => self.record_block(&key, &v),
            None => Ok(Vec::new()),
        }
    }

    /// Every record version of `job`, in (frame, id) order, through `f`
    /// (streams: one frame's block at a time).
    pub fn for_each_record(
        &self,
        job: u64,
        mut f: impl FnMut(u32, RecordValue),
    ) -> Result<(), StoreError> {
        for item in self.records.scan_prefix(keys::job_prefix(job)) {
            let (k, v) = item.map_err(|e| StoreError::sled(&self.path, e))?;
            let (_, frame) = keys::parse_frame(&k)
                .ok_or_else(|| self.corrupt("records", &k, "malformed key"))?;
            let value: FrameRecordsValue = self.decode("records", &k, &v)?;
            for r in self.record_block(&k, &value)? {
                f(frame, r);
            }
        }
        Ok(())
    }

    /// The samples of record `id` written in `frame` of `job` (none if
    /// there is no such record), read from the sample log: the frame's
    /// record block, then the record's sample block.
    pub fn record_samples(
        &self,
        job: u64,
        frame: u32,
        id: u64,
    ) -> Result<Vec<PackedSample>, StoreError> {
        let key = keys::frame(job, frame);
        let Some(v) = self.get::<FrameRecordsValue>("records", &key)? else {
            return Ok(Vec::new());
        };
        self.check_records_value(&key, &v, self.sample_log_bytes())?;
        if !(v.first_id..=v.last_id).contains(&id) {
            return Ok(Vec::new());
        }
        let records = self.record_block(&key, &v)?;
        match records.binary_search_by_key(&id, |r| r.id) {
            Ok(i) => self.samples_of(&records[i], &keys::record(job, frame, id)),
            Err(_) => Ok(Vec::new()),
        }
    }

    /// The samples of record `r`, read from `frame`'s records of `job`
    /// ([`Self::frame_records`], [`Self::for_each_record`]): what
    /// [`Self::record_samples`] gives for its id, without reading the
    /// frame's record block again.
    pub fn samples_of_record(
        &self,
        job: u64,
        frame: u32,
        r: &RecordValue,
    ) -> Result<Vec<PackedSample>, StoreError> {
        self.samples_of(r, &keys::record(job, frame, r.id))
    }

    /// The samples of stored record `r` (`key` names it), read from the log.
    fn samples_of(&self, r: &RecordValue, key: &[u8]) -> Result<Vec<PackedSample>, StoreError> {
        if r.samples_count == 0 {
            return Ok(Vec::new());
        }
        let in_log = |d: String| {
            self.log_error(format!(
                "samples of {} at offset {}: {d}",
                keys::describe(key),
                r.samples_offset
            ))
        };
        let bytes = self
            .lock_log()
            .read(r.samples_offset, r.samples_len)
            .map_err(in_log)?;
        SampleBlock::unpack_bytes(&bytes, r.samples_count).map_err(in_log)
    }

    // ------------------------------------------------------------ state

    /// The head of job `job`'s carried method state, if any.
    pub fn state_head(&self, job: u64) -> Result<Option<StateHeadValue>, StoreError> {
        self.get("state", &keys::state_head(job))
    }

    /// Job `job`'s carried method state (as of [`Self::state_head`]'s
    /// frame): the head's method-wide bytes and every state record, in id
    /// order.
    pub fn load_state(&self, job: u64) -> Result<Option<crate::method::MethodState>, StoreError> {
        let Some(head) = self.state_head(job)? else {
            return Ok(None);
        };
        let mut records = Vec::new();
        for item in self.state.scan_prefix(keys::job_prefix(job)) {
            let (k, v) = item.map_err(|e| StoreError::sled(&self.path, e))?;
            if k.len() == 8 {
                continue; // the head
            }
            let (_, id) = keys::parse_state_record(&k)
                .ok_or_else(|| self.corrupt("state", &k, "malformed key"))?;
            let value: StateRecordValue = self.decode("state", &k, &v)?;
            records.push((id, value.data));
        }
        Ok(Some(crate::method::MethodState {
            frame: head.frame,
            global: head.global,
            records,
        }))
    }

    /// Forgets job `job`'s carried method state (a render that starts its
    /// chain over). The head goes first, so that a crash halfway leaves no
    /// head over partial records.
    pub fn clear_state(&self, job: u64) -> Result<(), StoreError> {
        self.state
            .remove(keys::state_head(job))
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()?;
        for key in self.state.scan_prefix(keys::job_prefix(job)).keys() {
            let key = key.map_err(|e| StoreError::sled(&self.path, e))?;
            self.state
                .remove(key)
                .map_err(|e| StoreError::sled(&self.path, e))?;
        }
        self.flush()
    }

    /// The error for a state [`crate::method::Method::restore_state`]
    /// refused: a corrupt value in `state`, naming its key.
    pub fn state_error(&self, job: u64, e: crate::method::StateError) -> StoreError {
        let key = match e.record {
            Some(id) => keys::state_record(job, id).to_vec(),
            None => keys::state_head(job).to_vec(),
        };
        self.corrupt("state", &key, e.detail)
    }

    /// Writes a raw value (tests use it to corrupt a store on purpose).
    #[doc(hidden)]
    pub fn raw_insert(&self, tree: &str, key: &[u8], value: &[u8]) -> Result<(), StoreError> {
        let t = self.tree(tree).expect("known tree");
        t.insert(key, value)
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()
    }
}

/// The sample log of the store at `path` as `meta` describes it (its
/// generation and committed length), cut back to that length, and the
/// generation; the leftovers of a compaction killed before or after its
/// switch are removed once the current log has opened.
fn open_sample_log(path: &Path, meta: &sled::Tree) -> Result<(u64, SampleLog), StoreError> {
    let meta_u64 = |key: &[u8]| {
        v2::read_meta_u64(meta, key).map_err(|detail| StoreError::Corrupt {
            path: path.to_owned(),
            tree: "meta",
            key: keys::describe(key),
            detail,
        })
    };
    let committed = meta_u64(keys::META_SAMPLES_LOG_LEN)?;
    let generation = meta_u64(keys::META_SAMPLES_LOG_GENERATION)?.unwrap_or(0);
    let log_error = |detail: String| StoreError::SampleLog {
        path: path.to_owned(),
        file: path.join(samples::file_name(generation)),
        detail,
    };
    let log = SampleLog::open(path, generation, committed).map_err(log_error)?;
    samples::remove_stale_logs(path, generation).map_err(log_error)?;
    Ok((generation, log))
}

/// Fields of `spec` that differ from the stored job's (name and frame range
/// aside). Every field is named, so a field added to [`JobSpec`] does not
/// compile until it is compared here.
fn job_differences(stored: &JobSpec, spec: &JobSpec) -> Vec<String> {
    let JobSpec {
        name: _,
        scene,
        scene_hash,
        method,
        settings,
        width,
        height,
        spp,
        fps,
        seed,
        same_pattern,
        frame_start: _,
        frame_end: _,
    } = spec;
    let mut d = Vec::new();
    let mut check = |name: &str, same: bool, stored: String, given: String| {
        if !same {
            d.push(format!("{name} (stored {stored}, given {given})"));
        }
    };
    check(
        "scene",
        &stored.scene == scene,
        stored.scene.clone(),
        scene.clone(),
    );
    check(
        "scene hash",
        same_scene_hash(&stored.scene_hash, scene_hash),
        stored.scene_hash.clone(),
        scene_hash.clone(),
    );
    check(
        "method",
        &stored.method == method,
        stored.method.clone(),
        method.clone(),
    );
    check(
        "method settings",
        same_settings(&stored.settings, settings),
        stored.settings.clone(),
        settings.clone(),
    );
    check(
        "size",
        (stored.width, stored.height) == (*width, *height),
        format!("{}x{}", stored.width, stored.height),
        format!("{width}x{height}"),
    );
    check(
        "spp",
        stored.spp == *spp,
        stored.spp.to_string(),
        spp.to_string(),
    );
    check(
        "fps",
        stored.fps.to_bits() == fps.to_bits(),
        stored.fps.to_string(),
        fps.to_string(),
    );
    check(
        "seed",
        stored.seed == *seed,
        stored.seed.to_string(),
        seed.to_string(),
    );
    check(
        "same-pattern",
        stored.same_pattern == *same_pattern,
        stored.same_pattern.to_string(),
        same_pattern.to_string(),
    );
    d
}

/// Settings are serde JSON: equal as JSON values (text that is not JSON,
/// as in tests, compares as text).
fn same_settings(stored: &str, given: &str) -> bool {
    match (
        serde_json::from_str::<serde_json::Value>(stored),
        serde_json::from_str::<serde_json::Value>(given),
    ) {
        (Ok(a), Ok(b)) => a == b,
        _ => stored == given,
    }
}

/// Scene hashes are equal, or the stored one is a schema-1 hash (suffix
/// [`v1::LEGACY_HASH_SUFFIX`], external files not hashed) of the same file.
fn same_scene_hash(stored: &str, given: &str) -> bool {
    stored == given
        || stored
            .strip_suffix(v1::LEGACY_HASH_SUFFIX)
            .is_some_and(|main| given.split('+').next() == Some(main))
}

/// Checks the directory before sled touches it. Returns whether a store
/// already existed. A directory that has files but not sled's `conf` and
/// `db` is refused, so that sled never "repairs" something that is not its
/// own.
fn check_directory(path: &Path, create: bool) -> Result<bool, StoreError> {
    let not_a_store = |detail: String| StoreError::NotAStore {
        path: path.to_owned(),
        detail,
    };
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if create {
                Ok(false)
            } else {
                Err(StoreError::Missing {
                    path: path.to_owned(),
                })
            }
        }
        Err(e) => Err(not_a_store(e.to_string())),
        Ok(m) if !m.is_dir() => Err(not_a_store("not a directory".into())),
        Ok(_) => {
            let entries: Vec<String> = std::fs::read_dir(path)
                .map_err(|e| not_a_store(e.to_string()))?
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            if entries.is_empty() {
                return if create {
                    Ok(false)
                } else {
                    Err(StoreError::Missing {
                        path: path.to_owned(),
                    })
                };
            }
            for needed in ["conf", "db"] {
                if !entries.iter().any(|e| e == needed) {
                    return Err(not_a_store(format!(
                        "no `{needed}` file (found: {})",
                        entries.join(", ")
                    )));
                }
            }
            let db_len = std::fs::metadata(path.join("db"))
                .map(|m| m.len())
                .unwrap_or(0);
            if db_len == 0 {
                return Err(not_a_store("empty `db` file (truncated store?)".into()));
            }
            Ok(true)
        }
    }
}

/// How long to retry a lock held by someone else: sled releases its lock
/// from background threads shortly after a `Db` is dropped, so a store
/// closed a moment ago (by this process or one that just exited) can still
/// look locked.
const LOCK_WAIT: std::time::Duration = std::time::Duration::from_millis(1500);

/// `sled::open`, with its errors (and any panic on a damaged directory)
/// turned into [`StoreError`]s.
fn open_sled(path: &Path) -> Result<sled::Db, StoreError> {
    let start = std::time::Instant::now();
    let mut cleaned = false;
    loop {
        match open_sled_once(path) {
            Err(StoreError::Locked { .. }) if start.elapsed() < LOCK_WAIT => {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            Err(StoreError::NotAStore { .. }) if !cleaned && remove_unfinished_snapshots(path) => {
                cleaned = true;
            }
            other => return other,
        }
    }
}

/// sled 0.34 writes a snapshot to `snap.N.generating` and then renames it
/// to `snap.N`, but on open it reads the greatest `snap.*` file name,
/// `.generating` included (sled issue #1527): a process killed while
/// writing a snapshot — which sled also does while it opens a store after
/// a crash — leaves a store sled calls corrupt. Such a file is never
/// complete (the rename is what finishes it), and the snapshot only speeds
/// up recovery, which sled can do from its log alone, so removing it
/// recovers the store. Called only after sled refused the store, having
/// taken its lock first: no other process is writing a snapshot. Returns
/// whether it removed any.
fn remove_unfinished_snapshots(path: &Path) -> bool {
    let Ok(entries) = std::fs::read_dir(path) else {
        return false;
    };
    let mut removed = false;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with("snap.") && name.ends_with(".generating") {
            removed |= std::fs::remove_file(entry.path()).is_ok();
        }
    }
    removed
}

fn open_sled_once(path: &Path) -> Result<sled::Db, StoreError> {
    let config = sled::Config::new().path(path).cache_capacity(CACHE_BYTES);
    let opened = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| config.open()));
    match opened {
        Ok(Ok(db)) => Ok(db),
        Ok(Err(sled::Error::Io(e))) if e.to_string().contains("could not acquire lock") => {
            Err(StoreError::Locked {
                path: path.to_owned(),
                detail: e.to_string(),
            })
        }
        Ok(Err(sled::Error::Corruption { .. })) | Ok(Err(sled::Error::Unsupported(_))) => {
            Err(StoreError::NotAStore {
                path: path.to_owned(),
                detail: "sled reports a corrupt or unsupported database".into(),
            })
        }
        Ok(Err(e)) => Err(StoreError::sled(path, e)),
        Err(_) => Err(StoreError::NotAStore {
            path: path.to_owned(),
            detail: "sled could not read the database (damaged files)".into(),
        }),
    }
}

impl RecordCommit {
    /// A record created or changed in `frame`, with its samples in their
    /// stored form.
    pub fn from_record(
        record: &crate::cache::IrradianceRecord,
        samples: SampleBlock,
        strata: crate::cache::gather::Strata,
        frame: u32,
    ) -> Self {
        let v = |v: glam::Vec3| v.to_array();
        let has = !samples.is_empty();
        RecordCommit {
            record: RecordValue {
                id: record.id,
                created_frame: record.created_frame,
                last_frame: frame,
                position: v(record.position),
                normal: v(record.normal),
                irradiance: v(record.irradiance),
                grad_translation: record.grad_translation.map(v),
                grad_rotation: record.grad_rotation.map(v),
                radius: record.radius,
                object: record.object,
                strata_theta: if has { strata.theta } else { 0 },
                strata_phi: if has { strata.phi } else { 0 },
                // Filled in by `Store::commit_frame`.
                samples_count: 0,
                samples_offset: 0,
                samples_len: 0,
            },
            samples,
        }
    }
}
