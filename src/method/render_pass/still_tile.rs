//! One render tile's kept samples ([`KeptTile`]) and what of them stands
//! this frame: the tile's view of the frame's [`StillPass`] ([`TileStill`])
//! decides, sample by sample, whether a kept hit, shadow and cache lookup
//! stand ([`Standing`]), and [`TileKept`] gathers what the tile traced for
//! the next frame. The frame-level decisions (the moving boxes, the view
//! and the lights) are `render_pass::still`'s.

use super::kept_queries::KeptQueries;
use super::still::StillPass;
use super::{PrimarySamples, Surface};
use crate::backend::{Hit, Ray};
use crate::cache::LookupPoint;
use crate::method::pixels::{CandidateCoverage, EmitterEdges};
use crate::method::FrameContext;
use crate::sampling::Rng;
use glam::Vec3;

/// One tile's kept samples (its base samples, in order, a field each: a
/// frame moves them into its own samples and back rather than copying them
/// one by one) and the coverage of its candidate edge pixels.
#[derive(Default)]
pub(super) struct KeptTile {
    /// Each sample's camera ray and hit.
    rays: Vec<Ray>,
    hits: Vec<Hit>,
    /// Each sample's stream after the camera's draw.
    rngs: Vec<Rng>,
    /// Each sample's direct light's shadow (`None`: it had none).
    shadows: Vec<Option<KeptShadow>>,
    /// Each sample's cache lookup, an index into `lookups` ([`NO_LOOKUP`]:
    /// none).
    lookup_of: Vec<u32>,
    coverage: Vec<CandidateCoverage>,
    /// The lookups its samples index; `None` where they did not fit the
    /// budget.
    lookups: Option<Vec<KeptLookup>>,
    /// The path-traced parts of its samples that nothing moving met.
    pub(super) queries: KeptQueries,
}

impl KeptTile {
    /// Bytes a kept sample takes.
    pub(super) const SAMPLE_BYTES: usize = std::mem::size_of::<Ray>()
        + std::mem::size_of::<Hit>()
        + std::mem::size_of::<Rng>()
        + std::mem::size_of::<Option<KeptShadow>>()
        + std::mem::size_of::<u32>();

    /// Bytes held, counted by capacity: the samples' vectors keep room
    /// for a light rim's extra samples, which the frames append to them.
    pub(super) fn memory_bytes(&self) -> usize {
        fn held<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        held(&self.rays)
            + held(&self.hits)
            + held(&self.rngs)
            + held(&self.shadows)
            + held(&self.lookup_of)
            + held(&self.coverage)
            + self.lookups.as_ref().map_or(0, held)
            + self.queries.memory_bytes()
    }
}

/// A kept sample's lookup index where it looked nothing up.
const NO_LOOKUP: u32 = u32::MAX;

/// A cache lookup of a tile's base samples as this frame made it, and
/// whether no moving box lay on its clearance ray then (so what the ray
/// hit, if anything, was static).
#[derive(Clone, Copy)]
pub(super) struct KeptLookup {
    at: LookupPoint,
    clear: bool,
}

/// A shadow ray, what its light adds if unoccluded, whether it was, and
/// whether no moving box lay on it in the frame it is kept from.
#[derive(Clone, Copy)]
pub(super) struct KeptShadow {
    pub(super) ray: Ray,
    pub(super) contribution: Vec3,
    pub(super) occluded: bool,
    pub(super) clear: bool,
}

/// One tile's part of a [`StillPass`]: its samples in the last frame and
/// the coverage of its candidate edge pixels then.
pub(super) struct TileStill<'a> {
    pub(super) pass: &'a StillPass,
    kept: KeptTile,
}

impl<'a> TileStill<'a> {
    /// The tile's part of `pass`, with its samples in the last frame.
    pub(super) fn new(pass: &'a StillPass, kept: KeptTile) -> Self {
        TileStill { pass, kept }
    }

    /// The coverage of the tile's candidate edge pixels in the last frame.
    pub(super) fn coverage(&self) -> &[CandidateCoverage] {
        &self.kept.coverage
    }

    /// The path-traced parts of the tile's samples kept from the last
    /// frame.
    pub(super) fn queries(&self) -> &KeptQueries {
        &self.kept.queries
    }

    /// The last frame's shadows of the tile's base samples (`None`: it had
    /// none), moved out: call it once the shadows' standing is known
    /// ([`Self::standing`]).
    pub(super) fn take_shadows(&mut self) -> Vec<Option<KeptShadow>> {
        std::mem::take(&mut self.kept.shadows)
    }

    /// The last frame's camera rays, hits and streams of the tile's `n`
    /// base samples, moved out (`None` where none were kept): the caller
    /// keeps those whose hits stand ([`Self::hit_stands`]) and overwrites
    /// the others.
    pub(super) fn take_primary(&mut self, n: usize) -> Option<(Vec<Ray>, Vec<Hit>, Vec<Rng>)> {
        let kept = &mut self.kept;
        (n > 0 && kept.hits.len() == n).then(|| {
            (
                std::mem::take(&mut kept.rays),
                std::mem::take(&mut kept.hits),
                std::mem::take(&mut kept.rngs),
            )
        })
    }

    /// Whether a kept sample's camera hit stands this frame (`film_clear`:
    /// whether no moving box shows near its pixel).
    pub(super) fn hit_stands(&self, ray: &Ray, hit: &Hit, film_clear: bool) -> bool {
        self.pass.hit_stands(ray, hit, film_clear)
    }

    /// Whether base sample `i`'s hit was taken (`taken`) and its shadow in
    /// the last frame stands (or it had none, and has none again).
    fn shadow_stands(&self, i: usize, taken: &[bool]) -> bool {
        taken.get(i).copied().unwrap_or(false)
            && self.pass.lights_still
            && self.kept.shadows[i].is_none_or(|s| self.pass.shadow_stands(&s))
    }
}

/// What of the last frame's shading of a tile's base samples stands this
/// frame.
pub(super) struct Standing {
    /// Per base sample, whether its shadow stands
    /// ([`TileStill::shadow_stands`]).
    pub(super) shadows: Vec<bool>,
    /// Per base sample, whether its pixel is kept whole: it is no light's
    /// edge pixel (with extra samples), every sample of it has its hit and
    /// shadow taken and a plain material ([`Surface::is_plain`]), and no
    /// moving box lies on the clearance ray of any lookup they made, in the
    /// last frame or this one. Such a
    /// pixel takes its lookups from the last frame, and its samples need
    /// no [`Surface`] unless one falls back to path tracing.
    pub(super) whole: Vec<bool>,
}

impl TileStill<'_> {
    /// What of the tile's base samples (the first `taken.len()` of
    /// `primary`, `taken` saying whose hits were taken) stands.
    pub(super) fn standing(
        &self,
        ctx: &FrameContext,
        primary: &PrimarySamples,
        taken: &[bool],
    ) -> Standing {
        let shadows: Vec<bool> = (0..taken.len())
            .map(|i| self.shadow_stands(i, taken))
            .collect();
        let mut whole = vec![false; taken.len()];
        let Some(lookups) = self.kept.lookups.as_deref() else {
            return Standing { shadows, whole };
        };
        let camera = ctx.snapshot.camera.position;
        // Each lookup tested once: a pixel's samples share it.
        let mut stands = vec![None; lookups.len()];
        let mut lookup_stands = |k: u32| {
            k == NO_LOOKUP
                || *stands[k as usize].get_or_insert_with(|| {
                    let kept = lookups[k as usize];
                    kept.clear && self.pass.clearance_clear(&kept.at, camera)
                })
        };
        let (base, extra) = primary.samples.split_at(taken.len());
        // A light's edge pixels have extra samples, which may share their
        // base samples' lookups: those pixels are never kept whole.
        let mut edges: Vec<u32> = extra.iter().map(|s| s.pixel).collect();
        edges.sort_unstable();
        edges.dedup();
        let mut start = 0;
        while start < base.len() {
            let pixel = base[start].pixel;
            let end = start
                + base[start..]
                    .iter()
                    .take_while(|s| s.pixel == pixel)
                    .count();
            let kept = edges.binary_search(&pixel).is_err()
                && (start..end).all(|i| {
                    shadows[i]
                        && Surface::is_plain(ctx, &primary.hits[i])
                        && lookup_stands(self.kept.lookup_of[i])
                });
            whole[start..end].fill(kept);
            start = end;
        }
        Standing { shadows, whole }
    }

    /// The last frame's lookups of the samples `whole` keeps, appended to
    /// `lookups` (each once) and indexed from `of_sample`; how many.
    pub(super) fn take_lookups(
        &self,
        whole: &[bool],
        lookups: &mut Vec<LookupPoint>,
        of_sample: &mut [Option<u32>],
    ) -> u64 {
        let Some(kept) = self.kept.lookups.as_deref() else {
            return 0;
        };
        let first = lookups.len();
        let mut index = vec![NO_LOOKUP; kept.len()];
        for (i, _) in whole.iter().enumerate().filter(|(_, &w)| w) {
            let k = self.kept.lookup_of[i];
            if k == NO_LOOKUP {
                continue;
            }
            if index[k as usize] == NO_LOOKUP {
                index[k as usize] = lookups.len() as u32;
                lookups.push(kept[k as usize].at);
            }
            of_sample[i] = Some(index[k as usize]);
        }
        (lookups.len() - first) as u64
    }

    /// This frame's lookups of the tile's base samples (`of_sample`, the
    /// first `taken.len()` of them), for the next frame, where they fit in
    /// the tile's budget (`None` where they do not): each with whether its
    /// clearance ray is clear, known for the lookups from `first_kept` on
    /// (taken from the last frame, they stood); and each base sample's
    /// index among them.
    pub(super) fn keep_lookups(
        &self,
        camera: Vec3,
        (lookups, of_sample): (&[LookupPoint], &[Option<u32>]),
        first_kept: usize,
    ) -> Option<(Vec<KeptLookup>, Vec<u32>)> {
        let mut index = vec![NO_LOOKUP; lookups.len()];
        let mut kept = Vec::new();
        let of_base = of_sample
            .iter()
            .map(|k| {
                let Some(k) = k.map(|k| k as usize) else {
                    return NO_LOOKUP;
                };
                if index[k] == NO_LOOKUP {
                    index[k] = kept.len() as u32;
                    let at = lookups[k];
                    let clear = k >= first_kept || self.pass.clearance_clear(&at, camera);
                    kept.push(KeptLookup { at, clear });
                }
                index[k]
            })
            .collect();
        (kept.len() * std::mem::size_of::<KeptLookup>() <= self.pass.tile_budget)
            .then_some((kept, of_base))
    }
}

/// A tile's base samples as traced this frame and its candidates'
/// coverage (empty when nothing is kept), and how many of its samples were
/// taken from the last frame.
#[derive(Default)]
pub(super) struct TileKept {
    pub(super) tile: KeptTile,
    pub(super) taken: u64,
    /// Lookups taken from the last frame (those of pixels kept whole).
    pub(super) lookups_taken: u64,
    /// Path-traced queries taken from the last frame.
    pub(super) queries_taken: u64,
}

impl TileKept {
    /// The base samples (the first `taken.len()`) of `primary`, with their
    /// streams as the camera left them (`jittered`; none: nothing is kept),
    /// their shadows and their lookups (`None`: not kept; then no pixel of
    /// the tile can be kept whole next frame), and the coverage `edges`
    /// found.
    pub(super) fn of(
        primary: PrimarySamples,
        taken: &[bool],
        jittered: Vec<Rng>,
        mut shadows: Vec<Option<KeptShadow>>,
        lookups: Option<(Vec<KeptLookup>, Vec<u32>)>,
        edges: &EmitterEdges,
    ) -> Self {
        let n = jittered.len();
        let (lookups, lookup_of) = lookups.unzip();
        let PrimarySamples {
            mut rays, mut hits, ..
        } = primary;
        // Shrunk, not only truncated: a tile's rays and hits stay until the
        // pass ends, and where none of them are kept (`ic`, a tile where
        // something moved) their capacity held 52 bytes a sample for
        // nothing: most of `ic`'s peak (at 1024 × 1024 and 16 spp, 830 MiB).
        keep_first(&mut rays, n);
        keep_first(&mut hits, n);
        keep_first(&mut shadows, n);
        let mut lookup_of = lookup_of.unwrap_or_else(|| vec![NO_LOOKUP; n]);
        lookup_of.truncate(n);
        let coverage = if n > 0 {
            edges.coverage().to_vec()
        } else {
            Vec::new()
        };
        TileKept {
            tile: KeptTile {
                rays,
                hits,
                rngs: jittered,
                shadows,
                lookup_of,
                coverage,
                lookups,
                queries: KeptQueries::default(),
            },
            taken: taken.iter().filter(|&&t| t).count() as u64,
            lookups_taken: 0,
            queries_taken: 0,
        }
    }
}

/// `v` cut to its first `n` elements, its spare capacity freed.
fn keep_first<T>(v: &mut Vec<T>, n: usize) {
    v.truncate(n);
    v.shrink_to_fit();
}
