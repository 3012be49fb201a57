//! What the camera sees, for the global pass's mesh ([`super::global`]):
//! the size its grid spacing is a share of, the triangles that large
//! ones are split towards ([`super::pieces`]), and those whose grids'
//! vertices gather along more links ([`super::mesh`]). Looked at in the
//! scene as it stands when the pass is meshed
//! ([`MESHED_AT`](super::global::MESHED_AT)), along grids of camera rays
//! coarser than the film's pixels, at time 0 and at a few times over the
//! animation.

use super::global::diagonal;
use crate::accel::SceneBvh;
use crate::backend::Ray;
use glam::Vec3;
use std::collections::{HashMap, HashSet};

/// What the camera sees: per triangle it sees, the box around the points
/// it sees of it, and the size of what it sees at time 0 (the diagonal of
/// the box around it and those points); and the triangles it glimpses
/// along a finer grid of rays, through moving objects
/// (`Looking::glimpsed_by`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct View {
    seen: HashMap<u32, (Vec3, Vec3)>,
    size: f32,
    glimpsed: HashSet<u32>,
}

impl View {
    /// The view of a camera at `eye` that sees the points `hits`, each on
    /// its triangle; `None` where it sees nothing, or its box is flat to
    /// a point or not finite.
    pub fn new(eye: Vec3, hits: &[(u32, Vec3)]) -> Option<View> {
        let (lo, hi) = hits
            .iter()
            .fold((eye, eye), |(lo, hi), &(_, p)| (lo.min(p), hi.max(p)));
        let size = (hi - lo).length();
        if hits.is_empty() || !(size.is_finite() && size > 0.0) {
            return None;
        }
        let mut view = View {
            seen: HashMap::new(),
            size,
            glimpsed: HashSet::new(),
        };
        view.add(hits);
        Some(view)
    }

    /// Adds the points `hits` to what it sees, its size kept.
    pub fn add(&mut self, hits: &[(u32, Vec3)]) {
        for &(triangle, p) in hits {
            let b = self.seen.entry(triangle).or_insert((p, p));
            *b = (b.0.min(p), b.1.max(p));
        }
    }

    /// Adds `triangles` to those it glimpses ([`View::glimpses`]), its
    /// boxes and size kept.
    pub fn glimpse(&mut self, triangles: impl IntoIterator<Item = u32>) {
        self.glimpsed.extend(triangles);
    }

    /// Whether it glimpses `triangle`.
    pub fn glimpses(&self, triangle: u32) -> bool {
        self.glimpsed.contains(&triangle)
    }

    /// The diagonal of the box around the camera and what it sees.
    pub fn size(&self) -> f32 {
        self.size
    }

    /// The spacing wanted over the part of `triangle` in the box
    /// `(lo, hi)`: `spacing` at what the camera sees of the triangle,
    /// times `1 + d / size` at a distance `d` from it ([`View::size`]);
    /// `None` on a triangle it does not see, which is not split (hidden,
    /// it is a source of light alone, whose coarse cells the links
    /// average over).
    pub fn spacing_at(&self, spacing: f32, triangle: u32, piece: (Vec3, Vec3)) -> Option<f32> {
        let (lo, hi) = self.seen.get(&triangle)?;
        let gap = (piece.0 - *hi).max(*lo - piece.1).max(Vec3::ZERO);
        Some(spacing * (1.0 + gap.length() / self.size))
    }
}

/// Camera rays a side of the grid along which [`meshing_size`] finds what
/// the camera sees: its size, and the boxes of what it sees of the
/// triangles.
const VIEW_RAYS: u32 = 16;

/// Camera rays a side of the finer grid along which [`meshing_size`]
/// finds the triangles the camera glimpses ([`Looking::glimpsed_by`]),
/// whose grids' vertices gather along more links ([`super::mesh`]): a
/// triangle no ray meets is taken for hidden, and the first hits of
/// [`VIEW_RAYS`] a side met 26 of `l_hall`'s, those of this grid 228
/// (`benches/RESULTS.md`, "Links where the camera looks"), for about
/// 150,000 rays once a render (at time 0 and [`VIEW_TIMES`] times over
/// the animation). Not the grid the size is
/// found along: its rays reach nearer the horizon, and their far hits
/// widened the view's box, and with it the spacing (a ground 600 m across
/// seen from 2 m up: 0.020 relative RMSE against `path`, 0.049 so:
/// `tests/directional_light.rs`).
const SEEN_RAYS: u32 = 128;

/// The size the grid spacing is a share of is at most this many times
/// the diagonal of what the camera at time 0 sees ([`meshing_size`]).
const VIEW_SIZES: f32 = 2.0;

/// Films up to this many pixels high are meshed at the spacing the
/// settings give; a higher one at a spacing smaller in proportion to its
/// height ([`film_share`]).
const FULL_SPACING_PIXELS: u32 = 128;

/// The share of the size the spacing is a share of that a film `height`
/// pixels high is meshed at: 1 up to [`FULL_SPACING_PIXELS`], less in
/// proportion to the height past it (½ at 256), so that a grid cell
/// covers about as many pixels at any film size. By the height, as the
/// camera keeps its vertical field of view whatever the film's shape
/// (`Camera::direction`): the pixels an angle spans follow the height
/// alone, and a wider film sees more, not finer. (By the diagonal, as
/// first written, a film of 2048 × 8 pixels was meshed at about an
/// eleventh of the spacing and its render peaked at 632 MB, 142 MB now.)
///
/// Why: the spacing was a share of the scene's or the view's size alone,
/// so a cell was about 8 pixels across at 128 × 128 and 16 at 256 × 256, and the
/// Gouraud-interpolated light of the grid's vertices, each gathered along
/// about 60 links (the default 128 for a spacing squared of surface:
/// `GlobalSettings::links`), showed as blotches across the larger frames. On the seven
/// scenes of `benches/RESULTS.md` ("The global pass's spacing follows the
/// film") at 256 × 256 half the spacing lowered the block bias against
/// `path` by 34–55 % for 3–25 % more time; at 64 × 64 it cost 1.2–2.0
/// times the time for 8–51 % (the global pass is then most of a frame),
/// which is why the settings' spacing stays for small films.
pub(super) fn film_share(height: u32) -> f32 {
    if height <= FULL_SPACING_PIXELS {
        return 1.0; // exactly: small films keep their meshing bit for bit
    }
    (f64::from(FULL_SPACING_PIXELS) / f64::from(height)) as f32
}

/// The size the grid spacing is a share of
/// ([`GlobalSettings::spacing`](super::global::GlobalSettings::spacing)):
/// the diagonal of the static scene ([`static_diagonal`]), but at most
/// [`VIEW_SIZES`] times that of the box around the camera at time 0 and
/// what it sees of the scene (`meshed`, with `bvh` built over it) along a
/// grid of [`VIEW_RAYS`]² rays through a film of `width × height` pixels
/// (the rays that meet nothing left out), times the film's
/// [`film_share`] (by its height). And what those rays see, as the
/// [`View`] large triangles are split towards ([`super::pieces`]), with
/// the triangles a finer grid glimpses ([`SEEN_RAYS`]).
///
/// Why: a scene may reach far past what its camera looks at. A room at the
/// edge of a 2 km ground it never shows (`l_hall` so placed by
/// `benches/scenes/place.py ... ground 1000 950`, frames 0..4 at
/// 96×60) was meshed at a 32nd of 2.8 km, one cell a wall, and rendered
/// with a block bias of 33 % against `path` (at 64 spp); with this bound,
/// 1.8 % (at the origin, alone: 1.6 %). A room seen from inside has the
/// smaller diagonal (the bound is 1.6–2.0 times it in the built-in and
/// test scenes), so it is meshed as before. The sky does not lift the
/// bound: where a ray met nothing the scene's diagonal was taken, so the
/// test courtyard set on a ground 50 m across (`--ground 25` of
/// `tests/data/scenes/courtyard_swinging_light.py`), whose camera sees
/// the sky above the walls, was meshed at a 32nd of 71 m, 2.2 m, its walls
/// two cells high, and `movies` rendered it at 64×64 with 19× `ic`'s
/// block bias (0.115 against 0.0059; 0.013 now). A ray that meets
/// nothing sees nothing to mesh.
pub(super) fn meshing_size(
    scene: &crate::scene::Scene,
    meshed: &crate::scene::Snapshot,
    bvh: &SceneBvh,
    (width, height): (u32, u32),
) -> (f32, Option<View>) {
    let looking = Looking {
        bvh,
        static_count: meshed.static_count,
        aspect: width as f32 / height as f32,
    };
    let diagonal = static_diagonal(meshed);
    let camera = &meshed.camera;
    let view = View::new(camera.position, &looking.seen_by(camera));
    let size = view
        .as_ref()
        .map_or(diagonal, |view| diagonal.min(VIEW_SIZES * view.size()));
    let view = view.map(|mut view| {
        view.glimpse(looking.glimpsed_by(camera));
        seen_later(view, scene, camera, &looking)
    });
    (size * film_share(height), view)
}

/// Times over the animation, beside 0, from which the camera's view adds
/// to what large triangles are split towards and the triangles it
/// glimpses ([`seen_later`]).
const VIEW_TIMES: u32 = 8;

/// `view` with what the camera sees at [`VIEW_TIMES`] times evenly over
/// the animation (of `scene`, whose camera at time 0 is `at_zero`), seen
/// in the scene as it stands at time 0 (`looking`): a camera that travels
/// over a large ground has it split along its way, not only where it
/// starts. The meshing stays that of time 0 and of the animation alone,
/// whatever frames a render takes
/// ([`MESHED_AT`](super::global::MESHED_AT)). A camera that does not move
/// adds nothing.
fn seen_later(
    mut view: View,
    scene: &crate::scene::Scene,
    at_zero: &crate::scene::Camera,
    looking: &Looking,
) -> View {
    let duration = scene.animation.duration();
    for k in 1..=VIEW_TIMES {
        let camera = scene.camera_at(duration * k as f32 / VIEW_TIMES as f32);
        if camera.position != at_zero.position || camera.basis != at_zero.basis {
            view.add(&looking.seen_by(&camera));
            view.glimpse(looking.glimpsed_by(&camera));
        }
    }
    view
}

/// Moving surfaces a ray of the finer grid passes through
/// ([`Looking::glimpsed_by`]).
const THROUGH_MOVING: u32 = 8;

/// The scene as time 0 has it, looked at through a film: its BVH, how
/// many of its triangles are static (`0..static_count`), and the film's
/// width-to-height.
struct Looking<'a> {
    bvh: &'a SceneBvh,
    static_count: usize,
    aspect: f32,
}

impl Looking<'_> {
    /// What `camera` sees (each point with its triangle) along the grid of
    /// [`VIEW_RAYS`]² rays; the rays that meet nothing left out.
    fn seen_by(&self, camera: &crate::scene::Camera) -> Vec<(u32, Vec3)> {
        camera_rays(camera, self.aspect, VIEW_RAYS)
            .filter_map(|ray| {
                let hit = self.bvh.closest_hit(&ray);
                hit.is_hit().then(|| (hit.triangle, ray.at(hit.t)))
            })
            .collect()
    }

    /// The triangles `camera` glimpses along the finer grid of
    /// [`SEEN_RAYS`]² rays: each ray's first static triangle and the
    /// moving ones before it (up to [`THROUGH_MOVING`] of them). Why
    /// through: the meshing serves the whole animation, and a moving
    /// object hides what is behind it for a while only. And so the links
    /// of what it hides at time 0 do not depend on it: a block that jumps
    /// out of a room leaves the room's frames those of the room that never
    /// had it, bit for bit (`tests/movies.rs`).
    fn glimpsed_by(&self, camera: &crate::scene::Camera) -> HashSet<u32> {
        let mut met = HashSet::new();
        for mut ray in camera_rays(camera, self.aspect, SEEN_RAYS) {
            for _ in 0..=THROUGH_MOVING {
                let hit = self.bvh.closest_hit(&ray);
                if !hit.is_hit() {
                    break;
                }
                met.insert(hit.triangle);
                if (hit.triangle as usize) < self.static_count {
                    break;
                }
                // Past the hit by a share of its distance, so as not to
                // meet the same surface again.
                ray.tmin = hit.t + (hit.t * 1e-5).max(1e-6);
            }
        }
        met
    }
}

/// A grid of `rays`² rays from `camera` through the pixel centres of a
/// film of width-to-height `aspect` that many pixels a side.
fn camera_rays(
    camera: &crate::scene::Camera,
    aspect: f32,
    rays: u32,
) -> impl Iterator<Item = Ray> + '_ {
    let side = rays as f32;
    (0..rays * rays).map(move |i| {
        let (sx, sy) = ((i % rays) as f32 + 0.5, (i / rays) as f32 + 0.5);
        Ray::new(
            camera.position,
            camera.direction(sx / side, sy / side, aspect),
            0.0,
            f32::INFINITY,
        )
    })
}

/// The diagonal of `snapshot`'s static triangles' box (of all triangles
/// where none is static).
fn static_diagonal(snapshot: &crate::scene::Snapshot) -> f32 {
    let tris = match snapshot.static_count {
        0 => 0..snapshot.triangles.len(),
        n => 0..n,
    };
    diagonal(snapshot.triangles.range(tris).flat_map(|t| t.p))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The spacing wanted is the pass's at what the camera sees of a
    /// triangle, and grows with the distance from it; a triangle it does
    /// not see is not split.
    #[test]
    fn the_spacing_grows_with_the_distance_from_what_is_seen() {
        let hits = [
            (7, Vec3::ZERO),
            (7, Vec3::new(1.0, 0.0, 0.0)),
            (2, Vec3::new(3.0, 4.0, 0.0)),
        ];
        let view = View::new(Vec3::ZERO, &hits).unwrap();
        assert_eq!(view.size(), 5.0);
        let at = |x: f32| {
            view.spacing_at(
                0.1,
                7,
                (Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 1.0, 1.0)),
            )
        };
        assert_eq!(at(0.5), Some(0.1));
        assert!((at(6.0).unwrap() - 0.2).abs() < 1e-6);
        assert!((at(21.0).unwrap() - 0.5).abs() < 1e-6);
        assert_eq!(view.spacing_at(0.1, 3, (Vec3::ZERO, Vec3::ONE)), None);
        // A triangle glimpsed alone is not split towards; one seen along
        // the coarse grid alone is not glimpsed.
        let mut glimpsing = view.clone();
        glimpsing.glimpse([3]);
        assert!(glimpsing.glimpses(3) && !glimpsing.glimpses(7));
        assert!(!view.glimpses(3));
        assert_eq!(glimpsing.spacing_at(0.1, 3, (Vec3::ZERO, Vec3::ONE)), None);
        assert_eq!(glimpsing.size(), view.size());
        assert_eq!(View::new(Vec3::ONE, &[(0, Vec3::ONE)]), None);
        assert_eq!(View::new(Vec3::ONE, &[]), None);
    }

    /// Films up to 128 pixels high keep the settings' share, exactly; a
    /// higher one's shrinks as its height grows, whatever its width.
    #[test]
    fn a_higher_film_takes_a_smaller_share_by_its_height() {
        for h in [1, 8, 64, 128] {
            assert_eq!(film_share(h), 1.0, "{h} high");
        }
        assert_eq!(film_share(256), 0.5);
        assert_eq!(film_share(512), 0.25);
        assert_eq!(film_share(1024), 0.125);
        assert!((film_share(1080) - 128.0 / 1080.0).abs() < 1e-7);
        assert!(film_share(4096) > 0.0);
    }

    /// The two triangles of the square `[-r, r]²` at depth `z`, facing +z.
    fn square(r: f32, z: f32) -> [[Vec3; 3]; 2] {
        let [a, b, c, d] = [(-r, -r), (r, -r), (r, r), (-r, r)].map(|(x, y)| Vec3::new(x, y, z));
        [[a, b, c], [a, c, d]]
    }

    /// The triangles glimpsed from z = 5 looking down −z at, from the
    /// back: a square hidden behind a wall (2, 3 behind 0, 1), a patch in
    /// front of the wall (4, 5) and a block in front of the patch that
    /// covers it whole (6, 7), moving or not.
    fn glimpsed(block_moves: bool) -> HashSet<u32> {
        let triangles = [
            square(10.0, -1.0),
            square(1.0, -2.0),
            square(0.25, 0.0),
            square(0.5, 2.0),
        ]
        .concat();
        let scene = crate::scene::Scene::builtin("cube-in-box").unwrap();
        let mut snapshot = scene.snapshot(0.0);
        snapshot.triangles = triangles
            .iter()
            .map(|&p| crate::scene::Triangle { p, n: [Vec3::Z; 3] })
            .collect();
        snapshot.tri_object = vec![0; triangles.len()].into();
        snapshot.static_count = if block_moves { 6 } else { 8 };
        snapshot.camera.position = Vec3::new(0.0, 0.0, 5.0);
        snapshot.camera.basis = glam::Mat3::IDENTITY;
        let mut bvh = SceneBvh::new();
        bvh.update(&snapshot);
        let looking = Looking {
            bvh: &bvh,
            static_count: snapshot.static_count,
            aspect: 1.0,
        };
        looking.glimpsed_by(&snapshot.camera)
    }

    /// The finer grid's rays pass through a moving block to the static
    /// patch it covers, and stop at a static one: the patch a static
    /// block covers, and the square behind the wall, are not glimpsed.
    #[test]
    fn rays_glimpse_through_moving_triangles_to_the_first_static_one() {
        let sorted = |set: HashSet<u32>| {
            let mut ids: Vec<u32> = set.into_iter().collect();
            ids.sort_unstable();
            ids
        };
        assert_eq!(sorted(glimpsed(true)), [0, 1, 4, 5, 6, 7]);
        assert_eq!(sorted(glimpsed(false)), [0, 1, 6, 7]);
    }
}
