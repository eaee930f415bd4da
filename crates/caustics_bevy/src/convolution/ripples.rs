//! Main world: the pool's water, simulated from its impulses and written into its mesh.

use super::{DropPebble, PoolRipples};
use crate::CausticTechnique;
use crate::components::CausticGenerator;
use crate::cpu_time::timed;
use crate::gpu_budget::{CausticGpuBudget, largest_binding, mib};
use crate::grid_mesh::{grid_mesh, is_grid, rewrite_grid};
use crate::mesh_vertices::MovesOnGpu;
use crate::technique::CausticTechniqueChoice;
use bevy::camera::primitives::Aabb;
use bevy::camera::visibility::NoAutoAabb;
use bevy::platform::collections::HashSet;
use bevy::prelude::*;
use bevy::render::renderer::RenderDevice;
use caustics_core::convolution::ripples::{Impulse, PoolRipples as Ripples};
use caustics_core::convolution::{Boundary, ConvolutionKernels, Heightfield};
use std::sync::Arc;

/// The simulated water of a [`PoolRipples`]: its live impulses and the surface they
/// made this frame (pool coordinates: x and z from 0 to the pool's size), on the grid
/// its settings fit in ([`PoolRipples::fitted`]).
#[derive(Component, Clone, Debug)]
pub struct PoolSurface {
    settings: PoolRipples,
    ripples: Ripples,
    heightfield: Heightfield,
    /// `heightfield` is flat: evaluated with no live impulse.
    flat: bool,
    kernels: PoolKernels,
}

/// The three kernels of §4.1 for a pool's depth, exponent, extinction and texels and
/// for the sunlight it refracts, as the GPU reads them
/// (`caustics_core::convolution::ConvolutionKernels`, expanded about the refracted sun).
#[derive(Clone, Debug)]
pub struct PoolKernels {
    /// `[k₁, k₂, k₀, 0]` row-major over `Δz, Δx ∈ −r..=r`, for each mirror parity
    /// (`x + 2z`) in turn.
    pub taps: Arc<Vec<Vec4>>,
    /// `K`, by which every texel's terms are divided.
    pub normaliser: f64,
    /// The lobe's frame `[e₁, e₂, D]` in pool space.
    pub frame: [Vec3; 3],
    /// The water's index of refraction and the sunlight's direction in pool space they
    /// were made for.
    pub aimed: (f32, Vec3),
}

impl PoolKernels {
    /// The kernels for `pool`'s settings under sunlight along `sun` (pool space) into
    /// water of index `ior`.
    pub fn new(pool: &PoolRipples, ior: f32, sun: Vec3) -> Result<Self, String> {
        let settings = pool.light(ior, sun, 1.0);
        let kernels = ConvolutionKernels::new(&settings, pool.cell_size).map_err(|e| e.to_string())?;
        let taps = (0..4)
            .flat_map(|parity| kernels.mirrored_taps(parity & 1 == 1, parity & 2 == 2).to_vec())
            .map(|t| Vec4::new(t[0] as f32, t[1] as f32, t[2] as f32, 0.0))
            .collect();
        let frame = kernels.frame().map(|v| Vec3::new(v.x as f32, v.y as f32, v.z as f32));
        Ok(Self { taps: Arc::new(taps), normaliser: kernels.normaliser(), frame, aimed: (ior, sun) })
    }

    /// The kernels for the same pool under other light.
    fn reaimed(&self, pool: &PoolRipples) -> Result<Self, String> {
        Self::new(pool, self.aimed.0, self.aimed.1)
    }
}

impl PoolSurface {
    /// The pool's settings as the water runs them: the component's, with the grid
    /// lowered to what the GPU and the budget hold ([`PoolRipples::fitted`]).
    pub fn settings(&self) -> &PoolRipples {
        &self.settings
    }

    /// The impulses and wave settings.
    pub fn ripples(&self) -> &Ripples {
        &self.ripples
    }

    /// The heights at the texel centres as the CPU last evaluated them: this frame's
    /// while the water moves on the CPU. While it moves on the GPU (the module's text)
    /// the CPU evaluates none, and these are still water's; `ripples().heightfield(time)`
    /// evaluates any instant.
    pub fn heightfield(&self) -> &Heightfield {
        &self.heightfield
    }

    /// The water's mesh at `time` as the pool draws it (on the CPU or the GPU): a
    /// vertex over each texel centre, centred on the pool; or why there is none.
    pub fn mesh_at(&self, time: f32) -> Result<Mesh, String> {
        self.ripples.heightfield(time).map(|heightfield| new_grid_mesh(&heightfield)).map_err(|e| e.to_string())
    }

    /// The convolution kernels.
    pub fn kernels(&self) -> &PoolKernels {
        &self.kernels
    }

    /// Aims the kernels at new light (`PoolKernels::new`) if it is not the light they
    /// were made for.
    pub fn aim_kernels(&mut self, ior: f32, sun: Vec3) -> Result<(), String> {
        if self.kernels.aimed != (ior, sun) {
            self.kernels = PoolKernels::new(&self.settings, ior, sun)?;
        }
        Ok(())
    }

    /// A still pool for `pool`'s (fitted) settings, or why there is none.
    fn new(pool: &PoolRipples) -> Result<Self, String> {
        let (columns, rows) = (pool.columns as usize, pool.rows as usize);
        let ripples = Ripples::new(columns, rows, pool.cell_size, pool.waves()).map_err(|e| e.to_string())?;
        let heightfield = Heightfield::flat(columns, rows, pool.cell_size).map_err(|e| e.to_string())?;
        Ok(Self { settings: pool.clone(), ripples, heightfield, flat: true, kernels: PoolKernels::new(pool, 1.333, Vec3::NEG_Y)? })
    }
}

/// Starts a pool's water with impulses dropped before now: `impulses` as the pool's
/// clock read `time` (a saved frame's `caustics_core::view::PoolView`), each dropped
/// as long before this frame as it was before `time`, so that the water is what it
/// was then. Taken off once the pool's water has them; an impulse the pool refuses
/// (outside it) is reported and left out.
#[derive(Component, Clone, Debug, Default)]
pub struct PoolImpulses {
    /// The impulses, each with its drop time on the clock of `time`.
    pub impulses: Vec<Impulse>,
    /// The clock's reading that this frame stands for, in seconds.
    pub time: f32,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).main;
    app.add_systems(
        Update,
        (
            // Only in frames where a pool's settings change or go.
            timed(&cpu, configure_pools).run_if(timed(&cpu, any_match_filter::<Changed<PoolRipples>>.or_else(any_component_removed::<PoolRipples>))),
            timed(&cpu, replay_impulses),
            timed(&cpu, drop_pebbles),
            timed(&cpu, animate_pools),
        )
            .chain(),
    );
}

/// Gives each pool with [`PoolImpulses`] and water its impulses.
fn replay_impulses(mut commands: Commands, mut pools: Query<(Entity, &PoolImpulses, &mut PoolSurface)>, time: Res<Time>) {
    let now = time.elapsed_secs();
    for (entity, replay, mut surface) in &mut pools {
        for impulse in &replay.impulses {
            let at = now - (replay.time - impulse.time);
            if let Err(e) = surface.ripples.drop_pebble(impulse.position, impulse.strength, at) {
                warn!("bevy_caustics: an impulse of the pool {entity} is left out: {e}");
            }
        }
        commands.entity(entity).remove::<PoolImpulses>();
    }
}

/// Pools whose `PoolRipples` went away: their surface, mesh and whether it moved on
/// the GPU.
type Orphans = (Entity, &'static PoolSurface, Option<&'static Mesh3d>, Has<MovesOnGpu>);
/// What sizes a pool's water: the device's limits, the budget, the clock, the meshes.
type PoolResources<'w> = (Option<Res<'w, RenderDevice>>, Res<'w, CausticGpuBudget>, Res<'w, Time>, ResMut<'w, Assets<Mesh>>);

/// Starts the water of pools that are new or whose grid or waves changed (a still
/// pool), and redraws the kernels of those whose light changed (the water keeps
/// moving); a grid too large for the GPU or the budget is lowered
/// ([`PoolRipples::fitted`]), and invalid settings are reported once per entity and the
/// pool has no water until fixed.
fn configure_pools(
    mut commands: Commands,
    mut pools: Query<(Entity, &PoolRipples, Option<&mut PoolSurface>), Changed<PoolRipples>>,
    orphans: Query<Orphans, Without<PoolRipples>>,
    mut removed: RemovedComponents<PoolRipples>,
    mut warned: Local<HashSet<Entity>>,
    (device, budget, time, mut meshes): PoolResources,
) {
    let largest = device.as_deref().map_or(u64::MAX, largest_binding);
    for entity in removed.read() {
        warned.remove(&entity);
    }
    // Water that moved on the GPU stays as it is now, in the mesh asset.
    for (entity, surface, mesh3d, on_gpu) in &orphans {
        if on_gpu {
            if let (Ok(heightfield), Some(mut mesh)) = (surface.ripples.heightfield(time.elapsed_secs()), mesh3d.and_then(|m| meshes.get_mut(&m.0))) {
                write_in_place(&mut mesh, &heightfield);
            }
            commands.entity(entity).remove::<(MovesOnGpu, NoAutoAabb)>();
        }
        commands.entity(entity).remove::<PoolSurface>();
    }
    for (entity, asked, surface) in &mut pools {
        let pool = &asked.fitted(largest, budget.bytes);
        if pool != asked {
            warn!(
                "bevy_caustics: PoolRipples on {entity}: {}×{} texels with a kernel radius of {} do not fit this GPU or CausticGpuBudget ({}); \
                 its water runs at {}×{} texels of {} m with a radius of {}",
                asked.columns,
                asked.rows,
                asked.kernel_radius,
                mib(budget.bytes),
                pool.columns,
                pool.rows,
                pool.cell_size,
                pool.kernel_radius
            );
        }
        let same_water = surface.as_ref().is_some_and(|s| {
            let hf = &s.heightfield;
            *s.ripples.settings() == pool.waves() && (hf.columns(), hf.rows(), hf.cell_size()) == (pool.columns as usize, pool.rows as usize, pool.cell_size)
        });
        let made = match surface {
            Some(mut surface) if same_water => surface.kernels.reaimed(pool).map(|kernels| {
                surface.kernels = kernels;
                surface.settings = pool.clone();
            }),
            _ => PoolSurface::new(pool).map(|surface| {
                commands.entity(entity).insert(surface);
            }),
        };
        match made {
            Ok(()) => {
                warned.remove(&entity);
            }
            Err(reason) => {
                if warned.insert(entity) {
                    warn!("bevy_caustics: PoolRipples on {entity} is skipped: {reason}");
                }
                commands.entity(entity).remove::<PoolSurface>();
            }
        }
    }
}

/// Starts an impulse for each [`DropPebble`] in the first pool whose water lies under it.
fn drop_pebbles(mut pebbles: MessageReader<DropPebble>, mut pools: Query<(Entity, &GlobalTransform, &mut PoolSurface)>, time: Res<Time>) {
    for pebble in pebbles.read() {
        let landed = pools.iter_mut().find_map(|(entity, transform, surface)| {
            let local = transform.affine().inverse().transform_point3(pebble.position);
            let size = surface.settings.size();
            let at = Vec2::new(local.x, local.z) + 0.5 * size;
            let inside = at.cmpge(Vec2::ZERO).all() && at.cmple(size).all();
            inside.then_some((entity, at, surface))
        });
        let Some((entity, at, mut surface)) = landed else {
            debug!("bevy_caustics: a pebble at {} fell outside every pool", pebble.position);
            continue;
        };
        let at = caustics_core::glam::Vec2::new(at.x, at.y);
        if let Err(e) = surface.ripples.drop_pebble(at, pebble.strength, time.elapsed_secs()) {
            warn!("bevy_caustics: a pebble in the pool {entity} is ignored: {e}");
        }
    }
}

/// Present when a render app moves pools' water on the GPU (`water.rs`).
#[derive(Resource)]
pub(super) struct WaterOnGpu;

/// The components [`animate_pools`] reads.
type Pools<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        &'static mut PoolSurface,
        Option<&'static Mesh3d>,
        Option<&'static CausticTechniqueChoice>,
        Has<CausticGenerator>,
        Has<MovesOnGpu>,
        Option<&'static Aabb>,
    ),
>;

/// The half-height of the box given to water moved on the GPU whose waves reach
/// `bound` (m), if its box of half-height `current` no longer fits them: the box grows
/// to [`BOX_ROOM`] times the waves and shrinks once they fill less than a quarter of
/// it, so that the box (and what reads it: culling, the plans' change detection)
/// changes a few times in a shower, not every frame.
fn water_box(bound: f32, current: Option<f32>) -> Option<f32> {
    match current {
        Some(half) if bound <= half && bound * 4.0 * BOX_ROOM >= half => None,
        _ => Some(bound * BOX_ROOM),
    }
}

/// How much higher than its waves the box of water moved on the GPU is made.
const BOX_ROOM: f32 = 1.5;

/// Whether a pool's water can move on the GPU: a render app, and no technique that
/// reads the pool's triangles on the CPU (the caustic maps; a generator whose technique
/// is not chosen yet waits a frame).
fn moves_on_gpu(gpu: bool, choice: Option<&CausticTechniqueChoice>, generator: bool) -> bool {
    gpu && (!generator || choice.is_some_and(|c| matches!(c.technique(), CausticTechnique::WarpedVolumes | CausticTechnique::Convolution)))
}

/// Removes faded impulses and, while the water moves, has the render world write it
/// into the pool's mesh on the GPU ([`MovesOnGpu`], with an `Aabb` that holds every
/// wave the live impulses can raise) or evaluates it here and rewrites the mesh asset.
/// Still water costs nothing; when water that moved on the GPU stills, the asset is
/// written once, so that Bevy uploads the still surface over the last waves.
fn animate_pools(mut commands: Commands, time: Res<Time>, gpu: Option<Res<WaterOnGpu>>, mut pools: Pools, mut meshes: ResMut<Assets<Mesh>>) {
    let now = time.elapsed_secs();
    for (entity, mut surface, mesh3d, choice, generator, was_on_gpu, aabb) in &mut pools {
        let surface = &mut *surface;
        surface.ripples.remove_expired(now);
        let moving = !surface.ripples.impulses().is_empty();
        let has_grid = mesh3d.and_then(|m| meshes.get(&m.0)).is_some_and(|mesh| {
            let (indices, vertices) = grid_counts(&surface.heightfield);
            is_grid(mesh, indices, vertices)
        });
        if moving && has_grid && moves_on_gpu(gpu.is_some(), choice, generator) {
            let ripples = &surface.ripples;
            let bound = ripples.impulses().iter().map(|i| ripples.impulse_bound(i, now)).sum::<f64>().min(f32::MAX as f64) as f32;
            let half = 0.5 * surface.settings.size();
            let current = aabb.filter(|_| was_on_gpu).map(|b| b.half_extents.y);
            let mut water = commands.entity(entity);
            if let Some(height) = water_box(bound, current) {
                water.insert(Aabb::from_min_max(Vec3::new(-half.x, -height, -half.y), Vec3::new(half.x, height, half.y)));
            }
            if !was_on_gpu {
                water.insert((MovesOnGpu, NoAutoAabb));
            }
            continue;
        }
        if was_on_gpu {
            commands.entity(entity).remove::<(MovesOnGpu, NoAutoAabb)>();
        }
        if !moving && surface.flat && has_grid && !was_on_gpu {
            continue;
        }
        surface.heightfield = match surface.ripples.heightfield(now) {
            Ok(heightfield) => {
                surface.flat = !moving;
                heightfield
            }
            Err(e) => {
                warn!("bevy_caustics: the water of the pool {entity} is stilled: {e}");
                if let Ok(still) = PoolSurface::new(&surface.settings.clone()) {
                    *surface = still;
                }
                continue;
            }
        };
        if let Some(mut mesh) = mesh3d.and_then(|m| meshes.get_mut(&m.0))
            && write_in_place(&mut mesh, &surface.heightfield)
        {
            continue;
        }
        commands.entity(entity).insert(Mesh3d(meshes.add(new_grid_mesh(&surface.heightfield))));
    }
}

/// The texels `(column, row)`, row-major.
fn texels(heightfield: &Heightfield) -> impl Iterator<Item = (usize, usize)> + use<> {
    let columns = heightfield.columns();
    (0..heightfield.rows()).flat_map(move |row| (0..columns).map(move |column| (column, row)))
}

/// The mesh vertex over each texel centre, centred on the pool.
fn positions(heightfield: &Heightfield) -> impl Iterator<Item = [f32; 3]> + '_ {
    let cell = heightfield.cell_size();
    let half = 0.5 * Vec2::new(heightfield.columns() as f32, heightfield.rows() as f32) * cell;
    texels(heightfield).map(move |(column, row)| {
        let (x, z) = ((column as f32 + 0.5) * cell - half.x, (row as f32 + 0.5) * cell - half.y);
        [x, heightfield.height(column, row), z]
    })
}

/// The surface normal at each texel centre.
fn normals(heightfield: &Heightfield) -> impl Iterator<Item = [f32; 3]> + '_ {
    texels(heightfield).map(|(column, row)| heightfield.normal(column, row, Boundary::Mirror).to_array())
}

/// The index and vertex counts of the pool's grid mesh.
fn grid_counts(heightfield: &Heightfield) -> (usize, usize) {
    let (columns, rows) = (heightfield.columns(), heightfield.rows());
    (6 * (columns - 1) * (rows - 1), columns * rows)
}

/// Rewrites the positions and normals of `mesh` if it is this pool's grid; false, with
/// nothing changed, if not.
fn write_in_place(mesh: &mut Mesh, heightfield: &Heightfield) -> bool {
    rewrite_grid(mesh, grid_counts(heightfield), positions(heightfield), normals(heightfield))
}

/// Two triangles between each four neighbouring texel centres, wound counter-clockwise
/// seen from above.
fn grid_indices(heightfield: &Heightfield) -> Vec<u32> {
    let (columns, rows) = (heightfield.columns() as u32, heightfield.rows() as u32);
    let quads = (0..rows.saturating_sub(1)).flat_map(|r| (0..columns.saturating_sub(1)).map(move |c| (c, r)));
    quads
        .flat_map(|(c, r)| {
            let at = |c: u32, r: u32| r * columns + c;
            [at(c, r), at(c, r + 1), at(c + 1, r), at(c + 1, r), at(c, r + 1), at(c + 1, r + 1)]
        })
        .collect()
}

/// A new grid mesh of the surface: positions, normals, UVs over [0, 1]² and indices.
fn new_grid_mesh(heightfield: &Heightfield) -> Mesh {
    let (columns, rows) = (heightfield.columns(), heightfield.rows());
    let uv = |i: usize, n: usize| (i as f32 + 0.5) / n as f32;
    let uvs = texels(heightfield).map(|(c, r)| [uv(c, columns), uv(r, rows)]).collect();
    grid_mesh(positions(heightfield).collect(), normals(heightfield).collect(), uvs, grid_indices(heightfield))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_water_box_changes_only_when_outgrown_or_far_too_large() {
        assert_eq!(water_box(0.1, None), Some(0.1 * BOX_ROOM));
        let half = 0.1 * BOX_ROOM;
        // Waves rising and falling inside the box leave it.
        for bound in [0.1, 0.12, 0.149, 0.05, 0.04] {
            assert_eq!(water_box(bound, Some(half)), None, "{bound}");
        }
        // Outgrown: grows with room; far too large: shrinks.
        assert_eq!(water_box(0.2, Some(half)), Some(0.2 * BOX_ROOM));
        assert_eq!(water_box(0.01, Some(half)), Some(0.01 * BOX_ROOM));
    }
}
