//! Schema 1 (`migrations/0001_initial.md`): the value types that schema 2
//! changed (`frames`, `records` and `samples` values are the same; the
//! latter two, changed by schema 3, are in [`super::v2`]), kept to read a
//! version-1 store in the 0001 → 0002 migration, and a writer of version-1
//! stores for the test that opens one.

use super::schema;
use super::v2::{self, FrameValue, SamplesValue};
use super::{compress, encode, keys, RecordCommit};
use crate::method::FrameStats;
use rkyv::{Archive, Deserialize, Serialize};
use std::path::Path;

/// Schema-1 `jobs` value.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct JobValue {
    pub id: u64,
    pub name: String,
    pub scene: String,
    /// FNV-1a 64 of the scene file bytes (external files not included).
    pub scene_hash: String,
    pub method: String,
    /// `{:?}` of `MethodSettings`.
    pub settings: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub fps: f32,
    pub seed: u64,
    pub same_pattern: bool,
    pub frame_start: u32,
    pub frame_end: u32,
    pub frames_done: u32,
    pub last_frame: Option<u32>,
    pub created_unix: u64,
    pub updated_unix: u64,
}

/// Schema-1 `stats` value (no lifespans).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct StatsValue {
    pub frame: u32,
    pub records_alive: u64,
    pub records_created: u64,
    pub records_reused: u64,
    pub records_replaced: u64,
    pub records_dropped: u64,
    pub lookups: u64,
    pub lookup_records: u64,
    pub fallback_lookups: u64,
    pub rays: u64,
    pub phase_seconds: Vec<(String, f64)>,
    pub samples_raw_bytes: u64,
}

/// Suffix of the scene hash of a schema-1 job of a scene file: its
/// external buffers and images were not hashed; the first render under
/// schema 2 with the same file records the full hash.
pub const LEGACY_HASH_SUFFIX: &str = "+v1";

/// Prefix of schema-1 settings text that could not be read as JSON.
pub const LEGACY_SETTINGS_PREFIX: &str = "v1:";

impl JobValue {
    /// The schema-2 job: settings `{:?}` text read into JSON, scene hashes
    /// of files marked [`LEGACY_HASH_SUFFIX`].
    pub fn to_v2(&self) -> schema::JobValue {
        let settings = match debug_to_json(&self.settings) {
            Ok(v) => v.to_string(),
            Err(_) => format!("{LEGACY_SETTINGS_PREFIX}{}", self.settings),
        };
        let scene_hash = if self.scene.starts_with("builtin:") {
            self.scene_hash.clone()
        } else {
            format!("{}{LEGACY_HASH_SUFFIX}", self.scene_hash)
        };
        schema::JobValue {
            id: self.id,
            spec: schema::JobSpec {
                name: self.name.clone(),
                scene: self.scene.clone(),
                scene_hash,
                method: self.method.clone(),
                settings,
                width: self.width,
                height: self.height,
                spp: self.spp,
                fps: self.fps,
                seed: self.seed,
                same_pattern: self.same_pattern,
                frame_start: self.frame_start,
                frame_end: self.frame_end,
            },
            frames_done: self.frames_done,
            last_frame: self.last_frame,
            created_unix: self.created_unix,
            updated_unix: self.updated_unix,
        }
    }
}

impl StatsValue {
    /// The schema-2 stats (schema 1 stored no lifespans: left empty).
    pub fn to_v2(&self) -> super::v7::StatsValue {
        super::v7::StatsValue {
            stats: super::v7::FrameStats {
                frame: self.frame,
                records_alive: self.records_alive,
                records_created: self.records_created,
                records_reused: self.records_reused,
                records_replaced: self.records_replaced,
                records_dropped: self.records_dropped,
                lookups: self.lookups,
                lookup_records: self.lookup_records,
                fallback_lookups: self.fallback_lookups,
                rays: self.rays,
                phase_seconds: self.phase_seconds.clone(),
                ..super::v7::FrameStats::default()
            },
            samples_raw_bytes: self.samples_raw_bytes,
        }
    }

    /// Schema 1's conversion from the method's statistics.
    pub fn from_stats(s: &FrameStats, samples_raw_bytes: u64) -> Self {
        StatsValue {
            frame: s.frame,
            records_alive: s.records_alive,
            records_created: s.records_created,
            records_reused: s.records_reused,
            records_replaced: s.records_replaced,
            records_dropped: s.records_dropped,
            lookups: s.lookups,
            lookup_records: s.lookup_records,
            fallback_lookups: s.fallback_lookups,
            rays: s.rays,
            phase_seconds: s.phase_seconds.clone(),
            samples_raw_bytes,
        }
    }
}

/// Migration 0001 → 0002 (`migrations/0002_state_and_identity.md`):
/// rewrites every `jobs` and `stats` value in the schema-2 layout, creates
/// the `state` tree and stamps version 2, in one transaction: a crash
/// leaves either schema 1 untouched or schema 2 complete.
pub fn migrate_to_v2(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    let tree = |name: &str| db.open_tree(name).map_err(|e| e.to_string());
    let (meta, jobs, stats) = (tree("meta")?, tree("jobs")?, tree("stats")?);
    tree("state")?;
    let mut job_rows = Vec::new();
    for item in jobs.iter() {
        let (k, v) = item.map_err(|e| e.to_string())?;
        let old: JobValue = super::decode_value(&v)
            .map_err(|e| format!("tree `jobs` key {}: {e}", keys::describe(&k)))?;
        job_rows.push((k, encode(&old.to_v2())));
    }
    let mut stats_rows = Vec::new();
    for item in stats.iter() {
        let (k, v) = item.map_err(|e| e.to_string())?;
        let old: StatsValue = super::decode_value(&v)
            .map_err(|e| format!("tree `stats` key {}: {e}", keys::describe(&k)))?;
        stats_rows.push((k, encode(&old.to_v2())));
    }
    use sled::transaction::ConflictableTransactionError;
    use sled::Transactional;
    (&meta, &jobs, &stats)
        .transaction(|(meta, jobs, stats)| {
            for (k, v) in &job_rows {
                jobs.insert(&k[..], &v[..])?;
            }
            for (k, v) in &stats_rows {
                stats.insert(&k[..], &v[..])?;
            }
            meta.insert(keys::META_SCHEMA_VERSION, &2u32.to_be_bytes())?;
            Ok::<(), ConflictableTransactionError<()>>(())
        })
        .map_err(|e| format!("{e:?}"))?;
    Ok(())
}

/// Writes stores in the schema-1 layout, as radcache 0.1 with schema 1
/// did (the migration test builds its version-1 store with it).
pub struct Writer {
    db: sled::Db,
}

impl Writer {
    /// A new version-1 store at `path`.
    pub fn create(path: &Path) -> Result<Writer, String> {
        let db = sled::open(path).map_err(|e| e.to_string())?;
        db.open_tree("meta")
            .and_then(|m| m.insert(keys::META_SCHEMA_VERSION, &1u32.to_be_bytes()))
            .map_err(|e| e.to_string())?;
        Ok(Writer { db })
    }

    pub fn put_job(&self, job: &JobValue) -> Result<(), String> {
        self.insert("jobs", &keys::job(&job.name), &encode(job))
    }

    /// One finished frame of job `job`: EXR bytes, stats, records.
    pub fn put_frame(
        &self,
        job: u64,
        frame: u32,
        (width, height): (u32, u32),
        exr: &[u8],
        stats: &StatsValue,
        records: &[RecordCommit],
    ) -> Result<(), String> {
        let key = keys::frame(job, frame);
        let value = FrameValue {
            width,
            height,
            exr_len: exr.len() as u64,
            exr_zstd: compress(exr),
        };
        self.insert("frames", &key, &encode(&value))?;
        self.insert("stats", &key, &encode(stats))?;
        for rc in records {
            let key = keys::record(job, frame, rc.record.id);
            let record = v2::RecordValue::from_v3(&rc.record);
            self.insert("records", &key, &encode(&record))?;
            if !rc.samples.is_empty() {
                let samples = SamplesValue {
                    count: rc.samples.count,
                    packed_zstd: rc.samples.zstd.clone(),
                };
                self.insert("samples", &key, &encode(&samples))?;
            }
        }
        self.db.flush().map(|_| ()).map_err(|e| e.to_string())
    }

    fn insert(&self, tree: &str, key: &[u8], value: &[u8]) -> Result<(), String> {
        self.db
            .open_tree(tree)
            .and_then(|t| t.insert(key, value))
            .map(|_| ())
            .map_err(|e| e.to_string())
    }
}
/// Schema 1 stored a job's method settings as Rust `{:?}` text; schema 2
/// stores serde JSON. This reads the `{:?}` text of plain `derive(Debug)`
/// data (structs, tuple and unit enum variants, `Some`/`None`, numbers,
/// booleans, strings) into the JSON serde gives the same value:
/// `Name { a: 1 }` → `{"a": 1}`, `Variant(x)` → `{"Variant": x}`, a unit
/// variant → `"Variant"`, `None` → `null`, `Some(x)` → `x`, `inf`/`NaN` →
/// `null` (as serde_json writes non-finite floats).
pub fn debug_to_json(text: &str) -> Result<serde_json::Value, String> {
    let mut p = DebugParser {
        s: text.as_bytes(),
        i: 0,
    };
    let v = p.value()?;
    p.ws();
    if p.i != p.s.len() {
        return Err(format!("trailing text at byte {}", p.i));
    }
    Ok(v)
}

struct DebugParser<'a> {
    s: &'a [u8],
    i: usize,
}

impl DebugParser<'_> {
    fn ws(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.ws();
        self.s.get(self.i).copied()
    }

    fn eat(&mut self, c: u8) -> Result<(), String> {
        if self.peek() == Some(c) {
            self.i += 1;
            Ok(())
        } else {
            Err(format!("expected `{}` at byte {}", c as char, self.i))
        }
    }

    fn word(&mut self) -> String {
        self.ws();
        let start = self.i;
        while self.i < self.s.len()
            && (self.s[self.i].is_ascii_alphanumeric()
                || matches!(self.s[self.i], b'_' | b'.' | b'-' | b'+'))
        {
            self.i += 1;
        }
        String::from_utf8_lossy(&self.s[start..self.i]).into_owned()
    }

    fn value(&mut self) -> Result<serde_json::Value, String> {
        use serde_json::Value;
        match self.peek() {
            None => Err("unexpected end".into()),
            Some(b'"') => {
                // A Debug string: JSON escapes are a superset for our data.
                let start = self.i;
                self.i += 1;
                while self.i < self.s.len() && self.s[self.i] != b'"' {
                    self.i += if self.s[self.i] == b'\\' { 2 } else { 1 };
                }
                self.i += 1;
                let raw = std::str::from_utf8(&self.s[start..self.i.min(self.s.len())])
                    .map_err(|e| e.to_string())?;
                serde_json::from_str(raw).map_err(|e| format!("string {raw}: {e}"))
            }
            Some(b'[') => {
                self.i += 1;
                let mut items = Vec::new();
                while self.peek() != Some(b']') {
                    items.push(self.value()?);
                    if self.peek() == Some(b',') {
                        self.i += 1;
                    }
                }
                self.eat(b']')?;
                Ok(Value::Array(items))
            }
            Some(_) => {
                let w = self.word();
                if w.is_empty() {
                    return Err(format!("unexpected byte at {}", self.i));
                }
                match w.as_str() {
                    "true" => return Ok(Value::Bool(true)),
                    "false" => return Ok(Value::Bool(false)),
                    "None" | "inf" | "-inf" | "NaN" => return Ok(Value::Null),
                    _ => {}
                }
                if w.starts_with(|c: char| c.is_ascii_digit() || c == '-') {
                    return serde_json::from_str::<Value>(&w)
                        .map_err(|e| format!("number {w}: {e}"));
                }
                match self.peek() {
                    Some(b'{') => {
                        self.i += 1;
                        let mut map = serde_json::Map::new();
                        while self.peek() != Some(b'}') {
                            let key = self.word();
                            self.eat(b':')?;
                            map.insert(key, self.value()?);
                            if self.peek() == Some(b',') {
                                self.i += 1;
                            }
                        }
                        self.eat(b'}')?;
                        Ok(Value::Object(map))
                    }
                    Some(b'(') => {
                        self.i += 1;
                        let inner = self.value()?;
                        if self.peek() == Some(b',') {
                            self.i += 1;
                        }
                        self.eat(b')')?;
                        if w == "Some" {
                            Ok(inner)
                        } else {
                            let mut map = serde_json::Map::new();
                            map.insert(w, inner);
                            Ok(Value::Object(map))
                        }
                    }
                    _ => Ok(Value::String(w)),
                }
            }
        }
    }
}
