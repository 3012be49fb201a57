//! A texture movie (paper §4): the diffuse irradiance of one side of one
//! triangle over an interval of frames, as a texture of `R × R` texels
//! over the triangle's barycentric square (the texels of the lower half
//! and one diagonal beyond it, which bilinear lookups inside the triangle
//! reach). Its resolution is fixed for its life: a triangle whose needed
//! resolution changes gets a new movie (§4.1).

use super::direct::{
    chunk_points, direct_irradiance, ShadePoint, ShadowBlockers, ShadowCounts, StaticShadows,
    Statics,
};
use super::global::GlobalPass;
use super::patch::Patch;
use super::FrameContext;
use crate::sampling::{mix64, streams};
use crate::scene::Triangle;
use crate::store::rgbe;
use glam::Vec3;

/// A movie's identity: which side of which patch of which triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MovieKey {
    pub triangle: u32,
    /// The side against the geometric normal.
    pub back: bool,
    /// The part of the triangle it covers ([`super::patch`]).
    pub patch: Patch,
}

/// One movie, holding the texels of the frame being rendered.
#[derive(Clone, Debug)]
pub struct Movie {
    pub key: MovieKey,
    /// Texels along each of the triangle's two parametric edges.
    pub resolution: u32,
    /// The frame it opened at.
    pub start: u32,
    /// Shadows of static blockers at its texels (kept only for triangles
    /// that do not move: §5, "static occluders are computed once per movie").
    shadows: Option<StaticShadows>,
    /// Whether the memory budget gives it room to keep them this frame
    /// ([`Movie::make_room`]); none until it is given.
    room: bool,
    /// Irradiance per band texel, in storage order (`Movie::band`; row
    /// `j` from `band_offset`).
    pub texels: Vec<Vec3>,
    /// Its direct part alone, per band texel in storage order, RGBE-packed
    /// as the store keeps it (the "bad links" layer, §3.1: what the movie
    /// computes itself; the rest is the global pass's, Gouraud-interpolated
    /// from the stored vertices).
    pub(super) direct: Vec<[u8; 4]>,
    /// The frame the store holds [`Movie::direct`] with, where it holds
    /// them: a frame whose texels encode as the last frame's is not stored
    /// again.
    pub(super) stored_at: Option<u32>,
}

/// The movies of a frame, found by triangle: the render pass looks one up
/// for every camera sample, at each level down the patch hierarchy, where
/// the ordered map's searches took 5 % of `movies`' CPU time (`perf` of
/// the default scene; this index's, 3.5 %). The movies are in [`MovieKey`]
/// order, each triangle's together, so a triangle's are a slice searched
/// by side and patch.
pub(super) struct MovieIndex<'a> {
    /// Triangle `t`'s movies are `movies[starts[t]..starts[t + 1]]`.
    starts: Vec<u32>,
    movies: Vec<&'a Movie>,
}

impl<'a> MovieIndex<'a> {
    /// Indexes `movies`, in key order.
    pub fn new(movies: impl Iterator<Item = &'a Movie>) -> Self {
        let movies: Vec<&Movie> = movies.collect();
        debug_assert!(movies.windows(2).all(|w| w[0].key < w[1].key));
        let triangles = movies.last().map_or(0, |m| m.key.triangle as usize + 1);
        let mut starts = vec![0u32; triangles + 1];
        for m in &movies {
            starts[m.key.triangle as usize + 1] += 1;
        }
        for t in 0..triangles {
            starts[t + 1] += starts[t];
        }
        MovieIndex { starts, movies }
    }

    /// The movie of `key`, if the frame has it.
    pub fn get(&self, key: &MovieKey) -> Option<&'a Movie> {
        let t = key.triangle as usize;
        let range = *self.starts.get(t)? as usize..*self.starts.get(t + 1)? as usize;
        let of_triangle = &self.movies[range];
        let found = of_triangle.binary_search_by(|m| m.key.cmp(key)).ok()?;
        Some(of_triangle[found])
    }
}

/// Texel `(i, j)` is stored when `i + j ≤ R + 1`.
fn in_band(resolution: u32, i: u32, j: u32) -> bool {
    i + j <= resolution + 1
}

/// Where row `j` of the band starts in storage order: rows 0 to 2 hold
/// `R` texels, row `k ≥ 2` holds `R + 2 − k` (the texels `i` with
/// `i + k ≤ R + 1`). Row `R` starts past the end: the band's length.
fn band_offset(resolution: u32, j: u32) -> usize {
    let (r, j) = (resolution as usize, j as usize);
    if j <= 2 {
        j * r
    } else {
        // 2R, then the rows 2 … j − 1: Σ (R + 2 − k) = (j − 2)(R + 2) − (Σ k).
        2 * r + (j - 2) * (r + 2) - ((j - 1) * j / 2 - 1)
    }
}

impl Movie {
    pub fn open(key: MovieKey, resolution: u32, start: u32, moving: bool) -> Self {
        Movie {
            key,
            resolution,
            start,
            shadows: (!moving).then(StaticShadows::default),
            room: false,
            texels: Vec::new(),
            direct: Vec::new(),
            stored_at: None,
        }
    }

    /// The band's texels, `(index, i, j)`, in storage order; `index`
    /// (`j·R + i`) keys the texel's random numbers ([`texel_item`]).
    fn band(&self) -> impl Iterator<Item = (usize, u32, u32)> + '_ {
        let r = self.resolution;
        (0..r).flat_map(move |j| {
            (0..r)
                .filter(move |&i| in_band(r, i, j))
                .map(move |i| ((j * r + i) as usize, i, j))
        })
    }

    /// Where texel `(i, j)` is evaluated, in the triangle's barycentrics:
    /// its centre, moved onto the patch if it lies beyond the long edge,
    /// and a hair inside.
    fn texel_uv(&self, i: u32, j: u32) -> (f32, f32) {
        self.key.patch.to_triangle(self.texel_st(i, j))
    }

    /// [`Movie::texel_uv`] in the patch's own coordinates.
    fn texel_st(&self, i: u32, j: u32) -> (f32, f32) {
        let r = self.resolution as f32;
        let (mut u, mut v) = ((i as f32 + 0.5) / r, (j as f32 + 0.5) / r);
        let s = u + v;
        if s > 1.0 {
            u /= s;
            v /= s;
        }
        super::global::pulled(u, v)
    }

    fn texel_point(&self, tri: &Triangle, index: usize, (u, v): (f32, f32)) -> ShadePoint {
        let side = if self.key.back { -1.0 } else { 1.0 };
        ShadePoint::on_side(tri, (u, v), side, texel_item(&self.key, index))
    }

    /// The movie's frame of `ctx`: direct light per texel (static shadows
    /// kept from the frame it opened) plus the global pass's indirect.
    pub fn shade(
        &mut self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        global: &GlobalPass,
        samples: u32,
    ) -> ShadowCounts {
        let tri = &ctx.snapshot.triangles[self.key.triangle as usize];
        // Where each band texel is evaluated, found again each frame rather
        // than kept with the movie: with the vertices each interpolates,
        // 40 bytes a texel kept were 0.75 GB of a 1920×1080 frame's movies,
        // and finding them is a small part of shading them.
        let band: Vec<(usize, (f32, f32))> = self
            .band()
            .map(|(index, i, j)| (index, self.texel_uv(i, j)))
            .collect();
        let points: Vec<ShadePoint> = band
            .iter()
            .map(|&(index, uv)| self.texel_point(tri, index, uv))
            .collect();
        let statics = match &mut self.shadows {
            None => Statics::Moving,
            Some(kept) if self.room => Statics::Kept(kept),
            Some(_) => Statics::Unkept,
        };
        let (direct, counts) = direct_irradiance(ctx, blockers, &points, samples, statics);
        // The global pass solves one side of most triangles (a link
        // landing on the other gathers nothing: it neither takes nor gives
        // light there, as one-sided radiosity polygons), both of a flat
        // part with scene on either side. A side's values are its own
        // light, so a side not solved takes none of them: reading them lit
        // the outside of closed rooms with the light of the inside. A side
        // not solved that the camera sees gets its direct light only.
        let solved = global.solves(self.key.triangle, self.key.back);
        let (triangle, back) = (self.key.triangle, self.key.back);
        self.texels.clear();
        self.texels
            .extend(band.iter().zip(&direct).map(|(&(_, (u, v)), &e)| {
                let indirect = if solved {
                    global.indirect_with(&global.gouraud(triangle, back, u, v))
                } else {
                    Vec3::ZERO
                };
                e + indirect
            }));
        let direct: Vec<[u8; 4]> = direct.iter().map(|&e| rgbe::encode(e)).collect();
        if direct != self.direct {
            self.direct = direct;
            self.stored_at = None;
        }
        counts
    }

    /// Its direct part per band texel in storage order, as the store keeps
    /// it (RGBE).
    pub fn direct(&self) -> impl Iterator<Item = Vec3> + '_ {
        self.direct.iter().map(|&e| rgbe::decode(e))
    }

    /// Bilinear lookup at `(s, t)` of the movie's patch.
    pub fn lookup(&self, u: f32, v: f32) -> Vec3 {
        let r = self.resolution;
        let rf = r as f32;
        let axis = |t: f32| {
            let x = t * rf - 0.5;
            let i0 = (x.max(0.0).floor() as u32).min(r - 1);
            let f = (x - i0 as f32).clamp(0.0, 1.0);
            (i0, (i0 + 1).min(r - 1), f)
        };
        let (i0, i1, fx) = axis(u);
        let (j0, j1, fy) = axis(v);
        // Zero outside the band, which a lookup inside the triangle never
        // reads. Each of the two rows' start found once (a lookup runs per
        // camera sample).
        let at = |i: u32, (j, start): (u32, usize)| match in_band(r, i, j) {
            true => self.texels[start + i as usize],
            false => Vec3::ZERO,
        };
        let (row0, row1) = ((j0, band_offset(r, j0)), (j1, band_offset(r, j1)));
        (at(i0, row0) * (1.0 - fx) + at(i1, row0) * fx) * (1.0 - fy)
            + (at(i0, row1) * (1.0 - fx) + at(i1, row1) * fx) * fy
    }

    /// Bytes it holds: itself, its texels (linear, and their direct part
    /// RGBE) and its kept static shadows.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(&self.texels[..])
            + std::mem::size_of_val(&self.direct[..])
            + self.shadow_bytes()
    }

    /// Bytes its kept static shadows hold.
    pub fn shadow_bytes(&self) -> usize {
        self.shadows.as_ref().map_or(0, StaticShadows::bytes)
    }

    /// Its texels in the band: the points it shades.
    fn band_len(&self) -> usize {
        band_offset(self.resolution, self.resolution)
    }

    /// Whether it keeps static shadows valid for the frame of `blockers`
    /// (`None`: it keeps none, its triangle moves).
    pub fn holds_valid_shadows(
        &self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        samples: u32,
    ) -> Option<bool> {
        let kept = self.shadows.as_ref()?;
        Some(kept.valid_for(blockers, self.band_len(), chunk_points(ctx, samples)))
    }

    /// The most bytes its static shadows can hold once found (0 where its
    /// triangle moves).
    pub fn shadow_bound(&self, ctx: &FrameContext, samples: u32) -> usize {
        match self.shadows {
            None => 0,
            Some(_) => StaticShadows::bound(self.band_len(), samples, chunk_points(ctx, samples)),
        }
    }

    /// Gives it room to keep its static shadows this frame, or none: then
    /// it lets go of those it holds and finds them, in its frames to come,
    /// as a movie opened then would, until it is given room.
    pub fn make_room(&mut self, room: bool) {
        self.room = room;
        if !room {
            if let Some(s) = &mut self.shadows {
                *s = StaticShadows::default();
            }
        }
    }
}

/// The texels along an edge the whole triangle would need where a camera
/// ray met it at distance `t`: texels no larger than the pixel's footprint
/// there (§3.1: "at least one texel covers one image pixel"), times
/// `texels_per_pixel`.
pub fn texels_needed(tri: &Triangle, t: f32, pixel_angle: f32, texels_per_pixel: f32) -> f32 {
    let longest = tri.longest_edge();
    let footprint = (t * pixel_angle).max(1e-9);
    let texels = longest * texels_per_pixel / footprint;
    if texels.is_finite() {
        texels
    } else {
        f32::MAX
    }
}

/// The random streams' item of texel `index` (below 2^20: at most 1024²
/// texels) of movie `key`: the triangle from bit 28, the side at 27, the
/// patch's code (below 2^7 to level 3) from 20. A patch deeper than that
/// has no room there: its code, mixed, flips the bits from 20 to 56
/// instead, so that its texels draw other numbers than its triangle's
/// other patches' (two items could meet, with a chance of about one in
/// 2^37 a pair; their texels would then draw the same numbers, each still
/// unbiased).
fn texel_item(key: &MovieKey, index: usize) -> u64 {
    let code = u64::from(key.patch.code());
    let item = u64::from(key.triangle) << 28 | u64::from(key.back) << 27 | index as u64;
    let item = if code < 1 << 7 {
        item | code << 20
    } else {
        item ^ (mix64(code) & ((1 << 57) - (1 << 20)))
    };
    streams::MOVIE_TEXEL | item
}

/// A movie's resolution for `needed` texels along an edge: the next power
/// of two (so that small changes of size are no event), at most `max`.
pub fn resolution_for(needed: f32, max: u32) -> u32 {
    let max = max.max(1);
    if needed.is_nan() || needed >= max as f32 {
        return max;
    }
    (needed.ceil().max(1.0) as u32).next_power_of_two().min(max)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key() -> MovieKey {
        MovieKey {
            triangle: 3,
            back: false,
            patch: Patch::ROOT,
        }
    }

    /// The index finds exactly the movies the ordered map holds: each of
    /// them, and none of the keys it lacks (other patches, the other side,
    /// triangles without movies or past the frame's).
    #[test]
    fn movie_index_finds_what_the_map_holds() {
        let patches = [
            Patch::ROOT,
            Patch::ROOT.child(1),
            Patch::ROOT.child(3).child(2),
        ];
        let mut map = std::collections::BTreeMap::new();
        for (triangle, back, patch) in [
            (0, false, 0),
            (0, true, 1),
            (0, true, 2),
            (2, false, 2),
            (5, true, 0),
        ] {
            let key = MovieKey {
                triangle,
                back,
                patch: patches[patch],
            };
            map.insert(key, Movie::open(key, 2, 0, false));
        }
        let index = MovieIndex::new(map.values());
        for triangle in 0..8 {
            for back in [false, true] {
                for patch in patches.into_iter().chain([Patch::ROOT.child(0)]) {
                    let key = MovieKey {
                        triangle,
                        back,
                        patch,
                    };
                    let found = index.get(&key).map(|m| m.key);
                    assert_eq!(found, map.get(&key).map(|m| m.key), "{key:?}");
                }
            }
        }
    }

    /// The texels of a triangle's patches draw apart down to the deepest
    /// level, and to level 3 as before the patches went deeper.
    #[test]
    fn texels_of_every_patch_draw_their_own_numbers() {
        let mut items = std::collections::HashSet::new();
        let mut level = vec![Patch::ROOT];
        for _ in 0..=crate::method::movies::patch::MAX_LEVEL {
            for &patch in &level {
                let key = MovieKey { patch, ..key() };
                for index in [0, 1, 65535] {
                    let item = texel_item(&key, index);
                    assert!(items.insert(item), "{patch:?} texel {index}");
                    assert_eq!(item & !((1 << 57) - 1), streams::MOVIE_TEXEL);
                    if patch.level <= 3 {
                        let before = 3u64 << 28 | u64::from(patch.code()) << 20 | index as u64;
                        assert_eq!(item, streams::MOVIE_TEXEL | before);
                    }
                }
            }
            level = level
                .iter()
                .flat_map(|p| (0..4).map(|k| p.child(k)))
                .collect();
        }
    }

    /// Every texel a lookup inside the triangle reads is in the band.
    #[test]
    fn lookups_inside_the_triangle_read_only_band_texels() {
        for r in [1u32, 2, 3, 8, 16] {
            let mut movie = Movie::open(key(), r, 0, false);
            movie.texels = vec![Vec3::ONE; movie.band_len()];
            for a in 0..=40 {
                for b in 0..=40 - a {
                    let (u, v) = (a as f32 / 40.0, b as f32 / 40.0);
                    let got = movie.lookup(u, v);
                    assert!(
                        (got - Vec3::ONE).abs().max_element() < 1e-5,
                        "R {r} ({u}, {v}): {got}"
                    );
                }
            }
        }
    }

    /// A texture of a linear function is read back exactly between texel
    /// centres (bilinear).
    #[test]
    fn a_lookup_between_texel_centres_is_bilinear() {
        let r = 8u32;
        let mut movie = Movie::open(key(), r, 0, false);
        let band = movie
            .band()
            .map(|(_, i, j)| Vec3::new(i as f32, j as f32, 1.0));
        movie.texels = band.collect();
        let (u, v) = ((2.5 + 0.5) / 8.0, (1.25 + 0.5) / 8.0);
        let got = movie.lookup(u, v);
        assert!(
            (got - Vec3::new(2.5, 1.25, 1.0)).abs().max_element() < 1e-5,
            "{got}"
        );
    }

    /// The band's rows start, in closed form, where the band counted
    /// texel by texel puts them, and its length is the count.
    #[test]
    fn band_offsets_count_the_band() {
        for r in 1u32..40 {
            let movie = Movie::open(key(), r, 0, false);
            for (at, (_, i, j)) in movie.band().enumerate() {
                assert_eq!(band_offset(r, j) + i as usize, at, "R {r} ({i}, {j})");
            }
            assert_eq!(movie.band_len(), movie.band().count(), "R {r}");
        }
    }

    #[test]
    fn the_needed_resolution_doubles_as_the_footprint_halves() {
        let tri = Triangle {
            p: [Vec3::ZERO, Vec3::X, Vec3::Y],
            n: [Vec3::Z; 3],
        };
        let near = texels_needed(&tri, 1.0, 0.01, 1.0);
        let nearer = texels_needed(&tri, 0.5, 0.01, 1.0);
        assert!((near - 141.42).abs() < 0.01 && (nearer - 282.84).abs() < 0.02);
        assert_eq!(resolution_for(near, 1024), 256);
        assert_eq!(resolution_for(nearer, 1024), 512);
        assert_eq!(resolution_for(nearer, 256), 256);
        assert_eq!(resolution_for(texels_needed(&tri, 1e9, 0.01, 1.0), 256), 1);
        assert_eq!(
            resolution_for(texels_needed(&tri, 0.0, 0.01, 1.0), 256),
            256
        );
        assert_eq!(resolution_for(f32::NAN, 64), 64);
    }
}
