//! Rendering methods. Each one is a module behind the [`Method`] trait, with
//! its settings in one struct whose defaults come from its paper. Methods see
//! the scene only through a [`FrameContext`] and trace rays only through the
//! batched [`RayBackend`] interface.

mod arrivals;
mod carried;
pub mod ic;
mod lookups;
pub mod motion;
pub mod movies;
pub mod path;
pub mod pixels;
pub mod render_pass;
pub mod settings;
pub mod tcg;
pub mod trc;
mod unshadowed;

use crate::backend::RayBackend;
use crate::film::Film;
use crate::integrator::RayOffset;
use crate::light::LightSampler;
use crate::sampling::SampleKey;
use crate::scene::{Scene, Snapshot};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

/// Everything a method may read while rendering one frame.
pub struct FrameContext<'a> {
    pub scene: &'a Scene,
    pub snapshot: &'a Snapshot,
    pub lights: &'a LightSampler,
    pub backend: &'a dyn RayBackend,
    pub frame: u32,
    /// Frames per second: frame `f` is at time `f / fps` (temporal methods
    /// look one frame ahead).
    pub fps: f32,
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    /// Use the same random sequence in every frame (reference renders for
    /// the flicker figure, DESIGN.md "Measuring").
    pub same_pattern: bool,
    /// Coverage-only camera rays of a pixel on the edge of a seen light, in
    /// units of the method's `spp` ([`pixels`]).
    pub edge_coverage_factor: u32,
    /// The emitting triangles that may show on the film this frame
    /// ([`pixels::emitters_in_view`]).
    pub emitters_in_view: Vec<u32>,
    /// Set from another thread to abandon the frame in progress
    /// ([`crate::render::Renderer::abandon_flag`]).
    pub abandon: &'a AtomicBool,
    /// Set when the render stopped after an earlier frame while this one
    /// was in progress (that frame's write failed, or its caller said to
    /// stop): this frame would be thrown away too.
    pub render_stopped: &'a AtomicBool,
    /// How far rays leaving a surface start off it, for this scene's size.
    pub ray_offset: RayOffset,
    /// Where a method that made the snapshot of the next frame's time
    /// (`Scene::snapshot_from` of this frame's, unchanged) may leave it:
    /// the renderer takes it as that frame's instead of placing the moving
    /// triangles again (`trc` makes it for its estimate of t0+1).
    pub next_snapshot: &'a OnceLock<Snapshot>,
}

impl FrameContext<'_> {
    /// The sampling key of pixel sample `sample` of pixel `pixel`.
    pub fn pixel_key(&self, pixel: u32, sample: u32) -> SampleKey {
        SampleKey {
            seed: self.seed,
            frame: (!self.same_pattern).then_some(self.frame),
            item: u64::from(pixel),
            sample,
        }
    }

    /// Animation time of frame `frame`.
    pub fn time_of(&self, frame: u32) -> f32 {
        frame as f32 / self.fps
    }

    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// A pixel's size at the film's centre on a plane at distance 1 from
    /// the camera, `2·tan(fov/2)/height` (≈ the angle it spans, in
    /// radians): a pixel seen at distance `t` is about `t` times this wide.
    pub fn pixel_angle(&self) -> f32 {
        2.0 * self.snapshot.camera.tan_half_fov() / self.height as f32
    }

    /// Whether the frame in progress is abandoned: its result will be
    /// thrown away, so the big loops (pixel tiles, path bounces) skip what
    /// is left of their work. One frame of an extreme request (4096² pixels
    /// at 65,536 spp) is days of work; a cancel must not wait for it.
    pub fn abandoned(&self) -> bool {
        self.abandon.load(Ordering::Relaxed) || self.render_stopped.load(Ordering::Relaxed)
    }
}

/// What a method did in one frame (the store and server persist and serve
/// these; `render` prints a summary).
/// Stored whole in the store's `stats` tree (rkyv): a field added here is
/// stored with no other change (a schema change all the same: see
/// `store::schema`).
#[derive(
    Clone,
    Debug,
    Default,
    PartialEq,
    serde::Serialize,
    rkyv::Archive,
    rkyv::Serialize,
    rkyv::Deserialize,
)]
pub struct FrameStats {
    pub frame: u32,
    /// Records in the cache at the end of the frame.
    pub records_alive: u64,
    pub records_created: u64,
    /// Records from earlier frames used again (temporal methods).
    pub records_reused: u64,
    pub records_replaced: u64,
    pub records_dropped: u64,
    /// Cache lookups (shading points that needed cached irradiance).
    pub lookups: u64,
    /// Sum over lookups of the records interpolated (mean = this / lookups).
    pub lookup_records: u64,
    /// Pixel samples whose lookup no record covered, their indirect light
    /// path-traced instead (the name predates per-pixel lookups).
    pub fallback_lookups: u64,
    /// Mean lifespan, in frames, of the records computed in the frame (new
    /// and replacements; `trc`: TRC Eq. 10–11, at most δt_max; `ic`: 1;
    /// 0 when none was computed, and for `tcg`, whose records have no set
    /// life: they live while pixels use them).
    pub mean_lifespan: f64,
    /// Records by lifespan: `[n]` records may be used in `n` frames. `trc`
    /// counts the records computed in the frame, `movies` the texture
    /// movies that ended in it ([`Method::lifespans_counted`]); empty for
    /// the others.
    pub lifespan_histogram: Vec<u64>,
    /// Hemisphere samples traced again for records carried from earlier
    /// frames: `tcg`'s re-shot cells (Tawara et al. §3.2), `trc`'s
    /// replacement gathers (the same rays at the same point as the record
    /// they replace). 0 for methods that gather every record afresh.
    pub samples_reshot: u64,
    /// Bytes the method's cache holds in memory at the end of the frame:
    /// the frame's records with what they keep (sources, samples, temporal
    /// state) and their spatial index, with the pixel samples `trc` and
    /// `tcg` keep for the next frame's render pass, or the open texture
    /// movies and the global pass's solution (`movies`), with the peak of
    /// the working buffers that pass makes each frame beside it (it keeps
    /// its links across frames, and tracing them all again takes about one
    /// and a half times their bytes more: `GlobalPass::working_bytes`). 0
    /// for `path`, which keeps none.
    pub cache_bytes: u64,
    /// Rays traced in the frame (filled in by the renderer).
    pub rays: u64,
    /// Wall time of each phase, in seconds.
    pub phase_seconds: Vec<(String, f64)>,
}

/// The name in [`FrameStats::phase_seconds`] of the render pass, the one
/// `ic`, `trc` and `tcg` share ([`render_pass`]) or `movies`' own:
/// `bench` sets its time apart from the methods' own work on their records.
pub const RENDER_PHASE: &str = "render";

/// The mean of a lifespan histogram (`histogram[n]`: records that live
/// `n` frames, as in [`FrameStats::lifespan_histogram`]); 0 when it counts
/// none.
pub fn mean_lifespan(histogram: &[u64]) -> f64 {
    let records: u64 = histogram.iter().sum();
    let frames: u64 = (0u64..).zip(histogram).map(|(life, n)| life * n).sum();
    if records > 0 {
        frames as f64 / records as f64
    } else {
        0.0
    }
}

/// The revision of method `method`'s algorithm in this build: raised when
/// a change makes other frames or records under the same settings (not for
/// a speed-up that keeps them bit for bit). A store job remembers the
/// revision it started under and is not resumed under another
/// ([`crate::store::Store::begin_job`]): the frames it would add, and the
/// records a temporal method carries, would not match those stored. Jobs
/// stored before revisions were recorded read as revision 1.
pub fn algorithm_revision(method: &str) -> u64 {
    match method {
        // 2: records checked against the later frames of their life
        // (`trc::later`) and a light switched on in the dark seen by the
        // reprojection (2026-11-29). 3: a later change of the lights'
        // power checked where they move (2026-11-29). 4: records' points
        // stepped off the edges where surfaces meet, and gradients finite
        // at hits at distance 0 (`ic::off_the_edge`, 2026-11-29). 5: as
        // every method's next. 6: interpolated gradients' first pass runs
        // through the frame the records are replaced in, so the records
        // it replaces last know their successors; moved normals from the
        // moved triangle (`estimate::moved_normal`), and `next_direct`'s
        // estimate kept from going negative (2026-11-30). 7: as every
        // method's next. 8: under moving lights, a light of more than 48
        // triangles is taken as at most 48 points (`unshadowed::Clusters`,
        // 2026-12-01). 9, 10: as every method's next. 11: an object none
        // of a record's samples hit that comes into their paths ends its
        // life (`later::LaterFrames::arrival_share`, 2026-12-01). 12: so
        // does one they hit whose share of the view grew by more than
        // `a_t` (`method::arrivals`, 2026-12-02). 13: the direct light at
        // t0+1 is evaluated by default at frames after which a light moves
        // (`trc::NextDirect::MovingLights`, 2026-12-02). 14: and at the end
        // of a record's life, and between where it changed by more than
        // `a_t` there (`later::LitFrames`, 2026-12-02). 15: as every
        // method's next. 16: a record that lived one frame is dropped when
        // it expires, not replaced (`TemporalRecord::replaced_when_expired`,
        // 2026-12-06). 17: as `ic`'s 8. 18: extrapolated gradients carry
        // E alone, not the spatial gradients' change, and a record's
        // later frames are checked against what it shows there
        // (2026-12-07). 19: a replacement's estimate follows the change
        // observed over the life of the record it replaces where that is
        // the larger (`TrcSettings::history`, 2026-12-07). 20: the direct
        // light at t0+1 is evaluated by default also where only objects
        // move, at frames whose records live long
        // (`trc::NextDirect::LongLives`, 2026-12-07).
        "trc" => 20,
        // 2: as `trc`'s 4, the records all three gather. 3, 4, 5, 6, 7: as
        // below. 8: the gather paths' roulette survives on their whole
        // throughput, not half of it (`IcSettings::gather_length`,
        // 2026-12-07).
        "ic" => 8,
        // `tcg` 4: samples' ages count past 15 frames (to 1038), so the
        // `2^age` draw tells the oldest apart (2026-11-30). 5: a moving
        // record's samples are tested for stale light from where the
        // record was when they were shot (`tcg::stale`, 2026-11-30). 6: as
        // every method's next. 7: as `trc`'s 8, for the light refresh. 8:
        // as every method's next. 9: as every method's next, and a
        // sample is stale where a directional light turns
        // (`UnshadowedLights::directional_shift`, 2026-12-01). 10: with
        // `arrivals`, a seen object whose share of the view grew counts
        // too (`tcg::arrived`, 2026-12-02). 11: a sample is stale where its
        // light may have changed on any normal (`UnshadowedLights::change_at`),
        // and so are its neighbours across an edge
        // (`tcg::select::with_neighbours`, 2026-12-02). 12: as every
        // method's next. 13: as `ic`'s 8.
        "tcg" => 13,
        // `movies` 3: a kept link that missed everything covers its whole
        // ray, so an object that later moves far into it is seen
        // (`global::LinkReach`, 2026-11-30). 4: as every method's next.
        // 5: the global pass is meshed from the scene at time 0, not at
        // the frame it starts at, so a render resumed while an object
        // scales equals the uninterrupted one (`global::MESHED_AT`). 6: a
        // closed part turned inside out is solved on its outside, a side's
        // shading normal is turned to that side (`sides`, `direct`), and
        // the corners of an object scaled to nothing at time 0 are told
        // apart in its own space (`mesh::PassMesh`, 2026-12-01). 7: as
        // every method's next. 8: as every method's next, and a flat part
        // with nothing straight behind it is solved on the camera's side
        // (`sides::backs_solved`, 2026-12-01). 9: a vertex's links are
        // one multi-jittered set (`GlobalPass::link_ray`, 2026-12-02). 10:
        // the direct light a glossy lobe reflects goes along each link
        // where the lobe points, its indirect light spread with the lobe's
        // hemispherical albedo (`GlobalPass::glossy_direct`,
        // `spread_albedo`, 2026-12-02). 11: the direct light at the hits
        // of links landing in sharp cells (`sharp`, 2026-12-02). 12: a
        // large triangle the camera sees is split into pieces
        // (`pieces`), patches go seven levels down (`patch::MAX_LEVEL`),
        // and rays that meet the sky no longer lift the grid spacing's
        // bound (`global::meshing_size`, 2026-12-02). 13: as every
        // method's next. 14: films past 128 pixels high are meshed at a
        // spacing smaller in proportion to their height
        // (`view::film_share`, 2026-12-05). 15: the bounces the global
        // pass's iteration stops before are added as a geometric series
        // (`global::GeometricTail`, 2026-12-07).
        "movies" => 15,
        // 2 (all methods): rays find the surfaces they meet nearer than
        // 1e-4, which the BVH traversal culled (`accel::NEAR_SHIFT`,
        // 2026-11-30); so `trc` and the render pass keep paths with
        // segments under 1e-3 too. 3 (all methods): rays through an edge
        // two triangles share hit one of them (the watertight triangle
        // test, `accel::ShearedRay`, and widened boxes), and of two hits at
        // the same t the lower triangle id wins on both backends; every
        // hit's t, u and v are computed anew (2026-11-30). 4 (all
        // methods): in a scene under a unit across, rays leave surfaces by
        // 1e-4 of the scene's size rather than of a unit
        // (`integrator::RayOffset`), beyond 16 units a coordinate adds
        // 1e-5 of itself (`integrator::FAR_RAY_OFFSET`), a scene far from
        // the origin is rendered moved to it (`Scene::move_to_origin`),
        // and `movies` sizes its grids by what the camera sees where that
        // is smaller than the scene (`global::meshing_size`, 2026-12-01);
        // other scenes keep their frames. 5 (all methods): directional
        // lights are read and lit by, where files with them rendered as
        // if they had none (2026-12-01). 6 (all methods): a camera ray sees
        // the emitter it meets unless a surface hides it nearer than
        // `SHADOW_EPSILON` of its distance, not one ulp: on a GPU whose t
        // is a few ulps below the CPU's the emitter hid itself
        // (`pixels::short_of_emitter`, 2026-12-04); frames change only
        // where a surface lies that close in front of a seen light.
        _ => 6,
    }
}

/// A rendering method. Methods may keep state from frame to frame (the
/// temporal caches do), so frames are rendered in order through `&mut self`.
pub trait Method: Send {
    /// The name used on the command line (`--method NAME`).
    fn name(&self) -> &'static str;

    /// What the records of its [`FrameStats`] count, as a render's summary
    /// names them: records, or `movies`' texture movies.
    fn cache_unit(&self) -> &'static str {
        "records"
    }

    /// Which of its records [`FrameStats::lifespan_histogram`] counts, as a
    /// render's summary says it: those `computed` in the frame (`trc` sets
    /// a record's life when it makes it), or `movies`' texture movies `that
    /// ended` in it (a movie has no set life; it lasts while it is seen).
    fn lifespans_counted(&self) -> &'static str {
        "computed"
    }

    /// Renders one frame into a linear-radiance image.
    fn render_frame(&mut self, ctx: &FrameContext) -> Film;

    /// Two-pass methods (`trc` with interpolated temporal gradients) run a
    /// first pass over frames ahead of the one they render. Before
    /// rendering `frame`, the renderer calls [`Method::prepare_frame`] on
    /// each frame this returns, as long as it returns one; `end` is the
    /// frame after the last one the renderer will render. One-pass
    /// methods return `None`.
    fn next_frame_to_prepare(&self, _frame: u32, _end: u32) -> Option<u32> {
        None
    }

    /// The first pass over frame `ctx.frame` (see
    /// [`Method::next_frame_to_prepare`]).
    fn prepare_frame(&mut self, _ctx: &FrameContext) {}

    /// Statistics of the last rendered frame (methods without a cache
    /// report only their phases).
    fn last_frame_stats(&self) -> FrameStats {
        FrameStats::default()
    }

    /// Asks the method to keep the records (with their hemisphere samples)
    /// it creates or changes in each frame, for [`Method::take_frame_records`]
    /// (the store persists them). Off unless asked, so that no samples are
    /// held in memory otherwise. Methods without records ignore it.
    fn keep_frame_records(&mut self, _keep: bool) {}

    /// The records created or changed in the last frame, if kept (one
    /// frame's worth: taking them frees them).
    fn take_frame_records(&mut self) -> Option<FrameRecords> {
        None
    }

    /// Whether a frame depends on the frames rendered before it (the
    /// method carries a cache from frame to frame). Such a method reports
    /// its state changes in [`FrameRecords::state`] and a resume restores
    /// them with [`Method::restore_state`]; the others simply skip their
    /// finished frames.
    fn carries_state(&self) -> bool {
        false
    }

    /// Whether a frame depends on the end of the rendered range (a
    /// two-pass method looks ahead no further than it): then a resume must
    /// also keep the range's end.
    fn looks_ahead(&self) -> bool {
        false
    }

    /// Whether the method's state refers to the samples of the records
    /// its frames store rather than holding a copy (`tcg`, which puts every
    /// record's samples in both each frame): a resume then hands it those
    /// of the state's frame in [`MethodState::record_samples`].
    fn state_refers_to_record_samples(&self) -> bool {
        false
    }

    /// Continues from `state`, the state after frame `state.frame` as
    /// the method reported it frame by frame: the next frame rendered is
    /// `state.frame + 1`, exactly as if the frames before had just been
    /// rendered by this instance.
    fn restore_state(&mut self, _state: MethodState) -> Result<(), StateError> {
        Err(StateError {
            record: None,
            detail: format!("method {} keeps no state across frames", self.name()),
        })
    }
}

/// Records a method created or changed in one frame, with their
/// incoming-radiance samples (`samples[i]` belongs to `records[i]`; empty
/// when the method has none for it), and for methods that carry a cache
/// from frame to frame the changes of that cache.
///
/// The samples are in their stored form (8 bytes each, zstd-compressed:
/// [`crate::store::SampleBlock`]), packed by the method as soon as a record
/// is gathered, so that a frame never holds them at 32 bytes each.
#[derive(Clone, Debug, Default)]
pub struct FrameRecords {
    pub records: Vec<crate::cache::IrradianceRecord>,
    pub samples: Vec<crate::store::SampleBlock>,
    /// Strata of the samples (`M × N`, cell `j·N + k` at index `j·N + k`).
    pub strata: crate::cache::gather::Strata,
    /// `last_frames[i]`: the last frame `records[i]` may be used in
    /// (temporal methods; empty: each record lives one frame).
    pub last_frames: Vec<u32>,
    /// The changes of the state carried to the next frame
    /// ([`Method::carries_state`]); `None` for the other methods.
    pub state: Option<StateChanges>,
    /// The texture movies of the frame (`movies`), for the store's
    /// `movies` tree.
    pub movies: Option<crate::store::schema::MovieFramesValue>,
}

/// How a method's carried state changed in one frame: what the store
/// writes, in the frame's atomic batch, so that a render can resume after
/// that frame without rendering the frames before it again. The bytes are
/// the method's own (it validates them in [`Method::restore_state`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StateChanges {
    /// Method-wide state after the frame (e.g. the next record id),
    /// replacing the previous one.
    pub global: Vec<u8>,
    /// Records that entered the state or whose state changed in the frame,
    /// by id, with their whole state.
    pub put: Vec<(crate::cache::RecordId, Vec<u8>)>,
    /// Records that left the state in the frame (dropped, replaced).
    pub removed: Vec<crate::cache::RecordId>,
}

/// A method's whole carried state after frame `frame`: the last
/// [`StateChanges::global`] and the records put and not removed since, in
/// id order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MethodState {
    pub frame: u32,
    pub global: Vec<u8>,
    pub records: Vec<(crate::cache::RecordId, Vec<u8>)>,
    /// The samples of the records frame `frame` stored, by id, for a
    /// method whose state refers to them
    /// ([`Method::state_refers_to_record_samples`]); empty for the others.
    pub record_samples: std::collections::BTreeMap<u64, Vec<crate::store::rgbe::PackedSample>>,
}

/// A state [`Method::restore_state`] cannot continue from.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{detail}")]
pub struct StateError {
    /// The record whose state is bad (`None`: the method-wide state).
    pub record: Option<crate::cache::RecordId>,
    pub detail: String,
}
