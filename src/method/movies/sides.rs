//! Which side of each triangle the global pass solves.
//!
//! Radiosity polygons are one-sided: the paper's global pass solves the
//! side a polygon's normal faces, and so does ours ([`super::global`]).
//! The rest of the renderer is two-sided (`material`), as the reference
//! renders are, and files do not always face their normals into the
//! space that is lit and seen: a room modelled as a box whose normals face
//! out, with the camera and the lights inside, is common. Solving the
//! front sides there lost about two thirds of the room's light (0.12
//! against `path`'s 0.37 in the lit room of `tests/movies.rs`).
//!
//! Departure, named: the side is chosen per *component* (the triangles of
//! one object joined across the edges they share with the same
//! orientation: a room, a box, a sphere, a panel) by whether it encloses
//! the camera. The signed solid angles of a component's triangles seen
//! from the camera, positive where the camera is behind a triangle, sum
//! to 4π times its winding number around the camera: 1 for a closed
//! surface around the camera with its normals facing out, 0 outside a
//! closed surface, and for an open one (a room without a ceiling, a dome)
//! the share of the sphere of directions it wraps. Where the winding
//! number is at least ½, the component encloses the camera with its
//! normals facing away from it, and its back sides are solved; elsewhere
//! its fronts, as before, but for a *closed* component (every edge joined)
//! that the camera is outside of (winding number between −½ and ½) with
//! its normals facing in (negative signed volume, the sum of the cones
//! from the camera to its triangles: a sphere or a box whose winding is
//! turned inside out, as files exported with flipped normals have): its
//! backs, the outside the camera sees. Solving its fronts there left such
//! a ball black. A flat part never winds ½ around any point, so
//! a shelf, a panel or a picture keeps its front from wherever it is seen
//! (choosing by the side the camera sees turned a shelf seen from below
//! to its dark underside, and the room lost the light its top bounces).
//! Solving both sides of every part is not done: it would double the
//! links within the same budget and leave the inside of every solid to
//! solve. A *flat* part with a surface behind it, farther than a tenth of
//! its size (a partition, a table top, a wall of a room built from
//! separate walls facing out), has both its sides solved (`both_sides`):
//! one side alone left the room behind a thin partition 12–34 % dark,
//! without the light of the partition's other side and its bounce. A flat
//! part has no inside to waste links on; a room's outer wall, with
//! nothing behind it, and a light hung just under a ceiling keep one
//! side. Not mended: a box facing out, all one part, seen from outside
//! through its open side: its inside gets its direct light only (a box
//! whose walls do not join, their corners differing in their bits, is
//! flat walls with the box's inside behind them, solved on both sides).
//! A flat part with nothing straight behind it (most of its back rays
//! meet nothing: a wall standing on open ground, a ground plane, a room's
//! outer wall) is solved on the side the camera is on: a wall on open
//! ground, its normals facing away from the sun and the camera, was
//! solved on its dark side, and its lit side and the ground before it
//! lost their bounce (0.25 relative RMSE against `path`, 0.03 after;
//! `tests/directional_light.rs`). Where something lies behind, a shelf
//! keeps its front seen from below, as above.
//! A face turned the other way from its neighbours is a component of its
//! own.
//!
//! The choice is a function of the frame (its camera and geometry), so a
//! pass that starts at any frame makes the same one. Where a component's
//! side changes (the camera walks into a room through its wall or its
//! open side), the global pass traces again the links from its vertices
//! and those landing on it, and finds its static shadows again.

use crate::accel::SceneBvh;
use crate::integrator::RayOffset;
use crate::scene::{Scene, Snapshot};
use glam::Vec3;
use rayon::prelude::*;

/// The side the global pass solves of each triangle of a snapshot.
#[derive(Clone, Debug, PartialEq)]
pub struct SolvedSides {
    /// Per triangle, its component.
    component: Vec<u32>,
    /// Per component, whether every edge of its triangles is joined to
    /// another of them ([`parts`]).
    closed: Vec<bool>,
    /// Per component, whether its back sides are solved.
    back: Vec<bool>,
    /// Per component, whether both its sides are solved ([`both_sides`]);
    /// `back` then names the side its first vertices are on.
    both: Vec<bool>,
    /// Per component, whether it is a flat part with nothing straight
    /// behind it ([`both_sides`]): its side is the one the camera is on.
    open: Vec<bool>,
}

impl SolvedSides {
    /// The components of the triangles of `corners` (their corners in
    /// their objects' own space, [`object_space_corners`]: the same
    /// whatever frame they are found at, also where an object is scaled to
    /// nothing), the sides `snapshot`'s camera sets, and the parts solved
    /// on both sides as `meshed` (the snapshot the pass is meshed at, `bvh`
    /// built over it) places them, its rays leaving them by `offset`.
    pub fn new(
        corners: &[ObjectCorners],
        snapshot: &Snapshot,
        (meshed, bvh): (&Snapshot, &SceneBvh),
        offset: RayOffset,
    ) -> Self {
        let triangles: Vec<(u32, [Vec3; 3])> = (corners.iter())
            .map(|(object, c)| (*object, c.map(|(p, _)| p)))
            .collect();
        let parts = parts(&triangles);
        let (both, open) = both_sides(&triangles, &parts.component, (meshed, bvh), offset);
        Self::of_parts(parts, (both, open), snapshot)
    }

    /// The sides of `parts` from `snapshot`'s camera, with the parts
    /// solved on `both` sides and those `open` behind.
    fn of_parts(
        Parts { component, closed }: Parts,
        (both, open): (Vec<bool>, Vec<bool>),
        snapshot: &Snapshot,
    ) -> Self {
        let back = backs_solved(snapshot, &component, &closed, &open);
        SolvedSides {
            both,
            open,
            component,
            closed,
            back,
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.component[..])
            + std::mem::size_of_val(&self.closed[..])
            + std::mem::size_of_val(&self.back[..])
            + std::mem::size_of_val(&self.both[..])
            + std::mem::size_of_val(&self.open[..])
    }

    /// Whether both sides of triangle `id` are solved.
    pub fn both(&self, id: u32) -> bool {
        self.both[self.component(id)]
    }

    /// Whether the side of triangle `id` that `back` names is solved.
    pub fn solves(&self, id: u32, back: bool) -> bool {
        self.both(id) || back == self.back(id)
    }

    /// Takes the sides `snapshot`'s camera sets (it holds the same
    /// triangles); returns, per component, whether its side changed.
    pub fn update(&mut self, snapshot: &Snapshot) -> Vec<bool> {
        let back = backs_solved(snapshot, &self.component, &self.closed, &self.open);
        let changed = back.iter().zip(&self.back).map(|(a, b)| a != b).collect();
        self.back = back;
        changed
    }

    /// Per triangle, its component.
    pub fn components(&self) -> &[u32] {
        &self.component
    }

    /// The component of triangle `id`.
    pub fn component(&self, id: u32) -> usize {
        self.component[id as usize] as usize
    }

    /// Whether the back side of triangle `id` is the one solved.
    pub fn back(&self, id: u32) -> bool {
        self.back[self.component(id)]
    }

    /// `1` where the front side of triangle `id` is solved, `−1` where
    /// its back is: the solved side's normal is the triangle's times this.
    pub fn sign(&self, id: u32) -> f32 {
        if self.back(id) {
            -1.0
        } else {
            1.0
        }
    }
}

/// A triangle's object and the positions and normals of its corners in
/// the object's own space ([`object_space_corners`]).
pub type ObjectCorners = (u32, [(Vec3, Vec3); 3]);

/// Every triangle of `scene` in snapshot order (the order of
/// [`Scene::object_order`]), with its object and its corners' positions
/// and normals in the object's own space, in the corner order of `placed`
/// (a snapshot of `scene`, which turns a mirrored object's triangles).
pub fn object_space_corners(scene: &Scene, placed: &Snapshot) -> Vec<ObjectCorners> {
    let mut out = Vec::with_capacity(placed.triangles.len());
    for object in scene.object_order() {
        let mesh = &scene.objects[object].mesh;
        let flip = placed.object_to_world[object].determinant() < 0.0;
        for tri in &mesh.triangles {
            let mut idx = tri.map(|i| i as usize);
            if flip {
                idx.swap(1, 2);
            }
            // A corner the mesh lacks is a malformed mesh's; the loader
            // refuses those, so it only keeps this from panicking.
            let corner = |i: usize| {
                let p = mesh.positions.get(i).copied().unwrap_or(Vec3::NAN);
                (p, mesh.normals.get(i).copied().unwrap_or(Vec3::ZERO))
            };
            out.push((object as u32, idx.map(corner)));
        }
    }
    out
}

/// An edge of an object's triangle, from corner to corner (their bits).
type DirectedEdge = (u32, [u32; 3], [u32; 3]);

/// The edges of triangle `(object, corners)`, each from a corner to the
/// next, corners as bits (`-0` as `0`).
fn directed_edges((object, p): &(u32, [Vec3; 3])) -> [DirectedEdge; 3] {
    let bits = |q: Vec3| (q + Vec3::ZERO).to_array().map(f32::to_bits);
    [0, 1, 2].map(|k| (*object, bits(p[k]), bits(p[(k + 1) % 3])))
}

/// Whether triangle `p` has no area (two corners the same, or in a line):
/// it would run an edge both ways, so it joins nothing.
fn degenerate(p: &[Vec3; 3]) -> bool {
    (p[1] - p[0]).cross(p[2] - p[0]).length_squared() == 0.0
}

/// One triangle's run along an edge. The edge is named by its corners
/// in bit order, whichever way the triangle runs it, so that the runs of
/// an edge each way sort together.
struct EdgeRun {
    /// Its object and its corners' bits, the lesser first (a
    /// [`DirectedEdge`] put in order).
    edge: DirectedEdge,
    /// Whether the triangle runs it from the second corner to the first.
    backwards: bool,
    triangle: u32,
}

/// Every edge run of the triangles with area, those of one edge
/// together. A sort rather than a hash map of edges: a mesh of millions
/// of triangles has millions of edges, and hashing each took seconds.
fn edge_runs(triangles: &[(u32, [Vec3; 3])]) -> Vec<EdgeRun> {
    let mut runs: Vec<EdgeRun> = (triangles.iter().enumerate())
        .filter(|(_, triangle)| !degenerate(&triangle.1))
        .flat_map(|(id, triangle)| {
            directed_edges(triangle).map(|(object, a, b)| EdgeRun {
                edge: (object, a.min(b), a.max(b)),
                backwards: a > b,
                triangle: id as u32,
            })
        })
        .collect();
    runs.par_sort_unstable_by_key(|run| run.edge);
    runs
}

/// The triangles of a scene joined into components ([`parts`]).
struct Parts {
    /// Per triangle, its component.
    component: Vec<u32>,
    /// Per component, whether it is closed.
    closed: Vec<bool>,
}

/// Per triangle (`(object, corners)`), its component: triangles of one
/// object joined across edges they share with the same orientation, i.e.
/// an edge one runs from `a` to `b` and the other from `b` to `a` (corner
/// positions compared bit for bit, `-0` as `0`, as exporters write a
/// shared vertex split for its normals). A face turned the other way from
/// its neighbours is a component of its own, so its side is chosen apart
/// from theirs; a surface oriented throughout (a room and a table sealed
/// to its floor) is one. Only an edge that one triangle runs each way
/// joins: where more meet (two boxes sharing an edge) or a triangle is
/// degenerate (two corners the same, or no area: it would run an edge
/// both ways), nothing is joined across it. Numbered in the order of
/// their first triangles.
///
/// And per component, whether it is closed: none of its triangles is
/// degenerate and every edge of each is joined, so it bounds a volume
/// whose sign says which way its normals face. A sphere exported with its
/// seam split stays closed where the split corners have the same bits; a
/// box without its lid, or one whose corners differ in their bits, is not.
fn parts(triangles: &[(u32, [Vec3; 3])]) -> Parts {
    let count = triangles.len();
    let mut parent: Vec<u32> = (0..count as u32).collect();
    // Per triangle, whether each of its edges is joined: only an edge one
    // triangle runs each way joins.
    let mut sealed: Vec<bool> = triangles.iter().map(|t| !degenerate(&t.1)).collect();
    for runs in edge_runs(triangles).chunk_by(|a, b| a.edge == b.edge) {
        match runs {
            [one, other] if one.backwards != other.backwards => {
                union(&mut parent, one.triangle, other.triangle)
            }
            _ => runs
                .iter()
                .for_each(|run| sealed[run.triangle as usize] = false),
        }
    }
    // Components numbered in the order of their first triangles.
    let mut number = vec![u32::MAX; count];
    let mut numbered = 0;
    let component: Vec<u32> = (0..count as u32)
        .map(|id| {
            let root = find(&mut parent, id) as usize;
            if number[root] == u32::MAX {
                number[root] = numbered;
                numbered += 1;
            }
            number[root]
        })
        .collect();
    let mut closed = vec![true; numbered as usize];
    for (&c, &sealed) in component.iter().zip(&sealed) {
        closed[c as usize] &= sealed;
    }
    Parts { component, closed }
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        // Path halving.
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    // The smaller root stays: roots do not depend on the order of unions.
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

/// The least share of a part's size by which its corners may leave its
/// plane, or their normals turn from its first triangle's (`1 − cos`), for
/// the part to count as flat.
const FLAT_TOLERANCE: f32 = 1e-5;

/// The least gap behind a flat part, as a share of its size, for its
/// back to be solved too: a light hung a centimetre under a ceiling, or a
/// picture on a wall, keeps its front alone. Their backs face a gap no
/// camera sees, and solved they would undo the open-space test of the
/// surface behind them (`global::BURIED_SHARE`), whose vertices over the
/// gap would then spread its darkness into the texels beside it.
const GAP_SHARE: f32 = 0.1;

/// Rays a flat part sends from its back to measure the gap there.
const GAP_RAYS: usize = 16;

/// Per component of `triangles` (object space, in snapshot order), whether
/// both its sides are solved: it is flat (its triangles share one plane
/// and one orientation, in object space, so that the answer holds in
/// every frame), and behind it, as `meshed` places it (`bvh` over it), lies a surface
/// farther than [`GAP_SHARE`] of its size: the median of the distances
/// along its back normal from up to [`GAP_RAYS`] of its triangles'
/// centres, leaving them by `offset` (a miss counts as no gap: nothing
/// there to light or be lit by, as behind a room's outer wall); and
/// whether its back is open: the flat parts where that median is a miss
/// (their side is then the camera's, [`backs_solved`]).
fn both_sides(
    triangles: &[(u32, [Vec3; 3])],
    component: &[u32],
    (meshed, bvh): (&Snapshot, &SceneBvh),
    offset: RayOffset,
) -> (Vec<bool>, Vec<bool>) {
    let count = component.iter().max().map_or(0, |&c| c as usize + 1);
    let flat = flat_components(triangles, component, count);
    if !flat.contains(&true) || meshed.triangles.len() != triangles.len() {
        return (vec![false; count], vec![false; count]);
    }
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (id, &c) in component.iter().enumerate() {
        if flat[c as usize] {
            members[c as usize].push(id);
        }
    }
    let gaps: Vec<Option<Option<f32>>> = (members.par_iter())
        .map(|ids| (!ids.is_empty()).then(|| gap_behind(bvh, meshed, offset, ids)))
        .collect();
    let both = gaps
        .iter()
        .map(|g| g.flatten().is_some_and(|gap| gap > 0.0));
    let open = gaps.iter().map(|g| g.is_some_and(|gap| gap.is_none()));
    (both.collect(), open.collect())
}

/// How far the median gap behind the flat part of triangles `ids` reaches
/// past [`GAP_SHARE`] of the part's size (positive: both sides solved);
/// `None` where the median ray meets nothing (the part's back is open).
fn gap_behind(bvh: &SceneBvh, meshed: &Snapshot, offset: RayOffset, ids: &[usize]) -> Option<f32> {
    let size = super::global::diagonal(ids.iter().flat_map(|&id| meshed.triangles[id].p));
    let step = ids.len().div_ceil(GAP_RAYS);
    let mut misses = 0;
    let mut gaps: Vec<f32> = ids
        .iter()
        .step_by(step)
        .map(|&id| {
            let tri = &meshed.triangles[id];
            let back = -tri.geometric_normal();
            if back == Vec3::ZERO {
                // Scaled to nothing at time 0: no side to look out of.
                return 0.0;
            }
            let centre = tri.point(1.0 / 3.0, 1.0 / 3.0);
            let origin = offset.origin(centre, back, back);
            let hit = bvh.closest_hit(&crate::backend::Ray::new(origin, back, 0.0, f32::INFINITY));
            if hit.is_hit() {
                hit.t
            } else {
                misses += 1;
                0.0
            }
        })
        .collect();
    // Misses sort first, as gaps of 0: the median is one where most miss.
    let median = gaps.len() / 2;
    gaps.sort_by(f32::total_cmp);
    (median >= misses).then(|| gaps[median] - GAP_SHARE * size)
}

/// Per component, whether its triangles share one plane and one
/// orientation (in object space; a degenerate triangle is not flat), to
/// [`FLAT_TOLERANCE`] of the part's largest edge.
fn flat_components(triangles: &[(u32, [Vec3; 3])], component: &[u32], count: usize) -> Vec<bool> {
    // Per component, the unit normal and offset of its first triangle's
    // plane, and the largest edge seen.
    let mut plane: Vec<Option<(Vec3, f32, f32)>> = vec![None; count];
    let mut flat = vec![true; count];
    for (id, (_, p)) in triangles.iter().enumerate() {
        let c = component[id] as usize;
        let normal = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        let size = crate::scene::longest_edge(p);
        if normal == Vec3::ZERO || !size.is_finite() {
            flat[c] = false;
            continue;
        }
        match &mut plane[c] {
            None => plane[c] = Some((normal, normal.dot(p[0]), size)),
            Some((n0, d0, s0)) => {
                *s0 = s0.max(size);
                let in_plane = p
                    .iter()
                    .all(|q| (n0.dot(*q) - *d0).abs() <= FLAT_TOLERANCE * *s0);
                flat[c] &= in_plane && normal.dot(*n0) >= 1.0 - FLAT_TOLERANCE;
            }
        }
    }
    flat
}

/// Per component, whether its back sides are solved from `snapshot`'s
/// camera: where its winding number around the camera is at least ½,
/// where it is closed (`closed`), the camera outside it and its normals
/// facing in, or where it is a flat part with nothing straight behind
/// it (`open`) and the camera behind it (module docs). Each component's
/// sums run in triangle order, in `f64`, so the choice does not depend on
/// the thread count.
fn backs_solved(
    snapshot: &Snapshot,
    component: &[u32],
    closed: &[bool],
    open: &[bool],
) -> Vec<bool> {
    let eye = snapshot.camera.position.as_dvec3();
    let seen: Vec<(f64, f64)> = (0..snapshot.triangles.len())
        .into_par_iter()
        .map(|i| seen_from(eye, snapshot.triangles[i].p))
        .collect();
    let mut winding = vec![0.0f64; closed.len()];
    let mut volume = vec![0.0f64; closed.len()];
    for (&c, &(omega, cone)) in component.iter().zip(&seen) {
        winding[c as usize] += omega / (4.0 * std::f64::consts::PI);
        volume[c as usize] += cone;
    }
    (0..closed.len())
        .map(|c| {
            let around_camera = winding[c] >= 0.5;
            let outside = winding[c].abs() < 0.5;
            // The cones' volume is positive where the camera is behind.
            around_camera
                || (closed[c] && outside && volume[c] < 0.0)
                || (open[c] && volume[c] > 0.0)
        })
        .collect()
}

/// Triangle `p` seen from `eye`: the solid angle it subtends and the
/// signed volume of the cone from `eye` to it, both positive where `eye`
/// is behind it (its counter-clockwise front faces away).
///
/// The solid angle by Van Oosterom and Strackee's formula (1983):
/// `tan(Ω/2) = a·(b×c) / (|a||b||c| + (a·b)|c| + (a·c)|b| + (b·c)|a|)`,
/// with `a, b, c` the corners less `eye`; zero where `eye` lies in the
/// triangle's plane (seen edge on; on the triangle itself the formula's
/// ±2π would hang on the sign of a zero). The volume is `a·(b×c)/6`:
/// summed over a closed surface it is the volume the surface bounds,
/// wherever `eye` is, positive where its normals face out.
fn seen_from(eye: glam::DVec3, p: [Vec3; 3]) -> (f64, f64) {
    let [a, b, c] = p.map(|q| q.as_dvec3() - eye);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c));
    let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    let omega = 2.0 * numerator.atan2(denominator);
    let omega = if numerator != 0.0 && omega.is_finite() {
        omega
    } else {
        0.0
    };
    (omega, numerator / 6.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn bvh_of(snapshot: &Snapshot) -> SceneBvh {
        let mut bvh = SceneBvh::new();
        bvh.update(snapshot);
        bvh
    }

    /// The two triangles of the quad `o + s·u + t·v`, front along `u × v`.
    fn quad(o: Vec3, u: Vec3, v: Vec3) -> [[Vec3; 3]; 2] {
        [[o, o + u, o + u + v], [o, o + u + v, o + v]]
    }

    /// The unit square's two triangles at `z = 0`, front facing +z.
    fn square() -> [[Vec3; 3]; 2] {
        quad(Vec3::ZERO, Vec3::X, Vec3::Y)
    }

    /// The box `[-1, 1]³`, fronts facing out.
    fn outward_cube() -> Vec<[Vec3; 3]> {
        let (m, x, y, z) = (
            Vec3::splat(-1.0),
            2.0 * Vec3::X,
            2.0 * Vec3::Y,
            2.0 * Vec3::Z,
        );
        [
            quad(m, x, z),
            quad(m + y, z, x),
            quad(m, y, x),
            quad(m + z, x, y),
            quad(m, z, y),
            quad(m + x, y, z),
        ]
        .concat()
    }

    /// A square of side 2s seen along its axis from distance d subtends
    /// `4·asin(s²/(s² + d²))`, negative from its front; a closed box's
    /// triangles sum to 4π from inside (fronts facing out) and to 0 from
    /// outside.
    #[test]
    fn solid_angles_have_their_closed_forms() {
        for d in [100.0f32, 1.0, 1e-3] {
            let exact = 4.0 * (0.25 / (0.25 + f64::from(d).powi(2))).asin();
            let seen = |z: f32| -> f64 {
                let eye = Vec3::new(0.5, 0.5, z);
                square()
                    .iter()
                    .map(|&t| seen_from(eye.as_dvec3(), t).0)
                    .sum()
            };
            assert!(
                (seen(-d) - exact).abs() < 1e-9 * exact.max(1.0),
                "{d}: {}",
                seen(-d)
            );
            assert!(
                (seen(d) + exact).abs() < 1e-9 * exact.max(1.0),
                "{d}: {}",
                seen(d)
            );
        }
        let cube = outward_cube();
        let total =
            |eye: Vec3| -> f64 { cube.iter().map(|&t| seen_from(eye.as_dvec3(), t).0).sum() };
        assert!((total(Vec3::splat(0.1)) - 4.0 * PI).abs() < 1e-9);
        assert!(total(Vec3::new(3.0, 0.2, -1.0)).abs() < 1e-9);
    }

    /// The built-in scenes face their normals into the space the camera
    /// sees (rooms in, solids out), and have no flat part with a gap
    /// behind it: every front alone is solved, at the first, middle and
    /// last frame, as before sides were chosen; the frames of `movies`
    /// there did not change.
    #[test]
    fn built_in_scenes_solve_their_fronts() {
        for name in crate::scene::builtin::NAMES {
            let scene = crate::scene::Scene::builtin(name).unwrap();
            let meshed = scene.snapshot(0.0);
            for frame in [0, scene.frame_count / 2, scene.frame_count - 1] {
                let snapshot = scene.snapshot(frame as f32 / crate::scene::DEFAULT_FPS);
                let corners = object_space_corners(&scene, &meshed);
                let sides = SolvedSides::new(
                    &corners,
                    &snapshot,
                    (&meshed, &bvh_of(&meshed)),
                    RayOffset::UNIT_FLOOR,
                );
                assert!(!sides.back.contains(&true), "{name} frame {frame}");
                assert!(!sides.both.contains(&true), "{name}: both sides of a part");
                assert!(sides.back.len() > 1, "{name}: one component");
            }
        }
    }

    /// Components: the two triangles of a quad share an edge and are one;
    /// a second quad apart is another, and so is a third at the first's
    /// place on another object. An outward cube around the camera solves
    /// its backs; moved away from the camera, its fronts (`update` says
    /// which changed). A flat quad keeps its front from either side.
    #[test]
    fn components_and_their_sides() {
        let triangles: Vec<[Vec3; 3]> = [
            square().to_vec(),
            quad(Vec3::new(5.0, 0.0, 0.0), Vec3::Y, Vec3::X).to_vec(),
            square().to_vec(),
            outward_cube(),
        ]
        .concat();
        let objects: Vec<u32> = [[0; 4].to_vec(), vec![1, 1], vec![2; 12]].concat();
        let mut snapshot = snapshot_of(&triangles, &objects, Vec3::new(0.3, 0.2, -0.5));
        assert_eq!(
            parts(&tagged(&triangles, &objects)).component,
            [[0, 0, 1, 1, 2, 2].to_vec(), vec![3; 12]].concat()
        );
        let sides = sides_of(&triangles, &objects, &snapshot);
        // The eye is just behind the first and third squares, in front of
        // the second, and inside the cube.
        assert_eq!(sides.back, [false, false, false, true]);
        assert!(sides.back(17) && !sides.back(2) && !sides.back(5));
        let mut updated = sides.clone();
        assert_eq!(updated.update(&snapshot), [false; 4]);
        snapshot.camera.position = Vec3::new(0.3, 0.2, 4.0);
        assert_eq!(updated.update(&snapshot), [false, false, false, true]);
        assert_eq!(updated.back, [false; 4]);
        assert_eq!(updated, sides_of(&triangles, &objects, &snapshot));
    }

    /// The cube without its top, fronts out: around a camera inside it
    /// (the open top wraps less than half the sphere of directions) its
    /// backs are solved; seen from above, through the opening, from the
    /// side, or from a point on one of its walls, its fronts.
    #[test]
    fn an_open_box_is_solved_inside_only_around_the_camera() {
        let mut open = outward_cube();
        open.drain(2..4); // the top, +y
        let objects = vec![0; open.len()];
        let back_at =
            |eye: Vec3| sides_of(&open, &objects, &snapshot_of(&open, &objects, eye)).back;
        assert_eq!(back_at(Vec3::new(0.2, -0.3, 0.1)), [true]);
        assert_eq!(back_at(Vec3::new(0.2, 0.7, 0.1)), [true]);
        for eye in [
            Vec3::new(0.2, 3.0, 0.1),
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ] {
            assert_eq!(back_at(eye), [false], "{eye}");
        }
    }

    /// Closed parts: the cube, either way round; not the cube without its
    /// top, or a square. Around the camera the cube solves the side facing
    /// in; seen from outside, the side facing out, also where its fronts
    /// face in (an inside-out ball or block). The open box facing in, seen
    /// from outside, keeps its fronts (the inside seen through its top).
    #[test]
    fn a_closed_part_solves_the_side_the_camera_space_faces() {
        let outward = outward_cube();
        let inward: Vec<[Vec3; 3]> = outward.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let mut open = inward.clone();
        open.drain(2..4);
        let triangles = [outward.clone(), inward.clone(), open, square().to_vec()].concat();
        let objects: Vec<u32> = [vec![0; 12], vec![1; 12], vec![2; 10], vec![3; 2]].concat();
        let tagged = tagged(&triangles, &objects);
        assert_eq!(parts(&tagged).closed, [true, true, false, false]);
        let back_at = |cube: &[[Vec3; 3]], eye: Vec3| {
            let objects = vec![0; cube.len()];
            sides_of(cube, &objects, &snapshot_of(cube, &objects, eye)).back
        };
        let (inside, outside) = (Vec3::new(0.2, -0.3, 0.1), Vec3::new(0.5, 0.3, 4.0));
        assert_eq!(back_at(&outward, inside), [true]);
        assert_eq!(back_at(&outward, outside), [false]);
        assert_eq!(back_at(&inward, inside), [false]);
        assert_eq!(back_at(&inward, outside), [true]);
        let mut open = inward;
        open.drain(2..4);
        assert_eq!(back_at(&open, Vec3::new(0.2, 3.0, 0.1)), [false]);
    }

    /// A cube with one face turned inward: that face is a component of
    /// its own (its edges run the way its neighbours' do), and so is a
    /// quad that touches the cube at a corner only. From inside the cube
    /// every solved side faces the camera's space: the backs of the faces
    /// turned out, the front of the face turned in.
    #[test]
    fn a_face_turned_the_other_way_is_chosen_apart() {
        let mut cube = outward_cube();
        for t in &mut cube[6..8] {
            t.swap(1, 2);
        }
        let corner = quad(Vec3::ONE, Vec3::X, Vec3::Y).to_vec();
        let triangles = [cube, corner].concat();
        let snapshot = snapshot_of(&triangles, &[0; 14], Vec3::new(0.3, 0.2, -0.5));
        let c = parts(&tagged(&triangles, &[0; 14])).component;
        let expected: Vec<u32> = [[0; 6].to_vec(), vec![1, 1], vec![0; 4], vec![2, 2]].concat();
        assert_eq!(c, expected);
        let sides = sides_of(&triangles, &[0; 14], &snapshot);
        for (id, t) in triangles.iter().enumerate().take(12) {
            let solved = (t[1] - t[0]).cross(t[2] - t[0]) * sides.sign(id as u32);
            let centre = (t[0] + t[1] + t[2]) / 3.0;
            let towards_eye = snapshot.camera.position - centre;
            assert!(solved.dot(towards_eye) > 0.0, "triangle {id}");
        }
    }

    /// Two quads sharing an edge the same way round are one component; a
    /// degenerate triangle along that edge (it runs it both ways) is one
    /// of its own and joins nothing; a third quad on the edge (three meet
    /// there) leaves all three apart.
    #[test]
    fn only_an_edge_run_once_each_way_joins() {
        let (x, xy) = (Vec3::X, Vec3::new(1.0, 1.0, 0.0));
        let second = quad(Vec3::X, Vec3::X, Vec3::Y).to_vec();
        let sliver = vec![[x, xy, xy]];
        let joined = [square().to_vec(), second.clone(), sliver.clone()].concat();
        assert_eq!(parts(&tagged(&joined, &[0; 5])).component, [0, 0, 0, 0, 1]);
        let fin = quad(Vec3::X, Vec3::Z, Vec3::Y).to_vec();
        let three = [square().to_vec(), second, fin].concat();
        assert_eq!(
            parts(&tagged(&three, &[0; 6])).component,
            [0, 0, 1, 1, 2, 2]
        );
    }

    /// `triangles` on `objects`, as [`components`] takes them.
    fn tagged(triangles: &[[Vec3; 3]], objects: &[u32]) -> Vec<(u32, [Vec3; 3])> {
        objects
            .iter()
            .copied()
            .zip(triangles.iter().copied())
            .collect()
    }

    /// The sides of `triangles` on `objects` from `snapshot`'s camera.
    fn sides_of(triangles: &[[Vec3; 3]], objects: &[u32], snapshot: &Snapshot) -> SolvedSides {
        let tagged = tagged(triangles, objects);
        let parts = parts(&tagged);
        let none = vec![false; parts.closed.len()];
        SolvedSides::of_parts(parts, (none.clone(), none), snapshot)
    }

    /// A snapshot of `triangles` on `objects`, its camera at `eye`.
    fn snapshot_of(triangles: &[[Vec3; 3]], objects: &[u32], eye: Vec3) -> Snapshot {
        let scene = crate::scene::Scene::builtin("cube-in-box").unwrap();
        let mut snapshot = scene.snapshot(0.0);
        snapshot.triangles = triangles
            .iter()
            .map(|&p| crate::scene::Triangle {
                p,
                n: [Vec3::ZERO; 3],
            })
            .collect();
        snapshot.tri_object = objects.to_vec().into();
        snapshot.static_count = triangles.len();
        snapshot.camera.position = eye;
        snapshot
    }

    /// Flat parts: a square, and two squares side by side in its plane;
    /// not a square folded along its diagonal, the cube, or a triangle
    /// with no area.
    #[test]
    fn flat_parts_are_found_in_their_plane() {
        let mut folded = square();
        folded[1][2].z = 0.1;
        let two = [square(), quad(Vec3::X, Vec3::X, Vec3::Y)].concat();
        let sliver = vec![[Vec3::ZERO, Vec3::X, Vec3::X * 2.0]];
        let parts: Vec<Vec<[Vec3; 3]>> = vec![
            square().to_vec(),
            two,
            folded.to_vec(),
            outward_cube(),
            sliver,
        ];
        let mut triangles = Vec::new();
        let mut component = Vec::new();
        for (c, part) in parts.iter().enumerate() {
            triangles.extend(part.iter().map(|&t| (c as u32, t)));
            component.extend(std::iter::repeat_n(c as u32, part.len()));
        }
        assert_eq!(
            flat_components(&triangles, &component, parts.len()),
            [true, true, false, false, false]
        );
    }

    /// On open ground (a square 6 across), a wall 3 high facing away from
    /// the camera: nothing lies straight behind either, so each is solved
    /// on the side the camera is on, the wall on its back; so is the
    /// ground, turned to face down.
    #[test]
    fn a_wall_on_open_ground_is_solved_on_the_cameras_side() {
        let wall = quad(Vec3::new(1.0, 0.0, -3.0), 3.0 * Vec3::Y, 6.0 * Vec3::Z);
        let eye = Vec3::new(-2.0, 2.0, 0.0);
        for facing_up in [true, false] {
            let (u, v) = (6.0 * Vec3::Z, 6.0 * Vec3::X);
            let (u, v) = if facing_up { (u, v) } else { (v, u) };
            let ground = quad(Vec3::new(-3.0, 0.0, -3.0), u, v);
            let triangles = [ground.to_vec(), wall.to_vec()].concat();
            let objects = vec![0, 0, 1, 1];
            let tagged = tagged(&triangles, &objects);
            let parts = parts(&tagged);
            let snapshot = snapshot_of(&triangles, &objects, eye);
            let bvh = bvh_of(&snapshot);
            let offset = RayOffset::UNIT_FLOOR;
            let (both, open) = both_sides(&tagged, &parts.component, (&snapshot, &bvh), offset);
            assert_eq!((&both[..], &open[..]), (&[false; 2][..], &[true; 2][..]));
            let sides = SolvedSides::of_parts(parts, (both, open), &snapshot);
            assert_eq!([sides.back(0), sides.back(2)], [!facing_up, true]);
        }
    }

    /// In the room `[-1, 1]³`: both sides of a partition across it (the
    /// wall behind it 1 away, a tenth of its size is 0.25); one of a panel
    /// a hundredth under the ceiling, facing down; one of a square
    /// outside the room facing it, with nothing behind (open there); one
    /// of the room (not flat).
    #[test]
    fn both_sides_of_a_partition_one_of_a_panel_under_the_ceiling() {
        let partition = quad(Vec3::new(0.0, -1.0, -1.0), 1.5 * Vec3::Y, 2.0 * Vec3::Z);
        let panel = quad(Vec3::new(-0.2, 0.99, -0.2), 0.4 * Vec3::X, 0.4 * Vec3::Z);
        let outside = quad(Vec3::new(3.0, -0.5, -0.5), Vec3::Z, Vec3::Y);
        let triangles = [
            outward_cube(),
            partition.to_vec(),
            panel.to_vec(),
            outside.to_vec(),
        ]
        .concat();
        let objects: Vec<u32> = [vec![0; 12], vec![1; 2], vec![2; 2], vec![3; 2]].concat();
        let tagged = tagged(&triangles, &objects);
        let component = parts(&tagged).component;
        let snapshot = snapshot_of(&triangles, &objects, Vec3::new(0.5, 0.0, 0.5));
        let (both, open) = both_sides(
            &tagged,
            &component,
            (&snapshot, &bvh_of(&snapshot)),
            RayOffset::UNIT_FLOOR,
        );
        assert_eq!(both, [false, true, false, false]);
        // The square outside has nothing straight behind it.
        assert_eq!(open, [false, false, false, true]);
    }
}
