//! A scene's moving objects traced as instances: each object's mesh in
//! its own space under a BVH built once a render ([`MovingObjects`]), and
//! at any time a small BVH over the objects' boxes as they are placed then,
//! through which a ray is carried into each object's space
//! ([`Instances`]). For queries outside a backend that look at many times
//! at once: `trc`'s estimate of the direct light at t0+1 and at the later
//! frames its records check under a moving light. Each of those frames had
//! a BVH over its moving triangles, built and held while later records
//! could check it: up to `δt_max` of them, 2.2 GB at the peak of a render on a
//! 1,046,528-triangle turning ball (`benches/RESULTS.md`, "The moving
//! objects traced as instances").
//!
//! Instancing is exact for the rigid and affine motion the scenes have (a
//! node's transform carries its whole mesh: `Scene::place_triangle`); a
//! ray is carried into an object's space by the inverse of its transform,
//! its direction unnormalised, so that its `t` is the same in both. The
//! hits are not the bits of the same triangles placed in the world (the
//! rounding differs), so two times compared with each other are both
//! traced here.

use super::{children_crossed, to_obvhs_ray, BvhLife, TriangleBvh};
use crate::backend::Ray;
use crate::scene::{Scene, Snapshot};
use glam::{Affine3A, UVec2, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::triangle::Triangle as ObTriangle;
use std::sync::Arc;
use std::time::Duration;

/// The BVHs of a scene's moving objects ([`Scene::dynamic_objects`]),
/// each over its mesh in its own space.
pub struct MovingObjects {
    /// Per object of the scene, its BVH (`None`: it does not move, or has
    /// no triangles).
    bvhs: Vec<Option<TriangleBvh>>,
    /// Per object, its mesh's triangle count: what tells the scene these
    /// were built for ([`MovingObjects::are_of`]).
    triangle_counts: Vec<usize>,
}

impl MovingObjects {
    /// The BVHs of `scene`'s moving objects.
    pub fn of(scene: &Scene) -> Self {
        let moves = scene.dynamic_objects();
        let first = scene.first_triangles();
        let bvhs = (scene.objects.iter().enumerate())
            .map(|(o, object)| {
                if !moves[o] {
                    return None;
                }
                let mesh = &object.mesh;
                let at = |i: u32| mesh.positions[i as usize].into();
                let source: Vec<ObTriangle> = (mesh.triangles.iter())
                    .map(|&[a, b, c]| ObTriangle {
                        v0: at(a),
                        v1: at(b),
                        v2: at(c),
                    })
                    .collect();
                let id_of = |i| ((first[o] + i) as u32, o as u32);
                TriangleBvh::over(source, BvhLife::Render, id_of)
            })
            .collect();
        MovingObjects {
            bvhs,
            triangle_counts: scene
                .objects
                .iter()
                .map(|o| o.mesh.triangles.len())
                .collect(),
        }
    }

    /// Whether these are the BVHs of `scene`'s moving objects, as far as
    /// its objects' count, motion and triangle counts tell (a method
    /// renders one scene; this guards a holder handed another).
    pub fn are_of(&self, scene: &Scene) -> bool {
        let moves = scene.dynamic_objects();
        self.bvhs.len() == scene.objects.len()
            && (scene.objects.iter().enumerate()).all(|(o, object)| {
                let n = object.mesh.triangles.len();
                self.triangle_counts[o] == n && self.bvhs[o].is_some() == (moves[o] && n > 0)
            })
    }

    /// The objects placed as `snapshot` (a snapshot of their scene, of any
    /// of its kinds: only its objects' transforms are read) has them.
    pub fn placed(self: &Arc<Self>, snapshot: &Snapshot) -> Instances {
        let placed: Vec<Instance> = (self.bvhs.iter().enumerate())
            .filter_map(|(o, bvh)| {
                let to_world = Affine3A::from_mat4(*snapshot.object_to_world.get(o)?);
                Instance::new(o as u32, to_world, bvh.as_ref()?.bvh.total_aabb)
            })
            .collect();
        let boxes: Vec<Aabb> = placed.iter().map(|i| i.world_box).collect();
        let top = (!boxes.is_empty()).then(|| {
            let params = BvhLife::Frame.params(boxes.len());
            build_cwbvh(&boxes, params, &mut Duration::default())
        });
        Instances {
            objects: self.clone(),
            placed,
            top,
        }
    }
}

/// A moving object placed at some time.
struct Instance {
    object: u32,
    /// From the world into the object's own space.
    to_object: Affine3A,
    /// Around its mesh as placed, widened by [`INSTANCE_SLACK`].
    world_box: Aabb,
}

/// Relative widening of an instance's box in the world: its corners are
/// placed by its transform, rounded, and a ray through a triangle on the
/// box's face must still enter it. Far above the rounding of a transform
/// (a few ε of the coordinates); visiting an object more never changes
/// whether a ray is blocked.
const INSTANCE_SLACK: f32 = 1e-5;

impl Instance {
    /// Object `object` placed by `to_world`, its mesh in `own_box`; `None`
    /// where the transform collapses it (not invertible, or placing it
    /// past what can be traced: a snapshot collapses such triangles to a
    /// point, which no ray meets).
    fn new(object: u32, to_world: Affine3A, own_box: Aabb) -> Option<Instance> {
        let det = to_world.matrix3.determinant();
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let to_object = to_world.inverse();
        let corners = (0..8).map(|k| {
            let pick = |bit: usize, lo: f32, hi: f32| if k & bit == 0 { lo } else { hi };
            let (lo, hi) = (own_box.min, own_box.max);
            let corner = Vec3::new(
                pick(1, lo.x, hi.x),
                pick(2, lo.y, hi.y),
                pick(4, lo.z, hi.z),
            );
            to_world.transform_point3(corner)
        });
        let (lo, hi) = corners.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        });
        let slack = INSTANCE_SLACK * (hi - lo).max(lo.abs()).max(hi.abs()).max_element();
        let world_box = Aabb::new(
            Vec3A::from(lo - Vec3::splat(slack)),
            Vec3A::from(hi + Vec3::splat(slack)),
        );
        let within = |v: Vec3A| crate::scene::within_world(v.into());
        let traced = within(world_box.min) && within(world_box.max) && to_object.is_finite();
        traced.then_some(Instance {
            object,
            to_object,
            world_box,
        })
    }

    /// `ray` in the object's own space: the same `t` at the same points.
    fn carry(&self, ray: &Ray) -> Ray {
        Ray::new(
            self.to_object.transform_point3(ray.origin()),
            self.to_object.transform_vector3(ray.dir()),
            ray.tmin,
            ray.tmax,
        )
    }
}

/// A scene's moving objects as they are placed at one time.
pub struct Instances {
    objects: Arc<MovingObjects>,
    placed: Vec<Instance>,
    /// Over the placed objects' world boxes (`None`: none is placed).
    top: Option<CwBvh>,
}

/// Whether `ray`, a segment, may enter `bounds`: `false` only where the
/// box around its two ends, widened far past their rounding, misses them.
/// Most of `trc`'s shadow rays in the direct light at t0+1 pass far from
/// every moving object, and setting up the traversal of the objects' boxes
/// was most of their cost: `Instances::occludes` took 4.7 % of `trc`'s
/// samples in `perf` on cube-in-box (64×64, 200 frames), 2.8 % with this
/// test first (`benches/RESULTS.md`, "The moving objects traced as
/// instances"). Rays without an end are not turned away, nor are any with
/// NaN in them (every comparison fails).
fn segment_may_enter(ray: &Ray, bounds: &Aabb) -> bool {
    if !ray.tmax.is_finite() {
        return true;
    }
    let (o, d) = (Vec3A::from_array(ray.origin), Vec3A::from_array(ray.dir));
    let (a, b) = (o + d * ray.tmin, o + d * ray.tmax);
    // The ends are rounded; their box is widened far past that rounding
    // (by `INSTANCE_SLACK` of their largest coordinate, ~80 ulps), as the
    // instances' boxes are.
    let slack = Vec3A::splat(INSTANCE_SLACK * a.abs().max(b.abs()).max_element());
    let (lo, hi) = (a.min(b) - slack, a.max(b) + slack);
    !(lo.cmpgt(bounds.max).any() || hi.cmplt(bounds.min).any())
}

impl Instances {
    /// Whether some moving object's triangle lies on `ray`.
    pub fn occludes(&self, ray: &Ray) -> bool {
        let Some(top) = &self.top else {
            return false;
        };
        if !segment_may_enter(ray, &top.total_aabb) {
            return false;
        }
        let world = to_obvhs_ray(ray);
        let mut state = top.new_traversal(world.direction);
        let mut node;
        let mut occluded = false;
        'traversal: {
            obvhs::traverse!(
                top,
                node,
                state,
                children_crossed(node, &world, state.oct_inv4, world.tmax),
                {
                    let index = top.primitive_indices[state.primitive_id as usize];
                    let instance = &self.placed[index as usize];
                    let bvh = self.objects.bvhs[instance.object as usize].as_ref();
                    if bvh.is_some_and(|bvh| bvh.occludes(&instance.carry(ray))) {
                        occluded = true;
                        break 'traversal;
                    }
                }
            );
        }
        occluded
    }

    /// Whether no object is placed.
    pub fn is_empty(&self) -> bool {
        self.placed.is_empty()
    }

    /// Each placed object with its transform from the world into its
    /// own space (for tests).
    #[cfg(test)]
    pub fn placed_transforms(&self) -> Vec<(u32, Affine3A)> {
        self.placed
            .iter()
            .map(|i| (i.object, i.to_object))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Rng, SampleKey};
    use glam::Mat4;

    /// Segments between random points around the moving objects are blocked by
    /// the instances where, and only where, the moving triangles placed in
    /// the world (a BVH over the snapshot's own triangles) block them: on
    /// a cube that slides and turns and on 66 bouncing balls, at several
    /// times.
    #[test]
    fn instances_block_what_the_placed_moving_triangles_block() {
        for name in ["cube-in-box", "spheres"] {
            let scene = Scene::builtin(name).unwrap();
            let objects = Arc::new(MovingObjects::of(&scene));
            for (k, t) in [0.0, 0.37, 1.1].into_iter().enumerate() {
                let snapshot = scene.snapshot(t);
                let moving = snapshot.static_count..snapshot.triangles.len();
                let placed =
                    TriangleBvh::build(&snapshot, moving.clone(), BvhLife::Frame).expect("moving");
                let instances = objects.placed(&snapshot);
                assert!(!instances.is_empty() && objects.are_of(&scene));
                // Around the moving triangles, as far again each way.
                let (lo, hi) = (snapshot.triangles.range(moving.clone()))
                    .flat_map(|t| t.p)
                    .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                        (lo.min(p), hi.max(p))
                    });
                let (lo, hi) = (lo - (hi - lo), hi + (hi - lo));
                let mut rng = Rng::new(SampleKey {
                    seed: 7,
                    frame: Some(k as u32),
                    item: 0,
                    sample: 0,
                });
                let mut point = || {
                    let u = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                    lo + (hi - lo) * u
                };
                let (mut blocked, mut differ) = (0, 0);
                for _ in 0..4000 {
                    let ray = Ray::segment(point(), point());
                    let by_placed = placed.occludes(&ray);
                    blocked += by_placed as u32;
                    differ += (by_placed != instances.occludes(&ray)) as u32;
                }
                assert!(blocked > 200, "{name} at {t}: {blocked} blocked");
                assert_eq!(differ, 0, "{name} at {t}: {blocked} blocked");
            }
        }
    }

    /// An object its transform collapses (scaled to nothing) or carries
    /// past what can be traced is not placed; one turned and scaled
    /// unevenly is, around its placed corners.
    #[test]
    fn a_collapsed_object_is_not_placed() {
        let unit = Aabb::new(Vec3A::ZERO, Vec3A::ONE);
        let place = |m: Mat4| Instance::new(0, Affine3A::from_mat4(m), unit);
        assert!(place(Mat4::from_scale(Vec3::ZERO)).is_none());
        assert!(place(Mat4::from_translation(Vec3::splat(1e18))).is_none());
        assert!(place(Mat4::from_scale(Vec3::splat(f32::NAN))).is_none());
        let turned = Mat4::from_rotation_z(0.5) * Mat4::from_scale(Vec3::new(2.0, 1.0, 3.0));
        let instance = place(turned).expect("placed");
        for corner in [Vec3::ZERO, Vec3::ONE, Vec3::X, Vec3::new(1.0, 1.0, 0.0)] {
            let p = Vec3A::from(turned.transform_point3(corner));
            assert!(instance.world_box.contains_point(p), "{corner}");
            let back = instance.to_object.transform_point3(p.into());
            assert!((back - corner).length() < 1e-5, "{corner}: {back}");
        }
    }

    /// A segment that passes through a box is never turned away, also
    /// one along a face, or far from the origin;
    /// most of those that pass beside it are; rays without an end and
    /// NaNs are let through.
    #[test]
    fn segments_through_a_box_are_never_turned_away() {
        let mut rng = Rng::new(SampleKey {
            seed: 3,
            frame: None,
            item: 0,
            sample: 0,
        });
        let (mut through, mut turned_away_beside) = (0, 0);
        for far in [1.0f32, 1000.0] {
            let (lo, hi) = (
                Vec3::splat(far),
                Vec3::splat(far) + Vec3::new(0.5, 0.2, 0.1),
            );
            let bounds = Aabb::new(Vec3A::from(lo), Vec3A::from(hi));
            let mut point = |scale: f32| {
                let u = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                lo + (hi - lo) * 0.5 + (u - 0.5) * scale
            };
            for _ in 0..20_000 {
                let (a, b) = (point(2.0), point(2.0));
                let ray = Ray::segment(a, b);
                // Brute force: some point along it inside the box.
                let inside = (0..=256).any(|k| {
                    let p = ray.origin() + ray.dir() * (ray.tmax * k as f32 / 256.0);
                    p.cmpge(lo).all() && p.cmple(hi).all()
                });
                let may = segment_may_enter(&ray, &bounds);
                assert!(may || !inside, "{a} → {b} through the box at {far}");
                through += inside as u32;
                turned_away_beside += (!may) as u32;
            }
            // Along a face, from outside to outside.
            let along = |y: f32| Vec3::new(lo.x, y, lo.z + 0.05);
            let on_face = Ray::segment(along(lo.y - 1.0), along(hi.y + 1.0));
            assert!(segment_may_enter(&on_face, &bounds));
            let endless = Ray::new(Vec3::ZERO, -Vec3::ONE, 0.0, f32::INFINITY);
            assert!(segment_may_enter(&endless, &bounds));
            let nan = Ray::new(Vec3::splat(f32::NAN), Vec3::X, 0.0, 1.0);
            assert!(segment_may_enter(&nan, &bounds));
        }
        assert!(through > 1000, "{through} through");
        assert!(
            turned_away_beside > 10_000,
            "{turned_away_beside} turned away"
        );
    }
}
