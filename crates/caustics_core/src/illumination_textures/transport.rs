//! The light transport table (§3, after Iwasaki et al. 2004 [12]): for every vertex
//! of a rigid transparent mesh and every direction the vertex can be lit from, where
//! the light leaves the object and how much of it, precomputed once per mesh. The
//! paper's §4.1 then reads the outgoing ray at each vertex "by simply referring to the
//! light transport table using the incident light direction": a moving, turning object
//! and a moving light only change which direction is looked up (in the object's frame).
//!
//! Choices where the paper is silent:
//! - **Directions**: the hemisphere a vertex is lit from (around its normal; light from
//!   behind reaches it through the object, which the paper's limitation leaves out),
//!   on a hemi-octahedral grid whose corners include the horizon, so that bilinear
//!   interpolation covers every direction without a seam ([`DirectionGrid`]).
//! - **The two interfaces**: in at the vertex with its (smooth) normal, out where the
//!   refracted ray first meets the mesh (the core's BVH), with the interpolated normal
//!   there; Fresnel transmittance of both. Light reflected inside is dropped, as the
//!   paper does (§6), and a ray past the critical angle at the exit is counted as
//!   totally internally reflected.
//! - **Interpolation**: the four samples around a direction, bilinearly; a lost sample
//!   (total internal reflection) weighs in with no light, so light fades smoothly to
//!   the critical directions, and position and direction come from the others.

use crate::bvh::SceneBvh;
use crate::mesh::TriMesh;
use crate::optics::{Refraction, fresnel_transmittance, refract};
use crate::params::SpecularInteraction;
use crate::scene::{Generator, Scene};
use glam::{Affine3A, Vec2, Vec3};
use rayon::prelude::*;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Bumped whenever the table's content or file layout changes: older cache files are
/// rebuilt, not read.
pub const TRANSPORT_CACHE_VERSION: u32 = 1;

/// Why a table cannot be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TransportError {
    /// The mesh is not closed, so light entering it has no far side to leave by.
    #[error("the light transport table needs a closed (watertight) mesh: light must leave through a far side")]
    NotClosed,
    /// An index of refraction below 1 or not finite.
    #[error("index of refraction {0} is impossible: it must be a finite number ≥ 1")]
    ImpossibleIor(f32),
    /// The mesh has no triangles.
    #[error("the mesh has no triangles")]
    Empty,
}

/// The directions a vertex is lit from: `side²` samples on the hemisphere around its
/// normal, a hemi-octahedral map of the square `[−1, 1]²` sampled at `side` points a
/// row, corners and edges (the horizon) included.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct DirectionGrid {
    side: u32,
}

impl Default for DirectionGrid {
    /// 16² = 256 directions a vertex: on the `sphere` bench scene (a 2.1K-vertex ball)
    /// its caustic reads L2 0.10 against the tracer, where 8² reads 0.24, in a 14 MB
    /// table. The paper's 6.4K-vertex ball would take 44 MB; [`Self::fitting`] lowers
    /// the grid to a budget (the paper keeps its tables under 20 MB, §5).
    fn default() -> Self {
        Self::new(16)
    }
}

impl DirectionGrid {
    /// A grid of `side²` directions (at least 2²).
    pub fn new(side: u32) -> Self {
        Self { side: side.max(2) }
    }

    /// The largest grid up to `side` whose table for `vertices` vertices fits in
    /// `max_bytes`, and whether it had to be lowered.
    pub fn fitting(side: u32, vertices: usize, max_bytes: usize) -> (Self, bool) {
        let mut grid = Self::new(side);
        while grid.side > 2 && LightTransportTable::bytes_for(vertices, grid) > max_bytes {
            grid.side -= 1;
        }
        (grid, grid.side < side.max(2))
    }

    /// Directions along a side of the grid (at least 2).
    pub fn side(&self) -> u32 {
        self.side
    }

    /// Directions per vertex.
    pub fn len(&self) -> usize {
        (self.side * self.side) as usize
    }

    /// Never: a grid holds at least 2² directions.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The unit direction towards the light of sample `(i, j)`, in a frame whose z is
    /// the vertex normal.
    pub fn direction(&self, i: u32, j: u32) -> Vec3 {
        let s = (self.side - 1) as f32;
        decode(Vec2::new(2.0 * i as f32 / s - 1.0, 2.0 * j as f32 / s - 1.0))
    }

    /// The grid cell a local direction (z ≥ 0) falls in: its lower corner and the
    /// fractions towards the upper one.
    pub fn locate(&self, local: Vec3) -> (u32, u32, Vec2) {
        let q = (encode(local) + 1.0) * (0.5 * (self.side - 1) as f32);
        let base = q.floor().clamp(Vec2::ZERO, Vec2::splat((self.side - 2) as f32));
        (base.x as u32, base.y as u32, (q - base).clamp(Vec2::ZERO, Vec2::ONE))
    }
}

/// The upper hemisphere onto the square `[−1, 1]²`: the octahedral projection, turned
/// by 45°.
fn encode(d: Vec3) -> Vec2 {
    let p = Vec2::new(d.x, d.y) / (d.x.abs() + d.y.abs() + d.z.max(0.0)).max(f32::MIN_POSITIVE);
    Vec2::new(p.x + p.y, p.x - p.y)
}

fn decode(e: Vec2) -> Vec3 {
    let p = 0.5 * Vec2::new(e.x + e.y, e.x - e.y);
    Vec3::new(p.x, p.y, (1.0 - p.x.abs() - p.y.abs()).max(0.0)).normalize()
}

/// A vertex's tangent frame: `(tangent, bitangent, normal)`, the same every time.
fn frame(normal: Vec3) -> (Vec3, Vec3, Vec3) {
    let (t, b) = normal.any_orthonormal_pair();
    (t, b, normal)
}

/// Light leaving the object: where, which way, and the fraction of the light arriving
/// at the vertex that does (both Fresnel transmittances); 0 where it is lost. In the
/// table, which [`LightTransportTable::lookup`] interpolates, two parts are kept apart
/// from what the lookup knows exactly: `direction` holds the deviation from the
/// incident direction (`out − in`; a slab deviates nothing), and `transmittance` the
/// far side's Fresnel factor alone, the entry's being exact at the looked-up cosine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transported {
    /// Where the light leaves the object.
    pub exit: Vec3,
    /// The unit direction it leaves in; in the table, the deviation `out − in` instead.
    pub direction: Vec3,
    /// Fraction of the vertex's light that leaves (in the table: the far side's Fresnel
    /// factor alone); 0 where it is lost.
    pub transmittance: f32,
}

impl Transported {
    const LOST: Self = Self { exit: Vec3::ZERO, direction: Vec3::ZERO, transmittance: 0.0 };
}

/// Where [`LightTransportTable::load_or_build`] found its table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CacheOutcome {
    /// Read from the cache: built from the same mesh and settings.
    Loaded,
    /// Built, and written to the cache.
    Built,
    /// Built; the cache could not be written (the reason), so the next run builds again.
    BuiltNotWritten(String),
}

/// What a build found and cost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TransportStats {
    /// Table entries: vertices × directions.
    pub entries: usize,
    /// Entries whose light leaves the object.
    pub transmitted: usize,
    /// Entries lost to total internal reflection at the far side.
    pub total_internal_reflection: usize,
    /// Entries whose refracted ray met no far side (a mesh closed only by welding, or
    /// rounding at a vertex).
    pub missed: usize,
    /// Wall time of the build, seconds.
    pub build_seconds: f64,
}

/// How to build a table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransportBuild {
    /// Index of refraction of the object (finite, ≥ 1).
    pub ior: f32,
    /// The directions each vertex is lit from.
    pub grid: DirectionGrid,
}

/// The table of one mesh and index of refraction: `grid.len()` entries per vertex.
#[derive(Clone, Debug, PartialEq)]
pub struct LightTransportTable {
    key: u64,
    build: TransportBuild,
    normals: Vec<Vec3>,
    entries: Vec<Transported>,
    /// What the build found and cost.
    pub stats: TransportStats,
}

impl LightTransportTable {
    /// Traces every vertex's every direction through `mesh` (in its own frame),
    /// calling `progress(done, total)` as vertices are done.
    pub fn build(mesh: &TriMesh, build: TransportBuild, progress: &(dyn Fn(u64, u64) + Sync)) -> Result<Self, TransportError> {
        if !(build.ior.is_finite() && build.ior >= 1.0) {
            return Err(TransportError::ImpossibleIor(build.ior));
        }
        if mesh.triangles().is_empty() {
            return Err(TransportError::Empty);
        }
        if !mesh.is_closed() {
            return Err(TransportError::NotClosed);
        }
        let start = Instant::now();
        let scene = Scene {
            lights: Vec::new(),
            generators: vec![Generator::new(mesh.clone(), SpecularInteraction::Refract { ior: build.ior, dispersion: None })],
            receivers: Vec::new(),
        };
        let bvh = SceneBvh::build(&scene);
        let (lo, hi) = mesh.bounds();
        let hair = 1e-5 * (hi - lo).length().max(1e-6);
        let grid = build.grid;
        let vertices = mesh.positions().len();
        let done = std::sync::atomic::AtomicU64::new(0);
        let entries: Vec<Transported> = (0..vertices)
            .into_par_iter()
            .flat_map_iter(|v| {
                let (p, n) = (mesh.positions()[v], mesh.normals()[v]);
                let (t, b, n) = frame(n);
                let row: Vec<Transported> = (0..grid.side)
                    .flat_map(|j| (0..grid.side).map(move |i| (i, j)))
                    .map(|(i, j)| {
                        let l = grid.direction(i, j);
                        trace(&bvh, mesh, p, n, t * l.x + b * l.y + n * l.z, build.ior, hair)
                    })
                    .collect();
                let finished = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                if finished.is_multiple_of(256) || finished == vertices as u64 {
                    progress(finished, vertices as u64);
                }
                row
            })
            .collect();
        let count = |f: &dyn Fn(&Transported) -> bool| entries.iter().filter(|e| f(e)).count();
        let transmitted = count(&|e| e.transmittance > 0.0);
        let missed = count(&|e| e.transmittance < 0.0);
        let entries: Vec<Transported> = entries.into_iter().map(|e| if e.transmittance > 0.0 { e } else { Transported::LOST }).collect();
        let stats = TransportStats {
            entries: entries.len(),
            transmitted,
            total_internal_reflection: entries.len() - transmitted - missed,
            missed,
            build_seconds: start.elapsed().as_secs_f64(),
        };
        Ok(Self { key: Self::key(mesh, build), build, normals: mesh.normals().to_vec(), entries, stats })
    }

    /// The table's size in memory, bytes.
    pub fn bytes(&self) -> usize {
        Self::bytes_for(self.normals.len(), self.build.grid)
    }

    fn bytes_for(vertices: usize, grid: DirectionGrid) -> usize {
        vertices * (size_of::<Vec3>() + grid.len() * size_of::<Transported>())
    }

    /// The index of refraction and direction grid the table was built with.
    pub fn build_settings(&self) -> TransportBuild {
        self.build
    }

    /// The light from direction `to_light` (unit, object frame) arriving at vertex
    /// `vertex`, as it leaves the object: bilinear between the four table directions
    /// around it. `None` where the vertex faces away from the light, or all four
    /// samples lose their light.
    pub fn lookup(&self, vertex: usize, to_light: Vec3) -> Option<Transported> {
        let (t, b, n) = frame(*self.normals.get(vertex)?);
        let local = Vec3::new(to_light.dot(t), to_light.dot(b), to_light.dot(n));
        // Light from behind the vertex, or a NaN direction: nothing to look up.
        if local.z.is_nan() || local.z <= 0.0 {
            return None;
        }
        let grid = self.build.grid;
        let (i, j, f) = grid.locate(local);
        let at = |i: u32, j: u32| self.entries[vertex * grid.len() + (j * grid.side + i) as usize];
        let taps = [(at(i, j), (1.0 - f.x) * (1.0 - f.y)), (at(i + 1, j), f.x * (1.0 - f.y)), (at(i, j + 1), (1.0 - f.x) * f.y), (at(i + 1, j + 1), f.x * f.y)];
        let (mut exit, mut deviation, mut transmittance, mut weight) = (Vec3::ZERO, Vec3::ZERO, 0.0, 0.0);
        for (e, w) in taps {
            transmittance += w * e.transmittance;
            if e.transmittance > 0.0 {
                exit += w * e.exit;
                deviation += w * e.direction;
                weight += w;
            }
        }
        let direction = (deviation / weight.max(f32::MIN_POSITIVE) - to_light).normalize_or_zero();
        let transmittance = transmittance * fresnel_transmittance(local.z, 1.0 / self.build.ior);
        (weight > 0.0).then(|| Transported { exit: exit / weight, direction, transmittance })
    }

    /// [`Self::lookup`] for an object placed by `world_from_object` (a rigid motion):
    /// the light's direction into the object's frame, the result back out.
    pub fn lookup_world(&self, vertex: usize, to_light: Vec3, world_from_object: &Affine3A) -> Option<Transported> {
        let object_from_world = world_from_object.inverse();
        let local = object_from_world.transform_vector3(to_light).normalize_or_zero();
        self.lookup(vertex, local).map(|e| Transported {
            exit: world_from_object.transform_point3(e.exit),
            direction: world_from_object.transform_vector3(e.direction).normalize_or_zero(),
            transmittance: e.transmittance,
        })
    }

    /// The content key of `mesh` under `build`: FNV-1a over the cache version, the
    /// settings and every position, normal and index.
    pub fn key(mesh: &TriMesh, build: TransportBuild) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bits: u32| {
            for byte in bits.to_le_bytes() {
                h = (h ^ byte as u64).wrapping_mul(0x0100_0000_01b3);
            }
        };
        eat(TRANSPORT_CACHE_VERSION);
        eat(build.ior.to_bits());
        eat(build.grid.side);
        for c in mesh.positions().iter().chain(mesh.normals()).flat_map(|v| v.to_array()) {
            eat(c.to_bits());
        }
        for &i in mesh.triangles().iter().flatten() {
            eat(i);
        }
        h
    }

    /// The table of `mesh` from `cache_dir` when a file there was built from the same
    /// mesh and settings, else built (with `progress`) and written there. A file that
    /// does not match is rebuilt, never trusted.
    pub fn load_or_build(
        cache_dir: &Path,
        mesh: &TriMesh,
        build: TransportBuild,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Self, CacheOutcome), TransportError> {
        let key = Self::key(mesh, build);
        let path = Self::cache_path(cache_dir, key);
        if let Some(table) = Self::read(&path).filter(|t| t.key == key && t.normals.len() == mesh.positions().len()) {
            return Ok((table, CacheOutcome::Loaded));
        }
        let table = Self::build(mesh, build, progress)?;
        let outcome = match table.write(&path) {
            Ok(()) => CacheOutcome::Built,
            Err(e) => CacheOutcome::BuiltNotWritten(format!("{}: {e}", path.display())),
        };
        Ok((table, outcome))
    }

    /// Where the table of content key `key` is cached under `cache_dir`.
    pub fn cache_path(cache_dir: &Path, key: u64) -> PathBuf {
        cache_dir.join(format!("light-transport-{key:016x}.bin"))
    }

    const MAGIC: &'static [u8; 4] = b"CLTT";

    /// Writes the table to `path` whole or not at all (a temporary file, renamed).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let mut bytes = Vec::with_capacity(self.bytes() + 64);
        bytes.extend_from_slice(Self::MAGIC);
        bytes.extend_from_slice(&TRANSPORT_CACHE_VERSION.to_le_bytes());
        bytes.extend_from_slice(&self.key.to_le_bytes());
        bytes.extend_from_slice(&self.build.ior.to_le_bytes());
        bytes.extend_from_slice(&self.build.grid.side.to_le_bytes());
        bytes.extend_from_slice(&(self.normals.len() as u64).to_le_bytes());
        let floats = self
            .normals
            .iter()
            .flat_map(|n| n.to_array())
            .chain(self.entries.iter().flat_map(|e| [e.exit.to_array(), e.direction.to_array()].concat().into_iter().chain([e.transmittance])));
        for f in floats {
            bytes.extend_from_slice(&f.to_le_bytes());
        }
        let counts = [self.stats.transmitted, self.stats.total_internal_reflection, self.stats.missed];
        for c in counts {
            bytes.extend_from_slice(&(c as u64).to_le_bytes());
        }
        let temporary = path.with_extension("part");
        std::fs::File::create(&temporary)?.write_all(&bytes)?;
        std::fs::rename(&temporary, path)
    }

    /// Reads a table written by [`Self::write`]; `None` for a missing, truncated or
    /// foreign file, or one of another cache version.
    pub fn read(path: &Path) -> Option<Self> {
        let mut bytes = Vec::new();
        std::fs::File::open(path).ok()?.read_to_end(&mut bytes).ok()?;
        let mut at = 0usize;
        let mut take = |n: usize| -> Option<&[u8]> {
            let slice = bytes.get(at..at + n)?;
            at += n;
            Some(slice)
        };
        if take(4)? != Self::MAGIC || u32::from_le_bytes(take(4)?.try_into().ok()?) != TRANSPORT_CACHE_VERSION {
            return None;
        }
        let key = u64::from_le_bytes(take(8)?.try_into().ok()?);
        let ior = f32::from_le_bytes(take(4)?.try_into().ok()?);
        let grid = DirectionGrid::new(u32::from_le_bytes(take(4)?.try_into().ok()?));
        let vertices = usize::try_from(u64::from_le_bytes(take(8)?.try_into().ok()?)).ok()?;
        let floats = vertices.checked_mul(3 + 7 * grid.len())?;
        let data: Vec<f32> = take(floats.checked_mul(4)?)?.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
        let mut count = || usize::try_from(u64::from_le_bytes(take(8)?.try_into().ok()?)).ok();
        let (transmitted, total_internal_reflection, missed) = (count()?, count()?, count()?);
        let (normals, entries) = data.split_at(3 * vertices);
        let normals = normals.chunks_exact(3).map(Vec3::from_slice).collect();
        let entries: Vec<Transported> = entries
            .chunks_exact(7)
            .map(|c| Transported { exit: Vec3::from_slice(&c[0..3]), direction: Vec3::from_slice(&c[3..6]), transmittance: c[6] })
            .collect();
        let stats = TransportStats { entries: entries.len(), transmitted, total_internal_reflection, missed, build_seconds: 0.0 };
        Some(Self { key, build: TransportBuild { ior, grid }, normals, entries, stats })
    }
}

/// One entry: in at `p` (normal `n`) from `to_light`, out where the refracted ray
/// first meets the mesh, with the far side's Fresnel transmittance. −1 marks a ray
/// that found no far side, 0 total internal reflection there.
fn trace(bvh: &SceneBvh, mesh: &TriMesh, p: Vec3, n: Vec3, to_light: Vec3, ior: f32, hair: f32) -> Transported {
    let missed = Transported { transmittance: -1.0, ..Transported::LOST };
    let Refraction::Transmitted(inside) = refract(-to_light, n, 1.0 / ior) else {
        return Transported::LOST;
    };
    // Möller–Trumbore is not watertight: a ray through a vertex or an edge of the far
    // side (a vertex's ray through a ball's centre meets the antipodal vertex, a tiled
    // slab's vertex the one below it) may slip between its triangles. Once more from a
    // few hairs inside and aside, off that vertex.
    let first = bvh.intersect(p, inside, hair, f32::INFINITY).map(|hit| (p, hit));
    let Some((p, hit)) = first.or_else(|| {
        let (t, b) = n.any_orthonormal_pair();
        let q = p + (t * 7.0 + b * 5.0 - n * 16.0) * hair;
        bvh.intersect(q, inside, hair, f32::INFINITY).map(|hit| (q, hit))
    }) else {
        return missed;
    };
    // The interpolated normal, unless facet and smooth normals disagree on the side.
    let smooth = mesh.shading_normal(hit.triangle as usize, hit.uv);
    let normal = if smooth.dot(inside) > 0.0 { smooth } else { hit.geometric_normal };
    match refract(inside, normal, ior) {
        Refraction::Transmitted(out) => Transported {
            exit: p + inside * hit.t,
            direction: out + to_light,
            // The far side's factor: the lookup multiplies in the entry's.
            transmittance: fresnel_transmittance(inside.dot(normal), ior),
        },
        Refraction::TotalInternalReflection => Transported::LOST,
    }
}
