//! Bevy's lights as `bevy_pbr` lights a receiver, end to end: a flat plate of IOR 1
//! bends nothing and reflects nothing, so the caustic it casts onto the floor is the
//! light that reaches the floor through it — exactly the floor's direct light as
//! Bevy's own lighting draws it (lumens to candela, the spot's cone, the range's
//! window, exposure and the composite). The plate is invisible to the camera and casts
//! no shadow, so the floor gets both: the caustic doubles every pixel under the plate.
//!
//! The camera looks straight down orthographically and the compared pixels see their
//! light within 25° of the normal, where Bevy's Burley diffuse is Lambert's to 10⁻⁵;
//! the floor has no specular reflectance.

mod support;

use bevy::camera::visibility::RenderLayers;
use bevy::light::{GlobalAmbientLight, NotShadowCaster};
use bevy::prelude::*;
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::read_scene::bevy_mesh;
use bevy_caustics::{CausticGenerator, CausticReceiver};
use caustics_core::mesh::TriMesh;
use caustics_core::metrics::relative_l2;
use support::{render_caustics, render_without_caustics};

const SIZE: u32 = 64;
const VIEW: f32 = 2.0;

/// World point seen at the centre of pixel (x, y): screen right = +x, screen up = −z.
fn world_at(x: u32, y: u32) -> Vec3 {
    let s = VIEW / SIZE as f32;
    Vec3::new((x as f32 + 0.5 - SIZE as f32 / 2.0) * s, 0.0, (y as f32 + 0.5 - SIZE as f32 / 2.0) * s)
}

/// Spawns one light into the world.
type SpawnLight = Box<dyn Fn(&mut World) -> Entity>;

#[test]
fn an_ior_one_plate_casts_exactly_bevys_direct_light() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let world = renderer.world_mut();
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(4.0)).mesh());
    let matte = StandardMaterial { perceptual_roughness: 1.0, reflectance: 0.0, ..default() };
    let matte = world.resource_mut::<Assets<StandardMaterial>>().add(matte);
    world.spawn((Mesh3d(floor), MeshMaterial3d(matte.clone()), CausticReceiver));
    let plate = TriMesh::heightfield(97, 3.0, |_, _| 1.0, |_, _| caustics_core::glam::Vec3::Y).unwrap();
    let plate = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&plate));
    world.spawn((
        Mesh3d(plate),
        MeshMaterial3d(matte),
        CausticGenerator::refractive(1.0),
        RenderLayers::layer(1),
        NotShadowCaster,
        Transform::from_xyz(0.013, 0.0, 0.007),
    ));
    world.spawn(support::top_down_camera(target, VIEW, SIZE, Vec3::ZERO));

    let down = Transform::default().looking_to(Vec3::NEG_Y, Vec3::Z);
    let lights: [(&str, SpawnLight); 3] = [
        ("directional", Box::new(move |w| w.spawn((DirectionalLight { illuminance: 10.0, shadow_maps_enabled: false, ..default() }, down)).id())),
        (
            "point",
            Box::new(|w| {
                let light = PointLight { intensity: 4.0 * std::f32::consts::PI * 20.0, range: 20.0, shadow_maps_enabled: false, ..default() };
                w.spawn((light, Transform::from_xyz(0.1, 2.0, -0.05))).id()
            }),
        ),
        (
            "spot with a range",
            Box::new(|w| {
                let light = SpotLight {
                    intensity: 4.0 * std::f32::consts::PI * 20.0,
                    range: 3.0,
                    inner_angle: 0.2,
                    outer_angle: 0.4,
                    shadow_maps_enabled: false,
                    ..default()
                };
                w.spawn((light, Transform::from_xyz(-0.1, 2.0, 0.05).looking_to(Vec3::NEG_Y, Vec3::Z))).id()
            }),
        ),
    ];
    for (name, spawn) in &lights {
        let light = spawn(renderer.world_mut());
        let position = renderer.world_mut().get::<Transform>(light).unwrap().translation;
        let direct = render_without_caustics(&mut renderer, 3);
        // The volumes are built off the frame: wait for this light's.
        let with = render_caustics(&mut renderer, 2);
        // Pixels whose light arrives within 25° of the floor's normal; for the spot, inside
        // its inner cone, and its falloff band apart, where the volumes take the cone at
        // the plate's vertices and the band's kinks fall inside triangles.
        let angle = |i: usize| {
            let p = world_at(i as u32 % SIZE, i as u32 / SIZE);
            let to_light = if *name == "directional" { Vec3::Y } else { (position - p).normalize() };
            to_light.y.acos()
        };
        let compare = |keep: &dyn Fn(usize) -> bool| -> (f32, usize) {
            let (caustic, bevy): (Vec<f32>, Vec<f32>) =
                (0..(SIZE * SIZE) as usize).filter(|&i| keep(i)).map(|i| (with.pixels[i].x - direct.pixels[i].x, direct.pixels[i].x)).unzip();
            (relative_l2(&caustic, &bevy), bevy.len())
        };
        // The plate's triangles span 0.03 rad seen from the lights: a triangle's width
        // inside the inner cone (0.2 rad).
        let cone = if name.starts_with("spot") { 0.16 } else { 25f32.to_radians() };
        let (error, pixels) = compare(&|i| angle(i) < cone);
        eprintln!("{name}: the plate's caustic against Bevy's direct light on {pixels} pixels: relative L2 {error:.2e}");
        assert!(pixels > 100, "{name}: {pixels} pixels compared");
        assert!(error < 5e-3, "{name}: relative L2 {error}");
        if name.starts_with("spot") {
            let (band, pixels) = compare(&|i| (0.2..0.38).contains(&angle(i)));
            eprintln!("{name}, its falloff band: relative L2 {band:.2e} on {pixels} pixels");
            assert!(band < 0.03, "{name}: falloff band relative L2 {band}");
        }
        renderer.world_mut().despawn(light);
    }
}
