//! Directional lights (`KHR_lights_punctual` "directional", a sun): parallel
//! light of irradiance E from one direction, however far the scene reaches.
//! Every method against the closed form of a plane under a turning sun,
//! shadowed by a black square, and against converged `path` where the
//! sun's light comes back off a wall.

mod common;

use common::{ground, push_quad, scene};
use glam::{Quat, Vec3, Vec4};
use radcache::film::Film;
use radcache::method::movies::{MoviesSettings, TextureMovies};
use radcache::method::settings::method_settings;
use radcache::method::Method;
use radcache::metrics::rel_rmse;
use radcache::scene::animation::{Channel, Interpolation, Property};
use radcache::scene::{LightKind, Material, Mesh, Node, PunctualLight, Scene, Trs, DEFAULT_FPS};
use std::f32::consts::FRAC_1_PI;

/// The sun's direction (where its light goes) at frames 0 and 1: it turns
/// between them, so that methods that keep light across frames must see
/// it move.
const SUN: [Vec3; 2] = [Vec3::new(0.4, -1.0, 0.3), Vec3::new(-0.5, -1.0, 0.1)];

/// Irradiance (W·m⁻²) on a surface facing the sun.
const E: f32 = 3.0;

/// Adds a directional light of irradiance `e` to `s`, pointing along
/// `directions[f]` at frame `f` (a step key per frame; none where it does
/// not turn).
fn add_sun(s: &mut Scene, e: f32, directions: &[Vec3]) {
    let node = s.nodes.len();
    let turn = |d: Vec3| Quat::from_rotation_arc(Vec3::NEG_Z, d.normalize());
    s.nodes.push(Node {
        name: "sun".into(),
        parent: None,
        rest: Trs {
            rotation: turn(directions[0]),
            ..Trs::default()
        },
    });
    s.lights.push(PunctualLight {
        name: "sun".into(),
        node,
        intensity: Vec3::splat(e),
        kind: LightKind::Directional,
    });
    if directions.iter().all(|&d| d == directions[0]) {
        s.frame_count = directions.len() as u32;
        return;
    }
    s.animation.channels.push(Channel {
        node,
        property: Property::Rotation,
        interpolation: Interpolation::Step,
        times: (0..directions.len())
            .map(|f| f as f32 / DEFAULT_FPS)
            .collect(),
        values: directions.iter().map(|&d| Vec4::from(turn(d))).collect(),
    });
    s.frame_count = directions.len() as u32;
}

/// Plane y = 0 (albedo `ALBEDO`), a black unit square at y = 1, seen
/// straight down from (0, 4, 0), lit by the sun alone.
const ALBEDO: f32 = 0.7;
const EYE: Vec3 = Vec3::new(0.0, 4.0, 0.0);

/// One frame of the plane under the square: where the sun's light goes,
/// and the square's centre.
#[derive(Clone, Copy, Debug)]
struct Sky {
    sun: Vec3,
    square: Vec3,
}

/// The sun turns under a still square.
const TURNING: [Sky; 2] = [
    Sky {
        sun: SUN[0],
        square: Vec3::new(0.0, 1.0, 0.0),
    },
    Sky {
        sun: SUN[1],
        square: Vec3::new(0.0, 1.0, 0.0),
    },
];

/// The square slides by 0.4 m a frame under a still sun.
const SLIDING: [Sky; 3] = [
    Sky {
        sun: SUN[0],
        square: Vec3::new(-0.4, 1.0, 0.0),
    },
    Sky {
        sun: SUN[0],
        square: Vec3::new(0.0, 1.0, 0.0),
    },
    Sky {
        sun: SUN[0],
        square: Vec3::new(0.4, 1.0, 0.0),
    },
];

/// The plane under the square, at `frames[f]` in frame `f` (step keys;
/// none where nothing changes).
fn plane_under_a_square(frames: &[Sky]) -> Scene {
    let plane = ground(10.0, 0);
    let mut square = Mesh::default();
    push_quad(&mut square, Vec3::new(-0.5, 0.0, -0.5), Vec3::Z, Vec3::X, 1);
    let materials = vec![
        Material::diffuse("plane", Vec3::splat(ALBEDO)),
        Material::diffuse("black", Vec3::ZERO),
    ];
    let mut s = scene(
        vec![plane, square],
        materials,
        vec![],
        EYE,
        -Vec3::Y,
        1.0,
        vec![],
    );
    let square_node = s.objects[1].node;
    s.nodes[square_node].rest.translation = frames[0].square;
    if frames.iter().any(|f| f.square != frames[0].square) {
        s.animation.channels.push(Channel {
            node: square_node,
            property: Property::Translation,
            interpolation: Interpolation::Step,
            times: (0..frames.len()).map(|f| f as f32 / DEFAULT_FPS).collect(),
            values: frames.iter().map(|f| f.square.extend(0.0)).collect(),
        });
    }
    let suns: Vec<Vec3> = frames.iter().map(|f| f.sun).collect();
    add_sun(&mut s, E, &suns);
    s
}

/// Whether ray `o + t·d` (t > 0) crosses the unit square centred on
/// `centre`, level with it.
fn through_square(o: Vec3, d: Vec3, centre: Vec3) -> bool {
    let t = (centre.y - o.y) / d.y;
    let p = o + d * t - centre;
    t > 0.0 && p.x.abs() < 0.5 && p.z.abs() < 0.5
}

/// The closed form along the camera ray `d` under `sky`: black where it
/// meets the square, else `ρ/π · E · cosθ` where the plane sees the sun
/// past the square, and nothing in its shadow (the square reflects
/// nothing, and nothing else is there to bounce light).
fn closed_form(d: Vec3, sky: Sky) -> f32 {
    if through_square(EYE, d, sky.square) {
        return 0.0;
    }
    let p = EYE + d * (-EYE.y / d.y);
    let to_sun = -sky.sun.normalize();
    if through_square(p, to_sun, sky.square) {
        0.0
    } else {
        ALBEDO * FRAC_1_PI * E * to_sun.y
    }
}

/// Each pixel of a `size`² frame whose 3 × 3 neighbourhood the closed form
/// holds at one value under `sky` (on a grid of 8 × 8 points each): that
/// value. Pixels across an edge of the square or its shadow are left out,
/// where sampling noise and `movies`' texels blur the edge.
fn settled_pixels(s: &Scene, size: u32, sky: Sky) -> Vec<((u32, u32), f32)> {
    let camera = s.snapshot(0.0).camera;
    let sub = 8;
    let values = |x: u32, y: u32| {
        let at = |pixel: u32, k: u32| (pixel as f32 + (k as f32 + 0.5) / sub as f32) / size as f32;
        (0..sub * sub).map(move |k| (at(x, k % sub), at(y, k / sub)))
    };
    let value_of = |(sx, sy): (f32, f32)| closed_form(camera.direction(sx, sy, 1.0), sky);
    let mut settled = Vec::new();
    for y in 1..size - 1 {
        for x in 1..size - 1 {
            let first = value_of(values(x, y).next().unwrap());
            let uniform = (x - 1..=x + 1)
                .flat_map(|i| (y - 1..=y + 1).map(move |j| (i, j)))
                .flat_map(|(i, j)| values(i, j))
                .all(|u| value_of(u) == first);
            if uniform {
                settled.push(((x, y), first));
            }
        }
    }
    settled
}

/// Renders frames `0..frames` of `s` with `method` at its defaults.
fn render(s: Scene, method: &str, size: u32, frames: u32) -> Vec<Film> {
    let settings = method_settings(method, None).unwrap();
    let mut r = common::cpu_renderer(s, settings.instantiate(), size);
    (0..frames).map(|f| r.render_frame(f)).collect()
}

/// The plane is lit by `ρ/π · E · cosθ` where it sees the sun and is
/// black in the square's shadow, with every method, at both of the sun's
/// directions: a sun that turns is followed from one frame to the next
/// (the shadow moves by 0.9 m).
#[test]
fn every_method_lights_a_plane_under_a_turning_sun_as_the_closed_form() {
    every_method_matches_the_closed_form(&TURNING);
}

/// As above, the square sliding under a still sun: the shadows of a
/// still light that `movies` keeps from frame to frame follow a moving
/// blocker.
#[test]
fn every_method_shades_a_plane_under_a_sliding_square_as_the_closed_form() {
    every_method_matches_the_closed_form(&SLIDING);
}

fn every_method_matches_the_closed_form(frames: &[Sky]) {
    let size = 24;
    let s = plane_under_a_square(frames);
    let settled: Vec<_> = (frames.iter())
        .map(|&sky| settled_pixels(&s, size, sky))
        .collect();
    for frame in &settled {
        let shadowed = frame.iter().filter(|(_, v)| *v == 0.0).count();
        let lit = frame.iter().filter(|(_, v)| *v > 0.0).count();
        assert!(
            shadowed >= 4 && lit >= 100,
            "{shadowed} shadowed, {lit} lit"
        );
    }
    let lit = ALBEDO * FRAC_1_PI * E;
    for method in ["path", "ic", "trc", "tcg", "movies"] {
        let films = render(s.clone(), method, size, frames.len() as u32);
        for (f, (film, settled)) in films.iter().zip(&settled).enumerate() {
            for &((x, y), expected) in settled {
                let got = film.get(x, y);
                let off = (got - Vec3::splat(expected)).abs().max_element();
                assert!(
                    off <= 0.02 * expected.max(0.05 * lit),
                    "{method}, frame {f}, pixel ({x}, {y}): {got} against {expected}"
                );
            }
        }
    }
}

/// Under a still sun over a still square, `movies` keeps every shadow:
/// after its first frame it traces no shadow ray, and its texels are the
/// same (the sun's shadow rays reach past the scene, where no box of
/// still lights holds them; a moving blocker is checked against each).
#[test]
fn movies_keeps_the_shadows_of_a_still_sun() {
    let s = plane_under_a_square(&TURNING[..1]);
    let mut movies = TextureMovies::new(MoviesSettings::default());
    let mut r = common::cpu_renderer(
        s,
        Box::new(TextureMovies::new(MoviesSettings::default())),
        16,
    );
    let mut texels = Vec::new();
    for f in 0..3 {
        r.with_frame_context(f, |ctx| movies.render_frame(ctx));
        let shadows = movies.last_shadow_counts();
        assert!(shadows.kept > 0 || f == 0, "frame {f}: {shadows:?}");
        assert_eq!(shadows.traced == 0, f > 0, "frame {f}: {shadows:?}");
        texels.push(
            movies
                .movies()
                .map(|m| m.texels.clone())
                .collect::<Vec<_>>(),
        );
    }
    assert!(texels[1] == texels[0] && texels[2] == texels[0]);
}

/// A white wall beside the plane sends part of the sun's light back onto
/// it: indirect light, which `ic`, `trc`, `tcg` and `movies` cache, and
/// which changes when the sun turns. Each method's frames against `path`
/// at 1024 spp, by relative RMSE: 0.021–0.033 measured (`tcg` 0.076 and
/// 0.124 at frames 1 and 2 while its stale samples did not see a sun
/// turn: what arrives from every direction stays the same). The wall's
/// normals face the sun, then away from it (rendering is two-sided, but
/// `movies` solves its global pass on the side it chooses: it solved the
/// wall's front, dark when it faces away, 0.25, until a flat part with
/// nothing straight behind it was solved on the camera's side).
#[test]
fn a_turning_sun_lights_a_corner_as_path_does() {
    for facing_the_sun in [true, false] {
        let s = sunlit_corner(facing_the_sun, 3.0);
        let size = 16;
        let reference = {
            let settings = method_settings("path", Some(("spp", "1024"))).unwrap();
            let mut r = common::cpu_renderer(s.clone(), settings.instantiate(), size);
            (0..3).map(|f| r.render_frame(f)).collect::<Vec<_>>()
        };
        for method in ["ic", "trc", "tcg", "movies"] {
            let films = render(s.clone(), method, size, 3);
            for (f, (film, reference)) in films.iter().zip(&reference).enumerate() {
                let e = rel_rmse(film, reference);
                let case = format!("{method}, wall facing the sun {facing_the_sun}, frame {f}");
                println!("{case}: relative RMSE {e:.4}");
                assert!(e < 0.05, "{case}: relative RMSE {e}");
            }
        }
    }
}

/// A white ground `2·half` across (two triangles) and a wall 6 m wide and
/// 3 m high on it at x = 1, its normals facing −X (`facing_the_sun`) or
/// +X, lit by a sun that turns over three frames, always on the −X side
/// of the wall; seen from that side, looking down at the wall's foot.
fn sunlit_corner(facing_the_sun: bool, half: f32) -> Scene {
    sunlit_corner_seen_along(facing_the_sun, half, Vec3::new(1.0, -0.6, 0.0))
}

/// [`sunlit_corner`] seen from the same place along `look`.
fn sunlit_corner_seen_along(facing_the_sun: bool, half: f32, look: Vec3) -> Scene {
    let mut plane = ground(half, 0);
    let (u, v) = (Vec3::Z * 6.0, Vec3::Y * 3.0);
    let (u, v) = if facing_the_sun { (u, v) } else { (v, u) };
    push_quad(&mut plane, Vec3::new(1.0, 0.0, -3.0), u, v, 0);
    let eye = Vec3::new(-2.0, 2.0, 0.0);
    let materials = vec![Material::diffuse("white", Vec3::splat(0.8))];
    let mut s = scene(vec![plane], materials, vec![], eye, look, 1.2, vec![]);
    let directions = [
        Vec3::new(0.9, -0.5, 0.2),
        Vec3::new(0.6, -1.0, -0.3),
        Vec3::new(0.3, -1.0, -0.6),
    ];
    add_sun(&mut s, E, &directions);
    s
}

/// The corner on grounds 60 m and 600 m across, still two triangles, and
/// at 50 m seen looking level, the sky above the wall. `movies` grids a
/// triangle at most `MAX_GRID` cells an edge and gave a movie at most
/// 2,048 texels along a triangle's edge: such a ground was one coarse grid
/// where the wall bounces light onto it (`movies` 0.055 and 0.075 at
/// frame 0, `ic` 0.018), and its texels, 41 cm at 600 m, blurred the
/// wall's shadow along its foot. Now the global pass splits a large
/// triangle where the camera sees it (`movies::pieces`) and a movie's
/// patches go down to texels as fine as asked (`patch::MAX_LEVEL`):
/// measured 0.016 and 0.020. Looking level, a ray that met the sky made
/// the grid spacing a 32nd of the whole scene (2.2 m): 0.057 before, now
/// 0.022, `ic` 0.021 (`global::meshing_size`).
#[test]
fn movies_on_a_large_ground_of_two_triangles() {
    let level = Vec3::new(1.0, -0.1, 0.0);
    for (half, look) in [(30.0, None), (300.0, None), (25.0, Some(level))] {
        let s = match look {
            Some(look) => sunlit_corner_seen_along(true, half, look),
            None => sunlit_corner(true, half),
        };
        let settings = method_settings("path", Some(("spp", "1024"))).unwrap();
        let reference = common::cpu_renderer(s.clone(), settings.instantiate(), 16).render_frame(0);
        for method in ["ic", "movies"] {
            let e = rel_rmse(&render(s.clone(), method, 16, 1)[0], &reference);
            let case = format!(
                "ground {} m across, looking level {}",
                2.0 * half,
                look.is_some()
            );
            println!("{case}, {method}: relative RMSE {e:.4}");
            assert!(e < 0.03, "{case}, {method}: relative RMSE {e}");
        }
    }
}

/// A camera that starts 100 m away over the 600 m ground, looking
/// straight down, and comes to look at the corner at frame 1: the global
/// pass, meshed once, splits the ground where the camera looks over the
/// whole animation, not only where it starts. Refined towards time 0's
/// view alone, frame 1 was measured at 0.065 relative RMSE against `path`
/// at 1024 spp; now 0.030 (`ic` 0.019).
#[test]
fn movies_splits_a_large_ground_where_a_travelling_camera_looks() {
    let mut s = sunlit_corner(true, 300.0);
    let camera = s.camera.node;
    let Trs {
        translation: eye,
        rotation: look,
        ..
    } = s.nodes[camera].rest;
    let times = vec![0.0, 1.0 / DEFAULT_FPS];
    let step = |property, values| Channel {
        node: camera,
        property,
        interpolation: Interpolation::Step,
        times: times.clone(),
        values,
    };
    let down = Quat::from_rotation_arc(Vec3::NEG_Z, Vec3::NEG_Y);
    s.animation.channels.extend([
        step(
            Property::Translation,
            vec![(eye + Vec3::Z * 100.0).extend(0.0), eye.extend(0.0)],
        ),
        step(Property::Rotation, vec![Vec4::from(down), Vec4::from(look)]),
    ]);
    let settings = method_settings("path", Some(("spp", "1024"))).unwrap();
    let mut path = common::cpu_renderer(s.clone(), settings.instantiate(), 16);
    let reference = path.render_frame(1);
    for method in ["ic", "movies"] {
        let e = rel_rmse(&render(s.clone(), method, 16, 2)[1], &reference);
        println!("camera come to the corner, {method}: relative RMSE {e:.4}");
        assert!(e < 0.04, "{method}: relative RMSE {e}");
    }
}

/// Where a sun's node is does not matter, only which way it turns: a sun
/// carried along by its node (a translation key per frame) renders the
/// same frames, bit for bit, as one held still, with every method, and
/// no method traces more rays for it at the second frame: `trc` and `tcg`
/// keep work where the lights of consecutive frames are the same (a sun's
/// place taken as its node's made it a moving light), and `movies` keeps
/// the shadows of the lights the animation does not move or turn
/// (`Scene::moving_lights`; it took a sun on a moving node as moving and
/// traced its shadow rays again: 68,032 rays at frame 1 against 2,304).
#[test]
fn a_sun_carried_by_a_moving_node_renders_as_a_still_one() {
    let still = { plane_under_a_square(&TURNING[..1]) };
    let mut carried = still.clone();
    carried.animation.channels.push(Channel {
        node: carried.lights[0].node,
        property: Property::Translation,
        interpolation: Interpolation::Linear,
        times: vec![0.0, 1.0 / DEFAULT_FPS],
        values: vec![Vec4::ZERO, Vec4::new(5.0, 1.0, -3.0, 0.0)],
    });
    for method in ["path", "ic", "trc", "tcg", "movies"] {
        let a = render_counting_rays(still.clone(), method, 12, 2);
        let b = render_counting_rays(carried.clone(), method, 12, 2);
        for (f, ((a, a_rays), (b, b_rays))) in a.iter().zip(&b).enumerate() {
            assert!(a.pixels == b.pixels, "{method}, frame {f}");
            assert_eq!(a_rays, b_rays, "{method}, frame {f}: rays traced");
        }
    }
}

/// [`render`], with the rays each frame traced.
fn render_counting_rays(s: Scene, method: &str, size: u32, frames: u32) -> Vec<(Film, u64)> {
    let settings = method_settings(method, None).unwrap();
    let mut method = settings.instantiate();
    let mut r = common::cpu_renderer(s, settings.instantiate(), size);
    (0..frames)
        .map(|f| {
            r.with_frame_context(f, |ctx| {
                let before = ctx.backend.ray_counts().total();
                let film = method.render_frame(ctx);
                (film, ctx.backend.ray_counts().total() - before)
            })
        })
        .collect()
}
