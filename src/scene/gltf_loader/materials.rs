//! Materials: glTF's metallic-roughness factors, and emission with
//! `KHR_materials_emissive_strength`, bounded by [`MAX_EMISSION`]. Textures
//! are not read (`document` warns of them). Factors outside [0, 1], the
//! range glTF gives them, are clamped to it with a warning, and so is a
//! negative emissive strength; an alpha that blending or masking would
//! need is ignored with a warning (every surface is drawn opaque).

use super::{all_finite, Res, MAX_EMISSION};
use crate::scene::Material;
use glam::Vec3;
use std::path::Path;

/// The materials of `document`, whose warnings are printed naming `file`.
pub(super) fn build_materials(document: &gltf::Document, file: &Path) -> Res<Vec<Material>> {
    let mut materials = Vec::new();
    for m in document.materials() {
        let (material, warnings) = convert_material(&m)?;
        for warning in warnings {
            eprintln!("warning: {}: {warning}", file.display());
        }
        materials.push(material);
    }
    Ok(materials)
}

/// Material `m` and what its warnings say of it.
fn convert_material(m: &gltf::Material) -> Res<(Material, Vec<String>)> {
    let name = m
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
    let pbr = m.pbr_metallic_roughness();
    let base = pbr.base_color_factor();
    let strength = m.emissive_strength().unwrap_or(1.0);
    let emissive = m.emissive_factor();
    let factors = [
        &base[..],
        &emissive[..],
        &[pbr.metallic_factor(), pbr.roughness_factor(), strength],
    ]
    .concat();
    if !all_finite(&factors) {
        return Err(format!("material '{name}' has a NaN or infinite factor"));
    }
    // Out-of-range factors would make surfaces gain energy (a base colour
    // over 1) or take brightness that only the strength may add (an
    // emissive factor over 1); glTF forbids them.
    let mut warnings = Vec::new();
    let what = match (m.index(), m.name()) {
        (Some(i), Some(name)) => format!("material {i} '{name}'"),
        (Some(i), None) => format!("material {i}"),
        (None, _) => "the default material".into(),
    };
    let [r, g, b, alpha] = unit_factors(&mut warnings, &what, "baseColorFactor", base);
    let emissive = unit_factors(&mut warnings, &what, "emissiveFactor", emissive);
    let [metallic] = unit_factors(
        &mut warnings,
        &what,
        "metallicFactor",
        [pbr.metallic_factor()],
    );
    let [roughness] = unit_factors(
        &mut warnings,
        &what,
        "roughnessFactor",
        [pbr.roughness_factor()],
    );
    if strength < 0.0 {
        warnings.push(format!(
            "{what}: emissiveStrength {strength} is below 0; clamped to 0"
        ));
    }
    if let Some(ignored) = ignored_alpha(m, alpha) {
        warnings.push(format!("{what}: {ignored}"));
    }
    let emission = Vec3::from(emissive) * strength.max(0.0);
    if emission.max_element() > MAX_EMISSION {
        return Err(format!(
            "material '{name}' emits {:e} W·sr⁻¹·m⁻² (emissive factor × strength), over the {MAX_EMISSION:e} allowed",
            emission.max_element()
        ));
    }
    let mut material =
        Material::from_metallic_roughness(&name, Vec3::new(r, g, b), metallic, roughness);
    material.emission = emission;
    material.double_sided = m.double_sided();
    Ok((material, warnings))
}

/// `values` of factor `factor` of material `what`, clamped to [0, 1]; a
/// warning in `warnings` where that changed any.
fn unit_factors<const N: usize>(
    warnings: &mut Vec<String>,
    what: &str,
    factor: &str,
    values: [f32; N],
) -> [f32; N] {
    let clamped = values.map(|v| v.clamp(0.0, 1.0));
    if clamped != values {
        let text = |v: &[f32]| match v {
            [one] => one.to_string(),
            _ => format!(
                "[{}]",
                v.iter().map(f32::to_string).collect::<Vec<_>>().join(", ")
            ),
        };
        warnings.push(format!(
            "{what}: {factor} {} is outside [0, 1]; clamped to {}{}",
            text(&values),
            text(&clamped),
            if factor == "emissiveFactor" {
                " (brighter emission is KHR_materials_emissive_strength's)"
            } else {
                ""
            }
        ));
    }
    clamped
}

/// What is lost of base colour alpha `alpha` (in [0, 1]) of material `m`,
/// which is drawn opaque: a blended one's transparency, or a masked one's
/// cut-out (an alpha under the cutoff). `None` where glTF draws it opaque
/// too (`OPAQUE`, which ignores alpha; full alpha; a mask it passes).
fn ignored_alpha(m: &gltf::Material, alpha: f32) -> Option<String> {
    match m.alpha_mode() {
        gltf::material::AlphaMode::Blend if alpha < 1.0 => Some(format!(
            "baseColorFactor alpha {alpha} (alphaMode BLEND) is ignored: surfaces are drawn opaque"
        )),
        gltf::material::AlphaMode::Mask => {
            let cutoff = m.alpha_cutoff().unwrap_or(0.5);
            (alpha < cutoff).then(|| {
                format!(
                    "baseColorFactor alpha {alpha} is under alphaCutoff {cutoff} (alphaMode MASK), \
                     which cuts the whole surface away; it is drawn opaque"
                )
            })
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::convert_material;

    /// The materials of a document with `materials` (a JSON array), each
    /// with its warnings.
    fn convert(materials: serde_json::Value) -> Vec<(crate::scene::Material, Vec<String>)> {
        let json = serde_json::json!({"asset": {"version": "2.0"}, "materials": materials});
        let gltf = gltf::Gltf::from_slice_without_validation(json.to_string().as_bytes()).unwrap();
        let converted = gltf.document.materials().map(|m| convert_material(&m));
        converted.collect::<Result<_, _>>().unwrap()
    }

    /// Factors within [0, 1], and alpha where glTF ignores it, say nothing;
    /// each factor outside is clamped and named with its material and
    /// value; an alpha that blending or a mask would use is said to be
    /// ignored.
    #[test]
    fn factors_outside_the_unit_range_are_clamped_and_named() {
        let quiet = convert(serde_json::json!([
            {"name": "plain", "pbrMetallicRoughness":
                {"baseColorFactor": [0.0, 0.5, 1.0, 0.25], "metallicFactor": 1.0, "roughnessFactor": 0.0},
             "emissiveFactor": [1.0, 0.0, 0.5]},
            {"alphaMode": "MASK", "alphaCutoff": 0.5,
             "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 0.5]}},
            {"alphaMode": "BLEND"},
        ]));
        for (_, warnings) in &quiet {
            assert!(warnings.is_empty(), "{warnings:?}");
        }
        let loud = convert(serde_json::json!([
            {"name": "hot",
             "pbrMetallicRoughness": {"baseColorFactor": [2.0, -1.0, 0.5, 1.0], "metallicFactor": -0.5},
             "emissiveFactor": [4.0, 0.5, 0.0],
             "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": -3.0}}},
            {"alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 0.25],
             "roughnessFactor": 1.5}},
            {"name": "glass", "alphaMode": "BLEND",
             "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.5]}},
        ]));
        let (hot, warnings) = &loud[0];
        assert_eq!(
            warnings,
            &[
                "material 0 'hot': baseColorFactor [2, -1, 0.5, 1] is outside [0, 1]; clamped to [1, 0, 0.5, 1]",
                "material 0 'hot': emissiveFactor [4, 0.5, 0] is outside [0, 1]; clamped to [1, 0.5, 0] (brighter emission is KHR_materials_emissive_strength's)",
                "material 0 'hot': metallicFactor -0.5 is outside [0, 1]; clamped to 0",
                "material 0 'hot': emissiveStrength -3 is below 0; clamped to 0",
            ]
        );
        assert_eq!(hot.diffuse, glam::Vec3::new(1.0, 0.0, 0.5));
        assert!(!hot.is_emissive());
        assert_eq!(
            loud[1].1,
            [
                "material 1: roughnessFactor 1.5 is outside [0, 1]; clamped to 1",
                "material 1: baseColorFactor alpha 0.25 is under alphaCutoff 0.5 (alphaMode MASK), \
                 which cuts the whole surface away; it is drawn opaque",
            ]
        );
        assert_eq!(
            loud[2].1,
            ["material 2 'glass': baseColorFactor [1, 1, 1, 1.5] is outside [0, 1]; clamped to [1, 1, 1, 1]"]
        );
    }
}
