//! Scene description: a node hierarchy with keyframed TRS animation, triangle
//! meshes attached to nodes ("objects"), materials, punctual lights and a
//! camera. A [`Scene`] is time-independent; [`Scene::snapshot`] evaluates it at
//! a time `t` into world-space geometry ([`Snapshot`]) that the ray backends
//! and methods consume.
//!
//! Conventions (shared with glTF 2.0): right-handed, +Y up, the camera looks
//! down its local −Z axis, lengths in metres, radiance in W·sr⁻¹·m⁻², punctual
//! light intensity in W·sr⁻¹.

pub mod animation;
pub mod builtin;
mod camera;
pub mod gltf_loader;
mod placed;
mod snapshot;

pub use camera::Camera;
use glam::{Mat4, Quat, Vec3};
pub use placed::Placed;
pub use snapshot::{PlacedLight, Placing, Snapshot, Triangle};
use std::path::Path;

pub use animation::{Animation, Channel, Interpolation, Property};

/// Below this size (world units across) light is lost: the ray offset
/// scales with the scene ([`crate::integrator::RayOffset`]), but the BVH
/// traversal's near cut and the shift that keeps hits past it
/// ([`crate::accel::NEAR_SHIFT`]) are absolute, and round the rays of a
/// scene a micrometre across. Seen with `path` (64 spp, 32×32, frame 0) on
/// `cube-in-box` scaled down to a bounding-box diagonal of (against the
/// metre-scale frame: mean, worst 8×8 block) 1e-2 down to 1e-6 units:
/// +0.01 to +0.03 %, 0.1–0.16 %; 3e-7, −0.9 %, 3.7 %; 1e-7, −9 %, 39 %;
/// 1e-10, −92 %.
///
/// Until the ray offset's floor scaled with the scene (a fixed 1e-4 units
/// then), the error began in centimetres: 1e-2 units +0.6 %, 3.8 %; 1.1e-3,
/// +1.6 %, 12 %; 1.1e-4, 45 % of the light lost. `tests/scene_scale.rs`
/// holds this size within 0.5 % (blocks 1 %) and a hundredth of it to a
/// loss of more than 5 %.
pub const SMALLEST_SCENE: f32 = 1e-5;

/// Frames per second used when the command line does not say (DESIGN.md).
pub const DEFAULT_FPS: f32 = 24.0;

/// Errors from loading or validating a scene. Every variant names the source
/// (file path or built-in name) so that the user knows what to fix.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{source_name}: {message}")]
    Invalid {
        source_name: String,
        message: String,
    },
    #[error("{0}: unknown built-in scene (known: {known})", known = builtin::NAMES.join(", "))]
    UnknownBuiltin(String),
}

impl SceneError {
    pub fn invalid(source_name: impl Into<String>, message: impl Into<String>) -> Self {
        SceneError::Invalid {
            source_name: source_name.into(),
            message: message.into(),
        }
    }
}

/// Translation, rotation, scale: the local transform of a node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Default for Trs {
    fn default() -> Self {
        Trs {
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        }
    }
}

impl Trs {
    pub fn to_mat4(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// One node of the transform hierarchy. `rest` is the transform used when no
/// animation channel overrides a property.
#[derive(Clone, Debug)]
pub struct Node {
    pub name: String,
    pub parent: Option<usize>,
    pub rest: Trs,
}

/// A triangle mesh in its node's local space. `normals` has one entry per
/// position (smooth shading); `materials` one entry per triangle.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub materials: Vec<u32>,
}

/// A mesh placed in the scene by a node. The index of an object in
/// [`Scene::objects`] is its object id, stable over the whole animation.
#[derive(Clone, Debug)]
pub struct Object {
    pub name: String,
    pub node: usize,
    pub mesh: Mesh,
}

/// Surface material. Lambertian when `specular` is zero, otherwise the
/// energy-conserving modified Phong BRDF of Lafortune & Willems (1994):
/// `f = kd/π + ks·(n+2)/(2π)·cos^n α`, with `kd + ks ≤ 1` per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Diffuse albedo `kd`.
    pub diffuse: Vec3,
    /// Specular albedo `ks` of the Phong lobe.
    pub specular: Vec3,
    /// Phong exponent `n`.
    pub exponent: f32,
    /// Emitted radiance (W·sr⁻¹·m⁻²).
    pub emission: Vec3,
    /// Emits from the back face too (glTF `doubleSided`).
    pub double_sided: bool,
}

impl Material {
    /// Roughness below which a glTF material becomes glossy (DESIGN.md).
    pub const GLOSSY_ROUGHNESS: f32 = 0.3;
    /// Specular reflectance of a dielectric ("plastic") surface at normal
    /// incidence, IOR 1.5: ((1.5−1)/(1.5+1))² = 0.04. The reference renders
    /// use a rough plastic there; we keep its normal-incidence energy split.
    pub const DIELECTRIC_SPECULAR: f32 = 0.04;

    pub fn diffuse(name: &str, albedo: Vec3) -> Self {
        Material {
            name: name.to_string(),
            diffuse: albedo,
            specular: Vec3::ZERO,
            exponent: 1.0,
            emission: Vec3::ZERO,
            double_sided: false,
        }
    }

    pub fn glossy(name: &str, diffuse: Vec3, specular: Vec3, exponent: f32) -> Self {
        Material {
            specular,
            exponent,
            ..Material::diffuse(name, diffuse)
        }
    }

    pub fn emitter(name: &str, radiance: Vec3) -> Self {
        Material {
            emission: radiance,
            ..Material::diffuse(name, Vec3::ZERO)
        }
    }

    /// Map glTF metallic-roughness factors as DESIGN.md and the reference
    /// renders do: roughness ≥ 0.3 is Lambertian; below, modified Phong with
    /// `n = 2/α² − 2`, `α = roughness²`; metals put all of `baseColor` in the
    /// lobe, dielectrics keep a diffuse base under a 4 % white lobe.
    pub fn from_metallic_roughness(
        name: &str,
        base_color: Vec3,
        metallic: f32,
        roughness: f32,
    ) -> Self {
        if roughness >= Self::GLOSSY_ROUGHNESS {
            return Material::diffuse(name, base_color);
        }
        // α is clamped as the reference does (max(α, 0.001)), which also keeps n finite.
        let alpha = (roughness * roughness).max(1e-3);
        let exponent = (2.0 / (alpha * alpha) - 2.0).max(1.0);
        if metallic >= 0.5 {
            Material::glossy(name, Vec3::ZERO, base_color, exponent)
        } else {
            let ks = Self::DIELECTRIC_SPECULAR;
            Material::glossy(name, base_color * (1.0 - ks), Vec3::splat(ks), exponent)
        }
    }

    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    pub fn is_glossy(&self) -> bool {
        self.specular.max_element() > 0.0
    }
}

/// Spot cone of a punctual light (glTF `KHR_lights_punctual` spot).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spot {
    pub inner_cone: f32,
    pub outer_cone: f32,
}

/// How a punctual light sends its light from its node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// From the node's origin in every direction.
    Point,
    /// From the node's origin within a cone about its −Z.
    Spot(Spot),
    /// Parallel along the node's −Z, from infinitely far (a sun): where
    /// the node is does not matter, only which way it turns.
    Directional,
}

impl LightKind {
    /// The spot's cone, if this is a spot light.
    pub fn spot(self) -> Option<Spot> {
        match self {
            LightKind::Spot(spot) => Some(spot),
            _ => None,
        }
    }
}

/// A point, spot or directional light attached to a node; it shines down
/// the node's −Z.
#[derive(Clone, Debug)]
pub struct PunctualLight {
    pub name: String,
    pub node: usize,
    /// Per colour channel: the radiant intensity (W·sr⁻¹) of a point or
    /// spot light, the irradiance (W·m⁻²) a directional light gives a
    /// surface facing it.
    pub intensity: Vec3,
    pub kind: LightKind,
}

/// Perspective camera attached to a node; looks down the node's −Z.
#[derive(Clone, Debug)]
pub struct CameraDef {
    pub node: usize,
    /// Vertical field of view in radians.
    pub yfov: f32,
    /// The width-to-height ratio the file gives (glTF `aspectRatio`), if
    /// any. Frames keep `yfov` and take the image's own ratio; this is only
    /// to say when the two differ.
    pub aspect_ratio: Option<f32>,
}

/// A whole animated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub nodes: Vec<Node>,
    pub objects: Vec<Object>,
    pub materials: Vec<Material>,
    pub lights: Vec<PunctualLight>,
    pub camera: CameraDef,
    pub animation: Animation,
    /// Number of frames the animation is meant to be rendered for.
    pub frame_count: u32,
    /// What [`Scene::move_to_origin`] added to every position of the file
    /// (zero where it did not move the scene): the scene's own
    /// coordinates are these positions less it.
    pub moved_by: Vec3,
}

/// The length of the longest edge of the triangle with corners `p`.
pub fn longest_edge(p: &[Vec3; 3]) -> f32 {
    (0..3)
        .map(|k| (p[(k + 1) % 3] - p[k]).length())
        .fold(0.0f32, f32::max)
}

/// The smallest box `(min, max)` around `points`; `None` where there are
/// none (or none but NaN).
pub fn bounding_box(points: impl IntoIterator<Item = Vec3>) -> Option<(Vec3, Vec3)> {
    let (lo, hi) = (points.into_iter())
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        });
    lo.cmple(hi).all().then_some((lo, hi))
}

impl Scene {
    /// Loads a scene from a `.gltf`/`.glb` file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        Scene::load_confined(path, None)
    }

    /// Warns of a scene too small for the ray traversal ([`SMALLEST_SCENE`]).
    fn warn_if_tiny(&self, path: &Path) {
        let size = self.diagonal_at(0.0);
        if size < SMALLEST_SCENE {
            eprintln!(
                "warning: {}: the scene is {size:.2e} units across (its bounding box at time 0); \
                 rays are traversed from {} units behind their start, whose rounding loses \
                 light under {SMALLEST_SCENE} units (glTF lengths are metres: scale the scene up)",
                path.display(),
                crate::accel::NEAR_SHIFT
            );
        }
    }

    /// The diagonal of the bounding box of every mesh's vertices at time
    /// `t`, in world units; 0 for a scene without vertices.
    pub fn diagonal_at(&self, t: f32) -> f32 {
        self.bounds_at(t).map_or(0.0, |(lo, hi)| {
            let d = (hi - lo).length();
            if d.is_finite() {
                d
            } else {
                0.0
            }
        })
    }

    /// The bounding box (least and greatest corner) of every mesh's
    /// vertices at time `t`; `None` for a scene without vertices.
    pub fn bounds_at(&self, t: f32) -> Option<(Vec3, Vec3)> {
        let world = self.node_world_transforms(t);
        bounding_box(self.objects.iter().flat_map(|o| {
            let placed = world[o.node];
            o.mesh
                .positions
                .iter()
                .map(move |p| placed.transform_point3(*p))
        }))
    }

    /// Moves a scene whose box at time 0 lies far from the origin (its
    /// centre farther away than the box's diagonal) so that the box is
    /// centred on it, and returns the move, added to every position
    /// (also kept in [`Scene::moved_by`]); `None` leaves the scene as it is.
    ///
    /// Why: 32-bit coordinates are spaced in proportion to their size, and
    /// rays leave a surface by 1e-4 of its point's coordinates
    /// ([`crate::integrator::RayOffset`]), 0.1 units a kilometre from the
    /// origin. `l_hall` moved 100, 1,000 and 10,000 units away
    /// (`benches/scenes/place.py ... move D`) rendered with
    /// `path` at 64 spp a block bias of 0.37 %, 3.5 % and 35 % against its
    /// frames at the origin (light through the corners, contact shadows
    /// gone). Moved back, it renders as at the origin. Nothing the file
    /// holds is lost: the move is composed with each root's transform
    /// first (`T(by)·M`, whose translation is `t + by`, and so is a vertex
    /// a root places), and a coordinate less a centre near it is exact
    /// (Sterbenz's lemma).
    ///
    /// How: the scene's root nodes are hung from one more node, last, that
    /// moves them (every mesh, light and the camera hang from a root), so
    /// the file's own nodes and keys stay as it gives them. A scene around
    /// the origin, as most are, keeps its bits.
    pub fn move_to_origin(&mut self) -> Option<Vec3> {
        let (lo, hi) = self.bounds_at(0.0)?;
        let centre = 0.5 * lo + 0.5 * hi;
        let far = centre.length() > (hi - lo).length();
        if !far {
            return None;
        }
        let by = -centre;
        self.hang_roots_from("(moved to the origin)", by);
        self.moved_by += by;
        Some(by)
    }

    /// Hangs every root node from a new static root, last, named `name`
    /// and placed at `translation`; returns its index.
    pub fn hang_roots_from(&mut self, name: &str, translation: Vec3) -> usize {
        let root = self.nodes.len();
        for node in self.nodes.iter_mut().filter(|n| n.parent.is_none()) {
            node.parent = Some(root);
        }
        self.nodes.push(Node {
            name: name.into(),
            parent: None,
            rest: Trs {
                translation,
                ..Trs::default()
            },
        });
        root
    }

    /// Loads a scene from a `.gltf`/`.glb` file that, with every file its
    /// URIs name, must lie inside `root` when it is given
    /// ([`gltf_loader::load_confined`]).
    pub fn load_confined(path: &Path, root: Option<&Path>) -> Result<Scene, SceneError> {
        let scene = gltf_loader::load_confined(path, root)?;
        scene.warn_if_tiny(path);
        Ok(scene)
    }

    /// A built-in scene by name (see [`builtin::NAMES`]).
    pub fn builtin(name: &str) -> Result<Scene, SceneError> {
        builtin::build(name)
    }

    /// `node` and its ancestors, from it up to its root.
    pub fn ancestry(&self, node: usize) -> Vec<usize> {
        std::iter::successors(Some(node), |&n| self.nodes[n].parent).collect()
    }

    /// Whether a node moves: it or one of its ancestors is animated.
    pub fn node_is_dynamic(&self, node: usize) -> bool {
        let mut current = Some(node);
        while let Some(n) = current {
            if self.animation.animates(n) {
                return true;
            }
            current = self.nodes[n].parent;
        }
        false
    }

    pub fn object_is_dynamic(&self, object: usize) -> bool {
        self.node_is_dynamic(self.objects[object].node)
    }

    /// [`Self::node_is_dynamic`] of every node, in time linear in nodes
    /// and channels (asking node by node scans every channel for each of
    /// a node's ancestors).
    pub fn dynamic_nodes(&self) -> Vec<bool> {
        self.under_any(self.animation.animated_nodes(self.nodes.len()))
    }

    /// Per node, whether the turn or scale of its world transform can
    /// change: a rotation or scale channel targets it or an ancestor (a
    /// translation carries a subtree along and turns none of it).
    pub fn turning_nodes(&self) -> Vec<bool> {
        let turns = |p: Property| matches!(p, Property::Rotation | Property::Scale);
        let animated = self.animation.nodes_animated_in(self.nodes.len(), turns);
        self.under_any(animated)
    }

    /// Per punctual light, whether the animation changes the light it
    /// sends: a point or spot light on a node that moves, a directional
    /// light on one that turns (it has a direction and no place).
    pub fn moving_lights(&self) -> Vec<bool> {
        let (dynamic, turning) = (self.dynamic_nodes(), self.turning_nodes());
        (self.lights.iter())
            .map(|l| match l.kind {
                LightKind::Directional => turning[l.node],
                LightKind::Point | LightKind::Spot(_) => dynamic[l.node],
            })
            .collect()
    }

    /// Per node, whether it or an ancestor is `marked` (by node).
    fn under_any(&self, marked: Vec<bool>) -> Vec<bool> {
        // Resolved top-down as world transforms are: a node's answer is
        // its own or its nearest resolved ancestor's.
        let mut dynamic: Vec<Option<bool>> = vec![None; self.nodes.len()];
        let mut unresolved = Vec::new();
        for node in 0..self.nodes.len() {
            unresolved.clear();
            let mut next = Some(node);
            let mut above = false;
            while let Some(n) = next {
                if let Some(d) = dynamic[n] {
                    above = d;
                    break;
                }
                unresolved.push(n);
                next = self.nodes[n].parent;
            }
            for &n in unresolved.iter().rev() {
                above |= marked[n];
                dynamic[n] = Some(above);
            }
        }
        dynamic.into_iter().map(|d| d.unwrap_or(false)).collect()
    }

    /// [`Self::object_is_dynamic`] of every object.
    pub fn dynamic_objects(&self) -> Vec<bool> {
        let nodes = self.dynamic_nodes();
        self.objects.iter().map(|o| nodes[o.node]).collect()
    }

    /// The product of the rotations of `node` and its ancestors at `t`,
    /// root first, normalised at each step.
    fn chain_rotation(&self, node: usize, t: f32) -> Quat {
        self.ancestry(node)
            .iter()
            .rev()
            .fold(Quat::IDENTITY, |above, &n| {
                let local = self.animation.local_trs(n, self.nodes[n].rest, t).rotation;
                (above * local).normalize()
            })
    }

    /// World transforms of all nodes at time `t`.
    pub fn node_world_transforms(&self, t: f32) -> Vec<Mat4> {
        let locals = self
            .animation
            .local_transforms(self.nodes.iter().map(|n| n.rest), t);
        let mut world: Vec<Option<Mat4>> = vec![None; self.nodes.len()];
        // One walk's buffer for all nodes: this runs several times a frame.
        let mut unresolved = Vec::new();
        for i in 0..self.nodes.len() {
            self.resolve_world(i, &locals, &mut world, &mut unresolved);
        }
        world
            .into_iter()
            .map(|m| m.unwrap_or(Mat4::IDENTITY))
            .collect()
    }

    /// Resolves the world transform of `node` and of its ancestors not
    /// resolved yet. A loop, not recursion: a file may chain its nodes
    /// deeper than a thread's stack would hold.
    fn resolve_world(
        &self,
        node: usize,
        locals: &[Trs],
        world: &mut [Option<Mat4>],
        unresolved: &mut Vec<usize>,
    ) {
        // Up to the first resolved ancestor (loaders guarantee the
        // hierarchy is a forest, so the walk ends at a root)...
        unresolved.clear();
        let mut next = Some(node);
        let mut above = None;
        while let Some(n) = next {
            if let Some(m) = world[n] {
                above = Some(m);
                break;
            }
            unresolved.push(n);
            next = self.nodes[n].parent;
        }
        // ...then down, each node's transform its parent's times its own.
        for &n in unresolved.iter().rev() {
            let local = locals[n].to_mat4();
            let m = above.map_or(local, |parent| parent * local);
            world[n] = Some(m);
            above = Some(m);
        }
    }

    /// Rigid motion of an object from time `t0` to `t1`: the matrix taking a
    /// world point on the object at `t0` to where it is at `t1`.
    pub fn object_motion(&self, object: usize, t0: f32, t1: f32) -> Mat4 {
        let node = self.objects[object].node;
        let w0 = self.node_world_transforms(t0)[node];
        let w1 = self.node_world_transforms(t1)[node];
        w1 * w0.inverse()
    }

    /// Objects ordered static first, then dynamic (the triangle order of
    /// every snapshot).
    pub fn object_order(&self) -> Vec<usize> {
        static_first(&self.dynamic_objects())
    }

    /// Every object's world transform at time `t` (as a snapshot has them,
    /// without its triangles).
    pub fn object_transforms(&self, t: f32) -> Vec<Mat4> {
        self.objects_in(&self.node_world_transforms(t))
    }

    /// Every object's world transform, given every node's.
    fn objects_in(&self, world: &[Mat4]) -> Vec<Mat4> {
        self.objects.iter().map(|o| world[o.node]).collect()
    }
}

/// Indices of `dynamic` (per object) with the static objects first, each
/// part in index order.
fn static_first(dynamic: &[bool]) -> Vec<usize> {
    let (mut order, moving): (Vec<usize>, Vec<usize>) =
        (0..dynamic.len()).partition(|&o| !dynamic[o]);
    order.extend(moving);
    order
}

/// Largest world coordinate a triangle may have. Beyond it the BVH
/// builders' boxes overflow `f32` (a box's surface area of 1e36 is near
/// its range) and obvhs panics. The loader bounds every transform, key and
/// vertex by [`gltf_loader::MAX_COORDINATE`] and checks the placed scene at
/// t = 0 against this; only animation that carries geometry further gets
/// here later, and its triangles are then collapsed rather than traced.
pub const MAX_WORLD_COORDINATE: f32 = 1e17;

pub(crate) fn within_world(v: Vec3) -> bool {
    v.is_finite() && v.abs().max_element() <= MAX_WORLD_COORDINATE
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;

    /// A scene hung from a far root node whose translation is keyed as a
    /// cubic spline is moved to the origin: every vertex, light and the
    /// camera at any time lie where they did, less the centre (within the
    /// coordinates' spacing there), and the spline's tangents are kept.
    #[test]
    fn a_far_scene_moved_to_the_origin_keeps_its_shape_and_motion() {
        let mut scene = Scene::builtin("moving-light").unwrap();
        let far = Vec3::new(3000.0, -800.0, 1200.0);
        let root = scene.hang_roots_from("far", Vec3::ZERO);
        let (tangent_in, tangent_out) = (
            Vec4::new(0.5, 0.0, -1.0, 0.0),
            Vec4::new(2.0, 1.0, 0.0, 0.0),
        );
        scene.animation.channels.push(Channel {
            node: root,
            property: Property::Translation,
            interpolation: Interpolation::CubicSpline,
            times: vec![0.0, 1.0],
            values: vec![
                tangent_in,
                far.extend(0.0),
                tangent_out,
                tangent_in,
                (far + Vec3::X).extend(0.0),
                tangent_out,
            ],
        });
        let times = [0.0, 0.3, 0.75];
        let before: Vec<Snapshot> = times.iter().map(|&t| scene.snapshot(t)).collect();
        let by = scene.move_to_origin().expect("3.3 km away");
        assert_eq!(scene.moved_by, by);
        let (lo, hi) = scene.bounds_at(0.0).unwrap();
        assert!((lo + hi).abs().max_element() < 1e-2, "{lo} {hi}");
        let spline = scene.animation.channels.last().unwrap();
        assert_eq!(
            [spline.values[0], spline.values[2], spline.values[5]],
            [tangent_in, tangent_out, tangent_out]
        );
        let near = |a: Vec3, b: Vec3| (a + by - b).abs().max_element() < 4e-3;
        for (&t, was) in times.iter().zip(&before) {
            let now = scene.snapshot(t);
            let corners =
                |s: &Snapshot| s.triangles.iter().flat_map(|tri| tri.p).collect::<Vec<_>>();
            assert!(
                corners(was)
                    .into_iter()
                    .zip(corners(&now))
                    .all(|(a, b)| near(a, b)),
                "t = {t}"
            );
            assert!(near(was.camera.position, now.camera.position), "t = {t}");
            let lights = was.lights.iter().zip(&now.lights);
            assert!(lights.clone().count() > 0 || scene.lights.is_empty());
            assert!(
                lights.clone().all(|(a, b)| near(a.position, b.position)),
                "t = {t}"
            );
        }
        assert!(scene.move_to_origin().is_none(), "moved once");
    }

    /// A translation carries its subtree and turns none of it; a rotation
    /// or scale turns its subtree. A point light is moved by either, a
    /// sun only by a turn. Nodes: a root keyed by `root` with a child,
    /// each holding a point light and a sun.
    #[test]
    fn only_a_turn_moves_a_sun_and_either_moves_a_point_light() {
        // Appended to a built-in scene, whose own nodes and lights are
        // left out of the answers compared.
        let base = Scene::builtin("cube-in-box").unwrap();
        let (root, lights) = (base.nodes.len(), base.lights.len());
        let scene_with = |property: Property| {
            let mut scene = base.clone();
            for (name, parent) in [("root", None), ("child", Some(root))] {
                scene.nodes.push(Node {
                    name: name.into(),
                    parent,
                    rest: Trs::default(),
                });
            }
            for node in [root, root + 1] {
                for kind in [LightKind::Point, LightKind::Directional] {
                    let name = format!("{node} {kind:?}");
                    let intensity = Vec3::ONE;
                    scene.lights.push(PunctualLight {
                        name,
                        node,
                        intensity,
                        kind,
                    });
                }
            }
            let values = vec![Vec4::new(0.0, 0.0, 0.0, 1.0), Vec4::new(0.0, 1.0, 0.0, 1.0)];
            scene.animation.channels.push(animation::Channel {
                node: root,
                property,
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values,
            });
            scene
        };
        let carried = scene_with(Property::Translation);
        assert_eq!(carried.dynamic_nodes()[root..], [true, true]);
        assert_eq!(carried.turning_nodes()[root..], [false, false]);
        assert_eq!(
            carried.moving_lights()[lights..],
            [true, false, true, false]
        );
        for turn in [Property::Rotation, Property::Scale] {
            let turned = scene_with(turn);
            assert_eq!(turned.turning_nodes()[root..], [true, true], "{turn:?}");
            assert_eq!(turned.moving_lights()[lights..], [true; 4], "{turn:?}");
        }
        let mut still = scene_with(Property::Translation);
        still.animation.channels.pop();
        assert_eq!(still.moving_lights()[lights..], [false; 4]);
    }
}
