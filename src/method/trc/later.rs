//! A record's life checked against the frames after t0+1, where the known
//! animation departs from the motion its τ extrapolates. A departure from
//! TRC, named in the parent module's documentation.
//!
//! The paper estimates E(t0+1) by reprojection (§4.7) and takes the change
//! to go on at that rate: K is used while `|τ − 1|(t − t0) ≤ a^t` (Eq. 9–10).
//! What happens after t0+1 it cannot see. An object at rest at t0 that
//! starts moving or jumps later, one that stops or turns back, a light
//! switched on, off or moved later: the records that saw it keep its old light
//! until their temporal weight or δt_max ends their life (in
//! `tests/data/scenes/block_jumps.gltf` a block bias 3.5× `ic`'s for the
//! rest of δt_max: `benches/RESULTS.md`, "Records checked against the
//! later frames").
//!
//! The whole animation is known ahead (the paper's own premise for t0+1:
//! "the transformation matrix … at time t+1 is known", §5). So at its
//! creation a record is also reprojected, exactly as for t0+1, to each
//! later frame of its life where the motion departs from the extrapolated
//! one by more than its hemisphere resolves, and its life ends before the
//! first such frame where its reprojected irradiance is more than `a^t`
//! from what the record shows there (Eq. 10's bound, with the change
//! itself in place of its extrapolation: against E(t0), or with
//! extrapolated gradients E(t0) carried on by them, whose overshoot where
//! the change turns counts as a change missed does). A frame departs for
//! a record when
//! - an object it sees lies more than half a hemisphere cell, as seen
//!   from the record, from where the object's t0→t0+1 motion, continued
//!   (translation, turn and scale each at its own rate, as keyframes
//!   interpolate), would have taken it; or
//! - the lights have changed since t0 where they stayed from t0 to t0+1,
//!   or, where they moved, their power has (switched off, on or dimmed):
//!   lights moving at t0 keep the paper's extrapolation otherwise, but the
//!   frames an object departs in are reprojected with the lights then.
//!
//! An object none of the samples hit that comes into their paths is seen
//! by no reprojection; [`crate::method::arrivals`] ends those lives, and
//! those where an object the samples hit covers more of the view by over
//! `a_t` (it jumped nearer, or grew).
//!
//! Where lights move and `next_direct` evaluates the samples' direct light
//! at t0+1, it is evaluated at the end of the life too, and where the
//! change there exceeds `a_t`, between ([`LitFrames`]): the shadows the
//! lights move on are seen, as at t0+1.
//!
//! Limits: an object that a few samples hit and that then grows or comes
//! nearer by less is followed through those samples alone (the other
//! cells it comes to cover keep what they saw, as for t0+1); shadows that
//! moving objects cast later over what the record sees are not seen (as
//! for t0+1 without `next_direct`), nor a moving light's change that
//! comes and goes within the life; the gate's half cell is the cells'
//! mean size, and cells near the normal are narrower in φ, and the
//! object's nearest hit is taken at t0 (one that comes nearer turns by
//! more than its displacement over that distance); and a life longer than
//! [`LATER_FRAMES`] frames is checked over its first frames only.

use super::direct::LaterGeometry;
use super::estimate::{rigid_motion, NextFrame, Reprojection};
use crate::cache::gather::{HemisphereSamples, Strata};
use crate::method::arrivals::{moving_bounds, Arrivals, OwnBounds};
use crate::method::unshadowed::{LightsByFrame, UnshadowedLights};
use crate::method::FrameContext;
use crate::sampling::Frame;
use crate::scene::Scene;
use glam::{Mat4, Quat, Vec3};
use std::collections::BTreeMap;
use std::f32::consts::TAU;
use std::sync::{Arc, OnceLock};

/// The longest life the check covers (`δt_max` may be up to 100,000): a
/// longer one is checked over its first `LATER_FRAMES` frames, and is the
/// paper's beyond.
pub(super) const LATER_FRAMES: u32 = 64;

/// The frames t0+2 … after frame t0 (the frame whose records are being
/// made) that depart from the extrapolated motion somewhere.
pub(super) struct LaterFrames {
    t0: u32,
    /// By frame, those where something departs.
    frames: BTreeMap<u32, LaterFrame>,
    /// Which objects move.
    dynamic: Vec<bool>,
    /// The moving objects in the frames of the life, for those that come
    /// into the samples' paths.
    arrivals: Arrivals,
    /// Where lights move and `next_direct` evaluates the direct light at
    /// t0+1: the frames of the life after it, to evaluate it there too.
    lit: Option<LitFrames>,
}

/// The frames t0+2 … of a life under lights that move, where a record's
/// samples' direct light is evaluated again, with its shadows, as
/// `next_direct` evaluates it at t0+1: the record's change there is
/// checked against `a_t` at the end of the life τ gives it and, where it
/// exceeds it, by bisection for the last frame that does not. The
/// paper's extrapolation takes shadows to move on at their t0→t0+1 rate;
/// a light sinking to the horizon lengthens them ever faster, and the
/// records that saw an edge still far at t0 kept their light until their
/// life ran out (block bias 3.3× `ic`'s at the last frame of
/// `tests/trc.rs::a_swinging_light_moves_the_shadows_the_records_see`).
/// A change that comes and goes between t0+1 and the life's end is not
/// seen, as the paper's own rule does not see it.
struct LitFrames {
    /// By frame: the objects' motion from t0 and the lights then, and
    /// what the reprojection there needs, built on the first record that
    /// asks for it.
    frames: BTreeMap<u32, LitFrame>,
}

/// One frame of [`LitFrames`].
struct LitFrame {
    /// Per object, its rigid motion from t0 (`None`: it stays).
    motion: Vec<Option<Mat4>>,
    /// The lights then.
    lights: Arc<UnshadowedLights>,
    /// The direct light's geometry then, as an earlier frame's check made
    /// it ([`Ahead`] holds it).
    held: Option<Arc<LaterGeometry>>,
    /// The reprojection's input, with the direct light's geometry then
    /// (built once, by the first record whose check reaches the frame).
    next: OnceLock<Option<NextFrame>>,
}

impl LitFrames {
    /// The direct light's geometry, by frame, of the frames some record's
    /// check reached.
    fn geometries(&self) -> Vec<(u32, Arc<LaterGeometry>)> {
        (self.frames.iter())
            .filter_map(|(&t, f)| Some((t, f.next.get()?.as_ref()?.later_geometry()?.clone())))
            .collect()
    }

    /// The last frame from `last_valid` back to t0+1 where `record`'s
    /// samples, reprojected with their direct light evaluated again, do not
    /// `exceed` the temporal accuracy: `last_valid` itself where they do
    /// not there (or at the last frame kept, for a longer life), else
    /// found by bisection (t0+1 is known to be within it).
    fn last_valid(
        &self,
        ctx: &FrameContext,
        next: &NextFrame,
        record: &Reprojection,
        last_valid: u32,
        exceed: impl Fn(u32, &HemisphereSamples) -> bool,
    ) -> u32 {
        let exceeds = |t: u32| {
            self.frames.get(&t).is_some_and(|f| {
                let next = f.next.get_or_init(|| {
                    let at_t = (f.motion.clone(), f.lights.clone());
                    next.later_lit(ctx, t, at_t, f.held.as_ref())
                });
                next.as_ref().is_some_and(|n| exceed(t, &record.to(ctx, n)))
            })
        };
        // A life past the frames kept ([`LATER_FRAMES`]) is checked at the
        // last of them.
        let t1 = ctx.frame + 1;
        let end = self
            .frames
            .keys()
            .next_back()
            .map_or(t1, |&t| last_valid.min(t));
        if end <= t1 || !exceeds(end) {
            return last_valid;
        }
        let (mut within, mut beyond) = (t1, end);
        while beyond - within > 1 {
            let mid = within + (beyond - within) / 2;
            if exceeds(mid) {
                beyond = mid;
            } else {
                within = mid;
            }
        }
        within
    }
}

/// A frame after t0+1 where the motion departs from the extrapolated one.
struct LaterFrame {
    /// The objects' motion from t0 and the lights at t0 and then: the
    /// reprojection's input.
    next: NextFrame,
    /// Per object, how far (world units) its bounding box lies from where
    /// its t0→t0+1 motion, continued, would have taken it; 0 for an object
    /// that never moves.
    departure: Vec<f32>,
    /// The lights differ from t0's, where they stayed from t0 to t0+1; or
    /// their power does, where they moved.
    lights_changed: bool,
}

impl LaterFrames {
    /// Holds the direct light's geometry of the later frames the records'
    /// checks reached in `ahead`, for the next frames' checks (letting go
    /// of all where they check none: no light moves).
    pub(super) fn hold_lit_geometry(&self, ahead: &mut Ahead) {
        match &self.lit {
            Some(lit) => ahead.lit.extend(lit.geometries()),
            None => ahead.lit.clear(),
        }
    }

    /// The frames after `ctx.frame + 1` in a life of `max_life` frames
    /// from `ctx.frame` (at most [`LATER_FRAMES`]), `next` its view of
    /// `ctx.frame + 1`; `ahead` keeps the later frames' transforms and
    /// lights from frame to frame.
    pub(super) fn new(
        ctx: &FrameContext,
        next: &NextFrame,
        max_life: u32,
        ahead: &mut Ahead,
    ) -> Self {
        let (scene, t0) = (ctx.scene, ctx.frame);
        let dynamic = ctx.scene.dynamic_objects();
        let last = t0.saturating_add(max_life.min(LATER_FRAMES).saturating_sub(1));
        ahead.keep(t0 + 1..=last);
        let lights_move = lights_may_move(scene);
        let mut later = LaterFrames {
            t0,
            frames: BTreeMap::new(),
            dynamic,
            arrivals: Arrivals::default(),
            lit: None,
        };
        if last <= t0 || (!lights_move && !later.dynamic.contains(&true)) {
            return later;
        }
        let x0 = &ctx.snapshot.object_to_world;
        let own = ahead.bounds(scene, &later.dynamic).to_vec();
        let placed: Vec<_> = (t0 + 1..=last).map(|t| ahead.placed(ctx, t)).collect();
        later.arrivals = Arrivals::new(t0, &own, x0, placed.iter().map(|x| &x[..]));
        if last < t0 + 2 {
            return later;
        }
        let check_lit = next.lights_move() && next.evaluates_direct();
        let mut lit = BTreeMap::new();
        let x1 = &placed[0];
        let mut extrapolated: Vec<Option<Extrapolated>> = own
            .iter()
            .enumerate()
            .map(|(o, own)| Some(Extrapolated::new((*own)?.corners, x0[o], x1[o])))
            .collect();
        for t in t0 + 2..=last {
            let xt = ahead.placed(ctx, t);
            let departure: Vec<f32> = extrapolated
                .iter_mut()
                .zip(xt.iter())
                .map(|(e, &xt)| e.as_mut().map_or(0.0, |e| e.departure(xt, t - t0)))
                .collect();
            let (lights, lights_changed) = ahead.lights_changed(ctx, next, t, lights_move);
            let motion = || motion_since(x0, &xt, &later.dynamic);
            if check_lit {
                let frame = LitFrame {
                    motion: motion(),
                    lights: lights.clone(),
                    held: ahead.lit.get(&t).filter(|g| g.is_at(ctx, t)).cloned(),
                    next: OnceLock::new(),
                };
                lit.insert(t, frame);
            }
            if lights_changed || departure.iter().any(|&d| d > 0.0) {
                let frame = LaterFrame {
                    next: NextFrame::later(motion(), (next.lights_now().clone(), lights)),
                    departure,
                    lights_changed,
                };
                later.frames.insert(t, frame);
            }
        }
        later.lit = check_lit.then_some(LitFrames { frames: lit });
        later
    }

    /// The last frame, up to `last_valid` (Eq. 10–11's), that the gather
    /// of `record` (made at t0) may be used in: the frame before the first
    /// later frame where more than `a_t` of its samples' paths are crossed
    /// by an object none of them hit ([`Arrivals::share`]), or that departs
    /// from τ's extrapolation as the gather sees it and where its samples,
    /// reprojected there, `exceed` the temporal accuracy.
    pub(super) fn last_valid(
        &self,
        ctx: &FrameContext,
        next: &NextFrame,
        record: &Reprojection,
        a_t: f32,
        last_valid: u32,
        exceed: impl Fn(u32, &HemisphereSamples) -> bool,
    ) -> u32 {
        let last = self.last_departed(ctx, record, a_t, last_valid, &exceed);
        match &self.lit {
            Some(lit) => lit.last_valid(ctx, next, record, last, exceed),
            None => last,
        }
    }

    /// [`Self::last_valid`] but for lights that move on
    /// ([`LitFrames`]): the arrivals and the frames that depart.
    fn last_departed(
        &self,
        ctx: &FrameContext,
        record: &Reprojection,
        a_t: f32,
        last_valid: u32,
        exceed: &impl Fn(u32, &HemisphereSamples) -> bool,
    ) -> u32 {
        let (g, strata) = (record.gathered(), record.strata());
        if last_valid <= self.t0 || self.arrivals.is_empty() && self.frames.is_empty() {
            return last_valid;
        }
        let seen = nearest_hits(&g.samples, &self.dynamic);
        // The moving objects no sample hit.
        let mut unseen = Vec::new();
        if !self.arrivals.is_empty() {
            unseen.clone_from(&self.dynamic);
            // The record's own object is left out by `Arrivals::share`.
            for o in seen.iter().map(|&(o, _)| o) {
                if let Some(u) = unseen.get_mut(o as usize) {
                    *u = false;
                }
            }
        }
        let cell = resolvable_angle(strata);
        let frame = Frame::new(g.candidate.point.normal);
        let pose = (&g.candidate.point, &frame);
        let is_unseen = |o: u32| unseen.get(o as usize).copied().unwrap_or(false);
        let objects = (strata, g.candidate.object, is_unseen);
        for t in self.t0 + 1..=last_valid {
            let arrivals = || (self.arrivals).share(t, pose, &g.samples, objects, a_t);
            if !unseen.is_empty() && arrivals() > a_t {
                return t - 1;
            }
            let Some(f) = self.frames.get(&t) else {
                continue;
            };
            let departs = f.lights_changed
                || seen
                    .iter()
                    .any(|&(o, nearest)| f.departure[o as usize] > cell * nearest);
            if departs && exceed(t, &record.to(ctx, &f.next)) {
                return t - 1;
            }
        }
        last_valid
    }
}

/// The frames ahead of the one rendered: each object's transform, the
/// lights and the direct light's geometry, made once while the frames that
/// look at them come by.
#[derive(Default)]
pub(super) struct Ahead {
    placed: BTreeMap<u32, Arc<Vec<Mat4>>>,
    lights: LightsByFrame,
    /// The direct light's geometry of the frames [`LitFrames`] checked
    /// (`LaterFrames::hold_lit_geometry`): each frame's is made once a
    /// render. At most [`LATER_FRAMES`] (or `δt_max`) frames, as many as
    /// one frame's checks make at once.
    pub(super) lit: BTreeMap<u32, Arc<LaterGeometry>>,
    /// Each moving object's bounds in its own frame (found once).
    bounds: Option<Vec<Option<OwnBounds>>>,
}

impl Ahead {
    fn keep(&mut self, frames: std::ops::RangeInclusive<u32>) {
        self.placed.retain(|f, _| frames.contains(f));
        self.lit.retain(|f, _| frames.contains(f));
        self.lights.keep(frames);
    }

    /// Each moving object's bounds in its own frame.
    fn bounds(&mut self, scene: &Scene, dynamic: &[bool]) -> &[Option<OwnBounds>] {
        self.bounds
            .get_or_insert_with(|| moving_bounds(scene, dynamic))
    }

    /// The lights at frame `t` (`lights_move`: some light may move or
    /// change), also where an object departs: moving lights move in the
    /// reprojection too; and whether they changed otherwise than τ's
    /// extrapolation carries them on: lights that moved from t0 to t0+1
    /// move in it, one switched off, on or dimmed later does not.
    fn lights_changed(
        &mut self,
        ctx: &FrameContext,
        next: &NextFrame,
        t: u32,
        lights_move: bool,
    ) -> (Arc<UnshadowedLights>, bool) {
        let lights = if lights_move {
            self.lights.at(ctx, t)
        } else {
            next.lights_now().clone()
        };
        let changed = match next.lights_move() {
            false => !lights.same_as(next.lights_now()),
            true => !lights.same_power(next.lights_now()),
        };
        (lights, changed)
    }

    /// Each object's world transform at frame `t`.
    fn placed(&mut self, ctx: &FrameContext, t: u32) -> Arc<Vec<Mat4>> {
        self.placed
            .entry(t)
            .or_insert_with(|| {
                let scene = ctx.scene;
                let world = scene.node_world_transforms(ctx.time_of(t));
                Arc::new(scene.objects.iter().map(|o| world[o.node]).collect())
            })
            .clone()
    }
}

/// Each moving object's motion from its world transform at t0 (`x0`) to
/// the one at a later frame (`xt`) ([`rigid_motion`]); `None` for static
/// objects and those that stay.
fn motion_since(x0: &[Mat4], xt: &[Mat4], dynamic: &[bool]) -> Vec<Option<Mat4>> {
    let motion = x0.iter().zip(xt).zip(dynamic);
    let moved =
        |((w0, wt), &d): ((&Mat4, &Mat4), &bool)| d.then(|| rigid_motion(*w0, *wt)).flatten();
    motion.map(moved).collect()
}

/// Whether any light can move or change: a punctual light the animation
/// moves or turns ([`Scene::moving_lights`]), or an emissive material on a
/// moving object.
fn lights_may_move(scene: &Scene) -> bool {
    let dynamic = scene.dynamic_nodes();
    scene.moving_lights().contains(&true)
        || scene.objects.iter().any(|object| {
            dynamic[object.node]
                && object
                    .mesh
                    .materials
                    .iter()
                    .any(|&m| scene.materials[m as usize].is_emissive())
        })
}

/// Half the angle a cell of the record's hemisphere spans (the side of a
/// square of its mean solid angle, 2π over the cell count): a
/// displacement under it mostly leaves a reprojected sample in its cell,
/// where it keeps its own value (`estimate::HemisphereGrid::keep_own_samples`).
fn resolvable_angle(strata: Strata) -> f32 {
    0.5 * (TAU / strata.count().max(1) as f32).sqrt()
}

/// Each moving object that samples of the hemisphere hit, with the
/// distance of its nearest hit: an object's displacement `d` moves it by
/// about `d / nearest` radians as the record sees it (more if it comes
/// nearer).
fn nearest_hits(samples: &HemisphereSamples, dynamic: &[bool]) -> Vec<(u32, f32)> {
    let mut nearest: Vec<(u32, f32)> = Vec::new();
    for (&object, &distance) in samples.object.iter().zip(&samples.distance) {
        if !distance.is_finite() || !dynamic.get(object as usize).copied().unwrap_or(false) {
            continue;
        }
        match nearest.iter_mut().find(|(o, _)| *o == object) {
            Some((_, d)) => *d = d.min(distance),
            None => nearest.push((object, distance)),
        }
    }
    nearest
}

/// An object's motion from t0 to t0+1, continued, two ways: its
/// translation, turn and scale each going on at the same rate (what
/// keyframes on its own node interpolate, a steady slide while turning
/// included), and the same rigid step taken again (a steady orbit, where
/// an animated parent turns it about the parent's pivot). Its departure is
/// from the nearer of the two places.
struct Extrapolated {
    corners: [Vec3; 8],
    x0: Mat4,
    /// `None`: it stays where it was from t0 to t0+1.
    rates: Option<Rates>,
    /// The rigid step taken `k` times, `(k, stepᵏ · x0)`: the frames are
    /// asked for in order, so each costs one product, not `k`.
    stepped: (u32, Mat4),
}

/// Per frame: the change of scale, the turn (axis, angle) and the shift;
/// and the whole step, `x1 · x0⁻¹`.
struct Rates {
    scale: (Vec3, Vec3),
    rotation: (Quat, Vec3, f32),
    translation: (Vec3, Vec3),
    step: Mat4,
}

impl Extrapolated {
    fn new(corners: [Vec3; 8], x0: Mat4, x1: Mat4) -> Self {
        let rates = (x1 != x0).then(|| {
            let (s0, r0, p0) = x0.to_scale_rotation_translation();
            let (s1, r1, p1) = x1.to_scale_rotation_translation();
            let (axis, angle) = (r1 * r0.inverse()).to_axis_angle();
            Rates {
                scale: (s0, s1 - s0),
                rotation: (r0, axis, angle),
                translation: (p0, p1 - p0),
                step: x1 * x0.inverse(),
            }
        });
        Extrapolated {
            corners,
            x0,
            rates,
            stepped: (0, x0),
        }
    }

    /// Where each way of continuing puts it `k` frames after t0.
    fn at(&mut self, k: u32) -> [Mat4; 2] {
        let Some(r) = &self.rates else {
            return [self.x0; 2];
        };
        let (r0, axis, angle) = r.rotation;
        let f = k as f32;
        let by_parts = Mat4::from_scale_rotation_translation(
            r.scale.0 + r.scale.1 * f,
            Quat::from_axis_angle(axis, angle * f) * r0,
            r.translation.0 + r.translation.1 * f,
        );
        if self.stepped.0 > k {
            self.stepped = (0, self.x0);
        }
        while self.stepped.0 < k {
            self.stepped = (self.stepped.0 + 1, r.step * self.stepped.1);
        }
        [by_parts, self.stepped.1]
    }

    /// How far its box placed by `xt`, `k` frames after t0, lies from
    /// where its motion continued takes it: the largest distance of a
    /// corner, from the nearer of the two places. Infinite where neither
    /// place is a transform (an object scaled to nothing at t0) and `xt`
    /// is not `x0`.
    fn departure(&mut self, xt: Mat4, k: u32) -> f32 {
        let places = self.at(k);
        let from = |predicted: Mat4| {
            self.corners
                .iter()
                .map(|&c| {
                    xt.transform_point3(c)
                        .distance(predicted.transform_point3(c))
                })
                .fold(0.0, f32::max)
        };
        let nearest = places
            .into_iter()
            .filter(Mat4::is_finite)
            .map(from)
            .fold(f32::INFINITY, f32::min);
        if nearest.is_finite() || xt != self.x0 {
            nearest
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::gather::GatherPoint;
    use crate::method::ic::Candidate;
    use crate::method::trc::direct::ShadowGeometry;
    use crate::method::trc::{Gathered, NextDirect, TemporalRadianceCaching, TrcSettings};
    use crate::method::Method;
    use rayon::iter::ParallelIterator;
    use std::sync::Weak;

    const CUBE: [Vec3; 2] = [Vec3::splat(-0.5), Vec3::splat(0.5)];

    fn at(translation: Vec3, turn: f32) -> Mat4 {
        Mat4::from_rotation_translation(Quat::from_rotation_y(turn), translation)
    }

    fn extrapolated(x0: Mat4, x1: Mat4) -> Extrapolated {
        Extrapolated::new(OwnBounds::of(&CUBE).unwrap().corners, x0, x1)
    }

    /// A steady slide while turning and growing is what the continued
    /// motion follows: no departure, however long the life.
    #[test]
    fn steady_motion_does_not_depart() {
        let place = |f: f32| {
            Mat4::from_scale_rotation_translation(
                Vec3::splat(1.0 + 0.01 * f),
                Quat::from_rotation_y(0.05 * f),
                Vec3::new(0.1 * f, 0.0, -0.02 * f),
            )
        };
        let mut e = extrapolated(place(0.0), place(1.0));
        for k in [2, 10, 19, 64] {
            let d = e.departure(place(k as f32), k);
            assert!(d < 1e-4, "k = {k}: {d}");
        }
        let still = at(Vec3::ONE, 0.3);
        assert_eq!(extrapolated(still, still).departure(still, 5), 0.0);
    }

    /// An object that an animated parent turns about the parent's pivot
    /// (a steady orbit, turning as it goes) does not depart either.
    #[test]
    fn a_steady_orbit_does_not_depart() {
        let place = |f: f32| Mat4::from_rotation_y(0.05 * f) * at(Vec3::new(1.0, 0.0, 0.0), 0.0);
        let mut e = extrapolated(place(0.0), place(1.0));
        for k in [2, 10, 40, 3] {
            let d = e.departure(place(k as f32), k);
            assert!(d < 1e-4, "k = {k}: {d}");
        }
        // Asked out of order (the steps start over), the same places.
        let mut fresh = extrapolated(place(0.0), place(1.0));
        let moved = at(Vec3::ZERO, 0.0);
        assert_eq!(e.departure(moved, 7), fresh.departure(moved, 7));
    }

    /// An object at rest from t0 to t0+1 that then moves, one that jumps,
    /// one that stops: each departs by how far it is from the
    /// extrapolated place.
    #[test]
    fn starts_jumps_and_stops_depart_by_their_displacement() {
        let rest = at(Vec3::ZERO, 0.0);
        let moved = at(Vec3::new(0.0, -2.0, 0.0), 0.0);
        assert!((extrapolated(rest, rest).departure(moved, 4) - 2.0).abs() < 1e-5);
        let sliding = |f: f32| at(Vec3::new(0.1 * f, 0.0, 0.0), 0.0);
        // Extrapolated to x = 0.5 at t0 + 5; it stayed at 0.1.
        let d = extrapolated(sliding(0.0), sliding(1.0)).departure(sliding(1.0), 5);
        assert!((d - 0.4).abs() < 1e-5, "{d}");
        // Scaled to nothing at t0: nothing to extrapolate from.
        let gone = Mat4::from_scale(Vec3::ZERO);
        assert_eq!(extrapolated(gone, gone).departure(gone, 3), 0.0);
        let mut growing = extrapolated(gone, Mat4::from_scale(Vec3::splat(0.1)));
        assert_eq!(growing.departure(gone, 3), 0.0, "still where it was");
        let grown = Mat4::from_scale(Vec3::splat(0.3));
        assert_eq!(growing.departure(grown, 3), f32::INFINITY);
    }

    /// The nearest hit of each moving object; misses and static objects
    /// are left out.
    #[test]
    fn nearest_hits_keep_each_moving_objects_nearest() {
        let samples = HemisphereSamples {
            direction: vec![Vec3::Z; 5],
            radiance: vec![Vec3::ONE; 5],
            distance: vec![3.0, 1.5, f32::INFINITY, 2.0, 0.5],
            object: vec![1, 1, u32::MAX, 2, 0],
        };
        let dynamic = [false, true, true];
        assert_eq!(nearest_hits(&samples, &dynamic), vec![(1, 1.5), (2, 2.0)]);
    }

    /// Under a moving light the records check their direct light at later
    /// frames, each in that frame's geometry (its lights, its moving
    /// objects placed). Each frame's is made once a render: held while
    /// later frames' records may check it ([`Ahead`]) and handed to their
    /// checks. Two frames on, every frame that frame 0's records checked
    /// and that is still ahead comes with the geometry frame 0 made, and a
    /// record reprojected there with it finds, bit for bit, what it finds
    /// with that frame's geometry made anew; a frame that checks none lets
    /// them go.
    #[test]
    fn a_later_frames_geometry_is_made_once_a_render() {
        // A loose temporal accuracy: lives long enough to check.
        let mut settings = TrcSettings {
            temporal_accuracy: 1.0,
            ..TrcSettings::default()
        };
        settings.ic.strata = Strata { theta: 4, phi: 12 };
        settings.ic.spp = 1;
        let mut trc = TemporalRadianceCaching::new(settings);
        let mut renderer = crate::render::test_renderer("moving-light", 16);
        // The first pass of frames 0 and 1 (aging, replacement and fill).
        renderer.with_frame_context(0, |ctx| trc.prepare_frame(ctx));
        // Weak: the test holds none of them itself.
        let made: Vec<(u32, Weak<LaterGeometry>)> = (trc.ahead.lit.iter())
            .filter(|(&t, _)| t > 2)
            .map(|(&t, g)| (t, Arc::downgrade(g)))
            .collect();
        assert!(made.len() > 1, "frame 0 checked no later frame");
        renderer.with_frame_context(1, |ctx| trc.prepare_frame(ctx));
        assert!(trc.ahead.lit.keys().all(|&t| t > 2), "a frame past held");
        renderer.with_frame_context(2, |ctx| {
            let next = NextFrame::new(ctx, NextDirect::On, &mut ShadowGeometry::default());
            let later = LaterFrames::new(ctx, &next, 20, &mut trc.ahead);
            let lit = later.lit.expect("lights move: checked");
            let point = GatherPoint {
                position: Vec3::new(0.4, 0.0, 0.6),
                normal: Vec3::Y,
                geometric_normal: Vec3::Y,
            };
            let g: Vec<Gathered> = (trc.ic)
                .gather_parallel(ctx, &[Candidate::at(point)])
                .collect();
            let strata = trc.settings.ic.strata;
            for (t, g_t) in made {
                let frame = &lit.frames[&t];
                let held = frame.held.as_ref();
                let held = held.unwrap_or_else(|| panic!("frame {t}'s not held"));
                assert!(
                    std::ptr::eq(g_t.as_ptr(), &**held),
                    "frame {t}'s made again"
                );
                let to = |held: Option<&Arc<LaterGeometry>>| {
                    let at_t = (frame.motion.clone(), frame.lights.clone());
                    let later = next.later_lit(ctx, t, at_t, held).expect("lit");
                    Reprojection::new(&g[0], strata).to(ctx, &later)
                };
                let (kept, anew) = (to(Some(held)), to(None));
                assert_eq!(kept.radiance, anew.radiance, "frame {t}");
                assert_eq!(kept.distance, anew.distance, "frame {t}");
            }
            // A frame whose records check no later frame's direct light
            // (here: none evaluated at t0+1) lets them all go.
            let next = NextFrame::new(ctx, NextDirect::Off, &mut ShadowGeometry::default());
            let later = LaterFrames::new(ctx, &next, 20, &mut trc.ahead);
            later.hold_lit_geometry(&mut trc.ahead);
            assert!(trc.ahead.lit.is_empty(), "held with nothing checked");
        });
    }
}
