//! Main world: what the GPU build of the caustic volumes reads, gathered from the ECS
//! whenever something it depends on changed: the generators the volumes draw (their
//! meshes' topology, kept across frames, and placement), the lights, the receivers'
//! bounds and the occluders' BVH (rebuilt only when an occluder changed). The render
//! world builds the volumes from the generators' vertices in Bevy's vertex buffers
//! (`compute.rs`); the counts of the last build come back into [`CausticVolumes`].

use super::WarpedVolumesSettings;
use crate::CausticTechnique;
use crate::components::{CausticGenerator, InvalidCausticParams};
use crate::gpu_budget::mib;
use crate::irradiance::ActiveCausticTechniques;
use crate::irradiance::mesh_bvhs::MeshBvhs;
use crate::mesh_vertices::MovesOnGpu;
use crate::read_scene::{
    AnyLight, ChangedParts, LightComponents, OccluderComponents, blocks_caustic_light, core_lights, read_scene_changes, to_core, world_aabb,
};
use crate::technique::CausticTechniqueChoice;
use bevy::camera::primitives::Aabb;
use bevy::mesh::Indices;
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use bevy::render::{renderer::RenderDevice, settings::WgpuLimits};
use caustics_core::glam;
use caustics_core::mesh::TriMesh;
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::Light;
use caustics_core::triangle_bvh::{InstancedBvh, MeshBvh};
use caustics_core::volumes::{BuildStats, VertexFans, VolumeSettings};
use std::sync::{Arc, Mutex};

/// What the last GPU build of the caustic volumes kept and dropped (unlit, shadowed,
/// TIR, grazing, degenerate) and the flux on each side, read back from the GPU a frame
/// or two later: at once for new sources, every eighth frame while they only move on
/// the GPU (an ocean, a rippling pool). A new `generation` means a newer build. `gathered` counts the times
/// the main world gathered the builds' sources, reading generator meshes on the CPU
/// (when a generator, light, receiver or mesh asset changed): an ocean animated on the
/// GPU adds none while its waves move.
#[derive(Resource, Clone, Default)]
pub struct CausticVolumes {
    /// The last build's counts and flux.
    pub stats: BuildStats,
    /// Counts the builds read back.
    pub generation: u64,
    /// Counts the gatherings of the builds' sources on the CPU.
    pub gathered: u64,
    /// How the surface pass shared out the volumes in a recent frame.
    pub surface: SurfaceWork,
}

/// How the surface pass lit a view's receivers, counted on the GPU every eighth frame
/// for one view and read back a frame or two later: the volumes whose bounding shape covers a few pixels
/// are lit by a compute pass, pixel by pixel (`splatted`, shading `splatted_pixels`
/// pixels in all), the others rasterised (`rasterised`, shading the pass's fragments).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SurfaceWork {
    /// Volumes lit by the compute pass.
    pub splatted: u32,
    /// Pixels they shaded in all.
    pub splatted_pixels: u32,
    /// Volumes rasterised.
    pub rasterised: u32,
}

/// The counts of a GPU build, and of the surface pass, on their way from the render
/// world.
#[derive(Resource, Clone, Default)]
pub(super) struct BuildStatsChannel(pub Arc<Mutex<Option<BuildStats>>>, pub Arc<Mutex<Option<SurfaceWork>>>);

/// `VertexRay` in `build.wgsl`: seven `vec4`s, each a texel of the rays' texture.
pub(super) const RAY_TEXELS: u32 = 7;
const VERTEX_RAY_BYTES: u64 = RAY_TEXELS as u64 * 16;

/// The rays a row of their texture holds: a multiple of 16, so that a row of the rays'
/// buffer (1792 bytes for 16 rays) is a multiple of the 256 bytes a copy's rows take;
/// at most 1024, within the adapter's widest texture.
pub(super) fn rays_per_row(limits: &WgpuLimits) -> u32 {
    (limits.max_texture_dimension_2d / (16 * RAY_TEXELS) * 16).clamp(16, 1024)
}

/// A mesh's triangles and what the build derives from them alone: the fans of §3.4
/// and the sides each triangle owns (bits, `VertexFans::owned_edges`).
pub(super) struct Topology {
    pub vertices: usize,
    pub triangles: Vec<u32>,
    pub fans: VertexFans,
    pub owned_sides: Vec<u32>,
}

/// The mesh index of an occluder that is no generator (`GeneratorHit::generator`):
/// no generator's build passes through it.
pub(super) const SHADOW_CASTER: u32 = u32::MAX - 1;

/// One generator the volumes draw, as its build reads it.
#[derive(Clone)]
pub(super) struct VolumeGenerator {
    pub mesh: AssetId<Mesh>,
    pub world_from_local: Mat4,
    pub interaction: SpecularInteraction,
    /// Lit from behind too ([`caustics_core::scene::Sides::lit_from_behind`]).
    pub two_sided: bool,
    pub topology: Arc<Topology>,
    /// Its own mesh index in the occluders' BVH, which its rays pass through.
    pub occluder_index: u32,
    /// Its mesh moves on the GPU ([`MovesOnGpu`]): the volumes are built every frame.
    pub moves_on_gpu: bool,
}

/// Everything the GPU build reads but the generators' vertices. A new `generation`
/// means a new build.
#[derive(Resource, Clone, Default)]
pub(super) struct VolumeSources {
    pub generators: Vec<(Entity, VolumeGenerator)>,
    pub lights: Vec<Light>,
    /// Receivers, shadow casters and, with two or more generators, every generator,
    /// placed over their meshes' BVHs.
    pub occluders: Arc<InstancedBvh>,
    /// The meshes of `occluders` deformed on the GPU, whose BVHs the render world
    /// refits each frame (`bvh_refit.rs`).
    pub deformed: Vec<(AssetId<Mesh>, Arc<MeshBvh>)>,
    /// The receivers' world bounds: every volume ends beyond them.
    pub bounds: Option<(glam::Vec3, glam::Vec3)>,
    pub settings: VolumeSettings,
    /// The in-scattering pass draws each volume's bounding shape
    /// ([`super::ShaftIntegral::Exact`]): the build bounds the whole beam too, not only
    /// the slice the surface pass draws.
    pub draws_beams: bool,
    pub generation: u64,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).main;
    app.init_resource::<CausticVolumes>().init_resource::<VolumeSources>().init_resource::<BuildStatsChannel>().add_systems(
        PostUpdate,
        (crate::cpu_time::timed(&cpu, gather_sources).after(read_scene_changes), crate::cpu_time::timed(&cpu, receive_stats))
            .in_set(crate::CausticSystems::ReadScene),
    );
}

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
        Has<MovesOnGpu>,
    ),
    Without<InvalidCausticParams>,
>;

/// What the gathering keeps across frames.
#[derive(Default)]
struct GatherState {
    /// Topology by generator, with the mesh it was made from and checked for.
    topologies: HashMap<Entity, (AssetId<Mesh>, Arc<Topology>)>,
    /// The meshes of occluders and of generators at the last gathering, to notice
    /// their changes.
    occluder_meshes: HashSet<AssetId<Mesh>>,
    generator_meshes: HashSet<AssetId<Mesh>>,
    /// The bounds the occluders deformed on the GPU were placed with: they are placed
    /// again when their surface outgrows them.
    deformed_bounds: HashMap<AssetId<Mesh>, Aabb>,
    warned: HashSet<Entity>,
}

/// The triangle indices of a mesh; an error without triangles or with an index past
/// its vertices.
fn triangle_indices(mesh: &Mesh) -> Result<(usize, Vec<u32>), String> {
    let topology = mesh.primitive_topology();
    if topology != bevy::mesh::PrimitiveTopology::TriangleList {
        return Err(format!("is a {topology:?}, not a triangle list"));
    }
    let vertices = mesh.count_vertices();
    let indices: Vec<u32> = match mesh.indices() {
        Some(Indices::U16(i)) => i.iter().map(|&i| u32::from(i)).collect(),
        Some(Indices::U32(i)) => i.clone(),
        None => (0..vertices as u32).collect(),
    };
    let triangles = indices.len() / 3 * 3;
    if triangles == 0 {
        return Err("has no triangles".into());
    }
    if let Some(&bad) = indices[..triangles].iter().find(|&&i| i as usize >= vertices) {
        return Err(format!("has index {bad} past its {vertices} vertices"));
    }
    Ok((vertices, indices[..triangles].to_vec()))
}

/// What makes `mesh`'s first unusable vertex so: a position that is not finite, or a
/// normal that is NaN, infinite or zero. The GPU build would drop its triangles
/// without a word; the generator is skipped with a warning instead, as the other
/// techniques skip such a mesh (`core_mesh`).
fn unusable_vertex(mesh: &Mesh) -> Option<String> {
    use bevy::mesh::VertexAttributeValues::Float32x3;
    let first = |attribute, bad: fn(&Vec3) -> bool| match mesh.attribute(attribute) {
        Some(Float32x3(values)) => values.iter().map(|v| Vec3::from_array(*v)).position(|v| bad(&v)),
        _ => None,
    };
    if let Some(vertex) = first(Mesh::ATTRIBUTE_POSITION, |p| !p.is_finite()) {
        return Some(format!("has vertex {vertex} with a position that is not finite"));
    }
    first(Mesh::ATTRIBUTE_NORMAL, |n| !n.is_finite() || *n == Vec3::ZERO)
        .map(|vertex| format!("has vertex {vertex} with a normal that is NaN, infinite or zero"))
}

impl Topology {
    /// Whether `mesh` still has these triangles (an animated mesh's every frame: read
    /// in place, nothing copied).
    fn fits(&self, mesh: &Mesh) -> bool {
        let vertices = mesh.count_vertices();
        let same = |count: usize, mut indices: Box<dyn Iterator<Item = usize> + '_>| {
            count / 3 * 3 == self.triangles.len() && self.triangles.iter().all(|&t| indices.next() == Some(t as usize))
        };
        vertices == self.vertices
            && match mesh.indices() {
                Some(indices) => same(indices.len(), Box::new(indices.iter())),
                None => same(vertices, Box::new(0..vertices)),
            }
    }

    /// The rows of its rays' texture, `per_row` rays a row: its vertices' rays and the
    /// slicing axis.
    pub fn ray_rows(&self, per_row: u32) -> u32 {
        (self.vertices as u32 + 1).div_ceil(per_row)
    }

    /// The bytes of its rays' buffer, whole rows of `per_row` rays.
    pub fn ray_bytes(&self, per_row: u32) -> u64 {
        u64::from(self.ray_rows(per_row)) * u64::from(per_row) * VERTEX_RAY_BYTES
    }

    /// What keeps its build from binding on an adapter of `limits`, if anything: a
    /// buffer past the largest storage binding (its vertices take `vertex_bytes`) or its
    /// rays' texture past the tallest 2D texture. wgpu refuses such a binding, and
    /// Bevy quits the app on the validation error.
    fn unbindable(&self, vertex_bytes: u64, limits: &WgpuLimits) -> Option<String> {
        let per_row = rays_per_row(limits);
        let rows = self.ray_rows(per_row);
        let words = |n: usize| n as u64 * 4;
        let buffers = [
            ("vertex rays", self.ray_bytes(per_row)),
            ("vertices", vertex_bytes),
            ("triangles", words(self.triangles.len())),
            ("vertex fans", words(self.fans.starts().len() + self.fans.triangles().len())),
            ("triangle areas", (self.triangles.len() / 3) as u64 * 16),
        ];
        let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        if let Some((what, bytes)) = buffers.into_iter().find(|(_, bytes)| *bytes > binding) {
            return Some(format!("needs {} for its {what}, more than this adapter binds at once ({}): use a coarser mesh", mib(bytes), mib(binding)));
        }
        (rows > limits.max_texture_dimension_2d).then(|| {
            format!(
                "has {} vertices, more rays than this adapter's largest texture holds ({} rows of {per_row}): use a coarser mesh",
                self.vertices, limits.max_texture_dimension_2d
            )
        })
    }

    /// The topology of a mesh's triangles, checked.
    fn of(vertices: usize, triangles: Vec<u32>) -> Result<Self, String> {
        let corners: Vec<[u32; 3]> = triangles.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        // Positions do not matter to the fans: the topology's mesh stands at the origin.
        let mesh = TriMesh::new(vec![glam::Vec3::ZERO; vertices], vec![glam::Vec3::Y; vertices], corners).map_err(|e| e.to_string())?;
        let fans = VertexFans::new(&mesh);
        let owned_sides =
            (0..mesh.triangles().len()).map(|t| fans.owned_edges(&mesh, t).iter().enumerate().map(|(i, &owned)| u32::from(owned) << i).sum()).collect();
        Ok(Self { vertices, triangles, fans, owned_sides })
    }
}

/// Gathers the build's sources again when a generator, light, receiver, shadow caster
/// or the settings changed or went away, or a generator's or occluder's mesh asset was
/// modified.
/// Receivers, shadow casters and the other generators hide generator vertices from
/// the light and end their rays: they are placed again only when one of them changed,
/// over their meshes' BVHs ([`MeshBvhs`]), which are built again only when a mesh
/// is. A generator's topology is read again only when its mesh changed.
#[allow(clippy::too_many_arguments)]
fn gather_sources(
    generators: Generators<'_, '_>,
    lights: Query<LightComponents, AnyLight>,
    occluders: Query<OccluderComponents, Without<CausticGenerator>>,
    deformed: Query<(&Mesh3d, &Aabb), With<MovesOnGpu>>,
    changed: Res<ChangedParts>,
    mut mesh_events: MessageReader<AssetEvent<Mesh>>,
    meshes: Res<Assets<Mesh>>,
    settings: Res<WarpedVolumesSettings>,
    (mut sources, mut bvhs): (ResMut<VolumeSources>, ResMut<MeshBvhs>),
    mut volumes: ResMut<CausticVolumes>,
    mut active: ResMut<ActiveCausticTechniques>,
    mut state: Local<GatherState>,
    device: Option<Res<RenderDevice>>,
) {
    let (mut occluder_mesh_changed, mut generator_mesh_changed) = (false, false);
    let mut changed_meshes = HashSet::new();
    for event in mesh_events.read() {
        if let AssetEvent::Modified { id } | AssetEvent::Added { id } | AssetEvent::LoadedWithDependencies { id } = event {
            occluder_mesh_changed |= state.occluder_meshes.contains(id);
            generator_mesh_changed |= state.generator_meshes.contains(id);
            changed_meshes.insert(*id);
        }
    }
    let several_generators = generators.iter().filter(|(.., visible, _)| visible.get()).count() > 1;
    let changed = *changed;
    let generators_changed = generator_mesh_changed
        || changed.generators
        // A mesh that had not loaded at the last gathering.
        || generators.iter().any(|(_, _, _, m, ..)| !state.generator_meshes.contains(&m.id()));
    let outgrown = deformed.iter().any(|(mesh3d, aabb)| {
        state.deformed_bounds.get(&mesh3d.id()).is_some_and(|placed| (aabb.min().cmplt(placed.min()) | aabb.max().cmpgt(placed.max())).any())
    });
    let occluders_changed = occluder_mesh_changed || changed.occluders || (several_generators && generators_changed) || outgrown;
    if !(occluders_changed || generators_changed || settings.is_changed() || changed.lights) {
        return;
    }
    sources.settings = settings.core();
    sources.draws_beams = settings.shaft_integral == super::ShaftIntegral::Exact;
    sources.lights = core_lights(&lights);
    // Volumes end beyond the receivers' world bounds.
    sources.bounds = occluders
        .iter()
        .filter(|(_, receiver, _)| *receiver)
        .filter_map(|((_, t, _, aabb), ..)| aabb.map(|a| world_aabb(t, a)))
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
        .map(|(lo, hi)| (to_core(lo), to_core(hi)));
    // Every generator shadows the others (`occluders_of`): the volumes' own, and the
    // ones other techniques draw; each passes through its own mesh.
    let mut volume_generators = Vec::new();
    let mut occluder_meshes: Vec<(AssetId<Mesh>, Mat4, u32, Option<Aabb>)> = Vec::new();
    state.generator_meshes.clear();
    let mut index = 0;
    for (entity, generator, choice, mesh3d, transform, visible, moves_on_gpu) in &generators {
        state.generator_meshes.insert(mesh3d.id());
        let (Some(mesh), true) = (meshes.get(&mesh3d.0), visible.get()) else {
            continue;
        };
        index += 1;
        // A malformed mesh shadows nothing; the warning below says why it is skipped.
        if several_generators && occluders_changed {
            occluder_meshes.push((mesh3d.id(), transform.to_matrix(), index, None));
        }
        if choice.technique() != CausticTechnique::WarpedVolumes {
            continue;
        }
        let topology = match state.topologies.get(&entity) {
            Some((id, known)) if *id == mesh3d.id() && !changed_meshes.contains(id) => Ok(known.clone()),
            known => match known {
                Some((_, known)) if known.fits(mesh) => Ok(known.clone()),
                _ => triangle_indices(mesh).and_then(|(vertices, triangles)| Topology::of(vertices, triangles)).map(Arc::new),
            }
            .and_then(|topology| {
                // Positions and normals, as the build's copy holds them, at the least.
                let vertex_bytes = mesh.count_vertices() as u64 * mesh.get_vertex_size().max(24);
                match unusable_vertex(mesh).or_else(|| device.as_ref().and_then(|d| topology.unbindable(vertex_bytes, &d.limits()))) {
                    Some(problem) => Err(problem),
                    None => Ok(topology),
                }
            }),
        };
        match topology {
            Ok(topology) => {
                state.warned.remove(&entity);
                state.topologies.insert(entity, (mesh3d.id(), topology.clone()));
                let interaction = generator.specular_interaction();
                volume_generators.push((
                    entity,
                    VolumeGenerator {
                        mesh: mesh3d.id(),
                        world_from_local: transform.to_matrix(),
                        two_sided: choice.facts().sides.lit_from_behind(&interaction),
                        interaction,
                        topology,
                        occluder_index: if several_generators { index } else { caustics_core::triangle_bvh::NO_MESH },
                        moves_on_gpu,
                    },
                ));
            }
            Err(e) => {
                if state.warned.insert(entity) {
                    warn!("bevy_caustics: the mesh of CausticGenerator {entity} is skipped: it {e}");
                }
            }
        }
    }
    state.topologies.retain(|entity, _| volume_generators.iter().any(|(e, _)| e == entity));
    if occluders_changed {
        // What shadows the generators: receivers and the other meshes that cast shadows.
        state.occluder_meshes.clear();
        for ((mesh3d, transform, visible, _), receiver, no_shadows) in &occluders {
            if !blocks_caustic_light(visible, receiver, no_shadows) {
                continue;
            }
            state.occluder_meshes.insert(mesh3d.id());
            occluder_meshes.push((mesh3d.id(), transform.to_matrix(), SHADOW_CASTER, None));
        }
        // A surface deformed on the GPU is held in the top level by its bounds, and its
        // tree refit to each frame's vertices in the render world.
        let moving: HashMap<AssetId<Mesh>, Aabb> = deformed.iter().map(|(mesh3d, aabb)| (mesh3d.id(), *aabb)).collect();
        state.deformed_bounds.clear();
        for (mesh, _, _, bounds) in &mut occluder_meshes {
            *bounds = moving.get(mesh).copied();
            if let Some(aabb) = bounds {
                state.deformed_bounds.insert(*mesh, *aabb);
            }
        }
        sources.deformed = state.deformed_bounds.keys().filter_map(|mesh| Some((*mesh, bvhs.get(*mesh, &meshes)?))).collect();
        sources.occluders = Arc::new(bvhs.place(occluder_meshes, &meshes));
    }
    active.warped_volumes = !volume_generators.is_empty() && !sources.lights.is_empty() && sources.bounds.is_some();
    sources.generators = volume_generators;
    sources.generation += 1;
    volumes.gathered += 1;
}

/// Takes the counts of the newest GPU build that came back.
fn receive_stats(channel: Res<BuildStatsChannel>, mut volumes: ResMut<CausticVolumes>) {
    if let Some(stats) = channel.0.lock().ok().and_then(|mut s| s.take()) {
        volumes.stats = stats;
        volumes.generation += 1;
    }
    if let Some(surface) = channel.1.lock().ok().and_then(|mut s| s.take()) {
        volumes.surface = surface;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` quads: 2n + 2 vertices, 2n triangles.
    fn strip(n: u32) -> Topology {
        let triangles = (0..n).flat_map(|i| [2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 1, 2 * i + 3, 2 * i + 2]).collect();
        Topology::of(2 * n as usize + 2, triangles).unwrap()
    }

    #[test]
    fn a_generator_past_the_adapters_bindings_is_refused_with_the_reason() {
        let topology = strip(1000);
        let limits = WgpuLimits::downlevel_defaults();
        // 2002 rays and the slicing axis, 16 a row in a texture 200 texels wide: 126
        // rows of 1792 bytes.
        let narrow = WgpuLimits { max_texture_dimension_2d: 200, ..limits.clone() };
        assert_eq!(rays_per_row(&narrow), 16);
        let rays = 126 * 16 * VERTEX_RAY_BYTES;
        let bound =
            |vertex_bytes: u64, binding: u64| topology.unbindable(vertex_bytes, &WgpuLimits { max_storage_buffer_binding_size: binding, ..narrow.clone() });
        assert_eq!(bound(rays, rays), None);
        assert!(bound(rays, rays - 4).is_some_and(|why| why.contains("for its vertex rays")));
        assert!(bound(rays + 4, rays).is_some_and(|why| why.contains("for its vertices")));
        let tiny = WgpuLimits { max_buffer_size: 4096, ..limits.clone() };
        assert!(topology.unbindable(0, &tiny).is_some_and(|why| why.contains("more than this adapter binds at once (0.0 MiB)")));
        // 126 rows of 16 rays in a texture at most 125 texels tall.
        let short = WgpuLimits { max_texture_dimension_2d: 125, ..limits };
        assert!(topology.unbindable(0, &short).is_some_and(|why| why.contains("largest texture holds (125 rows of 16)")));
    }
}
