//! A glass ball over the Stanford bunny under a point light, with caustics and shadows
//! from illumination textures (Iwasaki, Dobashi, Yoshimoto & Nishita, Fig. 1): the
//! ball's light transport table is made once, and every move of the ball or the light
//! only sets the virtual planes up again.
//!
//! `cargo run --example illumination_textures` opens a window (or writes
//! `target/illumination_textures.png` without a display; `--headless --out PATH` to
//! force it). Arrow keys move the ball, W/A/S/D the light, 1–5 pick 1, 2, 4, 8 or 16
//! planes, T cycles the texture size (128² to 1024²). Headless, the ball and the light
//! move for a few steps before the picture is taken, and the run fails if the table was
//! made more than once; `--planes N` and `--texture N` set the settings.

#[path = "support/mod.rs"]
mod support;

use bevy::camera::Exposure;
use bevy::light::GlobalAmbientLight;
use bevy::math::Affine2;
use bevy::prelude::*;
use bevy_caustics::caustics_core::{glam, mesh::TriMesh};
use bevy_caustics::illumination_textures::{IlluminationFrames, LightTransportTables};
use bevy_caustics::prelude::*;
use bevy_caustics::read_scene::bevy_mesh;

/// The glass ball.
#[derive(Component)]
struct Ball;

/// The light.
#[derive(Component)]
struct Lamp;

fn main() -> AppExit {
    let settings = IlluminationTexturesSettings { planes: support::option("planes", 4), texture_size: support::option("texture", 512), ..default() };
    let bunny = TriMesh::from_obj(include_str!("../assets/models/bunny.obj")).expect("assets/models/bunny.obj is a mesh");
    let mut app = App::new();
    // Headless, the picture is taken when the tour below says so (frames: 0).
    app.add_plugins((support::plugins("illumination_textures", "illumination textures", (960, 640), 0), CausticsPlugin))
        .insert_resource(settings)
        .insert_resource(GlobalAmbientLight { brightness: 80.0, ..default() })
        .insert_resource(ClearColor(Color::srgb(0.05, 0.05, 0.06)))
        .add_systems(Startup, move |world: &mut World| spawn_scene(world, &bunny));
    if support::headless() {
        app.add_systems(Update, tour);
    } else {
        app.add_systems(Update, (move_ball_and_light, switch_settings));
    }
    app.run()
}

/// Headless: the planes are set up off the frame. Once they are, the ball and the light
/// move, three times, each time once the planes of the last pose are in; then the
/// picture is taken, and the run fails if the ball's table was made more than once.
#[allow(clippy::too_many_arguments)]
fn tour(
    frames: Res<IlluminationFrames>,
    tables: Res<LightTransportTables>,
    mut ball: Query<&mut Transform, (With<Ball>, Without<Lamp>)>,
    mut lamp: Query<&mut Transform, (With<Lamp>, Without<Ball>)>,
    (mut step, mut seen, mut waited): (Local<u32>, Local<u64>, Local<u32>),
    mut shoot: MessageWriter<support::Shoot>,
    mut exit: MessageWriter<AppExit>,
) {
    if *step > 3 {
        // Two frames to draw the last pose's planes, then the picture.
        *step += 1;
        if *step == 6 {
            shoot.write(support::Shoot);
        }
        return;
    }
    *waited += 1;
    if *waited > 200 {
        eprintln!("the illumination textures were not set up in 200 frames");
        exit.write(AppExit::error());
        return;
    }
    if frames.generation == *seen || frames.frames.is_empty() {
        return;
    }
    (*seen, *waited) = (frames.generation, 0);
    if *step == 3 {
        let made = tables.built + tables.loaded;
        eprintln!("light transport tables: {} built, {} read from the cache, over 4 poses", tables.built, tables.loaded);
        if made != 1 {
            eprintln!("the ball's light transport table was made {made} times, not once");
            exit.write(AppExit::error());
        }
        *step = 4;
        return;
    }
    for mut t in &mut ball {
        t.translation.x += 0.04;
        t.rotate_y(0.4);
    }
    for mut t in &mut lamp {
        t.translation.z -= 0.1 + 0.05 * *step as f32;
    }
    *step += 1;
}

/// Arrow keys move the ball, W/A/S/D the light, 2 m/s.
fn move_ball_and_light(
    keys: Res<ButtonInput<KeyCode>>,
    time: Res<Time>,
    mut ball: Query<&mut Transform, (With<Ball>, Without<Lamp>)>,
    mut lamp: Query<&mut Transform, (With<Lamp>, Without<Ball>)>,
) {
    let step = 0.5 * time.delta_secs();
    let axis = |minus: KeyCode, plus: KeyCode| (keys.pressed(plus) as i32 - keys.pressed(minus) as i32) as f32 * step;
    let ball_move = Vec3::new(axis(KeyCode::ArrowLeft, KeyCode::ArrowRight), 0.0, axis(KeyCode::ArrowUp, KeyCode::ArrowDown));
    let lamp_move = Vec3::new(axis(KeyCode::KeyA, KeyCode::KeyD), 0.0, axis(KeyCode::KeyW, KeyCode::KeyS));
    if ball_move != Vec3::ZERO {
        for mut t in &mut ball {
            t.translation += ball_move;
        }
    }
    if lamp_move != Vec3::ZERO {
        for mut t in &mut lamp {
            t.translation += 2.0 * lamp_move;
        }
    }
}

/// 1–5: 1, 2, 4, 8 or 16 planes; T: the next texture size.
fn switch_settings(keys: Res<ButtonInput<KeyCode>>, mut settings: ResMut<IlluminationTexturesSettings>) {
    let planes =
        [KeyCode::Digit1, KeyCode::Digit2, KeyCode::Digit3, KeyCode::Digit4, KeyCode::Digit5].iter().position(|&k| keys.just_pressed(k)).map(|i| 1 << i);
    if let Some(planes) = planes {
        settings.planes = planes;
        info!("illumination textures: {planes} planes");
    }
    if keys.just_pressed(KeyCode::KeyT) {
        settings.texture_size = if settings.texture_size >= 1024 { 128 } else { 2 * settings.texture_size };
        info!("illumination textures: {}² texels", settings.texture_size);
    }
}

fn spawn_scene(world: &mut World, bunny: &TriMesh) {
    support::textured_floor(world, support::wood(), Affine2::from_scale(Vec2::splat(2.0)), 2.0, 0.85);

    // The bunny, 0.48 m tall, in clay: it receives the ball's caustic and shadow.
    let bunny = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&bunny.transformed(&glam::Affine3A::from_scale(glam::Vec3::splat(0.05)))));
    let clay = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgb(0.62, 0.58, 0.52),
        perceptual_roughness: 0.9,
        ..default()
    });
    world.spawn((Mesh3d(bunny), MeshMaterial3d(clay), CausticReceiver));

    // The glass ball, 0.4 m across, over the bunny's back: its light focuses 0.3 m
    // below its centre, just above the bunny, inside the ball's own shadow.
    let ball = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&TriMesh::uv_sphere(glam::Vec3::ZERO, 0.2, 32, 64)));
    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(0.92, 0.96, 1.0, 0.15),
        alpha_mode: AlphaMode::Blend,
        perceptual_roughness: 0.03,
        reflectance: 0.6,
        ior: 1.5,
        ..default()
    });
    let refracts = CausticGenerator { technique: CausticTechnique::IlluminationTextures, ..CausticGenerator::refractive(1.5) };
    world.spawn((Ball, Mesh3d(ball), MeshMaterial3d(glass), refracts, Transform::from_xyz(0.0, 1.0, 0.0)));

    // A point light above and a little aside (10 W/sr in the core scene: 4π · 10 · 683 lm).
    world.spawn((
        Lamp,
        PointLight { intensity: 4.0 * std::f32::consts::PI * 10.0 * 683.0, range: 20.0, shadow_maps_enabled: true, ..default() },
        Transform::from_xyz(0.3, 4.0, 0.2),
    ));
    world.spawn((
        Camera3d::default(),
        Caustics::default(),
        Exposure { ev100: 8.0 },
        Transform::from_xyz(1.1, 1.2, 1.8).looking_at(Vec3::new(0.0, 0.45, 0.0), Vec3::Y),
    ));
}
