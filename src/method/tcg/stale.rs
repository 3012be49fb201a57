//! Samples that moving lights have left stale. Departure from Tawara et
//! al., whose Eq. 2 shoots again, beyond the `τ_min` share, only the
//! samples that hit moving objects: under a light that moves with no
//! moving object in a record's view, the record's light then lags the
//! light's motion by many frames (on a wall light crossing a room, 9.5 %
//! of block bias against `ic`'s 0.5 %). The paper asks for it in its own
//! words ("more rays should be replaced when and where lighting quickly
//! changes", §3.3), and it recomputes its photon map every frame so that
//! the samples it shoots again see the lights as they are. Here a sample
//! also counts in Eq. 2's `x` where the unshadowed direct light at its hit
//! point (the record's point plus its cell's centre direction times its
//! stored distance) has changed by more than [`STALE_LIGHT`] since the
//! frame it was shot in, which its age gives, and every sample where the
//! lights' power has (a light switched off). Stale samples are drawn
//! before the others (`select::pick_cells`). A hit that no light reaches
//! directly (a ceiling above a panel facing down) shows indirect light
//! only, which the moving light changes too: such samples are still shot
//! again only at Eq. 2's `τ_min` share. Where no light moves over the
//! frames the ages span, nothing is computed and `tcg` is the paper's.

use crate::cache::gather::{cell_direction, GatherPoint, Strata};
use crate::method::unshadowed::{LightsByFrame, UnshadowedLights};
use crate::method::FrameContext;
use crate::sampling::Frame;
use crate::store::rgbe::PackedSample;
use glam::{Vec2, Vec3};

/// The relative change of a sample's unshadowed direct light (any colour
/// channel) past which it is stale: the 5 % of Eq. 2's `τ_min` and of
/// TRC's temporal accuracy `a_t`.
pub(super) const STALE_LIGHT: f32 = 0.05;

/// Frames of lights kept for the test: one shot in frame `f` has age 0
/// when frame `f + 1` picks its cells, so a sample of age `a < WINDOW` is
/// tested against the lights of its own frame `t − 1 − a`; an older one
/// (past a default `τ_min`'s refresh cycle of about 20 frames) against
/// those of `t − WINDOW`, the oldest kept, which moved lights change as
/// well.
const WINDOW: u32 = 32;

/// The lights of the last frames (by frame number, so a resumed render
/// finds the same ones: they are computed again from the scene).
#[derive(Default)]
pub(super) struct LightHistory {
    frames: LightsByFrame,
}

impl LightHistory {
    /// Keeps the lights of frame `ctx.frame` and of the frames its
    /// samples' ages reach back to.
    pub(super) fn advance(&mut self, ctx: &FrameContext) {
        let t = ctx.frame;
        let first = t.saturating_sub(WINDOW);
        self.frames.keep(first..=t);
        for f in first..=t {
            self.frames.at(ctx, f);
        }
    }

    /// The samples' light test for frame `t` (after [`Self::advance`] to
    /// it); `None` when the lights of every frame the samples' ages reach
    /// back to are those of this frame (no sample can be stale).
    pub(super) fn staleness(&self, t: u32) -> Option<Staleness<'_>> {
        let at = |f: u32| {
            self.frames
                .get(f)
                .expect("every frame of the window is in the history")
        };
        let now = at(t);
        let power = now.power();
        // By age a: the lights of frame t − 1 − a where they differ.
        let then: Vec<Option<Then>> = (0..WINDOW)
            .map(|a| {
                let lights = at(t.saturating_sub(1 + a));
                (!lights.same_as(now)).then(|| Then {
                    lights,
                    power_changed: relative_change(lights.power(), power) > STALE_LIGHT,
                })
            })
            .collect();
        then.iter()
            .any(Option::is_some)
            .then_some(Staleness { now, then })
    }
}

/// The lights a sample of some age was shot under.
struct Then<'a> {
    lights: &'a UnshadowedLights,
    /// Whether their power differs from this frame's by more than
    /// [`STALE_LIGHT`]: then every sample of that age is stale, those
    /// whose hit no light reaches directly too (a ceiling lit only by the
    /// floor when a panel facing down is switched off).
    power_changed: bool,
}

/// Which samples' light has changed since they were shot, in one frame.
pub(super) struct Staleness<'a> {
    now: &'a UnshadowedLights,
    /// By age: the lights of the frame a sample of that age was shot in,
    /// `None` where they are this frame's.
    then: Vec<Option<Then<'a>>>,
}

impl Staleness<'_> {
    /// Whether sample `cell` of a record at `point`, its cells laid out in
    /// `frame`, is stale. `point` and `frame` are the record's pose in
    /// this frame: on a moving object the hit is placed from where the
    /// record is now, not from where it was when the sample was shot (not
    /// kept), which differs only where a light and the record's object
    /// both move.
    pub(super) fn is_stale(
        &self,
        (point, frame): (&GatherPoint, &Frame),
        strata: Strata,
        cell: usize,
        s: &PackedSample,
    ) -> bool {
        let age = s.age().min(WINDOW - 1);
        let Some(Some(then)) = self.then.get(age as usize) else {
            return false;
        };
        if then.power_changed {
            return true;
        }
        if s.is_miss() {
            return false;
        }
        let dir = cell_direction(frame, strata, cell as u32, Vec2::splat(0.5));
        let hit = point.position + dir * s.distance();
        // The hit's normal is not stored: the light arriving from anywhere.
        let (before, after) = (then.lights.arriving_at(hit), self.now.arriving_at(hit));
        relative_change(before, after) > STALE_LIGHT
    }
}

/// `|b − a| / max(a, b)`, the largest over the colour channels; 0 where
/// both are (nearly) dark.
fn relative_change(a: Vec3, b: Vec3) -> f32 {
    let scale = a.max(b);
    let change = (b - a).abs() / scale.max(Vec3::splat(1e-12));
    Vec3::select(scale.cmpgt(Vec3::splat(1e-12)), change, Vec3::ZERO).max_element()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_change_takes_the_worst_channel_and_ignores_darkness() {
        let a = Vec3::new(1.0, 1.0, 0.0);
        assert_eq!(relative_change(a, Vec3::new(1.0, 0.5, 0.0)), 0.5);
        assert_eq!(relative_change(a, a), 0.0);
        assert_eq!(relative_change(Vec3::ZERO, Vec3::splat(1e-13)), 0.0);
        assert_eq!(relative_change(Vec3::ZERO, Vec3::ONE), 1.0);
    }
}
