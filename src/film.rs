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

/// Writes `frame_NNNN.exr` and `frame_NNNN.png` (temporary: replaced by the
/// full film I/O module).
pub fn write_frame(film: &Film, dir: &Path, frame: u32) -> anyhow::Result<()> {
    use exr::prelude::*;
    let path = frame_path(dir, frame, "exr");
    let (w, h) = (film.width as usize, film.height as usize);
    write_rgb_file(&path, w, h, |x, y| {
        let p = film.pixels[y * w + x];
        (p.x, p.y, p.z)
    })?;
    let mut png = image::RgbImage::new(film.width, film.height);
    for (i, px) in png.pixels_mut().enumerate() {
        let p = film.pixels[i];
        let enc = |v: f32| {
            let v = v.clamp(0.0, 1.0);
            let s = if v <= 0.0031308 {
                12.92 * v
            } else {
                1.055 * v.powf(1.0 / 2.4) - 0.055
            };
            (s * 255.0 + 0.5) as u8
        };
        *px = image::Rgb([enc(p.x), enc(p.y), enc(p.z)]);
    }
    png.save(frame_path(dir, frame, "png"))?;
    Ok(())
}
