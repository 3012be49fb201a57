//! Ray throughput and BVH build/refit costs (`cargo bench --bench rays`).
//!
//! Scenes (built in code, deterministic):
//! - `spheres`: 100 UV spheres of 988 triangles inside a closed box (98 812
//!   triangles), radius 0.5–1.5, in the box [-10, 10]³;
//! - `soup`: 100 000 random triangles (vertices within ±0.5 of a centre
//!   uniform in [-10, 10]³), like the STACK.md measurement.
//!
//! Rays: 1M incoherent rays, origins uniform in the box, directions uniform
//! on the sphere, traced through `CpuBackend` (the renderer's path) on rayon
//! pools of 1 and 2 threads; best of 3 runs after a warm-up.

#[path = "../tests/common/mod.rs"]
mod common;

use glam::Vec3;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::RayHit;
use obvhs::triangle::Triangle as ObTriangle;
use obvhs::BvhBuildParams;
use radcache::accel::to_obvhs_ray;
use radcache::backend::cpu::CpuBackend;
use radcache::backend::{Hit, Ray, RayBackend};
use radcache::sampling::Rng;
use radcache::scene::animation::linear_translation;
use radcache::scene::{Material, Mesh, Scene};
use rayon::prelude::*;
use std::time::{Duration, Instant};

const HALF: f32 = 10.0;
const RAYS: usize = 1_000_000;

fn rand_in(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.next_f32()
}

fn rand_point(rng: &mut Rng, half: f32) -> Vec3 {
    Vec3::new(
        rand_in(rng, -half, half),
        rand_in(rng, -half, half),
        rand_in(rng, -half, half),
    )
}

fn rand_dir(rng: &mut Rng) -> Vec3 {
    let z = rand_in(rng, -1.0, 1.0);
    let phi = rand_in(rng, 0.0, std::f32::consts::TAU);
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// UV sphere: 2·slices·(stacks−1) triangles (988 for 20 × 26).
fn uv_sphere(center: Vec3, radius: f32) -> Mesh {
    let (stacks, slices) = (20u32, 26u32);
    let mut m = Mesh::default();
    for i in 0..=stacks {
        let theta = std::f32::consts::PI * i as f32 / stacks as f32;
        for j in 0..slices {
            let phi = std::f32::consts::TAU * j as f32 / slices as f32;
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            m.positions.push(center + n * radius);
            m.normals.push(n);
        }
    }
    let idx = |i: u32, j: u32| i * slices + j % slices;
    for i in 0..stacks {
        for j in 0..slices {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            if i != 0 {
                m.triangles.push([a, b, c]);
            }
            if i != stacks - 1 {
                m.triangles.push([a, c, d]);
            }
        }
    }
    m.materials = vec![0; m.triangles.len()];
    m
}

fn sphere_params(n: usize, seed: u64) -> Vec<(Vec3, f32)> {
    let mut rng = Rng::from_seed(seed, 7);
    (0..n)
        .map(|_| {
            let r = rand_in(&mut rng, 0.5, 1.5);
            (rand_point(&mut rng, HALF - r), r)
        })
        .collect()
}

fn make_scene(meshes: Vec<Mesh>, animate: &[usize]) -> Scene {
    let channels = animate
        .iter()
        .map(|&node| {
            linear_translation(node, &[(0.0, Vec3::ZERO), (1.0, Vec3::new(0.3, -0.2, 0.1))])
        })
        .collect();
    common::scene(
        meshes,
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
        channels,
        Vec3::ZERO,
        -Vec3::Z,
        1.0,
        vec![],
    )
}

/// 100 spheres + the closed box, all static.
fn spheres_scene() -> Scene {
    let mut meshes = vec![common::inward_box(Vec3::splat(-HALF), Vec3::splat(HALF), 0)];
    meshes.extend(
        sphere_params(100, 1)
            .into_iter()
            .map(|(c, r)| uv_sphere(c, r)),
    );
    make_scene(meshes, &[])
}

fn soup_scene() -> Scene {
    let mut rng = Rng::from_seed(2, 7);
    let mut m = Mesh::default();
    for t in 0..100_000u32 {
        let c = rand_point(&mut rng, HALF - 0.5);
        for _ in 0..3 {
            m.positions.push(c + rand_point(&mut rng, 0.5));
            m.normals.push(Vec3::Y);
        }
        m.triangles.push([3 * t, 3 * t + 1, 3 * t + 2]);
        m.materials.push(0);
    }
    make_scene(vec![m], &[])
}

/// Box static, `spheres` dynamic spheres (each its own animated object).
fn dynamic_scene(spheres: usize) -> Scene {
    let mut meshes = vec![common::inward_box(Vec3::splat(-HALF), Vec3::splat(HALF), 0)];
    meshes.extend(
        sphere_params(spheres, 3)
            .into_iter()
            .map(|(c, r)| uv_sphere(c, r)),
    );
    let animated: Vec<usize> = (1..=spheres).collect();
    make_scene(meshes, &animated)
}

fn random_rays(n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::from_seed(seed, 11);
    (0..n)
        .map(|_| {
            let o = rand_point(&mut rng, HALF * 0.999);
            Ray::new(o, rand_dir(&mut rng), 0.0, f32::INFINITY)
        })
        .collect()
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
}

/// Warm-up, then the best of 3 runs.
fn best_of_3(mut f: impl FnMut()) -> Duration {
    f();
    (0..3)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed()
        })
        .min()
        .unwrap()
}

fn mrays(n: usize, d: Duration) -> f64 {
    n as f64 / d.as_secs_f64() / 1e6
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// The renderer's traversal (`CpuBackend`: the watertight triangle test
/// and widened boxes) and, for its cost, obvhs's own: `CwBvh::ray_traverse`
/// over the same tree shape with obvhs's Möller–Trumbore test.
fn throughput(name: &str, scene: &Scene, rays: &[Ray]) {
    let snap = scene.snapshot(0.0);
    let mut backend = CpuBackend::new();
    backend.set_geometry(&snap);
    let tris: Vec<ObTriangle> = snap.triangles.iter().map(|t| to_ob(t.p)).collect();
    let obvhs_tree = build_cwbvh_from_tris(
        &tris,
        BvhBuildParams::medium_build(),
        &mut Duration::default(),
    );
    let tree_tris: Vec<ObTriangle> = obvhs_tree
        .primitive_indices
        .iter()
        .map(|&i| tris[i as usize])
        .collect();
    let mut hits = vec![Hit::MISS; rays.len()];
    let mut occ = vec![false; rays.len()];
    for threads in [1, 2] {
        let p = pool(threads);
        let closest = best_of_3(|| p.install(|| backend.closest_hit(rays, &mut hits)));
        let any = best_of_3(|| p.install(|| backend.any_hit(rays, &mut occ)));
        let obvhs = best_of_3(|| {
            p.install(|| trace_cwbvh(&obvhs_tree, &tree_tris, rays));
        });
        let hit_frac = hits.iter().filter(|h| h.is_hit()).count() as f64 / rays.len() as f64;
        let occ_frac = occ.iter().filter(|&&o| o).count() as f64 / rays.len() as f64;
        println!(
            "| {name:<8} | {:>7} | {threads} | {:>13.2} | {:>9.2} | {:>5.1}% / {:>5.1}% | {:>11.2} |",
            snap.triangles.len(),
            mrays(rays.len(), closest),
            mrays(rays.len(), any),
            100.0 * hit_frac,
            100.0 * occ_frac,
            mrays(rays.len(), obvhs),
        );
    }
}

fn static_build(name: &str, scene: &Scene) {
    let snap = scene.snapshot(0.0);
    for threads in [1, 2] {
        let p = pool(threads);
        let best = (0..4)
            .map(|_| {
                let mut backend = CpuBackend::new();
                p.install(|| backend.set_geometry(&snap));
                backend.last_build().static_build.expect("static build")
            })
            .skip(1)
            .min()
            .unwrap();
        println!(
            "| static {name:<8} | {:>7} | {threads} | {:>8.1} |",
            snap.static_count,
            ms(best)
        );
    }
}

fn dynamic_rebuild(spheres: usize) {
    let scene = dynamic_scene(spheres);
    for threads in [1, 2] {
        let p = pool(threads);
        let mut backend = CpuBackend::new();
        let mut count = 0;
        let best = (0..5)
            .map(|i| {
                let snap = scene.snapshot(i as f32 * 0.1);
                count = snap.dynamic_count();
                p.install(|| backend.set_geometry(&snap));
                backend.last_build().dynamic_build
            })
            .skip(1)
            .min()
            .unwrap();
        println!(
            "| dynamic ({spheres:>3} spheres) | {count:>7} | {threads} | {:>8.1} |",
            ms(best)
        );
    }
}

// --------------------------------------------------------------------------
// Refit vs rebuild (obvhs BVH2), measured outside CpuBackend.

fn to_ob(p: [Vec3; 3]) -> ObTriangle {
    ObTriangle {
        v0: p[0].into(),
        v1: p[1].into(),
        v2: p[2].into(),
    }
}

/// The preset `accel::TriangleBvh::build` uses for the moving part of
/// this size, rebuilt every frame.
fn preset(n: usize) -> BvhBuildParams {
    radcache::accel::BvhLife::Frame.params(n)
}

/// Refits `bvh` to `tris` (input order): leaf boxes from their triangles,
/// then `Bvh2::refit_all` for the inner nodes. Returns the triangles in BVH
/// order, for traversal.
fn refit(bvh: &mut Bvh2, tris: &[ObTriangle]) -> Vec<ObTriangle> {
    let ordered: Vec<ObTriangle> = bvh
        .primitive_indices
        .iter()
        .map(|&i| tris[i as usize])
        .collect();
    for node in bvh.nodes.iter_mut() {
        if node.is_leaf() {
            let first = node.first_index as usize;
            let mut aabb = Aabb::empty();
            for tri in &ordered[first..first + node.prim_count as usize] {
                aabb = aabb.union(&tri.aabb());
            }
            node.set_aabb(aabb);
        }
    }
    bvh.refit_all();
    ordered
}

fn trace_bvh2(bvh: &Bvh2, tris: &[ObTriangle], rays: &[Ray]) -> (Duration, usize) {
    let start = Instant::now();
    let hits = rays
        .par_iter()
        .with_min_len(256)
        .filter(|ray| {
            let mut hit = RayHit::none();
            bvh.ray_traverse(to_obvhs_ray(ray), &mut hit, |r, i| tris[i].intersect(r))
        })
        .count();
    (start.elapsed(), hits)
}

fn trace_cwbvh(bvh: &CwBvh, tris: &[ObTriangle], rays: &[Ray]) -> (Duration, usize) {
    let start = Instant::now();
    let hits = rays
        .par_iter()
        .with_min_len(256)
        .filter(|ray| {
            let mut hit = RayHit::none();
            bvh.ray_traverse(to_obvhs_ray(ray), &mut hit, |r, i| tris[i].intersect(r))
        })
        .count();
    (start.elapsed(), hits)
}

fn best_timed<T>(mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut best = None;
    let mut out = None;
    for _ in 0..3 {
        let start = Instant::now();
        let r = f();
        let d = start.elapsed();
        if best.is_none_or(|b| d < b) {
            best = Some(d);
        }
        out = Some(r);
    }
    (best.unwrap(), out.unwrap())
}

/// Spheres moving from their rest positions: `motion(i)` is sphere i's
/// displacement. Compares, on 2 threads: BVH2 refit (built at rest) vs BVH2
/// rebuild vs the CWBVH rebuild the renderer does.
fn refit_vs_rebuild(label: &str, spheres: usize, motion: impl Fn(usize, f32) -> Vec3) {
    let params = sphere_params(spheres, 3);
    let tris_at = |moved: bool| -> Vec<ObTriangle> {
        let mut out = Vec::new();
        for (i, &(c, r)) in params.iter().enumerate() {
            let offset = if moved { motion(i, r) } else { Vec3::ZERO };
            let m = uv_sphere(c + offset, r);
            for t in &m.triangles {
                out.push(to_ob(t.map(|k| m.positions[k as usize])));
            }
        }
        out
    };
    let rest = tris_at(false);
    let moved = tris_at(true);
    let n = rest.len();
    let rays = random_rays(250_000, 5);
    let p = pool(2);
    p.install(|| {
        let base = build_bvh2_from_tris(&rest, preset(n), &mut Duration::default());
        // Refit: each timed run starts from the rest-pose BVH (clone untimed).
        let mut refitted = base.clone();
        let mut ordered_refit = Vec::new();
        let mut refit_time = Duration::MAX;
        for _ in 0..3 {
            let mut b = base.clone();
            let start = Instant::now();
            let ordered = refit(&mut b, &moved);
            refit_time = refit_time.min(start.elapsed());
            refitted = b;
            ordered_refit = ordered;
        }
        let (rebuild_time, rebuilt) =
            best_timed(|| build_bvh2_from_tris(&moved, preset(n), &mut Duration::default()));
        let ordered_rebuilt: Vec<ObTriangle> = rebuilt
            .primitive_indices
            .iter()
            .map(|&i| moved[i as usize])
            .collect();
        let (cw_time, cw) =
            best_timed(|| build_cwbvh_from_tris(&moved, preset(n), &mut Duration::default()));
        let ordered_cw: Vec<ObTriangle> = cw
            .primitive_indices
            .iter()
            .map(|&i| moved[i as usize])
            .collect();

        let trace_best = |f: &dyn Fn() -> (Duration, usize)| {
            f();
            let mut best = (Duration::MAX, 0);
            for _ in 0..3 {
                let r = f();
                if r.0 < best.0 {
                    best = r;
                }
            }
            best
        };
        let (t_refit, h_refit) = trace_best(&|| trace_bvh2(&refitted, &ordered_refit, &rays));
        let (t_rebuilt, h_rebuilt) =
            trace_best(&|| trace_bvh2(&rebuilt, &ordered_rebuilt, &rays));
        let (t_cw, h_cw) = trace_best(&|| trace_cwbvh(&cw, &ordered_cw, &rays));
        assert_eq!(h_refit, h_rebuilt, "refitted and rebuilt BVH2 disagree");
        assert_eq!(h_refit, h_cw, "BVH2 and CWBVH disagree");
        println!(
            "| {label:<34} | {n:>6} | {:>9.2} | {:>10.2} | {:>10.2} | {:>10.2} | {:>10.2} | {:>10.2} |",
            ms(refit_time),
            ms(rebuild_time),
            ms(cw_time),
            mrays(rays.len(), t_refit),
            mrays(rays.len(), t_rebuilt),
            mrays(rays.len(), t_cw),
        );
    });
}

fn main() {
    // `cargo bench` passes `--bench`; ignore arguments.
    let total = Instant::now();
    let spheres = spheres_scene();
    let soup = soup_scene();
    let rays = random_rays(RAYS, 1);

    println!("\n## Ray throughput, CpuBackend, {RAYS} incoherent rays (Mrays/s, best of 3)\n");
    println!(
        "| scene    | tris    | T | closest (Mr/s) | any (Mr/s) | hit / occluded  | obvhs's own closest (Mr/s) |"
    );
    println!(
        "|----------|---------|---|---------------:|-----------:|-----------------|------------:|"
    );
    throughput("spheres", &spheres, &rays);
    throughput("soup", &soup, &rays);

    println!("\n## BVH build through CpuBackend::set_geometry (ms, best of 3)\n");
    println!("| part                  | tris    | T | build ms |");
    println!("|-----------------------|---------|---|---------:|");
    static_build("spheres", &spheres);
    static_build("soup", &soup);
    for n in [1, 10, 100] {
        dynamic_rebuild(n);
    }

    println!(
        "\n## Dynamic part: BVH2 refit vs rebuild (2 threads; traversal: 250k incoherent \
         closest-hit rays, Mrays/s)\n"
    );
    println!(
        "| motion (from rest pose)            | tris   | refit ms  | BVH2 rebuild | CWBVH build | \
         BVH2 refit Mr/s | BVH2 rebuilt Mr/s | CWBVH rebuilt Mr/s |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    let dir = |i: usize| {
        let mut rng = Rng::from_seed(i as u64, 77);
        rand_dir(&mut rng)
    };
    for spheres in [10, 100] {
        refit_vs_rebuild(
            &format!("{spheres} spheres: each 0.5 r own dir"),
            spheres,
            |i, r| dir(i) * 0.5 * r,
        );
        refit_vs_rebuild(
            &format!("{spheres} spheres: each 5 r own dir"),
            spheres,
            |i, r| dir(i) * 5.0 * r,
        );
        refit_vs_rebuild(
            &format!("{spheres} spheres: all +3 in x (rigid)"),
            spheres,
            |_, _| Vec3::new(3.0, 0.0, 0.0),
        );
        refit_vs_rebuild(
            &format!("{spheres} spheres: one crosses box"),
            spheres,
            |i, _| {
                if i == 0 {
                    Vec3::new(12.0, 3.0, -4.0)
                } else {
                    Vec3::ZERO
                }
            },
        );
    }
    println!(
        "\n(total bench time {:.1} s)",
        total.elapsed().as_secs_f64()
    );
}
