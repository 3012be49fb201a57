//! BSDFs at a surface point: Lambertian diffuse plus the energy-conserving
//! modified Phong lobe of Lafortune & Willems, "Using the modified Phong
//! reflectance model for physically based rendering" (1994):
//!
//! `f(wo, wi) = kd/π + ks·(n+2)/(2π)·cosⁿα`,  α = angle(wi, reflect(wo)).
//!
//! With `kd + ks ≤ 1` the albedo never exceeds 1 for any `wo` (the lobe
//! integrates `cosθi·cosⁿα` to at most `2π/(n+2)`). Every surface is
//! two-sided: the shading frame is flipped to the side the ray arrives from,
//! as in the reference renders (`twosided` in Mitsuba).

use crate::sampling::{cosine_hemisphere, cosine_power_lobe, Frame};
use crate::scene::Material;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Luminance weights (Rec. 709), used to split sampling between lobes.
pub fn luminance(c: Vec3) -> f32 {
    c.dot(LUMINANCE)
}

/// Rec. 709 luminance weights of (r, g, b).
pub const LUMINANCE: Vec3 = Vec3::new(0.2126, 0.7152, 0.0722);

/// The BSDF of one material at one shading point, in a local frame whose +Z
/// is the shading normal on the side of the outgoing direction.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    kd: Vec3,
    ks: Vec3,
    exponent: f32,
    /// Probability of sampling the Phong lobe rather than the diffuse one.
    specular_pick: f32,
    pub frame: Frame,
}

/// A direction drawn from a BSDF with its value and solid-angle pdf.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3,
    /// `f(wo, wi)` (without the cosine).
    pub f: Vec3,
    pub pdf: f32,
}

impl Bsdf {
    /// `normal` is the (unit) shading normal; it is flipped to face `wo`.
    pub fn new(material: &Material, normal: Vec3, wo: Vec3) -> Self {
        let n = if normal.dot(wo) < 0.0 {
            -normal
        } else {
            normal
        };
        let (d, s) = (luminance(material.diffuse), luminance(material.specular));
        Bsdf {
            kd: material.diffuse,
            ks: material.specular,
            exponent: material.exponent,
            specular_pick: if d + s > 0.0 { s / (d + s) } else { 0.0 },
            frame: Frame::new(n),
        }
    }

    /// Shading normal on the side of `wo`.
    pub fn normal(&self) -> Vec3 {
        self.frame.n
    }

    pub fn is_black(&self) -> bool {
        self.kd.max_element() <= 0.0 && self.ks.max_element() <= 0.0
    }

    /// Mirror direction of `wo` about the shading normal.
    fn reflect(&self, wo: Vec3) -> Vec3 {
        let n = self.frame.n;
        2.0 * n.dot(wo) * n - wo
    }

    /// `cosⁿα` of the Phong lobe, 0 behind the mirror direction.
    fn lobe(&self, wo: Vec3, wi: Vec3) -> f32 {
        let cos_alpha = self.reflect(wo).dot(wi);
        if cos_alpha > 0.0 {
            cos_alpha.powf(self.exponent)
        } else {
            0.0
        }
    }

    /// `f(wo, wi)`; zero unless both directions are above the surface.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let n = self.frame.n;
        if n.dot(wi) <= 0.0 || n.dot(wo) <= 0.0 {
            return Vec3::ZERO;
        }
        self.kd * FRAC_1_PI + self.eval_specular(wo, wi)
    }

    /// Solid-angle density with which [`Bsdf::sample`] picks `wi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let cos_i = self.frame.n.dot(wi);
        if cos_i <= 0.0 || self.frame.n.dot(wo) <= 0.0 {
            return 0.0;
        }
        let diffuse = cos_i * FRAC_1_PI;
        if !self.has_specular() {
            // No `cosⁿα` to evaluate (a `powf`, a twentieth of a diffuse
            // path tracer's time when it was evaluated and multiplied by 0).
            return diffuse;
        }
        (1.0 - self.specular_pick) * diffuse + self.specular_pick * self.pdf_specular(wo, wi)
    }

    /// Diffuse albedo `kd`: the part of the BSDF the irradiance caches serve.
    pub fn diffuse_albedo(&self) -> Vec3 {
        self.kd
    }

    /// Whether the BSDF has a Phong lobe (glossy part).
    pub fn has_specular(&self) -> bool {
        self.specular_pick > 0.0
    }

    /// The Phong lobe alone: `ks·(n+2)/(2π)·cosⁿα`, zero below the surface.
    pub fn eval_specular(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let n = self.frame.n;
        if n.dot(wi) <= 0.0 || n.dot(wo) <= 0.0 || !self.has_specular() {
            return Vec3::ZERO;
        }
        self.ks * ((self.exponent + 2.0) * 0.5 * FRAC_1_PI * self.lobe(wo, wi))
    }

    /// Density of [`Bsdf::sample_specular`]: `(n+1)/(2π)·cosⁿα` above the surface.
    pub fn pdf_specular(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.frame.n.dot(wi) <= 0.0 || self.frame.n.dot(wo) <= 0.0 {
            return 0.0;
        }
        (self.exponent + 1.0) * 0.5 * FRAC_1_PI * self.lobe(wo, wi)
    }

    /// Draws `wi` from the Phong lobe only (for estimating the glossy part
    /// separately from the cached diffuse part).
    pub fn sample_specular(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if !self.has_specular() || self.frame.n.dot(wo) <= 0.0 {
            return None;
        }
        let wi = Frame::new(self.reflect(wo)).to_world(cosine_power_lobe(u, self.exponent));
        let pdf = self.pdf_specular(wo, wi);
        (pdf > 0.0).then(|| BsdfSample {
            wi,
            f: self.eval_specular(wo, wi),
            pdf,
        })
    }

    /// Draws `wi` ∝ the mixture of the cosine lobe and the `cosⁿα` lobe.
    /// `pick` chooses the lobe, `u` the direction. `None` when the direction
    /// falls below the surface (the estimate is then zero).
    pub fn sample(&self, wo: Vec3, pick: f32, u: Vec2) -> Option<BsdfSample> {
        if self.frame.n.dot(wo) <= 0.0 {
            return None;
        }
        let wi = if pick < self.specular_pick {
            Frame::new(self.reflect(wo)).to_world(cosine_power_lobe(u, self.exponent))
        } else {
            self.frame.to_world(cosine_hemisphere(u))
        };
        let pdf = self.pdf(wo, wi);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wi,
            f: self.eval(wo, wi),
            pdf,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Rng, SampleKey};
    use std::f32::consts::PI;

    fn phong(n: f32) -> Material {
        Material::glossy("phong", Vec3::ZERO, Vec3::ONE, n)
    }

    fn rng(item: u64) -> Rng {
        Rng::new(SampleKey {
            seed: 5,
            frame: None,
            item,
            sample: 0,
        })
    }

    /// Directional albedo ∫ f cosθi dωi, estimated with the BSDF's own
    /// importance sampling.
    fn albedo(bsdf: &Bsdf, wo: Vec3, samples: u32, rng: &mut Rng) -> f32 {
        let mut sum = 0.0f64;
        for _ in 0..samples {
            if let Some(s) = bsdf.sample(wo, rng.next_f32(), rng.next_2d()) {
                sum += (s.f.x * s.wi.dot(bsdf.normal()) / s.pdf) as f64;
            }
        }
        (sum / samples as f64) as f32
    }

    #[test]
    fn phong_white_furnace_never_exceeds_one() {
        let mut rng = rng(1);
        for n in [1.0, 2.0, 10.0, 40.0, 100.0, 200.0, 500.0, 1000.0] {
            for theta_deg in [0.0f32, 30.0, 60.0, 85.0] {
                let t = theta_deg.to_radians();
                let wo = Vec3::new(t.sin(), 0.0, t.cos());
                let bsdf = Bsdf::new(&phong(n), Vec3::Z, wo);
                let a = albedo(&bsdf, wo, 20_000, &mut rng);
                assert!(a <= 1.0 + 0.01, "n={n} θo={theta_deg}: albedo {a} > 1");
                if theta_deg == 0.0 {
                    // At normal incidence the lobe lies fully above the surface
                    // and the normalisation makes it exactly 1.
                    assert!(
                        (a - 1.0).abs() < 0.01,
                        "n={n}: albedo at normal incidence {a}"
                    );
                }
            }
        }
    }

    #[test]
    fn lambertian_albedo_is_kd() {
        let m = Material::diffuse("d", Vec3::splat(0.6));
        let wo = Vec3::new(0.5, 0.1, 0.8).normalize();
        let bsdf = Bsdf::new(&m, Vec3::Z, wo);
        let a = albedo(&bsdf, wo, 10_000, &mut rng(2));
        assert!((a - 0.6).abs() < 1e-4, "albedo {a}");
    }

    /// The sampler's histogram over (cosθ, φ) bins matches the pdf
    /// integrated over each bin by quadrature.
    #[test]
    fn phong_sampling_matches_pdf() {
        let material = Material::glossy("g", Vec3::splat(0.3), Vec3::splat(0.5), 20.0);
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let bsdf = Bsdf::new(&material, Vec3::Z, wo);
        let (bins_c, bins_p) = (16usize, 16usize);
        let samples = 400_000;
        let mut hist = vec![0u32; bins_c * bins_p];
        let mut rng = rng(3);
        let bin_of = |w: Vec3| {
            let c = ((w.z.clamp(0.0, 0.999_999)) * bins_c as f32) as usize;
            let phi = w.y.atan2(w.x).rem_euclid(2.0 * PI);
            let p = ((phi / (2.0 * PI)) * bins_p as f32).min(bins_p as f32 - 1.0) as usize;
            c * bins_p + p
        };
        for _ in 0..samples {
            if let Some(s) = bsdf.sample(wo, rng.next_f32(), rng.next_2d()) {
                hist[bin_of(s.wi)] += 1;
            }
        }
        // Quadrature of the pdf over each bin (dω = dcosθ dφ).
        let sub = 24;
        let mut chi2 = 0.0;
        let mut dof = 0;
        for c in 0..bins_c {
            for p in 0..bins_p {
                let mut integral = 0.0f64;
                for i in 0..sub {
                    for j in 0..sub {
                        let cos = (c as f32 + (i as f32 + 0.5) / sub as f32) / bins_c as f32;
                        let phi =
                            2.0 * PI * (p as f32 + (j as f32 + 0.5) / sub as f32) / bins_p as f32;
                        let sin = (1.0 - cos * cos).sqrt();
                        let w = Vec3::new(sin * phi.cos(), sin * phi.sin(), cos);
                        integral += bsdf.pdf(wo, w) as f64;
                    }
                }
                let area = (1.0 / bins_c as f64) * (2.0 * PI as f64 / bins_p as f64);
                let expected = integral / (sub * sub) as f64 * area * samples as f64;
                if expected > 20.0 {
                    let d = hist[c * bins_p + p] as f64 - expected;
                    chi2 += d * d / expected;
                    dof += 1;
                }
            }
        }
        // χ² per degree of freedom ≈ 1 when the histogram follows the pdf;
        // quadrature error adds a little, a wrong pdf adds orders of magnitude.
        assert!(dof > 50, "too few populated bins: {dof}");
        assert!(
            chi2 / (dof as f64) < 2.0,
            "chi2/dof = {}",
            chi2 / dof as f64
        );
    }

    #[test]
    fn pdf_integrates_to_at_most_one() {
        let material = Material::glossy("g", Vec3::splat(0.2), Vec3::splat(0.7), 50.0);
        let wo = Vec3::new(0.0, 0.3, 0.95).normalize();
        let bsdf = Bsdf::new(&material, Vec3::Z, wo);
        // Uniform hemisphere quadrature.
        let mut rng = rng(4);
        let n = 400_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u = rng.next_2d();
            let z = u.x;
            let r = (1.0 - z * z).sqrt();
            let phi = 2.0 * PI * u.y;
            sum += bsdf.pdf(wo, Vec3::new(r * phi.cos(), r * phi.sin(), z)) as f64;
        }
        let integral = sum / n as f64 * 2.0 * PI as f64;
        assert!(integral <= 1.02 && integral > 0.9, "∫pdf = {integral}");
    }

    #[test]
    fn back_side_is_shaded_like_front() {
        let m = Material::diffuse("d", Vec3::splat(0.5));
        let wo = Vec3::new(0.0, 0.0, -1.0);
        let bsdf = Bsdf::new(&m, Vec3::Z, wo);
        assert!(bsdf.normal().z < 0.0);
        let f = bsdf.eval(wo, Vec3::new(0.1, 0.0, -0.99).normalize());
        assert!((f.x - 0.5 / PI).abs() < 1e-6);
    }
}
