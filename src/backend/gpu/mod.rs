//! The GPU ray backend: wgpu compute shaders (`shaders/*.wgsl`) traverse
//! obvhs BVHs of the frame's triangles (CWBVH or BVH2, [`GpuLayout`]),
//! closest hit and any hit over batches of rays. It returns the same hits
//! as the CPU backend (`tests/gpu_backend.rs` checks it on random scenes
//! and on every built-in scene).
//!
//! Split as bevy_solari splits its passes:
//! - **extract**: [`GpuBackend::set_geometry`] builds a BVH per part (the
//!   static triangles `0..n` of [`crate::accel::static_part_len`], the rest
//!   after) in the backend's
//!   layout (`src/backend/gpu/bvh.rs`) and lays triangles out in leaf order
//!   ([`GpuTriangle`], with their snapshot triangle and object ids);
//! - **prepare**: both parts live in one node buffer and one triangle buffer,
//!   static part first (`geometry`). The static part is uploaded once and
//!   again only when its fingerprint changes (a new scene); every frame
//!   rewrites only the dynamic tail. Ray, result and staging buffers are
//!   reused across dispatches and only ever grow;
//! - **passes**: "closest hit" (`shaders/closest_hit.wgsl`) and "any hit"
//!   (`shaders/any_hit.wgsl`), both on `shaders/ray_common.wgsl` and the
//!   layout's traversal (`cwbvh_traverse.wgsl` or `bvh2_traverse.wgsl`). A
//!   batch is cut in chunks of at most [`GpuBackend::chunk_rays`] rays (the storage
//!   binding limit: 128 MiB on lavapipe), each dispatched as a 2D grid (at
//!   most 65535 workgroups per dimension), its results copied to a staging
//!   buffer, mapped and read back (the plumbing the cache splat shares:
//!   `compute`).
//!
//! The adapter is chosen, and the device's own errors are kept, in
//! `device`.
//!
//! Why two BVHs traced one after the other instead of one merged BVH: the
//! static part (most of a scene) is built and uploaded once per render; a
//! merged BVH would be rebuilt and re-uploaded in full every frame. Up to
//! [`crate::accel::MERGE_STATIC_TRIANGLES`] static triangles the static part
//! is empty and one BVH holds them all, rebuilt every frame. The split is
//! exactly the CPU backend's (`src/accel.rs`); of equally near hits both
//! keep the lower triangle id, in either BVH.
//!
//! Two layouts, chosen at construction ([`GpuBackend::with_layout`], or
//! `RADCACHE_GPU_BVH=cwbvh|bvh2` for [`GpuBackend::new`]): CWBVH (Ylitie et
//! al. 2017), the CPU backend's own tree, 80-byte nodes with 8 quantised
//! child boxes each, traversed in the CPU's exact order; and BVH2, a short
//! stack loop over 48-byte nodes. obvhs ships no GPU traversal; both are
//! ours and both return the CPU's hits (bit for bit where the GPU rounds as
//! the CPU does, as lavapipe does, ties included; both start rays [`crate::accel::NEAR_SHIFT`] behind their origin as the
//! CPU does). CWBVH is the default: `cargo bench --bench gpu_rays`
//! measured it about 2× faster than BVH2 for closest hit and 2.5× for any
//! hit (README, `--backend`). That was on lavapipe, which runs the shaders
//! on the CPU: the ratio is lavapipe's, a real GPU's is not measured yet.
//!
//! Errors: everything that can fail for lack of a device — no adapter, no
//! device, a shader the driver rejects — fails in [`GpuBackend::new`] with an
//! error. The [`RayBackend`] methods return nothing, so a failure after
//! construction (the device lost, a buffer that cannot be mapped, a scene too
//! large for the device's binding limits) is kept as the backend's
//! [`RayBackend::failure`]: from then on every ray misses, and the renderer,
//! which checks it after each frame, discards the frame and stops with the
//! message (a resumable job keeps every frame finished before). It is never
//! silently swallowed, and it never panics. The `try_` methods return the
//! errors directly for callers that want to handle them.

use super::{Hit, Ray, RayBackend, RayCounters, RayCounts};
use crate::accel;
use crate::scene::Snapshot;
use bvh::Part;
pub use bvh::{GpuLayout, GpuNode, CWBVH_STACK_SIZE, STACK_SIZE};
use bytemuck::{Pod, Zeroable};
use cache_splat::{CacheSplat, GpuLookup};
use std::sync::Mutex;
use std::time::{Duration, Instant};

pub mod bvh;
pub mod cache_splat;
mod compute;
mod device;
mod geometry;

pub use compute::WAIT_LIMIT;
pub(crate) use compute::{
    bind, layout_entry, read_back, storage_entry, workgroup_grid, ComputePass, Submitted,
};
pub use device::{adapters, AdapterPolicy};
use device::{pick_adapter, record_device_errors};
pub(crate) use device::{ErrorSlot, FailureSlot};
use geometry::{GeometryBuffers, Growth};

/// Work items per workgroup. Must match `WORKGROUP_SIZE` in
/// `shaders/ray_common.wgsl`.
pub const WORKGROUP_SIZE: u32 = 64;

/// Rays per dispatch at most, before the device's binding limit is applied:
/// 4 Mi rays (128 MiB of rays) keep a large GPU busy while bounding the
/// buffers this backend keeps.
pub const MAX_CHUNK_RAYS: usize = 1 << 22;

/// Batch size that keeps the GPU busy: a dispatch has a fixed cost (submit,
/// map, wait) of a fraction of a millisecond, small beside 1 Mi rays.
pub const PREFERRED_BATCH: usize = 1 << 20;

/// The fewest rays worth a dispatch ([`RayBackend::min_batch`]): at 64 Ki
/// rays the fixed cost of a dispatch is a small part of tracing them. On
/// an H100 beside 16 cores, 16 Ki (more tasks for the threads to shade)
/// made `ic`, `trc` and `tcg` 1.3–1.5× slower on cube-in-box at 256×256
/// (README, "--backend").
pub const MIN_BATCH: usize = 1 << 16;

/// "No node / no triangle" (`NONE` in the shaders).
const NONE: u32 = u32::MAX;

/// Bytes of one closest-hit result (`Hit`, array stride 20 in WGSL).
const HIT_BYTES: u64 = std::mem::size_of::<Hit>() as u64;
/// Bytes of one any-hit result (a `u32` flag).
const FLAG_BYTES: u64 = 4;
/// Bytes of one ray.
const RAY_BYTES: u64 = std::mem::size_of::<Ray>() as u64;
/// Bytes of one triangle.
const TRIANGLE_BYTES: u64 = std::mem::size_of::<GpuTriangle>() as u64;

/// A triangle in BVH leaf order with the ids a hit reports. Field order must
/// match `Triangle` in `shaders/ray_common.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuTriangle {
    pub v0: [f32; 3],
    /// Snapshot triangle id.
    pub id: u32,
    pub v1: [f32; 3],
    /// Object id.
    pub object: u32,
    pub v2: [f32; 3],
    pub _pad: u32,
}

/// Parameters of one dispatch. Field order must match `Params` in
/// `shaders/ray_common.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
struct GpuParams {
    ray_count: u32,
    /// Work items per row of the 2D grid.
    row_width: u32,
    static_root: u32,
    dynamic_root: u32,
}

const _: () = assert!(std::mem::size_of::<GpuTriangle>() == 48);
const _: () = assert!(std::mem::size_of::<Ray>() == 32);
const _: () = assert!(std::mem::size_of::<Hit>() == 20);

/// Why the GPU backend could not start.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter found (install Mesa's Vulkan driver for a software one)")]
    NoAdapter,
    #[error("GPU adapter {adapter}: {message}")]
    Setup { adapter: String, message: String },
    #[error("GPU ray backend: {0}")]
    Geometry(String),
    /// A setting (`RADCACHE_GPU_BVH`) with a value the backend does not know.
    #[error("GPU ray backend: {0}")]
    Config(String),
}

/// Time spent by the GPU backend, summed since creation or the last
/// [`GpuBackend::reset_timings`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuTimings {
    /// BVH builds (static and dynamic).
    pub bvh_build: Duration,
    /// Static geometry uploads (nodes + triangles) and how many there were.
    pub static_upload: Duration,
    pub static_uploads: u32,
    /// Dynamic geometry uploads.
    pub dynamic_upload: Duration,
    /// Writing rays (and parameters) into the ray buffer.
    pub ray_upload: Duration,
    /// Submit to completion of the dispatch and the copy to staging.
    pub dispatch: Duration,
    /// Mapping the staging buffer and copying results out.
    pub readback: Duration,
    /// Submissions waited for: one per chunk, or per combined
    /// closest-and-any-hit call (two dispatches).
    pub dispatches: u64,
}

/// Ray, result and staging buffers, reused across dispatches; they only grow.
struct RayBuffers {
    /// Rays the buffers hold.
    capacity: u64,
    params: wgpu::Buffer,
    rays: wgpu::Buffer,
    results: wgpu::Buffer,
    staging: wgpu::Buffer,
}

pub struct GpuBackend {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    layout: wgpu::BindGroupLayout,
    /// The BVH layout the shaders traverse.
    bvh: GpuLayout,
    closest_pipeline: wgpu::ComputePipeline,
    any_pipeline: wgpu::ComputePipeline,
    geometry: GeometryBuffers,
    /// Idle buffer pairs. A call takes one (or makes one) and gives it
    /// back, so render tiles on several threads trace at once: with one
    /// pair behind a lock, each call's wait for the GPU held the others up
    /// (the pair: a combined closest-and-any-hit call,
    /// [`RayBackend::closest_and_any_hit`], fills both).
    rays: Mutex<Vec<[RayBuffers; 2]>>,
    chunk_rays: usize,
    max_binding: u64,
    max_groups_per_dim: u32,
    errors: ErrorSlot,
    /// The first error of a [`RayBackend`] call ([`RayBackend::failure`]),
    /// shared with the cache splat, whose errors fail the backend too.
    failed: FailureSlot,
    counters: RayCounters,
    timings: Mutex<GpuTimings>,
    /// How long a readback waits before the GPU counts as hung
    /// ([`WAIT_LIMIT`]).
    wait_limit: Duration,
    /// The render pass's cache interpolation on this device.
    splat: CacheSplat,
}

/// The closest-hit and any-hit compute pipelines over `bvh`'s traversal,
/// with their bind group layout.
struct RayPipelines {
    layout: wgpu::BindGroupLayout,
    closest: wgpu::ComputePipeline,
    any: wgpu::ComputePipeline,
}

impl RayPipelines {
    fn new(device: &wgpu::Device, bvh: &GpuLayout) -> Result<Self, String> {
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("rays"),
            entries: &[
                layout_entry(0, wgpu::BufferBindingType::Uniform),
                storage_entry(1, true),
                storage_entry(2, true),
                storage_entry(3, true),
                storage_entry(4, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("rays"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |name: &str, stage: &str| {
            let source = format!(
                "{}\n{}\n{}",
                include_str!("../../../shaders/ray_common.wgsl"),
                bvh.traversal_source(),
                stage
            );
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(name),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let closest = pipeline(
            "closest_hit",
            include_str!("../../../shaders/closest_hit.wgsl"),
        );
        let any = pipeline("any_hit", include_str!("../../../shaders/any_hit.wgsl"));
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!("shaders rejected: {e}"));
        }
        Ok(RayPipelines {
            layout,
            closest,
            any,
        })
    }
}

/// A byte or element count as `usize`, saturating on 32-bit targets.
fn usize_of(x: u64) -> usize {
    usize::try_from(x).unwrap_or(usize::MAX)
}

impl GpuBackend {
    /// [`Self::with_layout`] with the layout `RADCACHE_GPU_BVH` names
    /// (the default, CWBVH, when unset).
    pub fn new(policy: AdapterPolicy) -> Result<Self, GpuError> {
        Self::with_layout(policy, GpuLayout::from_env()?)
    }

    /// Picks an adapter by `policy`, opens a device with the adapter's own
    /// limits, compiles the shaders for BVH layout `bvh` and runs one tiny
    /// dispatch, so that a backend that is returned can trace.
    pub fn with_layout(policy: AdapterPolicy, bvh: GpuLayout) -> Result<Self, GpuError> {
        let adapter = pick_adapter(policy)?;
        let info = adapter.get_info();
        let adapter_name = format!("{} ({:?})", info.name, info.backend);
        let setup = |message: String| GpuError::Setup {
            adapter: adapter_name.clone(),
            message,
        };
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("radcache rays"),
            required_features: wgpu::Features::empty(),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| setup(format!("cannot open a device: {e}")))?;
        let errors = record_device_errors(&device);
        let pipelines = RayPipelines::new(&device, &bvh).map_err(setup)?;

        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let chunk_rays = MAX_CHUNK_RAYS.min(usize_of(max_binding / RAY_BYTES)).max(1);
        let geometry = GeometryBuffers::new(&device, bvh.node_bytes());
        let failed = FailureSlot::default();
        let splat = CacheSplat::new(
            &device,
            &queue,
            adapter_name.clone(),
            errors.clone(),
            failed.clone(),
        )?;
        let backend = GpuBackend {
            device,
            queue,
            info,
            layout: pipelines.layout,
            bvh,
            closest_pipeline: pipelines.closest,
            any_pipeline: pipelines.any,
            geometry,
            rays: Mutex::default(),
            chunk_rays,
            max_binding,
            max_groups_per_dim: limits.max_compute_workgroups_per_dimension.max(1),
            errors,
            failed,
            counters: RayCounters::default(),
            timings: Mutex::default(),
            wait_limit: WAIT_LIMIT,
            splat,
        };
        backend.probe().map_err(setup)?;
        // The probe's calls are no part of any render's.
        backend.reset_timings();
        backend.counters.reset();
        Ok(backend)
    }

    /// One empty-scene dispatch of each kind and one splat over an empty
    /// cache: shader compilation and the readback paths fail here, not in
    /// the middle of a render.
    fn probe(&self) -> Result<(), String> {
        let probe = [Ray::new(glam::Vec3::ZERO, glam::Vec3::X, 0.0, 1.0)];
        let mut hit = [Hit::MISS];
        self.try_closest_hit(&probe, &mut hit)
            .map_err(|e| format!("test dispatch failed: {e}"))?;
        let mut occluded = [true];
        self.try_any_hit(&probe, &mut occluded)
            .map_err(|e| format!("test dispatch failed: {e}"))?;
        if hit[0].is_hit() || occluded[0] {
            return Err("test dispatch returned a hit in an empty scene".into());
        }
        // No record is usable anywhere in an empty cache.
        let empty = self
            .splat
            .prepare(&[], 0.2, true)
            .and_then(|c| self.splat.interpolate(&c, &[GpuLookup::default()], None))
            .map_err(|e| format!("test splat failed: {e}"))?;
        if empty.first().is_none_or(|s| s.count != 0) {
            return Err("test splat found a record in an empty cache".into());
        }
        Ok(())
    }

    /// The adapter in use.
    pub fn adapter_info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// Whether the adapter is a software rasteriser (lavapipe).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// The BVH layout the shaders traverse.
    pub fn bvh_layout(&self) -> GpuLayout {
        self.bvh
    }

    /// Rays per dispatch at most.
    pub fn chunk_rays(&self) -> usize {
        self.chunk_rays
    }

    pub fn timings(&self) -> GpuTimings {
        *self.timings.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn reset_timings(&self) {
        *self.timings.lock().unwrap_or_else(|e| e.into_inner()) = GpuTimings::default();
    }

    /// How long a readback of the rays or the cache splat waits for the
    /// GPU before the backend fails ([`WAIT_LIMIT`] unless set): a device
    /// or driver that hangs becomes an error that stops the render.
    pub fn set_wait_limit(&mut self, limit: Duration) {
        self.wait_limit = limit;
        self.splat.set_wait_limit(limit);
    }

    fn add_timings(&self, f: impl FnOnce(&mut GpuTimings)) {
        f(&mut self.timings.lock().unwrap_or_else(|e| e.into_inner()));
    }

    /// Keeps the first error of `result` as [`RayBackend::failure`];
    /// whether the backend has failed (now or before).
    fn fail_on(&self, result: Result<(), GpuError>) -> bool {
        let mut failed = self.failed.lock().unwrap_or_else(|e| e.into_inner());
        if let Err(e) = result {
            failed.get_or_insert_with(|| e.to_string());
        }
        failed.is_some()
    }

    /// [`RayBackend::set_geometry`] with the size checks as errors: a part
    /// whose nodes or triangles exceed the device's storage binding size, or
    /// a BVH deeper than the shaders' stack.
    pub fn try_set_geometry(&mut self, snapshot: &Snapshot) -> Result<(), GpuError> {
        let static_len = accel::static_part_len(snapshot);
        let fp = accel::static_part_fingerprint(snapshot);
        let build_start = Instant::now();
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("geometry"),
            });

        let static_part = if self.geometry.static_fingerprint != fp {
            Some(Part::build(
                self.bvh,
                snapshot,
                0..static_len,
                accel::BvhLife::Render,
            )?)
        } else {
            None
        };
        let dynamic_range = static_len..snapshot.triangles.len();
        let dynamic_part = Part::build(self.bvh, snapshot, dynamic_range, accel::BvhLife::Frame)?;
        let bvh_build = build_start.elapsed();

        let g = &self.geometry;
        let static_size = match &static_part {
            Some(p) => (p.node_count() as u64, p.triangles.len() as u64),
            None => (g.static_nodes, g.static_triangles),
        };
        let grow = Growth {
            device: &self.device,
            max_binding: self.max_binding,
        };
        self.geometry.reserve(
            &grow,
            &mut encoder,
            static_size,
            &dynamic_part,
            static_part.is_none(),
        )?;
        let static_upload = static_part.map(|part| {
            let start = Instant::now();
            self.geometry.upload_static(&self.queue, &part, fp);
            start.elapsed()
        });
        let start = Instant::now();
        self.geometry
            .upload_dynamic(&self.queue, dynamic_part, static_size);
        self.queue.submit([encoder.finish()]);
        let dynamic_upload = start.elapsed();
        self.add_timings(|t| {
            t.bvh_build += bvh_build;
            t.dynamic_upload += dynamic_upload;
            if let Some(d) = static_upload {
                t.static_upload += d;
                t.static_uploads += 1;
            }
        });
        Ok(())
    }

    /// [`RayBackend::closest_hit`] returning the device's errors.
    pub fn try_closest_hit(&self, rays: &[Ray], hits: &mut [Hit]) -> Result<(), GpuError> {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        self.trace(&self.closest_pipeline, HIT_BYTES, rays, |first, bytes| {
            store_hits(hits, first, bytes)
        })?;
        self.counters.add_call(rays.len(), 0);
        Ok(())
    }

    /// [`RayBackend::any_hit`] returning the device's errors.
    pub fn try_any_hit(&self, rays: &[Ray], occluded: &mut [bool]) -> Result<(), GpuError> {
        assert_eq!(rays.len(), occluded.len(), "one result slot per ray");
        self.trace(&self.any_pipeline, FLAG_BYTES, rays, |first, bytes| {
            store_flags(occluded, first, bytes)
        })?;
        self.counters.add_call(0, rays.len());
        Ok(())
    }

    /// [`RayBackend::closest_and_any_hit`] returning the device's errors:
    /// both dispatches in one submission and one wait. Batches larger than
    /// a chunk, or an empty one, go through the two calls.
    pub fn try_closest_and_any_hit(
        &self,
        rays: &[Ray],
        hits: &mut [Hit],
        shadows: &[Ray],
        occluded: &mut [bool],
    ) -> Result<(), GpuError> {
        let fits = |r: &[Ray]| !r.is_empty() && r.len() <= self.chunk_rays;
        if !(fits(rays) && fits(shadows)) {
            if !rays.is_empty() {
                self.try_closest_hit(rays, hits)?;
            }
            if !shadows.is_empty() {
                self.try_any_hit(shadows, occluded)?;
            }
            return Ok(());
        }
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        assert_eq!(shadows.len(), occluded.len(), "one result slot per ray");
        let mut buffers = self.take_buffers();
        let [closest_buffers, any_buffers] = &mut buffers;
        let mut encoder = self.encoder("trace both");
        let start = Instant::now();
        let hit_bytes = self.encode(
            closest_buffers,
            &self.closest_pipeline,
            HIT_BYTES,
            rays,
            &mut encoder,
        );
        let flag_bytes = self.encode(
            any_buffers,
            &self.any_pipeline,
            FLAG_BYTES,
            shadows,
            &mut encoder,
        );
        let read = self.submit_and_read(
            encoder,
            start.elapsed(),
            &mut [
                (closest_buffers, hit_bytes, &mut |view| {
                    store_hits(hits, 0, view)
                }),
                (any_buffers, flag_bytes, &mut |view| {
                    store_flags(occluded, 0, view)
                }),
            ],
        );
        self.give_back_buffers(buffers, &read);
        read?;
        self.counters.add_call(rays.len(), shadows.len());
        Ok(())
    }

    /// Runs `pipeline` over `rays` chunk by chunk, a submission and a wait
    /// each; `store(first, bytes)` receives the results of rays `first..`
    /// (`result_bytes` each).
    fn trace(
        &self,
        pipeline: &wgpu::ComputePipeline,
        result_bytes: u64,
        rays: &[Ray],
        mut store: impl FnMut(usize, &[u8]),
    ) -> Result<(), GpuError> {
        let mut pair = self.take_buffers();
        let buffers = &mut pair[0];
        let mut traced = Ok(());
        for (index, chunk) in rays.chunks(self.chunk_rays).enumerate() {
            let first = index * self.chunk_rays;
            let mut encoder = self.encoder("trace");
            let start = Instant::now();
            let bytes = self.encode(buffers, pipeline, result_bytes, chunk, &mut encoder);
            traced = self.submit_and_read(
                encoder,
                start.elapsed(),
                &mut [(buffers, bytes, &mut |view| store(first, view))],
            );
            if traced.is_err() {
                break;
            }
        }
        self.give_back_buffers(pair, &traced);
        traced
    }

    /// An idle pair of ray buffers, made (small; they grow on use) when
    /// every pair is in use by another thread's call.
    fn take_buffers(&self) -> [RayBuffers; 2] {
        let idle = self.rays.lock().unwrap_or_else(|e| e.into_inner()).pop();
        idle.unwrap_or_else(|| {
            [
                RayBuffers::new(&self.device, 1),
                RayBuffers::new(&self.device, 1),
            ]
        })
    }

    /// Returns `pair` to the pool after a call that `went` well. After an
    /// error its staging buffer may still wait for a mapping that never
    /// came (a wait past the limit): it is dropped, not handed to the next
    /// call.
    fn give_back_buffers<T>(&self, pair: [RayBuffers; 2], went: &Result<(), T>) {
        if went.is_err() {
            return;
        }
        self.rays
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(pair);
    }

    fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }

    /// Submits `encoder` (its uploads took `upload`) and, after one wait,
    /// hands each read's staging buffer (its first `bytes`) to its `store`;
    /// adds the times to [`GpuTimings`].
    fn submit_and_read(
        &self,
        encoder: wgpu::CommandEncoder,
        upload: Duration,
        reads: &mut [StagedRead],
    ) -> Result<(), GpuError> {
        let start = Instant::now();
        let index = self.queue.submit([encoder.finish()]);
        let mut dispatch = start.elapsed();
        let mut readback = Duration::ZERO;
        // The first read waits for the whole submission; the others find
        // their copies done.
        for (buffers, bytes, store) in reads.iter_mut() {
            let submitted = Submitted {
                index: index.clone(),
                limit: self.wait_limit,
            };
            let (waited, read) = read_back(
                &self.device,
                submitted,
                &buffers.staging,
                *bytes,
                "results",
                &self.errors,
                |view| store(view),
            )
            .map_err(|message| GpuError::Setup {
                adapter: self.name(),
                message,
            })?;
            dispatch += waited;
            readback += read;
        }
        self.add_timings(|t| {
            t.ray_upload += upload;
            t.dispatch += dispatch;
            t.readback += readback;
            t.dispatches += 1;
        });
        Ok(())
    }

    /// Writes `rays` (at most a chunk) and their parameters into `buffers`,
    /// grown as needed, and encodes `pipeline`'s dispatch over them and
    /// the copy of their results to `buffers.staging` into `encoder`.
    /// Returns the results' size in bytes (`result_bytes` a ray).
    fn encode(
        &self,
        buffers: &mut RayBuffers,
        pipeline: &wgpu::ComputePipeline,
        result_bytes: u64,
        rays: &[Ray],
        encoder: &mut wgpu::CommandEncoder,
    ) -> u64 {
        let n = rays.len() as u64;
        if n > buffers.capacity {
            *buffers = RayBuffers::new(&self.device, n);
        }
        let (groups_x, groups_y) =
            workgroup_grid(n as u32, WORKGROUP_SIZE, self.max_groups_per_dim);
        let params = GpuParams {
            ray_count: n as u32,
            row_width: groups_x * WORKGROUP_SIZE,
            static_root: self.geometry.static_root,
            dynamic_root: self.geometry.dynamic_root,
        };
        self.queue
            .write_buffer(&buffers.params, 0, bytemuck::bytes_of(&params));
        self.queue
            .write_buffer(&buffers.rays, 0, bytemuck::cast_slice(rays));
        let bytes = n * result_bytes;
        let pass = ComputePass {
            label: "trace",
            pipeline,
            layout: &self.layout,
            entries: &[
                bind(0, &buffers.params),
                bind(1, &buffers.rays),
                bind(2, &self.geometry.nodes),
                bind(3, &self.geometry.triangles),
                bind(4, &buffers.results),
            ],
            groups: (groups_x, groups_y),
        };
        pass.encode(
            &self.device,
            encoder,
            &[(&buffers.results, bytes)],
            &buffers.staging,
        );
        bytes
    }
}

/// A submission's results to read back: the buffers whose staging holds
/// them, their size in bytes, and where they go.
type StagedRead<'a, 'b> = (&'a RayBuffers, u64, &'b mut dyn FnMut(&[u8]));

/// Copies closest-hit results read back from the device into `hits` from
/// `first` on.
fn store_hits(hits: &mut [Hit], first: usize, bytes: &[u8]) {
    let out: &[Hit] = bytemuck::cast_slice(bytes);
    hits[first..first + out.len()].copy_from_slice(out);
}

/// Copies any-hit flags read back from the device into `occluded` from
/// `first` on.
fn store_flags(occluded: &mut [bool], first: usize, bytes: &[u8]) {
    let flags: &[u32] = bytemuck::cast_slice(bytes);
    for (o, &f) in occluded[first..first + flags.len()].iter_mut().zip(flags) {
        *o = f != 0;
    }
}

impl RayBuffers {
    fn new(device: &wgpu::Device, capacity: u64) -> Self {
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        RayBuffers {
            capacity,
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("params"),
                size: std::mem::size_of::<GpuParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            rays: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("rays"),
                size: capacity * RAY_BYTES,
                usage,
                mapped_at_creation: false,
            }),
            results: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("results"),
                size: capacity * HIT_BYTES.max(FLAG_BYTES),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            staging: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("staging"),
                size: capacity * HIT_BYTES.max(FLAG_BYTES),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }
}

impl RayBackend for GpuBackend {
    fn name(&self) -> String {
        format!("gpu ({}, {:?})", self.info.name, self.info.backend)
    }

    /// A scene that does not fit the device fails the backend (see
    /// [`GpuBackend::try_set_geometry`]).
    fn set_geometry(&mut self, snapshot: &Snapshot) {
        if self.failure().is_none() {
            let result = self.try_set_geometry(snapshot);
            self.fail_on(result);
        }
    }

    /// A device failure (lost, out of memory) fails the backend: every ray
    /// misses from then on.
    fn closest_hit(&self, rays: &[Ray], hits: &mut [Hit]) {
        let result = match self.failure() {
            None => self.try_closest_hit(rays, hits),
            Some(_) => Ok(()),
        };
        if self.fail_on(result) {
            hits.fill(Hit::MISS);
        }
    }

    /// As [`Self::closest_hit`]: nothing is occluded once the backend failed.
    fn any_hit(&self, rays: &[Ray], occluded: &mut [bool]) {
        let result = match self.failure() {
            None => self.try_any_hit(rays, occluded),
            Some(_) => Ok(()),
        };
        if self.fail_on(result) {
            occluded.fill(false);
        }
    }

    /// As [`Self::closest_hit`] and [`Self::any_hit`], in one round trip.
    fn closest_and_any_hit(
        &self,
        rays: &[Ray],
        hits: &mut [Hit],
        shadows: &[Ray],
        occluded: &mut [bool],
    ) {
        let result = match self.failure() {
            None => self.try_closest_and_any_hit(rays, hits, shadows, occluded),
            Some(_) => Ok(()),
        };
        if self.fail_on(result) {
            hits.fill(Hit::MISS);
            occluded.fill(false);
        }
    }

    fn failure(&self) -> Option<String> {
        self.failed
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    fn ray_counts(&self) -> RayCounts {
        self.counters.counts()
    }

    fn preferred_batch(&self) -> usize {
        PREFERRED_BATCH
    }

    fn min_batch(&self) -> usize {
        MIN_BATCH
    }

    fn cache_splat(&self) -> Option<&CacheSplat> {
        Some(&self.splat)
    }
}

/// The GPU backend with its cache splat hidden: GPU rays, CPU cache
/// interpolation (what `--backend gpu` did before the splat). Tests and
/// `benches/cache_splat.rs` compare the two interpolations on the same rays.
pub struct RaysOnly(pub GpuBackend);

impl RayBackend for RaysOnly {
    fn name(&self) -> String {
        format!("{} rays, cpu interpolation", self.0.name())
    }
    fn set_geometry(&mut self, snapshot: &Snapshot) {
        self.0.set_geometry(snapshot)
    }
    fn closest_hit(&self, rays: &[Ray], hits: &mut [Hit]) {
        self.0.closest_hit(rays, hits)
    }
    fn any_hit(&self, rays: &[Ray], occluded: &mut [bool]) {
        self.0.any_hit(rays, occluded)
    }
    fn closest_and_any_hit(
        &self,
        rays: &[Ray],
        hits: &mut [Hit],
        shadows: &[Ray],
        occluded: &mut [bool],
    ) {
        self.0.closest_and_any_hit(rays, hits, shadows, occluded)
    }
    fn ray_counts(&self) -> RayCounts {
        self.0.ray_counts()
    }
    fn preferred_batch(&self) -> usize {
        self.0.preferred_batch()
    }
    fn min_batch(&self) -> usize {
        self.0.min_batch()
    }
    fn failure(&self) -> Option<String> {
        self.0.failure()
    }
}
