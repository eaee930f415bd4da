//! Physical parameters that users set, with the validation every entry point runs
//! before a value reaches an algorithm. Invalid input is an error, never a panic.

use crate::optics::CauchyDispersion;
use glam::Vec3;
use thiserror::Error;

/// A parameter that no algorithm can use, with the reason in words.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum ParamError {
    /// An index of refraction below one (or not finite). Real media have `n ≥ 1`.
    #[error("index of refraction {0} is impossible: it must be a finite number ≥ 1")]
    ImpossibleIor(f32),
    /// A dispersion model that gives an impossible IOR somewhere in the visible range.
    #[error("Cauchy dispersion A = {a}, B = {b} gives an index of refraction below 1 in the visible range")]
    ImpossibleDispersion {
        /// Cauchy `A`: the index of refraction in the long-wavelength limit.
        a: f32,
        /// Cauchy `B` in µm².
        b: f32,
    },
    /// A scattering or absorption coefficient that is negative or not finite.
    #[error("{name} = {value} is impossible: it must be a finite number ≥ 0 (per metre)")]
    NegativeCoefficient {
        /// Which coefficient.
        name: &'static str,
        /// Its value (per metre).
        value: f32,
    },
    /// A Henyey–Greenstein asymmetry outside the open interval (−1, 1).
    #[error("phase asymmetry g = {0} is impossible: it must lie strictly between −1 and 1")]
    ImpossibleAsymmetry(f32),
    /// A value outside the range it must lie in.
    #[error("{name} = {value} is impossible: it must be {expected}")]
    OutOfRange {
        /// Which value.
        name: &'static str,
        /// The value given.
        value: f32,
        /// The range it must lie in, in words.
        expected: &'static str,
    },
    /// Any other value that must be finite and is not.
    #[error("{name} = {value} is not a finite number")]
    NotFinite {
        /// Which value.
        name: &'static str,
        /// The value given.
        value: f32,
    },
}

/// Checks an index of refraction: finite and at least one.
pub fn check_ior(ior: f32) -> Result<f32, ParamError> {
    if ior.is_finite() && ior >= 1.0 { Ok(ior) } else { Err(ParamError::ImpossibleIor(ior)) }
}

/// Checks a Cauchy model: finite, and `n ≥ 1` over the visible range 0.38–0.78 µm.
pub fn check_dispersion(d: &CauchyDispersion) -> Result<(), ParamError> {
    let ok = d.a.is_finite() && d.b.is_finite() && d.ior(0.38) >= 1.0 && d.ior(0.78) >= 1.0;
    if ok { Ok(()) } else { Err(ParamError::ImpossibleDispersion { a: d.a, b: d.b }) }
}

/// Checks a coefficient (σₛ, σₐ, …): finite and non-negative.
pub fn check_coefficient(name: &'static str, value: f32) -> Result<f32, ParamError> {
    if value.is_finite() && value >= 0.0 { Ok(value) } else { Err(ParamError::NegativeCoefficient { name, value }) }
}

/// Checks a Henyey–Greenstein asymmetry parameter: finite and in (−1, 1).
pub fn check_asymmetry(g: f32) -> Result<f32, ParamError> {
    if g.is_finite() && g > -1.0 && g < 1.0 { Ok(g) } else { Err(ParamError::ImpossibleAsymmetry(g)) }
}

/// Checks that a value is finite.
pub fn check_finite(name: &'static str, value: f32) -> Result<f32, ParamError> {
    if value.is_finite() { Ok(value) } else { Err(ParamError::NotFinite { name, value }) }
}

/// How a generator surface redirects light.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum SpecularInteraction {
    /// A perfect mirror: all flux is reflected (metal, reflectance folded into the light colour).
    Reflect,
    /// A dielectric boundary between the outside (IOR 1) and a medium of index `ior`
    /// on the side opposite the surface normal; flux splits by the Fresnel terms.
    Refract {
        /// Index of refraction of the inside medium (≥ 1).
        ior: f32,
        /// Optional wavelength dependence; when present it replaces `ior` per channel.
        dispersion: Option<CauchyDispersion>,
    },
}

impl SpecularInteraction {
    /// Validates the interaction's parameters.
    pub fn validate(&self) -> Result<(), ParamError> {
        match self {
            SpecularInteraction::Reflect => Ok(()),
            SpecularInteraction::Refract { ior, dispersion } => {
                check_ior(*ior)?;
                if let Some(d) = dispersion {
                    check_dispersion(d)?;
                }
                Ok(())
            }
        }
    }

    /// Index of refraction seen by a wavelength (µm); `None` for a mirror.
    pub fn ior_at(&self, wavelength_um: f32) -> Option<f32> {
        match self {
            SpecularInteraction::Reflect => None,
            SpecularInteraction::Refract { ior, dispersion } => Some(dispersion.map_or(*ior, |d| d.ior(wavelength_um))),
        }
    }
}

/// A homogeneous participating medium (Ernst et al. 2005 §3.5). Absorption is per
/// linear RGB channel: water absorbs red metres sooner than blue, which is its colour.
/// A scene file may give it as one number for all three channels.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MediumCoefficients {
    /// Scattering coefficient σₛ (1/m).
    pub scattering: f32,
    /// Absorption coefficient σₐ per linear RGB channel (1/m).
    #[serde(deserialize_with = "per_channel")]
    pub absorption: Vec3,
    /// Henyey–Greenstein asymmetry g.
    pub asymmetry: f32,
}

impl MediumCoefficients {
    /// Extinction `σₜ = σₛ + σₐ` per channel.
    pub fn extinction(&self) -> Vec3 {
        self.absorption + self.scattering
    }

    /// Validates all three coefficients, each channel of σₐ.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_coefficient("scattering", self.scattering)?;
        for (name, value) in ["absorption (red)", "absorption (green)", "absorption (blue)"].into_iter().zip(self.absorption.to_array()) {
            check_coefficient(name, value)?;
        }
        check_asymmetry(self.asymmetry)?;
        Ok(())
    }
}

/// A per-channel value from a scene file: `[r, g, b]`, or one number for all three.
fn per_channel<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<Vec3, D::Error> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum PerChannel {
        Grey(f32),
        Rgb(Vec3),
    }
    Ok(match serde::Deserialize::deserialize(deserializer)? {
        PerChannel::Grey(value) => Vec3::splat(value),
        PerChannel::Rgb(value) => value,
    })
}
