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

/// What a random stream is keyed by. `frame` is `None` for streams that
/// are the same in every frame: those of `--same-pattern` renders (so that
/// frame differences show the scene's change, not noise), and the streams
/// a method keeps from frame to frame on purpose (a record's gathers, the
/// coherent pixel samples, the movies' texels).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SampleKey {
    pub seed: u64,
    pub frame: Option<u32>,
    /// What draws the stream: a pixel index (`y·width + x`), untagged, or
    /// one of [`streams`]' tags with the index of what it tags.
    pub item: u64,
    pub sample: u32,
}

/// The tags that keep the random streams of different uses apart. A
/// tagged [`SampleKey::item`] is a tag ORed with an index below 2^57 (a
/// pixel, a vertex, a texel, or a record's first stream); an untagged one
/// is a pixel of the per-frame pixel streams. Every tag differs from every
/// other in its bits from 57 up, so no two uses draw the same numbers.
pub mod streams {
    /// A record's hemisphere gathers (`ic`, and `trc` and `tcg`, which make
    /// their records as `ic` does).
    pub const RECORD: u64 = 1 << 62;
    /// `tcg`'s picks of the cells it shoots again, apart from the shots.
    pub const RECORD_PICK: u64 = RECORD | (1 << 61);
    /// The texels of `movies`' texture movies.
    pub const MOVIE_TEXEL: u64 = 1 << 60;
    /// Pixel samples drawn the same in every frame (`trc`, `tcg`), apart
    /// from a same-pattern reference's untagged ones.
    pub const COHERENT_PIXEL: u64 = 1 << 59;
    /// The vertices of `movies`' global pass: their direct light.
    pub const GLOBAL_VERTEX: u64 = 1 << 58;
    /// The links of the global pass's vertices, apart from their direct
    /// light (the same vertex's link `k` and light sample `k` drew the
    /// same numbers): ORed onto a vertex's item.
    pub const GLOBAL_LINK: u64 = GLOBAL_VERTEX | (1 << 57);
    /// The direct light at the hits of the global pass's links (one item
    /// a link, by its number in the pass).
    pub const GLOBAL_LANDING: u64 = 1 << 57;
    /// Every tag, for the test that they are apart.
    pub const ALL: [u64; 7] = [
        RECORD,
        RECORD_PICK,
        MOVIE_TEXEL,
        COHERENT_PIXEL,
        GLOBAL_VERTEX,
        GLOBAL_LINK,
        GLOBAL_LANDING,
    ];
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
#[derive(Clone, Debug, PartialEq, Eq)]
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
/// a pixel's samples, or their light samples): sample `i` falls in its own
/// cell of a `columns × rows` grid (`columns · rows = spp`, as square as
/// `spp`'s divisors allow: 4 × 4 for 16, 4 × 2 for 8, 17 × 1 for 17), and
/// within the cell in its own column and row of a `rows × columns`
/// sub-grid, so that the set is also stratified into `spp` strata along
/// each axis (multi-jittered sampling: Chiu, Shirley and Wang,
/// "Multi-Jittered Sampling", Graphics Gems IV, 1994). `u` places a sample
/// within its sub-cell. Averaged over the set the estimate stays unbiased,
/// and its variance falls faster than with independent samples. Why the
/// sub-grid: with plain jittered cells a vertical or horizontal edge
/// across a pixel (a room's corner, the side of an object, a shadow's edge)
/// is measured by `columns` or `rows` strata; multi-jittered, by `spp`.
///
/// The cells of row `r` take sub-column `σ(r)`, the cells of column `c`
/// sub-row `ρ(c)`, `σ` and `ρ` random permutations keyed by `shuffle`
/// (Kensler's correlated layout: "Correlated Multi-Jittered Sampling",
/// Pixar Technical Memo 13-01, 2013, `cmj`). Drawn anew per set, they make
/// each sample uniform over its cell: the estimate stays unbiased. They are
/// tabulated once per set rather than evaluated per sample.
///
/// With `scramble`, sample `i` takes cell `permute(i, spp, scramble)`
/// instead of cell `i`. Two stratified dimensions of one sample (pixel
/// position, light position) must be paired by a random permutation, drawn
/// anew per pixel, and not by a fixed one: only then is every pairing of
/// their cells equally likely, which keeps the pixel's estimate unbiased
/// where the two interact (a shadow edge inside the pixel). This is the
/// "padding" of independently stratified dimensions (PBRT 3rd ed., §7.3).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stratified2d {
    columns: u32,
    rows: u32,
    scramble: Option<u32>,
    /// `σ`: the sub-column (of `rows`) of the cells of each row.
    sub_columns: Vec<u32>,
    /// `ρ`: the sub-row (of `columns`) of the cells of each column.
    sub_rows: Vec<u32>,
}

impl Stratified2d {
    pub fn new(spp: u32, scramble: Option<u32>, shuffle: u32) -> Self {
        let (columns, rows) = Self::shape(spp);
        let permutation = |len: u32, key: u32| (0..len).map(|i| permute(i, len, key)).collect();
        Stratified2d {
            columns,
            rows,
            scramble,
            sub_columns: permutation(rows, Self::sub_column_key(shuffle)),
            sub_rows: permutation(columns, Self::sub_row_key(shuffle)),
        }
    }

    /// Sample `i` of the set, placed by `u` ∈ [0, 1)² within its sub-cell
    /// (`u` itself for `i` past the set).
    pub fn sample(&self, i: u32, u: Vec2) -> Vec2 {
        let (columns, rows) = (self.columns, self.rows);
        if i >= columns * rows {
            return u;
        }
        let cell = self.scramble.map_or(i, |p| permute(i, columns * rows, p));
        let (column, row) = (cell % columns, cell / columns);
        let sub_column = self.sub_columns[row as usize];
        let sub_row = self.sub_rows[column as usize];
        Self::place((columns, rows), (column, row), (sub_column, sub_row), u)
    }

    /// Sample `i` of `Stratified2d::new(spp, None, shuffle)`, the same
    /// point, without tabulating the shuffles: for a set whose samples are
    /// drawn one at a time and seldom together (a global-pass vertex's
    /// links, traced again one by one where motion may have changed them),
    /// where tabulating per sample would cost more than it saves.
    pub fn sample_of(spp: u32, shuffle: u32, i: u32, u: Vec2) -> Vec2 {
        let (columns, rows) = Self::shape(spp);
        if i >= columns * rows {
            return u;
        }
        let (column, row) = (i % columns, i / columns);
        let sub_column = permute(row, rows, Self::sub_column_key(shuffle));
        let sub_row = permute(column, columns, Self::sub_row_key(shuffle));
        Self::place((columns, rows), (column, row), (sub_column, sub_row), u)
    }

    /// The grid of `spp` samples, `(columns, rows)`: `rows` the largest
    /// divisor of `spp` not above its square root.
    fn shape(spp: u32) -> (u32, u32) {
        let spp = spp.max(1);
        let root = (spp as f64).sqrt() as u32;
        let rows = (1..=root).rev().find(|d| spp % d == 0).unwrap_or(1);
        (spp / rows, rows)
    }

    // Kensler's multipliers for the two shuffles of one key.
    fn sub_column_key(shuffle: u32) -> u32 {
        shuffle.wrapping_mul(0x63d8_3595)
    }

    fn sub_row_key(shuffle: u32) -> u32 {
        shuffle.wrapping_mul(0xa511_e9b3)
    }

    /// The point `u` places in sub-cell `(sub_column, sub_row)` of cell
    /// `(column, row)`.
    fn place(
        (columns, rows): (u32, u32),
        (column, row): (u32, u32),
        (sub_column, sub_row): (u32, u32),
        u: Vec2,
    ) -> Vec2 {
        let x = (column as f32 + (sub_column as f32 + u.x) / rows as f32) / columns as f32;
        let y = (row as f32 + (sub_row as f32 + u.y) / columns as f32) / rows as f32;
        Vec2::new(x, y).min(Vec2::splat(ONE_MINUS_EPSILON))
    }
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
/// The spherical triangle that a triangle subtends from a point: the unit
/// directions `a, b, c` to its vertices and its area `Ω` (the solid angle).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphericalTriangle {
    a: Vec3,
    b: Vec3,
    c: Vec3,
    /// `|a·(b×c)|`, kept for [`SphericalTriangle::arvo`].
    triple: f32,
    pub solid_angle: f32,
}

impl SphericalTriangle {
    /// The triangle `v` seen from `p`. `Ω = 2·atan2(|a·(b×c)|, 1 + a·b +
    /// b·c + c·a)` (Van Oosterom & Strackee 1983), accurate for small
    /// triangles, where Girard's angle sum less π cancels.
    pub fn new(v: &[Vec3; 3], p: Vec3) -> Self {
        let [a, b, c] = v.map(|x| (x - p).normalize_or_zero());
        let triple = a.dot(b.cross(c)).abs();
        let solid_angle = (2.0 * triple.atan2(1.0 + a.dot(b) + b.dot(c) + c.dot(a))).abs();
        SphericalTriangle {
            a,
            b,
            c,
            triple,
            solid_angle,
        }
    }

    /// A direction uniform over the spherical triangle (density `1/Ω`);
    /// `None` where the triangle is degenerate from its point. One sample
    /// of [`SphericalTriangle::arvo`]'s map.
    pub fn sample(&self, u: Vec2) -> Option<Vec3> {
        self.arvo()?.sample(u)
    }

    /// Arvo's map over this triangle (1995), in the form of PBRT-v4's
    /// `SampleSphericalTriangle`, with what does not depend on the sample
    /// worked out: callers that draw many samples from one point keep it.
    /// `None` where the triangle is degenerate from its point.
    ///
    /// Departures from PBRT, for speed (it runs for every light sample):
    /// the area is `Ω` rather than the angle sum, which saves the other two
    /// angles and keeps the map's density exactly `1/Ω`; and the angle α at
    /// a enters only through its sine and cosine, taken from the planes'
    /// unnormalised normals `a×b` and `a×c` rather than through `asin`:
    /// `(a×b)×(a×c) = (a·(b×c))·a`, so `sin α = |a·(b×c)| / (|a×b||a×c|)`
    /// from the triple product `new` found, and `|a×c|` is also the length
    /// of `c`'s part orthogonal to `a`. Two square roots instead of four.
    pub fn arvo(&self) -> Option<ArvoMap> {
        let (a, b, c) = (self.a, self.b, self.c);
        let (n_ab, n_ac) = (a.cross(b), a.cross(c));
        let (len_ab, len_ac) = (n_ab.length(), n_ac.length());
        let inv = (len_ab * len_ac).recip();
        if !inv.is_finite() {
            return None;
        }
        Some(ArvoMap {
            a,
            b,
            c_across: c - c.dot(a) * a,
            len_ac,
            a_dot_b: a.dot(b),
            cos_alpha: (n_ab.dot(n_ac) * inv).clamp(-1.0, 1.0),
            sin_alpha: (self.triple * inv).min(1.0),
            solid_angle: self.solid_angle,
        })
    }
}

/// Arvo's area-preserving map from the unit square onto a spherical
/// triangle ([`SphericalTriangle::arvo`]): `u.x` sets the area `u.x·Ω` of
/// the sub-triangle (a, b, c') whose vertex c' on the arc from a to c
/// follows in closed form, and `u.y` the point on the arc from b to c'.
/// The map is continuous and preserves area, so a stratified `u` stays
/// stratified over the solid angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArvoMap {
    a: Vec3,
    b: Vec3,
    /// `c`'s part orthogonal to `a`, and its length `|a×c|`.
    c_across: Vec3,
    len_ac: f32,
    a_dot_b: f32,
    /// The angle α at `a`, by its cosine and sine.
    cos_alpha: f32,
    sin_alpha: f32,
    solid_angle: f32,
}

impl ArvoMap {
    /// The direction `u` maps to (density `1/Ω`); `None` where the map
    /// breaks down in f32.
    pub fn sample(&self, u: Vec2) -> Option<Vec3> {
        let (a, b) = (self.a, self.b);
        let (cos_alpha, sin_alpha) = (self.cos_alpha, self.sin_alpha);
        // sin and cos of the sub-triangle's angle sum π + u.x·Ω.
        let (sin_sub, cos_sub) = (u.x * self.solid_angle).sin_cos();
        let (sin_sub, cos_sub) = (-sin_sub, -cos_sub);
        let sin_phi = sin_sub * cos_alpha - cos_sub * sin_alpha;
        let cos_phi = cos_sub * cos_alpha + sin_sub * sin_alpha;
        let k1 = cos_phi + cos_alpha;
        let k2 = sin_phi - sin_alpha * self.a_dot_b;
        let cos_bp = (k2 + (k2 * cos_phi - k1 * sin_phi) * cos_alpha)
            / ((k2 * sin_phi + k1 * cos_phi) * sin_alpha);
        if cos_bp.is_nan() {
            return None;
        }
        let cos_bp = cos_bp.clamp(-1.0, 1.0);
        let sin_bp = (1.0 - cos_bp * cos_bp).max(0.0).sqrt();
        let c_sub = cos_bp * a + sin_bp / self.len_ac * self.c_across;
        // The direction, on the arc from b to c'.
        let cos_theta = 1.0 - u.y * (1.0 - c_sub.dot(b));
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        Some(cos_theta * b + sin_theta * (c_sub - c_sub.dot(b) * b).try_normalize()?)
    }
}

/// Power heuristic with β = 2 (Veach 1997, Eq. 9.13). Squared in f64:
/// a solid-angle pdf of an f32 squares past f32's range from 1.8e19 (a
/// small emitter seen edge-on from a surface a million metres away), and
/// `inf / inf` would be a NaN pixel. An infinite pdf (past even f32) takes
/// all the weight from a finite one.
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    match (pdf_a.is_infinite(), pdf_b.is_infinite()) {
        (true, true) => return 0.5,
        (true, false) => return 1.0,
        (false, true) => return 0.0,
        (false, false) => {}
    }
    let (a, b) = (f64::from(pdf_a).powi(2), f64::from(pdf_b).powi(2));
    if a + b > 0.0 {
        (a / (a + b)) as f32
    } else {
        0.0
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Every stream tag differs from every other, and from an untagged
    /// item, in the bits above the indices they tag.
    #[test]
    fn stream_tags_are_apart() {
        let high = |tag: u64| tag >> 57;
        for (i, a) in streams::ALL.iter().enumerate() {
            assert_ne!(high(*a), 0, "{a:#x} is no tag");
            for b in &streams::ALL[i + 1..] {
                assert_ne!(high(*a), high(*b), "{a:#x} and {b:#x}");
            }
        }
    }

    /// Lambert's closed form for `∫ cosθ dω` over triangle `v` seen from
    /// `p` with normal `n`: `½ Σ θ_i (n · ĝ_i)`, with `θ_i` the angle an
    /// edge subtends and `ĝ_i` its plane's unit normal.
    pub(crate) fn lambert(v: &[Vec3; 3], p: Vec3, n: Vec3) -> f32 {
        0.5 * (0..3)
            .map(|i| {
                let (a, b) = ((v[i] - p).normalize(), (v[(i + 1) % 3] - p).normalize());
                a.dot(b).acos() * n.dot(b.cross(a).normalize())
            })
            .sum::<f32>()
    }

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

    /// Every cell of the grid once, and along each axis every one of the
    /// `spp` strata once: the multi-jittered property, for square and
    /// other sample counts and any keys.
    #[test]
    fn multi_jittered_sets_fill_every_cell_and_every_axis_stratum_once() {
        for (spp, scramble, shuffle, grid) in [
            (1, None, 0, (1, 1)),
            (4, Some(0x51), 7, (2, 2)),
            (8, None, 3, (4, 2)),
            (16, None, 0xdead_beef, (4, 4)),
            (17, Some(3), 1, (17, 1)),
            (64, Some(0x1234), 0x9876, (8, 8)),
            (512, Some(9), 5, (32, 16)),
            (1024, None, 42, (32, 32)),
        ] {
            let layout = Stratified2d::new(spp, scramble, shuffle);
            assert_eq!((layout.columns, layout.rows), grid, "spp {spp}");
            let (columns, rows) = grid;
            let strata = |v: f32| (v * spp as f32) as usize;
            let mut cells = vec![0; spp as usize];
            let mut xs = vec![0; spp as usize];
            let mut ys = vec![0; spp as usize];
            for s in 0..spp {
                let top = layout.sample(s, Vec2::splat(ONE_MINUS_EPSILON));
                assert!(top.x < 1.0 && top.y < 1.0);
                let v = layout.sample(s, Vec2::ZERO);
                // Anywhere in its sub-cell (up to rounding at the far side).
                let far = layout.sample(s, Vec2::splat(0.999));
                assert_eq!(
                    (strata(v.x), strata(v.y)),
                    (strata(far.x), strata(far.y)),
                    "spp {spp}: u moves sample {s} out of its sub-cell"
                );
                let (x, y) = ((v.x * columns as f32) as u32, (v.y * rows as f32) as u32);
                cells[(y * columns + x) as usize] += 1;
                xs[strata(v.x)] += 1;
                ys[strata(v.y)] += 1;
            }
            for (name, counts) in [("cells", &cells), ("columns", &xs), ("rows", &ys)] {
                assert!(
                    counts.iter().all(|&c| c == 1),
                    "spp {spp} {name}: {counts:?}"
                );
            }
            let past = layout.sample(spp, Vec2::new(0.3, 0.7));
            assert_eq!(past, Vec2::new(0.3, 0.7), "samples past the set are plain");
        }
    }

    /// `sample_of` is the unscrambled set, sample for sample, without its
    /// tables.
    #[test]
    fn samples_drawn_one_at_a_time_are_the_tabulated_set() {
        for (spp, shuffle) in [(1, 0), (8, 3), (17, 1), (96, 0xdead_beef), (128, 42)] {
            let layout = Stratified2d::new(spp, None, shuffle);
            for i in 0..spp + 2 {
                let u = Vec2::new((i as f32 * 0.37).fract(), (i as f32 * 0.61).fract());
                assert_eq!(
                    Stratified2d::sample_of(spp, shuffle, i, u),
                    layout.sample(i, u),
                    "spp {spp}, sample {i}"
                );
            }
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

    /// The centres of an `n × n` grid over the unit square.
    fn grid(n: u32) -> impl Iterator<Item = Vec2> {
        (0..n * n).map(move |i| {
            Vec2::new(
                ((i % n) as f32 + 0.5) / n as f32,
                ((i / n) as f32 + 0.5) / n as f32,
            )
        })
    }

    /// The octant triangle seen from the origin is the spherical triangle
    /// of one eighth of the sphere, `Ω = π/2`: the map must keep its
    /// directions inside it and spread them uniformly, so the part above
    /// 60° latitude gets the cap's share (1/2) and each side of the plane
    /// x = y half.
    #[test]
    fn spherical_triangle_samples_its_solid_angle_uniformly() {
        let octant = [Vec3::X, Vec3::Y, Vec3::Z];
        let sphere = SphericalTriangle::new(&octant, Vec3::ZERO);
        assert!((sphere.solid_angle - PI / 2.0).abs() < 1e-5);
        let n = 64;
        let (mut cap, mut above_diagonal) = (0, 0);
        for u in grid(n) {
            let w = sphere.sample(u).expect("a regular triangle");
            assert!((w.length() - 1.0).abs() < 1e-4, "{w}");
            assert!(w.min_element() > -1e-4, "{w} leaves the octant");
            cap += usize::from(w.z > 0.5);
            above_diagonal += usize::from(w.x > w.y);
        }
        let total = (n * n) as f32;
        assert!((cap as f32 / total - 0.5).abs() < 0.01, "cap {cap}");
        assert!((above_diagonal as f32 / total - 0.5).abs() < 0.01);
    }

    /// Where the ray from `p` along `w` meets the plane of triangle `v`, as
    /// barycentrics `(b1, b2)` of `v[1]` and `v[2]`, unclamped
    /// (Möller–Trumbore); `None` when `w` runs along the plane.
    fn barycentrics(v: &[Vec3; 3], p: Vec3, w: Vec3) -> Option<(f32, f32)> {
        let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
        let s1 = w.cross(e2);
        let divisor = s1.dot(e1);
        let s = p - v[0];
        let b = (s.dot(s1) / divisor, w.dot(s.cross(e1)) / divisor);
        (divisor != 0.0).then_some(b)
    }

    /// `∫ cosθ dω` over a triangle close to and slanted over a receiver,
    /// by the solid-angle samples of a 16 × 16 grid (each `Ω·cosθ`, each
    /// direction checked to point into the triangle), against Lambert's
    /// closed form for a polygon ([`lambert`]).
    #[test]
    fn solid_angle_samples_integrate_the_cosine_over_a_triangle() {
        let v = [
            Vec3::new(-0.3, 0.2, 0.1),
            Vec3::new(0.9, 0.4, -0.2),
            Vec3::new(0.1, 1.1, 0.6),
        ];
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        let sphere = SphericalTriangle::new(&v, p);
        let samples = 16 * 16;
        let estimate: f32 = grid(16)
            .map(|u| {
                let w = sphere.sample(u).unwrap();
                let (b1, b2) = barycentrics(&v, p, w).unwrap();
                let eps = 1e-4;
                assert!(
                    b1 >= -eps && b2 >= -eps && b1 + b2 <= 1.0 + eps,
                    "{b1} {b2}"
                );
                n.dot(w) * sphere.solid_angle
            })
            .sum::<f32>()
            / samples as f32;
        let lambert = lambert(&v, p, n);
        assert!(lambert > 0.1, "{lambert}");
        assert!(
            (estimate / lambert - 1.0).abs() < 2e-3,
            "{estimate} against {lambert}"
        );
    }

    /// Random triangles seen from random points (the map must not panic
    /// or go NaN on any): a direction, where there is one, is a finite unit
    /// vector and `Ω` is finite and within the hemisphere's 2π. Where `Ω`
    /// is within the bounds the renderer uses the map in
    /// ([`crate::light::SOLID_ANGLE_SAMPLING`]; below them the corners'
    /// directions are nearly coplanar and the map loses its digits), the
    /// direction points into the triangle: its unclamped barycentrics are
    /// on it.
    #[test]
    fn spherical_triangle_stays_finite_on_random_triangles() {
        let mut rng = Rng::from_seed(11, 0);
        let mut point = || (rng.next_2d().extend(rng.next_f32()) - 0.5) * 4.0;
        let mut sampled = 0;
        for _ in 0..20_000 {
            let v = [point(), point(), point()];
            let p = point();
            let sphere = SphericalTriangle::new(&v, p);
            assert!(sphere.solid_angle.is_finite(), "{v:?} from {p}");
            assert!(sphere.solid_angle <= 2.0 * PI + 1e-3, "{v:?} from {p}");
            let u = Vec2::new(point().x.abs().fract(), point().y.abs().fract());
            let Some(w) = sphere.sample(u) else { continue };
            assert!(w.is_finite() && (w.length() - 1.0).abs() < 1e-3, "{w}");
            if !crate::light::SOLID_ANGLE_SAMPLING.contains(&sphere.solid_angle) {
                continue;
            }
            let (b1, b2) = barycentrics(&v, p, w).expect("not along the plane");
            let eps = 1e-3;
            assert!(
                b1 >= -eps && b2 >= -eps && b1 + b2 <= 1.0 + eps,
                "{v:?} from {p}, Ω {}: {b1} {b2}",
                sphere.solid_angle
            );
            sampled += 1;
        }
        assert!(sampled > 15_000, "only {sampled} samples");
    }

    /// The weights of two strategies sum to one, also where the pdfs'
    /// squares overflow f32 (a small emitter seen from very far) or a pdf
    /// is infinite; they are never NaN.
    #[test]
    fn power_heuristic_weights_sum_to_one_past_f32s_squares() {
        let pairs = [
            (1.0, 1.0),
            (2.0, 1.0),
            (4e19, 1.0),
            (4e19, 8e19),
            (3e38, 1e-3),
            (f32::INFINITY, 5.0),
            (f32::INFINITY, f32::INFINITY),
        ];
        for (a, b) in pairs {
            let (wa, wb) = (power_heuristic(a, b), power_heuristic(b, a));
            assert!(wa.is_finite() && wb.is_finite(), "{a} {b}: {wa} {wb}");
            assert!((wa + wb - 1.0).abs() < 1e-6, "{a} {b}: {wa} + {wb}");
        }
        assert_eq!(power_heuristic(2.0, 1.0), 0.8);
        assert!((power_heuristic(4e19, 8e19) - 0.2).abs() < 1e-6);
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
    }
}
