//! Animation: every TRS channel of every animation, merged into one
//! [`Animation`] that plays from t = 0, its keys decoded and validated
//! (their times as glTF requires them: 0 or more, strictly increasing).
//! Morph-target weights channels are not read; one on a node whose mesh
//! has no morph targets is warned of.

use super::accessors::Buffers;
use super::nodes::{node_name, Hierarchy};
use super::Res;
use crate::scene::animation::{Animation, Channel, Interpolation, Property};
use glam::{Vec3, Vec4};
use gltf::accessor::Dimensions;
use std::collections::HashMap;
use std::path::Path;

/// All channels of all animations, merged (they all play from t = 0).
/// Channels on nodes outside the scene and morph-target weights are
/// dropped; warnings name `file`.
pub(super) fn build_animation(
    document: &gltf::Document,
    buffers: &Buffers,
    hierarchy: &Hierarchy,
    file: &Path,
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
            let where_ = || {
                format!(
                    "animation '{anim_name}', channel {} (node '{}')",
                    ch.index(),
                    node_name(&target.node())
                )
            };
            let property = match target.property() {
                gltf::animation::Property::Translation => Property::Translation,
                gltf::animation::Property::Rotation => Property::Rotation,
                gltf::animation::Property::Scale => Property::Scale,
                gltf::animation::Property::MorphTargetWeights => {
                    if !has_morph_targets(&target.node()) {
                        eprintln!(
                            "warning: {}: {}: it animates morph target weights, but the \
                             node's mesh has none; ignored",
                            file.display(),
                            where_()
                        );
                    }
                    continue;
                }
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
    check_key_times(&channel.times)?;
    Ok(channel)
}

/// What glTF requires of key times and [`Channel::validate`] lets pass (it
/// refuses non-finite and decreasing ones): a repeated time (some readers
/// take it for a jump, which glTF keys with `STEP`) and a negative one (a
/// key before the animation starts). Other tools refuse both, or read
/// them otherwise than radcache does.
fn check_key_times(times: &[f32]) -> Res<()> {
    // Validated as not decreasing: the first is the earliest.
    if let Some(&t) = times.first().filter(|&&t| t < 0.0) {
        return Err(format!(
            "key 0 is at t = {t} s, before 0: glTF requires key times of 0 or more"
        ));
    }
    match times.windows(2).position(|w| w[1] == w[0]) {
        Some(k) => Err(format!(
            "key {} is at t = {} s, as key {k} is: glTF requires strictly increasing key times",
            k + 1,
            times[k]
        )),
        None => Ok(()),
    }
}

/// Whether `node` has a mesh with morph targets, which glTF requires of
/// the node a weights channel animates.
fn has_morph_targets(node: &gltf::Node) -> bool {
    node.mesh()
        .is_some_and(|m| m.primitives().any(|p| p.morph_targets().next().is_some()))
}
