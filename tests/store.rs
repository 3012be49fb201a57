//! The persistent store: round trips, bad input (corrupt value, newer
//! schema, locked, damaged directory), migrations, jobs and resume.

use glam::Vec3;
use radcache::cache::eas::Eas;
use radcache::cache::gather::Strata;
use radcache::film;
use radcache::method::ic::{GlossyLobe, IcSettings};
use radcache::method::movies::{Movie, MoviesSettings, TextureMovies};
use radcache::method::path::PathSettings;
use radcache::method::tcg::TcgSettings;
use radcache::method::trc::{NextDirect, TemporalGradients, TrcSettings};
use radcache::method::{FrameStats, Method};
use radcache::render::{self, FrameSettings, MethodSettings, Renderer, SceneSource, StoreJob};
use radcache::store::migrate::{self, Migration};
use radcache::store::schema::FrameSourcesValue;
use radcache::store::{
    keys, v1, FrameCommit, JobSpec, PackedSample, RecordCommit, SampleBlock, Store, StoreError,
};
use std::path::{Path, PathBuf};

mod store_fixtures;
use store_fixtures::{open_raw, record, samples, spec};

fn commit_frames(store: &Store, name: &str, frames: std::ops::Range<u32>) {
    commit_frames_with(store, name, frames, |frame| {
        vec![frame as u8; 1000 + frame as usize]
    });
}

/// [`commit_frames`] with the EXR file of each frame made by `exr`.
fn commit_frames_with(
    store: &Store,
    name: &str,
    frames: std::ops::Range<u32>,
    exr: impl Fn(u32) -> Vec<u8>,
) {
    let mut job = store.begin_job(&spec(name), false).unwrap();
    let strata = Strata { theta: 4, phi: 12 };
    for frame in frames {
        let records = (0..3u64)
            .map(|id| {
                RecordCommit::from_record(
                    &record(id, frame),
                    // Object 1 is the dynamic one.
                    SampleBlock::pack(&samples(48, frame * 10 + id as u32), &[false, true]),
                    strata,
                    frame,
                )
            })
            .collect();
        let exr = exr(frame);
        let stats = FrameStats {
            frame,
            records_created: 3,
            records_alive: 3,
            ..FrameStats::default()
        };
        store
            .commit_frame(
                &mut job,
                FrameCommit {
                    frame,
                    width: 16,
                    height: 16,
                    exr: &exr,
                    records,
                    stats: &stats,
                    state: None,
                    movies: None,
                    sources: None,
                },
            )
            .unwrap();
    }
}

#[test]
fn store_round_trips_frames_records_samples_and_progress() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    {
        let store = Store::open(&path).unwrap();
        assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
        commit_frames(&store, "j", 0..4);
    }
    let store = Store::open_existing(&path).unwrap();
    let job = store.job("j").unwrap().unwrap();
    assert_eq!(job.frames_done, 4);
    assert_eq!(job.last_frame, Some(3));
    assert_eq!(store.frames_done(job.id).unwrap(), vec![0, 1, 2, 3]);
    for frame in 0..4u32 {
        let exr = store.frame_exr(job.id, frame).unwrap().unwrap();
        assert_eq!(exr, vec![frame as u8; 1000 + frame as usize]);
        let recs = store.frame_records(job.id, frame).unwrap();
        assert_eq!(recs.len(), 3);
        for r in &recs {
            let want = record(r.id, frame);
            assert_eq!(r.position, want.position.to_array());
            assert_eq!(r.grad_rotation[2], want.grad_rotation[2].to_array());
            assert_eq!((r.created_frame, r.last_frame), (frame, frame));
            assert_eq!((r.strata_theta, r.strata_phi), (4, 12));
            let got = store.record_samples(job.id, frame, r.id).unwrap();
            let src = samples(48, frame * 10 + r.id as u32);
            assert_eq!(got.len(), 48);
            for (i, s) in got.iter().enumerate() {
                let want = PackedSample::pack(
                    src.radiance[i],
                    src.distance[i],
                    src.object[i],
                    src.object[i] == 1,
                    0,
                );
                assert_eq!(*s, want);
                let err = (s.radiance() - src.radiance[i]).abs().max_element();
                assert!(err <= src.radiance[i].max_element() / 256.0 * 1.0001);
            }
        }
        assert_eq!(
            store
                .frame_stats(job.id, frame)
                .unwrap()
                .unwrap()
                .records_created,
            3
        );
    }
    // The records written through a frame, and only those: the blocks of
    // later frames are not read.
    for through in [0, 2, 3, u32::MAX] {
        let mut seen = Vec::new();
        store
            .for_each_record(job.id, through, |frame, r| seen.push((frame, r.id)))
            .unwrap();
        let want: Vec<(u32, u64)> = (0..=through.min(3))
            .flat_map(|f| {
                store
                    .frame_records(job.id, f)
                    .unwrap()
                    .into_iter()
                    .map(move |r| (f, r.id))
            })
            .collect();
        assert_eq!(seen, want, "records through frame {through}");
    }
    let report = radcache::store::inspect::report(&store, Some("j"), None).unwrap();
    assert_eq!(report.jobs[0].records, 12);
    assert_eq!(report.jobs[0].samples, 12 * 48);
    assert_eq!(report.jobs[0].lifespan_histogram.get(&1), Some(&12));
}

fn err_text(r: Result<impl Sized, StoreError>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

/// sled 0.34 reads an unfinished `snap.N.generating` file as its latest
/// snapshot (sled issue #1527), so a process killed while sled writes a
/// snapshot left a store it called corrupt (seen in the crash test: a kill
/// during the recovery after an earlier kill). The store removes such a
/// file and sled recovers from its log.
#[test]
fn an_unfinished_sled_snapshot_left_by_a_kill_does_not_lose_the_store() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    {
        let store = Store::open(&path).unwrap();
        commit_frames(&store, "j", 0..3);
    }
    let unfinished = path.join("snap.FFFFFFFFFFFFFFFF.generating");
    std::fs::write(&unfinished, b"torn").unwrap();
    let store = Store::open(&path).expect("the store reopens");
    let id = store.job("j").unwrap().unwrap().id;
    assert_eq!(store.frames_done(id).unwrap(), vec![0, 1, 2]);
    assert_eq!(store.frame_records(id, 2).unwrap().len(), 3);
    assert!(!unfinished.exists());
}

/// A process killed in its first milliseconds on a new store leaves what
/// sled had made by then: an empty `blobs/`, then `conf`, then an empty
/// `db` (and maybe the store's sample log, still empty). Nothing was stored, so the next render makes the store there
/// (it refused the directory as "not a radcache store" for good), and a
/// command that only reads finds no store. With something in `blobs/`, or
/// beside them, the directory is still refused untouched.
#[test]
fn a_store_whose_creation_was_cut_off_is_made_anew() {
    let dir = tempfile::tempdir().unwrap();
    let made = dir.path().join("made");
    drop(Store::open(&made).unwrap());
    let conf = std::fs::read(made.join("conf")).unwrap();
    // Without a sample: sled writes `db`'s first bytes from a thread of its
    // own, possibly after the log is made.
    let log = std::fs::read(made.join("samples.log")).unwrap();
    let states: [&[(&str, &[u8])]; 4] = [
        &[],
        &[("conf", &conf)],
        &[("conf", &conf), ("db", b"")],
        &[("conf", &conf), ("db", b""), ("samples.log", &log)],
    ];
    for (k, files) in states.iter().enumerate() {
        let path = dir.path().join(format!("cut{k}"));
        std::fs::create_dir_all(path.join("blobs")).unwrap();
        for (name, bytes) in *files {
            std::fs::write(path.join(name), bytes).unwrap();
        }
        let msg = err_text(Store::open_existing(&path));
        assert!(msg.contains("no store here"), "state {k}: {msg}");
        {
            let store = Store::open(&path).expect("the store is made");
            commit_frames(&store, "j", 0..2);
        }
        let store = Store::open_existing(&path).expect("the store reopens");
        let id = store.job("j").unwrap().unwrap().id;
        assert_eq!(store.frames_done(id).unwrap(), vec![0, 1], "state {k}");
    }
    // Not a cut-off creation: a file in `blobs/`, a file of someone else's.
    for (k, extra) in ["blobs/1", "notes.txt"].into_iter().enumerate() {
        let path = dir.path().join(format!("other{k}"));
        std::fs::create_dir_all(path.join("blobs")).unwrap();
        std::fs::write(path.join("conf"), &conf).unwrap();
        std::fs::write(path.join(extra), b"mine").unwrap();
        let msg = err_text(Store::open(&path));
        assert!(msg.contains("not a radcache store"), "{extra}: {msg}");
        assert_eq!(std::fs::read(path.join(extra)).unwrap(), b"mine");
        assert!(!path.join("db").exists(), "{extra}: sled made a database");
    }
}

/// A new store in `dir/db` holding frames 0 and 1 of job "j"
/// ([`commit_frames`]): its path, the store and the job's id.
fn store_of_two_frames(dir: &Path) -> (PathBuf, Store, u64) {
    let path = dir.join("db");
    let store = Store::open(&path).unwrap();
    commit_frames(&store, "j", 0..2);
    let id = store.job("j").unwrap().unwrap().id;
    (path, store, id)
}

#[test]
fn corrupt_value_is_an_error_naming_tree_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let (path, store, id) = store_of_two_frames(dir.path());
    for garbage in [&b"garbage"[..], &[0xff; 64][..], &[][..]] {
        store
            .raw_insert("records", &keys::frame(id, 1), garbage)
            .unwrap();
        let msg = err_text(store.frame_records(id, 1));
        assert!(msg.contains("tree `records`"), "{msg}");
        // The job by the name its user gave it, and its store id.
        assert!(
            msg.contains(&format!("job \"j\" (id {id}) frame 1")),
            "{msg}"
        );
        assert!(msg.contains(&path.display().to_string()), "{msg}");
        let msg = err_text(store.record_samples(id, 1, 2));
        assert!(msg.contains("tree `records`"), "{msg}");
    }
    store
        .raw_insert("frames", &keys::frame(id, 0), b"xx")
        .unwrap();
    let msg = err_text(store.frame_exr(id, 0));
    assert!(
        msg.contains("tree `frames`") && msg.contains(&format!("job \"j\" (id {id}) frame 0")),
        "{msg}"
    );
    store
        .raw_insert("jobs", &keys::job("j"), b"not a job")
        .unwrap();
    let msg = err_text(store.job("j"));
    assert!(
        msg.contains("tree `jobs`") && msg.contains("\"j\""),
        "{msg}"
    );
    // A frame's statistics and its radiance records' sources.
    for tree in ["stats", "sources"] {
        store
            .raw_insert(tree, &keys::frame(id, 0), b"garbage")
            .unwrap();
    }
    let msg = err_text(store.frame_stats(id, 0));
    assert!(msg.contains("tree `stats`"), "{msg}");
    let msg = err_text(store.frame_sources(id, 0));
    assert!(
        // The job's own value is damaged above: it is named by its id.
        msg.contains("tree `sources`") && msg.contains(&format!("job {id} frame 0")),
        "{msg}"
    );
    // Undamaged values still read.
    assert_eq!(store.frame_records(id, 0).unwrap().len(), 3);
}

/// A byte damaged anywhere in the sample log past its header makes the
/// frames and samples it holds an error naming the log, or leaves them as
/// they were: never other bytes (zstd's checksum of each block).
#[test]
fn a_damaged_sample_log_never_reads_as_other_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (path, store, id) = store_of_two_frames(dir.path());
    let read = |store: &Store| {
        (
            store.frame_exr(id, 1).map_err(|e| e.to_string()),
            store.record_samples(id, 1, 2).map_err(|e| e.to_string()),
        )
    };
    let (exr, samples) = read(&store);
    let (exr, samples) = (exr.unwrap().unwrap(), samples.unwrap());
    let log_path = path.join("samples.log");
    let log = std::fs::read(&log_path).unwrap();
    let magic = radcache::store::samples::MAGIC.len();
    let (mut errors, mut wrong) = (0, 0);
    for i in magic..log.len() {
        let mut damaged = log.clone();
        damaged[i] ^= 0x10;
        std::fs::write(&log_path, &damaged).unwrap();
        let (e, s) = read(&store);
        for outcome in [e.map(|e| e.unwrap() == exr), s.map(|s| s == samples)] {
            match outcome {
                Ok(same) => wrong += u32::from(!same),
                Err(msg) => {
                    assert!(msg.contains("samples.log"), "{msg}");
                    if msg.contains("EXR of") {
                        assert!(
                            msg.contains(&format!("EXR of job \"j\" (id {id}) frame 1")),
                            "{msg}"
                        );
                    }
                    errors += 1;
                }
            }
        }
    }
    std::fs::write(&log_path, &log).unwrap();
    assert_eq!(wrong, 0, "{wrong} damaged bytes read as other values");
    assert!(errors > 0);
    assert_eq!(read(&store).0.unwrap().unwrap(), exr);
}

#[test]
fn newer_schema_is_refused_and_left_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    {
        let store = Store::open(&path).unwrap();
        commit_frames(&store, "j", 0..1);
        store
            .raw_insert("meta", keys::META_SCHEMA_VERSION, &99u32.to_be_bytes())
            .unwrap();
    }
    for _ in 0..2 {
        let msg = err_text(Store::open(&path));
        assert!(msg.contains("schema version 99 is newer"), "{msg}");
        assert!(
            msg.contains(&format!("version {}", migrate::CURRENT_VERSION)),
            "{msg}"
        );
    }
}

/// A synthetic step 12 → 13: checks that it runs after the real steps
/// from 1 to 12 (the stored version is 12).
fn add_marker(db: &sled::Db, _dir: &Path) -> Result<(), String> {
    let meta = db.open_tree("meta").map_err(|e| e.to_string())?;
    let version = meta.get(keys::META_SCHEMA_VERSION).unwrap().unwrap();
    if version.as_ref() != 12u32.to_be_bytes() {
        return Err(format!("ran at version {version:?}"));
    }
    meta.insert(b"synthetic_step", &b"done"[..])
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[test]
fn older_schema_is_migrated_in_order() {
    // A version-1 store (fixture) brought to a synthetic version 13: the
    // real 1 → 2, …, 11 → 12, then 12 → 13, in order.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let method = MethodSettings::Path(PathSettings {
        spp: 1,
        ..PathSettings::default()
    });
    v1_fixture(&path, &method);
    let mut steps = migrate::MIGRATIONS.to_vec();
    assert_eq!(steps.len(), 11);
    steps.push(Migration {
        from: 12,
        name: "synthetic",
        run: add_marker,
    });
    // Without the step for 12 → 13 nothing runs, not even 1 → 2.
    let msg = err_text(Store::open_with(&path, false, 13, &steps[..11]));
    assert!(msg.contains("no migration from schema 12 to 13"), "{msg}");
    assert_eq!(
        Store::open_with(&path, false, 1, &[])
            .unwrap()
            .schema_version()
            .unwrap(),
        1
    );
    {
        let store = Store::open_with(&path, false, 13, &steps).unwrap();
        assert_eq!(store.schema_version().unwrap(), 13);
        assert!(store
            .tree("meta")
            .unwrap()
            .contains_key(b"synthetic_step")
            .unwrap());
        assert_eq!(store.frames_done(7).unwrap(), vec![0, 1]);
        assert_eq!(store.job("old").unwrap().unwrap().frames_done, 2);
    }
    // This build (version 12) now refuses the upgraded store.
    let msg = err_text(Store::open(&path));
    assert!(msg.contains("schema version 13 is newer"), "{msg}");
}

/// One `radcache render --job` run: the store at `path` opened, the job of
/// `spec` begun (or continued) and its frames `range` rendered into `out`
/// by a fresh renderer of `method`; the store is closed again after.
fn run_stored_job(
    path: &Path,
    spec: &JobSpec,
    method: &MethodSettings,
    range: std::ops::Range<u32>,
    out: &Path,
) -> anyhow::Result<render::RenderSummary> {
    let store = Store::open(path).unwrap();
    let job = store.begin_job(spec, false).unwrap();
    let mut sj = StoreJob { store: &store, job };
    render::render_job_to_dir(&mut renderer(method), range, out, true, Some(&mut sj))
}

/// A `trc` and a `tcg` job, each stopped after frame 2 of 0..6, their
/// carried state put back in the schema-6 layout (as a schema-6 build
/// wrote it), are migrated when the store is opened, and the resumes
/// render the frames uninterrupted renders do, byte for byte; running the
/// step again converts nothing twice.
#[test]
fn schema_6_carried_state_is_migrated_and_resumes_bit_identically() {
    let trc = TrcSettings {
        ic: small_ic_settings(),
        ..TrcSettings::default()
    };
    let tcg = TcgSettings {
        ic: small_ic_settings(),
        ..TcgSettings::default()
    };
    let jobs = [
        (
            "t",
            MethodSettings::Trc(trc),
            radcache::method::trc::downgrade_to_schema_6_record as fn(&[u8]) -> _,
        ),
        (
            "g",
            MethodSettings::Tcg(tcg),
            radcache::method::tcg::downgrade_to_schema_6_record,
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let fs = renderer(&jobs[0].1).settings.clone();
    let source = SceneSource::Builtin("cube-in-box".into());
    let out = |name: &str, kind: &str| dir.path().join(format!("{name}-{kind}"));
    let run = |name: &str, method: &MethodSettings, range: std::ops::Range<u32>| {
        let spec = render::job_spec(name, &source, method, &fs, 0..6).unwrap();
        run_stored_job(&path, &spec, method, range, &out(name, "resumed"))
    };
    for (name, method, _) in &jobs {
        render::render_to_dir(&mut renderer(method), 0..6, &out(name, "plain"), true).unwrap();
        run(name, method, 0..3).unwrap();
    }
    let ids: Vec<u64> = {
        let store = Store::open(&path).unwrap();
        let id = |name: &str| store.job(name).unwrap().unwrap().id;
        jobs.iter().map(|(name, _, _)| id(name)).collect()
    };
    let converted = {
        let db = open_raw(&path);
        let job_index = |job| ids.iter().position(|&id| id == job).unwrap();
        let mut n = [0; 2];
        for job in rewrite_state_records(&db, |job, _, data| {
            Some((jobs[job_index(job)].2)(data).unwrap())
        }) {
            n[job_index(job)] += 1;
        }
        radcache::store::v7::downgrade_stats_to_schema_7(&db).unwrap();
        migrate::write_version(&path, &db.open_tree("meta").unwrap(), 6).unwrap();
        db.flush().unwrap();
        n
    };
    assert!(converted.iter().all(|&n| n > 0), "{converted:?}");
    for (name, method, _) in &jobs {
        let s = run(name, method, 0..6).unwrap();
        assert_eq!((s.resumed, s.frames), (3, 3), "{name}");
        let files = |kind| exr_files(&out(name, kind), 0..6);
        assert_eq!(files("plain"), files("resumed"), "{name}");
    }
    // The step again (a crash before the version bump): nothing converted
    // twice, the state still reads.
    {
        let db = open_raw(&path);
        radcache::store::v6::migrate_to_v7(&db, &path).unwrap();
        db.flush().unwrap();
    }
    let version = Store::open(&path).unwrap().schema_version().unwrap();
    assert_eq!(version, migrate::CURRENT_VERSION);
    for (name, method, _) in &jobs {
        std::fs::remove_dir_all(out(name, "resumed")).unwrap();
        let s = run(name, method, 0..6).unwrap();
        assert_eq!((s.resumed, s.frames), (6, 0), "{name}");
    }
}

/// A state-record conversion, as `trc`'s downgrades for tests are.
type Convert = fn(&[u8]) -> Result<Vec<u8>, String>;

/// A migration step with the `meta` key of its progress.
type Step = (&'static [u8], fn(&sled::Db, &Path) -> Result<(), String>);

/// The layout of schema 11 (as a schema-11 build wrote it) is migrated
/// as schema 10's is below: the resumes render byte for byte what
/// uninterrupted renders do.
#[test]
fn schema_11_trc_state_is_migrated_and_resumes_bit_identically() {
    older_trc_state_is_migrated_and_resumes_bit_identically(
        11,
        radcache::method::trc::downgrade_to_schema_11_record,
        &[(
            keys::META_MIGRATE_0012_THROUGH,
            radcache::store::v11::migrate_to_v12,
        )],
    );
}

/// Two `trc` jobs (one with radiance records) and a `tcg` job, each
/// stopped after frame 2 of 0..6, the `trc` state put back in the layout
/// of schemas 7–10 (as a schema-10 build wrote it, but for the changes of
/// the spatial gradients, 0 here, which no frame applies), are migrated
/// when the store is opened (10 → 11 → 12): the resumes render the frames
/// uninterrupted renders do, byte for byte (the `tcg` state, left as it
/// was, too), and the state is shorter. Running the steps again converts
/// nothing twice.
#[test]
fn schema_10_trc_state_is_migrated_and_resumes_bit_identically() {
    older_trc_state_is_migrated_and_resumes_bit_identically(
        10,
        radcache::method::trc::downgrade_to_schema_10_record,
        &[
            (
                keys::META_MIGRATE_0011_THROUGH,
                radcache::store::v10::migrate_to_v11,
            ),
            (
                keys::META_MIGRATE_0012_THROUGH,
                radcache::store::v11::migrate_to_v12,
            ),
        ],
    );
}

/// The two tests above: the `trc` state put back by `downgrade` into the
/// layout of schema `version`, the store stamped so, then opened, resumed
/// and each of `steps` run again.
fn older_trc_state_is_migrated_and_resumes_bit_identically(
    version: u32,
    downgrade: Convert,
    steps: &[Step],
) {
    let trc = |glossy| {
        MethodSettings::Trc(TrcSettings {
            ic: IcSettings {
                glossy,
                ..small_ic_settings()
            },
            ..TrcSettings::default()
        })
    };
    let tcg = MethodSettings::Tcg(TcgSettings {
        ic: small_ic_settings(),
        ..TcgSettings::default()
    });
    let jobs = [
        ("t", "cube-in-box", trc(IcSettings::default().glossy)),
        ("e", "glossy-cornell", trc(GlossyLobe::Eas)),
        ("g", "cube-in-box", tcg),
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let out = |name: &str, kind: &str| dir.path().join(format!("{name}-{kind}"));
    let run = |(name, scene, method): &(&str, &str, MethodSettings), range| {
        let fs = renderer_of(scene, method).settings.clone();
        let source = SceneSource::Builtin(scene.to_string());
        let spec = render::job_spec(name, &source, method, &fs, 0..6).unwrap();
        let store = Store::open(&path).unwrap();
        let job = store.begin_job(&spec, false).unwrap();
        let mut sj = StoreJob { store: &store, job };
        let mut renderer = renderer_of(scene, method);
        render::render_job_to_dir(
            &mut renderer,
            range,
            &out(name, "resumed"),
            true,
            Some(&mut sj),
        )
    };
    for job in &jobs {
        let (name, scene, method) = job;
        let mut plain = renderer_of(scene, method);
        render::render_to_dir(&mut plain, 0..6, &out(name, "plain"), true).unwrap();
        run(job, 0..3).unwrap();
    }
    let state_rows = |db: &sled::Db| -> Vec<(Vec<u8>, Vec<u8>)> {
        let state = db.open_tree("state").unwrap();
        let rows = state.iter().map(|item| item.unwrap());
        rows.map(|(k, v)| (k.to_vec(), v.to_vec())).collect()
    };
    let size = |rows: &[(Vec<u8>, Vec<u8>)]| rows.iter().map(|(_, v)| v.len()).sum::<usize>();
    let (trc_ids, before) = {
        let store = Store::open(&path).unwrap();
        let id = |name: &str| store.job(name).unwrap().unwrap().id;
        let ids = [id("t"), id("e")];
        drop(store);
        let db = open_raw(&path);
        let before = state_rows(&db);
        let converted = rewrite_state_records(&db, |job, _, data| {
            ids.contains(&job).then(|| downgrade(data).unwrap())
        });
        for id in ids {
            assert!(converted.contains(&id), "job {id}: {converted:?}");
        }
        assert!(size(&state_rows(&db)) > size(&before));
        migrate::write_version(&path, &db.open_tree("meta").unwrap(), version).unwrap();
        db.flush().unwrap();
        (ids, before)
    };
    // Opened, the store is migrated: the state as this build wrote it.
    drop(Store::open(&path).unwrap());
    assert!(state_rows(&open_raw(&path)) == before);
    for job in &jobs {
        let name = job.0;
        let s = run(job, 0..6).unwrap();
        assert_eq!((s.resumed, s.frames), (3, 3), "{name}");
        let files = |kind| exr_files(&out(name, kind), 0..6);
        assert_eq!(files("plain"), files("resumed"), "{name}");
    }
    // The steps again (a crash before the version bump): nothing converted
    // twice, the state still reads.
    {
        let db = open_raw(&path);
        for (through, step) in steps {
            let through = db.open_tree("meta").unwrap().get(through);
            let through = through.unwrap().expect("the step's progress");
            let last = u64::from_be_bytes(through.as_ref().try_into().unwrap());
            assert_eq!(Some(last), trc_ids.into_iter().max());
            step(&db, &path).unwrap();
        }
        db.flush().unwrap();
    }
    let version = Store::open(&path).unwrap().schema_version().unwrap();
    assert_eq!(version, migrate::CURRENT_VERSION);
    for job in &jobs {
        let name = job.0;
        std::fs::remove_dir_all(out(name, "resumed")).unwrap();
        let s = run(job, 0..6).unwrap();
        assert_eq!((s.resumed, s.frames), (6, 0), "{name}");
    }
}

/// A small `trc` job over frames 0..6 of cube-in-box, stored at `path`
/// with frames 0..3 rendered into `out`: its method and spec, for the
/// tests that spoil its state and resume it.
fn trc_job_after_frame_2(path: &Path, out: &Path) -> (MethodSettings, JobSpec) {
    let method = MethodSettings::Trc(TrcSettings {
        ic: small_ic_settings(),
        ..TrcSettings::default()
    });
    let source = SceneSource::Builtin("cube-in-box".into());
    let fs = renderer(&method).settings.clone();
    let spec = render::job_spec("j", &source, &method, &fs, 0..6).unwrap();
    run_stored_job(path, &spec, &method, 0..3, out).unwrap();
    (method, spec)
}

/// A store stamped schema 10 (or 11) whose `trc` state does not read in
/// that schema's layout (here: already in this build's) fails its upgrade
/// with an error naming the step, tree and key, and is left at that
/// schema with its state as it was, not half read into the wrong fields.
#[test]
fn a_trc_state_that_does_not_read_as_its_schema_fails_the_upgrade_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    trc_job_after_frame_2(&path, &dir.path().join("o"));
    let steps = [
        (10, "0011_trc_state_without_spatial_gradient_changes"),
        (11, "0012_trc_state_without_derived_change"),
    ];
    for (version, step) in steps {
        let state_before = {
            let db = open_raw(&path);
            migrate::write_version(&path, &db.open_tree("meta").unwrap(), version).unwrap();
            db.flush().unwrap();
            let state = db.open_tree("state").unwrap();
            state.iter().map(|i| i.unwrap()).collect::<Vec<_>>()
        };
        let msg = err_text(Store::open(&path));
        for part in [
            &format!("migration from schema {version} failed"),
            step,
            "tree `state` key",
            &format!("schema-{version} trc record state"),
        ] {
            assert!(msg.contains(part), "{part}: {msg}");
        }
        let db = open_raw(&path);
        let stamped = db.open_tree("meta").unwrap().get(keys::META_SCHEMA_VERSION);
        assert_eq!(stamped.unwrap().unwrap().as_ref(), version.to_be_bytes());
        let state = db.open_tree("state").unwrap();
        let state_after: Vec<_> = state.iter().map(|i| i.unwrap()).collect();
        assert!(state_after == state_before, "schema {version}");
    }
}

/// `radcache render` says when it upgrades a store, once: a `trc` job
/// rendered with `--db` and put back to schema 10 resumes with the step
/// named on stderr and renders the frames a render without the store
/// does; the next run says nothing of it.
#[test]
fn the_cli_says_when_it_upgrades_a_store() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("db");
    let (plain, resumed) = (dir.path().join("plain"), dir.path().join("resumed"));
    let render = |frames: &str, out: &Path, db: Option<&Path>| -> String {
        let mut args = vec!["render", "--method", "trc", "--frames", frames];
        args.extend(["--size", "16x16", "--spp", "1", "-q"]);
        args.extend(["--out", out.to_str().unwrap()]);
        if let Some(db) = db {
            args.extend(["--db", db.to_str().unwrap(), "--job", "j"]);
        }
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
        assert!(run.status.success(), "{stderr}");
        stderr
    };
    render("0..3", &resumed, Some(&db));
    {
        let raw = open_raw(&db);
        let downgrade = radcache::method::trc::downgrade_to_schema_10_record;
        let converted = rewrite_state_records(&raw, |_, _, data| Some(downgrade(data).unwrap()));
        assert!(!converted.is_empty());
        migrate::write_version(&db, &raw.open_tree("meta").unwrap(), 10).unwrap();
        raw.flush().unwrap();
    }
    let said = render("0..5", &resumed, Some(&db));
    for step in [
        "upgrading schema 10 to 11 (0011_trc_state_without_spatial_gradient_changes)",
        "upgrading schema 11 to 12 (0012_trc_state_without_derived_change)",
    ] {
        assert!(said.contains(step), "{said}");
    }
    render("0..5", &plain, None);
    assert_eq!(exr_files(&plain, 0..5), exr_files(&resumed, 0..5));
    let said = render("0..5", &resumed, Some(&db));
    assert!(!said.contains("upgrading"), "{said}");
}

/// Schema-7 statistics (two jobs, the first already converted by a step
/// that crashed before the second) are rewritten in the schema-8 layout
/// when the store is opened: every count as it was, what schema 7 did not
/// measure 0, the first job not converted twice. Older builds then
/// refuse the store.
#[test]
fn schema_7_statistics_are_migrated_once_and_keep_every_count() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let (before, first) = {
        let store = Store::open(&path).unwrap();
        commit_frames(&store, "a", 0..3);
        commit_frames(&store, "b", 0..2);
        let ids = ["a", "b"].map(|n| store.job(n).unwrap().unwrap().id);
        let stats: Vec<FrameStats> = ids
            .iter()
            .flat_map(|&id| {
                let frames = store.frames_done(id).unwrap();
                let store = &store;
                frames
                    .into_iter()
                    .map(move |f| store.frame_stats(id, f).unwrap().unwrap().stats)
            })
            .collect();
        (stats, ids[0])
    };
    assert_eq!(before.len(), 5);
    {
        let db = open_raw(&path);
        radcache::store::v7::downgrade_stats_to_schema_7(&db).unwrap();
        // The crashed step had converted job "a" and marked it.
        let stats = db.open_tree("stats").unwrap();
        for item in stats.scan_prefix(keys::job_prefix(first)) {
            let (k, v) = item.unwrap();
            let old: radcache::store::v7::StatsValue = decoded(&v);
            let new = rkyv::to_bytes::<rkyv::rancor::Error>(&old.to_v8()).unwrap();
            stats.insert(k, new.as_slice()).unwrap();
        }
        let meta = db.open_tree("meta").unwrap();
        meta.insert(keys::META_MIGRATE_0008_THROUGH, &first.to_be_bytes())
            .unwrap();
        migrate::write_version(&path, &meta, 7).unwrap();
        db.flush().unwrap();
    }
    let store = Store::open(&path).unwrap();
    assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
    let mut after = Vec::new();
    for name in ["a", "b"] {
        let id = store.job(name).unwrap().unwrap().id;
        for f in store.frames_done(id).unwrap() {
            let v = store.frame_stats(id, f).unwrap().unwrap();
            assert_eq!(v.stored_bytes, 0, "{name} frame {f}");
            after.push(v.stats.clone());
        }
    }
    let unmeasured = |s: &FrameStats| FrameStats {
        samples_reshot: 0,
        cache_bytes: 0,
        ..s.clone()
    };
    assert_eq!(after, before.iter().map(unmeasured).collect::<Vec<_>>());
    drop(store);
    // Neither a schema-7 build nor a schema-8 one (which would leave the
    // `sources` of a job started over behind) opens it now.
    assert_an_older_build_refuses(&path, 7);
    assert_an_older_build_refuses(&path, 8);
}

/// State records of a schema-6 layout in a store stamped schema 7 (what a
/// schema-6 build's bytes would be without the migration) are a clear
/// error naming tree and key, not a panic.
#[test]
fn schema_6_state_bytes_under_schema_7_are_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let out = dir.path().join("o");
    let (method, spec) = trc_job_after_frame_2(&path, &out);
    {
        let db = open_raw(&path);
        let mut first = true;
        let converted = rewrite_state_records(&db, |_, _, data| {
            let downgrade = radcache::method::trc::downgrade_to_schema_6_record;
            std::mem::take(&mut first).then(|| downgrade(data).unwrap())
        });
        assert_eq!(converted.len(), 1);
        db.flush().unwrap();
    }
    // A longer range resumes from the state of frame 2.
    let msg = run_stored_job(&path, &spec, &method, 0..6, &out)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("tree `state`") && msg.contains("record"),
        "{msg}"
    );
}

/// A `tcg` job's state refers to the samples of the records its frame
/// stored: with frame 2's record block gone, a resume after frame 2 is
/// refused naming the record. The same state holding its records' samples,
/// as schemas 6–9 wrote it, resumes once the store is opened (and brought
/// to the current schema), with no record block to read, and renders the
/// frames an uninterrupted render does, byte for byte.
#[test]
fn a_schema_9_tcg_state_holding_its_samples_resumes_bit_identically() {
    let method = MethodSettings::Tcg(TcgSettings {
        ic: small_ic_settings(),
        ..TcgSettings::default()
    });
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let source = SceneSource::Builtin("cube-in-box".into());
    let fs = renderer(&method).settings.clone();
    let spec = render::job_spec("g", &source, &method, &fs, 0..6).unwrap();
    let out = |kind: &str| dir.path().join(kind);
    let run = |range| run_stored_job(&path, &spec, &method, range, &out("resumed"));
    render::render_to_dir(&mut renderer(&method), 0..6, &out("plain"), true).unwrap();
    run(0..3).unwrap();
    let (job, stored) = {
        let store = Store::open(&path).unwrap();
        let job = store.job("g").unwrap().unwrap().id;
        (job, store.frame_record_samples(job, 2).unwrap())
    };
    assert!(!stored.is_empty());
    {
        let db = open_raw(&path);
        let records = db.open_tree("records").unwrap();
        assert!(records.remove(keys::frame(job, 2)).unwrap().is_some());
        db.flush().unwrap();
    }
    let msg = format!("{:#}", run(0..6).map(|_| ()).unwrap_err());
    assert!(
        msg.contains("tree `state`") && msg.contains("has no samples among those its frame stored"),
        "{msg}"
    );
    {
        let db = open_raw(&path);
        let converted = rewrite_state_records(&db, |_, id, data| {
            Some(radcache::method::tcg::with_samples_as_schema_9(data, &stored[&id]).unwrap())
        });
        assert_eq!(converted.len(), stored.len());
        migrate::write_version(&path, &db.open_tree("meta").unwrap(), 9).unwrap();
        db.flush().unwrap();
    }
    let s = run(0..6).unwrap();
    assert_eq!((s.resumed, s.frames), (3, 3));
    assert_eq!(
        exr_files(&out("plain"), 0..6),
        exr_files(&out("resumed"), 0..6)
    );
    let version = Store::open(&path).unwrap().schema_version().unwrap();
    assert_eq!(version, migrate::CURRENT_VERSION);
}

#[test]
fn locked_store_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let store = Store::open(&path).unwrap();
    commit_frames(&store, "j", 0..1);
    let msg = err_text(Store::open(&path));
    assert!(msg.contains("locked"), "{msg}");
    // A second process (the CLI) too.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["inspect", "--db"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("locked"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    drop(store);
    assert!(Store::open(&path).is_ok());
}

fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| (p.display().to_string(), std::fs::read(&p).unwrap()))
        .collect();
    files.sort();
    files
}

#[test]
fn damaged_or_foreign_directories_are_refused_untouched() {
    let dir = tempfile::tempdir().unwrap();
    // Missing.
    let msg = err_text(Store::open_existing(&dir.path().join("nope")));
    assert!(msg.contains("no store here"), "{msg}");
    // A file, not a directory.
    let file = dir.path().join("file");
    std::fs::write(&file, b"hello").unwrap();
    assert!(err_text(Store::open(&file)).contains("not a directory"));
    assert_eq!(std::fs::read(&file).unwrap(), b"hello");
    // A directory of something else.
    let foreign = dir.path().join("foreign");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), b"mine").unwrap();
    let msg = err_text(Store::open(&foreign));
    assert!(msg.contains("not a radcache store"), "{msg}");
    assert_eq!(snapshot(&foreign).len(), 1);
    // A store whose `db` file was truncated to nothing (its sample log
    // holds samples: not a store whose creation was cut off).
    let truncated = dir.path().join("truncated");
    {
        let store = Store::open(&truncated).unwrap();
        commit_frames(&store, "j", 0..2);
    }
    std::fs::write(truncated.join("db"), b"").unwrap();
    let before = snapshot(&truncated);
    let msg = err_text(Store::open(&truncated));
    assert!(
        msg.contains("not a radcache store") && msg.contains("truncated"),
        "{msg}"
    );
    assert_eq!(snapshot(&truncated), before);
    // A store whose files were overwritten with garbage: an error (or, if
    // sled finds nothing it can read, an empty store) — never a panic.
    let garbage = dir.path().join("garbage");
    {
        let store = Store::open(&garbage).unwrap();
        commit_frames(&store, "j", 0..2);
    }
    for name in ["conf", "db"] {
        let len = std::fs::metadata(garbage.join(name)).unwrap().len() as usize;
        std::fs::write(garbage.join(name), vec![0xa5u8; len]).unwrap();
    }
    let before = snapshot(&garbage);
    let result = std::panic::catch_unwind(|| Store::open(&garbage).map(|_| ()));
    let result = result.expect("opening a garbage store must not panic");
    let msg = err_text(result);
    assert!(msg.contains(&garbage.display().to_string()), "{msg}");
    assert_eq!(
        snapshot(&garbage),
        before,
        "a refused store is left as it was"
    );
    // A store whose database sled recovers as empty (one byte flipped near
    // the start of `db`): refused, its sample log kept whole. Taking it
    // over as a new store would have emptied the log.
    let flipped = dir.path().join("flipped");
    {
        let store = Store::open(&flipped).unwrap();
        commit_frames(&store, "j", 0..2);
    }
    let mut db = std::fs::read(flipped.join("db")).unwrap();
    db[100] ^= 0xff;
    std::fs::write(flipped.join("db"), &db).unwrap();
    let log = std::fs::read(flipped.join("samples.log")).unwrap();
    assert!(log.len() > 8, "the frames wrote samples");
    for open in [Store::open, Store::open_existing] {
        let msg = err_text(open(&flipped));
        assert!(msg.contains(&flipped.display().to_string()), "{msg}");
        assert_eq!(std::fs::read(flipped.join("samples.log")).unwrap(), log);
    }
    // Another program's sled database: refused, nothing written into it.
    let other = dir.path().join("other");
    {
        let db = open_raw(&other);
        db.open_tree("theirs").unwrap().insert("k", "v").unwrap();
        db.flush().unwrap();
    }
    let msg = err_text(Store::open(&other));
    assert!(msg.contains("`theirs`"), "{msg}");
    let db = open_raw(&other);
    assert!(db.open_tree("meta").unwrap().is_empty(), "meta written");
    assert!(!other.join("samples.log").exists(), "a sample log made");
}

/// A job's scene is its content: the same file named by another path
/// (`./s.gltf`, an absolute path, a run from another directory) resumes
/// the job, and the job then names it as last given; another file, or
/// another built-in scene, is refused, naming the scene.
#[test]
fn a_job_resumes_its_scene_file_named_by_another_path() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let file = |scene: &str, hash: &str| JobSpec {
        scene: scene.into(),
        scene_hash: hash.into(),
        ..spec("f")
    };
    let first = store.begin_job(&file("hs/s.gltf", "aaaa"), false).unwrap();
    let again = store
        .begin_job(&file("/work/hs/s.gltf", "aaaa"), false)
        .unwrap();
    assert_eq!(again.id, first.id);
    assert_eq!(store.job("f").unwrap().unwrap().scene, "/work/hs/s.gltf");
    let msg = err_text(store.begin_job(&file("other.gltf", "bbbb"), false));
    assert!(
        msg.contains("scene (stored /work/hs/s.gltf, given other.gltf)"),
        "{msg}"
    );
    assert!(msg.contains("scene hash"), "{msg}");

    // A schema-1 hash left out the files beside the `.gltf`: another path
    // is not taken for the same scene on its strength.
    let legacy = JobSpec {
        name: "l".into(),
        ..file("old/s.gltf", "cccc+v1")
    };
    let legacy_id = store.begin_job(&legacy, false).unwrap().id;
    let moved = JobSpec {
        name: "l".into(),
        ..file("new/s.gltf", "cccc+dddd")
    };
    let msg = err_text(store.begin_job(&moved, false));
    assert!(
        msg.contains("scene (stored old/s.gltf, given new/s.gltf)"),
        "{msg}"
    );
    // `render` gives the absolute path now: the stored relative name, taken
    // from where the command runs, is that path, and the job resumes.
    let here = std::path::absolute("old/s.gltf").unwrap();
    let absolute = JobSpec {
        name: "l".into(),
        ..file(here.to_str().unwrap(), "cccc+dddd")
    };
    assert_eq!(store.begin_job(&absolute, false).unwrap().id, legacy_id);

    store.begin_job(&spec("b"), false).unwrap();
    let builtin = JobSpec {
        scene: "builtin:spheres".into(),
        ..spec("b")
    };
    let msg = err_text(store.begin_job(&builtin, false));
    assert!(msg.contains("scene (stored builtin:cube-in-box"), "{msg}");
}

#[test]
fn job_with_other_settings_is_refused_unless_forced() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let store = Store::open(&path).unwrap();
    commit_frames(&store, "j", 0..3);
    let old = store.job("j").unwrap().unwrap();
    let mut other = spec("j");
    other.scene_hash = "ffffffffffffffff".into();
    other.seed = 7;
    let msg = err_text(store.begin_job(&other, false));
    assert!(
        msg.contains("scene hash") && msg.contains("seed") && msg.contains("--force"),
        "{msg}"
    );
    // Same settings, other frame range: a resume.
    let mut longer = spec("j");
    longer.frame_end = 20;
    assert_eq!(store.begin_job(&longer, false).unwrap().id, old.id);
    let fresh = store.begin_job(&other, true).unwrap();
    assert_ne!(fresh.id, old.id);
    assert_eq!(fresh.frames_done, 0);
    assert!(store.frames_done(old.id).unwrap().is_empty());
    assert!(store.frame_records(old.id, 0).unwrap().is_empty());
    // Forced with the same settings: started over all the same (the way
    // out for a job whose stored frames are damaged).
    commit_frames(&store, "k", 0..2);
    let done = store.job("k").unwrap().unwrap();
    assert_eq!(done.frames_done, 2);
    let again = store.begin_job(&spec("k"), true).unwrap();
    assert_ne!(again.id, done.id);
    assert_eq!(again.frames_done, 0);
    assert!(store.frames_done(done.id).unwrap().is_empty());
}

#[test]
fn a_job_started_under_another_algorithm_revision_is_refused_unless_forced() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let trc = JobSpec {
        method: "trc".into(),
        ..spec("t")
    };
    let now = radcache::method::algorithm_revision("trc");
    assert!(now > 1, "trc's algorithm has changed since revisions began");
    // A `path` job stored by this build, under this build's revision.
    let path_spec = JobSpec {
        method: "path".into(),
        ..spec("i")
    };
    let (first, path_job) = {
        let store = Store::open(&path).unwrap();
        let path_job = store.begin_job(&path_spec, false).unwrap();
        let first = store.begin_job(&trc, false).unwrap();
        assert_eq!(store.job_revision(first.id).unwrap(), now);
        assert_eq!(store.begin_job(&trc, false).unwrap().id, first.id);
        (first, path_job)
    };
    // The `trc` job as a build from before revisions were recorded left it.
    {
        let db = open_raw(&path);
        let meta = db.open_tree("meta").unwrap();
        assert!(meta
            .remove(keys::meta_revision(first.id))
            .unwrap()
            .is_some());
        db.flush().unwrap();
    }
    let store = Store::open(&path).unwrap();
    assert_eq!(store.job_revision(first.id).unwrap(), 1);
    let msg = err_text(store.begin_job(&trc, false));
    assert!(
        msg.contains(&format!(
            "`trc` algorithm revision (stored 1, this build {now}"
        )) && msg.contains("--force"),
        "{msg}"
    );
    let report = radcache::store::inspect::report(&store, Some("t"), None).unwrap();
    assert_eq!(report.jobs[0].algorithm_revision, 1);
    let text = radcache::store::inspect::to_text(&report, false);
    assert!(
        text.contains(&format!("algorithm revision 1 (this build's is {now}")),
        "{text}"
    );
    // The `path` job resumes: its revision is this build's.
    assert_eq!(store.begin_job(&path_spec, false).unwrap().id, path_job.id);
    let before = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    let fresh = store.begin_job(&trc, true).unwrap();
    assert_ne!(fresh.id, first.id);
    assert!(fresh.created_unix >= before && fresh.updated_unix >= before);
    assert_eq!(store.job_revision(fresh.id).unwrap(), now);
    let resumed = store.begin_job(&trc, false).unwrap();
    assert_eq!(resumed.id, fresh.id);
    assert!(resumed.updated_unix >= before);
    // Deleted with its job.
    store.delete_job("t").unwrap();
    assert_eq!(store.job_revision(fresh.id).unwrap(), 1);
}

#[test]
fn compact_removes_revisions_no_job_holds() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let (kept, gone) = {
        let store = Store::open(&path).unwrap();
        let trc = JobSpec {
            method: "trc".into(),
            ..spec("k")
        };
        let kept = store.begin_job(&trc, false).unwrap().id;
        (kept, kept + 1000)
    };
    // As a kill between a job's revision and the job itself leaves it,
    // or an older build that deleted the job.
    {
        let db = open_raw(&path);
        let meta = db.open_tree("meta").unwrap();
        meta.insert(keys::meta_revision(gone), &7u64.to_be_bytes()[..])
            .unwrap();
        db.flush().unwrap();
    }
    let store = Store::open(&path).unwrap();
    assert_eq!(store.job_revision(gone).unwrap(), 7);
    assert_eq!(store.remove_orphaned_job_data().unwrap(), 1);
    assert_eq!(store.job_revision(gone).unwrap(), 1);
    assert_eq!(
        store.job_revision(kept).unwrap(),
        radcache::method::algorithm_revision("trc")
    );
    assert_eq!(store.remove_orphaned_job_data().unwrap(), 0);
}

#[test]
fn inspecting_an_unknown_job_lists_the_jobs() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let msg = err_text(radcache::store::inspect::report(&store, Some("b"), None));
    assert!(
        msg.contains("no such job in this store (jobs: none)"),
        "{msg}"
    );
    store.begin_job(&spec("a"), false).unwrap();
    store.begin_job(&spec("c"), false).unwrap();
    let msg = err_text(radcache::store::inspect::report(&store, Some("b"), None));
    assert!(msg.contains("(jobs: a, c)"), "{msg}");
}

#[test]
fn a_new_job_does_not_take_a_former_jobs_cancel_mark() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    store.begin_job(&spec("c"), false).unwrap();
    store.set_job_cancelled("c", true).unwrap();
    store.delete_job("c").unwrap();
    assert!(!store.job_cancelled("c").unwrap());
    // A cancel that came as the job was deleted leaves its mark behind.
    store.set_job_cancelled("c", true).unwrap();
    store.begin_job(&spec("c"), false).unwrap();
    assert!(!store.job_cancelled("c").unwrap());
    // A job's own mark stays when it resumes.
    store.set_job_cancelled("c", true).unwrap();
    store.begin_job(&spec("c"), false).unwrap();
    assert!(store.job_cancelled("c").unwrap());
}

/// `method`'s spec for job `name`, its settings JSON as `render` writes it
/// less the keys `without` (a job stored before those settings existed).
fn spec_of(name: &str, method: &MethodSettings, without: &[&str]) -> JobSpec {
    // Through the text, as `render` writes it: `to_value` widens an f32.
    let text = serde_json::to_string(method).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let fields = json
        .as_object_mut()
        .and_then(|tagged| tagged.values_mut().next())
        .and_then(|inner| inner.as_object_mut())
        .unwrap();
    for key in without {
        assert!(fields.remove(*key).is_some(), "no setting {key}");
    }
    JobSpec {
        method: method.name().into(),
        settings: json.to_string(),
        ..spec(name)
    }
}

/// A job stored before a setting existed resumes under the value it ran
/// with, the setting's serde default, and is refused, naming the setting,
/// under another: `tcg` before its light, occlusion and arrival rules ran
/// the paper's rule (off), `trc` before kept paths traced them again (its
/// frames are the same with them on, so on is the default it resumes
/// with).
#[test]
fn a_job_stored_before_a_setting_existed_resumes_under_the_value_it_ran() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let tcg = |light_refresh, occlusion_refresh, arrivals| {
        MethodSettings::Tcg(TcgSettings {
            light_refresh,
            occlusion_refresh,
            arrivals,
            ..TcgSettings::default()
        })
    };
    let rules = ["light_refresh", "occlusion_refresh", "arrivals"];
    let old = store
        .begin_job(&spec_of("t", &tcg(false, false, false), &rules), false)
        .unwrap();
    for (given, rule) in [
        (tcg(true, false, false), rules[0]),
        (tcg(false, true, false), rules[1]),
        (tcg(false, false, true), rules[2]),
    ] {
        let msg = err_text(store.begin_job(&spec_of("t", &given, &[]), false));
        assert!(
            msg.contains(&format!("{rule}: stored false, given true")),
            "{msg}"
        );
    }
    let resumed = store.begin_job(&spec_of("t", &tcg(false, false, false), &[]), false);
    assert_eq!(resumed.unwrap().id, old.id);

    let trc = MethodSettings::Trc(TrcSettings::default());
    let old = store
        .begin_job(&spec_of("r", &trc, &["keep_paths"]), false)
        .unwrap();
    let resumed = store.begin_job(&spec_of("r", &trc, &[]), false);
    assert_eq!(resumed.unwrap().id, old.id);
}

/// `trc`'s `next_direct` was a flag before it had a mode between: a job
/// stored with `false` (the default then) resumes under `off` and is
/// refused under today's default (`long-lives`), naming the setting;
/// one stored with `true` resumes under `on`.
#[test]
fn a_trc_job_stored_with_next_direct_as_a_flag_reads_it_as_off_or_on() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let trc = |next_direct| {
        MethodSettings::Trc(TrcSettings {
            next_direct,
            ..TrcSettings::default()
        })
    };
    for (name, flag, mode) in [
        ("off", false, NextDirect::Off),
        ("on", true, NextDirect::On),
    ] {
        let mut spec = spec_of(name, &trc(mode), &[]);
        let mut json: serde_json::Value = serde_json::from_str(&spec.settings).unwrap();
        json["Trc"]["next_direct"] = flag.into();
        spec.settings = json.to_string();
        let old = store.begin_job(&spec, false).unwrap();
        let resumed = store.begin_job(&spec_of(name, &trc(mode), &[]), false);
        assert_eq!(resumed.unwrap().id, old.id);
        if !flag {
            let given = spec_of(name, &trc(NextDirect::LongLives), &[]);
            let msg = err_text(store.begin_job(&given, false));
            assert!(
                msg.contains("next_direct: stored off, given long-lives"),
                "{msg}"
            );
        }
    }
}

/// A job refused for another spp names it once: it is one of the method's
/// settings and the job's spp too.
#[test]
fn another_spp_is_named_once() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let ic = |spp| {
        let method = MethodSettings::Ic(IcSettings {
            spp,
            ..IcSettings::default()
        });
        JobSpec {
            spp,
            ..spec_of("s", &method, &[])
        }
    };
    store.begin_job(&ic(2), false).unwrap();
    let msg = err_text(store.begin_job(&ic(4), false));
    assert!(msg.contains("spp: stored 2, given 4"), "{msg}");
    assert_eq!(msg.matches("spp").count(), 1, "{msg}");
}

/// `ic` with few strata and one sample per pixel: fixtures and resumes
/// that stay fast.
fn small_ic() -> MethodSettings {
    MethodSettings::Ic(small_ic_settings())
}

fn small_ic_settings() -> IcSettings {
    IcSettings {
        strata: Strata { theta: 4, phi: 12 },
        spp: 1,
        ..IcSettings::default()
    }
}

fn renderer(method: &MethodSettings) -> Renderer {
    renderer_of("cube-in-box", method)
}

/// [`renderer`] of the built-in scene `scene`.
fn renderer_of(scene: &str, method: &MethodSettings) -> Renderer {
    let source = SceneSource::Builtin(scene.into());
    let settings = FrameSettings {
        width: 16,
        height: 16,
        ..FrameSettings::default()
    };
    Renderer::new(
        source.load().unwrap(),
        method.instantiate(),
        render::make_backend(render::BackendChoice::Cpu).unwrap(),
        settings,
    )
}

fn exr_files(dir: &Path, frames: std::ops::Range<u32>) -> Vec<Vec<u8>> {
    frames
        .map(|f| std::fs::read(film::frame_path(dir, f, "exr")).unwrap())
        .collect()
}

fn resume_matches_uninterrupted(method: MethodSettings) {
    resume_matches_uninterrupted_on("cube-in-box", method);
}

/// [`resume_matches_uninterrupted`] on the built-in scene `scene`, a job
/// rendered in parts two ways: frames 0..2, a frame 4 from another range,
/// then 0..6 (a method that carries state from frame to frame starts
/// over, the state stored last being another chain's: frames 0..2 come
/// from the store only where each frame stands alone); and frame 4 first,
/// then 0..2, then 0..6 (every method resumes after frame 1, one that
/// carries state from the state stored there, rendering frame 4 again
/// in its chain).
fn resume_matches_uninterrupted_on(scene: &str, method: MethodSettings) {
    let carries_state = method.instantiate().carries_state();
    let stands_alone = (3, 3);
    let starts_over = (0, 6);
    let first = if carries_state {
        starts_over
    } else {
        stands_alone
    };
    resume_in_parts(scene, &method, [0..2, 4..5, 0..6], first);
    let resumes = if carries_state { (2, 4) } else { stands_alone };
    resume_in_parts(scene, &method, [4..5, 0..2, 0..6], resumes);
}

/// Renders a job of `method` on built-in `scene` in `parts` into a store,
/// the last part's (resumed, rendered) frames being `last`, and checks its
/// frames against an uninterrupted render's, also after files are
/// deleted from `--out`.
fn resume_in_parts(
    scene: &str,
    method: &MethodSettings,
    parts: [std::ops::Range<u32>; 3],
    last: (u32, u32),
) {
    let method = method.clone();
    let renderer = |m: &MethodSettings| renderer_of(scene, m);
    let dir = tempfile::tempdir().unwrap();
    let (plain, resumed) = (dir.path().join("plain"), dir.path().join("resumed"));
    render::render_to_dir(&mut renderer(&method), 0..6, &plain, true).unwrap();
    let path = dir.path().join("db");
    let source = SceneSource::Builtin(scene.into());
    let fs = renderer(&method).settings.clone();
    let job_spec = render::job_spec("j", &source, &method, &fs, 0..6).unwrap();
    let store = Store::open(&path).unwrap();
    for part in &parts {
        let job = store.begin_job(&job_spec, false).unwrap();
        let mut sj = StoreJob { store: &store, job };
        let summary = render::render_job_to_dir(
            &mut renderer(&method),
            part.clone(),
            &resumed,
            true,
            Some(&mut sj),
        )
        .unwrap();
        if *part == (0..6) {
            assert_eq!((summary.resumed, summary.frames), last, "after {parts:?}");
        }
    }
    assert_eq!(exr_files(&plain, 0..6), exr_files(&resumed, 0..6));
    let job = store.job("j").unwrap().unwrap();
    assert_eq!(job.frames_done, 6);
    for f in 0..6 {
        assert_eq!(
            store.frame_exr(job.id, f).unwrap().unwrap(),
            std::fs::read(film::frame_path(&plain, f, "exr")).unwrap()
        );
    }
    // Files deleted from --out come back from the store on the next run,
    // with no temporary file left beside them.
    std::fs::remove_file(film::frame_path(&resumed, 2, "exr")).unwrap();
    std::fs::remove_file(film::frame_path(&resumed, 3, "png")).unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&job_spec, false).unwrap(),
    };
    let s = render::render_job_to_dir(&mut renderer(&method), 0..6, &resumed, true, Some(&mut sj))
        .unwrap();
    assert_eq!((s.resumed, s.frames), (6, 0));
    assert_eq!(exr_files(&plain, 0..6), exr_files(&resumed, 0..6));
    assert_eq!(
        std::fs::read(film::frame_path(&plain, 3, "png")).unwrap(),
        std::fs::read(film::frame_path(&resumed, 3, "png")).unwrap()
    );
    let hidden: Vec<_> = std::fs::read_dir(&resumed)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(hidden.is_empty(), "{hidden:?}");
}

#[test]
fn resumed_path_render_is_bit_identical_to_uninterrupted() {
    resume_matches_uninterrupted(MethodSettings::Path(PathSettings {
        spp: 2,
        ..PathSettings::default()
    }));
}

#[test]
fn resumed_ic_render_is_bit_identical_and_stores_records_with_samples() {
    let settings = small_ic_settings();
    resume_matches_uninterrupted(MethodSettings::Ic(settings.clone()));
    // The records of a frame with their 48 samples each.
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let method = MethodSettings::Ic(settings);
    let mut r = renderer(&method);
    let spec = render::job_spec(
        "j",
        &SceneSource::Builtin("cube-in-box".into()),
        &method,
        &r.settings,
        0..1,
    )
    .unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let s = render::render_job_to_dir(&mut r, 0..1, &dir.path().join("out"), true, Some(&mut sj))
        .unwrap();
    let recs = store.frame_records(sj.job.id, 0).unwrap();
    assert_eq!(recs.len() as u64, s.frame_stats[0].records_created);
    assert!(!recs.is_empty());
    for rec in &recs {
        let samples = store.record_samples(sj.job.id, 0, rec.id).unwrap();
        assert_eq!(samples.len(), 48);
        // Irradiance from the stored samples ≈ the record's (RGBE error only).
        let e: Vec3 =
            samples.iter().map(|s| s.radiance()).sum::<Vec3>() * (std::f32::consts::PI / 48.0);
        let want = Vec3::from(rec.irradiance);
        assert!(
            (e - want).abs().max_element() <= want.max_element() * 0.01 + 1e-6,
            "{e} vs {want}"
        );
    }
}

/// A frame's `stored_bytes` is what its checkpoint wrote. Over a fresh
/// `ic` job (no carried state, no movies) that is the sample log past its
/// header, plus each frame's `frames` and `records` values and the job's
/// value as each frame rewrote it. Each frame's `cache_bytes` holds at
/// least its records, and `ic` shoots nothing again.
#[test]
fn frame_statistics_count_what_each_checkpoint_wrote_and_the_cache_held() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let method = small_ic();
    let mut r = renderer(&method);
    let source = SceneSource::Builtin("cube-in-box".into());
    let spec = render::job_spec("j", &source, &method, &r.settings, 0..3).unwrap();
    let store = Store::open(&path).unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let s = render::render_job_to_dir(&mut r, 0..3, &dir.path().join("out"), true, Some(&mut sj))
        .unwrap();
    let id = sj.job.id;
    let stored: u64 = (0..3)
        .map(|f| store.frame_stats(id, f).unwrap().unwrap().stored_bytes)
        .sum();
    let log = store.sample_log_bytes() - radcache::store::samples::MAGIC.len() as u64;
    drop(store);
    let db = open_raw(&path);
    let value_len = |tree: &str, key: &[u8]| {
        let v = db.open_tree(tree).unwrap().get(key).unwrap();
        v.map_or(0, |v| v.len() as u64)
    };
    let job = value_len("jobs", &keys::job("j"));
    let trees: u64 = (0..3)
        .map(|f| {
            value_len("frames", &keys::frame(id, f)) + value_len("records", &keys::frame(id, f))
        })
        .sum();
    assert!(log > 0 && trees > 0);
    assert_eq!(stored, log + trees + 3 * job);
    let record = std::mem::size_of::<radcache::cache::IrradianceRecord>() as u64;
    for f in &s.frame_stats {
        assert!(f.records_alive > 0);
        assert!(f.cache_bytes >= f.records_alive * record, "{f:?}");
        assert_eq!(f.samples_reshot, 0);
    }
}

#[test]
fn resumed_trc_render_is_bit_identical() {
    // Also across other ranges of the same job: a range whose stored state
    // belongs to another chain starts over.
    let mut trc = TrcSettings::default();
    trc.ic.strata = Strata { theta: 4, phi: 12 };
    trc.ic.spp = 1;
    resume_matches_uninterrupted(MethodSettings::Trc(trc));
}

/// `trc` under the built-in moving light, where each record's samples'
/// direct light is evaluated at t0+1 and at the end of its life, and
/// what one frame found is kept for the next (the moving triangles' BVH
/// at t0+1, `trc::direct::ShadowGeometry`; each later frame's geometry
/// the records' checks made, `trc::later::Ahead`): a resumed render
/// starts with none of it and gives the same frames.
#[test]
fn resumed_trc_render_under_a_moving_light_is_bit_identical() {
    let mut trc = TrcSettings::default();
    trc.ic.strata = Strata { theta: 4, phi: 12 };
    trc.ic.spp = 1;
    resume_matches_uninterrupted_on("moving-light", MethodSettings::Trc(trc));
}

/// `trc` among the moving balls, whose records live short, stopped after
/// frame 1 of 0..6: its default decides at each frame from the records
/// alive whether to evaluate the direct light at t0+1
/// (`NextDirect::LongLives`: at the first frame, none being alive, it
/// does; after it, here, not), and the resume, deciding from the restored
/// records, gives the uninterrupted frames (one that restored none, or
/// kept a count of its own, would decide at frame 2 as at a first frame).
#[test]
fn resumed_trc_render_among_short_lived_records_is_bit_identical() {
    let mut trc = TrcSettings::default();
    trc.ic.strata = Strata { theta: 4, phi: 12 };
    trc.ic.spp = 1;
    let method = MethodSettings::Trc(trc);
    let dir = tempfile::tempdir().unwrap();
    let (plain, resumed) = (dir.path().join("plain"), dir.path().join("resumed"));
    let renderer = || renderer_of("spheres", &method);
    render::render_to_dir(&mut renderer(), 0..6, &plain, true).unwrap();
    let source = SceneSource::Builtin("spheres".into());
    let fs = renderer().settings.clone();
    let job_spec = render::job_spec("j", &source, &method, &fs, 0..6).unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    for (part, done_before) in [(0..2, 0), (0..6, 2)] {
        let mut sj = StoreJob {
            store: &store,
            job: store.begin_job(&job_spec, false).unwrap(),
        };
        let summary =
            render::render_job_to_dir(&mut renderer(), part, &resumed, true, Some(&mut sj))
                .unwrap();
        assert_eq!(summary.resumed, done_before, "frames taken from the store");
    }
    assert_eq!(exr_files(&plain, 0..6), exr_files(&resumed, 0..6));
}

/// `trc` with radiance records (`--ic-glossy eas`) on `glossy-cornell`,
/// stopped after frame 2 of 0..6: the resume starts from the stored state,
/// whose records' material, sources and their temporal gradients come
/// back (without them the resumed frames would differ: the glossy
/// surfaces would reflect no sources, or unmoved ones).
#[test]
fn resumed_trc_render_with_radiance_records_is_bit_identical() {
    let trc = TrcSettings {
        ic: IcSettings {
            glossy: GlossyLobe::Eas,
            ..small_ic_settings()
        },
        ..TrcSettings::default()
    };
    let state = resume_from_state_matches_uninterrupted("glossy-cornell", MethodSettings::Trc(trc));
    // `inspect` counts the radiance records and their sources.
    assert!(state.radiance_records > 0 && state.radiance_records <= state.records);
    assert!(state.sources >= state.radiance_records, "{state:?}");
}

/// `tcg` with radiance records: the material comes back from the stored
/// state, and the sources are built again from the stored samples.
#[test]
fn resumed_tcg_render_with_radiance_records_is_bit_identical() {
    let tcg = TcgSettings {
        ic: IcSettings {
            glossy: GlossyLobe::Eas,
            ..small_ic_settings()
        },
        ..TcgSettings::default()
    };
    let state = resume_from_state_matches_uninterrupted("glossy-cornell", MethodSettings::Tcg(tcg));
    // `tcg` stores no sources: they are built from the samples.
    assert!(
        state.radiance_records > 0 && state.sources == 0,
        "{state:?}"
    );
}

/// A job with radiance records stores the sources of each record version
/// it writes, under the frame that wrote it: only records of that frame's
/// block, the diffuse walls' records without any, and each record's
/// sources together bring its irradiance (they split its hemisphere's
/// cells; a source that brings none is not kept). `inspect` counts them,
/// and a job started over leaves none behind.
#[test]
fn radiance_records_store_their_sources_until_the_job_starts_over() {
    let method = MethodSettings::Ic(IcSettings {
        glossy: GlossyLobe::Eas,
        ..small_ic_settings()
    });
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let source = SceneSource::Builtin("glossy-cornell".into());
    let fs = renderer_of("glossy-cornell", &method).settings.clone();
    let spec = render::job_spec("j", &source, &method, &fs, 0..2).unwrap();
    let render = |force: bool| {
        let mut sj = StoreJob {
            store: &store,
            job: store.begin_job(&spec, force).unwrap(),
        };
        let mut r = renderer_of("glossy-cornell", &method);
        render::render_job_to_dir(&mut r, 0..2, &dir.path().join("o"), true, Some(&mut sj))
            .unwrap();
        sj.job.id
    };
    let id = render(false);
    let mut counted = (0, 0);
    for f in 0..2 {
        let records = store.frame_records(id, f).unwrap();
        let sources = store.frame_sources(id, f).unwrap().unwrap().records;
        assert!(
            !sources.is_empty() && sources.len() < records.len(),
            "frame {f}"
        );
        assert!(sources.windows(2).all(|w| w[0].id < w[1].id));
        for rs in &sources {
            let record = records.iter().find(|r| r.id == rs.id).unwrap();
            let sum: Vec3 = rs.sources.iter().map(|s| Vec3::from(s.irradiance)).sum();
            let want = Vec3::from(record.irradiance);
            assert!(
                (sum - want).abs().max_element() <= 1e-4 * want.max_element() + 1e-6,
                "record {}: sources bring {sum}, the record {want}",
                rs.id
            );
            assert!(rs.sources.iter().all(|s| s.solid_angle > 0.0));
            counted.0 += 1;
            counted.1 += rs.sources.len() as u64;
        }
    }
    let report = radcache::store::inspect::report(&store, Some("j"), None).unwrap();
    let j = &report.jobs[0];
    assert_eq!((j.radiance_records, j.sources), counted);
    // Started over with other settings (`--force`): the old frames'
    // sources are gone with their records.
    let other = JobSpec {
        seed: spec.seed + 1,
        ..spec.clone()
    };
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&other, true).unwrap(),
    };
    for f in 0..2 {
        assert_eq!(store.frame_sources(id, f).unwrap(), None);
    }
    let mut r = renderer_of("glossy-cornell", &method);
    r.settings.seed = other.seed;
    render::render_job_to_dir(&mut r, 0..1, &dir.path().join("o2"), true, Some(&mut sj)).unwrap();
    assert!(store.frame_sources(sj.job.id, 0).unwrap().is_some());
}

/// A job of `method` on the built-in `scene` stopped after frame 2 of 0..6
/// resumes from its stored state (frames 3..5 rendered, not 0..2 again)
/// and its frames equal an uninterrupted render's byte for byte. Returns
/// what `inspect` reports of its carried state, which it also prints.
fn resume_from_state_matches_uninterrupted(
    scene: &str,
    method: MethodSettings,
) -> radcache::store::inspect::StateReport {
    let renderer = |m: &MethodSettings| renderer_of(scene, m);
    let dir = tempfile::tempdir().unwrap();
    let (plain, resumed) = (dir.path().join("plain"), dir.path().join("resumed"));
    render::render_to_dir(&mut renderer(&method), 0..6, &plain, true).unwrap();
    let source = SceneSource::Builtin(scene.into());
    let fs = renderer(&method).settings.clone();
    let job_spec = render::job_spec("j", &source, &method, &fs, 0..6).unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    for (range, done) in [(0..3, (0, 3)), (0..6, (3, 3))] {
        let job = store.begin_job(&job_spec, false).unwrap();
        let mut sj = StoreJob { store: &store, job };
        let s =
            render::render_job_to_dir(&mut renderer(&method), range, &resumed, true, Some(&mut sj))
                .unwrap();
        assert_eq!((s.resumed, s.frames), done);
    }
    assert_eq!(exr_files(&plain, 0..6), exr_files(&resumed, 0..6));
    let report = radcache::store::inspect::report(&store, Some("j"), None).unwrap();
    let state = report.jobs[0].state.clone().expect("a carried state");
    let text = radcache::store::inspect::to_text(&report, false);
    let shown = format!("{} radiance records", state.radiance_records);
    assert!(text.contains(&shown), "{text}");
    state
}

/// `tcg` resumes from its stored state, whose records carry their samples
/// (ages included): stopped after frame 3 of 0..8, the resume renders
/// frames 4..7 only, with exactly their rays, and every frame equals an
/// uninterrupted run byte for byte, as across other ranges of the same
/// job. The stored records of a frame carry samples shot in earlier frames.
#[test]
fn resumed_tcg_render_is_bit_identical_from_stored_state() {
    let mut tcg = TcgSettings::default();
    tcg.ic.strata = Strata { theta: 4, phi: 12 };
    tcg.ic.spp = 1;
    tcg.tau_min = 0.2;
    let method = MethodSettings::Tcg(tcg);
    resume_matches_uninterrupted(method.clone());

    let dir = tempfile::tempdir().unwrap();
    let (plain, resumed) = (dir.path().join("plain"), dir.path().join("resumed"));
    let uninterrupted = render::render_to_dir(&mut renderer(&method), 0..8, &plain, true).unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let source = SceneSource::Builtin("cube-in-box".into());
    let spec = render::job_spec("j", &source, &method, &renderer(&method).settings, 0..8).unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let s = render::render_job_to_dir_with(
        &mut renderer(&method),
        0..8,
        &resumed,
        true,
        Some(&mut sj),
        &mut |f| f < 3,
    )
    .unwrap();
    assert_eq!(s.frames, 4);
    let id = sj.job.id;
    let state = store.load_state(id).unwrap().unwrap();
    assert_eq!(state.frame, 3);
    assert_eq!(
        state.records.len() as u64,
        uninterrupted.frame_stats[3].records_alive
    );
    let records = store.frame_records(id, 3).unwrap();
    assert!(!records.is_empty());
    let ages: Vec<u32> = records
        .iter()
        .flat_map(|r| store.record_samples(id, 3, r.id).unwrap())
        .map(|s| s.age())
        .collect();
    assert!(ages.contains(&0) && ages.iter().any(|&a| a > 0));

    let mut second = renderer(&method);
    let s = render::render_job_to_dir(&mut second, 0..8, &resumed, true, Some(&mut sj)).unwrap();
    assert_eq!((s.resumed, s.frames), (4, 4));
    assert_eq!(second.method_calls().rendered, 4);
    assert_resumed_rays(&s.frame_stats, &uninterrupted.frame_stats[4..]);
    assert_eq!(exr_files(&plain, 0..8), exr_files(&resumed, 0..8));
    // `inspect` counts each record once, by its latest version, though
    // tcg writes its records again every frame.
    let report = radcache::store::inspect::report(&store, Some("j"), None).unwrap();
    let job = &report.jobs[0];
    let computed: u64 = uninterrupted
        .frame_stats
        .iter()
        .map(|f| f.records_created)
        .sum();
    assert_eq!(job.records, computed);
    assert!(job.record_versions > job.records, "{}", job.record_versions);
    assert_eq!(job.lifespan_histogram.values().sum::<u64>(), job.records);
}

/// A `movies` job keeps no state from frame to frame (a movie kept gives
/// the texels a new one would), so it resumes as `ic` does: across ranges
/// its frames equal an uninterrupted run byte for byte. Each frame's
/// texture movies are stored with it (`movies` tree): every movie open in
/// the frame, its texels within RGBE's precision of the method's, and a
/// job started over loses them with its frames.
#[test]
fn movies_job_stores_its_texture_movies_and_resumes_bit_identically() {
    let movies = MoviesSettings {
        spp: 2,
        shadow_samples: 4,
        ..MoviesSettings::default()
    };
    let method = MethodSettings::Movies(movies.clone());
    resume_matches_uninterrupted(method.clone());

    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let source = SceneSource::Builtin("cube-in-box".into());
    let spec = render::job_spec("m", &source, &method, &renderer(&method).settings, 0..3).unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    render::render_job_to_dir(
        &mut renderer(&method),
        0..3,
        &dir.path().join("out"),
        true,
        Some(&mut sj),
    )
    .unwrap();
    // The method's own movies after frame 2, to compare with the stored ones.
    let mut r = renderer(&MethodSettings::Path(Default::default()));
    let mut direct = TextureMovies::new(movies);
    for f in 0..3 {
        r.with_frame_context(f, |ctx| direct.render_frame(ctx));
    }
    let stored = store.frame_movie_texels(sj.job.id, 2).unwrap();
    let mine: Vec<&Movie> = direct.movies().collect();
    assert_eq!(stored.len(), mine.len());
    assert!(!mine.is_empty());
    // The movies nothing changed were stored once, with an earlier frame.
    let value = store.frame_movies(sj.job.id, 2).unwrap().unwrap();
    assert!(value
        .movies
        .iter()
        .any(|m| m.texels == 0 && m.stored_at < 2));
    assert!(value
        .movies
        .iter()
        .any(|m| m.texels > 0 && m.stored_at == 2));
    for ((value, texels), movie) in stored.iter().zip(&mine) {
        assert_eq!(
            (
                value.triangle,
                value.back,
                value.patch,
                value.resolution,
                value.start
            ),
            (
                movie.key.triangle,
                movie.key.back,
                movie.key.patch.code(),
                movie.resolution,
                movie.start
            )
        );
        // The movie holds its direct part as the store keeps it (RGBE).
        let band: Vec<Vec3> = movie.direct().collect();
        assert_eq!(*texels, band);
    }
    // Started over with other settings, the job's movies go with its frames.
    let other = MethodSettings::Movies(MoviesSettings {
        shadow_samples: 8,
        ..MoviesSettings::default()
    });
    let spec = render::job_spec("m", &source, &other, &renderer(&other).settings, 0..3).unwrap();
    let job = store.begin_job(&spec, true).unwrap();
    assert_eq!(store.frame_movies(job.id, 2).unwrap(), None);
    assert_eq!(store.frame_movies(sj.job.id, 2).unwrap(), None);
}

/// A `trc` render stopped after frame 5 of 0..10 — with records created
/// before frame 5 that are still valid after it (mid-window), and records
/// whose life ends at frame 5 (replaced or dropped on resume, as their
/// stored `used` flags say) — resumes from the stored state: only frames
/// 6..9 are rendered (and, with interpolated gradients, only their first
/// passes run), with exactly their rays, and the frames equal an
/// uninterrupted run byte for byte. A corrupt state record is a clear
/// error naming tree and key.
fn trc_resumes_from_stored_state(gradients: TemporalGradients) {
    let mut trc = TrcSettings::default();
    trc.ic.strata = Strata { theta: 4, phi: 12 };
    trc.ic.spp = 1;
    trc.max_life = 6;
    trc.temporal_accuracy = 0.02;
    trc.gradients = gradients;
    let method = MethodSettings::Trc(trc);
    // 4 fps: the cube moves enough per frame for records of many lifespans.
    let renderer = |m: &MethodSettings| {
        let mut r = renderer(m);
        r.settings.fps = 4.0;
        r
    };
    let dir = tempfile::tempdir().unwrap();
    let (plain, resumed) = (dir.path().join("plain"), dir.path().join("resumed"));
    let mut r = renderer(&method);
    let uninterrupted = render::render_to_dir(&mut r, 0..10, &plain, true).unwrap();
    assert_eq!(r.method_calls().rendered, 10);

    let store = Store::open(&dir.path().join("db")).unwrap();
    let source = SceneSource::Builtin("cube-in-box".into());
    let spec = render::job_spec("j", &source, &method, &r.settings, 0..10).unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let mut first = renderer(&method);
    let s = render::render_job_to_dir_with(
        &mut first,
        0..10,
        &resumed,
        true,
        Some(&mut sj),
        &mut |f| f < 5,
    )
    .unwrap();
    assert_eq!(s.frames, 6);
    let id = sj.job.id;

    // The stored state is the one after frame 5, and it is mid-window.
    let state = store.load_state(id).unwrap().unwrap();
    assert_eq!(state.frame, 5);
    let alive: std::collections::HashSet<u64> = state.records.iter().map(|r| r.0).collect();
    let (mut spanning, mut ending) = (0, 0);
    store
        .for_each_record(id, u32::MAX, |_, rec| {
            if alive.contains(&rec.id) && rec.created_frame < 5 {
                spanning += u32::from(rec.last_frame > 5);
                ending += u32::from(rec.last_frame == 5);
            }
        })
        .unwrap();
    assert!(spanning > 0, "no record spans the resume point");
    assert!(ending > 0, "no record ends at the resume point");

    // A corrupt state record: a clear error naming tree and key.
    let (bad_id, _) = state.records[0];
    let key = keys::state_record(id, bad_id);
    let good = store.tree("state").unwrap().get(key).unwrap().unwrap();
    store.raw_insert("state", &key, b"garbage").unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let msg =
        render::render_job_to_dir(&mut renderer(&method), 0..10, &resumed, true, Some(&mut sj))
            .map(|_| ())
            .unwrap_err()
            .to_string();
    assert!(
        msg.contains("tree `state`") && msg.contains(&format!("(id {id}) record {bad_id}")),
        "{msg}"
    );
    store.raw_insert("state", &key, &good).unwrap();

    // The resume renders frames 6..9 only.
    let mut second = renderer(&method);
    let s = render::render_job_to_dir(&mut second, 0..10, &resumed, true, Some(&mut sj)).unwrap();
    assert_eq!((s.resumed, s.frames), (6, 4));
    let calls = second.method_calls();
    assert_eq!(calls.rendered, 4, "no finished frame rendered again");
    if gradients == TemporalGradients::Interpolated {
        assert_eq!(calls.prepared, 4, "first passes of frames 6..9 only");
    } else {
        assert_eq!(calls.prepared, 0);
        assert_resumed_rays_without_kept_paths(&s.frame_stats, &uninterrupted.frame_stats[6..]);
    }
    assert_eq!(exr_files(&plain, 0..10), exr_files(&resumed, 0..10));
    // The state stays the working set: records alive after the last frame.
    let state = store.load_state(id).unwrap().unwrap();
    assert_eq!(state.frame, 9);
    assert_eq!(
        state.records.len() as u64,
        uninterrupted.frame_stats[9].records_alive
    );
    let report = radcache::store::inspect::report(&store, Some("j"), None).unwrap();
    let st = report.jobs[0].state.as_ref().unwrap();
    assert_eq!((st.frame, st.chain_start), (9, 0));
    assert_eq!(st.records, state.records.len() as u64);
    let text = radcache::store::inspect::to_text(&report, false);
    assert!(text.contains("carried state after frame 9"), "{text}");
    // `inspect` shows each frame's record statistics as the uninterrupted
    // render counted them (frames 0..5 from the first render, 6..9 from
    // the resume).
    let rows = &report.jobs[0].frame_details;
    assert_eq!(rows.len(), 10);
    for (row, stats) in rows.iter().zip(&uninterrupted.frame_stats) {
        let shown = (
            row.records_alive,
            row.records_created,
            row.records_reused,
            row.records_replaced,
            row.records_dropped,
            row.mean_lifespan,
        );
        let counted = (
            stats.records_alive,
            stats.records_created,
            stats.records_reused,
            stats.records_replaced,
            stats.records_dropped,
            stats.mean_lifespan,
        );
        assert_eq!(shown, counted, "frame {}", row.frame);
    }
    assert!(
        rows.iter().skip(1).any(|r| r.records_reused > 0),
        "{rows:?}"
    );
    let text = radcache::store::inspect::to_text(&report, true);
    assert!(
        text.contains("created") && text.contains("replaced") && text.contains("life"),
        "{text}"
    );
    // A frame the job has not finished is said to be missing, not an
    // empty table.
    let report = radcache::store::inspect::report(&store, Some("j"), Some(99)).unwrap();
    let text = radcache::store::inspect::to_text(&report, true);
    assert!(
        text.contains("frame 99 is not among this job's finished frames (10 of frames 0..10 done, the last 9)"),
        "{text}"
    );
}

/// A `trc` job rendered as 0..3 and then 3..6 holds frames 3..5 of a
/// chain that started at frame 3: asked for 0..6, it renders the whole
/// range again rather than calling it done, and its frames equal one 0..6
/// render. Asked then for 0..3, done by that chain, it renders nothing;
/// with interpolated gradients (frames depend on the range's end) it
/// renders 0..3 again. A frame whose PNG alone was deleted gets it back.
#[test]
fn trc_frames_done_by_another_chain_are_rendered_again() {
    for gradients in [
        TemporalGradients::Extrapolated,
        TemporalGradients::Interpolated,
    ] {
        let method = quick_trc(gradients);
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("plain");
        render::render_to_dir(&mut renderer(&method), 0..6, &plain, true).unwrap();
        let store = Store::open(&dir.path().join("db")).unwrap();
        let out = dir.path().join("out");
        let run = |frames| render_job_j(&store, &method, frames, &out, u32::MAX).frames;
        assert_eq!(run(0..3), 3);
        assert_eq!(run(3..6), 3);
        assert_eq!(
            run(0..6),
            6,
            "{gradients:?}: frames 3..5 are another chain's"
        );
        assert_eq!(exr_files(&plain, 0..6), exr_files(&out, 0..6));
        let again = match gradients {
            TemporalGradients::Interpolated => 3,
            _ => 0,
        };
        assert_eq!(run(0..3), again, "{gradients:?}");
        std::fs::remove_file(film::frame_path(&out, 1, "png")).unwrap();
        run(0..3);
        assert!(film::frame_path(&out, 1, "png").exists());
    }
}

/// Renders `frames` of job "j" of `store` (the built-in cube-in-box at
/// [`renderer`]'s settings) into `out`, stopping after frame `stop_after`.
fn render_job_j(
    store: &Store,
    method: &MethodSettings,
    frames: std::ops::Range<u32>,
    out: &Path,
    stop_after: u32,
) -> render::RenderSummary {
    let source = SceneSource::Builtin("cube-in-box".into());
    let settings = renderer(method).settings;
    let spec = render::job_spec("j", &source, method, &settings, frames.clone()).unwrap();
    let mut sj = StoreJob {
        store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let mut r = renderer(method);
    render::render_job_to_dir_with(&mut r, frames, out, true, Some(&mut sj), &mut |f| {
        f < stop_after
    })
    .unwrap()
}

/// A `trc` job done for 0..10, rendered again for 5..10 and stopped after
/// frame 6, resumes that chain after frame 6 (frames 7..9 are still the
/// first chain's, and are rendered again) rather than starting 5..10
/// over each time; its frames equal an uninterrupted 5..10 render. With
/// either gradients: interpolated ones end the chain at the range's end.
#[test]
fn trc_range_rendered_again_and_stopped_resumes_where_it_stopped() {
    for gradients in [
        TemporalGradients::Extrapolated,
        TemporalGradients::Interpolated,
    ] {
        range_rendered_again_and_stopped(quick_trc(gradients));
    }
}

/// `trc` with `gradients`, gathering 4 × 12 cells at 1 spp: quick.
fn quick_trc(gradients: TemporalGradients) -> MethodSettings {
    let mut trc = TrcSettings::default();
    trc.ic.strata = Strata { theta: 4, phi: 12 };
    trc.ic.spp = 1;
    trc.gradients = gradients;
    MethodSettings::Trc(trc)
}

fn range_rendered_again_and_stopped(method: MethodSettings) {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("plain");
    render::render_to_dir(&mut renderer(&method), 5..10, &plain, true).unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let out = dir.path().join("out");
    let run = |frames, stop_after| {
        let s = render_job_j(&store, &method, frames, &out, stop_after);
        (s.resumed, s.frames)
    };
    assert_eq!(run(0..10, u32::MAX), (0, 10));
    assert_eq!(run(5..10, 6), (0, 2), "frames 5 and 6 of a new chain");
    assert_eq!(run(5..10, u32::MAX), (2, 3), "resumed after frame 6");
    assert_eq!(exr_files(&plain, 5..10), exr_files(&out, 5..10));
    assert_eq!(run(5..10, u32::MAX), (5, 0), "done");
}

/// Frames are stored and written on a thread of their own while the next
/// one renders. `after_frame` is told of each frame in order, once it is
/// stored and its files are written. A frame whose files cannot be
/// replaced (a directory put in the place of frame 3's EXR while frame 2
/// is told of) ends the render with an error naming the file, and neither
/// it nor the frame rendering meanwhile is stored or written; once the
/// directory is gone the job resumes at frame 3 and its frames equal an
/// uninterrupted render's.
#[test]
fn a_frame_that_cannot_be_written_ends_the_render_there_and_the_job_resumes_at_it() {
    let method = quick_trc(TemporalGradients::Extrapolated);
    let dir = tempfile::tempdir().unwrap();
    let (plain, out) = (dir.path().join("plain"), dir.path().join("out"));
    render::render_to_dir(&mut renderer(&method), 0..6, &plain, true).unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let source = SceneSource::Builtin("cube-in-box".into());
    let settings = renderer(&method).settings;
    let spec = render::job_spec("j", &source, &method, &settings, 0..6).unwrap();
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let id = sj.job.id;
    let blocker = film::frame_path(&out, 3, "exr");
    let (mut told, mut stored_when_told) = (Vec::new(), Vec::new());
    let err = render::render_job_to_dir_with(
        &mut renderer(&method),
        0..6,
        &out,
        true,
        Some(&mut sj),
        &mut |f| {
            told.push(f);
            let files = ["exr", "png"].map(|e| film::frame_path(&out, f, e).is_file());
            stored_when_told
                .push(files == [true, true] && store.frames_done(id).unwrap().contains(&f));
            if f == 2 {
                std::fs::create_dir(&blocker).unwrap();
                std::fs::write(blocker.join("keep"), b"").unwrap();
            }
            true
        },
    )
    .unwrap_err();
    let said = format!("{err:#}");
    assert!(said.contains("frame_0003.exr"), "{said}");
    assert_eq!(told, [0, 1, 2]);
    assert_eq!(stored_when_told, [true; 3]);
    assert_eq!(store.frames_done(id).unwrap(), [0, 1, 2]);
    assert_eq!(store.load_state(id).unwrap().unwrap().frame, 2);
    assert!(!film::frame_path(&out, 4, "exr").exists());

    std::fs::remove_dir_all(&blocker).unwrap();
    let summary =
        render::render_job_to_dir(&mut renderer(&method), 0..6, &out, true, Some(&mut sj)).unwrap();
    assert_eq!((summary.resumed, summary.frames), (3, 3));
    assert_eq!(exr_files(&plain, 0..6), exr_files(&out, 0..6));
}

#[test]
fn trc_resumes_mid_window_from_stored_state_without_replay() {
    trc_resumes_from_stored_state(TemporalGradients::Extrapolated);
}

#[test]
fn trc_interpolated_resumes_from_stored_first_pass_without_replay() {
    trc_resumes_from_stored_state(TemporalGradients::Interpolated);
}

/// A version-1 store built by the schema-1 writer (`store::v1::Writer`):
/// an `ic` job of cube-in-box 16×16 that finished frames 0..2 of 0..4,
/// with the frames, statistics, records and samples the renderer made.
/// Returns the job, the EXR bytes and every record's samples as written:
/// `(frame, record id, samples)`.
#[allow(clippy::type_complexity)]
fn v1_fixture(
    path: &Path,
    method: &MethodSettings,
) -> (JobSpec, Vec<Vec<u8>>, Vec<(u32, u64, Vec<PackedSample>)>) {
    let source = SceneSource::Builtin("cube-in-box".into());
    let mut r = renderer(method);
    let spec = render::job_spec("old", &source, method, &r.settings, 0..4).unwrap();
    let writer = v1::Writer::create(path).unwrap();
    let job = v1::JobValue {
        id: 7,
        name: spec.name.clone(),
        scene: spec.scene.clone(),
        scene_hash: spec.scene_hash.clone(),
        method: spec.method.clone(),
        // Schema 1 compared `{:?}` text.
        settings: format!("{method:?}"),
        width: spec.width,
        height: spec.height,
        spp: spec.spp,
        fps: spec.fps,
        seed: spec.seed,
        same_pattern: spec.same_pattern,
        frame_start: 0,
        frame_end: 4,
        frames_done: 2,
        last_frame: Some(1),
        created_unix: 1,
        updated_unix: 2,
    };
    writer.put_job(&job).unwrap();
    r.keep_frame_records(true);
    let mut exrs = Vec::new();
    let mut rows = Vec::new();
    for frame in 0..2 {
        let film = r.render_frame(frame);
        let stats = r.last_frame_stats();
        let kept = r.take_frame_records().unwrap_or_default();
        let records: Vec<RecordCommit> = kept
            .records
            .iter()
            .zip(&kept.samples)
            .map(|(rec, s)| RecordCommit::from_record(rec, s.clone(), kept.strata, frame))
            .collect();
        let exr = film::encode_exr(&film).unwrap();
        let raw = records.iter().map(|r| r.samples.raw_bytes()).sum();
        writer
            .put_frame(
                7,
                frame,
                (16, 16),
                &exr,
                &v1::StatsValue::from_stats(&stats, raw),
                &records,
            )
            .unwrap();
        exrs.push(exr);
        rows.extend(
            records
                .iter()
                .map(|r| (frame, r.record.id, r.samples.unpack().unwrap())),
        );
    }
    (spec, exrs, rows)
}

#[test]
fn version_1_store_is_migrated_and_its_job_inspects_and_resumes() {
    let method = small_ic();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let (spec, exrs, v1_samples) = v1_fixture(&path, &method);
    let v1_records = v1_samples.len();
    assert!(v1_records > 0);
    let store = Store::open(&path).unwrap();
    assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
    let job = store.job("old").unwrap().unwrap();
    assert_eq!((job.id, job.frames_done, job.last_frame), (7, 2, Some(1)));
    // Settings `{:?}` → the JSON this build writes for them.
    let as_json = |s: &str| serde_json::from_str::<serde_json::Value>(s).unwrap();
    assert_eq!(as_json(&job.settings), as_json(&spec.settings));
    assert_eq!(store.frame_exr(7, 1).unwrap().unwrap(), exrs[1]);
    let stats = store.frame_stats(7, 0).unwrap().unwrap();
    assert!(stats.records_created > 0);
    // Records and samples, all still there.
    let recs: usize = (0..2)
        .map(|f| store.frame_records(7, f).unwrap().len())
        .sum();
    assert_eq!(recs, v1_records);
    // Every record's samples, moved to the sample log, read back as written.
    for (frame, id, samples) in &v1_samples {
        assert_eq!(samples.len(), 48);
        assert_eq!(&store.record_samples(7, *frame, *id).unwrap(), samples);
    }
    let report = radcache::store::inspect::report(&store, Some("old"), None).unwrap();
    assert_eq!(report.schema_version, migrate::CURRENT_VERSION);
    assert_eq!(report.jobs[0].records as usize, v1_records);
    assert_eq!(report.jobs[0].samples as usize, v1_records * 48);
    assert_eq!(report.jobs[0].frames_done, 2);

    // A real schema-1 store was written by a build of `ic`'s first
    // revision, which this build does not resume (its frames would differ:
    // `a_job_started_under_another_algorithm_revision_is_refused_unless_forced`).
    let refused = store.begin_job(&spec, false).unwrap_err().to_string();
    assert!(
        refused.contains("`ic` algorithm revision (stored 1"),
        "{refused}"
    );
    // This fixture's frames and records are this build's renderer's,
    // written in schema 1's layout: marked as such, the job resumes.
    drop(store);
    {
        let db = open_raw(&path);
        let revision = radcache::method::algorithm_revision("ic").to_be_bytes();
        let meta = db.open_tree("meta").unwrap();
        meta.insert(keys::meta_revision(7), &revision[..]).unwrap();
        db.flush().unwrap();
    }
    let store = Store::open(&path).unwrap();
    // The job resumes: frames 2..3 only, equal to an uninterrupted run.
    let out = dir.path().join("out");
    let mut sj = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    assert_eq!(sj.job.id, 7);
    let s =
        render::render_job_to_dir(&mut renderer(&method), 0..4, &out, true, Some(&mut sj)).unwrap();
    assert_eq!((s.resumed, s.frames), (2, 2));
    let plain = dir.path().join("plain");
    render::render_to_dir(&mut renderer(&method), 0..4, &plain, true).unwrap();
    assert_eq!(exr_files(&plain, 0..4), exr_files(&out, 0..4));
    // Its stored settings are now the JSON text.
    assert_eq!(store.job("old").unwrap().unwrap().settings, spec.settings);
    drop(sj);
    drop(store);
    // Opening it again runs nothing; an older build would refuse it.
    let store = Store::open(&path).unwrap();
    assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
    drop(store);
    assert_an_older_build_refuses(&path, 3);
}

/// A build that reads schema `supported` at most refuses the store at
/// `path` (of this build's schema) with a clear message.
fn assert_an_older_build_refuses(path: &Path, supported: u32) {
    let msg = err_text(Store::open_with(
        path,
        false,
        supported,
        migrate::MIGRATIONS,
    ));
    let newer = format!("schema version {} is newer", migrate::CURRENT_VERSION);
    assert!(
        msg.contains(&newer) && msg.contains(&format!("version {supported}")),
        "{msg}"
    );
}

#[test]
fn settings_debug_text_reads_as_serde_json() {
    use radcache::method::trc::TrcSettings;
    for m in [
        MethodSettings::Path(PathSettings::default()),
        MethodSettings::Ic(IcSettings::default()),
        MethodSettings::Trc(TrcSettings::default()),
        MethodSettings::Trc(TrcSettings {
            temporal_accuracy: 1e-7,
            gradients: TemporalGradients::Interpolated,
            ..TrcSettings::default()
        }),
    ] {
        // As stored: JSON text (floats in their shortest f32 form), read back.
        let json: serde_json::Value =
            serde_json::from_str(&serde_json::to_string(&m).unwrap()).unwrap();
        assert_eq!(v1::debug_to_json(&format!("{m:?}")).unwrap(), json, "{m:?}");
    }
}

#[test]
fn scene_hash_covers_external_buffers_and_images() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = dir.path().join("a.gltf");
    std::fs::write(
        &gltf,
        r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"a%20b.bin","byteLength":4},{"uri":"data:application/octet-stream;base64,AAAA","byteLength":3}],"images":[{"uri":"tex.png"}]}"#,
    )
    .unwrap();
    std::fs::write(dir.path().join("a b.bin"), [1u8, 2, 3, 4]).unwrap();
    std::fs::write(dir.path().join("tex.png"), b"png").unwrap();
    let source = SceneSource::File(gltf.clone());
    let (_, h1) = render::scene_identity(&source).unwrap();
    let (main, ext) = h1.split_once('+').expect("external files hashed");
    assert_eq!(
        main,
        radcache::hash::content_hash(&std::fs::read(&gltf).unwrap())
    );
    // The external part as stores already hold it: the hash of every
    // file's URI, NUL, length (u64 LE) and bytes, one after the other.
    let mut all = Vec::new();
    for (uri, bytes) in [("a%20b.bin", &b"\x01\x02\x03\x04"[..]), ("tex.png", b"png")] {
        all.extend_from_slice(uri.as_bytes());
        all.push(0);
        all.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        all.extend_from_slice(bytes);
    }
    assert_eq!(ext, radcache::hash::content_hash(&all));
    std::fs::write(dir.path().join("a b.bin"), [1u8, 2, 3, 5]).unwrap();
    let (_, h2) = render::scene_identity(&source).unwrap();
    assert_ne!(h1, h2, "a changed .bin changes the hash");
    assert!(h2.starts_with(main) && !h2.ends_with(ext));
    std::fs::write(dir.path().join("tex.png"), b"PNG").unwrap();
    let (_, h3) = render::scene_identity(&source).unwrap();
    assert_ne!(h2, h3, "a changed image changes the hash");
    // Of a buffer, what the loader reads counts: its declared byteLength
    // (a huge file named by a small buffer is not read whole).
    std::fs::write(dir.path().join("a b.bin"), [1u8, 2, 3, 5, 9, 9]).unwrap();
    let (_, longer) = render::scene_identity(&source).unwrap();
    assert_eq!(longer, h3, "bytes past byteLength are not the scene's");
    // A missing image (which the renderer ignores) hashes as missing: its
    // URI, NUL, then a length no file has and `missing`; it is another
    // scene than with the image there.
    std::fs::remove_file(dir.path().join("tex.png")).unwrap();
    let (_, gone) = render::scene_identity(&source).unwrap();
    let mut all = Vec::new();
    for (uri, bytes) in [("a%20b.bin", &b"\x01\x02\x03\x05"[..]), ("tex.png", b"")] {
        all.extend_from_slice(uri.as_bytes());
        all.push(0);
        match bytes.is_empty() {
            false => {
                all.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
                all.extend_from_slice(bytes);
            }
            true => all.extend_from_slice(b"\xff\xff\xff\xff\xff\xff\xff\xffmissing"),
        }
    }
    assert_eq!(
        gone,
        format!("{main}+{}", radcache::hash::content_hash(&all))
    );
    assert_ne!(gone, h3);
    // A missing buffer, which the loader needs, is a clear error.
    std::fs::rename(dir.path().join("a b.bin"), dir.path().join("moved.bin")).unwrap();
    let msg = render::scene_identity(&source).unwrap_err().to_string();
    assert!(
        msg.contains("a b.bin: file not found") && msg.contains("a.gltf"),
        "{msg}"
    );
    std::fs::rename(dir.path().join("moved.bin"), dir.path().join("a b.bin")).unwrap();

    // A schema-1 job of this file (hash of the .gltf alone, marked `+v1`
    // by the migration) resumes with the full hash, which it then keeps.
    std::fs::write(dir.path().join("tex.png"), b"PNG").unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let mut old = spec("g");
    old.scene_hash = format!("{main}{}", v1::LEGACY_HASH_SUFFIX);
    store.begin_job(&old, false).unwrap();
    let mut now = spec("g");
    now.scene_hash = h3.clone();
    assert_eq!(store.begin_job(&now, false).unwrap().scene_hash, h3);
    now.scene_hash = format!("{}+{ext}", "0".repeat(16));
    let msg = err_text(store.begin_job(&now, false));
    assert!(msg.contains("scene hash"), "{msg}");
}

#[test]
fn settings_are_compared_as_json_values() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let method = MethodSettings::Ic(IcSettings::default());
    let fs = FrameSettings::default();
    let source = SceneSource::Builtin("cube-in-box".into());
    let spec = render::job_spec("s", &source, &method, &fs, 0..2).unwrap();
    let value: serde_json::Value = serde_json::from_str(&spec.settings).unwrap();
    assert_eq!(value["Ic"]["strata"]["theta"], 16);
    store.begin_job(&spec, false).unwrap();
    // The same value, other formatting: the same job.
    let mut same = spec.clone();
    same.settings = serde_json::to_string_pretty(&value).unwrap();
    store.begin_job(&same, false).unwrap();
    let other = MethodSettings::Ic(IcSettings {
        accuracy: 0.3,
        ..IcSettings::default()
    });
    let other = render::job_spec("s", &source, &other, &fs, 0..2).unwrap();
    let msg = err_text(store.begin_job(&other, false));
    // Only the setting that differs is named, not both documents.
    assert!(
        msg.contains("method settings (accuracy: stored 0.2, given 0.3)"),
        "{msg}"
    );
    assert!(!msg.contains("theta"), "{msg}");
}

#[test]
fn version_2_store_moves_its_samples_into_the_sample_log() {
    // A schema-2 store: the schema-1 fixture brought to 2 by the real
    // 1 → 2 step (samples still in the `samples` tree).
    let method = small_ic();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let (_, _, written) = v1_fixture(&path, &method);
    {
        let store = Store::open_with(&path, false, 2, migrate::MIGRATIONS).unwrap();
        assert_eq!(store.schema_version().unwrap(), 2);
        assert_eq!(store.sample_log_bytes(), 8, "no samples in the log yet");
    }
    {
        let db = open_raw(&path);
        let samples = db.open_tree("samples").unwrap();
        assert_eq!(samples.len(), written.len());
    }
    let store = Store::open(&path).unwrap();
    assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
    for (frame, id, samples) in &written {
        assert_eq!(&store.record_samples(7, *frame, *id).unwrap(), samples);
    }
    let log_bytes = store.sample_log_bytes();
    assert!(log_bytes > 8 + written.len() as u64 * 48);
    assert_eq!(
        std::fs::metadata(path.join("samples.log")).unwrap().len(),
        log_bytes
    );
    let report = radcache::store::inspect::report(&store, Some("old"), None).unwrap();
    assert_eq!(report.jobs[0].samples as usize, written.len() * 48);
    // The log holds the samples, the frames' EXR files and (schema 4)
    // their record blocks, nothing else.
    assert_eq!(log_parts(&report.jobs[0]), log_bytes - 8);
    assert!(report.trees.iter().all(|t| t.name != "samples"));
    drop(store);
    // The `samples` tree is gone; running the step again changes nothing.
    {
        let db = open_raw(&path);
        assert!(!db.tree_names().iter().any(|n| n.as_ref() == b"samples"));
        radcache::store::v2::migrate_to_v3(&db, &path).unwrap();
        db.flush().unwrap();
    }
    let store = Store::open(&path).unwrap();
    assert_eq!(store.sample_log_bytes(), log_bytes);
    for (frame, id, samples) in &written {
        assert_eq!(&store.record_samples(7, *frame, *id).unwrap(), samples);
    }
}

/// A closed store at `path` with frames 0..2 of job "j"; the bytes of its
/// sample log.
fn store_with_two_frames(path: &Path) -> u64 {
    let store = Store::open(path).unwrap();
    commit_frames(&store, "j", 0..2);
    store.sample_log_bytes()
}

/// The tail is cut by the next write, not by opening: a store opened only
/// to be read (`inspect`) whose sled database lost commits, which looks
/// the same, keeps every byte of its log.
#[test]
fn torn_sample_log_tail_is_cut_by_the_next_write() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let log = path.join("samples.log");
    let committed = store_with_two_frames(&path);
    assert_eq!(std::fs::metadata(&log).unwrap().len(), committed);
    // A crash between a frame's log append and its sled transaction
    // leaves bytes no record references.
    {
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new().append(true).open(&log).unwrap();
        f.write_all(&[0xab; 1000]).unwrap();
    }
    {
        let store = Store::open_existing(&path).unwrap();
        assert_eq!(store.sample_log_bytes(), committed);
        let id = store.job("j").unwrap().unwrap().id;
        assert_eq!(store.frame_records(id, 1).unwrap().len(), 3);
    }
    assert_eq!(std::fs::metadata(&log).unwrap().len(), committed + 1000);
    {
        let store = Store::open_existing(&path).unwrap();
        // The job goes on: the next frame's samples follow the committed
        // ones and every frame's samples read back.
        commit_frames(&store, "j", 2..3);
    }
    let store = Store::open_existing(&path).unwrap();
    let id = store.job("j").unwrap().unwrap().id;
    for frame in 0..3 {
        for r in store.frame_records(id, frame).unwrap() {
            assert_eq!(store.record_samples(id, frame, r.id).unwrap().len(), 48);
        }
    }
    assert!(store.sample_log_bytes() > committed);
}

/// A sled database recovered with none of its commits (its schema there,
/// its jobs and the log's committed length not) looks like a store whose
/// first frame was never acknowledged: opening it keeps every byte of its
/// log as well, and the next write cuts them as above.
#[test]
fn a_log_no_commit_references_is_kept_until_the_next_write() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let log = path.join("samples.log");
    drop(Store::open(&path).unwrap());
    let header = std::fs::metadata(&log).unwrap().len();
    {
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new().append(true).open(&log).unwrap();
        f.write_all(&[0xcd; 5000]).unwrap();
    }
    for _ in 0..2 {
        let store = Store::open_existing(&path).unwrap();
        assert_eq!(store.sample_log_bytes(), header);
        assert!(store.job("j").unwrap().is_none());
        // `inspect` says what is there.
        let report = radcache::store::inspect::report(&store, None, None).unwrap();
        assert_eq!(report.sample_log_tail_bytes, 5000);
        let text = radcache::store::inspect::to_text(&report, false);
        assert!(
            text.contains("5000 bytes past its committed length"),
            "{text}"
        );
    }
    assert_eq!(std::fs::metadata(&log).unwrap().len(), header + 5000);
    {
        let store = Store::open_existing(&path).unwrap();
        commit_frames(&store, "j", 0..2);
    }
    // The tail was cut, not written after.
    let bytes = std::fs::read(&log).unwrap();
    assert!(!bytes.windows(5000).any(|w| w.iter().all(|&b| b == 0xcd)));
    let store = Store::open_existing(&path).unwrap();
    let report = radcache::store::inspect::report(&store, None, None).unwrap();
    assert_eq!(report.sample_log_tail_bytes, 0);
    let id = store.job("j").unwrap().unwrap().id;
    for frame in 0..2 {
        for r in store.frame_records(id, frame).unwrap() {
            assert_eq!(store.record_samples(id, frame, r.id).unwrap().len(), 48);
        }
    }
}

/// The files of a store directory copied to `to` (the store closed).
fn copy_store(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_dir() {
            copy_store(&entry.path(), &to.join(entry.file_name()));
        } else {
            std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
        }
    }
}

/// A database that lost the commits of frames whose files are in the log
/// (sled recovers a damaged database as the part before the damage) is
/// refused for writing: a crash leaves one frame's appends past the
/// committed length at most, so two frames' files there are frames the
/// database lost, which the next write would cut off. One frame's are
/// cut, as after a crash. Reading it goes on, and says so.
#[test]
fn a_log_holding_frames_its_database_lost_takes_no_write() {
    let dir = tempfile::tempdir().unwrap();
    let (path, two, three) = (
        dir.path().join("db"),
        dir.path().join("two"),
        dir.path().join("three"),
    );
    let log = |store: &Path| store.join("samples.log");
    // The frames' EXR files as a render makes them (their first bytes tell
    // them from the other blocks).
    let exr = |frame: u32| {
        let mut film = radcache::film::Film::new(16, 16);
        film.pixels.fill(glam::Vec3::splat(frame as f32));
        radcache::film::encode_exr(&film).unwrap()
    };
    let store = Store::open(&path).unwrap();
    commit_frames_with(&store, "j", 0..2, exr);
    drop(store);
    copy_store(&path, &two);
    let store = Store::open_existing(&path).unwrap();
    commit_frames_with(&store, "j", 2..3, exr);
    drop(store);
    copy_store(&path, &three);
    let store = Store::open_existing(&path).unwrap();
    commit_frames_with(&store, "j", 3..4, exr);
    drop(store);
    // Each database as it was, with the log of all four frames.
    for older in [&two, &three] {
        std::fs::copy(log(&path), log(older)).unwrap();
    }
    let full = std::fs::metadata(log(&path)).unwrap().len();

    // Two frames lost: refused, every byte kept.
    {
        let store = Store::open_existing(&two).unwrap();
        assert!(store.sample_log_holds_lost_frames());
        let report = radcache::store::inspect::report(&store, None, None).unwrap();
        assert!(report.sample_log_tail_lost_frames);
        let text = radcache::store::inspect::to_text(&report, false);
        assert!(text.contains("the database lost commits"), "{text}");
        let msg = err_text(store.begin_job(&spec("j"), false));
        assert!(
            msg.contains("damaged") && msg.contains("two or more frames"),
            "{msg}"
        );
        let mut store = store;
        let progress = indicatif::ProgressBar::hidden();
        let msg = err_text(radcache::store::compact::compact(&mut store, &progress));
        assert!(msg.contains("damaged"), "{msg}");
    }
    assert_eq!(std::fs::metadata(log(&two)).unwrap().len(), full);

    // One frame lost, as a crash leaves it: cut by the next write.
    let store = Store::open_existing(&three).unwrap();
    assert!(!store.sample_log_holds_lost_frames());
    commit_frames_with(&store, "j", 3..4, exr);
    let id = store.job("j").unwrap().unwrap().id;
    for frame in 0..4 {
        for r in store.frame_records(id, frame).unwrap() {
            assert_eq!(store.record_samples(id, frame, r.id).unwrap().len(), 48);
        }
    }
    assert_eq!(store.sample_log_bytes(), full);
}

#[test]
fn sample_log_shorter_than_referenced_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let log = path.join("samples.log");
    let committed = store_with_two_frames(&path);
    let f = std::fs::OpenOptions::new().write(true).open(&log).unwrap();
    f.set_len(committed - 100).unwrap();
    drop(f);
    for _ in 0..2 {
        let msg = err_text(Store::open_existing(&path));
        assert!(msg.contains(&log.display().to_string()), "{msg}");
        assert!(
            msg.contains("shorter than") && msg.contains(&committed.to_string()),
            "{msg}"
        );
    }
    // Left as it was.
    assert_eq!(std::fs::metadata(&log).unwrap().len(), committed - 100);
    std::fs::remove_file(&log).unwrap();
    let msg = err_text(Store::open_existing(&path));
    assert!(
        msg.contains(&log.display().to_string()) && msg.contains("lost"),
        "{msg}"
    );
    // Not a sample log at all.
    std::fs::write(&log, vec![0u8; committed as usize]).unwrap();
    let msg = err_text(Store::open_existing(&path));
    assert!(
        msg.contains("samples.log") && msg.contains("bad header"),
        "{msg}"
    );
}

#[test]
fn interrupted_0002_to_0003_migration_resumes_where_it_stopped() {
    let method = small_ic();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let (_, _, written) = v1_fixture(&path, &method);
    assert!(written.len() > 10);
    drop(Store::open_with(&path, false, 2, migrate::MIGRATIONS).unwrap());
    // A crash after two batches of 5 records, and in the middle of the
    // third one's log append (bytes no record references yet).
    let committed = {
        let db = open_raw(&path);
        radcache::store::v2::migrate_to_v3_batches(&db, &path, 5, Some(2)).unwrap();
        db.flush().unwrap();
        let meta = db.open_tree("meta").unwrap();
        let len = meta.get(keys::META_SAMPLES_LOG_LEN).unwrap().unwrap();
        assert_eq!(
            meta.get(keys::META_SCHEMA_VERSION)
                .unwrap()
                .unwrap()
                .as_ref(),
            2u32.to_be_bytes(),
            "still schema 2"
        );
        assert_eq!(db.open_tree("samples").unwrap().len(), written.len() - 10);
        u64::from_be_bytes(len.as_ref().try_into().unwrap())
    };
    append_torn_bytes_to_the_log(&path);
    let store = Store::open(&path).unwrap();
    assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
    for (frame, id, samples) in &written {
        assert_eq!(&store.record_samples(7, *frame, *id).unwrap(), samples);
    }
    // The torn bytes were cut off: blocks follow each other with no gap.
    let report = radcache::store::inspect::report(&store, Some("old"), None).unwrap();
    assert_eq!(log_parts(&report.jobs[0]), store.sample_log_bytes() - 8);
    assert!(store.sample_log_bytes() > committed);
}

/// The job's bytes in the sample log, by kind: record samples, frame EXR
/// files and (schema 4) record blocks.
fn log_parts(j: &radcache::store::inspect::JobReport) -> u64 {
    j.samples_stored_bytes + j.exr_stored_bytes + j.record_block_bytes
}

#[test]
fn corrupt_record_block_is_an_error_naming_the_log_and_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let log = path.join("samples.log");
    let store = Store::open(&path).unwrap();
    commit_frames(&store, "j", 0..3);
    let id = store.job("j").unwrap().unwrap().id;
    let at = |frame| store.frame_records_value(id, frame).unwrap().unwrap();
    let (b0, b1) = (at(0), at(1));
    assert_eq!((b1.count, b1.first_id, b1.last_id), (3, 0, 2));
    let names_block = |msg: &str, frame: u32| {
        msg.contains(&log.display().to_string()) && msg.contains(&format!("job {id} frame {frame}"))
    };
    // Frame 1's `records` value pointing at frame 0's (valid) block.
    let original = store
        .tree("records")
        .unwrap()
        .get(keys::frame(id, 1))
        .unwrap()
        .unwrap();
    let frame0 = store
        .tree("records")
        .unwrap()
        .get(keys::frame(id, 0))
        .unwrap()
        .unwrap();
    store
        .raw_insert("records", &keys::frame(id, 1), &frame0)
        .unwrap();
    let msg = err_text(store.frame_records(id, 1));
    assert!(names_block(&msg, 1) && msg.contains("frame 0"), "{msg}");
    store
        .raw_insert("records", &keys::frame(id, 1), &original)
        .unwrap();
    assert_eq!(store.frame_records(id, 1).unwrap().len(), 3);
    // Frame 1's block overwritten with garbage in the log.
    {
        use std::os::unix::fs::FileExt;
        let f = std::fs::OpenOptions::new().write(true).open(&log).unwrap();
        f.write_all_at(&vec![0x5a; b1.stored_len as usize], b1.offset)
            .unwrap();
    }
    let msg = err_text(store.frame_records(id, 1));
    assert!(names_block(&msg, 1), "{msg}");
    let msg = err_text(store.record_samples(id, 1, 2));
    assert!(names_block(&msg, 1), "{msg}");
    let msg = err_text(store.for_each_record(id, u32::MAX, |_, _| {}));
    assert!(names_block(&msg, 1), "{msg}");
    // The other frames still read.
    assert_eq!(store.frame_records(id, 0).unwrap().len(), 3);
    assert_eq!(store.frame_records(id, 2).unwrap().len(), 3);
    assert_eq!(b0.count, 3);
}

/// The schema-3 records of the store at `path` (closed), as stored: (frame,
/// value) in key order.
fn raw_v3_records(path: &Path) -> Vec<(u32, radcache::store::schema::RecordValue)> {
    let db = open_raw(path);
    let records = db.open_tree("records").unwrap();
    records
        .iter()
        .map(|item| {
            let (k, v) = item.unwrap();
            let (job, frame, id) = keys::parse_record(&k).expect("a schema-3 key");
            assert_eq!(job, 7);
            let mut aligned = rkyv::util::AlignedVec::<16>::new();
            aligned.extend_from_slice(&v);
            let r: radcache::store::schema::RecordValue =
                rkyv::from_bytes::<_, rkyv::rancor::Error>(&aligned).unwrap();
            assert_eq!(r.id, id);
            (frame, r)
        })
        .collect()
}

/// A tree's keys and values, raw.
type RawRows = Vec<(Vec<u8>, Vec<u8>)>;

/// The `frames` tree of the store at `path` (closed), raw, and its
/// `stats` values decoded as `decode` reads them.
fn frames_and_stats<S>(path: &Path, decode: impl Fn(&[u8]) -> S) -> (RawRows, Vec<(Vec<u8>, S)>) {
    let db = open_raw(path);
    let rows = |t: &str| -> RawRows {
        let tree = db.open_tree(t).unwrap();
        tree.iter()
            .map(|i| {
                let (k, v) = i.unwrap();
                (k.to_vec(), v.to_vec())
            })
            .collect()
    };
    let stats = rows("stats").into_iter().map(|(k, v)| (k, decode(&v)));
    (rows("frames"), stats.collect())
}

/// An rkyv value of type `T` from stored bytes.
fn decoded<T>(bytes: &[u8]) -> T
where
    T: rkyv::Archive,
    T::Archived: for<'a> rkyv::bytecheck::CheckBytes<rkyv::api::high::HighValidator<'a, rkyv::rancor::Error>>
        + rkyv::Deserialize<T, rkyv::api::high::HighDeserializer<rkyv::rancor::Error>>,
{
    let mut aligned = rkyv::util::AlignedVec::<16>::new();
    aligned.extend_from_slice(bytes);
    rkyv::from_bytes::<T, rkyv::rancor::Error>(&aligned).unwrap()
}

/// Puts `convert(job, id, bytes)` in place of the method's bytes of each
/// carried state record of `db` for which it gives some; the jobs of those
/// it converted, one entry a record.
fn rewrite_state_records(
    db: &sled::Db,
    mut convert: impl FnMut(u64, u64, &[u8]) -> Option<Vec<u8>>,
) -> Vec<u64> {
    let state = db.open_tree("state").unwrap();
    let mut converted = Vec::new();
    for item in state.iter() {
        let (k, v) = item.unwrap();
        let Some((job, id)) = keys::parse_state_record(&k) else {
            continue;
        };
        let mut value: radcache::store::schema::StateRecordValue = decoded(&v);
        if let Some(data) = convert(job, id, &value.data) {
            value.data = data;
            let bytes = rkyv::to_bytes::<rkyv::rancor::Error>(&value).unwrap();
            state.insert(k, bytes.as_slice()).unwrap();
            converted.push(job);
        }
    }
    converted
}

/// A schema-3 store at `path` (the schema-1 fixture brought to 3 by the
/// real steps): its EXRs, samples, and records as stored.
#[allow(clippy::type_complexity)]
fn v3_fixture(
    path: &Path,
) -> (
    Vec<Vec<u8>>,
    Vec<(u32, u64, Vec<PackedSample>)>,
    Vec<(u32, radcache::store::schema::RecordValue)>,
) {
    let (_, exrs, written) = v1_fixture(path, &small_ic());
    {
        let store = Store::open_with(path, false, 3, migrate::MIGRATIONS).unwrap();
        assert_eq!(store.schema_version().unwrap(), 3);
    }
    let records = raw_v3_records(path);
    assert_eq!(records.len(), written.len());
    assert!(records.iter().any(|(f, _)| *f == 0) && records.iter().any(|(f, _)| *f == 1));
    (exrs, written, records)
}

/// Checks that the store at `path`, now of this build's schema, reads back
/// the schema-3 fixture's frames, records and samples exactly.
fn check_v3_fixture_reads_back(
    store: &Store,
    exrs: &[Vec<u8>],
    written: &[(u32, u64, Vec<PackedSample>)],
    records: &[(u32, radcache::store::schema::RecordValue)],
) {
    assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
    for frame in 0..2u32 {
        let want: Vec<_> = records
            .iter()
            .filter(|(f, _)| *f == frame)
            .map(|(_, r)| r.clone())
            .collect();
        assert_eq!(store.frame_records(7, frame).unwrap(), want);
        assert_eq!(
            &store.frame_exr(7, frame).unwrap().unwrap(),
            &exrs[frame as usize]
        );
    }
    let mut all = Vec::new();
    store
        .for_each_record(7, u32::MAX, |f, r| all.push((f, r)))
        .unwrap();
    assert_eq!(all, records);
    for (frame, id, samples) in written {
        assert_eq!(&store.record_samples(7, *frame, *id).unwrap(), samples);
    }
    // One `records` key per frame; the log holds the samples, EXRs and
    // record blocks, back to back.
    let keys_now: Vec<_> = store
        .tree("records")
        .unwrap()
        .iter()
        .keys()
        .map(|k| k.unwrap().to_vec())
        .collect();
    assert_eq!(
        keys_now,
        vec![keys::frame(7, 0).to_vec(), keys::frame(7, 1).to_vec()]
    );
    let report = radcache::store::inspect::report(store, Some("old"), None).unwrap();
    assert_eq!(report.jobs[0].records as usize, records.len());
    assert_eq!(report.jobs[0].samples as usize, written.len() * 48);
    assert_eq!(log_parts(&report.jobs[0]), store.sample_log_bytes() - 8);
    assert!(report.jobs[0].record_value_bytes > report.jobs[0].record_block_bytes);
}

#[test]
fn version_3_store_moves_its_records_into_blocks_in_the_log() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let (exrs, written, records) = v3_fixture(&path);
    let before = frames_and_stats(&path, |v| {
        decoded::<radcache::store::v7::StatsValue>(v).to_v8()
    });
    let log_before = std::fs::metadata(path.join("samples.log")).unwrap().len();
    {
        let store = Store::open(&path).unwrap();
        check_v3_fixture_reads_back(&store, &exrs, &written, &records);
        assert!(store.sample_log_bytes() > log_before);
    }
    // `frames` untouched, `stats` only brought to the schema-8 layout.
    let after = frames_and_stats(&path, decoded::<radcache::store::schema::StatsValue>);
    assert_eq!(after, before);
    // Running the step again changes nothing.
    let log_len = {
        let db = open_raw(&path);
        radcache::store::v3::migrate_to_v4(&db, &path).unwrap();
        db.flush().unwrap();
        std::fs::metadata(path.join("samples.log")).unwrap().len()
    };
    let store = Store::open(&path).unwrap();
    assert_eq!(store.sample_log_bytes(), log_len);
    check_v3_fixture_reads_back(&store, &exrs, &written, &records);
    drop(store);
    // An older build refuses it.
    assert_an_older_build_refuses(&path, 3);
}

#[test]
fn interrupted_0003_to_0004_migration_resumes_where_it_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    let (exrs, written, records) = v3_fixture(&path);
    let in_frame_1 = records.iter().filter(|(f, _)| *f == 1).count();
    // A crash after the first batch (one frame), and in the middle of the
    // next one's log append (bytes no key references yet).
    {
        let db = open_raw(&path);
        radcache::store::v3::migrate_to_v4_batches(&db, &path, 1, Some(1)).unwrap();
        db.flush().unwrap();
        let meta = db.open_tree("meta").unwrap();
        assert_eq!(
            meta.get(keys::META_SCHEMA_VERSION)
                .unwrap()
                .unwrap()
                .as_ref(),
            3u32.to_be_bytes(),
            "still schema 3"
        );
        let lens: Vec<usize> = db
            .open_tree("records")
            .unwrap()
            .iter()
            .keys()
            .map(|k| k.unwrap().len())
            .collect();
        assert_eq!(lens.iter().filter(|&&l| l == 12).count(), 1);
        assert_eq!(lens.iter().filter(|&&l| l == 20).count(), in_frame_1);
    }
    append_torn_bytes_to_the_log(&path);
    let store = Store::open(&path).unwrap();
    check_v3_fixture_reads_back(&store, &exrs, &written, &records);
}

#[test]
fn a_frame_written_again_replaces_its_record_block_and_sources() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    let mut job = store.begin_job(&spec("j"), false).unwrap();
    let strata = Strata { theta: 4, phi: 12 };
    let commit = |job: &mut radcache::store::schema::JobValue,
                  records: Vec<RecordCommit>,
                  sources: Option<&FrameSourcesValue>| {
        let stats = FrameStats::default();
        store
            .commit_frame(
                job,
                FrameCommit {
                    frame: 0,
                    width: 16,
                    height: 16,
                    exr: b"exr",
                    records,
                    stats: &stats,
                    state: None,
                    movies: None,
                    sources,
                },
            )
            .unwrap();
    };
    let rc = |id: u64, seed: u32| {
        let mut r = record(id, 0);
        r.irradiance = Vec3::splat(seed as f32);
        RecordCommit::from_record(&r, SampleBlock::pack(&samples(48, seed), &[]), strata, 0)
    };
    // Record 5 a radiance record, given twice: the sources of its last
    // version are kept, and record 3 has none.
    let radiance = |id: u64, seed: u32| {
        let mut r = record(id, 0);
        let source = Eas {
            offset: Vec3::X,
            solid_angle: 0.5,
            irradiance: Vec3::splat(seed as f32),
            node: 0,
        };
        r.eas = Some(vec![source].into());
        r
    };
    let sources = FrameSourcesValue::of(&[radiance(5, 1), record(3, 0), radiance(5, 3)]).unwrap();
    assert_eq!(sources.records.len(), 1);
    assert_eq!(sources.records[0].id, 5);
    assert_eq!(sources.records[0].sources[0].irradiance, [3.0; 3]);
    // Out of order, and record 5 twice: its last version is kept.
    commit(&mut job, vec![rc(5, 1), rc(3, 2), rc(5, 3)], Some(&sources));
    assert_eq!(
        store.frame_sources(job.id, 0).unwrap().as_ref(),
        Some(&sources)
    );
    let recs = store.frame_records(job.id, 0).unwrap();
    assert_eq!(recs.iter().map(|r| r.id).collect::<Vec<_>>(), vec![3, 5]);
    assert_eq!(recs[1].irradiance, [3.0; 3]);
    let want = SampleBlock::pack(&samples(48, 3), &[]).unpack().unwrap();
    assert_eq!(store.record_samples(job.id, 0, 5).unwrap(), want);
    assert_eq!(store.samples_of_record(job.id, 0, &recs[1]).unwrap(), want);
    assert!(store.record_samples(job.id, 0, 4).unwrap().is_empty());
    // Written again: the new block replaces the old one, and with no
    // radiance record no sources are left …
    commit(&mut job, vec![rc(7, 4)], None);
    let recs = store.frame_records(job.id, 0).unwrap();
    assert_eq!(recs.iter().map(|r| r.id).collect::<Vec<_>>(), vec![7]);
    assert_eq!(store.frame_sources(job.id, 0).unwrap(), None);
    // … and a version with no records leaves none.
    commit(&mut job, Vec::new(), None);
    assert!(store.frame_records(job.id, 0).unwrap().is_empty());
    assert!(store.frame_records_value(job.id, 0).unwrap().is_none());
    assert_eq!(store.frames_done(job.id).unwrap(), vec![0]);
    assert_eq!(store.job("j").unwrap().unwrap().frames_done, 1);
}

/// A schema-4 store at `path` (written by this build's writer at schema
/// 4, its statistics then put back in the schema-7 layout: the rest is
/// laid out alike): frames 0..2 of job "j", closed.
fn v4_fixture(path: &Path) {
    {
        let store = Store::open_with(path, true, 4, migrate::MIGRATIONS).unwrap();
        assert_eq!(store.schema_version().unwrap(), 4);
        commit_frames(&store, "j", 0..2);
    }
    radcache::store::v7::downgrade_stats_to_schema_7(&open_raw(path)).unwrap();
}

/// The store's frames, records and samples of job "j", as read back.
#[allow(clippy::type_complexity)]
fn job_j_content(
    store: &Store,
) -> Vec<(
    Vec<u8>,
    Vec<radcache::store::schema::RecordValue>,
    Vec<Vec<PackedSample>>,
)> {
    let job = store.job("j").unwrap().unwrap();
    (0..2)
        .map(|f| {
            let records = store.frame_records(job.id, f).unwrap();
            let samples = records
                .iter()
                .map(|r| store.record_samples(job.id, f, r.id).unwrap())
                .collect();
            (
                store.frame_exr(job.id, f).unwrap().unwrap(),
                records,
                samples,
            )
        })
        .collect()
}

fn meta_generation(path: &Path) -> Option<Vec<u8>> {
    let db = open_raw(path);
    let meta = db.open_tree("meta").unwrap();
    let g = meta.get(keys::META_SAMPLES_LOG_GENERATION).unwrap();
    g.map(|v| v.to_vec())
}

#[test]
fn version_4_store_gets_a_log_generation_and_a_schema_4_build_refuses_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    v4_fixture(&path);
    let before = job_j_content(&Store::open_with(&path, false, 4, migrate::MIGRATIONS).unwrap());
    assert_eq!(meta_generation(&path), None);
    {
        let store = Store::open(&path).unwrap();
        assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
        assert_eq!(job_j_content(&store), before);
        assert_eq!(store.sample_log_file(), path.join("samples.log"));
    }
    assert_eq!(meta_generation(&path), Some(0u64.to_be_bytes().to_vec()));
    // An older build refuses it (its log may have moved by now).
    assert_an_older_build_refuses(&path, 4);
}

/// Schema 6 only gives the `movies` tree its texture movies (and schema
/// 7 changes only `trc`'s state): a schema-5 store opens with its content
/// unchanged and no movie, and a schema-5 build then refuses it (it would
/// leave a job's movies behind when the job starts over).
#[test]
fn version_5_store_opens_unchanged_and_a_schema_5_build_refuses_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    v4_fixture(&path);
    let before = {
        let v5 = Store::open_with(&path, true, 5, migrate::MIGRATIONS).unwrap();
        assert_eq!(v5.schema_version().unwrap(), 5);
        job_j_content(&v5)
    };
    {
        let store = Store::open(&path).unwrap();
        assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
        assert_eq!(job_j_content(&store), before);
        let job = store.job("j").unwrap().unwrap();
        for frame in store.frames_done(job.id).unwrap() {
            assert_eq!(store.frame_movies(job.id, frame).unwrap(), None);
        }
    }
    assert_an_older_build_refuses(&path, 5);
}

#[test]
fn interrupted_0004_to_0005_migration_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    v4_fixture(&path);
    let before = job_j_content(&Store::open_with(&path, false, 4, migrate::MIGRATIONS).unwrap());
    // A crash after the step, before the version bump: still schema 4.
    {
        let db = open_raw(&path);
        radcache::store::v4::migrate_to_v5(&db, &path).unwrap();
        db.flush().unwrap();
    }
    assert_eq!(
        Store::open_with(&path, false, 4, migrate::MIGRATIONS)
            .unwrap()
            .schema_version()
            .unwrap(),
        4
    );
    let store = Store::open(&path).unwrap();
    assert_eq!(store.schema_version().unwrap(), migrate::CURRENT_VERSION);
    assert_eq!(job_j_content(&store), before);
    drop(store);
    assert_eq!(meta_generation(&path), Some(0u64.to_be_bytes().to_vec()));
}

#[test]
fn leftover_logs_are_removed_on_open_and_a_missing_current_log_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db");
    store_with_two_frames(&path);
    // A compaction's leftover (a new log that never switched), and files
    // that are no log.
    for name in [
        "samples.1.log",
        "samples.7.log",
        "samples.x.log",
        "samples.log.bak",
    ] {
        std::fs::write(path.join(name), b"RCSLOG1\njunk").unwrap();
    }
    let store = Store::open(&path).unwrap();
    assert_eq!(
        store
            .frames_done(store.job("j").unwrap().unwrap().id)
            .unwrap(),
        vec![0, 1]
    );
    for (name, kept) in [
        ("samples.log", true),
        ("samples.1.log", false),
        ("samples.7.log", false),
        ("samples.x.log", true),
        ("samples.log.bak", true),
    ] {
        assert_eq!(path.join(name).exists(), kept, "{name}");
    }
    // `meta` naming a log that is not there: an error naming it; nothing
    // removed.
    store
        .raw_insert(
            "meta",
            keys::META_SAMPLES_LOG_GENERATION,
            &3u64.to_be_bytes(),
        )
        .unwrap();
    drop(store);
    let msg = err_text(Store::open(&path));
    assert!(
        msg.contains("samples.3.log") && msg.contains("lost?"),
        "{msg}"
    );
    assert!(path.join("samples.log").exists());
}

/// What a crash after an append, before its commit, leaves: 777 bytes past
/// the committed end of `samples.log`, which opening the store must cut off.
fn append_torn_bytes_to_the_log(store_dir: &std::path::Path) {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(store_dir.join("samples.log"))
        .unwrap();
    f.write_all(&[0x55; 777]).unwrap();
}

/// [`assert_resumed_rays`] for `trc`, whose records come back from the
/// store without their kept paths (`trc::paths`, in memory only): until
/// they are all replaced, a resumed frame also traces the paths that the
/// uninterrupted run took from them. Every frame traces at least as many
/// rays as the uninterrupted run's, and each after the first fewer than
/// twice as many (a frame replayed in it would double them at least).
fn assert_resumed_rays_without_kept_paths(resumed: &[FrameStats], uninterrupted: &[FrameStats]) {
    assert_eq!(resumed.len(), uninterrupted.len());
    for (f, (r, u)) in resumed.iter().zip(uninterrupted).enumerate() {
        assert!(
            r.rays >= u.rays,
            "frame {f}: {} rays against {}",
            r.rays,
            u.rays
        );
        if f > 0 {
            assert!(
                r.rays < 2 * u.rays,
                "frame {f}: {} rays against {}",
                r.rays,
                u.rays
            );
        }
    }
}

/// The rays of a resumed run's frames against an uninterrupted run's over
/// the same frames: each after the first the same (nothing is replayed);
/// the first at least as many, since it has no frame before whose pixel
/// samples it could take (`render_pass::StillSamples`).
fn assert_resumed_rays(resumed: &[FrameStats], uninterrupted: &[FrameStats]) {
    let rays = |stats: &[FrameStats]| -> Vec<u64> { stats.iter().map(|f| f.rays).collect() };
    let (resumed, uninterrupted) = (rays(resumed), rays(uninterrupted));
    assert_eq!(resumed.len(), uninterrupted.len());
    assert_eq!(
        resumed[1..],
        uninterrupted[1..],
        "the rays of the frames after the first"
    );
    assert!(
        resumed[0] >= uninterrupted[0],
        "{resumed:?} against {uninterrupted:?}"
    );
}

/// `tests/data/scenes/cube_in_box.glb` written into `dir` as glTF JSON
/// `name`, its buffer in `box.bin` beside it, naming the image `image` (a
/// texture the renderer ignores).
fn box_scene_naming_an_image(dir: &Path, name: &str, image: &str) -> PathBuf {
    let glb = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/scenes/cube_in_box.glb"
    ))
    .unwrap();
    let glb = gltf::binary::Glb::from_slice(&glb).unwrap();
    std::fs::write(dir.join("box.bin"), glb.bin.as_deref().unwrap()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&glb.json).unwrap();
    doc["buffers"][0]["uri"] = serde_json::json!("box.bin");
    doc["images"] = serde_json::json!([{ "uri": image }]);
    doc["textures"] = serde_json::json!([{ "source": 0 }]);
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
    path
}

/// `radcache render SCENE` as a tiny job `j` of store `db`: (success,
/// stdout, stderr).
fn render_tiny_job(scene: &Path, db: &Path, extra: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .arg("render")
        .arg(scene)
        .args(["--method", "path", "--size", "8x8", "--frames", "0..1"])
        .args([
            "--spp",
            "1",
            "--backend",
            "cpu",
            "-q",
            "--job",
            "j",
            "--out",
        ])
        .arg(db.with_extension("out"))
        .arg("--db")
        .arg(db)
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A scene whose image is missing renders as a job, as without `--job`
/// (the renderer ignores textures): the image is hashed as missing, so the
/// job resumes while it stays so, and is refused once the image appears,
/// saying that the scene changed.
#[test]
fn a_job_renders_a_scene_whose_ignored_image_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = box_scene_naming_an_image(dir.path(), "s.gltf", "missing.png");
    let db = dir.path().join("db");
    let (ok, _, stderr) = render_tiny_job(&scene, &db, &[]);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("1 texture(s) ignored"), "{stderr}");
    let (ok, stdout, stderr) = render_tiny_job(&scene, &db, &[]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("1 frames resumed"), "{stdout}");
    std::fs::write(dir.path().join("missing.png"), b"png").unwrap();
    let (ok, _, stderr) = render_tiny_job(&scene, &db, &[]);
    assert!(!ok);
    assert!(
        stderr.contains("its scene changed since the job was stored"),
        "{stderr}"
    );
}

/// A scene file changed between two renders under the same `--job` is
/// refused saying so plainly: the scene, named, changed since the job was
/// stored, and what to do; not "other settings". `--force` starts it
/// over. Another setting given as well is named beside it.
#[test]
fn a_job_whose_scene_file_changed_says_the_scene_changed() {
    let dir = tempfile::tempdir().unwrap();
    let scene = box_scene_naming_an_image(dir.path(), "s.gltf", "tex.png");
    std::fs::write(dir.path().join("tex.png"), b"png").unwrap();
    let db = dir.path().join("db");
    let (ok, _, stderr) = render_tiny_job(&scene, &db, &[]);
    assert!(ok, "{stderr}");
    let mut text = std::fs::read_to_string(&scene).unwrap();
    text.push('\n');
    std::fs::write(&scene, text).unwrap();
    let (ok, _, stderr) = render_tiny_job(&scene, &db, &[]);
    assert!(!ok);
    let named = format!(
        "job \"j\": its scene changed since the job was stored: {} (the file, or a file it \
         references) is not as it was (scene hash stored ",
        scene.display()
    );
    assert!(stderr.contains(&named), "{stderr}");
    assert!(
        stderr.contains("; use another --job name, or --force to start it over"),
        "{stderr}"
    );
    assert!(!stderr.contains("other settings"), "{stderr}");
    let (ok, _, stderr) = render_tiny_job(&scene, &db, &["--seed", "7"]);
    assert!(!ok);
    assert!(
        stderr.contains("is not as it was")
            && stderr.contains("and it exists with other settings: seed (stored 0, given 7)"),
        "{stderr}"
    );
    let (ok, _, stderr) = render_tiny_job(&scene, &db, &["--force"]);
    assert!(ok, "{stderr}");
}

/// This process's peak resident memory (`VmHWM`), in KiB.
#[cfg(target_os = "linux")]
fn peak_rss_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// A scene's image is hashed a chunk at a time: a 256 MiB one (sparse)
/// does not raise the peak memory by its size. Measured in a process of
/// its own (this test run again alone), as the peak is the process's.
#[cfg(target_os = "linux")]
#[test]
fn a_huge_image_is_hashed_without_holding_it() {
    const CHILD: &str = "RADCACHE_TEST_HASH_MEMORY_CHILD";
    const IMAGE: u64 = 256 << 20;
    if std::env::var_os(CHILD).is_none() {
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "a_huge_image_is_hashed_without_holding_it"])
            .args(["--nocapture", "--test-threads", "1"])
            .env(CHILD, "1")
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{text}");
        assert!(text.contains("1 passed"), "{text}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = box_scene_naming_an_image(dir.path(), "s.gltf", "huge.png");
    let image = std::fs::File::create(dir.path().join("huge.png")).unwrap();
    image.set_len(IMAGE).unwrap();
    drop(image);
    let before = peak_rss_kib();
    let (_, hash) = render::scene_identity(&SceneSource::File(scene)).unwrap();
    let grown = peak_rss_kib().saturating_sub(before);
    assert!(hash.contains('+'), "{hash}");
    assert!(
        grown < IMAGE / 1024 / 8,
        "the peak memory grew by {grown} KiB hashing a {IMAGE}-byte image"
    );
}

/// Several jobs deleted together go in one write: a name not found deletes
/// none of them (even the ones found before it), and then all go, their
/// keys with them.
#[test]
fn deleting_several_jobs_is_all_or_none() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open(&dir.path().join("db")).unwrap();
    commit_frames(&store, "a", 0..2);
    commit_frames(&store, "b", 0..1);
    store.set_job_cancelled("b", true).unwrap();
    let names = |store: &Store| -> Vec<String> {
        store
            .jobs()
            .unwrap()
            .into_iter()
            .map(|j| j.spec.name)
            .collect()
    };
    let err = err_text(store.delete_jobs(&["b", "a", "nope"]));
    assert!(
        err.contains("job \"nope\": not found; nothing deleted"),
        "{err}"
    );
    assert_eq!(names(&store), ["a", "b"]);
    assert!(store.job_cancelled("b").unwrap(), "its mark stays too");
    let deleted = store.delete_jobs(&["b", "a", "b"]).unwrap();
    let deleted: Vec<_> = deleted
        .iter()
        .map(|j| (j.spec.name.as_str(), j.frames_done))
        .collect();
    assert_eq!(deleted, [("b", 1), ("a", 2)]);
    assert!(names(&store).is_empty());
    assert!(!store.job_cancelled("b").unwrap());
    for tree in ["frames", "records", "stats"] {
        assert_eq!(store.tree(tree).unwrap().len(), 0, "{tree}");
    }
}
