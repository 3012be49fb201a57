//! A job's frames: each checkpointed in one atomic commit (EXR, records,
//! samples, statistics, the carried state and the job's progress), and
//! read back.

use super::samples::{compress, decompress, SampleBlock, SampleLog};
use super::schema::{
    FrameSourcesValue, FrameValue, JobValue, MovieFramesValue, MovieValue, RecordBlock,
    RecordSourcesValue, RecordValue, SourceValue, StateHeadValue, StateRecordValue, StatsValue,
};
use super::{append_record_block, encode, keys, now_unix, Store, StoreError};
use sled::transaction::{ConflictableTransactionError, TransactionError};
use sled::Transactional;
use std::collections::hash_map::{Entry, HashMap};

/// The most texels one frame's movies may store, and the most vertices
/// of its global pass: 2^28 (a GiB of RGBE), which a reader may allocate
/// before decompressing. A movie stores its band, about R²/2 texels
/// (526,845 at R = 1024, the finest `--movies-max-resolution`), so some
/// 509 movies at R = 1024 fill it (4096 would hold 2.16 G texels): the
/// writer refuses a frame past it ([`MovieFramesValue::check_storable`])
/// rather than store one that its reader calls corrupt.
const MAX_STORED_TEXELS: usize = 1 << 28;

/// Whether `texels` texels (of `movies` movies) are within
/// [`MAX_STORED_TEXELS`].
fn texels_within_limit(texels: u64, movies: usize) -> Result<(), String> {
    if texels > MAX_STORED_TEXELS as u64 {
        return Err(format!(
            "{texels} texels in one frame's {movies} movies, more than {MAX_STORED_TEXELS}"
        ));
    }
    Ok(())
}

/// Whether `vertices` global-pass vertices are within [`MAX_STORED_TEXELS`].
fn vertices_within_limit(vertices: u64) -> Result<(), String> {
    if vertices > MAX_STORED_TEXELS as u64 {
        return Err(format!(
            "{vertices} global-pass vertices, more than {MAX_STORED_TEXELS}"
        ));
    }
    Ok(())
}

impl MovieFramesValue {
    /// Whether its counts are within what [`Self::texels`] and
    /// [`Self::global`] read back (`MAX_STORED_TEXELS`): the writer's
    /// check before it commits the frame.
    pub fn check_storable(&self) -> Result<(), String> {
        texels_within_limit(self.stored_texels(), self.movies.len())?;
        vertices_within_limit(u64::from(self.global_vertices))
    }

    /// The texels the movies say it stores.
    fn stored_texels(&self) -> u64 {
        self.movies.iter().map(|m| u64::from(m.texels)).sum()
    }

    /// The global pass's indirect irradiance per vertex (RGBE decoded).
    pub fn global(&self) -> Result<Vec<glam::Vec3>, String> {
        vertices_within_limit(u64::from(self.global_vertices))?;
        let n = self.global_vertices as usize;
        let raw = decompress(&self.global_zstd, n * 4)?;
        Ok(raw
            .chunks_exact(4)
            .map(|c| super::rgbe::decode([c[0], c[1], c[2], c[3]]))
            .collect())
    }

    /// Each movie's stored texels (RGBE decoded), in movie order.
    pub fn texels(&self) -> Result<Vec<Vec<glam::Vec3>>, String> {
        // A damaged count must not make the decompression allocate it.
        let total = self.stored_texels();
        texels_within_limit(total, self.movies.len())?;
        let raw = decompress(&self.texels_zstd, total as usize * 4)?;
        let mut rgbe = raw
            .chunks_exact(4)
            .map(|c| super::rgbe::decode([c[0], c[1], c[2], c[3]]));
        Ok(self
            .movies
            .iter()
            .map(|m| rgbe.by_ref().take(m.texels as usize).collect())
            .collect())
    }
}

impl FrameSourcesValue {
    /// The sources of the radiance records among `records` (those with
    /// [`crate::cache::IrradianceRecord::eas`]), in id order; `None` when
    /// none is a radiance record.
    pub fn of(records: &[crate::cache::IrradianceRecord]) -> Option<Self> {
        let mut out: Vec<RecordSourcesValue> = records
            .iter()
            .filter_map(|r| {
                let sources = r.eas.as_deref()?.iter().map(|e| SourceValue {
                    offset: e.offset.to_array(),
                    solid_angle: e.solid_angle,
                    irradiance: e.irradiance.to_array(),
                });
                Some(RecordSourcesValue {
                    id: r.id,
                    sources: sources.collect(),
                })
            })
            .collect();
        // A record given twice keeps its last version, as in its block.
        out.reverse();
        out.sort_by_key(|r| r.id);
        out.dedup_by_key(|r| r.id);
        (!out.is_empty()).then_some(FrameSourcesValue { records: out })
    }
}

/// One record of a frame with its samples, ready to store.
pub struct RecordCommit {
    pub record: RecordValue,
    /// The record's samples in cell order, stored form (may be empty).
    /// [`Store::commit_frame`] fills in the record's sample location.
    pub samples: SampleBlock,
}

/// Everything one frame writes.
pub struct FrameCommit<'a> {
    pub frame: u32,
    pub width: u32,
    pub height: u32,
    /// The frame's EXR file bytes.
    pub exr: &'a [u8],
    pub records: Vec<RecordCommit>,
    pub stats: &'a crate::method::FrameStats,
    /// The frame's changes of a stateful method's carried state.
    pub state: Option<StateCommit<'a>>,
    /// The frame's texture movies (`movies`).
    pub movies: Option<&'a MovieFramesValue>,
    /// The sources of the radiance records among `records`
    /// ([`FrameSourcesValue::of`]).
    pub sources: Option<&'a FrameSourcesValue>,
}

/// A stateful method's state changes of one frame, with the chain they
/// belong to (see [`StateHeadValue`]).
pub struct StateCommit<'a> {
    pub chain_start: u32,
    pub chain_end: Option<u32>,
    pub changes: &'a crate::method::StateChanges,
}

/// A frame's bulk values once in the sample log ([`Store::append_frame`]).
struct LoggedFrame {
    frame: FrameValue,
    /// The encoded [`FrameRecordsValue`](super::schema::FrameRecordsValue) of the frame's record block, if it
    /// has records.
    records: Option<Vec<u8>>,
    /// The samples' size before compression, for the frame's statistics.
    samples_raw: u64,
}

/// Everything one frame's transaction writes, encoded before it starts
/// (sled may run a transaction's closure more than once).
struct FrameRows {
    /// The frame's key in the per-frame trees.
    key: [u8; 12],
    /// Whether the frame was written before: the per-frame rows it now
    /// writes none of are removed.
    again: bool,
    state: StateRows,
    state_head_key: [u8; 8],
    records: Option<Vec<u8>>,
    movies: Option<Vec<u8>>,
    sources: Option<Vec<u8>>,
    /// The sample log's new committed length.
    log_len: [u8; 8],
    /// Encoded last: it counts the bytes of the others
    /// ([`FrameRows::tree_bytes`]).
    stats: Vec<u8>,
    frame: Vec<u8>,
    job_key: Vec<u8>,
    job: Vec<u8>,
}

impl FrameRows {
    /// Bytes of the values written to the trees but the stats (which
    /// count them: [`StatsValue::stored_bytes`]).
    fn tree_bytes(&self) -> usize {
        [&self.records, &self.movies, &self.sources, &self.state.head]
            .into_iter()
            .flatten()
            .chain(self.state.put.iter().map(|(_, v)| v))
            .chain([&self.frame, &self.job])
            .map(Vec::len)
            .sum()
    }
}

/// A frame's changes of the `state` tree, encoded: rows put, rows removed
/// and the new head.
#[derive(Default)]
struct StateRows {
    put: Vec<([u8; 16], Vec<u8>)>,
    removed: Vec<[u8; 16]>,
    head: Option<Vec<u8>>,
}

impl StateRows {
    fn new(job: u64, frame: u32, sc: &StateCommit) -> Self {
        let put = sc
            .changes
            .put
            .iter()
            .map(|(id, data)| {
                let value = StateRecordValue {
                    frame,
                    data: data.clone(),
                };
                (keys::state_record(job, *id), encode(&value))
            })
            .collect();
        let removed = sc
            .changes
            .removed
            .iter()
            .map(|&id| keys::state_record(job, id))
            .collect();
        let head = StateHeadValue {
            frame,
            chain_start: sc.chain_start,
            chain_end: sc.chain_end,
            global: sc.changes.global.clone(),
        };
        StateRows {
            put,
            removed,
            head: Some(encode(&head)),
        }
    }
}

impl Store {
    pub fn frame_done(&self, job: u64, frame: u32) -> Result<bool, StoreError> {
        self.frames
            .contains_key(keys::frame(job, frame))
            .map_err(|e| StoreError::sled(&self.path, e))
    }

    /// Frames of `job` that are stored, in order.
    pub fn frames_done(&self, job: u64) -> Result<Vec<u32>, StoreError> {
        let mut out = Vec::new();
        for key in self.frames.scan_prefix(keys::job_prefix(job)).keys() {
            let key = key.map_err(|e| StoreError::sled(&self.path, e))?;
            let (_, frame) = keys::parse_frame(&key)
                .ok_or_else(|| self.corrupt("frames", &key, "malformed key"))?;
            out.push(frame);
        }
        Ok(out)
    }

    /// Writes one finished frame of `job` — image, records with samples,
    /// stats and progress: the records' sample blocks appended to the
    /// sample log and synced, then everything else and the log's new
    /// committed length in one atomic transaction, then a flush. Only
    /// when this returns `Ok` is the frame acknowledged; `job` is updated
    /// to the stored progress.
    pub fn commit_frame(&self, job: &mut JobValue, c: FrameCommit) -> Result<(), StoreError> {
        // Refused before anything is written: what its reader would call
        // corrupt.
        if let Some(movies) = c.movies {
            movies.check_storable().map_err(|detail| StoreError::Job {
                path: self.path.clone(),
                job: job.name.clone(),
                detail: format!(
                    "frame {}: its texture movies are too large to store: {detail} \
                         (lower --movies-max-resolution or --movies-texels-per-pixel; \
                         a server job's `max_resolution` or `texels_per_pixel`)",
                    c.frame
                ),
            })?;
        }
        let mut log = self.lock_log();
        let result = self.commit_frame_locked(&mut log, job, c);
        match &result {
            // The transaction references the appends, flushed or not.
            Ok(_) => log.commit(),
            // No transaction references them: cut them off now. If that
            // fails too, the commit's own error is the one to report: the
            // next open cuts the tail off as after a crash.
            Err(_) => {
                if let Err(e) = log.rollback() {
                    eprintln!(
                        "warning: {} (left for the next open to cut off)",
                        self.log_error(e)
                    );
                }
            }
        }
        let progressed = result?;
        self.flush()?;
        *job = progressed;
        Ok(())
    }

    /// Appends the frame's bulk values to the sample log, then writes its
    /// rows and the job's progress in one transaction; returns the
    /// progress.
    fn commit_frame_locked(
        &self,
        log: &mut SampleLog,
        job: &JobValue,
        c: FrameCommit,
    ) -> Result<JobValue, StoreError> {
        // A frame written again (by another chain of a stateful method)
        // replaces the record block, movies and sources of its former self
        // (or, writing none, removes them).
        let again = self.frame_done(job.id, c.frame)?;
        let log_start = log.end();
        let logged =
            self.append_frame(log, job.id, c.frame, (c.width, c.height), c.exr, c.records)?;
        let mut progressed = job.clone();
        if !again {
            progressed.frames_done += 1;
        }
        progressed.last_frame = Some(c.frame);
        progressed.updated_unix = now_unix();
        let mut rows = FrameRows {
            key: keys::frame(job.id, c.frame),
            again,
            state: c
                .state
                .as_ref()
                .map(|sc| StateRows::new(job.id, c.frame, sc))
                .unwrap_or_default(),
            state_head_key: keys::state_head(job.id),
            records: logged.records,
            movies: c.movies.map(encode),
            sources: c.sources.map(encode),
            log_len: log.end().to_be_bytes(),
            stats: Vec::new(), // below, once the others are encoded
            frame: encode(&logged.frame),
            job_key: keys::job(&job.name),
            job: encode(&progressed),
        };
        rows.stats = encode(&StatsValue {
            stats: c.stats.clone(),
            samples_raw_bytes: logged.samples_raw,
            stored_bytes: log.end() - log_start + rows.tree_bytes() as u64,
        });
        self.write_frame_rows(&rows)?;
        Ok(progressed)
    }

    /// Writes `rows` in one sled transaction over the trees they touch.
    fn write_frame_rows(&self, rows: &FrameRows) -> Result<(), StoreError> {
        let key = &rows.key[..];
        let result: Result<(), TransactionError<()>> = (
            &self.frames,
            &self.records,
            &self.meta,
            &self.stats,
            &self.state,
            &self.jobs,
            &self.movies,
            &self.sources,
        )
            .transaction(
                |(frames, records, meta, stats, state_tree, jobs, movies, sources)| {
                    for k in &rows.state.removed {
                        state_tree.remove(&k[..])?;
                    }
                    for (k, v) in &rows.state.put {
                        state_tree.insert(&k[..], &v[..])?;
                    }
                    if let Some(head) = &rows.state.head {
                        state_tree.insert(&rows.state_head_key[..], &head[..])?;
                    }
                    // A frame written again replaces its former value in
                    // each, or removes it where it writes none.
                    let per_frame = [
                        (records, &rows.records),
                        (movies, &rows.movies),
                        (sources, &rows.sources),
                    ];
                    for (tree, value) in per_frame {
                        match value {
                            Some(v) => {
                                tree.insert(key, &v[..])?;
                            }
                            None if rows.again => {
                                tree.remove(key)?;
                            }
                            None => {}
                        }
                    }
                    meta.insert(keys::META_SAMPLES_LOG_LEN, &rows.log_len[..])?;
                    stats.insert(key, &rows.stats[..])?;
                    frames.insert(key, &rows.frame[..])?;
                    jobs.insert(&rows.job_key[..], &rows.job[..])?;
                    Ok::<(), ConflictableTransactionError<()>>(())
                },
            );
        result.map_err(|e| match e {
            TransactionError::Storage(s) => StoreError::sled(&self.path, s),
            TransactionError::Abort(()) => unreachable!("the transaction never aborts"),
        })
    }

    /// Appends frame `frame`'s bulk values to the sample log and syncs it:
    /// its EXR file, each record's samples, then the records as one block
    /// (in id order, after their samples: it says where they lie). What
    /// the frame's transaction then points at.
    fn append_frame(
        &self,
        log: &mut SampleLog,
        job: u64,
        frame: u32,
        (width, height): (u32, u32),
        exr: &[u8],
        commits: Vec<RecordCommit>,
    ) -> Result<LoggedFrame, StoreError> {
        let exr_zstd = compress(exr);
        let frame_value = FrameValue {
            width,
            height,
            exr_len: exr.len() as u64,
            exr_offset: log.append(&exr_zstd).map_err(|e| self.log_error(e))?,
            exr_stored_len: exr_zstd.len() as u32,
        };
        drop(exr_zstd);
        let mut records = Vec::with_capacity(commits.len());
        let mut samples_raw = 0u64;
        for rc in commits {
            let mut record = rc.record;
            (
                record.samples_count,
                record.samples_offset,
                record.samples_len,
            ) = if rc.samples.is_empty() {
                (0, 0, 0)
            } else {
                samples_raw += rc.samples.raw_bytes();
                let offset = log
                    .append(&rc.samples.zstd)
                    .map_err(|e| self.log_error(e))?;
                (rc.samples.count, offset, rc.samples.zstd.len() as u32)
            };
            records.push(record);
        }
        // A record given twice keeps its last version, as a second insert
        // under its key did in schema 3.
        records.sort_by_key(|r| r.id);
        records.reverse();
        records.dedup_by_key(|r| r.id);
        records.reverse();
        let records_value = if records.is_empty() {
            None
        } else {
            let block = RecordBlock {
                job,
                frame,
                records,
            };
            let value = append_record_block(log, &block).map_err(|e| self.log_error(e))?;
            Some(encode(&value))
        };
        if log.end() > log.committed() {
            log.sync().map_err(|e| self.log_error(e))?;
        }
        Ok(LoggedFrame {
            frame: frame_value,
            records: records_value,
            samples_raw,
        })
    }

    /// The sources of the radiance records frame `frame` of `job` wrote
    /// (`None`: it wrote none, or was stored before schema 9).
    pub fn frame_sources(
        &self,
        job: u64,
        frame: u32,
    ) -> Result<Option<FrameSourcesValue>, StoreError> {
        self.get("sources", &keys::frame(job, frame))
    }

    /// The texture movies stored with frame `frame` of `job` (`movies`).
    pub fn frame_movies(
        &self,
        job: u64,
        frame: u32,
    ) -> Result<Option<MovieFramesValue>, StoreError> {
        let key = keys::frame(job, frame);
        match self
            .movies
            .get(key)
            .map_err(|e| StoreError::sled(&self.path, e))?
        {
            Some(bytes) => Ok(Some(self.decode("movies", &key, &bytes)?)),
            None => Ok(None),
        }
    }

    /// Every movie of frame `frame` of `job` with its texels (RGBE
    /// decoded), those stored with an earlier frame fetched from there.
    pub fn frame_movie_texels(
        &self,
        job: u64,
        frame: u32,
    ) -> Result<Vec<(MovieValue, Vec<glam::Vec3>)>, StoreError> {
        let Some(value) = self.frame_movies(job, frame)? else {
            return Ok(Vec::new());
        };
        // Earlier frames' movies and their decoded texels, read once each.
        let mut earlier: HashMap<u32, (MovieFramesValue, Vec<Vec<glam::Vec3>>)> = HashMap::new();
        let corrupt =
            |f: u32, detail: String| self.corrupt("movies", &keys::frame(job, f), &detail);
        let own = value.texels().map_err(|e| corrupt(frame, e))?;
        let mut out = Vec::with_capacity(value.movies.len());
        for (m, texels) in value.movies.iter().zip(own) {
            if m.texels > 0 || m.stored_at == frame {
                out.push((*m, texels));
                continue;
            }
            let (there, texels) = match earlier.entry(m.stored_at) {
                Entry::Occupied(e) => e.into_mut(),
                Entry::Vacant(e) => {
                    let v = self.frame_movies(job, m.stored_at)?.ok_or_else(|| {
                        corrupt(
                            frame,
                            format!(
                                "a movie's texels are in frame {}, which has none",
                                m.stored_at
                            ),
                        )
                    })?;
                    let t = v.texels().map_err(|err| corrupt(m.stored_at, err))?;
                    e.insert((v, t))
                }
            };
            let found = there
                .movies
                .iter()
                .zip(texels.iter())
                .find(|(o, _)| {
                    (o.triangle, o.back, o.patch, o.start) == (m.triangle, m.back, m.patch, m.start)
                        && o.texels > 0
                })
                .map(|(_, t)| t.clone())
                .ok_or_else(|| {
                    corrupt(
                        frame,
                        format!(
                            "movie of triangle {} not stored in frame {}",
                            m.triangle, m.stored_at
                        ),
                    )
                })?;
            out.push((*m, found));
        }
        Ok(out)
    }

    pub fn frame(&self, job: u64, frame: u32) -> Result<Option<FrameValue>, StoreError> {
        self.get("frames", &keys::frame(job, frame))
    }

    /// The EXR bytes of a stored frame.
    pub fn frame_exr(&self, job: u64, frame: u32) -> Result<Option<Vec<u8>>, StoreError> {
        let key = keys::frame(job, frame);
        let Some(v) = self.frame(job, frame)? else {
            return Ok(None);
        };
        let in_log = |d: String| {
            self.log_error(format!(
                "EXR of {} at offset {}: {d}",
                self.describe_key(&key),
                v.exr_offset
            ))
        };
        let stored = self
            .lock_log()
            .read(v.exr_offset, v.exr_stored_len)
            .map_err(in_log)?;
        let exr = decompress(&stored, v.exr_len as usize).map_err(in_log)?;
        Ok(Some(exr))
    }

    pub fn frame_stats(&self, job: u64, frame: u32) -> Result<Option<StatsValue>, StoreError> {
        self.get("stats", &keys::frame(job, frame))
    }
}

impl RecordCommit {
    /// A record created or changed in `frame`, with its samples in their
    /// stored form.
    pub fn from_record(
        record: &crate::cache::IrradianceRecord,
        samples: SampleBlock,
        strata: crate::cache::gather::Strata,
        frame: u32,
    ) -> Self {
        let v = |v: glam::Vec3| v.to_array();
        let has = !samples.is_empty();
        RecordCommit {
            record: RecordValue {
                id: record.id,
                created_frame: record.created_frame,
                last_frame: frame,
                position: v(record.position),
                normal: v(record.normal),
                irradiance: v(record.irradiance),
                grad_translation: record.grad_translation.map(v),
                grad_rotation: record.grad_rotation.map(v),
                radius: record.radius,
                object: record.object,
                strata_theta: if has { strata.theta } else { 0 },
                strata_phi: if has { strata.phi } else { 0 },
                // Filled in by `Store::commit_frame`.
                samples_count: 0,
                samples_offset: 0,
                samples_len: 0,
            },
            samples,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::FrameStats;

    /// A frame's movies: `movies` movies storing `texels` texels each
    /// (nothing compressed: only the counts are looked at).
    fn movies(movies: u32, texels: u32) -> MovieFramesValue {
        MovieFramesValue {
            movies: (0..movies)
                .map(|triangle| MovieValue {
                    triangle,
                    back: false,
                    patch: 1,
                    resolution: 1024,
                    start: 0,
                    texels,
                    stored_at: 0,
                })
                .collect(),
            texels_zstd: Vec::new(),
            global_vertices: 0,
            global_zstd: Vec::new(),
        }
    }

    /// The texels a movie at 1024 texels along an edge stores (its band:
    /// texel `(i, j)` where `i + j ≤ R + 1`).
    const BAND_1024: u32 = 526_845;

    #[test]
    fn a_band_at_1024_is_as_counted() {
        let r = 1024u32;
        let band: u32 = (0..r)
            .map(|j| (0..r).filter(|i| i + j <= r + 1).count() as u32)
            .sum();
        assert_eq!(band, BAND_1024);
    }

    /// The writer's limit is the reader's: 509 movies at R = 1024 fit,
    /// 510 do not, and neither does a global pass past it; the reader
    /// refuses what the writer refuses before it decompresses anything.
    #[test]
    fn the_writer_refuses_what_the_reader_would_call_corrupt() {
        assert!(movies(509, BAND_1024).check_storable().is_ok());
        let over = movies(510, BAND_1024);
        let e = over.check_storable().unwrap_err();
        assert!(
            e.contains("268690950 texels") && e.contains("510 movies"),
            "{e}"
        );
        assert_eq!(over.texels().unwrap_err(), e);
        // 4096 movies at 1024: counted without overflow.
        let e = movies(4096, BAND_1024).check_storable().unwrap_err();
        assert!(e.contains("2157957120 texels"), "{e}");
        let mut global = movies(1, 16);
        global.global_vertices = (MAX_STORED_TEXELS + 1) as u32;
        let e = global.check_storable().unwrap_err();
        assert_eq!(global.global().unwrap_err(), e);
        global.global_vertices = MAX_STORED_TEXELS as u32;
        assert!(global.check_storable().is_ok());
    }

    /// A frame whose movies are past the limit is refused with an error
    /// naming the frame and the count, and nothing of it is stored.
    #[test]
    fn a_frame_whose_movies_are_past_the_limit_is_not_committed() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&dir.path().join("db")).unwrap();
        let spec = crate::store::schema::JobValue::for_test("movies", "Movies(..)".into()).spec;
        let mut job = store.begin_job(&spec, false).unwrap();
        let before = job.clone();
        let over = movies(510, BAND_1024);
        let stats = FrameStats::default();
        let e = store
            .commit_frame(
                &mut job,
                FrameCommit {
                    frame: 1,
                    width: 8,
                    height: 8,
                    exr: &[1, 2, 3],
                    records: Vec::new(),
                    stats: &stats,
                    state: None,
                    movies: Some(&over),
                    sources: None,
                },
            )
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("frame 1") && e.contains("268690950 texels"),
            "{e}"
        );
        assert!(!store.frame_done(job.id, 1).unwrap());
        assert_eq!(job, before);
        assert_eq!(store.frame_movies(job.id, 1).unwrap(), None);
    }
}
