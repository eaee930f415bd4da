//! Writing linear float images: EXR as they are, PNG through an exposure and sRGB.

use caustics_core::glam::Vec3 as Rgb;
use std::path::Path;

/// Writes linear RGB as a 32-bit float OpenEXR file.
pub fn write_exr(path: &Path, width: u32, height: u32, pixels: &[Rgb]) -> Result<(), String> {
    use image::ImageEncoder;
    if pixels.len() != (width * height) as usize {
        return Err("image size does not match its pixels".into());
    }
    let bytes: Vec<u8> = pixels.iter().flat_map(|p| p.to_array()).flat_map(f32::to_le_bytes).collect();
    let file = std::fs::File::create(path).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    image::codecs::openexr::OpenExrEncoder::new(std::io::BufWriter::new(file))
        .write_image(&bytes, width, height, image::ExtendedColorType::Rgb32F)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Writes linear RGB as an 8-bit sRGB PNG, scaled so that `white` maps to 1, with a
/// Reinhard shoulder so that focal lines keep their shape instead of clipping.
pub fn write_png(path: &Path, width: u32, height: u32, pixels: &[Rgb], white: f32) -> Result<(), String> {
    let scale = 1.0 / white.max(1e-12);
    let data: Vec<u8> = pixels
        .iter()
        .flat_map(|p| {
            p.to_array().map(|c| {
                let x = (c * scale).max(0.0);
                let x = x / (1.0 + x / 4.0) * 1.25; // Reinhard with white point 4
                (linear_to_srgb(x.min(1.0)) * 255.0 + 0.5) as u8
            })
        })
        .collect();
    image::RgbImage::from_raw(width, height, data)
        .ok_or("image size does not match its pixels")?
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

fn linear_to_srgb(x: f32) -> f32 {
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 }
}

/// A robust white level: the given percentile of the non-zero luminances.
pub fn percentile_white(pixels: &[Rgb], percentile: f32) -> f32 {
    let mut l: Vec<f32> = pixels.iter().map(|p| p.max_element()).filter(|&v| v > 0.0).collect();
    if l.is_empty() {
        return 1.0;
    }
    l.sort_by(f32::total_cmp);
    l[((l.len() - 1) as f32 * percentile) as usize]
}
