//! `SceneChanges`, from which the techniques decide whether to read the scene again:
//! a frame where nothing moved reports nothing, and each kind of change is reported
//! in its part — including a mesh that begins or stops receiving caustics or casting
//! shadows, a generator's bounds apart from the generator, and a light or generator
//! that goes away.

use bevy::light::NotShadowCaster;
use bevy::prelude::*;
use caustics_bevy::components::validate_caustic_params;
use caustics_bevy::read_scene::{ChangedParts, SceneChanges};
use caustics_bevy::technique::{AvailableCausticTechniques, choose_techniques};
use caustics_bevy::{CausticGenerator, CausticReceiver};

#[derive(Resource, Default)]
struct Seen(ChangedParts);

fn record(mut changes: SceneChanges, mut seen: ResMut<Seen>) {
    seen.0 = changes.read();
}

fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, TransformPlugin, AssetPlugin::default()))
        .init_asset::<Mesh>()
        .init_resource::<AvailableCausticTechniques>()
        .init_resource::<Seen>()
        .add_systems(PostUpdate, (validate_caustic_params, choose_techniques, record).chain());
    app
}

/// Runs a frame and gives what changed in it, as (generators, occluders, lights).
fn frame(app: &mut App) -> (bool, bool, bool) {
    app.update();
    let seen = app.world().resource::<Seen>().0;
    (seen.generators, seen.occluders, seen.lights)
}

#[test]
fn each_change_is_reported_in_its_part_and_a_still_frame_in_none() {
    let mut app = app();
    let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(Cuboid::default());
    let generator = app.world_mut().spawn((Mesh3d(mesh.clone()), CausticGenerator::mirror(), Transform::default(), Visibility::default())).id();
    let floor = app.world_mut().spawn((Mesh3d(mesh.clone()), Transform::from_xyz(0.0, -1.0, 0.0), Visibility::default())).id();
    let sun = app.world_mut().spawn((DirectionalLight::default(), Transform::default(), Visibility::default())).id();
    assert_eq!(frame(&mut app), (true, true, true), "what is spawned is new");
    // The technique's choice arrives by command at the end of the first frame.
    frame(&mut app);
    assert_eq!(frame(&mut app), (false, false, false), "nothing moved");
    assert_eq!(frame(&mut app), (false, false, false), "nothing moved");

    app.world_mut().entity_mut(floor).insert(CausticReceiver);
    assert_eq!(frame(&mut app), (false, true, false), "the floor began receiving caustics");
    app.world_mut().entity_mut(floor).insert(NotShadowCaster);
    assert_eq!(frame(&mut app), (false, true, false), "the floor stopped casting shadows");
    app.world_mut().entity_mut(floor).remove::<(NotShadowCaster, CausticReceiver)>();
    assert_eq!(frame(&mut app), (false, true, false), "the floor casts shadows again and receives no more");
    app.world_mut().get_mut::<Transform>(floor).unwrap().translation.y = -2.0;
    assert_eq!(frame(&mut app), (false, true, false), "the floor moved");
    assert_eq!(frame(&mut app), (false, false, false), "nothing moved");

    app.world_mut().get_mut::<Transform>(generator).unwrap().rotate_y(0.1);
    assert_eq!(frame(&mut app), (true, false, false), "the generator turned");
    assert!(!app.world().resource::<Seen>().0.generator_bounds);
    // New bounds alone (a surface moved on the GPU gets them for its new waves) are
    // not a changed generator: the volumes read such a surface on the GPU.
    let bounds = bevy::camera::primitives::Aabb::from_min_max(Vec3::splat(-2.0), Vec3::splat(2.0));
    app.world_mut().entity_mut(generator).insert(bounds);
    assert_eq!(frame(&mut app), (false, false, false), "only the generator's bounds changed");
    assert!(app.world().resource::<Seen>().0.generator_bounds, "the generator's bounds changed");
    app.world_mut().get_mut::<CausticGenerator>(generator).unwrap().double_sided = true;
    assert!(frame(&mut app).0, "the generator became double-sided");

    app.world_mut().get_mut::<DirectionalLight>(sun).unwrap().illuminance *= 2.0;
    assert_eq!(frame(&mut app), (false, false, true), "the sun brightened");
    app.world_mut().despawn(sun);
    assert_eq!(frame(&mut app), (false, false, true), "the sun went away");
    app.world_mut().despawn(generator);
    assert!(frame(&mut app).0, "the generator went away");
    assert_eq!(frame(&mut app), (false, false, false), "nothing moved");
}
