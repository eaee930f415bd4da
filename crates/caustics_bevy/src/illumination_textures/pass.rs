//! Render world: the pass that draws each light's illumination textures once per
//! change, and their projection into every view each frame.

use super::render::{IlluminationPipelines, IlluminationTexturesGpu};
use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::{ProjectionContext, ProjectionView};
use crate::report::PassRecorder;
use bevy::prelude::*;
use bevy::render::{
    diagnostic::RecordDiagnostics,
    render_resource::*,
    renderer::{RenderContext, ViewQuery},
};

/// Once per frame in which the frames changed: what each light's virtual camera sees
/// (its depth map and the depths of its planes, a ray a texel), then every plane of
/// every light's frame, cleared, and every illumination volume's crossing drawn into
/// it (a quad over the crossing's texels, six vertices a volume; the plane is the
/// instance).
pub(super) fn draw_illumination_textures(
    mut ctx: RenderContext,
    mut gpu: ResMut<IlluminationTexturesGpu>,
    pipelines: Res<IlluminationPipelines>,
    cache: Res<PipelineCache>,
    recorder: Res<PassRecorder>,
) {
    if !gpu.dirty || gpu.frames.is_empty() {
        return;
    }
    // The pipelines still compiling: draw next frame.
    let (Some(see), Some(pipeline)) = (cache.get_compute_pipeline(pipelines.see), cache.get_render_pipeline(pipelines.draw)) else { return };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let encoder = ctx.command_encoder();
    for frame in &gpu.frames {
        encoder.clear_buffer(&frame.seen, 0, None);
        let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor { label: Some("illumination_see"), timestamp_writes: None });
        let span = diagnostics.pass_span(&mut pass, "illumination_textures/see");
        pass.set_bind_group(0, &frame.see_bind_group, &[]);
        anchor_first_timestamp(&mut pass, diagnostics.is_some(), cache.get_compute_pipeline(pipelines.see_anchor));
        pass.set_pipeline(see);
        let groups = frame.textures.width().div_ceil(8);
        pass.dispatch_workgroups(groups, groups, 1);
        span.end(&mut pass);
    }
    for frame in &gpu.frames {
        for (plane, layer) in frame.layers.iter().enumerate() {
            let mut pass = encoder.begin_render_pass(&RenderPassDescriptor {
                label: Some("illumination_textures"),
                color_attachments: &[Some(RenderPassColorAttachment {
                    view: layer,
                    depth_slice: None,
                    resolve_target: None,
                    ops: Operations { load: LoadOp::Clear(wgpu::Color::TRANSPARENT), store: StoreOp::Store },
                })],
                ..default()
            });
            // A pass span, so that every plane's shader invocations are counted too.
            let span = diagnostics.pass_span(&mut pass, "illumination_textures/draw");
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &frame.draw_bind_group, &[]);
            pass.draw(0..6 * frame.volume_count, plane as u32..plane as u32 + 1);
            span.end(&mut pass);
        }
    }
    recorder.record("illumination textures");
    gpu.dirty = false;
}

/// Adds every light's illumination textures where the view sees receivers.
pub(super) fn project_illumination_textures(
    view: ViewQuery<ProjectionView<IlluminationPipelines>>,
    mut gpu: ResMut<IlluminationTexturesGpu>,
    pipelines: Res<IlluminationPipelines>,
    projection: ProjectionContext<IlluminationPipelines>,
    mut ctx: RenderContext,
) {
    let entity = view.entity();
    let (buffer, prepass, offset, pipeline) = view.into_inner();
    if gpu.frames.is_empty() || gpu.dirty {
        return;
    }
    let Some(inputs) = projection.inputs(pipeline, prepass, &pipelines.project_layouts) else { return };
    let Some(normal) = inputs.normal else { return };
    let device = ctx.render_device().clone();
    let bind_groups: Vec<BindGroup> = gpu
        .frames
        .iter_mut()
        .filter_map(|f| {
            let (uniform, binding) = (f.uniform.buffer()?, f.uniform.binding()?);
            let source = [uniform.into(), (&f.array).into(), (&f.surface).into(), (&f.seen).into()];
            Some(inputs.bind_group(&mut f.projections, (entity, |v| projection.exists(v)), &source, || {
                device.create_bind_group(
                    "illumination_project_bind_group",
                    inputs.layout,
                    &BindGroupEntries::sequential((
                        inputs.view.clone(),
                        inputs.depth,
                        normal,
                        binding,
                        &f.array,
                        f.surface.as_entire_binding(),
                        f.seen.as_entire_binding(),
                    )),
                )
            }))
        })
        .collect();
    let names = ("illumination_projection", "illumination_textures/projection", "illumination textures projection");
    buffer.project(&mut ctx, inputs.pipeline, &bind_groups, offset.offset, names, &projection.recorder);
}
