//! The ground-truth photon tracer (CPU, rayon, deterministic): photons leave each
//! light towards the generators, follow any number of specular reflections and
//! refractions with exact Fresnel weights, and are deposited where they first reach a
//! receiver. Only caustic paths (light → specular⁺ → diffuse, Heckbert's L S⁺ D) are
//! deposited: direct light is Bevy's job.
//!
//! At a dielectric the photon is *split* into its reflected and transmitted parts,
//! each weighted by the Fresnel terms, rather than choosing one at random: a flat
//! interface then transmits exactly the Fresnel fraction with no sampling noise.
//! Branches lighter than [`TraceSettings::min_weight`] of the photon's emitted flux
//! or deeper than [`TraceSettings::max_depth`] are dropped and their flux counted in
//! [`TraceStats::dropped`], so energy bookkeeping stays exact.

use crate::bvh::{SceneBvh, Surface};
use crate::optics::{RGB_WAVELENGTHS_UM, Refraction, fresnel_reflectance, reflect, refract};
use crate::params::SpecularInteraction;
use crate::rng::Pcg32;
use crate::scene::{Generator, Light, LightKind, Scene, SceneError, Sides};
use glam::{DVec3, Vec2, Vec3};
use rayon::prelude::*;
use std::f32::consts::TAU;

/// How many photons, from which seed, and where paths stop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceSettings {
    /// Photons emitted per light.
    pub photons_per_light: u64,
    /// Seed of the per-photon random streams.
    pub seed: u64,
    /// Most specular interactions a branch may have before it is dropped.
    pub max_depth: u32,
    /// Branches whose flux falls below this fraction of the emitted photon's are dropped.
    pub min_weight: f32,
}

impl Default for TraceSettings {
    fn default() -> Self {
        Self { photons_per_light: 1 << 20, seed: 0x5eed, max_depth: 8, min_weight: 1e-4 }
    }
}

/// One photon deposit on a receiver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonHit {
    /// Where it landed (world space).
    pub position: Vec3,
    /// Unit geometric normal of the receiver triangle, facing the incoming photon.
    pub normal: Vec3,
    /// Unit direction of travel when it arrived.
    pub direction: Vec3,
    /// RGB flux carried (light units × m²).
    pub flux: Vec3,
    /// Index into [`Scene::receivers`].
    pub receiver: u32,
}

/// One straight piece of a caustic photon path: from a generator to where it next
/// meets a surface (or, escaping, to infinity). What a participating medium scatters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonSegment {
    /// Where it leaves the generator (world space).
    pub origin: Vec3,
    /// Unit direction of travel.
    pub direction: Vec3,
    /// Its length: infinite for a photon that leaves the scene.
    pub length: f32,
    /// RGB flux carried (light units × m²).
    pub flux: Vec3,
}

/// Where deposits go. Each worker fills its own empty copy; copies are merged in a
/// fixed order, so a sink's result does not depend on the number of threads.
pub trait PhotonSink: Send + Sync + Sized {
    /// An empty sink of the same shape.
    fn empty_like(&self) -> Self;
    /// Records one deposit.
    fn deposit(&mut self, hit: &PhotonHit);
    /// Records one segment of a caustic path (after at least one specular
    /// interaction); only sinks that estimate light in a medium need them.
    #[inline]
    fn segment(&mut self, _segment: &PhotonSegment) {}
    /// Adds another sink's deposits to this one.
    fn merge(&mut self, other: Self);
}

/// Energy bookkeeping of one trace, RGB flux summed over photons (in f64, so that
/// the balance closes to rounding even for 10⁹ photons).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TraceStats {
    /// Photons emitted, over every light.
    pub photons: u64,
    /// Flux that left the lights towards the generators.
    pub emitted: DVec3,
    /// Flux deposited on receivers after at least one specular interaction.
    pub deposited: DVec3,
    /// Flux that reached a receiver without touching a generator (direct light, not recorded).
    pub direct: DVec3,
    /// Flux that left the scene.
    pub escaped: DVec3,
    /// Flux of branches cut by `max_depth` or `min_weight`.
    pub dropped: DVec3,
    /// Flux absorbed by the back of a one-sided generator ([`crate::scene::Sides::Front`]),
    /// or faded by a point or spot light's range along the path to its receiver.
    pub absorbed: DVec3,
}

impl TraceStats {
    fn add(&mut self, o: &TraceStats) {
        self.photons += o.photons;
        self.emitted += o.emitted;
        self.deposited += o.deposited;
        self.direct += o.direct;
        self.escaped += o.escaped;
        self.dropped += o.dropped;
        self.absorbed += o.absorbed;
    }
}

/// Where photons of one light start and how much flux each carries.
#[derive(Clone, Debug)]
enum Emitter {
    /// Points on a plane perpendicular to the beam, uniform over the cells of
    /// `footprint` that the generators' shadow touches.
    Parallel { direction: Vec3, footprint: Footprint, flux: f32 },
    /// A cone of directions from a point (a whole sphere when `cos_max = -1`).
    Cone { position: Vec3, axis: Vec3, cos_max: f32, flux: f32 },
}

/// The generators' shadow on a plane perpendicular to a parallel beam, as the set of
/// cells of a `RES × RES` grid over its bounding rectangle that any generator
/// triangle's projected bounding box overlaps (conservative: every photon that can
/// hit a generator starts in a marked cell). Emitting only there wastes no photons
/// on light that misses the generators.
#[derive(Clone, Debug)]
struct Footprint {
    corner: Vec3,
    cell_u: Vec3,
    cell_v: Vec3,
    /// Marked cells as (column, row).
    cells: Vec<(u16, u16)>,
}

impl Footprint {
    const RES: usize = 128;

    fn new(scene: &Scene, direction: Vec3, center: Vec3, radius: f32) -> Self {
        let (t, b) = orthonormal_basis(direction);
        let project = |p: Vec3| Vec2::new((p - center).dot(t), (p - center).dot(b));
        let (mut lo, mut hi) = (Vec2::splat(f32::MAX), Vec2::splat(f32::MIN));
        for g in &scene.generators {
            for &p in g.mesh.positions() {
                (lo, hi) = (lo.min(project(p)), hi.max(project(p)));
            }
        }
        // Pad by a hair so that photons grazing the outline still start inside.
        let pad = Vec2::splat(1e-3 * radius);
        let (lo, hi) = (lo - pad, hi + pad);
        let cell = (hi - lo) / Self::RES as f32;
        let mut marked = vec![false; Self::RES * Self::RES];
        let to_cell = |x: f32, lo: f32, size: f32| (((x - lo) / size).floor().max(0.0) as usize).min(Self::RES - 1);
        for g in &scene.generators {
            for tri in 0..g.mesh.triangles().len() {
                let q = g.mesh.corners(tri).map(project);
                let (a, c) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
                for row in to_cell(a.y, lo.y, cell.y)..=to_cell(c.y, lo.y, cell.y) {
                    for col in to_cell(a.x, lo.x, cell.x)..=to_cell(c.x, lo.x, cell.x) {
                        marked[row * Self::RES + col] = true;
                    }
                }
            }
        }
        let cells = (0..marked.len()).filter(|&i| marked[i]).map(|i| ((i % Self::RES) as u16, (i / Self::RES) as u16)).collect();
        Self { corner: center - direction * (2.0 * radius) + t * lo.x + b * lo.y, cell_u: t * cell.x, cell_v: b * cell.y, cells }
    }

    /// Area of all marked cells.
    fn area(&self) -> f32 {
        self.cells.len() as f32 * self.cell_u.length() * self.cell_v.length()
    }

    /// A uniform point over the marked cells, at cell-space coordinate `s ∈ [0, 1)`.
    #[inline]
    fn sample(&self, s: f64, xi: Vec2) -> Vec3 {
        let i = ((s * self.cells.len() as f64) as usize).min(self.cells.len() - 1);
        let (col, row) = self.cells[i];
        self.corner + self.cell_u * (col as f32 + xi.x) + self.cell_v * (row as f32 + xi.y)
    }
}

/// An orthonormal basis `(t, b)` perpendicular to unit `n` (Duff et al. 2017).
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3::new(b, sign + n.y * n.y * a, -n.y))
}

impl Emitter {
    /// Aims `photons` photons of `light` at the scene's generators.
    fn new(light: &Light, scene: &Scene, (lo, hi): (Vec3, Vec3), photons: u64) -> Self {
        let n = photons.max(1) as f32;
        let center = 0.5 * (lo + hi);
        let radius = 0.5 * (hi - lo).length() * 1.001 + 1e-4;
        match light.kind {
            LightKind::Directional { direction, irradiance } => {
                let direction = direction.normalize();
                let footprint = Footprint::new(scene, direction, center, radius);
                Emitter::Parallel { direction, flux: irradiance * footprint.area() / n, footprint }
            }
            LightKind::Point { position, intensity } | LightKind::Spot { position, intensity, .. } => {
                let to_center = center - position;
                let dist = to_center.length();
                let (axis, cos_max) = if dist > radius { (to_center / dist, (1.0 - (radius / dist).powi(2)).max(0.0).sqrt()) } else { (Vec3::Y, -1.0) };
                let solid_angle = TAU * (1.0 - cos_max);
                Emitter::Cone { position, axis, cos_max, flux: intensity * solid_angle / n }
            }
        }
    }

    /// Origin, unit direction and scalar flux of photon `index` of `count`.
    ///
    /// Photons are stratified in emission order: photon i samples the i-th of `count`
    /// equal slices of the emitter's cells (row-major), at a random point in it. Every
    /// point is equally likely over all photons, so each carries the same flux, and
    /// consecutive photons start close together and walk the same BVH nodes, which
    /// keeps the nodes in cache (3× faster than random order on the 128² pool).
    #[inline]
    fn sample(&self, light: &Light, index: u64, count: u64, rng: &mut Pcg32) -> (Vec3, Vec3, f32) {
        let s = (index as f64 + rng.next_f32() as f64) / count.max(1) as f64;
        let xi = Vec2::new(rng.next_f32(), rng.next_f32());
        match self {
            Emitter::Parallel { direction, footprint, flux } => (footprint.sample(s, xi), *direction, *flux),
            &Emitter::Cone { position, axis, cos_max, flux } => {
                // Cells of a CONE_RES² grid over (cos θ, φ), row-major, then uniform
                // over the spherical cap: cos θ uniform in [cos_max, 1].
                const CONE_RES: f64 = 128.0;
                let cell = (s * CONE_RES * CONE_RES).floor();
                let xi = Vec2::new((((cell % CONE_RES) + xi.x as f64) / CONE_RES) as f32, (((cell / CONE_RES).floor() + xi.y as f64) / CONE_RES) as f32)
                    .min(Vec2::splat(1.0 - f32::EPSILON));
                let cos_t = 1.0 - xi.x * (1.0 - cos_max);
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let phi = TAU * xi.y;
                let (t, b) = orthonormal_basis(axis);
                let dir = (axis * cos_t + t * (sin_t * phi.cos()) + b * (sin_t * phi.sin())).normalize();
                (position, dir, flux * light.cone_attenuation(dir))
            }
        }
    }
}

/// A branch of a photon path waiting to be followed.
#[derive(Clone, Copy)]
struct Branch {
    origin: Vec3,
    dir: Vec3,
    flux: Vec3,
    depth: u32,
    /// Path length from the light to `origin` (for a light's range).
    travelled: f32,
}

/// A scene prepared for tracing: validated, with its BVH built once.
pub struct PhotonTracer<'a> {
    scene: &'a Scene,
    bvh: SceneBvh,
    /// Trace one RGB channel per photon (with its own IOR) when any generator disperses.
    dispersive: bool,
    /// Offset used to leave a surface without hitting it again.
    epsilon: f32,
    /// Per generator, which sides of its faces reflect or refract.
    sides: Vec<Sides>,
}

impl<'a> PhotonTracer<'a> {
    /// Validates `scene` and builds its BVH.
    pub fn new(scene: &'a Scene) -> Result<Self, SceneError> {
        scene.validate()?;
        let bvh = SceneBvh::build(scene);
        let dispersive = scene.generators.iter().any(|g| matches!(g.interaction, SpecularInteraction::Refract { dispersion: Some(d), .. } if d.b != 0.0));
        let extent = scene
            .generators
            .iter()
            .map(|g| &g.mesh)
            .chain(scene.receivers.iter().map(|r| &r.mesh))
            .map(|m| {
                let (lo, hi) = m.bounds();
                (hi - lo).max_element().max(lo.abs().max_element()).max(hi.abs().max_element())
            })
            .fold(1.0f32, f32::max);
        let sides = scene.generators.iter().map(Generator::sides).collect();
        Ok(Self { scene, bvh, dispersive, epsilon: 2e-5 * extent, sides })
    }

    /// The scene's BVH, for callers that cast their own rays (view rendering).
    pub fn bvh(&self) -> &SceneBvh {
        &self.bvh
    }

    /// Traces `settings.photons_per_light` photons from every light into `sink`,
    /// calling `progress(done, total)` between batches.
    pub fn trace<S: PhotonSink>(&self, settings: &TraceSettings, sink: &mut S, progress: &(dyn Fn(u64, u64) + Sync)) -> TraceStats {
        const BATCH: u64 = 1 << 14;
        let mut stats = TraceStats::default();
        let Some(bounds) = self.scene.generator_bounds() else {
            return stats;
        };
        let per_light = settings.photons_per_light;
        let total = per_light * self.scene.lights.len() as u64;
        let wave = BATCH * 4 * rayon::current_num_threads() as u64;
        let mut done = 0;
        for (li, light) in self.scene.lights.iter().enumerate() {
            let emitter = Emitter::new(light, self.scene, bounds, per_light);
            let mut start = 0;
            while start < per_light {
                let end = (start + wave).min(per_light);
                // Batches of a wave run in parallel; their sinks merge in batch order.
                let results: Vec<(S, TraceStats)> = (start..end)
                    .step_by(BATCH as usize)
                    .collect::<Vec<_>>()
                    .into_par_iter()
                    .map(|b0| {
                        let mut local = sink.empty_like();
                        let mut st = TraceStats::default();
                        for i in b0..(b0 + BATCH).min(end) {
                            self.trace_photon(light, li as u32, &emitter, settings, i, &mut local, &mut st);
                        }
                        (local, st)
                    })
                    .collect();
                for (s, st) in results {
                    sink.merge(s);
                    stats.add(&st);
                }
                done += end - start;
                progress(done, total);
                start = end;
            }
        }
        stats
    }

    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn trace_photon<S: PhotonSink>(
        &self,
        light: &Light,
        light_index: u32,
        emitter: &Emitter,
        settings: &TraceSettings,
        index: u64,
        sink: &mut S,
        stats: &mut TraceStats,
    ) {
        let mut rng = Pcg32::for_photon(settings.seed, light_index, index);
        let (origin, dir, flux) = emitter.sample(light, index, settings.photons_per_light, &mut rng);
        // Dispersive scenes: each photon carries one channel, three times as strong.
        let channel = self.dispersive.then_some((index % 3) as usize);
        let color = match channel {
            Some(c) => Vec3::from_array(std::array::from_fn(|i| if i == c { 3.0 } else { 0.0 })) * light.color,
            None => light.color,
        };
        let wavelength = RGB_WAVELENGTHS_UM[channel.unwrap_or(1)];
        let emitted = color * flux;
        stats.photons += 1;
        stats.emitted += emitted.as_dvec3();
        if flux <= 0.0 {
            return;
        }
        let cutoff = settings.min_weight * emitted.max_element();

        let mut stack = [Branch { origin, dir, flux: emitted, depth: 0, travelled: 0.0 }; 16];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let b = stack[len];
            let hit = self.bvh.intersect(b.origin, b.dir, 0.0, f32::INFINITY);
            if b.depth > 0 {
                let length = hit.as_ref().map_or(f32::INFINITY, |hit| hit.t);
                sink.segment(&PhotonSegment { origin: b.origin, direction: b.dir, length, flux: b.flux });
            }
            let Some(hit) = hit else {
                stats.escaped += b.flux.as_dvec3();
                continue;
            };
            let p = b.origin + b.dir * hit.t;
            let ng = hit.geometric_normal;
            let travelled = b.travelled + hit.t;
            match hit.surface {
                Surface::Receiver(r) => {
                    // A point or spot light's range fades the light by the path it took.
                    let window = light.range_attenuation(travelled);
                    stats.absorbed += (b.flux * (1.0 - window)).as_dvec3();
                    let b = Branch { flux: b.flux * window, ..b };
                    if b.depth == 0 {
                        stats.direct += b.flux.as_dvec3();
                    } else {
                        stats.deposited += b.flux.as_dvec3();
                        let normal = if ng.dot(b.dir) > 0.0 { -ng } else { ng };
                        sink.deposit(&PhotonHit { position: p, normal, direction: b.dir, flux: b.flux, receiver: r });
                    }
                }
                Surface::Generator(g) => {
                    // The back of a one-sided surface, reached from outside, absorbs.
                    if self.sides[g as usize] == Sides::Front && b.dir.dot(ng) > 0.0 {
                        stats.absorbed += b.flux.as_dvec3();
                        continue;
                    }
                    let generator = &self.scene.generators[g as usize];
                    let ns = generator.mesh.shading_normal(hit.triangle as usize, hit.uv);
                    let mut children = [(Vec3::ZERO, 0.0f32); 2];
                    match generator.interaction.ior_at(wavelength) {
                        None => children[0] = (reflect(b.dir, ns), 1.0),
                        Some(ior) => {
                            let entering = b.dir.dot(ng) < 0.0;
                            let eta = if entering { 1.0 / ior } else { ior };
                            let r = fresnel_reflectance(b.dir.dot(ns), eta);
                            children[0] = (reflect(b.dir, ns), r);
                            if let Refraction::Transmitted(t) = refract(b.dir, ns, eta) {
                                children[1] = (t, 1.0 - r);
                            } else {
                                children[0].1 = 1.0;
                            }
                        }
                    }
                    for (dir, weight) in children {
                        if weight <= 0.0 {
                            continue;
                        }
                        let flux = b.flux * weight;
                        if b.depth + 1 > settings.max_depth || flux.max_element() < cutoff || len == stack.len() {
                            stats.dropped += flux.as_dvec3();
                            continue;
                        }
                        // Leave the surface on the side the new direction goes.
                        let side = if dir.dot(ng) >= 0.0 { ng } else { -ng };
                        stack[len] = Branch { origin: p + side * self.epsilon, dir, flux, depth: b.depth + 1, travelled };
                        len += 1;
                    }
                }
            }
        }
    }
}
