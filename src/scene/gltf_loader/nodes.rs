//! The scene's nodes: the hierarchy reachable from the default scene
//! (proven a forest), each node's rest transform, and the camera node
//! (with warnings of the camera values glTF forbids that are not read).

use super::{all_finite, check_coordinates, Res};
use crate::scene::{CameraDef, Node, Trs};
use glam::{Mat4, Quat, Vec3};
use std::collections::{HashMap, HashSet};
use std::path::Path;

pub(super) fn node_at<'a>(document: &'a gltf::Document, index: usize) -> gltf::Node<'a> {
    // Indices come from the document's own node list, so this is in range.
    document
        .nodes()
        .nth(index)
        .expect("node index from the document")
}

pub(super) fn node_name(node: &gltf::Node) -> String {
    node.name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("node{}", node.index()))
}

/// The nodes reachable from the scene's roots, in document order, with
/// their parents; proven to be a forest.
pub(super) struct Hierarchy {
    /// glTF node index of each of our nodes.
    pub(super) order: Vec<usize>,
    /// Our node index of each reachable glTF node.
    pub(super) ours: HashMap<usize, usize>,
    /// glTF parent of each reachable glTF node.
    pub(super) parent_of: HashMap<usize, Option<usize>>,
}

impl Hierarchy {
    pub(super) fn collect(document: &gltf::Document, scene: &gltf::Scene) -> Res<Hierarchy> {
        let mut parent_of: HashMap<usize, Option<usize>> = HashMap::new();
        let mut stack: Vec<(usize, Option<usize>)> =
            scene.nodes().map(|n| (n.index(), None)).collect();
        while let Some((g, parent)) = stack.pop() {
            // A node reached twice has two parents or lies on a cycle; the
            // world-transform recursion relies on neither happening.
            if parent_of.insert(g, parent).is_some() {
                let name = node_name(&node_at(document, g));
                return Err(format!(
                    "node hierarchy is not a tree: node '{name}' is reached twice (a cycle or two parents)"
                ));
            }
            stack.extend(
                node_at(document, g)
                    .children()
                    .map(|c| (c.index(), Some(g))),
            );
        }
        let mut order: Vec<usize> = parent_of.keys().copied().collect();
        order.sort_unstable();
        let ours = order.iter().enumerate().map(|(i, &g)| (g, i)).collect();
        Ok(Hierarchy {
            order,
            ours,
            parent_of,
        })
    }
}

pub(super) fn build_nodes(gnodes: &[gltf::Node], hierarchy: &Hierarchy) -> Res<Vec<Node>> {
    gnodes
        .iter()
        .map(|n| {
            let parent = hierarchy.parent_of[&n.index()].map(|p| hierarchy.ours[&p]);
            let rest = rest_trs(n).map_err(|e| format!("node '{}': {e}", node_name(n)))?;
            Ok(Node {
                name: node_name(n),
                parent,
                rest,
            })
        })
        .collect()
}

fn rest_trs(node: &gltf::Node) -> Res<Trs> {
    const NON_FINITE: &str = "NaN or infinite value in its transform";
    match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => {
            if !all_finite(matrix.as_flattened()) {
                return Err(NON_FINITE.into());
            }
            let matrix = Mat4::from_cols_array_2d(&matrix);
            check_affine(&matrix, "its matrix")?;
            let (scale, rotation, translation) = matrix.to_scale_rotation_translation();
            // A singular matrix decomposes into NaN rotations.
            if !(scale.is_finite() && rotation.is_finite() && translation.is_finite()) {
                return Err("transform matrix cannot be decomposed into TRS (singular?)".into());
            }
            check_unsheared(&matrix)?;
            check_coordinates(translation, "translation")?;
            check_coordinates(scale, "scale")?;
            Ok(Trs {
                translation,
                rotation: rotation.normalize(),
                scale,
            })
        }
        gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            if !(all_finite(&translation) && all_finite(&rotation) && all_finite(&scale)) {
                return Err(NON_FINITE.into());
            }
            check_coordinates(Vec3::from(translation), "translation")?;
            check_coordinates(Vec3::from(scale), "scale")?;
            let rotation = Quat::from_array(rotation);
            if rotation.length() < 1e-6 {
                return Err("zero rotation quaternion".into());
            }
            Ok(Trs {
                translation: Vec3::from(translation),
                rotation: rotation.normalize(),
                scale: Vec3::from(scale),
            })
        }
    }
}

/// How far a matrix's last row may be from (0, 0, 0, 1): rounding in a
/// file's writer, not a projection.
const AFFINE_TOLERANCE: f32 = 1e-5;

/// How far from a right angle (its cosine) a matrix's axes may be: f32
/// rounding leaves about 1e-7, a writer that prints four significant
/// digits up to about 1e-4 (both harmless, the decomposition drops them);
/// 1e-3 is 0.06°, and a shear worth the name is far more.
const SHEAR_TOLERANCE: f32 = 1e-3;

/// A transform matrix glTF allows (a node's, §5.25; a joint's inverse
/// bind matrix) is affine: its last row (0, 0, 0, 1). Read as one, a
/// projective matrix silently lost that row.
pub(super) fn check_affine(matrix: &Mat4, what: &str) -> Res<()> {
    let row = matrix.row(3);
    if (row - glam::Vec4::W).abs().max_element() <= AFFINE_TOLERANCE {
        return Ok(());
    }
    Err(format!(
        "{what} has the last row ({}, {}, {}, {}), not (0, 0, 0, 1): it is projective, and \
         glTF allows only affine transforms",
        row.x, row.y, row.z, row.w
    ))
}

/// A node's matrix must decompose into translation, rotation and scale
/// (glTF §5.25): its axes (the columns of its 3×3 part) at right angles,
/// else the decomposition silently loses the shear. Compared as the
/// cosines of the angles between them, the check does not depend on the
/// axes' lengths (a shear of a short axis is one too).
fn check_unsheared(matrix: &Mat4) -> Res<()> {
    let axes =
        [matrix.x_axis, matrix.y_axis, matrix.z_axis].map(|a| a.truncate().normalize_or_zero());
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        let cosine = axes[a].dot(axes[b]);
        if cosine.abs() > SHEAR_TOLERANCE {
            let names = ["x", "y", "z"];
            return Err(format!(
                "its matrix is sheared (its {} and {} axes are {:.3}° apart, not 90°): glTF \
                 allows only a matrix that decomposes into translation, rotation and scale",
                names[a],
                names[b],
                cosine.clamp(-1.0, 1.0).acos().to_degrees()
            ));
        }
    }
    Ok(())
}

/// The first scene node (document order) with a perspective camera.
pub(super) fn find_camera(gnodes: &[gltf::Node]) -> Res<CameraDef> {
    let mut saw_orthographic = false;
    for (node, gnode) in gnodes.iter().enumerate() {
        let Some(camera) = gnode.camera() else {
            continue;
        };
        match camera.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let yfov = p.yfov();
                if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(format!(
                        "camera of node '{}' has yfov {yfov} out of range (0, π)",
                        node_name(gnode)
                    ));
                }
                let cameras = gnodes.iter().filter(|n| n.camera().is_some()).count();
                if cameras > 1 {
                    eprintln!(
                        "note: {cameras} cameras in the scene; rendering through the first \
                         perspective one, on node '{}'",
                        node_name(gnode)
                    );
                }
                let aspect_ratio = p.aspect_ratio().filter(|a| a.is_finite() && *a > 0.0);
                return Ok(CameraDef {
                    node,
                    yfov,
                    aspect_ratio,
                });
            }
            gltf::camera::Projection::Orthographic(_) => saw_orthographic = true,
        }
    }
    Err(if saw_orthographic {
        "no perspective camera (orthographic cameras are not supported)".into()
    } else {
        "no camera in the scene".into()
    })
}

/// Warns, naming `file`, of what glTF forbids in the values of the
/// scene's cameras that radcache does not read (all but the yfov of the
/// camera it renders through, which [`find_camera`] refuses out of
/// range), once for each camera. Said, not refused: the render does not
/// depend on them, but the file is malformed, and other tools may read it
/// otherwise.
pub(super) fn warn_of_camera_values(gnodes: &[gltf::Node], file: &Path) {
    let mut warned = HashSet::new();
    for camera in gnodes.iter().filter_map(gltf::Node::camera) {
        if !warned.insert(camera.index()) {
            continue;
        }
        let label = match camera.name() {
            Some(name) => format!("camera {} '{name}'", camera.index()),
            None => format!("camera {}", camera.index()),
        };
        for problem in camera_problems(&camera) {
            eprintln!("warning: {}: {label}: {problem}", file.display());
        }
    }
}

/// What glTF forbids in `camera`'s values radcache does not read, each
/// with why it changes nothing: rays start at the camera and are not
/// clipped, frames take the image's own ratio, and orthographic cameras
/// are not rendered through.
fn camera_problems(camera: &gltf::Camera) -> Vec<String> {
    use gltf::camera::Projection;
    match camera.projection() {
        Projection::Perspective(p) => {
            let aspect = (p.aspect_ratio().filter(|&a| !(a > 0.0 && a.is_finite()))).map(|a| {
                format!(
                    "aspectRatio {a} is not positive, as glTF requires; ignored: frames take the \
                     image's own width-to-height ratio"
                )
            });
            (clipping_problems(p.znear(), p.zfar(), true).into_iter())
                .map(|e| format!("{e}; ignored: rays are not clipped at znear or zfar"))
                .chain(aspect)
                .collect()
        }
        Projection::Orthographic(o) => {
            let magnifications = [("xmag", o.xmag()), ("ymag", o.ymag())]
                .into_iter()
                .filter(|&(_, m)| m == 0.0 || !m.is_finite())
                .map(|(name, m)| format!("{name} {m} is zero or not finite, which glTF forbids"));
            magnifications
                .chain(clipping_problems(o.znear(), Some(o.zfar()), false))
                .map(|e| format!("{e}; ignored: radcache renders through perspective cameras only"))
                .collect()
        }
    }
}

/// What glTF forbids in a camera's clipping planes: a perspective
/// camera's znear not positive (an orthographic one's negative), a zfar
/// (when given) not beyond znear.
fn clipping_problems(znear: f32, zfar: Option<f32>, perspective: bool) -> Vec<String> {
    let (near_ok, rule) = if perspective {
        (znear > 0.0, "positive")
    } else {
        (znear >= 0.0, "0 or more")
    };
    let near = (!(near_ok && znear.is_finite()))
        .then(|| format!("znear {znear} is not {rule}, as glTF requires"));
    let far = (zfar.filter(|f| f.partial_cmp(&znear) != Some(std::cmp::Ordering::Greater)))
        .map(|f| format!("zfar {f} is not beyond znear {znear}, as glTF requires"));
    near.into_iter().chain(far).collect()
}
