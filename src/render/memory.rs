//! A render's peak memory, estimated before it starts, and the memory this
//! process may still take: `radcache render`, `bench` and `POST /api/jobs`
//! refuse a render whose estimate is over what is available, with an
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
//!   bytes a pixel while the frame is written;
//! - `trc` and `tcg`: the samples of still tiles kept for the next frame
//!   ([`StillSamples`], within its budget of
//!   [`StillSamples::BUDGET_BYTES`]), from frame to frame (the render
//!   pass frees the rays and hits of the others with their tile,
//!   `render_pass::still_tile::TileKept::of`); `ic`, `trc` and `tcg`:
//!   before the pass, their fill stage holds a ray, hit and candidate a pixel
//!   (`ic::primary_candidates`), then the candidates, their clearances and
//!   a visited flag (`ic`'s `fill_from`);
//! - `movies`: its item buffer, every camera sample with its ray, stream
//!   and hit, held for the whole frame (`TextureMovies::trace_tiles`);
//! - per triangle, the frame's snapshot of it, the mesh's indices and
//!   material, and the BVH's copy of it in leaf order with its ids.
//!
//! # Measured
//! Peak resident memory of `radcache render --method M --size S --frames
//! 0..2 -q --out DIR` (built-in cube-in-box, release build, CPU backend
//! after `auto`'s GPU probe, 2 threads, `/usr/bin/time -f %M`, one run
//! each) against [`peak_bytes`], MiB; `ic`, `trc` and `tcg` since the
//! render pass frees the rays and hits it does not keep, the others before
//! (their rows did not change with it):
//!
//! | method | size | measured | estimated | ratio |
//! | --- | ---: | ---: | ---: | ---: |
//! | `path` | 256² | 70 | 9 | 0.13 |
//! | `path` | 1024² | 94 | 23 | 0.24 |
//! | `ic` | 256² | 78 | 15 | 0.19 |
//! | `ic` | 512² | 119 | 37 | 0.31 |
//! | `ic` | 1024² | 234 | 124 | 0.53 |
//! | `trc` | 256² | 377 | 125 | 0.33 |
//! | `trc` | 512² | 935 | 476 | 0.51 |
//! | `trc` | 1024² | 1,233 | 535 | 0.43 |
//! | `tcg` | 256² | 229 | 125 | 0.55 |
//! | `tcg` | 512² | 655 | 476 | 0.73 |
//! | `tcg` | 1024² | 811 | 535 | 0.66 |
//! | `movies` | 256² | 555 | 93 | 0.17 |
//! | `movies` | 512² | 1,295 | 347 | 0.27 |
//! | `movies` | 1024² | 2,939 | 1,364 | 0.46 |
//! | `movies --movies-texels-per-pixel 2` | 256² | 1,000 | 93 | 0.09 |
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
use crate::method::pixels::PixelSample;
use crate::method::render_pass::StillSamples;
use crate::render::MethodSettings;
use crate::sampling::Rng;
use glam::Vec3;
use std::mem::size_of;
use std::path::{Path, PathBuf};

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

/// A camera sample of `movies`' item buffer: the sample, its ray, its
/// stream and its hit.
const ITEM_SAMPLE_BYTES: u64 =
    (size_of::<PixelSample>() + size_of::<Ray>() + size_of::<Rng>() + size_of::<Hit>()) as u64;

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
        MethodSettings::Movies(_) => (0, samples.saturating_mul(ITEM_SAMPLE_BYTES), 0),
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
    /// [`available_bytes`] when it was checked.
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

/// `21.3 GiB`, `512 MiB`, `1.3 TiB`.
pub fn bytes_text(bytes: u64) -> String {
    const GIB: f64 = (1u64 << 30) as f64;
    const TIB: f64 = (1u64 << 40) as f64;
    if bytes >= 1 << 40 {
        // A frame no machine holds: TiB reads better than a million GiB.
        format!("{:.1} TiB", bytes as f64 / TIB)
    } else if bytes >= 1 << 30 {
        format!("{:.1} GiB", bytes as f64 / GIB)
    } else {
        format!("{} MiB", bytes.div_ceil(1 << 20))
    }
}

/// Bytes this process may still take: the least of the memory the kernel
/// can give without swapping (`MemAvailable`, which counts the caches it
/// can reclaim), the room under its cgroup's memory limit (and its
/// parents'), and the room under its address-space limit (`ulimit -v`).
/// `None` where none of them can be read (not Linux): then nothing is
/// checked.
pub fn available_bytes() -> Option<u64> {
    let read = |path: &Path| std::fs::read_to_string(path).ok();
    let kernel = read(Path::new("/proc/meminfo")).and_then(|t| meminfo_available(&t));
    let cgroups = read(Path::new("/proc/self/cgroup")).map_or_else(Vec::new, |t| cgroup_limits(&t));
    let cgroup = cgroups
        .iter()
        .filter_map(|(limit, usage)| cgroup_room(&read(limit)?, &read(usage)?))
        .min();
    let address_space = read(Path::new("/proc/self/limits"))
        .zip(read(Path::new("/proc/self/status")))
        .and_then(|(limits, status)| address_space_room(&limits, &status));
    [kernel, cgroup, address_space].into_iter().flatten().min()
}

/// This process's resident memory in bytes (`VmRSS`); `None` where it
/// cannot be read.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    kib_field(&status, "VmRSS:").map(|kib| kib * 1024)
}

/// `MemAvailable` of /proc/meminfo, in bytes.
fn meminfo_available(meminfo: &str) -> Option<u64> {
    kib_field(meminfo, "MemAvailable:").map(|kib| kib * 1024)
}

/// The number of a `Field:   123 kB` line.
fn kib_field(text: &str, field: &str) -> Option<u64> {
    let line = text.lines().find_map(|l| l.strip_prefix(field))?;
    line.split_whitespace().next()?.parse().ok()
}

/// Room under `ulimit -v`: the soft `Max address space` of
/// /proc/self/limits less the `VmSize` of /proc/self/status; `None` when
/// unlimited.
fn address_space_room(limits: &str, status: &str) -> Option<u64> {
    let soft = limits
        .lines()
        .find_map(|l| l.strip_prefix("Max address space"))?
        .split_whitespace()
        .next()?;
    let limit: u64 = soft.parse().ok()?; // "unlimited" is not a number.
    let size = kib_field(status, "VmSize:")? * 1024;
    Some(limit.saturating_sub(size))
}

/// Room under a cgroup's memory limit: its limit (`memory.max`, or v1's
/// `memory.limit_in_bytes`) less its usage; `None` when unlimited (`max`).
fn cgroup_room(limit: &str, usage: &str) -> Option<u64> {
    let limit: u64 = limit.trim().parse().ok()?;
    let usage: u64 = usage.trim().parse().ok()?;
    Some(limit.saturating_sub(usage))
}

/// The (limit, usage) files of the memory limits this process lives
/// under, from /proc/self/cgroup: its cgroup's and every one above it, in
/// the unified (v2) hierarchy, mounted at /sys/fs/cgroup or, beside v1's,
/// at /sys/fs/cgroup/unified, and in v1's memory hierarchy. A container
/// whose cgroups are mounted at its own shows its limit at the mount's
/// root, which the walk up reaches.
fn cgroup_limits(proc_cgroup: &str) -> Vec<(PathBuf, PathBuf)> {
    let mut files = Vec::new();
    for line in proc_cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let (mounts, limit, usage): (&[&str], _, _) = if controllers.is_empty() {
            (
                &["/sys/fs/cgroup", "/sys/fs/cgroup/unified"],
                "memory.max",
                "memory.current",
            )
        } else if controllers.split(',').any(|c| c == "memory") {
            (
                &["/sys/fs/cgroup/memory"],
                "memory.limit_in_bytes",
                "memory.usage_in_bytes",
            )
        } else {
            continue;
        };
        let relative = Path::new(path.trim_start_matches('/'));
        for mount in mounts {
            for dir in relative.ancestors() {
                let dir = Path::new(mount).join(dir);
                files.push((dir.join(limit), dir.join(usage)));
            }
        }
    }
    files
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

    #[test]
    fn byte_counts_read_in_mib_or_gib() {
        assert_eq!(bytes_text(0), "0 MiB");
        assert_eq!(bytes_text(1), "1 MiB");
        assert_eq!(bytes_text(512 << 20), "512 MiB");
        assert_eq!(bytes_text((1 << 30) - 1), "1024 MiB");
        assert_eq!(bytes_text(1 << 30), "1.0 GiB");
        assert_eq!(bytes_text(190 << 30), "190.0 GiB");
        assert_eq!(bytes_text((1 << 40) - (1 << 20)), "1024.0 GiB");
        assert_eq!(bytes_text(1 << 40), "1.0 TiB");
        assert_eq!(bytes_text(u64::MAX), "16777216.0 TiB");
    }

    const MEMINFO: &str = "MemTotal:       24523716 kB\nMemFree:        22103416 kB\n\
                           MemAvailable:   22342288 kB\nBuffers:          113452 kB\n";

    const STATUS: &str = "Name:\tradcache\nVmPeak:\t  220000 kB\nVmSize:\t  204800 kB\n\
                          VmHWM:\t   70000 kB\nVmRSS:\t   65536 kB\n";

    #[test]
    fn meminfo_gives_the_available_memory() {
        assert_eq!(meminfo_available(MEMINFO), Some(22_342_288 * 1024));
        assert_eq!(meminfo_available("MemTotal: 1 kB\n"), None);
        assert_eq!(meminfo_available("MemAvailable: lots kB\n"), None);
        assert_eq!(kib_field(STATUS, "VmRSS:"), Some(65536));
    }

    #[test]
    fn the_address_space_limit_leaves_the_limit_less_the_mapped_size() {
        let limits = |soft: &str| {
            format!(
                "Limit                     Soft Limit           Hard Limit           Units\n\
                 Max stack size            8388608              unlimited            bytes\n\
                 Max address space         {soft:<20} unlimited            bytes\n"
            )
        };
        assert_eq!(address_space_room(&limits("unlimited"), STATUS), None);
        assert_eq!(
            address_space_room(&limits("1073741824"), STATUS),
            Some((1 << 30) - 204_800 * 1024)
        );
        assert_eq!(address_space_room(&limits("1000"), STATUS), Some(0));
        assert_eq!(
            address_space_room(&limits("1073741824"), "VmRSS: 1 kB\n"),
            None
        );
    }

    #[test]
    fn a_cgroup_limit_leaves_the_limit_less_the_usage() {
        assert_eq!(cgroup_room("max\n", "123\n"), None);
        assert_eq!(cgroup_room("4294967296\n", "1073741824\n"), Some(3 << 30));
        assert_eq!(cgroup_room("100\n", "200\n"), Some(0));
        assert_eq!(cgroup_room("", "1"), None);
    }

    /// v2's limits are looked for in the process's cgroup and each above
    /// it under both of v2's mount points; v1's in its memory hierarchy;
    /// other v1 controllers are not memory limits.
    #[test]
    fn the_cgroup_limits_are_the_process_cgroup_and_its_parents() {
        let v2 = cgroup_limits("0::/user.slice/job\n");
        let limits: Vec<&Path> = v2.iter().map(|(l, _)| l.as_path()).collect();
        assert_eq!(
            limits,
            [
                "/sys/fs/cgroup/user.slice/job/memory.max",
                "/sys/fs/cgroup/user.slice/memory.max",
                "/sys/fs/cgroup/memory.max",
                "/sys/fs/cgroup/unified/user.slice/job/memory.max",
                "/sys/fs/cgroup/unified/user.slice/memory.max",
                "/sys/fs/cgroup/unified/memory.max",
            ]
            .map(Path::new)
        );
        assert_eq!(
            v2[0].1,
            Path::new("/sys/fs/cgroup/user.slice/job/memory.current")
        );
        let v1 = cgroup_limits("5:cpu,cpuacct:/a\n4:memory:/docker/abc\n0::/\n");
        let limits: Vec<&Path> = v1.iter().map(|(l, _)| l.as_path()).collect();
        assert_eq!(
            limits,
            [
                "/sys/fs/cgroup/memory/docker/abc/memory.limit_in_bytes",
                "/sys/fs/cgroup/memory/docker/memory.limit_in_bytes",
                "/sys/fs/cgroup/memory/memory.limit_in_bytes",
                "/sys/fs/cgroup/memory.max",
                "/sys/fs/cgroup/unified/memory.max",
            ]
            .map(Path::new)
        );
        assert!(cgroup_limits("").is_empty());
        assert!(cgroup_limits("garbage\n").is_empty());
    }

    /// On Linux something is always known (MemAvailable at least), and
    /// it is less than all of the machine.
    #[cfg(target_os = "linux")]
    #[test]
    fn this_machine_has_some_memory_available() {
        let available = available_bytes().expect("Linux reports MemAvailable");
        assert!(available > 0);
        assert!(resident_bytes().is_some_and(|r| r > 0));
    }
}
