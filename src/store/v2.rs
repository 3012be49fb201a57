//! Schema 2 (`migrations/0002_state_and_identity.md`; schema 1 had the
//! same `records` and `samples` values): the value types that schema 3
//! changed, kept to read a version-2 store in the 0002 → 0003 migration
//! (`migrations/0003_sample_log.md`), which moves every record's samples
//! out of the `samples` tree, and every frame's EXR file out of its
//! `frames` value, into the sample log.

use super::meta::read_meta_u64;
use super::samples::{SampleLog, FILE_NAME as LOG_FILE};
use super::{encode, keys, schema};
use rkyv::{Archive, Deserialize, Serialize};
use std::ops::Bound;
use std::path::Path;

/// Schema-1 and -2 `records` value (no sample location: the samples were
/// in the `samples` tree under the same key).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RecordValue {
    pub id: u64,
    pub created_frame: u32,
    pub last_frame: u32,
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub irradiance: [f32; 3],
    pub grad_translation: [[f32; 3]; 3],
    pub grad_rotation: [[f32; 3]; 3],
    pub radius: f32,
    pub object: u32,
    pub strata_theta: u32,
    pub strata_phi: u32,
}

/// Schema-1 and -2 `frames` value: the EXR file inside it.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FrameValue {
    pub width: u32,
    pub height: u32,
    pub exr_len: u64,
    pub exr_zstd: Vec<u8>,
}

/// Schema-1 and -2 `samples` value under `job · frame · record id`: the
/// record's `count` samples, the bytes of a
/// [`super::samples::SampleBlock`].
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SamplesValue {
    pub count: u32,
    pub packed_zstd: Vec<u8>,
}

impl RecordValue {
    /// The schema-2 form of a record (its sample location dropped).
    pub fn from_v3(r: &schema::RecordValue) -> Self {
        RecordValue {
            id: r.id,
            created_frame: r.created_frame,
            last_frame: r.last_frame,
            position: r.position,
            normal: r.normal,
            irradiance: r.irradiance,
            grad_translation: r.grad_translation,
            grad_rotation: r.grad_rotation,
            radius: r.radius,
            object: r.object,
            strata_theta: r.strata_theta,
            strata_phi: r.strata_phi,
        }
    }

    /// The schema-3 record, its samples at `(count, offset, len)`.
    fn to_v3(&self, count: u32, offset: u64, len: u32) -> schema::RecordValue {
        schema::RecordValue {
            id: self.id,
            created_frame: self.created_frame,
            last_frame: self.last_frame,
            position: self.position,
            normal: self.normal,
            irradiance: self.irradiance,
            grad_translation: self.grad_translation,
            grad_rotation: self.grad_rotation,
            radius: self.radius,
            object: self.object,
            strata_theta: self.strata_theta,
            strata_phi: self.strata_phi,
            samples_count: count,
            samples_offset: offset,
            samples_len: len,
        }
    }
}

/// Values converted per transaction of the migration.
const BATCH: usize = 1024;

/// Migration 0002 → 0003 (`migrations/0003_sample_log.md`): in batches
/// of `BATCH` records in key order, appends each record's samples to
/// `samples.log` (synced), then in one transaction over `records`,
/// `samples` and `meta` rewrites the records with their sample location,
/// removes their `samples` values and records the log's committed length
/// and the last key converted (`meta.migrate_0003_through`); then the same
/// for `frames`, their EXR files (`meta.migrate_0003_frames_through`); at
/// the end drops the `samples` tree. A crash mid-step resumes after the
/// last batch committed (the log's uncommitted tail is cut off first).
pub fn migrate_to_v3(db: &sled::Db, dir: &Path) -> Result<(), String> {
    migrate_to_v3_batches(db, dir, BATCH, None)
}

/// [`migrate_to_v3`] in batches of `batch` values, stopping after
/// `max_batches` of them if given (what a crash after that batch leaves:
/// tests resume from it).
#[doc(hidden)]
pub fn migrate_to_v3_batches(
    db: &sled::Db,
    dir: &Path,
    batch: usize,
    max_batches: Option<usize>,
) -> Result<(), String> {
    let tree = |name: &str| db.open_tree(name).map_err(|e| e.to_string());
    let (meta, records, frames, samples) = (
        tree("meta")?,
        tree("records")?,
        tree("frames")?,
        tree("samples")?,
    );
    let committed = read_meta_u64(&meta, keys::META_SAMPLES_LOG_LEN)?;
    // Generation 0: logs of other generations came with schema 5.
    let mut log = SampleLog::open(dir, 0, committed).map_err(|e| format!("{LOG_FILE}: {e}"))?;
    let mut budget = max_batches.unwrap_or(usize::MAX);
    let log_err = |e: std::io::Error| format!("{LOG_FILE}: {e}");
    // Records: their samples into the log, their `samples` values removed.
    let records_done = convert_tree(
        db,
        (&meta, &records, &samples),
        keys::META_MIGRATE_0003_THROUGH,
        &mut log,
        batch,
        &mut budget,
        |k, v, log| {
            let old: RecordValue = super::decode_value(v)
                .map_err(|e| format!("tree `records` key {}: {e}", keys::describe(k)))?;
            let (count, offset, len) = match samples.get(k).map_err(|e| e.to_string())? {
                Some(sv) => {
                    let s: SamplesValue = super::decode_value(&sv)
                        .map_err(|e| format!("tree `samples` key {}: {e}", keys::describe(k)))?;
                    if s.count == 0 {
                        (0, 0, 0)
                    } else {
                        let offset = log.append(&s.packed_zstd).map_err(log_err)?;
                        (s.count, offset, s.packed_zstd.len() as u32)
                    }
                }
                None => (0, 0, 0),
            };
            Ok((encode(&old.to_v3(count, offset, len)), true))
        },
    )?;
    // Frames: their EXR files into the log.
    let frames_done = records_done
        && convert_tree(
            db,
            (&meta, &frames, &samples),
            keys::META_MIGRATE_0003_FRAMES_THROUGH,
            &mut log,
            batch,
            &mut budget,
            |k, v, log| {
                let old: FrameValue = super::decode_value(v)
                    .map_err(|e| format!("tree `frames` key {}: {e}", keys::describe(k)))?;
                let offset = log.append(&old.exr_zstd).map_err(log_err)?;
                let new = schema::FrameValue {
                    width: old.width,
                    height: old.height,
                    exr_len: old.exr_len,
                    exr_offset: offset,
                    exr_stored_len: old.exr_zstd.len() as u32,
                };
                Ok((encode(&new), false))
            },
        )?;
    if !frames_done {
        return Ok(()); // stopped after `max_batches`
    }
    if read_meta_u64(&meta, keys::META_SAMPLES_LOG_LEN)?.is_none() {
        // Nothing at all to move: the log exists, empty; say so in `meta`.
        meta.insert(keys::META_SAMPLES_LOG_LEN, &log.end().to_be_bytes())
            .map_err(|e| e.to_string())?;
    }
    // Samples without a record (none are written so) go with the tree.
    drop(samples);
    db.drop_tree("samples").map_err(|e| e.to_string())?;
    db.flush().map_err(|e| e.to_string())?;
    Ok(())
}

/// Converts `tree`'s values after the key in `meta[marker]`, in batches:
/// `convert(key, value, log)` gives the new value (having appended its bulk
/// to the log) and whether to remove the key's `samples` value. Each batch:
/// log synced, then one transaction (values, removals, the log's length,
/// the marker), then a flush. Returns whether the tree is done (`false`:
/// `budget` batches ran out first).
fn convert_tree(
    db: &sled::Db,
    (meta, tree, samples): (&sled::Tree, &sled::Tree, &sled::Tree),
    marker: &[u8],
    log: &mut SampleLog,
    batch: usize,
    budget: &mut usize,
    convert: impl Fn(&[u8], &[u8], &mut SampleLog) -> Result<(Vec<u8>, bool), String>,
) -> Result<bool, String> {
    let mut through = meta
        .get(marker)
        .map_err(|e| e.to_string())?
        .map(|v| v.to_vec());
    loop {
        let start = match &through {
            Some(k) => Bound::Excluded(k.clone()),
            None => Bound::Unbounded,
        };
        let mut rows = Vec::with_capacity(batch);
        for item in tree
            .range::<Vec<u8>, _>((start, Bound::Unbounded))
            .take(batch)
        {
            let (k, v) = item.map_err(|e| e.to_string())?;
            let (value, remove_samples) = convert(&k, &v, log)?;
            rows.push((k, value, remove_samples));
        }
        let Some((last, _, _)) = rows.last() else {
            return Ok(true);
        };
        if *budget == 0 {
            log.rollback().map_err(|e| format!("{LOG_FILE}: {e}"))?;
            return Ok(false);
        }
        *budget -= 1;
        let last = last.to_vec();
        log.sync().map_err(|e| format!("{LOG_FILE}: {e}"))?;
        let end = log.end();
        use sled::transaction::ConflictableTransactionError;
        use sled::Transactional;
        (meta, tree, samples)
            .transaction(|(meta, tree, samples)| {
                for (k, v, remove_samples) in &rows {
                    tree.insert(k, &v[..])?;
                    if *remove_samples {
                        samples.remove(k)?;
                    }
                }
                meta.insert(keys::META_SAMPLES_LOG_LEN, &end.to_be_bytes())?;
                meta.insert(marker, &last[..])?;
                Ok::<(), ConflictableTransactionError<()>>(())
            })
            .map_err(|e| format!("{e:?}"))?;
        db.flush().map_err(|e| e.to_string())?;
        log.commit();
        through = Some(last);
    }
}
