//! `path`: the unbiased reference path tracer, the accuracy yardstick of
//! every other method. Camera rays through jittered pixel positions (each
//! pixel box-filtered over its own square, as the reference renders are;
//! more samples at the edge of a seen light: [`super::pixels`]) are handed
//! to the shared path-tracing engine in [`crate::integrator`].

use super::pixels::{
    self, CameraSampler, EmitterEdges, FirstLightSampler, PixelSample, PixelStreams,
};
use super::{FrameContext, FrameStats, Method};
use crate::backend::{Hit, Ray};
use crate::film::Film;
use crate::integrator::{trace_radiance, FirstHitEmission, PathLength, RadianceQuery};
use glam::Vec3;
use rayon::prelude::*;

/// Settings of the path tracer.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PathSettings {
    /// Samples per pixel.
    pub spp: u32,
    pub length: PathLength,
}

impl Default for PathSettings {
    fn default() -> Self {
        PathSettings {
            spp: 16,
            length: PathLength::default(),
        }
    }
}

pub struct PathTracer {
    pub settings: PathSettings,
    /// Wall time of the last frame ([`TRACE_PHASE`]).
    last_seconds: f64,
}

/// The name of `path`'s one phase in [`FrameStats::phase_seconds`]: a
/// frame's time, which `render` and `serve` report per frame. Not the
/// render pass of the caching methods ([`super::RENDER_PHASE`]), which
/// `bench` sets apart from their work on records.
pub const TRACE_PHASE: &str = "trace";

impl PathTracer {
    pub fn new(settings: PathSettings) -> Self {
        PathTracer {
            settings,
            last_seconds: 0.0,
        }
    }
}

impl PathTracer {
    /// Full paths from the camera for `samples`, in order, and their camera
    /// rays.
    fn trace(
        &self,
        ctx: &FrameContext,
        samples: &[PixelSample],
    ) -> (Vec<Ray>, Vec<crate::integrator::RadianceResult>) {
        let mut camera = CameraSampler::default();
        let mut lights = FirstLightSampler::default();
        let queries: Vec<RadianceQuery> = samples
            .iter()
            .map(|s| {
                let (ray, mut rng) = camera.query(ctx, s);
                RadianceQuery {
                    ray,
                    first_light: Some(lights.sample(ctx, s, &mut rng)),
                    rng,
                    weight: Vec3::ONE,
                    first_hit: FirstHitEmission::Include,
                }
            })
            .collect();
        let rays = queries.iter().map(|q| q.ray).collect();
        (rays, trace_radiance(ctx, self.settings.length, queries))
    }
}

impl Method for PathTracer {
    fn name(&self) -> &'static str {
        "path"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        let start = std::time::Instant::now();
        let mut film = Film::new(ctx.width, ctx.height);
        let spp = self.settings.spp.max(1);
        // Tiles of whole pixels, about one backend batch of paths each.
        let pixels_per_tile = ctx.backend.items_per_task(film.pixels.len(), spp as usize);
        film.pixels
            .par_chunks_mut(pixels_per_tile)
            .enumerate()
            .for_each(|(tile, out)| {
                if ctx.abandoned() {
                    return;
                }
                let first = (tile * pixels_per_tile) as u32;
                let mut samples = pixels::tile_samples(first, out.len() as u32, spp);
                let (rays, mut results) = self.trace(ctx, &samples);
                // The first hits decide which pixels are on a light's edge.
                let hits: Vec<Hit> = results.iter().map(|r| r.hit).collect();
                let edges = EmitterEdges::find(
                    ctx,
                    PixelStreams::PerFrame,
                    (&samples, &rays, &hits),
                    spp,
                    None,
                );
                results.extend(self.trace(ctx, edges.extra_samples()).1);
                samples.extend_from_slice(edges.extra_samples());
                let radiance: Vec<Vec3> = results.iter().map(|r| r.radiance).collect();
                edges.resolve(&samples, &radiance, first, out);
            });
        self.last_seconds = start.elapsed().as_secs_f64();
        film
    }

    fn last_frame_stats(&self) -> FrameStats {
        FrameStats {
            phase_seconds: vec![(TRACE_PHASE.into(), self.last_seconds)],
            ..FrameStats::default()
        }
    }
}
