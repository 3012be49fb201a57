//! Image metrics: RMSE, relative RMSE, block bias and flicker, and
//! [`compare_dirs`] behind `radcache compare` (DESIGN.md "Measuring" and
//! "Command line").
//!
//! All figures are over linear radiance and all three channels: a pixel
//! contributes three values. "Mean radiance" is [`Film::mean`], the mean over
//! pixels and channels. Differences and sums are taken in f64 so that a 4K
//! sequence does not lose the small differences being measured, and so that
//! huge (finite) values do not overflow to infinity.
//!
//! The per-image functions take two films of the same size and panic
//! otherwise; [`compare_dirs`] checks sizes first and reports the files.

mod compare;
mod error_map;

pub use compare::{
    compare_dirs, compare_dirs_with, light_mask_path, list_frames, read_light_mask,
    write_light_mask, CompareReport, FrameReport,
};
pub use error_map::{
    error_map, error_map_path, mean_error_map_path, MapWriter, DARK_FLOOR, FULL_SCALE,
};

use crate::film::{Film, FilmError};
use glam::{DVec3, Vec3};
use std::path::PathBuf;

/// Side of the square pixel blocks of [`block_bias`] (DESIGN.md "Measuring":
/// "the bias on 16×16-pixel block means").
pub const BLOCK: u32 = 16;

/// Errors of [`compare_dirs`]; each names the folder or files involved.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    // `error`, not `source`: thiserror makes a field named `source` the
    // cause, and `{:#}` printed the OS error twice.
    #[error("cannot read folder {}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("no frame_NNNN.exr files in reference folder {}", dir.display())]
    NoFrames { dir: PathBuf },
    #[error(
        "{} and {} both name frame {frame}: remove or rename one of them",
        a.display(), b.display()
    )]
    AmbiguousFrame { frame: u32, a: PathBuf, b: PathBuf },
    #[error("{} is missing (the reference has {})", path.display(), reference.display())]
    MissingFrame { path: PathBuf, reference: PathBuf },
    #[error(
        "sizes differ: {} is {}×{} but {} is {}×{}",
        a.display(), a_size.0, a_size.1, b.display(), b_size.0, b_size.1
    )]
    SizeMismatch {
        a: PathBuf,
        a_size: (u32, u32),
        b: PathBuf,
        b_size: (u32, u32),
    },
    #[error("{}: pixel ({x}, {y}) is {value}: every metric would be NaN or infinite", path.display())]
    NonFinite {
        path: PathBuf,
        x: u32,
        y: u32,
        value: String,
    },
    #[error("{}: pixel ({x}, {y}) has {channel} = {value}: radiance cannot be negative", path.display())]
    Negative {
        path: PathBuf,
        x: u32,
        y: u32,
        channel: char,
        value: f32,
    },
    #[error("{}: not a light mask of {}×{} pixels: {detail}", path.display(), size.0, size.1)]
    Mask {
        path: PathBuf,
        size: (u32, u32),
        detail: String,
    },
    #[error("cannot make the error maps' folder {}: {error}", path.display())]
    MapFolder {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error(transparent)]
    Film(#[from] FilmError),
}

// ---------------------------------------------------------------- per image

fn assert_same_size(test: &Film, reference: &Film) {
    assert_eq!(
        (test.width, test.height),
        (reference.width, reference.height),
        "metrics need images of the same size"
    );
}

/// Sum of the squares of the channels of `a − b`, in f64: the difference
/// of two finite f32 values may not be one.
fn sum_sq_diff(a: Vec3, b: Vec3) -> f64 {
    let d = a.as_dvec3() - b.as_dvec3();
    d.dot(d)
}

/// Mean over pixels and channels of (I − R)².
pub fn mse(test: &Film, reference: &Film) -> f64 {
    assert_same_size(test, reference);
    let sum: f64 = test
        .pixels
        .iter()
        .zip(&reference.pixels)
        .map(|(i, r)| sum_sq_diff(*i, *r))
        .sum();
    sum / (3 * test.pixels.len()).max(1) as f64
}

/// RMSE (DESIGN.md "Measuring", accuracy): √(mean over pixels and channels of
/// (I − R)²).
pub fn rmse(test: &Film, reference: &Film) -> f64 {
    mse(test, reference).sqrt()
}

/// Relative RMSE: [`rmse`] ÷ mean(R), so scenes of different brightness
/// compare. Infinite or NaN for an all-black reference.
pub fn rel_rmse(test: &Film, reference: &Film) -> f64 {
    rmse(test, reference) / reference.mean()
}

/// Sums over the kept pixels (`keep[pixel]`) of one or more frames: their
/// relative RMSE is the RMSE over them ÷ the reference's mean over them.
#[derive(Clone, Copy, Debug, Default)]
struct MaskedSums {
    sq_err: f64,
    ref_sum: f64,
    values: usize,
    /// [`flicker_sum`] over the pixels kept in both frames of each pair.
    flicker_sq: f64,
    flicker_values: usize,
}

impl MaskedSums {
    fn of(test: &Film, reference: &Film, keep: &[bool]) -> Self {
        assert_same_size(test, reference);
        assert_eq!(
            keep.len(),
            reference.pixels.len(),
            "a mask of the image's size"
        );
        let mut sums = MaskedSums::default();
        for k in (0..keep.len()).filter(|&k| keep[k]) {
            let r = reference.pixels[k].as_dvec3();
            sums.sq_err += sum_sq_diff(test.pixels[k], reference.pixels[k]);
            sums.ref_sum += r.x + r.y + r.z;
            sums.values += 3;
        }
        sums
    }

    fn add(&mut self, other: MaskedSums) {
        self.sq_err += other.sq_err;
        self.ref_sum += other.ref_sum;
        self.values += other.values;
        self.flicker_sq += other.flicker_sq;
        self.flicker_values += other.flicker_values;
    }

    fn ref_mean(&self) -> f64 {
        self.ref_sum / self.values as f64
    }

    fn flicker(&self) -> Option<f64> {
        (self.values > 0 && self.flicker_values > 0)
            .then(|| (self.flicker_sq / self.flicker_values as f64).sqrt() / self.ref_mean())
    }

    fn rel_rmse(&self) -> Option<f64> {
        (self.values > 0).then(|| (self.sq_err / self.values as f64).sqrt() / self.ref_mean())
    }
}

/// Per-channel means of the `block`×`block` tiles, row-major. Tiles on the
/// right and bottom edges may be partial; each is averaged over its own
/// pixel count.
fn block_means(film: &Film, block: u32) -> Vec<[f64; 3]> {
    let block = block.max(1);
    let (bw, bh) = (film.width.div_ceil(block), film.height.div_ceil(block));
    let mut sums = vec![([0.0_f64; 3], 0_u32); (bw * bh) as usize];
    for y in 0..film.height {
        for x in 0..film.width {
            let (sum, count) = &mut sums[((y / block) * bw + x / block) as usize];
            let p = film.get(x, y).as_dvec3();
            for (s, v) in sum.iter_mut().zip(p.to_array()) {
                *s += v;
            }
            *count += 1;
        }
    }
    sums.into_iter()
        .map(|(s, n)| s.map(|v| v / f64::from(n)))
        .collect()
}

/// Mean over blocks and channels of (mean_block(I) − mean_block(R))²; every
/// block counts once, whatever its pixel count.
pub fn block_mse(test: &Film, reference: &Film, block: u32) -> f64 {
    assert_same_size(test, reference);
    let (bi, br) = (block_means(test, block), block_means(reference, block));
    let sum: f64 = bi
        .iter()
        .zip(&br)
        .flat_map(|(i, r)| i.iter().zip(r).map(|(a, b)| (a - b) * (a - b)))
        .sum();
    sum / (3 * bi.len()).max(1) as f64
}

/// Block bias (DESIGN.md "Measuring"): the RMS over `block`×`block` tiles and
/// channels of (mean_block(I) − mean_block(R)), ÷ mean(R). Zero-mean noise
/// averages out inside a tile, so this shows bias that the all-pixel RMSE,
/// dominated by the edge pixels of a directly seen light, hides.
pub fn block_bias(test: &Film, reference: &Film, block: u32) -> f64 {
    block_mse(test, reference, block).sqrt() / reference.mean()
}

/// Sum over pixels and channels of ((I₁ − I₀) − (R₁ − R₀))², and the count of
/// values summed.
fn flicker_sum(i0: &Film, i1: &Film, r0: &Film, r1: &Film) -> (f64, usize) {
    flicker_sum_over(i0, i1, r0, r1, |_| true)
}

/// [`flicker_sum`] over the pixels `k` where `keep(k)`.
fn flicker_sum_over(
    i0: &Film,
    i1: &Film,
    r0: &Film,
    r1: &Film,
    keep: impl Fn(usize) -> bool,
) -> (f64, usize) {
    for f in [i1, r0, r1] {
        assert_same_size(i0, f);
    }
    let (mut sum, mut values) = (0.0, 0);
    for k in (0..i0.pixels.len()).filter(|&k| keep(k)) {
        let d = |f: &Film| f.pixels[k].as_dvec3();
        let e: DVec3 = (d(i1) - d(i0)) - (d(r1) - d(r0));
        sum += e.dot(e);
        values += 3;
    }
    (sum, values)
}

/// Flicker (DESIGN.md "Measuring", temporal stability): the RMS over pixels,
/// channels and consecutive frame pairs of (I(t+1) − I(t)) − (R(t+1) − R(t)),
/// ÷ the reference's mean radiance over all its frames. Subtracting the
/// reference's own change leaves only the method's frame-to-frame noise and
/// lag. `test[k]` and `reference[k]` are frame k of consecutive frames;
/// `None` with fewer than two frames.
pub fn flicker(test: &[Film], reference: &[Film]) -> Option<f64> {
    assert_eq!(
        test.len(),
        reference.len(),
        "flicker needs as many test as reference frames"
    );
    if reference.len() < 2 {
        return None;
    }
    let (mut sum, mut count) = (0.0, 0);
    for k in 0..reference.len() - 1 {
        let (s, n) = flicker_sum(&test[k], &test[k + 1], &reference[k], &reference[k + 1]);
        sum += s;
        count += n;
    }
    Some((sum / count as f64).sqrt() / sequence_mean(reference))
}

/// Mean over every pixel and channel of every frame.
fn sequence_mean(frames: &[Film]) -> f64 {
    let sum: f64 = frames
        .iter()
        .map(|f| f.mean() * f.pixels.len() as f64)
        .sum();
    sum / frames.iter().map(|f| f.pixels.len()).sum::<usize>().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn constant(w: u32, h: u32, v: f32) -> Film {
        Film {
            width: w,
            height: h,
            pixels: vec![Vec3::splat(v); (w * h) as usize],
        }
    }

    /// A smooth, non-constant image so that tests don't pass by symmetry.
    fn ramp(w: u32, h: u32) -> Film {
        let mut f = Film::new(w, h);
        for y in 0..h {
            for x in 0..w {
                f.pixels[(y * w + x) as usize] =
                    Vec3::new(0.2 + x as f32 / w as f32, 0.5, 0.1 + y as f32 / h as f32);
            }
        }
        f
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-5 * b.abs().max(1.0)
    }

    #[test]
    fn rmse_of_identical_images_is_zero() {
        let f = ramp(40, 30);
        assert_eq!(rmse(&f, &f), 0.0);
        assert_eq!(block_bias(&f, &f, BLOCK), 0.0);
    }

    #[test]
    fn rmse_of_constant_offset_is_the_offset() {
        let r = ramp(40, 30);
        let mut t = r.clone();
        t.pixels.iter_mut().for_each(|p| *p += Vec3::splat(0.25));
        assert!(close(rmse(&t, &r), 0.25), "{}", rmse(&t, &r));
        // A constant offset is all bias: the block bias sees it in full.
        assert!(close(block_bias(&t, &r, BLOCK) * r.mean(), 0.25));
        // One channel only: the mean over three channels is c²/3.
        let mut t1 = r.clone();
        t1.pixels.iter_mut().for_each(|p| p.x += 0.3);
        assert!(close(rmse(&t1, &r), 0.3 / 3f64.sqrt()));
    }

    #[test]
    fn rel_rmse_divides_by_reference_mean() {
        let r = constant(8, 8, 2.0);
        let t = constant(8, 8, 2.5);
        assert!(close(rel_rmse(&t, &r), 0.25));
        // Scaling both images leaves the relative figure unchanged.
        let (r10, t10) = (constant(8, 8, 20.0), constant(8, 8, 25.0));
        assert!(close(rel_rmse(&t10, &r10), rel_rmse(&t, &r)));
        assert!(close(rmse(&t10, &r10), 10.0 * rmse(&t, &r)));
    }

    #[test]
    fn block_bias_ignores_zero_mean_noise_in_blocks() {
        // 40×24: partial blocks on the right (8 px) and bottom (8 px) edges,
        // all of even size, so a checkerboard averages to 0 in every block.
        let r = ramp(40, 24);
        let e = 0.05_f32;
        let mut t = r.clone();
        for y in 0..24 {
            for x in 0..40 {
                let s = if (x + y) % 2 == 0 { e } else { -e };
                t.pixels[(y * 40 + x) as usize] += Vec3::splat(s);
            }
        }
        assert!(close(rmse(&t, &r), f64::from(e)));
        assert!(
            block_bias(&t, &r, BLOCK) < 1e-6,
            "{}",
            block_bias(&t, &r, BLOCK)
        );
    }

    #[test]
    fn block_bias_weights_partial_blocks_as_blocks() {
        // 17×16: one full block and a 1×16 column. Offset only the column:
        // its block mean moves by c, the full block's by 0 → RMS c/√2.
        let r = constant(17, 16, 1.0);
        let mut t = r.clone();
        for y in 0..16 {
            t.pixels[(y * 17 + 16) as usize] += Vec3::splat(0.4);
        }
        assert!(close(block_bias(&t, &r, BLOCK), 0.4 / 2f64.sqrt()));
    }

    #[test]
    fn flicker_ignores_constant_bias() {
        let refs: Vec<Film> = (0..4)
            .map(|k| constant(10, 10, 1.0 + k as f32 * 0.1))
            .collect();
        let tests: Vec<Film> = refs
            .iter()
            .map(|f| {
                let mut t = f.clone();
                t.pixels
                    .iter_mut()
                    .for_each(|p| *p += Vec3::new(0.5, -0.25, 0.125));
                t
            })
            .collect();
        assert!(flicker(&tests, &refs).unwrap() < 1e-7);
    }

    #[test]
    fn flicker_of_alternating_error() {
        // I(t) = R(t) + e·(−1)^t: every pair differs by ±2e → flicker 2e/mean(R).
        let e = 0.125_f32;
        let refs: Vec<Film> = (0..5)
            .map(|k| constant(6, 4, 1.0 + k as f32 * 0.25))
            .collect();
        let tests: Vec<Film> = refs
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let s = if k % 2 == 0 { e } else { -e };
                let mut t = f.clone();
                t.pixels.iter_mut().for_each(|p| *p += Vec3::splat(s));
                t
            })
            .collect();
        let mean = (1.0 + 1.25 + 1.5 + 1.75 + 2.0) / 5.0;
        let got = flicker(&tests, &refs).unwrap();
        assert!(close(got, 2.0 * f64::from(e) / mean), "{got}");
    }

    /// (I₁ − I₀) − (R₁ − R₀) of finite values can exceed f32: the
    /// differences are taken in f64. One channel only, so that the
    /// reference's mean stays within f32 too.
    #[test]
    fn flicker_of_opposite_huge_changes_is_finite() {
        let one = |v: f32| Film {
            width: 2,
            height: 2,
            pixels: vec![Vec3::new(v, 0.0, 0.0); 4],
        };
        let refs = [one(3e38), one(0.0)];
        let tests = [one(0.0), one(3e38)];
        // Each pixel is off by 2·3e38 in one of three channels; the
        // reference's mean over both frames is 3e38 / 6.
        let got = flicker(&tests, &refs).unwrap();
        assert!(close(got, 12.0 / 3f64.sqrt()), "{got}");
    }

    #[test]
    fn flicker_needs_two_frames() {
        let f = ramp(4, 4);
        assert_eq!(
            flicker(std::slice::from_ref(&f), std::slice::from_ref(&f)),
            None
        );
    }
}
