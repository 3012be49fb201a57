//! glTF loader tests: the two committed scenes load with the facts their
//! files state, and broken files give an error naming the file and the
//! problem instead of a panic.

use glam::{Mat4, Quat, Vec3};
use radcache::scene::{LightKind, Scene};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{tri_bin, tri_json, TRI};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/scenes")
        .join(name)
}

fn close(a: Vec3, b: Vec3, eps: f32) -> bool {
    (a - b).abs().max_element() <= eps
}

fn object(scene: &Scene, name: &str) -> usize {
    scene
        .objects
        .iter()
        .position(|o| o.name == name)
        .unwrap_or_else(|| panic!("no object {name}"))
}

fn material<'a>(scene: &'a Scene, name: &str) -> &'a radcache::scene::Material {
    scene
        .materials
        .iter()
        .find(|m| m.name == name)
        .unwrap_or_else(|| panic!("no material {name}"))
}

// ---------------------------------------------------------------- good files

#[test]
fn cube_in_box_structure() {
    let scene = Scene::load(&data("cube_in_box.glb")).unwrap();
    assert_eq!(scene.name, "cube_in_box");
    assert_eq!(scene.nodes.len(), 4);
    let names: Vec<&str> = scene.nodes.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, ["room", "light", "camera", "cube"]);
    assert!(scene.nodes.iter().all(|n| n.parent.is_none()));
    assert_eq!(scene.objects.len(), 3);
    assert!(scene.lights.is_empty());
    // Keys span 0..=100/24 s: frames 0..=100 at 24 fps.
    assert_eq!(scene.frame_count, 101);
    // Room: 24 + 6 + 6 indices; light: 6; cube: 36.
    let tris: Vec<usize> = scene
        .objects
        .iter()
        .map(|o| o.mesh.triangles.len())
        .collect();
    assert_eq!(tris, [12, 2, 12]);
    // The room's three primitives keep their own materials.
    let room = &scene.objects[object(&scene, "room")].mesh;
    let room_mats: Vec<&str> = room
        .materials
        .iter()
        .map(|&m| scene.materials[m as usize].name.as_str())
        .collect();
    assert_eq!(room_mats.iter().filter(|&&m| m == "white").count(), 8);
    assert_eq!(room_mats.iter().filter(|&&m| m == "red").count(), 2);
    assert_eq!(room_mats.iter().filter(|&&m| m == "green").count(), 2);
    assert_eq!(room.normals.len(), room.positions.len());
}

#[test]
fn cube_in_box_camera_and_materials() {
    let scene = Scene::load(&data("cube_in_box.glb")).unwrap();
    assert_eq!(scene.nodes[scene.camera.node].name, "camera");
    assert!((scene.camera.yfov - 0.8727).abs() < 1e-4);
    let snap = scene.snapshot(0.0);
    assert!(close(snap.camera.position, Vec3::new(0.0, 1.0, 2.9), 1e-6));

    let light = material(&scene, "light");
    assert!(close(light.emission, Vec3::new(30.0, 27.0, 22.5), 1e-4));
    assert!(!light.double_sided);
    let white = material(&scene, "white");
    assert_eq!(white.emission, Vec3::ZERO);
    assert!(close(white.diffuse, Vec3::new(0.725, 0.71, 0.68), 1e-6));
    assert!(!white.is_glossy());
}

#[test]
fn cube_in_box_dynamic_and_static() {
    let scene = Scene::load(&data("cube_in_box.glb")).unwrap();
    assert!(scene.object_is_dynamic(object(&scene, "cube")));
    assert!(!scene.object_is_dynamic(object(&scene, "room")));
    assert!(!scene.object_is_dynamic(object(&scene, "light")));
    let snap = scene.snapshot(1.0);
    assert_eq!(snap.triangles.len(), 26);
    assert_eq!(snap.static_count, 14);
}

/// The cube's animation keys, read with the `gltf` crate's own readers (not
/// our loader): (times, translations, rotations).
type Keys = (Vec<f32>, Vec<[f32; 3]>, Vec<[f32; 4]>);

fn cube_keys() -> Keys {
    use gltf::animation::util::ReadOutputs;
    let (doc, buffers, _) = gltf::import(data("cube_in_box.glb")).unwrap();
    let (mut times, mut translations, mut rotations) = (vec![], vec![], vec![]);
    for channel in doc
        .animations()
        .flat_map(|a| a.channels().collect::<Vec<_>>())
    {
        assert_eq!(channel.target().node().name(), Some("cube"));
        let reader = channel.reader(|b| Some(&buffers[b.index()]));
        times = reader.read_inputs().unwrap().collect();
        match reader.read_outputs().unwrap() {
            ReadOutputs::Translations(t) => translations = t.collect(),
            ReadOutputs::Rotations(r) => rotations = r.into_f32().collect(),
            _ => panic!("unexpected channel"),
        }
    }
    (times, translations, rotations)
}

#[test]
fn cube_in_box_snapshot_matches_keys() {
    let scene = Scene::load(&data("cube_in_box.glb")).unwrap();
    let cube = object(&scene, "cube");
    let (times, translations, rotations) = cube_keys();
    assert_eq!(times.len(), 101);
    for k in [0, 1, 37, 64, 100] {
        let snap = scene.snapshot(times[k]);
        let (_, r, t) = snap.object_to_world[cube].to_scale_rotation_translation();
        assert!(
            close(t, Vec3::from(translations[k]), 1e-5),
            "key {k}: {t} vs {:?}",
            translations[k]
        );
        let key = Quat::from_array(rotations[k]).normalize();
        assert!(r.dot(key).abs() > 1.0 - 1e-5, "key {k}: {r} vs {key}");
    }
    // The cube does move over the animation.
    assert!(!close(
        Vec3::from(translations[0]),
        Vec3::from(translations[50]),
        1e-3
    ));
}

#[test]
fn spheres_materials_and_motion() {
    let scene = Scene::load(&data("spheres.glb")).unwrap();
    assert_eq!(scene.nodes.len(), 19);
    assert_eq!(scene.objects.len(), 18);
    assert_eq!(scene.frame_count, 101);

    // roughness 0.1 → α = 0.01 → n = 2/α² − 2 = 19998.
    let glossy = material(&scene, "sphere2_glossy");
    assert!(glossy.is_glossy());
    assert!(
        (glossy.exponent - 19998.0).abs() < 5.0,
        "{}",
        glossy.exponent
    );
    assert!(close(glossy.specular, Vec3::splat(0.04), 1e-6));
    assert!(close(glossy.diffuse, Vec3::splat(0.85 * 0.96), 1e-5));

    let metal = material(&scene, "sphere5_glossy_metal");
    assert!(close(metal.specular, Vec3::new(0.7, 0.3, 0.8), 1e-6));
    assert_eq!(metal.diffuse, Vec3::ZERO);
    assert!((metal.exponent - 19998.0).abs() < 5.0);

    assert!(!material(&scene, "sphere0").is_glossy());
    let glossy_count = scene.materials.iter().filter(|m| m.is_glossy()).count();
    assert_eq!(glossy_count, 5); // spheres 2, 5, 8, 11 and 14

    for i in 0..16 {
        let s = object(&scene, &format!("sphere{i}"));
        assert!(scene.object_is_dynamic(s));
        assert_eq!(scene.objects[s].mesh.triangles.len(), 320);
    }
    assert!(!scene.object_is_dynamic(object(&scene, "room")));
    // Node scale is part of the rest transform: sphere0 has radius ≈ 0.121.
    let s0 = &scene.nodes[scene.objects[object(&scene, "sphere0")].node];
    assert!((s0.rest.scale.x - 0.121_254_77).abs() < 1e-6);
}

// ------------------------------------------------------- a small valid file

/// Writes `<name>.gltf` (and, if given, its `<name>.bin`) into `dir`.
fn write_case(
    dir: &Path,
    name: &str,
    edit: impl FnOnce(&mut Value),
    bin: Option<Vec<u8>>,
) -> PathBuf {
    let mut doc = tri_json(&format!("{name}.bin"));
    edit(&mut doc);
    let path = dir.join(format!("{name}.gltf"));
    std::fs::write(&path, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
    if let Some(bin) = bin {
        std::fs::write(dir.join(format!("{name}.bin")), bin).unwrap();
    }
    path
}

fn good_bin() -> Option<Vec<u8>> {
    Some(tri_bin(TRI, [0, 1, 2]))
}

/// Loading must fail (not panic) with the file name and `phrase` in the message.
fn assert_error(path: &Path, phrase: &str) {
    let err = match Scene::load(path) {
        Ok(_) => panic!("{} loaded but should fail with '{phrase}'", path.display()),
        Err(e) => e.to_string(),
    };
    let file = path.file_name().unwrap().to_str().unwrap();
    assert!(err.contains(file), "error does not name {file}: {err}");
    assert!(err.contains(phrase), "error lacks '{phrase}': {err}");
}

#[test]
fn small_valid_gltf_loads() {
    // The base of the broken cases must itself be fine, so that each broken
    // case fails for its own edit.
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(dir.path(), "ok", |_| {}, good_bin());
    let scene = Scene::load(&path).unwrap();
    assert_eq!(scene.objects.len(), 1);
    assert_eq!(scene.frame_count, 1);
    let mesh = &scene.objects[0].mesh;
    assert_eq!(mesh.triangles, [[0, 1, 2]]);
    // No NORMAL attribute: computed from the counter-clockwise face (+Z).
    assert!(mesh.normals.iter().all(|&n| close(n, Vec3::Z, 1e-6)));
    assert!(close(scene.materials[0].emission, Vec3::ONE, 0.0));
    assert!((scene.camera.yfov - 0.8).abs() < 1e-6);
}

/// Factors outside [0, 1], where glTF puts them, are clamped to it (with a
/// warning, `tests/cli.rs`): a base colour over 1 would make the surface
/// give back more light than it receives, and an emissive factor over 1
/// is brightness that only `KHR_materials_emissive_strength` may add.
#[test]
fn factors_outside_the_unit_range_are_clamped() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "overbright",
        |d| {
            d["materials"][0]["emissiveFactor"] = json!([2.0, 0.5, -1.0]);
            d["materials"][0]["pbrMetallicRoughness"] =
                json!({"baseColorFactor": [1.5, 0.25, -0.5, 1.0], "roughnessFactor": 7.0});
        },
        good_bin(),
    );
    let scene = Scene::load(&path).unwrap();
    let glow = material(&scene, "glow");
    assert_eq!(glow.emission, Vec3::new(1.0, 0.5, 0.0));
    assert_eq!(glow.diffuse, Vec3::new(1.0, 0.25, 0.0));
    assert!(!glow.is_glossy());
}

#[test]
fn data_uri_buffer_and_extras_load() {
    use base64_like::encode;
    let dir = tempfile::tempdir().unwrap();
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        encode(&tri_bin(TRI, [0, 1, 2]))
    );
    let path = write_case(
        dir.path(),
        "embedded",
        |d| {
            d["buffers"][0]["uri"] = json!(uri);
            // A primitive without material gets the default white diffuse,
            // a point light keeps the scene lit, a matrix node is decomposed.
            d["meshes"][0]["primitives"][0]
                .as_object_mut()
                .unwrap()
                .remove("material");
            d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
            d["extensions"] = json!({"KHR_lights_punctual": {"lights": [
                {"type": "spot", "color": [1.0, 0.5, 0.25], "intensity": 4.0,
                 "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
                {"type": "directional", "intensity": 1.0}
            ]}});
            d["nodes"][0]["matrix"] = json!([
                2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 1.0, 2.0, 3.0, 1.0
            ]);
            d["nodes"]
                .as_array_mut()
                .unwrap()
                .push(json!({"name": "lamp", "extensions": {"KHR_lights_punctual": {"light": 0}}}));
            d["nodes"].as_array_mut().unwrap().push(
                json!({"name": "sun", "rotation": [-0.70710677, 0.0, 0.0, 0.70710677],
                           "extensions": {"KHR_lights_punctual": {"light": 1}}}),
            );
            d["scenes"][0]["nodes"] = json!([0, 1, 2, 3]);
            // `extras` of any JSON type, as the spec allows (objects
            // alone loaded before).
            d["extras"] = json!([1, 2]);
            d["nodes"][0]["extras"] = json!("a note");
            d["materials"][0]["extras"] = json!(42);
        },
        None,
    );
    let scene = Scene::load(&path).unwrap();
    let default = &scene.materials[scene.objects[0].mesh.materials[0] as usize];
    assert!(close(default.diffuse, Vec3::splat(0.8), 1e-6));
    assert_eq!(scene.lights.len(), 2);
    let lamp = &scene.lights[0];
    assert_eq!(scene.nodes[lamp.node].name, "lamp");
    assert!(close(lamp.intensity, Vec3::new(4.0, 2.0, 1.0), 1e-6));
    let spot = lamp.kind.spot().unwrap();
    assert!((spot.inner_cone - 0.2).abs() < 1e-6 && (spot.outer_cone - 0.5).abs() < 1e-6);
    // The sun, turned a quarter round X, shines straight down.
    let sun = &scene.lights[1];
    assert_eq!(scene.nodes[sun.node].name, "sun");
    assert_eq!(sun.kind, LightKind::Directional);
    assert!(close(sun.intensity, Vec3::ONE, 1e-6));
    let placed = scene.snapshot(0.0).lights[1];
    assert!(close(placed.direction, Vec3::NEG_Y, 1e-6), "{placed:?}");
    let rest = scene.nodes[0].rest;
    assert!(close(rest.translation, Vec3::new(1.0, 2.0, 3.0), 1e-6));
    assert!(close(rest.scale, Vec3::splat(2.0), 1e-6));
}

/// Minimal base64 encoder so the test needs no extra dependency.
mod base64_like {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

    pub fn encode(bytes: &[u8]) -> String {
        let mut out = String::new();
        for chunk in bytes.chunks(3) {
            let b = [
                chunk[0],
                *chunk.get(1).unwrap_or(&0),
                *chunk.get(2).unwrap_or(&0),
            ];
            let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
            for i in 0..4 {
                if i <= chunk.len() {
                    out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
                } else {
                    out.push('=');
                }
            }
        }
        out
    }
}

#[test]
fn animated_gltf_channels() {
    // A STEP translation and a CUBICSPLINE scale channel from binary data.
    let dir = tempfile::tempdir().unwrap();
    let mut bin = tri_bin(TRI, [0, 1, 2]);
    let times = [0.0f32, 0.5, 1.0];
    let steps = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    let cubic: Vec<[f32; 3]> = (0..3)
        .flat_map(|k| [[0.0; 3], [1.0 + k as f32; 3], [0.0; 3]])
        .collect();
    for v in times
        .iter()
        .chain(steps.iter().flatten())
        .chain(cubic.iter().flatten())
    {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let len = bin.len();
    let animated = |d: &mut serde_json::Value| {
        d["buffers"][0]["byteLength"] = json!(len);
        let views = d["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 12}));
        views.push(json!({"buffer": 0, "byteOffset": 60, "byteLength": 36}));
        views.push(json!({"buffer": 0, "byteOffset": 96, "byteLength": 108}));
        let acc = d["accessors"].as_array_mut().unwrap();
        acc.push(json!({"bufferView": 2, "componentType": 5126, "count": 3, "type": "SCALAR", "min": [0.0], "max": [1.0]}));
        acc.push(json!({"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC3"}));
        acc.push(json!({"bufferView": 4, "componentType": 5126, "count": 9, "type": "VEC3"}));
        d["animations"] = json!([{
            "channels": [
                {"sampler": 0, "target": {"node": 0, "path": "translation"}},
                {"sampler": 1, "target": {"node": 0, "path": "scale"}}
            ],
            "samplers": [
                {"input": 2, "output": 3, "interpolation": "STEP"},
                {"input": 2, "output": 4, "interpolation": "CUBICSPLINE"}
            ]
        }]);
    };
    // One animation may drive a node's property once (glTF §3.11).
    let twice = write_case(
        dir.path(),
        "twice",
        |d| {
            animated(d);
            d["animations"][0]["channels"][1]["target"]["path"] = json!("translation");
        },
        Some(bin.clone()),
    );
    assert_error(&twice, "its translation is driven twice in this animation");
    let bin_for_pointer = bin.clone();
    let path = write_case(dir.path(), "anim", animated, Some(bin));
    let scene = Scene::load(&path).unwrap();
    assert_eq!(scene.animation.channels.len(), 2);
    // 1 s at 24 fps: frames 0..=24.
    assert_eq!(scene.frame_count, 25);
    let trs = |t: f32| scene.animation.local_trs(0, scene.nodes[0].rest, t);
    assert!(close(trs(0.49).translation, Vec3::ZERO, 0.0));
    assert!(close(trs(0.5).translation, Vec3::X, 0.0));
    assert!(close(trs(0.5).scale, Vec3::splat(2.0), 1e-6));
    // Zero tangents: the midpoint of a segment is the average of its keys.
    assert!(close(trs(0.75).scale, Vec3::splat(2.5), 1e-6));
    assert!(scene.object_is_dynamic(0));
    // A channel without a target node (spec-valid: an extension would name
    // its target) is ignored, and an animation left without channels too;
    // the crate refused the file.
    let pointer = write_case(
        dir.path(),
        "pointer",
        |d| {
            animated(d);
            let channels = d["animations"][0]["channels"].as_array_mut().unwrap();
            channels.push(json!({"sampler": 0, "target": {"path": "pointer"}}));
            let mut only = d["animations"][0].clone();
            only["channels"] = json!([{"sampler": 1, "target": {"path": "pointer"}}]);
            d["animations"].as_array_mut().unwrap().push(only);
        },
        Some(bin_for_pointer),
    );
    let with_pointer = Scene::load(&pointer).unwrap();
    assert_eq!(with_pointer.animation.channels.len(), 2);
    assert!(close(
        with_pointer
            .animation
            .local_trs(0, with_pointer.nodes[0].rest, 0.75)
            .scale,
        Vec3::splat(2.5),
        1e-6
    ));
}

#[test]
fn sparse_positions_apply() {
    // A sparse accessor replaces vertex 2 of the dense POSITION data.
    let dir = tempfile::tempdir().unwrap();
    let mut bin = tri_bin(TRI, [0, 1, 2]);
    bin.extend_from_slice(&2u32.to_le_bytes());
    for v in [0.0f32, 2.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let len = bin.len();
    let path = write_case(
        dir.path(),
        "sparse",
        |d| {
            d["buffers"][0]["byteLength"] = json!(len);
            let views = d["bufferViews"].as_array_mut().unwrap();
            views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 4}));
            views.push(json!({"buffer": 0, "byteOffset": 52, "byteLength": 12}));
            d["accessors"][0]["sparse"] = json!({"count": 1,
                "indices": {"bufferView": 2, "componentType": 5125},
                "values": {"bufferView": 3}});
        },
        Some(bin),
    );
    let scene = Scene::load(&path).unwrap();
    let p = &scene.objects[0].mesh.positions;
    assert_eq!(p[..2], [Vec3::ZERO, Vec3::X]);
    assert_eq!(p[2], Vec3::new(0.0, 2.0, 0.0));
}

// ------------------------------------------------------------- bad inputs

#[test]
fn nonexistent_file() {
    let dir = tempfile::tempdir().unwrap();
    assert_error(&dir.path().join("nothing_here.glb"), "file not found");
}

#[test]
fn unknown_extension() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mesh.obj");
    std::fs::write(&path, "v 0 0 0\n").unwrap();
    assert_error(&path, "unsupported file extension '.obj'");
}

#[test]
fn truncated_glb() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(data("cube_in_box.glb")).unwrap();
    for (name, len) in [
        ("half.glb", bytes.len() / 2),
        ("header.glb", 10),
        ("tail.glb", bytes.len() - 4),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes[..len]).unwrap();
        assert_error(&path, "truncated");
    }
}

#[test]
fn garbage_bytes() {
    let dir = tempfile::tempdir().unwrap();
    // Deterministic pseudo-random bytes (xorshift).
    let mut x = 0x1234_5678_9abc_def0u64;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    // A .gltf is JSON text: the parser says where it fails. A .glb is
    // told its first bytes are not the GLB magic.
    let path = dir.path().join("garbage.gltf");
    std::fs::write(&path, &bytes).unwrap();
    assert_error(&path, "not a valid glTF");
    let path = dir.path().join("garbage.glb");
    std::fs::write(&path, &bytes).unwrap();
    let head: Vec<String> = bytes[..4].iter().map(|b| format!("{b:02x}")).collect();
    assert_error(&path, &format!("not a binary glTF file: a .glb starts with the bytes \"glTF\" (67 6c 54 46), this one with {}", head.join(" ")));
    std::fs::write(&path, b"").unwrap();
    assert_error(&path, "this one with nothing (it is empty)");
    // glTF JSON written under the .glb name still loads, and so does JSON
    // that opens with a UTF-8 byte order mark, under either name.
    let gltf = write_case(dir.path(), "json", |_| {}, good_bin());
    let named_glb = dir.path().join("json.glb");
    std::fs::copy(&gltf, &named_glb).unwrap();
    Scene::load(&named_glb).unwrap();
    let with_bom = [b"\xEF\xBB\xBF".as_slice(), &std::fs::read(&gltf).unwrap()].concat();
    for name in ["json_bom.gltf", "json_bom.glb"] {
        let path = dir.path().join(name);
        std::fs::write(&path, &with_bom).unwrap();
        Scene::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    // A GLB header followed by garbage chunks.
    let mut glb = b"glTF".to_vec();
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(bytes.len() as u32 + 12).to_le_bytes());
    glb.extend_from_slice(&bytes);
    let path = dir.path().join("garbage_chunks.glb");
    std::fs::write(&path, &glb).unwrap();
    assert_error(&path, "corrupt GLB");
}

#[test]
fn missing_buffer_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(dir.path(), "nobuffer", |_| {}, None);
    assert_error(&path, "missing buffer file");
    assert_error(&path, "nobuffer.bin");
}

#[test]
fn short_buffer_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(dir.path(), "shortbuf", |_| {}, Some(vec![0; 20]));
    assert_error(&path, "buffer 0 is truncated");
}

#[test]
fn index_out_of_range() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "badindex",
        |_| {},
        Some(tri_bin(TRI, [0, 1, 7])),
    );
    assert_error(&path, "vertex index 7 is out of range");
}

/// glTF gives every attribute of a primitive POSITION's count (§3.7.2.1):
/// a NORMAL accessor with fewer or more elements is an error naming both
/// counts, not normals silently dropped and recomputed.
#[test]
fn an_attribute_count_unlike_positions_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = tri_bin(TRI, [0, 1, 2]);
    for _ in 0..4 {
        for v in [0.0f32, 0.0, 1.0] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    let len = bin.len();
    for count in [2, 4, 3] {
        let path = write_case(
            dir.path(),
            &format!("normals{count}"),
            |d| {
                d["buffers"][0]["byteLength"] = json!(len);
                (d["bufferViews"].as_array_mut().unwrap())
                    .push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 48}));
                (d["accessors"].as_array_mut().unwrap()).push(
                    json!({"bufferView": 2, "componentType": 5126, "count": count, "type": "VEC3"}),
                );
                d["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = json!(2);
            },
            Some(bin.clone()),
        );
        if count == 3 {
            Scene::load(&path).unwrap();
        } else {
            assert_error(
                &path,
                &format!(
                    "mesh of node 'tri': primitive 0: accessor 2 (NORMAL) has {count} elements \
                     but accessor 0 (POSITION) has 3"
                ),
            );
        }
    }
}

/// Without `indices` a primitive's vertices are its corners: a count that
/// is no multiple of 3 speaks of vertices, not of indices it does not have.
#[test]
fn triangles_without_indices_count_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = tri_bin(TRI, [0, 1, 2]);
    bin.truncate(36);
    for v in [1.0f32, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let path = write_case(
        dir.path(),
        "noindices",
        |d| {
            d["bufferViews"][0]["byteLength"] = json!(48);
            d["accessors"][0]["count"] = json!(4);
            d["accessors"][0]["max"] = json!([1.0, 1.0, 0.0]);
            (d["meshes"][0]["primitives"][0].as_object_mut().unwrap()).remove("indices");
        },
        Some(bin),
    );
    assert_error(
        &path,
        "primitive 0: 4 vertices for TRIANGLES without indices, not a multiple of 3",
    );
}

#[test]
fn accessor_past_buffer_view() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "longacc",
        |d| d["accessors"][0]["count"] = json!(1000),
        good_bin(),
    );
    assert_error(&path, "out of range of its buffer view");
    let path = write_case(
        dir.path(),
        "longview",
        |d| d["bufferViews"][0]["byteLength"] = json!(4000),
        good_bin(),
    );
    assert_error(&path, "out of range of buffer 0");
    let path = write_case(
        dir.path(),
        "stride",
        |d| d["bufferViews"][0]["byteStride"] = json!(4),
        good_bin(),
    );
    // glTF validation rejects strides below 4 only; 4 < 12 is ours to catch.
    assert_error(&path, "stride");
}

#[test]
fn infinite_transform() {
    let dir = tempfile::tempdir().unwrap();
    // 1e39 overflows f32 to infinity (JSON cannot hold NaN literally).
    let path = write_case(
        dir.path(),
        "inftrs",
        |d| d["nodes"][0]["translation"] = json!([1e39, 0.0, 0.0]),
        good_bin(),
    );
    assert_error(&path, "NaN or infinite value in its transform");
    let path = write_case(
        dir.path(),
        "infmatrix",
        |d| {
            d["nodes"][0]["matrix"] = json!([
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1e39, 0.0, 1.0
            ])
        },
        good_bin(),
    );
    assert_error(&path, "NaN or infinite value in its transform");
}

#[test]
fn nan_vertex_position() {
    let dir = tempfile::tempdir().unwrap();
    let mut tri = TRI;
    tri[1][2] = f32::NAN;
    let path = write_case(
        dir.path(),
        "nanvertex",
        |_| {},
        Some(tri_bin(tri, [0, 1, 2])),
    );
    assert_error(&path, "NaN or infinite vertex position");
}

#[test]
fn empty_scene() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "empty",
        |d| {
            d["scenes"][0]["nodes"] = json!([1]);
        },
        good_bin(),
    );
    assert_error(&path, "no triangle with any area");
    // Only line primitives: still nothing to render.
    let path = write_case(
        dir.path(),
        "lines",
        |d| d["meshes"][0]["primitives"][0]["mode"] = json!(1),
        good_bin(),
    );
    assert_error(&path, "no triangle with any area");
}

/// Triangles without area are dropped at load (a BVH cannot split many of
/// them at one point, and every ray near it would test them all): one
/// good triangle and 20,000 on a single vertex load as the one.
#[test]
fn triangles_without_area_are_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let count = 3 + 3 * 20_000;
    let mut indices = vec![0u32, 1, 2];
    indices.resize(count, 1);
    let mut bin = Vec::new();
    for v in TRI.iter().flatten() {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for i in &indices {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let path = write_case(
        dir.path(),
        "needle",
        |d| {
            d["buffers"][0]["byteLength"] = json!(bin.len());
            d["bufferViews"][1]["byteLength"] = json!(4 * count);
            d["accessors"][1]["count"] = json!(count);
        },
        Some(bin.clone()),
    );
    let scene = Scene::load(&path).unwrap();
    let triangles: usize = scene.objects.iter().map(|o| o.mesh.triangles.len()).sum();
    assert_eq!(triangles, 1);
}

/// What glTF forbids and its parser lets through: a node with both a
/// matrix and TRS, and a file that needs a later glTF than 2.0.
#[test]
fn what_gltf_forbids_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let both = write_case(
        dir.path(),
        "both",
        |d| {
            d["nodes"][0]["matrix"] = json!([
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0
            ]);
            d["nodes"][0]["translation"] = json!([1.0, 0.0, 0.0]);
        },
        good_bin(),
    );
    assert_error(&both, "node 'tri' has both a matrix and translation");
    let later = write_case(
        dir.path(),
        "later",
        |d| d["asset"]["minVersion"] = json!("2.1"),
        good_bin(),
    );
    assert_error(&later, "needs glTF 2.1 at least");
    // A camera whose type names an object it lacks (the parser unwrapped it).
    for (kind, other) in [
        (
            "perspective",
            json!({"orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.1, "zfar": 9.0}}),
        ),
        (
            "orthographic",
            json!({"perspective": {"yfov": 0.8, "znear": 0.01}}),
        ),
    ] {
        let mut camera = other;
        camera["type"] = json!(kind);
        let path = write_case(dir.path(), kind, |d| d["cameras"][0] = camera, good_bin());
        assert_error(
            &path,
            &format!("camera 0: its type is \"{kind}\" but it has no \"{kind}\" object"),
        );
    }
    let fine = write_case(
        dir.path(),
        "fine",
        |d| d["asset"]["minVersion"] = json!("2.0"),
        good_bin(),
    );
    Scene::load(&fine).unwrap();
}

/// `KHR_mesh_quantization` (gltfpack's default output): integer vertex
/// positions decoded as the extension says; without it they are refused.
#[test]
fn quantized_positions_need_their_extension() {
    let dir = tempfile::tempdir().unwrap();
    // u16 positions, not normalised (the node's scale would dequantise
    // them), 8-byte stride as vertex attributes need; then u32 indices.
    let mut bin = Vec::new();
    for v in [[0u16, 0, 0], [2, 0, 0], [0, 3, 0]] {
        for c in v.into_iter().chain([0]) {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u32, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let quantize = |d: &mut Value| {
        d["bufferViews"][0] =
            json!({"buffer": 0, "byteOffset": 0, "byteLength": 24, "byteStride": 8});
        d["bufferViews"][1] = json!({"buffer": 0, "byteOffset": 24, "byteLength": 12});
        d["buffers"][0]["byteLength"] = json!(36);
        d["accessors"][0]["componentType"] = json!(5123);
        d["accessors"][0]["max"] = json!([2.0, 3.0, 0.0]);
    };
    let bare = write_case(dir.path(), "bare", quantize, Some(bin.clone()));
    assert_error(
        &bare,
        "accessor 0 (POSITION) holds U16 components; glTF allows FLOAT unless the file uses KHR_mesh_quantization",
    );
    let declared = write_case(
        dir.path(),
        "declared",
        |d| {
            quantize(d);
            d["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
            d["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
        },
        Some(bin),
    );
    let scene = Scene::load(&declared).unwrap();
    let mesh = &scene.objects[0].mesh;
    assert_eq!(
        mesh.positions,
        [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0)
        ]
    );
    // An extension the loader cannot decode stays refused.
    let draco = write_case(
        dir.path(),
        "draco",
        |d| {
            d["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
            d["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
        },
        good_bin(),
    );
    assert_error(
        &draco,
        "requires the extension KHR_draco_mesh_compression, which radcache cannot read",
    );
}

/// A skinned mesh (skins are ignored) is placed by its first joint, never
/// by its own node (glTF §3.7.3.3), and follows that joint's animation.
#[test]
fn a_skinned_mesh_rides_its_first_joint() {
    skinned_mesh_rides_its_first_joint(Vec3::ONE);
}

/// The same with a mirrored joint (a rig's left side): the joint and its
/// inverse bind matrix mirror each other, so at the bind pose the mesh lies
/// as the file put it, its winding (and so its front face) too.
#[test]
fn a_skinned_mesh_on_a_mirrored_joint_keeps_its_front_face() {
    skinned_mesh_rides_its_first_joint(Vec3::new(-1.0, 1.0, 1.0));
}

/// The mesh's corners, in order, where the file put them, lifted by the
/// joint's animation; the joint (rest pose at x = 1) scaled by `scale`.
fn skinned_mesh_rides_its_first_joint(scale: Vec3) {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = good_bin().unwrap();
    // The joint's inverse bind matrix: the inverse of its rest pose.
    let rest = Mat4::from_scale_rotation_translation(scale, Quat::IDENTITY, Vec3::X);
    let inverse_bind = rest.inverse();
    let times = [0.0f32, 1.0];
    let joint_at = [[1.0f32, 0.0, 0.0], [1.0, 2.0, 0.0]];
    let floats = inverse_bind.to_cols_array().into_iter().chain(times);
    for x in floats.chain(joint_at.into_iter().flatten()) {
        bin.extend_from_slice(&x.to_le_bytes());
    }
    let len = bin.len();
    let path = write_case(
        dir.path(),
        "skinned",
        |d| {
            d["buffers"][0]["byteLength"] = json!(len);
            d["nodes"][0]["skin"] = json!(0);
            d["nodes"][0]["translation"] = json!([5.0, 0.0, 0.0]);
            d["nodes"]
                .as_array_mut()
                .unwrap()
                .push(json!({"name": "joint", "translation": [1.0, 0.0, 0.0],
                             "scale": scale.to_array()}));
            d["scenes"][0]["nodes"] = json!([0, 1, 2]);
            d["skins"] = json!([{"joints": [2], "inverseBindMatrices": 2}]);
            let views = d["bufferViews"].as_array_mut().unwrap();
            views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 64}));
            views.push(json!({"buffer": 0, "byteOffset": 112, "byteLength": 8}));
            views.push(json!({"buffer": 0, "byteOffset": 120, "byteLength": 24}));
            let accessors = d["accessors"].as_array_mut().unwrap();
            accessors
                .push(json!({"bufferView": 2, "componentType": 5126, "count": 1, "type": "MAT4"}));
            accessors.push(
                json!({"bufferView": 3, "componentType": 5126, "count": 2, "type": "SCALAR",
                                  "min": [0.0], "max": [1.0]}),
            );
            accessors
                .push(json!({"bufferView": 4, "componentType": 5126, "count": 2, "type": "VEC3"}));
            d["animations"] = json!([{
                "channels": [{"sampler": 0, "target": {"node": 2, "path": "translation"}}],
                "samplers": [{"input": 3, "output": 4}]
            }]);
        },
        Some(bin),
    );
    let scene = Scene::load(&path).unwrap();
    for (t, lift) in [(0.0, 0.0), (1.0, 2.0)] {
        let snap = scene.snapshot(t);
        let corners = snap.triangles[0].p;
        for (c, want) in corners.iter().zip(TRI) {
            let want = Vec3::from(want) + Vec3::Y * lift;
            assert!(close(*c, want, 1e-5), "t = {t}: {c} vs {want}");
        }
    }
}

#[test]
fn no_emitter_no_light() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "dark",
        |d| d["materials"][0]["emissiveFactor"] = json!([0.0, 0.0, 0.0]),
        good_bin(),
    );
    assert_error(&path, "no light source");
}

#[test]
fn no_camera() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "nocam",
        |d| d["scenes"][0]["nodes"] = json!([0]),
        good_bin(),
    );
    assert_error(&path, "no camera");
}

#[test]
fn hierarchy_cycle() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "cycle",
        |d| {
            d["nodes"][0]["children"] = json!([2]);
            d["nodes"]
                .as_array_mut()
                .unwrap()
                .push(json!({"name": "loop", "children": [0]}));
        },
        good_bin(),
    );
    assert_error(&path, "not a tree");
}

/// A hierarchy deeper than any thread's stack would hold if world
/// transforms were resolved by recursion renders: the triangle at the
/// bottom of a chain of 200,000 nodes, the camera under the triangle. The
/// chain runs from the last node to the first, so that no parent is
/// resolved before its child asks for it (with recursion the process
/// aborted, with the main thread's 8 MiB stack as with 2 MiB, a server's
/// blocking threads').
#[test]
fn a_node_chain_deeper_than_a_stack_renders() {
    const DEPTH: usize = 200_000;
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "deep",
        |d| {
            let mut nodes = vec![json!({"name": "tri", "mesh": 0, "children": [DEPTH + 1]})];
            nodes.extend((1..=DEPTH).map(|i| json!({"children": [i - 1]})));
            nodes.push(json!({"name": "cam", "camera": 0, "translation": [0.0, 0.0, 3.0]}));
            d["nodes"] = Value::Array(nodes);
            d["scenes"][0]["nodes"] = json!([DEPTH]);
        },
        good_bin(),
    );
    let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["render", "--method", "path", "--spp", "1", "--size", "4x4"])
        .args(["--frames", "0..1", "-q"])
        .arg(&path)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let film = radcache::film::read_exr(&dir.path().join("out/frame_0000.exr")).unwrap();
    assert!(
        film.pixels.iter().any(|p| p.max_element() > 0.0),
        "the triangle is seen"
    );
}

#[test]
fn bad_animation_keys() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = tri_bin(TRI, [0, 1, 2]);
    for v in [1.0f32, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for v in [0.0f32; 6] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let len = bin.len();
    let path = write_case(
        dir.path(),
        "backwards",
        |d| {
            d["buffers"][0]["byteLength"] = json!(len);
            let views = d["bufferViews"].as_array_mut().unwrap();
            views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 8}));
            views.push(json!({"buffer": 0, "byteOffset": 56, "byteLength": 24}));
            let acc = d["accessors"].as_array_mut().unwrap();
            acc.push(json!({"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]}));
            acc.push(json!({"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC3"}));
            d["animations"] = json!([{"name": "oops",
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
                "samplers": [{"input": 2, "output": 3}]}]);
        },
        Some(bin),
    );
    assert_error(&path, "not increasing");
    assert_error(&path, "animation 'oops'");
}

#[test]
fn dangling_reference_is_invalid() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "dangling",
        |d| d["nodes"][0]["mesh"] = json!(9),
        good_bin(),
    );
    assert_error(&path, "invalid glTF");
}

#[test]
fn mutated_glb_never_panics() {
    // Overwrite bytes all over a valid GLB (JSON and binary chunk alike):
    // whatever the damage, loading returns instead of panicking.
    let dir = tempfile::tempdir().unwrap();
    let original = std::fs::read(data("cube_in_box.glb")).unwrap();
    let path = dir.path().join("mutant.glb");
    let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
    for _ in 0..300 {
        let mut bytes = original.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() % bytes.len() as u64) as usize;
            bytes[at] = [b'9', b'-', b'0', b'"', 0xff, 0x00][(next() % 6) as usize];
        }
        std::fs::write(&path, &bytes).unwrap();
        match Scene::load(&path) {
            // What loads must also evaluate without panicking.
            Ok(scene) => drop(scene.snapshot(1.0)),
            Err(e) => {
                assert!(e.to_string().contains("mutant.glb"), "{e}");
                // The panic net must not be what caught it: our checks come first.
                assert!(!e.to_string().contains("parser failed"), "{e}");
            }
        }
    }
}

fn xorshift(mut x: u64) -> impl FnMut() -> u64 {
    move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    }
}

/// JSON pointers of every number in `v`.
fn number_pointers(v: &Value, at: String, out: &mut Vec<String>) {
    match v {
        Value::Number(_) => out.push(at),
        Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                number_pointers(item, format!("{at}/{i}"), out);
            }
        }
        Value::Object(map) => {
            for (k, item) in map {
                number_pointers(item, format!("{at}/{k}"), out);
            }
        }
        _ => {}
    }
}

#[test]
fn mutated_numbers_never_panic() {
    // Replace numbers of the cube-in-box JSON (counts, offsets, strides,
    // indices, factors) with hostile values; the binary chunk is kept as an
    // external buffer file. Loading must return, never panic.
    let dir = tempfile::tempdir().unwrap();
    let (doc, buffers, _) = gltf::import(data("cube_in_box.glb")).unwrap();
    let mut json = serde_json::to_value(doc.into_json()).unwrap();
    json["buffers"][0]["uri"] = json!("mutant.bin");
    std::fs::write(dir.path().join("mutant.bin"), &buffers[0].0).unwrap();
    let path = dir.path().join("mutant.gltf");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    Scene::load(&path).expect("the unmutated conversion loads");

    let mut pointers = Vec::new();
    number_pointers(&json, String::new(), &mut pointers);
    let hostile = [
        json!(0),
        json!(1),
        json!(3),
        json!(-1),
        json!(4095),
        json!(1u64 << 40),
        json!(-2.5),
        json!(1e39),
    ];
    let mut next = xorshift(0x2545_f491_4f6c_dd1d);
    for _ in 0..400 {
        let mut mutant = json.clone();
        let mut changed = vec![];
        for _ in 0..1 + next() % 3 {
            let at = &pointers[(next() % pointers.len() as u64) as usize];
            let val = hostile[(next() % hostile.len() as u64) as usize].clone();
            changed.push(format!("{at}={val}"));
            *mutant.pointer_mut(at).unwrap() = val;
        }
        std::fs::write(&path, serde_json::to_vec(&mutant).unwrap()).unwrap();
        match Scene::load(&path) {
            Ok(scene) => drop(scene.snapshot(1.0)),
            Err(e) => {
                assert!(e.to_string().contains("mutant.gltf"), "{e}");
                assert!(
                    !e.to_string().contains("parser failed"),
                    "{e} after {changed:?}"
                );
            }
        }
    }
}

/// A rotation channel over keys at t = 0 and 1 whose second key is `q`
/// (a glTF with its animation in the triangle's buffer).
fn rotation_keys_case(dir: &Path, name: &str, q: [f32; 4], interpolation: &str) -> PathBuf {
    let mut bin = tri_bin(TRI, [0, 1, 2]);
    for v in [0.0f32, 1.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let keys: Vec<[f32; 4]> = match interpolation {
        // In-tangent, value, out-tangent per key.
        "CUBICSPLINE" => vec![
            [0.0; 4],
            [0.0, 0.0, 0.0, 1.0],
            [0.0; 4],
            [0.0; 4],
            q,
            [0.0; 4],
        ],
        _ => vec![[0.0, 0.0, 0.0, 1.0], q],
    };
    for v in keys.iter().flatten() {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let len = bin.len();
    let count = keys.len();
    let interpolation = interpolation.to_string();
    write_case(
        dir,
        name,
        |d| {
            d["buffers"][0]["byteLength"] = json!(len);
            let views = d["bufferViews"].as_array_mut().unwrap();
            views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 8}));
            views.push(json!({"buffer": 0, "byteOffset": 56, "byteLength": 16 * count}));
            let acc = d["accessors"].as_array_mut().unwrap();
            acc.push(json!({"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]}));
            acc.push(
                json!({"bufferView": 3, "componentType": 5126, "count": count, "type": "VEC4"}),
            );
            d["animations"] = json!([{"name": "spin",
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}],
                "samplers": [{"input": 2, "output": 3, "interpolation": interpolation}]}]);
        },
        Some(bin),
    )
}

/// Values that pass as finite numbers but would make NaN or overflowing
/// geometry (and obvhs panic) are errors that say which.
#[test]
fn transforms_that_break_tracing_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    for interpolation in ["LINEAR", "STEP", "CUBICSPLINE"] {
        let path = rotation_keys_case(
            dir.path(),
            &format!("zero_{interpolation}"),
            [0.0; 4],
            interpolation,
        );
        assert_error(&path, "has no orientation");
    }
    let tiny = rotation_keys_case(dir.path(), "tiny", [1e-30, 0.0, 0.0, 0.0], "LINEAR");
    assert_error(&tiny, "has no orientation");
    // A proper second key loads, and its frames stay finite.
    let fine = rotation_keys_case(dir.path(), "fine", [0.0, 1.0, 0.0, 0.0], "CUBICSPLINE");
    let scene = Scene::load(&fine).unwrap();
    for t in [0.0, 0.3, 0.5, 0.7, 1.0] {
        let snap = scene.snapshot(t);
        assert!(snap
            .triangles
            .iter()
            .all(|tri| tri.p.iter().all(|p| p.is_finite())));
    }
    let huge_scale = write_case(
        dir.path(),
        "hugescale",
        |d| d["nodes"][0]["scale"] = json!([1e38, 1e38, 1e38]),
        good_bin(),
    );
    assert_error(&huge_scale, "scale has a component of magnitude 1e38");
    let huge_position = write_case(
        dir.path(),
        "hugeposition",
        |_| {},
        Some(tri_bin(
            [[0.0; 3], [3e38, 0.0, 0.0], [0.0, 1.0, 0.0]],
            [0, 1, 2],
        )),
    );
    assert_error(&huge_position, "vertex position has a component");
    // Each within bounds, together past them: 1e8 m scaled by 1e8 under a
    // parent scaled by 1e8.
    let far = write_case(
        dir.path(),
        "far",
        |d| {
            d["nodes"][0]["scale"] = json!([1e8, 1e8, 1e8]);
            let nodes = d["nodes"].as_array_mut().unwrap();
            nodes.push(json!({"name": "big", "scale": [1e8, 1e8, 1e8], "children": [0]}));
            d["scenes"][0]["nodes"] = json!([2, 1]);
        },
        Some(tri_bin(
            [[0.0; 3], [1e8, 0.0, 0.0], [0.0, 1.0, 0.0]],
            [0, 1, 2],
        )),
    );
    assert_error(&far, "node 'tri' places a vertex");
    // Scales that compound past f32's range: the world transform overflows
    // (infinite, and NaN where infinity meets a zero), which the error says
    // rather than reporting "a coordinate of magnitude NaN". 20 parents
    // scaled by 100 overflow the transform; 19 leave it finite (1e38) and
    // carry a vertex at 1e8 to infinity.
    for (parents, x) in [(20, 1.0), (19, 1e8)] {
        let path = write_case(
            dir.path(),
            &format!("chain{parents}"),
            |d| {
                let nodes = d["nodes"].as_array_mut().unwrap();
                for i in 0..parents {
                    let child = if i == 0 { 0 } else { i + 1 };
                    nodes.push(json!({"scale": [100.0, 100.0, 100.0], "children": [child]}));
                }
                d["scenes"][0]["nodes"] = json!([parents + 1, 1]);
            },
            Some(tri_bin(
                [[0.0; 3], [x, 0.0, 0.0], [0.0, 1.0, 0.0]],
                [0, 1, 2],
            )),
        );
        let err = Scene::load(&path).unwrap_err().to_string();
        assert!(!err.contains("NaN"), "{err}");
        assert_error(
            &path,
            if parents == 20 {
                "node 'tri' has a world transform at t = 0 that is not finite"
            } else {
                "node 'tri' places a vertex at a non-finite coordinate at t = 0"
            },
        );
    }
    // A light under parents whose scales compound to infinity (1e40):
    // its samples, and every pixel it lit, were NaN.
    let far_lamp = write_case(
        dir.path(),
        "farlamp",
        |d| {
            d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
            d["extensions"] =
                json!({"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 1.0}]}});
            let nodes = d["nodes"].as_array_mut().unwrap();
            for i in 2..7 {
                nodes.push(json!({"scale": [1e8, 1e8, 1e8], "children": [i + 1]}));
            }
            nodes.push(json!({"name": "lamp", "translation": [1.0, 0.0, 0.0],
                "extensions": {"KHR_lights_punctual": {"light": 0}}}));
            d["scenes"][0]["nodes"] = json!([0, 1, 2]);
        },
        good_bin(),
    );
    assert_error(
        &far_lamp,
        "light 'lamp' is placed at a coordinate past 1e17",
    );
    // Keys near f32's limit: a cubic spline's span between them was
    // infinite, and every sample of the channel NaN.
    let far_keys = rotation_keys_case(dir.path(), "farkeys", [0.0, 1.0, 0.0, 0.0], "CUBICSPLINE");
    let bin = dir.path().join("farkeys.bin");
    let mut bytes = std::fs::read(&bin).unwrap();
    for (i, t) in [-3e38f32, 3e38].iter().enumerate() {
        bytes[48 + 4 * i..52 + 4 * i].copy_from_slice(&t.to_le_bytes());
    }
    std::fs::write(&bin, bytes).unwrap();
    let mut doc: Value = serde_json::from_slice(&std::fs::read(&far_keys).unwrap()).unwrap();
    doc["accessors"][2]["min"] = json!([-3e38f32]);
    doc["accessors"][2]["max"] = json!([3e38f32]);
    std::fs::write(&far_keys, serde_json::to_vec(&doc).unwrap()).unwrap();
    assert_error(&far_keys, "a key at t = -3e38 s, beyond ±1e8 s");
}

/// Scenes that would render black without a word: no triangle with any
/// area, a camera scaled to nothing; and a spot light whose cones cross.
#[test]
fn scenes_that_render_nothing_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let flat = write_case(
        dir.path(),
        "flat",
        |_| {},
        Some(tri_bin(
            [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
            [0, 1, 2],
        )),
    );
    assert_error(&flat, "no triangle with any area");
    let squashed = write_case(
        dir.path(),
        "squashed",
        |d| d["nodes"][0]["scale"] = json!([0.0, 0.0, 0.0]),
        good_bin(),
    );
    assert_error(&squashed, "no triangle has any area");
    let spot = write_case(
        dir.path(),
        "spot",
        |d| {
            d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
            d["extensions"] = json!({"KHR_lights_punctual": {"lights": [
                {"type": "spot", "intensity": 1.0,
                 "spot": {"innerConeAngle": 1.0, "outerConeAngle": 0.5}}]}});
            d["nodes"][1]["extensions"] = json!({"KHR_lights_punctual": {"light": 0}});
        },
        good_bin(),
    );
    assert_error(&spot, "innerConeAngle 1 is larger than outerConeAngle 0.5");
    // Light near f32's limit: infinite and NaN pixels. 1e6 is fine.
    for (strength, fine) in [(3e38f32, false), (1e6, true)] {
        let name = format!("strength{fine}");
        let glow = write_case(
            dir.path(),
            &name,
            |d| {
                d["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]);
                d["materials"][0]["extensions"] =
                    json!({"KHR_materials_emissive_strength": {"emissiveStrength": strength}});
            },
            good_bin(),
        );
        let name = format!("lamp{fine}");
        let lamp = write_case(
            dir.path(),
            &name,
            |d| {
                d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
                d["extensions"] = json!({"KHR_lights_punctual": {"lights": [
                    {"type": "point", "intensity": strength}]}});
                d["nodes"][1]["extensions"] = json!({"KHR_lights_punctual": {"light": 0}});
            },
            good_bin(),
        );
        if fine {
            Scene::load(&glow).unwrap();
            Scene::load(&lamp).unwrap();
        } else {
            assert_error(&glow, "material 'glow' emits 3e38 W·sr⁻¹·m⁻²");
            assert_error(&lamp, "over the 1e12 allowed");
        }
    }
    let odd = write_case(
        dir.path(),
        "odd",
        |d| {
            d["accessors"][1]["count"] = json!(2);
            d["bufferViews"][1]["byteLength"] = json!(8);
        },
        good_bin(),
    );
    assert_error(&odd, "2 indices for TRIANGLES, not a multiple of 3");
}

#[test]
fn another_gltf_version_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "v3",
        |d| d["asset"]["version"] = json!("3.0"),
        good_bin(),
    );
    assert_error(&path, "glTF version 3.0 is not supported (expected 2.x)");
}

/// A FIFO or a link to a device is refused before it is read (it would
/// block, or read until memory runs out).
#[test]
fn a_scene_path_that_is_no_regular_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("zero.glb");
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    assert_error(&link, "not a regular file");
}

/// `Scene::load(path)` on a thread of its own, waited for at most 20 s: a
/// loader that reads a device or a FIFO to its end fails the test instead
/// of hanging it.
fn load_within_20s(path: &Path) -> Result<Scene, String> {
    let (tx, rx) = std::sync::mpsc::channel();
    let owned = path.to_owned();
    std::thread::spawn(move || {
        let _ = tx.send(Scene::load(&owned).map_err(|e| e.to_string()));
    });
    rx.recv_timeout(std::time::Duration::from_secs(20))
        .unwrap_or_else(|_| panic!("loading {} did not end within 20 s", path.display()))
}

/// A buffer URI is read as the file it names with its `%XX` escapes
/// decoded and a `file:` scheme taken off — and, like the scene path, only
/// if that is a regular file: `file:///dev/zero`, `%2Fdev%2Fzero` and a
/// FIFO whose name is escaped slipped past the check (the crate read them
/// for ever, or blocked). Other schemes are refused by name; a buffer far
/// longer than declared is read only as far as declared.
#[test]
fn buffer_uris_are_decoded_and_read_only_from_regular_files() {
    let dir = tempfile::tempdir().unwrap();
    let with_uri = |name: &str, uri: &str| {
        let uri = uri.to_string();
        write_case(
            dir.path(),
            name,
            move |doc| doc["buffers"][0]["uri"] = json!(uri),
            None,
        )
    };
    let fifo = dir.path().join("a fifo.bin");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    for (name, uri) in [
        ("file_zero", "file:///dev/zero"),
        ("localhost_zero", "file://LocalHost/dev/zero"),
        ("escaped_zero", "%2Fdev%2Fzero"),
        ("escaped_fifo", "a%20fifo.bin"),
    ] {
        let err = load_within_20s(&with_uri(name, uri)).unwrap_err();
        assert!(
            err.contains("not a regular file") && err.contains("buffer 0"),
            "{uri}: {err}"
        );
    }
    let err = load_within_20s(&with_uri("web", "https://example.com/t.bin")).unwrap_err();
    assert!(err.contains("'https:' URIs"), "{err}");
    let err = load_within_20s(&with_uri("remote", "file://example.com/t.bin")).unwrap_err();
    assert!(err.contains("only local files"), "{err}");
    let err = load_within_20s(&with_uri("missing", "no%20such.bin")).unwrap_err();
    assert!(
        err.contains("missing buffer file") && err.contains("no such.bin"),
        "{err}"
    );
    // Escaped names, a file: URI relative to the scene, and a buffer file
    // with a gigabyte's worth of zeros after its 48 declared bytes (sparse)
    // load, and read what they name.
    std::fs::write(dir.path().join("my mesh.bin"), good_bin().unwrap()).unwrap();
    let long = std::fs::File::create(dir.path().join("long.bin")).unwrap();
    std::io::Write::write_all(&mut &long, &good_bin().unwrap()).unwrap();
    long.set_len(1 << 30).unwrap();
    let absolute = dir.path().join("my mesh.bin");
    let absolute = absolute.to_str().unwrap().replace(' ', "%20");
    for (name, uri) in [
        ("escaped", "my%20mesh.bin".to_string()),
        ("file_relative", "file:my%20mesh.bin".to_string()),
        ("file_absolute", format!("file://{absolute}")),
        ("file_localhost", format!("file://localhost{absolute}")),
        ("long", "long.bin".to_string()),
    ] {
        let uri = uri.as_str();
        let scene = load_within_20s(&with_uri(name, uri)).unwrap_or_else(|e| panic!("{uri}: {e}"));
        assert_eq!(scene.objects[0].mesh.triangles, [[0, 1, 2]], "{uri}");
    }
}

/// Loading confined to a directory (as `radcache serve --scenes DIR`
/// does) reads buffers inside it only: `..`, an absolute path, a link to a
/// file or a folder outside, and the scene file itself outside are refused
/// naming the URI; a buffer in a subdirectory, a `data:` URI and a missing
/// file inside (reported missing) behave as unconfined. Unconfined (the
/// command line), a buffer outside loads as before; the scene's hash reads
/// the same files under the same confinement.
#[test]
fn a_confined_load_reads_files_inside_its_directory_only() {
    use radcache::render::{scene_identity, scene_identity_confined, SceneSource};
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scenes");
    std::fs::create_dir_all(root.join("bins")).unwrap();
    std::fs::write(dir.path().join("outside.bin"), good_bin().unwrap()).unwrap();
    std::fs::write(root.join("bins/inside.bin"), good_bin().unwrap()).unwrap();
    std::os::unix::fs::symlink(dir.path().join("outside.bin"), root.join("link.bin")).unwrap();
    std::os::unix::fs::symlink(dir.path(), root.join("up")).unwrap();
    let with_uri = |name: &str, uri: &str| {
        let uri = uri.to_string();
        write_case(
            &root,
            name,
            move |d| d["buffers"][0]["uri"] = json!(uri),
            None,
        )
    };
    let absolute = dir.path().join("outside.bin").display().to_string();
    for (name, uri) in [
        ("parent", "../outside.bin"),
        ("absolute", absolute.as_str()),
        ("file_uri", &format!("file://{absolute}")),
        ("linked", "link.bin"),
        ("through", "up/outside.bin"),
        ("escaped", "%2E%2E/outside.bin"),
    ] {
        let path = with_uri(name, uri);
        let err = Scene::load_confined(&path, Some(&root))
            .map(drop)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(&format!("buffer 0: URI '{uri}' names no file inside")),
            "{uri}: {err}"
        );
        let source = SceneSource::File(path.clone());
        let err = scene_identity_confined(&source, Some(&root)).unwrap_err();
        assert!(err.to_string().contains(&format!("URI '{uri}'")), "{err}");
        // The command line reads what the user's file names.
        Scene::load(&path).unwrap_or_else(|e| panic!("{uri}: {e}"));
        scene_identity(&source).unwrap();
    }
    for (name, uri) in [
        ("sub", "bins/inside.bin".to_string()),
        ("sub_dotted", "bins/../bins/inside.bin".to_string()),
        (
            "embedded",
            format!(
                "data:application/octet-stream;base64,{}",
                base64_like::encode(&good_bin().unwrap())
            ),
        ),
    ] {
        let path = with_uri(name, &uri);
        let scene = Scene::load_confined(&path, Some(&root)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scene.objects[0].mesh.triangles, [[0, 1, 2]], "{uri}");
        scene_identity_confined(&SceneSource::File(path), Some(&root)).unwrap();
    }
    let err = Scene::load_confined(&with_uri("gone", "bins/gone.bin"), Some(&root))
        .map(drop)
        .unwrap_err()
        .to_string();
    assert!(err.contains("missing buffer file"), "{err}");
    // The scene file itself, outside the directory or linked out of it.
    let elsewhere = write_case(dir.path(), "elsewhere", |_| {}, good_bin());
    std::os::unix::fs::symlink(&elsewhere, root.join("elsewhere.gltf")).unwrap();
    Scene::load(&elsewhere).unwrap();
    for path in [elsewhere, root.join("elsewhere.gltf")] {
        let err = Scene::load_confined(&path, Some(&root))
            .map(drop)
            .unwrap_err()
            .to_string();
        assert!(err.contains("not inside the directory"), "{err}");
        let source = SceneSource::File(path);
        assert!(scene_identity_confined(&source, Some(&root)).is_err());
    }
}

/// A triangle repeated (the same corners in the same winding, whichever
/// corner comes first) is kept once; the one facing the other way stays.
/// 20,000 copies load into two triangles (the BVH builder took time
/// quadratic in the copies).
#[test]
fn repeated_triangles_are_kept_once() {
    let dir = tempfile::tempdir().unwrap();
    let mut indices = vec![0u32, 1, 2, 1, 2, 0, 0, 2, 1, 2, 0, 1];
    for _ in 0..20_000 {
        indices.extend([0, 1, 2]);
    }
    let mut bin = tri_bin(TRI, [0, 1, 2])[..36].to_vec();
    for i in &indices {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let len = bin.len();
    let count = indices.len();
    let path = write_case(
        dir.path(),
        "copies",
        move |doc| {
            doc["buffers"][0]["byteLength"] = json!(len);
            doc["bufferViews"][1]["byteLength"] = json!(len - 36);
            doc["accessors"][1]["count"] = json!(count);
        },
        Some(bin),
    );
    let scene = Scene::load(&path).unwrap();
    assert_eq!(scene.objects[0].mesh.triangles, [[0, 1, 2], [0, 2, 1]]);
    assert_eq!(scene.objects[0].mesh.materials.len(), 2);
}

/// A camera scaled to nothing, at rest or by its animation, has no
/// orientation in its matrix: it keeps the one its rotation gives (its
/// frames were black, or the file refused), and sees what the unscaled
/// camera sees.
#[test]
fn a_camera_scaled_to_nothing_keeps_its_orientation() {
    let dir = tempfile::tempdir().unwrap();
    let turned =
        |d: &mut Value| d["nodes"][1]["rotation"] = json!([0.0, 0.0, 0.38268343, 0.9238795]);
    let seeing = Scene::load(&write_case(dir.path(), "seeing", turned, good_bin())).unwrap();
    let expected = seeing.camera_at(0.0);
    let blind = write_case(
        dir.path(),
        "blind",
        |d| {
            turned(d);
            d["nodes"][1]["scale"] = json!([0.0, 0.0, 0.0]);
        },
        good_bin(),
    );
    let shrinking = write_case(
        dir.path(),
        "shrinking",
        |d| {
            turned(d);
            let bin = scale_keys(d, [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
            d["animations"] = json!([{
                "channels": [{"sampler": 0, "target": {"node": 1, "path": "scale"}}],
                "samplers": [{"input": 2, "output": 3}]
            }]);
            std::fs::write(dir.path().join("shrinking.bin"), bin).unwrap();
        },
        None,
    );
    for (path, t) in [(blind, 0.0), (shrinking, 1.0)] {
        let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let camera = scene.snapshot(t).camera;
        assert!(
            camera.basis.abs_diff_eq(expected.basis, 1e-6) && camera.position == expected.position,
            "{}: {:?} against {:?}",
            path.display(),
            camera.basis,
            expected.basis
        );
    }
}

/// An accessor without a buffer view (and without sparse values) holds
/// zeros (glTF §3.6.2.1; the crate refused it): zero normals are
/// recomputed from the face, a view-less index list draws one triangle of
/// vertex 0, which has no area.
#[test]
fn an_accessor_without_a_buffer_view_holds_zeros() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "viewless",
        |d| {
            d["accessors"]
                .as_array_mut()
                .unwrap()
                .push(json!({"componentType": 5126, "count": 3, "type": "VEC3"}));
            d["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = json!(2);
        },
        good_bin(),
    );
    let scene = Scene::load(&path).unwrap();
    let mesh = &scene.objects[0].mesh;
    assert!(
        mesh.normals.iter().all(|&n| close(n, Vec3::Z, 1e-6)),
        "{:?}",
        mesh.normals
    );
    let path = write_case(
        dir.path(),
        "viewless_indices",
        |d| {
            d["accessors"][1]
                .as_object_mut()
                .unwrap()
                .remove("bufferView")
                .map(drop)
                .unwrap()
        },
        good_bin(),
    );
    assert_error(&path, "the scene has no triangle with any area");
}

/// A small file whose primitives all name one large accessor of zeros (or
/// whose mesh many nodes instance) is refused from the accessors' declared
/// counts, before anything is decoded: 64 primitives of a 256 MiB
/// accessor asked for over 30 GiB, 21 instances of one such mesh 12 GiB.
/// Primitives the loader skips (points) do not count.
#[test]
fn a_small_file_that_decodes_to_too_much_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let huge = |primitives: usize| {
        move |d: &mut Value| {
            d["accessors"].as_array_mut().unwrap().push(
                json!({"componentType": 5126, "count": 22_369_621, "type": "VEC3", "min": [0.0, 0.0, 0.0], "max": [0.0, 0.0, 0.0]}),
            );
            let prim = json!({"attributes": {"POSITION": 2}});
            let mut all = vec![d["meshes"][0]["primitives"][0].clone()];
            all.extend(std::iter::repeat_n(prim, primitives));
            d["meshes"][0]["primitives"] = Value::Array(all);
        }
    };
    let many = write_case(dir.path(), "many", huge(64), good_bin());
    assert!(std::fs::metadata(&many).unwrap().len() < 10_000);
    assert_error(&many, "over the 4 GiB a scene may take");
    // As points, which the loader skips, they cost nothing and load.
    let points = write_case(
        dir.path(),
        "points",
        |d| {
            huge(64)(d);
            for prim in d["meshes"][0]["primitives"].as_array_mut().unwrap()[1..].iter_mut() {
                prim["mode"] = json!(0);
            }
        },
        good_bin(),
    );
    Scene::load(&points).unwrap();
    let instanced = write_case(
        dir.path(),
        "instanced",
        |d| {
            huge(1)(d);
            let nodes = d["nodes"].as_array_mut().unwrap();
            let copies = 20;
            nodes.extend((0..copies).map(|_| json!({"mesh": 0})));
            d["scenes"][0]["nodes"] = json!((0..copies + 2).collect::<Vec<_>>());
        },
        good_bin(),
    );
    assert_error(&instanced, "over the 4 GiB a scene may take");
}

/// `radcache render` of one tiny frame of `path`, which must succeed: its
/// standard error, where the loader's warnings are.
fn render_warnings(path: &Path) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args(["render", "--method", "path", "--spp", "1", "--size", "4x4"])
        .args(["--frames", "0..1", "-q"])
        .arg(path)
        .arg("--out")
        .arg(path.with_extension("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{}: {stderr}", path.display());
    stderr
}

/// A skin's joints after the first carry nothing, so its first inverse
/// bind matrix alone is read, once for the skin: 200 nodes of a skin whose
/// 4,194,304 matrices are zeros but the first (an accessor without a
/// buffer view, the first set by a sparse value) decoded all 256 MiB of
/// them for each node, for over a minute.
#[test]
fn only_a_skins_first_inverse_bind_matrix_is_read() {
    const NODES: usize = 200;
    let dir = tempfile::tempdir().unwrap();
    let mut bin = good_bin().unwrap();
    bin.extend_from_slice(&0u32.to_le_bytes());
    // The inverse of the joint's rest pose (at x = 1).
    for x in Mat4::from_translation(-Vec3::X).to_cols_array() {
        bin.extend_from_slice(&x.to_le_bytes());
    }
    let len = bin.len();
    let path = write_case(
        dir.path(),
        "skinned_many",
        |d| {
            d["buffers"][0]["byteLength"] = json!(len);
            let views = d["bufferViews"].as_array_mut().unwrap();
            views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 4}));
            views.push(json!({"buffer": 0, "byteOffset": 52, "byteLength": 64}));
            d["accessors"].as_array_mut().unwrap().push(json!({
                "componentType": 5126, "count": 4_194_304, "type": "MAT4",
                "sparse": {"count": 1, "indices": {"bufferView": 2, "componentType": 5125},
                           "values": {"bufferView": 3}}
            }));
            d["skins"] = json!([{"joints": [2], "inverseBindMatrices": 2}]);
            let nodes = d["nodes"].as_array_mut().unwrap();
            nodes.push(json!({"name": "joint", "translation": [1.0, 0.0, 0.0]}));
            nodes.extend((0..NODES).map(|_| json!({"mesh": 0, "skin": 0})));
            d["scenes"][0]["nodes"] = json!((0..NODES + 3).collect::<Vec<_>>());
        },
        Some(bin),
    );
    let scene = load_within_20s(&path).unwrap();
    assert_eq!(scene.objects.len(), NODES + 1);
    assert!(scene.objects[1..]
        .iter()
        .all(|o| scene.nodes[o.node].name == "joint"));
    // At the bind pose, each lies where the file put it.
    for triangle in scene.snapshot(0.0).triangles.to_vec() {
        for (c, want) in triangle.p.iter().zip(TRI) {
            assert!(close(*c, Vec3::from(want), 1e-6), "{c} vs {want:?}");
        }
    }
}

/// A primitive whose POSITION or indices accessor has no buffer view (nor
/// sparse values) holds zeros, and none of its triangles has any area: it
/// is skipped, with a warning, before it is decoded (a 256 MiB accessor of
/// zeros took gigabytes, to draw nothing). A mesh left without a triangle
/// with any area is named, once however many nodes it has: it vanished
/// from the render without a word.
#[test]
fn meshes_that_draw_nothing_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = good_bin().unwrap();
    for i in [0u32, 1, 1] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let len = bin.len();
    let path = write_case(
        dir.path(),
        "nothing",
        |d| {
            d["buffers"][0]["byteLength"] = json!(len);
            (d["bufferViews"].as_array_mut().unwrap())
                .push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 12}));
            d["accessors"].as_array_mut().unwrap().extend([
                json!({"componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0.0, 0.0, 0.0], "max": [0.0, 0.0, 0.0]}),
                json!({"componentType": 5125, "count": 3, "type": "SCALAR"}),
                json!({"bufferView": 2, "componentType": 5125, "count": 3, "type": "SCALAR"}),
            ]);
            d["meshes"].as_array_mut().unwrap().extend([
                json!({"name": "zeros", "primitives": [
                    {"attributes": {"POSITION": 2}},
                    {"attributes": {"POSITION": 0}, "indices": 3}
                ]}),
                json!({"name": "flat", "primitives": [{"attributes": {"POSITION": 0}, "indices": 4}]}),
            ]);
            let nodes = d["nodes"].as_array_mut().unwrap();
            nodes.extend([json!({"mesh": 1}), json!({"mesh": 1}), json!({"mesh": 2})]);
            d["scenes"][0]["nodes"] = json!([0, 1, 2, 3, 4]);
        },
        Some(bin),
    );
    let scene = Scene::load(&path).unwrap();
    let triangles: Vec<usize> = (scene.objects.iter())
        .map(|o| o.mesh.triangles.len())
        .collect();
    assert_eq!(triangles, [1, 0, 0, 0]);
    let stderr = render_warnings(&path);
    for said in [
        "mesh 1 'zeros', primitive 0: its POSITION accessor 2 has no buffer view and no sparse \
         values, so every vertex is at the origin and no triangle has any area; skipped",
        "mesh 1 'zeros', primitive 1: its indices accessor 3 has no buffer view and no sparse \
         values, so every index is 0 and no triangle has any area; skipped",
        "mesh 1 'zeros': not drawn: none of its triangles has any area",
        "mesh 2 'flat': not drawn: none of its triangles has any area",
    ] {
        assert_warned(&stderr, &path, said);
    }
}

/// glTF allows a node only a matrix that decomposes into translation,
/// rotation and scale (§5.25), and a joint only an affine inverse bind
/// matrix: a sheared or projective one was read as another without a word
/// (the shear, or the last row, dropped). A writer's rounding (a rotation
/// and scales far apart, computed in f32) is no shear.
#[test]
fn matrices_that_are_not_translation_rotation_scale_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let with_matrix = |name: &str, node: usize, matrix: [f32; 16]| {
        write_case(
            dir.path(),
            name,
            |d| {
                let node = d["nodes"][node].as_object_mut().unwrap();
                node.remove("translation");
                node.insert("matrix".into(), json!(matrix));
            },
            good_bin(),
        )
    };
    #[rustfmt::skip]
    let cases = [
        ("shear", 0, [1.0, 0.0, 0.0, 0.0, 1.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
         "node 'tri': its matrix is sheared (its x and y axes are 33.690° apart, not 90°)"),
        ("projective", 0, [1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
         "node 'tri': its matrix has the last row (0.5, 0, 0, 1), not (0, 0, 0, 1): it is projective"),
        ("w_zero", 1, [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 3.0, 0.0],
         "node 'cam': its matrix has the last row (0, 0, 0, 0), not (0, 0, 0, 1)"),
    ];
    for (name, node, matrix, phrase) in cases {
        assert_error(&with_matrix(name, node, matrix), phrase);
    }
    let rotation = Quat::from_euler(glam::EulerRot::XYZ, 0.3, 1.1, -2.0);
    let scale = Vec3::new(1e3, 2e-3, 1.0);
    let translation = Vec3::new(1e6, -2.5, 0.125);
    let matrix = Mat4::from_scale_rotation_translation(scale, rotation, translation);
    let rounded = Scene::load(&with_matrix("rounded", 0, matrix.to_cols_array())).unwrap();
    let rest = rounded.nodes[0].rest;
    assert!(close(rest.scale, scale, 1e-3) && rest.translation == translation);
    assert!(rest.rotation.dot(rotation).abs() > 1.0 - 1e-6);
    // A skin's inverse bind matrix that is projective.
    let mut bin = good_bin().unwrap();
    let projective = [
        1.0f32, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.0, 0.0, 0.0, 1.0,
    ];
    for x in projective {
        bin.extend_from_slice(&x.to_le_bytes());
    }
    let path = write_case(
        dir.path(),
        "projective_joint",
        |d| {
            d["buffers"][0]["byteLength"] = json!(112);
            (d["bufferViews"].as_array_mut().unwrap())
                .push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 64}));
            (d["accessors"].as_array_mut().unwrap())
                .push(json!({"bufferView": 2, "componentType": 5126, "count": 1, "type": "MAT4"}));
            d["skins"] = json!([{"joints": [1], "inverseBindMatrices": 2}]);
            d["nodes"][0]["skin"] = json!(0);
        },
        Some(bin),
    );
    assert_error(
        &path,
        "skin of node 'tri': the first joint's inverse bind matrix has the last row (0, 0, 0.5, 1)",
    );
}

/// The attributes the loader does not read (texture coordinates,
/// tangents, colours, joints, weights) are not decoded, but what is wrong
/// with them is said, naming the mesh, the primitive and the attribute:
/// a count unlike POSITION's, a type glTF does not give them, elements
/// past their buffer view, a stride smaller than an element. They were
/// never looked at; the scene still loads, as it renders the same.
#[test]
fn malformed_attributes_that_are_not_read_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = good_bin().unwrap();
    bin.extend_from_slice(&[0; 32]);
    let path = write_case(
        dir.path(),
        "attributes",
        |d| {
            d["buffers"][0]["byteLength"] = json!(80);
            let views = d["bufferViews"].as_array_mut().unwrap();
            views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 32}));
            views.push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 32, "byteStride": 4}));
            d["accessors"].as_array_mut().unwrap().extend([
                json!({"bufferView": 2, "componentType": 5126, "count": 2, "type": "VEC2"}),
                json!({"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC3"}),
                json!({"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC4"}),
                json!({"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC2"}),
                json!({"componentType": 5126, "count": 2_147_483_647u32, "type": "VEC4"}),
            ]);
            d["meshes"][0]["primitives"][0]["attributes"] = json!({
                "POSITION": 0, "TEXCOORD_0": 2, "TEXCOORD_1": 3, "TANGENT": 4,
                "TEXCOORD_2": 5, "COLOR_0": 6
            });
        },
        Some(bin),
    );
    let stderr = render_warnings(&path);
    for said in [
        "accessor 2 (TEXCOORD_0) has 2 elements but accessor 0 (POSITION) has 3; glTF gives \
         every attribute of a primitive the same count; TEXCOORD_0 is ignored",
        "accessor 3 (TEXCOORD_1) has type Vec3; glTF gives TEXCOORD_1 type Vec2; TEXCOORD_1 is \
         ignored",
        "accessor 4 (TANGENT) is out of range of its buffer view; TANGENT is ignored",
        "accessor 5 (TEXCOORD_2): byte stride 4 is smaller than an element (8 bytes); \
         TEXCOORD_2 is ignored",
        "accessor 6 (COLOR_0) has 2147483647 elements but accessor 0 (POSITION) has 3",
    ] {
        let line = stderr.lines().find(|l| l.contains(said));
        let line = line.unwrap_or_else(|| panic!("expected {said:?} in: {stderr}"));
        assert!(
            line.starts_with("warning: ")
                && line.contains("mesh 0, primitive 0: ")
                && line.ends_with("is ignored: radcache does not read it"),
            "{line}"
        );
    }
}

/// A GLB of `doc` and the binary chunk `bin`, as the `gltf` crate writes it.
fn glb_of(doc: &Value, bin: Option<Vec<u8>>) -> Vec<u8> {
    gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: serde_json::to_vec(doc).unwrap().into(),
        bin: bin.map(Into::into),
    }
    .to_vec()
    .unwrap()
}

/// What is wrong with a GLB's container is said plainly, not in the words
/// of the parser ("unknown chunk type", "could not completely read the
/// object", "failed to fill whole buffer", "truncated or corrupt GLB:
/// unsupported version"), and so is a second buffer without a URI (only
/// the first may be the binary chunk; it was called missing) and a `data:`
/// URI that is not base64.
#[test]
fn a_broken_glb_container_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = tri_json("unused.bin");
    doc["buffers"][0].as_object_mut().unwrap().remove("uri");
    let glb = |doc: &Value| glb_of(doc, good_bin());
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(format!("{name}.glb"));
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let good = glb(&doc);
    Scene::load(&write("good", &good)).unwrap();
    let edited = |at: usize, value: u32| {
        let mut bytes = good.clone();
        bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
        bytes
    };
    let json_length = u32::from_le_bytes(good[12..16].try_into().unwrap());
    assert_eq!(json_length % 4, 0);
    let mut header_only = good[..12].to_vec();
    header_only[8..12].copy_from_slice(&12u32.to_le_bytes());
    let mut two_buffers = doc.clone();
    (two_buffers["buffers"].as_array_mut().unwrap()).push(json!({"byteLength": 16}));
    let mut bad_base64 = doc.clone();
    bad_base64["buffers"][0]["uri"] = json!("data:application/octet-stream;base64,@@@");
    for (name, bytes, phrase) in [
        (
            "unaligned",
            edited(12, json_length - 1),
            format!(
                "the JSON chunk's length, {} bytes, is not a multiple of 4",
                json_length - 1
            ),
        ),
        (
            "length_zero",
            edited(8, 0),
            "corrupt GLB header: it declares a file length of 0 bytes, shorter than the 12-byte \
             header itself"
                .into(),
        ),
        (
            "header_only",
            header_only,
            "the GLB has no JSON chunk: the file ends after its 12-byte header".into(),
        ),
        (
            "version1",
            edited(4, 1),
            "GLB version 1 is not supported: radcache reads GLB version 2".into(),
        ),
        (
            "version3",
            edited(4, 3),
            "GLB version 3 is not supported".into(),
        ),
        (
            "two_buffers",
            glb(&two_buffers),
            "buffer 1 has no URI: only the first buffer (buffer 0) may be the GLB binary chunk"
                .into(),
        ),
        (
            "bad_base64",
            glb(&bad_base64),
            "buffer 0: its data: URI is not valid base64".into(),
        ),
    ] {
        let path = write(name, &bytes);
        assert_error(&path, &phrase);
        let err = Scene::load(&path).map(drop).unwrap_err().to_string();
        for parser_said in [
            "truncated",
            "unknown chunk",
            "could not",
            "fill whole",
            "missing",
        ] {
            assert!(!err.contains(parser_said), "{name}: {err}");
        }
    }
}

/// Nodes that place the same mesh at the same spot are drawn once, with a
/// warning (the BVH builders are quadratic in coincident triangles: 5,000
/// copies took 44 s for two frames at 16×16); copies elsewhere are kept.
#[test]
fn coincident_copies_of_a_mesh_are_drawn_once() {
    const COPIES: usize = 30;
    let dir = tempfile::tempdir().unwrap();
    let copies = |spread: f32| {
        move |d: &mut Value| {
            let nodes = d["nodes"].as_array_mut().unwrap();
            nodes[0]["translation"] = json!([0.25, 0.5, -1.0]);
            for i in 1..COPIES {
                let x = 0.25 + spread * i as f32;
                nodes.push(json!({"name": format!("copy{i}"), "mesh": 0,
                                  "translation": [x, 0.5, -1.0]}));
            }
            d["scenes"][0]["nodes"] = json!((0..COPIES + 1).collect::<Vec<_>>());
        }
    };
    let same = write_case(dir.path(), "same", copies(0.0), good_bin());
    let scene = Scene::load(&same).unwrap();
    assert_eq!(scene.objects.len(), 1);
    assert_eq!(scene.objects[0].name, "tri");
    let warnings = render_warnings(&same);
    assert!(
        warnings.contains(&format!(
            "{} mesh node(s) place the same mesh exactly where another node does \
             (e.g. node 'copy1' repeats node 'tri')",
            COPIES - 1
        )),
        "{warnings}"
    );
    let spread = write_case(dir.path(), "spread", copies(0.5), good_bin());
    assert_eq!(Scene::load(&spread).unwrap().objects.len(), COPIES);
    assert!(!render_warnings(&spread).contains("same mesh"));
}

/// An animation that carries the camera past what can be traced at t > 0
/// (five parents each scaled from 1 to 1e8) is refused at load, naming the
/// camera's node and the frame: its frames rendered black, without a word.
#[test]
fn a_camera_animated_past_the_world_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "camfar",
        |d| {
            let bin = scale_keys(d, [1.0, 1.0, 1.0, 1e8, 1e8, 1e8]);
            // Nodes 2..=6, each the parent of the one before; 2 of the camera.
            let nodes = d["nodes"].as_array_mut().unwrap();
            for i in 2..=6 {
                let child = if i == 2 { 1 } else { i - 1 };
                nodes.push(json!({"name": format!("scaler{i}"), "children": [child]}));
            }
            d["scenes"][0]["nodes"] = json!([0, 6]);
            let channels: Vec<Value> = (2..=6)
                .map(|n| json!({"sampler": 0, "target": {"node": n, "path": "scale"}}))
                .collect();
            d["animations"] = json!([{
                "channels": channels,
                "samplers": [{"input": 2, "output": 3}]
            }]);
            std::fs::write(dir.path().join("camfar.bin"), bin).unwrap();
        },
        None,
    );
    assert_error(&path, "camera node 'cam' is carried to a");
    assert_error(&path, "at t = 0.0417 s (frame 1)");
}

/// Appends to `d` (a [`tri_json`] document over [`TRI`]) two scale keys,
/// at t = 0 and 1 s, of `scales` (two VEC3s): accessor 2 their times,
/// accessor 3 their values. Returns the buffer that holds them.
fn scale_keys(d: &mut Value, scales: [f32; 6]) -> Vec<u8> {
    keys_at(d, [0.0, 1.0], scales)
}

/// [`scale_keys`] at the key times `times`.
fn keys_at(d: &mut Value, times: [f32; 2], scales: [f32; 6]) -> Vec<u8> {
    let mut bin = tri_bin(TRI, [0, 1, 2]);
    for v in times.iter().chain(&scales) {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    d["buffers"][0]["byteLength"] = json!(bin.len());
    d["bufferViews"].as_array_mut().unwrap().extend([
        json!({"buffer": 0, "byteOffset": 48, "byteLength": 8}),
        json!({"buffer": 0, "byteOffset": 56, "byteLength": 24}),
    ]);
    d["accessors"].as_array_mut().unwrap().extend([
        json!({"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR",
               "min": [0.0], "max": [1.0]}),
        json!({"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC3"}),
    ]);
    bin
}

/// Asserts that `stderr` holds `said` once, on a warning that names `path`.
fn assert_warned(stderr: &str, path: &Path, said: &str) {
    let lines: Vec<&str> = stderr.lines().filter(|l| l.contains(said)).collect();
    assert_eq!(lines.len(), 1, "expected {said:?} once in: {stderr}");
    let file = path.display().to_string();
    assert!(
        lines[0].starts_with(&format!("warning: {file}: ")),
        "{stderr}"
    );
}

/// What radcache reads of a camera is its yfov (out of (0, π) it is
/// refused); the rest of a camera that glTF forbids (znear not positive,
/// zfar not beyond it, aspectRatio not positive; an orthographic
/// camera's zero xmag or ymag) changes nothing in the render and was
/// passed over without a word: it is warned of, once for each camera.
#[test]
fn camera_values_gltf_forbids_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "cameras",
        |d| {
            d["cameras"] = json!([
                {"type": "perspective",
                 "perspective": {"yfov": 0.8, "znear": 0.0, "zfar": 0.0, "aspectRatio": 0.0}},
                {"type": "orthographic",
                 "orthographic": {"xmag": 0.0, "ymag": 1.0, "znear": 1.0, "zfar": 1.0}}
            ]);
            let nodes = d["nodes"].as_array_mut().unwrap();
            nodes.push(json!({"name": "ortho", "camera": 1}));
            nodes.push(json!({"name": "ortho2", "camera": 1}));
            d["scenes"][0]["nodes"] = json!([0, 1, 2, 3]);
        },
        good_bin(),
    );
    let scene = Scene::load(&path).unwrap();
    assert_eq!(scene.camera.aspect_ratio, None);
    let stderr = render_warnings(&path);
    for said in [
        "camera 0: znear 0 is not positive, as glTF requires; ignored: rays are not clipped \
         at znear or zfar",
        "camera 0: zfar 0 is not beyond znear 0, as glTF requires; ignored: rays are not \
         clipped at znear or zfar",
        "camera 0: aspectRatio 0 is not positive, as glTF requires; ignored: frames take the \
         image's own width-to-height ratio",
        "camera 1: xmag 0 is zero or not finite, which glTF forbids; ignored: radcache renders \
         through perspective cameras only",
        "camera 1: zfar 1 is not beyond znear 1, as glTF requires; ignored: radcache renders \
         through perspective cameras only",
    ] {
        assert_warned(&stderr, &path, said);
    }
    for (yfov, name) in [(0.0, "narrow"), (3.2, "wide")] {
        let path = write_case(
            dir.path(),
            name,
            |d| d["cameras"][0]["perspective"]["yfov"] = json!(yfov),
            good_bin(),
        );
        assert_error(
            &path,
            &format!("camera of node 'cam' has yfov {yfov} out of range"),
        );
    }
}

/// `KHR_lights_punctual` asks of a spot light an outer cone of π/2 at
/// most (past it, as likely as not an angle in degrees) and an inner one
/// of 0 or more, and of every light an intensity of 0 or more: past π/2
/// and below 0 intensity are refused, a negative inner cone read as 0.
/// A light's `range` is not read: the light is not cut off there, and a
/// warning says so. All of these loaded without a word.
#[test]
fn lights_gltf_forbids_or_radcache_ignores_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let with_lights = |name: &str, lights: Value| {
        write_case(
            dir.path(),
            name,
            |d| {
                let count = lights.as_array().unwrap().len();
                d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
                d["extensions"] = json!({"KHR_lights_punctual": {"lights": lights}});
                let nodes = d["nodes"].as_array_mut().unwrap();
                nodes.extend((0..count).map(|light| {
                    json!({"name": format!("lamp{light}"),
                           "extensions": {"KHR_lights_punctual": {"light": light}}})
                }));
                d["scenes"][0]["nodes"] = json!((0..count + 2).collect::<Vec<_>>());
            },
            good_bin(),
        )
    };
    let wide = with_lights(
        "wide",
        json!([{"type": "spot", "spot": {"outerConeAngle": 45.0}}]),
    );
    assert_error(
        &wide,
        "spot light 'lamp0': outerConeAngle 45 is past π/2 (1.5708), the widest glTF allows",
    );
    // π/2 written with four digits is past f32's π/2, and allowed.
    let rounded = with_lights(
        "rounded",
        // As a file holds it (a literal here would be taken for π/2's).
        serde_json::from_str(
            r#"[{"type": "spot", "spot": {"innerConeAngle": 1.5708, "outerConeAngle": 1.5708}}]"#,
        )
        .unwrap(),
    );
    let spot = Scene::load(&rounded).unwrap().lights[0]
        .kind
        .spot()
        .unwrap();
    assert_eq!(
        (spot.inner_cone, spot.outer_cone),
        (std::f32::consts::FRAC_PI_2, std::f32::consts::FRAC_PI_2)
    );
    let negative = with_lights(
        "negative",
        json!([{"type": "point", "color": [0.0, 0.0, 0.0], "intensity": -1.0}]),
    );
    assert_error(
        &negative,
        "light 'lamp0' has a negative intensity, -1; glTF requires 0 or more",
    );
    let ignored = with_lights(
        "ignored",
        json!([
            {"type": "point", "range": 5.0},
            {"type": "spot", "spot": {"innerConeAngle": -0.25, "outerConeAngle": 0.5}}
        ]),
    );
    let scene = Scene::load(&ignored).unwrap();
    assert_eq!(scene.lights[1].kind.spot().unwrap().inner_cone, 0.0);
    let stderr = render_warnings(&ignored);
    assert_warned(
        &stderr,
        &ignored,
        "light 'lamp0' has a range of 5 m, which radcache does not read: the light is not cut \
         off there",
    );
    assert_warned(
        &stderr,
        &ignored,
        "spot light 'lamp1': innerConeAngle -0.25 is negative, which glTF forbids; read as 0",
    );
}

/// glTF requires an animation sampler's key times to be 0 or more and
/// strictly increasing, and a sparse accessor to substitute at least one
/// element: repeated or negative times (which earlier builds read
/// without a word) and a sparse count of 0 are refused, naming the
/// animation and the channel.
#[test]
fn key_times_gltf_forbids_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let case = |name: &str, times: [f32; 2], sparse: Option<Value>| {
        write_case(
            dir.path(),
            name,
            |d| {
                let bin = keys_at(d, times, [1.0; 6]);
                if let Some(sparse) = sparse {
                    d["accessors"][2]["sparse"] = sparse;
                }
                d["animations"] = json!([{"name": "grow",
                    "channels": [{"sampler": 0, "target": {"node": 0, "path": "scale"}}],
                    "samplers": [{"input": 2, "output": 3}]}]);
                std::fs::write(dir.path().join(format!("{name}.bin")), bin).unwrap();
            },
            None,
        )
    };
    let at = "animation 'grow', channel 0 (node 'tri'): ";
    assert_error(
        &case("repeated", [0.5, 0.5], None),
        &format!(
            "{at}key 1 is at t = 0.5 s, as key 0 is: glTF requires strictly increasing key times"
        ),
    );
    assert_error(
        &case("negative", [-1.0, 1.0], None),
        &format!("{at}key 0 is at t = -1 s, before 0: glTF requires key times of 0 or more"),
    );
    let empty = json!({"count": 0, "indices": {"bufferView": 2, "componentType": 5125},
                       "values": {"bufferView": 2}});
    assert_error(
        &case("sparse", [0.0, 1.0], Some(empty)),
        &format!("{at}accessor 2 (key times): its sparse count is 0; glTF requires 1 or more"),
    );
    Scene::load(&case("fine", [0.0, 1.0], None)).unwrap();
}

/// glTF requires a skin's inverseBindMatrices to hold a matrix for each
/// joint: fewer is refused, from the accessor's count (only the first
/// matrix is read).
#[test]
fn a_skin_with_fewer_inverse_bind_matrices_than_joints_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = good_bin().unwrap();
    for x in Mat4::IDENTITY.to_cols_array() {
        bin.extend_from_slice(&x.to_le_bytes());
    }
    let skinned = |name: &str, joints: Value| {
        write_case(
            dir.path(),
            name,
            |d| {
                d["buffers"][0]["byteLength"] = json!(112);
                (d["bufferViews"].as_array_mut().unwrap())
                    .push(json!({"buffer": 0, "byteOffset": 48, "byteLength": 64}));
                (d["accessors"].as_array_mut().unwrap()).push(
                    json!({"bufferView": 2, "componentType": 5126, "count": 1, "type": "MAT4"}),
                );
                d["skins"] = json!([{"joints": joints, "inverseBindMatrices": 2}]);
                d["nodes"][0]["skin"] = json!(0);
            },
            Some(bin.clone()),
        )
    };
    assert_error(
        &skinned("short", json!([1, 0])),
        "skin of node 'tri': its inverseBindMatrices accessor 2 has a count of 1, for 2 \
         joints; glTF requires a matrix for each joint",
    );
    Scene::load(&skinned("one", json!([1]))).unwrap();
}

/// A morph-target weights channel on a node whose mesh has no morph
/// targets (glTF requires them) animates nothing: it is warned of,
/// naming the animation and the channel.
#[test]
fn weights_animated_without_morph_targets_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "weights",
        |d| {
            let bin = scale_keys(d, [1.0; 6]);
            d["accessors"][3] =
                json!({"bufferView": 3, "componentType": 5126, "count": 2, "type": "SCALAR"});
            d["animations"] = json!([{"name": "morph",
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
                "samplers": [{"input": 2, "output": 3}]}]);
            std::fs::write(dir.path().join("weights.bin"), bin).unwrap();
        },
        None,
    );
    let stderr = render_warnings(&path);
    assert_warned(
        &stderr,
        &path,
        "animation 'morph', channel 0 (node 'tri'): it animates morph target weights, but the \
         node's mesh has none; ignored",
    );
}

/// A GLB header's length is the whole file's (glTF §4.4.2): one shorter
/// than the chunks it holds is refused (the parser read the chunks past
/// it without a word), and bytes after the length it gives are ignored,
/// with a warning (after a GLB without a binary chunk, they were read as
/// a broken one).
#[test]
fn a_glb_length_unlike_the_files_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(format!("{name}.glb"));
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let mut doc = tri_json("unused.bin");
    doc["buffers"][0].as_object_mut().unwrap().remove("uri");
    let good = glb_of(&doc, good_bin());
    let mut short = good.clone();
    short[8..12].copy_from_slice(&(good.len() as u32 - 4).to_le_bytes());
    short.extend_from_slice(&[0; 4]);
    assert_error(
        &write("short", &short),
        &format!(
            "corrupt GLB header: it declares a file length of {} bytes, but its chunks end at \
             byte {}",
            good.len() - 4,
            good.len()
        ),
    );
    let mut trailing = good.clone();
    trailing.extend_from_slice(b"trailing");
    let mut json_only = tri_json("unused.bin");
    json_only["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64_like::encode(&good_bin().unwrap())
    ));
    let mut json_only = glb_of(&json_only, None);
    let json_only_len = json_only.len();
    json_only.extend_from_slice(b"trailing");
    for (name, bytes, declared) in [
        ("trailing", trailing, good.len()),
        ("json_only", json_only, json_only_len),
    ] {
        let path = write(name, &bytes);
        Scene::load(&path).unwrap();
        assert_warned(
            &render_warnings(&path),
            &path,
            &format!(
                "8 bytes follow the {declared} bytes the GLB header declares as the file's \
                 length; ignored"
            ),
        );
    }
}

/// glTF forbids a byteStride on the buffer view of indices: refused,
/// naming the accessor (it loaded, as a stride of one index reads alike).
#[test]
fn indices_with_a_byte_stride_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_case(
        dir.path(),
        "strided",
        |d| d["bufferViews"][1]["byteStride"] = json!(4),
        good_bin(),
    );
    assert_error(
        &path,
        "accessor 1 (indices): its buffer view 1 has a byteStride (4), which glTF forbids for \
         indices",
    );
}
