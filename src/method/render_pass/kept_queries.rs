//! The path-traced parts of the render pass's pixel samples — the indirect
//! light of a sample no record covers, and glossy lobes — kept from one
//! frame for the next where nothing moving met them.
//!
//! Under coherent streams (`render_pass::PixelStreams::Coherent`) a pixel
//! sample draws the same camera ray, light sample and path in every frame,
//! so a query traced in the last frame is asked again, bit for bit, when
//! its sample hit the same surface and drew the same numbers. Its path then
//! traces exactly what it traced if it hit nothing moving, none of its
//! segments (extension and shadow rays) crosses a moving object's box now,
//! and the lights are where they were: its radiance is taken rather than
//! traced again, as `trc`'s replacements take their records' kept paths
//! (`trc::paths`) and the render pass its still samples' hits and shadows
//! (`render_pass::StillSamples`). The film is the one traced afresh.

use crate::integrator::{trace_radiance_tracked, PathLength, RadianceQuery};
use crate::method::motion::Blockers;
use crate::method::FrameContext;
use glam::Vec3;

/// One render tile's traced queries that may be taken in the next frame,
/// by base sample (the tile's `spp` samples a pixel, which are the same
/// samples in every frame).
#[derive(Default)]
pub(crate) struct KeptQueries {
    /// In sample order.
    queries: Vec<KeptQuery>,
    segments: Vec<[Vec3; 2]>,
    /// Bytes they may take: past this, no more are kept (those are traced
    /// again in the next frame).
    budget: usize,
}

struct KeptQuery {
    sample: u32,
    length: PathLength,
    query: RadianceQuery,
    radiance: Vec3,
    /// `segments[start..end]`.
    segments: (u32, u32),
}

/// The queries of one render tile this frame, `length` long, and the
/// base sample each belongs to (`None`: an extra sample of a light's rim,
/// never kept).
pub(crate) struct TileQueries {
    pub(crate) length: PathLength,
    pub(crate) samples: Vec<Option<u32>>,
    pub(crate) queries: Vec<RadianceQuery>,
}

impl KeptQueries {
    /// None yet, to take at most `budget` bytes.
    pub(crate) fn within(budget: usize) -> Self {
        KeptQueries {
            budget,
            ..KeptQueries::default()
        }
    }

    /// Traces `asked`, taking from `last` (the tile's kept queries of the
    /// last frame, given only where the lights stayed) the radiance of
    /// those it kept that no moving box of this frame (`blockers`) meets,
    /// and keeping here, for the next frame, every query of a base sample
    /// whose path met nothing moving. Returns each query's radiance, in
    /// order, and how many were taken.
    pub(crate) fn trace(
        &mut self,
        ctx: &FrameContext,
        asked: TileQueries,
        last: Option<&KeptQueries>,
        blockers: &Blockers,
    ) -> (Vec<Vec3>, u64) {
        let TileQueries {
            length,
            samples,
            queries,
        } = asked;
        let taken: Vec<Option<&KeptQuery>> = samples
            .iter()
            .zip(&queries)
            .map(|(&sample, query)| {
                let kept = last?.find(sample?, length, query)?;
                blockers.path_clear(last?.segments_of(kept)).then_some(kept)
            })
            .collect();
        let untaken: Vec<RadianceQuery> = queries
            .iter()
            .zip(&taken)
            .filter(|(_, t)| t.is_none())
            .map(|(q, _)| q.clone())
            .collect();
        let (traced, tracks) = trace_radiance_tracked(ctx, length, untaken);
        let mut traced = traced.into_iter().enumerate();
        let mut radiance = Vec::with_capacity(queries.len());
        let mut n_taken = 0;
        for ((sample, query), kept) in samples.into_iter().zip(queries).zip(taken) {
            let (r, segments) = match kept {
                Some(k) => {
                    n_taken += 1;
                    (k.radiance, last.map(|l| l.segments_of(k)))
                }
                None => {
                    let (path, result) = traced.next().expect("one result per query traced");
                    let segments = tracks.segments(path);
                    let keep = !tracks.hit_moving(path) && blockers.path_clear(segments);
                    (result.radiance, keep.then_some(segments))
                }
            };
            radiance.push(r);
            if let (Some(sample), Some(segments)) = (sample, segments) {
                self.keep(sample, length, query, r, segments);
            }
        }
        (radiance, n_taken)
    }

    /// Puts the queries in sample order, once every group is traced.
    pub(crate) fn finish(&mut self) {
        self.queries.sort_by_key(|q| q.sample);
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        self.queries.len() * std::mem::size_of::<KeptQuery>()
            + self.segments.len() * std::mem::size_of::<[Vec3; 2]>()
    }

    fn keep(
        &mut self,
        sample: u32,
        length: PathLength,
        query: RadianceQuery,
        radiance: Vec3,
        segments: &[[Vec3; 2]],
    ) {
        let bytes = std::mem::size_of::<KeptQuery>() + std::mem::size_of_val(segments);
        if self.memory_bytes() + bytes > self.budget {
            return;
        }
        let start = self.segments.len() as u32;
        self.segments.extend_from_slice(segments);
        self.queries.push(KeptQuery {
            sample,
            length,
            query,
            radiance,
            segments: (start, self.segments.len() as u32),
        });
    }

    /// The kept query of `sample` that is `query`, bit for bit, `length`
    /// long.
    fn find(&self, sample: u32, length: PathLength, query: &RadianceQuery) -> Option<&KeptQuery> {
        let first = self.queries.partition_point(|q| q.sample < sample);
        self.queries[first..]
            .iter()
            .take_while(|q| q.sample == sample)
            .find(|q| q.length == length && same_query(&q.query, query))
    }

    fn segments_of(&self, q: &KeptQuery) -> &[[Vec3; 2]] {
        &self.segments[q.segments.0 as usize..q.segments.1 as usize]
    }
}

/// Whether two queries are the same bit for bit (their paths then trace
/// the same rays in the same scene).
fn same_query(a: &RadianceQuery, b: &RadianceQuery) -> bool {
    let bits = |v: Vec3| v.to_array().map(f32::to_bits);
    bytemuck::bytes_of(&a.ray) == bytemuck::bytes_of(&b.ray)
        && a.rng == b.rng
        && bits(a.weight) == bits(b.weight)
        && a.first_light == b.first_light
        && a.first_hit == b.first_hit
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::Ray;
    use crate::integrator::FirstHitEmission;
    use crate::sampling::Rng;

    fn query(seed: u64) -> RadianceQuery {
        RadianceQuery {
            ray: Ray::new(Vec3::ZERO, Vec3::Y, 0.0, f32::INFINITY),
            first_light: None,
            rng: Rng::from_seed(seed, 0),
            weight: Vec3::ONE,
            first_hit: FirstHitEmission::Include,
        }
    }

    /// A kept query is found only by its sample, its length and the same
    /// query bit for bit (another random stream, another length: not
    /// found); past the budget nothing more is kept.
    #[test]
    fn queries_are_found_bit_for_bit_and_kept_within_the_budget() {
        let length = PathLength::default();
        let segment = [[Vec3::ZERO, Vec3::Y]];
        let one = std::mem::size_of::<KeptQuery>() + std::mem::size_of_val(&segment);
        let mut kept = KeptQueries::within(2 * one);
        kept.keep(3, length, query(1), Vec3::X, &segment);
        kept.keep(5, length, query(2), Vec3::Y, &segment);
        kept.keep(7, length, query(3), Vec3::Z, &segment);
        kept.finish();
        assert_eq!(kept.memory_bytes(), 2 * one);
        let found = kept.find(5, length, &query(2)).map(|q| q.radiance);
        assert_eq!(found, Some(Vec3::Y));
        assert_eq!(
            kept.segments_of(kept.find(3, length, &query(1)).unwrap()),
            &segment
        );
        assert!(kept.find(5, length, &query(1)).is_none());
        assert!(kept.find(3, length, &query(2)).is_none());
        let shorter = PathLength {
            max_depth: Some(0),
            ..length
        };
        assert!(kept.find(5, shorter, &query(2)).is_none());
        assert!(kept.find(7, length, &query(3)).is_none(), "over the budget");
    }
}
