//! The render pass's cache interpolation, CPU (octree, as `--backend cpu`
//! does it) against GPU (radiance cache splatting, `src/backend/gpu/cache_splat.rs`,
//! as `--backend gpu` does it), on `ic`'s cache of one frame of a built-in
//! scene.
//!
//! ```text
//! XDG_RUNTIME_DIR=/tmp cargo bench --bench cache_splat
//! SPLAT_SIZE=128 SPLAT_SPP=16 SPLAT_SCENE=chairs-room cargo bench --bench cache_splat
//! ```
//! Defaults: `cube-in-box`, frame 10, 64×64, 16 spp (`ic`'s default).
//!
//! Prints two Markdown tables, best of [`RUNS`] runs:
//! 1. the interpolation alone over the frame's lookups (one per pixel sample
//!    on a diffuse surface, as the render pass makes them): the CPU loop as
//!    the render tile runs it (one thread per tile; a frame this small is
//!    one tile), and the GPU's bin + upload ("prepare") and splat dispatch
//!    with readback;
//! 2. the whole render pass (`IrradianceCaching::render_with_cache`) with
//!    the CPU backend, with GPU rays but CPU interpolation, and with the GPU
//!    backend (GPU rays and interpolation): rows 2 and 3 differ only in the
//!    interpolation.
//!
//! On a machine without a GPU the adapter is lavapipe, a CPU rasteriser
//! running the shader on the same cores: the figures measure the overhead
//! of the GPU path there, not a GPU.

use glam::Vec3;
use radcache::backend::cpu::CpuBackend;
use radcache::backend::gpu::cache_splat::{GpuLookup, SplatTimings};
use radcache::backend::gpu::{AdapterPolicy, GpuBackend, RaysOnly};
use radcache::backend::{Hit, Ray, RayBackend};
use radcache::cache::LookupPoint;
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::pixels::{CameraSampler, PixelSample};
use radcache::method::render_pass::PixelStreams;
use radcache::method::FrameContext;
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::Scene;
use std::time::{Duration, Instant};

/// Repetitions; the best one is reported.
const RUNS: usize = 3;
/// The frame rendered (the cube has moved off its start).
const FRAME: u32 = 10;

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn best(mut f: impl FnMut() -> Duration) -> Duration {
    (0..RUNS).map(|_| f()).min().unwrap_or_default()
}

fn ms(d: Duration) -> String {
    format!("{:.2}", d.as_secs_f64() * 1e3)
}

/// The frame's lookups: the shading point and normal of each pixel sample
/// that hits a surface with a diffuse part (normal facing the camera).
fn lookups(ctx: &FrameContext, spp: u32) -> Vec<(Vec3, Vec3)> {
    let mut camera = CameraSampler::default();
    let rays: Vec<Ray> = (0..ctx.width * ctx.height)
        .flat_map(|pixel| (0..spp).map(move |s| PixelSample::base(pixel, s, spp)))
        .map(|s| camera.query(ctx, &s).0)
        .collect();
    let mut hits = vec![Hit::MISS; rays.len()];
    ctx.backend.closest_hit(&rays, &mut hits);
    rays.iter()
        .zip(&hits)
        .filter(|(_, h)| h.is_hit())
        .filter(|(_, h)| {
            let material = ctx.snapshot.tri_material[h.triangle as usize] as usize;
            ctx.scene.materials[material].diffuse.max_element() > 0.0
        })
        .map(|(ray, h)| {
            let n = ctx.snapshot.triangles[h.triangle as usize].shading_normal(h.u, h.v);
            let n = if n.dot(ray.dir()) > 0.0 { -n } else { n };
            (ray.at(h.t), n)
        })
        .collect()
}

fn main() {
    let scene_name: String = env_or("SPLAT_SCENE", "cube-in-box".to_string());
    let size: u32 = env_or("SPLAT_SIZE", 64);
    let spp: u32 = env_or("SPLAT_SPP", 16);
    let settings = IcSettings {
        spp,
        ..IcSettings::default()
    };
    let renderer = |backend: Box<dyn RayBackend>| {
        Renderer::new(
            Scene::builtin(&scene_name).expect("a built-in scene"),
            Box::new(IrradianceCaching::new(settings.clone())),
            backend,
            FrameSettings {
                width: size,
                height: size,
                ..FrameSettings::default()
            },
        )
    };
    let gpu = |what: &str| match GpuBackend::new(AdapterPolicy::AllowSoftware) {
        Ok(g) => Some(g),
        Err(e) => {
            eprintln!("no GPU rows ({what}): {e}");
            None
        }
    };
    let ic = IrradianceCaching::new(settings.clone());

    // 1. The interpolation alone, on the cache and lookups of the frame.
    println!("{scene_name}, frame {FRAME}, {size}x{size}, {spp} spp\n");
    let mut r = renderer(Box::new(CpuBackend::new()));
    let (cache, points) =
        r.with_frame_context(FRAME, |ctx| (ic.build_cache(ctx), lookups(ctx, spp)));
    println!(
        "{} records, {} lookups\n\n| interpolation | prepare (ms) | lookups (ms) | total (ms) |\n| --- | ---: | ---: | ---: |",
        cache.len(),
        points.len()
    );
    let cpu = best(|| {
        let start = Instant::now();
        let covered = points
            .iter()
            .filter(|&&(p, n)| {
                let at = LookupPoint::open(p, n);
                cache.interpolate(&at, settings.gradients).is_some()
            })
            .count();
        std::hint::black_box(covered);
        start.elapsed()
    });
    println!("| cpu, octree, 1 thread | – | {} | {} |", ms(cpu), ms(cpu));
    if let Some(g) = gpu("interpolation") {
        let splat = g.cache_splat().expect("the GPU backend splats");
        let gpu_points: Vec<GpuLookup> = points
            .iter()
            .map(|&(p, n)| GpuLookup::new(&LookupPoint::open(p, n)))
            .collect();
        let (mut prepare, mut lookup) = (Duration::MAX, Duration::MAX);
        let mut parts = SplatTimings::default();
        for _ in 0..RUNS {
            let start = Instant::now();
            let prepared = splat
                .prepare(cache.records(), cache.accuracy, settings.gradients)
                .expect("prepare");
            let p = start.elapsed();
            splat.reset_timings();
            let start = Instant::now();
            let sums = splat
                .interpolate(&prepared, &gpu_points, None)
                .expect("splat");
            std::hint::black_box(sums);
            let l = start.elapsed();
            if p + l < prepare.saturating_add(lookup) {
                (prepare, lookup, parts) = (p, l, splat.timings());
            }
        }
        let grid = splat
            .prepare(cache.records(), cache.accuracy, settings.gradients)
            .expect("prepare");
        println!(
            "| {} splat (grid {:?}, {} entries) | {} | {} | {} |",
            g.adapter_info().name,
            grid.grid().dims(),
            grid.grid().entries(),
            ms(prepare),
            ms(lookup),
            ms(prepare + lookup)
        );
        println!(
            "\nsplat lookups: upload {} ms, dispatch (GPU work, submit to done) {} ms, \
             readback {} ms, {} dispatch(es)",
            ms(parts.upload),
            ms(parts.dispatch),
            ms(parts.readback),
            parts.dispatches
        );
    }

    // 2. The whole render pass on the same cache.
    println!("\n| render pass | rays | interpolation | time (ms) |\n| --- | --- | --- | ---: |");
    let pass = |r: &mut Renderer| {
        best(|| {
            r.with_frame_context(FRAME, |ctx| {
                let start = Instant::now();
                std::hint::black_box(ic.render_with_cache(ctx, &cache, PixelStreams::PerFrame));
                start.elapsed()
            })
        })
    };
    let t = pass(&mut r);
    println!("| `--backend cpu` | cpu | cpu | {} |", ms(t));
    if let Some(g) = gpu("render pass, rays only") {
        let t = pass(&mut renderer(Box::new(RaysOnly(g))));
        println!("| gpu rays, cpu interpolation | gpu | cpu | {} |", ms(t));
    }
    if let Some(g) = gpu("render pass") {
        let t = pass(&mut renderer(Box::new(g)));
        println!("| `--backend gpu` | gpu | gpu | {} |", ms(t));
    }
}
