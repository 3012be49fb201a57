//! Per-frame irradiance caching against independent answers: the indirect
//! irradiance of a floor under a ceiling lit by a point light (computed by
//! quadrature), the effect of gradients, the path tracer, determinism.

mod common;

use common::{push_quad, scene};
use glam::Vec3;
use radcache::backend::cpu::CpuBackend;
use radcache::backend::{Hit, Ray};
use radcache::cache::gather::Strata;
use radcache::cache::{eas, IrradianceCache, LookupPoint};
use radcache::material::Bsdf;
use radcache::method::ic::{GlossyLobe, IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::metrics::{block_bias, rel_rmse, BLOCK};
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::{Material, Mesh, Scene};
use std::f32::consts::PI;

const CEILING_Y: f32 = 2.0;
const CEILING_ALBEDO: f32 = 0.8;
const INTENSITY: f32 = 20.0;
const HALF: f32 = 5.0;

/// A floor (albedo ~0, so nothing bounces back) under a 10 m × 10 m
/// ceiling facing down, lit by a point light at `light`; the camera looks
/// down at the floor from just under the ceiling.
fn floor_and_ceiling(light: Vec3) -> Scene {
    floor_of_and_ceiling(Material::diffuse("floor", Vec3::splat(1e-4)), light)
}

/// [`floor_and_ceiling`] with a floor of `floor_material`.
fn floor_of_and_ceiling(floor_material: Material, light: Vec3) -> Scene {
    let mut floor = Mesh::default();
    push_quad(
        &mut floor,
        Vec3::new(-HALF, 0.0, -HALF),
        Vec3::Z * 2.0 * HALF,
        Vec3::X * 2.0 * HALF,
        0,
    );
    let mut ceiling = Mesh::default();
    push_quad(
        &mut ceiling,
        Vec3::new(-HALF, CEILING_Y, -HALF),
        Vec3::X * 2.0 * HALF,
        Vec3::Z * 2.0 * HALF,
        1,
    );
    scene(
        vec![floor, ceiling],
        vec![
            floor_material,
            Material::diffuse("ceiling", Vec3::splat(CEILING_ALBEDO)),
        ],
        vec![],
        Vec3::new(0.0, 1.95, 0.0),
        -Vec3::Y,
        1.0,
        vec![(light, Vec3::splat(INTENSITY))],
    )
}

/// Indirect irradiance at floor point `p`: the ceiling's radiance
/// `L(x) = ρ/π · I·cosθ_x/d²` (lit by the point light only) integrated
/// over the ceiling, `E(p) = ∫ L(x) cosθ_p cosθ_x / r² dA`, by the midpoint
/// rule on a 600×600 grid.
fn floor_irradiance(p: Vec3, light: Vec3) -> f32 {
    over_ceiling(p, light, |_| 1.0)
}

/// `∫ w(wi) L(x) cosθ_p cosθ_x / r² dA` over the ceiling for floor point
/// `p`, `wi` the direction from `p` to `x`: [`floor_irradiance`]'s
/// quadrature with a weight per direction.
fn over_ceiling(p: Vec3, light: Vec3, w: impl Fn(Vec3) -> f32) -> f32 {
    let n = 600;
    let cell = 2.0 * HALF / n as f32;
    let mut e = 0.0f64;
    for i in 0..n {
        for j in 0..n {
            let x = Vec3::new(
                -HALF + (i as f32 + 0.5) * cell,
                CEILING_Y,
                -HALF + (j as f32 + 0.5) * cell,
            );
            let to_light = light - x;
            let d2 = to_light.length_squared();
            let radiance = CEILING_ALBEDO / PI * INTENSITY * (-to_light.y / d2.sqrt()) / d2;
            let r2 = (x - p).length_squared();
            let cos = CEILING_Y / r2.sqrt();
            e += (w((x - p) / r2.sqrt()) * radiance * cos * cos / r2) as f64;
        }
    }
    (e * (cell * cell) as f64) as f32
}

fn ic_cache(light: Vec3, settings: IcSettings, size: u32) -> (IrradianceCache, Renderer) {
    ic_cache_of(floor_and_ceiling(light), settings, size)
}

fn ic_cache_of(scene: Scene, settings: IcSettings, size: u32) -> (IrradianceCache, Renderer) {
    let ic = IrradianceCaching::new(settings);
    let mut renderer = Renderer::new(
        scene,
        Box::new(IrradianceCaching::new(IcSettings::default())),
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: size,
            height: size,
            ..FrameSettings::default()
        },
    );
    let cache = renderer.with_frame_context(0, |ctx| ic.build_cache(ctx));
    (cache, renderer)
}

/// Floor points seen by the camera (it sees |x|, |z| < 1.05 at y = 0).
fn floor_points(n: usize) -> Vec<Vec3> {
    (0..n)
        .flat_map(|i| (0..n).map(move |j| (i, j)))
        .map(|(i, j)| {
            let s = |k: usize| -0.9 + 1.8 * (k as f32 + 0.37) / n as f32;
            Vec3::new(s(i), 0.0, s(j))
        })
        .collect()
}

/// `L(x)` of [`floor_irradiance`] reflected by the glossy lobe at floor
/// point `p` towards `wo`: `∫ f_s(wo, wi) L(x) cosθ_p cosθ_x / r² dA`.
fn floor_glossy_radiance(p: Vec3, wo: Vec3, light: Vec3, bsdf: &Bsdf) -> f32 {
    over_ceiling(p, light, |wi| bsdf.eval_specular(wo, wi).x)
}

/// Radiance records (`--ic-glossy eas`): a glossy floor (n = 40, no
/// diffuse part, so it gets records only as a glossy surface) reflects the
/// lit ceiling. The records' equivalent area light sources, interpolated
/// and moved to floor points between them (EAS Eq. 16–17), against the same
/// reflection by quadrature over the ceiling. Its `ks` is small so that
/// the light it sends back to the ceiling (which the quadrature leaves
/// out) stays under 1 %.
#[test]
fn radiance_records_reflect_the_ceiling_as_quadrature_does() {
    let light = Vec3::new(0.2, 0.6, -0.1);
    let floor = Material::glossy("glossy floor", Vec3::ZERO, Vec3::splat(0.01), 40.0);
    let settings = IcSettings {
        accuracy: 0.1,
        strata: Strata { theta: 32, phi: 96 },
        glossy: GlossyLobe::Eas,
        ..IcSettings::default()
    };
    let (cache, _) = ic_cache_of(floor_of_and_ceiling(floor.clone(), light), settings, 32);
    let with_sources = cache.records().iter().filter(|r| r.eas.is_some()).count();
    assert!(with_sources >= 4, "{with_sources} records with sources");
    let camera = Vec3::new(0.0, 1.95, 0.0);
    let (mut worst, mut sum, mut count) = (0.0f32, 0.0f32, 0);
    for p in floor_points(6) {
        let wo = (camera - p).normalize();
        let bsdf = Bsdf::new(&floor, Vec3::Y, wo);
        let at = LookupPoint::open(p, Vec3::Y);
        let got = eas::reflected_radiance(&cache, &at, &bsdf, wo)
            .unwrap_or_else(|| panic!("no record with sources covers {p}"))
            .x;
        let expected = floor_glossy_radiance(p, wo, light, &bsdf);
        let err = (got - expected).abs() / expected;
        worst = worst.max(err);
        assert!(err < 0.1, "at {p}: {got} against {expected} by quadrature");
        (sum, count) = (sum + err, count + 1);
    }
    // Measured: mean 3.6 %, worst 7.5 % (Monte Carlo noise of 3,072
    // samples a record, the closed-form mean BRDF, Eq. 16 across records).
    let mean = sum / count as f32;
    assert!(mean < 0.05, "mean relative error {mean}, worst {worst}");
}

/// With accuracy a = 0.1 (Ward's weight bounds the estimated relative error
/// by about a, so the default 0.2 allows more than the 2 % asked here).
#[test]
fn cached_irradiance_matches_quadrature_between_records() {
    // 32×96 cells: the per-record Monte Carlo noise stays well under 1 %,
    // so what is left is the interpolation error under test.
    let light = Vec3::new(0.2, 0.6, -0.1);
    let settings = IcSettings {
        accuracy: 0.1,
        strata: Strata { theta: 32, phi: 96 },
        ..IcSettings::default()
    };
    let (cache, _) = ic_cache(light, settings, 32);
    assert!(
        cache.len() >= 4,
        "expected several records, got {}",
        cache.len()
    );
    let mut worst = 0.0f32;
    for p in floor_points(12) {
        let e = cache
            .interpolate(&LookupPoint::open(p, Vec3::Y), true)
            .unwrap_or_else(|| panic!("no record covers {p}"))
            .irradiance;
        let expected = floor_irradiance(p, light);
        let err = (e.x - expected).abs() / expected;
        worst = worst.max(err);
        assert!(
            err < 0.02,
            "at {p}: cached {} vs quadrature {expected} ({:.1} %)",
            e.x,
            err * 100.0
        );
    }
    eprintln!(
        "{} records, worst error {:.2} %",
        cache.len(),
        worst * 100.0
    );
}

#[test]
fn gradients_reduce_interpolation_error() {
    // The ceiling's bright spot lies beside the view: across the floor in
    // view the indirect irradiance climbs steeply towards +x; a coarse
    // accuracy makes records extrapolate far.
    let light = Vec3::new(2.0, 1.5, 0.0);
    let settings = IcSettings {
        accuracy: 0.5,
        strata: Strata { theta: 32, phi: 96 },
        ..IcSettings::default()
    };
    let (cache, _) = ic_cache(light, settings, 32);
    let (mut with, mut without, mut n) = (0.0f64, 0.0f64, 0);
    for p in floor_points(16) {
        let expected = floor_irradiance(p, light);
        let (Some(g), Some(c)) = (
            cache.interpolate(&LookupPoint::open(p, Vec3::Y), true),
            cache.interpolate(&LookupPoint::open(p, Vec3::Y), false),
        ) else {
            continue;
        };
        with += ((g.irradiance.x - expected) / expected).abs() as f64;
        without += ((c.irradiance.x - expected) / expected).abs() as f64;
        n += 1;
    }
    assert!(n > 100, "too few covered points: {n}");
    let (with, without) = (with / n as f64, without / n as f64);
    eprintln!("mean relative error: with gradients {with:.4}, without {without:.4}");
    assert!(
        with < 0.75 * without,
        "gradients did not help: {with} vs {without}"
    );
}

fn cube_in_box(method: Box<dyn radcache::method::Method>, size: u32) -> Renderer {
    common::cpu_renderer(Scene::builtin("cube-in-box").unwrap(), method, size)
}

/// `ic` against a converged `path` render of the same scene: relative RMSE
/// and block bias within bounds. At 48×48 the reference (1024 spp) has about
/// 3 % relative noise per pixel and `ic` at 64 spp about 8 % from direct
/// light and the light's edge pixels, so an unbiased `ic` lands near 0.1;
/// the bound 0.2 leaves room for interpolation error but not for a missing
/// or doubled bounce (≈ 30 % of the light here). The bias on 16×16 block
/// means must stay under 5 % (the bound).
#[test]
fn ic_agrees_with_path_tracer() {
    let size = 48;
    let reference = cube_in_box(
        Box::new(PathTracer::new(PathSettings {
            spp: 1024,
            ..PathSettings::default()
        })),
        size,
    )
    .render_frame(3);
    let settings = IcSettings {
        spp: 64,
        ..IcSettings::default()
    };
    let image = cube_in_box(Box::new(IrradianceCaching::new(settings)), size).render_frame(3);
    let e = rel_rmse(&image, &reference);
    let bias = block_bias(&image, &reference, BLOCK);
    eprintln!("ic vs path: rel_rmse {e:.4}, block bias {bias:.4}");
    assert!(e < 0.2, "rel_rmse {e}");
    assert!(bias < 0.05, "block bias {bias}");
}

#[test]
fn ic_frames_are_deterministic() {
    let settings = IcSettings {
        spp: 2,
        ..IcSettings::default()
    };
    let a = cube_in_box(Box::new(IrradianceCaching::new(settings.clone())), 24).render_frame(5);
    let mut r = cube_in_box(Box::new(IrradianceCaching::new(settings)), 24);
    let _ = r.render_frame(4);
    assert_eq!(r.render_frame(5), a);
}

/// Each record's translation gradient (Ward & Heckbert 1992, as re-derived
/// in `cache::gather`) against central differences of the quadrature.
#[test]
fn translation_gradients_match_finite_differences() {
    let light = Vec3::new(0.1, 1.3, 0.0);
    let settings = IcSettings {
        strata: Strata { theta: 32, phi: 96 },
        ..IcSettings::default()
    };
    let (cache, _) = ic_cache(light, settings, 32);
    let h = 0.02;
    for r in cache.records() {
        let p = r.position;
        let fd = |axis: Vec3| {
            (floor_irradiance(p + axis * h, light) - floor_irradiance(p - axis * h, light))
                / (2.0 * h)
        };
        let (gx, gz) = (fd(Vec3::X), fd(Vec3::Z));
        let g = r.grad_translation[0];
        // 5 % of the slope, or 1 % of E per metre where the slope is flat.
        let tol = 0.05 * gx.hypot(gz) + 0.01 * r.irradiance.x;
        assert!(
            (g.x - gx).hypot(g.z - gz) < tol,
            "record at {p}: gradient ({}, {}) vs finite differences ({gx}, {gz})",
            g.x,
            g.z
        );
    }
}

/// The pixels of a `size`² `cube-in-box` frame 0 whose centre sees the
/// ceiling right above the light (which hangs 2 cm under it, one-sided,
/// facing down): the ceiling there gets almost no light. Found with the
/// backend's rays and the emitters' bounds, and with them, the pixels
/// whose centre sees the rest of the ceiling.
fn ceiling_above_and_beside_the_light(size: u32) -> (Vec<usize>, Vec<usize>) {
    let mut renderer = cube_in_box(Box::new(PathTracer::new(PathSettings::default())), size);
    renderer.with_frame_context(0, |ctx| {
        let snapshot = ctx.snapshot;
        let (mut lo, mut hi) = (Vec3::MAX, Vec3::MIN);
        for (t, &m) in snapshot.triangles.iter().zip(&snapshot.tri_material) {
            if ctx.scene.materials[m as usize].is_emissive() {
                for p in t.p {
                    (lo, hi) = (lo.min(p), hi.max(p));
                }
            }
        }
        let camera = &snapshot.camera;
        let s = size as f32;
        let rays: Vec<Ray> = (0..size * size)
            .map(|i| {
                let (x, y) = ((i % size) as f32 + 0.5, (i / size) as f32 + 0.5);
                let d = camera.direction(x / s, y / s, 1.0);
                Ray::new(camera.position, d, 0.0, f32::INFINITY)
            })
            .collect();
        let mut hits = vec![Hit::MISS; rays.len()];
        ctx.backend.closest_hit(&rays, &mut hits);
        let (mut above, mut beside) = (Vec::new(), Vec::new());
        for (i, (ray, hit)) in rays.iter().zip(&hits).enumerate() {
            let p = Vec3::from(ray.origin) + Vec3::from(ray.dir) * hit.t;
            if !hit.is_hit() || p.y < hi.y + 0.01 {
                continue;
            }
            let over = p.x > lo.x && p.x < hi.x && p.z > lo.z && p.z < hi.z;
            if over {
                above.push(i);
            } else {
                beside.push(i);
            }
        }
        (above, beside)
    })
}

/// `ic` against the path tracer on the ceiling right above the light:
/// within 40 % there, where the path tracer shows it much darker than the
/// rest of the ceiling (so the test means something). With Ward's weight
/// alone the open ceiling's records cover it: 3.5× too bright (measured
/// when the clearance was added). At 128×128 these pixels see the strip
/// at a grazing angle, mixed with open ceiling beyond the light's far
/// edge; `ic` reads them about a third low (at 256×256 the strip's mean is
/// within 2 %): the records the fill puts in the strip have their radius
/// raised to the 2-pixel minimum spacing (`IcSettings::min_spacing_px`,
/// Tabellion & Lamorlette's clamp), so they reach the open ceiling just
/// beyond the edge and darken it, as a debug dump of one pixel's samples
/// showed (open samples interpolating a strip record's irradiance).
#[test]
fn ic_keeps_the_ceiling_above_the_light_dark() {
    let size = 128;
    let (above, beside) = ceiling_above_and_beside_the_light(size);
    assert!(above.len() >= 10, "{} pixels above the light", above.len());
    let mean = |film: &radcache::film::Film, pixels: &[usize]| {
        pixels.iter().map(|&i| film.pixels[i]).sum::<Vec3>() / pixels.len() as f32
    };
    let reference = cube_in_box(
        Box::new(PathTracer::new(PathSettings {
            spp: 256,
            ..PathSettings::default()
        })),
        size,
    )
    .render_frame(0);
    let image = cube_in_box(
        Box::new(IrradianceCaching::new(IcSettings::default())),
        size,
    )
    .render_frame(0);
    let (expected, got) = (mean(&reference, &above), mean(&image, &above));
    let open = mean(&reference, &beside);
    eprintln!(
        "ceiling above the light ({} pixels): ic {got}, path {expected}; \
         the rest of the ceiling {open}",
        above.len()
    );
    assert!(expected.x < 0.5 * open.x, "{expected} vs {open}");
    assert!(
        (got.x - expected.x).abs() < 0.4 * expected.x,
        "ic {got} vs path {expected}"
    );
}

/// In a closed box whose every surface emits `Le` and has albedo ρ, the
/// indirect radiance arriving anywhere is `ρ·Le/(1 − ρ)` (the light that
/// has bounced at least once), so every record's irradiance is
/// `π·ρ·Le/(1 − ρ)`: its error is the noise of its gathering paths alone.
/// At ρ = 0.9 nine tenths of that light has bounced more than once, so the
/// paths' Russian roulette decides it: ending them early (as a survival
/// of half the throughput did, before `ic` revision 8) left the records
/// 5.5 % rms from the closed form, noise the interpolation turns into
/// blotches that do not average out. The bound is the noise of roulette
/// on the whole throughput (3.6 % rms over these 30 records) with a
/// quarter to spare; a mean error of 2 % is 3σ of the 30 records' mean.
#[test]
fn records_in_a_bright_furnace_are_unbiased_and_quiet() {
    let (albedo, le) = (0.9f32, 1.0f32);
    let (cache, _) = ic_cache_of(common::furnace_box(albedo, le), IcSettings::default(), 32);
    let expected = std::f32::consts::PI * albedo * le / (1.0 - albedo);
    let errors: Vec<f32> = cache
        .records()
        .iter()
        .map(|r| (r.irradiance.x - expected) / expected)
        .collect();
    let n = errors.len() as f32;
    let mean = errors.iter().sum::<f32>() / n;
    let spread = (errors.iter().map(|e| e * e).sum::<f32>() / n).sqrt();
    eprintln!("{n} records, mean error {mean:+.4}, rms {spread:.4}");
    assert!(n >= 8.0, "expected several records, got {n}");
    assert!(mean.abs() < 0.02, "records' mean error {mean:+.4}");
    assert!(spread < 0.045, "records' rms error {spread:.4}");
}
