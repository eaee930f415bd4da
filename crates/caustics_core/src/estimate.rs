//! Turning photon deposits into irradiance: binned on a rectangular receiver region,
//! or by kernel density estimation at arbitrary receiver points.

use crate::tracer::{PhotonHit, PhotonSink};
use glam::{DVec3, Vec3};
use std::collections::HashMap;

/// A rectangle on a receiver plane cut into `nu × nv` cells: the corner `origin` and
/// the full edge vectors `edge_u` (columns) and `edge_v` (rows).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridRegion {
    pub origin: Vec3,
    pub edge_u: Vec3,
    pub edge_v: Vec3,
    pub nu: usize,
    pub nv: usize,
}

impl GridRegion {
    /// A horizontal square `[x0, x0+size] × [z0, z0+size]` at height `y`, columns along
    /// +x and rows along +z (the layout of `shared/reference`).
    pub fn horizontal(x0: f32, z0: f32, y: f32, size: f32, cells: usize) -> Self {
        Self { origin: Vec3::new(x0, y, z0), edge_u: Vec3::X * size, edge_v: Vec3::Z * size, nu: cells, nv: cells }
    }

    /// Area of one cell.
    pub fn cell_area(&self) -> f32 {
        self.edge_u.cross(self.edge_v).length() / (self.nu * self.nv) as f32
    }

    /// Unit normal `edge_u × edge_v`.
    pub fn normal(&self) -> Vec3 {
        self.edge_u.cross(self.edge_v).normalize_or(Vec3::Y)
    }

    /// The world position of the centre of cell `(row, col)`.
    pub fn cell_center(&self, row: usize, col: usize) -> Vec3 {
        self.origin
            + self.edge_u * ((col as f32 + 0.5) / self.nu as f32)
            + self.edge_v * ((row as f32 + 0.5) / self.nv as f32)
    }

    /// Row-major cell index of a point on (within `tolerance` of) the plane.
    #[inline]
    pub fn cell_of(&self, p: Vec3, tolerance: f32) -> Option<usize> {
        let d = p - self.origin;
        if d.dot(self.normal()).abs() > tolerance {
            return None;
        }
        let a = d.dot(self.edge_u) / self.edge_u.length_squared();
        let b = d.dot(self.edge_v) / self.edge_v.length_squared();
        if !(0.0..1.0).contains(&a) || !(0.0..1.0).contains(&b) {
            return None;
        }
        let col = ((a * self.nu as f32) as usize).min(self.nu - 1);
        let row = ((b * self.nv as f32) as usize).min(self.nv - 1);
        Some(row * self.nu + col)
    }
}

/// Caustic irradiance binned on a [`GridRegion`]: deposited flux over cell area,
/// RGB, row-major. Flux accumulates in f64: a cell may receive 10⁶ photons.
#[derive(Clone, Debug, PartialEq)]
pub struct IrradianceGrid {
    pub region: GridRegion,
    flux: Vec<DVec3>,
    tolerance: f32,
}

impl IrradianceGrid {
    /// An empty grid. Photons count when they land within 10⁻⁴ of the region's size
    /// from its plane.
    pub fn new(region: GridRegion) -> Self {
        let tolerance = 1e-4 * region.edge_u.length().max(region.edge_v.length());
        Self { region, flux: vec![DVec3::ZERO; region.nu * region.nv], tolerance }
    }

    /// Irradiance per cell (flux / cell area), RGB, row-major.
    pub fn irradiance(&self) -> Vec<Vec3> {
        let inv = 1.0 / self.region.cell_area() as f64;
        self.flux.iter().map(|f| (*f * inv).as_vec3()).collect()
    }

    /// Irradiance of one channel-average (luminance-free mean of RGB) per cell.
    pub fn irradiance_mean(&self) -> Vec<f32> {
        self.irradiance().iter().map(|e| (e.x + e.y + e.z) / 3.0).collect()
    }

    /// Total flux deposited in the region.
    pub fn total_flux(&self) -> DVec3 {
        self.flux.iter().copied().sum()
    }
}

impl PhotonSink for IrradianceGrid {
    fn empty_like(&self) -> Self {
        Self::new(self.region)
    }
    #[inline]
    fn deposit(&mut self, hit: &PhotonHit) {
        if let Some(i) = self.region.cell_of(hit.position, self.tolerance) {
            self.flux[i] += hit.flux.as_dvec3();
        }
    }
    fn merge(&mut self, other: Self) {
        for (a, b) in self.flux.iter_mut().zip(other.flux) {
            *a += b;
        }
    }
}

/// Every deposit, in emission order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PhotonList(pub Vec<PhotonHit>);

impl PhotonSink for PhotonList {
    fn empty_like(&self) -> Self {
        Self::default()
    }
    fn deposit(&mut self, hit: &PhotonHit) {
        self.0.push(*hit);
    }
    fn merge(&mut self, mut other: Self) {
        self.0.append(&mut other.0);
    }
}

/// Photons hashed into a uniform grid of the kernel's radius, for irradiance at
/// arbitrary receiver points by kernel density estimation.
pub struct PhotonMap {
    photons: Vec<PhotonHit>,
    cells: HashMap<[i32; 3], Vec<u32>>,
    radius: f32,
}

impl PhotonMap {
    /// Indexes `photons` for queries with kernel radius `radius` (> 0).
    pub fn new(photons: Vec<PhotonHit>, radius: f32) -> Self {
        let radius = radius.max(1e-6);
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (i, p) in photons.iter().enumerate() {
            cells.entry(Self::key(p.position, radius)).or_default().push(i as u32);
        }
        Self { photons, cells, radius }
    }

    fn key(p: Vec3, r: f32) -> [i32; 3] {
        (p / r).floor().as_ivec3().to_array()
    }

    /// The kernel radius.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// Irradiance at `point` on a receiver with unit `normal`, with the 2-D
    /// Epanechnikov kernel `K(t) = 2/(π r²)·(1 − t²)` over the tangent-plane distance
    /// (Silverman 1986, §4.2). Photons on other surfaces (farther than r/4 from the
    /// tangent plane, or arriving from behind) do not count.
    pub fn irradiance_at(&self, point: Vec3, normal: Vec3) -> Vec3 {
        let r = self.radius;
        let r2 = r * r;
        let base = Self::key(point, r);
        let mut sum = Vec3::ZERO;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let Some(ids) = self.cells.get(&[base[0] + dx, base[1] + dy, base[2] + dz]) else {
                        continue;
                    };
                    for &i in ids {
                        let ph = &self.photons[i as usize];
                        let d = ph.position - point;
                        let off_plane = d.dot(normal);
                        if off_plane.abs() > 0.25 * r || ph.normal.dot(normal) <= 0.0 {
                            continue;
                        }
                        let t2 = (d.length_squared() - off_plane * off_plane) / r2;
                        if t2 < 1.0 {
                            sum += ph.flux * (1.0 - t2);
                        }
                    }
                }
            }
        }
        sum * (2.0 / (std::f32::consts::PI * r2))
    }
}
