//! The scene evaluated at one time: world-space triangles, lights and camera.

use super::{
    bounding_box, longest_edge, static_first, within_world, Camera, LightKind, Material, Mesh,
    Placed, Scene,
};
use glam::{Mat3, Mat4, Vec3};
use std::sync::{Arc, OnceLock};

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
    /// As [`PunctualLight::intensity`](super::PunctualLight::intensity).
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

impl Scene {
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

    /// Per object, the id of its first triangle in a snapshot of the whole
    /// scene ([`Scene::snapshot`]: objects static first, each mesh's
    /// triangles in order), for [`Scene::place_triangle`].
    pub fn first_triangles(&self) -> Vec<usize> {
        let mut first = vec![0; self.objects.len()];
        let mut next = 0;
        for object in self.object_order() {
            first[object] = next;
            next += self.objects[object].mesh.triangles.len();
        }
        first
    }

    /// Triangle `index` of `object`'s mesh placed by `placing` (the
    /// object's transform at some time, [`Snapshot::object_to_world`]):
    /// bit for bit that triangle of a snapshot at that time, without
    /// placing the others (`trc` shades a few triangles of each of the
    /// frames ahead it looks at).
    pub fn place_triangle(&self, object: usize, index: usize, placing: &Placing) -> Triangle {
        let mesh = &self.objects[object].mesh;
        placing.place(mesh, mesh.triangles[index])
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
        let placing = Placing::new(*to_world);
        let kept = mesh.triangles.iter().zip(&mesh.materials);
        for (&tri, &material) in kept.filter(|(_, &m)| keep(m)) {
            self.triangles.push(placing.place(mesh, tri));
            self.objects.push(object);
            self.materials.push(material);
        }
    }
}

/// A transform as it places a mesh's triangles in world space (what it
/// takes of the transform found once, not for each triangle).
pub struct Placing {
    to_world: Mat4,
    /// Normals transform with the inverse transpose (non-uniform scale).
    normal_matrix: Mat3,
    /// A mirroring transform reverses winding.
    flip: bool,
}

impl Placing {
    pub fn new(to_world: Mat4) -> Self {
        Placing {
            to_world,
            normal_matrix: Mat3::from_mat4(to_world).inverse().transpose(),
            flip: to_world.determinant() < 0.0,
        }
    }

    /// Triangle `tri` (its vertex indices) of `mesh`, placed.
    fn place(&self, mesh: &Mesh, tri: [u32; 3]) -> Triangle {
        let mut idx = tri.map(|i| i as usize);
        if self.flip {
            // Keep the front face.
            idx.swap(1, 2);
        }
        let mut p = idx.map(|i| self.to_world.transform_point3(mesh.positions[i]));
        if !p.iter().all(|v| within_world(*v)) {
            // Collapsed to a point, which no ray hits; its index stays.
            p = [Vec3::ZERO; 3];
        }
        let n = idx.map(|i| {
            mesh.normals
                .get(i)
                .map(|&n| (self.normal_matrix * n).normalize_or_zero())
                .unwrap_or(Vec3::ZERO)
        });
        Triangle { p, n }
    }
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
    use crate::scene::{animation, builtin, Interpolation, Node, Property, PunctualLight, Trs};

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
    /// transforms and camera; and each triangle placed alone
    /// ([`Scene::place_triangle`]) is the whole one's.
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
            let first = scene.first_triangles();
            for (id, (tri, &object)) in whole.triangles.iter().zip(&whole.tri_object).enumerate() {
                let object = object as usize;
                let placing = Placing::new(emitters.object_to_world[object]);
                let alone = scene.place_triangle(object, id - first[object], &placing);
                assert_eq!(format!("{alone:?}"), format!("{tri:?}"), "{name}: {id}");
            }
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
}
