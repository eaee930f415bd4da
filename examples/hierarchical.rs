//! A glass Stanford bunny and a polished metal ring on a stone floor under two lights —
//! a spot from above and a low sun — with caustics from hierarchical caustic maps
//! (Wyman 2008): the bright focus below the bunny, the ring's cardioid, each light's
//! caustics adding up.
//!
//! `cargo run --example hierarchical` opens a window (or writes `target/hierarchical.png`
//! without a display; `--headless --out PATH` to force it). Keys 1 to 4 switch between
//! the flat gather (every photon), the hierarchical gather, the paper's full method
//! (hierarchy, clustering, variable splats; photons through the image-space pair of
//! front and back maps) and the plugin's default, the full method with photons traced
//! through the generators (the light the bunny throws onto the ring); headless,
//! `--flat`, `--hierarchical` or `--image-space` picks one (the default otherwise).
//! `--photons N` sets the photon buffer's side (a power of two, default 1024).

#[path = "support/mod.rs"]
mod support;

use bevy::camera::Exposure;
use bevy::light::GlobalAmbientLight;
use bevy::math::Affine2;
use bevy::prelude::*;
use bevy_caustics::caustics_core::{glam, mesh::TriMesh};
use bevy_caustics::prelude::*;
use bevy_caustics::read_scene::bevy_mesh;

fn main() -> AppExit {
    let photons: u32 = support::option("photons", 1024);
    let preset = if support::flag("flat") {
        HierarchicalMapsSettings::FLAT
    } else if support::flag("hierarchical") {
        HierarchicalMapsSettings::HIERARCHICAL
    } else if support::flag("image-space") {
        HierarchicalMapsSettings::FULL
    } else {
        HierarchicalMapsSettings::TRACED
    };
    let bunny = TriMesh::from_obj(include_str!("../assets/models/bunny.obj")).expect("assets/models/bunny.obj is a mesh");
    App::new()
        .add_plugins((support::plugins("hierarchical", "hierarchical caustic maps", (800, 520), 4), CausticsPlugin))
        .insert_resource(HierarchicalMapsSettings { photon_resolution: photons, ..preset })
        .insert_resource(GlobalAmbientLight { brightness: 60.0, ..default() })
        .insert_resource(ClearColor(Color::srgb(0.04, 0.04, 0.05)))
        .add_systems(Startup, move |world: &mut World| spawn_scene(world, &bunny))
        .add_systems(Update, switch_gather)
        .run()
}

/// Keys 1–4: flat, hierarchical, full (the paper's image-space pair), traced paths.
fn switch_gather(keys: Res<ButtonInput<KeyCode>>, mut settings: ResMut<HierarchicalMapsSettings>) {
    let preset = match keys.get_just_pressed().next() {
        Some(KeyCode::Digit1) => ("flat gather", HierarchicalMapsSettings::FLAT),
        Some(KeyCode::Digit2) => ("hierarchical gather", HierarchicalMapsSettings::HIERARCHICAL),
        Some(KeyCode::Digit3) => ("hierarchy, clustering and variable splats", HierarchicalMapsSettings::FULL),
        Some(KeyCode::Digit4) => ("the full method, photons traced through the generators", HierarchicalMapsSettings::TRACED),
        _ => return,
    };
    info!("caustic maps: {}", preset.0);
    *settings = HierarchicalMapsSettings { photon_resolution: settings.photon_resolution, ..preset.1 };
}

/// A stone floor, the glass bunny and the steel ring on it, a spot above and a low sun,
/// and a camera.
fn spawn_scene(world: &mut World, bunny: &TriMesh) {
    let stone = support::texture(128, |u, v| {
        let (x, y) = ((u * 128.0) as u32, (v * 128.0) as u32);
        let hash = (x.wrapping_mul(0x9E37_79B9) ^ y.wrapping_mul(0x85EB_CA6B)).wrapping_mul(0xC2B2_AE35);
        let slab = if (u * 4.0).fract() < 0.015 || (v * 4.0).fract() < 0.015 { 0.55 } else { 1.0 };
        let g = (120.0 + (hash >> 24) as f32 / 255.0 * 20.0) * slab;
        [g as u8, (g * 0.97) as u8, (g * 0.92) as u8]
    });
    support::textured_floor(world, stone, Affine2::from_scale(Vec2::splat(2.0)), 3.0, 0.9);

    // The bunny, 0.7 m tall, in glass.
    let scale = glam::Affine3A::from_scale_rotation_translation(glam::Vec3::splat(0.07), glam::Quat::from_rotation_y(0.6), glam::Vec3::new(-0.55, 0.0, 0.1));
    let bunny = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&bunny.transformed(&scale)));
    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(0.92, 0.96, 1.0, 0.18),
        alpha_mode: AlphaMode::Blend,
        perceptual_roughness: 0.03,
        reflectance: 0.6,
        ior: 1.5,
        ..default()
    });
    let refracts = CausticGenerator { technique: CausticTechnique::HierarchicalMaps, ..CausticGenerator::refractive(1.5) };
    world.spawn((Mesh3d(bunny), MeshMaterial3d(glass), refracts));

    // A polished steel ring: the low sun's cardioid inside it.
    let ring = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&TriMesh::solid_ring(glam::Vec3::new(0.75, 0.0, -0.2), 0.5, 0.53, 0.18, 128)));
    let metal = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgb(0.95, 0.93, 0.9),
        metallic: 1.0,
        perceptual_roughness: 0.06,
        ..default()
    });
    let reflects = CausticGenerator { technique: CausticTechnique::HierarchicalMaps, ..CausticGenerator::mirror() };
    world.spawn((Mesh3d(ring), MeshMaterial3d(metal), reflects));

    // Two lights: a spot from above on the bunny and a low sun across the ring.
    world.spawn((
        SpotLight { intensity: 4.0e6, range: 30.0, inner_angle: 0.25, outer_angle: 0.4, shadow_maps_enabled: true, ..default() },
        Transform::from_xyz(-1.2, 3.5, 0.6).looking_at(Vec3::new(-0.5, 0.3, 0.1), Vec3::Y),
    ));
    world.spawn((
        DirectionalLight { illuminance: 9000.0, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::new(-1.0, -0.42, 0.3), Vec3::Y),
    ));
    let sky = support::sky(&mut world.resource_mut::<Assets<Image>>(), 400.0);
    world.spawn((
        sky,
        Camera3d::default(),
        Caustics::default(),
        Exposure { ev100: 12.0 },
        Transform::from_xyz(0.2, 2.2, 2.6).looking_at(Vec3::new(0.05, 0.15, 0.0), Vec3::Y),
    ));
}
