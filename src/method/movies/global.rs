//! The coarse global pass (paper §3.1, §4.2): a radiosity solution on a
//! coarse mesh that gives every texel of a movie the light of the "good
//! links" — here everything but direct light, which the movies compute
//! per texel (the paper's conservative classification: "bad links are
//! those corresponding to direct illumination onto visible patches").
//!
//! Departures, named: the paper's global pass is hierarchical radiosity
//! with form factors between patches. Ours is point collocation on a
//! regular subdivision of each triangle (its *grid*, finer for larger
//! triangles): each grid vertex gathers along a fixed set of
//! cosine-distributed rays, its *links*, and the radiosity is solved by
//! Jacobi iteration over them (`bounces` of them at most, the rest added
//! as a geometric series: `GeometricTail`), so that a texel reads
//! its indirect irradiance by Gouraud interpolation of the vertex values,
//! as the paper renders its good links; a link that lands in a cell
//! across which the direct light changes sharply takes the direct light
//! at its own hit instead ([`super::sharp`], where the paper refines its
//! hierarchy). Temporal coherence as in §4.2: a
//! link is traced again only where motion may have changed it (its
//! vertex or its hit lies on a moving object, or its segment crosses a
//! moving object's box: the paper's shaft culling), and the energy
//! transport is then solved from scratch, as the paper does. A link kept
//! is what tracing it again would give, so the solution of a frame does
//! not depend on the frames before it. The same holds for each vertex's
//! row of the transport, built again only where its links, or the
//! open-space flags of the vertices they land by, changed. Each triangle
//! is solved on one side, as the paper's polygons are: its front, or its
//! back where its part encloses the camera facing away; a flat part with
//! scene on both sides of it, on both, each with a grid of its own
//! ([`super::sides`]).

use super::direct::{
    direct_irradiance, direct_irradiance_where, ShadePoint, ShadowBlockers, StaticShadows, Statics,
};
use super::mesh::{blend, renormalised, Gouraud, Meshing, PassMesh, Vertex};
use super::pieces::{self, Cells};
use super::sharp::{is_sharp, Landing, SharpLandings};
use super::sides::{object_space_corners, SolvedSides};
use super::view::meshing_size;
use super::FrameContext;
use crate::accel::SceneBvh;
use crate::backend::{Hit, Ray};
use crate::material::{luminance, Bsdf};
use crate::method::unshadowed::UnshadowedLights;
use crate::sampling::{cosine_hemisphere, streams, Frame, Rng, SampleKey, Stratified2d};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;

/// Settings of the global pass.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GlobalSettings {
    /// Grid spacing as a fraction of the static scene's diagonal, or of
    /// twice that of what the camera sees at time 0 where smaller, on
    /// films up to 128 pixels high, and a share smaller in proportion to
    /// a higher film's height (`meshing_size`, `film_share`): a
    /// triangle's grid has `⌈longest edge / spacing⌉`
    /// segments an edge (at most [`MAX_GRID`](super::mesh::MAX_GRID)), its
    /// edges as they are at time 0 ([`MESHED_AT`]).
    pub spacing: f32,
    /// Links of a vertex that stands for a spacing squared of surface
    /// (two cells whose short sides are a spacing); one that stands for
    /// less gets fewer, in proportion, and at least
    /// [`MIN_LINKS`](super::mesh::MIN_LINKS) (the corners of triangles too
    /// small for that are clustered, one vertex of a cluster gathering for
    /// its area: [`super::mesh`]). A grid's cells are at most a spacing
    /// along their longest edge, so a grid vertex stands for less: at the
    /// default 128, most of the courtyard's and `l_hall`'s vertices have
    /// 51–63 by their area (`benches/RESULTS.md`, "Links a vertex,
    /// doubled"; on right isosceles triangles 57 where the legs are 4
    /// spacings and 64 where they are 12, as `mesh`'s test
    /// `a_seen_triangle_gathers_along_more_links_than_a_hidden_one`
    /// computes them), which a grid on a triangle the camera sees doubles and
    /// one on a triangle it does not see halves (`mesh::SEEN_LINKS`).
    pub links: u32,
    /// Most Jacobi iterations (bounces of indirect light); the iteration
    /// stops sooner once converged ([`CONVERGED`]), and the bounces after
    /// the last are added as a geometric series (`GeometricTail`).
    pub bounces: u32,
    /// Shadow samples of a vertex's direct light.
    pub shadow_samples: u32,
}

impl Default for GlobalSettings {
    fn default() -> Self {
        GlobalSettings {
            spacing: 1.0 / 32.0,
            links: 128,
            bounces: 64,
            shadow_samples: 8,
        }
    }
}

/// The Jacobi iteration stops once an iteration changes the indirect
/// light by at most this share of it (summed over vertices). The error
/// left, about that share times `r/(1 − r)` with `r` the scene's mean
/// albedo (0.1 % for `r` = 0.5, 1 % for 0.9), is then mostly added back
/// (`GeometricTail`). A fixed 8 bounces lost a third of the light in a
/// closed box of albedo 0.9 (`0.9⁹`).
pub const CONVERGED: f64 = 1e-3;

/// The largest share of a vertex's links that may land on the side of a
/// surface not solved (its back, mostly: [`SolvedSides`]) for the vertex
/// to count as in open space.
pub const BURIED_SHARE: f32 = 0.1;
/// What one link found: the hit (triangle and barycentrics) and how far.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Link {
    hit: Hit,
    /// Whether it has been looked at since the pass was built.
    traced: bool,
    /// Whether it was traced at all (a direction below the geometric
    /// surface gathers nothing).
    live: bool,
    /// What it covers, which motion must not cross for it to stay valid:
    /// the segment from `from`, its origin, to `to`, its hit; where it hit
    /// nothing, the whole ray, `to` then a point on it a unit out
    /// ([`may_cross`]).
    from: Vec3,
    to: Vec3,
    /// Whether it landed on the side of a surface the solution is for
    /// ([`SolvedSides`]).
    on_solved_side: bool,
    /// The vertices it gathers from, where it landed.
    landing: Gouraud,
}

/// The global pass's state: the mesh, the links found so far and the
/// solution of the last frame.
pub struct GlobalPass {
    settings: GlobalSettings,
    /// The side of each triangle solved: the one its vertices gather on.
    sides: SolvedSides,
    /// Per triangle, its cells: one grid, or pieces ([`super::pieces`]).
    grids: Vec<Cells>,
    /// Per triangle solved on both sides, the cells of its second side.
    reverse_grids: Vec<Option<Cells>>,
    /// The pieces of the triangles split ([`Cells::Split`]).
    pieces: Vec<Cells>,
    /// The vertex in each slot of the grids.
    vertex_of: Vec<u32>,
    vertices: Vec<Vertex>,
    /// Each clustered vertex that gathers along no link, and the vertex
    /// of its cluster that gathers for it ([`PassMesh::cluster`]): it
    /// takes that one's indirect light and open-space flag.
    clustered: Vec<(u32, u32)>,
    links: Vec<Link>,
    /// Static shadows at the vertices that do not move.
    shadows: StaticShadows,
    /// The direct light at the hits of links landing in sharp cells.
    sharp: SharpLandings,
    /// Per vertex, indirect irradiance of the last solution.
    indirect: Vec<Vec3>,
    /// Per vertex, whether it lies in open space ([`BURIED_SHARE`]).
    valid: Vec<bool>,
    /// Per material, the albedo its surfaces reflect indirect light
    /// with ([`spread_albedo`]): found once, as it takes a quadrature of
    /// the lobe per glossy material.
    spread_albedo: Vec<Vec3>,
    /// Per vertex, its row of the transport ([`GlobalPass::row`]), kept
    /// across frames: a row changes only with its vertex's links or the
    /// open-space flags where they land, and building them all was most
    /// of the pass's time (a sort per vertex, every frame).
    rows: Vec<Vec<(u32, f32)>>,
    /// Links traced in the last frame.
    pub traced_links: u64,
    /// The most bytes the last frame's working buffers held at once
    /// ([`GlobalPass::working_bytes`]).
    working_bytes: usize,
}

/// The bytes of the buffers a pass makes for one frame and lets go by its
/// end, counted as they are made and let go: how many are held, and the
/// most held at once. Each is counted by its length, as
/// [`GlobalPass::memory_bytes`] counts what the pass keeps.
#[derive(Debug, Default)]
struct Working {
    held: usize,
    peak: usize,
}

impl Working {
    fn hold<T>(&mut self, buffer: &[T]) {
        self.hold_bytes(std::mem::size_of_val(buffer));
    }

    fn hold_bytes(&mut self, bytes: usize) {
        self.held += bytes;
        self.peak = self.peak.max(self.held);
    }

    fn release<T>(&mut self, buffer: &[T]) {
        self.release_bytes(std::mem::size_of_val(buffer));
    }

    fn release_bytes(&mut self, bytes: usize) {
        debug_assert!(bytes <= self.held, "released more than was held");
        self.held = self.held.saturating_sub(bytes);
    }
}

/// A frame's vertices as shading points, the direct irradiance found at
/// them and whether a link lands by each (where the direct light was
/// found: zero at the others).
#[derive(Clone, Copy)]
struct Lighting<'a> {
    points: &'a [ShadePoint],
    direct: &'a [Vec3],
    landed: &'a [bool],
}

/// Bytes of transport rows: the list and each row.
fn rows_bytes(rows: &[Vec<(u32, f32)>]) -> usize {
    std::mem::size_of_val(rows)
        + rows
            .iter()
            .map(|r| std::mem::size_of_val(&r[..]))
            .sum::<usize>()
}

impl GlobalPass {
    /// Bytes it holds from frame to frame: its mesh of vertices, their
    /// links, static shadows and last solution, and transport rows.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(&self.grids[..])
            + std::mem::size_of_val(&self.reverse_grids[..])
            + std::mem::size_of_val(&self.pieces[..])
            + std::mem::size_of_val(&self.vertex_of[..])
            + std::mem::size_of_val(&self.vertices[..])
            + std::mem::size_of_val(&self.clustered[..])
            + std::mem::size_of_val(&self.links[..])
            + self.shadows.bytes()
            + self.sharp.bytes()
            + std::mem::size_of_val(&self.indirect[..])
            + std::mem::size_of_val(&self.valid[..])
            + std::mem::size_of_val(&self.spread_albedo[..])
            + rows_bytes(&self.rows)
            + self.sides.bytes()
    }

    /// The most bytes held at once, beside [`memory_bytes`](Self::memory_bytes),
    /// by the buffers the last [`update`](Self::update) made and let go:
    /// a shading point per vertex, the links to trace again with their
    /// rays and hits, the vertices' direct light, and the solution's
    /// iterates and rows built again. On a frame that traces every link
    /// (the first) this is about one and a half times the links' own
    /// bytes (a stale entry, a drawn ray, then its index and ray, as they
    /// are unzipped). The shadow
    /// rays of the direct light, made and traced a bounded batch at a time,
    /// are left out; the links landing in sharp cells, with their points
    /// and light ([`super::sharp`]), are in.
    pub fn working_bytes(&self) -> usize {
        self.working_bytes
    }

    /// The pass over the scene of `ctx`, meshed as the scene stands at
    /// time 0 ([`MESHED_AT`]) and with the sides `ctx`'s camera sets.
    pub fn new(ctx: &FrameContext, settings: GlobalSettings) -> Self {
        let at_zero = (ctx.snapshot.time != MESHED_AT)
            .then(|| ctx.scene.snapshot_from(MESHED_AT, ctx.snapshot));
        let meshed = at_zero.as_ref().unwrap_or(ctx.snapshot);
        let corners = object_space_corners(ctx.scene, meshed);
        let mut bvh = SceneBvh::new();
        bvh.update(meshed);
        let sides = SolvedSides::new(&corners, ctx.snapshot, (meshed, &bvh), ctx.ray_offset);
        let both: Vec<bool> = (0..meshed.triangles.len() as u32)
            .map(|id| sides.both(id))
            .collect();
        let size = meshing_size(ctx.scene, meshed, &bvh, (ctx.width, ctx.height));
        let meshing = Meshing::fitting(&meshed.triangles, &both, &settings, size);
        let PassMesh {
            grids,
            reverse_grids,
            pieces,
            vertex_of,
            vertices,
            link_count,
            clustered,
            ..
        } = PassMesh::new(meshed, (&corners, sides.components()), &meshing, &both);
        let count = vertices.len();
        GlobalPass {
            settings,
            sides,
            grids,
            reverse_grids,
            pieces,
            vertex_of,
            vertices,
            clustered,
            links: Vec::new(),
            shadows: StaticShadows::default(),
            sharp: SharpLandings::default(),
            indirect: vec![Vec3::ZERO; count],
            valid: vec![true; count],
            spread_albedo: ctx.scene.materials.iter().map(spread_albedo).collect(),
            rows: Vec::new(),
            traced_links: 0,
            working_bytes: 0,
        }
        .with_links(link_count as usize)
    }

    fn with_links(mut self, count: usize) -> Self {
        self.links = vec![
            Link {
                hit: Hit::MISS,
                traced: false,
                live: false,
                from: Vec3::ZERO,
                to: Vec3::ZERO,
                on_solved_side: false,
                landing: [(0, 0.0); 3],
            };
            count
        ];
        self
    }

    /// Whether this pass was built for a snapshot with this many triangles.
    pub fn fits(&self, triangles: usize) -> bool {
        self.grids.len() == triangles
    }

    /// Whether the pass solves the side of triangle `id` that `back`
    /// names.
    pub fn solves(&self, id: u32, back: bool) -> bool {
        self.sides.solves(id, back)
    }

    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    pub fn link_count(&self) -> usize {
        self.links.len()
    }

    /// Per vertex, the indirect irradiance of the last solution.
    pub fn indirect(&self) -> &[Vec3] {
        &self.indirect
    }

    /// The cells of the side of triangle `id` that `back` names: its
    /// second side's where it has them on that side, else its first's.
    fn cells(&self, id: u32, back: bool) -> Cells {
        match self.reverse_grids[id as usize] {
            Some(reverse) if back != self.sides.back(id) => reverse,
            _ => self.grids[id as usize],
        }
    }

    /// The vertices that interpolate at barycentrics `(u, v)` of the side
    /// of triangle `id` that `back` names (its first cells or its second
    /// side's, as `cells` picks them; the grid of
    /// the piece that holds the point, where it is split), and their
    /// weights.
    pub fn gouraud(&self, id: u32, back: bool, u: f32, v: f32) -> Gouraud {
        let (grid, (s, t)) = pieces::leaf(&self.pieces, self.cells(id, back), (u, v));
        grid.weights(s, t)
            .map(|(slot, w)| (self.vertex_of[slot as usize], w))
    }

    /// Indirect irradiance where `g` says (the solved side of its
    /// triangle), from the last solution.
    pub fn indirect_with(&self, g: &Gouraud) -> Vec3 {
        blend(&self.indirect, &self.valid, g)
    }

    /// The frame of `ctx`: the sides its camera sets, links traced again
    /// where motion or a side that changed may have changed them, the
    /// direct light at the vertices links land by (`landed`), and
    /// the radiosity solved. Returns the shadow rays traced.
    /// Its working buffers' peak is then [`working_bytes`](Self::working_bytes).
    pub fn update(&mut self, ctx: &FrameContext, blockers: &ShadowBlockers, first: bool) -> u64 {
        self.update_lighting(ctx, blockers, first, Self::landed)
    }

    /// [`Self::update`], with the direct light found at the vertices
    /// `direct_at` marks (the test that the solution is the same with it
    /// found at every vertex marks them all).
    fn update_lighting(
        &mut self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        first: bool,
        direct_at: fn(&Self) -> Vec<bool>,
    ) -> u64 {
        let mut working = Working::default();
        let turned = self.sides.update(ctx.snapshot);
        if turned.contains(&true) {
            // The vertices that turned gather on the other hemisphere: their
            // kept static shadows are another point's.
            self.shadows = StaticShadows::default();
        }
        let points = self.points(ctx);
        working.hold(&points);
        let retraced = self.retrace_links(ctx, blockers, &points, first, &turned, &mut working);
        let moving: Vec<bool> = self
            .vertices
            .iter()
            .map(|v| blockers.is_moving_triangle(v.triangle))
            .collect();
        working.hold(&moving);
        let landed = direct_at(self);
        working.hold(&landed);
        let (direct, shadow_rays) =
            self.direct(ctx, blockers, &points, (&moving, &landed), &mut working);
        let lit = Lighting {
            points: &points,
            direct: &direct,
            landed: &landed,
        };
        let sharp_rays = self.solve(ctx, blockers, lit, &retraced, &mut working);
        self.working_bytes = working.peak;
        shadow_rays + sharp_rays
    }

    /// Every vertex as a shading point on its triangle's solved side, in
    /// the frame of `ctx` (pulled a hair towards its triangle's centre, so
    /// that a corner vertex does not gather from the edge it sits on).
    fn points(&self, ctx: &FrameContext) -> Vec<ShadePoint> {
        self.vertices
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let tri = &ctx.snapshot.triangles[v.triangle as usize];
                let (u, w) = pulled(v.at.0, v.at.1);
                let side = self.sides.sign(v.triangle) * if v.reverse { -1.0 } else { 1.0 };
                ShadePoint::on_side(tri, (u, w), side, streams::GLOBAL_VERTEX | i as u64)
            })
            .collect()
    }

    /// The ray of link `link` of the `links` of the vertex at `point`:
    /// the vertex's links are one multi-jittered set over its cosine
    /// hemisphere ([`Stratified2d`]), each jittered within its sub-cell by
    /// its own stream. Independent directions left a vertex's gathered
    /// light noisy enough that Gouraud interpolation smeared the noise into
    /// blotches a few cells across (a courtyard's shaded ground, lit only
    /// by its sunlit walls). A link's direction depends on its vertex, its
    /// number and their count only, so a link traced again goes where it
    /// went.
    fn link_ray(ctx: &FrameContext, point: &ShadePoint, link: u32, links: u32) -> Option<Ray> {
        let key = |sample| SampleKey {
            seed: ctx.seed,
            frame: None,
            item: streams::GLOBAL_LINK | point.item,
            sample,
        };
        // The set's shuffle takes a sample number no link has (a vertex
        // has at most twice the settings' `links` ≤ 1024 of them).
        let shuffle = Rng::new(key(u32::MAX)).next_u32();
        let u = Rng::new(key(link)).next_2d();
        let u = Stratified2d::sample_of(links, shuffle, link, u);
        let wi = Frame::new(point.n).to_world(cosine_hemisphere(u));
        (wi.dot(point.ng) > 0.0).then(|| {
            Ray::new(
                ctx.ray_offset.origin(point.p, point.ng, wi),
                wi,
                0.0,
                f32::INFINITY,
            )
        })
    }

    /// Traces the links that motion may have changed (all of them the
    /// first time), and those from or to a component whose solved side
    /// `turned` (per component): their hemisphere, or the side they land
    /// on, is another. Returns, per vertex, whether any of its links was
    /// (held in `working` until the frame's end).
    fn retrace_links(
        &mut self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        points: &[ShadePoint],
        first: bool,
        turned: &[bool],
        working: &mut Working,
    ) -> Vec<bool> {
        let stale = self.stale_links(blockers, first, turned);
        working.hold(&stale);
        let mut retraced = vec![false; self.vertices.len()];
        working.hold(&retraced);
        for &(_, i, _) in &stale {
            retraced[i as usize] = true;
        }
        let rays: Vec<(usize, Option<Ray>)> = stale
            .par_iter()
            .map(|&(index, i, k)| {
                let links = self.vertices[i as usize].links;
                (index, Self::link_ray(ctx, &points[i as usize], k, links))
            })
            .collect();
        working.hold(&rays);
        let drawn_bytes = std::mem::size_of_val(&rays[..]);
        for (index, ray) in &rays {
            if ray.is_none() {
                let link = &mut self.links[*index];
                link.traced = true;
                link.live = false;
                link.on_solved_side = false;
                link.hit = Hit::MISS;
            }
        }
        let (indices, rays): (Vec<usize>, Vec<Ray>) = rays
            .into_iter()
            .filter_map(|(index, ray)| ray.map(|r| (index, r)))
            .unzip();
        working.hold(&indices);
        working.hold(&rays);
        working.release_bytes(drawn_bytes);
        let mut hits = vec![Hit::MISS; rays.len()];
        working.hold(&hits);
        let batch = ctx.backend.preferred_batch().max(1);
        rays.par_chunks(batch)
            .zip(hits.par_chunks_mut(batch))
            .for_each(|(r, h)| ctx.backend.closest_hit(r, h));
        // Let go of as this function returns (nothing is held after).
        working.release(&stale);
        working.release(&indices);
        working.release(&rays);
        working.release(&hits);
        self.land_links(ctx, &indices, &rays, hits);
        self.traced_links = rays.len() as u64;
        retraced
    }

    /// The links to trace again (index, vertex, link of the vertex): all
    /// the first time; those from or to a moving triangle or a component
    /// that `turned`; those not traced yet; and those whose segment a
    /// moving object's box may cross. Only their segments are looked at.
    fn stale_links(
        &self,
        blockers: &ShadowBlockers,
        first: bool,
        turned: &[bool],
    ) -> Vec<(usize, u32, u32)> {
        let sides = &self.sides;
        let turned_triangle = |id: u32| turned[sides.component(id)];
        self.vertices
            .par_iter()
            .enumerate()
            .flat_map_iter(|(i, v)| {
                let moving_vertex = blockers.is_moving_triangle(v.triangle);
                let turned_vertex = turned_triangle(v.triangle);
                let links = &self.links;
                (0..v.links).filter_map(move |k| {
                    let index = (v.first_link + k) as usize;
                    let link = &links[index];
                    let stale = first
                        || moving_vertex
                        || turned_vertex
                        || (link.hit.is_hit() && turned_triangle(link.hit.triangle))
                        || !link.traced
                        || (link.hit.is_hit() && blockers.is_moving_triangle(link.hit.triangle))
                        || (link.live && may_cross(blockers, link));
                    stale.then_some((index, i as u32, k))
                })
            })
            .collect()
    }

    /// Stores what each traced link `indices[i]` found along `rays[i]`:
    /// where it landed on a solved side, the vertices it gathers from
    /// there; its segment, to the hit, or its ray where it hit nothing.
    fn land_links(&mut self, ctx: &FrameContext, indices: &[usize], rays: &[Ray], hits: Vec<Hit>) {
        for ((index, ray), hit) in indices.iter().zip(rays).zip(hits) {
            self.sharp.forget(*index as u32);
            // The side hit is the one the ray meets: its back where it
            // runs along the triangle's geometric normal (neither where it
            // grazes it).
            let landed = hit.is_hit().then(|| {
                let tri = &ctx.snapshot.triangles[hit.triangle as usize];
                tri.geometric_normal().dot(ray.dir())
            });
            let back = landed.filter(|&d| d != 0.0).map(|d| d > 0.0);
            let on_solved_side = back.is_some_and(|back| self.sides.solves(hit.triangle, back));
            let landing = if let Some(back) = back.filter(|_| on_solved_side) {
                self.gouraud(hit.triangle, back, hit.u, hit.v)
            } else {
                [(0, 0.0); 3]
            };
            let t = if hit.is_hit() { hit.t } else { 1.0 };
            self.links[*index] = Link {
                hit,
                traced: true,
                live: true,
                from: ray.origin(),
                to: ray.at(t),
                on_solved_side,
                landing,
            };
        }
    }

    /// Per vertex, whether a link lands by it: one of the three vertices a
    /// live link on a solved side gathers from (all three, as
    /// [`renormalised`] may take any of them). The solution reads a
    /// vertex's direct light there only: in its radiance `B` that the
    /// links landing by it gather, in the glossy and sharp light of those
    /// links. A vertex's own indirect light, which its texels read, does
    /// not need it. On a mesh far finer than the links (a sphere of a
    /// million corners at one link each) few vertices are landed by.
    fn landed(&self) -> Vec<bool> {
        let mut landed = vec![false; self.vertices.len()];
        for link in self.links.iter().filter(|l| l.live && l.on_solved_side) {
            for &(j, _) in &link.landing {
                landed[j as usize] = true;
            }
        }
        landed
    }

    /// Direct irradiance at the vertices `landed` marks, zero at the
    /// others (static shadows kept for the vertices that do not move, in
    /// the batches where one is landed by: `direct_irradiance_where`),
    /// held in `working` until the frame's end.
    fn direct(
        &mut self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        points: &[ShadePoint],
        (moving, landed): (&[bool], &[bool]),
        working: &mut Working,
    ) -> (Vec<Vec3>, u64) {
        let (still, mut moved): (Vec<usize>, Vec<usize>) =
            (0..points.len()).partition(|&i| !moving[i]);
        moved.retain(|&i| landed[i]);
        let still_landed: Vec<bool> = still.iter().map(|&i| landed[i]).collect();
        working.hold(&still_landed);
        working.hold(&still);
        working.hold(&moved);
        // Each set's points, held while their light is found.
        let pick = |set: &[usize], working: &mut Working| {
            let picked: Vec<ShadePoint> = set.iter().map(|&i| points[i]).collect();
            working.hold(&picked);
            picked
        };
        let samples = self.settings.shadow_samples;
        let still_points = pick(&still, working);
        let (e_still, c_still) = direct_irradiance_where(
            ctx,
            blockers,
            (&still_points, Some(&still_landed)),
            samples,
            Statics::Kept(&mut self.shadows),
        );
        working.release(&still_landed);
        drop(still_landed);
        working.hold(&e_still);
        working.release(&still_points);
        drop(still_points);
        let moved_points = pick(&moved, working);
        let (e_moved, c_moved) =
            direct_irradiance(ctx, blockers, &moved_points, samples, Statics::Moving);
        working.hold(&e_moved);
        working.release(&moved_points);
        drop(moved_points);
        let mut direct = vec![Vec3::ZERO; points.len()];
        working.hold(&direct);
        // Let go of as this function returns (nothing is held after).
        working.release(&still);
        working.release(&moved);
        working.release(&e_still);
        working.release(&e_moved);
        for (i, e) in still
            .into_iter()
            .zip(e_still)
            .chain(moved.into_iter().zip(e_moved))
        {
            direct[i] = e;
        }
        (direct, c_still.traced + c_moved.traced)
    }

    /// Jacobi iteration of `B = (ρ_d·E_direct + ρ·E_indirect)/π`, with
    /// `E_indirect` the mean over a vertex's links of the radiance `B`
    /// interpolated where each lands, times π (cosine-distributed links),
    /// plus the direct light glossy surfaces reflect along them
    /// ([`Self::glossy_direct`]). `ρ_d` is the diffuse albedo; `ρ` adds the
    /// glossy lobe's share ([`spread_albedo`]): the indirect light a
    /// glossy surface reflects is spread as if diffuse (radiosity has no
    /// view direction; light that arrives from all around leaves a lobe
    /// about as evenly), rather than lost from the light that bounces on.
    /// A link that lands on a side not solved or on an emitter's
    /// emission gathers nothing: emitted light is the direct light,
    /// counted once. A link landing where the direct light changes
    /// sharply takes its hit's own ([`Self::sharp_direct`]). `retraced`
    /// marks the vertices whose links were traced again this frame.
    /// Returns the shadow rays traced.
    fn solve(
        &mut self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        lit: Lighting,
        retraced: &[bool],
        working: &mut Working,
    ) -> u64 {
        let direct = lit.direct;
        let albedo: Vec<(Vec3, Vec3)> = self
            .vertices
            .iter()
            .map(|v| {
                let id = ctx.snapshot.tri_material[v.triangle as usize] as usize;
                (ctx.scene.materials[id].diffuse, self.spread_albedo[id])
            })
            .collect();
        working.hold(&albedo);
        self.update_rows(retraced, working);
        let mut constant = self.glossy_direct(ctx, lit, working);
        let (sharp, sharp_rays) = self.sharp_direct(ctx, blockers, direct, &albedo, working);
        for (c, s) in constant.iter_mut().zip(&sharp) {
            *c += *s;
        }
        working.release(&sharp);
        drop(sharp);
        // Three buffers for the whole iteration (up to `bounces` steps):
        // each step writes the radiance leaving every vertex into `b` and
        // the indirect light gathered from it into `next`, then swaps
        // `next` with `indirect`.
        let count = self.vertices.len();
        let (mut indirect, mut b, mut next) = (
            vec![Vec3::ZERO; count],
            vec![Vec3::ZERO; count],
            vec![Vec3::ZERO; count],
        );
        working.hold(&indirect);
        working.hold(&b);
        working.hold(&next);
        let mut tail = GeometricTail::default();
        for _ in 0..self.settings.bounces {
            for (((b, &(rho_d, rho)), &d), &i) in
                b.iter_mut().zip(&albedo).zip(direct).zip(&indirect)
            {
                *b = FRAC_1_PI * (rho_d * d + rho * i);
            }
            (next.par_iter_mut().zip(&self.rows).zip(&constant)).for_each(|((out, row), &g)| {
                *out = row.iter().fold(g, |acc, &(j, w)| acc + b[j as usize] * w);
            });
            for &(member, head) in &self.clustered {
                next[member as usize] = next[head as usize];
            }
            let step = Step::between(&indirect, &next);
            tail.push(step);
            std::mem::swap(&mut indirect, &mut next);
            if step.converged() {
                break;
            }
        }
        // `next` holds the iterate before the last: their difference is
        // the last bounce's light, which the bounces left out repeat
        // shrinking by the factor the iteration settled on.
        if let Some(factor) = tail.factor() {
            for (i, before) in indirect.iter_mut().zip(&next) {
                *i += (*i - *before) * factor;
            }
        }
        working.release(&next);
        working.release(&b);
        // Kept: counted by `memory_bytes` from here.
        working.release(&indirect);
        working.release(&constant);
        working.release(&albedo);
        self.indirect = indirect;
        sharp_rays
    }

    /// Per vertex, what taking the direct light at its links' own hits
    /// adds to the Gouraud interpolation of it that its row gathers, for
    /// the links that land in a sharp cell ([`super::sharp`]): the hit's
    /// `ρ_d·E_direct/π` less the interpolated one, times π over the
    /// vertex's links, as the row weighs each link. Also the shadow rays
    /// traced.
    fn sharp_direct(
        &mut self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        direct: &[Vec3],
        albedo: &[(Vec3, Vec3)],
        working: &mut Working,
    ) -> (Vec<Vec3>, u64) {
        let (owners, landings) = self.sharp_landings(ctx, blockers, direct, working);
        let (e, rays) = self.sharp.irradiance(ctx, blockers, &landings);
        working.hold(&e);
        let mut added = vec![Vec3::ZERO; self.vertices.len()];
        working.hold(&added);
        let diffuse = |id: u32| {
            let material = ctx.snapshot.tri_material[id as usize] as usize;
            ctx.scene.materials[material].diffuse
        };
        for ((&i, landing), e) in owners.iter().zip(&landings).zip(&e) {
            let l = &self.links[landing.link as usize];
            let interpolated = renormalised(&self.valid, &l.landing)
                .fold(Vec3::ZERO, |acc, (j, w)| {
                    acc + albedo[j as usize].0 * direct[j as usize] * w
                });
            let v = &self.vertices[i as usize];
            let scale = 1.0 / v.links.max(1) as f32;
            added[i as usize] += (diffuse(l.hit.triangle) * *e - interpolated) * scale;
        }
        working.release(&owners);
        working.release(&landings);
        working.release(&e);
        (added, rays)
    }

    /// The links that land in a sharp cell ([`is_sharp`] of the direct
    /// light at its vertices) as [`Landing`]s, and the vertex whose link
    /// each is, held in `working` until the caller lets them go.
    fn sharp_landings(
        &self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        direct: &[Vec3],
        working: &mut Working,
    ) -> (Vec<u32>, Vec<Landing>) {
        let brightness: Vec<f32> = direct.par_iter().map(|&d| luminance(d)).collect();
        working.hold(&brightness);
        let (owners, landings): (Vec<u32>, Vec<Landing>) = (self.vertices.par_iter().enumerate())
            .flat_map_iter(|(i, v)| {
                let brightness = &brightness;
                (v.first_link..v.first_link + v.links).filter_map(move |link| {
                    let l = &self.links[link as usize];
                    let landed = l.live && l.on_solved_side && l.hit.is_hit();
                    let sharp = landed
                        && is_sharp(
                            renormalised(&self.valid, &l.landing)
                                .map(|(j, _)| brightness[j as usize]),
                        );
                    sharp.then(|| (i as u32, self.landing(ctx, blockers, link)))
                })
            })
            .unzip();
        working.hold(&owners);
        working.hold(&landings);
        working.release(&brightness);
        (owners, landings)
    }

    /// Link `link` as a [`Landing`]: the point it hit, on the side it hit.
    fn landing(&self, ctx: &FrameContext, blockers: &ShadowBlockers, link: u32) -> Landing {
        let l = &self.links[link as usize];
        let tri = &ctx.snapshot.triangles[l.hit.triangle as usize];
        let side = if tri.geometric_normal().dot(l.to - l.from) > 0.0 {
            -1.0
        } else {
            1.0
        };
        let item = streams::GLOBAL_LANDING | u64::from(link);
        Landing {
            link,
            point: ShadePoint::on_side(tri, (l.hit.u, l.hit.v), side, item),
            moving: blockers.is_moving_triangle(l.hit.triangle),
        }
    }

    /// Per vertex, the direct light that glossy surfaces reflect to it
    /// along its links, as irradiance (π times the mean over its links):
    /// the part of the direct light a Phong lobe reflects goes where the
    /// lobe points, which a radiosity spread evenly would not follow (a
    /// glossy back wall sends a ceiling light's light down and forward;
    /// spread as if diffuse, the ceiling of `glossy-cornell` read 14.5 %
    /// brighter than `path`'s at 24 × 24, and left out, that of `spheres`
    /// 16 % darker). A link's share is the lobe at its hit,
    /// seen from its vertex, over the lights taken as points
    /// ([`UnshadowedLights`]), the lobe averaged over the solid angle an
    /// area light covers there (`Bsdf::mean_specular`, the EAS's cone
    /// average), times the transmittance where it lands. (Taken at the
    /// light's centre alone, a lobe narrower than the light gave a link
    /// up to its peak over the whole light, tens of times the light it
    /// reflects: fireflies on `tests/data/scenes/spheres.glb`'s glossy balls
    /// near its ceiling light, a frame at 0.69 relative RMSE against
    /// `path` with 256 links a vertex, and a block bias over 24 frames of
    /// 0.0056 with the default links, 0.0044 now.) The transmittance is
    /// its vertices' direct light over their unshadowed direct light, as
    /// the paper weights a link's unoccluded light by a transmittance
    /// texture (§3.1) rather than tracing shadow rays per link. The two
    /// differ in more than shadows near an area light (the direct light
    /// samples its area, the unshadowed one takes it as a point), so the
    /// ratio is held to [0, 1]. Every glossy link is evaluated each frame,
    /// though its lobe changes only with the lights or where it was traced
    /// again: keeping it would take 12 more bytes a link, for little
    /// (`spheres`, the most glossy links of our scenes, took 5.51 s before
    /// this light and 5.62 s with it over 12 frames at 64 × 64, one
    /// invocation each: `benches/RESULTS.md`). The transmittance is found
    /// only at the vertices links land by, the only ones it is read at.
    fn glossy_direct(&self, ctx: &FrameContext, lit: Lighting, working: &mut Working) -> Vec<Vec3> {
        let materials = &ctx.scene.materials;
        let material_of = |id: u32| &materials[ctx.snapshot.tri_material[id as usize] as usize];
        let is_glossy = |id: u32| material_of(id).is_glossy();
        if !materials.iter().any(|m| m.is_glossy()) {
            let none = vec![Vec3::ZERO; self.vertices.len()];
            working.hold(&none);
            return none;
        }
        let lights = UnshadowedLights::of(materials, ctx.snapshot);
        let transmittance: Vec<Vec3> = (lit.points.par_iter().zip(lit.direct).zip(lit.landed))
            .map(|((point, &shadowed), &landed)| {
                if !landed {
                    return Vec3::ZERO;
                }
                let open = lights.irradiance(point.p, point.n);
                let ratio = |k: usize| match open[k] > 0.0 {
                    true => (shadowed[k] / open[k]).clamp(0.0, 1.0),
                    false => 0.0,
                };
                Vec3::new(ratio(0), ratio(1), ratio(2))
            })
            .collect();
        working.hold(&transmittance);
        let glossy: Vec<Vec3> = (self.vertices.par_iter())
            .map(|v| {
                let reflected: Vec3 = (self.links_of(v).iter())
                    .filter(|l| l.live && l.on_solved_side && is_glossy(l.hit.triangle))
                    .map(|l| {
                        let tri = &ctx.snapshot.triangles[l.hit.triangle as usize];
                        let wo = (l.from - l.to).normalize_or_zero();
                        let bsdf = Bsdf::new(
                            material_of(l.hit.triangle),
                            tri.shading_normal(l.hit.u, l.hit.v),
                            wo,
                        );
                        let n = bsdf.normal();
                        let lobe = lights.reflected(l.to, |w, solid_angle| {
                            bsdf.mean_specular(wo, w, solid_angle) * n.dot(w).max(0.0)
                        });
                        lobe * blend(&transmittance, &self.valid, &l.landing)
                    })
                    .sum();
                reflected * (std::f32::consts::PI / v.links.max(1) as f32)
            })
            .collect();
        // Held until the solution's end; the transmittance let go of here.
        working.hold(&glossy);
        working.release(&transmittance);
        glossy
    }

    /// The open-space flags of this frame's links, and the rows that they
    /// or the links changed built again: those of vertices whose links
    /// were traced again, and those with a link landing next to a vertex
    /// whose flag changed. Each row kept is then the one [`GlobalPass::row`]
    /// would build, so the solution is the same as with every row built
    /// again (`kept_rows_equal_rows_built_again` checks it).
    fn update_rows(&mut self, retraced: &[bool], working: &mut Working) {
        let mut valid: Vec<bool> = self
            .vertices
            .par_iter()
            .map(|v| self.in_open_space(v))
            .collect();
        for &(member, head) in &self.clustered {
            valid[member as usize] = valid[head as usize];
        }
        working.hold(&valid);
        let flipped: Vec<bool> = valid.iter().zip(&self.valid).map(|(a, b)| a != b).collect();
        working.hold(&flipped);
        let any_flipped = flipped.contains(&true);
        // Kept: counted by `memory_bytes` from here, as the rows are.
        working.release(&valid);
        self.valid = valid;
        if self.rows.len() != self.vertices.len() {
            working.release(&flipped);
            self.rows = self.vertices.par_iter().map(|v| self.row(v)).collect();
            return;
        }
        let dirty: Vec<usize> = (0..self.vertices.len())
            .into_par_iter()
            .filter(|&i| {
                retraced[i]
                    || (any_flipped
                        && self.links_of(&self.vertices[i]).iter().any(|l| {
                            l.live
                                && l.on_solved_side
                                && l.landing.iter().any(|&(j, _)| flipped[j as usize])
                        }))
            })
            .collect();
        working.hold(&dirty);
        let built: Vec<Vec<(u32, f32)>> = dirty
            .par_iter()
            .map(|&i| self.row(&self.vertices[i]))
            .collect();
        // Built beside the rows they replace; let go of (or kept in their
        // place) as this function returns.
        working.hold_bytes(rows_bytes(&built));
        working.release(&flipped);
        working.release(&dirty);
        working.release_bytes(rows_bytes(&built));
        for (i, row) in dirty.into_iter().zip(built) {
            self.rows[i] = row;
        }
    }

    fn links_of(&self, v: &Vertex) -> &[Link] {
        &self.links[v.first_link as usize..(v.first_link + v.links) as usize]
    }

    /// Whether vertex `v` lies in open space: at most [`BURIED_SHARE`] of
    /// its links land on a side not solved. A vertex under another
    /// surface (the ceiling above a light hung just below it, the floor
    /// under a block) gathers darkness that no visible point has, and
    /// Gouraud interpolation would spread it to the visible texels next
    /// to it (the shadow leaks of coarse radiosity meshes): such vertices
    /// are left out of every interpolation.
    fn in_open_space(&self, v: &Vertex) -> bool {
        let links = self.links_of(v);
        let live = links.iter().filter(|l| l.live).count();
        let unsolved = links
            .iter()
            .filter(|l| l.live && l.hit.is_hit() && !l.on_solved_side)
            .count();
        unsolved as f32 <= BURIED_SHARE * live as f32
    }

    /// Vertex `v`'s gather, `E = π·mean(B at each link's landing point)`,
    /// as weights on the vertices the links land between (one entry per
    /// vertex, in vertex order): the Jacobi iteration is then a sparse
    /// product, and the links' landings are not interpolated again in
    /// every iteration.
    fn row(&self, v: &Vertex) -> Vec<(u32, f32)> {
        let mut entries: Vec<(u32, f32)> = self
            .links_of(v)
            .iter()
            .filter(|l| l.live && l.on_solved_side)
            .flat_map(|l| renormalised(&self.valid, &l.landing))
            .collect();
        entries.sort_by_key(|e| e.0);
        let scale = std::f32::consts::PI / v.links.max(1) as f32;
        let mut row: Vec<(u32, f32)> = Vec::with_capacity(entries.len());
        for (j, w) in entries {
            match row.last_mut() {
                Some(last) if last.0 == j => last.1 += w,
                _ => row.push((j, w)),
            }
        }
        row.iter_mut().for_each(|e| e.1 *= scale);
        row
    }
}

/// The albedo a surface of material `m` reflects light arriving from all
/// around with, as a radiosity spreads it: its diffuse albedo and its
/// Phong lobe's hemispherical albedo
/// ([`phong_hemispherical_albedo`](crate::material::phong_hemispherical_albedo)),
/// at most 1. Counting the lobe's `ks` whole overstated a narrow lobe's
/// share by half (its mean albedo is about 2/3 of `ks`).
fn spread_albedo(m: &crate::scene::Material) -> Vec3 {
    let lobe = if m.is_glossy() {
        m.specular * crate::material::phong_hemispherical_albedo(m.exponent)
    } else {
        Vec3::ZERO
    };
    (m.diffuse + lobe).min(Vec3::ONE)
}

/// Whether a moving object's box may cross what `link` covers. A link
/// that hit nothing is followed as far as any box reaches
/// ([`ray_may_hit`](crate::method::motion::ObjectBoxes::ray_may_hit)).
/// (It kept a segment of twice the scene's diagonal once: an object that
/// later moved beyond that, into the link's ray, was not seen to cross
/// it, and the kept link missed where one traced again hit.)
fn may_cross(blockers: &ShadowBlockers, link: &Link) -> bool {
    if link.hit.is_hit() {
        return blockers.segment_may_hit(link.from, link.to);
    }
    let dir = (link.to - link.from).normalize_or_zero();
    blockers.ray_may_hit(link.from, dir, f32::INFINITY, None)
}

/// Barycentrics `(u, v)` moved a thousandth of the way to the centroid,
/// off the edges: a vertex or texel there does not gather from the edge
/// it sits on (`GlobalPass::points`, `Movie::texel_st`).
pub(super) fn pulled(u: f32, v: f32) -> (f32, f32) {
    let k = 1e-3;
    (u + (1.0 / 3.0 - u) * k, v + (1.0 / 3.0 - v) * k)
}

/// The time the global pass is meshed at, whatever frame it starts at.
///
/// The mesh (each triangle's grid, its vertices' links, the link budget,
/// the spacing, and the corners shared) is sized from triangles' sizes,
/// which change over the animation wherever an object scales (or nothing
/// is static, so the spacing's box moves). Sized at the frame the pass
/// starts at, a render resumed at frame k meshed the scene otherwise than
/// the uninterrupted one that started at 0, and its frames differed (a
/// resumed render must equal the uninterrupted one). The pass cannot
/// know the job's first frame, but time 0 is the same for every job and
/// every resume of it, and is frame 0's own snapshot, so a render that
/// starts at frame 0 is meshed as before. The largest size of each
/// triangle over the animation would grid a growing object more finely,
/// but costs a snapshot of every frame before the first is rendered. The
/// price of time 0: an object that grows later is meshed as it was at 0
/// (coarser than `spacing` asks; one cell a triangle where it was scaled
/// to nothing, its corners told apart in its own space: `PassMesh::new`).
pub const MESHED_AT: f32 = 0.0;

/// What one Jacobi iteration changed: per channel, the sum over vertices
/// of the indirect light it added, and the sums of its size and of the
/// indirect light after it. Summed in order, in `f64`: where the
/// iteration stops, and the tail it then adds, must not depend on the
/// thread count.
#[derive(Clone, Copy, Debug, Default)]
struct Step {
    added: [f64; 3],
    change: f64,
    total: f64,
}

impl Step {
    /// From the iterate `before` to the iterate `after`.
    fn between(before: &[Vec3], after: &[Vec3]) -> Step {
        let mut step = Step::default();
        for (a, b) in before.iter().zip(after) {
            let d = *b - *a;
            for c in 0..3 {
                step.added[c] += f64::from(d[c]);
            }
            step.change += f64::from(d.abs().element_sum());
            step.total += f64::from(b.abs().element_sum());
        }
        step
    }

    /// Whether it changed the indirect light by at most [`CONVERGED`] of
    /// it.
    fn converged(&self) -> bool {
        self.change <= CONVERGED * self.total
    }
}

/// The bounces a Jacobi iteration stopped before, as the sum of a
/// geometric series. Each iteration adds the light of one more bounce,
/// `Δ_k = M·Δ_(k−1)`, which soon shrinks by the same factor `q` every
/// bounce (the transport's dominant eigenvalue: the scene's albedo
/// weighted by where its light goes); the bounces after the last, `Δ_k`,
/// then add `Δ_k·q/(1 − q)`. Stopping when an iteration changes the light
/// by 0.1 % ([`CONVERGED`]) left out about 0.1 % · q/(1 − q) of it: 0.9 %
/// at q = 0.9, and the cap of 64 iterations 3 % at 0.95 and 26 % at 0.98
/// (a closed box of that albedo, `tests/movies.rs`). The progressive
/// radiosity of Cohen et al. (SIGGRAPH 1988) adds the light not yet
/// shot as an ambient term for the same reason; here the vertices' own
/// last bounce carries it, so it falls where the light goes.
///
/// Taken per colour channel, and only once the factor has settled: the
/// last two iterations' ratios of the light they added agree within
/// [`SETTLED`] and lie below 1. Early on, while the light spreads from
/// the lit surfaces into the scene, the ratio moves (and may pass 1),
/// and no tail is added.
#[derive(Debug, Default)]
struct GeometricTail {
    /// The last three steps' light added, per channel (newest last).
    added: Vec<[f64; 3]>,
}

/// How closely the last two bounces' ratios must agree for
/// [`GeometricTail`] to extrapolate with them.
const SETTLED: f64 = 0.01;

impl GeometricTail {
    fn push(&mut self, step: Step) {
        if self.added.len() == 3 {
            self.added.remove(0);
        }
        self.added.push(step.added);
    }

    /// Per channel, `q/(1 − q)`, what the last iteration's change is
    /// multiplied by to give the bounces left out (`None`: no channel's
    /// factor has settled).
    fn factor(&self) -> Option<Vec3> {
        let [a, b, c] = self.added[..] else {
            return None;
        };
        let mut factor = Vec3::ZERO;
        for k in 0..3 {
            let (q0, q1) = (b[k] / a[k], c[k] / b[k]);
            let settled = a[k] > 0.0
                && b[k] > 0.0
                && (0.0..1.0).contains(&q1)
                && (q1 - q0).abs() <= SETTLED * q1;
            if settled {
                factor[k] = (q1 / (1.0 - q1)) as f32;
            }
        }
        (factor != Vec3::ZERO).then_some(factor)
    }
}

/// The diagonal of the box around `points` (1 where it is empty, flat to a
/// point or not finite).
pub(super) fn diagonal(points: impl Iterator<Item = Vec3>) -> f32 {
    crate::scene::bounding_box(points)
        .map(|(lo, hi)| (hi - lo).length())
        .filter(|d| d.is_finite() && *d > 0.0)
        .unwrap_or(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::movies::mesh::{MAX_LINKS, MIN_LINKS};

    /// The tail fed the steps of `x_(k+1) = g + q·x_k` (from 0) per
    /// channel: what it adds to the last iterate.
    fn tail_after(q: Vec3, g: Vec3, steps: usize) -> (Vec3, Option<Vec3>) {
        let mut tail = GeometricTail::default();
        let mut x = Vec3::ZERO;
        for _ in 0..steps {
            let next = g + q * x;
            tail.push(Step::between(&[x], &[next]));
            x = next;
        }
        let before = (x - g) / q;
        (x, tail.factor().map(|f| (x - before) * f))
    }

    /// On a geometric iteration the tail is the rest of the series: the
    /// iterate plus it is `g/(1 − q)`, per channel, after a few steps as
    /// after many; one or two steps (no settled ratio yet) add none.
    #[test]
    fn a_geometric_iteration_is_completed_by_its_tail() {
        let (q, g) = (Vec3::new(0.5, 0.9, 0.98), Vec3::new(1.0, 2.0, 0.5));
        for steps in [3, 8, 64] {
            let (x, added) = tail_after(q, g, steps);
            let added = added.expect("settled");
            let limit = g / (Vec3::ONE - q);
            let error = ((x + added - limit) / limit).abs().max_element();
            assert!(error < 1e-4, "{steps} steps: {x} + {added} against {limit}");
        }
        for steps in [1, 2] {
            assert!(tail_after(q, g, steps).1.is_none(), "{steps} steps");
        }
    }

    /// No tail where the ratio has not settled (the light still spreads)
    /// or is not below 1 (nothing converges); a channel that settled gets
    /// its own while one that did not gets none.
    #[test]
    fn an_unsettled_or_divergent_iteration_gets_no_tail() {
        let steps = |added: &[[f64; 3]]| {
            let mut tail = GeometricTail::default();
            for &a in added {
                tail.push(Step {
                    added: a,
                    ..Step::default()
                });
            }
            tail.factor()
        };
        assert!(steps(&[[1.0; 3], [2.0; 3], [1.0; 3]]).is_none());
        assert!(steps(&[[1.0; 3], [1.0; 3], [1.0; 3]]).is_none());
        assert!(steps(&[[1.0; 3], [0.0; 3], [0.0; 3]]).is_none());
        let mixed = steps(&[[1.0, 1.0, 4.0], [0.5, 1.0, 2.0], [0.25, 1.0, 1.0]]);
        assert_eq!(mixed, Some(Vec3::new(1.0, 0.0, 1.0)));
    }

    /// The rows kept across frames are those built again from scratch, on
    /// a scene whose moving cube changes links and open-space flags every
    /// frame; and both kinds of kept row occur (else this checks nothing).
    /// The pass a budget-breaking setting builds (the finest grid and 1024
    /// links a vertex on cube-in-box: 26 × 561 × 1024 = 15 M links asked)
    /// holds at most [`MAX_LINKS`] links, counted in the pass itself, and
    /// still solves to finite light.
    #[test]
    fn a_pass_past_the_budget_is_built_within_it() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 8);
        let settings = GlobalSettings {
            spacing: 1e-4,
            links: 1024,
            bounces: 1,
            shadow_samples: 1,
        };
        renderer.with_frame_context(0, |ctx| {
            let mut pass = GlobalPass::new(ctx, settings);
            let links = pass.links.len() as u64;
            assert!(links > MAX_LINKS / 4 && links <= MAX_LINKS, "{links}");
            pass.update(
                ctx,
                &ShadowBlockers::new(ctx, &mut Default::default()),
                true,
            );
            assert!(pass.indirect.iter().all(|e| e.is_finite()));
        });
    }

    /// A film past 128 pixels high is meshed finer, in proportion to its
    /// height ([`super::super::view::film_share`]): at 256 × 256 the
    /// spacing halves, and cube-in-box's walls, a grid each side of a
    /// triangle, hold about four times the vertices. Smaller films of
    /// one shape are meshed alike.
    #[test]
    fn a_larger_film_is_meshed_finer() {
        let vertices = |size: u32| {
            let mut renderer = crate::render::test_renderer("cube-in-box", size);
            renderer.with_frame_context(0, |ctx| {
                GlobalPass::new(ctx, GlobalSettings::default()).vertex_count()
            })
        };
        let (small, full, large) = (vertices(64), vertices(128), vertices(256));
        assert_eq!(small, full);
        let ratio = large as f64 / full as f64;
        assert!((3.0..5.0).contains(&ratio), "{full} → {large} vertices");
    }

    /// The direct light found only at the vertices links land by gives
    /// the solution found with it at every vertex, bit for bit, with fewer
    /// shadow rays: on the moving cube, at a link or two a vertex so that
    /// many vertices are landed by none.
    #[test]
    fn direct_light_at_the_landed_vertices_solves_as_at_every_one() {
        direct_light_at_the_landed_vertices_solves_as_at_every_one_in("cube-in-box");
    }

    /// The same where glossy surfaces reflect the direct light along
    /// links ([`GlobalPass::glossy_direct`], whose transmittance is found
    /// at the landed vertices only).
    #[test]
    fn glossy_light_at_the_landed_vertices_solves_as_at_every_one() {
        direct_light_at_the_landed_vertices_solves_as_at_every_one_in("glossy-cornell");
    }

    fn direct_light_at_the_landed_vertices_solves_as_at_every_one_in(scene: &str) {
        let mut renderer = crate::render::test_renderer(scene, 8);
        let settings = GlobalSettings {
            spacing: 1.0 / 12.0,
            links: 2,
            bounces: 4,
            shadow_samples: 2,
        };
        let (mut landed, mut every) = (None::<GlobalPass>, None::<GlobalPass>);
        let (mut unlanded, mut rays, mut glossy) = (0, [0, 0], false);
        for frame in 0..4 {
            renderer.with_frame_context(frame * 4, |ctx| {
                let every_vertex = |p: &GlobalPass| vec![true; p.vertices.len()];
                let ways: [fn(&GlobalPass) -> Vec<bool>; 2] = [GlobalPass::landed, every_vertex];
                for (k, (pass, direct_at)) in [(&mut landed, ways[0]), (&mut every, ways[1])]
                    .into_iter()
                    .enumerate()
                {
                    let pass = pass.get_or_insert_with(|| GlobalPass::new(ctx, settings));
                    let blockers = ShadowBlockers::new(ctx, &mut Default::default());
                    rays[k] += pass.update_lighting(ctx, &blockers, frame == 0, direct_at);
                }
                let (a, b) = (landed.as_ref().unwrap(), every.as_ref().unwrap());
                let differ = (a.indirect.iter().zip(&b.indirect)).filter(|(x, y)| x != y);
                assert_eq!(
                    differ.count(),
                    0,
                    "{scene}: vertices differing at frame {}",
                    frame * 4
                );
                assert!(a.indirect.iter().any(|e| e.max_element() > 0.0));
                unlanded += a.landed().iter().filter(|&&l| !l).count();
                glossy |= (a.links.iter().filter(|l| l.live && l.hit.is_hit())).any(|l| {
                    let material = ctx.snapshot.tri_material[l.hit.triangle as usize];
                    ctx.scene.materials[material as usize].is_glossy()
                });
            });
        }
        assert!(unlanded > 0, "{scene}: every vertex was landed by");
        assert!(rays[0] < rays[1], "{scene}: shadow rays {rays:?}");
        assert_eq!(
            glossy,
            scene == "glossy-cornell",
            "{scene}: links landing on glossy"
        );
    }

    /// The balls of `spheres` are finely tessellated: their corners are
    /// clustered, one vertex of each cluster gathering for it along links
    /// in proportion to its area and the others along none, near it and
    /// facing its way, with its light and open-space flag. The links are
    /// numbered in vertex order, and fewer than a clustered vertex each
    /// with the fewest links would take.
    #[test]
    fn fine_triangles_corners_are_clustered_and_read_their_gathering_ones_light() {
        let mut renderer = crate::render::test_renderer("spheres", 8);
        let settings = GlobalSettings {
            bounces: 4,
            shadow_samples: 1,
            ..GlobalSettings::default()
        };
        renderer.with_frame_context(0, |ctx| {
            let mut pass = GlobalPass::new(ctx, settings);
            assert!(
                pass.clustered.len() > pass.vertices.len() / 2,
                "{}",
                pass.clustered.len()
            );
            let mut first_link = 0;
            for v in &pass.vertices {
                assert_eq!(v.first_link, first_link);
                first_link += v.links;
            }
            assert_eq!(first_link as usize, pass.links.len());
            let heads: std::collections::HashSet<u32> =
                pass.clustered.iter().map(|&(_, head)| head).collect();
            let unclustered = pass.vertices.len() - pass.clustered.len() - heads.len();
            assert!(
                (pass.links.len() as u64)
                    < (pass.clustered.len() + heads.len()) as u64 * u64::from(MIN_LINKS)
                        + unclustered as u64 * u64::from(settings.links),
                "{} links",
                pass.links.len()
            );
            let point = |i: u32| {
                let v = &pass.vertices[i as usize];
                let tri = &ctx.snapshot.triangles[v.triangle as usize];
                let flip = if v.reverse { -1.0 } else { 1.0 };
                (tri.point(v.at.0, v.at.1), tri.geometric_normal() * flip)
            };
            // At most the settings' share of the whole scene's diagonal
            // (the pass's is the static part's or the view's, and within
            // the budget here).
            let spacing =
                diagonal(ctx.snapshot.triangles.iter().flat_map(|t| t.p)) * settings.spacing;
            for &(member, head) in &pass.clustered {
                let (m, h) = (
                    &pass.vertices[member as usize],
                    &pass.vertices[head as usize],
                );
                assert_eq!(m.links, 0);
                assert!(h.links >= MIN_LINKS && h.links <= settings.links);
                assert!(!heads.contains(&member));
                let ((pm, nm), (ph, nh)) = (point(member), point(head));
                assert!(pm.distance(ph) < 3f32.sqrt() * spacing, "{pm} {ph}");
                assert!(nm.dot(nh) > 0.5, "{nm} {nh}");
            }
            let blockers = ShadowBlockers::new(ctx, &mut Default::default());
            pass.update(ctx, &blockers, true);
            for &(member, head) in &pass.clustered {
                let (m, h) = (member as usize, head as usize);
                assert_eq!(
                    (pass.indirect[m], pass.valid[m]),
                    (pass.indirect[h], pass.valid[h])
                );
            }
            assert!(heads
                .iter()
                .any(|&h| pass.indirect[h as usize].max_element() > 0.0));
        });
    }

    #[test]
    fn kept_rows_equal_rows_built_again() {
        let mut renderer = crate::render::test_renderer("cube-in-box", 8);
        let settings = GlobalSettings {
            spacing: 1.0 / 12.0,
            links: 24,
            bounces: 2,
            shadow_samples: 1,
        };
        let mut pass = None::<GlobalPass>;
        let (mut kept, mut flipped) = (0, 0);
        for frame in 0..8 {
            renderer.with_frame_context(frame * 3, |ctx| {
                let pass = pass.get_or_insert_with(|| GlobalPass::new(ctx, settings));
                let valid_before = pass.valid.clone();
                let blockers = ShadowBlockers::new(ctx, &mut Default::default());
                pass.update(ctx, &blockers, frame == 0);
                let built: Vec<_> = pass.vertices.iter().map(|v| pass.row(v)).collect();
                assert_eq!(pass.rows, built, "frame {}", frame * 3);
                if frame > 0 {
                    kept += pass.links.len() - pass.traced_links as usize;
                    flipped += valid_before
                        .iter()
                        .zip(&pass.valid)
                        .filter(|(a, b)| a != b)
                        .count();
                }
            });
        }
        assert!(kept > 0, "every link was traced again");
        assert!(flipped > 0, "no open-space flag changed");
    }
}
