//! A `ParticipatingMedium` drawn by Bevy's own volumetric fog (`medium_fog.rs`), held
//! to physics on lavapipe: a lit board seen through a metre of absorbing medium dims
//! by exp(−σₐ ℓ), for a camera with `Caustics` and for one without; a directional
//! light into a slab of scattering medium gives the single-scattering radiance of the
//! analytic integral; caustic light on the board is dimmed once, with the rest of the
//! pixel. Without the medium's `FogVolume` the board is not dimmed and the slab is
//! black.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::camera::Exposure;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::light::{FogVolume, GlobalAmbientLight, VolumetricFog, VolumetricLight};
use bevy::prelude::*;
use bevy_caustics::headless::{HeadlessRenderer, RenderedImage};
use bevy_caustics::pixels::irradiance_image;
use bevy_caustics::{CausticReceiver, Caustics, InjectedIrradiance, ParticipatingMedium};
use std::f32::consts::PI;
use support::{EV100, exposure, render};

const SIZE: u32 = 64;
const SUN: f32 = 10.0;

/// The mean of the image's central 4 × 4 pixels: rays within a fraction of a degree of
/// the view's axis, along which Bevy's march takes the path's true length.
fn centre(image: &RenderedImage) -> Vec3 {
    let c = SIZE / 2;
    (c - 2..c + 2).flat_map(|y| (c - 2..c + 2).map(move |x| (x, y))).map(|(x, y)| image.pixel(x, y).truncate()).sum::<Vec3>() / 16.0
}

/// `(1 − e^{−σD})/σ`, or `D` as σ → 0.
fn integral(sigma: f32, d: f32) -> f32 {
    if sigma > 0.0 { (1.0 - (-sigma * d).exp()) / sigma } else { d }
}

#[test]
fn bevy_fog_dims_what_lies_behind_a_medium_and_scatters_the_sun_in_it() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let world = renderer.world_mut();
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    // A white board 3 m ahead, lit by nothing but its own colour.
    let board = world.resource_mut::<Assets<Mesh>>().add(Rectangle::new(4.0, 4.0));
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { base_color: Color::WHITE, unlit: true, ..default() });
    let board = world.spawn((Mesh3d(board), MeshMaterial3d(white), Transform::from_xyz(0.0, 0.0, -3.0))).id();
    let sun = world
        .spawn((DirectionalLight { illuminance: SUN, shadow_maps_enabled: true, ..default() }, Transform::default().looking_to(Vec3::new(0.0, -1.0, -1.0), Vec3::Y)))
        .id();
    let camera = world
        .spawn((Camera3d::default(), target, Caustics::default(), Tonemapping::None, Msaa::Off, Exposure { ev100: EV100 }, Transform::default().looking_to(Vec3::NEG_Z, Vec3::Y)))
        .id();
    let clear = centre(&render(&mut renderer, 3));
    assert!(clear.x > 0.1, "the board is not seen: {clear}");

    // A metre of medium that only absorbs, σₐ = 0.5, between the camera and the board.
    let medium = ParticipatingMedium { scattering: 0.0, absorption: 0.5, asymmetry: 0.0 };
    let box_ = renderer.world_mut().spawn((medium, Transform::from_xyz(0.0, 0.0, -1.5).with_scale(Vec3::new(4.0, 4.0, 1.0)))).id();
    let dimmed = centre(&render(&mut renderer, 3)) / clear;
    let expected = (-0.5f32).exp();
    eprintln!("behind 1 m of σa = 0.5: {dimmed} of the light, exp(−0.5) = {expected:.4}");
    assert!((dimmed / expected - Vec3::ONE).abs().max_element() < 0.02, "the board dims to {dimmed}, not exp(−0.5) = {expected}");
    let world = renderer.world_mut();
    assert!(world.get::<FogVolume>(box_).is_some(), "the medium brought no FogVolume");
    assert!(world.get::<VolumetricFog>(camera).is_some() && world.get::<VolumetricLight>(sun).is_some(), "the camera or the sun was not given Bevy's fog");

    // A camera without `Caustics` sees the medium as Bevy draws it.
    renderer.world_mut().entity_mut(camera).remove::<Caustics>();
    let dimmed = centre(&render(&mut renderer, 2)) / clear;
    eprintln!("without Caustics: {dimmed}");
    assert!((dimmed / expected - Vec3::ONE).abs().max_element() < 0.02, "without Caustics the board dims to {dimmed}, not {expected}");
    renderer.world_mut().entity_mut(camera).insert(Caustics::default());

    // Caustic light on the board (injected: 10 lux) is dimmed once, by Bevy's fog with
    // the rest of the pixel; the composite leaves the medium to it.
    renderer.world_mut().entity_mut(board).insert(CausticReceiver);
    let unlit = centre(&render(&mut renderer, 2));
    let injected = renderer.world_mut().resource_mut::<Assets<Image>>().add(irradiance_image(SIZE, SIZE, &vec![Vec3::splat(10.0); (SIZE * SIZE) as usize]));
    renderer.world_mut().entity_mut(camera).insert(InjectedIrradiance(injected));
    let caustic = (centre(&render(&mut renderer, 2)) - unlit) / (10.0 / PI * exposure());
    eprintln!("caustic light through the medium: {caustic}");
    assert!((caustic / expected - Vec3::ONE).abs().max_element() < 0.02, "caustic light dims to {caustic}, not once by exp(−0.5) = {expected}");
    renderer.world_mut().entity_mut(camera).remove::<InjectedIrradiance>();

    // Single scattering: a slab 1 m deep along the view and 1 m high, its top 0.1 m
    // above the eye ray, lit from above and behind it; black behind. The radiance at the
    // eye is ∫ σₛ p(θ) E e^{−σₜ s} e^{−σₜ ℓ(s)} ds, with ℓ(s) the light's path inside.
    renderer.world_mut().despawn(board);
    let (sigma_s, sigma_a, g) = (0.2, 0.02, 0.4);
    let medium = ParticipatingMedium { scattering: sigma_s, absorption: sigma_a, asymmetry: g };
    let (top, near, depth) = (0.1f32, 1.0f32, 1.0f32);
    renderer.world_mut().entity_mut(box_).insert((medium, Transform::from_xyz(0.0, top - 0.5, -near - depth / 2.0).with_scale(Vec3::new(4.0, 1.0, depth))));
    let seen = centre(&render(&mut renderer, 3));
    let sigma_t = sigma_s + sigma_a;
    // The light travels down and away from the eye; the scattered light comes back
    // along +z: cos θ = (0, −1, −1)/√2 · (0, 0, 1).
    let cos = -(0.5f32).sqrt();
    let phase = (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos).powf(1.5));
    // Back along the light from the point at depth s: up and towards the eye, out
    // through the top (0.1 m up) or the near face (s − near back), √2 apart a metre.
    let steps = 4000;
    let radiance: f32 = (0..steps)
        .map(|i| {
            let s = near + (i as f32 + 0.5) / steps as f32 * depth;
            let inside = (2.0f32).sqrt() * top.min(s - near);
            sigma_s * phase * SUN * (-sigma_t * (s + inside)).exp() * (sigma_t * near).exp() * depth / steps as f32
        })
        .sum();
    let expected = radiance * exposure();
    eprintln!("scattered sunlight: {seen} against {expected:.5} (σₜ-only path {:.5})", sigma_s * phase * SUN * integral(sigma_t, depth) * exposure());
    assert!(((seen / expected) - Vec3::ONE).abs().max_element() < 0.05, "single scattering: {seen} against the analytic {expected}");
}
