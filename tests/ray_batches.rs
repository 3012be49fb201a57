//! Work split over threads is split no finer than the backend's
//! `min_batch`: on a GPU every call is a dispatch, and paths traced in
//! tasks of 256 queries once made each bounce a dispatch of at most 256
//! rays (`ic` on lavapipe 10× slower than with large batches). The split
//! changes only scheduling, never a result.

use glam::Vec3;
use radcache::backend::cpu::CpuBackend;
use radcache::backend::{Hit, Ray, RayBackend, RayCounts};
use radcache::cache::gather::Strata;
use radcache::integrator::{trace_radiance_parallel, FirstHitEmission, PathLength, RadianceQuery};
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::path::PathTracer;
use radcache::render::{FrameSettings, Renderer};
use radcache::sampling::{Rng, SampleKey};
use radcache::scene::{Scene, Snapshot};
use std::sync::{Arc, Mutex};

/// The CPU backend with a chosen `min_batch` (and `preferred_batch`),
/// recording the size of every call.
struct Recording {
    inner: CpuBackend,
    min_batch: usize,
    preferred_batch: usize,
    sizes: Arc<Mutex<Vec<usize>>>,
}

impl RayBackend for Recording {
    fn name(&self) -> String {
        "recording".into()
    }
    fn set_geometry(&mut self, snapshot: &Snapshot) {
        self.inner.set_geometry(snapshot);
    }
    fn closest_hit(&self, rays: &[Ray], hits: &mut [Hit]) {
        self.sizes.lock().unwrap().push(rays.len());
        self.inner.closest_hit(rays, hits);
    }
    fn any_hit(&self, rays: &[Ray], occluded: &mut [bool]) {
        self.sizes.lock().unwrap().push(rays.len());
        self.inner.any_hit(rays, occluded);
    }
    fn ray_counts(&self) -> RayCounts {
        self.inner.ray_counts()
    }
    fn preferred_batch(&self) -> usize {
        self.preferred_batch
    }
    fn min_batch(&self) -> usize {
        self.min_batch
    }
}

/// A renderer of cube-in-box at 8×8 on a [`Recording`] backend of
/// `min_batch`, and the sizes it records.
fn renderer(min_batch: usize) -> (Renderer, Arc<Mutex<Vec<usize>>>) {
    let preferred_batch = CpuBackend::new().preferred_batch();
    path_renderer(min_batch, preferred_batch, 8)
}

/// A `path` renderer of cube-in-box at `size`² on a [`Recording`] backend
/// of `min_batch` and `preferred_batch`, and the sizes it records.
fn path_renderer(
    min_batch: usize,
    preferred_batch: usize,
    size: u32,
) -> (Renderer, Arc<Mutex<Vec<usize>>>) {
    let sizes = Arc::new(Mutex::new(Vec::new()));
    let backend = Recording {
        inner: CpuBackend::new(),
        preferred_batch,
        min_batch,
        sizes: sizes.clone(),
    };
    let renderer = Renderer::new(
        Scene::builtin("cube-in-box").unwrap(),
        Box::new(PathTracer::new(Default::default())),
        Box::new(backend),
        FrameSettings {
            width: size,
            height: size,
            ..Default::default()
        },
    );
    (renderer, sizes)
}

/// 3000 paths from the middle of cube-in-box traced with
/// `trace_radiance_parallel` on a backend of `min_batch`: their radiance,
/// and the sizes of the backend's calls.
fn trace(min_batch: usize) -> (Vec<Vec3>, Vec<usize>) {
    let (mut renderer, sizes) = renderer(min_batch);
    let radiance = renderer.with_frame_context(0, |ctx| {
        let centre = ctx.snapshot.camera.position * 0.5;
        let queries = (0..3000u32)
            .map(|i| {
                let mut rng = Rng::new(SampleKey {
                    seed: 7,
                    frame: None,
                    item: u64::from(i),
                    sample: 0,
                });
                let u = rng.next_2d();
                let (z, phi) = (2.0 * u.x - 1.0, std::f32::consts::TAU * u.y);
                let r = (1.0 - z * z).max(0.0).sqrt();
                let dir = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                RadianceQuery {
                    ray: Ray::new(centre, dir, 0.0, f32::INFINITY),
                    first_light: None,
                    rng,
                    weight: Vec3::ONE,
                    first_hit: FirstHitEmission::Include,
                }
            })
            .collect();
        trace_radiance_parallel(ctx, PathLength::default(), queries)
            .into_iter()
            .map(|r| r.radiance)
            .collect()
    });
    let sizes = sizes.lock().unwrap().clone();
    // The backend counts the calls it served (`render` prints them).
    assert_eq!(renderer.backend().ray_counts().calls, sizes.len() as u64);
    (radiance, sizes)
}

#[test]
fn tasks_are_no_smaller_than_the_backends_min_batch() {
    let (fine, fine_sizes) = trace(1);
    let (coarse, coarse_sizes) = trace(2000);
    // On the CPU a task is 256 queries; with a minimum of 2000, the 3000
    // queries make a task of 2000 and one of 1000, whose first bounces
    // carry all their rays.
    assert_eq!(fine_sizes.iter().max(), Some(&256), "{fine_sizes:?}");
    assert_eq!(coarse_sizes.iter().max(), Some(&2000), "{coarse_sizes:?}");
    assert!(coarse_sizes.contains(&1000), "{coarse_sizes:?}");
    assert!(coarse_sizes.len() < fine_sizes.len() / 4);
    assert_eq!(fine, coarse, "the split changed a result");
    assert!(fine.iter().any(|l| l.max_element() > 0.0));
}

/// `ic`'s gathers too: with a `min_batch` of many records' rays, the
/// records of a frame are gathered in fewer, larger calls, as many on 8
/// threads as on 2 (not split further over more threads), and are the
/// same records.
#[test]
fn gathers_are_no_smaller_than_the_backends_min_batch() {
    let ic = IrradianceCaching::new(IcSettings {
        spp: 1,
        strata: Strata { theta: 4, phi: 12 },
        ..IcSettings::default()
    });
    let cache = |min_batch| {
        let (mut r, sizes) = renderer(min_batch);
        let records = r.with_frame_context(0, |ctx| ic.build_cache(ctx).records().to_vec());
        let calls = sizes.lock().unwrap().len();
        (records, calls)
    };
    let on_threads = |threads, min_batch| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| cache(min_batch))
    };
    let (fine, fine_calls) = on_threads(2, 1);
    let (coarse, coarse_calls) = on_threads(2, 1 << 16);
    let (wide, wide_calls) = on_threads(8, 1 << 16);
    assert!(fine.len() > 4, "{} records", fine.len());
    assert_eq!(fine, coarse);
    assert_eq!(fine, wide);
    assert_eq!(wide_calls, coarse_calls, "8 threads against 2");
    assert!(
        coarse_calls < fine_calls,
        "{coarse_calls} calls against {fine_calls}"
    );
}

/// A backend whose preferred batch is a GPU's (1 Mi rays) once made a whole
/// frame one render tile, shaded on one thread while the others idled (a
/// 256×256 `path` frame on an H100 beside 16 cores). Tiles are now cut so
/// every thread gets two, no smaller than `min_batch`
/// (`RayBackend::items_per_task`), and the frame is the same.
#[test]
fn render_tiles_spread_over_the_threads_down_to_min_batch() {
    let render = |min_batch: usize| {
        let (mut renderer, sizes) = path_renderer(min_batch, 1 << 20, 32);
        let film = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap()
            .install(|| renderer.render_frame(0));
        let sizes = sizes.lock().unwrap().clone();
        (film.pixels, sizes)
    };
    // 1,024 pixels at 16 spp: with a `min_batch` of a whole frame's
    // samples, one tile, whose camera rays are one call of 16,384; with a
    // quarter of it, four tiles of 256 pixels (eight would be two a
    // thread, but a tile keeps 4,096 samples), four camera calls of 4,096.
    let tile_calls = |sizes: &[usize], n| sizes.iter().filter(|&&s| s == n).count();
    let (whole, whole_sizes) = render(1 << 14);
    let (spread, spread_sizes) = render(1 << 12);
    assert_eq!(tile_calls(&whole_sizes, 1 << 14), 1, "{whole_sizes:?}");
    assert_eq!(tile_calls(&spread_sizes, 1 << 14), 0, "{spread_sizes:?}");
    assert!(tile_calls(&spread_sizes, 1 << 12) >= 4, "{spread_sizes:?}");
    assert_eq!(whole, spread, "the split changed a pixel");
}
