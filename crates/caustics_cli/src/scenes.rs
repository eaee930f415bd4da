//! Scenes the CLI can open: the built-in procedural ones by name, a JSON scene
//! description (the format of `shared/reference`), or a glTF 2.0 file through Bevy's
//! loader and the plugin's automatic tagging.

use caustics_core::estimate::GridRegion;
use caustics_core::glam::Affine3A;
use caustics_core::glam::Vec3;
use caustics_core::mesh::TriMesh;
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{Generator, Light, LightKind};
use caustics_core::scenes::{BenchScene, POOL_WAVES, SceneDescription, boxed_pool, glass_sphere, metal_ring, roofed_pool, wave_heightfield, wave_pool};
use caustics_core::view::{PinholeCamera, SceneView};
use std::path::Path;

/// Names of the built-in scenes: one generator each (the pool, the sphere, the ring),
/// then scenes that mix generator kinds and occluders.
pub const BUILT_IN: [&str; 7] = ["pool", "sphere", "ring", "roofed_pool", "boxed_pool", "ball_pool", "mirror_bunny"];

/// A built-in scene by name, at the default tessellation.
pub fn built_in(name: &str) -> Option<BenchScene> {
    let default = match name {
        "pool" | "roofed_pool" | "boxed_pool" | "ball_pool" => 128,
        "sphere" => 64,
        "ring" | "mirror_bunny" => 256,
        _ => return None,
    };
    tessellated(name, default)
}

/// A built-in scene with its tessellated generator cut into `cells` (a pool's water
/// grid has `cells`² cells, the sphere and the rings `cells` segments around; the
/// ball beside the pool and the bunny keep theirs).
pub fn tessellated(name: &str, cells: usize) -> Option<BenchScene> {
    match name {
        "pool" => Some(wave_pool(cells + 1, 128)),
        "sphere" => Some(glass_sphere(cells)),
        "ring" => Some(metal_ring(cells)),
        "roofed_pool" => Some(roofed_pool(cells + 1, 128)),
        "boxed_pool" => Some(boxed_pool(cells + 1, 128)),
        "ball_pool" => Some(ball_beside_pool(cells)),
        "mirror_bunny" => Some(ring_beside_bunny(cells)),
        _ => None,
    }
}

/// The pool's rippled water over x ∈ [−2, 0] (`cells`² cells) beside a glass ball
/// (IOR 1.5, radius 0.3, 64 segments) standing over the floor at x = 0.55, under the
/// pool's sun: open and closed refractors side by side.
fn ball_beside_pool(cells: usize) -> BenchScene {
    let mut bench = wave_pool(cells + 1, 128);
    bench.scene.generators[0].mesh = wave_heightfield(cells + 1, 2.0, 0.8, &POOL_WAVES).transformed(&Affine3A::from_translation(Vec3::new(-1.0, 0.0, 0.0)));
    bench
        .scene
        .generators
        .push(Generator::new(TriMesh::uv_sphere(Vec3::new(0.55, 0.45, 0.0), 0.3, 32, 64), SpecularInteraction::Refract { ior: 1.5, dispersion: None }));
    bench.name = "ball_pool".into();
    bench
}

/// A glass Stanford bunny (0.6 m tall, IOR 1.5, floating 0.3 m up) beside a polished
/// ring (radius 0.35, `segments` around) under a point light low on the left: a closed
/// refractor and a mirror.
fn ring_beside_bunny(segments: usize) -> BenchScene {
    let mut bench = metal_ring(segments);
    bench.scene.lights = vec![Light::white(LightKind::Point { position: Vec3::new(-2.0, 1.6, 0.2), intensity: 20.0 })];
    bench.scene.generators[0].mesh = TriMesh::solid_ring(Vec3::new(0.5, 0.0, 0.0), 0.35, 0.38, 0.2, segments);
    let bunny = TriMesh::from_obj(include_str!("../../../assets/models/bunny.obj")).expect("the bunny asset parses (tested)");
    let place = Affine3A::from_translation(Vec3::new(-0.5, 0.3, 0.0)) * Affine3A::from_scale(Vec3::splat(0.06));
    bench.scene.generators.push(Generator::new(bunny.transformed(&place), SpecularInteraction::Refract { ior: 1.5, dispersion: None }));
    bench.name = "mirror_bunny".into();
    bench
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

/// A frame saved by the live comparison ([`SceneView`]) when `spec` is a `.json` file
/// that holds one; `None` for any other scene.
pub fn open_scene_view(spec: &str) -> Result<Option<SceneView>, String> {
    let path = Path::new(spec);
    if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) || !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|e| format!("{spec}: {e}"))?;
    if !SceneView::is_scene_view(&text) {
        return Ok(None);
    }
    SceneView::from_json(&text).map(Some).map_err(|e| format!("{spec}: {e}"))
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
