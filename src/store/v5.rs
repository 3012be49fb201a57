//! Schema 5 (`migrations/0005_log_generations.md`) left the `movies` tree
//! empty; schema 6 (`migrations/0006_movies.md`) stores the texture movies
//! of `--method movies` there. This module holds the 0005 → 0006 step.

use std::path::Path;

/// Migration 0005 → 0006: nothing to convert (no schema-5 store has a
/// movie). The version bump is what matters: a schema-5 build would not
/// delete a job's movies when the job starts over, so it must refuse a
/// store that may hold some.
pub fn migrate_to_v6(_db: &sled::Db, _dir: &Path) -> Result<(), String> {
    Ok(())
}
