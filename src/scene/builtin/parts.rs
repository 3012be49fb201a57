//! Parts the built-in scenes share: the box of the TVCG 2007 scenes (its
//! walls, camera and ceiling light), the spheres' palette and bounce, and
//! the furniture of the chairs room.

use super::super::{Material, Mesh, Trs};
use super::builder::{at, Builder};
use super::geometry::{light_panel, push_box, push_checkerboard, Facing};
use super::{
    BOX_CAMERA, BOX_LIGHT_SIZE, BOX_LIGHT_Y, BOX_MAX, BOX_MIN, BOX_YFOV_DEGREES, GREEN,
    LIGHT_RADIANCE, RED, WHITE,
};
use crate::sampling::mix64;
use glam::Vec3;

/// White, red and green diffuse materials of the shared box.
pub(super) fn box_wall_materials(b: &mut Builder) -> [u32; 3] {
    [
        b.material(Material::diffuse("red", RED)),
        b.material(Material::diffuse("green", GREEN)),
        b.material(Material::diffuse("white", WHITE)),
    ]
}

/// The diffuse shared box and its camera; `tiles` replaces the white floor
/// with a checkerboard of the two materials.
pub(super) fn box_room(b: &mut Builder, tiles: Option<[u32; 2]>) {
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
pub(super) fn box_room_with(b: &mut Builder, walls: [Option<u32>; 6], tiles: Option<[u32; 2]>) {
    let mut room = Mesh::default();
    push_box(&mut room, BOX_MIN, BOX_MAX, Facing::Inward, walls);
    if let Some(tiles) = tiles {
        push_checkerboard(&mut room, BOX_MIN, BOX_MAX, 0.25, tiles);
    }
    b.object("room", Trs::default(), room);
    b.camera(at(BOX_CAMERA), BOX_YFOV_DEGREES.to_radians());
}

/// The 0.5 m square light under the ceiling of the shared box; returns its node.
pub(super) fn box_ceiling_light(b: &mut Builder) -> usize {
    let light = b.material(Material::emitter("light", LIGHT_RADIANCE));
    let panel = light_panel(BOX_LIGHT_SIZE, light);
    b.object("light", at(Vec3::new(0.0, BOX_LIGHT_Y, 0.0)), panel)
}

/// Sphere materials: diffuse colours of the shared `spheres.glb` and glossy
/// ones with the Phong exponents of the papers (kd + ks ≤ 1).
pub(super) fn sphere_palette(b: &mut Builder) -> Vec<u32> {
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
pub(super) struct Bounce {
    pub(super) radius: f32,
    pub(super) apex: f32,
    pub(super) period: f32,
    pub(super) phase: f32,
}

impl Bounce {
    /// Deterministic, varied parameters for ball `i` (hashed, so that
    /// neighbours do not bounce in sync).
    pub(super) fn varied(i: u64) -> Self {
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

    pub(super) fn height_at(&self, t: f32) -> f32 {
        let s = (t / self.period + self.phase).fract();
        self.radius + self.apex * 4.0 * s * (1.0 - s)
    }
}

/// Table of Shirley's scene: a 1.4 × 0.9 m top at 0.77 m on four legs.
pub(super) fn table(material: u32) -> Mesh {
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
pub(super) fn chair(material: u32) -> Mesh {
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
pub(super) fn space_car(b: &mut Builder) -> Mesh {
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
