//! The rendering stage that `ic`, `trc` and `tcg` share (EAS Algorithm
//! 1, lines 18–24): per pixel sample the outgoing radiance is split as
//! `L = Le + L_direct + kd/π·E_indirect + L_glossy`:
//! - direct light by next-event estimation (one light sample per pixel
//!   sample; the glossy lobe's part MIS-weighted against lobe sampling),
//! - indirect diffuse from the cache: `E_indirect` interpolated with
//!   gradients (TRC Eq. 1–4), looked up once per pixel and triangle for
//!   the pixel's samples on it (`tile_lookups`) — on the CPU, or on the
//!   GPU by radiance cache splatting (TRC §5, `backend::gpu::cache_splat`) when
//!   the ray backend is the GPU one,
//! - the glossy lobe by path tracing from a lobe sample, or with
//!   `--ic-glossy eas` its indirect light from the records' equivalent
//!   area light sources (EAS paper Eq. 17, [`crate::cache::eas`]) and the
//!   lobe sample's ray traced to its first hit only, for the emission
//!   there that MIS weighs against the light sample.
//!
//! The methods differ only in the cache they hand it and in how their
//! pixel samples draw their random streams ([`PixelStreams`]). `trc` and
//! `tcg` also ask which records the pass uses (`render_pass`'s `used`,
//! `mark_used`). `movies` has a render pass of its own but shades with
//! this one's parts (its direct light, glossy lobes and primary samples).
//! With streams that are the same in every frame, the pass keeps the
//! primary hits, direct light, path-traced parts and cache lookups of the
//! last frame's samples and traces again only those that something moving
//! may have changed ([`StillSamples`]).
//!
//! Here is the pass, tile by tile; its parts are the submodules
//! `tile_lookups` (a tile's cache lookups), `shading` (a tile's samples
//! shaded: emission, direct light, indirect light and glossy lobes),
//! `still` (what is kept for the next frame, and what of it stands) and
//! `kept_queries` (the path-traced parts kept).

mod kept_queries;
mod shading;
mod still;
mod still_tile;
mod tile_lookups;

use super::ic::IcSettings;
use super::lookups::Interpolation;
pub use super::pixels::PixelStreams;
use super::pixels::{self, CameraSampler, EmitterEdges, KeptCoverage, PixelSample};
use super::{FrameContext, FrameStats};
use crate::backend::{Hit, Ray};
use crate::cache::gather::GatherPoint;
use crate::cache::IrradianceCache;
use crate::film::Film;
use crate::integrator::{trace_radiance, FirstHitEmission, PathLength, RadianceQuery, RayOffset};
use crate::material::Bsdf;
use crate::sampling::{cosine_hemisphere, Rng};
use glam::Vec3;
use kept_queries::{KeptQueries, TileQueries};
use rayon::prelude::*;
use shading::TileShading;
pub(crate) use shading::{direct_light, glossy_query};
use std::sync::atomic::AtomicBool;
pub(crate) use still::lights_fingerprint;
use still::StillPass;
pub use still::StillSamples;
use still_tile::{KeptLookup, KeptTile, TileKept, TileStill};
use tile_lookups::{pixel_lookups, TileLookups};

/// A shaded hit: position, normals and BSDF.
pub(crate) struct Surface<'a> {
    p: Vec3,
    ng: Vec3,
    /// How rays leave it (the frame's).
    offset: RayOffset,
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
            offset: ctx.ray_offset,
            wo,
            bsdf: Bsdf::new(material, triangle.shading_normal(hit.u, hit.v), wo),
            material,
            triangle,
        })
    }

    /// Whether a hit's shading needs no more than its diffuse albedo and
    /// cache lookup (a miss, or a material that neither emits nor has a
    /// glossy lobe): what a pixel kept whole may hold ([`Standing`](still_tile::Standing)).
    fn is_plain(ctx: &FrameContext, hit: &Hit) -> bool {
        !hit.is_hit() || {
            let m = material_of(ctx, hit);
            !m.is_emissive() && !m.is_glossy()
        }
    }

    /// The origin of a ray leaving the surface towards `w`.
    pub(crate) fn origin_towards(&self, w: Vec3) -> Vec3 {
        self.offset.origin(self.p, self.ng, w)
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
    let mut still_pass = still
        .as_mut()
        .and_then(|s| s.begin(ctx, spp, pixels_per_tile));
    let last_tiles = take_tiles(still_pass.as_mut(), film.pixels.len(), pixels_per_tile);
    let pass = TilePass {
        interpolation: &interpolation,
        settings,
        streams,
        used,
    };
    let tiles: Vec<(FrameStats, TileKept)> = film
        .pixels
        .par_chunks_mut(pixels_per_tile)
        .zip(last_tiles)
        .enumerate()
        .map(|(tile, (out, last))| {
            let first = (tile * pixels_per_tile) as u32;
            let still = still_pass.as_ref().zip(last).map(|(p, last)| p.tile(last));
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
    let mut still_pass = still
        .as_mut()
        .and_then(|s| s.begin(ctx, spp, pixels_per_tile));
    let last_tiles = take_tiles(still_pass.as_mut(), n_pixels, pixels_per_tile);
    let tiles: Vec<TileKept> = last_tiles
        .into_par_iter()
        .enumerate()
        .map(|(tile, last)| {
            if ctx.abandoned() {
                return TileKept::default();
            }
            let first = tile * pixels_per_tile;
            let count = pixels_per_tile.min(n_pixels - first);
            let mut still = still_pass.as_ref().zip(last).map(|(p, last)| p.tile(last));
            let (primary, edges, taken) = PrimarySamples::trace_keeping(
                ctx,
                streams,
                first as u32,
                count as u32,
                spp,
                still.as_mut(),
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
            TileKept::of(primary, &taken, jittered, shadows, None, &edges)
        })
        .collect();
    if let Some(still) = still {
        still.end(still_pass, tiles);
    }
}

/// The last frame's kept tiles, one per tile of `n_pixels` pixels in
/// tiles of `pixels_per_tile` (`None` each where nothing is kept, or the
/// tile lies past those the budget keeps), moved out of `still` for the
/// tiles to take from in parallel.
fn take_tiles(
    still: Option<&mut StillPass>,
    n_pixels: usize,
    pixels_per_tile: usize,
) -> Vec<Option<KeptTile>> {
    let n = n_pixels.div_ceil(pixels_per_tile.max(1));
    match still {
        Some(pass) => pass.take_tiles(n),
        None => (0..n).map(|_| None).collect(),
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
        mut still: Option<&mut TileStill>,
    ) -> (Self, EmitterEdges, Vec<bool>) {
        let mut primary = PrimarySamples::default();
        let base = pixels::tile_samples(first, count, spp);
        let last = still
            .as_deref_mut()
            .and_then(|s| s.take_primary(base.len()));
        let still = still.map(|s| &*s);
        let taken = match still.zip(last) {
            Some((still, last)) => primary.take_standing(ctx, streams, &base, still, last),
            None => {
                primary.add(ctx, streams, &base);
                vec![false; base.len()]
            }
        };
        // The first hits decide which pixels are on a light's edge.
        let clear = |pixel: u32| still.is_some_and(|s| s.pass.pixel_clear(pixel));
        let kept = still.map(|s| KeptCoverage {
            last: s.coverage(),
            clear: &clear,
        });
        let edges = EmitterEdges::find(
            ctx,
            streams,
            (&primary.samples, &primary.rays, &primary.hits),
            spp,
            kept.as_ref(),
        );
        primary.add(ctx, streams, edges.extra_samples());
        (primary, edges, taken)
    }

    /// The samples [`Self::trace`] gave for the same tile, from their hits
    /// alone: the samples, camera rays and streams drawn again, no ray
    /// traced. The camera draws each from its sample's key alone
    /// ([`CameraSampler::query`]), so they are bit for bit those the hits
    /// were traced along. A method that holds a whole frame's samples can
    /// keep their hits alone (20 of a sample's 84 bytes).
    pub(crate) fn again(
        ctx: &FrameContext,
        streams: PixelStreams,
        (first, count, spp): (u32, u32, u32),
        edges: &EmitterEdges,
        hits: Vec<Hit>,
    ) -> Self {
        let mut samples = pixels::tile_samples(first, count, spp);
        samples.extend_from_slice(edges.extra_samples());
        debug_assert_eq!(samples.len(), hits.len());
        let mut camera = CameraSampler::new(streams);
        let (rays, rngs) = samples.iter().map(|s| camera.query(ctx, s)).unzip();
        PrimarySamples {
            samples,
            rays,
            rngs,
            hits,
        }
    }

    /// Appends `samples`, tracing their camera rays.
    fn add(&mut self, ctx: &FrameContext, streams: PixelStreams, samples: &[PixelSample]) {
        let start = self.rays.len();
        // Exactly: the base samples' vectors are kept for the next frame
        // (`TileKept::of`), and a doubling for a light rim's few extra
        // samples would be kept with them.
        self.rays.reserve_exact(samples.len());
        self.rngs.reserve_exact(samples.len());
        self.hits.reserve_exact(samples.len());
        self.samples.reserve_exact(samples.len());
        let mut camera = CameraSampler::new(streams);
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

    /// Starts the samples with the tile's base `samples` as the last frame
    /// traced them (`last`: camera rays, hits and streams after the camera,
    /// moved out of `still`), keeping those whose hits stand and tracing
    /// the camera rays of the others again; returns which were kept.
    fn take_standing(
        &mut self,
        ctx: &FrameContext,
        streams: PixelStreams,
        samples: &[PixelSample],
        still: &TileStill,
        last: (Vec<Ray>, Vec<Hit>, Vec<Rng>),
    ) -> Vec<bool> {
        debug_assert!(self.rays.is_empty());
        (self.rays, self.hits, self.rngs) = last;
        let mut camera = CameraSampler::new(streams);
        let mut taken = vec![false; samples.len()];
        let mut fresh = Vec::new();
        // Whether the current pixel is clear on the film (its samples are
        // consecutive).
        let mut film: Option<(u32, bool)> = None;
        for (i, s) in samples.iter().enumerate() {
            let clear = match film {
                Some((pixel, clear)) if pixel == s.pixel => clear,
                _ => still.pass.film_clear(s.pixel),
            };
            film = Some((s.pixel, clear));
            if still.hit_stands(&self.rays[i], &self.hits[i], clear) {
                taken[i] = true;
                continue;
            }
            let (ray, rng) = camera.query(ctx, s);
            self.rays[i] = ray;
            self.rngs[i] = rng;
            fresh.push(i);
        }
        if fresh.len() == samples.len() {
            ctx.backend.closest_hit(&self.rays, &mut self.hits);
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
    /// the next frame to go on from (none where nothing is `kept`), with
    /// room for this frame's extra samples: the next frame appends its own
    /// to them without growing them again, most often.
    fn jittered(&self, n: usize, kept: bool) -> Vec<Rng> {
        if kept {
            let mut rngs = Vec::with_capacity(self.rngs.len());
            rngs.extend_from_slice(&self.rngs[..n]);
            rngs
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
    mut still: Option<TileStill>,
) -> (FrameStats, TileKept) {
    if ctx.abandoned() {
        return Default::default();
    }
    let spp = pass.settings.spp.max(1);
    let mut stats = FrameStats::default();
    let (primary, edges, taken) = PrimarySamples::trace_keeping(
        ctx,
        pass.streams,
        first,
        out.len() as u32,
        spp,
        still.as_mut(),
    );
    let jittered = primary.jittered(taken.len(), still.is_some());
    let standing = still.as_ref().map(|s| s.standing(ctx, &primary, &taken));
    let (shadows, whole) = standing.map_or((Vec::new(), Vec::new()), |s| (s.shadows, s.whole));
    let mut tile = TileShading::new(ctx, primary, whole);
    let shadow_rays = tile.direct_light(ctx, pass.streams, &shadows);
    let lookups = TileLookups::new(ctx, pass, &tile, still.as_ref(), &mut stats);
    let deferred = tile.indirect_light(ctx, pass, &lookups, &mut stats);
    let last_shadows = still.as_mut().map(|s| (s.take_shadows(), &shadows[..]));
    let kept_shadows = shadow_rays.add_unoccluded(
        ctx,
        &mut tile.radiance,
        still.as_ref().map(|s| s.pass).zip(last_shadows),
    );
    // The next frame's lookups first, then its path-traced parts, in what
    // is left of the tile's budget.
    let kept_lookups = still
        .as_ref()
        .and_then(|s| lookups.keep(ctx, s, taken.len()));
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
        tile.primary,
        &taken,
        jittered,
        kept_shadows,
        kept_lookups,
        &edges,
    );
    kept.lookups_taken = lookups.taken;
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
                let last = Some(still.queries());
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

/// What every tile of one render pass shares.
struct TilePass<'a> {
    interpolation: &'a Interpolation<'a>,
    settings: &'a IcSettings,
    streams: PixelStreams,
    used: Option<&'a [AtomicBool]>,
}

/// Indirect diffuse light by path tracing, where no record is usable:
/// cosine sampling makes the weight `kd` (`kd/π · L · cosθ / (cosθ/π)`).
fn diffuse_indirect_query(s: &Surface, rng: &mut Rng) -> RadianceQuery {
    let frame = s.bsdf.frame;
    let wi = frame.to_world(cosine_hemisphere(rng.next_2d()));
    RadianceQuery {
        ray: Ray::new(s.origin_towards(wi), wi, 0.0, f32::INFINITY),
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

    /// The samples drawn again from a tile's hits are those traced, bit
    /// for bit, the extra samples of pixels on a light's edge included
    /// (cube-in-box shows its light), with either kind of streams.
    #[test]
    fn samples_drawn_again_from_their_hits_are_those_traced() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 24);
        for streams in [PixelStreams::PerFrame, PixelStreams::Coherent] {
            renderer.with_frame_context(3, |ctx| {
                let (first, count, spp) = (0, 24 * 24, 3);
                let (traced, edges) = PrimarySamples::trace(ctx, streams, first, count, spp);
                assert!(
                    !edges.extra_samples().is_empty(),
                    "no light edge in the tile"
                );
                let hits = traced.hits.clone();
                let again = PrimarySamples::again(ctx, streams, (first, count, spp), &edges, hits);
                assert_eq!(again.samples, traced.samples);
                assert_eq!(again.rays, traced.rays);
                assert_eq!(again.rngs, traced.rngs);
                assert_eq!(again.hits, traced.hits);
            });
        }
    }
}
