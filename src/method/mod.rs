//! Rendering methods. Each one is a module behind the [`Method`] trait, with
//! its settings in one struct whose defaults come from its paper. Methods see
//! the scene only through a [`FrameContext`] and trace rays only through the
//! batched [`RayBackend`] interface.

pub mod path;

use crate::backend::RayBackend;
use crate::film::Film;
use crate::light::LightSampler;
use crate::sampling::SampleKey;
use crate::scene::{Scene, Snapshot};

/// Everything a method may read while rendering one frame.
pub struct FrameContext<'a> {
    pub scene: &'a Scene,
    pub snapshot: &'a Snapshot,
    pub lights: &'a LightSampler,
    pub backend: &'a dyn RayBackend,
    pub frame: u32,
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    /// Use the same random sequence in every frame (reference renders for
    /// the flicker figure, DESIGN.md "Measuring").
    pub same_pattern: bool,
}

impl FrameContext<'_> {
    /// The sampling key of pixel sample `sample` of pixel `pixel`.
    pub fn pixel_key(&self, pixel: u32, sample: u32) -> SampleKey {
        SampleKey {
            seed: self.seed,
            frame: (!self.same_pattern).then_some(self.frame),
            item: u64::from(pixel),
            sample,
        }
    }

    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }
}

/// A rendering method. Methods may keep state from frame to frame (the
/// temporal caches do), so frames are rendered in order through `&mut self`.
pub trait Method: Send {
    /// The name used on the command line (`--method NAME`).
    fn name(&self) -> &'static str;

    /// Renders one frame into a linear-radiance image.
    fn render_frame(&mut self, ctx: &FrameContext) -> Film;
}
