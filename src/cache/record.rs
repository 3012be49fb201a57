//! The irradiance record (Ward et al. 1988; gradients after Ward & Heckbert
//! 1992) and its extrapolation to a nearby point, TRC paper Eq. 4:
//!
//! `E_K(p) = E_K + (n_K × n)·∇r + (p − p_K)·∇p`.

use glam::Vec3;

/// Identifies a record for its whole life (across frames for the temporal
/// methods). Assigned in creation order, so deterministic.
pub type RecordId = u64;

/// A point where the cache is looked up: a surface point, its unit
/// shading normal, and its clearance: the distance to the nearest surface
/// straight along the normal ([`LookupPoint::OPEN`] where nothing is
/// there or it was not measured). See [`IrradianceRecord::weight`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LookupPoint {
    pub position: Vec3,
    pub normal: Vec3,
    pub clearance: f32,
}

impl LookupPoint {
    /// The clearance of a point with nothing above it: finite (and finite
    /// times [`Self::radius`]'s 3/2), so that it crosses to the GPU
    /// unchanged (WGSL may assume no infinities).
    pub const OPEN: f32 = 1e30;

    pub fn new(position: Vec3, normal: Vec3, clearance: f32) -> Self {
        LookupPoint {
            position,
            normal,
            clearance,
        }
    }

    /// A point whose clearance is not measured: Ward's weight unchanged.
    pub fn open(position: Vec3, normal: Vec3) -> Self {
        LookupPoint::new(position, normal, Self::OPEN)
    }

    /// The harmonic mean distance `R` a record gathered here would have
    /// if the surface at the clearance `h` were a plane parallel to this
    /// one: over the cosine-weighted hemisphere the mean of `1/r =
    /// cosθ/h` is `2/(3h)`, so `R = 3h/2`. One ray cannot see more; the
    /// factor keeps the bound consistent with the `R` of the records
    /// ([`crate::cache::gather`]), so a record gathered at this very point
    /// under such a plane is not cut down by it.
    pub fn radius(&self) -> f32 {
        1.5 * self.clearance
    }
}

/// The most weight ([`IrradianceRecord::weight`]) a record has in an
/// interpolation: a record exactly at p has infinite weight, and capped it
/// alone decides, where ∞/∞ would give NaN. `shaders/cache_splat.wgsl`'s
/// `WEIGHT_CAP` must match.
pub const WEIGHT_CAP: f32 = 1e6;

/// One cached irradiance sample of the indirect light on a surface.
#[derive(Clone, Debug, PartialEq)]
pub struct IrradianceRecord {
    pub id: RecordId,
    pub position: Vec3,
    /// Unit shading normal the hemisphere was gathered around.
    pub normal: Vec3,
    /// Indirect irradiance `E_K` (W·m⁻²) per colour channel.
    pub irradiance: Vec3,
    /// Translation gradient `∇p` per colour channel (r, g, b).
    pub grad_translation: [Vec3; 3],
    /// Rotation gradient `∇r` per colour channel (r, g, b).
    pub grad_rotation: [Vec3; 3],
    /// Harmonic mean distance `R_K` to the surfaces seen from the record,
    /// after clamping (see [`super::gather`]).
    pub radius: f32,
    /// Frame in which the record was computed.
    pub created_frame: u32,
    /// Object the record lies on.
    pub object: u32,
    /// The equivalent area light sources of a record on a glossy surface
    /// ([`super::eas`]), where the method asks for radiance records.
    pub eas: Option<std::sync::Arc<[super::eas::Eas]>>,
}

#[cfg(test)]
impl IrradianceRecord {
    /// A record `id` at `position` facing +y, of irradiance `irradiance`,
    /// radius 1 and no gradients, made at frame 0 on object 0 (for tests).
    pub(crate) fn flat(id: u64, position: Vec3, irradiance: Vec3) -> IrradianceRecord {
        IrradianceRecord {
            id,
            position,
            normal: Vec3::Y,
            irradiance,
            grad_translation: [Vec3::ZERO; 3],
            grad_rotation: [Vec3::ZERO; 3],
            radius: 1.0,
            created_frame: 0,
            object: 0,
            eas: None,
        }
    }
}

impl IrradianceRecord {
    /// Bytes of its sources, held beside the record (shared with the
    /// record's copies).
    pub fn sources_bytes(&self) -> usize {
        self.eas
            .as_ref()
            .map_or(0, |s| std::mem::size_of_val::<[super::eas::Eas]>(s))
    }

    /// Eq. 4: the record's irradiance extrapolated to point `p` with normal
    /// `n` through its gradients. `use_gradients = false` gives `E_K`.
    pub fn extrapolate(&self, p: Vec3, n: Vec3, use_gradients: bool) -> Vec3 {
        if !use_gradients {
            return self.irradiance;
        }
        let rotation = self.normal.cross(n);
        let translation = p - self.position;
        let delta = Vec3::new(
            rotation.dot(self.grad_rotation[0]) + translation.dot(self.grad_translation[0]),
            rotation.dot(self.grad_rotation[1]) + translation.dot(self.grad_translation[1]),
            rotation.dot(self.grad_rotation[2]) + translation.dot(self.grad_translation[2]),
        );
        // Gradients extrapolate linearly; never let them push irradiance negative.
        (self.irradiance + delta).max(Vec3::ZERO)
    }

    /// TRC Eq. 2, `w_K(p) = 1 / (‖p − p_K‖/R_K + √(1 − n·n_K))`, with
    /// `R_K` no larger than the lookup point's own estimate `R_p`
    /// ([`LookupPoint::radius`]): `‖p − p_K‖ / min(R_K, R_p)`.
    ///
    /// Why (a departure from Ward): his error model, the split sphere,
    /// bounds the change of irradiance between two points by their
    /// distance over the distance to the surfaces around them, and `R_K`
    /// measures that only around `p_K`. A point with a surface close above
    /// it (the ceiling above a light hung 2 cm under it, the floor under a
    /// low shelf) sees an environment `K` never saw, however near `p_K`
    /// is. `R_p` comes from one ray along p's normal and is huge wherever p
    /// is open, so it leaves the weight alone there.
    pub fn weight(&self, at: &LookupPoint) -> f32 {
        let d = (at.position - self.position).length() / self.radius.min(at.radius());
        // √(1 − n·n_K) = ‖n − n_K‖/√2 for unit normals, written without the
        // cancellation of 1 − n·n_K: near-parallel normals lose nothing to
        // rounding, equal ones give exactly 0, and a GPU that fuses the dot
        // product's multiply-adds (NVIDIA's does) cannot turn a 1-ulp
        // change of n·n_K into a term of √ulp ≈ 2.4e-4 at a record's own
        // point (seen on an H100: weight 4,000 instead of the 1e6 cap).
        let c = (at.normal - self.normal).length() * std::f32::consts::FRAC_1_SQRT_2;
        let denom = d + c;
        if denom > 0.0 {
            1.0 / denom
        } else {
            f32::INFINITY
        }
    }

    /// Ward's "in front" test: the record lies in front of `p` (above the
    /// tangent plane at p, averaged over both normals), so it sees a
    /// different environment and must not be used. The tolerance is relative
    /// to the record's radius so that the test is scale-invariant.
    pub fn is_in_front_of(&self, at: &LookupPoint) -> bool {
        const FRONT_TOLERANCE: f32 = 0.01;
        let d = (at.position - self.position).dot(0.5 * (at.normal + self.normal));
        d < -FRONT_TOLERANCE * self.radius
    }

    /// Radius of the sphere outside which the weight is below `1/a` (for
    /// points with the record's normal): `a·R_K`.
    pub fn influence_radius(&self, accuracy: f32) -> f32 {
        accuracy * self.radius
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(radius: f32) -> IrradianceRecord {
        IrradianceRecord {
            id: 0,
            position: Vec3::ZERO,
            normal: Vec3::Y,
            irradiance: Vec3::ONE,
            grad_translation: [Vec3::ZERO; 3],
            grad_rotation: [Vec3::ZERO; 3],
            radius,
            created_frame: 0,
            object: 0,
            eas: None,
        }
    }

    /// Ward's weight `R_K/d` at an open point (and at one whose clearance
    /// is far), `R_p/d = 1.5·h/d` under a surface close above it.
    #[test]
    fn weight_uses_the_smaller_of_the_record_and_lookup_radii() {
        let k = record(1.0);
        let p = Vec3::new(0.1, 0.0, 0.0);
        let open = k.weight(&LookupPoint::open(p, Vec3::Y));
        assert!((open - 10.0).abs() < 1e-4, "{open}");
        let far = k.weight(&LookupPoint::new(p, Vec3::Y, 2.0));
        assert_eq!(far, open);
        let under = k.weight(&LookupPoint::new(p, Vec3::Y, 0.02));
        assert!((under - 0.3).abs() < 1e-4, "{under}");
        // At accuracy 0.2 (usable where w ≥ 5) the record covers the open
        // point and not the one under the surface.
        assert!(open >= 5.0 && under < 5.0);
    }

    /// The normal term of Eq. 2 is `√(1 − n·n_K)`, computed as
    /// `‖n − n_K‖/√2`: the same for unit normals (checked against f64),
    /// and exactly 0 for equal normals, where the f32 dot product of a
    /// normalised vector with itself often rounds below 1 and
    /// `√(1 − n·n)` gives about 2.4e-4, a weight of ~4,000 at the record's
    /// own point instead of ∞.
    #[test]
    fn the_normal_term_is_exact_for_equal_normals_and_matches_the_dot_form() {
        let mut rng = crate::sampling::Rng::from_seed(7, 0);
        let mut rounded_below_one = 0;
        for _ in 0..1000 {
            let n = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            )
            .normalize();
            let k = IrradianceRecord {
                normal: n,
                ..record(1.0)
            };
            rounded_below_one += usize::from(n.dot(n) < 1.0);
            assert_eq!(k.weight(&LookupPoint::open(Vec3::ZERO, n)), f32::INFINITY);
            let m = (n + 0.3 * Vec3::new(rng.next_f32(), rng.next_f32(), 0.5)).normalize();
            let p = Vec3::new(0.25, 0.0, 0.0);
            let (n64, m64) = (n.as_dvec3(), m.as_dvec3());
            let exact = 1.0 / (0.25 + (1.0 - n64.dot(m64)).max(0.0).sqrt());
            let w = k.weight(&LookupPoint::open(p, m)) as f64;
            assert!((w - exact).abs() <= 1e-4 * exact, "{w} against {exact}");
        }
        // The case the old form got wrong is common, so the test meets it.
        assert!(rounded_below_one > 10, "{rounded_below_one}");
    }
}
