//! Pictures of where a frame is off (`radcache compare --error-maps DIR`):
//! the figures of [`super::compare_dirs`] say how much, these say where.
//! One a frame, and one of the frames' means ([`MapWriter`]): where the
//! frames' noise is independent the mean's is lower by the square root of
//! the frames, and what stays in it is the method's bias.
//!
//! Each pixel shows the signed relative error of its luminance,
//! `e = (L_test − L_ref) / max(L_ref, DARK_FLOOR · mean L_ref)`: red where
//! the test is brighter, blue where it is darker, in full colour from
//! `±FULL_SCALE`, blended over the reference's tone-mapped luminance in
//! grey so that the scene stays recognisable. Why relative per pixel: a
//! cache's faults (a leak, a blotch, a lag) are a share of the light where
//! they are, bright or dim. Why the floor: a pixel of the reference that is
//! black, or nearly, would make any difference infinite; below a twentieth
//! of the frame's mean a pixel is judged against that.

use super::MetricsError;
use crate::film::{encode_srgb8, tone_curve, write_rgb_png, Film};
use crate::material::luminance;
use glam::DVec3;
use std::path::{Path, PathBuf};

/// The relative error shown in full colour (±25 %); smaller ones are
/// blended towards grey in proportion.
pub const FULL_SCALE: f32 = 0.25;

/// The least luminance a pixel's error is relative to, as a share of the
/// reference frame's mean luminance.
pub const DARK_FLOOR: f32 = 0.05;

/// Share of the reference's tone-mapped luminance the grey underneath
/// keeps: dim enough that a faint red or blue still shows on white walls.
const BACKDROP: f32 = 0.5;

/// The error map of `test` against `reference` (same size; the caller
/// checks it), one 8-bit sRGB pixel per pixel.
pub fn error_map(test: &Film, reference: &Film) -> image::RgbImage {
    let count = reference.pixels.len().max(1) as f64;
    let mean = reference
        .pixels
        .iter()
        .map(|&c| luminance(c) as f64)
        .sum::<f64>()
        / count;
    let floor = (DARK_FLOOR as f64 * mean) as f32;
    let bytes: Vec<u8> = test
        .pixels
        .iter()
        .zip(&reference.pixels)
        .flat_map(|(&t, &r)| {
            let (t, r) = (luminance(t), luminance(r));
            let error = (t - r) / r.max(floor);
            map_pixel(error, r)
        })
        .collect();
    image::RgbImage::from_raw(reference.width, reference.height, bytes)
        .expect("film has width × height pixels")
}

/// The colour of a pixel of relative error `error` whose reference
/// luminance is `reference`: grey at 0 (the reference's, dimmed), pure
/// red at `+FULL_SCALE` and beyond, pure blue at `−FULL_SCALE` and beyond.
/// A NaN error (a black reference frame, whose floor is 0) shows grey.
fn map_pixel(error: f32, reference: f32) -> [u8; 3] {
    let grey = encode_srgb8(BACKDROP * tone_curve(reference)) as f32;
    let strength = if error.is_nan() {
        0.0
    } else {
        (error.abs() / FULL_SCALE).min(1.0)
    };
    let towards = |full: f32| (grey + (full - grey) * strength).round() as u8;
    let (red, blue) = if error > 0.0 {
        (255.0, 0.0)
    } else {
        (0.0, 255.0)
    };
    [towards(red), towards(0.0), towards(blue)]
}

/// `DIR/error_NNNN.png`: frame `frame`'s [`error_map`].
pub fn error_map_path(dir: &Path, frame: u32) -> PathBuf {
    dir.join(format!("error_{frame:04}.png"))
}

/// `DIR/error_mean.png`: the [`error_map`] of the test frames' mean
/// against the reference frames' mean.
pub fn mean_error_map_path(dir: &Path) -> PathBuf {
    dir.join("error_mean.png")
}

/// Writes the error maps of a comparison into a folder as its frames come,
/// and the map of their means at the end.
pub struct MapWriter {
    dir: PathBuf,
    /// `None` once frames of two sizes came.
    sums: Option<Sums>,
    frames: u32,
}

/// Per pixel, the sums of the test's and the reference's radiance over
/// the frames so far (f64: hundreds of frames lose nothing), and the size
/// of the frames.
struct Sums {
    test: Vec<DVec3>,
    reference: Vec<DVec3>,
    size: (u32, u32),
}

impl Sums {
    fn add(sums: &mut [DVec3], film: &Film) {
        for (sum, p) in sums.iter_mut().zip(&film.pixels) {
            *sum += p.as_dvec3();
        }
    }

    /// The mean film of `sums` over `frames` frames.
    fn mean(&self, sums: &[DVec3], frames: u32) -> Film {
        let n = f64::from(frames);
        Film {
            width: self.size.0,
            height: self.size.1,
            pixels: sums.iter().map(|s| (*s / n).as_vec3()).collect(),
        }
    }
}

impl MapWriter {
    /// A writer into `dir`, made if need be.
    pub fn create(dir: &Path) -> Result<Self, MetricsError> {
        std::fs::create_dir_all(dir).map_err(|error| MetricsError::MapFolder {
            path: dir.to_owned(),
            error,
        })?;
        Ok(MapWriter {
            dir: dir.to_owned(),
            sums: None,
            frames: 0,
        })
    }

    /// Writes frame `number`'s map and adds it to the means.
    pub fn add(&mut self, number: u32, test: &Film, reference: &Film) -> Result<(), MetricsError> {
        let path = error_map_path(&self.dir, number);
        write_rgb_png(&error_map(test, reference), &path)?;
        let size = (reference.width, reference.height);
        if self.frames == 0 {
            let zeros = vec![DVec3::ZERO; reference.pixels.len()];
            self.sums = Some(Sums {
                test: zeros.clone(),
                reference: zeros,
                size,
            });
        }
        self.frames += 1;
        if self.sums.as_ref().is_some_and(|s| s.size != size) {
            self.sums = None;
        }
        if let Some(sums) = &mut self.sums {
            Sums::add(&mut sums.test, test);
            Sums::add(&mut sums.reference, reference);
        }
        Ok(())
    }

    /// Writes the map of the means, where more than one frame came and
    /// all were of one size; returns its path then.
    pub fn finish(self) -> Result<Option<PathBuf>, MetricsError> {
        let Some(sums) = self.sums.filter(|_| self.frames > 1) else {
            return Ok(None);
        };
        let test = sums.mean(&sums.test, self.frames);
        let reference = sums.mean(&sums.reference, self.frames);
        let path = mean_error_map_path(&self.dir);
        write_rgb_png(&error_map(&test, &reference), &path)?;
        Ok(Some(path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A 4×1 film of these grey levels.
    fn film(levels: [f32; 4]) -> Film {
        let mut f = Film::new(4, 1);
        for (p, l) in f.pixels.iter_mut().zip(levels) {
            *p = Vec3::splat(l);
        }
        f
    }

    /// Equal pixels are grey, a brighter one red, a darker one blue, in
    /// proportion to the error up to [`FULL_SCALE`].
    #[test]
    fn red_where_brighter_blue_where_darker_grey_where_equal() {
        let reference = film([0.5; 4]);
        let test = film([0.5, 0.5 * 1.25, 0.5 * 0.9, 0.5 * 3.0]);
        let map = error_map(&test, &reference);
        let px = |x: u32| map.get_pixel(x, 0).0;
        let [r, g, b] = px(0);
        assert!(r == g && g == b && r > 0, "equal: {:?}", px(0));
        assert_eq!(px(1), [255, 0, 0], "+25 % is full red");
        assert_eq!(px(3), [255, 0, 0], "+200 % stays full red");
        let [r, g, b] = px(2);
        assert!(b > g && g == r, "−10 %: {:?}", px(2));
        // 0.4 of the way from the grey to blue.
        let grey = px(0)[0] as f32;
        assert!((g as f32 - 0.6 * grey).abs() <= 1.0, "{:?}", px(2));
        assert!((b as f32 - (grey + 0.4 * (255.0 - grey))).abs() <= 1.0);
    }

    /// A black reference pixel is judged against [`DARK_FLOOR`] of the
    /// mean, not against 0: a small difference there is a small error.
    #[test]
    fn a_black_reference_pixel_is_judged_against_the_floor() {
        let reference = film([0.0, 1.0, 1.0, 1.0]);
        let mean = 0.75 * luminance(Vec3::ONE);
        let small = 0.2 * DARK_FLOOR * mean * FULL_SCALE;
        let map = error_map(&film([small, 1.0, 1.0, 1.0]), &reference);
        let [r, g, b] = map.get_pixel(0, 0).0;
        // The backdrop of a black pixel is black: the red is the error's
        // share of full red, 0.2 · 255.
        assert_eq!((g, b), (0, 0));
        assert!((r as f32 - 0.2 * 255.0).abs() <= 1.0, "{r}");
    }

    /// The map of the means is written for two frames or more of one
    /// size, not for one frame, nor where the sizes differ.
    #[test]
    fn a_mean_map_needs_frames_of_one_size() {
        let dir = tempfile::tempdir().unwrap();
        let finish = |sizes: &[u32]| {
            let mut maps = MapWriter::create(dir.path()).unwrap();
            for (n, &w) in (0..).zip(sizes) {
                let f = Film::new(w, 1);
                maps.add(n, &f, &f).unwrap();
            }
            maps.finish().unwrap()
        };
        assert_eq!(finish(&[4]), None);
        assert_eq!(finish(&[4, 2]), None);
        assert_eq!(finish(&[4, 4, 2]), None);
        assert_eq!(finish(&[4, 4]), Some(mean_error_map_path(dir.path())));
        let mean = image::open(mean_error_map_path(dir.path())).unwrap();
        assert_eq!((mean.width(), mean.height()), (4, 1));
    }

    /// A black reference frame has no scale: its map is its grey (black),
    /// not NaN colours.
    #[test]
    fn a_black_frame_maps_to_black() {
        let map = error_map(&film([0.0, 0.1, 0.0, 0.0]), &film([0.0; 4]));
        assert_eq!(map.get_pixel(0, 0).0, [0, 0, 0]);
        assert_eq!(
            map.get_pixel(1, 0).0,
            [255, 0, 0],
            "any light on black is off"
        );
    }
}
