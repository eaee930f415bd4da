//! The smallest game with caustics: a wavy glass sheet over a floor under the sun.
//! `cargo run --example basic` opens a window.

use bevy::prelude::*;
use bevy_caustics::prelude::*;

fn main() {
    App::new().add_plugins((DefaultPlugins, CausticsPlugin)).add_systems(Startup, setup).run();
}

fn setup(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>, mut materials: ResMut<Assets<StandardMaterial>>) {
    // A floor that shows the caustic light landing on it.
    commands.spawn((Mesh3d(meshes.add(Plane3d::default().mesh().size(4.0, 4.0))), MeshMaterial3d(materials.add(Color::srgb(0.8, 0.75, 0.6))), CausticReceiver));
    // A gently curved sheet of glass 1 m up that refracts the sun (IOR 1.5).
    let mut sheet = Plane3d::default().mesh().size(2.0, 2.0).subdivisions(16).build();
    if let Some(bevy::mesh::VertexAttributeValues::Float32x3(positions)) = sheet.attribute_mut(Mesh::ATTRIBUTE_POSITION) {
        for p in positions.iter_mut() {
            p[1] = 0.05 * (3.0 * p[0]).sin() * (2.0 * p[2]).cos();
        }
    }
    sheet.compute_smooth_normals();
    commands.spawn((
        Mesh3d(meshes.add(sheet)),
        MeshMaterial3d(materials.add(StandardMaterial { base_color: Color::srgba(0.9, 0.95, 1.0, 0.2), alpha_mode: AlphaMode::Blend, ..default() })),
        Transform::from_xyz(0.0, 1.0, 0.0),
        CausticGenerator::refractive(1.5),
    ));
    commands.spawn((
        DirectionalLight { illuminance: 10_000.0, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::new(0.2, -1.0, 0.1), Vec3::Y),
    ));
    // The camera opts in, as for Bevy's Bloom; a camera without it does no caustics work.
    commands.spawn((Camera3d::default(), Caustics::default(), Transform::from_xyz(0.0, 3.0, 3.5).looking_at(Vec3::ZERO, Vec3::Y)));
}
