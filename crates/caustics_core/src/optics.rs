//! Geometric optics at a smooth interface: reflection, Snell refraction, dielectric
//! Fresnel terms, Beer–Lambert extinction, the Henyey–Greenstein phase function and
//! Cauchy dispersion.
//!
//! Conventions: directions are unit vectors; `incident` points *towards* the surface
//! (the way light travels) and `normal` is the surface normal on either side — the
//! functions orient it themselves. `eta` is always `n_incident / n_transmitted`.

use glam::Vec3;
use std::f32::consts::PI;

/// Mirror reflection `r = d − 2(d·n)n` (law of reflection). Works for either
/// orientation of `normal`.
#[inline]
pub fn reflect(incident: Vec3, normal: Vec3) -> Vec3 {
    incident - 2.0 * incident.dot(normal) * normal
}

/// Outcome of Snell's law at an interface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Refraction {
    /// The transmitted unit direction.
    Transmitted(Vec3),
    /// `sin θt` would exceed one: all light is reflected (total internal reflection).
    TotalInternalReflection,
}

impl Refraction {
    /// The transmitted direction, `None` under total internal reflection.
    pub fn direction(self) -> Option<Vec3> {
        match self {
            Refraction::Transmitted(d) => Some(d),
            Refraction::TotalInternalReflection => None,
        }
    }
}

/// Snell's law `n₁ sin θ₁ = n₂ sin θ₂` in vector form:
/// `t = η d + (η cos θᵢ − cos θₜ) n`, with `cos θₜ = √(1 − η²(1 − cos²θᵢ))`.
///
/// `eta = n₁ / n₂`. Never returns NaN: past the critical angle the result is
/// [`Refraction::TotalInternalReflection`]. `eta == 1` returns `incident` unchanged.
#[inline]
pub fn refract(incident: Vec3, normal: Vec3, eta: f32) -> Refraction {
    if eta == 1.0 {
        return Refraction::Transmitted(incident);
    }
    // Orient the normal against the incident direction.
    let mut n = normal;
    let mut cos_i = -incident.dot(n);
    if cos_i < 0.0 {
        n = -n;
        cos_i = -cos_i;
    }
    let cos_i = cos_i.min(1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t > 1.0 {
        return Refraction::TotalInternalReflection;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let t = eta * incident + (eta * cos_i - cos_t) * n;
    Refraction::Transmitted(t.normalize_or(incident))
}

/// Unpolarised Fresnel reflectance of a smooth dielectric interface,
/// `R = ½(r_s² + r_p²)` with
/// `r_s = (n₁cos θᵢ − n₂cos θₜ)/(n₁cos θᵢ + n₂cos θₜ)`,
/// `r_p = (n₂cos θᵢ − n₁cos θₜ)/(n₂cos θᵢ + n₁cos θₜ)` (Fresnel equations).
///
/// `cos_i` is the cosine between the incident ray and the normal (its sign is
/// ignored); `eta = n₁ / n₂`. Returns 1 under total internal reflection.
#[inline]
pub fn fresnel_reflectance(cos_i: f32, eta: f32) -> f32 {
    if eta == 1.0 {
        // No interface: nothing is reflected, exactly.
        return 0.0;
    }
    let cos_i = cos_i.abs().min(1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    // Divide through by n₂ so that only η = n₁/n₂ appears.
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r = 0.5 * (rs * rs + rp * rp);
    if r.is_finite() { r.clamp(0.0, 1.0) } else { 1.0 }
}

/// Unpolarised Fresnel transmittance `T = 1 − R` (energy conservation at a
/// lossless interface). Multiply radiance by `T / η²` if radiance rather than flux
/// is carried across the interface.
#[inline]
pub fn fresnel_transmittance(cos_i: f32, eta: f32) -> f32 {
    1.0 - fresnel_reflectance(cos_i, eta)
}

/// Critical angle `θc = asin(n₂/n₁)` for light going from the denser medium,
/// `None` when `eta = n₁/n₂ ≤ 1` (no total internal reflection possible).
pub fn critical_angle(eta: f32) -> Option<f32> {
    (eta > 1.0).then(|| (1.0 / eta).asin())
}

/// Beer–Lambert extinction `T(d) = exp(−σₜ d)` along a path of length `d` in a
/// homogeneous medium with extinction coefficient `σₜ = σₐ + σₛ`.
#[inline]
pub fn beer_lambert(sigma_t: f32, distance: f32) -> f32 {
    (-sigma_t.max(0.0) * distance.max(0.0)).exp()
}

/// Henyey–Greenstein phase function
/// `p(cos θ) = (1 − g²) / (4π (1 + g² − 2g cos θ)^{3/2})`, normalised over the sphere.
///
/// `cos_theta` is the cosine between the propagation directions before and after
/// scattering; `g ∈ (−1, 1)` is the mean cosine (clamped to ±0.999 so that the
/// function stays finite).
#[inline]
pub fn henyey_greenstein(cos_theta: f32, g: f32) -> f32 {
    let g = g.clamp(-0.999, 0.999);
    let denom = (1.0 + g * g - 2.0 * g * cos_theta.clamp(-1.0, 1.0)).max(1e-12);
    (1.0 - g * g) / (4.0 * PI * denom * denom.sqrt())
}

/// Cauchy's dispersion formula `n(λ) = A + B / λ²` (λ in micrometres).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CauchyDispersion {
    /// `A`: the index of refraction in the long-wavelength limit.
    pub a: f32,
    /// `B` in µm².
    pub b: f32,
}

/// Representative wavelengths (µm) of the red, green and blue channels.
pub const RGB_WAVELENGTHS_UM: [f32; 3] = [0.6563, 0.5461, 0.4358];

impl CauchyDispersion {
    /// Borosilicate crown glass (BK7): n_d ≈ 1.517.
    pub const BK7: Self = Self { a: 1.5046, b: 0.004_20 };
    /// Water at 20 °C: n_d ≈ 1.333.
    pub const WATER: Self = Self { a: 1.3247, b: 0.003_10 };

    /// A Cauchy model with no dispersion: `n(λ) = ior` everywhere.
    pub const fn constant(ior: f32) -> Self {
        Self { a: ior, b: 0.0 }
    }

    /// Index of refraction at `wavelength_um` micrometres.
    #[inline]
    pub fn ior(&self, wavelength_um: f32) -> f32 {
        self.a + self.b / (wavelength_um * wavelength_um)
    }

    /// Index of refraction per RGB channel, at [`RGB_WAVELENGTHS_UM`].
    pub fn ior_rgb(&self) -> [f32; 3] {
        RGB_WAVELENGTHS_UM.map(|l| self.ior(l))
    }
}
