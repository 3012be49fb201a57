//! The camera evaluated at one time, and how a scene places it.

use super::{within_world, Channel, Scene, Triangle, MAX_WORLD_COORDINATE};
use glam::{Mat3, Mat4, Vec3};

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

impl Scene {
    /// The camera at time `t` (as [`Scene::snapshot`] evaluates it).
    pub fn camera_at(&self, t: f32) -> Camera {
        let world = self.node_world_transforms(t);
        self.camera_in(&world, t)
    }

    /// The camera at time `t` given the world transforms of that time. A
    /// camera scaled to nothing (its node or an ancestor animated to scale
    /// 0) has no orientation in its matrix; it keeps the one its nodes'
    /// rotations give (its frames were black).
    pub(super) fn camera_in(&self, world: &[Mat4], t: f32) -> Camera {
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

#[cfg(test)]
mod tests {
    use super::*;

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
