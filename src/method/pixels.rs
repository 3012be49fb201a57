//! Which samples a pixel takes: the camera pass every method shares.
//!
//! Every pixel takes `spp` samples, box-filtered over its square and
//! stratified among themselves. A pixel on the edge of a directly seen light
//! (some of its samples see an emitter's emitting side, others do not) then
//! takes `emitter_edge_factor · spp` more, stratified among themselves:
//! adaptive supersampling where the image's contrast is largest (Mitchell,
//! "Generating antialiased images at low sampling densities", 1987), decided
//! from the first hits alone, before any shading. Why: the rim of a seen
//! light is a few pixels many times brighter than their neighbours, and with
//! `spp` samples their coverage noise is most of an all-pixel error
//! (DESIGN.md "Measuring") whatever the method does about lighting. The
//! same rule in `path` and in the caching methods keeps their comparison at
//! equal samples per pixel. Every sample is uniform over its pixel and the
//! pixel is the mean of all its samples, so the estimate stays unbiased.

use super::FrameContext;
use crate::backend::{Hit, Ray};
use crate::light::emitting_cosine;
use crate::sampling::{stratified_1d, stratified_2d, LightChoice, Rng};
use glam::Vec3;

/// Extra samples an emitter-edge pixel takes, in units of `spp` (the
/// default of [`crate::render::FrameSettings::emitter_edge_factor`]; 0 turns
/// the supersampling off). 4 takes the rim pixels to 5× the samples: their
/// coverage noise falls by √5 ≈ 2.2 for a few percent more samples in all.
pub const DEFAULT_EMITTER_EDGE_FACTOR: u32 = 4;

/// One sample of one pixel: its random streams are keyed by `key`, its
/// position is stratum `stratum` of `strata` over the pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelSample {
    pub pixel: u32,
    pub key: u32,
    pub stratum: u32,
    pub strata: u32,
}

impl PixelSample {
    /// Sample `sample` of the `spp` every pixel takes.
    pub fn base(pixel: u32, sample: u32, spp: u32) -> Self {
        PixelSample {
            pixel,
            key: sample,
            stratum: sample,
            strata: spp,
        }
    }
}

/// The `spp` samples of each of `count` pixels from `first`, pixel by pixel.
pub fn tile_samples(first: u32, count: u32, spp: u32) -> Vec<PixelSample> {
    (first..first + count)
        .flat_map(|pixel| (0..spp).map(move |s| PixelSample::base(pixel, s, spp)))
        .collect()
}

/// Whether a camera ray's first hit is the emitting side of a light.
pub fn sees_emitter(ctx: &FrameContext, ray: &Ray, hit: &Hit) -> bool {
    if !hit.is_hit() {
        return false;
    }
    let t = hit.triangle as usize;
    let material = &ctx.scene.materials[ctx.snapshot.tri_material[t] as usize];
    material.is_emissive()
        && emitting_cosine(
            &ctx.snapshot.triangles[t],
            material.double_sided,
            -ray.dir().normalize(),
        )
        .is_some()
}

/// The extra samples of the emitter-edge pixels among `base` (`spp` a
/// pixel, pixel by pixel, with their camera rays and first hits): keys
/// `spp..`, stratified among themselves.
pub fn edge_samples(
    ctx: &FrameContext,
    base: &[PixelSample],
    rays: &[Ray],
    hits: &[Hit],
    spp: u32,
) -> Vec<PixelSample> {
    let extra = ctx.emitter_edge_factor * spp;
    if extra == 0 {
        return Vec::new();
    }
    let sees: Vec<bool> = rays
        .iter()
        .zip(hits)
        .map(|(ray, hit)| sees_emitter(ctx, ray, hit))
        .collect();
    base.chunks(spp as usize)
        .zip(sees.chunks(spp as usize))
        .filter(|(_, sees)| sees.iter().any(|&s| s) && !sees.iter().all(|&s| s))
        .flat_map(|(pixel, _)| {
            let pixel = pixel[0].pixel;
            (0..extra).map(move |j| PixelSample {
                pixel,
                key: spp + j,
                stratum: j,
                strata: extra,
            })
        })
        .collect()
}

/// Each pixel's mean over its samples: `out[p − first]` for the pixels `p`
/// of `samples`, summed in sample order (bit-exact repeatability).
pub fn resolve(samples: &[PixelSample], radiance: &[Vec3], first: u32, out: &mut [Vec3]) {
    let mut counts = vec![0u32; out.len()];
    out.fill(Vec3::ZERO);
    for (s, l) in samples.iter().zip(radiance) {
        let i = (s.pixel - first) as usize;
        out[i] += *l;
        counts[i] += 1;
    }
    for (pixel, n) in out.iter_mut().zip(counts) {
        *pixel /= n.max(1) as f32;
    }
}

/// The primary ray of sample `s` and the sample's random stream positioned
/// after the jitter. The pixel is box-filtered: positions are uniform over
/// its square, stratified over the samples of its set ([`stratified_2d`]) —
/// unbiased, and the noise of edges inside the pixel falls faster than with
/// independent jitter.
pub fn camera_query(ctx: &FrameContext, s: &PixelSample) -> (Ray, Rng) {
    let mut rng = Rng::new(ctx.pixel_key(s.pixel, s.key));
    let jitter = stratified_2d(s.stratum, s.strata, rng.next_2d(), None);
    let (x, y) = (s.pixel % ctx.width, s.pixel / ctx.width);
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

/// The random permutations, one per pixel, that pair the strata of its
/// samples' first light samples with their pixel strata
/// ([`FirstLightSampler::sample`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct LightScrambles {
    pick: u32,
    position: u32,
}

impl LightScrambles {
    fn of(ctx: &FrameContext, pixel: u32) -> Self {
        let scramble = |reserved| Rng::new(ctx.pixel_key(pixel, reserved)).next_u32();
        LightScrambles {
            pick: scramble(LIGHT_PICK_SCRAMBLE),
            position: scramble(LIGHT_POSITION_SCRAMBLE),
        }
    }
}

/// Draws the first light samples of a run of pixel samples, hashing each
/// pixel's scrambles once for the run of its samples rather than once per
/// sample: two keyed generators a sample, where one a pixel will do (the
/// render pass of `trc` at 64×64 took 9 % less time without them).
#[derive(Default)]
pub struct FirstLightSampler {
    last: Option<(u32, LightScrambles)>,
}

impl FirstLightSampler {
    /// The light sample used at the first surface sample `s` hits: which
    /// light and where on it, both stratified over the samples of the
    /// sample's set like the pixel position, with strata paired by
    /// per-pixel random permutations ([`stratified_2d`]). Soft shadows,
    /// area-light shading and the choice among several lights are the
    /// largest noise left once edges are stratified.
    pub fn sample(&mut self, ctx: &FrameContext, s: &PixelSample, rng: &mut Rng) -> LightChoice {
        let scrambles = match self.last {
            Some((pixel, scrambles)) if pixel == s.pixel => scrambles,
            _ => {
                let scrambles = LightScrambles::of(ctx, s.pixel);
                self.last = Some((s.pixel, scrambles));
                scrambles
            }
        };
        LightChoice {
            pick: stratified_1d(s.stratum, s.strata, rng.next_f32(), scrambles.pick),
            u: stratified_2d(s.stratum, s.strata, rng.next_2d(), Some(scrambles.position)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolve_averages_each_pixel_over_all_its_samples() {
        let samples = [
            PixelSample::base(5, 0, 2),
            PixelSample::base(5, 1, 2),
            PixelSample::base(6, 0, 2),
            PixelSample::base(6, 1, 2),
            PixelSample {
                pixel: 5,
                key: 2,
                stratum: 0,
                strata: 2,
            },
            PixelSample {
                pixel: 5,
                key: 3,
                stratum: 1,
                strata: 2,
            },
        ];
        let radiance = [1.0, 2.0, 3.0, 5.0, 4.0, 5.0].map(Vec3::splat);
        let mut out = [Vec3::ONE * 9.0; 2];
        resolve(&samples, &radiance, 5, &mut out);
        assert_eq!(out, [Vec3::splat(3.0), Vec3::splat(4.0)]);
    }
}
