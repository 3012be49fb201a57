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
    /// left to the reprojection and `trc::later`, as the paper has it: the
    /// shadow rays cost more there than they gain (`direct`).
    #[default]
    MovingLights,
    /// At every frame where something moves.
    On,
}

impl NextDirect {
    /// The name `--trc-next-direct` and the `next_direct` setting take.
    pub fn name(self) -> &'static str {
        match self {
            NextDirect::Off => "off",
            NextDirect::MovingLights => "moving-lights",
            NextDirect::On => "on",
        }
    }

    /// Whether the direct light is evaluated again after a frame, some
    /// light moving after it or not.
    pub(crate) fn evaluates(self, lights_move: bool) -> bool {
        match self {
            NextDirect::Off => false,
            NextDirect::MovingLights => lights_move,
            NextDirect::On => true,
        }
    }
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
    /// light moves ([`NextDirect::MovingLights`]); at every frame it costs
    /// more than it gains on two of our three animated scenes (measured in
    /// `direct`).
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
            next_direct: NextDirect::MovingLights,
            keep_paths: true,
            history: true,
        }
    }
}
