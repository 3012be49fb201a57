//! Shading a tile's samples: their first hits shaded and their emission
//! ([`TileShading`]), their direct light (one light sample each, its shadow
//! rays in one batch, [`ShadowBatch`], the last frame's taken where they
//! stand), and their indirect light from the cache or, where no record is
//! usable, path-traced, with their glossy lobes.

use super::still::StillPass;
use super::still_tile::KeptShadow;
use super::tile_lookups::TileLookups;
use super::{material_of, Deferred, PixelStreams, PrimarySamples, Surface, TilePass};
use crate::backend::Ray;
use crate::cache::{eas, Interpolated};
use crate::integrator::{FirstHitEmission, RadianceQuery};
use crate::light::{emitting_cosine, TriangleSampling};
use crate::method::ic::GlossyLobe;
use crate::method::pixels::FirstLightSampler;
use crate::method::{FrameContext, FrameStats};
use crate::sampling::{power_heuristic, LightChoice, Rng};
use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

/// A tile's primary samples, their shaded first hits and the radiance
/// summed so far for each.
pub(super) struct TileShading<'a> {
    pub(super) primary: PrimarySamples,
    /// Each sample's shaded first hit; not shaded (`None`) for the samples
    /// of pixels kept whole.
    pub(super) surfaces: Vec<Option<Surface<'a>>>,
    /// Per base sample, whether its pixel is kept whole ([`Standing`](super::still_tile::Standing));
    /// empty where nothing is kept.
    pub(super) whole: Vec<bool>,
    pub(super) radiance: Vec<Vec3>,
}

/// The shadow rays of a tile's direct light and, for each, its sample and
/// what it adds if unoccluded.
#[derive(Default)]
pub(super) struct ShadowBatch {
    rays: Vec<Ray>,
    targets: Vec<(usize, Vec3)>,
}

/// The last frame's shadows of a tile's base samples, moved out of its
/// kept tile, and per base sample whether its shadow stands
/// ([`Standing::shadows`](super::still_tile::Standing::shadows)).
pub(super) type LastShadows<'a> = (Vec<Option<KeptShadow>>, &'a [bool]);

impl ShadowBatch {
    /// Adds the light of the unoccluded shadow rays to their samples, and
    /// that of the last frame's shadows that stand (`keep`, with this
    /// frame's kept samples); with `keep`, returns each sample's shadow
    /// (`None`: it had none) for the next frame, in the last frame's
    /// vector: a shadow that stands stays where it is.
    pub(super) fn add_unoccluded(
        self,
        ctx: &FrameContext,
        radiance: &mut [Vec3],
        keep: Option<(&StillPass, LastShadows)>,
    ) -> Vec<Option<KeptShadow>> {
        let mut occluded = vec![false; self.rays.len()];
        ctx.backend.any_hit(&self.rays, &mut occluded);
        let (pass, mut kept) = match keep {
            Some((pass, (last, stands))) => {
                (Some(pass), take_standing_shadows(last, stands, radiance))
            }
            None => (None, Vec::new()),
        };
        let traced = self.rays.into_iter().zip(self.targets).zip(occluded);
        for ((ray, (i, contribution)), occluded) in traced {
            if !occluded {
                radiance[i] += contribution;
            }
            if let Some(pass) = pass {
                kept[i] = Some(KeptShadow {
                    ray,
                    contribution,
                    occluded,
                    clear: pass.shadow_clear(&ray),
                });
            }
        }
        kept
    }
}

/// Adds to `radiance` the light of the last frame's unoccluded shadows
/// that stand (`stands`, per base sample); returns `last` with the others
/// cleared, one per sample (the extra ones of a light's rim too), for this
/// frame's traced shadows to fill. A shadow that stands met no moving box
/// in either frame, so it stays `clear`.
fn take_standing_shadows(
    mut last: Vec<Option<KeptShadow>>,
    stands: &[bool],
    radiance: &mut [Vec3],
) -> Vec<Option<KeptShadow>> {
    last.reserve_exact(radiance.len().saturating_sub(last.len()));
    last.resize(radiance.len(), None);
    for (i, shadow) in last.iter_mut().enumerate() {
        if stands.get(i) != Some(&true) {
            *shadow = None;
        } else if let Some(s) = shadow.filter(|s| !s.occluded) {
            radiance[i] += s.contribution;
        }
    }
    last
}

impl<'a> TileShading<'a> {
    /// The first hits shaded (but for those of pixels kept `whole`, whose
    /// materials emit nothing), with the emission of those that see an
    /// emitter's emitting side.
    pub(super) fn new(ctx: &'a FrameContext, primary: PrimarySamples, whole: Vec<bool>) -> Self {
        let surfaces: Vec<Option<Surface>> = primary
            .rays
            .iter()
            .zip(&primary.hits)
            .enumerate()
            .map(|(i, (ray, hit))| match whole.get(i) {
                Some(true) => None,
                _ => Surface::at(ctx, ray, hit),
            })
            .collect();
        let radiance = surfaces
            .iter()
            .map(|surface| match surface {
                Some(s)
                    if s.material.is_emissive()
                        && emitting_cosine(s.triangle, s.material.double_sided, s.wo).is_some() =>
                {
                    s.material.emission
                }
                _ => Vec3::ZERO,
            })
            .collect();
        TileShading {
            primary,
            surfaces,
            whole,
            radiance,
        }
    }

    /// Each sample's first light sample (drawn from its stream, before
    /// anything else draws from it) and the shadow rays of those that may
    /// add direct light; the samples whose last shadow stands
    /// (`shadows_stand`, per base sample: [`Standing::shadows`](super::still_tile::Standing::shadows))
    /// draw their light sample but trace nothing: their shadows are taken
    /// from the last frame ([`ShadowBatch::add_unoccluded`]).
    pub(super) fn direct_light(
        &mut self,
        ctx: &FrameContext,
        streams: PixelStreams,
        shadows_stand: &[bool],
    ) -> ShadowBatch {
        let mut lights = FirstLightSampler::new(streams);
        let mut batch = ShadowBatch::default();
        for (i, surface) in self.surfaces.iter().enumerate() {
            let rng = &mut self.primary.rngs[i];
            if shadows_stand.get(i) == Some(&true) {
                // The light sample's draw, whose outcome the shadow kept.
                rng.next_2d();
                continue;
            }
            let choice = lights.sample(ctx, &self.primary.samples[i], rng);
            let Some(surface) = surface.as_ref().filter(|s| !s.bsdf.is_black()) else {
                continue;
            };
            if let Some((shadow, contribution)) = direct_light(ctx, surface, choice, true) {
                batch.rays.push(shadow);
                batch.targets.push((i, contribution));
            }
        }
        batch
    }

    /// Per sample, in the order the CPU-only pass took them: the cached
    /// indirect light added, or where the sample's lookup found no usable
    /// record, a path-traced fallback (drawn from the sample's stream
    /// before the glossy lobe's); and the glossy lobe: path-traced, or
    /// with [`GlossyLobe::Eas`] its indirect light reflected from the
    /// records' equivalent area light sources, once per lookup, and its
    /// ray traced to the first hit only (path-traced where no record there
    /// has sources). Returns the traced parts.
    pub(super) fn indirect_light(
        &mut self,
        ctx: &'a FrameContext,
        pass: &TilePass,
        lookups: &TileLookups,
        stats: &mut FrameStats,
    ) -> Vec<Deferred> {
        let mut deferred = Vec::new();
        let mut reflected: Vec<Option<Option<Vec3>>> = vec![None; lookups.lookups.len()];
        for i in 0..self.surfaces.len() {
            if self.whole.get(i) == Some(&true) {
                deferred.extend(self.whole_indirect(ctx, i, lookups.of(i), stats));
                continue;
            }
            let Some(surface) = self.surfaces[i].as_ref().filter(|s| !s.bsdf.is_black()) else {
                continue;
            };
            let rng = &mut self.primary.rngs[i];
            let albedo = surface.bsdf.diffuse_albedo();
            match lookups.of(i).filter(|_| albedo.max_element() > 0.0) {
                Some(Some(e)) => self.radiance[i] += albedo * FRAC_1_PI * e.irradiance,
                Some(None) => {
                    stats.fallback_lookups += 1;
                    deferred.push(Deferred::fallback(i, surface, rng));
                }
                None => {}
            }
            let cached = match lookups.of_sample[i] {
                Some(l)
                    if pass.settings.glossy == GlossyLobe::Eas && surface.bsdf.has_specular() =>
                {
                    *reflected[l as usize].get_or_insert_with(|| {
                        let cache = pass.interpolation.cache();
                        let at = &lookups.lookups[l as usize];
                        eas::reflected_radiance(cache, at, &surface.bsdf, surface.wo)
                    })
                }
                _ => None,
            };
            let query = glossy_query(surface, rng);
            // Where the sources hold what the lobe's path would gather past
            // its first hit, the lobe's ray is still traced to its first
            // hit, for the emission there that MIS weighs against the
            // light sample.
            if let Some(radiance) = cached {
                self.radiance[i] += radiance;
            }
            deferred.extend(query.map(|query| Deferred {
                sample: i,
                query,
                first_hit_only: cached.is_some(),
            }));
        }
        deferred
    }

    /// Sample `i` of a pixel kept whole (`irradiance`: its lookup's, as
    /// [`TileLookups::of`] gives it): a plain material, so its diffuse lobe
    /// alone, as [`Self::indirect_light`] adds it (a BSDF's diffuse albedo
    /// is its material's `diffuse`), or where no record is usable its
    /// path-traced fallback, returned.
    fn whole_indirect(
        &mut self,
        ctx: &FrameContext,
        i: usize,
        irradiance: Option<&Option<Interpolated>>,
        stats: &mut FrameStats,
    ) -> Option<Deferred> {
        let hit = &self.primary.hits[i];
        match irradiance? {
            Some(e) => {
                self.radiance[i] += material_of(ctx, hit).diffuse * FRAC_1_PI * e.irradiance;
                None
            }
            None => {
                stats.fallback_lookups += 1;
                let surface = Surface::at(ctx, &self.primary.rays[i], hit)
                    .expect("a sample that looked the cache up hit something");
                Some(Deferred::fallback(i, &surface, &mut self.primary.rngs[i]))
            }
        }
    }
}

/// One light sample (`choice`, stratified over the pixel, its point
/// uniform in solid angle: this light is seen) for the whole
/// BSDF: the diffuse lobe unweighted (its emission hits are never counted
/// elsewhere: the cache excludes them), the glossy lobe MIS-weighted against
/// [`glossy_query`]'s lobe sampling. Without `with_diffuse`, the glossy
/// lobe's part alone (`movies`, whose textures hold the diffuse part).
pub(crate) fn direct_light(
    ctx: &FrameContext,
    s: &Surface,
    choice: LightChoice,
    with_diffuse: bool,
) -> Option<(Ray, Vec3)> {
    let ls = ctx
        .lights
        .sample(ctx.snapshot, s.p, choice, TriangleSampling::SolidAngle)?;
    let cos = s.bsdf.normal().dot(ls.wi);
    if cos <= 0.0 || s.wo.dot(s.bsdf.normal()) <= 0.0 {
        return None;
    }
    let diffuse = if with_diffuse {
        s.bsdf.diffuse_albedo() * FRAC_1_PI
    } else {
        Vec3::ZERO
    };
    let specular = s.bsdf.eval_specular(s.wo, ls.wi);
    let w = if ls.is_delta || !s.bsdf.has_specular() {
        1.0
    } else {
        power_heuristic(ls.pdf, s.bsdf.pdf_specular(s.wo, ls.wi))
    };
    let f = diffuse + specular * w;
    if f.max_element() <= 0.0 {
        return None;
    }
    let shadow = Ray::segment(s.origin_towards(ls.wi), ls.position);
    Some((shadow, f * ls.radiance * (cos / ls.pdf)))
}

/// The glossy lobe's indirect and MIS-weighted direct light, by sampling
/// the lobe and path tracing on.
pub(crate) fn glossy_query(s: &Surface, rng: &mut Rng) -> Option<RadianceQuery> {
    if !s.bsdf.has_specular() {
        return None;
    }
    let sample = s.bsdf.sample_specular(s.wo, rng.next_2d())?;
    let cos = s.bsdf.normal().dot(sample.wi);
    Some(RadianceQuery {
        ray: Ray::new(s.origin_towards(sample.wi), sample.wi, 0.0, f32::INFINITY),
        first_light: None,
        rng: rng.split(),
        weight: sample.f * (cos / sample.pdf),
        // The direct light of the same first hit ([`direct_light`]).
        first_hit: FirstHitEmission::Mis {
            bsdf_pdf: sample.pdf,
            light: TriangleSampling::SolidAngle,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Of the last frame's shadows, those that stand add their light where
    /// unoccluded and stay; the others are cleared, and the vector covers
    /// every sample of this frame (a rim's extra samples too), for the
    /// shadows traced again to fill.
    #[test]
    fn shadows_that_stand_add_their_light_and_stay() {
        let shadow = |contribution: f32, occluded| {
            Some(KeptShadow {
                ray: Ray::segment(Vec3::ZERO, Vec3::Z),
                contribution: Vec3::splat(contribution),
                occluded,
                clear: true,
            })
        };
        let last = vec![
            shadow(1.0, false),
            shadow(2.0, true),
            shadow(4.0, false),
            None,
        ];
        let stands = [true, true, false, true];
        let mut radiance = vec![Vec3::splat(0.5); 6];
        let kept = take_standing_shadows(last.clone(), &stands, &mut radiance);
        let sums: Vec<f32> = radiance.iter().map(|r| r.x).collect();
        assert_eq!(sums, [1.5, 0.5, 0.5, 0.5, 0.5, 0.5]);
        let expected = [last[0], last[1], None, None, None, None];
        let same = |a: &Option<KeptShadow>, b: &Option<KeptShadow>| match (a, b) {
            (Some(a), Some(b)) => a.contribution == b.contribution && a.occluded == b.occluded,
            (None, None) => true,
            _ => false,
        };
        assert_eq!(kept.len(), 6);
        assert!(kept.iter().zip(&expected).all(|(a, b)| same(a, b)));
    }
}
