//! `trc` (temporal radiance caching, TVCG 2007): record lifespans in a
//! static scene, the reprojected estimate of E(t0+1) (Table 1), ghosts of a
//! light switched off and of a jumping object, objects moving over records,
//! a moving camera, rooms seen from behind their normals, and records
//! computed and flicker against `ic`.

mod common;

use common::{
    add_moving_block, add_static_object, arriving_block_room, converged_sequence, inward_box,
    jumping_block_room, lit_room, outward_box, push_quad, region_error, scaling_block_room, scene,
};
use glam::{Vec3, Vec4};
use radcache::backend::cpu::CpuBackend;
use radcache::cache::gather::Strata;
use radcache::cache::IrradianceRecord;
use radcache::film::Film;
use radcache::integrator::PathLength;
use radcache::method::ic::{GlossyLobe, IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::render_pass::PixelStreams;
use radcache::method::trc::estimate_error::{estimate_errors, mean_and_median, percent};
use radcache::method::trc::{
    NextDirect, TemporalGradients, TemporalRadianceCaching, TemporalRecord, TrcSettings,
};
use radcache::method::Method;
use radcache::metrics::{block_bias, flicker, rel_rmse};
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::{Channel, Interpolation, Material, Mesh, Property, Scene};
use std::mem::size_of;

/// Every temporal gradient mode (TRC §4.5).
const GRADIENT_MODES: [TemporalGradients; 3] = [
    TemporalGradients::None,
    TemporalGradients::Extrapolated,
    TemporalGradients::Interpolated,
];

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

fn render_trc(r: &mut Renderer, trc: &mut TemporalRadianceCaching, frame: u32) -> Film {
    r.with_frame_context(frame, |ctx| trc.render_frame(ctx))
}

/// The records of a default `trc` (1 spp) that rendered frame `t0` alone,
/// and their irradiance gathered again at `t0 + 1` with their own random
/// streams (unchanged samples cancel): the actual `E(t0+1)` their
/// estimates are measured against.
fn records_and_their_next_frame(r: &mut Renderer, t0: u32) -> (Vec<TemporalRecord>, Vec<Vec3>) {
    let ic = IcSettings {
        spp: 1,
        ..IcSettings::default()
    };
    records_and_their_next_frame_with(r, t0, ic)
}

/// [`records_and_their_next_frame`] with records made by `ic`.
fn records_and_their_next_frame_with(
    r: &mut Renderer,
    t0: u32,
    ic: IcSettings,
) -> (Vec<TemporalRecord>, Vec<Vec3>) {
    records_and_their_next_frame_by(
        r,
        t0,
        TrcSettings {
            ic,
            ..TrcSettings::default()
        },
    )
}

/// [`records_and_their_next_frame`] with records made by `trc` with
/// `settings`.
fn records_and_their_next_frame_by(
    r: &mut Renderer,
    t0: u32,
    settings: TrcSettings,
) -> (Vec<TemporalRecord>, Vec<Vec3>) {
    let mut trc = TemporalRadianceCaching::new(settings);
    let _ = render_trc(r, &mut trc, t0);
    let records = trc.records().to_vec();
    let next = r.with_frame_context(t0 + 1, |ctx| trc.regather(ctx, &records));
    (records, next)
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
    static_records_live_max_life(lit_room(None, 24.0), small_ic(), true);
    static_records_live_max_life(lit_room(None, 24.0), small_ic(), false);
}

/// The same with radiance records (`--ic-glossy eas`) in a glossy room:
/// no source changes either (TRC Eq. 21 over the sources gives τ = 1), so
/// they live `δt_max` frames too, their sources carried unchanged (zero
/// temporal gradients), and each replacement gathers the sources of the
/// record it replaces.
#[test]
fn static_scene_radiance_records_live_max_life_and_frames_match_ic() {
    let mut room = lit_room(None, 24.0);
    room.materials[0] = Material::glossy("glossy", Vec3::splat(0.4), Vec3::splat(0.3), 60.0);
    let ic = IcSettings {
        glossy: GlossyLobe::Eas,
        ..small_ic()
    };
    static_records_live_max_life(room, ic, true);
}

/// [`static_scene_records_live_max_life_and_frames_match_ic`] in `scene`
/// (static) with records made by `ic`, replacements taking the paths of
/// the records they replace or not (`keep_paths`).
fn static_records_live_max_life(scene: Scene, ic: IcSettings, keep_paths: bool) {
    let max_life = 4;
    let radiance_records = ic.glossy == GlossyLobe::Eas;
    let settings = TrcSettings {
        ic,
        max_life,
        keep_paths,
        ..TrcSettings::default()
    };
    let mut r = renderer(scene, 16, 24.0, false);
    let mut trc = TemporalRadianceCaching::new(settings.clone());
    let ic = IrradianceCaching::new(settings.ic.clone());
    let cache0 = r.with_frame_context(0, |ctx| ic.build_cache(ctx));
    let n = cache0.len() as u64;
    assert!(n > 4, "too few records ({n}) for the test to mean anything");
    for f in 0..max_life {
        let frame = render_trc(&mut r, &mut trc, f);
        let stats = trc.last_frame_stats();
        let expected = r.with_frame_context(f, |ctx| {
            ic.render_with_cache(ctx, &cache0, PixelStreams::Coherent)
        });
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
        assert_eq!(stats.samples_reshot, 0, "frame {f}: nothing replaced");
        // Each record is held twice (carried, and in the frame's cache).
        let record = size_of::<TemporalRecord>() + size_of::<IrradianceRecord>();
        assert!(stats.cache_bytes >= n * record as u64, "frame {f}");
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
        if radiance_records {
            let with_sources = trc.records().iter().filter(|k| k.record.eas.is_some());
            assert_eq!(with_sources.count() as u64, n, "every record is glossy");
            assert!(trc.records().iter().all(|k| k
                .d_eas
                .as_deref()
                .is_some_and(|d| d.iter().all(|d| *d == Vec3::ZERO))));
        }
    }
    let before: std::collections::HashMap<u64, TemporalRecord> = trc
        .records()
        .iter()
        .map(|k| (k.record.id, k.clone()))
        .collect();
    let _ = render_trc(&mut r, &mut trc, max_life);
    let stats = trc.last_frame_stats();
    assert_eq!(stats.records_reused, 0);
    assert_eq!(stats.records_replaced + stats.records_dropped, n);
    assert!(stats.records_replaced > 0);
    // A replacement shoots every ray of the record it replaces again; a
    // record dropped shoots none (no moving object to gather inside). With
    // kept paths nothing moves, so every path is taken. (While the
    // traversal missed hits nearer than 1e-4, paths with a segment under
    // 1e-3 were not kept, and the rays of records beside a room's edge
    // towards its other wall, 1.4 % of all paths here, were shot again.)
    let cells = settings.ic.strata.count() as u64;
    if keep_paths {
        assert_eq!(
            stats.samples_reshot, 0,
            "samples shot again, of {} records' {cells} each",
            stats.records_replaced
        );
    } else {
        assert_eq!(stats.samples_reshot, stats.records_replaced * cells);
    }
    let replacements: Vec<_> = trc
        .records()
        .iter()
        .filter(|k| k.replaces.is_some())
        .collect();
    assert!(replacements
        .iter()
        .all(|k| k.record.created_frame == max_life));
    // A replacement gathers with the random streams of the record it
    // replaces (`ic::first_stream`): nothing changed, so neither does its
    // value, though the frames' pixel streams differ (`same_pattern` off).
    for k in replacements {
        let old = &before[&k.replaces.unwrap()].record;
        assert_eq!(
            k.record.irradiance, old.irradiance,
            "record {}",
            k.record.id
        );
        assert_eq!(k.record.eas, old.eas, "record {}", k.record.id);
    }
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
    let mut seeing = (Vec::new(), Vec::new());
    for t0 in [5u32, 20] {
        let (records, actual) = records_and_their_next_frame(&mut r, t0);
        for (k, (reprojected, constant)) in records.iter().zip(estimate_errors(&records, &actual)) {
            errors.0.push(reprojected);
            errors.1.push(constant);
            if k.next_irradiance != k.record.irradiance {
                seeing.0.push(reprojected);
                seeing.1.push(constant);
            }
        }
    }
    if !seeing.0.is_empty() {
        let (a, b) = (
            mean_and_median(&mut seeing.0).unwrap(),
            mean_and_median(&mut seeing.1).unwrap(),
        );
        eprintln!(
            "records that see the moving cube: {}: reprojection {}, none {}",
            seeing.0.len(),
            percent(a),
            percent(b)
        );
    }
    let (mean_r, median_r) = mean_and_median(&mut errors.0).unwrap();
    let (mean_n, median_n) = mean_and_median(&mut errors.1).unwrap();
    eprintln!(
        "E(t0+1) error over {} records: reprojection {}, none {}",
        errors.0.len(),
        percent((mean_r, median_r)),
        percent((mean_n, median_n))
    );
    // With each sample's direct light evaluated again at t0+1, the
    // estimate also sees the cube's shadow move (`next_direct`).
    let mut with_direct = Vec::new();
    for t0 in [5u32, 20] {
        let settings = TrcSettings {
            ic: IcSettings {
                spp: 1,
                ..IcSettings::default()
            },
            next_direct: NextDirect::On,
            ..TrcSettings::default()
        };
        let (records, actual) = records_and_their_next_frame_by(&mut r, t0, settings);
        with_direct.extend(estimate_errors(&records, &actual).into_iter().map(|e| e.0));
    }
    let (mean_d, median_d) = mean_and_median(&mut with_direct).unwrap();
    eprintln!(
        "with the direct light at t0+1: {}",
        percent((mean_d, median_d))
    );
    assert!(mean_d <= 1.05 * mean_n, "mean {mean_d} vs {mean_n}");
    assert!(
        median_d <= 1.05 * median_n,
        "median {median_d} vs {median_n}"
    );
    // The paper's gain (Table 1: mean 2.9 % vs 3.7 %) is NOT reproduced
    // here. Measured (see the module docs of `trc`): the 62 of 276 records
    // whose samples see the moving cube change by ~1 % per frame (constant
    // estimate: mean 1.34 %), the others by 3.7 % on average — shadows
    // moving over what they see, or the record lying on the cube — which
    // neither estimate sees. Against a converged E(t0+1) (32×96 strata)
    // both estimates are at ~4.9 %: a record's own Monte Carlo noise
    // (16×48 cells, one path each) exceeds its change from one frame to the
    // next, where the paper's rasterized hemispheres have no noise. This
    // guards against reprojection making the estimate worse (before
    // cell-centre displacement it did, by 10 %). The median is the noisier
    // of the two: over these 285 records it came out 3 % above the
    // constant estimate's, and 6 % once the triangle test became
    // watertight (which moves every hit in its last bits, so every record
    // draws other noise); over frames 5, 12 and 20 it was 8 % above before
    // and 6 % after. So it is held to 10 %, the mean to 5 %.
    assert!(mean_r <= 1.05 * mean_n, "mean {mean_r} vs {mean_n}");
    assert!(
        median_r <= 1.10 * median_n,
        "median {median_r} vs {median_n}"
    );
}

/// A white block sliding across a white floor (0.1 m a frame) under a
/// point light, in a black room. Gathered with one bounce (the first hit's
/// direct light from the point light, no further path), every gather
/// sample is a function of its direction alone: E(t0+1) gathered again has
/// no Monte Carlo noise to hide the estimate's error in (the rasterized
/// hemispheres of the paper's Table 1 have none either).
fn sliding_block_under_point_light(fps: f32) -> Scene {
    let mut floor = Mesh::default();
    push_quad(
        &mut floor,
        Vec3::new(-1.5, 0.0, -1.5),
        Vec3::Z * 3.0,
        Vec3::X * 3.0,
        0,
    );
    let materials = vec![
        Material::diffuse("white", Vec3::splat(0.7)),
        Material::diffuse("black", Vec3::ZERO),
    ];
    let block = outward_box(Vec3::new(-0.15, 0.0, -0.15), Vec3::new(0.15, 0.3, 0.15), 0);
    // Black walls and ceiling (their own floor hidden under the white
    // one): they reflect nothing, and bound the records' distances.
    let room = inward_box(Vec3::new(-1.5, -0.01, -1.5), Vec3::new(1.5, 1.5, 1.5), 1);
    let slide = Channel {
        node: 1,
        property: Property::Translation,
        interpolation: Interpolation::Linear,
        times: vec![0.0, 10.0 / fps],
        values: vec![
            Vec4::new(-0.5, 0.0, 0.0, 0.0),
            Vec4::new(0.5, 0.0, 0.0, 0.0),
        ],
    };
    let mut s = scene(
        vec![floor, block, room],
        materials,
        vec![slide],
        Vec3::new(0.0, 1.4, 1.4),
        Vec3::new(0.0, -1.0, -1.0),
        1.0,
        vec![(Vec3::new(0.3, 1.2, 0.6), Vec3::splat(3.0))],
    );
    s.frame_count = 10;
    s
}

/// TRC Table 1 where nothing but the estimate can err: on
/// [`sliding_block_under_point_light`] reprojecting the block's samples
/// with its motion (§4.7) predicts E(t0+1) better than taking E constant,
/// in mean over the records (the paper: 2.9 % against 3.7 %), and
/// evaluating each sample's direct light again at t0+1 (the block's
/// shadow moves over the floor the records see; TRC §5's "incoming
/// lighting at time t+1 of each point visible") better still. Measured:
/// 22.1 % with the direct light at t0+1, 27.2 % without, 32.9 % constant
/// (the block's own records, whose points stay in the world while the
/// block leaves, err alike in all; at cb1a639, where the traversal finds
/// surfaces nearer than 1e-4: 22.6 % and 27.5 % before). The median is
/// not lowered (4.37 %, 4.34 %, 3.47 %; 4.52 % and 4.35 % before): over the floor records whose estimate reprojection
/// changes, the predicted change correlates 0.80 with the true one but is
/// 0.55 of it where it is large, and where the true change is small,
/// moving samples between cells adds an error of about its size (these
/// figures without the direct light at t0+1). Neither comes from the
/// comparison: against E(t0+1) gathered with 16× the rays (64 × 192) the
/// figures without it are 28.4 % / 4.41 % against 33.5 % / 3.79 %, and at
/// the paper's 64 × 64 cells the median is still not lowered (3.34 %
/// against 2.80 %). Splatting each moved sample over the cells its surface
/// patch covers at t0+1, rather than into one cell, did not help either
/// (28.4 % / 4.62 %; tried and not kept).
#[test]
fn reprojection_predicts_a_moving_block_better_than_constant_in_mean() {
    let fps = 6.0;
    let mut r = renderer(sliding_block_under_point_light(fps), 64, fps, false);
    let one_bounce = IcSettings {
        spp: 1,
        gather_length: PathLength {
            max_depth: Some(1),
            ..PathLength::default()
        },
        ..IcSettings::default()
    };
    // Per setting of `next_direct` (off, on), the errors of the estimates
    // and of the constant E.
    let mut reprojected = [Vec::new(), Vec::new()];
    let mut constant = Vec::new();
    for (k, next_direct) in [NextDirect::Off, NextDirect::On].into_iter().enumerate() {
        for t0 in [2u32, 5] {
            let settings = TrcSettings {
                ic: one_bounce.clone(),
                next_direct,
                ..TrcSettings::default()
            };
            let (records, actual) = records_and_their_next_frame_by(&mut r, t0, settings);
            assert!(
                actual.iter().any(|e| e.max_element() > 0.0),
                "no indirect light"
            );
            assert!(records.len() > 20, "{} records", records.len());
            // The moving shadow subtracts light from samples: never more
            // than they held.
            assert!(
                (records.iter()).all(|k| k.next_irradiance.min_element() >= 0.0),
                "a negative E(t0+1) estimate (next_direct {next_direct:?})"
            );
            for (r, c) in estimate_errors(&records, &actual) {
                reprojected[k].push(r);
                if next_direct == NextDirect::On {
                    constant.push(c);
                }
            }
        }
    }
    let [(mean_r, median_r), (mean_d, median_d)] =
        reprojected.map(|mut v| mean_and_median(&mut v).unwrap());
    let (mean_c, median_c) = mean_and_median(&mut constant).unwrap();
    eprintln!(
        "E(t0+1) error over {} records: reprojection with the direct light at t0+1 {}, \
         without it {}, constant {}",
        constant.len(),
        percent((mean_d, median_d)),
        percent((mean_r, median_r)),
        percent((mean_c, median_c))
    );
    assert!(mean_r < mean_c, "mean {mean_r} vs {mean_c}");
    assert!(mean_d < mean_r, "mean {mean_d} vs {mean_r}");
}

/// A block at rest until frame k − 1 that then slides 1 m over three
/// frames: the records of frame 0 see nothing move from t0 to t0+1 (τ = 1)
/// and the paper gives each of them δt_max frames. With reprojection
/// (`trc::later`) the frame the block first moves in departs from that
/// extrapolation: records that see the block change there by more than
/// a^t and end their life at k − 1 (others at a later frame of the
/// slide), and before it nothing departs, so none ends sooner. With the constant estimate all live δt_max frames.
#[test]
fn records_that_see_an_object_start_moving_end_their_life_before_it() {
    let (k, max_life, fps) = (3u32, 8u32, 24.0);
    let scene = || {
        let mut s = lit_room(None, fps);
        add_moving_block(
            &mut s,
            (Vec3::new(-0.95, 0.0, -0.95), Vec3::new(-0.2, 1.0, -0.2)),
            Vec3::new(0.9, 0.1, 0.1),
            Interpolation::Linear,
            (
                vec![0.0, (k - 1) as f32 / fps, (k + 2) as f32 / fps],
                vec![Vec4::ZERO, Vec4::ZERO, Vec4::new(1.0, 0.0, 0.0, 0.0)],
            ),
        );
        s
    };
    let last_frames = |reprojection| -> Vec<u32> {
        let mut r = renderer(scene(), 16, fps, false);
        let mut trc = TemporalRadianceCaching::new(TrcSettings {
            ic: small_ic(),
            max_life,
            reprojection,
            ..TrcSettings::default()
        });
        render_trc(&mut r, &mut trc, 0);
        trc.records().iter().map(|r| r.last_valid).collect()
    };
    let constant = last_frames(false);
    assert!(constant.iter().all(|&l| l == max_life - 1), "{constant:?}");
    let checked = last_frames(true);
    let ended = checked.iter().filter(|&&l| l == k - 1).count();
    eprintln!(
        "{ended} of {} records of frame 0 end at frame k − 1",
        checked.len()
    );
    assert!(
        ended > 0,
        "no record ended before the block moved: {checked:?}"
    );
    // Frames from k on depart; a record that changes little at k may end
    // at a later one, as the block goes on.
    assert!(
        checked.iter().all(|&l| l >= k - 1),
        "a life ended before anything departed: {checked:?}"
    );
}

/// A light switched off at frame k. With the constant estimate (no
/// reprojection) records created before k know nothing of it (τ = 1) and
/// keep its indirect light as a ghost, but every one has expired by
/// k + δt_max (Eq. 11). With reprojection (the default) the frames of a
/// record's life where the lights, still from t0 to t0+1, have changed are
/// checked (`trc::later`): its samples' light falls to nothing there, and
/// every record ends its life at k − 1. The room is lit by that light
/// only, so the reference from frame k on is black.
#[test]
fn switched_off_light_leaves_no_indirect() {
    let (k, max_life) = (3u32, 4u32);
    let means = |reprojection| -> Vec<f64> {
        let mut r = renderer(lit_room(Some(k), 24.0), 12, 24.0, false);
        let mut trc = TemporalRadianceCaching::new(TrcSettings {
            ic: small_ic(),
            max_life,
            reprojection,
            ..TrcSettings::default()
        });
        let means: Vec<f64> = (0..k + max_life + 2)
            .map(|f| render_trc(&mut r, &mut trc, f).mean())
            .collect();
        eprintln!("reprojection {reprojection}: mean radiance per frame: {means:?}");
        assert!(means[0] > 0.0);
        means
    };
    let constant = means(false);
    assert!(
        constant[k as usize] > 0.0,
        "no ghost at frame k: test proves nothing"
    );
    for (f, m) in constant.iter().enumerate().skip((k + max_life) as usize) {
        assert!(
            *m == 0.0,
            "constant estimate: indirect light left at frame {f}: {m}"
        );
    }
    for (f, m) in means(true).iter().enumerate().skip(k as usize) {
        assert!(
            *m == 0.0,
            "reprojection: indirect light left at frame {f}: {m}"
        );
    }
}

/// The same, with the light sliding from frame 0 on: the lights move from
/// t0 to t0+1, so τ extrapolates their motion, but a light switched off
/// later is not part of it: the check of later frames sees their power
/// change at k (`trc::later`), also for records that see only surfaces
/// the light lit, and every record ends its life at k − 1.
#[test]
fn a_moving_light_switched_off_leaves_no_indirect() {
    let (k, max_life, fps) = (3u32, 6u32, 24.0);
    let mut scene = lit_room(Some(k), fps);
    scene.animation.channels.push(Channel {
        node: 1,
        property: Property::Translation,
        interpolation: Interpolation::Linear,
        times: vec![0.0, 1.0],
        values: vec![Vec4::ZERO, Vec4::new(0.5, 0.0, 0.0, 0.0)],
    });
    let mut r = renderer(scene, 12, fps, false);
    let mut trc = TemporalRadianceCaching::new(TrcSettings {
        ic: small_ic(),
        max_life,
        ..TrcSettings::default()
    });
    let means: Vec<f64> = (0..k + 3)
        .map(|f| render_trc(&mut r, &mut trc, f).mean())
        .collect();
    assert!(means[0] > 0.0);
    for (f, m) in means.iter().enumerate().skip(k as usize) {
        assert!(
            *m == 0.0,
            "indirect light left at frame {f}: {m} ({means:?})"
        );
    }
}

/// A light switched on at frame k in a room it alone lights: before k
/// every record is black. With the constant estimate they stay black
/// (E = 0 changes by nothing) and frame k has the direct light only. With
/// reprojection the check of later frames sees the lights change at k,
/// where the records' hits, dark at t0, gain their reflection of the new
/// light (`estimate::light_change`): every record ends at k − 1 and frame
/// k is that of a render that starts there.
#[test]
fn switched_on_light_lights_the_records_at_once() {
    let (k, max_life, fps) = (3u32, 6u32, 24.0);
    let scene = || {
        let mut s = lit_room(None, fps);
        s.animation.channels.push(Channel {
            node: 1,
            property: Property::Scale,
            interpolation: Interpolation::Step,
            times: vec![0.0, (k as f32 - 0.5) / fps],
            values: vec![Vec4::ZERO, Vec4::new(1.0, 1.0, 1.0, 0.0)],
        });
        s
    };
    let mean_at_k = |reprojection, first: u32| -> f64 {
        let mut r = renderer(scene(), 12, fps, false);
        let mut trc = TemporalRadianceCaching::new(TrcSettings {
            ic: small_ic(),
            max_life,
            reprojection,
            ..TrcSettings::default()
        });
        let means: Vec<f64> = (first..=k)
            .map(|f| render_trc(&mut r, &mut trc, f).mean())
            .collect();
        if first == 0 {
            assert_eq!(means[0], 0.0, "the room is dark before k");
        }
        means[means.len() - 1]
    };
    let fresh = mean_at_k(true, k);
    let constant = mean_at_k(false, 0);
    let checked = mean_at_k(true, 0);
    eprintln!("mean at frame k: fresh {fresh}, constant {constant}, checked {checked}");
    assert!(
        constant < 0.9 * fresh,
        "the constant estimate's records held no darkness: test proves nothing"
    );
    assert!(
        (checked - fresh).abs() < 0.02 * fresh,
        "reprojection: frame k {checked} against {fresh} rendered afresh"
    );
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
    let reference = converged_sequence(cube(), size, frames.clone());

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

/// Ghosts (issue 5, "Stability where it fails"): a red block jumps out of
/// the room at frame k. Records created before k saw it; as nothing moved
/// in their next frame, τ = 1.
///
/// - With the constant estimate (no reprojection) they know nothing more,
///   keep its red indirect light after it left (a ghost near its old
///   place), each for less than δt_max frames (Eq. 11): from frame
///   k + δt_max − 1 on every record was gathered after the jump.
/// - With reprojection (the default) each is also reprojected to the
///   frames of its life whose motion departs from τ's extrapolation
///   (`trc::later`): the jump is one, their light changes there by more
///   than a^t, and their life ends at k − 1. No ghost at frame k.
///
/// The reference is `ic` with the same spatial settings at the same
/// frames, both with `--same-pattern` sampling: a fresh cache every frame
/// has no temporal error, and with the same accuracy, strata and pixel
/// samples it has the same spatial interpolation error and direct light, so
/// `trc − ic` isolates the temporal error (a path-traced reference would
/// add `ic`'s spatial bias, of the order of the ghost at this tiny size).
/// Checked for every temporal gradient mode.
#[test]
fn jumping_object_leaves_no_ghost() {
    let (k, max_life) = (2u32, 6u32);
    let frames = 0..k + max_life + 2;
    let scene = || jumping_block_room(k, 24.0);
    let ic_frames = same_pattern_ic(scene(), frames.clone());
    let errors = |gradients, reprojection| {
        let trc = (max_life, gradients, reprojection);
        region_errors_against(scene(), trc, frames.clone(), &ic_frames)
    };
    // Before the jump nothing moves, so every mode renders the same frames
    // with reprojection: a record whose life the jump ended is not
    // interpolated towards its replacement, which shows the room after it.
    let mut before_jump: Option<Vec<f64>> = None;
    for gradients in GRADIENT_MODES {
        // The ghost with the constant estimate: the records of frame 0
        // (τ = 1) live through frame δt_max − 1 = k + 3 with the block's
        // light. Interpolated gradients fade it towards the replacements
        // from frame k on.
        let constant = errors(gradients, false);
        let ghost = constant[k as usize];
        assert!(
            ghost > 0.03,
            "{gradients:?}: no ghost at frame k ({ghost}): the test proves nothing"
        );
        // What is left once every record is younger than the jump is the
        // difference between two record sets (other points, other random
        // streams): 10–20 % of the ghost here.
        let left = |errors: &[f64], from: u32, what: &str| {
            for (f, e) in errors.iter().enumerate().skip(from as usize) {
                assert!(
                    *e < 0.3 * ghost,
                    "{gradients:?}, {what}: ghost left at frame {f}: {e} (at k: {ghost})"
                );
            }
        };
        left(&constant, k + max_life, "constant estimate");
        let checked = errors(gradients, true);
        left(&checked, k, "reprojection");
        let before = before_jump.get_or_insert_with(|| checked[..k as usize].to_vec());
        assert_eq!(
            &checked[..k as usize],
            &before[..],
            "{gradients:?}: frames before the jump differ between modes"
        );
    }
}

/// The spatial settings of the ghost tests: `ic`'s, and `trc`'s records.
fn ghost_ic() -> IcSettings {
    IcSettings {
        spp: 2,
        strata: Strata { theta: 16, phi: 48 },
        ..small_ic()
    }
}

/// `ic` with [`ghost_ic`] over `frames` of `scene` at 16×16 and 24 fps,
/// with `--same-pattern` sampling: a fresh cache every frame has no
/// temporal error, so against it `trc` with the same spatial settings
/// shows its temporal error alone.
fn same_pattern_ic(scene: Scene, frames: std::ops::Range<u32>) -> Vec<Film> {
    let mut r = renderer(scene, 16, 24.0, true);
    let mut ic = IrradianceCaching::new(ghost_ic());
    frames
        .map(|f| r.with_frame_context(f, |ctx| ic.render_frame(ctx)))
        .collect()
}

/// `trc` with [`ghost_ic`]'s records, `δt_max`, gradients and
/// reprojection as given and its other settings the defaults, over
/// `frames` of `scene` as [`same_pattern_ic`] renders it: per frame, the
/// [`region_error`] against `reference`'s frame.
fn region_errors_against(
    scene: Scene,
    (max_life, gradients, reprojection): (u32, TemporalGradients, bool),
    frames: std::ops::Range<u32>,
    reference: &[Film],
) -> Vec<f64> {
    let trc = TemporalRadianceCaching::new(TrcSettings {
        ic: ghost_ic(),
        max_life,
        gradients,
        reprojection,
        ..TrcSettings::default()
    });
    let mut r = Renderer::new(
        scene,
        Box::new(trc),
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: 16,
            height: 16,
            fps: 24.0,
            same_pattern: true,
            ..FrameSettings::default()
        },
    );
    r.set_frame_end(Some(frames.end));
    let errors: Vec<f64> = frames
        .map(|f| region_error(&r.render_frame(f), &reference[f as usize]))
        .collect();
    eprintln!(
        "{gradients:?}, reprojection {reprojection}: bias near the block per frame: {errors:.4?}"
    );
    errors
}

/// The other way round: a red block that jumps into the room's corner
/// from under the floor at frame k, and one that grows there from nothing
/// over frames k−1 … k+1. No record made before k saw the block (it lay
/// outside the room, or had no size), so no sample of theirs is reprojected
/// onto it, and the paper's estimate (τ = 1) gives them δt_max frames with
/// the corner's light as it was. With reprojection (the default) the
/// frames where an object no sample hit moves into the paths of a
/// record's samples are checked too (`trc::later`): the corner's records
/// end their life before the block comes.
///
/// Against `path` at 256 spp: with the block in place `trc`'s records lie
/// elsewhere than `ic`'s (a record set's bias at 16×16 is some 6 % here),
/// so `trc` is held to 1.5 × `ic`'s error and a hundredth, not to `ic`'s
/// frames; in every temporal gradient mode. Measured with extrapolated
/// gradients: jumps in, 0.069 from frame k on (the constant estimate
/// 0.240, `ic` 0.062); grows, 0.034, 0.033, 0.078 (0.103, 0.222, 0.222;
/// `ic` 0.025, 0.062, 0.062).
#[test]
fn an_object_that_jumps_in_or_grows_is_seen_at_once() {
    let (k, max_life) = (2u32, 6u32);
    let frames = 0..k + 4;
    let corner = (Vec3::new(-0.95, 0.0, -0.95), Vec3::new(-0.2, 1.0, -0.2));
    let red = Vec3::new(0.9, 0.1, 0.1);
    let keys = [(k as f32 - 1.0, 0.0), (k as f32 + 1.0, 1.0)];
    let scenes: [(&str, &dyn Fn() -> Scene); 2] = [
        ("jumps in", &|| arriving_block_room(k, 24.0)),
        ("grows", &|| scaling_block_room(corner, red, 24.0, &keys)),
    ];
    for (what, scene) in scenes {
        let reference = converged_sequence(scene(), 16, frames.clone());
        let ic_frames = same_pattern_ic(scene(), frames.clone());
        let ic: Vec<f64> = (ic_frames.iter().zip(&reference))
            .map(|(film, path)| region_error(film, path))
            .collect();
        let errors = |gradients, reprojection| {
            let trc = (max_life, gradients, reprojection);
            region_errors_against(scene(), trc, frames.clone(), &reference)
        };
        eprintln!("{what}: ic {ic:.4?}");
        for gradients in GRADIENT_MODES {
            let (missed, checked) = (errors(gradients, false), errors(gradients, true));
            eprintln!(
                "{what}, {gradients:?}: checked {checked:.4?}, constant estimate {missed:.4?}"
            );
            let f = k as usize + 1;
            assert!(
                missed[f] > 2.0 * ic[f],
                "{what}, {gradients:?}: the constant estimate at frame {f} ({}) is as good \
                 as ic ({}): the test proves nothing",
                missed[f],
                ic[f]
            );
            for f in k as usize..frames.end as usize {
                assert!(
                    checked[f] < 1.5 * ic[f] + 0.01,
                    "{what}, {gradients:?}: frame {f} off by {} near the block against path \
                     (ic {}, constant estimate {})",
                    checked[f],
                    ic[f],
                    missed[f]
                );
            }
        }
    }
}

/// Fast motion over records (issue 5, "Stability where it fails"): a
/// block slides over the floor, 5 cm a frame, and covers floor records.
/// Records stay where they were created (§4.4), so the replacement of a
/// covered one would gather the block's inside, seen from behind, and
/// darken the floor pixels around the block (on cube-in-box at 64×64 with
/// `--trc-max-life 5`, frames 0..100, it took the relative RMSE from 0.0226
/// to 0.0254, most of the excess a darkening along the cube's path).
/// A replacement whose gather rays mostly hit back faces is dropped
/// instead: no record made in a frame (replaced or new) lies inside the
/// block in that frame. (A record made on the block's leading face is
/// inside it a frame later, until it expires; that is the paper's rule.)
/// The same with a double-sided block, as Blender exports every material:
/// its back faces are surfaces too, but its inside is dark all the same
/// (a growing double-sided sphere exported from Blender showed black
/// blotches before).
#[test]
fn a_record_covered_by_a_moving_object_is_not_replaced_inside_it() {
    no_replacement_inside_a_moving_block(false);
    no_replacement_inside_a_moving_block(true);
}

fn no_replacement_inside_a_moving_block(double_sided: bool) {
    let (fps, frames, step) = (24.0, 16u32, 0.05);
    let (min, max) = (Vec3::new(-0.9, 0.0, -0.6), Vec3::new(-0.5, 0.3, -0.2));
    let mut s = room_with_sliding_block((min, max), step, frames, fps);
    s.materials.last_mut().unwrap().double_sided = double_sided;
    let mut r = renderer(s, 24, fps, false);
    let mut trc = TemporalRadianceCaching::new(TrcSettings {
        ic: small_ic(),
        max_life: 2,
        ..TrcSettings::default()
    });
    let mut replaced = 0;
    for f in 0..frames {
        let _ = render_trc(&mut r, &mut trc, f);
        // The block's volume at frame f, shrunk by 1 cm on every side.
        let shift = Vec3::X * step * f as f32;
        let (lo, hi) = (min + shift + 0.01, max + shift - 0.01);
        for k in trc.records().iter().filter(|k| k.record.created_frame == f) {
            let p = k.record.position;
            // Floor records under the block lie on its bottom face's plane.
            let under = p.x > lo.x && p.x < hi.x && p.z > lo.z && p.z < hi.z && p.y < hi.y;
            replaced += usize::from(k.replaces.is_some());
            assert!(
                !under,
                "frame {f}: record {} at {p} inside the block (double-sided: {double_sided})",
                k.record.id
            );
        }
    }
    assert!(
        replaced > 100,
        "only {replaced} replacements: the test proves little"
    );
}

/// A record that lived one frame is dropped when it expires, not replaced
/// at its point (`TemporalRecord::replaced_when_expired`): it served frame
/// t0 alone, where its temporal gradients weigh nothing. In the lit room
/// with a block sliding fast (many records near it change by more than
/// `a^t` in a frame), every replacement replaces a record that lived two
/// frames or more, while many one-frame records a pixel used do expire;
/// with `δt_max = 1`, where every record lives one frame, the paper's
/// replacement in place is kept.
#[test]
fn a_record_that_lived_one_frame_is_dropped_not_replaced() {
    let (one_frame, longer, expired_one_frame) = replacements_by_predecessor_life(5);
    assert!(
        expired_one_frame > 20,
        "only {expired_one_frame} used one-frame records expired: the test proves little"
    );
    assert_eq!(
        one_frame, 0,
        "one-frame records replaced ({longer} longer ones)"
    );
    assert!(longer > 20, "only {longer} replacements");
    let (one_frame, _, expired_one_frame) = replacements_by_predecessor_life(1);
    assert!(
        one_frame * 10 >= expired_one_frame * 9 && one_frame > 20,
        "δt_max = 1: {one_frame} of {expired_one_frame} used records replaced"
    );
}

/// With `δt_max = max_life`, in the lit room with a fast sliding block
/// (24×24, 12 frames): the replacements of records that lived one frame,
/// those of records that lived longer, and the records that lived one
/// frame, were used and expired.
fn replacements_by_predecessor_life(max_life: u32) -> (usize, usize, usize) {
    let (fps, frames) = (24.0, 12u32);
    let block = (Vec3::new(-0.9, 0.0, -0.6), Vec3::new(-0.3, 0.6, 0.0));
    let s = room_with_sliding_block(block, 0.15, frames, fps);
    let mut r = renderer(s, 24, fps, false);
    let mut trc = TemporalRadianceCaching::new(TrcSettings {
        ic: small_ic(),
        max_life,
        ..TrcSettings::default()
    });
    let (mut one_frame, mut longer, mut expired_one_frame) = (0, 0, 0);
    for f in 0..frames {
        let before: std::collections::HashMap<u64, (u32, bool)> = trc
            .records()
            .iter()
            .map(|k| (k.record.id, (k.lifespan(), k.used)))
            .collect();
        expired_one_frame += trc
            .records()
            .iter()
            .filter(|k| k.used && k.lifespan() == 1 && k.last_valid + 1 == f)
            .count();
        let _ = render_trc(&mut r, &mut trc, f);
        for k in trc.records().iter().filter(|k| k.record.created_frame == f) {
            match k.replaces.map(|old| before[&old].0) {
                Some(1) => one_frame += 1,
                Some(_) => longer += 1,
                None => {}
            }
        }
    }
    (one_frame, longer, expired_one_frame)
}

/// The lit room with a grey block (`min`, `max` at frame 0) sliding along
/// +x by `step` a frame over `frames` frames.
fn room_with_sliding_block((min, max): (Vec3, Vec3), step: f32, frames: u32, fps: f32) -> Scene {
    let mut s = lit_room(None, fps);
    let end = (frames - 1) as f32;
    add_moving_block(
        &mut s,
        (min, max),
        Vec3::splat(0.6),
        Interpolation::Linear,
        (
            vec![0.0, end / fps],
            vec![Vec4::ZERO, Vec4::new(step * end, 0.0, 0.0, 0.0)],
        ),
    );
    s
}

/// The replacements `trc` makes in the static lit room whose room mesh is
/// `room` (16×16, `δt_max = 2`, 8 frames): records replaced at their point
/// when they expire.
fn replacements_in_room(room: Mesh) -> usize {
    let mut s = lit_room(None, 24.0);
    s.objects[0].mesh = room;
    let mut r = renderer(s, 16, 24.0, false);
    let mut trc = TemporalRadianceCaching::new(TrcSettings {
        ic: small_ic(),
        max_life: 2,
        ..TrcSettings::default()
    });
    let mut replaced = 0;
    for f in 0..8 {
        let _ = render_trc(&mut r, &mut trc, f);
        replaced += trc
            .records()
            .iter()
            .filter(|k| k.record.created_frame == f && k.replaces.is_some())
            .count();
    }
    replaced
}

/// A room modelled with its walls facing out (one-sided, as exporters
/// leave them), seen from inside: every gather ray meets the back of a
/// wall. The rule that drops a replacement gathered inside a moving object
/// (previous test) must not take the static walls for one: the room is
/// replaced as the same room facing in is (every used record at its
/// expiry), where counting every back face dropped every replacement.
#[test]
fn a_room_seen_from_behind_its_normals_still_replaces_records() {
    let (min, max) = (Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 2.0, 1.0));
    let facing_in = replacements_in_room(inward_box(min, max, 0));
    let facing_out = replacements_in_room(outward_box(min, max, 0));
    assert!(
        facing_in > 50,
        "only {facing_in} replacements: the test proves little"
    );
    assert!(
        facing_out * 10 >= facing_in * 9,
        "walls facing out: {facing_out} replacements against {facing_in} facing in"
    );
}

/// Eq. 9–10 give a record at most `a_t` of change over its life, so on the
/// same records extrapolated temporal gradients (Eq. 15) may move a
/// pixel's cached light from its value without them by at most `a_t` of
/// it: its cached light is a weighted mean of the records', its direct
/// light the same. The default cube-in-box at 64×64 over frames 0..24,
/// by the luminance of each 3 × 3 block of pixels. Carried on with them,
/// the spatial gradients' change, which nothing bounds, tilted records
/// into discs: 0.150, three times `a_t`, here before it was dropped
/// (`TemporalRecord::at_frame`); 0.013 since.
#[test]
fn extrapolated_gradients_move_the_light_by_at_most_a_t() {
    let (size, frames) = (64, 0..24u32);
    let render = |gradients| {
        let trc = TemporalRadianceCaching::new(TrcSettings {
            gradients,
            ..TrcSettings::default()
        });
        let mut r = Renderer::new(
            Scene::builtin("cube-in-box").unwrap(),
            Box::new(trc),
            Box::new(CpuBackend::new()),
            FrameSettings {
                width: size,
                height: size,
                ..FrameSettings::default()
            },
        );
        frames
            .clone()
            .map(|f| r.render_frame(f))
            .collect::<Vec<Film>>()
    };
    let (none, extrapolated) = (
        render(TemporalGradients::None),
        render(TemporalGradients::Extrapolated),
    );
    let a_t = TrcSettings::default().temporal_accuracy;
    let luminance = |film: &Film, x: u32, y: u32| {
        let mut sum = 0.0;
        for (dx, dy) in (0..3).flat_map(|dx| (0..3).map(move |dy| (dx, dy))) {
            sum += film
                .get(x + dx, y + dy)
                .dot(Vec3::new(0.2126, 0.7152, 0.0722));
        }
        sum
    };
    let mut worst = (0.0f32, 0, 0, 0);
    for (f, (n, e)) in none.iter().zip(&extrapolated).enumerate() {
        for (x, y) in (0..size - 2).flat_map(|x| (0..size - 2).map(move |y| (x, y))) {
            let (ln, le) = (luminance(n, x, y), luminance(e, x, y));
            let moved = (le - ln).abs() / ln.max(1e-6);
            if moved > worst.0 {
                worst = (moved, f, x, y);
            }
        }
    }
    eprintln!(
        "largest move {:.4} (a_t {a_t}) at frame {}, ({}, {})",
        worst.0, worst.1, worst.2, worst.3
    );
    assert!(
        worst.0 > 0.002,
        "extrapolated gradients moved nothing ({:.4}): the test proves little",
        worst.0
    );
    assert!(
        worst.0 <= a_t * 1.05,
        "moved by {:.4} > a_t = {a_t}",
        worst.0
    );
}

/// TRC §4.5, Fig. 4c–e: temporal gradients smooth the jump of accuracy when
/// a record is replaced, extrapolated ones in one pass, interpolated ones
/// (Eq. 18–20, two passes) towards the replacement's value. Cube-in-box at
/// 16×16 over 16 frames with δt_max = 5 (the paper's Spheres setting, so
/// that records are replaced within the sequence), flicker against a
/// same-pattern `path` reference, over the sequence and over the pairs of
/// frames that enter a replacement. All three modes share the same records
/// (same aging, replacement and fill), so only the gradients differ.
#[test]
fn temporal_gradients_flicker_order() {
    let (size, frames) = (16, 0..16u32);
    let cube = || Scene::builtin("cube-in-box").unwrap();
    let reference = converged_sequence(cube(), size, frames.clone());
    let mut results = Vec::new();
    for gradients in GRADIENT_MODES {
        let trc = TemporalRadianceCaching::new(TrcSettings {
            ic: IcSettings {
                spp: 4,
                strata: Strata { theta: 8, phi: 24 },
                ..IcSettings::default()
            },
            max_life: 5,
            gradients,
            ..TrcSettings::default()
        });
        let mut r = Renderer::new(
            cube(),
            Box::new(trc),
            Box::new(CpuBackend::new()),
            FrameSettings {
                width: size,
                height: size,
                same_pattern: true,
                ..FrameSettings::default()
            },
        );
        r.set_frame_end(Some(frames.end));
        let mut computed = 0;
        let films: Vec<Film> = frames
            .clone()
            .map(|f| {
                let film = r.render_frame(f);
                let s = r.last_frame_stats();
                computed += s.records_created + s.records_replaced;
                film
            })
            .collect();
        let flicker = flicker(&films, &reference).unwrap();
        // The pairs of frames entering a replacement (every δt_max frames).
        let entering = [4usize, 9, 14]
            .map(|k| radcache::metrics::flicker(&films[k..k + 2], &reference[k..k + 2]).unwrap());
        let error = films
            .iter()
            .zip(&reference)
            .map(|(f, r)| radcache::metrics::rel_rmse(f, r))
            .sum::<f64>()
            / films.len() as f64;
        eprintln!(
            "{gradients:?}: flicker {flicker:.5}, entering replacements {entering:.4?}, \
             rel. RMSE {error:.4}, records computed {computed}"
        );
        results.push((flicker, computed, entering));
    }
    let (none, extrapolated, interpolated) = (results[0], results[1], results[2]);
    assert_eq!(none.1, extrapolated.1, "same records in every mode");
    assert_eq!(none.1, interpolated.1, "same records in every mode");
    // Measured: none 0.01203, extrapolated 0.01208, interpolated 0.01185.
    // Interpolation lowers the flicker of each pair of frames that enters
    // a replacement (frames 4→5, 9→10, 14→15), as the paper's Fig. 4e
    // says: 0.0068, 0.0139, 0.0169 with none, 0.0048, 0.0130, 0.0164
    // interpolated. (Until trc's revision 6 the first pass stopped a frame
    // short of the last replacements, so the records that lived longest
    // rendered without their successors: 0.0077, 0.0127, 0.0164, the
    // first pair above none's.) Extrapolation changes
    // little here, either way: most records live δt_max frames with τ ≈ 1,
    // so their extrapolated change is small, and a replacement gathers
    // with its predecessor's random streams (`ic::first_stream`), so where
    // nothing changed it does not jump. The test requires it to add no
    // more than 2 %. (With fresh streams for replacements, before those
    // mends: 0.0168, 0.0168, 0.0136.) The 64×64 bench over 48 frames of
    // `moving-light` shows the paper's order (README).
    assert!((extrapolated.0 / none.0 - 1.0).abs() < 0.02, "{results:?}");
    assert!(interpolated.0 < none.0, "{results:?}");
    assert!(interpolated.0 < extrapolated.0, "{results:?}");
    for pair in 0..3 {
        assert!(interpolated.2[pair] < none.2[pair], "{results:?}");
    }
}

/// `trc`'s render pass keys every stream of a pixel sample by pixel and
/// sample alone ([`PixelStreams::Coherent`]): its position, its light
/// sample and, where no record covers it, its path-traced indirect light.
/// `ic`'s are new every frame. With an empty cache every sample falls
/// back: over three frames of a static room the coherent frames are the
/// same bit for bit (nothing changed, so no fresh noise shows), the
/// per-frame ones flicker, and on average both render the same image (both
/// are unbiased).
#[test]
fn coherent_streams_do_not_flicker_where_nothing_changed() {
    let mut r = renderer(lit_room(None, 24.0), 16, 24.0, false);
    let ic = IrradianceCaching::new(IcSettings {
        spp: 4,
        ..small_ic()
    });
    let (min, max) = (Vec3::splat(-2.0), Vec3::splat(3.0));
    let empty = radcache::cache::IrradianceCache::new(min, max, ic.settings.accuracy);
    let mut frames = |streams| -> Vec<Film> {
        (0..3)
            .map(|f| r.with_frame_context(f, |ctx| ic.render_with_cache(ctx, &empty, streams)))
            .collect()
    };
    let coherent = frames(PixelStreams::Coherent);
    let per_frame = frames(PixelStreams::PerFrame);
    let bits = |f: &Film| -> Vec<[u32; 3]> {
        f.pixels
            .iter()
            .map(|p| p.to_array().map(f32::to_bits))
            .collect()
    };
    assert!(coherent.iter().all(|f| bits(f) == bits(&coherent[0])));
    // A static scene: the reference changes nothing between frames.
    let still = vec![coherent[0].clone(); 3];
    let f_per_frame = flicker(&per_frame, &still).expect("three frames");
    assert!(f_per_frame > 0.01, "per-frame flicker {f_per_frame:.4}");
    let mean = |films: &[Film]| -> f64 {
        films
            .iter()
            .flat_map(|f| f.pixels.iter())
            .map(|p| f64::from(p.x + p.y + p.z))
            .sum::<f64>()
    };
    let (a, b) = (mean(&coherent), mean(&per_frame));
    assert!((a - b).abs() < 0.05 * b, "mean {a} against {b}");
}

/// Cube-in-box with its camera moving by `step` and turning left by
/// `yaw` radians a frame (linear keys over `frames`): every frame shows
/// surfaces the last one did not, and records leave the view.
fn panning_cube_in_box(frames: u32, fps: f32, step: Vec3, yaw: f32) -> Scene {
    let mut s = Scene::builtin("cube-in-box").unwrap();
    let node = s.camera.node;
    let rest = s.nodes[node].rest;
    let last = (frames - 1) as f32;
    let times = vec![0.0, last / fps];
    let turned = glam::Quat::from_rotation_y(yaw * last) * rest.rotation;
    s.animation.channels.extend([
        Channel {
            node,
            property: Property::Translation,
            interpolation: Interpolation::Linear,
            times: times.clone(),
            values: vec![
                rest.translation.extend(0.0),
                (rest.translation + step * last).extend(0.0),
            ],
        },
        Channel {
            node,
            property: Property::Rotation,
            interpolation: Interpolation::Linear,
            times,
            values: vec![Vec4::from(rest.rotation), Vec4::from(turned)],
        },
    ]);
    s
}

/// `ic` and `trc` (with `trc_settings`, whose `ic` settings both use)
/// rendered side by side on `r` over the frames of `reference`: each
/// frame's relative RMSE against it, and the records each computed.
struct SideBySide {
    ic_errors: Vec<f64>,
    trc_errors: Vec<f64>,
    ic_records: u64,
    trc_records: u64,
    trc_replaced: u64,
}

fn ic_and_trc_against(
    r: &mut Renderer,
    trc_settings: TrcSettings,
    reference: &[Film],
) -> SideBySide {
    let mut ic = IrradianceCaching::new(trc_settings.ic.clone());
    let mut trc = TemporalRadianceCaching::new(trc_settings);
    let mut out = SideBySide {
        ic_errors: Vec::new(),
        trc_errors: Vec::new(),
        ic_records: 0,
        trc_records: 0,
        trc_replaced: 0,
    };
    for (f, reference) in (0u32..).zip(reference) {
        let film = r.with_frame_context(f, |ctx| ic.render_frame(ctx));
        out.ic_errors.push(rel_rmse(&film, reference));
        out.ic_records += ic.last_frame_stats().records_created;
        let film = render_trc(r, &mut trc, f);
        out.trc_errors.push(rel_rmse(&film, reference));
        let stats = trc.last_frame_stats();
        out.trc_records += stats.records_created + stats.records_replaced;
        out.trc_replaced += stats.records_replaced;
    }
    out
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// [`small_ic`] with 4 pixel samples, for the side-by-side tests.
fn quick_ic() -> IcSettings {
    IcSettings {
        spp: 4,
        ..small_ic()
    }
}

/// A moving camera (the most common animation, absent from the paper's
/// scenes): records are fixed in world space, so a pan only changes which
/// of them pixels use; records that left the view are dropped, newly seen
/// surfaces get new ones. `trc` must stay as accurate as `ic` (relative
/// RMSE against a converged `path` over the sequence, with the same pixel
/// samples) while it computes fewer records. Measured: 0.0750 against
/// 0.0721, 237 records against 1,570 (within 4 % of `ic` also for a pure
/// dolly, a pure turn and a pan).
#[test]
fn a_moving_camera_keeps_trc_as_accurate_as_ic() {
    let (size, frames, fps) = (24, 12u32, 24.0);
    // Left, up and in by 8 cm a frame while turning right 2.3° a frame:
    // 0.9 m and 25° over the sequence.
    let scene = || panning_cube_in_box(frames, fps, Vec3::new(-0.06, 0.02, -0.05), -0.04);
    let reference = converged_sequence(scene(), size, 0..frames);
    let mut r = renderer(scene(), size, fps, false);
    let trc = TrcSettings {
        ic: quick_ic(),
        ..TrcSettings::default()
    };
    let run = ic_and_trc_against(&mut r, trc, &reference);
    let (ic_error, trc_error) = (mean(&run.ic_errors), mean(&run.trc_errors));
    let (ic_records, trc_records) = (run.ic_records, run.trc_records);
    eprintln!(
        "mean relative RMSE: ic {ic_error:.4}, trc {trc_error:.4}; records: ic {ic_records}, trc {trc_records}"
    );
    assert!(
        trc_error < 1.1 * ic_error,
        "trc {trc_error} vs ic {ic_error}"
    );
    assert!(
        trc_records * 2 < ic_records,
        "{trc_records} vs {ic_records}"
    );
}

/// Long lifespans (issue 5, "Stability where it fails"): with `δt_max`
/// out of the way (1,000 frames), only the temporal weight (Eq. 9–11)
/// retires records, so each must leave once its estimated change adds up
/// to `a_t`. Under `moving-light`'s light, which moves about 1 cm a frame,
/// the records must keep being replaced and `trc`'s error against a
/// converged `path` must not drift above `ic`'s, also at the end of the
/// sequence. Measured (16×16, 48 frames): mean relative RMSE 0.0626
/// against `ic`'s 0.0649 (0.0625 with `δt_max = 20`), 377 replacements
/// (397 with `δt_max = 20`).
#[test]
fn long_lifespans_are_bounded_by_the_temporal_weight() {
    let (size, frames, fps) = (16, 48u32, 24.0);
    let scene = || Scene::builtin("moving-light").unwrap();
    let reference = converged_sequence(scene(), size, 0..frames);
    let mut r = renderer(scene(), size, fps, true);
    let trc = TrcSettings {
        ic: quick_ic(),
        max_life: 1000,
        ..TrcSettings::default()
    };
    let run = ic_and_trc_against(&mut r, trc, &reference);
    let (ic_errors, trc_errors, replaced) = (&run.ic_errors, &run.trc_errors, run.trc_replaced);
    let last_third = (2 * frames / 3) as usize;
    eprintln!(
        "relative RMSE: ic {:.4}, trc {:.4} (last third: {:.4}, {:.4}); {replaced} replaced",
        mean(ic_errors),
        mean(trc_errors),
        mean(&ic_errors[last_third..]),
        mean(&trc_errors[last_third..])
    );
    assert!(
        replaced > 100,
        "only {replaced} replacements: records outlive their change"
    );
    assert!(mean(trc_errors) < 1.1 * mean(ic_errors));
    assert!(mean(&trc_errors[last_third..]) < 1.1 * mean(&ic_errors[last_third..]));
}

/// TRC Table 1 where lights move: on `moving-light` (at 6 fps the ceiling
/// light moves up to 6.3 cm a frame) the reprojected estimate, whose
/// samples follow the light (`light_ratio`), predicts E(t0+1) better than
/// taking E constant in mean and in median, as in the paper (2.9 % / 1.6 %
/// against 3.7 % / 2.4 %). Measured over 292 records of frames 5 and 20
/// (cb1a639): 2.64 % / 0.70 % against 4.01 % / 1.67 % (earlier, at 24, 12
/// and 3 fps, the same
/// order: 0.33 / 0.22 against 0.71 / 0.54, 0.56 / 0.36 against 1.05 /
/// 0.68, 2.86 / 1.06 against 3.91 / 2.18). Evaluating each sample's direct
/// light again at t0+1 (`next_direct`) changed nothing here when measured
/// (2.66 % / 0.78 % against 2.66 % / 0.74 %, before cb1a639): the light
/// ratio already follows the light. It is the default where lights move
/// since `trc` revision 13: 2.67 % / 0.77 % (2026-12-02).
#[test]
fn reprojection_follows_a_moving_light_better_than_constant() {
    let fps = 6.0;
    let mut r = renderer(Scene::builtin("moving-light").unwrap(), 24, fps, false);
    let (mut reprojected, mut constant) = (Vec::new(), Vec::new());
    for t0 in [5u32, 20] {
        let (records, actual) = records_and_their_next_frame(&mut r, t0);
        for (a, c) in estimate_errors(&records, &actual) {
            reprojected.push(a);
            constant.push(c);
        }
    }
    let (mean_r, median_r) = mean_and_median(&mut reprojected).unwrap();
    let (mean_c, median_c) = mean_and_median(&mut constant).unwrap();
    eprintln!(
        "E(t0+1) error over {} records under a moving light: reprojection {}, constant {}",
        reprojected.len(),
        percent((mean_r, median_r)),
        percent((mean_c, median_c))
    );
    assert!(mean_r < mean_c, "mean {mean_r} vs {mean_c}");
    assert!(median_r < median_c, "median {median_r} vs {median_c}");
}

/// What a `trc` run of `frames` frames of the built-in `scene` (24×24,
/// `δt_max` = 3) gave, with or without [`TrcSettings::keep_paths`].
struct KeptPathsRun {
    frames: Vec<Vec<Vec3>>,
    records: Vec<IrradianceRecord>,
    samples_reshot: u64,
    replaced: u64,
    closest_rays: u64,
}

fn kept_paths_run(scene: &str, frames: u32, keep_paths: bool) -> KeptPathsRun {
    let settings = TrcSettings {
        ic: small_ic(),
        max_life: 3,
        keep_paths,
        ..TrcSettings::default()
    };
    let mut r = renderer(Scene::builtin(scene).unwrap(), 24, 24.0, false);
    let mut trc = TemporalRadianceCaching::new(settings);
    let mut run = KeptPathsRun {
        frames: Vec::new(),
        records: Vec::new(),
        samples_reshot: 0,
        replaced: 0,
        closest_rays: 0,
    };
    for f in 0..frames {
        run.frames.push(render_trc(&mut r, &mut trc, f).pixels);
        let stats = trc.last_frame_stats();
        run.samples_reshot += stats.samples_reshot;
        run.replaced += stats.records_replaced;
    }
    run.records = trc.records().iter().map(|k| k.record.clone()).collect();
    run.closest_rays = r.backend().ray_counts().closest;
    run
}

/// The same records and frames, bit for bit.
fn assert_same_records_and_frames(a: &KeptPathsRun, b: &KeptPathsRun) {
    assert_eq!(a.records, b.records);
    for (f, (a, b)) in a.frames.iter().zip(&b.frames).enumerate() {
        assert!(a == b, "frame {f} differs");
    }
}

/// Replacements that take the paths nothing moving met ([`TrcSettings::
/// keep_paths`]) give, on cube-in-box with its moving cube, the very
/// records and frames that tracing every path again gives, bit for bit,
/// while shooting fewer samples (the paths near the cube are traced
/// again, so some are shot).
#[test]
fn kept_paths_give_the_records_and_frames_of_tracing_them_again() {
    let kept = kept_paths_run("cube-in-box", 12, true);
    let traced = kept_paths_run("cube-in-box", 12, false);
    let replaced = kept.replaced;
    assert!(replaced > 10, "{replaced} replacements");
    // (Replacements gathered inside the cube, then dropped, shot theirs too.)
    assert!(traced.samples_reshot >= replaced * small_ic().strata.count() as u64);
    assert!(
        kept.samples_reshot > 0 && kept.samples_reshot < traced.samples_reshot / 2,
        "{} samples shot against {}",
        kept.samples_reshot,
        traced.samples_reshot
    );
    assert_same_records_and_frames(&kept, &traced);
}

/// Under a moving light a replacement cannot take its record's paths
/// whole (their light samples see the light elsewhere), but it takes the
/// hits of their extension rays that no moving box meets, and traces only
/// the shadow rays ([`radcache::integrator::Replay`]). On the built-in
/// moving light the records and frames are those of tracing every path
/// again, bit for bit, with fewer closest-hit rays traced.
#[test]
fn kept_hits_give_under_a_moving_light_the_records_and_frames_of_tracing_them_again() {
    let kept = kept_paths_run("moving-light", 8, true);
    let traced = kept_paths_run("moving-light", 8, false);
    assert!(kept.replaced > 10, "{} replacements", kept.replaced);
    assert!(
        (kept.closest_rays as f64) < 0.9 * traced.closest_rays as f64,
        "{} closest-hit rays against {}",
        kept.closest_rays,
        traced.closest_rays
    );
    assert_same_records_and_frames(&kept, &traced);
}

/// A far point light swinging across a courtyard
/// (`common::courtyard_under_a_swinging_light`, 15° a frame) moves every
/// shadow the walls cast on the ground: no object moves, and the
/// unshadowed light at the samples' hits does not see shadows. With the
/// direct light at t0+1 evaluated where lights move
/// (`NextDirect::MovingLights`, as the default `LongLives` does too),
/// records that see the shadows move end
/// their life: over the frames the light swings, `trc`'s mean block bias
/// against `path` at 256 spp is under 0.8× that with it off and within
/// 1.3× `ic`'s with the same spatial settings. Measured at 2026-12-02:
/// 0.022, off 0.051, `ic` 0.021. With the direct light evaluated at t0+1
/// only it was 0.036, all of the difference in the last two frames (0.058
/// and 0.118 against `ic`'s 0.022 and 0.036): as the light sinks the
/// walls' shadows lengthen ever faster, and records made when an edge was
/// still far from what they see lived on; `trc::later` now evaluates the
/// direct light at the end of each life too (`LitFrames`).
#[test]
fn a_swinging_light_moves_the_shadows_the_records_see() {
    let (frames, size) = (9u32, 16u32);
    let scene = || common::courtyard_under_a_swinging_light(frames + 1, true);
    let reference = common::converged_sequence(scene(), size, 0..frames);
    let mean_bias = |method: &mut dyn Method| {
        let mut r = renderer(scene(), size, 24.0, false);
        let films: Vec<Film> = (0..frames)
            .map(|f| r.with_frame_context(f, |ctx| method.render_frame(ctx)))
            .collect();
        (films.iter().zip(&reference).skip(1))
            .map(|(film, reference)| block_bias(film, reference, 8))
            .sum::<f64>()
            / f64::from(frames - 1)
    };
    let spatial = IcSettings {
        spp: 4,
        ..small_ic()
    };
    let ic = mean_bias(&mut IrradianceCaching::new(spatial.clone()));
    let trc = |next_direct| TrcSettings {
        ic: spatial.clone(),
        next_direct,
        ..TrcSettings::default()
    };
    let default = mean_bias(&mut TemporalRadianceCaching::new(trc(
        NextDirect::MovingLights,
    )));
    let off = mean_bias(&mut TemporalRadianceCaching::new(trc(NextDirect::Off)));
    eprintln!("mean block bias: trc {default:.4}, next_direct off {off:.4}, ic {ic:.4}");
    assert!(default < 0.8 * off, "trc {default}, next_direct off {off}");
    assert!(default < 1.3 * ic, "trc {default}, ic {ic}");
}

/// The frames `trc` renders of built-in `scene` (24×24, `small_ic`) under
/// `next_direct`, and its records at the end.
fn next_direct_run(
    scene: &str,
    frames: u32,
    next_direct: NextDirect,
) -> (Vec<Vec<Vec3>>, Vec<IrradianceRecord>) {
    let settings = TrcSettings {
        ic: small_ic(),
        next_direct,
        ..TrcSettings::default()
    };
    let mut r = renderer(Scene::builtin(scene).unwrap(), 24, 24.0, false);
    let mut trc = TemporalRadianceCaching::new(settings);
    let films = (0..frames)
        .map(|f| render_trc(&mut r, &mut trc, f).pixels)
        .collect();
    let records = trc.records().iter().map(|k| k.record.clone()).collect();
    (films, records)
}

/// The default (`NextDirect::LongLives`) evaluates the direct light at
/// t0+1 where only objects move exactly where the records alive live long
/// (`δt_max`/2 and more, as made): on cube-in-box, whose records live
/// long (13–18 of 20 frames at 64×64, `benches/RESULTS.md`), it renders
/// what `on` renders, bit for bit; among the balls, whose records live
/// short (2–4 frames there), it renders `on`'s first frame (its records
/// made with the direct light, none being alive to judge by) and then
/// frames and records unlike `on`'s.
#[test]
fn the_direct_light_at_t0_plus_1_is_evaluated_where_records_live_long() {
    let frames = 6;
    let default = next_direct_run("cube-in-box", frames, NextDirect::LongLives);
    let on = next_direct_run("cube-in-box", frames, NextDirect::On);
    assert_eq!(default.1, on.1, "cube-in-box's records");
    for (f, (a, b)) in default.0.iter().zip(&on.0).enumerate() {
        assert!(a == b, "cube-in-box frame {f} differs from on's");
    }
    let default = next_direct_run("spheres", frames, NextDirect::LongLives);
    let on = next_direct_run("spheres", frames, NextDirect::On);
    assert!(
        default.0[0] == on.0[0],
        "the first frame is rendered as on's"
    );
    assert_ne!(default.1, on.1, "the balls' records");
    let differ = (1..frames as usize).filter(|&f| default.0[f] != on.0[f]);
    assert!(differ.count() >= 3, "the balls' later frames are not on's");
}

/// The lit room with a white plate at mid-height tilting about x from
/// level to `degrees` over `frames` frames.
fn room_with_tilting_plate(frames: u32, degrees: f32) -> Scene {
    let mut s = lit_room(None, 24.0);
    s.materials
        .push(Material::diffuse("plate", Vec3::splat(0.9)));
    let plate = outward_box(Vec3::new(-0.5, -0.01, -0.5), Vec3::new(0.5, 0.01, 0.5), 2);
    add_static_object(&mut s, "plate", plate);
    let node = s.nodes.len() - 1;
    s.nodes[node].rest.translation = Vec3::new(0.0, 1.0, -0.3);
    let turned = glam::Quat::from_rotation_x(degrees.to_radians());
    s.animation.channels.push(Channel {
        node,
        property: Property::Rotation,
        interpolation: Interpolation::Linear,
        times: vec![0.0, (frames - 1) as f32 / 24.0],
        values: vec![Vec4::from(glam::Quat::IDENTITY), Vec4::from(turned)],
    });
    s.frame_count = frames;
    s
}

/// A replacement's estimate follows the change observed over the life of
/// the record it replaces (`TrcSettings::history`): under a plate tilting
/// 80° in the lit room over 32 frames (16×16, 4 spp), the records of the
/// first frames see light the reprojection cannot (the plate's faces
/// turning under the light keep their radiance in the reprojected samples)
/// and live their `δt_max` of 20 frames, with or without it; their
/// replacements, made with the change their predecessors lived through,
/// have over frames 20–31 a mean block bias against `path` at 256 spp
/// under 0.8× that without it and within 1.3× `ic`'s. Measured at
/// 2026-12-07: 0.0161, without 0.0227, `ic` 0.0166; over frames 0–19,
/// where no record was replaced yet, `trc` rises to 0.079 at frame 19
/// (`ic` 0.012): the first generation's lag, which this does not reach
/// (`--trc-next-direct on` does not either: 0.076).
#[test]
fn replacements_follow_the_change_their_predecessors_observed() {
    let (frames, size) = (32u32, 16u32);
    let scene = || room_with_tilting_plate(frames, 80.0);
    let reference = common::converged_sequence(scene(), size, 0..frames);
    let replaced = 20..frames;
    let mean_bias = |method: &mut dyn Method| {
        let mut r = renderer(scene(), size, 24.0, false);
        let films: Vec<Film> = (0..frames)
            .map(|f| r.with_frame_context(f, |ctx| method.render_frame(ctx)))
            .collect();
        let biases = replaced
            .clone()
            .map(|f| block_bias(&films[f as usize], &reference[f as usize], 8));
        biases.sum::<f64>() / replaced.len() as f64
    };
    let spatial = IcSettings {
        spp: 4,
        ..small_ic()
    };
    let ic = mean_bias(&mut IrradianceCaching::new(spatial.clone()));
    let trc = |history| {
        let settings = TrcSettings {
            ic: spatial.clone(),
            history,
            ..TrcSettings::default()
        };
        assert_eq!(settings.max_life, replaced.start);
        TemporalRadianceCaching::new(settings)
    };
    let with = mean_bias(&mut trc(true));
    let without = mean_bias(&mut trc(false));
    eprintln!("frames 20-31, mean block bias: trc {with:.4}, history off {without:.4}, ic {ic:.4}");
    assert!(with < 0.8 * without, "trc {with}, history off {without}");
    assert!(with < 1.3 * ic, "trc {with}, ic {ic}");
}
