//! Virtual planes and their illumination textures (§4.1–4.3): the CPU twin.
//!
//! - **Planes** (§4.2): `n` planes perpendicular to the flux-weighted mean direction of
//!   the light leaving the object, evenly spaced across the receivers' depth along it,
//!   each seen by an orthographic virtual camera spanning the receivers' bounds where
//!   the beams cross them; none depends on the viewpoint.
//! - **Textures** (eq. 3): each lit triangle of the object sweeps an illumination
//!   volume with the three rays the light transport table gives its vertices; where
//!   the volume crosses a plane it draws its triangle there with
//!   `I_Q = L_in cos θ F_t · S / (S₀ cos δ) · cos γ` — the triangle's flux over the beam's
//!   cross-section, times the cosine at the receiver surface the virtual camera sees
//!   through that texel (its normal map), added up over triangles.
//! - **Lookup** (§4.3): a receiver point takes its depth along the camera, the two
//!   planes around it and interpolates; a point the virtual camera does not see (behind
//!   another receiver surface) gets no caustic light: its shadow comes from the same
//!   depth map as the caustics.
//!
//! Past the paper: the flux is weighted per vertex (light, cosine and both Fresnel
//! factors, as the volumes do), and `S₀ cos δ` is kept above `S cos θ / MAX_MAGNIFICATION`
//! so that a volume crossing a plane at its focus stays finite.

use super::transport::LightTransportTable;
use crate::bvh::SceneBvh;
use crate::mesh::TriMesh;
use crate::scene::{Light, Receiver, Scene};
use glam::{Affine3A, Vec2, Vec3};

/// The largest `S / (S₀ cos δ)` a triangle is drawn with (as
/// `VolumeSettings::max_magnification` bounds the volumes).
pub const MAX_MAGNIFICATION: f32 = 1000.0;

/// How many planes, how fine their textures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IlluminationSettings {
    /// Virtual planes (the paper: 4).
    pub planes: u32,
    /// Texels along a side of each plane's texture (the paper: 512).
    pub texture_size: u32,
}

impl Default for IlluminationSettings {
    fn default() -> Self {
        Self { planes: 4, texture_size: 512 }
    }
}

/// One virtual plane: its depth along the camera axis and its illumination texture
/// (irradiance on the receiver surface seen through each texel, row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct IlluminationPlane {
    pub depth: f32,
    pub texture: Vec<f32>,
}

/// A light's illumination textures around the receivers.
#[derive(Clone, Debug, PartialEq)]
pub struct IlluminationTextures {
    /// The virtual camera: looks along `axis`; `u`, `v` span the texture plane.
    pub axis: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    /// The texture rectangle's lower corner and size in (u, v) metres.
    pub corner: Vec2,
    pub extent: Vec2,
    pub size: u32,
    pub planes: Vec<IlluminationPlane>,
    /// The nearest receiver along the axis through each texel: depth and normal.
    pub surface: Vec<Option<(f32, Vec3)>>,
    /// Flux the object's lit triangles send out (the table's transmitted light).
    pub flux_out: f64,
}

impl IlluminationTextures {
    /// The textures of `light` through `object` (`mesh` placed by `world_from_object`,
    /// `table` its light transport table) onto `receivers`. `None` when no light
    /// leaves the object towards the receivers.
    pub fn compute(
        table: &LightTransportTable,
        mesh: &TriMesh,
        world_from_object: &Affine3A,
        light: &Light,
        receivers: &[Receiver],
        settings: &IlluminationSettings,
    ) -> Option<Self> {
        let beams = lit_triangles(table, mesh, world_from_object, light);
        let axis = beams.iter().map(|b| b.flux * b.mean_direction()).sum::<Vec3>().try_normalize()?;
        let (u, v) = axis.any_orthonormal_pair();
        let scene = Scene { lights: Vec::new(), generators: Vec::new(), receivers: receivers.to_vec() };
        let corners = receivers.iter().flat_map(|r| {
            let (lo, hi) = r.mesh.bounds();
            (0..8).map(move |i| Vec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][i >> 2]))
        });
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for c in corners {
            let q = Vec3::new(c.dot(u), c.dot(v), c.dot(axis));
            (lo, hi) = (lo.min(q), hi.max(q));
        }
        if !lo.is_finite() || !hi.is_finite() {
            return None;
        }
        // Past the paper, whose planes span the whole target: only where the beams
        // cross the receivers' depth range, so that a wide floor does not spread the
        // texels thin over ground no caustic reaches.
        let (mut beam_lo, mut beam_hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for beam in &beams {
            for (exit, direction) in beam.exits.iter().zip(&beam.directions) {
                let along = direction.dot(axis);
                for depth in [lo.z, hi.z] {
                    let t = ((depth - exit.dot(axis)) / along).max(0.0);
                    let p = exit + direction * if along > 0.0 { t } else { 0.0 };
                    let q = Vec2::new(p.dot(u), p.dot(v));
                    (beam_lo, beam_hi) = (beam_lo.min(q), beam_hi.max(q));
                }
            }
        }
        let (lo, hi) = (lo.max(beam_lo.extend(lo.z)), hi.min(beam_hi.extend(hi.z)));
        if lo.x >= hi.x || lo.y >= hi.y {
            return None;
        }
        let size = settings.texture_size.max(1);
        let n = settings.planes.max(1);
        let depths: Vec<f32> =
            (0..n).map(|i| if n == 1 { 0.5 * (lo.z + hi.z) } else { lo.z + (hi.z - lo.z) * i as f32 / (n - 1) as f32 }).collect();
        let (corner, extent) = (lo.truncate(), (hi - lo).truncate().max(Vec2::splat(1e-6)));
        let texel = extent / size as f32;
        // The virtual camera's depth and normal map of the receivers.
        let bvh = SceneBvh::build(&scene);
        let start = lo.z - 1e-3 * (1.0 + (hi.z - lo.z));
        let surface: Vec<Option<(f32, Vec3)>> = (0..size * size)
            .map(|i| {
                let q = corner + (Vec2::new((i % size) as f32, (i / size) as f32) + 0.5) * texel;
                let origin = u * q.x + v * q.y + axis * start;
                bvh.intersect(origin, axis, 0.0, f32::INFINITY).map(|hit| {
                    let crate::bvh::Surface::Receiver(r) = hit.surface else { unreachable!("only receivers in this BVH") };
                    let normal = receivers[r as usize].mesh.shading_normal(hit.triangle as usize, hit.uv);
                    (start + hit.t, normal)
                })
            })
            .collect();
        let mut planes: Vec<IlluminationPlane> = depths.iter().map(|&depth| IlluminationPlane { depth, texture: vec![0.0; (size * size) as usize] }).collect();
        for beam in &beams {
            for plane in &mut planes {
                beam.draw(plane, (u, v, axis), (corner, texel, size), &surface);
            }
        }
        let flux_out = beams.iter().map(|b| b.flux as f64).sum();
        Some(Self { axis, u, v, corner, extent, size, planes, surface, flux_out })
    }

    /// Caustic irradiance at receiver point `p`: the two planes around its depth,
    /// interpolated (nearest texel); 0 where the virtual camera does not see `p`.
    pub fn irradiance_at(&self, p: Vec3) -> f32 {
        let q = (Vec2::new(p.dot(self.u), p.dot(self.v)) - self.corner) / self.extent * self.size as f32;
        if !(q.x >= 0.0 && q.y >= 0.0 && q.x < self.size as f32 && q.y < self.size as f32) {
            return 0.0;
        }
        let index = (q.y as u32 * self.size + q.x as u32) as usize;
        let z = p.dot(self.axis);
        let Some((depth, _)) = self.surface[index] else { return 0.0 };
        // Seen unless behind the nearest surface by more than the texel's slope allows.
        let texel = (self.extent / self.size as f32).max_element();
        if z > depth + 2.0 * texel + 1e-4 * (1.0 + depth.abs()) {
            return 0.0;
        }
        let at = |plane: &IlluminationPlane| plane.texture[index];
        let last = self.planes.len() - 1;
        let k = self.planes.partition_point(|plane| plane.depth <= z);
        match k {
            0 => at(&self.planes[0]),
            k if k > last => at(&self.planes[last]),
            k => {
                let (a, b) = (&self.planes[k - 1], &self.planes[k]);
                let f = ((z - a.depth) / (b.depth - a.depth).max(1e-12)).clamp(0.0, 1.0);
                at(a) + (at(b) - at(a)) * f
            }
        }
    }
}

/// One lit triangle's illumination volume: where its three rays leave the object,
/// which way, and the flux they carry.
struct Beam {
    exits: [Vec3; 3],
    directions: [Vec3; 3],
    flux: f32,
    /// `S cos θ`: the light's cross-section at the object, for the magnification cap.
    cross_section: f32,
}

impl Beam {
    fn mean_direction(&self) -> Vec3 {
        (self.directions[0] + self.directions[1] + self.directions[2]).normalize_or_zero()
    }

    /// Draws the volume's crossing with `plane` into its texture: `flux / (S₀ cos δ)`
    /// times `cos γ` at each texel's receiver, times the share of the texel covered.
    fn draw(&self, plane: &mut IlluminationPlane, (u, v, axis): (Vec3, Vec3, Vec3), (corner, texel, size): (Vec2, Vec2, u32), surface: &[Option<(f32, Vec3)>]) {
        let mut q = [Vec2::ZERO; 3];
        for (q, (exit, direction)) in q.iter_mut().zip(self.exits.iter().zip(&self.directions)) {
            let along = direction.dot(axis);
            let t = (plane.depth - exit.dot(axis)) / along;
            if !(along > 0.0 && t >= 0.0) {
                return; // the plane is behind where this ray leaves the object
            }
            let p = *exit + *direction * t;
            *q = (Vec2::new(p.dot(u), p.dot(v)) - corner) / texel;
        }
        let r = self.mean_direction();
        let texel_area = texel.x * texel.y;
        let area = 0.5 * (q[1] - q[0]).perp_dot(q[2] - q[0]);
        let s0_cos_delta = (area.abs() * texel_area * r.dot(axis)).max(self.cross_section / MAX_MAGNIFICATION);
        let intensity = self.flux / s0_cos_delta;
        let (lo, hi) = (q[0].min(q[1]).min(q[2]).floor().max(Vec2::ZERO), q[0].max(q[1]).max(q[2]).ceil().min(Vec2::splat(size as f32)));
        if area == 0.0 || lo.x >= hi.x || lo.y >= hi.y {
            return;
        }
        for y in lo.y as u32..hi.y as u32 {
            for x in lo.x as u32..hi.x as u32 {
                let covered = covered_area(q, Vec2::new(x as f32, y as f32));
                if covered <= 0.0 {
                    continue;
                }
                let index = (y * size + x) as usize;
                let cos_gamma = surface[index].map_or(1.0, |(_, n)| (-r.dot(n)).max(0.0));
                plane.texture[index] += intensity * cos_gamma * covered;
            }
        }
    }
}

/// The area of triangle `t` inside the unit square at `corner` (texel units): the
/// triangle clipped to the square's four sides (Sutherland–Hodgman), by the shoelace
/// formula. Drawing with it box-filters each volume's crossing into the texels it
/// covers, so a triangle smaller than a texel deposits its share instead of all or
/// nothing at the texel's centre.
fn covered_area(t: [Vec2; 3], corner: Vec2) -> f32 {
    let mut polygon: Vec<Vec2> = t.to_vec();
    let sides = [(0, corner.x, 1.0), (0, corner.x + 1.0, -1.0), (1, corner.y, 1.0), (1, corner.y + 1.0, -1.0)];
    for (axis, at, keep) in sides {
        let inside = |p: Vec2| (p[axis] - at) * keep >= 0.0;
        let mut clipped = Vec::with_capacity(polygon.len() + 2);
        for (i, &a) in polygon.iter().enumerate() {
            let b = polygon[(i + 1) % polygon.len()];
            if inside(a) {
                clipped.push(a);
            }
            if inside(a) != inside(b) {
                clipped.push(a + (b - a) * ((at - a[axis]) / (b[axis] - a[axis])));
            }
        }
        polygon = clipped;
        if polygon.len() < 3 {
            return 0.0;
        }
    }
    let twice: f32 = polygon.iter().zip(polygon.iter().cycle().skip(1)).map(|(a, b)| a.perp_dot(*b)).sum();
    0.5 * twice.abs()
}

/// The object's triangles facing `light` whose three vertices all pass light, as beams.
fn lit_triangles(table: &LightTransportTable, mesh: &TriMesh, world_from_object: &Affine3A, light: &Light) -> Vec<Beam> {
    let colour = light.color.element_sum() / 3.0;
    let vertex = |i: usize| {
        let p = world_from_object.transform_point3(mesh.positions()[i]);
        let n = world_from_object.transform_vector3(mesh.normals()[i]).normalize_or_zero();
        let (travel, irradiance) = light.incident(p);
        let out = table.lookup_world(i, -travel, world_from_object)?;
        let cos_theta = (-travel).dot(n).max(0.0);
        Some((out, irradiance * colour * cos_theta * out.transmittance, -travel))
    };
    mesh.triangles()
        .iter()
        .enumerate()
        .filter_map(|(t, tri)| {
            let corners = mesh.corners(t).map(|c| world_from_object.transform_point3(c));
            let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
            let area = 0.5 * normal.length();
            let [a, b, c] = tri.map(|i| vertex(i as usize));
            let [(a, fa, la), (b, fb, _), (c, fc, _)] = [a?, b?, c?];
            let cos = (normal.normalize_or_zero().dot(la)).max(0.0);
            (cos > 0.0).then(|| Beam {
                exits: [a.exit, b.exit, c.exit],
                directions: [a.direction, b.direction, c.direction],
                flux: area * (fa + fb + fc) / 3.0,
                cross_section: area * cos,
            })
        })
        .collect()
}
