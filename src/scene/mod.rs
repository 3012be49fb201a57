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
pub mod gltf_loader;
mod placed;

use glam::{Mat3, Mat4, Quat, Vec3};
pub use placed::Placed;
use std::path::Path;
use std::sync::{Arc, OnceLock};

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

/// World-space triangle with per-vertex shading normals.
#[derive(Clone, Copy, Debug)]
pub struct Triangle {
    pub p: [Vec3; 3],
    pub n: [Vec3; 3],
}

impl Triangle {
    /// Unnormalised geometric normal (counter-clockwise front), length = 2·area.
    pub fn cross(&self) -> Vec3 {
        (self.p[1] - self.p[0]).cross(self.p[2] - self.p[0])
    }

    pub fn area(&self) -> f32 {
        0.5 * self.cross().length()
    }

    /// The length of its longest edge ([`longest_edge`]).
    pub fn longest_edge(&self) -> f32 {
        longest_edge(&self.p)
    }

    pub fn geometric_normal(&self) -> Vec3 {
        self.cross().normalize_or_zero()
    }

    /// The mean of the corners.
    pub fn centroid(&self) -> Vec3 {
        (self.p[0] + self.p[1] + self.p[2]) / 3.0
    }

    /// Point at barycentrics (u, v): `p0·(1−u−v) + p1·u + p2·v`.
    pub fn point(&self, u: f32, v: f32) -> Vec3 {
        self.p[0] * (1.0 - u - v) + self.p[1] * u + self.p[2] * v
    }

    /// Interpolated shading normal at (u, v); falls back to the geometric one.
    pub fn shading_normal(&self, u: f32, v: f32) -> Vec3 {
        let n = self.n[0] * (1.0 - u - v) + self.n[1] * u + self.n[2] * v;
        let n = n.normalize_or_zero();
        if n == Vec3::ZERO {
            self.geometric_normal()
        } else {
            n
        }
    }
}

/// A punctual light evaluated at one time.
#[derive(Clone, Copy, Debug)]
pub struct PlacedLight {
    /// The node's origin; zero for a directional light, whose place is of
    /// no account (so that a sun carried by a moving node is a still
    /// light to what compares lights from frame to frame).
    pub position: Vec3,
    /// Unit direction the light points to (node −Z).
    pub direction: Vec3,
    /// As [`PunctualLight::intensity`].
    pub intensity: Vec3,
    pub kind: LightKind,
}

impl PlacedLight {
    pub fn is_directional(&self) -> bool {
        self.kind == LightKind::Directional
    }

    /// Intensity of a point or spot light toward unit direction `w` (from
    /// the light), with the glTF spot falloff (smooth between the outer
    /// and inner cone).
    pub fn intensity_toward(&self, w: Vec3) -> Vec3 {
        match self.kind {
            LightKind::Point | LightKind::Directional => self.intensity,
            LightKind::Spot(spot) => {
                let cos = self.direction.dot(w);
                let (ci, co) = (spot.inner_cone.cos(), spot.outer_cone.cos());
                let s = if ci - co > 1e-6 {
                    ((cos - co) / (ci - co)).clamp(0.0, 1.0)
                } else if cos >= co {
                    1.0
                } else {
                    0.0
                };
                self.intensity * (s * s)
            }
        }
    }
}

/// The camera evaluated at one time.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub position: Vec3,
    /// Columns: right (+X), up (+Y), backward (+Z) in world space, orthonormal.
    pub basis: Mat3,
    pub yfov: f32,
    /// `tan(yfov/2)`, computed once: every camera ray needs it.
    tan_half_fov: f32,
}

impl Camera {
    /// `tan(yfov/2)`: half the film's height at distance 1.
    pub fn tan_half_fov(&self) -> f32 {
        self.tan_half_fov
    }

    /// Direction of the ray through film point (sx, sy) ∈ \[0, 1\]², (0,0) at the
    /// top-left corner, for an image of the given aspect ratio (width/height).
    pub fn direction(&self, sx: f32, sy: f32, aspect: f32) -> Vec3 {
        let tan_half = self.tan_half_fov;
        let x = (2.0 * sx - 1.0) * tan_half * aspect;
        let y = (1.0 - 2.0 * sy) * tan_half;
        (self.basis * Vec3::new(x, y, -1.0)).normalize()
    }

    /// The film point (sx, sy) ∈ \[0, 1\]² (as [`Camera::direction`] takes it,
    /// (0,0) at the top-left corner) that world point `p` projects to, or
    /// `None` when `p` is not in front of the camera. Points outside the
    /// view give coordinates outside \[0, 1\].
    pub fn project(&self, p: Vec3, aspect: f32) -> Option<(f32, f32)> {
        let local = self.basis.transpose() * (p - self.position);
        if local.z >= -1e-6 {
            return None;
        }
        let tan_half = self.tan_half_fov;
        let x = local.x / -local.z / (tan_half * aspect);
        let y = local.y / -local.z / tan_half;
        Some((0.5 * (x + 1.0), 0.5 * (1.0 - y)))
    }

    /// Whether some of `tri` may show on the film: false only when all
    /// three corners lie outside one plane of the view frustum (behind the
    /// camera, or beyond one side of the film), so it errs towards true.
    pub fn may_see(&self, tri: &Triangle, aspect: f32) -> bool {
        let (tx, ty) = (self.tan_half_fov * aspect, self.tan_half_fov);
        let local = tri.p.map(|p| self.basis.transpose() * (p - self.position));
        // Inside the frustum every one of these is ≤ 0 (camera looks down −z).
        let planes: [fn(Vec3, f32, f32) -> f32; 5] = [
            |l, _, _| l.z,
            |l, tx, _| l.x + l.z * tx,
            |l, tx, _| -l.x + l.z * tx,
            |l, _, ty| l.y + l.z * ty,
            |l, _, ty| -l.y + l.z * ty,
        ];
        !planes
            .iter()
            .any(|outside| local.iter().all(|&l| outside(l, tx, ty) > 0.0))
    }
}

/// The scene evaluated at one time `t`: world-space triangles (static objects
/// first, then dynamic ones, in object order so that triangle ids are stable
/// across frames), lights and camera.
/// Its static triangles (and their objects and materials) are shared with
/// the snapshot it was made from ([`Scene::snapshot_from`], [`Placed`]).
#[derive(Clone, Debug)]
pub struct Snapshot {
    pub time: f32,
    pub triangles: Placed<Triangle>,
    /// Object id of each triangle.
    pub tri_object: Placed<u32>,
    /// Material id of each triangle.
    pub tri_material: Placed<u32>,
    /// Triangles `0..static_count` belong to objects that never move.
    pub static_count: usize,
    /// World transform of every object at `time`.
    pub object_to_world: Vec<Mat4>,
    pub lights: Vec<PlacedLight>,
    pub camera: Camera,
    /// [`Snapshot::static_fingerprint`] and the shared part's emitters
    /// ([`Snapshot::emitting_triangles`]), found once for the snapshots
    /// that share a static part.
    statics_seen: Arc<StaticsSeen>,
}

/// What is found once of a static part.
#[derive(Default)]
struct StaticsSeen {
    fingerprint: OnceLock<Fingerprinted>,
    emitters: OnceLock<SharedEmitters>,
}

/// The triangles of a shared part of [`Snapshot::tri_material`] whose
/// material is one of `emissive`, with the part they were found in (held,
/// as [`Fingerprinted`] holds its own).
struct SharedEmitters {
    materials: Arc<[u32]>,
    emissive: Vec<u32>,
    ids: Vec<u32>,
}

/// A fingerprint with the shared triangles and objects it was taken of
/// (held, so that no other part is ever taken for them: a shared part is
/// never changed in place, [`Placed`]). Their length is the static count
/// it was taken with.
struct Fingerprinted {
    triangles: Arc<[Triangle]>,
    objects: Arc<[u32]>,
    fingerprint: u64,
}

impl std::fmt::Debug for StaticsSeen {
    /// Nothing: derived from the triangles, it would only tell snapshots
    /// apart by what was asked of them.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("StaticsSeen")
    }
}

impl Snapshot {
    /// The bounding box (least and greatest corner) of the triangles;
    /// `None` without triangles.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        bounding_box(self.triangles.iter().flat_map(|t| t.p))
    }
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

    /// The camera at time `t` (as [`Scene::snapshot`] evaluates it).
    pub fn camera_at(&self, t: f32) -> Camera {
        let world = self.node_world_transforms(t);
        self.camera_in(&world, t)
    }

    /// The camera at time `t` given the world transforms of that time. A
    /// camera scaled to nothing (its node or an ancestor animated to scale
    /// 0) has no orientation in its matrix; it keeps the one its nodes'
    /// rotations give (its frames were black).
    fn camera_in(&self, world: &[Mat4], t: f32) -> Camera {
        self.camera_placed(&world[self.camera.node], t)
    }

    /// The camera at time `t` given its node's world transform `m` then.
    fn camera_placed(&self, m: &Mat4, t: f32) -> Camera {
        let mut camera = camera_at(m, self.camera.yfov);
        if !camera.basis.is_finite() {
            camera.basis = Mat3::from_quat(self.chain_rotation(self.camera.node, t));
        }
        camera
    }

    /// Checks that the camera can be rendered from at time `t`: a
    /// position within [`MAX_WORLD_COORDINATE`] and a finite orientation.
    /// Geometry and lights carried past the world are collapsed or
    /// darkened ([`Self::snapshot`]); a camera has no such fallback, and
    /// its frames were black. `when` names the time in the error (e.g.
    /// "t = 0.0417 s (frame 1)"), which names the camera's node.
    pub fn check_camera(&self, t: f32, when: &str) -> Result<(), String> {
        self.check_camera_at([t], |_| when.to_string())
    }

    /// [`Self::check_camera`] at each of `times` in turn, the first fault
    /// named with `when(t)`. Only the camera's node chain is evaluated,
    /// with its own channels picked once: cheap for many times in a large
    /// scene.
    pub fn check_camera_at(
        &self,
        times: impl IntoIterator<Item = f32>,
        when: impl Fn(f32) -> String,
    ) -> Result<(), String> {
        let mut chain = self.ancestry(self.camera.node);
        chain.reverse();
        let channels: Vec<Vec<&Channel>> = (chain.iter())
            .map(|&n| {
                self.animation
                    .channels
                    .iter()
                    .filter(|c| c.node == n)
                    .collect()
            })
            .collect();
        for t in times {
            // As `node_world_transforms` composes it: root first, each
            // node's transform its parent's times its own.
            let world = chain.iter().zip(&channels).fold(None, |above, (&n, chs)| {
                let mut local = self.nodes[n].rest;
                for c in chs {
                    c.apply(&mut local, t);
                }
                let local = local.to_mat4();
                Some(above.map_or(local, |parent: Mat4| parent * local))
            });
            let camera = self.camera_placed(&world.unwrap_or(Mat4::IDENTITY), t);
            let name = &self.nodes[self.camera.node].name;
            let p = camera.position;
            if !p.is_finite() {
                return Err(format!(
                    "camera node '{name}' is carried to a non-finite position at {}: the \
                     transforms of the node and its ancestors compound past f32's range \
                     (about 3.4e38), and no image can be rendered from there",
                    when(t)
                ));
            }
            if !within_world(p) {
                return Err(format!(
                    "camera node '{name}' is carried to a coordinate of magnitude {:e} at {}, \
                     beyond {MAX_WORLD_COORDINATE:e}, past what can be traced",
                    p.abs().max_element(),
                    when(t)
                ));
            }
            if !camera.basis.is_finite() {
                return Err(format!(
                    "camera node '{name}' has no orientation at {} (its transform is not \
                     finite: scaled to zero, or past f32's range?)",
                    when(t)
                ));
            }
        }
        Ok(())
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

    /// Evaluates the scene at time `t`.
    /// Every object's world transform at time `t` (as a snapshot has them,
    /// without its triangles).
    pub fn object_transforms(&self, t: f32) -> Vec<Mat4> {
        self.objects_in(&self.node_world_transforms(t))
    }

    /// Every object's world transform, given every node's.
    fn objects_in(&self, world: &[Mat4]) -> Vec<Mat4> {
        self.objects.iter().map(|o| world[o.node]).collect()
    }

    pub fn snapshot(&self, t: f32) -> Snapshot {
        self.snapshot_keeping(t, |_| true)
    }

    /// The snapshot at `t` with its emitting triangles only, in their
    /// order in [`Scene::snapshot`], and all of its lights, object
    /// transforms and camera: for what reads the lights of a frame, or the
    /// motion of its objects, rather than its geometry (`trc` and `tcg`
    /// look at the frames around the one rendered, and a whole snapshot
    /// moves every vertex of the scene). Its triangle ids are not the
    /// frame's.
    pub fn emitters_snapshot(&self, t: f32) -> Snapshot {
        self.snapshot_keeping(t, |m| self.materials[m as usize].is_emissive())
    }

    /// [`Scene::snapshot`] at `t`, made from `earlier`, a snapshot of this
    /// scene at another time: its static triangles, which no animation
    /// moves ([`Scene::dynamic_objects`]), are shared with it, bit for bit
    /// what placing them again gives, and only the moving ones are placed.
    /// A frame of a large scene otherwise moves every vertex: a static
    /// 2M-triangle mesh took 0.15 s a frame of 0.22 s (`trc`, 64 × 64).
    /// An `earlier` whose static part is not this scene's whole one (an
    /// [`Scene::emitters_snapshot`]) is not taken.
    pub fn snapshot_from(&self, t: f32, earlier: &Snapshot) -> Snapshot {
        let dynamic = self.dynamic_objects();
        let static_triangles: usize = (self.objects.iter().zip(&dynamic))
            .filter(|(_, &moves)| !moves)
            .map(|(o, _)| o.mesh.triangles.len())
            .sum();
        if earlier.static_count != static_triangles || earlier.tri_object.len() < static_triangles {
            return self.snapshot(t);
        }
        let world = self.node_world_transforms(t);
        let mut moving = Triangles::default();
        for object in (0..dynamic.len()).filter(|&o| dynamic[o]) {
            let o = &self.objects[object];
            moving.append(object as u32, &o.mesh, &world[o.node], |_| true);
        }
        let (triangles, objects) = (
            earlier.triangles.prefix(static_triangles),
            earlier.tri_object.prefix(static_triangles),
        );
        let shared = Arc::ptr_eq(&triangles, earlier.triangles.shared())
            && Arc::ptr_eq(&objects, earlier.tri_object.shared());
        Snapshot {
            triangles: Placed::new(triangles, moving.triangles),
            tri_object: Placed::new(objects, moving.objects),
            tri_material: Placed::new(
                earlier.tri_material.prefix(static_triangles),
                moving.materials,
            ),
            static_count: static_triangles,
            statics_seen: match shared {
                true => earlier.statics_seen.clone(),
                false => Arc::default(),
            },
            ..self.posed(t, &world)
        }
    }

    /// The snapshot at `t` with the triangles whose material `keep` takes.
    fn snapshot_keeping(&self, t: f32, keep: impl Fn(u32) -> bool) -> Snapshot {
        let world = self.node_world_transforms(t);
        let dynamic = self.dynamic_objects();
        let mut placed = Triangles::default();
        let mut static_count = 0;
        for object in static_first(&dynamic) {
            let o = &self.objects[object];
            placed.append(object as u32, &o.mesh, &world[o.node], &keep);
            if !dynamic[object] {
                static_count = placed.triangles.len();
            }
        }
        Snapshot {
            triangles: Placed::sharing_first(placed.triangles, static_count),
            tri_object: Placed::sharing_first(placed.objects, static_count),
            tri_material: Placed::sharing_first(placed.materials, static_count),
            static_count,
            ..self.posed(t, &world)
        }
    }

    /// A snapshot at `t` (nodes placed by `world`) with no triangles: its
    /// object transforms, lights and camera.
    fn posed(&self, t: f32, world: &[Mat4]) -> Snapshot {
        Snapshot {
            time: t,
            triangles: Placed::default(),
            tri_object: Placed::default(),
            tri_material: Placed::default(),
            static_count: 0,
            object_to_world: self.objects_in(world),
            statics_seen: Arc::default(),
            lights: self
                .lights
                .iter()
                .map(|l| {
                    let m = world[l.node];
                    let position = m.transform_point3(Vec3::ZERO);
                    // Carried past what can be traced (as triangles are
                    // collapsed, below), a light sends nothing: its
                    // position would make NaN light samples. A
                    // directional light has no position.
                    let directional = l.kind == LightKind::Directional;
                    let traceable = within_world(position);
                    let shines = traceable || directional;
                    PlacedLight {
                        position: if traceable && !directional {
                            position
                        } else {
                            Vec3::ZERO
                        },
                        direction: m.transform_vector3(-Vec3::Z).normalize_or_zero(),
                        intensity: if shines { l.intensity } else { Vec3::ZERO },
                        kind: l.kind,
                    }
                })
                .collect(),
            camera: self.camera_in(world, t),
        }
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

fn camera_at(m: &Mat4, yfov: f32) -> Camera {
    let (_, rotation, translation) = m.to_scale_rotation_translation();
    Camera {
        position: translation,
        basis: Mat3::from_quat(rotation.normalize()),
        yfov,
        tan_half_fov: (0.5 * yfov).tan(),
    }
}

/// Triangles placed in world space, with their objects and materials, as
/// a snapshot is assembled.
#[derive(Default)]
struct Triangles {
    triangles: Vec<Triangle>,
    objects: Vec<u32>,
    materials: Vec<u32>,
}

impl Triangles {
    /// Appends the triangles of `object` (its `mesh` placed by `to_world`)
    /// whose material `keep` takes.
    fn append(&mut self, object: u32, mesh: &Mesh, to_world: &Mat4, keep: impl Fn(u32) -> bool) {
        // Normals transform with the inverse transpose (non-uniform scale).
        let normal_matrix = Mat3::from_mat4(*to_world).inverse().transpose();
        let flip = to_world.determinant() < 0.0;
        let kept = mesh.triangles.iter().zip(&mesh.materials);
        for (tri, &material) in kept.filter(|(_, &m)| keep(m)) {
            let mut idx = tri.map(|i| i as usize);
            if flip {
                // A mirroring transform reverses winding; keep the front face.
                idx.swap(1, 2);
            }
            let mut p = idx.map(|i| to_world.transform_point3(mesh.positions[i]));
            if !p.iter().all(|v| within_world(*v)) {
                // Collapsed to a point, which no ray hits; its index stays.
                p = [Vec3::ZERO; 3];
            }
            let n = idx.map(|i| {
                mesh.normals
                    .get(i)
                    .map(|&n| (normal_matrix * n).normalize_or_zero())
                    .unwrap_or(Vec3::ZERO)
            });
            self.triangles.push(Triangle { p, n });
            self.objects.push(object);
            self.materials.push(material);
        }
    }
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

impl Snapshot {
    pub fn dynamic_count(&self) -> usize {
        self.triangles.len() - self.static_count
    }

    /// FNV-1a over the static triangles' vertex bits and object ids: ray
    /// backends rebuild (and re-upload) their static part only when this
    /// changes (a new scene), without keeping a copy of the geometry.
    /// Found once for the snapshots sharing a static part (a frame's and
    /// those made from it, [`Scene::snapshot_from`]): a 2M-triangle part
    /// took some 20 ms to hash, and the backend and `trc` asked for it
    /// every frame.
    pub fn static_fingerprint(&self) -> u64 {
        let (triangles, objects) = (self.triangles.shared(), self.tri_object.shared());
        let whole = triangles.len() == self.static_count && objects.len() == self.static_count;
        // With `whole`, the same allocations are the same static count.
        let seen = |f: &Fingerprinted| {
            Arc::ptr_eq(&f.triangles, triangles) && Arc::ptr_eq(&f.objects, objects)
        };
        let kept = &self.statics_seen.fingerprint;
        if !whole || kept.get().is_some_and(|s| !seen(s)) {
            return self.hash_statics();
        }
        kept.get_or_init(|| Fingerprinted {
            triangles: triangles.clone(),
            objects: objects.clone(),
            fingerprint: self.hash_statics(),
        })
        .fingerprint
    }

    /// The ids of the triangles whose material emits, in increasing order.
    /// Those of the shared part ([`Placed`]) are found once for the
    /// snapshots sharing it, for the emissive materials they were found
    /// for: a light sampler is made several times a frame, and a static
    /// 2M-triangle mesh took 4–5 % of `trc`'s time to scan for them.
    pub fn emitting_triangles(&self, materials: &[Material]) -> Vec<u32> {
        let emits = |&(_, &m): &(usize, &u32)| materials[m as usize].is_emissive();
        let emissive: Vec<u32> = (0..materials.len() as u32)
            .filter(|&m| materials[m as usize].is_emissive())
            .collect();
        let shared = self.tri_material.shared();
        let found = || SharedEmitters {
            materials: shared.clone(),
            emissive: emissive.clone(),
            ids: (shared.iter().enumerate().filter(emits))
                .map(|(i, _)| i as u32)
                .collect(),
        };
        let kept = self.statics_seen.emitters.get_or_init(found);
        let mut ids = match Arc::ptr_eq(&kept.materials, shared) && kept.emissive == emissive {
            true => kept.ids.clone(),
            false => found().ids,
        };
        let owned = self.tri_material.iter().enumerate().skip(shared.len());
        ids.extend(owned.filter(emits).map(|(i, _)| i as u32));
        ids
    }

    /// [`Snapshot::static_fingerprint`], hashed.
    fn hash_statics(&self) -> u64 {
        let mut h = crate::hash::Fnv1a::default();
        let mut eat = |x: u32| h.write_word(x);
        let statics = (self.triangles.range(0..self.static_count)).zip(&self.tri_object);
        for (tri, &object) in statics {
            for p in tri.p {
                for x in p.to_array() {
                    eat(x.to_bits());
                }
            }
            eat(object);
        }
        h.finish() ^ self.static_count as u64
    }
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

    /// The fingerprint found once for a static part is the hash of that
    /// part: a snapshot made from another shares its part and its
    /// fingerprint, and one whose static triangle or count is changed
    /// afterwards gets the hash of what it now holds, not the one kept.
    #[test]
    fn a_static_fingerprint_kept_is_the_hash_of_the_part_it_was_found_of() {
        let scene = Scene::builtin("chairs-room").unwrap();
        let first = scene.snapshot(0.0);
        assert!(first.static_count > 0);
        let fingerprint = first.static_fingerprint();
        assert_eq!(fingerprint, first.hash_statics());
        let next = scene.snapshot_from(0.5, &first);
        assert!(Arc::ptr_eq(&next.statics_seen, &first.statics_seen));
        // Shared, not copied: the change's point.
        assert!(Arc::ptr_eq(
            next.triangles.shared(),
            first.triangles.shared()
        ));
        assert!(Arc::ptr_eq(
            next.tri_object.shared(),
            first.tri_object.shared()
        ));
        assert!(Arc::ptr_eq(
            next.tri_material.shared(),
            first.tri_material.shared()
        ));
        assert_eq!(next.triangles.shared().len(), first.static_count);
        assert_eq!(next.static_fingerprint(), fingerprint);

        let mut moved = scene.snapshot_from(0.5, &first);
        moved.triangles[0].p[0].x += 1.0;
        assert_ne!(moved.static_fingerprint(), fingerprint);
        assert_eq!(moved.static_fingerprint(), moved.hash_statics());
        let mut fewer = scene.snapshot_from(0.5, &first);
        fewer.static_count -= 1;
        assert_ne!(fewer.static_fingerprint(), fingerprint);
        assert_eq!(fewer.static_fingerprint(), fewer.hash_statics());
        assert_eq!(first.static_fingerprint(), fingerprint);
    }

    /// The emitting triangles found once for a shared static part are
    /// those a scan of every triangle's material finds: in the snapshot
    /// they were found in and one made from it, for materials of which
    /// another emits, and in a snapshot whose static emitter was given
    /// another material since.
    #[test]
    fn emitting_triangles_kept_for_a_static_part_are_those_a_scan_finds() {
        let scan = |s: &Snapshot, materials: &[Material]| -> Vec<u32> {
            let emits = |i: &u32| materials[s.tri_material[*i as usize] as usize].is_emissive();
            (0..s.triangles.len() as u32).filter(emits).collect()
        };
        let mut static_emitters = 0;
        for name in builtin::NAMES {
            let scene = Scene::builtin(name).unwrap();
            let first = scene.snapshot(0.0);
            let next = scene.snapshot_from(0.5, &first);
            let found = first.emitting_triangles(&scene.materials);
            assert!(!found.is_empty(), "{name}");
            assert_eq!(found, scan(&first, &scene.materials), "{name}");
            assert!(next.statics_seen.emitters.get().is_some(), "{name}: kept");
            assert_eq!(
                next.emitting_triangles(&scene.materials),
                scan(&next, &scene.materials),
                "{name}"
            );

            let dark = (0..first.static_count)
                .map(|i| first.tri_material[i])
                .find(|&m| !scene.materials[m as usize].is_emissive());
            if let Some(dark) = dark {
                let mut lit = scene.materials.clone();
                lit[dark as usize].emission = Vec3::ONE;
                let found_lit = next.emitting_triangles(&lit);
                assert_ne!(found_lit, found, "{name}");
                assert_eq!(found_lit, scan(&next, &lit), "{name}");
                if let Some(&e) = found.iter().find(|&&e| (e as usize) < first.static_count) {
                    static_emitters += 1;
                    let mut changed = scene.snapshot_from(0.5, &first);
                    changed.tri_material[e as usize] = dark;
                    let found_changed = changed.emitting_triangles(&scene.materials);
                    assert!(!found_changed.contains(&e), "{name}");
                    assert_eq!(found_changed, scan(&changed, &scene.materials), "{name}");
                }
            }
        }
        assert!(
            static_emitters > 0,
            "no built-in scene has a static emitter"
        );
    }

    /// A snapshot made in an earlier one, whose static triangles it keeps,
    /// is the snapshot made afresh, bit for bit (their `Debug` texts
    /// agree), from an earlier time or a later one, and an emitters
    /// snapshot is not taken for one. The emitters snapshot has the
    /// emitting triangles of the whole one, in their order, and its lights,
    /// transforms and camera.
    #[test]
    fn snapshots_made_in_earlier_ones_and_of_emitters_agree_with_whole_ones() {
        let text = |s: &Snapshot| format!("{s:?}");
        for name in builtin::NAMES {
            let scene = Scene::builtin(name).unwrap();
            let times = [0.0, 0.52, 1.0, 0.25];
            for pair in times.windows(2) {
                let [earlier, t] = [pair[0], pair[1]];
                let whole = scene.snapshot(t);
                let from = scene.snapshot_from(t, &scene.snapshot(earlier));
                assert_eq!(text(&from), text(&whole), "{name} at {t}");
                let emitters = scene.emitters_snapshot(earlier);
                let from_emitters = scene.snapshot_from(t, &emitters);
                assert_eq!(text(&from_emitters), text(&whole), "{name} at {t}");
            }
            let (whole, emitters) = (scene.snapshot(0.3), scene.emitters_snapshot(0.3));
            let emitting: Vec<String> = (whole.triangles.iter().zip(&whole.tri_material))
                .filter(|(_, &m)| scene.materials[m as usize].is_emissive())
                .map(|(t, _)| format!("{t:?}"))
                .collect();
            let kept: Vec<String> = emitters
                .triangles
                .iter()
                .map(|t| format!("{t:?}"))
                .collect();
            assert!(!kept.is_empty(), "{name}: no emitter");
            assert_eq!(kept, emitting, "{name}");
            assert_eq!(
                format!(
                    "{:?}",
                    (
                        &emitters.object_to_world,
                        &emitters.lights,
                        &emitters.camera
                    )
                ),
                format!(
                    "{:?}",
                    (&whole.object_to_world, &whole.lights, &whole.camera)
                ),
            );
        }
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

    /// A light its animation carries past what can be traced sends nothing
    /// from then on (its samples would be NaN), as such triangles are
    /// collapsed; before, it shines from where it is.
    #[test]
    fn a_light_carried_past_the_world_goes_dark() {
        let mut scene = Scene::builtin("cube-in-box").unwrap();
        let parent = scene.nodes.len();
        scene.nodes.push(Node {
            name: "big".into(),
            parent: None,
            rest: Trs {
                scale: Vec3::splat(1e8),
                ..Trs::default()
            },
        });
        scene.nodes.push(Node {
            name: "lamp".into(),
            parent: Some(parent),
            rest: Trs::default(),
        });
        scene.lights.push(PunctualLight {
            name: "lamp".into(),
            node: parent + 1,
            intensity: Vec3::ONE,
            kind: LightKind::Point,
        });
        scene.animation.channels.push(animation::Channel {
            node: parent + 1,
            property: Property::Translation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0],
            values: vec![glam::Vec4::ZERO, glam::Vec4::new(1e10, 0.0, 0.0, 0.0)],
        });
        let at = |t: f32| *scene.snapshot(t).lights.last().unwrap();
        let near = at(1e-9);
        assert!(near.position.x > 0.0 && near.intensity == Vec3::ONE);
        let far = at(1.0);
        assert!(
            far.position.is_finite() && far.intensity == Vec3::ZERO,
            "{far:?}"
        );
    }

    #[test]
    fn project_inverts_direction() {
        let scene = Scene::builtin("cube-in-box").unwrap();
        let camera = scene.camera_at(0.5);
        let aspect = 1.5;
        for (sx, sy) in [(0.5, 0.5), (0.1, 0.9), (0.8, 0.2)] {
            let p = camera.position + 3.0 * camera.direction(sx, sy, aspect);
            let (x, y) = camera.project(p, aspect).unwrap();
            assert!((x - sx).abs() < 1e-4 && (y - sy).abs() < 1e-4, "{x} {y}");
        }
        let behind = camera.position - camera.direction(0.5, 0.5, aspect);
        assert_eq!(camera.project(behind, aspect), None);
    }

    /// A small triangle around the camera ray through film point `(sx, sy)`
    /// (outside [0,1]² is off the film), `d` along it (negative: behind).
    fn triangle_at(camera: &Camera, sx: f32, sy: f32, d: f32, aspect: f32) -> Triangle {
        let c = camera.position + d * camera.direction(sx, sy, aspect);
        let (r, u) = (camera.basis.x_axis * 0.01, camera.basis.y_axis * 0.01);
        Triangle {
            p: [c - r, c + r, c + u],
            n: [camera.basis.z_axis; 3],
        }
    }

    #[test]
    fn may_see_rejects_only_triangles_outside_one_frustum_plane() {
        let camera = Scene::builtin("cube-in-box").unwrap().camera_at(0.0);
        let aspect = 1.5;
        let at = |sx, sy, d| triangle_at(&camera, sx, sy, d, aspect);
        assert!(camera.may_see(&at(0.5, 0.5, 2.0), aspect));
        assert!(
            camera.may_see(&at(0.0, 1.0, 2.0), aspect),
            "on a film corner"
        );
        assert!(!camera.may_see(&at(0.5, 0.5, -2.0), aspect), "behind");
        for (sx, sy) in [(-0.2, 0.5), (1.2, 0.5), (0.5, -0.2), (0.5, 1.2)] {
            assert!(
                !camera.may_see(&at(sx, sy, 2.0), aspect),
                "off the film at {sx}, {sy}"
            );
        }
        // Corners on both sides of the camera's plane: kept (conservative).
        let mut straddling = at(0.5, 0.5, 2.0);
        straddling.p[0] = camera.position - 2.0 * camera.direction(0.5, 0.5, aspect);
        assert!(camera.may_see(&straddling, aspect));
    }
}
