//! `trc` (temporal radiance caching, TVCG 2007): record lifespans in a
//! static scene, the reprojected estimate of E(t0+1) (Table 1), ghosts of a
//! light switched off, and records computed and flicker against `ic`.

mod common;

use common::{inward_box, push_quad, scene};
use glam::{Vec3, Vec4};
use radcache::backend::cpu::CpuBackend;
use radcache::cache::gather::Strata;
use radcache::film::Film;
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::trc::{TemporalRadianceCaching, TrcSettings};
use radcache::method::Method;
use radcache::metrics::flicker;
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::{Channel, Interpolation, Material, Mesh, Property, Scene};

fn renderer(scene: Scene, size: u32, fps: f32, same_pattern: bool) -> Renderer {
    Renderer::new(
        scene,
        Box::new(PathTracer::new(PathSettings::default())),
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: size,
            height: size,
            fps,
            same_pattern,
            ..FrameSettings::default()
        },
    )
}

fn small_ic() -> IcSettings {
    IcSettings {
        spp: 1,
        strata: Strata { theta: 8, phi: 24 },
        ..IcSettings::default()
    }
}

/// A white room lit by a 0.5 m ceiling panel; with `off_at`, the panel is
/// scaled to nothing (switched off) from frame `off_at` on (step key).
fn lit_room(off_at: Option<u32>, fps: f32) -> Scene {
    let materials = vec![
        Material::diffuse("white", Vec3::splat(0.7)),
        Material::emitter("light", Vec3::splat(20.0)),
    ];
    let room = inward_box(Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 2.0, 1.0), 0);
    let mut panel = Mesh::default();
    push_quad(
        &mut panel,
        Vec3::new(-0.25, 1.9, -0.25),
        Vec3::X * 0.5,
        Vec3::Z * 0.5,
        1,
    );
    let channels = off_at
        .map(|k| {
            vec![Channel {
                node: 1,
                property: Property::Scale,
                interpolation: Interpolation::Step,
                times: vec![0.0, (k as f32 - 0.5) / fps],
                values: vec![Vec4::new(1.0, 1.0, 1.0, 0.0), Vec4::ZERO],
            }]
        })
        .unwrap_or_default();
    let mut s = scene(
        vec![room, panel],
        materials,
        channels,
        Vec3::new(0.0, 1.0, 0.95),
        -Vec3::Z,
        1.2,
        vec![],
    );
    s.frame_count = 64;
    s
}

fn render_trc(r: &mut Renderer, trc: &mut TemporalRadianceCaching, frame: u32) -> Film {
    r.with_frame_context(frame, |ctx| trc.render_frame(ctx))
}

/// Static scene: τ = 1 exactly (nothing moves, so no sample is
/// reprojected), so every record lives exactly δt_max frames (Eq. 11), and
/// frame f < δt_max of `trc` is `ic`'s render of frame f with the cache
/// `ic` built in frame 0 — the same records, equal up to the order of the
/// floating-point sums of the interpolation (the rebuilt octree visits
/// records in another order). At frame δt_max every record expires
/// together: those a pixel used are replaced at their point, the others
/// dropped.
#[test]
fn static_scene_records_live_max_life_and_frames_match_ic() {
    let max_life = 4;
    let settings = TrcSettings {
        ic: small_ic(),
        max_life,
        ..TrcSettings::default()
    };
    let mut r = renderer(lit_room(None, 24.0), 16, 24.0, false);
    let mut trc = TemporalRadianceCaching::new(settings.clone());
    let ic = IrradianceCaching::new(settings.ic.clone());
    let cache0 = r.with_frame_context(0, |ctx| ic.build_cache(ctx));
    let n = cache0.len() as u64;
    assert!(n > 4, "too few records ({n}) for the test to mean anything");
    for f in 0..max_life {
        let frame = render_trc(&mut r, &mut trc, f);
        let stats = trc.last_frame_stats();
        let expected = r.with_frame_context(f, |ctx| ic.render_with_cache(ctx, &cache0));
        let scale = expected
            .pixels
            .iter()
            .map(|p| p.max_element())
            .fold(0.0, f32::max);
        let diff = frame
            .pixels
            .iter()
            .zip(&expected.pixels)
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0, f32::max);
        assert!(diff <= 1e-5 * scale, "frame {f}: differs from ic by {diff}");
        if f == 0 {
            assert_eq!((stats.records_created, stats.records_reused), (n, 0));
        } else {
            assert_eq!(
                (
                    stats.records_created,
                    stats.records_reused,
                    stats.records_replaced
                ),
                (0, n, 0),
                "frame {f}"
            );
        }
        assert!(trc.records().iter().all(|k| k.last_valid == max_life - 1));
    }
    let _ = render_trc(&mut r, &mut trc, max_life);
    let stats = trc.last_frame_stats();
    assert_eq!(stats.records_reused, 0);
    assert_eq!(stats.records_replaced + stats.records_dropped, n);
    assert!(stats.records_replaced > 0);
    assert!(trc
        .records()
        .iter()
        .filter(|k| k.replaces.is_some())
        .all(|k| k.record.created_frame == max_life));
}

/// TRC Table 1 on cube-in-box: the error of the E(t0+1) estimate against
/// E(t0+1) gathered again at the same points (same random streams), with
/// reprojection (§4.7) and without (E constant), mean and median over all
/// records of a frame. At 6 fps the cube moves ~4 cm per frame.
#[test]
fn reprojection_estimate_of_next_frame_is_no_worse_than_constant() {
    let fps = 6.0;
    let mut r = renderer(Scene::builtin("cube-in-box").unwrap(), 24, fps, false);
    let mut errors = (Vec::new(), Vec::new());
    for t0 in [5u32, 20] {
        let mut trc = TemporalRadianceCaching::new(TrcSettings {
            ic: IcSettings {
                spp: 1,
                ..IcSettings::default()
            },
            ..TrcSettings::default()
        });
        let _ = render_trc(&mut r, &mut trc, t0);
        let records = trc.records().to_vec();
        let actual = r.with_frame_context(t0 + 1, |ctx| trc.regather(ctx, &records));
        // Relative to the frame's mean record irradiance: records in the
        // dark (under the cube) would divide by almost nothing.
        let mean: f32 =
            actual.iter().map(|e| e.element_sum() / 3.0).sum::<f32>() / actual.len().max(1) as f32;
        for (k, e1) in records.iter().zip(actual) {
            let rel = |est: Vec3| {
                let d = est - e1;
                (d.length_squared() / 3.0).sqrt() / mean
            };
            errors.0.push(rel(k.next_irradiance));
            errors.1.push(rel(k.record.irradiance));
        }
    }
    let stats = |v: &mut Vec<f32>| {
        v.sort_by(f32::total_cmp);
        (v.iter().sum::<f32>() / v.len() as f32, v[v.len() / 2])
    };
    let (mean_r, median_r) = stats(&mut errors.0);
    let (mean_n, median_n) = stats(&mut errors.1);
    eprintln!(
        "E(t0+1) error over {} records: reprojection mean {:.2} % median {:.2} %, \
         none mean {:.2} % median {:.2} %",
        errors.0.len(),
        100.0 * mean_r,
        100.0 * median_r,
        100.0 * mean_n,
        100.0 * median_n
    );
    // The paper's gain (Table 1: mean 2.9 % vs 3.7 %) is NOT reproduced
    // here: most of the error is the change of light on static surfaces,
    // which neither estimate sees. This guards against reprojection making
    // the estimate worse (before cell-centre displacement it did, by 10 %).
    assert!(mean_r <= 1.05 * mean_n, "mean {mean_r} vs {mean_n}");
    assert!(
        median_r <= 1.05 * median_n,
        "median {median_r} vs {median_n}"
    );
}

/// A light switched off at frame k: records created before k know nothing
/// of it (τ = 1) and keep its indirect light as a ghost, but every one has
/// expired by k + δt_max (Eq. 11). The room is lit by that light only, so
/// the reference from then on is black.
#[test]
fn switched_off_light_leaves_no_indirect_after_max_life() {
    let (k, max_life) = (3u32, 4u32);
    let mut r = renderer(lit_room(Some(k), 24.0), 12, 24.0, false);
    let mut trc = TemporalRadianceCaching::new(TrcSettings {
        ic: small_ic(),
        max_life,
        ..TrcSettings::default()
    });
    let mut means = Vec::new();
    for f in 0..k + max_life + 2 {
        let film = render_trc(&mut r, &mut trc, f);
        means.push(film.mean());
    }
    eprintln!("mean radiance per frame: {means:?}");
    assert!(means[0] > 0.0);
    assert!(
        means[k as usize] > 0.0,
        "no ghost at frame k: test proves nothing"
    );
    for (f, m) in means.iter().enumerate().skip((k + max_life) as usize) {
        assert!(*m == 0.0, "indirect light left at frame {f}: {m}");
    }
}

/// Over 16 frames of cube-in-box, `trc` computes far fewer records than
/// `ic` and flickers less against a same-pattern `path` reference.
#[test]
fn trc_computes_fewer_records_and_flickers_less_than_ic() {
    let (size, frames) = (16, 0..16u32);
    let cube = || Scene::builtin("cube-in-box").unwrap();
    let ic_settings = IcSettings {
        spp: 16,
        strata: Strata { theta: 8, phi: 24 },
        ..IcSettings::default()
    };
    let mut reference = renderer(cube(), size, 24.0, true);
    let mut path = PathTracer::new(PathSettings {
        spp: 256,
        ..PathSettings::default()
    });
    let reference: Vec<Film> = frames
        .clone()
        .map(|f| reference.with_frame_context(f, |ctx| path.render_frame(ctx)))
        .collect();

    let mut r = renderer(cube(), size, 24.0, false);
    let mut ic = IrradianceCaching::new(ic_settings.clone());
    let mut ic_records = 0;
    let ic_frames: Vec<Film> = frames
        .clone()
        .map(|f| {
            let film = r.with_frame_context(f, |ctx| ic.render_frame(ctx));
            ic_records += ic.last_frame_stats().records_created;
            film
        })
        .collect();
    let mut trc = TemporalRadianceCaching::new(TrcSettings {
        ic: ic_settings,
        ..TrcSettings::default()
    });
    let mut trc_records = 0;
    let trc_frames: Vec<Film> = frames
        .clone()
        .map(|f| {
            let film = render_trc(&mut r, &mut trc, f);
            let s = trc.last_frame_stats();
            trc_records += s.records_created + s.records_replaced;
            film
        })
        .collect();
    let ic_flicker = flicker(&ic_frames, &reference).unwrap();
    let trc_flicker = flicker(&trc_frames, &reference).unwrap();
    eprintln!(
        "records: ic {ic_records}, trc {trc_records}; flicker: ic {ic_flicker:.4}, trc {trc_flicker:.4}"
    );
    assert!(
        trc_records * 3 < ic_records,
        "{trc_records} vs {ic_records}"
    );
    assert!(trc_flicker < ic_flicker, "{trc_flicker} vs {ic_flicker}");
}
