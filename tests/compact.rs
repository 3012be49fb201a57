//! `radcache compact` (`store::compact`): the sample log rewritten without
//! its unreferenced bytes — what it reclaims, that everything reads back
//! the same, that a resumed render after it is still bit-identical, that a
//! kill after any step leaves the old or the new store whole, that a
//! compact store is left alone, and the command's errors.

use radcache::cache::gather::Strata;
use radcache::film;
use radcache::method::ic::IcSettings;
use radcache::method::tcg::TcgSettings;
use radcache::method::trc::TrcSettings;
use radcache::render::{self, FrameSettings, MethodSettings, Renderer, SceneSource, StoreJob};
use radcache::store::compact::{self, Step};
use radcache::store::schema::{RecordValue, StatsValue};
use radcache::store::{keys, PackedSample, Store};
use std::path::{Path, PathBuf};

/// `ic` with `phi` azimuthal strata (another `phi`: another job spec).
fn ic(phi: u32) -> MethodSettings {
    MethodSettings::Ic(IcSettings {
        strata: Strata { theta: 4, phi },
        spp: 1,
        ..IcSettings::default()
    })
}

fn trc() -> MethodSettings {
    let mut t = TrcSettings::default();
    t.ic.strata = Strata { theta: 4, phi: 8 };
    t.ic.spp = 1;
    MethodSettings::Trc(t)
}

fn tcg() -> MethodSettings {
    let mut t = TcgSettings::default();
    t.ic.strata = Strata { theta: 4, phi: 8 };
    t.ic.spp = 1;
    MethodSettings::Tcg(t)
}

fn renderer(method: &MethodSettings) -> Renderer {
    let settings = FrameSettings {
        width: 8,
        height: 8,
        ..FrameSettings::default()
    };
    Renderer::new(
        SceneSource::Builtin("cube-in-box".into()).load().unwrap(),
        method.instantiate(),
        render::make_backend(render::BackendChoice::Cpu).unwrap(),
        settings,
    )
}

/// Renders `frames` of job `name` with `method` into `store` (and `out`),
/// starting the job over if `force`.
fn render_job(
    store: &Store,
    name: &str,
    method: &MethodSettings,
    frames: std::ops::Range<u32>,
    out: &Path,
    force: bool,
) {
    let r = renderer(method);
    let source = SceneSource::Builtin("cube-in-box".into());
    let spec = render::job_spec(name, &source, method, &r.settings, frames.clone()).unwrap();
    let mut sj = StoreJob {
        store,
        job: store.begin_job(&spec, force).unwrap(),
    };
    render::render_job_to_dir(&mut renderer(method), frames, out, true, Some(&mut sj)).unwrap();
}

/// A closed store at `dir/db` with unreferenced log bytes of both kinds:
/// job "a" rendered, then started over with `--force` (other settings),
/// and a `trc` job "t" whose frame 2 was written by two ranges. Returns
/// the store's path and the bytes the first version of "a" left (all of
/// them orphaned by the restart).
fn fixture(dir: &Path) -> (PathBuf, u64) {
    let path = dir.join("db");
    let out = dir.join("out");
    let store = Store::open(&path).unwrap();
    render_job(&store, "a", &ic(12), 0..3, &out.join("a1"), false);
    let orphaned = store.sample_log_bytes() - 8;
    render_job(&store, "a", &ic(8), 0..3, &out.join("a2"), true);
    render_job(&store, "t", &trc(), 2..3, &out.join("t"), false);
    render_job(&store, "t", &trc(), 0..3, &out.join("t"), false);
    (path, orphaned)
}

/// One frame of a job as the store reads it back: EXR, stats, records
/// (their sample offsets aside: compaction moves them) and their samples.
#[derive(Debug, PartialEq)]
struct FrameContent {
    exr: Vec<u8>,
    stats: Option<StatsValue>,
    records: Vec<RecordValue>,
    samples: Vec<Vec<PackedSample>>,
}

/// Everything a store reads back: per job, its value and frames, and its
/// carried state.
type Content = Vec<(
    String,
    Vec<(u32, FrameContent)>,
    Option<radcache::method::MethodState>,
)>;

fn content(store: &Store) -> Content {
    let mut out = Vec::new();
    for job in store.jobs().unwrap() {
        let mut frames = Vec::new();
        for f in store.frames_done(job.id).unwrap() {
            let records = store.frame_records(job.id, f).unwrap();
            let samples = records
                .iter()
                .map(|r| store.samples_of_record(job.id, f, r).unwrap())
                .collect();
            let records = records
                .into_iter()
                .map(|r| RecordValue {
                    samples_offset: 0,
                    ..r
                })
                .collect();
            frames.push((
                f,
                FrameContent {
                    exr: store.frame_exr(job.id, f).unwrap().unwrap(),
                    stats: store.frame_stats(job.id, f).unwrap(),
                    records,
                    samples,
                },
            ));
        }
        let state = store.load_state(job.id).unwrap();
        out.push((format!("{:?}", job), frames, state));
    }
    out
}

/// The log files in store directory `path`.
fn log_files(path: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(path)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("samples.") && n.ends_with(".log"))
        .collect();
    names.sort();
    names
}

fn file_len(path: &Path) -> u64 {
    std::fs::metadata(path).unwrap().len()
}

fn hidden() -> indicatif::ProgressBar {
    indicatif::ProgressBar::hidden()
}

#[test]
fn compaction_reclaims_orphaned_bytes_and_everything_reads_back_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let (path, orphaned) = fixture(dir.path());
    let mut store = Store::open(&path).unwrap();
    let before = content(&store);
    let log_before = store.sample_log_bytes();
    assert_eq!(file_len(&path.join("samples.log")), log_before);
    let usage = compact::log_usage(&store).unwrap();
    assert!(usage.unreferenced >= orphaned, "{usage:?} {orphaned}");
    let inspected = radcache::store::inspect::report(&store, None, None).unwrap();
    assert_eq!(inspected.sample_log_unreferenced_bytes, usage.unreferenced);
    assert_eq!(inspected.sample_log_referenced_bytes, usage.referenced);

    let report = compact::compact(&mut store, &hidden()).unwrap();
    assert_eq!(report.before, usage);
    assert!(
        report.bytes_after + orphaned <= log_before,
        "{} + {orphaned} > {log_before}",
        report.bytes_after
    );
    // The new file is the log; the old one is gone.
    assert_eq!(log_files(&path), vec!["samples.1.log".to_string()]);
    assert_eq!(store.sample_log_file(), path.join("samples.1.log"));
    assert_eq!(store.sample_log_bytes(), report.bytes_after);
    assert_eq!(file_len(&path.join("samples.1.log")), report.bytes_after);
    assert_eq!(content(&store), before);
    let after = compact::log_usage(&store).unwrap();
    assert_eq!(after.unreferenced, 0);
    let inspected = radcache::store::inspect::report(&store, None, None).unwrap();
    assert_eq!(inspected.sample_log_unreferenced_bytes, 0);
    assert_eq!(inspected.sample_log_file, "samples.1.log");
    drop(store);
    // Reopened: the same.
    let store = Store::open(&path).unwrap();
    assert_eq!(store.sample_log_bytes(), report.bytes_after);
    assert_eq!(content(&store), before);
}

#[test]
fn compacting_a_compact_store_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = fixture(dir.path());
    let mut store = Store::open(&path).unwrap();
    compact::compact(&mut store, &hidden()).unwrap();
    let before = content(&store);
    let trees = all_trees(&store);
    let log = std::fs::read(path.join("samples.1.log")).unwrap();
    let report = compact::compact(&mut store, &hidden()).unwrap();
    assert_eq!(report.before.unreferenced, 0);
    assert_eq!(report.new_file, report.old_file);
    assert!(compact::to_text(&report).contains("nothing to do"));
    assert_eq!(all_trees(&store), trees);
    assert_eq!(std::fs::read(path.join("samples.1.log")).unwrap(), log);
    assert_eq!(log_files(&path), vec!["samples.1.log".to_string()]);
    assert_eq!(content(&store), before);
}

/// Every key and value of every tree.
fn all_trees(store: &Store) -> Vec<(String, Vec<u8>, Vec<u8>)> {
    radcache::store::TREES
        .iter()
        .flat_map(|t| {
            store
                .tree(t)
                .unwrap()
                .iter()
                .map(|i| {
                    let (k, v) = i.unwrap();
                    (t.to_string(), k.to_vec(), v.to_vec())
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Copies store directory `from` (closed) to `to`.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

#[test]
fn compaction_stopped_after_any_step_leaves_the_old_or_the_new_store_whole() {
    let dir = tempfile::tempdir().unwrap();
    let (original, _) = fixture(dir.path());
    let (before, log_before) = {
        let store = Store::open(&original).unwrap();
        (content(&store), store.sample_log_bytes())
    };
    for step in [Step::Copied, Step::Synced, Step::Switched, Step::Flushed] {
        let path = dir.path().join(format!("{step:?}"));
        copy_dir(&original, &path);
        let mut store = Store::open(&path).unwrap();
        let report = compact::compact_with(&mut store, &hidden(), Some(step)).unwrap();
        assert_eq!(report.stopped_after, Some(step));
        // Both files are there: what a kill right now leaves.
        assert_eq!(log_files(&path), vec!["samples.1.log", "samples.log"]);
        drop(store);
        let mut store = Store::open(&path).unwrap();
        assert_eq!(content(&store), before, "stopped after {step:?}");
        // One log is left, the one `meta` names, whole.
        let switched = store.sample_log_file() == path.join("samples.1.log");
        match step {
            Step::Copied | Step::Synced => assert!(!switched, "{step:?}"),
            Step::Flushed => assert!(switched, "{step:?}"),
            // Committed, not flushed: sled may have made it durable or not.
            Step::Switched => {}
        }
        let current = if switched {
            "samples.1.log"
        } else {
            "samples.log"
        };
        assert_eq!(log_files(&path), vec![current.to_string()], "{step:?}");
        let expected = if switched {
            report.bytes_after
        } else {
            log_before
        };
        assert_eq!(store.sample_log_bytes(), expected, "{step:?}");
        assert_eq!(file_len(&path.join(current)), expected, "{step:?}");
        // Compacting again finishes the job (or finds nothing to do).
        let again = compact::compact(&mut store, &hidden()).unwrap();
        assert_eq!(again.before.unreferenced == 0, switched, "{step:?}");
        assert_eq!(store.sample_log_bytes(), report.bytes_after, "{step:?}");
        assert_eq!(content(&store), before, "{step:?}");
        assert_eq!(log_files(&path).len(), 1, "{step:?}");
    }
}

/// The keys of job id `id` in every per-job tree.
fn keys_of_job(store: &Store, id: u64) -> usize {
    ["frames", "stats", "records", "sources", "state", "movies"]
        .iter()
        .map(|t| {
            store
                .tree(t)
                .unwrap()
                .scan_prefix(keys::job_prefix(id))
                .count()
        })
        .sum()
}

/// A deleted job leaves nothing but log bytes, which compaction reclaims;
/// the other job reads back the same. A kill after a job's name went and
/// before its keys did (simulated: the name removed alone) leaves keys no
/// job holds: compaction removes them first, then reclaims their bytes.
#[test]
fn deleted_jobs_and_keys_a_kill_left_without_a_job_are_reclaimed() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = fixture(dir.path());
    let mut store = Store::open(&path).unwrap();
    let a = store.job("a").unwrap().unwrap();
    let t = store.job("t").unwrap().unwrap();
    assert!(keys_of_job(&store, a.id) > 0 && keys_of_job(&store, t.id) > 0);
    let only_t: Content = content(&store)
        .into_iter()
        .filter(|j| j.0.contains("name: \"t\""))
        .collect();
    assert_eq!(only_t.len(), 1);

    assert_eq!(store.delete_job("a").unwrap().map(|j| j.id), Some(a.id));
    assert_eq!(store.delete_job("a").unwrap(), None, "deleted once");
    assert_eq!(keys_of_job(&store, a.id), 0);
    let report = compact::compact(&mut store, &hidden()).unwrap();
    assert_eq!(report.orphaned_jobs_removed, 0);
    assert_eq!(content(&store), only_t);
    assert_eq!(compact::log_usage(&store).unwrap().unreferenced, 0);

    // "t" loses its name only, as a kill in `delete_job` would leave it.
    store.tree("jobs").unwrap().remove(keys::job("t")).unwrap();
    store.flush().unwrap();
    assert!(keys_of_job(&store, t.id) > 0);
    let report = compact::compact(&mut store, &hidden()).unwrap();
    assert_eq!(report.orphaned_jobs_removed, 1);
    assert_eq!(keys_of_job(&store, t.id), 0);
    assert!(report.before.unreferenced > 0, "t's bytes are reclaimed");
    assert_eq!(store.sample_log_bytes(), 8, "only the log's header is left");
    assert!(compact::to_text(&report).contains("1 job id(s) no job holds"));
}

fn exr_files(dir: &Path, frames: std::ops::Range<u32>) -> Vec<Vec<u8>> {
    frames
        .map(|f| std::fs::read(film::frame_path(dir, f, "exr")).unwrap())
        .collect()
}

/// `method` (a stateful one) interrupted after frame 1, with orphans
/// before its bytes in the log, is compacted and resumed: bit-identical to
/// an uninterrupted render (a `tcg` state refers to the samples of its
/// frame's records, which compaction moves).
fn resumed_after_compaction_is_bit_identical(method: MethodSettings) {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("plain");
    render::render_to_dir(&mut renderer(&method), 0..4, &plain, true).unwrap();
    let path = dir.path().join("db");
    let resumed = dir.path().join("resumed");
    {
        let mut store = Store::open(&path).unwrap();
        // Orphans before the job's bytes, then the job "interrupted" after
        // frame 1 (and its frame 2 from another range, written again by
        // the resume).
        render_job(&store, "x", &ic(8), 0..2, &dir.path().join("x"), false);
        render_job(&store, "x", &ic(12), 0..2, &dir.path().join("x"), true);
        render_job(&store, "t", &method, 2..3, &resumed, false);
        render_job(&store, "t", &method, 0..2, &resumed, false);
        let report = compact::compact(&mut store, &hidden()).unwrap();
        assert!(report.before.unreferenced > 0);
        assert!(report.bytes_after < report.before.committed);
    }
    let store = Store::open(&path).unwrap();
    render_job(&store, "t", &method, 0..4, &resumed, false);
    assert_eq!(exr_files(&plain, 0..4), exr_files(&resumed, 0..4));
    let job = store.job("t").unwrap().unwrap();
    for f in 0..4 {
        assert_eq!(
            store.frame_exr(job.id, f).unwrap().unwrap(),
            exr_files(&plain, f..f + 1)[0]
        );
    }
    // The new frames went to the compacted log.
    assert_eq!(log_files(&path), vec!["samples.1.log".to_string()]);
}

#[test]
fn a_trc_render_resumed_after_compaction_is_bit_identical_to_an_uninterrupted_one() {
    resumed_after_compaction_is_bit_identical(trc());
}

#[test]
fn a_tcg_render_resumed_after_compaction_is_bit_identical_to_an_uninterrupted_one() {
    resumed_after_compaction_is_bit_identical(tcg());
}

fn radcache(args: &[&str], db: &Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(args)
        .arg("--db")
        .arg(db)
        .output()
        .unwrap()
}

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn compact_command_reports_bytes_and_inspect_shows_unreferenced_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (path, orphaned) = fixture(dir.path());
    let unreferenced = |out: &std::process::Output| {
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        report["sample_log_unreferenced_bytes"].as_u64().unwrap()
    };
    let inspect = radcache(&["inspect", "--json"], &path);
    assert!(inspect.status.success(), "{}", stderr(&inspect));
    assert!(unreferenced(&inspect) >= orphaned);
    let text = radcache(&["inspect"], &path);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.contains("unreferenced"), "{text}");
    let out = radcache(&["compact", "-q"], &path);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("samples.log → samples.1.log") && stdout.contains("dropped"),
        "{stdout}"
    );
    assert_eq!(unreferenced(&radcache(&["inspect", "--json"], &path)), 0);
    let out = radcache(&["compact"], &path);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("nothing to do"));
}

/// `radcache delete`: an unknown name deletes nothing and lists the jobs;
/// the jobs named go, the others stay, and `compact` reclaims their bytes.
#[test]
fn delete_command_deletes_the_named_jobs_or_none() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = fixture(dir.path());
    let out = radcache(&["delete", "a", "nope"], &path);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("no job \"nope\" (jobs: a, t); nothing deleted"),
        "{err}"
    );
    let names = |path: &Path| -> Vec<String> {
        let store = Store::open_existing(path).unwrap();
        store
            .jobs()
            .unwrap()
            .into_iter()
            .map(|j| j.spec.name)
            .collect()
    };
    assert_eq!(names(&path), ["a", "t"]);
    let out = radcache(&["delete", "a"], &path);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("deleted job a (3 frames)") && stdout.contains("radcache compact"),
        "{stdout}"
    );
    assert_eq!(names(&path), ["t"]);
    let out = radcache(&["compact", "-q"], &path);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("dropped"));
}

#[test]
fn compacting_a_locked_missing_foreign_or_newer_store_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = fixture(dir.path());
    let expect_error = |db: &Path, wanted: &str| {
        let out = radcache(&["compact"], db);
        let err = stderr(&out);
        assert!(!out.status.success(), "{err}");
        assert!(err.contains(wanted), "{err}");
        assert!(err.contains(&db.display().to_string()), "{err}");
        assert!(!err.contains("panicked"), "{err}");
    };
    let (before, log) = {
        // Held open, as by a running `render` or `serve`.
        let store = Store::open(&path).unwrap();
        let log = std::fs::read(path.join("samples.log")).unwrap();
        expect_error(&path, "locked");
        (content(&store), log)
    };
    assert_eq!(std::fs::read(path.join("samples.log")).unwrap(), log);
    assert_eq!(log_files(&path), vec!["samples.log".to_string()]);
    assert_eq!(content(&Store::open(&path).unwrap()), before);
    expect_error(&dir.path().join("nowhere"), "no store here");
    let foreign = dir.path().join("out");
    expect_error(&foreign, "not a radcache store");
    {
        let store = Store::open(&path).unwrap();
        store
            .raw_insert("meta", keys::META_SCHEMA_VERSION, &99u32.to_be_bytes())
            .unwrap();
    }
    expect_error(&path, "schema version 99 is newer");
    assert_eq!(std::fs::read(path.join("samples.log")).unwrap(), log);
}

/// A compaction that cannot write its new log (here, one whose name
/// leads to /dev/full, which takes no bytes) fails, and leaves no partial
/// new log behind until the next open; the store is as it was, and
/// compacts once it can write.
#[test]
fn a_compaction_that_fails_removes_its_partial_new_log() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = fixture(dir.path());
    let mut store = Store::open_existing(&path).unwrap();
    let before = content(&store);
    let new_log = path.join("samples.1.log");
    std::os::unix::fs::symlink("/dev/full", &new_log).unwrap();
    let err = compact::compact(&mut store, &hidden())
        .unwrap_err()
        .to_string();
    assert!(err.contains("samples.1.log"), "{err}");
    assert!(std::fs::symlink_metadata(&new_log).is_err(), "left: {err}");
    assert!(content(&store) == before);
    compact::compact(&mut store, &hidden()).unwrap();
    assert_eq!(log_files(&path), vec!["samples.1.log".to_string()]);
}
