//! A render's peak memory, estimated before it starts: `radcache render`,
//! `bench` and `POST /api/jobs` refuse a render whose estimate is over what
//! is available ([`system_memory`](crate::system_memory)), with an
//! error that says both, rather than have it end in the runtime's abort
//! (`memory allocation of N bytes failed`) or the OOM killer.
//!
//! # The estimate
//! It counts what the code allocates for every pixel and every pixel
//! sample of a frame whatever the scene shows, and the scene's triangles;
//! what depends on what the frame shows (records and their gathered paths,
//! texture movies and their shadows, the path-traced parts kept from frame
//! to frame) is left out. So it is a lower bound: a refused render would
//! not have fitted, on any scene, and the refusal never stops one that
//! would. At a frame's peak these are held at once:
//! - the film, a [`Vec3`] a pixel, then beside it the PNG preview's 3
//!   bytes a pixel while the frame is written (on the writer thread, while
//!   the next frame renders: counted once, as that write usually ends
//!   before the next frame's film is made);
//! - `trc` and `tcg`: the samples of still tiles kept for the next frame
//!   ([`StillSamples`], within its budget of
//!   [`StillSamples::BUDGET_BYTES`]), from frame to frame (the render
//!   pass frees the rays and hits of the others with their tile,
//!   `render_pass::still_tile::TileKept::of`); `ic`, `trc` and `tcg`:
//!   before the pass, their fill stage holds a ray, hit and candidate a pixel
//!   (`ic::primary_candidates`), then the candidates, their clearances and
//!   a visited flag (`ic`'s `fill_from`);
//! - `movies`: its item buffer, every camera sample's hit (within
//!   [`HELD_HITS_BYTES`]; past it the camera rays are traced again tile by
//!   tile to render) and whether it sees an emitter, held for the whole
//!   frame (`TextureMovies::trace_tiles`; the samples' rays and streams are
//!   drawn again tile by tile to render, `PrimarySamples::again`);
//! - per triangle, the frame's snapshot of it, the mesh's indices and
//!   material, and the BVH's copy of it in leaf order with its ids.
//!
//! # Measured
//! Peak resident memory of `radcache render --method M --size S --frames
//! 0..2 -q --out DIR` (built-in cube-in-box, release build, CPU backend
//! after `auto`'s GPU probe, 2 threads, `/usr/bin/time -f %M`, one run
//! each) against [`peak_bytes`], MiB, measured again at c986b14 (before,
//! from earlier builds: `path` 70 and 94, `ic` 78, 119 and 234, `trc` 377,
//! 935 and 1,233, `tcg` 229, 655 and 811, `movies` 463, 1,087, 1,451 and
//! 752):
//!
//! | method | size | measured | estimated | ratio |
//! | --- | ---: | ---: | ---: | ---: |
//! | `path` | 256² | 68 | 9 | 0.13 |
//! | `path` | 1024² | 99 | 23 | 0.23 |
//! | `ic` | 256² | 76 | 15 | 0.20 |
//! | `ic` | 512² | 118 | 37 | 0.31 |
//! | `ic` | 1024² | 234 | 124 | 0.53 |
//! | `trc` | 256² | 448 | 125 | 0.28 |
//! | `trc` | 512² | 1,059 | 476 | 0.45 |
//! | `trc` | 1024² | 1,365 | 535 | 0.39 |
//! | `tcg` | 256² | 218 | 125 | 0.57 |
//! | `tcg` | 512² | 655 | 476 | 0.73 |
//! | `tcg` | 1024² | 818 | 535 | 0.65 |
//! | `movies` | 256² | 552 | 30 | 0.05 |
//! | `movies` | 512² | 1,130 | 96 | 0.08 |
//! | `movies` | 1024² | 1,502 | 357 | 0.24 |
//! | `movies --movies-texels-per-pixel 2` | 256² | 841 | 30 | 0.04 |
//!
//! (`movies` measured again once its item buffer held its samples' hits
//! alone and its movies their texels in the band, their direct part RGBE
//! and no layout: 589, 1,623, 3,548 and 1,039 MiB before, estimated 93,
//! 347, 1,364 and 93. Before that, once its global pass was meshed finer
//! for larger films, `movies::view::film_share`: 555, 1,295, 2,939 and
//! 1,000 MiB before; the pass is within its link budget, which the
//! estimate leaves out with the rest of what the scene decides.)
//!
//! Before the render pass freed them, `ic` peaked at 117, 279 and 921 MiB
//! at 256², 512² and 1024², `trc` at 1,705 and `tcg` at 1,428 MiB at
//! 1024². Below the estimate: the program's 10.5 MiB at 1×1 on `--backend cpu`
//! and `auto`'s GPU probe, whose driver libraries make it 68 MiB (the
//! estimate counts 8); the scene's part, which the gather's hemisphere
//! (`--ic-strata`) and `--movies-texels-per-pixel` grow: `trc`'s records
//! and their gathered paths (up to 256 MiB), `tcg`'s records and their
//! samples, `movies`' textures and their shadows (within
//! `--movies-memory-mib`). What it counts takes over as the frame grows:
//! at 8192×8192 `trc` it is 7.3 GiB, the fill stage's 116 bytes a pixel.
//! A scene of 2 million more triangles (`path` at 64²) peaked 785
//! MiB higher, 412 bytes a triangle, of which the estimate counts 152.

use crate::backend::{Hit, Ray};
use crate::cache::LookupPoint;
use crate::method::ic::Candidate;
use crate::method::movies::HELD_HITS_BYTES;
use crate::method::render_pass::StillSamples;
use crate::render::MethodSettings;
use crate::sampling::Rng;
use crate::system_memory::bytes_text;
use glam::Vec3;
use std::mem::size_of;

/// Bytes a render holds whatever it renders (the program and its
/// threads): a 1×1 `path` frame peaks at 10.5 MiB on the CPU backend.
const BASE_BYTES: u64 = 8 << 20;

/// The film's bytes a pixel.
const FILM_BYTES: u64 = size_of::<Vec3>() as u64;

/// The PNG preview's bytes a pixel (8-bit RGB), beside the film while the
/// frame is written.
const PREVIEW_BYTES: u64 = 3;

/// A sample `trc` and `tcg` keep for the next frame
/// (`KeptTile::SAMPLE_BYTES`): ray, hit, stream, shadow (a ray and what
/// its light adds) and lookup index.
const KEPT_SAMPLE_BYTES: u64 = (size_of::<Ray>()
    + size_of::<Hit>()
    + size_of::<Rng>()
    + size_of::<Ray>()
    + size_of::<Vec3>()
    + size_of::<u32>()) as u64;

/// A camera sample of `movies`' item buffer: its hit (within
/// [`HELD_HITS_BYTES`] a frame), and whether it sees an emitter
/// (`EmitterEdges`).
const ITEM_HIT_BYTES: u64 = size_of::<Hit>() as u64;
const ITEM_FLAG_BYTES: u64 = size_of::<bool>() as u64;

/// The fill stage's bytes a pixel: a candidate, beside first the pixel
/// centre's ray and hit, then its clearance and visited flag.
const FILL_BYTES: u64 = (size_of::<Option<Candidate>>()
    + max(
        size_of::<Ray>() + size_of::<Hit>(),
        size_of::<Option<LookupPoint>>() + size_of::<bool>(),
    )) as u64;

/// A triangle's bytes: the frame's snapshot of it with its object and
/// material, the mesh's indices and material, and the BVH's copy in leaf
/// order with its snapshot and object ids.
const TRIANGLE_BYTES: u64 = (size_of::<crate::scene::Triangle>()
    + 2 * size_of::<u32>()
    + size_of::<[u32; 3]>()
    + size_of::<u32>()
    + size_of::<obvhs::triangle::Triangle>()
    + 2 * size_of::<u32>()) as u64;

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// The least peak memory, in bytes, that rendering `method` at `width` ×
/// `height` takes on a scene of `triangles` triangles (see the module's
/// documentation for what it counts, and how it compares with measured
/// peaks).
pub fn peak_bytes(method: &MethodSettings, width: u32, height: u32, triangles: u64) -> u64 {
    let pixels = u64::from(width) * u64::from(height);
    let samples = pixels.saturating_mul(u64::from(method.spp().max(1)));
    let (carried, transient, fill) = match method {
        MethodSettings::Path(_) => (0, 0, 0),
        MethodSettings::Ic(_) => (0, 0, FILL_BYTES),
        MethodSettings::Trc(_) | MethodSettings::Tcg(_) => {
            let kept = samples.min(StillSamples::BUDGET_BYTES as u64 / KEPT_SAMPLE_BYTES);
            (kept * KEPT_SAMPLE_BYTES, 0, FILL_BYTES)
        }
        MethodSettings::Movies(_) => {
            let hits = samples
                .saturating_mul(ITEM_HIT_BYTES)
                .min(HELD_HITS_BYTES as u64);
            (
                0,
                hits.saturating_add(samples.saturating_mul(ITEM_FLAG_BYTES)),
                0,
            )
        }
    };
    let render = carried
        .saturating_add(pixels.saturating_mul(FILM_BYTES))
        .saturating_add(transient);
    let write = carried.saturating_add(pixels.saturating_mul(FILM_BYTES + PREVIEW_BYTES));
    // The fill stage counts without the samples carried from the last
    // frame: a render of one frame has none then.
    let frame = render.max(write).max(pixels.saturating_mul(fill));
    BASE_BYTES
        .saturating_add(triangles.saturating_mul(TRIANGLE_BYTES))
        .saturating_add(frame)
}

/// The triangles of `scene`, every object's, as [`peak_bytes`] counts
/// them.
pub fn scene_triangles(scene: &crate::scene::Scene) -> u64 {
    let objects = scene.objects.iter();
    objects.map(|o| o.mesh.triangles.len() as u64).sum()
}

/// A render whose estimated peak is over the memory available.
#[derive(Clone, Debug, PartialEq)]
pub struct TooLarge {
    pub method: &'static str,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// [`peak_bytes`].
    pub need: u64,
    /// [`available_bytes`](crate::system_memory::available_bytes) when it was checked.
    pub available: u64,
}

impl std::fmt::Display for TooLarge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "a {}x{} {} render at {} spp needs at least {} of memory at its peak (estimated), \
             and {} is available",
            self.width,
            self.height,
            self.method,
            self.spp,
            bytes_text(self.need),
            bytes_text(self.available)
        )
    }
}

/// Whether rendering `method` at `width` × `height` on a scene of
/// `triangles` triangles fits in `available` bytes (`None`: unknown, so it
/// is not checked).
pub fn check_fits(
    method: &MethodSettings,
    (width, height): (u32, u32),
    triangles: u64,
    available: Option<u64>,
) -> Result<(), TooLarge> {
    let Some(available) = available else {
        return Ok(());
    };
    let need = peak_bytes(method, width, height, triangles);
    if need <= available {
        return Ok(());
    }
    Err(TooLarge {
        method: method.name(),
        width,
        height,
        spp: method.spp(),
        need,
        available,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::settings::method_settings;

    fn method(name: &str, settings: &[(&str, &str)]) -> MethodSettings {
        method_settings(name, settings.iter().copied()).unwrap()
    }

    const METHODS: [&str; 5] = ["path", "ic", "trc", "tcg", "movies"];

    /// More pixels, more samples or more triangles never need less.
    #[test]
    fn the_estimate_grows_with_pixels_samples_and_triangles() {
        for name in METHODS {
            let m = method(name, &[]);
            let mut last = 0;
            for side in [1, 64, 256, 512, 1024, 4096, 16384] {
                let need = peak_bytes(&m, side, side, 0);
                assert!(need > last, "{name} {side}²: {need} after {last}");
                last = need;
            }
            assert!(peak_bytes(&m, 512, 256, 0) < peak_bytes(&m, 512, 512, 0));
            assert!(peak_bytes(&m, 64, 64, 1000) > peak_bytes(&m, 64, 64, 0));
            let (few, many) = (
                method(name, &[("spp", "4")]),
                method(name, &[("spp", "64")]),
            );
            assert!(peak_bytes(&few, 512, 512, 0) <= peak_bytes(&many, 512, 512, 0));
        }
    }

    /// Past its small fixed part the estimate grows in proportion to the
    /// pixels, whatever the samples a pixel for `ic` (its render pass keeps
    /// no sample past its tile) and for `trc` past its kept samples'
    /// budget (which it fills by 1024² at 16 spp): at the fill stage's
    /// rate; `path` at the film's.
    #[test]
    fn the_estimate_scales_with_the_frame() {
        let rate = |name: &str, spp: &str| {
            let m = method(name, &[("spp", spp)]);
            let (small, large) = (peak_bytes(&m, 4096, 4096, 0), peak_bytes(&m, 8192, 8192, 0));
            (large - small) as f64 / (8192.0 * 8192.0 - 4096.0 * 4096.0)
        };
        assert_eq!(rate("ic", "16"), FILL_BYTES as f64);
        assert_eq!(rate("ic", "64"), rate("ic", "16"));
        assert_eq!(rate("trc", "16"), rate("ic", "16"));
        assert_eq!(rate("path", "16"), (FILM_BYTES + PREVIEW_BYTES) as f64);
        // The kept samples stop growing at their budget.
        let ic = method("ic", &[]);
        let trc = method("trc", &[]);
        let kept = |side| peak_bytes(&trc, side, side, 0) - peak_bytes(&ic, side, side, 0);
        assert!(kept(256) < kept(512));
        assert!(kept(1024) <= StillSamples::BUDGET_BYTES as u64);
        // 8192² at 16 spp: the fill stage's bytes a pixel.
        let gib = peak_bytes(&trc, 8192, 8192, 0) as f64 / (1u64 << 30) as f64;
        assert!((6.0..9.0).contains(&gib), "{gib} GiB");
    }

    /// A frame far past any machine saturates rather than overflows.
    #[test]
    fn the_estimate_does_not_overflow() {
        let huge = method("movies", &[("spp", "1000000")]);
        assert_eq!(peak_bytes(&huge, u32::MAX, u32::MAX, u64::MAX), u64::MAX);
        let trc = method("trc", &[("spp", "1000000")]);
        assert_eq!(peak_bytes(&trc, u32::MAX, u32::MAX, 0), u64::MAX);
    }

    #[test]
    fn a_render_over_what_is_available_is_refused_with_both_amounts() {
        let trc = method("trc", &[]);
        assert_eq!(check_fits(&trc, (8192, 8192), 0, None), Ok(()));
        assert_eq!(check_fits(&trc, (8192, 8192), 0, Some(u64::MAX)), Ok(()));
        let need = peak_bytes(&trc, 8192, 8192, 0);
        assert_eq!(check_fits(&trc, (8192, 8192), 0, Some(need)), Ok(()));
        let available = 5_300 << 20;
        let refused = check_fits(&trc, (8192, 8192), 0, Some(available)).unwrap_err();
        assert_eq!((refused.need, refused.available), (need, available));
        assert_eq!(
            refused.to_string(),
            format!(
                "a 8192x8192 trc render at 16 spp needs at least {} of memory at its peak \
                 (estimated), and 5.2 GiB is available",
                bytes_text(need)
            )
        );
        assert!(check_fits(&trc, (8192, 8192), 0, Some(need - 1)).is_err());
        assert_eq!(check_fits(&trc, (256, 256), 0, Some(available)), Ok(()));
    }
}
