//! Render world: extraction of the frames, and the GPU buffers, textures, pipelines and
//! bind groups the passes (`pass.rs`) draw with.

use super::{IlluminationFrames, IlluminationTexturesSettings, MAX_PLANES, SURFACE_TEXEL_BYTES, pass};
use crate::cpu_time::timed;
use crate::irradiance::kept_bind_group::{KeptLayout, ViewBindGroups};
use crate::irradiance::mesh_bvhs::InstancedBvhBuffer;
use bevy::core_pipeline::schedule::{Core3d, camera_driver};
use bevy::core_pipeline::{Core3dSystems, FullscreenShader};
use bevy::prelude::*;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    render_resource::{
        binding_types::{
            storage_buffer_read_only, storage_buffer_read_only_sized, storage_buffer_sized, texture_2d_array, texture_2d_multisampled, texture_depth_2d,
            texture_depth_2d_multisampled, uniform_buffer,
        },
        *,
    },
    renderer::{RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue},
    view::ViewUniform,
};
use caustics_core::illumination_textures::{Cosine, IlluminationTextures, IlluminationVolume, MAX_MAGNIFICATION, SHADOW_SLACK_TEXELS};
use caustics_core::triangle_bvh::InstancedBvh;
use std::sync::Arc;

/// The format of the illumination textures: 32-bit floats where the GPU blends them
/// (`FLOAT32_BLENDABLE`), else half floats, which hold them (the textures stay within
/// `[0, MAX_MAGNIFICATION]` in units of the frame's light colour) but lose about 2 % at
/// a focus where hundreds of volumes add up, each rounded on lavapipe.
fn texture_format(device: &RenderDevice) -> TextureFormat {
    if device.features().contains(WgpuFeatures::FLOAT32_BLENDABLE) { TextureFormat::Rgba32Float } else { TextureFormat::Rgba16Float }
}

/// `IlluminationFrame` in `types.wgsl`.
#[derive(Clone, Copy, Default, ShaderType)]
pub(super) struct GpuIlluminationFrame {
    axis: Vec4,
    u: Vec4,
    v: Vec4,
    /// The texture rectangle: corner (xy) and extent (zw), in (u, v) metres.
    rectangle: Vec4,
    light_color: Vec4,
    size: u32,
    planes: u32,
    cosine: u32,
    shadow_slack: f32,
    max_magnification: f32,
    /// Where the virtual camera's rays start, in depth along the axis.
    start: f32,
    /// Where the receivers' instances start in their `InstancedBvh` buffer (vec4s).
    receivers: u32,
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

impl GpuIlluminationFrame {
    fn new(t: &IlluminationTextures, cosine: Cosine, receivers: &InstancedBvh) -> Self {
        Self {
            axis: to_vec4(t.axis),
            u: to_vec4(t.u),
            v: to_vec4(t.v),
            rectangle: Vec4::new(t.corner.x, t.corner.y, t.extent.x, t.extent.y),
            light_color: to_vec4(t.light_color),
            size: t.size,
            planes: t.planes.len().min(MAX_PLANES as usize) as u32,
            cosine: (cosine == Cosine::VirtualCamera) as u32,
            shadow_slack: SHADOW_SLACK_TEXELS,
            max_magnification: MAX_MAGNIFICATION,
            start: t.start,
            receivers: receivers.gpu_instance_offset(),
        }
    }
}

/// Render world: the frames of the main world, by generation, the receivers they see
/// and the cosine.
#[derive(Resource, Default)]
struct ExtractedFrames {
    generation: u64,
    frames: Arc<Vec<IlluminationTextures>>,
    receivers: Arc<InstancedBvh>,
    cosine: Cosine,
}

/// One light's frame on the GPU: its uniform, volumes, the virtual camera's depth map
/// and the depths it saw, texture array (a view per plane to draw into, one of the
/// array to read) and the bind groups that see and draw.
pub(super) struct FrameGpu {
    pub(super) uniform: UniformBuffer<GpuIlluminationFrame>,
    volumes: StorageBuffer<Vec<GpuVolume>>,
    pub(super) volume_count: u32,
    pub(super) textures: Texture,
    pub(super) layers: Vec<TextureView>,
    pub(super) array: TextureView,
    pub(super) surface: Buffer,
    pub(super) seen: Buffer,
    pub(super) see_bind_group: BindGroup,
    pub(super) draw_bind_group: BindGroup,
    /// The projection's bind group for each view.
    pub(super) projections: ViewBindGroups,
}

/// Render world: the illumination textures on the GPU.
#[derive(Resource, Default)]
pub struct IlluminationTexturesGpu {
    generation: Option<u64>,
    /// The textures must be drawn this frame.
    pub(super) dirty: bool,
    pub(super) frames: Vec<FrameGpu>,
    /// The receivers the virtual cameras see (`triangle_bvh`).
    receivers: InstancedBvhBuffer,
    /// The buffer the frames' bind groups hold of them.
    receivers_buffer: Option<BufferId>,
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

    /// Frame `index`'s virtual camera: its depth map (three `vec4`s a texel, row-major:
    /// (normal, depth), then the solid spans' (in, out) pairs, `1e30` for none) and the
    /// two words of the depths it saw (`seen.wgsl`), copyable.
    pub fn depth_map(&self, index: usize) -> Option<(&Buffer, &Buffer)> {
        self.frames.get(index).map(|f| (&f.surface, &f.seen))
    }

    /// Bytes of GPU memory the illumination textures hold.
    pub fn bytes(&self) -> u64 {
        self.frames
            .iter()
            .map(|f| {
                let texels = f.textures.width() as u64 * f.textures.height() as u64 * f.layers.len() as u64;
                let texel_bytes = f.textures.format().block_copy_size(None).unwrap_or(16) as u64;
                f.surface.size() + f.seen.size() + f.volumes.buffer().map_or(0, |b| b.size()) + texels * texel_bytes
            })
            .sum::<u64>()
            + self.receivers.size()
    }
}

/// The virtual camera's and the draw's pipelines and the projection's layouts and
/// shader.
#[derive(Resource)]
pub(super) struct IlluminationPipelines {
    see_layout: KeptLayout,
    pub(super) see: CachedComputePipelineId,
    /// The empty `anchor` of [`crate::gpu_work::anchor_first_timestamp`], under `see`'s layout.
    pub(super) see_anchor: CachedComputePipelineId,
    draw_layout: KeptLayout,
    pub(super) draw: CachedRenderPipelineId,
    format: TextureFormat,
    pub(super) project_layouts: [KeptLayout; 2],
    project_shader: Handle<Shader>,
    fullscreen: FullscreenShader,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).render;
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
                timed(&cpu, crate::irradiance::prepare_projection_pipelines::<IlluminationPipelines>).run_if(textures_in_view).in_set(RenderSystems::Prepare),
            ),
        )
        .add_systems(
            RenderGraph,
            timed(&cpu, pass::draw_illumination_textures).run_if(textures_in_view).in_set(RenderGraphSystems::Render).before(camera_driver),
        )
        .add_systems(
            Core3d,
            timed(&cpu, pass::project_illumination_textures)
                .run_if(textures_in_view)
                .after(crate::irradiance::inject_irradiance)
                .after(Core3dSystems::Prepass)
                .before(Core3dSystems::MainPass),
        );
}

/// Whether any frame of illumination planes is on the GPU: else the textures' passes
/// are left out of the frame.
fn textures_in_view(gpu: Res<IlluminationTexturesGpu>) -> bool {
    !gpu.frames.is_empty()
}

fn extract_frames(mut extracted: ResMut<ExtractedFrames>, frames: Extract<Res<IlluminationFrames>>, settings: Extract<Res<IlluminationTexturesSettings>>) {
    if extracted.generation != frames.generation {
        extracted.generation = frames.generation;
        extracted.frames = frames.frames.clone();
        extracted.receivers = frames.receivers.clone();
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
    let see_layout = BindGroupLayoutDescriptor::new(
        "illumination_see_layout",
        &BindGroupLayoutEntries::with_indices(
            ShaderStages::COMPUTE,
            (
                (0, uniform_buffer::<GpuIlluminationFrame>(false)),
                (1, storage_buffer_sized(false, None)),
                (2, storage_buffer_sized(false, None)),
                (14, storage_buffer_read_only_sized(false, None)),
            ),
        ),
    );
    let see_shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "seen.wgsl");
    let [see, see_anchor] = crate::irradiance::compute_pipelines(&cache, "illumination", &see_layout, &see_shader, ["see", "anchor"]);
    let draw_layout = BindGroupLayoutDescriptor::new(
        "illumination_draw_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::VERTEX_FRAGMENT,
            (
                uniform_buffer::<GpuIlluminationFrame>(false),
                storage_buffer_read_only::<GpuVolume>(false),
                storage_buffer_read_only::<Vec4>(false),
                storage_buffer_read_only_sized(false, None),
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
            targets: vec![Some(ColorTargetState { format, blend: Some(BlendState { color: additive, alpha: additive }), write_mask: ColorWrites::ALL })],
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
                    storage_buffer_read_only_sized(false, None),
                ),
            ),
        )
    };
    commands.insert_resource(IlluminationPipelines {
        see_layout: KeptLayout::new(see_layout),
        see,
        see_anchor,
        draw_layout: KeptLayout::new(draw_layout),
        draw,
        format,
        project_layouts: [project_layout(false), project_layout(true)].map(KeptLayout::new),
        project_shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "project.wgsl"),
        fullscreen: fullscreen.clone(),
    });
}

impl SpecializedRenderPipeline for IlluminationPipelines {
    /// Whether the prepass is multisampled.
    type Key = bool;

    fn specialize(&self, multisampled: bool) -> RenderPipelineDescriptor {
        crate::irradiance::projection_pipeline(
            "illumination_project_pipeline",
            &self.project_layouts[multisampled as usize].descriptor,
            &self.project_shader,
            &self.fullscreen,
            multisampled,
        )
    }
}

/// Uploads each frame of a new generation: its uniform and volumes, with room for the
/// virtual camera's depth map and a texture array for its planes, and the receivers'
/// BVH. While a frame's size and plane count stay, its buffers, textures, views and
/// bind groups are kept and written into.
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
    let gpu = gpu.as_mut();
    gpu.generation = Some(extracted.generation);
    gpu.dirty = true;
    if extracted.frames.is_empty() {
        // Nothing to draw: the GPU memory goes back.
        (gpu.frames, gpu.receivers, gpu.receivers_buffer) = (Vec::new(), InstancedBvhBuffer::default(), None);
        return;
    }
    let receivers = gpu.receivers.write(&extracted.receivers, "caustic_illumination_receivers", &device, &queue);
    let receivers_moved = gpu.receivers_buffer.replace(receivers.id()) != Some(receivers.id());
    let (draw_layout, see_layout) = (pipelines.draw_layout.get(&cache), pipelines.see_layout.get(&cache));
    // The virtual camera's (`see`) and the planes' (`draw`) bind groups of a frame.
    let bind_groups = |uniform: &UniformBuffer<GpuIlluminationFrame>, volumes: &StorageBuffer<Vec<GpuVolume>>, surface: &Buffer, seen: &Buffer| {
        let (frame, volumes) = (uniform.binding()?, volumes.binding()?);
        let see = device.create_bind_group(
            "illumination_see_bind_group",
            see_layout,
            &BindGroupEntries::with_indices((
                (0, frame.clone()),
                (1, surface.as_entire_binding()),
                (2, seen.as_entire_binding()),
                (14, receivers.as_entire_binding()),
            )),
        );
        let draw = device.create_bind_group(
            "illumination_draw_bind_group",
            draw_layout,
            &BindGroupEntries::sequential((frame, volumes, surface.as_entire_binding(), seen.as_entire_binding())),
        );
        Some((see, draw))
    };
    let mut old = std::mem::take(&mut gpu.frames).into_iter();
    for t in extracted.frames.iter() {
        let frame = GpuIlluminationFrame::new(t, extracted.cosine, &extracted.receivers);
        let mut volumes: Vec<GpuVolume> = t.volumes.iter().map(GpuVolume::from).collect();
        let volume_count = volumes.len() as u32;
        // A binding may not be empty.
        if volumes.is_empty() {
            volumes.push(GpuVolume::default());
        }
        let layers = t.planes.len() as u32;
        // A frame of the same size and planes keeps its buffers, textures, views and
        // bind groups (a turning glass ball: every frame); its new uniform and volumes
        // are written into them, and a bind group is made again only for a buffer that
        // had to grow.
        if let Some(mut kept) = old.next().filter(|f| f.textures.width() == t.size && f.layers.len() as u32 == layers) {
            let volumes_before = kept.volumes.buffer().map(|b| b.id());
            kept.uniform.set(frame);
            kept.uniform.write_buffer(&device, &queue);
            kept.volumes.set(volumes);
            kept.volumes.write_buffer(&device, &queue);
            kept.volume_count = volume_count;
            if receivers_moved || kept.volumes.buffer().map(|b| b.id()) != volumes_before {
                let Some((see, draw)) = bind_groups(&kept.uniform, &kept.volumes, &kept.surface, &kept.seen) else { continue };
                (kept.see_bind_group, kept.draw_bind_group) = (see, draw);
            }
            gpu.frames.push(kept);
            continue;
        }
        let mut uniform = UniformBuffer::from(frame);
        uniform.set_label(Some("caustic_illumination_frame"));
        uniform.write_buffer(&device, &queue);
        let mut volume_buffer = StorageBuffer::from(volumes);
        volume_buffer.set_label(Some("caustic_illumination_volumes"));
        volume_buffer.write_buffer(&device, &queue);
        let textures = device.create_texture(&TextureDescriptor {
            label: Some("caustic_illumination_textures"),
            size: Extent3d { width: t.size, height: t.size, depth_or_array_layers: layers },
            mip_level_count: 1,
            sample_count: 1,
            dimension: TextureDimension::D2,
            format: pipelines.format,
            usage: TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let buffer = |label, size| {
            device.create_buffer(&BufferDescriptor {
                label: Some(label),
                size,
                usage: BufferUsages::STORAGE | BufferUsages::COPY_DST | BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let (surface, seen) =
            (buffer("caustic_illumination_depth_map", u64::from(t.size).pow(2) * SURFACE_TEXEL_BYTES), buffer("caustic_illumination_seen_depths", 8));
        let view = |dimension, base_array_layer, array_layer_count| {
            textures.create_view(&TextureViewDescriptor { dimension: Some(dimension), base_array_layer, array_layer_count, ..default() })
        };
        let layer_views = (0..layers).map(|l| view(TextureViewDimension::D2, l, Some(1))).collect();
        let array = view(TextureViewDimension::D2Array, 0, Some(layers));
        let Some((see_bind_group, draw_bind_group)) = bind_groups(&uniform, &volume_buffer, &surface, &seen) else { continue };
        let projections = ViewBindGroups::default();
        gpu.frames.push(FrameGpu {
            uniform,
            volumes: volume_buffer,
            volume_count,
            textures,
            layers: layer_views,
            array,
            surface,
            seen,
            see_bind_group,
            draw_bind_group,
            projections,
        });
    }
}
