//! Which samples a pixel takes: the camera pass every method shares.
//!
//! Every pixel takes `spp` samples, box-filtered over its square and
//! multi-jittered among themselves ([`Stratified2d`]). A pixel on the edge
//! of a directly seen light
//! (some of its samples see an emitter's emitting side, others do not, or
//! the rays through its corners disagree with all of them) is then
//! post-stratified by what its camera rays see first: it traces
//! `edge_coverage_factor · spp` more camera rays, multi-jittered among
//! themselves and never shaded, that only measure how much of the pixel sees
//! an emitter, and its value is that fraction of the mean of its shaded
//! samples that see one plus the rest of the mean of those that do not.
//!
//! Why: the rim of a seen light is a few pixels many times brighter than
//! their neighbours, and with `spp` samples their coverage noise is most of
//! an all-pixel error (DESIGN.md "Measuring") whatever the method does about
//! lighting. Coverage is one ray a sample (and often no BVH query at all,
//! [`sees_emitter_first`]), where a shaded sample
//! also costs a shadow ray, a cache lookup or a path, so the rim gets the
//! coverage of many samples at the shading cost of `spp`: visibility sampled
//! more densely than shading, as MSAA does (and decoupled sampling,
//! Ragan-Kelley et al., "Decoupled Sampling for Graphics Pipelines", TOG
//! 2011). The pixel integral splits exactly into its emitter-seeing and
//! other parts; each part's mean is estimated from the shaded samples that
//! fall in it (uniform over the part, up to the stratification), each
//! part's area from all the camera rays. The rule is decided from the
//! first hits alone, before any shading (adaptive supersampling, Mitchell
//! 1987), and is the same in `path` and the caching methods, so their
//! comparison stays at equal samples per pixel. Every other pixel is the
//! plain mean of its `spp` samples, bit for bit what it is without the rule.

use super::FrameContext;
use crate::accel::ray_hits_triangle;
use crate::backend::{Hit, Ray, SHADOW_EPSILON};
use crate::light::{emitting_cosine, LightSampler};
use crate::sampling::{streams, LightChoice, Rng, SampleKey, Stratified2d};
use crate::scene::Snapshot;
use glam::Vec3;

/// Coverage-only camera rays an emitter-edge pixel takes, in units of
/// `spp` (the default of [`crate::render::FrameSettings::edge_coverage_factor`];
/// 0 turns the post-stratification off). With 64, a rim pixel's emitter
/// coverage comes from 65·`spp` stratified rays: the variance of a
/// box-filtered straight edge under jittered sampling falls as N^-3/2, so
/// its noise is about 65^-3/4 ≈ 1/23 of what `spp` samples give. Measured
/// on cube-in-box at 128×128, 16 spp, 8 frames, against a 1024-spp
/// reference (`radcache render` then `radcache compare`), `ic`'s all-pixel
/// relative RMSE with multi-jittered sets (8781aae) was 0.0187 with 16,
/// 0.0171 with 32 and 0.0168 with 64 (with jittered cells, at d5dbb91:
/// 0.0259 with 32, 0.0193 with 64, 0.0185 with 128); at 64×64 the coverage
/// rays cost `trc`'s render pass about a fifth more (before 935e7a0 made
/// them cheaper).
pub const DEFAULT_EDGE_COVERAGE_FACTOR: u32 = 64;

/// How the random streams of pixel samples (their positions, light
/// samples, coverage rays and paths) are keyed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PixelStreams {
    /// By frame too: new every frame (per-frame computation: `ic`,
    /// `path`, `movies`).
    #[default]
    PerFrame,
    /// By pixel and sample number alone, the same in every frame, as the
    /// records of `trc` and `tcg` keep theirs (Tawara et al. 2004 shoot the
    /// same rays every frame). Where nothing changed a sample draws the
    /// same position, light point and path as in the last frame, so the
    /// pixel does not flicker with fresh noise, and the render pass takes a
    /// sample that nothing moving meets from the last frame instead of
    /// tracing it again ([`super::render_pass::StillSamples`]).
    Coherent,
}

impl PixelStreams {
    /// The key of sample `sample` of pixel `pixel`.
    pub fn key(self, ctx: &FrameContext, pixel: u32, sample: u32) -> SampleKey {
        match self {
            PixelStreams::PerFrame => ctx.pixel_key(pixel, sample),
            PixelStreams::Coherent => SampleKey {
                seed: ctx.seed,
                frame: None,
                item: streams::COHERENT_PIXEL | u64::from(pixel),
                sample,
            },
        }
    }
}

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
    hit.is_hit() && emits_towards(ctx, hit.triangle, ray)
}

/// Whether triangle `triangle` is an emitter whose emitting side `ray`
/// meets.
fn emits_towards(ctx: &FrameContext, triangle: u32, ray: &Ray) -> bool {
    let t = triangle as usize;
    let material = &ctx.scene.materials[ctx.snapshot.tri_material[t] as usize];
    material.is_emissive()
        && emitting_cosine(
            &ctx.snapshot.triangles[t],
            material.double_sided,
            -ray.dir().normalize(),
        )
        .is_some()
}

/// Emitters in view up to which [`sees_emitter_first`] tests each one
/// along a ray before it asks the scene's BVH; with more it traces plain
/// closest-hit rays.
const EMITTERS_TESTED_ONE_BY_ONE: usize = 16;

/// For each camera ray (from the camera through the film: only
/// [`FrameContext::emitters_in_view`] are looked at), whether its first hit
/// is an emitter's emitting side ([`sees_emitter`] of its closest hit), for
/// rays that need nothing else from their hit (the coverage and corner
/// rays).
///
/// With few emitters in view it first finds the nearest of them along the
/// ray. A ray that meets none, or the back of the nearest, sees none,
/// whatever else it hits: no BVH query at all. One that meets an emitting
/// side sees it unless something nearer is in the way: an any-hit query
/// stopped just short of the emitter, cheaper than a closest-hit one. On a
/// light's rim about half of the coverage rays miss it, and the coverage
/// rays are the render pass's largest ray count after the primary and
/// shadow rays. The answer is [`sees_emitter`]'s but for near ties: a
/// surface within [`SHADOW_EPSILON`] of the emitter's distance along the
/// ray (coplanar with it) hides it from the closest-hit query or not by
/// traversal order, and never here (`short_of_emitter`).
pub fn sees_emitter_first(ctx: &FrameContext, rays: &[Ray]) -> Vec<bool> {
    let emitters = &ctx.emitters_in_view;
    if emitters.is_empty() {
        return vec![false; rays.len()];
    }
    if emitters.len() > EMITTERS_TESTED_ONE_BY_ONE {
        let mut hits = vec![Hit::MISS; rays.len()];
        ctx.backend.closest_hit(rays, &mut hits);
        return rays
            .iter()
            .zip(&hits)
            .map(|(ray, hit)| sees_emitter(ctx, ray, hit))
            .collect();
    }
    // The rays that meet an emitting side first among the emitters, cut
    // just short of it, and which ray each is.
    let mut unless_occluded = Vec::new();
    let mut of_ray = Vec::new();
    for (i, ray) in rays.iter().enumerate() {
        let nearest = emitters
            .iter()
            .filter_map(|&e| {
                let t = ray_hits_triangle(&ctx.snapshot.triangles[e as usize], ray)?;
                Some((t, e))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((t, _)) = nearest.filter(|&(_, e)| emits_towards(ctx, e, ray)) {
            unless_occluded.push(Ray {
                tmax: short_of_emitter(t),
                ..*ray
            });
            of_ray.push(i);
        }
    }
    let mut occluded = vec![false; unless_occluded.len()];
    ctx.backend.any_hit(&unless_occluded, &mut occluded);
    let mut sees = vec![false; rays.len()];
    for (&i, &occluded) in of_ray.iter().zip(&occluded) {
        sees[i] = !occluded;
    }
    sees
}

/// A tile's pixels on the edge of a seen light and how much of each sees
/// an emitter ([`EmitterEdges::find`]), to resolve the tile's pixels with
/// ([`EmitterEdges::resolve`]).
#[derive(Clone, Debug, Default)]
pub struct EmitterEdges {
    /// Per sample (the base samples, then [`Self::extra_samples`]): its
    /// first hit is an emitter's emitting side.
    sees: Vec<bool>,
    /// The edge pixels, in pixel order.
    pixels: Vec<EdgeCoverage>,
    /// Camera rays each edge pixel took: its base samples and its coverage
    /// rays.
    edge_rays: u32,
    /// Samples to shade besides the base ones: one for each part of an edge
    /// pixel that only its coverage rays saw.
    extra: Vec<PixelSample>,
    /// What the coverage rays of every candidate pixel saw, in pixel order
    /// (for the next frame to keep: [`KeptCoverage`]).
    coverage: Vec<CandidateCoverage>,
}

/// A candidate pixel, how many of its base samples saw an emitter, and
/// what its coverage rays saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CandidateCoverage {
    pixel: u32,
    seen: u32,
    count: CoverageCount,
}

/// The coverage of the last frame's candidate pixels (in pixel order), and
/// which pixels nothing moving may have changed since: a candidate with the
/// same base samples seen whose pixel is `clear` keeps what its coverage
/// rays saw instead of tracing them again (under coherent streams they
/// are the same rays; `render_pass::StillSamples`).
pub struct KeptCoverage<'a> {
    pub last: &'a [CandidateCoverage],
    pub clear: &'a (dyn Fn(u32) -> bool + Sync),
}

impl KeptCoverage<'_> {
    fn count(&self, pixel: u32, seen: u32) -> Option<CoverageCount> {
        let i = self.last.binary_search_by_key(&pixel, |c| c.pixel).ok()?;
        let c = self.last[i];
        (c.seen == seen && (self.clear)(pixel)).then_some(c.count)
    }
}

/// Of an edge pixel's camera rays (its base samples and its coverage rays,
/// [`EmitterEdges::edge_rays`] in all), how many see an emitter's emitting
/// side first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct EdgeCoverage {
    pixel: u32,
    seen: u32,
}

impl EmitterEdges {
    /// The edge pixels among `base` (`spp` samples a pixel, pixel by pixel,
    /// from pixel `base[0].pixel`, with their camera rays and first hits),
    /// with their coverage measured by `ctx.edge_coverage_factor · spp` more
    /// camera rays each (sample keys `spp..`, stratified among
    /// themselves), traced here.
    ///
    /// A pixel is a candidate when its samples disagree on seeing an
    /// emitter, or agree but one of its corners' rays says otherwise: a
    /// light's edge that clips a few percent of a pixel is easily missed by
    /// all of its `spp` samples, and a light is often many times brighter
    /// than the surfaces (30× on cube-in-box), so a few percent of it
    /// missed is a large error. A
    /// candidate whose coverage rays all agree with its samples is no edge.
    pub fn find(
        ctx: &FrameContext,
        streams: PixelStreams,
        (base, rays, hits): (&[PixelSample], &[Ray], &[Hit]),
        spp: u32,
        kept: Option<&KeptCoverage>,
    ) -> Self {
        let extra = ctx.edge_coverage_factor.saturating_mul(spp);
        // No sample can see an emitter that is out of view.
        let sees = if !ctx.emitters_in_view.is_empty() {
            rays.iter()
                .zip(hits)
                .map(|(ray, hit)| sees_emitter(ctx, ray, hit))
                .collect()
        } else {
            vec![false; rays.len()]
        };
        let mut edges = EmitterEdges {
            sees,
            edge_rays: spp.saturating_add(extra),
            ..EmitterEdges::default()
        };
        let (Some(first), Some(last)) = (base.first(), base.last()) else {
            return edges;
        };
        if extra == 0 || ctx.emitters_in_view.is_empty() {
            return edges;
        }
        let corners = CornerRays::trace(ctx, first.pixel, last.pixel);
        let candidates: Vec<(u32, u32)> = base
            .chunks(spp as usize)
            .zip(edges.sees.chunks(spp as usize))
            .filter_map(|(samples, sees)| {
                let pixel = samples[0].pixel;
                let seen = sees.iter().filter(|&&s| s).count() as u32;
                let uniform = seen == 0 || seen == spp;
                let corners_agree = corners.all_agree(ctx.width, pixel, seen > 0);
                (!uniform || !corners_agree).then_some((pixel, seen))
            })
            .collect();
        let mut counts: Vec<Option<CoverageCount>> = candidates
            .iter()
            .map(|&(pixel, seen)| kept.and_then(|k| k.count(pixel, seen)))
            .collect();
        let missing: Vec<(u32, u32)> = candidates
            .iter()
            .zip(&counts)
            .filter(|(_, count)| count.is_none())
            .map(|(&c, _)| c)
            .collect();
        let mut traced = coverage_counts(ctx, streams, &missing, spp, extra).into_iter();
        for count in counts.iter_mut().filter(|c| c.is_none()) {
            *count = traced.next();
        }
        for (&(pixel, seen), count) in candidates.iter().zip(counts) {
            let count = count.expect("every candidate counted");
            edges
                .coverage
                .push(CandidateCoverage { pixel, seen, count });
            edges.add_candidate(pixel, seen, count, spp, extra);
        }
        edges
    }

    /// What the coverage rays of the candidate pixels saw, in pixel order.
    pub fn coverage(&self) -> &[CandidateCoverage] {
        &self.coverage
    }

    /// Adds candidate `pixel`, `seen` of whose `spp` base samples see an
    /// emitter, if what its `extra` coverage rays saw (`count`) shows it is
    /// an edge pixel. A part of the pixel that no base sample fell in gets
    /// one shaded sample: a coverage ray in it, drawn uniformly among them
    /// (its shading is then a uniform sample of the part, as the mean of a
    /// part's base samples is).
    fn add_candidate(&mut self, pixel: u32, seen: u32, count: CoverageCount, spp: u32, extra: u32) {
        let edge = EdgeCoverage {
            pixel,
            seen: seen + count.seen,
        };
        if edge.seen == 0 || edge.seen == self.edge_rays {
            return;
        }
        let parts = [
            (true, seen > 0, count.pick_seeing),
            (false, seen < spp, count.pick_other),
        ];
        for (part, shaded, first) in parts {
            if let (false, Some(j)) = (shaded, first) {
                self.extra.push(coverage_sample(pixel, spp, extra, j));
                self.sees.push(part);
            }
        }
        self.pixels.push(edge);
    }

    /// The samples to shade besides the base ones, in this order after
    /// them: the samples given to [`Self::resolve`] are the base samples
    /// followed by these.
    pub fn extra_samples(&self) -> &[PixelSample] {
        &self.extra
    }

    /// Each pixel's value from its samples' radiance (`samples`: the base
    /// samples given to [`Self::find`], then [`Self::extra_samples`]):
    /// `out[p − first]` for the pixels `p` of `samples`, summed in sample
    /// order (bit-exact repeatability). An edge pixel is `c·A + (1 − c)·B`,
    /// `c` the share of its camera rays that see an emitter, `A` and `B` the
    /// means of its samples that do and do not; every other pixel is the
    /// mean of its samples.
    pub fn resolve(
        &self,
        samples: &[PixelSample],
        radiance: &[Vec3],
        first: u32,
        out: &mut [Vec3],
    ) {
        // Per pixel, the sums and counts of the samples that see an
        // emitter and of those that do not. One of each pair is zero
        // outside the edge pixels, so their mean is the plain one.
        let mut seeing = vec![(Vec3::ZERO, 0u32); out.len()];
        let mut other = vec![(Vec3::ZERO, 0u32); out.len()];
        for ((s, l), &sees) in samples.iter().zip(radiance).zip(&self.sees) {
            let part = if sees { &mut seeing } else { &mut other };
            let (sum, n) = &mut part[(s.pixel - first) as usize];
            *sum += *l;
            *n += 1;
        }
        for (i, pixel) in out.iter_mut().enumerate() {
            let ((a, na), (b, nb)) = (seeing[i], other[i]);
            *pixel = (a + b) / (na + nb).max(1) as f32;
        }
        for edge in &self.pixels {
            let i = (edge.pixel - first) as usize;
            let ((a, na), (b, nb)) = (seeing[i], other[i]);
            // `find` gave a shaded sample to every part some ray saw; a part
            // no ray saw has weight 0 (`c` is 0 or 1).
            let c = edge.seen as f32 / self.edge_rays as f32;
            out[i] = c * a / na.max(1) as f32 + (1.0 - c) * b / nb.max(1) as f32;
        }
    }
}

/// Where the any-hit query of a ray that meets an emitter at `t` stops:
/// short of it by [`SHADOW_EPSILON`] of `t`, as a shadow segment stops
/// short of the light it aims at. The emitter's `t` is the CPU's
/// (`ray_hits_triangle`), the query the backend's: a GPU that fuses
/// multiply-adds may find the same emitter a few ulps nearer, and a query
/// stopped one ulp short (as it once was) then counted the emitter as its
/// own occluder (on an H200, cube-in-box's light rim lost coverage and
/// flickered; lavapipe's t equals the CPU's).
/// A surface within 1e-4 of `t` in front of the emitter no longer hides
/// it; such a surface would z-fight with it anyway. 0 stays 0 (a camera
/// on an emitter).
fn short_of_emitter(t: f32) -> f32 {
    t * (1.0 - SHADOW_EPSILON)
}

/// The emitting triangles of `snapshot` that may show on a film of aspect
/// ratio `aspect` ([`FrameContext::emitters_in_view`], computed once a
/// frame): without one no pixel is an edge pixel, and the corner rays are
/// not traced.
pub fn emitters_in_view(snapshot: &Snapshot, lights: &LightSampler, aspect: f32) -> Vec<u32> {
    let camera = &snapshot.camera;
    lights
        .emitting_triangles()
        .filter(|&t| camera.may_see(&snapshot.triangles[t], aspect))
        .map(|t| t as u32)
        .collect()
}

/// Coverage sample `j` of the `extra` an edge pixel takes after its `spp`.
fn coverage_sample(pixel: u32, spp: u32, extra: u32, j: u32) -> PixelSample {
    PixelSample {
        pixel,
        key: spp + j,
        stratum: j,
        strata: extra,
    }
}

/// What a candidate pixel's coverage rays saw: how many see an emitter
/// first, and in each part (seeing one, not seeing one) one of its rays
/// (its index among them) drawn uniformly, by reservoir sampling.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct CoverageCount {
    seen: u32,
    other: u32,
    pick_seeing: Option<u32>,
    pick_other: Option<u32>,
}

impl CoverageCount {
    /// Counts ray `j`, which `sees` an emitter or not; `u` ∈ [0, 1) is its
    /// own random number. The `k`-th ray of a part replaces the part's pick
    /// with probability 1/k, so each of the part's rays ends up picked
    /// with the same probability.
    fn add(&mut self, j: u32, sees: bool, u: f32) {
        let (n, pick) = if sees {
            (&mut self.seen, &mut self.pick_seeing)
        } else {
            (&mut self.other, &mut self.pick_other)
        };
        *n += 1;
        if u * (*n as f32) < 1.0 {
            *pick = Some(j);
        }
    }
}

/// Coverage rays traced at a time: memory stays bounded whatever `spp` is
/// (one edge pixel at the largest `--spp` takes 64 million).
const COVERAGE_BATCH: usize = 1 << 16;

/// What the `extra` coverage rays of each candidate pixel saw, candidate by
/// candidate, traced in batches of at most [`COVERAGE_BATCH`].
fn coverage_counts(
    ctx: &FrameContext,
    streams: PixelStreams,
    candidates: &[(u32, u32)],
    spp: u32,
    extra: u32,
) -> Vec<CoverageCount> {
    let mut counts = vec![CoverageCount::default(); candidates.len()];
    let mut camera = CameraSampler::new(streams);
    let mut rays = Vec::new();
    let mut owners = Vec::new();
    let mut flush = |rays: &mut Vec<Ray>, owners: &mut Vec<(usize, u32, f32)>| {
        let sees = sees_emitter_first(ctx, rays);
        for (&sees, &(c, j, u)) in sees.iter().zip(owners.iter()) {
            counts[c].add(j, sees, u);
        }
        rays.clear();
        owners.clear();
    };
    for (c, &(pixel, _)) in candidates.iter().enumerate() {
        for j in 0..extra {
            let (ray, mut rng) = camera.query(ctx, &coverage_sample(pixel, spp, extra, j));
            rays.push(ray);
            owners.push((c, j, rng.next_f32()));
            if rays.len() == COVERAGE_BATCH {
                flush(&mut rays, &mut owners);
            }
        }
    }
    flush(&mut rays, &mut owners);
    counts
}

/// Whether the camera ray through each pixel corner of some rows sees an
/// emitter first: `(width + 1)` corners a row, rows `y0..=y1 + 1`.
struct CornerRays {
    y0: u32,
    sees: Vec<bool>,
}

impl CornerRays {
    /// The corners of the rows of pixels `first..=last`.
    fn trace(ctx: &FrameContext, first: u32, last: u32) -> Self {
        let (y0, y1) = (first / ctx.width, last / ctx.width);
        let camera = &ctx.snapshot.camera;
        let rays: Vec<Ray> = (y0..=y1 + 1)
            .flat_map(|y| (0..=ctx.width).map(move |x| (x, y)))
            .map(|(x, y)| {
                let sx = x as f32 / ctx.width as f32;
                let sy = y as f32 / ctx.height as f32;
                let dir = camera.direction(sx, sy, ctx.aspect());
                Ray::new(camera.position, dir, 0.0, f32::INFINITY)
            })
            .collect();
        let sees = sees_emitter_first(ctx, &rays);
        CornerRays { y0, sees }
    }

    /// Whether all four corners of `pixel` agree with `sees`.
    fn all_agree(&self, width: u32, pixel: u32, sees: bool) -> bool {
        let (x, y) = (pixel % width, pixel / width - self.y0);
        let row = width + 1;
        [(x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)]
            .iter()
            .all(|&(cx, cy)| self.sees[(cy * row + cx) as usize] == sees)
    }
}

/// The layout of the last set of samples (a pixel's base samples, or its
/// coverage rays) a sampler placed, rebuilt when the set changes: a run of
/// one set's samples builds it once.
#[derive(Default)]
struct LayoutCache {
    /// `(pixel, strata)` of the set, and its layout.
    last: Option<((u32, u32), Stratified2d)>,
}

impl LayoutCache {
    fn of(&mut self, s: &PixelSample, make: impl FnOnce() -> Stratified2d) -> &Stratified2d {
        let key = (s.pixel, s.strata);
        if self.last.as_ref().is_some_and(|(k, _)| *k != key) {
            self.last = None;
        }
        &self.last.get_or_insert_with(|| (key, make())).1
    }
}

/// Sample numbers reserved for the per-pixel keys of the stratified pixel
/// positions and light choices (no pixel has this many samples).
const PIXEL_PATTERN: u32 = u32::MAX;
const LIGHT_PATTERN: u32 = u32::MAX - 1;

/// Places the camera rays of pixel samples.
#[derive(Default)]
pub struct CameraSampler {
    streams: PixelStreams,
    layouts: LayoutCache,
}

impl CameraSampler {
    pub fn new(streams: PixelStreams) -> Self {
        CameraSampler {
            streams,
            layouts: LayoutCache::default(),
        }
    }

    /// The primary ray of sample `s` and the sample's random stream
    /// positioned after the jitter. The pixel is box-filtered: positions
    /// are uniform over its square, multi-jittered over the samples of
    /// their set ([`Stratified2d`]) — unbiased, and the noise of edges
    /// inside the pixel falls faster than with independent jitter.
    pub fn query(&mut self, ctx: &FrameContext, s: &PixelSample) -> (Ray, Rng) {
        let layout = self.layouts.of(s, || {
            let shuffle = Rng::new(self.streams.key(ctx, s.pixel, PIXEL_PATTERN)).next_u32();
            Stratified2d::new(s.strata, None, shuffle)
        });
        let mut rng = Rng::new(self.streams.key(ctx, s.pixel, s.key));
        let jitter = layout.sample(s.stratum, rng.next_2d());
        let (x, y) = (s.pixel % ctx.width, s.pixel / ctx.width);
        let sx = (x as f32 + jitter.x) / ctx.width as f32;
        let sy = (y as f32 + jitter.y) / ctx.height as f32;
        let camera = &ctx.snapshot.camera;
        let dir = camera.direction(sx, sy, ctx.aspect());
        (Ray::new(camera.position, dir, 0.0, f32::INFINITY), rng)
    }
}

/// Draws the first light samples of pixel samples, building the layout of
/// each set once for the run of its samples rather than once per sample
/// (the render pass of `trc` at 64×64 took 9 % less time once the keyed
/// generators of the layout were no longer drawn per sample).
#[derive(Default)]
pub struct FirstLightSampler {
    streams: PixelStreams,
    layouts: LayoutCache,
}

impl FirstLightSampler {
    pub fn new(streams: PixelStreams) -> Self {
        FirstLightSampler {
            streams,
            layouts: LayoutCache::default(),
        }
    }

    /// The light sample used at the first surface sample `s` hits: one 2D
    /// sample stratified over the samples of the sample's set like the
    /// pixel position, with strata paired by a per-pixel random permutation
    /// ([`Stratified2d`]), that picks the light and the point on it
    /// ([`crate::light::LightSampler::choose`]). Soft shadows, area-light
    /// shading and the choice among several lights are the largest noise
    /// left once edges are stratified.
    pub fn sample(&mut self, ctx: &FrameContext, s: &PixelSample, rng: &mut Rng) -> LightChoice {
        let layout = self.layouts.of(s, || {
            let mut keys = Rng::new(self.streams.key(ctx, s.pixel, LIGHT_PATTERN));
            let scramble = keys.next_u32();
            Stratified2d::new(s.strata, Some(scramble), keys.next_u32())
        });
        ctx.lights.choose(layout.sample(s.stratum, rng.next_2d()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(pixel: u32, key: u32) -> PixelSample {
        PixelSample::base(pixel, key, 2)
    }

    #[test]
    fn a_pixel_off_the_edges_is_the_mean_of_its_samples() {
        let samples = [sample(5, 0), sample(5, 1), sample(6, 0), sample(6, 1)];
        let edges = EmitterEdges {
            sees: vec![false, false, true, true],
            ..EmitterEdges::default()
        };
        let radiance = [1.0, 2.0, 3.0, 5.0].map(Vec3::splat);
        let mut out = [Vec3::ONE * 9.0; 2];
        edges.resolve(&samples, &radiance, 5, &mut out);
        assert_eq!(out, [Vec3::splat(1.5), Vec3::splat(4.0)]);
    }

    /// Reservoir sampling: over many draws each ray of a part is picked
    /// about equally often, and the counts are exact.
    #[test]
    fn a_coverage_count_picks_each_ray_of_a_part_uniformly() {
        let sees = [false, true, true, false, true, true];
        let mut picked = [0u32; 6];
        let mut rng = Rng::from_seed(7, 11);
        let draws = 30_000;
        for _ in 0..draws {
            let mut count = CoverageCount::default();
            for (j, &s) in sees.iter().enumerate() {
                count.add(j as u32, s, rng.next_f32());
            }
            assert_eq!((count.seen, count.other), (4, 2));
            picked[count.pick_seeing.unwrap() as usize] += 1;
            picked[count.pick_other.unwrap() as usize] += 1;
        }
        for (j, &n) in picked.iter().enumerate() {
            let expected = if sees[j] { draws / 4 } else { draws / 2 };
            // Binomial standard deviation is under 90 draws; 5σ.
            assert!(n.abs_diff(expected) < 450, "ray {j}: {n} of {draws}");
        }
    }

    /// An edge pixel whose coverage rays say a quarter of it sees the
    /// light: a quarter of the light samples' mean plus three quarters of
    /// the others' mean, whatever share of its shaded samples saw it.
    #[test]
    fn an_edge_pixel_weights_its_two_parts_by_their_measured_coverage() {
        let samples = [sample(7, 0), sample(7, 1), sample(7, 2), sample(8, 0)];
        let edges = EmitterEdges {
            sees: vec![true, true, false, false],
            pixels: vec![EdgeCoverage { pixel: 7, seen: 25 }],
            edge_rays: 100,
            ..EmitterEdges::default()
        };
        let radiance = [10.0, 14.0, 2.0, 3.0].map(Vec3::splat);
        let mut out = [Vec3::ZERO; 2];
        edges.resolve(&samples, &radiance, 7, &mut out);
        assert_eq!(
            out,
            [Vec3::splat(0.25 * 12.0 + 0.75 * 2.0), Vec3::splat(3.0)]
        );
    }
}
