//! Frames as linear RGB f32 images, and their files: `frame_NNNN.exr` (linear
//! radiance, RGB f32) and `frame_NNNN.png` (tone-mapped sRGB preview), as
//! DESIGN.md "Command line" specifies.
//!
//! - EXR: scanline, RLE compression (one line per block), channels `R`,
//!   `G`, `B` as 32-bit float, no alpha — the layout of the Mitsuba
//!   references in `shared/reference/` but for their ZIP compression, which
//!   on rendered f32 radiance saves a few per cent for five times RLE's time
//!   ([`encode_exr`]); `compare` reads both alike.
//!   Reading accepts f16 or f32 (or u32) channels and converts them to f32.
//! - PNG: exposure 1, a tone curve on luminance that is the identity up to
//!   [`TONE_KNEE`] and rolls highlights off smoothly towards 1 (see
//!   [`tone_curve`]), then the sRGB OETF, 8 bits per channel.
//!
//! Every file is written atomically: encoded in memory, written to a temporary
//! file in the destination folder, then renamed over the destination, so a
//! crash never leaves a half-written frame behind.

use crate::material::luminance;
use crate::system_memory::{self, bytes_text};
use glam::Vec3;
use std::fs;
use std::io::{self, Cursor, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

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

    /// Mean over pixels and channels, summed in f64 (three channels of
    /// 3·10³⁸ would overflow f32).
    pub fn mean(&self) -> f64 {
        let sum: f64 = self.pixels.iter().map(|p| p.as_dvec3().element_sum()).sum();
        sum / (3.0 * self.pixels.len().max(1) as f64)
    }
}

/// `DIR/frame_NNNN.ext`.
pub fn frame_path(dir: &Path, frame: u32, ext: &str) -> PathBuf {
    dir.join(format!("frame_{frame:04}.{ext}"))
}

/// Errors reading or writing frame files; every message names the file.
#[derive(Debug, thiserror::Error)]
pub enum FilmError {
    #[error("{}: file not found", path.display())]
    NotFound { path: PathBuf },
    /// A directory, FIFO, device or socket where a frame file should be.
    #[error("{}: not a regular file (it is {kind})", path.display())]
    NotRegular { path: PathBuf, kind: &'static str },
    /// The OS error is part of the message, not a `source` (named `error`,
    /// not `source`, so thiserror does not chain it): `{:#}` of an
    /// `anyhow` error would otherwise print it twice.
    #[error("{}: {error}", path.display())]
    Io { path: PathBuf, error: io::Error },
    #[error("{}: not an OpenEXR file (no EXR magic number)", path.display())]
    NotExr { path: PathBuf },
    #[error("{}: no R, G, B channels in the first layer (found: {found})", path.display())]
    MissingChannels { path: PathBuf, found: String },
    #[error("{}: invalid or unsupported EXR: {message}", path.display())]
    Exr { path: PathBuf, message: String },
    /// The header declares more than the file holds or memory can take.
    #[error("{}: {problem}", path.display())]
    Declared {
        path: PathBuf,
        problem: DeclaredSizeError,
    },
    #[error("{}: cannot encode PNG: {message}", path.display())]
    Png { path: PathBuf, message: String },
}

impl FilmError {
    fn io(path: &Path, source: io::Error) -> Self {
        if source.kind() == io::ErrorKind::NotFound {
            FilmError::NotFound {
                path: path.to_owned(),
            }
        } else {
            FilmError::Io {
                path: path.to_owned(),
                error: source,
            }
        }
    }

    fn exr(path: &Path, error: exr::error::Error) -> Self {
        match error {
            exr::error::Error::Io(source) => FilmError::io(path, source),
            other => FilmError::Exr {
                path: path.to_owned(),
                message: other.to_string(),
            },
        }
    }
}

/// An EXR header that declares an image the file cannot hold or memory
/// cannot take: refused before any pixel is decoded.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DeclaredSizeError {
    #[error(
        "declares {width}×{height} pixels in {chunks} chunks, which need at least {need} bytes \
         (an 8-byte offset and a chunk header each), but the file has {len}: it is truncated \
         or its header is wrong"
    )]
    Truncated {
        width: usize,
        height: usize,
        chunks: usize,
        need: u64,
        len: u64,
    },
    #[error(
        "declares {width}×{height} pixels, {} decoded, more than the {} of memory available",
        bytes_text(*need),
        bytes_text(*available)
    )]
    TooLarge {
        width: usize,
        height: usize,
        need: u64,
        available: u64,
    },
}

// ---------------------------------------------------------------- EXR

/// The four bytes every OpenEXR file starts with.
pub(crate) const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];

/// Writes `film` as a scanline, RLE-compressed RGB f32 EXR (atomically).
pub fn write_exr(film: &Film, path: &Path) -> Result<(), FilmError> {
    let bytes = encode_exr(film).map_err(|e| FilmError::exr(path, e))?;
    write_atomically(path, &bytes)
}

/// The EXR file of `film` in memory (what [`write_exr`] writes; the store keeps these bytes).
pub fn encode_exr(film: &Film) -> Result<Vec<u8>, exr::error::Error> {
    use exr::prelude::*;
    let width = film.width as usize;
    let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
        let p = film.pixels[pos.y() * width + pos.x()];
        (p.x, p.y, p.z)
    });
    // RLE, not ZIP: the low bytes of rendered f32 radiance are noise, so
    // ZIP16 made a 256×256 frame of the default render 4 % smaller (a
    // converged reference 3 %) in 9 ms, 6 % of the default render's time;
    // RLE takes 1.8 ms and folds black away (half a frame black: 51 %
    // of the size, ZIP16 48 %); only a flat colour, which renders do not
    // make, does ZIP far better (RLE 52 %, ZIP16 0.4 %). The store's
    // zstd takes another 11 % off RLE's frames (none off ZIP's).
    // Measured at 9264e01 (`benches/HISTORY.md`).
    let encoding = Encoding {
        compression: Compression::RLE,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let size = (width, film.height as usize);
    let layer = Layer::new(size, LayerAttributes::default(), encoding, channels);
    let mut buffer = Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut buffer)?;
    Ok(buffer.into_inner())
}

/// Reads the R, G, B channels of the first layer of an EXR as f32. Only a
/// regular file is read (a FIFO or a device is refused unopened), and its
/// header is checked (channels, and the size it declares against the
/// file's length and the memory available) before any pixel is decoded.
pub fn read_exr(path: &Path) -> Result<Film, FilmError> {
    let bytes = read_regular_file(path)?;
    if !bytes.starts_with(&EXR_MAGIC) {
        return Err(FilmError::NotExr {
            path: path.to_owned(),
        });
    }
    check_header(&bytes, system_memory::available_bytes()).map_err(|e| e.at(path))?;
    decode_rgb(&bytes).map_err(|e| FilmError::exr(path, e))
}

/// Decodes EXR file bytes (as [`encode_exr`] writes and the store keeps),
/// after the same header checks as [`read_exr`].
pub fn decode_exr(bytes: &[u8]) -> Result<Film, exr::error::Error> {
    check_header(bytes, system_memory::available_bytes()).map_err(HeaderError::into_exr)?;
    decode_rgb(bytes)
}

/// The bytes of the regular file at `path`; a directory, FIFO, device (a
/// link to `/dev/zero`) or socket is refused ([`crate::regular_file`]), as
/// reading it would fail, block or never end.
fn read_regular_file(path: &Path) -> Result<Vec<u8>, FilmError> {
    use crate::regular_file::OpenError;
    use std::io::Read;
    let (mut file, metadata) = crate::regular_file::open(path).map_err(|e| match e {
        OpenError::NotFound => FilmError::NotFound {
            path: path.to_owned(),
        },
        OpenError::NotRegular { kind } => FilmError::NotRegular {
            path: path.to_owned(),
            kind,
        },
        OpenError::Io(e) => FilmError::io(path, e),
    })?;
    let mut bytes = Vec::with_capacity(usize::try_from(metadata.len()).unwrap_or(0));
    file.read_to_end(&mut bytes)
        .map_err(|e| FilmError::io(path, e))?;
    Ok(bytes)
}

/// The tone-mapped sRGB preview of `film` as PNG file bytes.
pub fn encode_png(film: &Film) -> Result<Vec<u8>, image::ImageError> {
    let mut buffer = Cursor::new(Vec::new());
    tonemap_srgb(film).write_to(&mut buffer, image::ImageFormat::Png)?;
    Ok(buffer.into_inner())
}

/// Why [`check_header`] refused a file, before a path is put to it.
#[derive(Debug)]
enum HeaderError {
    Exr(exr::error::Error),
    MissingChannels { found: String },
    Declared(DeclaredSizeError),
}

impl HeaderError {
    fn at(self, path: &Path) -> FilmError {
        match self {
            HeaderError::Exr(e) => FilmError::exr(path, e),
            HeaderError::MissingChannels { found } => FilmError::MissingChannels {
                path: path.to_owned(),
                found,
            },
            HeaderError::Declared(problem) => FilmError::Declared {
                path: path.to_owned(),
                problem,
            },
        }
    }

    fn into_exr(self) -> exr::error::Error {
        match self {
            HeaderError::Exr(e) => e,
            HeaderError::MissingChannels { found } => exr::error::Error::Invalid(
                format!("no R, G, B channels in the first layer (found: {found})").into(),
            ),
            HeaderError::Declared(problem) => {
                exr::error::Error::Invalid(problem.to_string().into())
            }
        }
    }
}

/// Reads and validates the header of EXR file `bytes` (once) and checks,
/// before any pixel is decoded (which allocates the declared size):
/// - that the first layer has R, G, B channels, so that a file without
///   them gets a clear error listing what it has, rather than exr's
///   generic "no layer matched your requirements";
/// - that the file can hold what it declares: every chunk needs at least
///   its 8-byte offset-table entry and an 8-byte chunk header (scanline
///   index and size; tiles and multi-part files need more), so a file
///   shorter than 16 bytes × the chunk count is truncated or lying (a
///   600-byte file declaring 60000×60000 pixels made `compare` allocate
///   43 GB and abort);
/// - that the decoded [`Film`] (12 bytes a pixel) fits in `available`
///   bytes ([`system_memory::available_bytes`]; `None`: not checked).
fn check_header(bytes: &[u8], available: Option<u64>) -> Result<(), HeaderError> {
    use exr::meta::MetaData;
    let meta = MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(HeaderError::Exr)?;
    MetaData::validate(&meta.headers, false).map_err(HeaderError::Exr)?;
    let Some(first) = meta.headers.first() else {
        return Err(HeaderError::Exr(exr::error::Error::Invalid(
            "no layer".into(),
        )));
    };
    let names: Vec<String> = first
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    let has = |n: &str| names.iter().any(|c| c == n);
    if !(has("R") && has("G") && has("B")) {
        return Err(HeaderError::MissingChannels {
            found: names.join(", "),
        });
    }
    let (width, height) = (first.layer_size.width(), first.layer_size.height());
    let chunks = meta
        .headers
        .iter()
        .fold(0_usize, |n, h| n.saturating_add(h.chunk_count));
    let need = (chunks as u64).saturating_mul(16);
    let len = bytes.len() as u64;
    if len < need {
        return Err(HeaderError::Declared(DeclaredSizeError::Truncated {
            width,
            height,
            chunks,
            need,
            len,
        }));
    }
    let decoded = (width as u64)
        .saturating_mul(height as u64)
        .saturating_mul(std::mem::size_of::<Vec3>() as u64);
    match available {
        Some(available) if decoded > available => {
            Err(HeaderError::Declared(DeclaredSizeError::TooLarge {
                width,
                height,
                need: decoded,
                available,
            }))
        }
        _ => Ok(()),
    }
}

fn decode_rgb(bytes: &[u8]) -> Result<Film, exr::error::Error> {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .specific_channels()
        .required("R")
        .required("G")
        .required("B")
        .collect_pixels(
            |size: Vec2<usize>, _| Film::new(size.width() as u32, size.height() as u32),
            // f16 and u32 samples are converted to the requested f32 by exr.
            |film: &mut Film, pos: Vec2<usize>, (r, g, b): (f32, f32, f32)| {
                let width = film.width as usize;
                film.pixels[pos.y() * width + pos.x()] = Vec3::new(r, g, b);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))?;
    Ok(image.layer_data.channel_data.pixels)
}

// ---------------------------------------------------------------- PNG

/// Luminance below this is shown linearly (exposure 1); above, highlights
/// roll off. Chosen so mid-tones (the references' mean is ≈ 0.56) are
/// untouched while the radiance-30 light does not clip to a flat block of
/// colour-shifted white before it has to.
pub const TONE_KNEE: f32 = 0.8;

/// The tone curve on luminance: identity up to [`TONE_KNEE`], then an
/// exponential shoulder `k + (1−k)(1 − e^{−(L−k)/(1−k)})` that is continuous
/// with slope 1 at the knee and approaches 1 as L → ∞. Chosen over a plain
/// clamp so bright walls keep their gradation, and over a global Reinhard so
/// that values ≤ 0.8 stay linear.
pub fn tone_curve(luminance: f32) -> f32 {
    let k = TONE_KNEE;
    if luminance <= k {
        luminance
    } else {
        k + (1.0 - k) * (1.0 - (-(luminance - k) / (1.0 - k)).exp())
    }
}

/// The sRGB OETF (IEC 61966-2-1): linear [0, 1] → encoded [0, 1].
pub fn srgb_oetf(linear: f32) -> f32 {
    if linear <= 0.003_130_8 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

/// A linear value in [0, 1] → 8-bit sRGB, rounded to nearest. Non-finite or
/// out-of-range input is clamped (NaN shows as black).
pub fn encode_srgb8(linear: f32) -> u8 {
    let v = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    (srgb_oetf(v) * 255.0 + 0.5) as u8
}

/// One pixel: tone-map by scaling RGB with `tone_curve(L) / L` (keeps hue),
/// then clamp each channel — a saturated colour above 1 may still clip.
/// Non-finite pixels skip the curve so that ∞ shows white and NaN black.
fn tonemap_pixel(c: Vec3) -> [u8; 3] {
    let l = luminance(c);
    let scale = if l.is_finite() && l > TONE_KNEE {
        tone_curve(l) / l
    } else {
        1.0
    };
    let c = c * scale;
    [encode_srgb8(c.x), encode_srgb8(c.y), encode_srgb8(c.z)]
}

/// The sRGB 8-bit preview of a linear film (exposure 1, [`tone_curve`]).
pub fn tonemap_srgb(film: &Film) -> image::RgbImage {
    // On the caller's thread, not rayon's pool: `serve` encodes previews
    // while its renders keep that pool busy, and a preview waiting for a
    // render's parallel pass to end would stall the dashboard.
    let bytes: Vec<u8> = film.pixels.iter().flat_map(|&c| tonemap_pixel(c)).collect();
    image::RgbImage::from_raw(film.width, film.height, bytes)
        .expect("film has width × height pixels")
}

/// Writes the tone-mapped sRGB preview as an 8-bit RGB PNG (atomically).
pub fn write_png(film: &Film, path: &Path) -> Result<(), FilmError> {
    write_rgb_png(&tonemap_srgb(film), path)
}

/// Writes an 8-bit sRGB image as a PNG (atomically).
pub fn write_rgb_png(image: &image::RgbImage, path: &Path) -> Result<(), FilmError> {
    let mut buffer = Cursor::new(Vec::new());
    image
        .write_to(&mut buffer, image::ImageFormat::Png)
        .map_err(|e| FilmError::Png {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
    write_atomically(path, &buffer.into_inner())
}

// ---------------------------------------------------------------- frames

/// Writes `DIR/frame_NNNN.png` then `DIR/frame_NNNN.exr`, creating `dir` if
/// needed. The EXR goes last so that its presence means the frame is complete
/// (a resume can test for the EXR alone).
pub fn write_frame(film: &Film, dir: &Path, frame: u32) -> Result<(), FilmError> {
    let exr_path = frame_path(dir, frame, "exr");
    let exr = encode_exr(film).map_err(|e| FilmError::exr(&exr_path, e))?;
    write_encoded_frame(film, &exr, dir, frame)
}

/// [`write_frame`] with the frame's EXR bytes already made by
/// [`encode_exr`] (a job's render stores the same bytes).
pub fn write_encoded_frame(
    film: &Film,
    exr: &[u8],
    dir: &Path,
    frame: u32,
) -> Result<(), FilmError> {
    fs::create_dir_all(dir).map_err(|e| FilmError::io(dir, e))?;
    write_png(film, &frame_path(dir, frame, "png"))?;
    write_atomically(&frame_path(dir, frame, "exr"), exr)
}

/// The frame files (`frame_NNNN.exr`, `frame_NNNN.png`) in `dir` that are
/// directories, with their frame numbers, in frame order: [`write_frame`]
/// cannot rename a file over them. Nothing when `dir` cannot be read.
pub fn frame_paths_taken_by_directories(dir: &Path) -> Vec<(u32, PathBuf)> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut taken: Vec<(u32, PathBuf)> = entries
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .filter_map(|e| {
            let name = e.file_name();
            let (number, ext) = name.to_str()?.strip_prefix("frame_")?.split_once('.')?;
            let frame: u32 = number.parse().ok()?;
            // Only the names `frame_path` makes (no sign, four digits or more).
            let path = frame_path(dir, frame, ext);
            (matches!(ext, "exr" | "png") && path.file_name() == Some(&name))
                .then_some((frame, path))
        })
        .collect();
    taken.sort();
    taken
}

/// Distinguishes temporary files of concurrent writers in one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `bytes` to a temporary file beside `path`, syncs it, and renames it
/// over `path`: rename within a folder is atomic, so readers see either the
/// old file or the whole new one, never a partial one.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FilmError> {
    let temp = temp_path(path);
    let result = fs::File::create(&temp)
        .and_then(|mut f| f.write_all(bytes).and_then(|()| f.sync_all()))
        .and_then(|()| fs::rename(&temp, path));
    result.map_err(|e| {
        let _ = fs::remove_file(&temp);
        FilmError::io(path, e)
    })
}

/// `.NAME.tmp-PID-N` in the same folder as `path` (same file system, so the
/// rename cannot fail with a cross-device error).
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy())
        .unwrap_or_default();
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.tmp-{}-{n}", std::process::id()))
}

/// Removes from `dir` the temporary frame files (`.frame_NNNN.png.tmp-PID-N`,
/// and earlier builds' `.frame_NNNN.exr.restore-PID`) of processes that no longer run: a
/// render killed while it wrote a frame leaves its temporary file, which
/// nothing else would ever remove. Those of running processes (another
/// render into the same folder) are left alone; where liveness cannot be
/// asked (no `/proc`), every one is. Returns how many went.
pub fn remove_stale_temporaries(dir: &Path) -> usize {
    remove_stale(dir, temporary_owner)
}

/// Removes from `dir` the temporary files that `write_atomically` left
/// of `files` (`.NAME.tmp-PID-N`, NAME one of `files`) in processes that
/// no longer run, as [`remove_stale_temporaries`] does of frames: those
/// of a bench killed while it wrote `bench.csv`. Returns how many went.
pub fn remove_stale_temporaries_of(dir: &Path, files: &[&str]) -> usize {
    remove_stale(dir, |name| {
        (files.iter()).find_map(|file| written_temporary_owner(name, file))
    })
}

/// The process id in `name` where it is [`temp_path`]'s name of `file`
/// (`.FILE.tmp-PID-N`); `None` otherwise.
fn written_temporary_owner(name: &str, file: &str) -> Option<u32> {
    let tail = name.strip_prefix('.')?.strip_prefix(file)?;
    pid_and_count(tail.strip_prefix(".tmp-")?)
}

/// Removes the files of `dir` whose names `owner` gives a process id of
/// a process that no longer runs; returns how many went.
fn remove_stale(dir: &Path, owner: impl Fn(&str) -> Option<u32>) -> usize {
    let Ok(entries) = fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(&owner) else {
            continue;
        };
        let running = pid == std::process::id() || process_may_run(pid);
        if !running && fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// The process id in a temporary frame file's name ([`temp_path`]'s
/// `.frame_NNNN.EXT.tmp-PID-N`, or `.frame_NNNN.exr.restore-PID`, which
/// earlier builds wrote when they restored a resumed job's files from the
/// store and which such a build killed may have left); `None` for any
/// other name.
fn temporary_owner(name: &str) -> Option<u32> {
    let rest = name.strip_prefix(".frame_")?;
    let (digits, rest) = rest.split_at_checked(4)?;
    if !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    match rest
        .strip_prefix(".png.tmp-")
        .or_else(|| rest.strip_prefix(".exr.tmp-"))
    {
        Some(tail) => pid_and_count(tail),
        None => rest.strip_prefix(".exr.restore-")?.parse().ok(),
    }
}

/// The process id of [`temp_path`]'s `PID-N` ending of a temporary
/// file's name.
fn pid_and_count(tail: &str) -> Option<u32> {
    let (pid, n) = tail.split_once('-')?;
    n.parse::<u64>().ok()?;
    pid.parse().ok()
}

/// Whether process `pid` may be running: `false` only where `/proc` says
/// it is not.
fn process_may_run(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.join("self").exists() || proc.join(pid.to_string()).exists()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::mix64;

    /// The temporary files of a process that no longer runs go; those of
    /// this process, of a running one, and other files stay.
    #[test]
    fn stale_temporary_frame_files_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        // Beyond the kernel's largest pid (2^22): never running.
        let gone = 4_194_304 + 17;
        let me = std::process::id();
        let stale = [
            format!(".frame_0003.png.tmp-{gone}-0"),
            format!(".frame_0003.exr.tmp-{gone}-12"),
            format!(".frame_0010.exr.restore-{gone}"),
        ];
        let kept = [
            format!(".frame_0004.png.tmp-{me}-1"),
            ".frame_0005.png.tmp-1-0".to_string(), // init runs
            format!("frame_0003.png.tmp-{gone}-0"),
            format!(".frame_03.png.tmp-{gone}-0"),
            format!(".frame_0003.png.tmp-{gone}"),
            "frame_0003.exr".to_string(),
        ];
        for name in stale.iter().chain(&kept) {
            fs::write(dir.path().join(name), b"x").unwrap();
        }
        assert_eq!(remove_stale_temporaries(dir.path()), stale.len());
        for name in &stale {
            assert!(!dir.path().join(name).exists(), "{name} stayed");
        }
        for name in &kept {
            assert!(dir.path().join(name).exists(), "{name} went");
        }
    }

    /// The temporaries of named files left by a process that no longer
    /// runs go; a running process's, other names' and the files stay.
    #[test]
    fn stale_temporaries_of_named_files_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let gone = 4_194_304 + 17;
        let me = std::process::id();
        let stale = [
            format!(".bench.csv.tmp-{gone}-0"),
            format!(".bench_seeds.csv.tmp-{gone}-3"),
        ];
        let kept = [
            format!(".bench.csv.tmp-{me}-1"),
            format!(".other.csv.tmp-{gone}-0"),
            format!(".bench.csv.tmp-{gone}"),
            format!(".bench.csvx.tmp-{gone}-0"),
            "bench.csv".to_string(),
        ];
        for name in stale.iter().chain(&kept) {
            fs::write(dir.path().join(name), b"x").unwrap();
        }
        let files = ["bench.csv", "bench_seeds.csv"];
        assert_eq!(remove_stale_temporaries_of(dir.path(), &files), stale.len());
        for name in &stale {
            assert!(!dir.path().join(name).exists(), "{name} stayed");
        }
        for name in &kept {
            assert!(dir.path().join(name).exists(), "{name} went");
        }
    }

    fn reference(rel: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/reference")
            .join(rel)
    }

    /// Values spread over many magnitudes, incl. subnormal, tiny, huge, 0.
    fn random_film(width: u32, height: u32, seed: u64) -> Film {
        let mut film = Film::new(width, height);
        for (i, p) in film.pixels.iter_mut().enumerate() {
            let h = mix64(seed ^ i as u64);
            let c = |k: u32| {
                let mantissa = ((h >> (k * 16)) & 0xffff) as f32 / 65536.0;
                let exponent = ((h >> (k * 7 + 40)) % 80) as i32 - 40;
                mantissa * 2f32.powi(exponent)
            };
            *p = Vec3::new(c(0), c(1), c(2));
        }
        film.pixels[0] = Vec3::new(0.0, f32::MIN_POSITIVE / 8.0, 1.0e30);
        film.pixels[1] = Vec3::new(f32::MAX, 1.0e-30, 30.0);
        film
    }

    #[test]
    fn exr_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr");
        let film = random_film(37, 21, 7);
        write_exr(&film, &path).unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (37, 21));
        for (a, b) in film.pixels.iter().zip(&back.pixels) {
            assert_eq!(
                a.to_array().map(f32::to_bits),
                b.to_array().map(f32::to_bits)
            );
        }
    }

    /// RLE folds black away, halves a flat colour (runs of its equal
    /// high bytes) and stores noise at about its raw size.
    #[test]
    fn rle_folds_black_halves_flat_colour_and_keeps_noise_near_raw() {
        let raw = 64 * 64 * 12;
        let black = encode_exr(&Film::new(64, 64)).unwrap().len();
        assert!(black * 10 < raw, "black film: {black} of {raw} bytes");
        let mut flat = Film::new(64, 64);
        flat.pixels.fill(Vec3::new(0.25, 0.5, 1.0));
        let flat = encode_exr(&flat).unwrap().len();
        assert!(flat * 10 < raw * 6, "flat film: {flat} of {raw} bytes");
        let noisy = encode_exr(&random_film(64, 64, 3)).unwrap().len();
        assert!(
            noisy > raw * 9 / 10 && noisy < raw * 11 / 10,
            "{noisy} of {raw}"
        );
    }

    #[test]
    fn exr_is_scanline_rle_rgb_f32() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr");
        write_exr(&Film::new(4, 3), &path).unwrap();
        let meta = exr::meta::MetaData::read_from_file(&path, false).unwrap();
        let header = &meta.headers[0];
        assert_eq!(header.compression, exr::compression::Compression::RLE);
        assert_eq!(header.blocks, exr::meta::BlockDescription::ScanLines);
        let names: Vec<String> = header
            .channels
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        assert_eq!(names, ["B", "G", "R"]); // EXR stores channels sorted by name
        assert!(header
            .channels
            .list
            .iter()
            .all(|c| c.sample_type == exr::meta::attribute::SampleType::F32));
    }

    #[test]
    fn reads_f16_channels() {
        use exr::prelude::*;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("half.exr");
        let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
            (
                f16::from_f32(p.x() as f32),
                f16::from_f32(0.5),
                f16::from_f32(1024.0),
            )
        });
        Image::from_channels((3, 2), channels)
            .write()
            .to_file(&path)
            .unwrap();
        let film = read_exr(&path).unwrap();
        assert_eq!(film.get(2, 1), Vec3::new(2.0, 0.5, 1024.0));
    }

    #[test]
    fn reads_shared_reference() {
        let film = read_exr(&reference("cube_in_box/frame_0000.exr")).unwrap();
        assert_eq!((film.width, film.height), (128, 128));
        // SOURCE.md "Noise": mean radiance 0.5641.
        assert!((film.mean() - 0.5641).abs() < 5e-4, "mean {}", film.mean());
        let spheres = read_exr(&reference("spheres/frame_0000.exr")).unwrap();
        assert!(
            (spheres.mean() - 0.5460).abs() < 5e-4,
            "mean {}",
            spheres.mean()
        );
    }

    #[test]
    fn reference_sees_the_light_exactly() {
        // SOURCE.md: a pixel seeing the light head-on holds exactly (30, 27, 22.5).
        let film = read_exr(&reference("cube_in_box/frame_0000.exr")).unwrap();
        let brightest = film
            .pixels
            .iter()
            .copied()
            .max_by(|a, b| luminance(*a).total_cmp(&luminance(*b)))
            .unwrap();
        assert_eq!(brightest, Vec3::new(30.0, 27.0, 22.5));
    }

    #[test]
    fn read_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.exr");
        let err = read_exr(&missing).unwrap_err();
        assert!(matches!(err, FilmError::NotFound { .. }), "{err}");
        assert!(err.to_string().contains("missing.exr"), "{err}");

        let text = dir.path().join("text.exr");
        fs::write(&text, "not an image").unwrap();
        let err = read_exr(&text).unwrap_err();
        assert!(matches!(err, FilmError::NotExr { .. }), "{err}");
        assert!(err.to_string().contains("text.exr"), "{err}");

        let truncated = dir.path().join("truncated.exr");
        let whole = fs::read(reference("cube_in_box/frame_0000.exr")).unwrap();
        fs::write(&truncated, &whole[..whole.len() / 2]).unwrap();
        let err = read_exr(&truncated).unwrap_err();
        assert!(err.to_string().contains("truncated.exr"), "{err}");
    }

    /// The header's claims are checked against the file's length and the
    /// memory available, before decoding; a whole file passes both.
    #[test]
    fn declared_size_is_checked_against_the_file_and_memory() {
        let at = |e: HeaderError| e.at(Path::new("x.exr"));
        // RLE: a chunk a line, 4000 chunks, so at least 64,000 bytes.
        let bytes = encode_exr(&Film::new(4, 4000)).unwrap();
        let decoded = 4 * 4000 * 12;
        check_header(&bytes, Some(decoded)).map_err(at).unwrap();
        let err = at(check_header(&bytes, Some(decoded - 1)).unwrap_err());
        assert!(
            matches!(
                &err,
                FilmError::Declared {
                    problem: DeclaredSizeError::TooLarge {
                        width: 4,
                        height: 4000,
                        need: 192_000,
                        ..
                    },
                    ..
                }
            ),
            "{err}"
        );
        assert!(
            err.to_string().contains("x.exr: declares 4×4000 pixels"),
            "{err}"
        );
        let err = at(check_header(&bytes[..1000], None).unwrap_err());
        let FilmError::Declared { problem, .. } = &err else {
            panic!("{err}");
        };
        assert_eq!(
            *problem,
            DeclaredSizeError::Truncated {
                width: 4,
                height: 4000,
                chunks: 4000,
                need: 64_000,
                len: 1000
            }
        );
    }

    #[test]
    fn missing_rgb_is_a_clear_error() {
        use exr::prelude::*;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("luma.exr");
        let channels = SpecificChannels::build()
            .with_channel("Y")
            .with_pixel_fn(|_p: Vec2<usize>| (0.5_f32,));
        Image::from_channels((2, 2), channels)
            .write()
            .to_file(&path)
            .unwrap();
        let err = read_exr(&path).unwrap_err();
        assert!(matches!(err, FilmError::MissingChannels { .. }), "{err}");
        let message = err.to_string();
        assert!(
            message.contains("luma.exr") && message.contains("Y"),
            "{message}"
        );
    }

    #[test]
    fn srgb_oetf_endpoints_and_boundary() {
        assert_eq!(encode_srgb8(0.0), 0);
        assert_eq!(encode_srgb8(1.0), 255);
        assert_eq!(encode_srgb8(-1.0), 0);
        assert_eq!(encode_srgb8(f32::INFINITY), 255);
        assert_eq!(encode_srgb8(f32::NAN), 0);
        // Both branches meet at 0.0031308 → 0.04045 (continuity of the OETF).
        let below = srgb_oetf(0.003_130_8);
        let above = srgb_oetf(f32::from_bits(0.003_130_8_f32.to_bits() + 1));
        assert!((below - 0.040_45).abs() < 1e-5, "{below}");
        assert!((above - below).abs() < 1e-5, "{above} vs {below}");
        assert_eq!(encode_srgb8(0.003_130_8), 10); // 0.04045·255 = 10.3
        assert!((srgb_oetf(0.5) - 0.735_357).abs() < 1e-5);
    }

    #[test]
    fn tone_curve_is_linear_then_rolls_off() {
        assert_eq!(tone_curve(0.5), 0.5);
        assert_eq!(tone_curve(TONE_KNEE), TONE_KNEE);
        let just_above = tone_curve(TONE_KNEE + 1e-3);
        assert!((just_above - (TONE_KNEE + 1e-3)).abs() < 1e-5); // slope 1 at the knee
        assert!(tone_curve(2.0) < 1.0 && tone_curve(2.0) > tone_curve(1.0));
        assert!(tone_curve(30.0) <= 1.0 && tone_curve(30.0) > 0.999);
        // Mid grey 0.5 passes through unchanged: sRGB 188.
        assert_eq!(tonemap_pixel(Vec3::splat(0.5)), [188; 3]);
        // The warm light keeps its hue: its luminance maps to ≈ 1, red clips.
        let light = tonemap_pixel(Vec3::new(30.0, 27.0, 22.5));
        assert!(
            light[0] == 255 && light[1] >= 250 && light[2] < light[1],
            "{light:?}"
        );
        let odd = tonemap_pixel(Vec3::new(f32::INFINITY, f32::NAN, 0.5));
        assert_eq!(odd, [255, 0, 188]);
    }

    #[test]
    fn png_has_the_right_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.png");
        let film = random_film(19, 11, 3);
        write_png(&film, &path).unwrap();
        let decoded = image::open(&path).unwrap().to_rgb8();
        assert_eq!(decoded.dimensions(), (19, 11));
        assert_eq!(decoded, tonemap_srgb(&film));
    }

    #[test]
    fn write_frame_writes_both_and_no_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a/b");
        let film = random_film(8, 4, 11);
        write_frame(&film, &out, 7).unwrap();
        write_frame(&film, &out, 7).unwrap(); // overwriting is fine
        assert_eq!(read_exr(&frame_path(&out, 7, "exr")).unwrap(), film);
        assert!(frame_path(&out, 7, "png").is_file());
        let mut names: Vec<String> = fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["frame_0007.exr", "frame_0007.png"]);
    }

    /// The OS's reason is in the message and not also its source:
    /// `{:#}` of an `anyhow` error (how the CLI prints errors) says it once.
    #[test]
    fn write_error_says_the_os_error_once() {
        let dir = tempfile::tempdir().unwrap();
        fs::create_dir_all(frame_path(dir.path(), 0, "exr").join("x")).unwrap();
        let err = write_frame(&Film::new(2, 2), dir.path(), 0).unwrap_err();
        let said = format!("{:#}", anyhow::Error::from(err));
        assert_eq!(said.matches("os error").count(), 1, "{said}");
        assert!(said.contains("frame_0000.exr"), "{said}");
    }

    #[test]
    fn directories_in_the_way_of_frame_files_are_found() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["frame_0012.png", "frame_0003.exr", "frame_12345.exr"] {
            fs::create_dir(dir.path().join(name)).unwrap();
        }
        // Not frame files, or files rather than directories.
        for name in ["frame_03.exr", "frame_0004.jpg", "frame_+004.exr", "other"] {
            fs::create_dir(dir.path().join(name)).unwrap();
        }
        fs::write(dir.path().join("frame_0005.exr"), "").unwrap();
        let taken = frame_paths_taken_by_directories(dir.path());
        assert_eq!(
            taken,
            [
                (3, frame_path(dir.path(), 3, "exr")),
                (12, frame_path(dir.path(), 12, "png")),
                (12345, frame_path(dir.path(), 12345, "exr")),
            ]
        );
        assert!(frame_paths_taken_by_directories(&dir.path().join("none")).is_empty());
    }

    #[test]
    fn write_error_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let blocker = dir.path().join("file");
        fs::write(&blocker, "").unwrap();
        let err = write_frame(&Film::new(2, 2), &blocker.join("sub"), 0).unwrap_err();
        assert!(err.to_string().contains("file"), "{err}");
    }
}
