//! Rendering without a window: build an app, render N frames into an image, read the
//! pixels back as linear floats. Used by the tests, the examples' headless mode and the
//! CLI. Runs on any wgpu adapter, Mesa's software Vulkan (lavapipe) included.

use crate::pixels::{decode_rgba16f, unpad_rows};
use crate::{CausticPassReport, CausticsPlugin};
use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::prelude::*;
use bevy::render::{
    RenderPlugin,
    gpu_readback::{Readback, ReadbackComplete},
    render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages},
};
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use std::path::Path;
use std::sync::{Arc, Mutex};
use thiserror::Error;

/// Why a headless render could not run.
#[derive(Debug, Error)]
pub enum HeadlessError {
    #[error(
        "no GPU adapter found ({0}). Install Mesa's software Vulkan to render without a GPU: \
         `apt-get install -y mesa-vulkan-drivers`"
    )]
    /// No adapter answered; the reason wgpu gave.
    NoAdapter(String),
    /// The frame's pixels did not come back in time.
    #[error("the frame was not read back after {0} extra updates")]
    NoReadback(u32),
    /// Mapping a buffer read back from the GPU failed.
    #[error("reading the GPU back failed: {0}")]
    Readback(String),
    /// The entity asked for is not a camera that renders.
    #[error("the entity is not a rendered camera")]
    NotACamera,
    /// A render pipeline failed to compile; the error.
    #[error("a pipeline failed to build: {0}")]
    Pipeline(String),
    /// An image could not be written to `path`.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The file.
        path: String,
        /// Why it failed.
        reason: String,
    },
}

/// The adapter wgpu finds on the backends Bevy would use.
#[derive(Clone, Debug)]
pub struct Adapter {
    /// Its name and backend, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)`.
    pub name: String,
    /// The queries it has of those that measure passes: timestamps (GPU times) and
    /// pipeline statistics (shader invocations).
    pub queries: wgpu::Features,
}

impl Adapter {
    /// Whether it times passes (`TIMESTAMP_QUERY`).
    pub fn has_timestamps(&self) -> bool {
        self.queries.contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// Whether it counts passes' shader invocations (`PIPELINE_STATISTICS_QUERY`).
    pub fn has_pipeline_statistics(&self) -> bool {
        self.queries.contains(wgpu::Features::PIPELINE_STATISTICS_QUERY)
    }
}

/// Timestamps at encoder and pass boundaries and pipeline statistics: what
/// `RenderDiagnosticsPlugin` needs to time passes and count their work on the GPU.
const MEASURING_FEATURES: wgpu::Features = wgpu::Features::TIMESTAMP_QUERY
    .union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS)
    .union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES)
    .union(wgpu::Features::PIPELINE_STATISTICS_QUERY);

/// Checks that wgpu finds an adapter on the backends Bevy would use.
pub fn probe_adapter() -> Result<Adapter, HeadlessError> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all()),
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapter =
        bevy::tasks::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default())).map_err(|e| HeadlessError::NoAdapter(e.to_string()))?;
    let info = adapter.get_info();
    Ok(Adapter { name: format!("{} ({:?})", info.name, info.backend), queries: adapter.features() & MEASURING_FEATURES })
}

/// Linear RGBA pixels of a rendered frame, row-major from the top-left.
#[derive(Clone, Debug)]
pub struct RenderedImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` pixels, row by row from the top-left.
    pub pixels: Vec<Vec4>,
}

impl RenderedImage {
    /// The pixel at `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> Vec4 {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Writes an 8-bit sRGB PNG, scaling linear values by `scale` and clamping.
    pub fn save_png(&self, path: &Path, scale: f32) -> Result<(), HeadlessError> {
        let err = |reason: String| HeadlessError::Write { path: path.display().to_string(), reason };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
        }
        let image = Image::new(
            Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
            TextureDimension::D2,
            self.pixels
                .iter()
                .flat_map(|p| {
                    let c = Color::LinearRgba(LinearRgba::new(p.x * scale, p.y * scale, p.z * scale, 1.0));
                    c.to_srgba().to_u8_array()
                })
                .collect(),
            TextureFormat::Rgba8UnormSrgb,
            RenderAssetUsages::MAIN_WORLD,
        );
        let dynamic = image.try_into_dynamic().map_err(|e| err(e.to_string()))?;
        dynamic.to_rgb8().save(path).map_err(|e| err(e.to_string()))
    }
}

/// A Bevy app that renders into an offscreen HDR image (`Rgba16Float`, linear, no
/// tonemapping unless the camera asks for it), with [`CausticsPlugin`] added. Time
/// advances 1/60 s a frame, whatever the frame takes: an animated scene renders the
/// same image on any machine.
pub struct HeadlessRenderer {
    /// The app: spawn the scene into its world.
    pub app: App,
    /// The adapter it renders on.
    pub adapter: Adapter,
    target: Handle<Image>,
    width: u32,
    height: u32,
}

impl HeadlessRenderer {
    /// Builds the app, after checking that an adapter exists.
    pub fn new(width: u32, height: u32) -> Result<Self, HeadlessError> {
        Self::build(width, height, false, None, |_| {})
    }

    /// [`Self::new`] with the asset server reading from `root` instead of `assets/`
    /// (a folder of glTF files to load as a game would).
    pub fn with_asset_root(width: u32, height: u32, root: &Path) -> Result<Self, HeadlessError> {
        Self::build(width, height, false, Some(root), |_| {})
    }

    /// [`Self::new`] with more plugins (a game's materials, say), added before the app
    /// is finished as plugins must be.
    pub fn with_plugins<M>(width: u32, height: u32, plugins: impl bevy::app::Plugins<M>) -> Result<Self, HeadlessError> {
        Self::build(width, height, false, None, |app| {
            app.add_plugins(plugins);
        })
    }

    /// Builds the app with Bevy's `RenderDiagnosticsPlugin` and whichever timestamp and
    /// pipeline-statistics queries the adapter has, so that [`Self::gpu_pass_work`]
    /// reads every pass's GPU time and shader invocations.
    pub fn timed(width: u32, height: u32) -> Result<Self, HeadlessError> {
        Self::build(width, height, true, None, |_| {})
    }

    /// [`Self::timed`] with more plugins, as [`Self::with_plugins`].
    pub fn timed_with_plugins<M>(width: u32, height: u32, plugins: impl bevy::app::Plugins<M>) -> Result<Self, HeadlessError> {
        Self::build(width, height, true, None, |app| {
            app.add_plugins(plugins);
        })
    }

    fn build(width: u32, height: u32, timed: bool, assets: Option<&Path>, more: impl FnOnce(&mut App)) -> Result<Self, HeadlessError> {
        use bevy::render::settings::{RenderCreation, WgpuSettings};
        let adapter = probe_adapter()?;
        let features = if timed { adapter.queries } else { wgpu::Features::empty() };
        let render_creation = RenderCreation::Automatic(Box::new(WgpuSettings { features, ..default() }));
        let mut app = App::new();
        let plugins = DefaultPlugins
            .set(WindowPlugin { primary_window: None, exit_condition: ExitCondition::DontExit, ..default() })
            .set(RenderPlugin { render_creation, synchronous_pipeline_compilation: true, ..default() })
            .set(AssetPlugin { file_path: assets.map_or_else(|| AssetPlugin::default().file_path, |root| root.to_string_lossy().into_owned()), ..default() })
            .disable::<WinitPlugin>()
            // Each update renders the frame it extracted, and the render world stays
            // in the app where tests can read the GPU's buffers.
            .disable::<bevy::render::pipelined_rendering::PipelinedRenderingPlugin>();
        // One logger a process: a second renderer (the bench makes many) logs through it.
        if bevy::log::tracing::dispatcher::has_been_set() {
            app.add_plugins(plugins.disable::<bevy::log::LogPlugin>());
        } else {
            app.add_plugins(plugins);
        }
        app.add_plugins(CausticsPlugin);
        app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(std::time::Duration::from_secs_f64(1.0 / 60.0)));
        if timed {
            app.add_plugins(bevy::render::diagnostic::RenderDiagnosticsPlugin);
        }
        more(&mut app);
        app.finish();
        app.cleanup();
        let mut image = Image::new_target_texture(width, height, TextureFormat::Rgba16Float, None);
        image.texture_descriptor.usage |= TextureUsages::COPY_SRC | TextureUsages::TEXTURE_BINDING;
        let target = app.world_mut().resource_mut::<Assets<Image>>().add(image);
        Ok(Self { app, adapter, target, width, height })
    }

    /// Every pass's GPU time and shader invocations in the newest frame whose
    /// diagnostics have arrived (a frame or two behind), by span (`caustics/volumes`,
    /// `caustic_maps/gather`, Bevy's own `main_opaque_pass_3d`…). Empty unless built
    /// [`Self::timed`] on an adapter with timestamp or pipeline-statistics queries.
    pub fn gpu_pass_work(&self) -> Vec<crate::gpu_work::PassWork> {
        self.app.world().get_resource::<bevy::diagnostic::DiagnosticsStore>().map_or_else(Vec::new, crate::gpu_work::newest_pass_work)
    }

    /// The plugin's CPU time (ms) in the main and in the render world, in the last
    /// frame the diagnostics published ([`crate::CausticCpuTime`]).
    pub fn plugin_cpu_times(&self) -> Option<(f64, f64)> {
        let store = self.app.world().get_resource::<bevy::diagnostic::DiagnosticsStore>()?;
        let last = |path| store.get(path).and_then(|d| d.measurement()).map(|m| m.value);
        Some((last(&crate::CausticCpuTime::MAIN)?, last(&crate::CausticCpuTime::RENDER)?))
    }

    /// The render target to put on the camera.
    pub fn render_target(&self) -> RenderTarget {
        RenderTarget::Image(self.target.clone().into())
    }

    /// The app's world, to spawn a scene into.
    pub fn world_mut(&mut self) -> &mut World {
        self.app.world_mut()
    }

    /// The caustics passes that ran in the last frame rendered.
    pub fn pass_report(&self) -> CausticPassReport {
        self.app.world().resource::<CausticPassReport>().clone()
    }

    /// Runs `frames` updates, then reads back the next frame that reaches the image
    /// (a few more updates: the readback is asynchronous).
    pub fn render(&mut self, frames: u32) -> Result<RenderedImage, HeadlessError> {
        for _ in 0..frames {
            self.app.update();
        }
        let result: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
        let sink = result.clone();
        let reader = self
            .app
            .world_mut()
            .spawn(Readback::texture(self.target.clone()))
            .observe(move |event: On<ReadbackComplete>| {
                if let Ok(mut slot) = sink.lock() {
                    *slot = Some(event.data.clone());
                }
            })
            .id();
        const MAX_EXTRA: u32 = 16;
        for _ in 0..MAX_EXTRA {
            self.app.update();
            let bytes = result.lock().ok().and_then(|mut s| s.take());
            if let Some(bytes) = bytes {
                self.app.world_mut().despawn(reader);
                if let Some(failure) = self.failed_pipeline() {
                    return Err(HeadlessError::Pipeline(failure));
                }
                return Ok(RenderedImage { width: self.width, height: self.height, pixels: decode_rgba16f(&bytes) });
            }
        }
        Err(HeadlessError::NoReadback(MAX_EXTRA))
    }
}

impl HeadlessRenderer {
    /// The caustic irradiance `E` (the light's units per m², lux for Bevy's lights) that
    /// the techniques added to `camera`'s view in the last frame rendered, read back from
    /// the view's caustic irradiance buffer with the camera's exposure divided out: one
    /// RGB value per pixel of the viewport, row-major from the top-left. Zero where the
    /// view had no caustics work.
    pub fn caustic_irradiance(&mut self, camera: Entity) -> Result<Vec<Vec3>, HeadlessError> {
        use crate::irradiance::ViewCausticIrradiance;
        use bevy::render::sync_world::RenderEntity;
        let world = self.app.world();
        let exposure = world.get::<bevy::camera::Exposure>(camera).copied().unwrap_or_default().exposure();
        let render_entity = world.get::<RenderEntity>(camera).ok_or(HeadlessError::NotACamera)?.id();
        let render_world = self.app.sub_app_mut(bevy::render::RenderApp).world_mut();
        let Some(view) = render_world.get::<ViewCausticIrradiance>(render_entity) else {
            return Ok(vec![Vec3::ZERO; (self.width * self.height) as usize]);
        };
        let texture = view.texture.texture.clone();
        let bytes = self.read_texture(&texture)?;
        Ok(decode_rgba16f(&bytes).into_iter().map(|e| e.truncate() / exposure).collect())
    }

    /// A texture of the render world read back: every layer's rows, top first, packed
    /// (without wgpu's row padding), in the texture's own format.
    pub fn read_texture(&mut self, texture: &bevy::render::render_resource::Texture) -> Result<Vec<u8>, HeadlessError> {
        use bevy::render::render_resource::{BufferDescriptor, BufferUsages, CommandEncoderDescriptor, MapMode, PollType};
        use bevy::render::renderer::{RenderDevice, RenderQueue};
        let render_world = self.app.sub_app_mut(bevy::render::RenderApp).world_mut();
        let (width, height, layers) = (texture.width(), texture.height(), texture.depth_or_array_layers());
        let texel = texture.format().block_copy_size(None).ok_or_else(|| HeadlessError::Readback(format!("{:?} cannot be copied", texture.format())))?;
        let (device, queue) = (render_world.resource::<RenderDevice>().clone(), render_world.resource::<RenderQueue>().clone());
        // Rows padded to wgpu's copy alignment.
        let packed = texel * width;
        let row = packed.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let usage = BufferUsages::COPY_DST | BufferUsages::MAP_READ;
        let size = (row * height * layers) as u64;
        let staging = device.create_buffer(&BufferDescriptor { label: Some("headless_texture_readback"), size, usage, mapped_at_creation: false });
        let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(height) },
            },
            texture.size(),
        );
        queue.submit([encoder.finish()]);
        let slice = staging.slice(..);
        let mapped: Arc<Mutex<Option<bool>>> = Arc::default();
        let done = mapped.clone();
        slice.map_async(MapMode::Read, move |result| {
            if let Ok(mut slot) = done.lock() {
                *slot = Some(result.is_ok());
            }
        });
        device.poll(PollType::wait_indefinitely()).map_err(|e| HeadlessError::Readback(e.to_string()))?;
        if mapped.lock().ok().and_then(|s| *s) != Some(true) {
            return Err(HeadlessError::Readback("the texture's readback buffer did not map".into()));
        }
        let bytes = slice.get_mapped_range();
        Ok(unpad_rows(&bytes, packed as usize))
    }

    /// The GPU memory the render device holds now (bytes, by the label its buffer or
    /// texture was made with), from the backend's allocator
    /// (`wgpu::Device::generate_allocator_report`): every live allocation, the plugin's,
    /// Bevy's and the app's. Resources dropped in the render world are freed once the
    /// GPU is done with them, a frame or two later. `None` where the backend keeps no
    /// such report (Metal, GL).
    pub fn gpu_memory(&self) -> Option<std::collections::BTreeMap<String, u64>> {
        let device = self.app.world().get_resource::<bevy::render::renderer::RenderDevice>()?;
        let report = device.wgpu_device().generate_allocator_report()?;
        let mut by_label = std::collections::BTreeMap::new();
        for allocation in report.allocations {
            *by_label.entry(allocation.name).or_default() += allocation.size;
        }
        Some(by_label)
    }

    /// [`failed_pipeline`] of the app's render world.
    pub fn failed_pipeline(&self) -> Option<String> {
        failed_pipeline(self.app.get_sub_app(bevy::render::RenderApp)?.world().get_resource()?)
    }
}

/// The first pipeline whose shader did not compile or whose pipeline was refused, with
/// its label and why: a frame drawn without it is not the frame asked for. A pipeline
/// still waiting for its shader to load has not failed.
pub fn failed_pipeline(cache: &bevy::render::render_resource::PipelineCache) -> Option<String> {
    use bevy::render::render_resource::{CachedPipelineState, PipelineDescriptor};
    use bevy::shader::ShaderCacheError;
    cache.pipelines().find_map(|p| match &p.state {
        CachedPipelineState::Err(ShaderCacheError::ShaderNotLoaded(_) | ShaderCacheError::ShaderImportNotYetAvailable) => None,
        CachedPipelineState::Err(error) => {
            let label = match &p.descriptor {
                PipelineDescriptor::RenderPipelineDescriptor(d) => d.label.clone(),
                PipelineDescriptor::ComputePipelineDescriptor(d) => d.label.clone(),
            };
            Some(format!("{}: {error}", label.as_deref().unwrap_or("unlabelled")))
        }
        _ => None,
    })
}
