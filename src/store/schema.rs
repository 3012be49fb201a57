//! Value schemas of store schema version 9
//! (`migrations/0009_record_sources.md`: the `sources` tree holds
//! [`FrameSourcesValue`]s), on top of 8
//! (`migrations/0008_frame_footprint.md`: [`StatsValue`] gained the bytes
//! a frame stored and, in its statistics, the samples it shot again and
//! its cache's bytes in memory; the schema-7 value is in [`super::v7`]), on
//! top of 7 (no type here changed:
//! `migrations/0007_radiance_records_in_state.md` changed the method-defined
//! bytes of `trc`'s and `tcg`'s [`StateRecordValue`]s), on top of 6
//! (`migrations/0006_movies.md`: the `movies` tree holds
//! [`MovieFramesValue`]s), on top of 5
//! (`migrations/0005_log_generations.md`, on top of
//! `migrations/0004_record_blocks.md`, `migrations/0003_sample_log.md`,
//! `migrations/0002_state_and_identity.md` and `migrations/0001_initial.md`;
//! the types schema 3 changed are kept in [`super::v2`], those schema 2
//! changed in [`super::v1`]; schema 4 changed where [`RecordValue`]s are
//! kept, not the type; schema 5 changed no type, only which file the
//! offsets below point into: the log `meta.samples_log_generation` names).
//! Every value is an rkyv 0.8 archive, validated (bytecheck) when read.
//! Bulk values live in the sample log ([`super::samples`]), zstd-compressed:
//! frame EXR files (the frame says where), each frame's records as one
//! [`RecordBlock`] (its [`FrameRecordsValue`] says where) and each record's
//! samples (the record says where).
//! Changing any of these types is a schema change: bump
//! [`super::migrate::CURRENT_VERSION`], add a migration and a
//! `migrations/NNNN_*.md`.
//!
//! A job's description ([`JobSpec`]) and a frame's statistics
//! ([`crate::method::FrameStats`]) are stored as they are, embedded in
//! [`JobValue`] and [`StatsValue`]: a field added to either is stored (and,
//! for the job, compared on resume) without another list to update.

use rkyv::{Archive, Deserialize, Serialize};

/// What a job renders: compared with the stored job on every `render`
/// ([`super::Store::begin_job`]), embedded in its [`JobValue`].
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct JobSpec {
    pub name: String,
    /// `builtin:NAME` or the scene file path as given.
    pub scene: String,
    /// FNV-1a 64 of the scene file bytes (then `+` and the hash of the
    /// external buffers and images it references, if any), or of
    /// `builtin:NAME`, in hex. Schema-1 jobs of scene files carry
    /// `HASH+v1` (their external files were not hashed).
    pub scene_hash: String,
    pub method: String,
    /// The method settings as serde JSON (`MethodSettings`); compared as
    /// JSON values, so formatting never matters.
    pub settings: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub fps: f32,
    pub seed: u64,
    pub same_pattern: bool,
    /// Frame range of the last `render` of this job (half-open).
    pub frame_start: u32,
    pub frame_end: u32,
}

/// `jobs` value: what a job renders and how far it got.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct JobValue {
    /// Prefix of the job's keys in the other trees.
    pub id: u64,
    pub spec: JobSpec,
    /// Progress: frames acknowledged so far (each one has a `frames` entry).
    pub frames_done: u32,
    /// Last acknowledged frame, if any.
    pub last_frame: Option<u32>,
    pub created_unix: u64,
    pub updated_unix: u64,
}

#[cfg(test)]
impl JobValue {
    /// A job `j` of `method` with `settings` (JSON text), frames 0..2 of
    /// `cube-in-box` at 8×8, none done: unit tests' stored job.
    pub fn for_test(method: &str, settings: String) -> JobValue {
        JobValue {
            id: 1,
            spec: JobSpec {
                name: "j".into(),
                scene: "builtin:cube-in-box".into(),
                scene_hash: "0".into(),
                method: method.into(),
                settings,
                width: 8,
                height: 8,
                spp: 4,
                fps: 24.0,
                seed: 0,
                same_pattern: false,
                frame_start: 0,
                frame_end: 2,
            },
            frames_done: 0,
            last_frame: None,
            created_unix: 0,
            updated_unix: 0,
        }
    }
}

/// A job reads as its spec (`job.scene`, `job.width`, …).
impl std::ops::Deref for JobValue {
    type Target = JobSpec;
    fn deref(&self) -> &JobSpec {
        &self.spec
    }
}

/// `frames` value: one finished frame. Its EXR file (as written to
/// `--out`), zstd-compressed, lies in the sample log (a bulk value kept
/// out of sled, like the samples).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FrameValue {
    pub width: u32,
    pub height: u32,
    /// Length of the EXR file before zstd.
    pub exr_len: u64,
    /// Where the compressed EXR lies in the sample log, and its length.
    pub exr_offset: u64,
    pub exr_stored_len: u32,
}

/// One version of an irradiance record (written in its creation frame),
/// with where its samples lie in the sample log: an element of a frame's
/// [`RecordBlock`] (schema 3: the `records` value under
/// `job · frame · record id`).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RecordValue {
    pub id: u64,
    pub created_frame: u32,
    /// Last frame the record may be used in (inclusive); lifespan is
    /// `last_frame − created_frame + 1` (1 for `ic`).
    pub last_frame: u32,
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub irradiance: [f32; 3],
    pub grad_translation: [[f32; 3]; 3],
    pub grad_rotation: [[f32; 3]; 3],
    pub radius: f32,
    pub object: u32,
    /// Strata `M × N` of the record's samples (0 × 0 when it has none).
    pub strata_theta: u32,
    pub strata_phi: u32,
    /// The record's samples: `samples_count` 8-byte samples, a
    /// [`super::samples::SampleBlock`] of `samples_len` bytes at
    /// `samples_offset` in `samples.log` (all 0 when it has none).
    pub samples_count: u32,
    pub samples_offset: u64,
    pub samples_len: u32,
}

/// `records` value under `job · frame`: where the records written in that
/// frame lie in the sample log, as one [`RecordBlock`] (no key when the
/// frame wrote none).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FrameRecordsValue {
    /// Records in the block.
    pub count: u32,
    /// The smallest and largest record id in the block (0 when empty).
    pub first_id: u64,
    pub last_id: u64,
    /// Where the zstd-compressed block lies in `samples.log`, its length
    /// there, and the length of its rkyv archive before zstd.
    pub offset: u64,
    pub stored_len: u32,
    pub raw_len: u32,
}

/// A frame's records in the sample log (rkyv archive, zstd-compressed):
/// every record version written in `frame` of job id `job`, in id order.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RecordBlock {
    pub job: u64,
    pub frame: u32,
    pub records: Vec<RecordValue>,
}

/// `stats` value: the [`crate::method::FrameStats`] of one frame, whole,
/// and what the store measured of the frame (schema 8 added
/// `stored_bytes` and the statistics' `samples_reshot` and `cache_bytes`:
/// `migrations/0008_frame_footprint.md`; the schema-7 value is in
/// [`super::v7`]).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct StatsValue {
    pub stats: crate::method::FrameStats,
    /// Uncompressed bytes of the frame's samples (for compression ratios).
    pub samples_raw_bytes: u64,
    /// Bytes the frame's checkpoint wrote: its appends to the sample log
    /// (EXR, samples, record block) and the values it put in the trees
    /// (frame, records, carried state, movies, job), its own statistics
    /// aside. 0 for frames stored before schema 8.
    pub stored_bytes: u64,
}

/// Stats read as the frame's [`crate::method::FrameStats`].
impl std::ops::Deref for StatsValue {
    type Target = crate::method::FrameStats;
    fn deref(&self) -> &crate::method::FrameStats {
        &self.stats
    }
}
/// `state` value under `job id`: the head of a job's carried method state
/// (written with every frame of a stateful method, in the frame's batch).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct StateHeadValue {
    /// The state is the one after this frame.
    pub frame: u32,
    /// The frame the method started from (its state depends on it).
    pub chain_start: u32,
    /// The end of the range rendered, for methods that look ahead (their
    /// frames depend on it); `None` for the others.
    pub chain_end: Option<u32>,
    /// The method-wide state (method-defined bytes).
    pub global: Vec<u8>,
}

/// `state` value under `job id · record id`: one record of a job's carried
/// method state.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct StateRecordValue {
    /// The frame that wrote this version.
    pub frame: u32,
    /// The record's state (method-defined bytes).
    pub data: Vec<u8>,
}

/// `sources` value under `job · frame` (schema 9,
/// `migrations/0009_record_sources.md`): the equivalent area light sources
/// of the radiance records (`--ic-glossy eas`) whose versions the frame
/// wrote to its [`RecordBlock`], in id order (no key when it wrote none).
/// Held inline, not in the sample log: a frame's sources are one small
/// value, and their floats would gain little from zstd.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FrameSourcesValue {
    pub records: Vec<RecordSourcesValue>,
}

/// A radiance record's sources (empty: its sources bring no light).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RecordSourcesValue {
    pub id: u64,
    pub sources: Vec<SourceValue>,
}

/// One equivalent area light source ([`crate::cache::eas::Eas`]): the
/// offset from its record to its centroid, its solid angle seen from the
/// record, and the irradiance it brings there.
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SourceValue {
    pub offset: [f32; 3],
    pub solid_angle: f32,
    pub irradiance: [f32; 3],
}

/// `movies` value under `job · frame` (schema 6,
/// `migrations/0006_movies.md`): the texture movies of `movies` open in
/// one frame, with that frame's texels (DESIGN.md: "texels are packed
/// RGBE"; the paper's disk cache of movie frames). Held inline, not in the
/// sample log: a frame's textures are one small block.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct MovieFramesValue {
    /// The movies, in key order (triangle, then side).
    pub movies: Vec<MovieValue>,
    /// The stored texels of the movies that hold some, movie after movie,
    /// 4 RGBE bytes each, zstd-compressed: each texel's *direct*
    /// irradiance (the paper's "bad links" layer, which the movie computes
    /// itself, and which does not change where nothing moves near it).
    pub texels_zstd: Vec<u8>,
    /// Vertices of the frame's global pass.
    pub global_vertices: u32,
    /// Their indirect irradiance, 4 RGBE bytes each, zstd-compressed (the
    /// "good links": a texel's is the Gouraud interpolation of its
    /// triangle's grid vertices, `method::movies::global`, on the side of
    /// the triangle the pass solved, `method::movies::sides`; the other
    /// side's texels take none).
    pub global_zstd: Vec<u8>,
}

/// One movie of a [`MovieFramesValue`].
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct MovieValue {
    /// Snapshot triangle id.
    pub triangle: u32,
    /// The side against the triangle's geometric normal.
    pub back: bool,
    /// The part of the triangle it covers: `1` the whole, then two bits a
    /// level of its sub-triangles (`method::movies::patch::Patch::code`).
    pub patch: u32,
    /// Texels along each parametric edge (`R`; texel `(i, j)` is stored
    /// when `i + j ≤ R + 1`, row by row).
    pub resolution: u32,
    /// The frame the movie opened at.
    pub start: u32,
    /// Texels stored in this value: all of them, or 0 when they are, in
    /// RGBE, those of an earlier frame of the same movie (a movie that
    /// nothing changed is stored once).
    pub texels: u32,
    /// The frame whose value holds this movie's texels (this frame when
    /// `texels` > 0).
    pub stored_at: u32,
}
