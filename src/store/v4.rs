//! Schema 4 (`migrations/0004_record_blocks.md`): the sample log is always
//! `samples.log`. Schema 5 (`migrations/0005_log_generations.md`) lets
//! `radcache compact` move it to a new file, named by a generation in
//! `meta`. This module holds the 0004 → 0005 migration step.

use super::keys;
use super::meta::read_meta_u64;
use std::path::Path;

/// Migration 0004 → 0005: writes `meta.samples_log_generation` = 0 (the
/// schema-4 log, `samples.log`) unless it is there. Nothing else changes:
/// the version bump is what matters, so that a schema-4 build, which knows
/// only `samples.log`, refuses a store whose log a compaction may have
/// moved. One insert, then the runner's flush: re-running it after a crash
/// changes nothing.
pub fn migrate_to_v5(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    let meta = db.open_tree("meta").map_err(|e| e.to_string())?;
    if read_meta_u64(&meta, keys::META_SAMPLES_LOG_GENERATION)?.is_none() {
        meta.insert(keys::META_SAMPLES_LOG_GENERATION, &0u64.to_be_bytes())
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}
