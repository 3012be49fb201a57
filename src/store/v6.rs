//! Schema 6 (`migrations/0006_movies.md`) stored the carried state of a
//! `trc` or `tcg` record without a material (nor, for `trc`, sources);
//! schema 7 (`migrations/0007_radiance_records_in_state.md`) adds them, for
//! their radiance records (`--ic-glossy eas`). This module holds the
//! 0006 → 0007 step.

use super::keys;
use std::path::Path;

/// Migration 0006 → 0007: rewrites every state record of every `trc` and
/// `tcg` job in the schema-7 layout (an irradiance record: no material,
/// no sources), one transaction per job
/// (`migrate::upgrade_state_records`:
/// progress in `meta.migrate_0007_through`, nothing converted twice).
/// Other methods' state is left as it is.
pub fn migrate_to_v7(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    super::migrate::upgrade_state_records(
        db,
        keys::META_MIGRATE_0007_THROUGH,
        |method| match method {
            "trc" => Some(crate::method::trc::upgrade_schema_6_record),
            "tcg" => Some(crate::method::tcg::upgrade_schema_6_record),
            _ => None,
        },
    )
}
