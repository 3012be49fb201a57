//! The rendering stage that `ic` and `trc` share (EAS Algorithm 1, lines
//! 18–24): per pixel sample the outgoing radiance is split as
//! `L = Le + L_direct + kd/π·E_indirect + L_glossy`:
//! - direct light by next-event estimation (one light sample per pixel
//!   sample; the glossy lobe's part MIS-weighted against lobe sampling),
//! - indirect diffuse from the cache: `E_indirect` interpolated with
//!   gradients (TRC Eq. 1–4), looked up once per pixel and triangle for
//!   the pixel's samples on it (`pixel_lookups`) — on the CPU, or on the
//!   GPU by radiance cache splatting (TRC §5, `backend::gpu_cache`) when
//!   the ray backend is the GPU one,
//! - the glossy lobe by path tracing from a lobe sample, or with
//!   `--ic-glossy eas` its indirect light from the records' equivalent
//!   area light sources (EAS paper Eq. 17, [`crate::cache::eas`]) and the
//!   lobe sample's ray traced to its first hit only, for the emission
//!   there that MIS weighs against the light sample.
//!
//! The methods differ only in the cache they hand it and in how the
//! path-traced fallbacks of uncovered samples draw their random streams
//! ([`FallbackStreams`]). `trc` also asks which records the pass uses
//! (`render_pass`'s `used`, `mark_used`).

use super::ic::{GlossyLobe, IcSettings};
use super::lookups::{measure_clearance, Interpolation, Lookup, ShadingPoint};
use super::pixels::{self, CameraSampler, EmitterEdges, FirstLightSampler, PixelSample};
use super::{FrameContext, FrameStats};
use crate::backend::{Hit, Ray};
use crate::cache::gather::GatherPoint;
use crate::cache::{eas, Interpolated, IrradianceCache};
use crate::film::Film;
use crate::integrator::{
    offset_origin, trace_radiance, FirstHitEmission, PathLength, RadianceQuery,
};
use crate::light::{emitting_cosine, TriangleSampling};
use crate::material::Bsdf;
use crate::sampling::{cosine_hemisphere, power_heuristic, LightChoice, Rng, SampleKey};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::atomic::AtomicBool;

/// A shaded hit: position, normals and BSDF.
pub(crate) struct Surface<'a> {
    p: Vec3,
    ng: Vec3,
    pub(crate) wo: Vec3,
    pub(crate) bsdf: Bsdf,
    pub(crate) material: &'a crate::scene::Material,
    pub(crate) triangle: &'a crate::scene::Triangle,
}

impl<'a> Surface<'a> {
    pub(crate) fn at(ctx: &'a FrameContext, ray: &Ray, hit: &Hit) -> Option<Self> {
        if !hit.is_hit() {
            return None;
        }
        let snapshot = ctx.snapshot;
        let triangle = &snapshot.triangles[hit.triangle as usize];
        let material = &ctx.scene.materials[snapshot.tri_material[hit.triangle as usize] as usize];
        let wo = -ray.dir().normalize();
        Some(Surface {
            p: ray.at(hit.t),
            ng: triangle.geometric_normal(),
            wo,
            bsdf: Bsdf::new(material, triangle.shading_normal(hit.u, hit.v), wo),
            material,
            triangle,
        })
    }

    pub(crate) fn gather_point(&self) -> GatherPoint {
        GatherPoint {
            position: self.p,
            normal: self.bsdf.normal(),
            geometric_normal: self.ng,
        }
    }
}

/// Rendering stage (EAS Algorithm 1, lines 18–24), tile by tile. With
/// `used` (one flag per cache record), every record that contributes to a
/// pixel sample is flagged (`trc`'s replace-or-drop rule). The cache is
/// interpolated on the GPU when the backend has one ([`Interpolation`]).
pub(crate) fn render_pass(
    ctx: &FrameContext,
    cache: &IrradianceCache,
    settings: &IcSettings,
    fallback: FallbackStreams,
    used: Option<&[AtomicBool]>,
    stats: &mut FrameStats,
) -> Film {
    let mut film = Film::new(ctx.width, ctx.height);
    let interpolation = Interpolation::new(ctx, cache, settings.gradients);
    let spp = settings.spp.max(1);
    let pixels_per_tile = (ctx.backend.preferred_batch() / spp as usize).max(1);
    let tile_stats: Vec<FrameStats> = film
        .pixels
        .par_chunks_mut(pixels_per_tile)
        .enumerate()
        .map(|(tile, out)| {
            let first = (tile * pixels_per_tile) as u32;
            let pass = TilePass {
                interpolation: &interpolation,
                settings,
                fallback,
                used,
            };
            render_tile(ctx, &pass, first, out)
        })
        .collect();
    for t in tile_stats {
        stats.lookups += t.lookups;
        stats.lookup_records += t.lookup_records;
        stats.fallback_lookups += t.fallback_lookups;
    }
    film
}

/// Flags every record that [`render_pass`] would use for some pixel sample
/// of this frame, without rendering: the same camera samples, the same
/// shading points and the same usability test (`w ≥ 1/a`, which depends on
/// the records' positions, normals and radii, not on their values). `trc`'s
/// first pass with interpolated gradients (TRC §4.5, two passes) decides
/// replace-or-drop from it before the frame is rendered.
pub(crate) fn mark_used(
    ctx: &FrameContext,
    cache: &IrradianceCache,
    settings: &IcSettings,
    used: &[AtomicBool],
) {
    let interpolation = Interpolation::new(ctx, cache, settings.gradients);
    let spp = settings.spp.max(1);
    let n_pixels = ctx.width * ctx.height;
    let pixels_per_tile = (ctx.backend.preferred_batch() / spp as usize).max(1) as u32;
    let tiles: Vec<u32> = (0..n_pixels).step_by(pixels_per_tile as usize).collect();
    tiles.into_par_iter().for_each(|first| {
        let count = pixels_per_tile.min(n_pixels - first);
        let (primary, _) = PrimarySamples::trace(ctx, first, count, spp);
        let surfaces = primary.surfaces(ctx);
        let (lookups, _) = pixel_lookups(
            ctx,
            &surfaces,
            &primary.hits,
            &primary.samples,
            settings.glossy,
        );
        interpolation.mark_used(&lookups, used);
    });
}

/// A path-traced part of a pixel sample (glossy lobe, or diffuse indirect
/// where no record is usable) and the sample it belongs to.
struct Deferred {
    sample: usize,
    query: RadianceQuery,
    /// Only the emission at the query's first hit is wanted (a glossy lobe
    /// whose indirect light the records' sources give).
    first_hit_only: bool,
}

/// A tile's pixel samples (`spp` a pixel, then the extra ones of pixels on
/// the edge of a seen light: [`pixels`]) with their camera rays, random
/// streams (positioned after the jitter) and first hits.
#[derive(Default)]
pub(crate) struct PrimarySamples {
    pub(crate) samples: Vec<PixelSample>,
    pub(crate) rays: Vec<Ray>,
    pub(crate) rngs: Vec<Rng>,
    pub(crate) hits: Vec<Hit>,
}

impl PrimarySamples {
    /// The `spp` samples of the `count` pixels from `first`, then the extra
    /// ones of the edge pixels among them, which the returned edges resolve.
    pub(crate) fn trace(
        ctx: &FrameContext,
        first: u32,
        count: u32,
        spp: u32,
    ) -> (Self, EmitterEdges) {
        let mut primary = PrimarySamples::default();
        primary.add(ctx, &pixels::tile_samples(first, count, spp));
        // The first hits decide which pixels are on a light's edge.
        let edges = EmitterEdges::find(ctx, &primary.samples, &primary.rays, &primary.hits, spp);
        primary.add(ctx, edges.extra_samples());
        (primary, edges)
    }

    /// Appends `samples`, tracing their camera rays.
    fn add(&mut self, ctx: &FrameContext, samples: &[PixelSample]) {
        let start = self.rays.len();
        let mut camera = CameraSampler::default();
        for s in samples {
            let (ray, rng) = camera.query(ctx, s);
            self.rays.push(ray);
            self.rngs.push(rng);
        }
        self.hits.resize(self.rays.len(), Hit::MISS);
        ctx.backend
            .closest_hit(&self.rays[start..], &mut self.hits[start..]);
        self.samples.extend_from_slice(samples);
    }

    pub(crate) fn surfaces<'a>(&self, ctx: &'a FrameContext) -> Vec<Option<Surface<'a>>> {
        self.rays
            .iter()
            .zip(&self.hits)
            .map(|(ray, hit)| Surface::at(ctx, ray, hit))
            .collect()
    }
}

/// The render pass's cache lookups: one per pixel and triangle hit, at the
/// mean shading point and normal of the pixel's samples on that triangle,
/// rather than one per pixel sample; and, per sample, its lookup (`None`
/// for samples that do not look the cache up).
///
/// Why: the interpolated irradiance (TRC Eq. 1–4) varies smoothly over a
/// pixel's footprint, and the mean of a linear function over the samples is
/// its value at their mean point, so sharing the lookup loses only the
/// curvature of `E` within one pixel, far below the cache's own
/// interpolation error. The lookups, about a quarter of the render pass at
/// 16 samples per pixel, fall to about one per pixel. Each sample keeps its
/// own visibility, emission, direct light and glossy lobe: the shading rate
/// of the cache is decoupled from the visibility sampling, as in MSAA.
/// Samples on different triangles never share (an edge, a corner), nor do
/// samples spread wider than their lookup's clearance ([`split_narrow`]).
fn pixel_lookups(
    ctx: &FrameContext,
    surfaces: &[Option<Surface>],
    hits: &[Hit],
    samples: &[PixelSample],
    glossy: GlossyLobe,
) -> (Vec<Lookup>, Vec<Option<u32>>) {
    let shading_points: Vec<Option<(u32, ShadingPoint)>> = surfaces
        .iter()
        .zip(hits)
        .map(|(surface, hit)| {
            let s = surface.as_ref()?;
            let diffuse = s.bsdf.diffuse_albedo().max_element() > 0.0;
            let radiance = glossy == GlossyLobe::Eas && s.bsdf.has_specular();
            (!s.bsdf.is_black() && (diffuse || radiance))
                .then(|| (hit.triangle, (s.p, s.bsdf.normal())))
        })
        .collect();
    let pixel_of: Vec<u32> = samples.iter().map(|s| s.pixel).collect();
    let (points, of_sample) = share_lookups(&shading_points, &pixel_of);
    let shared = measure_clearance(ctx, &points);
    let (mut lookups, of_sample, own) = split_narrow(shared, of_sample, &shading_points);
    lookups.extend(measure_clearance(ctx, &own));
    (lookups, of_sample)
}

/// Gives each sample of a shared lookup its own lookup (and clearance)
/// where the samples lie farther from the shared point than its
/// clearance: there `E` is not smooth over the pixel, and the clearance
/// of one point does not speak for the others. The case is a pixel that
/// sees, at a grazing angle, both the ceiling above a light hung just
/// under it (dark) and the open ceiling beyond the light's edge: one
/// lookup at their mean point shades the whole pixel with one or the
/// other. Such pixels are few (one ray per sample of theirs is traced
/// again).
///
/// Returns the shared lookups kept, in order; each sample's lookup, where
/// the samples of split ones index, in sample order, past the kept ones;
/// and the shading points of those samples, whose lookups (with their
/// clearance) the caller appends.
fn split_narrow(
    shared: Vec<Lookup>,
    mut of_sample: Vec<Option<u32>>,
    points: &[Option<(u32, ShadingPoint)>],
) -> (Vec<Lookup>, Vec<Option<u32>>, Vec<ShadingPoint>) {
    let point_of = |i: usize| {
        points[i]
            .expect("a sample with a lookup has a shading point")
            .1
    };
    let mut spread = vec![0.0f32; shared.len()];
    for (i, k) in of_sample.iter().enumerate() {
        if let Some(k) = *k {
            let d = (point_of(i).0 - shared[k as usize].position).length();
            spread[k as usize] = spread[k as usize].max(d);
        }
    }
    let narrow: Vec<bool> = shared
        .iter()
        .zip(&spread)
        .map(|(at, &s)| at.clearance < s)
        .collect();
    if !narrow.contains(&true) {
        return (shared, of_sample, Vec::new());
    }
    // The shared lookups kept, in order, then one per sample of the others.
    let mut index = vec![None; shared.len()];
    let mut lookups = Vec::with_capacity(shared.len());
    for (k, at) in shared.iter().enumerate() {
        if !narrow[k] {
            index[k] = Some(lookups.len() as u32);
            lookups.push(*at);
        }
    }
    let mut own = Vec::new();
    for (i, k) in of_sample.iter_mut().enumerate() {
        if let Some(shared_k) = *k {
            *k = index[shared_k as usize].or_else(|| {
                own.push(point_of(i));
                Some((lookups.len() + own.len() - 1) as u32)
            });
        }
    }
    (lookups, of_sample, own)
}

/// [`pixel_lookups`] over each sample's triangle and shading point (`None`:
/// no lookup) and pixel; a pixel's samples are consecutive (a run of equal
/// pixels shares lookups).
fn share_lookups(
    samples: &[Option<(u32, ShadingPoint)>],
    pixel_of: &[u32],
) -> (Vec<ShadingPoint>, Vec<Option<u32>>) {
    let mut lookups: Vec<ShadingPoint> = Vec::new();
    let mut counts: Vec<f32> = Vec::new();
    let mut of_sample = vec![None; samples.len()];
    // The current pixel's (triangle, lookup) pairs: a pixel hits few.
    let mut pixel: Vec<(u32, u32)> = Vec::with_capacity(4);
    for (i, sample) in samples.iter().enumerate() {
        if i == 0 || pixel_of[i] != pixel_of[i - 1] {
            pixel.clear();
        }
        let Some((triangle, (point, normal))) = *sample else {
            continue;
        };
        let k = match pixel.iter().find(|(t, _)| *t == triangle) {
            Some(&(_, k)) => k,
            None => {
                let k = lookups.len() as u32;
                lookups.push((Vec3::ZERO, Vec3::ZERO));
                counts.push(0.0);
                pixel.push((triangle, k));
                k
            }
        };
        let (p, n) = &mut lookups[k as usize];
        *p += point;
        *n += normal;
        counts[k as usize] += 1.0;
        of_sample[i] = Some(k);
    }
    for ((p, n), count) in lookups.iter_mut().zip(counts) {
        *p /= count;
        *n = n.normalize();
    }
    (lookups, of_sample)
}

/// One tile of pixels in three steps: primary hits, emission and direct
/// light, collecting the cache lookups of the tile (a G-buffer of shading
/// points); the lookups interpolated all at once (on the GPU when there is
/// one); then per sample the cached indirect light or, where no record is
/// usable, a path-traced fallback, and the glossy lobe. The shadow rays and
/// the path-traced parts are traced last, each in one batch.
fn render_tile(ctx: &FrameContext, pass: &TilePass, first: u32, out: &mut [Vec3]) -> FrameStats {
    let spp = pass.settings.spp.max(1);
    let mut stats = FrameStats::default();
    let (primary, edges) = PrimarySamples::trace(ctx, first, out.len() as u32, spp);
    let mut tile = TileShading::new(ctx, primary);
    let shadows = tile.direct_light(ctx);
    let (lookups, lookup_of_sample) = pixel_lookups(
        ctx,
        &tile.surfaces,
        &tile.primary.hits,
        &tile.primary.samples,
        pass.settings.glossy,
    );
    stats.lookups = lookups.len() as u64;
    let interpolated = pass.interpolation.interpolate(&lookups, pass.used);
    stats.lookup_records = interpolated
        .iter()
        .flatten()
        .map(|e| u64::from(e.records))
        .sum();
    let deferred = tile.indirect_light(
        ctx,
        pass,
        (&lookups, &lookup_of_sample),
        &interpolated,
        &mut stats,
    );
    shadows.add_unoccluded(ctx, &mut tile.radiance);
    let (first_hits, paths): (Vec<Deferred>, Vec<Deferred>) =
        deferred.into_iter().partition(|d| d.first_hit_only);
    let first_hit = PathLength {
        max_depth: Some(0),
        ..pass.settings.length
    };
    for (length, deferred) in [(pass.settings.length, paths), (first_hit, first_hits)] {
        let (targets, queries): (Vec<usize>, Vec<RadianceQuery>) =
            deferred.into_iter().map(|d| (d.sample, d.query)).unzip();
        for (i, r) in targets
            .into_iter()
            .zip(trace_radiance(ctx, length, queries))
        {
            tile.radiance[i] += r.radiance;
        }
    }
    edges.resolve(&tile.primary.samples, &tile.radiance, first, out);
    stats
}

/// A tile's primary samples, their shaded first hits and the radiance
/// summed so far for each.
struct TileShading<'a> {
    primary: PrimarySamples,
    surfaces: Vec<Option<Surface<'a>>>,
    radiance: Vec<Vec3>,
}

/// The shadow rays of a tile's direct light and, for each, its sample and
/// what it adds if unoccluded.
struct ShadowBatch {
    rays: Vec<Ray>,
    targets: Vec<(usize, Vec3)>,
}

impl ShadowBatch {
    fn add_unoccluded(self, ctx: &FrameContext, radiance: &mut [Vec3]) {
        let mut occluded = vec![false; self.rays.len()];
        ctx.backend.any_hit(&self.rays, &mut occluded);
        for ((i, c), blocked) in self.targets.into_iter().zip(occluded) {
            if !blocked {
                radiance[i] += c;
            }
        }
    }
}

impl<'a> TileShading<'a> {
    /// The first hits shaded, with the emission of those that see an
    /// emitter's emitting side.
    fn new(ctx: &'a FrameContext, primary: PrimarySamples) -> Self {
        let surfaces = primary.surfaces(ctx);
        let radiance = surfaces
            .iter()
            .map(|surface| match surface {
                Some(s)
                    if s.material.is_emissive()
                        && emitting_cosine(s.triangle, s.material.double_sided, s.wo).is_some() =>
                {
                    s.material.emission
                }
                _ => Vec3::ZERO,
            })
            .collect();
        TileShading {
            primary,
            surfaces,
            radiance,
        }
    }

    /// Each sample's first light sample (drawn from its stream, before
    /// anything else draws from it) and the shadow rays of those that may
    /// add direct light.
    fn direct_light(&mut self, ctx: &FrameContext) -> ShadowBatch {
        let mut lights = FirstLightSampler::default();
        let choices: Vec<LightChoice> = self
            .primary
            .samples
            .iter()
            .zip(&mut self.primary.rngs)
            .map(|(s, rng)| lights.sample(ctx, s, rng))
            .collect();
        let mut batch = ShadowBatch {
            rays: Vec::new(),
            targets: Vec::new(),
        };
        for (i, (surface, &choice)) in self.surfaces.iter().zip(&choices).enumerate() {
            let Some(surface) = surface.as_ref().filter(|s| !s.bsdf.is_black()) else {
                continue;
            };
            if let Some((shadow, contribution)) = direct_light(ctx, surface, choice, true) {
                batch.rays.push(shadow);
                batch.targets.push((i, contribution));
            }
        }
        batch
    }

    /// Per sample, in the order the CPU-only pass took them: the cached
    /// indirect light added, or where the sample's lookup found no usable
    /// record, a path-traced fallback (drawn from the sample's stream
    /// before the glossy lobe's); and the glossy lobe: path-traced, or
    /// with [`GlossyLobe::Eas`] its indirect light reflected from the
    /// records' equivalent area light sources, once per lookup, and its
    /// ray traced to the first hit only (path-traced where no record there
    /// has sources). Returns the traced parts.
    fn indirect_light(
        &mut self,
        ctx: &FrameContext,
        pass: &TilePass,
        (lookups, lookup_of_sample): (&[Lookup], &[Option<u32>]),
        interpolated: &[Option<Interpolated>],
        stats: &mut FrameStats,
    ) -> Vec<Deferred> {
        let mut deferred = Vec::new();
        let mut reflected: Vec<Option<Option<Vec3>>> = vec![None; lookups.len()];
        for (i, surface) in self.surfaces.iter().enumerate() {
            let Some(surface) = surface.as_ref().filter(|s| !s.bsdf.is_black()) else {
                continue;
            };
            let rng = &mut self.primary.rngs[i];
            let diffuse = surface.bsdf.diffuse_albedo().max_element() > 0.0;
            if let Some(lookup) = lookup_of_sample[i].filter(|_| diffuse) {
                match &interpolated[lookup as usize] {
                    Some(e) => {
                        self.radiance[i] +=
                            surface.bsdf.diffuse_albedo() * FRAC_1_PI * e.irradiance;
                    }
                    None => {
                        stats.fallback_lookups += 1;
                        let query = match pass.fallback {
                            FallbackStreams::PerFrame => diffuse_indirect_query(surface, rng),
                            FallbackStreams::Coherent => diffuse_indirect_query(
                                surface,
                                &mut coherent_fallback(ctx, &self.primary.samples[i]),
                            ),
                        };
                        deferred.push(Deferred {
                            sample: i,
                            query,
                            first_hit_only: false,
                        });
                    }
                }
            }
            if pass.settings.glossy == GlossyLobe::Eas && surface.bsdf.has_specular() {
                let cached = lookup_of_sample[i].and_then(|l| {
                    *reflected[l as usize].get_or_insert_with(|| {
                        let cache = pass.interpolation.cache();
                        eas::reflected_radiance(
                            cache,
                            &lookups[l as usize],
                            &surface.bsdf,
                            surface.wo,
                        )
                    })
                });
                let query = glossy_query(surface, rng);
                match (cached, query) {
                    // The sources hold what the lobe's path would gather
                    // past its first hit; the lobe's ray is still traced
                    // to its first hit, for the emission there that MIS
                    // weighs against the light sample.
                    (Some(radiance), query) => {
                        self.radiance[i] += radiance;
                        deferred.extend(query.map(|query| Deferred {
                            sample: i,
                            query,
                            first_hit_only: true,
                        }));
                    }
                    (None, query) => deferred.extend(query.map(|query| Deferred {
                        sample: i,
                        query,
                        first_hit_only: false,
                    })),
                }
            } else if let Some(query) = glossy_query(surface, rng) {
                deferred.push(Deferred {
                    sample: i,
                    query,
                    first_hit_only: false,
                });
            }
        }
        deferred
    }
}

/// One light sample (`choice`, stratified over the pixel, its point
/// uniform in solid angle: this light is seen) for the whole
/// BSDF: the diffuse lobe unweighted (its emission hits are never counted
/// elsewhere: the cache excludes them), the glossy lobe MIS-weighted against
/// [`glossy_query`]'s lobe sampling. Without `with_diffuse`, the glossy
/// lobe's part alone (`movies`, whose textures hold the diffuse part).
pub(crate) fn direct_light(
    ctx: &FrameContext,
    s: &Surface,
    choice: LightChoice,
    with_diffuse: bool,
) -> Option<(Ray, Vec3)> {
    let ls = ctx
        .lights
        .sample(ctx.snapshot, s.p, choice, TriangleSampling::SolidAngle)?;
    let cos = s.bsdf.normal().dot(ls.wi);
    if cos <= 0.0 || s.wo.dot(s.bsdf.normal()) <= 0.0 {
        return None;
    }
    let diffuse = if with_diffuse {
        s.bsdf.diffuse_albedo() * FRAC_1_PI
    } else {
        Vec3::ZERO
    };
    let specular = s.bsdf.eval_specular(s.wo, ls.wi);
    let w = if ls.is_delta || !s.bsdf.has_specular() {
        1.0
    } else {
        power_heuristic(ls.pdf, s.bsdf.pdf_specular(s.wo, ls.wi))
    };
    let f = diffuse + specular * w;
    if f.max_element() <= 0.0 {
        return None;
    }
    let shadow = Ray::segment(offset_origin(s.p, s.ng, ls.wi), ls.position);
    Some((shadow, f * ls.radiance * (cos / ls.pdf)))
}

/// The glossy lobe's indirect and MIS-weighted direct light, by sampling
/// the lobe and path tracing on.
pub(crate) fn glossy_query(s: &Surface, rng: &mut Rng) -> Option<RadianceQuery> {
    if !s.bsdf.has_specular() {
        return None;
    }
    let sample = s.bsdf.sample_specular(s.wo, rng.next_2d())?;
    let cos = s.bsdf.normal().dot(sample.wi);
    Some(RadianceQuery {
        ray: Ray::new(
            offset_origin(s.p, s.ng, sample.wi),
            sample.wi,
            0.0,
            f32::INFINITY,
        ),
        first_light: None,
        rng: rng.split(),
        weight: sample.f * (cos / sample.pdf),
        // The direct light of the same first hit ([`direct_light`]).
        first_hit: FirstHitEmission::Mis {
            bsdf_pdf: sample.pdf,
            light: TriangleSampling::SolidAngle,
        },
    })
}

/// How the render pass keys the random streams of its path-traced
/// fallbacks (diffuse indirect light of pixel samples no record covers:
/// slivers of a surface next to a concave edge, where no pixel centre
/// hit and so no record was made).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FallbackStreams {
    /// The pixel sample's own stream, new every frame, as `ic`'s records
    /// get new streams every frame (per-frame computation).
    PerFrame,
    /// A stream of the pixel and sample number alone, the same in every
    /// frame, as `trc`'s records keep theirs (Tawara et al. 2004: the same
    /// sample rays every frame): where nothing changed a fallback traces
    /// the same directions, and the pixel does not flicker with fresh
    /// noise. On `cube-in-box` (64×64, 48 frames) 1.4 % of the pixel samples
    /// fall back, along the box's edges; keying them so took `trc`'s
    /// lit-surface flicker from 0.038 to 0.034 at no cost (`benches/HISTORY.md`).
    Coherent,
}

/// What every tile of one render pass shares.
struct TilePass<'a> {
    interpolation: &'a Interpolation<'a>,
    settings: &'a IcSettings,
    fallback: FallbackStreams,
    used: Option<&'a [AtomicBool]>,
}

/// Tags the random streams of [`FallbackStreams::Coherent`] apart from
/// records' (bit 62) and pixels' (untagged).
const FALLBACK_STREAM: u64 = 1 << 63;

/// The stream of sample `s`'s fallback path under
/// [`FallbackStreams::Coherent`].
fn coherent_fallback(ctx: &FrameContext, s: &PixelSample) -> Rng {
    Rng::new(SampleKey {
        seed: ctx.seed,
        frame: None,
        item: FALLBACK_STREAM | u64::from(s.pixel),
        sample: s.key,
    })
}

/// Indirect diffuse light by path tracing, where no record is usable:
/// cosine sampling makes the weight `kd` (`kd/π · L · cosθ / (cosθ/π)`).
fn diffuse_indirect_query(s: &Surface, rng: &mut Rng) -> RadianceQuery {
    let frame = s.bsdf.frame;
    let wi = frame.to_world(cosine_hemisphere(rng.next_2d()));
    RadianceQuery {
        ray: Ray::new(offset_origin(s.p, s.ng, wi), wi, 0.0, f32::INFINITY),
        first_light: None,
        rng: rng.split(),
        weight: s.bsdf.diffuse_albedo(),
        first_hit: FirstHitEmission::Exclude,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::gather::Strata;
    use crate::method::ic::IrradianceCaching;
    /// Two pixels of four samples: the first pixel's samples on triangles 7
    /// and 9 (and one that looks nothing up), the second's all on 7 again.
    /// One lookup per pixel and triangle, at the mean point and the
    /// normalised mean normal; a triangle seen by two pixels is looked up
    /// in each.
    #[test]
    fn pixel_samples_share_one_lookup_per_triangle() {
        let n = Vec3::Z;
        let tilted = Vec3::new(0.6, 0.0, 0.8);
        let samples = [
            Some((7, (Vec3::new(0.0, 0.0, 0.0), n))),
            Some((9, (Vec3::new(5.0, 0.0, 0.0), tilted))),
            None,
            Some((7, (Vec3::new(2.0, 4.0, 0.0), n))),
            Some((7, (Vec3::new(1.0, 1.0, 0.0), n))),
            Some((7, (Vec3::new(3.0, 1.0, 0.0), Vec3::new(0.0, 0.6, 0.8)))),
            Some((7, (Vec3::new(1.0, 3.0, 0.0), Vec3::new(0.0, -0.6, 0.8)))),
            Some((7, (Vec3::new(3.0, 3.0, 0.0), n))),
        ];
        let (lookups, of_sample) = share_lookups(&samples, &[0, 0, 0, 0, 1, 1, 1, 1]);
        assert_eq!(
            of_sample,
            [
                Some(0),
                Some(1),
                None,
                Some(0),
                Some(2),
                Some(2),
                Some(2),
                Some(2)
            ]
        );
        assert_eq!(lookups.len(), 3);
        assert!((lookups[0].0 - Vec3::new(1.0, 2.0, 0.0)).length() < 1e-6);
        assert!((lookups[0].1 - n).length() < 1e-6);
        assert!((lookups[1].0 - Vec3::new(5.0, 0.0, 0.0)).length() < 1e-6);
        assert!((lookups[1].1 - tilted).length() < 1e-6);
        assert!((lookups[2].0 - Vec3::new(2.0, 2.0, 0.0)).length() < 1e-6);
        assert!((lookups[2].1 - n).length() < 1e-6);
    }

    /// Pixel 0's two samples lie 0.5 from their shared point, under a
    /// surface 0.1 above it: each gets its own lookup, after pixel 1's
    /// (kept, its clearance 2 above its spread). Nothing splits when every
    /// clearance exceeds its spread.
    #[test]
    fn samples_spread_wider_than_the_clearance_get_their_own_lookups() {
        let n = Vec3::Z;
        let points = [
            Some((7, (Vec3::new(-0.5, 0.0, 0.0), n))),
            Some((7, (Vec3::new(0.5, 0.0, 0.0), n))),
            None,
            Some((8, (Vec3::new(3.0, 0.0, 0.0), n))),
        ];
        let of_sample = vec![Some(0), Some(0), None, Some(1)];
        let shared = |clearance_0| {
            vec![
                Lookup::new(Vec3::ZERO, n, clearance_0),
                Lookup::new(Vec3::new(3.0, 0.0, 0.0), n, 2.0),
            ]
        };
        let (lookups, of, own) = split_narrow(shared(0.1), of_sample.clone(), &points);
        assert_eq!(lookups, shared(0.1)[1..]);
        assert_eq!(of, [Some(1), Some(2), None, Some(0)]);
        assert_eq!(own, [points[0].unwrap().1, points[1].unwrap().1]);
        let (lookups, of, own) = split_narrow(shared(0.6), of_sample.clone(), &points);
        assert_eq!((lookups, of, own), (shared(0.6), of_sample, Vec::new()));
    }

    /// `trc`'s first pass flags the records the render pass will use: on a
    /// scene whose light is in view (so edge pixels add shaded samples), the
    /// flags of [`mark_used`] equal those the render pass sets. (Here no
    /// record is used by an edge pixel's extra sample alone, so this guards
    /// the invariant rather than reproducing that case.)
    #[test]
    fn mark_used_flags_exactly_the_records_the_render_pass_uses() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 20);
        let ic = IrradianceCaching::new(IcSettings {
            spp: 4,
            strata: Strata { theta: 4, phi: 12 },
            ..IcSettings::default()
        });
        let (marked, rendered) = renderer.with_frame_context(2, |ctx| {
            let cache = ic.build_cache(ctx);
            let flags = || -> Vec<AtomicBool> {
                (0..cache.len()).map(|_| AtomicBool::new(false)).collect()
            };
            let (marked, rendered) = (flags(), flags());
            mark_used(ctx, &cache, &ic.settings, &marked);
            let mut stats = FrameStats::default();
            render_pass(
                ctx,
                &cache,
                &ic.settings,
                FallbackStreams::PerFrame,
                Some(&rendered),
                &mut stats,
            );
            let read = |f: Vec<AtomicBool>| -> Vec<bool> {
                f.into_iter().map(AtomicBool::into_inner).collect()
            };
            (read(marked), read(rendered))
        });
        assert!(rendered.iter().any(|&u| u));
        assert_eq!(marked, rendered);
    }
}
