//! The persistent space-time store (DESIGN.md "The store"): a sled 0.34
//! database directory with one tree per kind — `meta`, `records`,
//! `sources`, `movies`, `frames`, `jobs`, `stats`, `state` — and, beside it in the
//! same directory, the append-only sample log `samples.log` (after a
//! [`compact`]ion, `samples.N.log`: `meta` names it) ([`samples`]).
//!
//! - Keys: big-endian, built only by [`keys`] (layout there and in
//!   `migrations/0001_initial.md`, `migrations/0002_state_and_identity.md`,
//!   `migrations/0003_sample_log.md`, `migrations/0004_record_blocks.md`,
//!   `migrations/0005_log_generations.md`, `migrations/0006_movies.md`,
//!   `migrations/0007_radiance_records_in_state.md`,
//!   `migrations/0008_frame_footprint.md`,
//!   `migrations/0009_record_sources.md`,
//!   `migrations/0010_tcg_state_refers_to_samples.md`,
//!   `migrations/0011_trc_state_without_spatial_gradient_changes.md`,
//!   `migrations/0012_trc_state_without_derived_change.md`).
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
//!   synced, then one sled transaction over `frames`, `records`,
//!   `sources`, `movies`, `stats`, `state`, `jobs` and `meta` (the log's
//!   committed length), then `flush`;
//!   the frame counts as acknowledged only after that returns. A log tail
//!   beyond the committed length (a crash in between) is cut off when the
//!   store is opened.
//! - `state` holds the cache a stateful method (`trc`, `tcg`) carries to
//!   the next frame, as of the job's last frame: each frame writes only
//!   its changes (records put and removed, and the head), and a resume
//!   loads it ([`Store::load_state`]) instead of rendering the finished
//!   frames again. A `tcg` record's state refers to the samples its
//!   version in the same frame's record block holds
//!   ([`Store::frame_record_samples`]): each frame stores them all.
//! - Bytes of the log no value references any more (a job restarted with
//!   `--force`, a frame written again) stay until [`compact`] rewrites the
//!   log without them.
//! - The schema version lives in `meta`; see [`migrate`].
//!
//! `Store`'s methods are grouped by what they work on: opening and the
//! trees here, `jobs`, `frames` (the atomic commit of a frame), `records`
//! (a frame's records and their samples) and `state` (the carried cache).

pub mod compact;
mod frames;
pub mod inspect;
mod jobs;
pub mod keys;
mod meta;
pub mod migrate;
mod records;
pub mod rgbe;
pub mod samples;
pub mod schema;
mod state;
mod tail;
pub mod v1;
pub mod v10;
pub mod v11;
pub mod v2;
pub mod v3;
pub mod v4;
pub mod v5;
pub mod v6;
pub mod v7;
pub mod v8;
pub mod v9;

use meta::read_meta_u64;
use rkyv::api::high::{HighDeserializer, HighSerializer, HighValidator};
use rkyv::bytecheck::CheckBytes;
use rkyv::rancor;
use rkyv::ser::allocator::ArenaHandle;
use rkyv::util::AlignedVec;
use samples::{compress, SampleLog};
use schema::{FrameRecordsValue, JobValue, RecordBlock};
use std::path::{Path, PathBuf};

pub use frames::{FrameCommit, RecordCommit, StateCommit};
pub use jobs::{job_differs_text, JobAttempt, SceneChanged};
pub use rgbe::PackedSample;
pub use samples::SampleBlock;
pub use schema::JobSpec;

/// The trees, in the order `inspect` lists them.
pub const TREES: [&str; 8] = [
    "meta", "jobs", "frames", "stats", "records", "sources", "state", "movies",
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
    #[error("store {}: locked by another process (is a render, inspect, compact or `radcache serve` on it still running? A store serves one process at a time: to watch a render's cache while it runs, run it under `radcache serve` and read its /stats and /records; to work on a store a server holds, use its HTTP API or stop it)", path.display())]
    Locked { path: PathBuf },
    #[error("store {}: not a radcache store: {detail}", path.display())]
    NotAStore { path: PathBuf, detail: String },
    /// A radcache store whose database files sled cannot read: damaged
    /// (bits flipped, a file cut short), not merely another program's.
    #[error("store {}: damaged: {detail}; restore the directory from a copy, or remove it to start over (its jobs are lost)", path.display())]
    Damaged { path: PathBuf, detail: String },
    /// The store's directory could not be opened or made (a parent that
    /// cannot be created, no permission).
    #[error("store {}: cannot open or create the store directory: {detail}; check the path given as the store (--db)", path.display())]
    Open { path: PathBuf, detail: String },
    /// The store could not be opened for want of room: sled writes as it
    /// opens a store (its files, a recovery), so the path is not at fault.
    #[error("store {}: the disk is full: {detail}; sled needs room to open a store (even to read it): free some space, or raise the quota, and run it again", path.display())]
    DiskFull { path: PathBuf, detail: String },
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
    /// A job of that name exists with another scene content (its scene
    /// file, or one it references, changed since: `scene_changed`) or other
    /// settings (its `differences`, named), so it is not resumed.
    #[error("store {}: job {job:?}: {}; use another --job name, or --force to start it over", path.display(), jobs::job_differs_text(scene_changed.as_deref(), differences, "stored", |d| format!("it exists with other settings: {d}")))]
    JobDiffers {
        path: PathBuf,
        job: String,
        scene_changed: Option<Box<SceneChanged>>,
        /// The settings that differ, named (empty when only the scene's
        /// content does).
        differences: String,
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
    /// Any other error of sled's. Not marked as the error's source: the
    /// message holds its text, which a chain of causes would print twice.
    #[error("store {}: {}", path.display(), sled_text(error))]
    Sled { path: PathBuf, error: sled::Error },
}

/// sled's error as text for people: an I/O error as the OS words it
/// (without sled's "IO error: " prefix). (Corruption is
/// [`StoreError::Damaged`].)
fn sled_text(error: &sled::Error) -> String {
    match error {
        sled::Error::Io(e) => format!("I/O error: {}", io_text(e)),
        other => other.to_string(),
    }
}

/// An I/O error as the OS words it: "No space left on device (os error
/// 28)". sled hands on copies of its I/O errors (its `Clone`) whose text
/// is the original's Debug form, `Os { code: 28, kind: StorageFull, … }`:
/// such an error is worded from its code, or its kind.
fn io_text(e: &std::io::Error) -> String {
    let debug = e.get_ref().map(ToString::to_string).unwrap_or_default();
    match os_code(e) {
        Some(code) => std::io::Error::from_raw_os_error(code).to_string(),
        None if debug.starts_with("Kind(") => std::io::Error::from(e.kind()).to_string(),
        None => e.to_string(),
    }
}

/// The OS error code of `e`, or of the original whose Debug form is its
/// text ([`io_text`]).
fn os_code(e: &std::io::Error) -> Option<i32> {
    e.raw_os_error().or_else(|| {
        let debug = e.get_ref()?.to_string();
        debug
            .strip_prefix("Os { code: ")?
            .split(',')
            .next()?
            .parse()
            .ok()
    })
}

/// Whether `e` says the disk (or the user's quota on it) is full.
fn is_disk_full(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::{QuotaExceeded, StorageFull};
    let kind = os_code(e).map_or(e.kind(), |c| std::io::Error::from_raw_os_error(c).kind());
    matches!(kind, StorageFull | QuotaExceeded)
}

impl StoreError {
    /// sled's `source` met at `path`. Corruption is found where a read
    /// reaches it, not only as the store opens: it is [`Self::Damaged`]
    /// wherever, with what to do about it.
    fn sled(path: &Path, source: sled::Error) -> Self {
        match source {
            sled::Error::Corruption { .. } => StoreError::Damaged {
                path: path.to_owned(),
                detail: CORRUPT_FILES.into(),
            },
            error => StoreError::Sled {
                path: path.to_owned(),
                error,
            },
        }
    }
}

/// What [`StoreError::Damaged`] says of data sled found corrupt (its own
/// text of it is debug output, `file offset None backtrace ()`, and where
/// it found the damage says nothing to act on).
const CORRUPT_FILES: &str =
    "sled found corrupt data in its database files (`db`, `conf` or a `snap.*` snapshot)";

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
    sources: sled::Tree,
    state: sled::Tree,
    movies: sled::Tree,
    /// The sample log's generation (`meta.samples_log_generation`): its
    /// file is [`samples::file_name`] of it.
    log_generation: u64,
    /// The sample log; locked over a whole [`Store::commit_frame`] (its
    /// appends and the transaction that commits them).
    log: std::sync::Mutex<SampleLog>,
}

/// How long dropping a [`Store`] waits for sled's last flush.
const LAST_FLUSH_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

impl Drop for Store {
    /// sled flushes when its last handle drops, and after a write of its own
    /// failed (a full disk) that flush waits for ever: the process hung,
    /// its error unprinted, the store locked. So the flush is tried here
    /// in a thread of its own, for `LAST_FLUSH_WAIT` (10 s); if it fails or does
    /// not end, the handles are leaked rather than dropped (the process is
    /// ending, or the store's owner gave it up). Nothing committed is lost:
    /// every write of the store flushes before it returns.
    fn drop(&mut self) {
        let db = self.db.clone();
        let (done, flushed) = std::sync::mpsc::channel();
        let spawned = std::thread::Builder::new()
            .name("store-last-flush".into())
            .spawn(move || {
                let flushed = db.flush().is_ok();
                // Before it says so: the store's own handles, dropped once
                // it has, must be the last, so that sled's lock goes with
                // them (a store opened again at once would find it held).
                drop(db);
                let _ = done.send(flushed);
            });
        if spawned.is_ok() && flushed.recv_timeout(LAST_FLUSH_WAIT) == Ok(true) {
            return;
        }
        eprintln!(
            "warning: store {}: its last flush failed or did not end within {} s \
             (is the disk full?); what it committed was flushed already",
            self.path.display(),
            LAST_FLUSH_WAIT.as_secs()
        );
        std::mem::forget(self.db.clone());
        for tree in [
            &self.meta,
            &self.jobs,
            &self.frames,
            &self.stats,
            &self.records,
            &self.sources,
            &self.state,
            &self.movies,
        ] {
            std::mem::forget(tree.clone());
        }
    }
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

/// `bytes` copied where an rkyv archive may be read from: sled values
/// carry no alignment guarantee, and rkyv needs 16.
pub(crate) fn aligned(bytes: &[u8]) -> AlignedVec<16> {
    let mut aligned = AlignedVec::<16>::with_capacity(bytes.len());
    aligned.extend_from_slice(bytes);
    aligned
}

/// Reads an rkyv archive (validated) of a `T`.
pub(crate) fn decode_value<T>(bytes: &[u8]) -> Result<T, String>
where
    T: rkyv::Archive,
    T::Archived: for<'a> CheckBytes<HighValidator<'a, rancor::Error>>
        + rkyv::Deserialize<T, HighDeserializer<rancor::Error>>,
{
    rkyv::from_bytes::<T, rancor::Error>(&aligned(bytes)).map_err(|e| e.to_string())
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

/// Whether opening a store at `path` makes a new one: nothing there, or an
/// empty directory. (A directory a killed creation left is also made anew,
/// unannounced: it was meant to be a store.)
pub fn no_store_at(path: &std::path::Path) -> bool {
    match std::fs::read_dir(path) {
        Ok(mut entries) => entries.next().is_none(),
        Err(e) => e.kind() == std::io::ErrorKind::NotFound,
    }
}

/// The line that says a new store is made at `path` (`render --job` says
/// it once the store is made; `serve` once it listens, before it makes
/// the store).
pub fn new_store_note(path: &std::path::Path) -> String {
    format!(
        "note: no store at {}: a new, empty one is made there (to use an existing store, give its path as --db)",
        path.display()
    )
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
            None if existing => {
                check_unversioned(path, &db, create)?;
                None
            }
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
            sources: tree("sources")?,
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
            "sources" => &self.sources,
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

    /// Whether the sample log holds, past its committed length, frames the
    /// database lost ([`SampleLog::look_for_lost_frames`]): the store then
    /// refuses jobs and compaction (deleting a job, which appends nothing, still works).
    pub fn sample_log_holds_lost_frames(&self) -> bool {
        self.lock_log().holds_lost_frames()
    }

    /// Refuses to write to a store whose sample log holds frames its
    /// database lost ([`SampleLog::look_for_lost_frames`]): a write would cut
    /// them off. Reading it (`inspect`) goes on.
    pub(crate) fn refuse_if_frames_lost(&self) -> Result<(), StoreError> {
        if !self.sample_log_holds_lost_frames() {
            return Ok(());
        }
        Err(StoreError::Damaged {
            path: self.path.clone(),
            detail: format!(
                "its sample log {}: {}",
                self.sample_log_file().display(),
                samples::LOST_FRAMES
            ),
        })
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

    /// `key` as an error names it, its job by name ([`keys::describe_named`]).
    pub(crate) fn describe_key(&self, key: &[u8]) -> String {
        keys::describe_named(key, |id| self.job_name_of(id))
    }

    /// The name of the job of store id `id`, for an error message: read
    /// leniently, passing over a job value that does not decode (which
    /// the error being described may be about).
    fn job_name_of(&self, id: u64) -> Option<String> {
        self.jobs.iter().flatten().find_map(|(_, v)| {
            let job: JobValue = decode_value(&v).ok()?;
            (job.id == id).then(|| job.name.clone())
        })
    }

    fn corrupt(&self, tree: &'static str, key: &[u8], detail: impl ToString) -> StoreError {
        StoreError::Corrupt {
            path: self.path.clone(),
            tree,
            key: self.describe_key(key),
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

    /// Writes a raw value (tests use it to corrupt a store on purpose).
    #[doc(hidden)]
    pub fn raw_insert(&self, tree: &str, key: &[u8], value: &[u8]) -> Result<(), StoreError> {
        let t = self.tree(tree).expect("known tree");
        t.insert(key, value)
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()
    }
}

/// Refuses an existing sled database without a schema version unless it
/// is one that a `radcache` killed while creating it left behind: nothing
/// in any tree and no sample in any log. Anything else is either a store
/// whose database sled could not recover (it then opens with every tree
/// empty, and taking it over would throw away its sample log) or another
/// program's database; neither is ours to change. Commands that only read
/// a store (`create` false) never take one over.
fn check_unversioned(path: &Path, db: &sled::Db, create: bool) -> Result<(), StoreError> {
    let refuse = |detail: String| {
        Err(StoreError::NotAStore {
            path: path.to_owned(),
            detail,
        })
    };
    if !create {
        if let Some((name, len)) = sample_log_with_samples(path) {
            return Err(StoreError::Damaged {
                path: path.to_owned(),
                detail: format!(
                    "the sled database holds no schema version, but its sample log {name} \
                     holds {len} bytes (sled recovered nothing from the database); nothing \
                     was changed"
                ),
            });
        }
        return refuse(
            "the sled database holds no schema version (damaged, or not radcache's); \
             nothing was changed"
                .into(),
        );
    }
    for name in db.tree_names() {
        let tree = db.open_tree(&name).map_err(|e| StoreError::sled(path, e))?;
        if !tree.is_empty() {
            return refuse(format!(
                "the sled database holds no schema version but its tree `{}` is not \
                 empty (another program's database?); nothing was changed",
                String::from_utf8_lossy(&name)
            ));
        }
    }
    if let Err(e) = std::fs::read_dir(path) {
        return refuse(e.to_string());
    }
    if let Some((name, len)) = sample_log_with_samples(path) {
        return Err(StoreError::Damaged {
            path: path.to_owned(),
            detail: format!(
                "the sled database holds no schema version and no records, but its \
                 sample log {name} holds {len} bytes (sled recovered nothing from the \
                 database); nothing was changed"
            ),
        });
    }
    Ok(())
}

/// A sample log in the directory `path` that holds samples (more than its
/// header): its file name and length.
fn sample_log_with_samples(path: &Path) -> Option<(String, u64)> {
    std::fs::read_dir(path)
        .ok()?
        .filter_map(Result::ok)
        .find_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            let len = entry.metadata().map_or(0, |m| m.len());
            let samples =
                samples::parse_file_name(&name).is_some() && len > samples::MAGIC.len() as u64;
            samples.then_some((name, len))
        })
}

/// The sample log of the store at `path` as `meta` describes it (its
/// generation and committed length), cut back to that length, and the
/// generation; the leftovers of a compaction killed before or after its
/// switch are removed once the current log has opened.
fn open_sample_log(path: &Path, meta: &sled::Tree) -> Result<(u64, SampleLog), StoreError> {
    let meta_u64 = |key: &[u8]| {
        read_meta_u64(meta, key).map_err(|detail| StoreError::Corrupt {
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
    let mut log = SampleLog::open(path, generation, committed).map_err(log_error)?;
    (log.look_for_lost_frames())
        .map_err(|e| log_error(format!("cannot read past its committed length: {e}")))?;
    samples::remove_stale_logs(path, generation).map_err(log_error)?;
    Ok((generation, log))
}

/// Checks the directory before sled touches it. Returns whether a store
/// already existed. A directory that has files but not sled's `conf` and
/// `db` is refused, so that sled never "repairs" something that is not its
/// own, unless they are the beginnings of a store whose creation was cut
/// off ([`is_unfinished_creation`]): that one is made as a new store.
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
        // Not a verdict on what is there (permission denied, say).
        Err(e) => Err(StoreError::Open {
            path: path.to_owned(),
            detail: e.to_string(),
        }),
        Ok(m) if !m.is_dir() => Err(not_a_store("not a directory".into())),
        Ok(_) => {
            let entries: Vec<String> = std::fs::read_dir(path)
                .map_err(|e| StoreError::Open {
                    path: path.to_owned(),
                    detail: e.to_string(),
                })?
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            if entries.is_empty() || is_unfinished_creation(path, &entries) {
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

/// Whether the directory holds only what a `radcache` killed while it
/// created the store leaves: sled makes `blobs/`, then writes `conf`, then
/// creates an empty `db`, whose first bytes it writes from a background
/// thread, possibly after the store has made its (empty) sample log. An
/// empty `blobs/`, at most `conf`, an empty `db` and a sample log without
/// a sample stored nothing: it is a store still to be made (and sled
/// makes it, under its lock, from what is there). A store whose `db` was
/// emptied after it stored samples is refused.
fn is_unfinished_creation(path: &Path, entries: &[String]) -> bool {
    let len = |name: &str| std::fs::metadata(path.join(name)).map(|m| (m.is_file(), m.len()));
    let blobs_empty = std::fs::read_dir(path.join("blobs")).is_ok_and(|mut d| d.next().is_none());
    blobs_empty
        && entries.iter().all(|name| match name.as_str() {
            "blobs" | "conf" => true,
            "db" => len(name).is_ok_and(|l| l == (true, 0)),
            _ if samples::parse_file_name(name).is_some() => {
                len(name).is_ok_and(|(file, l)| file && l <= samples::MAGIC.len() as u64)
            }
            _ => false,
        })
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
            Err(StoreError::NotAStore { .. } | StoreError::Damaged { .. })
                if !cleaned && remove_unfinished_snapshots(path) =>
            {
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
        // sled's message (the OS error's Debug form) adds nothing to ours.
        Ok(Err(sled::Error::Io(e))) if e.to_string().contains("could not acquire lock") => {
            Err(StoreError::Locked {
                path: path.to_owned(),
            })
        }
        Ok(Err(e @ sled::Error::Corruption { .. })) => Err(StoreError::sled(path, e)),
        Ok(Err(sled::Error::Unsupported(e))) => Err(StoreError::NotAStore {
            path: path.to_owned(),
            detail: format!("sled cannot open the database (damaged, or not radcache's): {e}"),
        }),
        Ok(Err(sled::Error::Io(e))) => Err(open_io_error(path, &e)),
        Ok(Err(e)) => Err(StoreError::sled(path, e)),
        Err(_) => Err(StoreError::Damaged {
            path: path.to_owned(),
            detail: "sled could not read its database files".into(),
        }),
    }
}

/// An I/O error of sled's as it opened the store at `path`: the directory
/// (or a parent of it) could not be made or opened, or there is no room
/// for what sled writes as it opens (the path is then fine).
fn open_io_error(path: &Path, e: &std::io::Error) -> StoreError {
    let (path, detail) = (path.to_owned(), io_text(e));
    match is_disk_full(e) {
        true => StoreError::DiskFull { path, detail },
        false => StoreError::Open { path, detail },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A full disk, however sled hands the error on (the OS's, or its
    /// copy whose text is the Debug form), reads as the OS words it, and
    /// opening on it says the disk is full, not to check the path.
    #[test]
    fn disk_full_reads_as_the_os_words_it() {
        let full = || std::io::Error::from_raw_os_error(28);
        let copied = sled::Error::Io(full()).clone();
        for error in [sled::Error::Io(full()), copied] {
            let text = StoreError::sled(Path::new("st"), error).to_string();
            assert_eq!(
                text,
                "store st: I/O error: No space left on device (os error 28)"
            );
        }
        let sled::Error::Io(copied) = sled::Error::Io(full()).clone() else {
            unreachable!()
        };
        assert_eq!(io_text(&copied), "No space left on device (os error 28)");
        let kind_only = sled::Error::Io(std::io::ErrorKind::NotFound.into()).clone();
        let sled::Error::Io(kind_only) = kind_only else {
            unreachable!()
        };
        assert_eq!(io_text(&kind_only), "entity not found");
        let other = std::io::Error::other("could not acquire lock");
        assert_eq!(io_text(&other), "could not acquire lock");
        for e in [full(), copied, std::io::Error::from_raw_os_error(122)] {
            let text = open_io_error(Path::new("st"), &e).to_string();
            assert!(text.contains(": the disk is full: "), "{text}");
            assert!(text.contains("sled needs room to open a store"), "{text}");
            assert!(!text.contains("check the path"), "{text}");
        }
        let denied = std::io::Error::from_raw_os_error(13);
        let text = open_io_error(Path::new("st"), &denied).to_string();
        assert!(
            text.contains("Permission denied (os error 13); check the path"),
            "{text}"
        );
    }

    /// Corruption sled finds in a read after the store opened (bits
    /// flipped in `db` where opening does not look) says the store is
    /// damaged and what to do, as it does when opening finds it.
    #[test]
    fn corruption_found_after_opening_is_damage() {
        let corrupt = sled::Error::Corruption { at: None, bt: () };
        let error = StoreError::sled(Path::new("st"), corrupt);
        assert!(matches!(error, StoreError::Damaged { .. }), "{error:?}");
        assert_eq!(
            error.to_string(),
            format!(
                "store st: damaged: {CORRUPT_FILES}; restore the directory from a copy, or \
                 remove it to start over (its jobs are lost)"
            )
        );
        let other = StoreError::sled(Path::new("st"), sled::Error::ReportableBug("x".into()));
        assert!(matches!(other, StoreError::Sled { .. }), "{other:?}");
    }
}
