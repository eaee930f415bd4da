//! Render world: the passes that make each light view's caustic map once per change,
//! and its projection into every view each frame.

use super::render::{COUNTERS_PER_VIEW, CausticMapPipelines, CausticMapsGpu, Groups, KERNELS, Kernel, MeshDraw};
use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::{ProjectionContext, ProjectionView};
use crate::report::PassRecorder;
use bevy::prelude::*;
use bevy::render::{
    diagnostic::RecordDiagnostics,
    mesh::{RenderMesh, RenderMeshBufferInfo, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_resource::*,
    renderer::{RenderContext, ViewQuery},
};
use caustics_core::hierarchical::light_maps::NO_SURFACE;

/// Draws `draws` (pipeline `which` of each) with the light map bind group.
fn draw_meshes(
    pass: &mut wgpu::RenderPass,
    draws: &[MeshDraw],
    which: usize,
    bind_group: &BindGroup,
    cache: &PipelineCache,
    meshes: &RenderAssets<RenderMesh>,
    allocator: &MeshAllocator,
) -> bool {
    pass.set_bind_group(0, bind_group, &[]);
    for draw in draws {
        let (Some(pipeline), Some(mesh), Some(vertices)) =
            (cache.get_render_pipeline(draw.pipelines[which]), meshes.get(draw.mesh), allocator.mesh_vertex_slice(&draw.mesh))
        else {
            return false;
        };
        pass.set_pipeline(pipeline);
        pass.set_vertex_buffer(0, *vertices.buffer.slice(..));
        let instances = draw.instance..draw.instance + 1;
        match &mesh.buffer_info {
            RenderMeshBufferInfo::Indexed { index_format, count } => {
                let Some(indices) = allocator.mesh_index_slice(&draw.mesh) else { return false };
                pass.set_index_buffer(*indices.buffer.slice(..), *index_format);
                pass.draw_indexed(indices.range.start..indices.range.start + count, vertices.range.start as i32, instances);
            }
            RenderMeshBufferInfo::NonIndexed => pass.draw(vertices.range.clone(), instances),
        }
    }
    true
}

/// A light map's render pass: the target cleared to "no surface", depth to `depth_clear`.
fn light_map_pass<'a>(
    encoder: &'a mut CommandEncoder,
    label: &'static str,
    target: &TextureView,
    depth: &TextureView,
    depth_clear: f32,
) -> wgpu::RenderPass<'a> {
    let clear = LoadOp::Clear(wgpu::Color { r: NO_SURFACE as f64, g: 0.0, b: 0.0, a: 0.0 });
    encoder.begin_render_pass(&RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: target,
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: clear, store: StoreOp::Store },
        })],
        depth_stencil_attachment: Some(RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(Operations { load: LoadOp::Clear(depth_clear), store: StoreOp::Discard }),
            stencil_ops: None,
        }),
        ..default()
    })
}

/// Once per frame in which the plan changed: every light view's light maps, photon
/// buffer, gather, splats and resolved map.
pub(super) fn make_caustic_maps(
    mut ctx: RenderContext,
    mut gpu: ResMut<CausticMapsGpu>,
    pipelines: Res<CausticMapPipelines>,
    cache: Res<PipelineCache>,
    meshes: Res<RenderAssets<RenderMesh>>,
    allocator: Res<MeshAllocator>,
    recorder: Res<PassRecorder>,
) {
    if !gpu.dirty || gpu.views.is_empty() {
        return;
    }
    let compute: Option<Vec<&ComputePipeline>> = pipelines.compute.iter().map(|&id| cache.get_compute_pipeline(id)).collect();
    let (Some(compute), Some(scratch)) = (compute, gpu.scratch.as_ref()) else { return };
    let Some(args_bind_group) = scratch.args_bind_group.as_ref() else { return };
    let counters_size = COUNTERS_PER_VIEW as u64 * 4;
    let mut complete = true;
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    for (k, view) in gpu.views.iter().enumerate() {
        let encoder = ctx.command_encoder();
        // The generator's front and back faces, then the receivers and occluders, seen
        // from the light: three passes, each a span of `caustic_maps/light_maps`.
        let light_maps = [
            ("caustic_front_map", &scratch.front.1, &scratch.photon_depth, 1.0, &gpu.generator_draws, 0, &view.generator_bind_group),
            ("caustic_back_map", &scratch.back.1, &scratch.photon_depth, 0.0, &gpu.generator_draws, 1, &view.generator_bind_group),
            ("caustic_receiver_map", &view.receivers.1, &scratch.map_depth, 1.0, &gpu.occluder_draws, 0, &view.occluder_bind_group),
        ];
        for (label, target, depth, depth_clear, draws, variant, bind_group) in light_maps {
            let mut pass = light_map_pass(encoder, label, target, depth, depth_clear);
            let span = diagnostics.pass_span(&mut pass, "caustic_maps/light_maps");
            complete &= draw_meshes(&mut pass, draws, variant, bind_group, &cache, &meshes, &allocator);
            span.end(&mut pass);
        }
        encoder.clear_buffer(&scratch.counters, k as u64 * counters_size, Some(counters_size));
        encoder.clear_buffer(&scratch.levels, 0, None);
        // One compute pass per stage, each timed.
        for stage in view.dispatches.chunk_by(|a, b| a.kernel.stage() == b.kernel.stage()) {
            let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor { label: Some(stage[0].kernel.stage()), ..default() });
            let span = diagnostics.pass_span(&mut pass, stage[0].kernel.stage());
            pass.set_bind_group(0, &view.compute_bind_group, &[view.step_offsets[stage[0].step]]);
            anchor_first_timestamp(&mut pass, diagnostics.is_some(), cache.get_compute_pipeline(pipelines.anchor));
            for dispatch in stage {
                let kernel = KERNELS.iter().position(|(k, _)| *k == dispatch.kernel).unwrap_or(0);
                pass.set_pipeline(compute[kernel]);
                pass.set_bind_group(0, &view.compute_bind_group, &[view.step_offsets[dispatch.step]]);
                if dispatch.kernel == Kernel::WriteArgs {
                    pass.set_bind_group(1, args_bind_group, &[]);
                }
                match dispatch.groups {
                    Groups::Direct(x, y) => pass.dispatch_workgroups(x, y, 1),
                    Groups::Indirect(slot) => pass.dispatch_workgroups_indirect(&scratch.args, slot as u64 * 12),
                }
            }
            span.end(&mut pass);
        }
        recorder.record("caustic map");
    }
    // A pipeline still compiling or a mesh not yet uploaded: make them again next frame.
    gpu.dirty = !complete;
}

/// Adds every light view's caustic irradiance where the view sees its receivers.
pub(super) fn project_caustic_maps(
    view: ViewQuery<ProjectionView<CausticMapPipelines>>,
    mut gpu: ResMut<CausticMapsGpu>,
    pipelines: Res<CausticMapPipelines>,
    projection: ProjectionContext<CausticMapPipelines>,
    mut ctx: RenderContext,
) {
    let entity = view.entity();
    let (buffer, prepass, offset, pipeline) = view.into_inner();
    if gpu.generation.is_none() || gpu.views.is_empty() {
        return;
    }
    let Some(inputs) = projection.inputs(pipeline, prepass, &pipelines.project_layouts) else { return };
    let Some(normal) = inputs.normal else { return };
    let device = ctx.render_device().clone();
    let bind_groups: Vec<BindGroup> = gpu
        .views
        .iter_mut()
        .filter_map(|v| {
            let (uniform, binding) = (v.uniform.buffer()?, v.uniform.binding()?);
            let source = [uniform.into(), (&v.receivers.1).into(), (&v.resolved).into()];
            Some(inputs.bind_group(&mut v.projections, (entity, |e| projection.exists(e)), &source, || {
                device.create_bind_group(
                    "caustic_map_project_bind_group",
                    inputs.layout,
                    &BindGroupEntries::sequential((inputs.view.clone(), inputs.depth, normal, binding, &v.receivers.1, v.resolved.as_entire_binding())),
                )
            }))
        })
        .collect();
    let names = ("caustic_map_projection", "caustic_maps/projection", "caustic map projection");
    buffer.project(&mut ctx, inputs.pipeline, &bind_groups, offset.offset, names, &projection.recorder);
}
