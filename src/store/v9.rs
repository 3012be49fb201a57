//! Schema 9 (`migrations/0009_record_sources.md`) kept a copy of each
//! `tcg` record's samples in its carried state; schema 10
//! (`migrations/0010_tcg_state_refers_to_samples.md`) keeps them only in
//! the record's version the same frame stores, which the state refers to.
//! This module holds the 0009 → 0010 step.

use std::path::Path;

/// Migration 0009 → 0010: nothing to convert (a state that holds its
/// samples still reads, `method::tcg`'s `decode_record`). The version bump
/// is what matters: a schema-9 build would refuse a `tcg` state without
/// samples as damaged ("0 samples, the job's strata have N cells") instead
/// of saying that the store is newer.
pub fn migrate_to_v10(_db: &sled::Db, _dir: &Path) -> Result<(), String> {
    Ok(())
}
