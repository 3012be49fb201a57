//! The patch hierarchy of a triangle (paper §4.1, Fig. 4): a movie covers
//! the whole triangle or one of its sub-triangles, split four ways by the
//! midpoints of the edges, down to [`MAX_LEVEL`]. A triangle seen from
//! near at one end and from far at the other (a floor in perspective) gets
//! small fine textures near the camera and large coarse ones far away,
//! instead of one texture as fine as its nearest pixel over all of it.
//!
//! A patch maps its own barycentric square `(s, t)` (`s + t ≤ 1`) into
//! the triangle's `(u, v)`. Child `k` of a patch, in the parent's
//! coordinates: 0 the corner at `(0, 0)`, 1 at `(1, 0)`, 2 at `(0, 1)`, 3
//! the middle one, turned half a turn.

/// The deepest level: 4⁷ = 16,384 patches a triangle, so a triangle's
/// texels reach 128 × [`MoviesSettings::max_resolution`] an edge (32,768
/// at the default). At 3 levels, 2,048: a ground 600 m across, two
/// triangles, had texels of 41 cm where the camera 3 m away asked for
/// about 3 cm at 128 × 128, and the shadow of a wall on it, blurred over a
/// texel, leaked along the wall's foot (`tests/directional_light.rs`).
///
/// [`MoviesSettings::max_resolution`]: super::MoviesSettings::max_resolution
pub const MAX_LEVEL: u8 = 7;

/// A patch texture finer than this many texels along an edge is split
/// (while the level allows): past it, a quarter of the patch is cheaper
/// than the part the finest pixel does not need.
pub const SPLIT_RESOLUTION: f32 = 32.0;

/// A patch of a triangle: its level and the child taken at each level
/// (two bits a level, the first level highest).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Patch {
    pub level: u8,
    pub path: u16,
}

impl Patch {
    pub const ROOT: Patch = Patch { level: 0, path: 0 };

    /// Child `k` (0..4).
    pub fn child(self, k: u8) -> Patch {
        Patch {
            level: self.level + 1,
            path: (self.path << 2) | u16::from(k),
        }
    }

    /// The child at each level, first level first.
    fn steps(self) -> impl Iterator<Item = u8> {
        (0..self.level).map(move |l| ((self.path >> (2 * (self.level - 1 - l))) & 3) as u8)
    }

    /// A code unique among a triangle's patches (`1` for the root), below
    /// 2^(2·MAX_LEVEL + 1).
    pub fn code(self) -> u32 {
        (1u32 << (2 * self.level)) | u32::from(self.path)
    }

    /// The patch of [`Patch::code`] `code`, if it is one.
    pub fn from_code(code: u32) -> Option<Patch> {
        let level = (0..=MAX_LEVEL).find(|&l| code >> (2 * l) == 1)?;
        Some(Patch {
            level,
            path: (code & ((1 << (2 * level)) - 1)) as u16,
        })
    }

    /// The triangle's `(u, v)` of the patch's `(s, t)`.
    pub fn to_triangle(self, (s, t): (f32, f32)) -> (f32, f32) {
        let steps: Vec<u8> = self.steps().collect();
        steps
            .iter()
            .rev()
            .fold((s, t), |(s, t), &k| to_parent(k, (s, t)))
    }

    /// The patch's `(s, t)` of the triangle's `(u, v)` (outside `[0, 1]`
    /// where the point is not in the patch).
    pub fn from_triangle(self, (u, v): (f32, f32)) -> (f32, f32) {
        self.steps()
            .fold((u, v), |(u, v), k| from_parent(k, (u, v)))
    }
}

/// Child `k`'s `(s, t)` in its parent's coordinates.
pub fn to_parent(k: u8, (s, t): (f32, f32)) -> (f32, f32) {
    match k {
        0 => (0.5 * s, 0.5 * t),
        1 => (0.5 + 0.5 * s, 0.5 * t),
        2 => (0.5 * s, 0.5 + 0.5 * t),
        _ => (0.5 - 0.5 * s, 0.5 - 0.5 * t),
    }
}

/// The inverse of `to_parent`: a point of the parent in child `k`'s coordinates.
pub fn from_parent(k: u8, (u, v): (f32, f32)) -> (f32, f32) {
    match k {
        0 => (2.0 * u, 2.0 * v),
        1 => (2.0 * u - 1.0, 2.0 * v),
        2 => (2.0 * u, 2.0 * v - 1.0),
        _ => (1.0 - 2.0 * u, 1.0 - 2.0 * v),
    }
}

/// The child of a patch that holds the point at `(s, t)` of the patch.
pub fn child_at((s, t): (f32, f32)) -> u8 {
    if s >= 0.5 {
        1
    } else if t >= 0.5 {
        2
    } else if s + t <= 0.5 {
        0
    } else {
        3
    }
}

/// The patches that hold the triangle's point `(u, v)`, from the root
/// down to [`MAX_LEVEL`], each with the point in its own coordinates.
pub fn descent((u, v): (f32, f32)) -> impl Iterator<Item = (Patch, (f32, f32))> {
    std::iter::successors(Some((Patch::ROOT, (u, v))), |&(patch, local)| {
        (patch.level < MAX_LEVEL).then(|| {
            let k = child_at(local);
            (patch.child(k), from_parent(k, local))
        })
    })
}

/// The texels a side's camera samples ask, kept as the most any of them
/// asks in each of the side's deepest patches (level [`MAX_LEVEL`]): all
/// [`Needs::partition`] reads, since a patch needs the most its samples
/// ask, the most of its deepest patches'. A frame's samples are millions
/// (12 bytes each were 0.4 GB of a 1920×1080 frame at 16 spp); the deepest
/// patches they fall in are far fewer where triangles are large, and at
/// most as many where they are small.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Needs {
    /// `(path of a deepest patch, texels asked)`; sorted by path, one
    /// entry a patch, once [`Needs::settle`]d.
    leaves: Vec<(u16, f32)>,
}

impl Needs {
    /// A camera sample's hit at the triangle's `(u, v)`, where the whole
    /// triangle would need `needed` texels along an edge.
    pub fn add(&mut self, uv: (f32, f32), needed: f32) {
        // To the bottom of the descent the lookup (`TextureMovies::movie_at`)
        // takes, so the sample's patch at each level is the one a lookup
        // there finds.
        let (leaf, _) = descent(uv).last().expect("the root at least");
        self.leaves.push((leaf.path, needed));
    }

    /// Adds `other`'s samples.
    pub fn merge(&mut self, other: Needs) {
        self.leaves.extend(other.leaves);
    }

    /// Sorts the leaves by path and keeps one a patch, the most asked
    /// there (`f32::max` is exact and ignores NaN whatever the order).
    pub fn settle(&mut self) {
        self.leaves.sort_unstable_by_key(|l| l.0);
        self.leaves.dedup_by(|later, kept| {
            let same = later.0 == kept.0;
            if same {
                kept.1 = kept.1.max(later.1);
            }
            same
        });
        self.leaves.shrink_to_fit();
    }

    /// The patches the side is split into, each with the texels it needs
    /// along an edge (the most any of its samples asks). A patch that asks
    /// more than [`SPLIT_RESOLUTION`] is split (down to [`MAX_LEVEL`]);
    /// children no sample hit get no movie.
    pub fn partition(mut self) -> Vec<(Patch, f32)> {
        self.settle();
        let mut out = Vec::new();
        split(Patch::ROOT, &self.leaves, &mut out);
        out
    }
}

/// `leaves`: the settled leaves under `patch`, all of them.
fn split(patch: Patch, leaves: &[(u16, f32)], out: &mut Vec<(Patch, f32)>) {
    let scale = (1u32 << patch.level) as f32;
    let needed = leaves.iter().map(|l| l.1).fold(0.0f32, f32::max) / scale;
    if needed <= SPLIT_RESOLUTION || patch.level >= MAX_LEVEL {
        out.push((patch, needed));
        return;
    }
    // The child at this level is the path's next two bits; the paths are
    // sorted, so each child's leaves are a run.
    let shift = 2 * (MAX_LEVEL - 1 - patch.level);
    let mut rest = leaves;
    for k in 0..4u8 {
        let run = rest.partition_point(|l| ((l.0 >> shift) & 3) as u8 <= k);
        let (child, after) = rest.split_at(run);
        if !child.is_empty() {
            split(patch.child(k), child, out);
        }
        rest = after;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn patches() -> Vec<Patch> {
        let mut all = vec![Patch::ROOT];
        let mut level = vec![Patch::ROOT];
        for _ in 0..MAX_LEVEL {
            level = level
                .iter()
                .flat_map(|p| (0..4).map(|k| p.child(k)))
                .collect();
            all.extend(&level);
        }
        all
    }

    /// The children tile their parent: every point of the triangle is in
    /// exactly the patch the descent finds, and maps back to itself.
    #[test]
    fn descending_finds_the_patch_that_maps_back_to_the_point() {
        for i in 0..=40 {
            for j in 0..=40 - i {
                let (u, v) = (i as f32 / 40.0, j as f32 / 40.0);
                let (p, local) = descent((u, v)).last().unwrap();
                assert_eq!(p.level, MAX_LEVEL);
                assert!(local.0 >= -1e-5 && local.1 >= -1e-5 && local.0 + local.1 <= 1.0 + 1e-5);
                let (bu, bv) = p.to_triangle(local);
                assert!((bu - u).abs() < 1e-5 && (bv - v).abs() < 1e-5, "({u}, {v})");
                let again = p.from_triangle((u, v));
                assert!((again.0 - local.0).abs() < 1e-4 && (again.1 - local.1).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn codes_are_unique_and_read_back() {
        let all = patches();
        let mut codes: Vec<u32> = all.iter().map(|p| p.code()).collect();
        for p in &all {
            assert_eq!(Patch::from_code(p.code()), Some(*p));
        }
        codes.sort_unstable();
        codes.dedup();
        assert_eq!(codes.len(), all.len());
        assert_eq!(Patch::from_code(0), None);
    }

    fn needs(samples: &[(f32, f32, f32)]) -> Needs {
        let mut needs = Needs::default();
        for &(u, v, needed) in samples {
            needs.add((u, v), needed);
        }
        needs
    }

    fn partition(samples: &[(f32, f32, f32)]) -> Vec<(Patch, f32)> {
        needs(samples).partition()
    }

    /// A triangle asked for 100 texels at one corner and 5 elsewhere:
    /// split where the fine samples are, whole elsewhere.
    #[test]
    fn a_partition_splits_only_where_fine_texels_are_asked() {
        let samples = [(0.02, 0.02, 100.0), (0.9, 0.05, 5.0), (0.05, 0.9, 5.0)];
        let parts = partition(&samples);
        let fine = parts
            .iter()
            .find(|(p, _)| p.level == 2)
            .expect("a level-2 patch");
        assert!((fine.1 - 25.0).abs() < 1e-4, "{parts:?}");
        assert!(parts.iter().all(|(_, r)| *r <= SPLIT_RESOLUTION));
        // The coarse corners stay at level 1.
        assert_eq!(
            parts.iter().filter(|(p, _)| p.level == 1).count(),
            2,
            "{parts:?}"
        );
        // A triangle that asks little stays whole.
        assert_eq!(partition(&[(0.3, 0.3, 8.0)]), vec![(Patch::ROOT, 8.0)]);
    }

    /// The split as it was made from every sample (each level descending
    /// the samples of its patch): the reference the leaves must match.
    fn split_samples(patch: Patch, samples: Vec<(f32, f32, f32)>, out: &mut Vec<(Patch, f32)>) {
        let scale = (1u32 << patch.level) as f32;
        let needed = samples.iter().map(|s| s.2).fold(0.0f32, f32::max) / scale;
        if needed <= SPLIT_RESOLUTION || patch.level >= MAX_LEVEL {
            out.push((patch, needed));
            return;
        }
        let mut children: [Vec<(f32, f32, f32)>; 4] = Default::default();
        for (s, t, r) in samples {
            let k = child_at((s, t));
            let (cs, ct) = from_parent(k, (s, t));
            children[k as usize].push((cs, ct, r));
        }
        for (k, c) in children.into_iter().enumerate() {
            if !c.is_empty() {
                split_samples(patch.child(k as u8), c, out);
            }
        }
    }

    /// On samples scattered over the triangle or crowded in a corner,
    /// asking from a few texels to far past the deepest split (NaN among
    /// them), the partition from the leaves' maxima is the one made from
    /// every sample, bit for bit, and the same whichever way the samples
    /// were split among tiles.
    #[test]
    fn a_partition_from_the_leaves_is_the_one_from_every_sample() {
        use crate::sampling::{Rng, SampleKey};
        let mut rng = Rng::new(SampleKey {
            seed: 7,
            frame: None,
            item: 0,
            sample: 0,
        });
        for round in 0..40 {
            let n = 1 + round * 50;
            let reach = [4.0, 64.0, 1e3, 1e6][round / 2 % 4];
            // Every other round in a corner a few deepest patches across,
            // where many samples share a patch.
            let spread = [1.0, 0.002][round % 2];
            let samples: Vec<(f32, f32, f32)> = (0..n)
                .map(|i| {
                    let (a, b) = (spread * rng.next_f32(), spread * rng.next_f32());
                    let (u, v) = if a + b > 1.0 {
                        (1.0 - a, 1.0 - b)
                    } else {
                        (a, b)
                    };
                    let needed = if i % 97 == 5 {
                        f32::NAN
                    } else {
                        reach * rng.next_f32()
                    };
                    (u, v, needed)
                })
                .collect();
            let mut expected = Vec::new();
            split_samples(Patch::ROOT, samples.clone(), &mut expected);
            let got = partition(&samples);
            assert_eq!(format!("{got:?}"), format!("{expected:?}"), "round {round}");
            let cut = n / 3;
            let mut tiles = needs(&samples[..cut]);
            tiles.settle();
            let mut rest = needs(&samples[cut..]);
            rest.settle();
            tiles.merge(rest);
            assert_eq!(format!("{:?}", tiles.partition()), format!("{expected:?}"));
        }
    }
}
