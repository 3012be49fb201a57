//! `path`: the unbiased reference path tracer, the accuracy yardstick of
//! every other method.
//!
//! Standard unidirectional path tracing (Kajiya 1986) with next-event
//! estimation at every vertex, combined with BSDF sampling by multiple
//! importance sampling with the power heuristic (Veach 1997, §9.2), and
//! Russian roulette on the path throughput. Pixels are box-filtered over
//! their own square (uniform jitter), as the reference renders are.
//!
//! The tracer is written as a wavefront so that it only talks to the batched
//! [`RayBackend`]: a tile of pixels × samples is advanced one bounce at a
//! time — trace all extension rays, shade, trace all shadow rays.

use super::{FrameContext, Method};
use crate::backend::{Hit, Ray};
use crate::film::Film;
use crate::light::emitting_cosine;
use crate::material::Bsdf;
use crate::sampling::{power_heuristic, Rng};
use glam::Vec3;
use rayon::prelude::*;

/// Settings of the path tracer.
#[derive(Clone, Debug, PartialEq)]
pub struct PathSettings {
    /// Samples per pixel.
    pub spp: u32,
    /// Hard bounce limit (`None`: unbounded, terminated by Russian roulette
    /// only, as the reference renders are).
    pub max_depth: Option<u32>,
    /// Russian roulette starts after this many bounces (pbrt-v4 uses 1;
    /// later starts cost time, not accuracy).
    pub rr_start: u32,
}

impl Default for PathSettings {
    fn default() -> Self {
        PathSettings {
            spp: 16,
            max_depth: None,
            rr_start: 3,
        }
    }
}

/// Relative offset of secondary ray origins along the geometric normal,
/// scaled by the magnitude of the hit point, against self-intersection.
const RAY_OFFSET: f32 = 1e-4;

pub struct PathTracer {
    pub settings: PathSettings,
}

impl PathTracer {
    pub fn new(settings: PathSettings) -> Self {
        PathTracer { settings }
    }
}

/// State of one path between bounces.
#[derive(Clone)]
struct PathState {
    /// Index of the pixel inside the tile.
    pixel: u32,
    rng: Rng,
    throughput: Vec3,
    radiance: Vec3,
    bounces: u32,
    /// Solid-angle pdf of the BSDF sample that produced the current ray
    /// (for MIS when it hits an emitter).
    bsdf_pdf: f32,
}

/// A shadow ray waiting to be traced and what it adds if unoccluded.
struct ShadowQuery {
    path: usize,
    contribution: Vec3,
}

impl Method for PathTracer {
    fn name(&self) -> &'static str {
        "path"
    }

    fn render_frame(&mut self, ctx: &FrameContext) -> Film {
        let mut film = Film::new(ctx.width, ctx.height);
        let spp = self.settings.spp.max(1) as usize;
        // Tiles of whole pixels, about one backend batch of paths each.
        let pixels_per_tile = (ctx.backend.preferred_batch() / spp).max(1);
        film.pixels
            .par_chunks_mut(pixels_per_tile)
            .enumerate()
            .for_each(|(tile, out)| {
                let first = (tile * pixels_per_tile) as u32;
                self.render_tile(ctx, first, out);
            });
        film
    }
}

impl PathTracer {
    /// Renders pixels `first..first+out.len()` (row-major) into `out`.
    fn render_tile(&self, ctx: &FrameContext, first: u32, out: &mut [Vec3]) {
        let spp = self.settings.spp.max(1);
        let mut paths = Vec::with_capacity(out.len() * spp as usize);
        let mut rays = Vec::with_capacity(paths.capacity());
        for local in 0..out.len() as u32 {
            let pixel = first + local;
            let (x, y) = (pixel % ctx.width, pixel / ctx.width);
            for sample in 0..spp {
                let mut rng = Rng::new(ctx.pixel_key(pixel, sample));
                let jitter = rng.next_2d();
                let sx = (x as f32 + jitter.x) / ctx.width as f32;
                let sy = (y as f32 + jitter.y) / ctx.height as f32;
                let camera = &ctx.snapshot.camera;
                rays.push(Ray::new(
                    camera.position,
                    camera.direction(sx, sy, ctx.aspect()),
                    0.0,
                    f32::INFINITY,
                ));
                paths.push(PathState {
                    pixel: local,
                    rng,
                    throughput: Vec3::ONE,
                    radiance: Vec3::ZERO,
                    bounces: 0,
                    bsdf_pdf: 0.0,
                });
            }
        }
        let mut finished = Vec::with_capacity(paths.len());
        let mut hits = Vec::new();
        let mut continuations = Vec::new();
        let mut shadow_rays = Vec::new();
        let mut shadow_queries = Vec::new();
        let mut occluded = Vec::new();
        while !paths.is_empty() {
            hits.resize(rays.len(), Hit::MISS);
            ctx.backend.closest_hit(&rays, &mut hits);
            shadow_rays.clear();
            shadow_queries.clear();
            continuations.clear();
            for (i, path) in paths.iter_mut().enumerate() {
                let next = self.shade(
                    ctx,
                    path,
                    &rays[i],
                    &hits[i],
                    i,
                    &mut shadow_rays,
                    &mut shadow_queries,
                );
                continuations.push(next);
            }
            occluded.resize(shadow_rays.len(), false);
            ctx.backend.any_hit(&shadow_rays, &mut occluded);
            for (q, &blocked) in shadow_queries.iter().zip(&occluded) {
                if !blocked {
                    paths[q.path].radiance += q.contribution;
                }
            }
            // Compact: continuing paths and their rays stay, the others are done.
            rays.clear();
            let mut alive = Vec::with_capacity(paths.len());
            for (path, next) in paths.drain(..).zip(continuations.drain(..)) {
                match next {
                    Some(ray) => {
                        rays.push(ray);
                        alive.push(path);
                    }
                    None => finished.push(path),
                }
            }
            paths = alive;
        }
        let inv_spp = 1.0 / spp as f32;
        // Sum in (pixel, sample) order for bit-exact repeatability.
        finished.sort_by_key(|p| p.pixel);
        for p in finished {
            out[p.pixel as usize] += p.radiance * inv_spp;
        }
    }
}

impl PathTracer {
    /// Shades the hit of `path`: adds emission (MIS-weighted), queues a light
    /// sample and draws the continuation. Returns the next ray, or `None`
    /// when the path ends.
    #[allow(clippy::too_many_arguments)]
    fn shade(
        &self,
        ctx: &FrameContext,
        path: &mut PathState,
        ray: &Ray,
        hit: &Hit,
        index: usize,
        shadow_rays: &mut Vec<Ray>,
        shadow_queries: &mut Vec<ShadowQuery>,
    ) -> Option<Ray> {
        if !hit.is_hit() {
            return None; // Closed scenes: nothing beyond (black background).
        }
        let snapshot = ctx.snapshot;
        let tri = &snapshot.triangles[hit.triangle as usize];
        let material = &ctx.scene.materials[snapshot.tri_material[hit.triangle as usize] as usize];
        let dir = ray.dir();
        let wo = -dir.normalize();
        let p = ray.at(hit.t);

        if material.is_emissive() {
            if let Some(_cos) = emitting_cosine(tri, material.double_sided, wo) {
                let weight = if path.bounces == 0 {
                    1.0
                } else {
                    // MIS with next-event estimation of the previous vertex.
                    let light_pdf = ctx.lights.pdf_triangle(tri, hit.triangle, ray.origin(), p);
                    power_heuristic(path.bsdf_pdf, light_pdf)
                };
                path.radiance += path.throughput * material.emission * weight;
            }
        }

        if let Some(max) = self.settings.max_depth {
            if path.bounces >= max {
                return None;
            }
        }
        let bsdf = Bsdf::new(material, tri.shading_normal(hit.u, hit.v), wo);
        if bsdf.is_black() {
            return None;
        }
        // Offset along the geometric normal on the side of the outgoing ray.
        let ng = tri.geometric_normal();
        let offset = RAY_OFFSET * (1.0 + p.abs().max_element());
        let side = |w: Vec3| {
            if ng.dot(w) >= 0.0 {
                ng * offset
            } else {
                -ng * offset
            }
        };

        // Next-event estimation.
        let (pick, u) = (path.rng.next_f32(), path.rng.next_2d());
        if let Some(ls) = ctx
            .lights
            .sample(snapshot, &ctx.scene.materials, p, pick, u)
        {
            let f = bsdf.eval(wo, ls.wi);
            let cos = bsdf.normal().dot(ls.wi);
            if cos > 0.0 && f.max_element() > 0.0 {
                let weight = if ls.is_delta {
                    1.0
                } else {
                    power_heuristic(ls.pdf, bsdf.pdf(wo, ls.wi))
                };
                let contribution = path.throughput * f * ls.radiance * (cos * weight / ls.pdf);
                let origin = p + side(ls.wi);
                shadow_rays.push(Ray::segment(origin, ls.position));
                shadow_queries.push(ShadowQuery {
                    path: index,
                    contribution,
                });
            }
        }
        // Continue by BSDF sampling.
        let (pick, u) = (path.rng.next_f32(), path.rng.next_2d());
        bsdf.sample(wo, pick, u).and_then(|s| {
            let cos = bsdf.normal().dot(s.wi);
            path.throughput *= s.f * (cos / s.pdf);
            path.bsdf_pdf = s.pdf;
            path.bounces += 1;
            if path.bounces > self.settings.rr_start {
                // Survive with probability q = min(max βᵢ, 0.95), reweight by 1/q.
                let q = path.throughput.max_element().min(0.95);
                if path.rng.next_f32() >= q {
                    return None;
                }
                path.throughput /= q;
            }
            Some(Ray::new(p + side(s.wi), s.wi, 0.0, f32::INFINITY))
        })
    }
}
