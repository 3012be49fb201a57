//! Frames as linear RGB f32 images, and their files: `frame_NNNN.exr` (linear
//! radiance, RGB f32) and `frame_NNNN.png` (tone-mapped sRGB preview).

use glam::Vec3;
use std::path::{Path, PathBuf};

/// A linear-radiance RGB image, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl Film {
    pub fn new(width: u32, height: u32) -> Self {
        Film {
            width,
            height,
            pixels: vec![Vec3::ZERO; width as usize * height as usize],
        }
    }

    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Mean over pixels and channels.
    pub fn mean(&self) -> f64 {
        let sum: f64 = self.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum();
        sum / (3.0 * self.pixels.len().max(1) as f64)
    }
}

/// `DIR/frame_NNNN.ext`.
pub fn frame_path(dir: &Path, frame: u32, ext: &str) -> PathBuf {
    dir.join(format!("frame_{frame:04}.{ext}"))
}
