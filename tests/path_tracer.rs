//! The reference path tracer against closed forms: the furnace test, a
//! point light over a diffuse plane and two rectangular lights over one;
//! and its determinism.

mod common;

use common::{furnace_box, ground, inward_box, plane_under_point_light, push_quad, scene};
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
        let s = furnace_box(albedo, le);
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
    let eye = Vec3::new(0.0, 3.0, 0.0);
    let s = plane_under_point_light(albedo, intensity, light, eye);
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
        let expected = pixel_mean(size, (x, y), 32, |sx, sy| f64::from(radiance_at(sx, sy)));
        let got = f64::from(film.get(x, y).x);
        assert!(
            (got - expected).abs() / expected < 0.01,
            "pixel ({x},{y}): {got} vs closed form {expected}"
        );
    }
}

/// The mean of `radiance_at(sx, sy)` over a `sub` × `sub` grid of film
/// points in pixel `(x, y)` of a `size`² image: a closed form box-filtered
/// over the pixel's square, as the renderer's pixels are.
fn pixel_mean(
    size: u32,
    (x, y): (u32, u32),
    sub: u32,
    radiance_at: impl Fn(f32, f32) -> f64,
) -> f64 {
    let at = |pixel: u32, k: u32| (pixel as f32 + (k as f32 + 0.5) / sub as f32) / size as f32;
    let sum: f64 = (0..sub)
        .flat_map(|i| (0..sub).map(move |j| (i, j)))
        .map(|(i, j)| radiance_at(at(x, i), at(y, j)))
        .sum();
    sum / f64::from(sub * sub)
}

/// The form factor from a point on a plane to the rectangle `[x0, x1] ×
/// [z0, z1]` of a parallel plane at height `h` above it (coordinates
/// relative to the point): the corner formula (a point under one corner
/// of an `X·h × Y·h` rectangle) combined by inclusion and exclusion.
fn rectangle_form_factor(x0: f64, x1: f64, z0: f64, z1: f64, h: f64) -> f64 {
    let corner = |x: f64, z: f64| {
        let (a, b) = (x.abs() / h, z.abs() / h);
        let (ra, rb) = ((1.0 + a * a).sqrt(), (1.0 + b * b).sqrt());
        let f =
            (a / ra * (b / ra).atan() + b / rb * (a / rb).atan()) / (2.0 * std::f64::consts::PI);
        x.signum() * z.signum() * f
    };
    corner(x1, z1) - corner(x0, z1) - corner(x1, z0) + corner(x0, z0)
}

/// Two rectangular area lights of different power (each two emissive
/// triangles) facing a diffuse plane: the radiance leaving the plane is
/// `ρ · Σ Lᵢ · Fᵢ`, `Fᵢ` the form factor from the point to light `i` in
/// closed form. Checks next-event estimation through the light choice
/// (which light, then where on it, from one stratified sample) against an
/// independent answer, off the lights' axes so both lights matter. The
/// dimmer light gets about a seventh of the samples (its share of the
/// power), so it takes many samples for the noise to fall well below 1 %
/// (at 65,536 a pixel it was within 0.3 %).
#[test]
fn two_rectangular_lights_over_plane_match_the_form_factor() {
    let (albedo, h) = (0.6, 1.0);
    // (x0, x1, z0, z1, radiance) of each light at height h, facing down.
    let lights = [(-0.5, 0.5, -0.3, 0.3, 2.0), (0.7, 1.5, -1.0, 0.2, 7.0)];
    let plane = ground(10.0, 0);
    let mut emitters = Mesh::default();
    for (i, &(x0, x1, z0, z1, _)) in lights.iter().enumerate() {
        // X × Z = −Y: the emitting side faces the plane.
        push_quad(
            &mut emitters,
            Vec3::new(x0, h, z0),
            Vec3::X * (x1 - x0),
            Vec3::Z * (z1 - z0),
            1 + i as u32,
        );
    }
    let eye = Vec3::new(0.2, 0.5, 0.1);
    let yfov = 0.4;
    let s = scene(
        vec![plane, emitters],
        vec![
            Material::diffuse("plane", Vec3::splat(albedo)),
            Material::emitter("light a", Vec3::splat(lights[0].4)),
            Material::emitter("light b", Vec3::splat(lights[1].4)),
        ],
        vec![],
        eye,
        -Vec3::Y,
        yfov,
        vec![],
    );
    let size = 8;
    let mut r = renderer(s, 65536, size);
    let film = r.render_frame(0);
    let camera = r.scene.snapshot(0.0).camera;
    let radiance_at = |sx: f32, sy: f32| {
        let d = camera.direction(sx, sy, 1.0);
        let p = eye + d * (-eye.y / d.y);
        let (px, pz) = (f64::from(p.x), f64::from(p.z));
        lights
            .iter()
            .map(|&(x0, x1, z0, z1, l)| {
                let [x0, x1, z0, z1, l, h] = [x0, x1, z0, z1, l, h].map(f64::from);
                let f = rectangle_form_factor(x0 - px, x1 - px, z0 - pz, z1 - pz, h);
                f64::from(albedo) * l * f
            })
            .sum::<f64>()
    };
    for (x, y) in [(0u32, 0u32), (3, 4), (7, 2), (5, 7)] {
        let expected = pixel_mean(size, (x, y), 16, radiance_at);
        let got = f64::from(film.get(x, y).x);
        assert!(
            (got - expected).abs() / expected < 0.01,
            "pixel ({x},{y}): {got} vs closed form {expected}"
        );
    }
}

/// `cube_in_box.glb` with its room scaled a million times (its 0.5 m lamp
/// and the cube left as they are): from the far floor both the lamp and
/// the floor are edge-on, the lamp's solid-angle pdf (about 6e19) squares
/// past f32's range in the MIS weight, and a fifth of the pixels were NaN.
/// Every pixel is finite, and the cube is lit.
#[test]
fn a_small_lamp_in_a_vast_room_gives_no_nan() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scenes/cube_in_box.glb");
    let mut s = radcache::scene::Scene::load(&path).unwrap();
    let room = s
        .nodes
        .iter()
        .position(|n| n.name == "room")
        .expect("a room node");
    s.nodes[room].rest.scale = Vec3::splat(1e6);
    let film = renderer(s, 4, 32).render_frame(0);
    let bad = film.pixels.iter().filter(|p| !p.is_finite()).count();
    assert_eq!(bad, 0, "{bad} of {} pixels not finite", film.pixels.len());
    assert!(film.mean() > 0.0);
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
