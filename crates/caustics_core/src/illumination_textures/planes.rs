//! Virtual planes and their illumination textures (§4.1–4.3): the CPU twin.
//!
//! - **Planes** (§4.2): `n` planes perpendicular to the flux-weighted mean direction of
//!   the light leaving the object, evenly spaced across the depths of the receiver
//!   surfaces an orthographic virtual camera sees along it, where the beams cross
//!   them; none depends on the viewpoint.
//! - **Textures** (eq. 3): each lit triangle of the object sweeps an illumination
//!   volume with the three rays the light transport table gives its vertices; where
//!   the volume crosses a plane it draws its triangle there, box-filtered, with
//!   `I_Q = L_in cos θ F_t · S / (S₀ cos δ) · cos γ` — the triangle's flux over the
//!   beam's cross-section, times the cosine at the receiver surface the virtual camera
//!   sees through that texel (its normal map), added up over triangles. Beside it each
//!   texel keeps the light vector (the same without `cos γ`, times the direction).
//! - **Lookup** (§4.3): a receiver point takes its depth along the camera, the two
//!   planes around it and interpolates; it is in shadow where the light, followed
//!   back through the virtual camera's depth map, crosses a receiver surface — which
//!   for light along the axis is the paper's rule, that a point the camera does not
//!   see gets no caustic light.
//!
//! Past the paper, each measured on a glass ball over the Stanford bunny against the
//! tracer (docs/illumination-textures.md):
//! - the cosine is taken at the receiver point's own normal, from the light vector
//!   ([`Cosine::Receiver`]; the paper's per-texel `cos γ` stays as
//!   [`Cosine::VirtualCamera`]): one normal per texel misjudges every point of a steep
//!   surface in that texel's column;
//! - the shadow follows the light's own direction through a depth map of solid spans
//!   ([`SeenSurface::solid`]) instead of the virtual camera's axis, so that askew light
//!   passes beside an ear and under a body, and stops at a surface the camera sees
//!   elsewhere;
//! - the flux is weighted per vertex (light, cosine and both Fresnel factors, as the
//!   volumes do), and `S₀ cos δ` is kept above `S cos θ / MAX_MAGNIFICATION` so that a
//!   volume crossing a plane at its focus stays finite.

use super::transport::{LightTransportTable, Transported};
use crate::mesh::TriMesh;
use crate::scene::{Light, Receiver};
use crate::triangle_bvh::{InstancedBvh, NO_MESH};
use glam::{Affine3A, Vec2, Vec3, Vec4};
use rayon::prelude::*;

/// The largest `S / (S₀ cos δ)` a triangle is drawn with (as
/// `VolumeSettings::max_magnification` bounds the volumes).
pub const MAX_MAGNIFICATION: f32 = 1000.0;

/// How far behind a receiver surface, in texels (times the surface's slope for the
/// point's own), light may pass before the surface counts as in its way
/// ([`IlluminationTextures::shadowed`]).
pub const SHADOW_SLACK_TEXELS: f32 = 1.5;

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

/// One virtual plane: its depth along the camera axis and its illumination texture,
/// row-major. Per texel, `w` is eq. 3's irradiance on the receiver surface the virtual
/// camera sees through it; `xyz` is the light vector crossing the texel, the sum of
/// each volume's irradiance across its beam times its direction (no cosine), which
/// gives the irradiance on any normal `n` as `−xyz·n` and the light's way for shadows.
#[derive(Clone, Debug, PartialEq)]
pub struct IlluminationPlane {
    /// Depth along the virtual camera's `axis`.
    pub depth: f32,
    /// The illumination texture, `size²` texels, in units of `light_color`; empty
    /// before [`IlluminationTextures::draw`].
    pub texture: Vec<Vec4>,
}

/// A light's illumination textures around the receivers: the virtual camera, its
/// planes, the receivers it sees and the illumination volumes drawn onto the planes.
///
/// [`Self::frame`] sets everything up but the textures, which [`Self::draw`] fills:
/// the GPU pass draws the same volumes into the same frame (`caustics_bevy`'s
/// `illumination_textures`), and this is its twin. A game's frame is [`Self::placed`]
/// on the CPU and seen by the virtual camera on the GPU; [`Self::see`] is that pass's
/// twin.
#[derive(Clone, Debug, PartialEq)]
pub struct IlluminationTextures {
    /// The virtual camera: looks along `axis`; `u`, `v` span the texture plane.
    pub axis: Vec3,
    /// Unit axis along which texel `x` (the column) grows.
    pub u: Vec3,
    /// Unit axis along which texel `y` (the row) grows.
    pub v: Vec3,
    /// The texture rectangle's lower corner in (u, v) metres.
    pub corner: Vec2,
    /// The texture rectangle's size in (u, v) metres.
    pub extent: Vec2,
    /// Texels along a side of each plane's texture.
    pub size: u32,
    /// Where the virtual camera's rays start, in depth along `axis`: just before the
    /// receivers.
    pub start: f32,
    /// Depth along `axis` (after [`Self::see`]), and after [`Self::draw`] the texture
    /// (empty before).
    pub planes: Vec<IlluminationPlane>,
    /// What the virtual camera sees through each texel (after [`Self::see`]): the
    /// nearest receiver, its normal and the solid spans behind it.
    pub surface: Vec<Option<SeenSurface>>,
    /// One per lit triangle of the object, with the flux it carries in units of
    /// `light_color`'s irradiance.
    pub volumes: Vec<IlluminationVolume>,
    /// What the textures are multiplied by: the light's linear colour times the
    /// largest irradiance it casts on the object, so that the textures themselves
    /// stay within `[0, MAX_MAGNIFICATION]` (a half float holds them).
    pub light_color: Vec3,
    /// Flux the object's lit triangles send out (the table's transmitted light),
    /// the light's colour averaged.
    pub flux_out: f64,
}

impl IlluminationTextures {
    /// The frame of `light`'s textures through `object` (`mesh` placed by
    /// `world_from_object`, `table` its light transport table) onto `receivers`: the
    /// volumes, the virtual camera, its planes and what it sees of the receivers (§4.2),
    /// not drawn yet ([`Self::drawn`]). `None` when no light leaves the object towards
    /// the receivers.
    pub fn frame(
        table: &LightTransportTable,
        mesh: &TriMesh,
        world_from_object: &Affine3A,
        light: &Light,
        receivers: &[Receiver],
        settings: &IlluminationSettings,
    ) -> Option<Self> {
        let receivers = InstancedBvh::of_world_meshes(receivers.iter().map(|r| &r.mesh));
        let mut frame = Self::placed(table, mesh, world_from_object, light, &receivers, settings)?;
        frame.see(&receivers).then_some(frame)
    }

    /// The frame without what the virtual camera sees: the volumes, the camera and the
    /// texture rectangle, over the boxes of `receivers` (placed meshes); `settings`'
    /// planes, their depths left to [`Self::see`].
    pub fn placed(
        table: &LightTransportTable,
        mesh: &TriMesh,
        world_from_object: &Affine3A,
        light: &Light,
        receivers: &InstancedBvh,
        settings: &IlluminationSettings,
    ) -> Option<Self> {
        let (volumes, scale) = lit_triangles(table, mesh, world_from_object, light);
        let axis = volumes.iter().map(|b| b.flux * b.mean_direction()).sum::<Vec3>().try_normalize()?;
        let (u, v) = axis.any_orthonormal_pair();
        let corners = receivers
            .instance_bounds()
            .flat_map(|(lo, hi)| (0..8).map(move |i| Vec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][i >> 2])));
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
        for volume in &volumes {
            for (exit, direction) in volume.exits.iter().zip(&volume.directions) {
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
        if !(lo.x < hi.x && lo.y < hi.y) {
            return None;
        }
        let size = settings.texture_size.max(1);
        // Texels no finer than 10⁻⁵ of the coordinates' scale, so that a volume's
        // crossing, in texels, keeps its precision in f32 (a receiver smaller than a
        // texel then sits in one).
        let smallest = size as f32 * 1e-5 * (1.0 + lo.truncate().abs().max(hi.truncate().abs()).max_element());
        let grow = ((Vec2::splat(smallest) - (hi - lo).truncate()) * 0.5).max(Vec2::ZERO);
        let (corner, extent) = (lo.truncate() - grow, (hi - lo).truncate() + 2.0 * grow);
        let start = lo.z - 1e-3 * (1.0 + (hi.z - lo.z));
        let planes = (0..settings.planes.max(1)).map(|_| IlluminationPlane { depth: 0.0, texture: Vec::new() }).collect();
        let colour = light.color.element_sum() / 3.0;
        let flux_out = volumes.iter().map(|b| b.flux as f64).sum::<f64>() * (scale * colour) as f64;
        let light_color = light.color * scale;
        Some(Self { axis, u, v, corner, extent, size, start, planes, surface: Vec::new(), volumes, light_color, flux_out })
    }

    /// What the virtual camera sees of `receivers` (the frame's, as [`Self::placed`]
    /// took them) through each texel, and the planes' depths: evenly across the depths
    /// it sees (§4.2) — the receivers' surfaces where the beams cross them, not their
    /// whole bounds (a wide floor under a tilted axis would spread the planes over
    /// depths no caustic reaches). `false` where it sees none. The twin of `seen.wgsl`.
    pub fn see(&mut self, receivers: &InstancedBvh) -> bool {
        let (size, texel) = (self.size, self.extent / self.size as f32);
        let (u, v, axis, corner, start) = (self.u, self.v, self.axis, self.corner, self.start);
        self.surface = (0..size * size)
            .into_par_iter()
            .map(|i| {
                let q = corner + (Vec2::new((i % size) as f32, (i / size) as f32) + 0.5) * texel;
                SeenSurface::along(receivers, u * q.x + v * q.y + axis * start, axis)
            })
            .collect();
        let (near, far) = self.surface.iter().flatten().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), s| (a.min(s.depth), b.max(s.depth)));
        let n = self.planes.len();
        for (i, plane) in self.planes.iter_mut().enumerate() {
            plane.depth = plane_depth(near, far, i as u32, n as u32);
        }
        near <= far
    }

    /// The frame with its textures drawn.
    pub fn drawn(mut self) -> Self {
        self.draw();
        self
    }

    /// Draws every volume into every plane's texture (eq. 3, accumulated): the CPU twin
    /// of the GPU pass.
    pub fn draw(&mut self) {
        let texel = self.extent / self.size as f32;
        let texels = (self.size * self.size) as usize;
        let frame = (self.u, self.v, self.axis);
        let (corner, size, surface, volumes) = (self.corner, self.size, &self.surface, &self.volumes);
        self.planes.par_iter_mut().for_each(|plane| {
            plane.texture = vec![Vec4::ZERO; texels];
            for volume in volumes {
                volume.draw(plane, frame, (corner, texel, size), surface);
            }
        });
    }

    /// Where `p` falls on the textures, in texels (the texture spans `[0, size)²`).
    pub fn texel_coords(&self, p: Vec3) -> Vec2 {
        (Vec2::new(p.dot(self.u), p.dot(self.v)) - self.corner) / self.extent * self.size as f32
    }

    /// The texel at texel coordinates `q`, if on the textures.
    fn index(&self, q: Vec2) -> Option<usize> {
        let n = self.size as f32;
        (q.x >= 0.0 && q.y >= 0.0 && q.x < n && q.y < n).then(|| (q.y as u32 * self.size + q.x as u32) as usize)
    }

    /// Caustic irradiance (linear RGB) at receiver point `p` of unit normal `n` (§4.3):
    /// the two planes around its depth, interpolated (nearest texel), the cosine taken
    /// as `cosine` says, and nothing where [`Self::shadowed`]. Needs [`Self::draw`].
    pub fn irradiance_at(&self, p: Vec3, n: Vec3, cosine: Cosine) -> Vec3 {
        let q = self.texel_coords(p);
        let Some(index) = self.index(q) else { return Vec3::ZERO };
        let z = p.dot(self.axis);
        let light = self.interpolated(index, z);
        let e = match cosine {
            Cosine::Receiver => (-light.truncate().dot(n)).max(0.0),
            Cosine::VirtualCamera => light.w,
        };
        if e.is_nan() || e <= 0.0 || self.shadowed(q, z, light.truncate(), n) {
            return Vec3::ZERO;
        }
        self.light_color * e
    }

    /// Whether light arriving along `r` at depth `z` over texel point `q`, on a surface
    /// of normal `n`, is stopped by a receiver surface on its way from the nearest
    /// plane. The light is followed back through the virtual camera's depth map, texel
    /// by texel: it is stopped in a texel whose surface it crosses there, from behind
    /// (deeper than the surface plus a slack of [`SHADOW_SLACK_TEXELS`] times `n`'s
    /// slope in its own texel) to in front of where the solid behind it ends, for each
    /// solid span the texel holds. Light along the axis never leaves its texel, and this
    /// is the paper's rule (a point the virtual camera does not see is in shadow);
    /// askew light can pass under an ear or an overhang, and be stopped by a surface
    /// the camera sees elsewhere.
    pub fn shadowed(&self, q: Vec2, z: f32, r: Vec3, n: Vec3) -> bool {
        let along = r.dot(self.axis);
        if along.is_nan() || along <= 0.0 {
            return false;
        }
        let texel = self.extent / self.size as f32;
        let unit = texel.max_element();
        // How far behind a surface a point still counts as on it: the depth its slope
        // spans across the slack (at most 10, 84° off the axis).
        let slack = |n: Vec3| {
            let cos = n.dot(self.axis).abs().max(0.1);
            SHADOW_SLACK_TEXELS * unit * (1.0 + (1.0 - cos * cos).sqrt() / cos) + 1e-4 * (1.0 + z.abs())
        };
        // Texels crossed per unit of depth climbed back towards the light.
        let across = Vec2::new(-r.dot(self.u), -r.dot(self.v)) / (along * texel);
        let to_top = z - self.planes[0].depth;
        let mut cell = q.floor();
        let mut climbed = 0.0f32;
        // Each step enters a neighbouring texel: at most two sides' worth of them.
        for _ in 0..2 * self.size + 2 {
            let Some(index) = self.index(cell) else { return false };
            let exit = [0, 1].map(|k| {
                if across[k] > 0.0 {
                    (cell[k] + 1.0 - q[k]) / across[k]
                } else if across[k] < 0.0 {
                    (cell[k] - q[k]) / across[k]
                } else {
                    f32::INFINITY
                }
            });
            let leave = exit[0].min(exit[1]).min(to_top);
            // The point's own texel: whether it is the surface seen there, by its own
            // slope; others: whether the light crosses a solid span, with the flat slack.
            if let Some(seen) = self.surface[index] {
                let slack = slack(if climbed == 0.0 { n } else { self.axis });
                let (deep, shallow) = (z - climbed, z - leave);
                if seen.solid.iter().any(|&(enter, out)| deep > enter + slack && shallow <= out + slack) {
                    return true;
                }
            }
            if leave >= to_top {
                return false;
            }
            let k = if exit[0] <= exit[1] { 0 } else { 1 };
            cell[k] += across[k].signum();
            climbed = leave;
        }
        false
    }

    /// The textures at texel `index`, interpolated to depth `z` (clamped to the first
    /// and last plane), in units of `light_color`.
    fn interpolated(&self, index: usize, z: f32) -> Vec4 {
        let at = |plane: &IlluminationPlane| plane.texture.get(index).copied().unwrap_or(Vec4::ZERO);
        let last = self.planes.len() - 1;
        match self.planes.partition_point(|plane| plane.depth <= z) {
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

/// The most solid spans a texel's depth map keeps.
pub const SOLID_SPANS: usize = 4;

/// What the virtual camera sees through a texel: the nearest receiver surface, its
/// shading normal, and where the ray through the texel centre runs inside receivers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeenSurface {
    /// Depth of the nearest receiver surface along the camera's `axis`.
    pub depth: f32,
    /// Its shading normal (world space).
    pub normal: Vec3,
    /// Depth spans `(in, out)` inside receivers, nearest first: from a face towards the
    /// camera to the next face away from it (an ear is thin, a body thick, and light
    /// may pass between them; [`IlluminationTextures::shadowed`]). `out` is infinite
    /// behind a surface with nothing facing away behind it (a floor); unused spans are
    /// empty (`in` infinite). The first starts at `depth`.
    pub solid: [(f32, f32); SOLID_SPANS],
}

impl SeenSurface {
    /// The nearest receiver along `axis` from `origin`.
    fn along(receivers: &InstancedBvh, origin: Vec3, axis: Vec3) -> Option<Self> {
        let depth0 = origin.dot(axis);
        let mut solid = [(f32::INFINITY, f32::INFINITY); SOLID_SPANS];
        let mut first: Option<(f32, Vec3)> = None;
        let (mut span, mut inside, mut t) = (0, false, 0.0f32);
        for _ in 0..4 * SOLID_SPANS {
            let Some(hit) = receivers.intersect(origin, axis, t, f32::INFINITY, NO_MESH) else { break };
            let towards = hit.geometric_normal.dot(axis) < 0.0;
            first.get_or_insert((hit.t, hit.normal));
            match (inside, towards) {
                (false, _) => {
                    solid[span].0 = depth0 + hit.t;
                    inside = true;
                    if !towards {
                        solid[span].1 = depth0 + hit.t;
                        (span, inside) = (span + 1, false);
                    }
                }
                (true, false) => {
                    solid[span].1 = depth0 + hit.t;
                    (span, inside) = (span + 1, false);
                }
                (true, true) => {}
            }
            if span == SOLID_SPANS {
                break;
            }
            t = hit.t * (1.0 + 1e-5) + 1e-5;
        }
        let (t, normal) = first?;
        Some(Self { depth: depth0 + t, normal, solid })
    }
}

/// Plane `i` of `n`'s depth, evenly from `near` to `far` (one plane: halfway).
fn plane_depth(near: f32, far: f32, i: u32, n: u32) -> f32 {
    if n == 1 { 0.5 * (near + far) } else { near + (far - near) * i as f32 / (n - 1) as f32 }
}

/// Which cosine turns the light crossing a texel into irradiance on a receiver.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Cosine {
    /// At the receiver point's own normal (the view's normal on the GPU): the textures'
    /// light vector `xyz` dotted with it. Past the paper; the default, because one
    /// normal per texel misjudges every receiver point of a steep surface in that
    /// texel's column.
    #[default]
    Receiver,
    /// The paper's `cos γ` (eq. 3), per texel, at the normal the virtual camera sees
    /// there: the textures' `w`.
    VirtualCamera,
}

/// One lit triangle's illumination volume (§4.1, after Nishita et al. [14]): where
/// its three vertex rays leave the object, which way, and the flux they carry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IlluminationVolume {
    /// Where the triangle's three vertex rays leave the object (world space).
    pub exits: [Vec3; 3],
    /// The unit direction each of those rays leaves in.
    pub directions: [Vec3; 3],
    /// The triangle's area times its vertices' mean of light, cos θ and both Fresnel
    /// factors, in units of the textures' `light_color`.
    pub flux: f32,
    /// `S cos θ`: the light's cross-section at the object, for the magnification cap.
    pub cross_section: f32,
}

impl IlluminationVolume {
    /// The volume's mean direction, `r` of eq. 3's `cos γ = −r·n`.
    pub fn mean_direction(&self) -> Vec3 {
        (self.directions[0] + self.directions[1] + self.directions[2]).normalize_or_zero()
    }

    /// Draws the volume's crossing with `plane` into its texture: `flux / (S₀ cos δ)`
    /// times `cos γ` at each texel's receiver, times the share of the texel covered.
    fn draw(&self, plane: &mut IlluminationPlane, (u, v, axis): (Vec3, Vec3, Vec3), (corner, texel, size): (Vec2, Vec2, u32), surface: &[Option<SeenSurface>]) {
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
                let cos_gamma = surface[index].map_or(1.0, |s| (-r.dot(s.normal)).max(0.0));
                let e = intensity * cos_gamma * covered;
                plane.texture[index] += (r * intensity * covered).extend(e);
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
    let polygon = crate::estimate::clip_to_square(&t, corner);
    let twice: f32 = polygon.iter().zip(polygon.iter().cycle().skip(1)).map(|(a, b)| a.perp_dot(*b)).sum();
    0.5 * twice.abs()
}

/// The object's triangles facing `light` whose three vertices all pass light, as
/// illumination volumes, with the irradiance their flux is in units of: the largest
/// the light casts on a lit vertex.
fn lit_triangles(table: &LightTransportTable, mesh: &TriMesh, world_from_object: &Affine3A, light: &Light) -> (Vec<IlluminationVolume>, f32) {
    let vertices: Vec<Option<(Transported, f32, Vec3)>> = (0..mesh.positions().len())
        .map(|i| {
            let p = world_from_object.transform_point3(mesh.positions()[i]);
            let n = world_from_object.transform_vector3(mesh.normals()[i]).normalize_or_zero();
            let (travel, irradiance) = light.incident(p);
            let out = table.lookup_world(i, -travel, world_from_object)?;
            let cos_theta = (-travel).dot(n).max(0.0);
            (irradiance.is_finite() && irradiance > 0.0).then_some((out, irradiance * cos_theta * out.transmittance, -travel))
        })
        .collect();
    let scale = vertices.iter().flatten().map(|(_, e, _)| *e).fold(0.0f32, f32::max);
    if scale <= 0.0 {
        return (Vec::new(), 1.0);
    }
    let volumes = mesh
        .triangles()
        .iter()
        .enumerate()
        .filter_map(|(t, tri)| {
            let corners = mesh.corners(t).map(|c| world_from_object.transform_point3(c));
            let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
            let area = 0.5 * normal.length();
            let [a, b, c] = tri.map(|i| vertices[i as usize]);
            let [(a, fa, la), (b, fb, _), (c, fc, _)] = [a?, b?, c?];
            let cos = (normal.normalize_or_zero().dot(la)).max(0.0);
            (cos > 0.0).then(|| IlluminationVolume {
                exits: [a.exit, b.exit, c.exit],
                directions: [a.direction, b.direction, c.direction],
                flux: area * (fa + fb + fc) / (3.0 * scale),
                cross_section: area * cos,
            })
        })
        .collect();
    (volumes, scale)
}
