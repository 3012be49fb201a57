// BVH2 traversal shared by the ray stages of the GPU backend
// (`src/backend/gpu.rs`). Not a pipeline by itself: the Rust side prepends
// this file to `closest_hit.wgsl` and `any_hit.wgsl` (WGSL has no includes),
// after `ray_common.wgsl`.
//
// It mirrors, step for step, what the CPU backend does (`src/accel.rs` and
// obvhs 0.4 `Bvh2::ray_traverse_dynamic`) so that both find the same hits:
// the same ray-box slab test on `safe_inverse(dir)`, the nearer child first,
// the same watertight triangle test, the same strict `t < tmax` rules (a
// tie going to the lower triangle id), the static BVH before the dynamic
// one with one shrinking `tmax`.

/// Entries of the per-ray traversal stack. Must match `STACK_SIZE` in
/// `src/backend/gpu_bvh.rs`, which refuses BVHs deeper than this (a BVH2 of
/// depth d needs at most d entries). obvhs's PLOC builds of millions of
/// triangles stay well under it.
const STACK_SIZE: u32 = 64u;

/// Relative widening of every ray-box interval: 2γ₃ (γₙ = nε/(1−nε),
/// ε = 2⁻²⁴; pbrt-v4 §6.8.2). The CPU's compressed wide BVH rounds its boxes
/// outward; our exact BVH2 boxes are flat for axis-aligned walls, where a
/// rounding error in the slab test could otherwise cull a triangle the CPU
/// hits. Widening only ever visits more nodes, it never changes a hit.
const BOX_SLACK: f32 = 3.58e-7;

/// obvhs `Bvh2Node` with vec4-sized fields (48 bytes). Field order must
/// match `GpuNode` in `src/backend/gpu_bvh.rs`. Inner node: `prim_count == 0`,
/// children at `first_index` and `first_index + 1`. Leaf: triangles
/// `first_index .. first_index + prim_count` of `triangles`.
struct Node {
    aabb_min: vec3<f32>,
    _pad0: u32,
    aabb_max: vec3<f32>,
    _pad1: u32,
    prim_count: u32,
    first_index: u32,
    _pad2: u32,
    _pad3: u32,
}

@group(0) @binding(2) var<storage, read> nodes: array<Node>;

fn trace_ray(ray: Ray) -> TraceRay {
    let inv = vec3<f32>(safe_inverse(ray.dir.x), safe_inverse(ray.dir.y), safe_inverse(ray.dir.z));
    return prepare_ray(shifted_origin(ray, ray.dir), ray.dir, inv, ray.tmin + NEAR_SHIFT);
}

/// obvhs `Aabb::intersect_ray`: entry distance of the ray into the box, or
/// +∞ when it misses (the interval is widened by BOX_SLACK).
fn intersect_box(node: Node, ray: TraceRay) -> f32 {
    let t1 = (node.aabb_min - ray.origin) * ray.inv_dir;
    let t2 = (node.aabb_max - ray.origin) * ray.inv_dir;
    let lo = min(t1, t2);
    let hi = max(t1, t2);
    var t_near = max(max(lo.x, lo.y), lo.z);
    var t_far = min(min(hi.x, hi.y), hi.z);
    t_near = t_near - abs(t_near) * BOX_SLACK;
    t_far = t_far + abs(t_far) * BOX_SLACK;
    if t_far >= t_near && t_far >= 0.0 {
        return t_near;
    }
    return infinity();
}

/// Triangles of the leaf hit closer than `best.t` (strictly, as the CPU;
/// as near and of a lower id also, `is_better`):
/// updates `best` with the nearest. With `any`, stops at the first one.
/// Returns whether there was one.
fn leaf_hits(node: Node, ray: TraceRay, best: ptr<function, Hit>, any: bool) -> bool {
    var found = false;
    for (var i = node.first_index; i < node.first_index + node.prim_count; i++) {
        let tri = triangles[i];
        let h = intersect_triangle(tri, ray, (*best).t);
        if is_better(h, tri.id, *best) {
            *best = Hit(h.x, tri.id, tri.object, h.y, h.z);
            found = true;
            if any {
                return true;
            }
        }
    }
    return found;
}

/// Hits in the BVH rooted at `root` closer than `best.t`, shrinking
/// `best` to the nearest: obvhs `Bvh2::ray_traverse_dynamic` with
/// `ray_traverse`'s leaf test. With `any` it returns at the first hit
/// (obvhs `Bvh2::ray_traverse_miss`, negated). Returns whether there was a
/// hit. One loop for both queries: `any` is uniform across a dispatch, so
/// its branches cost nothing in divergence.
fn traverse(root: u32, ray: TraceRay, best: ptr<function, Hit>, any: bool) -> bool {
    if root == NONE {
        return false;
    }
    let root_node = nodes[root];
    if !(intersect_box(root_node, ray) < (*best).t) {
        return false;
    }
    if root_node.prim_count > 0u {
        return leaf_hits(root_node, ray, best, any);
    }
    var found = false;
    var stack: array<u32, STACK_SIZE>;
    var sp = 0u;
    var current = root_node.first_index;
    loop {
        var near = nodes[current];
        var far = nodes[current + 1u];
        var t_near = intersect_box(near, ray);
        var t_far = intersect_box(far, ray);
        if t_near > t_far {
            let n = near;
            near = far;
            far = n;
            let t = t_near;
            t_near = t_far;
            t_far = t;
        }
        var go_near = t_near < (*best).t;
        if go_near && near.prim_count > 0u {
            if leaf_hits(near, ray, best, any) {
                found = true;
                if any {
                    return true;
                }
            }
            go_near = false;
        }
        // After the near leaf: `best.t` may have shrunk.
        var go_far = t_far < (*best).t;
        if go_far && far.prim_count > 0u {
            if leaf_hits(far, ray, best, any) {
                found = true;
                if any {
                    return true;
                }
            }
            go_far = false;
        }
        if go_near && go_far {
            current = near.first_index;
            stack[sp] = far.first_index;
            sp += 1u;
        } else if go_near {
            current = near.first_index;
        } else if go_far {
            current = far.first_index;
        } else {
            if sp == 0u {
                break;
            }
            sp -= 1u;
            current = stack[sp];
        }
    }
    return found;
}
