//! `tcg`: temporally coherent final gathering (Tawara, Myszkowski &
//! Seidel, "Exploiting Temporal Coherence in Final Gathering for Dynamic
//! Scenes", CGI 2004 — `papers/temporally-coherent-final-gathering-2004.md`),
//! built on the irradiance records of [`super::ic`].
//!
//! Every record keeps its incoming-radiance samples, one per hemisphere
//! cell, in the paper's 8-byte form (§3.1: RGBE radiance, half-float hit
//! distance, and a flag word with the sample's age and whether it hit a
//! moving object; [`PackedSample`]). Records live from frame to frame, and
//! each frame only a share of their samples is shot again. Per frame:
//! 1. *survivors*: records move with the object they lie on (§4.1: object
//!    id and local frame; the cells turn with it). A record no pixel used
//!    in the previous frame is dropped. Departure: the paper keeps every
//!    record and updates it; dropping the unseen ones (`trc`'s rule, TRC
//!    §5) keeps the work on what the camera sees, and a record covered by
//!    a moving object is not refreshed for nothing. So is one that moving
//!    objects came into the view of, none of its samples having hit them
//!    or they having come nearer (departure, `arrived`: the paper's Eq. 2
//!    would let them in at `τ_min`; `fill` makes a record there again
//!    where a pixel needs one). Then redundant records are removed
//!    (§4.2): in id order, one with more than
//!    [`TcgSettings::max_neighbours`] other records usable at its point
//!    is removed, and hidden from the counts of the records after it;
//! 2. *update* (§3.2–3.3): each record shoots again `N_update` cells
//!    (Eq. 2, `select::cells_to_update`; departure: its `x` also counts
//!    the samples whose light moving lights changed, `stale`, and, with
//!    `occlusion_refresh` on, those whose path an object moved into,
//!    `crossed`, and the cells beside those across an edge,
//!    `select::with_neighbours`), drawn
//!    without repetition with
//!    probability ∝ `2^age` (`select::pick_cells`), each with a new
//!    jittered direction in its cell; its other samples age by a frame.
//!    Its irradiance, gradients and harmonic mean distance are computed
//!    again from all its samples with `ic`'s estimators;
//! 3. *fill*: `ic`'s fill stage adds records where none is usable;
//! 4. *render*: `ic`'s render pass, flagging every record a pixel sample
//!    used.
//!
//! A record's irradiance in the frame it is made is `ic`'s, from its
//! samples at full precision; from the next frame on it is computed from
//! the stored 8-byte samples, as the paper's records are.
//!
//! With `--ic-glossy eas`, glossy surfaces get radiance records (`ic`'s,
//! [`crate::cache::eas`]): each frame builds a record's sources again from
//! its samples, as it computes its irradiance again, so they follow the
//! samples the frame shot. The stored samples keep no direction: the
//! sources take each at its cell's centre (`radiance_sources`).
//!
//! # Measured
//! `radcache bench --scenes cube-in-box --size 64x64 --frames 0..400
//! --reference-spp 256 --methods ic trc tcg` (at 34c0a70): 3.07× faster
//! than `ic`, the same relative RMSE, 0.56× its flicker; on the 66 moving
//! balls of `spheres` (48 frames) 1.48× where `trc` is 0.98×. Under a
//! moving light, as the paper has it (`light_refresh` off), its block bias
//! was 1.9× `ic`'s: lighting that changes with no moving object in a
//! record's view reaches the record only as Eq. 2's `τ_min` share of its
//! samples is shot again each frame; `stale` shoots again the samples
//! whose light changed (`benches/RESULTS.md`, "`tcg` against `ic` and
//! `trc`").

mod arrived;
mod crossed;
mod select;
mod stale;
mod state;

pub use state::{
    downgrade_to_schema_6_record, is_radiance_record, upgrade_schema_6_record,
    with_samples_as_schema_9,
};

use super::arrivals::{moving_bounds, OwnBounds};
use super::carried;
use super::ic::{
    primary_candidates, scene_bounds, Candidate, Gathered, IcSettings, IrradianceCaching,
};
use super::render_pass::{render_pass, PixelStreams, StillSamples};
use super::{
    FrameContext, FrameRecords, FrameStats, Method, MethodState, StateChanges, StateError,
    RENDER_PHASE,
};
use crate::cache::eas::{self, Eas};
use crate::cache::gather::{
    cell_direction, cell_query, irradiance_and_gradients_in, GatherPoint, HemisphereSamples, Strata,
};
use crate::cache::{IrradianceCache, IrradianceRecord, LookupPoint, RecordId};
use crate::film::Film;
use crate::integrator::{trace_radiance_parallel, RadianceQuery};
use crate::material::Bsdf;
use crate::sampling::{streams, Frame, Rng, SampleKey};
use crate::store::rgbe::PackedSample;
use crate::store::samples::{pack_samples, SampleBlock};
use glam::{Mat3, Mat4, Vec3};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Settings of `tcg`, with their sources.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TcgSettings {
    /// Everything spatial: accuracy `a`, strata (the paper uses 192 and
    /// 768 samples a record, §5), spp, spacing, gradients, path lengths
    /// (see [`IcSettings`]).
    pub ic: IcSettings,
    /// `τ_min` of Eq. 2: the share of a record's samples shot again every
    /// frame. The paper's results use 0.05 (§5, Table 3).
    pub tau_min: f32,
    /// `τ_max` of Eq. 2: the share shot again of the samples that hit
    /// moving objects. The paper's results use 1.0 (§5).
    pub tau_max: f32,
    /// §4.2: a record with more usable neighbours than this is removed.
    /// The paper's example is 10.
    pub max_neighbours: u32,
    /// Whether the samples whose light moving lights changed since they
    /// were shot count in Eq. 2's `x` as those that hit moving objects do
    /// (departure, on by default: the module `stale`); off, `tcg` is the paper's.
    #[serde(default = "light_refresh_default")]
    pub light_refresh: bool,
    /// Whether the samples whose path an object moved into count in Eq.
    /// 2's `x` as those that hit moving objects do, and records a moved
    /// object buried are dropped (departure, off by default: the module
    /// `crossed`, which says what it costs); off, as the paper has it.
    #[serde(default = "occlusion_refresh_default")]
    pub occlusion_refresh: bool,
    /// Whether a record is dropped where moving objects that come into its
    /// view (none of its samples hit them, or they came nearer) newly
    /// cross more than 5 % (`arrived::ARRIVAL_SHARE`) of its samples'
    /// paths in one frame (departure, on by default: the module
    /// `arrived`); off, as the paper has it.
    #[serde(default = "arrivals_default")]
    pub arrivals: bool,
}

/// [`TcgSettings::light_refresh`] for settings stored before it existed:
/// off, the paper's rule, which such a job ran; so it resumes with the
/// frames it would have made (given `--tcg-light-refresh off`), and is
/// refused with the rule on.
fn light_refresh_default() -> bool {
    false
}

/// [`TcgSettings::occlusion_refresh`] for settings stored before it
/// existed: off, for the reason of [`light_refresh_default`].
fn occlusion_refresh_default() -> bool {
    false
}

/// [`TcgSettings::arrivals`] for settings stored before it existed: off,
/// for the reason of [`light_refresh_default`].
fn arrivals_default() -> bool {
    false
}

impl Default for TcgSettings {
    fn default() -> Self {
        TcgSettings {
            ic: IcSettings::default(),
            tau_min: 0.05,
            tau_max: 1.0,
            max_neighbours: 10,
            light_refresh: true,
            occlusion_refresh: false,
            arrivals: true,
        }
    }
}

/// `alive` without the records `marked`, whose ids are added to
/// `removed`.
fn without_marked(
    alive: Vec<(TcgRecord, (GatherPoint, Frame))>,
    marked: Vec<bool>,
    removed: &mut Vec<RecordId>,
) -> Vec<(TcgRecord, (GatherPoint, Frame))> {
    let mut kept = Vec::with_capacity(alive.len());
    for (r, is_marked) in alive.into_iter().zip(marked) {
        if is_marked {
            removed.push(r.0.record.id);
        } else {
            kept.push(r);
        }
    }
    kept
}

/// A record with its samples (§3.1).
#[derive(Clone, Debug)]
pub struct TcgRecord {
    /// The record as of the last frame (id, point, normal, irradiance,
    /// gradients, radius as clamped in that frame's cache).
    pub record: IrradianceRecord,
    /// Where it was made: its point then, and its random streams.
    pub(crate) candidate: Candidate,
    /// Its object's transform in the frame it was made: since then the
    /// record moves as its object does (§4.1).
    pub object_to_world: Mat4,
    /// One sample a cell, in cell order (`j·N + k`).
    pub samples: Vec<PackedSample>,
    /// Whether a pixel sample used it in the last rendered frame.
    pub used: bool,
}

impl TcgRecord {
    /// Bytes it holds apart from its sources (which the frame's cache
    /// counts): itself and its samples.
    fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + std::mem::size_of_val(&self.samples[..])
    }

    /// A record just gathered in the frame of `ctx`.
    fn gathered(ctx: &FrameContext, g: &Gathered, dynamic: &[bool]) -> Self {
        TcgRecord {
            record: g.record.clone(),
            candidate: g.candidate,
            object_to_world: object_transform(&ctx.snapshot.object_to_world, g.candidate.object),
            samples: pack_samples(&g.samples, dynamic),
            used: false,
        }
    }

    /// Its point and the frame its cells are laid out in, in a frame whose
    /// objects' world transforms are `objects` (§4.1): its creation point
    /// and cells moved with its object since.
    fn pose(&self, objects: &[Mat4]) -> (GatherPoint, Frame) {
        let point = self.candidate.point;
        let frame = Frame::new(point.normal);
        let now = object_transform(objects, self.candidate.object);
        // Exactly where it was made first: `now · then⁻¹` of a still
        // object far from the origin misses the identity by rounding.
        if now == self.object_to_world {
            return (point, frame);
        }
        let motion = now * self.object_to_world.inverse();
        if motion.abs_diff_eq(Mat4::IDENTITY, 1e-7) {
            return (point, frame);
        }
        // Normals by the inverse transpose (right under any scale); the
        // tangent turned with the object and made orthogonal again.
        let normals = Mat3::from_mat4(motion).inverse().transpose();
        let n = (normals * point.normal).normalize_or_zero();
        let tangent = motion.transform_vector3(frame.t);
        let t = (tangent - n * n.dot(tangent)).normalize_or_zero();
        let moved = GatherPoint {
            position: motion.transform_point3(point.position),
            normal: n,
            geometric_normal: (normals * point.geometric_normal).normalize_or_zero(),
        };
        (
            moved,
            Frame {
                t,
                b: n.cross(t),
                n,
            },
        )
    }
}

/// `object`'s world transform among `objects` (the identity for an
/// object not there, which a damaged state could name).
fn object_transform(objects: &[Mat4], object: u32) -> Mat4 {
    objects
        .get(object as usize)
        .copied()
        .unwrap_or(Mat4::IDENTITY)
}

/// A radiance record's sources ([`eas::build`]) from its stored samples,
/// laid out in `frame`. The 8-byte samples keep no direction: each is taken
/// at its cell's centre (departure; the sources' centroids move by at most
/// half a cell, and a record whose samples are re-shot every frame would
/// otherwise need its jittered directions stored too).
fn radiance_sources(
    radiance: Vec<Vec3>,
    distance: Vec<f32>,
    frame: &Frame,
    strata: Strata,
    bsdf: &Bsdf,
    tau: f32,
) -> Arc<[Eas]> {
    let centre = glam::Vec2::splat(0.5);
    let direction = (0..strata.count() as u32)
        .map(|cell| cell_direction(frame, strata, cell, centre))
        .collect();
    let samples = HemisphereSamples {
        object: vec![u32::MAX; radiance.len()],
        direction,
        radiance,
        distance,
    };
    eas::build(&samples, frame.n, strata, bsdf, tau).into()
}

/// §4.2: which of `records` (in id order, at their points of this frame,
/// radii of the last) are redundant: more than `max_neighbours` of the
/// records not removed before it are usable at its point (`w ≥ 1/a`).
/// Marking in order and hiding the marked from the later counts, as the
/// paper does, thins a crowd down to records with `max_neighbours`
/// neighbours each rather than removing it whole.
fn redundant(
    records: &[&IrradianceRecord],
    accuracy: f32,
    max_neighbours: u32,
    (min, max): (Vec3, Vec3),
) -> Vec<bool> {
    let mut cache = IrradianceCache::new(min, max, accuracy);
    for &r in records {
        cache.insert_as_is(r.clone());
    }
    let mut hidden = vec![false; records.len()];
    for (i, r) in records.iter().enumerate() {
        let at = LookupPoint::open(r.position, r.normal);
        let mut neighbours = 0u32;
        cache.for_each_usable_indexed(&at, |j, _, _| {
            if j != i && !hidden[j] {
                neighbours += 1;
            }
        });
        hidden[i] = neighbours > max_neighbours;
    }
    hidden
}

/// `tcg`: see the module documentation.
pub struct TemporallyCoherentGathering {
    pub settings: TcgSettings,
    ic: IrradianceCaching,
    records: Vec<TcgRecord>,
    last_frame: Option<u32>,
    next_id: RecordId,
    stats: FrameStats,
    /// Store hook ([`Method::keep_frame_records`]).
    keep: bool,
    kept: Option<FrameRecords>,
    /// The last frame's pixel samples, for the render pass to take again
    /// where nothing moving met them.
    still: StillSamples,
    /// The lights of the last frames, to find the samples they left stale.
    lights: stale::LightHistory,
    /// Each moving object's bounds in its own frame (found once), for
    /// `arrived`.
    bounds: Option<Vec<Option<OwnBounds>>>,
}

/// The objects' world transforms in the frame before the one rendered,
/// evaluated once a frame for what asks what moved since
/// (`crossed::MovedObjects`, `arrived::Arrived`).
pub(super) struct Before {
    frame: u32,
    transforms: Vec<glam::Mat4>,
}

impl Before {
    /// `None` in frame 0.
    fn of(ctx: &FrameContext) -> Option<Self> {
        let frame = ctx.frame.checked_sub(1)?;
        Some(Before {
            frame,
            transforms: ctx.scene.object_transforms(ctx.time_of(frame)),
        })
    }
}

impl TemporallyCoherentGathering {
    pub fn new(settings: TcgSettings) -> Self {
        TemporallyCoherentGathering {
            ic: IrradianceCaching::new(settings.ic.clone()),
            settings,
            records: Vec::new(),
            last_frame: None,
            next_id: 0,
            stats: FrameStats::default(),
            keep: false,
            kept: None,
            still: StillSamples::default(),
            lights: stale::LightHistory::default(),
            bounds: None,
        }
    }

    /// The records alive after the last frame, in cache order.
    pub fn records(&self) -> &[TcgRecord] {
        &self.records
    }

    /// Step 1 of the module documentation: the records that go on into
    /// frame `ctx.frame`, moved to it, each with its pose there. The ids
    /// of those that do not are added to `removed`: unused, buried by a
    /// `moved` object (`crossed`) or redundant.
    fn survivors(
        &mut self,
        ctx: &FrameContext,
        (moved, before): (Option<&crossed::MovedObjects>, Option<&Before>),
        stats: &mut FrameStats,
        removed: &mut Vec<RecordId>,
    ) -> Vec<(TcgRecord, (GatherPoint, Frame))> {
        // A frame that does not follow the last one starts a new cache.
        let follows = self.last_frame.is_some_and(|f| f + 1 == ctx.frame);
        let mut alive = Vec::with_capacity(self.records.len());
        for mut r in std::mem::take(&mut self.records) {
            if !(follows && r.used) {
                removed.push(r.record.id);
                continue;
            }
            let pose = r.pose(&ctx.snapshot.object_to_world);
            r.record.position = pose.0.position;
            r.record.normal = pose.0.normal;
            alive.push((r, pose));
        }
        if let Some(moved) = moved {
            let buried = moved.buried(ctx, alive.iter().map(|(r, (point, _))| (r, point)));
            alive = without_marked(alive, buried, removed);
        }
        if let Some(arrived) = follows.then(|| self.arrived(ctx, before)).flatten() {
            let marked = arrived.marked(&alive, self.settings.ic.strata);
            alive = without_marked(alive, marked, removed);
        }
        let points: Vec<&IrradianceRecord> = alive.iter().map(|(r, _)| &r.record).collect();
        let redundant = redundant(
            &points,
            self.settings.ic.accuracy,
            self.settings.max_neighbours,
            scene_bounds(ctx),
        );
        let kept = without_marked(alive, redundant, removed);
        stats.records_dropped = removed.len() as u64;
        kept
    }

    /// The objects that moved into this frame, where `arrivals` is on.
    fn arrived(&mut self, ctx: &FrameContext, before: Option<&Before>) -> Option<arrived::Arrived> {
        if !self.settings.arrivals {
            return None;
        }
        let bounds = (self.bounds)
            .get_or_insert_with(|| moving_bounds(ctx.scene, &ctx.scene.dynamic_objects()));
        arrived::Arrived::of(ctx, bounds, before)
    }

    /// Step 2 (§3.2–3.3): shoots each record's picked cells again, ages the
    /// others and computes the record again from its samples.
    fn update(
        &mut self,
        ctx: &FrameContext,
        alive: Vec<(TcgRecord, (GatherPoint, Frame))>,
        moved: Option<&crossed::MovedObjects>,
        dynamic: &[bool],
        stats: &mut FrameStats,
    ) -> Vec<TcgRecord> {
        let strata = self.settings.ic.strata;
        let staleness = if self.settings.light_refresh {
            self.lights.advance(ctx);
            self.lights.staleness(ctx.frame)
        } else {
            None
        };
        let picks: Vec<Vec<u32>> = alive
            .par_iter()
            .map(|(r, pose)| {
                let mut stale: Vec<bool> = match &staleness {
                    Some(l) => l.stale_cells(r, strata),
                    None => Vec::new(),
                };
                if let Some(moved) = moved {
                    moved.mark(r, pose, strata, &mut stale);
                }
                let stale = select::with_neighbours(&stale, &r.samples, strata);
                let is_stale = |cell: usize| stale.get(cell).copied().unwrap_or(false);
                let count = select::cells_to_update(&self.settings, &r.samples, is_stale);
                let mut rng = Rng::new(self.key(ctx, streams::RECORD_PICK, r, 0));
                select::pick_cells(&r.samples, count, &mut rng, is_stale)
            })
            .collect();
        let mut ranges: Vec<Range<usize>> = Vec::with_capacity(picks.len());
        // (record, cell) of each shot: 8 bytes, made on this thread.
        let mut shots: Vec<(u32, u32)> = Vec::new();
        for (i, cells) in picks.iter().enumerate() {
            ranges.push(shots.len()..shots.len() + cells.len());
            shots.extend(cells.iter().map(|&cell| (i as u32, cell)));
        }
        // Made in parallel (on the render's one thread they kept the other
        // threads waiting), collected from an indexed iterator: an
        // unindexed `collect` gathers pieces in the worker threads' heaps,
        // which kept them and raised the peak memory.
        let queries: Vec<RadianceQuery> = shots
            .par_iter()
            .map(|&(i, cell)| {
                let (r, (point, frame)) = &alive[i as usize];
                let rng = Rng::new(self.key(ctx, streams::RECORD, r, cell));
                cell_query(point, ctx.ray_offset, frame, strata, cell, rng)
            })
            .collect();
        stats.samples_reshot = queries.len() as u64;
        // A hit's distance is its `t` times its ray's length.
        let ray_lengths: Vec<f32> = queries.par_iter().map(|q| q.ray.dir().length()).collect();
        let results = trace_radiance_parallel(ctx, self.settings.ic.gather_length, queries);
        alive
            .into_par_iter()
            .zip(picks)
            .zip(ranges)
            .map(|(((mut r, (point, frame)), cells), range)| {
                for s in &mut r.samples {
                    *s = s.older();
                }
                for (&cell, (length, result)) in cells
                    .iter()
                    .zip(ray_lengths[range.clone()].iter().zip(&results[range]))
                {
                    let hit = result.hit;
                    let (distance, object) = if hit.is_hit() {
                        (hit.t * length, hit.object)
                    } else {
                        (f32::INFINITY, u32::MAX)
                    };
                    let is_dynamic = dynamic.get(object as usize).copied().unwrap_or(false);
                    r.samples[cell as usize] =
                        PackedSample::pack(result.radiance, distance, object, is_dynamic, 0);
                }
                self.recompute(ctx, &mut r, &point, &frame);
                r
            })
            .collect()
    }

    /// The sampling key of record `r`'s stream `tag` in this frame, for
    /// cell `cell`: each frame's picks and shots are new, and repeat
    /// exactly in a resumed render.
    fn key(&self, ctx: &FrameContext, tag: u64, r: &TcgRecord, cell: u32) -> SampleKey {
        SampleKey {
            seed: ctx.seed,
            frame: Some(ctx.frame),
            item: tag | r.candidate.stream,
            sample: cell,
        }
    }

    /// The record's irradiance, gradients and radius from its samples
    /// (`ic`'s estimators and radius limits), at its point of this frame;
    /// a radiance record's sources too ([`radiance_sources`]).
    fn recompute(&self, ctx: &FrameContext, r: &mut TcgRecord, point: &GatherPoint, frame: &Frame) {
        let strata = self.settings.ic.strata;
        let radiance: Vec<Vec3> = r.samples.iter().map(PackedSample::radiance).collect();
        let distance: Vec<f32> = r.samples.iter().map(PackedSample::distance).collect();
        let g = irradiance_and_gradients_in(&radiance, &distance, frame, strata);
        let (radius, grad_translation) = self.ic.limit_radius(&g, r.candidate.footprint);
        // The material comes from the carried state: one the scene lacks
        // (a damaged state) leaves the record no sources.
        let material = r
            .candidate
            .glossy
            .and_then(|m| ctx.scene.materials.get(m as usize));
        let eas = material.map(|material| {
            let bsdf = Bsdf::new(material, point.normal, point.normal);
            radiance_sources(
                radiance,
                distance,
                frame,
                strata,
                &bsdf,
                self.settings.ic.eas_tau,
            )
        });
        let record = &mut r.record;
        record.position = point.position;
        record.normal = point.normal;
        record.irradiance = g.irradiance;
        record.grad_translation = grad_translation;
        record.grad_rotation = g.grad_rotation;
        record.radius = radius;
        record.eas = eas;
    }

    /// Ends frame `t`: radii as neighbour clamping left them, the `used`
    /// flags, ids for the new records (those from `first_new` on), and what
    /// the store keeps of the frame.
    fn finish(
        &mut self,
        t: u32,
        mut records: Vec<TcgRecord>,
        first_new: usize,
        (cache, used): (&IrradianceCache, &[AtomicBool]),
        mut stats: FrameStats,
        removed: Vec<RecordId>,
    ) {
        debug_assert_eq!(records.len(), cache.len());
        for (i, ((r, in_cache), used)) in records
            .iter_mut()
            .zip(cache.records())
            .zip(used)
            .enumerate()
        {
            r.record.radius = in_cache.radius;
            r.used = used.load(Ordering::Relaxed);
            if i >= first_new {
                r.record.id = self.next_id;
                self.next_id += 1;
            }
        }
        stats.records_alive = records.len() as u64;
        stats.cache_bytes = (cache.memory_bytes()
            + records.iter().map(TcgRecord::memory_bytes).sum::<usize>()
            + self.still.memory_bytes()) as u64;
        // Every record's samples may have changed: all are stored again,
        // compressed on every core, and the states refer to them.
        // Compressed twice on the render's thread alone (the state held a
        // copy), a job of the default render took 1.9–2.0× its time
        // without `--job` (`benches/HISTORY.md`, "tcg's samples stored
        // once").
        self.kept = self.keep.then(|| FrameRecords {
            records: records.iter().map(|r| r.record.clone()).collect(),
            samples: (records.par_iter())
                .map(|r| SampleBlock::from_packed(&r.samples))
                .collect(),
            strata: self.settings.ic.strata,
            last_frames: Vec::new(),
            state: Some(StateChanges {
                global: carried::encode_next_id(self.next_id),
                put: records
                    .iter()
                    .map(|r| (r.record.id, state::encode_record(r)))
                    .collect(),
                removed,
            }),
            movies: None,
        });
        self.records = records;
        self.last_frame = Some(t);
        self.stats = stats;
    }
}

impl Method for TemporallyCoherentGathering {
    fn name(&self) -> &'static str {
        "tcg"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        let mut stats = FrameStats {
            frame: ctx.frame,
            ..FrameStats::default()
        };
        let mut removed = Vec::new();
        let start = Instant::now();
        let before = Before::of(ctx);
        let moved = (self.settings.occlusion_refresh)
            .then(|| crossed::MovedObjects::of(ctx, before.as_ref()))
            .flatten();
        let alive = self.survivors(
            ctx,
            (moved.as_ref(), before.as_ref()),
            &mut stats,
            &mut removed,
        );
        let dynamic = ctx.scene.dynamic_objects();
        let mut records = self.update(ctx, alive, moved.as_ref(), &dynamic, &mut stats);
        stats.records_reused = records.len() as u64;
        stats
            .phase_seconds
            .push(("update".into(), start.elapsed().as_secs_f64()));

        let start = Instant::now();
        let (min, max) = scene_bounds(ctx);
        let mut cache = IrradianceCache::new(min, max, self.settings.ic.accuracy);
        for r in &records {
            cache.insert(r.record.clone());
        }
        let first_new = records.len();
        self.ic.fill_from(
            ctx,
            &mut cache,
            &primary_candidates(ctx, &self.settings.ic),
            None,
            |g, _| TcgRecord::gathered(ctx, g, &dynamic),
            &mut records,
        );
        stats.records_created = (records.len() - first_new) as u64;
        stats
            .phase_seconds
            .push(("fill".into(), start.elapsed().as_secs_f64()));

        let start = Instant::now();
        let used: Vec<AtomicBool> = (0..cache.len()).map(|_| AtomicBool::new(false)).collect();
        let film = render_pass(
            ctx,
            &cache,
            &self.settings.ic,
            PixelStreams::Coherent,
            Some(&used),
            Some(&mut self.still),
            &mut stats,
        );
        stats
            .phase_seconds
            .push((RENDER_PHASE.into(), start.elapsed().as_secs_f64()));
        self.finish(
            ctx.frame,
            records,
            first_new,
            (&cache, &used),
            stats,
            removed,
        );
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

    fn carries_state(&self) -> bool {
        true
    }

    /// Every frame stores each record's samples in its version, which the
    /// state refers to instead of holding a copy.
    fn state_refers_to_record_samples(&self) -> bool {
        true
    }

    /// Continues after frame `state.frame` from the records alive then, in
    /// id order (cache order: survivors keep their order and new records
    /// get increasing ids).
    fn restore_state(&mut self, mut s: MethodState) -> Result<(), StateError> {
        let cells = self.settings.ic.strata.count();
        // Each record takes its samples out: a resume holds them once.
        let mut stored = std::mem::take(&mut s.record_samples);
        let (records, next_id) = carried::restore(
            "tcg",
            &s,
            |bytes| state::decode_record(bytes, cells, &mut stored),
            |r| r.record.id,
        )?;
        self.records = records;
        self.next_id = next_id;
        self.last_frame = Some(s.frame);
        self.stats = FrameStats::default();
        self.kept = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(id: u64, x: f32) -> IrradianceRecord {
        IrradianceRecord::flat(id, Vec3::new(x, 0.0, 0.0), Vec3::ONE)
    }

    /// A record on an object that turns about the record's normal and
    /// moves (§4.1): its point moves with the object, its normal stays,
    /// and its cells' tangent turns by the same angle; on an object where
    /// it was made, far from the origin, it is exactly as made.
    #[test]
    fn a_record_turns_its_cells_with_its_object() {
        let mut snapshot = crate::scene::Scene::builtin("cube-in-box")
            .unwrap()
            .snapshot(0.0);
        let point = GatherPoint {
            position: Vec3::new(1.0, 2.0, 3.0),
            normal: Vec3::Y,
            geometric_normal: Vec3::Y,
        };
        let made = Mat4::from_translation(Vec3::new(1e4, -3e3, 7e3)) * Mat4::from_rotation_x(0.3);
        let record = TcgRecord {
            record: record(0, 0.0),
            candidate: Candidate::at(point),
            object_to_world: made,
            samples: Vec::new(),
            used: false,
        };
        snapshot.object_to_world[0] = made;
        let (still, still_frame) = record.pose(&snapshot.object_to_world);
        assert_eq!(still.position, point.position);
        assert_eq!(still_frame.t, Frame::new(Vec3::Y).t);
        let angle = 0.7;
        let turn = Mat4::from_translation(Vec3::new(0.5, 0.0, -2.0)) * Mat4::from_rotation_y(angle);
        snapshot.object_to_world[0] = turn * made;
        let (moved, frame) = record.pose(&snapshot.object_to_world);
        let want = turn.transform_point3(point.position);
        assert!(moved.position.abs_diff_eq(want, 1e-2), "{}", moved.position);
        assert!(moved.normal.abs_diff_eq(Vec3::Y, 1e-5));
        let t0 = Frame::new(Vec3::Y).t;
        let turned = glam::Quat::from_rotation_y(angle) * t0;
        assert!(frame.t.abs_diff_eq(turned, 1e-4), "{} vs {turned}", frame.t);
        assert!(frame.b.abs_diff_eq(Vec3::Y.cross(turned), 1e-4));
    }

    /// 15 records on one point (each usable at the others) and one far
    /// away, at most 10 neighbours: the first 4 go (14, 13, 12 and 11
    /// neighbours left when their turn comes), the other 11 keep 10 each,
    /// and the far one stays.
    #[test]
    fn redundant_records_are_thinned_to_the_neighbour_bound() {
        let mut records: Vec<IrradianceRecord> = (0..15).map(|i| record(i, 0.0)).collect();
        records.push(record(15, 50.0));
        let refs: Vec<&IrradianceRecord> = records.iter().collect();
        let bounds = (Vec3::splat(-60.0), Vec3::splat(60.0));
        let hidden = redundant(&refs, 0.2, 10, bounds);
        let gone: Vec<usize> = (0..16).filter(|&i| hidden[i]).collect();
        assert_eq!(gone, vec![0, 1, 2, 3]);
        assert!(redundant(&refs, 0.2, 14, bounds).iter().all(|h| !h));
    }
}
