//! Pixels between the GPU and the CPU: texture rows read back without wgpu's padding,
//! half floats decoded, and an irradiance image for [`crate::InjectedIrradiance`].

use bevy::asset::RenderAssetUsages;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};

/// Texture bytes copied out with every row padded to wgpu's copy alignment, packed:
/// `packed` bytes a row.
pub fn unpad_rows(bytes: &[u8], packed: usize) -> Vec<u8> {
    let padded = packed.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as usize);
    bytes.chunks_exact(padded).flat_map(|r| &r[..packed]).copied().collect()
}

/// Rgba16Float bytes to linear RGBA.
pub fn decode_rgba16f(bytes: &[u8]) -> Vec<Vec4> {
    bytes.chunks_exact(8).map(|p| Vec4::from_array(std::array::from_fn(|c| f16_to_f32(u16::from_le_bytes([p[2 * c], p[2 * c + 1]]))))).collect()
}

/// IEEE 754 half to single precision.
pub fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exponent = (h >> 10) & 0x1f;
    let mantissa = (h & 0x3ff) as f32;
    sign * match exponent {
        0 => mantissa * 2f32.powi(-24),
        0x1f if mantissa == 0.0 => f32::INFINITY,
        0x1f => f32::NAN,
        e => (1.0 + mantissa / 1024.0) * 2f32.powi(e as i32 - 15),
    }
}

/// An `Rgba32Float` image of irradiance (lux) from linear RGB values (row-major),
/// ready to use as [`crate::InjectedIrradiance`].
pub fn irradiance_image(width: u32, height: u32, values: &[Vec3]) -> Image {
    let data = values.iter().flat_map(|v| [v.x, v.y, v.z, 1.0]).flat_map(f32::to_le_bytes).collect();
    Image::new(Extent3d { width, height, depth_or_array_layers: 1 }, TextureDimension::D2, data, TextureFormat::Rgba32Float, RenderAssetUsages::RENDER_WORLD)
}
