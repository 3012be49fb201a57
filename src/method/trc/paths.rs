//! The paths of a record's gather that nothing moving met, kept for the
//! record that replaces it.
//!
//! A replacement is gathered at K's point with K's random streams (§4.4,
//! "p_l = p_K"; `ic::first_stream`), so each of its paths starts as K's
//! did. A path of K that met no moving object — no hit on one, no segment
//! (extension or shadow ray) through one's box — and whose segments no
//! moving object's box meets at the replacement's frame either, with the
//! lights where they were, traces there exactly what it traced for K: the
//! same static hits, the same light samples, the same radiance. Its result
//! is taken rather than traced again; only the other paths are traced.
//! The record is the one a full gather gives (`tests/trc.rs` compares them
//! bit for bit), so frames, stores and resumed renders (which start with
//! nothing kept and trace everything) are unchanged.
//!
//! Not in the paper, whose GPU renderer gathers a record by rasterising
//! its hemisphere: this is the CPU counterpart of the render pass's kept
//! samples (`render_pass::StillSamples`), for the records' gathers, which
//! are most of `trc`'s time.
//!
//! Caveat shared with the kept samples: two static triangles hit at exactly
//! the same t may be told apart in another order by a BVH rebuilt around
//! moved objects. (Until the traversal found hits nearer than 1e-4,
//! `accel::NEAR_SHIFT`, a path with a segment under 1e-3 was not kept
//! either: another frame's BVH might have missed its hit.)

use crate::integrator::RadianceResult;
use crate::method::ic::GatherTracks;
use crate::method::motion::Blockers;
use glam::Vec3;

/// Bytes of kept paths `trc` holds at most over all its records: past
/// this, new records keep none (their replacements trace every path).
pub(crate) const BUDGET_BYTES: usize = 256 << 20;

/// One record's gather: each query's result, and the segments of those
/// kept (the queries whose path nothing moving met).
pub(crate) struct KeptPaths {
    /// The lights' fingerprint when the paths were traced.
    lights: u64,
    results: Vec<RadianceResult>,
    /// Query `i`'s segments are `segments[ends[i - 1]..ends[i]]`. A path
    /// traces at least its first ray, so a query not kept is one with none.
    ends: Vec<u32>,
    segments: Vec<[Vec3; 2]>,
}

impl std::fmt::Debug for KeptPaths {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KeptPaths")
            .field("queries", &self.results.len())
            .field(
                "kept",
                &(0..self.len())
                    .filter(|&i| self.segments_of(i).is_some())
                    .count(),
            )
            .field("segments", &self.segments.len())
            .finish()
    }
}

impl KeptPaths {
    /// The paths of a gather this frame: `results` for each query,
    /// `tracks` of those traced (the others were taken from `taken_from`,
    /// which kept them), `blockers` this frame's moving objects, `lights`
    /// the lights' fingerprint.
    pub(crate) fn of(
        results: &[RadianceResult],
        tracks: &GatherTracks,
        taken_from: Option<&KeptPaths>,
        blockers: &Blockers,
        lights: u64,
    ) -> Self {
        // About two segments a path (an extension ray and a shadow ray),
        // or as many as the paths taken from kept: no regrowing.
        let segments = taken_from.map_or(2 * results.len(), |old| old.segments.len());
        let mut paths = KeptPaths {
            lights,
            results: results.to_vec(),
            ends: Vec::with_capacity(results.len()),
            segments: Vec::with_capacity(segments),
        };
        let mut path = tracks.first;
        for (i, &traced) in tracks.traced.iter().enumerate() {
            let segments = if traced {
                let segments = tracks.tracks.segments(path);
                let moving = tracks.tracks.hit_moving(path);
                path += 1;
                (!moving && blockers.path_clear(segments)).then_some(segments)
            } else {
                // Taken: nothing moving met it then or now.
                taken_from.and_then(|old| old.segments_of(i))
            };
            paths.segments.extend_from_slice(segments.unwrap_or(&[]));
            paths.ends.push(paths.segments.len() as u32);
        }
        paths
    }

    /// The results a gather at this frame (with `blockers` and `lights`)
    /// may take, per query (`None`: trace it); `None` when the lights
    /// changed.
    pub(crate) fn known(
        &self,
        blockers: &Blockers,
        lights: u64,
    ) -> Option<Vec<Option<RadianceResult>>> {
        (lights == self.lights).then(|| {
            (0..self.results.len())
                .map(|i| {
                    self.segments_of(i)
                        .filter(|segments| blockers.path_clear(segments))
                        .map(|_| self.results[i])
                })
                .collect()
        })
    }

    /// The gather's paths (kept or not).
    pub(crate) fn len(&self) -> usize {
        self.results.len()
    }

    /// Bytes held.
    pub(crate) fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.results.len() * std::mem::size_of::<RadianceResult>()
            + self.ends.len() * 4
            + self.segments.len() * std::mem::size_of::<[Vec3; 2]>()
    }

    fn segments_of(&self, i: usize) -> Option<&[[Vec3; 2]]> {
        let end = *self.ends.get(i)? as usize;
        let start = if i == 0 { 0 } else { self.ends[i - 1] as usize };
        let segments = &self.segments[start..end];
        (!segments.is_empty()).then_some(segments)
    }
}

/// What one frame's replacements were offered by the paths their records
/// kept: how many paths, and how many of those they took.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Offered {
    pub(crate) paths: usize,
    pub(crate) taken: usize,
}

/// Whether keeping paths pays in this animation. Tracking a gather's paths
/// and testing their segments costs time of its own; where moving objects
/// cross most paths (`spheres`' 66 balls) few are taken, and keeping them
/// made `trc` 16 % slower. So new records keep their paths only while the
/// replacements of the last frames took at least half of the paths offered
/// them (counts decayed by [`PathsPay::DECAY`] a frame, so that one frame
/// whose few replacements all lay by a moving object does not decide),
/// and, so that a scene whose motion calms down is noticed, in every
/// `δt_max`-th frame (whose records are replaced about `δt_max` frames
/// later). Which records keep paths changes no record and no frame.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PathsPay {
    offered: f64,
    taken: f64,
}

impl PathsPay {
    /// The weight of a frame's counts one frame later.
    const DECAY: f64 = 0.9;

    /// Whether frame `t`'s new records keep their paths.
    pub(crate) fn track(&self, t: u32, max_life: u32) -> bool {
        2.0 * self.taken >= self.offered || t % max_life.max(1) == 0
    }

    /// Takes what a frame's replacements were offered and took.
    pub(crate) fn measure(&mut self, offered: Offered) {
        self.offered = self.offered * Self::DECAY + offered.paths as f64;
        self.taken = self.taken * Self::DECAY + offered.taken as f64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn offered(paths: usize, taken: usize) -> Offered {
        Offered { paths, taken }
    }

    /// Paths are kept from the start, stop being kept when under half of
    /// those offered lately were taken, are kept again in every
    /// `δt_max`-th frame to see whether they would pay, and again for good
    /// once they do; one poor frame after good ones does not decide.
    #[test]
    fn paths_are_kept_while_half_of_them_are_taken() {
        let mut pay = PathsPay::default();
        assert!(pay.track(1, 20));
        pay.measure(offered(100, 49));
        assert!(!pay.track(21, 20) && pay.track(40, 20));
        pay.measure(Offered::default());
        assert!(!pay.track(41, 20));
        for _ in 0..20 {
            pay.measure(offered(100, 90));
        }
        assert!(pay.track(41, 20));
        pay.measure(offered(300, 0));
        assert!(pay.track(42, 20), "one poor frame after good ones");
        for _ in 0..30 {
            pay.measure(offered(100, 10));
        }
        assert!(!pay.track(43, 20));
    }
}
