//! The global pass's triangles that are too large for one grid, split into
//! pieces where the camera looks ([`super::global`]).
//!
//! The pass grids a triangle with at most
//! [`MAX_GRID`](super::mesh::MAX_GRID) cells an edge. A triangle far
//! larger than that many spacings (a ground of two triangles under a
//! house) was one coarse grid, whose cells, metres across, smeared the
//! light a wall bounces onto the ground beside it: `movies` rendered a
//! sunlit corner on a ground 60 m and 600 m across at 0.055 and 0.075
//! relative RMSE against `path`, `ic` at 0.018
//! (`tests/directional_light.rs`).
//!
//! Such a triangle is now split in four at its edges' midpoints, as
//! [`super::patch`] splits a movie, and each piece again, while a piece is
//! still over the cap at the spacing wanted where it lies: the pass's
//! spacing at what the camera sees of the triangle, and that spacing times
//! `1 + d / size` at a distance `d` from it (`size` the view's), so that
//! far away a cell spans about the same angle seen from the view. Keeping
//! the pass's spacing out to a view's size, `max(1, d / size)`, took 2–3
//! times the links on the tests' grounds for errors within 5 % of these,
//! and crowded out the rest of the scene under the pass's budget where the
//! camera travels. The paper refines its hierarchy by the links' error;
//! this grades the mesh by where the viewer is, as importance-driven
//! radiosity does (Smits, Arvo & Salesin 1992), and leaves a triangle
//! within the cap one grid, as before.
//!
//! What the camera sees ([`super::view`]) is taken at time 0 and at eight
//! times over the animation, in the scene as it stands at time 0, as the
//! pass is meshed ([`super::global::MESHED_AT`]): a camera that travels over a large
//! ground has it split along its way. The spacing and the size the
//! distance is measured in stay those of time 0. A triangle the camera
//! does not see is not split: it only sends light, which a vertex's links
//! average over, and refining it only took links from the triangles seen
//! (a 2 km ground hidden under a room coarsened the room's grids as the
//! pass kept to its budget, `tests/movies.rs`: block bias 0.017 → 0.027).
//!
//! Pieces meet as triangles do: corners and the vertices along a shared
//! edge are one vertex where both sides grid it alike; where a piece meets
//! a finer one, the finer one's edge vertices are not the coarser one's
//! (a T-junction: the Gouraud shading steps there, as it does between
//! triangles of unlike grids).

use super::mesh::Grid;
use super::patch::{child_at, from_parent, to_parent};
use crate::scene::Triangle;
use glam::Vec3;

/// Deepest split: a piece a 4096th of its triangle's edge.
pub const MAX_DEPTH: u32 = 12;

/// A piece of a triangle: its corners' barycentrics `(u, v)` in the
/// triangle, corner `k` of the piece at its own `(s, t)` of
/// `(0, 0)`, `(1, 0)`, `(0, 1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Piece {
    pub corners: [(f32, f32); 3],
    pub depth: u32,
}

impl Piece {
    /// The whole triangle.
    pub const WHOLE: Piece = Piece {
        corners: [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)],
        depth: 0,
    };

    /// The triangle's `(u, v)` at the piece's `(s, t)`.
    pub fn to_triangle(&self, (s, t): (f32, f32)) -> (f32, f32) {
        let [c0, c1, c2] = self.corners;
        (
            c0.0 + s * (c1.0 - c0.0) + t * (c2.0 - c0.0),
            c0.1 + s * (c1.1 - c0.1) + t * (c2.1 - c0.1),
        )
    }

    /// Its four children, numbered as [`super::patch`] numbers a patch's.
    /// Their corners are the parent's corners and edge midpoints, exact
    /// (dyadic) barycentrics, so neighbours agree on them bit for bit.
    pub fn children(&self) -> [Piece; 4] {
        let corner = |k: u8, local: (f32, f32)| self.to_triangle(to_parent(k, local));
        let child = |k: u8| Piece {
            corners: [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)].map(|c| corner(k, c)),
            depth: self.depth + 1,
        };
        [child(0), child(1), child(2), child(3)]
    }

    /// Its corners in the world, on triangle `tri`.
    pub fn world_corners(&self, tri: &Triangle) -> [Vec3; 3] {
        self.corners.map(|c| on_triangle(tri, c))
    }

    /// The triangle's `(u, v)` of grid vertex `(a, b)` of an `n`-segment
    /// grid over the piece. The whole triangle's are `(a/n, b/n)`; a
    /// piece's on an edge are found from the edge's ends taken in one
    /// order, so that the piece across the edge, gridded alike, finds
    /// the same bits.
    pub fn grid_point(&self, n: u32, a: u32, b: u32) -> (f32, f32) {
        if *self == Piece::WHOLE {
            return (a as f32 / n as f32, b as f32 / n as f32);
        }
        let c = self.corners;
        let along = |from: (f32, f32), to: (f32, f32), k: u32| {
            let ((p, q), k) = if bits(from) <= bits(to) {
                ((from, to), k)
            } else {
                ((to, from), n - k)
            };
            let f = k as f32 / n as f32;
            (p.0 + (q.0 - p.0) * f, p.1 + (q.1 - p.1) * f)
        };
        match (a, b) {
            (_, 0) => along(c[0], c[1], a),
            (0, _) => along(c[0], c[2], b),
            _ if a + b == n => along(c[1], c[2], b),
            _ => self.to_triangle((a as f32 / n as f32, b as f32 / n as f32)),
        }
    }
}

/// The bits of barycentrics, to compare and key them exactly.
pub fn bits((u, v): (f32, f32)) -> (u32, u32) {
    (u.to_bits(), v.to_bits())
}

/// The point at barycentrics `(u, v)` of `tri` (its corners exactly at
/// the corners' barycentrics).
pub fn on_triangle(tri: &Triangle, (u, v): (f32, f32)) -> Vec3 {
    tri.p[0] * (1.0 - u - v) + tri.p[1] * u + tri.p[2] * v
}

/// How one side of a triangle is gridded: one grid over all of it or a
/// piece of it, or split in four, its children at `pieces[i..i + 4]` of
/// the pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cells {
    Grid(Grid),
    Split(u32),
}

/// The grid over triangle barycentrics `(u, v)` in the tiling whose root
/// is `root` (children in `pieces`), and the point's `(s, t)` in it.
pub fn leaf(pieces: &[Cells], root: Cells, (u, v): (f32, f32)) -> (Grid, (f32, f32)) {
    let (mut cells, mut local) = (root, (u, v));
    loop {
        match cells {
            Cells::Grid(grid) => return (grid, local),
            Cells::Split(first) => {
                let k = child_at(local);
                local = from_parent(k, local);
                cells = pieces[first as usize + k as usize];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Children tile their parent, and a point found by the descent maps
    /// back to itself through the pieces' corners.
    #[test]
    fn the_descent_finds_the_piece_that_holds_the_point() {
        let mut pieces = Vec::new();
        // The whole split once, its child 3 (the middle) again.
        let root = Cells::Split(0);
        for k in 0..4u32 {
            pieces.push(if k == 3 {
                Cells::Split(4)
            } else {
                Cells::Grid(Grid { n: 1, first: k })
            });
        }
        for k in 0..4u32 {
            pieces.push(Cells::Grid(Grid {
                n: 1,
                first: 10 + k,
            }));
        }
        let middle = Piece::WHOLE.children()[3];
        for i in 0..=30 {
            for j in 0..=30 - i {
                let (u, v) = (i as f32 / 30.0, j as f32 / 30.0);
                let (grid, local) = leaf(&pieces, root, (u, v));
                let piece = match grid.first {
                    f @ 0..=2 => Piece::WHOLE.children()[f as usize],
                    f => middle.children()[(f - 10) as usize],
                };
                let back = piece.to_triangle(local);
                assert!(
                    (back.0 - u).abs() < 1e-5 && (back.1 - v).abs() < 1e-5,
                    "({u}, {v})"
                );
                assert!(local.0 >= -1e-5 && local.1 >= -1e-5 && local.0 + local.1 <= 1.0 + 1e-5);
            }
        }
    }

    /// Two pieces across an edge, gridded alike, put the same bits at the
    /// edge's vertices, whichever way round each walks it.
    #[test]
    fn pieces_across_an_edge_agree_on_its_vertices() {
        let [c0, _, _, middle] = Piece::WHOLE.children();
        // Child 0's edge from corner 1 to corner 2 is the middle's edge
        // from corner 1 to corner 2, walked the other way.
        let n = 7;
        for k in 0..=n {
            let on_0 = c0.grid_point(n, n - k, k);
            let on_middle = middle.grid_point(n, k, n - k);
            assert_eq!(bits(on_0), bits(on_middle), "vertex {k}");
        }
    }
}
