//! Built-in scenes: the test scenes of the papers in the shared `papers/`
//! folder, rebuilt from their descriptions so that the renderer has animated
//! test content without any file (DESIGN.md, "Scenes").
//!
//! Every scene is a closed room around its camera (nothing escapes to black
//! background, which keeps the light transport comparable between methods),
//! every object sits on its own node, and only moving objects have animation
//! channels, so that the renderer can treat the rest as static. Motions are
//! sampled at every frame (24 fps) with `LINEAR` keys: a smooth path is then
//! exact at frame times, and paths are periodic so that a long render loops.
//!
//! Textures are not supported, so patterns (the tiled floor of
//! `moving-light`) are made of separate quads with their own materials.
//!
//! The scenes are here; the parts they share (the box of the TVCG 2007
//! scenes, the balls, the furniture) in `parts`, the meshes they are made
//! of in `geometry`, and the scene builder and animation tracks in
//! `builder`.

use super::{Material, Mesh, Scene, SceneError, Trs, DEFAULT_FPS};
use glam::{Quat, Vec3};
use std::f32::consts::{FRAC_PI_2, PI, TAU};

mod builder;
mod geometry;
mod parts;

use builder::{at, rotation_track, translation_track, trs, Builder};
use geometry::{cuboid, light_panel, push_box, uv_sphere, Facing};
use parts::{
    box_ceiling_light, box_room, box_room_with, box_wall_materials, chair, space_car,
    sphere_palette, table, Bounce,
};

/// Names of the built-in scenes; the first is the default scene.
pub const NAMES: &[&str] = &[
    "cube-in-box",
    "moving-light",
    "spheres",
    "glossy-cornell",
    "chairs-room",
];

/// Builds the built-in scene `name` (one of [`NAMES`]).
pub fn build(name: &str) -> Result<Scene, SceneError> {
    match name {
        "cube-in-box" => Ok(cube_in_box()),
        "moving-light" => Ok(moving_light()),
        "spheres" => Ok(spheres()),
        "glossy-cornell" => Ok(glossy_cornell()),
        "chairs-room" => Ok(chairs_room()),
        _ => Err(SceneError::UnknownBuiltin(name.to_string())),
    }
}

// ---------------------------------------------------------------------------
// The shared box of the TVCG 2007 scenes, laid out as the shared
// `cube_in_box.glb` / `spheres.glb` files: x ∈ [−1, 1], y ∈ [0, 2], the back
// wall at z = −1, and the room continued to a front wall at z = 3 behind the
// camera (z = 2.9) so that it is closed.

const WHITE: Vec3 = Vec3::new(0.725, 0.71, 0.68);
const RED: Vec3 = Vec3::new(0.63, 0.065, 0.05);
const GREEN: Vec3 = Vec3::new(0.14, 0.45, 0.091);
/// Radiance of the ceiling light of the shared files (emissive factor
/// (1, 0.9, 0.75) × emissive strength 30).
const LIGHT_RADIANCE: Vec3 = Vec3::new(30.0, 27.0, 22.5);
const BOX_MIN: Vec3 = Vec3::new(-1.0, 0.0, -1.0);
const BOX_MAX: Vec3 = Vec3::new(1.0, 2.0, 3.0);
const BOX_CAMERA: Vec3 = Vec3::new(0.0, 1.0, 2.9);
const BOX_YFOV_DEGREES: f32 = 50.0;
/// Height of the ceiling light: 2 cm under the ceiling, as in the shared files.
const BOX_LIGHT_Y: f32 = 1.98;
/// Side of the square ceiling light (0.25 m², as in the shared files).
const BOX_LIGHT_SIZE: f32 = 0.5;

/// Cube in a Box (TVCG 2007, Fig. 12a; Table 2: 24 polygons, 400 frames):
/// the diffuse box of the shared `cube_in_box.glb` (white floor, ceiling and
/// back wall, red left and green right wall, a 0.5 m square light under the
/// ceiling) with a 0.4 m cube that slides across the floor and back while
/// turning once about its vertical axis. 26 triangles, 400 frames (16.7 s
/// at 24 fps); the path is periodic, so frame 400 would equal frame 0.
fn cube_in_box() -> Scene {
    const FRAMES: u32 = 400;
    let mut b = Builder::new("cube-in-box", FRAMES);
    box_room(&mut b, None);
    box_ceiling_light(&mut b);
    let gold = b.material(Material::diffuse("cube", Vec3::new(0.8, 0.7, 0.3)));
    let cube = b.object("cube", Trs::default(), cuboid(Vec3::splat(0.2), gold));
    let period = FRAMES as f32 / DEFAULT_FPS;
    // Starting at the centre at full speed (rather than at rest at one end)
    // makes even the first few frames of the animation dynamic.
    b.animate(translation_track(cube, FRAMES, |t| {
        Vec3::new(0.6 * (TAU * t / period).sin(), 0.2, -0.2)
    }));
    b.animate(rotation_track(cube, FRAMES, |t| {
        Quat::from_rotation_y(TAU * t / period)
    }));
    b.finish()
}

/// Moving Light (TVCG 2007, Fig. 12b; Table 2: 24 polygons, 400 frames): the
/// box of `cube-in-box` with a tiled floor (an 8 × 16 checkerboard of 0.25 m
/// light and dark quads, the tiles highlighting changes of indirect light)
/// and a static cube; the ceiling light moves along a figure-eight under the
/// ceiling. 280 triangles, 400 frames (16.7 s at 24 fps), periodic.
fn moving_light() -> Scene {
    const FRAMES: u32 = 400;
    let mut b = Builder::new("moving-light", FRAMES);
    let tiles = [
        b.material(Material::diffuse("tile_light", Vec3::new(0.8, 0.78, 0.74))),
        b.material(Material::diffuse("tile_dark", Vec3::new(0.15, 0.15, 0.18))),
    ];
    box_room(&mut b, Some(tiles));
    let light = box_ceiling_light(&mut b);
    let gold = b.material(Material::diffuse("cube", Vec3::new(0.8, 0.7, 0.3)));
    let rest = trs(Vec3::new(-0.3, 0.2, -0.3), Quat::from_rotation_y(0.5));
    b.object("cube", rest, cuboid(Vec3::splat(0.2), gold));
    let period = FRAMES as f32 / DEFAULT_FPS;
    b.animate(translation_track(light, FRAMES, |t| {
        let phase = TAU * t / period;
        Vec3::new(0.6 * phase.sin(), BOX_LIGHT_Y, 0.4 * (2.0 * phase).sin())
    }));
    b.finish()
}

/// Spheres (TVCG 2007, Fig. 12e; Table 2: 64K polygons, 200 frames): 66
/// bouncing spheres, diffuse and glossy (modified Phong, n = 40, 100, 200),
/// in the box of `cube-in-box` with a glossy back wall (n = 100), like the
/// shared `spheres.glb` but with the paper's sphere count. Each sphere is a
/// 32 × 16 UV sphere (960 triangles) bouncing on the floor on a parabola,
/// with its own radius, height, period and phase. 63 374 triangles, 200
/// frames (8.3 s at 24 fps).
fn spheres() -> Scene {
    const FRAMES: u32 = 200;
    const COLUMNS: usize = 11;
    const ROWS: usize = 6;
    let mut b = Builder::new("spheres", FRAMES);
    let back = b.material(Material::glossy(
        "back_wall_glossy",
        WHITE * 0.5,
        Vec3::splat(0.4),
        100.0,
    ));
    let walls = box_wall_materials(&mut b);
    let [red, green, white] = walls;
    box_room_with(
        &mut b,
        [
            Some(red),
            Some(green),
            Some(white),
            Some(white),
            Some(back),
            Some(white),
        ],
        None,
    );
    box_ceiling_light(&mut b);
    let palette = sphere_palette(&mut b);
    let unit = uv_sphere(32, 16, 0);
    for i in 0..COLUMNS * ROWS {
        let (column, row) = (i % COLUMNS, i / COLUMNS);
        let x = -0.9 + 1.8 * column as f32 / (COLUMNS - 1) as f32;
        let z = -0.85 + 1.7 * row as f32 / (ROWS - 1) as f32;
        let bounce = Bounce::varied(i as u64);
        let mut mesh = unit.clone();
        mesh.materials.fill(palette[i % palette.len()]);
        let rest = Trs {
            scale: Vec3::splat(bounce.radius),
            ..Trs::default()
        };
        let node = b.object(&format!("sphere{i}"), rest, mesh);
        b.animate(translation_track(node, FRAMES, |t| {
            Vec3::new(x, bounce.height_at(t), z)
        }));
    }
    b.finish()
}

/// Glossy Cornell box (equivalent area light sources paper, Fig. 12): the
/// Cornell box with a glossy back wall (modified Phong n = 100), a glossy
/// tall block (n = 200) and a glossy short cube (n = 40), in the closed box
/// of `cube-in-box` (blocks sized as the classic Cornell box scaled to it).
/// The paper's scene is still; here the short cube slides back and forth
/// along z while turning, so that the scene is animated. 38 triangles, 240
/// frames (10 s at 24 fps), periodic.
fn glossy_cornell() -> Scene {
    const FRAMES: u32 = 240;
    let mut b = Builder::new("glossy-cornell", FRAMES);
    let back = b.material(Material::glossy(
        "back_wall_n100",
        WHITE * 0.5,
        Vec3::splat(0.5),
        100.0,
    ));
    let walls = box_wall_materials(&mut b);
    box_room_with(
        &mut b,
        [
            Some(walls[0]),
            Some(walls[1]),
            Some(walls[2]),
            Some(walls[2]),
            Some(back),
            Some(walls[2]),
        ],
        None,
    );
    box_ceiling_light(&mut b);
    let tall_material = b.material(Material::glossy(
        "tall_block_n200",
        Vec3::splat(0.35),
        Vec3::splat(0.5),
        200.0,
    ));
    let short_material = b.material(Material::glossy(
        "short_cube_n40",
        Vec3::splat(0.4),
        Vec3::splat(0.5),
        40.0,
    ));
    let tall_rest = trs(Vec3::new(-0.4, 0.6, -0.35), Quat::from_rotation_y(0.3));
    b.object(
        "tall_block",
        tall_rest,
        cuboid(Vec3::new(0.3, 0.6, 0.3), tall_material),
    );
    let short = b.object(
        "short_cube",
        Trs::default(),
        cuboid(Vec3::splat(0.3), short_material),
    );
    let period = FRAMES as f32 / DEFAULT_FPS;
    b.animate(translation_track(short, FRAMES, |t| {
        Vec3::new(0.42, 0.3, 0.1 + 0.35 * (TAU * t / period).sin())
    }));
    b.animate(rotation_track(short, FRAMES, |t| {
        Quat::from_rotation_y(-0.3 - TAU * t / period)
    }));
    b.finish()
}

/// Table and chairs room (texture movies paper, Fig. 8 right column and
/// Table 2: Shirley's table-and-four-chairs scene, 400 frames, a "space car"
/// crossing the room under two static and two dynamic lights): a 5 × 2.6 ×
/// 5 m room with a table and four chairs made of boxes, a hovering car (two
/// boxes) driving an ellipse around the table, two static ceiling panels and
/// two moving lights: an emissive panel running along a ceiling rail (area
/// light) and a point light (`PunctualLight`) circling twice over the table.
/// 390 triangles, 400 frames (16.7 s at 24 fps), periodic.
fn chairs_room() -> Scene {
    const FRAMES: u32 = 400;
    const HALF: f32 = 2.5;
    const HEIGHT: f32 = 2.6;
    let mut b = Builder::new("chairs-room", FRAMES);
    let wall = b.material(Material::diffuse("wall", Vec3::new(0.7, 0.68, 0.62)));
    let accent = b.material(Material::diffuse("wall_blue", Vec3::new(0.25, 0.35, 0.6)));
    let floor = b.material(Material::diffuse("floor_wood", Vec3::new(0.45, 0.3, 0.18)));
    let ceiling = b.material(Material::diffuse("ceiling", Vec3::splat(0.8)));
    let mut room = Mesh::default();
    push_box(
        &mut room,
        Vec3::new(-HALF, 0.0, -HALF),
        Vec3::new(HALF, HEIGHT, HALF),
        Facing::Inward,
        [
            Some(accent),
            Some(wall),
            Some(floor),
            Some(ceiling),
            Some(wall),
            Some(wall),
        ],
    );
    b.object("room", Trs::default(), room);

    let wood = b.material(Material::diffuse("table_wood", Vec3::new(0.55, 0.35, 0.2)));
    b.object("table", Trs::default(), table(wood));
    let upholstery = b.material(Material::diffuse("chair", Vec3::new(0.6, 0.22, 0.15)));
    // Chairs face the table: their local +Z (the sitter's front) points to it.
    let chairs = [
        (Vec3::new(0.0, 0.0, -0.75), 0.0),
        (Vec3::new(0.0, 0.0, 0.75), PI),
        (Vec3::new(1.0, 0.0, 0.0), -FRAC_PI_2),
        (Vec3::new(-1.0, 0.0, 0.0), FRAC_PI_2),
    ];
    for (i, (position, yaw)) in chairs.into_iter().enumerate() {
        b.object(
            &format!("chair{i}"),
            trs(position, Quat::from_rotation_y(yaw)),
            chair(upholstery),
        );
    }

    let panel = b.material(Material::emitter(
        "ceiling_panel",
        Vec3::new(20.0, 19.0, 17.0),
    ));
    let panel_y = HEIGHT - 0.02;
    for (i, x) in [-1.2, 1.2].into_iter().enumerate() {
        b.object(
            &format!("static_light{i}"),
            at(Vec3::new(x, panel_y, 0.0)),
            light_panel(0.5, panel),
        );
    }
    let rail = b.material(Material::emitter("rail_light", Vec3::new(30.0, 27.0, 22.5)));
    let rail_light = b.object("rail_light", Trs::default(), light_panel(0.3, rail));
    let bulb = b.point_light("bulb", Vec3::new(1.5, 1.3, 1.0));

    let car_mesh = space_car(&mut b);
    let car = b.object("car", Trs::default(), car_mesh);
    let camera = trs(Vec3::new(0.0, 1.7, 2.4), Quat::from_rotation_x(-0.3));
    b.camera(camera, 55f32.to_radians());

    let period = FRAMES as f32 / DEFAULT_FPS;
    let (a, c) = (1.75, 1.55);
    b.animate(translation_track(car, FRAMES, |t| {
        let phase = TAU * t / period;
        Vec3::new(a * phase.sin(), 0.0, c * phase.cos())
    }));
    // Heading along the velocity (a·cos φ, 0, −c·sin φ); the car's front is +X.
    b.animate(rotation_track(car, FRAMES, |t| {
        let phase = TAU * t / period;
        Quat::from_rotation_y((c * phase.sin()).atan2(a * phase.cos()))
    }));
    b.animate(translation_track(rail_light, FRAMES, |t| {
        Vec3::new(1.8 * (TAU * t / period).sin(), panel_y, -1.5)
    }));
    b.animate(translation_track(bulb, FRAMES, |t| {
        let phase = 2.0 * TAU * t / period;
        Vec3::new(1.2 * phase.cos(), 1.9, 1.2 * phase.sin())
    }));
    b.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;
    use crate::scene::{Snapshot, Triangle};

    fn all_scenes() -> Vec<Scene> {
        NAMES.iter().map(|name| build(name).unwrap()).collect()
    }

    /// Times spread over the animation, both ends included.
    fn sample_times(scene: &Scene) -> Vec<f32> {
        let end = scene.frame_count as f32 / DEFAULT_FPS;
        (0..=8).map(|i| end * i as f32 / 8.0).collect()
    }

    /// Möller–Trumbore: distance along `dir` to the triangle, if hit. The
    /// barycentric bounds get a little slack so that rays through a shared
    /// edge still hit one of its two triangles.
    fn intersect(origin: Vec3, dir: Vec3, tri: &Triangle) -> Option<f32> {
        let (e1, e2) = (tri.p[1] - tri.p[0], tri.p[2] - tri.p[0]);
        let p = dir.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            return None;
        }
        let s = origin - tri.p[0];
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = dir.dot(q) / det;
        let t = e2.dot(q) / det;
        let slack = 1e-5;
        (u >= -slack && v >= -slack && u + v <= 1.0 + slack && t > 1e-4).then_some(t)
    }

    fn uniform_direction(rng: &mut Rng) -> Vec3 {
        let (a, b) = (rng.next_f32(), rng.next_f32());
        let z = 1.0 - 2.0 * a;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = TAU * b;
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    fn object_triangles<'a>(scene: &Scene, snap: &'a Snapshot, name: &str) -> Vec<&'a Triangle> {
        let object = scene.objects.iter().position(|o| o.name == name).unwrap();
        snap.triangles
            .iter()
            .zip(&snap.tri_object)
            .filter(|(_, &o)| o as usize == object)
            .map(|(t, _)| t)
            .collect()
    }

    #[test]
    fn every_name_builds_a_valid_animated_scene() {
        for (name, scene) in NAMES.iter().zip(all_scenes()) {
            assert_eq!(scene.name, *name);
            assert!(
                scene.frame_count >= 2,
                "{name}: {} frames",
                scene.frame_count
            );
            let triangles: usize = scene.objects.iter().map(|o| o.mesh.triangles.len()).sum();
            assert!(triangles <= 100_000, "{name}: {triangles} triangles");
            let emitters = scene.materials.iter().any(Material::is_emissive);
            assert!(emitters || !scene.lights.is_empty(), "{name}: no light");
            for channel in &scene.animation.channels {
                channel.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
            }
            for object in &scene.objects {
                let mesh = &object.mesh;
                assert_eq!(
                    mesh.normals.len(),
                    mesh.positions.len(),
                    "{name}/{}",
                    object.name
                );
                assert_eq!(
                    mesh.materials.len(),
                    mesh.triangles.len(),
                    "{name}/{}",
                    object.name
                );
                assert!(mesh
                    .materials
                    .iter()
                    .all(|&m| (m as usize) < scene.materials.len()));
                let vertices = mesh.positions.len() as u32;
                assert!(mesh.triangles.iter().flatten().all(|&i| i < vertices));
            }
            println!(
                "{name}: {triangles} triangles, {} frames, {} objects, {} channels",
                scene.frame_count,
                scene.objects.len(),
                scene.animation.channels.len()
            );
        }
    }

    #[test]
    fn unknown_name_is_an_error() {
        assert!(
            matches!(build("no-such-scene"), Err(SceneError::UnknownBuiltin(n)) if n == "no-such-scene")
        );
        assert!(matches!(
            Scene::builtin(""),
            Err(SceneError::UnknownBuiltin(_))
        ));
    }

    #[test]
    fn default_scene_is_cube_in_box() {
        assert_eq!(NAMES[0], "cube-in-box");
    }

    #[test]
    fn snapshots_are_finite_over_the_animation() {
        for scene in all_scenes() {
            for t in sample_times(&scene) {
                let snap = scene.snapshot(t);
                for tri in &snap.triangles {
                    let finite = tri.p.iter().chain(&tri.n).all(|v| v.is_finite());
                    assert!(finite, "{} at t={t}: non-finite vertex", scene.name);
                    assert!(
                        tri.area() > 0.0,
                        "{} at t={t}: degenerate triangle",
                        scene.name
                    );
                }
                for light in &snap.lights {
                    assert!(light.position.is_finite() && light.direction.is_finite());
                }
                assert!(snap.camera.position.is_finite() && snap.camera.basis.is_finite());
            }
        }
    }

    /// Dynamic objects move, and static objects (no channels) stay put: an
    /// object is dynamic exactly when its geometry differs between times.
    #[test]
    fn only_animated_objects_move() {
        for scene in all_scenes() {
            let times = sample_times(&scene);
            let snaps: Vec<Snapshot> = times.iter().map(|&t| scene.snapshot(t)).collect();
            let mut moving = 0;
            for (id, object) in scene.objects.iter().enumerate() {
                let geometry = |snap: &Snapshot| -> Vec<[Vec3; 3]> {
                    let tris = object_triangles(&scene, snap, &object.name);
                    tris.iter().map(|t| t.p).collect()
                };
                let first = geometry(&snaps[0]);
                let moves = snaps[1..].iter().any(|s| geometry(s) != first);
                assert_eq!(
                    moves,
                    scene.object_is_dynamic(id),
                    "{}/{}: dynamic flag disagrees with motion",
                    scene.name,
                    object.name
                );
                moving += usize::from(moves);
            }
            let lights_move = snaps[1..].iter().any(|s| {
                s.lights
                    .iter()
                    .zip(&snaps[0].lights)
                    .any(|(a, b)| a.position != b.position)
            });
            assert!(moving > 0 || lights_move, "{}: nothing moves", scene.name);
            // Triangle ids are stable: the static prefix is bit-identical.
            for snap in &snaps[1..] {
                let n = snap.static_count;
                assert_eq!(n, snaps[0].static_count);
                let same = snap
                    .triangles
                    .range(0..n)
                    .zip(snaps[0].triangles.range(0..n));
                assert!(same.into_iter().all(|(a, b)| a.p == b.p && a.n == b.n));
            }
        }
    }

    /// From the camera, every direction hits the room from the inside: the
    /// room is closed around the camera and its walls face inward.
    #[test]
    fn room_encloses_camera_and_faces_inward() {
        let mut rng = Rng::from_seed(7, 11);
        for scene in all_scenes() {
            let snap = scene.snapshot(0.0);
            let room = object_triangles(&scene, &snap, "room");
            let eye = snap.camera.position;
            for _ in 0..1000 {
                let dir = uniform_direction(&mut rng);
                let nearest = room
                    .iter()
                    .filter_map(|tri| intersect(eye, dir, tri).map(|t| (t, tri)))
                    .min_by(|a, b| a.0.total_cmp(&b.0));
                let (_, tri) =
                    nearest.unwrap_or_else(|| panic!("{}: ray {dir} escapes", scene.name));
                assert!(
                    tri.geometric_normal().dot(dir) < 0.0,
                    "{}: back face toward {dir}",
                    scene.name
                );
            }
        }
    }

    /// Emission is one-sided: every ceiling light's front looks down.
    #[test]
    fn emitters_face_down_into_the_room() {
        for scene in all_scenes() {
            let snap = scene.snapshot(0.0);
            let emissive = |m: &u32| scene.materials[*m as usize].is_emissive();
            let mut count = 0;
            for (tri, _) in snap
                .triangles
                .iter()
                .zip(&snap.tri_material)
                .filter(|(_, m)| emissive(m))
            {
                assert!(
                    tri.geometric_normal().y < -0.999,
                    "{}: emitter faces up",
                    scene.name
                );
                assert!(tri.shading_normal(0.3, 0.3).y < -0.999);
                count += 1;
            }
            assert!(count > 0 || !scene.lights.is_empty());
        }
    }

    #[test]
    fn materials_conserve_energy() {
        for scene in all_scenes() {
            for m in &scene.materials {
                let total = m.diffuse + m.specular;
                assert!(
                    total.max_element() <= 1.0,
                    "{}/{}: kd+ks = {total}",
                    scene.name,
                    m.name
                );
                assert!(m.diffuse.min_element() >= 0.0 && m.specular.min_element() >= 0.0);
                assert!(m.exponent.is_finite() && m.exponent >= 1.0);
            }
        }
    }

    #[test]
    fn cube_in_box_matches_the_shared_file_layout() {
        let scene = build("cube-in-box").unwrap();
        assert_eq!(scene.frame_count, 400);
        let snap = scene.snapshot(0.0);
        assert_eq!(snap.camera.position, Vec3::new(0.0, 1.0, 2.9));
        assert!((snap.camera.yfov - 50f32.to_radians()).abs() < 1e-6);
        assert!((snap.camera.direction(0.5, 0.5, 1.0) - Vec3::NEG_Z).length() < 1e-6);
        let light = scene.materials.iter().find(|m| m.is_emissive()).unwrap();
        assert_eq!(light.emission, LIGHT_RADIANCE);
        let emitters: Vec<_> = snap
            .triangles
            .iter()
            .zip(&snap.tri_material)
            .filter(|(_, m)| scene.materials[**m as usize].is_emissive())
            .collect();
        let area: f32 = emitters.iter().map(|(t, _)| t.area()).sum();
        assert!((area - 0.25).abs() < 1e-5);
        assert!(emitters
            .iter()
            .all(|(t, _)| t.p.iter().all(|p| p.y == 1.98)));
        let triangles = snap.triangles.len();
        assert_eq!(triangles, 26, "room 12 + light 2 + cube 12");
    }

    #[test]
    fn helpers_wind_outward_with_matching_normals() {
        let meshes = [
            cuboid(Vec3::new(0.3, 0.5, 0.2), 0),
            uv_sphere(32, 16, 0),
            uv_sphere(5, 3, 0),
        ];
        for mesh in &meshes {
            for tri in &mesh.triangles {
                let p = tri.map(|i| mesh.positions[i as usize]);
                let normal = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
                let centroid = (p[0] + p[1] + p[2]) / 3.0;
                assert!(normal.dot(centroid) > 0.0, "triangle faces inward");
                for i in tri {
                    assert!(
                        mesh.normals[*i as usize].dot(normal) > 0.5,
                        "vertex normal disagrees"
                    );
                }
            }
        }
        assert_eq!(meshes[1].triangles.len(), 2 * 32 * 15);
        assert!(meshes[1]
            .normals
            .iter()
            .all(|n| (n.length() - 1.0).abs() < 1e-5));
        let mut room = Mesh::default();
        push_box(
            &mut room,
            Vec3::splat(-1.0),
            Vec3::splat(1.0),
            Facing::Inward,
            [Some(0); 6],
        );
        for tri in &room.triangles {
            let p = tri.map(|i| room.positions[i as usize]);
            assert!((p[1] - p[0]).cross(p[2] - p[0]).dot(p[0] + p[1] + p[2]) < 0.0);
        }
    }
}
