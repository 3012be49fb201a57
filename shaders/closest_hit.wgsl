// Stage "closest hit": for each ray of the chunk, the nearest triangle in
// [tmin, tmax) over the static then the dynamic BVH, or a miss.
// Prepended with `ray_common.wgsl` and a traversal (`bvh2_traverse.wgsl`
// or `cwbvh_traverse.wgsl`) by `src/backend/gpu.rs`.

@group(0) @binding(4) var<storage, read_write> hits: array<Hit>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn closest_hit(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = ray_index(id);
    if i == NONE {
        return;
    }
    let ray = rays[i];
    let r = trace_ray(ray);
    // `best.t` is the shrinking tmax shared by both BVHs, as on the CPU,
    // in the traversal's `t` (NEAR_SHIFT added) until the end.
    var best = Hit(ray.tmax + NEAR_SHIFT, NONE, NONE, 0.0, 0.0);
    traverse(params.static_root, r, &best, false);
    traverse(params.dynamic_root, r, &best, false);
    if best.triangle == NONE {
        best = Hit(infinity(), NONE, NONE, 0.0, 0.0);
    } else {
        best.t -= NEAR_SHIFT;
    }
    hits[i] = best;
}
