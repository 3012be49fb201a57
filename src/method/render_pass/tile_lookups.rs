//! The render pass's cache lookups of a tile: one per pixel and triangle
//! rather than one per pixel sample ([`pixel_lookups`]), those the pixels
//! kept whole take from the last frame, their interpolation, and what is
//! kept of them for the next frame ([`TileLookups`]).

use super::still_tile::{KeptLookup, TileStill};
use super::{Surface, TilePass, TileShading};
use crate::backend::Hit;
use crate::cache::{Interpolated, LookupPoint};
use crate::method::ic::GlossyLobe;
use crate::method::lookups::{measure_clearance, ShadingPoint};
use crate::method::pixels::PixelSample;
use crate::method::{FrameContext, FrameStats};
use glam::Vec3;

/// A tile's cache lookups and their interpolated irradiance: this frame's
/// (one per pixel and triangle, [`pixel_lookups`]) and, from `first_taken`
/// on, those the pixels kept whole take from the last frame.
pub(super) struct TileLookups {
    pub(super) lookups: Vec<LookupPoint>,
    /// Each sample's lookup (an index into `lookups`), if it made one.
    pub(super) of_sample: Vec<Option<u32>>,
    first_taken: usize,
    /// How many lookups were taken from the last frame.
    pub(super) taken: u64,
    interpolated: Vec<Option<Interpolated>>,
}

impl TileLookups {
    /// The lookups of `tile`'s shaded samples, those `still` keeps for its
    /// pixels kept whole, all interpolated at once (flagging the records
    /// used where the pass asks); counted in `stats`.
    pub(super) fn new(
        ctx: &FrameContext,
        pass: &TilePass,
        tile: &TileShading,
        still: Option<&TileStill>,
        stats: &mut FrameStats,
    ) -> Self {
        let (mut lookups, mut of_sample) = pixel_lookups(
            ctx,
            &tile.surfaces,
            &tile.primary.hits,
            &tile.primary.samples,
            pass.settings.glossy,
        );
        let first_taken = lookups.len();
        let taken = still.map_or(0, |s| {
            s.take_lookups(&tile.whole, &mut lookups, &mut of_sample)
        });
        let interpolated = pass.interpolation.interpolate(&lookups, pass.used);
        stats.lookups = lookups.len() as u64;
        stats.lookup_records = interpolated
            .iter()
            .flatten()
            .map(|e| u64::from(e.records))
            .sum();
        TileLookups {
            lookups,
            of_sample,
            first_taken,
            taken,
            interpolated,
        }
    }

    /// The lookups of the tile's `n_base` base samples, kept for the next
    /// frame within `still`'s budget ([`TileStill::keep_lookups`]).
    pub(super) fn keep(
        &self,
        ctx: &FrameContext,
        still: &TileStill,
        n_base: usize,
    ) -> Option<(Vec<KeptLookup>, Vec<u32>)> {
        let camera = ctx.snapshot.camera.position;
        let of_base = (&self.lookups[..], &self.of_sample[..n_base]);
        still.keep_lookups(camera, of_base, self.first_taken)
    }

    /// Sample `i`'s interpolated irradiance: `None` where it made no
    /// lookup, `Some(None)` where its lookup found no usable record.
    pub(super) fn of(&self, i: usize) -> Option<&Option<Interpolated>> {
        self.of_sample[i].map(|l| &self.interpolated[l as usize])
    }
}

/// The render pass's cache lookups: one per pixel and triangle hit, at the
/// mean shading point and normal of the pixel's samples on that triangle,
/// rather than one per pixel sample; and, per sample, its lookup (`None`
/// for samples that do not look the cache up).
///
/// Why: the interpolated irradiance (TRC Eq. 1–4) varies smoothly over a
/// pixel's footprint, and the mean of a linear function over the samples is
/// its value at their mean point, so sharing the lookup loses only the
/// curvature of `E` within one pixel, far below the cache's own
/// interpolation error. The lookups, about a quarter of the render pass at
/// 16 samples per pixel, fall to about one per pixel. Each sample keeps its
/// own visibility, emission, direct light and glossy lobe: the shading rate
/// of the cache is decoupled from the visibility sampling, as in MSAA.
/// Samples on different triangles never share (an edge, a corner), nor do
/// samples spread wider than their lookup's clearance ([`split_narrow`]).
pub(super) fn pixel_lookups(
    ctx: &FrameContext,
    surfaces: &[Option<Surface>],
    hits: &[Hit],
    samples: &[PixelSample],
    glossy: GlossyLobe,
) -> (Vec<LookupPoint>, Vec<Option<u32>>) {
    let shading_points: Vec<Option<(u32, ShadingPoint)>> = surfaces
        .iter()
        .zip(hits)
        .map(|(surface, hit)| {
            let s = surface.as_ref()?;
            let diffuse = s.bsdf.diffuse_albedo().max_element() > 0.0;
            let radiance = glossy == GlossyLobe::Eas && s.bsdf.has_specular();
            (!s.bsdf.is_black() && (diffuse || radiance))
                .then(|| (hit.triangle, (s.p, s.bsdf.normal())))
        })
        .collect();
    let pixel_of: Vec<u32> = samples.iter().map(|s| s.pixel).collect();
    let (points, of_sample) = share_lookups(&shading_points, &pixel_of);
    let shared = measure_clearance(ctx, &points);
    let (mut lookups, of_sample, own) = split_narrow(shared, of_sample, &shading_points);
    lookups.extend(measure_clearance(ctx, &own));
    (lookups, of_sample)
}

/// Gives each sample of a shared lookup its own lookup (and clearance)
/// where the samples lie farther from the shared point than its
/// clearance: there `E` is not smooth over the pixel, and the clearance
/// of one point does not speak for the others. The case is a pixel that
/// sees, at a grazing angle, both the ceiling above a light hung just
/// under it (dark) and the open ceiling beyond the light's edge: one
/// lookup at their mean point shades the whole pixel with one or the
/// other. Such pixels are few (one ray per sample of theirs is traced
/// again).
///
/// Returns the shared lookups kept, in order; each sample's lookup, where
/// the samples of split ones index, in sample order, past the kept ones;
/// and the shading points of those samples, whose lookups (with their
/// clearance) the caller appends.
fn split_narrow(
    shared: Vec<LookupPoint>,
    mut of_sample: Vec<Option<u32>>,
    points: &[Option<(u32, ShadingPoint)>],
) -> (Vec<LookupPoint>, Vec<Option<u32>>, Vec<ShadingPoint>) {
    let point_of = |i: usize| {
        points[i]
            .expect("a sample with a lookup has a shading point")
            .1
    };
    let mut spread = vec![0.0f32; shared.len()];
    for (i, k) in of_sample.iter().enumerate() {
        if let Some(k) = *k {
            let d = (point_of(i).0 - shared[k as usize].position).length();
            spread[k as usize] = spread[k as usize].max(d);
        }
    }
    let narrow: Vec<bool> = shared
        .iter()
        .zip(&spread)
        .map(|(at, &s)| at.clearance < s)
        .collect();
    if !narrow.contains(&true) {
        return (shared, of_sample, Vec::new());
    }
    // The shared lookups kept, in order, then one per sample of the others.
    let mut index = vec![None; shared.len()];
    let mut lookups = Vec::with_capacity(shared.len());
    for (k, at) in shared.iter().enumerate() {
        if !narrow[k] {
            index[k] = Some(lookups.len() as u32);
            lookups.push(*at);
        }
    }
    let mut own = Vec::new();
    for (i, k) in of_sample.iter_mut().enumerate() {
        if let Some(shared_k) = *k {
            *k = index[shared_k as usize].or_else(|| {
                own.push(point_of(i));
                Some((lookups.len() + own.len() - 1) as u32)
            });
        }
    }
    (lookups, of_sample, own)
}

/// [`pixel_lookups`] over each sample's triangle and shading point (`None`:
/// no lookup) and pixel; a pixel's samples are consecutive (a run of equal
/// pixels shares lookups).
fn share_lookups(
    samples: &[Option<(u32, ShadingPoint)>],
    pixel_of: &[u32],
) -> (Vec<ShadingPoint>, Vec<Option<u32>>) {
    let mut lookups: Vec<ShadingPoint> = Vec::new();
    let mut counts: Vec<f32> = Vec::new();
    let mut of_sample = vec![None; samples.len()];
    // The current pixel's (triangle, lookup) pairs: a pixel hits few.
    let mut pixel: Vec<(u32, u32)> = Vec::with_capacity(4);
    for (i, sample) in samples.iter().enumerate() {
        if i == 0 || pixel_of[i] != pixel_of[i - 1] {
            pixel.clear();
        }
        let Some((triangle, (point, normal))) = *sample else {
            continue;
        };
        let k = match pixel.iter().find(|(t, _)| *t == triangle) {
            Some(&(_, k)) => k,
            None => {
                let k = lookups.len() as u32;
                lookups.push((Vec3::ZERO, Vec3::ZERO));
                counts.push(0.0);
                pixel.push((triangle, k));
                k
            }
        };
        let (p, n) = &mut lookups[k as usize];
        *p += point;
        *n += normal;
        counts[k as usize] += 1.0;
        of_sample[i] = Some(k);
    }
    for ((p, n), count) in lookups.iter_mut().zip(counts) {
        *p /= count;
        *n = n.normalize();
    }
    (lookups, of_sample)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two pixels of four samples: the first pixel's samples on triangles 7
    /// and 9 (and one that looks nothing up), the second's all on 7 again.
    /// One lookup per pixel and triangle, at the mean point and the
    /// normalised mean normal; a triangle seen by two pixels is looked up
    /// in each.
    #[test]
    fn pixel_samples_share_one_lookup_per_triangle() {
        let n = Vec3::Z;
        let tilted = Vec3::new(0.6, 0.0, 0.8);
        let samples = [
            Some((7, (Vec3::new(0.0, 0.0, 0.0), n))),
            Some((9, (Vec3::new(5.0, 0.0, 0.0), tilted))),
            None,
            Some((7, (Vec3::new(2.0, 4.0, 0.0), n))),
            Some((7, (Vec3::new(1.0, 1.0, 0.0), n))),
            Some((7, (Vec3::new(3.0, 1.0, 0.0), Vec3::new(0.0, 0.6, 0.8)))),
            Some((7, (Vec3::new(1.0, 3.0, 0.0), Vec3::new(0.0, -0.6, 0.8)))),
            Some((7, (Vec3::new(3.0, 3.0, 0.0), n))),
        ];
        let (lookups, of_sample) = share_lookups(&samples, &[0, 0, 0, 0, 1, 1, 1, 1]);
        assert_eq!(
            of_sample,
            [
                Some(0),
                Some(1),
                None,
                Some(0),
                Some(2),
                Some(2),
                Some(2),
                Some(2)
            ]
        );
        assert_eq!(lookups.len(), 3);
        assert!((lookups[0].0 - Vec3::new(1.0, 2.0, 0.0)).length() < 1e-6);
        assert!((lookups[0].1 - n).length() < 1e-6);
        assert!((lookups[1].0 - Vec3::new(5.0, 0.0, 0.0)).length() < 1e-6);
        assert!((lookups[1].1 - tilted).length() < 1e-6);
        assert!((lookups[2].0 - Vec3::new(2.0, 2.0, 0.0)).length() < 1e-6);
        assert!((lookups[2].1 - n).length() < 1e-6);
    }

    /// Pixel 0's two samples lie 0.5 from their shared point, under a
    /// surface 0.1 above it: each gets its own lookup, after pixel 1's
    /// (kept, its clearance 2 above its spread). Nothing splits when every
    /// clearance exceeds its spread.
    #[test]
    fn samples_spread_wider_than_the_clearance_get_their_own_lookups() {
        let n = Vec3::Z;
        let points = [
            Some((7, (Vec3::new(-0.5, 0.0, 0.0), n))),
            Some((7, (Vec3::new(0.5, 0.0, 0.0), n))),
            None,
            Some((8, (Vec3::new(3.0, 0.0, 0.0), n))),
        ];
        let of_sample = vec![Some(0), Some(0), None, Some(1)];
        let shared = |clearance_0| {
            vec![
                LookupPoint::new(Vec3::ZERO, n, clearance_0),
                LookupPoint::new(Vec3::new(3.0, 0.0, 0.0), n, 2.0),
            ]
        };
        let (lookups, of, own) = split_narrow(shared(0.1), of_sample.clone(), &points);
        assert_eq!(lookups, shared(0.1)[1..]);
        assert_eq!(of, [Some(1), Some(2), None, Some(0)]);
        assert_eq!(own, [points[0].unwrap().1, points[1].unwrap().1]);
        let (lookups, of, own) = split_narrow(shared(0.6), of_sample.clone(), &points);
        assert_eq!((lookups, of, own), (shared(0.6), of_sample, Vec::new()));
    }
}
