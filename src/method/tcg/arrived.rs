//! Records that a moving object came into the view of since the last
//! frame. Departure from Tawara et al., whose Eq. 2 shoots again at
//! `τ_max` only the samples that hit moving objects: a block that jumps
//! into a room's corner, or grows there, or slides in from behind a wall,
//! is in none of the samples of the records that now see it, so its
//! light, and its shadows on what their samples hit, came in over some
//! `1/τ_min` frames (`tests/tcg.rs`). Here a record is dropped where, in
//! one frame, moving objects newly cross more than [`ARRIVAL_SHARE`] of
//! its samples' paths ([`crate::method::arrivals`], `trc`'s test, over
//! each cell's centre direction): the share of its cosine-weighted view
//! they may newly cover. Objects that none of its samples hit in the last
//! frame count, and so do those they hit where the share of the view the
//! object's bounding sphere covers grew by more than [`ARRIVAL_SHARE`]
//! (it jumped nearer, or grew). Where a pixel still needs a record, `fill`
//! makes one there that sees the scene as it is.
//!
//! An object that some samples hit and that stays as large in the view is
//! left to Eq. 2 (those samples are shot again at `τ_max`), as `trc`
//! leaves it to its reprojection: dropping the records beside every
//! moving ball of `spheres` as well took 2.6 times the records and 16 %
//! more time there, for the same error (`benches/RESULTS.md`).
//!
//! Records on moving objects are left to the paper's rule: their samples'
//! paths moved too, so what crossed them in the last frame is not known
//! from the objects' places alone.
//!
//! On by default (`TcgSettings::arrivals`); what it costs is in
//! `benches/RESULTS.md`.

use super::TcgRecord;
use crate::cache::gather::{cell_direction, GatherPoint, Strata};
use crate::method::arrivals::{Arrivals, OwnBounds, SamplePaths};
use crate::method::FrameContext;
use crate::sampling::Frame;
use crate::store::rgbe::PackedSample;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::cell::OnceCell;
use std::f32::consts::TAU;

/// The share of a record's samples whose paths moving objects may newly
/// cross in one frame before it is dropped: `trc`'s default `a^t`, the
/// change in the record were the object to show a radiance as far from
/// what it hides as the mean.
pub const ARRIVAL_SHARE: f32 = 0.05;

/// The moving objects of the last frame and this one.
pub(super) struct Arrived {
    arrivals: Arrivals,
    frame: u32,
    /// By object, whether it moves (and may arrive).
    moving: Vec<bool>,
}

impl Arrived {
    /// The moving objects (`own`: their bounds, by object; `None` for one
    /// that does not move) placed in the frame before `ctx.frame` (`then`,
    /// [`super::Before`]) and in it; `None` in frame 0 or where none moved.
    pub(super) fn of(
        ctx: &FrameContext,
        own: &[Option<OwnBounds>],
        then: Option<&super::Before>,
    ) -> Option<Self> {
        let then = then?;
        let now = &ctx.snapshot.object_to_world[..];
        let arrivals = Arrivals::new(then.frame, own, &then.transforms, [now].into_iter());
        (!arrivals.is_empty()).then(|| Arrived {
            arrivals,
            frame: ctx.frame,
            moving: own.iter().map(Option::is_some).collect(),
        })
    }

    /// Whether each record (with its pose of this frame) is one moving
    /// objects came into the view of: more than [`ARRIVAL_SHARE`] of its
    /// samples' paths newly crossed by objects none of them hit in the
    /// last frame, or that they hit and that now cover more of the view
    /// by over [`ARRIVAL_SHARE`] (the others Eq. 2 follows at `τ_max`).
    /// Records on moving objects are not.
    pub(super) fn marked(
        &self,
        records: &[(TcgRecord, (GatherPoint, Frame))],
        strata: Strata,
    ) -> Vec<bool> {
        records
            .par_iter()
            .map(|(r, (point, frame))| {
                let own = r.candidate.object as usize;
                if self.moving.get(own).copied().unwrap_or(false) {
                    return false;
                }
                let paths = CellPaths {
                    samples: &r.samples,
                    frame,
                    strata,
                };
                // Found only for a record some moving object is above the
                // horizon of (most records never ask).
                let seen = OnceCell::new();
                let unseen = |o: u32| {
                    let seen = seen.get_or_init(|| paths.hits_on_moving_objects(point.position));
                    let held = |&(hit, slack): &(Vec3, f32)| self.arrivals.held_then(o, hit, slack);
                    !seen.iter().any(held)
                };
                let (pose, objects) = ((point, frame), (strata, own as u32, unseen));
                self.arrivals
                    .share(self.frame, pose, &paths, objects, ARRIVAL_SHARE)
                    > ARRIVAL_SHARE
            })
            .collect()
    }
}

/// A record's packed samples as paths: each along its cell's centre
/// direction (the stored samples keep no direction), as far as its hit.
struct CellPaths<'a> {
    samples: &'a [PackedSample],
    frame: &'a Frame,
    strata: Strata,
}

impl CellPaths<'_> {
    /// Where the samples that hit moving objects hit, from `p`, each with
    /// how far the hit may lie from its cell's centre direction (the
    /// cell's width at its distance).
    fn hits_on_moving_objects(&self, p: Vec3) -> Vec<(Vec3, f32)> {
        let width = (TAU / self.strata.count().max(1) as f32).sqrt();
        (0..self.samples.len())
            .filter(|&i| self.samples[i].hit_dynamic() && !self.samples[i].is_miss())
            .map(|i| {
                let (dir, distance) = self.path(i);
                (p + dir * distance, width * distance)
            })
            .collect()
    }
}

impl SamplePaths for CellPaths<'_> {
    fn count(&self) -> usize {
        self.samples.len()
    }

    fn path(&self, i: usize) -> (Vec3, f32) {
        let dir = cell_direction(self.frame, self.strata, i as u32, Vec2::splat(0.5));
        let s = &self.samples[i];
        let distance = if s.is_miss() {
            f32::INFINITY
        } else {
            s.distance()
        };
        (dir, distance)
    }
}
