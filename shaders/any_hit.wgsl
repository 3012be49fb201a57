// Stage "any hit": for each ray of the chunk, 1 when any triangle of the
// dynamic or the static BVH intersects it in [tmin, tmax), else 0.
// Prepended with `ray_common.wgsl` and a traversal (`bvh2_traverse.wgsl`
// or `cwbvh_traverse.wgsl`) by `src/backend/gpu.rs`.

@group(0) @binding(4) var<storage, read_write> occluded: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn any_hit(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = ray_index(id);
    if i == NONE {
        return;
    }
    let ray = rays[i];
    let r = trace_ray(ray);
    // Dynamic parts are usually small: test them first (as the CPU does).
    var best = Hit(ray.tmax + NEAR_SHIFT, NONE, NONE, 0.0, 0.0);
    let hit = traverse(params.dynamic_root, r, &best, true)
        || traverse(params.static_root, r, &best, true);
    occluded[i] = select(0u, 1u, hit);
}
