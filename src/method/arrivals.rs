//! Objects that come into the paths of a record's samples after they
//! were shot: a departure from TRC and from Tawara et al., whose records
//! learn of a moving object only through the samples that hit it.
//!
//! An object none of a record's samples hit that comes into their paths
//! (a block that jumps in from outside the room, one that grows from
//! nothing, one that slides in from behind a wall) is in no sample: `trc`'s
//! reprojection (§4.7) moves only what the samples hit, and `tcg`'s Eq. 2
//! shoots again at `τ_max` only the samples that hit moving objects. So
//! the record keeps the light as it was. [`Arrivals::share`] is the share
//! of its samples whose path such an object's bounds newly cross: as the
//! samples are spread by the cosine, the part of the cosine-weighted
//! hemisphere the object may now cover, and the record's change were the
//! object to show a radiance as far from what it hides as the mean (what
//! it does show is unknown until gathered). An object that a few samples
//! hit counts too where the share of the view its bounding sphere covers
//! grew by more than the bound since they were shot (it jumped nearer, or
//! grew): those few samples cannot stand for all it covers now. `trc`
//! ends a record's life before the first frame where the share exceeds
//! `a^t` (`trc::later`); `tcg` drops a record where it exceeds 5 % in one
//! frame (`tcg::arrived`).
//!
//! In the room a block jumps into, `trc`'s corner bias against `path` fell
//! from 3.9× `ic`'s to 1.1× (`tests/trc.rs`,
//! `an_object_that_jumps_in_or_grows_is_seen_at_once`), `tcg`'s at the
//! jump from 3.1× to 0.3× (`tests/tcg.rs`,
//! `a_block_that_jumps_in_or_grows_is_seen_at_once`). An object whose
//! bounding sphere holds the record's point covers all of its view at
//! either frame, so its growth there is left to what its samples see.

use crate::cache::gather::{GatherPoint, HemisphereSamples, Strata};
use crate::method::motion::{segment_hits_box, Aabb};
use crate::sampling::Frame;
use crate::scene::{bounding_box, Scene};
use glam::{Mat3, Mat4, Vec3};
use std::f32::consts::{FRAC_PI_2, TAU};

/// A moving object's bounds in its own frame: its box's corners, and a
/// sphere around its vertices (a ball's is the ball, where its box's
/// would cover three times the view).
#[derive(Clone, Copy, Debug)]
pub(crate) struct OwnBounds {
    pub(crate) corners: [Vec3; 8],
    centre: Vec3,
    radius: f32,
}

impl OwnBounds {
    /// The bounds of `positions`; `None` for an object without vertices.
    pub(crate) fn of(positions: &[Vec3]) -> Option<Self> {
        let (min, max) = bounding_box(positions.iter().copied())?;
        let centre = (min + max) / 2.0;
        let radius = positions
            .iter()
            .map(|p| p.distance(centre))
            .fold(0.0, f32::max);
        let corners = std::array::from_fn(|i| {
            Vec3::new(
                if i & 1 == 0 { min.x } else { max.x },
                if i & 2 == 0 { min.y } else { max.y },
                if i & 4 == 0 { min.z } else { max.z },
            )
        });
        Some(OwnBounds {
            corners,
            centre,
            radius,
        })
    }

    /// Placed in the world by `x`; `None` where `x` is not a transform.
    fn placed(&self, x: Mat4) -> Option<Placed> {
        let corners = self.corners.map(|c| x.transform_point3(c));
        let lo = corners.iter().copied().reduce(Vec3::min)?;
        let hi = corners.iter().copied().reduce(Vec3::max)?;
        let centre = x.transform_point3(self.centre);
        let radius = self.radius * largest_stretch(Mat3::from_mat4(x));
        let finite = lo.is_finite() && hi.is_finite() && centre.is_finite() && radius.is_finite();
        finite.then_some(Placed {
            centre,
            radius,
            aabb: (lo, hi),
        })
    }
}

/// Each object's bounds in its own frame where `moving` (by object) says
/// it moves, else `None`.
pub(crate) fn moving_bounds(scene: &Scene, moving: &[bool]) -> Vec<Option<OwnBounds>> {
    let objects = scene.objects.iter().zip(moving);
    objects
        .map(|(o, &m)| OwnBounds::of(&o.mesh.positions).filter(|_| m))
        .collect()
}

/// The most `m` lengthens a vector: the longest column where they are
/// at right angles (a turn and a scale), else the Frobenius norm, which is
/// never less.
fn largest_stretch(m: Mat3) -> f32 {
    let [a, b, c] = [m.x_axis, m.y_axis, m.z_axis];
    let square = |u: Vec3, v: Vec3| u.dot(v).abs() <= 1e-4 * u.length() * v.length();
    if square(a, b) && square(b, c) && square(a, c) {
        a.length().max(b.length()).max(c.length())
    } else {
        (a.length_squared() + b.length_squared() + c.length_squared()).sqrt()
    }
}

/// An object's bounds in the world at one frame: a sphere, which turns
/// away most paths with a few products, and a box, which is nearer a
/// long object.
#[derive(Clone, Copy, Debug)]
struct Placed {
    centre: Vec3,
    radius: f32,
    aabb: Aabb,
}

impl Placed {
    /// An upper bound (near enough) on the share of the cosine-weighted
    /// hemisphere above `normal` at `p` that it covers: its sphere's
    /// `sin²α`, for the half-angle `α` the sphere subtends (a cap's
    /// projected solid angle over π, at most, where its axis is the
    /// normal); 1 from inside it, 0 where it lies wholly below the tangent
    /// plane.
    fn share(&self, p: Vec3, normal: Vec3) -> f32 {
        let to_centre = self.centre - p;
        let (d2, r2) = (to_centre.length_squared(), self.radius * self.radius);
        if d2 <= r2 {
            1.0
        } else if to_centre.dot(normal) < -self.radius {
            0.0
        } else {
            r2 / d2
        }
    }

    /// Whether the path from `p` along unit `dir` up to `distance` (∞ for
    /// a miss) may pass through the object: through its sphere, and
    /// through its box between `p` and where it leaves the sphere.
    fn crossed(&self, p: Vec3, dir: Vec3, distance: f32) -> bool {
        let to_centre = self.centre - p;
        let along = to_centre.dot(dir);
        let off2 = to_centre.length_squared() - along * along;
        let r2 = self.radius * self.radius;
        if off2 > r2 {
            return false;
        }
        let half = (r2 - off2).sqrt();
        if along + half < 0.0 || along - half > distance {
            return false;
        }
        segment_hits_box(p, p + dir * distance.min(along + half), self.aabb)
    }
}

/// The frames t0+1 … of the records made at t0: where each moving object
/// is in the frames it has moved in since t0, and where it was at t0.
#[derive(Default)]
pub(crate) struct Arrivals {
    t0: u32,
    /// By frame from t0+1 on, the bounds of each moving object placed
    /// anywhere but at t0 (only these can come into a path).
    moved: Vec<Vec<(u32, Placed)>>,
    /// By object, its bounds at t0 (`None`: it does not move).
    then: Vec<Option<Placed>>,
    /// Whether an object moves in any of the frames (found once, asked
    /// for every record).
    any_moved: bool,
}

impl Arrivals {
    /// The moving objects (`own`: their bounds, by object; `None` for one
    /// that does not move) placed by `x0` at `t0` and by each of `later`
    /// at t0+1, t0+2, … in turn.
    pub(crate) fn new<'a>(
        t0: u32,
        own: &[Option<OwnBounds>],
        x0: &[Mat4],
        later: impl Iterator<Item = &'a [Mat4]>,
    ) -> Self {
        let placed = |x: &[Mat4], o: usize| own[o]?.placed(*x.get(o)?);
        let moved: Vec<Vec<(u32, Placed)>> = later
            .map(|xt| {
                let moved = (0..own.len()).filter(|&o| xt.get(o) != x0.get(o));
                moved
                    .filter_map(|o| Some((o as u32, placed(xt, o)?)))
                    .collect()
            })
            .collect();
        Arrivals {
            t0,
            any_moved: moved.iter().any(|m| !m.is_empty()),
            moved,
            then: (0..own.len()).map(|o| placed(x0, o)).collect(),
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        !self.any_moved
    }

    /// Whether object `o`'s bounds at t0 hold `point`, within `slack`
    /// (its sphere's, the nearer of its bounds to a point on its surface).
    pub(crate) fn held_then(&self, o: u32, point: Vec3, slack: f32) -> bool {
        let then = self.then.get(o as usize).copied().flatten();
        then.is_some_and(|b| b.centre.distance(point) <= b.radius + slack)
    }

    /// The share of a record's samples (their `paths` from `point`, one in
    /// each cell of `strata` laid out in `frame` where there are as many)
    /// whose path the bounds at frame `t` of an object that none of them
    /// hit (`unseen`, asked only of the objects above the record's
    /// horizon) and that is not the record's own (`own`) cross, where they did not cross
    /// its bounds at t0. An object they hit counts too where its sphere's
    /// share of the view grew by more than `bound` since t0 (it jumped or
    /// came nearer, or grew): the few samples that hit it far away cannot
    /// stand for all it covers now. 0 where the objects' spheres cover at
    /// most `bound` of the hemisphere together, which turns away most
    /// records without testing a path; past it only the cells within each
    /// sphere's cone are tested (66 balls, each a few thousandths of a
    /// view: a few cells each).
    pub(crate) fn share(
        &self,
        t: u32,
        (point, frame): (&GatherPoint, &Frame),
        paths: &impl SamplePaths,
        (strata, own, unseen): (Strata, u32, impl Fn(u32) -> bool),
        bound: f32,
    ) -> f32 {
        let Some(moved) = (t.checked_sub(self.t0 + 1)).and_then(|i| self.moved.get(i as usize))
        else {
            return 0.0;
        };
        let p = point.position;
        let (mut near, mut covered) = (Vec::new(), 0.0);
        for &(o, placed) in moved {
            let share = placed.share(p, point.normal);
            if share <= 0.0 || o == own {
                continue;
            }
            let then = self.then.get(o as usize).copied().flatten();
            let grown = share - then.map_or(0.0, |b| b.share(p, point.normal));
            if grown > bound || unseen(o) {
                near.push((placed, then));
                covered += share;
            }
        }
        if covered <= bound {
            return 0.0;
        }
        let n = paths.count();
        let newly_crossed = |i: usize, now: &Placed, then: &Option<Placed>| {
            let (dir, distance) = paths.path(i);
            now.crossed(p, dir, distance) && !then.is_some_and(|b| b.crossed(p, dir, distance))
        };
        let mut crossed = vec![false; n];
        for (now, then) in &near {
            let mut test = |i: usize| {
                if !crossed[i] && newly_crossed(i, now, then) {
                    crossed[i] = true;
                }
            };
            if n == strata.count() {
                cone_cells(frame, strata, p, now, |cell| test(cell as usize));
            } else {
                (0..n).for_each(test);
            }
        }
        crossed.iter().filter(|&&c| c).count() as f32 / n.max(1) as f32
    }
}

/// The paths of a record's samples from its point: each one's unit
/// direction and how far it went (∞ for a miss).
pub(crate) trait SamplePaths {
    fn count(&self) -> usize;
    fn path(&self, i: usize) -> (Vec3, f32);
}

impl SamplePaths for HemisphereSamples {
    fn count(&self) -> usize {
        self.direction.len()
    }

    fn path(&self, i: usize) -> (Vec3, f32) {
        (self.direction[i], self.distance[i])
    }
}

/// Each cell of a hemisphere of `strata` (`j·N + k`, laid out in `frame`
/// as [`crate::cache::gather::cell_direction`] lays them) that a direction
/// from `p` through the sphere of `placed` may fall in: the rings its
/// cone's polar angles span, and in each the cells its azimuths do
/// (`asin(sin α / sin θ_c)` either side of its axis; all of them where the
/// cone holds the pole). A little wide, for rounding.
fn cone_cells(frame: &Frame, strata: Strata, p: Vec3, placed: &Placed, mut each: impl FnMut(u32)) {
    let (m, n) = (strata.theta, strata.phi);
    if m == 0 || n == 0 {
        return;
    }
    let to_centre = frame.to_local(placed.centre - p);
    let d = to_centre.length();
    let every_cell = 0..m * n;
    if d <= placed.radius || d == 0.0 {
        return every_cell.for_each(each);
    }
    let axis = to_centre / d;
    let alpha = (placed.radius / d).min(1.0).asin() * 1.001 + 1e-4;
    let theta = axis.z.clamp(-1.0, 1.0).acos();
    let (lo, hi) = (theta - alpha, (theta + alpha).min(FRAC_PI_2));
    if lo >= FRAC_PI_2 {
        return;
    }
    let ring = |angle: f32| ((angle.max(0.0).sin().powi(2) * m as f32) as u32).min(m - 1);
    let rings = ring(lo)..=ring(hi);
    let half_span = alpha.sin() / theta.sin();
    if lo <= 0.0 || half_span >= 1.0 {
        return rings.for_each(|j| (0..n).for_each(|k| each(j * n + k)));
    }
    let (centre, half) = (axis.y.atan2(axis.x), half_span.asin());
    let cell = |phi: f32| (phi / TAU * n as f32).floor() as i64;
    let (first, last) = (cell(centre - half), cell(centre + half));
    let cells = if last - first + 1 >= n as i64 {
        (0..n).collect::<Vec<u32>>()
    } else {
        (first..=last)
            .map(|k| k.rem_euclid(n as i64) as u32)
            .collect()
    };
    for j in rings {
        cells.iter().for_each(|&k| each(j * n + k));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::gather::cell_direction;

    /// A record at the origin facing +y, with one sample at the centre of
    /// each cell of a 16 × 48 hemisphere, each hitting static object 9
    /// three units away.
    struct Record {
        point: GatherPoint,
        frame: Frame,
        samples: HemisphereSamples,
    }

    impl Record {
        fn new() -> Record {
            let frame = Frame::new(Vec3::Y);
            let direction: Vec<Vec3> = (0..STRATA.count() as u32)
                .map(|c| cell_direction(&frame, STRATA, c, glam::Vec2::splat(0.5)))
                .collect();
            let n = direction.len();
            Record {
                point: GatherPoint {
                    position: Vec3::ZERO,
                    normal: Vec3::Y,
                    geometric_normal: Vec3::Y,
                },
                frame,
                samples: HemisphereSamples {
                    direction,
                    radiance: vec![Vec3::ONE; n],
                    distance: vec![3.0; n],
                    object: vec![9; n],
                },
            }
        }

        /// [`Arrivals::share`] of this record's samples at frame `t`, the
        /// record on object `own`, the cube (object 1) hit by its samples
        /// if `seen`.
        fn share(&self, a: &Arrivals, t: u32, (own, seen): (u32, bool), bound: f32) -> f32 {
            let unseen = |o: u32| o == 1 && !seen;
            let pose = (&self.point, &self.frame);
            a.share(t, pose, &self.samples, (STRATA, own, unseen), bound)
        }
    }

    /// A unit cube (object 1) placed with its centre at `then` at t0 and
    /// at `now` at t0+1.
    fn cube_moving(then: Vec3, now: Vec3) -> Arrivals {
        let own = OwnBounds::of(&[Vec3::splat(-0.5), Vec3::splat(0.5)]);
        let x0 = [Mat4::IDENTITY, Mat4::from_translation(then)];
        let x1 = [Mat4::IDENTITY, Mat4::from_translation(now)];
        Arrivals::new(0, &[None, own], &x0, [&x1[..]].into_iter())
    }

    const STRATA: Strata = Strata { theta: 16, phi: 48 };
    /// The record on object 0, and the cube unseen; the cube the record's
    /// own; the cube seen by its samples.
    const UNSEEN: (u32, bool) = (0, false);
    const OWN: (u32, bool) = (1, false);
    const SEEN: (u32, bool) = (0, true);

    /// A unit cube that comes from under the floor to stand over the
    /// record, its near face half a unit up, crosses the paths of the
    /// samples within the face's view: about the face's form factor, seen
    /// by the samples or not (seen, the share of the view it covers grew).
    /// Where it stood at t0 already, lies past the samples' hits, or is the
    /// record's own, it counts for none; seen, a step aside at the same
    /// distance counts for none, unseen it does; a far one is turned away
    /// by the bound.
    #[test]
    fn an_object_moved_into_the_samples_paths_counts_by_the_share_it_crosses() {
        let r = Record::new();
        let (over, under) = (Vec3::Y, Vec3::new(0.0, -20.0, 0.0));
        let share = r.share(&cube_moving(under, over), 1, UNSEEN, 0.05);
        // The near face's form factor from the point: four corner
        // rectangles of X = Y = 1 (a half side over the height),
        // 4 · (1/2π) · 2 · (X/√(1+X²)) · atan(Y/√(1+X²)) = 0.554.
        assert!((share - 0.554).abs() < 0.03, "{share}");
        assert_eq!(r.share(&cube_moving(over, over), 1, UNSEEN, 0.05), 0.0);
        assert_eq!(r.share(&cube_moving(under, over), 1, OWN, 0.05), 0.0);
        let seen = r.share(&cube_moving(under, over), 1, SEEN, 0.05);
        assert!((seen - share).abs() < 1e-6, "{seen} against {share}");
        let (left, right) = (Vec3::new(-0.3, 1.2, 0.0), Vec3::new(0.3, 1.2, 0.0));
        assert_eq!(r.share(&cube_moving(left, right), 1, SEEN, 0.05), 0.0);
        assert!(r.share(&cube_moving(left, right), 1, UNSEEN, 0.05) > 0.05);
        assert_eq!(
            r.share(&cube_moving(under, 4.0 * Vec3::Y), 1, UNSEEN, 0.0),
            0.0
        );
        let far = Vec3::new(0.0, 2.9, 0.0);
        assert_eq!(r.share(&cube_moving(under, far), 1, UNSEEN, 0.2), 0.0);
        assert!(r.share(&cube_moving(under, far), 1, UNSEEN, 0.0) > 0.0);
        // Frames outside those it holds count for nothing.
        assert_eq!(r.share(&cube_moving(under, over), 0, UNSEEN, 0.05), 0.0);
        assert_eq!(r.share(&cube_moving(under, over), 2, UNSEEN, 0.05), 0.0);
    }

    /// Every cell one of whose directions (eight jittered in each) meets
    /// a sphere is among its cone's cells, for spheres anywhere about
    /// records facing anywhere: against the brute force, over cells of
    /// two shapes; and the cone's cells are not many more.
    #[test]
    fn a_spheres_cone_cells_hold_every_cell_that_sees_it() {
        let mut rng = crate::sampling::Rng::from_seed(7, 0);
        let (mut reached, mut listed) = (0usize, 0usize);
        for strata in [STRATA, Strata { theta: 5, phi: 7 }] {
            for _ in 0..400 {
                let mut unit =
                    || 2.0 * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 1.0;
                let normal = unit().try_normalize().unwrap_or(Vec3::Y);
                let (p, centre) = (unit(), unit() * 3.0);
                let radius = 0.05 + 0.5 * unit().x.abs();
                let placed = Placed {
                    centre,
                    radius,
                    aabb: (centre - radius, centre + radius),
                };
                let frame = Frame::new(normal);
                let mut cells = vec![false; strata.count()];
                cone_cells(&frame, strata, p, &placed, |c| cells[c as usize] = true);
                for (cell, &in_cone) in cells.iter().enumerate() {
                    let sees = (0..8).any(|_| {
                        let u = glam::Vec2::new(rng.next_f32(), rng.next_f32());
                        let dir = cell_direction(&frame, strata, cell as u32, u);
                        placed.crossed(p, dir, f32::INFINITY)
                    });
                    assert!(in_cone || !sees, "cell {cell} sees the sphere, not listed");
                    reached += usize::from(sees);
                    listed += usize::from(in_cone);
                }
            }
        }
        assert!(
            reached > 1000,
            "{reached}: the spheres are seen too little to test"
        );
        assert!(
            listed < 3 * reached,
            "{listed} cells listed for {reached} that see"
        );
    }

    /// The share's bound is the sphere's `sin²α`: 1 from inside, 0 wholly
    /// below the tangent plane, counted across the horizon; a ball's
    /// sphere is the ball, turned and scaled.
    #[test]
    fn the_share_is_bounded_by_the_sphere_around_the_vertices() {
        let ball: Vec<Vec3> = (0..64)
            .map(|i| {
                let (a, b) = (i as f32 * 0.7, i as f32 * 1.3);
                Vec3::new(a.cos() * b.sin(), a.sin() * b.sin(), b.cos())
            })
            .collect();
        let own = OwnBounds::of(&ball).unwrap();
        // Around its box's centre, a little past the ball; its box's
        // sphere would be √3 across.
        assert!(ball.iter().all(|p| p.distance(own.centre) <= own.radius));
        assert!(own.radius < 1.1, "{}", own.radius);
        let at = |c: Vec3, scale: f32| {
            let turn = glam::Quat::from_rotation_z(0.3);
            let x = Mat4::from_scale_rotation_translation(Vec3::splat(scale), turn, c);
            own.placed(x).unwrap()
        };
        let d = Vec3::new(0.0, 8.0, 0.0);
        let far = at(d, 2.0);
        let expected = (2.0 * own.radius / far.centre.length()).powi(2);
        assert!((far.share(Vec3::ZERO, Vec3::Y) - expected).abs() < 1e-6);
        assert!(
            (far.radius - 2.0 * own.radius).abs() < 1e-5,
            "{}",
            far.radius
        );
        assert_eq!(at(Vec3::ZERO, 1.0).share(Vec3::ZERO, Vec3::Y), 1.0);
        assert_eq!(at(-d, 1.0).share(Vec3::ZERO, Vec3::Y), 0.0);
        assert!(at(Vec3::new(4.0, -0.5, 0.0), 1.0).share(Vec3::ZERO, Vec3::Y) > 0.0);
        // A shear stretches by more than any column: the bound still holds.
        let shear = Mat3::from_cols(Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Z);
        let stretch = largest_stretch(shear);
        let worst = (0..360)
            .map(|i| (i as f32).to_radians())
            .map(|a| (shear * Vec3::new(a.cos(), a.sin(), 0.0)).length())
            .fold(0.0, f32::max);
        assert!(stretch >= worst, "{stretch} < {worst}");
    }
}
