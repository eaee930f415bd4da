//! What the two fullscreen passes that multiply a view's image by the media's
//! transmittance share (`media.wgsl`): their pipeline, the media's uniform and the
//! pass itself. [`super::behind_transmission`] dims behind Bevy's transmissive
//! surfaces, [`super::tint`] by the colour of the media's absorption.

use crate::irradiance::kept_bind_group::{KeptLayout, write_changed};
use crate::irradiance::{ExtractedMedia, GpuMedium, MAX_MEDIA};
use bevy::camera::Viewport;
use bevy::core_pipeline::FullscreenShader;
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_resource::{binding_types::*, *};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue};
use bevy::render::view::{ViewTarget, ViewUniform};
use bevy::render::{Render, RenderApp, RenderStartup, RenderSystems};

pub(super) fn build(app: &mut App) {
    bevy::asset::embedded_asset!(app, "media.wgsl");
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<SpecializedRenderPipelines<DimPipeline>>()
        .init_resource::<MediaUniform>()
        .add_systems(RenderStartup, init_pipeline)
        .add_systems(Render, prepare_media.in_set(RenderSystems::PrepareResources));
}

/// Which transmittance a pass multiplies in: a fragment shader of `media.wgsl`.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Dim {
    /// exp(−σₜ ℓ) from the nearest transmissive surface to the opaque point behind it.
    BehindTransmission,
    /// exp(−(σₜ − σₜ,min) ℓ) from the eye to the view's depth.
    Tint,
}

impl Dim {
    fn entry_point(self) -> &'static str {
        match self {
            Dim::BehindTransmission => "dim_behind_transmission",
            Dim::Tint => "tint",
        }
    }
}

/// The multiplying pipelines: destination × source, so that each pixel of the image
/// is multiplied by the transmittance the fragment shader returns.
#[derive(Resource)]
pub struct DimPipeline {
    /// By [`Dim`], then for a single-sampled and a multisampled view depth.
    layouts: [[KeptLayout; 2]; 2],
    shader: Handle<Shader>,
    fullscreen: FullscreenShader,
}

/// What a multiplying pipeline is specialised on: its pass, the view depth's sampling
/// and the view's image format.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct DimKey {
    pub dim: Dim,
    pub multisampled: bool,
    pub format: TextureFormat,
}

impl DimPipeline {
    /// The shader that also draws the transmissive surfaces' depth.
    pub fn shader(&self) -> Handle<Shader> {
        self.shader.clone()
    }

    /// The bind group layout of `dim`'s pass: the view, its depth, the media, and for
    /// [`Dim::BehindTransmission`] the surfaces' depth.
    pub fn layout(&self, dim: Dim, multisampled: bool, cache: &PipelineCache) -> &BindGroupLayout {
        self.layouts[dim as usize][multisampled as usize].get(cache)
    }
}

impl SpecializedRenderPipeline for DimPipeline {
    type Key = DimKey;

    fn specialize(&self, key: Self::Key) -> RenderPipelineDescriptor {
        let shader_defs = if key.multisampled { vec!["MULTISAMPLED".into()] } else { vec![] };
        let multiply = BlendComponent { src_factor: BlendFactor::Zero, dst_factor: BlendFactor::Src, operation: BlendOperation::Add };
        RenderPipelineDescriptor {
            label: Some(format!("medium_{}_pipeline", key.dim.entry_point()).into()),
            layout: vec![self.layouts[key.dim as usize][key.multisampled as usize].descriptor.clone()],
            vertex: self.fullscreen.to_vertex_state(),
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                shader_defs,
                entry_point: Some(key.dim.entry_point().into()),
                targets: vec![Some(ColorTargetState {
                    format: key.format,
                    blend: Some(BlendState { color: multiply, alpha: BlendComponent::REPLACE }),
                    write_mask: ColorWrites::COLOR,
                })],
            }),
            ..default()
        }
    }
}

pub(super) fn init_pipeline(mut commands: Commands, fullscreen: Res<FullscreenShader>, asset_server: Res<AssetServer>) {
    let layouts = [Dim::BehindTransmission, Dim::Tint].map(|dim| {
        [false, true].map(|multisampled| {
            let depth = if multisampled { texture_depth_2d_multisampled() } else { texture_depth_2d() };
            let entries = (uniform_buffer::<ViewUniform>(true), depth, uniform_buffer::<GpuMedia>(false));
            let label = match (dim, multisampled) {
                (Dim::BehindTransmission, false) => "medium_behind_transmission_layout",
                (Dim::BehindTransmission, true) => "medium_behind_transmission_layout_multisampled",
                (Dim::Tint, false) => "medium_tint_layout",
                (Dim::Tint, true) => "medium_tint_layout_multisampled",
            };
            KeptLayout::new(match dim {
                Dim::BehindTransmission => BindGroupLayoutDescriptor::new(
                    label,
                    &BindGroupLayoutEntries::sequential(ShaderStages::FRAGMENT, (entries.0, entries.1, entries.2, texture_depth_2d())),
                ),
                Dim::Tint => BindGroupLayoutDescriptor::new(label, &BindGroupLayoutEntries::sequential(ShaderStages::FRAGMENT, entries)),
            })
        })
    });
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "media.wgsl");
    commands.insert_resource(DimPipeline { layouts, shader, fullscreen: fullscreen.clone() });
}

/// The media as `media.wgsl` reads them.
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
pub struct GpuMedia {
    count: u32,
    media: [GpuMedium; MAX_MEDIA],
}

/// Render world: the media's uniform, uploaded when they change and dropped while
/// there are none.
#[derive(Resource, Default)]
pub struct MediaUniform(pub UniformBuffer<GpuMedia>);

fn prepare_media(media: Res<ExtractedMedia>, mut uniform: ResMut<MediaUniform>, device: Res<RenderDevice>, queue: Res<RenderQueue>) {
    if media.0.is_empty() {
        if uniform.0.buffer().is_some() {
            uniform.0 = default();
        }
        return;
    }
    let (padded, count) = media.padded();
    uniform.0.set_label(Some("caustic_media"));
    write_changed(&mut uniform.0, GpuMedia { count, media: padded }, &device, &queue);
}

/// Multiplies the view's image by what `pipeline` returns, over the camera's viewport.
pub fn multiply(
    ctx: &mut RenderContext,
    target: &ViewTarget,
    viewport: Option<&Viewport>,
    span: &'static str,
    pipeline: &RenderPipeline,
    bind_group: &BindGroup,
    view_offset: u32,
) {
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
        label: Some(span),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: target.main_texture_view(),
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Load, store: StoreOp::Store },
        })],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    let span = diagnostics.pass_span(&mut pass, span);
    if let Some(viewport) = viewport {
        pass.set_camera_viewport(viewport);
    }
    pass.set_render_pipeline(pipeline);
    pass.set_bind_group(0, bind_group, &[view_offset]);
    pass.draw(0..3, 0..1);
    span.end(&mut pass);
}
