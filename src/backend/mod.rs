//! The batched ray interface. Methods trace rays only through
//! [`RayBackend`]; the CPU backend ([`cpu::CpuBackend`]) works everywhere and
//! a GPU backend can replace it without any method changing. A backend with
//! a device also offers the render pass's cache interpolation there
//! ([`RayBackend::cache_splat`], [`gpu::cache_splat`]); the caching methods use it
//! through `method::lookups`, which falls back to the CPU.
//!
//! `Ray` and `Hit` are `#[repr(C)]` plain data so that a GPU backend can upload
//! and read them back as they are.

pub mod cpu;
pub mod gpu;

use crate::scene::Snapshot;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::sync::atomic::{AtomicU64, Ordering};

/// A ray segment `origin + t·dir`, `t ∈ [tmin, tmax]`. `dir` need not be
/// unit length; `t` is in units of `dir`.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Ray {
    pub origin: [f32; 3],
    pub tmin: f32,
    pub dir: [f32; 3],
    pub tmax: f32,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray {
            origin: origin.to_array(),
            tmin,
            dir: dir.to_array(),
            tmax,
        }
    }

    /// A shadow segment from `from` towards `to`, stopping just short of `to`.
    pub fn segment(from: Vec3, to: Vec3) -> Self {
        Ray::new(from, to - from, 0.0, 1.0 - SHADOW_EPSILON)
    }

    pub fn origin(&self) -> Vec3 {
        Vec3::from_array(self.origin)
    }

    pub fn dir(&self) -> Vec3 {
        Vec3::from_array(self.dir)
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin() + self.dir() * t
    }
}

/// Relative shortening of shadow segments so they do not hit the light they
/// aim at (its triangle lies exactly at t = 1).
pub const SHADOW_EPSILON: f32 = 1e-4;

/// Closest hit: the triangle (snapshot triangle id), its object, the
/// barycentrics `(u, v)` of the hit (`p = p0(1−u−v) + p1·u + p2·v`) and `t`.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Hit {
    pub t: f32,
    pub triangle: u32,
    pub object: u32,
    pub u: f32,
    pub v: f32,
}

impl Hit {
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        triangle: u32::MAX,
        object: u32::MAX,
        u: 0.0,
        v: 0.0,
    };

    pub fn is_hit(&self) -> bool {
        self.triangle != u32::MAX
    }
}

/// Statistics a backend keeps: rays traced since creation, and in how many
/// calls (on a GPU, each a dispatch with its fixed cost).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    pub closest: u64,
    pub any: u64,
    pub calls: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.closest + self.any
    }
}

/// The counters behind a backend's [`RayCounts`], updated by its calls
/// from any thread.
#[derive(Debug, Default)]
pub(crate) struct RayCounters {
    closest: AtomicU64,
    any: AtomicU64,
    calls: AtomicU64,
}

impl RayCounters {
    /// One call that traced `closest` closest-hit and `any` any-hit rays.
    pub(crate) fn add_call(&self, closest: usize, any: usize) {
        self.closest.fetch_add(closest as u64, Ordering::Relaxed);
        self.any.fetch_add(any as u64, Ordering::Relaxed);
        self.calls.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn counts(&self) -> RayCounts {
        RayCounts {
            closest: self.closest.load(Ordering::Relaxed),
            any: self.any.load(Ordering::Relaxed),
            calls: self.calls.load(Ordering::Relaxed),
        }
    }

    pub(crate) fn reset(&self) {
        for counter in [&self.closest, &self.any, &self.calls] {
            counter.store(0, Ordering::Relaxed);
        }
    }
}

/// Batched ray tracing over the geometry of one frame.
pub trait RayBackend: Send + Sync {
    /// Human-readable name, e.g. "cpu (2 threads)".
    fn name(&self) -> String;

    /// Makes `snapshot` the geometry rays are traced against. Static
    /// triangles are (re)built only when they changed; dynamic ones every call.
    fn set_geometry(&mut self, snapshot: &Snapshot);

    /// For each ray, the closest intersection in `[tmin, tmax]` or [`Hit::MISS`].
    fn closest_hit(&self, rays: &[Ray], hits: &mut [Hit]);

    /// For each ray, whether anything intersects it in `[tmin, tmax]`.
    fn any_hit(&self, rays: &[Ray], occluded: &mut [bool]);

    /// [`Self::closest_hit`] of `rays` and [`Self::any_hit`] of `shadows`
    /// together, for callers that have both at hand (a path tracer traces
    /// bounce k + 1 with bounce k's shadow rays). A GPU backend runs them
    /// in one round trip, halving the fixed cost of a path's bounces; the
    /// results are those of the two calls.
    fn closest_and_any_hit(
        &self,
        rays: &[Ray],
        hits: &mut [Hit],
        shadows: &[Ray],
        occluded: &mut [bool],
    ) {
        if !rays.is_empty() {
            self.closest_hit(rays, hits);
        }
        if !shadows.is_empty() {
            self.any_hit(shadows, occluded);
        }
    }

    /// Rays traced so far.
    fn ray_counts(&self) -> RayCounts;

    /// Items (pixels, records, queries) per parallel task when `total`
    /// items are traced `rays_per_item` rays a batch: about one
    /// [`Self::preferred_batch`] a task, but cut so that every thread of
    /// the pool gets two tasks, never below [`Self::min_batch`] rays a task. A
    /// task's shading runs on one thread: on an H100 a GPU's preferred
    /// batch of 1 Mi rays made a 256×256 frame one render tile, shaded on
    /// one of 16 cores. The split changes scheduling only: every sample and
    /// record has its own random stream.
    fn items_per_task(&self, total: usize, rays_per_item: usize) -> usize {
        let rays_per_item = rays_per_item.max(1);
        let preferred = (self.preferred_batch() / rays_per_item).max(1);
        let floor = self.min_batch().div_ceil(rays_per_item);
        let spread = total.div_ceil(2 * rayon::current_num_threads());
        preferred.min(spread).max(floor).max(1)
    }

    /// Batch size that keeps this backend busy.
    fn preferred_batch(&self) -> usize;

    /// The fewest rays a call should carry for the call's fixed cost not to
    /// dominate: work split over threads is split no finer than this (1 on
    /// the CPU, where a call costs nothing; tens of thousands on a GPU,
    /// where each call is a dispatch, a copy back and a wait).
    fn min_batch(&self) -> usize {
        1
    }

    /// Why this backend stopped working, if it did (a GPU device lost, out
    /// of memory, a scene too large for it). The tracing methods cannot
    /// return errors — they run deep inside rayon tasks — so a backend that
    /// fails records the first error here and answers every later ray with
    /// a miss; whoever drives a frame checks this afterwards and discards
    /// the frame (the renderer does, see `Renderer::try_render_frame`).
    fn failure(&self) -> Option<String> {
        None
    }

    /// The render pass's cache interpolation on this backend's device
    /// (TRC §5 radiance cache splatting), for backends that have one: the
    /// GPU backend. `ic`, `trc` and `tcg` interpolate on the CPU otherwise. An
    /// error of the splat fails the backend like a ray error
    /// ([`gpu::cache_splat::CacheSplat::fail`]).
    fn cache_splat(&self) -> Option<&gpu::cache_splat::CacheSplat> {
        None
    }
}
