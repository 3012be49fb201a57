//! A scene's unit does not matter: the same scene modelled in metres, in
//! centimetres or in hundredths of a metre renders the same image with
//! every method. Radiance does not change when a scene is scaled (an
//! emitting triangle keeps its radiance, every solid angle is the same),
//! so with the same random streams only the ray offsets against
//! self-intersection and the renderer's other tolerances can tell the
//! scales apart: an absolute epsilon sized for a metre-scale room leaks
//! light, or loses contact shadows, in a room a few centimetres across.

mod common;

use common::{tri_bin, tri_json, TRI};
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
        let mut r = Renderer::new(
            cube_in_box_scaled(k),
            Box::new(PathTracer::new(PathSettings::default())),
            Box::new(CpuBackend::new()),
            FrameSettings {
                width: 32,
                height: 32,
                ..FrameSettings::default()
            },
        );
        let mut last = None;
        for f in 0..FRAMES {
            last = Some(r.with_frame_context(f, |ctx| method.render_frame(ctx)));
        }
        last.unwrap()
    })
}

/// Measured (32×32, frame 5): against the metre-scale renders, ×100 differs
/// by 0.0018 / 0.0025 / 0.0014 (`path` / `ic` / `trc`) and ×0.01 by 0.0134
/// / 0.0209 / 0.0167: paths that diverge at a ray offset now and then (the
/// offset has a floor of 0.1 mm, 0.5 % of the centimetre room), not a bias.
/// With a floor ten times as large (1 mm) `path` at ×0.01 differs by 0.0370.
/// `ic` and `trc` differ more than `path` at any scale that is not a power
/// of two, because one record placed elsewhere changes the noise of its
/// whole neighbourhood: the scene scaled by 1.000001 already differs by
/// 0.0161 (`ic`) and 0.0133 (`trc`) while `path` does not differ at all.
#[test]
fn scaled_scenes_render_the_same_images() {
    let metres = last_frames(1.0);
    for k in [100.0, 0.01] {
        let scaled = last_frames(k);
        for ((name, a), b) in ["path", "ic", "trc"].iter().zip(&scaled).zip(&metres) {
            let difference = rel_rmse(a, b);
            eprintln!("×{k} {name}: relative RMSE {difference:.4} against metres");
            assert!(
                difference < 0.03,
                "×{k}: {name} differs from the metre-scale render by {difference}"
            );
        }
    }
}

/// Below `SMALLEST_SCENE` across the ray offset's floor matters, and a
/// scene file that small is loaded with a warning that says why (a scene
/// in millimetres written as metres, say); one at the limit's scale up is
/// not.
#[test]
fn a_scene_too_small_for_the_ray_offsets_is_loaded_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let render = |k: f32| {
        let tri = TRI.map(|p| p.map(|c| c * k));
        let name = format!("tri{k}");
        std::fs::write(
            dir.path().join(format!("{name}.bin")),
            tri_bin(tri, [0, 1, 2]),
        )
        .unwrap();
        let gltf = dir.path().join(format!("{name}.gltf"));
        let json = tri_json(&format!("{name}.bin"));
        std::fs::write(&gltf, serde_json::to_vec(&json).unwrap()).unwrap();
        let scene = radcache::scene::Scene::load(&gltf).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
            .args([
                "render", "--method", "path", "--spp", "1", "--size", "4x4", "--frames", "0..1",
                "-q",
            ])
            .arg(&gltf)
            .arg("--out")
            .arg(dir.path().join(&name))
            .output()
            .unwrap();
        assert!(out.status.success());
        (
            scene.diagonal_at(0.0),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (size, stderr) = render(1e-3);
    assert!((size - 2f32.sqrt() * 1e-3).abs() < 1e-8, "{size}");
    assert!(
        stderr.contains("units across") && stderr.contains("scale the scene up"),
        "{stderr}"
    );
    let (size, stderr) = render(0.1);
    assert!(size > radcache::scene::SMALLEST_SCENE);
    assert!(!stderr.contains("units across"), "{stderr}");
}
