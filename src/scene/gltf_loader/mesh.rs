//! Mesh objects: each mesh node's triangle primitives merged into one
//! [`Mesh`] (strips and fans triangulated, triangles without area and
//! repeated triangles dropped, missing normals computed), and a skinned
//! mesh carried rigidly by its first joint.

use super::accessors::Buffers;
use super::nodes::{node_name, Hierarchy};
use super::{check_coordinates, Res};
use crate::scene::{Material, Mesh, Object};
use glam::{Mat4, Vec3};
use gltf::accessor::Dimensions;
use gltf::mesh::{Mode, Semantic};

/// Albedo of the material given to primitives that have none.
const DEFAULT_ALBEDO: f32 = 0.8;

pub(super) fn build_objects(
    gnodes: &[gltf::Node],
    hierarchy: &Hierarchy,
    buffers: &Buffers,
    materials: &mut Vec<Material>,
) -> Res<Vec<Object>> {
    let mut default_material = None;
    let mut objects = Vec::new();
    for (node, gnode) in gnodes.iter().enumerate() {
        let Some(mesh) = gnode.mesh() else { continue };
        let name = node_name(gnode);
        let mut mesh = build_mesh(&mesh, buffers, materials, &mut default_material)
            .map_err(|e| format!("mesh of node '{name}': {e}"))?;
        let node = match gnode.skin() {
            Some(skin) => rigid_skin(&skin, hierarchy, buffers, &mut mesh)
                .map_err(|e| format!("skin of node '{name}': {e}"))?
                .unwrap_or(node),
            None => node,
        };
        objects.push(Object { name, node, mesh });
    }
    Ok(objects)
}

/// A skinned mesh without its skinning (which is not read): glTF places it
/// by its joints alone, never by its own node's transform (§3.7.3.3). It is
/// carried rigidly by its first joint: its vertices are taken into that
/// joint's space by the joint's inverse bind matrix, so that at the bind
/// pose they lie where the file put them, and the mesh then follows the
/// joint's animation. Returns that joint's node (`None`: the joint is not
/// in the scene, and the mesh stays on its own node). A mirrored joint
/// keeps the mesh's front faces.
fn rigid_skin(
    skin: &gltf::Skin,
    hierarchy: &Hierarchy,
    buffers: &Buffers,
    mesh: &mut Mesh,
) -> Res<Option<usize>> {
    let Some(joint) = skin.joints().next() else {
        return Ok(None);
    };
    let Some(&node) = hierarchy.ours.get(&joint.index()) else {
        return Ok(None);
    };
    let inverse_bind = match skin.inverse_bind_matrices() {
        Some(acc) => {
            let m = buffers.floats(&acc, Dimensions::Mat4, "inverseBindMatrices")?;
            Mat4::from_cols_slice(&m[..16])
        }
        None => Mat4::IDENTITY,
    };
    let normals = glam::Mat3::from_mat4(inverse_bind).inverse().transpose();
    if !inverse_bind.is_finite() || !normals.is_finite() {
        return Err("the first joint's inverse bind matrix is not invertible".into());
    }
    for p in &mut mesh.positions {
        *p = inverse_bind.transform_point3(*p);
        check_coordinates(*p, "vertex position")?;
    }
    for n in &mut mesh.normals {
        *n = (normals * *n).normalize_or_zero();
    }
    if inverse_bind.determinant() < 0.0 {
        // A mirrored joint: the scene reverses the winding of what its
        // mirroring transform carries, and the joint's inverse bind matrix
        // mirrors back, so the two turn the triangles as the file put them.
        for tri in &mut mesh.triangles {
            tri.swap(1, 2);
        }
    }
    Ok(Some(node))
}

/// Merges the triangle primitives of `mesh`; primitives without a material
/// get a shared default white diffuse appended to `materials` on first use.
fn build_mesh(
    mesh: &gltf::Mesh,
    buffers: &Buffers,
    materials: &mut Vec<Material>,
    default_material: &mut Option<u32>,
) -> Res<Mesh> {
    let mut out = Mesh::default();
    for prim in mesh.primitives() {
        if !matches!(
            prim.mode(),
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            continue; // points and lines carry no surface
        }
        let what = format!("primitive {}", prim.index());
        let material = match prim.material().index() {
            Some(m) => m as u32,
            None => *default_material.get_or_insert_with(|| {
                materials.push(Material::diffuse("default", Vec3::splat(DEFAULT_ALBEDO)));
                (materials.len() - 1) as u32
            }),
        };
        let (positions, normals, triangles) =
            read_primitive(&prim, buffers).map_err(|e| format!("{what}: {e}"))?;
        let base = out.positions.len() as u32;
        out.positions.extend(positions);
        out.normals.extend(normals);
        out.materials
            .extend(std::iter::repeat_n(material, triangles.len()));
        out.triangles
            .extend(triangles.iter().map(|t| t.map(|i| i + base)));
    }
    let copies = drop_repeated_triangles(&mut out);
    if copies > 0 {
        eprintln!(
            "warning: mesh {}: {copies} triangle(s) dropped that repeat another's corners (a surface twice over only flickers between the two)",
            mesh.name().map_or_else(|| mesh.index().to_string(), |n| format!("'{n}'"))
        );
    }
    Ok(out)
}

/// Drops the triangles of `mesh` whose corners, in the same winding, are
/// those of a triangle before them, and returns how many. Why: besides
/// being invisible, such copies cannot be told apart by a BVH, and the
/// builder (obvhs's PLOC) spent time quadratic in their number (20,000
/// copies: 8 s before the first ray; 40,000: 31 s).
fn drop_repeated_triangles(mesh: &mut Mesh) -> usize {
    let corners = |t: &[u32; 3]| {
        let keys = t.map(|i| mesh.positions[i as usize].to_array().map(f32::to_bits));
        // The same triangle whichever corner comes first.
        let first = (0..3).min_by_key(|&k| keys[k]).unwrap_or(0);
        [keys[first], keys[(first + 1) % 3], keys[(first + 2) % 3]]
    };
    let mut seen = std::collections::HashSet::with_capacity(mesh.triangles.len());
    let keep: Vec<bool> = mesh
        .triangles
        .iter()
        .map(|t| seen.insert(corners(t)))
        .collect();
    let before = mesh.triangles.len();
    let mut k = keep.iter();
    mesh.triangles.retain(|_| *k.next().unwrap_or(&true));
    let mut k = keep.iter();
    mesh.materials.retain(|_| *k.next().unwrap_or(&true));
    before - mesh.triangles.len()
}

type PrimitiveData = (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>);

fn read_primitive(prim: &gltf::Primitive, buffers: &Buffers) -> Res<PrimitiveData> {
    let pos_acc = prim
        .get(&Semantic::Positions)
        .ok_or("no POSITION attribute")?;
    buffers.check_vertex_type(&pos_acc, "POSITION")?;
    let normal_acc = prim.get(&Semantic::Normals);
    if let Some(acc) = &normal_acc {
        check_attribute_count(acc, "NORMAL", &pos_acc)?;
    }
    let positions = buffers.vec3s(&pos_acc, "POSITION")?;
    if positions.iter().any(|p| !p.is_finite()) {
        return Err("NaN or infinite vertex position".into());
    }
    for &p in &positions {
        check_coordinates(p, "vertex position")?;
    }
    let n = positions.len();
    let indexed = prim.indices().is_some();
    let indices = match prim.indices() {
        Some(acc) => buffers.indices(&acc, "indices")?,
        None => (0..n as u32).collect(),
    };
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(format!(
            "vertex index {bad} is out of range (the primitive has {n} vertices)"
        ));
    }
    if prim.mode() == Mode::Triangles && indices.len() % 3 != 0 {
        let what = if indexed {
            "indices for TRIANGLES"
        } else {
            "vertices for TRIANGLES without indices"
        };
        return Err(format!("{} {what}, not a multiple of 3", indices.len()));
    }
    // Triangles without area (an index repeated, or corners on one line)
    // are never hit, and shape is kept by rigid motion; but a BVH cannot
    // split many of them at one point, and every ray near it would test
    // them all.
    let triangles: Vec<[u32; 3]> = triangulate(prim.mode(), &indices)
        .into_iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            (b - a).cross(c - a) != Vec3::ZERO
        })
        .collect();
    let given = match normal_acc {
        Some(acc) => {
            buffers.check_vertex_type(&acc, "NORMAL")?;
            Some(buffers.vec3s(&acc, "NORMAL")?)
        }
        None => None,
    };
    // Unusable normals (missing, NaN, zero) are recomputed rather than
    // rejected: they only affect shading. (A count unlike POSITION's is
    // refused above: the file is malformed, not merely unshaded.)
    let normals = match given {
        Some(normals) if normals.len() == n && normals.iter().all(|v| v.is_finite()) => {
            let mut normals: Vec<Vec3> = normals.into_iter().map(Vec3::normalize_or_zero).collect();
            if normals.contains(&Vec3::ZERO) {
                let faces = vertex_normals(&positions, &triangles);
                for (given, face) in normals.iter_mut().zip(faces) {
                    if *given == Vec3::ZERO {
                        *given = face;
                    }
                }
            }
            normals
        }
        _ => vertex_normals(&positions, &triangles),
    };
    Ok((positions, normals, triangles))
}

/// glTF gives every attribute of a primitive POSITION's count
/// (§3.7.2.1); checked for each attribute the loader reads (POSITION and
/// NORMAL: texture coordinates, colours, joints and weights are not read).
fn check_attribute_count(acc: &gltf::Accessor, what: &str, positions: &gltf::Accessor) -> Res<()> {
    if acc.count() == positions.count() {
        return Ok(());
    }
    Err(format!(
        "accessor {} ({what}) has {} elements but accessor {} (POSITION) has {}; \
         glTF gives every attribute of a primitive the same count",
        acc.index(),
        acc.count(),
        positions.index(),
        positions.count()
    ))
}

/// Triangle list from glTF index order (spec §3.7.2.1 for strips and fans).
fn triangulate(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    let n = idx.len();
    match mode {
        Mode::TriangleStrip => (0..n.saturating_sub(2))
            .map(|i| {
                let odd = i % 2;
                [idx[i], idx[i + 1 + odd], idx[i + 2 - odd]]
            })
            .collect(),
        Mode::TriangleFan => (1..n.saturating_sub(1))
            .map(|i| [idx[i], idx[i + 1], idx[0]])
            .collect(),
        _ => idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    }
}

/// Area-weighted vertex normals (each face adds its unnormalised normal,
/// whose length is twice its area).
fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut normals = vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let face = (b - a).cross(c - a);
        for &i in t {
            normals[i as usize] += face;
        }
    }
    normals.into_iter().map(Vec3::normalize_or_zero).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_triangulate() {
        let idx = [0, 1, 2, 3, 4];
        assert_eq!(
            triangulate(Mode::TriangleStrip, &idx),
            [[0, 1, 2], [1, 3, 2], [2, 3, 4]]
        );
        assert_eq!(
            triangulate(Mode::TriangleFan, &idx),
            [[1, 2, 0], [2, 3, 0], [3, 4, 0]]
        );
        assert_eq!(triangulate(Mode::Triangles, &idx), [[0, 1, 2]]);
        assert!(triangulate(Mode::TriangleStrip, &idx[..2]).is_empty());
    }
}
