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
//! stored distance, the record posed as it was in the frame the sample
//! was shot in, which its age gives) may have changed by more than
//! [`STALE_LIGHT`] since that frame, and every sample where the lights'
//! power has (a light switched off). The hit's normal is not stored, so
//! the change is bounded over every normal
//! (`UnshadowedLights::change_at`, a bound of ours): a light that only
//! turns about the hit changes the light of a surface at an angle to it
//! as much as one that comes nearer (a sun turning; a far point light
//! swinging across the sky, which a test of the light arriving from
//! every direction, this module's before 2026-12-02, missed: `tests/tcg.rs`,
//! where that lagged the light as the paper's rule does). Stale samples are drawn
//! before the others (`select::pick_cells`). A hit that no light reaches
//! directly (a ceiling above a panel facing down) shows indirect light
//! only, which the moving light changes too: such samples are still shot
//! again only at Eq. 2's `τ_min` share. Where no light moves over the
//! frames the ages span, nothing is computed and `tcg` is the paper's.

use super::TcgRecord;
use crate::cache::gather::{cell_direction, GatherPoint, Strata};
use crate::method::unshadowed::{LightsByFrame, UnshadowedLights};
use crate::method::FrameContext;
use crate::sampling::Frame;
use crate::store::rgbe::PackedSample;
use glam::{Mat4, Vec2, Vec3};
use std::collections::BTreeMap;

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

/// The lights and objects' world transforms of the last frames (by frame
/// number, so a resumed render finds the same ones: they are computed
/// again from the scene).
#[derive(Default)]
pub(super) struct LightHistory {
    frames: LightsByFrame,
    objects: BTreeMap<u32, Vec<Mat4>>,
}

impl LightHistory {
    /// Keeps the lights of frame `ctx.frame` and of the frames its
    /// samples' ages reach back to.
    pub(super) fn advance(&mut self, ctx: &FrameContext) {
        let t = ctx.frame;
        let first = t.saturating_sub(WINDOW);
        self.frames.keep(first..=t);
        self.objects.retain(|f, _| (first..=t).contains(f));
        for f in first..=t {
            self.frames.at(ctx, f);
            self.objects.entry(f).or_insert_with(|| {
                if f == t {
                    ctx.snapshot.object_to_world.clone()
                } else {
                    ctx.scene.object_transforms(ctx.time_of(f))
                }
            });
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
                    objects: &self.objects[&t.saturating_sub(1 + a)],
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
    /// The objects' world transforms of that frame: where its records were.
    objects: &'a [Mat4],
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
    /// Whether each of record `r`'s samples, in cell order, is stale.
    pub(super) fn stale_cells(&self, r: &TcgRecord, strata: Strata) -> Vec<bool> {
        // The record's pose by age, found once for all its samples of it.
        let mut poses: Vec<Option<(GatherPoint, Frame)>> = vec![None; self.then.len()];
        let mut stale = |(cell, s): (usize, &PackedSample)| {
            let age = s.age().min(WINDOW - 1) as usize;
            let Some(Some(then)) = self.then.get(age) else {
                return false;
            };
            let pose = poses[age].get_or_insert_with(|| r.pose(then.objects));
            self.is_stale(then, pose, strata, cell, s)
        };
        r.samples.iter().enumerate().map(&mut stale).collect()
    }

    /// Whether sample `cell`, shot under `then` by a record then at
    /// `point` with its cells laid out in `frame`, is stale. Its hit is
    /// placed from where the record was when it was shot, not from where
    /// it is now (they differ on a moving object), and both lights are
    /// measured there: a hit on a still surface is where it was.
    fn is_stale(
        &self,
        then: &Then,
        (point, frame): &(GatherPoint, Frame),
        strata: Strata,
        cell: usize,
        s: &PackedSample,
    ) -> bool {
        if then.power_changed {
            return true;
        }
        if s.is_miss() {
            return false;
        }
        let dir = cell_direction(frame, strata, cell as u32, Vec2::splat(0.5));
        let hit = point.position + dir * s.distance();
        // The hit's normal is not stored: the most its light may have
        // changed on any normal, against the most it may be.
        let (change, scale) = then.lights.change_at(self.now, hit);
        relative(change, scale) > STALE_LIGHT
    }
}

/// `|b − a| / max(a, b)`, the largest over the colour channels; 0 where
/// both are (nearly) dark.
fn relative_change(a: Vec3, b: Vec3) -> f32 {
    relative((b - a).abs(), a.max(b))
}

/// `change / scale`, the largest over the colour channels; 0 where
/// `scale` is (nearly) dark.
fn relative(change: Vec3, scale: Vec3) -> f32 {
    let share = change / scale.max(Vec3::splat(1e-12));
    Vec3::select(scale.cmpgt(Vec3::splat(1e-12)), share, Vec3::ZERO).max_element()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record made at the origin on an object that has since moved by
    /// `Δ` = (0.5, 0, 0), one sample of age 0 hitting 1 away along its
    /// first cell, and a light 0.1 above where that hit was made that has
    /// moved 0.01 sideways (along z, square to the lines from it to both
    /// places of the hit). The hit was made from where the record was, and
    /// there the light turned by about 0.1 rad: stale (a surface at an
    /// angle to it may see 10 % more or less). Placed from where the
    /// record is now, 0.51 from the light, it turned by 0.02 rad and came
    /// no nearer: not stale.
    #[test]
    fn a_moving_records_hit_is_placed_where_the_record_was() {
        let strata = Strata::default();
        let point = GatherPoint {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            geometric_normal: Vec3::Y,
        };
        let record = TcgRecord {
            record: crate::cache::IrradianceRecord::flat(0, Vec3::ZERO, Vec3::ONE),
            candidate: crate::method::ic::Candidate::at(point),
            object_to_world: Mat4::IDENTITY,
            samples: vec![PackedSample::pack(Vec3::ONE, 1.0, 1, false, 0)],
            used: true,
        };
        let delta = Vec3::new(0.5, 0.0, 0.0);
        let dir = cell_direction(&Frame::new(Vec3::Y), strata, 0, Vec2::splat(0.5));
        let light = dir + 0.1 * Vec3::Y;
        let (lights_then, lights_now) = (
            UnshadowedLights::point(light, Vec3::ONE),
            UnshadowedLights::point(light + 0.01 * Vec3::Z, Vec3::ONE),
        );
        let stale = |objects_then: &[Mat4]| {
            let staleness = Staleness {
                now: &lights_now,
                then: vec![Some(Then {
                    lights: &lights_then,
                    objects: objects_then,
                    power_changed: false,
                })],
            };
            staleness.stale_cells(&record, strata)
        };
        assert_eq!(stale(&[Mat4::IDENTITY]), [true]);
        assert_eq!(stale(&[Mat4::from_translation(delta)]), [false]);
    }

    #[test]
    fn relative_change_takes_the_worst_channel_and_ignores_darkness() {
        let a = Vec3::new(1.0, 1.0, 0.0);
        assert_eq!(relative_change(a, Vec3::new(1.0, 0.5, 0.0)), 0.5);
        assert_eq!(relative_change(a, a), 0.0);
        assert_eq!(relative_change(Vec3::ZERO, Vec3::splat(1e-13)), 0.0);
        assert_eq!(relative_change(Vec3::ZERO, Vec3::ONE), 1.0);
    }
}
