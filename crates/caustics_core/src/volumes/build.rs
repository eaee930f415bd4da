//! Building caustic volumes from generator meshes and lights (§3, §3.4).

use super::{BoundingShape, CausticVolume, NO_HIT_PLANE, OCCLUSION_SLACK, SurfaceSlab, VolumeSettings};
use crate::bvh::SceneBvh;
use crate::mesh::TriMesh;
use crate::optics::{RGB_WAVELENGTHS_UM, fresnel_reflectance, reflect, refract};
use crate::params::SpecularInteraction;
use crate::scene::{Light, Scene, Sides};
use glam::{DVec3, Vec3, Vec4};
use rayon::prelude::*;

/// The triangles around each vertex of a mesh (compressed rows), for the fans of §3.4.
/// Depends on the topology only: an animated generator keeps its fans.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VertexFans {
    start: Vec<u32>,
    triangles: Vec<u32>,
}

impl VertexFans {
    /// The fans around every vertex of `mesh`.
    pub fn new(mesh: &TriMesh) -> Self {
        let vertices = mesh.positions().len();
        let mut count = vec![0u32; vertices + 1];
        for tri in mesh.triangles() {
            for &v in tri {
                count[v as usize + 1] += 1;
            }
        }
        for i in 0..vertices {
            count[i + 1] += count[i];
        }
        let mut next = count.clone();
        let mut triangles = vec![0u32; count[vertices] as usize];
        for (t, tri) in mesh.triangles().iter().enumerate() {
            for &v in tri {
                triangles[next[v as usize] as usize] = t as u32;
                next[v as usize] += 1;
            }
        }
        Self { start: count, triangles }
    }

    /// Whether these fans were built for a mesh with this many vertices and triangles.
    pub fn fits(&self, mesh: &TriMesh) -> bool {
        self.start.len() == mesh.positions().len() + 1 && self.triangles.len() == 3 * mesh.triangles().len()
    }

    fn around(&self, vertex: u32) -> &[u32] {
        &self.triangles[self.start[vertex as usize] as usize..self.start[vertex as usize + 1] as usize]
    }

    /// Where each vertex's fan starts in [`Self::triangles`], and one past the last.
    pub fn starts(&self) -> &[u32] {
        &self.start
    }

    /// The triangles around every vertex, vertex after vertex.
    pub fn triangles(&self) -> &[u32] {
        &self.triangles
    }

    /// Which sides of triangle `t` it owns: side i (opposite vertex i) is shared with
    /// at most one neighbour, and the triangle with the lower index owns the points
    /// exactly on it; an open side is owned.
    pub fn owned_edges(&self, mesh: &TriMesh, t: usize) -> [bool; 3] {
        let tri = mesh.triangles()[t];
        std::array::from_fn(|i| {
            let (a, b) = (tri[(i + 1) % 3], tri[(i + 2) % 3]);
            let neighbour = self.around(a).iter().find(|&&f| f as usize != t && mesh.triangles()[f as usize].contains(&b));
            neighbour.is_none_or(|&f| t < f as usize)
        })
    }
}

/// Counts of what a build kept and dropped, and the flux on each side.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BuildStats {
    /// Volumes kept.
    pub volumes: usize,
    /// Triangles facing away from the light, or outside a spot light's cone.
    pub unlit: usize,
    /// Triangles that another surface hides from the light at all three vertices.
    pub shadowed: usize,
    /// Triangles with a vertex ray lost to total internal reflection.
    pub total_internal_reflection: usize,
    /// Triangles with a vertex ray too close to the triangle's plane (grazing light).
    pub grazing: usize,
    /// Zero-area triangles, or volumes with no receiver ahead of them.
    pub degenerate: usize,
    /// Kept volumes whose rays land on one surface: the surface pass draws their slab
    /// alone ([`super::SurfaceSlab`]).
    pub surface_slabs: usize,
    /// Kept volumes whose rays all meet nothing: they light no surface, only a medium.
    pub escaping: usize,
    /// Flux of the kept volumes.
    pub flux: DVec3,
    /// Flux of lit triangles that were dropped (TIR, grazing, degenerate).
    pub dropped_flux: DVec3,
}

impl std::ops::Add for BuildStats {
    type Output = Self;

    /// The sum of two builds' counts and fluxes.
    fn add(mut self, o: Self) -> Self {
        self.volumes += o.volumes;
        self.unlit += o.unlit;
        self.shadowed += o.shadowed;
        self.total_internal_reflection += o.total_internal_reflection;
        self.grazing += o.grazing;
        self.degenerate += o.degenerate;
        self.surface_slabs += o.surface_slabs;
        self.escaping += o.escaping;
        self.flux += o.flux;
        self.dropped_flux += o.dropped_flux;
        self
    }
}

/// Smallest cosine between a shared slicing axis and a triangle's rays and normal.
const SHARED_AXIS_MIN_COS: f32 = 0.25;

/// Where a vertex ray first meets a surface of `occluders`: the point and the
/// surface's geometric normal.
fn first_hit(occluders: &SceneBvh, p: Vec3, ray: &VertexRay) -> Option<(Vec3, Vec3)> {
    let VertexRay::Ray { direction, .. } = *ray else {
        return None;
    };
    let hair = 1e-5 * (1.0 + p.abs().max_element());
    occluders.intersect(p, direction, hair, f32::INFINITY).map(|hit| (p + hit.t * direction, hit.geometric_normal))
}

/// A vertex ray: unit direction and the fraction of flux it carries (Fresnel).
#[derive(Clone, Copy)]
enum VertexRay {
    Ray { direction: Vec3, fresnel: f32, irradiance: f32, incident: Vec3 },
    TotalInternalReflection { irradiance: f32, incident: Vec3 },
}

impl VertexRay {
    /// The same ray carrying no light: its vertex is in shadow.
    fn shadowed(self) -> Self {
        match self {
            VertexRay::Ray { direction, fresnel, incident, .. } => VertexRay::Ray { direction, fresnel, irradiance: 0.0, incident },
            VertexRay::TotalInternalReflection { incident, .. } => VertexRay::TotalInternalReflection { irradiance: 0.0, incident },
        }
    }
}

fn vertex_ray(light: &Light, interaction: &SpecularInteraction, ior: Option<f32>, p: Vec3, n: Vec3) -> VertexRay {
    let (l, irradiance) = light.incident(p);
    match interaction {
        SpecularInteraction::Reflect => VertexRay::Ray { direction: reflect(l, n).normalize_or(l), fresnel: 1.0, irradiance, incident: l },
        SpecularInteraction::Refract { .. } => {
            let ior = ior.unwrap_or(1.0);
            // The inside (index `ior`) is opposite the normal (see SpecularInteraction).
            let eta = if l.dot(n) < 0.0 { 1.0 / ior } else { ior };
            match refract(l, n, eta).direction() {
                Some(direction) => VertexRay::Ray { direction, fresnel: 1.0 - fresnel_reflectance(l.dot(n), eta), irradiance, incident: l },
                None => VertexRay::TotalInternalReflection { irradiance, incident: l },
            }
        }
    }
}

/// The local frame of a triangle: origin, axes (x along the first edge, y the normal
/// on the side the rays leave to, z completing it so that the triangle's own area
/// coefficient `a` is positive).
struct Frame {
    origin: Vec3,
    axes: [Vec3; 3],
}

impl Frame {
    fn local(&self, p: Vec3) -> Vec3 {
        let d = p - self.origin;
        Vec3::new(d.dot(self.axes[0]), d.dot(self.axes[1]), d.dot(self.axes[2]))
    }

    fn local_dir(&self, d: Vec3) -> Vec3 {
        Vec3::new(d.dot(self.axes[0]), d.dot(self.axes[1]), d.dot(self.axes[2]))
    }

    fn world(&self, p: Vec3) -> Vec3 {
        self.origin + self.world_dir(p)
    }

    fn world_dir(&self, d: Vec3) -> Vec3 {
        self.axes[0] * d.x + self.axes[1] * d.y + self.axes[2] * d.z
    }

    /// The plane tangent to a surface at a vertex ray's first hit (point, normal), in
    /// this frame and facing the local ray `r`, with the slack of [`OCCLUSION_SLACK`]
    /// (at least 10⁻⁴ of the volume's depth) in its offset.
    fn hit_plane(&self, (point, normal): (Vec3, Vec3), r: Vec3, depth: f32) -> Vec4 {
        let mut n = self.local_dir(normal);
        if n.dot(r) > 0.0 {
            n = -n;
        }
        let q = self.local(point);
        let slack = (OCCLUSION_SLACK * q.y).max(1e-4 * depth);
        let plane = n.extend(slack - n.dot(q));
        if plane.is_finite() { plane } else { NO_HIT_PLANE }
    }
}

/// The depth α past which every point of the volume is occluded by its hit planes
/// ([`CausticVolume::occluded`]: behind the planes of vertices weighing more than one
/// half), with a margin of 10⁻³ for rounding; `None` where there is none (a ray that
/// meets no surface, or a plane that the caustic triangle does not cross going deeper).
///
/// For each vertex `i`, past the depth where the corners of the part of the caustic
/// triangle with `λᵢ ≥ 1/4` have crossed plane `i`, that whole part lies behind it
/// (the plane is linear, the part convex). A point then lies behind the plane of every
/// vertex weighing at least 1/4, and those weigh more than 1/2: the others, at most two,
/// weigh less than 1/4 each. So the volume can end there and light exactly what it lit
/// when it reached the far side of the receivers, while the bounding prism (§4.3) ends
/// at the surfaces the rays land on rather than crossing the whole scene.
fn occluded_beyond(v: [Vec3; 3], r: [Vec3; 3], planes: [Vec4; 3]) -> Option<f32> {
    let mut end = 0.0f32;
    for (i, plane) in planes.iter().enumerate() {
        if *plane == NO_HIT_PLANE {
            return None;
        }
        let n = plane.truncate();
        // The part's corners: vertex i, and a quarter of the way from each other vertex.
        for j in 0..3 {
            let (at, ray) = if j == i { (v[i], r[i]) } else { (0.25 * v[i] + 0.75 * v[j], 0.25 * r[i] + 0.75 * r[j]) };
            // The plane's value n·q + w along the corner's ray q(α) = at + α ray.
            let (start, slope) = (n.dot(at) + plane.w, n.dot(ray));
            if slope.is_nan() || slope >= 0.0 {
                return None;
            }
            end = end.max(-start / slope);
        }
    }
    let end = end * (1.0 + 1e-3);
    end.is_finite().then_some(end)
}

/// How far each vertex ray's crossings of the three tangent planes may lie apart, as a
/// fraction of its own hit's depth, for the rays to land on one surface.
const ONE_SURFACE: f32 = 0.02;
/// The smallest cosine between the three hits' normals on one surface (8°).
const ONE_SURFACE_COS: f32 = 0.99;
/// How far the slab reaches either side of the tangent planes, as a fraction of the
/// hits' depth: room for receiver points rebuilt from a depth buffer.
const SLAB_MARGIN: f32 = 1e-3;

/// The slab around the one surface a volume's rays land on, in its local frame, and
/// the depths α between which the volume crosses it; `None` where the rays do not land
/// on one surface (rays landing on a step's edge, a corner; rays that all meet
/// nothing). `hits` are the rays' first hits (point, normal), local. On one surface
/// each ray crosses the tangent planes at the hits within [`ONE_SURFACE`] of its own
/// hit, and the normals agree within [`ONE_SURFACE_COS`]; the slab holds the planes
/// with [`SLAB_MARGIN`] either side. A ray that meets nothing (past the edge of a
/// floor) holds to the others' planes instead: the surface its neighbours land on is
/// the one the volume lights. Over a plane the crossing depth is a linear-fractional
/// function of the barycentric coordinates, so the volume crosses each of the slab's
/// planes between its vertex rays' crossings.
fn local_slab(v: [Vec3; 3], r: [Vec3; 3], hits: [Option<(Vec3, Vec3)>; 3]) -> Option<(SurfaceSlab, f32, f32)> {
    // The tangent planes n·p = offset at the hits, normals pointing the way the rays travel.
    let along = |n: Vec3| if n.dot(r[0] + r[1] + r[2]) < 0.0 { -n } else { n };
    let planes = hits.map(|hit| hit.map(|(point, n)| (along(n), along(n).dot(point))));
    let normal = planes.iter().flatten().map(|&(n, _)| n).sum::<Vec3>().try_normalize()?;
    if !planes.iter().flatten().all(|(n, _)| n.dot(normal) >= ONE_SURFACE_COS) {
        return None;
    }
    // Where ray j crosses the plane n·p = offset.
    let crossing = |(n, offset): (Vec3, f32), j: usize| {
        let towards = n.dot(r[j]);
        Some((offset - n.dot(v[j])) / towards).filter(|at| towards > 0.0 && at.is_finite() && *at > 0.0)
    };
    let first_plane = planes.iter().flatten().copied().next()?;
    let mut deepest = 0.0f32;
    for j in 0..3 {
        let own = crossing(planes[j].unwrap_or(first_plane), j)?;
        for &plane in planes.iter().flatten() {
            let at = crossing(plane, j)?;
            // Both finite and positive (`crossing`).
            if (at - own).abs() > ONE_SURFACE * own {
                return None;
            }
            deepest = deepest.max(at);
        }
    }
    let offsets = hits.iter().flatten().map(|&(point, _)| normal.dot(point));
    let margin = SLAB_MARGIN * deepest;
    let slab = SurfaceSlab { normal, near: offsets.clone().fold(f32::INFINITY, f32::min) - margin, far: offsets.fold(f32::NEG_INFINITY, f32::max) + margin };
    let (mut first, mut last) = (f32::INFINITY, 0.0f32);
    for j in 0..3 {
        first = first.min(crossing((normal, slab.near), j)?);
        last = last.max(crossing((normal, slab.far), j)?);
    }
    Some((slab, (1.0 - SLAB_MARGIN) * first, (1.0 + SLAB_MARGIN) * last))
}

/// A bounding shape (local) cut to the slab: each side line, from a top corner to the
/// one below, from where it crosses the near plane to where it crosses the far one; the
/// shape as it is where a side line does not cross both. The cut shape is the shape's
/// part inside the slab, and still convex: the surface pass rasterises a thin plate
/// around the surface instead of the slice, which a view at a grazing angle sees edge on.
fn cut_to_slab(shape: BoundingShape, slab: &SurfaceSlab) -> BoundingShape {
    let mut cut = shape;
    for k in 0..4 {
        let (top, bottom) = (shape.corners[k], shape.corners[k + 4]);
        let (a, b) = (slab.normal.dot(top), slab.normal.dot(bottom));
        if !(a < slab.near && slab.far < b) {
            return shape;
        }
        cut.corners[k] = top.lerp(bottom, (slab.near - a) / (b - a));
        cut.corners[k + 4] = top.lerp(bottom, (slab.far - a) / (b - a));
    }
    cut
}

/// Area coefficients (a, b, c) of `A(α) = a + bα + cα²` for vertices `v` (y = 0) and
/// rays `r` (y = 1) in one local frame (§3.4).
fn area_coefficients(v: [Vec3; 3], r: [Vec3; 3]) -> Vec3 {
    let (k1, k2) = (v[1] - v[0], v[2] - v[0]);
    let (l1, l2) = (r[1] - r[0], r[2] - r[0]);
    Vec3::new(k1.z * k2.x - k1.x * k2.z, k1.z * l2.x - k1.x * l2.z + l1.z * k2.x - l1.x * k2.z, l1.z * l2.x - l1.x * l2.z)
}

/// Vertex and ray of one mesh vertex in a frame: the ray scaled to `r_y = 1` and the
/// vertex moved along it into the plane `y = 0` (the flattening of Fig. 5). `None`
/// when the ray does not leave the plane steeply enough.
fn flattened(frame: &Frame, p: Vec3, ray: Vec3, min_cos: f32) -> Option<(Vec3, Vec3)> {
    let r = frame.local_dir(ray);
    if r.y < min_cos {
        return None;
    }
    let r = r / r.y;
    let v = frame.local(p);
    Some((v - v.y * r, r))
}

/// Builds the caustic volumes of one generator mesh under one light, for one colour
/// channel (`ior` overrides a refractor's index, for dispersion). Triangles lit from
/// behind cast only where `sides` lets them ([`Sides::lit_from_behind`]). `depth_bounds` are
/// the world bounds of the receivers: every volume ends beyond them. A vertex that
/// `occluders` (the scene's surfaces other than generators) hide from the light
/// carries no irradiance — past the paper, whose §3.1 lights every generator — so a
/// generator in shadow casts nothing and one in partial shadow casts a caustic that
/// fades across its shadow's edge, to the triangle. Each vertex ray also ends on the
/// first surface of `occluders` it meets ([`CausticVolume::hit_planes`]): points
/// behind it get no caustic light. Volumes are appended to `out`; triangles run in
/// parallel.
#[allow(clippy::too_many_arguments)]
pub fn build_generator_volumes(
    mesh: &TriMesh,
    fans: &VertexFans,
    interaction: &SpecularInteraction,
    sides: Sides,
    ior: Option<f32>,
    light: &Light,
    color: Vec3,
    depth_bounds: (Vec3, Vec3),
    occluders: Option<&SceneBvh>,
    settings: &VolumeSettings,
    out: &mut Vec<CausticVolume>,
) -> BuildStats {
    let own_fans;
    let fans = if fans.fits(mesh) {
        fans
    } else {
        own_fans = VertexFans::new(mesh);
        &own_fans
    };
    let two_sided = sides.lit_from_behind(interaction);
    let rays: Vec<VertexRay> = mesh.positions().par_iter().zip(mesh.normals().par_iter()).map(|(&p, &n)| vertex_ray(light, interaction, ior, p, n)).collect();
    let shadowed: Vec<bool> = match occluders {
        Some(occluders) => mesh.positions().par_iter().map(|&p| occluders.hides(light, p)).collect(),
        None => Vec::new(),
    };
    let rays: Vec<VertexRay> =
        rays.into_iter().zip(shadowed.iter().copied().chain(std::iter::repeat(false))).map(|(r, s)| if s { r.shadowed() } else { r }).collect();
    let hits: Vec<Option<(Vec3, Vec3)>> = match occluders {
        Some(occluders) => mesh.positions().par_iter().zip(rays.par_iter()).map(|(&p, r)| first_hit(occluders, p, r)).collect(),
        None => Vec::new(),
    };
    // The mean ray direction: a slicing axis shared by the triangles whose rays all
    // leave steeply enough along it.
    let slicing_axis = rays
        .iter()
        .map(|r| match r {
            VertexRay::Ray { direction, .. } => *direction,
            VertexRay::TotalInternalReflection { .. } => Vec3::ZERO,
        })
        .sum::<Vec3>()
        .try_normalize();
    let context = TriangleContext { mesh, fans, rays: &rays, shadowed: &shadowed, hits: &hits, two_sided, slicing_axis, light, color, depth_bounds, settings };
    let results: Vec<(Option<CausticVolume>, BuildStats)> = (0..mesh.triangles().len()).into_par_iter().map(|t| context.volume(t)).collect();
    let mut stats = BuildStats::default();
    out.reserve(results.len());
    for (volume, s) in results {
        stats = stats + s;
        out.extend(volume);
    }
    stats
}

/// What every triangle of one build shares.
struct TriangleContext<'a> {
    mesh: &'a TriMesh,
    fans: &'a VertexFans,
    rays: &'a [VertexRay],
    /// Per vertex, whether an occluder hides it from the light; empty without occluders.
    shadowed: &'a [bool],
    /// Per vertex, where its ray first meets an occluder (point, normal); empty without occluders.
    hits: &'a [Option<(Vec3, Vec3)>],
    two_sided: bool,
    slicing_axis: Option<Vec3>,
    light: &'a Light,
    color: Vec3,
    depth_bounds: (Vec3, Vec3),
    settings: &'a VolumeSettings,
}

impl TriangleContext<'_> {
    /// The caustic volume of triangle `t`, or why there is none.
    fn volume(&self, t: usize) -> (Option<CausticVolume>, BuildStats) {
        let TriangleContext { mesh, fans, rays, shadowed, hits, two_sided, slicing_axis, light, color, depth_bounds: (lo, hi), settings } = *self;
        let tri = mesh.triangles()[t];
        let p = mesh.corners(t);
        let mut stats = BuildStats::default();
        let cross = (p[1] - p[0]).cross(p[2] - p[0]);
        let longest = (p[1] - p[0]).length_squared().max((p[2] - p[0]).length_squared()).max((p[2] - p[1]).length_squared());
        if cross.length_squared() <= (1e-12 * longest) * longest || !cross.is_finite() {
            stats.degenerate = 1;
            return (None, stats);
        }
        let geometric = cross.normalize();
        // The front is the side the vertex normals face.
        let front = tri.iter().map(|&i| mesh.normals()[i as usize]).sum::<Vec3>();
        let mut unit = [Vec3::ZERO; 3];
        let mut weight = Vec3::ZERO;
        let mut lit = false;
        let mut tir = false;
        for i in 0..3 {
            let (irradiance, incident, fresnel) = match rays[tri[i] as usize] {
                VertexRay::Ray { direction, fresnel, irradiance, incident } => {
                    unit[i] = direction;
                    (irradiance, incident, fresnel)
                }
                VertexRay::TotalInternalReflection { irradiance, incident } => {
                    tir = true;
                    (irradiance, incident, 1.0)
                }
            };
            // Irradiance on the triangle's plane at the vertex, after Fresnel (with TIR:
            // the flux that the dropped volume would have carried).
            let cos = incident.dot(geometric).abs();
            weight[i] = irradiance * cos * fresnel;
            lit |= irradiance * cos > 0.0 && (two_sided || incident.dot(front) < 0.0);
        }
        let flux_estimate = |w: Vec3| (color * ((w.x + w.y + w.z) / 3.0 * 0.5 * cross.length())).as_dvec3();
        if !lit {
            if !shadowed.is_empty() && tri.iter().all(|&i| shadowed[i as usize]) {
                stats.shadowed = 1;
            } else {
                stats.unlit = 1;
            }
            return (None, stats);
        }
        if tir {
            stats.total_internal_reflection = 1;
            stats.dropped_flux = flux_estimate(weight);
            return (None, stats);
        }
        let mut normal = geometric;
        let mean_ray = unit[0] + unit[1] + unit[2];
        if mean_ray.dot(normal) < 0.0 {
            normal = -normal;
        }
        // Slice along the generator's shared axis where it fits this triangle, so that
        // neighbours pair their rays identically and their volumes leave no gaps or
        // overlaps; otherwise along the triangle's own normal, as §3.2 does.
        let shared = slicing_axis.filter(|&a| unit.iter().all(|u| u.dot(a) >= SHARED_AXIS_MIN_COS) && normal.dot(a) >= SHARED_AXIS_MIN_COS);
        let y = shared.unwrap_or(normal);
        // The origin is the vertex lowest along y, so the whole triangle lies at y ≥ 0.
        let lowest = (0..3).min_by(|&i, &j| p[i].dot(y).total_cmp(&p[j].dot(y))).unwrap_or(0);
        let edge = (p[(lowest + 1) % 3] - p[lowest]).reject_from_normalized(y);
        let x = edge.try_normalize().unwrap_or_else(|| crate::tracer::orthonormal_basis(y).0);
        let mut frame = Frame { origin: p[lowest], axes: [x, y, x.cross(y)] };
        let own = |frame: &Frame| -> Option<([Vec3; 3], [Vec3; 3])> {
            let mut v = [Vec3::ZERO; 3];
            let mut r = [Vec3::ZERO; 3];
            for i in 0..3 {
                (v[i], r[i]) = flattened(frame, p[i], unit[i], settings.min_ray_cosine)?;
            }
            Some((v, r))
        };
        let Some((mut v, mut r)) = own(&frame) else {
            stats.grazing = 1;
            stats.dropped_flux = flux_estimate(weight);
            return (None, stats);
        };
        let mut abc = area_coefficients(v, r);
        if abc.x < 0.0 {
            frame.axes[2] = -frame.axes[2];
            (v, r) = own(&frame).expect("mirroring z keeps ray heights");
            abc = area_coefficients(v, r);
        }
        // The flux crossing the triangle crosses its flattened image too: scale the
        // per-vertex irradiance from the triangle's plane to the slicing plane.
        weight *= cross.length() / abc.x;
        // The far corner of the receivers' bounds, and a little beyond, so that a
        // receiver lying exactly at the end is not lost to rounding.
        let depth = (0..8)
            .map(|i| Vec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][i >> 2]))
            .map(|c| frame.local(c).y)
            .fold(f32::NEG_INFINITY, f32::max)
            * (1.0 + 1e-3);
        if depth.is_nan() || depth <= 0.0 || abc.x.is_nan() || abc.x <= 0.0 || !abc.is_finite() {
            stats.degenerate = 1;
            stats.dropped_flux = flux_estimate(weight);
            return (None, stats);
        }
        // Per-vertex coefficients from the fan around each vertex, flattened into this
        // triangle's plane and summed (§3.4, Fig. 5); the triangle's own when the fan
        // cannot be flattened.
        let mut fan = [abc; 3];
        for (i, coefficients) in fan.iter_mut().enumerate() {
            let mut sum = Vec3::ZERO;
            let mut complete = true;
            for &f in fans.around(tri[i]) {
                let ft = mesh.triangles()[f as usize];
                let mut fv = [Vec3::ZERO; 3];
                let mut fr = [Vec3::ZERO; 3];
                for j in 0..3 {
                    let k = ft[j] as usize;
                    let ray = match rays[k] {
                        VertexRay::Ray { direction, .. } => direction,
                        VertexRay::TotalInternalReflection { .. } => Vec3::ZERO,
                    };
                    match flattened(&frame, mesh.positions()[k], ray, settings.min_ray_cosine) {
                        Some(vr) => (fv[j], fr[j]) = vr,
                        None => complete = false,
                    }
                }
                if !complete {
                    break;
                }
                sum += area_coefficients(fv, fr);
            }
            if complete && sum.x > 0.0 && sum.is_finite() {
                *coefficients = sum;
            }
        }
        // The light's path to each vertex, moved along its ray into the plane y = 0.
        let light_distance = Vec3::from_array(std::array::from_fn(|i| {
            let to_vertex = light.position().map_or(0.0, |l| (p[i] - l).length());
            to_vertex - frame.local(p[i]).y * r[i].length()
        }));
        let owned_edges = fans.owned_edges(mesh, t);
        // Each vertex ray's first hit (point, normal), if it meets a surface.
        let vertex_hits: [Option<(Vec3, Vec3)>; 3] = std::array::from_fn(|i| hits.get(tri[i] as usize).copied().flatten());
        let hit_planes: [Vec4; 3] = std::array::from_fn(|i| vertex_hits[i].map_or(NO_HIT_PLANE, |hit| frame.hit_plane(hit, r[i], depth)));
        // The volume ends where its rays have met the surfaces they hit, not at the far
        // side of every receiver: the points past there are occluded. Where the rays
        // land on one surface, the surface pass draws only the slab around it.
        let local_hits = vertex_hits.map(|hit| hit.map(|(p, n)| (frame.local(p), frame.local_dir(n))));
        let whole = |depth: f32| occluded_beyond(v, r, hit_planes).map_or(depth, |end| end.clamp(1e-3 * depth, depth));
        // Rays that all meet nothing land on no surface: the volume lights none, though
        // its beam still scatters in a medium.
        let escapes = !hits.is_empty() && local_hits.iter().all(Option::is_none);
        let (slab, depth, bounds, surface_bounds) = match local_slab(v, r, local_hits).filter(|&(_, _, last)| last <= depth) {
            Some((slab, first, last)) => {
                let normal = frame.world_dir(slab.normal);
                let offset = normal.dot(frame.origin);
                let world = SurfaceSlab { normal, near: slab.near + offset, far: slab.far + offset };
                // The slice of the beam that crosses the slab, bounded on its own and cut
                // to the slab where its sides cross it. A beam partly past the surface's
                // edge goes on in a medium.
                let top = std::array::from_fn(|i| v[i] + first * r[i]);
                let slice = BoundingShape::local(top, r, last - first);
                let end = if local_hits.iter().all(Option::is_some) { last } else { whole(depth) };
                (Some(world), end, BoundingShape::local(v, r, end), cut_to_slab(slice, &slab))
            }
            None => {
                let end = whole(depth);
                let bounds = BoundingShape::local(v, r, end);
                let surface = if escapes { BoundingShape::EMPTY } else { bounds };
                (escapes.then_some(SurfaceSlab::EMPTY), end, bounds, surface)
            }
        };
        let volume = CausticVolume {
            origin: frame.origin,
            axes: frame.axes,
            vertex_x: Vec3::new(v[0].x, v[1].x, v[2].x),
            vertex_z: Vec3::new(v[0].z, v[1].z, v[2].z),
            ray_x: Vec3::new(r[0].x, r[1].x, r[2].x),
            ray_z: Vec3::new(r[0].z, r[1].z, r[2].z),
            fan_a: Vec3::new(fan[0].x, fan[1].x, fan[2].x),
            fan_b: Vec3::new(fan[0].y, fan[1].y, fan[2].y),
            fan_c: Vec3::new(fan[0].z, fan[1].z, fan[2].z),
            triangle_abc: abc,
            surface_normal: normal,
            owned_edges,
            flux: weight,
            color,
            light_distance,
            inverse_range_squared: light.inverse_range_squared(),
            depth,
            slab,
            hit_planes,
            bounds: bounds.to_world(|q| frame.world(q)),
            surface_bounds: if surface_bounds == BoundingShape::EMPTY { surface_bounds } else { surface_bounds.to_world(|q| frame.world(q)) },
        };
        stats.volumes = 1;
        stats.surface_slabs = usize::from(volume.slab.is_some_and(|s| s.near <= s.far));
        stats.escaping = usize::from(volume.slab == Some(SurfaceSlab::EMPTY));
        stats.flux = volume.flux().as_dvec3();
        (Some(volume), stats)
    }
}

/// Builds every volume of a scene: each light × generator, and one set per RGB
/// channel for a dispersive refractor (its Cauchy index at the channel's wavelength,
/// the flux in that channel only — Ernst et al. render one pass per colour, §5).
/// Volumes end beyond the bounds of all receivers. The receivers and the other
/// generators shadow each generator ([`occluders_of`]).
pub fn build_scene_volumes(scene: &Scene, settings: &VolumeSettings) -> super::VolumeSet {
    build_drawn_volumes(scene, settings, |_| true)
}

/// [`build_scene_volumes`] for the generators `drawn(index)` picks; the others only
/// shadow them (another technique draws them).
pub fn build_drawn_volumes(scene: &Scene, settings: &VolumeSettings, drawn: impl Fn(usize) -> bool) -> super::VolumeSet {
    let bounds = scene.receivers.iter().map(|r| r.mesh.bounds()).reduce(|(a, b), (c, d)| (a.min(c), b.max(d))).unwrap_or((Vec3::ZERO, Vec3::ZERO));
    let mut volumes = Vec::new();
    let mut stats = BuildStats::default();
    let others = |g: usize| scene.generators.iter().enumerate().filter(move |(i, _)| *i != g).map(|(_, o)| o.mesh.clone());
    let receivers_only = SceneBvh::build(&occluders_of(scene.receivers.iter().map(|r| r.mesh.clone()), std::iter::empty()));
    for (g, generator) in scene.generators.iter().enumerate().filter(|(g, _)| drawn(*g)) {
        let with_others;
        let occluders = if scene.generators.len() > 1 {
            with_others = SceneBvh::build(&occluders_of(scene.receivers.iter().map(|r| r.mesh.clone()), others(g)));
            &with_others
        } else {
            &receivers_only
        };
        let fans = VertexFans::new(&generator.mesh);
        let sides = generator.sides();
        for light in &scene.lights {
            for (ior, color) in channels(&generator.interaction, light.color) {
                stats = stats
                    + build_generator_volumes(
                        &generator.mesh,
                        &fans,
                        &generator.interaction,
                        sides,
                        ior,
                        light,
                        color,
                        bounds,
                        Some(occluders),
                        settings,
                        &mut volumes,
                    );
            }
        }
    }
    super::VolumeSet::new(volumes, stats)
}

/// What shadows a generator and ends its caustic volumes' rays: the receivers and
/// every other generator, as occluders. A path belongs to the first generator the light
/// meets: light a glass body bends onto a mirror is that body's technique's to carry
/// (the caustic maps' traced paths follow it on), and the volumes of a mirror behind it
/// get none, where the paper (§3.1) lights every generator as if alone.
pub fn occluders_of(receivers: impl Iterator<Item = TriMesh>, other_generators: impl Iterator<Item = TriMesh>) -> Scene {
    let receivers = receivers.chain(other_generators).map(|mesh| crate::scene::Receiver { mesh, albedo: Vec3::ONE }).collect();
    Scene { receivers, ..Scene::default() }
}

/// The colour channels a generator is built in: one with the light's colour, or three
/// (red, green, blue, each with its own index) for a dispersive refractor.
pub fn channels(interaction: &SpecularInteraction, color: Vec3) -> Vec<(Option<f32>, Vec3)> {
    match interaction {
        SpecularInteraction::Refract { dispersion: Some(d), .. } => (0..3).map(|c| (Some(d.ior(RGB_WAVELENGTHS_UM[c])), color * Vec3::AXES[c])).collect(),
        SpecularInteraction::Refract { ior, dispersion: None } => vec![(Some(*ior), color)],
        SpecularInteraction::Reflect => vec![(None, color)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Pcg32;

    /// Past the depth `occluded_beyond` gives, every point of the caustic triangle is
    /// behind hit planes weighing more than one half, for rays that fan out or focus
    /// onto tilted surfaces: ending the volume there loses no lit point.
    #[test]
    fn every_point_past_the_tightened_depth_is_occluded() {
        let mut random = Pcg32::for_photon(3, 0, 0);
        let mut uniform = |lo: f32, hi: f32| lo + (hi - lo) * random.next_f32();
        let mut checked = 0;
        for _ in 0..2000 {
            let v: [Vec3; 3] = std::array::from_fn(|_| Vec3::new(uniform(-1.0, 1.0), 0.0, uniform(-1.0, 1.0)));
            let r: [Vec3; 3] = std::array::from_fn(|_| Vec3::new(uniform(-1.5, 1.5), 1.0, uniform(-1.5, 1.5)));
            let frame = Frame { origin: Vec3::ZERO, axes: [Vec3::X, Vec3::Y, Vec3::Z] };
            let planes: [Vec4; 3] = std::array::from_fn(|i| {
                let hit = v[i] + uniform(0.5, 4.0) * r[i];
                let normal = Vec3::new(uniform(-0.6, 0.6), 1.0, uniform(-0.6, 0.6)).normalize();
                frame.hit_plane((hit, normal), r[i], 10.0)
            });
            let Some(end) = occluded_beyond(v, r, planes) else { continue };
            // `CausticVolume::occluded`.
            let occluded = |p: Vec3, lambda: Vec3| (0..3).filter(|&i| planes[i].truncate().dot(p) + planes[i].w < 0.0).map(|i| lambda[i]).sum::<f32>() > 0.5;
            for _ in 0..50 {
                let (a, b) = (uniform(0.0, 1.0), uniform(0.0, 1.0));
                let lambda = if a + b > 1.0 { Vec3::new(1.0 - a, 1.0 - b, a + b - 1.0) } else { Vec3::new(a, b, 1.0 - a - b) };
                let alpha = end * uniform(1.0, 4.0);
                let point = (0..3).map(|k| lambda[k] * (v[k] + alpha * r[k])).sum::<Vec3>();
                assert!(occluded(point, lambda), "lit at α = {alpha} past {end}: λ {lambda}, planes {planes:?}");
            }
            checked += 1;
        }
        assert!(checked > 500, "only {checked} of the random volumes had a tightened depth");
    }

    /// Rays landing on one tilted plane: the slab holds the plane, and the slice of the
    /// beam between the depths it gives holds the slab's part inside the volume; rays
    /// landing on two surfaces a step apart keep the whole beam, and a ray that meets
    /// nothing holds to the surface its neighbours land on.
    #[test]
    fn the_slab_holds_the_surface_the_rays_land_on() {
        let mut random = Pcg32::for_photon(5, 0, 0);
        let mut uniform = |lo: f32, hi: f32| lo + (hi - lo) * random.next_f32();
        let mut slabs = 0;
        for _ in 0..2000 {
            let v: [Vec3; 3] = std::array::from_fn(|_| Vec3::new(uniform(-0.1, 0.1), 0.0, uniform(-0.1, 0.1)));
            let r: [Vec3; 3] = std::array::from_fn(|_| Vec3::new(uniform(-0.3, 0.3), 1.0, uniform(-0.3, 0.3)));
            let normal = Vec3::new(uniform(-0.5, 0.5), 1.0, uniform(-0.5, 0.5)).normalize();
            let on_surface = Vec3::new(0.0, uniform(0.5, 3.0), 0.0);
            // Where ray i meets the plane through `on_surface`; its normal either way.
            let hit = |i: usize| v[i] + (normal.dot(on_surface - v[i]) / normal.dot(r[i])) * r[i];
            let sign = if uniform(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 };
            let Some((slab, first, last)) = local_slab(v, r, std::array::from_fn(|i| Some((hit(i), sign * normal)))) else { continue };
            slabs += 1;
            let offset = slab.normal.dot(on_surface);
            assert!(slab.near < offset && offset < slab.far && slab.far - slab.near < 0.01, "{slab:?} against the plane at {offset}");
            for _ in 0..50 {
                let (a, b) = (uniform(0.0, 1.0), uniform(0.0, 1.0));
                let lambda = if a + b > 1.0 { Vec3::new(1.0 - a, 1.0 - b, a + b - 1.0) } else { Vec3::new(a, b, 1.0 - a - b) };
                // Where the caustic triangle's point with weights λ crosses either side of the slab.
                let (at, ray) = (0..3).fold((Vec3::ZERO, Vec3::ZERO), |(p, d), k| (p + lambda[k] * v[k], d + lambda[k] * r[k]));
                for plane in [slab.near, slab.far] {
                    let alpha = (plane - slab.normal.dot(at)) / slab.normal.dot(ray);
                    assert!(alpha > first && alpha < last, "the slab's plane at α = {alpha} lies outside the slice {first} – {last}");
                }
            }
        }
        assert!(slabs > 1500, "only {slabs} of 2000 volumes on one plane have a slab");
        let (v, r) = ([Vec3::ZERO, Vec3::X, Vec3::Z], [Vec3::Y; 3]);
        let (floor, tread) = (Some((Vec3::new(0.0, 2.0, 0.0), Vec3::Y)), Some((Vec3::new(0.0, 1.5, 0.0), Vec3::Y)));
        assert_eq!(local_slab(v, r, [floor, floor, tread]), None);
        assert_eq!(local_slab(v, r, [None; 3]), None);
        let (slab, first, last) = local_slab(v, r, [floor; 3]).expect("one floor");
        // A ray past the floor's edge holds to the others' floor.
        assert_eq!(local_slab(v, r, [floor, floor, None]), Some((slab, first, last)));
        assert_eq!(local_slab(v, r, [None, floor, None]), Some((slab, first, last)));
        assert!(slab.near > 1.99 && slab.near < 2.0 && slab.far > 2.0 && slab.far < 2.01, "{slab:?}");
        assert!(first > 1.98 && first < slab.near && last > slab.far && last < 2.02, "{first} – {last}");
    }

    /// A ray that meets nothing, or a plane the triangle leaves behind, keeps the
    /// volume at the far side of the receivers.
    #[test]
    fn a_ray_that_meets_nothing_keeps_the_whole_depth() {
        let v = [Vec3::ZERO, Vec3::X, Vec3::Z];
        let r = [Vec3::Y; 3];
        let floor = Vec4::new(0.0, -1.0, 0.0, 2.0);
        assert_eq!(occluded_beyond(v, r, [floor, floor, NO_HIT_PLANE]), None);
        let wall_behind = Vec4::new(-1.0, 0.0, 0.0, -5.0);
        assert_eq!(occluded_beyond(v, r, [floor, floor, wall_behind]), None);
        let end = occluded_beyond(v, r, [floor; 3]).expect("a floor two below");
        assert!((end - 2.0).abs() < 1e-2, "{end}");
    }
}
