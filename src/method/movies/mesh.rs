//! The global pass's mesh ([`super::global`]): each solved side of a
//! triangle is a regular grid of vertices, finer for larger triangles and
//! split into pieces where it is past [`MAX_GRID`] cells an edge
//! ([`super::pieces`]); each vertex gathers along its links. The spacing
//! and the links a vertex are fitted to the pass's link budget
//! ([`MAX_LINKS`]). A texel or a link's landing reads the vertices by
//! Gouraud interpolation over the cell that holds it ([`Grid::weights`]).
//!
//! Departure, named: triangles far smaller than the spacing (a finely
//! tessellated sphere, a scanned mesh) are not each given a vertex a
//! corner that gathers: their corners are clustered, a cluster a cube of
//! the spacing (`PassMesh::cluster`), and one vertex of each gathers for
//! all. The paper's global pass is hierarchical radiosity *without*
//! clustering, and its §6.1 estimates what clustering would save; without
//! it a mesh of a million corners took the whole link budget at one link
//! a corner, and coarsened every other surface to one cell a triangle.

use super::global::GlobalSettings;
use super::pieces::{self, Cells, Piece, MAX_DEPTH};
use super::sides::ObjectCorners;
use super::view::View;
use crate::scene::{Placed, Triangle};
use glam::Vec3;
use std::collections::HashMap;

/// The finest grid: segments along a triangle's edge.
pub const MAX_GRID: u32 = 32;
/// The fewest links a vertex gathers along (unless [`MAX_LINKS`] leaves
/// fewer).
pub const MIN_LINKS: u32 = 8;
/// The most links a pass keeps: each is 72 bytes (`Link`), and adds at
/// most three 8-byte entries to its vertex's transport row, so 4 M links
/// hold at most 400 MB. The built-in scenes need 0.25–0.5 M at the defaults;
/// where a scene would need more (many triangles, or a static part so
/// small that the spacing it sets is tiny), the grids coarsen, clustering
/// more of the triangles, until they fit, rather than the pass asking for
/// gigabytes; links thin only where the clusters' fewest links are past it
/// (`PassMesh::number_links`; a vertex not clustered keeps one at least).
pub const MAX_LINKS: u64 = 1 << 22;

/// Links a grid vertex on a triangle the camera sees has, as a share of
/// those its cells' size gives it ([`Meshing::grid`]); [`UNSEEN_LINKS`] on
/// one it does not see.
///
/// Why (importance-driven refinement, as the pass already grades its
/// pieces by the view: [`super::pieces`]): a seen vertex's gather noise
/// is what a texel shows, spread by the Gouraud interpolation into
/// blotches a cell or two across, frozen across frames; an unseen
/// vertex's indirect light (its direct light is its own shadow samples')
/// reaches the frame only along the links of others, each averaging the
/// many links that land near it. Measured (`benches/RESULTS.md`, "Links
/// where the camera looks"): on six scenes at 128 × 128 the error of twice
/// the links everywhere (`l_hall` in between) for 4 % more time in all,
/// where twice the links took 12 %; at 512 × 512, where the pass's budget
/// binds (`Meshing::seen_share_within_budget`), the block bias fell by
/// 26, 32 and 8 % on the courtyard, `l_hall` and cube-in-box.
const SEEN_LINKS: f32 = 2.0;
/// Links a grid vertex on a triangle the camera does not see has, as a
/// share of those its cells' size gives it ([`SEEN_LINKS`]).
const UNSEEN_LINKS: f32 = 0.5;

/// How finely the pass meshes a snapshot: the grid spacing (world units),
/// the links of a vertex on a cell a spacing across, and the fewest links
/// of a vertex.
#[derive(Clone, Debug)]
pub(super) struct Meshing {
    spacing: f32,
    links: u32,
    min_links: u32,
    /// What the camera sees at time 0, which a triangle too large for one
    /// grid is split towards ([`super::pieces`]); `None`: it sees nothing.
    view: Option<View>,
    /// Whether the grids' links follow what the camera sees
    /// ([`SEEN_LINKS`]): not while the spacing is fitted to the budget
    /// ([`Self::fitting`]).
    by_view: bool,
    /// The share of their links grids on seen triangles have:
    /// [`SEEN_LINKS`], or less where the budget has no room for it.
    seen_share: f32,
}

impl Meshing {
    /// The settings' meshing, coarsened until
    /// [`links_needed`](Self::links_needed) is at most [`MAX_LINKS`]
    /// (`both[i]`: triangle `i` has a grid on each side; missing: one).
    pub(super) fn fitting(
        triangles: &Placed<Triangle>,
        both: &[bool],
        settings: &GlobalSettings,
        (diagonal, view): (f32, Option<View>),
    ) -> Self {
        let mut m = Meshing {
            spacing: settings.spacing.max(1e-4) * diagonal,
            links: settings.links.max(1),
            min_links: MIN_LINKS.min(settings.links).max(1),
            view,
            by_view: false,
            seen_share: SEEN_LINKS,
        };
        // Coarser spacing makes more triangles fine, clustered, and counted
        // by their area: the links needed fall with the spacing squared
        // once all are, so this ends (a cluster's rounding up to the fewest
        // links, not counted, is thinned by `PassMesh::number_links`).
        for _ in 0..64 {
            let needed = m.links_needed(triangles, both);
            if needed <= MAX_LINKS {
                break;
            }
            let excess = (needed as f64 / MAX_LINKS as f64) as f32;
            m.spacing *= excess.sqrt().max(1.1);
        }
        // The view moves links between triangles once the spacing is set,
        // and where that is past the budget the seen triangles get what
        // room is left (at least their own links), rather than the grids
        // coarsened: a finer grid lowers the error more than more links a
        // vertex (`benches/RESULTS.md`: half the spacing, block bias −34
        // to −55 % at 256 × 256; twice the links, −8 to −25 %).
        m.by_view = true;
        if m.links_needed(triangles, both) > MAX_LINKS {
            m.seen_share = m.seen_share_within_budget(triangles, both);
        }
        m
    }

    /// The largest share of their links, from 1 to [`SEEN_LINKS`], that
    /// grids on seen triangles can have with the links needed within
    /// [`MAX_LINKS`] (to a 256th of the range, by bisection; 1 where none
    /// fits). Thinning every vertex's links to fit instead
    /// (`PassMesh::number_links`) left the unseen ones a quarter of theirs
    /// where the view takes in most of a scene: cube-in-box at 512 × 512
    /// had a block bias 16 % higher than without the view, 8 % lower so
    /// (`benches/RESULTS.md`, "Links where the camera looks").
    fn seen_share_within_budget(&mut self, triangles: &Placed<Triangle>, both: &[bool]) -> f32 {
        let (mut fits, mut over) = (1.0, SEEN_LINKS);
        for _ in 0..8 {
            self.seen_share = 0.5 * (fits + over);
            match self.links_needed(triangles, both) <= MAX_LINKS {
                true => fits = self.seen_share,
                false => over = self.seen_share,
            }
        }
        fits
    }

    /// The links `triangles` need, counting each gridded triangle's
    /// corners as its own (shared corners are one vertex in the pass: an
    /// upper bound) and each fine one ([`Self::fine`]) by its area, as its
    /// cluster's gathering vertex counts it ([`PassMesh::cluster`]); twice
    /// for a triangle `both` says has a grid on each side.
    fn links_needed(&self, triangles: &Placed<Triangle>, both: &[bool]) -> u64 {
        let (gridded, fine) =
            (triangles.iter().enumerate()).fold((0u64, 0f64), |(gridded, fine), (i, t)| {
                let sides = 1 + u64::from(both.get(i).copied().unwrap_or(false));
                match self.fine(t) {
                    true => (
                        gridded,
                        fine + f64::from(self.area_links(t.area())) * sides as f64,
                    ),
                    false => (
                        gridded + self.piece_links((i as u32, t), &Piece::WHOLE) * sides,
                        fine,
                    ),
                }
            });
        gridded + fine.ceil() as u64
    }

    /// Whether `tri` is *fine*: one cell at the pass's spacing, so small
    /// that the links its grid's vertices would have in proportion to its
    /// area are fewer than the fewest a vertex has. Its corners are
    /// clustered ([`PassMesh::cluster`]) rather than each raised to the
    /// fewest links.
    pub(super) fn fine(&self, tri: &Triangle) -> bool {
        tri.longest_edge() <= self.spacing
            && self.area_links(2.0 * tri.area()) < self.min_links as f32
    }

    /// The links a vertex gathering for `area` of surface has, in
    /// proportion: `links` for a spacing squared. A grid's vertex stands
    /// for about two of its cells (a third of each of six), which `grid`
    /// counts the same way. A grid's cells are at most a spacing along
    /// their longest edge, so two of them are less than a spacing squared
    /// (half of it for right isosceles cells whose long sides are a
    /// spacing, 0.87 for equilateral ones): a grid vertex has fewer than
    /// `links`, about half on the right-angled triangles of rooms and
    /// grounds.
    fn area_links(&self, area: f32) -> f32 {
        self.links as f32 * area / (self.spacing * self.spacing)
    }

    /// The links of piece `piece` of `tri` and of the pieces it splits
    /// into.
    fn piece_links(&self, tri: (u32, &Triangle), piece: &Piece) -> u64 {
        match self.grid(tri, piece) {
            Some((n, links)) => u64::from(Grid::vertex_count(n)) * u64::from(links),
            None => (piece.children().iter())
                .map(|c| self.piece_links(tri, c))
                .sum(),
        }
    }

    /// Piece `piece` of triangle `tri`: its grid's segments an edge and
    /// links a vertex, or `None` where it is split ([`super::pieces`]): it
    /// is past [`MAX_GRID`] cells an edge at the spacing wanted where it
    /// lies. A triangle within the cap at the pass's spacing is one grid
    /// of that spacing, wherever it lies.
    fn grid(&self, (id, tri): (u32, &Triangle), piece: &Piece) -> Option<(u32, u32)> {
        let corners = piece.world_corners(tri);
        let longest = crate::scene::longest_edge(&corners);
        let mut spacing = self.spacing;
        if longest / spacing > MAX_GRID as f32 {
            let wanted = (self.view.as_ref())
                .zip(crate::scene::bounding_box(corners))
                .and_then(|(v, piece_box)| v.spacing_at(spacing, id, piece_box));
            if let Some(wanted) = wanted {
                spacing = wanted;
                if longest / spacing > MAX_GRID as f32 && piece.depth < MAX_DEPTH {
                    return None;
                }
            }
        }
        let n = ((longest / spacing).ceil() as u32).clamp(1, MAX_GRID);
        // A piece at depth d is a 4^d-th of its triangle.
        let area = tri.area() / (1u64 << (2 * piece.depth)) as f32;
        let cell = area / (n * n) as f32;
        // Links as a vertex standing for two cells of this size at the
        // spacing wanted here would have (`area_links`), times the share
        // of the pass's spacing in that spacing, squared: past what the
        // camera sees, a vertex sends its light to what it sees through a
        // solid angle that falls with the distance squared, and its noise
        // is averaged over the many links that land near it. (1 within the
        // view: a triangle within the cap keeps its links.)
        let reference_cell = 0.5 * spacing * spacing;
        let importance = (self.spacing / spacing).powi(2);
        let (share, most) = self.seen_share(id);
        let links = ((self.links as f32 * cell / reference_cell * importance * share).ceil()
            as u32)
            .clamp(self.min_links, most.max(self.min_links));
        Some((n, links))
    }

    /// The share of its links a grid's vertex on triangle `id` has, and
    /// the most it has: [`SEEN_LINKS`] times them (or what the budget
    /// leaves room for) on a triangle the camera sees ([`View::glimpses`]), [`UNSEEN_LINKS`] on one it does not; the
    /// settings' where it sees nothing, or while the spacing is fitted.
    fn seen_share(&self, id: u32) -> (f32, u32) {
        let view = self.view.as_ref().filter(|_| self.by_view);
        match view.map(|view| view.glimpses(id)) {
            Some(true) => (
                self.seen_share,
                (self.links as f32 * self.seen_share) as u32,
            ),
            Some(false) => (UNSEEN_LINKS, self.links),
            None => (1.0, self.links),
        }
    }
}

/// The regular subdivision of one triangle into `n²` cells; its vertices
/// `(a, b)`, `a + b ≤ n`, at barycentrics `(a/n, b/n)`, numbered row by
/// row. Their numbers are *slots*: a vertex shared by several triangles
/// (a mesh vertex) fills a slot in each.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Grid {
    pub n: u32,
    /// Slot of vertex (0, 0) among all the pass's slots.
    pub first: u32,
}

impl Grid {
    pub fn vertex_count(n: u32) -> u32 {
        (n + 1) * (n + 2) / 2
    }

    /// The three vertices and weights that interpolate at barycentrics
    /// `(u, v)` (Gouraud shading over the cell that holds the point).
    pub fn weights(&self, u: f32, v: f32) -> [(u32, f32); 3] {
        let n = self.n;
        let nf = n as f32;
        let (x, y) = ((u * nf).clamp(0.0, nf), (v * nf).clamp(0.0, nf));
        let a0 = (x.floor() as u32).min(n - 1);
        let b0 = (y.floor() as u32).min(n - 1 - a0);
        let (mut fx, mut fy) = (
            (x - a0 as f32).clamp(0.0, 1.0),
            (y - b0 as f32).clamp(0.0, 1.0),
        );
        let at = |a: u32, b: u32| self.first + row_start(n, b) + a;
        if fx + fy <= 1.0 || a0 + b0 + 2 > n {
            let s = fx + fy;
            if s > 1.0 {
                fx /= s;
                fy /= s;
            }
            [
                (at(a0, b0), 1.0 - fx - fy),
                (at(a0 + 1, b0), fx),
                (at(a0, b0 + 1), fy),
            ]
        } else {
            [
                (at(a0 + 1, b0 + 1), fx + fy - 1.0),
                (at(a0, b0 + 1), 1.0 - fx),
                (at(a0 + 1, b0), 1.0 - fy),
            ]
        }
    }
}

/// Where a point falls among the global pass's vertices: the three that
/// interpolate at it and their weights (Gouraud shading).
pub type Gouraud = [(u32, f32); 3];

/// Gouraud interpolation of per-vertex `values` over the vertices marked
/// `valid` alone, their weights renormalised (all three where none is
/// valid).
pub fn blend(values: &[Vec3], valid: &[bool], g: &Gouraud) -> Vec3 {
    renormalised(valid, g).fold(Vec3::ZERO, |acc, (i, w)| acc + values[i as usize] * w)
}

/// The vertices of `g` marked `valid` with their weights renormalised
/// (all three where none is valid).
pub(super) fn renormalised<'a>(
    valid: &'a [bool],
    g: &'a Gouraud,
) -> impl Iterator<Item = (u32, f32)> + 'a {
    let total: f32 = g
        .iter()
        .filter(|(i, _)| valid[*i as usize])
        .map(|(_, w)| w)
        .sum();
    let all = total <= 1e-6;
    let scale = if all { 1.0 } else { 1.0 / total };
    g.iter()
        .filter(move |(i, _)| all || valid[*i as usize])
        .map(move |&(i, w)| (i, w * scale))
}

/// Index of the first vertex of row `b` of a grid of `n` segments.
fn row_start(n: u32, b: u32) -> u32 {
    // Rows 0..b hold (n+1) + n + … + (n−b+2) vertices.
    b * (n + 1) - b * (b.max(1) - 1) / 2
}

/// Which way `normal` faces, as one of [`FACINGS`]² cells of its
/// octahedral map (the unit sphere folded onto a square): cells some 30°
/// across, so that a cluster on a ball about as small as the spacing
/// holds the corners that face about one way, not half the ball.
fn facing(normal: Vec3) -> u16 {
    let n = normal / normal.abs().element_sum().max(f32::MIN_POSITIVE);
    let folded = if n.z >= 0.0 {
        glam::Vec2::new(n.x, n.y)
    } else {
        (glam::Vec2::ONE - glam::Vec2::new(n.y, n.x).abs())
            * glam::Vec2::new(n.x.signum(), n.y.signum())
    };
    let cell = ((folded + 1.0) * 0.5 * FACINGS as f32)
        .floor()
        .clamp(glam::Vec2::ZERO, glam::Vec2::splat(FACINGS as f32 - 1.0));
    cell.y as u16 * FACINGS + cell.x as u16
}

/// Cells an edge of [`facing`]'s octahedral map.
const FACINGS: u16 = 8;

/// The pass's vertices over the grids of a snapshot's triangles.
pub(super) struct PassMesh {
    /// Per triangle, its cells.
    pub(super) grids: Vec<Cells>,
    /// Per triangle solved on both sides, the cells of the side opposite
    /// its first cells'.
    pub(super) reverse_grids: Vec<Option<Cells>>,
    /// The pieces of the triangles split ([`Cells::Split`]).
    pub(super) pieces: Vec<Cells>,
    /// The vertex in each slot of the grids.
    pub(super) vertex_of: Vec<u32>,
    pub(super) vertices: Vec<Vertex>,
    /// The links of all vertices: at most `MAX_LINKS`, or three a
    /// triangle, so within `u32`.
    pub(super) link_count: u32,
    /// Each vertex of a cluster but the one that gathers for it, and that
    /// one ([`Self::cluster`]).
    pub(super) clustered: Vec<(u32, u32)>,
    /// Per vertex while the grids are made: the area it stands for of the
    /// fine triangles it is a corner of (a third of each), `None` where a
    /// triangle not fine has it too.
    fine_area: Vec<Option<f32>>,
}

impl PassMesh {
    /// The grids of `snapshot`'s triangles (`corners_in_object`: their
    /// corners in their objects' own space), a second one on the triangles
    /// `both` names, the corners of fine ones clustered within each
    /// component (`component`: per triangle, its [`super::sides`]
    /// component).
    pub(super) fn new(
        snapshot: &crate::scene::Snapshot,
        (corners_in_object, component): (&[ObjectCorners], &[u32]),
        meshing: &Meshing,
        both: &[bool],
    ) -> Self {
        let mut mesh = PassMesh {
            grids: Vec::with_capacity(snapshot.triangles.len()),
            reverse_grids: Vec::with_capacity(snapshot.triangles.len()),
            pieces: Vec::new(),
            vertex_of: Vec::new(),
            vertices: Vec::new(),
            link_count: 0,
            clustered: Vec::new(),
            fine_area: Vec::new(),
        };
        // Mesh vertices: a triangle corner at the same point of the same
        // object with the same shading normal (on the same side) is one
        // vertex, so that the Gouraud shading is continuous across the
        // mesh and a finely tessellated object (a sphere) has a vertex per
        // mesh vertex, not three per triangle. Keyed by object, not by
        // component ([`SolvedSides`]): parts of one object that touch only
        // at corners (a chair's leg flush with its seat) share those
        // vertices, which keying by component would split (`chairs-room`:
        // 780 corner vertices instead of 732). Where such parts have their
        // sides solved apart, a shared corner gathers on the side of the
        // part that made it first. Where an animation scales an object to
        // nothing (in some direction) at time 0, its corners are compared
        // in its own space: placed, they are all at one point then, with
        // no normal, and made one vertex for all its faces (a box grown
        // from nothing, once grown, was 76 % off `path` in its corner of
        // the frame, now 4.4 %: `tests/movies.rs`).
        let mut corners: HashMap<CornerKey, u32> = HashMap::new();
        let mut add = |mesh: &mut PassMesh, id: usize, reverse: bool| {
            let at = &corners_in_object[id].1;
            mesh.add_cells(snapshot, at, meshing, &mut corners, id, reverse)
        };
        for id in 0..snapshot.triangles.len() {
            let grid = add(&mut mesh, id, false);
            mesh.grids.push(grid);
            let reverse = both.get(id).copied().unwrap_or(false);
            let reverse = reverse.then(|| add(&mut mesh, id, true));
            mesh.reverse_grids.push(reverse);
        }
        mesh.cluster(snapshot, meshing, component);
        mesh.number_links();
        mesh
    }

    /// Clusters the vertices that only fine triangles have
    /// ([`Meshing::fine`]): those of one component, on one side, facing
    /// about one way (their triangle's normal in one cell of [`facing`])
    /// and within one cube a spacing across (time 0's places)
    /// are a cluster. Its vertex nearest its centre gathers for all, along
    /// links in proportion to their area as a grid's vertex has; the others gather
    /// along none and take its light ([`Self::clustered`]). Keyed by
    /// component, the cluster's sides are solved together; by facing, the
    /// two sides of a thin part, or a box's faces meeting at an edge, are
    /// apart.
    fn cluster(&mut self, snapshot: &crate::scene::Snapshot, meshing: &Meshing, component: &[u32]) {
        let place = |v: &Vertex| {
            let tri = &snapshot.triangles[v.triangle as usize];
            (tri.point(v.at.0, v.at.1), tri.geometric_normal())
        };
        let mut index: HashMap<(u32, bool, [i32; 3], u16), usize> = HashMap::new();
        let mut clusters: Vec<Vec<u32>> = Vec::new();
        for (i, v) in self.vertices.iter().enumerate() {
            if self.fine_area[i].is_none() {
                continue;
            }
            let (p, normal) = place(v);
            let normal = if v.reverse { -normal } else { normal };
            let cube = (p / meshing.spacing).floor().as_ivec3().to_array();
            let key = (
                component[v.triangle as usize],
                v.reverse,
                cube,
                facing(normal),
            );
            let k = *index.entry(key).or_insert_with(|| {
                clusters.push(Vec::new());
                clusters.len() - 1
            });
            clusters[k].push(i as u32);
        }
        for members in clusters {
            let area = |i: u32| self.fine_area[i as usize].unwrap_or(0.0);
            let total: f32 = members.iter().map(|&i| area(i)).sum();
            // The area-weighted centre (the mean place where the cluster
            // has no area), and the vertex nearest it gathers: a first
            // vertex in mesh order sat at a cube's corner, and the light it
            // gathered there was off the cluster's mean (a room of tiny
            // triangles read 0.5 % dark against `path`).
            let weight = |i: u32| if total > 0.0 { area(i) } else { 1.0 };
            let centre = members
                .iter()
                .map(|&i| place(&self.vertices[i as usize]).0 * weight(i))
                .sum::<Vec3>()
                / members.iter().map(|&i| weight(i)).sum::<f32>();
            let distance = |i: u32| place(&self.vertices[i as usize]).0.distance_squared(centre);
            let head = (members.iter().copied())
                .min_by(|&a, &b| distance(a).total_cmp(&distance(b)).then(a.cmp(&b)))
                .expect("a cluster has a vertex");
            for &m in members.iter().filter(|&&m| m != head) {
                self.clustered.push((m, head));
                self.fine_area[m as usize] = Some(0.0);
            }
            self.fine_area[head as usize] = Some(total);
        }
        for (v, area) in self.vertices.iter_mut().zip(&self.fine_area) {
            if let Some(area) = area {
                v.links = (meshing.area_links(*area).ceil() as u32)
                    .clamp(meshing.min_links, meshing.links);
            }
        }
        for &(member, _) in &self.clustered {
            self.vertices[member as usize].links = 0;
        }
        self.fine_area = Vec::new();
    }

    /// Numbers the vertices' links in vertex order, thinned first where
    /// they are past [`MAX_LINKS`] (the budget counts a cluster by its
    /// area, not the fewest links it has: [`Meshing::links_needed`]).
    fn number_links(&mut self) {
        let total: u64 = self.vertices.iter().map(|v| u64::from(v.links)).sum();
        if total > MAX_LINKS {
            let scale = MAX_LINKS as f64 / total as f64;
            for v in self.vertices.iter_mut().filter(|v| v.links > 0) {
                v.links = ((f64::from(v.links) * scale) as u32).max(1);
            }
        }
        let mut next = 0;
        for v in &mut self.vertices {
            v.first_link = next;
            next += v.links;
        }
        self.link_count = next;
    }

    /// Adds the cells of triangle `id` (its corners `at` in its object's
    /// space) on its first side, or with `reverse` on the other: one grid,
    /// or the pieces it is split into ([`super::pieces`]).
    fn add_cells(
        &mut self,
        snapshot: &crate::scene::Snapshot,
        at: &[(Vec3, Vec3); 3],
        meshing: &Meshing,
        corners: &mut HashMap<CornerKey, u32>,
        id: usize,
        reverse: bool,
    ) -> Cells {
        let mut side = GridSide {
            snapshot,
            at,
            corners,
            // The vertices on the pieces' edges, by their barycentrics.
            edges: HashMap::new(),
            id,
            reverse,
        };
        self.add_piece(&mut side, meshing, &Piece::WHOLE)
    }

    /// Adds `piece` of a triangle side: its grid where `meshing` grids it
    /// whole, else its four children's cells (in `pieces`, their
    /// descendants after them).
    fn add_piece(&mut self, side: &mut GridSide, meshing: &Meshing, piece: &Piece) -> Cells {
        let tri = &side.snapshot.triangles[side.id];
        if let Some((n, links)) = meshing.grid((side.id as u32, tri), piece) {
            let fine = *piece == Piece::WHOLE && meshing.fine(tri);
            return Cells::Grid(self.add_grid(side, piece, (n, links), fine));
        }
        let first = self.pieces.len();
        self.pieces.extend([Cells::Split(0); 4]);
        for (k, child) in piece.children().iter().enumerate() {
            self.pieces[first + k] = self.add_piece(side, meshing, child);
        }
        Cells::Split(first as u32)
    }

    /// Adds the grid of `n` segments an edge over `piece` of a triangle
    /// side, `links` a vertex: its slots, and the vertices they do not
    /// share. `fine`: the triangle is fine ([`Meshing::fine`]), its
    /// vertices clustered unless another triangle has them too.
    fn add_grid(
        &mut self,
        side: &mut GridSide,
        piece: &Piece,
        (n, links): (u32, u32),
        fine: bool,
    ) -> Grid {
        let GridSide {
            snapshot,
            at,
            id,
            reverse,
            ..
        } = *side;
        let tri = &snapshot.triangles[id];
        let grid = Grid {
            n,
            first: self.vertex_of.len() as u32,
        };
        let object = snapshot.tri_object[id];
        let placing = snapshot.object_to_world[object as usize].determinant();
        let collapsed = placing == 0.0 || !placing.is_finite();
        // Not clustered where the object is collapsed: its corners, all at
        // one point, are told apart in its own space only.
        let fine = fine && !collapsed;
        let third = tri.area() / 3.0;
        for b in 0..=n {
            for a in 0..=n - b {
                let point = piece.grid_point(n, a, b);
                let mut new_vertex = || {
                    self.vertices.push(Vertex {
                        triangle: id as u32,
                        at: point,
                        reverse,
                        links,
                        // Numbered once the mesh is clustered.
                        first_link: 0,
                    });
                    self.vertices.len() as u32 - 1
                };
                // Triangle corners and piece edges lie on a grid's edge.
                let on_edge = a == 0 || b == 0 || a + b == n;
                let corner = (Piece::WHOLE.corners.iter())
                    .position(|&c| on_edge && pieces::bits(c) == pieces::bits(point));
                let vertex = match corner {
                    Some(k) => {
                        let (p, n) = if collapsed {
                            at[k]
                        } else {
                            (tri.p[k], tri.n[k])
                        };
                        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                        *side
                            .corners
                            .entry((object, bits(p), bits(n), reverse, collapsed))
                            .or_insert_with(new_vertex)
                    }
                    None if on_edge && *piece != Piece::WHOLE => *side
                        .edges
                        .entry(pieces::bits(point))
                        .or_insert_with(new_vertex),
                    None => new_vertex(),
                };
                self.vertex_of.push(vertex);
                self.fine_area.resize(self.vertices.len(), Some(0.0));
                let area = &mut self.fine_area[vertex as usize];
                *area = area.filter(|_| fine).map(|a| a + third);
            }
        }
        grid
    }
}

/// The side of a triangle [`PassMesh::add_cells`] grids, and the vertices
/// its grids share.
struct GridSide<'a> {
    snapshot: &'a crate::scene::Snapshot,
    /// The triangle's corners in its object's own space.
    at: &'a [(Vec3, Vec3); 3],
    /// The mesh's vertices at triangle corners.
    corners: &'a mut HashMap<CornerKey, u32>,
    /// The vertices on the edges of its pieces, by their barycentrics'
    /// bits.
    edges: HashMap<(u32, u32), u32>,
    id: usize,
    reverse: bool,
}

/// A mesh vertex of the pass: object, position and normal (their bits),
/// the side, and whether the position and normal are in the object's own
/// space (its transform is singular at time 0) rather than placed.
type CornerKey = (u32, [u32; 3], [u32; 3], bool, bool);

/// Where a vertex of the pass lies: a triangle and its barycentrics there
/// (for a vertex shared by several triangles, the first of them).
#[derive(Clone, Copy, Debug)]
pub(super) struct Vertex {
    pub(super) triangle: u32,
    pub(super) at: (f32, f32),
    /// On the side opposite its triangle's first grid's (a triangle
    /// solved on both sides).
    pub(super) reverse: bool,
    pub(super) links: u32,
    /// Index of its first link.
    pub(super) first_link: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every facing cell is some direction's, and two directions in one
    /// cell are within 60° of each other (over a dense set of directions).
    #[test]
    fn one_facing_cell_holds_directions_about_one_way() {
        let dirs: Vec<Vec3> = (0..200)
            .flat_map(|i| (0..100).map(move |j| (i, j)))
            .map(|(i, j)| {
                let phi = i as f32 / 200.0 * std::f32::consts::TAU;
                let z = (j as f32 + 0.5) / 50.0 - 1.0;
                let r = (1.0 - z * z).sqrt();
                Vec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .chain([Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z])
            .collect();
        let mut cells: HashMap<u16, Vec<Vec3>> = HashMap::new();
        for d in dirs {
            cells.entry(facing(d)).or_default().push(d);
        }
        assert_eq!(cells.len(), usize::from(FACINGS * FACINGS));
        for (cell, dirs) in &cells {
            let widest = (dirs
                .iter()
                .flat_map(|a| dirs.iter().map(move |b| a.dot(*b))))
            .fold(1.0f32, f32::min);
            assert!(
                widest > 0.5,
                "cell {cell}: directions {widest} apart (cosine)"
            );
        }
    }

    /// A scene within the budget keeps the settings' meshing; one far over
    /// it (a static part a thousandth of its size, so a tiny spacing; or
    /// more triangles than the budget has links) is coarsened to fit.
    #[test]
    fn meshing_fits_the_link_budget() {
        let settings = GlobalSettings::default();
        let quad = |x: f32, size: f32| crate::scene::Triangle {
            p: [
                Vec3::new(x, 0.0, 0.0),
                Vec3::new(x + size, 0.0, 0.0),
                Vec3::new(x, size, 0.0),
            ],
            n: [Vec3::Z; 3],
        };
        let room: Placed<_> = (0..100)
            .map(|i| quad(i as f32, 1.0))
            .collect::<Vec<_>>()
            .into();
        let m = Meshing::fitting(&room, &[], &settings, (10.0, None));
        assert_eq!(
            (m.spacing, m.links, m.min_links),
            (10.0 / 32.0, 128, MIN_LINKS)
        );
        // A triangle solved on both sides needs its links twice.
        let one_side = m.links_needed(&room, &[]);
        let half: Vec<bool> = (0..100).map(|i| i % 2 == 0).collect();
        assert_eq!(m.links_needed(&room, &half), one_side * 3 / 2);
        let tiny_static = Meshing::fitting(&room, &[], &settings, (0.01, None));
        assert!(tiny_static.links_needed(&room, &[]) <= MAX_LINKS);
        let both = vec![true; room.len()];
        let tiny_both = Meshing::fitting(&room, &both, &settings, (0.01, None));
        assert!(tiny_both.links_needed(&room, &both) <= MAX_LINKS);
        assert!(
            Meshing {
                spacing: 0.01 / 32.0,
                ..m
            }
            .links_needed(&room, &[])
                > MAX_LINKS
        );
        // A million triangles a thousandth of the spacing: fine, counted by
        // their area, the settings' meshing kept.
        let many: Vec<_> = (0..1_000_000)
            .map(|i| quad(i as f32 * 1e-3, 1e-3))
            .collect();
        let many: Placed<_> = many.into();
        let kept = Meshing::fitting(&many, &[], &settings, (1000.0, None));
        assert_eq!((kept.spacing, kept.links), (1000.0 / 32.0, 128));
        let area = 1e6 * 0.5e-6;
        let by_area = 128.0 * area / (kept.spacing * kept.spacing);
        assert_eq!(kept.links_needed(&many, &[]), by_area.ceil() as u64);
        // Two million triangles a spacing across, one cell each but not
        // fine: the spacing coarsens until they are, the links a vertex
        // kept.
        let coarse: Placed<_> = (0..2_000_000)
            .map(|i| quad(i as f32 * 10.0, 10.0))
            .collect::<Vec<_>>()
            .into();
        let clustered = Meshing::fitting(&coarse, &[], &settings, (320.0, None));
        assert!(clustered.spacing > 10.0, "{clustered:?}");
        assert!(clustered.fine(&coarse[0]), "{clustered:?}");
        assert_eq!((clustered.links, clustered.min_links), (128, MIN_LINKS));
        assert!(clustered.links_needed(&coarse, &[]) <= MAX_LINKS);
    }

    /// A triangle 600 m across that the camera sees near its corner is
    /// split there into pieces gridded at the pass's spacing and left
    /// coarse far away; one it does not see, as large, is one grid; and the
    /// budget counts the pieces' links.
    #[test]
    fn a_large_triangle_is_split_where_it_is_seen() {
        let big = |y: f32| Triangle {
            p: [
                Vec3::new(0.0, y, 0.0),
                Vec3::new(600.0, y, 0.0),
                Vec3::new(0.0, y, 600.0),
            ],
            n: [Vec3::Y; 3],
        };
        let triangles: Placed<_> = [big(0.0), big(-1.0)].into_iter().collect();
        let hits: Vec<(u32, Vec3)> = (0..4)
            .map(|i| (0, Vec3::new(1.0 + i as f32, 0.0, 2.0)))
            .collect();
        let view = View::new(Vec3::new(0.0, 2.0, 0.0), &hits).map(|mut view| {
            view.glimpse([0]);
            view
        });
        let settings = GlobalSettings::default();
        let m = Meshing::fitting(&triangles, &[], &settings, (8.0, view));
        assert_eq!(m.spacing, 8.0 / 32.0);
        assert_eq!(m.grid((0, &triangles[0]), &Piece::WHOLE), None);
        assert_eq!(
            m.grid((1, &triangles[1]), &Piece::WHOLE).map(|(n, _)| n),
            Some(MAX_GRID)
        );
        // Down to the piece that holds a seen point: cells a spacing
        // across at most there.
        let mut piece = Piece::WHOLE;
        let (n, links) = loop {
            match m.grid((0, &triangles[0]), &piece) {
                Some(grid) => break grid,
                None => piece = piece.children()[0],
            }
        };
        let c = piece.world_corners(&triangles[0]);
        let longest = (c[1] - c[0])
            .length()
            .max((c[2] - c[0]).length())
            .max((c[2] - c[1]).length());
        assert!(
            longest / n as f32 <= m.spacing,
            "{piece:?}: {n} cells of {longest}"
        );
        // As many links as a seen triangle within the cap would get for
        // cells of that area.
        let cell = 600.0 * 600.0 / 2.0 / 4f32.powi(piece.depth as i32) / (n * n) as f32;
        let by_area = settings.links as f32 * cell / (0.5 * m.spacing * m.spacing);
        assert_eq!(links, (by_area * SEEN_LINKS).ceil() as u32);
        // The far corner: one coarse piece, fewer links a vertex.
        let far = Piece::WHOLE.children()[1];
        let (far_n, far_links) = m.grid((0, &triangles[0]), &far).expect("far piece whole");
        assert!(
            far_n <= MAX_GRID && far_links < links,
            "{far_n} {far_links}"
        );
        // The unseen one's cells are far larger than a spacing squared:
        // the most links a vertex has, half of them or not.
        let seen_only = m.piece_links((0, &triangles[0]), &Piece::WHOLE);
        assert_eq!(
            m.links_needed(&triangles, &[]),
            seen_only + Grid::vertex_count(MAX_GRID) as u64 * 128
        );
        assert!(seen_only > Grid::vertex_count(MAX_GRID) as u64 * 128);
    }

    /// Of two like triangles, the one the camera sees has its grid's
    /// vertices gather along [`SEEN_LINKS`] times the links a view-less
    /// meshing gives (up to that many times the settings'), the other
    /// [`UNSEEN_LINKS`] times (down to the fewest), and the budget counts
    /// what each has. (A fine triangle's corners are clustered and
    /// gather by their area, seen or not.)
    #[test]
    fn a_seen_triangle_gathers_along_more_links_than_a_hidden_one() {
        let tri = |z: f32, legs: f32| Triangle {
            p: [
                Vec3::new(0.0, 0.0, z),
                Vec3::new(legs, 0.0, z),
                Vec3::new(0.0, legs, z),
            ],
            n: [Vec3::Z; 3],
        };
        let settings = GlobalSettings::default();
        let eye = Vec3::new(0.0, 0.0, 1.0);
        let sees_first = || {
            let mut view = View::new(eye, &[(0, Vec3::new(0.01, 0.01, 0.0))])?;
            view.glimpse([0]);
            Some(view)
        };
        assert!(sees_first().is_some_and(|v| v.glimpses(0) && !v.glimpses(1)));
        let spacing = 10.0 / 32.0;
        // Cells of 0.22, 0.25 and 0.125 spacings squared: 57, 64 and 32
        // links by their area.
        for legs in [4.0, 12.0, 1.0] {
            let legs = legs * spacing;
            let triangles: Placed<_> = [tri(0.0, legs), tri(-1.0, legs)].into_iter().collect();
            let viewed = Meshing::fitting(&triangles, &[], &settings, (10.0, sees_first()));
            let blind = Meshing::fitting(&triangles, &[], &settings, (10.0, None));
            let grid = |m: &Meshing, id: u32| {
                m.grid((id, &triangles[id as usize]), &Piece::WHOLE)
                    .expect("within the cap")
            };
            let (n, links) = grid(&blind, 0);
            assert_eq!(grid(&blind, 1), (n, links));
            let by_area = settings.links as f32 * (legs * legs / 2.0 / (n * n) as f32)
                / (0.5 * spacing * spacing);
            let within =
                |share: f32, most: u32| ((by_area * share).ceil() as u32).clamp(MIN_LINKS, most);
            assert_eq!(links, within(1.0, settings.links), "legs {legs}");
            let (seen, hidden) = (grid(&viewed, 0), grid(&viewed, 1));
            assert_eq!(seen, (n, within(SEEN_LINKS, 2 * settings.links)));
            assert_eq!(hidden, (n, within(UNSEEN_LINKS, settings.links)));
            assert!(seen.1 > 3 * hidden.1, "legs {legs}: {seen:?} {hidden:?}");
            let vertices = u64::from(Grid::vertex_count(n));
            assert_eq!(
                viewed.links_needed(&triangles, &[]),
                vertices * u64::from(seen.1 + hidden.1)
            );
        }
        // Past the budget, the view moves links but does not coarsen the
        // grids: the spacing is the one fitted without it, and the seen
        // triangles get what room is left.
        let many: Placed<_> = (0..40_000)
            .map(|i| tri(i as f32, 4.0 * spacing))
            .collect::<Vec<_>>()
            .into();
        let glimpsed = || {
            let mut view = sees_first()?;
            view.glimpse(0..20_000);
            Some(view)
        };
        let viewed = Meshing::fitting(&many, &[], &settings, (10.0, glimpsed()));
        let blind = Meshing::fitting(&many, &[], &settings, (10.0, None));
        assert!(blind.spacing > spacing, "{blind:?}");
        assert_eq!(viewed.spacing, blind.spacing);
        assert!(viewed.links_needed(&many, &[]) <= MAX_LINKS);
        let (seen, hidden) = (
            viewed.grid((0, &many[0]), &Piece::WHOLE).unwrap(),
            viewed.grid((30_000, &many[30_000]), &Piece::WHOLE).unwrap(),
        );
        let own = blind.grid((0, &many[0]), &Piece::WHOLE).unwrap();
        assert!(seen.1 > own.1 && seen.1 < 2 * own.1, "{seen:?} {own:?}");
        assert_eq!(hidden.1, (own.1 as f32 * UNSEEN_LINKS).ceil() as u32);
    }

    #[test]
    fn grid_rows_number_every_vertex_once() {
        for n in 1..=MAX_GRID {
            let mut seen = vec![false; Grid::vertex_count(n) as usize];
            for b in 0..=n {
                for a in 0..=n - b {
                    let i = (row_start(n, b) + a) as usize;
                    assert!(!seen[i], "n {n}: ({a}, {b}) numbered twice");
                    seen[i] = true;
                }
            }
            assert!(seen.iter().all(|&s| s), "n {n}");
        }
    }

    /// Gouraud interpolation of a linear function is exact, everywhere in
    /// the triangle, its edges and corners included.
    #[test]
    fn grid_interpolation_reproduces_a_linear_function() {
        for n in 1..=5 {
            let grid = Grid { n, first: 0 };
            let identity: Vec<u32> = (0..Grid::vertex_count(n)).collect();
            let valid = vec![true; identity.len()];
            let f = |u: f32, v: f32| Vec3::new(1.0 + 2.0 * u - 3.0 * v, u, v);
            let mut values = vec![Vec3::ZERO; Grid::vertex_count(n) as usize];
            for b in 0..=n {
                for a in 0..=n - b {
                    values[(row_start(n, b) + a) as usize] =
                        f(a as f32 / n as f32, b as f32 / n as f32);
                }
            }
            for i in 0..=20 {
                for j in 0..=20 - i {
                    let (u, v) = (i as f32 / 20.0, j as f32 / 20.0);
                    let g = grid
                        .weights(u, v)
                        .map(|(slot, w)| (identity[slot as usize], w));
                    let got = blend(&values, &valid, &g);
                    assert!(
                        (got - f(u, v)).abs().max_element() < 1e-4,
                        "n {n} at ({u}, {v}): {got}"
                    );
                }
            }
        }
    }
}
