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
//! its fronts, as before. A flat part never winds ½ around any point, so
//! a shelf, a panel or a picture keeps its front from wherever it is seen
//! (choosing by the side the camera sees turned a shelf seen from below
//! to its dark underside, and the room lost the light its top bounces).
//! Solving both sides is not done: it would double the links within the
//! same budget and leave the inside of every solid to solve. A room whose
//! walls are separate objects facing out is not mended (no wall encloses
//! the camera), nor a box facing out seen from outside through its open
//! side, nor one whose walls meet at edges whose corners differ in their
//! bits: their insides get their direct light only. A face turned the
//! other way from its neighbours is a component of its own.
//!
//! The choice is a function of the frame (its camera and geometry), so a
//! pass that starts at any frame makes the same one. Where a component's
//! side changes (the camera walks into a room through its wall or its
//! open side), the global pass traces again the links from its vertices
//! and those landing on it, and finds its static shadows again.

use crate::scene::{Scene, Snapshot};
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;

/// The side the global pass solves of each triangle of a snapshot.
#[derive(Clone, Debug, PartialEq)]
pub struct SolvedSides {
    /// Per triangle, its component.
    component: Vec<u32>,
    /// Per component, whether its back sides are solved.
    back: Vec<bool>,
}

impl SolvedSides {
    /// The components of `scene`'s triangles (found in object space, so
    /// the same whatever frame they are found at, also where an object is
    /// scaled to nothing) and the sides `snapshot`'s camera sets.
    pub fn new(scene: &Scene, snapshot: &Snapshot) -> Self {
        Self::of_components(components(&object_space_triangles(scene)), snapshot)
    }

    fn of_components(component: Vec<u32>, snapshot: &Snapshot) -> Self {
        let count = component.iter().max().map_or(0, |&c| c as usize + 1);
        let back = backs_solved(snapshot, &component, count);
        SolvedSides { component, back }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.component[..]) + std::mem::size_of_val(&self.back[..])
    }

    /// Takes the sides `snapshot`'s camera sets (it holds the same
    /// triangles); returns, per component, whether its side changed.
    pub fn update(&mut self, snapshot: &Snapshot) -> Vec<bool> {
        let back = backs_solved(snapshot, &self.component, self.back.len());
        let changed = back.iter().zip(&self.back).map(|(a, b)| a != b).collect();
        self.back = back;
        changed
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

/// Every triangle of `scene` in snapshot order (the order of
/// [`Scene::object_order`]), with its object and its corners in the
/// object's own space.
fn object_space_triangles(scene: &Scene) -> Vec<(u32, [Vec3; 3])> {
    let mut out = Vec::new();
    for object in scene.object_order() {
        let mesh = &scene.objects[object].mesh;
        out.extend(mesh.triangles.iter().map(|t| {
            // A corner the mesh lacks is a malformed mesh's; the loader
            // refuses those, so it only keeps this from panicking.
            let corner = |i: u32| mesh.positions.get(i as usize).copied().unwrap_or(Vec3::NAN);
            (object as u32, t.map(corner))
        }));
    }
    out
}

/// An edge of an object's triangle, from corner to corner (their bits).
type DirectedEdge = (u32, [u32; 3], [u32; 3]);

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
fn components(triangles: &[(u32, [Vec3; 3])]) -> Vec<u32> {
    let count = triangles.len();
    let bits = |q: Vec3| (q + Vec3::ZERO).to_array().map(f32::to_bits);
    let degenerate = |p: &[Vec3; 3]| (p[1] - p[0]).cross(p[2] - p[0]).length_squared() == 0.0;
    let edges = |id: usize| {
        let (object, p) = &triangles[id];
        (0..3).map(move |k| (*object, bits(p[k]), bits(p[(k + 1) % 3])))
    };
    // Per directed edge, its first triangle and how many run it.
    let mut along: HashMap<DirectedEdge, (u32, u32)> = HashMap::new();
    let whole: Vec<usize> = (0..count)
        .filter(|&id| !degenerate(&triangles[id].1))
        .collect();
    for &id in &whole {
        for edge in edges(id) {
            along.entry(edge).or_insert((id as u32, 0)).1 += 1;
        }
    }
    let mut parent: Vec<u32> = (0..count as u32).collect();
    for &id in &whole {
        for edge in edges(id) {
            let (object, a, b) = edge;
            match (along.get(&edge), along.get(&(object, b, a))) {
                (Some(&(_, 1)), Some(&(other, 1))) => union(&mut parent, id as u32, other),
                _ => continue,
            }
        }
    }
    let mut number: HashMap<u32, u32> = HashMap::new();
    (0..count as u32)
        .map(|id| {
            let root = find(&mut parent, id);
            let next = number.len() as u32;
            *number.entry(root).or_insert(next)
        })
        .collect()
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

/// Per component, whether its back sides are solved from `snapshot`'s
/// camera: where its winding number around the camera is at least ½
/// (module docs). Each component's sum runs in triangle order, in `f64`,
/// so the choice does not depend on the thread count.
fn backs_solved(snapshot: &Snapshot, component: &[u32], count: usize) -> Vec<bool> {
    let eye = snapshot.camera.position.as_dvec3();
    let angles: Vec<f64> = snapshot
        .triangles
        .par_iter()
        .map(|t| signed_solid_angle(eye, t.p))
        .collect();
    let mut winding = vec![0.0f64; count];
    for (&c, &omega) in component.iter().zip(&angles) {
        winding[c as usize] += omega / (4.0 * std::f64::consts::PI);
    }
    winding.into_iter().map(|w| w >= 0.5).collect()
}

/// The solid angle triangle `p` subtends at `eye`, positive where `eye`
/// is behind it (its counter-clockwise front faces away), by Van Oosterom
/// and Strackee's formula (1983): `tan(Ω/2) = a·(b×c) / (|a||b||c| +
/// (a·b)|c| + (a·c)|b| + (b·c)|a|)`, with `a, b, c` the corners less `eye`.
/// Zero where `eye` lies in the triangle's plane (seen edge on; on the
/// triangle itself the formula's ±2π would hang on the sign of a zero).
fn signed_solid_angle(eye: glam::DVec3, p: [Vec3; 3]) -> f64 {
    let [a, b, c] = p.map(|q| q.as_dvec3() - eye);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c));
    let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    let omega = 2.0 * numerator.atan2(denominator);
    if numerator != 0.0 && omega.is_finite() {
        omega
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

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
                    .map(|&t| signed_solid_angle(eye.as_dvec3(), t))
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
        let total = |eye: Vec3| -> f64 {
            cube.iter()
                .map(|&t| signed_solid_angle(eye.as_dvec3(), t))
                .sum()
        };
        assert!((total(Vec3::splat(0.1)) - 4.0 * PI).abs() < 1e-9);
        assert!(total(Vec3::new(3.0, 0.2, -1.0)).abs() < 1e-9);
    }

    /// The built-in scenes face their normals into the space the camera
    /// sees (rooms in, solids out): every front is solved, at the first,
    /// middle and last frame, as before sides were chosen; the frames of
    /// `movies` there did not change.
    #[test]
    fn built_in_scenes_solve_their_fronts() {
        for name in crate::scene::builtin::NAMES {
            let scene = crate::scene::Scene::builtin(name).unwrap();
            for frame in [0, scene.frame_count / 2, scene.frame_count - 1] {
                let snapshot = scene.snapshot(frame as f32 / crate::scene::DEFAULT_FPS);
                let sides = SolvedSides::new(&scene, &snapshot);
                assert!(!sides.back.contains(&true), "{name} frame {frame}");
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
            components(&tagged(&triangles, &objects)),
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
        let c = components(&tagged(&triangles, &[0; 14]));
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
        assert_eq!(components(&tagged(&joined, &[0; 5])), [0, 0, 0, 0, 1]);
        let fin = quad(Vec3::X, Vec3::Z, Vec3::Y).to_vec();
        let three = [square().to_vec(), second, fin].concat();
        assert_eq!(components(&tagged(&three, &[0; 6])), [0, 0, 1, 1, 2, 2]);
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
        SolvedSides::of_components(components(&tagged(triangles, objects)), snapshot)
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
        snapshot.tri_object = objects.to_vec();
        snapshot.camera.position = eye;
        snapshot
    }
}
