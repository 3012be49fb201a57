//! Records, samples and a job spec for the store's tests and its bench
//! (`tests/store.rs`, `benches/store.rs`).
#![allow(dead_code)]

use glam::Vec3;
use radcache::cache::gather::HemisphereSamples;
use radcache::cache::IrradianceRecord;
use radcache::store::JobSpec;

/// A job over frames 0..10 of `builtin:cube-in-box` at 16×16.
pub fn spec(name: &str) -> JobSpec {
    JobSpec {
        name: name.into(),
        scene: "builtin:cube-in-box".into(),
        scene_hash: "0123456789abcdef".into(),
        method: "ic".into(),
        settings: "Ic(..)".into(),
        width: 16,
        height: 16,
        spp: 4,
        fps: 24.0,
        seed: 0,
        same_pattern: false,
        frame_start: 0,
        frame_end: 10,
    }
}

/// A record whose fields all depend on `id` (and `frame`).
pub fn record(id: u64, frame: u32) -> IrradianceRecord {
    let f = id as f32;
    IrradianceRecord {
        id,
        position: Vec3::new(f, 1.0, -2.0),
        normal: Vec3::Y,
        irradiance: Vec3::new(0.5, 0.25, f),
        grad_translation: [Vec3::X, Vec3::Y, Vec3::Z],
        grad_rotation: [Vec3::Z, Vec3::X, Vec3::Y * f],
        radius: 0.75,
        created_frame: frame,
        object: 3,
        eas: None,
    }
}

/// A hemisphere of `n` samples, radiance varying smoothly with the
/// sample index (shifted by `seed`), every fifth a miss: zstd sees
/// about what it sees in a render.
pub fn samples(n: usize, seed: u32) -> HemisphereSamples {
    let mut s = HemisphereSamples::default();
    for i in 0..n {
        let x = (i as f32 + seed as f32) * 0.37;
        s.direction.push(Vec3::Y);
        s.radiance
            .push(Vec3::new(x.sin().abs(), x.cos().abs() * 3.0, 0.01 * x));
        if i % 5 == 0 {
            s.distance.push(f32::INFINITY);
            s.object.push(u32::MAX);
        } else {
            s.distance.push(1.0 + x);
            s.object.push(i as u32 % 4);
        }
    }
    s
}

/// The sled database under a store, opened directly, retrying while the
/// lock of a store just closed is released: sled lets go of it from
/// background threads a moment after the store is dropped (a plain
/// `sled::open` there failed now and then with "could not acquire lock").
pub fn open_raw(path: &std::path::Path) -> sled::Db {
    for _ in 0..100 {
        if let Ok(db) = sled::open(path) {
            return db;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    sled::open(path).unwrap()
}
