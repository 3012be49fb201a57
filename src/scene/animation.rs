//! Keyframed node animation with glTF 2.0 semantics (glTF spec §3.11 and
//! Appendix C): translation/rotation/scale channels, `LINEAR` (slerp for
//! rotations), `STEP` and `CUBICSPLINE` (Hermite with per-key tangents).
//! Before the first key the first value holds, after the last the last.

use super::Trs;
use glam::{Quat, Vec3, Vec4};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Property {
    Translation,
    Rotation,
    Scale,
}

impl Property {
    /// Its name in glTF (`target.path`).
    pub fn name(self) -> &'static str {
        match self {
            Property::Translation => "translation",
            Property::Rotation => "rotation",
            Property::Scale => "scale",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    Linear,
    Step,
    CubicSpline,
}

/// The largest key time a channel may have, in seconds (either sign;
/// about three years). A cubic spline scales its tangents (up to
/// [`crate::scene::gltf_loader::MAX_COORDINATE`]) by the span between two
/// keys: keys near `f32`'s limit made that span infinite and every sample
/// of the channel NaN.
pub const MAX_KEY_TIME: f32 = 1e8;

/// One animated property of one node. Values are stored as `Vec4`
/// (xyz for translation and scale, xyzw for rotation quaternions). For
/// `CubicSpline`, `values` holds three entries per key, as glTF does:
/// in-tangent, value, out-tangent.
#[derive(Clone, Debug)]
pub struct Channel {
    pub node: usize,
    pub property: Property,
    pub interpolation: Interpolation,
    pub times: Vec<f32>,
    pub values: Vec<Vec4>,
}

impl Channel {
    /// Checks the invariants the sampler relies on; `Err` says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if self.times.is_empty() {
            return Err("animation channel has no keyframes".into());
        }
        if self.times.iter().any(|t| !t.is_finite()) {
            return Err("animation channel has a non-finite key time".into());
        }
        if let Some(t) = self.times.iter().find(|t| t.abs() > MAX_KEY_TIME) {
            return Err(format!(
                "animation channel has a key at t = {t:e} s, beyond ±{MAX_KEY_TIME:e} s"
            ));
        }
        if self.times.windows(2).any(|w| w[1] < w[0]) {
            return Err("animation key times are not increasing".into());
        }
        let per_key = if self.interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        if self.values.len() != self.times.len() * per_key {
            return Err(format!(
                "animation channel has {} values for {} keys (expected {})",
                self.values.len(),
                self.times.len(),
                self.times.len() * per_key
            ));
        }
        if self.values.iter().any(|v| !v.is_finite()) {
            return Err("animation channel has a NaN or infinite value".into());
        }
        let limit = crate::scene::gltf_loader::MAX_COORDINATE;
        let largest = self
            .values
            .iter()
            .map(|v| v.abs().max_element())
            .fold(0.0, f32::max);
        if largest > limit {
            return Err(format!(
                "animation channel has a value of magnitude {largest:e}, beyond {limit:e}, \
                 past what can be traced"
            ));
        }
        if self.property == Property::Rotation {
            // A zero quaternion has no orientation: slerp and normalisation
            // would turn it into NaN transforms.
            if let Some(k) = (0..self.times.len()).find(|&k| self.key(k).length() < 1e-6) {
                return Err(format!(
                    "rotation key {k} is the quaternion {}, which has no orientation",
                    self.key(k)
                ));
            }
        }
        Ok(())
    }

    /// The key value `k` (the middle of the triple for cubic splines).
    fn key(&self, k: usize) -> Vec4 {
        match self.interpolation {
            Interpolation::CubicSpline => self.values[3 * k + 1],
            _ => self.values[k],
        }
    }

    /// Samples the channel at time `t`.
    pub fn sample(&self, t: f32) -> Vec4 {
        let times = &self.times;
        let last = times.len() - 1;
        if t <= times[0] {
            return self.key(0);
        }
        if t >= times[last] {
            return self.key(last);
        }
        // First key strictly after t; t lies in [times[k0], times[k1]).
        let k1 = times.partition_point(|&x| x <= t);
        let k0 = k1 - 1;
        let dt = times[k1] - times[k0];
        let s = if dt > 0.0 { (t - times[k0]) / dt } else { 0.0 };
        let rotation = self.property == Property::Rotation;
        match self.interpolation {
            Interpolation::Step => self.key(k0),
            Interpolation::Linear if rotation => {
                let a = Quat::from_vec4(self.key(k0)).normalize();
                let b = Quat::from_vec4(self.key(k1)).normalize();
                Vec4::from(a.slerp(b, s))
            }
            Interpolation::Linear => self.key(k0).lerp(self.key(k1), s),
            Interpolation::CubicSpline => {
                // glTF Appendix C: p(s) = (2s³−3s²+1)v0 + (s³−2s²+s)·dt·b0
                //                        + (−2s³+3s²)v1 + (s³−s²)·dt·a1
                let v0 = self.values[3 * k0 + 1];
                let b0 = self.values[3 * k0 + 2];
                let a1 = self.values[3 * k1];
                let v1 = self.values[3 * k1 + 1];
                let (s2, s3) = (s * s, s * s * s);
                let p = v0 * (2.0 * s3 - 3.0 * s2 + 1.0)
                    + b0 * (dt * (s3 - 2.0 * s2 + s))
                    + v1 * (-2.0 * s3 + 3.0 * s2)
                    + a1 * (dt * (s3 - s2));
                if rotation {
                    // The spline may pass through the zero quaternion (keys
                    // q and −q): the nearer key's orientation then.
                    let nearer = if s < 0.5 { v0 } else { v1 };
                    p.try_normalize().unwrap_or(nearer.normalize())
                } else {
                    p
                }
            }
        }
    }
}

/// All animation channels of a scene (glTF animations are merged: they all
/// play from t = 0).
#[derive(Clone, Debug, Default)]
pub struct Animation {
    pub channels: Vec<Channel>,
}

impl Animation {
    pub fn animates(&self, node: usize) -> bool {
        self.channels.iter().any(|c| c.node == node)
    }

    /// Last key time over all channels (0 for a still scene).
    pub fn duration(&self) -> f32 {
        self.channels
            .iter()
            .filter_map(|c| c.times.last().copied())
            .fold(0.0, f32::max)
    }

    /// Local transform of `node` at time `t`: `rest` with animated properties
    /// replaced by their sampled values.
    pub fn local_trs(&self, node: usize, rest: Trs, t: f32) -> Trs {
        let mut trs = rest;
        for channel in self.channels.iter().filter(|c| c.node == node) {
            channel.apply(&mut trs, t);
        }
        trs
    }

    /// Local transforms of all nodes at time `t`, from their `rests`, in
    /// one pass over the channels: [`Self::local_trs`] of every node
    /// would scan every channel once per node, which a scene of many
    /// animated nodes pays several times a frame.
    pub fn local_transforms(&self, rests: impl Iterator<Item = Trs>, t: f32) -> Vec<Trs> {
        let mut locals: Vec<Trs> = rests.collect();
        for channel in &self.channels {
            if let Some(trs) = locals.get_mut(channel.node) {
                channel.apply(trs, t);
            }
        }
        locals
    }

    /// Per node of `count`, whether a channel targets it.
    pub fn animated_nodes(&self, count: usize) -> Vec<bool> {
        self.nodes_animated_in(count, |_| true)
    }

    /// Per node of `count`, whether a channel of a property that `which`
    /// takes targets it.
    pub fn nodes_animated_in(&self, count: usize, which: impl Fn(Property) -> bool) -> Vec<bool> {
        let mut animated = vec![false; count];
        for channel in self.channels.iter().filter(|c| which(c.property)) {
            if let Some(a) = animated.get_mut(channel.node) {
                *a = true;
            }
        }
        animated
    }
}

impl Channel {
    /// Sets the property this channel animates in `trs` to its value at `t`.
    pub(crate) fn apply(&self, trs: &mut Trs, t: f32) {
        let v = self.sample(t);
        match self.property {
            Property::Translation => trs.translation = v.truncate(),
            Property::Scale => trs.scale = v.truncate(),
            Property::Rotation => trs.rotation = Quat::from_vec4(v).normalize(),
        }
    }
}

/// Helper for built-in scenes and tests: a linear channel from (time, value) keys.
pub fn linear_translation(node: usize, keys: &[(f32, Vec3)]) -> Channel {
    Channel {
        node,
        property: Property::Translation,
        interpolation: Interpolation::Linear,
        times: keys.iter().map(|k| k.0).collect(),
        values: keys.iter().map(|k| k.1.extend(0.0)).collect(),
    }
}

/// Helper for built-in scenes and tests: a linear (slerped) rotation channel.
pub fn linear_rotation(node: usize, keys: &[(f32, Quat)]) -> Channel {
    Channel {
        node,
        property: Property::Rotation,
        interpolation: Interpolation::Linear,
        times: keys.iter().map(|k| k.0).collect(),
        values: keys.iter().map(|k| Vec4::from(k.1)).collect(),
    }
}
