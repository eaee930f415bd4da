//! What every example shares: its command line, the window-or-PNG runner and a few
//! procedural textures. Included by each example with `#[path = "support/mod.rs"]`;
//! each uses a part of it.
#![allow(dead_code)]

use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
use bevy::light::GlobalAmbientLight;
use bevy::math::Affine2;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy::window::WindowResolution;
use bevy_caustics::caustics_core::{glam, mesh::TriMesh};
use bevy_caustics::prelude::*;
use bevy_caustics::reference::bevy_mesh;
use bevy_caustics::headless::HeadlessRenderer;
use std::path::PathBuf;
use std::process::ExitCode;

/// The options every example takes, and its own ones by name.
pub struct Args {
    pub headless: bool,
    pub out: PathBuf,
    /// `--name value` pairs the example reads with [`Args::number`].
    pub extra: Vec<(String, String)>,
    /// The example's own switches given (`--name`, no value).
    pub switches: Vec<String>,
}

impl Args {
    /// Parses `--headless`, `--out PATH`, the example's own `--name value` options
    /// (`options`) and `--name` switches (`switches`). Without a display the example
    /// runs headless.
    pub fn parse(name: &str, options: &[&str], switches: &[&str]) -> Result<Self, String> {
        let mut args = Args {
            headless: false,
            out: PathBuf::from(format!("target/{name}.png")),
            extra: Vec::new(),
            switches: Vec::new(),
        };
        let mut it = std::env::args().skip(1);
        while let Some(arg) = it.next() {
            let bare = arg.trim_start_matches("--");
            match arg.as_str() {
                "--headless" => args.headless = true,
                "--out" => args.out = it.next().ok_or("--out needs a path")?.into(),
                _ if arg.starts_with("--") && options.contains(&bare) => {
                    let value = it.next().ok_or(format!("{arg} needs a value"))?;
                    args.extra.push((bare.to_string(), value));
                }
                _ if arg.starts_with("--") && switches.contains(&bare) => args.switches.push(bare.to_string()),
                other => {
                    let own: Vec<String> = options.iter().map(|k| format!("--{k} N")).chain(switches.iter().map(|k| format!("--{k}"))).collect();
                    return Err(format!("unknown argument {other:?} (use --headless, --out PATH {})", own.join(" ")));
                }
            }
        }
        let has_display = ["DISPLAY", "WAYLAND_DISPLAY"].iter().any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()));
        args.headless |= !has_display;
        Ok(args)
    }

    /// Whether the switch `--name` was given.
    pub fn has(&self, name: &str) -> bool {
        self.switches.iter().any(|s| s == name)
    }

    /// The value of `--name`, or `default`.
    pub fn number<T: std::str::FromStr>(&self, name: &str, default: T) -> Result<T, String> {
        match self.extra.iter().rev().find(|(k, _)| k == name) {
            Some((_, v)) => v.parse().map_err(|_| format!("--{name} needs a number, not {v:?}")),
            None => Ok(default),
        }
    }
}

/// Runs `main`, printing its error on one line and exiting non-zero on failure.
pub fn exit_code(name: &str, main: impl FnOnce() -> Result<(), String>) -> ExitCode {
    match main() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{name}: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Shows the scene `spawn` builds: in a window (with `animate` running every frame),
/// or headless, `frames` updates rendered offscreen and written to `args.out`.
pub fn show<M>(
    args: &Args,
    title: &str,
    (width, height): (u32, u32),
    frames: u32,
    spawn: impl Fn(&mut World, RenderTarget) + Send + Sync + 'static,
    animate: impl IntoScheduleConfigs<bevy::ecs::system::ScheduleSystem, M>,
) -> Result<(), String> {
    if args.headless {
        let mut renderer = HeadlessRenderer::new(width, height).map_err(|e| e.to_string())?;
        let target = renderer.render_target();
        spawn(renderer.world_mut(), target);
        let image = renderer.render(frames).map_err(|e| e.to_string())?;
        let report = renderer.pass_report();
        for (entity, choice) in &report.generators {
            eprintln!("generator {entity}: {choice}");
        }
        let passes: Vec<String> = report.passes.iter().map(|(pass, views)| format!("{pass} ({views} views)")).collect();
        eprintln!("caustics passes in the last frame: {}", if passes.is_empty() { "none".to_string() } else { passes.join(", ") });
        image.save_png(&args.out, 1.0).map_err(|e| e.to_string())?;
        eprintln!("wrote {}", args.out.display());
        return Ok(());
    }
    let mut app = App::new();
    app.add_plugins(DefaultPlugins.set(WindowPlugin {
        primary_window: Some(Window {
            title: format!("bevy_caustics — {title}"),
            resolution: WindowResolution::new(width, height).with_scale_factor_override(1.0),
            ..default()
        }),
        ..default()
    }))
    .add_plugins((CausticsPlugin, bevy_caustics::debug_panel::CausticsDebugPanelPlugin));
    app.add_systems(Startup, move |world: &mut World| spawn(world, RenderTarget::default()))
        .add_systems(Update, animate);
    app.run();
    Ok(())
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
pub fn sky(world: &mut World, intensity: f32) -> bevy::light::EnvironmentMapLight {
    let mut images = world.resource_mut::<Assets<Image>>();
    let (top, horizon, ground) = (Color::srgb(0.35, 0.55, 0.9), Color::srgb(0.85, 0.85, 0.8), Color::srgb(0.3, 0.22, 0.15));
    bevy::light::EnvironmentMapLight { intensity, ..bevy::light::EnvironmentMapLight::hemispherical_gradient(&mut images, top, horizon, ground) }
}

/// The sun of the ring scene: low, so that the ring's far wall focuses it into the cardioid.
const RING_SUN_LUX: f32 = 20_000.0;
const RING_SUN_DIRECTION: Vec3 = Vec3::new(1.0, -0.45, 0.0);

/// Ernst et al.'s Fig. 1: a solid metal ring of `segments` around on a wooden floor,
/// under a low sun (the `ring` and `volumes_compare` examples), drawn by warped volumes
/// (`Auto` would pick the caustic maps for a mirror).
pub fn ring_scene(world: &mut World, segments: usize, intensity: VolumeIntensity) {
    world.insert_resource(WarpedVolumesSettings { intensity, ..default() });
    world.insert_resource(GlobalAmbientLight { brightness: 300.0, ..default() });
    world.insert_resource(ClearColor(Color::srgb(0.05, 0.05, 0.06)));
    // Planks 0.75 m wide, their seams off the ring's axis of symmetry (z = 0).
    let planks = Affine2::from_scale_angle_translation(Vec2::splat(2.0), 0.0, Vec2::new(0.0, 0.125));
    textured_floor(world, wood(), planks, 3.0, 0.8);
    let metal = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgb(0.95, 0.93, 0.88),
        metallic: 1.0,
        perceptual_roughness: 0.08,
        ..default()
    });
    let ring = bevy_mesh(&TriMesh::solid_ring(glam::Vec3::ZERO, 1.0, 1.05, 0.3, segments));
    let ring = world.resource_mut::<Assets<Mesh>>().add(ring);
    let mirror = CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::mirror() };
    world.spawn((Mesh3d(ring), MeshMaterial3d(metal), mirror));
    world.spawn((
        DirectionalLight { illuminance: RING_SUN_LUX, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(RING_SUN_DIRECTION, Vec3::Y),
    ));
}
