//! Schema 6 (`migrations/0006_movies.md`) stored the carried state of a
//! `trc` or `tcg` record without a material (nor, for `trc`, sources);
//! schema 7 (`migrations/0007_radiance_records_in_state.md`) adds them, for
//! their radiance records (`--ic-glossy eas`). This module holds the
//! 0006 → 0007 step.

use super::keys;
use super::migrate::Row;
use super::schema::{JobValue, StateRecordValue};
use super::{decode_value, encode};
use std::path::Path;

/// Migration 0006 → 0007: rewrites every state record of every `trc` and
/// `tcg` job in the schema-7 layout (an irradiance record: no material,
/// no sources), one transaction per job (`migrate::rewrite_job_by_job`:
/// progress in `meta.migrate_0007_through`, nothing converted twice). Other methods' state is left
/// as it is.
pub fn migrate_to_v7(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    let state = db.open_tree("state").map_err(|e| e.to_string())?;
    let jobs = stateful_jobs(&db.open_tree("jobs").map_err(|e| e.to_string())?)?;
    let ids: Vec<u64> = jobs.iter().map(|(id, _)| *id).collect();
    super::migrate::rewrite_job_by_job(db, "state", keys::META_MIGRATE_0007_THROUGH, &ids, |job| {
        let (_, upgrade) = jobs
            .iter()
            .find(|(id, _)| *id == job)
            .expect("listed above");
        upgraded_records(&state, job, *upgrade)
    })
}

/// A method's conversion of a schema-6 state record.
type Upgrade = fn(&[u8]) -> Result<Vec<u8>, String>;

/// The ids of the jobs whose method carries records in `state` (`trc`,
/// `tcg`), each with its method's conversion, in increasing id.
fn stateful_jobs(jobs: &sled::Tree) -> Result<Vec<(u64, Upgrade)>, String> {
    let mut found: Vec<(u64, Upgrade)> = Vec::new();
    for item in jobs.iter() {
        let (k, v) = item.map_err(|e| e.to_string())?;
        let job: JobValue =
            decode_value(&v).map_err(|e| format!("tree `jobs` key {}: {e}", keys::describe(&k)))?;
        let upgrade: Upgrade = match job.method.as_str() {
            "trc" => crate::method::trc::upgrade_schema_6_record,
            "tcg" => crate::method::tcg::upgrade_schema_6_record,
            _ => continue,
        };
        found.push((job.id, upgrade));
    }
    found.sort_unstable_by_key(|(id, _)| *id);
    Ok(found)
}

/// Job `job`'s state records, keys and values, their bytes converted to
/// the schema-7 layout by `upgrade`.
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
