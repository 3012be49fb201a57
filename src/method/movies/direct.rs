//! Direct irradiance at a set of surface points (the texels of a movie,
//! the vertices of the global pass) with the visibility of static and
//! moving blockers kept apart (paper §5, Fig. 6): which of a point's
//! shadow samples static blockers stop is found once, when its movie
//! opens, and each later frame only the moving blockers are tested, and
//! only on the samples whose segment passes through a moving object's
//! bounding box (the paper's shaft culling).
//!
//! Departure: the paper keeps, per texel, only the fraction of its samples
//! that each set of blockers stops (`Ts`, `Td`: transmittance textures
//! drawn by the graphics hardware) and merges them with
//! `T = (max(Ts,Td) + min(1,Ts+Td))/2`, because which samples were stopped
//! is lost (its Fig. 7). We keep one bit per sample, so the merge is
//! exact: a sample is dark if either set stops it ([`merge_stopped`], the
//! one merge every path of the renderer goes through). [`paper_merge`] is
//! the paper's formula, the mean of the exact merge's bounds; it is not
//! used, and kept to say what we depart from (unit tests check both).

use super::super::FrameContext;
use crate::accel::TriangleBvh;
use crate::backend::{Ray, SHADOW_EPSILON};
use crate::integrator::RayOffset;
use crate::light::{LightSource, PointLights, TriangleSampling};
use crate::sampling::{Rng, SampleKey, Stratified2d};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub use super::super::motion::{segment_hits_box, Aabb, Blockers};

/// The static triangles' BVH, built once a render and shared by the
/// frames' [`ShadowBlockers`].
pub use crate::accel::StaticGeometry;

/// What may stop a shadow sample in one frame: the moving objects' boxes
/// and which lights stand still ([`Blockers`], which it derefs to) and,
/// where anything moves, the static triangles on their own: the static
/// blockers of a segment that crosses a moving object.
pub struct ShadowBlockers {
    moving: Blockers,
    /// `None` where nothing moves (no segment crosses a moving box) or
    /// nothing stands still.
    statics: Option<Arc<TriangleBvh>>,
}

impl ShadowBlockers {
    pub fn new(ctx: &FrameContext, statics: &mut StaticGeometry) -> Self {
        let moving = Blockers::new(ctx);
        let statics = if moving.boxes.is_empty() {
            None
        } else {
            statics.of(ctx.snapshot)
        };
        ShadowBlockers { moving, statics }
    }

    /// Whether a static triangle lies on `ray` (the same intersection
    /// test, on the same shifted ray, as the backend's own traversal).
    fn static_blocks(&self, ray: &Ray) -> bool {
        self.statics.as_ref().is_some_and(|b| b.occludes(ray))
    }
}

impl std::ops::Deref for ShadowBlockers {
    type Target = Blockers;

    fn deref(&self) -> &Blockers {
        &self.moving
    }
}

/// The most shadow samples a point may take (one bit each in a `u64`).
pub const MAX_SHADOW_SAMPLES: u32 = 64;

/// A surface point whose direct irradiance is wanted.
#[derive(Clone, Copy, Debug)]
pub struct ShadePoint {
    pub p: Vec3,
    /// Shading normal, on the side the irradiance is wanted for.
    pub n: Vec3,
    /// Geometric normal on the same side.
    pub ng: Vec3,
    /// The point's random streams (the same in every frame: a point that
    /// does not move sees the same light samples, and its static shadows
    /// stay valid).
    pub item: u64,
}

impl ShadePoint {
    /// The point at barycentrics `(u, v)` of `tri`, on the side of it that
    /// `side` names (`1`: the side its normal faces, `−1`: its back). The
    /// shading normal is turned to that side, as `material::Bsdf::new`
    /// turns it to the viewer's: a mesh whose vertex normals disagree with
    /// its winding (a ball exported inside out) has them point the other
    /// way, and the side would take the irradiance of its back, in a
    /// closed ball none.
    pub fn on_side(
        tri: &crate::scene::Triangle,
        (u, v): (f32, f32),
        side: f32,
        item: u64,
    ) -> ShadePoint {
        let ng = tri.geometric_normal() * side;
        let n = tri.shading_normal(u, v);
        ShadePoint {
            p: tri.point(u, v),
            n: if n.dot(ng) < 0.0 { -n } else { n },
            ng,
            item,
        }
    }
}

/// The shadows static blockers cast on a set of points, kept while the
/// points and the lights that do not move stay where they are.
#[derive(Clone, Debug, Default)]
pub struct StaticShadows {
    /// The light pick distribution they were found under.
    fingerprint: u64,
    /// The points of each batch they were found in ([`chunk_points`]).
    chunk: usize,
    /// The points of all batches.
    points: usize,
    /// Each batch's shadows, kept as found: joining them into one list
    /// would hold them twice while it is made. `None`: not found yet, as
    /// no point of the batch was wanted ([`direct_irradiance_where`]).
    chunks: Vec<Option<ShadowChunk>>,
}

/// The kept shadows of one batch of points, their open samples in one
/// list (one allocation a batch, not a point), each list allocated at its
/// length, so that [`StaticShadows::bytes`] is what they hold.
#[derive(Clone, Debug, Default)]
struct ShadowChunk {
    points: Vec<PointShadows>,
    /// Every point's open samples, point after point.
    open: Vec<OpenSample>,
}

impl ShadowChunk {
    /// Point `i`'s open samples.
    fn open_of(&self, i: usize) -> &[OpenSample] {
        let end = self
            .points
            .get(i + 1)
            .map_or(self.open.len(), |p| p.first as usize);
        &self.open[self.points[i].first as usize..end]
    }
}

/// One point's kept shadows.
#[derive(Clone, Copy, Debug, Default)]
struct PointShadows {
    /// The summed contributions of its samples on static lights that no
    /// static blocker stops (what it gets where nothing moves near it).
    clear: Vec3,
    /// Where its open samples start in its batch's list: its samples on
    /// static lights that no static blocker stops. Only these may be
    /// stopped by a moving object, and their segments and contributions
    /// are kept so that no light is sampled again.
    first: u32,
    /// Its samples on lights that move (bit `s`: sample `s`).
    moving: u64,
}

#[derive(Clone, Copy, Debug)]
struct OpenSample {
    sample: u32,
    c: Vec3,
    /// Its shadow segment's direction (origin to light point): with the
    /// point, the segment itself, bit for bit ([`OpenSample::ray`]), in
    /// 12 bytes rather than a ray's 32.
    dir: Vec3,
}

impl OpenSample {
    /// The shadow segment from `point`: the origin pushed off the surface
    /// by `offset`, as [`RayOffset::origin`] pushes it towards any light
    /// above it.
    fn ray(&self, point: &ShadePoint, offset: RayOffset) -> Ray {
        let origin = offset.origin(point.p, point.ng, point.ng);
        Ray::new(origin, self.dir, 0.0, 1.0 - SHADOW_EPSILON)
    }
}

impl StaticShadows {
    /// Whether these are the shadows of `points` points in this frame (the
    /// lights were picked as when they were found), in batches of `chunk`.
    pub fn valid_for(&self, blockers: &ShadowBlockers, points: usize, chunk: usize) -> bool {
        self.fingerprint == blockers.pick_fingerprint
            && self.chunk == chunk
            && self.points == points
    }

    /// Bytes held on the heap: every list by its capacity.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.chunks.capacity() * size_of::<Option<ShadowChunk>>()
            + (self.chunks.iter().flatten())
                .map(|c| {
                    c.points.capacity() * size_of::<PointShadows>()
                        + c.open.capacity() * size_of::<OpenSample>()
                })
                .sum::<usize>()
    }

    /// The most [`bytes`](Self::bytes) the shadows of `points` points of
    /// `samples` shadow samples, found in batches of `chunk`, can hold:
    /// every sample open. Known before they are found, so that room can
    /// be made for them ([`super::TextureMovies`]' memory budget).
    pub fn bound(points: usize, samples: u32, chunk: usize) -> usize {
        use std::mem::size_of;
        let samples = samples.clamp(1, MAX_SHADOW_SAMPLES) as usize;
        points.div_ceil(chunk.max(1)) * size_of::<Option<ShadowChunk>>()
            + points * (size_of::<PointShadows>() + samples * size_of::<OpenSample>())
    }
}

/// Shadow samples taken: rays traced against all blockers, and samples
/// answered by the kept static shadows alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShadowCounts {
    pub traced: u64,
    pub kept: u64,
}

impl std::ops::AddAssign for ShadowCounts {
    fn add_assign(&mut self, o: Self) {
        self.traced += o.traced;
        self.kept += o.kept;
    }
}

/// Light sample `s` of `samples` at `point`, stratified over the point's
/// samples, and the light it lands on. The point's view of each light is
/// worked out once for all its samples ([`PointLights`]).
struct PointSampler<'a> {
    layout: Stratified2d,
    seed: u64,
    point: &'a ShadePoint,
    lights: PointLights<'a>,
}

impl<'a> PointSampler<'a> {
    fn new(ctx: &'a FrameContext, point: &'a ShadePoint, samples: u32) -> Self {
        let mut keys = Rng::new(key(ctx.seed, point.item, u32::MAX));
        let scramble = keys.next_u32();
        PointSampler {
            layout: Stratified2d::new(samples, Some(scramble), keys.next_u32()),
            seed: ctx.seed,
            point,
            lights: ctx
                .lights
                .at_point(ctx.snapshot, point.p, TriangleSampling::SolidAngle),
        }
    }

    /// Sample `s`: the light it picks, and its contribution to E (before
    /// visibility) and shadow segment where that light can send light to
    /// the point in this frame.
    fn sample(&mut self, ctx: &FrameContext, s: u32) -> Option<Drawn> {
        let point = self.point;
        let u = self
            .layout
            .sample(s, Rng::new(key(self.seed, point.item, s)).next_2d());
        let choice = ctx.lights.choose(u);
        let source = ctx.lights.source_of(choice.pick)?;
        let lit = self.lights.sample(choice).and_then(|ls| {
            let cos = point.n.dot(ls.wi);
            // Written so that a NaN (a degenerate triangle's normal) fails too.
            (cos > 0.0 && point.ng.dot(ls.wi) > 0.0).then(|| {
                let shadow =
                    Ray::segment(ctx.ray_offset.origin(point.p, point.ng, ls.wi), ls.position);
                (ls.radiance * (cos / ls.pdf), shadow)
            })
        });
        Some(Drawn { source, lit })
    }
}

/// A drawn light sample.
struct Drawn {
    source: LightSource,
    /// `(contribution to E before visibility, shadow segment)`; `None`
    /// where the light cannot reach the point in this frame (its back
    /// face, outside its cone). A light that moves may reach it in a later
    /// frame, so the sample is still one of the point's samples on a
    /// moving light.
    lit: Option<(Vec3, Ray)>,
}

fn key(seed: u64, item: u64, sample: u32) -> SampleKey {
    SampleKey {
        seed,
        frame: None,
        item,
        sample,
    }
}

/// How a [`direct_irradiance`] takes the points' static shadows.
pub enum Statics<'a> {
    /// The points move: every sample is traced against every blocker.
    Moving,
    /// The points do not move, and their static shadows are kept here:
    /// used where still valid, found (and kept) where not, a batch of
    /// points at a time, and not found while no point of the batch is
    /// wanted ([`direct_irradiance_where`]).
    Kept(&'a mut StaticShadows),
    /// The points do not move, but there is no room to keep their static
    /// shadows: they are found as for points seen the first time, batch
    /// by batch, and each batch's let go as it ends. The irradiance is
    /// then, bit for bit, that of points seen the first time (so of a
    /// movie opened at this frame), at the cost of every sample's ray.
    Unkept,
}

/// The points a batch of [`direct_irradiance`] takes (the shadows of
/// points that do not move are kept batch by batch).
pub fn chunk_points(ctx: &FrameContext, samples: u32) -> usize {
    let samples = samples.clamp(1, MAX_SHADOW_SAMPLES);
    (ctx.backend.min_batch() / samples as usize).clamp(64, 4096)
}

/// Direct irradiance at `points` with `samples` shadow samples each, the
/// static shadows taken as `statics` says.
pub fn direct_irradiance(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    points: &[ShadePoint],
    samples: u32,
    statics: Statics,
) -> (Vec<Vec3>, ShadowCounts) {
    direct_irradiance_where(ctx, blockers, (points, None), samples, statics)
}

/// [`direct_irradiance`] at the points `wanted` marks (`None`: all), zero
/// at the others. A point's irradiance is the same whichever others are
/// wanted with it (its samples are its own streams'), so a point skipped
/// in one frame and wanted in the next gets what it would have had. Kept
/// static shadows are found a batch at a time ([`chunk_points`]), for
/// every point of a batch once one of them is wanted.
pub fn direct_irradiance_where(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    (points, wanted): (&[ShadePoint], Option<&[bool]>),
    samples: u32,
    statics: Statics,
) -> (Vec<Vec3>, ShadowCounts) {
    debug_assert!(wanted.is_none_or(|w| w.len() == points.len()));
    let samples = samples.clamp(1, MAX_SHADOW_SAMPLES);
    let chunk = chunk_points(ctx, samples);
    match statics {
        Statics::Moving => only_wanted(points, wanted, |points| {
            let parts: Vec<(Vec<Vec3>, ShadowCounts)> = points
                .par_chunks(chunk)
                .map(|p| moving_points(ctx, p, samples))
                .collect();
            join(parts)
        }),
        Statics::Unkept => only_wanted(points, wanted, |points| {
            let parts: Vec<(Vec<Vec3>, ShadowCounts)> = points
                .par_chunks(chunk)
                .map(|p| {
                    let (e, counts, _let_go) = first_static_points(ctx, blockers, p, samples);
                    (e, counts)
                })
                .collect();
            join(parts)
        }),
        Statics::Kept(kept) => {
            if !kept.valid_for(blockers, points.len(), chunk) {
                // Let go of the shadows no longer valid before their
                // successors are found: the two are never held at once.
                *kept = StaticShadows {
                    fingerprint: blockers.pick_fingerprint,
                    chunk,
                    points: points.len(),
                    chunks: (0..points.len().div_ceil(chunk)).map(|_| None).collect(),
                };
            }
            let parts: Vec<(Vec<Vec3>, ShadowCounts)> = (points.par_chunks(chunk).enumerate())
                .zip(kept.chunks.par_iter_mut())
                .map(|((k, p), shadows)| {
                    let wanted = wanted.map(|w| &w[k * chunk..k * chunk + p.len()]);
                    kept_batch(ctx, blockers, (p, wanted), samples, shadows)
                })
                .collect();
            join(parts)
        }
    }
}

/// One batch of points that do not move, their static shadows kept in
/// `shadows`: taken from there where found, found and kept where not and
/// a point is wanted, not found while none is.
fn kept_batch(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    (points, wanted): (&[ShadePoint], Option<&[bool]>),
    samples: u32,
    shadows: &mut Option<ShadowChunk>,
) -> (Vec<Vec3>, ShadowCounts) {
    if let Some(found) = shadows {
        return kept_points(ctx, blockers, (points, wanted), samples, found);
    }
    if !(0..points.len()).any(|i| is_wanted(wanted, i)) {
        return (vec![Vec3::ZERO; points.len()], ShadowCounts::default());
    }
    let (mut e, counts, found) = first_static_points(ctx, blockers, points, samples);
    *shadows = Some(found);
    for (i, e) in e.iter_mut().enumerate() {
        if !is_wanted(wanted, i) {
            *e = Vec3::ZERO;
        }
    }
    (e, counts)
}

/// Whether point `i` is one `wanted` marks (`None`: all are).
fn is_wanted(wanted: Option<&[bool]>, i: usize) -> bool {
    wanted.is_none_or(|w| w[i])
}

/// `irradiance` of the `wanted` ones of `points`, put back in their
/// places, zero at the others.
fn only_wanted(
    points: &[ShadePoint],
    wanted: Option<&[bool]>,
    irradiance: impl FnOnce(&[ShadePoint]) -> (Vec<Vec3>, ShadowCounts),
) -> (Vec<Vec3>, ShadowCounts) {
    let Some(wanted) = wanted else {
        return irradiance(points);
    };
    let picked: Vec<ShadePoint> = (points.iter().zip(wanted))
        .filter(|(_, &w)| w)
        .map(|(p, _)| *p)
        .collect();
    let (picked_e, counts) = irradiance(&picked);
    let mut picked_e = picked_e.into_iter();
    let e = (wanted.iter())
        .map(|&w| match w {
            true => picked_e.next().unwrap_or(Vec3::ZERO),
            false => Vec3::ZERO,
        })
        .collect();
    (e, counts)
}

fn join(parts: Vec<(Vec<Vec3>, ShadowCounts)>) -> (Vec<Vec3>, ShadowCounts) {
    let mut e = Vec::new();
    let mut counts = ShadowCounts::default();
    for (part, c) in parts {
        e.extend(part);
        counts += c;
    }
    (e, counts)
}

/// Shadow rays waiting to be traced, each with the slots (point ·
/// sample) it answers for. A point's samples that make the same segment
/// share one ray: every sample on a point, spot or directional light
/// does (the light has one position), so a texel's 16 samples of a sun
/// traced one ray, not 16, and answer as they did.
struct Pending {
    /// Samples a point.
    per: usize,
    rays: Vec<Ray>,
    /// Each slot pushed, in push order, with the ray that answers it.
    slots: Vec<(usize, u32)>,
    /// The rays of the point pushed last start here.
    point_rays: usize,
}

impl Pending {
    fn new(per: usize) -> Self {
        Pending {
            per,
            rays: Vec::new(),
            slots: Vec::new(),
            point_rays: 0,
        }
    }

    /// Pushes `slot`'s segment, or has the same segment, pushed already
    /// for its point, answer for it. A point's slots are pushed together.
    fn push(&mut self, ray: Ray, slot: usize) {
        let new_point = self
            .slots
            .last()
            .is_none_or(|&(last, _)| last / self.per != slot / self.per);
        if new_point {
            self.point_rays = self.rays.len();
        }
        // The direction first: it tells apart the samples of an area light,
        // which share the origin.
        let same =
            (self.rays[self.point_rays..].iter()).position(|r| r.dir == ray.dir && *r == ray);
        let index = match same {
            Some(k) => self.point_rays + k,
            None => {
                self.rays.push(ray);
                self.rays.len() - 1
            }
        };
        self.slots.push((slot, index as u32));
    }

    /// Traces against every blocker: per point (of `points`), the samples
    /// stopped (bit `s`: sample `s`), and the rays traced.
    fn stopped(self, ctx: &FrameContext, points: usize) -> (Vec<u64>, u64) {
        let mut occluded = vec![false; self.rays.len()];
        ctx.backend.any_hit(&self.rays, &mut occluded);
        let mut stopped = vec![0u64; points];
        for &(slot, ray) in &self.slots {
            if occluded[ray as usize] {
                stopped[slot / self.per] |= 1 << (slot % self.per);
            }
        }
        (stopped, self.rays.len() as u64)
    }
}

/// The samples `0..samples` of a point, as bits.
fn all_samples(samples: u32) -> u64 {
    u64::MAX >> (64 - samples.clamp(1, MAX_SHADOW_SAMPLES))
}

/// The merge of static and dynamic visibility (paper §5, Fig. 6–7), the
/// one the renderer makes: bit `s` of the result is set where sample `s`
/// is stopped by a static blocker (`by_static`, found when the points'
/// shadows were kept) or by what this frame traces (`by_dynamic`: the
/// moving blockers, or every blocker for a sample on a light that moves).
/// Departure: the paper has only each set's stopped fraction and merges
/// them with [`paper_merge`]; with one bit per sample the merge is exact.
pub fn merge_stopped(by_static: u64, by_dynamic: u64) -> u64 {
    by_static | by_dynamic
}

/// A point's irradiance from its samples' `contributions` (before
/// visibility, in sample order; zero for a sample whose light cannot
/// reach it), the samples in `stopped` left out: their mean. Summed in
/// sample order whatever order they were found in, so that a kept movie
/// and a new one give the same bits (a resumed render equals an
/// uninterrupted one).
pub fn lit_mean(contributions: &[Vec3], stopped: u64) -> Vec3 {
    let scale = 1.0 / contributions.len() as f32;
    let sum = contributions
        .iter()
        .enumerate()
        .fold(Vec3::ZERO, |a, (s, &c)| {
            a + if stopped & (1 << s) != 0 {
                Vec3::ZERO
            } else {
                c
            }
        });
    sum * scale
}

/// Each point's irradiance: its samples' slots merged with the samples
/// stopped by static and by dynamic blockers.
fn merged_means(slots: &[Vec3], per: usize, by_static: &[u64], by_dynamic: &[u64]) -> Vec<Vec3> {
    slots
        .chunks(per)
        .zip(by_static.iter().zip(by_dynamic))
        .map(|(c, (&s, &d))| lit_mean(c, merge_stopped(s, d)))
        .collect()
}

/// Points on moving objects: every sample traced against every blocker.
fn moving_points(
    ctx: &FrameContext,
    points: &[ShadePoint],
    samples: u32,
) -> (Vec<Vec3>, ShadowCounts) {
    let per = samples as usize;
    let mut pending = Pending::new(per);
    let mut slots = vec![Vec3::ZERO; points.len() * per];
    for (i, point) in points.iter().enumerate() {
        let mut sampler = PointSampler::new(ctx, point, samples);
        for s in 0..samples {
            if let Some((c, ray)) = sampler.sample(ctx, s).and_then(|d| d.lit) {
                let slot = i * per + s as usize;
                slots[slot] = c;
                pending.push(ray, slot);
            }
        }
    }
    // Nothing to merge: every blocker is in the one trace.
    let (stopped, traced) = pending.stopped(ctx, points.len());
    let e = slots
        .chunks(per)
        .zip(stopped)
        .map(|(c, stopped)| lit_mean(c, stopped))
        .collect();
    (e, ShadowCounts { traced, kept: 0 })
}

/// Points that do not move, with their static shadows kept: a point whose
/// view of the static lights no moving object's box can cross takes its
/// kept sum; the others test their open samples against the moving
/// objects whose boxes their segments cross. Samples on moving lights are
/// drawn and traced again.
fn kept_points(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    (points, wanted): (&[ShadePoint], Option<&[bool]>),
    samples: u32,
    shadows: &ShadowChunk,
) -> (Vec<Vec3>, ShadowCounts) {
    let per = samples as usize;
    let mut slots = vec![Vec3::ZERO; points.len() * per];
    let mut by_static = vec![0u64; points.len()];
    let mut shortcut = vec![false; points.len()];
    let mut pending = Pending::new(per);
    let mut kept = 0u64;
    for (i, (point, kept_shadows)) in points.iter().zip(&shadows.points).enumerate() {
        if !is_wanted(wanted, i) {
            // No samples: its irradiance is zero.
            continue;
        }
        let open = shadows.open_of(i);
        if blockers.static_view_clear(point.p) && kept_shadows.moving == 0 {
            shortcut[i] = true;
            kept += u64::from(samples);
            continue;
        }
        // A sample on a static light is stopped by a static blocker (or
        // cannot be reached) unless it was kept as open.
        by_static[i] = all_samples(samples) & !kept_shadows.moving;
        for o in open {
            let slot = i * per + o.sample as usize;
            by_static[i] &= !(1 << o.sample);
            slots[slot] = o.c;
            let ray = o.ray(point, ctx.ray_offset);
            if blockers.segment_may_hit(ray.origin(), ray.at(ray.tmax)) {
                pending.push(ray, slot);
            } else {
                kept += 1;
            }
        }
        kept +=
            u64::from(samples) - open.len() as u64 - u64::from(kept_shadows.moving.count_ones());
        if kept_shadows.moving != 0 {
            let mut sampler = PointSampler::new(ctx, point, samples);
            for s in (0..samples).filter(|s| kept_shadows.moving & (1 << s) != 0) {
                if let Some((c, ray)) = sampler.sample(ctx, s).and_then(|d| d.lit) {
                    let slot = i * per + s as usize;
                    slots[slot] = c;
                    pending.push(ray, slot);
                }
            }
        }
    }
    let (by_dynamic, traced) = pending.stopped(ctx, points.len());
    let mut e = merged_means(&slots, per, &by_static, &by_dynamic);
    for (i, _) in shortcut.iter().enumerate().filter(|(_, &s)| s) {
        e[i] = shadows.points[i].clear;
    }
    (e, ShadowCounts { traced, kept })
}

/// Points that do not move, seen for the first time: the static shadows
/// of their samples on static lights found (and returned), their
/// irradiance with every blocker.
fn first_static_points(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    points: &[ShadePoint],
    samples: u32,
) -> (Vec<Vec3>, ShadowCounts, ShadowChunk) {
    let n = points.len();
    let per = samples as usize;
    let mut found = vec![PointShadows::default(); n];
    let mut pending = Pending::new(per);
    let mut slots = vec![Vec3::ZERO; n * per];
    // Samples on static lights.
    let mut probes = Pending::new(per);
    for (i, point) in points.iter().enumerate() {
        let mut sampler = PointSampler::new(ctx, point, samples);
        for s in 0..samples {
            let Some(drawn) = sampler.sample(ctx, s) else {
                continue;
            };
            let slot = i * per + s as usize;
            if let Some((c, _)) = drawn.lit {
                slots[slot] = c;
            }
            if !blockers.is_static(drawn.source) {
                // Drawn again every frame, also where the light cannot
                // reach the point now: it may later.
                found[i].moving |= 1 << s;
                if let Some((_, ray)) = drawn.lit {
                    pending.push(ray, slot);
                }
            } else if let Some((_, ray)) = drawn.lit {
                probes.push(ray, slot);
            }
        }
    }
    let (probe_static, probe_any) = static_and_any_blocked(ctx, blockers, &probes.rays);
    let mut by_static = vec![0u64; n];
    let (mut by_dynamic, traced) = pending.stopped(ctx, n);
    // Allocated at its length: what is kept is what is counted.
    let mut open = Vec::with_capacity(probe_static.iter().filter(|&&s| !s).count());
    let mut next = 0;
    for &(slot, k) in &probes.slots {
        let (i, s, k) = (slot / per, slot % per, k as usize);
        let ray = probes.rays[k];
        // The probes run point after point: a point's open samples start
        // where the last point's ended.
        while next <= i {
            found[next].first = open.len() as u32;
            next += 1;
        }
        if probe_static[k] {
            by_static[i] |= 1 << s;
        } else {
            let sample = OpenSample {
                sample: s as u32,
                c: slots[slot],
                dir: ray.dir(),
            };
            debug_assert_eq!(sample.ray(&points[i], ctx.ray_offset), ray);
            open.push(sample);
        }
        if probe_any[k] {
            by_dynamic[i] |= 1 << s;
        }
    }
    for f in &mut found[next..] {
        f.first = open.len() as u32;
    }
    let traced = probes.rays.len() as u64 + traced;
    for (i, f) in found.iter_mut().enumerate() {
        // What a point gets where nothing moves near it: its samples on
        // static lights that no static blocker stops.
        f.clear = lit_mean(
            &slots[i * per..(i + 1) * per],
            merge_stopped(by_static[i], f.moving),
        );
    }
    (
        merged_means(&slots, per, &by_static, &by_dynamic),
        ShadowCounts { traced, kept: 0 },
        ShadowChunk {
            points: found,
            open,
        },
    )
}

/// For each segment: whether a static blocker stops it, and whether any
/// blocker does. One any-hit ray each answers the second, and the first
/// too where the segment is clear of every moving object's box; a segment
/// that crosses one is traced again against the static triangles alone,
/// so that a static surface just behind a moving one, or touching it (a
/// box standing on a table), is found however near it lies. (Stepping
/// from hit to hit past the moving surfaces skipped a static one within
/// the step, and gave up after a number of steps calling the segment
/// clear: such a sample was kept as open, and once the moving object was
/// gone a kept movie took its light through the static blocker, where a
/// movie opened then did not.)
///
/// The two answers are merged by [`merge_stopped`], which the later
/// frames' kept answers go through too: a static blocker that the first
/// trace missed (a hair behind a moving surface) stops the sample in this
/// frame as in every later one.
fn static_and_any_blocked(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    rays: &[Ray],
) -> (Vec<bool>, Vec<bool>) {
    let mut by_any = vec![false; rays.len()];
    ctx.backend.any_hit(rays, &mut by_any);
    let by_static = rays
        .iter()
        .zip(&by_any)
        .map(|(ray, &any)| {
            if !blockers.segment_may_hit(ray.origin(), ray.at(ray.tmax)) {
                return any;
            }
            blockers.static_blocks(ray)
        })
        .collect();
    (by_static, by_any)
}

/// The paper's merge of the transmittance of static (`ts`) and moving
/// (`td`) blockers, each the fraction of a texel's samples stopped
/// (§5): `T = (max(Ts,Td) + min(1,Ts+Td))/2`, the mean of the merge's
/// bounds (the blockers overlap wholly, or not at all).
pub fn paper_merge(ts: f32, td: f32) -> f32 {
    (ts.max(td) + (ts + td).min(1.0)) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point's shading normal is turned to its side: a triangle whose
    /// vertex normals face against its winding gives, on either side, the
    /// normal of that side; one whose vertex normals agree keeps them.
    #[test]
    fn a_shade_point_turns_its_normal_to_its_side() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        for normal in [Vec3::Z, -Vec3::Z, Vec3::new(0.6, 0.0, 0.8)] {
            let tri = crate::scene::Triangle { p, n: [normal; 3] };
            for side in [1.0, -1.0] {
                let point = ShadePoint::on_side(&tri, (0.25, 0.25), side, 0);
                assert_eq!(point.ng, Vec3::Z * side);
                assert!(point.n.dot(point.ng) > 0.0, "{normal} on side {side}");
                assert!((point.n.dot(normal).abs() - 1.0).abs() < 1e-6);
            }
        }
    }

    /// The renderer's merge and sum ([`merge_stopped`], [`lit_mean`])
    /// against visibility computed apart, per sample, as the product of
    /// the static and the dynamic visibility (in `f64`), for every pair of
    /// stopped sets of 6 samples with random contributions. With equal
    /// contributions the stopped share is `|S ∪ D|/n` counted by
    /// inclusion–exclusion, and lies between the bounds the paper's
    /// formula averages.
    #[test]
    fn the_renderers_merge_darkens_what_either_set_stops() {
        let n = 6usize;
        let mut rng = Rng::from_seed(11, 0);
        for s in 0u64..64 {
            for d in 0u64..64 {
                let c: Vec<Vec3> = (0..n)
                    .map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()))
                    .collect();
                let got = lit_mean(&c, merge_stopped(s, d));
                let visible = |bits: u64, k: usize| if bits >> k & 1 == 1 { 0.0 } else { 1.0 };
                for axis in 0..3 {
                    let want: f64 = (0..n)
                        .map(|k| f64::from(c[k][axis]) * visible(s, k) * visible(d, k))
                        .sum::<f64>()
                        / n as f64;
                    assert!(
                        (f64::from(got[axis]) - want).abs() < 1e-6,
                        "S {s:06b} D {d:06b}: {got} against {want}"
                    );
                }
                let stopped = 1.0 - lit_mean(&vec![Vec3::ONE; n], merge_stopped(s, d)).x;
                let frac = |bits: u64| bits.count_ones() as f32 / n as f32;
                let (ts, td) = (frac(s), frac(d));
                assert!((stopped - (ts + td - frac(s & d))).abs() < 1e-6);
                assert!(ts.max(td) - 1e-6 <= stopped && stopped <= (ts + td).min(1.0) + 1e-6);
            }
        }
    }

    /// The paper's formula is the mean of the least and the most that two
    /// sets stopping shares `Ts` and `Td` of a texel's samples can stop
    /// together (Fig. 7: wholly overlapping, or apart as far as they can
    /// be), found here by trying every pair of sets of 6 samples.
    #[test]
    fn the_papers_merge_is_the_mean_of_the_merges_bounds() {
        let n = 6u32;
        let mut least = [[n; 7]; 7];
        let mut most = [[0u32; 7]; 7];
        for s in 0u64..64 {
            for d in 0u64..64 {
                let (a, b) = (s.count_ones() as usize, d.count_ones() as usize);
                let union = (s | d).count_ones();
                least[a][b] = least[a][b].min(union);
                most[a][b] = most[a][b].max(union);
            }
        }
        for a in 0..=n as usize {
            for b in 0..=n as usize {
                let share = |k: u32| k as f32 / n as f32;
                let mean = (share(least[a][b]) + share(most[a][b])) / 2.0;
                let paper = paper_merge(share(a as u32), share(b as u32));
                assert!(
                    (paper - mean).abs() < 1e-6,
                    "Ts {a}/6, Td {b}/6: {paper} against {mean}"
                );
            }
        }
    }
}
