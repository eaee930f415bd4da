//! What the examples share: the plugins that open a window, or write a PNG without
//! one for CI ([`plugins`]), their command-line options, and a few procedural textures.
//! Included by each example with `#[path = "support/mod.rs"]`; each uses a part of it.
#![allow(dead_code)]

use bevy::app::{PluginGroupBuilder, ScheduleRunnerPlugin};
use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
use bevy::math::Affine2;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, PipelineCache, TextureDimension, TextureFormat, TextureUsages};
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured, save_to_disk};
use bevy::render::{Render, RenderApp, RenderPlugin, RenderSystems};
use bevy::time::TimeUpdateStrategy;
use bevy::window::{ExitCondition, WindowResolution};
use bevy::winit::WinitPlugin;
use bevy_caustics::CausticPassReport;
use bevy_caustics::headless::failed_pipeline;
use bevy_caustics::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Whether the example runs without a window: `--headless`, or no display to open one on.
pub fn headless() -> bool {
    let has_display = ["DISPLAY", "WAYLAND_DISPLAY"].iter().any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()));
    flag("headless") || !has_display
}

/// Whether `--name` is on the command line.
pub fn flag(name: &str) -> bool {
    std::env::args().any(|a| a.strip_prefix("--") == Some(name))
}

/// The value after `--name` on the command line, or `default`; a value that does not
/// parse ends the example with a message.
pub fn option<T: std::str::FromStr>(name: &str, default: T) -> T {
    let args: Vec<String> = std::env::args().collect();
    let Some(at) = args.iter().position(|a| a.strip_prefix("--") == Some(name)) else { return default };
    match args.get(at + 1).map(|v| v.parse()) {
        Some(Ok(value)) => value,
        _ => {
            eprintln!("--{name} needs a value of the right kind");
            std::process::exit(2);
        }
    }
}

/// Where a headless run writes its PNG: `--out PATH`, or `target/NAME.png`.
pub fn out_path(name: &str) -> PathBuf {
    option("out", PathBuf::from(format!("target/{name}.png")))
}

/// Bevy's default plugins for an example: a window titled `title`, `width × height`,
/// with the "Caustics" panel; or, headless ([`headless`]), no window, every camera
/// drawing into an image, and the frame after `frames` updates (or, with `frames` 0,
/// the frame in which the app sends [`Shoot`]) written to [`out_path`] before the app
/// exits (with an error if a pipeline failed to build). With `frames` > 0,
/// `--sequence N` writes that frame and the `N − 1` after it instead, as
/// `<out stem>-000.png`, …
pub fn plugins(name: &'static str, title: &str, (width, height): (u32, u32), frames: u32) -> PluginGroupBuilder {
    if !headless() {
        let window =
            Window {
                title: format!("bevy_caustics — {title}"), resolution: WindowResolution::new(width, height).with_scale_factor_override(1.0), ..default()
            };
        return DefaultPlugins.set(WindowPlugin { primary_window: Some(window), ..default() }).add(bevy_caustics::debug_panel::CausticsDebugPanelPlugin);
    }
    DefaultPlugins
        .set(WindowPlugin { primary_window: None, exit_condition: ExitCondition::DontExit, ..default() })
        .set(RenderPlugin { synchronous_pipeline_compilation: true, ..default() })
        .disable::<WinitPlugin>()
        .disable::<bevy::render::pipelined_rendering::PipelinedRenderingPlugin>()
        // Without winit's loop, Bevy's own runs the frames.
        .add(ScheduleRunnerPlugin::run_loop(Duration::ZERO))
        // A sequence follows a fixed number of frames; a shot on `Shoot` is one picture.
        .add(HeadlessShot { out: out_path(name), size: UVec2::new(width, height), frames, sequence: if frames == 0 { 0 } else { option("sequence", 0) } })
}

/// Headless, with no fixed number of frames: take the picture now.
#[derive(Message, Clone, Copy)]
pub struct Shoot;

/// Headless: draws every camera into an image, writes the frame after `frames`
/// updates (time advancing 1/60 s each) to `out` (or `sequence` frames from there),
/// prints the caustics passes that ran and each generator's technique, and exits.
struct HeadlessShot {
    out: PathBuf,
    size: UVec2,
    frames: u32,
    sequence: u32,
}

/// The image the cameras draw into, where to write it, after how many updates, how
/// many frames (0: one, at `out` itself; always 0 with no fixed number of updates),
/// the frames written so far, and a pipeline that failed to build.
#[derive(Resource, Clone)]
struct Shot {
    image: Handle<Image>,
    out: PathBuf,
    frames: u32,
    sequence: u32,
    written: Arc<AtomicU32>,
    failed: Arc<Mutex<Option<String>>>,
}

impl Plugin for HeadlessShot {
    fn build(&self, app: &mut App) {
        app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(1.0 / 60.0)))
            .add_message::<Shoot>()
            .add_systems(PostStartup, draw_into_image)
            .add_systems(Last, take_shot);
    }

    fn finish(&self, app: &mut App) {
        let mut image = Image::new_target_texture(self.size.x, self.size.y, TextureFormat::Rgba8UnormSrgb, None);
        image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
        let image = app.world_mut().resource_mut::<Assets<Image>>().add(image);
        let failed = Arc::<Mutex<Option<String>>>::default();
        let (out, frames, sequence) = (self.out.clone(), self.frames, self.sequence);
        app.insert_resource(Shot { image, out, frames, sequence, written: Arc::default(), failed: failed.clone() });
        if let Some(render) = app.get_sub_app_mut(RenderApp) {
            // A pipeline that failed to build (a WGSL error, say), noted each frame.
            let note = move |cache: Res<PipelineCache>| {
                if let Ok(mut failed) = failed.lock() {
                    *failed = failed_pipeline(&cache);
                }
            };
            render.add_systems(Render, note.in_set(RenderSystems::Cleanup));
        }
    }
}

/// Every camera draws into the shot's image.
fn draw_into_image(mut commands: Commands, cameras: Query<Entity, With<Camera>>, shot: Res<Shot>) {
    for camera in &cameras {
        commands.entity(camera).insert(RenderTarget::Image(shot.image.clone().into()));
    }
}

/// After `frames` updates, or on [`Shoot`]: a screenshot of the image, written to disk
/// (or the next `sequence` frames), then the exit.
fn take_shot(
    mut commands: Commands,
    mut updates: Local<u32>,
    mut shoot: MessageReader<Shoot>,
    shot: Res<Shot>,
    report: Res<CausticPassReport>,
    mut exit: MessageWriter<AppExit>,
) {
    *updates += 1;
    let shoot = shoot.read().count() > 0;
    let shots = shot.sequence.max(1);
    let index = updates.wrapping_sub(shot.frames);
    if !(shot.frames == 0 && shoot || shot.frames > 0 && index < shots) {
        return;
    }
    if let Some(failed) = shot.failed.lock().ok().and_then(|f| f.clone()) {
        eprintln!("a pipeline failed to build: {failed}");
        exit.write(AppExit::error());
        return;
    }
    if index == 0 || shot.frames == 0 {
        for (entity, choice) in &report.generators {
            eprintln!("generator {entity}: {choice}");
        }
        let passes: Vec<String> = report.passes.iter().map(|(pass, views)| format!("{pass} ({views} views)")).collect();
        eprintln!("caustics passes in the last frame: {}", if passes.is_empty() { "none".to_string() } else { passes.join(", ") });
    }
    if let Some(dir) = shot.out.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let out = if shot.sequence == 0 {
        shot.out.clone()
    } else {
        let stem = shot.out.file_stem().unwrap_or_default().to_string_lossy();
        shot.out.with_file_name(format!("{stem}-{index:03}.png"))
    };
    let written = shot.written.clone();
    commands.spawn(Screenshot::image(shot.image.clone())).observe(save_to_disk(out.clone())).observe(
        move |_: On<ScreenshotCaptured>, mut exit: MessageWriter<AppExit>| {
            eprintln!("wrote {}", out.display());
            if written.fetch_add(1, Ordering::Relaxed) + 1 == shots {
                exit.write(AppExit::Success);
            }
        },
    );
}

/// Where the cursor's ray meets the water's rest level `y = 0` (the pool examples'
/// pebbles and touches).
pub fn cursor_on_water(window: &Window, (camera, transform): (&Camera, &GlobalTransform)) -> Option<Vec3> {
    let ray = window.cursor_position().and_then(|cursor| camera.viewport_to_world(transform, cursor).ok())?;
    ray.intersect_plane(Vec3::ZERO, InfinitePlane3d::new(Vec3::Y)).map(|d| ray.get_point(d))
}

/// An sRGB texture of `size`² texels from a colour function of (u, v) ∈ [0, 1)², repeating.
pub fn texture(size: u32, color: impl Fn(f32, f32) -> [u8; 3]) -> Image {
    let data = (0..size * size)
        .flat_map(|i| {
            let [r, g, b] = color((i % size) as f32 / size as f32, (i / size) as f32 / size as f32);
            [r, g, b, 255]
        })
        .collect();
    let mut image = Image::new(
        Extent3d { width: size, height: size, depth_or_array_layers: 1 },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        ..ImageSamplerDescriptor::linear()
    });
    image
}

/// A floor at y = 0 facing up, `half_size` from the origin each way, showing `texture`
/// (`uv` maps the plane's UVs into it, repeating) and the caustics that land on it.
pub fn textured_floor(world: &mut World, texture: Image, uv: Affine2, half_size: f32, roughness: f32) -> Entity {
    let texture = world.resource_mut::<Assets<Image>>().add(texture);
    let material = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color_texture: Some(texture),
        uv_transform: uv,
        perceptual_roughness: roughness,
        ..default()
    });
    let mesh = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(half_size)).mesh());
    world.spawn((Mesh3d(mesh), MeshMaterial3d(material), CausticReceiver)).id()
}

/// Light cyan pool tiles with dark grout.
pub fn tiles() -> Image {
    texture(64, |u, v| if u < 3.0 / 64.0 || v < 3.0 / 64.0 { [70, 90, 100] } else { [190, 225, 230] })
}

/// Wood: warm planks with rings of grain.
pub fn wood() -> Image {
    texture(256, |u, v| {
        let plank = (v * 4.0).floor();
        let grain = ((u * 6.0 + plank * 1.7 + (v * 40.0 + plank).sin() * 0.15) * std::f32::consts::TAU).sin();
        let t = 0.5 + 0.5 * grain;
        let seam = if (v * 4.0).fract() < 0.02 { 0.6 } else { 1.0 };
        let c = |a: f32, b: f32| ((a + (b - a) * t) * seam) as u8;
        [c(150.0, 110.0), c(98.0, 68.0), c(58.0, 38.0)]
    })
}

/// Sand: pale, with a fine grain of hashed speckles (no pattern to repeat across a tile).
pub fn sand() -> Image {
    texture(128, |u, v| {
        let (x, y) = ((u * 128.0) as u32, (v * 128.0) as u32);
        let hash = (x.wrapping_mul(0x9E37_79B9) ^ y.wrapping_mul(0x85EB_CA6B)).wrapping_mul(0xC2B2_AE35);
        let grain = (hash >> 24) as f32 / 255.0 * 22.0;
        [(190.0 + grain) as u8, (172.0 + grain) as u8, (128.0 + grain * 0.6) as u8]
    })
}

/// A sky to reflect in metal (blue above, a pale horizon, brown ground), for a camera:
/// without one, a polished metal shows only the sun's highlight and reads as grey paint.
pub fn sky(images: &mut Assets<Image>, intensity: f32) -> bevy::light::EnvironmentMapLight {
    let (top, horizon, ground) = (Color::srgb(0.35, 0.55, 0.9), Color::srgb(0.85, 0.85, 0.8), Color::srgb(0.3, 0.22, 0.15));
    bevy::light::EnvironmentMapLight { intensity, ..bevy::light::EnvironmentMapLight::hemispherical_gradient(images, top, horizon, ground) }
}
