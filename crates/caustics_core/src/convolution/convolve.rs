//! Eq. 2 as the paper's sum of three convolutions (§4.1), by FFT.

use super::heightfield::check_grid;
use super::{ConvolutionSettings, Heightfield, TransmittedLight, transmitted_light};
use crate::params::ParamError;
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// The three kernels of §4.1 and the per-texel terms they convolve, in the order
/// `[x, z, vertical]` (the paper's `j = x, y, z`).
///
/// With `d ≫ h`, `P = (Δx, −d, Δz)` for a floor point `(Δx, Δz)` from the texel, and
/// `P̂_v = d/‖P‖`. The integrand of eq. 2 with the linearised lobe is
/// `F L̂t,vⁿ [n (L̂t,x/L̂t,v) P̂_vⁿ P̂_x + n (L̂t,z/L̂t,v) P̂_vⁿ P̂_z + P̂_vⁿ⁺¹] e^{−ε‖P‖}`
/// with `F = L_s T(θi) cos θi`; the bracket splits into the kernels
/// `k = [P̂_vⁿ P̂_x, P̂_vⁿ P̂_z, P̂_vⁿ⁺¹] e^{−ε‖P‖}` and the terms
/// `[n L̂t,x/L̂t,v, n L̂t,z/L̂t,v, 1] F / K_v`, where the normaliser
/// `K_v = Σ P̂_vⁿ⁺¹` (no extinction) replaces `L̂t,vⁿ` and `∼` (module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct ConvolutionKernels {
    radius: usize,
    exponent: f64,
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
        let radius = settings.kernel_radius as isize;
        let mut normaliser = 0.0;
        let taps = (-radius..=radius)
            .flat_map(|dz| (-radius..=radius).map(move |dx| (dx, dz)))
            .map(|(dx, dz)| {
                let (x, z) = (dx as f64 * cell, dz as f64 * cell);
                let distance = (x * x + z * z + depth * depth).sqrt();
                let vertical = depth / distance;
                let lobe = vertical.powf(exponent);
                normaliser += lobe * vertical;
                let attenuated = lobe * (-extinction * distance).exp() / distance;
                [attenuated * x, attenuated * z, attenuated * depth]
            })
            .collect();
        Ok(Self { radius: settings.kernel_radius, exponent, taps, normaliser })
    }

    /// The kernel radius `r`: the kernels have `(2r + 1)²` taps.
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// `k(Δx, Δz)` as `[x, z, vertical]`, row-major over `Δz, Δx ∈ −r..=r` texels (the
    /// floor point's offset from the surface texel).
    pub fn taps(&self) -> &[[f64; 3]] {
        &self.taps
    }

    /// `K_v = Σ P̂_vⁿ⁺¹` over the taps, by which every term is divided; ≥ 1 (the centre tap).
    pub fn normaliser(&self) -> f64 {
        self.normaliser
    }

    /// The functions to be convolved at a texel (§4.2 pass 5), `[x, z, vertical]`.
    pub fn terms(&self, light: &TransmittedLight) -> [f64; 3] {
        if light.flux == 0.0 {
            return [0.0; 3];
        }
        let direction = light.direction.as_dvec3();
        let scale = light.flux as f64 / self.normaliser;
        let tilt = self.exponent * scale / -direction.y;
        [tilt * direction.x, tilt * direction.z, scale]
    }
}

/// The convolution form for one heightfield size, planned once: the kernels' spectra
/// on the extended surface's period ([`super::Boundary::period`]) and the FFTs.
/// Circular convolution over that period is exactly the footprint sum over the
/// extended surface; a kernel wider than the period wraps onto it.
pub struct ConvolutionCaustics {
    settings: ConvolutionSettings,
    columns: usize,
    rows: usize,
    cell_size: f32,
    kernels: ConvolutionKernels,
    kernel_spectra: [Vec<Complex64>; 3],
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
        let kernel_spectra = std::array::from_fn(|j| {
            let mut folded = vec![Complex64::ZERO; width * height];
            let offsets = (-radius..=radius).flat_map(|dz| (-radius..=radius).map(move |dx| (dx, dz)));
            for ((dx, dz), tap) in offsets.zip(kernels.taps()) {
                let x = dx.rem_euclid(width as isize) as usize;
                let z = dz.rem_euclid(height as isize) as usize;
                folded[z * width + x].re += tap[j];
            }
            forward.process(&mut folded);
            folded
        });
        let zeros = vec![Complex64::ZERO; width * height];
        Ok(Self {
            settings: *settings,
            columns,
            rows,
            cell_size,
            kernels,
            kernel_spectra,
            forward,
            inverse,
            term: zeros.clone(),
            spectrum: zeros,
        })
    }

    /// The kernels in use.
    pub fn kernels(&self) -> &ConvolutionKernels {
        &self.kernels
    }

    /// The floor irradiance below every texel centre, row-major. Errors: a heightfield
    /// of another size or cell size than planned, or a height at or below the floor.
    pub fn irradiance(&mut self, heightfield: &Heightfield) -> Result<Vec<f32>, ParamError> {
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
        for (j, kernel_spectrum) in self.kernel_spectra.iter().enumerate() {
            for (index, value) in self.term.iter_mut().enumerate() {
                let (column, mirrored_x) = boundary.fold((index % width) as isize, self.columns);
                let (row, mirrored_z) = boundary.fold((index / width) as isize, self.rows);
                let term = terms[row * self.columns + column][j];
                let flipped = (j == 0 && mirrored_x) || (j == 1 && mirrored_z);
                *value = Complex64::new(if flipped { -term } else { term }, 0.0);
            }
            self.forward.process(&mut self.term);
            for ((sum, term), kernel) in self.spectrum.iter_mut().zip(&self.term).zip(kernel_spectrum) {
                *sum += term * kernel;
            }
        }
        self.inverse.process(&mut self.spectrum);
        let scale = 1.0 / (width * height) as f64;
        let irradiance = (0..self.rows).flat_map(|row| (0..self.columns).map(move |column| row * width + column));
        Ok(irradiance.map(|index| (self.spectrum[index].re * scale) as f32).collect())
    }
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
        Self {
            width,
            height,
            along_rows,
            along_columns,
            column: vec![Complex64::ZERO; height],
            scratch: vec![Complex64::ZERO; scratch_len],
        }
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
