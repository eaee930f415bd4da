//! Render world: the water of pools that ripple on the GPU ([`MovesOnGpu`], which
//! `ripples.rs` gives a pool while its water moves). Each frame, for each such pool,
//! `ripple_heights` evaluates the live impulses' wall images at the texel centres
//! (§4.3, as for the convolution) and `write_vertices` writes the surface and its
//! normals over the water mesh in Bevy's vertex buffer, before anything reads or draws
//! it (the caustic volumes' build included). The CPU uploads the waves (clock and
//! impulses) once a frame; it evaluates no height and uploads no mesh.

use super::PoolSurface;
use super::render::{GpuPool, GpuWaves, ripple_waves, write_waves};
use crate::cpu_time::timed;
use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::kept_bind_group::{KeptBindGroup, KeptLayout};
use crate::mesh_vertices::{MeshVertices, MovesOnGpu, WriteMeshVertices};
use crate::report::PassRecorder;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::{
    Extract, Render, RenderApp, RenderStartup, RenderSystems,
    diagnostic::RecordDiagnostics,
    mesh::{RenderMesh, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_resource::{
        binding_types::{storage_buffer, storage_buffer_read_only, storage_buffer_sized, uniform_buffer},
        *,
    },
    renderer::{RenderContext, RenderDevice, RenderQueue},
};

/// One pool to move this frame: its water mesh, texels and waves, and its impulses.
struct ExtractedWater {
    entity: Entity,
    mesh: AssetId<Mesh>,
    uniform: GpuPool,
    waves: GpuWaves,
}

#[derive(Resource, Default)]
struct ExtractedWaters(Vec<ExtractedWater>);

/// A pool's buffers and bind group, kept while it moves on the GPU.
struct WaterBuffers {
    texels: u32,
    uniform: UniformBuffer<GpuPool>,
    waves: StorageBuffer<GpuWaves>,
    heights: Buffer,
    bind_group: KeptBindGroup,
}

/// This frame's pools: their buffers, and a bind group and texel grid per dispatch.
#[derive(Resource, Default)]
struct GpuWaters {
    buffers: HashMap<Entity, WaterBuffers>,
    dispatches: Vec<(BindGroup, UVec2)>,
}

#[derive(Resource)]
struct WaterPipelines {
    layout: KeptLayout,
    /// `ripple_heights`, `write_vertices`, and the empty `anchor` of [`anchor_first_timestamp`].
    pipelines: [CachedComputePipelineId; 3],
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).render;
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedWaters>()
        .init_resource::<GpuWaters>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, timed(&cpu, extract_waters))
        .add_systems(Render, timed(&cpu, prepare_waters).in_set(RenderSystems::PrepareResources))
        .add_systems(bevy::render::renderer::RenderGraph, timed(&cpu, move_waters).in_set(WriteMeshVertices));
}

/// `convolution.wgsl`'s bindings that its two water kernels read and write.
fn init_pipelines(mut commands: Commands, asset_server: Res<AssetServer>, cache: Res<PipelineCache>) {
    let layout = BindGroupLayoutDescriptor::new(
        "pool_water_layout",
        &BindGroupLayoutEntries::with_indices(
            ShaderStages::COMPUTE,
            (
                (0, uniform_buffer::<GpuPool>(false)),
                (1, storage_buffer_read_only::<GpuWaves>(false)),
                (3, storage_buffer::<f32>(false)),
                (6, storage_buffer_sized(false, None)),
            ),
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "convolution.wgsl");
    let pipelines = crate::irradiance::compute_pipelines(&cache, "pool_water", &layout, &shader, ["ripple_heights", "write_vertices", "anchor"]);
    commands.insert_resource(WaterPipelines { layout: KeptLayout::new(layout), pipelines });
}

/// The visible pools whose water moves on the GPU.
type MovingPools<'w, 's> = Query<'w, 's, (Entity, &'static PoolSurface, &'static Mesh3d, &'static InheritedVisibility), With<MovesOnGpu>>;

fn extract_waters(mut extracted: ResMut<ExtractedWaters>, pools: Extract<MovingPools>, time: Extract<Res<Time>>) {
    extracted.0.clear();
    for (entity, surface, mesh, _) in pools.iter().filter(|(.., visible)| visible.get()) {
        let (uniform, waves) = (GpuPool::waves(surface), ripple_waves(surface, time.elapsed_secs()));
        extracted.0.push(ExtractedWater { entity, mesh: mesh.id(), uniform, waves });
    }
}

#[expect(clippy::too_many_arguments)]
fn prepare_waters(
    mut extracted: ResMut<ExtractedWaters>,
    mut waters: ResMut<GpuWaters>,
    pipelines: Res<WaterPipelines>,
    cache: Res<PipelineCache>,
    meshes: Res<RenderAssets<RenderMesh>>,
    allocator: Res<MeshAllocator>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let waters = &mut *waters;
    waters.buffers.retain(|entity, _| extracted.0.iter().any(|w| w.entity == *entity));
    waters.dispatches.clear();
    let layout = pipelines.layout.get(&cache);
    for water in &mut extracted.0 {
        let texels = water.uniform.columns * water.uniform.rows;
        let Some(vertices) = MeshVertices::of(water.mesh, &meshes, &allocator, &device).filter(|v| v.count == texels) else {
            continue;
        };
        let new = || WaterBuffers {
            texels,
            uniform: UniformBuffer::default(),
            waves: StorageBuffer::default(),
            heights: super::render::texel_buffer(&device, "caustic_pool_water_heights", texels, 1),
            bind_group: KeptBindGroup::default(),
        };
        let buffers = waters.buffers.entry(water.entity).or_insert_with(new);
        if buffers.texels != texels {
            *buffers = new();
        }
        water.uniform.vertex = vertices.layout;
        write_waves((&mut buffers.uniform, &mut buffers.waves), (water.uniform, std::mem::take(&mut water.waves)), (&device, &queue));
        let (Some(uniform), Some(waves)) = (buffers.uniform.buffer(), buffers.waves.buffer()) else {
            continue;
        };
        let bound = [layout.into(), uniform.into(), waves.into(), (&buffers.heights).into(), vertices.bound()];
        let bind_group = buffers.bind_group.get(&bound, || {
            device.create_bind_group(
                "pool_water_bind_group",
                layout,
                &BindGroupEntries::with_indices((
                    (0, uniform.as_entire_binding()),
                    (1, waves.as_entire_binding()),
                    (3, buffers.heights.as_entire_binding()),
                    (6, BindingResource::Buffer(vertices.binding())),
                )),
            )
        });
        waters.dispatches.push((bind_group, UVec2::new(water.uniform.columns, water.uniform.rows)));
    }
}

/// The heights of every moving pool, then its vertices from them.
fn move_waters(mut ctx: RenderContext, waters: Res<GpuWaters>, pipelines: Res<WaterPipelines>, cache: Res<PipelineCache>, recorder: Res<PassRecorder>) {
    let [heights, write, anchor] = pipelines.pipelines.map(|id| cache.get_compute_pipeline(id));
    let (Some(heights), Some(write), false) = (heights, write, waters.dispatches.is_empty()) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx.command_encoder().begin_compute_pass(&ComputePassDescriptor { label: Some("pool_water"), ..default() });
    let span = diagnostics.pass_span(&mut pass, "caustics/pool_water");
    pass.set_bind_group(0, &waters.dispatches[0].0, &[]);
    anchor_first_timestamp(&mut pass, diagnostics.is_some(), anchor);
    for (bind_group, texels) in &waters.dispatches {
        pass.set_bind_group(0, bind_group, &[]);
        for pipeline in [heights, write] {
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups(texels.x.div_ceil(8), texels.y.div_ceil(8), 1);
        }
    }
    span.end(&mut pass);
    drop(pass);
    recorder.record("pool water");
}
