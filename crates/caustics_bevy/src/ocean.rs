//! An animated ocean surface: the [`Ocean`] component rewrites its entity's mesh every
//! frame from Tessendorf's FFT spectrum (`caustics_core::ocean`). With a
//! [`crate::CausticGenerator`] beside it, the caustic techniques see the mesh asset
//! change and rebuild — the same path any user-animated generator takes.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::platform::collections::HashSet;
use bevy::prelude::*;
use caustics_core::ocean::{OceanSettings, OceanSpectrum, OceanSurface};

/// A square patch of wind-driven ocean, centred on its entity, in its xz plane. The
/// entity's `Mesh3d` is created (or replaced when the resolution changes) and then
/// updated in place every frame. The fields are `caustics_core::ocean::OceanSettings`'
/// (see there), in Bevy types for the inspector, and `time_scale`, simulated seconds
/// per real second.
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
            depth: None,
            seed: self.seed,
        }
    }
}

/// The wave field drawn for an [`Ocean`]'s current settings.
#[derive(Component)]
struct OceanWaves(OceanSpectrum);

/// Animates every [`Ocean`]. `CausticsPlugin` adds it; it also works on its own.
pub struct OceanPlugin;

impl Plugin for OceanPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<Ocean>().add_systems(Update, (draw_waves, animate_oceans).chain());
    }
}

/// (Re)draws the wave field of oceans that are new or changed; invalid settings are
/// reported once and the ocean stands still.
fn draw_waves(
    mut commands: Commands,
    oceans: Query<(Entity, &Ocean), Changed<Ocean>>,
    mut warned: Local<HashSet<Entity>>,
) {
    for (entity, ocean) in &oceans {
        match OceanSpectrum::new(&ocean.settings()) {
            Ok(spectrum) => {
                warned.remove(&entity);
                commands.entity(entity).insert(OceanWaves(spectrum));
            }
            Err(e) => {
                if warned.insert(entity) {
                    warn!("bevy_caustics: Ocean on {entity} is skipped: {e}");
                }
                commands.entity(entity).remove::<OceanWaves>();
            }
        }
    }
}

fn animate_oceans(
    mut commands: Commands,
    time: Res<Time>,
    mut oceans: Query<(Entity, &Ocean, &OceanWaves, Option<&Mesh3d>)>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    for (entity, ocean, waves, mesh3d) in &mut oceans {
        let surface = waves.0.evaluate(time.elapsed_secs() * ocean.time_scale);
        let (positions, normals) = vertices(&surface);
        if let Some(mut mesh) = mesh3d.and_then(|m| meshes.get_mut(&m.0))
            && mesh.count_vertices() == positions.len()
        {
            mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
            mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
            continue;
        }
        let mesh = grid_mesh(&surface, positions, normals);
        commands.entity(entity).insert(Mesh3d(meshes.add(mesh)));
    }
}

/// Positions and normals of the tiling grid (see `OceanSurface::vertices`).
fn vertices(surface: &OceanSurface) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let (positions, normals) = surface.vertices();
    (positions.iter().map(|p| p.to_array()).collect(), normals.iter().map(|n| n.to_array()).collect())
}

fn grid_mesh(surface: &OceanSurface, positions: Vec<[f32; 3]>, normals: Vec<[f32; 3]>) -> Mesh {
    let n = surface.resolution;
    let uvs: Vec<[f32; 2]> =
        (0..=n).flat_map(|j| (0..=n).map(move |i| [i as f32 / n as f32, j as f32 / n as f32])).collect();
    let indices = surface.triangles().into_iter().flatten().collect();
    Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
        .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
        .with_inserted_indices(Indices::U32(indices))
}
