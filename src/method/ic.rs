//! `ic`: per-frame irradiance caching (Ward, Rubinstein & Clear 1988; Ward
//! & Heckbert 1992), as summarised in §3 of the TRC paper
//! (`temporal-radiance-caching-tvcg2007`), in the two-stage form of
//! Algorithm 1 of the EAS paper: a cache-filling stage creates records
//! where none is usable, then a rendering stage interpolates them. A new
//! cache is built every frame — the "per-frame computation" every temporal
//! method is compared with.
//!
//! The rendering stage, which `trc` and `tcg` share, is
//! [`super::render_pass`]; in
//! it the cache's records are used where `w ≥ 1/a`, with `R_K` no larger
//! than an estimate from the lookup point's clearance (a departure from
//! Ward explained at `IrradianceRecord::weight`).

use super::lookups::{measure_clearance, ShadingPoint};
use super::render_pass::{render_pass, PixelStreams, Surface};
use super::{FrameContext, FrameRecords, FrameStats, Method, RENDER_PHASE};
use crate::backend::{Hit, Ray};
use crate::cache::gather::{
    gather_queries, irradiance_and_gradients, samples_from_results, GatherPoint,
    GatheredIrradiance, HemisphereSamples, Strata,
};
use crate::cache::{eas, IrradianceCache, IrradianceRecord, LookupPoint, RecordId};
use crate::film::Film;
use crate::integrator::{
    trace_radiance_parallel, trace_radiance_replayed, KnownPath, PathLength, PathTracks,
    RadianceQuery, RadianceResult, Replay,
};
use crate::material::{luminance, Bsdf, LUMINANCE};
use crate::sampling::{streams, SampleKey};
use crate::store::SampleBlock;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// Settings of `ic`, with their sources.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IcSettings {
    /// Accuracy `a` (Ward 1988): records are used where `w ≥ 1/a`. Ward
    /// recommends 0.1–0.3; 0.2 is our default.
    pub accuracy: f32,
    /// Hemisphere cells per record (`M × N`).
    pub strata: Strata,
    /// Pixel samples (direct light, glossy lobe and anti-aliasing).
    pub spp: u32,
    /// Smallest distance between records, in pixels: `a·R ≥ min·footprint`
    /// (Tabellion & Lamorlette 2004 clamp R in screen space so corners do
    /// not fill with records).
    pub min_spacing_px: f32,
    /// Largest influence radius, in pixels (keeps records in open space from
    /// covering half the image).
    pub max_spacing_px: f32,
    /// Interpolate with translation and rotation gradients (Eq. 4).
    pub gradients: bool,
    /// Path length of pixel paths (glossy lobe, fallbacks).
    pub length: PathLength,
    /// Path length of the record-gathering paths. Roulette starts at the
    /// first hit, on the path's whole throughput (survival `min(max β,
    /// 0.95)`): a dark surface ends most paths at once, a bright room keeps
    /// them. Half the throughput (the default before `ic` revision 8) left
    /// records noisier than the time it saved was worth: on cube-in-box
    /// 1.36× the block bias and flicker in 0.74× the CPU time, where more
    /// strata would take 1.8× the time to quiet them as much,
    /// and in a room of albedo 0.9 1.6× the block bias
    /// (`benches/RESULTS.md`, "Roulette on the gather paths").
    pub gather_length: PathLength,
    /// How glossy lobes get their indirect light.
    #[serde(default)]
    pub glossy: GlossyLobe,
    /// The EAS precision criterion `τ` (EAS paper Eq. 13), with
    /// [`GlossyLobe::Eas`].
    #[serde(default = "default_eas_tau")]
    pub eas_tau: f32,
}

fn default_eas_tau() -> f32 {
    eas::DEFAULT_TAU
}

impl IcSettings {
    /// The least radius `R` a record may have where a pixel's footprint is
    /// `footprint`: records at least `min_spacing_px` pixels apart.
    pub(crate) fn min_radius(&self, footprint: f32) -> f32 {
        self.min_spacing_px * footprint / self.accuracy
    }

    /// The largest radius `R` a record may have there: records at most
    /// `max_spacing_px` pixels apart.
    pub(crate) fn max_radius(&self, footprint: f32) -> f32 {
        self.max_spacing_px * footprint / self.accuracy
    }
}

/// Where the indirect light of glossy lobes comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum GlossyLobe {
    /// Path-traced from one lobe sample per pixel sample (MIS-weighted
    /// against the light sample for the direct part).
    #[default]
    Path,
    /// Radiance records: glossy surfaces get records too, and each keeps
    /// equivalent area light sources ([`crate::cache::eas`]) that the
    /// pixels around it reflect; the direct part is the light sample alone.
    Eas,
}

impl Default for IcSettings {
    fn default() -> Self {
        IcSettings {
            accuracy: 0.2,
            strata: Strata::default(),
            spp: 16,
            min_spacing_px: 2.0,
            max_spacing_px: 64.0,
            gradients: true,
            length: PathLength::default(),
            gather_length: PathLength {
                rr_start: 0,
                survival: 1.0,
                ..PathLength::default()
            },
            glossy: GlossyLobe::Path,
            eas_tau: eas::DEFAULT_TAU,
        }
    }
}

/// The random streams of a record first gathered at `pixel`'s candidate in
/// this frame: frame and pixel (the pixel alone with `--same-pattern`).
/// They are the record's own from then on: a record gathered again at the
/// same point (`trc`'s replacement, TRC §4.4) shoots the same hemisphere
/// directions with the same path streams, as temporally coherent final
/// gathering does (Tawara et al. 2004, §3: the same sample rays every
/// frame), so that where nothing changed the new value equals the old one
/// and a replacement shows only the change, not fresh Monte Carlo noise.
fn first_stream(ctx: &FrameContext, pixel: u32) -> u64 {
    // Frames below 2^29 keep clear of the stream tags (bits 61–62).
    let frame = if ctx.same_pattern { 0 } else { ctx.frame + 1 };
    (u64::from(frame) << 32) | u64::from(pixel)
}

pub struct IrradianceCaching {
    pub settings: IcSettings,
    stats: FrameStats,
    /// Store hook ([`Method::keep_frame_records`]): samples of the records
    /// gathered this frame, and the last frame's records with them.
    keep_records: bool,
    gathered_samples: std::sync::Mutex<Vec<(RecordId, SampleBlock)>>,
    kept: Option<FrameRecords>,
}

impl IrradianceCaching {
    pub fn new(settings: IcSettings) -> Self {
        IrradianceCaching {
            settings,
            stats: FrameStats::default(),
            keep_records: false,
            gathered_samples: Default::default(),
            kept: None,
        }
    }
}

/// The first surface seen through a pixel centre, where a record may go
/// (`trc` also makes them for records it replaces at the same point).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Candidate {
    pub(crate) pixel: u32,
    /// The random streams of the record's gather ([`first_stream`]): set
    /// where a record is first gathered and kept by the records `trc`
    /// gathers again at the same point.
    pub(crate) stream: u64,
    pub(crate) point: GatherPoint,
    pub(crate) object: u32,
    /// World size of one pixel at this depth.
    pub(crate) footprint: f32,
    /// The material of a glossy surface whose record keeps equivalent area
    /// light sources ([`GlossyLobe::Eas`]); `None` for an irradiance record.
    pub(crate) glossy: Option<u32>,
}

#[cfg(test)]
impl Candidate {
    /// A candidate at `point` of object 0, pixel 0, for unit tests.
    pub(crate) fn at(point: GatherPoint) -> Self {
        Candidate {
            pixel: 0,
            stream: 0,
            point,
            object: 0,
            footprint: 0.01,
            glossy: None,
        }
    }
}

/// A record just gathered, with the hemisphere samples and first hits it
/// was computed from (`trc` reprojects them, TRC §4.7).
pub(crate) struct Gathered {
    pub(crate) candidate: Candidate,
    pub(crate) record: IrradianceRecord,
    pub(crate) samples: HemisphereSamples,
    /// Each gather query's result (its radiance and first hit).
    pub(crate) results: Vec<RadianceResult>,
}

impl Method for IrradianceCaching {
    fn name(&self) -> &'static str {
        "ic"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        let mut stats = FrameStats {
            frame: ctx.frame,
            ..FrameStats::default()
        };
        let start = Instant::now();
        let cache = self.build_cache(ctx);
        self.keep_records_of(&cache);
        stats
            .phase_seconds
            .push(("fill".into(), start.elapsed().as_secs_f64()));
        let start = Instant::now();
        let film = render_pass(
            ctx,
            &cache,
            &self.settings,
            PixelStreams::PerFrame,
            None,
            None,
            &mut stats,
        );
        stats
            .phase_seconds
            .push((RENDER_PHASE.into(), start.elapsed().as_secs_f64()));
        stats.records_created = cache.len() as u64;
        stats.records_alive = cache.len() as u64;
        stats.cache_bytes = cache.memory_bytes() as u64;
        // A per-frame cache's records are used in this frame only (the
        // histogram stays empty: it is for the temporal methods' lives).
        stats.mean_lifespan = if cache.is_empty() { 0.0 } else { 1.0 };
        self.stats = stats;
        film
    }

    fn last_frame_stats(&self) -> FrameStats {
        self.stats.clone()
    }

    fn keep_frame_records(&mut self, keep: bool) {
        self.keep_records = keep;
    }

    fn take_frame_records(&mut self) -> Option<FrameRecords> {
        self.kept.take()
    }
}

impl IrradianceCaching {
    /// Store hook: remembers the records of this frame's cache with the
    /// samples gathered for them (samples of records that were gathered but
    /// not inserted are dropped).
    fn keep_records_of(&mut self, cache: &IrradianceCache) {
        let gathered = std::mem::take(
            self.gathered_samples
                .get_mut()
                .unwrap_or_else(|e| e.into_inner()),
        );
        if !self.keep_records {
            return;
        }
        let mut by_id: std::collections::HashMap<RecordId, SampleBlock> =
            gathered.into_iter().collect();
        let records = cache.records().to_vec();
        let samples = records
            .iter()
            .map(|r| by_id.remove(&r.id).unwrap_or_default())
            .collect();
        self.kept = Some(FrameRecords {
            records,
            samples,
            strata: self.settings.strata,
            ..FrameRecords::default()
        });
    }
}

pub(crate) fn scene_bounds(ctx: &FrameContext) -> (Vec3, Vec3) {
    (ctx.snapshot.bounds()).unwrap_or((Vec3::splat(-1.0), Vec3::ONE))
}

impl IrradianceCaching {
    /// A new cache for this frame, filled by [`Self::fill`].
    pub fn build_cache(&self, ctx: &FrameContext) -> IrradianceCache {
        let (min, max) = scene_bounds(ctx);
        let mut cache = IrradianceCache::new(min, max, self.settings.accuracy);
        self.fill(ctx, &mut cache);
        cache
    }

    /// Cache-filling stage (EAS Algorithm 1, lines 1–17): pixel centres are
    /// visited coarse to fine (every 2ᴸ-th pixel, then the pixels between),
    /// so that the first records are spread over the image rather than
    /// clustered along the first scanlines; a record is created wherever no
    /// existing record is usable.
    pub fn fill(&self, ctx: &FrameContext, cache: &mut IrradianceCache) {
        let candidates = primary_candidates(ctx, &self.settings);
        self.fill_from(ctx, cache, &candidates, None, |_, _| (), &mut Vec::new());
    }

    /// Renders this frame with a given cache (what [`Method::render_frame`]
    /// does after [`Self::build_cache`], there with
    /// [`PixelStreams::PerFrame`]); tests compare `trc` with it.
    pub fn render_with_cache(
        &self,
        ctx: &FrameContext,
        cache: &IrradianceCache,
        streams: PixelStreams,
    ) -> Film {
        let mut stats = FrameStats::default();
        render_pass(ctx, cache, &self.settings, streams, None, None, &mut stats)
    }

    /// The fill stage over given candidates (one per pixel). Every record
    /// it inserts is first passed to `annotate` (in parallel, right after
    /// its gather) and the result pushed to `inserted`, in insertion order:
    /// `trc` estimates each new record's E(t0+1) there. The gathers of the
    /// candidates `track` picks also say where each path went
    /// (`annotate`'s second argument, `None` for the others).
    pub(crate) fn fill_from<X: Send>(
        &self,
        ctx: &FrameContext,
        cache: &mut IrradianceCache,
        candidates: &[Option<Candidate>],
        track: Option<&TrackPaths<'_>>,
        annotate: impl Fn(&Gathered, Option<GatherTracks>) -> X + Sync,
        inserted: &mut Vec<X>,
    ) {
        let (w, h) = (ctx.width as usize, ctx.height as usize);
        let mut step = 1usize;
        while step * 8 < w.max(h) {
            step *= 2;
        }
        let clearances = candidate_clearances(ctx, candidates);
        let mut visited = vec![false; w * h];
        while step >= 1 {
            // Four interleaved sub-batches per level: candidates of one batch
            // are 2·step pixels apart, so few of them cover each other.
            for (ox, oy) in [(0, 0), (1, 1), (1, 0), (0, 1)] {
                // Pixel indices only: the candidates are read in parallel
                // by `create_records`, not copied here on one thread.
                let mut pixels = Vec::new();
                for y in (oy * step..h).step_by(2 * step) {
                    for x in (ox * step..w).step_by(2 * step) {
                        let i = y * w + x;
                        if !visited[i] {
                            visited[i] = true;
                            pixels.push(i);
                        }
                    }
                }
                let batch = pixels
                    .par_iter()
                    .filter_map(|&i| Some((candidates[i]?, clearances[i]?)));
                self.create_records(ctx, cache, batch, track, &annotate, inserted);
            }
            step /= 2;
        }
    }

    /// Gathers records (in parallel) for the candidates no record covers
    /// (each with its lookup point), then inserts them in pixel order.
    fn create_records<X: Send>(
        &self,
        ctx: &FrameContext,
        cache: &mut IrradianceCache,
        batch: impl ParallelIterator<Item = (Candidate, LookupPoint)>,
        track: Option<&TrackPaths<'_>>,
        annotate: &(impl Fn(&Gathered, Option<GatherTracks>) -> X + Sync),
        inserted: &mut Vec<X>,
    ) {
        // In the batch's order (rayon's `collect` keeps it).
        let needed: Vec<Candidate> = batch
            .filter(|(_, at)| !cache.covers(at))
            .map(|(c, _)| c)
            .collect();
        let annotated = |(g, tracks): (Gathered, Option<GatherTracks>)| {
            let x = annotate(&g, tracks);
            (g.record, x)
        };
        let records: Vec<(IrradianceRecord, X)> = match track {
            Some(track) => {
                let unknown = vec![None; needed.len()];
                let make = |_, g, tracks| annotated((g, tracks));
                self.gather_parallel_tracked(ctx, &needed, &unknown, track, &make)
                    .collect()
            }
            None => self
                .gather_parallel(ctx, &needed)
                .map(|g| annotated((g, None)))
                .collect(),
        };
        // A record of the batch may already be covered by an earlier one of
        // the same batch (they were gathered in parallel); it is kept all the
        // same: the work is done, and it only adds accuracy.
        for (record, x) in records {
            cache.insert(record);
            inserted.push(x);
        }
    }

    /// Gathers records at `candidates` in parallel, in candidate order, each
    /// with its own random streams (`Candidate::stream`).
    pub(crate) fn gather_parallel<'a>(
        &'a self,
        ctx: &'a FrameContext,
        candidates: &'a [Candidate],
    ) -> impl ParallelIterator<Item = Gathered> + 'a {
        // `trc` and the fine fill levels gather a handful of records at a
        // time: one task for all of them would leave the other threads idle.
        let rays = self.settings.strata.count();
        let per_task = ctx.backend.items_per_task(candidates.len(), rays);
        candidates.par_chunks(per_task).flat_map_iter(move |chunk| {
            let length = self.settings.gather_length;
            self.gather_chunk(ctx, chunk, |queries| {
                (trace_radiance_parallel(ctx, length, queries.to_vec()), ())
            })
            .0
        })
    }

    /// [`Self::gather_parallel`], taking the results of the paths that
    /// `known` gives (per candidate, per gather query: `None` traces it),
    /// each record handed to `make` with its candidate's index and, where
    /// `track` picks it, where its traced paths went ([`GatherTracks`]; a
    /// task's paths are tracked together where one of its records is
    /// picked, and handed only to those picked, so that which records get
    /// tracks does not depend on how the candidates split into tasks).
    /// A path's result depends only on its query and the scene it meets, so
    /// a path taken where it would have met the same leaves the record as
    /// tracing it would.
    ///
    /// Why `make` is called here: a task's tracks are let go as soon as its
    /// records are made, rather than held for every record of the frame
    /// until the last is gathered (on `wall_light` the tracks of a frame's
    /// replacements were 66 MB of `trc`'s 145 MB peak heap, `heaptrack`).
    /// A task's records are made in parallel, as a GPU's tasks are large.
    pub(crate) fn gather_parallel_tracked<'a, X: Send + 'a>(
        &'a self,
        ctx: &'a FrameContext,
        candidates: &'a [Candidate],
        known: &'a [Option<Vec<Option<KnownPath<'a>>>>],
        track: &'a TrackPaths<'a>,
        make: &'a (impl Fn(usize, Gathered, Option<GatherTracks>) -> X + Sync),
    ) -> impl ParallelIterator<Item = X> + 'a {
        assert_eq!(candidates.len(), known.len(), "one entry per candidate");
        let rays = self.settings.strata.count();
        let per_task = ctx.backend.items_per_task(candidates.len(), rays);
        candidates
            .par_chunks(per_task)
            .zip(known.par_chunks(per_task))
            .enumerate()
            .flat_map_iter(move |(task, (chunk, known))| {
                let length = self.settings.gather_length;
                let tracked = chunk.iter().any(track);
                let (gathered, (traced, tracks)) = self.gather_chunk(ctx, chunk, |queries| {
                    trace_unknown(ctx, length, queries, known, tracked)
                });
                let tracks = Arc::new(tracks);
                let mut first = 0;
                let per_record: Vec<Option<GatherTracks>> = (traced.chunks(rays).zip(chunk))
                    .map(|(traced, c)| {
                        let own = GatherTracks {
                            traced: traced.to_vec(),
                            tracks: tracks.clone(),
                            first,
                        };
                        first += traced.iter().filter(|&&t| t).count();
                        track(c).then_some(own)
                    })
                    .collect();
                let made: Vec<X> = (gathered.into_par_iter().zip(per_record))
                    .enumerate()
                    .map(|(k, (g, tracks))| make(task * per_task + k, g, tracks))
                    .collect();
                made
            })
    }

    /// Computes the records of `chunk` with one batch of radiance queries,
    /// whose results `trace` gives (with what else it returns).
    fn gather_chunk<T>(
        &self,
        ctx: &FrameContext,
        chunk: &[Candidate],
        trace: impl FnOnce(&[RadianceQuery]) -> (Vec<RadianceResult>, T),
    ) -> (Vec<Gathered>, T) {
        let strata = self.settings.strata;
        let mut queries = Vec::with_capacity(chunk.len() * strata.count());
        for c in chunk {
            let key = SampleKey {
                seed: ctx.seed,
                // The frame is in the stream (`first_stream`).
                frame: None,
                item: streams::RECORD | c.stream,
                sample: 0,
            };
            queries.extend(gather_queries(&c.point, ctx.ray_offset, strata, key));
        }
        let (results, traced) = trace(&queries);
        let dynamic = self.keep_records.then(|| ctx.scene.dynamic_objects());
        let gathered = chunk
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let range = i * strata.count()..(i + 1) * strata.count();
                let samples =
                    samples_from_results(&queries[range.clone()], &results[range.clone()]);
                let g = irradiance_and_gradients(&samples, c.point.normal, strata);
                if let Some(dynamic) = &dynamic {
                    // Packed here, in the gather's thread: the store never
                    // sees the 32-byte samples.
                    let block = SampleBlock::pack(&samples, dynamic);
                    let mut kept = self
                        .gathered_samples
                        .lock()
                        .unwrap_or_else(|e| e.into_inner());
                    kept.push((RecordId::from(c.pixel), block));
                }
                let (radius, grad_translation) = self.limit_radius(&g, c.footprint);
                // A replacement's material comes from the carried state: one
                // the scene lacks (a damaged state) leaves it no sources.
                let material = c.glossy.and_then(|m| ctx.scene.materials.get(m as usize));
                let eas = material.map(|material| {
                    let normal = c.point.normal;
                    let bsdf = Bsdf::new(material, normal, normal);
                    eas::build(&samples, normal, strata, &bsdf, self.settings.eas_tau).into()
                });
                let record = IrradianceRecord {
                    id: RecordId::from(c.pixel),
                    position: c.point.position,
                    normal: c.point.normal,
                    irradiance: g.irradiance,
                    grad_translation,
                    grad_rotation: g.grad_rotation,
                    radius,
                    created_frame: ctx.frame,
                    object: c.object,
                    eas,
                };
                Gathered {
                    candidate: *c,
                    record,
                    samples,
                    results: results[range].to_vec(),
                }
            })
            .collect();
        (gathered, traced)
    }

    /// `R` from the harmonic mean distance, limited by the translation
    /// gradient (`R ≤ E/‖∇p E‖`: the gradient alone would change E by 100 %
    /// over R) and clamped to the pixel-spacing limits (influence `a·R`);
    /// and the translation gradient to interpolate with.
    ///
    /// Where the lower spacing limit raises `R` above the gradient limit,
    /// the gradient is scaled down to `‖∇p E‖ = E/R`, so that extrapolating
    /// over the record's influence (`a·R`) changes E by at most `a`. The
    /// case is a record at a concave edge: a gather ray that hits the other
    /// face at t ≈ 0 enters Ward & Heckbert's `1/min(r)` terms and makes
    /// the gradient arbitrarily large (1e6 against ~20 for its neighbours
    /// was seen), which the radius limit alone cannot bound once `R` is
    /// clamped up. (Křivánek et al. 2006 limit `R` by the gradient; this is
    /// the same bound applied the other way round.)
    pub(crate) fn limit_radius(&self, g: &GatheredIrradiance, footprint: f32) -> (f32, [Vec3; 3]) {
        let slope = luminance_gradient(&g.grad_translation).length();
        let mut r = g.harmonic_distance;
        if slope > 0.0 {
            r = r.min(luminance(g.irradiance) / slope);
        }
        let r_min = self.settings.min_radius(footprint);
        let r_max = self.settings.max_radius(footprint);
        let r = r.clamp(r_min, r_max.max(r_min));
        (r, limit_gradient(g.grad_translation, g.irradiance, r))
    }
}

/// The surface point seen through each pixel centre that wants a record
/// (a surface with a diffuse part, or with [`GlossyLobe::Eas`] a glossy
/// one), or `None`.
pub(crate) fn primary_candidates(
    ctx: &FrameContext,
    settings: &IcSettings,
) -> Vec<Option<Candidate>> {
    let glossy = settings.glossy;
    let camera = &ctx.snapshot.camera;
    let n_pixels = (ctx.width * ctx.height) as usize;
    // Made and read in parallel, as they are traced: on the render's one
    // thread they kept the other threads waiting (`Surface::at` alone was
    // 1.35 % of the default render's samples in `perf`).
    let rays: Vec<Ray> = (0..n_pixels as u32)
        .into_par_iter()
        .map(|pixel| {
            let (x, y) = (pixel % ctx.width, pixel / ctx.width);
            let sx = (x as f32 + 0.5) / ctx.width as f32;
            let sy = (y as f32 + 0.5) / ctx.height as f32;
            Ray::new(
                camera.position,
                camera.direction(sx, sy, ctx.aspect()),
                0.0,
                f32::INFINITY,
            )
        })
        .collect();
    let mut hits = vec![Hit::MISS; rays.len()];
    ctx.backend.closest_hit(&rays, &mut hits);
    let pixel_angle = ctx.pixel_angle();
    rays.par_iter()
        .zip(&hits)
        .enumerate()
        .map(|(pixel, (ray, hit))| {
            let surface = Surface::at(ctx, ray, hit)?;
            let radiance = glossy == GlossyLobe::Eas && surface.bsdf.has_specular();
            let diffuse = surface.bsdf.diffuse_albedo().max_element() > 0.0;
            let footprint = hit.t * ray.dir().length() * pixel_angle;
            (diffuse || radiance).then(|| Candidate {
                pixel: pixel as u32,
                stream: first_stream(ctx, pixel as u32),
                point: off_the_edge(
                    surface.gather_point(),
                    ray,
                    settings.min_radius(footprint),
                    footprint,
                ),
                object: hit.object,
                footprint,
                glossy: radiance.then(|| ctx.snapshot.tri_material[hit.triangle as usize]),
            })
        })
        .collect()
}

/// Share of the least radius a record may have by which [`off_the_edge`]
/// steps a pixel centre's hit towards the camera: a tenth of the share of
/// `R` that Ward's in-front test tolerates
/// ([`IrradianceRecord::is_in_front_of`]), so a record stays usable on its
/// own surface.
const EDGE_STEP_OF_RADIUS: f32 = 1e-3;

/// The most [`off_the_edge`] steps, as a share of the pixel's footprint.
const EDGE_STEP_OF_PIXEL: f32 = 1e-2;

/// `point`, the hit of the camera ray `ray` through a pixel centre,
/// stepped back along the ray by [`EDGE_STEP_OF_RADIUS`] of `r_min`, the
/// least radius a record there may have, and at most
/// [`EDGE_STEP_OF_PIXEL`] of the pixel's `footprint` (at the default
/// spacing and accuracy both are a hundredth of a pixel).
///
/// Why: a camera centred in a box room renders its edges along a square
/// image's diagonals, and there the pixel centres hit exactly the line
/// where two walls meet (`x = 1, y = 2` on `cube-in-box`: 24 records' points
/// at 32 × 32, 208 at 256 × 256). The gather rays of a record there,
/// pushed off its own surface along the normal, started on the other one:
/// those towards it escaped through it and the others hit its back at
/// t = 0, so the record saw light in half its hemisphere or less, and a 0
/// hit distance made its gradient NaN. The camera saw the point from open
/// space, so the step leads into it.
///
/// Why both bounds: lookups lie on the surface, a pixel's samples around
/// its centre, and a record's weight there is bounded by the lookup's own
/// clearance as well as by `R` ([`IrradianceRecord::weight`]). A step of a
/// share of `r_min` alone grows as `1/a` and left records unusable at
/// their own pixels at low accuracies (every sample path-traced at
/// `a = 0.005`); a hundredth of a pixel adds little to distances of about
/// a pixel. So the step is short (4e-5 on `cube-in-box` at 256 × 256):
/// the gather rays towards the other wall meet it nearer than 1e-4, which
/// the BVH traversal culled until `accel::NEAR_SHIFT` (such records were
/// then still 4–14 % dark at 256 × 256; `tests` checks 32 and 256).
fn off_the_edge(mut point: GatherPoint, ray: &Ray, r_min: f32, footprint: f32) -> GatherPoint {
    let step = (EDGE_STEP_OF_RADIUS * r_min).min(EDGE_STEP_OF_PIXEL * footprint);
    point.position -= ray.dir().normalize() * step;
    point
}

/// Each candidate's lookup point with its clearance, in one ray batch for
/// the whole frame (they depend on the candidates only, not on the cache
/// the fill grows): on a GPU one round trip instead of one per fill
/// sub-batch.
fn candidate_clearances(
    ctx: &FrameContext,
    candidates: &[Option<Candidate>],
) -> Vec<Option<LookupPoint>> {
    let points: Vec<ShadingPoint> = candidates
        .iter()
        .flatten()
        .map(|c| (c.point.position, c.point.normal))
        .collect();
    let mut lookups = measure_clearance(ctx, &points).into_iter();
    candidates
        .iter()
        .map(|c| c.as_ref().and_then(|_| lookups.next()))
        .collect()
}

/// Which candidates' gathers say where their paths went
/// ([`IrradianceCaching::gather_parallel_tracked`]).
pub(crate) type TrackPaths<'a> = dyn Fn(&Candidate) -> bool + Sync + 'a;

/// Where the paths a record's gather traced went: for each gather query
/// whether it was traced (else its result was taken); the tracks of those
/// traced are, in query order, `tracks`' from `first` on (`tracks` holds
/// the tracks of a whole task of gathers).
pub(crate) struct GatherTracks {
    pub(crate) traced: Vec<bool>,
    pub(crate) tracks: Arc<PathTracks>,
    pub(crate) first: usize,
}

/// The results of `queries` (a chunk's candidates' gather queries, in
/// order): those `known` gives whole (per candidate, per query), the
/// others traced, taking the hits it gives ([`KnownPath`]); which were
/// traced, and (with `track`; else none) the tracks of those, in order.
fn trace_unknown(
    ctx: &FrameContext,
    length: PathLength,
    queries: &[RadianceQuery],
    known: &[Option<Vec<Option<KnownPath>>>],
    track: bool,
) -> (Vec<RadianceResult>, (Vec<bool>, PathTracks)) {
    let per_candidate = (queries.len() / known.len().max(1)).max(1);
    let known_at = |i: usize| {
        known[i / per_candidate]
            .as_ref()
            .and_then(|k| k.get(i % per_candidate).copied().flatten())
    };
    let known: Vec<Option<KnownPath>> = (0..queries.len()).map(known_at).collect();
    let results: Vec<Option<RadianceResult>> = (known.iter())
        .map(|k| match k {
            Some(KnownPath::Result(r)) => Some(*r),
            _ => None,
        })
        .collect();
    let traced: Vec<bool> = results.iter().map(Option::is_none).collect();
    let mut unknown = Vec::new();
    let mut replays: Vec<Replay> = Vec::new();
    for ((q, k), _) in queries.iter().zip(&known).zip(&traced).filter(|(_, &t)| t) {
        unknown.push(q.clone());
        replays.push(match k {
            Some(KnownPath::Hits(hits)) => hits,
            _ => &[],
        });
    }
    if replays.iter().all(|r| r.is_empty()) {
        replays.clear();
    }
    let (mut fresh, tracks) = trace_radiance_replayed(ctx, length, unknown, &replays, track);
    fresh.reverse();
    let results = results
        .into_iter()
        .map(|r| r.unwrap_or_else(|| fresh.pop().expect("one result per query traced")))
        .collect();
    (results, (traced, tracks))
}

/// The luminance of a per-channel gradient.
fn luminance_gradient(grad: &[Vec3; 3]) -> Vec3 {
    grad[0] * LUMINANCE.x + grad[1] * LUMINANCE.y + grad[2] * LUMINANCE.z
}

/// A translation gradient scaled down, if need be, so that it changes the
/// luminance of `e` by at most 100 % over `r` (see
/// [`IrradianceCaching::limit_radius`]; `trc` bounds its estimate of the
/// next frame's gradient with the same `r`).
pub(crate) fn limit_gradient(grad: [Vec3; 3], e: Vec3, r: f32) -> [Vec3; 3] {
    let (slope, e) = (luminance_gradient(&grad).length(), luminance(e));
    let scale = if slope * r > e { e / (slope * r) } else { 1.0 };
    grad.map(|c| c * scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::gather::Strata;

    /// A candidate from a damaged carried state may name a material the
    /// scene lacks: its record is gathered without sources, not a panic;
    /// one naming a glossy material the scene has keeps sources.
    #[test]
    fn a_candidate_naming_a_missing_material_gathers_no_sources() {
        let mut renderer = crate::render::test_renderer("glossy-cornell", 8);
        let glossy = renderer.with_frame_context(0, |ctx| {
            let glossy = ctx
                .scene
                .materials
                .iter()
                .position(crate::scene::Material::is_glossy);
            glossy.expect("glossy-cornell has glossy materials") as u32
        });
        let ic = IrradianceCaching::new(IcSettings {
            strata: Strata { theta: 4, phi: 12 },
            glossy: GlossyLobe::Eas,
            ..IcSettings::default()
        });
        let candidate = |material| Candidate {
            pixel: 0,
            stream: 0,
            point: GatherPoint {
                position: glam::Vec3::new(0.0, 0.5, 0.0),
                normal: glam::Vec3::Y,
                geometric_normal: glam::Vec3::Y,
            },
            object: 0,
            footprint: 0.01,
            glossy: Some(material),
        };
        let gathered: Vec<Gathered> = renderer.with_frame_context(0, |ctx| {
            let candidates = [candidate(u32::MAX), candidate(glossy)];
            ic.gather_parallel(ctx, &candidates).collect()
        });
        assert!(gathered[0].record.eas.is_none());
        assert!(gathered[1].record.eas.is_some());
    }

    /// `cube-in-box`'s camera is centred in the room, so a square image's
    /// diagonals run along the room's edges and the pixel centres there
    /// hit exactly the line where two walls meet. The records gathered at
    /// those pixels must see what a record a millimetre into the room
    /// sees (with the same random streams): before [`off_the_edge`], half
    /// their gather rays started on the other wall and saw nothing. At
    /// 256 × 256 the step is 4e-5, and until the traversal saw walls that
    /// near (`accel::NEAR_SHIFT`) such records were still 4–14 % dark.
    #[test]
    fn records_at_pixels_on_a_rooms_edge_gather_the_rooms_light() {
        for size in [32, 256] {
            records_on_the_edges_against_records_inside(size);
        }
    }

    fn records_on_the_edges_against_records_inside(size: u32) {
        let mut renderer = crate::render::test_renderer("cube-in-box", size);
        let ic = IrradianceCaching::new(IcSettings::default());
        let (on_edge, inside): (Vec<Gathered>, Vec<Gathered>) =
            renderer.with_frame_context(0, |ctx| {
                // Near the edges where the ceiling (y = 2) meets the side walls
                // (x = ±1): the pixels there lie a pixel's footprint apart.
                let on_edge: Vec<Candidate> = primary_candidates(ctx, &ic.settings)
                    .into_iter()
                    .flatten()
                    .filter(|c| {
                        let p = c.point.position;
                        (p.x.abs() - 1.0).abs() < 5e-3 && (p.y - 2.0).abs() < 5e-3
                    })
                    .collect();
                let inside: Vec<Candidate> = on_edge
                    .iter()
                    .map(|c| {
                        let mut c = *c;
                        let p = c.point.position;
                        c.point.position = glam::Vec3::new(p.x.signum() * 0.999, 1.999, p.z);
                        c
                    })
                    .collect();
                (
                    ic.gather_parallel(ctx, &on_edge).collect(),
                    ic.gather_parallel(ctx, &inside).collect(),
                )
            });
        assert!(
            on_edge.len() >= 8,
            "{size}: {} pixels on the edges",
            on_edge.len()
        );
        for (edge, inside) in on_edge.iter().zip(&inside) {
            let (e, i) = (&edge.record, &inside.record);
            let gradients = e.grad_translation.iter().chain(&e.grad_rotation);
            assert!(gradients.clone().all(|v| v.is_finite()), "{e:?}");
            let ratio = luminance(e.irradiance) / luminance(i.irradiance);
            assert!(
                (0.95..1.05).contains(&ratio),
                "{size}: {ratio}: {e:?} against {i:?}"
            );
        }
    }

    /// A hemisphere lit from one side, gathered next to a wall: one cell's
    /// ray hits the wall at t ≈ 0, which makes Ward & Heckbert's gradient
    /// huge. Limited with the record's radius, extrapolating over the
    /// record's influence (`a·R`) changes the luminance by at most `a`.
    #[test]
    fn a_hit_at_t_near_zero_cannot_blow_up_the_translation_gradient() {
        let strata = Strata { theta: 4, phi: 12 };
        let normal = Vec3::Z;
        let frame = crate::sampling::Frame::new(normal);
        let mut samples = HemisphereSamples::default();
        for j in 0..strata.theta {
            for k in 0..strata.phi {
                let phi = std::f32::consts::TAU * (k as f32 + 0.5) / strata.phi as f32;
                let s = ((j as f32 + 0.5) / strata.theta as f32).sqrt();
                let dir = frame.to_world(Vec3::new(
                    s * phi.cos(),
                    s * phi.sin(),
                    (1.0 - s * s).sqrt(),
                ));
                samples.direction.push(dir);
                // The wall next to the record, at t ≈ 0 and brighter.
                let wall = (j, k) == (3, 3);
                let l = if wall {
                    4.0
                } else if dir.x > 0.0 {
                    2.0
                } else {
                    0.5
                };
                samples.radiance.push(Vec3::splat(l));
                samples.distance.push(if wall { 1e-7 } else { 1.0 });
                samples.object.push(0);
            }
        }
        let g = irradiance_and_gradients(&samples, normal, strata);
        let e = luminance(g.irradiance);
        let raw = luminance_gradient(&g.grad_translation).length();
        let r = 0.05;
        assert!(
            raw * r > 100.0 * e,
            "the t ≈ 0 hit makes the raw gradient huge: {raw}"
        );

        let limited = limit_gradient(g.grad_translation, g.irradiance, r);
        let slope = luminance_gradient(&limited).length();
        assert!(
            (slope * r - e).abs() <= 1e-4 * e,
            "|∇E|·R = {} against E = {e}",
            slope * r
        );
        // A gradient within the limit is kept as it is.
        let small = limit_gradient(limited.map(|c| c * 0.5), g.irradiance, r);
        assert_eq!(small, limited.map(|c| c * 0.5));

        let a = IcSettings::default().accuracy;
        let record = IrradianceRecord {
            id: 0,
            position: Vec3::ZERO,
            normal,
            irradiance: g.irradiance,
            grad_translation: limited,
            grad_rotation: [Vec3::ZERO; 3],
            radius: r,
            created_frame: 0,
            object: 0,
            eas: None,
        };
        for k in 0..16 {
            let angle = std::f32::consts::TAU * k as f32 / 16.0;
            let p = Vec3::new(angle.cos(), angle.sin(), 0.0) * a * r;
            let change = (luminance(record.extrapolate(p, normal, true)) - e).abs();
            assert!(
                change <= a * e * 1.0001,
                "E changed by {change} of {e} at {p}"
            );
        }
    }
}
