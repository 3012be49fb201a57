//! Equivalent area light sources: the radiance records of glossy surfaces
//! (Omidvar, Ribardière, Carré, Méneveux & Bouatouch, "A radiance cache
//! method for highly glossy surfaces", `papers/equivalent-area-light-
//! sources-glossy-radiance-cache.md`).
//!
//! A record's hemisphere samples are clustered in a tree of spherical caps
//! and sectors over the projected hemisphere (§3.2, Fig. 5); each node is a
//! potential EAS with the irradiance, solid angle and centroid of its
//! samples (Eq. 11–12). A cut through the tree, refined where the reflected
//! radiance of the current cut differs most from that of the nodes two
//! levels below (Eq. 13–14, Fig. 6), is what the record keeps. A point near
//! the record sees each EAS moved (Eq. 16), and reflects the EAS of the
//! records around it through the mean BRDF (Eq. 15, 17;
//! [`Bsdf::mean_specular`]).
//!
//! Departures, each for a reason given where it is made:
//! - the tree is laid over the gather's `M × N` cells (rings of equal
//!   projected area, sectors of equal angle), whose solid angles are exact,
//!   instead of over free samples with `Ω = 2π/#s`;
//! - Eq. 16 without the EAS normal's `cosα'/cosα` (the samples, and the
//!   store, keep no surface normal at the hits);
//! - the cut is capped at [`MAX_EAS`] sources;
//! - the mean BRDF is the closed form of [`Bsdf::mean_specular`], not a
//!   fitted table.
//!
//! EAS serve the glossy lobe only; the diffuse part of the same records is
//! their irradiance with gradients, as in `ic`. `trc` carries them across
//! frames; [`irradiance_over`] gives its estimate of each source at the
//! next frame (TRC Eq. 21).

use super::gather::{HemisphereSamples, Strata};
use super::{IrradianceCache, LookupPoint, WEIGHT_CAP};
use crate::material::{luminance, Bsdf};
use crate::sampling::Frame;
use glam::Vec3;
use std::f32::consts::{PI, TAU};
use std::ops::Range;

/// The paper's precision criterion `τ` (§3.2: "all the images in this
/// paper have been produced with τ = 0.02").
pub const DEFAULT_TAU: f32 = 0.02;

/// Most EAS a record keeps. The paper's records keep 50 to 500 (its
/// Table 1) from 4,096 samples each; ours gather 768, whose noise keeps the
/// cut from meeting `τ` on most glossy records (251 of 333 reached a cap
/// of 256 at frame 0 of `spheres`, 64×64), so the cap is what stops it. A
/// cap of 256 gave the same error (within 0.7 %) as 64 in 3 % more time on
/// `spheres` and 35 % more on `glossy-cornell` (`radcache bench --scenes
/// spheres,glossy-cornell --size 64x64 --frames 0..4 --methods
/// ic:glossy=eas`, once with each).
pub const MAX_EAS: usize = 64;

/// Distance given to the samples that hit nothing: far enough that moving
/// over a record's influence does not change their direction.
const MISS_DISTANCE: f32 = 1e6;

/// Reflection directions over which a cut's reflected radiance is compared
/// (the paper's `#D`): `D_THETA × D_PHI`, cosine-distributed.
const D_THETA: usize = 4;
const D_PHI: usize = 8;
const D: usize = D_THETA * D_PHI;

/// One equivalent area light source of a record (§3.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eas {
    /// From the record to the centroid of the source's sample hits (its
    /// `Pos`, Eq. 12, weighted by irradiance).
    pub offset: Vec3,
    /// `Ω`: the sum of its samples' solid angles.
    pub solid_angle: f32,
    /// `E`: the irradiance it brings the record.
    pub irradiance: Vec3,
    /// Its node in the record's tree: which of the record's cells it holds
    /// ([`irradiance_over`] sums the same cells of other samples).
    pub node: u32,
}

impl Eas {
    /// Eq. 16 at `p` with unit normal `n`, for the source of a record at
    /// `record` with normal `record_normal`: the direction to the source,
    /// its irradiance `E' = E·d²cosθ'/(d'²cosθ)` and its solid angle
    /// `Ω' = Ω·d²/d'²`. `None` where it lies below `p`'s horizon.
    fn seen_from(&self, record: Vec3, record_normal: Vec3, p: Vec3, n: Vec3) -> Option<Seen> {
        let centre = record + self.offset;
        let to = centre - p;
        let (d2, d2_moved) = (self.offset.length_squared(), to.length_squared());
        if d2_moved <= 0.0 || d2 <= 0.0 {
            return None;
        }
        let direction = to / d2_moved.sqrt();
        let cos_moved = n.dot(direction);
        let cos = record_normal.dot(self.offset) / d2.sqrt();
        if cos_moved <= 0.0 || cos <= 0.0 {
            return None;
        }
        let scale = d2 / d2_moved;
        Some(Seen {
            direction,
            irradiance: self.irradiance * (scale * cos_moved / cos),
            solid_angle: (self.solid_angle * scale).min(TAU),
        })
    }
}

/// An EAS as a point away from its record sees it (Eq. 16).
struct Seen {
    direction: Vec3,
    irradiance: Vec3,
    solid_angle: f32,
}

/// Eq. 17: the glossy radiance reflected towards `wo` at `at` by `bsdf`,
/// from the EAS of the records usable there, weighted as their irradiance
/// is (Ward's weights). `None` where no usable record has EAS.
pub fn reflected_radiance(
    cache: &IrradianceCache,
    at: &LookupPoint,
    bsdf: &Bsdf,
    wo: Vec3,
) -> Option<Vec3> {
    let (mut sum, mut weights) = (Vec3::ZERO, 0.0f32);
    cache.for_each_usable(at, |record, w| {
        let Some(sources) = &record.eas else {
            return;
        };
        let w = w.min(WEIGHT_CAP);
        let mut radiance = Vec3::ZERO;
        for eas in sources.iter() {
            if let Some(seen) =
                eas.seen_from(record.position, record.normal, at.position, at.normal)
            {
                radiance +=
                    seen.irradiance * bsdf.mean_specular(wo, seen.direction, seen.solid_angle);
            }
        }
        sum += radiance * w;
        weights += w;
    });
    (weights > 0.0).then(|| sum / weights)
}

/// The EAS of a record gathered at `normal` from `samples` (cell `(j, k)`
/// at `j·N + k`, as [`super::gather`] lays them out), for a surface whose
/// BSDF is `bsdf`: the cut through the cap-and-sector tree that meets the
/// precision `tau` (Eq. 13), or [`MAX_EAS`] sources. Sources that bring no
/// light are left out. Empty where the BSDF has no glossy lobe.
pub fn build(
    samples: &HemisphereSamples,
    normal: Vec3,
    strata: Strata,
    bsdf: &Bsdf,
    tau: f32,
) -> Vec<Eas> {
    if !bsdf.has_specular() || samples.radiance.len() != strata.count() || strata.count() == 0 {
        return Vec::new();
    }
    let tree = Tree::new(samples, strata);
    let cut = Cut::refine(&tree, bsdf, &reflection_directions(normal), tau);
    cut.into_iter()
        .map(|node| tree.eas(node))
        .filter(|e| luminance(e.irradiance) > 0.0)
        .collect()
}

/// The irradiance each of `sources` (built by [`build`] over one set of a
/// record's samples) brings over `samples`, other values of the same cells:
/// the record's incoming light at another time. `trc` compares a radiance
/// record's sources at `t0` and its estimate of `t0 + 1` this way, as TRC
/// Eq. 21 compares a radiance record's coefficients. `None` where the
/// samples are not laid out as `strata`.
pub fn irradiance_over(
    sources: &[Eas],
    samples: &HemisphereSamples,
    strata: Strata,
) -> Option<Vec<Vec3>> {
    if samples.radiance.len() != strata.count() || strata.count() == 0 {
        return None;
    }
    let tree = Tree::new(samples, strata);
    sources
        .iter()
        .map(|s| tree.nodes.get(s.node as usize).map(|n| n.irradiance))
        .collect()
}

/// The outgoing directions `#D` over which cuts are compared, in the
/// record's frame (+Z its normal).
fn reflection_directions(normal: Vec3) -> [Vec3; D] {
    let frame = Frame::new(normal);
    std::array::from_fn(|i| {
        let (j, k) = (i / D_PHI, i % D_PHI);
        let sin2 = (j as f32 + 0.5) / D_THETA as f32;
        let phi = TAU * (k as f32 + 0.5) / D_PHI as f32;
        let (s, c) = (sin2.sqrt(), (1.0 - sin2).sqrt());
        frame.to_world(Vec3::new(s * phi.cos(), s * phi.sin(), c))
    })
}

/// A part of the projected hemisphere (Fig. 5): the central cap of the
/// first `rings` rings, or a sector of rings and φ cells.
#[derive(Clone, Debug)]
enum Region {
    Cap { rings: u32 },
    Sector { rings: Range<u32>, phis: Range<u32> },
}

/// A node of the tree: a potential EAS (Eq. 12).
struct Node {
    irradiance: Vec3,
    solid_angle: f32,
    /// `Σ offset·lum(E)` and `Σ lum(E)` of its samples: the centroid.
    weighted_offset: Vec3,
    weight: f32,
    /// `Σ offset·Ω`: the centroid of a node that brings no light.
    plain_offset: Vec3,
    children: Vec<u32>,
}

/// The cap-and-sector tree of one record's samples, nodes in an arena.
struct Tree {
    nodes: Vec<Node>,
}

impl Tree {
    fn new(samples: &HemisphereSamples, strata: Strata) -> Self {
        let mut tree = Tree { nodes: Vec::new() };
        tree.build(
            Region::Cap {
                rings: strata.theta,
            },
            samples,
            strata,
        );
        tree
    }

    /// Builds the node of `region` after its children; returns its index.
    fn build(&mut self, region: Region, samples: &HemisphereSamples, strata: Strata) -> u32 {
        let parts = split(&region, strata);
        if parts.is_empty() {
            let Region::Sector { rings, phis } = region else {
                unreachable!("a cap always splits");
            };
            let node = leaf(samples, strata, rings.start, phis.start);
            self.nodes.push(node);
            return self.nodes.len() as u32 - 1;
        }
        let children: Vec<u32> = parts
            .into_iter()
            .map(|part| self.build(part, samples, strata))
            .collect();
        let mut node = Node {
            irradiance: Vec3::ZERO,
            solid_angle: 0.0,
            weighted_offset: Vec3::ZERO,
            weight: 0.0,
            plain_offset: Vec3::ZERO,
            children: Vec::new(),
        };
        for &c in &children {
            let child = &self.nodes[c as usize];
            node.irradiance += child.irradiance;
            node.solid_angle += child.solid_angle;
            node.weighted_offset += child.weighted_offset;
            node.weight += child.weight;
            node.plain_offset += child.plain_offset;
        }
        node.children = children;
        self.nodes.push(node);
        self.nodes.len() as u32 - 1
    }

    fn root(&self) -> u32 {
        self.nodes.len() as u32 - 1
    }

    fn children(&self, node: u32) -> &[u32] {
        &self.nodes[node as usize].children
    }

    /// The nodes two levels below `node` (a leaf where a branch ends
    /// sooner): the paper's comparison level.
    fn comparison_level(&self, node: u32) -> Vec<u32> {
        let mut level = vec![node];
        for _ in 0..2 {
            level = level
                .iter()
                .flat_map(|&n| match self.children(n) {
                    [] => vec![n],
                    children => children.to_vec(),
                })
                .collect();
        }
        level
    }

    /// The node as an EAS: its irradiance, solid angle and centroid.
    fn eas(&self, node: u32) -> Eas {
        let n = &self.nodes[node as usize];
        let offset = if n.weight > 0.0 {
            n.weighted_offset / n.weight
        } else {
            n.plain_offset / n.solid_angle.max(f32::MIN_POSITIVE)
        };
        Eas {
            offset,
            solid_angle: n.solid_angle,
            irradiance: n.irradiance,
            node,
        }
    }
}

/// The children of a region (none for a single cell): a cap splits into
/// a cap of half its rings and six sectors around it (Fig. 5a; the
/// innermost ring, into six sectors alone), a sector into halves of its
/// rings and of its φ cells (Fig. 5b).
fn split(region: &Region, strata: Strata) -> Vec<Region> {
    match region {
        Region::Cap { rings } => {
            let inner = rings / 2;
            let sectors = strata.phi.min(6);
            let mut parts: Vec<Region> = (inner > 0)
                .then_some(Region::Cap { rings: inner })
                .into_iter()
                .collect();
            parts.extend((0..sectors).map(|s| Region::Sector {
                rings: inner..*rings,
                phis: s * strata.phi / sectors..(s + 1) * strata.phi / sectors,
            }));
            parts
        }
        Region::Sector { rings, phis } => {
            let halves = |r: &Range<u32>| {
                if r.len() < 2 {
                    vec![r.clone()]
                } else {
                    let mid = r.start + r.len() as u32 / 2;
                    vec![r.start..mid, mid..r.end]
                }
            };
            if rings.len() < 2 && phis.len() < 2 {
                return Vec::new();
            }
            halves(rings)
                .into_iter()
                .flat_map(|r| {
                    halves(phis).into_iter().map(move |p| Region::Sector {
                        rings: r.clone(),
                        phis: p,
                    })
                })
                .collect()
        }
    }
}

/// A single cell as a node (Eq. 11): its sample's irradiance
/// `L·π/(MN)` (cells of equal projected solid angle, as the gather's
/// irradiance counts them), its exact solid angle
/// `Δφ·(cosθ_j − cosθ_{j+1})` (instead of the paper's `2π/#s`, which
/// holds for samples uniform in solid angle) and its hit point.
fn leaf(samples: &HemisphereSamples, strata: Strata, ring: u32, phi: u32) -> Node {
    let (m, n) = (strata.theta as f32, strata.phi as f32);
    let i = (ring * strata.phi + phi) as usize;
    let irradiance = samples.radiance[i] * (PI / (m * n));
    let cos = |j: f32| (1.0 - j / m).max(0.0).sqrt();
    let solid_angle = TAU / n * (cos(ring as f32) - cos(ring as f32 + 1.0));
    let distance = samples.distance[i].min(MISS_DISTANCE);
    let offset = samples.direction[i] * distance;
    let weight = luminance(irradiance).max(0.0);
    Node {
        irradiance,
        solid_angle,
        weighted_offset: offset * weight,
        weight,
        plain_offset: offset * solid_angle,
        children: Vec::new(),
    }
}

/// A cut through the tree and what it needs to be refined (§3.2, Fig. 6).
struct Cut<'a> {
    tree: &'a Tree,
    bsdf: &'a Bsdf,
    directions: &'a [Vec3; D],
    nodes: Vec<CutNode>,
    /// Each tree node's [`Cut::reflected`], once computed: a node is in the
    /// comparison level of its grandparent and then, maybe, in the cut.
    reflected: Vec<Option<[f32; D]>>,
    /// `Σ (L_comp − L_cur)` and `Σ L_comp` over the cut's nodes, per
    /// reflection direction (luminance; the paper's `Y`).
    difference: [f32; D],
    comparison: [f32; D],
}

struct CutNode {
    node: u32,
    difference: [f32; D],
    comparison: [f32; D],
    /// Eq. 14: `Σ_D (L_child − L_node)²`.
    local_error: f32,
}

impl<'a> Cut<'a> {
    /// From the root's children, the node of largest local error replaced
    /// by its children while the global error (Eq. 13) exceeds `tau`.
    fn refine(tree: &'a Tree, bsdf: &'a Bsdf, directions: &'a [Vec3; D], tau: f32) -> Vec<u32> {
        let mut cut = Cut {
            tree,
            bsdf,
            directions,
            nodes: Vec::new(),
            reflected: vec![None; tree.nodes.len()],
            difference: [0.0; D],
            comparison: [0.0; D],
        };
        for &child in tree.children(tree.root()) {
            cut.add(child);
        }
        while cut.global_error() > tau {
            let Some(worst) = cut.worst() else {
                break;
            };
            let node = cut.nodes[worst].node;
            let grown = cut.nodes.len() - 1 + tree.children(node).len();
            if grown > MAX_EAS {
                break;
            }
            cut.remove(worst);
            for &child in tree.children(node) {
                cut.add(child);
            }
        }
        cut.nodes.into_iter().map(|n| n.node).collect()
    }

    /// The luminance a node reflects towards each direction (Eq. 7).
    fn reflected(&mut self, node: u32) -> [f32; D] {
        if let Some(r) = self.reflected[node as usize] {
            return r;
        }
        let r = self.reflect(node);
        self.reflected[node as usize] = Some(r);
        r
    }

    fn reflect(&self, node: u32) -> [f32; D] {
        let eas = self.tree.eas(node);
        let length = eas.offset.length();
        if luminance(eas.irradiance) <= 0.0 || length <= 0.0 {
            return [0.0; D];
        }
        let axis = eas.offset / length;
        std::array::from_fn(|k| {
            let f = self
                .bsdf
                .mean_specular(self.directions[k], axis, eas.solid_angle);
            luminance(eas.irradiance * f)
        })
    }

    fn add(&mut self, node: u32) {
        let current = self.reflected(node);
        let mut comparison = [0.0; D];
        for n in self.tree.comparison_level(node) {
            for (c, r) in comparison.iter_mut().zip(self.reflected(n)) {
                *c += r;
            }
        }
        let difference: [f32; D] = std::array::from_fn(|k| comparison[k] - current[k]);
        for k in 0..D {
            self.difference[k] += difference[k];
            self.comparison[k] += comparison[k];
        }
        self.nodes.push(CutNode {
            node,
            difference,
            comparison,
            local_error: difference.iter().map(|d| d * d).sum(),
        });
    }

    fn remove(&mut self, index: usize) {
        let gone = self.nodes.swap_remove(index);
        for k in 0..D {
            self.difference[k] -= gone.difference[k];
            self.comparison[k] -= gone.comparison[k];
        }
    }

    /// Eq. 13: the RMS over the directions of `L_comp − L_cur`, relative to
    /// the mean of `L_comp`. Zero where nothing is reflected.
    fn global_error(&self) -> f32 {
        let mean = self.comparison.iter().sum::<f32>() / D as f32;
        if mean <= 0.0 {
            return 0.0;
        }
        let rms = (self.difference.iter().map(|d| d * d).sum::<f32>() / D as f32).sqrt();
        rms / mean
    }

    /// The refinable node of largest local error, if any has an error.
    fn worst(&self) -> Option<usize> {
        self.nodes
            .iter()
            .enumerate()
            .filter(|(_, n)| !self.tree.children(n.node).is_empty() && n.local_error > 0.0)
            .max_by(|a, b| a.1.local_error.total_cmp(&b.1.local_error))
            .map(|(i, _)| i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::IrradianceRecord;
    use crate::scene::Material;

    fn phong(n: f32) -> Material {
        Material::glossy("phong", Vec3::ZERO, Vec3::ONE, n)
    }

    /// Cell-centre samples of the hemisphere above the origin (normal +Z),
    /// each seeing what `scene(direction)` returns: radiance and distance.
    fn samples(strata: Strata, scene: impl Fn(Vec3) -> (Vec3, f32)) -> HemisphereSamples {
        let mut s = HemisphereSamples::default();
        for j in 0..strata.theta {
            for k in 0..strata.phi {
                let sin2 = (j as f32 + 0.5) / strata.theta as f32;
                let phi = TAU * (k as f32 + 0.5) / strata.phi as f32;
                let (st, ct) = (sin2.sqrt(), (1.0 - sin2).sqrt());
                let dir = Vec3::new(st * phi.cos(), st * phi.sin(), ct);
                let (radiance, distance) = scene(dir);
                s.direction.push(dir);
                s.radiance.push(radiance);
                s.distance.push(distance);
                s.object.push(0);
            }
        }
        s
    }

    /// Distance along `dir` from the origin to a sphere, if it is hit.
    fn sphere_hit(dir: Vec3, centre: Vec3, radius: f32) -> Option<f32> {
        let b = dir.dot(centre);
        let c = centre.length_squared() - radius * radius;
        let disc = b * b - c;
        (disc >= 0.0 && b - disc.sqrt() > 0.0).then(|| b - disc.sqrt())
    }

    /// Every sample's irradiance ends up in exactly one source (the cut is a
    /// partition of the cells), so the EAS sum to the gathered irradiance;
    /// the cut stays within its cap.
    #[test]
    fn the_sources_partition_the_records_irradiance() {
        let strata = Strata::default();
        let s = samples(strata, |d| {
            let x = (d.x * 7.0).sin().abs() + 0.1 * d.z;
            (Vec3::new(x, 0.5 * x, 1.0 - d.z), 1.0 + d.y.abs())
        });
        let bsdf = Bsdf::new(&phong(100.0), Vec3::Z, Vec3::Z);
        let sources = build(&s, Vec3::Z, strata, &bsdf, DEFAULT_TAU);
        assert!(
            !sources.is_empty() && sources.len() <= MAX_EAS,
            "{}",
            sources.len()
        );
        let total: Vec3 = sources.iter().map(|e| e.irradiance).sum();
        let gathered: Vec3 =
            s.radiance.iter().copied().sum::<Vec3>() * (PI / strata.count() as f32);
        assert!(
            (total - gathered).abs().max_element() < 1e-4 * gathered.max_element(),
            "{total} vs {gathered}"
        );
        let omega: f32 = sources.iter().map(|e| e.solid_angle).sum();
        assert!(omega <= TAU * 1.0001, "{omega}");
        // A diffuse surface keeps no sources.
        let diffuse = Bsdf::new(&Material::diffuse("d", Vec3::ONE), Vec3::Z, Vec3::Z);
        assert!(build(&s, Vec3::Z, strata, &diffuse, DEFAULT_TAU).is_empty());
    }

    /// Over the samples they were built from, the sources' irradiance is
    /// their own; over samples where one cell is brighter, only the source
    /// holding that cell changes, by exactly that cell's extra irradiance.
    #[test]
    fn irradiance_over_other_samples_sums_each_sources_own_cells() {
        let strata = Strata::default();
        let s = samples(strata, |d| {
            (Vec3::splat(0.2 + (d.x * 5.0).cos().abs()), 1.0 + d.z)
        });
        let bsdf = Bsdf::new(&phong(100.0), Vec3::Z, Vec3::Z);
        let sources = build(&s, Vec3::Z, strata, &bsdf, DEFAULT_TAU);
        let same = irradiance_over(&sources, &s, strata).expect("same layout");
        for (e, over) in sources.iter().zip(&same) {
            assert_eq!(e.irradiance, *over);
        }
        let cell = 7 * strata.phi as usize + 13;
        let mut brighter = s.clone();
        brighter.radiance[cell] += Vec3::ONE;
        let extra = PI / strata.count() as f32;
        let moved = irradiance_over(&sources, &brighter, strata).expect("same layout");
        let changed: Vec<Vec3> = sources
            .iter()
            .zip(&moved)
            .map(|(e, m)| *m - e.irradiance)
            .filter(|d| *d != Vec3::ZERO)
            .collect();
        assert_eq!(changed.len(), 1, "{changed:?}");
        assert!((changed[0] - Vec3::splat(extra)).abs().max_element() < 1e-5);
        let short = HemisphereSamples::default();
        assert!(irradiance_over(&sources, &short, strata).is_none());
    }

    /// The glossy radiance a point reflects from a small spherical light,
    /// through the EAS of a record beside it (Eq. 16–17), against the same
    /// integral by Monte Carlo over the light as the point sees it, at the
    /// lobe's peak and on its flank.
    #[test]
    fn a_record_beside_the_point_reflects_a_small_light_as_the_point_sees_it() {
        let strata = Strata {
            theta: 64,
            phi: 192,
        };
        let (centre, radius, le) = (Vec3::new(0.4, 0.0, 1.0), 0.1, Vec3::splat(10.0));
        let s = samples(strata, |d| match sphere_hit(d, centre, radius) {
            Some(t) => (le, t),
            None => (Vec3::ZERO, f32::INFINITY),
        });
        let material = phong(40.0);
        let bsdf = Bsdf::new(&material, Vec3::Z, Vec3::Z);
        let sources = build(&s, Vec3::Z, strata, &bsdf, DEFAULT_TAU);
        let mut cache = IrradianceCache::new(Vec3::splat(-2.0), Vec3::splat(2.0), 0.2);
        cache.insert(IrradianceRecord {
            id: 0,
            position: Vec3::ZERO,
            normal: Vec3::Z,
            irradiance: sources.iter().map(|e| e.irradiance).sum(),
            grad_translation: [Vec3::ZERO; 3],
            grad_rotation: [Vec3::ZERO; 3],
            radius: 10.0,
            created_frame: 0,
            object: 0,
            eas: Some(sources.into()),
        });
        for p in [Vec3::ZERO, Vec3::new(0.08, 0.05, 0.0)] {
            let to_light = (centre - p).normalize();
            let mirror = Vec3::new(-to_light.x, -to_light.y, to_light.z);
            for wo in [mirror, (mirror + Vec3::new(-0.15, 0.1, 0.0)).normalize()] {
                let at = LookupPoint::open(p, Vec3::Z);
                let bsdf = Bsdf::new(&material, Vec3::Z, wo);
                let eas = reflected_radiance(&cache, &at, &bsdf, wo).unwrap().x;
                let exact = reflected_by_sampling(&bsdf, wo, p, centre, radius, le.x);
                let error = (eas - exact).abs() / exact;
                assert!(error < 0.05, "p={p} wo={wo}: EAS {eas} against {exact}");
            }
        }
    }

    /// `∫ f_s(wo, ωi)·L·cosθi dωi` over the sphere as `p` sees it (normal
    /// +Z), uniform in the cone it subtends.
    fn reflected_by_sampling(
        bsdf: &Bsdf,
        wo: Vec3,
        p: Vec3,
        centre: Vec3,
        radius: f32,
        le: f32,
    ) -> f32 {
        let to = centre - p;
        let cos_max = (1.0 - radius * radius / to.length_squared()).sqrt();
        let cone = TAU * (1.0 - cos_max);
        let frame = Frame::new(to.normalize());
        let n = 200;
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let cos = 1.0 - (i as f32 + 0.5) / n as f32 * (1.0 - cos_max);
                let sin = (1.0 - cos * cos).sqrt();
                let phi = TAU * (j as f32 + 0.5) / n as f32;
                let wi = frame.to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos));
                sum += (bsdf.eval_specular(wo, wi).x * le * wi.z.max(0.0)) as f64;
            }
        }
        (sum / (n * n) as f64) as f32 * cone
    }
}
