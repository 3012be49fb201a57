//! Animation: every TRS channel of every animation, merged into one
//! [`Animation`] that plays from t = 0, its keys decoded and validated.

use super::accessors::Buffers;
use super::nodes::{node_name, Hierarchy};
use super::Res;
use crate::scene::animation::{Animation, Channel, Interpolation, Property};
use glam::{Vec3, Vec4};
use gltf::accessor::Dimensions;
use std::collections::HashMap;

/// All channels of all animations, merged (they all play from t = 0).
/// Channels on nodes outside the scene and morph-target weights are dropped.
pub(super) fn build_animation(
    document: &gltf::Document,
    buffers: &Buffers,
    hierarchy: &Hierarchy,
) -> Res<Animation> {
    let mut channels = Vec::new();
    // The animation that drives each (node, property), to name a second.
    let mut driven: HashMap<(usize, Property), (usize, String)> = HashMap::new();
    for anim in document.animations() {
        let anim_name = anim
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("animation{}", anim.index()));
        for ch in anim.channels() {
            let target = ch.target();
            let Some(&node) = hierarchy.ours.get(&target.node().index()) else {
                continue;
            };
            let property = match target.property() {
                gltf::animation::Property::Translation => Property::Translation,
                gltf::animation::Property::Rotation => Property::Rotation,
                gltf::animation::Property::Scale => Property::Scale,
                gltf::animation::Property::MorphTargetWeights => continue,
            };
            let where_ = || {
                format!(
                    "animation '{anim_name}', channel {} (node '{}')",
                    ch.index(),
                    node_name(&target.node())
                )
            };
            let channel = read_channel(&ch, node, property, buffers)
                .map_err(|e| format!("{}: {e}", where_()))?;
            // glTF §3.11: one animation drives a node's property once.
            // Several animations may (clips meant to play one at a time);
            // all play at once here, and the last one sets the property.
            match driven.insert((node, property), (anim.index(), anim_name.clone())) {
                Some((other, _)) if other == anim.index() => {
                    return Err(format!(
                        "{}: its {} is driven twice in this animation",
                        where_(),
                        property.name()
                    ))
                }
                Some((_, other)) => eprintln!(
                    "warning: {}: its {} is driven by animation '{other}' too; \
                     all animations play at once, and this later one sets it",
                    where_(),
                    property.name()
                ),
                None => {}
            }
            channels.push(channel);
        }
    }
    Ok(Animation { channels })
}

fn read_channel(
    ch: &gltf::animation::Channel,
    node: usize,
    property: Property,
    buffers: &Buffers,
) -> Res<Channel> {
    let sampler = ch.sampler();
    let interpolation = match sampler.interpolation() {
        gltf::animation::Interpolation::Linear => Interpolation::Linear,
        gltf::animation::Interpolation::Step => Interpolation::Step,
        gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
    };
    let times = buffers.floats(&sampler.input(), Dimensions::Scalar, "key times")?;
    let values: Vec<Vec4> = if property == Property::Rotation {
        let flat = buffers.floats(&sampler.output(), Dimensions::Vec4, "key values")?;
        flat.chunks_exact(4).map(Vec4::from_slice).collect()
    } else {
        let flat = buffers.floats(&sampler.output(), Dimensions::Vec3, "key values")?;
        flat.chunks_exact(3)
            .map(|v| Vec3::from_slice(v).extend(0.0))
            .collect()
    };
    let channel = Channel {
        node,
        property,
        interpolation,
        times,
        values,
    };
    channel.validate()?;
    Ok(channel)
}
