//! `compare_dirs` on folders of frames: the reference copies in
//! `tests/data/reference/` (see its SOURCE.md) and small synthetic sequences.

use glam::Vec3;
use radcache::film::{decode_exr, frame_path, read_exr, write_exr, Film};
use radcache::metrics::{
    compare_dirs, compare_dirs_with, error_map_path, light_mask_path, mean_error_map_path,
    write_light_mask, MetricsError,
};
use std::fs;
use std::path::{Path, PathBuf};

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/reference")
        .join(rel)
}

fn constant(w: u32, h: u32, v: f32) -> Film {
    Film {
        width: w,
        height: h,
        pixels: vec![Vec3::splat(v); (w * h) as usize],
    }
}

fn offset(f: &Film, c: f32) -> Film {
    let mut t = f.clone();
    t.pixels.iter_mut().for_each(|p| *p += Vec3::splat(c));
    t
}

/// Writes `frames` as `dir/frame_NNNN.exr`.
fn write_seq(dir: &Path, frames: &[(u32, Film)]) {
    fs::create_dir_all(dir).unwrap();
    for (n, f) in frames {
        write_exr(f, &frame_path(dir, *n, "exr")).unwrap();
    }
}

#[test]
fn seed0_against_seed1_matches_source_md() {
    // SOURCE.md "Noise": RMSE(seed0 − seed1) = 0.0189 for cube_in_box.
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("seed0"), tmp.path().join("seed1"));
    fs::create_dir_all(&a).unwrap();
    fs::create_dir_all(&b).unwrap();
    fs::copy(data("cube_in_box/frame_0000.exr"), a.join("frame_0000.exr")).unwrap();
    fs::copy(
        data("cube_in_box/seed1_frame_0000.exr"),
        b.join("frame_0000.exr"),
    )
    .unwrap();
    let report = compare_dirs(&a, &b).unwrap();
    assert_eq!(report.frames, 1);
    assert!(
        (report.rmse / 0.0189 - 1.0).abs() < 0.05,
        "rmse {}",
        report.rmse
    );
    // Relative: 0.034 in SOURCE.md.
    assert!(
        (report.rel_rmse / 0.034 - 1.0).abs() < 0.05,
        "rel {}",
        report.rel_rmse
    );
    // Two noisy images with the same expectation: little block bias.
    assert!(
        report.block_bias < 0.2 * report.rel_rmse,
        "block {}",
        report.block_bias
    );
    assert_eq!(report.flicker, None);
}

/// `--error-maps`: one PNG a frame, in a folder made for them, red where
/// that frame's test is brighter, blue where darker, grey where equal;
/// the figures are those of a compare without maps.
#[test]
fn error_maps_show_where_each_frame_is_off() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("ref"), tmp.path().join("test"));
    let reference = constant(8, 4, 0.5);
    let mut left_brighter = reference.clone();
    for (i, p) in left_brighter.pixels.iter_mut().enumerate() {
        if i % 8 < 4 {
            *p *= 1.3;
        }
    }
    let darker = constant(8, 4, 0.35);
    write_seq(&a, &[(0, reference.clone()), (1, reference)]);
    write_seq(&b, &[(0, left_brighter), (1, darker)]);
    let maps = tmp.path().join("maps/nested");
    let report = compare_dirs_with(&a, &b, Some(&maps)).unwrap();
    assert_eq!(
        serde_json::to_string(&report).unwrap(),
        serde_json::to_string(&compare_dirs(&a, &b).unwrap()).unwrap()
    );
    let read = |frame| image::open(error_map_path(&maps, frame)).unwrap().to_rgb8();
    let first = read(0);
    assert_eq!(first.dimensions(), (8, 4));
    for (x, _, p) in first.enumerate_pixels() {
        let [r, g, b] = p.0;
        if x < 4 {
            assert_eq!([r, g, b], [255, 0, 0], "+30 % at x = {x}");
        } else {
            assert!(r == g && g == b && r > 0, "equal at x = {x}: {:?}", p.0);
        }
    }
    assert!(read(1).pixels().all(|p| p.0 == [0, 0, 255]), "−30 %");
    // The means: the left half +30 % then −30 % is the reference's mean
    // (grey), the right half equal then −30 % is −15 % (blue, not full).
    let mean = image::open(mean_error_map_path(&maps)).unwrap().to_rgb8();
    for (x, _, p) in mean.enumerate_pixels() {
        let [r, g, b] = p.0;
        if x < 4 {
            assert!(r == g && g == b && r > 0, "mean at x = {x}: {:?}", p.0);
        } else {
            assert!(b > r && r == g && b < 255, "mean at x = {x}: {:?}", p.0);
        }
    }
}

#[test]
fn reference_folder_against_itself() {
    // Frames 0, 12, 23: seed1_frame_0000.exr is not a frame; no consecutive pair.
    let dir = data("cube_in_box");
    let report = compare_dirs(&dir, &dir).unwrap();
    assert_eq!(report.frames, 3);
    let numbers: Vec<u32> = report.per_frame.iter().map(|f| f.frame).collect();
    assert_eq!(numbers, [0, 12, 23]);
    assert_eq!(
        (report.rmse, report.rel_rmse, report.block_bias),
        (0.0, 0.0, 0.0)
    );
    assert_eq!(report.flicker, None);
}

#[test]
fn json_has_the_specified_keys() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let refs: Vec<(u32, Film)> = (0..3).map(|k| (k, constant(20, 18, 1.0))).collect();
    let tests: Vec<(u32, Film)> = refs.iter().map(|(k, f)| (*k, offset(f, 0.5))).collect();
    write_seq(&r, &refs);
    write_seq(&t, &tests);
    let report = compare_dirs(&r, &t).unwrap();
    let json = serde_json::to_value(&report).unwrap();
    let keys: Vec<&str> = json
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    let mut want = [
        "frames",
        "rmse",
        "rel_rmse",
        "block_bias",
        "rel_rmse_surfaces",
        "flicker",
        "flicker_surfaces",
        "per_frame",
    ];
    let mut got = keys.clone();
    got.sort();
    want.sort();
    assert_eq!(got, want);
    assert_eq!(json["frames"], 3);
    assert!((json["rmse"].as_f64().unwrap() - 0.5).abs() < 1e-6);
    assert!((json["rel_rmse"].as_f64().unwrap() - 0.5).abs() < 1e-6);
    assert_eq!(json["flicker"].as_f64().unwrap(), 0.0); // constant bias: no flicker
    let first = json["per_frame"][0].as_object().unwrap();
    let mut frame_keys: Vec<&str> = first.keys().map(String::as_str).collect();
    frame_keys.sort();
    assert_eq!(
        frame_keys,
        ["block_bias", "flicker", "frame", "rel_rmse", "rmse"]
    );
    // Frame 0 has no frame before it.
    assert!(json["per_frame"][0]["flicker"].is_null());
    assert_eq!(json["per_frame"][1]["flicker"].as_f64().unwrap(), 0.0);
    // The text table: header, three frames, overall.
    assert_eq!(report.to_text().lines().count(), 5);
}

#[test]
fn a_frame_that_jumps_shows_in_the_flicker_of_the_pairs_around_it() {
    // Frames 0..5 with I = R, but frame 2 brighter by e everywhere (a pop,
    // as of records all replaced at once): the pairs (1,2) and (2,3) change
    // by ±e more than the reference, the others not at all. The sequence's
    // squared flicker is the mean of the pairs'.
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let (e, mean) = (0.25, 2.0);
    let refs: Vec<(u32, Film)> = (0..5).map(|k| (k, constant(6, 4, mean))).collect();
    let tests: Vec<(u32, Film)> = refs
        .iter()
        .map(|(k, f)| (*k, offset(f, if *k == 2 { e } else { 0.0 })))
        .collect();
    write_seq(&r, &refs);
    write_seq(&t, &tests);
    let report = compare_dirs(&r, &t).unwrap();
    let per_frame: Vec<Option<f64>> = report.per_frame.iter().map(|f| f.flicker).collect();
    let jump = f64::from(e / mean);
    assert_eq!(per_frame[0], None);
    for (k, want) in [(1, 0.0), (2, jump), (3, jump), (4, 0.0)] {
        let got = per_frame[k].unwrap();
        assert!((got - want).abs() < 1e-9, "frame {k}: {got}, want {want}");
    }
    let pairs_mean_sq = (2.0 * jump * jump) / 4.0;
    let flicker = report.flicker.unwrap();
    assert!((flicker - pairs_mean_sq.sqrt()).abs() < 1e-9, "{flicker}");
    // The text table shows them in the flicker column.
    let text = report.to_text();
    let row = |k: usize| text.lines().nth(1 + k).unwrap().to_string();
    assert_eq!(row(0).split_whitespace().count(), 4, "{text}");
    assert!(row(2).trim_end().ends_with(&format!("{jump:.6}")), "{text}");
}

#[test]
fn flicker_uses_only_consecutive_frames() {
    // Frames 0, 1, 3 with I = R + e·(−1)^n. Pair (0,1) differs by 2e; the
    // (1,3) gap would add a zero difference and lower the RMS to √2·e.
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let e = 0.125;
    let refs: Vec<(u32, Film)> = [0, 1, 3]
        .iter()
        .map(|&k| (k, constant(8, 8, 1.0)))
        .collect();
    let tests: Vec<(u32, Film)> = refs
        .iter()
        .map(|(k, f)| (*k, offset(f, if k % 2 == 0 { e } else { -e })))
        .collect();
    write_seq(&r, &refs);
    write_seq(&t, &tests);
    let report = compare_dirs(&r, &t).unwrap();
    let flicker = report.flicker.unwrap();
    assert!((flicker - 2.0 * f64::from(e)).abs() < 1e-9, "{flicker}");
    // Frame 3's frame before it, 2, is not among them.
    assert_eq!(report.per_frame[2].flicker, None);
}

#[test]
fn extra_test_frames_are_ignored() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    write_seq(&r, &[(0, constant(4, 4, 1.0))]);
    write_seq(&t, &[(0, constant(4, 4, 1.0)), (1, constant(4, 4, 9.0))]);
    let report = compare_dirs(&r, &t).unwrap();
    assert_eq!((report.frames, report.rmse), (1, 0.0));
}

#[test]
fn missing_frame_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    write_seq(&r, &[(0, constant(4, 4, 1.0)), (1, constant(4, 4, 1.0))]);
    write_seq(&t, &[(0, constant(4, 4, 1.0))]);
    let err = compare_dirs(&r, &t).unwrap_err();
    assert!(matches!(err, MetricsError::MissingFrame { .. }), "{err}");
    assert!(
        err.to_string()
            .contains(&*t.join("frame_0001.exr").to_string_lossy()),
        "{err}"
    );
}

#[test]
fn size_mismatch_names_both_files() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    write_seq(&r, &[(0, constant(4, 4, 1.0))]);
    write_seq(&t, &[(0, constant(5, 4, 1.0))]);
    let err = compare_dirs(&r, &t).unwrap_err();
    assert!(matches!(err, MetricsError::SizeMismatch { .. }), "{err}");
    let message = err.to_string();
    for needle in ["ref/frame_0000.exr", "test/frame_0000.exr", "4×4", "5×4"] {
        assert!(message.contains(needle), "{needle} not in {message}");
    }
}

#[test]
fn a_nan_or_infinite_pixel_names_the_file_and_the_pixel() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let mut bad = constant(4, 4, 1.0);
    bad.pixels[4 * 2 + 3] = Vec3::new(1.0, f32::INFINITY, 0.0);
    write_seq(&r, &[(0, constant(4, 4, 1.0)), (1, constant(4, 4, 1.0))]);
    write_seq(&t, &[(0, constant(4, 4, 1.0)), (1, bad)]);
    let err = compare_dirs(&r, &t).unwrap_err();
    assert!(matches!(err, MetricsError::NonFinite { .. }), "{err}");
    let message = err.to_string();
    for needle in ["test/frame_0001.exr", "pixel (3, 2)", "inf"] {
        assert!(message.contains(needle), "{needle} not in {message}");
    }
}

#[test]
fn empty_or_absent_reference_folder_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let err = compare_dirs(tmp.path(), tmp.path()).unwrap_err();
    assert!(matches!(err, MetricsError::NoFrames { .. }), "{err}");
    let absent = tmp.path().join("nope");
    let err = compare_dirs(&absent, tmp.path()).unwrap_err();
    assert!(err.to_string().contains("nope"), "{err}");
}

#[test]
fn unreadable_test_frame_names_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    write_seq(&r, &[(0, constant(4, 4, 1.0))]);
    fs::create_dir_all(&t).unwrap();
    fs::write(t.join("frame_0000.exr"), "garbage").unwrap();
    let err = compare_dirs(&r, &t).unwrap_err();
    assert!(err.to_string().contains("test/frame_0000.exr"), "{err}");
}

#[test]
fn light_masks_leave_their_pixels_out_of_the_surface_error() {
    // 4×4 frames, reference 1 everywhere but 30 in the first pixel (a light).
    // The test is off by 10 at the light and by 0.1 elsewhere: the all-pixel
    // RMSE is dominated by the light's pixel, the surface error is 0.1 / 1.
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let mut reference = constant(4, 4, 1.0);
    reference.pixels[0] = Vec3::splat(30.0);
    let mut test = offset(&reference, 0.1);
    test.pixels[0] = Vec3::splat(40.0);
    write_seq(&r, &[(0, reference.clone()), (1, reference.clone())]);
    write_seq(&t, &[(0, test.clone()), (1, test.clone())]);
    let no_masks = compare_dirs(&r, &t).unwrap();
    assert_eq!(no_masks.rel_rmse_surfaces, None);

    let mut lights = vec![false; 16];
    lights[0] = true;
    for frame in [0, 1] {
        write_light_mask(&light_mask_path(&r, frame), 4, 4, &lights).unwrap();
    }
    let report = compare_dirs(&r, &t).unwrap();
    let surfaces = report.rel_rmse_surfaces.unwrap();
    assert!((surfaces - 0.1).abs() < 1e-6, "{surfaces}");
    assert!(report.rel_rmse > 5.0 * surfaces, "{}", report.rel_rmse);
    assert_eq!(report.rel_rmse, no_masks.rel_rmse);
    // Same error in both frames: no flicker anywhere.
    assert!(report.flicker_surfaces.unwrap() < 1e-7);
    assert!(report.to_text().contains("directly seen lights"));

    // One frame without its mask: no surface figure rather than a partial one.
    fs::remove_file(light_mask_path(&r, 1)).unwrap();
    let partial = compare_dirs(&r, &t).unwrap();
    assert_eq!(
        (partial.rel_rmse_surfaces, partial.flicker_surfaces),
        (None, None)
    );

    // A mask of the wrong size is an error naming the file.
    write_light_mask(&light_mask_path(&r, 1), 2, 8, &[false; 16]).unwrap();
    let e = compare_dirs(&r, &t).unwrap_err();
    assert!(matches!(e, MetricsError::Mask { .. }), "{e}");
    assert!(e.to_string().contains("seen_lights_0001.png"), "{e}");
}

/// The bytes of an EXR whose header declares `width`×`height` pixels of R,
/// G, B f32 scanlines compressed with `compression` (OpenEXR's code: 0 none,
/// 3 ZIP), followed by `padding` zero bytes where the offset table and the
/// pixels should be — a file that may not hold what it declares.
fn declared_exr(width: i32, height: i32, compression: u8, padding: usize) -> Vec<u8> {
    fn attribute(out: &mut Vec<u8>, name: &str, kind: &str, data: &[u8]) {
        for text in [name, kind] {
            out.extend(text.as_bytes());
            out.push(0);
        }
        out.extend((data.len() as i32).to_le_bytes());
        out.extend(data);
    }
    let mut channels = Vec::new();
    for name in ["B", "G", "R"] {
        channels.extend(name.as_bytes());
        channels.push(0);
        // f32, not linear, 3 reserved bytes, sampling 1×1.
        channels.extend(2_i32.to_le_bytes());
        channels.extend([0_u8; 4]);
        channels.extend(1_i32.to_le_bytes());
        channels.extend(1_i32.to_le_bytes());
    }
    channels.push(0);
    let window: Vec<u8> = [0, 0, width - 1, height - 1]
        .iter()
        .flat_map(|v: &i32| v.to_le_bytes())
        .collect();
    let mut out = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
    attribute(&mut out, "channels", "chlist", &channels);
    attribute(&mut out, "compression", "compression", &[compression]);
    attribute(&mut out, "dataWindow", "box2i", &window);
    attribute(&mut out, "displayWindow", "box2i", &window);
    attribute(&mut out, "lineOrder", "lineOrder", &[0]);
    attribute(&mut out, "pixelAspectRatio", "float", &1_f32.to_le_bytes());
    attribute(&mut out, "screenWindowCenter", "v2f", &[0; 8]);
    attribute(&mut out, "screenWindowWidth", "float", &1_f32.to_le_bytes());
    out.push(0);
    out.resize(out.len() + padding, 0);
    out
}

/// A 600-byte file that declares 60000×60000 uncompressed pixels (60000
/// chunks, so at least 960000 bytes) is refused from its header, naming
/// the file and the size, before a 43 GB image is allocated.
#[test]
fn a_file_shorter_than_its_declared_chunks_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("huge");
    fs::create_dir_all(&dir).unwrap();
    let path = frame_path(&dir, 0, "exr");
    fs::write(&path, declared_exr(60000, 60000, 0, 64)).unwrap();
    let err = read_exr(&path).unwrap_err();
    let message = err.to_string();
    for needle in ["huge/frame_0000.exr", "60000×60000", "960000 bytes"] {
        assert!(message.contains(needle), "{needle} not in {message}");
    }
    let err = compare_dirs(&dir, &dir).unwrap_err();
    assert!(err.to_string().contains("60000×60000"), "{err}");
}

/// A file that holds every chunk its header needs, but whose declared size
/// (10⁹×1024 pixels: 12 TB decoded) no machine's memory holds, is refused
/// before anything of that size is allocated, naming both sizes.
#[test]
fn a_declared_size_beyond_memory_is_refused() {
    if radcache::system_memory::available_bytes().is_none() {
        return; // nothing to check against (not Linux)
    }
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("wide.exr");
    // ZIP: 16 lines a chunk, so 64 chunks of at least 16 bytes each.
    fs::write(&path, declared_exr(1_000_000_000, 1024, 3, 2048)).unwrap();
    let err = read_exr(&path).unwrap_err();
    let message = err.to_string();
    for needle in ["wide.exr", "1000000000×1024", "11.2 TiB", "available"] {
        assert!(message.contains(needle), "{needle} not in {message}");
    }
    // The store's bytes are checked alike.
    let err = decode_exr(&fs::read(&path).unwrap()).unwrap_err();
    assert!(err.to_string().contains("1000000000×1024"), "{err}");
}

/// Radiance is never negative: a negative channel is an error naming the
/// file, the pixel and the channel (before, the relative figures came out
/// negative). −0.0 is not negative.
#[test]
fn a_negative_pixel_names_the_file_the_pixel_and_the_channel() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let mut reference = constant(4, 3, 0.5);
    reference.pixels[4 + 2] = Vec3::new(0.5, -1.0, 0.5);
    write_seq(&r, &[(0, reference)]);
    write_seq(&t, &[(0, constant(4, 3, 0.5))]);
    let err = compare_dirs(&r, &t).unwrap_err();
    let message = err.to_string();
    for needle in ["ref/frame_0000.exr", "pixel (2, 1)", "G", "-1", "negative"] {
        assert!(message.contains(needle), "{needle} not in {message}");
    }

    let mut zero = constant(4, 3, 0.5);
    zero.pixels[0] = Vec3::new(-0.0, 0.5, 0.5);
    write_seq(&t, &[(0, zero)]);
    write_seq(&r, &[(0, constant(4, 3, 0.5))]);
    compare_dirs(&r, &t).unwrap();
    compare_dirs(&t, &r).unwrap();
}

/// A reference of 3·10³⁸ everywhere: its mean overflowed f32 (three
/// channels summed), which made every relative figure 0.
#[test]
fn huge_references_give_the_right_relative_figures() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let huge = constant(5, 4, 3e38);
    write_seq(&r, &[(0, huge.clone()), (1, huge.clone())]);
    write_seq(&t, &[(0, constant(5, 4, 0.5)), (1, huge)]);
    let report = compare_dirs(&r, &t).unwrap();
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
    // Frame 0 is off by (all of) the reference, frame 1 exact.
    assert!(close(report.per_frame[0].rel_rmse, 1.0), "{report:?}");
    assert!(close(report.per_frame[0].block_bias, 1.0), "{report:?}");
    assert!(close(report.rel_rmse, 0.5_f64.sqrt()), "{report:?}");
    assert!(close(report.block_bias, 0.5_f64.sqrt()), "{report:?}");
    // The test changes by the reference's value, the reference not at all.
    assert!(close(report.flicker.unwrap(), 1.0), "{report:?}");
}

/// Runs `f` on another thread and gives its result, failing (rather than
/// hanging) if it takes longer than `seconds`: reading a FIFO blocks.
fn within<T: Send + 'static>(seconds: u64, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(f());
    });
    receive
        .recv_timeout(std::time::Duration::from_secs(seconds))
        .expect("still blocked: a FIFO was opened")
}

/// A frame that is a directory, a FIFO or a link to a device is said to be
/// no regular file (it was "missing"), and a FIFO is not opened (which
/// would block); a light mask likewise.
#[cfg(unix)]
#[test]
fn a_frame_that_is_not_a_regular_file_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    write_seq(&r, &[(0, constant(4, 4, 1.0)), (1, constant(4, 4, 1.0))]);
    write_seq(&t, &[(1, constant(4, 4, 1.0))]);
    let frame = frame_path(&t, 0, "exr");
    let fifo = |path: &Path| {
        let made = std::process::Command::new("mkfifo").arg(path).status();
        assert!(made.unwrap().success());
    };
    for what in ["directory", "link to /dev/zero", "FIFO"] {
        match what {
            "directory" => fs::create_dir(&frame).unwrap(),
            "FIFO" => fifo(&frame),
            _ => std::os::unix::fs::symlink("/dev/zero", &frame).unwrap(),
        }
        let (r2, t2) = (r.clone(), t.clone());
        let err = within(20, move || compare_dirs(&r2, &t2).unwrap_err());
        let message = err.to_string();
        assert!(
            message.contains("test/frame_0000.exr") && message.contains("not a regular file"),
            "{what}: {message}"
        );
        assert!(!message.contains("missing"), "{what}: {message}");
        // The same as a reference frame.
        let (r2, t2) = (r.clone(), t.clone());
        let err = within(20, move || compare_dirs(&t2, &r2).unwrap_err());
        assert!(
            err.to_string().contains("not a regular file"),
            "{what}: {err}"
        );
        if frame.is_dir() {
            fs::remove_dir(&frame).unwrap();
        } else {
            fs::remove_file(&frame).unwrap();
        }
    }

    // A light mask that is a FIFO is not opened either.
    write_seq(&t, &[(0, constant(4, 4, 1.0))]);
    let mask = light_mask_path(&r, 0);
    fifo(&mask);
    let (r2, t2) = (r.clone(), t.clone());
    let err = within(20, move || compare_dirs(&r2, &t2).unwrap_err());
    let message = err.to_string();
    assert!(
        message.contains("seen_lights_0000.png") && message.contains("not a regular file"),
        "{message}"
    );
}

/// `radcache compare REF TEST --json` where some reference frames have no
/// light mask: the `_surfaces` figures are null, stdout stays JSON, and a
/// note on stderr names the first frame whose mask is missing.
#[test]
fn a_missing_light_mask_is_noted_on_stderr() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let frames: Vec<(u32, Film)> = (0..3).map(|k| (k, constant(4, 4, 1.0))).collect();
    write_seq(&r, &frames);
    write_seq(&t, &frames);
    let compare = || {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
            .arg("compare")
            .args([&r, &t])
            .arg("--json")
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        (json, String::from_utf8(out.stderr).unwrap())
    };
    // No masks at all: nothing to note.
    let (json, stderr) = compare();
    assert!(json["rel_rmse_surfaces"].is_null());
    assert!(!stderr.contains("note"), "{stderr}");

    let lights = [false; 16];
    for frame in [0, 2] {
        write_light_mask(&light_mask_path(&r, frame), 4, 4, &lights).unwrap();
    }
    let (json, stderr) = compare();
    assert!(json["rel_rmse_surfaces"].is_null() && json["flicker_surfaces"].is_null());
    assert!(
        stderr.contains("note:") && stderr.contains("seen_lights_0001.png"),
        "{stderr}"
    );
    assert!(!stderr.contains("seen_lights_0002.png"), "{stderr}");

    // The first frame's missing.
    write_light_mask(&light_mask_path(&r, 1), 4, 4, &lights).unwrap();
    fs::remove_file(light_mask_path(&r, 0)).unwrap();
    let (_, stderr) = compare();
    assert!(stderr.contains("seen_lights_0000.png"), "{stderr}");

    // Every frame has one: no note.
    write_light_mask(&light_mask_path(&r, 0), 4, 4, &lights).unwrap();
    let (json, stderr) = compare();
    assert!(json["rel_rmse_surfaces"].is_number(), "{json}");
    assert!(!stderr.contains("note"), "{stderr}");
}

/// `radcache compare REF TEST` with `extra` arguments: (status, stdout,
/// stderr).
fn run_compare(r: &Path, t: &Path, extra: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radcache"))
        .arg("compare")
        .args([r, t])
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

/// An all-black reference has a mean radiance of 0, so the relative
/// figures are undefined: `null` in `--json`, and a warning on stderr says
/// why (they were `inf` and `null` without a word). A reference with only
/// some black frames has overall figures; the warning names those frames,
/// whose own relative figures are undefined.
#[test]
fn a_black_reference_is_warned_about() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let black: Vec<(u32, Film)> = (0..3).map(|k| (k, constant(4, 4, 0.0))).collect();
    let tests: Vec<(u32, Film)> = black.iter().map(|(k, f)| (*k, offset(f, 0.5))).collect();
    write_seq(&r, &black);
    write_seq(&t, &tests);
    let (ok, stdout, stderr) = run_compare(&r, &t, &["--json"]);
    assert!(ok, "{stderr}");
    let json: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    for key in ["rel_rmse", "block_bias", "flicker"] {
        assert!(json[key].is_null(), "{key}: {json}");
    }
    assert!(
        (json["rmse"].as_f64().unwrap() - 0.5).abs() < 1e-6,
        "{json}"
    );
    assert!(
        stderr.contains("warning:")
            && stderr.contains("mean radiance is 0 (all black)")
            && stderr.contains("rel_rmse, block_bias, flicker")
            && stderr.contains("rmse is absolute"),
        "{stderr}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    // The table too.
    let (ok, _, table_stderr) = run_compare(&r, &t, &[]);
    assert!(ok && table_stderr == stderr, "{table_stderr}");

    // Frames 0 and 2 black, frame 1 not: the overall figures stand.
    write_seq(&r, &[(1, constant(4, 4, 1.0))]);
    let (ok, stdout, stderr) = run_compare(&r, &t, &["--json"]);
    assert!(ok, "{stderr}");
    let json: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(
        json["rel_rmse"].is_number() && json["flicker"].is_number(),
        "{json}"
    );
    assert!(json["per_frame"][0]["rel_rmse"].is_null(), "{json}");
    assert!(json["per_frame"][1]["rel_rmse"].is_number(), "{json}");
    assert!(
        stderr.contains("warning:")
            && stderr.contains("frames 0000 and 0002")
            && stderr.contains("mean radiance 0 (all black)"),
        "{stderr}"
    );
    assert!(!stderr.contains("0001"), "{stderr}");

    // No black frame: no warning.
    write_seq(&r, &[(0, constant(4, 4, 1.0)), (2, constant(4, 4, 1.0))]);
    let (ok, _, stderr) = run_compare(&r, &t, &["--json"]);
    assert!(ok && stderr.is_empty(), "{stderr}");
}

/// Two files of one folder that name the same frame (`frame_0001.exr` and
/// `frame_00001.exr`) are refused, naming both, whichever folder it is:
/// the frame was counted twice, or its other file said to be missing.
#[test]
fn two_files_of_one_frame_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (r, t) = (tmp.path().join("ref"), tmp.path().join("test"));
    let frames: Vec<(u32, Film)> = (0..3).map(|k| (k, constant(4, 4, 1.0))).collect();
    write_seq(&r, &frames);
    write_seq(&t, &frames);
    fs::copy(r.join("frame_0001.exr"), r.join("frame_00001.exr")).unwrap();
    for (a, b) in [(&r, &t), (&t, &r)] {
        let err = compare_dirs(a, b).unwrap_err();
        let message = err.to_string();
        for needle in ["ref/frame_0001.exr", "ref/frame_00001.exr", "frame 1"] {
            assert!(message.contains(needle), "{needle} not in {message}");
        }
    }
    let err = radcache::metrics::list_frames(&r).unwrap_err();
    assert!(err.to_string().contains("frame_00001.exr"), "{err}");

    // Not ambiguous: what the renderer writes past frame 9999, a number
    // written with fewer digits and a name in capitals, each alone.
    fs::remove_file(r.join("frame_00001.exr")).unwrap();
    fs::rename(r.join("frame_0002.exr"), r.join("frame_2.exr")).unwrap();
    fs::rename(t.join("frame_0001.exr"), t.join("FRAME_0001.EXR")).unwrap();
    write_seq(
        &r,
        &[(9999, constant(4, 4, 1.0)), (10000, constant(4, 4, 2.0))],
    );
    write_seq(
        &t,
        &[(9999, constant(4, 4, 1.0)), (10000, constant(4, 4, 2.0))],
    );
    assert!(frame_path(&r, 10000, "exr").ends_with("frame_10000.exr"));
    let report = compare_dirs(&r, &t).unwrap();
    let numbers: Vec<u32> = report.per_frame.iter().map(|f| f.frame).collect();
    assert_eq!(numbers, [0, 1, 2, 9999, 10000]);
    assert_eq!(report.rmse, 0.0);
}
