//! Eq. 2 as the paper's sum of three convolutions (§4.1), by FFT.

use super::heightfield::check_grid;
use super::{Boundary, ConvolutionSettings, Heightfield, MIN_DOWNWARD_COSINE, TransmittedLight, transmitted_light};
use crate::params::ParamError;
use glam::DVec3;
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// The three kernels of §4.1 and the per-texel terms they convolve, in the order
/// `[first, second, axis]`.
///
/// With `d ≫ h`, `P = (Δx, −d, Δz)` for a floor point `(Δx, Δz)` from the texel, and
/// `P̂_v = d/‖P‖`. The lobe is expanded about a unit axis `D` ([`LobeAxis`]) with
/// `e₁, e₂` completing it to an orthonormal frame: writing a texel's light as
/// `L̂t = c (D + t₁e₁ + t₂e₂)` with `c = L̂t·D` and `tᵢ = (L̂t·eᵢ)/c`, to first order in
/// the `tᵢ`, `(L̂t·P̂)ⁿ ≈ cⁿ [(D·P̂)ⁿ + n (D·P̂)ⁿ⁻¹ (t₁ e₁·P̂ + t₂ e₂·P̂)]`. Times eq. 2's
/// `F P̂_v e^{−ε‖P‖}` (`F = L_s T(θi) cos θi`), this splits into the kernels
/// `k = [n (D·P̂)ⁿ⁻¹ e₁·P̂, n (D·P̂)ⁿ⁻¹ e₂·P̂, (D·P̂)ⁿ] P̂_v e^{−ε‖P‖}` and the terms
/// `[t₁, t₂, 1] F / K`, where the normaliser `K = Σ (D·P̂)ⁿ P̂_v` (no extinction)
/// replaces `cⁿ` and `∼` (module documentation). The paper's axis is the vertical
/// (`e₁ = x`, `e₂ = z`, `tᵢ = L̂t,ᵢ/L̂t,v`). All three are scaled by the footprint's
/// largest `(D·P̂)`ⁿ, which cancels in `k/K` and keeps a narrow lobe about a tilted
/// axis from underflowing.
///
/// Behind a mirror wall the light is mirrored, and so is its frame: the terms, dot
/// products with the frame, are the same, and the kernels are those of the mirrored
/// frame — one set per mirror parity ([`Self::mirrored_taps`]). About a tilted axis
/// the tilt kernels `k₁, k₂` do not sum to zero over the footprint as the vertical's
/// do; each is taken less its share `(Σk₁/Σk₀) k₀` (sums without extinction), so that
/// the expansion moves a texel's light without changing how much reaches the floor.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvolutionKernels {
    radius: usize,
    frame: [DVec3; 3],
    /// The taps of the four mirror parities, `x + 2z`, one after the other.
    taps: Vec<[f64; 3]>,
    normaliser: f64,
}

impl ConvolutionKernels {
    /// The kernels for `settings` on texels `cell_size` wide.
    pub fn new(settings: &ConvolutionSettings, cell_size: f32) -> Result<Self, ParamError> {
        settings.validate()?;
        check_grid(1, 1, cell_size)?;
        let (cell, depth) = (cell_size as f64, settings.depth as f64);
        let (exponent, extinction) = (settings.exponent as f64, settings.extinction as f64);
        let frame = settings.lobe_frame();
        let radius = settings.kernel_radius as isize;
        let offsets: Vec<DVec3> =
            (-radius..=radius).flat_map(|dz| (-radius..=radius).map(move |dx| DVec3::new(dx as f64 * cell, -depth, dz as f64 * cell))).collect();
        let nearest = offsets.iter().map(|p| frame[2].dot(*p) / p.length()).fold(f64::MIN_POSITIVE, f64::max);
        let mut normaliser = 0.0;
        for p in &offsets {
            let along = (frame[2].dot(*p) / p.length() / nearest).max(0.0);
            normaliser += along.powf(exponent) * depth / p.length();
        }
        let taps = (0..4)
            .flat_map(|parity| {
                let mirror = DVec3::new(if parity & 1 == 1 { -1.0 } else { 1.0 }, 1.0, if parity & 2 == 2 { -1.0 } else { 1.0 });
                let [e1, e2, axis] = frame.map(|v| v * mirror);
                // `[k₁, k₂, k₀]` at an offset, with and without extinction.
                let tap = |p: &DVec3| {
                    let distance = p.length();
                    let unit = *p / distance;
                    let along = (axis.dot(unit) / nearest).max(0.0);
                    if along == 0.0 {
                        return ([0.0; 3], 1.0);
                    }
                    let slope = if exponent == 0.0 { 0.0 } else { exponent * along.powf(exponent - 1.0) / nearest };
                    let clear = depth / distance;
                    ([slope * e1.dot(unit) * clear, slope * e2.dot(unit) * clear, along.powf(exponent) * clear], (-extinction * distance).exp())
                };
                // Each tilt kernel less its share of the lobe, so that it moves light
                // without adding or removing any (the vertical's are odd: nothing to take).
                let sums = offsets.iter().map(|p| tap(p).0).fold([0.0; 3], |a, k| [a[0] + k[0], a[1] + k[1], a[2] + k[2]]);
                let shares = [sums[0] / sums[2], sums[1] / sums[2]];
                offsets
                    .iter()
                    .map(move |p| {
                        let ([k1, k2, k0], attenuation) = tap(p);
                        [(k1 - shares[0] * k0) * attenuation, (k2 - shares[1] * k0) * attenuation, k0 * attenuation]
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        Ok(Self { radius: settings.kernel_radius, frame, taps, normaliser })
    }

    /// The kernel radius `r`: the kernels have `(2r + 1)²` taps.
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// `k(Δx, Δz)`, row-major over `Δz, Δx ∈ −r..=r` texels (the floor point's offset
    /// from the surface texel), for light seen directly.
    pub fn taps(&self) -> &[[f64; 3]] {
        self.mirrored_taps(false, false)
    }

    /// The taps for light seen mirrored across the walls along x and/or z.
    pub fn mirrored_taps(&self, mirrored_x: bool, mirrored_z: bool) -> &[[f64; 3]] {
        let count = (2 * self.radius + 1).pow(2);
        let parity = mirrored_x as usize + 2 * mirrored_z as usize;
        &self.taps[parity * count..(parity + 1) * count]
    }

    /// `K`, by which every term is divided (see the type's documentation).
    pub fn normaliser(&self) -> f64 {
        self.normaliser
    }

    /// The lobe's frame `[e₁, e₂, D]` for light seen directly.
    pub fn frame(&self) -> [DVec3; 3] {
        self.frame
    }

    /// The functions to be convolved at a texel (§4.2 pass 5), `[t₁, t₂, 1] F / K`; zero
    /// for light that leaves within [`MIN_DOWNWARD_COSINE`] of the axis's normal plane.
    pub fn terms(&self, light: &TransmittedLight) -> [f64; 3] {
        let direction = light.direction.as_dvec3();
        let along = direction.dot(self.frame[2]);
        if light.flux == 0.0 || along < MIN_DOWNWARD_COSINE as f64 {
            return [0.0; 3];
        }
        let scale = light.flux as f64 / self.normaliser;
        [scale * direction.dot(self.frame[0]) / along, scale * direction.dot(self.frame[1]) / along, scale]
    }
}

/// The convolution form for one heightfield size, planned once: the kernels' spectra
/// on the extended surface's period ([`super::Boundary::period`]) and the FFTs.
/// Circular convolution over that period is exactly the footprint sum over the
/// extended surface; a kernel wider than the period wraps onto it. Behind mirror walls
/// each mirror parity of the extended surface is convolved with its own kernels.
pub struct ConvolutionCaustics {
    settings: ConvolutionSettings,
    columns: usize,
    rows: usize,
    cell_size: f32,
    kernels: ConvolutionKernels,
    /// Per mirror parity seen on the extended surface (one without mirrors), per kernel.
    kernel_spectra: Vec<[Vec<Complex64>; 3]>,
    forward: Fft2d,
    inverse: Fft2d,
    term: Vec<Complex64>,
    spectrum: Vec<Complex64>,
}

impl ConvolutionCaustics {
    /// Plans the convolution of `columns × rows` heightfields with texels `cell_size`
    /// wide. Errors: invalid settings or grid.
    pub fn new(settings: &ConvolutionSettings, columns: usize, rows: usize, cell_size: f32) -> Result<Self, ParamError> {
        check_grid(columns, rows, cell_size)?;
        let kernels = ConvolutionKernels::new(settings, cell_size)?;
        let (width, height) = (settings.boundary.period(columns), settings.boundary.period(rows));
        let mut planner = FftPlanner::new();
        let mut forward = Fft2d::new(&mut planner, width, height, rustfft::FftDirection::Forward);
        let inverse = Fft2d::new(&mut planner, width, height, rustfft::FftDirection::Inverse);
        let radius = kernels.radius() as isize;
        let parities = if settings.boundary == Boundary::Mirror { 4 } else { 1 };
        let kernel_spectra = (0..parities)
            .map(|parity| {
                let taps = kernels.mirrored_taps(parity & 1 == 1, parity & 2 == 2);
                std::array::from_fn(|j| {
                    let mut folded = vec![Complex64::ZERO; width * height];
                    let offsets = (-radius..=radius).flat_map(|dz| (-radius..=radius).map(move |dx| (dx, dz)));
                    for ((dx, dz), tap) in offsets.zip(taps) {
                        let x = dx.rem_euclid(width as isize) as usize;
                        let z = dz.rem_euclid(height as isize) as usize;
                        folded[z * width + x].re += tap[j];
                    }
                    forward.process(&mut folded);
                    folded
                })
            })
            .collect();
        let zeros = vec![Complex64::ZERO; width * height];
        Ok(Self { settings: *settings, columns, rows, cell_size, kernels, kernel_spectra, forward, inverse, term: zeros.clone(), spectrum: zeros })
    }

    /// The kernels in use.
    pub fn kernels(&self) -> &ConvolutionKernels {
        &self.kernels
    }

    /// The floor irradiance below every texel centre, row-major, never negative
    /// ([`lift_negative_irradiance`] of [`Self::signed_irradiance`]). Errors: a
    /// heightfield of another size or cell size than planned, or a height at or below
    /// the floor.
    pub fn irradiance(&mut self, heightfield: &Heightfield) -> Result<Vec<f32>, ParamError> {
        let mut irradiance = self.signed_irradiance(heightfield)?;
        lift_negative_irradiance(&mut irradiance, self.columns, self.rows);
        Ok(irradiance)
    }

    /// The three convolutions of §4.1 summed as they are: negative below zero where a
    /// narrow lobe's signed tilt kernels undershoot.
    pub fn signed_irradiance(&mut self, heightfield: &Heightfield) -> Result<Vec<f32>, ParamError> {
        let planned = "the size the convolution was planned for";
        if heightfield.columns() != self.columns || heightfield.rows() != self.rows {
            let value = (heightfield.columns() * heightfield.rows()) as f32;
            return Err(ParamError::OutOfRange { name: "heightfield texels", value, expected: planned });
        }
        if heightfield.cell_size() != self.cell_size {
            return Err(ParamError::OutOfRange { name: "cell size", value: heightfield.cell_size(), expected: planned });
        }
        let light = transmitted_light(heightfield, &self.settings)?;
        let terms: Vec<[f64; 3]> = light.iter().map(|texel| self.kernels.terms(texel)).collect();
        let (width, height) = (self.forward.width, self.forward.height);
        let boundary = self.settings.boundary;
        self.spectrum.fill(Complex64::ZERO);
        for (parity, spectra) in self.kernel_spectra.iter().enumerate() {
            for (j, kernel_spectrum) in spectra.iter().enumerate() {
                for (index, value) in self.term.iter_mut().enumerate() {
                    let (column, mirrored_x) = boundary.fold((index % width) as isize, self.columns);
                    let (row, mirrored_z) = boundary.fold((index / width) as isize, self.rows);
                    let seen = mirrored_x as usize + 2 * mirrored_z as usize == parity;
                    *value = Complex64::new(if seen { terms[row * self.columns + column][j] } else { 0.0 }, 0.0);
                }
                self.forward.process(&mut self.term);
                for ((sum, term), kernel) in self.spectrum.iter_mut().zip(&self.term).zip(kernel_spectrum) {
                    *sum += term * kernel;
                }
            }
        }
        self.inverse.process(&mut self.spectrum);
        let scale = 1.0 / (width * height) as f64;
        let irradiance = (0..self.rows).flat_map(|row| (0..self.columns).map(move |column| row * width + column));
        Ok(irradiance.map(|index| (self.spectrum[index].re * scale) as f32).collect())
    }
}

/// Half-width, in texels, of the square around a texel of negative irradiance from
/// which [`lift_negative_irradiance`] takes the flux to lift it to zero.
pub const LIFT_RADIUS: usize = 5;

/// Makes floor irradiance non-negative without changing its flux. The tilt kernels of
/// §4.1 are signed, so a narrow lobe (a large `n`) undershoots below zero beside a
/// bright focus; clamping alone would add that light. Instead each texel x with a
/// deficit D(x) = max(−E(x), 0) takes it from the positive texels y around it (within
/// [`LIFT_RADIUS`]) in proportion to their irradiance: with S(x) = Σ_y max(E(y), 0)
/// and R(x) = D(x)/S(x), E′(y) = max(E(y), 0)·max(0, 1 − Σ_x R(x)). The neighbourhoods
/// are symmetric, so Σ E′ = Σ E exactly unless a deficit finds no positive neighbour
/// or the deficits round a texel exceed its irradiance; returns the flux (per texel
/// area) so lost. Two gathers: the GPU's `deficit_ratios` and `lift` kernels are this.
pub fn lift_negative_irradiance(irradiance: &mut [f32], columns: usize, rows: usize) -> f64 {
    let window = |c: usize, r: usize| {
        let (c0, c1) = (c.saturating_sub(LIFT_RADIUS), (c + LIFT_RADIUS).min(columns - 1));
        let (r0, r1) = (r.saturating_sub(LIFT_RADIUS), (r + LIFT_RADIUS).min(rows - 1));
        (r0..=r1).flat_map(move |rr| (c0..=c1).map(move |cc| rr * columns + cc))
    };
    let before: f64 = irradiance.iter().map(|&e| e as f64).sum();
    let ratios: Vec<f32> = (0..rows * columns)
        .map(|i| {
            let deficit = (-irradiance[i]).max(0.0);
            if deficit == 0.0 {
                return 0.0;
            }
            let supply: f32 = window(i % columns, i / columns).map(|j| irradiance[j].max(0.0)).sum();
            if supply > 0.0 { deficit / supply } else { 0.0 }
        })
        .collect();
    if ratios.iter().all(|&r| r == 0.0) && irradiance.iter().all(|&e| e >= 0.0) {
        return 0.0;
    }
    let lifted: Vec<f32> = (0..rows * columns)
        .map(|i| {
            let taken: f32 = window(i % columns, i / columns).map(|j| ratios[j]).sum();
            irradiance[i].max(0.0) * (1.0 - taken).max(0.0)
        })
        .collect();
    irradiance.copy_from_slice(&lifted);
    before - irradiance.iter().map(|&e| e as f64).sum::<f64>()
}

/// The floor irradiance by the convolution form; [`ConvolutionCaustics`] plans once
/// for many heightfields of one size.
pub fn convolution_irradiance(heightfield: &Heightfield, settings: &ConvolutionSettings) -> Result<Vec<f32>, ParamError> {
    ConvolutionCaustics::new(settings, heightfield.columns(), heightfield.rows(), heightfield.cell_size())?.irradiance(heightfield)
}

/// An unnormalised 2D FFT of a row-major `width × height` array, in place.
struct Fft2d {
    width: usize,
    height: usize,
    along_rows: Arc<dyn Fft<f64>>,
    along_columns: Arc<dyn Fft<f64>>,
    column: Vec<Complex64>,
    scratch: Vec<Complex64>,
}

impl Fft2d {
    fn new(planner: &mut FftPlanner<f64>, width: usize, height: usize, direction: rustfft::FftDirection) -> Self {
        let along_rows = planner.plan_fft(width, direction);
        let along_columns = planner.plan_fft(height, direction);
        let scratch_len = along_rows.get_inplace_scratch_len().max(along_columns.get_inplace_scratch_len());
        Self { width, height, along_rows, along_columns, column: vec![Complex64::ZERO; height], scratch: vec![Complex64::ZERO; scratch_len] }
    }

    fn process(&mut self, data: &mut [Complex64]) {
        for row in data.chunks_exact_mut(self.width) {
            self.along_rows.process_with_scratch(row, &mut self.scratch);
        }
        for column in 0..self.width {
            for (row, value) in self.column.iter_mut().enumerate() {
                *value = data[row * self.width + column];
            }
            self.along_columns.process_with_scratch(&mut self.column, &mut self.scratch);
            for (row, value) in self.column.iter().enumerate() {
                data[row * self.width + column] = *value;
            }
        }
    }
}
