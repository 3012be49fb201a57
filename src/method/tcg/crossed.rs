//! Samples whose path a moving object has moved into. Departure from
//! Tawara et al., whose Eq. 2 counts in `x` only the samples that hit
//! moving objects: a sample that saw the floor past the place a box now
//! stands was shot before the box came, so it is not among them, and the
//! box's indirect shadow reaches the records only as Eq. 2's `τ_min`
//! share of their samples is shot again each frame (a block that jumps
//! into a room's corner: `tests/tcg.rs`). It does not mend the lag of a
//! box that changes the light of the samples' hits (README, "Accuracy and
//! speed of `path`": penumbrae and bounced light, which no test as cheap
//! as this sees). The paper's §3.3 asks for more rays
//! "when and where lighting quickly changes"; here a sample also counts
//! in `x` where, from the record's point of this frame along its cell's
//! centre direction, its path up to its stored hit (however far, for a
//! miss) crosses the box of an object that moved since the last frame.
//! An object that moved earlier was tested in the frame it moved, and
//! with the paper's `τ_max = 1` every sample counted then was shot again
//! then. The record's own object is left out (its box holds the record's
//! point; §4.1 refreshes records on moving objects at `τ_min`). The test
//! is conservative, a box for the object, but for the centre direction:
//! a sample jittered to a box's edge may be left to `τ_min`.
//!
//! Off by default (`TcgSettings::occlusion_refresh`): it mends objects
//! that jump or appear (`tests/tcg.rs`), but under steady motion it cost
//! 1.32× the time on cube-in-box at the same error and 1.62× on
//! `spheres`, whose 66 balls cross many samples' paths every frame, with
//! a block bias 1.05× higher (`benches/RESULTS.md`).
//!
//! With it, a record a moved object now covers is dropped
//! ([`MovedObjects::buried`]): its samples shot again would see the
//! object's inside, and its neighbours' pixels would use it.

use super::TcgRecord;
use crate::backend::{Hit, Ray};
use crate::cache::gather::{cell_direction, GatherPoint, Strata};
use crate::method::motion::ObjectBoxes;
use crate::method::FrameContext;
use crate::sampling::Frame;
use glam::Vec2;

/// The boxes of the objects that moved since the last frame.
pub(super) struct MovedObjects {
    boxes: ObjectBoxes,
}

impl MovedObjects {
    /// The objects whose world transform in frame `ctx.frame` differs from
    /// the one in the frame before (`then`, [`super::Before`]); `None` in
    /// frame 0 or where none moved.
    pub(super) fn of(ctx: &FrameContext, then: Option<&super::Before>) -> Option<Self> {
        let then = &then?.transforms;
        let now = &ctx.snapshot.object_to_world;
        let moved = |object: u32| then.get(object as usize) != now.get(object as usize);
        let boxes = ObjectBoxes::new(ctx, moved);
        (!boxes.is_empty()).then_some(MovedObjects { boxes })
    }

    /// Whether each record, at its point of this frame, is buried by a
    /// moved object: the point lies in the box of a moved object other
    /// than its own, and the first surface along its normal shows its
    /// back (the record is inside, as a floor's record under a box set
    /// down on it). No pixel sees such a record, but the lookups of the
    /// pixels beside the object use it (Ward's weights have no visibility
    /// term), and shot again its samples see the object's inside: it is
    /// dropped, and `fill` makes a record where a visible point needs one.
    /// One ray a record in a moved object's box.
    pub(super) fn buried<'a>(
        &self,
        ctx: &FrameContext,
        records: impl Iterator<Item = (&'a TcgRecord, &'a GatherPoint)>,
    ) -> Vec<bool> {
        let mut buried = Vec::new();
        let (mut rays, mut tested) = (Vec::new(), Vec::new());
        for (i, (r, point)) in records.enumerate() {
            buried.push(false);
            if self
                .boxes
                .contains(point.position, Some(r.candidate.object))
            {
                let n = point.normal;
                let origin = ctx
                    .ray_offset
                    .origin(point.position, point.geometric_normal, n);
                rays.push(Ray::new(origin, n, 0.0, f32::INFINITY));
                tested.push(i);
            }
        }
        let mut hits = vec![Hit::MISS; rays.len()];
        ctx.backend.closest_hit(&rays, &mut hits);
        for ((i, hit), ray) in tested.into_iter().zip(&hits).zip(&rays) {
            let triangle = ctx.snapshot.triangles.get(hit.triangle as usize);
            buried[i] = triangle.is_some_and(|t| t.geometric_normal().dot(ray.dir()) > 0.0);
        }
        buried
    }

    /// Marks in `stale` (by cell; grown to all of them) each of record
    /// `r`'s samples whose path a moved object's box crosses, from the
    /// record's `point` of this frame with its cells laid out in `frame`,
    /// and each that hit a moving object.
    pub(super) fn mark(
        &self,
        r: &TcgRecord,
        (point, frame): &(GatherPoint, Frame),
        strata: Strata,
        stale: &mut Vec<bool>,
    ) {
        stale.resize(r.samples.len(), false);
        let own = Some(r.candidate.object);
        // Every cell's ray starts at the record's point: how far it need
        // go is found once (`MovedObjects` always holds a box).
        let far = self.boxes.reach(point.position).unwrap_or(0.0);
        for ((cell, s), stale) in (0u32..).zip(&r.samples).zip(stale.iter_mut()) {
            // Those that hit a moving object are in `x` already; marked,
            // they are drawn first too (`select::pick_cells`): else the
            // samples the paths test adds would take their draws, and an
            // object that moved away would linger in them (on `spheres`
            // the block bias rose from 0.0057 to 0.0083; 0.0060 so).
            if *stale || s.hit_dynamic() {
                *stale = true;
                continue;
            }
            let dir = cell_direction(frame, strata, cell, Vec2::splat(0.5));
            let to_hit = if s.is_miss() {
                f32::INFINITY
            } else {
                s.distance()
            };
            *stale =
                (self.boxes).ray_within_reach_may_hit(point.position, dir, to_hit.min(far), own);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::ic::Candidate;
    use crate::store::rgbe::PackedSample;
    use glam::{Mat4, Vec3};

    /// A record at the origin facing +y on object 0, with one sample per
    /// cell of `strata` at `distance` (`∞`: a miss).
    fn record(strata: Strata, distance: f32) -> (TcgRecord, (GatherPoint, Frame)) {
        let point = GatherPoint {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            geometric_normal: Vec3::Y,
        };
        let sample = match distance.is_finite() {
            true => PackedSample::pack(Vec3::ONE, distance, 1, false, 3),
            false => PackedSample::pack(Vec3::ONE, f32::INFINITY, u32::MAX, false, 3),
        };
        let record = TcgRecord {
            record: crate::cache::IrradianceRecord::flat(0, Vec3::ZERO, Vec3::ONE),
            candidate: Candidate::at(point),
            object_to_world: Mat4::IDENTITY,
            samples: vec![sample; strata.count()],
            used: true,
        };
        (record, (point, Frame::new(Vec3::Y)))
    }

    /// A small box of object `object` on cell `cell`'s centre direction, 2
    /// away: the samples that reach past it are stale, those that stop
    /// short of it or lie in other cells are not, and a box of the
    /// record's own object counts for none; a sample that hit a moving
    /// object is marked wherever the box is.
    #[test]
    fn a_sample_is_stale_where_a_moved_box_crosses_its_path() {
        let strata = Strata { theta: 4, phi: 8 };
        let cell = 13;
        let dir = cell_direction(&Frame::new(Vec3::Y), strata, cell, Vec2::splat(0.5));
        let c = 2.0 * dir;
        let boxed = |object: u32| MovedObjects {
            boxes: ObjectBoxes::of([(object, (c - Vec3::splat(0.05), c + Vec3::splat(0.05)))]),
        };
        // Record `r`'s marks under a moved box of `object`, its samples
        // `distance` away, the first of them on a moving object if
        // `dynamic`.
        let marks = |object: u32, distance: f32, dynamic: bool| {
            let (mut r, pose) = record(strata, distance);
            r.samples[0] = PackedSample::pack(Vec3::ONE, distance, 1, dynamic, 3);
            let mut stale = Vec::new();
            boxed(object).mark(&r, &pose, strata, &mut stale);
            stale
        };
        let only = |c: u32| {
            (0..strata.count() as u32)
                .map(|i| i == c)
                .collect::<Vec<_>>()
        };
        assert_eq!(marks(1, 3.0, false), only(cell));
        assert_eq!(marks(1, f32::INFINITY, false), only(cell));
        assert_eq!(marks(1, 1.5, false), only(u32::MAX));
        assert_eq!(marks(0, 3.0, false), only(u32::MAX));
        assert_eq!(marks(1, 1.5, true), only(0));
    }
}
