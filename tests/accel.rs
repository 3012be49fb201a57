//! The BVHs and the CPU backend against a brute-force loop over every
//! triangle of the snapshot, with an intersection routine of its own (plane
//! hit + signed-area barycentrics in f64, not `accel::intersect_triangle`).

mod common;

use glam::{DVec3, Quat, Vec3};
use radcache::accel::MERGE_STATIC_TRIANGLES;
use radcache::backend::cpu::CpuBackend;
use radcache::backend::{Hit, Ray, RayBackend};
use radcache::sampling::Rng;
use radcache::scene::animation::{linear_rotation, linear_translation};
use radcache::scene::{Material, Mesh, Scene, Snapshot};

// ---------------------------------------------------------------------------
// Scene generation

fn rand_in(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.next_f32()
}

fn rand_vec(rng: &mut Rng, lo: Vec3, hi: Vec3) -> Vec3 {
    Vec3::new(
        rand_in(rng, lo.x, hi.x),
        rand_in(rng, lo.y, hi.y),
        rand_in(rng, lo.z, hi.z),
    )
}

/// Uniform on the unit sphere.
fn rand_dir(rng: &mut Rng) -> Vec3 {
    let z = rand_in(rng, -1.0, 1.0);
    let phi = rand_in(rng, 0.0, std::f32::consts::TAU);
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

fn push_tri(mesh: &mut Mesh, p: [Vec3; 3]) {
    let base = mesh.positions.len() as u32;
    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
    for q in p {
        mesh.positions.push(q);
        mesh.normals.push(n);
    }
    mesh.triangles.push([base, base + 1, base + 2]);
    mesh.materials.push(0);
}

/// A soup of about `n` triangles in the cube `center ± half`: small and large
/// random triangles, axis-aligned ones (some coplanar on a coarse grid) and
/// bumpy patches / fans whose triangles share edges and vertices.
fn soup(rng: &mut Rng, n: usize, center: Vec3, half: f32) -> Mesh {
    let mut mesh = Mesh::default();
    let lo = center - Vec3::splat(half);
    let hi = center + Vec3::splat(half);
    while mesh.triangles.len() < n {
        let kind = rng.next_u32() % 10;
        let c = rand_vec(rng, lo, hi);
        match kind {
            // Small random triangles.
            0..=3 => {
                let s = rand_in(rng, 0.02, 0.1) * half;
                let p = [0, 1, 2].map(|_| c + rand_vec(rng, -Vec3::splat(s), Vec3::splat(s)));
                push_tri(&mut mesh, p);
            }
            // Large random triangles spanning much of the cube.
            4 => {
                let p = [0, 1, 2].map(|_| rand_vec(rng, lo, hi));
                push_tri(&mut mesh, p);
            }
            // Axis-aligned right triangles; planes snapped to a coarse grid so
            // that some overlap in the same plane (exact ties in t).
            5 | 6 => {
                let axis = (rng.next_u32() % 3) as usize;
                let mut c = c;
                c[axis] = (c[axis] * 2.0).round() / 2.0;
                let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
                let s = rand_in(rng, 0.05, 0.4) * half;
                let mut p1 = c;
                p1[a] += s;
                let mut p2 = c;
                p2[b] += s * rand_in(rng, 0.3, 1.5);
                if rng.next_u32() % 2 == 0 {
                    push_tri(&mut mesh, [c, p1, p2]);
                } else {
                    push_tri(&mut mesh, [c, p2, p1]);
                }
            }
            // A bumpy 4×4-quad patch: 32 triangles sharing edges and vertices.
            7 | 8 => {
                let u = rand_dir(rng) * rand_in(rng, 0.05, 0.15) * half;
                let w = u.cross(rand_dir(rng)).normalize_or_zero() * u.length();
                let nrm = u.cross(w).normalize_or_zero();
                let base = mesh.positions.len() as u32;
                for j in 0..5 {
                    for i in 0..5 {
                        let h = rand_in(rng, -0.3, 0.3) * u.length();
                        mesh.positions
                            .push(c + u * i as f32 + w * j as f32 + nrm * h);
                        mesh.normals.push(nrm);
                    }
                }
                for j in 0..4u32 {
                    for i in 0..4u32 {
                        let a = base + j * 5 + i;
                        let (b, c2, d) = (a + 1, a + 6, a + 5);
                        mesh.triangles.push([a, b, c2]);
                        mesh.triangles.push([a, c2, d]);
                        mesh.materials.extend([0, 0]);
                    }
                }
            }
            // A closed fan around a vertex (shared edges meeting at one point).
            _ => {
                let axis = rand_dir(rng);
                let e1 = axis.any_orthonormal_vector();
                let e2 = axis.cross(e1);
                let r = rand_in(rng, 0.05, 0.2) * half;
                let k = 6;
                let base = mesh.positions.len() as u32;
                mesh.positions.push(c + axis * r * 0.3);
                mesh.normals.push(axis);
                for i in 0..k {
                    let a = i as f32 / k as f32 * std::f32::consts::TAU;
                    mesh.positions.push(c + (e1 * a.cos() + e2 * a.sin()) * r);
                    mesh.normals.push(axis);
                }
                for i in 0..k {
                    mesh.triangles
                        .push([base, base + 1 + i, base + 1 + (i + 1) % k]);
                    mesh.materials.push(0);
                }
            }
        }
    }
    mesh
}

/// One static soup and two dynamic soups animated with translation and
/// rotation channels (key times 0 and 1).
/// A static soup of `statics` triangles in a closed room, with two moving
/// soups of 500 inside.
fn soup_scene(seed: u64, statics: usize) -> Scene {
    let mut rng = Rng::from_seed(seed, 1);
    let mut stat = soup(&mut rng, statics, Vec3::ZERO, 4.0);
    // A closed room around it: large axis-aligned triangles sharing edges
    // (each face's diagonal), and most unbounded rays end on it.
    let room = common::inward_box(Vec3::splat(-5.0), Vec3::splat(5.0), 0);
    let base = stat.positions.len() as u32;
    stat.positions.extend(room.positions);
    stat.normals.extend(room.normals);
    stat.triangles
        .extend(room.triangles.iter().map(|t| t.map(|i| i + base)));
    stat.materials.extend(room.materials);
    // Dynamic meshes are in local space around their node's origin.
    let dyn_a = soup(&mut rng, 500, Vec3::ZERO, 1.5);
    let dyn_b = soup(&mut rng, 500, Vec3::ZERO, 1.0);
    let channels = vec![
        linear_translation(
            1,
            &[
                (0.0, Vec3::new(-2.0, 0.0, 0.0)),
                (1.0, Vec3::new(2.5, 1.0, -1.0)),
            ],
        ),
        linear_rotation(
            1,
            &[
                (0.0, Quat::IDENTITY),
                (
                    1.0,
                    Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 2.5),
                ),
            ],
        ),
        linear_translation(
            2,
            &[
                (0.0, Vec3::new(1.0, -2.0, 2.0)),
                (1.0, Vec3::new(-1.0, 2.5, -2.0)),
            ],
        ),
        linear_rotation(
            2,
            &[
                (0.0, Quat::from_rotation_y(0.7)),
                (1.0, Quat::from_rotation_x(-1.9)),
            ],
        ),
    ];
    common::scene(
        vec![stat, dyn_a, dyn_b],
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
        channels,
        Vec3::new(0.0, 0.0, 10.0),
        -Vec3::Z,
        1.0,
        vec![],
    )
}

// ---------------------------------------------------------------------------
// Independent reference intersection (f64)

fn d(v: Vec3) -> DVec3 {
    v.as_dvec3()
}

/// Intersection of the ray's line with the triangle's plane: `t` and the
/// barycentrics `(b0, b1, b2)` of the plane point, computed from signed
/// areas against the normal (so all ≥ 0 means inside). `None` when the
/// ray is parallel to the plane or the triangle is degenerate.
fn plane_hit(p: &[Vec3; 3], o: DVec3, dir: DVec3) -> Option<(f64, [f64; 3])> {
    let (p0, p1, p2) = (d(p[0]), d(p[1]), d(p[2]));
    let n = (p1 - p0).cross(p2 - p0);
    let nn = n.length_squared();
    let denom = n.dot(dir);
    if nn == 0.0 || denom == 0.0 {
        return None;
    }
    let t = n.dot(p0 - o) / denom;
    let x = o + dir * t;
    let b0 = (p1 - x).cross(p2 - x).dot(n) / nn;
    let b1 = (p2 - x).cross(p0 - x).dot(n) / nn;
    let b2 = (p0 - x).cross(p1 - x).dot(n) / nn;
    Some((t, [b0, b1, b2]))
}

/// A triangle crossed by the ray: its id, `t`, and how deep inside the
/// triangle the crossing is (minimum barycentric; < 0 means outside).
#[derive(Clone, Copy, Debug)]
struct RefHit {
    tri: usize,
    t: f64,
    margin: f64,
}

fn ref_hit(snap: &Snapshot, i: usize, ray: &Ray) -> Option<RefHit> {
    let (t, b) = plane_hit(&snap.triangles[i].p, d(ray.origin()), d(ray.dir()))?;
    Some(RefHit {
        tri: i,
        t,
        margin: b[0].min(b[1]).min(b[2]),
    })
}

/// Brute-force closest hit inside `[tmin, tmax]`.
fn brute_closest(snap: &Snapshot, ray: &Ray) -> Option<RefHit> {
    let (tmin, tmax) = (f64::from(ray.tmin), f64::from(ray.tmax));
    let mut best: Option<RefHit> = None;
    for i in 0..snap.triangles.len() {
        if let Some(h) = ref_hit(snap, i, ray) {
            if h.margin >= 0.0 && h.t >= tmin && h.t <= tmax && best.is_none_or(|b| h.t < b.t) {
                best = Some(h);
            }
        }
    }
    best
}

/// Barycentric margin below which a crossing counts as "on an edge": f32
/// Möller–Trumbore and the f64 reference may then disagree.
const EDGE: f64 = 1e-5;

/// Whether any triangle is crossed within `EDGE` of one of its edges (or of
/// the interval ends) at a `t` no farther than `t_limit`: the only place
/// where a disagreement with the f32 BVH is excused.
fn edge_crossing_before(snap: &Snapshot, ray: &Ray, t_limit: f64) -> Option<RefHit> {
    let (tmin, tmax) = (f64::from(ray.tmin), f64::from(ray.tmax));
    (0..snap.triangles.len())
        .filter_map(|i| ref_hit(snap, i, ray))
        .find(|h| {
            h.margin.abs() <= EDGE
                && h.t >= tmin - 1e-5 * tmin.abs()
                && h.t <= tmax.min(t_limit) * (1.0 + 1e-5)
        })
}

// ---------------------------------------------------------------------------
// Rays

fn bounds(snap: &Snapshot) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for tri in &snap.triangles {
        for p in tri.p {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo, hi)
}

/// Random rays from inside and around `[lo, hi]`: a third unbounded, a third
/// with a finite `tmax`, a third with `tmin > 0` and finite `tmax`; some
/// directions not unit length.
fn random_rays(rng: &mut Rng, lo: Vec3, hi: Vec3, n: usize) -> Vec<Ray> {
    let pad = (hi - lo) * 0.2;
    (0..n)
        .map(|i| {
            let o = rand_vec(rng, lo - pad, hi + pad);
            let mut dir = rand_dir(rng);
            if i % 4 == 1 {
                dir *= rand_in(rng, 0.1, 5.0);
            }
            match i % 3 {
                0 => Ray::new(o, dir, 0.0, f32::INFINITY),
                1 => Ray::new(o, dir, 0.0, rand_in(rng, 0.1, 6.0)),
                _ => {
                    let tmin = rand_in(rng, 0.01, 3.0);
                    Ray::new(o, dir, tmin, tmin + rand_in(rng, 0.1, 6.0))
                }
            }
        })
        .collect()
}

// ---------------------------------------------------------------------------
// Comparison

#[derive(Default, Debug)]
struct Stats {
    rays: usize,
    hits: usize,
    ties: usize,
    edge_excused: usize,
    failures: Vec<String>,
}

fn check_ray(snap: &Snapshot, ray: &Ray, hit: &Hit, occluded: bool, stats: &mut Stats) {
    stats.rays += 1;
    let brute = brute_closest(snap, ray);
    let fail = |stats: &mut Stats, why: String| {
        // A disagreement is excused only if some triangle is crossed on an
        // edge (within EDGE in barycentrics) no farther than the hits at stake.
        let limit = match (brute, hit.is_hit()) {
            (Some(b), true) => b.t.max(f64::from(hit.t)),
            (Some(b), false) => b.t,
            (None, true) => f64::from(hit.t),
            (None, false) => f64::INFINITY,
        };
        if edge_crossing_before(snap, ray, limit * (1.0 + 1e-4)).is_some() {
            stats.edge_excused += 1;
        } else {
            stats.failures.push(format!("{why}; ray {ray:?}"));
        }
    };

    // any_hit agrees with the brute-force closest hit existing.
    if occluded != brute.is_some() {
        fail(stats, format!("any_hit {occluded} vs brute {brute:?}"));
    }

    match (brute, hit.is_hit()) {
        (None, false) => {}
        (Some(b), false) => fail(stats, format!("BVH missed, brute hit {b:?}")),
        (None, true) => fail(stats, format!("BVH hit {hit:?}, brute missed")),
        (Some(b), true) => {
            stats.hits += 1;
            let t = f64::from(hit.t);
            let tri = hit.triangle as usize;
            // t within 1e-4 relative, with an absolute floor in position
            // units of 1e-5·(1 + |origin|): f32 inputs cannot place a hit
            // closer than that, however small t is.
            let dir_len = d(ray.dir()).length();
            let floor = 1e-5 * (1.0 + d(ray.origin()).length()) / dir_len;
            let rel = |a: f64, b: f64| (a - b).abs() <= 1e-4 * b.abs() + floor;
            if tri != b.tri {
                // A near-tie: the BVH's triangle is crossed at (about) the same t.
                let other = ref_hit(snap, tri, ray);
                match other {
                    Some(o) if o.margin >= -EDGE && rel(o.t, b.t) && rel(t, b.t) => stats.ties += 1,
                    _ => {
                        fail(stats, format!("BVH hit {hit:?} ({other:?}), brute {b:?}"));
                        return;
                    }
                }
            } else if !rel(t, b.t) {
                stats
                    .failures
                    .push(format!("t {t} vs brute {} for {hit:?}; ray {ray:?}", b.t));
            }
            if hit.object != snap.tri_object[tri] {
                stats.failures.push(format!(
                    "object {} vs tri_object {}",
                    hit.object, snap.tri_object[tri]
                ));
            }
            // Barycentrics reproduce the hit point.
            let tr = &snap.triangles[tri];
            let (u, v) = (f64::from(hit.u), f64::from(hit.v));
            let on_tri = d(tr.p[0]) * (1.0 - u - v) + d(tr.p[1]) * u + d(tr.p[2]) * v;
            let on_ray = d(ray.origin()) + d(ray.dir()) * t;
            let scale = 1.0 + d(ray.origin()).length() + (d(ray.dir()) * t).length();
            if (on_tri - on_ray).length() > 1e-4 * scale
                || !(-1e-4..=1.0001).contains(&u)
                || !(-1e-4..=1.0001).contains(&v)
                || u + v > 1.0001
            {
                stats.failures.push(format!(
                    "barycentrics ({u}, {v}) give {on_tri} but ray point is {on_ray}"
                ));
            }
        }
    }
}

fn trace(backend: &CpuBackend, rays: &[Ray]) -> (Vec<Hit>, Vec<bool>) {
    let mut hits = vec![Hit::MISS; rays.len()];
    let mut occ = vec![false; rays.len()];
    backend.closest_hit(rays, &mut hits);
    backend.any_hit(rays, &mut occ);
    (hits, occ)
}

// ---------------------------------------------------------------------------
// Tests

/// Both layouts: a static part small enough to share one BVH with the
/// moving soups ([`radcache::accel::MERGE_STATIC_TRIANGLES`]), and one
/// large enough to keep its own, built once.
#[test]
fn bvh_matches_brute_force_on_animated_soup() {
    let mut rng = Rng::from_seed(99, 3);
    let mut total = Stats::default();
    for (statics, split) in [(3000, false), (5000, true)] {
        let scene = soup_scene(7, statics);
        let mut backend = CpuBackend::new();
        for (frame, &time) in [0.0f32, 0.3, 0.75, 1.0, 1.6].iter().enumerate() {
            let snap = scene.snapshot(time);
            assert_eq!(snap.static_count > MERGE_STATIC_TRIANGLES, split);
            assert!(snap.dynamic_count() >= 1000);
            backend.set_geometry(&snap);
            let build = backend.last_build();
            assert_eq!(build.static_build.is_some(), split && frame == 0);
            brute_force_frame(&backend, &snap, &mut rng, &mut total, time);
        }
    }
    for f in total.failures.iter().take(10) {
        eprintln!("{f}");
    }
    assert!(
        total.failures.is_empty(),
        "{} failures",
        total.failures.len()
    );
    // Both hits and misses were exercised.
    assert!(total.hits > total.rays / 5 && total.hits < total.rays * 9 / 10);
    // Edge disagreements (shown to be on an edge above) stay rare.
    assert!(
        total.edge_excused * 10_000 <= total.rays,
        "{} edge disagreements in {} rays",
        total.edge_excused,
        total.rays
    );
}

/// 4000 random rays of one frame against brute force, added to `total`.
fn brute_force_frame(
    backend: &CpuBackend,
    snap: &Snapshot,
    rng: &mut Rng,
    total: &mut Stats,
    time: f32,
) {
    let (lo, hi) = bounds(snap);
    let rays = random_rays(rng, lo, hi, 4000);
    let (hits, occ) = trace(backend, &rays);
    let mut stats = Stats::default();
    for ((ray, hit), &o) in rays.iter().zip(&hits).zip(&occ) {
        check_ray(snap, ray, hit, o, &mut stats);
    }
    eprintln!(
        "t={time}: {} rays, {} hits, {} near-ties, {} excused on edges, {} failures",
        stats.rays,
        stats.hits,
        stats.ties,
        stats.edge_excused,
        stats.failures.len()
    );
    total.rays += stats.rays;
    total.hits += stats.hits;
    total.edge_excused += stats.edge_excused;
    total.failures.extend(stats.failures);
}

/// Rays aimed at dynamic triangles' current centroids hit them, frame after
/// frame, and rays at where they were no longer do.
#[test]
fn dynamic_hits_follow_the_objects() {
    let mut quad_a = Mesh::default();
    common::push_quad(&mut quad_a, Vec3::new(-0.5, -0.5, 0.0), Vec3::X, Vec3::Y, 0);
    let mut quad_b = Mesh::default();
    common::push_quad(
        &mut quad_b,
        Vec3::new(-0.3, 0.0, -0.3),
        Vec3::Z * 0.6,
        Vec3::X * 0.6,
        0,
    );
    let room = common::inward_box(Vec3::splat(-10.0), Vec3::splat(10.0), 0);
    let scene = common::scene(
        vec![room, quad_a, quad_b],
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
        vec![
            linear_translation(
                1,
                &[
                    (0.0, Vec3::new(-5.0, 0.0, 0.0)),
                    (1.0, Vec3::new(5.0, 2.0, 0.0)),
                ],
            ),
            linear_rotation(
                1,
                &[(0.0, Quat::IDENTITY), (1.0, Quat::from_rotation_y(1.2))],
            ),
            linear_translation(
                2,
                &[
                    (0.0, Vec3::new(0.0, -6.0, 3.0)),
                    (1.0, Vec3::new(0.0, 4.0, -3.0)),
                ],
            ),
            linear_rotation(
                2,
                &[
                    (0.0, Quat::from_rotation_x(0.3)),
                    (1.0, Quat::from_rotation_z(-0.8)),
                ],
            ),
        ],
        Vec3::ZERO,
        -Vec3::Z,
        1.0,
        vec![],
    );
    let mut backend = CpuBackend::new();
    let mut previous: Option<Snapshot> = None;
    for time in [0.0f32, 0.25, 0.5, 0.75, 1.0] {
        let snap = scene.snapshot(time);
        assert_eq!(snap.static_count, 12);
        assert_eq!(snap.dynamic_count(), 4);
        backend.set_geometry(&snap);
        // 12 static triangles: one BVH over all, rebuilt every frame.
        assert!(backend.last_build().static_build.is_none(), "t={time}");
        for tri in snap.static_count..snap.triangles.len() {
            let tr = &snap.triangles[tri];
            let c = (tr.p[0] + tr.p[1] + tr.p[2]) / 3.0;
            let n = tr.geometric_normal();
            let ray = Ray::new(c + n * 0.5, -n, 0.0, f32::INFINITY);
            let mut hit = [Hit::MISS];
            backend.closest_hit(&[ray], &mut hit);
            assert_eq!(hit[0].triangle as usize, tri, "t={time}: {hit:?}");
            assert_eq!(hit[0].object, snap.tri_object[tri]);
            assert!((hit[0].t - 0.5).abs() < 1e-4, "{hit:?}");
            let mut occ = [false];
            backend.any_hit(&[Ray::new(c + n * 0.5, -n, 0.0, 0.6)], &mut occ);
            assert!(occ[0]);
            // Where the triangle was one frame ago it is not any more.
            if let Some(prev) = &previous {
                let pt = &prev.triangles[tri];
                let pc = (pt.p[0] + pt.p[1] + pt.p[2]) / 3.0;
                let pn = pt.geometric_normal();
                let old = Ray::new(pc + pn * 0.5, -pn, 0.0, f32::INFINITY);
                backend.closest_hit(&[old], &mut hit);
                assert_ne!(hit[0].triangle as usize, tri, "t={time}: stale hit");
                assert!(hit[0].is_hit(), "the room encloses everything");
                assert!((hit[0].triangle as usize) < snap.static_count || hit[0].t > 0.6);
            }
        }
        previous = Some(snap);
    }
}

/// A static part above the merge limit keeps its own BVH, built once and
/// again only when the static triangles change (another scene).
#[test]
fn a_large_static_part_is_built_once() {
    let (a, b) = (soup_scene(3, 5000), soup_scene(4, 5000));
    let mut backend = CpuBackend::new();
    let mut builds_static = |scene: &Scene, time: f32| {
        backend.set_geometry(&scene.snapshot(time));
        backend.last_build().static_build.is_some()
    };
    assert!(builds_static(&a, 0.0));
    assert!(!builds_static(&a, 0.5));
    assert!(!builds_static(&a, 0.5), "the same time again");
    assert!(builds_static(&b, 0.5), "another scene");
    assert!(!builds_static(&b, 0.9));
    assert!(builds_static(&a, 0.5), "back to the first");
}

impl Stats {
    /// Fails with the first few mismatches against the brute force.
    fn assert_no_failures(&self) {
        assert!(
            self.failures.is_empty(),
            "{:?}",
            &self.failures[..self.failures.len().min(5)]
        );
    }
}

fn check_all_against_brute(scene: &Scene, times: &[f32], rays_per_time: usize) -> Stats {
    let mut backend = CpuBackend::new();
    let mut rng = Rng::from_seed(5, 5);
    let mut stats = Stats::default();
    for &time in times {
        let snap = scene.snapshot(time);
        backend.set_geometry(&snap);
        let (lo, hi) = if snap.triangles.is_empty() {
            (Vec3::splat(-1.0), Vec3::splat(1.0))
        } else {
            bounds(&snap)
        };
        let rays = random_rays(&mut rng, lo, hi, rays_per_time);
        let (hits, occ) = trace(&backend, &rays);
        for ((ray, hit), &o) in rays.iter().zip(&hits).zip(&occ) {
            check_ray(&snap, ray, hit, o, &mut stats);
        }
    }
    stats
}

fn scene_of(meshes: Vec<Mesh>, animate: &[usize]) -> Scene {
    let channels = animate
        .iter()
        .map(|&node| {
            linear_translation(
                node,
                &[(0.0, Vec3::ZERO), (1.0, Vec3::new(1.0, -0.5, 0.25))],
            )
        })
        .collect();
    common::scene(
        meshes,
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
        channels,
        Vec3::new(0.0, 0.0, 10.0),
        -Vec3::Z,
        1.0,
        vec![],
    )
}

#[test]
fn empty_dynamic_part() {
    let mut rng = Rng::from_seed(11, 1);
    let scene = scene_of(vec![soup(&mut rng, 400, Vec3::ZERO, 2.0)], &[]);
    let snap = scene.snapshot(0.0);
    assert_eq!(snap.dynamic_count(), 0);
    let stats = check_all_against_brute(&scene, &[0.0, 0.5], 2000);
    stats.assert_no_failures();
    assert!(stats.hits > 0);
}

#[test]
fn empty_static_part() {
    let mut rng = Rng::from_seed(12, 1);
    let scene = scene_of(
        vec![
            soup(&mut rng, 300, Vec3::ZERO, 2.0),
            soup(&mut rng, 300, Vec3::ONE, 1.0),
        ],
        &[0, 1],
    );
    let snap = scene.snapshot(0.0);
    assert_eq!(snap.static_count, 0);
    assert_eq!(snap.dynamic_count(), snap.triangles.len());
    let stats = check_all_against_brute(&scene, &[0.0, 0.5, 1.0], 2000);
    stats.assert_no_failures();
    assert!(stats.hits > 0);
}

#[test]
fn empty_scene_misses_everything() {
    // No objects at all, and objects whose meshes have no triangles.
    for scene in [
        scene_of(vec![], &[]),
        scene_of(vec![Mesh::default(), Mesh::default()], &[1]),
    ] {
        let mut backend = CpuBackend::new();
        for time in [0.0, 0.5] {
            let snap = scene.snapshot(time);
            assert!(snap.triangles.is_empty());
            backend.set_geometry(&snap);
            let mut rng = Rng::from_seed(1, 1);
            let rays = random_rays(&mut rng, Vec3::splat(-1.0), Vec3::splat(1.0), 500);
            let (hits, occ) = trace(&backend, &rays);
            assert!(hits.iter().all(|h| *h == Hit::MISS));
            assert!(occ.iter().all(|&o| !o));
        }
        // Also an empty batch.
        backend.closest_hit(&[], &mut []);
        backend.any_hit(&[], &mut []);
    }
}

/// The excuse for disagreements is narrow: a ray through the interior of a
/// lone triangle is never excused, and one through a shared edge is.
#[test]
fn edge_excuse_is_only_for_edges() {
    let mut mesh = Mesh::default();
    common::push_quad(
        &mut mesh,
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::X * 2.0,
        Vec3::Y * 2.0,
        0,
    );
    let scene = scene_of(vec![mesh], &[]);
    let snap = scene.snapshot(0.0);
    let inside = Ray::new(Vec3::new(0.5, -0.3, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
    assert!(edge_crossing_before(&snap, &inside, f64::INFINITY).is_none());
    // The quad's diagonal runs from (-1,-1) to (1,1).
    let diagonal = Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
    assert!(edge_crossing_before(&snap, &diagonal, f64::INFINITY).is_some());
    let b = brute_closest(&snap, &diagonal).unwrap();
    assert!((b.t - 1.0).abs() < 1e-12);
}

/// Axis-aligned rays whose zero components are +0.0 or −0.0 (as `-n` gives
/// for an axis-aligned normal `n`): all hit the closed room they start in,
/// and agree with brute force on the soup inside.
#[test]
fn axis_aligned_rays_with_signed_zeros() {
    let scene = soup_scene(21, 3000);
    let snap = scene.snapshot(0.4);
    let mut backend = CpuBackend::new();
    backend.set_geometry(&snap);
    let mut rng = Rng::from_seed(4, 4);
    let mut rays = Vec::new();
    for _ in 0..60 {
        let o = rand_vec(&mut rng, Vec3::splat(-4.9), Vec3::splat(4.9));
        for axis in 0..3 {
            for sign in [1.0f32, -1.0] {
                for zeros in 0..4 {
                    let mut dir = [0.0f32; 3];
                    dir[(axis + 1) % 3] = if zeros & 1 == 0 { 0.0 } else { -0.0 };
                    dir[(axis + 2) % 3] = if zeros & 2 == 0 { 0.0 } else { -0.0 };
                    dir[axis] = sign;
                    rays.push(Ray::new(o, Vec3::from_array(dir), 0.0, f32::INFINITY));
                }
            }
        }
    }
    let (hits, occ) = trace(&backend, &rays);
    assert!(hits.iter().all(|h| h.is_hit()), "a ray escaped the room");
    assert!(occ.iter().all(|&o| o));
    let mut stats = Stats::default();
    for ((ray, hit), &o) in rays.iter().zip(&hits).zip(&occ) {
        check_ray(&snap, ray, hit, o, &mut stats);
    }
    stats.assert_no_failures();
    assert_eq!(stats.edge_excused, 0);
}

/// obvhs 0.4's CWBVH culls every box a ray leaves before t = 1e-4, so a
/// wall met nearer than that was missed (`accel::NEAR_SHIFT`): a gather
/// ray of a record on a room's edge, 4e-5 off the other wall, went through
/// it. Rays and shadow segments leaving the line where a room's ceiling
/// meets a wall, 1e-7 to 1e-3 off that wall and heading into it, hit it
/// (one of its triangles, where the plane is), closest and any hit.
#[test]
fn walls_met_nearer_than_the_traversals_cut_are_hit() {
    let room = common::inward_box(Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 2.0, 1.0), 0);
    let block = common::outward_box(Vec3::splat(-0.2), Vec3::splat(0.2), 0);
    let scene = scene_of(vec![room, block], &[]);
    let snap = scene.snapshot(0.0);
    let mut backend = CpuBackend::new();
    backend.set_geometry(&snap);
    let on_the_wall = |hit: &Hit| {
        snap.triangles[hit.triangle as usize]
            .p
            .iter()
            .all(|p| p.x == -1.0)
    };
    let mut rng = Rng::from_seed(21, 1);
    let mut rays = Vec::new();
    let mut expected = Vec::new();
    for delta in [1e-7f32, 1e-6, 1e-5, 4e-5, 1e-4, 3e-4, 1e-3] {
        for _ in 0..100 {
            let origin = Vec3::new(-1.0 + delta, 2.0 - 3e-4, rand_in(&mut rng, -0.9, 0.9));
            let dir = Vec3::new(
                -rand_in(&mut rng, 0.05, 1.0),
                -rand_in(&mut rng, 0.05, 1.0),
                rand_in(&mut rng, -1.0, 1.0),
            )
            .normalize();
            // The plane x = −1, in f64 from the origin as rounded.
            let t = (f64::from(origin.x) + 1.0) / -f64::from(dir.x);
            rays.push(Ray::new(origin, dir, 0.0, f32::INFINITY));
            expected.push(t);
            rays.push(Ray::segment(origin, origin + dir * (2.0 * t as f32 + 1e-2)));
            expected.push(t / (2.0 * t + 1e-2));
        }
    }
    let (hits, occluded) = trace(&backend, &rays);
    let mut missed = Vec::new();
    for ((ray, hit), (&t, &occ)) in rays.iter().zip(&hits).zip(expected.iter().zip(&occluded)) {
        let tolerance = 1e-4 * t + 1e-6 / f64::from(ray.dir().x.abs());
        if !hit.is_hit() || !on_the_wall(hit) || (f64::from(hit.t) - t).abs() > tolerance || !occ {
            missed.push(format!("{ray:?}: {hit:?}, occluded {occ}, t {t}"));
        }
    }
    assert!(
        missed.is_empty(),
        "{} of {} rays:\n{}",
        missed.len(),
        rays.len(),
        missed[..missed.len().min(5)].join("\n")
    );
}

/// Rays aimed exactly at the shared edges and vertices of a closed mesh
/// from inside it all hit it, in both queries: the triangle test is
/// watertight (Woop et al. 2013) and the box test widened. Möller–Trumbore
/// let 1,332 of these 30,720 rays pass between two triangles; with the
/// watertight test but obvhs's own box test, 6 rays through a vertex on a
/// box's face lost their leaf.
#[test]
fn rays_through_shared_edges_never_leave_a_closed_mesh() {
    let snap = common::closed_lumpy_sphere_snapshot();
    let rays = common::rays_at_edges(&snap, 4, 2.0, 5);
    let mut backend = CpuBackend::new();
    backend.set_geometry(&snap);
    let (hits, occluded) = trace(&backend, &rays);
    let leaks: Vec<String> = rays
        .iter()
        .zip(hits.iter().zip(&occluded))
        .filter(|(_, (h, &o))| !h.is_hit() || !o)
        .map(|(r, (h, o))| format!("{r:?}: {h:?}, occluded {o}"))
        .collect();
    assert!(
        leaks.is_empty(),
        "{} of {} rays left the closed mesh; first: {:?}",
        leaks.len(),
        rays.len(),
        &leaks[..leaks.len().min(5)]
    );
}
