//! The `PoolRipples` component without a renderer: its grid mesh, pebbles that land
//! in it (and those that do not), deterministic waves written in place, impulses that
//! fade and still water that costs nothing, and invalid settings skipped without a panic.

#![cfg(feature = "convolution")]

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use caustics_bevy::convolution::{DropPebble, PoolImpulses, PoolRipples, PoolRipplesPlugin, PoolSurface};
use std::time::Duration;

fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, TransformPlugin, AssetPlugin::default(), PoolRipplesPlugin))
        .init_asset::<Mesh>()
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(100)));
    app
}

/// A 2 m × 1 m pool at 32 × 16 texels, its centre at (10, 1, 0) in the world.
fn spawn_pool(app: &mut App) -> Entity {
    let pool = PoolRipples { columns: 32, rows: 16, cell_size: 1.0 / 16.0, ..default() };
    app.world_mut().spawn((pool, Transform::from_xyz(10.0, 1.0, 0.0))).id()
}

fn handle(app: &App, entity: Entity) -> Handle<Mesh> {
    app.world().get::<Mesh3d>(entity).expect("the pool has a mesh").0.clone()
}

fn positions(app: &App, entity: Entity) -> Vec<[f32; 3]> {
    let mesh = app.world().resource::<Assets<Mesh>>().get(&handle(app, entity)).expect("its mesh asset exists");
    mesh.attribute(Mesh::ATTRIBUTE_POSITION).unwrap().as_float3().unwrap().to_vec()
}

fn impulses(app: &App, entity: Entity) -> usize {
    app.world().get::<PoolSurface>(entity).expect("the pool has water").ripples().impulses().len()
}

fn drop_pebble(app: &mut App, position: Vec3) {
    app.world_mut().write_message(DropPebble { position, strength: 0.01 });
}

#[test]
fn pebbles_ripple_the_pool_mesh_in_place() {
    let mut app = app();
    let pool = spawn_pool(&mut app);
    app.update();
    app.update();
    let mesh = handle(&app, pool);
    let still = positions(&app, pool);
    // A vertex over each texel centre, centred on the entity, at rest.
    assert_eq!(still.len(), 32 * 16);
    assert_eq!(still[0], [-1.0 + 1.0 / 32.0, 0.0, -0.5 + 1.0 / 32.0]);
    assert!(still.iter().all(|p| p[1] == 0.0));

    // Pebbles outside the pool's footprint (beside it; far below is still over it) are ignored.
    drop_pebble(&mut app, Vec3::new(8.9, 1.0, 0.0));
    drop_pebble(&mut app, Vec3::new(10.0, 1.0, 0.6));
    app.update();
    assert_eq!(impulses(&app, pool), 0);
    assert!(positions(&app, pool).iter().all(|p| p[1] == 0.0));

    drop_pebble(&mut app, Vec3::new(10.5, -40.0, 0.2));
    app.update();
    assert_eq!(impulses(&app, pool), 1);
    app.update();
    let rippled = positions(&app, pool);
    assert!(rippled.iter().flatten().all(|v| v.is_finite()));
    let highest = rippled.iter().map(|p| p[1].abs()).fold(0.0, f32::max);
    assert!(highest > 1e-4, "the pebble made no wave ({highest})");
    app.update();
    assert_ne!(positions(&app, pool), rippled, "the wave did not move");
    assert_eq!(handle(&app, pool), mesh, "the mesh is updated in place");

    // The wave fades; its impulse is removed and the water is still again.
    for _ in 0..300 {
        app.update();
    }
    assert_eq!(impulses(&app, pool), 0);
    assert!(positions(&app, pool).iter().all(|p| p[1] == 0.0));
    assert_eq!(handle(&app, pool), mesh);
}

#[test]
fn the_same_pebbles_make_the_same_waves() {
    let run = || {
        let mut app = app();
        let pool = spawn_pool(&mut app);
        app.update();
        for (frame, x) in [(0, 9.4), (3, 10.7), (4, 10.1)] {
            while app.world().resource::<Time>().elapsed() < Duration::from_millis(100 * frame) {
                app.update();
            }
            drop_pebble(&mut app, Vec3::new(x, 1.0, -0.3));
        }
        for _ in 0..5 {
            app.update();
        }
        positions(&app, pool)
    };
    let first = run();
    assert!(first.iter().any(|p| p[1] != 0.0));
    assert_eq!(first, run());
}

#[test]
fn invalid_settings_leave_the_pool_dry_until_fixed() {
    let mut app = app();
    let pool = spawn_pool(&mut app);
    app.world_mut().get_mut::<PoolRipples>(pool).unwrap().cell_size = f32::NAN;
    app.update();
    drop_pebble(&mut app, Vec3::new(10.0, 1.0, 0.0));
    app.update();
    assert!(app.world().get::<PoolSurface>(pool).is_none());
    app.world_mut().get_mut::<PoolRipples>(pool).unwrap().time_damping = -1.0;
    app.update();
    assert!(app.world().get::<PoolSurface>(pool).is_none());

    let mut settings = app.world_mut().get_mut::<PoolRipples>(pool).unwrap();
    (settings.cell_size, settings.time_damping) = (1.0 / 16.0, 1.0);
    app.update();
    assert_eq!(positions(&app, pool).len(), 32 * 16);
    // A new resolution makes a new grid.
    app.world_mut().get_mut::<PoolRipples>(pool).unwrap().columns = 8;
    app.update();
    assert_eq!(positions(&app, pool).len(), 8 * 16);
}

#[test]
fn a_saved_pool_starts_with_the_water_it_was_saved_with() {
    // Two pebbles a few frames apart, then the waves run on.
    let mut first = app();
    let pool = spawn_pool(&mut first);
    first.update();
    drop_pebble(&mut first, Vec3::new(9.6, 1.0, 0.2));
    first.update();
    first.update();
    drop_pebble(&mut first, Vec3::new(10.5, 1.0, -0.1));
    for _ in 0..5 {
        first.update();
    }
    let world = first.world();
    let time = world.resource::<Time>().elapsed_secs();
    let saved = world.get::<PoolRipples>(pool).unwrap().to_view(0, world.get::<GlobalTransform>(pool).unwrap(), world.get::<PoolSurface>(pool).unwrap(), time);
    assert_eq!(saved.impulses.len(), 2);
    let waves = positions(&first, pool);
    assert!(waves.iter().any(|p| p[1].abs() > 1e-4), "the water moves");

    // Made again in another app whose clock reads otherwise: the same water.
    let mut again = app();
    again.update();
    again.update();
    let transform = Transform::from_matrix(Mat4::from_cols_array(&caustics_core::glam::Mat4::from(saved.transform).to_cols_array()));
    let copy = again.world_mut().spawn((PoolRipples::from_view(&saved), PoolImpulses { impulses: saved.impulses.clone(), time: saved.time }, transform)).id();
    again.world_mut().resource_mut::<Time<Virtual>>().pause();
    again.update();
    again.update();
    assert!(again.world().get::<PoolImpulses>(copy).is_none(), "the impulses are in its water");
    assert_eq!(again.world().get::<PoolRipples>(copy), first.world().get::<PoolRipples>(pool));
    let copied = positions(&again, copy);
    let off = waves.iter().zip(&copied).map(|(a, b)| (a[1] - b[1]).abs()).fold(0.0, f32::max);
    assert!(off < 1e-6, "the heights differ by up to {off} m");
    assert_eq!(again.world().get::<GlobalTransform>(copy).unwrap().translation(), Vec3::new(10.0, 1.0, 0.0));
}
