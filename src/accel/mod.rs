//! Acceleration structures over the triangles of one frame, built with
//! obvhs. The scene is split in two BVHs: the static triangles (built once
//! per render, rebuilt only if they change) and the dynamic ones (rebuilt
//! every frame — dynamic parts are small; `cargo bench --bench rays`
//! measures the rebuild). The static one is shared with a method that
//! built the same triangles' BVH for its own rays ([`StaticGeometry`]). A
//! ray is traced through both and keeps the nearer hit. A small static part is not worth a second traversal per ray: up to
//! [`MERGE_STATIC_TRIANGLES`] static triangles, a frame with moving parts
//! gets one BVH over all its triangles ([`static_part_len`], the rule the
//! GPU backend splits by too).
//!
//! Methods that look at many times at once trace the moving objects as
//! instances instead ([`MovingObjects`], [`Instances`]).
//!
//! We use obvhs's compressed wide BVH (CWBVH, Ylitie et al. 2017) on the CPU:
//! STACK.md measured it faster than BVH2 for incoherent rays.

mod instances;

pub use instances::{Instances, MovingObjects};

use crate::backend::{Hit, Ray};
use crate::scene::Snapshot;
use glam::{UVec2, Vec3A, Vec4};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::triangle::Triangle as ObTriangle;
use obvhs::BvhBuildParams;
use std::ops::Range;
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::time::{Duration, Instant};

/// One BVH over a subset of the snapshot's triangles, with the triangles
/// stored in BVH leaf order so traversal reads them contiguously.
pub struct TriangleBvh {
    bvh: CwBvh,
    triangles: Vec<ObTriangle>,
    /// Snapshot triangle id of each BVH-ordered triangle.
    ids: Vec<u32>,
    /// Object id of each BVH-ordered triangle.
    objects: Vec<u32>,
}

fn to_obvhs(tri: &crate::scene::Triangle) -> ObTriangle {
    ObTriangle {
        v0: tri.p[0].into(),
        v1: tri.p[1].into(),
        v2: tri.p[2].into(),
    }
}

/// How far back along a ray, in its `t` units, traversal starts it: `t`
/// inside the BVHs is the ray's own `t` plus this (`to_obvhs_ray`).
///
/// Why: obvhs 0.4's CWBVH culls every child box a ray leaves before
/// `t = 1e-4` whatever the ray's `tmin` (`cwbvh::node::EPSILON`, applied in
/// `CwBvhNode::intersect_ray`), so a triangle nearer than that was missed
/// wherever its leaf's box ends there too: a flat wall met within 1e-4.
/// Gather rays of records on a room's edge (`ic::off_the_edge`: at
/// 256 × 256 on `cube-in-box`, 4e-5 off the other wall) passed through it,
/// and those records came out 4–14 % dark. Started twice that cut behind
/// the ray's origin, with `tmin` and `tmax` moved along, every box the ray
/// meets in its own `[tmin, tmax]` is left at `t ≥ 2e-4` and kept, and what
/// lies behind its origin is still out of range. The GPU's traversals
/// shift their rays alike (`shaders/ray_common.wgsl`), so both backends
/// keep finding the same hits.
///
/// What it costs: the moved origin is rounded at the scale of
/// `2e-4 · |dir|` as well as of the origin. Gather and camera rays have
/// unit directions, and a shadow segment is as long as the way to its light, so
/// that rounding stays far below the rays' offset from their surface
/// ([`crate::integrator::RayOffset`]: 1e-4 of the coordinates and of the
/// scene's size up to a unit) in a scene over
/// [`crate::scene::SMALLEST_SCENE`] across; only a light some 1e7 times
/// farther than the point's own coordinates could see its shadow rays
/// start behind the surface they leave.
pub const NEAR_SHIFT: f32 = 2e-4;

/// `ray` as obvhs traverses it: its origin moved back by [`NEAR_SHIFT`]
/// (in units of its direction) and its range moved along. Public for the
/// ray benchmark, whose obvhs BVH2 baseline takes the same rays
/// (`benches/rays.rs`).
pub fn to_obvhs_ray(ray: &Ray) -> obvhs::ray::Ray {
    // `+ 0.0` turns −0.0 components into +0.0. obvhs 0.4 takes the slab
    // order from `direction < 0.0` (false for −0.0) but the inverse from
    // `signum` (−1 for −0.0): with a −0.0 component the two disagree and the
    // ray misses every box, e.g. `-n` for an axis-aligned normal `n`.
    let dir = Vec3A::from_array(ray.dir) + Vec3A::ZERO;
    obvhs::ray::Ray::new(
        Vec3A::from_array(ray.origin) - dir * NEAR_SHIFT,
        dir,
        ray.tmin + NEAR_SHIFT,
        ray.tmax + NEAR_SHIFT,
    )
}

/// A ray prepared for the watertight ray/triangle test of Woop, Benthin &
/// Wald ("Watertight Ray/Triangle Intersection", JCGT 2013, §3): the
/// triangle is moved into a space where the ray starts at the origin and
/// runs along +z, and the ray crosses it where the 2D edge functions `U`,
/// `V`, `W` of its projected vertices agree in sign.
///
/// Why not Möller–Trumbore: its edge tests are computed from each
/// triangle's own edge vectors, so a ray through an edge two triangles
/// share can fail both (at 128 × 128, two camera rays of `cube-in-box`
/// passed between a wall's two triangles and left the closed room). Here
/// the edge function of a shared edge is the same products of the same
/// projected vertices in both triangles, so its two values are exact
/// negatives of each other: the ray is inside one triangle or the other,
/// or on the edge and inside both (§3.2). The paper's fallback to double
/// precision where an edge function rounds to 0 only sharpens that edge
/// case (it does not make the test watertight), and WGSL has no `f64`: we
/// leave it out on both backends, so that they compute the same bits.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    origin: Vec3A,
    /// The axes `kx`, `ky`, `kz` of the ray's space (`kz`: the direction's
    /// largest component).
    axes: [usize; 3],
    /// `Sx`, `Sy`, `Sz` of the paper's shear.
    shear: [f32; 3],
}

impl ShearedRay {
    pub fn new(ray: &obvhs::ray::Ray) -> ShearedRay {
        let d = ray.direction.to_array();
        let a = d.map(f32::abs);
        // The largest component, lower axis first on a tie (the GPU's rule).
        let kz = if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        // Keeps the triangles' winding in the ray's space (§3.1).
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        ShearedRay {
            origin: ray.origin,
            axes: [kx, ky, kz],
            shear: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
        }
    }

    /// Where the ray crosses `tri`: `(t, u, v)` with the hit at
    /// `v0·(1−u−v) + v1·u + v2·v`, or `None` outside `[tmin, tmax]`. Rays
    /// along the plane of the triangle never hit. The paper's test (§3)
    /// without back-face culling.
    #[inline(always)]
    pub fn intersect(&self, tri: &ObTriangle, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.axes;
        let [sx, sy, sz] = self.shear;
        let project = |v: Vec3A| {
            let p = (v - self.origin).to_array();
            (p[kx] - sx * p[kz], p[ky] - sy * p[kz], sz * p[kz])
        };
        let (ax, ay, az) = project(tri.v0);
        let (bx, by, bz) = project(tri.v1);
        let (cx, cy, cz) = project(tri.v2);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let inv_det = 1.0 / det;
        let t = (u * az + v * bz + w * cz) * inv_det;
        // `U` weighs `v0`, `V` `v1` and `W` `v2`.
        (t >= tmin && t <= tmax).then_some((t, v * inv_det, w * inv_det))
    }
}

/// [`ShearedRay::intersect`] for one triangle: `(t, u, v)` with the hit at
/// `v0·(1−u−v) + v1·u + v2·v`, or `None` outside `[tmin, tmax]`. Traversals
/// prepare their ray once instead.
pub fn intersect_triangle(tri: &ObTriangle, ray: &obvhs::ray::Ray) -> Option<(f32, f32, f32)> {
    ShearedRay::new(ray).intersect(tri, ray.tmin, ray.tmax)
}

/// Where `ray` hits `tri` (`t`), computed as the BVHs compute it, so that
/// a hit found here and the one [`SceneBvh::closest_hit`] finds on the same
/// triangle have the same `t` to the bit.
pub fn ray_hits_triangle(tri: &crate::scene::Triangle, ray: &Ray) -> Option<f32> {
    intersect_triangle(&to_obvhs(tri), &to_obvhs_ray(ray)).map(|(t, _, _)| t - NEAR_SHIFT)
}

/// Relative widening of every child box's interval in [`children_crossed`]:
/// 2γ₃ (γₙ = nε/(1−nε), ε = 2⁻²⁴; pbrt-v4 §6.8.2), as the GPU's
/// `BOX_SLACK`. Why: a ray through a shared vertex or edge on a box's face
/// could round out of the box and lose the triangle it meets (the
/// triangle test is watertight; obvhs's box test is not). Visiting a box
/// more never changes a hit.
const BOX_SLACK: f32 = 3.58e-7;

/// obvhs's `CwBvhNode::intersect_ray` with its near cut and each child's
/// interval widened by [`BOX_SLACK`]: the hit mask of the children whose
/// box the ray crosses in `[1e-4, tmax]`, four children at a time (glam's
/// `Vec4` is SSE on x86). The GPU's `intersect_children` computes the
/// same, in the same order, so both visit the same boxes.
#[inline(always)]
fn children_crossed(
    node: &obvhs::cwbvh::node::CwBvhNode,
    ray: &obvhs::ray::Ray,
    oct_inv4: u32,
    tmax: f32,
) -> u32 {
    /// obvhs's `cwbvh::node::EPSILON` (private there): the near cut.
    const NEAR_CULL: f32 = 1e-4;
    let adj_inv = node.compute_extent() * ray.inv_direction;
    let adj_origin = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    let negative = ray.direction.cmplt(Vec3A::ZERO);
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let quad = |q: &[u8; 8], i: usize| {
        Vec4::new(
            q[i * 4] as f32,
            q[i * 4 + 1] as f32,
            q[i * 4 + 2] as f32,
            q[i * 4 + 3] as f32,
        )
    };
    let mut hit_mask = 0u32;
    for i in 0..2 {
        let slab = |lo: &[u8; 8], hi: &[u8; 8], axis: usize| {
            let (lo, hi) = (quad(lo, i), quad(hi, i));
            let (near, far) = if negative.test(axis) {
                (hi, lo)
            } else {
                (lo, hi)
            };
            let (scale, offset) = (adj_inv[axis], adj_origin[axis]);
            (near * scale + offset, far * scale + offset)
        };
        let (near_x, far_x) = slab(&node.child_min_x, &node.child_max_x, 0);
        let (near_y, far_y) = slab(&node.child_min_y, &node.child_max_y, 1);
        let (near_z, far_z) = slab(&node.child_min_z, &node.child_max_z, 2);
        let near = near_x.max(near_y.max(near_z));
        let far = far_x.min(far_y.min(far_z));
        let near = (near - near.abs() * BOX_SLACK).max(Vec4::splat(NEAR_CULL));
        let far = (far + far.abs() * BOX_SLACK).min(Vec4::splat(tmax));
        let crossed = near.cmple(far).bitmask();
        for j in 0..4 {
            if crossed & (1 << j) != 0 {
                let child = i * 4 + j;
                let bits = obvhs::cwbvh::node::extract_byte64(child_bits8, child);
                let index = obvhs::cwbvh::node::extract_byte64(bit_index8, child);
                hit_mask |= bits << index;
            }
        }
    }
    hit_mask
}

/// How long a BVH serves, which picks obvhs's build preset for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BvhLife {
    /// Built once and traversed by every ray of a render (the static part,
    /// each moving object's mesh in its own space): obvhs's medium preset
    /// above [`MEDIUM_BUILD_ABOVE`] triangles, whose better tree repays its
    /// longer build.
    Render,
    /// Built again every frame (the moving triangles placed at the frame's
    /// time): the fast preset at any size. Its tree served as well: on a
    /// turning ball of 1M triangles (`benches/scenes/turning_ball.py
    /// 1024`) it took 0.67–0.70 s a frame to build against the medium
    /// preset's 0.78–0.80 s, and `ic` over 24 frames at 64×64 took 25.65 /
    /// 23.36 s against 29.36 / 25.50 s (alternating); on the built-in
    /// `spheres` (63,374 moving triangles) 26–42 ms against 28–47 ms, and
    /// no change measurable in whole renders. Frames are the same bits
    /// (hits do not depend on the tree: ties go to the lower triangle id).
    Frame,
}

/// Triangles above which a BVH built once a render takes obvhs's medium
/// preset ([`BvhLife::Render`]).
pub const MEDIUM_BUILD_ABOVE: usize = 10_000;

impl BvhLife {
    /// obvhs's build preset for a BVH of this life over `triangles`.
    pub fn params(self, triangles: usize) -> BvhBuildParams {
        match self {
            BvhLife::Render if triangles > MEDIUM_BUILD_ABOVE => BvhBuildParams::medium_build(),
            _ => BvhBuildParams::fast_build(),
        }
    }
}

impl TriangleBvh {
    /// Builds a BVH over snapshot triangles `range`, to serve for `life`;
    /// `None` when empty.
    pub fn build(snapshot: &Snapshot, range: Range<usize>, life: BvhLife) -> Option<Self> {
        let source: Vec<ObTriangle> = (snapshot.triangles.range(range.clone()))
            .map(to_obvhs)
            .collect();
        let id_of = |i| {
            let id = range.start + i;
            (id as u32, snapshot.tri_object[id])
        };
        Self::over(source, life, id_of)
    }

    /// Builds a BVH over `source`, to serve for `life`, triangle `i` of it
    /// snapshot triangle `id_of(i).0` of object `id_of(i).1`; `None` when
    /// empty.
    fn over(
        source: Vec<ObTriangle>,
        life: BvhLife,
        id_of: impl Fn(usize) -> (u32, u32),
    ) -> Option<Self> {
        if source.is_empty() {
            return None;
        }
        let params = life.params(source.len());
        let mut bvh = build_cwbvh_from_tris(&source, params, &mut Duration::default());
        // obvhs reserves a CWBVH node (80 bytes) for every primitive and
        // fills a fraction of them. A BVH held for long (`trc` held the
        // moving triangles' BVHs of the later frames its records check)
        // held that room too: `trc` on a ball of 261,120 triangles turning
        // under a moving light peaked at ~1.45 GB of RSS, ~1.1 GB without
        // (`benches/RESULTS.md`, "What a frame of replacements holds at
        // once").
        bvh.nodes.shrink_to_fit();
        bvh.primitive_indices.shrink_to_fit();
        let order = &bvh.primitive_indices;
        let (ids, objects) = order.iter().map(|&i| id_of(i as usize)).unzip();
        Some(TriangleBvh {
            triangles: order.iter().map(|&i| source[i as usize]).collect(),
            ids,
            objects,
            bvh,
        })
    }

    /// Nearest hit along `ray` closer than `best.t`; updates `best`. Of
    /// hits at the same `t` (a ray through an edge hits both triangles)
    /// the lower triangle id wins, whichever the traversal meets first: the
    /// GPU's traversals keep the same one.
    #[inline]
    fn closest_hit(&self, ray: &obvhs::ray::Ray, sheared: &ShearedRay, best: &mut Hit) {
        let mut tmax = ray.tmax.min(best.t);
        let mut nearest = best.is_hit().then_some((best.t, best.triangle));
        let mut found: Option<(usize, f32, f32, f32)> = None;
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            children_crossed(node, ray, state.oct_inv4, tmax),
            {
                let i = state.primitive_id as usize;
                if let Some((t, u, v)) = sheared.intersect(&self.triangles[i], ray.tmin, tmax) {
                    let id = self.ids[i];
                    let tie_won = nearest.is_some_and(|(bt, bid)| t == bt && id < bid);
                    if t < tmax || tie_won {
                        nearest = Some((t, id));
                        found = Some((i, t, u, v));
                        tmax = t;
                    }
                }
            }
        );
        if let Some((i, t, u, v)) = found {
            *best = Hit {
                t,
                triangle: self.ids[i],
                object: self.objects[i],
                u,
                v,
            };
        }
    }

    /// Whether this BVH was built over exactly snapshot triangles `range`:
    /// the same vertices to the bit, with the same objects.
    pub fn holds(&self, snapshot: &Snapshot, range: Range<usize>) -> bool {
        let bits = |t: &ObTriangle| [t.v0, t.v1, t.v2].map(|v| v.to_array().map(f32::to_bits));
        let same = |((&id, tri), &object): ((&u32, &ObTriangle), &u32)| {
            let id = id as usize;
            range.contains(&id)
                && snapshot.tri_object[id] == object
                && bits(tri) == bits(&to_obvhs(&snapshot.triangles[id]))
        };
        // `ids` is a permutation of the range the BVH was built over.
        self.ids.len() == range.len()
            && self
                .ids
                .iter()
                .zip(&self.triangles)
                .zip(&self.objects)
                .all(same)
    }

    /// Whether some triangle of this BVH lies on `ray` (an any-hit query
    /// outside a backend: `trc`'s estimate of the next frame's shadows).
    pub fn occludes(&self, ray: &Ray) -> bool {
        let r = to_obvhs_ray(ray);
        self.occluded(&r, &ShearedRay::new(&r))
    }

    #[inline]
    fn occluded(&self, ray: &obvhs::ray::Ray, sheared: &ShearedRay) -> bool {
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut occluded = false;
        'traversal: {
            obvhs::traverse!(
                self.bvh,
                node,
                state,
                children_crossed(node, ray, state.oct_inv4, ray.tmax),
                {
                    let tri = &self.triangles[state.primitive_id as usize];
                    if sheared
                        .intersect(tri, ray.tmin, ray.tmax)
                        .is_some_and(|h| h.0 < ray.tmax)
                    {
                        occluded = true;
                        break 'traversal;
                    }
                }
            );
        }
        occluded
    }
}

/// Time spent building BVHs for one frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct BuildTimes {
    pub static_build: Option<Duration>,
    pub dynamic_build: Duration,
}

/// Frames with moving parts and at most this many static triangles are
/// traced through one BVH over all their triangles, rebuilt every frame.
/// Why: a rebuild costs about 0.27 µs a triangle (`cargo bench --bench
/// rays`: 2.7 ms for 9,880 triangles), so at most 1.1 ms a frame here,
/// while tracing every ray through a second BVH cost cube-in-box (26
/// triangles, 12 of them moving) 8 % of `trc`'s render pass and 10 % of
/// its aging at 64×64. Frames are bit-identical either way.
pub const MERGE_STATIC_TRIANGLES: usize = 4096;

/// How many of `snapshot`'s triangles (`0..n`, its static ones or none)
/// go in the BVH a render builds once; the rest go in the one rebuilt every
/// frame. Both backends split by this rule, so they traverse the same trees
/// and break ties between equally near hits alike.
pub fn static_part_len(snapshot: &Snapshot) -> usize {
    let moving = snapshot.static_count < snapshot.triangles.len();
    if moving && snapshot.static_count <= MERGE_STATIC_TRIANGLES {
        0
    } else {
        snapshot.static_count
    }
}

/// The fingerprint of the part [`static_part_len`] puts in the BVH built
/// once (`None` for an empty part): while it is unchanged the part is kept.
pub fn static_part_fingerprint(snapshot: &Snapshot) -> Option<u64> {
    (static_part_len(snapshot) > 0).then(|| snapshot.static_fingerprint())
}

/// The BVH of the frame's static part (built once a render,
/// [`static_part_len`]) and of the rest (rebuilt every frame).
#[derive(Default)]
pub struct SceneBvh {
    /// Shared with the render's [`StaticGeometry`] ([`shared_static_bvh`]).
    static_part: Option<Arc<TriangleBvh>>,
    /// [`static_part_fingerprint`] of the triangles `static_part` holds.
    static_fingerprint: Option<u64>,
    dynamic_part: Option<Arc<TriangleBvh>>,
}

impl SceneBvh {
    pub fn new() -> Self {
        Self::default()
    }

    /// Makes the BVHs match `snapshot`.
    pub fn update(&mut self, snapshot: &Snapshot) -> BuildTimes {
        let mut times = BuildTimes::default();
        let static_len = static_part_len(snapshot);
        let fp = static_part_fingerprint(snapshot);
        if self.static_fingerprint != fp {
            let start = Instant::now();
            // The part is all the static triangles or none of them.
            self.static_part = (static_len > 0)
                .then(|| shared_static_bvh(snapshot))
                .flatten();
            self.static_fingerprint = fp;
            times.static_build = Some(start.elapsed());
        }
        let start = Instant::now();
        self.dynamic_part = TriangleBvh::build(
            snapshot,
            static_len..snapshot.triangles.len(),
            BvhLife::Frame,
        )
        .map(Arc::new);
        times.dynamic_build = start.elapsed();
        times
    }

    pub fn closest_hit(&self, ray: &Ray) -> Hit {
        let r = to_obvhs_ray(ray);
        // `hit.t` is the traversal's (shifted) `t` until the end.
        let sheared = ShearedRay::new(&r);
        let mut hit = Hit::MISS;
        if let Some(part) = &self.static_part {
            part.closest_hit(&r, &sheared, &mut hit);
        }
        if let Some(part) = &self.dynamic_part {
            part.closest_hit(&r, &sheared, &mut hit);
        }
        if hit.is_hit() {
            hit.t -= NEAR_SHIFT;
        }
        hit
    }

    pub fn occluded(&self, ray: &Ray) -> bool {
        let r = to_obvhs_ray(ray);
        let sheared = ShearedRay::new(&r);
        // Dynamic parts are usually small: test them first.
        self.dynamic_part
            .as_ref()
            .is_some_and(|p| p.occluded(&r, &sheared))
            || self
                .static_part
                .as_ref()
                .is_some_and(|p| p.occluded(&r, &sheared))
    }
}

/// The BVH of a render's static triangles, built once (while the static
/// part's fingerprint holds) for the methods that test segments against
/// the static geometry alone (`trc`'s direct light at t0+1, `movies`'
/// static blockers behind moving ones); the CPU backend's own static part
/// where it has one (`shared_static_bvh`).
#[derive(Default)]
pub struct StaticGeometry {
    fingerprint: Option<u64>,
    bvh: Option<Arc<TriangleBvh>>,
}

impl StaticGeometry {
    /// The BVH of `snapshot`'s static triangles (`None`: there are none).
    pub fn of(&mut self, snapshot: &Snapshot) -> Option<Arc<TriangleBvh>> {
        let fingerprint = snapshot.static_fingerprint();
        if self.fingerprint != Some(fingerprint) {
            self.bvh = shared_static_bvh(snapshot);
            self.fingerprint = Some(fingerprint);
        }
        self.bvh.clone()
    }
}

/// BVHs that some holder still keeps, each with a key that narrows the
/// search (a static part's [`Snapshot::static_fingerprint`]): a kept BVH is taken only if it holds exactly the
/// triangles asked for (checked, not trusted to the key), so sharing never
/// changes a hit.
static SHARED: Mutex<Vec<(u64, Weak<TriangleBvh>)>> = Mutex::new(Vec::new());

/// The BVH of `snapshot`'s static triangles (`None`: there are none), one
/// build for every holder alive at once. Why: the CPU backend's static
/// part ([`SceneBvh`]) and a method's [`StaticGeometry`] are the same
/// triangles wherever the backend splits them off (past
/// [`MERGE_STATIC_TRIANGLES`] or in a still scene), and each built its own:
/// twice the build time and memory for the largest part of a scene.
fn shared_static_bvh(snapshot: &Snapshot) -> Option<Arc<TriangleBvh>> {
    let statics = 0..snapshot.static_count;
    shared_bvh(snapshot.static_fingerprint(), snapshot, statics)
}

/// A kept BVH of snapshot triangles `range` found under `key`, or one
/// built (and kept for others while a holder has it).
fn shared_bvh(key: u64, snapshot: &Snapshot, range: Range<usize>) -> Option<Arc<TriangleBvh>> {
    let kept = || {
        let mut shared = SHARED.lock().unwrap_or_else(PoisonError::into_inner);
        shared.retain(|(_, bvh)| bvh.strong_count() > 0);
        (shared.iter())
            .filter(|(k, _)| *k == key)
            .filter_map(|(_, bvh)| bvh.upgrade())
            .find(|bvh| bvh.holds(snapshot, range.clone()))
    };
    if let Some(bvh) = kept() {
        return Some(bvh);
    }
    // Built outside the lock: a render building a large part does not hold
    // up another's. Two holders asking together may both build it; each
    // then keeps its own.
    let bvh = Arc::new(TriangleBvh::build(snapshot, range, BvhLife::Render)?);
    let mut shared = SHARED.lock().unwrap_or_else(PoisonError::into_inner);
    shared.push((key, Arc::downgrade(&bvh)));
    Some(bvh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// `cube-in-box` with every triangle static and its walls moved by
    /// `offset`, so that its static part is split off (a still scene).
    fn still_snapshot(offset: f32) -> Snapshot {
        let mut snap = Scene::builtin("cube-in-box").unwrap().snapshot(0.0);
        snap.static_count = snap.triangles.len();
        for tri in snap.triangles.iter_mut() {
            tri.p = tri.p.map(|p| p + glam::Vec3::splat(offset));
        }
        snap
    }

    fn static_part(bvh: &SceneBvh) -> &Arc<TriangleBvh> {
        bvh.static_part.as_ref().expect("a static part")
    }

    /// The backend's static part and a method's static geometry of one
    /// scene are one BVH; another scene's, or the same scene's once it is
    /// let go, are built anew.
    #[test]
    fn the_backend_and_a_method_share_one_static_bvh() {
        let snap = still_snapshot(0.0);
        let mut backend = SceneBvh::new();
        backend.update(&snap);
        let mut method = StaticGeometry::default();
        let of_method = method.of(&snap).expect("static triangles");
        assert!(Arc::ptr_eq(static_part(&backend), &of_method));

        let mut other = SceneBvh::new();
        other.update(&still_snapshot(1.0));
        assert!(!Arc::ptr_eq(static_part(&other), &of_method));

        drop((backend, method, of_method));
        assert!(SHARED
            .lock()
            .unwrap()
            .iter()
            .all(|(fp, bvh)| *fp != snap.static_fingerprint() || bvh.strong_count() == 0));
    }

    /// A kept BVH whose fingerprint matches another scene's (forced here)
    /// is not taken for it: its triangles are compared.
    #[test]
    fn a_kept_bvh_is_taken_only_for_its_own_triangles() {
        let snap = still_snapshot(2.0);
        let bvh = TriangleBvh::build(&snap, 0..snap.static_count, BvhLife::Render).unwrap();
        assert!(bvh.holds(&snap, 0..snap.static_count));
        let moved = still_snapshot(3.0);
        assert!(!bvh.holds(&moved, 0..moved.static_count));
        let mut fewer = snap.clone();
        fewer.static_count -= 1;
        assert!(!bvh.holds(&fewer, 0..fewer.static_count));
        let mut reassigned = snap.clone();
        reassigned.tri_object[0] += 1;
        assert!(!bvh.holds(&reassigned, 0..reassigned.static_count));
    }
}
