//! The light-space images photons are traced in, as a GPU rasterises them from a
//! [`LightView`] — and their CPU twin, which casts one ray through each texel centre
//! (where a rasteriser samples):
//!
//! - **front**: the nearest generator surface that faces the light (back faces culled,
//!   depth test "less"): where each photon meets a specular surface first;
//! - **back**: the farthest generator surface that faces away (front faces culled,
//!   depth test "greater"): the far side of a closed refractor, where the photon leaves
//!   it (Wyman 2005's back-face map);
//! - **receivers**: the nearest surface that is not a generator (no culling): where
//!   photons land, and the "shadow map" that keeps caustic light off receivers hidden
//!   from the light.

use super::light_view::LightView;
use crate::bvh::SceneBvh;
use crate::scene::{Scene, Sides};
use glam::Vec3;
use rayon::prelude::*;

/// The depth a map holds where it saw nothing.
pub const NO_SURFACE: f32 = f32::MAX;

/// One texel of the front or back map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    /// View depth of the surface, [`NO_SURFACE`] where there is none.
    pub depth: f32,
    /// The smooth shading normal there (unit, world space, as the mesh orients it).
    pub normal: Vec3,
    /// Index of the generator (into the scene's generators, the GPU's materials).
    pub material: u32,
}

impl SurfaceSample {
    /// A texel that saw no surface.
    pub const NONE: Self = Self { depth: NO_SURFACE, normal: Vec3::ZERO, material: 0 };

    /// Whether the texel saw a surface.
    #[inline]
    pub fn is_surface(&self) -> bool {
        self.depth < NO_SURFACE
    }
}

/// The three maps of one light view: front and back at the photon buffer's resolution,
/// receivers at the caustic map's.
#[derive(Clone, Debug, PartialEq)]
pub struct LightMaps {
    /// Side of the front and back maps (the photon buffer's), in texels.
    pub photon_resolution: u32,
    /// Row-major front map: the nearest generator surface facing the light.
    pub front: Vec<SurfaceSample>,
    /// Row-major back map: the farthest generator surface facing away from the light.
    pub back: Vec<SurfaceSample>,
    /// Side of the receiver map (the caustic map's), in texels.
    pub map_resolution: u32,
    /// Row-major view depths of the nearest receiver, [`NO_SURFACE`] where none.
    pub receivers: Vec<f32>,
}

/// Surfaces a ray may pass before the one a culled rasteriser would keep.
const MAX_SKIPPED: usize = 16;

impl LightMaps {
    /// The maps `scene` rasterises into `view`, by ray casting through texel centres:
    /// the CPU twin of the GPU's light-space passes.
    pub fn ray_cast(scene: &Scene, view: &LightView, photon_resolution: u32, map_resolution: u32) -> Self {
        let generators = SceneBvh::build(&Scene { generators: scene.generators.clone(), ..Scene::default() });
        // The front map keeps the back faces of open double-sided generators (the GPU
        // draws them without culling): their backs reflect and refract too.
        let both_sides: Vec<bool> = scene.generators.iter().map(|g| g.sides() == Sides::Both).collect();
        let no_generator = vec![false; scene.generators.len()];
        let receivers = SceneBvh::build(&Scene { receivers: scene.receivers.clone(), ..Scene::default() });
        let texels = |resolution: u32| (0..resolution * resolution).into_par_iter().map(move |i| (i % resolution, i / resolution));
        let front = texels(photon_resolution)
            .map(|(x, y)| {
                let (origin, dir) = view.ray(view.photon_uv(x, y, photon_resolution));
                first_facing(scene, &generators, view, (origin, dir), false, &both_sides)
            })
            .collect();
        let back = texels(photon_resolution)
            .map(|(x, y)| {
                let (origin, dir) = view.ray(view.photon_uv(x, y, photon_resolution));
                // From the far plane back towards the light: the first surface met that
                // faces away from the light is the farthest one.
                let t_far = (view.far - view.depth(origin)) / dir.dot(view.forward).max(1e-6);
                first_facing(scene, &generators, view, (origin + dir * t_far, -dir), true, &no_generator)
            })
            .collect();
        let receivers = texels(map_resolution)
            .map(|(x, y)| {
                let (origin, dir) = view.ray(LightView::texel_center(x, y, map_resolution));
                receivers.intersect(origin, dir, 0.0, f32::INFINITY).map_or(NO_SURFACE, |hit| view.depth(origin + dir * hit.t))
            })
            .collect();
        Self { photon_resolution, front, back, map_resolution, receivers }
    }

    /// The front map at texel `(x, y)`.
    #[inline]
    pub fn front(&self, x: u32, y: u32) -> SurfaceSample {
        self.front[(y * self.photon_resolution + x) as usize]
    }

    /// The back map at texel `(x, y)`.
    #[inline]
    pub fn back(&self, x: u32, y: u32) -> SurfaceSample {
        self.back[(y * self.photon_resolution + x) as usize]
    }

    /// The receiver depth at texel `(x, y)`.
    #[inline]
    pub fn receiver(&self, x: u32, y: u32) -> f32 {
        self.receivers[(y * self.map_resolution + x) as usize]
    }
}

/// The first generator surface along the ray whose geometric normal faces against the
/// light (`away_from_light = false`: a front face) or with it (`true`: a back face),
/// skipping the others as face culling does — except on the generators `unculled`
/// lists (true per generator), which any face stops.
fn first_facing(scene: &Scene, bvh: &SceneBvh, view: &LightView, (origin, dir): (Vec3, Vec3), away_from_light: bool, unculled: &[bool]) -> SurfaceSample {
    let light_dir = if away_from_light { -dir } else { dir };
    let mut t_min = 0.0;
    for _ in 0..MAX_SKIPPED {
        let Some(hit) = bvh.intersect(origin, dir, t_min, f32::INFINITY) else { break };
        let p = origin + dir * hit.t;
        let crate::bvh::Surface::Generator(g) = hit.surface else { break };
        if (hit.geometric_normal.dot(light_dir) > 0.0) == away_from_light || unculled[g as usize] {
            let normal = scene.generators[g as usize].mesh.shading_normal(hit.triangle as usize, hit.uv);
            return SurfaceSample { depth: view.depth(p), normal, material: g };
        }
        t_min = hit.t * (1.0 + 1e-6) + 1e-7;
    }
    SurfaceSample::NONE
}
