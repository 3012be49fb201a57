//! The GPU ray backend against the CPU one: the same hits on random triangle
//! soups with moving objects and on every built-in scene, and the same
//! path-traced frame.
//!
//! These tests need a wgpu adapter. Machines without a GPU use Mesa's
//! software Vulkan driver (lavapipe), which `.ci/run` installs; without any
//! adapter the tests FAIL (they do not skip), saying what to install.
//!
//! Parity rules (for the same rays, same geometry):
//! - same hit/miss;
//! - t within 1e-5 relative;
//! - same triangle, except on an exact tie (two triangles at the same t,
//!   |t_gpu − t_cpu| ≤ 1e-5·t, e.g. a shared edge) where the traversal
//!   orders (BVH2 on the GPU, CWBVH on the CPU) may pick either; the object
//!   may then differ too, and is otherwise equal;
//! - barycentrics within 1e-4 when the triangle is the same;
//! - any hit identical.
//!
//! Every parity test runs for both GPU layouts ([`GpuLayout`]). The GPU's
//! CWBVH is the CPU's very tree traversed in the CPU's order, so on lavapipe
//! it is held to bit-identical hits ([`cwbvh_is_exact`]).

mod common;

use common::{inward_box, scene};
use glam::{Quat, Vec3};
use radcache::backend::cpu::CpuBackend;
use radcache::backend::gpu::{AdapterPolicy, GpuBackend, GpuLayout, WAIT_LIMIT};
use radcache::backend::{Hit, Ray, RayBackend, RayCounts};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::render::{FrameSettings, Renderer};
use radcache::sampling::Rng;
use radcache::scene::animation::{linear_rotation, linear_translation};
use radcache::scene::{builtin, Material, Mesh, Scene, Snapshot};
use std::time::Duration;

/// Relative tolerance on t (and on ties), of the larger of t and the
/// coordinates' scale ([`t_tolerance`]).
const T_REL: f32 = 1e-5;
/// Absolute tolerance on barycentrics.
const UV_ABS: f32 = 1e-4;

fn gpu() -> GpuBackend {
    gpu_with(GpuLayout::default())
}

fn gpu_with(layout: GpuLayout) -> GpuBackend {
    match GpuBackend::with_layout(AdapterPolicy::AllowSoftware, layout) {
        Ok(gpu) => gpu,
        Err(e) => panic!(
            "GPU backend unavailable: {e}. These tests need a wgpu adapter; on a machine \
             without a GPU install Mesa's software Vulkan driver: \
             apt-get install mesa-vulkan-drivers libvulkan1 (.ci/run does this)"
        ),
    }
}

fn rng(stream: u64) -> Rng {
    Rng::from_seed(0x6770_755f_7465_7374, stream)
}

fn random_unit(rng: &mut Rng) -> Vec3 {
    let z = 2.0 * rng.next_f32() - 1.0;
    let phi = std::f32::consts::TAU * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

fn random_in(rng: &mut Rng, min: Vec3, max: Vec3) -> Vec3 {
    min + (max - min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
}

fn bounds(snapshot: &Snapshot) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for t in &snapshot.triangles {
        for p in t.p {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo, hi)
}

/// Ray sets of a snapshot: camera rays through random pixels, random
/// incoherent rays inside the scene's bounds (infinite and finite), and
/// secondary rays leaving the surfaces the camera rays hit, in random
/// directions, with the path tracer's kind of offset; also shadow segments
/// between hit points and random points.
fn rays_for(snapshot: &Snapshot, cpu: &CpuBackend, n: usize, stream: u64) -> Vec<Ray> {
    let mut rng = rng(stream);
    let (lo, hi) = bounds(snapshot);
    let pad = (hi - lo) * 0.05;
    let cam = &snapshot.camera;
    let mut rays = Vec::with_capacity(n);
    let quarter = n / 4;
    for _ in 0..quarter {
        let (sx, sy) = (rng.next_f32(), rng.next_f32());
        rays.push(Ray::new(
            cam.position,
            cam.direction(sx, sy, 1.5),
            0.0,
            f32::INFINITY,
        ));
    }
    let camera_rays = rays.clone();
    for i in 0..quarter {
        let o = random_in(&mut rng, lo - pad, hi + pad);
        let d = random_unit(&mut rng) * (0.5 + rng.next_f32());
        let tmax = if i % 2 == 0 {
            f32::INFINITY
        } else {
            rng.next_f32() * (hi - lo).length()
        };
        rays.push(Ray::new(o, d, 0.0, tmax));
    }
    let mut hits = vec![Hit::MISS; camera_rays.len()];
    cpu.closest_hit(&camera_rays, &mut hits);
    for (ray, hit) in camera_rays.iter().zip(&hits) {
        if rays.len() >= n {
            break;
        }
        if !hit.is_hit() {
            continue;
        }
        let tri = &snapshot.triangles[hit.triangle as usize];
        let p = tri.point(hit.u, hit.v);
        let mut ng = tri.geometric_normal();
        if ng.dot(ray.dir()) > 0.0 {
            ng = -ng;
        }
        let origin = p + ng * 1e-4 * p.abs().max_element().max(1.0);
        let mut d = random_unit(&mut rng);
        if d.dot(ng) < 0.0 {
            d = -d;
        }
        rays.push(Ray::new(origin, d, 0.0, f32::INFINITY));
        if rays.len() < n {
            // A shadow segment leaving on the same side, as a light sample's.
            let mut e = random_unit(&mut rng);
            if e.dot(ng) < 0.0 {
                e = -e;
            }
            let to = origin + e * (hi - lo).length() * rng.next_f32();
            rays.push(Ray::segment(origin, to));
        }
    }
    while rays.len() < n {
        let a = random_in(&mut rng, lo - pad, hi + pad);
        let b = random_in(&mut rng, lo - pad, hi + pad);
        rays.push(Ray::segment(a, b));
    }
    rays
}

/// How far the GPU's t may be from the CPU's, for a hit on a triangle
/// with geometric normal `normal`. The triangle test computes t from
/// `v − o` of the triangle's vertices, rounded at the scale of the
/// coordinates, so its absolute error stays near `ulp(|o|)/|d|` however
/// near the hit is, and grows as `1/|cos θ|` for a ray that grazes the
/// plane. A GPU that fuses multiply-adds rounds those terms differently.
/// On an H100 (with the Möller–Trumbore test this replaced): a hit at
/// t = 0.0046 from a ray starting 4 units from the
/// origin moved by 1.2e-6 (2.6e-4 of t); a ray at cos θ = 9e-4 hit at
/// t = 1.23824 on the CPU and 1.23821 on the GPU, where f64 gives 1.23820.
/// So t is held to [`T_REL`] of the larger of t and that scale, over
/// `|cos θ|`.
fn t_tolerance(ray: &Ray, t: f32, normal: Vec3) -> f32 {
    let coordinates = ray.origin().abs().max_element().max(1.0);
    let cos = normal
        .normalize_or_zero()
        .dot(ray.dir().normalize_or_zero());
    T_REL * t.abs().max(coordinates / ray.dir().length()) / cos.abs().max(1e-4)
}

#[derive(Debug, Default)]
struct Parity {
    rays: usize,
    hits: usize,
    /// Rays whose triangle differs on an exact tie.
    ties: usize,
    /// Rays whose t is not bit-identical (but within tolerance).
    t_not_bitwise: usize,
    max_t_rel: f32,
    max_uv: f32,
    occluded: usize,
}

/// Traces `rays` on both backends and checks the parity rules; `what`
/// names the case in failure messages.
fn check_parity(
    what: &str,
    cpu: &CpuBackend,
    gpu: &GpuBackend,
    snapshot: &Snapshot,
    rays: &[Ray],
) -> Parity {
    let mut cpu_hits = vec![Hit::MISS; rays.len()];
    let mut gpu_hits = vec![Hit::MISS; rays.len()];
    cpu.closest_hit(rays, &mut cpu_hits);
    gpu.try_closest_hit(rays, &mut gpu_hits)
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    let mut p = Parity {
        rays: rays.len(),
        ..Parity::default()
    };
    let mut failures = Vec::new();
    for (i, (c, g)) in cpu_hits.iter().zip(&gpu_hits).enumerate() {
        if c.is_hit() != g.is_hit() {
            failures.push(format!("ray {i} {:?}: cpu {c:?}, gpu {g:?}", rays[i]));
            continue;
        }
        if !c.is_hit() {
            if g.t != f32::INFINITY || g.object != u32::MAX {
                failures.push(format!("ray {i}: miss not MISS on the gpu: {g:?}"));
            }
            continue;
        }
        p.hits += 1;
        let dt = (g.t - c.t).abs();
        let rel = dt / c.t.abs().max(f32::MIN_POSITIVE);
        p.max_t_rel = p.max_t_rel.max(rel);
        if g.t.to_bits() != c.t.to_bits() {
            p.t_not_bitwise += 1;
        }
        let normal = snapshot.triangles[c.triangle as usize].geometric_normal();
        if dt > t_tolerance(&rays[i], c.t, normal) {
            failures.push(format!(
                "ray {i}: t cpu {} gpu {} ({c:?} / {g:?})",
                c.t, g.t
            ));
            continue;
        }
        if c.triangle != g.triangle {
            // A tie: the GPU's triangle must really be hit at the same t.
            let tri = &snapshot.triangles[g.triangle as usize];
            let q = tri.point(g.u, g.v);
            let expected = rays[i].at(c.t);
            let scale = expected.abs().max_element().max(1.0);
            if (q - expected).length() > 1e-3 * scale {
                failures.push(format!(
                    "ray {i}: different triangles not at a tie: cpu {c:?}, gpu {g:?}"
                ));
            }
            p.ties += 1;
            continue;
        }
        if c.object != g.object {
            failures.push(format!("ray {i}: object cpu {c:?} gpu {g:?}"));
            continue;
        }
        let duv = (g.u - c.u).abs().max((g.v - c.v).abs());
        p.max_uv = p.max_uv.max(duv);
        if duv > UV_ABS {
            failures.push(format!("ray {i}: barycentrics cpu {c:?} gpu {g:?}"));
        }
    }

    let mut cpu_occ = vec![false; rays.len()];
    let mut gpu_occ = vec![true; rays.len()];
    cpu.any_hit(rays, &mut cpu_occ);
    gpu.try_any_hit(rays, &mut gpu_occ)
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    for (i, (c, g)) in cpu_occ.iter().zip(&gpu_occ).enumerate() {
        if c != g {
            failures.push(format!("ray {i} {:?}: any hit cpu {c} gpu {g}", rays[i]));
        }
    }
    p.occluded = cpu_occ.iter().filter(|&&o| o).count();
    assert!(
        failures.is_empty(),
        "{what}: {} of {} rays differ; first ones:\n{}",
        failures.len(),
        rays.len(),
        failures[..failures.len().min(10)].join("\n")
    );
    // Both results must mean something: most sets hit, some rays miss.
    assert!(p.hits > 0, "{what}: no ray hit anything");
    eprintln!("{what}: {p:?}");
    p
}

/// A soup of `n` random triangles (sizes varying over two decades) in the
/// box [lo, hi].
fn soup(rng: &mut Rng, n: usize, lo: Vec3, hi: Vec3) -> Mesh {
    let mut m = Mesh::default();
    for _ in 0..n {
        let c = random_in(rng, lo, hi);
        let size = 0.02 * 10f32.powf(2.0 * rng.next_f32()) * (hi - lo).min_element() * 0.1;
        let base = m.positions.len() as u32;
        for _ in 0..3 {
            m.positions.push(c + random_unit(rng) * size);
            m.normals.push(Vec3::Z);
        }
        m.triangles.push([base, base + 1, base + 2]);
        m.materials.push(0);
    }
    m
}

/// A room with a static soup, and moving soups (translated, rotated and
/// both) inside it.
fn soup_scene(seed: u64) -> Scene {
    let mut r = rng(1000 + seed);
    let room = inward_box(Vec3::splat(-4.0), Vec3::splat(4.0), 0);
    let statics = soup(&mut r, 20_000, Vec3::splat(-3.0), Vec3::splat(3.0));
    let movers: Vec<Mesh> = (0..3)
        .map(|_| soup(&mut r, 2_000, Vec3::splat(-1.0), Vec3::splat(1.0)))
        .collect();
    let mut meshes = vec![room, statics];
    meshes.extend(movers);
    let channels = vec![
        linear_translation(
            2,
            &[
                (0.0, Vec3::new(-2.0, 0.0, 0.0)),
                (1.0, Vec3::new(2.0, 1.0, 0.0)),
            ],
        ),
        linear_rotation(
            3,
            &[
                (0.0, Quat::IDENTITY),
                (
                    1.0,
                    Quat::from_axis_angle(Vec3::new(1.0, 1.0, 0.0).normalize(), 2.0),
                ),
            ],
        ),
        linear_translation(
            4,
            &[
                (0.0, Vec3::new(0.0, -2.0, 1.0)),
                (1.0, Vec3::new(0.0, 2.0, -1.0)),
            ],
        ),
        linear_rotation(
            4,
            &[(0.0, Quat::IDENTITY), (1.0, Quat::from_rotation_z(3.0))],
        ),
    ];
    scene(
        meshes,
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
        channels,
        Vec3::new(0.0, 0.0, 3.9),
        -Vec3::Z,
        1.0,
        vec![],
    )
}

/// With the CWBVH layout the GPU walks the CPU's tree in the CPU's order
/// with the CPU's arithmetic, so on lavapipe (which, like the CPU, does not
/// fuse multiply-adds) every hit is bit-identical: same triangle, same t,
/// same barycentrics. A real GPU may contract `a·b + c`
/// into an FMA, move a t by an ulp and so resolve an exact tie the other
/// way: there only the general rules of [`check_parity`] apply.
fn cwbvh_is_exact(gpu: &GpuBackend, what: &str, p: &Parity) {
    if gpu.bvh_layout() == GpuLayout::Cwbvh && gpu.is_software() {
        let exact = (p.ties, p.t_not_bitwise, p.max_uv);
        assert_eq!(exact, (0, 0, 0.0), "{what}: {p:?}");
    }
}

fn random_soups_with_moving_objects(layout: GpuLayout) {
    let mut gpu = gpu_with(layout);
    eprintln!("adapter: {}, {layout:?}", gpu.name());
    for seed in 0..2u64 {
        let s = soup_scene(seed);
        let mut cpu = CpuBackend::new();
        for (k, t) in [0.0f32, 0.37, 0.81].into_iter().enumerate() {
            let snap = s.snapshot(t);
            assert!(snap.dynamic_count() > 0 && snap.static_count > 0);
            cpu.set_geometry(&snap);
            gpu.set_geometry(&snap);
            let rays = rays_for(&snap, &cpu, 40_000, seed * 10 + k as u64);
            let what = format!("{layout:?} soup {seed} t={t}");
            let p = check_parity(&what, &cpu, &gpu, &snap, &rays);
            cwbvh_is_exact(&gpu, &what, &p);
        }
    }
    // The static part (same fingerprint across frames of a scene) is
    // uploaded once per scene.
    assert_eq!(gpu.timings().static_uploads, 2, "{:?}", gpu.timings());
}

#[test]
fn gpu_bvh2_matches_cpu_on_random_soups_with_moving_objects() {
    random_soups_with_moving_objects(GpuLayout::Bvh2);
}

#[test]
fn gpu_cwbvh_matches_cpu_on_random_soups_with_moving_objects() {
    random_soups_with_moving_objects(GpuLayout::Cwbvh);
}

/// The built-in scenes are small: those with moving parts are traced
/// through one BVH over all their triangles (`accel::static_part_len`),
/// where the random soups above keep a static and a dynamic part.
fn every_builtin_scene(layout: GpuLayout) {
    let mut gpu = gpu_with(layout);
    let mut total = Parity::default();
    let mut merged_frames = 0;
    for (n, name) in builtin::NAMES.iter().enumerate() {
        let s = Scene::builtin(name).unwrap();
        let mut cpu = CpuBackend::new();
        let times = [
            0.0,
            (s.frame_count / 2) as f32 / radcache::scene::DEFAULT_FPS,
        ];
        for (k, t) in times.into_iter().enumerate() {
            let snap = s.snapshot(t);
            if snap.dynamic_count() > 0 && radcache::accel::static_part_len(&snap) == 0 {
                merged_frames += 1;
            }
            cpu.set_geometry(&snap);
            gpu.set_geometry(&snap);
            let rays = rays_for(&snap, &cpu, 30_000, 100 + (n * 2 + k) as u64);
            let what = format!("{layout:?} {name} t={t}");
            let p = check_parity(&what, &cpu, &gpu, &snap, &rays);
            cwbvh_is_exact(&gpu, &what, &p);
            total.rays += p.rays;
            total.hits += p.hits;
            total.ties += p.ties;
            total.t_not_bitwise += p.t_not_bitwise;
            total.occluded += p.occluded;
            total.max_t_rel = total.max_t_rel.max(p.max_t_rel);
            total.max_uv = total.max_uv.max(p.max_uv);
        }
    }
    eprintln!("{layout:?}, all built-in scenes: {total:?}");
    assert!(
        merged_frames > 0,
        "no built-in frame used the one-BVH layout"
    );
}

#[test]
fn gpu_bvh2_matches_cpu_on_every_builtin_scene() {
    every_builtin_scene(GpuLayout::Bvh2);
}

#[test]
fn gpu_cwbvh_matches_cpu_on_every_builtin_scene() {
    every_builtin_scene(GpuLayout::Cwbvh);
}

/// Rays aimed at the shared edges and vertices of a closed mesh from
/// inside: none leaves it on the GPU either (its triangle test is the
/// CPU's watertight one, its boxes are widened as the CPU's), and as both
/// keep the lower triangle id of two hits at the same t, a software
/// adapter finds the CPU's hits to the bit, ties included, in both layouts.
#[test]
fn gpu_rays_through_shared_edges_never_leave_a_closed_mesh() {
    let snap = common::closed_lumpy_sphere_snapshot();
    let rays = common::rays_at_edges(&snap, 2, 2.0, 6);
    let mut cpu = CpuBackend::new();
    cpu.set_geometry(&snap);
    for layout in GpuLayout::ALL {
        let mut gpu = gpu_with(layout);
        gpu.set_geometry(&snap);
        let what = format!("{layout:?} closed mesh, rays at its edges");
        let p = check_parity(&what, &cpu, &gpu, &snap, &rays);
        assert_eq!(
            (p.hits, p.occluded),
            (rays.len(), rays.len()),
            "{what}: {p:?}"
        );
        if gpu.is_software() {
            assert_eq!(
                (p.ties, p.t_not_bitwise, p.max_uv),
                (0, 0, 0.0),
                "{what}: {p:?}"
            );
        }
    }
}

/// Large batches are cut into chunks; results must land at the right place.
#[test]
fn gpu_batches_larger_than_a_chunk_and_empty_batches() {
    for layout in GpuLayout::ALL {
        batches_larger_than_a_chunk_and_empty_batches(layout);
    }
}

fn batches_larger_than_a_chunk_and_empty_batches(layout: GpuLayout) {
    let mut gpu = gpu_with(layout);
    let s = soup_scene(7);
    let snap = s.snapshot(0.5);
    let mut cpu = CpuBackend::new();
    cpu.set_geometry(&snap);
    gpu.set_geometry(&snap);
    gpu.try_closest_hit(&[], &mut []).unwrap();
    let chunk = gpu.chunk_rays();
    // More than one chunk where that is affordable (lavapipe: 4 Mi rays per
    // chunk is too slow for a test); otherwise many small batches in a row,
    // which exercise the same buffer reuse.
    let n = if chunk <= 1 << 16 {
        2 * chunk + 17
    } else {
        100_003
    };
    let rays = rays_for(&snap, &cpu, n, 999);
    check_parity("large batch", &cpu, &gpu, &snap, &rays);
    for part in rays.chunks(4_099).take(5) {
        check_parity("small batch", &cpu, &gpu, &snap, part);
    }
    let counts = gpu.ray_counts();
    assert_eq!(counts.closest, counts.any);
    assert!(counts.closest >= n as u64);
}

/// Calls from many threads at once (render tiles on every core): each
/// takes a pair of ray buffers of its own from the backend's pool, so the
/// calls are in flight together and each gets its own rays' results,
/// exactly those of one call over all the rays.
#[test]
fn gpu_calls_from_many_threads_get_their_own_results() {
    let mut gpu = gpu();
    let s = soup_scene(3);
    let snap = s.snapshot(0.25);
    let mut cpu = CpuBackend::new();
    cpu.set_geometry(&snap);
    gpu.set_geometry(&snap);
    let rays = rays_for(&snap, &cpu, 40_000, 77);
    let mut one_call = vec![Hit::MISS; rays.len()];
    let mut one_call_occluded = vec![false; rays.len()];
    gpu.closest_hit(&rays, &mut one_call);
    gpu.any_hit(&rays, &mut one_call_occluded);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(8)
        .build()
        .unwrap();
    let mut hits = vec![Hit::MISS; rays.len()];
    let mut occluded = vec![false; rays.len()];
    pool.install(|| {
        use rayon::prelude::*;
        hits.par_chunks_mut(1_000)
            .zip(occluded.par_chunks_mut(1_000))
            .zip(rays.par_chunks(1_000))
            .for_each(|((h, o), r)| gpu.closest_and_any_hit(r, h, r, o));
    });
    assert_eq!(hits, one_call);
    assert_eq!(occluded, one_call_occluded);
    assert!(gpu.ray_counts().calls >= 42, "{:?}", gpu.ray_counts());
}

/// The combined call (a path tracer's bounce with the previous bounce's
/// shadow rays) gives exactly what the two calls give, in one round trip;
/// with one side empty it is the other call alone.
#[test]
fn gpu_closest_and_any_hit_equals_the_two_calls() {
    for layout in GpuLayout::ALL {
        let mut gpu = gpu_with(layout);
        // The start-up probe's calls are not counted.
        assert_eq!(gpu.ray_counts(), RayCounts::default(), "{layout:?}");
        let s = soup_scene(11);
        let snap = s.snapshot(0.25);
        let mut cpu = CpuBackend::new();
        cpu.set_geometry(&snap);
        gpu.set_geometry(&snap);
        let rays = rays_for(&snap, &cpu, 5_000, 21);
        let shadows = rays_for(&snap, &cpu, 3_001, 22);
        let mut hits = vec![Hit::MISS; rays.len()];
        let mut occluded = vec![false; shadows.len()];
        gpu.try_closest_hit(&rays, &mut hits).unwrap();
        gpu.try_any_hit(&shadows, &mut occluded).unwrap();
        assert!(occluded.contains(&true) && occluded.contains(&false));

        let before = gpu.ray_counts();
        let mut both_hits = vec![Hit::MISS; rays.len()];
        let mut both_occluded = vec![true; shadows.len()];
        gpu.closest_and_any_hit(&rays, &mut both_hits, &shadows, &mut both_occluded);
        let after = gpu.ray_counts();
        assert_eq!(gpu.failure(), None, "{layout:?}");
        assert_eq!(both_hits, hits, "{layout:?}: closest hits");
        assert_eq!(both_occluded, occluded, "{layout:?}: any hits");
        assert_eq!(after.calls - before.calls, 1, "{layout:?}: one round trip");
        assert_eq!(after.closest - before.closest, rays.len() as u64);
        assert_eq!(after.any - before.any, shadows.len() as u64);

        // One side empty: the other call alone.
        let mut only_occluded = vec![true; shadows.len()];
        gpu.closest_and_any_hit(&[], &mut [], &shadows, &mut only_occluded);
        assert_eq!(only_occluded, occluded, "{layout:?}: shadows alone");
        let mut only_hits = vec![Hit::MISS; rays.len()];
        gpu.closest_and_any_hit(&rays, &mut only_hits, &[], &mut []);
        assert_eq!(only_hits, hits, "{layout:?}: rays alone");
    }
}

/// A whole path-traced frame: with identical hits the path tracer takes the
/// same decisions, so the frames agree. On a software adapter (which, like
/// the CPU, fuses no multiply-adds) we require bit-identical pixels on all
/// but a handful (a t differing in its last bit may move a hit point by an
/// ulp) and a tight bound on all. A real GPU rounds every hit a little
/// differently (on an H100 about half the pixels differed, by at most
/// 2.1e-5 relative), so there only a path that branched elsewhere may
/// leave the tight bound, on at most 1 % of the pixels.
#[test]
fn gpu_path_traced_frame_equals_cpu_frame() {
    for name in ["cube-in-box", "glossy-cornell"] {
        let render = |backend: Box<dyn RayBackend>| {
            let mut r = Renderer::new(
                Scene::builtin(name).unwrap(),
                Box::new(PathTracer::new(PathSettings {
                    spp: 4,
                    ..PathSettings::default()
                })),
                backend,
                FrameSettings {
                    width: 32,
                    height: 32,
                    ..FrameSettings::default()
                },
            );
            let film = r.render_frame(3);
            (film, r.backend().ray_counts())
        };
        let gpu = gpu();
        let software = gpu.is_software();
        let (cpu_film, cpu_counts) = render(Box::new(CpuBackend::new()));
        let (gpu_film, gpu_counts) = render(Box::new(gpu));
        let (mut differing, mut diverged) = (0, 0);
        let mut max_rel = 0.0f32;
        for (c, g) in cpu_film.pixels.iter().zip(&gpu_film.pixels) {
            if c != g {
                differing += 1;
                let rel = (*c - *g).abs().max_element() / c.max_element().max(1e-3);
                max_rel = max_rel.max(rel);
                diverged += usize::from(rel >= 1e-3);
            }
        }
        let pixels = cpu_film.pixels.len();
        eprintln!(
            "{name}: {differing} of {pixels} pixels differ, {diverged} by 1e-3 or more, \
             max relative difference {max_rel:e}; rays cpu {cpu_counts:?} gpu {gpu_counts:?}"
        );
        assert!(
            diverged <= pixels / 100,
            "{name}: {diverged} pixels differ by 1e-3 or more"
        );
        if software {
            assert!(
                differing <= pixels / 100,
                "{name}: {differing} pixels differ"
            );
            assert!(
                max_rel < 1e-3 || differing <= 2,
                "{name}: max relative difference {max_rel}"
            );
        }
        let (cm, gm) = (cpu_film.mean(), gpu_film.mean());
        assert!((cm - gm).abs() <= 1e-4 * cm, "{name}: mean {cm} vs {gm}");
    }
}

#[test]
fn gpu_backend_names_its_adapter() {
    let gpu = gpu();
    let name = gpu.name();
    assert!(name.starts_with("gpu ("), "{name}");
    assert!(name.contains(&gpu.adapter_info().name), "{name}");
    assert!(gpu.preferred_batch() >= 1 << 20);
}

/// Triangles at exponentially shrinking distances from the origin, each
/// as large as it is far (1.5 times smaller than the one before): the
/// scene looks the same at every scale, so the BVH builder peels them off
/// one by one and the tree is about as deep as there are triangles. (They
/// shrink rather than grow so that all stay within a snapshot's bounds,
/// `scene::MAX_WORLD_COORDINATE`.)
fn exponential_row(n: usize) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..n {
        let x = 1.5f32.powi(-(i as i32));
        let base = m.positions.len() as u32;
        for p in [
            Vec3::new(x, 0.0, 0.0),
            Vec3::new(x, x, 0.0),
            Vec3::new(x, 0.0, x),
        ] {
            m.positions.push(p);
            m.normals.push(Vec3::X);
        }
        m.triangles.push([base, base + 1, base + 2]);
        m.materials.push(0);
    }
    m
}

#[test]
fn a_scene_the_gpu_cannot_take_fails_the_backend_instead_of_panicking() {
    let s = scene(
        vec![exponential_row(100)],
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
        vec![],
        Vec3::new(-1.0, 0.3, 0.3),
        Vec3::X,
        1.0,
        vec![],
    );
    let snapshot = s.snapshot(0.0);
    // BVH2: an 8-wide CWBVH of this row is several times shallower and
    // fits its stack.
    gpu_with(GpuLayout::Cwbvh)
        .try_set_geometry(&snapshot)
        .expect("the CWBVH layout takes the row");
    let mut gpu = gpu_with(GpuLayout::Bvh2);
    let expected = gpu
        .try_set_geometry(&snapshot)
        .expect_err("a BVH deeper than the traversal stack is refused")
        .to_string();
    assert!(expected.contains("depth"), "{expected}");
    assert_eq!(
        gpu.failure(),
        None,
        "try_ methods leave the backend working"
    );

    RayBackend::set_geometry(&mut gpu, &snapshot);
    let failure = gpu.failure().expect("set_geometry failed the backend");
    assert_eq!(failure, expected);
    let rays = [Ray::new(
        Vec3::new(-1.0, 0.3, 0.3),
        Vec3::X,
        0.0,
        f32::INFINITY,
    )];
    let (mut hits, mut occluded) = ([Hit::MISS], [true]);
    gpu.closest_hit(&rays, &mut hits);
    gpu.any_hit(&rays, &mut occluded);
    assert!(
        !hits[0].is_hit() && !occluded[0],
        "a failed backend reports misses"
    );
    assert_eq!(gpu.failure(), Some(expected), "the first error is kept");
}

/// A GPU that does not finish a dispatch within the wait limit (here
/// 1 µs, where tracing these rays takes milliseconds even on a GPU) fails
/// the backend with an error that says so, instead of a render that waits
/// for ever; later calls report misses without waiting. The same rays
/// with the default limit trace.
#[test]
fn a_gpu_that_does_not_answer_in_time_fails_the_backend() {
    let snapshot = soup_scene(0).snapshot(0.3);
    let mut cpu = CpuBackend::new();
    cpu.set_geometry(&snapshot);
    let rays = rays_for(&snapshot, &cpu, 1 << 18, 7);
    let mut hits = vec![Hit::MISS; rays.len()];

    // A thread held off the CPU between its submit and its wait for longer
    // than the dispatch takes finds it done: a few tries.
    let (mut gpu, failure) = (0..5)
        .find_map(|_| {
            let mut gpu = gpu();
            RayBackend::set_geometry(&mut gpu, &snapshot);
            gpu.set_wait_limit(Duration::from_micros(1));
            gpu.closest_hit(&rays, &mut hits);
            let failure = gpu.failure()?;
            Some((gpu, failure))
        })
        .expect("the wait past the limit failed the backend");
    assert!(
        failure.contains("did not finish") && failure.contains("hangs"),
        "{failure}"
    );
    assert!(
        hits.iter().all(|h| !h.is_hit()),
        "a failed call reports misses"
    );
    gpu.set_wait_limit(WAIT_LIMIT);
    let mut occluded = vec![true; rays.len()];
    gpu.any_hit(&rays, &mut occluded);
    assert!(occluded.iter().all(|o| !o), "a failed backend stays failed");
    assert_eq!(gpu.failure(), Some(failure), "the first error is kept");

    let mut patient = self::gpu();
    RayBackend::set_geometry(&mut patient, &snapshot);
    patient.closest_hit(&rays, &mut hits);
    assert_eq!(patient.failure(), None);
    assert!(hits.iter().any(|h| h.is_hit()));
}
