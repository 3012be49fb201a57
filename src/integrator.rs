//! Radiance along batches of rays by path tracing: the light-transport engine
//! shared by every method (camera paths of `path`, hemisphere gathering of
//! cache records, glossy continuations).
//!
//! Unidirectional path tracing (Kajiya 1986) with next-event estimation at
//! every vertex, combined with BSDF sampling by multiple importance sampling
//! with the power heuristic (Veach 1997, §9.2), and Russian roulette on the
//! path throughput. It is written as a wavefront so that it only talks to the
//! batched [`RayBackend`](crate::backend::RayBackend): all paths of a batch
//! advance one bounce at a time — trace all extension rays (with the
//! previous bounce's shadow rays), shade, queue the shadow rays.

use crate::backend::{Hit, Ray};
use crate::light::{emitting_cosine, TriangleSampling};
use crate::material::Bsdf;
use crate::method::FrameContext;
use crate::sampling::{power_heuristic, LightChoice, Rng};
use crate::scene::Triangle;
use glam::Vec3;
use rayon::prelude::*;

/// Path-length control shared by every caller.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PathLength {
    /// Hard bounce limit (`None`: unbounded, terminated by Russian roulette
    /// only, as the reference renders are).
    pub max_depth: Option<u32>,
    /// Russian roulette starts after this many bounces (pbrt-v4 starts after
    /// 1; a later start costs time, not accuracy).
    pub rr_start: u32,
    /// Scales the survival probability of Russian roulette
    /// (`q = min(s·max βᵢ, 0.95)`). Below 1 it trades variance of the
    /// deeper bounces for time; the estimate stays unbiased.
    pub survival: f32,
}

impl Default for PathLength {
    fn default() -> Self {
        PathLength {
            max_depth: None,
            rr_start: 3,
            survival: 1.0,
        }
    }
}

/// How the emission of the first surface a query's ray hits is counted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FirstHitEmission {
    /// Fully (camera rays).
    Include,
    /// Not at all: the caller accounts for direct light separately (the
    /// hemisphere gathering of indirect-light records).
    Exclude,
    /// MIS-weighted against next-event estimation at the ray's origin, for a
    /// ray drawn by BSDF sampling with this solid-angle pdf; `light` is how
    /// that estimate drew its points on emitting triangles.
    Mis {
        bsdf_pdf: f32,
        light: TriangleSampling,
    },
}

/// One radiance estimate to compute: the radiance arriving at `ray.origin`
/// from direction `ray.dir`, times `weight`.
#[derive(Clone, Debug)]
pub struct RadianceQuery {
    pub ray: Ray,
    /// The light sample at the first hit (stratified by the caller); `None`
    /// draws it from `rng`.
    pub first_light: Option<LightChoice>,
    pub rng: Rng,
    pub weight: Vec3,
    pub first_hit: FirstHitEmission,
}

/// The estimate of a query and the first hit of its ray.
#[derive(Clone, Copy, Debug)]
pub struct RadianceResult {
    pub radiance: Vec3,
    pub hit: Hit,
}

/// Relative offset of secondary ray origins along the geometric normal,
/// against self-intersection: of the hit point's largest coordinate (up
/// to [`NEAR_COORDINATES`] floors) and of [`RayOffset`]'s floor.
pub const RAY_OFFSET: f32 = 1e-4;

/// The offset's share of a coordinate's part beyond [`NEAR_COORDINATES`]
/// floors: still some 170 times the spacing of 32-bit floats there.
///
/// Why not [`RAY_OFFSET`] all the way: 1,700 times that spacing, it grew
/// past what the rounding of a hit needs and into the scene's detail
/// where the coordinates are large. A room 1.3 km from the origin, at the
/// edge of a 2 km ground (`l_hall` moved there by `benches/scenes/place.py
/// ... ground 1000 950`, `path` at 64 spp), had a block bias of 3.5 %
/// against its frames at the origin, light through its corners and
/// contact shadows gone, with offsets of 0.1 units; 0.35 % with this share (`tests/scene_scale.rs`).
pub const FAR_RAY_OFFSET: f32 = 1e-5;

/// How far from the origin, in floors, coordinates take [`RAY_OFFSET`] of
/// themselves: the scenes every measurement here was made in (rooms a few
/// units across around the origin) keep their offsets, and their frames.
pub const NEAR_COORDINATES: f32 = 16.0;

/// How far rays leaving a surface start off it in one frame:
/// [`RAY_OFFSET`] of the point's largest coordinate and of a floor, the
/// size of the scene and its camera up to one unit.
///
/// Why a floor: a hit point `o + t·d` is rounded at the scale of its ray's
/// origin and length as well as of its own coordinates, which near the
/// world's origin bound neither. Why the scene's size: a floor of one unit
/// is ample in metres but a percent of a scene a few millimetres across,
/// where light leaked and contact shadows thinned (`l_hall` scaled to
/// 9 mm by `benches/scenes/place.py ... scale 0.001`: `path` at 64 spp
/// has a block bias of 3.7 % against its frames in metres, 0.04 % with
/// this floor). Scaled with a scene under a unit, the offset is the
/// same share of it at any size (`tests/scene_scale.rs`); a scene of a
/// unit or more keeps the floor of one unit, and its frames their bits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayOffset {
    floor: f32,
}

impl RayOffset {
    /// The offset of a scene a unit across or more.
    pub const UNIT_FLOOR: RayOffset = RayOffset { floor: 1.0 };

    /// The offset of a scene whose geometry and camera span `extent` units
    /// (the diagonal of their box): one without geometry, or beyond what
    /// can be measured, takes [`Self::UNIT_FLOOR`].
    pub fn for_extent(extent: f32) -> RayOffset {
        if extent > 0.0 && extent < 1.0 {
            RayOffset { floor: extent }
        } else {
            Self::UNIT_FLOOR
        }
    }

    /// The offset of a frame whose scene's vertices lie in `bounds` and
    /// whose camera is at `camera`: a first hit is rounded at the scale of
    /// the camera's distance as well.
    pub fn around(bounds: Option<(Vec3, Vec3)>, camera: Vec3) -> RayOffset {
        bounds.map_or(Self::UNIT_FLOOR, |(lo, hi)| {
            Self::for_extent((hi.max(camera) - lo.min(camera)).length())
        })
    }

    /// How far a ray leaving `p` starts off its surface.
    #[inline]
    pub fn distance(self, p: Vec3) -> f32 {
        let (m, near) = (p.abs().max_element(), NEAR_COORDINATES * self.floor);
        if m <= near {
            RAY_OFFSET * (self.floor + m)
        } else {
            RAY_OFFSET * (self.floor + near) + FAR_RAY_OFFSET * (m - near)
        }
    }

    /// Origin for a ray leaving surface point `p` (geometric normal `ng`)
    /// towards `w`: pushed off the surface on the side `w` goes to.
    #[inline]
    pub fn origin(self, p: Vec3, ng: Vec3, w: Vec3) -> Vec3 {
        let offset = self.distance(p);
        if ng.dot(w) >= 0.0 {
            p + ng * offset
        } else {
            p - ng * offset
        }
    }
}

/// State of one path between bounces (its radiance so far is summed in
/// its query's result).
struct PathState<'a> {
    query: usize,
    /// What the path traced before ([`Replay`]; empty: nothing).
    replay: Replay<'a>,
    first_light: Option<LightChoice>,
    rng: Rng,
    throughput: Vec3,
    bounces: u32,
    emission: FirstHitEmission,
}

/// The shadow rays of one bounce's light samples, waiting to be traced,
/// and for each the query it adds to if unoccluded and what it adds.
#[derive(Default)]
struct PendingShadows {
    rays: Vec<Ray>,
    targets: Vec<(usize, Vec3)>,
    occluded: Vec<bool>,
}

impl PendingShadows {
    fn push(&mut self, ray: Ray, query: usize, contribution: Vec3) {
        self.rays.push(ray);
        self.targets.push((query, contribution));
    }

    /// Sizes `occluded` for the rays queued, for the backend to fill.
    fn prepare(&mut self) {
        self.occluded.clear();
        self.occluded.resize(self.rays.len(), false);
    }

    /// Tells `sink` the shadow rays queued, with their queries.
    fn tell(&self, sink: &mut impl SegmentSink) {
        for (ray, &(query, _)) in self.rays.iter().zip(&self.targets) {
            sink.shadow(query, ray);
        }
    }

    /// Adds the unoccluded contributions (`occluded` filled by the backend)
    /// to their queries' radiance and empties the queue.
    fn resolve(&mut self, results: &mut [RadianceResult]) {
        for (&(query, contribution), &blocked) in self.targets.iter().zip(&self.occluded) {
            if !blocked {
                results[query].radiance += contribution;
            }
        }
        self.rays.clear();
        self.targets.clear();
    }
}

/// Where a batch's paths went, path by path: the segments each traced
/// (each extension ray to its hit, or far past the scene where it left
/// it, and each shadow ray to its light), and whether it hit a triangle of
/// a moving object. A path that no moving object met, whose segments no
/// moving object meets in a later frame either, gives that frame, from the
/// same random stream, the very same radiance (the lights staying): `trc`
/// takes it instead of tracing it again (`method::trc`'s kept paths).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PathTracks {
    /// Path `i`'s segments are `segments[ends[i - 1]..ends[i]]`.
    ends: Vec<u32>,
    segments: Vec<[Vec3; 2]>,
    /// Path `i`'s extension rays, each with its hit, are
    /// `extensions[extension_ends[i - 1]..extension_ends[i]]`.
    extension_ends: Vec<u32>,
    extensions: Vec<(Ray, Hit)>,
    hit_moving: Vec<bool>,
}

impl PathTracks {
    pub fn len(&self) -> usize {
        self.ends.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }

    /// Path `i`'s segments.
    pub fn segments(&self, i: usize) -> &[[Vec3; 2]] {
        &self.segments[span(&self.ends, i).expect("a path of the batch")]
    }

    /// Path `i`'s extension rays with their hits, bounce by bounce: what a
    /// later trace of the path may take ([`Replay`]); none where they were
    /// not asked for ([`trace_radiance_tracked`]).
    pub fn extensions(&self, i: usize) -> &[(Ray, Hit)] {
        &self.extensions[span(&self.extension_ends, i).expect("a path of the batch")]
    }

    /// Whether path `i` hit a triangle of a moving object.
    pub fn hit_moving(&self, i: usize) -> bool {
        self.hit_moving[i]
    }

    /// Appends `other`'s paths after these.
    fn append(&mut self, other: PathTracks) {
        let base = self.segments.len() as u32;
        self.ends.extend(other.ends.into_iter().map(|e| e + base));
        self.segments.extend(other.segments);
        let base = self.extensions.len() as u32;
        (self.extension_ends).extend(other.extension_ends.into_iter().map(|e| e + base));
        self.extensions.extend(other.extensions);
        self.hit_moving.extend(other.hit_moving);
    }
}

/// Item `i`'s range in a list whose items' ends are `ends` (`None`: there
/// is no item `i`).
pub(crate) fn span(ends: &[u32], i: usize) -> Option<std::ops::Range<usize>> {
    let end = *ends.get(i)? as usize;
    let start = if i == 0 { 0 } else { ends[i - 1] as usize };
    Some(start..end)
}

/// The extension rays a path traced before, each with its hit, bounce by
/// bounce (empty: none). Where the path traces the very same ray again (to
/// the bit: the same random stream from the same point), it takes that hit
/// instead of tracing the ray; the shadow rays of its light samples are
/// traced, in the lights of the frame. The caller vouches that the
/// geometry along those rays is the same ([`crate::method::motion::Blockers`]:
/// no moving object's box meets them, and the path hit no moving object).
/// The hit is then the one tracing would find (the nearest, ties to the
/// lower triangle id, in any BVH), and the path's radiance the same bits.
pub type Replay<'a> = &'a [(Ray, Hit)];

/// What is known of a query's path from an earlier trace.
#[derive(Clone, Copy, Debug)]
pub enum KnownPath<'a> {
    /// Its result: nothing it met, nor the lights, changed.
    Result(RadianceResult),
    /// Its extension rays' hits: the lights changed.
    Hits(Replay<'a>),
}

/// The segment an extension ray traced to `hit`, or far past the scene
/// where it left it: what a moving object's box must not meet for the
/// ray to find the same hit in another frame.
pub fn extension_segment(ray: &Ray, hit: &Hit) -> [Vec3; 2] {
    let end = if hit.is_hit() {
        ray.at(hit.t)
    } else {
        ray.origin() + ray.dir() * (ESCAPE_DISTANCE / ray.dir().length().max(1e-30))
    };
    [ray.origin(), end]
}

/// How far past its origin a ray that hit nothing is followed when its
/// segment is tested against moving boxes.
const ESCAPE_DISTANCE: f32 = 1e6;

/// Receives the segments paths trace (nothing, for callers that do not
/// keep them).
trait SegmentSink {
    fn extension(&mut self, query: usize, ray: &Ray, hit: &Hit);
    fn shadow(&mut self, query: usize, ray: &Ray);
}

impl SegmentSink for () {
    #[inline]
    fn extension(&mut self, _: usize, _: &Ray, _: &Hit) {}
    #[inline]
    fn shadow(&mut self, _: usize, _: &Ray) {}
}

/// The segments of a batch's paths as they are traced (bounce by bounce,
/// all paths interleaved), to be sorted into [`PathTracks`].
struct TrackSink {
    traced: Vec<(u32, [Vec3; 2])>,
    /// The extension rays with their hits, where they are asked for
    /// (`None`: the caller keeps segments alone).
    extensions: Option<Vec<(u32, (Ray, Hit))>>,
    hit_moving: Vec<bool>,
    /// Triangles at or past this index belong to moving objects.
    static_count: usize,
}

impl SegmentSink for TrackSink {
    fn extension(&mut self, query: usize, ray: &Ray, hit: &Hit) {
        self.traced
            .push((query as u32, extension_segment(ray, hit)));
        if let Some(extensions) = &mut self.extensions {
            extensions.push((query as u32, (*ray, *hit)));
        }
        self.hit_moving[query] |= hit.is_hit() && hit.triangle as usize >= self.static_count;
    }

    fn shadow(&mut self, query: usize, ray: &Ray) {
        // A shadow ray is a segment `origin → origin + dir`.
        self.traced
            .push((query as u32, [ray.origin(), ray.origin() + ray.dir()]));
    }
}

impl TrackSink {
    fn new(queries: usize, static_count: usize, hits: bool) -> Self {
        TrackSink {
            traced: Vec::with_capacity(queries * 6),
            extensions: hits.then(|| Vec::with_capacity(queries * 2)),
            hit_moving: vec![false; queries],
            static_count,
        }
    }

    /// The segments and extension rays path by path, each path's in the
    /// order traced.
    fn into_tracks(self) -> PathTracks {
        let n = self.hit_moving.len();
        let (ends, segments) = by_path(n, self.traced, [Vec3::ZERO; 2]);
        let blank = (Ray::new(Vec3::ZERO, Vec3::ZERO, 0.0, 0.0), Hit::MISS);
        let (extension_ends, extensions) = by_path(n, self.extensions.unwrap_or_default(), blank);
        PathTracks {
            ends,
            segments,
            extension_ends,
            extensions,
            hit_moving: self.hit_moving,
        }
    }
}

/// `items` of `paths` paths, each tagged with its path, sorted by path
/// (each path's in the order given), with each path's end; `blank` fills
/// the slots before they are.
fn by_path<T: Copy>(paths: usize, items: Vec<(u32, T)>, blank: T) -> (Vec<u32>, Vec<T>) {
    let mut ends = vec![0u32; paths];
    for &(q, _) in &items {
        ends[q as usize] += 1;
    }
    let mut next = Vec::with_capacity(paths);
    let mut total = 0;
    for e in ends.iter_mut() {
        next.push(total);
        total += *e;
        *e = total;
    }
    let mut sorted = vec![blank; total as usize];
    for (q, item) in items {
        let slot = &mut next[q as usize];
        sorted[*slot as usize] = item;
        *slot += 1;
    }
    (ends, sorted)
}

/// [`trace_radiance_parallel`], also returning where each query's path
/// went.
pub fn trace_radiance_tracked(
    ctx: &FrameContext,
    length: PathLength,
    queries: Vec<RadianceQuery>,
) -> (Vec<RadianceResult>, PathTracks) {
    trace_paths(ctx, length, queries, &[], Tracking::Segments)
}

/// [`trace_radiance_parallel`] where each query's path may take the hits
/// of `replays` (one per query, or none at all: [`Replay`]), also
/// returning, with `track`, where each path went, its extension rays'
/// hits included (else no tracks).
pub fn trace_radiance_replayed(
    ctx: &FrameContext,
    length: PathLength,
    queries: Vec<RadianceQuery>,
    replays: &[Replay],
    track: bool,
) -> (Vec<RadianceResult>, PathTracks) {
    let tracking = match track {
        true => Tracking::WithHits,
        false => Tracking::Off,
    };
    trace_paths(ctx, length, queries, replays, tracking)
}

/// What [`trace_paths`] records of where the paths went.
#[derive(Clone, Copy, PartialEq)]
enum Tracking {
    Off,
    /// Their segments ([`PathTracks::segments`]).
    Segments,
    /// Their segments and their extension rays' hits
    /// ([`PathTracks::extensions`]).
    WithHits,
}

/// [`trace_radiance_replayed`], recording what `tracking` asks for.
fn trace_paths(
    ctx: &FrameContext,
    length: PathLength,
    queries: Vec<RadianceQuery>,
    replays: &[Replay],
    tracking: Tracking,
) -> (Vec<RadianceResult>, PathTracks) {
    let n = queries.len();
    assert!(
        replays.is_empty() || replays.len() == n,
        "one replay per query"
    );
    let per_task = QUERIES_PER_TASK.max(ctx.backend.min_batch());
    let traced: Vec<(Vec<RadianceResult>, PathTracks)> = queries
        .into_par_iter()
        .enumerate()
        .chunks(per_task)
        .map(|chunk| {
            let first = chunk.first().map_or(0, |&(i, _)| i);
            let queries: Vec<RadianceQuery> = chunk.into_iter().map(|(_, q)| q).collect();
            let replays = replays.get(first..first + queries.len()).unwrap_or(&[]);
            if tracking == Tracking::Off {
                let results = trace_radiance_into(ctx, length, queries, replays, &mut ());
                return (results, PathTracks::default());
            }
            let hits = tracking == Tracking::WithHits;
            let mut sink = TrackSink::new(queries.len(), ctx.snapshot.static_count, hits);
            let results = trace_radiance_into(ctx, length, queries, replays, &mut sink);
            (results, sink.into_tracks())
        })
        .collect();
    let mut results = Vec::with_capacity(n);
    let mut tracks = PathTracks::default();
    for (r, t) in traced {
        results.extend(r);
        tracks.append(t);
    }
    (results, tracks)
}

/// [`trace_radiance`] split over the thread pool, `QUERIES_PER_TASK`
/// queries a task, or the backend's [`crate::backend::RayBackend::min_batch`] where that
/// is more: the same results, since each query carries its own random
/// stream. For batches a single task would otherwise shade alone while
/// the other threads wait — `trc` gathers a handful of records a frame,
/// and one record is 768 queries. On a GPU, tasks of `QUERIES_PER_TASK`
/// made each path bounce a dispatch of at most 256 rays, whose fixed cost
/// dwarfed their tracing.
pub fn trace_radiance_parallel(
    ctx: &FrameContext,
    length: PathLength,
    queries: Vec<RadianceQuery>,
) -> Vec<RadianceResult> {
    let per_task = QUERIES_PER_TASK.max(ctx.backend.min_batch());
    if queries.len() <= per_task {
        return trace_radiance(ctx, length, queries);
    }
    queries
        .par_chunks(per_task)
        .flat_map_iter(|chunk| trace_radiance(ctx, length, chunk.to_vec()))
        .collect()
}

/// Queries per task of [`trace_radiance_parallel`]: enough that a task's
/// ray batches still amortise the backend's per-batch cost.
const QUERIES_PER_TASK: usize = 256;

/// Computes every query of the batch on the calling thread (the backend may
/// parallelise each ray batch). Results are in query order and depend only
/// on the queries, so they are reproducible.
///
/// Bounce k's shadow rays are traced with bounce k + 1's extension rays,
/// in one backend call ([`crate::backend::RayBackend::closest_and_any_hit`]):
/// a GPU pays a path's round trips once a bounce, not twice. The radiance
/// of a query is summed in the same order as bounce by bounce (bounce k's
/// light sample before bounce k + 1's emission), so the results are those
/// of tracing each bounce's shadows before the next bounce.
pub fn trace_radiance(
    ctx: &FrameContext,
    length: PathLength,
    queries: Vec<RadianceQuery>,
) -> Vec<RadianceResult> {
    trace_radiance_into(ctx, length, queries, &[], &mut ())
}

/// [`trace_radiance`], each query's path taking the hits of its replay
/// (`replays`: one per query, or none at all), telling `sink` every
/// segment traced.
fn trace_radiance_into(
    ctx: &FrameContext,
    length: PathLength,
    queries: Vec<RadianceQuery>,
    replays: &[Replay],
    sink: &mut impl SegmentSink,
) -> Vec<RadianceResult> {
    let mut results = vec![
        RadianceResult {
            radiance: Vec3::ZERO,
            hit: Hit::MISS,
        };
        queries.len()
    ];
    let mut rays = Vec::with_capacity(queries.len());
    let mut paths = Vec::with_capacity(queries.len());
    for (i, q) in queries.into_iter().enumerate() {
        rays.push(q.ray);
        paths.push(PathState {
            query: i,
            replay: replays.get(i).copied().unwrap_or(&[]),
            first_light: q.first_light,
            rng: q.rng,
            throughput: q.weight,
            bounces: 0,
            emission: q.first_hit,
        });
    }
    let mut hits = Vec::new();
    let mut continuations = Vec::with_capacity(paths.len());
    let mut shadows = PendingShadows::default();
    let mut untaken = Untaken::default();
    // An abandoned frame's paths end at the next bounce: their results are
    // thrown away.
    while !paths.is_empty() && !ctx.abandoned() {
        untaken.trace(ctx, &paths, &rays, &mut hits, &mut shadows);
        shadows.tell(sink);
        shadows.resolve(&mut results);
        continuations.clear();
        for (path, (ray, hit)) in paths.iter_mut().zip(rays.iter().zip(&hits)) {
            sink.extension(path.query, ray, hit);
            if path.bounces == 0 {
                results[path.query].hit = *hit;
            }
            let radiance = &mut results[path.query].radiance;
            let next = shade(ctx, length, path, ray, hit, radiance, &mut shadows);
            continuations.push(next);
        }
        // Compact in place (`retain` visits the paths once, in order):
        // continuing paths and their rays stay, the others are done.
        rays.clear();
        let mut next = continuations.iter();
        paths.retain(|_| match next.next() {
            Some(&Some(ray)) => {
                rays.push(ray);
                true
            }
            _ => false,
        });
    }
    // The last bounce's light samples.
    shadows.prepare();
    ctx.backend.any_hit(&shadows.rays, &mut shadows.occluded);
    shadows.tell(sink);
    shadows.resolve(&mut results);
    results
}

/// The extension rays of a bounce that no path's [`Replay`] gives a hit
/// for, traced together.
#[derive(Default)]
struct Untaken {
    taken: Vec<bool>,
    rays: Vec<Ray>,
    hits: Vec<Hit>,
}

impl Untaken {
    /// Fills `hits` for `rays` (one per path of `paths`): a path's replay
    /// gives the hit of the ray it traced before at this bounce, where
    /// the ray is the same to the bit; the others are traced, with the
    /// shadow rays queued in `shadows`.
    fn trace(
        &mut self,
        ctx: &FrameContext,
        paths: &[PathState],
        rays: &[Ray],
        hits: &mut Vec<Hit>,
        shadows: &mut PendingShadows,
    ) {
        hits.clear();
        hits.resize(rays.len(), Hit::MISS);
        shadows.prepare();
        self.taken.clear();
        for ((path, ray), hit) in paths.iter().zip(rays).zip(hits.iter_mut()) {
            let replayed = path.replay.get(path.bounces as usize);
            let same = replayed.filter(|(before, _)| same_ray(before, ray));
            if let Some(&(_, before)) = same {
                *hit = before;
            }
            self.taken.push(same.is_some());
        }
        if !self.taken.contains(&true) {
            ctx.backend
                .closest_and_any_hit(rays, hits, &shadows.rays, &mut shadows.occluded);
            return;
        }
        self.rays.clear();
        let untaken = rays.iter().zip(&self.taken).filter(|(_, &taken)| !taken);
        self.rays.extend(untaken.map(|(ray, _)| *ray));
        self.hits.clear();
        self.hits.resize(self.rays.len(), Hit::MISS);
        ctx.backend.closest_and_any_hit(
            &self.rays,
            &mut self.hits,
            &shadows.rays,
            &mut shadows.occluded,
        );
        let mut traced = self.hits.iter();
        for (hit, _) in hits
            .iter_mut()
            .zip(&self.taken)
            .filter(|(_, &taken)| !taken)
        {
            *hit = *traced.next().expect("one hit per ray traced");
        }
    }
}

/// Whether two rays are the same to the bit.
fn same_ray(a: &Ray, b: &Ray) -> bool {
    let bits = |r: &Ray| {
        let [x, y, z] = r.origin.map(f32::to_bits);
        let [u, v, w] = r.dir.map(f32::to_bits);
        [x, y, z, u, v, w, r.tmin.to_bits(), r.tmax.to_bits()]
    };
    bits(a) == bits(b)
}

/// Emission seen along `ray` at `hit` on `tri`, weighted as `mode` says.
fn emission_weight(
    ctx: &FrameContext,
    mode: FirstHitEmission,
    tri: &Triangle,
    triangle: u32,
    ray: &Ray,
    p: Vec3,
) -> f32 {
    match mode {
        FirstHitEmission::Include => 1.0,
        FirstHitEmission::Exclude => 0.0,
        FirstHitEmission::Mis { bsdf_pdf, light } => {
            let light_pdf = ctx
                .lights
                .pdf_triangle(tri, triangle, ray.origin(), p, light);
            power_heuristic(bsdf_pdf, light_pdf)
        }
    }
}

/// Shades the hit of `path`: adds emission to the query's `radiance`,
/// queues a light sample in `shadows` and draws the continuation. Returns the next ray, or `None` when
/// the path ends.
fn shade(
    ctx: &FrameContext,
    length: PathLength,
    path: &mut PathState,
    ray: &Ray,
    hit: &Hit,
    radiance: &mut Vec3,
    shadows: &mut PendingShadows,
) -> Option<Ray> {
    if !hit.is_hit() {
        return None; // Closed scenes: nothing beyond (black background).
    }
    let snapshot = ctx.snapshot;
    let tri = &snapshot.triangles[hit.triangle as usize];
    let material = &ctx.scene.materials[snapshot.tri_material[hit.triangle as usize] as usize];
    let wo = -ray.dir().normalize();
    let p = ray.at(hit.t);

    if material.is_emissive() && emitting_cosine(tri, material.double_sided, wo).is_some() {
        let weight = emission_weight(ctx, path.emission, tri, hit.triangle, ray, p);
        *radiance += path.throughput * material.emission * weight;
    }
    if length.max_depth.is_some_and(|max| path.bounces >= max) {
        return None;
    }
    let bsdf = Bsdf::new(material, tri.shading_normal(hit.u, hit.v), wo);
    if bsdf.is_black() {
        return None;
    }
    let vertex = Vertex {
        p,
        ng: tri.geometric_normal(),
        wo,
        bsdf,
    };
    let sampling = next_event(ctx, path, &vertex, shadows);
    continue_path(length, ctx.ray_offset, path, &vertex, sampling)
}

/// A path vertex on a surface that scatters light.
struct Vertex {
    p: Vec3,
    ng: Vec3,
    wo: Vec3,
    bsdf: Bsdf,
}

/// Next-event estimation at `v`, MIS-weighted against BSDF sampling: queues
/// the light sample's shadow ray in `shadows`. The stratified light
/// sample of a pixel's first hit is seen directly: it gets the costlier,
/// less noisy points (`TriangleSampling`). Returns how the light sample's
/// points on emitting triangles were drawn, which the BSDF-sampled
/// continuation's MIS weight needs.
fn next_event(
    ctx: &FrameContext,
    path: &mut PathState,
    v: &Vertex,
    shadows: &mut PendingShadows,
) -> TriangleSampling {
    let (pick, u) = (path.rng.next_f32(), path.rng.next_2d());
    let (choice, sampling) = match path.first_light.take() {
        Some(choice) => (choice, TriangleSampling::SolidAngle),
        None => (LightChoice { pick, u }, TriangleSampling::Area),
    };
    let Some(ls) = ctx.lights.sample(ctx.snapshot, v.p, choice, sampling) else {
        return sampling;
    };
    let f = v.bsdf.eval(v.wo, ls.wi);
    let cos = v.bsdf.normal().dot(ls.wi);
    if cos > 0.0 && f.max_element() > 0.0 {
        let weight = if ls.is_delta {
            1.0
        } else {
            power_heuristic(ls.pdf, v.bsdf.pdf(v.wo, ls.wi))
        };
        let contribution = path.throughput * f * ls.radiance * (cos * weight / ls.pdf);
        shadows.push(
            Ray::segment(ctx.ray_offset.origin(v.p, v.ng, ls.wi), ls.position),
            path.query,
            contribution,
        );
    }
    sampling
}

/// Continues the path from `v` by BSDF sampling, with Russian roulette
/// after `length.rr_start` bounces; `sampling` is how [`next_event`] drew
/// its light points here, for the MIS weight of an emitter the new ray
/// hits. Returns the new ray, or `None` when the path ends.
fn continue_path(
    length: PathLength,
    offset: RayOffset,
    path: &mut PathState,
    v: &Vertex,
    sampling: TriangleSampling,
) -> Option<Ray> {
    let (pick, u) = (path.rng.next_f32(), path.rng.next_2d());
    let s = v.bsdf.sample(v.wo, pick, u)?;
    let cos = v.bsdf.normal().dot(s.wi);
    path.throughput *= s.f * (cos / s.pdf);
    path.emission = FirstHitEmission::Mis {
        bsdf_pdf: s.pdf,
        light: sampling,
    };
    path.bounces += 1;
    if path.bounces > length.rr_start {
        // Survive with probability q = min(s·max βᵢ, 0.95), reweight by 1/q.
        let q = (length.survival * path.throughput.max_element()).min(0.95);
        if path.rng.next_f32() >= q {
            return None;
        }
        path.throughput /= q;
    }
    Some(Ray::new(
        offset.origin(v.p, v.ng, s.wi),
        s.wi,
        0.0,
        f32::INFINITY,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor is the scene's size under a unit (the camera's place
    /// counted in), a unit from there up, and a unit where no size can be
    /// measured; a floor of a unit is the offset of the first renders.
    #[test]
    fn the_ray_offset_floor_is_the_scene_size_up_to_a_unit() {
        let at = |offset: RayOffset| offset.distance(Vec3::ZERO) / RAY_OFFSET;
        assert_eq!(at(RayOffset::for_extent(0.25)), 0.25);
        for no_size in [0.0, -1.0, f32::NAN, f32::INFINITY, 1.0, 30.0] {
            assert_eq!(
                RayOffset::for_extent(no_size),
                RayOffset::UNIT_FLOOR,
                "{no_size}"
            );
        }
        let p = Vec3::new(-3.0, 0.5, 2.0);
        assert_eq!(RayOffset::UNIT_FLOOR.distance(p), RAY_OFFSET * (1.0 + 3.0));
        let room = Some((Vec3::ZERO, Vec3::splat(0.01)));
        let inside = RayOffset::around(room, Vec3::splat(0.005));
        assert!((at(inside) - 0.01 * 3f32.sqrt()).abs() < 1e-7);
        let outside = RayOffset::around(room, Vec3::new(0.01, 0.01, 0.5));
        assert!(at(outside) > 0.49, "{outside:?}");
        assert_eq!(RayOffset::around(None, Vec3::ZERO), RayOffset::UNIT_FLOOR);
        // Beyond 16 floors a coordinate adds a tenth as much.
        let unit = RayOffset::UNIT_FLOOR;
        let (at_16, at_116) = (
            unit.distance(Vec3::X * 16.0),
            unit.distance(Vec3::X * 116.0),
        );
        assert_eq!(at_16, RAY_OFFSET * 17.0);
        assert!(
            (at_116 - at_16 - FAR_RAY_OFFSET * 100.0).abs() < 1e-7,
            "{at_116}"
        );
        let tiny = RayOffset::for_extent(0.01);
        assert!((tiny.distance(Vec3::Y * 1.16) - RAY_OFFSET * 0.17 - FAR_RAY_OFFSET).abs() < 1e-9);
        // Towards `w`, on its side of the surface.
        let o = RayOffset::for_extent(0.5).origin(Vec3::ZERO, Vec3::Y, -Vec3::Y);
        assert_eq!(o, Vec3::new(0.0, -RAY_OFFSET * 0.5, 0.0));
    }

    /// A path takes the hits of its replay where it traces the same ray
    /// (the same result, bit for bit, as tracing it; a replayed hit made
    /// up is used), and traces a ray that differs from the one replayed,
    /// whatever hit that one had.
    #[test]
    fn a_path_takes_a_replayed_hit_only_for_the_same_ray() {
        let mut r = crate::render::test_renderer("cube-in-box", 8);
        r.with_frame_context(0, |ctx| {
            let queries: Vec<RadianceQuery> = (0..64)
                .map(|i| RadianceQuery {
                    ray: Ray::new(
                        Vec3::new(0.1, 0.5, 0.2),
                        Vec3::new((i as f32 * 0.7).sin(), 0.3, (i as f32 * 0.7).cos()).normalize(),
                        0.0,
                        f32::INFINITY,
                    ),
                    first_light: None,
                    rng: Rng::from_seed(i, 3),
                    weight: Vec3::ONE,
                    first_hit: FirstHitEmission::Include,
                })
                .collect();
            let length = PathLength::default();
            let trace = |replays: &[Replay]| {
                let (results, _) =
                    trace_radiance_replayed(ctx, length, queries.clone(), replays, false);
                results
                    .iter()
                    .map(|r| r.radiance.to_array().map(f32::to_bits))
                    .collect::<Vec<_>>()
            };
            let (_, tracks) = trace_radiance_replayed(ctx, length, queries.clone(), &[], true);
            let alone = trace(&[]);
            let kept: Vec<Replay> = (0..queries.len()).map(|i| tracks.extensions(i)).collect();
            assert_eq!(trace(&kept), alone, "the same hits");
            // Every first hit moved away: taken, it changes what is seen.
            let made_up: Vec<Vec<(Ray, Hit)>> = (0..queries.len())
                .map(|i| {
                    let mut e = tracks.extensions(i).to_vec();
                    e[0].1 = Hit::MISS;
                    e
                })
                .collect();
            let replays: Vec<Replay> = made_up.iter().map(Vec::as_slice).collect();
            assert_ne!(trace(&replays), alone, "made-up hits taken");
            // The same made-up hits for rays a hair apart: traced.
            let apart: Vec<Vec<(Ray, Hit)>> = made_up
                .iter()
                .map(|e| {
                    let mut e = e.clone();
                    e[0].0.tmax = f32::MAX;
                    e
                })
                .collect();
            let replays: Vec<Replay> = apart.iter().map(Vec::as_slice).collect();
            assert_eq!(trace(&replays), alone, "other rays traced");
        });
    }
}
