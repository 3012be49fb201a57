//! Deterministic random numbers. Every random decision is keyed by
//! `(seed, frame, pixel or record, sample index)`, so a frame renders the same
//! whether it is rendered alone, in another order, or after a resume, and on
//! any number of threads.
//!
//! The key is hashed (SplitMix64 finaliser, Steele et al. 2014) into the state
//! of a PCG32 generator (O'Neill 2014); each path then draws its dimensions in
//! order from that stream.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// What a random stream is keyed by. `frame` is `None` for the
/// `--same-pattern` reference renders, whose random sequence is identical in
/// every frame so that frame differences show the scene's change, not noise.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SampleKey {
    pub seed: u64,
    pub frame: Option<u32>,
    /// Pixel index (`y·width + x`) or record id.
    pub item: u64,
    pub sample: u32,
}

/// SplitMix64 finaliser: a bijective 64-bit mix with good avalanche.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl SampleKey {
    /// Folds the four fields into one 64-bit hash.
    pub fn hash(&self) -> u64 {
        const GOLDEN: u64 = 0x9e37_79b9_7f4a_7c15;
        let frame = self.frame.map_or(u64::MAX, u64::from);
        let mut h = mix64(self.seed.wrapping_add(GOLDEN));
        h = mix64(h ^ frame.wrapping_mul(GOLDEN));
        h = mix64(h ^ self.item);
        mix64(h ^ u64::from(self.sample).wrapping_mul(GOLDEN))
    }
}

/// PCG32 (XSH-RR variant): small, fast and statistically solid.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

impl Rng {
    const MULT: u64 = 6_364_136_223_846_793_005;

    pub fn new(key: SampleKey) -> Self {
        let h = key.hash();
        Self::from_seed(h, mix64(h ^ 0xda3e_39cb_94b9_5bdb))
    }

    pub fn from_seed(seed: u64, stream: u64) -> Self {
        let mut rng = Rng {
            state: 0,
            inc: (stream << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(seed);
        rng.next_u32();
        rng
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(Self::MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// An independent stream seeded from this one (for a sub-path that must
    /// not share numbers with its parent).
    pub fn split(&mut self) -> Rng {
        let seed = (u64::from(self.next_u32()) << 32) | u64::from(self.next_u32());
        Rng::from_seed(mix64(seed), mix64(seed ^ 0x5851_f42d_4c95_7f2d))
    }

    /// Uniform in [0, 1): 24 random mantissa bits, never exactly 1.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }
}

/// Stratifies a 2D sample over the `spp` samples of a pixel: sample `i` of
/// the first `n²` (`n = ⌊√spp⌋`) falls in its own cell of an `n × n` grid,
/// at `u` within the cell; later samples are plain `u`. Averaged over the
/// pixel's samples the estimate stays unbiased, and its variance falls
/// faster than with independent samples. `transposed` walks the grid in
/// the other order, so that two stratified dimensions of one sample (pixel
/// position, light position) are not paired cell for cell.
pub fn stratified_2d(sample: u32, spp: u32, u: Vec2, transposed: bool) -> Vec2 {
    let n = (spp as f32).sqrt() as u32;
    if sample >= n * n {
        return u;
    }
    let (a, b) = ((sample % n) as f32, (sample / n) as f32);
    let cell = if transposed {
        Vec2::new(b, a)
    } else {
        Vec2::new(a, b)
    };
    (cell + u) / n as f32
}

/// An orthonormal basis around a unit normal (Duff et al. 2017, branchless).
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub t: Vec3,
    pub b: Vec3,
    pub n: Vec3,
}

impl Frame {
    pub fn new(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Frame {
            t: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            b: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.t * v.x + self.b * v.y + self.n * v.z
    }

    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.t), v.dot(self.b), v.dot(self.n))
    }
}

/// Cosine-weighted direction on the +Z hemisphere (Malley's method);
/// pdf = cosθ/π.
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u.x).max(0.0).sqrt())
}

/// Direction around +Z with density ∝ cosⁿθ; pdf = (n+1)/(2π)·cosⁿθ.
#[inline]
pub fn cosine_power_lobe(u: Vec2, n: f32) -> Vec3 {
    let cos_theta = u.x.powf(1.0 / (n + 1.0));
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta)
}

/// Uniform point on a triangle as barycentrics (u, v) (Heitz 2019 would be
/// more uniform in the unit square; the square-root map is standard).
#[inline]
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

/// Power heuristic with β = 2 (Veach 1997, Eq. 9.13).
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let (a, b) = (pdf_a * pdf_a, pdf_b * pdf_b);
    if a + b > 0.0 {
        a / (a + b)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_repeat_and_differ() {
        let key = SampleKey {
            seed: 1,
            frame: Some(3),
            item: 42,
            sample: 7,
        };
        let a: Vec<u32> = (0..8)
            .scan(Rng::new(key), |r, _| Some(r.next_u32()))
            .collect();
        let b: Vec<u32> = (0..8)
            .scan(Rng::new(key), |r, _| Some(r.next_u32()))
            .collect();
        assert_eq!(a, b);
        for other in [
            SampleKey { seed: 2, ..key },
            SampleKey {
                frame: Some(4),
                ..key
            },
            SampleKey { frame: None, ..key },
            SampleKey { item: 43, ..key },
            SampleKey { sample: 8, ..key },
        ] {
            assert_ne!(Rng::new(other).next_u32(), a[0], "{other:?}");
        }
    }

    #[test]
    fn uniform_floats_have_the_right_mean() {
        let mut rng = Rng::new(SampleKey {
            seed: 9,
            frame: None,
            item: 0,
            sample: 0,
        });
        let n = 200_000;
        let mean = (0..n).map(|_| rng.next_f32() as f64).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.003, "mean {mean}");
    }

    #[test]
    fn frame_is_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let f = Frame::new(n);
            assert!(
                f.t.dot(f.b).abs() < 1e-5 && f.t.dot(n).abs() < 1e-5 && f.b.dot(n).abs() < 1e-5
            );
            assert!((f.t.cross(f.b) - n).length() < 1e-4, "right-handed for {n}");
            let v = Vec3::new(0.2, 0.3, 0.9);
            assert!((f.to_local(f.to_world(v)) - v).length() < 1e-5);
        }
    }
}
