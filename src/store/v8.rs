//! Schema 8 (`migrations/0008_frame_footprint.md`) kept a radiance
//! record's sources only in a `trc` job's carried state; schema 9
//! (`migrations/0009_record_sources.md`) stores the sources of every
//! radiance record version a frame writes in the `sources` tree. This
//! module holds the 0008 → 0009 step.

use std::path::Path;

/// Migration 0008 → 0009: nothing to convert (no schema-8 store has a row
/// in `sources`; its radiance records stay without stored sources). The
/// version bump is what matters: a schema-8 build would not delete a
/// job's sources when the job starts over, and the next run's records
/// would show the sources of the old ones with the same ids, so it must
/// refuse a store that may hold some.
pub fn migrate_to_v9(_db: &sled::Db, _dir: &Path) -> Result<(), String> {
    Ok(())
}
