//! The photon buffer (Wyman 2008 §3, Fig. 2): one photon per texel of a light view,
//! traced through the generator in image space and landed on the receivers.
//!
//! A photon starts where the front map saw a generator. A mirror reflects it. A
//! refractor bends it in with Snell's law and the Fresnel transmittance, and when the
//! back map sees the refractor's far side behind it, finds where it leaves: the exit
//! distance `d` along the refracted ray solves `z₁ + d (t·forward) = z_back(texel at
//! p₁ + d t)` by fixed-point iteration from the distance straight through (Wyman 2005
//! approximates `d` from that distance and one along the normal; iterating in the
//! back-face map needs no precomputation and converges to the true crossing where the
//! far side is not too steep). The far side's normal bends it out, again with Fresnel,
//! or reflects all of it (total internal reflection: the photon is dropped and its
//! flux counted). Without a far side (an open surface such as water) it goes on in the
//! medium. It then marches the receiver map texel by texel (a DDA through the light's
//! view) to the first texel where it passes behind the receiver surface, and lands
//! there. [`trace_photon`] is the CPU twin of the GPU's photon kernel.

use super::light_maps::{LightMaps, NO_SURFACE};
use super::light_view::{LightView, Projection};
use crate::optics::{RGB_WAVELENGTHS_UM, Refraction, fresnel_transmittance, reflect, refract};
use crate::params::SpecularInteraction;
use crate::scene::Light;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// One texel of the photon buffer.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Photon {
    /// Caustic-map coordinates of its hit on a receiver, in `[0, 1)²`.
    pub uv: Vec2,
    /// Flux in units of an unoccluded photon at the view's centre (the light's
    /// intensity times the photon texel's [`LightView::texel_measure`]): the beam's
    /// relative measure, the spot's cone and the Fresnel transmittances. Zero: no photon.
    pub flux: f32,
    /// The beam it stands for, ωᵢ: a perspective texel's solid angle (sr), a parallel
    /// texel's cross-section (m²).
    pub solid_angle: f32,
}

impl Photon {
    /// Whether the texel holds a caustic photon.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.flux > 0.0
    }
}

/// What became of a photon buffer texel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PhotonFate {
    /// It lands on a receiver.
    Caustic,
    /// Its ray meets no generator: not a caustic photon.
    NoGenerator,
    /// Outside the spot's cone.
    OutsideCone,
    /// A surface nearer the light (the receiver map) hides the generator there.
    Shadowed,
    /// Totally internally reflected at the refractor's far side.
    TotalInternalReflection,
    /// It leaves the light's view before reaching a receiver.
    LeftMap,
}

/// Counts and flux (in photon units, f64) of a photon buffer by fate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhotonStats {
    pub texels: u64,
    pub caustic: u64,
    pub total_internal_reflection: u64,
    pub left_map: u64,
    /// Photons whose generator texel a nearer surface hides from the light.
    pub shadowed: u64,
    /// Flux of the photons that met a generator, before Fresnel.
    pub flux_at_generators: f64,
    /// Flux carried to receivers.
    pub flux_caustic: f64,
    /// Flux lost to total internal reflection (transmitted in, never out).
    pub flux_total_internal_reflection: f64,
    /// Flux that left the view.
    pub flux_left_map: f64,
}

impl PhotonStats {
    fn add(mut self, fate: PhotonFate, at_generator: f32, carried: f32) -> Self {
        self.texels += 1;
        self.flux_at_generators += at_generator as f64;
        match fate {
            PhotonFate::Caustic => {
                self.caustic += 1;
                self.flux_caustic += carried as f64;
            }
            PhotonFate::TotalInternalReflection => {
                self.total_internal_reflection += 1;
                self.flux_total_internal_reflection += carried as f64;
            }
            PhotonFate::LeftMap => {
                self.left_map += 1;
                self.flux_left_map += carried as f64;
            }
            PhotonFate::Shadowed => self.shadowed += 1,
            PhotonFate::NoGenerator | PhotonFate::OutsideCone => {}
        }
        self
    }

    fn merge(mut self, o: Self) -> Self {
        self.texels += o.texels;
        self.caustic += o.caustic;
        self.total_internal_reflection += o.total_internal_reflection;
        self.left_map += o.left_map;
        self.shadowed += o.shadowed;
        self.flux_at_generators += o.flux_at_generators;
        self.flux_caustic += o.flux_caustic;
        self.flux_total_internal_reflection += o.flux_total_internal_reflection;
        self.flux_left_map += o.flux_left_map;
        self
    }
}

/// The photons of one light view, row-major, `resolution²` of them.
#[derive(Clone, Debug, PartialEq)]
pub struct PhotonBuffer {
    pub resolution: u32,
    pub photons: Vec<Photon>,
    pub stats: PhotonStats,
}

/// The index of refraction photons see in a generator (the green channel's for a
/// dispersive one), `None` for a mirror.
pub fn photon_ior(interaction: &SpecularInteraction) -> Option<f32> {
    interaction.ior_at(RGB_WAVELENGTHS_UM[1])
}

impl PhotonBuffer {
    /// Traces every texel of `maps` (materials indexed by the maps' `material`), with
    /// `exit_iterations` refinements of each exit point.
    pub fn trace(maps: &LightMaps, view: &LightView, materials: &[SpecularInteraction], light: &Light, exit_iterations: u32) -> Self {
        let n = maps.photon_resolution;
        let iors: Vec<Option<f32>> = materials.iter().map(photon_ior).collect();
        let (photons, stats): (Vec<Vec<Photon>>, Vec<PhotonStats>) = (0..n)
            .into_par_iter()
            .map(|y| {
                let mut stats = PhotonStats::default();
                let row = (0..n)
                    .map(|x| {
                        let traced = trace_photon(maps, view, &iors, light, x, y, exit_iterations);
                        stats = stats.add(traced.fate, traced.flux_at_generator, traced.flux);
                        traced.photon()
                    })
                    .collect::<Vec<_>>();
                (row, stats)
            })
            .unzip();
        let stats = stats.into_iter().fold(PhotonStats::default(), PhotonStats::merge);
        Self { resolution: n, photons: photons.into_iter().flatten().collect(), stats }
    }

    /// The photon of texel `(x, y)`.
    #[inline]
    pub fn photon(&self, x: u32, y: u32) -> Photon {
        self.photons[(y * self.resolution + x) as usize]
    }
}

/// A photon's path, as far as it went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracedPhoton {
    pub fate: PhotonFate,
    /// Where it landed (world space) when it did.
    pub hit: Vec3,
    pub uv: Vec2,
    /// Flux when it met the generator (before Fresnel), and the flux it carries on.
    pub flux_at_generator: f32,
    pub flux: f32,
    pub solid_angle: f32,
}

impl TracedPhoton {
    fn lost(fate: PhotonFate, flux_at_generator: f32, flux: f32) -> Self {
        Self { fate, hit: Vec3::ZERO, uv: Vec2::ZERO, flux_at_generator, flux, solid_angle: 0.0 }
    }

    /// The photon buffer texel: the photon where it landed, none elsewhere.
    pub fn photon(&self) -> Photon {
        match self.fate {
            PhotonFate::Caustic => Photon { uv: self.uv, flux: self.flux, solid_angle: self.solid_angle },
            _ => Photon::default(),
        }
    }
}

/// The photon of texel `(x, y)`: `iors[material]` is a generator's index of refraction,
/// `None` for a mirror.
pub fn trace_photon(
    maps: &LightMaps,
    view: &LightView,
    iors: &[Option<f32>],
    light: &Light,
    x: u32,
    y: u32,
    exit_iterations: u32,
) -> TracedPhoton {
    let resolution = maps.photon_resolution;
    let front = maps.front(x, y);
    if !front.is_surface() {
        return TracedPhoton::lost(PhotonFate::NoGenerator, 0.0, 0.0);
    }
    let uv = LightView::texel_center(x, y, resolution);
    // Past the paper, whose front map sees generators alone: a surface nearer the light
    // than the generator (a roof over the water) keeps the light off it.
    let m = maps.map_resolution;
    let (mx, my) = (((uv.x * m as f32) as u32).min(m - 1), ((uv.y * m as f32) as u32).min(m - 1));
    if maps.receiver(mx, my) < front.depth - shadow_bias(front.depth) {
        return TracedPhoton::lost(PhotonFate::Shadowed, 0.0, 0.0);
    }
    let (ray_origin, dir) = view.ray(uv);
    let beam = view.relative_beam(uv);
    let weight = beam * light.cone_attenuation(dir);
    if weight <= 0.0 {
        return TracedPhoton::lost(PhotonFate::OutsideCone, 0.0, 0.0);
    }
    let forward = view.forward;
    let p1 = ray_origin + dir * ((front.depth - view.depth(ray_origin)) / dir.dot(forward));
    let n1 = if front.normal.dot(dir) > 0.0 { -front.normal } else { front.normal };
    let Some(&ior) = iors.get(front.material as usize) else {
        return TracedPhoton::lost(PhotonFate::NoGenerator, 0.0, 0.0);
    };
    let (origin, out, flux) = match ior {
        None => (p1, reflect(dir, n1), weight),
        Some(ior) => {
            let Refraction::Transmitted(t1) = refract(dir, n1, 1.0 / ior) else {
                return TracedPhoton::lost(PhotonFate::TotalInternalReflection, weight, weight);
            };
            let flux = weight * fresnel_transmittance(dir.dot(n1), 1.0 / ior);
            let back = maps.back(x, y);
            if back.is_surface() && back.depth > front.depth {
                let (d, normal) = exit_distance(maps, view, p1, front.depth, t1, back, exit_iterations);
                let p2 = p1 + t1 * d;
                match refract(t1, normal, ior) {
                    Refraction::Transmitted(t2) => (p2, t2, flux * fresnel_transmittance(t1.dot(normal), ior)),
                    Refraction::TotalInternalReflection => {
                        return TracedPhoton::lost(PhotonFate::TotalInternalReflection, weight, flux);
                    }
                }
            } else {
                (p1, t1, flux)
            }
        }
    };
    match march_receivers(maps, view, origin, out) {
        Some(hit) => match view.uv(hit) {
            Some(uv) if (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y) => TracedPhoton {
                fate: PhotonFate::Caustic,
                hit,
                uv: uv.min(Vec2::splat(ONE_BELOW)),
                flux_at_generator: weight,
                // A point or spot light's range fades the photon by its whole path.
                flux: flux * light.range_attenuation(path_length(light, p1, origin, hit)),
                solid_angle: beam * view.texel_measure(resolution),
            },
            _ => TracedPhoton::lost(PhotonFate::LeftMap, weight, flux),
        },
        None => TracedPhoton::lost(PhotonFate::LeftMap, weight, flux),
    }
}

/// The path length from `light` through the generator entry `p1` and exit `p2` (the
/// same point for one interface) to the receiver `hit`; 0 from a directional light.
fn path_length(light: &Light, p1: Vec3, p2: Vec3, hit: Vec3) -> f32 {
    light.position().map_or(0.0, |l| (p1 - l).length() + (p2 - p1).length() + (hit - p2).length())
}

/// How much nearer the light than a generator a receiver must be to shadow it (view
/// depth units): 0.1 % and 0.1 mm, so that a receiver touching the generator, sampled
/// at another texel's centre, does not.
#[inline]
pub fn shadow_bias(depth: f32) -> f32 {
    1e-3 * depth.abs() + 1e-4
}

/// The largest `f32` below one: map coordinates stay inside the last texel.
pub const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

/// Distance along the refracted ray `t` from `p1` (depth `z1`) to the refractor's far
/// side, and the far side's normal there. Starts from the far side seen along the
/// light's own ray (`back`) and iterates `d ← (z_back(p1 + d t) − z1) / (t·forward)`.
/// A ray that runs across the view (`t·forward` ≈ 0) keeps the first estimate: the
/// distance to the far side along the light's ray.
fn exit_distance(
    maps: &LightMaps,
    view: &LightView,
    p1: Vec3,
    z1: f32,
    t: Vec3,
    back: super::light_maps::SurfaceSample,
    iterations: u32,
) -> (f32, Vec3) {
    let dz = t.dot(view.forward);
    if dz < 1e-3 {
        return ((back.depth - z1).max(0.0), back.normal);
    }
    let resolution = maps.photon_resolution;
    let mut sample = back;
    let mut d = (back.depth - z1) / dz;
    for _ in 0..iterations {
        let Some(uv) = view.uv(p1 + t * d) else { break };
        let Some((x, y)) = texel_of(uv, resolution) else { break };
        let next = maps.back(x, y);
        if !next.is_surface() || next.depth <= z1 {
            break;
        }
        sample = next;
        d = (next.depth - z1) / dz;
    }
    (d, sample.normal)
}

/// The texel of a `resolution²` map that `uv` falls in, `None` outside the map.
#[inline]
pub fn texel_of(uv: Vec2, resolution: u32) -> Option<(u32, u32)> {
    let t = uv * resolution as f32;
    (t.x >= 0.0 && t.y >= 0.0 && t.x < resolution as f32 && t.y < resolution as f32).then_some((t.x as u32, t.y as u32))
}

/// The image-plane line a map coordinate boundary lies on, and the parameter at which
/// the ray `o + d v` (view coordinates) crosses the column boundary `u` (`axis = 0`)
/// or the row boundary `v` (`axis = 1`); infinity where it runs parallel to it or
/// crossed it behind its origin. The second matters in perspective for a ray along
/// its own view ray (a photon that did not bend): its motion across the map is zero
/// up to rounding, whose sign picks a boundary the ray met only at the light, at
/// `d < 0`; taken as "now", the march would walk the row sideways off the map.
#[inline]
fn crossing(view: &LightView, o: Vec3, v: Vec3, axis: usize, boundary: f32) -> f32 {
    let half = view.half_extent();
    // Image-plane coordinate of the boundary: x = (2u − 1)·hx, y = (1 − 2v)·hy.
    let (c, oc, vc) = if axis == 0 { ((2.0 * boundary - 1.0) * half.x, o.x, v.x) } else { ((1.0 - 2.0 * boundary) * half.y, o.y, v.y) };
    let (num, den) = match view.projection {
        Projection::Orthographic { .. } => (c - oc, vc),
        Projection::Perspective { .. } => (c * o.z - oc, vc - c * v.z),
    };
    let d = num / den;
    if den.abs() < 1e-20 || d < 0.0 { f32::INFINITY } else { d }
}

/// The first point along `origin + d·dir` (d ≥ 0) that lies behind the receiver
/// surface in the receiver map, texel by texel; `None` when the ray leaves the view
/// first (or runs into the light). Each texel holds its receiver's depth at its centre:
/// the ray lands at its first texel whose depth it reaches.
pub fn march_receivers(maps: &LightMaps, view: &LightView, origin: Vec3, dir: Vec3) -> Option<Vec3> {
    let m = maps.map_resolution;
    let o = view.to_view(origin);
    let v = Vec3::new(dir.dot(view.right), dir.dot(view.up), dir.dot(view.forward));
    let (mut ix, mut iy) = texel_of(view.uv(origin)?, m)?;
    // Which way the map coordinates move along the ray: constant in both projections
    // (in perspective u(d) is a ratio of linear functions, monotonic while z > 0).
    let (su, sv) = match view.projection {
        Projection::Orthographic { .. } => (v.x, -v.y),
        Projection::Perspective { .. } => (v.x * o.z - o.x * v.z, -(v.y * o.z - o.y * v.z)),
    };
    let step = |s: f32| if s > 0.0 { 1i64 } else if s < 0.0 { -1 } else { 0 };
    let (step_u, step_v) = (step(su), step(sv));
    let mf = m as f32;
    let mut d_enter = 0.0f32;
    for _ in 0..(2 * m + 4) {
        let boundary = |i: u32, s: i64| if s > 0 { (i + 1) as f32 / mf } else { i as f32 / mf };
        let du = if step_u == 0 { f32::INFINITY } else { crossing(view, o, v, 0, boundary(ix, step_u)).max(d_enter) };
        let dv = if step_v == 0 { f32::INFINITY } else { crossing(view, o, v, 1, boundary(iy, step_v)).max(d_enter) };
        let d_exit = du.min(dv);
        let z_receiver = maps.receiver(ix, iy);
        if z_receiver < NO_SURFACE {
            if o.z + d_enter * v.z >= z_receiver {
                return Some(origin + dir * d_enter);
            }
            if v.z > 0.0 {
                let d_hit = (z_receiver - o.z) / v.z;
                if d_hit <= d_exit {
                    return Some(origin + dir * d_hit);
                }
            }
        }
        if !d_exit.is_finite() {
            return None;
        }
        let z_exit = o.z + d_exit * v.z;
        if z_exit > view.far || (matches!(view.projection, Projection::Perspective { .. }) && z_exit <= 0.0) {
            return None;
        }
        let (nx, ny) = if du <= dv { (ix as i64 + step_u, iy as i64) } else { (ix as i64, iy as i64 + step_v) };
        if nx < 0 || ny < 0 || nx >= m as i64 || ny >= m as i64 {
            return None;
        }
        (ix, iy, d_enter) = (nx as u32, ny as u32, d_exit);
    }
    None
}
