//! Materials: glTF's metallic-roughness factors, and emission with
//! `KHR_materials_emissive_strength`, bounded by [`MAX_EMISSION`]. Textures
//! are not read (`document` warns of them).

use super::{all_finite, Res, MAX_EMISSION};
use crate::scene::Material;
use glam::Vec3;

pub(super) fn build_materials(document: &gltf::Document) -> Res<Vec<Material>> {
    document.materials().map(|m| convert_material(&m)).collect()
}

fn convert_material(m: &gltf::Material) -> Res<Material> {
    let name = m
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, _] = pbr.base_color_factor();
    let strength = m.emissive_strength().unwrap_or(1.0);
    let emission = Vec3::from(m.emissive_factor()) * strength;
    let factors = [r, g, b, pbr.metallic_factor(), pbr.roughness_factor()];
    if !all_finite(&factors) || !emission.is_finite() {
        return Err(format!("material '{name}' has a NaN or infinite factor"));
    }
    if emission.max_element() > MAX_EMISSION {
        return Err(format!(
            "material '{name}' emits {:e} W·sr⁻¹·m⁻² (emissive factor × strength), over the {MAX_EMISSION:e} allowed",
            emission.max_element()
        ));
    }
    // Out-of-range factors would make surfaces gain energy; glTF forbids them.
    let unit = |x: f32| x.clamp(0.0, 1.0);
    let mut material = Material::from_metallic_roughness(
        &name,
        Vec3::new(r, g, b).clamp(Vec3::ZERO, Vec3::ONE),
        unit(pbr.metallic_factor()),
        unit(pbr.roughness_factor()),
    );
    material.emission = emission.max(Vec3::ZERO);
    material.double_sided = m.double_sided();
    Ok(material)
}
