//! Main world: a light transport table per mesh, built once, and each light's virtual
//! planes, set up again only when something they depend on changed.

use super::IlluminationTexturesSettings;
use crate::CausticTechnique;
use crate::components::{CausticGenerator, InvalidCausticParams};
use crate::gpu_budget::{CausticGpuBudget, largest_binding, mib};
use crate::irradiance::ActiveCausticTechniques;
use crate::irradiance::mesh_bvhs::MeshBvhs;
use crate::read_scene::{
    AnyLight, ChangedParts, LightComponents, MeshComponents, OccluderComponents, blocks_caustic_light, core_lights, core_mesh, read_scene_changes,
};
use crate::technique::CausticTechniqueChoice;
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use bevy::render::renderer::RenderDevice;
use bevy::tasks::{AsyncComputeTaskPool, Task, block_on, poll_once};
use caustics_core::glam::Affine3A;
use caustics_core::hierarchical::photons::photon_ior;
use caustics_core::illumination_textures::{CacheOutcome, DirectionGrid, IlluminationSettings, IlluminationTextures, LightTransportTable, TransportBuild};
use caustics_core::mesh::TriMesh;
use caustics_core::scene::Light;
use caustics_core::triangle_bvh::InstancedBvh;
use std::path::PathBuf;
use std::sync::Arc;

/// The light transport tables the generators use, one per mesh, index of refraction,
/// scale and direction grid, and how many were ever made: a moving or turning object
/// and a moving light reuse theirs.
#[derive(Resource, Default)]
pub struct LightTransportTables {
    tables: HashMap<TableKey, Arc<LightTransportTable>>,
    /// Tables traced since the app started.
    pub built: u64,
    /// Tables read back from the disk cache.
    pub loaded: u64,
}

impl LightTransportTables {
    /// How many tables are held.
    pub fn len(&self) -> usize {
        self.tables.len()
    }

    /// Whether no table is held.
    pub fn is_empty(&self) -> bool {
        self.tables.is_empty()
    }

    /// Bytes the held tables take.
    pub fn bytes(&self) -> usize {
        self.tables.values().map(|t| t.bytes()).sum()
    }
}

/// What a table is made for: the object's mesh in its own frame, scaled as its
/// transform scales it (a table follows rigid motions only), at an index of refraction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct TableKey {
    mesh: AssetId<Mesh>,
    scale: [u32; 3],
    ior: u32,
    directions: u32,
}

/// Each light's virtual camera through each generator, placed but not seen nor drawn
/// (the render world sees and draws them: `IlluminationTextures::see` and `draw` are
/// the twins), and the receivers they see, shared with the render world. A new
/// `generation` means new contents.
#[derive(Resource, Clone, Default)]
pub struct IlluminationFrames {
    /// One frame for each light through each generator.
    pub frames: Arc<Vec<IlluminationTextures>>,
    /// The meshes that receive or block the light, placed over their BVHs.
    pub receivers: Arc<InstancedBvh>,
    /// Counts the builds; a new one means new contents.
    pub generation: u64,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).main;
    app.init_resource::<LightTransportTables>().init_resource::<IlluminationFrames>().init_resource::<BuildState>().add_systems(
        PostUpdate,
        crate::cpu_time::timed(&cpu, set_up_planes)
            .run_if(crate::cpu_time::timed(&cpu, planes_wanted))
            .after(read_scene_changes)
            .in_set(crate::CausticSystems::ReadScene),
    );
}

/// Whether the planes have work or something to clear: a generator drawn by them, a
/// build under way or asked for, or frames that still hold one. A scene without them
/// spends nothing on their set-up.
fn planes_wanted(choices: Query<&CausticTechniqueChoice>, frames: Res<IlluminationFrames>, state: Res<BuildState>) -> bool {
    state.pending || state.running.is_some() || !frames.frames.is_empty() || choices.iter().any(|c| c.technique() == CausticTechnique::IlluminationTextures)
}

/// One generator as the build reads it.
struct GeneratorInput {
    entity: Entity,
    key: TableKey,
    /// The mesh in the object's frame, scaled.
    mesh: Arc<TriMesh>,
    world_from_object: Affine3A,
    table: Option<Arc<LightTransportTable>>,
}

/// What a build made: the frames, the tables it had to make and how, and what it
/// could not do, by generator.
#[derive(Default)]
struct BuildOutput {
    frames: Vec<IlluminationTextures>,
    receivers: Arc<InstancedBvh>,
    tables: Vec<(TableKey, Arc<LightTransportTable>, CacheOutcome)>,
    problems: Vec<(Entity, String)>,
}

/// Everything the planes depend on that is cheap to compare each frame: the
/// generators drawn with illumination textures (with their index of refraction), the
/// meshes that receive or block their light, the lights, the settings. A build reads
/// the meshes of exactly these.
#[derive(Clone, Debug, Default, PartialEq)]
struct Inputs {
    generators: Vec<(Entity, AssetId<Mesh>, GlobalTransform, f32)>,
    lights: Vec<Light>,
    occluders: Vec<(AssetId<Mesh>, GlobalTransform)>,
    settings: Option<IlluminationTexturesSettings>,
}

/// The set-up's state between frames.
#[derive(Resource, Default)]
struct BuildState {
    last: Inputs,
    /// Something changed since the running build started.
    pending: bool,
    running: Option<Task<BuildOutput>>,
    warned: HashSet<Entity>,
    warned_settings: bool,
    /// The settings last asked for that did not fit (warned once).
    lowered: Option<IlluminationSettings>,
    /// Each table's mesh in the object's frame, scaled, read from its asset once.
    local_meshes: HashMap<TableKey, Arc<TriMesh>>,
}

/// Sets up the virtual planes again when a generator, light, receiver, shadow caster,
/// mesh asset or the settings changed, on the async compute pool while the frames go
/// on with the previous ones; makes a generator's table first when it has none.
#[allow(clippy::too_many_arguments)]
fn set_up_planes(
    generators: Query<(Entity, &CausticGenerator, &CausticTechniqueChoice, MeshComponents), Without<InvalidCausticParams>>,
    occluders: Query<OccluderComponents, Without<CausticGenerator>>,
    lights: Query<LightComponents, AnyLight>,
    changed: Res<ChangedParts>,
    mut mesh_events: MessageReader<AssetEvent<Mesh>>,
    meshes: Res<Assets<Mesh>>,
    settings: Res<IlluminationTexturesSettings>,
    mut tables: ResMut<LightTransportTables>,
    mut frames: ResMut<IlluminationFrames>,
    mut active: ResMut<ActiveCausticTechniques>,
    mut state: ResMut<BuildState>,
    (cpu, device, budget, mut bvhs): (Res<crate::CausticCpuTime>, Option<Res<RenderDevice>>, Res<CausticGpuBudget>, ResMut<MeshBvhs>),
) {
    let core_settings = match settings.core() {
        Ok(s) => {
            state.warned_settings = false;
            Some(s)
        }
        Err(e) => {
            if !state.warned_settings {
                warn!("bevy_caustics: the illumination textures are skipped: {e}");
                state.warned_settings = true;
            }
            None
        }
    };
    let mut mesh_changed = false;
    for event in mesh_events.read() {
        if let AssetEvent::Modified { id } | AssetEvent::Added { id } | AssetEvent::LoadedWithDependencies { id } = event {
            let last = &state.last;
            mesh_changed |= last.generators.iter().any(|g| g.1 == *id) || last.occluders.iter().any(|o| o.0 == *id);
            state.local_meshes.retain(|key, _| key.mesh != *id);
        }
    }
    // The inputs are read again only when change detection says some may differ.
    let changed = *changed;
    if changed.generators || changed.occluders || changed.lights || settings.is_changed() || mesh_changed {
        let next = inputs(&generators, &occluders, &lights, core_settings.map(|_| settings.clone()));
        if mesh_changed || next != state.last {
            state.pending = true;
            state.last = next;
        }
    }

    if let Some(task) = state.running.as_mut() {
        let Some(output) = block_on(poll_once(task)) else { return };
        state.running = None;
        for (key, table, outcome) in output.tables {
            let s = table.stats;
            let how = match outcome {
                CacheOutcome::Loaded => {
                    tables.loaded += 1;
                    "read from the cache".to_string()
                }
                CacheOutcome::Built => {
                    tables.built += 1;
                    format!("built in {:.2} s", s.build_seconds)
                }
                CacheOutcome::BuiltNotWritten(why) => {
                    tables.built += 1;
                    format!("built in {:.2} s, not cached ({why})", s.build_seconds)
                }
            };
            info!(
                "bevy_caustics: light transport table: {} entries, {:.1} MB, {} lost to total internal reflection, {how}",
                s.entries,
                table.bytes() as f64 / 1e6,
                s.total_internal_reflection
            );
            tables.tables.insert(key, table);
        }
        for (entity, problem) in output.problems {
            if state.warned.insert(entity) {
                warn!("bevy_caustics: CausticGenerator {entity}: {problem}");
            }
        }
        active.set_if_neq(ActiveCausticTechniques { illumination_textures: !output.frames.is_empty(), ..*active });
        *frames = IlluminationFrames { frames: Arc::new(output.frames), receivers: output.receivers, generation: frames.generation + 1 };
    }
    if !state.pending || state.running.is_some() {
        return;
    }
    state.pending = false;
    let Some(core_settings) = core_settings else {
        if !frames.frames.is_empty() {
            active.set_if_neq(ActiveCausticTechniques { illumination_textures: false, ..*active });
            *frames = IlluminationFrames { frames: Arc::default(), receivers: Arc::default(), generation: frames.generation + 1 };
        }
        return;
    };

    // The build's inputs: generators in their own frame, receivers in the world's.
    let mut inputs = Vec::new();
    let mut keys = HashSet::new();
    let next = state.last.clone();
    for &(entity, mesh_id, transform, ior) in &next.generators {
        let Some(mesh) = meshes.get(mesh_id) else { continue };
        let (scale, rotation, translation) = transform.to_scale_rotation_translation();
        // A turning object's scale comes back from its matrix a rounding off: to five
        // digits, it keeps its table.
        let scale = (scale * 1e5).round() / 1e5;
        let key = TableKey { mesh: mesh_id, scale: scale.to_array().map(f32::to_bits), ior: ior.to_bits(), directions: settings.table_directions };
        let local = match state.local_meshes.get(&key) {
            Some(local) => local.clone(),
            None => match core_mesh(mesh, &GlobalTransform::from_scale(scale)) {
                Ok(local) => {
                    let local = Arc::new(local);
                    state.local_meshes.insert(key, local.clone());
                    local
                }
                Err(e) => {
                    if state.warned.insert(entity) {
                        warn!("bevy_caustics: the mesh of CausticGenerator {entity} is skipped: it {e}");
                    }
                    continue;
                }
            },
        };
        keys.insert(key);
        let world_from_object = Affine3A::from_rotation_translation(
            caustics_core::glam::Quat::from_array(rotation.to_array()),
            caustics_core::glam::Vec3::from_array(translation.to_array()),
        );
        inputs.push(GeneratorInput { entity, key, mesh: local, world_from_object, table: tables.tables.get(&key).cloned() });
    }
    // Tables and meshes no generator uses any more are let go.
    tables.tables.retain(|key, _| keys.contains(key));
    state.local_meshes.retain(|key, _| keys.contains(key));
    let receivers =
        Arc::new(bvhs.place(next.occluders.iter().enumerate().map(|(k, (mesh, transform))| (*mesh, transform.to_matrix(), k as u32, None)), &meshes));
    let lights = next.lights;
    let fitted = fitting(core_settings, lights.len(), device.as_deref(), budget.bytes);
    let builds = !inputs.is_empty() && !lights.is_empty();
    if builds && fitted != core_settings && state.lowered != Some(core_settings) {
        warn!(
            "bevy_caustics: illumination textures of {} planes at {}² for {} light(s) do not fit this GPU or CausticGpuBudget ({}); they use {} planes at {}²",
            core_settings.planes,
            core_settings.texture_size,
            lights.len(),
            mib(budget.bytes),
            fitted.planes,
            fitted.texture_size
        );
    }
    state.lowered = (builds && fitted != core_settings).then_some(core_settings);
    let core_settings = fitted;
    let (directions, max_bytes, cache_dir) = (settings.table_directions, settings.max_table_bytes, settings.cache_dir.clone());
    let clock = cpu.main.clone();
    state.running = Some(
        AsyncComputeTaskPool::get()
            .spawn(async move { clock.time(|| make_frames(inputs, &lights, receivers, &core_settings, (directions, max_bytes, cache_dir))) }),
    );
}

/// The planes' inputs as the scene stands: the generators drawn with illumination
/// textures, the meshes that block their light and the lights (none of these without
/// `settings`, the settings when they are valid).
fn inputs(
    generators: &Query<(Entity, &CausticGenerator, &CausticTechniqueChoice, MeshComponents), Without<InvalidCausticParams>>,
    occluders: &Query<OccluderComponents, Without<CausticGenerator>>,
    lights: &Query<LightComponents, AnyLight>,
    settings: Option<IlluminationTexturesSettings>,
) -> Inputs {
    let mut next = Inputs { settings, ..default() };
    for (entity, generator, choice, (mesh, transform, visible, _)) in generators {
        if choice.technique() != CausticTechnique::IlluminationTextures || !visible.get() || next.settings.is_none() {
            continue;
        }
        let Some(ior) = photon_ior(&generator.specular_interaction()) else { continue };
        next.generators.push((entity, mesh.id(), *transform, ior));
    }
    if !next.generators.is_empty() {
        for ((mesh, transform, visible, _), receiver, no_shadows) in occluders {
            if blocks_caustic_light(visible, receiver, no_shadows) {
                next.occluders.push((mesh.id(), *transform));
            }
        }
        next.lights = core_lights(lights);
    }
    next
}

/// `settings` with the planes and texture size that the device's limits and the budget
/// allow for `frames` lights' textures (at most 16 bytes a texel and plane: 32-bit
/// floats) and depth maps (48 bytes a texel, one storage binding): the size halves until
/// they fit, or reaches 16. Without a render device only the budget bounds them.
fn fitting(settings: IlluminationSettings, frames: usize, device: Option<&RenderDevice>, budget: u64) -> IlluminationSettings {
    let (largest, widest, layers) =
        device.map_or((u64::MAX, u32::MAX, u32::MAX), |d| (largest_binding(d), d.limits().max_texture_dimension_2d, d.limits().max_texture_array_layers));
    let mut fitted = IlluminationSettings { planes: settings.planes.min(layers), ..settings };
    let texels = |s: &IlluminationSettings| u64::from(s.texture_size).pow(2);
    let depth_map = super::SURFACE_TEXEL_BYTES;
    let bytes = |s: &IlluminationSettings| texels(s) * (16 * u64::from(s.planes) + depth_map) * frames as u64;
    while fitted.texture_size > 16 && (bytes(&fitted) > budget || texels(&fitted) * depth_map > largest || fitted.texture_size > widest) {
        fitted.texture_size /= 2;
    }
    fitted
}

/// The build: each generator's table (made once per key), then each light's frame,
/// placed over `receivers`.
fn make_frames(
    inputs: Vec<GeneratorInput>,
    lights: &[Light],
    receivers: Arc<InstancedBvh>,
    settings: &IlluminationSettings,
    (directions, max_bytes, cache_dir): (u32, usize, Option<PathBuf>),
) -> BuildOutput {
    let mut output = BuildOutput { receivers, ..default() };
    let mut made: HashMap<TableKey, Arc<LightTransportTable>> = HashMap::new();
    for input in inputs {
        let table = match input.table.or_else(|| made.get(&input.key).cloned()) {
            Some(table) => table,
            None => {
                let vertices = input.mesh.positions().len();
                let (grid, lowered) = DirectionGrid::fitting(directions, vertices, max_bytes);
                if lowered {
                    let problem =
                        format!("its light transport table at {directions}² directions would pass max_table_bytes ({max_bytes}); it uses {}²", grid.side());
                    output.problems.push((input.entity, problem));
                }
                let build = TransportBuild { ior: f32::from_bits(input.key.ior), grid };
                let result = match &cache_dir {
                    Some(dir) => LightTransportTable::load_or_build(dir, &input.mesh, build, &|_, _| {}),
                    None => LightTransportTable::build(&input.mesh, build, &|_, _| {}).map(|t| (t, CacheOutcome::Built)),
                };
                match result {
                    Ok((table, outcome)) => {
                        let table = Arc::new(table);
                        made.insert(input.key, table.clone());
                        output.tables.push((input.key, table.clone(), outcome));
                        table
                    }
                    Err(e) => {
                        output.problems.push((input.entity, format!("casts no illumination textures: its light transport table: {e}")));
                        continue;
                    }
                }
            }
        };
        for light in lights {
            if let Some(frame) = IlluminationTextures::placed(&table, &input.mesh, &input.world_from_object, light, &output.receivers, settings) {
                output.frames.push(frame);
            }
        }
    }
    output
}
