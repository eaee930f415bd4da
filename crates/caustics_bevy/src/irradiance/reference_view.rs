//! A view's caustic irradiance for the comparison against the ground-truth tracer
//! ([`crate::comparison`]): copied out each frame for reading back, and a split view
//! whose right half shows a reference irradiance in place of what the techniques drew.
//! Both run after every technique has drawn into the buffer, before the composite
//! shows it.

use super::{InjectPipeline, ViewCausticIrradiance};
use crate::cpu_time::{CausticCpuTime, timed};
use bevy::asset::RenderAssetUsages;
use bevy::core_pipeline::{Core3dSystems, core_3d::main_opaque_pass_3d, schedule::Core3d};
use bevy::prelude::*;
use bevy::render::{
    RenderApp,
    extract_component::{ExtractComponent, ExtractComponentPlugin},
    render_asset::RenderAssets,
    render_resource::*,
    renderer::{RenderContext, ViewQuery},
    texture::GpuImage,
    view::{ViewUniformOffset, ViewUniforms},
};

/// Copies the view's caustic irradiance buffer (irradiance times the view's exposure,
/// capped; `Rgba16Float`; the camera's viewport) into this image every frame, for
/// Bevy's `Readback::texture`. [`capture_image`] makes one of the right size.
#[derive(Component, Clone, Debug, ExtractComponent)]
pub struct CaptureCausticIrradiance(pub Handle<Image>);

/// Shows this irradiance image (as [`super::InjectedIrradiance`] reads one) in the
/// right half of the view in place of what the techniques drew there: the techniques
/// on the left, a reference on the right.
#[derive(Component, Clone, Debug, ExtractComponent)]
pub struct ReferenceSplit(pub Handle<Image>);

/// An image for [`CaptureCausticIrradiance`] of a viewport `size` pixels.
pub fn capture_image(size: UVec2) -> Image {
    let extent = Extent3d { width: size.x.max(1), height: size.y.max(1), depth_or_array_layers: 1 };
    let mut image = Image::new_uninit(extent, TextureDimension::D2, super::CAUSTIC_IRRADIANCE_FORMAT, RenderAssetUsages::RENDER_WORLD);
    image.texture_descriptor.usage = TextureUsages::COPY_DST | TextureUsages::COPY_SRC | TextureUsages::TEXTURE_BINDING;
    image
}

pub(super) fn build(app: &mut App) {
    app.add_plugins((ExtractComponentPlugin::<CaptureCausticIrradiance>::default(), ExtractComponentPlugin::<ReferenceSplit>::default()));
    let cpu = CausticCpuTime::of(app).render;
    if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
        render_app.add_systems(Core3d, timed(&cpu, split_and_capture).in_set(Core3dSystems::MainPass).before(main_opaque_pass_3d));
    }
}

/// Copies the view's buffer into its capture image, then draws the reference into the
/// right half of its viewport.
fn split_and_capture(
    view: ViewQuery<(&ViewCausticIrradiance, &ViewUniformOffset, Option<&CaptureCausticIrradiance>, Option<&ReferenceSplit>)>,
    images: Res<RenderAssets<GpuImage>>,
    inject: Res<InjectPipeline>,
    cache: Res<PipelineCache>,
    view_uniforms: Res<ViewUniforms>,
    mut ctx: RenderContext,
) {
    let (buffer, view_offset, capture, split) = view.into_inner();
    let (corner, size) = buffer.region();
    if let Some(target) = capture.and_then(|c| images.get(&c.0)) {
        let copied = size.min(UVec2::new(target.texture.width(), target.texture.height()));
        ctx.command_encoder().copy_texture_to_texture(
            TexelCopyTextureInfo {
                texture: &buffer.texture.texture,
                mip_level: 0,
                origin: Origin3d { x: corner.x, y: corner.y, z: 0 },
                aspect: TextureAspect::All,
            },
            target.texture.as_image_copy(),
            Extent3d { width: copied.x, height: copied.y, depth_or_array_layers: 1 },
        );
    }
    let Some(reference) = split.and_then(|s| images.get(&s.0)) else { return };
    let device = ctx.render_device().clone();
    let mut pass = buffer.accumulate(ctx.command_encoder(), "caustic_reference_split");
    let half = size.x / 2;
    pass.set_scissor_rect(corner.x + half, corner.y, size.x - half, size.y);
    inject.draw(&mut pass, Some(reference), view_offset, (&device, &cache, &view_uniforms));
}
