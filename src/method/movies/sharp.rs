//! The direct light where the global pass's links land across a sharp
//! change of it: a shadow's edge, or the fall-off next to a light, within
//! one cell of the coarse mesh.
//!
//! The pass's radiosity `B` at a link's landing point is the Gouraud
//! interpolation of its vertices' (paper §3.1's good links, rendered
//! Gouraud-shaded). That is fine for the indirect part of `B`, which
//! varies slowly, but not for its direct part where a cell straddles a
//! shadow's edge or lies next to a light: the courtyard's shaded ground,
//! lit by sunlit walls and ground whose cells straddle the walls' shadows,
//! read 5–9 % dark against `path` per 8 × 8 block
//! (`tests/data/scenes/courtyard_swinging_light.glb`). The paper meets
//! this by refining its hierarchy where links carry much energy; our
//! departure keeps the mesh and, for each link whose landing cell's
//! vertices differ sharply in direct light ([`SHARP_RATIO`]), takes the
//! direct light at the link's own hit instead ([`SharpLandings`]). Links
//! elsewhere keep the interpolation; the indirect part of `B` is
//! interpolated everywhere.

use super::direct::{direct_irradiance, ShadePoint, ShadowBlockers, Statics};
use super::FrameContext;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;

/// A landing cell is sharp where its dimmest vertex has less than this
/// share of its brightest one's direct light (luminance). At 64 × 64 over
/// 12 frames of seven scenes, 1/4 took the courtyard's block bias from
/// 0.0122 to 0.0085 and `l_hall`'s from 0.0068 to 0.0061 (next to its
/// light); the others' moved by at most 8 % (`wall_light`'s up,
/// 0.0032 → 0.0034); 1/2 did as well on the courtyard for more links,
/// 1/8 lost `l_hall`'s gain (`benches/RESULTS.md`).
pub const SHARP_RATIO: f32 = 0.25;

/// Shadow samples at a sharp landing. A link's light is averaged with
/// those of its vertex's other links (128 by default), so few suffice;
/// one was too few next to an area light, where a single sample's
/// irradiance is heavy-tailed and the mean of a vertex's links mostly
/// falls short of it (`l_hall`'s block bias rose from 0.0068 to 0.0073 with
/// one, fell to 0.0061 with two).
pub const SHARP_SAMPLES: u32 = 2;

/// Whether direct light `values` at a landing cell's vertices change
/// sharply across it ([`SHARP_RATIO`]).
pub fn is_sharp(values: impl Iterator<Item = f32>) -> bool {
    let (lo, hi) = values.fold((f32::INFINITY, 0.0f32), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    hi > 0.0 && lo < SHARP_RATIO * hi
}

/// One link landing in a sharp cell: its number in the pass, the point
/// it hit (on the side it hit), and whether that point moves.
#[derive(Clone, Copy, Debug)]
pub struct Landing {
    pub link: u32,
    pub point: ShadePoint,
    pub moving: bool,
}

/// The direct irradiance at the hits of links that landed in sharp cells,
/// kept from frame to frame where it cannot have changed: the lights all
/// stand still and were picked as when it was found, the hit does not
/// move and its link was not traced again ([`SharpLandings::forget`]),
/// and no moving object's box stood, or stands, between the hit and the
/// lights. A kept value is then, bit for bit, what finding it again would
/// give (the same light samples against the same blockers), so the pass's
/// solution still depends on its frame alone.
#[derive(Clone, Debug, Default)]
pub struct SharpLandings {
    /// The light pick distribution the kept values were found under.
    fingerprint: u64,
    kept: HashMap<u32, Vec3>,
}

impl SharpLandings {
    /// Bytes held on the heap (a hash map's entries with their control
    /// byte, by capacity).
    pub fn bytes(&self) -> usize {
        self.kept.capacity() * (std::mem::size_of::<(u32, Vec3)>() + 1)
    }

    /// Let go of link `link`'s value: it was traced again.
    pub fn forget(&mut self, link: u32) {
        self.kept.remove(&link);
    }

    /// Direct irradiance at each landing ([`SHARP_SAMPLES`] shadow
    /// samples each), kept values taken where valid, and the shadow rays
    /// traced.
    pub fn irradiance(
        &mut self,
        ctx: &FrameContext,
        blockers: &ShadowBlockers,
        landings: &[Landing],
    ) -> (Vec<Vec3>, u64) {
        let keep = blockers.lights_still();
        if !keep || self.fingerprint != blockers.pick_fingerprint {
            self.kept.clear();
            self.fingerprint = blockers.pick_fingerprint;
        }
        // Whether each landing's light depends on the static scene alone
        // (found once: a box test each, in parallel).
        let clear: Vec<bool> = (landings.par_iter())
            .map(|l| keep && !l.moving && blockers.static_view_clear(l.point.p))
            .collect();
        let mut found = vec![Vec3::ZERO; landings.len()];
        let mut missing = Vec::new();
        for (i, l) in landings.iter().enumerate() {
            match self.kept.get(&l.link).filter(|_| clear[i]) {
                Some(&e) => found[i] = e,
                None => missing.push(i),
            }
        }
        let points: Vec<ShadePoint> = missing.iter().map(|&i| landings[i].point).collect();
        let (e, counts) = direct_irradiance(ctx, blockers, &points, SHARP_SAMPLES, Statics::Moving);
        for (&i, e) in missing.iter().zip(e) {
            found[i] = e;
            let link = landings[i].link;
            match clear[i] {
                true => self.kept.insert(link, e),
                false => self.kept.remove(&link),
            };
        }
        (found, counts.traced)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_is_sharp_where_its_direct_light_falls_to_a_quarter() {
        assert!(is_sharp([1.0, 0.2, 0.9].into_iter()));
        assert!(is_sharp([0.0, 2.0].into_iter()));
        assert!(!is_sharp([1.0, 0.3, 0.9].into_iter()));
        // A cell in full shadow has nothing to interpolate wrongly.
        assert!(!is_sharp([0.0, 0.0, 0.0].into_iter()));
    }
}
