// What both BVH traversals of the GPU backend (`src/backend/gpu.rs`)
// share: the dispatch parameters, rays, triangles, hits, their bindings and
// the ray-triangle test. Not a pipeline by itself: the Rust side
// concatenates this file, one traversal (`bvh2_traverse.wgsl` or
// `cwbvh_traverse.wgsl`) and one stage (`closest_hit.wgsl`, `any_hit.wgsl`),
// as WGSL has no includes. Each traversal declares binding 2 (its nodes),
// `trace_ray` and `traverse(root, ray, best, any)`.
//
// The triangle test, the strict `t < tmax` rules and the tie rule are
// those of the CPU backend (`src/accel.rs`), so that both find the same
// hits.

/// Work items per workgroup. Must match `WORKGROUP_SIZE` in
/// `src/backend/gpu.rs`. 64 fills a warp/wavefront twice over on real GPUs
/// and is well under lavapipe's 1024 invocations per workgroup.
const WORKGROUP_SIZE: u32 = 64u;

/// "No node / no triangle": the root of an empty BVH, the id of a miss.
const NONE: u32 = 0xffffffffu;

/// `f32::EPSILON` (2⁻²³): obvhs `safe_inverse` treats direction components
/// at most this small as ±EPSILON, so that 1/dir stays finite.
const F32_EPSILON: f32 = 1.1920929e-7;

/// Parameters of one dispatch (one chunk of rays).
/// Field order must match `GpuParams` in `src/backend/gpu.rs`.
struct Params {
    /// Rays in this chunk.
    ray_count: u32,
    /// Work items per row of the 2D dispatch (workgroups in x × WORKGROUP_SIZE).
    row_width: u32,
    /// Root node of the static BVH, or NONE when there are no static triangles.
    static_root: u32,
    /// Root node of the dynamic BVH, or NONE.
    dynamic_root: u32,
}

/// A ray as the methods build it. Field order must match `Ray` in
/// `src/backend/mod.rs` (32 bytes: vec3 + f32 pack into 16).
struct Ray {
    origin: vec3<f32>,
    tmin: f32,
    dir: vec3<f32>,
    tmax: f32,
}

/// A triangle in BVH leaf order with the ids the hit reports (48 bytes).
/// Field order must match `GpuTriangle` in `src/backend/gpu.rs`.
struct Triangle {
    v0: vec3<f32>,
    /// Snapshot triangle id.
    id: u32,
    v1: vec3<f32>,
    /// Object id.
    object: u32,
    v2: vec3<f32>,
    _pad: u32,
}

/// Closest hit. Field order must match `Hit` in `src/backend/mod.rs`
/// (20 bytes, array stride 20).
struct Hit {
    t: f32,
    triangle: u32,
    object: u32,
    u: f32,
    v: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> rays: array<Ray>;
@group(0) @binding(3) var<storage, read> triangles: array<Triangle>;
// Binding 2 (the nodes) is declared by each traversal, binding 4 (the
// results) by each stage.

/// A ray prepared for traversal, as obvhs `Ray::new` prepares it, and for
/// the watertight triangle test as `accel::ShearedRay` prepares it.
struct TraceRay {
    origin: vec3<f32>,
    dir: vec3<f32>,
    inv_dir: vec3<f32>,
    tmin: f32,
    /// kx, ky, kz: the axes of the ray's space (kz: the largest component).
    axes: vec3<u32>,
    /// Sx, Sy, Sz of the shear.
    shear: vec3<f32>,
}

/// A TraceRay from its origin, direction and tmin, with the shear of
/// `accel::ShearedRay::new`: the same axes on ties, the same divisions.
fn prepare_ray(origin: vec3<f32>, dir: vec3<f32>, inv_dir: vec3<f32>, tmin: f32) -> TraceRay {
    let a = abs(dir);
    var kz = 2u;
    if a.x >= a.y && a.x >= a.z {
        kz = 0u;
    } else if a.y >= a.z {
        kz = 1u;
    }
    var kx = (kz + 1u) % 3u;
    var ky = (kz + 2u) % 3u;
    if dir[kz] < 0.0 {
        let k = kx;
        kx = ky;
        ky = k;
    }
    let shear = vec3<f32>(dir[kx] / dir[kz], dir[ky] / dir[kz], 1.0 / dir[kz]);
    return TraceRay(origin, dir, inv_dir, tmin, vec3<u32>(kx, ky, kz), shear);
}

/// `accel::NEAR_SHIFT`: traversal starts a ray this far (in its `t` units)
/// behind its origin, with `tmin` and `tmax` moved along, and a hit's `t`
/// is given back less it. Why: obvhs's CWBVH culls every box a ray leaves
/// before t = 1e-4 (`NEAR_CULL` in `cwbvh_traverse.wgsl` mirrors it), which
/// missed walls met nearer than that; both GPU layouts shift as the CPU
/// does, so that they find the CPU's hits.
const NEAR_SHIFT: f32 = 2e-4;

/// `ray`'s origin moved back by NEAR_SHIFT along `dir` (its direction as
/// the traversal takes it), as `accel::to_obvhs_ray` computes it.
fn shifted_origin(ray: Ray, dir: vec3<f32>) -> vec3<f32> {
    return ray.origin - dir * NEAR_SHIFT;
}

/// obvhs `safe_inverse`: 1/x, or ±1/EPSILON (sign of x, −0 counts as
/// negative like Rust's `signum`) when |x| ≤ EPSILON.
fn safe_inverse(x: f32) -> f32 {
    if abs(x) <= F32_EPSILON {
        let negative = (bitcast<u32>(x) & 0x80000000u) != 0u;
        return select(1.0, -1.0, negative) / F32_EPSILON;
    }
    return 1.0 / x;
}

/// +∞, written to `Hit::t` on a miss (`Hit::MISS`).
fn infinity() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

/// `(x, y, z)` of vertex `v` in the ray's space: moved to the ray's
/// origin, its axes permuted and sheared (`accel::ShearedRay::intersect`).
fn to_ray_space(v: vec3<f32>, ray: TraceRay) -> vec3<f32> {
    let p = v - ray.origin;
    let pz = p[ray.axes.z];
    return vec3<f32>(p[ray.axes.x] - ray.shear.x * pz, p[ray.axes.y] - ray.shear.y * pz, ray.shear.z * pz);
}

/// The watertight test of Woop, Benthin & Wald (JCGT 2013) as
/// `accel::ShearedRay::intersect` computes it: returns (t, u, v) with the
/// hit at `v0·(1−u−v) + v1·u + v2·v`, or t = +∞ when the ray misses the
/// triangle or t falls outside [tmin, tmax]. Rays in the triangle's plane
/// never hit.
fn intersect_triangle(tri: Triangle, ray: TraceRay, tmax: f32) -> vec3<f32> {
    let miss = vec3<f32>(infinity(), 0.0, 0.0);
    let a = to_ray_space(tri.v0, ray);
    let b = to_ray_space(tri.v1, ray);
    let c = to_ray_space(tri.v2, ray);
    let u = c.x * b.y - c.y * b.x;
    let v = a.x * c.y - a.y * c.x;
    let w = b.x * a.y - b.y * a.x;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return miss;
    }
    let det = u + v + w;
    if det == 0.0 {
        return miss;
    }
    let inv_det = 1.0 / det;
    let t = (u * a.z + v * b.z + w * c.z) * inv_det;
    if t >= ray.tmin && t <= tmax {
        return vec3<f32>(t, v * inv_det, w * inv_det);
    }
    return miss;
}

/// Whether hit `h` (t, u, v) on triangle `id` takes the place of `best`:
/// nearer, or as near and of a lower triangle id (a ray through an edge
/// hits both triangles; the CPU keeps the lower id too).
fn is_better(h: vec3<f32>, id: u32, best: Hit) -> bool {
    return h.x < best.t || (h.x == best.t && best.triangle != NONE && id < best.triangle);
}

/// Index of the ray this work item traces in a 2D dispatch, or NONE past
/// the end of the chunk.
fn ray_index(id: vec3<u32>) -> u32 {
    let i = id.y * params.row_width + id.x;
    return select(NONE, i, i < params.ray_count);
}
