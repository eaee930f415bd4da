//! Light shafts at a fixed cost per eye ray: the caustic beams' scattering source
//! deposited once per build on a grid over a medium's box, then each eye ray marched
//! through the grid in a fixed number of steps, as Bevy's volumetric fog marches its
//! shadow map. [`in_scattered_radiance`](super::in_scattered_radiance), the exact
//! per-volume integral of §3.5, stays as its twin.
//!
//! §3.5's radiance is `L = ∫ σₛ p(θ) E_beam(x) e^{−σₜ dₛ(x)} e^{−σₜ dₑ} dt` along the
//! eye ray. The factor `S(x) = E_beam e^{−σₜ dₛ}` does not depend on the eye: each
//! cell of the grid holds its mean over the cell, `∫_cell S dV / V_cell`, and the
//! beams' mean direction there for the phase function. The deposit samples every
//! volume on a lattice as fine as the cells (its caustic triangles, §3.3, at a
//! regular series of depths, each split into equal sub-triangles), weighting each
//! sample by the volume it stands for and spreading it over the eight cells around it:
//! `∫ E_beam dV` over a beam is its flux times its length, which the deposit keeps
//! exactly however thin the beam. A sample's direction, which only aims the phase
//! function, goes to one cell, the lowest of its eight, and each cell's direction
//! gathers the eight cells below it ([`BeamGrid::gather_directions`]): the sum over
//! the samples that lit the cell, at three adds a sample where a spread took
//! twenty-four. The march samples the grid trilinearly.

use super::medium::MediumBox;
use super::{CausticVolume, VolumeSettings};
use crate::optics::henyey_greenstein;
use glam::{UVec3, Vec3};

/// The most depth steps of one volume's deposit.
pub const MAX_DEPOSIT_STEPS: u32 = 1024;
/// The most sub-triangles along a caustic triangle's side in the deposit.
pub const MAX_DEPOSIT_SPLIT: u32 = 64;

/// The grid's cells along each axis of a medium's box: `longest` along its longest
/// side, proportionally fewer (at least 2) along the others, so that cells are about
/// cubes.
pub fn grid_size(medium: &MediumBox, longest: u32) -> UVec3 {
    let m = medium.world_from_local.matrix3;
    let extent = Vec3::new(m.x_axis.length(), m.y_axis.length(), m.z_axis.length());
    let longest = longest.max(2) as f32;
    let size = (extent / extent.max_element() * longest).round().max(Vec3::splat(2.0));
    if size.is_finite() { size.as_uvec3() } else { UVec3::splat(2) }
}

/// The smallest world edge of a cell of a `size` grid over `medium`'s box, and a
/// cell's world volume.
pub fn cell_of(medium: &MediumBox, size: UVec3) -> (f32, f32) {
    let m = medium.world_from_local.matrix3;
    let edge = Vec3::new(m.x_axis.length(), m.y_axis.length(), m.z_axis.length()) / size.as_vec3();
    (edge.min_element(), m.determinant().abs() / (size.x * size.y * size.z) as f32)
}

/// How many depth steps one volume's deposit takes: enough that samples along its
/// longest ray lie at most `spacing` apart.
pub fn deposit_steps(volume: &CausticVolume, spacing: f32) -> u32 {
    let longest_ray = (0..3)
        .map(|i| Vec3::new(volume.ray_x[i], 1.0, volume.ray_z[i]).length())
        .fold(1.0f32, f32::max);
    let steps = (volume.depth * longest_ray / spacing).ceil();
    if steps.is_finite() { (steps as u32).clamp(1, MAX_DEPOSIT_STEPS) } else { 1 }
}

/// The local x and z of the caustic triangle's corners at the middle of depth step
/// `step` of `steps`, that depth α, and the step's thickness in α.
pub fn deposit_slice(volume: &CausticVolume, steps: u32, step: u32) -> (Vec3, Vec3, f32, f32) {
    let d_alpha = volume.depth / steps as f32;
    let alpha = (step as f32 + 0.5) * d_alpha;
    (volume.vertex_x + alpha * volume.ray_x, volume.vertex_z + alpha * volume.ray_z, alpha, d_alpha)
}

/// How many sub-triangles to a side every caustic triangle of one volume's deposit is
/// split into, so that their centroids lie at most `spacing` apart at the wider end
/// (the corners move linearly with depth, so the sides are longest at one end). One
/// split for the whole beam lays its samples on one lattice, which the GPU shares
/// among a workgroup's invocations however thin the beam.
pub fn deposit_split(volume: &CausticVolume, spacing: f32) -> u32 {
    let longest = |alpha: f32| {
        let (x, z) = (volume.vertex_x + alpha * volume.ray_x, volume.vertex_z + alpha * volume.ray_z);
        let side = |i: usize, j: usize| (x[i] - x[j]).hypot(z[i] - z[j]);
        side(0, 1).max(side(1, 2)).max(side(2, 0))
    };
    let split = (longest(0.0).max(longest(volume.depth)) / spacing).ceil();
    if split.is_finite() { (split as u32).clamp(1, MAX_DEPOSIT_SPLIT) } else { 1 }
}

/// Sample `k` of the `split²` of a caustic triangle with corners `(x, z)`: the local
/// x and z of one sub-triangle's centroid, and the sub-triangle's area.
pub fn deposit_sample(x: Vec3, z: Vec3, split: u32, k: u32) -> (f32, f32, f32) {
    let (a, b) = (k / split, k % split);
    let n = split as f32;
    // The split² sub-triangles: those of a square's lower half (a + b < split) and,
    // mirrored, those of its upper half.
    let (u, w) = if a + b < split {
        ((a as f32 + 1.0 / 3.0) / n, (b as f32 + 1.0 / 3.0) / n)
    } else {
        (((split - 1 - a) as f32 + 2.0 / 3.0) / n, ((split - 1 - b) as f32 + 2.0 / 3.0) / n)
    };
    let (x1, z1, x2, z2) = (x.y - x.x, z.y - z.x, x.z - x.x, z.z - z.x);
    let area = 0.5 * (x1 * z2 - z1 * x2).abs();
    (x.x + u * x1 + w * x2, z.x + u * z1 + w * z2, area / (n * n))
}

/// The steps of a march `length` long through cells whose smallest edge is `cell`:
/// one a cell, from 1 to `max_steps`.
pub fn march_steps(length: f32, cell: f32, max_steps: u32) -> u32 {
    let steps = (length / cell).ceil();
    if steps.is_finite() { (steps as u32).clamp(1, max_steps.max(1)) } else { 1 }
}

/// The caustic beams' scattering source on a grid over one medium's box.
#[derive(Clone, Debug)]
pub struct BeamGrid {
    pub medium: MediumBox,
    pub size: UVec3,
    /// Per cell (x fastest, then y, then z of the box's local frame): the mean of
    /// `colour · E_beam · e^{−σₜ dₛ}` over the cell (linear RGB).
    pub source: Vec<Vec3>,
    /// Per cell, the directions of the beam samples that lit it, summed with the
    /// weight of their source ([`Self::gather_directions`] of `deposited`).
    pub direction: Vec<Vec3>,
    /// Per cell, the directions of the samples whose lowest corner it is.
    deposited: Vec<Vec3>,
}

impl BeamGrid {
    /// An empty grid over `medium`, `longest` cells along its longest side.
    pub fn new(medium: MediumBox, longest: u32) -> Self {
        let size = grid_size(&medium, longest);
        let cells = (size.x * size.y * size.z) as usize;
        Self { medium, size, source: vec![Vec3::ZERO; cells], direction: vec![Vec3::ZERO; cells], deposited: vec![Vec3::ZERO; cells] }
    }

    /// The smallest world edge of a cell, and a cell's world volume.
    pub fn cell(&self) -> (f32, f32) {
        cell_of(&self.medium, self.size)
    }

    /// Adds every volume's beam to the grid, then gathers the directions.
    pub fn deposit_all(&mut self, volumes: &[CausticVolume], settings: &VolumeSettings) {
        for volume in volumes {
            self.deposit(volume, settings);
        }
        self.gather_directions();
    }

    /// Each cell's direction: the sum of those deposited at the eight cells `c − o`,
    /// `o ∈ {0, 1}³`, the lowest corners of every sample that lit it.
    pub fn gather_directions(&mut self) {
        let size = self.size;
        let index = |c: UVec3| ((c.z * size.y + c.y) * size.x + c.x) as usize;
        for z in 0..size.z {
            for y in 0..size.y {
                for x in 0..size.x {
                    let c = UVec3::new(x, y, z);
                    self.direction[index(c)] = (0..8u32)
                        .map(|corner| UVec3::new(corner & 1, (corner >> 1) & 1, corner >> 2))
                        .filter(|&o| c.cmpge(o).all())
                        .map(|o| self.deposited[index(c - o)])
                        .sum();
                }
            }
        }
    }

    /// Adds one volume's beam: every sample of its lattice (its caustic triangle at
    /// [`deposit_steps`] depths, each split into [`deposit_split`]² sub-triangles, the
    /// samples at most a cell apart, where the eight cells' trilinear weights of a
    /// sample still sum evenly over a beam) that lies lit inside it
    /// ([`CausticVolume::sample`]) adds its source times the volume it stands for to
    /// the eight cells around it ([`Self::corners`]), and its direction to the lowest
    /// of them. [`Self::gather_directions`] must follow.
    fn deposit(&mut self, volume: &CausticVolume, settings: &VolumeSettings) {
        let (cell, cell_volume) = self.cell();
        let (steps, split) = (deposit_steps(volume, cell), deposit_split(volume, cell));
        let sigma_t = self.medium.coefficients.extinction();
        let local_from_world = self.medium.world_from_local.inverse();
        for k in 0..steps * split * split {
            let (x, z, alpha, d_alpha) = deposit_slice(volume, steps, k / (split * split));
            let (sx, sz, area) = deposit_sample(x, z, split, k % (split * split));
            let p = volume.origin + volume.axes[0] * sx + volume.axes[1] * alpha + volume.axes[2] * sz;
            let local = local_from_world.transform_point3(p);
            if !(local.abs().max_element() <= 0.5) {
                continue;
            }
            let Some(s) = volume.sample(p, settings) else {
                continue;
            };
            let beam_length = s.ray.length();
            let attenuated = s.plane_irradiance * beam_length * (-sigma_t * s.depth * beam_length).exp();
            let source = volume.color * (attenuated * area * d_alpha / cell_volume);
            if !source.is_finite() {
                continue;
            }
            let corners = self.corners(local);
            for (index, w) in corners {
                self.source[index] += w * source;
            }
            self.deposited[corners[0].0] += s.ray / beam_length * source.element_sum();
        }
    }

    /// The eight cells around a point of the box's unit cube `[−½, ½]³` and their
    /// trilinear weights between cell centres (the outer cells' centres clamp): the
    /// deposit spreads a sample over them (its adjoint, so that a sample's source
    /// is kept whole and a beam finer than a cell leaves no aliasing), the lookup
    /// interpolates from them.
    pub fn corners(&self, local: Vec3) -> [(usize, f32); 8] {
        let size = self.size.as_vec3();
        let q = ((local + 0.5) * size - 0.5).clamp(Vec3::ZERO, size - 1.0);
        let base = q.floor().min(size - 2.0).max(Vec3::ZERO);
        let f = q - base;
        let base = base.as_uvec3();
        std::array::from_fn(|corner| {
            let o = UVec3::new(corner as u32 & 1, (corner as u32 >> 1) & 1, corner as u32 >> 2);
            let c = base + o;
            let w = Vec3::select(o.cmpeq(UVec3::ONE), f, 1.0 - f).element_product();
            (((c.z * self.size.y + c.y) * self.size.x + c.x) as usize, w)
        })
    }

    /// The source and summed direction at a point of the unit cube, interpolated
    /// trilinearly between cell centres (clamped to the outer cells' centres).
    pub fn lookup(&self, local: Vec3) -> (Vec3, Vec3) {
        self.corners(local).iter().fold((Vec3::ZERO, Vec3::ZERO), |(source, direction), &(index, w)| {
            (source + w * self.source[index], direction + w * self.direction[index])
        })
    }

    /// Radiance scattered towards the eye along the eye ray from `eye` to `end`:
    /// midpoint samples of `σₛ p(θ) S(x) e^{−σₜ dₑ}` between where the ray enters and
    /// leaves the medium, `dₑ` measured from the entry (§3.5), one a cell's smallest
    /// edge apart (a coarser march would step over beams a cell wide) but at most
    /// `max_steps`.
    pub fn in_scattered_radiance(&self, eye: Vec3, end: Vec3, max_steps: u32) -> Vec3 {
        let length = (end - eye).length();
        if length.is_nan() || length <= 0.0 || length.is_infinite() {
            return Vec3::ZERO;
        }
        let dir = (end - eye) / length;
        let Some((enter, exit)) = self.medium.clip(eye, dir, length) else {
            return Vec3::ZERO;
        };
        let c = self.medium.coefficients;
        let local_from_world = self.medium.world_from_local.inverse();
        let steps = march_steps(exit - enter, self.cell().0, max_steps);
        let dt = (exit - enter) / steps as f32;
        let mut radiance = Vec3::ZERO;
        for i in 0..steps {
            let t = enter + (i as f32 + 0.5) * dt;
            let (source, direction) = self.lookup(local_from_world.transform_point3(eye + t * dir));
            let beam = direction.normalize_or_zero();
            let phase = henyey_greenstein(beam.dot(-dir), if beam == Vec3::ZERO { 0.0 } else { c.asymmetry });
            radiance += source * (c.scattering * phase * (-c.extinction() * (t - enter)).exp() * dt);
        }
        radiance
    }
}
