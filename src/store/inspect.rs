//! `radcache inspect`: what a store holds — jobs, frames done, records per
//! frame, bytes per tree and of the sample log, compression ratios, record
//! lifespans (per object, and split between moving and static objects when
//! the caller knows which objects move).

use super::schema::{JobValue, StateRecordValue};
use super::{Store, StoreError, TREES};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

#[derive(Clone, Debug, Serialize)]
pub struct InspectReport {
    pub path: String,
    pub schema_version: u32,
    /// Bytes of the database files (sled's `size_on_disk`).
    pub size_on_disk: u64,
    /// The sample log's file name (`samples.log`, or `samples.N.log`
    /// after a compaction) and its committed bytes (the bulk values,
    /// outside sled).
    pub sample_log_file: String,
    pub sample_log_bytes: u64,
    /// Of those, the bytes some value references and those none does any
    /// more (what `radcache compact` reclaims).
    pub sample_log_referenced_bytes: u64,
    pub sample_log_unreferenced_bytes: u64,
    /// Bytes of the file past its committed length: a frame a crash cut
    /// off between its appends and its commit, or frames whose commits the
    /// database lost. The store's next write cuts them off.
    pub sample_log_tail_bytes: u64,
    /// Whether that tail holds two or more frames' files, which no crash
    /// leaves: the database lost commits, and the store refuses jobs and compaction.
    pub sample_log_tail_lost_frames: bool,
    /// Key and value bytes per tree (logical: before sled's own overhead).
    pub trees: Vec<TreeReport>,
    /// `size_on_disk` / Σ (key + value bytes): sled's space amplification.
    pub space_amplification: f64,
    /// The frame asked for (`inspect --frame`), whose row alone each job
    /// shows.
    pub frame: Option<u32>,
    pub jobs: Vec<JobReport>,
}

#[derive(Clone, Debug, Serialize)]
pub struct TreeReport {
    pub name: String,
    pub keys: u64,
    pub key_bytes: u64,
    pub value_bytes: u64,
}

#[derive(Clone, Debug, Serialize)]
pub struct JobReport {
    pub name: String,
    pub id: u64,
    pub scene: String,
    pub scene_hash: String,
    pub method: String,
    /// The method's settings as the store holds them (serde JSON). In
    /// JSON, an object of every setting by the names `POST /api/jobs`
    /// takes and a served job shows (`settings_by_name`).
    #[serde(serialize_with = "settings_by_name")]
    pub settings: String,
    /// The revision of the method's algorithm the job started under
    /// ([`crate::method::algorithm_revision`]): a build whose own differs
    /// does not resume it.
    pub algorithm_revision: u64,
    pub size: String,
    pub spp: u32,
    pub fps: f32,
    pub seed: u64,
    /// Whether every frame draws its pixel samples from the same streams
    /// (`--same-pattern`): a resume checks it, as the other settings.
    pub same_pattern: bool,
    /// Frame range of the last render, `START..END`.
    pub frames: String,
    pub frames_done: u32,
    pub last_frame: Option<u32>,
    /// Records computed: distinct (creation frame, id) pairs, since `ic`
    /// numbers each frame's records from 0 again.
    pub records: u64,
    /// Record versions written: more than `records` where a method writes
    /// a record again in later frames (`tcg`, whose samples change).
    pub record_versions: u64,
    pub samples: u64,
    /// Stored (zstd) and raw bytes of the record samples.
    pub samples_stored_bytes: u64,
    pub samples_raw_bytes: u64,
    /// Stored (zstd) and raw bytes of the frame EXR files.
    pub exr_stored_bytes: u64,
    pub exr_raw_bytes: u64,
    /// Bytes of the records' rkyv values (their frames' blocks before zstd).
    pub record_value_bytes: u64,
    /// Bytes of the frames' record blocks in the sample log (zstd).
    pub record_block_bytes: u64,
    /// Of the record versions, the radiance records (`--ic-glossy eas`),
    /// and the sources stored with them (the `sources` tree).
    pub radiance_records: u64,
    pub sources: u64,
    /// Lifespan in frames (of each record's latest version) → records.
    pub lifespan_histogram: BTreeMap<u32, u64>,
    /// Object (its index in the scene) → the records on it.
    pub records_by_object: BTreeMap<u32, ObjectRecords>,
    /// The scene's animated objects, where the caller could load the job's
    /// scene (the store keeps only its name and hash; [`report`] leaves
    /// this `None`): the text then splits the records between moving and
    /// static objects.
    pub moving_objects: Option<BTreeSet<u32>>,
    /// Per-frame details (all frames, or the one asked for).
    pub frame_details: Vec<FrameReport>,
    /// The carried state of a stateful method (`trc`, `tcg`) a resume
    /// would continue from, if any.
    pub state: Option<StateReport>,
    /// The texture movies of a `movies` job, if it stored any.
    pub movies: Option<MoviesReport>,
}

/// What a `movies` job's frames hold in the `movies` tree.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct MoviesReport {
    /// Distinct movies (a side of a triangle from the frame it opened).
    pub movies: u64,
    /// Movie frames (a movie in a frame).
    pub movie_frames: u64,
    /// Movie frames whose texels are stored (the others encode as an
    /// earlier frame of theirs, and point at it).
    pub movie_frames_stored: u64,
    /// Texels stored over all movie frames.
    pub texels: u64,
    /// Bytes of the texels stored (zstd) and raw (4 RGBE bytes each).
    pub stored_bytes: u64,
    pub raw_bytes: u64,
}

impl MoviesReport {
    /// Mean length of the stored movies, in frames.
    pub fn mean_length(&self) -> f64 {
        self.movie_frames as f64 / self.movies.max(1) as f64
    }
}

/// The records computed on some objects, and their lifespans.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ObjectRecords {
    pub records: u64,
    /// Sum of the records' lifespans, in frames.
    pub lifespan_frames: u64,
}

impl ObjectRecords {
    fn add(&mut self, records: u64, lifespan_frames: u64) {
        self.records += records;
        self.lifespan_frames += lifespan_frames;
    }

    /// Mean lifespan in frames; 0 with no records.
    pub fn mean_lifespan(&self) -> f64 {
        if self.records == 0 {
            0.0
        } else {
            self.lifespan_frames as f64 / self.records as f64
        }
    }
}

impl JobReport {
    /// The records on moving objects and those on static ones, by
    /// [`JobReport::moving_objects`]; `None` where it is not known.
    pub fn moving_and_static(&self) -> Option<(ObjectRecords, ObjectRecords)> {
        let moving = self.moving_objects.as_ref()?;
        let (mut on_moving, mut on_static) = (ObjectRecords::default(), ObjectRecords::default());
        for (object, r) in &self.records_by_object {
            let side = if moving.contains(object) {
                &mut on_moving
            } else {
                &mut on_static
            };
            side.add(r.records, r.lifespan_frames);
        }
        Some((on_moving, on_static))
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct StateReport {
    /// The state is the one after this frame.
    pub frame: u32,
    /// First frame of the range it belongs to (and its end, for methods
    /// that look ahead).
    pub chain_start: u32,
    pub chain_end: Option<u32>,
    /// Records in the state, and their value bytes.
    pub records: u64,
    pub value_bytes: u64,
    /// Of the records, the radiance records (`--ic-glossy eas`), and the
    /// sources they carry (`trc`; `tcg` builds them each frame from the
    /// samples and stores none).
    pub radiance_records: u64,
    pub sources: u64,
}

#[derive(Clone, Debug, Serialize)]
pub struct FrameReport {
    pub frame: u32,
    /// Record versions written in this frame.
    pub records_written: u64,
    /// Records alive at the end of the frame, and those the frame created,
    /// reused from earlier frames, replaced and dropped, and the mean
    /// lifespan of those it computed (from the frame's statistics).
    pub records_alive: u64,
    pub records_created: u64,
    pub records_reused: u64,
    pub records_replaced: u64,
    pub records_dropped: u64,
    /// 0 where the frame computed no record whose life is set (`null` in
    /// JSON, `-` in text).
    #[serde(serialize_with = "null_when_unset")]
    pub mean_lifespan: f64,
    pub samples: u64,
    /// Samples the frame shot again for carried records, the bytes the
    /// method's cache held at its end and the bytes its checkpoint wrote
    /// (0 for frames stored before schema 8).
    pub samples_reshot: u64,
    pub cache_bytes: u64,
    pub stored_bytes: u64,
    pub exr_bytes: u64,
    pub rays: u64,
}

/// Builds the report: every job, or only `job`; per-frame rows for
/// `frame` only when given.
pub fn report(
    store: &Store,
    job: Option<&str>,
    frame: Option<u32>,
) -> Result<InspectReport, StoreError> {
    let mut trees = Vec::new();
    for name in TREES {
        let tree = store.tree(name).expect("known tree");
        let mut t = TreeReport {
            name: name.to_string(),
            keys: 0,
            key_bytes: 0,
            value_bytes: 0,
        };
        for item in tree.iter() {
            let (k, v) = item.map_err(|e| StoreError::sled(store.path(), e))?;
            t.keys += 1;
            t.key_bytes += k.len() as u64;
            t.value_bytes += v.len() as u64;
        }
        trees.push(t);
    }
    let logical: u64 = trees.iter().map(|t| t.key_bytes + t.value_bytes).sum();
    let size_on_disk = store.size_on_disk()?;
    let jobs: Vec<JobValue> = match job {
        Some(name) => match store.job(name)? {
            Some(job) => vec![job],
            None => {
                return Err(StoreError::Job {
                    path: store.path().to_owned(),
                    job: name.to_string(),
                    detail: format!("no such job in this store (jobs: {})", store.job_names()?),
                })
            }
        },
        None => store.jobs()?,
    };
    let mut reports = Vec::new();
    for j in &jobs {
        reports.push(job_report(store, j, frame)?);
    }
    let usage = super::compact::log_usage(store)?;
    let log_file = store.sample_log_file();
    let file_len = std::fs::metadata(&log_file).map_or(0, |m| m.len());
    Ok(InspectReport {
        path: store.path().display().to_string(),
        schema_version: store.schema_version()?,
        size_on_disk,
        sample_log_file: log_file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        sample_log_bytes: usage.committed,
        sample_log_referenced_bytes: usage.referenced,
        sample_log_unreferenced_bytes: usage.unreferenced,
        sample_log_tail_bytes: file_len.saturating_sub(usage.committed),
        sample_log_tail_lost_frames: store.sample_log_holds_lost_frames(),
        trees,
        space_amplification: size_on_disk as f64 / logical.max(1) as f64,
        frame,
        jobs: reports,
    })
}

/// The method state job `id` carries (`None` for a method without one, or
/// before its first frame): the frame it follows, its range, and the
/// records and bytes it holds.
fn state_report(store: &Store, j: &JobValue) -> Result<Option<StateReport>, StoreError> {
    let Some(head) = store.state_head(j.id)? else {
        return Ok(None);
    };
    let mut state = StateReport {
        frame: head.frame,
        chain_start: head.chain_start,
        chain_end: head.chain_end,
        records: 0,
        value_bytes: 0,
        radiance_records: 0,
        sources: 0,
    };
    for item in store.state.scan_prefix(super::keys::job_prefix(j.id)) {
        let (k, v) = item.map_err(|e| StoreError::sled(store.path(), e))?;
        // The head's key is the job prefix alone; longer keys are records.
        if k.len() == 8 {
            continue;
        }
        state.records += 1;
        state.value_bytes += v.len() as u64;
        let value: StateRecordValue = store.decode("state", &k, &v)?;
        let sources =
            radiance_sources(&j.method, &value.data).map_err(|e| store.corrupt("state", &k, e))?;
        if let Some(n) = sources {
            state.radiance_records += 1;
            state.sources += n as u64;
        }
    }
    Ok(Some(state))
}

/// The sources of a record of `method`'s carried state, from its bytes:
/// `None` for an irradiance record.
fn radiance_sources(method: &str, data: &[u8]) -> Result<Option<usize>, String> {
    match method {
        "trc" => crate::method::trc::sources_in(data),
        "tcg" => Ok(crate::method::tcg::is_radiance_record(data)?.then_some(0)),
        _ => Ok(None),
    }
}

/// ` (R radiance records, S sources)` where the state holds radiance
/// records; nothing otherwise.
fn radiance_text(st: &StateReport) -> String {
    match (st.radiance_records, st.sources) {
        (0, _) => String::new(),
        (r, 0) => format!(" ({r} radiance records)"),
        (r, s) => format!(" ({r} radiance records, {s} sources)"),
    }
}

fn job_report(store: &Store, j: &JobValue, only: Option<u32>) -> Result<JobReport, StoreError> {
    let mut r = JobReport::of(j);
    r.algorithm_revision = store.job_revision(j.id)?;
    r.state = state_report(store, j)?;
    let mut per_frame = frame_reports(store, j.id, &mut r)?;
    // Records and samples: one streaming pass over the job's frames.
    for frame in store.frames_done(j.id)? {
        if let Some(v) = store.frame_records_value(j.id, frame)? {
            r.record_value_bytes += u64::from(v.raw_len);
            r.record_block_bytes += u64::from(v.stored_len);
        }
        if let Some(v) = store.frame_sources(j.id, frame)? {
            r.radiance_records += v.records.len() as u64;
            r.sources += v
                .records
                .iter()
                .map(|r| r.sources.len() as u64)
                .sum::<u64>();
        }
    }
    // Each record's latest version, keyed by (creation frame, id):
    // (frame written, lifespan, object).
    let mut latest: BTreeMap<(u32, u64), (u32, u32, u32)> = BTreeMap::new();
    store.for_each_record(j.id, u32::MAX, |frame, rec| {
        r.record_versions += 1;
        let lifespan = rec
            .last_frame
            .saturating_sub(rec.created_frame)
            .saturating_add(1);
        let entry = latest
            .entry((rec.created_frame, rec.id))
            .or_insert((frame, lifespan, rec.object));
        if frame >= entry.0 {
            *entry = (frame, lifespan, rec.object);
        }
        let samples = u64::from(rec.samples_count);
        r.samples += samples;
        r.samples_stored_bytes += u64::from(rec.samples_len);
        r.samples_raw_bytes += samples * super::PackedSample::BYTES as u64;
        if let Some(f) = per_frame.get_mut(&frame) {
            f.records_written += 1;
            f.samples += samples;
        }
    })?;
    r.records = latest.len() as u64;
    for &(_, lifespan, object) in latest.values() {
        *r.lifespan_histogram.entry(lifespan).or_insert(0) += 1;
        r.records_by_object
            .entry(object)
            .or_default()
            .add(1, u64::from(lifespan));
    }
    r.movies = movies_report(store, j.id)?;
    r.frame_details = match only {
        Some(f) => per_frame.remove(&f).into_iter().collect(),
        None => per_frame.into_values().collect(),
    };
    Ok(r)
}

/// The texture movies of job `job`'s frames (`None`: it stored none).
fn movies_report(store: &Store, job: u64) -> Result<Option<MoviesReport>, StoreError> {
    let mut r = MoviesReport::default();
    let mut distinct = std::collections::HashSet::new();
    for frame in store.frames_done(job)? {
        let Some(v) = store.frame_movies(job, frame)? else {
            continue;
        };
        for m in &v.movies {
            distinct.insert((m.triangle, m.back, m.patch, m.start));
            r.movie_frames += 1;
            r.movie_frames_stored += u64::from(m.texels > 0);
            r.texels += u64::from(m.texels);
        }
        r.stored_bytes += v.texels_zstd.len() as u64;
    }
    r.movies = distinct.len() as u64;
    r.raw_bytes = r.texels * 4;
    Ok((r.movie_frames > 0).then_some(r))
}

impl JobReport {
    /// The report of job `j` before anything is read of its frames.
    fn of(j: &JobValue) -> Self {
        JobReport {
            name: j.name.clone(),
            id: j.id,
            scene: j.scene.clone(),
            scene_hash: j.scene_hash.clone(),
            method: j.method.clone(),
            settings: j.settings.clone(),
            algorithm_revision: 1,
            size: format!("{}x{}", j.width, j.height),
            spp: j.spp,
            fps: j.fps,
            seed: j.seed,
            same_pattern: j.same_pattern,
            frames: format!("{}..{}", j.frame_start, j.frame_end),
            frames_done: j.frames_done,
            last_frame: j.last_frame,
            records: 0,
            record_versions: 0,
            samples: 0,
            samples_stored_bytes: 0,
            samples_raw_bytes: 0,
            exr_stored_bytes: 0,
            exr_raw_bytes: 0,
            record_value_bytes: 0,
            record_block_bytes: 0,
            radiance_records: 0,
            sources: 0,
            lifespan_histogram: BTreeMap::new(),
            records_by_object: BTreeMap::new(),
            moving_objects: None,
            frame_details: Vec::new(),
            state: None,
            movies: None,
        }
    }
}

/// Each finished frame of job `job` with its stored statistics (records
/// and samples still to count), its EXR bytes added to `r`.
fn frame_reports(
    store: &Store,
    job: u64,
    r: &mut JobReport,
) -> Result<BTreeMap<u32, FrameReport>, StoreError> {
    let mut per_frame = BTreeMap::new();
    for frame in store.frames_done(job)? {
        let v = store.frame(job, frame)?.expect("listed frame exists");
        r.exr_stored_bytes += u64::from(v.exr_stored_len);
        r.exr_raw_bytes = r.exr_raw_bytes.saturating_add(v.exr_len);
        let stats = store.frame_stats(job, frame)?.unwrap_or_default();
        per_frame.insert(
            frame,
            FrameReport {
                frame,
                records_written: 0,
                records_alive: stats.records_alive,
                records_created: stats.records_created,
                records_reused: stats.records_reused,
                records_replaced: stats.records_replaced,
                records_dropped: stats.records_dropped,
                mean_lifespan: stats.mean_lifespan,
                samples: 0,
                samples_reshot: stats.samples_reshot,
                cache_bytes: stats.cache_bytes,
                stored_bytes: stats.stored_bytes,
                exr_bytes: u64::from(v.exr_stored_len),
                rays: stats.rays,
            },
        );
    }
    Ok(per_frame)
}

fn ratio(raw: u64, stored: u64) -> String {
    if stored == 0 {
        "-".into()
    } else {
        format!("{:.2}", raw as f64 / stored as f64)
    }
}

/// The report as text. Per-frame rows only when `frames` (a job or a frame
/// was asked for).
pub fn to_text(r: &InspectReport, frames: bool) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "store {} (schema {}): {} bytes on disk, space amplification {:.2}; sample log {} bytes",
        r.path, r.schema_version, r.size_on_disk, r.space_amplification, r.sample_log_bytes
    );
    let _ = writeln!(
        s,
        "sample log {}: {} bytes referenced, {} unreferenced{}",
        r.sample_log_file,
        r.sample_log_referenced_bytes,
        r.sample_log_unreferenced_bytes,
        if r.sample_log_unreferenced_bytes > 0 {
            " (`radcache compact` reclaims them)"
        } else {
            ""
        }
    );
    if r.sample_log_tail_lost_frames {
        let _ = writeln!(
            s,
            "sample log {}: {} bytes past its committed length, holding the files of two \
             or more frames, which no crash leaves: the database lost commits (damaged); \
             the store refuses jobs and compaction",
            r.sample_log_file, r.sample_log_tail_bytes
        );
    } else if r.sample_log_tail_bytes > 0 {
        let _ = writeln!(
            s,
            "sample log {}: {} bytes past its committed length, which no value references \
             (a frame a crash cut off, or commits the database lost); the store's next \
             write cuts them off",
            r.sample_log_file, r.sample_log_tail_bytes
        );
    }
    let _ = writeln!(
        s,
        "{:<8} {:>10} {:>12} {:>14}",
        "tree", "keys", "key bytes", "value bytes"
    );
    for t in &r.trees {
        let _ = writeln!(
            s,
            "{:<8} {:>10} {:>12} {:>14}",
            t.name, t.keys, t.key_bytes, t.value_bytes
        );
    }
    for j in &r.jobs {
        job_text(&mut s, j);
        if frames {
            frame_table(&mut s, j, r.frame);
        }
    }
    s
}

/// A job's method settings as a reader wants them: `the defaults`, or the
/// settings that differ from the method's defaults as `name=value`, by the
/// names `--methods`, `POST /api/jobs` and a refused resume give them
/// ([`named_settings`](crate::method::settings::named_settings)), read as
/// this build reads them (a setting added since, at the value the job
/// ran). The stored JSON as it is where it cannot be read so (an unknown
/// method, a malformed value).
fn settings_text(method: &str, stored: &str) -> String {
    use crate::method::settings::{method_settings, named_settings};
    use crate::render::MethodSettings;
    let read_now = super::jobs::settings_as_read_now(stored);
    let (Ok(defaults), Ok(now)) = (
        method_settings(method, []),
        serde_json::from_str::<MethodSettings>(&read_now),
    ) else {
        return stored.to_string();
    };
    if now.name() != method {
        return stored.to_string(); // not this method's settings
    }
    let settings = now;
    let (now, defaults) = (named_settings(&settings), named_settings(&defaults));
    let names: BTreeSet<&String> = now.keys().chain(defaults.keys()).collect();
    // A value as `--methods` takes it: text unquoted; a path length left
    // unbounded has no name, so it shows as none.
    let text = |v: Option<&serde_json::Value>| match v {
        None => "none".to_string(),
        Some(serde_json::Value::String(s)) => s.clone(),
        Some(v) => v.to_string(),
    };
    let changed: Vec<(&String, String)> = names
        .into_iter()
        .filter(|name| now.get(*name) != defaults.get(*name))
        .map(|name| (name, text(now.get(name))))
        .collect();
    // Settings no name sets (a path length's Russian roulette) differ when
    // the named changes do not make the job's settings again: then the
    // stored JSON says them.
    let named_changes = changed.iter().map(|(n, v)| (n.as_str(), v.as_str()));
    let unnamed = method_settings(method, named_changes).ok().as_ref() != Some(&settings);
    let changed: Vec<String> = changed.iter().map(|(n, v)| format!("{n}={v}")).collect();
    match (changed.is_empty(), unnamed) {
        (true, false) => "the defaults".into(),
        (false, false) => format!("changed from the defaults: {}", changed.join(", ")),
        (_, true) => format!(
            "changed from the defaults{}{}, and in settings without a name: {read_now}",
            if changed.is_empty() { "" } else { ": " },
            changed.join(", ")
        ),
    }
}

/// Stored settings `stored` as JSON: an object of every setting by name
/// ([`named_settings`](crate::method::settings::named_settings)), as a
/// served job shows them and `POST /api/jobs` takes them back, read as this
/// build reads them (a setting added since, at the value the job ran).
/// Where they cannot be read so, the stored JSON without its method tag,
/// or the stored text where that is no JSON: never JSON inside a string
/// that is JSON.
fn settings_by_name<S: serde::Serializer>(stored: &str, out: S) -> Result<S::Ok, S::Error> {
    use crate::method::settings::{named_settings, untagged};
    use crate::render::MethodSettings;
    use serde::Serialize as _;
    let read_now = super::jobs::settings_as_read_now(stored);
    if let Ok(settings) = serde_json::from_str::<MethodSettings>(&read_now) {
        return named_settings(&settings).serialize(out);
    }
    match serde_json::from_str::<serde_json::Value>(stored) {
        Ok(v) => untagged(v).serialize(out),
        Err(_) => out.serialize_str(stored),
    }
}

/// A mean lifespan in JSON: `null` where none is set (0), as [`life_text`]
/// shows `-`.
fn null_when_unset<S: serde::Serializer>(mean_lifespan: &f64, out: S) -> Result<S::Ok, S::Error> {
    match *mean_lifespan > 0.0 {
        true => out.serialize_f64(*mean_lifespan),
        false => out.serialize_none(),
    }
}

/// A job's part of [`to_text`]: what it renders, its records, samples,
/// state and frames, and its lifespan histogram.
fn job_text(s: &mut String, j: &JobReport) {
    let _ = writeln!(
        s,
        "\njob {:?} (id {}): {} [{}], {} {} spp {}, fps {}, seed {}{}, frames {} last asked — {} frames done in all, the last finished {}",
        j.name,
        j.id,
        j.scene,
        j.scene_hash,
        j.method,
        j.size,
        j.spp,
        j.fps,
        j.seed,
        if j.same_pattern { ", same pattern" } else { "" },
        j.frames,
        j.frames_done,
        j.last_frame.map_or("-".into(), |f| f.to_string()),
    );
    let _ = writeln!(s, "  settings: {}", settings_text(&j.method, &j.settings));
    let now = crate::method::algorithm_revision(&j.method);
    let _ = writeln!(
        s,
        "  algorithm revision {}{}",
        j.algorithm_revision,
        match j.algorithm_revision == now {
            true => String::new(),
            false => format!(" (this build's is {now}: it does not resume the job)"),
        }
    );
    let _ = writeln!(
        s,
        "  records {}{} ({} B of rkyv values, {} B stored in blocks), samples {}: {} B stored / {} B raw (ratio {})",
        j.records,
        match j.record_versions {
            v if v > j.records => format!(" in {v} versions (written again in later frames)"),
            _ => String::new(),
        },
        j.record_value_bytes,
        j.record_block_bytes,
        j.samples,
        j.samples_stored_bytes,
        j.samples_raw_bytes,
        ratio(j.samples_raw_bytes, j.samples_stored_bytes)
    );
    if j.radiance_records > 0 {
        let _ = writeln!(
            s,
            "  radiance records {} of the records, with {} sources stored",
            j.radiance_records, j.sources
        );
    }
    if let Some(st) = &j.state {
        let _ = writeln!(
            s,
            "  carried state after frame {} (range from frame {}{}): {} records{}, {} B",
            st.frame,
            st.chain_start,
            st.chain_end.map_or(String::new(), |e| format!(" to {e}")),
            st.records,
            radiance_text(st),
            st.value_bytes
        );
    }
    if let Some(m) = &j.movies {
        let _ = writeln!(
            s,
            "  texture movies {} (mean length {:.2} frames), {} movie frames ({} stored, the others unchanged), {} texels: {} B stored / {} B raw (ratio {})",
            m.movies,
            m.mean_length(),
            m.movie_frames,
            m.movie_frames_stored,
            m.texels,
            m.stored_bytes,
            m.raw_bytes,
            ratio(m.raw_bytes, m.stored_bytes)
        );
    }
    let _ = writeln!(
        s,
        "  frames: {} B stored / {} B EXR (ratio {})",
        j.exr_stored_bytes,
        j.exr_raw_bytes,
        ratio(j.exr_raw_bytes, j.exr_stored_bytes)
    );
    let hist: Vec<String> = j
        .lifespan_histogram
        .iter()
        .map(|(l, n)| format!("{l}: {n}"))
        .collect();
    if !hist.is_empty() {
        let _ = writeln!(
            s,
            "  record lifespan (frames: records): {}",
            hist.join(", ")
        );
    }
    objects_text(s, j);
}

/// How many objects [`objects_text`] names.
const OBJECTS_SHOWN: usize = 6;

/// A job's records by object: moving against static where known, and the
/// objects with the most records.
fn objects_text(s: &mut String, j: &JobReport) {
    if j.records_by_object.is_empty() {
        return;
    }
    if let Some((moving, fixed)) = j.moving_and_static() {
        let _ = writeln!(
            s,
            "  records on moving objects: {} (mean lifespan {:.2} frames), on static objects: {} ({:.2} frames)",
            moving.records,
            moving.mean_lifespan(),
            fixed.records,
            fixed.mean_lifespan()
        );
    }
    let mut objects: Vec<(&u32, &ObjectRecords)> = j.records_by_object.iter().collect();
    objects.sort_by_key(|(object, r)| (std::cmp::Reverse(r.records), **object));
    let shown: Vec<String> = objects
        .iter()
        .take(OBJECTS_SHOWN)
        .map(|(object, r)| format!("{object}: {} ({:.2})", r.records, r.mean_lifespan()))
        .collect();
    let more = objects.len().saturating_sub(OBJECTS_SHOWN);
    let _ = writeln!(
        s,
        "  records by object (object: records (mean lifespan)): {}{}",
        shown.join(", "),
        if more > 0 {
            format!(", and {more} more objects")
        } else {
            String::new()
        }
    );
}

/// Where job `j`'s report was asked for `frame` (`inspect --frame`) and
/// the job has not finished it, the sentence saying so; `None` where the
/// frame is shown.
pub fn frame_not_done(j: &JobReport, frame: u32) -> Option<String> {
    if j.frame_details.iter().any(|f| f.frame == frame) {
        return None;
    }
    Some(format!(
        "frame {frame} is not among this job's finished frames ({} of frames {} done{})",
        j.frames_done,
        j.frames,
        match j.last_frame {
            Some(last) => format!(", the last {last}"),
            None => String::new(),
        }
    ))
}

/// A job's per-frame rows of [`to_text`]: records written, alive, created,
/// reused, replaced and dropped, mean lifespan, samples, samples re-shot,
/// cache bytes, bytes stored, EXR bytes, rays.
fn frame_table(s: &mut String, j: &JobReport, asked: Option<u32>) {
    if let Some(missing) = asked.and_then(|frame| frame_not_done(j, frame)) {
        let _ = writeln!(s, "  {missing}");
    } else if j.frame_details.is_empty() {
        let _ = writeln!(
            s,
            "  no finished frame to show ({} of frames {} done)",
            j.frames_done, j.frames
        );
    } else {
        let _ = writeln!(
            s,
            "  {:>6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>6} {:>9} {:>9} {:>10} {:>10} {:>9} {:>10}",
            "frame",
            "written",
            "alive",
            "created",
            "reused",
            "replaced",
            "dropped",
            "life",
            "samples",
            "re-shot",
            "cache B",
            "stored B",
            "exr B",
            "rays"
        );
        for f in &j.frame_details {
            let _ = writeln!(
                s,
                "  {:>6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>6} {:>9} {:>9} {:>10} {:>10} {:>9} {:>10}",
                f.frame,
                f.records_written,
                f.records_alive,
                f.records_created,
                f.records_reused,
                f.records_replaced,
                f.records_dropped,
                life_text(f.mean_lifespan),
                f.samples,
                f.samples_reshot,
                f.cache_bytes,
                f.stored_bytes,
                f.exr_bytes,
                f.rays
            );
        }
    }
}

/// A frame's mean lifespan for the table: "-" where the frame computed no
/// record or its method sets no life (`tcg`, `path`; see
/// [`FrameStats::mean_lifespan`](crate::method::FrameStats::mean_lifespan)).
fn life_text(mean_lifespan: f64) -> String {
    if mean_lifespan > 0.0 {
        format!("{mean_lifespan:.2}")
    } else {
        "-".into()
    }
}

#[cfg(test)]
mod tests {
    use super::settings_text;
    use crate::method::settings::method_settings;

    fn stored(method: &str, changes: &[(&str, &str)]) -> String {
        let settings = method_settings(method, changes.iter().copied()).expect("valid settings");
        serde_json::to_string(&settings).expect("serializes")
    }

    #[test]
    fn frames_without_a_set_life_show_a_dash_and_null() {
        assert_eq!(super::life_text(0.0), "-");
        assert_eq!(super::life_text(2.5), "2.50");
        #[derive(serde::Serialize)]
        struct Life(#[serde(serialize_with = "super::null_when_unset")] f64);
        let json = |life| serde_json::to_value(Life(life)).unwrap();
        assert_eq!(json(0.0), serde_json::Value::Null);
        assert_eq!(json(2.5), serde_json::json!(2.5));
    }

    #[test]
    fn settings_are_shown_as_what_differs_from_the_defaults() {
        for method in ["path", "ic", "trc", "tcg", "movies"] {
            assert_eq!(settings_text(method, &stored(method, &[])), "the defaults");
        }
        let changed = stored("trc", &[("at", "0.1"), ("accuracy", "0.3")]);
        assert_eq!(
            settings_text("trc", &changed),
            "changed from the defaults: accuracy=0.3, at=0.1"
        );
        let path = stored("path", &[("max_depth", "3")]);
        assert_eq!(
            settings_text("path", &path),
            "changed from the defaults: max_depth=3"
        );
        // A setting no name sets is not hidden.
        let mut unnamed: serde_json::Value = serde_json::from_str(&stored("trc", &[])).unwrap();
        let rr_start = unnamed
            .pointer_mut("/Trc/ic/length/rr_start")
            .expect("a path length");
        *rr_start = serde_json::json!(7);
        let shown = settings_text("trc", &unnamed.to_string());
        assert!(
            shown.starts_with("changed from the defaults, and in settings without a name: {")
                && shown.contains("\"rr_start\":7"),
            "{shown}"
        );
        let gradients = stored("trc", &[("gradients", "none")]);
        assert_eq!(
            settings_text("trc", &gradients),
            "changed from the defaults: gradients=none"
        );
        // What cannot be compared is shown as stored.
        let other = stored("ic", &[]);
        assert_eq!(settings_text("trc", &other), other);
        assert_eq!(settings_text("nope", &changed), changed);
        assert_eq!(settings_text("trc", "{not json"), "{not json");
    }

    /// A job's `settings` in `inspect --json` are an object of every
    /// setting by name, which the names take back to the same settings; not
    /// their JSON text in a string. Settings this build cannot read are the
    /// stored JSON (untagged), or the stored text where that is no JSON.
    #[test]
    fn json_settings_are_an_object_by_name() {
        use crate::store::schema::JobValue;
        let as_json = |settings: String| {
            let job = JobValue::for_test("trc", settings);
            serde_json::to_value(super::JobReport::of(&job)).unwrap()["settings"].clone()
        };
        let changes = [("at", "0.1"), ("accuracy", "0.3"), ("strata", "8x24")];
        let shown = as_json(stored("trc", &changes));
        let object = shown.as_object().expect("an object");
        assert_eq!(shown["at"].to_string(), "0.1", "{shown}");
        assert_eq!(shown["accuracy"].to_string(), "0.3", "{shown}");
        assert_eq!(shown["strata"], "8x24", "{shown}");
        assert_eq!(shown["keep_paths"], true, "{shown}");
        let text = |v: &serde_json::Value| match v {
            serde_json::Value::String(s) => s.clone(),
            v => v.to_string(),
        };
        let pairs: Vec<(String, String)> =
            object.iter().map(|(k, v)| (k.clone(), text(v))).collect();
        let again = method_settings("trc", pairs.iter().map(|(k, v)| (&k[..], &v[..])));
        assert_eq!(again, method_settings("trc", changes));
        assert_eq!(
            as_json(r#"{"Radiosity":{"patches":4}}"#.into()),
            serde_json::json!({"patches": 4})
        );
        assert_eq!(as_json("{not json".into()), "{not json");
    }
}
