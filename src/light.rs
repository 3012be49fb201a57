//! Light sampling for next-event estimation: one light is picked with
//! probability proportional to its emitted power, then a point on it.
//! Area lights are the emissive triangles of the snapshot, sampled
//! uniformly in the solid angle they subtend (Arvo 1995) or, when that is
//! tiny or nearly a hemisphere, by area; point, spot and directional
//! lights are delta lights.

use crate::material::luminance;
use crate::sampling::{
    uniform_triangle, ArvoMap, LightChoice, SphericalTriangle, ONE_MINUS_EPSILON,
};
use crate::scene::{PlacedLight, Snapshot, Triangle};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Where the light of a sample comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    /// Emissive triangle: snapshot triangle id, and its area, unit normal,
    /// radiance and sidedness (looked up once per snapshot, not for every
    /// sample).
    Triangle {
        id: u32,
        area: f32,
        normal: Vec3,
        radiance: Vec3,
        double_sided: bool,
    },
    /// Punctual light (index into `Snapshot::lights`).
    Punctual(usize),
}

/// A light as [`LightSampler::source_of`] names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightSource {
    /// An emitting triangle (snapshot triangle id).
    Triangle(u32),
    /// A punctual light (index into `Snapshot::lights`, as into `Scene::lights`).
    Punctual(usize),
}

/// A point on a light as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Point on the light.
    pub position: Vec3,
    /// Unit direction from the shading point to the light.
    pub wi: Vec3,
    pub distance: f32,
    /// Radiance arriving along `wi` (area light) or intensity/d² (punctual),
    /// before visibility.
    pub radiance: Vec3,
    /// Solid-angle pdf of this sample (including the pick probability); for
    /// punctual lights the pick probability alone.
    pub pdf: f32,
    /// Punctual lights cannot be hit by BSDF sampling, so they get no MIS.
    pub is_delta: bool,
}

/// How [`LightSampler::sample`] draws the point on an emitting triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TriangleSampling {
    /// Uniform in the solid angle the triangle subtends where that is
    /// neither tiny nor nearly a hemisphere, by area otherwise: no noise
    /// from the `cosθ_l/d²` of points across the light, which area
    /// sampling has wherever the light is near or seen at a slant (the
    /// walls next to a ceiling light). For the first hits of pixel
    /// samples, whose direct light is seen: it costs about as much as a
    /// ray in a small scene, and at every vertex of every path it made
    /// `ic` 10–26 % slower on cube-in-box (64×64, four A/B pairs) for
    /// 0.4 % less lit-surface error than at the first hits alone.
    SolidAngle,
    /// Uniform by area: for the vertices of paths (a record's gather, the
    /// continuation of a pixel's path), whose light many paths average.
    Area,
}

/// Power-proportional sampler over all lights of one snapshot.
#[derive(Clone, Debug, Default)]
pub struct LightSampler {
    sources: Vec<Source>,
    /// A sphere (centre, radius) around every triangle, where the
    /// snapshot has a directional light: its power is what the sphere's
    /// disc intercepts, and its shadow rays end outside the sphere.
    reach: Option<(Vec3, f32)>,
    /// Cumulative pick probabilities, last entry 1.
    cdf: Vec<f32>,
    /// Pick probability of each emitting triangle, by snapshot id in
    /// increasing order, so that a BSDF ray hitting an emitter can compute
    /// the light pdf for MIS. Not one entry per triangle: a snapshot of a
    /// large scene took a zeroed vector of all its triangles, for each
    /// sampler (`trc` makes several a frame).
    triangle_pick: Vec<(u32, f32)>,
}

/// Emitted power of a one- or two-sided Lambertian emitter: `π·A·L`.
fn triangle_power(tri: &Triangle, radiance: Vec3, double_sided: bool) -> f32 {
    let sides = if double_sided { 2.0 } else { 1.0 };
    PI * tri.area() * luminance(radiance) * sides
}

impl LightSampler {
    pub fn new(snapshot: &Snapshot, materials: &[crate::scene::Material]) -> Self {
        let mut sources = Vec::new();
        let mut power = Vec::new();
        // A large scene's triangles are read only where they emit.
        for id in snapshot.emitting_triangles(materials) {
            let m = &materials[snapshot.tri_material[id as usize] as usize];
            let tri = &snapshot.triangles[id as usize];
            if tri.area() > 0.0 {
                sources.push(Source::Triangle {
                    id,
                    area: tri.area(),
                    normal: tri.geometric_normal(),
                    radiance: m.emission,
                    double_sided: m.double_sided,
                });
                power.push(triangle_power(tri, m.emission, m.double_sided));
            }
        }
        let reach = (snapshot.lights.iter().any(PlacedLight::is_directional))
            .then(|| snapshot.bounds())
            .flatten()
            .map(|(lo, hi)| ((lo + hi) * 0.5, (hi - lo).length() * 0.5));
        for (i, light) in snapshot.lights.iter().enumerate() {
            // 4π·I for a point light; spots are weighted the same way, which
            // only changes variance, not the expectation. A directional
            // light's power is what falls on the disc of the scene's
            // bounding sphere, π·r²·E (as PBRT weighs it).
            let p = match reach {
                Some((_, r)) if light.is_directional() => PI * r * r * luminance(light.intensity),
                _ if light.is_directional() => 0.0,
                _ => 4.0 * PI * luminance(light.intensity),
            };
            if p > 0.0 {
                sources.push(Source::Punctual(i));
                power.push(p);
            }
        }
        let total: f32 = power.iter().sum();
        let mut cdf = Vec::with_capacity(power.len());
        let mut acc = 0.0;
        for p in &power {
            acc += p / total;
            cdf.push(acc);
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        let triangle_pick = (sources.iter().zip(&power))
            .filter_map(|(source, p)| match source {
                Source::Triangle { id, .. } => Some((*id, p / total)),
                Source::Punctual(_) => None,
            })
            .collect();
        LightSampler {
            sources,
            reach,
            cdf,
            triangle_pick,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    /// This sampler, made of a whole snapshot, for that snapshot's
    /// [`crate::scene::Scene::emitters_snapshot`], whose triangles are
    /// `emitting` (the whole snapshot's
    /// [`Snapshot::emitting_triangles`]) in order: the same samples, bit
    /// for bit, read from the emitters alone, so that a frame's lights are
    /// held without its other triangles (`trc`'s frames ahead). Made of
    /// the whole snapshot for its bounds, which weigh a directional light.
    pub fn for_emitters(mut self, emitting: &[u32]) -> Self {
        let renumber = |id: &mut u32| *id = emitting.partition_point(|&e| e < *id) as u32;
        for source in &mut self.sources {
            if let Source::Triangle { id, .. } = source {
                renumber(id);
            }
        }
        for (id, _) in &mut self.triangle_pick {
            renumber(id);
        }
        self
    }

    /// The snapshot ids of the emitting triangles.
    pub fn emitting_triangles(&self) -> impl Iterator<Item = usize> + '_ {
        self.sources.iter().filter_map(|s| match s {
            Source::Triangle { id, .. } => Some(*id as usize),
            Source::Punctual(_) => None,
        })
    }

    fn pick_probability(&self, k: usize) -> f32 {
        self.cdf[k] - if k == 0 { 0.0 } else { self.cdf[k - 1] }
    }

    /// One 2D sample split into a light choice: `u.x` picks the source by
    /// where it falls in the pick distribution, and is then rescaled to
    /// `[0, 1)` within that source's interval to place the point with
    /// `u.y` (PBRT's `SampleDiscrete` remapping). Why: the stratification
    /// of `u` over a pixel's samples then carries over to each light. A
    /// quad light's two triangles each get half of the strata, as a grid;
    /// drawn apart, the pick and the point paired each triangle with a
    /// random half of the position strata, and the samples on one
    /// triangle were hardly stratified at all.
    pub fn choose(&self, u: Vec2) -> LightChoice {
        let Some(k) = self.source_at(u.x) else {
            return LightChoice { pick: u.x, u };
        };
        let below = if k == 0 { 0.0 } else { self.cdf[k - 1] };
        let width = self.pick_probability(k);
        let x = if width > 0.0 {
            ((u.x - below) / width).clamp(0.0, ONE_MINUS_EPSILON)
        } else {
            0.0
        };
        LightChoice {
            pick: u.x,
            u: Vec2::new(x, u.y),
        }
    }

    /// The light that pick value `pick` (a [`LightChoice::pick`]) selects,
    /// for callers that must know whether it moves (`movies` keeps the
    /// shadows of lights that do not).
    pub fn source_of(&self, pick: f32) -> Option<LightSource> {
        self.source_at(pick).map(|k| match self.sources[k] {
            Source::Triangle { id, .. } => LightSource::Triangle(id),
            Source::Punctual(i) => LightSource::Punctual(i),
        })
    }

    /// A fingerprint of the pick distribution: equal for two samplers
    /// whose picks map every `u` to the same source (a light whose power
    /// changed changes it).
    pub fn pick_fingerprint(&self) -> u64 {
        self.cdf.iter().fold(self.cdf.len() as u64, |h, c| {
            crate::sampling::mix64(h ^ u64::from(c.to_bits()))
        })
    }

    /// The source that pick value `pick` ∈ [0, 1) selects.
    fn source_at(&self, pick: f32) -> Option<usize> {
        (!self.cdf.is_empty()).then(|| {
            self.cdf
                .partition_point(|&c| c <= pick)
                .min(self.cdf.len() - 1)
        })
    }

    /// Samples a light point for shading point `p`. `None` when there are no
    /// lights or the sampled point cannot send light towards `p` (back side
    /// of a one-sided emitter, outside a spot cone, degenerate geometry).
    /// For many samples at one point, [`LightSampler::at_point`].
    pub fn sample(
        &self,
        snapshot: &Snapshot,
        p: Vec3,
        choice: LightChoice,
        sampling: TriangleSampling,
    ) -> Option<LightSample> {
        let k = self.source_at(choice.pick)?;
        let strategy = self.strategy(snapshot, k, p, sampling);
        self.sample_source(snapshot, k, strategy.as_ref(), p, choice.u)
    }

    /// Light samples at shading point `p`, with what each emitting
    /// triangle's sampling needs of `p` alone worked out once
    /// ([`PointLights`]).
    pub fn at_point<'a>(
        &'a self,
        snapshot: &'a Snapshot,
        p: Vec3,
        sampling: TriangleSampling,
    ) -> PointLights<'a> {
        PointLights {
            lights: self,
            snapshot,
            p,
            sampling,
            strategies: Vec::new(),
        }
    }

    /// How source `k` is sampled from `p`: `None` for a point light, and
    /// for an emitting triangle wholly behind `p`'s side of it (a back
    /// face).
    fn strategy(
        &self,
        snapshot: &Snapshot,
        k: usize,
        p: Vec3,
        sampling: TriangleSampling,
    ) -> Option<TriangleStrategy> {
        let Source::Triangle {
            id,
            normal,
            double_sided,
            ..
        } = self.sources[k]
        else {
            return None;
        };
        let tri = &snapshot.triangles[id as usize];
        // The whole triangle is on one side of p: skip a back face.
        emitting_side_cosine(normal, double_sided, p - tri.p[0])?;
        Some(TriangleStrategy::from(tri, p, sampling))
    }

    /// A point on source `k` for `p` from `u`, the triangle's `strategy`
    /// from [`LightSampler::strategy`].
    fn sample_source(
        &self,
        snapshot: &Snapshot,
        k: usize,
        strategy: Option<&TriangleStrategy>,
        p: Vec3,
        u: Vec2,
    ) -> Option<LightSample> {
        let pick_pdf = self.pick_probability(k);
        match self.sources[k] {
            Source::Triangle {
                id,
                area,
                normal,
                radiance,
                double_sided,
            } => {
                let strategy = strategy?;
                let tri = &snapshot.triangles[id as usize];
                let (position, wi, distance, d2) = strategy.point(tri, normal, p, u)?;
                let cos_light = emitting_side_cosine(normal, double_sided, -wi)?;
                Some(LightSample {
                    position,
                    wi,
                    distance,
                    radiance,
                    pdf: pick_pdf * strategy.pdf(area, d2, cos_light),
                    is_delta: false,
                })
            }
            Source::Punctual(i) => match self.reach {
                Some(reach) if snapshot.lights[i].is_directional() => {
                    directional_light_sample(&snapshot.lights[i], p, pick_pdf, reach)
                }
                _ => point_light_sample(&snapshot.lights[i], p, pick_pdf),
            },
        }
    }

    /// Solid-angle pdf with which [`LightSampler::sample`] would have chosen
    /// the point `hit` on emissive triangle `triangle` from `origin` (for MIS
    /// when a BSDF-sampled ray hits an emitter).
    pub fn pdf_triangle(
        &self,
        tri: &Triangle,
        triangle: u32,
        origin: Vec3,
        hit: Vec3,
        sampling: TriangleSampling,
    ) -> f32 {
        let pick = (self.triangle_pick)
            .binary_search_by_key(&triangle, |&(id, _)| id)
            .map_or(0.0, |k| self.triangle_pick[k].1);
        if pick <= 0.0 {
            return 0.0;
        }
        let d = hit - origin;
        let d2 = d.length_squared();
        let cos_light = tri.geometric_normal().dot(d / d2.sqrt()).abs();
        if cos_light <= 0.0 {
            return 0.0;
        }
        pick * TriangleStrategy::from(tri, origin, sampling).pdf(tri.area(), d2, cos_light)
    }
}

/// The lights as seen from one shading point, for many light samples there
/// (a texel's shadow samples): which side of each emitting triangle faces
/// the point, and the triangle's spherical triangle and Arvo's map, are
/// worked out for the first sample that picks it and kept for the others,
/// rather than once per sample. Its samples are [`LightSampler::sample`]'s,
/// bit for bit.
pub struct PointLights<'a> {
    lights: &'a LightSampler,
    snapshot: &'a Snapshot,
    p: Vec3,
    sampling: TriangleSampling,
    /// The sources picked so far and how each is sampled from `p`
    /// ([`LightSampler::strategy`]); a point's samples pick few.
    strategies: Vec<(usize, Option<TriangleStrategy>)>,
}

impl PointLights<'_> {
    /// [`LightSampler::sample`] at this point.
    pub fn sample(&mut self, choice: LightChoice) -> Option<LightSample> {
        let lights = self.lights;
        let k = lights.source_at(choice.pick)?;
        let at = match self.strategies.iter().position(|(j, _)| *j == k) {
            Some(at) => at,
            None => {
                let strategy = lights.strategy(self.snapshot, k, self.p, self.sampling);
                self.strategies.push((k, strategy));
                self.strategies.len() - 1
            }
        };
        let strategy = self.strategies[at].1.as_ref();
        lights.sample_source(self.snapshot, k, strategy, self.p, choice.u)
    }
}

/// The sample of point or spot light `light` for shading point `p`, picked
/// with probability `pick_pdf`; `None` where it sends no light towards `p`.
fn point_light_sample(light: &PlacedLight, p: Vec3, pick_pdf: f32) -> Option<LightSample> {
    let to_light = light.position - p;
    let d2 = to_light.length_squared();
    if d2 <= 0.0 {
        return None;
    }
    let distance = d2.sqrt();
    let wi = to_light / distance;
    let radiance = light.intensity_toward(-wi) / d2;
    if radiance.max_element() <= 0.0 {
        return None;
    }
    Some(LightSample {
        position: light.position,
        wi,
        distance,
        radiance,
        pdf: pick_pdf,
        is_delta: true,
    })
}

/// The sample of directional light `light` for shading point `p`, picked
/// with probability `pick_pdf`: its irradiance from against its direction,
/// through a point past the sphere `reach` (centre, radius) around the
/// scene, where its shadow ray ends. `None` where it has no direction.
fn directional_light_sample(
    light: &PlacedLight,
    p: Vec3,
    pick_pdf: f32,
    (centre, radius): (Vec3, f32),
) -> Option<LightSample> {
    let wi = -light.direction;
    // Every triangle lies within `radius` of `centre`, so within
    // `|p − centre| + radius` of `p`; twice that is past them all.
    let distance = 2.0 * ((p - centre).length() + radius);
    if wi == Vec3::ZERO || !(distance > 0.0 && distance.is_finite()) {
        return None;
    }
    if light.intensity.max_element() <= 0.0 {
        return None;
    }
    Some(LightSample {
        position: p + wi * distance,
        wi,
        distance,
        radiance: light.intensity,
        pdf: pick_pdf,
        is_delta: true,
    })
}

/// Solid angles (sr) between which an emitting triangle is sampled by solid
/// angle: below, the triangle is small or seen edge-on, the directions to
/// its corners are nearly coplanar and the map loses its digits in f32, and
/// area sampling is as good; above, the triangle fills nearly a hemisphere
/// and the map degenerates. The upper bound is PBRT-v4's; PBRT-v4's lower
/// bound, 3·10⁻⁴, is ten times lower: between the two, on 200,000 random
/// triangles and points, the map sent 22 directions more than 10⁻³ (in
/// barycentric units) off their triangle, the largest 1.3 (its earlier
/// form, with normalised plane normals, 27, up to 1.6);
/// above 3·10⁻³, none (`spherical_triangle_stays_finite_on_random_triangles`
/// checks it).
pub(crate) const SOLID_ANGLE_SAMPLING: std::ops::RangeInclusive<f32> = 3e-3..=6.22;

/// How a point on an emitting triangle is drawn for a shading point: the
/// choice depends only on the two and the caller's [`TriangleSampling`],
/// so [`LightSampler::pdf_triangle`] finds the one
/// [`LightSampler::sample`] made.
#[derive(Clone, Copy, Debug, PartialEq)]
enum TriangleStrategy {
    /// Uniform in the solid angle `Ω` the triangle subtends, by Arvo's map
    /// ([`SphericalTriangle::arvo`]; `None` where the triangle is
    /// degenerate from the point).
    SolidAngle {
        solid_angle: f32,
        map: Option<ArvoMap>,
    },
    /// Uniform by area ([`uniform_triangle`]).
    Area,
}

impl TriangleStrategy {
    fn from(tri: &Triangle, p: Vec3, sampling: TriangleSampling) -> Self {
        if sampling == TriangleSampling::Area {
            return TriangleStrategy::Area;
        }
        let sphere = SphericalTriangle::new(&tri.p, p);
        if SOLID_ANGLE_SAMPLING.contains(&sphere.solid_angle) {
            TriangleStrategy::SolidAngle {
                solid_angle: sphere.solid_angle,
                map: sphere.arvo(),
            }
        } else {
            TriangleStrategy::Area
        }
    }

    /// A point on `tri` (unit normal `normal`) for shading point `p`, from
    /// `u`: the point, the unit direction and distance to it from `p`, and
    /// the distance²; `None` where it cannot be drawn.
    fn point(
        &self,
        tri: &Triangle,
        normal: Vec3,
        p: Vec3,
        u: Vec2,
    ) -> Option<(Vec3, Vec3, f32, f32)> {
        match self {
            TriangleStrategy::SolidAngle { map, .. } => {
                // The direction is drawn: the point is where it meets the
                // triangle's plane.
                let wi = map.as_ref()?.sample(u)?;
                let distance = normal.dot(tri.p[0] - p) / normal.dot(wi);
                if !(distance > 0.0 && distance.is_finite()) {
                    return None;
                }
                Some((p + distance * wi, wi, distance, distance * distance))
            }
            TriangleStrategy::Area => {
                let (bu, bv) = uniform_triangle(u);
                let position = tri.point(bu, bv);
                let to_light = position - p;
                let d2 = to_light.length_squared();
                if d2 <= 0.0 {
                    return None;
                }
                let distance = d2.sqrt();
                Some((position, to_light / distance, distance, d2))
            }
        }
    }

    /// The solid-angle density of a point at distance² `d2` and emitter
    /// cosine `cos_light` on a triangle of area `area`.
    fn pdf(&self, area: f32, d2: f32, cos_light: f32) -> f32 {
        match self {
            TriangleStrategy::SolidAngle { solid_angle, .. } => 1.0 / solid_angle,
            // Area pdf 1/A converted to solid angle: d²/(A·cosθ_l).
            TriangleStrategy::Area => d2 / (area * cos_light),
        }
    }
}

/// Cosine between the emitter's normal and the emitted direction `w` (unit,
/// leaving the light), or `None` if that side does not emit. Front faces are
/// counter-clockwise (glTF); `double_sided` emitters emit from both sides.
pub fn emitting_cosine(tri: &Triangle, double_sided: bool, w: Vec3) -> Option<f32> {
    emitting_side_cosine(tri.geometric_normal(), double_sided, w)
}

/// [`emitting_cosine`] for an emitter of unit geometric normal `normal`.
fn emitting_side_cosine(normal: Vec3, double_sided: bool, w: Vec3) -> Option<f32> {
    let cos = normal.dot(w);
    if cos > 0.0 {
        Some(cos)
    } else if double_sided && cos < 0.0 {
        Some(-cos)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::tests::lambert;
    use crate::scene::Scene;

    /// A sun added to `cube-in-box`: picked by the power its light sends
    /// through the disc of the sphere around the scene, against the
    /// panel's `π·A·L`, and sampled from against its direction, with its
    /// irradiance, through a point past every triangle.
    #[test]
    fn a_sun_is_picked_by_the_light_it_sends_the_scene_and_sampled_past_it() {
        let scene = Scene::builtin("cube-in-box").unwrap();
        let mut snapshot = scene.snapshot(0.0);
        let panel = LightSampler::new(&snapshot, &scene.materials);
        let down = Vec3::new(0.2, -1.0, 0.1).normalize();
        let e = Vec3::new(3.0, 2.0, 1.0);
        snapshot.lights.push(PlacedLight {
            position: Vec3::splat(1e3),
            direction: down,
            intensity: e,
            kind: crate::scene::LightKind::Directional,
        });
        let lights = LightSampler::new(&snapshot, &scene.materials);
        let (lo, hi) = snapshot.bounds().unwrap();
        let r = (hi - lo).length() / 2.0;
        let sun_power = PI * r * r * luminance(e);
        let panel_power: f32 = (0..panel.sources.len())
            .map(|k| match panel.sources[k] {
                Source::Triangle { area, radiance, .. } => PI * area * luminance(radiance),
                Source::Punctual(_) => unreachable!("cube-in-box has no punctual light"),
            })
            .sum();
        let sun = lights.sources.len() - 1;
        let expected = sun_power / (sun_power + panel_power);
        assert!((lights.pick_probability(sun) - expected).abs() < 1e-5);
        let choice = LightChoice {
            pick: 1.0 - 1e-6,
            u: Vec2::splat(0.5),
        };
        for p in [(lo + hi) / 2.0, lo, hi, Vec3::new(lo.x, hi.y, lo.z)] {
            let s = lights
                .sample(&snapshot, p, choice, TriangleSampling::Area)
                .unwrap();
            assert!(s.is_delta && s.wi == -down && s.radiance == e, "{s:?}");
            assert!((s.pdf - expected).abs() < 1e-5);
            assert!((s.position - p - s.wi * s.distance).length() < 1e-4 * s.distance);
            let outside = s.position.cmplt(lo).any() || s.position.cmpgt(hi).any();
            assert!(
                outside,
                "{p}: the shadow ray ends at {} in the scene",
                s.position
            );
        }
    }

    /// `choose` sends each source the share of the unit square its pick
    /// probability says, and spreads the rescaled coordinate of the points
    /// it sends a source evenly over [0, 1): a stratified set of `u` stays
    /// stratified on every light.
    #[test]
    fn a_choice_keeps_the_stratification_of_its_sample_on_each_light() {
        let scene = Scene::builtin("chairs-room").unwrap();
        let snapshot = scene.snapshot(0.0);
        let lights = LightSampler::new(&snapshot, &scene.materials);
        assert!(lights.sources.len() >= 2, "needs several lights");
        let n = 256;
        let mut xs: Vec<Vec<f32>> = vec![Vec::new(); lights.sources.len()];
        for i in 0..n {
            // One u per column of the square: x = (i + ½)/n.
            let u = Vec2::new((i as f32 + 0.5) / n as f32, 0.3);
            let choice = lights.choose(u);
            assert_eq!(choice.u.y, u.y);
            assert!((0.0..1.0).contains(&choice.u.x), "{choice:?}");
            let k = lights.source_at(choice.pick).unwrap();
            xs[k].push(choice.u.x);
        }
        for (k, x) in xs.iter_mut().enumerate() {
            let p = lights.pick_probability(k);
            let expected = p * n as f32;
            assert!(
                (x.len() as f32 - expected).abs() <= 1.0,
                "source {k}: {} of {n}, expected {expected}",
                x.len()
            );
            // Evenly spread: consecutive values 1/len apart, up to rounding.
            x.sort_by(f32::total_cmp);
            for pair in x.windows(2) {
                let gap = pair[1] - pair[0];
                let step = 1.0 / (p * n as f32);
                assert!(
                    (gap - step).abs() < 1e-3,
                    "source {k}: gap {gap}, step {step}"
                );
            }
        }
    }

    /// A light sample's bits.
    type SampleBits = ([[u32; 3]; 3], u32, u32, bool);

    fn bits(s: Option<LightSample>) -> Option<SampleBits> {
        s.map(|s| {
            let v = [s.position, s.wi, s.radiance].map(|v| v.to_array().map(f32::to_bits));
            (v, s.distance.to_bits(), s.pdf.to_bits(), s.is_delta)
        })
    }

    /// A sampler made of a whole snapshot and renumbered for its emitters
    /// alone ([`LightSampler::for_emitters`]) draws, from the emitters'
    /// snapshot, the samples it draws from the whole one, bit for bit: on
    /// chairs-room (a panel after other triangles, and a bulb) with a sun
    /// added, whose power the whole scene's bounds weigh (a sampler made of
    /// the emitters alone picks it otherwise).
    #[test]
    fn a_sampler_for_the_emitters_alone_samples_as_over_the_whole_snapshot() {
        let scene = Scene::builtin("chairs-room").unwrap();
        let sun = PlacedLight {
            position: Vec3::ZERO,
            direction: Vec3::new(0.3, -1.0, 0.2).normalize(),
            intensity: Vec3::splat(2.0),
            kind: crate::scene::LightKind::Directional,
        };
        let (mut whole, mut emitters) = (scene.snapshot(0.0), scene.emitters_snapshot(0.0));
        whole.lights.push(sun);
        emitters.lights.push(sun);
        let emitting = whole.emitting_triangles(&scene.materials);
        assert!(emitting[0] > 0, "the emitters' ids are the whole's");
        let lights = LightSampler::new(&whole, &scene.materials);
        let renumbered = lights.clone().for_emitters(&emitting);
        let of_emitters = LightSampler::new(&emitters, &scene.materials);
        let sun_k = lights.sources.len() - 1;
        assert_ne!(
            lights.pick_probability(sun_k),
            of_emitters.pick_probability(sun_k)
        );
        let (lo, hi) = whole.bounds().unwrap();
        let mut rng = crate::sampling::Rng::from_seed(5, 0);
        let mut drawn = 0;
        for _ in 0..400 {
            let p = lo + (hi - lo) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let choice = lights.choose(rng.next_2d());
            for sampling in [TriangleSampling::SolidAngle, TriangleSampling::Area] {
                let one = lights.sample(&whole, p, choice, sampling);
                let other = renumbered.sample(&emitters, p, choice, sampling);
                assert_eq!(bits(one), bits(other), "at {p} with {choice:?}");
                drawn += one.is_some_and(|s| !s.is_delta) as u32;
            }
        }
        assert!(drawn > 200, "{drawn} drawn from the lights' triangles");
    }

    /// Many samples at one point through [`PointLights`] are those of
    /// [`LightSampler::sample`], bit for bit: on chairs-room (a panel of
    /// two triangles and a bulb), at points across the room and just
    /// behind the panel (whose back faces give no sample), under both
    /// strategies.
    #[test]
    fn point_lights_sample_as_the_light_sampler_does() {
        let scene = Scene::builtin("chairs-room").unwrap();
        let snapshot = scene.snapshot(0.0);
        let lights = LightSampler::new(&snapshot, &scene.materials);
        let (lo, hi) = snapshot.bounds().unwrap();
        let mut rng = crate::sampling::Rng::from_seed(11, 0);
        let mut points: Vec<Vec3> = (0..40)
            .map(|_| lo + (hi - lo) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()))
            .collect();
        for id in lights.emitting_triangles() {
            let tri = &snapshot.triangles[id];
            let centre = tri.centroid();
            points.push(centre - 0.01 * tri.geometric_normal());
        }
        let (mut drawn, mut refused) = (0, 0);
        for sampling in [TriangleSampling::SolidAngle, TriangleSampling::Area] {
            for &p in &points {
                let mut at_point = lights.at_point(&snapshot, p, sampling);
                for _ in 0..32 {
                    let choice = lights.choose(rng.next_2d());
                    let one = lights.sample(&snapshot, p, choice, sampling);
                    let many = at_point.sample(choice);
                    assert_eq!(bits(one), bits(many), "at {p} with {choice:?}");
                    if one.is_some() {
                        drawn += 1;
                    } else {
                        refused += 1;
                    }
                }
            }
        }
        assert!(
            drawn > 1000 && refused > 0,
            "{drawn} drawn, {refused} refused"
        );
    }

    /// cube-in-box's ceiling light seen from the back wall just under it,
    /// where the light is near and slanted: the irradiance from 16
    /// stratified light samples (no occluder in between) under both
    /// strategies, over 400 random shifts of the pattern. Both must have
    /// Lambert's closed form as their mean, solid-angle points far less
    /// noise, and `pdf_triangle` must give the density each sample was
    /// drawn with (MIS depends on it).
    #[test]
    fn solid_angle_points_light_a_wall_by_the_closed_form_with_less_noise() {
        let scene = Scene::builtin("cube-in-box").unwrap();
        let snapshot = scene.snapshot(0.0);
        let lights = LightSampler::new(&snapshot, &scene.materials);
        let (p, n) = (Vec3::new(0.1, 1.7, -1.0), Vec3::Z);
        let mut exact = 0.0;
        for id in lights.emitting_triangles() {
            let radiance = luminance(scene.materials[snapshot.tri_material[id] as usize].emission);
            exact += radiance * lambert(&snapshot.triangles[id].p, p, n);
        }
        let mut rng = crate::sampling::Rng::from_seed(7, 0);
        let mut moments = Vec::new();
        for sampling in [TriangleSampling::SolidAngle, TriangleSampling::Area] {
            let (mut sum, mut sum_sq, trials) = (0.0f64, 0.0f64, 400);
            for _ in 0..trials {
                let shift = rng.next_2d();
                let mut e = 0.0;
                for i in 0..16u32 {
                    let cell = Vec2::new((i % 4) as f32, (i / 4) as f32);
                    let u = ((cell + shift) / 4.0).fract();
                    let choice = lights.choose(u);
                    let Some(ls) = lights.sample(&snapshot, p, choice, sampling) else {
                        continue;
                    };
                    let id = lights.source_at(choice.pick).unwrap();
                    let Source::Triangle { id, .. } = lights.sources[id] else {
                        unreachable!("cube-in-box has area lights only")
                    };
                    let tri = &snapshot.triangles[id as usize];
                    let pdf = lights.pdf_triangle(tri, id, p, ls.position, sampling);
                    assert!((pdf / ls.pdf - 1.0).abs() < 1e-3, "{pdf} vs {}", ls.pdf);
                    e += luminance(ls.radiance) * n.dot(ls.wi).max(0.0) / ls.pdf / 16.0;
                }
                sum += e as f64;
                sum_sq += (e * e) as f64;
            }
            let mean = sum / trials as f64;
            let variance = sum_sq / trials as f64 - mean * mean;
            let tolerance = 4.0 * (variance / trials as f64).sqrt() + 1e-3 * exact as f64;
            assert!(
                (mean - exact as f64).abs() < tolerance,
                "{sampling:?}: mean {mean} against {exact}"
            );
            moments.push(variance);
        }
        assert!(
            moments[0] < 0.25 * moments[1],
            "solid-angle variance {} against area {}",
            moments[0],
            moments[1]
        );
    }
}
