//! The two passes: caustic irradiance on receivers, and in-scattering in media.

use super::render::{VolumeBuffers, VolumesPipeline, ViewSeesMedium, ViewVolumePipelines};
use crate::irradiance::{ViewCausticIrradiance, ViewCausticWork};
use crate::report::PassRecorder;
use bevy::core_pipeline::prepass::ViewPrepassTextures;
use bevy::prelude::*;
use bevy::render::{
    render_resource::*,
    renderer::{RenderContext, ViewQuery},
    view::{ViewTarget, ViewUniformOffset, ViewUniforms},
};

/// Draws every volume's bounding prism, 36 vertices an instance, into `target`.
#[allow(clippy::too_many_arguments)]
fn draw_volumes(
    ctx: &mut RenderContext,
    label: &'static str,
    target: &TextureView,
    pipeline_id: CachedRenderPipelineId,
    pipelines: &ViewVolumePipelines,
    prepass: &ViewPrepassTextures,
    view_offset: &ViewUniformOffset,
    resources: (&VolumeBuffers, &VolumesPipeline, &PipelineCache, &ViewUniforms),
) -> bool {
    let (buffers, layouts, cache, view_uniforms) = resources;
    let (Some(pipeline), Some(depth), Some(normal), Some(view), Some(volumes), Some(settings)) = (
        cache.get_render_pipeline(pipeline_id),
        prepass.depth_view(),
        prepass.normal_view(),
        view_uniforms.uniforms.binding(),
        buffers.volumes.binding(),
        buffers.settings.binding(),
    ) else {
        return false;
    };
    if buffers.count == 0 {
        return false;
    }
    let bind_group = ctx.render_device().create_bind_group(
        "caustic_volumes_bind_group",
        &cache.get_bind_group_layout(&layouts.layouts[pipelines.multisampled as usize]),
        &BindGroupEntries::sequential((view, volumes, settings, depth, normal)),
    );
    let mut pass = ctx.command_encoder().begin_render_pass(&RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: target,
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Load, store: StoreOp::Store },
        })],
        ..default()
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, &bind_group, &[view_offset.offset]);
    pass.draw(0..36, 0..buffers.count);
    true
}

/// Adds the caustic volumes' irradiance at every receiver pixel to the view's buffer.
#[allow(clippy::too_many_arguments)]
pub(super) fn surface_pass(
    view: ViewQuery<(&ViewCausticIrradiance, &ViewPrepassTextures, &ViewUniformOffset, &ViewVolumePipelines)>,
    buffers: Res<VolumeBuffers>,
    layouts: Res<VolumesPipeline>,
    cache: Res<PipelineCache>,
    view_uniforms: Res<ViewUniforms>,
    recorder: Res<PassRecorder>,
    mut ctx: RenderContext,
) {
    let (irradiance, prepass, offset, pipelines) = view.into_inner();
    let resources = (&*buffers, &*layouts, &*cache, &*view_uniforms);
    let target = &irradiance.texture.default_view;
    if draw_volumes(&mut ctx, "caustic_volumes", target, pipelines.surface, pipelines, prepass, offset, resources) {
        recorder.record("volumes");
    }
}

/// Caustics views that see a medium.
type MediumViews = (With<ViewSeesMedium>, With<ViewCausticWork>);

/// Adds the light scattered out of the caustic beams in media to the view's HDR image.
#[allow(clippy::too_many_arguments)]
pub(super) fn volumetric_pass(
    view: ViewQuery<(&ViewTarget, &ViewPrepassTextures, &ViewUniformOffset, &ViewVolumePipelines), MediumViews>,
    buffers: Res<VolumeBuffers>,
    layouts: Res<VolumesPipeline>,
    cache: Res<PipelineCache>,
    view_uniforms: Res<ViewUniforms>,
    recorder: Res<PassRecorder>,
    mut ctx: RenderContext,
) {
    let (target, prepass, offset, pipelines) = view.into_inner();
    let resources = (&*buffers, &*layouts, &*cache, &*view_uniforms);
    let target = target.main_texture_view();
    if draw_volumes(&mut ctx, "caustic_volumetric", target, pipelines.volumetric, pipelines, prepass, offset, resources) {
        recorder.record("volumetric");
    }
}
