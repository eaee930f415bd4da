//! The main demo: a rippled pool under the sun, its ripples moving. The caustics on
//! the pool floor are the plugin's warped caustic volumes, rebuilt every frame from
//! the animated water mesh. With `--reference` they come instead from the
//! ground-truth photon tracer (`caustics_core`, still water), evaluated at the surface
//! each pixel sees and handed to the plugin as injected irradiance.
//!
//! `cargo run --example demo` opens a window when there is a display; otherwise, or
//! with `--headless`, it renders offscreen and writes a PNG (`--out`, default
//! `target/demo.png`). `--reference --photons N` sets the tracer's photon count.

#[path = "support/mod.rs"]
mod support;

use bevy::camera::RenderTarget;
use bevy::prelude::*;
use bevy_caustics::caustics_core::{
    estimate::{PhotonList, PhotonMap},
    mesh::TriMesh,
    scenes::{Wave, wave_heightfield, wave_pool},
    tracer::{PhotonTracer, TraceSettings},
};
use bevy_caustics::headless::irradiance_image;
use bevy_caustics::reference::{bevy_mesh, pinhole, view_irradiance};
use bevy_caustics::{CausticGenerator, CausticsSettings, InjectedIrradiance};
use std::process::ExitCode;

const WIDTH: u32 = 960;
const HEIGHT: u32 = 540;
/// Sun illuminance (lux): Bevy's daylight default.
const SUN_LUX: f32 = light_consts::lux::AMBIENT_DAYLIGHT;
const CAMERA_POSITION: Vec3 = Vec3::new(0.0, 3.4, 3.9);
const CAMERA_TARGET: Vec3 = Vec3::new(0.0, 0.0, 0.3);
const FOV_Y: f32 = std::f32::consts::FRAC_PI_4;

fn main() -> ExitCode {
    support::exit_code("demo", run)
}

fn run() -> Result<(), String> {
    let args = support::Args::parse("demo", &["photons"], &["reference"])?;
    let irradiance = if args.has("reference") { Some(trace_caustics(args.number("photons", 4u64 << 20)?)?) } else { None };
    let spawn = move |world: &mut World, target: RenderTarget| spawn_pool(world, target, irradiance.clone());
    support::show(&args, "rippled pool", (WIDTH, HEIGHT), 8, spawn, ripple)
}

/// The view's caustic irradiance (lux), one value per pixel, from the ground-truth tracer.
fn trace_caustics(photons: u64) -> Result<Vec<Vec3>, String> {
    let pool = wave_pool(129, 128);
    let tracer = PhotonTracer::new(&pool.scene).map_err(|e| e.to_string())?;
    let mut list = PhotonList::default();
    let settings = TraceSettings { photons_per_light: photons, ..default() };
    eprintln!("tracing {photons} photons through the water…");
    tracer.trace(&settings, &mut list, &|done, total| {
        if done == total || done % (total / 4).max(1) < 65536 {
            eprintln!("  {:3.0} %", 100.0 * done as f64 / total as f64);
        }
    });
    let map = PhotonMap::new(list.0, 0.02);
    let camera = pinhole(&Transform::from_translation(CAMERA_POSITION).looking_at(CAMERA_TARGET, Vec3::Y), FOV_Y, WIDTH, HEIGHT);
    eprintln!("gathering caustic irradiance for {WIDTH}×{HEIGHT} pixels…");
    // The pool's light has irradiance 1; the sun here has SUN_LUX.
    Ok(view_irradiance(&tracer, &map, &camera).into_iter().map(|e| e * SUN_LUX).collect())
}

/// The water of `shared/reference`'s pool, its waves moved on by `time` seconds.
fn water_surface(time: f32) -> TriMesh {
    let waves = [
        Wave { kx: 8.0, kz: 0.0, amplitude: 0.07, phase: -1.3 * time },
        Wave { kx: 0.0, kz: 9.0, amplitude: 0.05, phase: 0.7 - 1.1 * time },
    ];
    wave_heightfield(129, 4.0, 0.8, &waves)
}

/// The animated generator: the water mesh rewritten in place every frame. The plugin
/// sees the mesh asset change and rebuilds the caustic volumes.
#[derive(Component)]
struct Water;

fn ripple(time: Res<Time>, water: Query<&Mesh3d, With<Water>>, mut meshes: ResMut<Assets<Mesh>>) {
    for mesh in &water {
        if let Some(mut mesh) = meshes.get_mut(&mesh.0) {
            *mesh = bevy_mesh(&water_surface(time.elapsed_secs()));
        }
    }
}

/// The pool; with `injected` irradiance (the tracer's), shown instead of live caustics.
fn spawn_pool(world: &mut World, target: RenderTarget, injected: Option<Vec<Vec3>>) {
    let water = bevy_mesh(&water_surface(0.0));
    let injected = injected.map(|e| world.resource_mut::<Assets<Image>>().add(irradiance_image(WIDTH, HEIGHT, &e)));
    support::textured_floor(world, support::tiles(), bevy::math::Affine2::from_scale(Vec2::splat(16.0)), 8.0, 0.9);
    let water_material = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(0.55, 0.8, 0.9, 0.3),
        alpha_mode: AlphaMode::Blend,
        perceptual_roughness: 0.05,
        reflectance: 0.5,
        ..default()
    });
    let water = world.resource_mut::<Assets<Mesh>>().add(water);
    let mut water = world.spawn((Mesh3d(water), MeshMaterial3d(water_material)));
    if injected.is_none() {
        water.insert((CausticGenerator::refractive(1.333), Water));
    }
    world.spawn((
        DirectionalLight { illuminance: SUN_LUX, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::new(0.3, -1.0, -0.2), Vec3::Y),
    ));
    let mut camera = world.spawn((
        Camera3d::default(),
        // Caustics are added to the linear HDR image, before tonemapping.
        CausticsSettings::default(),
        target,
        Projection::from(PerspectiveProjection { fov: FOV_Y, ..default() }),
        Transform::from_translation(CAMERA_POSITION).looking_at(CAMERA_TARGET, Vec3::Y),
    ));
    if let Some(injected) = injected {
        camera.insert(InjectedIrradiance(injected));
    }
}
