//! Render world: extraction, GPU buffers and pipelines of the caustic volumes passes.

use super::beam_grid::{self, BeamGridPipelines, MarchKey};
use super::build::{BuildStatsChannel, SurfaceWork};
use super::{ShaftIntegral, WarpedVolumesSettings, compute, pass};
use crate::components::Caustics;
use crate::cpu_time::timed;
use crate::irradiance::kept_bind_group::{KeptBindGroup, KeptLayout, write_changed};
use crate::irradiance::{ExtractedMedia, GpuMedium, MAX_MEDIA, MediumQuery, ViewCausticIrradiance, ViewCausticWork, cached_texture};
use bevy::camera::primitives::{Aabb, Frustum};
use bevy::core_pipeline::{
    Core3dSystems, FullscreenShader,
    prepass::ViewPrepassTextures,
    schedule::{Core3d, camera_driver},
};
use bevy::prelude::*;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    camera::ExtractedCamera,
    render_resource::{
        binding_types::{
            sampler, storage_buffer_read_only, texture_2d, texture_2d_multisampled, texture_depth_2d, texture_depth_2d_multisampled, uniform_buffer,
        },
        *,
    },
    renderer::{RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue},
    sync_world::RenderEntity,
    texture::{CachedTexture, TextureCache},
    view::{ExtractedView, Msaa, ViewUniform, ViewUniforms},
};
use bevy::shader::ShaderDefVal;
use caustics_core::volumes::IntensityMode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// One caustic volume as `volumes.wgsl` reads it and `build.wgsl` writes it
/// (`CausticVolume` in `types.wgsl`): its layout and size.
#[derive(Clone, Copy, ShaderType)]
pub(super) struct GpuCausticVolume {
    /// xyz: origin, w: depth.
    origin: Vec4,
    axis_x: Vec4,
    axis_y: Vec4,
    axis_z: Vec4,
    surface_normal: Vec4,
    vertex_x: Vec4,
    vertex_z: Vec4,
    ray_x: Vec4,
    ray_z: Vec4,
    fan_a: Vec4,
    fan_b: Vec4,
    fan_c: Vec4,
    triangle_abc: Vec4,
    flux: Vec4,
    color: Vec4,
    /// xyz: the light's path to each vertex, w: 1/range² (0: no range).
    light_distance: Vec4,
    /// The slab `near ≤ n·p ≤ far` around the surface the rays land on (world): xyz n
    /// (zero: none), w near; then x far.
    slab: Vec4,
    slab_far: Vec4,
    hit_planes: [Vec4; 3],
    /// The bounding shape the in-scattering pass draws ([`super::ShaftIntegral::Exact`];
    /// else, where the surface pass draws a slice, that slice's).
    corners: [Vec4; 8],
    /// The one the surface pass draws: the slice of the beam crossing the slab, none
    /// for a volume that lights no surface, else `corners`.
    surface_corners: [Vec4; 8],
}

/// `VolumeSettings` in `volumes.wgsl`.
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
pub(super) struct GpuVolumeSettings {
    intensity_mode: u32,
    max_magnification: f32,
    medium_count: u32,
    /// [`WarpedVolumesSettings::splat_pixels`].
    splat_pixels: u32,
    /// [`WarpedVolumesSettings::footprint_filter`]: 1 or 0.
    footprint_filter: u32,
    /// xyz: the colour every volume shares up to a factor ([`compute::VolumeBuild`]'s
    /// hue), its largest channel 1; w 1 when they share one: `splat` then adds one word
    /// of light a pixel, where the three channels would take three atomic adds.
    hue: Vec4,
    media: [GpuMedium; MAX_MEDIA],
}

/// Render world: the main world's settings.
#[derive(Resource, Default)]
pub(super) struct ExtractedVolumeSettings(pub WarpedVolumesSettings);

/// The volumes as the GPU build writes them and the passes read them: one rgba32float
/// texel a vec4 of [`GpuCausticVolume`], in field order, whole volumes to a row
/// (`load_volume` in `types.wgsl`). A texture rather than a storage buffer: lavapipe
/// loads a storage buffer's words at scattered places lane by lane, and a texel about
/// five times faster (`docs/cli-and-performance.md`).
pub(super) struct VolumeTexture {
    pub texture: Texture,
    pub view: TextureView,
}

/// `VOLUME_TEXELS` in `types.wgsl`: the texels a volume takes.
pub(super) const VOLUME_TEXELS: u32 = 37;

/// An rgba32float texture of `size` texels, one `vec4` of a record each, and its view.
pub(super) fn texel_texture(device: &RenderDevice, label: &'static str, size: UVec2, usage: TextureUsages) -> (Texture, TextureView) {
    let texture = device.create_texture(&TextureDescriptor {
        label: Some(label),
        size: Extent3d { width: size.x, height: size.y, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: TextureDimension::D2,
        format: TextureFormat::Rgba32Float,
        usage,
        view_formats: &[],
    });
    let view = texture.create_view(&TextureViewDescriptor::default());
    (texture, view)
}

impl VolumeTexture {
    /// Room for at least `capacity` volumes, at most [`Self::largest`].
    pub fn new(device: &RenderDevice, capacity: u64) -> Self {
        let per_row = Self::per_row(device);
        let rows = capacity.div_ceil(per_row).max(1) as u32;
        let usage = TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING;
        let (texture, view) = texel_texture(device, "caustic_volumes", UVec2::new(per_row as u32 * VOLUME_TEXELS, rows), usage);
        Self { texture, view }
    }

    /// Whole volumes to a row: at most 128, within the adapter's widest texture.
    fn per_row(device: &RenderDevice) -> u64 {
        u64::from(device.limits().max_texture_dimension_2d / VOLUME_TEXELS).clamp(1, 128)
    }

    /// The most volumes a texture on this adapter holds.
    pub fn largest(device: &RenderDevice) -> u64 {
        Self::per_row(device) * u64::from(device.limits().max_texture_dimension_2d)
    }

    /// The volumes it holds.
    pub fn capacity(&self) -> u64 {
        let size = self.texture.size();
        u64::from(size.width / VOLUME_TEXELS) * u64::from(size.height)
    }
}

/// Render world: the volumes the GPU build wrote (`None` while no generator, light or
/// receiver calls for any), the counters whose first words are the passes' indirect
/// draw, and the passes' settings.
#[derive(Resource, Default)]
pub(super) struct VolumeBuffers {
    pub volumes: Option<VolumeTexture>,
    pub counters: Option<Buffer>,
    /// The build of the current sources came back with no volume: the passes skip
    /// their draws (a generator in full shadow, say).
    pub empty: bool,
    pub settings: UniformBuffer<GpuVolumeSettings>,
}

impl VolumeBuffers {
    /// The volumes the buffer holds room for.
    pub fn capacity(&self) -> u64 {
        self.volumes.as_ref().map_or(0, VolumeTexture::capacity)
    }
}

/// A few words of a GPU buffer copied after a frame's commands and read back
/// asynchronously, one copy at a time and, unless asked for at once, one every
/// [`COPY_EVERY`] frames: the build's counters, the surface pass's counts. A mapping
/// costs tens of µs of CPU, and these counts are for reports, not for drawing.
#[derive(Default)]
pub(super) struct WordsReadback {
    staging: Option<Buffer>,
    reading: Arc<AtomicBool>,
    copied: bool,
    /// A copy was asked for this frame, made or not.
    asked: bool,
    /// Frames since the last one a copy was asked for, with none being read.
    idle: u8,
    /// Copies to let pass before the next one that is not asked for at once.
    wait: u8,
}

/// One copy in this many, of a source copied every frame, is read back.
const COPY_EVERY: u8 = 8;

/// Frames with no copy asked for (the build or the pass stopped) after which the
/// staging buffer goes.
const IDLE_FRAMES: u8 = 4;

impl WordsReadback {
    /// Copies the first `words` of `source` for reading after this frame, when `now`
    /// or when its turn came, unless a copy is under way. Whether it copied.
    pub fn copy(&mut self, device: &RenderDevice, encoder: &mut CommandEncoder, (source, words): (&Buffer, u64), label: &'static str, now: bool) -> bool {
        self.asked = true;
        if !now && self.wait > 0 {
            self.wait -= 1;
            return false;
        }
        if self.reading.swap(true, Ordering::AcqRel) {
            return false;
        }
        let size = 4 * words;
        let staging = self.staging.get_or_insert_with(|| {
            device.create_buffer(&BufferDescriptor {
                label: Some(label),
                size,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        encoder.copy_buffer_to_buffer(source, 0, staging, 0, size);
        (self.copied, self.idle, self.wait) = (true, 0, COPY_EVERY - 1);
        true
    }

    /// Makes the next [`Self::copy`] copy, its turn come or not.
    pub fn copy_next(&mut self) {
        self.wait = 0;
    }

    /// After this frame's commands went in: hands the words copied this frame to `read`
    /// once mapped. After [`IDLE_FRAMES`] frames with no copy asked for and none being
    /// read, the staging buffer goes.
    pub fn read_back(&mut self, read: impl FnOnce(&[u32]) + Send + 'static) {
        let asked = std::mem::take(&mut self.asked);
        let (true, Some(staging)) = (std::mem::take(&mut self.copied), self.staging.clone()) else {
            if asked {
                self.idle = 0;
            } else if !self.reading.load(Ordering::Acquire) {
                self.idle = self.idle.saturating_add(1);
                if self.idle >= IDLE_FRAMES {
                    self.staging = None;
                }
            }
            return;
        };
        let (reading, buffer) = (self.reading.clone(), staging.clone());
        staging.slice(..).map_async(MapMode::Read, move |result| {
            if result.is_ok() {
                let words: Vec<u32> = bytemuck::cast_slice(&buffer.slice(..).get_mapped_range()).to_vec();
                buffer.unmap();
                read(&words);
            }
            reading.store(false, Ordering::Release);
        });
    }
}

/// Render world: this view shows shafts (`Caustics::shafts`) and sees a
/// participating medium, and so runs the volumetric pass.
#[derive(Component)]
pub(super) struct ViewSeesMedium;

/// Render world: a view's pipelines for the two passes.
#[derive(Component)]
pub(super) struct ViewVolumePipelines {
    pub surface: CachedRenderPipelineId,
    /// The volumetric pass: straight into the view's image, or with `upsample` into its
    /// [`ViewShafts`] texture first.
    pub shafts: ShaftPipeline,
    pub upsample: Option<CachedRenderPipelineId>,
    pub multisampled: bool,
}

/// The volumetric pass's pipeline, as [`ShaftIntegral`] asks.
#[derive(Clone, Copy)]
pub(super) enum ShaftPipeline {
    /// Every volume's bounding shape drawn, the eye ray integrated through each.
    Exact(CachedRenderPipelineId),
    /// A fullscreen triangle, the eye ray marched through the beam grid.
    March(CachedRenderPipelineId),
}

/// Render world: the smaller texture a view's shafts are integrated into, one texel
/// for every `scale`² block of its pixels ([`WarpedVolumesSettings::shaft_downsample`]),
/// and what the upsampling reads it with.
#[derive(Component)]
pub(super) struct ViewShafts {
    pub texture: CachedTexture,
    pub scale: u32,
    pub bind_group: BindGroup,
}

/// The shaft texture's format: the view's HDR image's precision.
const SHAFT_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// Render world: what a view's surface pass draws with. A single-sampled copy of the
/// view's depth prepass, the size of its irradiance buffer, which the rasterised
/// volumes are tested against (read only): a prism whose back face lies in front of
/// the receiver at a pixel cannot contain that pixel's receiver point, and shades
/// nothing there. And for `splat` (`volumes.wgsl`): the light it adds, fixed point,
/// and the list of volumes it leaves to the rasteriser.
#[derive(Component)]
pub(super) struct ViewSurfaceTargets {
    pub depth: CachedTexture,
    /// The depth of each pixel's receiver point, at the pixel's centre, written by the
    /// same copy: both surface paths read it instead of rebuilding it for every volume.
    pub centre: CachedTexture,
    /// Reads the view and its depth and normal prepasses for the copy.
    pub depth_bind_group: BindGroup,
    /// Three words ([`SPLAT_SCALE`] a unit of exposed irradiance) a pixel of the
    /// camera's viewport.
    pub splatted: Buffer,
    /// The rasteriser's indirect draw (four words), then the volumes it draws: room for
    /// every volume of the build.
    pub large: Buffer,
    /// Reads `splatted` into the irradiance buffer.
    pub resolve_bind_group: BindGroup,
    /// `splat`'s: the view, the volumes and settings, `centre`, the normal prepass,
    /// the counters, `splatted` and `large`.
    pub splat_bind_group: BindGroup,
    /// The rasterised volumes': the view, the volumes and settings, `centre`, the
    /// normal prepass and `large`.
    pub draw_bind_group: BindGroup,
    /// The four bind groups above, kept while they bind the same.
    kept: [KeptBindGroup; 4],
}

/// Render world: the bind group a view's volumetric pass draws with (the march's, or
/// the exact integral's), kept while it binds the same.
#[derive(Component)]
pub(super) struct ViewShaftBindGroup {
    pub bind_group: BindGroup,
    kept: KeptBindGroup,
}

/// Fixed-point units of `splat`'s light per unit of exposed irradiance: a pixel holds
/// 2¹⁸ units of it, 128 volumes at [`crate::irradiance::MAX_EXPOSED_IRRADIANCE`].
pub(super) const SPLAT_SCALE: u32 = 1 << 14;
/// [`ViewSurfaceTargets::large`]: the indirect draw's four words, the counts of
/// [`SurfaceWork`] (`volumes.wgsl`), then from this word on the rasterised volumes.
pub(super) const FIRST_LARGE: u64 = 8;

/// Render world: the counts of [`SurfaceWork`] copied from the first view's
/// [`ViewSurfaceTargets::large`] of a frame.
#[derive(Resource, Default, Deref, DerefMut)]
pub(super) struct SurfaceWorkReadback(WordsReadback);

/// After this frame's commands went in: reads the surface pass's counts copied this
/// frame back, on to the main world.
fn read_back_surface_work(mut readback: ResMut<SurfaceWorkReadback>, channel: Res<BuildStatsChannel>) {
    let channel = channel.1.clone();
    readback.read_back(move |words| {
        if let Ok(mut work) = channel.lock() {
            *work = Some(SurfaceWork { splatted: words[4], splatted_pixels: words[5], rasterised: words[1] });
        }
    });
}

/// The receiver depth's format and the surface pass's depth test.
const RECEIVER_DEPTH_FORMAT: TextureFormat = TextureFormat::Depth32Float;
/// [`ViewSurfaceTargets::centre`]'s format.
const RECEIVER_CENTRE_FORMAT: TextureFormat = TextureFormat::R32Float;

/// The fullscreen pass that fills a view's [`ViewSurfaceTargets::depth`], for a
/// single-sampled and a multisampled prepass; `splat`, for each; and the fullscreen
/// pass that adds what it splatted to the irradiance buffer.
#[derive(Resource)]
pub(super) struct SurfacePipelines {
    depth_layouts: [KeptLayout; 2],
    pub depth_copy: [CachedRenderPipelineId; 2],
    splat_layouts: [KeptLayout; 2],
    pub splat: [CachedComputePipelineId; 2],
    resolve_layout: KeptLayout,
    pub resolve: CachedRenderPipelineId,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).render;
    let channel = app.world().resource::<BuildStatsChannel>().clone();
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .insert_resource(channel)
        .init_resource::<ExtractedVolumeSettings>()
        .init_resource::<compute::ExtractedSources>()
        .init_resource::<compute::VolumeBuild>()
        .init_resource::<VolumeBuffers>()
        .init_resource::<SpecializedRenderPipelines<VolumesPipeline>>()
        .init_resource::<SpecializedRenderPipelines<ShaftUpsamplePipeline>>()
        .init_resource::<SpecializedRenderPipelines<BeamGridPipelines>>()
        .init_resource::<beam_grid::BeamGridBuffers>()
        .init_resource::<SurfaceWorkReadback>()
        .add_systems(RenderStartup, ((init_pipeline, beam_grid::init_pipelines), warm_pipelines).chain())
        .add_systems(RenderStartup, compute::init_pipelines)
        .add_systems(ExtractSchedule, (timed(&cpu, extract_settings), timed(&cpu, compute::extract_sources), timed(&cpu, mark_views_seeing_media)))
        .add_systems(
            RenderGraph,
            (timed(&cpu, compute::build_volumes), timed(&cpu, beam_grid::deposit_beams)).chain().in_set(RenderGraphSystems::Render).before(camera_driver),
        )
        .add_systems(
            Render,
            (
                timed(&cpu, prepare_buffers).in_set(RenderSystems::PrepareResources).after(compute::prepare_build),
                timed(&cpu, compute::prepare_build).in_set(RenderSystems::PrepareResources),
                timed(&cpu, beam_grid::prepare_grids).in_set(RenderSystems::PrepareResources).after(compute::prepare_build).after(prepare_buffers),
                timed(&cpu, compute::read_back_counts).in_set(RenderSystems::Cleanup),
                timed(&cpu, read_back_surface_work).in_set(RenderSystems::Cleanup),
                timed(&cpu, prepare_shaft_textures).in_set(RenderSystems::PrepareResources),
                timed(&cpu, prepare_surface_targets).in_set(RenderSystems::PrepareBindGroups),
                timed(&cpu, prepare_shaft_bind_groups).in_set(RenderSystems::PrepareBindGroups),
                timed(&cpu, prepare_pipelines).in_set(RenderSystems::Prepare),
            ),
        )
        .add_systems(
            Core3d,
            (
                timed(&cpu, pass::surface_pass).after(crate::irradiance::inject_irradiance).after(Core3dSystems::Prepass).before(Core3dSystems::MainPass),
                // After Bevy's volumetric fog (which runs before the early post-processing):
                // the shafts, dimmed along the eye ray already, are not dimmed again.
                timed(&cpu, pass::volumetric_pass).in_set(Core3dSystems::EarlyPostProcess),
            ),
        );
}

fn extract_settings(mut extracted: ResMut<ExtractedVolumeSettings>, settings: Extract<Res<WarpedVolumesSettings>>) {
    extracted.0 = **settings;
}

/// 3D cameras, their frusta and caustics settings.
type CameraFrusta = Query<'static, 'static, (RenderEntity, &'static Frustum, Option<&'static Caustics>), With<Camera3d>>;

/// Marks the views that show shafts and whose frustum meets a medium's box.
fn mark_views_seeing_media(mut commands: Commands, views: Extract<CameraFrusta>, media: Extract<MediumQuery>) {
    let unit_cube = Aabb { center: Vec3::ZERO.into(), half_extents: Vec3::splat(0.5).into() };
    for (view, frustum, settings) in &views {
        let sees = settings.is_some_and(|s| s.shafts)
            && media.iter().any(|(_, t, visible)| visible.get() && frustum.intersects_obb(&unit_cube, &t.affine(), true, true));
        if sees {
            commands.entity(view).insert(ViewSeesMedium);
        } else {
            commands.entity(view).remove::<ViewSeesMedium>();
        }
    }
}

fn prepare_buffers(
    (extracted, sources, build): (Res<ExtractedVolumeSettings>, Res<compute::ExtractedSources>, Res<compute::VolumeBuild>),
    media: Res<ExtractedMedia>,
    mut buffers: ResMut<VolumeBuffers>,
    mut surface_work: ResMut<SurfaceWorkReadback>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let settings = extracted.0.core();
    let (media, medium_count) = media.padded();
    let value = GpuVolumeSettings {
        intensity_mode: match settings.intensity {
            IntensityMode::Conserving => 0,
            IntensityMode::Interpolated => 1,
            IntensityMode::Constant => 2,
        },
        max_magnification: settings.max_magnification,
        medium_count,
        splat_pixels: extracted.0.splat_pixels,
        footprint_filter: settings.footprint_filter.into(),
        hue: build.hue.map_or(Vec4::ZERO, |h| (h / h.max_element()).extend(1.0)),
        media,
    };
    buffers.settings.set_label(Some("caustic_volume_settings"));
    // New settings or sources share the volumes out anew: counted at once.
    if write_changed(&mut buffers.settings, value, &device, &queue) || sources.new {
        surface_work.copy_next();
    }
}

/// The bind group layouts of the rasterised passes, surface and volumetric (each for a
/// single-sampled and a multisampled prepass), and the shader.
#[derive(Resource)]
pub(super) struct VolumesPipeline {
    surface_layouts: [KeptLayout; 2],
    volumetric_layouts: [KeptLayout; 2],
    shader: Handle<Shader>,
}

impl VolumesPipeline {
    /// The layout a pass draws with.
    pub fn layout(&self, volumetric: bool, multisampled: bool) -> &KeptLayout {
        let layouts = if volumetric { &self.volumetric_layouts } else { &self.surface_layouts };
        &layouts[multisampled as usize]
    }
}

/// What `volumes.wgsl` reads in every entry point (the view, the volumes, the settings
/// and the prepass), seen from `visibility`, then `more` from binding 5 on.
/// The layout of `volumes.wgsl`: binding 3 the depth prepass, or for the surface pass
/// (`centre`) [`ViewSurfaceTargets::centre`].
fn volumes_layout(label: &'static str, (multisampled, centre): (bool, bool), visibility: ShaderStages, more: &[BindingType]) -> BindGroupLayoutDescriptor {
    let mut entries = BindGroupLayoutEntries::sequential(
        visibility,
        (
            uniform_buffer::<ViewUniform>(true),
            texture_2d(TextureSampleType::Float { filterable: false }),
            uniform_buffer::<GpuVolumeSettings>(false),
            match (centre, multisampled) {
                (true, _) => texture_2d(TextureSampleType::Float { filterable: false }),
                (false, true) => texture_depth_2d_multisampled(),
                (false, false) => texture_depth_2d(),
            },
            if multisampled {
                texture_2d_multisampled(TextureSampleType::Float { filterable: false })
            } else {
                texture_2d(TextureSampleType::Float { filterable: false })
            },
        ),
    )
    .to_vec();
    entries.extend(more.iter().zip(5..).map(|(&ty, binding)| BindGroupLayoutEntry { binding, visibility, ty, count: None }));
    BindGroupLayoutDescriptor::new(label, &entries)
}

/// A storage buffer of `u32`s.
fn words(read_only: bool) -> BindingType {
    BindingType::Buffer { ty: BufferBindingType::Storage { read_only }, has_dynamic_offset: false, min_binding_size: None }
}

/// The shader definition every variant of `volumes.wgsl` needs.
fn splat_defs() -> [ShaderDefVal; 1] {
    [ShaderDefVal::UInt("SPLAT_SCALE".into(), SPLAT_SCALE)]
}

#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub(super) struct VolumesPipelineKey {
    volumetric: bool,
    multisampled: bool,
    /// The surface pass's pixels are footprint means
    /// ([`WarpedVolumesSettings::footprint_filter`]).
    filtered: bool,
    /// The volumetric pass's pixels per shaft sample, across (1: every pixel).
    shaft_scale: u32,
    /// The colour target: the irradiance buffer's format for the surface pass, the
    /// view's (resolved, single-sampled) HDR image for the volumetric pass.
    target_format: TextureFormat,
}

fn init_pipeline(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    device: Res<RenderDevice>,
    fullscreen: Res<FullscreenShader>,
    cache: Res<PipelineCache>,
) {
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "volumes.wgsl");
    let surface_layouts =
        [false, true].map(|multisampled| volumes_layout("caustic_volumes_surface_layout", (multisampled, true), ShaderStages::VERTEX_FRAGMENT, &[words(true)]));
    let volumetric_layouts =
        [false, true].map(|multisampled| volumes_layout("caustic_volumes_volumetric_layout", (multisampled, false), ShaderStages::VERTEX_FRAGMENT, &[]));
    let splat_layouts = [false, true].map(|multisampled| {
        volumes_layout("caustic_volumes_splat_layout", (multisampled, true), ShaderStages::COMPUTE, &[words(true), words(false), words(false)])
    });
    let splat = [false, true].map(|multisampled| {
        let mut shader_defs = vec!["SPLAT".into(), "RECEIVER_CENTRE".into()];
        shader_defs.extend(multisampled.then(|| "MULTISAMPLED".into()));
        shader_defs.extend(splat_defs());
        cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some("caustic_volumes_splat_pipeline".into()),
            layout: vec![splat_layouts[multisampled as usize].clone()],
            shader: shader.clone(),
            shader_defs,
            entry_point: Some("splat".into()),
            ..default()
        })
    });
    let (surface_layouts, volumetric_layouts) = (surface_layouts.map(KeptLayout::new), volumetric_layouts.map(KeptLayout::new));
    commands.insert_resource(VolumesPipeline { surface_layouts, volumetric_layouts, shader });
    let layout = BindGroupLayoutDescriptor::new(
        "caustic_shafts_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (texture_2d(TextureSampleType::Float { filterable: true }), sampler(SamplerBindingType::Filtering)),
        ),
    );
    let sampler = device.create_sampler(&SamplerDescriptor {
        label: Some("caustic_shafts_sampler"),
        mag_filter: FilterMode::Linear,
        min_filter: FilterMode::Linear,
        ..default()
    });
    commands.insert_resource(ShaftUpsamplePipeline {
        layout: KeptLayout::new(layout),
        sampler,
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "upsample.wgsl"),
        fullscreen: fullscreen.clone(),
    });
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "receiver_depth.wgsl");
    let depth_layouts = [false, true].map(|multisampled| {
        BindGroupLayoutDescriptor::new(
            "caustic_receiver_depth_layout",
            &BindGroupLayoutEntries::sequential(
                ShaderStages::FRAGMENT,
                (
                    uniform_buffer::<ViewUniform>(true),
                    if multisampled { texture_depth_2d_multisampled() } else { texture_depth_2d() },
                    if multisampled {
                        texture_2d_multisampled(TextureSampleType::Float { filterable: false })
                    } else {
                        texture_2d(TextureSampleType::Float { filterable: false })
                    },
                ),
            ),
        )
    });
    let depth_copy = [false, true].map(|multisampled| {
        cache.queue_render_pipeline(RenderPipelineDescriptor {
            label: Some("caustic_receiver_depth_pipeline".into()),
            layout: vec![depth_layouts[multisampled as usize].clone()],
            vertex: fullscreen.to_vertex_state(),
            fragment: Some(FragmentState {
                shader: shader.clone(),
                shader_defs: if multisampled { vec!["MULTISAMPLED".into()] } else { vec![] },
                entry_point: Some("copy_depth".into()),
                targets: vec![Some(ColorTargetState { format: RECEIVER_CENTRE_FORMAT, blend: None, write_mask: ColorWrites::ALL })],
            }),
            depth_stencil: Some(DepthStencilState {
                format: RECEIVER_DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(CompareFunction::Always),
                stencil: default(),
                bias: default(),
            }),
            ..default()
        })
    });
    let resolve_layout = BindGroupLayoutDescriptor::new(
        "caustic_volumes_resolve_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (uniform_buffer::<ViewUniform>(true), storage_buffer_read_only::<u32>(false), uniform_buffer::<GpuVolumeSettings>(false)),
        ),
    );
    // A projection into the irradiance buffer, drawn only where the view sees a
    // surface (its depth test against the receiver depth).
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "splat_resolve.wgsl");
    let mut descriptor = crate::irradiance::projection_pipeline("caustic_volumes_resolve_pipeline", &resolve_layout, &shader, &fullscreen, false);
    if let Some(fragment) = descriptor.fragment.as_mut() {
        fragment.shader_defs = splat_defs().to_vec();
    }
    descriptor.depth_stencil = Some(DepthStencilState {
        format: RECEIVER_DEPTH_FORMAT,
        depth_write_enabled: Some(false),
        depth_compare: Some(CompareFunction::Less),
        stencil: default(),
        bias: default(),
    });
    let resolve = cache.queue_render_pipeline(descriptor);
    let (depth_layouts, splat_layouts) = (depth_layouts.map(KeptLayout::new), splat_layouts.map(KeptLayout::new));
    let resolve_layout = KeptLayout::new(resolve_layout);
    commands.insert_resource(SurfacePipelines { depth_layouts, depth_copy, splat_layouts, splat, resolve_layout, resolve });
}

impl SpecializedRenderPipeline for VolumesPipeline {
    type Key = VolumesPipelineKey;

    fn specialize(&self, key: Self::Key) -> RenderPipelineDescriptor {
        let mut shader_defs = splat_defs().to_vec();
        if key.multisampled {
            shader_defs.push("MULTISAMPLED".into());
        }
        if key.shaft_scale > 1 {
            shader_defs.push(ShaderDefVal::UInt("SHAFT_SCALE".into(), key.shaft_scale));
        }
        if !key.volumetric {
            // Surfaces: each volume cut to the slab around where its rays land, each
            // pixel's receiver point read from `ViewSurfaceTargets::centre`.
            shader_defs.extend(["SURFACE".into(), "RECEIVER_CENTRE".into()]);
        }
        let (label, entry) = if key.volumetric { ("caustic_volumetric_pipeline", "volumetric") } else { ("caustic_volumes_pipeline", "surface") };
        // Shafts go into the view's image scaled by the view's
        // `Caustics::intensity` as the blend constant (straight, or when they
        // are upsampled from their own texture); the composite scales the surface
        // pass's buffer.
        let src_factor = if key.volumetric && key.shaft_scale == 1 { BlendFactor::Constant } else { BlendFactor::One };
        let additive = BlendComponent { src_factor, dst_factor: BlendFactor::One, operation: BlendOperation::Add };
        RenderPipelineDescriptor {
            label: Some(label.into()),
            layout: vec![self.layout(key.volumetric, key.multisampled).descriptor.clone()],
            vertex: VertexState { shader: self.shader.clone(), shader_defs: shader_defs.clone(), entry_point: Some("vertex".into()), buffers: vec![] },
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                shader_defs,
                entry_point: Some(entry.into()),
                targets: vec![Some(ColorTargetState {
                    format: key.target_format,
                    blend: Some(BlendState { color: additive, alpha: additive }),
                    write_mask: ColorWrites::ALL,
                })],
            }),
            // Back faces only: each pixel whose ray crosses a volume's bounding prism
            // runs the exact test once (§4.3). The surface pass draws a prism's outline
            // on the view instead, grown by a pixel, at its farthest corner's depth, and
            // keeps the pixels the compute pass would light (`volumes.wgsl`); the back
            // faces only where it reaches behind the eye. Point-sampled, it skips pixels whose
            // receiver lies behind that depth ([`ViewSurfaceTargets::depth`]; reversed
            // z), outside the prism; a footprint around such a point may not be.
            primitive: PrimitiveState { cull_mode: Some(Face::Front), front_face: FrontFace::Ccw, ..default() },
            depth_stencil: (!key.volumetric).then(|| DepthStencilState {
                format: RECEIVER_DEPTH_FORMAT,
                depth_write_enabled: Some(false),
                depth_compare: Some(if key.filtered { CompareFunction::Always } else { CompareFunction::LessEqual }),
                stencil: default(),
                bias: default(),
            }),
            ..default()
        }
    }
}

#[expect(clippy::too_many_arguments)]
fn prepare_pipelines(
    mut commands: Commands,
    views: Query<(Entity, &ExtractedView, &Msaa, &ViewPrepassTextures), With<ViewCausticWork>>,
    pipeline: Res<VolumesPipeline>,
    mut pipelines: ResMut<SpecializedRenderPipelines<VolumesPipeline>>,
    upsample: Res<ShaftUpsamplePipeline>,
    mut upsample_pipelines: ResMut<SpecializedRenderPipelines<ShaftUpsamplePipeline>>,
    (march, mut march_pipelines): (Res<BeamGridPipelines>, ResMut<SpecializedRenderPipelines<BeamGridPipelines>>),
    extracted: Res<ExtractedVolumeSettings>,
    cache: Res<PipelineCache>,
) {
    let scale = extracted.0.shaft_scale();
    let grid = extracted.0.shaft_integral == ShaftIntegral::Grid;
    let filtered = extracted.0.footprint_filter;
    for (entity, view, msaa, prepass) in &views {
        if prepass.depth.is_none() || prepass.normal.is_none() {
            continue;
        }
        let multisampled = msaa.samples() > 1;
        let mut specialize = |volumetric, target_format, shaft_scale| {
            pipelines.specialize(
                &cache,
                &pipeline,
                VolumesPipelineKey { volumetric, multisampled, filtered: filtered && !volumetric, shaft_scale, target_format },
            )
        };
        let surface = specialize(false, crate::CAUSTIC_IRRADIANCE_FORMAT, 1);
        // Below full resolution, into the shaft texture, then spread over the image.
        let target_format = if scale > 1 { SHAFT_FORMAT } else { view.target_format };
        let upsample = (scale > 1).then(|| upsample_pipelines.specialize(&cache, &upsample, ShaftUpsampleKey { target_format: view.target_format, scale }));
        let shafts = if grid {
            ShaftPipeline::March(march_pipelines.specialize(&cache, &march, MarchKey { multisampled, shaft_scale: scale, target_format }))
        } else {
            ShaftPipeline::Exact(specialize(true, target_format, scale))
        };
        commands.entity(entity).insert(ViewVolumePipelines { surface, shafts, upsample, multisampled });
    }
}

/// Queues, at startup, the pipelines a view with the default settings and an HDR
/// target (`Rgba16Float`) specializes (single-sampled and with 4 samples), so that they compile
/// before the first caustic volume appears instead of after it.
fn warm_pipelines(
    (pipeline, mut pipelines): (Res<VolumesPipeline>, ResMut<SpecializedRenderPipelines<VolumesPipeline>>),
    (upsample, mut upsample_pipelines): (Res<ShaftUpsamplePipeline>, ResMut<SpecializedRenderPipelines<ShaftUpsamplePipeline>>),
    (march, mut march_pipelines): (Res<BeamGridPipelines>, ResMut<SpecializedRenderPipelines<BeamGridPipelines>>),
    cache: Res<PipelineCache>,
) {
    let scale = WarpedVolumesSettings::default().shaft_scale();
    for multisampled in [false, true] {
        let surface = VolumesPipelineKey { volumetric: false, multisampled, filtered: true, shaft_scale: 1, target_format: crate::CAUSTIC_IRRADIANCE_FORMAT };
        pipelines.specialize(&cache, &pipeline, surface);
        march_pipelines.specialize(&cache, &march, MarchKey { multisampled, shaft_scale: scale, target_format: SHAFT_FORMAT });
    }
    upsample_pipelines.specialize(&cache, &upsample, ShaftUpsampleKey { target_format: TextureFormat::Rgba16Float, scale });
}

/// Gives every view that runs the volumetric pass below full resolution its shaft
/// texture (`ceil(size / scale)` texels across and down), and takes it from the others.
#[expect(clippy::too_many_arguments)]
fn prepare_shaft_textures(
    mut commands: Commands,
    views: Query<(Entity, &ExtractedCamera, Option<&ViewShafts>), With<ViewSeesMedium>>,
    others: Query<Entity, (With<ViewShafts>, Without<ViewSeesMedium>)>,
    extracted: Res<ExtractedVolumeSettings>,
    upsample: Res<ShaftUpsamplePipeline>,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    cache: Res<PipelineCache>,
) {
    for entity in &others {
        commands.entity(entity).remove::<ViewShafts>();
    }
    let scale = extracted.0.shaft_scale();
    for (entity, camera, shafts) in &views {
        let Some(size) = camera.physical_target_size.filter(|s| s.x > 0 && s.y > 0 && scale > 1) else {
            commands.entity(entity).remove::<ViewShafts>();
            continue;
        };
        let usage = TextureUsages::TEXTURE_BINDING | TextureUsages::RENDER_ATTACHMENT;
        let texture = cached_texture(&mut texture_cache, &device, "caustic_shafts", size.map(|n| n.div_ceil(scale)), SHAFT_FORMAT, usage);
        // Kept while the texture cache hands the view the same texture.
        let bind_group = match shafts.filter(|s| s.texture.default_view.id() == texture.default_view.id()) {
            Some(shafts) => shafts.bind_group.clone(),
            None => device.create_bind_group(
                "caustic_shafts_bind_group",
                upsample.layout.get(&cache),
                &BindGroupEntries::sequential((&texture.default_view, &upsample.sampler)),
            ),
        };
        commands.entity(entity).insert(ViewShafts { texture, scale, bind_group });
    }
}

/// Gives every caustics view that reads a depth prepass its [`ViewSurfaceTargets`]
/// (the depth the size of its irradiance buffer, the splatted light the size of its
/// viewport), keeping its buffers while those sizes and the build's capacity stay, and
/// takes them from views without caustics work.
#[expect(clippy::too_many_arguments)]
fn prepare_surface_targets(
    mut commands: Commands,
    mut views: Query<(Entity, &ViewCausticIrradiance, &ViewPrepassTextures, &Msaa, Option<&mut ViewSurfaceTargets>)>,
    others: Query<Entity, (With<ViewSurfaceTargets>, Without<ViewCausticIrradiance>)>,
    (pipelines, volume_layouts): (Res<SurfacePipelines>, Res<VolumesPipeline>),
    buffers: Res<VolumeBuffers>,
    view_uniforms: Res<ViewUniforms>,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    cache: Res<PipelineCache>,
) {
    for entity in &others {
        commands.entity(entity).remove::<ViewSurfaceTargets>();
    }
    for (entity, irradiance, prepass, msaa, mut kept_targets) in &mut views {
        let (Some(depth), Some(normal), Some(volumes), Some(counters), Some(settings), Some(view_buffer), Some(view_binding)) = (
            prepass.depth_view(),
            prepass.normal_view(),
            buffers.volumes.as_ref().filter(|_| !buffers.empty).map(|v| &v.view),
            buffers.counters.as_ref(),
            buffers.settings.buffer(),
            view_uniforms.uniforms.buffer(),
            view_uniforms.uniforms.binding(),
        ) else {
            commands.entity(entity).remove::<ViewSurfaceTargets>();
            continue;
        };
        let size = irradiance.texture.texture.size();
        let mut target = |label, format, usage| cached_texture(&mut texture_cache, &device, label, UVec2::new(size.width, size.height), format, usage);
        let texture = target("caustic_receiver_depth", RECEIVER_DEPTH_FORMAT, TextureUsages::RENDER_ATTACHMENT);
        let centre = target("caustic_receiver_centre", RECEIVER_CENTRE_FORMAT, TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING);
        let multisampled = (msaa.samples() > 1) as usize;
        let [mut kept_depth, mut kept_resolve, mut kept_splat, mut kept_draw] = kept_targets.as_mut().map(|t| std::mem::take(&mut t.kept)).unwrap_or_default();
        let targets = kept_targets.as_deref();
        let layout = pipelines.depth_layouts[multisampled].get(&cache);
        let depth_bind_group = kept_depth.get(&[layout.into(), view_buffer.into(), depth.into(), normal.into()], || {
            device.create_bind_group("caustic_receiver_depth_bind_group", layout, &BindGroupEntries::sequential((view_binding.clone(), depth, normal)))
        });
        let pixels = u64::from(irradiance.region().1.element_product());
        let splatted_size = 3 * 4 * pixels.max(1);
        let large_size = 4 * (FIRST_LARGE + buffers.capacity());
        let buffer = |label, size, usage| device.create_buffer(&BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false });
        let splatted = match targets.filter(|t| t.splatted.size() == splatted_size) {
            Some(t) => t.splatted.clone(),
            None => buffer("caustic_volumes_splatted", splatted_size, BufferUsages::STORAGE | BufferUsages::COPY_DST),
        };
        let large = match targets.filter(|t| t.large.size() == large_size) {
            Some(t) => t.large.clone(),
            None => {
                buffer("caustic_volumes_large", large_size, BufferUsages::STORAGE | BufferUsages::INDIRECT | BufferUsages::COPY_DST | BufferUsages::COPY_SRC)
            }
        };
        let layout = pipelines.resolve_layout.get(&cache);
        let resolve_bind_group = kept_resolve.get(&[layout.into(), view_buffer.into(), (&splatted).into(), settings.into()], || {
            device.create_bind_group(
                "caustic_volumes_resolve_bind_group",
                layout,
                &BindGroupEntries::sequential((view_binding.clone(), splatted.as_entire_binding(), settings.as_entire_binding())),
            )
        });
        let layout = pipelines.splat_layouts[multisampled].get(&cache);
        let bound = [
            layout.into(),
            view_buffer.into(),
            volumes.into(),
            settings.into(),
            (&centre.default_view).into(),
            normal.into(),
            counters.into(),
            (&splatted).into(),
            (&large).into(),
        ];
        let splat_bind_group = kept_splat.get(&bound, || {
            device.create_bind_group(
                "caustic_volumes_splat_bind_group",
                layout,
                &BindGroupEntries::sequential((
                    view_binding.clone(),
                    volumes,
                    settings.as_entire_binding(),
                    &centre.default_view,
                    normal,
                    counters.as_entire_binding(),
                    splatted.as_entire_binding(),
                    large.as_entire_binding(),
                )),
            )
        });
        let layout = volume_layouts.layout(false, multisampled == 1).get(&cache);
        let bound = [layout.into(), view_buffer.into(), volumes.into(), settings.into(), (&centre.default_view).into(), normal.into(), (&large).into()];
        let draw_bind_group = kept_draw.get(&bound, || {
            let entries = (view_binding.clone(), volumes, settings.as_entire_binding(), &centre.default_view, normal, large.as_entire_binding());
            device.create_bind_group("caustic_volumes_surface_bind_group", layout, &BindGroupEntries::sequential(entries))
        });
        let kept = [kept_depth, kept_resolve, kept_splat, kept_draw];
        let targets =
            ViewSurfaceTargets { depth: texture, centre, depth_bind_group, splatted, large, resolve_bind_group, splat_bind_group, draw_bind_group, kept };
        // Replaced in place: no command a frame for a view that keeps its targets.
        match kept_targets {
            Some(mut kept) => *kept = targets,
            None => {
                commands.entity(entity).insert(targets);
            }
        }
    }
}

/// Gives every view that sees a medium the [`ViewShaftBindGroup`] of its volumetric
/// pipeline, and takes it from the others.
#[expect(clippy::too_many_arguments)]
fn prepare_shaft_bind_groups(
    mut commands: Commands,
    mut views: Query<(Entity, &ViewVolumePipelines, &ViewPrepassTextures, Option<&mut ViewShaftBindGroup>), With<ViewSeesMedium>>,
    others: Query<Entity, (With<ViewShaftBindGroup>, Without<ViewSeesMedium>)>,
    (layouts, march): (Res<VolumesPipeline>, Res<BeamGridPipelines>),
    (buffers, grids): (Res<VolumeBuffers>, Res<beam_grid::BeamGridBuffers>),
    view_uniforms: Res<ViewUniforms>,
    device: Res<RenderDevice>,
    cache: Res<PipelineCache>,
) {
    for entity in &others {
        commands.entity(entity).remove::<ViewShaftBindGroup>();
    }
    for (entity, pipelines, prepass, mut shafts) in &mut views {
        let (Some(depth), Some(view_buffer), Some(view_binding), Some(settings)) =
            (prepass.depth_view(), view_uniforms.uniforms.buffer(), view_uniforms.uniforms.binding(), buffers.settings.buffer())
        else {
            commands.entity(entity).remove::<ViewShaftBindGroup>();
            continue;
        };
        let mut kept = shafts.as_mut().map(|s| std::mem::take(&mut s.kept)).unwrap_or_default();
        let bindings = (
            pipelines.shafts,
            prepass.normal_view(),
            buffers.volumes.as_ref().map(|v| &v.view),
            grids.grids.buffer(),
            grids.textures.as_ref(),
            buffers.counters.as_ref(),
        );
        let bind_group = match bindings {
            (ShaftPipeline::Exact(_), Some(normal), Some(volumes), ..) => {
                let layout = layouts.layout(true, pipelines.multisampled).get(&cache);
                let bound = [layout.into(), view_buffer.into(), volumes.into(), settings.into(), depth.into(), normal.into()];
                kept.get(&bound, || {
                    let entries = (view_binding.clone(), volumes, settings.as_entire_binding(), depth, normal);
                    device.create_bind_group("caustic_volumes_bind_group", layout, &BindGroupEntries::sequential(entries))
                })
            }
            (ShaftPipeline::March(_), .., Some(grid), Some([light, directions]), Some(counters)) => {
                let layout = march.march_layouts[pipelines.multisampled as usize].get(&cache);
                let bound = [layout.into(), view_buffer.into(), settings.into(), grid.into(), counters.into(), light.into(), directions.into(), depth.into()];
                kept.get(&bound, || {
                    let entries = (
                        view_binding.clone(),
                        settings.as_entire_binding(),
                        grid.as_entire_binding(),
                        counters.as_entire_binding(),
                        light,
                        directions,
                        &march.sampler,
                        depth,
                    );
                    device.create_bind_group("caustic_shaft_march_bind_group", layout, &BindGroupEntries::sequential(entries))
                })
            }
            _ => {
                commands.entity(entity).remove::<ViewShaftBindGroup>();
                continue;
            }
        };
        match shafts {
            Some(mut shafts) => *shafts = ViewShaftBindGroup { bind_group, kept },
            None => {
                commands.entity(entity).insert(ViewShaftBindGroup { bind_group, kept });
            }
        }
    }
}

/// The fullscreen pass that spreads a view's shaft texture over its image.
#[derive(Resource)]
pub(super) struct ShaftUpsamplePipeline {
    layout: KeptLayout,
    sampler: Sampler,
    shader: Handle<Shader>,
    fullscreen: FullscreenShader,
}

#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub(super) struct ShaftUpsampleKey {
    target_format: TextureFormat,
    scale: u32,
}

impl SpecializedRenderPipeline for ShaftUpsamplePipeline {
    type Key = ShaftUpsampleKey;

    fn specialize(&self, key: Self::Key) -> RenderPipelineDescriptor {
        // Scaled by the view's `Caustics::intensity` as the blend constant.
        let additive = BlendComponent { src_factor: BlendFactor::Constant, dst_factor: BlendFactor::One, operation: BlendOperation::Add };
        RenderPipelineDescriptor {
            label: Some("caustic_shaft_upsample_pipeline".into()),
            layout: vec![self.layout.descriptor.clone()],
            vertex: self.fullscreen.to_vertex_state(),
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                shader_defs: vec![ShaderDefVal::UInt("SHAFT_SCALE".into(), key.scale)],
                entry_point: Some("upsample".into()),
                targets: vec![Some(ColorTargetState {
                    format: key.target_format,
                    blend: Some(BlendState { color: additive, alpha: additive }),
                    write_mask: ColorWrites::ALL,
                })],
            }),
            ..default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{GpuCausticVolume, VOLUME_TEXELS};
    use bevy::render::render_resource::ShaderType;

    #[test]
    fn a_volume_takes_the_texels_the_shaders_read() {
        assert_eq!(GpuCausticVolume::min_size().get(), u64::from(VOLUME_TEXELS) * 16, "one rgba32float texel a vec4 of the volume");
        let wgsl = include_str!("types.wgsl");
        assert!(wgsl.contains(&format!("const VOLUME_TEXELS: u32 = {VOLUME_TEXELS}u;")), "types.wgsl's VOLUME_TEXELS is not {VOLUME_TEXELS}");
    }
}
