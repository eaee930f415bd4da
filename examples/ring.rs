//! A polished metal ring on a wooden floor under a low sun: the cardioid caustic of
//! Ernst, Akenine-Möller & Jensen 2005, Fig. 1, drawn by warped caustic volumes.
//!
//! `cargo run --example ring` opens a window (or writes `target/ring.png` without a
//! display; `--headless --out PATH` to force it). `--segments N` sets the ring's
//! tessellation (default 64), `--constant` switches to constant intensity per caustic
//! triangle (the paper's comparison).

#[path = "support/mod.rs"]
mod support;

use bevy::camera::Exposure;
use bevy::light::GlobalAmbientLight;
use bevy::math::Affine2;
use bevy::prelude::*;
use bevy_caustics::caustics_core::{glam, mesh::TriMesh};
use bevy_caustics::prelude::*;
use bevy_caustics::read_scene::bevy_mesh;

/// The sun: low, so that the ring's far wall focuses it into the cardioid.
const SUN_LUX: f32 = 20_000.0;
const SUN_DIRECTION: Vec3 = Vec3::new(1.0, -0.45, 0.0);

fn main() -> AppExit {
    let segments: usize = support::option("segments", 64);
    let intensity = if support::flag("constant") { VolumeIntensity::Constant } else { VolumeIntensity::Conserving };
    App::new()
        .add_plugins((support::plugins("ring", "ring", (800, 500), 6), CausticsPlugin))
        .insert_resource(WarpedVolumesSettings { intensity, ..default() })
        .insert_resource(GlobalAmbientLight { brightness: 300.0, ..default() })
        .insert_resource(ClearColor(Color::srgb(0.05, 0.05, 0.06)))
        .add_systems(Startup, move |world: &mut World| ring(world, segments))
        .add_systems(Startup, camera)
        .run()
}

/// A solid metal ring of `segments` around on a wooden floor, under the sun; drawn by
/// warped volumes (`Auto` would pick the caustic maps for a mirror).
fn ring(world: &mut World, segments: usize) {
    // Planks 0.75 m wide, their seams off the ring's axis of symmetry (z = 0).
    let planks = Affine2::from_scale_angle_translation(Vec2::splat(2.0), 0.0, Vec2::new(0.0, 0.125));
    support::textured_floor(world, support::wood(), planks, 3.0, 0.8);
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
    world.spawn((DirectionalLight { illuminance: SUN_LUX, shadow_maps_enabled: true, ..default() }, Transform::default().looking_to(SUN_DIRECTION, Vec3::Y)));
}

/// Looking down at the ring, the sun behind it, with a sky for the metal to reflect.
fn camera(mut commands: Commands, mut images: ResMut<Assets<Image>>) {
    commands.spawn((
        support::sky(&mut images, 1000.0),
        Camera3d::default(),
        Caustics::default(),
        Exposure { ev100: 12.0 },
        Transform::from_xyz(-0.6, 2.6, 2.4).looking_at(Vec3::new(0.1, 0.0, 0.0), Vec3::Y),
    ));
}
