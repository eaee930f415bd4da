//! The `Ocean` component without a renderer: it creates its grid mesh, rewrites it in
//! place as time passes, redraws its waves when its settings change, replaces a mesh
//! that is not its grid, and skips invalid settings without a panic.

#![cfg(feature = "ocean")]

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use caustics_bevy::ocean::{Ocean, OceanPlugin};
use std::time::Duration;

fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, AssetPlugin::default(), OceanPlugin))
        .init_asset::<Mesh>()
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(250)));
    app
}

fn handle(app: &App, entity: Entity) -> Handle<Mesh> {
    app.world().get::<Mesh3d>(entity).expect("the ocean has a mesh").0.clone()
}

fn attribute(app: &App, entity: Entity, id: bevy::mesh::MeshVertexAttribute) -> Vec<[f32; 3]> {
    let mesh = app.world().resource::<Assets<Mesh>>().get(&handle(app, entity)).expect("its mesh asset exists");
    mesh.attribute(id).unwrap().as_float3().unwrap().to_vec()
}

fn positions(app: &App, entity: Entity) -> Vec<[f32; 3]> {
    attribute(app, entity, Mesh::ATTRIBUTE_POSITION)
}

#[test]
fn an_ocean_animates_its_mesh_in_place() {
    let mut app = app();
    let ocean = app.world_mut().spawn(Ocean { resolution: 32, wind_speed: 8.0, ..default() }).id();
    app.update();
    app.update();
    let mesh = handle(&app, ocean);
    let first = positions(&app, ocean);
    // (N + 1)²: the last row and column repeat the first, so that patches tile.
    assert_eq!(first.len(), 33 * 33);
    assert!(first.iter().flatten().all(|v| v.is_finite()));
    let normals = attribute(&app, ocean, Mesh::ATTRIBUTE_NORMAL);
    assert_eq!(normals.len(), first.len());
    assert!(normals.iter().all(|n| (Vec3::from_array(*n).length() - 1.0).abs() < 1e-4 && n[1] > 0.0));
    let uvs = app.world().resource::<Assets<Mesh>>().get(&mesh).unwrap().attribute(Mesh::ATTRIBUTE_UV_0).unwrap().len();
    assert_eq!(uvs, first.len());

    app.update();
    let second = positions(&app, ocean);
    assert_ne!(first, second, "the waves did not move");
    assert_eq!(handle(&app, ocean), mesh, "the mesh is updated in place");

    // New wind, same grid: the same mesh with new waves.
    app.world_mut().get_mut::<Ocean>(ocean).unwrap().wind_speed = 3.0;
    app.update();
    assert_eq!(handle(&app, ocean), mesh);
    let calm = positions(&app, ocean);
    let rms = |p: &[[f32; 3]]| (p.iter().map(|v| v[1] * v[1]).sum::<f32>() / p.len() as f32).sqrt();
    assert!(rms(&calm) < 0.5 * rms(&second), "{} vs {}", rms(&calm), rms(&second));

    // A new resolution makes a new grid.
    app.world_mut().get_mut::<Ocean>(ocean).unwrap().resolution = 16;
    app.update();
    assert_eq!(positions(&app, ocean).len(), 17 * 17);
    assert_ne!(handle(&app, ocean), mesh);

    // Time stands still at time scale 0.
    app.world_mut().get_mut::<Ocean>(ocean).unwrap().time_scale = 0.0;
    app.update();
    let frozen = positions(&app, ocean);
    app.update();
    assert_eq!(positions(&app, ocean), frozen);
}

#[test]
fn a_mesh_that_is_not_the_grid_is_replaced() {
    let mut app = app();
    let cube = app.world_mut().resource_mut::<Assets<Mesh>>().add(Cuboid::default());
    let ocean = app.world_mut().spawn((Ocean { resolution: 8, ..default() }, Mesh3d(cube.clone()))).id();
    app.update();
    assert_ne!(handle(&app, ocean), cube);
    assert_eq!(positions(&app, ocean).len(), 81);
    let cube_positions = app.world().resource::<Assets<Mesh>>().get(&cube).unwrap().count_vertices();
    assert_eq!(cube_positions, 24, "the user's mesh is left alone");
}

#[test]
fn invalid_settings_leave_the_ocean_still() {
    let mut app = app();
    let ocean = app.world_mut().spawn(Ocean { resolution: 30, ..default() }).id();
    let nan = app.world_mut().spawn(Ocean { resolution: 8, time_scale: f32::NAN, ..default() }).id();
    app.update();
    app.update();
    assert!(app.world().get::<Mesh3d>(ocean).is_none());
    assert!(app.world().get::<Mesh3d>(nan).is_none());
    app.world_mut().get_mut::<Ocean>(ocean).unwrap().resolution = 8;
    app.world_mut().get_mut::<Ocean>(nan).unwrap().time_scale = 2.0;
    app.update();
    assert_eq!(positions(&app, ocean).len(), 81);
    assert_eq!(positions(&app, nan).len(), 81);

    // Invalid again: the mesh stays as it was.
    app.world_mut().get_mut::<Ocean>(ocean).unwrap().wind_speed = -1.0;
    app.update();
    let still = positions(&app, ocean);
    app.update();
    assert_eq!(positions(&app, ocean), still);

    // Removing the component stops the animation and despawning is fine.
    app.world_mut().entity_mut(nan).remove::<Ocean>();
    app.update();
    let left = positions(&app, nan);
    app.update();
    assert_eq!(positions(&app, nan), left);
    app.world_mut().despawn(ocean);
    app.update();
}
