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
//! The methods differ only in the cache they hand it and in how their
//! pixel samples draw their random streams ([`PixelStreams`]). `trc` also
//! asks which records the pass uses (`render_pass`'s `used`, `mark_used`).
//! With streams that are the same in every frame, the pass keeps the
//! primary hits, direct light, path-traced parts and cache lookups of the
//! last frame's samples and traces again only those that something moving
//! may have changed ([`StillSamples`]).

use super::ic::{GlossyLobe, IcSettings};
use super::kept_queries::{KeptQueries, TileQueries};
use super::lookups::{measure_clearance, Interpolation, Lookup, ShadingPoint};
use super::motion::{self, Blockers};
pub use super::pixels::PixelStreams;
use super::pixels::{
    self, CameraSampler, CandidateCoverage, EmitterEdges, FirstLightSampler, KeptCoverage,
    PixelSample,
};
use super::{FrameContext, FrameStats};
use crate::backend::{Hit, Ray};
use crate::cache::gather::GatherPoint;
use crate::cache::{eas, Interpolated, IrradianceCache, LookupPoint};
use crate::film::Film;
use crate::integrator::{
    offset_origin, trace_radiance, FirstHitEmission, PathLength, RadianceQuery,
};
use crate::light::{emitting_cosine, TriangleSampling};
use crate::material::Bsdf;
use crate::sampling::{cosine_hemisphere, mix64, power_heuristic, LightChoice, Rng};
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
        let triangle = &ctx.snapshot.triangles[hit.triangle as usize];
        let material = material_of(ctx, hit);
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

    /// Whether a hit's shading needs no more than its diffuse albedo and
    /// cache lookup (a miss, or a material that neither emits nor has a
    /// glossy lobe): what a pixel kept whole may hold ([`Standing`]).
    fn is_plain(ctx: &FrameContext, hit: &Hit) -> bool {
        !hit.is_hit() || {
            let m = material_of(ctx, hit);
            !m.is_emissive() && m.specular.max_element() <= 0.0
        }
    }

    pub(crate) fn gather_point(&self) -> GatherPoint {
        GatherPoint {
            position: self.p,
            normal: self.bsdf.normal(),
            geometric_normal: self.ng,
        }
    }
}

/// The material of the triangle `hit` hit.
fn material_of<'a>(ctx: &'a FrameContext, hit: &Hit) -> &'a crate::scene::Material {
    &ctx.scene.materials[ctx.snapshot.tri_material[hit.triangle as usize] as usize]
}

/// Rendering stage (EAS Algorithm 1, lines 18–24), tile by tile. With
/// `used` (one flag per cache record), every record that contributes to a
/// pixel sample is flagged (`trc`'s replace-or-drop rule). The cache is
/// interpolated on the GPU when the backend has one ([`Interpolation`]).
/// With `still` (coherent streams only), the samples of the last frame that
/// nothing moving met are taken again rather than traced, and this frame's
/// are kept for the next ([`StillSamples`]): the film is the same, bit for
/// bit, as without.
pub(crate) fn render_pass(
    ctx: &FrameContext,
    cache: &IrradianceCache,
    settings: &IcSettings,
    streams: PixelStreams,
    used: Option<&[AtomicBool]>,
    still: Option<&mut StillSamples>,
    stats: &mut FrameStats,
) -> Film {
    let mut film = Film::new(ctx.width, ctx.height);
    let interpolation = Interpolation::new(ctx, cache, settings.gradients);
    let spp = settings.spp.max(1);
    let pixels_per_tile = ctx.backend.items_per_task(film.pixels.len(), spp as usize);
    let mut still = still.filter(|_| streams == PixelStreams::Coherent);
    let still_pass = still
        .as_mut()
        .and_then(|s| s.begin(ctx, spp, pixels_per_tile));
    let pass = TilePass {
        interpolation: &interpolation,
        settings,
        streams,
        used,
    };
    let tiles: Vec<(FrameStats, TileKept)> = film
        .pixels
        .par_chunks_mut(pixels_per_tile)
        .enumerate()
        .map(|(tile, out)| {
            let first = (tile * pixels_per_tile) as u32;
            let still = still_pass.as_ref().map(|p| p.tile(tile));
            render_tile(ctx, &pass, first, out, still)
        })
        .collect();
    let mut kept = Vec::with_capacity(tiles.len());
    for (t, tile) in tiles {
        stats.lookups += t.lookups;
        stats.lookup_records += t.lookup_records;
        stats.fallback_lookups += t.fallback_lookups;
        kept.push(tile);
    }
    if let Some(still) = still {
        still.end(still_pass, kept);
    }
    film
}

/// Flags every record that [`render_pass`] would use for some pixel sample
/// of this frame, without rendering: the same camera samples, the same
/// shading points and the same usability test (`w ≥ 1/a`, which depends on
/// the records' positions, normals and radii, not on their values). `trc`'s
/// first pass with interpolated gradients (TRC §4.5, two passes) decides
/// replace-or-drop from it before the frame is rendered. With `still`
/// (the first pass's own, frame after frame), the camera hits and rim
/// coverage of the last frame's samples that nothing moving met are taken
/// again, as in [`render_pass`].
pub(crate) fn mark_used(
    ctx: &FrameContext,
    cache: &IrradianceCache,
    settings: &IcSettings,
    streams: PixelStreams,
    used: &[AtomicBool],
    still: Option<&mut StillSamples>,
) {
    let interpolation = Interpolation::new(ctx, cache, settings.gradients);
    let spp = settings.spp.max(1);
    let n_pixels = (ctx.width * ctx.height) as usize;
    let pixels_per_tile = ctx.backend.items_per_task(n_pixels, spp as usize);
    let mut still = still.filter(|_| streams == PixelStreams::Coherent);
    let still_pass = still
        .as_mut()
        .and_then(|s| s.begin(ctx, spp, pixels_per_tile));
    let tiles: Vec<TileKept> = (0..n_pixels.div_ceil(pixels_per_tile))
        .into_par_iter()
        .map(|tile| {
            let first = tile * pixels_per_tile;
            let count = pixels_per_tile.min(n_pixels - first);
            let still = still_pass.as_ref().map(|p| p.tile(tile));
            let (primary, edges, taken) = PrimarySamples::trace_keeping(
                ctx,
                streams,
                first as u32,
                count as u32,
                spp,
                still.as_ref(),
            );
            let surfaces = primary.surfaces(ctx);
            let (lookups, _) = pixel_lookups(
                ctx,
                &surfaces,
                &primary.hits,
                &primary.samples,
                settings.glossy,
            );
            interpolation.mark_used(&lookups, used);
            // No light is sampled here: the samples are kept without shadows.
            let jittered = primary.jittered(taken.len(), still.is_some());
            let shadows = vec![None; jittered.len()];
            TileKept::of(&primary, &taken, jittered, shadows, None, &edges)
        })
        .collect();
    if let Some(still) = still {
        still.end(still_pass, tiles);
    }
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

impl Deferred {
    /// Sample `sample`'s diffuse indirect light, path-traced where its
    /// lookup found no usable record: from the sample's own stream (`rng`),
    /// under coherent streams the same in every frame, so where nothing
    /// changed a fallback traces the same directions.
    fn fallback(sample: usize, surface: &Surface, rng: &mut Rng) -> Self {
        Deferred {
            sample,
            query: diffuse_indirect_query(surface, rng),
            first_hit_only: false,
        }
    }
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
        streams: PixelStreams,
        first: u32,
        count: u32,
        spp: u32,
    ) -> (Self, EmitterEdges) {
        let (primary, edges, _) = Self::trace_keeping(ctx, streams, first, count, spp, None);
        (primary, edges)
    }

    /// [`Self::trace`], taking from `still` the samples of the last frame
    /// whose hits nothing moving may have changed; and which ones it took.
    fn trace_keeping(
        ctx: &FrameContext,
        streams: PixelStreams,
        first: u32,
        count: u32,
        spp: u32,
        still: Option<&TileStill>,
    ) -> (Self, EmitterEdges, Vec<bool>) {
        let mut primary = PrimarySamples::default();
        let base = pixels::tile_samples(first, count, spp);
        let taken = primary.add(ctx, streams, &base, still);
        // The first hits decide which pixels are on a light's edge.
        let clear = |pixel: u32| still.is_some_and(|s| s.pass.pixel_clear(pixel));
        let kept = still.map(|s| KeptCoverage {
            last: s.coverage,
            clear: &clear,
        });
        let edges = EmitterEdges::find(
            ctx,
            streams,
            (&primary.samples, &primary.rays, &primary.hits),
            spp,
            kept.as_ref(),
        );
        primary.add(ctx, streams, edges.extra_samples(), None);
        (primary, edges, taken)
    }

    /// Appends `samples`, tracing the camera rays of those not taken from
    /// `still` (whose samples are `samples`, in order, in the last frame);
    /// returns which were taken.
    fn add(
        &mut self,
        ctx: &FrameContext,
        streams: PixelStreams,
        samples: &[PixelSample],
        still: Option<&TileStill>,
    ) -> Vec<bool> {
        let start = self.rays.len();
        self.rays.reserve(samples.len());
        self.rngs.reserve(samples.len());
        self.hits.reserve(samples.len());
        self.samples.reserve(samples.len());
        let mut camera = CameraSampler::new(streams);
        let mut taken = vec![false; samples.len()];
        let mut fresh = Vec::new();
        // Whether the current pixel is clear on the film (its samples are
        // consecutive).
        let mut film: Option<(u32, bool)> = None;
        let still = still.filter(|st| !st.samples.is_empty());
        for (i, s) in samples.iter().enumerate() {
            let kept = still.and_then(|st| {
                let clear = match film {
                    Some((pixel, clear)) if pixel == s.pixel => clear,
                    _ => st.pass.film_clear(s.pixel),
                };
                film = Some((s.pixel, clear));
                st.primary(i, clear)
            });
            if let Some(k) = kept {
                self.rays.push(k.ray);
                self.rngs.push(k.rng.clone());
                self.hits.push(k.hit);
                taken[i] = true;
            } else {
                let (ray, rng) = camera.query(ctx, s);
                self.rays.push(ray);
                self.rngs.push(rng);
                self.hits.push(Hit::MISS);
                fresh.push(start + i);
            }
        }
        if fresh.len() == samples.len() {
            ctx.backend
                .closest_hit(&self.rays[start..], &mut self.hits[start..]);
        } else if !fresh.is_empty() {
            let rays: Vec<Ray> = fresh.iter().map(|&i| self.rays[i]).collect();
            let mut hits = vec![Hit::MISS; rays.len()];
            ctx.backend.closest_hit(&rays, &mut hits);
            for (&i, hit) in fresh.iter().zip(hits) {
                self.hits[i] = hit;
            }
        }
        self.samples.extend_from_slice(samples);
        taken
    }

    /// The streams of the first `n` samples as the camera left them, for
    /// the next frame to go on from (none where nothing is `kept`).
    fn jittered(&self, n: usize, kept: bool) -> Vec<Rng> {
        if kept {
            self.rngs[..n].to_vec()
        } else {
            Vec::new()
        }
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
/// the path-traced parts are traced last, each in one batch. With `still`,
/// the primary hits and direct light of the last frame's samples that
/// nothing moving met are taken from it, and the tile's are returned for
/// the next frame.
fn render_tile(
    ctx: &FrameContext,
    pass: &TilePass,
    first: u32,
    out: &mut [Vec3],
    still: Option<TileStill>,
) -> (FrameStats, TileKept) {
    let spp = pass.settings.spp.max(1);
    let mut stats = FrameStats::default();
    let (primary, edges, taken) = PrimarySamples::trace_keeping(
        ctx,
        pass.streams,
        first,
        out.len() as u32,
        spp,
        still.as_ref(),
    );
    let jittered = primary.jittered(taken.len(), still.is_some());
    let standing = still.as_ref().map(|s| s.standing(ctx, &primary, &taken));
    let (shadows, whole) = standing.map_or((Vec::new(), Vec::new()), |s| (s.shadows, s.whole));
    let mut tile = TileShading::new(ctx, primary, whole);
    let shadows_stand = still.as_ref().map(|s| (s, &shadows[..]));
    let shadows = tile.direct_light(ctx, pass.streams, shadows_stand);
    let (mut lookups, mut lookup_of_sample) = pixel_lookups(
        ctx,
        &tile.surfaces,
        &tile.primary.hits,
        &tile.primary.samples,
        pass.settings.glossy,
    );
    let first_taken_lookup = lookups.len();
    let lookups_taken = still.as_ref().map_or(0, |s| {
        s.take_lookups(&tile.whole, &mut lookups, &mut lookup_of_sample)
    });
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
    let kept_shadows =
        shadows.add_unoccluded(ctx, &mut tile.radiance, still.as_ref().map(|s| s.pass));
    let kept_lookups = still.as_ref().and_then(|s| {
        let camera = ctx.snapshot.camera.position;
        let of_base = (&lookups[..], &lookup_of_sample[..taken.len()]);
        s.pass
            .keep_lookups(camera, of_base, first_taken_lookup, s.pass.tile_budget)
    });
    let lookups_bytes = kept_lookups
        .as_ref()
        .map_or(0, |(l, _)| l.len() * std::mem::size_of::<KeptLookup>());
    let queries = trace_deferred(
        ctx,
        pass,
        deferred,
        still
            .as_ref()
            .map(|s| (s, s.pass.tile_budget.saturating_sub(lookups_bytes))),
        &taken,
        &mut tile.radiance,
    );
    edges.resolve(&tile.primary.samples, &tile.radiance, first, out);
    let mut kept = TileKept::of(
        &tile.primary,
        &taken,
        jittered,
        kept_shadows,
        kept_lookups,
        &edges,
    );
    kept.lookups_taken = lookups_taken;
    if let Some((queries, taken)) = queries {
        kept.tile.queries = queries;
        kept.queries_taken = taken;
    }
    (stats, kept)
}

/// Traces the tile's deferred queries (the paths, then the glossy lobes'
/// first hits) and adds their radiance to their samples. With `still`
/// (and lights that did not move since the last frame), takes the
/// radiance of the last frame's queries that are asked again and that
/// nothing moving meets ([`KeptQueries`]) and returns this frame's, kept
/// within `still`'s budget, with how many were taken; `taken` says how
/// many samples are base samples (the rest are a light rim's extra ones,
/// never kept).
fn trace_deferred(
    ctx: &FrameContext,
    pass: &TilePass,
    deferred: Vec<Deferred>,
    still: Option<(&TileStill, usize)>,
    taken: &[bool],
    radiance: &mut [Vec3],
) -> Option<(KeptQueries, u64)> {
    let (first_hits, paths): (Vec<Deferred>, Vec<Deferred>) =
        deferred.into_iter().partition(|d| d.first_hit_only);
    let first_hit = PathLength {
        max_depth: Some(0),
        ..pass.settings.length
    };
    // Under lights that moved since the last frame the queries are not
    // kept: they would most likely move again, and nothing could be taken.
    let (still, budget) = still.filter(|(s, _)| !s.pass.lights_moved()).unzip();
    let mut kept = budget.map(|budget| (KeptQueries::within(budget), 0));
    for (length, deferred) in [(pass.settings.length, paths), (first_hit, first_hits)] {
        let (targets, queries): (Vec<usize>, Vec<RadianceQuery>) =
            deferred.into_iter().map(|d| (d.sample, d.query)).unzip();
        let traced = match (still, kept.as_mut()) {
            (Some(still), Some((kept, n_taken))) => {
                let asked = TileQueries {
                    length,
                    samples: targets
                        .iter()
                        .map(|&i| (i < taken.len()).then_some(i as u32))
                        .collect(),
                    queries,
                };
                let last = still.queries;
                let (traced, n) = kept.trace(ctx, asked, last, &still.pass.blockers);
                *n_taken += n;
                traced
            }
            _ => trace_radiance(ctx, length, queries)
                .into_iter()
                .map(|r| r.radiance)
                .collect(),
        };
        for (i, r) in targets.into_iter().zip(traced) {
            radiance[i] += r;
        }
    }
    if let Some((kept, _)) = kept.as_mut() {
        kept.finish();
    }
    kept
}

/// A tile's primary samples, their shaded first hits and the radiance
/// summed so far for each.
struct TileShading<'a> {
    primary: PrimarySamples,
    /// Each sample's shaded first hit; not shaded (`None`) for the samples
    /// of pixels kept whole.
    surfaces: Vec<Option<Surface<'a>>>,
    /// Per base sample, whether its pixel is kept whole ([`Standing`]);
    /// empty where nothing is kept.
    whole: Vec<bool>,
    radiance: Vec<Vec3>,
}

/// The shadow rays of a tile's direct light and, for each, its sample and
/// what it adds if unoccluded; and the shadows taken from the last frame.
#[derive(Default)]
struct ShadowBatch {
    rays: Vec<Ray>,
    targets: Vec<(usize, Vec3)>,
    kept: Vec<(usize, KeptShadow)>,
}

impl ShadowBatch {
    /// Adds the light of the unoccluded shadow rays to their samples. With
    /// `keep` (this frame's kept samples), returns each sample's shadow
    /// (`None`: it had none), for the next frame.
    fn add_unoccluded(
        self,
        ctx: &FrameContext,
        radiance: &mut [Vec3],
        keep: Option<&StillPass>,
    ) -> Vec<Option<KeptShadow>> {
        let mut occluded = vec![false; self.rays.len()];
        ctx.backend.any_hit(&self.rays, &mut occluded);
        let mut kept = vec![None; if keep.is_some() { radiance.len() } else { 0 }];
        let traced = self.rays.into_iter().zip(self.targets).zip(occluded);
        let traced = traced.map(|((ray, (i, contribution)), occluded)| {
            let clear = keep.is_some_and(|pass| pass.shadow_clear(&ray));
            let shadow = KeptShadow {
                ray,
                contribution,
                occluded,
                clear,
            };
            (i, shadow)
        });
        // A shadow taken again met no moving box of this frame.
        let taken = self
            .kept
            .into_iter()
            .map(|(i, s)| (i, KeptShadow { clear: true, ..s }));
        let keep = keep.is_some();
        for (i, shadow) in traced.chain(taken) {
            if !shadow.occluded {
                radiance[i] += shadow.contribution;
            }
            if keep {
                kept[i] = Some(shadow);
            }
        }
        kept
    }
}

impl<'a> TileShading<'a> {
    /// The first hits shaded (but for those of pixels kept `whole`, whose
    /// materials emit nothing), with the emission of those that see an
    /// emitter's emitting side.
    fn new(ctx: &'a FrameContext, primary: PrimarySamples, whole: Vec<bool>) -> Self {
        let surfaces: Vec<Option<Surface>> = primary
            .rays
            .iter()
            .zip(&primary.hits)
            .enumerate()
            .map(|(i, (ray, hit))| match whole.get(i) {
                Some(true) => None,
                _ => Surface::at(ctx, ray, hit),
            })
            .collect();
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
            whole,
            radiance,
        }
    }

    /// Each sample's first light sample (drawn from its stream, before
    /// anything else draws from it) and the shadow rays of those that may
    /// add direct light; the last frame's shadows that stand (`standing`:
    /// the kept samples and, per base sample, [`Standing::shadows`]) are
    /// taken instead of sampled and traced again.
    fn direct_light(
        &mut self,
        ctx: &FrameContext,
        streams: PixelStreams,
        standing: Option<(&TileStill, &[bool])>,
    ) -> ShadowBatch {
        let mut lights = FirstLightSampler::new(streams);
        let mut batch = ShadowBatch::default();
        for (i, surface) in self.surfaces.iter().enumerate() {
            let rng = &mut self.primary.rngs[i];
            let kept = standing.filter(|(_, stands)| stands.get(i) == Some(&true));
            if let Some(shadow) = kept.map(|(still, _)| still.samples[i].shadow) {
                // The light sample's draw, whose outcome the shadow kept.
                rng.next_2d();
                batch.kept.extend(shadow.map(|shadow| (i, shadow)));
                continue;
            }
            let choice = lights.sample(ctx, &self.primary.samples[i], rng);
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
        ctx: &'a FrameContext,
        pass: &TilePass,
        (lookups, lookup_of_sample): (&[Lookup], &[Option<u32>]),
        interpolated: &[Option<Interpolated>],
        stats: &mut FrameStats,
    ) -> Vec<Deferred> {
        let mut deferred = Vec::new();
        let mut reflected: Vec<Option<Option<Vec3>>> = vec![None; lookups.len()];
        for (i, surface) in self.surfaces.iter().enumerate() {
            let rng = &mut self.primary.rngs[i];
            if self.whole.get(i) == Some(&true) {
                // A plain material: its diffuse lobe alone, as below (a
                // BSDF's diffuse albedo is its material's `diffuse`).
                let Some(lookup) = lookup_of_sample[i] else {
                    continue;
                };
                let hit = &self.primary.hits[i];
                match &interpolated[lookup as usize] {
                    Some(e) => {
                        let albedo = material_of(ctx, hit).diffuse;
                        self.radiance[i] += albedo * FRAC_1_PI * e.irradiance;
                    }
                    None => {
                        stats.fallback_lookups += 1;
                        let surface = Surface::at(ctx, &self.primary.rays[i], hit)
                            .expect("a sample that looked the cache up hit something");
                        deferred.push(Deferred::fallback(i, &surface, rng));
                    }
                }
                continue;
            }
            let Some(surface) = surface.as_ref().filter(|s| !s.bsdf.is_black()) else {
                continue;
            };
            let diffuse = surface.bsdf.diffuse_albedo().max_element() > 0.0;
            if let Some(lookup) = lookup_of_sample[i].filter(|_| diffuse) {
                match &interpolated[lookup as usize] {
                    Some(e) => {
                        self.radiance[i] +=
                            surface.bsdf.diffuse_albedo() * FRAC_1_PI * e.irradiance;
                    }
                    None => {
                        stats.fallback_lookups += 1;
                        deferred.push(Deferred::fallback(i, surface, rng));
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

/// What every tile of one render pass shares.
struct TilePass<'a> {
    interpolation: &'a Interpolation<'a>,
    settings: &'a IcSettings,
    streams: PixelStreams,
    used: Option<&'a [AtomicBool]>,
}

/// The pixel samples of a method's last frame, kept for its next one: with
/// [`PixelStreams::Coherent`] a sample draws the same camera ray and light
/// point in every frame, so where the camera, the lights and the static
/// geometry stay, only moving objects can change what the sample's camera
/// ray hits and whether its shadow ray is stopped. A sample whose camera
/// ray hit a static triangle (or nothing) and meets no moving object's box
/// this frame keeps its hit; if its shadow ray meets no moving object's box
/// in the last frame or this one either, it keeps its direct light. A
/// pixel on the rim of a seen light keeps what its coverage rays saw
/// ([`pixels::EmitterEdges`]) where no moving box shows within a pixel of
/// it on the film in either frame. A path-traced part of a sample (the
/// indirect light where no record is usable, a glossy lobe) asked again
/// bit for bit keeps its radiance where its path met nothing moving then
/// and no moving box meets it now, the lights staying
/// (`method::kept_queries`). A pixel all of whose samples keep their hits
/// and shadows, on materials that neither emit nor have a glossy lobe, is
/// kept whole where no moving box lies on its lookups' clearance rays in
/// either frame (`Standing`): it keeps its cache lookups, and its
/// samples' first hits are not shaded again; only the interpolation,
/// whose records change from frame to frame, is done again. The rest is
/// traced again. So the film equals, bit for bit, the one traced afresh,
/// and a resumed job (which starts with none kept) equals an
/// uninterrupted one.
///
/// This is the design's "static parts are never recomputed for motion
/// they cannot see" applied to the render pass, as `movies` does for its
/// texels' shadows (Martín et al. §5) and the TRC paper's GPU renderer gets
/// for little cost by rasterizing. Per-frame computation (`ic`) keeps
/// nothing: it is the baseline the temporal methods are measured against.
#[derive(Default)]
pub struct StillSamples {
    last: Option<KeptFrame>,
    /// Samples of the last render pass whose hit was taken from the frame
    /// before (their direct light too where no moving box met it).
    pub taken: u64,
    /// Cache lookups the last render pass took from the frame before (of
    /// pixels kept whole, `Standing`).
    pub lookups_taken: u64,
    /// Path-traced parts of samples (fallbacks, glossy lobes) the last
    /// render pass took from the frame before (`KeptQueries`).
    pub queries_taken: u64,
}

impl StillSamples {
    /// Bytes kept per frame at most: past this (about 4.5 million samples:
    /// 512 × 512 pixels at 16 spp) the pass keeps nothing and traces every
    /// sample, as `ic` does.
    pub const BUDGET_BYTES: usize = 512 << 20;

    /// This frame's pass over the samples kept from the last one (`None`
    /// where a frame's samples would not fit the budget: nothing is kept).
    fn begin(&mut self, ctx: &FrameContext, spp: u32, pixels_per_tile: usize) -> Option<StillPass> {
        let last = self.last.take();
        StillPass::new(ctx, last, spp, pixels_per_tile)
    }

    /// Keeps the tiles `pass` traced for the next frame.
    fn end(&mut self, pass: Option<StillPass>, tiles: Vec<TileKept>) {
        self.taken = tiles.iter().map(|t| t.taken).sum();
        self.lookups_taken = tiles.iter().map(|t| t.lookups_taken).sum();
        self.queries_taken = tiles.iter().map(|t| t.queries_taken).sum();
        self.last = pass.map(|pass| pass.finish(tiles.into_iter().map(|t| t.tile).collect()));
    }

    /// Bytes the kept samples take.
    pub fn memory_bytes(&self) -> usize {
        self.last.as_ref().map_or(0, |f| {
            f.tiles.iter().map(KeptTile::memory_bytes).sum::<usize>()
                + f.screen.len() * std::mem::size_of::<ScreenRect>()
        })
    }
}

/// One frame's kept samples, tile by tile, and what they were traced under.
struct KeptFrame {
    frame: u32,
    view: u64,
    lights: u64,
    /// Where the moving boxes showed on the film.
    screen: Vec<ScreenRect>,
    tiles: Vec<KeptTile>,
}

/// One tile's kept samples (its base samples, in order) and the coverage
/// of its candidate edge pixels.
#[derive(Default)]
struct KeptTile {
    samples: Vec<StillSample>,
    coverage: Vec<CandidateCoverage>,
    /// The lookups its samples index (`StillSample::lookup`); `None` where
    /// they did not fit the budget.
    lookups: Option<Vec<KeptLookup>>,
    /// The path-traced parts of its samples that nothing moving met.
    queries: KeptQueries,
}

impl KeptTile {
    fn memory_bytes(&self) -> usize {
        self.samples.len() * std::mem::size_of::<StillSample>()
            + self.coverage.len() * std::mem::size_of::<CandidateCoverage>()
            + self.lookups.as_ref().map_or(0, Vec::len) * std::mem::size_of::<KeptLookup>()
            + self.queries.memory_bytes()
    }
}

/// The part of the film, in pixels (`x0, y0, x1, y1`), where a box may
/// show: the bounds of its corners' projections, or the whole plane where
/// a corner lies behind the camera.
type ScreenRect = [f32; 4];

/// One base pixel sample as traced: its camera ray, hit, stream after the
/// camera's draw, its direct light's shadow (`None`: it had none) and its
/// cache lookup (an index into its tile's kept lookups, [`NO_LOOKUP`]:
/// none).
#[derive(Clone)]
struct StillSample {
    ray: Ray,
    hit: Hit,
    rng: Rng,
    shadow: Option<KeptShadow>,
    lookup: u32,
}

/// A kept sample's lookup index where it looked nothing up.
const NO_LOOKUP: u32 = u32::MAX;

/// A cache lookup of a tile's base samples as this frame made it, and
/// whether no moving box lay on its clearance ray then (so what the ray
/// hit, if anything, was static).
#[derive(Clone, Copy)]
struct KeptLookup {
    at: Lookup,
    clear: bool,
}

/// A shadow ray, what its light adds if unoccluded, whether it was, and
/// whether no moving box lay on it in the frame it is kept from.
#[derive(Clone, Copy)]
struct KeptShadow {
    ray: Ray,
    contribution: Vec3,
    occluded: bool,
    clear: bool,
}

/// One render pass's view of the kept samples: this frame's moving boxes,
/// and the last frame's samples where they may be taken.
struct StillPass {
    frame: u32,
    view: u64,
    lights: u64,
    blockers: Blockers,
    /// Where this frame's moving boxes show on the film, `width` pixels
    /// wide.
    screen: Vec<ScreenRect>,
    width: u32,
    /// The last frame, when it was the one before with the same view.
    last: Option<KeptFrame>,
    /// Whether the lights are where they were (else no shadow is kept).
    lights_still: bool,
    /// A distance from the camera past every moving box: a camera ray that
    /// hit nothing is tested as a segment that long.
    far: f32,
    /// Bytes each tile's kept lookups and queries ([`KeptQueries`]) may
    /// take, the lookups first.
    tile_budget: usize,
}

impl StillPass {
    /// `None` where a frame's samples would not fit the budget.
    fn new(
        ctx: &FrameContext,
        last: Option<KeptFrame>,
        spp: u32,
        pixels_per_tile: usize,
    ) -> Option<Self> {
        let samples = ctx.width as usize * ctx.height as usize * spp as usize;
        let samples_bytes = samples.saturating_mul(std::mem::size_of::<StillSample>());
        if samples_bytes > StillSamples::BUDGET_BYTES {
            return None;
        }
        // What the samples leave of the budget, shared by the tiles' kept
        // lookups and queries.
        let tiles = (ctx.width as usize * ctx.height as usize).div_ceil(pixels_per_tile.max(1));
        let tile_budget = (StillSamples::BUDGET_BYTES - samples_bytes) / tiles.max(1);
        let view = view_fingerprint(ctx, spp, pixels_per_tile);
        let lights = lights_fingerprint(ctx);
        let last = last.filter(|l| l.frame.checked_add(1) == Some(ctx.frame) && l.view == view);
        let blockers = Blockers::new(ctx);
        let camera = ctx.snapshot.camera.position;
        let far = blockers
            .boxes
            .iter()
            .map(|&(lo, hi)| (lo - camera).abs().max((hi - camera).abs()).length())
            .fold(0.0f32, f32::max)
            * 2.0
            + 1.0;
        let screen = blockers
            .boxes
            .iter()
            .map(|&b| screen_rect(ctx, b))
            .collect();
        Some(StillPass {
            frame: ctx.frame,
            view,
            lights,
            lights_still: last.as_ref().is_some_and(|l| l.lights == lights),
            blockers,
            screen,
            width: ctx.width,
            last,
            far,
            tile_budget,
        })
    }

    fn tile(&self, tile: usize) -> TileStill<'_> {
        let kept = self.last.as_ref().and_then(|l| l.tiles.get(tile));
        TileStill {
            pass: self,
            samples: kept.map_or(&[][..], |k| k.samples.as_slice()),
            coverage: kept.map_or(&[][..], |k| k.coverage.as_slice()),
            lookups: kept.and_then(|k| k.lookups.as_deref()),
            queries: kept.map(|k| &k.queries),
        }
    }

    fn finish(self, tiles: Vec<KeptTile>) -> KeptFrame {
        KeptFrame {
            frame: self.frame,
            view: self.view,
            lights: self.lights,
            screen: self.screen,
            tiles,
        }
    }

    /// Whether no camera ray through `pixel` can have met a moving object
    /// in the last frame or this one: no moving box's film rect, in either
    /// frame, comes within a pixel of its square. Then every ray through
    /// it, whatever its position in the pixel, sees what it saw (lights
    /// and view staying).
    fn pixel_clear(&self, pixel: u32) -> bool {
        let Some(last) = self.last.as_ref().filter(|_| self.lights_still) else {
            return false;
        };
        self.film_clear(pixel) && film_clear(&last.screen, self.width, pixel)
    }

    /// Whether the lights moved since the last frame (not when there is
    /// none to compare with).
    fn lights_moved(&self) -> bool {
        self.last.is_some() && !self.lights_still
    }

    /// Whether a camera ray's hit stands this frame: it hit a static
    /// triangle or nothing, and no moving box lies on its way there (none
    /// shows near its pixel on the film, `film_clear`, or its segment
    /// misses every box).
    fn hit_stands(&self, ray: &Ray, hit: &Hit, film_clear: bool) -> bool {
        if hit.is_hit() && self.blockers.is_moving_triangle(hit.triangle) {
            return false;
        }
        if film_clear {
            return true;
        }
        let t = if hit.is_hit() {
            hit.t
        } else {
            self.far / ray.dir().length()
        };
        !self.blockers.segment_may_hit(ray.origin(), ray.at(t))
    }

    /// Whether a shadow ray's outcome stands this frame: the lights stayed
    /// and no moving box lay on it in the last frame (`clear`: so what
    /// stopped it, if anything, was static) nor lies on it now.
    fn shadow_stands(&self, shadow: &KeptShadow) -> bool {
        self.lights_still && shadow.clear && self.shadow_clear(&shadow.ray)
    }

    /// Whether no moving box of this frame lies on shadow ray `ray`.
    fn shadow_clear(&self, ray: &Ray) -> bool {
        !self
            .blockers
            .segment_may_hit(ray.origin(), ray.origin() + ray.dir())
    }

    /// Whether no moving box of this frame shows within a pixel of
    /// `pixel` on the film.
    fn film_clear(&self, pixel: u32) -> bool {
        film_clear(&self.screen, self.width, pixel)
    }

    /// Whether no moving box of this frame lies on lookup `at`'s clearance
    /// ray ([`measure_clearance`]'s, to its hit or, where it hit nothing,
    /// past every box) nor holds its hit, and the ray is not so short that
    /// another BVH might miss its hit ([`motion::path_long_enough`]): then
    /// what it hit, if anything, was static.
    fn clearance_clear(&self, at: &Lookup, camera: Vec3) -> bool {
        let origin = offset_origin(at.position, at.normal, at.normal);
        let length = if at.clearance == LookupPoint::OPEN {
            self.far + (at.position - camera).length()
        } else {
            at.clearance
        };
        let end = origin + at.normal * length;
        // A hit on a moving object lies in its box, but the segment may stop
        // a rounding error short of the box's face: the end is tested with
        // a margin.
        let margin = Vec3::splat(1e-4 * (1.0 + end.abs().max_element()));
        motion::path_long_enough(&[[origin, end]])
            && !self.blockers.segment_may_hit(origin, end)
            && !self.blockers.box_may_hit((end - margin, end + margin))
    }

    /// This frame's lookups of the tile's base samples (`of_sample`, the
    /// first `taken.len()` of them), for the next frame, where they fit in
    /// `budget` bytes (`None` where they do not): each with whether its
    /// clearance ray is clear, known for the lookups from `first_kept` on
    /// (taken from the last frame, they stood); and each base sample's
    /// index among them.
    fn keep_lookups(
        &self,
        camera: Vec3,
        (lookups, of_sample): (&[Lookup], &[Option<u32>]),
        first_kept: usize,
        budget: usize,
    ) -> Option<(Vec<KeptLookup>, Vec<u32>)> {
        let mut index = vec![NO_LOOKUP; lookups.len()];
        let mut kept = Vec::new();
        let of_base = of_sample
            .iter()
            .map(|k| {
                let Some(k) = k.map(|k| k as usize) else {
                    return NO_LOOKUP;
                };
                if index[k] == NO_LOOKUP {
                    index[k] = kept.len() as u32;
                    let at = lookups[k];
                    let clear = k >= first_kept || self.clearance_clear(&at, camera);
                    kept.push(KeptLookup { at, clear });
                }
                index[k]
            })
            .collect();
        (kept.len() * std::mem::size_of::<KeptLookup>() <= budget).then_some((kept, of_base))
    }
}

/// One tile's part of a [`StillPass`]: its samples in the last frame and
/// the coverage of its candidate edge pixels then.
struct TileStill<'a> {
    pass: &'a StillPass,
    samples: &'a [StillSample],
    coverage: &'a [CandidateCoverage],
    lookups: Option<&'a [KeptLookup]>,
    queries: Option<&'a KeptQueries>,
}

impl TileStill<'_> {
    /// Base sample `i` of the last frame, if its hit stands (`film_clear`:
    /// whether no moving box shows near its pixel).
    fn primary(&self, i: usize, film_clear: bool) -> Option<&StillSample> {
        self.samples
            .get(i)
            .filter(|k| self.pass.hit_stands(&k.ray, &k.hit, film_clear))
    }

    /// Whether base sample `i`'s hit was taken (`taken`) and its shadow in
    /// the last frame stands (or it had none, and has none again).
    fn shadow_stands(&self, i: usize, taken: &[bool]) -> bool {
        taken.get(i).copied().unwrap_or(false)
            && self.pass.lights_still
            && self.samples[i]
                .shadow
                .is_none_or(|s| self.pass.shadow_stands(&s))
    }
}

/// What of the last frame's shading of a tile's base samples stands this
/// frame.
struct Standing {
    /// Per base sample, whether its shadow stands
    /// ([`TileStill::shadow_stands`]).
    shadows: Vec<bool>,
    /// Per base sample, whether its pixel is kept whole: it is no light's
    /// edge pixel (with extra samples), every sample of it has its hit and
    /// shadow taken and a plain material ([`Surface::is_plain`]), and no
    /// moving box lies on the clearance ray of any lookup they made, in the
    /// last frame or this one. Such a
    /// pixel takes its lookups from the last frame, and its samples need
    /// no [`Surface`] unless one falls back to path tracing.
    whole: Vec<bool>,
}

impl TileStill<'_> {
    /// What of the tile's base samples (the first `taken.len()` of
    /// `primary`, `taken` saying whose hits were taken) stands.
    fn standing(&self, ctx: &FrameContext, primary: &PrimarySamples, taken: &[bool]) -> Standing {
        let shadows: Vec<bool> = (0..taken.len())
            .map(|i| self.shadow_stands(i, taken))
            .collect();
        let mut whole = vec![false; taken.len()];
        let Some(lookups) = self.lookups else {
            return Standing { shadows, whole };
        };
        let camera = ctx.snapshot.camera.position;
        // Each lookup tested once: a pixel's samples share it.
        let mut stands = vec![None; lookups.len()];
        let mut lookup_stands = |k: u32| {
            k == NO_LOOKUP
                || *stands[k as usize].get_or_insert_with(|| {
                    let kept = lookups[k as usize];
                    kept.clear && self.pass.clearance_clear(&kept.at, camera)
                })
        };
        let (base, extra) = primary.samples.split_at(taken.len());
        // A light's edge pixels have extra samples, which may share their
        // base samples' lookups: those pixels are never kept whole.
        let mut edges: Vec<u32> = extra.iter().map(|s| s.pixel).collect();
        edges.sort_unstable();
        edges.dedup();
        let mut start = 0;
        while start < base.len() {
            let pixel = base[start].pixel;
            let end = start
                + base[start..]
                    .iter()
                    .take_while(|s| s.pixel == pixel)
                    .count();
            let kept = edges.binary_search(&pixel).is_err()
                && (start..end).all(|i| {
                    shadows[i]
                        && Surface::is_plain(ctx, &primary.hits[i])
                        && lookup_stands(self.samples[i].lookup)
                });
            whole[start..end].fill(kept);
            start = end;
        }
        Standing { shadows, whole }
    }

    /// The last frame's lookups of the samples `whole` keeps, appended to
    /// `lookups` (each once) and indexed from `of_sample`; how many.
    fn take_lookups(
        &self,
        whole: &[bool],
        lookups: &mut Vec<Lookup>,
        of_sample: &mut [Option<u32>],
    ) -> u64 {
        let Some(kept) = self.lookups else {
            return 0;
        };
        let first = lookups.len();
        let mut index = vec![NO_LOOKUP; kept.len()];
        for (i, _) in whole.iter().enumerate().filter(|(_, &w)| w) {
            let k = self.samples[i].lookup;
            if k == NO_LOOKUP {
                continue;
            }
            if index[k as usize] == NO_LOOKUP {
                index[k as usize] = lookups.len() as u32;
                lookups.push(kept[k as usize].at);
            }
            of_sample[i] = Some(index[k as usize]);
        }
        (lookups.len() - first) as u64
    }
}

/// A tile's base samples as traced this frame and its candidates'
/// coverage (empty when nothing is kept), and how many of its samples were
/// taken from the last frame.
struct TileKept {
    tile: KeptTile,
    taken: u64,
    /// Lookups taken from the last frame (those of pixels kept whole).
    lookups_taken: u64,
    /// Path-traced queries taken from the last frame.
    queries_taken: u64,
}

impl TileKept {
    /// The base samples (the first `taken.len()`) of `primary`, with their
    /// streams as the camera left them (`jittered`; none: nothing is kept),
    /// their shadows and their lookups (`None`: not kept; then no pixel of
    /// the tile can be kept whole next frame), and the coverage `edges`
    /// found.
    fn of(
        primary: &PrimarySamples,
        taken: &[bool],
        jittered: Vec<Rng>,
        shadows: Vec<Option<KeptShadow>>,
        lookups: Option<(Vec<KeptLookup>, Vec<u32>)>,
        edges: &EmitterEdges,
    ) -> Self {
        let keep = !jittered.is_empty();
        let (lookups, of_sample) = lookups.unzip();
        let samples = jittered
            .into_iter()
            .enumerate()
            .map(|(i, rng)| StillSample {
                ray: primary.rays[i],
                hit: primary.hits[i],
                rng,
                shadow: shadows[i],
                lookup: of_sample.as_ref().map_or(NO_LOOKUP, |l| l[i]),
            })
            .collect();
        let coverage = if keep {
            edges.coverage().to_vec()
        } else {
            Vec::new()
        };
        TileKept {
            tile: KeptTile {
                samples,
                coverage,
                lookups,
                queries: KeptQueries::default(),
            },
            taken: taken.iter().filter(|&&t| t).count() as u64,
            lookups_taken: 0,
            queries_taken: 0,
        }
    }
}

/// Whether none of `rects` comes within a pixel of `pixel`'s square on a
/// film `width` pixels wide.
fn film_clear(rects: &[ScreenRect], width: u32, pixel: u32) -> bool {
    let (x, y) = ((pixel % width) as f32, (pixel / width) as f32);
    let square = [x - 1.0, y - 1.0, x + 2.0, y + 2.0];
    !rects
        .iter()
        .any(|r| r[0] <= square[2] && square[0] <= r[2] && r[1] <= square[3] && square[1] <= r[3])
}

/// Where box `(lo, hi)` may show on the film, in pixels ([`ScreenRect`]).
fn screen_rect(ctx: &FrameContext, (lo, hi): (Vec3, Vec3)) -> ScreenRect {
    const WHOLE_PLANE: ScreenRect = [
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::INFINITY,
    ];
    let (w, h) = (ctx.width as f32, ctx.height as f32);
    let mut rect = [
        f32::INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
    ];
    for k in 0..8 {
        let corner = Vec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let Some((sx, sy)) = ctx.snapshot.camera.project(corner, ctx.aspect()) else {
            return WHOLE_PLANE;
        };
        let (x, y) = (sx * w, sy * h);
        rect = [
            rect[0].min(x),
            rect[1].min(y),
            rect[2].max(x),
            rect[3].max(y),
        ];
    }
    rect
}

/// What places a frame's pixel samples: the camera, the film, the samples
/// and tiles, and which triangles are static. Two frames with the same
/// one draw the same camera rays under coherent streams.
fn view_fingerprint(ctx: &FrameContext, spp: u32, pixels_per_tile: usize) -> u64 {
    let camera = &ctx.snapshot.camera;
    let floats = camera
        .position
        .to_array()
        .into_iter()
        .chain(camera.basis.to_cols_array())
        .chain([camera.yfov]);
    let counts = [
        u64::from(ctx.width),
        u64::from(ctx.height),
        u64::from(spp),
        pixels_per_tile as u64,
        u64::from(ctx.edge_coverage_factor),
        ctx.snapshot.static_count as u64,
        ctx.snapshot.triangles.len() as u64,
        ctx.seed,
    ];
    fingerprint(floats, counts)
}

/// Where the lights are and what they send: two frames with the same one
/// give every shading point the same light samples.
pub(crate) fn lights_fingerprint(ctx: &FrameContext) -> u64 {
    let snapshot = ctx.snapshot;
    let triangles = ctx
        .lights
        .emitting_triangles()
        .flat_map(|id| snapshot.triangles[id].p)
        .flat_map(|p| p.to_array());
    let points = snapshot.lights.iter().flat_map(|l| {
        [l.position, l.direction, l.intensity]
            .into_iter()
            .flat_map(|v| v.to_array())
    });
    let ids = ctx.lights.emitting_triangles().map(|id| id as u64);
    fingerprint(
        triangles.chain(points),
        ids.chain([ctx.lights.pick_fingerprint(), snapshot.lights.len() as u64]),
    )
}

/// A hash of some floats (by their bits) and integers.
fn fingerprint(floats: impl Iterator<Item = f32>, ints: impl IntoIterator<Item = u64>) -> u64 {
    let h = floats.fold(0x5eed, |h, f| mix64(h ^ u64::from(f.to_bits())));
    ints.into_iter().fold(h, |h, i| mix64(h.rotate_left(7) ^ i))
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

    /// One frame rendered with kept samples and afresh.
    #[derive(Clone, Copy, Debug, PartialEq)]
    struct KeptCheck {
        /// Whether the two films are the same bit for bit.
        same: bool,
        /// Samples, lookups and path-traced queries taken from the last
        /// frame.
        taken: u64,
        lookups_taken: u64,
        queries_taken: u64,
        /// Rays each traced.
        kept_rays: u64,
        fresh_rays: u64,
    }

    /// Renders `frames` in turn with one kept [`StillSamples`] under an
    /// `ic` cache of each frame, and again each afresh (nothing kept), with
    /// coherent streams.
    fn kept_against_fresh(scene: &str, frames: &[u32]) -> Vec<KeptCheck> {
        let mut renderer = crate::render::test_renderer(scene, 20);
        let ic = IrradianceCaching::new(IcSettings {
            spp: 4,
            strata: Strata { theta: 4, phi: 12 },
            ..IcSettings::default()
        });
        let mut still = StillSamples::default();
        frames
            .iter()
            .map(|&frame| {
                renderer.with_frame_context(frame, |ctx| {
                    let cache = ic.build_cache(ctx);
                    let render = |still: Option<&mut StillSamples>| {
                        let before = ctx.backend.ray_counts().total();
                        let film = render_pass(
                            ctx,
                            &cache,
                            &ic.settings,
                            PixelStreams::Coherent,
                            None,
                            still,
                            &mut FrameStats::default(),
                        );
                        (film, ctx.backend.ray_counts().total() - before)
                    };
                    let (kept, kept_rays) = render(Some(&mut still));
                    let (fresh, fresh_rays) = render(None);
                    let same = kept.pixels.iter().zip(&fresh.pixels).all(|(a, b)| {
                        a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
                    });
                    KeptCheck {
                        same,
                        taken: still.taken,
                        lookups_taken: still.lookups_taken,
                        queries_taken: still.queries_taken,
                        kept_rays,
                        fresh_rays,
                    }
                })
            })
            .collect()
    }

    /// What a frame rendered with nothing to take from gives.
    fn took_nothing(check: KeptCheck) -> bool {
        check.same
            && check.taken == 0
            && check.lookups_taken == 0
            && check.queries_taken == 0
            && check.kept_rays == check.fresh_rays
    }

    /// A frame whose samples are taken from the last one where nothing
    /// moving met them equals, bit for bit, the frame traced afresh: on
    /// `cube-in-box` (a cube moves; the camera and light stay) most samples
    /// are taken and fewer rays traced, the path-traced indirect light of
    /// samples no record covers and the cache lookups of pixels kept whole
    /// too; where the moving cube's box lies on their rays some are not; a
    /// frame that does not follow the last one takes none.
    #[test]
    fn kept_samples_give_the_frame_traced_afresh() {
        let frames = kept_against_fresh("cube-in-box", &[3, 4, 5, 9]);
        let samples = 20 * 20 * 4;
        assert!(took_nothing(frames[0]), "{:?}", frames[0]);
        for check in &frames[1..3] {
            assert!(check.same, "{check:?}");
            assert!(
                check.taken > samples / 2 && check.taken < samples,
                "{check:?} of {samples} samples"
            );
            assert!(check.lookups_taken > 0, "{check:?}");
            assert!(check.queries_taken > 0, "{check:?}");
            assert!(check.kept_rays < check.fresh_rays / 2, "{check:?}");
        }
        assert!(took_nothing(frames[3]), "{:?}", frames[3]);
    }

    /// On `glossy-cornell` (glossy walls and blocks, a block moving) the
    /// glossy lobes of the still samples are taken too, and the frame is
    /// the one traced afresh.
    #[test]
    fn kept_glossy_lobes_give_the_frame_traced_afresh() {
        let frames = kept_against_fresh("glossy-cornell", &[6, 7]);
        assert!(took_nothing(frames[0]), "{:?}", frames[0]);
        let check = frames[1];
        assert!(check.same, "{check:?}");
        assert!(check.queries_taken > 100, "{check:?}");
        assert!(check.kept_rays < check.fresh_rays / 2, "{check:?}");
    }

    /// A lookup whose clearance ray hits the moving cube is not kept, though
    /// the ray ends on the cube's face (where a segment test alone may stop
    /// a rounding error short of its box); one whose ray passes beside the
    /// cube is.
    #[test]
    fn a_clearance_ray_that_hits_a_moving_object_is_not_clear() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 16);
        // Frame 0: the cube is not turned, so its faces are its box's.
        renderer.with_frame_context(0, |ctx| {
            let pass = StillPass::new(ctx, None, 1, 16).expect("a small frame fits");
            let (lo, hi) = pass.blockers.boxes[0];
            let camera = ctx.snapshot.camera.position;
            // Back-wall points behind the cube and beside it, found by rays
            // from just behind the cube's box.
            let wall_behind = |x: f32, y: f32| {
                let ray = Ray::new(
                    Vec3::new(x, y, lo.z - 1e-3),
                    Vec3::NEG_Z,
                    0.0,
                    f32::INFINITY,
                );
                let mut hit = [Hit::MISS];
                ctx.backend.closest_hit(&[ray], &mut hit);
                assert!(hit[0].is_hit(), "a wall behind ({x}, {y})");
                ray.at(hit[0].t)
            };
            let mid = (lo + hi) * 0.5;
            let beside = mid.x + (hi.x - lo.x) * 1.5;
            let points = [
                (wall_behind(mid.x, mid.y), Vec3::Z),
                (wall_behind(beside, mid.y), Vec3::Z),
            ];
            let lookups = measure_clearance(ctx, &points);
            let (behind, open) = (lookups[0], lookups[1]);
            assert!(
                (behind.clearance - (lo.z - behind.position.z)).abs() < 1e-2,
                "the ray behind the cube hits its back: {behind:?}, box {lo}..{hi}"
            );
            assert!(open.clearance > hi.z - open.position.z, "{open:?}");
            assert!(!pass.clearance_clear(&behind, camera));
            assert!(pass.clearance_clear(&open, camera));
        });
    }

    /// A box's film rect holds every film point whose camera ray meets the
    /// box, by brute force: rays through random points of the film (and a
    /// pixel's margin around it) tested against random boxes in front of
    /// the camera by the slab test; many meet one, and none of those lies
    /// outside its rect. A box around the camera covers the plane.
    #[test]
    fn a_box_shows_only_inside_its_film_rect() {
        let size = 32;
        let mut renderer = crate::render::test_renderer("cube-in-box", size);
        renderer.with_frame_context(0, |ctx| {
            let camera = &ctx.snapshot.camera;
            let mut rng = Rng::from_seed(3, 0);
            let forward = -camera.basis.z_axis;
            let mut met = 0;
            for _ in 0..200 {
                let mut v = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let centre = camera.position + forward * (1.0 + 5.0 * v().x) + (v() - 0.5) * 3.0;
                let half = v() * 0.5;
                let (lo, hi) = (centre - half, centre + half);
                let rect = screen_rect(ctx, (lo, hi));
                for _ in 0..200 {
                    let film = v() * (size as f32 + 2.0) - Vec3::ONE;
                    let (sx, sy) = (film.x / size as f32, film.y / size as f32);
                    let dir = camera.direction(sx, sy, ctx.aspect());
                    let far = camera.position + dir * 100.0;
                    if crate::method::motion::segment_hits_box(camera.position, far, (lo, hi)) {
                        met += 1;
                        let inside = rect[0] <= film.x + 1e-3
                            && film.x <= rect[2] + 1e-3
                            && rect[1] <= film.y + 1e-3
                            && film.y <= rect[3] + 1e-3;
                        assert!(inside, "film point {film} meets the box outside {rect:?}");
                    }
                }
            }
            assert!(met > 1000, "only {met} rays met a box");
            let around = (camera.position - Vec3::ONE, camera.position + Vec3::ONE);
            assert_eq!(screen_rect(ctx, around)[0], f32::NEG_INFINITY);
        });
    }

    /// Under a moving light every sample keeps its hit but traces its
    /// shadow ray and its path-traced parts again, and the frames still
    /// equal those traced afresh.
    #[test]
    fn kept_samples_under_a_moving_light_trace_their_shadows_again() {
        let frames = kept_against_fresh("moving-light", &[3, 4]);
        let check = frames[1];
        assert!(check.same && frames[0].same);
        assert!(check.taken > 0);
        // Their paths' light moved too, and no pixel is kept whole.
        assert_eq!(check.queries_taken, 0);
        assert_eq!(check.lookups_taken, 0);
        let KeptCheck {
            taken,
            kept_rays,
            fresh_rays,
            ..
        } = check;
        assert!(
            kept_rays < fresh_rays,
            "{kept_rays} rays against {fresh_rays}"
        );
        let shadows = fresh_rays - kept_rays;
        assert!(
            shadows <= taken,
            "{shadows} rays saved by {taken} samples taken"
        );
    }

    /// `trc`'s first pass flags the records the render pass will use: on a
    /// scene whose light is in view (so edge pixels add shaded samples), the
    /// flags of [`mark_used`] equal those the render pass sets, with either
    /// kind of streams, and with samples kept from the frame before. (Here
    /// no record is used by an edge pixel's extra sample alone, so this
    /// guards the invariant rather than reproducing that case.)
    #[test]
    fn mark_used_flags_exactly_the_records_the_render_pass_uses() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 20);
        let ic = IrradianceCaching::new(IcSettings {
            spp: 4,
            strata: Strata { theta: 4, phi: 12 },
            ..IcSettings::default()
        });
        for streams in [PixelStreams::PerFrame, PixelStreams::Coherent] {
            let (mut still, mut first_pass) = (StillSamples::default(), StillSamples::default());
            for frame in [1, 2] {
                let (marked, rendered) = renderer.with_frame_context(frame, |ctx| {
                    let cache = ic.build_cache(ctx);
                    let flags = || -> Vec<AtomicBool> {
                        (0..cache.len()).map(|_| AtomicBool::new(false)).collect()
                    };
                    let (marked, rendered) = (flags(), flags());
                    mark_used(
                        ctx,
                        &cache,
                        &ic.settings,
                        streams,
                        &marked,
                        Some(&mut first_pass),
                    );
                    let mut stats = FrameStats::default();
                    render_pass(
                        ctx,
                        &cache,
                        &ic.settings,
                        streams,
                        Some(&rendered),
                        Some(&mut still),
                        &mut stats,
                    );
                    let read = |f: Vec<AtomicBool>| -> Vec<bool> {
                        f.into_iter().map(AtomicBool::into_inner).collect()
                    };
                    (read(marked), read(rendered))
                });
                assert!(rendered.iter().any(|&u| u));
                assert_eq!(marked, rendered, "{streams:?}, frame {frame}");
            }
            let kept = if streams == PixelStreams::Coherent {
                1
            } else {
                0
            };
            assert_eq!(u64::from(still.taken > 0), kept, "{streams:?}");
            assert_eq!(u64::from(first_pass.taken > 0), kept, "{streams:?}");
        }
    }
}
