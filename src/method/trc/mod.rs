//! `trc`: temporal radiance caching (Gautron, Bouatouch & Pattanaik,
//! "Temporal Radiance Caching", IEEE TVCG 2007 —
//! `papers/temporal-radiance-caching-tvcg2007.md`, §4–5), built on the
//! per-frame irradiance cache of [`super::ic`].
//!
//! Records live across frames (TRC Algorithm 1). When a record K is gathered
//! at frame t0, its incoming light at t0+1 is estimated by reprojecting its
//! hemisphere samples (§4.7, `Reprojection::to`); the ratio `τ = E(t0+1)/E(t0)`
//! sets how many frames K may be used (Eq. 9–11) and the difference gives
//! its extrapolated temporal gradients (Eq. 15–17), applied at lookup by
//! Eq. 14 (E's alone, not the spatial gradients' of Eq. 16–17: a
//! departure, `TemporalRecord::at_frame` says why). Another: the paper
//! extrapolates the change to t0+1 over the whole life, blind to an
//! object at rest that starts moving or jumps
//! later, or a light switched off later; as the animation is known ahead,
//! the record is also reprojected to the later frames of its life where
//! the motion departs from that extrapolation, and its life ends before
//! the first where it is more than `a^t` from what it shows there (E(t0),
//! or with extrapolated gradients E(t0) carried on), or where an object
//! none of its samples hit (or one they hit that now covers more of the
//! view by over `a^t`) comes into more than `a^t` of their paths
//! (`later`, `method::arrivals`). Each frame:
//! 1. *age records*: a record still valid is reused; one that is no longer
//!    valid but contributed to the previous frame is replaced by a new
//!    record gathered at the same point (§4.4, "p_l = p_K"); one that
//!    contributed to no pixel is dropped (§5, "Replacement/deletion
//!    method": no trail of records behind moving objects). Departures: a
//!    replacement whose gather rays mostly hit the back faces of moving
//!    objects is dropped too (`back_face_share`): a moving object has come
//!    over its point, and gathered inside the object it would darken the
//!    pixels around it; and a record that lived one frame is dropped, not
//!    replaced (`TemporalRecord::replaced_when_expired`): the fill covers
//!    its point if no other record does;
//! 2. *fill*: `ic`'s fill stage adds records where none is usable;
//! 3. *render*: `ic`'s render pass, flagging every record a pixel sample
//!    used (our stand-in for the paper's occlusion query; with the GPU
//!    backend the render pass splats the records on the GPU as in §5 and
//!    returns these flags from there, `backend::gpu::cache_splat`).
//!
//! With `--ic-glossy eas` glossy surfaces get radiance records (`ic`'s,
//! [`crate::cache::eas`]), and they live across frames as the paper's
//! radiance records do (§4.6): the reprojected samples are summed over
//! each source's cells (`eas::irradiance_over`), τ is the largest ratio
//! over the sources (Eq. 21; the record's irradiance keeps its own Eq. 7,
//! for the surface's diffuse part), and each source has its own
//! extrapolated gradient (§4.6.2). Departure: with interpolated gradients
//! the sources keep their extrapolated ones, since the replacement keeps
//! another cut of its own tree and Eq. 18–20 have no source of it to pair
//! with each of K's.
//!
//! Everything spatial — candidates, gathering, weights, gradients,
//! neighbour clamping, direct light, glossy lobes — is `ic`'s code.
//! Here are the temporal parts: a record's life (the temporal weight and
//! gradients) in the submodule `record`, the E(t0+1) estimate by
//! reprojection in `estimate`, its check against the later frames in
//! `later`, the paths a replacement takes in `paths`,
//! and the encoding of the carried state for the store in `state`.
//!
//! # The E(t0+1) estimate (TRC Table 1)
//! Reprojection makes the estimate of E(t0+1) no better than E(t0) itself
//! where objects move (cube-in-box; test
//! `reprojection_estimate_of_next_frame_is_no_worse_than_constant`), for
//! reasons the measurements show (`benches/RESULTS.md`, "The E(t0+1)
//! estimate with and without reprojection"):
//! - only the records whose samples see a moving object get an estimate
//!   other than E(t0). Most records change through moving shadows on what
//!   they see (or lie on a moving object, fixed in world space), which no
//!   reprojection of first hits can see; the optional `direct` estimate
//!   evaluates each sample's direct light again at t0+1 and sees the
//!   shadows;
//! - a record's own Monte Carlo noise (16×48 cells, one path each) is
//!   larger than its change in one frame, where the paper's rasterized
//!   hemispheres are noise-free. With the same random streams a static
//!   sample's noise cancels exactly between E(t0) and the regathered
//!   E(t0+1), while a reprojected sample lands in a cell whose actual
//!   sample has other noise: that comparison favours the constant
//!   estimate;
//! - scaling moved samples by the ratio of unshadowed direct light at
//!   their new place and normal made the estimate worse where only
//!   objects move, so it is applied only when lights move. As a check at
//!   the end of a life it lowered the lag under a turning plate (block
//!   bias 0.079 → 0.043 at its worst) but cut lives in the middle of a
//!   box's turn on `l_hall`, whose replacements then missed the shadows
//!   the box moved (they are not in the moved samples): not kept
//!   (`benches/RESULTS.md`, "The moved samples relit at the life's end").
//!
//! Where the light moves, reprojection helps as in the paper (test
//! `reprojection_follows_a_moving_light_better_than_constant`).

mod direct;
mod estimate;
pub mod estimate_error;
mod later;
mod paths;
mod record;
mod settings;
mod state;

use record::{
    change_of, frames_of_validity, relative_change, shown_irradiance, sources_change,
    with_observed_change,
};
pub use record::{Successor, TemporalRecord};
use settings::lives_are_long;
pub use settings::{NextDirect, TemporalGradients, TrcSettings};
pub use state::{
    downgrade_to_schema_10_record, downgrade_to_schema_11_record, downgrade_to_schema_6_record,
    sources_in, upgrade_schema_10_record, upgrade_schema_11_record, upgrade_schema_6_record,
};

use super::carried;
use super::ic::IrradianceCaching;
use super::ic::{primary_candidates, scene_bounds, Candidate, GatherTracks, Gathered, TrackPaths};
use super::motion::Blockers;
use super::render_pass::{lights_fingerprint, mark_used, render_pass, PixelStreams, StillSamples};
use super::{
    mean_lifespan, FrameContext, FrameRecords, FrameStats, Method, MethodState, StateChanges,
    StateError, RENDER_PHASE,
};
use crate::cache::eas;
use crate::cache::gather::{self, HemisphereSamples};
use crate::cache::{IrradianceCache, RecordId};
use crate::film::Film;
use crate::integrator::KnownPath;
use crate::store::SampleBlock;
use estimate::{NextFrame, Reprojection};
use glam::Vec3;
use later::LaterFrames;
use paths::KeptPaths;
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// A frame through the first pass (interpolated gradients), waiting to be
/// rendered.
struct PendingFrame {
    frame: u32,
    /// The records of the frame's cache, in cache order, radii as clamped.
    records: Vec<TemporalRecord>,
    stats: FrameStats,
    /// The frame after the last one any of these records is valid in:
    /// their replacements are known once the first pass has reached it.
    horizon: u32,
    /// Store hook: the first pass's new records and state changes of this
    /// frame, handed out when the frame is rendered.
    kept: Option<FrameRecords>,
}

/// `trc`. With extrapolated or no temporal gradients, one pass: each frame
/// ages the records, replaces or drops the expired ones, fills and renders.
/// With interpolated gradients (TRC Eq. 18–20), the aging, replacement and
/// fill run as a first pass ahead of rendering ([`Method::prepare_frame`],
/// driven by the renderer): a frame is rendered once the first pass has
/// reached the frame after the last frame any of its records is valid in —
/// at most `δt_max` frames ahead, fewer near the end of the rendered range
/// (records still valid at its end keep their extrapolated gradients). The
/// first pass decides replace-or-drop from a pass over the pixel samples'
/// lookups that flags the same records the render pass would
/// ([`super::ic`]'s `mark_used`), so both passes see the same records.
pub struct TemporalRadianceCaching {
    pub settings: TrcSettings,
    ic: IrradianceCaching,
    records: Vec<TemporalRecord>,
    /// The last frame through aging and fill (the first pass).
    last_frame: Option<u32>,
    next_id: RecordId,
    stats: FrameStats,
    /// Interpolated gradients: frames through the first pass, not rendered.
    pending: VecDeque<PendingFrame>,
    /// Interpolated gradients: replacements found by the first pass, by
    /// the id of the record they replace, while that record may be used.
    successors: HashMap<RecordId, Successor>,
    /// Store hook ([`Method::keep_frame_records`]): keep each frame's new
    /// records with their samples and the frame's state changes.
    keep: bool,
    /// The kept records and changes of the last frame rendered.
    kept: Option<FrameRecords>,
    /// Records forgotten by a first pass that went back (interpolated
    /// gradients), to report as removed with the next state changes.
    forgotten: Vec<RecordId>,
    /// The BVHs of the E(t0+1) estimate's shadow rays.
    shadow_geometry: direct::ShadowGeometry,
    /// The last frame's pixel samples, for the render pass to take again
    /// where nothing moving met them.
    still: StillSamples,
    /// The same for the first pass's usage marks (interpolated gradients),
    /// which runs ahead of rendering.
    first_pass_still: StillSamples,
    /// Whether kept paths pay for their keeping here ([`paths::PathsPay`]).
    paths_pay: paths::PathsPay,
    /// The transforms and lights of the frames after the next, for the
    /// records' life checks ([`later`]).
    ahead: later::Ahead,
    /// Records replaced together at most ([`REPLACE_BATCH`]; tests set
    /// others).
    replace_batch: usize,
}

impl TemporalRadianceCaching {
    pub fn new(settings: TrcSettings) -> Self {
        TemporalRadianceCaching {
            ic: IrradianceCaching::new(settings.ic.clone()),
            settings,
            records: Vec::new(),
            last_frame: None,
            next_id: 0,
            stats: FrameStats::default(),
            pending: VecDeque::new(),
            successors: HashMap::new(),
            keep: false,
            kept: None,
            forgotten: Vec::new(),
            shadow_geometry: direct::ShadowGeometry::default(),
            still: StillSamples::default(),
            first_pass_still: StillSamples::default(),
            paths_pay: paths::PathsPay::default(),
            ahead: later::Ahead::default(),
            replace_batch: REPLACE_BATCH,
        }
    }

    /// The records alive after the last frame through aging and fill (with
    /// interpolated gradients, the first pass may be ahead of rendering),
    /// in cache order.
    pub fn records(&self) -> &[TemporalRecord] {
        &self.records
    }

    /// Gathers again, in the frame of `ctx`, at the points of `records`
    /// with the random streams each was first gathered with: the actual
    /// `E(t)` to compare with an estimate (TRC Table 1).
    pub fn regather(&self, ctx: &FrameContext, records: &[TemporalRecord]) -> Vec<Vec3> {
        use rayon::prelude::*;
        let candidates: Vec<Candidate> = records.iter().map(|r| r.candidate).collect();
        self.ic
            .gather_parallel(ctx, &candidates)
            .map(|g| g.record.irradiance)
            .collect()
    }

    /// TRC §4.4–4.7 for a record just gathered at `ctx.frame`: estimate
    /// E(t0+1), derive τ, lifespan and temporal gradients; the lifespan
    /// then checked against the frames after t0+1 ([`later`]). A
    /// replacement also has the change a frame `observed` over the life of
    /// the record it replaces (`TrcSettings::history`; `None` where off).
    fn temporal(
        &self,
        making: &RecordMaking,
        g: &Gathered,
        observed: Option<Vec3>,
    ) -> TemporalRecord {
        let (ctx, strata) = (making.ctx, self.settings.ic.strata);
        let a_t = self.settings.temporal_accuracy;
        let e0 = g.record.irradiance;
        let reprojection = Reprojection::new(g, strata);
        let next_samples = self
            .settings
            .reprojection
            .then(|| reprojection.to(ctx, &making.next));
        let mut next = self.change_to(g, next_samples.as_ref());
        if let Some(observed) = observed {
            next.irradiance = with_observed_change(e0, next.irradiance, observed);
            next.change = change_of(&g.record, next.irradiance, next.d_eas.as_deref());
        }
        let age = frames_of_validity(next.change, a_t, self.settings.max_life);
        let mut last_valid = ctx.frame + age;
        let e1 = next.irradiance;
        if let Some(later) = &making.later {
            let shown = |t: u32| shown_irradiance(self.settings.gradients, e0, e1, t - ctx.frame);
            // Against what the record will show there, not E(t0): where
            // the change turns, extrapolated gradients carry it on past
            // the light they were to follow.
            let exceeds = |t: u32, samples: &HemisphereSamples| {
                let later = self.change_to(g, Some(samples));
                let shown_change = relative_change(shown(t), later.irradiance);
                shown_change.max(sources_change(&g.record, later.d_eas.as_deref())) > a_t
            };
            last_valid =
                later.last_valid(ctx, &making.next, &reprojection, a_t, last_valid, exceeds);
        }
        TemporalRecord {
            record: g.record.clone(),
            candidate: g.candidate,
            next_irradiance: e1,
            last_valid,
            d_eas: next.d_eas,
            replaces: None,
            used: false,
            paths: None,
        }
    }

    /// Gather `g`'s record as its `samples` at a later frame give it (none:
    /// unchanged): irradiance and spatial gradients, each source's change
    /// (§4.6.2) and the worst relative change `|τ − 1|` (Eq. 7, 21).
    fn change_to(&self, g: &Gathered, samples: Option<&HemisphereSamples>) -> Change {
        let strata = self.settings.ic.strata;
        let irradiance = samples.map_or(g.record.irradiance, |samples| {
            gather::irradiance(samples, strata)
        });
        let d_eas = g.record.eas.as_ref().map(|sources| {
            let later = samples.and_then(|samples| eas::irradiance_over(sources, samples, strata));
            let d: Arc<[Vec3]> = match later {
                Some(later) => sources
                    .iter()
                    .zip(later)
                    .map(|(s, e)| e - s.irradiance)
                    .collect(),
                None => vec![Vec3::ZERO; sources.len()].into(),
            };
            d
        });
        let change = change_of(&g.record, irradiance, d_eas.as_deref());
        Change {
            irradiance,
            d_eas,
            change,
        }
    }

    /// Aging and fill of frame `ctx.frame` (TRC Algorithm 1): the frame's
    /// cache and its records in cache order (new ones not numbered yet).
    fn age_and_fill(&mut self, ctx: &FrameContext) -> (IrradianceCache, Aged) {
        let start = Instant::now();
        let lives_long = lives_are_long(
            self.records.iter().map(TemporalRecord::lifespan),
            self.settings.max_life,
        );
        let next_direct = self.settings.next_direct.at_frame(lives_long);
        let next = NextFrame::new(ctx, next_direct, &mut self.shadow_geometry);
        let later = self
            .settings
            .reprojection
            .then(|| LaterFrames::new(ctx, &next, self.settings.max_life, &mut self.ahead));
        let motion = FrameMotion {
            blockers: Blockers::new(ctx),
            lights: lights_fingerprint(ctx),
            lights_move: next.lights_move(),
            track: self.settings.keep_paths
                && self.paths_pay.track(ctx.frame, self.settings.max_life),
            moving: ctx.scene.dynamic_objects(),
        };
        let making = RecordMaking {
            ctx,
            next,
            later,
            keep: self.keep,
            motion,
        };
        let (min, max) = scene_bounds(ctx);
        let mut cache = IrradianceCache::new(min, max, self.settings.ic.accuracy);
        let mut aged = Aged {
            alive: Vec::with_capacity(self.records.len()),
            stats: FrameStats {
                frame: ctx.frame,
                ..FrameStats::default()
            },
            removed: std::mem::take(&mut self.forgotten),
            samples: Vec::new(),
            paths_bytes: 0,
            after_departure: HashSet::new(),
        };
        let expired = self.age(ctx.frame, &mut cache, &mut aged);
        let offered = self.replace(&making, expired, &mut cache, &mut aged);
        self.paths_pay.measure(offered);
        let phases = &mut aged.stats.phase_seconds;
        phases.push(("age".into(), start.elapsed().as_secs_f64()));

        let start = Instant::now();
        self.fill(&making, &mut cache, &mut aged);
        let phases = &mut aged.stats.phase_seconds;
        phases.push(("fill".into(), start.elapsed().as_secs_f64()));
        if let Some(later) = &making.later {
            later.hold_lit_geometry(&mut self.ahead);
        }
        if let Some(later) = making.next.into_later_snapshot() {
            // Already set only if another pass made it first: equal.
            let _ = ctx.next_snapshot.set(later);
        }
        (cache, aged)
    }

    /// Ages the records at frame `t` (TRC Algorithm 1, §4.4, §5
    /// replacement/deletion): one still valid goes into the cache as it
    /// is; an expired one is returned, to be replaced, if a pixel used it
    /// in frame `t − 1` and it lived more than that frame
    /// ([`TemporalRecord::replaced_when_expired`]), and dropped otherwise.
    fn age(&mut self, t: u32, cache: &mut IrradianceCache, aged: &mut Aged) -> Vec<TemporalRecord> {
        let follows = self.last_frame.is_some_and(|f| f + 1 == t);
        let mut expired = Vec::new();
        for r in std::mem::take(&mut self.records) {
            if r.is_valid_at(t) {
                aged.stats.records_reused += 1;
                cache.insert_as_is(r.at_frame(t, self.settings.gradients, None));
                aged.paths_bytes += r.paths.as_deref().map_or(0, KeptPaths::memory_bytes);
                aged.alive.push(r);
                continue;
            }
            if self.keep {
                aged.removed.push(r.record.id);
            }
            if follows && r.used && r.replaced_when_expired(self.settings.max_life) {
                expired.push(r);
            } else {
                aged.stats.records_dropped += 1;
            }
        }
        expired
    }

    /// Replaces each of the `expired` records at its location (§4.4:
    /// p_l = p_K), inserted whether or not another record covers the
    /// point, gathered with K's random streams (`ic::first_stream`),
    /// taking the results of K's paths that nothing moving met then or
    /// meets now ([`paths`]); a replacement gathered inside a moving object
    /// ([`back_face_share`]) is dropped instead. Returns how many paths the
    /// replacements were offered and took.
    ///
    /// In batches of [`REPLACE_BATCH`] records, each batch's kept paths let
    /// go once its replacements are made: every record made in one frame
    /// expires at once where nothing shortened its life (at `δt_max`), and
    /// such a wave held the old records' kept paths, what they offered
    /// and the new records' paths all at once, up to twice
    /// [`paths::BUDGET_BYTES`] (411 MB of kept paths at frame 20 of the
    /// default 256 × 256 render, `heaptrack`). Batches change no record.
    fn replace(
        &self,
        making: &RecordMaking,
        mut expired: Vec<TemporalRecord>,
        cache: &mut IrradianceCache,
        aged: &mut Aged,
    ) -> paths::Offered {
        let mut offered = paths::Offered::default();
        aged.stats.samples_reshot = 0;
        for batch in expired.chunks_mut(self.replace_batch.max(1)) {
            offered += self.replace_batch(making, batch, cache, aged);
            for old in batch {
                old.paths = None;
            }
        }
        offered
    }

    /// [`Self::replace`] of one batch of the `expired` records.
    fn replace_batch(
        &self,
        making: &RecordMaking,
        expired: &[TemporalRecord],
        cache: &mut IrradianceCache,
        aged: &mut Aged,
    ) -> paths::Offered {
        use rayon::prelude::*;
        let (ctx, motion) = (making.ctx, &making.motion);
        let candidates: Vec<Candidate> = expired.iter().map(|r| r.candidate).collect();
        let (known, offered) = motion.known_paths(expired);
        // Each replacement traces again the rays of the record it replaces
        // that it cannot take.
        aged.stats.samples_reshot +=
            (candidates.len() * self.settings.ic.strata.count() - offered.taken) as u64;
        let track = |c: &Candidate| motion.tracks(c);
        let make = |i: usize, g: Gathered, tracks: Option<GatherTracks>| {
            let inside = back_face_share(ctx, &g) > MAX_BACK_FACE_SHARE;
            (!inside).then(|| {
                let k = &expired[i];
                let observed = self.observed_change(k, ctx.frame, &g);
                let old = k.paths.as_deref();
                self.make_record(making, &g, tracks.as_ref(), old, observed)
            })
        };
        let gathered: Vec<Option<(TemporalRecord, Option<SampleBlock>)>> = self
            .ic
            .gather_parallel_tracked(ctx, &candidates, &known, &track, &make)
            .collect();
        for (gathered, old) in gathered.into_iter().zip(expired) {
            let Some((mut new, samples)) = gathered else {
                aged.stats.records_dropped += 1;
                continue;
            };
            aged.keep_paths_within_budget(&mut new);
            new.replaces = Some(old.record.id);
            let settings = &self.settings;
            if old.ended_at_a_departure(settings.temporal_accuracy, settings.max_life) {
                aged.after_departure.insert(old.record.id);
            }
            cache.insert(new.at_frame(ctx.frame, self.settings.gradients, None));
            aged.alive.push(new);
            aged.samples.extend(samples);
            aged.stats.records_replaced += 1;
        }
        offered
    }

    /// The change a frame of the light at expired record `k`'s point over
    /// its life, as its replacement gathered there at frame `t` (`l`)
    /// observes it: `(E_l − E_K) / (t − t0)`. The two gathers draw the same
    /// random streams and `l` takes `k`'s paths that nothing moving met,
    /// so their noise cancels but on the paths that changed. `None` where
    /// `k`'s life ended at a later frame whose motion departed from the
    /// extrapolated one ([`TemporalRecord::ended_at_a_departure`]): the
    /// change before the departure does not go on after it; and where
    /// `history` is off, which takes none.
    fn observed_change(&self, k: &TemporalRecord, t: u32, l: &Gathered) -> Option<Vec3> {
        let settings = &self.settings;
        if !settings.history
            || k.ended_at_a_departure(settings.temporal_accuracy, settings.max_life)
        {
            return None;
        }
        let span = t.saturating_sub(k.record.created_frame).max(1) as f32;
        Some((l.record.irradiance - k.record.irradiance) / span)
    }

    /// New records where nothing is usable (`ic`'s fill stage), each with
    /// its E(t0+1) estimate.
    fn fill(&self, making: &RecordMaking, cache: &mut IrradianceCache, aged: &mut Aged) {
        let ctx = making.ctx;
        let pixels = primary_candidates(ctx, &self.settings.ic);
        let mut created = Vec::new();
        let track = |c: &Candidate| making.motion.tracks(c);
        // Where the lights move on, only their hits would be taken, and a
        // new record is often dropped unused instead of replaced (a third
        // of them on `wall_light`): the paths of those that were replaced
        // once are kept (`benches/RESULTS.md`, "Under moving lights, the
        // paths' hits").
        let motion = &making.motion;
        let new_records_keep = motion.track && !motion.lights_move;
        self.ic.fill_from(
            ctx,
            cache,
            &pixels,
            new_records_keep.then_some(&track as &TrackPaths),
            |g, tracks| self.make_record(making, g, tracks.as_ref(), None, None),
            &mut created,
        );
        aged.stats.records_created = created.len() as u64;
        for (mut r, samples) in created {
            aged.keep_paths_within_budget(&mut r);
            aged.alive.push(r);
            aged.samples.extend(samples);
        }
    }

    /// The temporal record of gather `g` (new, or replacing a record whose
    /// kept paths were `taken_from`), with its paths where `tracks` has
    /// them and the record may be replaced, and its samples packed for the
    /// store. A record granted one frame is dropped when it expires
    /// ([`TemporalRecord::replaced_when_expired`]), so no replacement would
    /// take its paths: a third of the records of a 64×64 `spheres` render.
    fn make_record(
        &self,
        making: &RecordMaking,
        g: &Gathered,
        tracks: Option<&GatherTracks>,
        taken_from: Option<&KeptPaths>,
        observed: Option<Vec3>,
    ) -> (TemporalRecord, Option<SampleBlock>) {
        let mut r = self.temporal(making, g, observed);
        let replaceable = r.replaced_when_expired(self.settings.max_life);
        let tracks = tracks.filter(|_| replaceable);
        r.paths = tracks.map(|tracks| Arc::new(making.motion.paths(g, tracks, taken_from)));
        (r, making.pack(g))
    }

    /// Ends frame `t`'s aging: radii as neighbour clamping left them, the
    /// `used` flags, ids for the new records, lifespan statistics, and (for
    /// interpolated gradients) the successors of the records replaced.
    fn finish(&mut self, t: u32, aged: Aged, cache: &IrradianceCache, used: &[AtomicBool]) {
        let Aged {
            mut alive,
            mut stats,
            removed,
            samples,
            after_departure,
            ..
        } = aged;
        debug_assert_eq!(alive.len(), cache.len());
        let longest = self.settings.max_life.max(1) as usize;
        let mut lifespans = vec![0u64; longest + 1];
        // Store hook: the frame's new records and its state changes.
        let mut kept = self.keep.then(|| FrameRecords {
            strata: self.settings.ic.strata,
            samples,
            state: Some(StateChanges {
                removed,
                ..StateChanges::default()
            }),
            ..FrameRecords::default()
        });
        for ((r, in_cache), used) in alive.iter_mut().zip(cache.records()).zip(used) {
            let changed = r.sync(in_cache.radius, used.load(Ordering::Relaxed));
            let new = r.record.created_frame == t;
            if new {
                r.record.id = self.next_id;
                self.next_id += 1;
            }
            if let Some(k) = kept.as_mut() {
                keep_for_store(k, r, new, changed);
            }
            if new {
                lifespans[(r.lifespan() as usize).min(longest)] += 1;
                if let (TemporalGradients::Interpolated, Some(old)) =
                    (self.settings.gradients, r.replaces)
                {
                    if !after_departure.contains(&old) {
                        self.successors.insert(old, Successor::of(r));
                    }
                }
            }
        }
        stats.mean_lifespan = mean_lifespan(&lifespans);
        stats.lifespan_histogram = lifespans;
        stats.records_alive = alive.len() as u64;
        stats.cache_bytes = (cache.memory_bytes()
            + alive
                .iter()
                .map(TemporalRecord::memory_bytes)
                .sum::<usize>()
            + self.still.memory_bytes()
            + self.first_pass_still.memory_bytes()) as u64;
        if let Some(k) = kept.as_mut() {
            k.state.as_mut().expect("set above").global = carried::encode_next_id(self.next_id);
        }
        self.kept = kept;
        self.records = alive;
        self.last_frame = Some(t);
        self.stats = stats;
    }

    /// Renders frame `t` from its first pass (interpolated gradients).
    fn render_pending(&mut self, ctx: &FrameContext) -> Film {
        let t = ctx.frame;
        while self.pending.front().is_some_and(|p| p.frame < t) {
            self.pending.pop_front();
        }
        if self.pending.front().is_none_or(|p| p.frame != t) {
            // Not driven by a renderer that prepares frames: no lookahead.
            self.prepare_frame(ctx);
        }
        let p = self.pending.pop_front().expect("frame prepared just now");
        self.kept = p.kept;
        let mut stats = p.stats;
        let start = Instant::now();
        let (min, max) = scene_bounds(ctx);
        let mut cache = IrradianceCache::new(min, max, self.settings.ic.accuracy);
        for r in &p.records {
            let successor = self.successors.get(&r.record.id);
            cache.insert_as_is(r.at_frame(t, TemporalGradients::Interpolated, successor));
        }
        let film = render_pass(
            ctx,
            &cache,
            &self.settings.ic,
            PixelStreams::Coherent,
            None,
            Some(&mut self.still),
            &mut stats,
        );
        stats
            .phase_seconds
            .push((RENDER_PHASE.into(), start.elapsed().as_secs_f64()));
        // A record replaced at t_l is last used at t_l − 1.
        self.successors.retain(|_, l| l.frame > t + 1);
        self.stats = stats;
        film
    }
}

impl Method for TemporalRadianceCaching {
    fn name(&self) -> &'static str {
        "trc"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        if self.settings.gradients == TemporalGradients::Interpolated {
            return self.render_pending(ctx);
        }
        let (cache, mut aged) = self.age_and_fill(ctx);
        let start = Instant::now();
        let used: Vec<AtomicBool> = (0..cache.len()).map(|_| AtomicBool::new(false)).collect();
        let film = render_pass(
            ctx,
            &cache,
            &self.settings.ic,
            PixelStreams::Coherent,
            Some(&used),
            Some(&mut self.still),
            &mut aged.stats,
        );
        aged.stats
            .phase_seconds
            .push((RENDER_PHASE.into(), start.elapsed().as_secs_f64()));
        self.finish(ctx.frame, aged, &cache, &used);
        film
    }

    /// Interpolated gradients: the first pass runs ahead until the
    /// replacements of every record frame `frame` uses are known, that is
    /// through the frame `horizon` they are replaced in (or to the end of
    /// the range).
    fn next_frame_to_prepare(&self, frame: u32, end: u32) -> Option<u32> {
        if self.settings.gradients != TemporalGradients::Interpolated {
            return None;
        }
        let Some(p) = self.pending.iter().find(|p| p.frame == frame) else {
            return Some(frame);
        };
        let next = self.last_frame.unwrap_or(frame) + 1;
        (next <= p.horizon && next < end).then_some(next)
    }

    /// The first pass over `ctx.frame` (interpolated gradients): aging,
    /// replacement and fill, and the records the frame's pixel samples use.
    fn prepare_frame(&mut self, ctx: &FrameContext) {
        let t = ctx.frame;
        if self.last_frame.is_some_and(|f| f >= t) {
            // Going back: start over from this frame.
            if self.keep {
                self.forgotten
                    .extend(self.records.iter().map(|r| r.record.id));
            }
            self.records.clear();
            self.pending.clear();
            self.successors.clear();
            self.last_frame = None;
        }
        let (cache, mut aged) = self.age_and_fill(ctx);
        let start = Instant::now();
        let used: Vec<AtomicBool> = (0..cache.len()).map(|_| AtomicBool::new(false)).collect();
        mark_used(
            ctx,
            &cache,
            &self.settings.ic,
            PixelStreams::Coherent,
            &used,
            Some(&mut self.first_pass_still),
        );
        aged.stats
            .phase_seconds
            .push(("usage".into(), start.elapsed().as_secs_f64()));
        self.finish(t, aged, &cache, &used);
        let horizon = self
            .records
            .iter()
            .map(|r| r.last_valid + 1)
            .max()
            .unwrap_or(t + 1);
        self.pending.push_back(PendingFrame {
            frame: t,
            records: self.records.clone(),
            stats: self.stats.clone(),
            horizon,
            kept: self.kept.take(),
        });
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

    fn looks_ahead(&self) -> bool {
        self.settings.gradients == TemporalGradients::Interpolated
    }

    /// Continues after frame `state.frame` from the records alive then (in
    /// id order, which is cache order: survivors keep their order and new
    /// records get increasing ids) and the next record id. With
    /// interpolated gradients the state is the first pass's at that frame:
    /// the first pass goes on from there (its lookahead beyond the frame
    /// was not acknowledged and is redone), and no successor found before
    /// is needed again (a record replaced at `t_l ≤ frame` was last used at
    /// `t_l − 1 < frame + 1`).
    fn restore_state(&mut self, s: MethodState) -> Result<(), StateError> {
        let (records, next_id) =
            carried::restore("trc", &s, state::decode_record, |r| r.record.id)?;
        self.records = records;
        self.next_id = next_id;
        self.last_frame = Some(s.frame);
        self.stats = FrameStats::default();
        self.pending.clear();
        self.successors.clear();
        self.forgotten.clear();
        self.kept = None;
        Ok(())
    }
}

/// What the records made in a frame need beside their gathers: the frame,
/// the E(t0+1) estimate's view of the next one, whether the store keeps
/// their samples, and what moves (for their kept paths and their samples'
/// stored form).
struct RecordMaking<'a> {
    ctx: &'a FrameContext<'a>,
    next: NextFrame,
    /// The frames after the next, for the records' life checks (with
    /// reprojection).
    later: Option<LaterFrames>,
    /// Store hook: the records are kept, with their samples.
    keep: bool,
    motion: FrameMotion,
}

impl RecordMaking<'_> {
    /// Store hook: gather `g`'s samples in their stored form, packed as
    /// soon as they are gathered (the E(t0+1) estimate used them at full
    /// precision first); nothing when the records are not kept.
    fn pack(&self, g: &Gathered) -> Option<SampleBlock> {
        self.keep
            .then(|| SampleBlock::pack(&g.samples, &self.motion.moving))
    }
}

/// A record's change to a later frame, as its reprojected samples give it.
struct Change {
    /// E at that frame.
    irradiance: Vec3,
    /// A radiance record's change of each source's irradiance.
    d_eas: Option<Arc<[Vec3]>>,
    /// The worst relative change from t0 (`|τ − 1|` for t0+1).
    change: f32,
}

/// A frame through aging and fill, before its lookups.
struct Aged {
    /// The frame's records in cache order (new ones not numbered yet).
    alive: Vec<TemporalRecord>,
    stats: FrameStats,
    /// Store hook: ids of the records dropped or replaced.
    removed: Vec<RecordId>,
    /// Store hook: samples of the new records, in their order in `alive`.
    samples: Vec<SampleBlock>,
    /// Bytes of the kept paths of the records in `alive`.
    paths_bytes: usize,
    /// Records replaced whose life a later frame's departure ended: their
    /// replacements are not their successors (they keep extrapolated
    /// gradients).
    after_departure: HashSet<RecordId>,
}

impl Aged {
    /// Lets a record just gathered keep its paths while all the records'
    /// fit [`paths::BUDGET_BYTES`] (past it, its replacement traces every
    /// path: slower, the same record).
    fn keep_paths_within_budget(&mut self, r: &mut TemporalRecord) {
        let bytes = r.paths.as_deref().map_or(0, KeptPaths::memory_bytes);
        if self.paths_bytes + bytes > paths::BUDGET_BYTES {
            r.paths = None;
        } else {
            self.paths_bytes += bytes;
        }
    }
}

/// What moves in a frame, for the kept paths ([`paths`]), and whether
/// the frame's new records keep theirs.
struct FrameMotion {
    blockers: Blockers,
    lights: u64,
    /// The lights move on to the next frame: the paths kept are most
    /// likely traced again in other lights, for their hits only.
    lights_move: bool,
    track: bool,
    /// Which objects move.
    moving: Vec<bool>,
}

impl FrameMotion {
    /// Whether the gather at `c` keeps its paths: in frames whose records
    /// keep theirs, where `c` lies on no moving object. A new record's
    /// paths there start inside that object's box, so none would be kept
    /// ([`KeptPaths::of`]); a replacement there is rare (a record its
    /// object has left is seldom used in its last frame) and its paths
    /// start where the object was, so few would be. Tracking them is
    /// waste; it changes no record.
    fn tracks(&self, c: &Candidate) -> bool {
        self.track && !self.moving.get(c.object as usize).copied().unwrap_or(true)
    }

    /// What the kept paths of the `expired` records give their
    /// replacements (per record, per query, what is known of each path:
    /// [`KeptPaths::known`]; `None` where the record kept none), and how
    /// many paths were offered, taken whole and taken for their hits.
    fn known_paths<'a>(
        &self,
        expired: &'a [TemporalRecord],
    ) -> (Vec<KnownPaths<'a>>, paths::Offered) {
        use rayon::prelude::*;
        let known: Vec<KnownPaths> = expired
            .par_iter()
            .map(|r| (r.paths.as_deref()).map(|p| p.known(&self.blockers, self.lights)))
            .collect();
        let all = || known.iter().flatten().flatten();
        let offered = paths::Offered {
            taken: all()
                .filter(|k| matches!(k, Some(KnownPath::Result(_))))
                .count(),
            relit: all()
                .filter(|k| matches!(k, Some(KnownPath::Hits(_))))
                .count(),
            paths: expired
                .iter()
                .filter_map(|r| r.paths.as_deref())
                .map(KeptPaths::len)
                .sum(),
        };
        (known, offered)
    }

    /// The paths of gather `g` to keep: `tracks` of those it traced
    /// (`None`: taken from `taken_from`).
    fn paths(
        &self,
        g: &Gathered,
        tracks: &GatherTracks,
        taken_from: Option<&KeptPaths>,
    ) -> KeptPaths {
        let lights = (self.lights, !self.lights_move);
        KeptPaths::of(&g.results, tracks, taken_from, &self.blockers, lights)
    }
}

/// Per query of a replacement's gather, what its record's kept path gives
/// (`None`: traced again); `None` for a replacement given none.
type KnownPaths<'a> = Option<Vec<Option<KnownPath<'a>>>>;

/// Records replaced together at most ([`TemporalRadianceCaching::replace`]):
/// their kept paths, about 100 KB a record, and what those offer held at
/// once; enough records for every thread's gathers.
const REPLACE_BATCH: usize = 256;

/// Above this share of gather rays that hit the back of a surface, a
/// replacement's point is taken to lie inside an object (see
/// [`back_face_share`]).
const MAX_BACK_FACE_SHARE: f32 = 0.5;

/// The share of a gather's rays whose first hit is the back of a triangle
/// of a moving object (the ray leaves along the triangle's geometric
/// normal). A record is replaced where it was created, fixed in
/// world space (§4.4), and a moving object may since have come over that
/// point: a floor record under the cube then gathers the cube's inside,
/// seen from behind, and lends its darkness to the floor pixels around the
/// cube. A point on a visible surface sees almost only front faces.
///
/// Only what moved counts, because only a moving object can have come over
/// a point that was a visible surface when its record was made: the static
/// back faces a record sees it saw when it was made too (a room modelled
/// with its walls facing out, the ceiling above a light panel that faces
/// down). Counting every triangle dropped every replacement in such a room,
/// and on cube-in-box it changed nothing measurable: 64×64, frames 0..100,
/// `--trc-max-life 5`, relative RMSE 0.0226 (all triangles) against 0.0232
/// (moving ones) with seed 0 and 0.02256 against 0.02258 with seed 1, with
/// lit-surface errors within 0.1 % in both (0.0255 without the rule).
/// Double-sided triangles count too: their backs are surfaces, but a closed
/// object's inside is dark whatever its material's sidedness (Blender
/// exports every material double-sided, and a growing sphere's records
/// were replaced inside it as black blotches). At worst a record under a
/// thin double-sided moving object is dropped, and `fill` makes a new one
/// where a pixel needs it.
fn back_face_share(ctx: &FrameContext, g: &Gathered) -> f32 {
    let snapshot = ctx.snapshot;
    let is_inside_of_moving = |triangle: u32, dir: Vec3| {
        let t = triangle as usize;
        t >= snapshot.static_count
            && snapshot
                .triangles
                .get(t)
                // The sign alone: the unnormalised normal spares a square
                // root and a division per gather ray.
                .is_some_and(|tri| tri.cross().dot(dir) > 0.0)
    };
    let hits = g.results.iter().map(|r| &r.hit).zip(&g.samples.direction);
    let back = hits
        .filter(|(hit, &dir)| is_inside_of_moving(hit.triangle, dir))
        .count();
    back as f32 / g.results.len().max(1) as f32
}
/// Adds record `r` of the frame to what the store writes of it: a `new`
/// record with its samples' block and last frame; its carried state where
/// it is new or `changed` (radius or used flag).
fn keep_for_store(kept: &mut FrameRecords, r: &TemporalRecord, new: bool, changed: bool) {
    if new {
        kept.records.push(r.record.clone());
        kept.last_frames.push(r.last_valid);
    }
    if new || changed {
        let put = &mut kept.state.as_mut().expect("a temporal frame's state").put;
        put.push((r.record.id, state::encode_record(r)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::cpu::CpuBackend;
    use crate::cache::gather::GatherPoint;
    use crate::method::ic::Candidate;
    use crate::method::unshadowed::UnshadowedLights;
    use crate::render::{FrameSettings, NoMethod, Renderer};
    use crate::scene::Scene;
    use rayon::iter::ParallelIterator;
    use std::collections::HashSet;

    /// A record reprojected to t0+1 and then to a later frame, under a
    /// moving light, keeps the direct light its samples' hits had at t0
    /// from the first reprojection ([`Reprojection`]): the later frame's
    /// samples equal, bit for bit, those of a record reprojected there
    /// alone, and the light's move changes them.
    #[test]
    fn a_record_reprojected_again_finds_what_it_found_alone() {
        let mut settings = TrcSettings::default();
        settings.ic.strata = crate::cache::gather::Strata { theta: 6, phi: 18 };
        let strata = settings.ic.strata;
        let trc = TemporalRadianceCaching::new(settings);
        let mut renderer = crate::render::test_renderer("moving-light", 8);
        renderer.with_frame_context(0, |ctx| {
            let next = NextFrame::new(ctx, NextDirect::On, &mut direct::ShadowGeometry::default());
            assert!(next.lights_move() && next.evaluates_direct());
            let t = 12;
            let later_snapshot = ctx.scene.snapshot(ctx.time_of(t));
            let motion: Vec<_> = (ctx.snapshot.object_to_world.iter())
                .zip(&later_snapshot.object_to_world)
                .map(|(w0, wt)| estimate::rigid_motion(*w0, *wt))
                .collect();
            let emitters = ctx.scene.emitters_snapshot(ctx.time_of(t));
            let lights = Arc::new(UnshadowedLights::of(&ctx.scene.materials, &emitters));
            let later = next
                .later_lit(ctx, t, (motion, lights), None)
                .expect("lit later frame");
            let up = Vec3::Y;
            let point = GatherPoint {
                position: Vec3::new(0.4, 0.0, 0.6),
                normal: up,
                geometric_normal: up,
            };
            let g: Vec<Gathered> = trc
                .ic
                .gather_parallel(ctx, &[Candidate::at(point)])
                .collect();
            let again = Reprojection::new(&g[0], strata);
            again.to(ctx, &next);
            let (kept, alone) = (
                again.to(ctx, &later),
                Reprojection::new(&g[0], strata).to(ctx, &later),
            );
            assert_eq!(kept.radiance, alone.radiance);
            assert_eq!(kept.distance, alone.distance);
            assert_ne!(alone.radiance, g[0].samples.radiance);
        });
    }

    /// Replacing records in batches, each batch's kept paths let go before
    /// the next ([`TemporalRadianceCaching::replace`]), changes no record
    /// and no frame: a run replacing one record at a time equals, bit for
    /// bit, one replacing all of a frame's at once, over waves of
    /// replacements (`δt_max` = 3) that take paths kept by the records
    /// they replace, and re-shoots the same samples.
    #[test]
    fn replacing_in_batches_changes_no_record() {
        let run = |batch: usize| {
            let mut settings = TrcSettings {
                max_life: 3,
                ..TrcSettings::default()
            };
            settings.ic.strata = crate::cache::gather::Strata { theta: 4, phi: 12 };
            settings.ic.spp = 1;
            let mut trc = TemporalRadianceCaching::new(settings);
            trc.replace_batch = batch;
            let mut renderer = crate::render::test_renderer("cube-in-box", 16);
            let (mut frames, mut records, mut reshot, mut replaced) = (vec![], vec![], 0, 0);
            for f in 0..8 {
                frames.push(renderer.with_frame_context(f, |ctx| trc.render_frame(ctx)));
                let stats = trc.last_frame_stats();
                reshot += stats.samples_reshot;
                replaced += stats.records_replaced;
                records.extend(
                    trc.records
                        .iter()
                        .map(|r| (r.record.id, r.record.irradiance)),
                );
            }
            (frames, records, reshot, replaced)
        };
        let (one, all) = (run(1), run(usize::MAX));
        let strata = 4 * 12;
        assert!(one.3 > 20, "{} records replaced", one.3);
        assert!(
            all.2 < all.3 * strata,
            "no kept path taken: {} re-shot",
            all.2
        );
        // One record a batch gathers each in a task of its own: the same
        // records keep paths however the gathers split into tasks
        // (`gather_parallel_tracked` hands tracks only to those picked).
        assert_eq!(one.2, all.2, "samples re-shot");
        assert_eq!(one.3, all.3, "records replaced");
        assert_eq!(one.1, all.1, "records");
        assert!(one.0 == all.0, "frames");
    }

    /// With interpolated gradients, every record a frame uses that is
    /// replaced within the range knows its successor when the frame is
    /// rendered: without it the record falls back to extrapolated
    /// gradients and its light jumps in the frame the successor appears,
    /// the discontinuity Eq. 18–20 are there to remove. In a scene at rest
    /// every record lives `δt_max` frames and is replaced, so frame 0's
    /// records are replaced at the first pass's farthest reach, `δt_max`.
    #[test]
    fn records_rendered_with_interpolated_gradients_know_their_successors() {
        let mut scene = Scene::builtin("cube-in-box").unwrap();
        scene.animation.channels.clear();
        let mut settings = TrcSettings {
            gradients: TemporalGradients::Interpolated,
            max_life: 3,
            ..TrcSettings::default()
        };
        settings.ic.strata = crate::cache::gather::Strata { theta: 4, phi: 12 };
        settings.ic.spp = 1;
        let mut trc = TemporalRadianceCaching::new(settings);
        let mut renderer = Renderer::new(
            scene,
            Box::new(NoMethod),
            Box::new(CpuBackend::new()),
            FrameSettings {
                width: 16,
                height: 16,
                ..FrameSettings::default()
            },
        );
        let end = 8;
        let mut replaced = HashSet::new();
        // (frame, record) rendered without its successor.
        let mut without = Vec::new();
        for frame in 0..end {
            while let Some(f) = trc.next_frame_to_prepare(frame, end) {
                renderer.with_frame_context(f, |ctx| trc.prepare_frame(ctx));
                replaced.extend(trc.records.iter().filter_map(|r| r.replaces));
            }
            let p = trc.pending.front().expect("frame prepared");
            assert_eq!(p.frame, frame);
            let ids = p.records.iter().map(|r| r.record.id);
            without.extend(
                ids.filter(|id| !trc.successors.contains_key(id))
                    .map(|id| (frame, id)),
            );
            renderer.with_frame_context(frame, |ctx| trc.render_frame(ctx));
        }
        assert!(replaced.len() > 50, "{} records replaced", replaced.len());
        let missing: Vec<_> = without
            .iter()
            .filter(|(_, id)| replaced.contains(id))
            .collect();
        assert!(
            missing.is_empty(),
            "{} (frame, record) rendered before their replacement was known: {:?}",
            missing.len(),
            &missing[..missing.len().min(5)]
        );
    }
}
