//! Main world: caustic volumes from the ECS, rebuilt only when something they depend
//! on changed.

use super::WarpedVolumesSettings;
use crate::components::{CausticGenerator, CausticReceiver, InvalidCausticParams};
use crate::technique::CausticTechniqueChoice;
use crate::irradiance::ActiveCausticTechniques;
use crate::reference::{AnyLight, LightComponents, OccluderComponents, blocks_caustic_light, core_light, core_mesh, to_core, world_aabb};
use bevy::camera::primitives::Aabb;
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use caustics_core::scene::{Light, Sides};
use bevy::tasks::{AsyncComputeTaskPool, Task, block_on, poll_once};
use caustics_core::bvh::SceneBvh;
use caustics_core::mesh::TriMesh;
use caustics_core::params::SpecularInteraction;
use caustics_core::technique::Technique;
use caustics_core::volumes::{BuildStats, CausticVolume, VertexFans, VolumeSettings, build_generator_volumes, channels, occluders_of};
use std::sync::Arc;

/// The caustic volumes of the current scene, shared with the render world. A new
/// `generation` means new contents.
#[derive(Resource, Clone, Default)]
pub struct CausticVolumes {
    pub volumes: Arc<Vec<CausticVolume>>,
    /// What the last build kept and dropped (TIR, grazing, degenerate), and the flux.
    pub stats: BuildStats,
    pub generation: u64,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticsCpuTime::of(app).main;
    app.init_resource::<CausticVolumes>()
        .add_systems(PostUpdate, crate::cpu_time::timed(&cpu, build_volumes).in_set(crate::CausticsSystems::ReadScene));
}

type LightChanged = Or<(
    Changed<GlobalTransform>,
    Changed<DirectionalLight>,
    Changed<PointLight>,
    Changed<SpotLight>,
    Changed<InheritedVisibility>,
)>;
type OccluderChanged = Or<(Changed<GlobalTransform>, Changed<Aabb>, Changed<Mesh3d>, Changed<InheritedVisibility>)>;
type GeneratorChanged =
    Or<(Changed<GlobalTransform>, Changed<Mesh3d>, Changed<CausticGenerator>, Changed<CausticTechniqueChoice>, Changed<InheritedVisibility>)>;
type Generators<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        &'static CausticGenerator,
        &'static CausticTechniqueChoice,
        &'static Mesh3d,
        &'static GlobalTransform,
        &'static InheritedVisibility,
    ),
    Without<InvalidCausticParams>,
>;

/// One generator's input to a build: its world-space mesh, interaction and sides.
struct GeneratorInput {
    entity: Entity,
    mesh: TriMesh,
    interaction: SpecularInteraction,
    sides: Sides,
}

/// What a build produced: the volumes, their stats and the fans it kept.
type BuildOutput = (Vec<CausticVolume>, BuildStats, HashMap<Entity, VertexFans>);

/// The build state across frames.
#[derive(Default)]
struct BuildState {
    /// Fans by generator, handed to each build and back.
    fans: HashMap<Entity, VertexFans>,
    /// The generators' meshes at the last build, to notice their changes.
    meshes: HashSet<AssetId<Mesh>>,
    warned: HashSet<Entity>,
    /// Something changed since the running build started.
    pending: bool,
    running: Option<Task<BuildOutput>>,
}

/// Rebuilds every caustic volume when a generator, light, receiver, shadow caster or
/// the settings changed, or a generator's or occluder's mesh asset was modified (an
/// animated ocean: every frame). Receivers, shadow casters and the other generators
/// hide generator vertices from the light and end their rays (`build_generator_volumes`,
/// `occluders_of`). The build runs on the async compute
/// pool, in parallel over triangles, while the frames go on with the previous volumes:
/// no frame waits for it. Changes that arrive during a build start one more when it
/// ends.
#[allow(clippy::too_many_arguments)]
fn build_volumes(
    generators: Generators<'_, '_>,
    changed_generators: Query<(), (With<CausticGenerator>, GeneratorChanged)>,
    lights: Query<LightComponents, AnyLight>,
    changed_lights: Query<(), (AnyLight, LightChanged)>,
    occluders: Query<OccluderComponents, Without<CausticGenerator>>,
    changed_occluders: Query<(), (With<Mesh3d>, Without<CausticGenerator>, OccluderChanged)>,
    mut removed: RemovedComponents<CausticTechniqueChoice>,
    mut removed_invalid: RemovedComponents<InvalidCausticParams>,
    (mut removed_meshes, mut removed_receivers): (RemovedComponents<Mesh3d>, RemovedComponents<CausticReceiver>),
    mut mesh_events: MessageReader<AssetEvent<Mesh>>,
    meshes: Res<Assets<Mesh>>,
    settings: Res<WarpedVolumesSettings>,
    mut volumes: ResMut<CausticVolumes>,
    mut active: ResMut<ActiveCausticTechniques>,
    mut state: Local<BuildState>,
    cpu: Res<crate::CausticsCpuTime>,
) {
    let mesh_changed = mesh_events.read().any(|e| match e {
        AssetEvent::Modified { id } | AssetEvent::Added { id } | AssetEvent::LoadedWithDependencies { id } => {
            state.meshes.contains(id)
        }
        _ => false,
    });
    state.pending |= mesh_changed
        || settings.is_changed()
        || !changed_generators.is_empty()
        || !changed_lights.is_empty()
        || !changed_occluders.is_empty()
        || removed.read().count() > 0
        || removed_invalid.read().count() > 0
        || removed_meshes.read().count() > 0
        || removed_receivers.read().count() > 0
        // A mesh that had not loaded at the last build.
        || generators.iter().any(|(_, _, _, m, ..)| !state.meshes.contains(&m.id()));

    if let Some(task) = state.running.as_mut() {
        let Some((built, stats, fans)) = block_on(poll_once(task)) else {
            return;
        };
        state.running = None;
        state.fans = fans;
        active.warped_volumes = !built.is_empty();
        *volumes = CausticVolumes { volumes: Arc::new(built), stats, generation: volumes.generation + 1 };
    }
    if !state.pending {
        return;
    }
    state.pending = false;

    let core_settings = settings.core();
    let lights: Vec<Light> = lights
        .iter()
        .filter(|(.., visible)| visible.get())
        .filter_map(|(d, p, s, t, _)| core_light(d, p, s, t))
        .filter(|l| l.validate().is_ok())
        .collect();
    // Volumes end beyond the receivers' world bounds.
    let bounds = occluders
        .iter()
        .filter(|(_, receiver, _)| *receiver)
        .filter_map(|((_, t, _, aabb), ..)| aabb.map(|a| world_aabb(t, a)))
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
        .map(|(lo, hi)| (to_core(lo), to_core(hi)));
    state.meshes.clear();
    // What shadows the generators: receivers and the other meshes that cast shadows.
    let mut shadowing = Vec::new();
    for ((mesh3d, transform, visible, _), receiver, no_shadows) in &occluders {
        if !blocks_caustic_light(visible, receiver, no_shadows) {
            continue;
        }
        state.meshes.insert(mesh3d.id());
        if let Some(Ok(mesh)) = meshes.get(&mesh3d.0).map(|m| core_mesh(m, transform)) {
            shadowing.push(mesh);
        }
    }
    // Every generator shadows the others (`occluders_of`): the volumes' own, and the
    // ones other techniques draw.
    let mut inputs = Vec::new();
    let mut other_generators = Vec::new();
    for (entity, generator, choice, mesh3d, transform, visible) in &generators {
        state.meshes.insert(mesh3d.id());
        let uses_volumes = choice.technique() == Technique::WarpedVolumes;
        let (Some(mesh), true) = (meshes.get(&mesh3d.0), visible.get()) else {
            continue;
        };
        match core_mesh(mesh, transform) {
            Ok(mesh) if !uses_volumes => other_generators.push((entity, mesh)),
            Ok(mesh) => {
                state.warned.remove(&entity);
                let sides = choice.facts.sides;
                other_generators.push((entity, mesh.clone()));
                inputs.push(GeneratorInput { entity, mesh, interaction: generator.specular_interaction(), sides });
            }
            Err(e) => {
                if state.warned.insert(entity) {
                    warn!("bevy_caustics: the mesh of CausticGenerator {entity} is skipped: it {e}");
                }
            }
        }
    }
    let fans = std::mem::take(&mut state.fans);
    let clock = cpu.main.clone();
    let scene = BuildScene { inputs, other_generators, shadowing, lights, bounds };
    state.running = Some(AsyncComputeTaskPool::get().spawn(async move { clock.time(|| build_all(scene, fans, &core_settings)) }));
}

/// What one build reads: the generators the volumes draw, the others (which only
/// shadow them), the other shadowing meshes, the lights and the receivers' bounds.
struct BuildScene {
    inputs: Vec<GeneratorInput>,
    other_generators: Vec<(Entity, TriMesh)>,
    shadowing: Vec<TriMesh>,
    lights: Vec<Light>,
    bounds: Option<(caustics_core::glam::Vec3, caustics_core::glam::Vec3)>,
}

/// Builds every volume of `scene`, reusing the fans of the last build.
fn build_all(scene: BuildScene, mut fans: HashMap<Entity, VertexFans>, core_settings: &VolumeSettings) -> BuildOutput {
    let BuildScene { inputs, other_generators, shadowing, lights, bounds } = scene;
    let mut built = Vec::new();
    let mut stats = BuildStats::default();
    let mut kept = HashMap::new();
    let Some(bounds) = bounds else {
        return (built, stats, kept);
    };
    for input in inputs {
        let others = other_generators.iter().filter(|(e, _)| *e != input.entity).map(|(_, m)| m.clone());
        let occluders = SceneBvh::build(&occluders_of(shadowing.iter().cloned(), others));
        let mut fan = fans.remove(&input.entity).unwrap_or_default();
        if !fan.fits(&input.mesh) {
            fan = VertexFans::new(&input.mesh);
        }
        for light in &lights {
            for (ior, color) in channels(&input.interaction, light.color) {
                let s = build_generator_volumes(
                    &input.mesh,
                    &fan,
                    &input.interaction,
                    input.sides,
                    ior,
                    light,
                    color,
                    bounds,
                    Some(&occluders),
                    core_settings,
                    &mut built,
                );
                stats = stats + s;
            }
        }
        kept.insert(input.entity, fan);
    }
    (built, stats, kept)
}
