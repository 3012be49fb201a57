//! The direct light at the first hits of a record's hemisphere samples, at
//! t0 and at t0+1: how the E(t0+1) estimate sees shadows move.
//!
//! TRC §5 has the shaders that rasterize a record's hemisphere at t0 output
//! "an estimate of the position and incoming lighting at time t+1 of each
//! point visible", and §4.7 estimates the outgoing radiance of the
//! reprojected points "by accounting for the rotation and displacement of
//! both objects and light sources". Moving the first hits with their
//! objects accounts for what the record sees; what lights those hits
//! changes too, most often through a moving object's shadow falling on a
//! static surface the record sees. Here each sample's one-bounce part is
//! evaluated again at t0+1: one light sample at its first hit with the
//! same random numbers at both times, its shadow ray traced in the
//! geometry of each, and the difference added to the sample's radiance.
//! The light sample's own noise then cancels wherever nothing changed.
//!
//! By default at frames after which a light moves (`TrcSettings::
//! next_direct`, `NextDirect::MovingLights`): a moving light moves the
//! shadows of static objects too, which nothing else in the estimate sees;
//! and where only objects move, at frames whose records live long
//! (`NextDirect::LongLives`, the default since `trc` revision 20), where
//! each record's estimate decides many frames. At every frame (`on`),
//! measured at 5e31e19
//! (`benches/RESULTS.md`, "The direct light at t0+1"): it lowers the E(t0+1) error of the
//! sliding-block test from 27.5 % to 22.6 % in mean, and `trc`'s frame
//! error on cube-in-box (400 frames) by 3.7 % for 12 % more time, but costs
//! 15 % on `moving-light` and 48 % on `spheres` (two shadow rays a sample
//! through 63,000 moving triangles) for no gain there.

use super::Gathered;
use crate::accel::{Instances, MovingObjects, StaticGeometry, TriangleBvh};
use crate::backend::{Hit, Ray};
use crate::integrator::RayOffset;
use crate::light::{LightSampler, TriangleSampling};
use crate::material::Bsdf;
use crate::method::FrameContext;
use crate::sampling::streams;
use crate::sampling::{LightChoice, Rng, SampleKey};
use crate::scene::{Placing, Snapshot, Triangle};
use glam::{Mat4, Vec3};
use std::cell::OnceCell;
use std::sync::Arc;

/// The geometry the E(t0+1) estimates' shadow rays run through, kept from
/// frame to frame: the static triangles' BVH (built once a render, shared
/// with the backend's where it has one) and the moving objects' BVHs in
/// their own spaces (built once a render), placed at each time compared
/// ([`MovingObjects::placed`]). Each frame compared had a BVH over its
/// moving triangles, and a frame's was held while later records could
/// check it: on a 1,046,528-triangle ball turning under a moving light
/// the render peaked at 2.2 GB, with instances at 0.72 GB
/// (`benches/RESULTS.md`, "The moving objects traced as instances").
#[derive(Default)]
pub(super) struct ShadowGeometry {
    statics: StaticGeometry,
    moving: Option<Arc<MovingObjects>>,
}

impl ShadowGeometry {
    /// The BVHs of `ctx`'s scene's moving objects, built on first use.
    fn moving_objects(&mut self, ctx: &FrameContext) -> Arc<MovingObjects> {
        let kept = self.moving.take().filter(|m| m.are_of(ctx.scene));
        let objects = kept.unwrap_or_else(|| Arc::new(MovingObjects::of(ctx.scene)));
        self.moving = Some(objects.clone());
        objects
    }
}

/// The geometry and lights of t0 and t0+1 that the direct light at a
/// sample's first hit depends on.
pub(super) struct DirectChange {
    /// The static triangles' BVH (`None`: there are none).
    statics: Option<Arc<TriangleBvh>>,
    /// The moving objects' BVHs, which every time compared places.
    objects: Arc<MovingObjects>,
    /// The moving objects at t0 (shared with the later frames'
    /// comparisons, [`Self::to_frame`]).
    moving_now: Arc<Instances>,
    /// The frame compared with t0.
    later: Arc<LaterGeometry>,
    /// The whole snapshot of t0+1 it was made of, for the renderer to take
    /// when that frame comes ([`Self::into_later`]; `None` for the later
    /// frames' comparisons, [`Self::to_frame`]).
    later_snapshot: Option<Snapshot>,
    lights_move: bool,
}

/// A frame's geometry and lights as the direct light at a sample's first
/// hit needs them there: made once for each frame that some record checks
/// (`super::later::Ahead` holds them while a later frame's records may
/// still check that frame). Each was otherwise made again by every frame
/// whose records checked it: on a 1,046,528-triangle ball turning under a
/// moving light (camera inside its room), placing the ball's triangles
/// for the later frames and building their BVHs took 70 % of the samples
/// of `perf record` over 24 frames even with the BVHs held while their
/// frame was ahead (`benches/RESULTS.md`, "Each later frame's geometry
/// made once a render").
///
/// The frame's triangles are not held: its moving objects are traced as
/// instances of the render's one BVH of each ([`MovingObjects`]), and the
/// few triangles a sample hits are placed again when shaded
/// ([`Self::triangle`]). Its whole snapshot was held too, up to 19 frames
/// ahead: on a 261,120-triangle ball turning under a moving light, 440 MB
/// of an 888 MB peak heap (`benches/RESULTS.md`, "What a frame of
/// replacements holds at once").
pub(super) struct LaterGeometry {
    /// The frame's emitting triangles and lights
    /// ([`crate::scene::Scene::emitters_snapshot`]), which `lights`
    /// samples.
    emitters: Snapshot,
    /// Each object's transform then, as it places triangles (its normal
    /// matrix found once a frame, not for every sample shaded).
    placings: Vec<Placing>,
    /// Per object, the id of its first triangle
    /// ([`crate::scene::Scene::first_triangles`]).
    first_triangles: Vec<usize>,
    /// Its moving objects, placed.
    moving: Instances,
    lights: LightSampler,
}

impl LaterGeometry {
    /// The geometry of `snapshot`, a whole frame of `ctx`'s scene (t0+1's,
    /// which the renderer takes next), whose moving objects are `objects`.
    fn new(ctx: &FrameContext, snapshot: &Snapshot, objects: &Arc<MovingObjects>) -> Self {
        let scene = ctx.scene;
        let emitting = snapshot.emitting_triangles(&scene.materials);
        let lights = LightSampler::new(snapshot, &scene.materials).for_emitters(&emitting);
        Self::lit_by(ctx, scene.emitters_snapshot(snapshot.time), lights, objects)
    }

    /// The geometry of the frame at time `t` of `ctx`'s scene, whose
    /// moving objects are `objects`, made of its emitters alone where no
    /// directional light is: a sampler of the emitters alone then draws
    /// what that of the whole frame draws, bit for bit
    /// ([`LightSampler::for_emitters`]), and the frame's other triangles
    /// are neither placed nor read (its moving objects are instances).
    /// A directional light's power is weighed by the whole frame's bounds,
    /// so there the whole frame is placed. On a 1,046,528-triangle ball
    /// turning under a moving light, placing each later frame checked
    /// made `trc` 9–15 % slower (`benches/RESULTS.md`, "The moving
    /// objects traced as instances").
    fn at(ctx: &FrameContext, t: f32, objects: &Arc<MovingObjects>) -> Self {
        // Placed lights are the scene's, one for one, at any time.
        let directional = crate::scene::LightKind::Directional;
        if ctx.scene.lights.iter().any(|l| l.kind == directional) {
            return Self::new(ctx, &ctx.scene.snapshot_from(t, ctx.snapshot), objects);
        }
        let emitters = ctx.scene.emitters_snapshot(t);
        let lights = LightSampler::new(&emitters, &ctx.scene.materials);
        Self::lit_by(ctx, emitters, lights, objects)
    }

    /// The geometry of the frame whose emitters are `emitters`, sampled by
    /// `lights`.
    fn lit_by(
        ctx: &FrameContext,
        emitters: Snapshot,
        lights: LightSampler,
        objects: &Arc<MovingObjects>,
    ) -> Self {
        let placings = emitters.object_to_world.iter();
        LaterGeometry {
            placings: placings.map(|&w| Placing::new(w)).collect(),
            moving: objects.placed(&emitters),
            lights,
            emitters,
            first_triangles: ctx.scene.first_triangles(),
        }
    }

    /// Whether this is the geometry of frame `t` of `ctx`'s render.
    pub(super) fn is_at(&self, ctx: &FrameContext, t: u32) -> bool {
        self.emitters.time == ctx.time_of(t)
    }

    /// Triangle `id` of `ctx`'s snapshot as it lies in this frame: bit for
    /// bit this frame's snapshot's triangle `id`.
    fn triangle(&self, ctx: &FrameContext, id: u32) -> Triangle {
        let (now, id) = (ctx.snapshot, id as usize);
        if id < now.static_count {
            return now.triangles[id];
        }
        let object = now.tri_object[id] as usize;
        let index = id - self.first_triangles[object];
        (ctx.scene).place_triangle(object, index, &self.placings[object])
    }
}

/// The first hit of a record's hemisphere sample.
pub(super) struct FirstHit<'a> {
    /// The sample's index in the gather.
    pub sample: usize,
    pub hit: &'a Hit,
    /// Where it lies at t0.
    pub point: Vec3,
    /// Its object's motion to t0+1 and where that takes it; `None`: it
    /// stays.
    pub moved: Option<(Mat4, Vec3)>,
}

/// A first hit as the direct light there needs it.
#[derive(Clone, Copy)]
struct Shading {
    p: Vec3,
    ng: Vec3,
    /// Towards the record.
    wo: Vec3,
    bsdf: Bsdf,
}

/// What [`DirectChange::change`] finds for a sample at t0 and keeps for
/// every later frame it is compared with (under a moving light a record
/// is compared with t0+1, the end of its life and the frames a bisection
/// reaches): `D(t0)`, and, where the first hit lies on a static triangle
/// (the same triangle at every time, so the same shading bit for bit), the
/// hit's shading. Shading the hit again for each frame was a fifth of the
/// direct light's work on the built-in moving-light.
#[derive(Default)]
pub(super) struct SampleAtStart {
    /// One light sample's direct light, shadowed, at t0.
    direct: OnceCell<Vec3>,
    /// The first hit's shading where its triangle is static (`None`: it
    /// reflects nothing).
    still: OnceCell<Option<Shading>>,
}

impl DirectChange {
    /// `None` when nothing moves from t0 to t0+1 (no object, no light):
    /// then no sample's direct light changes.
    pub(super) fn new(
        ctx: &FrameContext,
        later: Snapshot,
        (objects_move, lights_move): (bool, bool),
        geometry: &mut ShadowGeometry,
    ) -> Option<Self> {
        if !objects_move && !lights_move {
            return None;
        }
        let objects = geometry.moving_objects(ctx);
        Some(DirectChange {
            statics: (ctx.snapshot.static_count > 0)
                .then(|| geometry.statics.of(ctx.snapshot))
                .flatten(),
            moving_now: Arc::new(objects.placed(ctx.snapshot)),
            later: Arc::new(LaterGeometry::new(ctx, &later, &objects)),
            objects,
            later_snapshot: Some(later),
            lights_move,
        })
    }

    /// The whole snapshot of t0+1, given up (`None`: this compares t0
    /// with a later frame).
    pub(super) fn into_later(self) -> Option<Snapshot> {
        self.later_snapshot
    }

    /// The geometry of the frame compared with t0.
    pub(super) fn later(&self) -> &Arc<LaterGeometry> {
        &self.later
    }

    /// The geometry of frame `t`, a later frame to compare t0 with
    /// ([`Self::to_frame`]).
    pub(super) fn geometry_at(&self, ctx: &FrameContext, t: u32) -> LaterGeometry {
        LaterGeometry::at(ctx, ctx.time_of(t), &self.objects)
    }

    /// The same comparison from t0 to the later frame `later`
    /// (`super::later`'s check of moving lights): t0's side and the static
    /// geometry are shared.
    pub(super) fn to_frame(&self, later: Arc<LaterGeometry>) -> Self {
        DirectChange {
            statics: self.statics.clone(),
            objects: self.objects.clone(),
            moving_now: self.moving_now.clone(),
            later,
            later_snapshot: None,
            lights_move: true,
        }
    }

    /// `D(t0+1) − ratio·D(t0)` for the sample of `g` whose first hit is
    /// `at`: `D` one light sample's direct light reflected by the hit
    /// towards the record, shadowed in the geometry of its time. `ratio` is
    /// what the caller scaled the whole sample by for moving lights
    /// (`estimate::light_change`'s ratio): the direct part it scaled is
    /// replaced by `D(t0+1)`. `start` keeps `D(t0)` once found, and the
    /// shading of a hit on a static triangle: every comparison from t0
    /// ([`Self::to_frame`]) finds the same.
    pub(super) fn change(
        &self,
        ctx: &FrameContext,
        g: &Gathered,
        at: &FirstHit,
        (ratio, start): (Vec3, &SampleAtStart),
    ) -> Vec3 {
        let choice = self.light_choice(ctx, g, at.sample);
        if at.moved.is_none() && !self.lights_move {
            return self.shadow_change(ctx, g, at, choice);
        }
        let lit = |sample: Option<(Ray, Vec3)>, t: usize| {
            sample.map_or(Vec3::ZERO, |(ray, d)| {
                if self.occluded(&ray, t) {
                    Vec3::ZERO
                } else {
                    d
                }
            })
        };
        let at_start = || {
            let tri = &ctx.snapshot.triangles[at.hit.triangle as usize];
            shading(ctx, tri, at.hit, at.point, g.record.position)
        };
        let still = (at.hit.triangle as usize) < ctx.snapshot.static_count;
        let kept = still.then(|| *start.still.get_or_init(at_start));
        let before = *start.direct.get_or_init(|| {
            let s = kept.unwrap_or_else(at_start);
            lit(
                s.and_then(|s| unoccluded(ctx.snapshot, ctx.lights, ctx.ray_offset, &s, choice)),
                0,
            )
        });
        let later = &self.later;
        let s = kept.unwrap_or_else(|| {
            let p1 = at.moved.map_or(at.point, |(_, p)| p);
            let tri = later.triangle(ctx, at.hit.triangle);
            shading(ctx, &tri, at.hit, p1, g.record.position)
        });
        let after =
            s.and_then(|s| unoccluded(&later.emitters, &later.lights, ctx.ray_offset, &s, choice));
        lit(after, 1) - ratio * before
    }

    /// [`Self::change`] for a hit that stays under lights that stay: the
    /// same shadow ray at both times, so only moving objects on it can
    /// change what it sees. The hit is shaded only where they do (most
    /// samples' rays cross no moving object at either time).
    fn shadow_change(
        &self,
        ctx: &FrameContext,
        g: &Gathered,
        at: &FirstHit,
        choice: LightChoice,
    ) -> Vec3 {
        let snapshot = ctx.snapshot;
        let tri = &snapshot.triangles[at.hit.triangle as usize];
        let ng = tri.geometric_normal();
        let Some(ls) = ctx
            .lights
            .sample(snapshot, at.point, choice, TriangleSampling::Area)
        else {
            return Vec3::ZERO;
        };
        let sign = self.visibility_change(&Ray::segment(
            ctx.ray_offset.origin(at.point, ng, ls.wi),
            ls.position,
        ));
        if sign == 0.0 {
            return Vec3::ZERO;
        }
        shading(ctx, tri, at.hit, at.point, g.record.position)
            .and_then(|s| unoccluded(snapshot, ctx.lights, ctx.ray_offset, &s, choice))
            .map_or(Vec3::ZERO, |(_, d)| sign * d)
    }

    /// The light sample of sample `i` of `g`: the same random numbers at
    /// t0 and t0+1, a stream of the record's own keyed with the frame
    /// (which its gather's streams are not).
    fn light_choice(&self, ctx: &FrameContext, g: &Gathered, i: usize) -> LightChoice {
        let mut rng = Rng::new(SampleKey {
            seed: ctx.seed,
            frame: Some(ctx.frame),
            item: streams::RECORD | g.candidate.stream,
            sample: i as u32,
        });
        LightChoice {
            pick: rng.next_f32(),
            u: rng.next_2d(),
        }
    }

    /// +1 where `ray` is blocked at t0 and clear at t0+1, −1 the other way
    /// round, 0 where nothing changed.
    fn visibility_change(&self, ray: &Ray) -> f32 {
        let blocked = |t: usize| self.moving(t).occludes(ray);
        let (before, after) = (blocked(0), blocked(1));
        if before == after || self.statics.as_ref().is_some_and(|b| b.occludes(ray)) {
            0.0
        } else if before {
            1.0
        } else {
            -1.0
        }
    }

    /// The moving objects at t0 (`t` = 0) or t0+1 (`t` = 1).
    fn moving(&self, t: usize) -> &Instances {
        match t {
            0 => &self.moving_now,
            _ => &self.later.moving,
        }
    }

    /// Whether `ray` is blocked at t0 (`t` = 0) or t0+1 (`t` = 1).
    fn occluded(&self, ray: &Ray, t: usize) -> bool {
        self.moving(t).occludes(ray) || self.statics.as_ref().is_some_and(|b| b.occludes(ray))
    }
}

/// The first hit `hit` (on `tri`, triangle `hit.triangle` as it lies at
/// the time shaded) at `p`, seen from the record at `record`; `None` where
/// it reflects nothing.
fn shading(
    ctx: &FrameContext,
    tri: &Triangle,
    hit: &Hit,
    p: Vec3,
    record: Vec3,
) -> Option<Shading> {
    let material = ctx.snapshot.tri_material[hit.triangle as usize];
    let material = &ctx.scene.materials[material as usize];
    let wo = (record - p).normalize_or_zero();
    let bsdf = Bsdf::new(material, tri.shading_normal(hit.u, hit.v), wo);
    (!bsdf.is_black()).then(|| Shading {
        p,
        ng: tri.geometric_normal(),
        wo,
        bsdf,
    })
}

/// One light sample's direct light at `s` towards the record, unshadowed,
/// and its shadow ray, leaving `s` by `offset`. Points on area lights are drawn by area, as at the
/// vertices of the gather's paths.
fn unoccluded(
    snapshot: &Snapshot,
    lights: &LightSampler,
    offset: RayOffset,
    s: &Shading,
    choice: LightChoice,
) -> Option<(Ray, Vec3)> {
    let ls = lights.sample(snapshot, s.p, choice, TriangleSampling::Area)?;
    let cos = s.bsdf.normal().dot(ls.wi);
    let f = s.bsdf.eval(s.wo, ls.wi);
    if cos <= 0.0 || f.max_element() <= 0.0 {
        return None;
    }
    let ray = Ray::segment(offset.origin(s.p, s.ng, ls.wi), ls.position);
    Some((ray, f * ls.radiance * (cos / ls.pdf)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::test_renderer;

    /// A later frame's triangles placed one at a time as samples are
    /// shaded ([`LaterGeometry::triangle`]) are, bit for bit, that frame's
    /// whole snapshot's, static and moving, on scenes whose objects move
    /// (cube-in-box's cube, the bouncing spheres), three frames ahead.
    #[test]
    fn a_later_frames_triangles_placed_alone_are_its_snapshots() {
        for name in ["cube-in-box", "spheres"] {
            let mut renderer = test_renderer(name, 4);
            renderer.with_frame_context(1, |ctx| {
                let later = ctx.scene.snapshot(ctx.time_of(4));
                let objects = Arc::new(MovingObjects::of(ctx.scene));
                let geometry = LaterGeometry::new(ctx, &later, &objects);
                assert!(
                    later.dynamic_count() > 0 && later.static_count > 0,
                    "{name}"
                );
                let mut moved = 0;
                for (id, tri) in later.triangles.iter().enumerate() {
                    let alone = geometry.triangle(ctx, id as u32);
                    assert_eq!(format!("{alone:?}"), format!("{tri:?}"), "{name}: {id}");
                    moved += (alone.p != ctx.snapshot.triangles[id].p) as usize;
                }
                assert!(moved > 0, "{name}: nothing moved");
            });
        }
    }

    /// A later frame's geometry made of its emitters alone samples its
    /// lights as that made of the whole frame, bit for bit, and places
    /// its objects alike; with a directional light (weighed by the whole
    /// frame's bounds) it is made of the whole frame.
    #[test]
    fn a_later_frames_geometry_from_its_emitters_is_the_whole_frames() {
        let sun = crate::scene::PunctualLight {
            name: "sun".into(),
            node: 0,
            intensity: glam::Vec3::splat(2.0),
            kind: crate::scene::LightKind::Directional,
        };
        for (name, with_sun) in [
            ("moving-light", false),
            ("spheres", false),
            ("cube-in-box", true),
        ] {
            let mut scene = crate::scene::Scene::builtin(name).unwrap();
            if with_sun {
                scene.lights.push(sun.clone());
            }
            let mut renderer = crate::render::Renderer::new(
                scene,
                Box::new(crate::method::path::PathTracer::new(Default::default())),
                Box::new(crate::backend::cpu::CpuBackend::new()),
                crate::render::FrameSettings {
                    width: 4,
                    height: 4,
                    ..Default::default()
                },
            );
            renderer.with_frame_context(1, |ctx| {
                let objects = Arc::new(MovingObjects::of(ctx.scene));
                for t in [2, 5, 9] {
                    let time = ctx.time_of(t);
                    let alone = LaterGeometry::at(ctx, time, &objects);
                    let whole = LaterGeometry::new(ctx, &ctx.scene.snapshot(time), &objects);
                    let debug = |g: &LaterGeometry| format!("{:?}", g.lights);
                    assert_eq!(debug(&alone), debug(&whole), "{name}, frame {t}");
                    assert!(alone.is_at(ctx, t) && whole.is_at(ctx, t));
                    assert_eq!(
                        alone.moving.placed_transforms(),
                        whole.moving.placed_transforms(),
                        "{name}, frame {t}"
                    );
                    assert!(alone.lights.emitting_triangles().count() > 0 || with_sun);
                }
            });
        }
    }

    /// The moving objects' BVHs are built once a render, and each frame
    /// compared places them: t0+1's and the next frame's t0 are the same
    /// transforms.
    #[test]
    fn the_moving_objects_bvhs_are_built_once_a_render() {
        let mut renderer = test_renderer("cube-in-box", 4);
        let mut geometry = ShadowGeometry::default();
        let mut at = |frame: u32| {
            renderer.with_frame_context(frame, |ctx| {
                let later = ctx.scene.snapshot(ctx.time_of(frame + 1));
                let change = DirectChange::new(ctx, later, (true, false), &mut geometry);
                let change = change.expect("the cube moves");
                let transforms = |i: &Instances| i.placed_transforms();
                (
                    change.objects.clone(),
                    transforms(change.moving(0)),
                    transforms(change.moving(1)),
                )
            })
        };
        let (objects_0, _, next_0) = at(0);
        let (objects_1, now_1, next_1) = at(1);
        assert!(Arc::ptr_eq(&objects_0, &objects_1), "built again");
        assert!(!next_0.is_empty() && next_0 == now_1);
        assert_ne!(now_1, next_1, "the cube moves");
        // Another scene's objects are built for it.
        let mut other = test_renderer("spheres", 4);
        other.with_frame_context(0, |ctx| {
            assert!(!objects_1.are_of(ctx.scene));
            assert!(!Arc::ptr_eq(&geometry.moving_objects(ctx), &objects_1));
        });
    }
}
