//! Geometry helpers of the built-in scenes. Front faces are
//! counter-clockwise (glTF), and flat faces carry their face normal at
//! every vertex.

use super::super::Mesh;
use glam::Vec3;
use std::f32::consts::{PI, TAU};

/// Appends the parallelogram `origin, origin+u, origin+u+v, origin+v` as two
/// triangles whose front face and normal point along `u × v`.
fn push_quad(mesh: &mut Mesh, origin: Vec3, u: Vec3, v: Vec3, material: u32) {
    let normal = u.cross(v).normalize();
    let base = mesh.positions.len() as u32;
    mesh.positions
        .extend([origin, origin + u, origin + u + v, origin + v]);
    mesh.normals.extend([normal; 4]);
    mesh.triangles
        .extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
    mesh.materials.extend([material; 2]);
}

/// Which way the faces of [`push_box`] look: out of a solid, or into a room.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Facing {
    Outward,
    Inward,
}

/// Appends the faces of the axis-aligned box `[min, max]`. `materials` is
/// indexed −X, +X, −Y, +Y, −Z, +Z (for a room: left, right, floor, ceiling,
/// back, front); `None` leaves that face out.
pub(super) fn push_box(
    mesh: &mut Mesh,
    min: Vec3,
    max: Vec3,
    facing: Facing,
    materials: [Option<u32>; 6],
) {
    let size = max - min;
    for axis in 0..3 {
        // Cyclic order: e_b × e_c = e_axis.
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let u = Vec3::AXES[b] * size[b];
        let v = Vec3::AXES[c] * size[c];
        for positive in [false, true] {
            let Some(material) = materials[2 * axis + usize::from(positive)] else {
                continue;
            };
            let mut origin = min;
            if positive {
                origin[axis] = max[axis];
            }
            // The +axis face of a solid and the −axis face of a room look along +axis.
            if positive == (facing == Facing::Outward) {
                push_quad(mesh, origin, u, v, material);
            } else {
                push_quad(mesh, origin, v, u, material);
            }
        }
    }
}

/// A solid box of half extents `half` centred on the origin.
pub(super) fn cuboid(half: Vec3, material: u32) -> Mesh {
    let mut mesh = Mesh::default();
    push_box(&mut mesh, -half, half, Facing::Outward, [Some(material); 6]);
    mesh
}

/// A square emitter of side `size` centred on the origin, its front (the
/// emitting side) facing down, to hang under a ceiling.
pub(super) fn light_panel(size: f32, material: u32) -> Mesh {
    let mut mesh = Mesh::default();
    let h = 0.5 * size;
    // X × Z = −Y: the front face looks down.
    push_quad(
        &mut mesh,
        Vec3::new(-h, 0.0, -h),
        Vec3::X * size,
        Vec3::Z * size,
        material,
    );
    mesh
}

/// Tiles the floor (y = `min.y`) of `[min, max]` with `tile`-sized quads
/// facing up, alternating the two materials.
pub(super) fn push_checkerboard(
    mesh: &mut Mesh,
    min: Vec3,
    max: Vec3,
    tile: f32,
    materials: [u32; 2],
) {
    let columns = ((max.x - min.x) / tile).round() as usize;
    let rows = ((max.z - min.z) / tile).round() as usize;
    // Vertices are computed from the bounds (not by accumulating `tile`), so
    // that neighbouring tiles share exact edges and the floor has no cracks.
    let x_at = |i: usize| min.x + (max.x - min.x) * i as f32 / columns as f32;
    let z_at = |j: usize| min.z + (max.z - min.z) * j as f32 / rows as f32;
    for j in 0..rows {
        for i in 0..columns {
            let origin = Vec3::new(x_at(i), min.y, z_at(j));
            let u = Vec3::Z * (z_at(j + 1) - z_at(j));
            let v = Vec3::X * (x_at(i + 1) - x_at(i));
            // Z × X = +Y: the tiles face up into the room.
            push_quad(mesh, origin, u, v, materials[(i + j) % 2]);
        }
    }
}

/// A unit UV sphere centred on the origin with smooth normals: `rings`
/// bands from pole to pole, `segments` around +Y, triangle fans at the poles
/// (no degenerate triangles): `2·segments·(rings − 1)` triangles.
pub(super) fn uv_sphere(segments: u32, rings: u32, material: u32) -> Mesh {
    let point = |theta: f32, phi: f32| {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    };
    let mut positions = vec![Vec3::Y];
    for ring in 1..rings {
        let theta = PI * ring as f32 / rings as f32;
        for segment in 0..segments {
            positions.push(point(theta, TAU * segment as f32 / segments as f32));
        }
    }
    positions.push(-Vec3::Y);
    let south = positions.len() as u32 - 1;
    // Vertex `segment` of ring `ring` (1..rings), wrapping around.
    let vertex = |ring: u32, segment: u32| 1 + (ring - 1) * segments + segment % segments;
    let mut triangles = Vec::new();
    for s in 0..segments {
        // With φ growing and θ (southward) growing, (p, p+φ, p+south) is
        // counter-clockwise seen from outside.
        triangles.push([0, vertex(1, s + 1), vertex(1, s)]);
        for ring in 1..rings - 1 {
            let (a, b) = (vertex(ring, s), vertex(ring, s + 1));
            let (c, d) = (vertex(ring + 1, s), vertex(ring + 1, s + 1));
            triangles.push([a, b, c]);
            triangles.push([b, d, c]);
        }
        triangles.push([vertex(rings - 1, s), vertex(rings - 1, s + 1), south]);
    }
    Mesh {
        normals: positions.clone(),
        materials: vec![material; triangles.len()],
        positions,
        triangles,
    }
}
