//! Rays per second, CPU (2 threads) against the GPU backend with each BVH
//! layout (BVH2, CWBVH), on the same 100k-triangle scene and the same 1M
//! incoherent rays; plus the GPU's upload and readback times.
//!
//! ```text
//! cargo bench --bench gpu_rays            # all adapters wgpu finds, lavapipe included
//! GPU_RAYS=10000 cargo bench --bench gpu_rays   # fewer rays (quick look)
//! GPU_RAYS_CPU_THREADS=16 cargo bench --bench gpu_rays   # the CPU row on 16 threads
//! ```
//! Prints a Markdown table. Without a wgpu adapter only the CPU rows appear.

use glam::{Quat, Vec3};
use radcache::backend::cpu::CpuBackend;
use radcache::backend::gpu::{AdapterPolicy, GpuBackend, GpuLayout, GpuTimings};
use radcache::backend::{Hit, Ray, RayBackend};
use radcache::sampling::Rng;
use radcache::scene::{Animation, CameraDef, Material, Mesh, Node, Object, Scene, Snapshot, Trs};
use std::time::{Duration, Instant};

/// Triangles of the scene (static soup + closed room).
const TRIANGLES: usize = 100_000;
/// Rays per measurement (override with `GPU_RAYS`).
const RAYS: usize = 1 << 20;
/// Repetitions; the best one is reported.
const RUNS: usize = 3;
/// CPU threads (the 2-core machines of STACK.md; override with
/// `GPU_RAYS_CPU_THREADS` to set a GPU against all the cores beside it).
const CPU_THREADS: usize = 2;

fn random_unit(rng: &mut Rng) -> Vec3 {
    let z = 2.0 * rng.next_f32() - 1.0;
    let phi = std::f32::consts::TAU * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

fn random_in(rng: &mut Rng, lo: Vec3, hi: Vec3) -> Vec3 {
    lo + (hi - lo) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
}

/// A closed box [-4, 4]³ (12 triangles) with a soup of small random
/// triangles inside: every ray hits something.
fn scene() -> Scene {
    let mut rng = Rng::from_seed(42, 0);
    let mut mesh = Mesh::default();
    let push = |mesh: &mut Mesh, p: [Vec3; 3]| {
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(p);
        mesh.normals.extend([Vec3::Z; 3]);
        mesh.triangles.push([base, base + 1, base + 2]);
        mesh.materials.push(0);
    };
    let (lo, hi) = (Vec3::splat(-4.0), Vec3::splat(4.0));
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    for [a, b, c, d] in [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ] {
        push(&mut mesh, [corners[a], corners[b], corners[c]]);
        push(&mut mesh, [corners[a], corners[c], corners[d]]);
    }
    while mesh.triangles.len() < TRIANGLES {
        let c = random_in(&mut rng, Vec3::splat(-3.5), Vec3::splat(3.5));
        let size = 0.02 + 0.08 * rng.next_f32();
        let p = [0, 1, 2].map(|_| c + random_unit(&mut rng) * size);
        push(&mut mesh, p);
    }
    Scene {
        name: "bench soup".into(),
        nodes: vec![
            Node {
                name: "soup".into(),
                parent: None,
                rest: Trs::default(),
            },
            Node {
                name: "camera".into(),
                parent: None,
                rest: Trs {
                    translation: Vec3::new(0.0, 0.0, 3.9),
                    rotation: Quat::IDENTITY,
                    scale: Vec3::ONE,
                },
            },
        ],
        objects: vec![Object {
            name: "soup".into(),
            node: 0,
            mesh,
        }],
        materials: vec![Material::diffuse("grey", Vec3::splat(0.5))],
        lights: vec![],
        camera: CameraDef {
            node: 1,
            yfov: 1.0,
            aspect_ratio: None,
        },
        animation: Animation { channels: vec![] },
        frame_count: 1,
        moved_by: Vec3::ZERO,
    }
}

fn incoherent_rays(n: usize) -> Vec<Ray> {
    let mut rng = Rng::from_seed(7, 1);
    (0..n)
        .map(|_| {
            let o = random_in(&mut rng, Vec3::splat(-3.9), Vec3::splat(3.9));
            Ray::new(o, random_unit(&mut rng), 0.0, f32::INFINITY)
        })
        .collect()
}

/// Best of `RUNS` of `f`, with what `f` returns on that run.
fn best<T>(mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut out = None;
    for _ in 0..RUNS {
        let start = Instant::now();
        let v = f();
        let d = start.elapsed();
        if out.as_ref().is_none_or(|(b, _)| d < *b) {
            out = Some((d, v));
        }
    }
    out.expect("RUNS > 0")
}

fn mrays(n: usize, d: Duration) -> f64 {
    n as f64 / d.as_secs_f64() / 1e6
}

/// A positive number from the environment, or `default`.
fn env_or(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&v| v > 0)
        .unwrap_or(default)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() {
    let n: usize = env_or("GPU_RAYS", RAYS);
    let threads: usize = env_or("GPU_RAYS_CPU_THREADS", CPU_THREADS);
    let scene = scene();
    let snapshot: Snapshot = scene.snapshot(0.0);
    let rays = incoherent_rays(n);
    let mut hits = vec![Hit::MISS; n];
    let mut occluded = vec![false; n];
    println!(
        "scene: {} triangles (static); {} incoherent rays; best of {RUNS}\n",
        snapshot.triangles.len(),
        n
    );
    println!("| backend | closest hit Mrays/s | any hit Mrays/s | notes |");
    println!("| --- | ---: | ---: | --- |");

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("rayon pool");
    let (cpu_closest, cpu_any, cpu_hits) = pool.install(|| {
        let mut cpu = CpuBackend::new();
        cpu.set_geometry(&snapshot);
        let (c, _) = best(|| cpu.closest_hit(&rays, &mut hits));
        let (a, _) = best(|| cpu.any_hit(&rays, &mut occluded));
        (c, a, hits.clone())
    });
    println!(
        "| cpu ({threads} threads, CWBVH) | {:.2} | {:.2} | |",
        mrays(n, cpu_closest),
        mrays(n, cpu_any)
    );

    let cpu = CpuRun {
        closest: cpu_closest,
        any: cpu_any,
        hits: cpu_hits,
    };
    let mut notes = Vec::new();
    for layout in GpuLayout::ALL {
        match gpu_row(layout, &snapshot, &rays, &cpu) {
            Ok(note) => notes.push(note),
            Err(e) => {
                println!("\nGPU: {e}");
                return;
            }
        }
    }
    for note in notes {
        println!("\n{note}");
    }
}

/// The CPU's times and hits, which the GPU rows are compared with.
struct CpuRun {
    closest: Duration,
    any: Duration,
    hits: Vec<Hit>,
}

/// Measures the GPU backend with `layout` on `rays`, prints its table row
/// and returns the notes printed under the table.
fn gpu_row(
    layout: GpuLayout,
    snapshot: &Snapshot,
    rays: &[Ray],
    cpu: &CpuRun,
) -> Result<String, radcache::backend::gpu::GpuError> {
    let n = rays.len();
    let mut hits = vec![Hit::MISS; n];
    let mut occluded = vec![false; n];
    let mut gpu = GpuBackend::with_layout(AdapterPolicy::AllowSoftware, layout)?;
    let start = Instant::now();
    gpu.set_geometry(snapshot);
    let setup = start.elapsed();
    let geometry = gpu.timings();
    gpu.reset_timings();
    // One warm-up batch (pipeline caches, buffer growth), not measured.
    gpu.closest_hit(rays, &mut hits);
    gpu.any_hit(rays, &mut occluded);
    gpu.reset_timings();
    let (gpu_closest, closest_t) = best(|| {
        gpu.reset_timings();
        gpu.closest_hit(rays, &mut hits);
        gpu.timings()
    });
    let (gpu_any, any_t) = best(|| {
        gpu.reset_timings();
        gpu.any_hit(rays, &mut occluded);
        gpu.timings()
    });
    let same = hits
        .iter()
        .zip(&cpu.hits)
        .filter(|(g, c)| g.triangle == c.triangle && g.t == c.t)
        .count();
    // A GPU that fuses multiply-adds moves many t by an ulp or so: count
    // the same triangles apart from the bit-identical t.
    let same_triangle = hits
        .iter()
        .zip(&cpu.hits)
        .filter(|(g, c)| g.triangle == c.triangle)
        .count();
    let breakdown = |t: &GpuTimings| {
        format!(
            "upload {:.1} ms, dispatch {:.1} ms, readback {:.1} ms, {} dispatches",
            ms(t.ray_upload),
            ms(t.dispatch),
            ms(t.readback),
            t.dispatches
        )
    };
    println!(
        "| {}, {} | {:.2} | {:.2} | {:.2}× / {:.2}× the CPU's rate |",
        gpu.name(),
        layout.name(),
        mrays(n, gpu_closest),
        mrays(n, gpu_any),
        cpu.closest.as_secs_f64() / gpu_closest.as_secs_f64(),
        cpu.any.as_secs_f64() / gpu_any.as_secs_f64(),
    );
    let name = layout.name();
    Ok([
        format!("GPU {name} closest hit, best run: {}", breakdown(&closest_t)),
        format!("GPU {name} any hit, best run:     {}", breakdown(&any_t)),
        format!(
            "GPU {name} geometry: build {:.1} ms, static upload {:.1} ms ({} MiB of triangles, plus nodes), set_geometry total {:.1} ms",
            ms(geometry.bvh_build),
            ms(geometry.static_upload),
            (snapshot.triangles.len() * 48) >> 20,
            ms(setup)
        ),
        format!(
            "GPU {name} readback: {:.1} MiB of hits in {:.1} ms = {:.0} MiB/s",
            (n * std::mem::size_of::<Hit>()) as f64 / (1 << 20) as f64,
            ms(closest_t.readback),
            (n * std::mem::size_of::<Hit>()) as f64
                / (1 << 20) as f64
                / closest_t.readback.as_secs_f64().max(1e-9)
        ),
        format!(
            "GPU {name} closest hits identical to the CPU (triangle and t): {same} of {n} ({:.4} %); same triangle: {same_triangle} ({:.4} %)",
            100.0 * same as f64 / n as f64,
            100.0 * same_triangle as f64 / n as f64
        ),
    ]
    .join("\n"))
}
