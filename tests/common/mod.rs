//! Small scenes built in code for closed-form and brute-force tests.
#![allow(dead_code)]

use glam::{Quat, Vec3, Vec4};
use radcache::backend::cpu::CpuBackend;
use radcache::film::Film;
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::Method;
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::{
    Animation, CameraDef, Channel, Interpolation, Material, Mesh, Node, Object, Property,
    PunctualLight, Scene, Trs,
};

/// Appends the quad `origin + s·u + t·v` (s, t ∈ [0,1]); its front face
/// (counter-clockwise) looks along `u × v`.
pub fn push_quad(mesh: &mut Mesh, origin: Vec3, u: Vec3, v: Vec3, material: u32) {
    let base = mesh.positions.len() as u32;
    let n = u.cross(v).normalize();
    for p in [origin, origin + u, origin + u + v, origin + v] {
        mesh.positions.push(p);
        mesh.normals.push(n);
    }
    mesh.triangles.push([base, base + 1, base + 2]);
    mesh.triangles.push([base, base + 2, base + 3]);
    mesh.materials.extend([material, material]);
}

/// An axis-aligned box whose front faces look inward (a closed room).
pub fn inward_box(min: Vec3, max: Vec3, material: u32) -> Mesh {
    let mut m = Mesh::default();
    let d = max - min;
    let (x, y, z) = (Vec3::X * d.x, Vec3::Y * d.y, Vec3::Z * d.z);
    push_quad(&mut m, min, z, x, material); // floor, faces +y
    push_quad(&mut m, min + y, x, z, material); // ceiling, faces -y
    push_quad(&mut m, min, x, y, material); // back, faces +z
    push_quad(&mut m, min + z, y, x, material); // front, faces -z
    push_quad(&mut m, min, y, z, material); // left, faces +x
    push_quad(&mut m, min + x, z, y, material); // right, faces -x
    m
}

/// One object per mesh, each on its own root node; `channels` animate them
/// (their `node` field is the object index). The camera sits at `eye`
/// looking along `look` (no roll).
pub fn scene(
    meshes: Vec<Mesh>,
    materials: Vec<Material>,
    channels: Vec<Channel>,
    eye: Vec3,
    look: Vec3,
    yfov: f32,
    lights: Vec<(Vec3, Vec3)>,
) -> Scene {
    let mut nodes = Vec::new();
    let mut objects = Vec::new();
    for (i, mesh) in meshes.into_iter().enumerate() {
        nodes.push(Node {
            name: format!("object{i}"),
            parent: None,
            rest: Trs::default(),
        });
        objects.push(Object {
            name: format!("object{i}"),
            node: i,
            mesh,
        });
    }
    let camera_node = nodes.len();
    nodes.push(Node {
        name: "camera".into(),
        parent: None,
        rest: Trs {
            translation: eye,
            rotation: Quat::from_rotation_arc(-Vec3::Z, look.normalize()),
            scale: Vec3::ONE,
        },
    });
    let mut punctual = Vec::new();
    for (i, (position, intensity)) in lights.into_iter().enumerate() {
        nodes.push(Node {
            name: format!("light{i}"),
            parent: None,
            rest: Trs {
                translation: position,
                ..Trs::default()
            },
        });
        punctual.push(PunctualLight {
            name: format!("light{i}"),
            node: nodes.len() - 1,
            intensity,
            kind: radcache::scene::LightKind::Point,
        });
    }
    Scene {
        name: "test".into(),
        nodes,
        objects,
        materials,
        lights: punctual,
        camera: CameraDef {
            node: camera_node,
            yfov,
            aspect_ratio: None,
        },
        animation: Animation { channels },
        frame_count: 2,
        moved_by: Vec3::ZERO,
    }
}

/// A CPU renderer of `scene` with `method` at `size × size`, default seed.
pub fn cpu_renderer(
    scene: Scene,
    method: Box<dyn radcache::method::Method>,
    size: u32,
) -> radcache::render::Renderer {
    radcache::render::Renderer::new(
        scene,
        method,
        Box::new(radcache::backend::cpu::CpuBackend::new()),
        radcache::render::FrameSettings {
            width: size,
            height: size,
            ..radcache::render::FrameSettings::default()
        },
    )
}

/// A white room lit by a 0.5 m ceiling panel; with `off_at`, the panel is
/// scaled to nothing (switched off) from frame `off_at` on (step key).
pub fn lit_room(off_at: Option<u32>, fps: f32) -> Scene {
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

/// `path` at 256 spp over `frames` of `scene` (`size`², 24 fps) with the
/// same random sequence in every frame: the flicker yardstick (DESIGN.md
/// "Measuring").
pub fn converged_sequence(scene: Scene, size: u32, frames: std::ops::Range<u32>) -> Vec<Film> {
    let mut r = Renderer::new(
        scene,
        Box::new(PathTracer::new(PathSettings::default())),
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: size,
            height: size,
            fps: 24.0,
            same_pattern: true,
            ..FrameSettings::default()
        },
    );
    let mut path = PathTracer::new(PathSettings {
        spp: 256,
        ..PathSettings::default()
    });
    frames
        .map(|f| r.with_frame_context(f, |ctx| path.render_frame(ctx)))
        .collect()
}

/// An axis-aligned box whose front faces look outward (a solid block).
pub fn outward_box(min: Vec3, max: Vec3, material: u32) -> Mesh {
    let mut m = Mesh::default();
    let d = max - min;
    let (x, y, z) = (Vec3::X * d.x, Vec3::Y * d.y, Vec3::Z * d.z);
    push_quad(&mut m, min, x, z, material); // bottom, faces -y
    push_quad(&mut m, min + y, z, x, material); // top, faces +y
    push_quad(&mut m, min, y, x, material); // back, faces -z
    push_quad(&mut m, min + z, x, y, material); // front, faces +z
    push_quad(&mut m, min, z, y, material); // left, faces -x
    push_quad(&mut m, min + x, y, z, material); // right, faces +x
    m
}

/// Adds `mesh` as an object named `name` on a node of its own (at rest).
pub fn add_static_object(s: &mut Scene, name: &str, mesh: Mesh) {
    s.objects.push(radcache::scene::Object {
        name: name.into(),
        node: s.nodes.len(),
        mesh,
    });
    s.nodes.push(radcache::scene::Node {
        name: name.into(),
        parent: None,
        rest: radcache::scene::Trs::default(),
    });
}

/// Adds a block (an [`outward_box`] of a new diffuse material `colour`)
/// on its own node, moved by the translation channel `values` at `times`
/// with `interpolation`.
pub fn add_moving_block(
    s: &mut Scene,
    (min, max): (Vec3, Vec3),
    colour: Vec3,
    interpolation: Interpolation,
    (times, values): (Vec<f32>, Vec<Vec4>),
) {
    s.materials.push(Material::diffuse("block", colour));
    let block = outward_box(min, max, (s.materials.len() - 1) as u32);
    add_static_object(s, "block", block);
    s.animation.channels.push(Channel {
        node: s.nodes.len() - 1,
        property: Property::Translation,
        interpolation,
        times,
        values,
    });
}

/// The lit room with a bright red block in its back left corner that
/// jumps out of the room (20 m down, under the floor) at frame `k`: a STEP
/// translation key. Before `k` the block bleeds red onto the back and left
/// walls and the floor and shadows their indirect light.
pub fn jumping_block_room(k: u32, fps: f32) -> Scene {
    block_room_jumping(k, fps, [Vec4::ZERO, Vec4::new(0.0, -20.0, 0.0, 0.0)])
}

/// [`jumping_block_room`] the other way: the block jumps into the corner
/// from under the floor at frame `k`.
pub fn arriving_block_room(k: u32, fps: f32) -> Scene {
    block_room_jumping(k, fps, [Vec4::new(0.0, -20.0, 0.0, 0.0), Vec4::ZERO])
}

/// The lit room with the red block of [`jumping_block_room`] translated by
/// `before` until frame `k` and by `after` from it.
fn block_room_jumping(k: u32, fps: f32, [before, after]: [Vec4; 2]) -> Scene {
    let mut s = lit_room(None, fps);
    add_moving_block(
        &mut s,
        (Vec3::new(-0.95, 0.0, -0.95), Vec3::new(-0.2, 1.0, -0.2)),
        Vec3::new(0.9, 0.1, 0.1),
        Interpolation::Step,
        (vec![0.0, (k as f32 - 0.5) / fps], vec![before, after]),
    );
    s
}

/// The lit room with a block (`corners`, a diffuse `colour`) scaled about
/// the room's origin by its node: linearly between `keys` (frame at
/// `fps`, scale), and held before the first and after the last. A scale
/// of 0 is a block not there yet.
pub fn scaling_block_room(
    corners: (Vec3, Vec3),
    colour: Vec3,
    fps: f32,
    keys: &[(f32, f32)],
) -> Scene {
    let mut s = lit_room(None, fps);
    s.materials.push(Material::diffuse("block", colour));
    let block = outward_box(corners.0, corners.1, (s.materials.len() - 1) as u32);
    add_static_object(&mut s, "block", block);
    s.animation.channels.push(Channel {
        node: s.nodes.len() - 1,
        property: Property::Scale,
        interpolation: Interpolation::Linear,
        times: keys.iter().map(|&(frame, _)| frame / fps).collect(),
        values: keys.iter().map(|&(_, k)| Vec4::new(k, k, k, 0.0)).collect(),
    });
    s
}

/// The bias of `test` over the lower left quarter of the image (where the
/// block stood): the difference of the region's mean radiance from the
/// reference's, relative to the reference's, worst colour channel. A ghost
/// is a bias (the block's red light, its missing shadow); the noise of
/// records gathered with other random streams mostly averages out over the
/// region.
pub fn region_error(test: &Film, reference: &Film) -> f64 {
    let (w, h) = (reference.width as usize, reference.height as usize);
    let (mut a, mut b) = (Vec3::ZERO, Vec3::ZERO);
    for y in h / 2..h {
        for x in 0..w / 2 {
            a += test.pixels[y * w + x];
            b += reference.pixels[y * w + x];
        }
    }
    f64::from(((a - b).abs() / b.max(Vec3::splat(1e-6))).max_element())
}

/// A closed 2 m box whose every surface has albedo `albedo` and emits
/// `le`, seen from its centre: the furnace, radiance `le/(1−albedo)`
/// everywhere.
pub fn furnace_box(albedo: f32, le: f32) -> Scene {
    let material = Material {
        emission: Vec3::splat(le),
        ..Material::diffuse("furnace", Vec3::splat(albedo))
    };
    let room = inward_box(Vec3::splat(-1.0), Vec3::splat(1.0), 0);
    scene(
        vec![room],
        vec![material],
        vec![],
        Vec3::ZERO,
        -Vec3::Z,
        1.2,
        vec![],
    )
}

/// The square `[−half, half]²` of the plane y = 0, facing up, of
/// `material`.
pub fn ground(half: f32, material: u32) -> Mesh {
    let mut plane = Mesh::default();
    push_quad(
        &mut plane,
        Vec3::new(-half, 0.0, -half),
        Vec3::Z * 2.0 * half,
        Vec3::X * 2.0 * half,
        material,
    );
    plane
}

/// A 20 m Lambertian plane (y = 0) of albedo `albedo` under a point light
/// of intensity `intensity` at `light`, seen straight down from `eye`
/// (vertical field of view 1 rad).
pub fn plane_under_point_light(albedo: f32, intensity: f32, light: Vec3, eye: Vec3) -> Scene {
    scene(
        vec![ground(10.0, 0)],
        vec![Material::diffuse("plane", Vec3::splat(albedo))],
        vec![],
        eye,
        -Vec3::Y,
        1.0,
        vec![(light, Vec3::splat(intensity))],
    )
}

// ------------------------------------------- a small glTF file with a .bin

/// One emissive triangle (external buffer `<stem>.bin`) and a camera.
pub fn tri_json(bin_name: &str) -> serde_json::Value {
    serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"name": "tri", "mesh": 0},
            {"name": "cam", "camera": 0, "translation": [0.0, 0.0, 3.0]}
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"name": "glow", "emissiveFactor": [1.0, 1.0, 1.0]}],
        "buffers": [{"uri": bin_name, "byteLength": 48}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}
        ]
    })
}

pub fn tri_bin(positions: [[f32; 3]; 3], indices: [u32; 3]) -> Vec<u8> {
    let mut bytes = Vec::new();
    for v in positions.iter().flatten() {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    for i in indices {
        bytes.extend_from_slice(&i.to_le_bytes());
    }
    bytes
}

pub const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

/// A closed, lumpy icosphere: the 20 faces split `subdivisions` times,
/// every vertex at `radius` ± 10 % (drawn from `seed`), triangles sharing
/// their vertices by index. No edge is axis-aligned, and every edge is
/// shared by two triangles: a ray from inside that leaves is a leak.
pub fn closed_lumpy_sphere(subdivisions: u32, radius: f32, seed: u64) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let m = (positions[a as usize] + positions[b as usize]).normalize();
                positions.push(m);
                positions.len() as u32 - 1
            })
        };
        faces = faces
            .iter()
            .flat_map(|&[a, b, c]| {
                let ab = midpoint(a, b, &mut positions);
                let bc = midpoint(b, c, &mut positions);
                let ca = midpoint(c, a, &mut positions);
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    let mut rng = radcache::sampling::Rng::from_seed(seed, 0);
    let mut mesh = Mesh::default();
    for p in positions {
        let lump = 0.9 + 0.2 * rng.next_f32();
        mesh.positions.push(p * radius * lump);
        mesh.normals.push(-p);
    }
    mesh.materials = vec![0; faces.len()];
    mesh.triangles = faces;
    mesh
}

/// The one frame of a scene of [`closed_lumpy_sphere`] (3 subdivisions,
/// radius 5, 1,280 triangles) around the origin.
pub fn closed_lumpy_sphere_snapshot() -> radcache::scene::Snapshot {
    let scene = scene(
        vec![closed_lumpy_sphere(3, 5.0, 11)],
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
        vec![],
        Vec3::ZERO,
        -Vec3::Z,
        1.0,
        vec![],
    );
    scene.snapshot(0.0)
}

/// Rays from `origins` points drawn inside radius `inner` at every vertex
/// and at a random point of every edge of `snapshot`'s triangles, the
/// points computed in `f32` from the triangles' own vertices: rays that
/// pass within rounding of shared edges and vertices.
pub fn rays_at_edges(
    snapshot: &radcache::scene::Snapshot,
    origins: usize,
    inner: f32,
    seed: u64,
) -> Vec<radcache::backend::Ray> {
    let mut rng = radcache::sampling::Rng::from_seed(seed, 1);
    let mut rays = Vec::new();
    for _ in 0..origins {
        let mut r = || (rng.next_f32() * 2.0 - 1.0) * inner / 3f32.sqrt();
        let origin = Vec3::new(r(), r(), r());
        for tri in &snapshot.triangles {
            for k in 0..3 {
                let (a, b) = (tri.p[k], tri.p[(k + 1) % 3]);
                for target in [a, a + (b - a) * rng.next_f32()] {
                    let dir = (target - origin).normalize();
                    rays.push(radcache::backend::Ray::new(origin, dir, 0.0, f32::INFINITY));
                }
            }
        }
    }
    rays
}

/// A courtyard (a white ground, a wall left, right and behind, no roof)
/// under a point light 40 m away that swings over it from low on the left
/// to low on the right, 15° a frame (a sun made of a point light, as some
/// exporters write one): each wall's inner face goes from lit to dark or
/// the other way, and the back wall, which the light grazes, is lit by
/// them only. Still at its last place with `swings` false.
pub fn courtyard_under_a_swinging_light(frames: u32, swings: bool) -> Scene {
    const DISTANCE: f32 = 40.0;
    let white = 0u32;
    let slab = |min: Vec3, max: Vec3| outward_box(min, max, white);
    let at = |f: u32| {
        let angle = (150.0 - 15.0 * f.min(frames - 2) as f32).to_radians();
        Vec3::new(angle.cos(), angle.sin(), 0.0) * DISTANCE
    };
    let mut s = scene(
        vec![
            ground(3.0, white),
            slab(Vec3::new(-1.1, 0.0, -1.0), Vec3::new(-1.0, 2.0, 1.0)),
            slab(Vec3::new(1.0, 0.0, -1.0), Vec3::new(1.1, 2.0, 1.0)),
            slab(Vec3::new(-1.1, 0.0, -1.1), Vec3::new(1.1, 2.0, -1.0)),
        ],
        vec![Material::diffuse("white", Vec3::splat(0.7))],
        vec![],
        Vec3::new(0.0, 1.0, 2.6),
        Vec3::new(0.0, -0.1, -1.0),
        1.0,
        vec![(at(frames - 2), Vec3::splat(2.0 * DISTANCE * DISTANCE))],
    );
    if swings {
        let light = s.lights[0].node;
        s.animation.channels.push(Channel {
            node: light,
            property: Property::Translation,
            interpolation: Interpolation::Linear,
            times: (0..frames).map(|f| f as f32 / 24.0).collect(),
            values: (0..frames).map(|f| at(f).extend(0.0)).collect(),
        });
    }
    s.frame_count = frames;
    s
}

/// The CPU backend as a GPU that fuses multiply-adds looks to a method:
/// the `t` of each closest hit moved by up to [`ULP_HITS_BY`] relative
/// (−8 to +8 ulps, by a hash of the ray), and every any-hit query
/// reaching that far past its `tmax` (as where the GPU's `t` of a surface
/// comes out below the CPU's). On an H200 the `t` of 58 % of the hits of
/// `benches/gpu_rays.rs` differed from the CPU's in their last bits, where
/// lavapipe's equal the CPU's: this is how a machine without such a GPU
/// tests that nothing hangs on those bits.
pub struct UlpHits {
    inner: CpuBackend,
    /// Whether closest hits move too (else only any-hit queries reach further).
    closest: bool,
}

/// How far [`UlpHits`] moves a hit, relative to its `t`.
pub const ULP_HITS_BY: f32 = 8.0 * f32::EPSILON;

impl UlpHits {
    pub fn new() -> Self {
        UlpHits {
            inner: CpuBackend::new(),
            closest: true,
        }
    }

    /// Closest hits exactly the CPU's; only any-hit queries reach further.
    pub fn any_hit_only() -> Self {
        UlpHits {
            closest: false,
            ..UlpHits::new()
        }
    }
}

impl radcache::backend::RayBackend for UlpHits {
    fn name(&self) -> String {
        "cpu, hits moved by ulps".into()
    }
    fn set_geometry(&mut self, snapshot: &radcache::scene::Snapshot) {
        self.inner.set_geometry(snapshot);
    }
    fn closest_hit(&self, rays: &[radcache::backend::Ray], hits: &mut [radcache::backend::Hit]) {
        self.inner.closest_hit(rays, hits);
        if !self.closest {
            return;
        }
        for (ray, hit) in rays.iter().zip(hits.iter_mut()) {
            if hit.is_hit() {
                let bits = bytemuck::bytes_of(ray)
                    .iter()
                    .fold(0u32, |h, &b| h.wrapping_mul(16_777_619) ^ u32::from(b));
                let ulps = (bits % 17) as f32 - 8.0;
                hit.t *= 1.0 + ulps * f32::EPSILON;
            }
        }
    }
    fn any_hit(&self, rays: &[radcache::backend::Ray], occluded: &mut [bool]) {
        let further: Vec<_> = rays
            .iter()
            .map(|r| radcache::backend::Ray {
                tmax: r.tmax + r.tmax.abs() * ULP_HITS_BY,
                ..*r
            })
            .collect();
        self.inner.any_hit(&further, occluded);
    }
    fn ray_counts(&self) -> radcache::backend::RayCounts {
        self.inner.ray_counts()
    }
    fn preferred_batch(&self) -> usize {
        self.inner.preferred_batch()
    }
}
