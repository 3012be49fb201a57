//! Schema 11 kept, in each `trc` record's carried state, its change to
//! the next frame (`|τ − 1|`, TRC Eq. 7 and 21) and the temporal gradient
//! of its irradiance (Eq. 15), both of which follow from E(t0), the
//! estimate of E(t0+1) and the sources' changes that the state keeps
//! besides (`TemporalRecord::change`, `TemporalRecord::d_irradiance`);
//! schema 12 (`migrations/0012_trc_state_without_derived_change.md`)
//! drops them. This module holds the 0011 → 0012 step.

use super::keys;
use std::path::Path;

/// Migration 0011 → 0012: rewrites every state record of every `trc` job
/// without the two derived values, one transaction per job
/// (`migrate::upgrade_state_records`: progress in
/// `meta.migrate_0012_through`, nothing converted twice). Other methods'
/// state is left as it is.
pub fn migrate_to_v12(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    super::migrate::upgrade_state_records(db, keys::META_MIGRATE_0012_THROUGH, |method| {
        (method == "trc").then_some(crate::method::trc::upgrade_schema_11_record as _)
    })
}
