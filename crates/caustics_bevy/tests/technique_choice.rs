//! The technique each generator gets, without a renderer: `Auto`'s table on Bevy's own
//! meshes (a UV sphere welded at its seam is closed, a plane is open), a mirror inside
//! a participating medium, and every technique requested while it is unavailable — the
//! generator warns once, names what it asked for and falls back to `Auto`'s choice —
//! and the lights whose RectLight or RenderLayers the caustics do not follow say so.

use bevy::camera::primitives::MeshAabb;
use bevy::camera::visibility::RenderLayers;
use bevy::light::RectLight;
use bevy::log::tracing_subscriber::{self, Layer, layer::Context, prelude::*};
use bevy::prelude::*;
use caustics_bevy::components::validate_caustic_params;
use caustics_bevy::irradiance::{CausticReceiverMaterialPlugin, warn_receivers_with_unread_material};
use caustics_bevy::lights::warn_unsupported_lights;
use caustics_bevy::technique::{AvailableCausticTechniques, choose_techniques};
use caustics_bevy::{CausticGenerator, CausticReceiver, CausticTechnique, CausticTechniqueChoice, ParticipatingMedium};
use std::sync::{Arc, Mutex};

fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, TransformPlugin, AssetPlugin::default()))
        .init_asset::<Mesh>()
        .init_resource::<AvailableCausticTechniques>()
        .add_systems(PostUpdate, (validate_caustic_params, choose_techniques).chain());
    app
}

fn spawn(app: &mut App, mesh: Mesh, generator: CausticGenerator, at: Vec3) -> Entity {
    let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
    let aabb = mesh_aabb(app, &mesh);
    app.world_mut().spawn((Mesh3d(mesh), generator, Transform::from_translation(at), aabb)).id()
}

fn mesh_aabb(app: &App, mesh: &Handle<Mesh>) -> bevy::camera::primitives::Aabb {
    app.world().resource::<Assets<Mesh>>().get(mesh).unwrap().compute_aabb().unwrap()
}

fn choice(app: &App, entity: Entity) -> CausticTechniqueChoice {
    app.world().get::<CausticTechniqueChoice>(entity).expect("the generator has a technique").clone()
}

fn seen(app: &App, entity: Entity) -> String {
    choice(app, entity).to_string()
}

fn ball() -> Mesh {
    Sphere::new(0.5).mesh().uv(32, 18)
}

#[test]
fn auto_picks_by_what_the_generator_is() {
    let mut app = app();
    let glass = spawn(&mut app, ball(), CausticGenerator::refractive(1.5), Vec3::ZERO);
    let water = spawn(&mut app, Plane3d::default().mesh().size(4.0, 4.0).build(), CausticGenerator::refractive(1.333), Vec3::Y);
    let mirror = spawn(&mut app, Cuboid::default().into(), CausticGenerator::mirror(), Vec3::new(5.0, 0.0, 0.0));
    let hazy_mirror = spawn(&mut app, Cuboid::default().into(), CausticGenerator::mirror(), Vec3::new(-5.0, 0.0, 0.0));
    app.world_mut().spawn((
        ParticipatingMedium { scattering: 0.1, absorption: Vec3::splat(0.0), asymmetry: 0.0 },
        Transform::from_xyz(-5.0, 0.0, 0.0).with_scale(Vec3::splat(4.0)),
        // No visibility plugin here to inherit it.
        InheritedVisibility::VISIBLE,
    ));
    app.update();
    assert_eq!(seen(&app, glass), "closed refractor → hierarchical maps");
    assert_eq!(seen(&app, water), "open refracting surface → warped volumes");
    // The glass ball is in the scene: the mirror joins it on the maps, whose traced
    // paths carry light between them; in a medium it keeps the volumes' shafts.
    assert_eq!(seen(&app, mirror), "mirror beside a closed refractor → hierarchical maps");
    assert_eq!(seen(&app, hazy_mirror), "mirror in a participating medium → warped volumes");

    // A hole in the ball (its first band of triangles gone) makes it an open surface.
    let mut holed = ball();
    let indices: Vec<u32> = holed.indices().unwrap().iter().skip(3 * 64).map(|i| i as u32).collect();
    holed.insert_indices(bevy::mesh::Indices::U32(indices));
    let handle = app.world().get::<Mesh3d>(glass).unwrap().0.clone();
    app.world_mut().resource_mut::<Assets<Mesh>>().insert(handle.id(), holed).unwrap();
    app.update();
    app.update();
    assert_eq!(choice(&app, glass).technique(), CausticTechnique::WarpedVolumes, "{}", seen(&app, glass));
    // No closed refractor left: the mirror goes back to the volumes.
    assert_eq!(seen(&app, mirror), "mirror → warped volumes");

    // A generator that stops being one loses its choice.
    app.world_mut().entity_mut(water).remove::<CausticGenerator>();
    app.update();
    assert!(app.world().get::<CausticTechniqueChoice>(water).is_none());
}

/// Every warning logged while it is installed.
#[derive(Clone, Default)]
struct Warnings(Arc<Mutex<Vec<String>>>);

impl<S: bevy::log::tracing::Subscriber> Layer<S> for Warnings {
    fn on_event(&self, event: &bevy::log::tracing::Event<'_>, _: Context<'_, S>) {
        struct Message<'a>(&'a mut String);
        impl bevy::log::tracing::field::Visit for Message<'_> {
            fn record_debug(&mut self, _: &bevy::log::tracing::field::Field, value: &dyn std::fmt::Debug) {
                self.0.push_str(&format!("{value:?}"));
            }
        }
        if *event.metadata().level() == bevy::log::Level::WARN {
            let mut text = String::new();
            event.record(&mut Message(&mut text));
            self.0.lock().unwrap().push(text);
        }
    }
}

#[test]
fn no_technique_choice_is_silently_dark() {
    let warnings = Warnings::default();
    tracing_subscriber::registry().with(warnings.clone()).init();
    // Each technique asked for while it is unavailable (its cargo feature off, or taken
    // out by the app), on a generator it would otherwise draw.
    let cases = [
        (CausticTechnique::WarpedVolumes, CausticTechnique::HierarchicalMaps, "closed refractor → hierarchical maps"),
        (CausticTechnique::HierarchicalMaps, CausticTechnique::IlluminationTextures, "closed refractor → illumination textures"),
        (CausticTechnique::Convolution, CausticTechnique::HierarchicalMaps, "closed refractor → hierarchical maps"),
        (CausticTechnique::IlluminationTextures, CausticTechnique::HierarchicalMaps, "closed refractor → hierarchical maps"),
    ];
    for (asked, fallback, reason) in cases {
        let mut app = app();
        let all = AvailableCausticTechniques::default();
        let without = all.0.iter().copied().filter(|&t| t != asked).collect();
        app.insert_resource(AvailableCausticTechniques(without));
        let glass = spawn(&mut app, ball(), CausticGenerator { technique: asked, ..CausticGenerator::refractive(1.5) }, Vec3::ZERO);
        warnings.0.lock().unwrap().clear();
        for _ in 0..3 {
            app.update();
        }
        let chosen = choice(&app, glass);
        assert_eq!(chosen.technique(), fallback, "{asked:?}: {}", chosen);
        assert!(chosen.to_string().ends_with(reason), "{asked:?}: {}", chosen);
        let asked_label = asked.label();
        let logged = warnings.0.lock().unwrap().clone();
        let named: Vec<_> = logged.iter().filter(|w| w.contains(&format!("{glass}")) && w.contains(asked_label)).collect();
        assert_eq!(named.len(), 1, "{asked:?}: one warning naming the entity and the technique, got {logged:?}");
        assert!(named[0].contains(fallback.label()), "{}", named[0]);
    }

    // Nothing available at all: one warning, no choice, no work.
    let mut app = app();
    app.insert_resource(AvailableCausticTechniques(Default::default()));
    let glass = spawn(&mut app, ball(), CausticGenerator::refractive(1.5), Vec3::ZERO);
    warnings.0.lock().unwrap().clear();
    for _ in 0..3 {
        app.update();
    }
    assert!(app.world().get::<CausticTechniqueChoice>(glass).is_none());
    let logged = warnings.0.lock().unwrap().clone();
    assert_eq!(logged.iter().filter(|w| w.contains("casts no caustics")).count(), 1, "{logged:?}");

    // What the caustics do not follow of Bevy's lights says so, once per light: a
    // RectLight, and a light limited to some RenderLayers.
    let mut app = self::app();
    app.add_systems(PostUpdate, warn_unsupported_lights);
    let rect = app.world_mut().spawn(RectLight::default()).id();
    let layered = app.world_mut().spawn((PointLight::default(), RenderLayers::layer(1))).id();
    app.world_mut().spawn((PointLight::default(), RenderLayers::default()));
    app.world_mut().spawn(SpotLight::default());
    warnings.0.lock().unwrap().clear();
    for _ in 0..3 {
        app.update();
    }
    let logged = warnings.0.lock().unwrap().clone();
    assert_eq!(logged.len(), 2, "{logged:?}");
    assert!(logged.iter().any(|w| w.contains(&format!("RectLight {rect}"))), "{logged:?}");
    assert!(logged.iter().any(|w| w.contains(&format!("light {layered}")) && w.contains("RenderLayers")), "{logged:?}");

    // A receiver whose material the composite cannot read says so, once.
    let mut app = self::app();
    app.add_plugins(CausticReceiverMaterialPlugin::<StandardMaterial>::default());
    app.add_systems(PostUpdate, warn_receivers_with_unread_material);
    let floor = app.world_mut().resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().build());
    let unread = app.world_mut().spawn((Mesh3d(floor.clone()), CausticReceiver)).id();
    app.world_mut().spawn((Mesh3d(floor), MeshMaterial3d::<StandardMaterial>::default(), CausticReceiver));
    warnings.0.lock().unwrap().clear();
    for _ in 0..3 {
        app.update();
    }
    let logged = warnings.0.lock().unwrap().clone();
    assert_eq!(logged.len(), 1, "{logged:?}");
    assert!(logged[0].contains(&format!("CausticReceiver {unread}")) && logged[0].contains("albedo 1"), "{logged:?}");
}
