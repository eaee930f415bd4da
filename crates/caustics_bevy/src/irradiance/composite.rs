//! The composite: receivers drawn a second time, depth-tested against the finished
//! opaque depth and additively blended, in a phase of their own
//! ([`CausticComposite3d`]) between Bevy's opaque and transmissive passes — so that
//! the copy of the opaque image that Bevy's transmission samples already holds the
//! caustics, and transparent surfaces drawn later blend over them. See the module
//! docs of [`super`].

use super::kept_bind_group::{KeptLayout, write_changed};
use super::{ExtractedReceivers, GpuViewCaustics, ViewCausticIrradiance, ViewCausticWork};
use crate::components::CausticReceiver;
use crate::report::PassRecorder;
use bevy::camera::{MainPassResolutionOverride, Viewport};
use bevy::core_pipeline::core_3d::CORE_3D_DEPTH_FORMAT;
use bevy::core_pipeline::{Core3dSystems, schedule::Core3d};
use bevy::ecs::entity::EntityHash;
use bevy::ecs::query::ROQueryItem;
use bevy::ecs::system::{
    SystemParamItem,
    lifetimeless::{Read, SRes},
};
use bevy::math::FloatOrd;
use bevy::mesh::{Mesh, MeshVertexBufferLayoutRef};
use bevy::pbr::{
    DrawMesh, MeshInputUniform, MeshPipeline, MeshPipelineKey, MeshPipelineViewLayoutKey, MeshUniform, RenderMeshInstances, SetMeshBindGroup,
    SetMeshViewBindGroup, ViewKeyCache, get_mesh_instance_world_from_local,
};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::camera::ExtractedCamera;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::renderer::{RenderContext, ViewQuery};
use bevy::render::view::{RetainedViewEntity, ViewDepthTexture, ViewTarget};
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderSystems};
use bevy::render::{
    batching::gpu_preprocessing::BatchedInstanceBuffers,
    mesh::{RenderMesh, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_phase::{
        AddRenderCommand, CachedRenderPipelinePhaseItem, DrawFunctionId, DrawFunctions, PhaseItem, PhaseItemExtraIndex, RenderCommand, RenderCommandResult,
        SetItemPipeline, SortedPhaseItem, SortedRenderPhasePlugin, TrackedRenderPass, ViewSortedRenderPhases,
    },
    render_resource::{binding_types::*, *},
    renderer::{RenderDevice, RenderQueue},
    sync_world::MainEntity,
    texture::{FallbackImage, GpuImage},
    view::{ExtractedView, RenderVisibleEntities},
};
use indexmap::IndexMap;
use std::ops::Range;

/// A receiver drawn again with its caustic light: the composite's phase item, sorted
/// front to back (additive blending needs no order; nearer receivers hide farther
/// fragments from the depth test).
pub struct CausticComposite3d {
    /// The receiver's centre, from which `distance` is measured each frame.
    pub mesh_center: Vec3,
    pub distance: f32,
    pub pipeline: CachedRenderPipelineId,
    pub entity: (Entity, MainEntity),
    pub draw_function: DrawFunctionId,
    pub batch_range: Range<u32>,
    pub extra_index: PhaseItemExtraIndex,
    pub indexed: bool,
}

impl PhaseItem for CausticComposite3d {
    fn entity(&self) -> Entity {
        self.entity.0
    }

    fn main_entity(&self) -> MainEntity {
        self.entity.1
    }

    fn draw_function(&self) -> DrawFunctionId {
        self.draw_function
    }

    fn batch_range(&self) -> &Range<u32> {
        &self.batch_range
    }

    fn batch_range_mut(&mut self) -> &mut Range<u32> {
        &mut self.batch_range
    }

    fn extra_index(&self) -> PhaseItemExtraIndex {
        self.extra_index.clone()
    }

    fn batch_range_and_extra_index_mut(&mut self) -> (&mut Range<u32>, &mut PhaseItemExtraIndex) {
        (&mut self.batch_range, &mut self.extra_index)
    }
}

impl SortedPhaseItem for CausticComposite3d {
    type SortKey = std::cmp::Reverse<FloatOrd>;

    fn sort_key(&self) -> Self::SortKey {
        std::cmp::Reverse(FloatOrd(self.distance))
    }

    fn recalculate_sort_keys(items: &mut IndexMap<(Entity, MainEntity), Self, EntityHash>, view: &ExtractedView) {
        let rangefinder = view.rangefinder3d();
        for item in items.values_mut() {
            item.distance = rangefinder.distance(&item.mesh_center);
        }
    }

    fn indexed(&self) -> bool {
        self.indexed
    }
}

impl CachedRenderPipelinePhaseItem for CausticComposite3d {
    fn cached_pipeline(&self) -> CachedRenderPipelineId {
        self.pipeline
    }
}

/// The composite's pipeline: Bevy's mesh pipeline layouts plus the view's caustic
/// buffer (group 1) and the receiver's albedo (group 3).
#[derive(Resource)]
pub struct CausticCompositePipeline {
    mesh_pipeline: MeshPipeline,
    /// Group 1: the view's caustic buffer and settings.
    pub view_layout: KeptLayout,
    material_layout: KeptLayout,
    shader: Handle<Shader>,
}

pub(super) fn build(app: &mut App) {
    app.add_plugins(SortedRenderPhasePlugin::<CausticComposite3d, MeshPipeline>::new(default()));
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<SpecializedMeshPipelines<CausticCompositePipeline>>()
        .init_resource::<ReceiverBindGroups>()
        .init_resource::<DrawFunctions<CausticComposite3d>>()
        .add_render_command::<CausticComposite3d, DrawCausticComposite>()
        .add_systems(ExtractSchedule, extract_phases)
        .add_systems(Render, bevy::render::render_phase::sort_phase_system::<CausticComposite3d>.in_set(RenderSystems::PhaseSort))
        .add_systems(
            Core3d,
            draw_composite
                .after(bevy::core_pipeline::core_3d::main_opaque_pass_3d)
                .before(bevy::pbr::main_transmissive_pass_3d)
                .before(bevy::core_pipeline::core_3d::main_transparent_pass_3d)
                .in_set(Core3dSystems::MainPass),
        );
}

/// The 3D cameras that show caustics.
type CausticCameras = Query<'static, 'static, (Entity, &'static Camera), (With<Camera3d>, With<crate::Caustics>)>;

/// Gives every 3D camera with caustics work its composite phase for the frame, and
/// lets those of other cameras go.
fn extract_phases(
    mut phases: ResMut<ViewSortedRenderPhases<CausticComposite3d>>,
    cameras: Extract<CausticCameras>,
    mut live: Local<bevy::platform::collections::HashSet<RetainedViewEntity>>,
) {
    live.clear();
    for (entity, camera) in &cameras {
        if camera.is_active {
            let view = RetainedViewEntity::new(entity.into(), None, 0);
            phases.prepare_for_new_frame(view);
            live.insert(view);
        }
    }
    phases.retain(|view, _| live.contains(view));
}

/// Draws the view's composite phase onto its image, loading the opaque pass's colour
/// and depth.
pub(crate) fn draw_composite(
    world: &World,
    view: ViewQuery<(&ExtractedCamera, &ExtractedView, &ViewTarget, &ViewDepthTexture, Option<&MainPassResolutionOverride>)>,
    phases: Res<ViewSortedRenderPhases<CausticComposite3d>>,
    mut ctx: RenderContext,
) {
    let view_entity = view.entity();
    let (camera, extracted_view, target, depth, resolution_override) = view.into_inner();
    let Some(phase) = phases.get(&extracted_view.retained_view_entity).filter(|p| !p.items.is_empty()) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
        label: Some("caustic_composite"),
        color_attachments: &[Some(target.get_color_attachment())],
        depth_stencil_attachment: Some(depth.get_attachment(StoreOp::Store)),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    let span = diagnostics.pass_span(&mut pass, "caustics/composite");
    if let Some(viewport) = Viewport::from_viewport_and_override(camera.viewport.as_ref(), resolution_override) {
        pass.set_camera_viewport(&viewport);
    }
    if let Err(err) = phase.render(&mut pass, world, view_entity) {
        error!("bevy_caustics: the caustic composite did not draw: {err:?}");
    }
    span.end(&mut pass);
}

pub(super) fn init_pipeline(mut commands: Commands, mesh_pipeline: Res<MeshPipeline>, asset_server: Res<AssetServer>) {
    let view_layout = BindGroupLayoutDescriptor::new(
        "caustic_irradiance_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (texture_2d(TextureSampleType::Float { filterable: false }), uniform_buffer::<GpuViewCaustics>(false)),
        ),
    );
    let material_layout = BindGroupLayoutDescriptor::new(
        "caustic_receiver_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (uniform_buffer::<ReceiverUniform>(false), texture_2d(TextureSampleType::Float { filterable: true }), sampler(SamplerBindingType::Filtering)),
        ),
    );
    commands.insert_resource(CausticCompositePipeline {
        mesh_pipeline: mesh_pipeline.clone(),
        view_layout: KeptLayout::new(view_layout),
        material_layout: KeptLayout::new(material_layout),
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "composite.wgsl"),
    });
}

impl SpecializedMeshPipeline for CausticCompositePipeline {
    type Key = MeshPipelineKey;

    fn specialize(&self, key: Self::Key, layout: &MeshVertexBufferLayoutRef) -> Result<RenderPipelineDescriptor, SpecializedMeshPipelineError> {
        let mut attributes = vec![Mesh::ATTRIBUTE_POSITION.at_shader_location(0)];
        let mut shader_defs = Vec::new();
        if layout.0.contains(Mesh::ATTRIBUTE_UV_0) {
            attributes.push(Mesh::ATTRIBUTE_UV_0.at_shader_location(1));
            shader_defs.push("VERTEX_UVS".into());
        }
        if key.contains(MeshPipelineKey::DISTANCE_FOG) {
            shader_defs.push("DISTANCE_FOG".into());
        }
        if let Some(batch) = self.mesh_pipeline.per_object_buffer_batch_size {
            shader_defs.push(bevy::shader::ShaderDefVal::UInt("PER_OBJECT_BUFFER_BATCH_SIZE".into(), batch));
        }
        let view_layout = self.mesh_pipeline.get_view_layout(MeshPipelineViewLayoutKey::from(key));
        Ok(RenderPipelineDescriptor {
            label: Some("caustic_composite_pipeline".into()),
            layout: vec![
                view_layout.main_layout,
                self.view_layout.descriptor.clone(),
                super::mesh_layout(&self.mesh_pipeline, key),
                self.material_layout.descriptor.clone(),
            ],
            vertex: VertexState {
                shader: self.shader.clone(),
                shader_defs: shader_defs.clone(),
                buffers: vec![layout.0.get_layout(&attributes)?],
                ..default()
            },
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                shader_defs,
                targets: vec![Some(ColorTargetState {
                    format: key.target_format(),
                    blend: Some(BlendState {
                        color: BlendComponent { src_factor: BlendFactor::One, dst_factor: BlendFactor::One, operation: BlendOperation::Add },
                        alpha: BlendComponent::OVER,
                    }),
                    write_mask: ColorWrites::COLOR,
                })],
                ..default()
            }),
            primitive: PrimitiveState {
                topology: key.primitive_topology(),
                strip_index_format: key.strip_index_format(),
                cull_mode: Some(Face::Back),
                ..default()
            },
            // Reverse-Z: pass where the receiver is the nearest surface; never write depth.
            depth_stencil: Some(DepthStencilState {
                format: CORE_3D_DEPTH_FORMAT,
                depth_write_enabled: Some(false),
                depth_compare: Some(CompareFunction::GreaterEqual),
                stencil: default(),
                bias: default(),
            }),
            multisample: MultisampleState { count: key.msaa_samples(), ..default() },
            ..default()
        })
    }
}

/// A receiver's albedo parameters on the GPU.
#[derive(ShaderType, Clone, Copy, PartialEq)]
struct ReceiverUniform {
    base_color: Vec4,
    uv_transform: Mat3,
    fog_enabled: u32,
}

/// A receiver's albedo uniform and bind group, kept across frames while its albedo and
/// its texture stay the same.
struct ReceiverBinding {
    uniform: UniformBuffer<ReceiverUniform>,
    texture: TextureViewId,
    bind_group: BindGroup,
}

/// Render world: each receiver's albedo bind group, by main-world entity.
#[derive(Resource, Default)]
pub(super) struct ReceiverBindGroups(HashMap<MainEntity, ReceiverBinding>);

/// Keeps each receiver's albedo bind group up to date, when some view has caustics
/// work: a new uniform buffer and bind group only for a new receiver or a new texture,
/// an upload only when its albedo changed.
#[expect(clippy::too_many_arguments)]
pub(super) fn prepare_receiver_bind_groups(
    views: Query<(), With<ViewCausticWork>>,
    receivers: Res<ExtractedReceivers>,
    mut bind_groups: ResMut<ReceiverBindGroups>,
    pipeline: Res<CausticCompositePipeline>,
    pipeline_cache: Res<PipelineCache>,
    images: Res<RenderAssets<GpuImage>>,
    fallback: Res<FallbackImage>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    if views.is_empty() {
        bind_groups.0.clear();
        return;
    }
    bind_groups.0.retain(|entity, _| receivers.0.contains_key(entity));
    let layout = pipeline.material_layout.get(&pipeline_cache);
    for (entity, albedo) in &receivers.0 {
        let image = match albedo.texture {
            Some(id) => match images.get(id) {
                Some(image) => image,
                // Texture still loading: draw nothing rather than the wrong colour.
                None => {
                    bind_groups.0.remove(entity);
                    continue;
                }
            },
            None => &fallback.d2,
        };
        let value = ReceiverUniform {
            base_color: Vec4::from_array(albedo.base_color.to_f32_array()),
            uv_transform: albedo.uv_transform,
            fog_enabled: albedo.fog_enabled as u32,
        };
        let texture = image.texture_view.id();
        if let Some(kept) = bind_groups.0.get_mut(entity)
            && kept.texture == texture
        {
            write_changed(&mut kept.uniform, value, &device, &queue);
            continue;
        }
        let mut uniform = UniformBuffer::from(value);
        uniform.set_label(Some("caustic_receiver_albedo"));
        uniform.write_buffer(&device, &queue);
        let Some(binding) = uniform.binding() else { continue };
        let bind_group =
            device.create_bind_group("caustic_receiver_bind_group", layout, &BindGroupEntries::sequential((binding, &image.texture_view, &image.sampler)));
        bind_groups.0.insert(*entity, ReceiverBinding { uniform, texture, bind_group });
    }
}

/// Queues every visible receiver of every view with caustics work into the view's
/// composite phase.
#[expect(clippy::too_many_arguments)]
pub(super) fn queue(
    draw_functions: Res<DrawFunctions<CausticComposite3d>>,
    pipeline: Res<CausticCompositePipeline>,
    mut pipelines: ResMut<SpecializedMeshPipelines<CausticCompositePipeline>>,
    pipeline_cache: Res<PipelineCache>,
    mut phases: ResMut<ViewSortedRenderPhases<CausticComposite3d>>,
    views: Query<(&ExtractedView, &RenderVisibleEntities), With<ViewCausticWork>>,
    view_key_cache: Res<ViewKeyCache>,
    render_meshes: Res<RenderAssets<RenderMesh>>,
    mesh_instances: Res<RenderMeshInstances>,
    mesh_allocator: Res<MeshAllocator>,
    batched: Option<Res<BatchedInstanceBuffers<MeshUniform, MeshInputUniform>>>,
    receivers: Res<ExtractedReceivers>,
    recorder: Res<PassRecorder>,
) {
    let draw_function = draw_functions.read().id::<DrawCausticComposite>();
    for (view, visible) in &views {
        let (Some(phase), Some(&view_key), Some(visible)) =
            (phases.get_mut(&view.retained_view_entity), view_key_cache.get(&view.retained_view_entity), visible.get::<CausticReceiver>())
        else {
            continue;
        };
        let mut queued = false;
        for (render_entity, main_entity) in visible.iter_visible() {
            if !receivers.0.contains_key(main_entity) {
                continue;
            }
            let Some(instance) = mesh_instances.render_mesh_queue_data(*main_entity) else { continue };
            let Some(mesh) = render_meshes.get(instance.mesh_asset_id()) else { continue };
            let Some(slabs) = mesh_allocator.mesh_slabs(&instance.mesh_asset_id()) else { continue };
            // A skinned or morphed receiver gets no caustics.
            let Some(mesh_key) = super::mesh_key(&instance, mesh) else { continue };
            let key = view_key | mesh_key;
            let Ok(pipeline_id) = pipelines.specialize(&pipeline_cache, &pipeline, key, &mesh.layout) else {
                continue;
            };
            let center = get_mesh_instance_world_from_local(*main_entity, instance.current_uniform_index, &mesh_instances, batched.as_deref())
                .transform_point3(mesh.aabb_center);
            phase.add_transient(CausticComposite3d {
                mesh_center: center,
                entity: (*render_entity, *main_entity),
                draw_function,
                pipeline: pipeline_id,
                batch_range: 0..1,
                extra_index: PhaseItemExtraIndex::None,
                indexed: slabs.index_slab_id.is_some(),
                distance: 0.0,
            });
            queued = true;
        }
        if queued {
            recorder.record("composite");
        }
    }
}

type DrawCausticComposite =
    (SetItemPipeline, SetMeshViewBindGroup<0>, SetCausticIrradianceBindGroup<1>, SetMeshBindGroup<2>, SetReceiverBindGroup<3>, DrawMesh);

struct SetCausticIrradianceBindGroup<const I: usize>;

impl<P: PhaseItem, const I: usize> RenderCommand<P> for SetCausticIrradianceBindGroup<I> {
    type Param = ();
    type ViewQuery = Option<Read<ViewCausticIrradiance>>;
    type ItemQuery = ();

    fn render<'w>(
        _: &P,
        view: ROQueryItem<'w, '_, Self::ViewQuery>,
        _: Option<()>,
        _: SystemParamItem<'w, '_, Self::Param>,
        pass: &mut TrackedRenderPass<'w>,
    ) -> RenderCommandResult {
        let Some(buffer) = view else { return RenderCommandResult::Skip };
        pass.set_bind_group(I, &buffer.bind_group, &[]);
        RenderCommandResult::Success
    }
}

struct SetReceiverBindGroup<const I: usize>;

impl<P: PhaseItem, const I: usize> RenderCommand<P> for SetReceiverBindGroup<I> {
    type Param = SRes<ReceiverBindGroups>;
    type ViewQuery = ();
    type ItemQuery = ();

    fn render<'w>(item: &P, _: (), _: Option<()>, bind_groups: SystemParamItem<'w, '_, Self::Param>, pass: &mut TrackedRenderPass<'w>) -> RenderCommandResult {
        let Some(binding) = bind_groups.into_inner().0.get(&item.main_entity()) else {
            return RenderCommandResult::Skip;
        };
        pass.set_bind_group(I, &binding.bind_group, &[]);
        RenderCommandResult::Success
    }
}
