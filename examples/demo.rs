//! The main demo: a tiled pool under the sun, with a shelf and steps, a ladder and a
//! glass ball bobbing on the water. Every caustics generator is on
//! `CausticTechnique::Auto`, so the scene is also the proof of the default: the rippling
//! water (a pool) draws with warped caustic volumes, onto the floor, the walls and the
//! steps, with light shafts in the water (a participating medium); the ball (a closed
//! refractor) with hierarchical caustic maps, its light through two interfaces spread
//! around its shadow on the floor. The water is Bevy's `specular_transmission`: the
//! pool is seen through it, caustics included, and the sky is reflected in it.
//!
//! `cargo run --example demo` opens a window when there is a display: drag the mouse on
//! the water to make ripples, arrow keys move the sun, and the "Caustics" panel
//! switches each generator's technique and graphs every pass's GPU time. Without a
//! display, or with `--headless`, it runs 1.2 seconds of the pool offscreen (the ball
//! bobbing, a shower of rain setting the water rippling) and writes the last frame as
//! a PNG (`--out`, default `target/demo.png`); `--frames N` sets how many 50 ms frames,
//! and `--sequence N` writes that frame and the `N − 1` after it (`scripts/animation.sh`).
//!
//! In a corner, a second camera looks from under the water towards the sun. Water
//! scatters light forwards, so the shafts under the ripples show best from there,
//! against the surface; from above they stand in front of their own bright floor.
//!
//! The scene is one plugin, [`Pool`]; `tests/demo_comparison.rs` measures it against
//! the ground-truth tracer, as the panel's "Compare with reference" button does.

#[path = "support/mod.rs"]
mod support;

use bevy::camera::{Exposure, MsaaWriteback, Viewport};
use bevy::light::{EnvironmentMapLight, GlobalAmbientLight};
use bevy::math::Affine2;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy::window::PrimaryWindow;
use bevy_caustics::prelude::*;
use std::f32::consts::{FRAC_PI_2, TAU};
use std::time::Duration;

/// The window's (or the headless image's) size in pixels.
pub const WIDTH: u32 = 960;
pub const HEIGHT: u32 = 540;
/// The pool is `SIZE` metres square and `DEPTH` deep; its walls stand `COPING` above
/// the water.
const SIZE: f32 = 4.0;
const DEPTH: f32 = 1.2;
const COPING: f32 = 0.15;
/// The glass ball's radius (m), where it bobs (x, z), its centre's mean height and how
/// it bobs: amplitude (m) and period (s). At the bottom of each bob it dips 2 cm into
/// the water and starts a ripple; the rest of the time it is clear of the water, which
/// it would otherwise cut through (the water's mesh runs on under it, and light inside
/// the glass would meet it).
const BALL_RADIUS: f32 = 0.3;
const BALL_AT: Vec2 = Vec2::new(0.5, 0.1);
const BALL_HEIGHT: f32 = BALL_RADIUS + 0.06;
const BOB: (f32, f32) = (0.08, 1.2);
/// A touch on the water: the ripple's height at its start (m).
const TOUCH: f32 = 0.02;
/// Rain: a shower of so many drops a second for the first so many seconds sets the
/// whole pool rippling (the caustic web on floor and walls, the shafts under it); then
/// a drizzle of `DRIZZLE` drops a second keeps it alive.
const SHOWER: (f32, f32) = (60.0, 0.8);
const DRIZZLE: f32 = 2.0;
/// Headless: frames rendered 50 ms apart.
pub const FRAMES: u32 = 24;
/// The sun: Bevy's daylight illuminance, from `SUN_AZIMUTH` (radians about +y from +x)
/// and `SUN_ELEVATION` above the horizon.
const SUN_LUX: f32 = light_consts::lux::AMBIENT_DAYLIGHT;
const SUN_AZIMUTH: f32 = 2.8;
const SUN_ELEVATION: f32 = 0.95;
/// The sky's luminance (cd/m²) and the cameras' exposure.
const SKY: f32 = 1500.0;
const EV100: f32 = 11.5;

fn main() -> AppExit {
    let frames: u32 = support::option("frames", FRAMES);
    let mut app = App::new();
    app.add_plugins((support::plugins("demo", "pool", (WIDTH, HEIGHT), frames), CausticsPlugin, Pool)).add_systems(Update, (touch_water, move_sun));
    if support::headless() {
        // Frames 50 ms apart.
        app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(50)));
    }
    app.run()
}

/// The pool with its rippling water and bobbing ball, under the sun, and the view from
/// under its water.
pub struct Pool;

impl Plugin for Pool {
    fn build(&self, app: &mut App) {
        app.add_systems(Startup, spawn_scene).add_systems(Update, (bob_ball, rain, place_underwater_view));
    }
}

/// The pool, and the view from under its water.
fn spawn_scene(world: &mut World) {
    let sky = spawn_pool(world);
    spawn_underwater_view(world, sky);
}

/// The glass ball, bobbing on the water.
#[derive(Component)]
struct Ball;

/// The camera under the water, drawn in the image's bottom right corner.
#[derive(Component)]
pub struct UnderwaterView;

/// The underwater view's share of the image's width, and its margin (pixels).
const INSET: (f32, u32) = (0.4, 8);

/// The sun, moved by the arrow keys.
#[derive(Component)]
struct Sun {
    azimuth: f32,
    elevation: f32,
}

impl Sun {
    fn transform(&self) -> Transform {
        let (sin_e, cos_e) = self.elevation.sin_cos();
        let towards_sun = Vec3::new(cos_e * self.azimuth.cos(), sin_e, cos_e * self.azimuth.sin());
        Transform::default().looking_to(-towards_sun, Vec3::Y)
    }
}

/// The pool, its lights and its main camera; returns the sky, for other cameras.
fn spawn_pool(world: &mut World) -> EnvironmentMapLight {
    world.insert_resource(GlobalAmbientLight { brightness: 800.0, color: Color::srgb(0.75, 0.85, 1.0), ..default() });
    world.insert_resource(ClearColor(Color::srgb(0.45, 0.65, 0.95)));
    let tiles = world.resource_mut::<Assets<Image>>().add(support::tiles());
    // One tile every 25 cm on a surface of `size` metres (each mesh's UVs span [0, 1]²).
    let tiled = |size: Vec2| StandardMaterial {
        base_color_texture: Some(tiles.clone()),
        uv_transform: Affine2::from_scale(size * 4.0),
        perceptual_roughness: 0.8,
        ..default()
    };
    let floor = world.resource_mut::<Assets<StandardMaterial>>().add(tiled(Vec2::splat(SIZE)));
    let plane = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(SIZE / 2.0)).mesh());
    world.spawn((Mesh3d(plane), MeshMaterial3d(floor), Transform::from_xyz(0.0, -DEPTH, 0.0), CausticReceiver));
    spawn_walls(world, &tiled);
    spawn_steps(world, &tiled);
    spawn_deck(world);
    spawn_ladder(world);

    let water = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        specular_transmission: 0.92,
        // How far Bevy's transmission shifts what is seen through the surface; the
        // water's colour is the medium's absorption below.
        thickness: 0.3,
        ior: 1.333,
        perceptual_roughness: 0.04,
        reflectance: 0.5,
        // Seen from under the water too.
        double_sided: true,
        cull_mode: None,
        ..default()
    });
    world.spawn((
        Name::new("water"),
        PoolRipples { columns: 128, rows: 128, cell_size: SIZE / 128.0, depth: DEPTH, ..default() },
        CausticGenerator::refractive(1.333),
        MeshMaterial3d(water),
    ));
    // The water body: it scatters the focused light into shafts, and dims what is seen
    // through it, from above and from the underwater view, red first as water does: the
    // pool turns blue-green with depth.
    world.spawn((
        Name::new("pool water (medium)"),
        ParticipatingMedium { scattering: 0.4, absorption: ParticipatingMedium::WATER_ABSORPTION, asymmetry: 0.6 },
        Transform::from_xyz(0.0, -DEPTH / 2.0, 0.0).with_scale(Vec3::new(SIZE, DEPTH, SIZE)),
    ));

    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgb(0.95, 0.98, 1.0),
        specular_transmission: 0.95,
        thickness: 2.0 * BALL_RADIUS,
        ior: 1.5,
        perceptual_roughness: 0.02,
        reflectance: 0.6,
        ..default()
    });
    let sphere = Sphere::new(BALL_RADIUS).mesh().ico(4).expect("an icosphere of 4 subdivisions");
    let sphere = world.resource_mut::<Assets<Mesh>>().add(sphere);
    world.spawn((
        Name::new("glass ball"),
        Ball,
        Mesh3d(sphere),
        MeshMaterial3d(glass),
        CausticGenerator::refractive(1.5),
        Transform::from_xyz(BALL_AT.x, BALL_HEIGHT, BALL_AT.y),
    ));

    let sun = Sun { azimuth: SUN_AZIMUTH, elevation: SUN_ELEVATION };
    world.spawn((
        Name::new("sun"),
        // The water casts the sun's shadow: under it, the caustics carry the light that
        // the water lets through.
        DirectionalLight { illuminance: SUN_LUX, shadow_maps_enabled: true, ..default() },
        sun.transform(),
        sun,
    ));
    let sky = support::sky(&mut world.resource_mut::<Assets<Image>>(), SKY);
    world.spawn((
        Camera3d::default(),
        Caustics::default(),
        sky.clone(),
        Exposure { ev100: EV100 },
        Projection::from(PerspectiveProjection { fov: 0.9, ..default() }),
        Transform::from_xyz(-1.3, 1.8, 3.5).looking_at(Vec3::new(0.3, -0.9, -0.7), Vec3::Y),
    ));
    sky
}

/// A second camera, in the pool's corner half a metre under the water, looking across
/// it towards the sun and up at the surface; [`place_underwater_view`] gives it its
/// corner of the image.
fn spawn_underwater_view(world: &mut World, sky: EnvironmentMapLight) {
    world.spawn((
        Name::new("underwater camera"),
        UnderwaterView,
        Camera3d::default(),
        // Its own sky behind it, not the main view's image.
        Camera { order: 1, is_active: false, msaa_writeback: MsaaWriteback::Off, ..default() },
        Caustics::default(),
        sky,
        Exposure { ev100: EV100 },
        Projection::from(PerspectiveProjection { fov: 1.0, ..default() }),
        Transform::from_xyz(1.6, -0.9, -1.6).looking_at(Vec3::new(-1.0, 0.15, 0.4), Vec3::Y),
    ));
}

/// Keeps the underwater view in the bottom right corner of its image, whatever the
/// window's size; it draws once its image's size is known.
fn place_underwater_view(mut views: Query<&mut Camera, With<UnderwaterView>>) {
    for mut camera in &mut views {
        let Some(size) = camera.physical_target_size() else { continue };
        let (share, margin) = INSET;
        let width = (size.x as f32 * share) as u32;
        let inset = UVec2::new(width, width * 9 / 16);
        let fits = inset.x > 0 && inset.y > 0 && inset.x + margin < size.x && inset.y + margin < size.y;
        let position = size - inset - UVec2::splat(margin);
        let placed = camera.viewport.as_ref().map(|v| (v.physical_position, v.physical_size));
        if placed != fits.then_some((position, inset)) || camera.is_active != fits {
            camera.is_active = fits;
            camera.viewport = fits.then(|| Viewport { physical_position: position, physical_size: inset, ..default() });
        }
    }
}

/// The pool's tiles on a surface of so many metres.
type Tiled<'a> = dyn Fn(Vec2) -> StandardMaterial + 'a;

/// Four tiled walls from the floor to the coping; caustics land on them.
fn spawn_walls(world: &mut World, tiled: &Tiled) {
    let height = DEPTH + COPING;
    // Both faces cast the sun's shadow: the wall the sun stands behind shades the floor
    // beside it, which the water's shadow does not reach.
    let material = StandardMaterial { double_sided: true, cull_mode: None, ..tiled(Vec2::new(SIZE, height)) };
    let material = world.resource_mut::<Assets<StandardMaterial>>().add(material);
    let wall = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Z, Vec2::new(SIZE / 2.0, height / 2.0)).mesh());
    for turn in 0..4 {
        let rotation = Quat::from_rotation_y(turn as f32 * FRAC_PI_2);
        let centre = rotation * Vec3::new(0.0, height / 2.0 - DEPTH, -SIZE / 2.0);
        world.spawn((Mesh3d(wall.clone()), MeshMaterial3d(material.clone()), Transform::from_translation(centre).with_rotation(rotation), CausticReceiver));
    }
}

/// Three wide tiled steps down from the left wall, near its far end, the top one a
/// shelf 15 cm under the water.
fn spawn_steps(world: &mut World, tiled: &Tiled) {
    const WIDTH: f32 = 1.4;
    const SHELF: f32 = 1.0;
    const TREAD: f32 = 0.4;
    let rise = (DEPTH - 0.15) / 3.0;
    for step in 0..3 {
        let (height, length) = ((step + 1) as f32 * rise, SHELF + (2 - step) as f32 * TREAD);
        let material = world.resource_mut::<Assets<StandardMaterial>>().add(tiled(Vec2::new(length, WIDTH)));
        let block = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(length, height, WIDTH).mesh());
        let centre = Vec3::new(-SIZE / 2.0 + length / 2.0, height / 2.0 - DEPTH, -SIZE / 2.0 + 0.4 + WIDTH / 2.0);
        world.spawn((Mesh3d(block), MeshMaterial3d(material), Transform::from_translation(centre), CausticReceiver));
    }
}

/// Pale stone around the pool, level with the coping.
fn spawn_deck(world: &mut World) {
    const WIDE: f32 = 6.0;
    const THICK: f32 = 0.3;
    // Sandstone slabs half a metre wide.
    let slabs = world.resource_mut::<Assets<Image>>().add(support::texture(64, |u, v| {
        let joint = u < 2.0 / 64.0 || v < 2.0 / 64.0;
        if joint { [90, 84, 74] } else { [168, 150, 124] }
    }));
    let y = COPING - THICK / 2.0;
    let offset = (SIZE + WIDE) / 2.0;
    let (side, end) = (Vec2::new(SIZE + 2.0 * WIDE, WIDE), Vec2::new(WIDE, SIZE));
    for (size, at) in
        [(side, Vec3::new(0.0, y, offset)), (side, Vec3::new(0.0, y, -offset)), (end, Vec3::new(offset, y, 0.0)), (end, Vec3::new(-offset, y, 0.0))]
    {
        let stone = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
            base_color_texture: Some(slabs.clone()),
            uv_transform: Affine2::from_scale(2.0 * size),
            perceptual_roughness: 0.9,
            ..default()
        });
        let slab = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(size.x, THICK, size.y).mesh());
        world.spawn((Mesh3d(slab), MeshMaterial3d(stone), Transform::from_translation(at)));
    }
}

/// A steel ladder on the right wall: two rails and four rungs.
fn spawn_ladder(world: &mut World) {
    const RAIL: f32 = 0.022;
    const HALF_WIDTH: f32 = 0.25;
    let steel = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgb(0.9, 0.9, 0.92),
        metallic: 1.0,
        perceptual_roughness: 0.15,
        ..default()
    });
    let x = SIZE / 2.0 - 0.12;
    let (bottom, top) = (-DEPTH + 0.1, COPING + 0.7);
    let rail = world.resource_mut::<Assets<Mesh>>().add(Cylinder::new(RAIL, top - bottom).mesh());
    let rung = world.resource_mut::<Assets<Mesh>>().add(Cylinder::new(RAIL * 0.8, 2.0 * HALF_WIDTH).mesh());
    for z in [-HALF_WIDTH, HALF_WIDTH] {
        let at = Vec3::new(x, (top + bottom) / 2.0, 0.4 + z);
        world.spawn((Mesh3d(rail.clone()), MeshMaterial3d(steel.clone()), Transform::from_translation(at)));
    }
    for i in 0..4 {
        let at = Vec3::new(x, bottom + 0.2 + 0.28 * i as f32, 0.4);
        world.spawn((Mesh3d(rung.clone()), MeshMaterial3d(steel.clone()), Transform::from_translation(at).with_rotation(Quat::from_rotation_x(FRAC_PI_2))));
    }
}

/// The ball bobs; each time it dips into the water it starts a ripple.
fn bob_ball(time: Res<Time>, mut ball: Query<&mut Transform, With<Ball>>, mut touches: MessageWriter<DropPebble>) {
    let (amplitude, period) = BOB;
    let height = |t: f32| BALL_HEIGHT + amplitude * (t / period * TAU).sin();
    let (now, before) = (time.elapsed_secs(), time.elapsed_secs() - time.delta_secs());
    for mut transform in &mut ball {
        transform.translation.y = height(now);
        // Its lowest point going into the water.
        if height(before) > BALL_RADIUS && height(now) <= BALL_RADIUS {
            touches.write(DropPebble { position: transform.translation, strength: TOUCH });
        }
    }
}

/// Raindrops at `SHOWER` and then `DRIZZLE` drops a second, anywhere on the water: at
/// random, from a fixed seed, so that every run shows the same water.
fn rain(time: Res<Time>, mut due: Local<f32>, mut seed: Local<u32>, mut touches: MessageWriter<DropPebble>) {
    let (shower, lasting) = SHOWER;
    *due += if time.elapsed_secs() < lasting { shower } else { DRIZZLE } * time.delta_secs();
    let mut random = || {
        // Numerical Recipes' linear congruential generator, its top 24 bits in [0, 1).
        *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (*seed >> 8) as f32 / (1u32 << 24) as f32
    };
    while *due >= 1.0 {
        *due -= 1.0;
        let (x, z) = ((random() - 0.5) * 0.95 * SIZE, (random() - 0.5) * 0.95 * SIZE);
        touches.write(DropPebble { position: Vec3::new(x, 0.0, z), strength: TOUCH });
    }
}

/// Dragging on the water with the left button makes ripples along the path, one every
/// 10 cm of it.
fn touch_water(
    buttons: Res<ButtonInput<MouseButton>>,
    window: Single<&Window, With<PrimaryWindow>>,
    camera: Single<(&Camera, &GlobalTransform), Without<UnderwaterView>>,
    mut last: Local<Option<Vec3>>,
    mut touches: MessageWriter<DropPebble>,
) {
    if !buttons.pressed(MouseButton::Left) {
        *last = None;
        return;
    }
    let Some(at) = support::cursor_on_water(&window, *camera) else { return };
    if at.x.abs().max(at.z.abs()) < SIZE / 2.0 && last.is_none_or(|l| l.distance(at) > 0.1) {
        touches.write(DropPebble { position: at, strength: TOUCH });
        *last = Some(at);
    }
}

/// Arrow keys: left and right turn the sun about the vertical, up and down raise and
/// lower it (between 10° and 85°).
fn move_sun(keys: Res<ButtonInput<KeyCode>>, time: Res<Time>, mut sun: Query<(&mut Sun, &mut Transform)>) {
    let axis = |minus, plus| keys.pressed(plus) as i32 as f32 - keys.pressed(minus) as i32 as f32;
    let (turn, raise) = (axis(KeyCode::ArrowLeft, KeyCode::ArrowRight), axis(KeyCode::ArrowDown, KeyCode::ArrowUp));
    if turn == 0.0 && raise == 0.0 {
        return;
    }
    for (mut sun, mut transform) in &mut sun {
        sun.azimuth += turn * 0.8 * time.delta_secs();
        sun.elevation = (sun.elevation + raise * 0.5 * time.delta_secs()).clamp(10f32.to_radians(), 85f32.to_radians());
        *transform = sun.transform();
    }
}
