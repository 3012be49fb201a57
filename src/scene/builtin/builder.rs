//! Scene assembly and animation helpers of the built-in scenes.

use super::super::animation::{linear_rotation, linear_translation, Channel};
use super::super::{
    Animation, CameraDef, Material, Mesh, Node, Object, PunctualLight, Scene, Trs, DEFAULT_FPS,
};
use glam::{Quat, Vec3};

pub(super) fn at(translation: Vec3) -> Trs {
    Trs {
        translation,
        ..Trs::default()
    }
}

pub(super) fn trs(translation: Vec3, rotation: Quat) -> Trs {
    Trs {
        translation,
        rotation,
        ..Trs::default()
    }
}

/// Time of frame `k` at the default frame rate.
fn frame_time(k: u32) -> f32 {
    k as f32 / DEFAULT_FPS
}

/// A translation channel with a `LINEAR` key at every frame `0..=frames`
/// from `path(t)`: exact at frame times, piecewise linear in between.
pub(super) fn translation_track(node: usize, frames: u32, path: impl Fn(f32) -> Vec3) -> Channel {
    let keys: Vec<(f32, Vec3)> = (0..=frames)
        .map(|k| (frame_time(k), path(frame_time(k))))
        .collect();
    linear_translation(node, &keys)
}

/// A rotation channel with a key at every frame; per-frame steps are small,
/// so slerp's shortest arc follows `rotation(t)`.
pub(super) fn rotation_track(node: usize, frames: u32, rotation: impl Fn(f32) -> Quat) -> Channel {
    let keys: Vec<(f32, Quat)> = (0..=frames)
        .map(|k| (frame_time(k), rotation(frame_time(k))))
        .collect();
    linear_rotation(node, &keys)
}

/// Accumulates nodes, objects, materials and lights into a [`Scene`].
pub(super) struct Builder {
    scene: Scene,
    has_camera: bool,
}

impl Builder {
    pub(super) fn new(name: &str, frame_count: u32) -> Self {
        Builder {
            scene: Scene {
                name: name.to_string(),
                nodes: Vec::new(),
                objects: Vec::new(),
                materials: Vec::new(),
                lights: Vec::new(),
                camera: CameraDef {
                    node: 0,
                    yfov: 1.0,
                    aspect_ratio: None,
                },
                animation: Animation::default(),
                frame_count,
                moved_by: Vec3::ZERO,
            },
            has_camera: false,
        }
    }

    pub(super) fn material(&mut self, material: Material) -> u32 {
        self.scene.materials.push(material);
        self.scene.materials.len() as u32 - 1
    }

    fn node(&mut self, name: &str, rest: Trs) -> usize {
        self.scene.nodes.push(Node {
            name: name.to_string(),
            parent: None,
            rest,
        });
        self.scene.nodes.len() - 1
    }

    /// Places `mesh` on a new node of its own; returns the node.
    pub(super) fn object(&mut self, name: &str, rest: Trs, mesh: Mesh) -> usize {
        let node = self.node(name, rest);
        self.scene.objects.push(Object {
            name: name.to_string(),
            node,
            mesh,
        });
        node
    }

    /// A point light on a new node (placed by its animation); returns the node.
    pub(super) fn point_light(&mut self, name: &str, intensity: Vec3) -> usize {
        let node = self.node(name, Trs::default());
        self.scene.lights.push(PunctualLight {
            name: name.to_string(),
            node,
            intensity,
            kind: crate::scene::LightKind::Point,
        });
        node
    }

    pub(super) fn camera(&mut self, rest: Trs, yfov: f32) {
        let node = self.node("camera", rest);
        self.scene.camera = CameraDef {
            node,
            yfov,
            aspect_ratio: None,
        };
        self.has_camera = true;
    }

    pub(super) fn animate(&mut self, channel: Channel) {
        self.scene.animation.channels.push(channel);
    }

    pub(super) fn finish(self) -> Scene {
        // Built-in scenes are fixed code, so a missing camera is a bug in this
        // file that the tests catch, never a user error.
        assert!(
            self.has_camera,
            "built-in scene {} has no camera",
            self.scene.name
        );
        self.scene
    }
}
