//! Scenes the CLI can open: the built-in procedural ones by name, a JSON scene
//! description (the format of `shared/reference`), or a glTF 2.0 file through Bevy's
//! loader and the plugin's automatic tagging.

use caustics_core::estimate::GridRegion;
use caustics_core::glam::Vec3;
use caustics_core::scenes::{BenchScene, SceneDescription, glass_sphere, metal_ring, wave_pool};
use caustics_core::view::PinholeCamera;
use std::path::Path;

/// Names of the built-in scenes.
pub const BUILT_IN: [&str; 3] = ["pool", "sphere", "ring"];

/// A built-in scene by name, at the default tessellation.
pub fn built_in(name: &str) -> Option<BenchScene> {
    let default = match name {
        "pool" => 128,
        "sphere" => 64,
        "ring" => 256,
        _ => return None,
    };
    tessellated(name, default)
}

/// A built-in scene with its generator cut into `cells` (the pool's water grid has
/// `cells`² cells, the sphere and the ring `cells` segments around).
pub fn tessellated(name: &str, cells: usize) -> Option<BenchScene> {
    match name {
        "pool" => Some(wave_pool(cells + 1, 128)),
        "sphere" => Some(glass_sphere(cells)),
        "ring" => Some(metal_ring(cells)),
        _ => None,
    }
}

/// A scene with a camera to view it from.
pub struct LoadedScene {
    pub bench: BenchScene,
    pub camera: Option<PinholeCamera>,
}

/// Opens `spec`: a built-in name, a `.json` description or a `.gltf`/`.glb` file.
pub fn open(spec: &str, cells: usize) -> Result<LoadedScene, String> {
    if let Some(mut bench) = built_in(spec) {
        (bench.region.nu, bench.region.nv) = (cells, cells);
        return Ok(LoadedScene { bench, camera: None });
    }
    let path = Path::new(spec);
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if !path.exists() {
        return Err(format!("{spec}: no such file, and not a built-in scene ({})", BUILT_IN.join(", ")));
    }
    match ext.as_str() {
        "json" => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{spec}: {e}"))?;
            let desc = SceneDescription::from_json(&text).map_err(|e| format!("{spec}: {e}"))?;
            Ok(LoadedScene { bench: desc.build(cells).map_err(|e| format!("{spec}: {e}"))?, camera: None })
        }
        "gltf" | "glb" => crate::gltf::load(path, cells),
        _ => Err(format!("{spec}: unknown scene format (expected .gltf, .glb or .json)")),
    }
}

/// A camera looking at the generators from above and to the side.
pub fn default_camera(bench: &BenchScene, width: u32, height: u32) -> PinholeCamera {
    let region: &GridRegion = &bench.region;
    let center = region.origin + 0.5 * (region.edge_u + region.edge_v);
    let size = region.edge_u.length().max(region.edge_v.length());
    let top = bench.scene.generator_bounds().map_or(center.y + size, |(_, hi)| hi.y);
    PinholeCamera {
        position: center + Vec3::new(0.0, (top - center.y) + 1.2 * size, 1.4 * size),
        look_at: center,
        up: Vec3::Y,
        fov_y: 45f32.to_radians(),
        width,
        height,
    }
}
