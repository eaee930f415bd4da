//! The media's transmittance behind Bevy's transmissive surfaces: water seen from above.
//!
//! Bevy's volumetric fog dims each pixel along its eye ray to the depth the frame ends
//! with, which where a transmissive surface is in front (the water of a pool seen from
//! above) is that surface's; and Bevy's transmission shows what lies behind the surface
//! by sampling a copy of the opaque image taken before the fog. Without this pass the
//! pool floor under 3 m of water would be as bright as in air. Between the opaque pass
//! (with the caustic composite) and Bevy's transmissive pass, for each view that draws
//! Bevy's fog, this module
//! 1. draws the view's transmissive meshes depth-only (`caustics/medium_surface_depth`):
//!    the nearest transmissive surface at each pixel;
//! 2. multiplies each pixel of the opaque image that has such a surface in front of
//!    it by exp(−σₜ ℓ) in each channel, ℓ the eye ray's length inside the media
//!    between that surface and the opaque point (`caustics/medium_behind_transmission`,
//!    through [`super::dim`]).
//!
//! Bevy's fog and [`super::tint`] then dim the ray in front of the surface, so each stretch of the path
//! is dimmed once, the caustics the composite added included. The surfaces are Bevy's
//! `Transmissive3d` phase of the view (every material that reads the transmission
//! texture), drawn with back faces culled: a face that Bevy culls draws nothing over
//! the pixel it would have dimmed. Left out: skinned and morphed meshes (drawn
//! undimmed behind), refraction's offset (a pixel is dimmed along its own eye ray, not
//! the refracted one), and with `ScreenSpaceTransmission::steps` > 1 the stretches
//! between transmissive layers.

use super::dim::{self, Dim, DimKey, DimPipeline, MediaUniform};
use crate::irradiance::kept_bind_group::KeptBindGroup;
use crate::irradiance::{ExtractedMedia, cached_texture, mesh_key, mesh_layout};
use crate::report::PassRecorder;
use bevy::core_pipeline::core_3d::CORE_3D_DEPTH_FORMAT;
use bevy::core_pipeline::{Core3dSystems, schedule::Core3d};
use bevy::ecs::query::ROQueryItem;
use bevy::ecs::system::{
    SystemParamItem,
    lifetimeless::{Read, SRes},
};
use bevy::light::VolumetricFog;
use bevy::mesh::{Mesh, MeshVertexBufferLayoutRef};
use bevy::pbr::{
    DrawMesh, MeshPipeline, MeshPipelineKey, MeshPipelineViewLayoutKey, RenderMeshInstances, SetMeshBindGroup, SetMeshViewBindGroup,
    SetMeshViewBindingArrayBindGroup, Transmissive3d, ViewKeyCache,
};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::camera::ExtractedCamera;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::mesh::RenderMesh;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_phase::{AddRenderCommand, DrawFunctions, PhaseItem, RenderCommand, RenderCommandResult, TrackedRenderPass, ViewSortedRenderPhases};
use bevy::render::render_resource::*;
use bevy::render::renderer::{RenderContext, RenderDevice, ViewQuery};
use bevy::render::sync_world::MainEntity;
use bevy::render::texture::{CachedTexture, TextureCache};
use bevy::render::view::{ExtractedView, ViewDepthTexture, ViewTarget, ViewUniformOffset, ViewUniforms};
use bevy::render::{Render, RenderApp, RenderStartup, RenderSystems};

pub(super) fn build(app: &mut App) {
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<SpecializedMeshPipelines<SurfaceDepthPipeline>>()
        .add_render_command::<Transmissive3d, DrawSurfaceDepth>()
        .add_systems(RenderStartup, init_pipeline.after(bevy::pbr::MeshPipelineSystems).after(dim::init_pipeline))
        .add_systems(
            Render,
            (queue.in_set(RenderSystems::Queue).after(RenderSystems::QueueMeshes), prepare_bind_groups.in_set(RenderSystems::PrepareBindGroups)),
        )
        .add_systems(
            Core3d,
            dim_behind_transmission.after(crate::irradiance::draw_composite).before(bevy::pbr::main_transmissive_pass_3d).in_set(Core3dSystems::MainPass),
        );
}

/// The depth-only pipeline of a transmissive mesh: Bevy's mesh pipeline layouts, the
/// vertex stage of `media.wgsl`, no fragment stage.
#[derive(Resource, Clone)]
pub struct SurfaceDepthPipeline {
    mesh_pipeline: MeshPipeline,
    shader: Handle<Shader>,
}

impl SpecializedMeshPipeline for SurfaceDepthPipeline {
    type Key = MeshPipelineKey;

    fn specialize(&self, key: Self::Key, layout: &MeshVertexBufferLayoutRef) -> Result<RenderPipelineDescriptor, SpecializedMeshPipelineError> {
        let mut shader_defs = Vec::new();
        if let Some(batch) = self.mesh_pipeline.per_object_buffer_batch_size {
            shader_defs.push(bevy::shader::ShaderDefVal::UInt("PER_OBJECT_BUFFER_BATCH_SIZE".into(), batch));
        }
        let view_layout = self.mesh_pipeline.get_view_layout(MeshPipelineViewLayoutKey::from(key));
        Ok(RenderPipelineDescriptor {
            label: Some("medium_surface_depth_pipeline".into()),
            layout: vec![view_layout.main_layout, view_layout.binding_array_layout, mesh_layout(&self.mesh_pipeline, key)],
            vertex: VertexState {
                shader: self.shader.clone(),
                shader_defs,
                entry_point: Some("surface_depth".into()),
                buffers: vec![layout.0.get_layout(&[Mesh::ATTRIBUTE_POSITION.at_shader_location(0)])?],
            },
            fragment: None,
            primitive: PrimitiveState {
                topology: key.primitive_topology(),
                strip_index_format: key.strip_index_format(),
                cull_mode: Some(Face::Back),
                ..default()
            },
            // Reverse Z: keep the nearest surface.
            depth_stencil: Some(DepthStencilState {
                format: CORE_3D_DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(CompareFunction::Greater),
                stencil: default(),
                bias: default(),
            }),
            ..default()
        })
    }
}

fn init_pipeline(mut commands: Commands, mesh_pipeline: Res<MeshPipeline>, dim: Res<DimPipeline>) {
    commands.insert_resource(SurfaceDepthPipeline { mesh_pipeline: mesh_pipeline.clone(), shader: dim.shader() });
}

/// Render world, on a view whose opaque image is dimmed behind its transmissive
/// surfaces this frame: the pipelines, and what the passes draw into and bind.
#[derive(Component)]
pub struct ViewMediumBehindTransmission {
    /// Each transmissive mesh's depth pipeline, by main-world entity.
    surfaces: HashMap<MainEntity, CachedRenderPipelineId>,
    dim: CachedRenderPipelineId,
    multisampled: bool,
    /// The surfaces' depth, and the dimming pass's bind group, made each frame in
    /// `prepare_bind_groups`.
    depth: Option<CachedTexture>,
    bind_group: KeptBindGroup,
}

/// Views that draw Bevy's fog, and what they had last frame.
type FogViews = (Entity, &'static ExtractedView, &'static ViewTarget, &'static Msaa, Option<&'static mut ViewMediumBehindTransmission>);

/// Gives each view that draws Bevy's fog of the media and has transmissive surfaces
/// the pipelines of its passes; takes them from the others.
#[expect(clippy::too_many_arguments)]
fn queue(
    mut commands: Commands,
    mut views: Query<FogViews, With<VolumetricFog>>,
    others: Query<Entity, (With<ViewMediumBehindTransmission>, Without<VolumetricFog>)>,
    phases: Res<ViewSortedRenderPhases<Transmissive3d>>,
    media: Res<ExtractedMedia>,
    view_key_cache: Res<ViewKeyCache>,
    (mesh_instances, render_meshes): (Res<RenderMeshInstances>, Res<RenderAssets<RenderMesh>>),
    (surface_pipeline, dim_pipeline): (Res<SurfaceDepthPipeline>, Res<DimPipeline>),
    (mut surface_pipelines, mut dim_pipelines): (ResMut<SpecializedMeshPipelines<SurfaceDepthPipeline>>, ResMut<SpecializedRenderPipelines<DimPipeline>>),
    pipeline_cache: Res<PipelineCache>,
    recorder: Res<PassRecorder>,
) {
    for entity in &others {
        commands.entity(entity).remove::<ViewMediumBehindTransmission>();
    }
    for (entity, view, target, msaa, mut kept) in &mut views {
        let phase = phases.get(&view.retained_view_entity).filter(|p| !p.items.is_empty());
        let (Some(phase), Some(&view_key), false) = (phase, view_key_cache.get(&view.retained_view_entity), media.0.is_empty()) else {
            if kept.is_some() {
                commands.entity(entity).remove::<ViewMediumBehindTransmission>();
            }
            continue;
        };
        let mut surfaces = kept.as_mut().map(|kept| std::mem::take(&mut kept.surfaces)).unwrap_or_default();
        surfaces.clear();
        for item in phase.items.values() {
            let main_entity = item.main_entity();
            let Some(instance) = mesh_instances.render_mesh_queue_data(main_entity) else { continue };
            let Some(mesh) = render_meshes.get(instance.mesh_asset_id()) else { continue };
            let Some(mesh_key) = mesh_key(&instance, mesh) else { continue };
            let key = view_key | mesh_key;
            if let Ok(pipeline) = surface_pipelines.specialize(&pipeline_cache, &surface_pipeline, key, &mesh.layout) {
                surfaces.insert(main_entity, pipeline);
            }
        }
        let multisampled = msaa.samples() > 1;
        let key = DimKey { dim: Dim::BehindTransmission, multisampled, format: target.main_texture_format() };
        let dim = dim_pipelines.specialize(&pipeline_cache, &dim_pipeline, key);
        recorder.record("medium_behind_transmission");
        match kept {
            Some(mut kept) => {
                kept.surfaces = surfaces;
                kept.dim = dim;
                kept.multisampled = multisampled;
            }
            None => {
                commands.entity(entity).insert(ViewMediumBehindTransmission { surfaces, dim, multisampled, depth: None, bind_group: default() });
            }
        }
    }
}

/// The surfaces' depth texture of each view with the passes, and the dimming pass's
/// bind group.
fn prepare_bind_groups(
    mut views: Query<(&ExtractedCamera, &ViewDepthTexture, &mut ViewMediumBehindTransmission)>,
    uniform: Res<MediaUniform>,
    view_uniforms: Res<ViewUniforms>,
    pipeline: Res<DimPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
) {
    let (Some(view_buffer), Some(view_binding), Some(media_buffer)) = (view_uniforms.uniforms.buffer(), view_uniforms.uniforms.binding(), uniform.0.buffer())
    else {
        return;
    };
    for (camera, view_depth, mut view) in &mut views {
        let Some(size) = camera.physical_target_size.filter(|s| s.x > 0 && s.y > 0) else {
            view.depth = None;
            continue;
        };
        let usage = TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING;
        let depth = cached_texture(&mut texture_cache, &device, "caustic_medium_surface_depth", size, CORE_3D_DEPTH_FORMAT, usage);
        let layout = pipeline.layout(Dim::BehindTransmission, view.multisampled, &pipeline_cache);
        let bound = [layout.into(), view_buffer.into(), view_depth.view().into(), media_buffer.into(), (&depth.default_view).into()];
        view.bind_group.get(&bound, || {
            device.create_bind_group(
                "medium_behind_transmission_bind_group",
                layout,
                &BindGroupEntries::sequential((view_binding.clone(), view_depth.view(), media_buffer.as_entire_binding(), &depth.default_view)),
            )
        });
        view.depth = Some(depth);
    }
}

/// Draws the view's transmissive surfaces' depth, then dims its opaque image behind
/// them.
fn dim_behind_transmission(
    world: &World,
    view: ViewQuery<(&ExtractedCamera, &ExtractedView, &ViewTarget, &ViewUniformOffset, &ViewMediumBehindTransmission)>,
    phases: Res<ViewSortedRenderPhases<Transmissive3d>>,
    draw_functions: Res<DrawFunctions<Transmissive3d>>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let view_entity = view.entity();
    let (camera, extracted_view, target, view_offset, passes) = view.into_inner();
    let (Some(phase), Some(depth), Some(bind_group), Some(dim)) =
        (phases.get(&extracted_view.retained_view_entity), passes.depth.as_ref(), passes.bind_group.current(), pipeline_cache.get_render_pipeline(passes.dim))
    else {
        return;
    };
    let viewport = camera.viewport.clone();
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();

    let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
        label: Some("medium_surface_depth"),
        color_attachments: &[],
        depth_stencil_attachment: Some(RenderPassDepthStencilAttachment {
            view: &depth.default_view,
            depth_ops: Some(Operations { load: LoadOp::Clear(0.0), store: StoreOp::Store }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    let span = diagnostics.pass_span(&mut pass, "caustics/medium_surface_depth");
    if let Some(viewport) = &viewport {
        pass.set_camera_viewport(viewport);
    }
    let id = draw_functions.read().id::<DrawSurfaceDepth>();
    let mut functions = draw_functions.write();
    functions.prepare(world);
    if let Some(draw) = functions.get_mut(id) {
        for item in phase.items.values().filter(|item| !item.batch_range().is_empty()) {
            if let Err(err) = draw.draw(world, &mut pass, view_entity, item) {
                error!("bevy_caustics: a transmissive surface's depth did not draw: {err:?}");
            }
        }
    }
    span.end(&mut pass);
    drop(pass);
    dim::multiply(&mut ctx, target, viewport.as_ref(), "caustics/medium_behind_transmission", dim, bind_group, view_offset.offset);
}

/// A transmissive mesh's depth: the view's pipeline for its mesh, Bevy's view and mesh
/// bind groups as the `Transmissive3d` phase has them.
type DrawSurfaceDepth = (SetSurfaceDepthPipeline, SetMeshViewBindGroup<0>, SetMeshViewBindingArrayBindGroup<1>, SetMeshBindGroup<2>, DrawMesh);

struct SetSurfaceDepthPipeline;

impl RenderCommand<Transmissive3d> for SetSurfaceDepthPipeline {
    type Param = SRes<PipelineCache>;
    type ViewQuery = Option<Read<ViewMediumBehindTransmission>>;
    type ItemQuery = ();

    fn render<'w>(
        item: &Transmissive3d,
        view: ROQueryItem<'w, '_, Self::ViewQuery>,
        _: Option<()>,
        cache: SystemParamItem<'w, '_, Self::Param>,
        pass: &mut TrackedRenderPass<'w>,
    ) -> RenderCommandResult {
        let pipeline = view.and_then(|v| v.surfaces.get(&item.main_entity())).and_then(|id| cache.into_inner().get_render_pipeline(*id));
        let Some(pipeline) = pipeline else { return RenderCommandResult::Skip };
        pass.set_render_pipeline(pipeline);
        RenderCommandResult::Success
    }
}
