//! `trc`'s settings: the temporal accuracy `a_t` and `δt_max` (TRC
//! Eq. 9–11), the temporal gradients (§4.5), the reprojection (§4.7), and
//! this renderer's own additions to them, with their defaults.

use crate::method::ic::IcSettings;

/// Temporal gradients (TRC §4.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum TemporalGradients {
    /// A record's value is constant over its life (Fig. 4c).
    None,
    /// Extrapolated from the estimate of E(t0+1), Eq. 15 (Fig. 4d): E's
    /// change alone, not the spatial gradients' of Eq. 16–17
    /// (`TemporalRecord::at_frame` says why).
    #[default]
    Extrapolated,
    /// Interpolated between K and the record l that replaces it at the same
    /// point, Eq. 18–20 (Fig. 4e). Two passes: a frame is rendered once the
    /// replacements of the records it uses are known (see
    /// [`TemporalRadianceCaching`](super::TemporalRadianceCaching)). A record dropped rather than replaced,
    /// or whose replacement lies beyond the last frame rendered, falls back
    /// to its extrapolated gradients.
    Interpolated,
}

impl TemporalGradients {
    /// The name `--trc-gradients` and the `gradients` setting take.
    pub fn name(self) -> &'static str {
        match self {
            TemporalGradients::None => "none",
            TemporalGradients::Extrapolated => "extrapolated",
            TemporalGradients::Interpolated => "interpolated",
        }
    }
}

/// When the E(t0+1) estimate evaluates each hemisphere sample's direct
/// light again at t0+1 (`direct`: one light sample, shadowed in the next
/// frame's geometry), so that it sees shadows move on what the record sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum NextDirect {
    /// Never: the estimate sees moving lights through the unshadowed light
    /// at the samples' hits only (`estimate::light_change`).
    Off,
    /// At frames after which some light moves. Why: a light that moves
    /// moves every shadow it casts, of static objects too, and the
    /// unshadowed light sees none of them: under a far point light swinging
    /// across a courtyard, records lived on while the walls' shadows
    /// crossed the ground they saw (block bias 4× `ic`'s; with it, `ic`'s;
    /// `benches/RESULTS.md`). Where only objects move, their shadows are
    /// left to the reprojection and `trc::later`, as the paper has it.
    MovingLights,
    /// As [`Self::MovingLights`], and also where only objects move at a
    /// frame whose records live long: the harmonic mean lifespan of the
    /// records alive at its start is at least `δt_max`/2, or none is
    /// alive (`lives_are_long`). Why: where records live long, each new
    /// one's estimate decides many frames, and a moving shadow it misses
    /// lives as long (cube-in-box, 400 frames: rel. RMSE 0.02023 →
    /// 0.01962 for 9–14 % more time); where they live short, the shadow rays
    /// cost as much and gain nothing (at every frame the balls took 27 %
    /// more time for the same error; `benches/RESULTS.md`).
    #[default]
    LongLives,
    /// At every frame where something moves.
    On,
}

impl NextDirect {
    /// The name `--trc-next-direct` and the `next_direct` setting take.
    pub fn name(self) -> &'static str {
        match self {
            NextDirect::Off => "off",
            NextDirect::MovingLights => "moving-lights",
            NextDirect::LongLives => "long-lives",
            NextDirect::On => "on",
        }
    }

    /// The mode at one frame, [`Self::LongLives`] settled by whether the
    /// records alive at the frame's start live long (`lives_long`).
    pub(crate) fn at_frame(self, lives_long: bool) -> NextDirect {
        match self {
            NextDirect::LongLives if lives_long => NextDirect::On,
            NextDirect::LongLives => NextDirect::MovingLights,
            mode => mode,
        }
    }

    /// Whether the direct light is evaluated again after a frame, some
    /// light moving after it or not.
    pub(crate) fn evaluates(self, lights_move: bool) -> bool {
        match self {
            NextDirect::Off => false,
            NextDirect::MovingLights | NextDirect::LongLives => lights_move,
            NextDirect::On => true,
        }
    }
}

/// Whether records of the `lifespans` alive at a frame's start live long
/// for [`NextDirect::LongLives`]: the mean lifespan of the records made
/// per frame is at least `δt_max`/2. The records alive at a time are a
/// length-biased sample of those made (one that lives L frames is alive
/// in L of them), so that mean is their harmonic mean (`1 / E[1/L]`): a
/// mean over about the last `δt_max` frames' new records, read from the
/// records alone, so that a resumed render decides as the uninterrupted
/// one did. None alive (the first frame): long, so that the first
/// records, which decide what follows, see the shadows move.
pub(crate) fn lives_are_long(lifespans: impl IntoIterator<Item = u32>, max_life: u32) -> bool {
    let (n, inverse_sum) = lifespans.into_iter().fold((0u64, 0f64), |(n, s), l| {
        (n + 1, s + 1.0 / f64::from(l.max(1)))
    });
    // n / Σ 1/L ≥ δt_max / 2, without the division.
    n == 0 || 2.0 * n as f64 >= f64::from(max_life) * inverse_sum
}

/// [`TrcSettings::next_direct`] as stored: a flag before it had a mode
/// between (`false`: off, which such jobs ran; `true`: on), or its mode.
fn next_direct_or_flag<'de, D: serde::Deserializer<'de>>(d: D) -> Result<NextDirect, D::Error> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum Stored {
        Flag(bool),
        Mode(NextDirect),
    }
    Ok(match serde::Deserialize::deserialize(d)? {
        Stored::Flag(true) => NextDirect::On,
        Stored::Flag(false) => NextDirect::Off,
        Stored::Mode(mode) => mode,
    })
}

/// Settings of `trc`, with their sources.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrcSettings {
    /// Everything spatial: accuracy `a`, strata, spp, spacing, spatial
    /// gradients, path lengths (see [`IcSettings`]).
    pub ic: IcSettings,
    /// Temporal accuracy `a^t` (Eq. 10): K is used at t while
    /// `w_t(t) ≥ 1/a^t`. The paper's examples use 0.05 (§6).
    pub temporal_accuracy: f32,
    /// `δt_max` (Eq. 11): K is used at t only while `t − t0 < δt_max`. The
    /// paper's examples use 20 frames (§6); 1 gives per-frame computation.
    pub max_life: u32,
    pub gradients: TemporalGradients,
    /// Estimate E(t0+1) by reprojection (§4.7), and check each record's
    /// life against the later frames by reprojection too (`trc::later`)
    /// and against objects that come into its samples' paths
    /// (`method::arrivals`); off: E(t0+1) = E(t0), the "no reprojection"
    /// column of Table 1 (then every record lives `δt_max` frames).
    pub reprojection: bool,
    /// With reprojection, when to evaluate each sample's direct light again
    /// at t0+1 (one light sample, shadowed in the next frame's geometry,
    /// `direct`): the estimate then sees moving shadows and moving lights
    /// on the surfaces the record sees. By default at frames after which a
    /// light moves, and where only objects move at frames whose records
    /// live long ([`NextDirect::LongLives`]); at every frame it costs more
    /// than it gains where records live short (measured in `direct`).
    #[serde(deserialize_with = "next_direct_or_flag")]
    pub next_direct: NextDirect,
    /// A replacement takes the results of the paths of K's gather that
    /// nothing moving met, then or now, rather than tracing them again
    /// (`trc::paths`): the same records, faster. Off: every path is traced
    /// again, as the paper's replacement does.
    #[serde(default = "keep_paths_default")]
    pub keep_paths: bool,
    /// A replacement's estimate of E(t0+1) follows the change observed
    /// over the life of the record it replaces, where that change is the
    /// larger (`trc::record::with_observed_change`): the reprojection
    /// keeps each sample's radiance, so light of more than one bounce that
    /// a moving object changes goes unseen, and records lived on
    /// `δt_max` frames while it drifted. Off: the paper's estimate alone.
    /// Not in settings stored before it existed (whose jobs ran without).
    #[serde(default)]
    pub history: bool,
}

/// [`TrcSettings::keep_paths`] for settings stored before it existed.
fn keep_paths_default() -> bool {
    true
}

impl Default for TrcSettings {
    fn default() -> Self {
        TrcSettings {
            ic: IcSettings::default(),
            temporal_accuracy: 0.05,
            max_life: 20,
            gradients: TemporalGradients::default(),
            reprojection: true,
            next_direct: NextDirect::LongLives,
            keep_paths: true,
            history: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records made at a steady rate, each frame's with lives drawn from
    /// `lives` in turn, alive at frame `t` while `t0 ≤ t < t0 + life`.
    fn alive_at(t: u32, lives: &[u32], per_frame: usize) -> Vec<u32> {
        let mut alive = Vec::new();
        let mut next = 0;
        for t0 in 0..=t {
            for _ in 0..per_frame {
                let life = lives[next % lives.len()];
                next += 1;
                if t < t0 + life {
                    alive.push(life);
                }
            }
        }
        alive
    }

    /// The statistic is the mean life of the records made per frame, not
    /// of those alive (which long lives outnumber): with lives of 1 and 19
    /// frames made alike (mean 10), the alive are 19 of 19 frames to 1 of
    /// 1, a mean of 18.1, yet the records live long for `δt_max` 20 and
    /// not for 21; all of 9 frames or all of 11 settle either side of 20.
    #[test]
    fn long_lives_are_judged_by_the_records_made_not_those_alive() {
        let alive = alive_at(100, &[1, 19], 10);
        let arithmetic = alive.iter().sum::<u32>() as f64 / alive.len() as f64;
        assert!(arithmetic > 18.0, "{arithmetic}");
        assert!(lives_are_long(alive.iter().copied(), 20));
        assert!(!lives_are_long(alive.iter().copied(), 21));
        assert!(!lives_are_long(alive_at(100, &[9], 7), 20));
        assert!(lives_are_long(alive_at(100, &[11], 7), 20));
        assert!(lives_are_long([], 20), "the first frame's records");
    }

    #[test]
    fn long_lives_settle_to_on_or_moving_lights_per_frame() {
        assert_eq!(NextDirect::LongLives.at_frame(true), NextDirect::On);
        assert_eq!(
            NextDirect::LongLives.at_frame(false),
            NextDirect::MovingLights
        );
        for mode in [NextDirect::Off, NextDirect::MovingLights, NextDirect::On] {
            assert_eq!(mode.at_frame(true), mode);
            assert_eq!(mode.at_frame(false), mode);
        }
        assert_eq!(TrcSettings::default().next_direct, NextDirect::LongLives);
    }
}
