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
//! exact: a sample is dark if either set stops it. [`paper_merge`] is the
//! paper's formula, whose two terms bound the exact merge (a unit test
//! checks it).

use super::super::FrameContext;
use crate::accel::TriangleBvh;
use crate::backend::{Ray, SHADOW_EPSILON};
use crate::integrator::offset_origin;
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

/// The shadows static blockers cast on a set of points, kept while the
/// points and the lights that do not move stay where they are.
#[derive(Clone, Debug, Default)]
pub struct StaticShadows {
    /// The light pick distribution they were found under.
    fingerprint: u64,
    points: Vec<PointShadows>,
}

/// One point's kept shadows.
#[derive(Clone, Debug, Default)]
struct PointShadows {
    /// The summed contributions of its samples on static lights that no
    /// static blocker stops (what it gets where nothing moves near it).
    clear: Vec3,
    /// Its samples on lights that move (bit `s`: sample `s`).
    moving: u64,
    /// Its samples on static lights that no static blocker stops: only
    /// these may be stopped by a moving object, and their segments and
    /// contributions are kept so that no light is sampled again.
    open: Vec<OpenSample>,
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
    /// as [`offset_origin`] pushes it towards any light above it.
    fn ray(&self, point: &ShadePoint) -> Ray {
        let origin = offset_origin(point.p, point.ng, point.ng);
        Ray::new(origin, self.dir, 0.0, 1.0 - SHADOW_EPSILON)
    }
}

impl StaticShadows {
    fn valid_for(&self, blockers: &ShadowBlockers, points: usize) -> bool {
        self.fingerprint == blockers.pick_fingerprint && self.points.len() == points
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.points
            .iter()
            .map(|p| {
                std::mem::size_of::<PointShadows>()
                    + p.open.len() * std::mem::size_of::<OpenSample>()
            })
            .sum()
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
                let shadow = Ray::segment(offset_origin(point.p, point.ng, ls.wi), ls.position);
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

/// Direct irradiance at `points` with `samples` shadow samples each.
/// With `kept` (points that do not move), the static shadows in it are
/// used where still valid and found again where not.
pub fn direct_irradiance(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    points: &[ShadePoint],
    samples: u32,
    kept: Option<&mut StaticShadows>,
) -> (Vec<Vec3>, ShadowCounts) {
    let samples = samples.clamp(1, MAX_SHADOW_SAMPLES);
    let chunk = (ctx.backend.min_batch() / samples as usize).clamp(64, 4096);
    match kept {
        None => {
            let parts: Vec<(Vec<Vec3>, ShadowCounts)> = points
                .par_chunks(chunk)
                .map(|p| moving_points(ctx, p, samples))
                .collect();
            join(parts)
        }
        Some(kept) if kept.valid_for(blockers, points.len()) => {
            let parts: Vec<(Vec<Vec3>, ShadowCounts)> = points
                .par_chunks(chunk)
                .zip(kept.points.par_chunks(chunk))
                .map(|(p, shadows)| kept_points(ctx, blockers, p, samples, shadows))
                .collect();
            join(parts)
        }
        Some(kept) => {
            let parts: Vec<(Vec<Vec3>, ShadowCounts, Vec<PointShadows>)> = points
                .par_chunks(chunk)
                .map(|p| first_static_points(ctx, blockers, p, samples))
                .collect();
            let mut e = Vec::with_capacity(points.len());
            let mut counts = ShadowCounts::default();
            let mut found = Vec::with_capacity(points.len());
            for (part_e, part_counts, part) in parts {
                e.extend(part_e);
                counts += part_counts;
                found.extend(part);
            }
            *kept = StaticShadows {
                fingerprint: blockers.pick_fingerprint,
                points: found,
            };
            (e, counts)
        }
    }
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

/// Shadow rays waiting to be traced, each with the slot (point · sample)
/// its contribution goes to if nothing stops it.
#[derive(Default)]
struct Pending {
    rays: Vec<Ray>,
    targets: Vec<(usize, Vec3)>,
}

impl Pending {
    fn push(&mut self, ray: Ray, slot: usize, c: Vec3) {
        self.rays.push(ray);
        self.targets.push((slot, c));
    }

    /// Traces against every blocker and fills the unoccluded slots.
    fn fill_unoccluded(self, ctx: &FrameContext, slots: &mut [Vec3]) -> u64 {
        let mut occluded = vec![false; self.rays.len()];
        ctx.backend.any_hit(&self.rays, &mut occluded);
        for ((slot, c), blocked) in self.targets.into_iter().zip(occluded) {
            if !blocked {
                slots[slot] = c;
            }
        }
        self.rays.len() as u64
    }
}

/// Each point's irradiance from its samples' slots, summed in sample
/// order whatever order they were found in, so that a kept movie and a
/// new one give the same bits (a resumed render equals an uninterrupted
/// one).
fn sum_slots(slots: &[Vec3], samples: u32) -> Vec<Vec3> {
    let scale = 1.0 / samples as f32;
    slots
        .chunks(samples as usize)
        .map(|s| s.iter().fold(Vec3::ZERO, |a, &c| a + c) * scale)
        .collect()
}

/// Points on moving objects: every sample traced against every blocker.
fn moving_points(
    ctx: &FrameContext,
    points: &[ShadePoint],
    samples: u32,
) -> (Vec<Vec3>, ShadowCounts) {
    let mut pending = Pending::default();
    let per = samples as usize;
    for (i, point) in points.iter().enumerate() {
        let mut sampler = PointSampler::new(ctx, point, samples);
        for s in 0..samples {
            if let Some((c, ray)) = sampler.sample(ctx, s).and_then(|d| d.lit) {
                pending.push(ray, i * per + s as usize, c);
            }
        }
    }
    let mut slots = vec![Vec3::ZERO; points.len() * per];
    let traced = pending.fill_unoccluded(ctx, &mut slots);
    (sum_slots(&slots, samples), ShadowCounts { traced, kept: 0 })
}

/// Points that do not move, with their static shadows kept: a point whose
/// view of the static lights no moving object's box can cross takes its
/// kept sum; the others test their open samples against the moving
/// objects whose boxes their segments cross. Samples on moving lights are
/// drawn and traced again.
fn kept_points(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    points: &[ShadePoint],
    samples: u32,
    shadows: &[PointShadows],
) -> (Vec<Vec3>, ShadowCounts) {
    let per = samples as usize;
    let mut slots = vec![Vec3::ZERO; points.len() * per];
    let mut shortcut = vec![false; points.len()];
    let mut pending = Pending::default();
    let mut kept = 0u64;
    for (i, (point, kept_shadows)) in points.iter().zip(shadows).enumerate() {
        let shaft_clear = blockers
            .static_lights
            .is_none_or(|(lo, hi)| !blockers.box_may_hit((lo.min(point.p), hi.max(point.p))));
        if shaft_clear && kept_shadows.moving == 0 {
            shortcut[i] = true;
            kept += u64::from(samples);
            continue;
        }
        for o in &kept_shadows.open {
            let slot = i * per + o.sample as usize;
            let ray = o.ray(point);
            if blockers.segment_may_hit(ray.origin(), ray.at(ray.tmax)) {
                pending.push(ray, slot, o.c);
            } else {
                slots[slot] = o.c;
                kept += 1;
            }
        }
        kept += u64::from(samples)
            - kept_shadows.open.len() as u64
            - u64::from(kept_shadows.moving.count_ones());
        if kept_shadows.moving != 0 {
            let mut sampler = PointSampler::new(ctx, point, samples);
            for s in (0..samples).filter(|s| kept_shadows.moving & (1 << s) != 0) {
                if let Some((c, ray)) = sampler.sample(ctx, s).and_then(|d| d.lit) {
                    pending.push(ray, i * per + s as usize, c);
                }
            }
        }
    }
    let traced = pending.fill_unoccluded(ctx, &mut slots);
    let mut e = sum_slots(&slots, samples);
    for (i, _) in shortcut.iter().enumerate().filter(|(_, &s)| s) {
        e[i] = shadows[i].clear;
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
) -> (Vec<Vec3>, ShadowCounts, Vec<PointShadows>) {
    let n = points.len();
    let per = samples as usize;
    let mut found = vec![PointShadows::default(); n];
    let mut pending = Pending::default();
    // Samples on static lights: (slot, contribution, ray).
    let mut probes: Vec<(usize, Vec3, Ray)> = Vec::new();
    for (i, point) in points.iter().enumerate() {
        let mut sampler = PointSampler::new(ctx, point, samples);
        for s in 0..samples {
            let Some(drawn) = sampler.sample(ctx, s) else {
                continue;
            };
            let slot = i * per + s as usize;
            if !blockers.is_static(drawn.source) {
                // Drawn again every frame, also where the light cannot
                // reach the point now: it may later.
                found[i].moving |= 1 << s;
                if let Some((c, ray)) = drawn.lit {
                    pending.push(ray, slot, c);
                }
            } else if let Some((c, ray)) = drawn.lit {
                probes.push((slot, c, ray));
            }
        }
    }
    let rays: Vec<Ray> = probes.iter().map(|p| p.2).collect();
    let (by_static, by_any) = static_and_any_blocked(ctx, blockers, &rays);
    let mut slots = vec![Vec3::ZERO; n * per];
    let mut static_slots = vec![Vec3::ZERO; n * per];
    for (k, &(slot, c, ray)) in probes.iter().enumerate() {
        if !by_static[k] {
            static_slots[slot] = c;
            let open = OpenSample {
                sample: (slot % per) as u32,
                c,
                dir: ray.dir(),
            };
            debug_assert_eq!(open.ray(&points[slot / per]), ray);
            found[slot / per].open.push(open);
        }
        if !by_any[k] {
            slots[slot] = c;
        }
    }
    let traced = probes.len() as u64 + pending.fill_unoccluded(ctx, &mut slots);
    for (f, clear) in found.iter_mut().zip(sum_slots(&static_slots, samples)) {
        f.clear = clear;
    }
    (
        sum_slots(&slots, samples),
        ShadowCounts { traced, kept: 0 },
        found,
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
fn static_and_any_blocked(
    ctx: &FrameContext,
    blockers: &ShadowBlockers,
    rays: &[Ray],
) -> (Vec<bool>, Vec<bool>) {
    let mut by_any = vec![false; rays.len()];
    ctx.backend.any_hit(rays, &mut by_any);
    let by_static = rays
        .iter()
        .zip(&mut by_any)
        .map(|(ray, any)| {
            if !blockers.segment_may_hit(ray.origin(), ray.at(ray.tmax)) {
                return *any;
            }
            let stopped = blockers.static_blocks(ray);
            // A static blocker stops it whatever moves: so it is in every
            // later frame's kept answer, and so it is in this one's.
            *any |= stopped;
            stopped
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

    /// The exact merge of per-sample bits lies between the two bounds the
    /// paper's formula averages, for every pair of bit sets of 6 samples.
    #[test]
    fn the_exact_merge_lies_between_the_bounds_the_paper_averages() {
        let n = 6u32;
        for s in 0u64..64 {
            for d in 0u64..64 {
                let frac = |bits: u64| bits.count_ones() as f32 / n as f32;
                let (ts, td, exact) = (frac(s), frac(d), frac(s | d));
                assert!(ts.max(td) <= exact + 1e-6 && exact <= (ts + td).min(1.0) + 1e-6);
                let paper = paper_merge(ts, td);
                assert!((paper - exact).abs() <= ((ts + td).min(1.0) - ts.max(td)) / 2.0 + 1e-6);
            }
        }
    }
}
