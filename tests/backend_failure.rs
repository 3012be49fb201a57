//! A ray backend that stops working in the middle of a render (a GPU
//! device lost, out of memory) must not panic the process: the renderer
//! discards the frame, stops with a message naming the frame and the
//! backend, and a job resumed on another backend continues from the last
//! stored frame, with the frames an uninterrupted render gives.

use radcache::backend::cpu::CpuBackend;
use radcache::backend::{Hit, Ray, RayBackend, RayCounts};
use radcache::cache::gather::Strata;
use radcache::film;
use radcache::method::ic::IcSettings;
use radcache::method::trc::TrcSettings;
use radcache::render::{
    self, FrameFailed, FrameSettings, MethodSettings, Renderer, SceneSource, StoreJob,
};
use radcache::scene::Snapshot;
use radcache::store::Store;
use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Mutex;

/// The CPU backend, failing for good once it is given the geometry for
/// the `fail_at`-th time (0-based): as a GPU does when its device is lost.
struct FailingBackend {
    inner: CpuBackend,
    geometry_calls: AtomicU32,
    fail_at: u32,
    failed: Mutex<Option<String>>,
}

impl FailingBackend {
    fn new(fail_at: u32) -> Self {
        FailingBackend {
            inner: CpuBackend::new(),
            geometry_calls: AtomicU32::new(0),
            fail_at,
            failed: Mutex::new(None),
        }
    }

    /// Whether rays fail now (and from now on).
    fn fails(&self) -> bool {
        let mut failed = self.failed.lock().unwrap();
        if self.geometry_calls.load(Ordering::Relaxed) > self.fail_at {
            failed.get_or_insert_with(|| "device lost (simulated)".into());
        }
        failed.is_some()
    }
}

impl RayBackend for FailingBackend {
    fn name(&self) -> String {
        "test".into()
    }

    fn set_geometry(&mut self, snapshot: &Snapshot) {
        self.geometry_calls.fetch_add(1, Ordering::Relaxed);
        self.inner.set_geometry(snapshot);
    }

    fn closest_hit(&self, rays: &[Ray], hits: &mut [Hit]) {
        if self.fails() {
            hits.fill(Hit::MISS);
        } else {
            self.inner.closest_hit(rays, hits);
        }
    }

    fn any_hit(&self, rays: &[Ray], occluded: &mut [bool]) {
        if self.fails() {
            occluded.fill(false);
        } else {
            self.inner.any_hit(rays, occluded);
        }
    }

    fn ray_counts(&self) -> RayCounts {
        self.inner.ray_counts()
    }

    fn preferred_batch(&self) -> usize {
        self.inner.preferred_batch()
    }

    fn failure(&self) -> Option<String> {
        self.failed.lock().unwrap().clone()
    }
}

fn trc() -> MethodSettings {
    MethodSettings::Trc(TrcSettings {
        ic: IcSettings {
            strata: Strata { theta: 4, phi: 12 },
            spp: 1,
            ..IcSettings::default()
        },
        ..TrcSettings::default()
    })
}

fn renderer(method: &MethodSettings, backend: Box<dyn RayBackend>) -> Renderer {
    let settings = FrameSettings {
        width: 16,
        height: 16,
        ..FrameSettings::default()
    };
    let scene = SceneSource::Builtin("cube-in-box".into()).load().unwrap();
    Renderer::new(scene, method.instantiate(), backend, settings)
}

fn exr(dir: &Path, frame: u32) -> Vec<u8> {
    std::fs::read(film::frame_path(dir, frame, "exr")).unwrap()
}

#[test]
fn a_failing_backend_stops_the_render_and_the_job_resumes_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let (plain, out) = (dir.path().join("plain"), dir.path().join("out"));
    let method = trc();
    let cpu = || Box::new(CpuBackend::new()) as Box<dyn RayBackend>;
    render::render_to_dir(&mut renderer(&method, cpu()), 0..6, &plain, true).unwrap();

    let store = Store::open(&dir.path().join("db")).unwrap();
    let r = renderer(&method, cpu());
    let spec = render::job_spec(
        "j",
        &SceneSource::Builtin("cube-in-box".into()),
        &method,
        &r.settings,
        0..6,
    )
    .unwrap();
    let mut job = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let failing = Box::new(FailingBackend::new(3));
    let err = render::render_job_to_dir(
        &mut renderer(&method, failing),
        0..6,
        &out,
        true,
        Some(&mut job),
    )
    .expect_err("the backend failed during frame 3");
    let msg = format!("{err:#}");
    assert!(
        msg.contains("frame 3")
            && msg.contains("the test backend failed: device lost (simulated)")
            && msg.contains("resume"),
        "{msg}"
    );
    let job_id = job.job.id;
    assert_eq!(store.frames_done(job_id).unwrap(), vec![0, 1, 2]);
    assert!(
        !film::frame_path(&out, 3, "exr").exists(),
        "the failed frame was written"
    );

    let mut job = StoreJob {
        store: &store,
        job: store.begin_job(&spec, false).unwrap(),
    };
    let summary = render::render_job_to_dir(
        &mut renderer(&method, cpu()),
        0..6,
        &out,
        true,
        Some(&mut job),
    )
    .unwrap();
    assert_eq!((summary.resumed, summary.frames), (3, 3));
    for f in 0..6 {
        assert_eq!(exr(&plain, f), exr(&out, f), "frame {f}");
    }
}

#[test]
fn a_failed_backend_refuses_every_later_frame() {
    let mut r = renderer(&trc(), Box::new(FailingBackend::new(1)));
    assert!(r.try_render_frame(0).is_ok());
    let first = r.try_render_frame(1).expect_err("fails in frame 1");
    let FrameFailed::Backend {
        frame: 1,
        backend,
        message,
    } = &first
    else {
        panic!("{first:?}");
    };
    assert_eq!(backend, "test");
    let later = r.try_render_frame(2).expect_err("stays failed");
    assert_eq!(later.frame(), 2);
    assert_eq!(later.message(), message);
}
