//! The camera pass every method shares (`method::pixels`): pixels on the
//! edge of a directly seen light are post-stratified by their emitter
//! coverage, every other pixel is rendered exactly as without it, and the
//! error of the edge pixels falls against a converged reference.

use radcache::backend::cpu::CpuBackend;
use radcache::cache::gather::Strata;
use radcache::film::Film;
use radcache::method::ic::{IcSettings, IrradianceCaching};
use radcache::method::path::{PathSettings, PathTracer};
use radcache::method::pixels::DEFAULT_EDGE_COVERAGE_FACTOR;
use radcache::method::Method;
use radcache::render::{FrameSettings, Renderer};
use radcache::scene::Scene;

const SIZE: u32 = 24;

fn render(method: Box<dyn Method>, edge_coverage_factor: u32) -> Film {
    let mut r = Renderer::new(
        Scene::builtin("cube-in-box").unwrap(),
        method,
        Box::new(CpuBackend::new()),
        FrameSettings {
            width: SIZE,
            height: SIZE,
            edge_coverage_factor,
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
/// without the post-stratified edge pixels: the pixels that differ are few
/// (the rim, not the image), every other pixel is bit-identical (the same
/// samples), and over the differing pixels the squared error against a
/// 1024-spp `path` reference rendered without the rule (plain means of
/// 1024 samples: an independent estimator of the same pixel integrals) falls
/// tenfold. The coverage comes from 65× the rays, which cuts the variance
/// of a box-filtered straight edge several hundredfold (N^-3/2); what is
/// left is the shading noise of each part's few samples and the
/// reference's own noise, so 0.1 leaves room for both.
#[test]
fn only_pixels_on_a_seen_lights_edge_take_more_samples_and_their_error_falls() {
    let reference = render(path(1024), 0);
    for (name, method) in [("path", path as fn(u32) -> Box<dyn Method>), ("ic", ic)] {
        let off = render(method(4), 0);
        let on = render(method(4), DEFAULT_EDGE_COVERAGE_FACTOR);
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
        assert!(after < 0.1 * before, "{name}: {before} → {after}");
    }
}
