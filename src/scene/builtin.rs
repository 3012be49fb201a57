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

use super::animation::{linear_rotation, linear_translation, Channel};
use super::{
    Animation, CameraDef, Material, Mesh, Node, Object, PunctualLight, Scene, SceneError, Trs,
    DEFAULT_FPS,
};
use crate::sampling::mix64;
use glam::{Quat, Vec3};
use std::f32::consts::{FRAC_PI_2, PI, TAU};

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

// ---------------------------------------------------------------------------
// Scene parts.

/// White, red and green diffuse materials of the shared box.
fn box_wall_materials(b: &mut Builder) -> [u32; 3] {
    [
        b.material(Material::diffuse("red", RED)),
        b.material(Material::diffuse("green", GREEN)),
        b.material(Material::diffuse("white", WHITE)),
    ]
}

/// The diffuse shared box and its camera; `tiles` replaces the white floor
/// with a checkerboard of the two materials.
fn box_room(b: &mut Builder, tiles: Option<[u32; 2]>) {
    let [red, green, white] = box_wall_materials(b);
    let floor = if tiles.is_some() { None } else { Some(white) };
    box_room_with(
        b,
        [
            Some(red),
            Some(green),
            floor,
            Some(white),
            Some(white),
            Some(white),
        ],
        tiles,
    );
}

/// The shared box with the given wall materials (order of [`push_box`]),
/// an optional tiled floor, and the camera of the shared files.
fn box_room_with(b: &mut Builder, walls: [Option<u32>; 6], tiles: Option<[u32; 2]>) {
    let mut room = Mesh::default();
    push_box(&mut room, BOX_MIN, BOX_MAX, Facing::Inward, walls);
    if let Some(tiles) = tiles {
        push_checkerboard(&mut room, BOX_MIN, BOX_MAX, 0.25, tiles);
    }
    b.object("room", Trs::default(), room);
    b.camera(at(BOX_CAMERA), BOX_YFOV_DEGREES.to_radians());
}

/// The 0.5 m square light under the ceiling of the shared box; returns its node.
fn box_ceiling_light(b: &mut Builder) -> usize {
    let light = b.material(Material::emitter("light", LIGHT_RADIANCE));
    let panel = light_panel(BOX_LIGHT_SIZE, light);
    b.object("light", at(Vec3::new(0.0, BOX_LIGHT_Y, 0.0)), panel)
}

/// Sphere materials: diffuse colours of the shared `spheres.glb` and glossy
/// ones with the Phong exponents of the papers (kd + ks ≤ 1).
fn sphere_palette(b: &mut Builder) -> Vec<u32> {
    let diffuse = [
        ("red", Vec3::new(0.8, 0.2, 0.2)),
        ("blue", Vec3::new(0.2, 0.6, 0.8)),
        ("yellow", Vec3::new(0.9, 0.7, 0.2)),
        ("green", Vec3::new(0.3, 0.8, 0.3)),
    ];
    let glossy = [
        (
            "glossy_white_n40",
            Vec3::splat(0.5),
            Vec3::splat(0.45),
            40.0,
        ),
        (
            "glossy_purple_n100",
            Vec3::new(0.42, 0.18, 0.48),
            Vec3::splat(0.4),
            100.0,
        ),
        (
            "glossy_metal_n200",
            Vec3::ZERO,
            Vec3::new(0.9, 0.75, 0.5),
            200.0,
        ),
    ];
    let mut palette = Vec::new();
    for (name, colour) in diffuse {
        palette.push(b.material(Material::diffuse(&format!("sphere_{name}"), colour)));
    }
    for (name, kd, ks, n) in glossy {
        palette.push(b.material(Material::glossy(&format!("sphere_{name}"), kd, ks, n)));
    }
    palette
}

/// A bouncing ball: height `radius + apex·4s(1−s)`, `s` the phase within
/// one bounce, touching the floor at `s = 0`.
#[derive(Clone, Copy)]
struct Bounce {
    radius: f32,
    apex: f32,
    period: f32,
    phase: f32,
}

impl Bounce {
    /// Deterministic, varied parameters for ball `i` (hashed, so that
    /// neighbours do not bounce in sync).
    fn varied(i: u64) -> Self {
        let u = |salt: u64| {
            (mix64(i.wrapping_mul(0x9e37_79b9) ^ salt) >> 40) as f32 / (1u64 << 24) as f32
        };
        Bounce {
            radius: 0.05 + 0.03 * u(1),
            apex: 0.3 + 0.8 * u(2),
            period: 0.8 + 0.8 * u(3),
            phase: u(4),
        }
    }

    fn height_at(&self, t: f32) -> f32 {
        let s = (t / self.period + self.phase).fract();
        self.radius + self.apex * 4.0 * s * (1.0 - s)
    }
}

/// Table of Shirley's scene: a 1.4 × 0.9 m top at 0.77 m on four legs.
fn table(material: u32) -> Mesh {
    let mut mesh = Mesh::default();
    let all = [Some(material); 6];
    push_box(
        &mut mesh,
        Vec3::new(-0.7, 0.72, -0.45),
        Vec3::new(0.7, 0.77, 0.45),
        Facing::Outward,
        all,
    );
    for (x, z) in [(-0.6, -0.35), (0.6, -0.35), (-0.6, 0.35), (0.6, 0.35)] {
        let min = Vec3::new(x - 0.03, 0.0, z - 0.03);
        push_box(
            &mut mesh,
            min,
            min + Vec3::new(0.06, 0.72, 0.06),
            Facing::Outward,
            all,
        );
    }
    mesh
}

/// A chair facing +Z: a 0.44 m seat at 0.47 m on four legs, and a back.
fn chair(material: u32) -> Mesh {
    let mut mesh = Mesh::default();
    let all = [Some(material); 6];
    push_box(
        &mut mesh,
        Vec3::new(-0.22, 0.43, -0.22),
        Vec3::new(0.22, 0.47, 0.22),
        Facing::Outward,
        all,
    );
    for (x, z) in [(-0.2, -0.2), (0.2, -0.2), (-0.2, 0.2), (0.2, 0.2)] {
        let min = Vec3::new(x - 0.02, 0.0, z - 0.02);
        push_box(
            &mut mesh,
            min,
            min + Vec3::new(0.04, 0.43, 0.04),
            Facing::Outward,
            all,
        );
    }
    push_box(
        &mut mesh,
        Vec3::new(-0.22, 0.47, -0.22),
        Vec3::new(0.22, 0.95, -0.19),
        Facing::Outward,
        all,
    );
    mesh
}

/// The "very simplified space car": a body and a cabin hovering 17.5 cm over
/// the floor, its front along +X.
fn space_car(b: &mut Builder) -> Mesh {
    let body = b.material(Material::diffuse("car_body", Vec3::new(0.2, 0.5, 0.8)));
    let cabin = b.material(Material::diffuse("car_cabin", Vec3::splat(0.85)));
    let mut mesh = Mesh::default();
    push_box(
        &mut mesh,
        Vec3::new(-0.3, 0.175, -0.15),
        Vec3::new(0.3, 0.325, 0.15),
        Facing::Outward,
        [Some(body); 6],
    );
    push_box(
        &mut mesh,
        Vec3::new(-0.15, 0.325, -0.12),
        Vec3::new(0.15, 0.445, 0.12),
        Facing::Outward,
        [Some(cabin); 6],
    );
    mesh
}

// ---------------------------------------------------------------------------
// Geometry helpers. Front faces are counter-clockwise (glTF), and flat faces
// carry their face normal at every vertex.

/// Appends the parallelogram `origin, origin+u, origin+u+v, origin+v` as two
/// triangles whose front face and normal point along `u × v`.
fn push_quad(mesh: &mut Mesh, origin: Vec3, u: Vec3, v: Vec3, material: u32) {
    let normal = u.cross(v).normalize();
    let base = mesh.positions.len() as u32;
    mesh.positions
        .extend([origin, origin + u, origin + u + v, origin + v]);
    mesh.normals.extend([normal; 4]);
    mesh.triangles
        .extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
    mesh.materials.extend([material; 2]);
}

/// Which way the faces of [`push_box`] look: out of a solid, or into a room.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Facing {
    Outward,
    Inward,
}

/// Appends the faces of the axis-aligned box `[min, max]`. `materials` is
/// indexed −X, +X, −Y, +Y, −Z, +Z (for a room: left, right, floor, ceiling,
/// back, front); `None` leaves that face out.
fn push_box(mesh: &mut Mesh, min: Vec3, max: Vec3, facing: Facing, materials: [Option<u32>; 6]) {
    let size = max - min;
    for axis in 0..3 {
        // Cyclic order: e_b × e_c = e_axis.
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let u = Vec3::AXES[b] * size[b];
        let v = Vec3::AXES[c] * size[c];
        for positive in [false, true] {
            let Some(material) = materials[2 * axis + usize::from(positive)] else {
                continue;
            };
            let mut origin = min;
            if positive {
                origin[axis] = max[axis];
            }
            // The +axis face of a solid and the −axis face of a room look along +axis.
            if positive == (facing == Facing::Outward) {
                push_quad(mesh, origin, u, v, material);
            } else {
                push_quad(mesh, origin, v, u, material);
            }
        }
    }
}

/// A solid box of half extents `half` centred on the origin.
fn cuboid(half: Vec3, material: u32) -> Mesh {
    let mut mesh = Mesh::default();
    push_box(&mut mesh, -half, half, Facing::Outward, [Some(material); 6]);
    mesh
}

/// A square emitter of side `size` centred on the origin, its front (the
/// emitting side) facing down, to hang under a ceiling.
fn light_panel(size: f32, material: u32) -> Mesh {
    let mut mesh = Mesh::default();
    let h = 0.5 * size;
    // X × Z = −Y: the front face looks down.
    push_quad(
        &mut mesh,
        Vec3::new(-h, 0.0, -h),
        Vec3::X * size,
        Vec3::Z * size,
        material,
    );
    mesh
}

/// Tiles the floor (y = `min.y`) of `[min, max]` with `tile`-sized quads
/// facing up, alternating the two materials.
fn push_checkerboard(mesh: &mut Mesh, min: Vec3, max: Vec3, tile: f32, materials: [u32; 2]) {
    let columns = ((max.x - min.x) / tile).round() as usize;
    let rows = ((max.z - min.z) / tile).round() as usize;
    // Vertices are computed from the bounds (not by accumulating `tile`), so
    // that neighbouring tiles share exact edges and the floor has no cracks.
    let x_at = |i: usize| min.x + (max.x - min.x) * i as f32 / columns as f32;
    let z_at = |j: usize| min.z + (max.z - min.z) * j as f32 / rows as f32;
    for j in 0..rows {
        for i in 0..columns {
            let origin = Vec3::new(x_at(i), min.y, z_at(j));
            let u = Vec3::Z * (z_at(j + 1) - z_at(j));
            let v = Vec3::X * (x_at(i + 1) - x_at(i));
            // Z × X = +Y: the tiles face up into the room.
            push_quad(mesh, origin, u, v, materials[(i + j) % 2]);
        }
    }
}

/// A unit UV sphere centred on the origin with smooth normals: `rings`
/// bands from pole to pole, `segments` around +Y, triangle fans at the poles
/// (no degenerate triangles): `2·segments·(rings − 1)` triangles.
fn uv_sphere(segments: u32, rings: u32, material: u32) -> Mesh {
    let point = |theta: f32, phi: f32| {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    };
    let mut positions = vec![Vec3::Y];
    for ring in 1..rings {
        let theta = PI * ring as f32 / rings as f32;
        for segment in 0..segments {
            positions.push(point(theta, TAU * segment as f32 / segments as f32));
        }
    }
    positions.push(-Vec3::Y);
    let south = positions.len() as u32 - 1;
    // Vertex `segment` of ring `ring` (1..rings), wrapping around.
    let vertex = |ring: u32, segment: u32| 1 + (ring - 1) * segments + segment % segments;
    let mut triangles = Vec::new();
    for s in 0..segments {
        // With φ growing and θ (southward) growing, (p, p+φ, p+south) is
        // counter-clockwise seen from outside.
        triangles.push([0, vertex(1, s + 1), vertex(1, s)]);
        for ring in 1..rings - 1 {
            let (a, b) = (vertex(ring, s), vertex(ring, s + 1));
            let (c, d) = (vertex(ring + 1, s), vertex(ring + 1, s + 1));
            triangles.push([a, b, c]);
            triangles.push([b, d, c]);
        }
        triangles.push([vertex(rings - 1, s), vertex(rings - 1, s + 1), south]);
    }
    Mesh {
        normals: positions.clone(),
        materials: vec![material; triangles.len()],
        positions,
        triangles,
    }
}

// ---------------------------------------------------------------------------
// Scene assembly and animation helpers.

fn at(translation: Vec3) -> Trs {
    Trs {
        translation,
        ..Trs::default()
    }
}

fn trs(translation: Vec3, rotation: Quat) -> Trs {
    Trs {
        translation,
        rotation,
        ..Trs::default()
    }
}

/// Time of frame `k` at the default frame rate.
fn frame_time(k: u32) -> f32 {
    k as f32 / DEFAULT_FPS
}

/// A translation channel with a `LINEAR` key at every frame `0..=frames`
/// from `path(t)`: exact at frame times, piecewise linear in between.
fn translation_track(node: usize, frames: u32, path: impl Fn(f32) -> Vec3) -> Channel {
    let keys: Vec<(f32, Vec3)> = (0..=frames)
        .map(|k| (frame_time(k), path(frame_time(k))))
        .collect();
    linear_translation(node, &keys)
}

/// A rotation channel with a key at every frame; per-frame steps are small,
/// so slerp's shortest arc follows `rotation(t)`.
fn rotation_track(node: usize, frames: u32, rotation: impl Fn(f32) -> Quat) -> Channel {
    let keys: Vec<(f32, Quat)> = (0..=frames)
        .map(|k| (frame_time(k), rotation(frame_time(k))))
        .collect();
    linear_rotation(node, &keys)
}

/// Accumulates nodes, objects, materials and lights into a [`Scene`].
struct Builder {
    scene: Scene,
    has_camera: bool,
}

impl Builder {
    fn new(name: &str, frame_count: u32) -> Self {
        Builder {
            scene: Scene {
                name: name.to_string(),
                nodes: Vec::new(),
                objects: Vec::new(),
                materials: Vec::new(),
                lights: Vec::new(),
                camera: CameraDef { node: 0, yfov: 1.0 },
                animation: Animation::default(),
                frame_count,
            },
            has_camera: false,
        }
    }

    fn material(&mut self, material: Material) -> u32 {
        self.scene.materials.push(material);
        self.scene.materials.len() as u32 - 1
    }

    fn node(&mut self, name: &str, rest: Trs) -> usize {
        self.scene.nodes.push(Node {
            name: name.to_string(),
            parent: None,
            rest,
        });
        self.scene.nodes.len() - 1
    }

    /// Places `mesh` on a new node of its own; returns the node.
    fn object(&mut self, name: &str, rest: Trs, mesh: Mesh) -> usize {
        let node = self.node(name, rest);
        self.scene.objects.push(Object {
            name: name.to_string(),
            node,
            mesh,
        });
        node
    }

    /// A point light on a new node (placed by its animation); returns the node.
    fn point_light(&mut self, name: &str, intensity: Vec3) -> usize {
        let node = self.node(name, Trs::default());
        self.scene.lights.push(PunctualLight {
            name: name.to_string(),
            node,
            intensity,
            spot: None,
        });
        node
    }

    fn camera(&mut self, rest: Trs, yfov: f32) {
        let node = self.node("camera", rest);
        self.scene.camera = CameraDef { node, yfov };
        self.has_camera = true;
    }

    fn animate(&mut self, channel: Channel) {
        self.scene.animation.channels.push(channel);
    }

    fn finish(self) -> Scene {
        // Built-in scenes are fixed code, so a missing camera is a bug in this
        // file that the tests catch, never a user error.
        assert!(
            self.has_camera,
            "built-in scene {} has no camera",
            self.scene.name
        );
        self.scene
    }
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
                let same = snap.triangles[..n].iter().zip(&snaps[0].triangles[..n]);
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
