//! The composite: receivers drawn a second time into the transparent phase (after
//! every opaque surface, sorted with the transparent ones), depth-tested and
//! additively blended. See the module docs of [`super`].

use super::{ExtractedReceivers, GpuViewCaustics, ViewCausticIrradiance, ViewCausticWork};
use crate::components::CausticReceiver;
use crate::report::PassRecorder;
use bevy::core_pipeline::core_3d::{CORE_3D_DEPTH_FORMAT, Transparent3d, TransparentSortingInfo3d};
use bevy::ecs::query::ROQueryItem;
use bevy::ecs::system::{SystemParamItem, lifetimeless::{Read, SRes}};
use bevy::mesh::{Mesh, MeshVertexBufferLayoutRef};
use bevy::pbr::{
    DrawMesh, MeshInputUniform, MeshPipeline, MeshPipelineKey, MeshPipelineViewLayoutKey, MeshUniform,
    RenderMeshInstances, SetMeshBindGroup, SetMeshViewBindGroup, ViewKeyCache, get_mesh_instance_world_from_local,
};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::{
    batching::gpu_preprocessing::BatchedInstanceBuffers,
    mesh::{RenderMesh, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_phase::{
        AddRenderCommand, DrawFunctions, PhaseItem, PhaseItemExtraIndex, RenderCommand, RenderCommandResult,
        SetItemPipeline, TrackedRenderPass, ViewSortedRenderPhases,
    },
    render_resource::{binding_types::*, *},
    renderer::{RenderDevice, RenderQueue},
    sync_world::MainEntity,
    texture::{FallbackImage, GpuImage},
    view::{ExtractedView, RenderVisibleEntities},
};

/// The composite's pipeline: Bevy's mesh pipeline layouts plus the view's caustic
/// buffer (group 1) and the receiver's albedo (group 3).
#[derive(Resource)]
pub struct CausticCompositePipeline {
    mesh_pipeline: MeshPipeline,
    pub view_layout: BindGroupLayoutDescriptor,
    material_layout: BindGroupLayoutDescriptor,
    shader: Handle<Shader>,
}

pub(super) fn build(render_app: &mut SubApp) {
    render_app
        .init_resource::<SpecializedMeshPipelines<CausticCompositePipeline>>()
        .init_resource::<ReceiverBindGroups>()
        .add_render_command::<Transparent3d, DrawCausticComposite>();
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
            (
                uniform_buffer::<ReceiverUniform>(false),
                texture_2d(TextureSampleType::Float { filterable: true }),
                sampler(SamplerBindingType::Filtering),
            ),
        ),
    );
    commands.insert_resource(CausticCompositePipeline {
        mesh_pipeline: mesh_pipeline.clone(),
        view_layout,
        material_layout,
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "composite.wgsl"),
    });
}

impl SpecializedMeshPipeline for CausticCompositePipeline {
    type Key = MeshPipelineKey;

    fn specialize(
        &self,
        key: Self::Key,
        layout: &MeshVertexBufferLayoutRef,
    ) -> Result<RenderPipelineDescriptor, SpecializedMeshPipelineError> {
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
                self.view_layout.clone(),
                self.mesh_pipeline.mesh_layouts.model_only.clone(),
                self.material_layout.clone(),
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
#[derive(ShaderType, Clone, Copy)]
struct ReceiverUniform {
    base_color: Vec4,
    uv_transform: Mat3,
    fog_enabled: u32,
}

/// Render world: each receiver's albedo bind group, by main-world entity.
#[derive(Resource, Default)]
pub(super) struct ReceiverBindGroups(HashMap<MainEntity, BindGroup>);

/// Builds each receiver's albedo bind group, when some view has caustics work.
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
    bind_groups.0.clear();
    if views.is_empty() {
        return;
    }
    let layout = pipeline_cache.get_bind_group_layout(&pipeline.material_layout);
    for (entity, albedo) in &receivers.0 {
        let image = match albedo.texture {
            Some(id) => match images.get(id) {
                Some(image) => image,
                // Texture still loading: draw nothing rather than the wrong colour.
                None => continue,
            },
            None => &fallback.d2,
        };
        let mut uniform = UniformBuffer::from(ReceiverUniform {
            base_color: Vec4::from_array(albedo.base_color.to_f32_array()),
            uv_transform: albedo.uv_transform,
            fog_enabled: albedo.fog_enabled as u32,
        });
        uniform.set_label(Some("caustic_receiver_albedo"));
        uniform.write_buffer(&device, &queue);
        let Some(binding) = uniform.binding() else { continue };
        let bind_group = device.create_bind_group(
            "caustic_receiver_bind_group",
            &layout,
            &BindGroupEntries::sequential((binding, &image.texture_view, &image.sampler)),
        );
        bind_groups.0.insert(*entity, bind_group);
    }
}

/// Queues every visible receiver of every view with caustics work into the view's
/// transparent phase.
#[expect(clippy::too_many_arguments)]
pub(super) fn queue(
    draw_functions: Res<DrawFunctions<Transparent3d>>,
    pipeline: Res<CausticCompositePipeline>,
    mut pipelines: ResMut<SpecializedMeshPipelines<CausticCompositePipeline>>,
    pipeline_cache: Res<PipelineCache>,
    mut phases: ResMut<ViewSortedRenderPhases<Transparent3d>>,
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
        let (Some(phase), Some(&view_key), Some(visible)) = (
            phases.get_mut(&view.retained_view_entity),
            view_key_cache.get(&view.retained_view_entity),
            visible.get::<CausticReceiver>(),
        ) else {
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
            let key = view_key
                | MeshPipelineKey::from_primitive_topology_and_strip_index(mesh.primitive_topology(), mesh.index_format());
            let Ok(pipeline_id) = pipelines.specialize(&pipeline_cache, &pipeline, key, &mesh.layout) else {
                continue;
            };
            let center = get_mesh_instance_world_from_local(
                *main_entity,
                instance.current_uniform_index,
                &mesh_instances,
                batched.as_deref(),
            )
            .transform_point3(mesh.aabb_center);
            // Keyed by the render entity (materials use a placeholder) so the receiver's
            // own transparent draw, if any, is kept.
            phase.add_transient(Transparent3d {
                sorting_info: TransparentSortingInfo3d::Sorted { mesh_center: center, depth_bias: 0.0 },
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

type DrawCausticComposite = (
    SetItemPipeline,
    SetMeshViewBindGroup<0>,
    SetCausticIrradianceBindGroup<1>,
    SetMeshBindGroup<2>,
    SetReceiverBindGroup<3>,
    DrawMesh,
);

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

    fn render<'w>(
        item: &P,
        _: (),
        _: Option<()>,
        bind_groups: SystemParamItem<'w, '_, Self::Param>,
        pass: &mut TrackedRenderPass<'w>,
    ) -> RenderCommandResult {
        let Some(bind_group) = bind_groups.into_inner().0.get(&item.main_entity()) else {
            return RenderCommandResult::Skip;
        };
        pass.set_bind_group(I, bind_group, &[]);
        RenderCommandResult::Success
    }
}
