//! An animated ocean patch by Tessendorf's FFT method ("Simulating Ocean Water",
//! SIGGRAPH course notes, 2001): a random field of waves with the Phillips spectrum,
//! moved by the deep-water dispersion relation and summed by inverse FFTs into
//! heights, exact spectral slopes (normals) and optional choppy displacement. The
//! patch tiles seamlessly. Deterministic for a seed.

use crate::mesh::TriMesh;
use crate::params::{ParamError, check_coefficient, check_finite};
use crate::rng::Pcg32;
use glam::{Vec2, Vec3};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::f32::consts::{PI, TAU};
use std::sync::Arc;

/// Gravity (m/s²).
pub const GRAVITY: f32 = 9.81;

/// What an ocean patch looks like.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OceanSettings {
    /// Grid points per side, a power of two (the FFT size).
    pub resolution: usize,
    /// Side of the square patch (m).
    pub size: f32,
    /// Wind speed V (m/s): the largest waves are L = V²/g long.
    pub wind_speed: f32,
    /// Wind direction in the xz plane (any length but zero).
    pub wind_direction: Vec2,
    /// Phillips constant A: the height scale.
    pub amplitude: f32,
    /// Choppy-wave factor λ (0: rounded sines; ~1: sharp crests), Tessendorf eq. 44.
    pub choppiness: f32,
    /// Waves shorter than this (m) are suppressed (eq. 41's damping, `l`).
    pub small_wave_cutoff: f32,
    pub seed: u64,
}

impl Default for OceanSettings {
    fn default() -> Self {
        Self {
            resolution: 64,
            size: 32.0,
            wind_speed: 6.0,
            wind_direction: Vec2::X,
            amplitude: 2e-3,
            choppiness: 0.0,
            small_wave_cutoff: 0.05,
            seed: 1,
        }
    }
}

impl OceanSettings {
    /// Checks every value; a resolution that is not a power of two (≥ 2) is an error.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.resolution < 2 || !self.resolution.is_power_of_two() || self.resolution > 4096 {
            let expected = "a power of two from 2 to 4096";
            return Err(ParamError::OutOfRange { name: "ocean resolution", value: self.resolution as f32, expected });
        }
        if !(self.size.is_finite() && self.size > 0.0) {
            return Err(ParamError::OutOfRange { name: "ocean size", value: self.size, expected: "a finite length > 0" });
        }
        check_coefficient("wind speed", self.wind_speed)?;
        check_finite("wind direction x", self.wind_direction.x)?;
        check_finite("wind direction z", self.wind_direction.y)?;
        if self.wind_direction.length_squared() == 0.0 {
            let expected = "a non-zero direction";
            return Err(ParamError::OutOfRange { name: "wind direction length", value: 0.0, expected });
        }
        check_coefficient("ocean amplitude", self.amplitude)?;
        check_coefficient("choppiness", self.choppiness)?;
        check_coefficient("small-wave cutoff", self.small_wave_cutoff)?;
        Ok(())
    }
}

/// The surface at one time: per grid point (row-major, x fastest) the displacement
/// from its rest position and the unit normal.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OceanSurface {
    pub resolution: usize,
    pub size: f32,
    pub displacement: Vec<Vec3>,
    pub normals: Vec<Vec3>,
}

/// The wave field of a patch: the random amplitudes h̃₀(k) (eq. 42) and FFT plans.
pub struct OceanSpectrum {
    settings: OceanSettings,
    /// h̃₀(k) per grid frequency, and h̃₀*(−k) beside it.
    h0: Vec<(Complex32, Complex32)>,
    omega: Vec<f32>,
    fft: Arc<dyn Fft<f32>>,
}

impl std::fmt::Debug for OceanSpectrum {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OceanSpectrum").field("settings", &self.settings).finish_non_exhaustive()
    }
}

impl OceanSpectrum {
    /// Draws the wave field (Gaussian amplitudes from the seed).
    pub fn new(settings: &OceanSettings) -> Result<Self, ParamError> {
        settings.validate()?;
        let n = settings.resolution;
        let wind = settings.wind_direction.normalize();
        let big_l = settings.wind_speed * settings.wind_speed / GRAVITY;
        let phillips = |k: Vec2| -> f32 {
            let k2 = k.length_squared();
            if k2 == 0.0 || big_l == 0.0 {
                return 0.0;
            }
            let cos = k.dot(wind) / k2.sqrt();
            let l = settings.small_wave_cutoff;
            // Eq. 40 with the small-wave damping of eq. 41.
            settings.amplitude * (-1.0 / (k2 * big_l * big_l)).exp() / (k2 * k2) * cos * cos * (-k2 * l * l).exp()
        };
        let gaussian = |rng: &mut Pcg32| {
            // Box–Muller.
            let u = rng.next_f32().max(1e-7);
            let v = rng.next_f32();
            let r = (-2.0 * u.ln()).sqrt();
            Complex32::new(r * (TAU * v).cos(), r * (TAU * v).sin())
        };
        let mut draws = vec![Complex32::ZERO; n * n];
        for (i, d) in draws.iter_mut().enumerate() {
            let mut rng = Pcg32::for_photon(settings.seed, 0, i as u64);
            *d = gaussian(&mut rng);
        }
        let mut h0 = Vec::with_capacity(n * n);
        let mut omega = Vec::with_capacity(n * n);
        for j in 0..n {
            for i in 0..n {
                let k = wave_vector(i, j, n, settings.size);
                // The Nyquist row and column have no −k partner on the grid: left empty,
                // so that every field is exactly Hermitian (real in space).
                let nyquist = i == 0 || j == 0;
                let amp = |k: Vec2, draw: Complex32| if nyquist { Complex32::ZERO } else { draw * (phillips(k) * 0.5).sqrt() };
                // −k on the grid: index (N − i) mod N.
                let (mi, mj) = ((n - i) % n, (n - j) % n);
                let here = amp(k, draws[j * n + i]);
                let opposite = amp(-k, draws[mj * n + mi]).conj();
                h0.push((here, opposite));
                omega.push((GRAVITY * k.length()).sqrt());
            }
        }
        let fft = FftPlanner::new().plan_fft_inverse(n);
        Ok(Self { settings: *settings, h0, omega, fft })
    }

    pub fn settings(&self) -> &OceanSettings {
        &self.settings
    }

    /// The surface at time `t` (s): h̃(k, t) = h̃₀(k) e^{iωt} + h̃₀*(−k) e^{−iωt} (eq. 43),
    /// summed by inverse FFTs into heights, slopes ∇h = Σ i k h̃ (eq. 37) and the choppy
    /// displacement D = Σ −i k̂ h̃ (eq. 44).
    pub fn evaluate(&self, t: f32) -> OceanSurface {
        let n = self.settings.resolution;
        let mut fields = [vec![Complex32::ZERO; n * n], vec![Complex32::ZERO; n * n], vec![Complex32::ZERO; n * n]];
        for j in 0..n {
            for i in 0..n {
                let idx = j * n + i;
                let k = wave_vector(i, j, n, self.settings.size);
                let (a, b) = self.h0[idx];
                let phase = Complex32::from_polar(1.0, self.omega[idx] * t);
                let h = a * phase + b * phase.conj();
                let ik = |c: f32| Complex32::new(0.0, c) * h;
                // Height and the x slope share one complex transform (both are real
                // fields: h + i·∂h/∂x), as do the z slope and the two displacements.
                fields[0][idx] = h + Complex32::i() * ik(k.x);
                let unit = k.normalize_or_zero();
                fields[1][idx] = ik(k.y) + Complex32::i() * ik(-unit.x);
                fields[2][idx] = ik(-unit.y);
            }
        }
        for field in &mut fields {
            self.inverse_2d(field);
        }
        let chop = self.settings.choppiness;
        let mut displacement = Vec::with_capacity(n * n);
        let mut normals = Vec::with_capacity(n * n);
        for j in 0..n {
            for i in 0..n {
                let idx = j * n + i;
                // e^{i k·x} with k centred on zero: (−1)^{i+j} on the plain transform.
                let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
                let (h, dhdx) = (sign * fields[0][idx].re, sign * fields[0][idx].im);
                let (dhdz, dx) = (sign * fields[1][idx].re, sign * fields[1][idx].im);
                let dz = sign * fields[2][idx].re;
                displacement.push(Vec3::new(chop * dx, h, chop * dz));
                normals.push(Vec3::new(-dhdx, 1.0, -dhdz).normalize());
            }
        }
        OceanSurface { resolution: n, size: self.settings.size, displacement, normals }
    }

    fn inverse_2d(&self, field: &mut [Complex32]) {
        let n = self.settings.resolution;
        for row in field.chunks_exact_mut(n) {
            self.fft.process(row);
        }
        let mut column = vec![Complex32::ZERO; n];
        for i in 0..n {
            for j in 0..n {
                column[j] = field[j * n + i];
            }
            self.fft.process(&mut column);
            for j in 0..n {
                field[j * n + i] = column[j];
            }
        }
    }
}

/// k = 2π (i − N/2, j − N/2) / size (eq. 36).
fn wave_vector(i: usize, j: usize, n: usize, size: f32) -> Vec2 {
    let half = (n / 2) as f32;
    Vec2::new(i as f32 - half, j as f32 - half) * (2.0 * PI / size)
}

impl OceanSurface {
    /// Rest position of grid point (i, j): the patch centred on the origin, y = 0.
    pub fn rest_position(&self, i: usize, j: usize) -> Vec3 {
        let step = self.size / self.resolution as f32;
        Vec3::new(-0.5 * self.size + i as f32 * step, 0.0, -0.5 * self.size + j as f32 * step)
    }

    /// Positions and normals of the (N + 1)² vertices of the patch's grid: the last row
    /// and column repeat the first, so that copies tile without a seam.
    pub fn vertices(&self) -> (Vec<Vec3>, Vec<Vec3>) {
        let n = self.resolution;
        let mut positions = Vec::with_capacity((n + 1) * (n + 1));
        let mut normals = Vec::with_capacity((n + 1) * (n + 1));
        for j in 0..=n {
            for i in 0..=n {
                let idx = (j % n) * n + (i % n);
                positions.push(self.rest_position(i, j) + self.displacement[idx]);
                normals.push(self.normals[idx]);
            }
        }
        (positions, normals)
    }

    /// The triangles of [`Self::vertices`]' grid, front faces up.
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let n = self.resolution as u32;
        let stride = n + 1;
        (0..n)
            .flat_map(|j| (0..n).map(move |i| j * stride + i))
            .flat_map(|p| [[p, p + stride, p + 1], [p + 1, p + stride, p + stride + 1]])
            .collect()
    }

    /// The patch as a mesh, normals from the spectral slopes.
    pub fn mesh(&self) -> TriMesh {
        let (positions, normals) = self.vertices();
        TriMesh::new(positions, normals, self.triangles()).expect("spectral normals have y = 1 before normalising")
    }
}
