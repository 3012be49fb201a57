//! The glTF document before the `gltf` crate reads it, and the guard it is
//! read under: the GLB container ([`json_chunk`], the declared length),
//! animation channels the crate would refuse, extensions, what glTF forbids
//! that the crate lets through, references its validation indexes without
//! checking, warnings of what the loader ignores, and the turning of the
//! crate's errors and panics into messages.

use super::Res;
use std::cell::Cell;
use std::panic::{self, AssertUnwindSafe};
use std::path::Path;
use std::sync::Once;

thread_local! {
    /// Set while this thread parses a file, so the panic hook stays silent.
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// Runs `f`, turning a panic into an error. The default hook would print a
/// confusing "thread panicked" message before our clean error, so a hook that
/// stays silent on threads inside this function (and defers to the previous
/// hook everywhere else) is installed once.
pub(super) fn quietly_catch_panics<T>(f: impl FnOnce() -> Res<T>) -> Res<T> {
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

/// A GLB file (glTF §4.4) opens with a 12-byte header of three
/// little-endian u32: this magic, the version and the file's length; its
/// chunks follow, each its length and type (u32 each) and its bytes, the
/// first one the JSON (type `JSON`).
const GLB_MAGIC: &[u8; 4] = b"glTF";

/// The little-endian u32 at byte `at` of a GLB, if the file reaches past it.
fn glb_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let raw = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(raw.try_into().ok()?))
}

/// The JSON text of a glTF file: a `.gltf` whole, or a `.glb`'s first
/// chunk when its type is JSON and the file holds all of it (`None`
/// otherwise: the parser reports what is wrong). Whenever the `gltf`
/// crate's `Glb::from_slice` reads a GLB, this is the JSON it reads.
pub(crate) fn json_chunk(bytes: &[u8]) -> Option<&[u8]> {
    if !bytes.starts_with(GLB_MAGIC) {
        return Some(bytes);
    }
    if bytes.get(16..20)? != b"JSON" {
        return None;
    }
    let length = glb_u32(bytes, 12)? as usize;
    bytes.get(20..20usize.checked_add(length)?)
}

/// A `.glb` file that is neither a GLB (its magic) nor JSON text (some
/// tools write glTF JSON under either name) is refused naming what it
/// starts with, rather than with the JSON parser's "expected value at
/// line 1". A GLB's header and its JSON chunk's are checked before the
/// `gltf` crate reads them, as its errors do not say what is wrong ("could
/// not completely read the object", "unknown chunk type"): the file length
/// the header states (a mismatch is the clearest sign of a truncated
/// download), its version, and the chunk that must follow it. Returns the
/// bytes to parse: the file, or a GLB as far as its declared length
/// ([`within_declared_length`]; a warning names `file`).
pub(super) fn check_glb_header<'a>(named_glb: bool, bytes: &'a [u8], file: &Path) -> Res<&'a [u8]> {
    if !bytes.starts_with(GLB_MAGIC) {
        let first = bytes.iter().find(|b| !b.is_ascii_whitespace());
        if named_glb && first != Some(&b'{') {
            let head: Vec<String> = bytes.iter().take(4).map(|b| format!("{b:02x}")).collect();
            return Err(format!(
                "not a binary glTF file: a .glb starts with the bytes \"glTF\" \
                 (67 6c 54 46), this one with {}",
                if head.is_empty() {
                    "nothing (it is empty)".into()
                } else {
                    head.join(" ")
                }
            ));
        }
        return Ok(bytes);
    }
    let (Some(version), Some(declared)) = (glb_u32(bytes, 4), glb_u32(bytes, 8)) else {
        return Err(format!(
            "truncated GLB: only {} bytes, shorter than the 12-byte header",
            bytes.len()
        ));
    };
    if version != 2 {
        return Err(format!(
            "GLB version {version} is not supported: radcache reads GLB version 2 (glTF 2.0)"
        ));
    }
    let declared = declared as usize;
    if bytes.len() < declared {
        return Err(format!(
            "truncated GLB: the header declares {declared} bytes but the file has {}",
            bytes.len()
        ));
    }
    if declared < GLB_HEADER_BYTES {
        return Err(format!(
            "corrupt GLB header: it declares a file length of {declared} bytes, shorter than \
             the 12-byte header itself (the file has {})",
            bytes.len()
        ));
    }
    let within = within_declared_length(bytes, declared, file)?;
    check_json_chunk_header(within)?;
    Ok(within)
}

/// A GLB's bytes as far as the length its header declares, the whole
/// file's (glTF's GLB header): the parser reads to the file's end
/// whatever that length says, so chunks that end past it were read
/// without a word (they are refused), and bytes after it read as a
/// broken chunk where no binary chunk came before them (they are left
/// out, with a warning naming `file`).
fn within_declared_length<'a>(bytes: &'a [u8], declared: usize, file: &Path) -> Res<&'a [u8]> {
    if bytes.len() == declared {
        return Ok(bytes);
    }
    let end = chunks_end(bytes);
    if end > declared {
        return Err(format!(
            "corrupt GLB header: it declares a file length of {declared} bytes, but its chunks \
             end at byte {end} (the file has {})",
            bytes.len()
        ));
    }
    eprintln!(
        "warning: {}: {} bytes follow the {declared} bytes the GLB header declares as the \
         file's length; ignored",
        file.display(),
        bytes.len() - declared
    );
    Ok(&bytes[..declared])
}

/// Where a GLB's chunks end: its JSON chunk's end, or its binary chunk's
/// when a chunk header of that type follows the JSON (where
/// [`check_json_chunk_header`] finds it).
fn chunks_end(bytes: &[u8]) -> usize {
    let json_length = glb_u32(bytes, GLB_HEADER_BYTES).unwrap_or(0) as usize;
    let json_end = (GLB_HEADER_BYTES + CHUNK_HEADER_BYTES).saturating_add(json_length);
    let bin_type = (json_end.checked_add(CHUNK_HEADER_BYTES))
        .and_then(|type_end| bytes.get(type_end - 4..type_end));
    match glb_u32(bytes, json_end).filter(|_| bin_type == Some(b"BIN\0".as_slice())) {
        Some(bin_length) => (json_end + CHUNK_HEADER_BYTES).saturating_add(bin_length as usize),
        None => json_end,
    }
}

/// Bytes of a GLB's header, and of each chunk's header (its length and
/// type).
const GLB_HEADER_BYTES: usize = 12;
const CHUNK_HEADER_BYTES: usize = 8;

/// The JSON chunk that must follow a GLB's header is there, and, when
/// something follows it, ends where the next chunk can be found: GLB
/// chunks are padded to 4 bytes, and a JSON chunk whose length is not a
/// multiple of 4 leaves the next one's header out of place, unless its
/// writer left the padding out too.
fn check_json_chunk_header(bytes: &[u8]) -> Res<()> {
    let start = GLB_HEADER_BYTES + CHUNK_HEADER_BYTES;
    if bytes.len() == GLB_HEADER_BYTES {
        return Err("the GLB has no JSON chunk: the file ends after its 12-byte header".into());
    }
    let Some(length) = glb_u32(bytes, GLB_HEADER_BYTES).filter(|_| bytes.len() >= start) else {
        return Err(format!(
            "truncated GLB: the file ends within the header of its JSON chunk ({} bytes)",
            bytes.len()
        ));
    };
    let end = start.saturating_add(length as usize);
    let next_type = end
        .checked_add(CHUNK_HEADER_BYTES)
        .and_then(|type_end| bytes.get(type_end - 4..type_end));
    if length % 4 != 0 && end < bytes.len() && next_type != Some(b"BIN\0".as_slice()) {
        return Err(format!(
            "corrupt GLB: the JSON chunk's length, {length} bytes, is not a multiple of 4 \
             (GLB chunks are padded to 4 bytes), and no chunk follows where it ends"
        ));
    }
    Ok(())
}

/// The file without its animation channels that name no target node, if
/// it has any (`None`: nothing to take off, or JSON the parser will
/// report). The spec lets an extension (`KHR_animation_pointer`) name what
/// such a channel animates, but the crate refuses a channel without a
/// node; they are ignored with a warning, and so is an animation left
/// without channels.
pub(super) fn without_channels_lacking_a_node(bytes: &[u8]) -> Option<Vec<u8>> {
    let mut root: serde_json::Value = serde_json::from_slice(json_chunk(bytes)?).ok()?;
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
    // A GLB is written back with its binary chunk: one the crate cannot
    // split is left for the parser to report, without the warning.
    let glb = if bytes.starts_with(GLB_MAGIC) {
        Some(gltf::binary::Glb::from_slice(bytes).ok()?)
    } else {
        None
    };
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

/// What glTF forbids and the `gltf` crate does not check: an
/// `asset.minVersion` past the 2.0 this reader reads, and a node with both
/// a matrix and translation, rotation or scale (§5.25: one or the other).
pub(super) fn check_asset_and_nodes(root: &gltf::json::Root) -> Res<()> {
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

/// Says what the file has that this reader ignores (textures, skinning,
/// morph targets, extensions, point and line primitives) or reads otherwise than
/// its maker may have meant (a Blender file's light units), so that a
/// render that looks wrong is not a surprise.
pub(super) fn warn_of_ignored_features(root: &gltf::json::Root) {
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
            "warning: this file comes from Blender; its light intensities are read as W/sr \
             (W/m² for a sun), but Blender's exporter writes candela and lux (683 × W/sr, \
             683 × W/m²) unless its Lighting Mode is 'Unitless': exported so, they render 683 \
             times too bright"
        );
    }
}

/// The glTF extension that lets vertex positions and normals be integers
/// (what gltfpack writes by default). The `gltf` crate does not know it, so
/// it is taken off `extensionsRequired` before the crate validates the file:
/// this loader decodes such accessors itself (in [`super::accessors`]).
const MESH_QUANTIZATION: &str = "KHR_mesh_quantization";

/// Whether this loader reads extension `e`: those the `gltf` crate is
/// built to read (its features in Cargo.toml) and [`MESH_QUANTIZATION`].
fn reads_extension(e: &str) -> bool {
    gltf::json::extensions::ENABLED_EXTENSIONS.contains(&e) || e == MESH_QUANTIZATION
}

/// Refuses a file that requires an extension this loader cannot read (a
/// compressed mesh, say), naming it; takes [`MESH_QUANTIZATION`] off the
/// required extensions (the crate would refuse it) and says whether the
/// file uses it.
pub(super) fn check_extensions(root: &mut gltf::json::Root) -> Res<bool> {
    if let Some(e) = (root.extensions_required.iter()).find(|e| !reads_extension(e)) {
        let readable = gltf::json::extensions::ENABLED_EXTENSIONS.join(", ");
        return Err(format!(
            "the file requires the extension {e}, which radcache cannot read (it reads {readable} and {MESH_QUANTIZATION})"
        ));
    }
    root.extensions_required.retain(|e| e != MESH_QUANTIZATION);
    Ok(root.extensions_used.iter().any(|e| e == MESH_QUANTIZATION))
}

/// References that `gltf`'s validation indexes without checking (POSITION
/// accessors, which its own validation hook reads) or does not check at all
/// (animation targets); either would panic later.
pub(super) fn check_unvalidated_references(root: &gltf::json::Root) -> Res<()> {
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
/// zeros, as [`Buffers`](super::accessors::Buffers) reads it.
pub(super) fn validated(root: gltf::json::Root) -> Res<gltf::Document> {
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

pub(super) fn parse_error(e: gltf::Error) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A GLB of `json` and the binary chunk `bin`, as the `gltf` crate
    /// writes it.
    fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
        gltf::binary::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length: 0,
            },
            json: json.into(),
            bin: Some(bin.into()),
        }
        .to_vec()
        .unwrap()
    }

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
    fn json_chunk_is_what_the_crate_reads() {
        let json = br#"{"asset":{"version":"2.0"}}"#;
        assert_eq!(json_chunk(json), Some(&json[..]));
        let glb = glb(json, &[1, 2, 3, 4]);
        let read = gltf::binary::Glb::from_slice(&glb).unwrap();
        assert_eq!(json_chunk(&glb), Some(&*read.json));
        // Too short for its chunk header or its JSON, or the first chunk
        // not JSON: none, as the crate refuses them.
        assert_eq!(json_chunk(&glb[..19]), None);
        assert_eq!(json_chunk(&glb[..30]), None);
        let mut bin_first = glb.clone();
        bin_first[16..20].copy_from_slice(b"BIN\0");
        assert_eq!(json_chunk(&bin_first), None);
        assert!(gltf::binary::Glb::from_slice(&bin_first).is_err());
    }

    #[test]
    fn a_glb_keeps_its_binary_chunk_when_channels_are_taken_off() {
        let json = serde_json::json!({"animations": [{"channels": [
            {"sampler": 0, "target": {"node": 0, "path": "scale"}},
            {"sampler": 0, "target": {"path": "pointer"}},
        ]}]});
        let json = serde_json::to_vec(&json).unwrap();
        let bin = [1u8, 2, 3, 4, 5, 6, 7, 8];
        let glb = glb(&json, &bin);
        let rewritten = without_channels_lacking_a_node(&glb).unwrap();
        let read = gltf::binary::Glb::from_slice(&rewritten).unwrap();
        assert_eq!(read.bin.as_deref(), Some(&bin[..]));
        let root: serde_json::Value =
            serde_json::from_slice(json_chunk(&rewritten).unwrap()).unwrap();
        assert_eq!(
            root["animations"][0]["channels"].as_array().unwrap().len(),
            1
        );
        // A GLB the crate cannot split is left as it is.
        let mut broken = glb.clone();
        broken[4] = 3; // version 3
        assert_eq!(without_channels_lacking_a_node(&broken), None);
    }
}
