//! The CPU ray backend: obvhs traversal of the frame's [`SceneBvh`],
//! parallel over the rays of a batch with rayon.

use super::{Hit, Ray, RayBackend, RayCounts};
use crate::accel::{BuildTimes, SceneBvh};
use crate::scene::Snapshot;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// Rays per rayon task: large enough to amortise scheduling, small enough
/// that a batch of a few thousand rays still spreads over all cores.
const RAYS_PER_TASK: usize = 256;

#[derive(Default)]
pub struct CpuBackend {
    bvh: SceneBvh,
    closest: AtomicU64,
    any: AtomicU64,
    calls: AtomicU64,
    last_build: BuildTimes,
}

impl CpuBackend {
    pub fn new() -> Self {
        Self::default()
    }

    /// BVH build times of the last [`RayBackend::set_geometry`] call.
    pub fn last_build(&self) -> BuildTimes {
        self.last_build
    }
}

impl RayBackend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }

    fn set_geometry(&mut self, snapshot: &Snapshot) {
        self.last_build = self.bvh.update(snapshot);
    }

    fn closest_hit(&self, rays: &[Ray], hits: &mut [Hit]) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        rays.par_iter()
            .zip(hits.par_iter_mut())
            .with_min_len(RAYS_PER_TASK)
            .for_each(|(ray, hit)| *hit = self.bvh.closest_hit(ray));
        self.closest.fetch_add(rays.len() as u64, Ordering::Relaxed);
        self.calls.fetch_add(1, Ordering::Relaxed);
    }

    fn any_hit(&self, rays: &[Ray], occluded: &mut [bool]) {
        assert_eq!(rays.len(), occluded.len(), "one result slot per ray");
        rays.par_iter()
            .zip(occluded.par_iter_mut())
            .with_min_len(RAYS_PER_TASK)
            .for_each(|(ray, o)| *o = self.bvh.occluded(ray));
        self.any.fetch_add(rays.len() as u64, Ordering::Relaxed);
        self.calls.fetch_add(1, Ordering::Relaxed);
    }

    fn ray_counts(&self) -> RayCounts {
        RayCounts {
            closest: self.closest.load(Ordering::Relaxed),
            any: self.any.load(Ordering::Relaxed),
            calls: self.calls.load(Ordering::Relaxed),
        }
    }

    fn preferred_batch(&self) -> usize {
        // Several batches run at once (one per pixel tile), so a modest size
        // keeps each in cache.
        4096
    }
}
