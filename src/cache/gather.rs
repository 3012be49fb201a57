//! Hemisphere gathering for a new record: stratified sampling of the
//! incoming indirect radiance over `M × N` cells, the irradiance, the
//! Ward & Heckbert (1992) translation and rotation gradients from the same
//! samples, and the harmonic mean distance `R`.
//!
//! Cells are cosine-weighted: cell `(j, k)` spans `sin²θ ∈ [j/M, (j+1)/M)`
//! and `φ ∈ [2πk/N, 2π(k+1)/N)`, so each has the same projected solid angle
//! `π/(MN)` and `E = π/(MN) · Σ L_{j,k}` (Ward & Heckbert 1992, Eq. 2).
//! The incoming radiance of each cell is one path-traced sample whose first
//! hit does not count emission: direct light is computed per pixel by
//! next-event estimation, the cache holds the indirect part only.

use crate::backend::Ray;
use crate::integrator::{FirstHitEmission, RadianceQuery, RadianceResult, RayOffset};
use crate::sampling::{Frame, Rng, SampleKey};
use glam::Vec3;
use std::f32::consts::{PI, TAU};

/// Stratification of the gathering hemisphere.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Strata {
    /// Cells in θ (`M`).
    pub theta: u32,
    /// Cells in φ (`N`); Ward & Heckbert suggest `N ≈ π·M`.
    pub phi: u32,
}

impl Default for Strata {
    /// 16 × 48 = 768 rays per record, in the range of the papers (Ward &
    /// Heckbert 1992 use a few hundred to a few thousand samples per record).
    fn default() -> Self {
        Strata { theta: 16, phi: 48 }
    }
}

impl Strata {
    pub fn count(&self) -> usize {
        // In usize: settings read back from a store are not range-checked
        // as flags are, and a u32 product could overflow.
        self.theta as usize * self.phi as usize
    }
}

/// The incoming-radiance samples of one record, cell `(j, k)` at index
/// `j·N + k`. Kept with the record: the temporal methods reproject and
/// re-shoot them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HemisphereSamples {
    /// World-space unit direction of each sample.
    pub direction: Vec<Vec3>,
    /// Incoming indirect radiance.
    pub radiance: Vec<Vec3>,
    /// Distance to the first hit (`f32::INFINITY` for a miss).
    pub distance: Vec<f32>,
    /// Object of the first hit (`u32::MAX` for a miss).
    pub object: Vec<u32>,
}

/// Where a record is gathered.
#[derive(Clone, Copy, Debug)]
pub struct GatherPoint {
    pub position: Vec3,
    /// Shading normal, oriented to the side the camera sees.
    pub normal: Vec3,
    /// Geometric normal (for offsetting ray origins).
    pub geometric_normal: Vec3,
}

/// The `M·N` radiance queries of a record, cell by cell, leaving `point`
/// by `offset`. `key` identifies the record's random stream; its `sample`
/// field is replaced by the cell index so that every cell has its own
/// stream.
pub fn gather_queries(
    point: &GatherPoint,
    offset: RayOffset,
    strata: Strata,
    key: SampleKey,
) -> Vec<RadianceQuery> {
    let frame = Frame::new(point.normal);
    (0..strata.count() as u32)
        .map(|cell| {
            let rng = Rng::new(SampleKey {
                sample: cell,
                ..key
            });
            cell_query(point, offset, &frame, strata, cell, rng)
        })
        .collect()
}

/// The radiance query of cell `cell` (`j·N + k`) of a record at `point`
/// whose hemisphere is laid out in `frame` (its normal is `frame.n`),
/// leaving it by `offset`: a
/// direction jittered within the cell by `rng`'s first two numbers, the
/// rest of `rng` for the path. `tcg` re-shoots single cells with it, in
/// the frame its record carries along with its object.
pub fn cell_query(
    point: &GatherPoint,
    offset: RayOffset,
    frame: &Frame,
    strata: Strata,
    cell: u32,
    mut rng: Rng,
) -> RadianceQuery {
    let dir = cell_direction(frame, strata, cell, rng.next_2d());
    let origin = offset.origin(point.position, point.geometric_normal, dir);
    RadianceQuery {
        ray: Ray::new(origin, dir, 0.0, f32::INFINITY),
        first_light: None,
        rng,
        weight: Vec3::ONE,
        first_hit: FirstHitEmission::Exclude,
    }
}

/// The direction at `u ∈ [0, 1)²` within cell `cell` (`j·N + k`) of a
/// hemisphere laid out in `frame`: cosine-weighted, rings of equal
/// projected area. `u = (½, ½)` is the cell's centre.
pub fn cell_direction(frame: &Frame, strata: Strata, cell: u32, u: glam::Vec2) -> Vec3 {
    let (m, n) = (strata.theta, strata.phi);
    let (j, k) = (cell / n, cell % n);
    let sin2 = (j as f32 + u.x) / m as f32;
    let phi = TAU * (k as f32 + u.y) / n as f32;
    let (sin_t, cos_t) = (sin2.sqrt(), (1.0 - sin2).max(0.0).sqrt());
    frame.to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t))
}

/// Collects the traced queries of [`gather_queries`] into samples.
pub fn samples_from_results(
    queries: &[RadianceQuery],
    results: &[RadianceResult],
) -> HemisphereSamples {
    let n = queries.len();
    let mut s = HemisphereSamples {
        direction: Vec::with_capacity(n),
        radiance: Vec::with_capacity(n),
        distance: Vec::with_capacity(n),
        object: Vec::with_capacity(n),
    };
    for (q, r) in queries.iter().zip(results) {
        let dir = q.ray.dir();
        s.direction.push(dir);
        s.radiance.push(r.radiance);
        if r.hit.is_hit() {
            s.distance.push(r.hit.t * dir.length());
            s.object.push(r.hit.object);
        } else {
            s.distance.push(f32::INFINITY);
            s.object.push(u32::MAX);
        }
    }
    s
}

/// Irradiance, gradients and harmonic mean distance of a gathered hemisphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GatheredIrradiance {
    pub irradiance: Vec3,
    pub grad_translation: [Vec3; 3],
    pub grad_rotation: [Vec3; 3],
    /// Harmonic mean distance `MN / Σ 1/r` (infinite if nothing was hit).
    pub harmonic_distance: f32,
}

/// The least hit distance [`irradiance_and_gradients`] divides by. A
/// gather ray can hit at exactly 0: from a record on the edge where two
/// surfaces meet (a pixel centre that lands on a room's corner line), a
/// ray into the other surface starts on it. Divided by 0, a gradient term
/// is ±∞, or 0·∞ = NaN where the two cells' radiance is equal, and a NaN
/// gradient made the record add nothing wherever it was used (Eq. 4 clamps
/// `E + NaN` to 0). A huge but finite term is then bounded by the gradient
/// limit as any near hit's is (`ic::limit_gradient`).
const MIN_HIT_DISTANCE: f32 = 1e-6;

/// Ward & Heckbert 1992 estimates from stratified samples (in the notation
/// of Křivánek et al., "Practical Global Illumination with Irradiance
/// Caching", SIGGRAPH 2008 course, §2.3):
///
/// `E = π/(MN) Σ L_{j,k}`
///
/// `∇r E = π/(MN) Σ_k v_k Σ_j tan θ_j L_{j,k}`
///
/// `∇p E = Σ_k [ u_k (2π/N) Σ_{j≥1} sinθ⁻_j cos²θ⁻_j / min(r_{j,k}, r_{j−1,k}) (L_{j,k} − L_{j−1,k})
///            + v⁻_k Σ_j (sinθ⁺_j − sinθ⁻_j) / min(r_{j,k}, r_{j,k−1}) (L_{j,k} − L_{j,k−1}) ]`
///
/// with `u_k` the base-plane direction of sector `k`'s centre, `v_k` the
/// direction perpendicular to it, `v⁻_k` perpendicular to the boundary
/// between sectors `k−1` and `k`, and `θ⁻_j`, `θ⁺_j` the lower and upper
/// boundaries of ring `j`.
///
/// Two departures from the formulas as usually quoted, both re-derived and
/// checked against finite differences in `tests/ic.rs`: the rotation
/// gradient has a positive sign because Eq. 4 applies it as
/// `(n_K × n)·∇r` (rotating the normal towards bright light must increase
/// E); the azimuthal-wall term of `∇p` is `(sinθ⁺ − sinθ⁻)/r`, the
/// integral of `cosθ·sinθ·dφ/dx = cosθ/r` over the ring, which for
/// cosine-weighted rings differs from `(cosθ⁻ − cosθ⁺)/(r·sinθ)` most at
/// grazing angles.
pub fn irradiance_and_gradients(
    samples: &HemisphereSamples,
    normal: Vec3,
    strata: Strata,
) -> GatheredIrradiance {
    irradiance_and_gradients_in(
        &samples.radiance,
        &samples.distance,
        &Frame::new(normal),
        strata,
    )
}

/// `E = π/(MN) Σ L_{j,k}` of a gathered hemisphere alone (for what needs
/// no gradients: `trc`'s estimates of E at later frames).
pub fn irradiance(samples: &HemisphereSamples, strata: Strata) -> Vec3 {
    irradiance_of_cells(&samples.radiance, strata)
}

/// `E = π/(MN) Σ L_{j,k}` of each cell's radiance `l`.
fn irradiance_of_cells(l: &[Vec3], strata: Strata) -> Vec3 {
    let sum: Vec3 = l.iter().copied().sum();
    sum * (PI / strata.count() as f32)
}

/// [`irradiance_and_gradients`] of cells laid out in `frame` (normal
/// `frame.n`), from each cell's radiance `l` and hit distance `r` in cell
/// order: `tcg`'s records keep their cells' frame as their object turns.
pub fn irradiance_and_gradients_in(
    l: &[Vec3],
    r: &[f32],
    frame: &Frame,
    strata: Strata,
) -> GatheredIrradiance {
    let (m, n) = (strata.theta as usize, strata.phi as usize);
    let cell = |j: usize, k: usize| j * n + k;
    let base = |phi: f32| frame.to_world(Vec3::new(phi.cos(), phi.sin(), 0.0));
    let rings = RingTerms::new(m, n);

    let irradiance = irradiance_of_cells(l, strata);

    let mut rotation = [Vec3::ZERO; 3];
    let mut translation = rotation;
    for k in 0..n {
        let phi_center = TAU * (k as f32 + 0.5) / n as f32;
        let phi_boundary = TAU * k as f32 / n as f32;
        let u_k = base(phi_center);
        let v_k = base(phi_center + 0.5 * PI);
        let v_boundary = base(phi_boundary + 0.5 * PI);
        let k_prev = (k + n - 1) % n;
        for j in 0..m {
            let lj = l[cell(j, k)];
            add_scaled(&mut rotation, v_k, lj * rings.rotation[j]);
            if j >= 1 {
                let rmin = r[cell(j, k)].min(r[cell(j - 1, k)]).max(MIN_HIT_DISTANCE);
                let coef = rings.lower_wall[j] / rmin;
                add_scaled(&mut translation, u_k, (lj - l[cell(j - 1, k)]) * coef);
            }
            let rmin = r[cell(j, k)].min(r[cell(j, k_prev)]).max(MIN_HIT_DISTANCE);
            let coef = rings.sin_span[j] / rmin;
            add_scaled(
                &mut translation,
                v_boundary,
                (lj - l[cell(j, k_prev)]) * coef,
            );
        }
    }
    let inverse_sum: f32 = r.iter().map(|d| 1.0 / d.max(MIN_HIT_DISTANCE)).sum();
    GatheredIrradiance {
        irradiance,
        grad_translation: translation,
        grad_rotation: rotation,
        harmonic_distance: if inverse_sum > 0.0 {
            r.len() as f32 / inverse_sum
        } else {
            f32::INFINITY
        },
    }
}

/// The terms of [`irradiance_and_gradients`] that depend on the ring `j`
/// alone, computed once a record rather than once a cell (they cost an
/// `asin` and trigonometry each, a few percent of `ic`'s time when
/// computed per cell; the values are the same).
struct RingTerms {
    /// `tanθ · π/(MN)`, `θ` at ring `j`'s centre (`sin²θ = (j + ½)/M`):
    /// the angle of the cell centre rather than of the jittered sample,
    /// since `tanθ` of a grazing sample would blow up the rotation term.
    rotation: Vec<f32>,
    /// `2π/N · sinθ⁻ cos²θ⁻` of ring `j`'s lower boundary (used for
    /// `j ≥ 1`), in the order of operations of the per-cell formula.
    lower_wall: Vec<f32>,
    /// `sinθ⁺ − sinθ⁻` over ring `j`.
    sin_span: Vec<f32>,
}

impl RingTerms {
    fn new(m: usize, n: usize) -> Self {
        // θ⁻ of ring `j`, θ⁺ of ring `j − 1`: `sin²θ = j/M`.
        let boundary: Vec<f32> = (0..=m)
            .map(|j| (j as f32 / m as f32).sqrt().asin())
            .collect();
        let rotation = (0..m)
            .map(|j| {
                let sin2 = (j as f32 + 0.5) / m as f32;
                let (sin_t, cos_t) = (sin2.sqrt(), (1.0 - sin2).sqrt());
                let tan_t = sin_t / cos_t;
                tan_t * PI / (m * n) as f32
            })
            .collect();
        let lower_wall = boundary[..m]
            .iter()
            .map(|t| TAU / n as f32 * t.sin() * t.cos() * t.cos())
            .collect();
        let sin_span = boundary
            .windows(2)
            .map(|w| w[1].sin() - w[0].sin())
            .collect();
        RingTerms {
            rotation,
            lower_wall,
            sin_span,
        }
    }
}

/// `grad[c] += dir · value[c]` for each colour channel `c`.
fn add_scaled(grad: &mut [Vec3; 3], dir: Vec3, value: Vec3) {
    for (g, v) in grad.iter_mut().zip(value.to_array()) {
        *g += dir * v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Cells whose rays hit at t = 0 (`-0` too, as a ray from the plane of
    /// the surface it hits measures it) next to cells of the same radiance,
    /// where a term was 0·∞ = NaN, and of another radiance, where it was
    /// ±∞: the gradients stay finite, and the harmonic mean distance is
    /// that of hits at [`MIN_HIT_DISTANCE`].
    #[test]
    fn hits_at_zero_distance_leave_the_gradients_finite() {
        let strata = Strata { theta: 4, phi: 8 };
        let mut l = vec![Vec3::splat(0.5); 32];
        let mut r = vec![1.0; 32];
        r[9] = 0.0;
        r[10] = -0.0;
        r[20] = 0.0;
        l[20] = Vec3::new(2.0, 0.0, 1.0);
        let g = irradiance_and_gradients_in(&l, &r, &Frame::new(Vec3::Z), strata);
        let gradients = g.grad_translation.iter().chain(&g.grad_rotation);
        assert!(gradients.clone().all(|v| v.is_finite()), "{g:?}");
        assert!(g.irradiance.is_finite());
        let expected = 32.0 / (29.0 + 3.0 / MIN_HIT_DISTANCE);
        assert!((g.harmonic_distance / expected - 1.0).abs() < 1e-4, "{g:?}");
    }
}
