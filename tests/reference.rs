//! The path tracer, `ic` and `trc` against independent reference renders
//! (Mitsuba 3, 4096 spp; `tests/data/reference/SOURCE.md` says how they
//! were made).
//!
//! Tolerances come from the references' own noise: frame 0 was rendered
//! twice with different seeds, so `RMSE(seed0 − seed1)/√2` is the noise σ_ref
//! of one reference image. Our image at `spp` samples has σ ≈ σ_ref·√(4096/spp)
//! (same estimator family), so an unbiased renderer lands near
//! `√(σ² + σ_ref²)`; we allow 25 % over that. The bias on 16×16-pixel block
//! means, which noise barely moves, must stay within 3 % of the mean
//! radiance (an error of a few percent of the indirect light fails it).

use radcache::backend::cpu::CpuBackend;
use radcache::film::{read_exr, Film};
use radcache::method::ic::{GlossyLobe, IcSettings, IrradianceCaching};
use radcache::method::movies::{MoviesSettings, TextureMovies};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::tcg::{TcgSettings, TemporallyCoherentGathering};
use radcache::method::trc::{TemporalRadianceCaching, TrcSettings};
use radcache::method::Method;
use radcache::metrics::{block_bias, rmse, BLOCK};
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::Scene;
use std::path::Path;

const SPP: u32 = 64;
const REFERENCE_SPP: f64 = 4096.0;

fn data(path: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(path)
}

fn reference_noise(scene: &str) -> f64 {
    let a = read_exr(&data(&format!("reference/{scene}/frame_0000.exr"))).unwrap();
    let b = read_exr(&data(&format!("reference/{scene}/seed1_frame_0000.exr"))).unwrap();
    rmse(&a, &b) / 2f64.sqrt()
}

/// A CPU renderer of `scenes/{scene_file}` with `method`, `width`×`height`.
fn renderer(
    scene_file: &str,
    method: Box<dyn Method>,
    (width, height): (u32, u32),
    same_pattern: bool,
) -> Renderer {
    Renderer::new(
        Scene::load(&data(&format!("scenes/{scene_file}"))).unwrap(),
        method,
        Box::new(CpuBackend::new()),
        FrameSettings {
            width,
            height,
            same_pattern,
            ..FrameSettings::default()
        },
    )
}

/// Frame `frame` of the reference of `scene`.
fn reference_frame(scene: &str, frame: u32) -> Film {
    read_exr(&data(&format!("reference/{scene}/frame_{frame:04}.exr"))).unwrap()
}

fn check_scene(scene_file: &str, scene: &str, frames: &[u32], max_block_bias: f64) {
    let sigma_ref = reference_noise(scene);
    let sigma = sigma_ref * (REFERENCE_SPP / SPP as f64).sqrt();
    let expected_rmse = (sigma * sigma + sigma_ref * sigma_ref).sqrt();
    let path = PathTracer::new(PathSettings {
        spp: SPP,
        ..PathSettings::default()
    });
    let size = size_of(&reference_frame(scene, frames[0]));
    let mut renderer = renderer(scene_file, Box::new(path), size, true);
    for &frame in frames {
        let reference = reference_frame(scene, frame);
        let image = renderer.render_frame(frame);
        let e = rmse(&image, &reference);
        let bias = block_bias(&image, &reference, BLOCK);
        eprintln!("{scene} frame {frame}: rmse {e:.4} (noise-only ≈ {expected_rmse:.4}), block bias {bias:.4}");
        assert!(
            e < 1.25 * expected_rmse,
            "{scene} frame {frame}: rmse {e} vs noise-only {expected_rmse}"
        );
        assert!(
            bias < max_block_bias,
            "{scene} frame {frame}: block bias {bias} ≥ {max_block_bias}"
        );
    }
}

#[test]
fn cube_in_box_matches_reference() {
    check_scene("cube_in_box.glb", "cube_in_box", &[0, 12, 23], 0.03);
}

/// Spheres: a third of the spheres are glossy, which the reference renders
/// with GGX and we with modified Phong (DESIGN.md: compare glossy surfaces
/// only with our own `path`); they cover a few blocks, hence the looser
/// block-bias bound.
#[test]
fn spheres_match_reference() {
    check_scene("spheres.glb", "spheres", &[0], 0.05);
}

/// Scenes made for this repository, on what the shared two do not show
/// (`tests/data/reference/MADE_HERE.md`): a non-square camera, a node
/// hierarchy with non-uniform scale, keys off the frames, emissive
/// strength, a two-sided light seen from behind.
#[test]
fn l_hall_matches_reference() {
    check_scene("l_hall.glb", "l_hall", &[0, 11, 23], 0.03);
}

/// A light that moves along a wall and a fast ball, through a portrait
/// camera (`MADE_HERE.md`).
#[test]
fn wall_light_matches_reference() {
    check_scene("wall_light.glb", "wall_light", &[0, 6, 11], 0.03);
}

fn size_of(film: &Film) -> (u32, u32) {
    (film.width, film.height)
}

/// The reference halved to `size`×`size` by 2×2 box averaging: the same
/// image as a 1-pixel box filter at half the resolution, so the means of
/// blocks of half the side are unchanged.
fn halved(reference: &Film) -> Film {
    let (w, h) = (reference.width / 2, reference.height / 2);
    let mut out = Film::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let sum = reference.get(2 * x, 2 * y)
                + reference.get(2 * x + 1, 2 * y)
                + reference.get(2 * x, 2 * y + 1)
                + reference.get(2 * x + 1, 2 * y + 1);
            out.pixels[(y * w + x) as usize] = sum / 4.0;
        }
    }
    out
}

/// `ic`, `trc` and `tcg` (each also with radiance records on glossy
/// surfaces) and
/// `movies`, at their defaults, against the independent
/// references of `scene` at `frames` (`trc` and `tcg` render every frame
/// from 0 up to the last, so that their records age as in a render).
/// References of 128 pixels or more across are halved (the 128×128 shared
/// ones are rendered at 64×64), and the blocks with them, so that the
/// block bias is the same measure as [`check_scene`]'s.
fn check_caching_methods(scene_file: &str, scene: &str, frames: &[u32], max_block_bias: f64) {
    let halve = reference_frame(scene, frames[0]).width >= 128;
    let reference_at = |frame| {
        let full = reference_frame(scene, frame);
        if halve {
            halved(&full)
        } else {
            full
        }
    };
    let block = if halve { BLOCK / 2 } else { BLOCK };
    let size = size_of(&reference_at(frames[0]));
    let ic = IrradianceCaching::new(IcSettings::default());
    let ic_eas = IrradianceCaching::new(IcSettings {
        glossy: GlossyLobe::Eas,
        ..IcSettings::default()
    });
    let trc = TemporalRadianceCaching::new(TrcSettings::default());
    let mut trc_eas = TrcSettings::default();
    trc_eas.ic.glossy = GlossyLobe::Eas;
    let trc_eas = TemporalRadianceCaching::new(trc_eas);
    let tcg = TemporallyCoherentGathering::new(TcgSettings::default());
    let mut tcg_eas = TcgSettings::default();
    tcg_eas.ic.glossy = GlossyLobe::Eas;
    let tcg_eas = TemporallyCoherentGathering::new(tcg_eas);
    let movies = TextureMovies::new(MoviesSettings::default());
    let mut ic = renderer(scene_file, Box::new(ic), size, false);
    let mut ic_eas = renderer(scene_file, Box::new(ic_eas), size, false);
    let mut movies = renderer(scene_file, Box::new(movies), size, false);
    let mut trc = renderer(scene_file, Box::new(trc), size, false);
    let mut trc_eas = renderer(scene_file, Box::new(trc_eas), size, false);
    let mut tcg = renderer(scene_file, Box::new(tcg), size, false);
    let mut tcg_eas = renderer(scene_file, Box::new(tcg_eas), size, false);
    let last = frames.iter().copied().max().unwrap_or(0);
    for frame in 0..=last {
        let trc_image = trc.render_frame(frame);
        let trc_eas_image = trc_eas.render_frame(frame);
        let tcg_image = tcg.render_frame(frame);
        let tcg_eas_image = tcg_eas.render_frame(frame);
        let movies_image = movies.render_frame(frame);
        if !frames.contains(&frame) {
            continue;
        }
        let reference = reference_at(frame);
        let ic_image = ic.render_frame(frame);
        let ic_eas_image = ic_eas.render_frame(frame);
        for (method, image) in [
            ("ic", &ic_image),
            ("ic glossy=eas", &ic_eas_image),
            ("trc", &trc_image),
            ("trc glossy=eas", &trc_eas_image),
            ("tcg", &tcg_image),
            ("tcg glossy=eas", &tcg_eas_image),
            ("movies", &movies_image),
        ] {
            let bias = block_bias(image, &reference, block);
            eprintln!("{scene} frame {frame}: {method} block bias {bias:.4}");
            assert!(
                bias < max_block_bias,
                "{scene}, {method} frame {frame}: block bias {bias} ≥ {max_block_bias}"
            );
        }
    }
}

/// The caching methods interpolate, so their bias is not zero: 0.4 to
/// 0.6 % of the mean radiance here (2026-12-07: `ic` 0.38–0.44 %, `trc`
/// 0.46–0.51 %, `tcg` 0.46–0.56 %, `movies` 0.38–0.40 %; 0.6 to 0.7 %
/// when first measured). The bound, 2 %, is three times that and under
/// DESIGN.md's 5 % target: records gathered with one bounce instead of
/// unbounded paths fail it (11.9 % at frame 0). The cube of this file moves
/// little, so records that never expire stay at 0.9 % by frame 23: the
/// temporal failures are `tests/trc.rs`'s to catch.
#[test]
fn caching_methods_match_reference() {
    check_caching_methods("cube_in_box.glb", "cube_in_box", &[0, 12, 23], 0.02);
}

/// Measured 1.2 to 1.4 % (0.8 to 1.5 % on 2026-12-07; `path`: 1.1 % at
/// frame 0, [`spheres_match_reference`]);
/// the glossy spheres differ by BSDF model, so the bound is looser than on
/// `cube_in_box`: twice the measured bias.
#[test]
fn caching_methods_match_spheres_reference() {
    check_caching_methods("spheres.glb", "spheres", &[0, 12, 23], 0.03);
}

/// Measured (CLI, 96×60, every frame from 0): `ic` 0.8–1.0 %, `trc`
/// 1.1–1.9 %, `tcg` 1.1–2.0 %, `movies` 0.9–1.2 % (`path` at 64 spp:
/// 0.5 %); the bound is 1.5 times the largest. On 2026-12-07, at the
/// frames this test takes: `ic` 0.6–0.9 %, `trc` 0.9–1.1 % at `trc`
/// revision 17 and 0.9–1.6 % at 18 (frame 23: 1.06 → 1.64 % with seed 0,
/// from the check of later frames against what a record shows; over
/// seeds 0–7 its mean is 1.18 % with that check and 1.00 % without, the
/// largest 1.64 %: `benches/RESULTS.md`, "The check against the shown,
/// over seeds"), `tcg` 0.9–1.9 %, `movies` 0.5–0.7 %. At `trc` revision
/// 19 (a replacement follows the change its predecessor observed), over
/// seeds 0–3 at frames 0 / 11 / 23: 0.87 / 1.10 / 1.06 % (1.34 % at
/// frame 23 without it; `benches/RESULTS.md`, "The change a replacement
/// observes").
#[test]
fn caching_methods_match_l_hall_reference() {
    check_caching_methods("l_hall.glb", "l_hall", &[0, 11, 23], 0.03);
}

/// Under the moving light (CLI, 48×64, every frame from 0): `ic`
/// 0.3–0.7 %, `trc` 0.3–0.6 %, `tcg` 0.3–0.9 % (9.5 % at frame 11 with
/// the paper's rule, `light_refresh` off, whose samples lag the light),
/// `movies` 0.7–2.2 %.
#[test]
fn caching_methods_match_wall_light_reference() {
    check_caching_methods("wall_light.glb", "wall_light", &[0, 6, 11], 0.03);
}
