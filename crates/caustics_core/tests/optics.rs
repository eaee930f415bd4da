//! Properties of the optics primitives that physics fixes exactly.

use caustics_core::optics::*;
use glam::Vec3;
use proptest::prelude::*;

fn dir_at(theta: f32) -> Vec3 {
    // Travelling downwards onto a surface with normal +y, at angle θ from the normal.
    Vec3::new(theta.sin(), -theta.cos(), 0.0)
}

proptest! {
    /// Snell's law holds for the returned vector, which is unit length and on the far side.
    #[test]
    fn snell_law_holds(theta in 0.0f32..1.5, n1 in 1.0f32..2.5, n2 in 1.0f32..2.5) {
        let eta = n1 / n2;
        match refract(dir_at(theta), Vec3::Y, eta) {
            Refraction::Transmitted(t) => {
                prop_assert!((t.length() - 1.0).abs() < 1e-5);
                prop_assert!(t.y < 0.0);
                let sin_t = (t.x * t.x + t.z * t.z).sqrt();
                prop_assert!((n1 * theta.sin() - n2 * sin_t).abs() < 2e-5 * n1.max(n2));
            }
            Refraction::TotalInternalReflection => prop_assert!(eta * theta.sin() > 1.0 - 1e-6),
        }
    }

    /// Energy is conserved at the interface and both terms are probabilities.
    #[test]
    fn reflectance_and_transmittance_sum_to_one(cos_i in -1.0f32..1.0, eta in 0.3f32..3.0) {
        let (r, t) = (fresnel_reflectance(cos_i, eta), fresnel_transmittance(cos_i, eta));
        prop_assert!((0.0..=1.0).contains(&r) && (0.0..=1.0).contains(&t));
        prop_assert!((r + t - 1.0).abs() < 1e-6);
    }

    /// Helmholtz reciprocity: R(θ₁, n₁→n₂) = R(θ₂, n₂→n₁) with θ₂ the refracted angle.
    /// Near grazing the way back is ill-conditioned: a rounding of cos θ₂ moves the
    /// cos θ₁ it implies κ = n² cos θ₂ / cos θ₁ times as much (245 at 88.8° into
    /// n = 2.4), so the tolerance grows with κ times f32's rounding.
    #[test]
    fn fresnel_is_reciprocal(theta in 0.0f32..1.55, n in 1.0f32..2.5) {
        let t = refract(dir_at(theta), Vec3::Y, 1.0 / n).direction().unwrap();
        let cos_t = -t.y;
        let forward = fresnel_reflectance(theta.cos(), 1.0 / n);
        let backward = fresnel_reflectance(cos_t, n);
        let kappa = n * n * cos_t / theta.cos();
        prop_assert!((forward - backward).abs() < 1e-4 + 1e-6 * kappa, "{forward} vs {backward}, κ = {kappa}");
    }

    /// Reflection keeps the angle and the tangential component, and is an involution.
    #[test]
    fn reflection_mirrors(theta in 0.0f32..1.5, phi in 0.0f32..std::f32::consts::TAU) {
        let d = Vec3::new(theta.sin() * phi.cos(), -theta.cos(), theta.sin() * phi.sin());
        let r = reflect(d, Vec3::Y);
        prop_assert!((r.y + d.y).abs() < 1e-6 && (r.x - d.x).abs() < 1e-6 && (r.z - d.z).abs() < 1e-6);
        prop_assert!((reflect(r, Vec3::Y) - d).length() < 1e-6);
    }
}

#[test]
fn total_internal_reflection_starts_exactly_at_the_critical_angle() {
    for n in [1.1f32, 1.333, 1.5, 2.4] {
        let theta_c = critical_angle(n).unwrap();
        // Going from glass (n) into air: eta = n.
        let below = refract(dir_at(theta_c * (1.0 - 1e-4)), Vec3::Y, n);
        let above = refract(dir_at(theta_c * (1.0 + 1e-4)), Vec3::Y, n);
        assert!(matches!(below, Refraction::Transmitted(_)), "n = {n}");
        assert_eq!(above, Refraction::TotalInternalReflection, "n = {n}");
        assert_eq!(fresnel_reflectance((theta_c * 1.0001).cos(), n), 1.0);
        assert!(fresnel_reflectance((theta_c * 0.999).cos(), n) < 1.0);
    }
    assert_eq!(critical_angle(1.0), None);
    assert_eq!(critical_angle(0.75), None);
}

#[test]
fn normal_and_grazing_incidence() {
    for n in [1.333f32, 1.5, 2.42] {
        let r0 = ((1.0 - n) / (1.0 + n)).powi(2);
        assert!((fresnel_reflectance(1.0, 1.0 / n) - r0).abs() < 1e-6);
        assert!((fresnel_reflectance(1.0, n) - r0).abs() < 1e-6);
        // At normal incidence the ray goes straight through.
        let t = refract(Vec3::NEG_Y, Vec3::Y, 1.0 / n).direction().unwrap();
        assert!((t - Vec3::NEG_Y).length() < 1e-6);
        // Grazing incidence reflects everything.
        assert!(fresnel_reflectance(0.0, 1.0 / n) > 1.0 - 1e-6);
    }
}

#[test]
fn ior_one_is_the_identity() {
    for theta in [0.0f32, 0.3, 1.0, 1.5, std::f32::consts::FRAC_PI_2] {
        let d = dir_at(theta);
        let t = refract(d, Vec3::Y, 1.0).direction().unwrap();
        assert!((t - d).length() < 1e-6, "θ = {theta}");
        assert_eq!(fresnel_reflectance(theta.cos(), 1.0), 0.0);
    }
}

#[test]
fn refraction_never_returns_nan_on_degenerate_input() {
    for (d, n) in [(Vec3::ZERO, Vec3::Y), (Vec3::X, Vec3::Y), (Vec3::NEG_Y, Vec3::ZERO)] {
        if let Refraction::Transmitted(t) = refract(d, n, 1.0 / 1.5) {
            assert!(t.is_finite());
        }
        assert!(fresnel_reflectance(d.dot(n), 1.5).is_finite());
    }
}

#[test]
fn beer_lambert_multiplies_over_path_segments() {
    let s = 0.7;
    assert!((beer_lambert(s, 1.0) * beer_lambert(s, 2.5) - beer_lambert(s, 3.5)).abs() < 1e-6);
    assert_eq!(beer_lambert(s, 0.0), 1.0);
    assert_eq!(beer_lambert(0.0, 100.0), 1.0);
    assert!((beer_lambert(2.0, 1.0) - (-2.0f32).exp()).abs() < 1e-7);
}

/// ∫ p dω = 1 and ∫ p cos θ dω = g, by midpoint quadrature over cos θ.
#[test]
fn henyey_greenstein_is_normalised_with_mean_cosine_g() {
    for g in [-0.9f32, -0.3, 0.0, 0.5, 0.9] {
        let n = 200_000;
        let (mut total, mut mean) = (0.0f64, 0.0f64);
        for i in 0..n {
            let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
            let p = henyey_greenstein(mu as f32, g) as f64 * 2.0 * std::f64::consts::PI * (2.0 / n as f64);
            total += p;
            mean += p * mu;
        }
        assert!((total - 1.0).abs() < 1e-3, "g = {g}: ∫p = {total}");
        assert!((mean - g as f64).abs() < 2e-3, "g = {g}: mean cosine {mean}");
    }
}

#[test]
fn cauchy_dispersion_bends_blue_more() {
    let [r, g, b] = CauchyDispersion::BK7.ior_rgb();
    assert!(b > g && g > r);
    assert!((CauchyDispersion::BK7.ior(0.5876) - 1.5168).abs() < 2e-3, "BK7 n_d");
    assert!((CauchyDispersion::WATER.ior(0.5876) - 1.333).abs() < 2e-3, "water n_d");
    assert_eq!(CauchyDispersion::constant(1.4).ior_rgb(), [1.4; 3]);
}
