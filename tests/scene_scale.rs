//! A scene's unit does not matter: the same scene modelled in metres, in
//! centimetres or in tenths of a millimetre renders the same image with
//! every method. Radiance does not change when a scene is scaled (an
//! emitting triangle keeps its radiance, every solid angle is the same),
//! so with the same random streams only the ray offsets against
//! self-intersection and the renderer's other tolerances can tell the
//! scales apart: an absolute epsilon sized for a metre-scale room leaks
//! light, or loses contact shadows, in a room a few centimetres across.

mod common;

use common::{tri_bin, tri_json, TRI};
use glam::Vec3;
use radcache::backend::cpu::CpuBackend;
use radcache::cache::gather::Strata;
use radcache::film::Film;
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::trc::{TemporalRadianceCaching, TrcSettings};
use radcache::method::Method;
use radcache::metrics::rel_rmse;
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::{Property, Scene};

/// `cube-in-box` (a 2 × 2 × 2.9 m room, its cube moving) with every length
/// multiplied by `k`: mesh positions, node translations and translation
/// keys.
fn cube_in_box_scaled(k: f32) -> Scene {
    let mut s = Scene::builtin("cube-in-box").unwrap();
    for object in &mut s.objects {
        for p in &mut object.mesh.positions {
            *p *= k;
        }
    }
    for node in &mut s.nodes {
        node.rest.translation *= k;
    }
    for channel in &mut s.animation.channels {
        if channel.property == Property::Translation {
            for v in &mut channel.values {
                *v *= k;
            }
        }
    }
    s
}

/// A 32×32 renderer of `scene` on the CPU (its method is the caller's).
fn renderer_32x32(scene: Scene) -> Renderer {
    Renderer::new(
        scene,
        Box::new(PathTracer::new(PathSettings::default())),
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: 32,
            height: 32,
            ..FrameSettings::default()
        },
    )
}

/// Frame `frame` of `scene` by `path` at 64 spp, at 32×32.
fn path_64_spp(scene: Scene, frame: u32) -> Film {
    let mut method = PathTracer::new(PathSettings {
        spp: 64,
        ..PathSettings::default()
    });
    renderer_32x32(scene).with_frame_context(frame, |ctx| method.render_frame(ctx))
}

/// Frame `FRAMES - 1` of `path`, `ic` and `trc` (each run over frames
/// `0..FRAMES`, so `trc` reuses records) on the scene scaled by `k`.
fn last_frames(k: f32) -> [Film; 3] {
    const FRAMES: u32 = 6;
    let ic = IcSettings {
        spp: 4,
        strata: Strata { theta: 8, phi: 24 },
        ..IcSettings::default()
    };
    let methods: [Box<dyn Method>; 3] = [
        Box::new(PathTracer::new(PathSettings {
            spp: 16,
            ..PathSettings::default()
        })),
        Box::new(IrradianceCaching::new(ic.clone())),
        Box::new(TemporalRadianceCaching::new(TrcSettings {
            ic,
            ..TrcSettings::default()
        })),
    ];
    methods.map(|mut method| {
        let mut r = renderer_32x32(cube_in_box_scaled(k));
        let mut last = None;
        for f in 0..FRAMES {
            last = Some(r.with_frame_context(f, |ctx| method.render_frame(ctx)));
        }
        last.unwrap()
    })
}

/// Measured (32×32, frame 5): against the metre-scale renders, ×100 differs
/// by 0.0018 / 0.0042 / 0.0030 (`path` / `ic` / `trc`), ×0.01 by 0.0034 /
/// 0.0045 / 0.0035 and ×0.0001 (a room 0.36 mm across) by 0.0034 / 0.0054
/// / 0.0041: rounding that differs between scales, as the ray offset is
/// the same share of the room at each (`RayOffset`). While the offset had
/// a floor of 1e-4 units whatever the scene's size, ×0.01 differed by
/// 0.0134 / 0.0209 / 0.0167 (`path` 0.0122 with that floor put back now),
/// the floor 0.5 % of the centimetre room; at ×0.0001 it was 28 % of the
/// room (`SMALLEST_SCENE` has what that lost).
#[test]
fn scaled_scenes_render_the_same_images() {
    let metres = last_frames(1.0);
    for k in [100.0, 0.01, 0.0001] {
        let scaled = last_frames(k);
        for ((name, a), b) in ["path", "ic", "trc"].iter().zip(&scaled).zip(&metres) {
            let difference = rel_rmse(a, b);
            eprintln!("×{k} {name}: relative RMSE {difference:.4} against metres");
            assert!(
                difference < 0.01,
                "×{k}: {name} differs from the metre-scale render by {difference}"
            );
        }
    }
}

/// `SMALLEST_SCENE` ([`radcache::scene::SMALLEST_SCENE`]): a scene that
/// size across renders as in metres (`path`, 64 spp, 32×32, frame 0 of
/// `cube-in-box` scaled to that diagonal: the frame's mean within 0.5 %,
/// each 8×8 block within 1 %), and one a hundredth of it does not (the
/// traversal's absolute near shift loses light). Measured (mean, worst
/// block against metres): 1e-5 across +0.01 %, 0.11 %; 1e-7, −9 %, 39 %.
#[test]
fn the_smallest_scene_renders_as_in_metres_and_a_smaller_one_does_not() {
    let frame = |k: f32| path_64_spp(cube_in_box_scaled(k), 0);
    let metres = frame(1.0);
    let diagonal = cube_in_box_scaled(1.0).diagonal_at(0.0);
    // (mean ratio − 1, worst relative difference of an 8×8 block's sum).
    let against_metres = |film: &Film| {
        let block = |f: &Film, bx: usize, by: usize| {
            let rows = (by * 8..by * 8 + 8).flat_map(|y| (bx * 8..bx * 8 + 8).map(move |x| (x, y)));
            rows.map(|(x, y)| f.pixels[y * 32 + x].element_sum())
                .sum::<f32>()
        };
        let blocks = (0..16).map(|b| (b % 4, b / 4));
        let worst = blocks
            .map(|(bx, by)| (block(film, bx, by) / block(&metres, bx, by) - 1.0).abs())
            .fold(0.0f32, f32::max);
        let sum = |f: &Film| f.pixels.iter().map(|p| p.element_sum()).sum::<f32>();
        (sum(film) / sum(&metres) - 1.0, worst)
    };
    let smallest = against_metres(&frame(radcache::scene::SMALLEST_SCENE / diagonal));
    let smaller = against_metres(&frame(radcache::scene::SMALLEST_SCENE / 100.0 / diagonal));
    eprintln!("against metres (mean, worst block): smallest {smallest:?}, a hundredth {smaller:?}");
    assert!(
        smallest.0.abs() < 0.005 && smallest.1 < 0.01,
        "{smallest:?}"
    );
    assert!(smaller.0 < -0.05, "{smaller:?}");
}

/// Below `SMALLEST_SCENE` across the traversal's rounding matters, and a
/// scene file that small is loaded with a warning that says why (a scene
/// in micrometres written as metres, say); one ten times the limit is
/// not.
#[test]
fn a_scene_too_small_for_the_ray_traversal_is_loaded_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let render = |k: f32| {
        let tri = TRI.map(|p| p.map(|c| c * k));
        let (scene, stderr) = tri_file_rendered(dir.path(), &format!("tri{k}"), tri, Vec3::ZERO);
        (scene.diagonal_at(0.0), stderr)
    };
    let (size, stderr) = render(1e-6);
    assert!((size - 2f32.sqrt() * 1e-6).abs() < 1e-11, "{size}");
    assert!(
        stderr.contains("units across") && stderr.contains("scale the scene up"),
        "{stderr}"
    );
    let (size, stderr) = render(1e-4);
    assert!(size > radcache::scene::SMALLEST_SCENE);
    assert!(!stderr.contains("units across"), "{stderr}");
}

/// `tri` (with `TRI`'s camera moved by `camera`) written as `NAME.gltf`
/// in `dir`, loaded, and rendered by `radcache render`: the scene and
/// what the command wrote to its standard error.
fn tri_file_rendered(
    dir: &std::path::Path,
    name: &str,
    tri: [[f32; 3]; 3],
    camera: Vec3,
) -> (Scene, String) {
    std::fs::write(dir.join(format!("{name}.bin")), tri_bin(tri, [0, 1, 2])).unwrap();
    let gltf = dir.join(format!("{name}.gltf"));
    let mut json = tri_json(&format!("{name}.bin"));
    let corners = |pick: fn(f32, f32) -> f32| {
        (0..3)
            .map(|a| tri.iter().map(|p| p[a]).reduce(pick).unwrap())
            .collect::<Vec<f32>>()
    };
    json["accessors"][0]["min"] = serde_json::json!(corners(f32::min));
    json["accessors"][0]["max"] = serde_json::json!(corners(f32::max));
    json["nodes"][1]["translation"] = serde_json::json!((camera + Vec3::Z * 3.0).to_array());
    std::fs::write(&gltf, serde_json::to_vec(&json).unwrap()).unwrap();
    let scene = Scene::load(&gltf).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .args([
            "render", "--method", "path", "--spp", "1", "--size", "4x4", "--frames", "0..1", "-q",
        ])
        .arg(&gltf)
        .arg("--out")
        .arg(dir.join(name))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    (scene, stderr)
}

/// A scene file far from the origin is loaded moved to it, with a note
/// that says by how much; one around the origin is loaded as it is.
#[test]
fn a_scene_file_far_from_the_origin_is_loaded_moved_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let far = Vec3::new(5000.0, -20.0, 300.0);
    let tri = TRI.map(|p| (Vec3::from_array(p) + far).to_array());
    let (scene, stderr) = tri_file_rendered(dir.path(), "far", tri, far);
    let centre = far + Vec3::new(0.5, 0.5, 0.0);
    assert_eq!(scene.moved_by, -centre);
    let (lo, hi) = scene.bounds_at(0.0).unwrap();
    assert_eq!(
        (lo, hi),
        (Vec3::new(-0.5, -0.5, 0.0), Vec3::new(0.5, 0.5, 0.0))
    );
    assert!(
        stderr.contains("rendered moved by (-5000.5, 19.5, -300)"),
        "{stderr}"
    );
    let (scene, stderr) = tri_file_rendered(dir.path(), "home", TRI, Vec3::ZERO);
    assert_eq!(scene.moved_by, Vec3::ZERO);
    assert!(!stderr.contains("moved"), "{stderr}");
}

/// `scene` with `by` added to its root nodes' places and translation keys
/// (every node of `cube-in-box` is a root): the same scene elsewhere.
fn moved(mut scene: Scene, by: Vec3) -> Scene {
    let roots: Vec<bool> = scene.nodes.iter().map(|n| n.parent.is_none()).collect();
    assert!(roots.iter().all(|&r| r), "cube-in-box has no hierarchy");
    for node in &mut scene.nodes {
        node.rest.translation += by;
    }
    for channel in &mut scene.animation.channels {
        if channel.property == Property::Translation {
            assert_eq!(
                channel.interpolation,
                radcache::scene::Interpolation::Linear
            );
            for v in &mut channel.values {
                *v += by.extend(0.0);
            }
        }
    }
    scene
}

/// A scene 13 km from the origin renders as at the origin once
/// [`Scene::move_to_origin`] has moved it back, and not before: there rays
/// leave surfaces by 1e-4 of 13 km (`path`, 64 spp, 32×32, frame 2 against
/// the scene at the origin: relative RMSE measured 0.32 where it lies,
/// 0.0015 moved back, the rounding of coordinates 1 mm apart there). A
/// scene around the origin is not moved.
#[test]
fn a_scene_far_from_the_origin_is_moved_to_it_and_renders_as_there() {
    let frame = |scene: Scene| path_64_spp(scene, 2);
    let home = cube_in_box_scaled(1.0);
    let (lo, hi) = home.bounds_at(0.0).unwrap();
    assert!(home.clone().move_to_origin().is_none(), "{lo} {hi}");
    let at_home = frame(home.clone());

    let far = Vec3::new(1e4, 5e3, -7e3);
    let mut away = moved(home, far);
    let where_it_lies = rel_rmse(&frame(away.clone()), &at_home);
    let by = away.move_to_origin().expect("a scene 13 km away is moved");
    assert!((by + far + 0.5 * (lo + hi)).length() < 1e-2, "{by}");
    assert_eq!(away.moved_by, by);
    let (moved_lo, moved_hi) = away.bounds_at(0.0).unwrap();
    assert!(
        (moved_lo + moved_hi).length() < 1e-2,
        "{moved_lo} {moved_hi}"
    );
    let moved_back = rel_rmse(&frame(away), &at_home);
    eprintln!(
        "13 km away: relative RMSE {where_it_lies:.4} where it lies, {moved_back:.4} moved back"
    );
    assert!(where_it_lies > 0.1, "{where_it_lies}");
    assert!(moved_back < 0.01, "{moved_back}");
}

/// A room 1.3 km from the origin, at the edge of a 2 km ground out of its
/// sight (a scene too large to be moved closer), renders as at the origin
/// (`path`, 64 spp, 32×32, frame 2): rays leave its surfaces by 1e-4 of
/// their coordinates' first 16 units and 1e-5 of the rest
/// (`FAR_RAY_OFFSET`), about a centimetre there. Measured relative RMSE
/// against the room at the origin: 0.0214 while the whole coordinate took
/// 1e-4 (a tenth of a unit), 0.0070 now.
#[test]
fn a_room_at_the_edge_of_a_large_scene_renders_as_at_the_origin() {
    let home = cube_in_box_scaled(1.0);
    let at_home = path_64_spp(home.clone(), 2);
    let mut edge = moved(home, Vec3::new(950.0, 0.0, 950.0));
    let mut ground = radcache::scene::Mesh::default();
    let (corner, side) = (Vec3::new(-1000.0, -0.5, 1000.0), 2000.0);
    let quad = [
        corner,
        corner + Vec3::X * side,
        corner + Vec3::new(side, 0.0, -side),
    ];
    for p in quad.into_iter().chain([
        corner + Vec3::new(side, 0.0, -side),
        corner - Vec3::Z * side,
    ]) {
        ground.positions.push(p);
        ground.normals.push(Vec3::Y);
    }
    ground.triangles = vec![[0, 2, 1], [0, 4, 3]];
    ground.materials = vec![0, 0];
    edge.nodes.push(radcache::scene::Node {
        name: "ground".into(),
        parent: None,
        rest: radcache::scene::Trs::default(),
    });
    edge.objects.push(radcache::scene::Object {
        name: "ground".into(),
        node: edge.nodes.len() - 1,
        mesh: ground,
    });
    assert!(
        edge.clone().move_to_origin().is_none(),
        "the ground is centred"
    );
    let difference = rel_rmse(&path_64_spp(edge, 2), &at_home);
    eprintln!(
        "a room 1.3 km out on a 2 km ground: relative RMSE {difference:.4} against the origin"
    );
    assert!(difference < 0.012, "{difference}");
}
