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
//! Where the lights move, no result can be taken: the path's light samples
//! see them elsewhere. Its extension rays are the same (the same random
//! stream from the same point: the BSDF samples and the roulette do not
//! depend on the lights), and where its hits were static and no moving
//! object's box meets their segments now, each is still the nearest: the
//! path takes them ([`crate::integrator::Replay`]) and traces only its
//! shadow rays. Paths kept in frames after which the lights move keep
//! their hits alone (their shadow rays' segments would not be taken),
//! and only replacements keep them there: new records are often dropped
//! unused (a third on `wall_light`), where tracking theirs cost more than
//! it saved. Under a sliding panel, in rooms of 40K to 2M triangles,
//! `trc` took 0.86–0.91× the time, under the courtyard's swinging light
//! 0.94×, on `wall_light` the same (`benches/RESULTS.md`, "Under moving
//! lights, the paths' hits").
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

use crate::backend::{Hit, Ray};
use crate::integrator::{extension_segment, span, KnownPath, RadianceResult};
use crate::method::ic::GatherTracks;
use crate::method::motion::Blockers;
use glam::Vec3;

/// Bytes of kept paths `trc` holds at most over all its records: past
/// this, new records keep none (their replacements trace every path).
pub(crate) const BUDGET_BYTES: usize = 256 << 20;

/// One record's gather: each query's result, and the segments of those
/// kept (the queries whose path nothing moving met); the extension rays,
/// with their hits, of those whose extension rays nothing moving met.
pub(crate) struct KeptPaths {
    /// The lights' fingerprint when the paths were traced.
    lights: u64,
    results: Vec<RadianceResult>,
    /// Query `i`'s segments are `segments[ends[i - 1]..ends[i]]`. A path
    /// traces at least its first ray, so a query not kept is one with none.
    ends: Vec<u32>,
    segments: Vec<[Vec3; 2]>,
    /// Query `i`'s extension rays and hits are
    /// `extensions[extension_ends[i - 1]..extension_ends[i]]` (none: not
    /// kept).
    extension_ends: Vec<u32>,
    extensions: Vec<(Ray, Hit)>,
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
            .field("extensions", &self.extensions.len())
            .finish()
    }
}

impl KeptPaths {
    /// The paths of a gather this frame: `results` for each query,
    /// `tracks` of those traced (the others were taken from `taken_from`,
    /// which kept them), `blockers` this frame's moving objects, `lights`
    /// the lights' fingerprint and whether the results may be taken (where
    /// the lights move on, the paths are kept for their hits alone: their
    /// shadow rays need not be tested, nor held).
    pub(crate) fn of(
        results: &[RadianceResult],
        tracks: &GatherTracks,
        taken_from: Option<&KeptPaths>,
        blockers: &Blockers,
        (lights, whole): (u64, bool),
    ) -> Self {
        // About two segments a path (an extension ray and a shadow ray),
        // or as many as the paths taken from kept: no regrowing.
        let (segments, extensions) = taken_from.map_or((2 * results.len(), results.len()), |old| {
            (old.segments.len(), old.extensions.len())
        });
        let mut paths = KeptPaths {
            lights,
            // Where the lights move on, no result will be taken.
            results: if whole { results.to_vec() } else { Vec::new() },
            ends: Vec::with_capacity(results.len()),
            segments: Vec::with_capacity(segments),
            extension_ends: Vec::with_capacity(results.len()),
            extensions: Vec::with_capacity(extensions),
        };
        let mut path = tracks.first;
        for (i, &traced) in tracks.traced.iter().enumerate() {
            let (segments, extensions) = if traced {
                let (tracks, p) = (&tracks.tracks, path);
                path += 1;
                let (segments, extensions) = (tracks.segments(p), tracks.extensions(p));
                let stays = !tracks.hit_moving(p);
                // The extension rays' segments are among the path's.
                let all_clear = whole && stays && blockers.path_clear(segments);
                // Its hits were static: no moving object was nearer. While
                // no moving box meets their segments (`known`), none is.
                let clear = !whole && stays;
                (all_clear.then_some(segments), clear.then_some(extensions))
            } else {
                // Taken: nothing moving met it then or now.
                taken_from.map_or((None, None), |old| {
                    (old.segments_of(i), old.extensions_of(i))
                })
            };
            let (segments, extensions) = match whole {
                true => (segments, None),
                false => (None, extensions),
            };
            paths.segments.extend_from_slice(segments.unwrap_or(&[]));
            paths.ends.push(paths.segments.len() as u32);
            paths
                .extensions
                .extend_from_slice(extensions.unwrap_or(&[]));
            paths.extension_ends.push(paths.extensions.len() as u32);
        }
        paths
    }

    /// What a gather at this frame (with `blockers` and `lights`) may take
    /// of each query's path (`None`: trace it): its result where the
    /// lights are the same and no moving box meets its segments; else its
    /// extension rays' hits where none meets those.
    pub(crate) fn known(&self, blockers: &Blockers, lights: u64) -> Vec<Option<KnownPath<'_>>> {
        let same_lights = lights == self.lights && self.results.len() == self.len();
        (0..self.len())
            .map(|i| {
                if same_lights {
                    let clear = |s: &&[[Vec3; 2]]| blockers.path_clear(s);
                    let result = self.segments_of(i).filter(clear);
                    return result.map(|_| KnownPath::Result(self.results[i]));
                }
                (self.extensions_of(i))
                    .filter(|e| extensions_clear(blockers, e))
                    .map(KnownPath::Hits)
            })
            .collect()
    }

    /// The gather's paths (kept or not).
    pub(crate) fn len(&self) -> usize {
        self.ends.len()
    }

    /// Bytes held.
    pub(crate) fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.results.len() * std::mem::size_of::<RadianceResult>()
            + self.ends.len() * 4
            + self.segments.len() * std::mem::size_of::<[Vec3; 2]>()
            + self.extension_ends.len() * 4
            + self.extensions.len() * std::mem::size_of::<(Ray, Hit)>()
    }

    fn segments_of(&self, i: usize) -> Option<&[[Vec3; 2]]> {
        let segments = self.segments.get(span(&self.ends, i)?)?;
        (!segments.is_empty()).then_some(segments)
    }

    fn extensions_of(&self, i: usize) -> Option<&[(Ray, Hit)]> {
        let extensions = self.extensions.get(span(&self.extension_ends, i)?)?;
        (!extensions.is_empty()).then_some(extensions)
    }
}

/// Whether no moving box meets the segments `extensions` traced.
fn extensions_clear(blockers: &Blockers, extensions: &[(Ray, Hit)]) -> bool {
    (extensions.iter()).all(|(ray, hit)| blockers.path_clear(&[extension_segment(ray, hit)]))
}

/// What one frame's replacements were offered by the paths their records
/// kept: how many paths, how many of those they took whole, and how many
/// they took the hits of (traced again in other lights, or where a moving
/// object's box now meets a shadow ray).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Offered {
    pub(crate) paths: usize,
    pub(crate) taken: usize,
    pub(crate) relit: usize,
}

impl std::ops::AddAssign for Offered {
    fn add_assign(&mut self, other: Offered) {
        self.paths += other.paths;
        self.taken += other.taken;
        self.relit += other.relit;
    }
}

/// Whether keeping paths pays in this animation. Tracking a gather's paths
/// and testing their segments costs time of its own; where moving objects
/// cross most paths (`spheres`' 66 balls) few are taken, and keeping them
/// made `trc` 16 % slower. So new records keep their paths only while the
/// replacements of the last frames took at least half of the paths offered
/// them, whole or for their hits (counts decayed by [`PathsPay::DECAY`] a frame, so that one frame
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
        let taken = offered.taken + offered.relit;
        self.taken = self.taken * Self::DECAY + taken as f64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn offered(paths: usize, taken: usize) -> Offered {
        Offered {
            paths,
            taken,
            relit: 0,
        }
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
