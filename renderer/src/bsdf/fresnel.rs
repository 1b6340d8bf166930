//! Fresnel equations for dielectric and conductor interfaces, the diffuse Fresnel reflectance,
//! and the mirror/refraction helpers (Mitsuba 3's `fresnel.h` semantics).

use crate::spectrum::Rgb;
use glam::Vec3;

/// Unpolarised Fresnel reflectance of a dielectric interface with relative IOR `eta`
/// (interior / exterior), for an incident cosine `cos_theta_i` measured against the normal,
/// which points to the exterior. A negative cosine means arrival from the interior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DielectricFresnel {
    /// Reflectance R ∈ [0, 1] (1 under total internal reflection).
    pub r: f32,
    /// Signed cosine of the transmitted direction (opposite sign to `cos_theta_i`; 0 under TIR).
    pub cos_theta_t: f32,
    /// Relative IOR η_t/η_i seen by the incident ray (η from outside, 1/η from inside).
    pub eta_it: f32,
    /// Its reciprocal η_i/η_t.
    pub eta_ti: f32,
}

/// Dielectric Fresnel reflectance and refraction data; see [`DielectricFresnel`].
pub fn fresnel_dielectric(cos_theta_i: f32, eta: f32) -> DielectricFresnel {
    let outside = cos_theta_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    // Snell: cos²θt = 1 − sin²θi / η².
    let cos_t_sqr = 1.0 - (1.0 - cos_theta_i * cos_theta_i) * (eta_ti * eta_ti);
    let cos_i = cos_theta_i.abs();
    let cos_t = cos_t_sqr.max(0.0).sqrt();
    let r = if eta == 1.0 {
        0.0
    } else if cos_i == 0.0 {
        1.0
    } else {
        let a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
        let a_p = (cos_t - eta_it * cos_i) / (cos_t + eta_it * cos_i);
        0.5 * (a_s * a_s + a_p * a_p)
    };
    DielectricFresnel {
        r,
        cos_theta_t: if cos_theta_i >= 0.0 { -cos_t } else { cos_t },
        eta_it,
        eta_ti,
    }
}

/// Unpolarised Fresnel reflectance of a conductor with complex IOR `eta + i·k` (per channel) for
/// an incident cosine `cos_theta_i` ≥ 0 (exact formula, as Mitsuba's `fresnel_conductor`).
pub fn fresnel_conductor(cos_theta_i: f32, eta: Rgb, k: Rgb) -> Rgb {
    let c = cos_theta_i;
    Rgb::new(
        fresnel_conductor_1(c, eta.x, k.x),
        fresnel_conductor_1(c, eta.y, k.y),
        fresnel_conductor_1(c, eta.z, k.z),
    )
}

fn fresnel_conductor_1(cos_i: f32, eta: f32, k: f32) -> f32 {
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let sin4 = sin2 * sin2;
    let t1 = eta * eta - k * k - sin2;
    // a² + b² = |η̃² − sin²θ|, a = Re √(η̃² − sin²θ).
    let a2pb2 = (t1 * t1 + 4.0 * k * k * eta * eta).max(0.0).sqrt();
    let a = (0.5 * (a2pb2 + t1)).max(0.0).sqrt();
    let term1 = a2pb2 + cos2;
    let term2 = 2.0 * cos_i * a;
    let r_s = (term1 - term2) / (term1 + term2);
    let term3 = a2pb2 * cos2 + sin4;
    let term4 = term2 * sin2;
    let r_p = r_s * (term3 - term4) / (term3 + term4);
    0.5 * (r_s + r_p)
}

/// Hemispherically averaged (cosine-weighted) Fresnel reflectance of a dielectric boundary with
/// relative IOR `eta`, by the polynomial fits Mitsuba uses (Egan & Hilgeman 1973 for η < 1,
/// d'Eon & Irving 2011 otherwise).
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv = 1.0 / eta;
    if eta < 1.0 {
        -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 * inv
    } else {
        // Horner in 1/η.
        let c = [0.919317f32, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881];
        c.iter().rev().fold(0.0, |acc, &ci| acc * inv + ci)
    }
}

/// Mirror `w` about the local normal +z.
#[inline]
pub fn reflect(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

/// Mirror `w` about the unit vector `m`.
#[inline]
pub fn reflect_about(w: Vec3, m: Vec3) -> Vec3 {
    2.0 * w.dot(m) * m - w
}

/// Refract `w` through the local +z interface, given the data from [`fresnel_dielectric`].
#[inline]
pub fn refract(w: Vec3, cos_theta_t: f32, eta_ti: f32) -> Vec3 {
    Vec3::new(-eta_ti * w.x, -eta_ti * w.y, cos_theta_t)
}

/// Refract `w` through a microfacet with unit normal `m`, given [`fresnel_dielectric`]`(w·m)`.
#[inline]
pub fn refract_about(w: Vec3, m: Vec3, cos_theta_t: f32, eta_ti: f32) -> Vec3 {
    m * (w.dot(m) * eta_ti + cos_theta_t) - w * eta_ti
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_fresnel_hand_values() {
        // Normal incidence: ((η−1)/(η+1))², from either side.
        let f = fresnel_dielectric(1.0, 1.5);
        assert!((f.r - 0.04).abs() < 1e-6, "{}", f.r);
        assert!((f.cos_theta_t + 1.0).abs() < 1e-6);
        assert!((f.eta_it - 1.5).abs() < 1e-6 && (f.eta_ti - 1.0 / 1.5).abs() < 1e-6);
        let f = fresnel_dielectric(-1.0, 1.5);
        assert!((f.r - 0.04).abs() < 1e-6 && (f.cos_theta_t - 1.0).abs() < 1e-6);
        // 45° from air into η = 1.5: sinθt = 0.4714, cosθt = 0.881917;
        // rs = ((0.707107 − 1.5·0.881917)/(0.707107 + 1.5·0.881917))² = 0.092013,
        // rp = ((0.881917 − 1.5·0.707107)/(0.881917 + 1.5·0.707107))² = 0.008466.
        let c = std::f32::consts::FRAC_1_SQRT_2;
        let f = fresnel_dielectric(c, 1.5);
        assert!((f.r - 0.5 * (0.092013 + 0.008466)).abs() < 2e-5, "{}", f.r);
        assert!((f.cos_theta_t + 0.881917).abs() < 1e-5);
        // Brewster angle tan θB = η: rp = 0, so R = rs/2 with rs = cos²(θi+θt)... = 0.0739/… check:
        let theta_b = 1.5f32.atan();
        let f = fresnel_dielectric(theta_b.cos(), 1.5);
        // rs at Brewster = ((η² − 1)/(η² + 1))² = (1.25/3.25)² = 0.147929.
        assert!((f.r - 0.5 * 0.147929).abs() < 2e-5, "{}", f.r);
        // Total internal reflection from inside beyond the critical angle (41.8°): 60°.
        let f = fresnel_dielectric(-0.5, 1.5);
        assert_eq!(f.r, 1.0);
        assert_eq!(f.cos_theta_t, 0.0);
        // Index matched: no reflection.
        assert_eq!(fresnel_dielectric(0.3, 1.0).r, 0.0);
        // Grazing: full reflection.
        assert_eq!(fresnel_dielectric(0.0, 1.5).r, 1.0);
    }

    #[test]
    fn conductor_fresnel_hand_values() {
        // Normal incidence: ((η−1)² + k²)/((η+1)² + k²); gold-ish red channel η=0.2, k=3.
        let r = fresnel_conductor(1.0, Rgb::new(0.2, 1.5, 0.0), Rgb::new(3.0, 0.0, 1.0));
        assert!((r.x - (0.64 + 9.0) / (1.44 + 9.0)).abs() < 1e-5, "{}", r.x);
        // k = 0 reduces to the dielectric formula.
        assert!((r.y - 0.04).abs() < 1e-6);
        // η = 0, k = 1 (Mitsuba's "none" material) is a perfect mirror at every angle.
        for c in [1.0, 0.7, 0.2, 0.01] {
            let r = fresnel_conductor(c, Rgb::ZERO, Rgb::ONE);
            assert!((r - Rgb::ONE).abs().max_element() < 1e-5, "{c}: {r}");
        }
        // k = 0 at 45° matches the dielectric value.
        let c = std::f32::consts::FRAC_1_SQRT_2;
        let r = fresnel_conductor(c, Rgb::splat(1.5), Rgb::ZERO);
        assert!((r.x - fresnel_dielectric(c, 1.5).r).abs() < 1e-5);
    }

    #[test]
    fn diffuse_fresnel_reflectance_matches_numerical_integral() {
        // Fdr(η) = 2∫₀¹ R(μ) μ dμ, from outside for η > 1 and inside for η < 1.
        for eta in [1.33f32, 1.5, 1.0 / 1.5, 1.0 / 1.33] {
            let n = 20000;
            let mut sum = 0.0f64;
            for i in 0..n {
                let mu = (i as f32 + 0.5) / n as f32;
                sum += (fresnel_dielectric(mu, eta).r * mu) as f64;
            }
            let exact = 2.0 * sum / n as f64;
            let fit = fresnel_diffuse_reflectance(eta) as f64;
            assert!(
                (fit - exact).abs() < 0.01 * exact.max(0.05),
                "η={eta}: {fit} vs {exact}"
            );
        }
    }

    #[test]
    fn refraction_obeys_snell() {
        let w = Vec3::new(0.6, 0.0, 0.8);
        let f = fresnel_dielectric(w.z, 1.5);
        let t = refract(w, f.cos_theta_t, f.eta_ti);
        assert!((t.length() - 1.0).abs() < 1e-5);
        assert!(t.z < 0.0);
        // sinθi = η sinθt.
        assert!((0.6 - 1.5 * (-t.x)).abs() < 1e-5);
        let m = Vec3::new(0.1, 0.2, 0.9).normalize();
        let f = fresnel_dielectric(w.dot(m), 1.5);
        let t = refract_about(w, m, f.cos_theta_t, f.eta_ti);
        assert!((t.length() - 1.0).abs() < 1e-5);
        assert!((t.dot(m) - f.cos_theta_t).abs() < 1e-5);
        let r = reflect_about(w, m);
        assert!((r.dot(m) - w.dot(m)).abs() < 1e-6 && (r.length() - 1.0).abs() < 1e-5);
    }
}
