// Compressed wide BVH (CWBVH: Ylitie, Karras & Laine 2017, "Efficient
// Incoherent Ray Traversal on GPUs Using Compressed Wide BVHs") traversal
// for the ray stages of the GPU backend (`src/backend/gpu.rs`). Not a
// pipeline by itself: the Rust side concatenates `ray_common.wgsl`, this
// file and a stage (`closest_hit.wgsl`, `any_hit.wgsl`).
//
// It is the same BVH the CPU backend traverses (obvhs 0.4
// `build_cwbvh_from_tris`, nodes uploaded byte for byte) and mirrors, step
// for step, obvhs's CPU loop (`CwBvh::ray_traverse` / `ray_traverse_miss`,
// `traverse!` and `CwBvhNode::intersect_ray`): the same node groups and
// triangle groups as hit masks, the same octant-ordered children, the same
// quantised slab test with its 1e-4 near cut, the same watertight triangle
// test and strict `t < tmax` rules (a tie going to the lower triangle id);
// so it visits triangles in the CPU's order and finds the same hits, ties
// included.

/// Entries of the per-ray stack of node groups. Must match
/// `CWBVH_STACK_SIZE` in `src/backend/gpu_bvh.rs`, which refuses deeper
/// BVHs (at most one group per level is pending). obvhs uses 32 too: its
/// 8-wide trees are shallow.
const STACK_SIZE: u32 = 32u;

/// obvhs `cwbvh::node::EPSILON`: the CPU culls every child box the ray
/// leaves before this distance (`tmin.max(EPSILON)` in `intersect_ray`).
/// Mirrored so that the GPU visits every box the CPU visits (and, with
/// BOX_SLACK, a few more); rays start NEAR_SHIFT behind their origin on
/// both, so it culls none they meet in their range.
const NEAR_CULL: f32 = 0.0001;

/// Relative widening of the child intervals: 2γ₃ (pbrt-v4 §6.8.2). A
/// driver may fuse the slab's multiply and add (the CPU does not); the
/// widening keeps every child the CPU visits visited. Visiting more never
/// changes a hit.
const BOX_SLACK: f32 = 3.58e-7;

/// obvhs `CwBvhNode` as it is in memory (80 bytes, repr(C)); WGSL has no
/// u8, so the byte arrays are read as words, lowest byte first.
struct Node {
    /// Origin of the child grid (node box min).
    p: vec3<f32>,
    /// Bytes: e[0], e[1], e[2] (exponents of the grid scale per axis),
    /// imask (bit s: child slot s is an inner node).
    e_imask: u32,
    /// Index of the first inner child; inner children are contiguous.
    child_base: u32,
    /// Index of the first triangle of the leaf children.
    primitive_base: u32,
    /// child_meta[0..8]: leaf: unary triangle count in bits 5..8, offset
    /// from `primitive_base` in bits 0..5; inner: 001 then slot + 24;
    /// empty: 0.
    child_meta: vec2<u32>,
    /// child_min_x[0..8] (words 0, 1), child_max_x[0..8] (words 2, 3).
    qx: vec4<u32>,
    qy: vec4<u32>,
    qz: vec4<u32>,
}

@group(0) @binding(2) var<storage, read> nodes: array<Node>;

/// As the CPU's `to_obvhs_ray`: −0 direction components become +0 (the
/// CPU adds 0.0), so that the octant, the slab order and 1/dir agree; the
/// origin moved back by NEAR_SHIFT.
fn trace_ray(ray: Ray) -> TraceRay {
    let dir = select(ray.dir, vec3<f32>(0.0), ray.dir == vec3<f32>(0.0));
    let inv = vec3<f32>(safe_inverse(dir.x), safe_inverse(dir.y), safe_inverse(dir.z));
    return prepare_ray(shifted_origin(ray, dir), dir, inv, ray.tmin + NEAR_SHIFT);
}

/// obvhs `ray_get_octant_inv4`: 7 − octant of the direction, in every byte.
/// XORed with a child slot it gives the slot's rank in traversal order.
fn octant_inv4(dir: vec3<f32>) -> u32 {
    return select(0x04040404u, 0u, dir.x < 0.0) | select(0x02020202u, 0u, dir.y < 0.0)
        | select(0x01010101u, 0u, dir.z < 0.0);
}

/// Byte `i` (0..8) of an 8-byte array stored in two words.
fn byte_of(lo: u32, hi: u32, i: u32) -> u32 {
    return extractBits(select(lo, hi, i >= 4u), (i & 3u) * 8u, 8u);
}

/// obvhs `CwBvhNode::intersect_ray`: the hit mask of the node's children
/// whose box the ray crosses in [NEAR_CULL, tmax]. Bits 24..32: inner
/// children, at their traversal rank (slot ^ octant) + 24; bits 0..24:
/// the triangles of leaf children (unary count shifted by their offset).
fn intersect_children(node: Node, ray: TraceRay, oct_inv4: u32, tmax: f32) -> u32 {
    let e = vec3<u32>(node.e_imask & 0xffu, (node.e_imask >> 8u) & 0xffu, (node.e_imask >> 16u) & 0xffu);
    // The grid scale 2^(e − 127) per axis, folded into the ray.
    let extent = bitcast<vec3<f32>>(e << vec3<u32>(23u));
    let adj_inv = extent * ray.inv_dir;
    let adj_origin = (node.p - ray.origin) * ray.inv_dir;
    let negative = ray.dir < vec3<f32>(0.0);
    var mask = 0u;
    for (var c = 0u; c < 8u; c++) {
        let meta_byte = byte_of(node.child_meta.x, node.child_meta.y, c);
        // An empty slot adds no bit: skip its box.
        if meta_byte == 0u {
            continue;
        }
        let lo = vec3<f32>(
            f32(byte_of(node.qx.x, node.qx.y, c)),
            f32(byte_of(node.qy.x, node.qy.y, c)),
            f32(byte_of(node.qz.x, node.qz.y, c)),
        );
        let hi = vec3<f32>(
            f32(byte_of(node.qx.z, node.qx.w, c)),
            f32(byte_of(node.qy.z, node.qy.w, c)),
            f32(byte_of(node.qz.z, node.qz.w, c)),
        );
        let t_lo = select(lo, hi, negative) * adj_inv + adj_origin;
        let t_hi = select(hi, lo, negative) * adj_inv + adj_origin;
        var t_near = max(t_lo.x, max(t_lo.y, t_lo.z));
        var t_far = min(t_hi.x, min(t_hi.y, t_hi.z));
        t_near = max(t_near - abs(t_near) * BOX_SLACK, NEAR_CULL);
        t_far = min(t_far + abs(t_far) * BOX_SLACK, tmax);
        if t_near <= t_far {
            // obvhs `get_child_and_index_bits`, one byte at a time: meta
            // bits 3 and 4 both set only for inner children (slot + 24).
            let inner = (meta_byte & 0x18u) == 0x18u;
            let bit_index = (meta_byte ^ select(0u, oct_inv4 & 0xffu, inner)) & 0x1fu;
            mask |= ((meta_byte >> 5u) & 7u) << bit_index;
        }
    }
    return mask;
}

/// Hits in the CWBVH rooted at `root` closer than `best.t`, shrinking
/// `best` to the nearest: obvhs `traverse!` as `CwBvh::ray_traverse` runs
/// it. With `any` it returns at the first hit (`ray_traverse_miss`,
/// negated). Returns whether there was a hit.
///
/// State, as in the paper: `node_group` = (first inner child, bits 24..32:
/// children still to visit by rank, bits 0..8: the node's imask);
/// `tri_group` = (first triangle, bits: triangles still to test).
fn traverse(root: u32, ray: TraceRay, best: ptr<function, Hit>, any: bool) -> bool {
    if root == NONE {
        return false;
    }
    let oct_inv4 = octant_inv4(ray.dir);
    var stack: array<vec2<u32>, STACK_SIZE>;
    var sp = 0u;
    var found = false;
    // A group holding only the root (rank 7 at relative index 0).
    var node_group = vec2<u32>(root, 0x80000000u);
    var tri_group = vec2<u32>(0u, 0u);
    loop {
        // Highest bit first, as the CPU: the same order, the same ties.
        while tri_group.y != 0u {
            let bit = firstLeadingBit(tri_group.y);
            tri_group.y &= ~(1u << bit);
            let tri = triangles[tri_group.x + bit];
            let h = intersect_triangle(tri, ray, (*best).t);
            if is_better(h, tri.id, *best) {
                *best = Hit(h.x, tri.id, tri.object, h.y, h.z);
                found = true;
                if any {
                    return true;
                }
            }
        }
        if (node_group.y & 0xff000000u) != 0u {
            let hits_imask = node_group.y;
            let rank_bit = firstLeadingBit(hits_imask);
            node_group.y &= ~(1u << rank_bit);
            if (node_group.y & 0xff000000u) != 0u {
                stack[sp] = node_group;
                sp += 1u;
            }
            // Rank back to slot; inner children are stored in slot order,
            // so the child's index is the count of inner slots below it.
            let slot = (rank_bit - 24u) ^ (oct_inv4 & 0xffu);
            let relative = countOneBits(hits_imask & ~(0xffffffffu << slot));
            let node = nodes[node_group.x + relative];
            let hitmask = intersect_children(node, ray, oct_inv4, (*best).t);
            node_group = vec2<u32>(node.child_base, (hitmask & 0xff000000u) | (node.e_imask >> 24u));
            tri_group = vec2<u32>(node.primitive_base, hitmask & 0x00ffffffu);
        } else {
            node_group = vec2<u32>(0u, 0u);
        }
        if tri_group.y == 0u && (node_group.y & 0xff000000u) == 0u {
            if sp == 0u {
                break;
            }
            sp -= 1u;
            node_group = stack[sp];
        }
    }
    return found;
}
