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

/// Largest f32 below 1: stratified values are clamped to it so that
/// `(k + u)/n` never rounds up to 1.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// The layout of one stratified set of `spp` 2D samples (the positions of
/// a pixel's samples, or their light samples): sample `i` of the first
/// `n²` (`n = ⌊√spp⌋`) falls in its own cell of an `n × n` grid, and within
/// the cell in its own column and row of an `n × n` sub-grid, so that the
/// set is also stratified into `n²` strata along each axis (multi-jittered
/// sampling: Chiu, Shirley and Wang, "Multi-Jittered Sampling", Graphics
/// Gems IV, 1994); later samples are plain `u`. `u` places a sample within
/// its sub-cell. Averaged over the set the estimate stays unbiased, and its
/// variance falls faster than with independent samples. Why the sub-grid:
/// with plain jittered cells a vertical or horizontal edge across a pixel
/// (a room's corner, the side of an object, a shadow's edge) is measured by
/// `n` strata along the axis it varies in; multi-jittered, by `n²`.
///
/// The cells of row `r` take sub-column `σ(r)`, the cells of column `c`
/// sub-row `ρ(c)`, `σ` and `ρ` random permutations keyed by `shuffle`
/// (Kensler's correlated layout: "Correlated Multi-Jittered Sampling",
/// Pixar Technical Memo 13-01, 2013, `cmj`). Drawn anew per set, they make
/// each sample uniform over its cell: the estimate stays unbiased. They are
/// tabulated once per set rather than evaluated per sample.
///
/// With `scramble`, sample `i` takes cell `permute(i, n², scramble)`
/// instead of cell `i`. Two stratified dimensions of one sample (pixel
/// position, light position) must be paired by a random permutation, drawn
/// anew per pixel, and not by a fixed one: only then is every pairing of
/// their cells equally likely, which keeps the pixel's estimate unbiased
/// where the two interact (a shadow edge inside the pixel). This is the
/// "padding" of independently stratified dimensions (PBRT 3rd ed., §7.3).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stratified2d {
    n: u32,
    scramble: Option<u32>,
    /// `σ`: the sub-column of the cells of each row.
    sub_columns: Vec<u32>,
    /// `ρ`: the sub-row of the cells of each column.
    sub_rows: Vec<u32>,
}

impl Stratified2d {
    pub fn new(spp: u32, scramble: Option<u32>, shuffle: u32) -> Self {
        let n = (spp as f32).sqrt() as u32;
        // Kensler's multipliers for the two shuffles of one key.
        let permutation = |key: u32| (0..n).map(|i| permute(i, n, key)).collect();
        Stratified2d {
            n,
            scramble,
            sub_columns: permutation(shuffle.wrapping_mul(0x63d8_3595)),
            sub_rows: permutation(shuffle.wrapping_mul(0xa511_e9b3)),
        }
    }

    /// Sample `i` of the set, placed by `u` ∈ [0, 1)² within its sub-cell.
    pub fn sample(&self, i: u32, u: Vec2) -> Vec2 {
        let n = self.n;
        if i >= n * n {
            return u;
        }
        let cell = self.scramble.map_or(i, |p| permute(i, n * n, p));
        let (column, row) = (cell % n, cell / n);
        let sub_column = self.sub_columns[row as usize];
        let sub_row = self.sub_rows[column as usize];
        let x = (column as f32 + (sub_column as f32 + u.x) / n as f32) / n as f32;
        let y = (row as f32 + (sub_row as f32 + u.y) / n as f32) / n as f32;
        Vec2::new(x, y).min(Vec2::splat(ONE_MINUS_EPSILON))
    }
}

/// Stratifies a 1D sample over the `spp` samples of a pixel: sample `i`
/// falls in stratum `permute(i, spp, scramble)` of `spp`, at `u` within it
/// (see [`Stratified2d`] for why the strata are permuted per pixel).
pub fn stratified_1d(sample: u32, spp: u32, u: f32, scramble: u32) -> f32 {
    let spp = spp.max(1);
    let stratum = permute(sample % spp, spp, scramble);
    ((stratum as f32 + u) / spp as f32).min(ONE_MINUS_EPSILON)
}

/// Element `i` of a pseudo-random permutation of `0..len` chosen by `p`,
/// in O(1) and without storing the permutation: Kensler, "Correlated
/// Multi-Jittered Sampling" (Pixar Technical Memo 13-01, 2013), `permute`.
/// A keyed bijection on the next power of two, cycle-walked until it lands
/// below `len`.
pub fn permute(mut i: u32, len: u32, p: u32) -> u32 {
    debug_assert!(i < len, "permute: {i} is not below {len}");
    let mut w = len.max(1) - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    loop {
        i ^= p;
        i = i.wrapping_mul(0xe170_893d);
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i = i.wrapping_mul(0x0929_eb3f);
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i = i.wrapping_mul(1 | (p >> 27));
        i = i.wrapping_mul(0x6935_fa69);
        i ^= (i & w) >> 11;
        i = i.wrapping_mul(0x74dc_b303);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0x9e50_1cc3);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0xc860_a3df);
        i &= w;
        i ^= i >> 5;
        if i < len {
            return (i.wrapping_add(p)) % len;
        }
    }
}

/// The random numbers of one light sample: which light (`pick`) and where
/// on it (`u`), as [`crate::light::LightSampler::sample`] takes them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightChoice {
    pub pick: f32,
    pub u: Vec2,
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

/// Uniform point on a triangle as barycentrics (u, v), by the square-root
/// map. Heitz's low-distortion map (2019) spreads one triangle's samples
/// more evenly, but on cube-in-box's quad light, whose two triangles share
/// a stratified set ([`crate::light::LightSampler::choose`]), it gave 8 %
/// more direct-light noise than this map (64×64, 16 spp, 8 seeds).
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
    fn permute_is_a_permutation_that_depends_on_its_key() {
        for len in [1, 2, 3, 7, 16, 33, 64, 100, 1024] {
            let mut orders = Vec::new();
            for p in [0u32, 1, 0xdead_beef, 0x1234_5678] {
                let order: Vec<u32> = (0..len).map(|i| permute(i, len, p)).collect();
                let mut sorted = order.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, (0..len).collect::<Vec<_>>(), "len {len} key {p}");
                orders.push(order);
            }
            if len >= 7 {
                orders.dedup();
                assert!(orders.len() > 1, "every key gave the same order of {len}");
            }
        }
    }

    #[test]
    fn stratified_samples_fill_every_stratum_once() {
        for spp in [1, 4, 16, 17, 64] {
            let mut seen_1d = vec![0; spp as usize];
            for s in 0..spp {
                let x = stratified_1d(s, spp, 0.5, 0xabc);
                seen_1d[(x * spp as f32) as usize] += 1;
                assert!(stratified_1d(s, spp, ONE_MINUS_EPSILON, 0xabc) < 1.0);
            }
            assert!(seen_1d.iter().all(|&c| c == 1), "spp {spp}: {seen_1d:?}");
        }
    }

    /// Every cell of the grid once, and along each axis every one of the
    /// `n²` strata once: the multi-jittered property, for any keys.
    #[test]
    fn multi_jittered_sets_fill_every_cell_and_every_axis_stratum_once() {
        for (spp, scramble, shuffle) in [
            (1, None, 0),
            (4, Some(0x51), 7),
            (16, None, 0xdead_beef),
            (17, Some(3), 1),
            (64, Some(0x1234), 0x9876),
            (1024, None, 42),
        ] {
            let n = (spp as f32).sqrt() as u32;
            let layout = Stratified2d::new(spp, scramble, shuffle);
            let mut cells = vec![0; (n * n) as usize];
            let mut columns = vec![0; (n * n) as usize];
            let mut rows = vec![0; (n * n) as usize];
            for s in 0..n * n {
                let top = layout.sample(s, Vec2::splat(ONE_MINUS_EPSILON));
                assert!(top.x < 1.0 && top.y < 1.0);
                // Anywhere in the sub-cell (up to rounding at its far side).
                for u in [Vec2::ZERO, Vec2::splat(0.999)] {
                    let v = layout.sample(s, u);
                    let (x, y) = ((v.x * n as f32) as u32, (v.y * n as f32) as u32);
                    assert_eq!(
                        ((v.x * (n * n) as f32) as u32, (v.y * (n * n) as f32) as u32),
                        (
                            (layout.sample(s, Vec2::splat(0.5)).x * (n * n) as f32) as u32,
                            (layout.sample(s, Vec2::splat(0.5)).y * (n * n) as f32) as u32
                        ),
                        "u moves sample {s} out of its sub-cell"
                    );
                    if u == Vec2::ZERO {
                        cells[(y * n + x) as usize] += 1;
                        columns[(v.x * (n * n) as f32) as usize] += 1;
                        rows[(v.y * (n * n) as f32) as usize] += 1;
                    }
                }
            }
            for (name, counts) in [("cells", &cells), ("columns", &columns), ("rows", &rows)] {
                assert!(
                    counts.iter().all(|&c| c == 1),
                    "spp {spp} {name}: {counts:?}"
                );
            }
            let past = layout.sample(n * n, Vec2::new(0.3, 0.7));
            assert_eq!(past, Vec2::new(0.3, 0.7), "samples past n² are plain");
        }
    }

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
