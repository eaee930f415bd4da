//! Turning photon deposits into irradiance: binned on a rectangular receiver region,
//! or by kernel density estimation at arbitrary receiver points; and photon paths
//! into the radiance a participating medium scatters towards the eye.

use crate::optics::henyey_greenstein;
use crate::tracer::{PhotonHit, PhotonSegment, PhotonSink};
use crate::volumes::MediumBox;
use glam::{DVec3, Vec3};
use std::collections::HashMap;

/// A rectangle on a receiver plane cut into `nu × nv` cells: the corner `origin` and
/// the full edge vectors `edge_u` (columns) and `edge_v` (rows).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridRegion {
    /// Corner of cell `(0, 0)`.
    pub origin: Vec3,
    /// Full edge that the `nu` columns divide.
    pub edge_u: Vec3,
    /// Full edge that the `nv` rows divide.
    pub edge_v: Vec3,
    /// Number of columns along `edge_u`.
    pub nu: usize,
    /// Number of rows along `edge_v`.
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
        self.origin + self.edge_u * ((col as f32 + 0.5) / self.nu as f32) + self.edge_v * ((row as f32 + 0.5) / self.nv as f32)
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

/// Where to read a technique so that it measures what [`IrradianceGrid::projected`]
/// does: points on the receivers' surfaces with their normal and weight, binned into
/// the cell they lie over. A cell's value is the sum of irradiance × weight over its
/// points: the flux the technique lands there per area of the cell, as the photons'
/// deposits give it. Each triangle is cut exactly at the cells' sides (its shadow on
/// the region's plane clipped to each cell it touches, the pieces lifted back onto
/// it), and each piece into about `per_cell` points a cell; a triangle within 3° of
/// standing on edge to the plane is cut into a barycentric grid instead.
pub fn surface_samples(region: &GridRegion, receivers: &[crate::scene::Receiver], per_cell: usize) -> Vec<Vec<(Vec3, Vec3, f32)>> {
    let (nu, nv) = (region.nu as f32, region.nv as f32);
    let (eu, ev) = (region.edge_u / region.edge_u.length_squared() * nu, region.edge_v / region.edge_v.length_squared() * nv);
    let to_cells = |p: Vec3| glam::Vec2::new((p - region.origin).dot(eu), (p - region.origin).dot(ev));
    let cell_area = region.cell_area();
    let mut cells = vec![Vec::new(); region.nu * region.nv];
    let mut push = |p: Vec3, normal: Vec3, weight: f32| {
        if let Some(cell) = region.cell_of(p, f32::INFINITY) {
            cells[cell].push((p, normal, weight));
        }
    };
    for receiver in receivers {
        for t in 0..receiver.mesh.triangles().len() {
            let [a, b, c] = receiver.mesh.corners(t);
            let cross = (b - a).cross(c - a);
            let (area, normal) = (0.5 * cross.length(), cross.normalize_or_zero());
            if area.is_nan() || area <= 0.0 {
                continue;
            }
            let facing = normal.dot(region.normal()).abs();
            let q = [a, b, c].map(to_cells);
            let projected = 0.5 * (q[1] - q[0]).perp_dot(q[2] - q[0]);
            if facing < 0.05 || projected == 0.0 {
                let m = ((area / cell_area * per_cell as f32).sqrt().ceil() as usize).clamp(1, 4096);
                for (p, share) in barycentric_grid([a, b, c], m) {
                    push(p, normal, share * area / cell_area);
                }
                continue;
            }
            // A point of the cell plane back onto the triangle, by its barycentrics.
            let lift = |x: glam::Vec2| {
                let twice = 2.0 * projected;
                a + (b - a) * ((x - q[0]).perp_dot(q[2] - q[0]) / twice) + (c - a) * ((q[1] - q[0]).perp_dot(x - q[0]) / twice)
            };
            let (lo, hi) = (q[0].min(q[1]).min(q[2]).floor().max(glam::Vec2::ZERO), q[0].max(q[1]).max(q[2]).ceil().min(glam::Vec2::new(nu, nv)));
            for y in lo.y as i32..hi.y as i32 {
                for x in lo.x as i32..hi.x as i32 {
                    let polygon = clip_to_square(&q, glam::Vec2::new(x as f32, y as f32));
                    for k in 1..polygon.len().saturating_sub(1) {
                        let piece = [polygon[0], polygon[k], polygon[k + 1]];
                        let fraction = 0.5 * (piece[1] - piece[0]).perp_dot(piece[2] - piece[0]).abs();
                        let m = ((fraction * per_cell as f32).sqrt().ceil() as usize).clamp(1, 64);
                        for (centre, share) in barycentric_grid(piece.map(|p| p.extend(0.0)), m) {
                            push(lift(centre.truncate()), normal, share * fraction / facing);
                        }
                    }
                }
            }
        }
    }
    cells
}

/// The centres of the `m²` triangles of a triangle's barycentric grid, with the share
/// of its area each stands for.
fn barycentric_grid([a, b, c]: [Vec3; 3], m: usize) -> impl Iterator<Item = (Vec3, f32)> {
    let share = 1.0 / (m * m) as f32;
    let at = move |u: f32, v: f32| a + (b - a) * (u / m as f32) + (c - a) * (v / m as f32);
    (0..m).flat_map(move |i| (0..m - i).map(move |j| (i as f32, j as f32))).flat_map(move |(i, j)| {
        let inverted = ((i + j) as usize + 1 < m).then(|| at(i + 2.0 / 3.0, j + 2.0 / 3.0));
        std::iter::once(at(i + 1.0 / 3.0, j + 1.0 / 3.0)).chain(inverted).map(move |p| (p, share))
    })
}

/// Triangle `t` clipped to the unit square at `corner` (Sutherland–Hodgman); empty
/// when they do not overlap.
pub(crate) fn clip_to_square(t: &[glam::Vec2; 3], corner: glam::Vec2) -> Vec<glam::Vec2> {
    let mut polygon: Vec<glam::Vec2> = t.to_vec();
    for (axis, at, keep) in [(0, corner.x, 1.0), (0, corner.x + 1.0, -1.0), (1, corner.y, 1.0), (1, corner.y + 1.0, -1.0)] {
        let inside = |p: glam::Vec2| (p[axis] - at) * keep >= 0.0;
        let mut clipped = Vec::with_capacity(polygon.len() + 2);
        for (i, &p) in polygon.iter().enumerate() {
            let n = polygon[(i + 1) % polygon.len()];
            if inside(p) {
                clipped.push(p);
            }
            if inside(p) != inside(n) {
                clipped.push(p + (n - p) * ((at - p[axis]) / (n[axis] - p[axis])));
            }
        }
        polygon = clipped;
        if polygon.len() < 3 {
            return Vec::new();
        }
    }
    polygon
}

/// Caustic irradiance binned on a [`GridRegion`]: deposited flux over cell area,
/// RGB, row-major. Flux accumulates in f64: a cell may receive 10⁶ photons.
#[derive(Clone, Debug, PartialEq)]
pub struct IrradianceGrid {
    /// The region the photons are binned on.
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

    /// A grid over curved receivers: every photon counts in the cell it lands over,
    /// at any distance from the plane, so a cell holds the flux landed on the surfaces
    /// above (and below) it per area of the cell. [`surface_samples`] gives the points
    /// a technique is read at for the same quantity.
    pub fn projected(region: GridRegion) -> Self {
        Self { tolerance: f32::INFINITY, ..Self::new(region) }
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
        Self { flux: vec![DVec3::ZERO; self.flux.len()], ..*self }
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

/// A caustic photon path's segment inside a medium: from where it enters (or leaves
/// its generator inside) to where it leaves or meets a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonBeam {
    /// Its start, inside the medium.
    pub start: Vec3,
    /// Unit direction of travel.
    pub direction: Vec3,
    /// Length inside the medium.
    pub length: f32,
    /// RGB flux at `start`.
    pub flux: Vec3,
}

/// The caustic photons' paths through one medium, as beams: the reference for the
/// light the medium scatters out of caustic beams (the shafts), independent of the
/// caustic volumes. Each beam is attenuated from where it enters the medium or
/// leaves its generator there, as the volumes attenuate theirs from the generator
/// (Ernst et al. 2005 §3.5): light that crossed the medium before a specular bounce
/// inside it is not dimmed for that stretch, and a generator inside the medium is
/// taken as a surface, not a body of another material.
#[derive(Clone, Debug, PartialEq)]
pub struct PhotonBeams {
    /// The medium the beams cross.
    pub medium: MediumBox,
    /// The beams, in emission order.
    pub beams: Vec<PhotonBeam>,
}

impl PhotonBeams {
    /// No beams yet, in `medium`.
    pub fn new(medium: MediumBox) -> Self {
        Self { medium, beams: Vec::new() }
    }

    /// Radiance scattered towards the eye along the ray from `eye` to `end` by the
    /// beams, with the beam × ray estimator of Jarosz et al. 2011 (§5.2, "beam × beam
    /// 1D"): a beam of flux Φ that passes the ray at distance `u` ≤ `radius`, at angle
    /// θ, adds `σₛ p(θ) Φ e^{−σₜ(dₑ + d_b)} K(u) / sin θ`, with `K = 1/(2·radius)` the
    /// box kernel across the two lines and `dₑ`, `d_b` the medium paths of the eye
    /// ray and of the beam to their closest points. Beams within a degree of parallel
    /// to the ray are skipped (their `1/sin θ` has no bounded estimate).
    pub fn in_scattered_radiance(&self, eye: Vec3, end: Vec3, radius: f32) -> Vec3 {
        let length = (end - eye).length();
        if !(length > 0.0 && length.is_finite() && radius > 0.0) {
            return Vec3::ZERO;
        }
        let d = (end - eye) / length;
        let Some((enter, exit)) = self.medium.clip(eye, d, length) else {
            return Vec3::ZERO;
        };
        let c = self.medium.coefficients;
        let sigma_t = c.extinction();
        let mut sum = Vec3::ZERO;
        for beam in &self.beams {
            let w = beam.direction;
            let n = d.cross(w);
            let sin2 = n.length_squared();
            if sin2 < 3e-4 {
                continue;
            }
            let to_beam = beam.start - eye;
            if to_beam.dot(n).powi(2) > radius * radius * sin2 {
                continue;
            }
            let t = to_beam.cross(w).dot(n) / sin2;
            let s = to_beam.cross(d).dot(n) / sin2;
            if t < enter || t > exit || s < 0.0 || s > beam.length {
                continue;
            }
            let phase = henyey_greenstein(w.dot(-d), c.asymmetry);
            sum += beam.flux * (-sigma_t * (t - enter + s)).exp() * (phase / sin2.sqrt());
        }
        sum * (c.scattering / (2.0 * radius))
    }
}

impl PhotonSink for PhotonBeams {
    fn empty_like(&self) -> Self {
        Self::new(self.medium)
    }
    fn deposit(&mut self, _hit: &PhotonHit) {}
    fn segment(&mut self, segment: &PhotonSegment) {
        let length = segment.length.min(1e6);
        if let Some((t0, t1)) = self.medium.clip(segment.origin, segment.direction, length) {
            let start = segment.origin + t0 * segment.direction;
            self.beams.push(PhotonBeam { start, direction: segment.direction, length: t1 - t0, flux: segment.flux });
        }
    }
    fn merge(&mut self, mut other: Self) {
        self.beams.append(&mut other.beams);
    }
}
