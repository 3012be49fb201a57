//! The reference path tracer against closed forms: the furnace test and a
//! point light over a diffuse plane; and its determinism.

mod common;

use common::{inward_box, push_quad, scene};
use glam::Vec3;
use radcache::method::path::{PathSettings, PathTracer};
use radcache::render::Renderer;
use radcache::scene::{Material, Mesh};

fn renderer(scene: radcache::scene::Scene, spp: u32, size: u32) -> Renderer {
    let method = PathTracer::new(PathSettings {
        spp,
        ..PathSettings::default()
    });
    common::cpu_renderer(scene, Box::new(method), size)
}

/// Inside a closed box whose every surface has albedo ρ and emits Le, the
/// radiance everywhere is Le/(1−ρ) (the sum of the geometric series of
/// bounces). Exercises emission, MIS between light and BSDF sampling and
/// unbounded Russian roulette together.
#[test]
fn furnace_radiance_is_le_over_one_minus_albedo() {
    for (albedo, le) in [(0.5f32, 1.0f32), (0.8, 0.5)] {
        let material = Material {
            emission: Vec3::splat(le),
            ..Material::diffuse("furnace", Vec3::splat(albedo))
        };
        let room = inward_box(Vec3::splat(-1.0), Vec3::splat(1.0), 0);
        let s = scene(
            vec![room],
            vec![material],
            vec![],
            Vec3::ZERO,
            -Vec3::Z,
            1.2,
            vec![],
        );
        let film = renderer(s, 256, 32).render_frame(0);
        let expected = le / (1.0 - albedo);
        let mean = film.mean() as f32;
        assert!(
            (mean - expected).abs() / expected < 0.01,
            "ρ={albedo} Le={le}: mean radiance {mean}, expected {expected}"
        );
        // 262k paths put the standard error of the mean near 0.2 % at
        // ρ = 0.8 (paths have geometric length), so 1 % is a 5σ bound. Per
        // pixel, 256 paths leave ~6 % noise; a structural error (dark
        // edges, leaks) shows up far beyond the 50 % bound.
        for p in &film.pixels {
            assert!(
                (p.x - expected).abs() / expected < 0.5,
                "pixel {p} far from {expected}"
            );
        }
    }
}

/// A point light of intensity I at height h over a Lambertian plane of
/// albedo ρ: the plane's radiance is ρ/π · I·cosθ/d². Each pixel is the mean
/// over its footprint, so the expectation is integrated over the pixel by
/// quadrature and compared within 1 %.
#[test]
fn point_light_over_plane_matches_inverse_square_law() {
    let albedo = 0.7;
    let intensity = 5.0;
    let light = Vec3::new(0.3, 1.0, -0.2);
    let mut plane = Mesh::default();
    push_quad(
        &mut plane,
        Vec3::new(-10.0, 0.0, -10.0),
        Vec3::Z * 20.0,
        Vec3::X * 20.0,
        0,
    );
    let eye = Vec3::new(0.0, 3.0, 0.0);
    let yfov = 1.0;
    let s = scene(
        vec![plane],
        vec![Material::diffuse("plane", Vec3::splat(albedo))],
        vec![],
        eye,
        -Vec3::Y,
        yfov,
        vec![(light, Vec3::splat(intensity))],
    );
    let size = 16;
    let mut r = renderer(s, 4096, size);
    let film = r.render_frame(0);
    let camera = r.scene.snapshot(0.0).camera;
    let radiance_at = |sx: f32, sy: f32| {
        let d = camera.direction(sx, sy, 1.0);
        let p = eye + d * (-eye.y / d.y);
        let to_light = light - p;
        let d2 = to_light.length_squared();
        let cos = to_light.y / d2.sqrt();
        albedo / std::f32::consts::PI * intensity * cos / d2
    };
    for (x, y) in [(2u32, 3u32), (8, 8), (12, 5), (5, 13), (15, 0)] {
        let sub = 32;
        let mut expected = 0.0;
        for i in 0..sub {
            for j in 0..sub {
                let sx = (x as f32 + (i as f32 + 0.5) / sub as f32) / size as f32;
                let sy = (y as f32 + (j as f32 + 0.5) / sub as f32) / size as f32;
                expected += radiance_at(sx, sy);
            }
        }
        expected /= (sub * sub) as f32;
        let got = film.get(x, y);
        assert!(
            (got.x - expected).abs() / expected < 0.01,
            "pixel ({x},{y}): {} vs closed form {expected}",
            got.x
        );
    }
}

/// The same frame rendered twice (and after another frame) is identical:
/// sampling is keyed by (seed, frame, pixel, sample) only.
#[test]
fn frames_are_deterministic_and_keyed_by_frame_and_seed() {
    let make = |seed| {
        let material = Material::diffuse("w", Vec3::splat(0.5));
        let light = Material::emitter("l", Vec3::splat(10.0));
        let mut room = inward_box(Vec3::splat(-1.0), Vec3::splat(1.0), 0);
        push_quad(
            &mut room,
            Vec3::new(-0.2, 0.99, -0.2),
            Vec3::X * 0.4,
            Vec3::Z * 0.4,
            1,
        );
        let s = scene(
            vec![room],
            vec![material, light],
            vec![],
            Vec3::ZERO,
            -Vec3::Z,
            1.0,
            vec![],
        );
        let mut r = renderer(s, 4, 12);
        r.settings.seed = seed;
        r
    };
    let mut a = make(0);
    let first = a.render_frame(1);
    let _ = a.render_frame(0);
    assert_eq!(a.render_frame(1), first, "re-rendering a frame changed it");
    assert_eq!(make(0).render_frame(1), first, "a fresh renderer disagrees");
    assert_ne!(make(1).render_frame(1), first, "the seed is ignored");
    assert_ne!(
        make(0).render_frame(2),
        first,
        "the frame is not part of the key"
    );
    let mut same = make(0);
    same.settings.same_pattern = true;
    assert_eq!(
        same.render_frame(2),
        same.render_frame(1),
        "--same-pattern must repeat the sequence"
    );
}
