//! Closest-hit ray queries over every triangle of a [`Scene`], on a compressed wide
//! BVH (CWBVH, Ylitie et al. 2017) built by `obvhs`.

use crate::scene::{Light, LightKind, Scene};
use glam::{Vec2, Vec3};
use glam_bvh::Vec3A as BvhVec3;
use obvhs::{
    BvhBuildParams,
    cwbvh::{CwBvh, builder::build_cwbvh_from_tris},
    ray::{Ray, RayHit},
    triangle::Triangle,
};
use std::time::Duration;

/// Which scene surface a triangle belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// Index into [`Scene::generators`].
    Generator(u32),
    /// Index into [`Scene::receivers`].
    Receiver(u32),
}

/// A ray's closest hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the (unit) ray direction.
    pub t: f32,
    /// Which scene surface the hit triangle belongs to.
    pub surface: Surface,
    /// Triangle index within the surface's mesh.
    pub triangle: u32,
    /// Barycentric coordinates (weights of corners 1 and 2).
    pub uv: Vec2,
    /// Unit geometric normal of the triangle (front face: counter-clockwise).
    pub geometric_normal: Vec3,
}

/// Precomputed triangle for Möller–Trumbore: one corner and two edges.
#[derive(Clone, Copy)]
struct PackedTriangle {
    v0: BvhVec3,
    e1: BvhVec3,
    e2: BvhVec3,
}

impl PackedTriangle {
    /// Möller–Trumbore; returns `(t, u, v)` or `None`. Degenerate (zero-area)
    /// triangles never hit.
    #[inline(always)]
    fn intersect(&self, origin: BvhVec3, dir: BvhVec3, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let p = dir.cross(self.e2);
        let det = self.e1.dot(p);
        if det.abs() < 1e-12 {
            return None;
        }
        let inv = 1.0 / det;
        let s = origin - self.v0;
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(self.e1);
        let v = dir.dot(q) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = self.e2.dot(q) * inv;
        (t > tmin && t < tmax).then_some((t, u, v))
    }
}

/// All scene triangles in BVH order, with the surface each came from.
pub struct SceneBvh {
    bvh: CwBvh,
    triangles: Vec<PackedTriangle>,
    owners: Vec<(Surface, u32)>,
}

fn to_bvh(v: Vec3) -> BvhVec3 {
    BvhVec3::new(v.x, v.y, v.z)
}

impl SceneBvh {
    /// Builds the BVH over all generator and receiver triangles.
    pub fn build(scene: &Scene) -> Self {
        let meshes = scene
            .generators
            .iter()
            .enumerate()
            .map(|(i, g)| (Surface::Generator(i as u32), &g.mesh))
            .chain(scene.receivers.iter().enumerate().map(|(i, r)| (Surface::Receiver(i as u32), &r.mesh)));
        let mut tris = Vec::new();
        let mut owners = Vec::new();
        for (surface, mesh) in meshes {
            for t in 0..mesh.triangles().len() {
                let [a, b, c] = mesh.corners(t).map(to_bvh);
                tris.push(Triangle { v0: a, v1: b, v2: c });
                owners.push((surface, t as u32));
            }
        }
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
        // Reorder the triangles so that leaf primitive ids index them directly.
        let (triangles, owners) = bvh
            .primitive_indices
            .iter()
            .map(|&i| {
                let t = &tris[i as usize];
                (PackedTriangle { v0: t.v0, e1: t.v1 - t.v0, e2: t.v2 - t.v0 }, owners[i as usize])
            })
            .unzip();
        Self { bvh, triangles, owners }
    }

    /// Whether a surface in this BVH hides `p` from `light`: the shadow ray starts at
    /// `p` itself (a hair along, for rounding), so the surface `p` lies on must not be
    /// in the BVH — as for generators, which their occluders' BVH leaves out.
    pub fn hides(&self, light: &Light, p: Vec3) -> bool {
        let (to_light, distance) = match light.kind {
            LightKind::Directional { direction, .. } => (-direction.normalize_or_zero(), f32::INFINITY),
            LightKind::Point { position, .. } | LightKind::Spot { position, .. } => {
                let d = position - p;
                (d.normalize_or_zero(), d.length())
            }
        };
        let hair = 1e-5 * (1.0 + p.abs().max_element());
        self.intersect(p, to_light, hair, distance).is_some()
    }

    /// The closest hit along `origin + t·dir`, `t ∈ (tmin, tmax)`.
    #[inline]
    pub fn intersect(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        if self.triangles.is_empty() {
            return None;
        }
        // `−0.0` components (a negated axis-aligned direction) make obvhs' slab test miss
        // every node; adding `+0.0` turns them into `+0.0` and changes nothing else.
        let (o, d) = (to_bvh(origin), to_bvh(dir + Vec3::ZERO));
        let ray = Ray::new(o, d, tmin, tmax);
        let mut hit = RayHit::none();
        let mut best_uv = (0.0, 0.0);
        let found = self.bvh.ray_traverse(ray, &mut hit, |r, id| match self.triangles[id].intersect(o, d, r.tmin, r.tmax) {
            Some((t, u, v)) => {
                best_uv = (u, v);
                t
            }
            None => f32::INFINITY,
        });
        if !found {
            return None;
        }
        // `best_uv` belongs to the last accepted candidate, which is the closest hit:
        // the traversal only accepts hits nearer than the current `tmax`.
        let id = hit.primitive_id as usize;
        let tri = &self.triangles[id];
        let n = tri.e1.cross(tri.e2);
        let (surface, triangle) = self.owners[id];
        Some(Hit { t: hit.t, surface, triangle, uv: Vec2::new(best_uv.0, best_uv.1), geometric_normal: Vec3::new(n.x, n.y, n.z).normalize_or(Vec3::Y) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::scene::Receiver;

    #[test]
    fn axis_aligned_rays_hit_whatever_the_sign_of_their_zeros() {
        let floor = TriMesh::quad(Vec3::ZERO, Vec3::Z, Vec3::X);
        let scene = Scene { receivers: vec![Receiver { mesh: floor, albedo: Vec3::ONE }], ..Scene::default() };
        let bvh = SceneBvh::build(&scene);
        let down = Vec3::new(0.0, -1.0, 0.0);
        assert!(bvh.intersect(Vec3::new(0.2, 1.0, 0.1), down, 0.0, f32::INFINITY).is_some());
        // −(0, −1, 0) = (−0, 1, −0).
        assert!(bvh.intersect(Vec3::new(0.2, -1.0, 0.1), -down, 0.0, f32::INFINITY).is_some());
    }
}
