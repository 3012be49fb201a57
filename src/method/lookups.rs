//! The render pass's cache lookups, a tile at a time: TRC Eq. 1–4 at every
//! pixel sample's shading point, on the CPU through the cache's octree, or
//! on the GPU by radiance cache splatting (TRC §5,
//! [`crate::backend::gpu_cache`]) when the ray backend has a device. Both
//! give the same usable records and the same irradiance up to f32
//! summation order; `ic` and `trc` do not know which one runs.

use super::FrameContext;
use crate::backend::gpu_cache::{CacheSplat, GpuLookup, PreparedCache};
use crate::cache::{Interpolated, IrradianceCache};
use glam::Vec3;
use std::sync::atomic::{AtomicBool, Ordering};

/// A shading point and its unit normal.
pub(crate) type Lookup = (Vec3, Vec3);

/// How one render pass interpolates its cache.
pub(crate) enum Interpolation<'a> {
    /// [`IrradianceCache::interpolate_marking`], lookup by lookup.
    Cpu {
        cache: &'a IrradianceCache,
        gradients: bool,
    },
    /// The records binned and uploaded once for the pass; each tile's
    /// lookups splatted in one dispatch.
    Gpu {
        splat: &'a CacheSplat,
        prepared: PreparedCache,
    },
}

impl<'a> Interpolation<'a> {
    /// The GPU splat when the frame's backend has one, else the CPU.
    ///
    /// Panics when the device fails, as the GPU backend's ray methods do.
    pub(crate) fn new(ctx: &'a FrameContext, cache: &'a IrradianceCache, gradients: bool) -> Self {
        match ctx.backend.cache_splat() {
            Some(splat) => Interpolation::Gpu {
                splat,
                prepared: splat
                    .prepare(cache.records(), cache.accuracy, gradients)
                    .unwrap_or_else(|e| panic!("{e}")),
            },
            None => Interpolation::Cpu { cache, gradients },
        }
    }

    /// The interpolated irradiance at each lookup (`None` where no record
    /// is usable), in order. With `used`, every record used is flagged.
    pub(crate) fn interpolate(
        &self,
        lookups: &[Lookup],
        used: Option<&[AtomicBool]>,
    ) -> Vec<Option<Interpolated>> {
        match self {
            Interpolation::Cpu { cache, gradients } => lookups
                .iter()
                .map(|&(p, n)| {
                    cache.interpolate_marking(p, n, *gradients, |i| {
                        if let Some(used) = used {
                            used[i].store(true, Ordering::Relaxed);
                        }
                    })
                })
                .collect(),
            Interpolation::Gpu { splat, prepared } => {
                let points: Vec<GpuLookup> =
                    lookups.iter().map(|&(p, n)| GpuLookup::new(p, n)).collect();
                splat
                    .interpolate(prepared, &points, used)
                    .unwrap_or_else(|e| panic!("{e}"))
                    .iter()
                    .map(|s| s.interpolated())
                    .collect()
            }
        }
    }

    /// Flags every record usable at some lookup, without interpolating
    /// (the CPU skips the extrapolation; the GPU pass is the same one).
    pub(crate) fn mark_used(&self, lookups: &[Lookup], used: &[AtomicBool]) {
        match self {
            Interpolation::Cpu { cache, .. } => {
                for &(p, n) in lookups {
                    cache.for_each_usable_indexed(p, n, |i, _, _| {
                        used[i].store(true, Ordering::Relaxed)
                    });
                }
            }
            Interpolation::Gpu { .. } => {
                self.interpolate(lookups, Some(used));
            }
        }
    }
}
