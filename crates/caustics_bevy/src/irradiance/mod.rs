//! The per-view caustic irradiance buffer and the one composite step that shows it.
//!
//! Every technique accumulates caustic irradiance `E` (the light's units per m², lux
//! for Bevy's lights) into an HDR buffer the size of the view, at the surface each
//! pixel sees. It is stored as `E · exposure` (the view's exposure, as `bevy_pbr`
//! applies it to lights), each pass's share capped at [`MAX_EXPOSED_IRRADIANCE`], so
//! that a 100 000 lux sun focused a thousandfold under Bevy's default exposure stays
//! finite in half floats. The composite then draws the [`CausticReceiver`] meshes once more, after the
//! opaque pass and depth-tested against it, adding the Lambertian radiance
//! `albedo/π · E · exposure` — what `bevy_pbr` adds for the same irradiance from a
//! light — so caustics land on receivers only, with their unmodified
//! `StandardMaterial` colour and texture, and only where they are visible.
//!
//! An application can supply the buffer itself with [`InjectedIrradiance`] (the demo
//! injects the CPU reference tracer's irradiance this way). Caustics views need
//! Bevy's `Hdr` camera component: the composite adds linear light before tonemapping.

mod composite;

use crate::components::{CausticReceiver, InvalidCausticParams};
use crate::report::PassRecorder;
use bevy::camera::Hdr;
use bevy::core_pipeline::prepass::{DepthPrepass, NormalPrepass};
use bevy::core_pipeline::{Core3dSystems, FullscreenShader, schedule::Core3d};
use bevy::pbr::{MeshMaterial3d, StandardMaterial};
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    camera::ExtractedCamera,
    extract_component::{ExtractComponent, ExtractComponentPlugin},
    render_asset::RenderAssets,
    render_resource::{
        binding_types::{texture_2d, uniform_buffer},
        *,
    },
    renderer::{RenderContext, RenderDevice, ViewQuery},
    sync_world::{MainEntity, RenderEntity},
    texture::{CachedTexture, GpuImage, TextureCache},
    view::{ViewUniform, ViewUniformOffset, ViewUniforms},
};

pub use composite::CausticCompositePipeline;

/// Format of the caustic irradiance buffer: HDR float, blendable so that passes can
/// accumulate with additive blending.
pub const CAUSTIC_IRRADIANCE_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// The most a pass adds to, and the composite reads from, a texel of the buffer, as
/// `E · exposure`: 2048 times what shows a white surface at mid grey, far past what
/// tone mapping tells apart (only bloom sees the clipped part), while 32 such shares
/// still sum within half-float range (65 504). Under Bevy's default exposure (EV100
/// 9.7) it is 2·10⁶ lux, twenty direct suns. Below it the buffer holds `E · exposure`
/// exactly (to half-float precision); a `Rgba32Float` buffer would hold more at twice
/// the bandwidth of every caustics pass and the composite, for light nobody can see.
pub const MAX_EXPOSED_IRRADIANCE: f32 = 2048.0;

/// Caustic irradiance supplied by the application for a camera's view: a float image
/// (`Rgba32Float` or `Rgba16Float`), linear, in the light's units per m² (lux for Bevy
/// lights), one value per pixel for the surface that pixel sees (an image of another
/// size is resampled to the view). It starts the view's buffer each frame, before the
/// techniques add theirs. [`crate::headless::irradiance_image`] builds one.
#[derive(Component, Clone, Debug, ExtractComponent, Reflect)]
#[reflect(Component)]
pub struct InjectedIrradiance(pub Handle<Image>);

/// Main world: which techniques have something to draw this frame (set by the
/// techniques' own systems). A view has caustics work when any has, or when the
/// application injects irradiance into it.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ActiveCausticTechniques {
    pub warped_volumes: bool,
    pub convolution: bool,
    pub hierarchical_maps: bool,
}

impl ActiveCausticTechniques {
    pub fn any(&self) -> bool {
        self.warped_volumes || self.convolution || self.hierarchical_maps
    }

    /// Whether a technique reads receiver normals (the normal prepass).
    pub fn needs_normals(&self) -> bool {
        self.warped_volumes || self.hierarchical_maps
    }
}

/// A camera and whether it has the depth and normal prepasses.
type CameraPrepasses = (Entity, Has<DepthPrepass>, Has<NormalPrepass>);
/// HDR 3D cameras, the ones caustics are drawn for.
type HdrCameras = (With<Camera3d>, With<Hdr>);

/// The techniques read receiver points from Bevy's prepasses: HDR 3D cameras get the
/// depth prepass while any technique has work, and the normal prepass while a technique
/// that reads receiver normals does (caustic volumes, caustic maps). In `Last`, after
/// every technique has said whether it has work this frame.
fn add_prepasses(mut commands: Commands, active: Res<ActiveCausticTechniques>, cameras: Query<CameraPrepasses, HdrCameras>) {
    for (camera, depth, normal) in &cameras {
        if active.any() && !depth {
            commands.entity(camera).insert(DepthPrepass);
        }
        if active.needs_normals() && !normal {
            commands.entity(camera).insert(NormalPrepass);
        }
    }
}

/// Render world: this view has caustics work this frame.
#[derive(Component)]
pub struct ViewCausticWork;

/// Render world: a view's caustic irradiance buffer and its bind group for the composite.
#[derive(Component)]
pub struct ViewCausticIrradiance {
    pub texture: CachedTexture,
    pub bind_group: BindGroup,
}

impl ViewCausticIrradiance {
    /// A render pass that adds to the buffer (with a pipeline from
    /// [`projection_pipeline`]), keeping what the techniques before it wrote.
    pub fn accumulate<'a>(&self, encoder: &'a mut CommandEncoder, label: &'static str) -> wgpu::RenderPass<'a> {
        encoder.begin_render_pass(&RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(RenderPassColorAttachment {
                view: &self.texture.default_view,
                depth_slice: None,
                resolve_target: None,
                ops: Operations { load: LoadOp::Load, store: StoreOp::Store },
            })],
            ..default()
        })
    }
}

/// A technique's fullscreen pass that adds the irradiance it computes at each pixel's
/// receiver point to the view's buffer: `layouts[multisampled]` for the view's
/// prepass, the fragment entry point `project` of `shader` (with `MULTISAMPLED`
/// defined for a multisampled prepass), additive blending.
pub fn projection_pipeline(
    label: &'static str,
    layouts: &[BindGroupLayoutDescriptor; 2],
    shader: &Handle<Shader>,
    fullscreen: &FullscreenShader,
    multisampled: bool,
) -> RenderPipelineDescriptor {
    let shader_defs = if multisampled { vec!["MULTISAMPLED".into()] } else { vec![] };
    let additive = BlendComponent { src_factor: BlendFactor::One, dst_factor: BlendFactor::One, operation: BlendOperation::Add };
    RenderPipelineDescriptor {
        label: Some(label.into()),
        layout: vec![layouts[multisampled as usize].clone()],
        vertex: fullscreen.to_vertex_state(),
        fragment: Some(FragmentState {
            shader: shader.clone(),
            shader_defs,
            entry_point: Some("project".into()),
            targets: vec![Some(ColorTargetState {
                format: CAUSTIC_IRRADIANCE_FORMAT,
                blend: Some(BlendState { color: additive, alpha: additive }),
                write_mask: ColorWrites::ALL,
            })],
        }),
        ..default()
    }
}

/// Render world: a receiver's albedo as its `StandardMaterial` defines it.
#[derive(Clone, Copy, Debug)]
struct ReceiverAlbedo {
    base_color: LinearRgba,
    texture: Option<AssetId<Image>>,
    uv_transform: Mat3,
}

/// Render world: the receivers of this frame, by main-world entity.
#[derive(Resource, Default)]
struct ExtractedReceivers(HashMap<MainEntity, ReceiverAlbedo>);

pub(crate) fn build(app: &mut App) {
    bevy::asset::embedded_asset!(app, "composite.wgsl");
    bevy::asset::embedded_asset!(app, "inject.wgsl");
    bevy::shader::load_shader_library!(app, "receiver.wgsl");
    app.register_type::<InjectedIrradiance>()
        .init_resource::<ActiveCausticTechniques>()
        .add_systems(Last, add_prepasses)
        .add_systems(PostUpdate, warn_receivers_without_standard_material)
        .add_plugins(ExtractComponentPlugin::<InjectedIrradiance>::default());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedReceivers>()
        .add_systems(
            RenderStartup,
            (composite::init_pipeline.after(bevy::pbr::MeshPipelineSystems), init_inject_pipeline),
        )
        .add_systems(ExtractSchedule, (extract_receivers, mark_views_with_work))
        .add_systems(
            Render,
            (
                composite::queue.in_set(RenderSystems::Queue),
                prepare_irradiance_buffers.in_set(RenderSystems::PrepareResources),
                composite::prepare_receiver_bind_groups.in_set(RenderSystems::PrepareBindGroups),
            ),
        )
        .add_systems(Core3d, inject_irradiance.after(Core3dSystems::Prepass).before(Core3dSystems::MainPass));
    composite::build(render_app);
}

/// A receiver mesh whose albedo the composite cannot read.
type UnreadReceiver = (With<CausticReceiver>, With<Mesh3d>, Without<MeshMaterial3d<StandardMaterial>>);

/// Warns once per receiver whose mesh has no `StandardMaterial` (an `ExtendedMaterial`
/// or a material of the game's own): the composite cannot read its albedo and shows
/// its caustics on white.
pub fn warn_receivers_without_standard_material(
    receivers: Query<Entity, UnreadReceiver>,
    mut warned: Local<HashSet<Entity>>,
) {
    for entity in &receivers {
        if warned.insert(entity) {
            warn!("bevy_caustics: CausticReceiver {entity} has no StandardMaterial: its caustics are shown with albedo 1 (other materials, ExtendedMaterial included, are not read)");
        }
    }
}

/// Valid receivers, with their material if they have one.
type ReceiverQuery = Query<
    'static,
    'static,
    (Entity, Option<&'static MeshMaterial3d<StandardMaterial>>),
    (With<CausticReceiver>, Without<InvalidCausticParams>),
>;

fn extract_receivers(
    mut extracted: ResMut<ExtractedReceivers>,
    receivers: Extract<ReceiverQuery>,
    materials: Extract<Res<Assets<StandardMaterial>>>,
) {
    extracted.0.clear();
    for (entity, material) in &receivers {
        let material = material.and_then(|m| materials.get(&m.0));
        let albedo = match material {
            Some(m) => ReceiverAlbedo {
                base_color: m.base_color.to_linear(),
                texture: m.base_color_texture.as_ref().map(Handle::id),
                uv_transform: Mat3::from(m.uv_transform),
            },
            None => ReceiverAlbedo { base_color: LinearRgba::WHITE, texture: None, uv_transform: Mat3::IDENTITY },
        };
        extracted.0.insert(MainEntity::from(entity), albedo);
    }
}

/// 3D cameras, whether they have injected irradiance and whether they render HDR.
type CameraQuery =
    Query<'static, 'static, (Entity, RenderEntity, Has<InjectedIrradiance>, Has<Hdr>), With<Camera3d>>;

/// A view has caustics work when the application injects irradiance into it, or when
/// a technique has something to draw. Caustics are added to the linear HDR image
/// before tonemapping, so the camera needs [`Hdr`] (as bloom does); a camera without
/// it is reported once and skipped.
fn mark_views_with_work(
    mut commands: Commands,
    views: Extract<CameraQuery>,
    active: Extract<Res<ActiveCausticTechniques>>,
    mut warned: Local<HashSet<Entity>>,
) {
    for (main_entity, render_entity, injected, hdr) in &views {
        let mut entity = commands.entity(render_entity);
        let has_work = injected || active.any();
        if has_work && hdr {
            entity.insert(ViewCausticWork);
        } else {
            entity.remove::<(ViewCausticWork, ViewCausticIrradiance)>();
        }
        if has_work && !hdr && warned.insert(main_entity) {
            warn!("bevy_caustics: camera {main_entity} has caustics but no `Hdr` component; add `Hdr` to see them");
        }
    }
}

fn prepare_irradiance_buffers(
    mut commands: Commands,
    views: Query<(Entity, &ExtractedCamera), With<ViewCausticWork>>,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    pipeline: Res<CausticCompositePipeline>,
    pipeline_cache: Res<PipelineCache>,
) {
    for (entity, camera) in &views {
        let Some(size) = camera.physical_viewport_size.filter(|s| s.x > 0 && s.y > 0) else {
            continue;
        };
        let texture = texture_cache.get(
            &device,
            TextureDescriptor {
                label: Some("caustic_irradiance"),
                size: Extent3d { width: size.x, height: size.y, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: TextureDimension::D2,
                format: CAUSTIC_IRRADIANCE_FORMAT,
                // COPY_SRC: tools read it back (`HeadlessRenderer::caustic_irradiance`).
                usage: TextureUsages::TEXTURE_BINDING | TextureUsages::RENDER_ATTACHMENT | TextureUsages::COPY_SRC,
                view_formats: &[],
            },
        );
        let bind_group = device.create_bind_group(
            "caustic_irradiance_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.view_layout),
            &BindGroupEntries::single(&texture.default_view),
        );
        commands.entity(entity).insert(ViewCausticIrradiance { texture, bind_group });
    }
}

/// The pipeline that starts a view's buffer from [`InjectedIrradiance`].
#[derive(Resource)]
pub(crate) struct InjectPipeline {
    layout: BindGroupLayoutDescriptor,
    pipeline: CachedRenderPipelineId,
}

fn init_inject_pipeline(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    fullscreen: Res<FullscreenShader>,
    pipeline_cache: Res<PipelineCache>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "caustic_inject_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (texture_2d(TextureSampleType::Float { filterable: false }), uniform_buffer::<ViewUniform>(true)),
        ),
    );
    let pipeline = pipeline_cache.queue_render_pipeline(RenderPipelineDescriptor {
        label: Some("caustic_inject_pipeline".into()),
        layout: vec![layout.clone()],
        vertex: fullscreen.to_vertex_state(),
        fragment: Some(FragmentState {
            shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "inject.wgsl"),
            targets: vec![Some(ColorTargetState {
                format: CAUSTIC_IRRADIANCE_FORMAT,
                blend: None,
                write_mask: ColorWrites::ALL,
            })],
            ..default()
        }),
        ..default()
    });
    commands.insert_resource(InjectPipeline { layout, pipeline });
}

/// Starts the view's buffer for this frame: the injected irradiance times exposure, or zero.
pub(crate) fn inject_irradiance(
    view: ViewQuery<(&ViewCausticIrradiance, &ViewUniformOffset, Option<&InjectedIrradiance>)>,
    images: Res<RenderAssets<GpuImage>>,
    inject: Res<InjectPipeline>,
    pipeline_cache: Res<PipelineCache>,
    view_uniforms: Res<ViewUniforms>,
    recorder: Res<PassRecorder>,
    mut ctx: RenderContext,
) {
    let (buffer, view_offset, injected) = view.into_inner();
    let source = injected.and_then(|i| images.get(&i.0));
    let pipeline = pipeline_cache.get_render_pipeline(inject.pipeline);
    let bind_group = match (source, view_uniforms.uniforms.binding()) {
        (Some(image), Some(view_binding)) => Some(ctx.render_device().create_bind_group(
            "caustic_inject_bind_group",
            &pipeline_cache.get_bind_group_layout(&inject.layout),
            &BindGroupEntries::sequential((&image.texture_view, view_binding)),
        )),
        _ => None,
    };
    let mut pass = ctx.command_encoder().begin_render_pass(&RenderPassDescriptor {
        label: Some("caustic_irradiance_inject"),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: &buffer.texture.default_view,
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Clear(Default::default()), store: StoreOp::Store },
        })],
        ..default()
    });
    if let (Some(pipeline), Some(bind_group)) = (pipeline, bind_group) {
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bind_group, &[view_offset.offset]);
        pass.draw(0..3, 0..1);
        recorder.record("inject");
    }
}
