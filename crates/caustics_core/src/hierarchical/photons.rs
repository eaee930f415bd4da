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
//!
//! Past the paper, [`PhotonPaths::Traced`] follows each photon from its front-map
//! surface through the generators' triangles ([`InstancedBvh`]) instead: every
//! interface it meets, in and out of a concave body as often as it crosses one,
//! reflected inside past the critical angle, and on through other generators — a
//! mirror that the light of a glass body falls on, a glass ball behind a window —
//! until it reaches a receiver in the receiver map. The image-space pair sees one
//! entry and the farthest exit, which is exact for a convex refractor alone.

use super::light_maps::{LightMaps, NO_SURFACE};
use super::light_view::{LightView, Projection};
use crate::optics::{RGB_WAVELENGTHS_UM, Refraction, fresnel_transmittance, reflect, refract};
use crate::params::SpecularInteraction;
use crate::scene::{Generator, Light, Sides};
use crate::triangle_bvh::{InstancedBvh, NO_MESH};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// One texel of the photon buffer.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Photon {
    /// Caustic-map coordinates of its hit on a receiver, in `[0, 1)²`.
    pub uv: Vec2,
    /// Flux in units of an unoccluded photon at the view's centre (the light's
    /// intensity times the photon texel's [`LightView::photon_measure`]): the beam's
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
    /// Its light falls first on a generator another technique draws.
    DrawnElsewhere,
    /// A traced path met the back of a one-sided surface, which absorbs.
    Absorbed,
    /// A traced path met more than [`MAX_PATH_EVENTS`] interfaces.
    Trapped,
    /// A Fresnel branch's path ends before the refraction it reflects at.
    NoBranch,
}

/// Counts and flux (in photon units, f64) of a photon buffer by fate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhotonStats {
    /// Texels of the buffer, whatever their fate.
    pub texels: u64,
    /// Photons that land on a receiver.
    pub caustic: u64,
    /// Photons totally internally reflected at the refractor's far side.
    pub total_internal_reflection: u64,
    /// Photons that leave the view before reaching a receiver.
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
    /// Traced paths absorbed by a one-sided surface's back or cut after
    /// [`MAX_PATH_EVENTS`] interfaces.
    pub lost_on_path: u64,
    /// Flux of the paths lost on the way.
    pub flux_lost_on_path: f64,
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
            PhotonFate::Absorbed | PhotonFate::Trapped => {
                self.lost_on_path += 1;
                self.flux_lost_on_path += carried as f64;
            }
            PhotonFate::Shadowed => self.shadowed += 1,
            PhotonFate::NoGenerator | PhotonFate::OutsideCone | PhotonFate::DrawnElsewhere | PhotonFate::NoBranch => {}
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
        self.lost_on_path += o.lost_on_path;
        self.flux_lost_on_path += o.flux_lost_on_path;
        self
    }
}

/// The photons of one light view, row-major, `resolution²` of them.
#[derive(Clone, Debug, PartialEq)]
pub struct PhotonBuffer {
    /// Side of the buffer, in photons.
    pub resolution: u32,
    /// Its `resolution²` photons, row-major.
    pub photons: Vec<Photon>,
    /// Counts and flux of its texels by fate.
    pub stats: PhotonStats,
}

/// The index of refraction photons see in a generator (the green channel's for a
/// dispersive one), `None` for a mirror.
pub fn photon_ior(interaction: &SpecularInteraction) -> Option<f32> {
    interaction.ior_at(RGB_WAVELENGTHS_UM[1])
}

/// What a photon meets at a generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonMaterial {
    /// [`photon_ior`]: `None` for a mirror.
    pub ior: Option<f32>,
    /// Whether the back of its faces, reached from outside, absorbs
    /// ([`Sides::Front`]): only traced paths reach it.
    pub one_sided: bool,
    /// Whether this caustic map carries the light that falls on it first. A generator
    /// another technique draws still shadows, reflects and refracts the photons that
    /// reach it along a traced path.
    pub drawn_here: bool,
}

impl PhotonMaterial {
    /// Every generator of a scene, each drawn here where `drawn_here(index)` says so.
    pub fn of_generators(generators: &[Generator], drawn_here: impl Fn(usize) -> bool) -> Vec<Self> {
        generators
            .iter()
            .enumerate()
            .map(|(i, g)| Self { ior: photon_ior(&g.interaction), one_sided: g.sides() == Sides::Front, drawn_here: drawn_here(i) })
            .collect()
    }
}

/// Interfaces a traced path may cross, the tracer's default depth (the light's entry
/// into a ball and its exit are two).
pub const MAX_PATH_EVENTS: u32 = 8;

/// How photons find their way through the generators past the surface the front map
/// saw.
#[derive(Clone, Copy, Debug)]
pub enum PathTracer<'a> {
    /// The image-space pair (Wyman 2005): out where the back map sees the far side,
    /// refined `exit_iterations` times.
    ImageSpace {
        /// Fixed-point iterations refining each exit distance.
        exit_iterations: u32,
    },
    /// Traced through the generators' triangles; `epsilon` lifts each new ray off the
    /// surface it leaves. `branch` 0 follows the light each refracting interface
    /// transmits; branch `k ≥ 1` the light the `k`-th reflects (its Fresnel
    /// reflectance), transmitted at the others.
    Traced {
        /// The generators' triangles.
        bvh: &'a InstancedBvh,
        /// How far each new ray starts off the surface it leaves (m).
        epsilon: f32,
        /// Which Fresnel branch: 0 the transmitted light, `k` the `k`-th reflection.
        branch: u32,
    },
}

impl<'a> PathTracer<'a> {
    /// Branch `branch` of a traced path through `bvh`, lifted off surfaces by
    /// [`InstancedBvh::ray_offset`].
    pub fn traced(bvh: &'a InstancedBvh, branch: u32) -> Self {
        Self::Traced { bvh, epsilon: bvh.ray_offset(), branch }
    }
}

impl PhotonBuffer {
    /// Traces every texel of `maps` (materials indexed by the maps' `material`).
    pub fn trace(maps: &LightMaps, view: &LightView, materials: &[PhotonMaterial], light: &Light, paths: PathTracer) -> Self {
        let n = maps.photon_resolution;
        let (photons, stats): (Vec<Vec<Photon>>, Vec<PhotonStats>) = (0..n)
            .into_par_iter()
            .map(|y| {
                let mut stats = PhotonStats::default();
                let row = (0..n)
                    .map(|x| {
                        let traced = trace_photon(maps, view, materials, light, x, y, paths);
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
    /// What became of it.
    pub fate: PhotonFate,
    /// Where it landed (world space) when it did.
    pub hit: Vec3,
    /// Caustic-map coordinates of where it landed.
    pub uv: Vec2,
    /// Flux when it met the generator (before Fresnel).
    pub flux_at_generator: f32,
    /// Flux it carries on past the generator.
    pub flux: f32,
    /// The beam it stands for ([`Photon::solid_angle`]).
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

/// Where a photon lands: the receiver point, the last generator point it left from,
/// the flux it carries and the path length between its first surface and that point;
/// or its fate and flux where it does not.
type Landing = Result<(Vec3, Vec3, f32, f32), (PhotonFate, f32)>;

/// The photon of texel `(x, y)`: `materials` indexed by the maps' generator index.
pub fn trace_photon(maps: &LightMaps, view: &LightView, materials: &[PhotonMaterial], light: &Light, x: u32, y: u32, paths: PathTracer) -> TracedPhoton {
    let resolution = maps.photon_resolution;
    let front = maps.front(x, y);
    if !front.is_surface() {
        return TracedPhoton::lost(PhotonFate::NoGenerator, 0.0, 0.0);
    }
    let Some(&material) = materials.get(front.material as usize) else {
        return TracedPhoton::lost(PhotonFate::NoGenerator, 0.0, 0.0);
    };
    if !material.drawn_here {
        return TracedPhoton::lost(PhotonFate::DrawnElsewhere, 0.0, 0.0);
    }
    let uv = view.photon_uv(x, y, resolution);
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
    let p1 = ray_origin + dir * ((front.depth - view.depth(ray_origin)) / dir.dot(view.forward));
    let landing = match paths {
        PathTracer::ImageSpace { exit_iterations } => image_space_path(maps, view, material, (x, y), p1, dir, weight, exit_iterations),
        PathTracer::Traced { bvh, epsilon, branch } => {
            traced_path(maps, view, materials, (bvh, epsilon, branch), (p1, front.material, front.normal), dir, weight)
        }
    };
    let (hit, last, flux, travelled) = match landing {
        Ok(landed) => landed,
        Err((fate, flux)) => return TracedPhoton::lost(fate, weight, flux),
    };
    match view.uv(hit) {
        Some(uv) if (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y) => {
            // A point or spot light's range fades the photon by its whole path.
            let path = light.position().map_or(0.0, |l| (p1 - l).length() + travelled + (hit - last).length());
            TracedPhoton {
                fate: PhotonFate::Caustic,
                hit,
                uv: uv.min(Vec2::splat(ONE_BELOW)),
                flux_at_generator: weight,
                flux: flux * light.range_attenuation(path),
                solid_angle: beam * view.photon_measure(resolution),
            }
        }
        _ => TracedPhoton::lost(PhotonFate::LeftMap, weight, flux),
    }
}

/// The image-space pair: a mirror reflects at `p1`; a refractor bends the light in
/// there and, where the back map sees its far side behind, out there.
#[allow(clippy::too_many_arguments)]
fn image_space_path(
    maps: &LightMaps,
    view: &LightView,
    material: PhotonMaterial,
    (x, y): (u32, u32),
    p1: Vec3,
    dir: Vec3,
    weight: f32,
    exit_iterations: u32,
) -> Landing {
    let front = maps.front(x, y);
    let n1 = if front.normal.dot(dir) > 0.0 { -front.normal } else { front.normal };
    let (origin, out, flux) = match material.ior {
        None => (p1, reflect(dir, n1), weight),
        Some(ior) => {
            let Refraction::Transmitted(t1) = refract(dir, n1, 1.0 / ior) else {
                return Err((PhotonFate::TotalInternalReflection, weight));
            };
            let flux = weight * fresnel_transmittance(dir.dot(n1), 1.0 / ior);
            let back = maps.back(x, y);
            if back.is_surface() && back.depth > front.depth {
                let (d, normal) = exit_distance(maps, view, p1, front.depth, t1, back, exit_iterations);
                match refract(t1, normal, ior) {
                    Refraction::Transmitted(t2) => (p1 + t1 * d, t2, flux * fresnel_transmittance(t1.dot(normal), ior)),
                    Refraction::TotalInternalReflection => return Err((PhotonFate::TotalInternalReflection, flux)),
                }
            } else {
                (p1, t1, flux)
            }
        }
    };
    match march_receivers(maps, view, origin, out, f32::INFINITY) {
        Some(hit) => Ok((hit, origin, flux, (origin - p1).length())),
        None => Err((PhotonFate::LeftMap, flux)),
    }
}

/// Branch `branch` of a traced path from `p1` on generator `material` (smooth normal
/// `normal` there, as the front map holds it, standing in for the geometric one at this
/// first surface): at every interface a mirror reflects, a refractor transmits its
/// Fresnel fraction or, past the critical angle, reflects all of it inside (the
/// tracer's transmitted branch and, at total internal reflection, its only one); at
/// its `branch`-th refraction the path takes the reflected fraction instead (the
/// tracer's reflected branch there). The photon lands where its ray reaches a receiver
/// in the receiver map before any generator triangle. A branch whose path ends before
/// its refraction is [`PhotonFate::NoBranch`]: branch 0 carries that light.
#[allow(clippy::too_many_arguments)]
fn traced_path(
    maps: &LightMaps,
    view: &LightView,
    materials: &[PhotonMaterial],
    (bvh, epsilon, branch): (&InstancedBvh, f32, u32),
    (p1, material, normal): (Vec3, u32, Vec3),
    mut dir: Vec3,
    mut flux: f32,
) -> Landing {
    let (mut p, mut travelled, mut refractions) = (p1, 0.0f32, 0u32);
    let (mut material, mut ns, mut ng) = (material, normal, normal);
    for _ in 0..MAX_PATH_EVENTS {
        let Some(m) = materials.get(material as usize) else { return Err((PhotonFate::NoGenerator, flux)) };
        if m.one_sided && dir.dot(ng) > 0.0 {
            return Err(branch_fate(PhotonFate::Absorbed, flux, refractions, branch));
        }
        let n = if ns.dot(dir) > 0.0 { -ns } else { ns };
        dir = match m.ior {
            None => reflect(dir, n),
            Some(ior) => {
                let eta = if dir.dot(ng) < 0.0 { 1.0 / ior } else { ior };
                match refract(dir, n, eta) {
                    Refraction::Transmitted(t) => {
                        refractions += 1;
                        let transmitted = fresnel_transmittance(dir.dot(n), eta);
                        if refractions == branch {
                            flux *= 1.0 - transmitted;
                            reflect(dir, n)
                        } else {
                            flux *= transmitted;
                            t
                        }
                    }
                    Refraction::TotalInternalReflection => reflect(dir, n),
                }
            }
        };
        // Leave the surface on the side the new direction goes.
        let side = if dir.dot(ng) >= 0.0 { ng } else { -ng };
        let origin = p + side * epsilon;
        let next = bvh.intersect(origin, dir, 0.0, f32::INFINITY, NO_MESH);
        let landed = march_receivers(maps, view, origin, dir, next.map_or(f32::INFINITY, |h| h.t));
        if refractions < branch && (landed.is_some() || next.is_none()) {
            return Err((PhotonFate::NoBranch, 0.0));
        }
        if let Some(hit) = landed {
            return Ok((hit, origin, flux, travelled));
        }
        let Some(next) = next else { return Err((PhotonFate::LeftMap, flux)) };
        (p, travelled) = (origin + dir * next.t, travelled + next.t);
        (material, ns, ng) = (next.generator, next.normal, next.geometric_normal);
    }
    Err(branch_fate(PhotonFate::Trapped, flux, refractions, branch))
}

/// A path lost with `flux` after `refractions`: lost on branch `branch`, or no path of
/// it where the branch's refraction never came.
fn branch_fate(fate: PhotonFate, flux: f32, refractions: u32, branch: u32) -> (PhotonFate, f32) {
    if refractions < branch { (PhotonFate::NoBranch, 0.0) } else { (fate, flux) }
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
fn exit_distance(maps: &LightMaps, view: &LightView, p1: Vec3, z1: f32, t: Vec3, back: super::light_maps::SurfaceSample, iterations: u32) -> (f32, Vec3) {
    let dz = t.dot(view.forward);
    if dz < 1e-3 {
        return ((back.depth - z1).max(0.0), back.normal);
    }
    let resolution = maps.photon_resolution;
    let mut sample = back;
    let mut d = (back.depth - z1) / dz;
    for _ in 0..iterations {
        let Some(uv) = view.uv(p1 + t * d) else { break };
        let Some((x, y)) = view.photon_texel(uv, resolution) else { break };
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

/// The first point along `origin + d·dir` (0 ≤ d ≤ `reach`) that lies behind the
/// receiver surface in the receiver map, texel by texel; `None` when the ray leaves the
/// view first, runs into the light or goes past `reach` (where a traced path meets a
/// generator). Each texel holds its receiver's depth at its centre:
/// the ray lands at its first texel whose depth it reaches.
pub fn march_receivers(maps: &LightMaps, view: &LightView, origin: Vec3, dir: Vec3, reach: f32) -> Option<Vec3> {
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
    let step = |s: f32| {
        if s > 0.0 {
            1i64
        } else if s < 0.0 {
            -1
        } else {
            0
        }
    };
    let (step_u, step_v) = (step(su), step(sv));
    let mf = m as f32;
    let mut d_enter = 0.0f32;
    for _ in 0..(2 * m + 4) {
        if d_enter > reach {
            return None;
        }
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
                    return (d_hit <= reach).then(|| origin + dir * d_hit);
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
