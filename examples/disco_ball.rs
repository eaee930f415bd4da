//! A disco ball in a Cornell-box-like room filled with a thin haze: every flat mirror
//! facet throws a spot on the walls and a beam through the haze — volumetric caustics
//! (Ernst, Akenine-Möller & Jensen 2005, Fig. 10). The ball turns.
//!
//! `cargo run --example disco_ball` opens a window (or writes `target/disco_ball.png`
//! without a display; `--headless --out PATH` to force it). `--facets N` sets the
//! facets around the equator (default 24).

#[path = "support/mod.rs"]
mod support;

use bevy::camera::Exposure;
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy_caustics::caustics_core::{glam, mesh::TriMesh};
use bevy_caustics::prelude::*;
use bevy_caustics::read_scene::bevy_mesh;
use std::f32::consts::{PI, TAU};

/// The room: 4 m wide, deep and high, open at the front (+z).
const ROOM: f32 = 4.0;
const BALL_CENTER: Vec3 = Vec3::new(0.0, 2.6, 0.0);

fn main() -> AppExit {
    let facets: usize = support::option("facets", 24);
    App::new()
        .add_plugins((support::plugins("disco_ball", "disco ball", (640, 480), 6), CausticsPlugin))
        .add_systems(Startup, move |world: &mut World| spawn_room(world, facets))
        .add_systems(Update, turn)
        .run()
}

#[derive(Component)]
struct Ball;

fn turn(time: Res<Time>, mut balls: Query<&mut Transform, With<Ball>>) {
    for mut t in &mut balls {
        t.rotation = Quat::from_rotation_y(0.3 * time.elapsed_secs());
    }
}

/// A sphere of flat mirror facets: quads of `segments` around and `segments / 2` from
/// pole to pole, each with its own vertices and its face normal (the paper's disco
/// ball: "each quadrilateral uses the normal of the quadrilateral"). A quad between
/// two latitudes is planar; its normal is the cross product of its diagonals. At the
/// poles the quad is a triangle.
fn faceted_sphere(radius: f32, segments: usize) -> TriMesh {
    let rings = (segments / 2).max(2);
    let point = |ring: usize, seg: usize| {
        let theta = PI * ring as f32 / rings as f32;
        let phi = TAU * seg as f32 / segments as f32;
        radius * glam::Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin())
    };
    let (mut positions, mut normals, mut triangles) = (Vec::new(), Vec::new(), Vec::new());
    for ring in 0..rings {
        for seg in 0..segments {
            let quad = [point(ring, seg), point(ring, seg + 1), point(ring + 1, seg + 1), point(ring + 1, seg)];
            let normal = (quad[2] - quad[0]).cross(quad[3] - quad[1]).normalize();
            debug_assert!(normal.dot(quad[0] + quad[2]) > 0.0, "facet normals face out");
            let base = positions.len() as u32;
            positions.extend(quad);
            normals.extend([normal; 4]);
            // Counter-clockwise seen from outside, leaving out the poles' empty triangles.
            if ring != 0 {
                triangles.push([base, base + 1, base + 2]);
            }
            if ring + 1 != rings {
                triangles.push([base, base + 2, base + 3]);
            }
        }
    }
    TriMesh::new(positions, normals, triangles).expect("facet normals are never zero")
}

fn spawn_room(world: &mut World, facets: usize) {
    world.insert_resource(GlobalAmbientLight { brightness: 40.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    let wall = |m: &mut Assets<StandardMaterial>, c: Color| m.add(StandardMaterial { base_color: c, perceptual_roughness: 0.9, ..default() });
    let white = wall(&mut materials, Color::srgb(0.8, 0.8, 0.78));
    let red = wall(&mut materials, Color::srgb(0.7, 0.12, 0.1));
    let green = wall(&mut materials, Color::srgb(0.12, 0.55, 0.15));
    let mirror = materials.add(StandardMaterial { metallic: 1.0, perceptual_roughness: 0.05, ..default() });
    let mut meshes = world.resource_mut::<Assets<Mesh>>();
    let panel = meshes.add(Plane3d::new(Vec3::Y, Vec2::splat(ROOM / 2.0)).mesh());
    let ball = meshes.add(bevy_mesh(&faceted_sphere(0.35, facets)));
    let h = ROOM / 2.0;
    // Floor, ceiling, back, left, right: planes facing into the room.
    for (material, transform) in [
        (white.clone(), Transform::IDENTITY),
        (white.clone(), Transform::from_xyz(0.0, ROOM, 0.0).with_rotation(Quat::from_rotation_x(PI))),
        (white, Transform::from_xyz(0.0, h, -h).with_rotation(Quat::from_rotation_x(PI / 2.0))),
        (red, Transform::from_xyz(-h, h, 0.0).with_rotation(Quat::from_rotation_z(-PI / 2.0))),
        (green, Transform::from_xyz(h, h, 0.0).with_rotation(Quat::from_rotation_z(PI / 2.0))),
    ] {
        world.spawn((Mesh3d(panel.clone()), MeshMaterial3d(material), transform, CausticReceiver));
    }
    world.spawn((Mesh3d(ball), MeshMaterial3d(mirror), Transform::from_translation(BALL_CENTER), CausticGenerator::mirror(), Ball));
    // A spot from the front corner aims at the ball; its cone (0.15 rad) stays inside
    // the ball's outline (0.152 rad from there), so no direct light spills past it.
    let spot = Vec3::new(1.2, 3.4, 1.8);
    world.spawn((
        SpotLight { intensity: 400_000.0, range: 20.0, outer_angle: 0.15, inner_angle: 0.1, shadow_maps_enabled: true, ..default() },
        Transform::from_translation(spot).looking_at(BALL_CENTER, Vec3::Y),
    ));
    // A thin haze fills the room: the facets' beams show in it.
    world.spawn((
        ParticipatingMedium { scattering: 0.08, absorption: Vec3::splat(0.01), asymmetry: 0.3 },
        Transform::from_xyz(0.0, h, 0.0).with_scale(Vec3::splat(ROOM)),
    ));
    world.spawn((
        Camera3d::default(),
        Caustics::default(),
        Exposure { ev100: 9.0 },
        Projection::from(PerspectiveProjection { fov: 1.0, ..default() }),
        Transform::from_xyz(0.0, 2.0, 6.2).looking_at(Vec3::new(0.0, 2.0, 0.0), Vec3::Y),
    ));
}
