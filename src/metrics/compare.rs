//! Folders of frames compared ([`compare_dirs`], behind `radcache compare`):
//! frames matched by number, checked, measured one pair at a time, and the
//! report's table and JSON.

use super::{
    block_mse, flicker_sum, flicker_sum_over, mse, MapWriter, MaskedSums, MetricsError, BLOCK,
};
use crate::film::{read_exr, Film};
use glam::Vec3;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The figures for one frame.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameReport {
    pub frame: u32,
    pub rmse: f64,
    pub rel_rmse: f64,
    pub block_bias: f64,
    /// [`flicker`](super::flicker) of the one pair from the frame before to this one, ÷
    /// the reference's mean over all frames as the sequence's figure is
    /// (the sequence's squared flicker is the mean of its pairs' when the
    /// frames are of one size): where a method changes the whole image at
    /// once (records expiring together, a ghost leaving) it stands out.
    /// `None` for a frame whose number − 1 is not among those compared.
    pub flicker: Option<f64>,
}

/// The result of comparing a test folder with a reference folder. Serialises
/// to `{"frames":N,"rmse":…,"rel_rmse":…,"block_bias":…,"flicker":…,
/// "rel_rmse_surfaces":…,"flicker_surfaces":…,"per_frame":[…]}`; `flicker`
/// is `null` without consecutive frames, the `_surfaces` figures without
/// light masks, and every relative figure (an infinite or NaN `f64`) where
/// the reference's mean radiance it divides by is 0 (all black).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CompareReport {
    pub frames: usize,
    /// √(mean over frames of the per-frame MSE).
    pub rmse: f64,
    /// `rmse` ÷ the reference's mean radiance over all frames.
    pub rel_rmse: f64,
    /// √(mean over frames of the per-frame block MSE) ÷ the same mean.
    pub block_bias: f64,
    /// Relative RMSE over the pixels that see no light source directly (nor
    /// border one), all frames together; `None` unless every reference frame
    /// has a light mask ([`light_mask_path`]).
    pub rel_rmse_surfaces: Option<f64>,
    pub flicker: Option<f64>,
    /// [`Self::flicker`] over the pixels that see no light in either frame
    /// of a pair, ÷ the reference's mean over the pixels that see none;
    /// `None` without light masks or consecutive frames.
    pub flicker_surfaces: Option<f64>,
    pub per_frame: Vec<FrameReport>,
}

/// `frame_NNNN.exr` files of `dir` as (frame number, path), sorted by number;
/// the name in any case (`Frame_0002.EXR`, as a copy from a system whose
/// names ignore case may spell it). Other files (`frame_NNNN.png`,
/// `seed1_frame_0000.exr`, …) are ignored.
/// The number may have any count of digits (the renderer writes at least
/// four: `frame_0012.exr`, `frame_12345.exr`), but two files that name the
/// same frame (`frame_0001.exr` and `frame_00001.exr`, or `FRAME_0001.EXR`) are an error naming
/// both: which of them is the frame is anyone's guess.
pub fn list_frames(dir: &Path) -> Result<Vec<(u32, PathBuf)>, MetricsError> {
    let io_err = |error| MetricsError::Io {
        path: dir.to_owned(),
        error,
    };
    let mut frames = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io_err)? {
        let entry = entry.map_err(io_err)?;
        if let Some(n) = entry.file_name().to_str().and_then(frame_number) {
            frames.push((n, entry.path()));
        }
    }
    frames.sort();
    if let Some(pair) = frames.windows(2).find(|pair| pair[0].0 == pair[1].0) {
        return Err(MetricsError::AmbiguousFrame {
            frame: pair[0].0,
            a: pair[0].1.clone(),
            b: pair[1].1.clone(),
        });
    }
    Ok(frames)
}

/// The light mask of frame `frame` in a reference folder:
/// `seen_lights_NNNN.png`, white where a pixel sees a light source directly
/// or borders one that does. [`compare_dirs`] leaves those pixels out of
/// [`CompareReport::rel_rmse_surfaces`]: the handful of pixels on the rim of
/// a directly seen light can carry much of an all-pixel RMSE at low sample
/// counts (DESIGN.md "Measuring"; `method::pixels` post-stratifies them by
/// their coverage to keep that down), and that anti-aliasing noise is the
/// same for every method, so it hides how well a method computes the
/// lighting of surfaces.
pub fn light_mask_path(dir: &Path, frame: u32) -> PathBuf {
    dir.join(format!("seen_lights_{frame:04}.png"))
}

/// Writes a light mask (row-major, `width`×`height`) as an 8-bit grey PNG.
pub fn write_light_mask(
    path: &Path,
    width: u32,
    height: u32,
    mask: &[bool],
) -> Result<(), MetricsError> {
    let size = (width, height);
    let bad = |detail: String| MetricsError::Mask {
        path: path.to_owned(),
        size,
        detail,
    };
    let pixels = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
    let image = image::GrayImage::from_raw(width, height, pixels)
        .ok_or_else(|| bad(format!("{} values given", mask.len())))?;
    image.save(path).map_err(|e| bad(e.to_string()))
}

/// Reads the light mask at `path` for an image of `size`; `Ok(None)` when
/// there is no such file.
pub fn read_light_mask(path: &Path, size: (u32, u32)) -> Result<Option<Vec<bool>>, MetricsError> {
    let bad = |detail: String| MetricsError::Mask {
        path: path.to_owned(),
        size,
        detail,
    };
    // Asked before the file is opened: opening a FIFO blocks.
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(bad(e.to_string())),
        Ok(m) => crate::regular_file::check(&m).map_err(|e| bad(e.to_string()))?,
    }
    let image = image::open(path)
        .map_err(|e| bad(e.to_string()))?
        .to_luma8();
    if image.dimensions() != size {
        let (w, h) = image.dimensions();
        return Err(bad(format!("it is {w}×{h}")));
    }
    Ok(Some(image.pixels().map(|p| p.0[0] >= 128).collect()))
}

/// `frame_0012.exr` (in any case) → 12.
fn frame_number(name: &str) -> Option<u32> {
    let name = name.to_ascii_lowercase();
    let digits = name.strip_prefix("frame_")?.strip_suffix(".exr")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

fn size(f: &Film) -> (u32, u32) {
    (f.width, f.height)
}

fn check_size(a: &Path, fa: &Film, b: &Path, fb: &Film) -> Result<(), MetricsError> {
    if size(fa) == size(fb) {
        return Ok(());
    }
    Err(MetricsError::SizeMismatch {
        a: a.to_owned(),
        a_size: size(fa),
        b: b.to_owned(),
        b_size: size(fb),
    })
}

/// One frame read from both folders.
struct FramePair {
    number: u32,
    ref_path: PathBuf,
    test: Film,
    reference: Film,
    /// Pixels to keep for the surface error (`None`: no light mask).
    surfaces: Option<Vec<bool>>,
    /// Where the light mask of the reference frame is, or would be.
    mask_path: PathBuf,
}

/// The first pixel of `film` with a NaN, infinite or negative channel is an
/// error naming the file and the pixel: a NaN or infinity would make every
/// metric NaN (or infinite) without saying where it came from, and a
/// negative value is no radiance (a negative reference made the relative
/// figures negative). −0.0 is not negative.
fn check_pixels(path: &Path, film: &Film) -> Result<(), MetricsError> {
    let bad = |p: &Vec3| !p.is_finite() || p.cmplt(Vec3::ZERO).any();
    let Some(i) = film.pixels.iter().position(bad) else {
        return Ok(());
    };
    let (x, y) = (i as u32 % film.width, i as u32 / film.width);
    let p = film.pixels[i];
    if !p.is_finite() {
        return Err(MetricsError::NonFinite {
            path: path.to_path_buf(),
            x,
            y,
            value: p.to_string(),
        });
    }
    let (channel, value) = ['R', 'G', 'B']
        .into_iter()
        .zip(p.to_array())
        .find(|&(_, v)| v < 0.0)
        .expect("a negative channel");
    Err(MetricsError::Negative {
        path: path.to_path_buf(),
        x,
        y,
        channel,
        value,
    })
}

/// Reads frame `number` of the reference (`ref_path`) and of the test
/// folder (`test_path`, the file of `test_dir` that [`list_frames`] gave
/// that number; `None`: there is none).
fn read_pair(
    number: u32,
    ref_path: PathBuf,
    test_path: Option<PathBuf>,
    test_dir: &Path,
) -> Result<FramePair, MetricsError> {
    // Only a frame that is not listed is missing; one that is there but is
    // no regular file (a directory, FIFO, link to a device) is
    // [`read_exr`]'s error, which says so without opening it.
    let Some(test_path) = test_path else {
        return Err(MetricsError::MissingFrame {
            path: test_dir.join(ref_path.file_name().expect("listed files have names")),
            reference: ref_path,
        });
    };
    let reference = read_exr(&ref_path)?;
    let test = read_exr(&test_path)?;
    check_size(&test_path, &test, &ref_path, &reference)?;
    check_pixels(&ref_path, &reference)?;
    check_pixels(&test_path, &test)?;
    let dir = ref_path.parent().unwrap_or(Path::new("."));
    let mask_path = light_mask_path(dir, number);
    let lights = read_light_mask(&mask_path, size(&reference))?;
    let surfaces = lights.map(|m| m.into_iter().map(|light| !light).collect());
    Ok(FramePair {
        number,
        ref_path,
        test,
        reference,
        surfaces,
        mask_path,
    })
}

/// Running sums over the sequence; frames are read one at a time so a long
/// high-resolution sequence never sits in memory whole.
#[derive(Default)]
struct Totals {
    mse: f64,
    block_mse: f64,
    ref_sum: f64,
    ref_values: usize,
    flicker_sum: f64,
    flicker_values: usize,
    /// Sums over the pixels that see no light; `None` once a frame has no
    /// light mask.
    surfaces: Option<MaskedSums>,
    /// Whether any reference frame has a light mask, and the mask path of
    /// the first that has none: where some have one, [`Self::mask_note`]
    /// says why the `_surfaces` figures are missing.
    any_mask: bool,
    first_without_mask: Option<PathBuf>,
    /// The reference frames whose mean radiance is 0 (all black): their
    /// relative figures are undefined, and [`Self::black_warning`] says so.
    black_frames: Vec<u32>,
    per_frame: Vec<FrameReport>,
    /// For each of `per_frame`, the [`flicker_sum`] of the pair that ends
    /// at it, where the frame before it was compared.
    pair_flicker: Vec<Option<(f64, usize)>>,
}

impl Totals {
    fn add_frame(&mut self, f: &FramePair) {
        let (mse, block_mse) = (
            mse(&f.test, &f.reference),
            block_mse(&f.test, &f.reference, BLOCK),
        );
        let mean = f.reference.mean();
        if mean == 0.0 {
            self.black_frames.push(f.number);
        }
        let first = self.per_frame.is_empty();
        if f.surfaces.is_some() {
            self.any_mask = true;
        } else if self.first_without_mask.is_none() {
            self.first_without_mask = Some(f.mask_path.clone());
        }
        self.surfaces = match (&f.surfaces, self.surfaces) {
            (Some(keep), Some(mut sums)) => {
                sums.add(MaskedSums::of(&f.test, &f.reference, keep));
                Some(sums)
            }
            (Some(keep), None) if first => Some(MaskedSums::of(&f.test, &f.reference, keep)),
            _ => None,
        };
        self.mse += mse;
        self.block_mse += block_mse;
        self.ref_sum += mean * (3 * f.reference.pixels.len()) as f64;
        self.ref_values += 3 * f.reference.pixels.len();
        self.per_frame.push(FrameReport {
            frame: f.number,
            rmse: mse.sqrt(),
            rel_rmse: mse.sqrt() / mean,
            block_bias: block_mse.sqrt() / mean,
            flicker: None, // Known once the sequence's mean is ([`Self::report`]).
        });
        self.pair_flicker.push(None);
    }

    /// Counts the pair only when the frame numbers are consecutive: the
    /// definition is about I(t+1) − I(t), not about any two listed frames.
    fn add_pair(&mut self, prev: &FramePair, next: &FramePair) -> Result<(), MetricsError> {
        if prev.number.checked_add(1) != Some(next.number) {
            return Ok(());
        }
        check_size(
            &prev.ref_path,
            &prev.reference,
            &next.ref_path,
            &next.reference,
        )?;
        let (s, n) = flicker_sum(&prev.test, &next.test, &prev.reference, &next.reference);
        self.flicker_sum += s;
        self.flicker_values += n;
        // `next` is the frame added last.
        if let Some(last) = self.pair_flicker.last_mut() {
            *last = Some((s, n));
        }
        if let (Some(sums), Some(a), Some(b)) = (&mut self.surfaces, &prev.surfaces, &next.surfaces)
        {
            let (s, n) = flicker_sum_over(
                &prev.test,
                &next.test,
                &prev.reference,
                &next.reference,
                |k| a[k] && b[k],
            );
            sums.flicker_sq += s;
            sums.flicker_values += n;
        }
        Ok(())
    }

    /// The note for stderr when some reference frames have a light mask
    /// and others not: the `_surfaces` figures need one for every frame,
    /// and would otherwise be `null` without a word.
    fn mask_note(&self) -> Option<String> {
        let missing = self.first_without_mask.as_ref().filter(|_| self.any_mask)?;
        Some(format!(
            "note: {} is missing: rel_rmse_surfaces and flicker_surfaces need a light mask \
             (seen_lights_NNNN.png) for every reference frame, so they are left out",
            missing.display()
        ))
    }

    /// The warning for stderr where the reference has a mean radiance of 0
    /// (all black; pixels are never negative): the relative figures divide
    /// by it, so they are undefined (`inf` or `NaN` in the table, `null` in
    /// JSON) rather than large. Where only some frames are black, the
    /// figures over all frames stand and the warning names those frames;
    /// where the reference is black only outside its seen lights, it names
    /// the `_surfaces` figures.
    fn black_warning(&self) -> Option<String> {
        const UNDEFINED: &str = "undefined (inf or NaN in the table, null in --json)";
        let black = &self.black_frames;
        if !black.is_empty() && black.len() == self.per_frame.len() {
            let surfaces = match self.surfaces {
                Some(_) => ", rel_rmse_surfaces, flicker_surfaces",
                None => "",
            };
            return Some(format!(
                "warning: the reference's mean radiance is 0 (all black): relative figures \
                 (rel_rmse, block_bias, flicker{surfaces}) are {UNDEFINED}; rmse is absolute"
            ));
        }
        if let Some(&first) = black.first() {
            const SHOWN: usize = 5;
            let named = black[..black.len().min(SHOWN)]
                .iter()
                .map(|n| format!("{n:04}"))
                .collect::<Vec<_>>();
            let frames = match (black.len(), &named[..]) {
                (1, _) => format!("frame {first:04} has"),
                (n, [most @ .., last]) if n <= SHOWN => {
                    format!("frames {} and {last} have", most.join(", "))
                }
                (n, _) => format!("frames {} and {} more have", named.join(", "), n - SHOWN),
            };
            let its = if black.len() == 1 { "its" } else { "their" };
            return Some(format!(
                "warning: reference {frames} mean radiance 0 (all black): {its} rel_rmse and \
                 block_bias are {UNDEFINED}; the figures over all frames are not"
            ));
        }
        let surfaces = self.surfaces.filter(|s| s.values > 0)?;
        (surfaces.ref_sum == 0.0).then(|| {
            format!(
                "warning: the reference's mean radiance outside its directly seen lights is 0 \
                 (black): rel_rmse_surfaces and flicker_surfaces are {UNDEFINED}"
            )
        })
    }

    fn report(mut self) -> CompareReport {
        let frames = self.per_frame.len();
        let mean = self.ref_sum / self.ref_values.max(1) as f64;
        for (f, pair) in self.per_frame.iter_mut().zip(&self.pair_flicker) {
            f.flicker = pair.map(|(s, n)| (s / n.max(1) as f64).sqrt() / mean);
        }
        let rmse = (self.mse / frames as f64).sqrt();
        let block = (self.block_mse / frames as f64).sqrt();
        let flicker = (self.flicker_values > 0)
            .then(|| (self.flicker_sum / self.flicker_values as f64).sqrt() / mean);
        CompareReport {
            frames,
            rmse,
            rel_rmse: rmse / mean,
            block_bias: block / mean,
            rel_rmse_surfaces: self.surfaces.and_then(|s| s.rel_rmse()),
            flicker,
            flicker_surfaces: self.surfaces.and_then(|s| s.flicker()),
            per_frame: self.per_frame,
        }
    }
}

/// Compares every `frame_NNNN.exr` of `reference_dir` with the file of
/// `test_dir` of the same frame number (`radcache compare REF_DIR
/// TEST_DIR`). Frames only in `test_dir` are ignored; a reference frame
/// missing from `test_dir`, or of another size, or a NaN, infinite or
/// negative pixel, or two files of one folder that name the same frame
/// ([`list_frames`]), is an error. Flicker uses the pairs whose numbers
/// differ by one. Where only some reference frames have light masks, a
/// note on stderr names the first frame's mask that is missing; where the
/// reference is black, a warning says which relative figures are undefined
/// (`inf` or `NaN`, `null` in JSON).
pub fn compare_dirs(reference_dir: &Path, test_dir: &Path) -> Result<CompareReport, MetricsError> {
    compare_dirs_with(reference_dir, test_dir, None)
}

/// [`compare_dirs`], writing with `error_maps` the [`error_map()`](super::error_map()) of each
/// frame to `DIR/error_NNNN.png` (the folder made if need be) as the
/// frame is compared, and that of the frames' means to
/// `DIR/error_mean.png` ([`MapWriter`]).
pub fn compare_dirs_with(
    reference_dir: &Path,
    test_dir: &Path,
    error_maps: Option<&Path>,
) -> Result<CompareReport, MetricsError> {
    let mut maps = error_maps.map(MapWriter::create).transpose()?;
    let frames = list_frames(reference_dir)?;
    if frames.is_empty() {
        return Err(MetricsError::NoFrames {
            dir: reference_dir.to_owned(),
        });
    }
    let mut tests: std::collections::BTreeMap<u32, PathBuf> =
        list_frames(test_dir)?.into_iter().collect();
    let mut totals = Totals::default();
    let mut prev: Option<FramePair> = None;
    for (number, ref_path) in frames {
        let pair = read_pair(number, ref_path, tests.remove(&number), test_dir)?;
        totals.add_frame(&pair);
        if let Some(maps) = &mut maps {
            maps.add(number, &pair.test, &pair.reference)?;
        }
        if let Some(prev) = &prev {
            totals.add_pair(prev, &pair)?;
        }
        prev = Some(pair);
    }
    if let Some(maps) = maps {
        maps.finish()?;
    }
    // stderr: stdout may be `--json`.
    for note in [totals.black_warning(), totals.mask_note()]
        .into_iter()
        .flatten()
    {
        eprintln!("{note}");
    }
    Ok(totals.report())
}

impl CompareReport {
    /// A table for people: one line per frame, with the flicker of the pair
    /// that ends at it, then the overall line with the sequence's flicker
    /// (`-` when there are no consecutive frames).
    pub fn to_text(&self) -> String {
        let mut out = format!(
            "{:>6} {:>12} {:>12} {:>12} {:>12}\n",
            "frame", "rmse", "rel_rmse", "block_bias", "flicker"
        );
        for f in &self.per_frame {
            let _ = writeln!(
                out,
                "{:>6} {:>12.6} {:>12.6} {:>12.6} {:>12}",
                format!("{:04}", f.frame),
                f.rmse,
                f.rel_rmse,
                f.block_bias,
                f.flicker.map_or(String::new(), |v| format!("{v:.6}"))
            );
        }
        let flicker = self.flicker.map_or("-".to_string(), |v| format!("{v:.6}"));
        let _ = writeln!(
            out,
            "{:>6} {:>12.6} {:>12.6} {:>12.6} {:>12}  ({} frames)",
            "all", self.rmse, self.rel_rmse, self.block_bias, flicker, self.frames
        );
        if let Some(s) = self.rel_rmse_surfaces {
            let flicker = self
                .flicker_surfaces
                .map_or("-".to_string(), |v| format!("{v:.6}"));
            let _ = writeln!(
                out,
                "without the pixels at directly seen lights: rel_rmse {s:.6}, flicker {flicker}"
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::tests::constant;

    #[test]
    fn frame_numbers() {
        assert_eq!(frame_number("frame_0012.exr"), Some(12));
        assert_eq!(frame_number("frame_12345.exr"), Some(12345));
        assert_eq!(frame_number("Frame_0002.EXR"), Some(2));
        assert_eq!(frame_number("frame_0012.png"), None);
        assert_eq!(frame_number("seed1_frame_0000.exr"), None);
        assert_eq!(frame_number("frame_.exr"), None);
        assert_eq!(frame_number("frame_-1.exr"), None);
    }

    /// [`Totals::black_warning`] of `frames` (number, reference) compared
    /// with a test of 0.5 everywhere, with `lights` as every frame's mask.
    fn black_warning_of(frames: &[(u32, Film)], lights: Option<&[bool]>) -> Option<String> {
        let mut totals = Totals::default();
        for (number, reference) in frames {
            let pair = FramePair {
                number: *number,
                ref_path: PathBuf::from(format!("frame_{number:04}.exr")),
                test: constant(reference.width, reference.height, 0.5),
                reference: reference.clone(),
                surfaces: lights.map(|l| l.iter().map(|light| !light).collect()),
                mask_path: PathBuf::new(),
            };
            totals.add_frame(&pair);
        }
        totals.black_warning()
    }

    #[test]
    fn black_reference_frames_are_named() {
        let lit = constant(2, 2, 1.0);
        let black = constant(2, 2, 0.0);
        assert_eq!(black_warning_of(&[(0, lit.clone())], None), None);
        let all = black_warning_of(&[(0, black.clone()), (1, black.clone())], None).unwrap();
        assert!(
            all.contains("mean radiance is 0 (all black)") && !all.contains("surfaces"),
            "{all}"
        );
        let all = black_warning_of(&[(3, black.clone())], Some(&[false; 4])).unwrap();
        assert!(
            all.contains("flicker, rel_rmse_surfaces, flicker_surfaces)"),
            "{all}"
        );

        let one = black_warning_of(&[(0, lit.clone()), (7, black.clone())], None).unwrap();
        assert!(
            one.contains("reference frame 0007 has mean radiance 0"),
            "{one}"
        );
        assert!(one.contains(": its rel_rmse"), "{one}");
        let mut many: Vec<(u32, Film)> = (10..18).map(|n| (n, black.clone())).collect();
        many.push((18, lit.clone()));
        let many = black_warning_of(&many, None).unwrap();
        assert!(
            many.contains("frames 0010, 0011, 0012, 0013, 0014 and 3 more have"),
            "{many}"
        );

        // Lit only at its seen lights: the surface figures divide by 0.
        let mut light = black.clone();
        light.pixels[0] = Vec3::ONE;
        let mask = [true, false, false, false];
        let surfaces = black_warning_of(&[(0, light.clone())], Some(&mask)).unwrap();
        assert!(
            surfaces.contains("outside its directly seen lights is 0")
                && surfaces.contains("rel_rmse_surfaces and flicker_surfaces are undefined"),
            "{surfaces}"
        );
        assert_eq!(black_warning_of(&[(0, light)], None), None);
    }

    #[test]
    fn text_table_has_a_line_per_frame_and_overall() {
        let report = CompareReport {
            frames: 2,
            rmse: 0.5,
            rel_rmse: 0.25,
            block_bias: 0.125,
            rel_rmse_surfaces: None,
            flicker: None,
            flicker_surfaces: None,
            per_frame: vec![
                FrameReport {
                    frame: 3,
                    rmse: 0.5,
                    rel_rmse: 0.25,
                    block_bias: 0.125,
                    flicker: None,
                },
                FrameReport {
                    frame: 4,
                    rmse: 0.5,
                    rel_rmse: 0.25,
                    block_bias: 0.125,
                    flicker: Some(0.0625),
                },
            ],
        };
        let text = report.to_text();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        assert!(lines[1].trim_start().starts_with("0003"), "{text}");
        // A frame's flicker is that of the pair ending at it; the first has none.
        assert_eq!(lines[1].split_whitespace().count(), 4, "{text}");
        assert!(lines[2].trim_end().ends_with("0.062500"), "{text}");
        assert!(
            lines[3].trim_start().starts_with("all") && lines[3].contains('-'),
            "{text}"
        );
    }
}
