//! Punctual lights (`KHR_lights_punctual`): point, spot and directional
//! lights on the scene's nodes, their intensity bounded by
//! [`MAX_EMISSION`] and their cones as the extension bounds them; a
//! light's `range` (not read) and a negative inner cone (read as 0) are
//! warned of. A point or spot light's intensity (candela) is read as
//! W·sr⁻¹, a directional light's (lux) as W·m⁻², as radiance is read from
//! the materials' emission: the photometric units without the 683 lm/W.

use super::nodes::node_name;
use super::{all_finite, Res, MAX_EMISSION};
use crate::scene::{LightKind, PunctualLight, Spot};
use glam::Vec3;
use std::collections::HashSet;
use std::f32::consts::FRAC_PI_2;
use std::path::Path;

/// The lights of the scene's nodes; their warnings are printed naming
/// `file`, once for each light however many nodes it has.
pub(super) fn build_lights(gnodes: &[gltf::Node], file: &Path) -> Res<Vec<PunctualLight>> {
    use gltf::khr_lights_punctual::Kind;
    let mut lights = Vec::new();
    let mut warned = HashSet::new();
    for (node, gnode) in gnodes.iter().enumerate() {
        let Some(light) = gnode.light() else { continue };
        let name = light
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| node_name(gnode));
        let intensity = checked_intensity(&light, &name)?;
        let mut warnings = Vec::new();
        let kind = match light.kind() {
            Kind::Directional => LightKind::Directional,
            Kind::Point => LightKind::Point,
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => LightKind::Spot(spot_cone(
                &name,
                inner_cone_angle,
                outer_cone_angle,
                &mut warnings,
            )?),
        };
        // Lights fall off with the square of the distance, however far:
        // a file that counts on its range to keep a light out of a room
        // renders otherwise than it was made to.
        if let Some(range) = light.range() {
            warnings.push(format!(
                "light '{name}' has a range of {range} m, which radcache does not read: the \
                 light is not cut off there"
            ));
        }
        if warned.insert(light.index()) {
            for warning in warnings {
                eprintln!("warning: {}: {warning}", file.display());
            }
        }
        lights.push(PunctualLight {
            name,
            node,
            intensity,
            kind,
        });
    }
    Ok(lights)
}

/// Colour × intensity, refused if glTF forbids it (a negative intensity,
/// even of a black light) or it cannot be traced.
fn checked_intensity(light: &gltf::khr_lights_punctual::Light, name: &str) -> Res<Vec3> {
    if light.intensity() < 0.0 {
        return Err(format!(
            "light '{name}' has a negative intensity, {}; glTF requires 0 or more",
            light.intensity()
        ));
    }
    let intensity = Vec3::from(light.color()) * light.intensity();
    if !intensity.is_finite() || intensity.min_element() < 0.0 {
        return Err(format!(
            "light '{name}' has a NaN, infinite or negative intensity"
        ));
    }
    if intensity.max_element() > MAX_EMISSION {
        return Err(format!(
            "light '{name}' has an intensity of {:e} W·sr⁻¹ (colour × intensity), over the {MAX_EMISSION:e} allowed",
            intensity.max_element()
        ));
    }
    Ok(intensity)
}

/// A spot light's cone as `KHR_lights_punctual` bounds it: 0 ≤ inner ≤
/// outer ≤ π/2. An outer angle past π/2 is refused, not clamped: as
/// likely an angle in degrees as a cone wider than a hemisphere, which
/// readers light differently. A negative inner angle is read as 0 (the
/// falloff starts at the axis), with a warning pushed to `warnings`.
fn spot_cone(name: &str, inner: f32, outer: f32, warnings: &mut Vec<String>) -> Res<Spot> {
    if !(all_finite(&[inner, outer]) && outer > 0.0) {
        return Err(format!("spot light '{name}' has invalid cone angles"));
    }
    // π/2 written with a few digits (1.5708) is past f32's π/2: allowed,
    // and read as π/2.
    if outer > FRAC_PI_2 + 1e-3 {
        return Err(format!(
            "spot light '{name}': outerConeAngle {outer} is past π/2 ({FRAC_PI_2:.4}), the \
             widest glTF allows (its angles are in radians)"
        ));
    }
    if inner > outer {
        return Err(format!(
            "spot light '{name}': innerConeAngle {inner} is larger than outerConeAngle {outer}"
        ));
    }
    if inner < 0.0 {
        warnings.push(format!(
            "spot light '{name}': innerConeAngle {inner} is negative, which glTF forbids; read as 0"
        ));
    }
    let outer = outer.min(FRAC_PI_2);
    Ok(Spot {
        inner_cone: inner.clamp(0.0, outer),
        outer_cone: outer,
    })
}
