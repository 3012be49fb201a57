//! A `trc` record with its life (TRC §4.4–4.6): how long it may be used
//! (the temporal weight, Eq. 7 and 9–11, over a radiance record's sources
//! Eq. 21) and how it changes meanwhile (the temporal gradients, Eq. 14–20).

use super::paths::KeptPaths;
use super::TemporalGradients;
use crate::cache::eas::Eas;
use crate::cache::{IrradianceRecord, RecordId};
use crate::method::ic::Candidate;
use glam::Vec3;
use std::sync::Arc;

/// The record l that replaced K at K's point (TRC §4.4), as far as K's
/// interpolated temporal gradients (Eq. 18–20) need it.
#[derive(Clone, Debug)]
pub struct Successor {
    /// `t_l`, the frame l was gathered in (K's last frame is `t_l − 1`).
    pub frame: u32,
    pub id: RecordId,
    pub irradiance: Vec3,
    pub grad_rotation: [Vec3; 3],
    pub grad_translation: [Vec3; 3],
}

impl Successor {
    /// New record `l` as its predecessor's successor.
    pub(super) fn of(l: &TemporalRecord) -> Self {
        Successor {
            frame: l.record.created_frame,
            id: l.record.id,
            irradiance: l.record.irradiance,
            grad_rotation: l.record.grad_rotation,
            grad_translation: l.record.grad_translation,
        }
    }
}

/// A record with its life (TRC §4.4–4.5).
#[derive(Clone, Debug)]
pub struct TemporalRecord {
    /// The record as gathered at `t0 = record.created_frame` (its radius as
    /// clamped by the latest cache it was in).
    pub record: IrradianceRecord,
    /// Where it was gathered (kept for replacement at the same point).
    pub(crate) candidate: Candidate,
    /// Estimate of `E(t0+1)` (§4.7), from which its change (Eq. 7) and
    /// its extrapolated temporal gradient (Eq. 15) follow.
    pub next_irradiance: Vec3,
    /// Last frame K may contribute to (Eq. 10 and 11).
    pub last_valid: u32,
    /// A radiance record's (`--ic-glossy eas`) extrapolated temporal
    /// gradient of each of its sources' irradiance, in the order of
    /// `record.eas` (§4.6.2: each coefficient's own Eq. 15).
    pub d_eas: Option<Arc<[Vec3]>>,
    /// The record this one replaced at the same point, if any.
    pub replaces: Option<RecordId>,
    /// Whether a pixel sample used K in the last rendered frame.
    pub used: bool,
    /// The paths of K's gather that nothing moving met, for its
    /// replacement to take ([`super::paths`]; in memory only).
    pub(crate) paths: Option<Arc<KeptPaths>>,
}

impl TemporalRecord {
    /// Worst channel of `|τ − 1|`, `τ = E(t0+1)/E(t0)` (Eq. 7, 9), and of
    /// a radiance record's sources (Eq. 21): the change that bounds its
    /// temporal weight.
    pub fn change(&self) -> f32 {
        change_of(&self.record, self.next_irradiance, self.d_eas.as_deref())
    }

    /// Extrapolated temporal gradient ∇t_E (Eq. 15 with `t1 − t0 = 1`);
    /// not those of the spatial gradients (Eq. 16–17: why at `at_frame`).
    pub fn d_irradiance(&self) -> Vec3 {
        self.next_irradiance - self.record.irradiance
    }

    /// Takes the radius neighbour clamping left in the frame's cache and
    /// whether a pixel used the record; returns whether either changed
    /// (its carried state must then be written again).
    pub(super) fn sync(&mut self, radius: f32, used: bool) -> bool {
        let changed = self.record.radius.to_bits() != radius.to_bits() || self.used != used;
        self.record.radius = radius;
        self.used = used;
        changed
    }

    /// Bytes it holds apart from its sources (which the frame's cache
    /// counts): itself and its sources' temporal gradients.
    pub(super) fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.d_eas.as_deref().map_or(0, std::mem::size_of_val)
            + self.paths.as_deref().map_or(0, KeptPaths::memory_bytes)
    }

    /// TRC Eq. 14: the record as it is used at frame `t`: interpolated
    /// towards its replacement `successor` (Eq. 18–20, E and both spatial
    /// gradients) when the gradients are interpolated and it is known,
    /// else E extrapolated (Eq. 15).
    ///
    /// Departure: the paper extrapolates the spatial gradients too (Eq.
    /// 16–17, their change from t0 to the estimate of t0+1). Those changes
    /// come from the reprojected samples, whose cells move in whole cells
    /// and whose holes take their farthest neighbour's distance, so a
    /// frame's change of a gradient is a jump, not a rate: carried over a
    /// life of up to `δt_max` frames, and bounded by nothing (Eq. 9–10
    /// bound E's change alone), it tilted records into discs up to 10 of
    /// 255 too bright in the PNG of the default render of cube-in-box
    /// (frame 12 at 256 × 256, against `path` at 512 spp), and moved the
    /// light by three times `a_t` (`tests/trc.rs`). Without it `trc`'s error,
    /// block bias and flicker fell on cube-in-box, under the moving light
    /// and among the balls, and its records were the same
    /// (`benches/RESULTS.md`, "Extrapolated gradients: E alone"). Neither
    /// computed nor stored since (store schema 11).
    pub(super) fn at_frame(
        &self,
        t: u32,
        gradients: TemporalGradients,
        successor: Option<&Successor>,
    ) -> IrradianceRecord {
        let mut r = self.record.clone();
        let t0 = r.created_frame;
        let (d_e, d_r, d_p) = match (gradients, successor) {
            (TemporalGradients::None, _) => return r,
            (TemporalGradients::Interpolated, Some(l)) if l.frame > t0 => {
                // Eq. 18–20: (X(t_l) − X(t_K)) / (t_l − t_K).
                let span = (l.frame - t0) as f32;
                let d = |a: [Vec3; 3], b: [Vec3; 3]| {
                    [
                        (a[0] - b[0]) / span,
                        (a[1] - b[1]) / span,
                        (a[2] - b[2]) / span,
                    ]
                };
                (
                    (l.irradiance - r.irradiance) / span,
                    d(l.grad_rotation, r.grad_rotation),
                    d(l.grad_translation, r.grad_translation),
                )
            }
            _ => (self.d_irradiance(), [Vec3::ZERO; 3], [Vec3::ZERO; 3]),
        };
        r.irradiance = extrapolated(r.irradiance, d_e, t.saturating_sub(t0));
        let dt = t.saturating_sub(t0) as f32;
        for c in 0..3 {
            r.grad_rotation[c] += d_r[c] * dt;
            r.grad_translation[c] += d_p[c] * dt;
        }
        // A radiance record's sources follow their extrapolated gradients
        // with either kind of gradients: its replacement keeps another cut
        // of its own tree, so Eq. 18–20 have no source of l to pair with
        // each source of K.
        if let (Some(sources), Some(d)) = (&r.eas, &self.d_eas) {
            if dt > 0.0 {
                r.eas = Some(
                    sources
                        .iter()
                        .zip(d.iter())
                        .map(|(s, d)| Eas {
                            irradiance: (s.irradiance + *d * dt).max(Vec3::ZERO),
                            ..*s
                        })
                        .collect(),
                );
            }
        }
        r
    }

    /// TRC Eq. 9–11: `w_t(t) = 1/((τ−1)(t−t0)) ≥ 1/a^t` and `t − t0 < δt_max`.
    pub fn is_valid_at(&self, t: u32) -> bool {
        t >= self.record.created_frame && t <= self.last_valid
    }

    /// Whether its life ended before its temporal weight ended it (Eq.
    /// 10–11): at a later frame whose motion departed from the
    /// extrapolated one ([`super::later`]). Its replacement then shows the
    /// light after that departure, which interpolated gradients (Eq.
    /// 18–20, a steady change) must not spread over K's life.
    pub(super) fn ended_at_a_departure(&self, temporal_accuracy: f32, max_life: u32) -> bool {
        let t0 = self.record.created_frame;
        self.last_valid < t0 + frames_of_validity(self.change(), temporal_accuracy, max_life)
    }

    /// Whether K, expired after a frame that used it, is replaced by a new
    /// record at its point (TRC §4.4, `p_l = p_K`) rather than dropped.
    ///
    /// Departure: not when K lived one frame short of a longer `δt_max`
    /// (its light changed by more than `a^t` from t0 to t0+1). The paper
    /// replaces in place for two ends: the accuracy at a point stays the
    /// same over time, and K's gradients can be interpolated towards its
    /// successor (Eq. 18–20). K served frame t0 alone, where its temporal
    /// gradients weigh nothing (`t − t0 = 0`), and where the light changes
    /// that fast a point's accuracy changes every frame anyway. Replaced,
    /// such records were put back whether or not other records cover their
    /// points, every frame: dropped, `ic`'s fill makes a record only where
    /// none is usable. Where everything moves (`benches/scenes/
    /// many_cubes.py 20`, 24 frames) `trc` computed 14,847 records instead
    /// of 19,753 (`ic` 14,457) in about 0.8× the time; on the built-in
    /// `spheres` 29,960 instead of 42,103 in 0.7× the time; the error and
    /// flicker within 1 % of before on both, and on cube-in-box (400
    /// frames) and moving-light too (`benches/RESULTS.md`, "Records that
    /// lived one frame are not replaced").
    pub(super) fn replaced_when_expired(&self, max_life: u32) -> bool {
        self.lifespan() > 1 || max_life <= 1
    }

    /// Frames K may contribute to (Eq. 10–11): `last_valid − t0 + 1`, from 1
    /// to `δt_max`.
    pub fn lifespan(&self) -> u32 {
        self.last_valid + 1 - self.record.created_frame
    }
}

#[cfg(test)]
impl TemporalRecord {
    /// A record at the origin facing +y, of irradiance `e0`, whose
    /// estimate predicts `change` (for tests).
    pub(super) fn test_record(e0: Vec3, change: f32) -> TemporalRecord {
        let point = crate::cache::gather::GatherPoint {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            geometric_normal: Vec3::Y,
        };
        TemporalRecord {
            record: crate::cache::IrradianceRecord::flat(0, Vec3::ZERO, e0),
            candidate: crate::method::ic::Candidate::at(point),
            next_irradiance: e0 * (1.0 + change),
            last_valid: 0,
            d_eas: None,
            replaces: None,
            used: false,
            paths: None,
        }
    }
}

/// `|τ − 1|` of TRC Eq. 7, `τ = E(t0+1)/E(t0)` per channel: the worst
/// channel decides. A channel dark at t0 that lights up is an infinite
/// change; one dark at both is none.
pub(super) fn relative_change(e0: Vec3, e1: Vec3) -> f32 {
    (0..3)
        .map(|c| {
            let (a, b) = (e0[c], e1[c]);
            if a > 0.0 {
                (b / a - 1.0).abs()
            } else if b > 0.0 {
                f32::INFINITY
            } else {
                0.0
            }
        })
        .fold(0.0f32, f32::max)
}

/// TRC Eq. 21 over a radiance record's sources: the largest `|τ − 1|` of
/// any source (each channel as in [`relative_change`]), given each
/// source's change `d_eas` to the next frame; 0 for an irradiance record.
/// The record's irradiance keeps its own Eq. 7 besides: the diffuse part
/// of a glossy surface interpolates it. Eq. 21 takes the largest ratio
/// `λ₁/λ₀`, which a source that dims never sets: taken literally, a
/// light turning away from the surface would leave its record valid for
/// `δt_max` frames. The temporal weight (Eq. 9) measures change either
/// way through `|τ − 1|`, so the largest `|τ − 1|` is what is taken here.
pub(super) fn sources_change(record: &IrradianceRecord, d_eas: Option<&[Vec3]>) -> f32 {
    let (Some(sources), Some(d)) = (&record.eas, d_eas) else {
        return 0.0;
    };
    sources
        .iter()
        .zip(d)
        .map(|(s, d)| relative_change(s.irradiance, s.irradiance + *d))
        .fold(0.0f32, f32::max)
}

/// The change that bounds the temporal weight of `record` gathered at
/// t0 whose E at a later frame is `e` and its sources' changes `d_eas`:
/// the worst of its own (Eq. 7) and its sources' (Eq. 21).
pub(super) fn change_of(record: &IrradianceRecord, e: Vec3, d_eas: Option<&[Vec3]>) -> f32 {
    relative_change(record.irradiance, e).max(sources_change(record, d_eas))
}

/// E(t0+1) of a replacement made at t0 with `e0` whose estimate is
/// `estimate`, given the change a frame `observed` over the life of the
/// record it replaces: the estimate, or `e0` carried on by the observed
/// change where that is the larger relative change (Eq. 7's worst
/// channel).
///
/// Departure (`TrcSettings::history`): the paper estimates E(t0+1) by
/// reprojection alone (§4.7), which moves each sample's hit point with its
/// object but keeps its radiance, so it misses what lights those points
/// differently: light of more than one bounce that a moving object
/// changes, or its shadow moving over what the record sees. A record
/// whose estimate saw no change lived `δt_max` frames while that light
/// drifted, and its replacement, the same. The replacement itself
/// measures that drift, noise all but cancelled (the same random streams,
/// the paths nothing moving met taken as they were), and where it is the
/// larger change it sets the life (Eq. 9–10) and the extrapolated gradient
/// (Eq. 15) as an estimate would. A radiance record's sources keep their
/// estimated changes (the replacement cuts its own tree, so no source of
/// it pairs with one of K's, as for Eq. 18–20). On `l_hall`, against
/// `path` at 1024 spp over all 24 frames and seeds 0–3, the block bias
/// fell from 0.01161 to 0.01072 (lower in every seed) for 11 % more
/// records; 2 % lower on the shared `cube_in_box` for 8 % more; equal
/// under moving lights (`benches/RESULTS.md`, "The change a replacement
/// observes").
pub(super) fn with_observed_change(e0: Vec3, estimate: Vec3, observed: Vec3) -> Vec3 {
    let carried_on = extrapolated(e0, observed, 1);
    if relative_change(e0, carried_on) > relative_change(e0, estimate) {
        carried_on
    } else {
        estimate
    }
}

/// The irradiance a record made at t0 with `e0` (and E(t0+1) estimated
/// as `e1`) shows `dt` frames later as its lifespan is judged at its
/// creation (Eq. 14 with Eq. 15's gradient, as [`TemporalRecord::at_frame`]
/// applies it): `e0` without temporal gradients, and with interpolated
/// ones too, which lead towards the replacement not yet made (it is made
/// anew where the life ends, so their value meets the light there).
pub(super) fn shown_irradiance(gradients: TemporalGradients, e0: Vec3, e1: Vec3, dt: u32) -> Vec3 {
    match gradients {
        TemporalGradients::Extrapolated => extrapolated(e0, e1 - e0, dt),
        TemporalGradients::None | TemporalGradients::Interpolated => e0,
    }
}

/// `e0` carried `dt` frames along the change `d_e` a frame, never below
/// zero.
fn extrapolated(e0: Vec3, d_e: Vec3, dt: u32) -> Vec3 {
    (e0 + d_e * dt as f32).max(Vec3::ZERO)
}

/// How many frames after t0 a record whose irradiance changes by `change`
/// a frame stays valid. Eq. 9–10: `1/(|τ−1|(t−t0)) ≥ 1/a^t ⇔ t − t0 ≤
/// a^t/|τ−1|`; Eq. 11: `t − t0 < δt_max`.
pub(super) fn frames_of_validity(change: f32, temporal_accuracy: f32, max_life: u32) -> u32 {
    let max_age = max_life.max(1) - 1;
    if change <= 0.0 {
        return max_age;
    }
    let a = (temporal_accuracy / change).floor();
    if a.is_finite() {
        (a as u32).min(max_age)
    } else {
        max_age
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An expired record is replaced at its point if it lived more than one
    /// frame; one that lived a single frame is dropped unless every life is
    /// one frame (`δt_max = 1`), where the paper's rule stands.
    #[test]
    fn only_records_that_lived_more_than_a_frame_are_replaced() {
        let mut k = TemporalRecord::test_record(Vec3::ONE, 0.2);
        k.record.created_frame = 7;
        let replaced = |k: &TemporalRecord, max_life| k.replaced_when_expired(max_life);
        k.last_valid = 7;
        assert_eq!(k.lifespan(), 1);
        assert!(!replaced(&k, 20));
        assert!(!replaced(&k, 2));
        assert!(replaced(&k, 1));
        k.last_valid = 8;
        assert!(replaced(&k, 20));
        assert!(replaced(&k, 2));
    }

    /// The worst channel decides; a channel that lights up from black is an
    /// infinite change, one black at both frames none.
    #[test]
    fn relative_change_is_the_worst_channel() {
        let e0 = Vec3::new(1.0, 2.0, 0.0);
        assert!((relative_change(e0, Vec3::new(1.01, 1.9, 0.0)) - 0.05).abs() < 1e-6);
        assert_eq!(relative_change(e0, e0), 0.0);
        assert_eq!(relative_change(e0, Vec3::new(1.0, 2.0, 0.1)), f32::INFINITY);
    }

    /// Eq. 21 over a radiance record's sources: light moving from one
    /// source to another leaves the irradiance as it was, but not the
    /// sources; the worst source decides. An irradiance record has none.
    #[test]
    fn sources_change_is_the_worst_source() {
        let source = |node, e: f32| Eas {
            offset: Vec3::Y,
            solid_angle: 0.1,
            irradiance: Vec3::splat(e),
            node,
        };
        let mut record = IrradianceRecord {
            id: 0,
            position: Vec3::ZERO,
            normal: Vec3::Y,
            irradiance: Vec3::splat(3.0),
            grad_translation: [Vec3::ZERO; 3],
            grad_rotation: [Vec3::ZERO; 3],
            radius: 1.0,
            created_frame: 0,
            object: 0,
            eas: Some(vec![source(1, 1.0), source(2, 2.0)].into()),
        };
        // 0.1 moves from the second source to the first.
        let d = [Vec3::splat(0.1), Vec3::splat(-0.1)];
        assert_eq!(relative_change(Vec3::splat(3.0), Vec3::splat(3.0)), 0.0);
        assert!((sources_change(&record, Some(&d)) - 0.1).abs() < 1e-6);
        assert_eq!(sources_change(&record, None), 0.0);
        record.eas = None;
        assert_eq!(sources_change(&record, Some(&d)), 0.0);
    }

    /// Extrapolated gradients carry E alone; the spatial gradients stay
    /// the record's own (`at_frame`'s departure), and what the lifespan's
    /// check takes the record to show is what it shows. Interpolated ones
    /// with a successor carry all three towards it (Eq. 18–20).
    #[test]
    fn extrapolated_gradients_carry_e_alone() {
        let mut k = TemporalRecord::test_record(Vec3::splat(2.0), 0.01);
        k.record.created_frame = 10;
        k.record.grad_translation = [Vec3::X; 3];
        k.next_irradiance = Vec3::splat(2.02);
        let at = k.at_frame(14, TemporalGradients::Extrapolated, None);
        assert!(at.irradiance.abs_diff_eq(Vec3::splat(2.08), 1e-5));
        assert_eq!(at.grad_translation, [Vec3::X; 3]);
        assert_eq!(at.grad_rotation, [Vec3::ZERO; 3]);
        let shown = |g| shown_irradiance(g, k.record.irradiance, k.next_irradiance, 4);
        assert_eq!(shown(TemporalGradients::Extrapolated), at.irradiance);
        assert_eq!(shown(TemporalGradients::None), Vec3::splat(2.0));
        // Never below zero.
        k.next_irradiance = Vec3::splat(1.0);
        let at = k.at_frame(14, TemporalGradients::Extrapolated, None);
        assert_eq!(at.irradiance, Vec3::ZERO);

        let l = Successor {
            frame: 20,
            id: 1,
            irradiance: Vec3::splat(3.0),
            grad_rotation: [Vec3::ZERO; 3],
            grad_translation: [Vec3::splat(11.0); 3],
        };
        let at = k.at_frame(15, TemporalGradients::Interpolated, Some(&l));
        assert!(at.irradiance.abs_diff_eq(Vec3::splat(2.5), 1e-5));
        let expected = Vec3::new(6.0, 5.5, 5.5);
        assert!(at
            .grad_translation
            .iter()
            .all(|g| g.abs_diff_eq(expected, 1e-5)));
    }

    /// The observed change replaces the estimate where it is the larger
    /// relative change (never below zero), in whichever direction; where
    /// the estimate's is larger, or they are equal, the estimate stands.
    #[test]
    fn the_larger_of_the_estimate_and_the_observed_change_is_taken() {
        let e0 = Vec3::new(1.0, 2.0, 4.0);
        let estimate = Vec3::new(1.01, 2.0, 4.0);
        let drifting = Vec3::new(0.0, 0.0, -0.2);
        assert_eq!(
            with_observed_change(e0, estimate, drifting),
            Vec3::new(1.0, 2.0, 3.8)
        );
        assert_eq!(
            with_observed_change(e0, estimate, Vec3::splat(0.005)),
            estimate
        );
        assert_eq!(
            with_observed_change(e0, estimate, Vec3::new(0.01, 0.0, 0.0)),
            estimate
        );
        assert_eq!(with_observed_change(e0, e0, Vec3::ZERO), e0);
        let darkening = with_observed_change(e0, estimate, Vec3::splat(-5.0));
        assert_eq!(darkening, Vec3::ZERO);
    }

    /// Eq. 9–11 with `a^t = 0.05`, `δt_max = 20`: 1 % a frame stays valid 5
    /// frames after t0, 6 % none, and no change at most 19 (t − t0 < 20).
    #[test]
    fn validity_follows_the_temporal_weight_and_the_lifespan_bound() {
        assert_eq!(frames_of_validity(0.01, 0.05, 20), 5);
        assert_eq!(frames_of_validity(0.06, 0.05, 20), 0);
        assert_eq!(frames_of_validity(0.0, 0.05, 20), 19);
        assert_eq!(frames_of_validity(0.001, 0.05, 20), 19);
        assert_eq!(frames_of_validity(f32::INFINITY, 0.05, 20), 0);
        assert_eq!(frames_of_validity(0.0, 0.05, 1), 0);
    }
}
