//! The CPU ray backend: obvhs traversal of the frame's [`SceneBvh`],
//! parallel over the rays of a batch with rayon.

use super::{Hit, Ray, RayBackend, RayCounters, RayCounts};
use crate::accel::{BuildTimes, SceneBvh};
use crate::scene::Snapshot;
use rayon::prelude::*;

/// Rays per rayon task: large enough to amortise scheduling, small enough
/// that a batch of a few thousand rays still spreads over all cores.
const RAYS_PER_TASK: usize = 256;

#[derive(Default)]
pub struct CpuBackend {
    bvh: SceneBvh,
    counters: RayCounters,
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
        match rayon::current_num_threads() {
            1 => "cpu (1 thread)".to_string(),
            n => format!("cpu ({n} threads)"),
        }
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
        self.counters.add_call(rays.len(), 0);
    }

    fn any_hit(&self, rays: &[Ray], occluded: &mut [bool]) {
        assert_eq!(rays.len(), occluded.len(), "one result slot per ray");
        rays.par_iter()
            .zip(occluded.par_iter_mut())
            .with_min_len(RAYS_PER_TASK)
            .for_each(|(ray, o)| *o = self.bvh.occluded(ray));
        self.counters.add_call(0, rays.len());
    }

    fn ray_counts(&self) -> RayCounts {
        self.counters.counts()
    }

    fn preferred_batch(&self) -> usize {
        // Several batches run at once (one per pixel tile), so a modest size
        // keeps each in cache.
        4096
    }
}
