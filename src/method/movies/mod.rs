//! `movies`: texture movies with a coarse global pass (Martín, Pueyo &
//! Tost, "Frame-to-Frame Coherent Animation with Two-Pass Radiosity",
//! 2003 — `papers/texture-movies-two-pass-radiosity-2003.md`).
//!
//! Each visible side of a triangle, or of a part of it ([`patch`]), gets a
//! *texture movie*: its diffuse irradiance as a texture, frame after
//! frame, at the resolution its projected size needs (§4.1). Per frame:
//! 1. *global pass* ([`global`]): a coarse radiosity solution whose links
//!    are traced again only where motion may have changed them (§4.2);
//! 2. *item buffer*: the camera rays of the frame's pixel samples say
//!    which sides of which triangles are seen and at what resolution; a
//!    side is split into sub-triangles where its finest texels are asked
//!    ([`patch`], §4.1's hierarchy). A movie opens when its patch becomes
//!    visible, closes when it is no longer seen, and is replaced by a new
//!    one when its resolution changes (§4.1's events);
//! 3. *movies* ([`movie`]): each open movie's texels get their direct
//!    light (the "bad links"), with the shadows of static blockers found
//!    once per movie and only the moving blockers tested each frame
//!    (§5, Fig. 6; [`direct`]), plus the global pass's indirect light
//!    (the "good links", Gouraud-interpolated);
//! 4. *render*: each pixel sample reads its texel (bilinear) for the
//!    diffuse part; a glossy lobe is path-traced, as `ic` does.
//!
//! Departures, each named where it is made: the global pass is point
//! collocation, not hierarchical radiosity ([`global`]), whose links
//! take the direct light at their hits where it changes sharply across
//! the cell they land in rather than refining the mesh ([`sharp`]),
//! whose triangles too large for one grid are split towards what the
//! camera sees rather than by the links' error ([`pieces`]), whose
//! triangles far smaller than its spacing have their corners clustered,
//! one vertex gathering for each cluster ([`mesh`]), and
//! carries
//! glossy surfaces, which the paper's diffuse radiosity has not: the
//! direct light a lobe reflects goes along each link where the lobe
//! points, its indirect light is spread evenly
//! (`GlobalPass::glossy_direct`, `spread_albedo`); static and
//! moving shadows merge per sample, exactly, rather than by the paper's
//! formula ([`direct`]); a patch is split where the texels it needs are
//! fine, not where it is partly hidden (the paper's criterion is the
//! visible fraction and the projected size; ours is the size alone, which
//! also leaves hidden sub-patches without a movie); a movie's
//! frames are computed as the frames are rendered rather than over its
//! whole interval up front, so that no frame waits for a later one, and
//! the texture of a frame depends only on that frame (a resumed render
//! equals an uninterrupted one with no state carried); the global pass
//! solves one side of each triangle, its front or, where its part
//! encloses the camera facing away from it, its back ([`sides`]), and a
//! side the camera sees that it does not solve gets its
//! direct light only ([`movie`]). The paper's disk
//! cache of movie frames under a memory budget is the store's `movies`
//! tree: each frame's textures are written with the frame, and only the
//! frame being rendered is held in memory. The memory budget
//! (`memory_mib`) is for what we keep in memory from frame to frame
//! instead, the movies' static shadows (the paper's one static
//! transmittance texture per movie), and it holds while they are found:
//! a movie given no room finds them again each frame.
//!
//! # Measured
//! `radcache bench --scenes cube-in-box --size 64x64 --frames 0..400
//! --reference-spp 256 --methods ic movies` (at 04e1861): 2.05× faster
//! than `ic`, 0.89× its error (block bias 0.0017 against 0.0031), 0.40×
//! its flicker (0.24× on lit surfaces). Where what moves is everywhere its
//! coherence goes, as the paper says: under the moving light 0.97× `ic`'s
//! speed (every shadow sample lands on a moving light), on the 66 moving
//! balls of `spheres` 1.70×, both with less error than `ic`
//! (`benches/RESULTS.md`, "`movies` against `ic`"; 3.09× on cube-in-box
//! at e9e482c, with 1.01× `ic`'s error).

pub mod direct;
pub mod global;
pub mod mesh;
pub mod movie;
pub mod patch;
pub mod pieces;
pub mod sharp;
pub mod sides;
pub mod view;

use super::pixels::FirstLightSampler;
use super::render_pass::{direct_light, glossy_query, PixelStreams, PrimarySamples, Surface};
use super::{FrameContext, FrameRecords, FrameStats, Method, RENDER_PHASE};
use crate::backend::Hit;
use crate::film::Film;
use crate::integrator::{trace_radiance, PathLength, RadianceQuery};
use crate::light::emitting_cosine;
use crate::method::pixels::EmitterEdges;
use crate::store::rgbe;
use crate::store::samples::compress;
use crate::store::schema::{MovieFramesValue, MovieValue};
pub use direct::ShadowCounts;
pub use direct::{paper_merge, MAX_SHADOW_SAMPLES};
use glam::Vec3;
use global::{GlobalPass, GlobalSettings};
use movie::MovieIndex;
pub use movie::{Movie, MovieKey};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::f32::consts::FRAC_1_PI;
use std::mem::size_of;
use std::time::Instant;

/// Settings of `movies`, with their sources.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MoviesSettings {
    /// Pixel samples (the texture is read per sample; the glossy lobe is
    /// path-traced per sample).
    pub spp: u32,
    /// Shadow samples per texel (the paper's `N` sample points on the
    /// shooter, §3.1; it takes more for larger form factors, we take a
    /// fixed number, at most [`MAX_SHADOW_SAMPLES`]).
    pub shadow_samples: u32,
    /// Texels across a pixel's footprint (§3.1: at least one texel a
    /// pixel, so 1).
    pub texels_per_pixel: f32,
    /// The finest texture, in texels along an edge.
    pub max_resolution: u32,
    /// Memory for the movies' kept static shadows, in MiB (the paper's
    /// user-set texture memory, §5), held at every moment of a frame
    /// (`TextureMovies::make_room_for_shadows`): a movie given no room
    /// finds its static shadows each frame and lets them go, as a new
    /// movie would (same texels, more rays). It bounds neither the
    /// texels, nor the global pass (its own static shadows included), nor
    /// the working buffers of a batch of points being shaded.
    pub memory_mib: u32,
    pub global: GlobalSettings,
    /// Paths of the glossy lobes.
    pub length: PathLength,
}

impl Default for MoviesSettings {
    fn default() -> Self {
        MoviesSettings {
            spp: 16,
            shadow_samples: 16,
            texels_per_pixel: 1.0,
            max_resolution: 256,
            memory_mib: 512,
            global: GlobalSettings::default(),
            length: PathLength::default(),
        }
    }
}

/// The `movies` method: open movies from frame to frame and the global
/// pass's links.
pub struct TextureMovies {
    pub settings: MoviesSettings,
    global: Option<GlobalPass>,
    movies: BTreeMap<MovieKey, Movie>,
    /// The static triangles alone, for the static shadows of segments
    /// that cross a moving object ([`direct::ShadowBlockers`]).
    statics: direct::StaticGeometry,
    stats: FrameStats,
    /// The movies' shadow samples of the last frame.
    shadows: ShadowCounts,
    /// The bytes of the movies' static shadows once the last frame's were
    /// found: the most they held in the frame.
    shadow_bytes: usize,
    /// Whether to hand each frame's movies to the store.
    keep: bool,
    kept: Option<FrameRecords>,
    /// The most bytes of hits the item buffer holds ([`HELD_HITS_BYTES`]).
    held_hits_bytes: usize,
}

/// The most bytes of its camera samples' hits a frame's item buffer holds
/// from the trace to the render; a frame with more traces its camera rays
/// again as each tile is rendered. A 3840×2160 frame of cube-in-box at
/// 16 spp has 2.65 GB of hits, half its peak memory (4.98 GB); traced
/// again, it peaks at 2.40 GB and takes 4 % more time (`benches/RESULTS.md`).
/// 1 GiB holds the hits of 1920×1080 at 16 spp, 0.66 GB, with room to
/// spare.
pub const HELD_HITS_BYTES: usize = 1 << 30;

impl TextureMovies {
    pub fn new(settings: MoviesSettings) -> Self {
        TextureMovies {
            settings,
            global: None,
            movies: BTreeMap::new(),
            statics: direct::StaticGeometry::default(),
            stats: FrameStats::default(),
            shadows: ShadowCounts::default(),
            shadow_bytes: 0,
            keep: false,
            kept: None,
            held_hits_bytes: HELD_HITS_BYTES,
        }
    }

    /// Frame `frame`'s movies in their stored form: texels RGBE-packed,
    /// the whole zstd-compressed; a movie whose texels encode as those it
    /// last stored points at that frame instead.
    fn stored_movies(&mut self, frame: u32) -> MovieFramesValue {
        let mut values = Vec::with_capacity(self.movies.len());
        let mut bytes = Vec::new();
        for m in self.movies.values_mut() {
            let (texels, stored_at) = match m.stored_at {
                Some(at) => (0, at),
                None => {
                    bytes.extend(m.direct.iter().flatten());
                    m.stored_at = Some(frame);
                    (m.direct.len() as u32, frame)
                }
            };
            values.push(MovieValue {
                triangle: m.key.triangle,
                back: m.key.back,
                patch: m.key.patch.code(),
                resolution: m.resolution,
                start: m.start,
                texels,
                stored_at,
            });
        }
        let global = self
            .global
            .as_ref()
            .map(|g| g.indirect())
            .unwrap_or_default();
        let global_bytes: Vec<u8> = global.iter().flat_map(|&e| rgbe::encode(e)).collect();
        MovieFramesValue {
            movies: values,
            texels_zstd: compress(&bytes),
            global_vertices: global.len() as u32,
            global_zstd: compress(&global_bytes),
        }
    }

    /// Makes room within [`MoviesSettings::memory_mib`] for the static
    /// shadows the frame's movies will hold, before any is found, so that
    /// the budget holds at every moment of the frame, not only at its end:
    /// the shadows still valid stay (their rays are saved already; the
    /// largest are given up first were they over the budget), and a movie
    /// without valid ones (opened, or given no room before) gets room for
    /// the most its texels can need ([`Movie::shadow_bound`]), in key
    /// order, while the budget has it. A movie given none finds its static
    /// shadows for the frame batch by batch and lets them go (its texels
    /// are a new movie's; its rays every sample's), and asks again next
    /// frame. (Finding every movie's shadows and then dropping the largest
    /// until the rest fit, as before, held them all in every frame,
    /// whatever the budget: about 300 MiB at 256×256 on cube-in-box, 4.6 kB
    /// a pixel, so some 10 GB at 1920×1080.)
    fn make_room_for_shadows(&mut self, ctx: &FrameContext, blockers: &direct::ShadowBlockers) {
        let budget = (self.settings.memory_mib as usize).saturating_mul(1 << 20);
        let samples = self.settings.shadow_samples;
        let mut held = 0usize;
        let mut kept: Vec<(usize, MovieKey)> = Vec::new();
        let mut wanting: Vec<MovieKey> = Vec::new();
        for (key, m) in self.movies.iter_mut() {
            match m.holds_valid_shadows(ctx, blockers, samples) {
                None => {}
                Some(true) => {
                    let bytes = m.shadow_bytes();
                    held += bytes;
                    kept.push((bytes, *key));
                }
                Some(false) => {
                    // Let go of now: shadows no longer valid are found
                    // again, and must not be held beside their successors.
                    m.make_room(false);
                    wanting.push(*key);
                }
            }
        }
        kept.sort_by(|a, b| b.cmp(a));
        for (bytes, key) in kept {
            if held <= budget {
                break;
            }
            if let Some(m) = self.movies.get_mut(&key) {
                m.make_room(false);
                held -= bytes;
            }
        }
        for key in wanting {
            if let Some(m) = self.movies.get_mut(&key) {
                let need = m.shadow_bound(ctx, samples);
                let room = held + need <= budget;
                if room {
                    held += need;
                }
                m.make_room(room);
            }
        }
    }

    /// The movies open after the last frame.
    pub fn movies(&self) -> impl Iterator<Item = &Movie> {
        self.movies.values()
    }

    /// The movies' shadow samples in the last frame: traced, and answered
    /// by the kept static shadows alone.
    pub fn last_shadow_counts(&self) -> ShadowCounts {
        self.shadows
    }

    /// The most bytes the movies' static shadows held in the last frame
    /// (within [`MoviesSettings::memory_mib`]).
    pub fn last_shadow_bytes(&self) -> usize {
        self.shadow_bytes
    }
}

/// A tile of pixels: its camera samples' first hits, held from the trace
/// to the render (the item buffer) within [`HELD_HITS_BYTES`] a frame,
/// and the sides they see until [`TextureMovies::wanted_movies`] takes
/// them. The samples' camera rays and streams are not held:
/// [`PrimarySamples::again`] draws them again to render the tile (84
/// bytes a sample held for the whole frame were 2.8 GB of a 1920×1080
/// frame at 16 spp; its hits alone are 0.7 GB).
struct Tile {
    first: u32,
    count: u32,
    /// `None` where the frame's hits are past [`HELD_HITS_BYTES`]: the
    /// tile's camera rays are traced again to render it.
    hits: Option<Vec<Hit>>,
    edges: EmitterEdges,
    seen: SeenSides,
}

/// The sides of triangles a tile's samples see with a diffuse part, each
/// with the texels its samples ask where.
type SeenSides = BTreeMap<(u32, bool), patch::Needs>;

impl Method for TextureMovies {
    fn name(&self) -> &'static str {
        "movies"
    }

    fn cache_unit(&self) -> &'static str {
        "texture movies"
    }

    fn lifespans_counted(&self) -> &'static str {
        "that ended"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        let mut stats = FrameStats {
            frame: ctx.frame,
            ..FrameStats::default()
        };
        let blockers = direct::ShadowBlockers::new(ctx, &mut self.statics);

        let start = Instant::now();
        self.update_global(ctx, &blockers);
        stats
            .phase_seconds
            .push(("global".into(), start.elapsed().as_secs_f64()));

        let start = Instant::now();
        let mut tiles = self.trace_tiles(ctx);
        if ctx.abandoned() {
            // Thrown away (`FrameContext::abandoned`): the tiles are partial.
            return self.abandon_frame(ctx);
        }
        let wanted = self.wanted_movies(&mut tiles);
        self.apply_events(ctx, wanted, &blockers, &mut stats);
        if !self.shade_movies(ctx, &blockers) {
            // The movies the loop skipped are half built: one opened this
            // frame has no texels (a lookup would index nothing), a kept one
            // the last frame's. None may be rendered or kept.
            return self.abandon_frame(ctx);
        }
        stats
            .phase_seconds
            .push(("movies".into(), start.elapsed().as_secs_f64()));

        let start = Instant::now();
        let film = self.render(ctx, tiles, &mut stats);
        if ctx.abandoned() {
            // Its glossy paths were cut short; and its movies' texels must
            // not be marked stored with a frame the store never gets.
            return self.abandon_frame(ctx);
        }
        stats
            .phase_seconds
            .push((RENDER_PHASE.into(), start.elapsed().as_secs_f64()));
        stats.records_alive = self.movies.len() as u64;
        stats.cache_bytes = self.cache_bytes();
        self.stats = stats;
        self.kept = self.keep.then(|| FrameRecords {
            movies: Some(self.stored_movies(ctx.frame)),
            ..FrameRecords::default()
        });
        film
    }

    fn last_frame_stats(&self) -> FrameStats {
        self.stats.clone()
    }

    fn keep_frame_records(&mut self, keep: bool) {
        self.keep = keep;
    }

    fn take_frame_records(&mut self) -> Option<FrameRecords> {
        self.kept.take()
    }
}

impl TextureMovies {
    /// The global pass of `ctx`'s frame: built where there is none or the
    /// scene's triangles changed in number, then updated.
    fn update_global(&mut self, ctx: &FrameContext, blockers: &direct::ShadowBlockers) {
        let fresh = !self
            .global
            .as_ref()
            .is_some_and(|g| g.fits(ctx.snapshot.triangles.len()));
        if fresh {
            self.global = Some(GlobalPass::new(ctx, self.settings.global));
        }
        let global = self.global.as_mut().expect("built above");
        global.update(ctx, blockers, fresh);
    }

    /// The frame's movies' texels (their direct light, and the global
    /// pass's indirect light), their shadows kept within the budget.
    /// `false` where the frame was abandoned part way.
    fn shade_movies(&mut self, ctx: &FrameContext, blockers: &direct::ShadowBlockers) -> bool {
        self.make_room_for_shadows(ctx, blockers);
        let global = self.global.as_ref().expect("updated before");
        let samples = self.settings.shadow_samples;
        let counts: Vec<ShadowCounts> = self
            .movies
            .par_iter_mut()
            .map(|(_, m)| match ctx.abandoned() {
                true => ShadowCounts::default(),
                false => m.shade(ctx, blockers, global, samples),
            })
            .collect();
        if ctx.abandoned() {
            return false;
        }
        self.shadows = ShadowCounts::default();
        counts.into_iter().for_each(|c| self.shadows += c);
        // Shadows are only let go of before the movies are shaded, and
        // found while they are: their most in the frame is now.
        self.shadow_bytes = self.movies.values().map(Movie::shadow_bytes).sum();
        true
    }

    /// The bytes of the cache a frame holds: the movies, and the global
    /// pass's solution with the working buffers it needs beside it each
    /// frame (about one and a half times its links' bytes on a frame that
    /// traces them all), whose peak counts.
    fn cache_bytes(&self) -> u64 {
        let global = (self.global.as_ref()).map_or(0, |g| g.memory_bytes() + g.working_bytes());
        (self.movies.values().map(Movie::memory_bytes).sum::<usize>() + global) as u64
    }

    /// The end of an abandoned frame ([`FrameContext::abandoned`]), which
    /// the renderer throws away: an empty film, no frame records, and no
    /// movie left, so that nothing half built is rendered, kept or stored
    /// (a later frame opens its movies again, as a fresh instance would).
    /// The global pass, which runs to its end before any check, stays.
    fn abandon_frame(&mut self, ctx: &FrameContext) -> Film {
        self.movies.clear();
        self.shadows = ShadowCounts::default();
        self.shadow_bytes = 0;
        self.kept = None;
        self.stats = FrameStats {
            frame: ctx.frame,
            ..FrameStats::default()
        };
        Film::new(ctx.width, ctx.height)
    }

    fn tile_pixels(&self, ctx: &FrameContext) -> u32 {
        let pixels = (ctx.width * ctx.height) as usize;
        let spp = self.settings.spp.max(1) as usize;
        ctx.backend.items_per_task(pixels, spp) as u32
    }

    /// The camera samples of every pixel, tile by tile, with their hits:
    /// the item buffer of the frame and the first step of its render.
    fn trace_tiles(&self, ctx: &FrameContext) -> Vec<Tile> {
        let spp = self.settings.spp.max(1);
        let per_tile = self.tile_pixels(ctx);
        let n_pixels = ctx.width * ctx.height;
        // The base samples' hits; a light's edge pixels add a few.
        let hit_bytes = (n_pixels as usize * spp as usize).saturating_mul(size_of::<Hit>());
        let hold = hit_bytes <= self.held_hits_bytes;
        let starts: Vec<u32> = (0..n_pixels).step_by(per_tile as usize).collect();
        starts
            .into_par_iter()
            .filter(|_| !ctx.abandoned())
            .map(|first| {
                let count = per_tile.min(n_pixels - first);
                let (primary, edges) =
                    PrimarySamples::trace(ctx, PixelStreams::PerFrame, first, count, spp);
                Tile {
                    first,
                    count,
                    seen: self.seen_sides(ctx, &primary),
                    hits: hold.then_some(primary.hits),
                    edges,
                }
            })
            .collect()
    }

    /// The sides `primary`'s samples see, and the texels each sample needs
    /// there (the finest the pixel's footprint asks).
    fn seen_sides(&self, ctx: &FrameContext, primary: &PrimarySamples) -> SeenSides {
        let pixel_angle = ctx.pixel_angle();
        let per_pixel = self.settings.texels_per_pixel;
        let mut sides = SeenSides::new();
        for (ray, hit) in primary.rays.iter().zip(&primary.hits) {
            let Some(side) = seen_side(ctx, ray.dir(), hit) else {
                continue;
            };
            let tri = &ctx.snapshot.triangles[hit.triangle as usize];
            let distance = hit.t * ray.dir().length();
            let needed = movie::texels_needed(tri, distance, pixel_angle, per_pixel);
            sides.entry(side).or_default().add((hit.u, hit.v), needed);
        }
        sides.values_mut().for_each(patch::Needs::settle);
        sides
    }

    /// Which patches of which sides of which triangles the samples see
    /// with a diffuse part, and the resolution each needs (the finest any
    /// of its samples asks): each side split where its finest texels are
    /// asked ([`patch::Needs::partition`]). Takes the tiles' seen sides,
    /// which they hold no longer.
    fn wanted_movies(&self, tiles: &mut [Tile]) -> BTreeMap<MovieKey, u32> {
        let s = &self.settings;
        let mut sides = SeenSides::new();
        for tile in tiles {
            for (side, needs) in std::mem::take(&mut tile.seen) {
                sides.entry(side).or_default().merge(needs);
            }
        }
        let mut wanted = BTreeMap::new();
        for ((triangle, back), needs) in sides {
            for (patch, needed) in needs.partition() {
                let key = MovieKey {
                    triangle,
                    back,
                    patch,
                };
                wanted.insert(key, movie::resolution_for(needed, s.max_resolution));
            }
        }
        wanted
    }

    /// The movie that holds the point a camera ray along `dir` hit, and
    /// the point in its patch's coordinates: the patches of the hit's side
    /// descended as [`patch::Needs::partition`] split them.
    fn movie_at<'m>(
        movies: &MovieIndex<'m>,
        ctx: &FrameContext,
        dir: Vec3,
        hit: &Hit,
    ) -> Option<(&'m Movie, (f32, f32))> {
        let (triangle, back) = seen_side(ctx, dir, hit)?;
        patch::descent((hit.u, hit.v)).find_map(|(patch, local)| {
            let key = MovieKey {
                triangle,
                back,
                patch,
            };
            Some((movies.get(&key)?, local))
        })
    }

    /// §4.1's events: movies no longer seen close, movies whose needed
    /// resolution changed are replaced, newly seen patches open.
    fn apply_events(
        &mut self,
        ctx: &FrameContext,
        wanted: BTreeMap<MovieKey, u32>,
        blockers: &direct::ShadowBlockers,
        stats: &mut FrameStats,
    ) {
        let mut closed_lengths = Vec::new();
        self.movies.retain(|key, m| {
            let keep = wanted.get(key) == Some(&m.resolution);
            if !keep {
                closed_lengths.push(ctx.frame.saturating_sub(m.start));
                if wanted.contains_key(key) {
                    stats.records_replaced += 1;
                } else {
                    stats.records_dropped += 1;
                }
            } else {
                stats.records_reused += 1;
            }
            keep
        });
        for (key, resolution) in wanted {
            self.movies.entry(key).or_insert_with(|| {
                stats.records_created += 1;
                let moving = blockers.is_moving_triangle(key.triangle);
                Movie::open(key, resolution, ctx.frame, moving)
            });
        }
        stats.records_created -= stats.records_replaced.min(stats.records_created);
        // Lengths of the movies that ended, in frames.
        for length in closed_lengths {
            let l = length as usize;
            if stats.lifespan_histogram.len() <= l {
                stats.lifespan_histogram.resize(l + 1, 0);
            }
            stats.lifespan_histogram[l] += 1;
        }
        stats.mean_lifespan = super::mean_lifespan(&stats.lifespan_histogram);
    }

    /// Each pixel sample: emission, the diffuse part from its texel, and
    /// the glossy lobe path-traced.
    fn render(&self, ctx: &FrameContext, tiles: Vec<Tile>, stats: &mut FrameStats) -> Film {
        let mut film = Film::new(ctx.width, ctx.height);
        let per_tile = self.tile_pixels(ctx) as usize;
        let movies = MovieIndex::new(self.movies.values());
        let lookups: Vec<u64> = film
            .pixels
            .par_chunks_mut(per_tile)
            .zip(tiles)
            .map(|(out, tile)| {
                debug_assert_eq!(out.len(), tile.count as usize);
                self.render_tile(ctx, &movies, tile, out)
            })
            .collect();
        stats.lookups = lookups.iter().sum();
        film
    }

    fn render_tile(
        &self,
        ctx: &FrameContext,
        movies: &MovieIndex,
        tile: Tile,
        out: &mut [Vec3],
    ) -> u64 {
        let spp = self.settings.spp.max(1);
        let streams = PixelStreams::PerFrame;
        let mut primary = match tile.hits {
            Some(hits) => {
                let shape = (tile.first, tile.count, spp);
                PrimarySamples::again(ctx, streams, shape, &tile.edges, hits)
            }
            // The same samples, rays and hits as the first trace (its edge
            // pixels too: the trace is keyed by the samples alone).
            None => PrimarySamples::trace(ctx, streams, tile.first, tile.count, spp).0,
        };
        let surfaces: Vec<Option<Surface>> = primary.surfaces(ctx);
        let mut radiance = vec![Vec3::ZERO; surfaces.len()];
        let mut lights = FirstLightSampler::default();
        let mut shadows = Vec::new();
        let mut glossy: Vec<(usize, RadianceQuery)> = Vec::new();
        let mut lookups = 0u64;
        for (i, surface) in surfaces.iter().enumerate() {
            let Some(s) = surface else { continue };
            if s.material.is_emissive()
                && emitting_cosine(s.triangle, s.material.double_sided, s.wo).is_some()
            {
                radiance[i] += s.material.emission;
            }
            if s.bsdf.is_black() {
                continue;
            }
            let (ray, hit) = (&primary.rays[i], &primary.hits[i]);
            if let Some((movie, (u, v))) = Self::movie_at(movies, ctx, ray.dir(), hit) {
                lookups += 1;
                radiance[i] += s.bsdf.diffuse_albedo() * FRAC_1_PI * movie.lookup(u, v);
            }
            if s.bsdf.has_specular() {
                let rng = &mut primary.rngs[i];
                let choice = lights.sample(ctx, &primary.samples[i], rng);
                if let Some((shadow, c)) = direct_light(ctx, s, choice, false) {
                    shadows.push((i, shadow, c));
                }
                if let Some(q) = glossy_query(s, rng) {
                    glossy.push((i, q));
                }
            }
        }
        let rays: Vec<_> = shadows.iter().map(|s| s.1).collect();
        let mut occluded = vec![false; rays.len()];
        ctx.backend.any_hit(&rays, &mut occluded);
        for ((i, _, c), blocked) in shadows.into_iter().zip(occluded) {
            if !blocked {
                radiance[i] += c;
            }
        }
        let (targets, queries): (Vec<usize>, Vec<RadianceQuery>) = glossy.into_iter().unzip();
        for (i, r) in targets
            .into_iter()
            .zip(trace_radiance(ctx, self.settings.length, queries))
        {
            radiance[i] += r.radiance;
        }
        tile.edges
            .resolve(&primary.samples, &radiance, tile.first, out);
        lookups
    }
}

/// The side of the triangle a camera ray along `dir` that made `hit`
/// sees, where the material has a diffuse part (a movie's to shade):
/// `(triangle, back)`.
fn seen_side(ctx: &FrameContext, dir: Vec3, hit: &Hit) -> Option<(u32, bool)> {
    if !hit.is_hit() {
        return None;
    }
    let id = hit.triangle as usize;
    let material = &ctx.scene.materials[ctx.snapshot.tri_material[id] as usize];
    if material.diffuse.max_element() <= 0.0 {
        return None;
    }
    let back = ctx.snapshot.triangles[id].geometric_normal().dot(dir) > 0.0;
    Some((hit.triangle, back))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::Ray;
    use direct::ShadePoint;
    use std::mem::size_of;

    /// A coarse global pass, cheap enough for a unit test's frames.
    fn coarse_global() -> GlobalSettings {
        GlobalSettings {
            spacing: 1.0 / 8.0,
            links: 16,
            bounces: 2,
            shadow_samples: 1,
        }
    }

    /// Movies over [`coarse_global`] at `spp` camera samples a pixel and
    /// one shadow sample a texel.
    fn cheap_movies(spp: u32) -> TextureMovies {
        TextureMovies::new(MoviesSettings {
            spp,
            shadow_samples: 1,
            global: coarse_global(),
            ..MoviesSettings::default()
        })
    }

    /// The memory a frame reports holds the global pass's working buffers
    /// as well as what it keeps: on a first frame (every link traced) at
    /// least the buffers held at once while the links are drawn (a shading
    /// point and a flag a vertex, each link as a stale entry and as its
    /// ray), and those held while the radiosity is solved (a point, two
    /// flags and five irradiances a vertex), counted here from their
    /// lengths and element sizes.
    #[test]
    fn reported_memory_holds_the_global_pass_working_buffers() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 8);
        let mut movies = cheap_movies(1);
        renderer.with_frame_context(0, |ctx| movies.render_frame(ctx));
        let global = movies.global.as_ref().expect("built in the frame");
        let (vertices, links) = (global.vertex_count(), global.link_count());
        assert!(vertices > 0 && links > 0);
        let drawing = vertices * (size_of::<ShadePoint>() + size_of::<bool>())
            + links * (size_of::<(usize, u32, u32)>() + size_of::<(usize, Option<Ray>)>());
        let solving =
            vertices * (size_of::<ShadePoint>() + 2 * size_of::<bool>() + 7 * size_of::<Vec3>());
        let kept = movies.movies().map(Movie::memory_bytes).sum::<usize>() + global.memory_bytes();
        let reported = movies.last_frame_stats().cache_bytes as usize;
        assert!(
            reported >= kept + drawing.max(solving),
            "reported {reported} bytes; kept {kept}, drawing {drawing}, solving {solving}"
        );
    }

    /// A frame whose hits are past the item buffer's budget traces its
    /// camera rays again to render, and is, bit for bit, the frame that
    /// held them (cube-in-box shows its light: its edge pixels' extra
    /// samples are traced again too).
    #[test]
    fn a_frame_past_the_held_hits_traces_them_again_to_the_same_film() {
        let run = |held_hits_bytes: usize| {
            let mut renderer = crate::render::test_renderer("cube-in-box", 24);
            let mut movies = cheap_movies(2);
            movies.held_hits_bytes = held_hits_bytes;
            (0..2)
                .map(|frame| {
                    renderer.with_frame_context(frame, |ctx| {
                        let before = ctx.backend.ray_counts().closest;
                        let film = movies.render_frame(ctx);
                        (film.pixels, ctx.backend.ray_counts().closest - before)
                    })
                })
                .collect::<Vec<_>>()
        };
        let (held, traced_again) = (run(HELD_HITS_BYTES), run(0));
        let camera_samples = 24 * 24 * 2;
        for ((film, rays), (film_again, rays_again)) in held.iter().zip(&traced_again) {
            assert_eq!(film, film_again);
            assert!(
                *rays_again >= rays + camera_samples,
                "{rays} then {rays_again}"
            );
        }
    }

    /// The budget of the movies' static shadows holds at its peak in every
    /// frame: on cube-in-box at 64×64, whose movies' shadows hold about
    /// 20 MB when all are kept, under a budget of 1 MiB the most the
    /// shadows held in each frame (once found: they are let go of only
    /// before) is within it, counted from their lists' capacities by the
    /// renderer and, after the frame, movie by movie here; each movie's
    /// shadows are within the room made for them. The budget is used (at
    /// least half of it held, fewer rays than with none), and the frames
    /// are, bit for bit, those of no budget and of one past every need.
    /// Finding every movie's shadows and then dropping the largest held
    /// all 20 MB in every frame.
    #[test]
    fn the_shadow_budget_holds_while_the_shadows_are_found() {
        let run = |mib: u32| {
            let mut renderer = crate::render::test_renderer("cube-in-box", 64);
            let mut movies = TextureMovies::new(MoviesSettings {
                spp: 1,
                memory_mib: mib,
                global: coarse_global(),
                ..MoviesSettings::default()
            });
            (0..4)
                .map(|frame| {
                    renderer.with_frame_context(frame, |ctx| {
                        let before = ctx.backend.ray_counts().total();
                        let film = movies.render_frame(ctx);
                        let rays = ctx.backend.ray_counts().total() - before;
                        let samples = movies.settings.shadow_samples;
                        let mut held = 0;
                        for m in movies.movies() {
                            assert!(m.shadow_bytes() <= m.shadow_bound(ctx, samples));
                            held += m.shadow_bytes();
                        }
                        assert_eq!(held, movies.last_shadow_bytes());
                        (film, held, rays)
                    })
                })
                .collect::<Vec<_>>()
        };
        let budget = 1 << 20;
        let all = run(1 << 20);
        let within = run(1);
        let none = run(0);
        let needed = all.last().map_or(0, |f| f.1);
        assert!(needed > 10 * budget, "all the shadows hold only {needed}");
        for frame in 0..4 {
            let (film, held, rays) = &within[frame];
            assert!(*held <= budget, "frame {frame}: {held} bytes held");
            assert!(*held >= budget / 2, "frame {frame}: only {held} bytes used");
            assert_eq!(none[frame].1, 0);
            assert!(film.pixels == all[frame].0.pixels, "frame {frame}");
            assert!(film.pixels == none[frame].0.pixels, "frame {frame}");
            if frame > 0 {
                assert!(
                    *rays < none[frame].2 && all[frame].2 < *rays,
                    "frame {frame}: {rays} rays, {} with all kept, {} with none",
                    all[frame].2,
                    none[frame].2
                );
            }
        }
    }
}
