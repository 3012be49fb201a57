//! Punctual lights (`KHR_lights_punctual`): point and spot lights on the
//! scene's nodes, their intensity bounded by [`MAX_EMISSION`]; directional
//! lights are skipped with a warning.

use super::nodes::node_name;
use super::{all_finite, Res, MAX_EMISSION};
use crate::scene::{PunctualLight, Spot};
use glam::Vec3;

pub(super) fn build_lights(gnodes: &[gltf::Node]) -> Res<Vec<PunctualLight>> {
    use gltf::khr_lights_punctual::Kind;
    let mut lights = Vec::new();
    for (node, gnode) in gnodes.iter().enumerate() {
        let Some(light) = gnode.light() else { continue };
        let name = light
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| node_name(gnode));
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
        let spot = match light.kind() {
            Kind::Directional => {
                eprintln!("warning: directional light '{name}' is not supported and is skipped");
                continue;
            }
            Kind::Point => None,
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                if !(all_finite(&[inner_cone_angle, outer_cone_angle]) && outer_cone_angle > 0.0) {
                    return Err(format!("spot light '{name}' has invalid cone angles"));
                }
                if inner_cone_angle > outer_cone_angle {
                    return Err(format!(
                        "spot light '{name}': innerConeAngle {inner_cone_angle} is larger than \
                         outerConeAngle {outer_cone_angle}"
                    ));
                }
                Some(Spot {
                    inner_cone: inner_cone_angle.clamp(0.0, outer_cone_angle),
                    outer_cone: outer_cone_angle,
                })
            }
        };
        lights.push(PunctualLight {
            name,
            node,
            intensity,
            spot,
        });
    }
    Ok(lights)
}
