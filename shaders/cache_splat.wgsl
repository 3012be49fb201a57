// Pass "splat records": the render pass's irradiance-cache interpolation
// (TRC Eq. 1–4) for a batch of lookups, each the shading point and normal of
// a pixel sample. Driven by `src/backend/gpu/cache_splat.rs`, which
// explains how this maps to the paper's radiance cache splatting (TRC §5)
// and why the records are binned into a grid first (WGSL has no float
// atomics).
//
// Each work item is one lookup. It visits the records binned into its grid
// cell and applies exactly the CPU's tests (`IrradianceCache::
// interpolate_marking` in `src/cache/mod.rs`): p inside the record's sphere
// of influence (the octree's test), w ≥ 1/a (Eq. 3), not in front of p,
// w capped at WEIGHT_CAP; then sums w·E_K(p) (Eq. 4) and w (Eq. 1).

/// Work items per workgroup. Must match `SPLAT_WORKGROUP_SIZE` in
/// `src/backend/gpu/cache_splat.rs`; 64 as the ray stages use.
const WORKGROUP_SIZE: u32 = 64u;

/// A lookup outside the grid lies in no sphere of influence.
const NONE: u32 = 0xffffffffu;

/// `params.flags` bit: extrapolate with the gradients (Eq. 4).
const FLAG_GRADIENTS: u32 = 1u;
/// `params.flags` bit: set the used bit of every usable record.
const FLAG_MARK: u32 = 2u;

/// Weight of a record exactly at p (w = ∞): it alone decides. Must match
/// `WEIGHT_CAP` in `src/cache/record.rs`.
const WEIGHT_CAP: f32 = 1e6;

/// `IrradianceRecord::is_in_front_of`'s tolerance, relative to R_K.
const FRONT_TOLERANCE: f32 = 0.01;
const FRAC_1_SQRT_2: f32 = 0.70710677;

/// Parameters of one dispatch. Field order must match `SplatParams` in
/// `src/backend/gpu/cache_splat.rs`.
struct Params {
    /// Lookups in this chunk.
    lookup_count: u32,
    /// Work items per row of the 2D dispatch.
    row_width: u32,
    /// FLAG_GRADIENTS | FLAG_MARK.
    flags: u32,
    _pad0: u32,
    /// Corner of the grid's first cell.
    grid_min: vec3<f32>,
    /// 1/a: a record is usable where w ≥ this (Eq. 3).
    threshold: f32,
    /// 1 / cell size, per axis.
    inv_cell: vec3<f32>,
    _pad1: f32,
    /// Cells per axis.
    dims: vec3<u32>,
    _pad2: u32,
}

/// One record (144 bytes). Field order must match `GpuRecord` in
/// `src/backend/gpu/cache_splat.rs`.
struct Record {
    position: vec3<f32>,
    /// Radius of the sphere of influence, a·R_K, computed on the CPU so that
    /// the containment test sees the octree's exact value.
    influence: f32,
    normal: vec3<f32>,
    /// Harmonic mean distance R_K.
    radius: f32,
    irradiance: vec3<f32>,
    _pad: f32,
    /// Translation gradient ∇p per colour channel (xyz; w unused).
    grad_translation: array<vec4<f32>, 3>,
    /// Rotation gradient ∇r per colour channel (xyz; w unused).
    grad_rotation: array<vec4<f32>, 3>,
}

/// A shading point to interpolate at (32 bytes). Field order must match
/// `GpuLookup` in `src/backend/gpu/cache_splat.rs`.
struct Lookup {
    position: vec3<f32>,
    /// R_p, the point's own harmonic distance estimate (`LookupPoint::radius`).
    radius: f32,
    normal: vec3<f32>,
    _pad: f32,
}

/// The sums of one lookup (32 bytes). Field order must match `GpuSplat` in
/// `src/backend/gpu/cache_splat.rs`.
struct Splat {
    /// Σ w_K·E_K(p).
    sum: vec3<f32>,
    /// Σ w_K.
    weights: f32,
    /// Records used.
    count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> records: array<Record>;
/// Records of cell c: `cell_records[cell_start[c] .. cell_start[c + 1]]`.
@group(0) @binding(2) var<storage, read> cell_start: array<u32>;
@group(0) @binding(3) var<storage, read> cell_records: array<u32>;
@group(0) @binding(4) var<storage, read> lookups: array<Lookup>;
@group(0) @binding(5) var<storage, read_write> splats: array<Splat>;
/// One bit per record: used by some lookup of the dispatch (`trc` keeps
/// the records that contributed to a frame). An OR is order-free, so the
/// integer atomics WGSL has are enough here.
@group(0) @binding(6) var<storage, read_write> used: array<atomic<u32>>;

/// The grid cell holding p, or NONE outside the grid.
fn cell_of(p: vec3<f32>) -> u32 {
    let c = floor((p - params.grid_min) * params.inv_cell);
    let dims = vec3<f32>(params.dims);
    if any(c < vec3<f32>(0.0)) || any(c >= dims) {
        return NONE;
    }
    let i = vec3<u32>(c);
    return (i.z * params.dims.y + i.y) * params.dims.x + i.x;
}

/// Eq. 4: E_K(p) = E_K + (n_K × n)·∇r + (p − p_K)·∇p, never negative
/// (`IrradianceRecord::extrapolate`).
fn extrapolate(r: Record, p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    if (params.flags & FLAG_GRADIENTS) == 0u {
        return r.irradiance;
    }
    let rotation = cross(r.normal, n);
    let translation = p - r.position;
    let delta = vec3<f32>(
        dot(rotation, r.grad_rotation[0].xyz) + dot(translation, r.grad_translation[0].xyz),
        dot(rotation, r.grad_rotation[1].xyz) + dot(translation, r.grad_translation[1].xyz),
        dot(rotation, r.grad_rotation[2].xyz) + dot(translation, r.grad_translation[2].xyz),
    );
    return max(r.irradiance + delta, vec3<f32>(0.0));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn splat_records(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.y * params.row_width + id.x;
    if i >= params.lookup_count {
        return;
    }
    let p = lookups[i].position;
    let n = lookups[i].normal;
    let r_p = lookups[i].radius;
    var out = Splat(vec3<f32>(0.0), 0.0, 0u, 0u, 0u, 0u);
    let cell = cell_of(p);
    if cell != NONE {
        let end = cell_start[cell + 1u];
        for (var j = cell_start[cell]; j < end; j = j + 1u) {
            let k = cell_records[j];
            // The octree's test: p inside the sphere of influence. Only the
            // record's first 16 bytes are read for it; most binned records
            // fail it.
            let d = p - records[k].position;
            let influence = records[k].influence;
            if dot(d, d) > influence * influence {
                continue;
            }
            let r = records[k];
            // Eq. 2: w = 1/(‖p − p_K‖/R_K + √(1 − n·n_K)); ∞ at p_K itself;
            // R_K no larger than p's own R_p (`IrradianceRecord::weight`).
            let reach = min(r.radius, r_p);
            // √(1 − n·n_K) as ‖n − n_K‖/√2, free of cancellation (see there).
            let denom = length(d) / reach + length(n - r.normal) * FRAC_1_SQRT_2;
            var w = WEIGHT_CAP;
            if denom > 0.0 {
                w = 1.0 / denom;
                // Eq. 3: usable where w ≥ 1/a.
                if !(w >= params.threshold) {
                    continue;
                }
            }
            // Ward's "in front" test: the record sees another environment.
            if dot(d, 0.5 * (n + r.normal)) < -FRONT_TOLERANCE * r.radius {
                continue;
            }
            if (params.flags & FLAG_MARK) != 0u {
                atomicOr(&used[k >> 5u], 1u << (k & 31u));
            }
            w = min(w, WEIGHT_CAP);
            out.sum = out.sum + extrapolate(r, p, n) * w;
            out.weights = out.weights + w;
            out.count = out.count + 1u;
        }
    }
    splats[i] = out;
}
