//! Render world: the caustic volumes built on the GPU (`build.wgsl`), once per change
//! of their sources and every frame while a generator's mesh moves on the GPU (an
//! ocean): the generators' vertices as this frame draws them, read from Bevy's own
//! vertex buffers (copied only for a mesh without normals, whose smooth normals are
//! made here), their topology (uploaded when it changes), the lights and the
//! occluders' BVH. One job per generator, light and colour channel runs five
//! dispatches (vertex rays, slicing axis, triangle areas, vertex fans, triangle volumes) that append the volumes
//! kept to [`VolumeBuffers::volumes`] and count them as the instances of the passes'
//! indirect draw; the counts of what was dropped go back to the main world.

use super::build::{BuildStatsChannel, RAY_TEXELS, Topology, VolumeGenerator, VolumeSources, rays_per_row};
use super::render::{GpuCausticVolume, VolumeBuffers, VolumeTexture, WordsReadback, texel_texture};
use crate::gpu_budget::{CausticGpuBudget, mib};
use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::bvh_refit::{BvhRefit, BvhRefitPipelines, DrawnMeshes};
use crate::irradiance::kept_bind_group::{Bound, KeptBindGroup, KeptLayout};
use crate::irradiance::mesh_bvhs::InstancedBvhBuffer;
use crate::mesh_vertices::MeshVertices;
use crate::report::PassRecorder;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::{
    Extract,
    diagnostic::RecordDiagnostics,
    mesh::{RenderMesh, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_resource::{
        binding_types::{storage_buffer_read_only_sized, storage_buffer_sized, texture_2d, texture_storage_2d, uniform_buffer},
        *,
    },
    renderer::{RenderContext, RenderDevice, RenderQueue},
};
use caustics_core::glam;
use caustics_core::mesh::TriMesh;
use caustics_core::scene::{Light, LightKind};
use caustics_core::triangle_bvh::InstancedBvh;
use caustics_core::volumes::{BuildStats, channels};
use std::sync::{Arc, Mutex};

/// `BuildJob` in `build.wgsl`: one generator under one light in one colour channel.
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
struct GpuBuildJob {
    world_from_local: Mat4,
    normal_from_local: Mat4,
    light: Vec4,
    spot: Vec4,
    light_power: Vec4,
    color: Vec4,
    bounds_lo: Vec4,
    bounds_hi: Vec4,
    counts: UVec4,
    vertex: UVec4,
}

/// The words of `counters` in `build.wgsl`: the indirect draw (36 vertices, the
/// instances, two zeros), five counts, the kept and the dropped flux (f32 bits), the
/// surface slabs and the escaping volumes.
const COUNTER_WORDS: usize = 17;

/// The counters before a build: an indirect draw of no instance.
const EMPTY_COUNTERS: [u32; COUNTER_WORDS] = {
    let mut words = [0; COUNTER_WORDS];
    words[0] = 36;
    words
};

fn v4(v: glam::Vec3, w: f32) -> Vec4 {
    Vec4::new(v.x, v.y, v.z, w)
}

impl GpuBuildJob {
    /// The job of `generator` under `light` in one channel (its index of refraction,
    /// `None` for a mirror, and its flux colour), against the occluders' BVH whose
    /// instances start at `occluders`, its vertices read through `vertex`
    /// ([`MeshVertices::layout`]).
    fn new(
        generator: &VolumeGenerator,
        light: &Light,
        (ior, color): (Option<f32>, glam::Vec3),
        sources: &VolumeSources,
        (occluders, vertex): (u32, UVec4),
    ) -> Self {
        let (light_vec, spot, power, spot_scale) = match light.kind {
            LightKind::Directional { direction, irradiance } => (v4(direction.normalize(), 0.0), Vec4::ZERO, irradiance, 0.0),
            LightKind::Point { position, intensity } => (v4(position, 1.0), Vec4::ZERO, intensity, 0.0),
            LightKind::Spot { position, direction, intensity, inner_angle, outer_angle } => {
                // `Light::cone_attenuation`'s constants.
                let (cos_outer, cos_inner) = (outer_angle.cos(), inner_angle.min(outer_angle).cos());
                let axis = direction.normalize_or(glam::Vec3::NEG_Y);
                (v4(position, 1.0), v4(axis, cos_outer), intensity, 1.0 / (cos_inner - cos_outer).max(1e-4))
            }
        };
        let (lo, hi) = sources.bounds.unwrap_or_default();
        Self {
            world_from_local: generator.world_from_local,
            normal_from_local: Mat4::from_mat3(Mat3::from_mat4(generator.world_from_local).inverse().transpose()),
            light: light_vec,
            spot,
            light_power: Vec4::new(power, spot_scale, light.inverse_range_squared(), f32::from(u8::from(sources.draws_beams))),
            color: v4(color, ior.unwrap_or(0.0)),
            bounds_lo: v4(lo, sources.settings.min_ray_cosine),
            bounds_hi: v4(hi, if generator.two_sided { 1.0 } else { 0.0 }),
            counts: UVec4::new(generator.topology.vertices as u32, generator.topology.owned_sides.len() as u32, occluders, generator.occluder_index),
            vertex,
        }
    }
}

/// Where the build reads a generator's vertices.
enum VertexSource {
    /// From the buffer Bevy draws its mesh from.
    Drawn,
    /// From a copy: positions and smooth normals made here (a mesh without normals),
    /// interleaved.
    Copied(Vec<[f32; 3]>),
    /// Nowhere: its mesh is not there, or no longer fits its topology.
    Missing,
}

/// Render world: the sources of the last gathering, and where each generator's
/// vertices are read, when they are new.
#[derive(Resource, Default)]
pub(super) struct ExtractedSources {
    generation: u64,
    sources: VolumeSources,
    vertices: Vec<VertexSource>,
    /// The sources changed at this frame's extraction.
    pub(super) new: bool,
}

/// Where the build reads the vertices of a generator's mesh: Bevy's vertex buffer when
/// it has `Float32x3` positions and normals fitting its topology; a copy with smooth
/// normals made here for a mesh without normals.
fn vertex_source(mesh: &Mesh, topology: &Topology) -> VertexSource {
    use bevy::mesh::VertexAttributeValues::Float32x3;
    let Ok(Float32x3(positions)) = mesh.try_attribute(Mesh::ATTRIBUTE_POSITION) else {
        return VertexSource::Missing;
    };
    if positions.len() != topology.vertices {
        return VertexSource::Missing;
    }
    if matches!(mesh.try_attribute(Mesh::ATTRIBUTE_NORMAL), Ok(Float32x3(normals)) if normals.len() == positions.len()) {
        return VertexSource::Drawn;
    }
    let corners = topology.triangles.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    match TriMesh::with_smooth_normals(positions.iter().map(|&p| glam::Vec3::from_array(p)).collect(), corners) {
        Ok(smooth) => VertexSource::Copied(positions.iter().zip(smooth.normals()).flat_map(|(p, n)| [*p, n.to_array()]).collect()),
        Err(_) => VertexSource::Missing,
    }
}

pub(super) fn extract_sources(mut extracted: ResMut<ExtractedSources>, sources: Extract<Res<VolumeSources>>, meshes: Extract<Res<Assets<Mesh>>>) {
    extracted.new = extracted.generation != sources.generation;
    if !extracted.new {
        return;
    }
    extracted.generation = sources.generation;
    extracted.vertices = sources.generators.iter().map(|(_, g)| meshes.get(g.mesh).map_or(VertexSource::Missing, |m| vertex_source(m, &g.topology))).collect();
    extracted.sources = (**sources).clone();
}

/// One generator's buffers: its topology, the copy of its vertices (a mesh without
/// normals) and its per-vertex rays.
struct GeneratorBuffers {
    topology: Arc<Topology>,
    /// Triangles, fans (each vertex's first entry, then the fans' triangles), owned
    /// sides.
    indices: [Buffer; 3],
    copy: Option<Buffer>,
    rays: Buffer,
    /// `rays` as `triangle_volumes` reads them, copied into a texture
    /// ([`Dispatch::ray_texels`]).
    ray_texels: (Texture, TextureView),
    /// Each triangle's area coefficients along the shared slicing axis (`build.wgsl`).
    areas: Buffer,
    bind_group: KeptBindGroup,
}

/// A job's dispatch: its generator's bind group, its uniform offset, its vertices and
/// triangles, and its rays' buffer and texture, copied from one to the other between
/// the fans and the volumes.
struct Dispatch {
    bind_group: BindGroup,
    rays: Buffer,
    ray_texels: Texture,
    offset: u32,
    vertices: u32,
    triangles: u32,
}

/// Render world: what the build runs with, and whether it runs this frame.
#[derive(Resource, Default)]
pub(super) struct VolumeBuild {
    generators: HashMap<Entity, GeneratorBuffers>,
    /// The occluders' `InstancedBvh` as last uploaded, with the one it holds.
    occluders: Option<(Arc<InstancedBvh>, InstancedBvhBuffer, Buffer)>,
    /// The refit of the occluders deformed on the GPU, every frame they move.
    refit: BvhRefit,
    jobs: DynamicUniformBuffer<GpuBuildJob>,
    /// What `jobs` holds, and each one's offset: the same jobs are not uploaded again.
    written_jobs: (Vec<GpuBuildJob>, Vec<u32>),
    /// [`EMPTY_COUNTERS`], copied over the counters before each build.
    empty_counters: Option<Buffer>,
    dispatches: Vec<Dispatch>,
    /// A generator's vertices were not uploaded yet at the last build: build again.
    retry: bool,
    /// The volumes asked for when the adapter's limit last lowered them (warned once).
    clamped: Option<u64>,
    /// The counters' copy that the main world's [`super::CausticVolumes`] reads.
    readback: WordsReadback,
    /// The sources' generation of the build whose counters were copied last.
    copied_generation: u64,
    /// The volumes a build of a generation kept, as read back.
    counted: Arc<Mutex<Option<(u64, u32)>>>,
    /// The colour every volume of the last build shares up to a factor (summing to
    /// one), if they share one: the shafts' grid then adds one channel of light.
    pub(super) hue: Option<glam::Vec3>,
}

impl VolumeBuild {
    /// Whether the volumes are built this frame.
    pub(super) fn builds_this_frame(&self) -> bool {
        !self.dispatches.is_empty()
    }
}

/// The build's pipelines (vertex rays, slicing axis, triangle areas, vertex fans, triangle volumes, and
/// the empty `anchor` of [`anchor_first_timestamp`]) and layout, and the occluders' refit.
#[derive(Resource)]
pub(super) struct VolumeBuildPipelines {
    layout: KeptLayout,
    pipelines: [CachedComputePipelineId; 6],
    refit: BvhRefitPipelines,
}

pub(super) fn init_pipelines(mut commands: Commands, asset_server: Res<AssetServer>, cache: Res<PipelineCache>) {
    let read = || storage_buffer_read_only_sized(false, None);
    let layout = BindGroupLayoutDescriptor::new(
        "caustic_volume_build_layout",
        &BindGroupLayoutEntries::with_indices(
            ShaderStages::COMPUTE,
            (
                (0, uniform_buffer::<GpuBuildJob>(true)),
                (1, read()),
                (3, read()),
                (4, read()),
                (5, storage_buffer_sized(false, None)),
                (6, read()),
                (7, storage_buffer_sized(false, None)),
                (8, texture_storage_2d(TextureFormat::Rgba32Float, StorageTextureAccess::WriteOnly)),
                (9, storage_buffer_sized(false, None)),
                (10, texture_2d(TextureSampleType::Float { filterable: false })),
                (14, read()),
            ),
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "build.wgsl");
    let pipelines = crate::irradiance::compute_pipelines(
        &cache,
        "caustic_volume",
        &layout,
        &shader,
        ["vertex_rays", "slicing_axis", "triangle_areas", "vertex_fans", "triangle_volumes", "anchor"],
    );
    commands.insert_resource(VolumeBuildPipelines { layout: KeptLayout::new(layout), pipelines, refit: BvhRefitPipelines::new(&cache, &asset_server) });
}

fn storage(device: &RenderDevice, label: &'static str, contents: &[u8]) -> Buffer {
    // A binding may not be empty.
    let contents = if contents.is_empty() { &[0; 4][..] } else { contents };
    device.create_buffer_with_data(&BufferInitDescriptor { label: Some(label), contents, usage: BufferUsages::STORAGE | BufferUsages::COPY_DST })
}

impl GeneratorBuffers {
    fn new(device: &RenderDevice, topology: &Arc<Topology>) -> Self {
        let bytes = |words: &[u32]| bytemuck::cast_slice::<u32, u8>(words).to_vec();
        let per_row = rays_per_row(&device.limits());
        Self {
            topology: topology.clone(),
            indices: [
                storage(device, "caustic_volume_triangles", &bytes(&topology.triangles)),
                storage(device, "caustic_volume_fans", &bytes(&[topology.fans.starts(), topology.fans.triangles()].concat())),
                storage(device, "caustic_volume_owned_sides", &bytes(&topology.owned_sides)),
            ],
            copy: None,
            rays: device.create_buffer(&BufferDescriptor {
                label: Some("caustic_volume_vertex_rays"),
                size: topology.ray_bytes(per_row),
                usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            ray_texels: texel_texture(
                device,
                "caustic_volume_vertex_ray_texels",
                UVec2::new(per_row * RAY_TEXELS, topology.ray_rows(per_row)),
                TextureUsages::COPY_DST | TextureUsages::TEXTURE_BINDING,
            ),
            areas: device.create_buffer(&BufferDescriptor {
                label: Some("caustic_volume_triangle_areas"),
                size: (topology.triangles.len() / 3).max(1) as u64 * 16,
                usage: BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
            bind_group: KeptBindGroup::default(),
        }
    }

    /// The generator's vertices for this build: Bevy's vertex buffer, or the copy
    /// (uploaded here), laid out as [`MeshVertices::layout`] says.
    fn vertices(&mut self, source: &VertexSource, mesh: AssetId<Mesh>, (meshes, allocator, device, queue): DrawnMeshes) -> Option<MeshVertices> {
        match source {
            VertexSource::Drawn => MeshVertices::of(mesh, meshes, allocator, device).filter(|v| v.count as usize == self.topology.vertices),
            VertexSource::Copied(interleaved) => {
                let bytes: &[u8] = bytemuck::cast_slice(interleaved);
                let copy = match &self.copy {
                    Some(copy) if copy.size() == bytes.len() as u64 => {
                        queue.write_buffer(copy, 0, bytes);
                        copy.clone()
                    }
                    _ => self.copy.insert(storage(device, "caustic_volume_vertices", bytes)).clone(),
                };
                Some(MeshVertices {
                    size: std::num::NonZeroU64::new(copy.size())?,
                    buffer: copy,
                    offset: 0,
                    layout: UVec4::new(0, 6, 0, 3),
                    count: self.topology.vertices as u32,
                })
            }
            VertexSource::Missing => None,
        }
    }
}

/// When the sources are new, a generator's or an occluder's mesh moves on the GPU or
/// the last build missed a mesh's vertices: uploads the topology and occluders that
/// changed, plans the refit of the deformed occluders, writes the jobs when they
/// changed and sizes the volumes for every triangle of every job.
pub(super) fn prepare_build(
    extracted: Res<ExtractedSources>,
    mut build: ResMut<VolumeBuild>,
    mut buffers: ResMut<VolumeBuffers>,
    pipelines: Res<VolumeBuildPipelines>,
    cache: Res<PipelineCache>,
    (meshes, allocator): (Res<RenderAssets<RenderMesh>>, Res<MeshAllocator>),
    (device, queue, budget): (Res<RenderDevice>, Res<RenderQueue>, Res<CausticGpuBudget>),
) {
    // A build read back with no volume for the current sources: nothing to draw.
    if let Some((generation, volumes)) = build.counted.lock().ok().and_then(|mut c| c.take()) {
        buffers.empty = generation == extracted.generation && volumes == 0;
    }
    let moving = extracted.sources.generators.iter().any(|(_, g)| g.moves_on_gpu) || !extracted.sources.deformed.is_empty();
    if !(extracted.new || moving || build.retry) {
        return;
    }
    buffers.empty = false;
    build.retry = false;
    let build = &mut *build;
    let sources = &extracted.sources;
    build.generators.retain(|entity, _| sources.generators.iter().any(|(e, _)| e == entity));
    let mut jobs = Vec::new();
    let mut planned = Vec::new();
    let mut capacity = 0u64;
    let mut hues = Vec::new();
    let mut vertex_bindings = HashMap::new();
    for ((entity, generator), source) in sources.generators.iter().zip(&extracted.vertices) {
        if build.generators.get(entity).is_none_or(|known| !Arc::ptr_eq(&known.topology, &generator.topology)) {
            build.generators.insert(*entity, GeneratorBuffers::new(&device, &generator.topology));
        }
        let Some(g) = build.generators.get_mut(entity) else { continue };
        let Some(vertices) = g.vertices(source, generator.mesh, (&meshes, &allocator, &device, &queue)) else {
            // Not uploaded yet (a mesh added this frame): the next frame builds again.
            build.retry |= matches!(source, VertexSource::Drawn);
            continue;
        };
        let layout = vertices.layout;
        vertex_bindings.insert(*entity, vertices);
        for light in &sources.lights {
            for channel in channels(&generator.interaction, light.color) {
                hues.push(channel.1);
                let job = GpuBuildJob::new(generator, light, channel, sources, (sources.occluders.gpu_instance_offset(), layout));
                planned.push((*entity, jobs.len(), job.counts));
                jobs.push(job);
                capacity += u64::from(job.counts.y);
            }
        }
    }
    build.hue = shared_hue(&hues);
    if build.jobs.buffer().is_none() || build.written_jobs.0 != jobs {
        build.jobs.clear();
        let offsets = jobs.iter().map(|job| build.jobs.push(job)).collect();
        build.jobs.set_label(Some("caustic_volume_jobs"));
        build.jobs.write_buffer(&device, &queue);
        build.written_jobs = (jobs, offsets);
    }
    build.dispatches.clear();
    if capacity == 0 || sources.bounds.is_none() {
        // Nothing to build: the GPU memory goes back (the counters' readback buffer
        // once no copy is on its way).
        (buffers.volumes, buffers.counters, build.occluders, build.empty_counters) = (None, None, None, None);
        (build.jobs, build.written_jobs, build.refit) = default();
        return;
    }
    let occluders = match &mut build.occluders {
        Some((bvh, _, buffer)) if Arc::ptr_eq(bvh, &sources.occluders) => buffer.clone(),
        uploaded => {
            let mut gpu = uploaded.take().map(|(_, gpu, _)| gpu).unwrap_or_default();
            let buffer = gpu.write(&sources.occluders, "caustic_volume_occluders", &device, &queue);
            *uploaded = Some((sources.occluders.clone(), gpu, buffer.clone()));
            buffer
        }
    };
    build.refit.prepare(&sources.occluders, &occluders, &sources.deformed, &pipelines.refit, (&meshes, &allocator, &device, &queue), &cache);
    let volume_bytes = GpuCausticVolume::min_size().get();
    let bindable = VolumeTexture::largest(&device).min(budget.bytes / volume_bytes);
    if capacity > bindable {
        if build.clamped != Some(capacity) {
            warn!(
                "bevy_caustics: the caustic volumes of {capacity} generator triangles (per light and colour channel) need {}, more than this adapter's largest texture holds \
                 or CausticGpuBudget allows ({}): the first {bindable} volumes built are drawn and the rest dropped (counted in CausticVolumes' \
                 dropped flux); use coarser generator meshes",
                mib(capacity * volume_bytes),
                mib(bindable * volume_bytes)
            );
        }
        build.clamped = Some(capacity);
        capacity = bindable;
    }
    if buffers.volumes.as_ref().is_none_or(|v| v.capacity() < capacity) {
        buffers.volumes = Some(VolumeTexture::new(&device, capacity));
    }
    let counters = buffers
        .counters
        .get_or_insert_with(|| {
            device.create_buffer(&BufferDescriptor {
                label: Some("caustic_volume_counters"),
                size: (COUNTER_WORDS * 4) as u64,
                usage: BufferUsages::STORAGE | BufferUsages::INDIRECT | BufferUsages::COPY_DST | BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        })
        .clone();
    build.empty_counters.get_or_insert_with(|| {
        device.create_buffer_with_data(&BufferInitDescriptor {
            label: Some("caustic_volume_empty_counters"),
            contents: bytemuck::cast_slice(&EMPTY_COUNTERS),
            usage: BufferUsages::COPY_SRC,
        })
    });
    let (Some(jobs), Some(volumes)) = (build.jobs.binding(), buffers.volumes.as_ref().map(|v| &v.view)) else {
        return;
    };
    let layout = pipelines.layout.get(&cache);
    let Some(jobs_buffer) = build.jobs.buffer().cloned() else { return };
    for (entity, job, counts) in planned {
        let offset = build.written_jobs.1[job];
        let (Some(g), Some(vertices)) = (build.generators.get_mut(&entity), vertex_bindings.get(&entity)) else { continue };
        let [a, b, c] = g.indices.each_ref().map(Bound::from);
        let bound = [
            layout.into(),
            (&jobs_buffer).into(),
            vertices.bound(),
            a,
            b,
            (&g.areas).into(),
            c,
            (&g.rays).into(),
            volumes.into(),
            (&g.ray_texels.1).into(),
            (&counters).into(),
            (&occluders).into(),
        ];
        let (indices, rays, areas, ray_texels) = (&g.indices, &g.rays, &g.areas, &g.ray_texels.1);
        let bind_group = g.bind_group.get(&bound, || {
            device.create_bind_group(
                "caustic_volume_build_bind_group",
                layout,
                &BindGroupEntries::with_indices((
                    (0, jobs.clone()),
                    (1, BindingResource::Buffer(vertices.binding())),
                    (3, indices[0].as_entire_binding()),
                    (4, indices[1].as_entire_binding()),
                    (5, areas.as_entire_binding()),
                    (6, indices[2].as_entire_binding()),
                    (7, rays.as_entire_binding()),
                    (8, volumes),
                    (9, counters.as_entire_binding()),
                    (10, ray_texels),
                    (14, occluders.as_entire_binding()),
                )),
            )
        });
        build.dispatches.push(Dispatch {
            bind_group,
            rays: g.rays.clone(),
            ray_texels: g.ray_texels.0.clone(),
            offset,
            vertices: counts.x,
            triangles: counts.y,
        });
    }
}

/// Once per change of the sources (every frame while they move on the GPU): the
/// counters started again, every job's five dispatches, then a copy of the counters
/// for the main world, at once for new sources.
pub(super) fn build_volumes(
    mut ctx: RenderContext,
    mut build: ResMut<VolumeBuild>,
    buffers: Res<VolumeBuffers>,
    extracted: Res<ExtractedSources>,
    pipelines: Res<VolumeBuildPipelines>,
    cache: Res<PipelineCache>,
    recorder: Res<PassRecorder>,
) {
    let Some(kernels) = pipelines.pipelines.iter().map(|id| cache.get_compute_pipeline(*id)).collect::<Option<Vec<_>>>() else {
        return;
    };
    let build = &mut *build;
    let (Some(counters), Some(empty), false) = (buffers.counters.as_ref(), build.empty_counters.as_ref(), build.dispatches.is_empty()) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let encoder = ctx.command_encoder();
    if build.refit.is_planned() {
        let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor { label: Some("caustic_occluder_refit"), ..default() });
        let span = diagnostics.pass_span(&mut pass, "caustics/occluder_refit");
        build.refit.dispatch(&mut pass, &pipelines.refit, &cache, diagnostics.is_some());
        span.end(&mut pass);
        recorder.record("occluder refit");
    }
    encoder.copy_buffer_to_buffer(empty, 0, counters, 0, empty.size());
    // Each job in two passes (spans of one name add up): its rays, axis, areas and
    // fans, then, once the rays are copied into their texture, its volumes.
    let anchor = kernels[5];
    for dispatch in &build.dispatches {
        let (vertices, triangles) = (dispatch.vertices.div_ceil(64), dispatch.triangles.div_ceil(64));
        let build_pass = |encoder: &mut CommandEncoder, kernels: &[&ComputePipeline], groups: &[u32]| {
            let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor { label: Some("caustic_volume_build"), ..default() });
            let span = diagnostics.pass_span(&mut pass, "caustics/volume_build");
            pass.set_bind_group(0, &dispatch.bind_group, &[dispatch.offset]);
            anchor_first_timestamp(&mut pass, diagnostics.is_some(), Some(anchor));
            for (kernel, &groups) in kernels.iter().zip(groups) {
                pass.set_pipeline(kernel);
                pass.dispatch_workgroups(groups, 1, 1);
            }
            span.end(&mut pass);
        };
        build_pass(encoder, &kernels[..4], &[vertices, 1, triangles, vertices]);
        let rays = TexelCopyBufferInfo {
            buffer: &dispatch.rays,
            layout: TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(dispatch.ray_texels.width() * 16), rows_per_image: None },
        };
        encoder.copy_buffer_to_texture(rays, dispatch.ray_texels.as_image_copy(), dispatch.ray_texels.size());
        build_pass(encoder, &kernels[4..5], &[triangles]);
    }
    build.dispatches.clear();
    recorder.record("volume build");
    let device = ctx.render_device().clone();
    // New sources are counted at once: an empty build draws nothing from then on.
    if build.readback.copy(&device, ctx.command_encoder(), (counters, COUNTER_WORDS as u64), "caustic_volume_counters_readback", extracted.new) {
        build.copied_generation = extracted.generation;
    }
}

/// The colour `colours` share up to a positive factor, summing to one (the black ones
/// aside), or `None` where two differ in hue.
fn shared_hue(colours: &[glam::Vec3]) -> Option<glam::Vec3> {
    let mut hues = colours.iter().filter(|c| c.element_sum() > 0.0).map(|c| *c / c.element_sum());
    let first = hues.next().unwrap_or(glam::Vec3::ONE / 3.0);
    hues.all(|h| h.abs_diff_eq(first, 1e-6)).then_some(first).filter(|h| h.is_finite() && h.min_element() >= 0.0)
}

/// The counts of a build, from its counters.
fn stats_of(words: &[u32]) -> BuildStats {
    let flux =
        |i: usize| glam::DVec3::new(f64::from(f32::from_bits(words[i])), f64::from(f32::from_bits(words[i + 1])), f64::from(f32::from_bits(words[i + 2])));
    BuildStats {
        volumes: words[1] as usize,
        unlit: words[4] as usize,
        shadowed: words[5] as usize,
        total_internal_reflection: words[6] as usize,
        grazing: words[7] as usize,
        degenerate: words[8] as usize,
        flux: flux(9),
        dropped_flux: flux(12),
        surface_slabs: words[15] as usize,
        escaping: words[16] as usize,
    }
}

/// After this frame's commands went in: reads the counters copied this frame back, on
/// to the main world.
pub(super) fn read_back_counts(mut build: ResMut<VolumeBuild>, channel: Res<BuildStatsChannel>) {
    let (generation, channel, counted) = (build.copied_generation, channel.0.clone(), build.counted.clone());
    build.readback.read_back(move |words| {
        if let (Ok(mut stats), Ok(mut count)) = (channel.lock(), counted.lock()) {
            *stats = Some(stats_of(words));
            *count = Some((generation, words[1]));
        }
    });
}
