//! Schemas 7–10 kept, in each `trc` record's carried state, the
//! extrapolated changes of its spatial gradients (TRC Eq. 16–17), which no
//! frame has applied since `trc` revision 18 (`TemporalRecord::at_frame`);
//! schema 11 (`migrations/0011_trc_state_without_spatial_gradient_changes.md`)
//! drops them. This module holds the 0010 → 0011 step.

use super::keys;
use std::path::Path;

/// Migration 0010 → 0011: rewrites every state record of every `trc` job
/// without the changes of its spatial gradients, one transaction per job
/// (`migrate::upgrade_state_records`:
/// progress in `meta.migrate_0011_through`, nothing converted twice).
/// Other methods' state is left as it is.
pub fn migrate_to_v11(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    super::migrate::upgrade_state_records(db, keys::META_MIGRATE_0011_THROUGH, |method| {
        (method == "trc").then_some(crate::method::trc::upgrade_schema_10_record as _)
    })
}
