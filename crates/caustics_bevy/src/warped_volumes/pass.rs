//! The two passes: caustic irradiance on receivers, and in-scattering in media.

use super::beam_grid::{BeamGridBuffers, BeamGridPipelines};
use super::render::{ShaftPipeline, SurfacePipelines, SurfaceWorkReadback, VolumeBuffers, VolumesPipeline, ViewSeesMedium, ViewShafts, ViewSurfaceTargets, ViewVolumePipelines};
use crate::irradiance::{ViewCausticIrradiance, ViewCausticWork};
use crate::report::PassRecorder;
use bevy::core_pipeline::prepass::ViewPrepassTextures;
use bevy::ecs::system::SystemParam;
use bevy::prelude::*;
use bevy::render::{
    diagnostic::RecordDiagnostics,
    render_resource::*,
    renderer::{RenderContext, ViewQuery},
    view::{ViewTarget, ViewUniformOffset, ViewUniforms},
};

/// What both passes draw with.
#[derive(SystemParam)]
pub(super) struct VolumeDraw<'w> {
    buffers: Res<'w, VolumeBuffers>,
    layouts: Res<'w, VolumesPipeline>,
    cache: Res<'w, PipelineCache>,
    view_uniforms: Res<'w, ViewUniforms>,
    recorder: Res<'w, PassRecorder>,
    grids: Res<'w, BeamGridBuffers>,
    march: Res<'w, BeamGridPipelines>,
}

/// Where a pass draws: the target (the view's target size over `scale`, within the
/// camera's viewport over `scale`; cleared first when `clear`), tested against a depth
/// texture, read only, when given.
type PassTarget<'a> = (&'a TextureView, Option<&'a TextureView>, u32, bool);

impl VolumeDraw<'_> {
    /// Draws the volumes' bounding prisms, 36 vertices an instance, into `target` with
    /// the view's pipeline `pipeline_id` ([`Self::additive_pass`]): for the surface
    /// pass those `splat` left in `surface`'s list, else every volume the build kept.
    /// Whether it drew.
    fn draw(
        &self,
        ctx: &mut RenderContext,
        pass: &'static str,
        target: PassTarget,
        (pipeline_id, surface): (CachedRenderPipelineId, Option<&ViewSurfaceTargets>),
        view: VolumeView,
    ) -> bool {
        let (_, _, pipelines, prepass, _) = view;
        let (false, Some(pipeline), Some(depth), Some(normal), Some(view_binding), Some(volumes), Some(counters), Some(settings)) = (
            self.buffers.empty,
            self.cache.get_render_pipeline(pipeline_id),
            prepass.depth_view(),
            prepass.normal_view(),
            self.view_uniforms.uniforms.binding(),
            self.buffers.volumes.as_ref(),
            self.buffers.counters.as_ref(),
            self.buffers.settings.binding(),
        ) else {
            return false;
        };
        let entries = (view_binding, volumes.as_entire_binding(), settings, depth, normal);
        let layout = self.cache.get_bind_group_layout(self.layouts.layout(surface.is_none(), pipelines.multisampled));
        let (bind_group, indirect) = match surface {
            Some(surface) => {
                let (a, b, c, _, e) = entries;
                let entries = BindGroupEntries::sequential((a, b, c, &surface.centre.default_view, e, surface.large.as_entire_binding()));
                (ctx.render_device().create_bind_group("caustic_volumes_surface_bind_group", &layout, &entries), &surface.large)
            }
            None => (ctx.render_device().create_bind_group("caustic_volumes_bind_group", &layout, &BindGroupEntries::sequential(entries)), counters),
        };
        self.additive_pass(ctx, pass, target, (pipeline, &bind_group), view, |render_pass| render_pass.draw_indirect(indirect, 0));
        true
    }

    /// The volumetric pass into `target`: the eye rays marched through the beam grid
    /// (a fullscreen triangle) where the view has that pipeline, else every volume
    /// drawn ([`Self::draw`]). Whether it drew.
    fn integrate(&self, ctx: &mut RenderContext, (target, scale, clear): (&TextureView, u32, bool), view: VolumeView) -> bool {
        let march = match view.2.shafts {
            ShaftPipeline::Exact(exact) => return self.draw(ctx, "volumetric", (target, None, scale, clear), (exact, None), view),
            ShaftPipeline::March(march) => march,
        };
        let (_, _, pipelines, prepass, _) = view;
        let (false, Some(pipeline), Some(depth), Some(view_binding), Some(settings), Some(grids), Some(cells)) = (
            self.buffers.empty,
            self.cache.get_render_pipeline(march),
            prepass.depth_view(),
            self.view_uniforms.uniforms.binding(),
            self.buffers.settings.binding(),
            self.grids.grids.binding(),
            self.grids.cells.as_ref(),
        ) else {
            return false;
        };
        let bind_group = ctx.render_device().create_bind_group(
            "caustic_shaft_march_bind_group",
            &self.cache.get_bind_group_layout(&self.march.march_layouts[pipelines.multisampled as usize]),
            &BindGroupEntries::sequential((view_binding, settings, grids, cells.as_entire_binding(), depth)),
        );
        let target = (target, None, scale, clear);
        self.additive_pass(ctx, "volumetric", target, (pipeline, &bind_group), view, |render_pass| render_pass.draw(0..3, 0..1));
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
type VolumeView<'a> =
    (&'a ViewCausticIrradiance, &'a ViewCausticWork, &'a ViewVolumePipelines, &'a ViewPrepassTextures, &'a ViewUniformOffset);

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
    // One invocation a volume the buffer has room for; those past the build's count return.
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
    readback.copy(&device, encoder, (&targets.large, super::render::FIRST_LARGE), "caustic_surface_work_readback");
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
    draw.draw(&mut ctx, "volumes", (target, Some(&targets.depth.default_view), 1, false), (view.2.surface, Some(targets)), view);
}

/// Caustics views that see a medium.
type MediumViews = (With<ViewSeesMedium>, With<ViewCausticWork>);

/// Adds the light splatted out of the caustic beams in media to the view's HDR image:
/// straight, or integrated into the view's smaller shaft texture and spread over the
/// image by a fullscreen pass.
pub(super) fn volumetric_pass(
    view: ViewQuery<(&ViewTarget, Option<&ViewShafts>, VolumeView<'static>), MediumViews>,
    draw: VolumeDraw,
    mut ctx: RenderContext,
) {
    let (target, shafts, view) = view.into_inner();
    let (Some(shafts), Some(upsample)) = (shafts, view.2.upsample) else {
        draw.integrate(&mut ctx, (target.main_texture_view(), 1, false), view);
        return;
    };
    let Some(pipeline) = draw.cache.get_render_pipeline(upsample) else { return };
    if !draw.integrate(&mut ctx, (&shafts.texture.default_view, shafts.scale, true), view) {
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
