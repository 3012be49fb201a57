//! The render pass's cache lookups, a tile at a time: TRC Eq. 1–4 at each
//! shading point (one per pixel and triangle, `render_pass::pixel_lookups`), on the
//! CPU through the cache's octree, or
//! on the GPU by radiance cache splatting (TRC §5,
//! [`crate::backend::gpu::cache_splat`]) when the ray backend has a device. Both
//! give the same usable records and the same irradiance up to f32
//! summation order; `ic`, `trc` and `tcg` do not know which one runs.
//!
//! A GPU error cannot be returned from a render tile: it fails the backend
//! ([`CacheSplat::fail`], as a ray error does) and the lookups are
//! answered on the CPU, so the results stay right while the renderer, which
//! checks the backend after the frame, discards it.

use super::FrameContext;
use crate::backend::gpu::cache_splat::{CacheSplat, GpuLookup, PreparedCache};
use crate::backend::{Hit, Ray};
use crate::cache::{Interpolated, IrradianceCache, LookupPoint};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// A shading point and its unit normal.
pub(crate) type ShadingPoint = (Vec3, Vec3);

/// Each shading point `(p, n)` as a lookup, with its clearance measured
/// by one ray from `p` along `n` (the nearest hit's distance, or
/// [`LookupPoint::OPEN`] on a miss): what keeps a record from being used
/// under a surface it never saw ([`crate::cache::IrradianceRecord::weight`]).
///
/// The rays are made and read in parallel, as they are traced: the fill
/// stage measures a whole frame's pixel centres at once, and on the
/// render's one thread that kept the other threads waiting.
pub(crate) fn measure_clearance(ctx: &FrameContext, points: &[ShadingPoint]) -> Vec<LookupPoint> {
    let rays: Vec<Ray> = points
        .par_iter()
        .map(|&(p, n)| Ray::new(ctx.ray_offset.origin(p, n, n), n, 0.0, f32::INFINITY))
        .collect();
    let mut hits = vec![Hit::MISS; rays.len()];
    ctx.backend.closest_hit(&rays, &mut hits);
    points
        .par_iter()
        .zip(&hits)
        .map(|(&(p, n), hit)| {
            let clearance = if hit.is_hit() {
                hit.t
            } else {
                LookupPoint::OPEN
            };
            LookupPoint::new(p, n, clearance)
        })
        .collect()
}

/// How one render pass interpolates its cache.
pub(crate) enum Interpolation<'a> {
    /// [`IrradianceCache::interpolate_marking`], lookup by lookup.
    Cpu {
        cache: &'a IrradianceCache,
        gradients: bool,
    },
    /// The records binned and uploaded once for the pass; each tile's
    /// lookups splatted in one dispatch (`cache` answers them if the GPU
    /// fails).
    Gpu {
        splat: &'a CacheSplat,
        prepared: PreparedCache,
        cache: &'a IrradianceCache,
        gradients: bool,
    },
}

impl<'a> Interpolation<'a> {
    /// The GPU splat when the frame's backend has one (and has not
    /// failed), else the CPU.
    pub(crate) fn new(ctx: &'a FrameContext, cache: &'a IrradianceCache, gradients: bool) -> Self {
        let cpu = Interpolation::Cpu { cache, gradients };
        let Some(splat) = ctx.backend.cache_splat().filter(|s| !s.has_failed()) else {
            return cpu;
        };
        match splat.prepare(cache.records(), cache.accuracy, gradients) {
            Ok(prepared) => Interpolation::Gpu {
                splat,
                prepared,
                cache,
                gradients,
            },
            Err(e) => {
                splat.fail(&e);
                cpu
            }
        }
    }

    /// The interpolated irradiance at each lookup (`None` where no record
    /// is usable), in order. With `used`, every record used is flagged.
    pub(crate) fn interpolate(
        &self,
        lookups: &[LookupPoint],
        used: Option<&[AtomicBool]>,
    ) -> Vec<Option<Interpolated>> {
        match self {
            Interpolation::Cpu { cache, gradients } => {
                interpolate_on_cpu(cache, *gradients, lookups, used)
            }
            Interpolation::Gpu {
                splat,
                prepared,
                cache,
                gradients,
            } => {
                let points: Vec<GpuLookup> = lookups.iter().map(GpuLookup::new).collect();
                match splat.interpolate(prepared, &points, used) {
                    Ok(sums) => sums.iter().map(|s| s.interpolated()).collect(),
                    Err(e) => {
                        splat.fail(&e);
                        interpolate_on_cpu(cache, *gradients, lookups, used)
                    }
                }
            }
        }
    }

    /// The cache interpolated (the CPU's, whichever answers the lookups).
    pub(crate) fn cache(&self) -> &'a IrradianceCache {
        match self {
            Interpolation::Cpu { cache, .. } | Interpolation::Gpu { cache, .. } => cache,
        }
    }

    /// Flags every record usable at some lookup, without interpolating
    /// (the CPU skips the extrapolation; the GPU pass is the same one).
    pub(crate) fn mark_used(&self, lookups: &[LookupPoint], used: &[AtomicBool]) {
        match self {
            Interpolation::Cpu { cache, .. } => mark_on_cpu(cache, lookups, used),
            Interpolation::Gpu { .. } => {
                self.interpolate(lookups, Some(used));
            }
        }
    }
}

/// [`IrradianceCache::interpolate_marking`] at each lookup.
fn interpolate_on_cpu(
    cache: &IrradianceCache,
    gradients: bool,
    lookups: &[LookupPoint],
    used: Option<&[AtomicBool]>,
) -> Vec<Option<Interpolated>> {
    lookups
        .iter()
        .map(|at| {
            cache.interpolate_marking(at, gradients, |i| {
                if let Some(used) = used {
                    used[i].store(true, Ordering::Relaxed);
                }
            })
        })
        .collect()
}

/// Flags the records usable at each lookup (no extrapolation needed).
fn mark_on_cpu(cache: &IrradianceCache, lookups: &[LookupPoint], used: &[AtomicBool]) {
    for at in lookups {
        cache.for_each_usable_indexed(at, |i, _, _| used[i].store(true, Ordering::Relaxed));
    }
}
