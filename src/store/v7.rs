//! Schema 7 stored a frame's statistics without the samples it shot again
//! or the bytes its cache held and its checkpoint wrote; schema 8
//! (`migrations/0008_frame_footprint.md`) adds them. This module holds the
//! `stats` value as schemas 2 to 7 laid it out, and the 0007 → 0008 step.

use super::schema;
use super::{decode_value, encode, keys};
use crate::method::FrameStats as CurrentFrameStats;
use rkyv::{Archive, Deserialize, Serialize};
use std::path::Path;

/// A frame's statistics in schemas 2 to 7 (field for field the
/// [`crate::method::FrameStats`] of those schemas).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct FrameStats {
    pub frame: u32,
    pub records_alive: u64,
    pub records_created: u64,
    pub records_reused: u64,
    pub records_replaced: u64,
    pub records_dropped: u64,
    pub lookups: u64,
    pub lookup_records: u64,
    pub fallback_lookups: u64,
    pub mean_lifespan: f64,
    pub lifespan_histogram: Vec<u64>,
    pub rays: u64,
    pub phase_seconds: Vec<(String, f64)>,
}

/// `stats` value of schemas 2 to 7.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct StatsValue {
    pub stats: FrameStats,
    pub samples_raw_bytes: u64,
}

/// A `$target` struct literal with the fields schemas 7 and 8 share taken
/// from `$s` (a frame's statistics of either), then `$rest`: the one list
/// of them both conversions use.
macro_rules! shared_stats {
    ($target:ident from $s:expr, $($rest:tt)*) => {
        $target {
            frame: $s.frame,
            records_alive: $s.records_alive,
            records_created: $s.records_created,
            records_reused: $s.records_reused,
            records_replaced: $s.records_replaced,
            records_dropped: $s.records_dropped,
            lookups: $s.lookups,
            lookup_records: $s.lookup_records,
            fallback_lookups: $s.fallback_lookups,
            mean_lifespan: $s.mean_lifespan,
            lifespan_histogram: $s.lifespan_histogram.clone(),
            rays: $s.rays,
            phase_seconds: $s.phase_seconds.clone(),
            $($rest)*
        }
    };
}

impl StatsValue {
    /// The schema-8 value. What schema 7 did not count (samples re-shot,
    /// cache and stored bytes) is 0: those frames were not measured.
    pub fn to_v8(&self) -> schema::StatsValue {
        schema::StatsValue {
            stats: shared_stats!(CurrentFrameStats from self.stats, ..CurrentFrameStats::default()),
            samples_raw_bytes: self.samples_raw_bytes,
            stored_bytes: 0,
        }
    }

    /// The schema-7 value of `v`, dropping what schema 7 did not keep
    /// (tests build schema-7 stores with it).
    #[doc(hidden)]
    pub fn from_v8(v: &schema::StatsValue) -> Self {
        StatsValue {
            stats: shared_stats!(FrameStats from v.stats,),
            samples_raw_bytes: v.samples_raw_bytes,
        }
    }
}

/// Migration 0007 → 0008: rewrites every `stats` value in the schema-8
/// layout, one transaction per job (`migrate::rewrite_job_by_job`:
/// progress in `meta.migrate_0008_through`, nothing converted twice).
pub fn migrate_to_v8(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    let stats = db.open_tree("stats").map_err(|e| e.to_string())?;
    let mut jobs: Vec<u64> = Vec::new();
    for key in stats.iter().keys() {
        let key = key.map_err(|e| e.to_string())?;
        let (job, _) = keys::parse_frame(&key)
            .ok_or_else(|| format!("tree `stats` key {}: malformed key", keys::describe(&key)))?;
        if jobs.last() != Some(&job) {
            jobs.push(job);
        }
    }
    super::migrate::rewrite_job_by_job(db, "stats", keys::META_MIGRATE_0008_THROUGH, &jobs, |job| {
        let mut rows = Vec::new();
        for item in stats.scan_prefix(keys::job_prefix(job)) {
            let (k, v) = item.map_err(|e| e.to_string())?;
            let old: StatsValue = decode_value(&v)
                .map_err(|e| format!("tree `stats` key {}: {e}", keys::describe(&k)))?;
            rows.push((k.to_vec(), encode(&old.to_v8())));
        }
        Ok(rows)
    })
}

/// Rewrites every `stats` value of the store at `db` in the schema-7
/// layout (tests build schema-7 stores with it).
#[doc(hidden)]
pub fn downgrade_stats_to_schema_7(db: &sled::Db) -> Result<(), String> {
    let stats = db.open_tree("stats").map_err(|e| e.to_string())?;
    for item in stats.iter() {
        let (k, v) = item.map_err(|e| e.to_string())?;
        let new: schema::StatsValue = decode_value(&v).map_err(|e| e.to_string())?;
        stats
            .insert(k, encode(&StatsValue::from_v8(&new)))
            .map_err(|e| e.to_string())?;
    }
    db.flush().map(|_| ()).map_err(|e| e.to_string())
}
