//! What the GPU tests share: a camera looking straight down at a known exposure, and
//! the caustic irradiance read back from two of its images.

use bevy::camera::{Exposure, Hdr, RenderTarget};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
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
        Hdr,
        Tonemapping::None,
        Exposure { ev100: EV100 },
        Projection::from(OrthographicProjection { scale: view / pixels as f32, ..OrthographicProjection::default_3d() }),
        Transform::from_translation(centre + 5.0 * Vec3::Y).looking_at(centre, Vec3::NEG_Z),
    )
}

/// Caustic irradiance per pixel on a white Lambertian receiver: this image minus the
/// one without caustics, over albedo/π · exposure (the composite's radiance).
pub fn caustic_irradiance(with: &RenderedImage, without: &RenderedImage) -> Vec<f32> {
    with.pixels.iter().zip(&without.pixels).map(|(a, b)| (a.x - b.x) * PI / exposure()).collect()
}

/// Renders `frames` frames, panicking with the renderer's error.
pub fn render(renderer: &mut HeadlessRenderer, frames: u32) -> RenderedImage {
    renderer.render(frames).unwrap_or_else(|e| panic!("{e}"))
}
