//! glTF 2.0 loader (`.gltf` and `.glb`) producing a [`Scene`].
//!
//! What is read (DESIGN.md, "Scenes"): the default scene's node hierarchy with
//! rest TRS, every mesh node as one object (its triangle primitives merged),
//! metallic-roughness materials with `KHR_materials_emissive_strength`,
//! `KHR_lights_punctual` point and spot lights, integer vertex attributes
//! of `KHR_mesh_quantization`, the first perspective camera and all TRS
//! animation channels. A skinned mesh is not skinned: it keeps its bind
//! pose, carried rigidly by its first joint (`mesh::rigid_skin`), with a
//! warning. Textures and morph targets are ignored, with a warning, and so
//! are a mesh's triangles that repeat another's corners.
//!
//! Bad input must give an error naming the file and the problem, never a
//! panic. The `gltf` crate's own accessor readers can panic on malformed
//! files (reads past a buffer end, a zero count, a stride smaller than an
//! element), so accessors are decoded here with bounds-checked code, and the
//! whole parse additionally runs under `catch_unwind` as a last line of
//! defence.
//!
//! This module holds the entry point ([`load`]), the order of the steps
//! (`load_bytes`) and the checks of the whole scene; each step lives in its
//! own module:
//! - `document`: the JSON document before the `gltf` crate reads it (the
//!   GLB container, extensions, references the crate leaves unchecked), and
//!   the panic guard;
//! - `files`: reading the file and the files its URIs name, confined to a
//!   directory or not;
//! - `accessors`: buffers, and bounds-checked accessor decoding;
//! - `nodes`: the node hierarchy, rest transforms and the camera;
//! - `mesh`: mesh objects, their primitives and skins;
//! - `materials` and `lights`: surfaces and punctual lights;
//! - `animation`: TRS animation channels.

mod accessors;
mod animation;
mod document;
mod files;
mod lights;
mod materials;
mod mesh;
mod nodes;

pub(crate) use document::json_chunk;
pub use files::{confined_file, confined_uri_file, open_regular_file, read_regular_file, uri_file};

use super::{Material, Object, PunctualLight, Scene, SceneError, DEFAULT_FPS};
use accessors::{load_buffers, Buffers};
use document::{
    check_asset_and_nodes, check_extensions, check_glb_header, check_unvalidated_references,
    parse_error, quietly_catch_panics, validated, warn_of_ignored_features,
    without_channels_lacking_a_node,
};
use glam::Vec3;
use nodes::{build_nodes, find_camera, node_at, warn_of_camera_values, Hierarchy};
use std::collections::HashMap;
use std::path::Path;

/// Internal results carry only the problem; [`load`] prefixes the file path.
type Res<T> = Result<T, String>;

/// Largest translation, scale or vertex coordinate a file may hold (see
/// [`crate::scene::MAX_WORLD_COORDINATE`]: these leave room for a few
/// levels of hierarchy).
pub const MAX_COORDINATE: f32 = 1e8;
/// Largest emitted radiance (W·sr⁻¹·m⁻²) or point light intensity
/// (W·sr⁻¹) a file may give: the sun's disc is about 2e7 W·sr⁻¹·m⁻²;
/// values near f32's limit (3e38) overflowed the sums of light and left
/// infinite and NaN pixels.
pub const MAX_EMISSION: f32 = 1e12;

/// Loads a glTF 2.0 scene from `path`, reading the files its URIs name
/// wherever they are. Every error names the file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    load_confined(path, None)
}

/// Loads a glTF 2.0 scene from `path`; when `root` is given, the scene file
/// and every file its buffer URIs name must lie inside that directory
/// (canonical paths compared: see [`confined_file`]), as for the scenes
/// of `radcache serve --scenes DIR`. `data:` URIs and a GLB's own binary
/// chunk read no file, and load either way. Every error names the file.
pub fn load_confined(path: &Path, root: Option<&Path>) -> Result<Scene, SceneError> {
    let source = path.display().to_string();
    let fail = |message: String| SceneError::invalid(source.clone(), message);
    if path.is_dir() {
        return Err(fail("is a directory; expected a .gltf or .glb file".into()));
    }
    check_extension(path).map_err(fail)?;
    // Confined, the file read is the canonical path checked.
    let file = match root {
        None => path.to_path_buf(),
        Some(root) => confined_file(path, root).ok_or_else(|| {
            fail("the scene file is not inside the directory it is confined to".into())
        })?,
    };
    let bytes = read_regular_file(&file, None).map_err(fail)?;
    quietly_catch_panics(|| load_bytes(path, &bytes, root)).map_err(fail)
}

fn check_extension(path: &Path) -> Res<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("gltf") | Some("glb") => Ok(()),
        Some(other) => Err(format!(
            "unsupported file extension '.{other}' (expected .gltf or .glb)"
        )),
        None => Err("unsupported file: no extension (expected .gltf or .glb)".into()),
    }
}

fn load_bytes(path: &Path, bytes: &[u8], confined_to: Option<&Path>) -> Res<Scene> {
    // glTF JSON is UTF-8 without a byte order mark (the spec's "JSON
    // Encoding"), but an editor may write one; the JSON parser refuses
    // it, so it is skipped.
    let bytes = bytes
        .strip_prefix(b"\xEF\xBB\xBF".as_slice())
        .unwrap_or(bytes);
    let named_glb = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let bytes = check_glb_header(named_glb, bytes, path)?;
    let rewritten = without_channels_lacking_a_node(bytes);
    let bytes = rewritten.as_deref().unwrap_or(bytes);
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(parse_error)?;
    let mut root = document.into_json();
    if !root.asset.version.starts_with("2.") {
        return Err(format!(
            "glTF version {} is not supported (expected 2.x)",
            root.asset.version
        ));
    }
    check_asset_and_nodes(&root)?;
    warn_of_ignored_features(&root);
    check_unvalidated_references(&root)?;
    let quantized = check_extensions(&mut root)?;
    let document = validated(root)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = Buffers {
        data: load_buffers(&document, base, confined_to, blob)?,
        quantized,
    };
    let scene_def = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or("the file has no scene")?;
    let hierarchy = Hierarchy::collect(&document, &scene_def)?;
    let gnodes: Vec<gltf::Node> = hierarchy
        .order
        .iter()
        .map(|&g| node_at(&document, g))
        .collect();

    accessors::check_decoded_bytes(&gnodes, &document, |g| hierarchy.ours.contains_key(&g))?;
    let nodes = build_nodes(&gnodes, &hierarchy)?;
    let mut materials = materials::build_materials(&document, path)?;
    let objects = mesh::build_objects(&gnodes, &hierarchy, &buffers, &mut materials, path)?;
    let lights = lights::build_lights(&gnodes, path)?;
    let camera = find_camera(&gnodes)?;
    warn_of_camera_values(&gnodes, path);
    let animation = animation::build_animation(&document, &buffers, &hierarchy, path)?;
    check_renderable(&objects, &materials, &lights)?;

    let mut scene = Scene {
        name: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
        frame_count: frame_count(animation.duration()),
        nodes,
        objects,
        materials,
        lights,
        camera,
        animation,
        moved_by: Vec3::ZERO,
    };
    drop_coincident_objects(&mut scene, &gnodes);
    check_first_frame(&scene)?;
    check_camera_over_time(&scene)?;
    if let Some(by) = scene.move_to_origin() {
        eprintln!(
            "note: {}: the scene lies {:.3e} units from the origin, and is rendered moved by \
             ({}, {}, {}) to it, where coordinates are finer (the API's record positions are \
             the file's)",
            path.display(),
            by.length(),
            by.x,
            by.y,
            by.z
        );
    }
    Ok(scene)
}

/// Drops the objects that repeat an earlier one exactly: the same glTF
/// mesh placed by the same world transform at every time (the same bits
/// at t = 0, on a node that no channel moves, nor any of its ancestors),
/// with one warning. Such copies add nothing to an image, but the BVH
/// builders are quadratic in coincident triangles (as
/// `mesh::drop_repeated_triangles` says within one mesh): 5,000 copies
/// took 44 s to render two frames at 16×16. Animated copies are kept, and
/// so are skinned ones (placed by a joint, not their node) and meshes
/// without triangles (which cost nothing).
fn drop_coincident_objects(scene: &mut Scene, gnodes: &[gltf::Node]) {
    // `mesh::build_objects` makes one object per mesh node, in order.
    let meshes: Vec<Option<usize>> = (gnodes.iter())
        .filter_map(|n| Some((n.skin().is_none()).then_some(n.mesh()?.index())))
        .collect();
    if meshes.len() != scene.objects.len() || meshes.len() < 2 {
        return;
    }
    let dynamic = scene.dynamic_nodes();
    let world = scene.node_world_transforms(0.0);
    let mut first: HashMap<(usize, [u32; 16]), usize> = HashMap::new();
    let mut keep = Vec::with_capacity(meshes.len());
    let mut example = None;
    for (i, (object, &mesh)) in scene.objects.iter().zip(&meshes).enumerate() {
        let Some(mesh) =
            mesh.filter(|_| !(dynamic[object.node] || object.mesh.triangles.is_empty()))
        else {
            keep.push(true);
            continue;
        };
        let key = (mesh, world[object.node].to_cols_array().map(f32::to_bits));
        let repeats = *first.entry(key).or_insert(i) != i;
        if repeats && example.is_none() {
            example = Some((object.name.clone(), scene.objects[first[&key]].name.clone()));
        }
        keep.push(!repeats);
    }
    let Some((copy, original)) = example else {
        return;
    };
    let dropped = keep.iter().filter(|k| !**k).count();
    let mut keep = keep.into_iter();
    scene.objects.retain(|_| keep.next().unwrap_or(true));
    eprintln!(
        "warning: {dropped} mesh node(s) place the same mesh exactly where another node does \
         (e.g. node '{copy}' repeats node '{original}'), and are drawn once: coincident \
         copies add nothing to an image but make building the ray tracing hierarchy \
         quadratically slow"
    );
}

/// What only the placed scene shows, checked at t = 0: a vertex that its
/// node's world transform carries beyond
/// [`crate::scene::MAX_WORLD_COORDINATE`] (each transform and vertex is
/// within [`MAX_COORDINATE`], but a hierarchy compounds them, and past it
/// the BVH builders overflow), a camera whose transform has no orientation
/// (scaled to zero: every ray NaN), or triangles that all have no area
/// (degenerate, or scaled to zero). The last two render black frames
/// without a word otherwise.
fn check_first_frame(scene: &Scene) -> Res<()> {
    let world = scene.node_world_transforms(0.0);
    for object in &scene.objects {
        let name = &scene.nodes[object.node].name;
        let transform = world[object.node];
        // Each rest transform and key is finite: a world transform that is
        // not has overflowed (scales compounding to infinity, and NaN where
        // infinity meets a zero), and has no magnitude worth printing.
        if !transform.is_finite() {
            return Err(format!(
                "node '{name}' has a world transform at t = 0 that is not finite: the transforms \
                 of the node and its ancestors compound past f32's range (about 3.4e38), \
                 past what can be traced"
            ));
        }
        let far = object.mesh.positions.iter().find_map(|&p| {
            let w = transform.transform_point3(p);
            (!crate::scene::within_world(w)).then_some(w)
        });
        if let Some(w) = far {
            let largest = w.abs().max_element();
            return Err(if w.is_finite() {
                format!(
                    "node '{name}' places a vertex at a coordinate of magnitude {largest:e} \
                     at t = 0, beyond {:e}, past what can be traced",
                    crate::scene::MAX_WORLD_COORDINATE
                )
            } else {
                format!(
                    "node '{name}' places a vertex at a non-finite coordinate at t = 0 (its \
                     world transform carries it past f32's range, about 3.4e38), \
                     past what can be traced"
                )
            });
        }
    }
    if let Some(light) = (scene.lights.iter())
        .find(|l| !crate::scene::within_world(world[l.node].transform_point3(Vec3::ZERO)))
    {
        return Err(format!(
            "light '{}' is placed at a coordinate past {:e} (or NaN) at t = 0, past what can be traced",
            light.name,
            crate::scene::MAX_WORLD_COORDINATE
        ));
    }
    scene.check_camera(0.0, "t = 0")?;
    let snapshot = scene.snapshot(0.0);
    let has_area =
        |t: &crate::scene::Triangle| (t.p[1] - t.p[0]).cross(t.p[2] - t.p[0]) != Vec3::ZERO;
    if !snapshot.triangles.iter().any(has_area) {
        return Err("no triangle has any area at t = 0 (degenerate, or scaled to zero)".into());
    }
    Ok(())
}

/// Most frames whose camera [`check_camera_over_time`] checks at load (at
/// the default rate; later ones are checked as they render).
const CAMERA_FRAMES_CHECKED: u32 = 100_000;

/// The camera at every key time of its node chain's channels and at the
/// frames' times (the first [`CAMERA_FRAMES_CHECKED`], at the default
/// rate), as [`Scene::check_camera`] checks it: an animation that carries
/// it past what can be traced is refused before any frame renders, not
/// found at its frame (whose image was black, without a word).
fn check_camera_over_time(scene: &Scene) -> Res<()> {
    if !scene.node_is_dynamic(scene.camera.node) {
        return Ok(()); // As at t = 0, checked already.
    }
    let chain = scene.ancestry(scene.camera.node);
    let fps = DEFAULT_FPS;
    let mut times: Vec<f32> = (scene.animation.channels.iter())
        .filter(|c| chain.contains(&c.node))
        .flat_map(|c| c.times.iter().copied())
        .filter(|&t| t >= 0.0)
        .chain((0..scene.frame_count.min(CAMERA_FRAMES_CHECKED)).map(|f| f as f32 / fps))
        .collect();
    times.sort_by(f32::total_cmp);
    times.dedup();
    scene.check_camera_at(times, |t| {
        let f = t * fps;
        if (f - f.round()).abs() <= 1e-3 {
            format!("t = {t:.4} s (frame {})", f.round())
        } else {
            format!(
                "t = {t:.4} s (a key time, between frames {} and {})",
                f.floor(),
                f.ceil()
            )
        }
    })
}

/// Frames covering `t = 0..=duration` at the default rate; the small
/// tolerance keeps a duration of exactly N/24 s (stored as f32) at N+1 frames.
fn frame_count(duration: f32) -> u32 {
    if duration > 0.0 {
        ((duration as f64 * DEFAULT_FPS as f64 - 1e-3)
            .ceil()
            .max(0.0) as u32)
            .saturating_add(1)
    } else {
        1
    }
}

/// A renderable scene has triangles and something that emits light.
fn check_renderable(
    objects: &[Object],
    materials: &[Material],
    lights: &[PunctualLight],
) -> Res<()> {
    if objects.iter().all(|o| o.mesh.triangles.is_empty()) {
        return Err(
            "the scene has no triangle with any area (no mesh with triangle primitives, \
             or only degenerate triangles)"
                .into(),
        );
    }
    let is_emissive = |m: &u32| {
        materials
            .get(*m as usize)
            .is_some_and(Material::is_emissive)
    };
    let emissive = objects
        .iter()
        .any(|o| o.mesh.materials.iter().any(is_emissive));
    if !emissive && lights.is_empty() {
        return Err(
            "no light source: no triangle has an emissive material and there are no punctual lights"
                .into(),
        );
    }
    Ok(())
}

/// A translation, scale or vertex position within ±[`MAX_COORDINATE`].
fn check_coordinates(v: Vec3, what: &str) -> Res<()> {
    let largest = v.abs().max_element();
    if largest > MAX_COORDINATE {
        return Err(format!(
            "{what} has a component of magnitude {largest:e}, beyond {MAX_COORDINATE:e}, \
             past what can be traced"
        ));
    }
    Ok(())
}

fn all_finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_counts() {
        assert_eq!(frame_count(0.0), 1);
        assert_eq!(frame_count(1.0), 25);
        assert_eq!(frame_count(100.0 / 24.0), 101);
        assert_eq!(frame_count(1.01), 26);
    }
}
