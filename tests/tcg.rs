//! `tcg` (temporally coherent final gathering, Tawara et al. 2004): records
//! that keep their samples and shoot a share of them again each frame
//! (Eq. 2, ages), records that move with their object (§4.1), a light
//! switched off or moving (with and without `light_refresh`), a block that
//! jumps away (the adaptive share of Eq. 2 against a uniform one) or in
//! (with and without `occlusion_refresh`, with and without `arrivals`),
//! or grows, and accuracy and flicker against `ic` and a converged
//! reference.

mod common;

use common::{
    arriving_block_room, converged_sequence, courtyard_under_a_swinging_light, inward_box,
    jumping_block_room, lit_room, push_quad, region_error, scaling_block_room, scene,
};
use glam::{Quat, Vec3, Vec4};
use radcache::backend::cpu::CpuBackend;
use radcache::cache::gather::Strata;
use radcache::film::Film;
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::tcg::{TcgSettings, TemporallyCoherentGathering};
use radcache::method::Method;
use radcache::metrics::{block_bias, flicker, rel_rmse};
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::{Channel, Interpolation, Material, Mesh, Property, Scene};
use radcache::store::PackedSample;

fn renderer(scene: Scene, size: u32, same_pattern: bool) -> Renderer {
    Renderer::new(
        scene,
        Box::new(PathTracer::new(PathSettings::default())),
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: size,
            height: size,
            same_pattern,
            ..FrameSettings::default()
        },
    )
}

fn small(spp: u32) -> TcgSettings {
    TcgSettings {
        ic: IcSettings {
            spp,
            strata: Strata { theta: 8, phi: 24 },
            ..IcSettings::default()
        },
        ..TcgSettings::default()
    }
}

fn render(r: &mut Renderer, tcg: &mut TemporallyCoherentGathering, frame: u32) -> Film {
    r.with_frame_context(frame, |ctx| tcg.render_frame(ctx))
}

/// `tcg` with `settings` over `scene`'s frames `0..against.len()` at
/// `size`, each frame's [`region_error`] against `against`'s.
fn region_errors(scene: Scene, size: u32, settings: TcgSettings, against: &[Film]) -> Vec<f64> {
    let mut r = renderer(scene, size, true);
    let mut tcg = TemporallyCoherentGathering::new(settings);
    (0u32..)
        .zip(against)
        .map(|(f, film)| region_error(&render(&mut r, &mut tcg, f), film))
        .collect()
}

/// `settings` under the paper's rule for lights (`light_refresh` off).
fn without_light_refresh(settings: TcgSettings) -> TcgSettings {
    TcgSettings {
        light_refresh: false,
        ..settings
    }
}

/// `tcg` with `settings` over frames `0..frames` of `scene` at `size`: the
/// block bias (8-pixel blocks) of the last against `path` at 256 spp, the
/// mean over eight seeds. At these sizes one seed's bias is mostly its
/// records' noise: in a room under a still light the eight gave 0.007 to
/// 0.021.
fn last_frame_bias(
    scene: impl Fn() -> Scene,
    frames: u32,
    size: u32,
    settings: TcgSettings,
) -> f64 {
    const SEEDS: [u64; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
    let reference = converged_sequence(scene(), size, 0..frames);
    let last = frames as usize - 1;
    let bias_with = |seed: u64| {
        let mut r = renderer(scene(), size, false);
        r.settings.seed = seed;
        let mut tcg = TemporallyCoherentGathering::new(settings.clone());
        let films: Vec<Film> = (0..frames).map(|f| render(&mut r, &mut tcg, f)).collect();
        block_bias(&films[last], &reference[last], 8)
    };
    SEEDS.iter().map(|&seed| bias_with(seed)).sum::<f64>() / SEEDS.len() as f64
}

/// The age of the oldest sample of `tcg`'s records, in frames.
fn oldest_sample(tcg: &TemporallyCoherentGathering) -> u32 {
    tcg.records()
        .iter()
        .flat_map(|r| &r.samples)
        .map(|s| s.age())
        .max()
        .unwrap_or(0)
}

/// Every frame after the first, each record that lived on shot exactly
/// Eq. 2's number of cells again, `⌈(τ_max − τ_min)·x + τ_min·N⌉` with `x`
/// its samples that hit a moving object before the frame: those are its
/// samples of age 0 after it, the others one frame older. In a static
/// scene no record is made after frame 0, and over 2/τ_min frames every
/// sample is shot again (the draw favours the old ones, ∝ 2^age). The
/// paper's `x` (`occlusion_refresh` off: no sample counts for the cube
/// moving into its path; its light stands still).
#[test]
fn records_shoot_again_the_share_of_equation_2_oldest_first() {
    for scene in [Scene::builtin("cube-in-box").unwrap(), lit_room(None, 24.0)] {
        let is_static = scene.animation.channels.is_empty();
        let settings = TcgSettings {
            occlusion_refresh: false,
            ..small(1)
        };
        let mut r = renderer(scene, 12, false);
        let mut tcg = TemporallyCoherentGathering::new(settings.clone());
        let _ = render(&mut r, &mut tcg, 0);
        let cells = settings.ic.strata.count();
        let mut checked = 0;
        for f in 1..(2.0 / settings.tau_min) as u32 {
            let before: std::collections::HashMap<u64, Vec<_>> = tcg
                .records()
                .iter()
                .map(|r| (r.record.id, r.samples.clone()))
                .collect();
            let _ = render(&mut r, &mut tcg, f);
            let stats = tcg.last_frame_stats();
            if is_static {
                assert_eq!(stats.records_created, 0, "frame {f}");
            }
            // Every record in memory holds its 8-byte samples.
            let held = (tcg.records().len() * cells * PackedSample::BYTES) as u64;
            assert!(stats.cache_bytes > held, "frame {f}: {stats:?}");
            let mut reshot = 0;
            for rec in tcg.records() {
                let Some(old) = before.get(&rec.record.id) else {
                    continue;
                };
                let x = old.iter().filter(|s| s.hit_dynamic()).count() as f32;
                let want = ((settings.tau_max - settings.tau_min) * x
                    + settings.tau_min * cells as f32)
                    .ceil()
                    .min(cells as f32) as usize;
                let fresh = rec.samples.iter().filter(|s| s.age() == 0).count();
                assert_eq!(fresh, want, "frame {f} record {}", rec.record.id);
                reshot += want as u64;
                for (new, old) in rec.samples.iter().zip(old) {
                    let aged = new.age() == old.age() + 1;
                    assert!(new.age() == 0 || aged, "{new:?} after {old:?}");
                }
                checked += 1;
            }
            // The frame's statistics count those shots (records that did
            // not live on shot nothing).
            assert_eq!(stats.samples_reshot, reshot, "frame {f}");
        }
        assert!(checked > 0);
        if is_static {
            // Ages count frames since each sample was shot (above, frame
            // by frame, past 15 too): none is much older than the frames
            // it takes to go round once (the paper's Fig. 6: at most 14
            // frames where 10 go round). Ages that stopped at 15 left up
            // to twice that.
            let oldest = oldest_sample(&tcg);
            let round = (1.0 / settings.tau_min).ceil() as u32;
            assert!(oldest <= round * 3 / 2, "a sample {oldest} frames old");
            eprintln!("oldest sample: {oldest} frames (a round is {round})");
        }
    }
}

/// A block that slides and turns over a floor (§4.1): the records on it
/// stay on its surface, with its normal, frame after frame.
#[test]
fn records_on_a_moving_object_move_with_it() {
    let materials = vec![Material::diffuse("white", Vec3::splat(0.7))];
    let room = inward_box(Vec3::new(-1.5, 0.0, -1.5), Vec3::new(1.5, 2.0, 1.5), 0);
    let mut block = Mesh::default();
    let (lo, d) = (Vec3::new(-0.3, -0.3, -0.3), 0.6);
    let (x, y, z) = (Vec3::X * d, Vec3::Y * d, Vec3::Z * d);
    push_quad(&mut block, lo, x, z, 0); // faces -y
    push_quad(&mut block, lo + y, z, x, 0); // faces +y
    push_quad(&mut block, lo, y, x, 0); // faces -z
    push_quad(&mut block, lo + z, x, y, 0); // faces +z
    push_quad(&mut block, lo, z, y, 0); // faces -x
    push_quad(&mut block, lo + x, y, z, 0); // faces +x
    let turn = |a: f32| Vec4::from(Quat::from_rotation_y(a).to_array());
    let channels = vec![
        Channel {
            node: 1,
            property: Property::Translation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0],
            values: vec![
                Vec4::new(-0.4, 0.5, 0.0, 0.0),
                Vec4::new(0.4, 0.5, 0.0, 0.0),
            ],
        },
        Channel {
            node: 1,
            property: Property::Rotation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0],
            values: vec![turn(0.0), turn(1.2)],
        },
    ];
    let mut s = scene(
        vec![room, block],
        materials,
        channels,
        Vec3::new(0.0, 1.2, 1.4),
        Vec3::new(0.0, -0.5, -1.0),
        1.0,
        vec![(Vec3::new(0.0, 1.8, 0.5), Vec3::splat(2.0))],
    );
    s.frame_count = 24;
    let mut r = renderer(s, 16, false);
    let mut tcg = TemporallyCoherentGathering::new(small(1));
    let mut on_block = 0;
    for f in 0..6 {
        let _ = render(&mut r, &mut tcg, f);
        let snapshot = r.scene.snapshot(f as f32 / r.settings.fps);
        for rec in tcg.records().iter().map(|r| &r.record) {
            if rec.object != 1 || rec.created_frame == f {
                continue;
            }
            on_block += 1;
            let on_face = snapshot
                .triangles
                .iter()
                .zip(&snapshot.tri_object)
                .filter(|(_, &o)| o == 1)
                .any(|(tri, _)| {
                    let n = tri.geometric_normal();
                    let plane = n.dot(rec.position - tri.p[0]).abs();
                    // Its point lies off the face by up to a thousandth of
                    // its least radius, towards the camera that saw it
                    // (`ic::off_the_edge`), so of its radius.
                    let off = 1e-4 + 1e-3 * rec.radius;
                    plane < off && n.dot(rec.normal) > 0.9999 && inside(tri.p, rec.position)
                });
            assert!(on_face, "frame {f}: record {} left the block", rec.id);
        }
    }
    assert!(on_block > 10, "{on_block} record-frames on the block");
}

/// Whether `p` (in the triangle's plane) lies inside triangle `v`, up to
/// a small tolerance.
fn inside(v: [Vec3; 3], p: Vec3) -> bool {
    let n = (v[1] - v[0]).cross(v[2] - v[0]);
    (0..3).all(|i| {
        let (a, b) = (v[i], v[(i + 1) % 3]);
        (b - a).cross(p - a).dot(n) >= -1e-5
    })
}

/// A light switched off at frame k, as the paper has it
/// (`light_refresh` off): the samples that saw its light are shot again a
/// share a frame, oldest first in probability (∝ 2^age), since they hit
/// no moving object (the walls stay). The indirect light lags behind the
/// switch (the paper's age-driven update, where lighting changes without a
/// moving object in view of the records), and is gone in the first frame
/// in which every sample was shot after the switch (its age at frame f at
/// most f − k), which comes within 3/τ_min frames (the paper measured the
/// oldest sample at 1.4/τ_min, its Fig. 6).
#[test]
fn a_switched_off_light_leaves_no_indirect_light_once_every_sample_is_shot_again() {
    let k = 2u32;
    let settings = TcgSettings {
        tau_min: 0.25,
        light_refresh: false,
        ..small(1)
    };
    let rounds = (3.0 / settings.tau_min).ceil() as u32;
    let mut r = renderer(lit_room(Some(k), 24.0), 12, false);
    let mut tcg = TemporallyCoherentGathering::new(settings);
    let mut means = Vec::new();
    let mut all_shot_since = None;
    for f in 0..k + rounds {
        means.push(render(&mut r, &mut tcg, f).mean());
        let oldest = oldest_sample(&tcg);
        if f >= k && oldest <= f - k {
            all_shot_since.get_or_insert(f);
        }
    }
    eprintln!("mean radiance per frame: {means:?}; all shot again at {all_shot_since:?}");
    assert!(means[0] > 0.0);
    assert!(
        means[k as usize + 1] > 0.0,
        "no lag: the test proves nothing"
    );
    let clean = all_shot_since.expect("some sample never shot again") as usize;
    for (f, m) in means.iter().enumerate().skip(clean) {
        assert!(*m == 0.0, "indirect light left at frame {f}: {m}");
    }
}

/// The same switch with `light_refresh` on (the default): the lights'
/// power fell, so every sample shot before the switch is stale and shot
/// again in the switch's own frame, and no indirect light is left from it
/// on.
#[test]
fn a_switched_off_light_leaves_at_once_with_light_refresh() {
    let k = 2u32;
    let mut r = renderer(lit_room(Some(k), 24.0), 12, false);
    let mut tcg = TemporallyCoherentGathering::new(small(1));
    let means: Vec<f64> = (0..k + 4)
        .map(|f| render(&mut r, &mut tcg, f).mean())
        .collect();
    assert!(means[..k as usize].iter().all(|&m| m > 0.0), "{means:?}");
    for (f, m) in means.iter().enumerate().skip(k as usize) {
        assert!(*m == 0.0, "indirect light left at frame {f}: {m}");
    }
}

/// A light that moves (the room's ceiling panel carried 1.2 m over 8
/// frames): the samples whose direct light it changed are shot again as it
/// moves, so `tcg`'s block bias at the last frame stays that of the same
/// room under a still light, where the paper's rule (`light_refresh` off)
/// lags the light. Measured (means of eight seeds, 2026-12-07): 0.0153
/// with the rule, 0.0482 without, 0.0144 under a still light; with one
/// seed (2026-12-02) 0.022 with the rule before its bound over every
/// normal and its neighbours across edges.
#[test]
fn a_moving_light_is_followed_with_light_refresh() {
    let frames = 10u32;
    let scene = |moves: bool| {
        let mut s = lit_room(None, 24.0);
        if !moves {
            return s;
        }
        s.animation.channels.push(Channel {
            node: 1,
            property: Property::Translation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 8.0 / 24.0],
            values: vec![
                Vec4::new(-0.6, 0.0, 0.0, 0.0),
                Vec4::new(0.6, 0.0, 0.0, 0.0),
            ],
        });
        s
    };
    let bias_of =
        |moves: bool, settings: TcgSettings| last_frame_bias(|| scene(moves), frames, 16, settings);
    let following = bias_of(true, small(4));
    let lagging = bias_of(true, without_light_refresh(small(4)));
    let still = bias_of(false, small(4));
    eprintln!(
        "block bias at the last frame: {following:.4} with light_refresh, {lagging:.4} without, \
         {still:.4} under a still light"
    );
    assert!(
        following * 1.5 < lagging,
        "light_refresh: {following}, without: {lagging}"
    );
    assert!(
        following < 1.25 * still,
        "light_refresh: {following}, a still light: {still}"
    );
}

/// Over 16 frames of cube-in-box, `tcg` computes far fewer gather rays
/// than `ic`, flickers less, and is as accurate against a converged
/// reference (within 10 % of `ic`'s relative RMSE).
#[test]
fn tcg_traces_fewer_rays_flickers_less_and_is_as_accurate_as_ic() {
    let (size, frames) = (16, 0..16u32);
    let cube = || Scene::builtin("cube-in-box").unwrap();
    let settings = small(16);
    let reference = converged_sequence(cube(), size, frames.clone());

    let mut r = renderer(cube(), size, false);
    let mut ic = IrradianceCaching::new(settings.ic.clone());
    let ic_frames: Vec<Film> = frames
        .clone()
        .map(|f| r.with_frame_context(f, |ctx| ic.render_frame(ctx)))
        .collect();
    let ic_rays = r.backend().ray_counts().total();
    let mut tcg = TemporallyCoherentGathering::new(settings);
    let tcg_frames: Vec<Film> = frames
        .clone()
        .map(|f| render(&mut r, &mut tcg, f))
        .collect();
    let tcg_rays = r.backend().ray_counts().total() - ic_rays;
    let error = |films: &[Film]| -> f64 {
        films
            .iter()
            .zip(&reference)
            .map(|(a, b)| rel_rmse(a, b))
            .sum::<f64>()
            / films.len() as f64
    };
    let (ic_error, tcg_error) = (error(&ic_frames), error(&tcg_frames));
    let ic_flicker = flicker(&ic_frames, &reference).unwrap();
    let tcg_flicker = flicker(&tcg_frames, &reference).unwrap();
    eprintln!(
        "rays: ic {ic_rays}, tcg {tcg_rays}; rel. RMSE ic {ic_error:.4}, tcg {tcg_error:.4}; \
         flicker ic {ic_flicker:.4}, tcg {tcg_flicker:.4}"
    );
    assert!(tcg_rays * 2 < ic_rays, "{tcg_rays} vs {ic_rays}");
    assert!(tcg_error < 1.1 * ic_error, "{tcg_error} vs {ic_error}");
    assert!(tcg_flicker < ic_flicker, "{tcg_flicker} vs {ic_flicker}");
}

/// Fast motion (stability where the method may fail): a red block in the
/// room's corner jumps out of the room at frame k. A record's samples that
/// hit the block are flagged as hitting a moving object, so Eq. 2 shoots
/// every one of them again at frame k (`τ_max = 1`): the block's light
/// leaves the records at once, where a uniform share (`τ_max = τ_min`)
/// takes about `1/τ_min` frames (the paper's Fig. 7: the uniform update
/// leaves an incorrect shadow near a moving ball, the adaptive one does
/// not). Measured near the block's old place against `ic` with the same
/// spatial settings at the same frames (a fresh cache every frame has no
/// temporal error): from frame k on the adaptive update's difference is
/// under 0.7× the uniform one's, and from frame k + 1 on below the largest
/// difference before the jump (records at other points with other random
/// streams): the ghost is gone.
#[test]
fn a_block_that_jumps_away_leaves_no_ghost() {
    let (k, size, fps) = (3u32, 16u32, 24.0);
    let frames = 0..k + 4;
    let mut reference = renderer(jumping_block_room(k, fps), size, true);
    let mut ic = IrradianceCaching::new(small(2).ic);
    let ic_films: Vec<Film> = frames
        .clone()
        .map(|f| reference.with_frame_context(f, |ctx| ic.render_frame(ctx)))
        .collect();
    let errors = |settings| region_errors(jumping_block_room(k, fps), size, settings, &ic_films);
    let adaptive = errors(small(2));
    let uniform = errors(TcgSettings {
        tau_max: 0.05,
        ..small(2)
    });
    eprintln!("near the block against ic: adaptive {adaptive:.4?}, uniform {uniform:.4?}");
    let before = adaptive[..k as usize].iter().copied().fold(0.0, f64::max);
    for f in k as usize..adaptive.len() {
        assert!(
            adaptive[f] < 0.7 * uniform[f],
            "frame {f}: adaptive {} against uniform {}",
            adaptive[f],
            uniform[f]
        );
        if f > k as usize {
            assert!(
                adaptive[f] < before,
                "frame {f}: a ghost of {} (before the jump {before})",
                adaptive[f]
            );
        }
    }
}

/// Fast motion the other way: the red block jumps into the room's corner
/// at frame k. The records near the corner saw the walls and floor past
/// the block's place, and none of their samples hit a moving object, so
/// under the paper's Eq. 2 (`occlusion_refresh` off) only `τ_min` of them
/// are shot again a frame and the block's shadow and red light come in
/// over many frames. With `occlusion_refresh` on the samples
/// whose path the block's box now crosses count in `x` and are shot again
/// at frame k, and the records the block buried are dropped. Measured near
/// the block against a converged reference: at frame k the error is under
/// half the paper's rule's and within 1.5× `ic`'s (a fresh cache), at
/// frame k + 1 under 0.7× the paper's rule's. (What is left, the block's
/// direct shadow on the surfaces the samples hit, comes in at `τ_min`:
/// `tcg::crossed`.)
#[test]
fn a_block_that_jumps_in_casts_its_indirect_light_at_once() {
    let (k, size, fps) = (3u32, 16u32, 24.0);
    let frames = 0..k + 2;
    let reference = converged_sequence(arriving_block_room(k, fps), size, frames.clone());
    let mut r = renderer(arriving_block_room(k, fps), size, true);
    let mut ic = IrradianceCaching::new(small(2).ic);
    let ic_error: Vec<f64> = frames
        .clone()
        .map(|f| {
            region_error(
                &r.with_frame_context(f, |ctx| ic.render_frame(ctx)),
                &reference[f as usize],
            )
        })
        .collect();
    let errors = |settings| region_errors(arriving_block_room(k, fps), size, settings, &reference);
    // `arrivals` off in both: this is `crossed`'s test.
    let refreshed = errors(TcgSettings {
        occlusion_refresh: true,
        arrivals: false,
        ..small(2)
    });
    let lagging = errors(TcgSettings {
        occlusion_refresh: false,
        arrivals: false,
        ..small(2)
    });
    eprintln!(
        "near the block against the reference: refreshed {refreshed:.4?}, the paper's rule \
         {lagging:.4?}, ic {ic_error:.4?}"
    );
    let k = k as usize;
    assert!(
        refreshed[k] < 0.5 * lagging[k] && refreshed[k] < 1.5 * ic_error[k],
        "frame {k}: refreshed {}, the paper's rule {}, ic {}",
        refreshed[k],
        lagging[k],
        ic_error[k]
    );
    assert!(
        refreshed[k + 1] < 0.7 * lagging[k + 1],
        "frame {}: refreshed {}, the paper's rule {}",
        k + 1,
        refreshed[k + 1],
        lagging[k + 1]
    );
}

/// Objects that come into records' view (`tcg::arrived`): the red block
/// jumps into the room's corner at frame k, or grows there from nothing
/// over frames k−1 … k+1. No sample of the records near the corner hit
/// it, so under the paper's rule (`arrivals` off) its light and the
/// shadows of their samples' hits come in at `τ_min` a frame. With the
/// records whose paths it newly crosses dropped and made again, the
/// corner's bias against a converged reference stays within 1.5× `ic`'s
/// (a fresh cache every frame) + 0.01 from frame k on, where the paper's
/// rule is off by more than twice `ic`'s at frame k + 1.
#[test]
fn a_block_that_jumps_in_or_grows_is_seen_at_once() {
    let (k, size, fps) = (2u32, 16u32, 24.0);
    let frames = 0..k + 4;
    let corner = (Vec3::new(-0.95, 0.0, -0.95), Vec3::new(-0.2, 1.0, -0.2));
    let red = Vec3::new(0.9, 0.1, 0.1);
    let keys = [(k as f32 - 1.0, 0.0), (k as f32 + 1.0, 1.0)];
    let scenes: [(&str, &dyn Fn() -> Scene); 2] = [
        ("jumps in", &|| arriving_block_room(k, fps)),
        ("grows", &|| scaling_block_room(corner, red, fps, &keys)),
    ];
    for (what, scene) in scenes {
        let reference = converged_sequence(scene(), size, frames.clone());
        let mut r = renderer(scene(), size, true);
        let mut ic = IrradianceCaching::new(small(2).ic);
        let ic: Vec<f64> = (frames.clone().zip(&reference))
            .map(|(f, path)| {
                region_error(&r.with_frame_context(f, |ctx| ic.render_frame(ctx)), path)
            })
            .collect();
        let errors = |arrivals| {
            let settings = TcgSettings {
                arrivals,
                ..small(2)
            };
            region_errors(scene(), size, settings, &reference)
        };
        let (seen, lagging) = (errors(true), errors(false));
        eprintln!("{what}: arrivals {seen:.4?}, the paper's rule {lagging:.4?}, ic {ic:.4?}");
        let f = k as usize + 1;
        assert!(
            lagging[f] > 2.0 * ic[f],
            "{what}: the paper's rule at frame {f} ({}) is as good as ic ({}): the test \
             proves nothing",
            lagging[f],
            ic[f]
        );
        for f in k as usize..frames.end as usize {
            assert!(
                seen[f] < 1.5 * ic[f] + 0.01,
                "{what}: frame {f} off by {} near the block (ic {}, the paper's rule {})",
                seen[f],
                ic[f],
                lagging[f]
            );
        }
    }
}

/// A light that swings across the sky at the same distance from
/// everything it lights ([`courtyard_under_a_swinging_light`]): the light
/// arriving at a hit from it changes in direction only, and a surface's
/// irradiance with it. The samples whose hits it turned towards or away
/// from are shot again (`tcg::stale` bounds the change on a surface of any
/// normal), and the cells beside them (`select::with_neighbours`: else a
/// cell across a wall's top edge drifts to the sky, which is not stale).
/// At the last frame `tcg`'s block bias is within 1.15× that of shooting
/// every sample again every frame (`τ_min = 1`, the brute-force update)
/// and 1.5× that under the light held still there; with the paper's rule
/// (`light_refresh` off) the walls' light lags the light. Measured
/// (means of eight seeds, 2026-12-07): 0.0191, 0.0271 with every sample
/// shot again, 0.0275 under a still light, 0.2166 with the paper's rule;
/// with one seed (2026-12-02) 0.476 when only the light arriving from
/// every direction was tested, and 0.087 with the bound but not the
/// neighbours.
#[test]
fn a_light_that_swings_at_the_same_distance_is_followed() {
    let frames = 10u32;
    let bias_of = |swings: bool, settings: TcgSettings| {
        let scene = || courtyard_under_a_swinging_light(frames, swings);
        last_frame_bias(scene, frames, 16, settings)
    };
    let following = bias_of(true, small(4));
    let every_sample = bias_of(
        true,
        TcgSettings {
            tau_min: 1.0,
            ..small(4)
        },
    );
    let lagging = bias_of(true, without_light_refresh(small(4)));
    let still = bias_of(false, small(4));
    eprintln!(
        "block bias at the last frame: {following:.4} with light_refresh, {every_sample:.4} \
         shooting every sample again, {lagging:.4} without, {still:.4} under a still light"
    );
    assert!(
        following < 1.15 * every_sample,
        "light_refresh: {following}, every sample shot again: {every_sample}"
    );
    assert!(
        following < 1.5 * still,
        "light_refresh: {following}, a still light: {still}"
    );
    assert!(
        2.0 * following < lagging,
        "light_refresh: {following}, without: {lagging}"
    );
}
