//! glTF 2.0 loader (`.gltf` and `.glb`) producing a [`Scene`].
//!
//! What is read (DESIGN.md, "Scenes"): the default scene's node hierarchy with
//! rest TRS, every mesh node as one object (its triangle primitives merged),
//! metallic-roughness materials with `KHR_materials_emissive_strength`,
//! `KHR_lights_punctual` point and spot lights, integer vertex attributes
//! of `KHR_mesh_quantization`, the first perspective camera and all TRS
//! animation channels. Textures, skins and morph targets are
//! ignored, with a warning, and so are a mesh's triangles that repeat
//! another's corners.
//!
//! Bad input must give an error naming the file and the problem, never a
//! panic. The `gltf` crate's own accessor readers can panic on malformed
//! files (reads past a buffer end, a zero count, a stride smaller than an
//! element), so accessors are decoded here with bounds-checked code, and the
//! whole parse additionally runs under `catch_unwind` as a last line of
//! defence.

use super::animation::{Animation, Channel, Interpolation, Property};
use super::{
    CameraDef, Material, Mesh, Node, Object, PunctualLight, Scene, SceneError, Spot, Trs,
    DEFAULT_FPS,
};
use glam::{Mat4, Quat, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};
use std::cell::Cell;
use std::collections::HashMap;
use std::panic::{self, AssertUnwindSafe};
use std::path::Path;
use std::sync::Once;

/// Internal results carry only the problem; [`load`] prefixes the file path.
type Res<T> = Result<T, String>;

/// Accessors without a buffer view are all zeros and cost no file bytes, so
/// their `count` is the only thing bounding the allocation: cap it.
const MAX_VIEWLESS_BYTES: usize = 1 << 28;

/// Albedo of the material given to primitives that have none.
const DEFAULT_ALBEDO: f32 = 0.8;
/// Largest translation, scale or vertex coordinate a file may hold (see
/// [`crate::scene::MAX_WORLD_COORDINATE`]: these leave room for a few
/// levels of hierarchy).
pub const MAX_COORDINATE: f32 = 1e8;
/// Largest emitted radiance (nits) or point light intensity (candela) a
/// file may give: the sun's disc is about 1.6e9 nits; values near f32's
/// limit (3e38) overflowed the sums of light and left infinite and NaN
/// pixels.
pub const MAX_EMISSION: f32 = 1e12;

/// Loads a glTF 2.0 scene from `path`. Every error names the file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let source = path.display().to_string();
    let fail = |message: String| SceneError::invalid(source.clone(), message);
    check_extension(path).map_err(fail)?;
    let bytes = read_file(path).map_err(fail)?;
    quietly_catch_panics(|| load_bytes(path, &bytes)).map_err(fail)
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

fn read_file(path: &Path) -> Res<Vec<u8>> {
    read_regular_file(path, None)
}

/// The bytes of `path`, at most `limit` of them: a FIFO or a device (a
/// link to `/dev/zero`) is refused, as it would block or never end, and a
/// limit keeps a file far longer than needed out of memory.
pub fn read_regular_file(path: &Path, limit: Option<u64>) -> Res<Vec<u8>> {
    use std::io::Read;
    let cannot = |e: std::io::Error| match e.kind() {
        std::io::ErrorKind::NotFound => "file not found".to_string(),
        _ => format!("cannot read file: {e}"),
    };
    // Asked of the path before it is opened (opening a FIFO blocks), and
    // of the file opened (the path may have changed between).
    let regular = |m: std::fs::Metadata| {
        if m.is_file() {
            Ok(())
        } else {
            Err("not a regular file".to_string())
        }
    };
    regular(std::fs::metadata(path).map_err(cannot)?)?;
    let file = std::fs::File::open(path).map_err(cannot)?;
    regular(file.metadata().map_err(cannot)?)?;
    let mut bytes = Vec::new();
    file.take(limit.unwrap_or(u64::MAX))
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read file: {e}"))?;
    Ok(bytes)
}

/// The file that a glTF `uri` other than a `data:` URI names, relative to
/// the directory `base` of the file that holds it: `%XX` escapes decoded
/// (glTF URIs are RFC 3986), a `file:` scheme allowed; other schemes (a
/// `http:` URI) are refused, as nothing is fetched.
pub fn uri_file(base: &Path, uri: &str) -> Res<std::path::PathBuf> {
    let path = match uri.split_once(':') {
        Some((scheme, rest)) if is_uri_scheme(scheme) => {
            if !scheme.eq_ignore_ascii_case("file") {
                return Err(format!(
                    "URI '{uri}': only files are read, not '{scheme}:' URIs"
                ));
            }
            file_uri_path(rest).ok_or_else(|| {
                format!("URI '{uri}': only local files are read (its host is not this machine)")
            })?
        }
        _ => uri,
    };
    let decoded = crate::uri::percent_decode(path)
        .ok_or_else(|| format!("URI '{uri}': malformed %-escape or not UTF-8"))?;
    Ok(base.join(decoded))
}

/// The path of a `file:` URI after its scheme (RFC 8089): `/p`, or
/// `//HOST/p` with no host or `localhost`; `None` for another host.
fn file_uri_path(rest: &str) -> Option<&str> {
    let Some(authority_and_path) = rest.strip_prefix("//") else {
        return Some(rest);
    };
    let (host, path) = match authority_and_path.find('/') {
        Some(i) => authority_and_path.split_at(i),
        None => (authority_and_path, ""),
    };
    (host.is_empty() || host.eq_ignore_ascii_case("localhost")).then_some(path)
}

/// Whether `s` is a URI scheme (RFC 3986: a letter, then letters, digits,
/// `+`, `-`, `.`), longer than one letter so that a Windows drive (`C:`)
/// stays a path.
fn is_uri_scheme(s: &str) -> bool {
    let mut chars = s.chars();
    s.len() > 1
        && chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
}

thread_local! {
    /// Set while this thread parses a file, so the panic hook stays silent.
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// Runs `f`, turning a panic into an error. The default hook would print a
/// confusing "thread panicked" message before our clean error, so a hook that
/// stays silent on threads inside this function (and defers to the previous
/// hook everywhere else) is installed once.
fn quietly_catch_panics<T>(f: impl FnOnce() -> Res<T>) -> Res<T> {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        let previous = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            if !QUIET.try_with(Cell::get).unwrap_or(false) {
                previous(info);
            }
        }));
    });
    let was_quiet = QUIET.with(|q| q.replace(true));
    let result = panic::catch_unwind(AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was_quiet));
    result.unwrap_or_else(|payload| {
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown error".into());
        Err(format!("malformed glTF: the parser failed ({what})"))
    })
}

/// What glTF forbids and the `gltf` crate does not check: an
/// `asset.minVersion` past the 2.0 this reader reads, and a node with both
/// a matrix and translation, rotation or scale (§5.25: one or the other).
fn check_asset_and_nodes(root: &gltf::json::Root) -> Res<()> {
    if let Some(min) = root.asset.min_version.as_deref().filter(|&v| v != "2.0") {
        return Err(format!(
            "the file needs glTF {min} at least (asset.minVersion); this reader reads 2.0"
        ));
    }
    for (i, node) in root.nodes.iter().enumerate() {
        let trs = node.translation.is_some() || node.rotation.is_some() || node.scale.is_some();
        if node.matrix.is_some() && trs {
            let name = node.name.clone().unwrap_or_else(|| format!("node{i}"));
            return Err(format!(
                "node '{name}' has both a matrix and translation, rotation or scale \
                 (glTF allows one or the other)"
            ));
        }
    }
    Ok(())
}

/// Says what the file has that this reader ignores (textures, skins, morph
/// targets, extensions, point and line primitives) or reads otherwise than
/// its maker may have meant (a Blender file's light units), so that a
/// render that looks wrong is not a surprise.
fn warn_of_ignored_features(root: &gltf::json::Root) {
    if !root.textures.is_empty() {
        eprintln!(
            "warning: {} texture(s) ignored: materials use their colour and emissive factors",
            root.textures.len()
        );
    }
    if !root.skins.is_empty() {
        eprintln!(
            "warning: skins ignored: a skinned mesh keeps its bind pose, carried rigidly by its first joint"
        );
    }
    let morphs = root
        .meshes
        .iter()
        .flat_map(|m| &m.primitives)
        .any(|p| p.targets.as_ref().is_some_and(|t| !t.is_empty()));
    if morphs {
        eprintln!("warning: morph targets ignored: meshes render in their base shape");
    }
    let ignored: Vec<&str> = (root.extensions_used.iter())
        .map(String::as_str)
        .filter(|e| !reads_extension(e))
        .collect();
    if !ignored.is_empty() {
        eprintln!(
            "warning: extension(s) ignored: {} (materials use their metallic-roughness and emissive factors)",
            ignored.join(", ")
        );
    }
    let surfaceless = (root.meshes.iter())
        .flat_map(|m| &m.primitives)
        .filter(|p| {
            use gltf::json::{mesh::Mode as M, validation::Checked};
            matches!(
                p.mode,
                Checked::Valid(M::Points | M::Lines | M::LineLoop | M::LineStrip)
            )
        })
        .count();
    if surfaceless > 0 {
        eprintln!(
            "warning: {surfaceless} point or line primitive(s) ignored: they have no surface"
        );
    }
    let punctual = (root.extensions.as_ref())
        .and_then(|e| e.khr_lights_punctual.as_ref())
        .is_some_and(|l| !l.lights.is_empty());
    let from_blender = (root.asset.generator.as_deref()).is_some_and(|g| g.contains("Blender"));
    if punctual && from_blender {
        eprintln!(
            "warning: this file comes from Blender; its point and spot light intensities are \
             read as W/sr, but Blender's exporter writes candela (683 × W/sr) unless its \
             Lighting Mode is 'Unitless': exported in candela, they render 683 times too bright"
        );
    }
}

/// The glTF extension that lets vertex positions and normals be integers
/// (what gltfpack writes by default). The `gltf` crate does not know it, so
/// it is taken off `extensionsRequired` before the crate validates the file:
/// this loader decodes such accessors itself ([`component`]).
const MESH_QUANTIZATION: &str = "KHR_mesh_quantization";

/// Whether this loader reads extension `e`: those the `gltf` crate is
/// built to read (its features in Cargo.toml) and [`MESH_QUANTIZATION`].
fn reads_extension(e: &str) -> bool {
    gltf::json::extensions::ENABLED_EXTENSIONS.contains(&e) || e == MESH_QUANTIZATION
}

/// The file without its animation channels that name no target node, if
/// it has any (`None`: nothing to take off, or JSON the parser will
/// report). The spec lets an extension (`KHR_animation_pointer`) name what
/// such a channel animates, but the crate refuses a channel without a
/// node; they are ignored with a warning, and so is an animation left
/// without channels.
fn without_channels_lacking_a_node(bytes: &[u8]) -> Option<Vec<u8>> {
    let glb = if bytes.starts_with(b"glTF") {
        Some(gltf::binary::Glb::from_slice(bytes).ok()?)
    } else {
        None
    };
    let json = glb.as_ref().map_or(bytes, |g| &g.json);
    let mut root: serde_json::Value = serde_json::from_slice(json).ok()?;
    let animations = root.get_mut("animations")?.as_array_mut()?;
    let mut dropped = 0;
    for animation in animations.iter_mut() {
        if let Some(channels) = animation.get_mut("channels").and_then(|c| c.as_array_mut()) {
            let before = channels.len();
            channels.retain(|c| c.get("target").is_none_or(|t| t.get("node").is_some()));
            dropped += before - channels.len();
        }
    }
    if dropped == 0 {
        return None;
    }
    animations.retain(|a| {
        a.get("channels")
            .and_then(|c| c.as_array())
            .is_none_or(|c| !c.is_empty())
    });
    eprintln!(
        "warning: {dropped} animation channel(s) without a target node ignored (an extension names what they animate)"
    );
    let json = serde_json::to_vec(&root).ok()?;
    match glb {
        None => Some(json),
        Some(glb) => gltf::binary::Glb {
            json: json.into(),
            ..glb
        }
        .to_vec()
        .ok(),
    }
}

/// Refuses a file that requires an extension this loader cannot read (a
/// compressed mesh, say), naming it; takes [`MESH_QUANTIZATION`] off the
/// required extensions (the crate would refuse it) and says whether the
/// file uses it.
fn check_extensions(root: &mut gltf::json::Root) -> Res<bool> {
    if let Some(e) = (root.extensions_required.iter()).find(|e| !reads_extension(e)) {
        let readable = gltf::json::extensions::ENABLED_EXTENSIONS.join(", ");
        return Err(format!(
            "the file requires the extension {e}, which radcache cannot read (it reads {readable} and {MESH_QUANTIZATION})"
        ));
    }
    root.extensions_required.retain(|e| e != MESH_QUANTIZATION);
    Ok(root.extensions_used.iter().any(|e| e == MESH_QUANTIZATION))
}

fn load_bytes(path: &Path, bytes: &[u8]) -> Res<Scene> {
    check_glb_length(bytes)?;
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
        data: load_buffers(&document, base, blob)?,
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

    let nodes = build_nodes(&gnodes, &hierarchy)?;
    let mut materials = build_materials(&document)?;
    let objects = build_objects(&gnodes, &hierarchy, &buffers, &mut materials)?;
    let lights = build_lights(&gnodes)?;
    let camera = find_camera(&gnodes)?;
    let animation = build_animation(&document, &buffers, &hierarchy)?;
    check_renderable(&objects, &materials, &lights)?;

    let scene = Scene {
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
    };
    check_first_frame(&scene)?;
    Ok(scene)
}

/// What only the placed scene shows, checked at t = 0: a camera whose
/// transform has no orientation (scaled to zero: every ray NaN), or
/// triangles that all have no area (degenerate, or scaled to zero). Either
/// renders black frames without a word otherwise.
fn check_first_frame(scene: &Scene) -> Res<()> {
    let world = scene.node_world_transforms(0.0);
    for object in &scene.objects {
        let far = object.mesh.positions.iter().find_map(|&p| {
            let w = world[object.node].transform_point3(p);
            (!crate::scene::within_world(w)).then_some(w)
        });
        if let Some(w) = far {
            return Err(format!(
                "node '{}' places a vertex at a coordinate of magnitude {:e} at t = 0, \
                 beyond {:e}, past what can be traced",
                scene.nodes[object.node].name,
                w.abs().max_element(),
                crate::scene::MAX_WORLD_COORDINATE
            ));
        }
    }
    let snapshot = scene.snapshot(0.0);
    let camera = &snapshot.camera;
    if !(camera.position.is_finite() && camera.basis.is_finite()) {
        return Err(format!(
            "camera node '{}' has no orientation at t = 0 (scaled to zero?)",
            scene.nodes[scene.camera.node].name
        ));
    }
    let has_area =
        |t: &crate::scene::Triangle| (t.p[1] - t.p[0]).cross(t.p[2] - t.p[0]) != Vec3::ZERO;
    if !snapshot.triangles.iter().any(has_area) {
        return Err("no triangle has any area at t = 0 (degenerate, or scaled to zero)".into());
    }
    Ok(())
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

/// The GLB header states the file length; a mismatch is the clearest sign of
/// a truncated download, clearer than the chunk error the parser reports.
fn check_glb_length(bytes: &[u8]) -> Res<()> {
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    let Some(len) = bytes.get(8..12) else {
        return Err(format!(
            "truncated GLB: only {} bytes, shorter than the 12-byte header",
            bytes.len()
        ));
    };
    let declared = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
    if bytes.len() < declared {
        return Err(format!(
            "truncated GLB: the header declares {declared} bytes but the file has {}",
            bytes.len()
        ));
    }
    Ok(())
}

/// References that `gltf`'s validation indexes without checking (POSITION
/// accessors, which its own validation hook reads) or does not check at all
/// (animation targets); either would panic later.
fn check_unvalidated_references(root: &gltf::json::Root) -> Res<()> {
    let accessors = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(bad) = prim.attributes.values().find(|a| a.value() >= accessors) {
                return Err(format!(
                    "mesh {m}, primitive {p}: attribute accessor {} is out of range ({accessors} accessors)",
                    bad.value()
                ));
            }
        }
    }
    for (a, anim) in root.animations.iter().enumerate() {
        for (c, ch) in anim.channels.iter().enumerate() {
            let node = ch.target.node.value();
            if node >= root.nodes.len() {
                return Err(format!(
                    "animation {a}, channel {c}: target node {node} is out of range ({} nodes)",
                    root.nodes.len()
                ));
            }
            if let gltf::json::validation::Checked::Invalid = ch.target.path {
                return Err(format!("animation {a}, channel {c}: unknown target path"));
            }
        }
    }
    // The crate unwraps the object its type names.
    for (i, camera) in root.cameras.iter().enumerate() {
        use gltf::json::camera::Type;
        use gltf::json::validation::Checked;
        let missing = match camera.type_ {
            Checked::Valid(Type::Perspective) if camera.perspective.is_none() => "perspective",
            Checked::Valid(Type::Orthographic) if camera.orthographic.is_none() => "orthographic",
            Checked::Valid(_) => continue,
            Checked::Invalid => return Err(format!("camera {i}: unknown type")),
        };
        return Err(format!(
            "camera {i}: its type is \"{missing}\" but it has no \"{missing}\" object"
        ));
    }
    Ok(())
}

/// The document of `root` once the crate's validation passes, but for one
/// rule of the crate's own: an accessor without a buffer view and without
/// sparse values is refused there, where glTF (§3.6.2.1) says it holds
/// zeros, as [`Buffers`] reads it.
fn validated(root: gltf::json::Root) -> Res<gltf::Document> {
    use gltf::json::validation::{Error, Validate};
    let mut errors = Vec::new();
    root.validate(&root, gltf::json::Path::new, &mut |path, error| {
        let path = path();
        let viewless = matches!(error, Error::Missing)
            && path.as_str().starts_with("accessors[")
            && path.as_str().ends_with("].bufferView");
        if !viewless {
            errors.push((path, error));
        }
    });
    if errors.is_empty() {
        Ok(gltf::Document::from_json_without_validation(root))
    } else {
        Err(parse_error(gltf::Error::Validation(errors)))
    }
}

fn parse_error(e: gltf::Error) -> String {
    match e {
        gltf::Error::Binary(e) => format!("truncated or corrupt GLB: {e}"),
        gltf::Error::Deserialize(e) => format!("not a valid glTF file: {e}"),
        gltf::Error::Validation(errors) => {
            let list: Vec<String> = errors
                .iter()
                .take(5)
                .map(|(path, err)| format!("{}: {err}", path.as_str()))
                .collect();
            format!("invalid glTF: {}", list.join("; "))
        }
        other => format!("cannot parse glTF: {other}"),
    }
}

/// Buffer contents, indexed like the document's buffers.
fn load_buffers(
    document: &gltf::Document,
    base: &Path,
    mut blob: Option<Vec<u8>>,
) -> Res<Vec<Vec<u8>>> {
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        let source = buffer.source();
        let data = match source {
            // Read here, not by the crate: its errors do not name the file,
            // and it reads whatever the URI names to its end (a device, a
            // FIFO).
            gltf::buffer::Source::Uri(uri) if !uri.starts_with("data:") => {
                let file = uri_file(base, uri).map_err(|e| format!("buffer {i}: {e}"))?;
                read_regular_file(&file, Some(buffer.length() as u64)).map_err(|e| {
                    let e = if e == "file not found" {
                        "missing buffer file".into()
                    } else {
                        e
                    };
                    format!("{e} '{}' (buffer {i})", file.display())
                })?
            }
            _ => {
                gltf::buffer::Data::from_source_and_blob(source, Some(base), &mut blob)
                    .map_err(|e| match e {
                        gltf::Error::MissingBlob => format!(
                            "buffer {i} refers to the GLB binary chunk, which is missing (truncated GLB?)"
                        ),
                        e => format!("cannot load buffer {i}: {e}"),
                    })?
                    .0
            }
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "buffer {i} is truncated: it declares {} bytes but has {}",
                buffer.length(),
                data.len()
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// Bounds-checked accessor decoding (see the module comment for why the
/// crate's readers are not used).
struct Buffers {
    data: Vec<Vec<u8>>,
    /// Whether the file uses `KHR_mesh_quantization`: vertex attributes
    /// may then be integers.
    quantized: bool,
}

impl Buffers {
    fn view_bytes(&self, view: &gltf::buffer::View) -> Res<&[u8]> {
        let buffer = self
            .data
            .get(view.buffer().index())
            .ok_or_else(|| format!("buffer view {} names a missing buffer", view.index()))?;
        view.offset()
            .checked_add(view.length())
            .and_then(|end| buffer.get(view.offset()..end))
            .ok_or_else(|| {
                format!(
                    "buffer view {} is out of range of buffer {} ({} bytes)",
                    view.index(),
                    view.buffer().index(),
                    buffer.len()
                )
            })
    }

    /// The accessor's elements packed tightly (`count × element size`
    /// bytes), with sparse substitutions applied.
    fn elements(&self, acc: &gltf::Accessor, what: &str) -> Res<Vec<u8>> {
        let i = acc.index();
        let out_of_range = || format!("accessor {i} ({what}) is out of range of its buffer view");
        let count = acc.count();
        let elem = acc.data_type().size() * acc.dimensions().multiplicity();
        if count == 0 {
            return Err(format!("accessor {i} ({what}) is empty"));
        }
        let total = count.checked_mul(elem).ok_or_else(out_of_range)?;
        let mut out = match acc.view() {
            Some(view) => {
                let bytes = self.view_bytes(&view)?;
                let stride = view.stride().unwrap_or(elem);
                if stride < elem {
                    return Err(format!(
                        "accessor {i} ({what}): byte stride {stride} is smaller than an element ({elem} bytes)"
                    ));
                }
                let last = stride
                    .checked_mul(count - 1)
                    .and_then(|x| x.checked_add(acc.offset()))
                    .ok_or_else(out_of_range)?;
                if last.checked_add(elem).is_none_or(|end| end > bytes.len()) {
                    return Err(out_of_range());
                }
                let mut out = Vec::with_capacity(total);
                for k in 0..count {
                    let start = acc.offset() + k * stride;
                    out.extend_from_slice(&bytes[start..start + elem]);
                }
                out
            }
            None if total <= MAX_VIEWLESS_BYTES => vec![0; total],
            None => return Err(format!("accessor {i} ({what}) is too large")),
        };
        if let Some(sparse) = acc.sparse() {
            self.apply_sparse(&sparse, &mut out, count, elem)
                .map_err(|e| format!("accessor {i} ({what}): sparse {e}"))?;
        }
        Ok(out)
    }

    fn apply_sparse(
        &self,
        sparse: &gltf::accessor::sparse::Sparse,
        out: &mut [u8],
        count: usize,
        elem: usize,
    ) -> Res<()> {
        let n = sparse.count();
        let (indices, values) = (sparse.indices(), sparse.values());
        let index_size = indices.index_type().size();
        let slice = |bytes: &'_ [u8], offset: usize, len: Option<usize>| -> Res<Vec<u8>> {
            len.and_then(|len| bytes.get(offset..offset.checked_add(len)?))
                .map(<[u8]>::to_vec)
                .ok_or_else(|| "data is out of range of its buffer view".to_string())
        };
        let index_bytes = slice(
            self.view_bytes(&indices.view())?,
            indices.offset(),
            n.checked_mul(index_size),
        )?;
        let value_bytes = slice(
            self.view_bytes(&values.view())?,
            values.offset(),
            n.checked_mul(elem),
        )?;
        for (k, raw) in index_bytes.chunks_exact(index_size).enumerate() {
            let target = read_uint(raw) as usize;
            if target >= count {
                return Err(format!("index {target} is out of range ({count} elements)"));
            }
            out[target * elem..(target + 1) * elem]
                .copy_from_slice(&value_bytes[k * elem..(k + 1) * elem]);
        }
        Ok(())
    }

    /// Float values of an accessor of the given type, flattened; integer
    /// components are converted (normalised ones to \[0, 1\] or \[−1, 1\]).
    fn floats(&self, acc: &gltf::Accessor, dims: Dimensions, what: &str) -> Res<Vec<f32>> {
        if acc.dimensions() != dims {
            return Err(format!(
                "accessor {} ({what}) has type {:?}, expected {dims:?}",
                acc.index(),
                acc.dimensions()
            ));
        }
        let ty = acc.data_type();
        let bytes = self.elements(acc, what)?;
        Ok(bytes
            .chunks_exact(ty.size())
            .map(|c| component(c, ty, acc.normalized()))
            .collect())
    }

    /// glTF 2.0 keeps vertex positions and normals in floats (§3.7.2.1);
    /// `KHR_mesh_quantization` also allows 8- and 16-bit integers.
    fn check_vertex_type(&self, acc: &gltf::Accessor, what: &str) -> Res<()> {
        let ty = acc.data_type();
        let allowed = match ty {
            DataType::F32 => true,
            DataType::U32 => false,
            _ => self.quantized,
        };
        if allowed {
            return Ok(());
        }
        let why = if self.quantized {
            "integers of 8 or 16 bits at most"
        } else {
            "FLOAT unless the file uses KHR_mesh_quantization"
        };
        Err(format!(
            "accessor {} ({what}) holds {ty:?} components; glTF allows {why}",
            acc.index()
        ))
    }

    fn vec3s(&self, acc: &gltf::Accessor, what: &str) -> Res<Vec<Vec3>> {
        let flat = self.floats(acc, Dimensions::Vec3, what)?;
        Ok(flat.chunks_exact(3).map(Vec3::from_slice).collect())
    }

    fn indices(&self, acc: &gltf::Accessor, what: &str) -> Res<Vec<u32>> {
        let ty = acc.data_type();
        if acc.dimensions() != Dimensions::Scalar
            || !matches!(ty, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(format!(
                "accessor {} ({what}) must be unsigned integer scalars for indices",
                acc.index()
            ));
        }
        let bytes = self.elements(acc, what)?;
        Ok(bytes.chunks_exact(ty.size()).map(read_uint).collect())
    }
}

/// Little-endian unsigned integer of 1, 2 or 4 bytes.
fn read_uint(raw: &[u8]) -> u32 {
    raw.iter().rev().fold(0u32, |acc, &b| (acc << 8) | b as u32)
}

/// One component as f32 (glTF §3.11 normalisation for integer types).
fn component(raw: &[u8], ty: DataType, normalized: bool) -> f32 {
    let (value, scale) = match ty {
        DataType::F32 => return f32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]),
        DataType::I8 => (raw[0] as i8 as f32, 127.0),
        DataType::U8 => (raw[0] as f32, 255.0),
        DataType::I16 => (i16::from_le_bytes([raw[0], raw[1]]) as f32, 32767.0),
        DataType::U16 => (u16::from_le_bytes([raw[0], raw[1]]) as f32, 65535.0),
        DataType::U32 => (read_uint(raw) as f32, 1.0),
    };
    if normalized {
        (value / scale).max(-1.0)
    } else {
        value
    }
}

fn node_at<'a>(document: &'a gltf::Document, index: usize) -> gltf::Node<'a> {
    // Indices come from the document's own node list, so this is in range.
    document
        .nodes()
        .nth(index)
        .expect("node index from the document")
}

fn node_name(node: &gltf::Node) -> String {
    node.name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("node{}", node.index()))
}

/// The nodes reachable from the scene's roots, in document order, with
/// their parents; proven to be a forest.
struct Hierarchy {
    /// glTF node index of each of our nodes.
    order: Vec<usize>,
    /// Our node index of each reachable glTF node.
    ours: HashMap<usize, usize>,
    /// glTF parent of each reachable glTF node.
    parent_of: HashMap<usize, Option<usize>>,
}

impl Hierarchy {
    fn collect(document: &gltf::Document, scene: &gltf::Scene) -> Res<Hierarchy> {
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

fn build_nodes(gnodes: &[gltf::Node], hierarchy: &Hierarchy) -> Res<Vec<Node>> {
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

fn rest_trs(node: &gltf::Node) -> Res<Trs> {
    const NON_FINITE: &str = "NaN or infinite value in its transform";
    match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => {
            if !all_finite(matrix.as_flattened()) {
                return Err(NON_FINITE.into());
            }
            let (scale, rotation, translation) =
                Mat4::from_cols_array_2d(&matrix).to_scale_rotation_translation();
            // A singular matrix decomposes into NaN rotations.
            if !(scale.is_finite() && rotation.is_finite() && translation.is_finite()) {
                return Err("transform matrix cannot be decomposed into TRS (singular?)".into());
            }
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

fn build_materials(document: &gltf::Document) -> Res<Vec<Material>> {
    document.materials().map(|m| convert_material(&m)).collect()
}

fn convert_material(m: &gltf::Material) -> Res<Material> {
    let name = m
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, _] = pbr.base_color_factor();
    let strength = m.emissive_strength().unwrap_or(1.0);
    let emission = Vec3::from(m.emissive_factor()) * strength;
    let factors = [r, g, b, pbr.metallic_factor(), pbr.roughness_factor()];
    if !all_finite(&factors) || !emission.is_finite() {
        return Err(format!("material '{name}' has a NaN or infinite factor"));
    }
    if emission.max_element() > MAX_EMISSION {
        return Err(format!(
            "material '{name}' emits {:e} nits (emissive factor × strength), over the {MAX_EMISSION:e} allowed",
            emission.max_element()
        ));
    }
    // Out-of-range factors would make surfaces gain energy; glTF forbids them.
    let unit = |x: f32| x.clamp(0.0, 1.0);
    let mut material = Material::from_metallic_roughness(
        &name,
        Vec3::new(r, g, b).clamp(Vec3::ZERO, Vec3::ONE),
        unit(pbr.metallic_factor()),
        unit(pbr.roughness_factor()),
    );
    material.emission = emission.max(Vec3::ZERO);
    material.double_sided = m.double_sided();
    Ok(material)
}

fn build_objects(
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

/// A skinned mesh without its skinning (skins are ignored): glTF places it
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
    let positions = buffers.vec3s(&pos_acc, "POSITION")?;
    if positions.iter().any(|p| !p.is_finite()) {
        return Err("NaN or infinite vertex position".into());
    }
    for &p in &positions {
        check_coordinates(p, "vertex position")?;
    }
    let n = positions.len();
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
        return Err(format!(
            "{} indices for TRIANGLES, not a multiple of 3",
            indices.len()
        ));
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
    let given = match prim.get(&Semantic::Normals) {
        Some(acc) => {
            buffers.check_vertex_type(&acc, "NORMAL")?;
            Some(buffers.vec3s(&acc, "NORMAL")?)
        }
        None => None,
    };
    // Unusable normals (missing, wrong count, NaN, zero) are recomputed
    // rather than rejected: they only affect shading.
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
pub(crate) fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
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

fn build_lights(gnodes: &[gltf::Node]) -> Res<Vec<PunctualLight>> {
    use gltf::khr_lights_punctual::Kind;
    let mut lights = Vec::new();
    for (node, gnode) in gnodes.iter().enumerate() {
        let Some(light) = gnode.light() else { continue };
        let name = light
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| node_name(gnode));
        let intensity = Vec3::from(light.color()) * light.intensity();
        if !intensity.is_finite() || intensity.min_element() < 0.0 {
            return Err(format!(
                "light '{name}' has a NaN, infinite or negative intensity"
            ));
        }
        if intensity.max_element() > MAX_EMISSION {
            return Err(format!(
                "light '{name}' has an intensity of {:e} cd (colour × intensity), over the {MAX_EMISSION:e} allowed",
                intensity.max_element()
            ));
        }
        let spot = match light.kind() {
            Kind::Directional => {
                eprintln!("warning: directional light '{name}' is not supported and is skipped");
                continue;
            }
            Kind::Point => None,
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                if !(all_finite(&[inner_cone_angle, outer_cone_angle]) && outer_cone_angle > 0.0) {
                    return Err(format!("spot light '{name}' has invalid cone angles"));
                }
                if inner_cone_angle > outer_cone_angle {
                    return Err(format!(
                        "spot light '{name}': innerConeAngle {inner_cone_angle} is larger than \
                         outerConeAngle {outer_cone_angle}"
                    ));
                }
                Some(Spot {
                    inner_cone: inner_cone_angle.clamp(0.0, outer_cone_angle),
                    outer_cone: outer_cone_angle,
                })
            }
        };
        lights.push(PunctualLight {
            name,
            node,
            intensity,
            spot,
        });
    }
    Ok(lights)
}

/// The first scene node (document order) with a perspective camera.
fn find_camera(gnodes: &[gltf::Node]) -> Res<CameraDef> {
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

/// All channels of all animations, merged (they all play from t = 0).
/// Channels on nodes outside the scene and morph-target weights are dropped.
fn build_animation(
    document: &gltf::Document,
    buffers: &Buffers,
    hierarchy: &Hierarchy,
) -> Res<Animation> {
    let mut channels = Vec::new();
    // The animation that drives each (node, property), to name a second.
    let mut driven: HashMap<(usize, Property), (usize, String)> = HashMap::new();
    for anim in document.animations() {
        let anim_name = anim
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("animation{}", anim.index()));
        for ch in anim.channels() {
            let target = ch.target();
            let Some(&node) = hierarchy.ours.get(&target.node().index()) else {
                continue;
            };
            let property = match target.property() {
                gltf::animation::Property::Translation => Property::Translation,
                gltf::animation::Property::Rotation => Property::Rotation,
                gltf::animation::Property::Scale => Property::Scale,
                gltf::animation::Property::MorphTargetWeights => continue,
            };
            let where_ = || {
                format!(
                    "animation '{anim_name}', channel {} (node '{}')",
                    ch.index(),
                    node_name(&target.node())
                )
            };
            let channel = read_channel(&ch, node, property, buffers)
                .map_err(|e| format!("{}: {e}", where_()))?;
            // glTF §3.11: one animation drives a node's property once.
            // Several animations may (clips meant to play one at a time);
            // all play at once here, and the last one sets the property.
            match driven.insert((node, property), (anim.index(), anim_name.clone())) {
                Some((other, _)) if other == anim.index() => {
                    return Err(format!(
                        "{}: its {} is driven twice in this animation",
                        where_(),
                        property.name()
                    ))
                }
                Some((_, other)) => eprintln!(
                    "warning: {}: its {} is driven by animation '{other}' too; \
                     all animations play at once, and this later one sets it",
                    where_(),
                    property.name()
                ),
                None => {}
            }
            channels.push(channel);
        }
    }
    Ok(Animation { channels })
}

fn read_channel(
    ch: &gltf::animation::Channel,
    node: usize,
    property: Property,
    buffers: &Buffers,
) -> Res<Channel> {
    let sampler = ch.sampler();
    let interpolation = match sampler.interpolation() {
        gltf::animation::Interpolation::Linear => Interpolation::Linear,
        gltf::animation::Interpolation::Step => Interpolation::Step,
        gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
    };
    let times = buffers.floats(&sampler.input(), Dimensions::Scalar, "key times")?;
    let values: Vec<Vec4> = if property == Property::Rotation {
        let flat = buffers.floats(&sampler.output(), Dimensions::Vec4, "key values")?;
        flat.chunks_exact(4).map(Vec4::from_slice).collect()
    } else {
        let flat = buffers.floats(&sampler.output(), Dimensions::Vec3, "key values")?;
        flat.chunks_exact(3)
            .map(|v| Vec3::from_slice(v).extend(0.0))
            .collect()
    };
    let channel = Channel {
        node,
        property,
        interpolation,
        times,
        values,
    };
    channel.validate()?;
    Ok(channel)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn panics_become_errors() {
        let result: Res<()> = quietly_catch_panics(|| panic!("index out of bounds"));
        let message = result.unwrap_err();
        assert!(message.contains("malformed glTF"), "{message}");
        assert!(message.contains("index out of bounds"), "{message}");
        // The thread is usable and no longer quiet afterwards.
        assert!(!QUIET.with(Cell::get));
        assert_eq!(quietly_catch_panics(|| Ok(7)), Ok(7));
    }

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

    #[test]
    fn normalised_components() {
        assert_eq!(component(&[255], DataType::U8, true), 1.0);
        assert_eq!(component(&[0x80], DataType::I8, true), -1.0);
        assert_eq!(component(&[0xff, 0x7f], DataType::I16, true), 1.0);
        assert_eq!(component(&[7, 0], DataType::U16, false), 7.0);
        assert_eq!(read_uint(&[1, 2, 0, 0]), 0x0201);
    }

    #[test]
    fn frame_counts() {
        assert_eq!(frame_count(0.0), 1);
        assert_eq!(frame_count(1.0), 25);
        assert_eq!(frame_count(100.0 / 24.0), 101);
        assert_eq!(frame_count(1.01), 26);
    }
}
