//! Sunlight through an animated ocean: caustics on a sandy sea floor and light shafts
//! in the water beneath, with slight dispersion (Ernst, Akenine-Möller & Jensen 2005,
//! Fig. 9). The `Ocean` component (Tessendorf's FFT waves) moves the water mesh every
//! frame on the GPU, and the caustic volumes are built on the GPU from the waves of the
//! same frame: the CPU does no per-frame work for either.
//!
//! `cargo run --example ocean` opens a window (or writes `target/ocean.png` without a
//! display; `--headless --out PATH` to force it). `--resolution N` sets the ocean grid
//! (a power of two, default 32), `--wind M/S` the wind speed (default 7) and
//! `--shaft-downsample N` the pixels across each light-shaft sample (1, 2 or 4, default
//! 4; `WarpedVolumesSettings::shaft_downsample`).

#[path = "support/mod.rs"]
mod support;

use bevy::camera::Exposure;
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy_caustics::prelude::*;

/// The water surface's height above the sea floor (m).
const DEPTH: f32 = 3.0;
/// The ocean patch's side (m).
const PATCH: f32 = 12.0;

fn main() -> AppExit {
    let resolution: u32 = support::option("resolution", 32);
    let wind: f32 = support::option("wind", 7.0);
    let shaft_downsample: u32 = support::option("shaft-downsample", WarpedVolumesSettings::default().shaft_downsample);
    App::new()
        .add_plugins((support::plugins("ocean", "ocean", (800, 450), 8), CausticsPlugin))
        .insert_resource(WarpedVolumesSettings { shaft_downsample, ..default() })
        .insert_resource(GlobalAmbientLight { brightness: 600.0, color: Color::srgb(0.5, 0.7, 0.9), ..default() })
        .insert_resource(ClearColor(Color::srgb(0.02, 0.12, 0.18)))
        .add_systems(Startup, move |world: &mut World| spawn_sea(world, resolution, wind))
        .run()
}

/// The sandy floor, the ocean over it under the sun, the water body's medium and a
/// camera under the surface.
fn spawn_sea(world: &mut World, resolution: u32, wind_speed: f32) {
    support::textured_floor(world, support::sand(), bevy::math::Affine2::from_scale(Vec2::splat(6.0)), PATCH / 2.0, 0.95);
    // Seen from below too (no culling), and glowing faintly as the sky seen through it
    // would (Bevy does not refract: this stands in for Snell's window).
    let water = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(0.3, 0.6, 0.7, 0.25),
        emissive: LinearRgba::rgb(0.35, 0.65, 0.8) * 10000.0,
        emissive_exposure_weight: 1.0,
        alpha_mode: AlphaMode::Blend,
        perceptual_roughness: 0.05,
        reflectance: 0.6,
        double_sided: true,
        cull_mode: None,
        ..default()
    });
    // Sea water with Cauchy dispersion n = A + B/λ² (λ in µm): 1.334 in red, 1.340 in
    // green, 1.352 in blue, twice real water's spread so that the coloured fringes show.
    let refract = GeneratorInteraction::Refract { ior: 1.333, dispersion: Some(Vec2::new(1.320, 0.006)) };
    world.spawn((
        Ocean { resolution, size: PATCH, wind_speed, wind_direction: Vec2::new(1.0, 0.4), amplitude: 4e-3, ..default() },
        MeshMaterial3d(water),
        CausticGenerator { interaction: refract, ..CausticGenerator::refractive(1.333) },
        Transform::from_xyz(0.0, DEPTH, 0.0),
    ));
    world.spawn((
        // The water casts the sun's shadow: below it the caustic volumes carry all of
        // the transmitted light, and direct light on the sand would count it twice.
        DirectionalLight { illuminance: 30_000.0, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::new(0.35, -1.0, 0.2), Vec3::Y),
    ));
    // The water body scatters the focused light into shafts.
    world.spawn((
        ParticipatingMedium { scattering: 0.06, absorption: ParticipatingMedium::WATER_ABSORPTION, asymmetry: 0.6 },
        Transform::from_xyz(0.0, DEPTH / 2.0, 0.0).with_scale(Vec3::new(PATCH, DEPTH, PATCH)),
    ));
    world.spawn((
        Camera3d::default(),
        Caustics::default(),
        Exposure { ev100: 12.0 },
        Transform::from_xyz(-4.5, 1.6, 4.5).looking_at(Vec3::new(0.5, 0.4, -0.5), Vec3::Y),
    ));
}
