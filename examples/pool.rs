//! A tiled pool under the afternoon sun, its caustics by convolution (Trendall &
//! Stewart 2000): click the water to drop a pebble. The ripples (§4.3) bounce off the
//! walls; the floor irradiance is the paper's three convolutions of the refracted
//! sunlight, on the GPU every frame.
//!
//! `cargo run --example pool` opens a window when there is a display; otherwise, or
//! with `--headless`, it drops a few scripted pebbles, renders offscreen and writes a
//! PNG (`--out`, default `target/pool.png`). `--kernel R` sets the kernel radius
//! (`(2R + 1)²` taps), `--depth M` the pool's depth. In a window, a panel of
//! sliders sets the depth, the scattering a and the cosine exponent n (one lobe,
//! n = 2a), the extinction ε and the kernel radius while the water moves.

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy::window::PrimaryWindow;
use bevy_caustics::debug_panel::bevy_egui::EguiPrimaryContextPass;
use bevy_caustics::prelude::*;
use std::time::Duration;

const WIDTH: u32 = 960;
const HEIGHT: u32 = 540;
/// The pool is `SIZE` metres square.
const SIZE: f32 = 4.0;
/// Scripted pebbles for the headless run: frame, position on the water (x, z).
const PEBBLES: [(u32, Vec2); 4] = [(0, Vec2::new(0.8, -0.6)), (4, Vec2::new(-1.1, 0.3)), (8, Vec2::new(0.2, 1.2)), (12, Vec2::new(-0.4, -1.3))];
/// A pebble's wave height at its start (m).
const PEBBLE: f32 = 0.015;
/// Frames rendered headless, 50 ms apart.
const FRAMES: u32 = 30;

fn main() -> AppExit {
    let kernel_radius: u32 = support::option("kernel", 6);
    let depth: f32 = support::option("depth", 1.0);
    let mut app = App::new();
    app.add_plugins((support::plugins("pool", "pool", (WIDTH, HEIGHT), FRAMES), CausticsPlugin))
        .add_systems(Startup, move |world: &mut World| spawn_pool(world, kernel_radius, depth))
        .add_systems(Update, drop_pebble_on_click);
    if support::headless() {
        // Frames 50 ms apart, and pebbles on a script.
        app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(50))).add_systems(Update, drop_scripted_pebbles);
    } else {
        app.add_systems(EguiPrimaryContextPass, pool_sliders);
    }
    app.run()
}

/// The tiled pool, its water under the afternoon sun, and a camera above it.
fn spawn_pool(world: &mut World, kernel_radius: u32, depth: f32) {
    let tiles = support::tiles();
    let floor = support::textured_floor(world, tiles.clone(), bevy::math::Affine2::from_scale(Vec2::splat(8.0)), SIZE / 2.0, 0.9);
    world.entity_mut(floor).insert(Transform::from_xyz(0.0, -depth, 0.0));
    spawn_walls(world, tiles, depth);
    let water = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(0.55, 0.8, 0.9, 0.25),
        alpha_mode: AlphaMode::Blend,
        perceptual_roughness: 0.05,
        reflectance: 0.5,
        ..default()
    });
    world.spawn((
        // A narrow forward-scattering lobe (n = 400, about 0.05 rad): clear water.
        PoolRipples { columns: 128, rows: 128, cell_size: SIZE / 128.0, depth, exponent: 400.0, kernel_radius, ..default() },
        CausticGenerator { technique: CausticTechnique::Convolution, ..CausticGenerator::refractive(1.333) },
        MeshMaterial3d(water),
    ));
    // An afternoon sun, 20° off zenith: the lobe is expanded about its refracted
    // direction (the paper's expansion about the vertical holds only a few degrees
    // from overhead; see docs/convolution.md's error tables).
    world.spawn((
        // The water casts the sun's shadow: below it the caustics carry the transmitted light.
        DirectionalLight { illuminance: light_consts::lux::AMBIENT_DAYLIGHT, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::new(0.3, -1.0, -0.2), Vec3::Y),
    ));
    world.spawn((
        Camera3d::default(),
        Caustics::default(),
        // A white floor under the midday sun.
        bevy::camera::Exposure { ev100: 11.0 },
        Transform::from_xyz(0.0, 4.8, 3.4).looking_at(Vec3::new(0.0, -0.8, 0.1), Vec3::Y),
    ));
}

/// The pool's light settings as sliders in the window.
fn pool_sliders(mut contexts: bevy_caustics::debug_panel::bevy_egui::EguiContexts, mut pools: Query<&mut PoolRipples>) -> Result {
    use bevy_caustics::debug_panel::bevy_egui::egui::{Slider, Window};
    let Ok(mut pool) = pools.single_mut() else { return Ok(()) };
    let mut settings = pool.clone();
    Window::new("Pool").show(contexts.ctx_mut()?, |ui| {
        ui.add(Slider::new(&mut settings.depth, 0.1..=4.0).text("depth (m)"));
        // The convolution's cosine lobe cosⁿ stands for the Gaussian exp(−a(1 − cos²)) of
        // eq. 2 with n = 2a: two handles on the one lobe.
        let mut a = settings.exponent / 2.0;
        ui.add(Slider::new(&mut a, 1.0..=5000.0).logarithmic(true).text("scattering a"));
        settings.exponent = 2.0 * a;
        ui.add(Slider::new(&mut settings.exponent, 2.0..=10000.0).logarithmic(true).text("cosine exponent n = 2a"));
        ui.add(Slider::new(&mut settings.extinction, 0.0..=2.0).text("extinction ε (1/m)"));
        ui.add(Slider::new(&mut settings.kernel_radius, 0..=32).text("kernel radius (texels)"));
    });
    pool.set_if_neq(settings);
    Ok(())
}

/// Four tiled walls from the floor to a little above the water.
fn spawn_walls(world: &mut World, tiles: Image, depth: f32) {
    let height = depth + 0.15;
    let texture = world.resource_mut::<Assets<Image>>().add(tiles);
    let material = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color_texture: Some(texture),
        uv_transform: bevy::math::Affine2::from_scale(Vec2::new(8.0, 2.0 * height)),
        perceptual_roughness: 0.9,
        // Both faces cast the sun's shadow: the wall the sun stands behind shades the
        // floor beside it, which the water's shadow does not reach.
        double_sided: true,
        cull_mode: None,
        ..default()
    });
    let wall = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Z, Vec2::new(SIZE / 2.0, height / 2.0)).mesh());
    for turn in 0..4 {
        let rotation = Quat::from_rotation_y(turn as f32 * std::f32::consts::FRAC_PI_2);
        let centre = rotation * Vec3::new(0.0, height / 2.0 - depth, -SIZE / 2.0);
        world.spawn((Mesh3d(wall.clone()), MeshMaterial3d(material.clone()), Transform::from_translation(centre).with_rotation(rotation)));
    }
}

/// Headless: the scripted pebbles, each at its frame.
fn drop_scripted_pebbles(mut frame: Local<u32>, mut pebbles: MessageWriter<DropPebble>) {
    for (_, at) in PEBBLES.iter().filter(|(when, _)| *when == *frame) {
        pebbles.write(DropPebble { position: Vec3::new(at.x, 0.0, at.y), strength: PEBBLE });
    }
    *frame += 1;
}

/// A click on the water drops a pebble where the cursor's ray meets the rest surface.
fn drop_pebble_on_click(
    buttons: Res<ButtonInput<MouseButton>>,
    window: Single<&Window, With<PrimaryWindow>>,
    camera: Single<(&Camera, &GlobalTransform)>,
    mut pebbles: MessageWriter<DropPebble>,
) {
    if !buttons.just_pressed(MouseButton::Left) {
        return;
    }
    if let Some(at) = support::cursor_on_water(&window, *camera) {
        pebbles.write(DropPebble { position: at, strength: PEBBLE });
    }
}
