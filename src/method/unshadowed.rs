//! Lights reduced to the unshadowed direct light they give a point: how
//! the light reaching a surface changes from one frame to another when
//! lights move, without a shadow ray. `trc` scales its reprojected samples
//! by it (TRC §4.7), and `tcg` finds with it the samples that moving
//! lights have left stale.

use super::FrameContext;
use crate::scene::{Material, PlacedLight, Snapshot};
use glam::Vec3;
use std::collections::{BTreeMap, HashMap};
use std::ops::RangeInclusive;
use std::sync::Arc;

/// A frame's lights, each area light taken as a point at its triangle's
/// centroid.
#[derive(Clone, Debug)]
pub(crate) struct UnshadowedLights {
    emitters: Vec<Emitter>,
}

/// The lights of the frames around the one rendered, each evaluated once
/// (from a snapshot of the frame's emitters) and found again by
/// frame number, so that a resumed render computes the same ones.
#[derive(Default)]
pub(crate) struct LightsByFrame {
    frames: BTreeMap<u32, Arc<UnshadowedLights>>,
}

impl LightsByFrame {
    /// Forgets the frames outside `keep`.
    pub(crate) fn keep(&mut self, keep: RangeInclusive<u32>) {
        self.frames.retain(|f, _| keep.contains(f));
    }

    /// The lights of frame `f` of `ctx`'s scene, evaluated if new.
    pub(crate) fn at(&mut self, ctx: &FrameContext, f: u32) -> Arc<UnshadowedLights> {
        self.frames
            .entry(f)
            .or_insert_with(|| {
                Arc::new(if f == ctx.frame {
                    UnshadowedLights::of(&ctx.scene.materials, ctx.snapshot)
                } else {
                    let frame = ctx.scene.emitters_snapshot(ctx.time_of(f));
                    UnshadowedLights::of(&ctx.scene.materials, &frame)
                })
            })
            .clone()
    }

    /// The lights of frame `f`, if kept.
    pub(crate) fn get(&self, f: u32) -> Option<&UnshadowedLights> {
        self.frames.get(&f).map(|l| &**l)
    }
}

/// A light reduced to what the unshadowed direct light needs.
#[derive(Clone, Copy, Debug)]
enum Emitter {
    /// An emissive triangle: centroid, unit normal, `L_e · area`, area.
    Area {
        center: Vec3,
        normal: Vec3,
        power: Vec3,
        area: f32,
        double_sided: bool,
    },
    /// A punctual light.
    Punctual(PlacedLight),
}

impl UnshadowedLights {
    /// The lights of `snapshot` (a frame of the scene whose `materials`
    /// these are): each emitting triangle a point at its centroid, but for
    /// the emitting triangles of an object and material that are more than
    /// [`CLUSTERED_OVER`]: those are merged into at most 48 points
    /// ([`Clusters`]). Why: every sample `trc` reprojects under moving
    /// lights, and every sample `tcg` checks for moving lights' change,
    /// sums over these points; with a point a triangle, a moving emitting
    /// ball of 6,240 triangles took `trc` 31.76 s and `tcg` 44.57 s for 6
    /// frames at 48 × 48, where `ic` takes 1.04 s (`benches/HISTORY.md`).
    pub(crate) fn of(materials: &[Material], snapshot: &Snapshot) -> Self {
        Self::merging_over(materials, snapshot, CLUSTERED_OVER)
    }

    /// [`Self::of`], merging the triangles of the lights with more than
    /// `clustered_over` of them.
    fn merging_over(materials: &[Material], snapshot: &Snapshot, clustered_over: usize) -> Self {
        // The emitting triangles, found once: the passes below run over
        // them, not over every triangle of the frame.
        let emitting: Vec<usize> = (snapshot.emitting_triangles(materials).into_iter())
            .map(|id| id as usize)
            .filter(|&id| snapshot.triangles[id].area() > 0.0)
            .collect();
        let mut clusters = Clusters::of_large_lights(snapshot, &emitting, clustered_over);
        let mut emitters = Vec::new();
        for &id in &emitting {
            if clusters.take(snapshot, id) {
                continue;
            }
            let (tri, m) = (
                &snapshot.triangles[id],
                &materials[snapshot.tri_material[id] as usize],
            );
            emitters.push(Emitter::Area {
                center: tri.centroid(),
                normal: tri.geometric_normal(),
                power: m.emission * tri.area(),
                area: tri.area(),
                double_sided: m.double_sided,
            });
        }
        emitters.extend(clusters.into_emitters(materials));
        emitters.extend(snapshot.lights.iter().map(|l| Emitter::Punctual(*l)));
        UnshadowedLights { emitters }
    }

    /// One point light of `intensity` at `position`, for unit tests.
    #[cfg(test)]
    pub(crate) fn point(position: Vec3, intensity: Vec3) -> Self {
        UnshadowedLights {
            emitters: vec![Emitter::Punctual(PlacedLight {
                position,
                direction: Vec3::NEG_Z,
                intensity,
                kind: crate::scene::LightKind::Point,
            })],
        }
    }

    /// One directional light of irradiance `intensity` along `direction`
    /// (unit), for unit tests.
    #[cfg(test)]
    pub(crate) fn sun(direction: Vec3, intensity: Vec3) -> Self {
        UnshadowedLights {
            emitters: vec![Emitter::Punctual(PlacedLight {
                position: Vec3::ZERO,
                direction,
                intensity,
                kind: crate::scene::LightKind::Directional,
            })],
        }
    }

    /// Whether the two frames' lights are in the same places, to within
    /// rounding: a light held still by equal animation keys (as exporters
    /// that sample every frame write them) is interpolated at each frame
    /// and may round differently, and taking that for a move would make
    /// `trc` reproject every record at every later frame and `tcg` find
    /// every sample stale. A move or change of a part in 10⁵ counts.
    pub(crate) fn same_as(&self, other: &Self) -> bool {
        self.emitters.len() == other.emitters.len()
            && self
                .emitters
                .iter()
                .zip(&other.emitters)
                .all(|pair| match pair {
                    (
                        Emitter::Area {
                            center: c0,
                            normal: n0,
                            power: p0,
                            ..
                        },
                        Emitter::Area {
                            center: c1,
                            normal: n1,
                            power: p1,
                            ..
                        },
                    ) => nearly_equal(*c0, *c1) && nearly_equal(*n0, *n1) && nearly_equal(*p0, *p1),
                    (Emitter::Punctual(l0), Emitter::Punctual(l1)) => {
                        nearly_equal(l0.position, l1.position)
                            && nearly_equal(l0.direction, l1.direction)
                            && nearly_equal(l0.intensity, l1.intensity)
                            && l0.kind == l1.kind
                    }
                    _ => false,
                })
    }

    /// Whether the two frames' lights emit the same power, to within
    /// rounding (as [`Self::same_as`]): lights that move but are not
    /// switched on, off or dimmed.
    pub(crate) fn same_power(&self, other: &Self) -> bool {
        nearly_equal(self.power(), other.power())
    }

    /// The power the lights emit (W): `π·L_e·A` an area light (each side
    /// that emits), `4π·I` a point or spot light (spots taken as points),
    /// and what a directional light sends through one square unit, `E`
    /// (the scene's size is not known here: these lights may be those of
    /// a snapshot of the emitters alone). The total is compared only with
    /// itself at other frames.
    pub(crate) fn power(&self) -> Vec3 {
        use std::f32::consts::PI;
        let each = |l: &Emitter| match *l {
            Emitter::Area {
                power,
                double_sided,
                ..
            } => power * PI * if double_sided { 2.0 } else { 1.0 },
            Emitter::Punctual(light) if light.is_directional() => light.intensity,
            Emitter::Punctual(light) => light.intensity * 4.0 * PI,
        };
        self.emitters.iter().map(each).sum()
    }

    /// Unshadowed direct irradiance at `p` (normal `n`).
    pub(crate) fn irradiance(&self, p: Vec3, n: Vec3) -> Vec3 {
        self.reflected(p, |w, _| Vec3::splat(n.dot(w).max(0.0)))
    }

    /// How much the unshadowed direct irradiance at `p` may differ between
    /// these lights and `other` (the same lights at another time) on a
    /// surface of any normal there, and what they give a surface facing
    /// each light (the larger of the two times), by colour channel: where
    /// the normal at `p` is not known (a gather sample's hit), the first
    /// over the second bounds the relative change of its light. The change
    /// is `Σ |E′·w′ − E·w|` over the lights, `E` what one gives a surface
    /// facing it and `w` the unit direction to it, which bounds
    /// `|Σ E′·max(0, n·w′) − Σ E·max(0, n·w)|` for every unit `n`
    /// (`max(0, ·)` moves nothing farther apart): a light that comes
    /// nearer, goes farther, dims, or only turns about `p` (a sun, or a
    /// far point light swinging across the sky at the same distance)
    /// shows in it. Lights that do not pair up (one dropped out, a
    /// triangle scaled to nothing) count as changed wholly.
    pub(crate) fn change_at(&self, other: &Self, p: Vec3) -> (Vec3, Vec3) {
        let (mut change, mut before, mut after) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        let paired = self.emitters.len() == other.emitters.len();
        for (a, b) in self.emitters.iter().zip(&other.emitters) {
            let ((ea, wa, _), (eb, wb, _)) = (a.arriving(p), b.arriving(p));
            let channel = |k: usize| (wb * eb[k] - wa * ea[k]).length();
            change += Vec3::new(channel(0), channel(1), channel(2));
            (before, after) = (before + ea, after + eb);
        }
        if !paired {
            let facing = |lights: &Self| lights.emitters.iter().map(|e| e.arriving(p).0).sum();
            let (all_before, all_after): (Vec3, Vec3) = (facing(self), facing(other));
            return (all_before + all_after, all_before.max(all_after));
        }
        (change, before.max(after))
    }

    /// Σ over the lights of what each gives a surface at `p` facing it,
    /// times `weight(w, Ω)` for `w` the unit direction to it and `Ω` the
    /// solid angle it covers there (0 for a punctual light): the
    /// irradiance for `weight` the cosine to a normal, the radiance a
    /// surface there reflects for its BSDF (averaged over `Ω`) times that
    /// cosine.
    pub(crate) fn reflected(&self, p: Vec3, weight: impl Fn(Vec3, f32) -> Vec3) -> Vec3 {
        (self.emitters.iter())
            .map(|l| {
                let (e, w, solid_angle) = l.arriving(p);
                e * weight(w, solid_angle)
            })
            .sum()
    }
}

impl Emitter {
    /// What it gives a surface at `p` facing it (unshadowed), the unit
    /// direction from `p` to it, and the solid angle it covers seen from
    /// `p` (its area projected and over the distance squared, at most a
    /// hemisphere; 0 for a punctual light).
    fn arriving(&self, p: Vec3) -> (Vec3, Vec3, f32) {
        match *self {
            Emitter::Area {
                center,
                normal,
                power,
                area,
                double_sided,
            } => {
                let d = center - p;
                let d2 = d.length_squared().max(1e-8);
                let w = d / d2.sqrt();
                let cos_l = -normal.dot(w);
                let cos_l = if double_sided { cos_l.abs() } else { cos_l };
                let solid_angle = (area * cos_l.max(0.0) / d2).min(std::f32::consts::TAU);
                (power * (cos_l.max(0.0) / d2), w, solid_angle)
            }
            Emitter::Punctual(light) if light.is_directional() => {
                (light.intensity, -light.direction, 0.0)
            }
            Emitter::Punctual(light) => {
                let d = light.position - p;
                let d2 = d.length_squared().max(1e-8);
                let w = d / d2.sqrt();
                (light.intensity_toward(-w) / d2, w, 0.0)
            }
        }
    }
}

/// The most emitting triangles of one object and material taken one by
/// one; more are merged ([`Clusters`]). A quad light, or a light of a few
/// dozen triangles, keeps a point a triangle, as before there were
/// clusters.
const CLUSTERED_OVER: usize = 48;

/// The emitting triangles of the lights (one object, one material) with
/// more than [`CLUSTERED_OVER`] of them, merged into points: a light's
/// triangles are split by the axis their normal leans to most (6 ways) and
/// by the octant of the light's box their centroid lies in (8), and each
/// part becomes one point at its triangles' area-weighted centroid, with
/// their summed power and the direction of their summed area vectors as
/// its normal. The lights' total power is kept to rounding (`same_power`);
/// what each point sends is the far field of its part, which is what the
/// ratios of these irradiances before and after a move need, not the
/// light itself (the frames are lit by `light::LightSampler`).
struct Clusters {
    /// Per (object, material) of a large light: its index in `lights`.
    large: HashMap<(u32, u32), usize>,
    lights: Vec<LargeLight>,
}

/// A light that [`Clusters`] merges.
struct LargeLight {
    material: u32,
    /// Its box's centre, which the octants are of.
    centre: Vec3,
    /// Its parts by (normal axis, octant).
    parts: BTreeMap<(u8, u8), Part>,
}

/// What a [`Clusters`] part sums of its triangles.
#[derive(Clone, Copy, Default)]
struct Part {
    area: f32,
    /// Σ area · centroid.
    weighted_centre: Vec3,
    /// Σ area · unit normal.
    vector_area: Vec3,
}

impl Clusters {
    /// The lights among the triangles `emitting` of `snapshot` with more
    /// than `clustered_over` triangles, nothing merged yet.
    fn of_large_lights(snapshot: &Snapshot, emitting: &[usize], clustered_over: usize) -> Self {
        let mut counts: HashMap<(u32, u32), (usize, Vec3, Vec3)> = HashMap::new();
        for &id in emitting {
            let key = (snapshot.tri_object[id], snapshot.tri_material[id]);
            let (n, lo, hi) = counts
                .entry(key)
                .or_insert((0, Vec3::INFINITY, -Vec3::INFINITY));
            *n += 1;
            for p in snapshot.triangles[id].p {
                *lo = lo.min(p);
                *hi = hi.max(p);
            }
        }
        let mut large: Vec<((u32, u32), Vec3)> = counts
            .into_iter()
            .filter(|(_, (n, _, _))| *n > clustered_over)
            .map(|(key, (_, lo, hi))| (key, 0.5 * (lo + hi)))
            .collect();
        large.sort_by_key(|(key, _)| *key);
        Clusters {
            large: large
                .iter()
                .enumerate()
                .map(|(i, (key, _))| (*key, i))
                .collect(),
            lights: large
                .into_iter()
                .map(|((_, material), centre)| LargeLight {
                    material,
                    centre,
                    parts: BTreeMap::new(),
                })
                .collect(),
        }
    }

    /// Merges the emitting triangle `id` of `snapshot` into its light's
    /// part if its light is large; whether it was.
    fn take(&mut self, snapshot: &Snapshot, id: usize) -> bool {
        let key = (snapshot.tri_object[id], snapshot.tri_material[id]);
        let Some(&light) = self.large.get(&key) else {
            return false;
        };
        let tri = &snapshot.triangles[id];
        let LargeLight { centre, parts, .. } = &mut self.lights[light];
        let (area, normal) = (tri.area(), tri.geometric_normal());
        let at = tri.centroid();
        let octant = u8::from(at.x > centre.x)
            | u8::from(at.y > centre.y) << 1
            | u8::from(at.z > centre.z) << 2;
        let part = parts.entry((leaning_axis(normal), octant)).or_default();
        part.area += area;
        part.weighted_centre += area * at;
        part.vector_area += area * normal;
        true
    }

    /// One emitter a part, lights in (object, material) order.
    fn into_emitters(self, materials: &[Material]) -> Vec<Emitter> {
        let mut emitters = Vec::new();
        for LargeLight {
            material, parts, ..
        } in self.lights
        {
            let m = &materials[material as usize];
            emitters.extend(parts.into_values().map(|part| Emitter::Area {
                center: part.weighted_centre / part.area,
                normal: part.vector_area.normalize_or_zero(),
                power: m.emission * part.area,
                area: part.area,
                double_sided: m.double_sided,
            }));
        }
        emitters
    }
}

/// Which of ±x, ±y, ±z `normal` leans to most: `0..6`.
fn leaning_axis(normal: Vec3) -> u8 {
    let a = normal.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    2 * axis + u8::from(normal[axis as usize] < 0.0)
}

/// Whether `a` and `b` differ by at most a part in 10⁵ of the longer
/// (rounding in the interpolation of equal keys is a few parts in 10⁷).
fn nearly_equal(a: Vec3, b: Vec3) -> bool {
    const TOLERANCE: f32 = 1e-5;
    (a - b).length() <= TOLERANCE * a.length().max(b.length())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Triangle;
    use std::f32::consts::TAU;

    /// A narrow glossy lobe under a small area light, looked at along the
    /// light's mirror direction: the radiance `reflected` gives with the
    /// lobe averaged over the light's solid angle is the lobe integrated
    /// over the light's triangle (brute force), where the lobe taken at the
    /// light's centre alone, as a point's, gives tens of times too much
    /// (the fireflies `movies`' global pass showed on the glossy balls of
    /// `tests/data/scenes/spheres.glb`). A punctual light covers no solid
    /// angle: the lobe at its direction.
    #[test]
    fn a_glossy_lobe_reflects_an_area_light_integrated_over_its_area() {
        use crate::material::Bsdf;
        let centre = Vec3::new(0.5, 0.0, 1.0);
        let w_c = centre.normalize();
        let (n, wo) = (Vec3::Z, Vec3::new(-w_c.x, -w_c.y, w_c.z));
        // An equilateral triangle facing the origin, a quarter of its
        // distance from its centre to each corner.
        let (u, v) = (w_c.cross(Vec3::Y).normalize() * 0.25, Vec3::Y * 0.25);
        let r = centre.length();
        let corners = [u, v * 0.87 - u * 0.5, -v * 0.87 - u * 0.5].map(|c| centre + c * r);
        let light = Triangle {
            p: corners,
            n: [-w_c; 3],
        };
        let radiance = Vec3::new(3.0, 2.0, 1.0);
        let lights = UnshadowedLights {
            emitters: vec![Emitter::Area {
                center: light.centroid(),
                normal: -w_c,
                power: radiance * light.area(),
                area: light.area(),
                double_sided: false,
            }],
        };
        let glossy = crate::scene::Material::glossy("lobe", Vec3::ZERO, Vec3::splat(0.9), 2000.0);
        let bsdf = Bsdf::new(&glossy, n, wo);
        let cos = |w: Vec3| n.dot(w).max(0.0);
        let averaged = lights.reflected(Vec3::ZERO, |w, solid_angle| {
            bsdf.mean_specular(wo, w, solid_angle) * cos(w)
        });
        let as_point = lights.reflected(Vec3::ZERO, |w, _| bsdf.eval_specular(wo, w) * cos(w));
        let integrated =
            radiance * integrated_over(&light, |w| bsdf.eval_specular(wo, w).x * cos(w));
        let ratio = averaged / integrated;
        assert!(
            ratio.min_element() > 0.9 && ratio.max_element() < 1.1,
            "{averaged} {integrated}"
        );
        assert!(
            as_point.x > 10.0 * integrated.x,
            "{as_point} against {integrated}"
        );
        for tilt in [0.0, 0.01, 0.03, 0.1] {
            let w = (w_c + u * tilt).normalize();
            let (mean, at) = (bsdf.mean_specular(wo, w, 0.0), bsdf.eval_specular(wo, w));
            let off = (mean - at).abs().max_element();
            assert!(off <= 0.01 * at.x + 1e-6, "{tilt}: {mean} {at}");
        }
    }

    /// `∫ f(w) dω` over the solid angle `light` covers seen from the
    /// origin, by a 400 × 400 grid of points on it.
    fn integrated_over(light: &Triangle, f: impl Fn(Vec3) -> f32) -> f32 {
        let (k, [a, b, c]) = (400, light.p);
        let facing = light.geometric_normal();
        let mut sum = 0.0;
        for (i, j) in (0..k).flat_map(|i| (0..k).map(move |j| (i, j))) {
            let (mut s, mut t) = ((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
            if s + t > 1.0 {
                (s, t) = (1.0 - s, 1.0 - t);
            }
            let q = a + (b - a) * s + (c - a) * t;
            let w = q.normalize();
            sum += f(w) * (-facing.dot(w)).max(0.0) / q.length_squared();
        }
        sum * light.area() / (k * k) as f32
    }

    /// A ball of radius `r` at `centre`: a cube whose faces are split in
    /// `k × k` squares (two triangles each, fronts out), its corners
    /// pushed out onto the sphere.
    fn ball(centre: Vec3, r: f32, k: u32) -> Vec<[Vec3; 3]> {
        let mut triangles = Vec::new();
        for axis in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z] {
            let u = axis.any_orthonormal_vector();
            let v = axis.cross(u);
            let at = |i: u32, j: u32| {
                let (a, b) = (
                    2.0 * i as f32 / k as f32 - 1.0,
                    2.0 * j as f32 / k as f32 - 1.0,
                );
                centre + r * (axis + a * u + b * v).normalize()
            };
            for i in 0..k {
                for j in 0..k {
                    triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                    triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
        triangles
    }

    /// `triangles` in a snapshot of `cube-in-box` (whose materials it also
    /// gives), on object `object` each, all of its emitting material.
    fn emitting(parts: &[(u32, Vec<[Vec3; 3]>)]) -> (Vec<Material>, Snapshot) {
        let scene = crate::scene::Scene::builtin("cube-in-box").unwrap();
        let light = scene
            .materials
            .iter()
            .position(Material::is_emissive)
            .unwrap();
        let mut snapshot = scene.snapshot(0.0);
        snapshot.triangles.clear();
        snapshot.tri_object.clear();
        snapshot.tri_material.clear();
        snapshot.lights.clear();
        for (object, triangles) in parts {
            for &p in triangles {
                snapshot.triangles.push(crate::scene::Triangle {
                    p,
                    n: [Vec3::ZERO; 3],
                });
                snapshot.tri_object.push(*object);
                snapshot.tri_material.push(light as u32);
            }
        }
        snapshot.static_count = snapshot.triangles.len();
        (scene.materials, snapshot)
    }

    /// A ball light of 768 triangles and a panel of 288 are merged into
    /// at most 48 points each, a quad light (2 triangles) kept as it is.
    /// Their power is the triangles' (to rounding), and the unshadowed
    /// irradiance they give a point facing them 0.5 to 3 m away, and its
    /// ratio between two such points (what `trc` and `tcg` take of it),
    /// are within 2 % of the triangles' taken one by one.
    #[test]
    fn large_lights_are_merged_into_points_that_light_as_their_triangles() {
        let panel: Vec<[Vec3; 3]> = (0..144)
            .flat_map(|c| {
                let o = Vec3::new((c % 12) as f32 * 0.05, 2.0, (c / 12) as f32 * 0.05);
                let (x, z) = (Vec3::X * 0.05, Vec3::Z * 0.05);
                [[o, o + x, o + x + z], [o, o + x + z, o + z]]
            })
            .collect();
        let quad = panel[..2].iter().map(|t| t.map(|p| p + Vec3::Y)).collect();
        let parts = [
            (0, ball(Vec3::new(1.0, 1.0, -1.0), 0.2, 8)),
            (1, panel),
            (2, quad),
        ];
        let (materials, snapshot) = emitting(&parts);
        let merged = UnshadowedLights::of(&materials, &snapshot);
        let one_by_one = UnshadowedLights::merging_over(&materials, &snapshot, usize::MAX);
        assert_eq!(one_by_one.emitters.len(), 768 + 288 + 2);
        assert!(
            merged.emitters.len() <= 48 + 48 + 2,
            "{}",
            merged.emitters.len()
        );
        assert!(merged.emitters.len() > 2 + 2);
        let (a, b) = (merged.power(), one_by_one.power());
        assert!(
            (a - b).abs().max_element() <= 1e-5 * b.max_element(),
            "{a} {b}"
        );
        let lit = |lights: &UnshadowedLights, p: Vec3| {
            let towards = Vec3::new(1.0, 1.5, -0.5) - p;
            lights.irradiance(p, towards.normalize()).x
        };
        let points = [
            Vec3::new(1.0, 0.0, -0.5),
            Vec3::new(-1.0, 1.0, 1.0),
            Vec3::new(0.3, 1.2, 0.2),
            Vec3::new(2.5, 2.5, -2.5),
            Vec3::new(0.2, 0.4, -1.6),
        ];
        for (i, &p) in points.iter().enumerate() {
            let (m, o) = (lit(&merged, p), lit(&one_by_one, p));
            assert!((m / o - 1.0).abs() < 0.02, "at {p}: {m} against {o}");
            let q = points[(i + 1) % points.len()];
            let ratio = (m / lit(&merged, q)) / (o / lit(&one_by_one, q));
            assert!((ratio - 1.0).abs() < 0.02, "{p} to {q}: {ratio}");
        }
    }

    /// Unit normals over the sphere, a 64 × 32 grid (equal area).
    fn normals() -> impl Iterator<Item = Vec3> {
        (0..64).flat_map(|i| {
            (0..32).map(move |j| {
                let (phi, cos) = (i as f32 / 64.0 * TAU, 1.0 - 2.0 * (j as f32 + 0.5) / 32.0);
                let sin = (1.0 - cos * cos).sqrt();
                Vec3::new(sin * phi.cos(), cos, sin * phi.sin())
            })
        })
    }

    /// The largest change of the irradiance at `p` between `a` and `b`
    /// over [`normals`], by channel.
    fn largest_change(a: &UnshadowedLights, b: &UnshadowedLights, p: Vec3) -> Vec3 {
        normals()
            .map(|n| (b.irradiance(p, n) - a.irradiance(p, n)).abs())
            .fold(Vec3::ZERO, Vec3::max)
    }

    /// That `largest` (a change over the normals) is within `bound` and
    /// meets it to 5 % (the grid's steps).
    fn assert_met(bound: Vec3, largest: Vec3) {
        assert!(
            largest.cmple(bound * 1.0001).all(),
            "{largest} over {bound}"
        );
        assert!(
            largest.cmpgt(bound * 0.95).all(),
            "{largest} against {bound}"
        );
    }

    /// A sun turned by θ: the bound is `2E·sin(θ/2)`, it holds on every
    /// normal of a grid over the sphere, and is met on one; the scale is
    /// what it gives a surface facing it.
    #[test]
    fn a_turning_sun_changes_any_surfaces_light_by_at_most_its_bound() {
        let e = Vec3::new(2.0, 1.0, 0.5);
        let before = Vec3::new(0.3, -1.0, 0.2).normalize();
        let turn = glam::Quat::from_axis_angle(Vec3::Z, 0.3);
        let (a, b) = (
            UnshadowedLights::sun(before, e),
            UnshadowedLights::sun(turn * before, e),
        );
        let (bound, scale) = a.change_at(&b, Vec3::ONE);
        let expected = e * (before - turn * before).length();
        assert!(
            (bound - expected).abs().max_element() < 1e-6,
            "{bound} {expected}"
        );
        assert_eq!(scale, e);
        assert_eq!(a.change_at(&a, Vec3::ONE).0, Vec3::ZERO);
        assert_met(bound, largest_change(&a, &b, Vec3::ZERO));
    }

    /// A far point light swung 15° about a point at the same distance (a
    /// sun made of a point light): the light arriving there from it is the
    /// same, but a surface at an angle to it sees it change, by about the
    /// bound on the worst normal. So for a point light moved nearer, a
    /// spot turned away, an area light moved and tilted, all at once: the
    /// bound holds on every normal.
    #[test]
    fn a_light_that_only_turns_about_a_point_changes_its_light_within_the_bound() {
        let p = Vec3::new(0.5, 0.2, -0.3);
        let i = Vec3::new(1600.0, 800.0, 400.0);
        let swung = glam::Quat::from_rotation_z(15f32.to_radians());
        let far = Vec3::new(0.0, 40.0, 0.0);
        let (a, b) = (lit_by(p + far, i), lit_by(p + swung * far, i));
        let (bound, scale) = a.change_at(&b, p);
        assert!((scale - i / 1600.0).abs().max_element() < 1e-6, "{scale}");
        let largest = largest_change(&a, &b, p);
        assert_met(bound, largest);
        assert!(largest.max_element() > 0.2 * scale.max_element());

        let spot = |position: Vec3, direction: Vec3| PlacedLight {
            position,
            direction,
            intensity: Vec3::splat(3.0),
            kind: crate::scene::LightKind::Spot(crate::scene::Spot {
                inner_cone: 0.3,
                outer_cone: 0.6,
            }),
        };
        let panel = |center: Vec3, normal: Vec3| Emitter::Area {
            center,
            normal,
            power: Vec3::new(2.0, 2.0, 1.0),
            area: 1.0,
            double_sided: false,
        };
        let lights = |k: f32| UnshadowedLights {
            emitters: vec![
                Emitter::Punctual(PlacedLight {
                    position: Vec3::new(2.0 - k, 1.0, 0.0),
                    direction: Vec3::NEG_Z,
                    intensity: Vec3::new(1.0, 2.0, 3.0),
                    kind: crate::scene::LightKind::Point,
                }),
                Emitter::Punctual(spot(
                    Vec3::new(0.0, 2.0, 0.0),
                    Vec3::new(k, -1.0, 0.0).normalize(),
                )),
                panel(
                    Vec3::new(-1.0 + k, 1.5, 0.5),
                    Vec3::new(0.2 * k, -1.0, 0.0).normalize(),
                ),
            ],
        };
        let (a, b) = (lights(0.0), lights(0.4));
        for q in [Vec3::ZERO, p, Vec3::new(-0.5, 0.0, 1.0)] {
            let (bound, _) = a.change_at(&b, q);
            let largest = largest_change(&a, &b, q);
            assert!(
                largest.cmple(bound * 1.0001).all(),
                "{q}: {largest} over {bound}"
            );
            assert!(largest.max_element() > 0.0, "{q}");
        }
    }

    /// Lights that do not pair up (one more in the second) count as changed
    /// wholly: the change is at least the scale.
    #[test]
    fn lights_that_do_not_pair_up_change_wholly() {
        let a = lit_by(Vec3::Y, Vec3::ONE);
        let mut b = a.clone();
        b.emitters
            .extend(lit_by(Vec3::new(5.0, 5.0, 0.0), Vec3::splat(1e-3)).emitters);
        let (change, scale) = a.change_at(&b, Vec3::ZERO);
        assert!(change.cmpge(scale).all() && scale.cmpgt(Vec3::ZERO).all());
    }

    fn lit_by(position: Vec3, intensity: Vec3) -> UnshadowedLights {
        UnshadowedLights::point(position, intensity)
    }

    #[test]
    fn lights_that_differ_by_rounding_are_the_same_and_a_move_is_not() {
        let p = Vec3::new(3.0, 2.0, -1.5);
        let i = Vec3::splat(40.0);
        let here = lit_by(p, i);
        // What interpolating equal keys at another time can give: an ulp.
        let rounded = lit_by(
            Vec3::new(f32::from_bits(3.0f32.to_bits() + 1), 2.0, -1.5),
            i,
        );
        assert!(here.same_as(&rounded));
        assert!(!here.same_as(&lit_by(p + Vec3::new(0.0, 1e-3, 0.0), i)));
        assert!(!here.same_as(&lit_by(p, i * 1.001)));
        assert!(!here.same_as(&lit_by(p, Vec3::ZERO)), "switched off");
        assert!(lit_by(p, Vec3::ZERO).same_as(&lit_by(p, Vec3::ZERO)));
        let spot = |outer_cone: f32| {
            let mut lights = lit_by(p, i);
            if let Emitter::Punctual(light) = &mut lights.emitters[0] {
                light.kind = crate::scene::LightKind::Spot(crate::scene::Spot {
                    inner_cone: 0.1,
                    outer_cone,
                });
            }
            lights
        };
        assert!(spot(0.5).same_as(&spot(0.5)));
        assert!(!spot(0.5).same_as(&spot(0.6)), "a spot's cone widened");
    }
}
