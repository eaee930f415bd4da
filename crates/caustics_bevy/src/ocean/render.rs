//! Render world: oceans evaluated on the GPU (`waves.wgsl`). Each frame, for every
//! [`super::Ocean`] animated there, the spectrum of eq. 43 at the frame's time, its
//! inverse FFTs and the displaced vertices are computed and written over the positions
//! and normals of the ocean's mesh in Bevy's vertex buffer, before anything reads or
//! draws it (the caustic volumes' build included). The spectrum's amplitudes go up once
//! per change of the ocean's settings; a frame costs the CPU one uniform write.

use super::{OceanModes, OceanWaves};
use crate::cpu_time::timed;
use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::kept_bind_group::{KeptBindGroup, KeptLayout};
use crate::mesh_vertices::MeshVertices;
use crate::mesh_vertices::MovesOnGpu;
use crate::report::PassRecorder;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::{
    Extract, Render, RenderApp, RenderStartup, RenderSystems,
    diagnostic::RecordDiagnostics,
    mesh::{RenderMesh, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_resource::{
        binding_types::{storage_buffer_read_only_sized, storage_buffer_sized, uniform_buffer},
        *,
    },
    renderer::{RenderContext, RenderDevice, RenderQueue},
};
use std::sync::Arc;

/// `OceanStep` in `waves.wgsl`: one dispatch's parameters.
#[derive(Clone, Copy, Default, ShaderType)]
struct OceanStep {
    resolution: u32,
    fields: u32,
    half_span: u32,
    axis: u32,
    size: f32,
    choppiness: f32,
    time: f32,
    pad: f32,
    vertex: UVec4,
}

/// One ocean to animate this frame.
struct ExtractedOcean {
    entity: Entity,
    mesh: AssetId<Mesh>,
    modes: Arc<OceanModes>,
    resolution: u32,
    size: f32,
    choppiness: f32,
    time: f32,
}

#[derive(Resource, Default)]
struct ExtractedOceans(Vec<ExtractedOcean>);

/// An ocean's buffers: its spectrum's amplitudes and frequencies, and the two halves
/// of the FFT's ping-pong; and its two bind groups, kept while they bind the same.
struct OceanBuffers {
    modes: Arc<OceanModes>,
    amplitudes: Buffer,
    omega: Buffer,
    fields: [Buffer; 2],
    bind_groups: [KeptBindGroup; 2],
}

/// A prepared ocean: its bind groups (fields 1 → 0 and 0 → 1), the uniform offset of
/// each dispatch (spectrum, the FFT stages, vertices) and its size.
struct OceanDispatches {
    bind_groups: [BindGroup; 2],
    offsets: Vec<u32>,
    resolution: u32,
    fields: u32,
}

#[derive(Resource, Default)]
struct GpuOceans {
    buffers: HashMap<Entity, OceanBuffers>,
    steps: DynamicUniformBuffer<OceanStep>,
    dispatches: Vec<OceanDispatches>,
}

#[derive(Resource)]
struct OceanPipelines {
    layout: KeptLayout,
    /// Spectrum, FFT stage, vertices, and the empty `anchor` of [`anchor_first_timestamp`].
    pipelines: [CachedComputePipelineId; 4],
}

pub(super) fn build(app: &mut App) {
    bevy::asset::embedded_asset!(app, "waves.wgsl");
    let cpu = crate::CausticCpuTime::of(app).render;
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedOceans>()
        .init_resource::<GpuOceans>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, timed(&cpu, extract_oceans))
        .add_systems(
            Render,
            timed(&cpu, prepare_oceans)
                .run_if(|extracted: Res<ExtractedOceans>, oceans: Res<GpuOceans>| {
                    !extracted.0.is_empty() || !oceans.buffers.is_empty() || !oceans.dispatches.is_empty()
                })
                .in_set(RenderSystems::PrepareResources),
        )
        .add_systems(
            bevy::render::renderer::RenderGraph,
            timed(&cpu, animate_waves).run_if(|oceans: Res<GpuOceans>| !oceans.dispatches.is_empty()).in_set(crate::mesh_vertices::WriteMeshVertices),
        );
}

fn init_pipelines(mut commands: Commands, asset_server: Res<AssetServer>, cache: Res<PipelineCache>) {
    let layout = BindGroupLayoutDescriptor::new(
        "ocean_waves_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                uniform_buffer::<OceanStep>(true),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
            ),
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "waves.wgsl");
    let pipelines = crate::irradiance::compute_pipelines(&cache, "ocean_waves", &layout, &shader, ["spectrum", "fft_stage", "write_vertices", "anchor"]);
    commands.insert_resource(OceanPipelines { layout: KeptLayout::new(layout), pipelines });
}

/// The oceans whose waves move on the GPU.
type GpuOceanQuery<'w, 's> =
    Query<'w, 's, (Entity, &'static super::Ocean, &'static OceanWaves, &'static Mesh3d, &'static InheritedVisibility), With<MovesOnGpu>>;

fn extract_oceans(mut extracted: ResMut<ExtractedOceans>, oceans: Extract<GpuOceanQuery>, time: Extract<Res<Time>>) {
    extracted.0.clear();
    for (entity, ocean, waves, mesh, _) in oceans.iter().filter(|(.., visible)| visible.get()) {
        let settings = waves.spectrum.settings();
        extracted.0.push(ExtractedOcean {
            entity,
            mesh: mesh.id(),
            modes: waves.modes.clone(),
            resolution: settings.resolution as u32,
            size: settings.size,
            choppiness: settings.choppiness,
            time: time.elapsed_secs() * ocean.time_scale,
        });
    }
}

fn storage(device: &RenderDevice, label: &'static str, contents: &[u8]) -> Buffer {
    device.create_buffer_with_data(&BufferInitDescriptor { label: Some(label), contents, usage: BufferUsages::STORAGE })
}

impl OceanBuffers {
    fn new(device: &RenderDevice, modes: &Arc<OceanModes>, fields: u32) -> Self {
        let bytes = modes.omega.len() as u64 * u64::from(fields) * 8;
        let field = || {
            device.create_buffer(&BufferDescriptor {
                label: Some("caustic_ocean_fields"),
                size: bytes,
                usage: BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        Self {
            modes: modes.clone(),
            amplitudes: storage(device, "caustic_ocean_amplitudes", bytemuck::cast_slice(&modes.amplitudes)),
            omega: storage(device, "caustic_ocean_omega", bytemuck::cast_slice(&modes.omega)),
            fields: [field(), field()],
            bind_groups: default(),
        }
    }
}

/// Two real fields share each complex transform: height and slopes, and with
/// choppiness the displacement and its derivatives.
fn field_count(choppiness: f32) -> u32 {
    if choppiness == 0.0 { 2 } else { 4 }
}

#[expect(clippy::too_many_arguments)]
fn prepare_oceans(
    extracted: Res<ExtractedOceans>,
    mut oceans: ResMut<GpuOceans>,
    pipelines: Res<OceanPipelines>,
    cache: Res<PipelineCache>,
    meshes: Res<RenderAssets<RenderMesh>>,
    allocator: Res<MeshAllocator>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let oceans = &mut *oceans;
    oceans.buffers.retain(|entity, _| extracted.0.iter().any(|o| o.entity == *entity));
    oceans.steps.clear();
    oceans.dispatches.clear();
    let layout = pipelines.layout.get(&cache);
    let mut planned = Vec::new();
    for ocean in &extracted.0 {
        let n = ocean.resolution;
        let Some(vertices) = MeshVertices::of(ocean.mesh, &meshes, &allocator, &device).filter(|v| v.count == (n + 1) * (n + 1)) else {
            continue;
        };
        let fields = field_count(ocean.choppiness);
        if oceans.buffers.get(&ocean.entity).is_none_or(|b| !Arc::ptr_eq(&b.modes, &ocean.modes) || b.fields[0].size() != u64::from(n * n * fields) * 8) {
            oceans.buffers.insert(ocean.entity, OceanBuffers::new(&device, &ocean.modes, fields));
        }
        let base = OceanStep { resolution: n, fields, size: ocean.size, choppiness: ocean.choppiness, time: ocean.time, vertex: vertices.layout, ..default() };
        let mut offsets = vec![oceans.steps.push(&base)];
        for axis in 0..2 {
            for half_span in (0..n.ilog2()).map(|s| 1 << s) {
                offsets.push(oceans.steps.push(&OceanStep { half_span, axis, ..base }));
            }
        }
        offsets.push(oceans.steps.push(&base));
        planned.push((ocean.entity, vertices, offsets, n, fields));
    }
    if planned.is_empty() {
        // No waves to make: the steps' buffer goes back.
        oceans.steps = DynamicUniformBuffer::default();
        return;
    }
    oceans.steps.set_label(Some("caustic_ocean_fft_steps"));
    oceans.steps.write_buffer(&device, &queue);
    let (Some(steps), Some(steps_buffer)) = (oceans.steps.binding(), oceans.steps.buffer()) else {
        return;
    };
    for (entity, vertices, offsets, resolution, fields) in planned {
        let Some(b) = oceans.buffers.get_mut(&entity) else { continue };
        let (amplitudes, omega, halves) = (&b.amplitudes, &b.omega, &b.fields);
        let bind_group = |kept: &mut KeptBindGroup, from: usize, to: usize| {
            let bound = [layout.into(), steps_buffer.into(), vertices.bound(), (&halves[from]).into(), (&halves[to]).into()];
            kept.get(&bound, || {
                device.create_bind_group(
                    "ocean_waves_bind_group",
                    layout,
                    &BindGroupEntries::sequential((
                        steps.clone(),
                        amplitudes.as_entire_binding(),
                        omega.as_entire_binding(),
                        halves[from].as_entire_binding(),
                        halves[to].as_entire_binding(),
                        BindingResource::Buffer(vertices.binding()),
                    )),
                )
            })
        };
        let [first, second] = &mut b.bind_groups;
        let bind_groups = [bind_group(first, 1, 0), bind_group(second, 0, 1)];
        oceans.dispatches.push(OceanDispatches { bind_groups, offsets, resolution, fields });
    }
}

/// The spectrum into fields 0, the FFT stages alternating 0 → 1 and 1 → 0 (an even
/// number of them: the result lands in fields 0), then the vertices from fields 0.
fn animate_waves(mut ctx: RenderContext, oceans: Res<GpuOceans>, pipelines: Res<OceanPipelines>, cache: Res<PipelineCache>, recorder: Res<PassRecorder>) {
    let [spectrum, stage, write, anchor] = pipelines.pipelines.map(|id| cache.get_compute_pipeline(id));
    let (Some(spectrum), Some(stage), Some(write), false) = (spectrum, stage, write, oceans.dispatches.is_empty()) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx.command_encoder().begin_compute_pass(&ComputePassDescriptor { label: Some("ocean_waves"), ..default() });
    let span = diagnostics.pass_span(&mut pass, "caustics/ocean_waves");
    pass.set_bind_group(0, &oceans.dispatches[0].bind_groups[0], &[oceans.dispatches[0].offsets[0]]);
    anchor_first_timestamp(&mut pass, diagnostics.is_some(), anchor);
    for ocean in &oceans.dispatches {
        let (n, last) = (ocean.resolution, ocean.offsets.len() - 1);
        pass.set_pipeline(spectrum);
        pass.set_bind_group(0, &ocean.bind_groups[0], &[ocean.offsets[0]]);
        pass.dispatch_workgroups(n.div_ceil(8), n.div_ceil(8), 1);
        pass.set_pipeline(stage);
        for (s, &offset) in ocean.offsets[1..last].iter().enumerate() {
            pass.set_bind_group(0, &ocean.bind_groups[1 - s % 2], &[offset]);
            pass.dispatch_workgroups((n / 2).div_ceil(64), n, ocean.fields);
        }
        pass.set_pipeline(write);
        pass.set_bind_group(0, &ocean.bind_groups[1], &[ocean.offsets[last]]);
        pass.dispatch_workgroups((n + 1).div_ceil(8), (n + 1).div_ceil(8), 1);
    }
    span.end(&mut pass);
    drop(pass);
    recorder.record("ocean waves");
}
