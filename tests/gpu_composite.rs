//! The composite path on a real GPU adapter (lavapipe in CI): a known irradiance
//! pattern injected into the buffer must come out as albedo/π · E · exposure on
//! receiver pixels, and nowhere else. Also: a scene with nothing to do runs no
//! caustics pass, and invalid parameters are skipped without a panic.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

use bevy::asset::RenderAssetUsages;
use bevy::camera::Exposure;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::image::{ImageSampler, ImageSamplerDescriptor};
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::pixels::irradiance_image;
use bevy_caustics::{CausticGenerator, CausticReceiver, Caustics, InjectedIrradiance, InvalidCausticParams, ParticipatingMedium, TagCausticsFromMaterials};
use std::f32::consts::PI;

const SIZE: u32 = 64;
/// Linear albedos of the receiver texture's two texels (exact in Rgba8Unorm: k/255).
const ALBEDO: [Vec3; 2] = [Vec3::new(204.0 / 255.0, 51.0 / 255.0, 25.0 / 255.0), Vec3::new(25.0 / 255.0, 102.0 / 255.0, 230.0 / 255.0)];
/// `exposure = 1 / (1.2 · 2^ev100)` (Bevy's `Exposure::exposure`).
const EV100: f32 = 0.0;

/// The injected irradiance at pixel (x, y), in lux.
fn irradiance(x: u32, y: u32) -> Vec3 {
    Vec3::new(1.0 + 0.02 * x as f32, 0.8 + 0.01 * y as f32, 1.2) * 2.0
}

fn spawn_view(renderer: &mut HeadlessRenderer, inject: bool) {
    let target = renderer.render_target();
    let world = renderer.world_mut();
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    let texture = Image {
        sampler: ImageSampler::Descriptor(ImageSamplerDescriptor::nearest()),
        ..Image::new(
            Extent3d { width: 2, height: 1, depth_or_array_layers: 1 },
            TextureDimension::D2,
            ALBEDO.iter().flat_map(|a| [(a.x * 255.0).round() as u8, (a.y * 255.0).round() as u8, (a.z * 255.0).round() as u8, 255]).collect(),
            TextureFormat::Rgba8Unorm,
            RenderAssetUsages::RENDER_WORLD,
        )
    };
    let texture = world.resource_mut::<Assets<Image>>().add(texture);
    let receiver_material = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { base_color_texture: Some(texture), ..default() });
    let plain = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    let plane = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(1.0)).mesh());
    let cube = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(0.4, 0.4, 0.4));
    // The receiver fills the middle of the view; a cube stands on it; a plain plane
    // (not a receiver) lies beside it.
    world.spawn((Mesh3d(plane.clone()), MeshMaterial3d(receiver_material), CausticReceiver));
    world.spawn((Mesh3d(cube), MeshMaterial3d(plain.clone()), Transform::from_xyz(0.5, 0.2, 0.5)));
    world.spawn((Mesh3d(plane), MeshMaterial3d(plain), Transform::from_xyz(2.0, 0.0, 0.0)));
    let mut camera = world.spawn((
        Camera3d::default(),
        target,
        Caustics::default(),
        Tonemapping::None,
        Exposure { ev100: EV100 },
        Projection::from(OrthographicProjection { scale: 3.0 / SIZE as f32, ..OrthographicProjection::default_3d() }),
        Transform::from_xyz(0.5, 5.0, 0.0).looking_at(Vec3::new(0.5, 0.0, 0.0), Vec3::NEG_Z),
        Msaa::Off,
    ));
    if inject {
        let values: Vec<Vec3> = (0..SIZE * SIZE).map(|i| irradiance(i % SIZE, i / SIZE)).collect();
        let image = camera.world_scope(|w| w.resource_mut::<Assets<Image>>().add(irradiance_image(SIZE, SIZE, &values)));
        camera.insert(InjectedIrradiance(image));
    }
}

/// World position seen at pixel (x, y) for the orthographic camera above: 3 m across,
/// centred on (0.5, 0, 0), screen right = +x, screen up = −z.
fn world_at(x: u32, y: u32) -> Vec2 {
    let s = 3.0 / SIZE as f32;
    Vec2::new(0.5 + (x as f32 + 0.5 - SIZE as f32 / 2.0) * s, (y as f32 + 0.5 - SIZE as f32 / 2.0) * s)
}

#[test]
fn composite_pass_report_validation_and_tagging_on_a_real_adapter() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    spawn_view(&mut renderer, true);
    let image = renderer.render(4).unwrap_or_else(|e| panic!("{e}"));
    image.save_png(&std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("gpu_composite.png"), 1.0).unwrap();
    let report = renderer.pass_report();
    assert_eq!(report.views("inject"), 1, "{report:?}");
    assert_eq!(report.views("composite"), 1, "{report:?}");

    let exposure = 1.0 / (1.2 * 2f32.powf(EV100));
    let (mut seen, mut checked, mut dark) = ([false; 2], 0, [0; 2]);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let p = world_at(x, y);
            let got = image.pixel(x, y).truncate();
            // Pixel centres within 0.03 m (< a pixel) of an edge are left out.
            let off_receiver = p.abs().max_element() > 1.03;
            let cube_distance = (p - Vec2::splat(0.5)).abs().max_element();
            if off_receiver || cube_distance < 0.17 {
                // The plain plane, the background and the cube's top, which occludes the
                // receiver: nothing lights the scene but the caustics, so all stay black.
                assert!(got.max_element() < 1e-4, "pixel ({x},{y}) at {p} is not a visible receiver but got {got}");
                dark[usize::from(!off_receiver)] += 1;
                continue;
            }
            let on_edge = p.abs().max_element() > 0.97 || cube_distance < 0.23 || p.x.abs() < 0.05;
            if on_edge {
                continue;
            }
            let e = irradiance(x, y) / PI * exposure;
            let albedo = got / e;
            // Rgba16Float keeps 11 significant bits: 2⁻¹¹ ≈ 5·10⁻⁴ relative per value,
            // twice (the buffer and the target): 2·10⁻³ covers it.
            let which = ALBEDO.iter().position(|a| (albedo - *a).abs().max_element() < 2e-3 * a.max_element().max(1.0));
            let Some(which) = which else {
                panic!("pixel ({x},{y}) at {p}: {got} is not albedo·E/π·exposure (albedo would be {albedo})");
            };
            seen[which] = true;
            checked += 1;
        }
    }
    assert!(dark[0] > 500 && dark[1] > 30, "too few dark pixels checked (off receiver, on cube): {dark:?}");
    assert!(seen[0] && seen[1], "both texels of the base-colour texture must show");
    assert!(checked > 1500, "only {checked} receiver pixels checked");

    // The same app without injected irradiance and without generators: no pass runs.
    let cameras: Vec<Entity> = renderer.world_mut().query_filtered::<Entity, With<InjectedIrradiance>>().iter(renderer.world_mut()).collect();
    for camera in cameras {
        renderer.world_mut().entity_mut(camera).remove::<InjectedIrradiance>();
    }
    let image = renderer.render(3).unwrap_or_else(|e| panic!("{e}"));
    let report = renderer.pass_report();
    assert!(report.is_empty(), "a scene with nothing to do ran {report:?}");
    assert!(image.pixels.iter().all(|p| p.truncate().max_element() < 1e-4), "no caustics, no light");

    // Invalid parameters: reported once (one warning per marker insertion) and skipped,
    // never a panic.
    #[derive(Resource, Default)]
    struct Reported(Vec<Entity>);
    let world = renderer.world_mut();
    world.init_resource::<Reported>();
    world.add_observer(|insert: On<Insert, InvalidCausticParams>, mut reported: ResMut<Reported>| {
        reported.0.push(insert.entity);
    });
    let bad_generator = world.spawn(CausticGenerator::refractive(0.5)).id();
    let bad_medium = world.spawn(ParticipatingMedium { scattering: -1.0, absorption: Vec3::new(0.1, f32::NAN, 0.1), asymmetry: 0.0 }).id();
    let nan_medium = world.spawn(ParticipatingMedium { scattering: 0.1, absorption: Vec3::new(0.1, f32::NAN, 0.1), asymmetry: 0.0 }).id();
    let water = ParticipatingMedium { scattering: 0.05, absorption: Vec3::splat(0.1), asymmetry: 0.9 };
    let bad_water = world.spawn((CausticGenerator::refractive(0.9), water)).id();
    let good = world.spawn((CausticGenerator::refractive(1.5), water)).id();
    renderer.render(2).unwrap_or_else(|e| panic!("{e}"));
    let world = renderer.world_mut();
    // Setting the same invalid value again, or changing a valid component beside an
    // invalid one, warns no more and keeps the marker.
    world.entity_mut(bad_generator).insert(CausticGenerator::refractive(0.5));
    world.entity_mut(bad_water).insert(ParticipatingMedium { asymmetry: 0.8, ..water });
    renderer.render(2).unwrap_or_else(|e| panic!("{e}"));
    let world = renderer.world_mut();
    let marker = |w: &World, e: Entity| w.get::<InvalidCausticParams>(e).map(|m| m.0.to_string());
    assert!(marker(world, bad_generator).unwrap().contains("index of refraction 0.5"));
    assert!(marker(world, bad_medium).unwrap().contains("scattering"));
    assert!(marker(world, nan_medium).unwrap().contains("absorption"));
    assert!(marker(world, bad_water).unwrap().contains("index of refraction 0.9"));
    assert_eq!(marker(world, good), None);
    let mut reported = world.resource::<Reported>().0.clone();
    reported.sort();
    let mut expected = vec![bad_generator, bad_medium, nan_medium, bad_water];
    expected.sort();
    assert_eq!(reported, expected, "one report per invalid entity");
    // Fixing the value, or removing the invalid component, clears the marker.
    world.entity_mut(bad_generator).insert(CausticGenerator::refractive(1.33));
    world.entity_mut(bad_water).remove::<CausticGenerator>();
    renderer.render(1).unwrap_or_else(|e| panic!("{e}"));
    let world = renderer.world_mut();
    assert_eq!(marker(world, bad_generator), None);
    assert_eq!(marker(world, bad_water), None);

    // Opt-in tagging from materials, as a glTF scene arrives: glass refracts, smooth
    // metal mirrors, the rest receives; meshes outside the marked root are left alone.
    let world = renderer.world_mut();
    let mesh = world.resource_mut::<Assets<Mesh>>().add(Cuboid::default());
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    let glass = materials.add(StandardMaterial { specular_transmission: 1.0, ior: 1.5, ..default() });
    let metal = materials.add(StandardMaterial { metallic: 1.0, perceptual_roughness: 0.0, ..default() });
    let wood = materials.add(StandardMaterial { perceptual_roughness: 0.8, ..default() });
    let root = world.spawn((TagCausticsFromMaterials, Transform::default())).id();
    let spawn = |w: &mut World, m: &Handle<StandardMaterial>, parent: Option<Entity>| {
        let mut e = w.spawn((Mesh3d(mesh.clone()), MeshMaterial3d(m.clone()), Transform::default()));
        if let Some(p) = parent {
            e.insert(ChildOf(p));
        }
        e.id()
    };
    let (g, mirror, floor, outside) =
        (spawn(world, &glass, Some(root)), spawn(world, &metal, Some(root)), spawn(world, &wood, Some(root)), spawn(world, &wood, None));
    renderer.render(1).unwrap_or_else(|e| panic!("{e}"));
    let world = renderer.world_mut();
    assert_eq!(world.get::<CausticGenerator>(g), Some(&CausticGenerator::refractive(1.5)));
    assert_eq!(world.get::<CausticGenerator>(mirror), Some(&CausticGenerator::mirror()));
    assert!(world.get::<CausticReceiver>(floor).is_some());
    assert!(world.get::<CausticReceiver>(outside).is_none() && world.get::<CausticGenerator>(outside).is_none());
}
