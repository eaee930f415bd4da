//! A scene fuzzer for every CPU twin: random scenes built from adversarial parts, each
//! run through the photon tracer, the caustic volumes, the caustic maps, illumination
//! textures and convolution caustics, and held to what must hold for any input.
//!
//! A case is drawn from `(seed, index)` alone, so any case is reproduced by its two
//! numbers. It belongs to one [`Category`] of trouble — degenerate or non-finite
//! meshes, extreme scales, impossible or borderline indices of refraction and
//! dispersion, lights grazing, inside a generator, on a receiver or far away, a focus
//! exactly on a receiver, empty scenes, a flood of photons on one texel, adversarial
//! pools. Its input either is refused with a clear error (a mesh, light or setting that
//! cannot be drawn: [`Verdict::Refused`]) or passes validation, and then every twin
//! must, without panicking ([`check_case`]):
//!
//! - give only finite outputs (irradiance, fluxes, textures, maps);
//! - put out no more energy than came in, to [`ENERGY_TOLERANCE`]: the tracer's
//!   deposits against its emitted flux; the volumes' kept flux against the light the
//!   generator triangles receive (each triangle's area times the largest irradiance at
//!   its corners, the build's own model, summed over lights and colour channels); a
//!   caustic map's resolved photons against the photons traced (each carries at most
//!   one unit); the illumination volumes' flux against the light on the object's
//!   triangles; the pool floor's mean irradiance against the sun's.
//!
//! [`CountingAllocator`] measures the memory a case takes when a binary installs it as
//! its global allocator (the CLI and the fuzz test do).

use crate::convolution::ripples::{PoolRipples as Ripples, RippleSettings};
use crate::convolution::{Boundary, ConvolutionCaustics, ConvolutionSettings, Heightfield, LobeAxis};
use crate::hierarchical::{CausticMapSettings, PhotonPaths, scene_caustics};
use crate::illumination_textures::{Cosine, DirectionGrid, IlluminationSettings, IlluminationTextures, LightTransportTable, TransportBuild};
use crate::mesh::TriMesh;
use crate::optics::CauchyDispersion;
use crate::params::SpecularInteraction;
use crate::rng::Pcg32;
use crate::scene::{Generator, Light, LightKind, Receiver, Scene};
use crate::tracer::{PhotonHit, PhotonSink, PhotonTracer, TraceSettings};
use crate::volumes::{VolumeSettings, build_scene_volumes};
use glam::{Affine3A, DVec3, Vec3};
use std::alloc::{GlobalAlloc, Layout, System};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Relative slack on every energy bound: the twins sum up to ~10⁵ `f32` terms, each
/// rounded to 2⁻²⁴, in orders that differ from the bound's own sum (10⁵ · 6·10⁻⁸ ≈
/// 6·10⁻³ at worst, ~10⁻⁴ in practice); 10⁻² leaves room for that and nothing else —
/// a real leak (a doubled triangle, a Fresnel weight above one) is far larger.
pub const ENERGY_TOLERANCE: f64 = 1e-2;

/// The most memory one case may hold at its peak (with [`CountingAllocator`]): cases
/// have at most a few thousand triangles and 2¹⁶ photons a light, so this bounds
/// what every twin allocates for them with room to spare.
pub const MEMORY_BOUND: usize = 512 << 20;

/// What a case is made to break.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    /// Zero-area and sliver triangles, duplicated and collinear vertices, inverted winding.
    DegenerateMesh,
    /// NaN and infinite positions or normals, zero normals, indices past the vertices,
    /// coordinates at and past [`crate::mesh::MAX_COORDINATE`], subnormal ones.
    NonFinite,
    /// The whole scene scaled by 10⁻⁶ to 10⁶.
    ExtremeScale,
    /// IOR exactly 1, 1 + 10⁻⁷, 4, 50, and impossible ones (below 1, NaN, infinite).
    Ior,
    /// Cauchy dispersion at and past its limits.
    Dispersion,
    /// Sunlight within a hair of the generator's plane.
    GrazingLight,
    /// A point or spot light inside a generator, or on one of its vertices.
    LightInside,
    /// A point light on a receiver.
    LightAtReceiver,
    /// A point light very far away, or of enormous or zero intensity.
    LightAtInfinity,
    /// A lens whose focus lies exactly on the receiver.
    FocalOnReceiver,
    /// No generators, no receivers, or no lights.
    EmptyScene,
    /// Many photons onto a receiver one texel wide.
    PhotonFlood,
    /// Adversarial pools for convolution caustics: spiky, flat, tiny or huge cells,
    /// grazing sun, extreme depth, scattering and extinction.
    Pool,
}

/// Every category, in the order cases cycle through them.
pub const CATEGORIES: [Category; 13] = [
    Category::DegenerateMesh,
    Category::NonFinite,
    Category::ExtremeScale,
    Category::Ior,
    Category::Dispersion,
    Category::GrazingLight,
    Category::LightInside,
    Category::LightAtReceiver,
    Category::LightAtInfinity,
    Category::FocalOnReceiver,
    Category::EmptyScene,
    Category::PhotonFlood,
    Category::Pool,
];

impl Category {
    /// What the twins do with this category's inputs (the table in docs/stability.md).
    pub fn handling(self) -> &'static str {
        match self {
            Category::DegenerateMesh => "zero-area triangles are dropped and counted (volumes: degenerate), slivers kept; fans and BVHs accept duplicates",
            Category::NonFinite => {
                "TriMesh::new refuses a non-finite position, a zero or non-finite normal, an index past the vertices, naming it, and a coordinate past 1e12 m; subnormal triangles are dropped as degenerate"
            }
            Category::ExtremeScale => "tolerances scale with the scene (the tracer's offset, the maps' views, the volumes' planes)",
            Category::Ior => "below 1, NaN or infinite: refused (ImpossibleIor); 1 casts no pattern; large ones stay finite",
            Category::Dispersion => "a Cauchy model with n < 1 in the visible range or non-finite terms is refused",
            Category::GrazingLight => "rays within the smallest cosine of the surface are dropped and counted (grazing)",
            Category::LightInside => "irradiance at a vertex on the light is clamped (r² ≥ 10⁻¹²); the light behind a face is unlit",
            Category::LightAtReceiver => "the light's own receiver point gets no caustic; everything stays finite",
            Category::LightAtInfinity => "far lights act as parallel ones; zero intensity gives zero caustics; a light above 1e20 (lux or cd) is refused",
            Category::FocalOnReceiver => "caustic triangles past the magnification limit are left out; the focus is bright and finite",
            Category::EmptyScene => "no lights: refused (NoLights); no generators or receivers: no caustics, no work",
            Category::PhotonFlood => "splats conserve their photons on a one-texel receiver; the tracer's balance closes",
            Category::Pool => "invalid heights or settings are refused naming the value; valid ones give a finite, non-negative floor",
        }
    }
}

/// How a case ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// Every twin ran; the largest energy ratio any of them reached (output over input).
    Passed {
        /// Largest output-over-input energy ratio any twin reached.
        energy_ratio: f64,
    },
    /// The input was refused before any twin ran, with this message.
    Refused(String),
    /// Something that must hold did not.
    Failed(String),
}

/// One case's result.
#[derive(Clone, Debug, PartialEq)]
pub struct CaseResult {
    /// The seed the case was drawn from.
    pub seed: u64,
    /// The case's index within its seed.
    pub index: u64,
    /// The kind of trouble the case was drawn from.
    pub category: Category,
    /// How the case ended.
    pub verdict: Verdict,
    /// Peak bytes allocated while it ran ([`CountingAllocator`]; 0 when not installed).
    pub peak_bytes: usize,
}

/// Case `index` of `seed`: its category (cases cycle through [`CATEGORIES`]) and its
/// draws.
fn case(seed: u64, index: u64) -> (Category, Draw) {
    (CATEGORIES[(index % CATEGORIES.len() as u64) as usize], Draw(Pcg32::for_photon(seed, 0x0f22, index)))
}

/// The scene of case `index` of `seed` when it is one that passes validation (not a
/// pool, not refused): what the GPU passes are fuzzed with.
pub fn valid_scene(seed: u64, index: u64) -> Option<(Category, Scene)> {
    let (category, mut draw) = case(seed, index);
    (category != Category::Pool).then(|| scene_case(category, &mut draw).ok()).flatten().map(|(scene, _)| (category, scene))
}

/// A rippling pool that passes validation, drawn from adversarial parts: what the GPU
/// convolution pass is fuzzed with. Coordinates are the pool's (x and z from 0 to its
/// size); the light's `sun_direction` is in the same frame.
#[derive(Clone, Debug)]
pub struct PoolCase {
    /// Texel columns of the pool (along x).
    pub columns: usize,
    /// Texel rows of the pool (along z).
    pub rows: usize,
    /// Side of one square texel (m).
    pub cell_size: f32,
    /// The wave each pebble's impulse sends out.
    pub waves: RippleSettings,
    /// The water and sunlight the caustics are computed for.
    pub light: ConvolutionSettings,
    /// Where pebbles fall (in the pool, on its walls and corners) and how high each
    /// impulse starts (m).
    pub pebbles: Vec<(glam::Vec2, f32)>,
}

/// Pool `index` of `seed` when it passes validation (`None` when its grid, waves or
/// light are refused): one- and two-texel pools, cells from a micrometre to a kilometre,
/// waves and damping from 10⁻³ to 10⁴, every light of [`Category::Pool`]'s cases, and
/// from no pebble to two hundred, of zero to ten metres, on the walls and corners.
pub fn valid_pool(seed: u64, index: u64) -> Option<PoolCase> {
    let mut draw = Draw(Pcg32::for_photon(seed, 0x9001, index));
    let (columns, rows) = (draw.pick(&[1, 2, 3, 8, 17, 32, 64]), draw.pick(&[1, 2, 5, 16, 32, 64]));
    let cell_size = draw.pick(&[1e-6, 1e-3, 0.05, 1.0, 1e3]);
    let waves = RippleSettings {
        wave_number: draw.pick(&[1e-3, 1.0, 60.0, 1e4]),
        angular_frequency: draw.pick(&[1e-3, 1.0, 20.0, 1e4]),
        time_damping: draw.pick(&[0.0, 0.5, 1e3]),
        front_damping: draw.pick(&[0.0, 0.5, 1e3]),
        expiry_height: draw.pick(&[1e-9, 1e-4, 1.0]),
    };
    let light = pool_light(&mut draw);
    Ripples::new(columns, rows, cell_size, waves).ok()?;
    ConvolutionCaustics::new(&light, columns, rows, cell_size).ok()?;
    let size = glam::Vec2::new(columns as f32, rows as f32) * cell_size;
    let count = draw.pick(&[0, 1, 5, 200]);
    let pebbles = (0..count)
        .map(|_| {
            let at = match draw.below(3) {
                0 => glam::Vec2::new(draw.unit(), draw.unit()),
                1 => glam::Vec2::new(draw.pick(&[0.0, 1.0]), draw.pick(&[0.0, 1.0])),
                _ => glam::Vec2::new(draw.pick(&[0.0, 1.0]), draw.unit()),
            };
            (at * size, draw.pick(&[0.0, 1e-6, 0.05, -0.05, 10.0]))
        })
        .collect();
    Some(PoolCase { columns, rows, cell_size, waves, light, pebbles })
}

/// Draws case `index` of `seed` and runs it through every twin.
pub fn run_case(seed: u64, index: u64) -> CaseResult {
    let (category, mut draw) = case(seed, index);
    let start = CountingAllocator::start_peak();
    let verdict = match catch_unwind(AssertUnwindSafe(|| check_case(category, &mut draw))) {
        Ok(verdict) => verdict,
        Err(panic) => {
            let message = panic.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| panic.downcast_ref::<String>().cloned());
            Verdict::Failed(format!("panicked: {}", message.unwrap_or_default()))
        }
    };
    let peak_bytes = CountingAllocator::peak_since(start);
    let verdict = match verdict {
        Verdict::Passed { .. } if peak_bytes > MEMORY_BOUND => {
            Verdict::Failed(format!("held {} MiB at its peak, past the {} MiB bound", peak_bytes >> 20, MEMORY_BOUND >> 20))
        }
        v => v,
    };
    CaseResult { seed, index, category, verdict, peak_bytes }
}

/// Random draws for a case.
struct Draw(Pcg32);

impl Draw {
    fn unit(&mut self) -> f32 {
        self.0.next_f32()
    }

    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    fn below(&mut self, n: usize) -> usize {
        (self.0.next_u32() as usize) % n.max(1)
    }

    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len())]
    }

    fn chance(&mut self, p: f32) -> bool {
        self.unit() < p
    }

    fn direction(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            if let Some(unit) = v.try_normalize().filter(|_| v.length_squared() <= 1.0) {
                return unit;
            }
        }
    }
}

/// A mesh as a modeller's file may hold it: positions, normals, triangles, unchecked.
#[derive(Clone, Debug, Default)]
struct RawMesh {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

impl RawMesh {
    /// A wavy sheet of `n × n` cells over `[-half, half]²` at height `y`, normals up.
    fn sheet(draw: &mut Draw, n: u32, half: f32, y: f32) -> Self {
        let amplitude = draw.range(0.0, 0.1) * half;
        let (kx, kz) = (draw.range(0.5, 6.0), draw.range(0.5, 6.0));
        let mut mesh = Self::default();
        for j in 0..=n {
            for i in 0..=n {
                let (u, v) = (i as f32 / n as f32 * 2.0 - 1.0, j as f32 / n as f32 * 2.0 - 1.0);
                let h = amplitude * (kx * u).sin() * (kz * v).cos();
                let (dx, dz) = (amplitude * kx * (kx * u).cos() * (kz * v).cos() / half, -amplitude * kz * (kx * u).sin() * (kz * v).sin() / half);
                mesh.positions.push(Vec3::new(u * half, y + h, v * half));
                mesh.normals.push(Vec3::new(-dx, 1.0, -dz).normalize());
            }
        }
        let stride = n + 1;
        for j in 0..n {
            for i in 0..n {
                let p = j * stride + i;
                mesh.triangles.push([p, p + stride, p + 1]);
                mesh.triangles.push([p + 1, p + stride, p + stride + 1]);
            }
        }
        mesh
    }

    fn of(mesh: &TriMesh) -> Self {
        Self { positions: mesh.positions().to_vec(), normals: mesh.normals().to_vec(), triangles: mesh.triangles().to_vec() }
    }

    fn build(self) -> Result<TriMesh, String> {
        TriMesh::new(self.positions, self.normals, self.triangles).map_err(|e| e.to_string())
    }

    /// Spoils it as `category` asks.
    fn spoil(&mut self, draw: &mut Draw, category: Category) {
        let v = self.positions.len();
        let t = self.triangles.len();
        match category {
            Category::DegenerateMesh => {
                for _ in 0..1 + draw.below(t / 4 + 1) {
                    let tri = draw.below(t);
                    let [a, b, c] = self.triangles[tri];
                    match draw.below(5) {
                        // Zero area: a repeated corner.
                        0 => self.triangles[tri] = [a, a, b],
                        // A sliver: a corner moved onto the opposite side.
                        1 => self.positions[c as usize] = self.positions[a as usize].lerp(self.positions[b as usize], draw.unit()),
                        // Duplicated vertices: a copy of a corner used in its place.
                        2 => {
                            self.positions.push(self.positions[a as usize]);
                            self.normals.push(self.normals[a as usize]);
                            self.triangles[tri] = [self.positions.len() as u32 - 1, b, c];
                        }
                        // Inverted winding.
                        3 => self.triangles[tri] = [a, c, b],
                        // Three collinear corners.
                        _ => {
                            let (pa, pb) = (self.positions[a as usize], self.positions[b as usize]);
                            self.positions[c as usize] = pa + 2.0 * (pb - pa);
                        }
                    }
                }
            }
            Category::NonFinite => match draw.below(9) {
                0 => self.positions[draw.below(v)].x = f32::NAN,
                1 => self.positions[draw.below(v)].y = f32::INFINITY,
                2 => self.normals[draw.below(v)] = Vec3::new(f32::NAN, 1.0, 0.0),
                3 => self.normals[draw.below(v)] = Vec3::ZERO,
                4 => self.triangles[draw.below(t)][draw.below(3)] = v as u32 + draw.below(5) as u32,
                5 => self.normals.truncate(v - 1),
                // Finite: at the largest coordinate a mesh may have, past it (its
                // squares overflow), and subnormal (its areas underflow).
                6 => self.positions.iter_mut().for_each(|p| *p *= crate::mesh::MAX_COORDINATE),
                7 => self.positions[draw.below(v)] = Vec3::new(3e38, -3e38, 3e38),
                _ => self.positions.iter_mut().for_each(|p| *p *= 1e-39),
            },
            _ => {}
        }
    }
}

/// A case's scene, or why it was refused.
fn scene_case(category: Category, draw: &mut Draw) -> Result<(Scene, u64), String> {
    let sun = Vec3::new(draw.range(-0.4, 0.4), -1.0, draw.range(-0.4, 0.4)).normalize();
    let mut lights = vec![Light::white(LightKind::Directional { direction: sun, irradiance: draw.range(0.1, 10.0) })];
    let mut interaction =
        if draw.chance(0.3) { SpecularInteraction::Reflect } else { SpecularInteraction::Refract { ior: draw.range(1.1, 2.4), dispersion: None } };
    let floor = TriMesh::quad(Vec3::ZERO, Vec3::X * 2.0, Vec3::Z * 2.0);
    let mut receivers = vec![Receiver { mesh: floor, albedo: Vec3::ONE }];
    let mut photons = 1 << 12;
    let cells = 2 + draw.below(10) as u32;
    let mut raw = RawMesh::sheet(draw, cells, 1.0, 1.0);
    let mut double_sided = draw.chance(0.5);
    match category {
        Category::DegenerateMesh | Category::NonFinite => raw.spoil(draw, category),
        Category::ExtremeScale => {
            let scale = 10f32.powf(draw.pick(&[-6.0, -4.0, -2.0, 2.0, 4.0, 6.0]) + draw.range(-0.5, 0.5));
            raw.positions.iter_mut().for_each(|p| *p *= scale);
            receivers[0].mesh = TriMesh::quad(Vec3::ZERO, Vec3::X * 2.0 * scale, Vec3::Z * 2.0 * scale);
            if draw.chance(0.5) {
                lights[0] = Light::white(LightKind::Point { position: Vec3::new(0.2, 3.0, 0.1) * scale, intensity: draw.range(1.0, 100.0) * scale * scale });
            }
        }
        Category::Ior => {
            let ior = draw.pick(&[1.0, 1.0 + 1e-7, 1.0 + 1e-4, 4.0, 50.0, 1e6, 0.999, 0.0, -1.5, f32::NAN, f32::INFINITY]);
            interaction = SpecularInteraction::Refract { ior, dispersion: None };
            if draw.chance(0.5) {
                raw = RawMesh::of(&TriMesh::uv_sphere(Vec3::Y, 0.5, 4 + draw.below(8), 6 + draw.below(10)));
            }
        }
        Category::Dispersion => {
            let b = draw.pick(&[0.0, 1e-9, 0.004, 0.02, 0.2, -0.01, -0.2, 1e3, f32::NAN]);
            let a = draw.pick(&[1.0, 1.0001, 1.3, 1.5, 2.0, 0.9, 1e3]);
            interaction = SpecularInteraction::Refract { ior: a, dispersion: Some(CauchyDispersion { a, b }) };
            if draw.chance(0.5) {
                raw = RawMesh::of(&TriMesh::uv_sphere(Vec3::Y, 0.5, 6, 10));
            }
        }
        Category::GrazingLight => {
            let elevation = draw.pick(&[1e-7, 1e-5, 1e-3, 0.01, 0.05]);
            let azimuth = draw.range(0.0, std::f32::consts::TAU);
            let direction = Vec3::new(azimuth.cos(), -elevation, azimuth.sin());
            lights[0] = Light::white(LightKind::Directional { direction, irradiance: 1.0 });
        }
        Category::LightInside => {
            raw = RawMesh::of(&TriMesh::uv_sphere(Vec3::Y, 0.5, 4 + draw.below(6), 6 + draw.below(8)));
            let position = if draw.chance(0.5) { raw.positions[draw.below(raw.positions.len())] } else { Vec3::Y + draw.direction() * draw.range(0.0, 0.45) };
            lights[0] = if draw.chance(0.5) {
                Light::white(LightKind::Point { position, intensity: draw.range(1.0, 100.0) })
            } else {
                let (inner, outer) = (draw.range(0.0, 1.0), draw.range(0.0, 1.6));
                Light::white(LightKind::Spot { position, direction: draw.direction(), intensity: 10.0, inner_angle: inner, outer_angle: outer })
            };
        }
        Category::LightAtReceiver => {
            let position = Vec3::new(draw.range(-2.0, 2.0), 0.0, draw.range(-2.0, 2.0));
            lights[0] = Light::white(LightKind::Point { position, intensity: draw.range(1.0, 100.0) });
            double_sided = true;
        }
        Category::LightAtInfinity => {
            let distance = 10f32.powf(draw.range(3.0, 30.0));
            let intensity = draw.pick(&[0.0, 1.0, distance * distance, f32::MAX, 1e30]);
            lights[0] = Light::white(LightKind::Point { position: Vec3::new(0.1, 1.0, 0.2).normalize() * distance, intensity });
        }
        Category::FocalOnReceiver => {
            // A thin plano-convex lens (a sphere cap) of focal length f = R / (n − 1)
            // held f above the floor: the paraxial focus lies on it.
            let (ior, radius) = (draw.range(1.3, 1.9), draw.range(0.3, 1.0));
            let focal = radius / (ior - 1.0);
            let lens = TriMesh::uv_sphere(Vec3::ZERO, radius, 6 + draw.below(10), 8 + draw.below(12));
            raw = RawMesh::of(&lens);
            raw.positions.iter_mut().for_each(|p| *p = Vec3::new(p.x, p.y * 0.2 + focal, p.z));
            interaction = SpecularInteraction::Refract { ior, dispersion: None };
            lights[0] = Light::white(LightKind::Directional { direction: Vec3::NEG_Y, irradiance: 1.0 });
        }
        Category::EmptyScene => match draw.below(3) {
            0 => lights.clear(),
            1 => receivers.clear(),
            _ => raw = RawMesh::default(),
        },
        Category::PhotonFlood => {
            photons = 1 << 16;
            let texel = draw.pick(&[1e-3, 1e-5, 1e-7]);
            receivers[0].mesh = TriMesh::quad(Vec3::new(0.0, 0.0, 0.0), Vec3::X * texel, Vec3::Z * texel);
            raw = RawMesh::of(&TriMesh::uv_sphere(Vec3::Y, 0.5, 8, 12));
            interaction = SpecularInteraction::Refract { ior: 1.5, dispersion: None };
        }
        Category::Pool => unreachable!("pools are not scenes"),
    }
    let generators = if raw.triangles.is_empty() { Vec::new() } else { vec![Generator { double_sided, ..Generator::new(raw.build()?, interaction) }] };
    let scene = Scene { lights, generators, receivers };
    scene.validate().map_err(|e| e.to_string())?;
    Ok((scene, photons))
}

/// Sums the tracer's deposits, checking each.
#[derive(Default)]
struct Deposits {
    flux: DVec3,
    bad: Option<String>,
}

impl PhotonSink for Deposits {
    fn empty_like(&self) -> Self {
        Self::default()
    }

    fn deposit(&mut self, hit: &PhotonHit) {
        let finite = hit.position.is_finite() && hit.normal.is_finite() && hit.direction.is_finite() && hit.flux.is_finite();
        if (!finite || hit.flux.min_element() < 0.0) && self.bad.is_none() {
            self.bad = Some(format!("the tracer deposited {hit:?}"));
        }
        self.flux += hit.flux.as_dvec3();
    }

    fn merge(&mut self, other: Self) {
        self.flux += other.flux;
        self.bad = self.bad.take().or(other.bad);
    }
}

/// Points on every receiver (its corners and triangle centres) with their normals,
/// for the twins' irradiance queries.
fn receiver_points(scene: &Scene) -> Vec<(Vec3, Vec3)> {
    scene
        .receivers
        .iter()
        .flat_map(|r| {
            (0..r.mesh.triangles().len()).flat_map(move |t| {
                let c = r.mesh.corners(t);
                let n = (c[1] - c[0]).cross(c[2] - c[0]).normalize_or(Vec3::Y);
                [(c[0], n), ((c[0] + c[1] + c[2]) / 3.0, n)]
            })
        })
        .collect()
}

/// The light that reaches the generators' triangles, as the builds model it: per
/// triangle, its area times the largest irradiance at its corners, in the light's mean
/// colour (a dispersive generator's channels split it).
fn incident_bound(scene: &Scene) -> f64 {
    let mut total = 0.0;
    for light in &scene.lights {
        let colour = light.color.element_sum() as f64 / 3.0;
        for generator in &scene.generators {
            for t in 0..generator.mesh.triangles().len() {
                let c = generator.mesh.corners(t);
                let area = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length() as f64;
                let irradiance = c.iter().map(|&p| light.incident(p).1 as f64).fold(0.0, f64::max);
                total += area * irradiance * colour;
            }
        }
    }
    total
}

/// `output / input`, 0 when both are 0, an error when the output passes the input.
fn energy_ratio(twin: &str, output: f64, input: f64) -> Result<f64, String> {
    if !output.is_finite() || output < 0.0 {
        return Err(format!("{twin}: energy {output} is not a finite, non-negative number"));
    }
    let ratio = if output == 0.0 { 0.0 } else { output / input };
    if ratio > 1.0 + ENERGY_TOLERANCE || (ratio.is_nan() && output > 0.0) {
        return Err(format!("{twin}: put out {output:e} of {input:e} that came in ({ratio:.4}×)"));
    }
    Ok(ratio)
}

fn finite_all(twin: &str, what: &str, values: impl IntoIterator<Item = f32>) -> Result<(), String> {
    match values.into_iter().find(|v| !v.is_finite() || *v < 0.0) {
        Some(v) => Err(format!("{twin}: {what} holds {v}")),
        None => Ok(()),
    }
}

/// Runs a case through every twin that takes its input.
fn check_case(category: Category, draw: &mut Draw) -> Verdict {
    let result = if category == Category::Pool { pool_case(draw) } else { scene_case(category, draw).map(|(scene, photons)| check_scene(&scene, photons)) };
    match result {
        Ok(Ok(energy_ratio)) => Verdict::Passed { energy_ratio },
        Ok(Err(failure)) => Verdict::Failed(failure),
        Err(refusal) if refusal.trim().is_empty() => Verdict::Failed("refused without a message".into()),
        Err(refusal) => Verdict::Refused(refusal),
    }
}

/// Every scene twin on a valid scene; the largest energy ratio.
fn check_scene(scene: &Scene, photons: u64) -> Result<f64, String> {
    let mut worst = 0.0f64;
    let points = receiver_points(scene);

    let tracer = PhotonTracer::new(scene).map_err(|e| format!("tracer refused a valid scene: {e}"))?;
    let mut deposits = Deposits::default();
    let stats = tracer.trace(&TraceSettings { photons_per_light: photons, ..TraceSettings::default() }, &mut deposits, &|_, _| {});
    if let Some(bad) = deposits.bad {
        return Err(bad);
    }
    let parts = stats.deposited + stats.direct + stats.escaped + stats.dropped + stats.absorbed;
    let emitted = stats.emitted.element_sum();
    if !(emitted.is_finite() && (parts.element_sum() - emitted).abs() <= ENERGY_TOLERANCE * emitted.max(f64::MIN_POSITIVE)) {
        return Err(format!("tracer: its balance does not close: {stats:?}"));
    }
    worst = worst.max(energy_ratio("tracer", deposits.flux.element_sum(), emitted)?);

    let settings = VolumeSettings::default();
    let volumes = build_scene_volumes(scene, &settings);
    let flux = volumes.stats.flux.element_sum() / 3.0;
    if !(volumes.stats.dropped_flux.is_finite()) {
        return Err(format!("volumes: dropped flux {:?}", volumes.stats.dropped_flux));
    }
    worst = worst.max(energy_ratio("volumes", flux, incident_bound(scene))?);
    for &(p, n) in &points {
        let e = volumes.irradiance(p, n, &settings);
        finite_all("volumes", "the irradiance on a receiver", e.to_array())?;
    }

    let maps =
        CausticMapSettings { photon_resolution: 32, map_resolution: 32, paths: PhotonPaths::Traced, fresnel_branches: 1, ..CausticMapSettings::default() };
    for view in scene_caustics(scene, &maps) {
        finite_all("caustic maps", "the resolved map", view.resolved.iter().copied())?;
        let traced = (maps.photon_resolution as f64).powi(2) * maps.photon_buffers() as f64;
        worst = worst.max(energy_ratio("caustic maps", view.resolved.iter().map(|&v| v as f64).sum(), traced)?);
        for &(p, n) in &points {
            finite_all("caustic maps", "the irradiance on a receiver", [view.irradiance_at(p, n)])?;
        }
    }

    for generator in &scene.generators {
        let SpecularInteraction::Refract { ior, .. } = generator.interaction else { continue };
        let build = TransportBuild { ior, grid: DirectionGrid::new(4) };
        // An open mesh has no light transport table: illumination textures decline it.
        let Ok(table) = LightTransportTable::build(&generator.mesh, build, &|_, _| {}) else { continue };
        for light in &scene.lights {
            let settings = IlluminationSettings { planes: 2, texture_size: 16 };
            let Some(textures) = IlluminationTextures::frame(&table, &generator.mesh, &Affine3A::IDENTITY, light, &scene.receivers, &settings) else {
                continue;
            };
            let textures = textures.drawn();
            for plane in &textures.planes {
                finite_all("illumination textures", "a texture", plane.texture.iter().flat_map(|t| [t.w, t.x.abs(), t.y.abs(), t.z.abs()]))?;
            }
            // `flux_out` is in the light's mean colour already.
            let alone = Scene { lights: vec![*light], generators: vec![generator.clone()], receivers: Vec::new() };
            worst = worst.max(energy_ratio("illumination textures", textures.flux_out, incident_bound(&alone))?);
            for &(p, n) in &points {
                finite_all("illumination textures", "the irradiance on a receiver", textures.irradiance_at(p, n, Cosine::Receiver).to_array())?;
            }
        }
    }
    Ok(worst)
}

/// A pool for convolution caustics: `Err` when refused; `Ok(Err)` on a failure.
fn pool_case(draw: &mut Draw) -> Result<Result<f64, String>, String> {
    let (columns, rows) = (draw.pick(&[1, 2, 3, 8, 17, 32]), draw.pick(&[1, 2, 5, 16, 32]));
    let cell = draw.pick(&[1e-6, 1e-3, 0.05, 1.0, 1e3, 0.0, f32::NAN]);
    let amplitude = draw.pick(&[0.0, 1e-6, 0.01, 0.3, 10.0]);
    let mut heights: Vec<f32> = (0..columns * rows).map(|_| amplitude * draw.range(-1.0, 1.0)).collect();
    if draw.chance(0.1) {
        let at = draw.below(heights.len());
        heights[at] = draw.pick(&[f32::NAN, f32::INFINITY, 1e30]);
    }
    let heightfield = Heightfield::new(columns, rows, cell, heights).map_err(|e| e.to_string())?;
    let settings = pool_light(draw);
    let mut caustics = ConvolutionCaustics::new(&settings, columns, rows, cell).map_err(|e| e.to_string())?;
    let floor = caustics.irradiance(&heightfield).map_err(|e| e.to_string())?;
    Ok(finite_all("convolution", "the floor's irradiance", floor.iter().copied()).and_then(|()| {
        let mean = floor.iter().map(|&e| e as f64).sum::<f64>() / floor.len() as f64;
        energy_ratio("convolution", mean, settings.sun_irradiance as f64)
    }))
}

/// The light of an adversarial pool: the sun from grazing to overhead, from dark to
/// 10³⁰, indices of refraction and every kernel setting at and past their limits.
fn pool_light(draw: &mut Draw) -> ConvolutionSettings {
    let elevation: f32 = draw.pick(&[1e-6, 0.01, 0.3, 1.0, std::f32::consts::FRAC_PI_2]);
    let azimuth = draw.range(0.0, std::f32::consts::TAU);
    ConvolutionSettings {
        ior: draw.pick(&[1.0, 1.333, 2.4, 50.0, 0.5]),
        sun_direction: Vec3::new(elevation.cos() * azimuth.cos(), -elevation.sin(), elevation.cos() * azimuth.sin()),
        sun_irradiance: draw.pick(&[0.0, 1.0, 1e5, 1e30]),
        depth: draw.pick(&[1e-6, 0.01, 1.0, 100.0, 1e6, 0.0]),
        scattering: draw.pick(&[0.0, 1.0, 50.0, 1e4]),
        exponent: draw.pick(&[0.0, 1.0, 100.0, 1e5, 2e5]),
        extinction: draw.pick(&[0.0, 0.1, 10.0, 1e4]),
        kernel_radius: draw.pick(&[0, 1, 3, 40]),
        boundary: draw.pick(&[Boundary::Mirror, Boundary::Periodic]),
        lobe_axis: draw.pick(&[LobeAxis::Vertical, LobeAxis::RefractedSun]),
    }
}

/// A global allocator that counts the bytes in use and their peak: install it with
/// `#[global_allocator] static A: CountingAllocator = CountingAllocator;` to have
/// [`run_case`] measure each case's memory.
pub struct CountingAllocator;

static IN_USE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

impl CountingAllocator {
    /// Starts a new peak from the bytes in use now; returns them.
    fn start_peak() -> usize {
        let now = IN_USE.load(Ordering::Relaxed);
        PEAK.store(now, Ordering::Relaxed);
        now
    }

    /// The peak since [`Self::start_peak`] above what was in use then.
    fn peak_since(start: usize) -> usize {
        PEAK.load(Ordering::Relaxed).saturating_sub(start)
    }

    fn grew(size: usize) {
        let now = IN_USE.fetch_add(size, Ordering::Relaxed) + size;
        PEAK.fetch_max(now, Ordering::Relaxed);
    }
}

// SAFETY: every call goes to `System` unchanged; the counters only observe it.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc`, passed on.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            Self::grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract for `dealloc`, passed on.
        unsafe { System.dealloc(ptr, layout) };
        IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's contract for `realloc`, passed on.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
            Self::grew(new_size);
        }
        p
    }
}
