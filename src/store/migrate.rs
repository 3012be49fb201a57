//! Schema versions and the migration runner. The store carries its version
//! in `meta` (`schema_version`, u32 big-endian). Opening a store:
//! - with no version and no data: a new store, stamped [`CURRENT_VERSION`];
//! - with an older version: each [`Migration`] from that version on runs in
//!   order, and the version is bumped and flushed after each step (a step
//!   must therefore be idempotent: a crash mid-step re-runs it);
//! - with a newer version: [`StoreError::NewerSchema`], nothing touched.
//!
//! One `migrations/NNNN_*.md` per version documents its layout.

use super::meta::{read_meta_u32, read_meta_u64, MetaError};
use super::schema::{JobValue, StateRecordValue};
use super::{decode_value, encode, keys, StoreError};
use std::path::Path;

/// The schema this build reads and writes.
pub const CURRENT_VERSION: u32 = 12;

/// One upgrade step, `from` → `from + 1`.
#[derive(Clone, Copy)]
pub struct Migration {
    pub from: u32,
    pub name: &'static str,
    /// The step, given the database and the store directory (the sample
    /// log lives there).
    pub run: fn(&sled::Db, &Path) -> Result<(), String>,
}

/// The real migrations, in order: version 1 is the initial layout
/// (`migrations/0001_initial.md`).
pub const MIGRATIONS: &[Migration] = &[
    Migration {
        from: 1,
        name: "0002_state_and_identity",
        run: super::v1::migrate_to_v2,
    },
    Migration {
        from: 2,
        name: "0003_sample_log",
        run: super::v2::migrate_to_v3,
    },
    Migration {
        from: 3,
        name: "0004_record_blocks",
        run: super::v3::migrate_to_v4,
    },
    Migration {
        from: 4,
        name: "0005_log_generations",
        run: super::v4::migrate_to_v5,
    },
    Migration {
        from: 5,
        name: "0006_movies",
        run: super::v5::migrate_to_v6,
    },
    Migration {
        from: 6,
        name: "0007_radiance_records_in_state",
        run: super::v6::migrate_to_v7,
    },
    Migration {
        from: 7,
        name: "0008_frame_footprint",
        run: super::v7::migrate_to_v8,
    },
    Migration {
        from: 8,
        name: "0009_record_sources",
        run: super::v8::migrate_to_v9,
    },
    Migration {
        from: 9,
        name: "0010_tcg_state_refers_to_samples",
        run: super::v9::migrate_to_v10,
    },
    Migration {
        from: 10,
        name: "0011_trc_state_without_spatial_gradient_changes",
        run: super::v10::migrate_to_v11,
    },
    Migration {
        from: 11,
        name: "0012_trc_state_without_derived_change",
        run: super::v11::migrate_to_v12,
    },
];

/// A `(key, value)` row of a tree.
pub(super) type Row = (Vec<u8>, Vec<u8>);

/// The core of a step that rewrites one tree job by job: for each of
/// `jobs` (increasing ids) after the one `meta[through]` names, puts the
/// rows `rows(job)` gives into `tree` and the job's id under `through`, in
/// one transaction, then flushes. A crash mid-step resumes after the last
/// job committed, so no value is converted twice, and no transaction
/// holds more than one job's rows.
pub(super) fn rewrite_job_by_job(
    db: &sled::Db,
    tree: &str,
    through: &[u8],
    jobs: &[u64],
    rows: impl Fn(u64) -> Result<Vec<Row>, String>,
) -> Result<(), String> {
    use sled::transaction::ConflictableTransactionError;
    use sled::Transactional;
    let open = |name: &str| db.open_tree(name).map_err(|e| e.to_string());
    let (meta, target) = (open("meta")?, open(tree)?);
    let done = read_meta_u64(&meta, through)?;
    for &job in jobs {
        if done.is_some_and(|d| job <= d) {
            continue;
        }
        let rows = rows(job)?;
        (&meta, &target)
            .transaction(|(meta, target)| {
                for (k, v) in &rows {
                    target.insert(&k[..], &v[..])?;
                }
                meta.insert(through, &job.to_be_bytes()[..])?;
                Ok::<(), ConflictableTransactionError<()>>(())
            })
            .map_err(|e| format!("{e:?}"))?;
        db.flush().map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// A method's conversion of one of its state records' bytes.
pub(super) type Upgrade = fn(&[u8]) -> Result<Vec<u8>, String>;

/// The core of a step that converts carried state: rewrites every state
/// record of every job whose method `upgrade_of` gives a conversion for,
/// one transaction per job ([`rewrite_job_by_job`], progress in
/// `meta[through]`). Other methods' state and every job's head are left
/// as they are.
pub(super) fn upgrade_state_records(
    db: &sled::Db,
    through: &[u8],
    upgrade_of: fn(&str) -> Option<Upgrade>,
) -> Result<(), String> {
    let state = db.open_tree("state").map_err(|e| e.to_string())?;
    let jobs = stateful_jobs(
        &db.open_tree("jobs").map_err(|e| e.to_string())?,
        upgrade_of,
    )?;
    let ids: Vec<u64> = jobs.iter().map(|(id, _)| *id).collect();
    rewrite_job_by_job(db, "state", through, &ids, |job| {
        let (_, upgrade) = jobs
            .iter()
            .find(|(id, _)| *id == job)
            .expect("listed above");
        upgraded_records(&state, job, *upgrade)
    })
}

/// The ids of the jobs whose method `upgrade_of` converts, each with its
/// conversion, in increasing id.
fn stateful_jobs(
    jobs: &sled::Tree,
    upgrade_of: fn(&str) -> Option<Upgrade>,
) -> Result<Vec<(u64, Upgrade)>, String> {
    let mut found: Vec<(u64, Upgrade)> = Vec::new();
    for item in jobs.iter() {
        let (k, v) = item.map_err(|e| e.to_string())?;
        let job: JobValue =
            decode_value(&v).map_err(|e| format!("tree `jobs` key {}: {e}", keys::describe(&k)))?;
        if let Some(upgrade) = upgrade_of(job.method.as_str()) {
            found.push((job.id, upgrade));
        }
    }
    found.sort_unstable_by_key(|(id, _)| *id);
    Ok(found)
}

/// Job `job`'s state records, keys and values, their bytes converted by
/// `upgrade`.
fn upgraded_records(state: &sled::Tree, job: u64, upgrade: Upgrade) -> Result<Vec<Row>, String> {
    let mut records = Vec::new();
    for item in state.scan_prefix(keys::job_prefix(job)) {
        let (k, v) = item.map_err(|e| e.to_string())?;
        if keys::parse_state_record(&k).is_none() {
            continue; // the head: unchanged
        }
        let at = || format!("tree `state` key {}", keys::describe(&k));
        let mut value: StateRecordValue = decode_value(&v).map_err(|e| format!("{}: {e}", at()))?;
        value.data = upgrade(&value.data).map_err(|e| format!("{}: {e}", at()))?;
        records.push((k.to_vec(), encode(&value)));
    }
    Ok(records)
}

/// The schema version stored in `meta`, if any.
pub fn read_version(path: &Path, meta: &sled::Tree) -> Result<Option<u32>, StoreError> {
    read_meta_u32(meta, keys::META_SCHEMA_VERSION).map_err(|e| match e {
        MetaError::Sled(e) => StoreError::sled(path, e),
        MetaError::Width { .. } => StoreError::Corrupt {
            path: path.to_owned(),
            tree: "meta",
            key: keys::describe(keys::META_SCHEMA_VERSION),
            detail: e.to_string(),
        },
    })
}

pub fn write_version(path: &Path, meta: &sled::Tree, version: u32) -> Result<(), StoreError> {
    meta.insert(keys::META_SCHEMA_VERSION, &version.to_be_bytes())
        .map_err(|e| StoreError::sled(path, e))?;
    Ok(())
}

/// Brings a store at `found` up to `target` with `steps`; returns the
/// version reached. Fails without touching anything if `found > target`
/// or a step is missing.
pub fn migrate(
    path: &Path,
    db: &sled::Db,
    meta: &sled::Tree,
    found: u32,
    target: u32,
    steps: &[Migration],
) -> Result<u32, StoreError> {
    if found > target {
        return Err(StoreError::NewerSchema {
            path: path.to_owned(),
            found,
            supported: target,
        });
    }
    // Check the whole chain before running any step.
    for v in found..target {
        if !steps.iter().any(|m| m.from == v) {
            return Err(StoreError::Migration {
                path: path.to_owned(),
                from: v,
                detail: format!("no migration from schema {v} to {}", v + 1),
            });
        }
    }
    for v in found..target {
        let step = steps.iter().find(|m| m.from == v).expect("checked above");
        // Said before the step, which may take a while on a large store,
        // and which older builds cannot undo (they refuse the store after).
        eprintln!(
            "store {}: upgrading schema {v} to {} ({})",
            path.display(),
            v + 1,
            step.name
        );
        (step.run)(db, path).map_err(|detail| StoreError::Migration {
            path: path.to_owned(),
            from: v,
            detail: format!("{}: {detail}", step.name),
        })?;
        write_version(path, meta, v + 1)?;
        db.flush().map_err(|e| StoreError::sled(path, e))?;
    }
    Ok(target)
}
