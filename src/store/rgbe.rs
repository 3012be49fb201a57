//! Ward's shared-exponent RGBE packing of radiance (Ward, "Real pixels",
//! Graphics Gems II, 1991; the `Li` field of the 8-byte radiance sample of
//! the 2004 temporally coherent final gathering paper, §3.1), and that
//! 8-byte sample itself: [`PackedSample`].
//!
//! RGBE: the largest channel `v = m·2^e` (`m ∈ [0.5, 1)`) fixes the
//! exponent byte `e + 128`; each channel `c` keeps the 8-bit mantissa
//! `⌊c·2^(8−e)⌋`. Decoding returns the middle of the mantissa step,
//! `(b + 0.5)·2^(e−8)` (as Radiance does), so every channel is within
//! `max(r, g, b)/256` of its value. Zero, negative and NaN channels
//! encode as 0; a largest channel below `1e-32` is black (`[0, 0, 0, 0]`);
//! a largest channel of `2^127` or more (or +∞) saturates.

use glam::Vec3;
use half::f16;

/// Packs linear radiance into 4 bytes `[r, g, b, e]`.
pub fn encode(c: Vec3) -> [u8; 4] {
    let clean = |x: f32| if x > 0.0 { x } else { 0.0 }; // NaN and negatives → 0
    let (r, g, b) = (clean(c.x), clean(c.y), clean(c.z));
    let v = r.max(g).max(b);
    if v < 1e-32 {
        return [0; 4];
    }
    if v >= 2f32.powi(127) {
        return [255; 4];
    }
    // v is a normal float here: its biased exponent gives frexp's e.
    let e = ((v.to_bits() >> 23) & 0xff) as i32 - 126; // v ∈ [2^(e−1), 2^e)
    let scale = exp2i(8 - e);
    let byte = |x: f32| (x * scale).floor().min(255.0) as u8;
    [byte(r), byte(g), byte(b), (e + 128) as u8]
}

/// Unpacks 4 RGBE bytes into linear radiance.
pub fn decode(rgbe: [u8; 4]) -> Vec3 {
    let [r, g, b, e] = rgbe;
    if e == 0 {
        return Vec3::ZERO;
    }
    // `(x + ½)·2^k` is exact in f32 for every byte `x` and `k = e − 136 ∈
    // [−135, 119]`: `2x + 1` has 9 bits and `2^(k−1)` is at least 2^−136,
    // above f32's smallest step 2^−149. So f32 gives the f64 result's
    // bits, without f64's `powi` (`tcg` decodes every sample of its
    // records each frame).
    let k = i32::from(e) - 136;
    let f = if k >= -126 {
        exp2i(k)
    } else {
        2f64.powi(k) as f32
    };
    let ch = |x: u8| (f32::from(x) + 0.5) * f;
    Vec3::new(ch(r), ch(g), ch(b))
}

/// `2^k` exactly, for `k ∈ [−126, 127]`.
fn exp2i(k: i32) -> f32 {
    f32::from_bits(((k + 127) as u32) << 23)
}

/// Bits of [`PackedSample::flags`].
///
/// The age takes 14 bits: bits 0–3 hold it below 15 and 15 from there on,
/// when bits 6–15 hold what it is past 15 (saturating at [`flags::MAX_AGE`]).
/// Samples written before 2026-11-30 kept it in bits 0–3 alone,
/// saturating at 15, and the low bits of the hit object's index in bits
/// 6–15: they read the same below 15, and at 15 as 15 plus those object
/// bits, an age of 15 to 1038 where the true one is 15 or more. Only `tcg`
/// reads ages, and it resumes no job stored before (its algorithm
/// revision 4 refuses them). Four bits were too few: at `tcg`'s default `τ_min = 0.05` a
/// sample waits about 20 frames to be shot again, so the `2^age` draw
/// (Tawara et al. 2004, §3.2) could not tell the oldest samples apart.
pub mod flags {
    /// Bits 0–3: the age where below 15, else 15.
    pub const AGE_LOW_MASK: u16 = 0x000f;
    /// Bit 4: the sample's ray hit an animated object.
    pub const HIT_DYNAMIC: u16 = 1 << 4;
    /// Bit 5: the ray left the scene (distance is +∞, no object).
    pub const MISS: u16 = 1 << 5;
    /// Bits 6–15: the age past 15, where bits 0–3 are 15.
    pub const AGE_HIGH_SHIFT: u16 = 6;
    /// The largest age the flags hold: 15 + 1023 frames.
    pub const MAX_AGE: u32 = AGE_LOW_MASK as u32 + (u16::MAX >> AGE_HIGH_SHIFT) as u32;

    /// The age bits of `age` (saturating at [`MAX_AGE`]).
    pub(crate) fn age_bits(age: u32) -> u16 {
        let low = u32::from(AGE_LOW_MASK);
        match age.min(MAX_AGE) {
            a if a < low => a as u16,
            a => AGE_LOW_MASK | (((a - low) as u16) << AGE_HIGH_SHIFT),
        }
    }

    /// The age `flags` hold.
    pub(crate) fn age(flags: u16) -> u32 {
        match flags & AGE_LOW_MASK {
            low if low < AGE_LOW_MASK => u32::from(low),
            low => u32::from(low) + u32::from(flags >> AGE_HIGH_SHIFT),
        }
    }

    /// All the bits of the age.
    pub(crate) const AGE_BITS: u16 = AGE_LOW_MASK | (u16::MAX << AGE_HIGH_SHIFT);
}

/// One incoming-radiance sample of a record in 8 bytes (2004 paper §3.1):
/// RGBE radiance, half-float hit distance, 16 flag bits (see [`flags`]).
/// The sample's direction is not stored: it is cell `j·N + k` of the
/// record's `M × N` strata (index in the sample array), so its cell is
/// known from the index and its exact jittered direction can be
/// regenerated from the record's deterministic sample key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PackedSample {
    pub rgbe: [u8; 4],
    /// `f16` bits of the distance to the first hit (+∞ on a miss).
    pub distance: u16,
    pub flags: u16,
}

impl PackedSample {
    pub const BYTES: usize = 8;

    /// Packs one sample. `object` is `u32::MAX` on a miss (only whether
    /// it is one is kept).
    pub fn pack(radiance: Vec3, distance: f32, object: u32, hit_dynamic: bool, age: u32) -> Self {
        let miss = object == u32::MAX || !distance.is_finite();
        let mut f = flags::age_bits(age);
        if miss {
            f |= flags::MISS;
        } else if hit_dynamic {
            f |= flags::HIT_DYNAMIC;
        }
        let d = if miss { f32::INFINITY } else { distance };
        PackedSample {
            rgbe: encode(radiance),
            distance: f16::from_f32(d).to_bits(),
            flags: f,
        }
    }

    pub fn radiance(&self) -> Vec3 {
        decode(self.rgbe)
    }

    pub fn distance(&self) -> f32 {
        f16::from_bits(self.distance).to_f32()
    }

    pub fn age(&self) -> u32 {
        flags::age(self.flags)
    }

    /// The sample one frame older (its age saturates at
    /// [`flags::MAX_AGE`]).
    pub fn older(self) -> Self {
        PackedSample {
            flags: (self.flags & !flags::AGE_BITS) | flags::age_bits(self.age() + 1),
            ..self
        }
    }

    pub fn is_miss(&self) -> bool {
        self.flags & flags::MISS != 0
    }

    pub fn hit_dynamic(&self) -> bool {
        self.flags & flags::HIT_DYNAMIC != 0
    }

    /// Little-endian: `r g b e`, distance (2), flags (2).
    pub fn to_bytes(&self) -> [u8; 8] {
        let d = self.distance.to_le_bytes();
        let f = self.flags.to_le_bytes();
        let [r, g, b, e] = self.rgbe;
        [r, g, b, e, d[0], d[1], f[0], f[1]]
    }

    pub fn from_bytes(b: [u8; 8]) -> Self {
        PackedSample {
            rgbe: [b[0], b[1], b[2], b[3]],
            distance: u16::from_le_bytes([b[4], b[5]]),
            flags: u16::from_le_bytes([b[6], b[7]]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (no test depends on `rand`).
    fn lcg(state: &mut u64) -> f32 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 40) as f32) / (1u64 << 24) as f32
    }

    #[test]
    fn rgbe_round_trip_error_is_within_max_channel_over_256() {
        let mut s = 7u64;
        for i in 0..200_000 {
            let scale = 10f32.powf(lcg(&mut s) * 24.0 - 12.0);
            let c = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * scale;
            // Some samples with one channel exactly zero or tiny.
            let c = if i % 7 == 0 {
                Vec3::new(c.x, 0.0, c.z * 1e-4)
            } else {
                c
            };
            let d = decode(encode(c));
            let bound = c.max_element() / 256.0 * (1.0 + 1e-5);
            let err = (d - c).abs().max_element();
            assert!(err <= bound, "{c:?} → {d:?}: error {err} > {bound}");
        }
    }

    /// The f32 decode gives Ward's `(x + ½)·2^(e−136)` computed in f64,
    /// bit for bit, for every mantissa byte and exponent.
    #[test]
    fn decode_in_f32_is_the_f64_formula_exactly() {
        for e in 1..=255u8 {
            for x in 0..=255u8 {
                let want = ((f64::from(x) + 0.5) * 2f64.powi(i32::from(e) - 136)) as f32;
                let got = decode([x, x, x, e]);
                assert_eq!(got.x.to_bits(), want.to_bits(), "x {x} e {e}");
            }
        }
    }

    #[test]
    fn rgbe_special_values() {
        assert_eq!(encode(Vec3::ZERO), [0; 4]);
        assert_eq!(decode([0; 4]), Vec3::ZERO);
        assert_eq!(encode(Vec3::new(f32::NAN, -1.0, 0.0)), [0; 4]);
        assert_eq!(encode(Vec3::splat(f32::INFINITY)), [255; 4]);
        // Powers of two sit on a mantissa step boundary.
        let one = decode(encode(Vec3::ONE));
        assert!((one - Vec3::ONE).abs().max_element() <= 1.0 / 256.0);
        // Exponent range extremes do not overflow.
        let tiny = Vec3::splat(2e-32);
        assert!((decode(encode(tiny)) - tiny).abs().max_element() <= tiny.x / 256.0 * 1.0001);
        let huge = Vec3::splat(1e38);
        assert!((decode(encode(huge)) - huge).abs().max_element() <= huge.x / 256.0 * 1.0001);
    }

    #[test]
    fn packed_sample_round_trip() {
        let p = PackedSample::pack(Vec3::new(0.5, 0.25, 2.0), 5.4321, 1234, true, 3);
        assert_eq!(PackedSample::from_bytes(p.to_bytes()), p);
        assert_eq!(p.age(), 3);
        assert!(p.hit_dynamic());
        assert!(!p.is_miss());
        assert!((p.distance() - 5.4321).abs() < 5.4321 / 1024.0);
        assert!(
            (p.radiance() - Vec3::new(0.5, 0.25, 2.0))
                .abs()
                .max_element()
                <= 2.0 / 256.0
        );

        let miss = PackedSample::pack(Vec3::ONE, f32::INFINITY, u32::MAX, true, 99);
        assert!(miss.is_miss());
        assert!(!miss.hit_dynamic());
        assert_eq!(miss.distance(), f32::INFINITY);
        assert_eq!(miss.age(), 99);
        assert_eq!(std::mem::size_of::<PackedSample>(), PackedSample::BYTES);
    }

    /// Every age up to [`flags::MAX_AGE`] reads back as packed and as
    /// reached one frame at a time, and then saturates, the other flags
    /// untouched; flags written before ages took 14 bits (an object's
    /// low bits in 6–15) read the same below 15, and 15 or more at 15.
    #[test]
    fn ages_count_to_their_maximum_and_keep_the_other_flags() {
        let mut aged = PackedSample::pack(Vec3::ONE, 2.0, 7, true, 0);
        for age in 0..=flags::MAX_AGE + 3 {
            let want = age.min(flags::MAX_AGE);
            let packed = PackedSample::pack(Vec3::ONE, 2.0, 7, true, age);
            assert_eq!((packed.age(), aged.age()), (want, want), "age {age}");
            assert_eq!(packed, aged, "age {age}");
            assert!(aged.hit_dynamic() && !aged.is_miss());
            aged = aged.older();
        }
        assert_eq!(flags::MAX_AGE, 1038);
        for object in [0u16, 1, 0x155, 0x3ff] {
            for old_age in 0..=15u16 {
                let old = PackedSample {
                    flags: old_age | flags::HIT_DYNAMIC | (object << 6),
                    ..aged
                };
                if old_age < 15 {
                    assert_eq!(old.age(), u32::from(old_age));
                } else {
                    assert!(old.age() >= 15);
                }
                assert!(old.hit_dynamic() && !old.is_miss());
            }
        }
    }
}
