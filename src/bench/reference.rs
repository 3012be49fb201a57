//! The converged `path` reference of a scene, rendered once into
//! `DIR/reference/<scene>/` with a light mask per frame, and reused while
//! its `reference.json` matches.

use super::run::{clear_frames, frame_settings, render_frames, BenchScene};
use super::BenchOptions;
use crate::backend::{Hit, Ray};
use crate::method::path::PathSettings;
use crate::method::FrameContext;
use crate::metrics;
use crate::render::{self, BackendChoice, FrameSettings, MethodSettings, Renderer};
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;
/// What `DIR/reference/<scene>/reference.json` records; a reference is
/// reused only when all of it matches.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ReferenceInfo {
    scene: String,
    /// The scene's content hash as a job records it
    /// ([`render::scene_identity`]): a file's, with those of the buffers and
    /// images it names, so that editing a `.bin` renders the reference again.
    scene_hash: String,
    frames: [u32; 2],
    width: u32,
    height: u32,
    spp: u32,
    seed: u64,
    fps: f32,
    method: String,
    same_pattern: bool,
    /// The folder holds a light mask per frame (written since the surface
    /// error exists; an older reference is rendered again).
    #[serde(default)]
    light_masks: bool,
    /// Coverage-only camera rays of pixels on a seen light's edge, in units
    /// of `spp` (`method::pixels`; 0 in references made before the edge
    /// pixels were post-stratified, which are rendered again).
    #[serde(default)]
    edge_coverage_factor: u32,
    /// `path`'s algorithm revision ([`crate::method::algorithm_revision`]):
    /// a reference an earlier `path` rendered (one without this field was)
    /// is rendered again, as its frames are no longer what `path` makes.
    #[serde(default)]
    path_revision: u64,
    /// The backend the reference was rendered on ([`REFERENCE_BACKEND`]; a
    /// reference from before it was fixed, rendered with `auto`, perhaps on
    /// a GPU, is rendered again).
    #[serde(default)]
    backend: String,
    /// The seed the reference's own random streams were keyed with
    /// ([`reference_seed`] of `seed`, the runs'; `None` in references made
    /// with the runs' seed itself, which are rendered again).
    #[serde(default)]
    reference_seed: Option<u64>,
}

/// What [`reference_seed`] sets apart from the runs' seed.
const REFERENCE_SEED_TAG: u64 = 0x5245_4645_5245_4e43; // "REFERENC"

/// The seed of the reference of runs rendered with `seed`: never `seed`
/// itself, so that no run draws the reference's random numbers. With the
/// runs' seed, a `--same-pattern` run of `path` drew the same streams as
/// the reference's first samples (both keyed without the frame): its
/// error came out too low, on cube-in-box (64×64, 24 frames, 256 spp)
/// `path` at 64 spp by 20 % (0.02683 against 0.03373 with a reference of
/// its own seed) and at 16 spp by 4–5 % (`benches/RESULTS.md`, "The
/// reference's own seed"), and a run at the reference's spp was the
/// reference, error 0.
pub(super) fn reference_seed(seed: u64) -> u64 {
    seed ^ REFERENCE_SEED_TAG
}

/// The backend every reference is rendered on: the CPU, whatever the runs
/// are rendered on. A reference must not share the defects of what it
/// measures: on an H200 the GPU's light rims were wrong (fixed since,
/// `pixels::short_of_emitter`), its reference (`auto` then) had the same
/// rims, and the GPU's runs came out 2.6 times more accurate than the
/// CPU's same runs (cube-in-box `path`, rel. RMSE 0.098 against 0.257). The GPU exists to be checked against the CPU, not
/// the other way round.
const REFERENCE_BACKEND: BackendChoice = BackendChoice::Cpu;

/// Renders the reference of `scene` into `dir` unless a matching one is
/// there already.
pub(super) fn ensure_reference(opts: &BenchOptions, scene: &BenchScene, dir: &Path) -> Result<()> {
    let source = scene.source;
    let info = ReferenceInfo {
        scene: source.to_string(),
        scene_hash: render::scene_identity(source)?.1,
        frames: [opts.frames.start, opts.frames.end],
        width: opts.width,
        height: opts.height,
        spp: opts.reference_spp,
        seed: opts.seed,
        fps: opts.fps,
        method: "path".into(),
        same_pattern: true,
        light_masks: true,
        edge_coverage_factor: frame_settings(opts, true).edge_coverage_factor,
        path_revision: crate::method::algorithm_revision("path"),
        backend: REFERENCE_BACKEND.name().into(),
        reference_seed: Some(reference_seed(opts.seed)),
    };
    let json = dir.join("reference.json");
    let have = std::fs::read_to_string(&json)
        .ok()
        .and_then(|s| serde_json::from_str::<ReferenceInfo>(&s).ok());
    if have.as_ref() == Some(&info) {
        if readable(opts, dir) {
            if !opts.quiet {
                eprintln!("reference {}: reusing {}", source, dir.display());
            }
            return Ok(());
        }
        eprintln!(
            "note: reference {}: a frame or light mask in {} does not read whole; it is \
             rendered again",
            source,
            dir.display()
        );
    }
    // Stale or partial: start again, so no frame of another reference stays.
    let _ = std::fs::remove_file(&json);
    clear_frames(dir)?;
    if !opts.quiet {
        eprintln!(
            "reference {}: rendering frames {}..{} at {}x{}, path {} spp, same pattern → {}",
            source,
            opts.frames.start,
            opts.frames.end,
            opts.width,
            opts.height,
            opts.reference_spp,
            dir.display()
        );
    }
    let settings = MethodSettings::Path(PathSettings {
        spp: opts.reference_spp,
        ..PathSettings::default()
    });
    let mut renderer = Renderer::new(
        scene.scene.clone(),
        settings.instantiate(),
        render::make_backend(REFERENCE_BACKEND)?,
        FrameSettings {
            seed: reference_seed(opts.seed),
            ..frame_settings(opts, true)
        },
    );
    // Stopped, it leaves no reference.json: the next bench renders it again.
    renderer.set_abandon_flag(opts.stop.clone());
    let what = format!("reference {}", scene.label);
    render_frames(
        &mut renderer,
        opts.frames.clone(),
        Some(dir),
        &what,
        opts.quiet,
    )?;
    for frame in opts.frames.clone() {
        let mask = renderer.with_frame_context(frame, seen_lights);
        metrics::write_light_mask(
            &metrics::light_mask_path(dir, frame),
            opts.width,
            opts.height,
            &mask,
        )?;
    }
    // Written last: its presence says the frames are complete.
    std::fs::write(&json, serde_json::to_string_pretty(&info)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    Ok(())
}

/// Whether every frame of the reference in `dir`, and its light mask,
/// reads whole at the bench's size: a damaged file (a truncated copy)
/// renders the reference again rather than failing the bench once every
/// run has rendered. Reading the files costs little beside one run.
fn readable(opts: &BenchOptions, dir: &Path) -> bool {
    let size = (opts.width, opts.height);
    opts.frames.clone().all(|f| {
        let frame = crate::film::read_exr(&crate::film::frame_path(dir, f, "exr"));
        let mask = metrics::read_light_mask(&metrics::light_mask_path(dir, f), size);
        frame.is_ok_and(|film| (film.width, film.height) == size) && matches!(mask, Ok(Some(_)))
    })
}

/// Which pixels of the frame see a light source directly or border a pixel
/// that does (the light mask of [`metrics::light_mask_path`]): 8×8 primary
/// rays per pixel on a regular grid over its square, then a one-pixel
/// dilation, so that a rim pixel the grid misses is left out as well. An
/// emissive triangle counts from either side: leaving out a few more pixels
/// only narrows the surface error, it does not bias it.
fn seen_lights(ctx: &FrameContext) -> Vec<bool> {
    const GRID: u32 = 8;
    let (w, h) = (ctx.width, ctx.height);
    let camera = &ctx.snapshot.camera;
    let emissive = |hit: &Hit| {
        hit.is_hit() && {
            let material = ctx.snapshot.tri_material[hit.triangle as usize];
            ctx.scene.materials[material as usize].is_emissive()
        }
    };
    let mut lit = vec![false; (w * h) as usize];
    for y in 0..h {
        let rays: Vec<Ray> = (0..w * GRID * GRID)
            .map(|i| {
                let (x, s) = (i / (GRID * GRID), i % (GRID * GRID));
                let sx = (x as f32 + ((s % GRID) as f32 + 0.5) / GRID as f32) / w as f32;
                let sy = (y as f32 + ((s / GRID) as f32 + 0.5) / GRID as f32) / h as f32;
                let dir = camera.direction(sx, sy, ctx.aspect());
                Ray::new(camera.position, dir, 0.0, f32::INFINITY)
            })
            .collect();
        let mut hits = vec![Hit::MISS; rays.len()];
        ctx.backend.closest_hit(&rays, &mut hits);
        for (x, pixel_hits) in hits.chunks(GRID as usize * GRID as usize).enumerate() {
            lit[(y * w) as usize + x] = pixel_hits.iter().any(emissive);
        }
    }
    dilate(&lit, w, h)
}

/// `mask` grown by one pixel in the eight directions.
fn dilate(mask: &[bool], w: u32, h: u32) -> Vec<bool> {
    let at = |x: i64, y: i64| {
        (0..w as i64).contains(&x)
            && (0..h as i64).contains(&y)
            && mask[(y * w as i64 + x) as usize]
    };
    (0..(w * h) as i64)
        .map(|i| {
            let (x, y) = (i % w as i64, i / w as i64);
            (-1..=1).any(|dy| (-1..=1).any(|dx| at(x + dx, y + dy)))
        })
        .collect()
}
