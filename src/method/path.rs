//! `path`: the unbiased reference path tracer, the accuracy yardstick of
//! every other method. Camera rays through jittered pixel positions (each
//! pixel box-filtered over its own square, as the reference renders are) are
//! handed to the shared path-tracing engine in [`crate::integrator`].

use super::{FrameContext, Method};
use crate::backend::Ray;
use crate::film::Film;
use crate::integrator::{trace_radiance, FirstHitEmission, PathLength, RadianceQuery};
use crate::sampling::{stratified_1d, stratified_2d, LightChoice, Rng};
use glam::Vec3;
use rayon::prelude::*;

/// Settings of the path tracer.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
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
}

impl PathTracer {
    pub fn new(settings: PathSettings) -> Self {
        PathTracer { settings }
    }
}

/// The primary ray of pixel sample `sample` (of `spp`) of `pixel`, and the
/// sample's random stream positioned after the jitter. The pixel is
/// box-filtered: positions are uniform over its square, stratified over the
/// pixel's samples ([`stratified_2d`]) — unbiased, and the noise of edges
/// inside the pixel (the rim of a directly seen light) falls faster than
/// with independent jitter.
pub fn camera_query(ctx: &FrameContext, pixel: u32, sample: u32, spp: u32) -> (Ray, Rng) {
    let mut rng = Rng::new(ctx.pixel_key(pixel, sample));
    let jitter = stratified_2d(sample, spp, rng.next_2d(), None);
    let (x, y) = (pixel % ctx.width, pixel / ctx.width);
    let sx = (x as f32 + jitter.x) / ctx.width as f32;
    let sy = (y as f32 + jitter.y) / ctx.height as f32;
    let camera = &ctx.snapshot.camera;
    let dir = camera.direction(sx, sy, ctx.aspect());
    (Ray::new(camera.position, dir, 0.0, f32::INFINITY), rng)
}

/// Sample numbers reserved for the per-pixel scrambles of the stratified
/// light choice (no pixel has this many samples).
const LIGHT_PICK_SCRAMBLE: u32 = u32::MAX;
const LIGHT_POSITION_SCRAMBLE: u32 = u32::MAX - 1;

/// The light sample used at the first surface a pixel sample hits: which
/// light and where on it, both stratified over the pixel's samples like the
/// pixel position, with strata paired by per-pixel random permutations
/// ([`stratified_2d`]). Soft shadows, area-light shading and the choice
/// among several lights are the largest noise left once edges are
/// stratified.
pub fn first_light_sample(
    ctx: &FrameContext,
    pixel: u32,
    rng: &mut Rng,
    sample: u32,
    spp: u32,
) -> LightChoice {
    let scramble = |reserved| Rng::new(ctx.pixel_key(pixel, reserved)).next_u32();
    LightChoice {
        pick: stratified_1d(sample, spp, rng.next_f32(), scramble(LIGHT_PICK_SCRAMBLE)),
        u: stratified_2d(
            sample,
            spp,
            rng.next_2d(),
            Some(scramble(LIGHT_POSITION_SCRAMBLE)),
        ),
    }
}

impl Method for PathTracer {
    fn name(&self) -> &'static str {
        "path"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        let mut film = Film::new(ctx.width, ctx.height);
        let spp = self.settings.spp.max(1);
        // Tiles of whole pixels, about one backend batch of paths each.
        let pixels_per_tile = (ctx.backend.preferred_batch() / spp as usize).max(1);
        film.pixels
            .par_chunks_mut(pixels_per_tile)
            .enumerate()
            .for_each(|(tile, out)| {
                let first = (tile * pixels_per_tile) as u32;
                let queries = (0..out.len() as u32)
                    .flat_map(|i| (0..spp).map(move |s| (first + i, s)))
                    .map(|(pixel, sample)| {
                        let (ray, mut rng) = camera_query(ctx, pixel, sample, spp);
                        RadianceQuery {
                            ray,
                            first_light: Some(first_light_sample(
                                ctx, pixel, &mut rng, sample, spp,
                            )),
                            rng,
                            weight: Vec3::ONE,
                            first_hit: FirstHitEmission::Include,
                        }
                    })
                    .collect();
                let results = trace_radiance(ctx, self.settings.length, queries);
                // Sum each pixel's samples in sample order: bit-exact repeatability.
                let inv_spp = 1.0 / spp as f32;
                for (pixel, samples) in out.iter_mut().zip(results.chunks(spp as usize)) {
                    *pixel = samples.iter().map(|r| r.radiance).sum::<Vec3>() * inv_spp;
                }
            });
        film
    }
}
