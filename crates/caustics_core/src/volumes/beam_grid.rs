//! Light shafts at a fixed cost per eye ray: the caustic beams' scattering source
//! deposited once per build on a grid over a medium's box, then each eye ray marched
//! through the grid in a fixed number of steps, as Bevy's volumetric fog marches its
//! shadow map. [`in_scattered_radiance`](super::in_scattered_radiance), the exact
//! per-volume integral of §3.5, stays as its twin.
//!
//! §3.5's radiance is `L = ∫ σₛ p(θ) E_beam(x) e^{−σₜ dₛ(x)} e^{−σₜ dₑ} dt` along the
//! eye ray. The factor `S(x) = E_beam e^{−σₜ dₛ}` does not depend on the eye: each
//! cell of the grid holds its mean over the cell, `∫_cell S dV / V_cell`, and the
//! beams' mean direction there for the phase function. The deposit splits every
//! volume into thin beams about a cell wide (the sub-triangles of its caustic
//! triangles, §3.3) and samples each where its central ray crosses the grid's layers
//! across the axis it runs most along, one sample a layer in the layer's middle plane,
//! weighting each by the beam volume it stands for and spreading it over the cells
//! around it (four in the middle plane, eight where the beam ends inside a layer):
//! `∫ E_beam dV` over a beam is its flux times its length, which the deposit keeps
//! exactly however thin the beam. A sample's direction, which only aims the phase
//! function, goes to one block of 2 × 2 × 2 cells, the one that holds the lowest of
//! its eight, and each cell's direction gathers the eight blocks below its own
//! ([`BeamGrid::gather_directions`]): the sum over the samples that lit the cell (and
//! some beside it), at three adds a sample where a spread took twenty-four. The march
//! samples the grid trilinearly.
//!
//! A fine generator's beams are far more than the grid's cells: the deposit merges
//! the narrow beams that enter the grid through one cell into a bundle (the moments of
//! their rays across the axis, each ray's own triangle included) and adds the bundle
//! layer by layer over a box of the bundle's mean and spread
//! ([`BeamGrid::deposit_all`]), so that its work past the grid's resolution grows with
//! the cells the beams enter, not with the triangles.

use super::medium::MediumBox;
use super::{CausticVolume, VolumeSettings};
use crate::optics::henyey_greenstein;
use glam::{Affine3A, UVec3, Vec2, Vec3};

/// The most layers one thin beam of the deposit adds to.
pub const MAX_DEPOSIT_LAYERS: u32 = 1024;
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

/// Thin beam `k` of the `split²` a volume's deposit splits it into: the barycentric
/// coordinates of its sub-triangle's centroid in every caustic triangle (the corners
/// move linearly with depth, so the centroid's ray is the same blend of the volume's).
pub fn deposit_barycentric(split: u32, k: u32) -> Vec3 {
    let (a, b) = (k / split, k % split);
    let n = split as f32;
    // The split² sub-triangles: those of a square's lower half (a + b < split) and,
    // mirrored, those of its upper half.
    let (u, w) = if a + b < split {
        ((a as f32 + 1.0 / 3.0) / n, (b as f32 + 1.0 / 3.0) / n)
    } else {
        (((split - 1 - a) as f32 + 2.0 / 3.0) / n, ((split - 1 - b) as f32 + 2.0 / 3.0) / n)
    };
    Vec3::new(1.0 - u - w, u, w)
}

/// The area of `volume`'s caustic triangle at depth α (§3.4's `|A(α)|`).
fn caustic_area(volume: &CausticVolume, alpha: f32) -> f32 {
    let (x, z) = (volume.vertex_x + alpha * volume.ray_x, volume.vertex_z + alpha * volume.ray_z);
    0.5 * ((x.y - x.x) * (z.z - z.x) - (z.y - z.x) * (x.z - x.x)).abs()
}

/// The blend of `volume`'s vertex rays by barycentric weights λ in the coordinates of
/// a grid of `cells` over a box with `local_from_world` (cell centres at whole
/// numbers): the ray at `α = 0`, and how far it moves per unit of α.
fn grid_ray(volume: &CausticVolume, lambda: Vec3, local_from_world: &Affine3A, cells: Vec3) -> (Vec3, Vec3) {
    let origin = volume.origin + volume.axes[0] * lambda.dot(volume.vertex_x) + volume.axes[2] * lambda.dot(volume.vertex_z);
    let ray = volume.axes[0] * lambda.dot(volume.ray_x) + volume.axes[1] + volume.axes[2] * lambda.dot(volume.ray_z);
    ((local_from_world.transform_point3(origin) + 0.5) * cells - 0.5, local_from_world.transform_vector3(ray) * cells)
}

/// One thin beam of a volume's deposit, in the coordinates of a grid whose cell
/// centres lie at whole numbers: the barycentric blend of the volume's rays that is its
/// central ray ([`deposit_barycentric`]), that ray `q(α) = start + α·per_alpha`, the
/// axis it runs most along, and the layers across that axis it passes, `first` and
/// `count`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinBeam {
    /// Barycentric weights of the volume's rays that blend into its central ray.
    pub lambda: Vec3,
    /// The ray at `α = 0`, in grid coordinates.
    pub start: Vec3,
    /// How far the ray moves per unit of `α`, in grid coordinates.
    pub per_alpha: Vec3,
    /// The axis the ray runs most along (0: x, 1: y, 2: z).
    pub axis: usize,
    /// The first layer across `axis` that it passes.
    pub first: i32,
    /// How many layers it passes, at most [`MAX_DEPOSIT_LAYERS`].
    pub count: u32,
}

impl ThinBeam {
    /// Thin beam `k` of `split²` through the grid of `size` cells over a box with
    /// `local_from_world` (the box's unit cube): none where its ray does not move
    /// across the grid or is not finite.
    pub fn new(volume: &CausticVolume, split: u32, k: u32, local_from_world: &Affine3A, size: UVec3) -> Option<Self> {
        let lambda = deposit_barycentric(split, k);
        let cells = size.as_vec3();
        let (start, per_alpha) = grid_ray(volume, lambda, local_from_world, cells);
        let along = per_alpha.abs();
        let axis = if along.x >= along.y && along.x >= along.z {
            0
        } else if along.y >= along.z {
            1
        } else {
            2
        };
        let ends = (start[axis], start[axis] + volume.depth * per_alpha[axis]);
        let (lo, hi) = (ends.0.min(ends.1), ends.0.max(ends.1));
        if !(start.is_finite() && per_alpha.is_finite() && hi > lo) {
            return None;
        }
        let first = (lo + 0.5).floor().max(0.0);
        let last = (hi + 0.5).floor().min(cells[axis] - 1.0);
        let count = (last - first + 1.0).clamp(0.0, MAX_DEPOSIT_LAYERS as f32);
        Some(Self { lambda, start, per_alpha, axis, first: first as i32, count: count as u32 })
    }

    /// Layer `j` of [`Self::count`]: the α in the middle of the part of the beam
    /// inside it, that part's length in α, and its grid point there, moved along the
    /// axis onto the layer's middle plane: across the axis a sample spreads
    /// trilinearly, along it it is binned whole into its layer (where the beam ends
    /// inside the layer too), so it lights only the four cells of its layer around it.
    pub fn layer(&self, depth: f32, j: u32) -> Option<(f32, f32, Vec3)> {
        let layer = (self.first + j as i32) as f32;
        let (a0, a1) = ((layer - 0.5 - self.start[self.axis]) / self.per_alpha[self.axis], (layer + 0.5 - self.start[self.axis]) / self.per_alpha[self.axis]);
        let (whole_lo, whole_hi) = (a0.min(a1), a0.max(a1));
        let (lo, hi) = (whole_lo.max(0.0), whole_hi.min(depth));
        if !(hi > lo) {
            return None;
        }
        let alpha = 0.5 * (lo + hi);
        let mut q = self.start + alpha * self.per_alpha;
        q[self.axis] = layer;
        Some((alpha, hi - lo, q))
    }
}

/// The most beams one bundle of the deposit merges; a cell entered by more deposits
/// them one by one.
pub const MAX_BUNDLE_BEAMS: u32 = 1024;
/// The widest beam a bundle takes: its caustic triangles' sides at most this many
/// cells ([`deposit_split`]).
pub const MAX_BUNDLED_SPLIT: u32 = 6;
/// How far a bundle's light reaches either side of its mean across its axis, at most,
/// in cells.
pub const MAX_BUNDLE_REACH: f32 = 4.0;

/// The weight of cell `i` along one axis (centres at whole numbers) of a bundle's
/// points there: uniform within `reach` of their mean `mean`, each point spread over
/// the two cells around it as a single beam's sample is (the tent between cell
/// centres), so that a bundle of `reach` 0 spreads as one point. Over
/// [`bundle_cells`] the weights sum to one; a cell past the grid's edge gives its
/// weight to the outer cell.
fn bundle_weight(mean: f32, reach: f32, i: i32) -> f32 {
    // ∫ tent from −∞ to x.
    let ramp = |x: f32| match x {
        x if x <= -1.0 => 0.0,
        x if x <= 0.0 => 0.5 * (x + 1.0) * (x + 1.0),
        x if x <= 1.0 => 1.0 - 0.5 * (1.0 - x) * (1.0 - x),
        _ => 1.0,
    };
    let x = mean - i as f32;
    if reach > 1.0e-3 { (ramp(x + reach) - ramp(x - reach)) / (2.0 * reach) } else { (1.0 - x.abs()).max(0.0) }
}

/// The cells, past the grid's edges too, that a bundle's points within `reach` of
/// `mean` may light along one axis.
fn bundle_cells(mean: f32, reach: f32) -> std::ops::RangeInclusive<i32> {
    (mean - reach).floor() as i32..=(mean + reach).floor() as i32 + 1
}

/// One narrow beam as a bundle member ([`BeamGrid::deposit_all`]), in grid
/// coordinates about its bundle's entry cell: `t` counts layers along the beam's axis
/// from the face it enters that cell's layer by, `across` is where its central ray
/// lies there on the two other axes, `slope` how far it moves across a layer.
#[derive(Clone, Copy, Debug)]
struct BundledBeam {
    /// The entry cell's index.
    key: usize,
    /// Which way along which axis it runs (bit `2·axis + forward`) and its colour's
    /// strongest channels (bit `6 + mask`): a bundle merges only beams of one each.
    flags: u32,
    across: Vec2,
    slope: Vec2,
    /// Its caustic triangle's variance across the axis, `x + 2t·y + t²·z`.
    width: Vec3,
    /// Its `t` at the generator and where it ends.
    start: f32,
    end: f32,
    /// Its source per layer, before extinction.
    source: Vec3,
    /// World length of its path per layer.
    length: f32,
    /// Its direction, for the phase function.
    direction: Vec3,
}

/// The narrow beams that enter the grid in one cell: their count, the
/// union of their flags, and the sums of their [`BundledBeam`]s and of the moments
/// that give their spread across the axis at each layer
/// (`Var(across + t·slope)`).
#[derive(Clone, Copy, Debug, Default)]
struct BeamBundle {
    flags: u32,
    count: u32,
    across: Vec2,
    slope: Vec2,
    across_squared: f32,
    across_slope: f32,
    slope_squared: f32,
    start: f32,
    end: f32,
    source: Vec3,
    length: f32,
    direction: Vec3,
}

impl BeamBundle {
    /// Whether its beams go as one: two or more (up to [`MAX_BUNDLE_BEAMS`]) running
    /// one way, of one colour.
    fn merges(&self) -> bool {
        (2..=MAX_BUNDLE_BEAMS).contains(&self.count) && (self.flags & 0x3f).count_ones() == 1 && (self.flags >> 6).count_ones() == 1
    }

    fn add(&mut self, m: &BundledBeam) {
        self.flags |= m.flags;
        self.count += 1;
        self.across += m.across;
        self.slope += m.slope;
        self.across_squared += m.across.length_squared() + m.width.x;
        self.across_slope += m.across.dot(m.slope) + m.width.y;
        self.slope_squared += m.slope.length_squared() + m.width.z;
        self.start += m.start;
        self.end += m.end;
        self.source += m.source;
        self.length += m.length;
        self.direction += m.direction;
    }
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
    /// The medium whose box the grid covers.
    pub medium: MediumBox,
    /// Cells along the box's local x, y and z ([`grid_size`]).
    pub size: UVec3,
    /// Per cell (x fastest, then y, then z of the box's local frame): the mean of
    /// `colour · E_beam · e^{−σₜ dₛ}` over the cell (linear RGB).
    pub source: Vec<Vec3>,
    /// Per cell, the directions of the beam samples that lit it, summed with the
    /// weight of their source ([`Self::gather_directions`] of `deposited`).
    pub direction: Vec<Vec3>,
    /// Per block of 2 × 2 × 2 cells ([`direction_blocks`]), the directions of the
    /// samples whose lowest corner lies in it.
    deposited: Vec<Vec3>,
}

/// The blocks of 2 × 2 × 2 cells (the last ones cut short) that hold a `size` grid's
/// deposited directions: a direction only aims the phase function, and varies across
/// a beam far slower than its light, so that half the resolution keeps the shafts and
/// spares the deposit most of its direction adds.
pub fn direction_blocks(size: UVec3) -> UVec3 {
    (size + 1) / 2
}

/// The index of block `block` among a `size` grid's [`direction_blocks`] (x fastest).
fn block_index(size: UVec3, block: UVec3) -> usize {
    let blocks = direction_blocks(size);
    ((block.z * blocks.y + block.y) * blocks.x + block.x) as usize
}

impl BeamGrid {
    /// An empty grid over `medium`, `longest` cells along its longest side.
    pub fn new(medium: MediumBox, longest: u32) -> Self {
        let size = grid_size(&medium, longest);
        let cells = (size.x * size.y * size.z) as usize;
        let blocks = direction_blocks(size).element_product() as usize;
        Self { medium, size, source: vec![Vec3::ZERO; cells], direction: vec![Vec3::ZERO; cells], deposited: vec![Vec3::ZERO; blocks] }
    }

    /// The smallest world edge of a cell, and a cell's world volume.
    pub fn cell(&self) -> (f32, f32) {
        cell_of(&self.medium, self.size)
    }

    /// Adds every volume's beam to the grid, then gathers the directions: narrow beams
    /// (at most [`MAX_BUNDLED_SPLIT`] cells wide) that enter the grid in the same cell,
    /// running the same way in the same colour, as one bundle ([`BeamBundle`]), the
    /// others one by one. Every such beam is added to its bundle as it is counted; a
    /// bundle that does not merge is dropped and its beams go one by one. Returns how
    /// many beams went into bundles.
    pub fn deposit_all(&mut self, volumes: &[CausticVolume], settings: &VolumeSettings) -> usize {
        let members: Vec<Option<BundledBeam>> = volumes.iter().map(|v| self.bundled_beam(v, settings)).collect();
        let mut bundles = std::collections::BTreeMap::<usize, BeamBundle>::new();
        for m in members.iter().flatten() {
            bundles.entry(m.key).or_default().add(m);
        }
        let mut bundled = 0;
        for (volume, member) in volumes.iter().zip(&members) {
            if member.as_ref().is_some_and(|m| bundles[&m.key].merges()) {
                bundled += 1;
            } else {
                self.deposit(volume, settings);
            }
        }
        for (key, bundle) in bundles.iter().filter(|(_, b)| b.merges()) {
            self.deposit_bundle(*key, bundle);
        }
        self.gather_directions();
        bundled
    }

    /// Adds every volume's beam to the grid one by one (the reference the bundles of
    /// [`Self::deposit_all`] are held to), then gathers the directions.
    pub fn deposit_each(&mut self, volumes: &[CausticVolume], settings: &VolumeSettings) {
        for volume in volumes {
            self.deposit(volume, settings);
        }
        self.gather_directions();
    }

    /// `volume`'s beam as a bundle's member: none where it is wider than
    /// [`MAX_BUNDLED_SPLIT`] cells somewhere, crosses no layer, or is unlit at its
    /// middle. Its source per layer is taken at its middle: constant along the beam
    /// for [`IntensityMode::Conserving`](super::IntensityMode) (the caustic triangle's
    /// flux times the beam's length), up to the magnification cap.
    fn bundled_beam(&self, volume: &CausticVolume, settings: &VolumeSettings) -> Option<BundledBeam> {
        let (cell, cell_volume) = self.cell();
        if deposit_split(volume, cell) > MAX_BUNDLED_SPLIT {
            return None;
        }
        let local_from_world = self.medium.world_from_local.inverse();
        let beam = ThinBeam::new(volume, 1, 0, &local_from_world, self.size).filter(|b| b.count > 0)?;
        let axis = beam.axis;
        let rate = beam.per_alpha[axis].abs();
        let forward = beam.per_alpha[axis] > 0.0;
        let sign = if forward { 1.0 } else { -1.0 };
        let entry = if forward { beam.first } else { beam.first + beam.count as i32 - 1 };
        // Layers counted from the face the beam enters the entry layer by.
        let start = (beam.start[axis] - (entry as f32 - 0.5 * sign)) * sign;
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let slope = Vec2::new(beam.per_alpha[a], beam.per_alpha[b]) / rate;
        let at_start = Vec2::new(beam.start[a], beam.start[b]) - start * slope;
        let cells = self.size.as_vec3();
        let across = (at_start + 0.5 * slope + 0.5).floor().clamp(Vec2::ZERO, Vec2::new(cells[a], cells[b]) - 1.0);
        let alpha = 0.5 * volume.depth;
        let s = volume.sample_on_ray(beam.lambda, alpha, settings)?;
        let beam_length = s.ray.length();
        // `ThinBeam::new` keeps only rays that move across the grid: `rate` is positive.
        let source = volume.color * (s.plane_irradiance * beam_length * caustic_area(volume, alpha) / (rate * cell_volume));
        if !(source.is_finite() && source.element_sum() > 0.0) {
            return None;
        }
        // A beam from far outside the grid goes alone (the GPU sums starts and ends in
        // fixed point).
        let end = start + volume.depth * rate;
        if !(start.abs() <= MAX_DEPOSIT_LAYERS as f32 && end.abs() <= MAX_DEPOSIT_LAYERS as f32) {
            return None;
        }
        let mut cell_at = UVec3::ZERO;
        cell_at[axis] = entry as u32;
        cell_at[a] = across.x as u32;
        cell_at[b] = across.y as u32;
        // The caustic triangle's own spread across the axis: a triangle's variance is
        // the sum of its squared sides over 36, here quadratic in t.
        let corner = |i: usize| {
            let (o, r) = grid_ray(volume, Vec3::AXES[i], &local_from_world, cells);
            let slope = Vec2::new(r[a], r[b]) / rate;
            (Vec2::new(o[a], o[b]) - start * slope, slope)
        };
        let corners = [corner(0), corner(1), corner(2)];
        let mut width = Vec3::ZERO;
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let (da, db) = (corners[i].0 - corners[j].0, corners[i].1 - corners[j].1);
            width += Vec3::new(da.length_squared(), da.dot(db), db.length_squared()) / 36.0;
        }
        let hue = volume.color.cmpge(Vec3::splat(0.5 * volume.color.max_element())).bitmask();
        Some(BundledBeam {
            key: ((cell_at.z * self.size.y + cell_at.y) * self.size.x + cell_at.x) as usize,
            flags: 1 << (2 * axis as u32 + forward as u32) | 1 << (6 + hue),
            across: at_start - across,
            slope,
            width,
            start,
            end,
            source,
            length: beam_length / rate,
            direction: s.ray / beam_length,
        })
    }

    /// Adds a bundle's beams as one: at each layer its source, dimmed along the mean
    /// path, over the cells its members' points cover there (a box with their mean and
    /// spread, [`bundle_weight`], in place of each point's four cells), and its mean
    /// direction to the lowest cell around the mean.
    fn deposit_bundle(&mut self, key: usize, bundle: &BeamBundle) {
        let size = self.size;
        let entry_cell = UVec3::new(key as u32 % size.x, (key as u32 / size.x) % size.y, key as u32 / (size.x * size.y));
        let route = bundle.flags.trailing_zeros();
        let (axis, forward) = ((route / 2) as usize, route % 2 == 1);
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let n = bundle.count as f32;
        let (p, d) = (bundle.across / n, bundle.slope / n);
        let var_p = bundle.across_squared / n - p.length_squared();
        let cov = bundle.across_slope / n - p.dot(d);
        let var_d = bundle.slope_squared / n - d.length_squared();
        let (start, end, length) = (bundle.start / n, bundle.end / n, bundle.length / n);
        let direction = bundle.direction.normalize_or_zero();
        let sigma_t = self.medium.coefficients.extinction();
        let centre = Vec2::new(entry_cell[a] as f32, entry_cell[b] as f32);
        let first = start.max(0.0).floor() as i32;
        let last = (end.ceil() as i32).min(first + MAX_DEPOSIT_LAYERS as i32);
        for k in first..last {
            let layer = entry_cell[axis] as i32 + if forward { k } else { -k };
            if layer < 0 || layer >= size[axis] as i32 {
                break;
            }
            let (lo, hi) = (start.max(k as f32), end.min(k as f32 + 1.0));
            if !(hi > lo) {
                continue;
            }
            let t = 0.5 * (lo + hi);
            let mean = centre + p + d * t;
            if !(mean.cmpge(Vec2::splat(-0.5)).all() && mean.cmple(Vec2::new(size[a] as f32, size[b] as f32) - 0.5).all()) {
                continue;
            }
            let reach = (1.5 * (var_p + 2.0 * t * cov + t * t * var_d).max(0.0)).sqrt().min(MAX_BUNDLE_REACH);
            let source = bundle.source * (-sigma_t * (length * (t - start))).exp() * (hi - lo);
            let mut c = UVec3::ZERO;
            c[axis] = layer as u32;
            let (last_a, last_b) = (size[a] as i32 - 1, size[b] as i32 - 1);
            for i in bundle_cells(mean.x, reach) {
                let w_i = bundle_weight(mean.x, reach, i);
                for j in bundle_cells(mean.y, reach).filter(|_| w_i > 0.0) {
                    (c[a], c[b]) = (i.clamp(0, last_a) as u32, j.clamp(0, last_b) as u32);
                    self.source[((c.z * size.y + c.y) * size.x + c.x) as usize] += w_i * bundle_weight(mean.y, reach, j) * source;
                }
            }
            // The direction to every other block from the one of the first cell lit,
            // whose eight blocks cover those lit: one block where the bundle lights at
            // most three cells across.
            let blocks = |mean: f32, last: i32| {
                let cells = bundle_cells(mean, reach);
                let (lo, hi) = ((*cells.start()).clamp(0, last), (*cells.end()).clamp(0, last));
                (lo / 2..=hi / 2).step_by(2).map(|i| i as u32)
            };
            let share = direction * (source.element_sum() / (blocks(mean.x, last_a).count() * blocks(mean.y, last_b).count()) as f32);
            let mut block = UVec3::ZERO;
            block[axis] = layer as u32 / 2;
            for i in blocks(mean.x, last_a) {
                for j in blocks(mean.y, last_b) {
                    (block[a], block[b]) = (i, j);
                    self.deposited[block_index(size, block)] += share;
                }
            }
        }
    }

    /// The block of [`direction_blocks`] that holds cell `cell` (an index).
    fn block_of(&self, cell: usize) -> usize {
        let size = self.size;
        block_index(size, UVec3::new(cell as u32 % size.x, (cell as u32 / size.x) % size.y, cell as u32 / (size.x * size.y)) / 2)
    }

    /// Each cell's direction: the sum of those deposited in the eight blocks `b − o`,
    /// `o ∈ {0, 1}³`, `b` the cell's block, which hold the lowest corners of every
    /// sample that lit it (and of some beside it).
    pub fn gather_directions(&mut self) {
        let size = self.size;
        for z in 0..size.z {
            for y in 0..size.y {
                for x in 0..size.x {
                    let b = UVec3::new(x, y, z) / 2;
                    self.direction[((z * size.y + y) * size.x + x) as usize] = (0..8u32)
                        .map(|corner| UVec3::new(corner & 1, (corner >> 1) & 1, corner >> 2))
                        .filter(|&o| b.cmpge(o).all())
                        .map(|o| b - o)
                        .map(|d| self.deposited[block_index(size, d)])
                        .sum();
                }
            }
        }
    }

    /// Adds one volume's beam: each of its [`deposit_split`]² thin beams
    /// ([`ThinBeam`]) at every layer it crosses ([`ThinBeam::layer`]), where that
    /// sample is lit ([`CausticVolume::sample_on_ray`]: it lies inside by
    /// construction): its source times the beam volume it stands for (the thin beam's
    /// cross-section in the caustic triangle's plane times the α spent in the layer,
    /// exact for parallel rays: a prism between two parallel planes holds `A·Δα` along
    /// any of its rays) to the cells around it ([`Self::corners_at`]), and its
    /// direction to the lowest of them.
    /// [`Self::gather_directions`] must follow.
    fn deposit(&mut self, volume: &CausticVolume, settings: &VolumeSettings) {
        let (cell, cell_volume) = self.cell();
        let split = deposit_split(volume, cell);
        let sigma_t = self.medium.coefficients.extinction();
        let local_from_world = self.medium.world_from_local.inverse();
        let cells = self.size.as_vec3();
        for k in 0..split * split {
            let Some(beam) = ThinBeam::new(volume, split, k, &local_from_world, self.size) else {
                continue;
            };
            for j in 0..beam.count {
                let Some((alpha, d_alpha, q)) = beam.layer(volume.depth, j) else {
                    continue;
                };
                if !(((q + 0.5) / cells - 0.5).abs().max_element() <= 0.5) {
                    continue;
                }
                let area = caustic_area(volume, alpha) / (split * split) as f32;
                let Some(s) = volume.sample_on_ray(beam.lambda, alpha, settings) else {
                    continue;
                };
                let beam_length = s.ray.length();
                let attenuated = s.plane_irradiance * beam_length * (-sigma_t * (s.depth * beam_length)).exp();
                let source = volume.color * attenuated * (area * d_alpha / cell_volume);
                if !source.is_finite() {
                    continue;
                }
                let corners = self.corners_at(q);
                for (index, w) in corners {
                    self.source[index] += w * source;
                }
                let block = self.block_of(corners[0].0);
                self.deposited[block] += s.ray / beam_length * source.element_sum();
            }
        }
    }

    /// The eight cells around a point of the box's unit cube `[−½, ½]³` and their
    /// trilinear weights between cell centres (the outer cells' centres clamp): the
    /// deposit spreads a sample over them (its adjoint, so that a sample's source
    /// is kept whole and a beam finer than a cell leaves no aliasing), the lookup
    /// interpolates from them.
    pub fn corners(&self, local: Vec3) -> [(usize, f32); 8] {
        self.corners_at((local + 0.5) * self.size.as_vec3() - 0.5)
    }

    /// [`Self::corners`] of a point in grid coordinates (cell centres at whole numbers):
    /// a point on a layer's middle plane has four of weight zero.
    pub fn corners_at(&self, q: Vec3) -> [(usize, f32); 8] {
        let size = self.size.as_vec3();
        let q = q.clamp(Vec3::ZERO, size - 1.0);
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
        self.corners(local)
            .iter()
            .fold((Vec3::ZERO, Vec3::ZERO), |(source, direction), &(index, w)| (source + w * self.source[index], direction + w * self.direction[index]))
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
            radiance += source * (-c.extinction() * (t - enter)).exp() * (c.scattering * phase * dt);
        }
        radiance
    }
}

#[cfg(test)]
mod tests {
    use super::{bundle_cells, bundle_weight};

    #[test]
    fn a_bundles_weights_sum_to_one_and_narrow_to_one_points() {
        for (mean, reach) in [(3.3, 0.0), (3.3, 0.7), (3.5, 2.5), (3.0, 1.0), (0.2, 1.4), (-0.4, 0.9)] {
            let weights: Vec<(i32, f32)> = bundle_cells(mean, reach).map(|i| (i, bundle_weight(mean, reach, i))).collect();
            let sum: f32 = weights.iter().map(|(_, w)| w).sum();
            let centre: f32 = weights.iter().map(|(i, w)| *i as f32 * w).sum();
            assert!((sum - 1.0).abs() < 1e-5 && (centre - mean).abs() < 1e-4, "{mean} ± {reach}: {weights:?}");
            assert!(
                bundle_weight(mean, reach, bundle_cells(mean, reach).start() - 1) == 0.0
                    && bundle_weight(mean, reach, bundle_cells(mean, reach).end() + 1) == 0.0
            );
        }
        // No spread: the two cells around the point, as a single beam's sample.
        let lit: Vec<(i32, f32)> = bundle_cells(3.3, 0.0).map(|i| (i, bundle_weight(3.3, 0.0, i))).filter(|(_, w)| *w > 0.0).collect();
        assert!(lit.len() == 2 && (lit[0].0, lit[1].0) == (3, 4) && (lit[0].1 - 0.7).abs() < 1e-5, "{lit:?}");
    }
}
