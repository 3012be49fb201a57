//! Pass "splat records": the render pass's irradiance-cache interpolation
//! (TRC Eq. 1–4) on the GPU, for `ic`, `trc` and `tcg` when the ray backend
//! is the GPU one. WGSL in `shaders/cache_splat.wgsl`.
//!
//! # How this is the paper's radiance cache splatting (TRC §5)
//! TRC §5 (after Gautron et al. 2005) observes that a record K cannot
//! contribute outside its sphere of influence (centre `p_K`, radius `a·R_K`
//! where `w_K ≥ 1/a`), so the indirect light of the visible points is
//! obtained by *splatting* each record's sphere on the image: a quad tightly
//! bounding the sphere is rasterized, a fragment program evaluates `w_K` at
//! each covered pixel's visible point and rejects the pixel where K may not
//! contribute (Eq. 3), and additive blending accumulates `w_K·E_K(p)` and
//! `w_K`, whose quotient is Eq. 1.
//!
//! Here the visible points are the pixel samples' shading points and
//! normals that the CPU render tile computed (a G-buffer of *lookups*,
//! [`GpuLookup`]). The accumulation is the part that cannot be copied
//! as is: a compute shader has no blending, and WGSL has no float atomics,
//! so records cannot add into the pixels they cover in parallel (an
//! `atomicCompareExchangeWeak` loop on bit-cast floats would work, but it
//! serialises on contended pixels and makes the sums depend on scheduling).
//! So the splat is turned around by **binning**, as tiled splatting
//! renderers do:
//! 1. *bin* ([`SplatGrid::new`], on the CPU: a few thousand records per
//!    frame, linear time): each record is "rasterized" into the cells of a
//!    uniform 3D grid that its sphere of influence overlaps — the 3D
//!    analogue of the paper's bounding quad, independent of the camera;
//! 2. *splat* (the shader, one work item per lookup): each lookup walks the
//!    records of its cell in record order and evaluates exactly the CPU's
//!    tests of [`crate::cache::IrradianceCache::interpolate_marking`] —
//!    inside the sphere, `w ≥ 1/a`, not in front, `w` capped at
//!    [`WEIGHT_CAP`](crate::cache::WEIGHT_CAP),
//!    gradients when enabled — summing `w·E_K(p)` and `w` in registers (the
//!    blending), with no atomics and a deterministic order.
//!
//! The records a lookup uses are flagged in a bitset with `atomicOr`
//! (integer atomics exist, and an OR does not depend on order): `trc`'s
//! replacement/deletion rule of §5 needs "did K contribute to any pixel",
//! which the paper reads from occlusion queries.
//!
//! The only difference from the CPU is the summation order (octree order
//! there, record order here) and the GPU's own rounding of the same f32
//! operations, so the interpolated irradiance agrees to a few f32 ulps
//! (`tests/gpu_cache.rs` checks ≤ 1e-4 relative) and the usable set is the
//! same except where a weight sits within rounding of `1/a`.
//!
//! Buffers are kept by [`CacheSplat`] and reused across dispatches and
//! frames; they only grow. Records and grid are uploaded once per render
//! pass ([`CacheSplat::prepare`]); lookups per render tile.

use super::{
    bind, layout_entry, read_back, storage_entry, workgroup_grid, ComputePass, ErrorSlot,
    FailureSlot, GpuError, Submitted,
};
use crate::cache::{Interpolated, IrradianceRecord, LookupPoint};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Work items per workgroup. Must match `WORKGROUP_SIZE` in
/// `shaders/cache_splat.wgsl`.
pub const SPLAT_WORKGROUP_SIZE: u32 = 64;

/// Most cells of the grid: 4 MiB of cell starts, enough for cells about
/// as wide as a typical sphere of influence in any scene we render.
const MAX_CELLS: usize = 1 << 20;

/// Most cells per axis: keeps a flat or thin scene from getting a grid
/// that is almost all empty cells along its long axis.
const MAX_CELLS_PER_AXIS: usize = 512;

/// Most (cell, record) entries per record on average: a few huge records
/// (open space, the 64-pixel spacing limit) among small ones would
/// otherwise fill thousands of small cells each; the cells grow instead.
const MAX_ENTRIES_PER_RECORD: usize = 64;

/// A lookup outside the grid (`NONE` in the shader).
const NONE: u32 = u32::MAX;

/// `flags` bit: extrapolate with the gradients (`FLAG_GRADIENTS`).
const FLAG_GRADIENTS: u32 = 1;
/// `flags` bit: flag the used records (`FLAG_MARK`).
const FLAG_MARK: u32 = 2;

/// A record as the shader reads it (144 bytes). Field order must match
/// `Record` in `shaders/cache_splat.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuRecord {
    pub position: [f32; 3],
    /// `a·R_K`, the octree's radius, computed here so both sides test the
    /// same f32.
    pub influence: f32,
    pub normal: [f32; 3],
    pub radius: f32,
    pub irradiance: [f32; 3],
    pub _pad: f32,
    /// ∇p per channel (xyz; w unused).
    pub grad_translation: [[f32; 4]; 3],
    /// ∇r per channel (xyz; w unused).
    pub grad_rotation: [[f32; 4]; 3],
}

/// A shading point to interpolate at (32 bytes). Field order must match
/// `Lookup` in `shaders/cache_splat.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuLookup {
    pub position: [f32; 3],
    /// [`LookupPoint::radius`].
    pub radius: f32,
    pub normal: [f32; 3],
    pub _pad: f32,
}

impl GpuLookup {
    pub fn new(at: &LookupPoint) -> Self {
        GpuLookup {
            position: at.position.to_array(),
            radius: at.radius(),
            normal: at.normal.to_array(),
            _pad: 0.0,
        }
    }
}

/// The sums of one lookup (32 bytes). Field order must match `Splat` in
/// `shaders/cache_splat.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuSplat {
    /// `Σ w_K·E_K(p)`.
    pub sum: [f32; 3],
    /// `Σ w_K`.
    pub weights: f32,
    /// Records used.
    pub count: u32,
    pub _pad: [u32; 3],
}

impl GpuSplat {
    /// TRC Eq. 1, as [`crate::cache::IrradianceCache::interpolate`] returns
    /// it: `None` where no record is usable.
    pub fn interpolated(&self) -> Option<Interpolated> {
        (self.count > 0).then(|| Interpolated {
            irradiance: Vec3::from_array(self.sum) / self.weights,
            records: self.count,
        })
    }
}

/// Parameters of one dispatch. Field order must match `Params` in
/// `shaders/cache_splat.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
struct SplatParams {
    lookup_count: u32,
    row_width: u32,
    flags: u32,
    _pad0: u32,
    grid_min: [f32; 3],
    threshold: f32,
    inv_cell: [f32; 3],
    _pad1: f32,
    dims: [u32; 3],
    _pad2: u32,
}

impl SplatParams {
    /// The parameters of a dispatch of `lookup_count` lookups over
    /// `prepared`'s grid, `groups_x` workgroups a row; `mark`: set the used
    /// bits of the records used.
    fn new(prepared: &PreparedCache, lookup_count: u32, groups_x: u32, mark: bool) -> Self {
        let grid = &prepared.grid;
        let mut flags = 0;
        if prepared.gradients {
            flags |= FLAG_GRADIENTS;
        }
        if mark {
            flags |= FLAG_MARK;
        }
        SplatParams {
            lookup_count,
            row_width: groups_x * SPLAT_WORKGROUP_SIZE,
            flags,
            grid_min: grid.grid_min.to_array(),
            threshold: grid.threshold,
            inv_cell: [1.0 / grid.cell; 3],
            dims: grid.dims,
            ..SplatParams::default()
        }
    }
}

const _: () = assert!(std::mem::size_of::<GpuRecord>() == 144);
const _: () = assert!(std::mem::size_of::<GpuLookup>() == 32);
const _: () = assert!(std::mem::size_of::<GpuSplat>() == 32);
const _: () = assert!(std::mem::size_of::<SplatParams>() == 64);

const RECORD_BYTES: u64 = std::mem::size_of::<GpuRecord>() as u64;
const LOOKUP_BYTES: u64 = std::mem::size_of::<GpuLookup>() as u64;
const SPLAT_BYTES: u64 = std::mem::size_of::<GpuSplat>() as u64;

/// The records of one cache binned into a uniform grid over their spheres
/// of influence (the "bin" step; see the module comment). Cell `c` lists
/// `cell_records[cell_start[c]..cell_start[c + 1]]`, in record order: every
/// record whose sphere overlaps the cell.
#[derive(Clone, Debug)]
pub struct SplatGrid {
    records: Vec<GpuRecord>,
    cell_start: Vec<u32>,
    cell_records: Vec<u32>,
    grid_min: Vec3,
    cell: f32,
    dims: [u32; 3],
    /// `1/a` (Eq. 3).
    threshold: f32,
}

impl SplatGrid {
    /// Bins `records` of a cache of accuracy `accuracy`.
    pub fn new(records: &[IrradianceRecord], accuracy: f32) -> Self {
        let spheres: Vec<(Vec3, f32)> = records
            .iter()
            .map(|r| (r.position, r.influence_radius(accuracy)))
            .collect();
        let (grid_min, cell, dims) = grid_shape(&spheres);
        let mut grid = SplatGrid {
            records: records.iter().map(|r| gpu_record(r, accuracy)).collect(),
            cell_start: Vec::new(),
            cell_records: Vec::new(),
            grid_min,
            cell,
            dims,
            threshold: 1.0 / accuracy,
        };
        grid.bin(&spheres);
        grid
    }

    pub fn len(&self) -> usize {
        self.records.len()
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Cells per axis.
    pub fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// (cell, record) entries: the work of the splat is about this times
    /// the lookups per cell.
    pub fn entries(&self) -> usize {
        self.cell_records.len()
    }

    /// The records binned in the cell holding `p` (what the shader walks):
    /// a superset of the records whose sphere of influence holds `p`.
    pub fn candidates(&self, p: Vec3) -> &[u32] {
        match self.cell_of(p) {
            NONE => &[],
            c => {
                let c = c as usize;
                &self.cell_records[self.cell_start[c] as usize..self.cell_start[c + 1] as usize]
            }
        }
    }

    /// The cell holding `p`, or `NONE`: the same arithmetic as `cell_of`
    /// in the shader.
    fn cell_of(&self, p: Vec3) -> u32 {
        let c = ((p - self.grid_min) * (1.0 / self.cell)).floor();
        let dims = Vec3::new(
            self.dims[0] as f32,
            self.dims[1] as f32,
            self.dims[2] as f32,
        );
        if c.cmplt(Vec3::ZERO).any() || c.cmpge(dims).any() {
            return NONE;
        }
        let [x, y, z] = [c.x as u32, c.y as u32, c.z as u32];
        (z * self.dims[1] + y) * self.dims[0] + x
    }

    /// Integer cell coordinates of `p`, clamped into the grid.
    fn clamped_cell(&self, p: Vec3) -> [usize; 3] {
        let c = ((p - self.grid_min) * (1.0 / self.cell)).floor();
        let clamp = |v: f32, d: u32| (v.max(0.0) as usize).min(d as usize - 1);
        [
            clamp(c.x, self.dims[0]),
            clamp(c.y, self.dims[1]),
            clamp(c.z, self.dims[2]),
        ]
    }

    /// Fills the cell lists (counting pass, prefix sum, filling pass). A
    /// record goes into every cell of its sphere's bounding box that the
    /// sphere (grown by `slack`) touches; `slack` covers rounding between
    /// the CPU's and the GPU's cell of a point on a cell boundary.
    fn bin(&mut self, spheres: &[(Vec3, f32)]) {
        let cells = self.dims.iter().map(|&d| d as usize).product::<usize>();
        let slack = self.slack(spheres);
        let mut counts = vec![0u32; cells + 1];
        self.for_each_cell_of(spheres, slack, |cell, _| counts[cell + 1] += 1);
        for c in 1..=cells {
            counts[c] += counts[c - 1];
        }
        let mut next = counts.clone();
        let mut cell_records = vec![0u32; counts[cells] as usize];
        self.for_each_cell_of(spheres, slack, |cell, k| {
            cell_records[next[cell] as usize] = k;
            next[cell] += 1;
        });
        self.cell_start = counts;
        self.cell_records = cell_records;
    }

    /// A thousandth of a cell plus a few ulps of the largest coordinate.
    fn slack(&self, spheres: &[(Vec3, f32)]) -> f32 {
        let largest = spheres
            .iter()
            .map(|(c, r)| c.abs().max_element() + r)
            .fold(0.0f32, f32::max);
        1e-3 * self.cell + 1e-5 * largest
    }

    /// Calls `visit(cell, record)` for every cell each sphere touches, in
    /// record order.
    fn for_each_cell_of(
        &self,
        spheres: &[(Vec3, f32)],
        slack: f32,
        mut visit: impl FnMut(usize, u32),
    ) {
        let [dx, dy, _] = self.dims.map(|d| d as usize);
        for (k, &(centre, radius)) in spheres.iter().enumerate() {
            let r = radius + slack;
            let lo = self.clamped_cell(centre - Vec3::splat(r));
            let hi = self.clamped_cell(centre + Vec3::splat(r));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let box_min =
                            self.grid_min + Vec3::new(x as f32, y as f32, z as f32) * self.cell;
                        let nearest = centre.clamp(box_min, box_min + Vec3::splat(self.cell));
                        if (nearest - centre).length_squared() <= r * r {
                            visit((z * dy + y) * dx + x, k as u32);
                        }
                    }
                }
            }
        }
    }
}

/// The record as the shader reads it.
fn gpu_record(r: &IrradianceRecord, accuracy: f32) -> GpuRecord {
    let row = |v: Vec3| [v.x, v.y, v.z, 0.0];
    GpuRecord {
        position: r.position.to_array(),
        influence: r.influence_radius(accuracy),
        normal: r.normal.to_array(),
        radius: r.radius,
        irradiance: r.irradiance.to_array(),
        _pad: 0.0,
        grad_translation: r.grad_translation.map(row),
        grad_rotation: r.grad_rotation.map(row),
    }
}

/// Corner, cell size and cells per axis of a grid over `spheres`: cells
/// as wide as the median sphere, grown until the grid fits [`MAX_CELLS`],
/// [`MAX_CELLS_PER_AXIS`] and [`MAX_ENTRIES_PER_RECORD`].
fn grid_shape(spheres: &[(Vec3, f32)]) -> (Vec3, f32, [u32; 3]) {
    if spheres.is_empty() {
        return (Vec3::ZERO, 1.0, [1, 1, 1]);
    }
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for &(c, r) in spheres {
        lo = lo.min(c - Vec3::splat(r));
        hi = hi.max(c + Vec3::splat(r));
    }
    // A margin so that no sphere touches the grid's outer faces.
    let extent = (hi - lo).max_element().max(1e-6);
    lo -= Vec3::splat(1e-3 * extent);
    hi += Vec3::splat(1e-3 * extent);
    let mut diameters: Vec<f32> = spheres.iter().map(|&(_, r)| 2.0 * r).collect();
    diameters.sort_unstable_by(f32::total_cmp);
    let mut cell = diameters[diameters.len() / 2]
        .max((hi - lo).max_element() / MAX_CELLS_PER_AXIS as f32)
        .max(1e-6);
    loop {
        let dims = ((hi - lo) / cell).ceil().max(Vec3::ONE);
        let dims = [dims.x as usize, dims.y as usize, dims.z as usize];
        let cells: usize = dims.iter().product();
        // Entries per sphere, bounded by its bounding box in cells.
        let entries: usize = spheres
            .iter()
            .map(|&(_, r)| {
                let span = ((2.0 * r / cell).ceil() as usize + 1).min(MAX_CELLS_PER_AXIS + 1);
                span * span * span
            })
            .sum();
        let fits = cells <= MAX_CELLS
            && dims.iter().all(|&d| d <= MAX_CELLS_PER_AXIS)
            && entries <= MAX_ENTRIES_PER_RECORD * spheres.len();
        if fits {
            return (lo, cell, dims.map(|d| d as u32));
        }
        cell *= 1.25;
    }
}

/// Records and grid uploaded for one render pass ([`CacheSplat::prepare`]).
pub struct PreparedCache {
    grid: SplatGrid,
    gradients: bool,
    /// Which upload the splat's buffers hold; another prepared cache in
    /// between makes [`CacheSplat::interpolate`] upload this one again.
    generation: u64,
}

impl PreparedCache {
    pub fn grid(&self) -> &SplatGrid {
        &self.grid
    }
}

/// Time spent by the splat, summed since creation or the last
/// [`CacheSplat::reset_timings`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplatTimings {
    /// Binning the records and uploading records and grid.
    pub prepare: Duration,
    /// Writing lookups and parameters.
    pub upload: Duration,
    /// Submit to completion of the dispatch and the copy to staging.
    pub dispatch: Duration,
    /// Mapping the staging buffer and copying the sums out.
    pub readback: Duration,
    pub dispatches: u64,
}

/// Buffers of the pass, reused across dispatches; they only grow.
struct SplatBuffers {
    /// `PreparedCache::generation` of the records and grid uploaded.
    generation: u64,
    params: wgpu::Buffer,
    records: GrowingBuffer,
    cell_start: GrowingBuffer,
    cell_records: GrowingBuffer,
    used: GrowingBuffer,
    lookups: GrowingBuffer,
    splats: GrowingBuffer,
    staging: GrowingBuffer,
}

/// A buffer that is replaced by a larger one when a write does not fit.
struct GrowingBuffer {
    buffer: wgpu::Buffer,
    bytes: u64,
    label: &'static str,
    usage: wgpu::BufferUsages,
}

impl GrowingBuffer {
    /// `bytes` at first: one element, the least a binding of the shader's
    /// runtime-sized array may hold.
    fn new(
        device: &wgpu::Device,
        label: &'static str,
        bytes: u64,
        usage: wgpu::BufferUsages,
    ) -> Self {
        GrowingBuffer {
            buffer: create_buffer(device, label, bytes, usage),
            bytes,
            label,
            usage,
        }
    }

    /// Makes room for `bytes`, growing by a quarter more so that slowly growing sizes do not
    /// reallocate every time.
    fn reserve(&mut self, device: &wgpu::Device, bytes: u64) {
        if bytes > self.bytes {
            let size = (bytes + bytes / 4).next_multiple_of(4);
            self.buffer = create_buffer(device, self.label, size, self.usage);
            self.bytes = size;
        }
    }
}

fn create_buffer(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: false,
    })
}

/// The pass, on the GPU backend's device.
pub struct CacheSplat {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: String,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    buffers: Mutex<SplatBuffers>,
    generation: AtomicU64,
    max_binding: u64,
    max_groups_per_dim: u32,
    errors: ErrorSlot,
    /// The GPU backend's failure, which [`Self::fail`] sets.
    failed: FailureSlot,
    timings: Mutex<SplatTimings>,
    /// The backend's [`super::WAIT_LIMIT`] or what it was set to.
    wait_limit: Duration,
}

impl CacheSplat {
    /// Compiles the shader on the backend's device (`adapter` names it in
    /// errors; `errors` is the backend's slot for uncaptured errors, `failed`
    /// its [`crate::backend::RayBackend::failure`]).
    pub(super) fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        adapter: String,
        errors: ErrorSlot,
        failed: FailureSlot,
    ) -> Result<Self, GpuError> {
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("splat records"),
            entries: &[
                layout_entry(0, wgpu::BufferBindingType::Uniform),
                storage_entry(1, true),
                storage_entry(2, true),
                storage_entry(3, true),
                storage_entry(4, true),
                storage_entry(5, false),
                storage_entry(6, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("splat records"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("cache_splat"),
            source: wgpu::ShaderSource::Wgsl(
                include_str!("../../../shaders/cache_splat.wgsl").into(),
            ),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("splat records"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("splat_records"),
            compilation_options: Default::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Setup {
                adapter,
                message: format!("cache splat shader rejected: {e}"),
            });
        }
        let limits = device.limits();
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let buffers = SplatBuffers {
            generation: 0,
            params: create_buffer(
                device,
                "splat params",
                std::mem::size_of::<SplatParams>() as u64,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            ),
            records: GrowingBuffer::new(device, "splat records", RECORD_BYTES, storage),
            cell_start: GrowingBuffer::new(device, "splat cell starts", 4, storage),
            cell_records: GrowingBuffer::new(device, "splat cell records", 4, storage),
            used: GrowingBuffer::new(
                device,
                "splat used",
                4,
                storage | wgpu::BufferUsages::COPY_SRC,
            ),
            lookups: GrowingBuffer::new(device, "splat lookups", LOOKUP_BYTES, storage),
            splats: GrowingBuffer::new(
                device,
                "splat sums",
                SPLAT_BYTES,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            ),
            staging: GrowingBuffer::new(
                device,
                "splat staging",
                SPLAT_BYTES,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
        };
        Ok(CacheSplat {
            device: device.clone(),
            queue: queue.clone(),
            adapter,
            layout,
            pipeline,
            buffers: Mutex::new(buffers),
            generation: AtomicU64::new(1),
            max_binding: limits
                .max_storage_buffer_binding_size
                .min(limits.max_buffer_size),
            max_groups_per_dim: limits.max_compute_workgroups_per_dimension.max(1),
            errors,
            failed,
            timings: Mutex::default(),
            wait_limit: super::WAIT_LIMIT,
        })
    }

    /// Set with the backend's, [`super::GpuBackend::set_wait_limit`].
    pub(super) fn set_wait_limit(&mut self, limit: Duration) {
        self.wait_limit = limit;
    }

    pub fn timings(&self) -> SplatTimings {
        *self.timings.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn reset_timings(&self) {
        *self.timings.lock().unwrap_or_else(|e| e.into_inner()) = SplatTimings::default();
    }

    fn add_timings(&self, f: impl FnOnce(&mut SplatTimings)) {
        f(&mut self.timings.lock().unwrap_or_else(|e| e.into_inner()));
    }

    /// Fails the GPU backend with `error` (the first error is kept): a
    /// caller that cannot return it (a render tile) reports it here, and
    /// the renderer discards the frame as for a ray error.
    pub fn fail(&self, error: &GpuError) {
        let mut failed = self.failed.lock().unwrap_or_else(|e| e.into_inner());
        failed.get_or_insert_with(|| error.to_string());
    }

    /// Whether the GPU backend has failed (then the splat is not used).
    pub fn has_failed(&self) -> bool {
        self.failure().is_some()
    }

    /// The first error [`Self::fail`] kept.
    fn failure(&self) -> Option<String> {
        self.failed
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    fn error(&self, message: String) -> GpuError {
        GpuError::Setup {
            adapter: self.adapter.clone(),
            message,
        }
    }

    /// Lookups per dispatch at most (the storage binding limit).
    fn chunk_lookups(&self) -> usize {
        usize::try_from(self.max_binding / LOOKUP_BYTES.max(SPLAT_BYTES))
            .unwrap_or(usize::MAX)
            .max(1)
    }

    /// Bins `records` (a cache of accuracy `accuracy`) and uploads them for
    /// [`Self::interpolate`]; `gradients` as `IcSettings::gradients`.
    pub fn prepare(
        &self,
        records: &[IrradianceRecord],
        accuracy: f32,
        gradients: bool,
    ) -> Result<PreparedCache, GpuError> {
        let start = Instant::now();
        let prepared = PreparedCache {
            grid: SplatGrid::new(records, accuracy),
            gradients,
            generation: self.generation.fetch_add(1, Ordering::Relaxed),
        };
        let g = &prepared.grid;
        for (what, bytes) in [
            ("records", g.records.len() as u64 * RECORD_BYTES),
            ("grid cells", g.cell_start.len() as u64 * 4),
            ("grid entries", g.cell_records.len() as u64 * 4),
        ] {
            if bytes > self.max_binding {
                return Err(self.error(format!(
                    "cache {what} ({} MiB) exceed the device's storage binding size of {} MiB",
                    bytes >> 20,
                    self.max_binding >> 20
                )));
            }
        }
        let mut buffers = self.buffers.lock().unwrap_or_else(|e| e.into_inner());
        self.upload(&mut buffers, &prepared);
        let elapsed = start.elapsed();
        self.add_timings(|t| t.prepare += elapsed);
        Ok(prepared)
    }

    /// Writes the records and the grid of `prepared` into the buffers.
    fn upload(&self, buffers: &mut SplatBuffers, prepared: &PreparedCache) {
        let g = &prepared.grid;
        let writes: [(&mut GrowingBuffer, &[u8]); 3] = [
            (&mut buffers.records, bytemuck::cast_slice(&g.records)),
            (&mut buffers.cell_start, bytemuck::cast_slice(&g.cell_start)),
            (
                &mut buffers.cell_records,
                bytemuck::cast_slice(&g.cell_records),
            ),
        ];
        for (buffer, bytes) in writes {
            buffer.reserve(&self.device, bytes.len() as u64);
            if !bytes.is_empty() {
                self.queue.write_buffer(&buffer.buffer, 0, bytes);
            }
        }
        buffers
            .used
            .reserve(&self.device, g.records.len().div_ceil(32) as u64 * 4);
        buffers.generation = prepared.generation;
    }

    /// TRC Eq. 1 at each lookup over the records of `prepared`: what
    /// [`crate::cache::IrradianceCache::interpolate_marking`] returns, in
    /// lookup order. With `used` (one flag per record), every record some
    /// lookup uses is flagged.
    pub fn interpolate(
        &self,
        prepared: &PreparedCache,
        lookups: &[GpuLookup],
        used: Option<&[AtomicBool]>,
    ) -> Result<Vec<GpuSplat>, GpuError> {
        if let Some(used) = used {
            assert_eq!(used.len(), prepared.grid.len(), "one used flag per record");
        }
        let mut out = Vec::with_capacity(lookups.len());
        if lookups.is_empty() {
            return Ok(out);
        }
        // One batch at a time: the buffers are shared.
        let mut buffers = self.buffers.lock().unwrap_or_else(|e| e.into_inner());
        if buffers.generation != prepared.generation {
            self.upload(&mut buffers, prepared);
        }
        for chunk in lookups.chunks(self.chunk_lookups()) {
            // Once a wait failed (a hung device), each tile queued on the
            // buffers would otherwise wait out its own WAIT_LIMIT behind it.
            if let Some(failure) = self.failure() {
                return Err(self.error(format!("an earlier GPU call failed: {failure}")));
            }
            self.dispatch(&mut buffers, prepared, chunk, used, &mut out)?;
        }
        Ok(out)
    }

    /// One dispatch over `lookups`: upload, splat, read back the sums (into
    /// `out`) and the used bits (into `used`).
    fn dispatch(
        &self,
        buffers: &mut SplatBuffers,
        prepared: &PreparedCache,
        lookups: &[GpuLookup],
        used: Option<&[AtomicBool]>,
        out: &mut Vec<GpuSplat>,
    ) -> Result<(), GpuError> {
        let start = Instant::now();
        let n = lookups.len() as u64;
        let grid = &prepared.grid;
        let splat_bytes = n * SPLAT_BYTES;
        let used_bytes = if used.is_some() {
            grid.len().div_ceil(32) as u64 * 4
        } else {
            0
        };
        buffers.lookups.reserve(&self.device, n * LOOKUP_BYTES);
        buffers.splats.reserve(&self.device, splat_bytes);
        buffers
            .staging
            .reserve(&self.device, splat_bytes + used_bytes);

        let (groups_x, groups_y) =
            workgroup_grid(n as u32, SPLAT_WORKGROUP_SIZE, self.max_groups_per_dim);
        let params = SplatParams::new(prepared, n as u32, groups_x, used.is_some());
        self.queue
            .write_buffer(&buffers.params, 0, bytemuck::bytes_of(&params));
        self.queue
            .write_buffer(&buffers.lookups.buffer, 0, bytemuck::cast_slice(lookups));
        let upload = start.elapsed();
        let start = Instant::now();
        let pass = ComputePass {
            label: "splat records",
            pipeline: &self.pipeline,
            layout: &self.layout,
            entries: &[
                bind(0, &buffers.params),
                bind(1, &buffers.records.buffer),
                bind(2, &buffers.cell_start.buffer),
                bind(3, &buffers.cell_records.buffer),
                bind(4, &buffers.lookups.buffer),
                bind(5, &buffers.splats.buffer),
                bind(6, &buffers.used.buffer),
            ],
            groups: (groups_x, groups_y),
        };
        // The used bits are set by the pass: cleared before it.
        let used_buffer = &buffers.used.buffer;
        let clear_used = |encoder: &mut wgpu::CommandEncoder| {
            if used_bytes > 0 {
                encoder.clear_buffer(used_buffer, 0, Some(used_bytes));
            }
        };
        let mut copies = vec![(&buffers.splats.buffer, splat_bytes)];
        if used_bytes > 0 {
            copies.push((used_buffer, used_bytes));
        }
        let index = pass.submit(
            &self.device,
            &self.queue,
            clear_used,
            &copies,
            &buffers.staging.buffer,
        );
        let submitted = start.elapsed();
        let wait = Submitted {
            index,
            limit: self.wait_limit,
        };
        let (waited, readback) = read_back(
            &self.device,
            wait,
            &buffers.staging.buffer,
            splat_bytes + used_bytes,
            "splat sums",
            &self.errors,
            |view| {
                let (sums, bits) = view.split_at(splat_bytes as usize);
                out.extend_from_slice(bytemuck::cast_slice(sums));
                if let Some(used) = used {
                    mark_used(bytemuck::cast_slice(bits), used);
                }
            },
        )
        .map_err(|e| self.error(e))?;
        let dispatch = submitted + waited;
        self.add_timings(|t| {
            t.upload += upload;
            t.dispatch += dispatch;
            t.readback += readback;
            t.dispatches += 1;
        });
        Ok(())
    }
}

/// Sets `used[k]` for every bit `k` set in `bits`.
fn mark_used(bits: &[u32], used: &[AtomicBool]) {
    for (w, &word) in bits.iter().enumerate() {
        let mut word = word;
        while word != 0 {
            let b = word.trailing_zeros() as usize;
            used[w * 32 + b].store(true, Ordering::Relaxed);
            word &= word - 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    fn record(rng: &mut Rng, id: u64) -> IrradianceRecord {
        let v = |rng: &mut Rng| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        IrradianceRecord {
            id,
            position: v(rng) * 4.0 - 2.0,
            normal: (v(rng) - 0.5).normalize_or(Vec3::Z),
            irradiance: v(rng),
            grad_translation: [Vec3::ZERO; 3],
            grad_rotation: [Vec3::ZERO; 3],
            radius: 0.05 + 2.0 * rng.next_f32().powi(4),
            created_frame: 0,
            object: 0,
            eas: None,
        }
    }

    /// Binning never loses a record: every sphere holding a point is listed
    /// in the point's cell (the CPU side of the splat, no GPU needed).
    #[test]
    fn every_sphere_holding_a_point_is_in_its_cell() {
        let mut rng = Rng::from_seed(7, 0);
        let records: Vec<_> = (0..500).map(|i| record(&mut rng, i)).collect();
        let accuracy = 0.3;
        let grid = SplatGrid::new(&records, accuracy);
        assert!(grid.entries() <= MAX_ENTRIES_PER_RECORD * records.len());
        for _ in 0..20_000 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 5.0 - 2.5;
            let cell = grid.candidates(p);
            for (k, r) in records.iter().enumerate() {
                let radius = r.influence_radius(accuracy);
                if (p - r.position).length_squared() <= radius * radius {
                    assert!(cell.contains(&(k as u32)), "record {k} missing at {p}");
                }
            }
            assert!(
                cell.windows(2).all(|w| w[0] < w[1]),
                "cell lists in record order"
            );
        }
    }

    #[test]
    fn an_empty_cache_has_one_empty_cell() {
        let grid = SplatGrid::new(&[], 0.2);
        assert_eq!(grid.dims(), [1, 1, 1]);
        assert!(grid.candidates(Vec3::ZERO).is_empty());
        assert!(grid.candidates(Vec3::splat(7.0)).is_empty());
    }

    #[test]
    fn used_bits_set_their_flags() {
        let used: Vec<AtomicBool> = (0..70).map(|_| AtomicBool::new(false)).collect();
        mark_used(&[0b101, 0, 1 << 5], &used);
        let set: Vec<usize> = (0..70)
            .filter(|&i| used[i].load(Ordering::Relaxed))
            .collect();
        assert_eq!(set, vec![0, 2, 69]);
    }
}
