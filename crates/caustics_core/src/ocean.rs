//! An animated ocean patch by Tessendorf's FFT method ("Simulating Ocean Water",
//! SIGGRAPH course notes, 2001; equation numbers below are that text's): a random
//! field of waves with the Phillips spectrum, moved by the dispersion relation of
//! deep (or depth-limited) water and summed by inverse FFTs into heights, exact
//! spectral slopes and optional choppy displacement, with the exact normals of the
//! displaced surface. The patch tiles seamlessly. Deterministic for a seed.
//!
//! ```
//! use caustics_core::ocean::{OceanSettings, OceanSpectrum};
//! let mut spectrum = OceanSpectrum::new(&OceanSettings::default()).unwrap();
//! let mut surface = spectrum.evaluate(0.0);
//! spectrum.evaluate_into(0.5, &mut surface); // reuses every buffer
//! let mesh = surface.mesh(); // (N + 1)² vertices centred on the origin, y up
//! assert_eq!(mesh.positions().len(), 65 * 65);
//! ```

use crate::mesh::TriMesh;
use crate::params::{ParamError, check_finite};
use crate::rng::Pcg32;
use glam::{Vec2, Vec3};
use rustfft::{Fft, FftPlanner};
use std::f32::consts::{PI, TAU};
use std::sync::Arc;

/// The complex type of the spectra ([`OceanSpectrum::height_spectrum`]).
pub use rustfft::num_complex::Complex32;

/// Gravity (m/s²).
pub const GRAVITY: f32 = 9.81;

/// The largest resolution [`OceanSettings::validate`] accepts.
pub const MAX_RESOLUTION: usize = 4096;

/// No displacement, slope or height may exceed this bound (m): far beyond any sea, and
/// with the patch (at most [`crate::mesh::MAX_COORDINATE`] across) still within the
/// coordinates a mesh may have. [`OceanSpectrum::new`] refuses settings whose waves
/// could.
const MAX_MAGNITUDE: f64 = 1e11;

/// What an ocean patch looks like.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OceanSettings {
    /// Grid points per side, a power of two from 2 to [`MAX_RESOLUTION`] (the FFT size).
    pub resolution: usize,
    /// Side of the square patch (m); the patch repeats with this period.
    pub size: f32,
    /// Wind speed V (m/s): the largest waves are L = V²/g long (eq. 40). Zero: a flat sea.
    pub wind_speed: f32,
    /// Wind direction ŵ in the xz plane (x, z); any length but zero.
    pub wind_direction: Vec2,
    /// Phillips constant A (eq. 40): the height scale (m² for heights in metres).
    pub amplitude: f32,
    /// Choppy-wave factor λ (eq. 44): 0 gives rounded sines, about 1 sharp crests;
    /// too large and the surface folds over itself.
    pub choppiness: f32,
    /// Waves shorter than about this length l (m) are damped by exp(−k²l²) (eq. 41).
    pub small_wave_cutoff: f32,
    /// Water depth D (m) for the depth-limited dispersion ω² = g k tanh(k D) (eq. 32);
    /// `None` is deep water, ω² = g k (eq. 31). Shallow water slows the long waves.
    pub depth: Option<f32>,
    /// Seed of the random amplitudes (eq. 42): the same seed gives the same sea.
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
            depth: None,
            seed: 1,
        }
    }
}

fn check_non_negative(name: &'static str, value: f32, expected: &'static str) -> Result<(), ParamError> {
    if value.is_finite() && value >= 0.0 { Ok(()) } else { Err(ParamError::OutOfRange { name, value, expected }) }
}

fn check_positive(name: &'static str, value: f32, expected: &'static str) -> Result<(), ParamError> {
    if value.is_finite() && value > 0.0 { Ok(()) } else { Err(ParamError::OutOfRange { name, value, expected }) }
}

impl OceanSettings {
    /// Checks every value: a resolution that is not a power of two from 2 to
    /// [`MAX_RESOLUTION`], a size or depth that is not a finite length > 0, a negative
    /// or non-finite speed, amplitude, choppiness or cutoff, and a zero or non-finite
    /// wind direction are errors naming the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.resolution < 2 || !self.resolution.is_power_of_two() || self.resolution > MAX_RESOLUTION {
            let expected = "a power of two from 2 to 4096";
            return Err(ParamError::OutOfRange { name: "ocean resolution", value: self.resolution as f32, expected });
        }
        check_positive("ocean size", self.size, "a finite length > 0 (m)")?;
        if self.size > crate::mesh::MAX_COORDINATE {
            return Err(ParamError::OutOfRange { name: "ocean size", value: self.size, expected: "at most 1e12 m" });
        }
        check_non_negative("wind speed", self.wind_speed, "a finite speed ≥ 0 (m/s)")?;
        check_finite("wind direction x", self.wind_direction.x)?;
        check_finite("wind direction z", self.wind_direction.y)?;
        if self.wind_direction == Vec2::ZERO {
            let expected = "a non-zero direction";
            return Err(ParamError::OutOfRange { name: "wind direction length", value: 0.0, expected });
        }
        check_non_negative("ocean amplitude", self.amplitude, "a finite number ≥ 0")?;
        check_non_negative("choppiness", self.choppiness, "a finite factor ≥ 0")?;
        check_non_negative("small-wave cutoff", self.small_wave_cutoff, "a finite length ≥ 0 (m)")?;
        if let Some(depth) = self.depth {
            check_positive("ocean depth", depth, "a finite depth > 0 (m), or None for deep water")?;
        }
        Ok(())
    }

    /// The unit wind direction ŵ (also for directions whose squared length overflows).
    pub fn wind_unit(&self) -> Vec2 {
        let w = self.wind_direction;
        (w / w.abs().max_element()).normalize_or(Vec2::X)
    }

    /// The Phillips spectrum with small-wave damping at wave vector `k` (rad/m):
    /// P(k) = A exp(−1/(kL)²) / k⁴ |k̂·ŵ|² · exp(−k²l²), L = V²/g (eqs. 40 and 41).
    /// Zero at k = 0 and without wind.
    pub fn phillips(&self, k: Vec2) -> f32 {
        // In f64: k⁴ and (kL)² neither underflow nor overflow for any f32 input.
        let (kx, kz) = (k.x as f64, k.y as f64);
        let k2 = kx * kx + kz * kz;
        let speed = self.wind_speed as f64;
        let big_l = speed * speed / GRAVITY as f64;
        if k2 == 0.0 || big_l == 0.0 || self.amplitude == 0.0 {
            return 0.0;
        }
        let wind = self.wind_unit();
        let cos = (kx * wind.x as f64 + kz * wind.y as f64) / k2.sqrt();
        let l = self.small_wave_cutoff as f64;
        let damping = (-k2 * l * l).exp();
        let p = self.amplitude as f64 * (-1.0 / (k2 * big_l * big_l)).exp() / (k2 * k2) * cos * cos * damping;
        p as f32
    }

    /// The angular frequency ω (rad/s) of a wave of wave number `k` (rad/m):
    /// ω² = g k in deep water (eq. 31), ω² = g k tanh(k D) at depth D (eq. 32).
    pub fn dispersion(&self, k: f32) -> f32 {
        let deep = GRAVITY * k;
        match self.depth {
            Some(depth) => (deep * (k * depth).tanh()).sqrt(),
            None => deep.sqrt(),
        }
    }

    /// The wave vector of grid frequency (i, j): k = 2π (i − N/2, j − N/2) / size (eq. 36).
    pub fn wave_vector(&self, i: usize, j: usize) -> Vec2 {
        let half = (self.resolution / 2) as f32;
        Vec2::new(i as f32 - half, j as f32 - half) * (2.0 * PI / self.size)
    }
}

/// The surface at one time on the N × N grid, row-major (x fastest): per point the
/// displacement from its rest position ([`Self::rest_position`]) — (λDx, h, λDz) — and
/// the unit normal of the displaced surface there.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OceanSurface {
    /// Grid points per side (N).
    pub resolution: usize,
    /// Side of the square patch (m).
    pub size: f32,
    /// Per point, the displacement (λDx, h, λDz) from its rest position (m).
    pub displacement: Vec<Vec3>,
    /// Per point, the unit normal of the displaced surface.
    pub normals: Vec<Vec3>,
}

/// Buffers reused by [`OceanSpectrum::evaluate_into`].
#[derive(Clone, Debug, Default)]
struct Workspace {
    fields: [Vec<Complex32>; 4],
    transposed: Vec<Complex32>,
    scratch: Vec<Complex32>,
}

/// The wave field of a patch: the random amplitudes h̃₀(k) (eq. 42), their
/// frequencies, and the FFT plan (made once, reused by every evaluation).
#[derive(Clone)]
pub struct OceanSpectrum {
    settings: OceanSettings,
    /// h̃₀(k) per grid frequency, and h̃₀*(−k) beside it.
    h0: Vec<(Complex32, Complex32)>,
    omega: Vec<f32>,
    /// An upper bound of |h|, |∇h|, λ|D| and λ|∂D| over the patch and all time (m).
    bound: f32,
    fft: Arc<dyn Fft<f32>>,
    work: Workspace,
}

impl std::fmt::Debug for OceanSpectrum {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OceanSpectrum").field("settings", &self.settings).finish_non_exhaustive()
    }
}

/// A standard complex Gaussian pair (ξr, ξi) by Box–Muller.
fn gaussian(rng: &mut Pcg32) -> Complex32 {
    let u = rng.next_f32().max(1e-7);
    let v = rng.next_f32();
    let r = (-2.0 * u.ln()).sqrt();
    Complex32::new(r * (TAU * v).cos(), r * (TAU * v).sin())
}

impl OceanSpectrum {
    /// Validates the settings and draws the wave field: h̃₀(k) = (ξr + iξi) √(P(k)/2)
    /// (eq. 42) with Gaussian ξ from the seed. Settings whose waves would not stay
    /// finite (an amplitude or choppiness near `f32`'s limits) are an error too.
    pub fn new(settings: &OceanSettings) -> Result<Self, ParamError> {
        settings.validate()?;
        let n = settings.resolution;
        let draws: Vec<Complex32> = (0..n * n).map(|i| gaussian(&mut Pcg32::for_photon(settings.seed, 0, i as u64))).collect();
        let mut h0 = Vec::with_capacity(n * n);
        let mut omega = Vec::with_capacity(n * n);
        // |h|, |∇h|, |D| and |∂D| are at most Σ (|h̃₀(k)| + |h̃₀(−k)|)(1 + k)(1 + k).
        let mut bound = 0.0f64;
        for j in 0..n {
            for i in 0..n {
                let k = settings.wave_vector(i, j);
                // The Nyquist row and column have no −k partner on the grid (−k aliases
                // to a different wave vector): left empty, so that every field is
                // exactly Hermitian (real in space).
                let nyquist = i == 0 || j == 0;
                let amp = |k: Vec2, draw: Complex32| {
                    if nyquist { Complex32::ZERO } else { draw * (settings.phillips(k) * 0.5).sqrt() }
                };
                // −k on the grid: index (N − i) mod N.
                let (mi, mj) = ((n - i) % n, (n - j) % n);
                let here = amp(k, draws[j * n + i]);
                let opposite = amp(-k, draws[mj * n + mi]).conj();
                let silent = here == Complex32::ZERO && opposite == Complex32::ZERO;
                let weight = (1.0 + k.length() as f64).powi(2);
                bound += (here.norm() as f64 + opposite.norm() as f64) * weight;
                h0.push((here, opposite));
                omega.push(if silent { 0.0 } else { settings.dispersion(k.length()) });
            }
        }
        bound *= settings.choppiness.max(1.0) as f64;
        if bound.is_nan() || bound >= MAX_MAGNITUDE {
            return Err(ParamError::OutOfRange {
                name: "ocean wave height bound",
                value: bound as f32,
                expected: "below 1e11 m: lower the amplitude, the choppiness or the wind, or shrink the patch",
            });
        }
        let fft = FftPlanner::new().plan_fft_inverse(n);
        Ok(Self { settings: *settings, h0, omega, bound: bound as f32, fft, work: Workspace::default() })
    }

    /// The settings the wave field was drawn from.
    pub fn settings(&self) -> &OceanSettings {
        &self.settings
    }

    /// An upper bound of the waves' height and choppy displacement (m), for all time:
    /// the surface stays within this distance of its rest plane in every direction.
    pub fn height_bound(&self) -> f32 {
        self.bound
    }

    /// Per grid frequency, row-major: h̃₀(k) and h̃₀*(−k) as (re, im, re, im), and ω
    /// (0 for a silent mode) — what a GPU evaluation of eq. 43 reads.
    pub fn modes(&self) -> impl ExactSizeIterator<Item = ([f32; 4], f32)> + '_ {
        self.h0.iter().zip(&self.omega).map(|((a, b), &omega)| ([a.re, a.im, b.re, b.im], omega))
    }

    /// The height spectrum at time `t` (s): h̃(k, t) = h̃₀(k) e^{iωt} + h̃₀*(−k) e^{−iωt}
    /// (eq. 43), row-major on the grid of [`OceanSettings::wave_vector`]. It is
    /// Hermitian, h̃(−k, t) = h̃*(k, t), so the height h(x, t) = Σₖ h̃(k, t) e^{ik·x}
    /// (eq. 35, x from the patch's centre) is real.
    pub fn height_spectrum(&self, t: f32) -> Vec<Complex32> {
        (0..self.h0.len()).map(|idx| self.mode(idx, t)).collect()
    }

    #[inline]
    fn mode(&self, idx: usize, t: f32) -> Complex32 {
        let (a, b) = self.h0[idx];
        if self.omega[idx] == 0.0 {
            return a + b;
        }
        // The phase in f64, so that long running times keep their precision.
        let phase = (self.omega[idx] as f64 * t as f64).rem_euclid(std::f64::consts::TAU) as f32;
        let rotation = Complex32::from_polar(1.0, phase);
        a * rotation + b * rotation.conj()
    }

    /// The surface at time `t` (s). Allocates its buffers; see [`Self::evaluate_into`]
    /// for a per-frame loop.
    pub fn evaluate(&self, t: f32) -> OceanSurface {
        let mut surface = OceanSurface::default();
        self.evaluate_with(t, &mut Workspace::default(), &mut surface);
        surface
    }

    /// The surface at time `t` (s) written into `surface`, reusing its buffers and the
    /// spectrum's: no allocation after the first call.
    pub fn evaluate_into(&mut self, t: f32, surface: &mut OceanSurface) {
        let mut work = std::mem::take(&mut self.work);
        self.evaluate_with(t, &mut work, surface);
        self.work = work;
    }

    /// Sums the spectrum by inverse FFTs into the height h, its slope ∇h = Σ i k h̃ e^{ik·x}
    /// (eq. 37), the choppy displacement D = Σ −i k̂ h̃ e^{ik·x} (eq. 44) and D's
    /// derivatives, and from them the exact normal of the displaced surface
    /// x + λD(x), h(x): ∂/∂z × ∂/∂x of it (for λ = 0, (−∂h/∂x, 1, −∂h/∂z) normalised).
    fn evaluate_with(&self, t: f32, work: &mut Workspace, out: &mut OceanSurface) {
        let settings = &self.settings;
        let n = settings.resolution;
        let chop = settings.choppiness;
        // Two real fields share each complex transform as a + i·b (both Hermitian).
        let fields = if chop == 0.0 { 2 } else { 4 };
        for field in &mut work.fields[..fields] {
            field.clear();
            field.resize(n * n, Complex32::ZERO);
        }
        let i = Complex32::i();
        for mz in 0..n {
            for mx in 0..n {
                let idx = mz * n + mx;
                let k = settings.wave_vector(mx, mz);
                // e^{ik·x} with x from the patch's centre is (−1)^{mx+mz} e^{2πi m·n/N} (−1)^{nx+nz}.
                let centre = if (mx + mz) % 2 == 0 { 1.0 } else { -1.0 };
                let h = self.mode(idx, t) * centre;
                let unit = k.normalize_or_zero();
                // ∂/∂x is a factor i kx; D is −i k̂ h̃, so ∂Dx/∂x = kx² / k h̃ and so on.
                work.fields[0][idx] = h + i * (i * k.x * h);
                work.fields[1][idx] = i * k.y * h + i * (-i * unit.x * h);
                if fields == 4 {
                    work.fields[2][idx] = -i * unit.y * h + i * (unit.x * k.x * h);
                    work.fields[3][idx] = unit.y * k.y * h + i * (unit.x * k.y * h);
                }
            }
        }
        for field in &mut work.fields[..fields] {
            self.inverse_2d(field, &mut work.transposed, &mut work.scratch);
        }
        out.resolution = n;
        out.size = settings.size;
        out.displacement.clear();
        out.normals.clear();
        for z in 0..n {
            for x in 0..n {
                // The transforms leave their results transposed: (x, z) at x·N + z.
                let at = x * n + z;
                let sign = if (x + z) % 2 == 0 { 1.0 } else { -1.0 };
                let value = |f: usize| work.fields[f][at] * sign;
                let (h, dhdx) = (value(0).re, value(0).im);
                let (dhdz, dx) = (value(1).re, value(1).im);
                let (dz, dxx, dzz, dxz) = if fields == 4 { (value(2).re, value(2).im, value(3).re, value(3).im) } else { (0.0, 0.0, 0.0, 0.0) };
                let along_x = Vec3::new(1.0 + chop * dxx, dhdx, chop * dxz);
                let along_z = Vec3::new(chop * dxz, dhdz, 1.0 + chop * dzz);
                out.displacement.push(Vec3::new(chop * dx, h, chop * dz));
                out.normals.push(along_z.cross(along_x).normalize_or(Vec3::Y));
            }
        }
    }

    /// In-place inverse 2D FFT, rows then columns; the result is left transposed in
    /// `field` (column i's values at i·N..).
    fn inverse_2d(&self, field: &mut [Complex32], transposed: &mut Vec<Complex32>, scratch: &mut Vec<Complex32>) {
        let n = self.settings.resolution;
        scratch.resize(self.fft.get_inplace_scratch_len(), Complex32::ZERO);
        self.fft.process_with_scratch(field, scratch);
        transposed.clear();
        transposed.extend((0..n * n).map(|at| field[(at % n) * n + at / n]));
        self.fft.process_with_scratch(transposed, scratch);
        field.copy_from_slice(transposed);
    }
}

impl OceanSurface {
    /// Rest position of grid point (i, j): the patch centred on the origin, y = 0, its
    /// points `size / N` apart.
    pub fn rest_position(&self, i: usize, j: usize) -> Vec3 {
        let step = self.size / self.resolution as f32;
        Vec3::new(-0.5 * self.size + i as f32 * step, 0.0, -0.5 * self.size + j as f32 * step)
    }

    /// Position and normal of vertex (i, j) of the (N + 1)² grid (i, j ≤ N): row and
    /// column N repeat 0 one patch over, so that copies of the patch tile without a seam.
    #[inline]
    pub fn vertex(&self, i: usize, j: usize) -> (Vec3, Vec3) {
        let n = self.resolution;
        let idx = (j % n) * n + (i % n);
        (self.rest_position(i, j) + self.displacement[idx], self.normals[idx])
    }

    /// Positions and normals of the (N + 1)² vertices, row-major (x fastest); see
    /// [`Self::vertex`].
    pub fn vertices(&self) -> (Vec<Vec3>, Vec<Vec3>) {
        let n = self.resolution;
        (0..=n).flat_map(|j| (0..=n).map(move |i| self.vertex(i, j))).unzip()
    }

    /// The triangles of [`Self::vertices`]' grid, front faces up (+y), the same
    /// split as [`TriMesh::heightfield`].
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let n = self.resolution as u32;
        let stride = n + 1;
        (0..n).flat_map(|j| (0..n).map(move |i| j * stride + i)).flat_map(|p| [[p, p + stride, p + 1], [p + 1, p + stride, p + stride + 1]]).collect()
    }

    /// The patch as a mesh: (N + 1)² vertices centred on the origin in the xz plane,
    /// y up, normals from the spectral slopes.
    pub fn mesh(&self) -> TriMesh {
        let (positions, normals) = self.vertices();
        // Finite by OceanSpectrum::new's bound; normals are unit (Y where degenerate).
        TriMesh::new(positions, normals, self.triangles()).expect("an ocean surface is finite with unit normals")
    }
}
