//! An animated ocean surface: the [`Ocean`] component moves its entity's mesh every
//! frame by Tessendorf's FFT spectrum (`caustics_core::ocean`).
//!
//! On the GPU (the default, [`Ocean::on_gpu`]) the render world evaluates the waves
//! each frame straight into the vertex buffer Bevy draws the mesh from (`render.rs`,
//! `waves.wgsl`): the CPU does nothing per frame, and caustic volumes built from the
//! ocean read the waves of the frame they are drawn in. The mesh asset keeps the
//! surface of the moment it was made, and the entity's `Aabb` covers every wave the
//! spectrum can raise ([`OceanSpectrum::height_bound`], with `NoAutoAabb`).
//!
//! On the CPU (when asked, when the ocean is a [`crate::CausticGenerator`] drawn by a
//! technique that reads its triangles on the CPU, or without a render app) the mesh
//! asset is rewritten in place every frame — the same path any user-animated generator
//! takes: write the `Mesh` behind a `Mesh3d` through `Assets<Mesh>::get_mut`, and Bevy
//! re-uploads it and recomputes the entity's `Aabb`.

mod render;

use crate::CausticTechnique;
use crate::cpu_time::timed;
use crate::grid_mesh::{grid_mesh, is_grid, rewrite_grid};
use crate::mesh_vertices::MovesOnGpu;
use crate::technique::CausticTechniqueChoice;
use bevy::camera::primitives::Aabb;
use bevy::camera::visibility::NoAutoAabb;
use bevy::platform::collections::HashSet;
use bevy::prelude::*;
use caustics_core::ocean::{OceanSettings, OceanSpectrum, OceanSurface};
use std::sync::Arc;

/// The largest resolution evaluated on the GPU: four complex fields of 2048² texels fill
/// the 128 MiB that every adapter binds as one storage buffer. Finer oceans stay on the
/// CPU.
pub const MAX_GPU_RESOLUTION: u32 = 2048;

/// A square patch of wind-driven ocean, centred on its entity, in its xz plane. The
/// entity's `Mesh3d` is created when it has none (or one that is not this ocean's
/// grid, or whose data lives only in the render world) and then updated in place
/// every frame: (N + 1)² vertices, the last row and column repeating the first so
/// that copies tile. The fields are `caustics_core::ocean::OceanSettings`' (see there),
/// in Bevy types for the inspector; `time_scale`, simulated seconds per second of
/// `Time::elapsed_secs`; and `on_gpu`: evaluate the waves on the GPU where the ocean's
/// use allows (see the module's text), else on the CPU. Invalid settings are reported
/// once and the ocean stands still.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component)]
#[require(Transform, Visibility)]
#[allow(missing_docs)]
pub struct Ocean {
    pub resolution: u32,
    pub size: f32,
    pub wind_speed: f32,
    pub wind_direction: Vec2,
    pub amplitude: f32,
    pub choppiness: f32,
    pub small_wave_cutoff: f32,
    pub depth: Option<f32>,
    pub seed: u64,
    pub time_scale: f32,
    pub on_gpu: bool,
}

impl Default for Ocean {
    fn default() -> Self {
        let core = OceanSettings::default();
        Self {
            resolution: core.resolution as u32,
            size: core.size,
            wind_speed: core.wind_speed,
            wind_direction: Vec2::new(core.wind_direction.x, core.wind_direction.y),
            amplitude: core.amplitude,
            choppiness: core.choppiness,
            small_wave_cutoff: core.small_wave_cutoff,
            depth: core.depth,
            seed: core.seed,
            time_scale: 1.0,
            on_gpu: true,
        }
    }
}

impl Ocean {
    /// The core crate's settings.
    pub fn settings(&self) -> OceanSettings {
        OceanSettings {
            resolution: self.resolution as usize,
            size: self.size,
            wind_speed: self.wind_speed,
            wind_direction: caustics_core::glam::Vec2::new(self.wind_direction.x, self.wind_direction.y),
            amplitude: self.amplitude,
            choppiness: self.choppiness,
            small_wave_cutoff: self.small_wave_cutoff,
            depth: self.depth,
            seed: self.seed,
        }
    }

    /// The wave field for these settings, or why there is none.
    fn spectrum(&self) -> Result<OceanSpectrum, String> {
        if !self.time_scale.is_finite() {
            return Err(format!("time scale {} is not a finite number", self.time_scale));
        }
        OceanSpectrum::new(&self.settings()).map_err(|e| e.to_string())
    }
}

/// A spectrum's modes as the GPU reads them (`OceanSpectrum::modes`).
struct OceanModes {
    amplitudes: Vec<[f32; 4]>,
    omega: Vec<f32>,
}

/// The wave field drawn for an [`Ocean`]'s current settings, the surface it last
/// evaluated on the CPU (its buffers reused every frame) and the field's modes for the
/// GPU.
#[derive(Component)]
struct OceanWaves {
    spectrum: OceanSpectrum,
    surface: OceanSurface,
    modes: Arc<OceanModes>,
}

/// Present when a render app evaluates oceans on the GPU.
#[derive(Resource)]
struct GpuWaves;

/// Animates every [`Ocean`]. `CausticsPlugin` adds it; it also works on its own.
pub struct OceanPlugin;

impl Plugin for OceanPlugin {
    fn build(&self, app: &mut App) {
        let cpu = crate::CausticCpuTime::of(app).main;
        app.register_type::<Ocean>().add_systems(Update, (timed(&cpu, draw_waves), timed(&cpu, animate_oceans)).chain().run_if(timed(&cpu, seas)));
        if app.get_sub_app(bevy::render::RenderApp).is_some() {
            app.insert_resource(GpuWaves);
            crate::mesh_vertices::build(app);
            render::build(app);
        }
    }
}

/// Entities with an ocean or the waves of one.
type Seas = Or<(With<Ocean>, With<OceanWaves>)>;

/// Whether an entity has an ocean or the waves of one: the oceans' systems are left
/// out of the frame otherwise (one query, where two conditions cost twice).
fn seas(seas: Query<(), Seas>) -> bool {
    !seas.is_empty()
}

/// (Re)draws the wave field of oceans that are new or whose settings changed; invalid
/// settings are reported once per entity and the ocean stands still until fixed.
fn draw_waves(
    mut commands: Commands,
    oceans: Query<(Entity, &Ocean, Option<&OceanWaves>), Changed<Ocean>>,
    orphans: Query<Entity, (With<OceanWaves>, Without<Ocean>)>,
    mut removed: RemovedComponents<Ocean>,
    mut warned: Local<HashSet<Entity>>,
) {
    for entity in removed.read() {
        warned.remove(&entity);
    }
    for entity in &orphans {
        commands.entity(entity).remove::<OceanWaves>();
    }
    for (entity, ocean, waves) in &oceans {
        // A change of time scale (or a mutable access that changed nothing) keeps the sea.
        if waves.is_some_and(|w| *w.spectrum.settings() == ocean.settings()) && ocean.time_scale.is_finite() {
            continue;
        }
        match ocean.spectrum() {
            Ok(spectrum) => {
                warned.remove(&entity);
                let (amplitudes, omega) = spectrum.modes().unzip();
                let modes = Arc::new(OceanModes { amplitudes, omega });
                commands.entity(entity).insert(OceanWaves { spectrum, surface: OceanSurface::default(), modes });
            }
            Err(reason) => {
                if warned.insert(entity) {
                    warn!("bevy_caustics: Ocean on {entity} is skipped: {reason}");
                }
                commands.entity(entity).remove::<OceanWaves>();
            }
        }
    }
}

/// The components [`animate_oceans`] reads.
type Oceans<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        &'static Ocean,
        &'static mut OceanWaves,
        Option<&'static Mesh3d>,
        Option<&'static CausticTechniqueChoice>,
        Has<crate::CausticGenerator>,
        Has<MovesOnGpu>,
    ),
>;

/// Whether an ocean's waves are evaluated on the GPU: asked for, possible, and no
/// technique reads the ocean's triangles on the CPU (only the caustic volumes' build
/// reads them on the GPU; a generator whose technique is not chosen yet waits a frame).
fn evaluates_on_gpu(ocean: &Ocean, gpu: bool, choice: Option<&CausticTechniqueChoice>, generator: bool) -> bool {
    gpu && ocean.on_gpu && ocean.resolution <= MAX_GPU_RESOLUTION && (!generator || choice.is_some_and(|c| c.technique() == CausticTechnique::WarpedVolumes))
}

/// Moves every ocean: on the GPU, makes its mesh once (the surface of this moment) and
/// leaves the frames to the render world; on the CPU, evaluates it and rewrites the mesh.
fn animate_oceans(mut commands: Commands, time: Res<Time>, gpu: Option<Res<GpuWaves>>, mut oceans: Oceans, mut meshes: ResMut<Assets<Mesh>>) {
    for (entity, ocean, mut waves, mesh3d, choice, generator, was_on_gpu) in &mut oceans {
        // A wave field drawn anew (new settings): a new bound, and the mesh of this moment.
        let redrawn = waves.is_changed();
        let n = waves.spectrum.settings().resolution;
        let grid = mesh3d.and_then(|m| meshes.get(&m.0)).is_some_and(|mesh| is_grid(mesh, 6 * n * n, (n + 1) * (n + 1)));
        let on_gpu = evaluates_on_gpu(ocean, gpu.is_some(), choice, generator);
        if on_gpu && was_on_gpu && !redrawn && grid {
            continue;
        }
        let OceanWaves { spectrum, surface, .. } = &mut *waves;
        spectrum.evaluate_into(time.elapsed_secs() * ocean.time_scale, surface);
        if on_gpu {
            let (size, bound) = (spectrum.settings().size, spectrum.height_bound());
            let aabb =
                Aabb::from_min_max(Vec3::new(-0.5 * size - bound, -bound, -0.5 * size - bound), Vec3::new(0.5 * size + bound, bound, 0.5 * size + bound));
            commands.entity(entity).insert((MovesOnGpu, NoAutoAabb, aabb));
        } else if was_on_gpu {
            commands.entity(entity).remove::<(MovesOnGpu, NoAutoAabb)>();
        }
        let written = mesh3d.and_then(|m| meshes.get_mut(&m.0)).is_some_and(|mut mesh| write_in_place(&mut mesh, surface));
        if !written {
            commands.entity(entity).insert(Mesh3d(meshes.add(new_grid_mesh(surface))));
        }
    }
}

/// Rewrites the positions and normals of `mesh` if it is this surface's grid ((N + 1)²
/// vertices, 6N² indices); false, with nothing changed, if not.
fn write_in_place(mesh: &mut Mesh, surface: &OceanSurface) -> bool {
    let n = surface.resolution;
    let vertices = (0..=n).flat_map(|j| (0..=n).map(move |i| surface.vertex(i, j)));
    let positions = vertices.clone().map(|(position, _)| position.to_array());
    let normals = vertices.map(|(_, normal)| normal.to_array());
    rewrite_grid(mesh, (6 * n * n, (n + 1) * (n + 1)), positions, normals)
}

/// A new grid mesh of the surface: positions, normals, UVs over [0, 1]² and indices.
fn new_grid_mesh(surface: &OceanSurface) -> Mesh {
    let n = surface.resolution;
    let (positions, normals) = surface.vertices();
    let uvs = (0..=n).flat_map(|j| (0..=n).map(move |i| [i as f32 / n as f32, j as f32 / n as f32])).collect();
    let indices = surface.triangles().into_iter().flatten().collect();
    grid_mesh(positions.iter().map(|p| p.to_array()).collect(), normals.iter().map(|n| n.to_array()).collect(), uvs, indices)
}
