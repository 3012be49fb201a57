//! Every key the store writes, and nothing else: no other module builds or
//! parses raw keys (STYLE.md). Integers are big-endian so that sled's
//! lexicographic order is numeric order and prefix scans walk space-time
//! in order. The layout is documented in `migrations/`, one file per
//! schema version: `0001_initial.md`, `0002_state_and_identity.md`,
//! `0003_sample_log.md`, `0004_record_blocks.md`,
//! `0005_log_generations.md` (no key changed but
//! `meta.samples_log_generation`), `0006_movies.md` (`movies` holds a
//! frame's texture movies), `0007_radiance_records_in_state.md` (no key
//! changed; `trc`'s and `tcg`'s state records hold radiance records),
//! `0008_frame_footprint.md` (no key changed; a frame's `stats` value
//! grew), `0009_record_sources.md` (`sources` holds the sources of a
//! frame's radiance records), `0010_tcg_state_refers_to_samples.md`
//! (no key changed; a `tcg` record's state no longer holds its samples)
//! `0011_trc_state_without_spatial_gradient_changes.md` (no key
//! changed; a `trc` record's state is 72 bytes shorter) and
//! `0012_trc_state_without_derived_change.md` (no key changed; 16 bytes
//! shorter again).
//! The version this build writes is [`super::migrate::CURRENT_VERSION`].
//!
//! | tree      | key                                   | bytes |
//! |-----------|---------------------------------------|-------|
//! | `meta`    | ASCII name (`schema_version`, …)      | var   |
//! | `jobs`    | job name, UTF-8                       | var   |
//! | `frames`  | job id u64 · frame u32                | 12    |
//! | `stats`   | job id u64 · frame u32                | 12    |
//! | `records` | job id u64 · frame u32                | 12    |
//! | `sources` | job id u64 · frame u32 (schema 9)     | 12    |
//! | `state`   | job id u64 (the head)                 | 8     |
//! | `state`   | job id u64 · record id u64            | 16    |
//! | `movies`  | job id u64 · frame u32 (schema 6)     | 12    |
//!
//! Since schema 3 there is no `samples` tree: a record's samples are in the
//! sample log (`samples.log`), the record says where. Since schema 4 the
//! records themselves are there too, one block per frame: `records` holds
//! one small value per frame that wrote records, saying where its block
//! lies (schema 3 had one key per record, `job · frame · record id`, built
//! by [`record`], which now only names a record in messages and the
//! 0003 → 0004 migration).
//!
//! In `records`, `frame` is the frame in which these versions of the
//! records were written (their creation frame for `ic`), so the frame's
//! block holds one frame's record changes, and a `job` prefix scan walks
//! them in frame order; `sources` is keyed as `records`, for the radiance
//! records among them. `state` holds the carried state of a method that
//! carries its cache from frame to frame (`trc`, `tcg`) after the job's
//! last frame: its head under the job id, then its records in id order.

/// `meta` key of the schema version (value: u32 big-endian, 4 bytes).
pub const META_SCHEMA_VERSION: &[u8] = b"schema_version";
/// `meta` key of the crate version that created the store (UTF-8).
pub const META_CREATED_BY: &[u8] = b"created_by";
/// `meta` key of the sample log's committed length (u64 big-endian):
/// records reference no byte beyond it (see `store::samples`).
pub const META_SAMPLES_LOG_LEN: &[u8] = b"samples_log_len";
/// `meta` key of the sample log's generation (u64 big-endian; schema 5,
/// `migrations/0005_log_generations.md`): the log is the file
/// `store::samples::file_name(generation)`; each compaction writes the
/// next one. Absent: 0 (`samples.log`).
pub const META_SAMPLES_LOG_GENERATION: &[u8] = b"samples_log_generation";
/// `meta` key of the 0002 → 0003 migration's progress: the last `records`
/// key it converted (left in place after it; see
/// `migrations/0003_sample_log.md`).
pub const META_MIGRATE_0003_THROUGH: &[u8] = b"migrate_0003_through";
/// The same for its second part, over `frames`.
pub const META_MIGRATE_0003_FRAMES_THROUGH: &[u8] = b"migrate_0003_frames_through";
/// `meta` key of the 0003 → 0004 migration's progress: the last frame
/// (`job · frame` key) whose records it moved into a block (see
/// `migrations/0004_record_blocks.md`).
pub const META_MIGRATE_0004_THROUGH: &[u8] = b"migrate_0004_through";
/// `meta` key of the 0006 → 0007 migration's progress: the last `trc` or
/// `tcg` job id (u64 big-endian) whose state records it converted (see
/// `migrations/0007_radiance_records_in_state.md`).
pub const META_MIGRATE_0007_THROUGH: &[u8] = b"migrate_0007_through";
/// `meta` key of the 0007 → 0008 migration's progress: the last job id
/// (u64 big-endian) whose `stats` values it rewrote (see
/// `migrations/0008_frame_footprint.md`).
pub const META_MIGRATE_0008_THROUGH: &[u8] = b"migrate_0008_through";
/// `meta` key of the 0010 → 0011 migration's progress: the last `trc` job
/// id (u64 big-endian) whose state records it converted (see
/// `migrations/0011_trc_state_without_spatial_gradient_changes.md`).
pub const META_MIGRATE_0011_THROUGH: &[u8] = b"migrate_0011_through";
/// The same for the 0011 → 0012 migration (see
/// `migrations/0012_trc_state_without_derived_change.md`).
pub const META_MIGRATE_0012_THROUGH: &[u8] = b"migrate_0012_through";

/// `meta` key of the highest `job-N` number `radcache serve` has given
/// (u64 big-endian; no schema change: older builds ignore it), so that a
/// deleted job's number is not given again.
pub const META_SERVED_JOBS_HIGH: &[u8] = b"served_jobs_high";

/// `meta` key of the algorithm revision job id `job`'s method started
/// under ([`crate::method::algorithm_revision`]; u64 big-endian; no schema
/// change: older builds ignore it). Absent: revision 1. By id, not name:
/// ids are never given twice, so a key an older build left behind (it
/// deleted the job) belongs to no later job.
pub fn meta_revision(job: u64) -> Vec<u8> {
    format!("{META_REVISION_PREFIX}{job}").into_bytes()
}

/// The text [`meta_revision`] keys start with.
pub const META_REVISION_PREFIX: &str = "revision:";

/// The job id of a [`meta_revision`] key.
pub fn revision_job(key: &[u8]) -> Option<u64> {
    std::str::from_utf8(key)
        .ok()?
        .strip_prefix(META_REVISION_PREFIX)?
        .parse()
        .ok()
}

/// `meta` key marking job `name` as cancelled by `radcache serve` (value
/// empty): a restarted server keeps it cancelled instead of resuming it.
pub fn meta_cancelled(name: &str) -> Vec<u8> {
    [b"cancelled:".as_slice(), name.as_bytes()].concat()
}

/// `meta` key of the attempt mark of job `name` (`radcache serve`): set
/// durably as the server starts rendering the job and removed when that
/// render ends in any orderly way, so that one found on a start is a
/// render the server died in (`store::JobAttempt`). Value: the frames the
/// job had stored as the attempt began, then the attempts in a row the
/// server died in with no frame stored since, two u32 big-endian (8
/// bytes, read as one u64). No schema change, as the cancel mark: older
/// builds read only the `meta` keys they know and leave others as they
/// are (migrations too), so they ignore it and resume the job as before.
pub fn meta_attempt(name: &str) -> Vec<u8> {
    [b"attempt:".as_slice(), name.as_bytes()].concat()
}

pub fn job(name: &str) -> Vec<u8> {
    name.as_bytes().to_vec()
}

/// `job · frame` (frames, stats, records).
pub fn frame(job: u64, frame: u32) -> [u8; 12] {
    let mut k = [0u8; 12];
    k[..8].copy_from_slice(&job.to_be_bytes());
    k[8..].copy_from_slice(&frame.to_be_bytes());
    k
}

/// `job · frame · record id`: a record version in messages; the `records`
/// key of schema 1–3 (schema 2 also `samples`).
pub fn record(job: u64, frame: u32, id: u64) -> [u8; 20] {
    let mut k = [0u8; 20];
    k[..12].copy_from_slice(&self::frame(job, frame));
    k[12..].copy_from_slice(&id.to_be_bytes());
    k
}

/// Prefix of every key of one job in `frames`, `stats`, `records`.
pub fn job_prefix(job: u64) -> [u8; 8] {
    job.to_be_bytes()
}

/// The job id a key of `frames`, `stats`, `records`, `sources`, `state`
/// or `movies` starts with.
pub fn job_of(key: &[u8]) -> Option<u64> {
    Some(u64::from_be_bytes(key.get(..8)?.try_into().ok()?))
}

/// `state` key of a job's state head (= [`job_prefix`]: it sorts before the
/// job's state records).
pub fn state_head(job: u64) -> [u8; 8] {
    job_prefix(job)
}

/// `job · record id` (`state` records).
pub fn state_record(job: u64, id: u64) -> [u8; 16] {
    let mut k = [0u8; 16];
    k[..8].copy_from_slice(&job.to_be_bytes());
    k[8..].copy_from_slice(&id.to_be_bytes());
    k
}

/// Decodes a `job · record id` key.
pub fn parse_state_record(key: &[u8]) -> Option<(u64, u64)> {
    let k: [u8; 16] = key.try_into().ok()?;
    Some((
        u64::from_be_bytes(k[..8].try_into().ok()?),
        u64::from_be_bytes(k[8..].try_into().ok()?),
    ))
}

/// Decodes a `job · frame` key.
pub fn parse_frame(key: &[u8]) -> Option<(u64, u32)> {
    let k: [u8; 12] = key.try_into().ok()?;
    Some((
        u64::from_be_bytes(k[..8].try_into().ok()?),
        u32::from_be_bytes(k[8..].try_into().ok()?),
    ))
}

/// Decodes a `job · frame · record id` key.
pub fn parse_record(key: &[u8]) -> Option<(u64, u32, u64)> {
    let k: [u8; 20] = key.try_into().ok()?;
    let (job, frame) = parse_frame(&k[..12])?;
    Some((job, frame, u64::from_be_bytes(k[12..].try_into().ok()?)))
}

/// A key as text for error messages: UTF-8 names as they are, binary keys
/// decoded, anything else in hex.
pub fn describe(key: &[u8]) -> String {
    describe_named(key, |_| None)
}

/// [`describe`], naming the job of a key by `name_of` its store id where
/// that knows it (`job "walk" (id 3) frame 14`): users know their jobs by
/// name, the store keys them by id.
pub fn describe_named(key: &[u8], name_of: impl Fn(u64) -> Option<String>) -> String {
    let job = |id: u64| {
        name_of(id).map_or_else(|| format!("job {id}"), |n| format!("job {n:?} (id {id})"))
    };
    if let Some((j, frame, id)) = parse_record(key) {
        return format!("{} frame {frame} record {id}", job(j));
    }
    if let Some((j, frame)) = parse_frame(key) {
        return format!("{} frame {frame}", job(j));
    }
    if let Some((j, id)) = parse_state_record(key) {
        return format!("{} record {id}", job(j));
    }
    match std::str::from_utf8(key) {
        Ok(s) if s.chars().all(|c| !c.is_control()) => format!("{s:?}"),
        _ if key.len() == 8 => job(u64::from_be_bytes(key.try_into().unwrap())),
        _ => key.iter().map(|b| format!("{b:02x}")).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_sort_in_space_time_order_and_round_trip() {
        assert!(frame(1, 255) < frame(1, 256));
        assert!(frame(1, u32::MAX) < frame(2, 0));
        assert!(record(1, 2, u64::MAX) < record(1, 3, 0));
        assert_eq!(parse_frame(&frame(7, 9)), Some((7, 9)));
        assert_eq!(parse_record(&record(7, 9, 11)), Some((7, 9, 11)));
        assert!(frame(3, 5).starts_with(&job_prefix(3)));
        assert_eq!(describe(&frame(3, 5)), "job 3 frame 5");
        assert_eq!(describe(b"schema_version"), "\"schema_version\"");
        assert_eq!(parse_state_record(&state_record(7, 11)), Some((7, 11)));
        assert!(state_head(7)[..] < state_record(7, 0)[..]);
        assert!(state_record(7, u64::MAX)[..] < state_head(8)[..]);
        assert_eq!(describe(&state_record(3, 5)), "job 3 record 5");
        assert_eq!(describe(&state_head(3)), "job 3");
        let walk = |id: u64| (id == 3).then(|| "walk".to_string());
        assert_eq!(
            describe_named(&frame(3, 5), walk),
            "job \"walk\" (id 3) frame 5"
        );
        assert_eq!(describe_named(&state_head(3), walk), "job \"walk\" (id 3)");
        assert_eq!(describe_named(&frame(4, 5), walk), "job 4 frame 5");
    }
}
