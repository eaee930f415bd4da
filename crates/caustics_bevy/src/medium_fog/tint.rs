//! The colour of the media's absorption, which Bevy's volumetric fog cannot draw: its
//! transmittance is one number for all three channels. A medium's `FogVolume` takes
//! σₐ's least channel ([`super::fog_coefficients`]); after Bevy's main passes and
//! before its fog, this pass multiplies each pixel of every view that draws Bevy's fog
//! by exp(−(σₜ,c − σₜ,min) ℓ) in each channel c, ℓ the eye ray's length inside each
//! medium up to the view's depth (`caustics/medium_tint`). With Bevy's grey part, what
//! lies in or behind the medium is dimmed by exp(−σₜ,c ℓ): under water red goes first
//! and blue last. Behind a transmissive surface the rest of the path is dimmed, all of
//! σₜ, by [`super::behind_transmission`]. While every medium absorbs all channels
//! alike the pass is left out.

use super::dim::{self, Dim, DimKey, DimPipeline, MediaUniform};
use crate::irradiance::kept_bind_group::KeptBindGroup;
use crate::irradiance::{ExtractedMedia, GpuMedium};
use crate::report::PassRecorder;
use bevy::core_pipeline::core_3d::main_transparent_pass_3d;
use bevy::core_pipeline::{Core3dSystems, schedule::Core3d};
use bevy::light::VolumetricFog;
use bevy::prelude::*;
use bevy::render::camera::ExtractedCamera;
use bevy::render::render_resource::*;
use bevy::render::renderer::{RenderContext, RenderDevice, ViewQuery};
use bevy::render::view::{ViewDepthTexture, ViewTarget, ViewUniformOffset, ViewUniforms};
use bevy::render::{Render, RenderApp, RenderSystems};

pub(super) fn build(app: &mut App) {
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .add_systems(Render, (queue.in_set(RenderSystems::Queue), prepare_bind_groups.in_set(RenderSystems::PrepareBindGroups)))
        .add_systems(Core3d, tint.after(main_transparent_pass_3d).in_set(Core3dSystems::MainPass));
}

/// Render world, on a view whose image is tinted by the media this frame: its
/// pipeline and bind group.
#[derive(Component)]
pub struct ViewMediumTint {
    pipeline: CachedRenderPipelineId,
    multisampled: bool,
    bind_group: KeptBindGroup,
}

/// Gives each view that draws Bevy's fog the tint's pipeline while a medium absorbs
/// its channels unequally; takes it from the others.
#[expect(clippy::too_many_arguments)]
fn queue(
    mut commands: Commands,
    mut views: Query<(Entity, &ViewTarget, &Msaa, Option<&mut ViewMediumTint>), With<VolumetricFog>>,
    others: Query<Entity, (With<ViewMediumTint>, Without<VolumetricFog>)>,
    media: Res<ExtractedMedia>,
    pipeline: Res<DimPipeline>,
    mut pipelines: ResMut<SpecializedRenderPipelines<DimPipeline>>,
    pipeline_cache: Res<PipelineCache>,
    recorder: Res<PassRecorder>,
) {
    for entity in &others {
        commands.entity(entity).remove::<ViewMediumTint>();
    }
    let coloured = !media.0.iter().all(GpuMedium::is_grey);
    for (entity, target, msaa, kept) in &mut views {
        if !coloured {
            if kept.is_some() {
                commands.entity(entity).remove::<ViewMediumTint>();
            }
            continue;
        }
        let multisampled = msaa.samples() > 1;
        let key = DimKey { dim: Dim::Tint, multisampled, format: target.main_texture_format() };
        let id = pipelines.specialize(&pipeline_cache, &pipeline, key);
        recorder.record("medium_tint");
        match kept {
            Some(mut kept) => (kept.pipeline, kept.multisampled) = (id, multisampled),
            None => {
                commands.entity(entity).insert(ViewMediumTint { pipeline: id, multisampled, bind_group: default() });
            }
        }
    }
}

/// Each tinted view's bind group: its view uniform and depth, and the media.
fn prepare_bind_groups(
    mut views: Query<(&ViewDepthTexture, &mut ViewMediumTint)>,
    uniform: Res<MediaUniform>,
    view_uniforms: Res<ViewUniforms>,
    pipeline: Res<DimPipeline>,
    pipeline_cache: Res<PipelineCache>,
    device: Res<RenderDevice>,
) {
    let (Some(view_buffer), Some(view_binding), Some(media_buffer)) = (view_uniforms.uniforms.buffer(), view_uniforms.uniforms.binding(), uniform.0.buffer())
    else {
        return;
    };
    for (view_depth, mut view) in &mut views {
        let layout = pipeline.layout(Dim::Tint, view.multisampled, &pipeline_cache);
        let bound = [layout.into(), view_buffer.into(), view_depth.view().into(), media_buffer.into()];
        view.bind_group.get(&bound, || {
            device.create_bind_group(
                "medium_tint_bind_group",
                layout,
                &BindGroupEntries::sequential((view_binding.clone(), view_depth.view(), media_buffer.as_entire_binding())),
            )
        });
    }
}

/// Multiplies the view's image by the tint.
fn tint(view: ViewQuery<(&ExtractedCamera, &ViewTarget, &ViewUniformOffset, &ViewMediumTint)>, pipeline_cache: Res<PipelineCache>, mut ctx: RenderContext) {
    let (camera, target, view_offset, tint) = view.into_inner();
    let (Some(bind_group), Some(pipeline)) = (tint.bind_group.current(), pipeline_cache.get_render_pipeline(tint.pipeline)) else {
        return;
    };
    dim::multiply(&mut ctx, target, camera.viewport.as_ref(), "caustics/medium_tint", pipeline, bind_group, view_offset.offset);
}
