//! Jobs: a render recorded under a name, its settings checked when it
//! resumes, cancelled, or started over with `--force`.

use super::schema::{JobSpec, JobValue};
use super::v1;
use super::{encode, keys, now_unix, Store, StoreError};
use crate::method::algorithm_revision;
use crate::method::settings::named_settings;
use crate::render::MethodSettings;
use sled::transaction::{ConflictableTransactionError, TransactionError};
use sled::Transactional;
use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The attempt mark of a job of `radcache serve` ([`Store::begin_job_attempt`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JobAttempt {
    /// The frames the job had stored (in all its ranges) as the attempt
    /// began.
    pub frames_stored_at_start: u32,
    /// This attempt and the ones before it that the server died in, in a
    /// row, with no frame stored in between.
    pub unfinished_attempts: u32,
}

impl JobAttempt {
    /// The attempts the server died in with no frame stored since
    /// `frames_stored_at_start`, the job now holding `frames_stored`
    /// frames: none once a frame was stored (the job moves on).
    pub fn died_without_progress(&self, frames_stored: u32) -> u32 {
        match self.frames_stored_at_start == frames_stored {
            true => self.unfinished_attempts,
            false => 0,
        }
    }

    /// As stored: the frames in the high half, the attempts in the low
    /// ([`keys::meta_attempt`]).
    fn to_u64(self) -> u64 {
        (u64::from(self.frames_stored_at_start) << 32) | u64::from(self.unfinished_attempts)
    }

    fn from_u64(value: u64) -> JobAttempt {
        JobAttempt {
            frames_stored_at_start: (value >> 32) as u32,
            unfinished_attempts: value as u32,
        }
    }
}

impl Store {
    pub fn job(&self, name: &str) -> Result<Option<JobValue>, StoreError> {
        self.get("jobs", &keys::job(name))
    }

    pub fn jobs(&self) -> Result<Vec<JobValue>, StoreError> {
        let mut out = Vec::new();
        for item in self.jobs.iter() {
            let (k, v) = item.map_err(|e| StoreError::sled(&self.path, e))?;
            out.push(self.decode("jobs", &k, &v)?);
        }
        Ok(out)
    }

    /// The names of the store's jobs, `a, b`, or `none`: what an error
    /// for a job name not found lists.
    pub fn job_names(&self) -> Result<String, StoreError> {
        let names: Vec<String> = self.jobs()?.into_iter().map(|j| j.spec.name).collect();
        Ok(match names.is_empty() {
            true => "none".to_string(),
            false => names.join(", "),
        })
    }

    /// Marks job `name` cancelled (or not) for `radcache serve`, durably
    /// (a `meta` key; no schema change).
    pub fn set_job_cancelled(&self, name: &str, cancelled: bool) -> Result<(), StoreError> {
        let key = keys::meta_cancelled(name);
        let r = if cancelled {
            self.meta.insert(key, &[] as &[u8]).map(|_| ())
        } else {
            self.meta.remove(key).map(|_| ())
        };
        r.map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()
    }

    /// Whether job `name` is marked cancelled ([`Self::set_job_cancelled`]).
    pub fn job_cancelled(&self, name: &str) -> Result<bool, StoreError> {
        self.meta
            .contains_key(keys::meta_cancelled(name))
            .map_err(|e| StoreError::sled(&self.path, e))
    }

    /// Marks that `radcache serve` starts rendering job `name` with
    /// `frames_stored` frames stored, durably (a `meta` key,
    /// [`keys::meta_attempt`]; no schema change), and returns the mark: a
    /// mark still there is an attempt the server died in, and counts
    /// towards this one unless a frame was stored since
    /// ([`JobAttempt::died_without_progress`]).
    pub fn begin_job_attempt(
        &self,
        name: &str,
        frames_stored: u32,
    ) -> Result<JobAttempt, StoreError> {
        let died = self
            .job_attempt(name)?
            .map_or(0, |a| a.died_without_progress(frames_stored));
        let attempt = JobAttempt {
            frames_stored_at_start: frames_stored,
            unfinished_attempts: died.saturating_add(1),
        };
        self.meta
            .insert(keys::meta_attempt(name), &attempt.to_u64().to_be_bytes())
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()?;
        Ok(attempt)
    }

    /// The attempt mark of job `name` ([`Self::begin_job_attempt`]), if any.
    pub fn job_attempt(&self, name: &str) -> Result<Option<JobAttempt>, StoreError> {
        let key = keys::meta_attempt(name);
        let value = super::meta::read_meta_u64(&self.meta, &key)
            .map_err(|detail| self.corrupt("meta", &key, detail))?;
        Ok(value.map(JobAttempt::from_u64))
    }

    /// Removes the attempt mark of job `name`, durably: its render ended
    /// in order, or a resume gives it fresh attempts.
    pub fn clear_job_attempts(&self, name: &str) -> Result<(), StoreError> {
        self.meta
            .remove(keys::meta_attempt(name))
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()
    }

    /// The highest `job-N` number `radcache serve` has given
    /// ([`keys::META_SERVED_JOBS_HIGH`]); 0 before the first.
    pub fn served_jobs_high(&self) -> Result<u64, StoreError> {
        let key = keys::META_SERVED_JOBS_HIGH;
        super::meta::read_meta_u64(&self.meta, key)
            .map(|n| n.unwrap_or(0))
            .map_err(|detail| self.corrupt("meta", key, detail))
    }

    /// Records `n` as the highest `job-N` number given (made durable by
    /// the next flush).
    pub fn set_served_jobs_high(&self, n: u64) -> Result<(), StoreError> {
        self.meta
            .insert(keys::META_SERVED_JOBS_HIGH, &n.to_be_bytes())
            .map(drop)
            .map_err(|e| StoreError::sled(&self.path, e))
    }

    /// Starts or resumes job `spec.name`. A job of that name with another
    /// scene or other settings, or started by a build whose algorithm for
    /// its method differs ([`algorithm_revision`]), is refused unless
    /// `force`. `force` starts
    /// the job over under a new id whatever its settings (the old id's data
    /// is then deleted): also the way out for a job whose stored frames are
    /// damaged.
    pub fn begin_job(&self, spec: &JobSpec, force: bool) -> Result<JobValue, StoreError> {
        self.refuse_if_frames_lost()?;
        let key = keys::job(&spec.name);
        let now = now_unix();
        if let Some(mut job) = self.job(&spec.name)? {
            let (scene_changed, mut diffs) = job_differences(&job.spec, spec);
            let stored_revision = self.job_revision(job.id)?;
            let build_revision = algorithm_revision(&spec.method);
            if job.spec.method == spec.method && stored_revision != build_revision {
                diffs.push(format!(
                    "`{}` algorithm revision (stored {stored_revision}, this build {build_revision}: the frames it would add would not match those stored)",
                    spec.method
                ));
            }
            if scene_changed.is_none() && diffs.is_empty() && !force {
                // Same job: the new range, and the spec as this build
                // writes it (a schema-1 job's settings and hash upgraded).
                job.spec = spec.clone();
                job.updated_unix = now;
                self.jobs
                    .insert(&key, encode(&job))
                    .map_err(|e| StoreError::sled(&self.path, e))?;
                self.flush()?;
                return Ok(job);
            }
            if !force {
                return Err(StoreError::JobDiffers {
                    path: self.path.clone(),
                    job: spec.name.clone(),
                    scene_changed: scene_changed.map(Box::new),
                    differences: diffs.join(", "),
                });
            }
            let fresh = self.new_job_value(spec, now)?;
            // The name now points at a fresh id: atomic by construction.
            self.jobs
                .insert(&key, encode(&fresh))
                .map_err(|e| StoreError::sled(&self.path, e))?;
            self.flush()?;
            self.delete_job_data(job.id)?;
            return Ok(fresh);
        }
        let fresh = self.new_job_value(spec, now)?;
        // A cancel or attempt mark of a former job of this name (a cancel
        // that came as it was deleted, a kill during its deletion) is not
        // the new job's.
        for mark in [
            keys::meta_cancelled(&spec.name),
            keys::meta_attempt(&spec.name),
        ] {
            self.meta
                .remove(mark)
                .map_err(|e| StoreError::sled(&self.path, e))?;
        }
        self.jobs
            .insert(&key, encode(&fresh))
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()?;
        Ok(fresh)
    }

    /// The algorithm revision the method of job id `job` started under
    /// ([`algorithm_revision`]); 1 where none is recorded (a job stored
    /// before revisions were).
    pub fn job_revision(&self, job: u64) -> Result<u64, StoreError> {
        let key = keys::meta_revision(job);
        let revision = super::meta::read_meta_u64(&self.meta, &key)
            .map_err(|detail| self.corrupt("meta", &key, detail))?;
        Ok(revision.unwrap_or(1))
    }

    /// A fresh job of `spec` under a new id, its algorithm revision
    /// recorded (before the job: a kill between leaves a revision no job
    /// holds, which `compact` removes).
    fn new_job_value(&self, spec: &JobSpec, now: u64) -> Result<JobValue, StoreError> {
        // Ids are unique over the store's life (sled persists the counter
        // and skips ahead after a crash), so a restarted job never sees
        // keys of its former self.
        let id = self
            .db
            .generate_id()
            .map_err(|e| StoreError::sled(&self.path, e))?
            + 1;
        self.meta
            .insert(
                keys::meta_revision(id),
                &algorithm_revision(&spec.method).to_be_bytes(),
            )
            .map_err(|e| StoreError::sled(&self.path, e))?;
        Ok(JobValue {
            id,
            spec: spec.clone(),
            frames_done: 0,
            last_frame: None,
            created_unix: now,
            updated_unix: now,
        })
    }

    /// Deletes job `name`, if there is one, and returns it
    /// ([`Self::delete_jobs`]).
    pub fn delete_job(&self, name: &str) -> Result<Option<JobValue>, StoreError> {
        if self.job(name)?.is_none() {
            return Ok(None);
        }
        Ok(self.delete_jobs(&[name])?.pop())
    }

    /// Deletes jobs `names`, all or none, and returns them. Their names,
    /// with their durable cancel and attempt marks, go in one transaction
    /// and one flush: a kill leaves every job or none, and a name not
    /// found ([`StoreError::Job`]) deletes none. Then every key of their
    /// ids (their revisions too); a kill meanwhile leaves keys no job
    /// owns, which `radcache compact` removes
    /// ([`Self::remove_orphaned_job_data`]). Their bytes in the sample log
    /// stay until `radcache compact`.
    pub fn delete_jobs(&self, names: &[impl AsRef<str>]) -> Result<Vec<JobValue>, StoreError> {
        let mut seen = BTreeSet::new();
        let names: Vec<&str> = names
            .iter()
            .map(AsRef::as_ref)
            .filter(|n| seen.insert(*n))
            .collect();
        let result: Result<Vec<JobValue>, TransactionError<StoreError>> = (&self.jobs, &self.meta)
            .transaction(|(jobs, meta)| {
                let mut deleted = Vec::new();
                for &name in &names {
                    let key = keys::job(name);
                    let Some(value) = jobs.remove(key.as_slice())? else {
                        return Err(ConflictableTransactionError::Abort(StoreError::Job {
                            path: self.path.clone(),
                            job: name.to_string(),
                            detail: "not found; nothing deleted".into(),
                        }));
                    };
                    let job = self
                        .decode("jobs", &key, &value)
                        .map_err(ConflictableTransactionError::Abort)?;
                    meta.remove(keys::meta_cancelled(name))?;
                    meta.remove(keys::meta_attempt(name))?;
                    deleted.push(job);
                }
                Ok(deleted)
            });
        let deleted = result.map_err(|e| match e {
            TransactionError::Abort(e) => e,
            TransactionError::Storage(e) => StoreError::sled(&self.path, e),
        })?;
        self.flush()?;
        for job in &deleted {
            self.delete_job_data(job.id)?;
        }
        Ok(deleted)
    }

    /// Deletes the keys of every job id that no job holds: those a kill
    /// left between a job's deletion, or its restart with `--force`, and
    /// the deletion of its data. The number of such ids.
    pub fn remove_orphaned_job_data(&self) -> Result<usize, StoreError> {
        let live: BTreeSet<u64> = self.jobs()?.iter().map(|j| j.id).collect();
        let mut orphans = BTreeSet::new();
        for (name, tree) in self.per_job_trees() {
            // One key per job id: a seek past each id's keys.
            let mut from = keys::job_prefix(0);
            while let Some(key) = tree.range(from..).keys().next() {
                let key = key.map_err(|e| StoreError::sled(&self.path, e))?;
                let id =
                    keys::job_of(&key).ok_or_else(|| self.corrupt(name, &key, "malformed key"))?;
                if !live.contains(&id) {
                    orphans.insert(id);
                }
                let Some(next) = id.checked_add(1) else { break };
                from = keys::job_prefix(next);
            }
        }
        // Revisions of ids no job holds (a kill as a job began, or a job
        // an older build deleted).
        for key in self.meta.scan_prefix(keys::META_REVISION_PREFIX).keys() {
            let key = key.map_err(|e| StoreError::sled(&self.path, e))?;
            let id = keys::revision_job(&key)
                .ok_or_else(|| self.corrupt("meta", &key, "malformed revision key"))?;
            if !live.contains(&id) {
                orphans.insert(id);
            }
        }
        for &id in &orphans {
            self.delete_job_data(id)?;
        }
        Ok(orphans.len())
    }

    /// The trees whose keys start with a job id ([`keys::job_prefix`]),
    /// by name.
    fn per_job_trees(&self) -> [(&'static str, &sled::Tree); 6] {
        ["frames", "stats", "records", "sources", "state", "movies"]
            .map(|name| (name, self.tree(name).expect("known tree")))
    }

    /// Deletes every key of job id `job` in the per-job trees, and its
    /// algorithm revision.
    fn delete_job_data(&self, job: u64) -> Result<(), StoreError> {
        let prefix = keys::job_prefix(job);
        // Their bytes stay in the log, unreferenced (it is append-only),
        // until `radcache compact` ([`compact`]).
        for (_, tree) in self.per_job_trees() {
            self.remove_prefix(tree, &prefix)?;
        }
        self.meta
            .remove(keys::meta_revision(job))
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()
    }

    /// Removes every key of `tree` under `prefix`, in batches of at most
    /// `BATCH` keys: a job's millions of records go in thousands of writes
    /// rather than one each, without holding all their keys at once.
    pub(super) fn remove_prefix(&self, tree: &sled::Tree, prefix: &[u8]) -> Result<(), StoreError> {
        const BATCH: usize = 4096;
        let mut keys = tree.scan_prefix(prefix).keys().peekable();
        while keys.peek().is_some() {
            let mut batch = sled::Batch::default();
            for key in keys.by_ref().take(BATCH) {
                batch.remove(key.map_err(|e| StoreError::sled(&self.path, e))?);
            }
            tree.apply_batch(batch)
                .map_err(|e| StoreError::sled(&self.path, e))?;
        }
        Ok(())
    }
}

/// A job's scene, named as before, whose content is not as it was when the
/// job was stored: the scene file, or a file it references (a `.bin`, an
/// image), was changed since.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SceneChanged {
    /// The scene as given now (a file's absolute path).
    pub scene: String,
    /// Its hash as the job stored it.
    pub stored_hash: String,
    /// Its hash now.
    pub given_hash: String,
}

impl SceneChanged {
    /// Says so, the job having been `stored` (or "submitted") before.
    pub fn describe(&self, stored: &str) -> String {
        format!(
            "its scene changed since the job was {stored}: {} (the file, or a file it \
             references) is not as it was (scene hash stored {}, given {})",
            self.scene, self.stored_hash, self.given_hash
        )
    }
}

/// How a job that cannot be resumed says why: its scene changed since
/// the job was `when` ("stored", "submitted"), and, where `differences`
/// (the settings that differ) is not empty, `settings(differences)`, a
/// clause saying what that means to the reader.
pub fn job_differs_text(
    scene_changed: Option<&SceneChanged>,
    differences: &str,
    when: &str,
    settings: impl Fn(&str) -> String,
) -> String {
    match (scene_changed, differences.is_empty()) {
        (Some(changed), true) => changed.describe(when),
        (Some(changed), false) => {
            format!("{}, and {}", changed.describe(when), settings(differences))
        }
        (None, _) => settings(differences),
    }
}

/// Fields of `spec` that differ from the stored job's (name and frame range
/// aside): its scene's content if it is the same scene changed since
/// ([`SceneChanged`]), and the others, named. Every field is named, so a
/// field added to [`JobSpec`] does not compile until it is compared here.
fn job_differences(stored: &JobSpec, spec: &JobSpec) -> (Option<SceneChanged>, Vec<String>) {
    let JobSpec {
        name: _,
        scene,
        scene_hash,
        method,
        settings,
        width,
        height,
        spp,
        fps,
        seed,
        same_pattern,
        frame_start: _,
        frame_end: _,
    } = spec;
    let mut d = Vec::new();
    let stored_settings = settings_as_read_now(&stored.settings);
    // Another method's settings differ as a whole: the method says it.
    if &stored.method == method && !same_settings(&stored_settings, settings) {
        d.push(settings_differences(&stored_settings, settings));
    }
    // The spp is one of the method's settings too: named once.
    let spp_named = d.first().is_some_and(|s| s.contains("spp: stored"));
    let mut check = |name: &str, same: bool, stored: String, given: String| {
        if !same {
            d.push(format!("{name} (stored {stored}, given {given})"));
        }
    };
    let scene_match = match_scene(stored, scene, scene_hash);
    check(
        "scene",
        scene_match.same_scene,
        stored.scene.clone(),
        scene.clone(),
    );
    check(
        "scene hash",
        scene_match.same_hash || scene_match.changed.is_some(),
        stored.scene_hash.clone(),
        scene_hash.clone(),
    );
    check(
        "method",
        &stored.method == method,
        stored.method.clone(),
        method.clone(),
    );
    check(
        "size",
        (stored.width, stored.height) == (*width, *height),
        format!("{}x{}", stored.width, stored.height),
        format!("{width}x{height}"),
    );
    check(
        "spp",
        stored.spp == *spp || spp_named,
        stored.spp.to_string(),
        spp.to_string(),
    );
    check(
        "fps",
        stored.fps.to_bits() == fps.to_bits(),
        stored.fps.to_string(),
        fps.to_string(),
    );
    check(
        "seed",
        stored.seed == *seed,
        stored.seed.to_string(),
        seed.to_string(),
    );
    check(
        "same-pattern",
        stored.same_pattern == *same_pattern,
        stored.same_pattern.to_string(),
        same_pattern.to_string(),
    );
    (scene_match.changed, d)
}

/// How a job's scene compares with a stored job's.
struct SceneMatch {
    /// The same scene: the same name, or the same file by another path.
    same_scene: bool,
    /// The same content ([`same_scene_hash`]).
    same_hash: bool,
    /// The same scene, changed since it was stored.
    changed: Option<SceneChanged>,
}

/// Compares `scene` (with its content's `scene_hash`) with `stored`'s.
fn match_scene(stored: &JobSpec, scene: &str, scene_hash: &str) -> SceneMatch {
    // The scene is its content: the same file named by another path
    // (`./s.gltf`, an absolute path, a run from another directory) resumes.
    // Only by a hash of everything the scene reads: a schema-1 hash
    // ([`same_scene_hash`]) leaves out the files beside the `.gltf`.
    let same_file =
        is_file_scene(&stored.scene) && is_file_scene(scene) && stored.scene_hash == scene_hash;
    // `render` gives a file's absolute path; a job stored by an earlier
    // build names it as it was given, relative to where it ran: the same
    // name from here is the same path (a schema-1 hash then still resumes).
    let same_path = stored.scene == scene
        || (is_file_scene(&stored.scene)
            && Path::new(&stored.scene).is_relative()
            && std::path::absolute(&stored.scene).is_ok_and(|p| p == Path::new(scene)));
    // The same scene, changed since: said as such. Another scene's hash
    // differs as well, named beside it.
    let same_hash = same_scene_hash(&stored.scene_hash, scene_hash);
    SceneMatch {
        same_scene: same_path || same_file,
        same_hash,
        changed: (same_path && !same_hash).then(|| SceneChanged {
            scene: scene.to_string(),
            stored_hash: stored.scene_hash.clone(),
            given_hash: scene_hash.to_string(),
        }),
    }
}

/// A stored job's settings as this build reads and writes them. A setting
/// added since the job was stored takes its serde default, which is what
/// the job ran before the setting existed; so the job resumes when given
/// that value, and is refused, naming the setting, when given another.
/// Settings this build cannot read stay as stored.
pub(crate) fn settings_as_read_now(stored: &str) -> Cow<'_, str> {
    serde_json::from_str::<MethodSettings>(stored)
        .ok()
        .and_then(|m| serde_json::to_string(&m).ok())
        .map_or(Cow::Borrowed(stored), Cow::Owned)
}

/// Settings are serde JSON: equal as JSON values (text that is not JSON,
/// as in tests, compares as text).
fn same_settings(stored: &str, given: &str) -> bool {
    match (
        serde_json::from_str::<serde_json::Value>(stored),
        serde_json::from_str::<serde_json::Value>(given),
    ) {
        (Ok(a), Ok(b)) => a == b,
        _ => stored == given,
    }
}

/// Whether job scene text `scene` names a file (not `builtin:NAME`).
fn is_file_scene(scene: &str) -> bool {
    !scene.starts_with("builtin:")
}

/// "method settings (max_life: stored 20, given 5; …)": the settings that
/// differ, by the names `--methods` and job requests give them
/// ([`named_settings`]); where those do not tell them apart, or the
/// settings cannot be read, by their path in the JSON.
fn settings_differences(stored: &str, given: &str) -> String {
    let named = |text: &str| {
        let settings = serde_json::from_str::<MethodSettings>(text).ok()?;
        let plain = |v: serde_json::Value| match v {
            serde_json::Value::String(s) => s,
            v => v.to_string(),
        };
        Some(
            named_settings(&settings)
                .into_iter()
                .map(|(k, v)| (k, plain(v)))
                .collect::<BTreeMap<_, _>>(),
        )
    };
    if let (Some(a), Some(b)) = (named(stored), named(given)) {
        let differing = differing_values(&a, &b);
        if !differing.is_empty() {
            return format!("method settings ({})", differing.join("; "));
        }
    }
    json_differences(stored, given)
}

/// "KEY: stored A, given B" for each key whose value differs.
fn differing_values<V: PartialEq + std::fmt::Display>(
    a: &BTreeMap<String, V>,
    b: &BTreeMap<String, V>,
) -> Vec<String> {
    let text = |v: Option<&V>| v.map_or_else(|| "none".to_string(), V::to_string);
    a.keys()
        .chain(b.keys())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| format!("{k}: stored {}, given {}", text(a.get(k)), text(b.get(k))))
        .collect()
}

/// [`settings_differences`] by the settings' paths in their JSON.
fn json_differences(stored: &str, given: &str) -> String {
    fn leaves(prefix: String, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
        match v {
            serde_json::Value::Object(map) => {
                for (k, v) in map {
                    let path = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    leaves(path, v, out);
                }
            }
            other => {
                out.insert(prefix, other.to_string());
            }
        }
    }
    let parse = |text: &str| {
        let mut out = BTreeMap::new();
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(text) {
            leaves(String::new(), &v, &mut out);
        }
        out
    };
    let differing = differing_values(&parse(stored), &parse(given));
    match differing.is_empty() {
        true => format!("method settings (stored {stored}, given {given})"),
        false => format!("method settings ({})", differing.join("; ")),
    }
}

/// Scene hashes are equal, or the stored one is a schema-1 hash (suffix
/// [`v1::LEGACY_HASH_SUFFIX`], external files not hashed) of the same file.
fn same_scene_hash(stored: &str, given: &str) -> bool {
    stored == given
        || stored
            .strip_suffix(v1::LEGACY_HASH_SUFFIX)
            .is_some_and(|main| given.split('+').next() == Some(main))
}

#[cfg(test)]
mod tests {
    use super::{JobAttempt, Store};
    use crate::store::schema::JobValue;

    fn attempt(frames_stored_at_start: u32, unfinished_attempts: u32) -> JobAttempt {
        JobAttempt {
            frames_stored_at_start,
            unfinished_attempts,
        }
    }

    /// Each start counts the attempts before it that left their mark with
    /// no frame stored since, and starts over at 1 once one was; the mark
    /// is durable, and goes when cleared, when its job is deleted and when
    /// a new job of that name begins.
    #[test]
    fn attempt_marks_count_the_starts_without_progress() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("db");
        let store = Store::open(&path).unwrap();
        assert_eq!(store.job_attempt("j").unwrap(), None);
        assert_eq!(store.begin_job_attempt("j", 0).unwrap(), attempt(0, 1));
        assert_eq!(store.begin_job_attempt("j", 0).unwrap(), attempt(0, 2));
        assert_eq!(store.job_attempt("other").unwrap(), None, "one job's");
        drop(store);
        let store = Store::open(&path).unwrap();
        assert_eq!(store.job_attempt("j").unwrap(), Some(attempt(0, 2)));
        assert_eq!(attempt(0, 2).died_without_progress(0), 2);
        assert_eq!(attempt(0, 2).died_without_progress(1), 0);
        // A frame stored since: the count starts over.
        assert_eq!(store.begin_job_attempt("j", 3).unwrap(), attempt(3, 1));
        let far = attempt(u32::MAX - 1, 7);
        assert_eq!(JobAttempt::from_u64(far.to_u64()), far);
        store.clear_job_attempts("j").unwrap();
        assert_eq!(store.job_attempt("j").unwrap(), None);
        assert_eq!(store.begin_job_attempt("j", 3).unwrap(), attempt(3, 1));

        let spec = JobValue::for_test("path", "{}".into()).spec;
        store.begin_job(&spec, false).unwrap();
        store.begin_job_attempt(&spec.name, 0).unwrap();
        store.delete_job(&spec.name).unwrap();
        assert_eq!(store.job_attempt(&spec.name).unwrap(), None, "deleted");
        // One a kill during a deletion left: not the new job's.
        store.begin_job_attempt(&spec.name, 0).unwrap();
        store.begin_job(&spec, false).unwrap();
        assert_eq!(store.job_attempt(&spec.name).unwrap(), None, "new job");
        // The same job begun again (each start of the worker) keeps it.
        store.begin_job_attempt(&spec.name, 0).unwrap();
        store.begin_job(&spec, false).unwrap();
        assert_eq!(store.job_attempt(&spec.name).unwrap(), Some(attempt(0, 1)));
    }

    /// Every key under the prefix goes, over several batches; a key of
    /// another job that sorts right after them stays.
    #[test]
    fn remove_prefix_takes_every_key_of_the_prefix_only() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&dir.path().join("db")).unwrap();
        let tree = &store.state;
        let (job, other) = (7u64.to_be_bytes(), 8u64.to_be_bytes());
        for i in 0u32..10_000 {
            let key = [&job[..], &i.to_be_bytes()[..]].concat();
            tree.insert(key, &[1u8][..]).unwrap();
        }
        tree.insert([&other[..], &[0u8; 4][..]].concat(), &[2u8][..])
            .unwrap();
        store.remove_prefix(tree, &job).unwrap();
        assert_eq!(tree.scan_prefix(job).count(), 0);
        assert_eq!(tree.scan_prefix(other).count(), 1);
    }
}
