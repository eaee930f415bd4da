//! The per-view caustic irradiance buffer and the one composite step that shows it.
//!
//! Every technique accumulates caustic irradiance `E` (the light's units per m², lux
//! for Bevy's lights) into an HDR buffer the size of the view, at the surface each
//! pixel sees. The composite then draws the [`CausticReceiver`] meshes once more, after
//! the opaque pass and depth-tested against it, adding the Lambertian radiance
//! `albedo/π · E` scaled by the view's exposure — exactly what `bevy_pbr` adds for the
//! same irradiance from a light — so caustics land on receivers only, with their
//! unmodified `StandardMaterial` colour and texture, and only where they are visible.
//!
//! An application can supply the buffer itself with [`InjectedIrradiance`] (the CLI
//! and the demo inject the CPU reference tracer's irradiance this way).

mod composite;

use crate::components::{CausticReceiver, InvalidCausticParams};
use crate::report::PassRecorder;
use bevy::core_pipeline::{Core3dSystems, schedule::Core3d};
use bevy::pbr::{MeshMaterial3d, StandardMaterial};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    camera::ExtractedCamera,
    extract_component::{ExtractComponent, ExtractComponentPlugin},
    render_asset::RenderAssets,
    render_resource::*,
    renderer::{RenderContext, RenderDevice, ViewQuery},
    sync_world::MainEntity,
    texture::{CachedTexture, GpuImage, TextureCache},
};

pub use composite::CausticCompositePipeline;

/// Format of the caustic irradiance buffer: HDR float, blendable so that passes can
/// accumulate with additive blending.
pub const CAUSTIC_IRRADIANCE_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// Caustic irradiance supplied by the application for a camera's view: an image of
/// the view's size in [`CAUSTIC_IRRADIANCE_FORMAT`], linear, in the light's units per
/// m² (lux for Bevy lights), one value per pixel for the surface that pixel sees. It is
/// copied into the view's buffer each frame before the techniques add theirs.
#[derive(Component, Clone, Debug, ExtractComponent, Reflect)]
#[reflect(Component)]
pub struct InjectedIrradiance(pub Handle<Image>);

/// Render world: this view has caustics work this frame.
#[derive(Component)]
pub struct ViewCausticWork;

/// Render world: a view's caustic irradiance buffer and its bind group for the composite.
#[derive(Component)]
pub struct ViewCausticIrradiance {
    pub texture: CachedTexture,
    pub bind_group: BindGroup,
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
    app.register_type::<InjectedIrradiance>()
        .add_plugins(ExtractComponentPlugin::<InjectedIrradiance>::default());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedReceivers>()
        .add_systems(RenderStartup, composite::init_pipeline.after(bevy::pbr::MeshPipelineSystems))
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

fn extract_receivers(
    mut extracted: ResMut<ExtractedReceivers>,
    receivers: Extract<Query<(Entity, Option<&MeshMaterial3d<StandardMaterial>>), (With<CausticReceiver>, Without<InvalidCausticParams>)>>,
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

/// A view has caustics work when the application injects irradiance into it (and,
/// with techniques, when a valid generator lights one of its receivers).
fn mark_views_with_work(
    mut commands: Commands,
    views: Extract<Query<(bevy::render::sync_world::RenderEntity, Has<InjectedIrradiance>), With<Camera3d>>>,
) {
    for (render_entity, injected) in &views {
        let mut entity = commands.entity(render_entity);
        if injected {
            entity.insert(ViewCausticWork);
        } else {
            entity.remove::<(ViewCausticWork, ViewCausticIrradiance)>();
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
                usage: TextureUsages::TEXTURE_BINDING | TextureUsages::RENDER_ATTACHMENT | TextureUsages::COPY_DST,
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

/// Starts the view's buffer for this frame: the injected irradiance, or zero.
fn inject_irradiance(
    view: ViewQuery<(&ViewCausticIrradiance, Option<&InjectedIrradiance>)>,
    images: Res<RenderAssets<GpuImage>>,
    recorder: Res<PassRecorder>,
    mut warned: Local<bool>,
    mut ctx: RenderContext,
) {
    let (buffer, injected) = view.into_inner();
    let target = &buffer.texture.texture;
    let source = injected.and_then(|i| images.get(&i.0));
    match source {
        Some(src) if src.texture_descriptor.format == CAUSTIC_IRRADIANCE_FORMAT => {
            let size = Extent3d {
                width: src.texture_descriptor.size.width.min(target.width()),
                height: src.texture_descriptor.size.height.min(target.height()),
                depth_or_array_layers: 1,
            };
            if size.width != target.width() || size.height != target.height() {
                clear(&mut ctx, &buffer.texture.default_view);
            }
            ctx.command_encoder().copy_texture_to_texture(src.texture.as_image_copy(), target.as_image_copy(), size);
            recorder.record("inject");
        }
        Some(src) => {
            if !*warned {
                warn!(
                    "bevy_caustics: InjectedIrradiance image is {:?}; it must be {CAUSTIC_IRRADIANCE_FORMAT:?}",
                    src.texture_descriptor.format
                );
                *warned = true;
            }
            clear(&mut ctx, &buffer.texture.default_view);
        }
        None => clear(&mut ctx, &buffer.texture.default_view),
    }
}

fn clear(ctx: &mut RenderContext, view: &TextureView) {
    ctx.command_encoder().begin_render_pass(&RenderPassDescriptor {
        label: Some("caustic_irradiance_clear"),
        color_attachments: &[Some(RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Clear(Default::default()), store: StoreOp::Store },
        })],
        ..default()
    });
}
