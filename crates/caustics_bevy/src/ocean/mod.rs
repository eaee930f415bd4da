//! An animated ocean surface: the [`Ocean`] component rewrites its entity's mesh every
//! frame from Tessendorf's FFT spectrum (`caustics_core::ocean`). With a
//! [`crate::CausticGenerator`] beside it, the caustic techniques see the mesh asset
//! change and rebuild — the same path any user-animated generator takes: write the
//! `Mesh` asset behind a `Mesh3d` in place (`Assets<Mesh>::get_mut`), and Bevy
//! re-uploads it and recomputes the entity's `Aabb`.

use crate::cpu_time::timed;
use crate::grid_mesh::{grid_mesh, rewrite_grid};
use bevy::platform::collections::HashSet;
use bevy::prelude::*;
use caustics_core::ocean::{OceanSettings, OceanSpectrum, OceanSurface};

/// A square patch of wind-driven ocean, centred on its entity, in its xz plane. The
/// entity's `Mesh3d` is created when it has none (or one that is not this ocean's
/// grid, or whose data lives only in the render world) and then updated in place
/// every frame: (N + 1)² vertices, the last row and column repeating the first so
/// that copies tile. The fields are `caustics_core::ocean::OceanSettings`' (see there),
/// in Bevy types for the inspector, and `time_scale`, simulated seconds per second of
/// `Time::elapsed_secs`. Invalid settings are reported once and the ocean stands still.
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

/// The wave field drawn for an [`Ocean`]'s current settings, and the surface it last
/// evaluated (its buffers reused every frame).
#[derive(Component)]
struct OceanWaves {
    spectrum: OceanSpectrum,
    surface: OceanSurface,
}

/// Animates every [`Ocean`]. `CausticsPlugin` adds it; it also works on its own.
pub struct OceanPlugin;

impl Plugin for OceanPlugin {
    fn build(&self, app: &mut App) {
        let cpu = crate::CausticsCpuTime::of(app).main;
        app.register_type::<Ocean>().add_systems(Update, (timed(&cpu, draw_waves), timed(&cpu, animate_oceans)).chain());
    }
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
                commands.entity(entity).insert(OceanWaves { spectrum, surface: OceanSurface::default() });
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

fn animate_oceans(
    mut commands: Commands,
    time: Res<Time>,
    mut oceans: Query<(Entity, &Ocean, &mut OceanWaves, Option<&Mesh3d>)>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    for (entity, ocean, mut waves, mesh3d) in &mut oceans {
        let OceanWaves { spectrum, surface } = &mut *waves;
        spectrum.evaluate_into(time.elapsed_secs() * ocean.time_scale, surface);
        if let Some(mut mesh) = mesh3d.and_then(|m| meshes.get_mut(&m.0))
            && write_in_place(&mut mesh, surface)
        {
            continue;
        }
        commands.entity(entity).insert(Mesh3d(meshes.add(new_grid_mesh(surface))));
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
