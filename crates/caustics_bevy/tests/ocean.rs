//! The `Ocean` component without a renderer: it creates its grid mesh, rewrites it in
//! place as time passes, and skips invalid settings without a panic.

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

fn positions(app: &App, entity: Entity) -> Vec<[f32; 3]> {
    let mesh = app.world().get::<Mesh3d>(entity).expect("the ocean has a mesh");
    let mesh = app.world().resource::<Assets<Mesh>>().get(&mesh.0).expect("its mesh asset exists");
    mesh.attribute(Mesh::ATTRIBUTE_POSITION).unwrap().as_float3().unwrap().to_vec()
}

#[test]
fn an_ocean_animates_its_mesh_in_place() {
    let mut app = app();
    let ocean = app.world_mut().spawn(Ocean { resolution: 32, wind_speed: 8.0, ..default() }).id();
    app.update();
    app.update();
    let handle = app.world().get::<Mesh3d>(ocean).unwrap().0.clone();
    let first = positions(&app, ocean);
    assert_eq!(first.len(), 33 * 33);
    assert!(first.iter().flatten().all(|v| v.is_finite()));
    app.update();
    let second = positions(&app, ocean);
    assert_ne!(first, second, "the waves did not move");
    assert_eq!(app.world().get::<Mesh3d>(ocean).unwrap().0, handle, "the mesh is updated in place");

    // A new resolution makes a new grid.
    app.world_mut().get_mut::<Ocean>(ocean).unwrap().resolution = 16;
    app.update();
    assert_eq!(positions(&app, ocean).len(), 17 * 17);
}

#[test]
fn invalid_settings_leave_the_ocean_still() {
    let mut app = app();
    let ocean = app.world_mut().spawn(Ocean { resolution: 30, ..default() }).id();
    app.update();
    app.update();
    assert!(app.world().get::<Mesh3d>(ocean).is_none());
    app.world_mut().get_mut::<Ocean>(ocean).unwrap().resolution = 8;
    app.update();
    assert_eq!(positions(&app, ocean).len(), 81);
}
