//! Hierarchical caustic maps (Wyman 2008).
//!
//! Caustic mapping in three passes (Fig. 2): a **photon buffer** per light view — one
//! photon per texel, reflected or refracted through the generators in image space and
//! landed on the receivers ([`photons`]) — gathered and **splatted** into a light-space
//! **caustic map** ([`caustic_map`]), which receivers **look up** like a shadow map.
//! The paper's three improvements:
//!
//! 1. **Hierarchical gather** (§3.1): a mipmap of photon validity, traversed breadth
//!    first, discards whole groups of photons that never met a generator ([`hierarchy`]);
//! 2. **Clustering** (§3.2): photons that converge on one caustic-map texel are
//!    splatted once, with their summed flux;
//! 3. **Variable splats in a multi-resolution map** (§3.3): a splat as wide as its
//!    photons diverge, written into the mipmap level that keeps it small, and the levels
//!    summed (eq. 3).
//!
//! Everything here is the CPU twin of the GPU passes in `caustics_bevy`, stage by
//! stage: [`light_maps`] casts rays where the GPU rasterises, the rest is the same
//! arithmetic. [`ViewCaustics::compute`] runs all stages for one light view and times
//! each.

pub mod caustic_map;
pub mod hierarchy;
pub mod light_maps;
pub mod light_view;
pub mod photons;

pub use caustic_map::{CausticMap, SplatStats};
pub use hierarchy::{GatherEntry, GatherStats, PhotonPyramid};
pub use light_maps::LightMaps;
pub use light_view::{LightView, Projection};
pub use photons::{PathTracer, Photon, PhotonBuffer, PhotonMaterial, PhotonStats};

use crate::params::ParamError;
use crate::scene::{Light, LightKind, Scene};
use crate::triangle_bvh::InstancedBvh;
use glam::Vec3;
use std::time::Instant;

/// Width of the pyramid level the hierarchical gather starts from (§3.1: "our
/// implementation starts with a mipmap of resolution 16²").
pub const START_RESOLUTION: u32 = 16;
/// A variable splat's diameter, in texels of its level, above which it moves one level
/// up (§3.3's 5.0).
pub const SPLAT_LEVEL_THRESHOLD: f32 = 5.0;
/// The narrowest splat: radius one texel, bilinear splatting.
pub const MIN_SPLAT_DIAMETER: f32 = 2.0;
/// Largest photon buffer and caustic map side: 4096² photons (the paper's largest)
/// address 24 bits of nodes.
pub const MAX_RESOLUTION: u32 = 4096;

/// How the photon buffer is gathered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gather {
    /// Every photon of the buffer is processed (the baseline).
    Flat,
    /// The pyramid is traversed from [`START_RESOLUTION`]² nodes (§3.1), with or
    /// without clustering (§3.2).
    Hierarchical {
        /// Where converging photons are clustered.
        clustering: Clustering,
    },
}

/// Where the hierarchical gather clusters converging photons (§3.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clustering {
    /// Never: every valid photon that is gathered is splatted on its own.
    Off,
    /// At the level just above the photon buffer only ("combine last").
    LastLevel,
    /// At every level ("combine all").
    AllLevels,
}

/// How photons are splatted (§3.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Splats {
    /// One diameter, in caustic-map texels, for every splat, in the full-resolution map.
    Fixed {
        /// Splat diameter in full-resolution texels, above 0 and at most 64.
        diameter: f32,
    },
    /// Diameters from photon divergence, in a pyramid of maps up to `max_level` (the
    /// paper sums levels 0–3).
    Variable {
        /// Top level of the pyramid of maps, at most 8 (the paper: 3).
        max_level: u32,
        /// What happens to a splat too wide for `max_level`.
        overflow: LevelOverflow,
    },
}

/// What happens to a variable splat too wide for the top level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LevelOverflow {
    /// Dropped, as the paper does ("such photons contribute little").
    Discard,
    /// Splatted into the top level (radius capped at [`caustic_map::MAX_SPLAT_RADIUS`]
    /// texels there), keeping its flux.
    Clamp,
}

/// How a photon crosses the generators past the surface the light meets first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PhotonPaths {
    /// In at the front map, out at the back map (Wyman 2008 §3 after Wyman 2005):
    /// exact for a convex refractor alone, no light from one generator to another.
    #[default]
    ImageSpace,
    /// Past the paper: traced through the generators' triangles, every interface of a
    /// concave body and every generator on the way ([`photons`]).
    Traced,
}

/// Everything one light view's caustic map is made with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CausticMapSettings {
    /// Photon buffer side (a power of two, 16 to 4096): `photon_resolution²` photons.
    pub photon_resolution: u32,
    /// Caustic map (and receiver map) side, a power of two, 16 to 4096.
    pub map_resolution: u32,
    /// How the photon buffer is gathered.
    pub gather: Gather,
    /// How photons are splatted.
    pub splats: Splats,
    /// Refinements of a photon's exit point from a closed refractor (image space).
    pub exit_iterations: u32,
    /// How photons cross the generators past the front map's surface.
    pub paths: PhotonPaths,
    /// Past the paper: Fresnel-reflected branches a traced path follows beside the
    /// transmitted light, each a photon buffer of its own splatted into the same map —
    /// branch `k` reflects at a photon's `k`-th refraction, as the tracer's reflected
    /// branch there (the light a glass body throws back, or reflects once inside). Up to
    /// [`MAX_FRESNEL_BRANCHES`]; image-space paths have none.
    pub fresnel_branches: u32,
}

/// Most Fresnel-reflected branches a caustic map follows: the fourth and later carry
/// well under 1 % of a glass body's caustic flux (`mirror_bunny`).
pub const MAX_FRESNEL_BRANCHES: u32 = 3;

impl Default for CausticMapSettings {
    /// 1024² photons into a 1024² map, hierarchical with clustering at the last level
    /// and variable splats into levels 0–3 (clamped): the paper's fastest gather (§5)
    /// with its splats.
    fn default() -> Self {
        Self {
            photon_resolution: 1024,
            map_resolution: 1024,
            gather: Gather::Hierarchical { clustering: Clustering::LastLevel },
            splats: Splats::Variable { max_level: 3, overflow: LevelOverflow::Clamp },
            exit_iterations: 4,
            paths: PhotonPaths::ImageSpace,
            fresnel_branches: 0,
        }
    }
}

impl CausticMapSettings {
    /// How [`PhotonBuffer::trace`] follows the photons of `branch` under these
    /// settings: through `bvh` (the scene's [`InstancedBvh`]) when they are traced and
    /// it is given.
    pub fn path_tracer<'a>(&self, bvh: Option<&'a InstancedBvh>, branch: u32) -> PathTracer<'a> {
        match (self.paths, bvh) {
            (PhotonPaths::Traced, Some(bvh)) => PathTracer::traced(bvh, branch),
            _ => PathTracer::ImageSpace { exit_iterations: self.exit_iterations },
        }
    }

    /// The photon buffers a light view traces: the transmitted light's, then the
    /// Fresnel branches' of traced paths.
    pub fn photon_buffers(&self) -> u32 {
        1 + if self.paths == PhotonPaths::Traced { self.fresnel_branches } else { 0 }
    }

    /// These settings for the light views `views` of one scene. A point light's cube
    /// face that the scene extends past spreads its maps over four times its own image
    /// ([`light_view::CUBE_FACE_REACH`], emission ½), so every view's map side is
    /// multiplied by the smallest emission's inverse (up to [`MAX_RESOLUTION`]): a map
    /// texel then spans the solid angle it does on a face that does not reach, and the
    /// photons land one a texel. One side for all the views: on the GPU they share the
    /// gather's scratch. At 1024², a glass ball under a point light over a floor wider
    /// than the face reads 0.22 relative L2 against the tracer without it.
    pub fn for_views<'a>(&self, views: impl IntoIterator<Item = &'a LightView>) -> Self {
        let emission = views.into_iter().map(|v| v.emission).fold(1.0f32, f32::min).max(1.0 / MAX_RESOLUTION as f32);
        let scale = ((1.0 / emission).round() as u32).max(1).next_power_of_two();
        Self { map_resolution: self.map_resolution.saturating_mul(scale).min(MAX_RESOLUTION), ..*self }
    }

    /// Checks the resolutions (powers of two within range) and the fixed splat size.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (name, value) in [("photon resolution", self.photon_resolution), ("caustic map resolution", self.map_resolution)] {
            if !value.is_power_of_two() || !(16..=MAX_RESOLUTION).contains(&value) {
                return Err(ParamError::OutOfRange { name, value: value as f32, expected: "a power of two from 16 to 4096" });
            }
        }
        if let Splats::Fixed { diameter } = self.splats
            && !(diameter.is_finite() && diameter > 0.0 && diameter <= 64.0)
        {
            return Err(ParamError::OutOfRange { name: "splat diameter", value: diameter, expected: "between 0 and 64 texels" });
        }
        if let Splats::Variable { max_level, .. } = self.splats
            && max_level > 8
        {
            return Err(ParamError::OutOfRange { name: "top splat level", value: max_level as f32, expected: "at most 8" });
        }
        if self.fresnel_branches > MAX_FRESNEL_BRANCHES {
            return Err(ParamError::OutOfRange { name: "Fresnel branches", value: self.fresnel_branches as f32, expected: "at most 3" });
        }
        Ok(())
    }
}

/// The light's intensity as the caustic map scales it: irradiance across the beam for
/// parallel light, intensity per steradian for point and spot lights (times its colour).
pub fn light_intensity(light: &Light) -> f32 {
    match light.kind {
        LightKind::Directional { irradiance, .. } => irradiance,
        LightKind::Point { intensity, .. } | LightKind::Spot { intensity, .. } => intensity,
    }
}

/// Seconds each stage took (the paper's Tables 3–4 stages).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// The light-space maps (on a GPU, rasterisation; here ray casting).
    pub light_maps: f64,
    /// Tracing the photon buffer.
    pub photons: f64,
    /// Building the pyramid (none for the flat gather).
    pub pyramid: f64,
    /// Gathering.
    pub gather: f64,
    /// Splatting and resolving the levels.
    pub splat: f64,
}

/// One light view's caustic map, computed on the CPU with every stage's result kept.
#[derive(Clone, Debug)]
pub struct ViewCaustics {
    /// The light the view belongs to.
    pub light: Light,
    /// The light view the maps and photons live in.
    pub view: LightView,
    /// The settings the caustic map is made with.
    pub settings: CausticMapSettings,
    /// The front, back and receiver maps the photons are traced in.
    pub maps: LightMaps,
    /// The transmitted light's photons, with their pyramid and gather.
    pub photons: PhotonBuffer,
    /// The Fresnel branches' photons ([`CausticMapSettings::fresnel_branches`]),
    /// gathered and splatted into the same map.
    pub branches: Vec<PhotonBuffer>,
    /// The transmitted light's photon pyramid.
    pub pyramid: PhotonPyramid,
    /// The transmitted light's gathered photons and clusters.
    pub entries: Vec<GatherEntry>,
    /// Every photon buffer's gather, summed.
    pub gather_stats: GatherStats,
    /// The caustic map every photon buffer is splatted into.
    pub map: CausticMap,
    /// What splatting did, summed over every photon buffer.
    pub splat_stats: SplatStats,
    /// The resolved full-resolution map (eq. 3), photon units per texel.
    pub resolved: Vec<f32>,
    /// Seconds each stage took.
    pub times: StageTimes,
}

impl ViewCaustics {
    /// Runs every stage for `view` of `light` in `scene`.
    pub fn compute(scene: &Scene, light: &Light, view: &LightView, settings: &CausticMapSettings) -> Self {
        Self::compute_drawn(scene, light, view, settings, &|_| true)
    }

    /// [`Self::compute`] of the light that meets the generators `drawn(index)` picks
    /// first ([`PhotonMaterial::drawn_here`]); the others are drawn by other techniques.
    pub fn compute_drawn(scene: &Scene, light: &Light, view: &LightView, settings: &CausticMapSettings, drawn: &dyn Fn(usize) -> bool) -> Self {
        let clock = Instant::now();
        let maps = LightMaps::ray_cast(scene, view, settings.photon_resolution, settings.map_resolution);
        let light_maps = clock.elapsed().as_secs_f64();
        let materials = PhotonMaterial::of_generators(&scene.generators, drawn);
        let clock = Instant::now();
        let bvh = (settings.paths == PhotonPaths::Traced).then(|| InstancedBvh::of_scene(scene));
        let mut buffers = trace_buffers(&maps, view, &materials, light, settings, bvh.as_ref()).into_iter();
        let mut times = StageTimes { light_maps, photons: clock.elapsed().as_secs_f64(), ..StageTimes::default() };
        let photons = buffers.next().expect("a view traces at least one photon buffer");
        let branches: Vec<PhotonBuffer> = buffers.collect();
        let mut map = CausticMap::for_splats(settings.splats, settings.map_resolution);
        let mut splat_stats = SplatStats::default();
        let (pyramid, entries, mut gather_stats) = gather_into(&mut map, &photons, settings, &mut splat_stats, &mut times);
        for branch in &branches {
            gather_stats.add(&gather_into(&mut map, branch, settings, &mut splat_stats, &mut times).2);
        }
        let clock = Instant::now();
        let resolved = map.resolve();
        times.splat += clock.elapsed().as_secs_f64();
        Self { light: *light, view: *view, settings: *settings, maps, photons, branches, pyramid, entries, gather_stats, map, splat_stats, resolved, times }
    }

    /// Caustic irradiance (the light's colour mean) at receiver point `p` with unit normal `n`.
    pub fn irradiance_at(&self, p: Vec3, n: Vec3) -> f32 {
        let intensity = light_intensity(&self.light) * self.light.color.element_sum() / 3.0;
        caustic_map::irradiance_at(&self.view, &self.maps, &self.resolved, self.settings.photon_resolution, intensity, p, n)
    }
}

/// The photon buffers of one light view under `settings`
/// ([`CausticMapSettings::photon_buffers`]): the transmitted light's, then each Fresnel
/// branch's, traced through `bvh` (the scene's) where the paths are traced.
pub fn trace_buffers(
    maps: &LightMaps,
    view: &LightView,
    materials: &[PhotonMaterial],
    light: &Light,
    settings: &CausticMapSettings,
    bvh: Option<&InstancedBvh>,
) -> Vec<PhotonBuffer> {
    (0..settings.photon_buffers()).map(|branch| PhotonBuffer::trace(maps, view, materials, light, settings.path_tracer(bvh, branch))).collect()
}

/// Gathers one photon buffer (§3.1–3.2) and splats it into `map` (§3.3), counting the
/// splats in `splat_stats` and each stage's seconds in `times`: its pyramid, the
/// entries gathered and the gather's counts.
pub fn gather_into(
    map: &mut CausticMap,
    photons: &PhotonBuffer,
    settings: &CausticMapSettings,
    splat_stats: &mut SplatStats,
    times: &mut StageTimes,
) -> (PhotonPyramid, Vec<GatherEntry>, GatherStats) {
    let clock = Instant::now();
    let pyramid = PhotonPyramid::for_gather(photons, settings.map_resolution, settings.gather);
    times.pyramid += clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    let (entries, stats) = hierarchy::gather(&pyramid, settings.gather);
    times.gather += clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    map.splat_entries(photons, &pyramid, &entries, settings.splats, splat_stats);
    times.splat += clock.elapsed().as_secs_f64();
    (pyramid, entries, stats)
}

/// Every light view of every light of `scene` with its caustic map, at `settings`
/// for those views ([`CausticMapSettings::for_views`]); empty without generators or
/// receivers.
pub fn scene_caustics(scene: &Scene, settings: &CausticMapSettings) -> Vec<ViewCaustics> {
    let Some(generators) = scene.generator_bounds() else { return Vec::new() };
    let Some(receivers) = scene.receivers.iter().map(|r| r.mesh.bounds()).reduce(|(a, b), (c, d)| (a.min(c), b.max(d))) else {
        return Vec::new();
    };
    let views: Vec<(&Light, LightView)> =
        scene.lights.iter().flat_map(|light| LightView::for_light(light, generators, receivers).into_iter().map(move |view| (light, view))).collect();
    let settings = settings.for_views(views.iter().map(|(_, view)| view));
    views.iter().map(|(light, view)| ViewCaustics::compute(scene, light, view, &settings)).collect()
}

/// Caustic irradiance at `p` (unit normal `n`) summed over every light view.
pub fn irradiance_at(views: &[ViewCaustics], p: Vec3, n: Vec3) -> f32 {
    views.iter().map(|v| v.irradiance_at(p, n)).sum()
}
