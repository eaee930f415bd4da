//! The generators' triangles in a binary BVH laid out as the GPU reads it (two `vec4`s
//! a node, six a triangle), for photons traced through the generators instead of
//! through the light's front and back maps ([`super::PhotonPaths::Traced`]). The
//! traversal here is the CPU twin of `generator_bvh.wgsl`: the same stack, the same
//! slab and Möller–Trumbore tests in the same order, so both find the same hit.

use crate::mesh::TriMesh;
use crate::scene::Scene;
use glam::{Vec2, Vec3, Vec4};

/// Triangles a leaf holds at most.
pub const LEAF_SIZE: usize = 4;
/// Depth of the traversal stack (`generator_bvh.wgsl` declares the same): the builder
/// splits at the median, so a tree of 2³¹ triangles stays shallower.
pub const STACK_DEPTH: usize = 32;

/// A node: its box, and either its first child (the second follows it) or its
/// triangles. `std430`: `min.w` holds `first` (the left child, or the first triangle of
/// a leaf) and `max.w` the triangle count (0 for an inner node), as bits.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    pub count: u32,
}

/// A triangle in world space with its vertex normals, in BVH order: `positions[i].w`
/// holds the generator's index as bits, `normals[i].w` is 0.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct BvhTriangle {
    pub positions: [[f32; 4]; 3],
    pub normals: [[f32; 4]; 3],
}

impl BvhTriangle {
    fn corner(&self, i: usize) -> Vec3 {
        Vec4::from_array(self.positions[i]).truncate()
    }

    /// The generator this triangle belongs to.
    pub fn generator(&self) -> u32 {
        self.positions[0][3].to_bits()
    }

    fn centroid(&self) -> Vec3 {
        (self.corner(0) + self.corner(1) + self.corner(2)) / 3.0
    }
}

/// A ray's closest generator hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneratorHit {
    pub t: f32,
    pub generator: u32,
    /// The interpolated vertex normal (unit, as the mesh orients it).
    pub normal: Vec3,
    /// The triangle's unit geometric normal (counter-clockwise front).
    pub geometric_normal: Vec3,
}

/// Every generator triangle of a scene in one binary BVH.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GeneratorBvh {
    pub nodes: Vec<BvhNode>,
    pub triangles: Vec<BvhTriangle>,
}

impl GeneratorBvh {
    /// The BVH of `scene`'s generators (empty without triangles). Degenerate triangles
    /// are kept: the intersection test never hits them.
    pub fn build(scene: &Scene) -> Self {
        Self::of_meshes(scene.generators.iter().enumerate().map(|(g, generator)| (g as u32, &generator.mesh)))
    }

    /// The BVH of world-space meshes, each with its generator's index.
    pub fn of_meshes<'a>(meshes: impl Iterator<Item = (u32, &'a TriMesh)>) -> Self {
        let mut triangles: Vec<BvhTriangle> = meshes
            .flat_map(|(g, mesh)| {
                mesh.triangles().iter().map(move |tri| BvhTriangle {
                    positions: tri.map(|i| mesh.positions()[i as usize].extend(f32::from_bits(g)).to_array()),
                    normals: tri.map(|i| mesh.normals()[i as usize].extend(0.0).to_array()),
                })
            })
            .collect();
        if triangles.is_empty() {
            return Self::default();
        }
        let mut nodes = vec![BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 }];
        // Each entry: the node to fill and its triangle range.
        let mut pending = vec![(0usize, 0usize, triangles.len())];
        while let Some((node, start, end)) = pending.pop() {
            let (lo, hi) = bounds(&triangles[start..end]);
            nodes[node].min = lo.to_array();
            nodes[node].max = hi.to_array();
            if end - start <= LEAF_SIZE {
                nodes[node].first = start as u32;
                nodes[node].count = (end - start) as u32;
                continue;
            }
            // The median along the centroids' widest axis.
            let (clo, chi) = triangles[start..end]
                .iter()
                .map(BvhTriangle::centroid)
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), c| (a.min(c), b.max(c)));
            let axis = (chi - clo).to_array().iter().enumerate().fold(0, |best, (i, &e)| if e > (chi - clo)[best] { i } else { best });
            let mid = (start + end) / 2;
            triangles[start..end].select_nth_unstable_by(mid - start, |a, b| a.centroid()[axis].total_cmp(&b.centroid()[axis]));
            let left = nodes.len();
            nodes.push(BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 });
            nodes.push(BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 });
            nodes[node].first = left as u32;
            pending.push((left, start, mid));
            pending.push((left + 1, mid, end));
        }
        Self { nodes, triangles }
    }

    /// The BVH as `triangle_bvh.wgsl` reads it: the nodes, then the triangles, as
    /// bytes (16 zero bytes for an empty BVH: a GPU binding may not be empty).
    pub fn gpu_bytes(&self) -> Vec<u8> {
        let bytes = [bytemuck::cast_slice(&self.nodes), bytemuck::cast_slice(&self.triangles)].concat();
        if bytes.is_empty() { vec![0; 16] } else { bytes }
    }

    /// Where the triangles start in [`Self::gpu_bytes`], in `vec4`s: two a node; 0 for
    /// a BVH without triangles, which the GPU reads as none.
    pub fn gpu_triangle_offset(&self) -> u32 {
        if self.triangles.is_empty() { 0 } else { 2 * self.nodes.len() as u32 }
    }

    /// How far a traced ray starts off the surface it leaves: 2·10⁻⁵ of the
    /// generators' extent (the tracer's offset).
    pub fn ray_offset(&self) -> f32 {
        self.nodes.first().map_or(2e-5, |root| {
            let (lo, hi) = (Vec3::from_array(root.min), Vec3::from_array(root.max));
            2e-5 * (hi - lo).max_element().max(lo.abs().max_element()).max(hi.abs().max_element()).max(1e-6)
        })
    }

    /// The closest generator hit along `origin + t·dir` with `t` in `(t_min, t_max)`.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<GeneratorHit> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv = dir.recip();
        let mut closest: Option<(f32, usize, Vec2)> = None;
        let mut t_far = t_max;
        let mut stack = [0u32; STACK_DEPTH];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let node = self.nodes[stack[len] as usize];
            if !slab(origin, inv, &node, t_min, t_far) {
                continue;
            }
            if node.count > 0 {
                for i in node.first..node.first + node.count {
                    if let Some((t, uv)) = möller_trumbore(&self.triangles[i as usize], origin, dir, t_min, t_far) {
                        t_far = t;
                        closest = Some((t, i as usize, uv));
                    }
                }
            } else if len + 2 <= STACK_DEPTH {
                stack[len] = node.first;
                stack[len + 1] = node.first + 1;
                len += 2;
            }
        }
        closest.map(|(t, i, uv)| {
            let tri = &self.triangles[i];
            let n = |k: usize| Vec4::from_array(tri.normals[k]).truncate();
            let normal = (n(0) * (1.0 - uv.x - uv.y) + n(1) * uv.x + n(2) * uv.y).normalize_or_zero();
            let geometric = (tri.corner(1) - tri.corner(0)).cross(tri.corner(2) - tri.corner(0)).normalize_or_zero();
            GeneratorHit { t, generator: tri.generator(), normal: if normal == Vec3::ZERO { geometric } else { normal }, geometric_normal: geometric }
        })
    }
}

fn bounds(triangles: &[BvhTriangle]) -> (Vec3, Vec3) {
    triangles.iter().flat_map(|t| (0..3).map(|i| t.corner(i))).fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(p), b.max(p)))
}

/// Whether the ray meets the node's box within `(t_min, t_max)`.
#[inline]
fn slab(origin: Vec3, inv: Vec3, node: &BvhNode, t_min: f32, t_max: f32) -> bool {
    let t0 = (Vec3::from_array(node.min) - origin) * inv;
    let t1 = (Vec3::from_array(node.max) - origin) * inv;
    // `max`/`min` drop the NaN of 0·∞ (a ray in the plane of a face), as WGSL's do on
    // the GPUs that follow IEEE: the slab stays open along that axis.
    let near = t0.min(t1).max_element().max(t_min);
    let far = t0.max(t1).min_element().min(t_max);
    near <= far
}

/// Möller–Trumbore on either side: `(t, (u, v))`, `None` for a miss, a degenerate
/// triangle or a ray in its plane.
#[inline]
fn möller_trumbore(tri: &BvhTriangle, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, Vec2)> {
    let v0 = tri.corner(0);
    let (e1, e2) = (tri.corner(1) - v0, tri.corner(2) - v0);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - v0;
    let u = s.dot(p) * inv;
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    let t = e2.dot(q) * inv;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > t_min && t < t_max).then_some((t, Vec2::new(u, v)))
}
