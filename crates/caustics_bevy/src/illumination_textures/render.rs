//! Render world: extraction of the frames, and the GPU buffers, textures, pipelines and
//! bind groups the passes (`pass.rs`) draw with.

use crate::cpu_time::timed;
use super::{IlluminationFrames, IlluminationTexturesSettings, MAX_PLANES, pass};
use bevy::core_pipeline::schedule::{Core3d, camera_driver};
use bevy::core_pipeline::{Core3dSystems, FullscreenShader};
use bevy::prelude::*;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    render_resource::{
        binding_types::{
            storage_buffer_read_only, texture_2d_array, texture_2d_multisampled, texture_depth_2d, texture_depth_2d_multisampled,
            uniform_buffer,
        },
        *,
    },
    renderer::{RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue},
    view::ViewUniform,
};
use caustics_core::illumination_textures::{
    Cosine, IlluminationTextures, IlluminationVolume, MAX_MAGNIFICATION, SHADOW_SLACK_TEXELS, SeenSurface,
};
use std::sync::Arc;

/// The format of the illumination textures: 32-bit floats where the GPU blends them
/// (`FLOAT32_BLENDABLE`), else half floats, which hold them (the textures stay within
/// `[0, MAX_MAGNIFICATION]` in units of the frame's light colour) but lose about 2 % at
/// a focus where hundreds of volumes add up, each rounded on lavapipe.
fn texture_format(device: &RenderDevice) -> TextureFormat {
    if device.features().contains(WgpuFeatures::FLOAT32_BLENDABLE) { TextureFormat::Rgba32Float } else { TextureFormat::Rgba16Float }
}

/// "No receiver here, nothing solid": the shaders' infinity.
const FAR: f32 = 1.0e30;

/// `IlluminationFrame` in `types.wgsl`.
#[derive(Clone, Copy, Default, ShaderType)]
pub(super) struct GpuIlluminationFrame {
    axis: Vec4,
    u: Vec4,
    v: Vec4,
    /// The texture rectangle: corner (xy) and extent (zw), in (u, v) metres.
    rectangle: Vec4,
    light_color: Vec4,
    depths: [Vec4; 4],
    size: u32,
    planes: u32,
    cosine: u32,
    shadow_slack: f32,
    max_magnification: f32,
}

/// `IlluminationVolume` in `types.wgsl`: the three exits and directions, then
/// (flux, cross-section).
#[derive(Clone, Copy, Default, ShaderType)]
struct GpuVolume {
    exits: [Vec4; 3],
    directions: [Vec4; 3],
    flux: Vec4,
}

fn to_vec4(v: caustics_core::glam::Vec3) -> Vec4 {
    Vec4::new(v.x, v.y, v.z, 0.0)
}

impl From<&IlluminationVolume> for GpuVolume {
    fn from(v: &IlluminationVolume) -> Self {
        Self { exits: v.exits.map(to_vec4), directions: v.directions.map(to_vec4), flux: Vec4::new(v.flux, v.cross_section, 0.0, 0.0) }
    }
}

/// A texel of the virtual camera's depth map as `types.wgsl` reads it: three `vec4`s,
/// (normal, depth) then the solid spans' (in, out) pairs, [`FAR`] for none.
fn surface_texel(seen: &Option<SeenSurface>) -> [Vec4; 3] {
    match seen {
        None => [Vec4::new(0.0, 0.0, 0.0, FAR), Vec4::splat(FAR), Vec4::splat(FAR)],
        Some(s) => {
            // `SOLID_SPANS` is the four spans `types.wgsl` reads, two to a `vec4`.
            let [(a0, b0), (a1, b1), (a2, b2), (a3, b3)] = s.solid.map(|(a, b)| (a.min(FAR), b.min(FAR)));
            [to_vec4(s.normal).with_w(s.depth), Vec4::new(a0, b0, a1, b1), Vec4::new(a2, b2, a3, b3)]
        }
    }
}

impl GpuIlluminationFrame {
    fn new(t: &IlluminationTextures, cosine: Cosine) -> Self {
        let mut depths = [0.0; MAX_PLANES as usize];
        for (d, plane) in depths.iter_mut().zip(&t.planes) {
            *d = plane.depth;
        }
        Self {
            axis: to_vec4(t.axis),
            u: to_vec4(t.u),
            v: to_vec4(t.v),
            rectangle: Vec4::new(t.corner.x, t.corner.y, t.extent.x, t.extent.y),
            light_color: to_vec4(t.light_color),
            depths: std::array::from_fn(|i| Vec4::from_slice(&depths[4 * i..4 * i + 4])),
            size: t.size,
            planes: t.planes.len().min(MAX_PLANES as usize) as u32,
            cosine: (cosine == Cosine::VirtualCamera) as u32,
            shadow_slack: SHADOW_SLACK_TEXELS,
            max_magnification: MAX_MAGNIFICATION,
        }
    }
}

/// Render world: the frames of the main world, by generation, and the cosine.
#[derive(Resource, Default)]
struct ExtractedFrames {
    generation: u64,
    frames: Arc<Vec<IlluminationTextures>>,
    cosine: Cosine,
}

/// One light's frame on the GPU: its uniform, volumes, depth map, texture array (a
/// view per plane to draw into, one of the array to read) and the draw bind group.
pub(super) struct FrameGpu {
    pub(super) uniform: UniformBuffer<GpuIlluminationFrame>,
    volumes: StorageBuffer<Vec<GpuVolume>>,
    pub(super) volume_count: u32,
    pub(super) textures: Texture,
    pub(super) layers: Vec<TextureView>,
    pub(super) array: TextureView,
    pub(super) surface: StorageBuffer<Vec<Vec4>>,
    pub(super) draw_bind_group: BindGroup,
}

/// Render world: the illumination textures on the GPU.
#[derive(Resource, Default)]
pub struct IlluminationTexturesGpu {
    generation: Option<u64>,
    /// The textures must be drawn this frame.
    pub(super) dirty: bool,
    pub(super) frames: Vec<FrameGpu>,
}

impl IlluminationTexturesGpu {
    /// The textures' format on this GPU.
    pub fn format(&self) -> Option<TextureFormat> {
        self.frames.first().map(|f| f.textures.format())
    }

    /// How many light frames have textures.
    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// Frame `index`'s texture array (`Rgba16Float`, a layer per plane, [`IlluminationTextures`]'s
    /// texel layout), copyable.
    pub fn textures(&self, index: usize) -> Option<&Texture> {
        self.frames.get(index).map(|f| &f.textures)
    }

    /// Bytes of GPU memory the illumination textures hold.
    pub fn bytes(&self) -> u64 {
        self.frames
            .iter()
            .map(|f| {
                let texels = f.textures.width() as u64 * f.textures.height() as u64 * f.layers.len() as u64;
                let texel_bytes = f.textures.format().block_copy_size(None).unwrap_or(16) as u64;
                [f.surface.buffer(), f.volumes.buffer()].iter().flatten().map(|b| b.size()).sum::<u64>() + texels * texel_bytes
            })
            .sum()
    }
}

/// The draw pipeline and the projection's layouts and shader.
#[derive(Resource)]
pub(super) struct IlluminationPipelines {
    pub(super) draw_layout: BindGroupLayoutDescriptor,
    pub(super) draw: CachedRenderPipelineId,
    format: TextureFormat,
    pub(super) project_layouts: [BindGroupLayoutDescriptor; 2],
    project_shader: Handle<Shader>,
    fullscreen: FullscreenShader,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticsCpuTime::of(app).render;
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedFrames>()
        .init_resource::<IlluminationTexturesGpu>()
        .init_resource::<SpecializedRenderPipelines<IlluminationPipelines>>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, timed(&cpu, extract_frames))
        .add_systems(
            Render,
            (
                timed(&cpu, prepare_frames).in_set(RenderSystems::PrepareResources),
                timed(&cpu, crate::irradiance::prepare_projection_pipelines::<IlluminationPipelines>)
                    .run_if(|gpu: Res<IlluminationTexturesGpu>| !gpu.frames.is_empty())
                    .in_set(RenderSystems::Prepare),
            ),
        )
        .add_systems(RenderGraph, timed(&cpu, pass::draw_illumination_textures).in_set(RenderGraphSystems::Render).before(camera_driver))
        .add_systems(
            Core3d,
            timed(&cpu, pass::project_illumination_textures)
                .after(crate::irradiance::inject_irradiance)
                .after(Core3dSystems::Prepass)
                .before(Core3dSystems::MainPass),
        );
}

fn extract_frames(mut extracted: ResMut<ExtractedFrames>, frames: Extract<Res<IlluminationFrames>>, settings: Extract<Res<IlluminationTexturesSettings>>) {
    if extracted.generation != frames.generation {
        extracted.generation = frames.generation;
        extracted.frames = frames.frames.clone();
    }
    extracted.cosine = settings.cosine.core();
}

fn init_pipelines(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    cache: Res<PipelineCache>,
    fullscreen: Res<FullscreenShader>,
    device: Res<RenderDevice>,
) {
    let format = texture_format(&device);
    let float = TextureSampleType::Float { filterable: false };
    let draw_layout = BindGroupLayoutDescriptor::new(
        "illumination_draw_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::VERTEX_FRAGMENT,
            (
                uniform_buffer::<GpuIlluminationFrame>(false),
                storage_buffer_read_only::<GpuVolume>(false),
                storage_buffer_read_only::<Vec4>(false),
            ),
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "draw.wgsl");
    let additive = BlendComponent { src_factor: BlendFactor::One, dst_factor: BlendFactor::One, operation: BlendOperation::Add };
    let draw = cache.queue_render_pipeline(RenderPipelineDescriptor {
        label: Some("illumination_draw_pipeline".into()),
        layout: vec![draw_layout.clone()],
        vertex: VertexState { shader: shader.clone(), entry_point: Some("draw_vertex".into()), ..default() },
        fragment: Some(FragmentState {
            shader,
            entry_point: Some("draw_fragment".into()),
            targets: vec![Some(ColorTargetState {
                format,
                blend: Some(BlendState { color: additive, alpha: additive }),
                write_mask: ColorWrites::ALL,
            })],
            ..default()
        }),
        ..default()
    });
    let project_layout = |multisampled: bool| {
        BindGroupLayoutDescriptor::new(
            if multisampled { "illumination_project_layout_msaa" } else { "illumination_project_layout" },
            &BindGroupLayoutEntries::sequential(
                ShaderStages::FRAGMENT,
                (
                    uniform_buffer::<ViewUniform>(true),
                    if multisampled { texture_depth_2d_multisampled() } else { texture_depth_2d() },
                    if multisampled { texture_2d_multisampled(float) } else { bevy::render::render_resource::binding_types::texture_2d(float) },
                    uniform_buffer::<GpuIlluminationFrame>(false),
                    texture_2d_array(float),
                    storage_buffer_read_only::<Vec4>(false),
                ),
            ),
        )
    };
    commands.insert_resource(IlluminationPipelines {
        draw_layout,
        draw,
        format,
        project_layouts: [project_layout(false), project_layout(true)],
        project_shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "project.wgsl"),
        fullscreen: fullscreen.clone(),
    });
}

impl SpecializedRenderPipeline for IlluminationPipelines {
    /// Whether the prepass is multisampled.
    type Key = bool;

    fn specialize(&self, multisampled: bool) -> RenderPipelineDescriptor {
        crate::irradiance::projection_pipeline("illumination_project_pipeline", &self.project_layouts, &self.project_shader, &self.fullscreen, multisampled)
    }
}

/// Uploads each frame of a new generation: its uniform, volumes and depth map, and a
/// texture array for its planes (kept while its size and plane count stay).
fn prepare_frames(
    extracted: Res<ExtractedFrames>,
    mut gpu: ResMut<IlluminationTexturesGpu>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    pipelines: Res<IlluminationPipelines>,
    cache: Res<PipelineCache>,
) {
    if gpu.generation == Some(extracted.generation) {
        return;
    }
    gpu.generation = Some(extracted.generation);
    gpu.dirty = true;
    let layout = cache.get_bind_group_layout(&pipelines.draw_layout);
    let old = std::mem::take(&mut gpu.frames);
    for (k, t) in extracted.frames.iter().enumerate() {
        let mut uniform = UniformBuffer::from(GpuIlluminationFrame::new(t, extracted.cosine));
        uniform.set_label(Some("caustic_illumination_frame"));
        uniform.write_buffer(&device, &queue);
        let mut volumes: Vec<GpuVolume> = t.volumes.iter().map(GpuVolume::from).collect();
        let volume_count = volumes.len() as u32;
        // A binding may not be empty.
        if volumes.is_empty() {
            volumes.push(GpuVolume::default());
        }
        let mut volume_buffer = StorageBuffer::from(volumes);
        volume_buffer.set_label(Some("caustic_illumination_volumes"));
        volume_buffer.write_buffer(&device, &queue);
        let mut surface = StorageBuffer::from(t.surface.iter().flat_map(surface_texel).collect::<Vec<Vec4>>());
        surface.set_label(Some("caustic_illumination_depth_map"));
        surface.write_buffer(&device, &queue);
        let layers = t.planes.len() as u32;
        let reuse = old.get(k).filter(|f| f.textures.width() == t.size && f.layers.len() as u32 == layers).map(|f| f.textures.clone());
        let textures = reuse.unwrap_or_else(|| {
            device.create_texture(&TextureDescriptor {
                label: Some("caustic_illumination_textures"),
                size: Extent3d { width: t.size, height: t.size, depth_or_array_layers: layers },
                mip_level_count: 1,
                sample_count: 1,
                dimension: TextureDimension::D2,
                format: pipelines.format,
                usage: TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        });
        let view = |dimension, base_array_layer, array_layer_count| {
            textures.create_view(&TextureViewDescriptor { dimension: Some(dimension), base_array_layer, array_layer_count, ..default() })
        };
        let layer_views = (0..layers).map(|l| view(TextureViewDimension::D2, l, Some(1))).collect();
        let array = view(TextureViewDimension::D2Array, 0, Some(layers));
        let (Some(frame_binding), Some(volume_binding), Some(surface_binding)) = (uniform.binding(), volume_buffer.binding(), surface.binding())
        else {
            continue;
        };
        let draw_bind_group =
            device.create_bind_group("illumination_draw_bind_group", &layout, &BindGroupEntries::sequential((frame_binding, volume_binding, surface_binding)));
        gpu.frames.push(FrameGpu { uniform, volumes: volume_buffer, volume_count, textures, layers: layer_views, array, surface, draw_bind_group });
    }
}
