//! The irradiance record (Ward et al. 1988; gradients after Ward & Heckbert
//! 1992) and its extrapolation to a nearby point, TRC paper Eq. 4:
//!
//! `E_K(p) = E_K + (n_K × n)·∇r + (p − p_K)·∇p`.

use glam::Vec3;

/// Identifies a record for its whole life (across frames for the temporal
/// methods). Assigned in creation order, so deterministic.
pub type RecordId = u64;

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
}

impl IrradianceRecord {
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

    /// TRC Eq. 2: `w_K(p) = 1 / (‖p − p_K‖/R_K + √(1 − n·n_K))`.
    pub fn weight(&self, p: Vec3, n: Vec3) -> f32 {
        let d = (p - self.position).length() / self.radius;
        let c = (1.0 - n.dot(self.normal)).max(0.0).sqrt();
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
    pub fn is_in_front_of(&self, p: Vec3, n: Vec3) -> bool {
        const FRONT_TOLERANCE: f32 = 0.01;
        let d = (p - self.position).dot(0.5 * (n + self.normal));
        d < -FRONT_TOLERANCE * self.radius
    }

    /// Radius of the sphere outside which the weight is below `1/a` (for
    /// points with the record's normal): `a·R_K`.
    pub fn influence_radius(&self, accuracy: f32) -> f32 {
        accuracy * self.radius
    }
}
