//! The camera pass every method shares (`method::pixels`): pixels on the
//! edge of a directly seen light take more samples, every other pixel is
//! rendered exactly as without them, and the error of the edge pixels falls
//! against a converged reference.

use radcache::backend::cpu::CpuBackend;
use radcache::cache::gather::Strata;
use radcache::film::Film;
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::Method;
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::Scene;

const SIZE: u32 = 24;

fn render(method: Box<dyn Method>, emitter_edge_factor: u32) -> Film {
    let mut r = Renderer::new(
        Scene::builtin("cube-in-box").unwrap(),
        method,
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: SIZE,
            height: SIZE,
            emitter_edge_factor,
            ..FrameSettings::default()
        },
    );
    r.render_frame(3)
}

fn path(spp: u32) -> Box<dyn Method> {
    Box::new(PathTracer::new(PathSettings {
        spp,
        ..PathSettings::default()
    }))
}

fn ic(spp: u32) -> Box<dyn Method> {
    Box::new(IrradianceCaching::new(IcSettings {
        spp,
        strata: Strata { theta: 6, phi: 18 },
        ..IcSettings::default()
    }))
}

/// Cube-in-box sees its ceiling light. At 4 samples a pixel, with and
/// without the extra samples at the light's edge: the pixels that differ
/// are few (the rim, not the image), every other pixel is bit-identical
/// (the same samples), and over the differing pixels the squared error
/// against a 1024-spp `path` reference falls. Five times the samples cut
/// the variance of a box-filtered edge by about 5; the bound, 0.6, leaves
/// room for one frame's noise.
#[test]
fn only_pixels_on_a_seen_lights_edge_take_more_samples_and_their_error_falls() {
    let reference = render(path(1024), 0);
    for (name, method) in [("path", path as fn(u32) -> Box<dyn Method>), ("ic", ic)] {
        let off = render(method(4), 0);
        let on = render(method(4), 4);
        let edge: Vec<usize> = (0..off.pixels.len())
            .filter(|&i| off.pixels[i] != on.pixels[i])
            .collect();
        let n = off.pixels.len();
        assert!(
            !edge.is_empty() && edge.len() < n / 8,
            "{name}: {} of {n} pixels changed",
            edge.len()
        );
        let squared_error = |film: &Film| -> f64 {
            edge.iter()
                .map(|&i| f64::from((film.pixels[i] - reference.pixels[i]).length_squared()))
                .sum()
        };
        let (before, after) = (squared_error(&off), squared_error(&on));
        eprintln!(
            "{name}: {} edge pixels, squared error {before:.4} → {after:.4}",
            edge.len()
        );
        assert!(after < 0.6 * before, "{name}: {before} → {after}");
    }
}
