//! The two passes: caustic irradiance on receivers, and in-scattering in media.

use super::render::{
    ShaftPipeline, SurfacePipelines, SurfaceWorkReadback, ViewSeesMedium, ViewShaftBindGroup, ViewShafts, ViewSurfaceTargets, ViewVolumePipelines,
    VolumeBuffers,
};
use crate::irradiance::{ViewCausticIrradiance, ViewCausticWork};
use crate::report::PassRecorder;
use bevy::core_pipeline::prepass::ViewPrepassTextures;
use bevy::ecs::system::SystemParam;
use bevy::prelude::*;
use bevy::render::{
    diagnostic::RecordDiagnostics,
    render_resource::*,
    renderer::{RenderContext, ViewQuery},
    view::{ViewTarget, ViewUniformOffset},
};

/// What both passes draw with.
#[derive(SystemParam)]
pub(super) struct VolumeDraw<'w> {
    buffers: Res<'w, VolumeBuffers>,
    cache: Res<'w, PipelineCache>,
    recorder: Res<'w, PassRecorder>,
}

/// Where a pass draws: the target (the view's target size over `scale`, within the
/// camera's viewport over `scale`; cleared first when `clear`), tested against a depth
/// texture, read only, when given.
type PassTarget<'a> = (&'a TextureView, Option<&'a TextureView>, u32, bool);

impl VolumeDraw<'_> {
    /// Draws the volumes' bounding prisms, 36 vertices an instance, into `target` with
    /// the view's pipeline `pipeline_id` and `bind_group` ([`Self::additive_pass`]), as
    /// many as `indirect` says: for the surface pass those `splat` left in its list,
    /// else every volume the build kept. Whether it drew.
    fn draw(
        &self,
        ctx: &mut RenderContext,
        pass: &'static str,
        target: PassTarget,
        (pipeline_id, bind_group, indirect): (CachedRenderPipelineId, &BindGroup, &Buffer),
        view: VolumeView,
    ) -> bool {
        let (false, Some(pipeline)) = (self.buffers.empty, self.cache.get_render_pipeline(pipeline_id)) else {
            return false;
        };
        self.additive_pass(ctx, pass, target, (pipeline, bind_group), view, |render_pass| render_pass.draw_indirect(indirect, 0));
        true
    }

    /// The volumetric pass into `target` with the view's `bind_group`: the eye rays
    /// marched through the beam grid (a fullscreen triangle) where the view has that
    /// pipeline, else every volume drawn ([`Self::draw`]). Whether it drew.
    fn integrate(&self, ctx: &mut RenderContext, (target, scale, clear): (&TextureView, u32, bool), bind_group: &BindGroup, view: VolumeView) -> bool {
        let target = (target, None, scale, clear);
        let march = match (view.2.shafts, self.buffers.counters.as_ref()) {
            (ShaftPipeline::Exact(exact), Some(counters)) => return self.draw(ctx, "volumetric", target, (exact, bind_group, counters), view),
            (ShaftPipeline::Exact(_), None) => return false,
            (ShaftPipeline::March(march), _) => march,
        };
        let (false, Some(pipeline)) = (self.buffers.empty, self.cache.get_render_pipeline(march)) else {
            return false;
        };
        self.additive_pass(ctx, "volumetric", target, (pipeline, bind_group), view, |render_pass| render_pass.draw(0..3, 0..1));
        true
    }

    /// One render pass into `target` with `pipeline` and `bind_group` (at the view's
    /// uniform offset) and the view's `Caustics::intensity` as the blend
    /// constant, drawing what `draw` draws; timed as the span `caustics/{pass}` and
    /// recorded as `pass` in the report.
    fn additive_pass(
        &self,
        ctx: &mut RenderContext,
        pass: &'static str,
        (target, depth_test, scale, clear): PassTarget,
        (pipeline, bind_group): (&RenderPipeline, &BindGroup),
        (irradiance, work, _, _, view_offset): VolumeView,
        draw: impl FnOnce(&mut wgpu::RenderPass),
    ) {
        let diagnostics = ctx.diagnostic_recorder();
        let diagnostics = diagnostics.as_deref();
        let mut render_pass = ctx.command_encoder().begin_render_pass(&RenderPassDescriptor {
            label: Some(pass),
            color_attachments: &[Some(RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: Operations { load: if clear { LoadOp::Clear(default()) } else { LoadOp::Load }, store: StoreOp::Store },
            })],
            depth_stencil_attachment: depth_test.map(|view| RenderPassDepthStencilAttachment { view, depth_ops: None, stencil_ops: None }),
            ..default()
        });
        irradiance.set_scaled_viewport(&mut render_pass, scale);
        let span = diagnostics.pass_span(&mut render_pass, format!("caustics/{pass}"));
        render_pass.set_pipeline(pipeline);
        let intensity = f64::from(work.0.applied_intensity());
        render_pass.set_blend_constant(wgpu::Color { r: intensity, g: intensity, b: intensity, a: intensity });
        render_pass.set_bind_group(0, bind_group, &[view_offset.offset]);
        draw(&mut render_pass);
        span.end(&mut render_pass);
        self.recorder.record(pass);
    }
}

/// What the passes read of a view.
type VolumeView<'a> = (&'a ViewCausticIrradiance, &'a ViewCausticWork, &'a ViewVolumePipelines, &'a ViewPrepassTextures, &'a ViewUniformOffset);

/// Adds the caustic volumes' irradiance at every receiver pixel to the view's buffer:
/// a copy of the view's depth prepass with each pixel's receiver depth
/// (`receiver_depth.wgsl`, once a frame), then `splat` lights the pixels of the volumes
/// that cover a few and lists the others, its light is added to the buffer, then the
/// listed volumes' prisms are drawn, tested against the copy.
pub(super) fn surface_pass(
    view: ViewQuery<(&ViewSurfaceTargets, VolumeView<'static>)>,
    draw: VolumeDraw,
    surface: Res<SurfacePipelines>,
    mut readback: ResMut<SurfaceWorkReadback>,
    mut ctx: RenderContext,
) {
    let (targets, view) = view.into_inner();
    let multisampled = view.2.multisampled as usize;
    let (false, Some(copy), Some(splat), Some(resolve)) = (
        draw.buffers.empty,
        draw.cache.get_render_pipeline(surface.depth_copy[multisampled]),
        draw.cache.get_compute_pipeline(surface.splat[multisampled]),
        draw.cache.get_render_pipeline(surface.resolve),
    ) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let encoder = ctx.command_encoder();
    let mut render_pass = encoder.begin_render_pass(&RenderPassDescriptor {
        label: Some("caustic_receiver_depth"),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: &targets.centre.default_view,
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Clear(default()), store: StoreOp::Store },
        })],
        depth_stencil_attachment: Some(RenderPassDepthStencilAttachment {
            view: &targets.depth.default_view,
            depth_ops: Some(Operations { load: LoadOp::Clear(0.0), store: StoreOp::Store }),
            stencil_ops: None,
        }),
        ..default()
    });
    view.0.set_viewport(&mut render_pass);
    let span = diagnostics.pass_span(&mut render_pass, "caustics/receiver_depth");
    render_pass.set_pipeline(copy);
    render_pass.set_bind_group(0, &targets.depth_bind_group, &[view.4.offset]);
    render_pass.draw(0..3, 0..1);
    span.end(&mut render_pass);
    drop(render_pass);
    // One invocation a volume the buffer has room for; those past the build's count
    // light nothing.
    encoder.clear_buffer(&targets.splatted, 0, None);
    encoder.clear_buffer(&targets.large, 0, Some(4 * super::render::FIRST_LARGE));
    let groups = draw.buffers.capacity().div_ceil(64).max(1);
    let across = groups.min(65535);
    let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor { label: Some("caustic_volumes_splat"), ..default() });
    let span = diagnostics.pass_span(&mut pass, "caustics/volumes_splat");
    pass.set_pipeline(splat);
    pass.set_bind_group(0, &targets.splat_bind_group, &[view.4.offset]);
    pass.dispatch_workgroups(across as u32, groups.div_ceil(across) as u32, 1);
    span.end(&mut pass);
    drop(pass);
    let device = ctx.render_device().clone();
    let encoder = ctx.command_encoder();
    readback.copy(&device, encoder, (&targets.large, super::render::FIRST_LARGE), "caustic_surface_work_readback", false);
    // Only where the view sees a surface (reversed z: the fullscreen triangle lies at 0).
    let mut render_pass = encoder.begin_render_pass(&RenderPassDescriptor {
        label: Some("caustic_volumes_resolve"),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: &view.0.texture.default_view,
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Load, store: StoreOp::Store },
        })],
        depth_stencil_attachment: Some(RenderPassDepthStencilAttachment { view: &targets.depth.default_view, depth_ops: None, stencil_ops: None }),
        ..default()
    });
    view.0.set_viewport(&mut render_pass);
    let span = diagnostics.pass_span(&mut render_pass, "caustics/volumes_resolve");
    render_pass.set_pipeline(resolve);
    render_pass.set_bind_group(0, &targets.resolve_bind_group, &[view.4.offset]);
    render_pass.draw(0..3, 0..1);
    span.end(&mut render_pass);
    drop(render_pass);
    let target = &view.0.texture.default_view;
    let bound = (view.2.surface, &targets.draw_bind_group, &targets.large);
    draw.draw(&mut ctx, "volumes", (target, Some(&targets.depth.default_view), 1, false), bound, view);
}

/// Caustics views that see a medium.
type MediumViews = (With<ViewSeesMedium>, With<ViewCausticWork>);

/// Adds the light splatted out of the caustic beams in media to the view's HDR image:
/// straight, or integrated into the view's smaller shaft texture and spread over the
/// image by a fullscreen pass.
pub(super) fn volumetric_pass(
    view: ViewQuery<(&ViewTarget, Option<&ViewShafts>, &ViewShaftBindGroup, VolumeView<'static>), MediumViews>,
    draw: VolumeDraw,
    mut ctx: RenderContext,
) {
    let (target, shafts, bound, view) = view.into_inner();
    let (Some(shafts), Some(upsample)) = (shafts, view.2.upsample) else {
        draw.integrate(&mut ctx, (target.main_texture_view(), 1, false), &bound.bind_group, view);
        return;
    };
    let Some(pipeline) = draw.cache.get_render_pipeline(upsample) else { return };
    if !draw.integrate(&mut ctx, (&shafts.texture.default_view, shafts.scale, true), &bound.bind_group, view) {
        return;
    }
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut render_pass = ctx.command_encoder().begin_render_pass(&RenderPassDescriptor {
        label: Some("volumetric_upsample"),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: target.main_texture_view(),
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Load, store: StoreOp::Store },
        })],
        ..default()
    });
    view.0.set_viewport(&mut render_pass);
    let span = diagnostics.pass_span(&mut render_pass, "caustics/volumetric_upsample");
    render_pass.set_pipeline(pipeline);
    let intensity = f64::from(view.1.0.applied_intensity());
    render_pass.set_blend_constant(wgpu::Color { r: intensity, g: intensity, b: intensity, a: intensity });
    render_pass.set_bind_group(0, &shafts.bind_group, &[]);
    render_pass.draw(0..3, 0..1);
    span.end(&mut render_pass);
}
