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
use super::mesh::Gouraud;
use super::patch::Patch;
use super::FrameContext;
use crate::sampling::{mix64, streams};
use crate::scene::Triangle;
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
    /// Irradiance per texel (`j·R + i`; zero outside the band).
    pub texels: Vec<Vec3>,
    /// Its direct part alone, per band texel in storage order (the "bad
    /// links" layer, §3.1: what the movie computes itself; the rest is the
    /// global pass's, Gouraud-interpolated).
    pub direct: Vec<Vec3>,
    /// The texels as last stored, RGBE, and the frame they were stored
    /// with (a frame whose texels encode the same is not stored again).
    pub(super) stored: Option<(u32, Vec<[u8; 4]>)>,
    /// Per band texel: its index, where it is evaluated, and the global
    /// pass's vertices it interpolates (fixed for the movie's life: the
    /// vertices are the same whichever side of the triangle is solved).
    layout: Vec<(usize, (f32, f32), Gouraud)>,
}

/// Texel `(i, j)` is stored when `i + j ≤ R + 1`.
fn in_band(resolution: u32, i: u32, j: u32) -> bool {
    i + j <= resolution + 1
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
            stored: None,
            layout: Vec::new(),
        }
    }

    /// The band's texels, `(index, i, j)`, in storage order.
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
        if self.layout.is_empty() {
            self.layout = self
                .band()
                .map(|(index, i, j)| {
                    let (u, v) = self.texel_uv(i, j);
                    let g = global.gouraud(self.key.triangle, self.key.back, u, v);
                    (index, (u, v), g)
                })
                .collect();
        }
        let points: Vec<ShadePoint> = self
            .layout
            .iter()
            .map(|&(index, uv, _)| self.texel_point(tri, index, uv))
            .collect();
        let statics = match &mut self.shadows {
            None => Statics::Moving,
            Some(kept) if self.room => Statics::Kept(kept),
            Some(_) => Statics::Unkept,
        };
        let (direct, counts) = direct_irradiance(ctx, blockers, &points, samples, statics);
        let r = self.resolution as usize;
        self.texels.clear();
        self.texels.resize(r * r, Vec3::ZERO);
        // The global pass solves one side of most triangles (a link
        // landing on the other gathers nothing: it neither takes nor gives
        // light there, as one-sided radiosity polygons), both of a flat
        // part with scene on either side. A side's values are its own
        // light, so a side not solved takes none of them: reading them lit
        // the outside of closed rooms with the light of the inside. A side
        // not solved that the camera sees gets its direct light only.
        let solved = global.solves(self.key.triangle, self.key.back);
        for (&(index, _, g), &e) in self.layout.iter().zip(&direct) {
            let indirect = if solved {
                global.indirect_with(&g)
            } else {
                Vec3::ZERO
            };
            self.texels[index] = e + indirect;
        }
        self.direct = direct;
        counts
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
        let at = |i: u32, j: u32| self.texels[(j * r + i) as usize];
        (at(i0, j0) * (1.0 - fx) + at(i1, j0) * fx) * (1.0 - fy)
            + (at(i0, j1) * (1.0 - fx) + at(i1, j1) * fx) * fy
    }

    /// Bytes it holds: itself, its texels (linear and as last stored),
    /// their layout and its kept static shadows.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(&self.texels[..])
            + std::mem::size_of_val(&self.direct[..])
            + self
                .stored
                .as_ref()
                .map_or(0, |(_, rgbe)| std::mem::size_of_val(&rgbe[..]))
            + std::mem::size_of_val(&self.layout[..])
            + self.shadow_bytes()
    }

    /// Bytes its kept static shadows hold.
    pub fn shadow_bytes(&self) -> usize {
        self.shadows.as_ref().map_or(0, StaticShadows::bytes)
    }

    /// Its texels in the band: the points it shades.
    fn band_len(&self) -> usize {
        let r = self.resolution as usize;
        // Row j holds the texels i < R with i + j ≤ R + 1.
        (0..r).map(|j| r.min(r + 2 - j)).sum()
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
            movie.texels = vec![Vec3::ZERO; (r * r) as usize];
            for (index, _, _) in movie.band().collect::<Vec<_>>() {
                movie.texels[index] = Vec3::ONE;
            }
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
        movie.texels = vec![Vec3::ZERO; (r * r) as usize];
        for (index, i, j) in movie.band().collect::<Vec<_>>() {
            movie.texels[index] = Vec3::new(i as f32, j as f32, 1.0);
        }
        let (u, v) = ((2.5 + 0.5) / 8.0, (1.25 + 0.5) / 8.0);
        let got = movie.lookup(u, v);
        assert!(
            (got - Vec3::new(2.5, 1.25, 1.0)).abs().max_element() < 1e-5,
            "{got}"
        );
    }

    /// The band's length in closed form is the band counted texel by texel.
    #[test]
    fn band_len_counts_the_band() {
        for r in 1u32..40 {
            let movie = Movie::open(key(), r, 0, false);
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
