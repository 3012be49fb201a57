//! Mesh objects: each mesh node's triangle primitives merged into one
//! [`Mesh`] (strips and fans triangulated, triangles without area and
//! repeated triangles dropped, missing normals computed), and a skinned
//! mesh carried rigidly by its first joint. What would make a mesh render
//! otherwise than its file says without an error (a primitive or a whole
//! mesh without any triangle with area, an attribute that is not read and
//! is malformed) is warned of, naming the mesh.

use super::accessors::Buffers;
use super::nodes::{check_affine, node_name, Hierarchy};
use super::{check_coordinates, Res};
use crate::scene::{Material, Mesh, Object};
use glam::{Mat4, Vec3};
use gltf::accessor::Dimensions;
use gltf::mesh::{Mode, Semantic};
use std::collections::hash_map::{Entry, HashMap};
use std::collections::HashSet;
use std::path::Path;

/// Albedo of the material given to primitives that have none.
const DEFAULT_ALBEDO: f32 = 0.8;

/// One object for each mesh node; the meshes' warnings are printed naming
/// `file`, once for each mesh however many nodes it has.
pub(super) fn build_objects(
    gnodes: &[gltf::Node],
    hierarchy: &Hierarchy,
    buffers: &Buffers,
    materials: &mut Vec<Material>,
    file: &Path,
) -> Res<Vec<Object>> {
    let mut default_material = None;
    let mut warned = HashSet::new();
    let mut inverse_binds = HashMap::new();
    let mut objects = Vec::new();
    for (node, gnode) in gnodes.iter().enumerate() {
        let Some(gmesh) = gnode.mesh() else { continue };
        let name = node_name(gnode);
        let (mut mesh, warnings) = build_mesh(&gmesh, buffers, materials, &mut default_material)
            .map_err(|e| format!("mesh of node '{name}': {e}"))?;
        if warned.insert(gmesh.index()) {
            for warning in warnings {
                eprintln!("warning: {}: {warning}", file.display());
            }
        }
        let node = match gnode.skin() {
            Some(skin) => rigid_skin(&skin, hierarchy, buffers, &mut inverse_binds, &mut mesh)
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
/// keeps the mesh's front faces. `inverse_binds` keeps each skin's matrix,
/// read once however many nodes the skin has.
fn rigid_skin(
    skin: &gltf::Skin,
    hierarchy: &Hierarchy,
    buffers: &Buffers,
    inverse_binds: &mut HashMap<usize, Mat4>,
    mesh: &mut Mesh,
) -> Res<Option<usize>> {
    check_inverse_bind_count(skin)?;
    let Some(joint) = skin.joints().next() else {
        return Ok(None);
    };
    let Some(&node) = hierarchy.ours.get(&joint.index()) else {
        return Ok(None);
    };
    let inverse_bind = match inverse_binds.entry(skin.index()) {
        Entry::Occupied(known) => *known.get(),
        Entry::Vacant(entry) => *entry.insert(first_inverse_bind(skin, buffers)?),
    };
    let normals = glam::Mat3::from_mat4(inverse_bind).inverse().transpose();
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

/// glTF requires a skin's inverse bind matrices to hold one for each of its
/// joints: fewer leave joints without one, a file other tools refuse or
/// skin otherwise. Judged from the accessor's count, as only the first
/// matrix is read ([`first_inverse_bind`]).
fn check_inverse_bind_count(skin: &gltf::Skin) -> Res<()> {
    let Some(acc) = skin.inverse_bind_matrices() else {
        return Ok(());
    };
    let joints = skin.joints().count();
    if acc.count() >= joints {
        return Ok(());
    }
    Err(format!(
        "its inverseBindMatrices accessor {} has a count of {}, for {joints} joints; glTF \
         requires a matrix for each joint",
        acc.index(),
        acc.count()
    ))
}

/// The inverse bind matrix of the skin's first joint (the identity when
/// the skin gives none), checked to be invertible and affine (applied as
/// an affine map, a projective one would silently lose its last row). It
/// alone is read: the other joints carry nothing, and their matrices may
/// be millions of zeros (an accessor without a buffer view).
fn first_inverse_bind(skin: &gltf::Skin, buffers: &Buffers) -> Res<Mat4> {
    let Some(acc) = skin.inverse_bind_matrices() else {
        return Ok(Mat4::IDENTITY);
    };
    let m = buffers.first_floats(&acc, Dimensions::Mat4, "inverseBindMatrices")?;
    let inverse_bind = Mat4::from_cols_slice(&m);
    let normals = glam::Mat3::from_mat4(inverse_bind).inverse().transpose();
    if !inverse_bind.is_finite() || !normals.is_finite() {
        return Err("the first joint's inverse bind matrix is not invertible".into());
    }
    check_affine(&inverse_bind, "the first joint's inverse bind matrix")?;
    Ok(inverse_bind)
}

/// Merges the triangle primitives of `mesh`, with what its warnings say of
/// it; primitives without a material get a shared default white diffuse
/// appended to `materials` on first use.
fn build_mesh(
    mesh: &gltf::Mesh,
    buffers: &Buffers,
    materials: &mut Vec<Material>,
    default_material: &mut Option<u32>,
) -> Res<(Mesh, Vec<String>)> {
    let label = match mesh.name() {
        Some(name) => format!("mesh {} '{name}'", mesh.index()),
        None => format!("mesh {}", mesh.index()),
    };
    let mut out = Mesh::default();
    let mut warnings = Vec::new();
    let mut surfaces = 0;
    for prim in mesh.primitives() {
        if !matches!(
            prim.mode(),
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            continue; // points and lines carry no surface
        }
        surfaces += 1;
        let what = format!("primitive {}", prim.index());
        if let Some(why) = all_zeros(&prim) {
            warnings.push(format!("{label}, {what}: {why}; skipped"));
            continue;
        }
        warnings.extend(
            ignored_attribute_problems(&prim, buffers)
                .into_iter()
                .map(|problem| format!("{label}, {what}: {problem}")),
        );
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
        warnings.push(format!(
            "{label}: {copies} triangle(s) dropped that repeat another's corners (a surface twice over only flickers between the two)"
        ));
    }
    // Each primitive's triangles without area are dropped (`read_primitive`);
    // a mesh left without any would vanish from the render unsaid.
    if surfaces > 0 && out.triangles.is_empty() {
        warnings.push(format!(
            "{label}: not drawn: none of its triangles has any area (their corners lie on one \
             line or at one point)"
        ));
    }
    Ok((out, warnings))
}

/// Why every triangle of `prim` is without area, as its accessors declare
/// before any is decoded: one without a buffer view or sparse values holds
/// zeros (glTF §3.6.2.1), so POSITION's puts every vertex at the origin,
/// and the indices' make every triangle vertex 0 three times. Decoded,
/// such an accessor was gigabytes of zeros that drew nothing.
fn all_zeros(prim: &gltf::Primitive) -> Option<String> {
    let zeros = |acc: &gltf::Accessor| acc.view().is_none() && acc.sparse().is_none();
    if let Some(acc) = prim.get(&Semantic::Positions).filter(zeros) {
        return Some(format!(
            "its POSITION accessor {} has no buffer view and no sparse values, so every vertex \
             is at the origin and no triangle has any area",
            acc.index()
        ));
    }
    let acc = prim.indices().filter(zeros)?;
    Some(format!(
        "its indices accessor {} has no buffer view and no sparse values, so every index is 0 \
         and no triangle has any area",
        acc.index()
    ))
}

/// What is wrong with each attribute of `prim` that the loader does not
/// read (all but POSITION and NORMAL: texture coordinates, tangents,
/// colours, joints, weights): a count unlike POSITION's, a type glTF does
/// not give it, elements outside its buffer view. Said, not refused: the
/// render does not depend on them, but the file is malformed, and other
/// tools may read it otherwise. Nothing is decoded.
fn ignored_attribute_problems(prim: &gltf::Primitive, buffers: &Buffers) -> Vec<String> {
    let Some(positions) = prim.get(&Semantic::Positions) else {
        return Vec::new();
    };
    let ignored = |(semantic, _): &(Semantic, gltf::Accessor)| {
        !matches!(semantic, Semantic::Positions | Semantic::Normals)
    };
    (prim.attributes().filter(ignored))
        .filter_map(|(semantic, acc)| {
            let name = semantic.to_string();
            check_attribute_count(&acc, &name, &positions)
                .and_then(|()| check_attribute_type(&semantic, &acc, &name))
                .and_then(|()| buffers.check_layout(&acc, &name))
                .err()
                .map(|e| format!("{e}; {name} is ignored: radcache does not read it"))
        })
        .collect()
}

/// glTF's types for each vertex attribute (§3.7.2.1); an application's own
/// (`_NAME`) may have any.
fn check_attribute_type(semantic: &Semantic, acc: &gltf::Accessor, what: &str) -> Res<()> {
    use Dimensions as D;
    let allowed: &[Dimensions] = match semantic {
        Semantic::Positions | Semantic::Normals => &[D::Vec3],
        Semantic::Tangents | Semantic::Joints(_) | Semantic::Weights(_) => &[D::Vec4],
        Semantic::TexCoords(_) => &[D::Vec2],
        Semantic::Colors(_) => &[D::Vec3, D::Vec4],
        Semantic::Extras(_) => return Ok(()),
    };
    if allowed.contains(&acc.dimensions()) {
        return Ok(());
    }
    let names: Vec<String> = allowed.iter().map(|d| format!("{d:?}")).collect();
    Err(format!(
        "accessor {} ({what}) has type {:?}; glTF gives {what} type {}",
        acc.index(),
        acc.dimensions(),
        names.join(" or ")
    ))
}

/// Drops the triangles of `mesh` whose corners, in the same winding, are
/// those of a triangle before them, and returns how many. Why: besides
/// being invisible, such copies cannot be told apart by a BVH, and the
/// builder (obvhs's PLOC) spent time quadratic in their number (20,000
/// copies: 8 s before the first ray; 40,000: 31 s).
fn drop_repeated_triangles(mesh: &mut Mesh) -> usize {
    // Each corner by the first vertex at its position (vertices split for
    // their normals or texture coordinates are one corner), so that a
    // triangle's key is three ids rather than nine coordinates: the table
    // of a 2M-triangle mesh is a third the size, and its cache misses were
    // most of the time.
    let mut first_at = std::collections::HashMap::with_capacity(mesh.positions.len());
    let corner: Vec<u32> = (mesh.positions.iter().enumerate())
        .map(|(i, p)| {
            *first_at
                .entry(p.to_array().map(f32::to_bits))
                .or_insert(i as u32)
        })
        .collect();
    drop(first_at);
    let corners = |t: &[u32; 3]| {
        let keys = t.map(|i| corner[i as usize]);
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
/// (§3.7.2.1): an error for NORMAL, which the loader reads, a warning for
/// the attributes it does not read (`ignored_attribute_problems`).
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
