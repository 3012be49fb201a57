//! The estimate of a record's irradiance at the next frame, E(t0+1), by
//! reprojecting its hemisphere samples with the known motion of objects
//! and lights (TRC §4.7, Fig. 6). How well it does against E(t0+1)
//! gathered again is measured in the parent module's documentation.

use super::direct::{DirectChange, FirstHit, LaterGeometry, SampleAtStart, ShadowGeometry};
use super::{Gathered, NextDirect};
use crate::backend::Hit;
use crate::cache::gather::{HemisphereSamples, Strata};
use crate::method::unshadowed::UnshadowedLights;
use crate::method::FrameContext;
use crate::sampling::Frame;
use crate::scene::{Snapshot, Triangle};
use glam::{Mat4, Vec3};
use std::cell::OnceCell;
use std::f32::consts::{FRAC_1_PI, PI, TAU};
use std::sync::Arc;

/// What changes from this frame to the next (TRC §5: "the transformation
/// matrix … at time t+1 is known"; "such matrices are available for light
/// sources as well").
pub(super) struct NextFrame {
    /// Per object, its rigid motion from t to t+1 (`Scene::object_motion`,
    /// from the two snapshots' transforms); `None` when it does not move.
    motion: Vec<Option<Mat4>>,
    /// The lights at t and t+1.
    lights: (Arc<UnshadowedLights>, Arc<UnshadowedLights>),
    /// Whether some light moves from t to t+1.
    lights_move: bool,
    /// The direct light at the samples' first hits at t and t+1 (`None`
    /// when nothing moves).
    direct: Option<DirectChange>,
}

impl NextFrame {
    /// What changes after `ctx`'s frame; where `next_direct` evaluates the
    /// direct light again, also the geometry the samples' direct light at
    /// t+1 needs, `geometry` keeping its BVHs from frame to frame.
    pub(super) fn new(
        ctx: &FrameContext,
        next_direct: NextDirect,
        geometry: &mut ShadowGeometry,
    ) -> Self {
        let now = ctx.snapshot;
        // The next frame's geometry only where its direct light is
        // evaluated: otherwise its lights and the objects' motion.
        let t = ctx.time_of(ctx.frame + 1);
        let mut later = match next_direct {
            NextDirect::On => ctx.scene.snapshot_from(t, now),
            _ => ctx.scene.emitters_snapshot(t),
        };
        let (l0, l1) = (
            Arc::new(UnshadowedLights::of(&ctx.scene.materials, now)),
            Arc::new(UnshadowedLights::of(&ctx.scene.materials, &later)),
        );
        let lights_move = !l0.same_as(&l1);
        let evaluated = next_direct.evaluates(lights_move);
        if evaluated && next_direct != NextDirect::On {
            later = ctx.scene.snapshot_from(t, now);
        }
        let motion: Vec<Option<Mat4>> = now
            .object_to_world
            .iter()
            .zip(&later.object_to_world)
            .map(|(w0, w1)| rigid_motion(*w0, *w1))
            .collect();
        let objects_move = motion.iter().any(Option::is_some);
        let direct = evaluated
            .then(|| DirectChange::new(ctx, later, (objects_move, lights_move), geometry))
            .flatten();
        NextFrame {
            motion,
            lights_move,
            lights: (l0, l1),
            direct,
        }
    }

    /// What changes from t0 to a later frame t (`super::later`): each
    /// object's rigid motion from t0 to t and the lights at both. The
    /// direct light is not evaluated again there (`next_direct` looks at
    /// t0+1 only).
    pub(super) fn later(
        motion: Vec<Option<Mat4>>,
        lights: (Arc<UnshadowedLights>, Arc<UnshadowedLights>),
    ) -> Self {
        NextFrame {
            motion,
            lights_move: !lights.0.same_as(&lights.1),
            lights,
            direct: None,
        }
    }

    /// [`Self::later`] with the direct light at the samples' first hits
    /// evaluated again at frame `t`, with its shadows, as this frame's
    /// `next_direct` evaluates it at t0+1 (`super::later`'s check of lights
    /// that move on), in frame `t`'s geometry: `held` where an earlier
    /// frame's check made it, else made. `None` where this frame does not
    /// evaluate it.
    pub(super) fn later_lit(
        &self,
        ctx: &FrameContext,
        t: u32,
        (motion, lights): (Vec<Option<Mat4>>, Arc<UnshadowedLights>),
        held: Option<&Arc<LaterGeometry>>,
    ) -> Option<Self> {
        let direct = self.direct.as_ref()?;
        let geometry = held
            .cloned()
            .unwrap_or_else(|| Arc::new(direct.geometry_at(ctx, t)));
        Some(NextFrame {
            direct: Some(direct.to_frame(geometry)),
            ..Self::later(motion, (self.lights.0.clone(), lights))
        })
    }

    /// The whole snapshot of t0+1 made for the direct light there, given
    /// up (`None`: none was made): the renderer's for that frame
    /// ([`crate::method::FrameContext::next_snapshot`]).
    pub(super) fn into_later_snapshot(self) -> Option<Snapshot> {
        self.direct.and_then(DirectChange::into_later)
    }

    /// The geometry of the frame the direct light is evaluated again at
    /// (`None`: it is not).
    pub(super) fn later_geometry(&self) -> Option<&Arc<LaterGeometry>> {
        Some(self.direct.as_ref()?.later())
    }

    /// Whether the direct light at t0+1 is evaluated (`next_direct`).
    pub(super) fn evaluates_direct(&self) -> bool {
        self.direct.is_some()
    }

    /// The lights at t0.
    pub(super) fn lights_now(&self) -> &Arc<UnshadowedLights> {
        &self.lights.0
    }

    /// Whether some light moves from t0 to t0+1.
    pub(super) fn lights_move(&self) -> bool {
        self.lights_move
    }
}

/// The motion taking a point of an object placed by `w0` to where `w1`
/// places it; `None` when it stays.
pub(super) fn rigid_motion(w0: Mat4, w1: Mat4) -> Option<Mat4> {
    let m = w1 * w0.inverse();
    (!m.abs_diff_eq(Mat4::IDENTITY, 1e-7)).then_some(m)
}

/// A record's hemisphere samples at t0, to be reprojected to t0+1 and to
/// the later frames `trc::later` checks its life against. What the samples
/// saw at t0 that every reprojection needs alike (the unshadowed direct
/// irradiance at each hit, each hit's light sample with its shadow) is
/// found at the first reprojection and kept for the others: under a moving
/// light a record is reprojected to two or more frames, and finding D(t0)
/// again each time was half of the direct light's work there.
pub(super) struct Reprojection<'g> {
    g: &'g Gathered,
    strata: Strata,
    start: Vec<AtStart>,
}

/// What one sample's first hit was lit by at t0, found once a record.
#[derive(Default)]
struct AtStart {
    /// The unshadowed direct irradiance ([`light_change`]'s `D(t0)`).
    unshadowed: OnceCell<Vec3>,
    /// Its light sample's direct light, shadowed ([`DirectChange::change`]'s
    /// `D(t0)`), and what that needs again at the later frames.
    direct: SampleAtStart,
}

impl<'g> Reprojection<'g> {
    /// The samples of `g`, gathered on `strata`.
    pub(super) fn new(g: &'g Gathered, strata: Strata) -> Self {
        Reprojection {
            g,
            strata,
            start: (0..g.samples.radiance.len())
                .map(|_| AtStart::default())
                .collect(),
        }
    }

    /// The gather whose samples these are.
    pub(super) fn gathered(&self) -> &'g Gathered {
        self.g
    }

    /// The hemisphere's cells the samples were gathered in.
    pub(super) fn strata(&self) -> Strata {
        self.strata
    }

    /// TRC §4.7 (Fig. 6): the record's hemisphere samples at t0 moved to
    /// t0+1 (or to the later frame `next` describes). The record stays
    /// where it is (§4.4: record locations are fixed in world space, also
    /// on dynamic objects). Each sample's first hit moves with its object
    /// (static hits and misses stay), is projected back onto the record's
    /// stratified hemisphere (its cell `(j, k)` from `sin²θ` and `φ`, as in
    /// `cache::gather`), overlaps are resolved by a depth test (nearest
    /// wins), and empty cells are filled from the farthest neighbouring
    /// sample (the local background, Walter et al. 1999), pass after pass
    /// until none is left. Moving lights: each sample's radiance is scaled
    /// by the ratio of unshadowed direct irradiance at its hit point after
    /// and before ("accounting for the rotation and displacement of both
    /// objects and light sources"): shadowing is assumed unchanged and the
    /// hit's own indirect light assumed to scale with its direct light. A
    /// hit that had no direct light and has some (a light switched on, a
    /// surface turned towards one) gains its diffuse reflection of it,
    /// unshadowed: no ratio scales light from nothing.
    pub(super) fn to(&self, ctx: &FrameContext, next: &NextFrame) -> HemisphereSamples {
        let g = self.g;
        let (m, n) = (self.strata.theta as usize, self.strata.phi as usize);
        let mut grid = HemisphereGrid::new(m, n);
        let frame = Frame::new(g.record.normal);
        let mut own = g.samples.radiance.clone();
        for (i, own) in own.iter_mut().enumerate() {
            if let Some((cell, sample)) = self.reproject_sample(ctx, next, &frame, &grid, i) {
                *own = sample.radiance;
                grid.keep_nearest(cell, sample);
            }
        }
        grid.keep_own_samples(&own, &g.samples.object);
        grid.fill_holes();
        grid.into_samples(&g.samples)
    }

    /// Sample `i` of the gather at t0+1: its cell and what the cell sees, or
    /// `None` where it moved below the record's horizon. Its first hit moves
    /// with its object (static hits and misses stay in their cells), and its
    /// radiance follows moving lights ([`Self::radiance_at_next`]).
    fn reproject_sample(
        &self,
        ctx: &FrameContext,
        next: &NextFrame,
        frame: &Frame,
        grid: &HemisphereGrid,
        i: usize,
    ) -> Option<(usize, CellSample)> {
        let s = &self.g.samples;
        let dir = s.direction[i].normalize();
        let hit_point = self.g.record.position + dir * s.distance[i];
        let at = self.moved_hit(next, frame, grid, i, (dir, hit_point))?;
        let sample = CellSample {
            depth: at.depth,
            radiance: self.radiance_at_next(ctx, next, i, (dir, hit_point), at.moved),
            object: s.object[i],
        };
        Some((at.cell, sample))
    }

    /// Where sample `i`'s first hit (its direction and point) lies at
    /// t0+1; `None` where it moved below the record's horizon.
    fn moved_hit(
        &self,
        next: &NextFrame,
        frame: &Frame,
        grid: &HemisphereGrid,
        i: usize,
        (dir, hit_point): (Vec3, Vec3),
    ) -> Option<HitAtNext> {
        let (s, origin) = (&self.g.samples, self.g.record.position);
        let (dist, object) = (s.distance[i], s.object[i]);
        let motion = next
            .motion
            .get(object as usize)
            .copied()
            .flatten()
            .filter(|_| dist.is_finite());
        let Some(mat) = motion else {
            return Some(HitAtNext {
                cell: i,
                depth: dist,
                moved: None,
            });
        };
        let moved = mat.transform_point3(hit_point);
        let d = moved - origin;
        let depth = d.length();
        let after = frame.to_local(d / depth.max(1e-12));
        if !(after.z > 0.0 && depth > 0.0) {
            return None; // moved below the record's horizon
        }
        let cell = grid.moved_cell(i, frame.to_local(dir), after)?;
        Some(HitAtNext {
            cell,
            depth,
            moved: Some((mat, moved)),
        })
    }

    /// Sample `i`'s radiance at t0+1, its first hit in direction `dir` at
    /// `hit_point` (moved to `moved` with its object's motion, if it
    /// moves): scaled as moving lights change the hit's unshadowed light
    /// ([`light_change`]), and its direct light evaluated again where
    /// `next` does.
    fn radiance_at_next(
        &self,
        ctx: &FrameContext,
        next: &NextFrame,
        i: usize,
        (dir, hit_point): (Vec3, Vec3),
        moved: Option<(Mat4, Vec3)>,
    ) -> Vec3 {
        let (g, start) = (self.g, &self.start[i]);
        let mut radiance = g.samples.radiance[i];
        let Some(hit) = g.results.get(i).map(|r| &r.hit).filter(|h| h.is_hit()) else {
            return radiance;
        };
        let change = if next.lights_move {
            let (l0, l1) = &next.lights;
            let d0 = &start.unshadowed;
            light_change(ctx.snapshot, hit, dir, (hit_point, d0), moved, l0, l1)
        } else {
            LightChange::NONE
        };
        let ratio = change.ratio;
        radiance *= ratio;
        let Some(direct) = &next.direct else {
            // Light where there was none (a light switched on, a surface
            // turned towards one): the hit's diffuse reflection of it,
            // unshadowed. `direct` evaluates it with its shadow instead.
            let m = ctx.snapshot.tri_material[hit.triangle as usize] as usize;
            return radiance + ctx.scene.materials[m].diffuse * FRAC_1_PI * change.from_dark;
        };
        let at = FirstHit {
            sample: i,
            hit,
            point: hit_point,
            moved,
        };
        // The change subtracts D(t0) estimated with a light sample of its
        // own, not the path's: where a shadow arrives it can take more than
        // the sample held. Radiance is never negative (a negative E(t0+1)
        // made |τ − 1| > 1 and the gradients overshoot).
        (radiance + direct.change(ctx, g, &at, (ratio, &start.direct))).max(Vec3::ZERO)
    }
}

/// Where a sample's first hit lies at t0+1 ([`Reprojection::moved_hit`]).
struct HitAtNext {
    /// Its cell of the record's hemisphere.
    cell: usize,
    /// Its distance from the record.
    depth: f32,
    /// Its object's motion from t0 to t0+1 and the point moved, if the
    /// object moves.
    moved: Option<(Mat4, Vec3)>,
}

/// What a cell of the reprojected hemisphere sees.
#[derive(Clone, Copy, Debug, PartialEq)]
struct CellSample {
    depth: f32,
    radiance: Vec3,
    object: u32,
}

/// The record's stratified hemisphere at t0+1: `m × n` cells, `(j, k)` at
/// `j · n + k` as in `cache::gather`, each holding the sample reprojected
/// into it.
struct HemisphereGrid {
    m: usize,
    n: usize,
    cells: Vec<Option<CellSample>>,
}

impl HemisphereGrid {
    fn new(m: usize, n: usize) -> Self {
        HemisphereGrid {
            m,
            n,
            cells: vec![None; m * n],
        }
    }

    /// The cell of a sample gathered in cell `i` along `before` (local
    /// frame) that now lies along `after`, or `None` below the horizon.
    /// The sample's displacement in (sin²θ, φ) is applied to the centre of
    /// its cell: samples of one rigidly moving surface then move together,
    /// where their jittered positions would collide and leave holes inside
    /// the surface.
    fn moved_cell(&self, i: usize, before: Vec3, after: Vec3) -> Option<usize> {
        let (m, n) = (self.m, self.n);
        let (j0, k0) = (i / n, i % n);
        let du = before.z * before.z - after.z * after.z;
        let dphi = (after.y.atan2(after.x) - before.y.atan2(before.x) + PI).rem_euclid(TAU) - PI;
        let u = (j0 as f32 + 0.5) / m as f32 + du;
        if u >= 1.0 {
            return None;
        }
        let phi = ((k0 as f32 + 0.5) / n as f32 * TAU + dphi).rem_euclid(TAU);
        let j = ((u.max(0.0) * m as f32) as usize).min(m - 1);
        let k = ((phi / TAU * n as f32) as usize).min(n - 1);
        Some(j * n + k)
    }

    /// The depth test (Fig. 6c): of the samples landing in one cell, the
    /// nearest wins.
    fn keep_nearest(&mut self, cell: usize, sample: CellSample) {
        if self.cells[cell].is_none_or(|c| sample.depth < c.depth) {
            self.cells[cell] = Some(sample);
        }
    }

    /// A cell that still sees the object its own sample saw keeps its own
    /// sample (`own`, the samples' radiance at t0+1, in gather order): our
    /// cells hold one path-traced sample each, and passing samples between
    /// cells of one surface would only reshuffle Monte Carlo noise (the
    /// paper's rasterized hemispheres have none).
    fn keep_own_samples(&mut self, own: &[Vec3], objects: &[u32]) {
        for (i, cell) in self.cells.iter_mut().enumerate() {
            if let Some(c) = cell.as_mut().filter(|c| c.object == objects[i]) {
                c.radiance = own[i];
            }
        }
    }

    /// Hole filling from the farthest neighbour (Fig. 6d; the local
    /// background, Walter et al. 1999), pass after pass until no empty
    /// cell has a filled neighbour.
    fn fill_holes(&mut self) {
        while self.cells.iter().any(Option::is_none) {
            let before = self.cells.clone();
            for j in 0..self.m {
                for k in 0..self.n {
                    if before[j * self.n + k].is_none() {
                        self.cells[j * self.n + k] = self.farthest_neighbour(&before, j, k);
                    }
                }
            }
            if self.cells == before {
                break; // nothing left above the horizon
            }
        }
    }

    /// The farthest filled cell of `cells` among the eight around `(j, k)`
    /// (φ wraps around, θ does not).
    fn farthest_neighbour(
        &self,
        cells: &[Option<CellSample>],
        j: usize,
        k: usize,
    ) -> Option<CellSample> {
        let n = self.n;
        let mut best: Option<CellSample> = None;
        for dj in [-1i64, 0, 1] {
            let jj = j as i64 + dj;
            if jj < 0 || jj >= self.m as i64 {
                continue;
            }
            for dk in [n - 1, 0, 1] {
                let kk = (k + dk) % n;
                if let Some(c) = cells[jj as usize * n + kk] {
                    if best.is_none_or(|b| c.depth > b.depth) {
                        best = Some(c);
                    }
                }
            }
        }
        best
    }

    /// The estimate as hemisphere samples: `gathered`'s directions, each
    /// cell's radiance and depth (none and infinitely far where the grid
    /// stayed empty).
    fn into_samples(self, gathered: &HemisphereSamples) -> HemisphereSamples {
        HemisphereSamples {
            direction: gathered.direction.clone(),
            radiance: self
                .cells
                .iter()
                .map(|c| c.map_or(Vec3::ZERO, |c| c.radiance))
                .collect(),
            distance: self
                .cells
                .iter()
                .map(|c| c.map_or(f32::INFINITY, |c| c.depth))
                .collect(),
            object: gathered.object.clone(),
        }
    }
}

/// How the unshadowed direct irradiance `D` at a sample's hit point
/// (moved with its object) changes from t0 to t0+1, per channel.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LightChange {
    /// `D(t0+1)/D(t0)`; 1 where `D(t0)` is zero.
    ratio: Vec3,
    /// `D(t0+1)` where `D(t0)` is zero (no ratio scales light from
    /// nothing); 0 elsewhere.
    from_dark: Vec3,
}

impl LightChange {
    const NONE: LightChange = LightChange {
        ratio: Vec3::ONE,
        from_dark: Vec3::ZERO,
    };
}

/// The [`LightChange`] at a sample's hit point `p0`, `d0` holding its
/// `D(t0)` once found (the same for every later frame).
fn light_change(
    snapshot: &Snapshot,
    hit: &Hit,
    dir: Vec3,
    (p0, d0): (Vec3, &OnceCell<Vec3>),
    moved: Option<(Mat4, Vec3)>,
    l0: &UnshadowedLights,
    l1: &UnshadowedLights,
) -> LightChange {
    let triangle = &snapshot.triangles[hit.triangle as usize];
    let mut n0 = triangle.geometric_normal();
    if n0.dot(dir) > 0.0 {
        n0 = -n0; // the side the record sees
    }
    let (p1, n1) = match moved {
        Some((mat, p1)) => (p1, moved_normal(triangle, mat, n0)),
        None => (p0, n0),
    };
    let (d0, d1) = (
        *d0.get_or_init(|| l0.irradiance(p0, n0)),
        l1.irradiance(p1, n1),
    );
    let lit = d0.cmpgt(Vec3::splat(1e-12));
    LightChange {
        ratio: Vec3::select(lit, d1 / d0, Vec3::ONE),
        from_dark: Vec3::select(lit, Vec3::ZERO, d1),
    }
}

/// The normal of `triangle` moved by `mat`, on the side of `n0` (one of
/// its normals before the move). Under a non-uniform scale a normal does
/// not move as a vector does (it takes the inverse transpose), so it is
/// the moved triangle's own; the moved vector still points to its side
/// (`A·n · A⁻ᵀ·n = n·n > 0`).
fn moved_normal(triangle: &Triangle, mat: Mat4, n0: Vec3) -> Vec3 {
    let [a, b, c] = triangle.p.map(|p| mat.transform_point3(p));
    let n = (b - a).cross(c - a).normalize_or_zero();
    if n.dot(mat.transform_vector3(n0)) < 0.0 {
        -n
    } else {
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(depth: f32, object: u32) -> CellSample {
        CellSample {
            depth,
            radiance: Vec3::splat(depth),
            object,
        }
    }

    /// A moved normal is the inverse transpose's (the closed form), on the
    /// side it faced, under a turn, a non-uniform scale and a mirror.
    #[test]
    fn moved_normals_take_the_inverse_transpose() {
        let triangle = Triangle {
            p: [
                Vec3::ZERO,
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 1.0),
            ],
            n: [Vec3::ZERO; 3],
        };
        let n0 = -triangle.geometric_normal();
        for mat in [
            Mat4::from_rotation_x(0.7) * Mat4::from_translation(Vec3::ONE),
            Mat4::from_scale(Vec3::new(1.0, 4.0, 0.5)),
            Mat4::from_scale(Vec3::new(-1.0, 3.0, 1.0)) * Mat4::from_rotation_z(0.3),
        ] {
            let want = mat.inverse().transpose().transform_vector3(n0).normalize();
            let got = moved_normal(&triangle, mat, n0);
            assert!(got.abs_diff_eq(want, 1e-5), "{got} {want}");
            let naive = mat.transform_vector3(n0).normalize();
            assert!(naive.dot(want) > 0.0);
        }
    }

    /// Two samples in one cell: the nearer one is seen (Fig. 6c).
    #[test]
    fn the_depth_test_keeps_the_nearest_sample() {
        let mut grid = HemisphereGrid::new(2, 4);
        grid.keep_nearest(5, sample(3.0, 1));
        grid.keep_nearest(5, sample(1.0, 2));
        grid.keep_nearest(5, sample(2.0, 3));
        assert_eq!(grid.cells[5], Some(sample(1.0, 2)));
    }

    /// Holes take the farthest of their neighbours (Fig. 6d), across the
    /// φ seam too, pass after pass until the grid is full.
    #[test]
    fn holes_are_filled_from_the_farthest_neighbour() {
        // 3 × 5 cells; the near object at (1, 0), the far one at (1, 4),
        // which is next to (1, 0) across the seam.
        let mut grid = HemisphereGrid::new(3, 5);
        grid.keep_nearest(5, sample(1.0, 7));
        grid.keep_nearest(9, sample(4.0, 8));
        grid.fill_holes();
        let full: Vec<CellSample> = grid.cells.iter().map(|c| c.unwrap()).collect();
        // Every cell next to the far sample takes it, over the near one.
        for cell in [0, 4, 8, 10, 14] {
            assert_eq!(full[cell], sample(4.0, 8), "cell {cell}");
        }
        // Cells next to the near sample only, at first, keep it.
        for cell in [1, 6, 11] {
            assert_eq!(full[cell], sample(1.0, 7), "cell {cell}");
        }
        assert_eq!(full[5], sample(1.0, 7), "a filled cell stays");
    }

    /// A sample's cell moves by its displacement in φ and in sin²θ, and
    /// one moved past the horizon lands nowhere.
    #[test]
    fn moved_cells_follow_the_displacement_in_phi_and_theta() {
        let grid = HemisphereGrid::new(4, 8);
        let at = |theta: f32, phi: f32| {
            Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            )
        };
        let before = at(0.8, 0.3);
        let i = 2 * 8 + 1;
        assert_eq!(grid.moved_cell(i, before, before), Some(i));
        let turned = at(0.8, 0.3 + TAU / 4.0);
        assert_eq!(grid.moved_cell(i, before, turned), Some(2 * 8 + 3));
        // Row 2 holds sin²θ in [0.5, 0.75): from sin²θ = 0.6 to 0.8 the
        // sample moves one row down, to the horizon (sin²θ = 1) past it.
        let row_2 = at(0.6f32.sqrt().asin(), 0.3);
        let row_3 = at(0.8f32.sqrt().asin(), 0.3);
        assert_eq!(grid.moved_cell(i, row_2, row_3), Some(3 * 8 + 1));
        assert_eq!(grid.moved_cell(i, row_2, at(PI / 2.0, 0.3)), None);
    }
}
