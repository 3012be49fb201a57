//! Lights reduced to the unshadowed direct light they give a point: how
//! the light reaching a surface changes from one frame to another when
//! lights move, without a shadow ray. `trc` scales its reprojected samples
//! by it (TRC §4.7), and `tcg` finds with it the samples that moving
//! lights have left stale.

use super::FrameContext;
use crate::scene::Snapshot;
use glam::Vec3;
use std::collections::BTreeMap;
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
                    UnshadowedLights::of(ctx, ctx.snapshot)
                } else {
                    UnshadowedLights::of(ctx, &ctx.scene.emitters_snapshot(ctx.time_of(f)))
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
    /// An emissive triangle: centroid, unit normal, `L_e · area`.
    Area {
        center: Vec3,
        normal: Vec3,
        power: Vec3,
        double_sided: bool,
    },
    /// A punctual light.
    Point(crate::scene::PointLight),
}

impl UnshadowedLights {
    /// The lights of `snapshot` (a frame of `ctx`'s scene).
    pub(crate) fn of(ctx: &FrameContext, snapshot: &Snapshot) -> Self {
        let mut emitters = Vec::new();
        for (tri, &m) in snapshot.triangles.iter().zip(&snapshot.tri_material) {
            let m = &ctx.scene.materials[m as usize];
            if m.is_emissive() && tri.area() > 0.0 {
                emitters.push(Emitter::Area {
                    center: (tri.p[0] + tri.p[1] + tri.p[2]) / 3.0,
                    normal: tri.geometric_normal(),
                    power: m.emission * tri.area(),
                    double_sided: m.double_sided,
                });
            }
        }
        emitters.extend(snapshot.lights.iter().map(|l| Emitter::Point(*l)));
        UnshadowedLights { emitters }
    }

    /// One point light of `intensity` at `position`, for unit tests.
    #[cfg(test)]
    pub(crate) fn point(position: Vec3, intensity: Vec3) -> Self {
        UnshadowedLights {
            emitters: vec![Emitter::Point(crate::scene::PointLight {
                position,
                direction: Vec3::NEG_Z,
                intensity,
                spot: None,
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
                    (Emitter::Point(l0), Emitter::Point(l1)) => {
                        nearly_equal(l0.position, l1.position)
                            && nearly_equal(l0.direction, l1.direction)
                            && nearly_equal(l0.intensity, l1.intensity)
                            && l0.spot == l1.spot
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
    /// that emits), `4π·I` a punctual one (spots taken as points).
    pub(crate) fn power(&self) -> Vec3 {
        use std::f32::consts::PI;
        let each = |l: &Emitter| match *l {
            Emitter::Area {
                power,
                double_sided,
                ..
            } => power * PI * if double_sided { 2.0 } else { 1.0 },
            Emitter::Point(light) => light.intensity * 4.0 * PI,
        };
        self.emitters.iter().map(each).sum()
    }

    /// Unshadowed direct irradiance at `p` (normal `n`).
    pub(crate) fn irradiance(&self, p: Vec3, n: Vec3) -> Vec3 {
        self.arriving(p, |w| n.dot(w).max(0.0))
    }

    /// The unshadowed light arriving at `p` from every direction (each
    /// light's irradiance on a surface facing it): where the normal at `p`
    /// is not known, any change of the lights shows in it.
    pub(crate) fn arriving_at(&self, p: Vec3) -> Vec3 {
        self.arriving(p, |_| 1.0)
    }

    /// Σ over the lights of what each sends to `p` from direction `w`
    /// (unit, towards the light), times `cos_at(w)`.
    fn arriving(&self, p: Vec3, cos_at: impl Fn(Vec3) -> f32) -> Vec3 {
        let mut e = Vec3::ZERO;
        for l in &self.emitters {
            match *l {
                Emitter::Area {
                    center,
                    normal,
                    power,
                    double_sided,
                } => {
                    let d = center - p;
                    let d2 = d.length_squared().max(1e-8);
                    let w = d / d2.sqrt();
                    let cos_l = -normal.dot(w);
                    let cos_l = if double_sided { cos_l.abs() } else { cos_l };
                    e += power * (cos_l.max(0.0) * cos_at(w) / d2);
                }
                Emitter::Point(light) => {
                    let d = light.position - p;
                    let d2 = d.length_squared().max(1e-8);
                    let w = d / d2.sqrt();
                    e += light.intensity_toward(-w) * (cos_at(w) / d2);
                }
            }
        }
        e
    }
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
            if let Emitter::Point(light) = &mut lights.emitters[0] {
                light.spot = Some(crate::scene::Spot {
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
