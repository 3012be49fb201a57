//! Animation sampling (glTF semantics) and the node hierarchy: keys are hit
//! exactly, interpolation matches formulas computed here independently,
//! values clamp outside the key range, children follow animated parents and
//! `Scene::object_motion` maps a point on an object from one time to another.

use glam::{Mat4, Quat, Vec3, Vec4};
use radcache::backend::cpu::CpuBackend;
use radcache::film::Film;
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::{FrameContext, Method};
use radcache::render::{FrameFailed, FrameSettings, Renderer};
use radcache::scene::animation::{linear_rotation, linear_translation};
use radcache::scene::{
    Animation, CameraDef, Channel, Interpolation, Material, Mesh, Node, Object, Property, Scene,
    Trs,
};
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4};

const EPS: f32 = 1e-5;

fn close4(a: Vec4, b: Vec4) -> bool {
    (a - b).abs().max_element() <= EPS
}

fn close3(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() <= EPS
}

fn same_rotation(a: Quat, b: Quat) -> bool {
    a.dot(b).abs() >= 1.0 - 1e-5
}

const TIMES: [f32; 3] = [0.0, 1.0, 3.0];

fn keys() -> Vec<Vec4> {
    vec![
        Vec4::new(0.0, 1.0, 2.0, 0.0),
        Vec4::new(4.0, -1.0, 2.5, 0.0),
        Vec4::new(-2.0, 3.0, 0.0, 0.0),
    ]
}

fn channel(interpolation: Interpolation, values: Vec<Vec4>) -> Channel {
    Channel {
        node: 0,
        property: Property::Translation,
        interpolation,
        times: TIMES.to_vec(),
        values,
    }
}

/// Cubic spline values: (in-tangent, value, out-tangent) per key.
fn cubic(tangents: &[(Vec4, Vec4)]) -> Vec<Vec4> {
    keys()
        .into_iter()
        .zip(tangents)
        .flat_map(|(v, &(a, b))| [a, v, b])
        .collect()
}

fn some_tangents() -> Vec<(Vec4, Vec4)> {
    vec![
        (
            Vec4::new(1.0, 0.0, 0.0, 0.0),
            Vec4::new(2.0, -1.0, 0.5, 0.0),
        ),
        (
            Vec4::new(-3.0, 1.0, 0.0, 0.0),
            Vec4::new(0.5, 4.0, -2.0, 0.0),
        ),
        (Vec4::new(0.0, 0.0, 1.0, 0.0), Vec4::new(1.0, 1.0, 1.0, 0.0)),
    ]
}

fn all_channels() -> Vec<Channel> {
    vec![
        channel(Interpolation::Linear, keys()),
        channel(Interpolation::Step, keys()),
        channel(Interpolation::CubicSpline, cubic(&some_tangents())),
    ]
}

#[test]
fn channels_validate() {
    for c in all_channels() {
        c.validate().unwrap();
    }
    // Cubic splines need three values per key.
    assert!(channel(Interpolation::CubicSpline, keys())
        .validate()
        .is_err());
}

#[test]
fn keys_are_hit_exactly() {
    for c in all_channels() {
        for (k, &t) in TIMES.iter().enumerate() {
            assert!(
                close4(c.sample(t), keys()[k]),
                "{:?} at key {k}",
                c.interpolation
            );
        }
    }
}

#[test]
fn values_clamp_outside_the_keys() {
    for c in all_channels() {
        assert!(close4(c.sample(-5.0), keys()[0]), "{:?}", c.interpolation);
        assert!(close4(c.sample(3.5), keys()[2]), "{:?}", c.interpolation);
        assert!(close4(c.sample(1e6), keys()[2]), "{:?}", c.interpolation);
    }
}

#[test]
fn linear_midpoint_is_the_average() {
    let c = channel(Interpolation::Linear, keys());
    let k = keys();
    assert!(close4(c.sample(0.5), (k[0] + k[1]) * 0.5));
    assert!(close4(c.sample(2.0), (k[1] + k[2]) * 0.5));
    // A quarter of the way through the second (2 s long) segment.
    assert!(close4(c.sample(1.5), k[1] * 0.75 + k[2] * 0.25));
}

#[test]
fn step_holds_the_previous_key() {
    let c = channel(Interpolation::Step, keys());
    let k = keys();
    assert!(close4(c.sample(0.999), k[0]));
    assert!(close4(c.sample(1.0), k[1]));
    assert!(close4(c.sample(2.9), k[1]));
}

#[test]
fn slerp_midpoint_is_the_half_angle() {
    let c = linear_rotation(
        0,
        &[
            (0.0, Quat::IDENTITY),
            (2.0, Quat::from_rotation_y(FRAC_PI_2)),
        ],
    );
    let mid = Quat::from_vec4(c.sample(1.0));
    assert!(
        same_rotation(mid, Quat::from_rotation_y(FRAC_PI_4)),
        "{mid}"
    );
    assert!((mid.length() - 1.0).abs() < EPS);
    // Slerp, not a normalised lerp: at a quarter the angle is a quarter.
    let quarter = Quat::from_vec4(c.sample(0.5));
    assert!(
        same_rotation(quarter, Quat::from_rotation_y(FRAC_PI_2 / 4.0)),
        "{quarter}"
    );
}

#[test]
fn cubic_with_zero_tangents_midpoint_is_the_average() {
    let zero = vec![(Vec4::ZERO, Vec4::ZERO); 3];
    let c = channel(Interpolation::CubicSpline, cubic(&zero));
    let k = keys();
    assert!(close4(c.sample(0.5), (k[0] + k[1]) * 0.5));
    assert!(close4(c.sample(2.0), (k[1] + k[2]) * 0.5));
}

/// The same Hermite segment evaluated as a cubic Bézier with de Casteljau:
/// control points v0, v0 + dt·b0/3, v1 − dt·a1/3, v1.
fn bezier(v0: Vec4, b0: Vec4, a1: Vec4, v1: Vec4, dt: f32, s: f32) -> Vec4 {
    let p = [v0, v0 + b0 * (dt / 3.0), v1 - a1 * (dt / 3.0), v1];
    let q: Vec<Vec4> = p.windows(2).map(|w| w[0].lerp(w[1], s)).collect();
    let r: Vec<Vec4> = q.windows(2).map(|w| w[0].lerp(w[1], s)).collect();
    r[0].lerp(r[1], s)
}

#[test]
fn cubic_with_tangents_matches_hermite() {
    let tangents = some_tangents();
    let c = channel(Interpolation::CubicSpline, cubic(&tangents));
    let k = keys();
    for (seg, (t0, t1)) in [(0usize, (0.0f32, 1.0f32)), (1, (1.0, 3.0))] {
        for s in [0.1f32, 0.25, 0.5, 0.8] {
            let t = t0 + s * (t1 - t0);
            let expected = bezier(
                k[seg],
                tangents[seg].1,
                tangents[seg + 1].0,
                k[seg + 1],
                t1 - t0,
                s,
            );
            let got = c.sample(t);
            assert!(
                (got - expected).abs().max_element() < 1e-4,
                "t={t}: {got} vs {expected}"
            );
        }
    }
    // The tangents matter: a zero-tangent spline differs off the keys.
    let flat = channel(
        Interpolation::CubicSpline,
        cubic(&[(Vec4::ZERO, Vec4::ZERO); 3]),
    );
    assert!(!close4(c.sample(0.5), flat.sample(0.5)));
}

#[test]
fn local_trs_overrides_only_animated_properties() {
    let rest = Trs {
        translation: Vec3::new(9.0, 9.0, 9.0),
        rotation: Quat::from_rotation_x(0.3),
        scale: Vec3::splat(2.0),
    };
    let animation = Animation {
        channels: vec![linear_translation(0, &[(0.0, Vec3::ZERO), (1.0, Vec3::X)])],
    };
    let trs = animation.local_trs(0, rest, 0.5);
    assert!(close3(trs.translation, Vec3::new(0.5, 0.0, 0.0)));
    assert_eq!(trs.rotation, rest.rotation);
    assert_eq!(trs.scale, rest.scale);
    // Another node is untouched.
    assert_eq!(animation.local_trs(1, rest, 0.5), rest);
    assert!((animation.duration() - 1.0).abs() < EPS);
}

// -------------------------------------------------------------- hierarchy

fn triangle_mesh() -> Mesh {
    Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        normals: vec![Vec3::Z; 3],
        triangles: vec![[0, 1, 2]],
        materials: vec![0],
    }
}

/// Nodes: 0 = animated parent, 1 = its (unanimated) child with an object,
/// 2 = a static object, 3 = camera.
fn hierarchy_scene() -> Scene {
    let child_rest = Trs {
        translation: Vec3::new(0.0, 1.0, 0.0),
        rotation: Quat::from_rotation_z(0.5),
        scale: Vec3::splat(0.5),
    };
    let parent = Node {
        name: "parent".into(),
        parent: None,
        rest: Trs::default(),
    };
    let child = Node {
        name: "child".into(),
        parent: Some(0),
        rest: child_rest,
    };
    let fixed = Node {
        name: "fixed".into(),
        parent: None,
        rest: Trs::default(),
    };
    let cam = Node {
        name: "cam".into(),
        parent: None,
        rest: Trs {
            translation: Vec3::new(0.0, 0.0, 5.0),
            ..Trs::default()
        },
    };
    Scene {
        name: "hierarchy".into(),
        nodes: vec![parent, child, fixed, cam],
        objects: vec![
            Object {
                name: "fixed".into(),
                node: 2,
                mesh: triangle_mesh(),
            },
            Object {
                name: "child".into(),
                node: 1,
                mesh: triangle_mesh(),
            },
        ],
        materials: vec![Material::emitter("glow", Vec3::ONE)],
        lights: vec![],
        camera: CameraDef {
            node: 3,
            yfov: 0.8,
            aspect_ratio: None,
        },
        animation: Animation {
            channels: vec![
                linear_translation(0, &[(0.0, Vec3::ZERO), (2.0, Vec3::new(2.0, 0.0, -1.0))]),
                linear_rotation(
                    0,
                    &[
                        (0.0, Quat::IDENTITY),
                        (2.0, Quat::from_rotation_y(FRAC_PI_2)),
                    ],
                ),
            ],
        },
        frame_count: 49,
        moved_by: Vec3::ZERO,
    }
}

fn close_mat(a: Mat4, b: Mat4) -> bool {
    a.abs_diff_eq(b, 1e-5)
}

#[test]
fn child_follows_animated_parent() {
    let scene = hierarchy_scene();
    assert!(
        scene.node_is_dynamic(1),
        "a child of an animated node moves"
    );
    assert!(!scene.node_is_dynamic(2));
    assert!(scene.object_is_dynamic(1));
    assert!(!scene.object_is_dynamic(0));
    for t in [0.0, 0.7, 1.0, 2.0] {
        let world = scene.node_world_transforms(t);
        let parent = Mat4::from_rotation_translation(
            Quat::from_rotation_y(FRAC_PI_4 * t),
            Vec3::new(t, 0.0, -0.5 * t),
        );
        let child = parent * scene.nodes[1].rest.to_mat4();
        assert!(close_mat(world[0], parent), "t={t}");
        assert!(close_mat(world[1], child), "t={t}");
        assert!(close_mat(world[2], Mat4::IDENTITY));
    }
    let w0 = scene.node_world_transforms(0.0)[1];
    let w1 = scene.node_world_transforms(1.0)[1];
    assert!(!close_mat(w0, w1), "the child moved");
}

#[test]
fn snapshot_orders_static_first() {
    let scene = hierarchy_scene();
    let snap = scene.snapshot(1.0);
    assert_eq!(snap.static_count, 1);
    assert_eq!(snap.tri_object.to_vec(), [0, 1]);
    assert!(close3(snap.camera.position, Vec3::new(0.0, 0.0, 5.0)));
}

#[test]
fn object_motion_maps_points_between_times() {
    let scene = hierarchy_scene();
    let (t0, t1) = (0.3, 1.6);
    let (a, b) = (scene.snapshot(t0), scene.snapshot(t1));
    // Triangle 1 belongs to the dynamic child object.
    let motion = scene.object_motion(1, t0, t1);
    for k in 0..3 {
        let moved = motion.transform_point3(a.triangles[1].p[k]);
        assert!(
            close3(moved, b.triangles[1].p[k]),
            "{moved} vs {}",
            b.triangles[1].p[k]
        );
    }
    // An interior point (barycentric) maps the same way.
    let moved = motion.transform_point3(a.triangles[1].point(0.2, 0.3));
    assert!(close3(moved, b.triangles[1].point(0.2, 0.3)));
    // The static object does not move.
    assert!(close_mat(scene.object_motion(0, t0, t1), Mat4::IDENTITY));
}

/// A forest of 60 nodes (parents listed in any order, some nodes driven by
/// two channels of the same property, the later winning as glTF's merged
/// animations do): world transforms and dynamic flags, as the scene
/// computes them for all nodes at once, equal the node-by-node definition
/// (each node's own channels on its rest pose, times its parent's world
/// transform, recursively).
#[test]
fn all_nodes_at_once_equal_the_node_by_node_definition() {
    let mut scene = hierarchy_scene();
    let count = 60;
    // A fixed shuffle of parents: node i's parent is a node placed before
    // it in `order`, so the hierarchy is a forest in no index order.
    let order: Vec<usize> = (0..count).map(|i| (i * 37 + 11) % count).collect();
    let first = scene.nodes.len();
    scene.nodes.extend((0..count).map(|i| Node {
        name: format!("n{i}"),
        parent: None,
        rest: Trs {
            translation: Vec3::new(i as f32 * 0.1, 0.5, -0.2 * i as f32),
            rotation: Quat::from_rotation_x(0.1 * i as f32),
            scale: Vec3::splat(1.0 + 0.01 * i as f32),
        },
    }));
    for k in 1..count {
        if k % 7 != 0 {
            let parent = order[(k * 13) % k];
            scene.nodes[first + order[k]].parent = Some(first + parent);
        }
    }
    for i in (0..count).filter(|i| i % 4 == 1) {
        let node = first + i;
        let to = Vec3::new(1.0, i as f32 * 0.05, 0.0);
        scene.animation.channels.extend([
            linear_translation(node, &[(0.0, Vec3::ZERO), (2.0, to)]),
            linear_rotation(
                node,
                &[(0.0, Quat::IDENTITY), (2.0, Quat::from_rotation_z(1.0))],
            ),
        ]);
        if i % 8 == 1 {
            // A second translation channel of the same node: it wins.
            scene
                .animation
                .channels
                .push(linear_translation(node, &[(0.0, -to), (2.0, to * 3.0)]));
        }
    }
    fn world_of(scene: &Scene, node: usize, t: f32) -> Mat4 {
        let local = scene
            .animation
            .local_trs(node, scene.nodes[node].rest, t)
            .to_mat4();
        match scene.nodes[node].parent {
            Some(p) => world_of(scene, p, t) * local,
            None => local,
        }
    }
    let dynamic = scene.dynamic_nodes();
    let mut moving = 0;
    assert_eq!(dynamic.len(), scene.nodes.len());
    for (n, &d) in dynamic.iter().enumerate() {
        assert_eq!(d, scene.node_is_dynamic(n), "node {n}");
        moving += usize::from(d);
    }
    assert!(
        moving > count / 4 && moving < count,
        "{moving} of {count} move"
    );
    for t in [0.0, 0.6, 1.7, 2.5] {
        let world = scene.node_world_transforms(t);
        for (n, m) in world.iter().enumerate() {
            assert!(close_mat(*m, world_of(&scene, n, t)), "node {n} at {t}");
        }
    }
    let objects = scene.dynamic_objects();
    for (o, object) in scene.objects.iter().enumerate() {
        assert_eq!(objects[o], scene.node_is_dynamic(object.node));
    }
}

/// [`hierarchy_scene`] with two parents above the camera, each scaled from
/// 1 to 1e30 over 1 s: 1.7e57 at frame 1 (t = 1/24 s), past f32's range.
fn scene_whose_camera_leaves_f32_at_frame_1() -> Scene {
    let mut scene = hierarchy_scene();
    for name in ["big", "bigger"] {
        let node = scene.nodes.len();
        scene.nodes.push(Node {
            name: name.into(),
            parent: None,
            rest: Trs::default(),
        });
        let camera = scene.camera.node;
        let top = std::iter::successors(Some(camera), |&n| scene.nodes[n].parent)
            .last()
            .unwrap();
        scene.nodes[top].parent = Some(node);
        scene.animation.channels.push(Channel {
            node,
            property: Property::Scale,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0],
            values: vec![Vec4::new(1.0, 1.0, 1.0, 0.0), Vec4::splat(1e30)],
        });
    }
    scene
}

fn tiny_renderer(scene: Scene, method: Box<dyn Method>) -> Renderer {
    let settings = FrameSettings {
        width: 4,
        height: 4,
        ..FrameSettings::default()
    };
    Renderer::new(scene, method, Box::new(CpuBackend::new()), settings)
}

/// A camera that its ancestors' animated scales carry past f32's range at
/// t > 0 has no position: its frames were black, without a word. The
/// frame is refused, naming the camera's node and the frame, before it
/// renders; the frame before it renders.
#[test]
fn a_camera_carried_past_f32_fails_its_frame() {
    let scene = scene_whose_camera_leaves_f32_at_frame_1();
    assert!(scene.check_camera(0.0, "t = 0").is_ok());
    let err = scene.check_camera(1.0 / 24.0, "frame 1").unwrap_err();
    assert!(
        err.contains("camera node 'cam' is carried to a non-finite position at frame 1"),
        "{err}"
    );
    let method = PathTracer::new(PathSettings {
        spp: 1,
        ..PathSettings::default()
    });
    let mut r = tiny_renderer(scene, Box::new(method));
    assert!(r.try_render_frame(0).is_ok());
    let failed = r.try_render_frame(1).expect_err("frame 1 has no camera");
    assert!(
        matches!(failed, FrameFailed::Camera { frame: 1, .. }),
        "{failed:?}"
    );
    let message = failed.to_string();
    assert!(
        message.starts_with("frame 1: camera node 'cam' is carried to a non-finite position at t = 0.0417 s (frame 1)"),
        "{message}"
    );
}

/// A two-pass method that prepares the next frame before it renders one,
/// counting what it prepares.
struct PreparesNextFrame {
    prepared: Vec<u32>,
}

impl Method for PreparesNextFrame {
    fn name(&self) -> &'static str {
        "prepares-next"
    }

    fn next_frame_to_prepare(&self, frame: u32, end: u32) -> Option<u32> {
        (frame + 1..end.min(frame + 2)).find(|f| !self.prepared.contains(f))
    }

    fn prepare_frame(&mut self, ctx: &FrameContext) {
        self.prepared.push(ctx.frame);
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        Film::new(ctx.width, ctx.height)
    }
}

/// A frame prepared ahead (a two-pass method's first pass) is checked too:
/// the frame that needs it fails, naming both, and nothing is prepared from
/// a camera out of reach. Ending the range before it renders the frame.
#[test]
fn a_camera_out_of_reach_in_a_frame_prepared_ahead_fails_the_frame_that_needs_it() {
    let method = Box::new(PreparesNextFrame {
        prepared: Vec::new(),
    });
    let mut r = tiny_renderer(scene_whose_camera_leaves_f32_at_frame_1(), method);
    let failed = r.try_render_frame(0).expect_err("frame 0 needs frame 1");
    assert!(
        matches!(failed, FrameFailed::Camera { frame: 0, .. }),
        "{failed:?}"
    );
    let message = failed.to_string();
    assert!(
        message.starts_with("frame 0: camera node 'cam' is carried to a non-finite position at t = 0.0417 s (frame 1, which the method prepares ahead)"),
        "{message}"
    );
    assert_eq!(r.method_calls().prepared, 0);
    r.set_frame_end(Some(1));
    assert!(r.try_render_frame(0).is_ok());
}
