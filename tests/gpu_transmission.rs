//! Caustics seen through glass drawn the Bevy way, on lavapipe: a floor receiver under a
//! slab of `StandardMaterial::specular_transmission` glass, seen from straight above.
//! Bevy's transmission samples a copy of the opaque image; the composite draws the
//! caustics into that image before the copy, so they show through the slab dimmed
//! exactly as the floor's own light is: the caustic seen through the slab over the
//! caustic seen without it equals the floor's sunlit radiance through the slab over its
//! radiance without it. Drawn after the copy (in the transparent phase, as it once
//! was), the slab hides the caustics: the ratio is 0.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::prelude::*;
use bevy_caustics::headless::{HeadlessRenderer, RenderedImage};
use bevy_caustics::pixels::irradiance_image;
use bevy_caustics::{CausticReceiver, InjectedIrradiance};
use support::{render, top_down_camera};

const SIZE: u32 = 32;
/// The caustic irradiance injected on the whole floor (lux).
const CAUSTIC: f32 = 2_000.0;

/// The mean red radiance of the pixels in the middle of the view, where the slab covers
/// the floor.
fn middle(image: &RenderedImage) -> f32 {
    let (lo, hi) = (SIZE / 4, 3 * SIZE / 4);
    let pixels: Vec<f32> = (lo..hi).flat_map(|y| (lo..hi).map(move |x| (x, y))).map(|(x, y)| image.pixel(x, y).x).collect();
    pixels.iter().sum::<f32>() / pixels.len() as f32
}

#[test]
fn caustics_show_through_transmissive_glass_as_the_floor_does() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let world = renderer.world_mut();
    let injected = world.resource_mut::<Assets<Image>>().add(irradiance_image(1, 1, &[Vec3::splat(CAUSTIC)]));
    let camera = world.spawn((top_down_camera(target, 4.0, SIZE, Vec3::ZERO), Msaa::Off)).id();
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(8.0, 8.0));
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 1.0, ..default() });
    world.spawn((Mesh3d(floor), MeshMaterial3d(white), CausticReceiver));
    world.spawn((DirectionalLight { illuminance: 10_000.0, ..default() }, Transform::default().looking_to(Vec3::new(0.3, -1.0, 0.2), Vec3::X)));
    world.insert_resource(bevy::light::GlobalAmbientLight { brightness: 0.0, ..default() });
    let slab = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(2.5, 0.1, 2.5));
    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::WHITE,
        specular_transmission: 1.0,
        thickness: 0.1,
        ior: 1.5,
        perceptual_roughness: 0.05,
        ..default()
    });

    let frame = |renderer: &mut HeadlessRenderer, caustics: bool| {
        let mut camera = renderer.world_mut().entity_mut(camera);
        if caustics {
            camera.insert(InjectedIrradiance(injected.clone()));
        } else {
            camera.remove::<InjectedIrradiance>();
        }
        middle(&render(renderer, 3))
    };
    let (lit, caustic_lit) = (frame(&mut renderer, false), frame(&mut renderer, true));
    let slab = renderer.world_mut().spawn((Mesh3d(slab), MeshMaterial3d(glass), Transform::from_xyz(0.0, 1.0, 0.0))).id();
    let (through, caustic_through) = (frame(&mut renderer, false), frame(&mut renderer, true));
    renderer.world_mut().despawn(slab);

    let floor_ratio = through / lit;
    let caustic_ratio = (caustic_through - through) / (caustic_lit - lit);
    eprintln!("through the slab: the floor's own light × {floor_ratio:.4}, its caustics × {caustic_ratio:.4}");
    assert!(caustic_lit - lit > 0.0, "the injected caustics do not show on the bare floor");
    assert!((0.5..1.0).contains(&floor_ratio), "the slab passes {floor_ratio} of the floor's light");
    assert!((caustic_ratio - floor_ratio).abs() < 0.02 * floor_ratio, "the caustics pass × {caustic_ratio}, the floor's light × {floor_ratio}");
}
