//! What the GPU tests share: a camera looking straight down at a known exposure, and
//! the caustic irradiance read back from two of its images, GPU buffers read back. Each
//! test uses a part of it.
#![allow(dead_code)]

use bevy::camera::{Exposure, RenderTarget};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy_caustics::Caustics;
use bevy_caustics::headless::{HeadlessRenderer, RenderedImage};
use std::f32::consts::PI;

/// The cameras' exposure value.
pub const EV100: f32 = 2.0;

/// The linear exposure Bevy applies at [`EV100`].
pub fn exposure() -> f32 {
    1.0 / (1.2 * 2f32.powf(EV100))
}

/// An orthographic HDR camera 5 m above `centre`, looking down, `view` metres across
/// `pixels` pixels (screen right = +x, screen up = −z), without tonemapping.
pub fn top_down_camera(target: RenderTarget, view: f32, pixels: u32, centre: Vec3) -> impl Bundle {
    (
        Camera3d::default(),
        target,
        Caustics::default(),
        Tonemapping::None,
        Exposure { ev100: EV100 },
        Projection::from(OrthographicProjection { scale: view / pixels as f32, ..OrthographicProjection::default_3d() }),
        Transform::from_translation(centre + 5.0 * Vec3::Y).looking_at(centre, Vec3::NEG_Z),
    )
}

/// The floor point (y = 0) seen at the centre of pixel (x, y) by [`top_down_camera`]
/// centred on the origin, `view` metres across `pixels`: screen right = +x, screen
/// up = −z.
pub fn floor_point(x: u32, y: u32, pixels: u32, view: f32) -> Vec3 {
    let s = view / pixels as f32;
    Vec3::new((x as f32 + 0.5 - pixels as f32 / 2.0) * s, 0.0, (y as f32 + 0.5 - pixels as f32 / 2.0) * s)
}

/// Caustic irradiance per pixel on a white Lambertian receiver: this image minus the
/// one without caustics, over albedo/π · exposure (the composite's radiance).
pub fn caustic_irradiance(with: &RenderedImage, without: &RenderedImage) -> Vec<f32> {
    with.pixels.iter().zip(&without.pixels).map(|(a, b)| (a.x - b.x) * PI / exposure()).collect()
}

/// No ambient light, a black background, and a white matte floor 4 m square at y = 0
/// that receives caustics: the scene around a generator under test. Returns the white
/// material, for the generator.
pub fn white_floor_in_the_dark(world: &mut World) -> Handle<StandardMaterial> {
    use bevy::light::GlobalAmbientLight;
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(2.0)).mesh());
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 1.0, ..default() });
    world.spawn((Mesh3d(floor), MeshMaterial3d(white.clone()), bevy_caustics::CausticReceiver));
    white
}

/// The bytes of a GPU buffer of the render world (`COPY_SRC`), copied back.
pub fn read_buffer(renderer: &mut HeadlessRenderer, buffer: &bevy::render::render_resource::Buffer) -> Vec<u8> {
    use bevy::render::render_resource::{BufferDescriptor, BufferUsages, CommandEncoderDescriptor, MapMode, PollType};
    use bevy::render::renderer::{RenderDevice, RenderQueue};
    let world = renderer.app.sub_app_mut(bevy::render::RenderApp).world_mut();
    let (device, queue) = (world.resource::<RenderDevice>().clone(), world.resource::<RenderQueue>().clone());
    let usage = BufferUsages::COPY_DST | BufferUsages::MAP_READ;
    let staging = device.create_buffer(&BufferDescriptor { label: Some("test_readback"), size: buffer.size(), usage, mapped_at_creation: false });
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, buffer.size());
    queue.submit([encoder.finish()]);
    let slice = staging.slice(..);
    slice.map_async(MapMode::Read, |mapped| mapped.expect("the readback buffer maps"));
    device.poll(PollType::wait_indefinitely()).expect("the GPU finishes");
    slice.get_mapped_range().to_vec()
}

/// Renders `frames` frames with no caustic technique available, so that every
/// generator casts nothing: the baseline that caustic irradiance is measured against.
pub fn render_without_caustics(renderer: &mut HeadlessRenderer, frames: u32) -> RenderedImage {
    use bevy_caustics::AvailableCausticTechniques;
    let available = renderer.world_mut().resource::<AvailableCausticTechniques>().clone();
    renderer.world_mut().insert_resource(AvailableCausticTechniques(Default::default()));
    let image = render(renderer, frames);
    renderer.world_mut().insert_resource(available);
    image
}

/// Renders `frames` frames, panicking with the renderer's error.
pub fn render(renderer: &mut HeadlessRenderer, frames: u32) -> RenderedImage {
    renderer.render(frames).unwrap_or_else(|e| panic!("{e}"))
}

/// Renders until the caustics for the current scene are in, then `frames` more: the
/// volumes are built off the frame, so after `render_without_caustics` (which takes
/// the generators' technique away) they come back some frames later.
pub fn render_caustics(renderer: &mut HeadlessRenderer, frames: u32) -> RenderedImage {
    use bevy_caustics::warped_volumes::CausticVolumes;
    let built = renderer.world_mut().resource::<CausticVolumes>().generation;
    for _ in 0..100 {
        render(renderer, 1);
        let generation = renderer.world_mut().resource::<CausticVolumes>().generation;
        let report = renderer.pass_report();
        if generation > built || report.views("caustic map projection") + report.views("pool floor") > 0 {
            break;
        }
    }
    render(renderer, frames)
}
