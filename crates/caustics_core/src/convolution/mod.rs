//! Pool caustics by convolution (Trendall & Stewart 2000, "General calculations using
//! graphics hardware, with application to interactive caustics", §4).
//!
//! Sunlight crosses a water surface `y = h(x, z)` ([`Heightfield`]), is refracted by
//! Snell's law (eq. 1, [`crate::optics::refract`]), weighted by the Fresnel
//! transmittance `T(θi)` and spread on its way down by a forward-scattering lobe
//! `exp(−a(1 − (L̂t·P̂)²))` with extinction `exp(−ε‖P‖)`; the irradiance on the floor
//! `y = −d` is eq. 2,
//! `E(x₀) = L_s ∫ T(θi) cos θi P̂_v exp(−a(1 − (L̂t·P̂)²)) exp(−ε‖P‖) dx dz`,
//! where `P` runs from the surface point to the floor point and `P̂_v` is its downward
//! component. Two evaluations:
//! - [`direct_irradiance`]: eq. 2 as written, by midpoint quadrature over the texels,
//!   with the exact `‖P‖`, `P̂` and Gaussian lobe;
//! - [`ConvolutionCaustics`]: §4.1's sum of three convolutions. With `d ≫ h`, `P`
//!   depends on the offset `x₀ − x` alone; the lobe is replaced by `(L̂t·P̂)ⁿ` expanded to
//!   first order in the horizontal components of `L̂t`,
//!   `(L̂t·P̂)ⁿ ≈ (L̂t,v P̂_v)ⁿ⁻¹ (L̂t,v P̂_v + n L̂t,x P̂_x + n L̂t,z P̂_z)`,
//!   so eq. 2 is a per-texel function convolved with a kernel, three times
//!   ([`ConvolutionKernels`]); on the CPU by FFT.
//!
//! [`convolution_error`] is the distance between the two: the cost of the paper's
//! approximations. [`ripples`] makes the rippling pond of §4.3.
//!
//! Frame: the crate's, y up (the paper's z); the surface's rest level is `y = 0`, texel
//! `(column, row)` lies at `x = (column + ½)·cell`, `z = (row + ½)·cell`, and the floor
//! irradiance is computed below each texel centre.
//!
//! What the paper leaves open, decided the same way for both forms:
//! - **Normalisation.** Eq. 2 is a proportionality (`L(P̂) ∼ exp(…)`). Each texel's lobe
//!   is divided by its own sum over the footprint without extinction, so a texel hands
//!   its flux `L_s T(θi) cos θi` to the floor less what extinction absorbs: energy is
//!   conserved, and a flat surface with `ε = 0` lights the floor with exactly
//!   `L_s T(θi) cos θi`. For the linearised lobe that sum is `L̂t,vⁿ K_v` (the horizontal
//!   kernels sum to zero by symmetry), a per-texel factor, so separability is kept.
//! - **Footprint.** Both integrate over the `(2r + 1)²` texels around the floor point
//!   ([`ConvolutionSettings::kernel_radius`]), so their difference measures the paper's
//!   approximations and not the truncation of the integral.
//! - **Edges.** [`Boundary`]: a tiling patch, or a pool whose walls mirror the light.
//! - §4.1's per-texel term has `cos θt` where eq. 2 and pass 3 of §4.2 have `cos θi`;
//!   `cos θi` is used. Its horizontal terms lack the expansion's factor `n`; it is kept.
//! - Light leaving the surface with `L̂t,v` below [`MIN_DOWNWARD_COSINE`] (within 0.06° of
//!   the horizontal) travels over a thousand depths sideways before it reaches the floor,
//!   far beyond any footprint; both forms drop it (this also bounds `L̂t,x / L̂t,v`).
//!   So does light that meets a facet from behind (the paper assumes no self-shadowing).

mod convolve;
mod direct;
mod heightfield;
pub mod ripples;

pub use convolve::{ConvolutionCaustics, ConvolutionKernels, LIFT_RADIUS, convolution_irradiance, lift_negative_irradiance};
pub use direct::direct_irradiance;
pub use heightfield::{Heightfield, MAX_HEIGHTFIELD_SIDE};

use crate::metrics::relative_l2;
use crate::optics::{fresnel_transmittance, refract};
use crate::params::{ParamError, check_coefficient, check_ior};
use glam::Vec3;

/// The largest [`ConvolutionSettings::kernel_radius`]: a 4097² footprint.
pub const MAX_KERNEL_RADIUS: usize = 2048;

/// The largest [`ConvolutionSettings::exponent`]: a lobe `(L̂t·P̂)ⁿ ≈ exp(−nθ²/2)` about
/// 0.003 rad wide. The bound keeps the per-texel terms `n L̂t,x / L̂t,v` (at most
/// `n / MIN_DOWNWARD_COSINE`) far from overflow.
pub const MAX_EXPONENT: f32 = 1.0e5;

/// Transmitted light whose downward component is smaller carries nothing (see the
/// module documentation).
pub const MIN_DOWNWARD_COSINE: f32 = 1.0e-3;

/// The direction about which the convolution form expands each texel's lobe
/// ([`ConvolutionKernels`]); the expansion is first order in the light's departure
/// from it, so it is accurate while every texel's light leaves close to it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LobeAxis {
    /// The vertical (§4.1): accurate under a high sun only (the light of a sun θ off
    /// zenith leaves every texel about θ/n_water off the vertical).
    Vertical,
    /// The sunlight refracted by the flat surface: only the ripples' own bending must
    /// be small, whatever the sun's height, and flat water stays exact. Beyond the paper.
    #[default]
    RefractedSun,
}

/// How the surface and the floor continue past the heightfield's edges, for both forms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Boundary {
    /// A pool whose four walls are mirrors for the light in the water: light that would
    /// land past a wall lands mirrored inside. The surface is continued by its mirror
    /// image across each wall (the walls lie on the texel edges), which is what the
    /// mirrored impulses of [`ripples`] make, and the transmitted directions are
    /// mirrored with it. Energy is conserved; under a tilted sun the floor is darker
    /// along the wall the light comes from (its shadow) and brighter along the other.
    #[default]
    Mirror,
    /// A patch that tiles the plane (an FFT ocean): the surface repeats.
    Periodic,
}

impl Boundary {
    /// Texels in one period of the extended surface along a side of `texels`.
    pub fn period(self, texels: usize) -> usize {
        match self {
            Boundary::Mirror => 2 * texels,
            Boundary::Periodic => texels,
        }
    }

    /// The texel the extended surface shows at index `index` (any integer) along a
    /// side of `texels`, and whether it is seen mirrored.
    pub fn fold(self, index: isize, texels: usize) -> (usize, bool) {
        let folded = index.rem_euclid(self.period(texels) as isize) as usize;
        if folded < texels { (folded, false) } else { (2 * texels - 1 - folded, true) }
    }
}

/// The model's parameters, shared by both forms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConvolutionSettings {
    /// Index of refraction of the water (`n_t`; air is 1).
    pub ior: f32,
    /// The direction the sunlight travels (`L̂i`), y up, so its y is ≤ 0; any length.
    pub sun_direction: Vec3,
    /// `L_s`: the sun's irradiance on a plane facing it (lux or W/m²).
    pub sun_irradiance: f32,
    /// `d`: depth of the floor below the surface's rest level (m).
    pub depth: f32,
    /// `a`: the Gaussian forward-scattering lobe `exp(−a(1 − (L̂t·P̂)²))` of the direct
    /// form; its angular width is about `1/√(2a)` rad. 0: no lobe.
    pub scattering: f32,
    /// `n`: the exponentiated cosine `(L̂t·P̂)ⁿ` that stands for the lobe in the
    /// convolution form. `n = 2a` matches the Gaussian near its axis
    /// (`cⁿ = (c²)^{n/2} ≈ exp(−(n/2)(1 − c²))`). From 0 to [`MAX_EXPONENT`].
    pub exponent: f32,
    /// `ε`: extinction coefficient of the water (1/m).
    pub extinction: f32,
    /// `r`: both forms integrate over the `(2r + 1)²` texels around a floor point; 3 is
    /// the paper's 7 × 7 kernel. May exceed the heightfield (the extended surface is
    /// summed as often as the footprint covers it). At most [`MAX_KERNEL_RADIUS`].
    pub kernel_radius: usize,
    /// How the surface continues past its edges.
    pub boundary: Boundary,
    /// The convolution form's expansion axis (the direct form has none).
    pub lobe_axis: LobeAxis,
}

impl Default for ConvolutionSettings {
    fn default() -> Self {
        Self {
            ior: 1.333,
            sun_direction: Vec3::NEG_Y,
            sun_irradiance: 1.0,
            depth: 1.0,
            scattering: 50.0,
            exponent: 100.0,
            extinction: 0.1,
            kernel_radius: 3,
            boundary: Boundary::Mirror,
            lobe_axis: LobeAxis::RefractedSun,
        }
    }
}

impl ConvolutionSettings {
    /// Checks every value: an IOR below 1 or not finite; a sun direction that is zero,
    /// not finite or points upwards; a negative or non-finite irradiance, scattering,
    /// extinction or exponent, or an exponent above [`MAX_EXPONENT`]; a depth that is not
    /// a finite length > 0; a kernel radius above [`MAX_KERNEL_RADIUS`].
    pub fn validate(&self) -> Result<(), ParamError> {
        check_ior(self.ior)?;
        let sun = self.sun_direction;
        if !sun.is_finite() || sun == Vec3::ZERO || sun.y > 0.0 {
            let expected = "a finite, non-zero direction pointing down (y ≤ 0)";
            return Err(ParamError::OutOfRange { name: "sun direction y", value: sun.y, expected });
        }
        check_coefficient("sun irradiance", self.sun_irradiance)?;
        if !(self.depth.is_finite() && self.depth > 0.0) {
            return Err(ParamError::OutOfRange { name: "pool depth", value: self.depth, expected: "a finite length > 0 (m)" });
        }
        check_coefficient("scattering a", self.scattering)?;
        check_coefficient("extinction ε", self.extinction)?;
        if !(self.exponent.is_finite() && (0.0..=MAX_EXPONENT).contains(&self.exponent)) {
            let expected = "a number from 0 to 100000";
            return Err(ParamError::OutOfRange { name: "cosine exponent n", value: self.exponent, expected });
        }
        if self.kernel_radius > MAX_KERNEL_RADIUS {
            let (value, expected) = (self.kernel_radius as f32, "at most 2048 texels");
            return Err(ParamError::OutOfRange { name: "kernel radius", value, expected });
        }
        Ok(())
    }

    /// The frame `[e₁, e₂, D]` the convolution form expands the lobe in: the axis `D`
    /// ([`LobeAxis`], pointing down) and two unit vectors completing it, `e₁` in the
    /// plane of `D` and x (the vertical's frame is `[x, z, −y]`).
    pub fn lobe_frame(&self) -> [glam::DVec3; 3] {
        let axis = match self.lobe_axis {
            LobeAxis::Vertical => Vec3::NEG_Y,
            LobeAxis::RefractedSun => refract(self.sun_unit(), Vec3::Y, 1.0 / self.ior).direction().filter(|d| d.y < 0.0).unwrap_or(Vec3::NEG_Y),
        };
        let axis = axis.as_dvec3().normalize();
        let e1 = (glam::DVec3::X - axis.x * axis).normalize();
        [e1, axis.cross(e1), axis]
    }

    /// The unit direction of the sunlight (also for directions whose squared length
    /// overflows).
    pub fn sun_unit(&self) -> Vec3 {
        let sun = self.sun_direction;
        (sun / sun.abs().max_element()).normalize_or(Vec3::NEG_Y)
    }
}

/// The light one texel sends into the water (§4.2, passes 1 to 4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransmittedLight {
    /// `L_s T(θi) cos θi`: the flux entering the water per unit area. 0 where the sun
    /// meets the facet from behind or the light leaves nearly horizontally.
    pub flux: f32,
    /// `L̂t` (eq. 1), a unit vector pointing down; straight down where `flux` is 0.
    pub direction: Vec3,
}

/// The transmitted light of every texel, row-major, with normals by
/// [`Heightfield::normal`]. Errors: invalid settings, or a height at or below the floor.
pub fn transmitted_light(heightfield: &Heightfield, settings: &ConvolutionSettings) -> Result<Vec<TransmittedLight>, ParamError> {
    check_inputs(heightfield, settings)?;
    let sun = settings.sun_unit();
    let eta = 1.0 / settings.ior;
    let (columns, rows) = (heightfield.columns(), heightfield.rows());
    let texels = (0..rows).flat_map(|row| (0..columns).map(move |column| (column, row)));
    let light = texels.map(|(column, row)| {
        let normal = heightfield.normal(column, row, settings.boundary);
        let cos_i = -sun.dot(normal);
        let dark = TransmittedLight { flux: 0.0, direction: Vec3::NEG_Y };
        if cos_i <= 0.0 {
            return dark;
        }
        match refract(sun, normal, eta).direction() {
            Some(direction) if -direction.y >= MIN_DOWNWARD_COSINE => {
                TransmittedLight { flux: settings.sun_irradiance * fresnel_transmittance(cos_i, eta) * cos_i, direction }
            }
            _ => dark,
        }
    });
    Ok(light.collect())
}

/// How far the convolution form is from the direct integral: the relative L2
/// difference `‖E_conv − E_direct‖₂ / ‖E_direct‖₂` over the floor (0 when both are dark).
pub fn convolution_error(heightfield: &Heightfield, settings: &ConvolutionSettings) -> Result<f32, ParamError> {
    let direct = direct_irradiance(heightfield, settings)?;
    let convolution = convolution_irradiance(heightfield, settings)?;
    Ok(relative_l2(&convolution, &direct))
}

/// Valid settings, and a surface everywhere above the floor (`d + h > 0`).
fn check_inputs(heightfield: &Heightfield, settings: &ConvolutionSettings) -> Result<(), ParamError> {
    settings.validate()?;
    let lowest = heightfield.heights().iter().copied().fold(f32::INFINITY, f32::min);
    if lowest as f64 + settings.depth as f64 > 0.0 {
        Ok(())
    } else {
        let expected = "above the pool floor (greater than −depth)";
        Err(ParamError::OutOfRange { name: "lowest surface height", value: lowest, expected })
    }
}
