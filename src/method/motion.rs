//! What moves in one frame: the bounding boxes of the moving objects and
//! which lights stay where they are. Work that only static geometry
//! decides (a shadow sample that no moving box meets, a camera ray whose
//! hit is static) is kept from frame to frame and only what a moving box
//! meets is traced again: `movies`' static shadows (Martín et al. §5, the
//! paper's shaft culling) and the render pass's still pixel samples
//! (`render_pass::StillSamples`).

use super::FrameContext;
use crate::light::LightSource;
use glam::Vec3;

/// An axis-aligned box.
pub type Aabb = (Vec3, Vec3);

/// What moves in one frame: the bounding boxes of the moving objects
/// ([`ObjectBoxes`], which it derefs to), and which lights do not move
/// (their shadow samples may be kept).
pub struct Blockers {
    moving: ObjectBoxes,
    /// Bounding box of the point and spot lights and emitting triangles
    /// that do not move (`None`: there are none).
    pub static_lights: Option<Aabb>,
    /// Whether a directional light does not turn: its shadow rays reach
    /// past the scene, so no box holds what they cross.
    pub static_directional: bool,
    static_count: usize,
    static_punctual: Vec<bool>,
    pub pick_fingerprint: u64,
    lights_still: bool,
}

impl Blockers {
    pub fn new(ctx: &FrameContext) -> Self {
        let snapshot = ctx.snapshot;
        let static_punctual: Vec<bool> = ctx.scene.moving_lights().iter().map(|m| !m).collect();
        let mut static_lights: Option<Aabb> = None;
        let mut grow = |p: Vec3| {
            let (lo, hi) = static_lights.get_or_insert((p, p));
            *lo = lo.min(p);
            *hi = hi.max(p);
        };
        for id in ctx.lights.emitting_triangles() {
            if id < snapshot.static_count {
                snapshot.triangles[id].p.into_iter().for_each(&mut grow);
            }
        }
        let mut static_directional = false;
        for (light, &fixed) in snapshot.lights.iter().zip(&static_punctual) {
            match fixed && light.is_directional() {
                true => static_directional = true,
                false if fixed => grow(light.position),
                false => {}
            }
        }
        let lights_still = static_punctual.iter().all(|&fixed| fixed)
            && (ctx.lights.emitting_triangles()).all(|id| id < snapshot.static_count);
        Blockers {
            moving: ObjectBoxes::new(ctx, |_| true),
            static_lights,
            static_directional,
            static_count: snapshot.static_count,
            static_punctual,
            pick_fingerprint: ctx.lights.pick_fingerprint(),
            lights_still,
        }
    }

    /// Whether no moving object's box may stand between `p` and the
    /// lights that do not move (none where a directional one does: its
    /// shadow rays leave every box), so that their light at `p` is what
    /// the static scene alone lets through.
    pub fn static_view_clear(&self, p: Vec3) -> bool {
        !self.static_directional
            && (self.static_lights).is_none_or(|(lo, hi)| !self.box_may_hit((lo.min(p), hi.max(p))))
    }

    /// Whether every light stands still: none moves, and none is a
    /// triangle of a moving object.
    pub fn lights_still(&self) -> bool {
        self.lights_still
    }

    pub fn is_static(&self, source: LightSource) -> bool {
        match source {
            LightSource::Triangle(id) => (id as usize) < self.static_count,
            LightSource::Punctual(i) => self.static_punctual.get(i).copied().unwrap_or(false),
        }
    }

    /// Whether no moving box meets any of a path's `segments`.
    pub fn path_clear(&self, segments: &[[Vec3; 2]]) -> bool {
        segments.iter().all(|&[a, b]| !self.segment_may_hit(a, b))
    }

    /// Whether triangle `id` belongs to an object that moves.
    pub fn is_moving_triangle(&self, id: u32) -> bool {
        id as usize >= self.static_count
    }
}

impl std::ops::Deref for Blockers {
    type Target = ObjectBoxes;

    fn deref(&self) -> &ObjectBoxes {
        &self.moving
    }
}

/// The bounding boxes of some moving objects in one frame (from the
/// frame's triangles), each with its object, for the segment tests of
/// work kept from earlier frames.
pub struct ObjectBoxes {
    pub boxes: Vec<Aabb>,
    /// The object of each box.
    objects: Vec<u32>,
    /// A BVH over `boxes` where they are many ([`BoxIndex`]).
    index: Option<BoxIndex>,
    /// The centre and half the diagonal of the box around them all;
    /// `None` where there is no box.
    around: Option<(Vec3, f32)>,
}

impl ObjectBoxes {
    /// The boxes of the moving objects that `include` takes (by object).
    pub fn new(ctx: &FrameContext, include: impl Fn(u32) -> bool) -> Self {
        let snapshot = ctx.snapshot;
        let mut boxes: Vec<Option<Aabb>> = vec![None; ctx.scene.objects.len()];
        for (tri, &object) in
            (snapshot.triangles.iter().zip(&snapshot.tri_object)).skip(snapshot.static_count)
        {
            if !include(object) {
                continue;
            }
            let b = &mut boxes[object as usize];
            for p in tri.p {
                let (lo, hi) = b.get_or_insert((p, p));
                *lo = lo.min(p);
                *hi = hi.max(p);
            }
        }
        ObjectBoxes::of(
            (0u32..)
                .zip(boxes)
                .filter_map(|(object, b)| Some((object, b?))),
        )
    }

    /// The boxes `boxes`, each with its object.
    pub fn of(boxes: impl IntoIterator<Item = (u32, Aabb)>) -> Self {
        let (objects, boxes): (Vec<u32>, Vec<Aabb>) = boxes.into_iter().unzip();
        let around = boxes
            .iter()
            .copied()
            .reduce(|(lo, hi), (l, h)| (lo.min(l), hi.max(h)))
            .map(|(lo, hi)| ((lo + hi) / 2.0, (hi - lo).length() / 2.0));
        ObjectBoxes {
            index: BoxIndex::over(&boxes),
            boxes,
            objects,
            around,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// Whether segment `a → b` may pass through a moving object.
    pub fn segment_may_hit(&self, a: Vec3, b: Vec3) -> bool {
        self.segment_may_hit_other_than(a, b, None)
    }

    /// Whether segment `a → b` may pass through a moving object other
    /// than `skip` (the one a segment starts on, whose box holds its
    /// start).
    pub fn segment_may_hit_other_than(&self, a: Vec3, b: Vec3, skip: Option<u32>) -> bool {
        let counts = |i: usize| Some(self.objects[i]) != skip;
        match &self.index {
            Some(index) => index.segment_hits(&self.boxes, a, b, counts),
            None => (self.boxes.iter().enumerate())
                .any(|(i, &bx)| counts(i) && segment_hits_box(a, b, bx)),
        }
    }

    /// Whether the ray from `origin` along unit `dir` may pass through a
    /// moving object other than `skip` before distance `t`; `t = ∞` (a ray
    /// that hit nothing) is followed as far as [`Self::reach`].
    pub fn ray_may_hit(&self, origin: Vec3, dir: Vec3, t: f32, skip: Option<u32>) -> bool {
        self.reach(origin)
            .is_some_and(|far| self.ray_within_reach_may_hit(origin, dir, t.min(far), skip))
    }

    /// How far from `origin` a ray must be followed to pass every box: to
    /// the farthest point of the box around them all, whose every point
    /// lies within the distance from `origin` to its centre plus half its
    /// diagonal, and a part in a thousand past it, for the rounding of the
    /// slab test at the end. `None` where there is no box.
    pub fn reach(&self, origin: Vec3) -> Option<f32> {
        let (centre, radius) = self.around?;
        Some(((origin - centre).length() + radius) * 1.001)
    }

    /// [`Self::ray_may_hit`] for a `t` no farther than [`Self::reach`] of
    /// `origin`, which many rays from one origin find once.
    pub fn ray_within_reach_may_hit(
        &self,
        origin: Vec3,
        dir: Vec3,
        t: f32,
        skip: Option<u32>,
    ) -> bool {
        self.segment_may_hit_other_than(origin, origin + dir * t, skip)
    }

    /// Whether point `p` lies in the box of a moving object other than
    /// `skip`.
    pub fn contains(&self, p: Vec3, skip: Option<u32>) -> bool {
        (self.boxes.iter().zip(&self.objects))
            .any(|(&(lo, hi), &o)| Some(o) != skip && lo.cmple(p).all() && p.cmple(hi).all())
    }

    /// Whether any moving object's box meets box `b`.
    pub fn box_may_hit(&self, b: Aabb) -> bool {
        self.boxes
            .iter()
            .any(|&(lo, hi)| lo.cmple(b.1).all() && b.0.cmple(hi).all())
    }
}

/// A BVH (obvhs's) over the moving objects' boxes, for the segment tests
/// that every kept link and shadow sample takes each frame: with many
/// moving objects (`spheres`' 66 balls) testing each box in turn was an
/// eighth of `movies`' time. Its nodes bound the boxes grown by a hair, so
/// that they never turn away a segment the exact slab test
/// ([`segment_hits_box`], still the test of each box) would accept: the
/// answers are those of the plain loop.
struct BoxIndex {
    bvh: obvhs::bvh2::Bvh2,
}

impl BoxIndex {
    /// Boxes up to which the plain loop is as fast.
    const MIN_BOXES: usize = 8;

    fn over(boxes: &[Aabb]) -> Option<Self> {
        if boxes.len() < Self::MIN_BOXES {
            return None;
        }
        let grown: Vec<obvhs::aabb::Aabb> = boxes
            .iter()
            .map(|&(lo, hi)| {
                // A ten-thousandth of the box's size (of a unit at least)
                // and of its coordinates: far above the rounding of the
                // two slab tests, far below any gap between objects.
                let pad = Vec3::splat(1e-4 * (hi - lo).max_element().max(1.0))
                    + 1e-4 * lo.abs().max(hi.abs());
                obvhs::aabb::Aabb::new((lo - pad).into(), (hi + pad).into())
            })
            .collect();
        let mut build_time = std::time::Duration::ZERO;
        let bvh = obvhs::bvh2::builder::build_bvh2(
            &grown,
            obvhs::BvhBuildParams::fast_build(),
            &mut build_time,
        );
        Some(BoxIndex { bvh })
    }

    /// Whether segment `a → b` meets one of `boxes` (the ones indexed)
    /// that `counts` (by index).
    fn segment_hits(
        &self,
        boxes: &[Aabb],
        a: Vec3,
        b: Vec3,
        counts: impl Fn(usize) -> bool,
    ) -> bool {
        let d = b - a;
        if !(a.is_finite() && d.is_finite() && d != Vec3::ZERO) {
            return (boxes.iter().enumerate())
                .any(|(i, &bx)| counts(i) && segment_hits_box(a, b, bx));
        }
        // `+ 0.0`: obvhs misreads −0.0 components (`accel::to_obvhs_ray`).
        let ray =
            obvhs::ray::Ray::new(a.into(), glam::Vec3A::from(d) + glam::Vec3A::ZERO, 0.0, 1.0);
        let indices = &self.bvh.primitive_indices;
        !self.bvh.ray_traverse_miss(ray, |_, i| {
            let i = indices[i] as usize;
            if counts(i) && segment_hits_box(a, b, boxes[i]) {
                0.0
            } else {
                f32::INFINITY
            }
        })
    }
}

/// Slab test of segment `a → b` against box `(lo, hi)`.
pub fn segment_hits_box(a: Vec3, b: Vec3, (lo, hi): Aabb) -> bool {
    // A segment whose bounds miss the box misses it: six comparisons turn
    // away most segments before the slab test's divisions (`trc` tests
    // tens of millions of kept path segments on cube-in-box).
    if a.min(b).cmpgt(hi).any() || a.max(b).cmplt(lo).any() {
        return false;
    }
    let d = b - a;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for axis in 0..3 {
        let (o, v) = (a[axis], d[axis]);
        if v.abs() < 1e-12 {
            if o < lo[axis] || o > hi[axis] {
                return false;
            }
            continue;
        }
        let (mut near, mut far) = ((lo[axis] - o) / v, (hi[axis] - o) / v);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        t0 = t0.max(near);
        t1 = t1.min(far);
        if t0 > t1 {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The BVH over many boxes answers every segment as testing each box
    /// in turn does, over all boxes or some: random segments among 100
    /// random boxes, segments along the axes (with −0.0 components), ones that end on a box's
    /// face or start inside one, and degenerate ones; and both answers
    /// occur.
    #[test]
    fn box_index_answers_as_the_plain_loop() {
        let mut rng = crate::sampling::Rng::from_seed(5, 0);
        let mut point = |scale: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * scale
                - Vec3::splat(scale / 2.0)
        };
        let boxes: Vec<Aabb> = (0..100)
            .map(|_| {
                let c = point(10.0);
                let h = point(1.0).abs();
                (c - h, c + h)
            })
            .collect();
        let index = BoxIndex::over(&boxes).expect("many boxes are indexed");
        let mut segments: Vec<(Vec3, Vec3)> =
            (0..4000).map(|_| (point(12.0), point(12.0))).collect();
        for &(lo, hi) in boxes.iter().take(20) {
            let (a, c) = (point(12.0), (lo + hi) / 2.0);
            segments.push((a, Vec3::new(lo.x, c.y, c.z)));
            segments.push((a, Vec3::new(c.x, hi.y, c.z)));
            segments.push((Vec3::new(c.x, c.y, hi.z + 1.0), Vec3::new(c.x, c.y, hi.z)));
            segments.push((c, point(12.0)));
            segments.push((lo, lo));
            segments.push((
                c + Vec3::new(-0.0, -0.0, 8.0),
                c + Vec3::new(-0.0, -0.0, -8.0),
            ));
        }
        let (mut hits, mut misses) = (0, 0);
        for (a, b) in segments {
            let plain = boxes.iter().any(|&bx| segment_hits_box(a, b, bx));
            assert_eq!(
                index.segment_hits(&boxes, a, b, |_| true),
                plain,
                "{a} → {b}"
            );
            // A box left out (the one a segment starts on) is left out of
            // the indexed answer as of the loop's.
            let counts = |i: usize| i % 3 != 0;
            let some =
                (boxes.iter().enumerate()).any(|(i, &bx)| counts(i) && segment_hits_box(a, b, bx));
            assert_eq!(index.segment_hits(&boxes, a, b, counts), some, "{a} → {b}");
            if plain {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(hits > 100 && misses > 100, "{hits} hits, {misses} misses");
    }

    #[test]
    fn a_segment_meets_a_box_it_crosses_and_not_one_beside_it() {
        let b = (Vec3::splat(-1.0), Vec3::splat(1.0));
        assert!(segment_hits_box(
            Vec3::new(-5.0, 0.0, 0.0),
            Vec3::new(5.0, 0.0, 0.0),
            b
        ));
        assert!(segment_hits_box(Vec3::ZERO, Vec3::new(5.0, 5.0, 5.0), b));
        assert!(!segment_hits_box(
            Vec3::new(-5.0, 2.0, 0.0),
            Vec3::new(5.0, 2.0, 0.0),
            b
        ));
        // Stops short of the box.
        assert!(!segment_hits_box(
            Vec3::new(-5.0, 0.0, 0.0),
            Vec3::new(-2.0, 0.0, 0.0),
            b
        ));
        // Parallel to a slab, inside it.
        assert!(segment_hits_box(
            Vec3::new(0.5, -5.0, 0.5),
            Vec3::new(0.5, 5.0, 0.5),
            b
        ));
    }
}
