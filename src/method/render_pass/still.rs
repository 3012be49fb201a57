//! What the render pass keeps of a frame for the next one
//! ([`StillSamples`]), and the frame-level tests that decide what of it
//! stands there ([`StillPass`]): whether the view and the lights are the
//! ones the last frame was rendered under (their fingerprints), where the
//! boxes of the moving objects show on the film (`screen_rect`), and
//! whether one of them lies on a kept camera ray, shadow ray or lookup's
//! clearance ray. A tile's kept samples, and which of them stand, are
//! `render_pass::still_tile`'s; what of a light rim's coverage stands is
//! `pixels::KeptCoverage`'s to decide, and what of a path-traced part
//! `render_pass::kept_queries`'s.

use super::still_tile::{KeptShadow, KeptTile, TileKept, TileStill};
use crate::backend::{Hit, Ray};
use crate::cache::LookupPoint;
use crate::integrator::RayOffset;
use crate::method::motion::Blockers;
use crate::method::FrameContext;
use crate::sampling::mix64;
use glam::Vec3;

/// The pixel samples of a method's last frame, kept for its next one: with
/// [`PixelStreams::Coherent`](super::PixelStreams::Coherent) a sample draws
/// the same camera ray and light point in every frame, so where the camera,
/// the lights and the static geometry stay, only moving objects can change
/// what the sample's camera ray hits and whether its shadow ray is stopped.
/// A sample whose camera ray hit a static triangle (or nothing) and meets
/// no moving object's box this frame keeps its hit; if its shadow ray meets
/// no moving object's box in the last frame or this one either, it keeps
/// its direct light. A pixel on the rim of a seen light keeps what its
/// coverage rays saw
/// ([`EmitterEdges`](crate::method::pixels::EmitterEdges)) where no moving
/// box shows within a pixel of it on the film in either frame. A
/// path-traced part of a sample (the indirect light where no record is
/// usable, a glossy lobe) asked again bit for bit keeps its radiance where
/// its path met nothing moving then and no moving box meets it now, the
/// lights staying (`render_pass::kept_queries`). A pixel all of whose
/// samples keep their hits and shadows, on materials that neither emit nor
/// have a glossy lobe, is kept whole where no moving box lies on its
/// lookups' clearance rays in either frame (`Standing`): it keeps its cache
/// lookups, and its samples' first hits are not shaded again; only the
/// interpolation, whose records change from frame to frame, is done again.
/// The rest is traced again. So the film equals, bit for bit, the one
/// traced afresh, and a resumed job (which starts with none kept) equals an
/// uninterrupted one.
///
/// This is the design's "static parts are never recomputed for motion
/// they cannot see" applied to the render pass, as `movies` does for its
/// texels' shadows (Martín et al. §5) and the TRC paper's GPU renderer gets
/// for little cost by rasterizing. Per-frame computation (`ic`) keeps
/// nothing: it is the baseline the temporal methods are measured against.
pub struct StillSamples {
    last: Option<KeptFrame>,
    /// Bytes a frame may keep ([`Self::BUDGET_BYTES`]).
    budget: usize,
    /// Samples of the last render pass whose hit was taken from the frame
    /// before (their direct light too where no moving box met it).
    pub taken: u64,
    /// Cache lookups the last render pass took from the frame before (of
    /// pixels kept whole, `Standing`).
    pub lookups_taken: u64,
    /// Path-traced parts of samples (fallbacks, glossy lobes) the last
    /// render pass took from the frame before (`KeptQueries`).
    pub queries_taken: u64,
}

impl StillSamples {
    /// Bytes kept per frame at most, counted for the base samples (a light
    /// rim's extra samples, a small share, take room beside them): about
    /// 4.5 million samples, 512 × 512 pixels at 16 spp. A larger frame
    /// keeps its first tiles that fit and traces the others' samples every
    /// frame, as `ic` does.
    pub const BUDGET_BYTES: usize = 512 << 20;

    /// Kept samples within `budget` bytes a frame, not
    /// [`Self::BUDGET_BYTES`] (tests of what a full budget drops).
    #[cfg(test)]
    fn within(budget: usize) -> Self {
        StillSamples {
            budget,
            ..StillSamples::default()
        }
    }

    /// This frame's pass over the samples kept from the last one (`None`
    /// where not even one tile's samples fit the budget: nothing is
    /// kept).
    pub(super) fn begin(
        &mut self,
        ctx: &FrameContext,
        spp: u32,
        pixels_per_tile: usize,
    ) -> Option<StillPass> {
        let last = self.last.take();
        StillPass::new(ctx, last, (spp, pixels_per_tile), self.budget)
    }

    /// Keeps the tiles `pass` traced for the next frame.
    pub(super) fn end(&mut self, pass: Option<StillPass>, tiles: Vec<TileKept>) {
        self.taken = tiles.iter().map(|t| t.taken).sum();
        self.lookups_taken = tiles.iter().map(|t| t.lookups_taken).sum();
        self.queries_taken = tiles.iter().map(|t| t.queries_taken).sum();
        self.last = pass.map(|pass| pass.finish(tiles.into_iter().map(|t| t.tile).collect()));
    }

    /// Bytes the kept samples take.
    pub fn memory_bytes(&self) -> usize {
        self.last.as_ref().map_or(0, |f| {
            f.tiles.iter().map(KeptTile::memory_bytes).sum::<usize>()
                + f.screen.len() * std::mem::size_of::<ScreenRect>()
        })
    }
}

impl Default for StillSamples {
    fn default() -> Self {
        StillSamples {
            last: None,
            budget: Self::BUDGET_BYTES,
            taken: 0,
            lookups_taken: 0,
            queries_taken: 0,
        }
    }
}

/// One frame's kept samples, tile by tile, and what they were traced under.
struct KeptFrame {
    frame: u32,
    view: u64,
    lights: u64,
    /// Where the moving boxes showed on the film.
    screen: Vec<ScreenRect>,
    tiles: Vec<KeptTile>,
}

/// The part of the film, in pixels (`x0, y0, x1, y1`), where a box may
/// show: the bounds of its corners' projections, or the whole plane where
/// a corner lies behind the camera.
type ScreenRect = [f32; 4];

/// One render pass's view of the kept samples: this frame's moving boxes,
/// and the last frame's samples where they may be taken.
pub(super) struct StillPass {
    frame: u32,
    view: u64,
    lights: u64,
    pub(super) blockers: Blockers,
    /// Where this frame's moving boxes show on the film, `width` pixels
    /// wide.
    screen: Vec<ScreenRect>,
    width: u32,
    /// The last frame, when it was the one before with the same view.
    last: Option<KeptFrame>,
    /// Whether the lights are where they were (else no shadow is kept).
    pub(super) lights_still: bool,
    /// A distance from the camera past every moving box: a camera ray that
    /// hit nothing is tested as a segment that long.
    far: f32,
    /// How rays leave surfaces this frame ([`measure_clearance`](crate::method::lookups::measure_clearance)'s).
    offset: RayOffset,
    /// Bytes each tile's kept lookups and queries
    /// ([`KeptQueries`](super::kept_queries::KeptQueries)) may take, the
    /// lookups first.
    pub(super) tile_budget: usize,
    /// How many tiles, from the first, keep their samples for the next
    /// frame (and take the last frame's).
    kept_tiles: usize,
}

impl StillPass {
    /// The pass over a frame's samples (`spp` a pixel, in tiles of
    /// `pixels_per_tile`), keeping the first tiles whose samples fit in
    /// `budget` bytes (all of them in a frame small enough); `None` where
    /// not even one tile's fit.
    fn new(
        ctx: &FrameContext,
        last: Option<KeptFrame>,
        (spp, pixels_per_tile): (u32, usize),
        budget: usize,
    ) -> Option<Self> {
        let pixels = ctx.width as usize * ctx.height as usize;
        let tiles = pixels.div_ceil(pixels_per_tile.max(1)).max(1);
        let bytes = |pixels: usize| {
            pixels
                .saturating_mul(spp as usize)
                .saturating_mul(KeptTile::SAMPLE_BYTES)
        };
        // A frame too large for the budget keeps as many whole tiles as
        // fit, the same ones every frame, rather than none: a large frame
        // still takes a share of its samples from the last one.
        let (kept_tiles, samples_bytes) = if bytes(pixels) <= budget {
            (tiles, bytes(pixels))
        } else {
            let kept = budget / bytes(pixels_per_tile).max(1);
            (kept, kept * bytes(pixels_per_tile))
        };
        if kept_tiles == 0 {
            return None;
        }
        // What the samples leave of the budget, shared by the kept tiles'
        // lookups and queries.
        let tile_budget = (budget - samples_bytes) / kept_tiles;
        let view = view_fingerprint(ctx, spp, pixels_per_tile);
        let lights = lights_fingerprint(ctx);
        let last = last.filter(|l| l.frame.checked_add(1) == Some(ctx.frame) && l.view == view);
        let blockers = Blockers::new(ctx);
        let camera = ctx.snapshot.camera.position;
        let far = blockers
            .boxes
            .iter()
            .map(|&(lo, hi)| (lo - camera).abs().max((hi - camera).abs()).length())
            .fold(0.0f32, f32::max)
            * 2.0
            + 1.0;
        let screen = blockers
            .boxes
            .iter()
            .map(|&b| screen_rect(ctx, b))
            .collect();
        Some(StillPass {
            frame: ctx.frame,
            view,
            lights,
            lights_still: last.as_ref().is_some_and(|l| l.lights == lights),
            blockers,
            screen,
            width: ctx.width,
            last,
            far,
            offset: ctx.ray_offset,
            tile_budget,
            kept_tiles,
        })
    }

    /// The last frame's `n` tiles, moved out of the pass (empty where none
    /// was kept; `None` past the tiles the budget keeps), for
    /// [`Self::tile`].
    pub(super) fn take_tiles(&mut self, n: usize) -> Vec<Option<KeptTile>> {
        let mut tiles = self
            .last
            .as_mut()
            .map_or_else(Vec::new, |l| std::mem::take(&mut l.tiles));
        tiles.resize_with(n, KeptTile::default);
        let keep = self.kept_tiles;
        let tiles = tiles.into_iter().enumerate();
        tiles.map(|(i, t)| (i < keep).then_some(t)).collect()
    }

    /// One tile's part of the pass, with its samples in the last frame.
    pub(super) fn tile(&self, kept: KeptTile) -> TileStill<'_> {
        TileStill::new(self, kept)
    }

    fn finish(self, tiles: Vec<KeptTile>) -> KeptFrame {
        KeptFrame {
            frame: self.frame,
            view: self.view,
            lights: self.lights,
            screen: self.screen,
            tiles,
        }
    }

    /// Whether no camera ray through `pixel` can have met a moving object
    /// in the last frame or this one: no moving box's film rect, in either
    /// frame, comes within a pixel of its square. Then every ray through
    /// it, whatever its position in the pixel, sees what it saw (lights
    /// and view staying).
    pub(super) fn pixel_clear(&self, pixel: u32) -> bool {
        let Some(last) = self.last.as_ref().filter(|_| self.lights_still) else {
            return false;
        };
        self.film_clear(pixel) && film_clear(&last.screen, self.width, pixel)
    }

    /// Whether the lights moved since the last frame (not when there is
    /// none to compare with).
    pub(super) fn lights_moved(&self) -> bool {
        self.last.is_some() && !self.lights_still
    }

    /// Whether a camera ray's hit stands this frame: it hit a static
    /// triangle or nothing, and no moving box lies on its way there (none
    /// shows near its pixel on the film, `film_clear`, or its segment
    /// misses every box).
    pub(super) fn hit_stands(&self, ray: &Ray, hit: &Hit, film_clear: bool) -> bool {
        if hit.is_hit() && self.blockers.is_moving_triangle(hit.triangle) {
            return false;
        }
        if film_clear {
            return true;
        }
        let t = if hit.is_hit() {
            hit.t
        } else {
            self.far / ray.dir().length()
        };
        !self.blockers.segment_may_hit(ray.origin(), ray.at(t))
    }

    /// Whether a shadow ray's outcome stands this frame: the lights stayed
    /// and no moving box lay on it in the last frame (`clear`: so what
    /// stopped it, if anything, was static) nor lies on it now.
    pub(super) fn shadow_stands(&self, shadow: &KeptShadow) -> bool {
        self.lights_still && shadow.clear && self.shadow_clear(&shadow.ray)
    }

    /// Whether no moving box of this frame lies on shadow ray `ray`.
    pub(super) fn shadow_clear(&self, ray: &Ray) -> bool {
        !self
            .blockers
            .segment_may_hit(ray.origin(), ray.origin() + ray.dir())
    }

    /// Whether no moving box of this frame shows within a pixel of
    /// `pixel` on the film.
    pub(super) fn film_clear(&self, pixel: u32) -> bool {
        film_clear(&self.screen, self.width, pixel)
    }

    /// Whether no moving box of this frame lies on lookup `at`'s clearance
    /// ray ([`measure_clearance`](crate::method::lookups::measure_clearance)'s, to its hit or, where it hit nothing,
    /// past every box) nor holds its hit: then what it hit, if anything,
    /// was static.
    pub(super) fn clearance_clear(&self, at: &LookupPoint, camera: Vec3) -> bool {
        let origin = self.offset.origin(at.position, at.normal, at.normal);
        let length = if at.clearance == LookupPoint::OPEN {
            self.far + (at.position - camera).length()
        } else {
            at.clearance
        };
        let end = origin + at.normal * length;
        // A hit on a moving object lies in its box, but the segment may stop
        // a rounding error short of the box's face: the end is tested with
        // a margin, a ray offset's.
        let margin = Vec3::splat(self.offset.distance(end));
        !self.blockers.segment_may_hit(origin, end)
            && !self.blockers.box_may_hit((end - margin, end + margin))
    }
}

/// Whether none of `rects` comes within a pixel of `pixel`'s square on a
/// film `width` pixels wide.
fn film_clear(rects: &[ScreenRect], width: u32, pixel: u32) -> bool {
    let (x, y) = ((pixel % width) as f32, (pixel / width) as f32);
    let square = [x - 1.0, y - 1.0, x + 2.0, y + 2.0];
    !rects
        .iter()
        .any(|r| r[0] <= square[2] && square[0] <= r[2] && r[1] <= square[3] && square[1] <= r[3])
}

/// Where box `(lo, hi)` may show on the film, in pixels ([`ScreenRect`]).
fn screen_rect(ctx: &FrameContext, (lo, hi): (Vec3, Vec3)) -> ScreenRect {
    const WHOLE_PLANE: ScreenRect = [
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::INFINITY,
    ];
    let (w, h) = (ctx.width as f32, ctx.height as f32);
    let mut rect = [
        f32::INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
    ];
    for k in 0..8 {
        let corner = Vec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let Some((sx, sy)) = ctx.snapshot.camera.project(corner, ctx.aspect()) else {
            return WHOLE_PLANE;
        };
        let (x, y) = (sx * w, sy * h);
        rect = [
            rect[0].min(x),
            rect[1].min(y),
            rect[2].max(x),
            rect[3].max(y),
        ];
    }
    rect
}

/// What places a frame's pixel samples: the camera, the film, the samples
/// and tiles, and which triangles are static. Two frames with the same
/// one draw the same camera rays under coherent streams.
fn view_fingerprint(ctx: &FrameContext, spp: u32, pixels_per_tile: usize) -> u64 {
    let camera = &ctx.snapshot.camera;
    let floats = camera
        .position
        .to_array()
        .into_iter()
        .chain(camera.basis.to_cols_array())
        .chain([camera.yfov]);
    let counts = [
        u64::from(ctx.width),
        u64::from(ctx.height),
        u64::from(spp),
        pixels_per_tile as u64,
        u64::from(ctx.edge_coverage_factor),
        ctx.snapshot.static_count as u64,
        ctx.snapshot.triangles.len() as u64,
        ctx.seed,
    ];
    fingerprint(floats, counts)
}

/// Where the lights are and what they send: two frames with the same one
/// give every shading point the same light samples.
pub(crate) fn lights_fingerprint(ctx: &FrameContext) -> u64 {
    let snapshot = ctx.snapshot;
    let triangles = ctx
        .lights
        .emitting_triangles()
        .flat_map(|id| snapshot.triangles[id].p)
        .flat_map(|p| p.to_array());
    let points = snapshot.lights.iter().flat_map(|l| {
        [l.position, l.direction, l.intensity]
            .into_iter()
            .flat_map(|v| v.to_array())
    });
    let ids = ctx.lights.emitting_triangles().map(|id| id as u64);
    fingerprint(
        triangles.chain(points),
        ids.chain([ctx.lights.pick_fingerprint(), snapshot.lights.len() as u64]),
    )
}

/// A hash of some floats (by their bits) and integers.
fn fingerprint(floats: impl Iterator<Item = f32>, ints: impl IntoIterator<Item = u64>) -> u64 {
    let h = floats.fold(0x5eed, |h, f| mix64(h ^ u64::from(f.to_bits())));
    ints.into_iter().fold(h, |h, i| mix64(h.rotate_left(7) ^ i))
}

#[cfg(test)]
mod tests {
    use super::super::{render_pass, PixelStreams};
    use super::*;
    use crate::cache::gather::Strata;
    use crate::method::ic::{IcSettings, IrradianceCaching};
    use crate::method::lookups::measure_clearance;
    use crate::method::FrameStats;
    use crate::sampling::Rng;

    /// One frame rendered with kept samples and afresh.
    #[derive(Clone, Copy, Debug, PartialEq)]
    struct KeptCheck {
        /// Whether the two films are the same bit for bit.
        same: bool,
        /// Samples, lookups and path-traced queries taken from the last
        /// frame.
        taken: u64,
        lookups_taken: u64,
        queries_taken: u64,
        /// Rays each traced.
        kept_rays: u64,
        fresh_rays: u64,
    }

    /// Renders `frames` in turn with one kept [`StillSamples`] under an
    /// `ic` cache of each frame, and again each afresh (nothing kept), with
    /// coherent streams.
    fn kept_against_fresh(scene: &str, frames: &[u32], mut still: StillSamples) -> Vec<KeptCheck> {
        let mut renderer = crate::render::test_renderer(scene, 20);
        let ic = IrradianceCaching::new(IcSettings {
            spp: 4,
            strata: Strata { theta: 4, phi: 12 },
            ..IcSettings::default()
        });
        frames
            .iter()
            .map(|&frame| {
                renderer.with_frame_context(frame, |ctx| {
                    let cache = ic.build_cache(ctx);
                    let render = |still: Option<&mut StillSamples>| {
                        let before = ctx.backend.ray_counts().total();
                        let film = render_pass(
                            ctx,
                            &cache,
                            &ic.settings,
                            PixelStreams::Coherent,
                            None,
                            still,
                            &mut FrameStats::default(),
                        );
                        (film, ctx.backend.ray_counts().total() - before)
                    };
                    let (kept, kept_rays) = render(Some(&mut still));
                    let (fresh, fresh_rays) = render(None);
                    let same = kept.pixels.iter().zip(&fresh.pixels).all(|(a, b)| {
                        a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
                    });
                    KeptCheck {
                        same,
                        taken: still.taken,
                        lookups_taken: still.lookups_taken,
                        queries_taken: still.queries_taken,
                        kept_rays,
                        fresh_rays,
                    }
                })
            })
            .collect()
    }

    /// What a frame rendered with nothing to take from gives.
    fn took_nothing(check: KeptCheck) -> bool {
        check.same
            && check.taken == 0
            && check.lookups_taken == 0
            && check.queries_taken == 0
            && check.kept_rays == check.fresh_rays
    }

    /// A frame whose samples are taken from the last one where nothing
    /// moving met them equals, bit for bit, the frame traced afresh: on
    /// `cube-in-box` (a cube moves; the camera and light stay) most samples
    /// are taken and fewer rays traced, the path-traced indirect light of
    /// samples no record covers and the cache lookups of pixels kept whole
    /// too; where the moving cube's box lies on their rays some are not; a
    /// frame that does not follow the last one takes none.
    #[test]
    fn kept_samples_give_the_frame_traced_afresh() {
        let frames = kept_against_fresh("cube-in-box", &[3, 4, 5, 9], StillSamples::default());
        let samples = 20 * 20 * 4;
        assert!(took_nothing(frames[0]), "{:?}", frames[0]);
        for check in &frames[1..3] {
            assert!(check.same, "{check:?}");
            assert!(
                check.taken > samples / 2 && check.taken < samples,
                "{check:?} of {samples} samples"
            );
            assert!(check.lookups_taken > 0, "{check:?}");
            assert!(check.queries_taken > 0, "{check:?}");
            assert!(check.kept_rays < check.fresh_rays / 2, "{check:?}");
        }
        assert!(took_nothing(frames[3]), "{:?}", frames[3]);
    }

    /// A budget that holds a frame's samples and nothing more keeps their
    /// hits and shadows but no lookups and no path-traced parts, so no
    /// pixel is kept whole (with the whole budget these frames take both:
    /// the test above). A budget one byte short of the samples keeps the
    /// tiles that fit whole, not the last one, so the next frame takes
    /// fewer samples; one short of a tile's samples keeps nothing. The
    /// frames are those traced afresh either way.
    #[test]
    fn kept_samples_past_their_budget_are_traced_again() {
        // On two threads the 20×20 frame is four tiles of 100 pixels.
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let samples = 20 * 20 * 4 * KeptTile::SAMPLE_BYTES;
        let whole = StillSamples::within(samples);
        let frames = two.install(|| kept_against_fresh("cube-in-box", &[3, 4], whole));
        let all = frames[1];
        assert!(all.same && all.taken > 0, "{all:?}");
        assert_eq!((all.lookups_taken, all.queries_taken), (0, 0), "{all:?}");
        assert!(all.kept_rays < all.fresh_rays, "{all:?}");

        let short = StillSamples::within(samples - 1);
        let frames = two.install(|| kept_against_fresh("cube-in-box", &[3, 4], short));
        assert!(took_nothing(frames[0]), "{:?}", frames[0]);
        let part = frames[1];
        assert!(part.same, "{part:?}");
        assert!(0 < part.taken && part.taken < all.taken, "{part:?} {all:?}");
        assert!(part.kept_rays > all.kept_rays, "{part:?} {all:?}");

        let tile = StillSamples::within(100 * 4 * KeptTile::SAMPLE_BYTES - 1);
        for check in two.install(|| kept_against_fresh("cube-in-box", &[3, 4], tile)) {
            assert!(took_nothing(check), "{check:?}");
        }
    }

    /// On `glossy-cornell` (glossy walls and blocks, a block moving) the
    /// glossy lobes of the still samples are taken too, and the frame is
    /// the one traced afresh.
    #[test]
    fn kept_glossy_lobes_give_the_frame_traced_afresh() {
        let frames = kept_against_fresh("glossy-cornell", &[6, 7], StillSamples::default());
        assert!(took_nothing(frames[0]), "{:?}", frames[0]);
        let check = frames[1];
        assert!(check.same, "{check:?}");
        assert!(check.queries_taken > 100, "{check:?}");
        assert!(check.kept_rays < check.fresh_rays / 2, "{check:?}");
    }

    /// A lookup whose clearance ray hits the moving cube is not kept, though
    /// the ray ends on the cube's face (where a segment test alone may stop
    /// a rounding error short of its box); one whose ray passes beside the
    /// cube is.
    #[test]
    fn a_clearance_ray_that_hits_a_moving_object_is_not_clear() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 16);
        // Frame 0: the cube is not turned, so its faces are its box's.
        renderer.with_frame_context(0, |ctx| {
            let pass = StillPass::new(ctx, None, (1, 16), StillSamples::BUDGET_BYTES)
                .expect("a small frame fits");
            let (lo, hi) = pass.blockers.boxes[0];
            let camera = ctx.snapshot.camera.position;
            // Back-wall points behind the cube and beside it, found by rays
            // from just behind the cube's box.
            let wall_behind = |x: f32, y: f32| {
                let ray = Ray::new(
                    Vec3::new(x, y, lo.z - 1e-3),
                    Vec3::NEG_Z,
                    0.0,
                    f32::INFINITY,
                );
                let mut hit = [Hit::MISS];
                ctx.backend.closest_hit(&[ray], &mut hit);
                assert!(hit[0].is_hit(), "a wall behind ({x}, {y})");
                ray.at(hit[0].t)
            };
            let mid = (lo + hi) * 0.5;
            let beside = mid.x + (hi.x - lo.x) * 1.5;
            let points = [
                (wall_behind(mid.x, mid.y), Vec3::Z),
                (wall_behind(beside, mid.y), Vec3::Z),
            ];
            let lookups = measure_clearance(ctx, &points);
            let (behind, open) = (lookups[0], lookups[1]);
            assert!(
                (behind.clearance - (lo.z - behind.position.z)).abs() < 1e-2,
                "the ray behind the cube hits its back: {behind:?}, box {lo}..{hi}"
            );
            assert!(open.clearance > hi.z - open.position.z, "{open:?}");
            assert!(!pass.clearance_clear(&behind, camera));
            assert!(pass.clearance_clear(&open, camera));
        });
    }

    /// A box's film rect holds every film point whose camera ray meets the
    /// box, by brute force: rays through random points of the film (and a
    /// pixel's margin around it) tested against random boxes in front of
    /// the camera by the slab test; many meet one, and none of those lies
    /// outside its rect. A box around the camera covers the plane.
    #[test]
    fn a_box_shows_only_inside_its_film_rect() {
        let size = 32;
        let mut renderer = crate::render::test_renderer("cube-in-box", size);
        renderer.with_frame_context(0, |ctx| {
            let camera = &ctx.snapshot.camera;
            let mut rng = Rng::from_seed(3, 0);
            let forward = -camera.basis.z_axis;
            let mut met = 0;
            for _ in 0..200 {
                let mut v = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let centre = camera.position + forward * (1.0 + 5.0 * v().x) + (v() - 0.5) * 3.0;
                let half = v() * 0.5;
                let (lo, hi) = (centre - half, centre + half);
                let rect = screen_rect(ctx, (lo, hi));
                for _ in 0..200 {
                    let film = v() * (size as f32 + 2.0) - Vec3::ONE;
                    let (sx, sy) = (film.x / size as f32, film.y / size as f32);
                    let dir = camera.direction(sx, sy, ctx.aspect());
                    let far = camera.position + dir * 100.0;
                    if crate::method::motion::segment_hits_box(camera.position, far, (lo, hi)) {
                        met += 1;
                        let inside = rect[0] <= film.x + 1e-3
                            && film.x <= rect[2] + 1e-3
                            && rect[1] <= film.y + 1e-3
                            && film.y <= rect[3] + 1e-3;
                        assert!(inside, "film point {film} meets the box outside {rect:?}");
                    }
                }
            }
            assert!(met > 1000, "only {met} rays met a box");
            let around = (camera.position - Vec3::ONE, camera.position + Vec3::ONE);
            assert_eq!(screen_rect(ctx, around)[0], f32::NEG_INFINITY);
        });
    }

    /// Under a moving light every sample keeps its hit but traces its
    /// shadow ray and its path-traced parts again, and the frames still
    /// equal those traced afresh.
    #[test]
    fn kept_samples_under_a_moving_light_trace_their_shadows_again() {
        let frames = kept_against_fresh("moving-light", &[3, 4], StillSamples::default());
        let check = frames[1];
        assert!(check.same && frames[0].same);
        assert!(check.taken > 0);
        // Their paths' light moved too, and no pixel is kept whole.
        assert_eq!(check.queries_taken, 0);
        assert_eq!(check.lookups_taken, 0);
        let KeptCheck {
            taken,
            kept_rays,
            fresh_rays,
            ..
        } = check;
        assert!(
            kept_rays < fresh_rays,
            "{kept_rays} rays against {fresh_rays}"
        );
        let shadows = fresh_rays - kept_rays;
        assert!(
            shadows <= taken,
            "{shadows} rays saved by {taken} samples taken"
        );
    }
}
