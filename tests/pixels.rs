//! The camera pass every method shares (`method::pixels`): pixels on the
//! edge of a directly seen light are post-stratified by their emitter
//! coverage, every other pixel is rendered exactly as without it, and the
//! error of the edge pixels falls against a converged reference.

mod common;

use glam::Vec3;
use radcache::backend::cpu::CpuBackend;
use radcache::backend::{Hit, Ray, RayBackend};
use radcache::cache::gather::Strata;
use radcache::film::Film;
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::pixels::{sees_emitter, sees_emitter_first, DEFAULT_EDGE_COVERAGE_FACTOR};
use radcache::method::Method;
use radcache::render::{FrameSettings, Renderer};
use radcache::sampling::{cosine_hemisphere, Rng};
use radcache::scene::{Material, Mesh, Scene};

const SIZE: u32 = 24;

fn render(method: Box<dyn Method>, edge_coverage_factor: u32) -> Film {
    render_on(method, edge_coverage_factor, Box::new(CpuBackend::new()))
}

/// Frame 3 of cube-in-box at `SIZE`² by `method` on `backend`.
fn render_on(
    method: Box<dyn Method>,
    edge_coverage_factor: u32,
    backend: Box<dyn RayBackend>,
) -> Film {
    let mut r = Renderer::new(
        Scene::builtin("cube-in-box").unwrap(),
        method,
        backend,
        FrameSettings {
            width: SIZE,
            height: SIZE,
            edge_coverage_factor,
            ..FrameSettings::default()
        },
    );
    r.render_frame(3)
}

fn path(spp: u32) -> Box<dyn Method> {
    Box::new(PathTracer::new(PathSettings {
        spp,
        ..PathSettings::default()
    }))
}

fn ic(spp: u32) -> Box<dyn Method> {
    Box::new(IrradianceCaching::new(IcSettings {
        spp,
        strata: Strata { theta: 6, phi: 18 },
        ..IcSettings::default()
    }))
}

/// Cube-in-box sees its ceiling light. At 4 samples a pixel, with and
/// without the post-stratified edge pixels: the pixels that differ are few
/// (the rim, not the image), every other pixel is bit-identical (the same
/// samples), and over the differing pixels the squared error against a
/// 1024-spp `path` reference rendered without the rule (plain means of
/// 1024 samples: an independent estimator of the same pixel integrals) falls
/// tenfold. The coverage comes from 65× the rays, which cuts the variance
/// of a box-filtered straight edge several hundredfold (N^-3/2); what is
/// left is the shading noise of each part's few samples and the
/// reference's own noise, so 0.1 leaves room for both.
#[test]
fn only_pixels_on_a_seen_lights_edge_take_more_samples_and_their_error_falls() {
    let reference = render(path(1024), 0);
    for (name, method) in [("path", path as fn(u32) -> Box<dyn Method>), ("ic", ic)] {
        let off = render(method(4), 0);
        let on = render(method(4), DEFAULT_EDGE_COVERAGE_FACTOR);
        let edge: Vec<usize> = (0..off.pixels.len())
            .filter(|&i| off.pixels[i] != on.pixels[i])
            .collect();
        let n = off.pixels.len();
        assert!(
            !edge.is_empty() && edge.len() < n / 8,
            "{name}: {} of {n} pixels changed",
            edge.len()
        );
        let squared_error = |film: &Film| -> f64 {
            edge.iter()
                .map(|&i| f64::from((film.pixels[i] - reference.pixels[i]).length_squared()))
                .sum()
        };
        let (before, after) = (squared_error(&off), squared_error(&on));
        eprintln!(
            "{name}: {} edge pixels, squared error {before:.4} → {after:.4}",
            edge.len()
        );
        assert!(after < 0.1 * before, "{name}: {before} → {after}");
    }
}

/// The light's rim does not hang on the last bits of the backend's `t`:
/// on `common::UlpHits` (any-hit queries that reach a few ulps further)
/// every pixel of cube-in-box (its ceiling light in
/// view) is what the CPU backend renders, bit for bit. When the coverage
/// rays' any-hit query stopped one ulp short of the emitter, the emitter
/// hid itself from about half of them on such a backend (an H200): the rim
/// lost coverage, and the GPU's frames disagreed with the CPU's wherever
/// the light was seen.
#[test]
fn a_backend_whose_hits_differ_by_ulps_sees_the_same_light_rim() {
    for (name, method) in [("path", path as fn(u32) -> Box<dyn Method>), ("ic", ic)] {
        let cpu = render(method(4), DEFAULT_EDGE_COVERAGE_FACTOR);
        let nearer = render_on(
            method(4),
            DEFAULT_EDGE_COVERAGE_FACTOR,
            Box::new(common::UlpHits::any_hit_only()),
        );
        let differ = (0..cpu.pixels.len())
            .filter(|&i| cpu.pixels[i] != nearer.pixels[i])
            .count();
        assert_eq!(differ, 0, "{name}: {differ} pixels differ");
    }
}

/// The edge `px = EDGE_A + EDGE_B · py` (film pixel coordinates, `py`
/// down) of a light that fills the film left of it.
const EDGE_A: f32 = 5.01;
const EDGE_B: f32 = 0.06;
const EDGE_SIZE: u32 = 16;

/// A light of unit radiance facing a camera with a 90° field of view from
/// 1 m: left of the edge the film sees the light, right of it nothing. The
/// edge crosses column 5 from a 1 % sliver in the top row to 94 % at the
/// bottom, so some pixels' samples all miss the light in them.
fn light_edge_scene() -> Scene {
    // Film pixel coordinates to the light's plane z = −1: with
    // tan(yfov/2) = 1 the film spans [−1, 1]² there, y up.
    let size = EDGE_SIZE as f32;
    let world = |px: f32, py: f32| Vec3::new(2.0 * px / size - 1.0, 1.0 - 2.0 * py / size, -1.0);
    let (top, bottom, far_left) = (-50.0, 66.0, -50.0);
    let corners = [
        world(far_left, top),
        world(far_left, bottom),
        world(EDGE_A + EDGE_B * bottom, bottom),
        world(EDGE_A + EDGE_B * top, top),
    ];
    let light = Mesh {
        positions: corners.to_vec(),
        normals: vec![Vec3::Z; 4],
        // Counter-clockwise seen from the camera: the emitting side faces it.
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        materials: vec![0, 0],
    };
    common::scene(
        vec![light],
        vec![Material::emitter("light", Vec3::ONE)],
        vec![],
        Vec3::ZERO,
        -Vec3::Z,
        std::f32::consts::FRAC_PI_2,
        vec![],
    )
}

/// The share of pixel `(x, y)` left of the edge: `∫ clamp(a + b·py − x, 0,
/// 1) dpy` over the pixel's row span, by the midpoint rule.
fn covered(x: u32, y: u32) -> f32 {
    let steps = 1000;
    (0..steps)
        .map(|k| {
            let py = y as f32 + (k as f32 + 0.5) / steps as f32;
            (EDGE_A + EDGE_B * py - x as f32).clamp(0.0, 1.0)
        })
        .sum::<f32>()
        / steps as f32
}

/// Against the closed form: each pixel is the light's radiance times the
/// share of the pixel it covers. With 4 samples a pixel and no edge rule
/// the rim pixels are off by their coverage noise, and the slivers that
/// all four samples miss are black; with the rule every pixel is within
/// 0.03 of its coverage (about 4σ of 260 stratified coverage rays on an
/// edge) and the RMS error falls more than fourfold.
#[test]
fn a_light_edge_pixel_is_its_radiance_times_its_covered_share() {
    let errors = |factor: u32| -> Vec<f32> {
        let mut r = common::cpu_renderer(light_edge_scene(), path(4), EDGE_SIZE);
        r.settings.edge_coverage_factor = factor;
        let film = r.render_frame(0);
        (0..EDGE_SIZE * EDGE_SIZE)
            .map(|i| {
                let (x, y) = (i % EDGE_SIZE, i / EDGE_SIZE);
                film.pixels[i as usize].x - covered(x, y)
            })
            .collect()
    };
    let rms = |e: &[f32]| (e.iter().map(|d| d * d).sum::<f32>() / e.len() as f32).sqrt();
    let (off, on) = (errors(0), errors(DEFAULT_EDGE_COVERAGE_FACTOR));
    let worst = on.iter().fold(0.0f32, |m, d| m.max(d.abs()));
    eprintln!("RMS error {} → {}, worst {worst}", rms(&off), rms(&on));
    assert!(worst < 0.03, "worst pixel off by {worst}");
    assert!(rms(&on) < rms(&off) / 4.0, "{} → {}", rms(&off), rms(&on));
}

/// A room with a one-sided light quad under its ceiling (split into
/// `light_cells × light_cells` quads), a cube between the camera and part
/// of it, and a second light quad facing away from the camera (its back
/// side is all the camera sees of it).
fn lit_room(light_cells: u32) -> Scene {
    let room = common::inward_box(Vec3::splat(-1.0), Vec3::splat(1.0), 0);
    let mut cube = Mesh::default();
    let (x, y, z) = (Vec3::X * 0.5, Vec3::Y * 0.5, Vec3::Z * 0.5);
    let o = Vec3::new(-0.3, 0.3, -0.5);
    common::push_quad(&mut cube, o, x, y, 0);
    common::push_quad(&mut cube, o + z, y, x, 0);
    common::push_quad(&mut cube, o, y, z, 0);
    common::push_quad(&mut cube, o + x, z, y, 0);
    common::push_quad(&mut cube, o, z, x, 0);
    common::push_quad(&mut cube, o + y, x, z, 0);
    let mut lights = Mesh::default();
    let cell = 1.0 / light_cells as f32;
    for i in 0..light_cells {
        for j in 0..light_cells {
            let corner = Vec3::new(-0.5 + i as f32 * cell, 0.99, -0.5 + j as f32 * cell);
            // u × v = −y: the emitting side faces down into the room.
            common::push_quad(&mut lights, corner, Vec3::X * cell, Vec3::Z * cell, 1);
        }
    }
    // Faces −z, away from the camera at z = 0.9 looking along −z.
    common::push_quad(
        &mut lights,
        Vec3::new(0.4, -0.6, -0.8),
        Vec3::Y * 0.3,
        Vec3::X * 0.3,
        1,
    );
    common::scene(
        vec![room, cube, lights],
        vec![
            Material::diffuse("wall", Vec3::splat(0.5)),
            Material::emitter("light", Vec3::splat(5.0)),
        ],
        vec![],
        Vec3::new(0.0, 0.0, 0.9),
        Vec3::new(0.0, 0.4, -1.0),
        1.2,
        vec![],
    )
}

/// `sees_emitter_first` (the nearest emitter along the ray, then an
/// any-hit query short of it) answers what a closest-hit query and
/// `sees_emitter` answer, ray for ray, with few emitters in view and with
/// many (more than it tests one by one: closest hits): over a fine grid of camera
/// rays and random rays from inside the room, of which many see a light,
/// many see the occluding cube or the light's back side, and many see walls.
#[test]
fn the_first_hit_emitter_test_agrees_with_closest_hits() {
    for cells in [2, 4] {
        let mut r = common::cpu_renderer(lit_room(cells), path(1), 16);
        r.with_frame_context(0, |ctx| {
            // 2×2 cells: all 10 emitting triangles in view, tested one by
            // one (the test is for camera rays, but with every emitter in
            // view it holds for any ray); 4×4: more than the 16 up to which
            // that is done.
            let emitters = ctx.emitters_in_view.len();
            if cells == 2 {
                assert_eq!(emitters, 10);
            } else {
                assert!(emitters > 16, "{emitters} in view");
            }
            let camera = &ctx.snapshot.camera;
            let n = 200;
            let mut rays: Vec<Ray> = (0..n * n)
                .map(|i| {
                    let (sx, sy) = ((i % n) as f32 / n as f32, (i / n) as f32 / n as f32);
                    let dir = camera.direction(sx + 0.37 / n as f32, sy + 0.61 / n as f32, 1.0);
                    Ray::new(camera.position, dir, 0.0, f32::INFINITY)
                })
                .collect();
            let mut rng = Rng::from_seed(7, 11);
            rays.extend((0..20_000).map(|_| {
                let origin = rng.next_2d().extend(rng.next_f32()) * 1.8 - 0.9;
                // A random direction: a cosine lobe about ±z or ±x.
                let lobe = cosine_hemisphere(rng.next_2d());
                let dir = match rng.next_u32() % 4 {
                    0 => lobe,
                    1 => -lobe,
                    2 => Vec3::new(lobe.z, lobe.y, lobe.x),
                    _ => -Vec3::new(lobe.z, lobe.y, lobe.x),
                };
                Ray::new(origin, dir, 1e-4, f32::INFINITY)
            }));
            let fast = sees_emitter_first(ctx, &rays);
            let mut hits = vec![Hit::MISS; rays.len()];
            ctx.backend.closest_hit(&rays, &mut hits);
            let mut agree = 0;
            let mut seeing = 0;
            for ((ray, hit), &fast) in rays.iter().zip(&hits).zip(&fast) {
                let slow = sees_emitter(ctx, ray, hit);
                agree += usize::from(fast == slow);
                seeing += usize::from(slow);
            }
            assert_eq!(agree, rays.len(), "{cells}×{cells} light cells");
            // Non-trivial: both answers are common.
            assert!(
                seeing > rays.len() / 50,
                "{seeing} of {} see a light",
                rays.len()
            );
            assert!(
                seeing < rays.len() / 2,
                "{seeing} of {} see a light",
                rays.len()
            );
        });
    }
}
