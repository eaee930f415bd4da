//! Triangles in binary BVHs laid out as the GPU reads them (two `vec4`s a node, six a
//! triangle), in two levels: a [`MeshBvh`] per mesh in the mesh's own space, built
//! once per mesh asset, and an [`InstancedBvh`] over the placed meshes, rebuilt from
//! their transforms when one moves. The caustic maps trace photons through the
//! generators with it ([`super::PhotonPaths::Traced`]) and the caustic volumes cast
//! their shadow and hit rays. The traversal here is the CPU twin of
//! `triangle_bvh.wgsl`: the same stacks, transforms, slab and Möller–Trumbore tests in
//! the same order, so both find the same hit.

use crate::mesh::TriMesh;
use crate::scene::Scene;
use glam::{Mat4, Vec2, Vec3, Vec4};
use std::sync::Arc;

/// Triangles a leaf holds at most.
pub const LEAF_SIZE: usize = 4;
/// A mesh index no instance has: [`InstancedBvh::intersect`] skips none.
pub const NO_MESH: u32 = u32::MAX;
/// Depth of the traversal stack (`triangle_bvh.wgsl` declares the same): the builder
/// splits at the median, so a tree of 2³¹ triangles stays shallower.
pub const STACK_DEPTH: usize = 32;

/// A node: its box, and either its first child (the second follows it) or its
/// triangles. `std430`: `min.w` holds `first` (the left child, or the first triangle of
/// a leaf) and `max.w` the triangle count (0 for an inner node), as bits.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct BvhNode {
    /// Lower corner of the box.
    pub min: [f32; 3],
    /// The left child of an inner node, or a leaf's first triangle (instance, in a top
    /// level).
    pub first: u32,
    /// Upper corner of the box.
    pub max: [f32; 3],
    /// Triangles (instances, in a top level) in a leaf; 0 for an inner node.
    pub count: u32,
}

/// A triangle in its mesh's space with its vertex normals, in BVH order (`w` is 0).
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct BvhTriangle {
    /// The three corners, `w` 0.
    pub positions: [[f32; 4]; 3],
    /// The three vertex normals, `w` 0.
    pub normals: [[f32; 4]; 3],
}

impl BvhTriangle {
    /// The triangle of vertices `corners` of `positions` and `normals`.
    fn of(positions: &[Vec3], normals: &[Vec3], corners: [u32; 3]) -> Self {
        Self { positions: corners.map(|i| positions[i as usize].extend(0.0).to_array()), normals: corners.map(|i| normals[i as usize].extend(0.0).to_array()) }
    }

    fn corner(&self, i: usize) -> Vec3 {
        Vec4::from_array(self.positions[i]).truncate()
    }

    fn centroid(&self) -> Vec3 {
        (self.corner(0) + self.corner(1) + self.corner(2)) / 3.0
    }
}

/// A ray's closest generator hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneratorHit {
    /// The hit's `t` along `origin + t·dir`.
    pub t: f32,
    /// The mesh index its instance was placed with ([`InstancedBvh::new`]).
    pub generator: u32,
    /// The interpolated vertex normal (unit, as the mesh orients it).
    pub normal: Vec3,
    /// The triangle's unit geometric normal (counter-clockwise front).
    pub geometric_normal: Vec3,
}

/// One mesh's triangles in a binary BVH, in the mesh's own space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshBvh {
    /// The nodes, root first; a node's children come after it.
    pub nodes: Vec<BvhNode>,
    /// The triangles in BVH order: a leaf's `first` and `count` index them.
    pub triangles: Vec<BvhTriangle>,
    /// Each triangle's three vertices in the mesh it was built from, in BVH order: what
    /// a refit ([`Self::refit`], `bvh_refit.wgsl`) reads the moved vertices by.
    pub corners: Vec<[u32; 3]>,
}

impl MeshBvh {
    /// One mesh's BVH in its own space, as an [`InstancedBvh`] places it. Degenerate
    /// triangles are kept: the intersection test never hits them.
    pub fn of_mesh(mesh: &TriMesh) -> Self {
        let mut triangles: Vec<(BvhTriangle, [u32; 3])> =
            mesh.triangles().iter().map(|&tri| (BvhTriangle::of(mesh.positions(), mesh.normals(), tri), tri)).collect();
        let nodes = build_nodes(&mut triangles, LEAF_SIZE, |items| bounds(items.iter().map(|(t, _)| t)), |(t, _)| t.centroid());
        let (triangles, corners) = triangles.into_iter().unzip();
        Self { nodes, triangles, corners }
    }

    /// The same tree over the mesh's vertices moved to `positions` and `normals` (the
    /// mesh it was built from, deformed: the same vertices and triangles): each
    /// triangle read again and each node's box made again from its triangles' or its
    /// children's, children first. The CPU twin of `bvh_refit.wgsl`. The tree's shape
    /// stays, so a mesh deformed far from its build is traversed more slowly, never
    /// wrongly. An error, with nothing changed, when a vertex is missing.
    pub fn refit(&mut self, positions: &[Vec3], normals: &[Vec3]) -> Result<(), String> {
        let vertices = positions.len().min(normals.len());
        if let Some(bad) = self.corners.iter().flatten().find(|&&v| v as usize >= vertices) {
            return Err(format!("the tree reads vertex {bad}, past the {vertices} given"));
        }
        for (triangle, &corners) in self.triangles.iter_mut().zip(&self.corners) {
            *triangle = BvhTriangle::of(positions, normals, corners);
        }
        for n in (0..self.nodes.len()).rev() {
            let node = self.nodes[n];
            let (lo, hi) = if node.count > 0 {
                bounds(&self.triangles[node.first as usize..(node.first + node.count) as usize])
            } else {
                let (a, b) = (self.nodes[node.first as usize], self.nodes[node.first as usize + 1]);
                (Vec3::from_array(a.min).min(Vec3::from_array(b.min)), Vec3::from_array(a.max).max(Vec3::from_array(b.max)))
            };
            (self.nodes[n].min, self.nodes[n].max) = (lo.to_array(), hi.to_array());
        }
        Ok(())
    }

    /// The nodes by depth, root first: a level's boxes depend only on deeper levels', so
    /// the GPU's refit makes one level a dispatch, deepest first.
    pub fn levels(&self) -> Vec<Vec<u32>> {
        let mut levels: Vec<Vec<u32>> = Vec::new();
        let mut level = if self.nodes.is_empty() { Vec::new() } else { vec![0u32] };
        while !level.is_empty() {
            let next = level.iter().map(|&n| self.nodes[n as usize]).filter(|n| n.count == 0).flat_map(|n| [n.first, n.first + 1]).collect();
            levels.push(std::mem::replace(&mut level, next));
        }
        levels
    }

    /// The BVH as `triangle_bvh.wgsl` reads it: the nodes, then the triangles.
    fn gpu_bytes(&self) -> Vec<u8> {
        [bytemuck::cast_slice(&self.nodes), bytemuck::cast_slice(&self.triangles)].concat()
    }

    /// Its length in [`Self::gpu_bytes`], in `vec4`s.
    fn gpu_len(&self) -> u32 {
        (2 * self.nodes.len() + 6 * self.triangles.len()) as u32
    }

    /// The closest triangle along `origin + t·dir` with `t` in `(t_min, t_max)`: `(t,
    /// triangle, (u, v))`.
    fn closest(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, usize, Vec2)> {
        let mut closest = None;
        walk(&self.nodes, origin, dir, t_min, t_max, |i, t_far| {
            if let Some((t, uv)) = möller_trumbore(&self.triangles[i as usize], origin, dir, t_min, *t_far) {
                *t_far = t;
                closest = Some((t, i as usize, uv));
            }
        });
        closest
    }

    /// Triangle `i`'s interpolated vertex normal at `uv` and its geometric normal
    /// (counter-clockwise front), neither normalised.
    fn normals_at(&self, i: usize, uv: Vec2) -> (Vec3, Vec3) {
        let tri = &self.triangles[i];
        let n = |k: usize| Vec4::from_array(tri.normals[k]).truncate();
        let normal = n(0) * (1.0 - uv.x - uv.y) + n(1) * uv.x + n(2) * uv.y;
        (normal, (tri.corner(1) - tri.corner(0)).cross(tri.corner(2) - tri.corner(0)))
    }
}

impl GeneratorHit {
    /// A hit with the normals unit, the interpolated one replaced by the geometric one
    /// where it vanishes.
    fn new(t: f32, generator: u32, normal: Vec3, geometric: Vec3) -> Self {
        let geometric_normal = geometric.normalize_or_zero();
        let normal = normal.normalize_or_zero();
        Self { t, generator, normal: if normal == Vec3::ZERO { geometric_normal } else { normal }, geometric_normal }
    }
}

/// [`BvhInstance::ids`]`[3]`: the instance's transform mirrors (negative determinant),
/// which turns its triangles' winding and so their geometric normals.
const MIRRORED: u32 = 1;

/// A mesh's BVH placed in the world, as `triangle_bvh.wgsl` reads it (four `vec4`s):
/// the rows of its `local_from_world` affine transform (w the translation), then as
/// bits where its mesh's nodes and triangles start (in `vec4`s), its mesh index and
/// flags.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct BvhInstance {
    /// The rows of its `local_from_world` affine transform, `w` the translation.
    pub local_from_world: [[f32; 4]; 3],
    /// As bits: where its mesh's nodes start and where its triangles start (in `vec4`s),
    /// its mesh index, and flags.
    pub ids: [u32; 4],
}

impl BvhInstance {
    fn row(&self, i: usize) -> Vec4 {
        Vec4::from_array(self.local_from_world[i])
    }

    /// A world-space point in the mesh's space.
    fn point(&self, p: Vec3) -> Vec3 {
        Vec3::new(self.row(0).truncate().dot(p) + self.row(0).w, self.row(1).truncate().dot(p) + self.row(1).w, self.row(2).truncate().dot(p) + self.row(2).w)
    }

    /// A world-space direction in the mesh's space (not normalised: `t` along the ray is
    /// the same in both spaces).
    fn direction(&self, d: Vec3) -> Vec3 {
        Vec3::new(self.row(0).truncate().dot(d), self.row(1).truncate().dot(d), self.row(2).truncate().dot(d))
    }

    /// A mesh-space normal in the world: the inverse transpose of `world_from_local`.
    fn normal(&self, n: Vec3) -> Vec3 {
        self.row(0).truncate() * n.x + self.row(1).truncate() * n.y + self.row(2).truncate() * n.z
    }
}

/// Placed meshes in two levels: each distinct mesh's [`MeshBvh`] (shared, built
/// once per mesh) and a top level over the instances' world boxes, rebuilt from their
/// transforms. A mesh's triangles are never copied into the world.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstancedBvh {
    /// The distinct meshes' BVHs, in the order they lie in [`Self::gpu_meshes`].
    pub meshes: Vec<Arc<MeshBvh>>,
    /// The top level's nodes: a leaf's `first` and `count` index [`Self::instances`].
    pub top: Vec<BvhNode>,
    /// The placed meshes, in the order the top level's leaves index them.
    pub instances: Vec<BvhInstance>,
    /// Each instance's mesh in [`Self::meshes`].
    instance_meshes: Vec<usize>,
}

/// The top level's instances a leaf holds: one, so that its box is the instance's.
const TOP_LEAF_SIZE: usize = 1;

impl InstancedBvh {
    /// The placed meshes: each mesh's BVH (in its own space), its `world_from_local`
    /// and its mesh index ([`GeneratorHit::generator`]). An instance without triangles
    /// or with a transform that is not invertible hits nothing and is left out; meshes
    /// shared by [`Arc`] are laid out once.
    pub fn new(placed: impl IntoIterator<Item = (Arc<MeshBvh>, Mat4, u32)>) -> Self {
        Self::with_bounds(placed.into_iter().map(|(bvh, world_from_local, index)| (bvh, world_from_local, index, None)))
    }

    /// [`Self::new`], where an instance may bring its own box in its mesh's space for
    /// the top level instead of its BVH's root box: one that holds every shape a mesh
    /// deformed on the GPU takes, whose BVH is refit there ([`MeshBvh::refit`]).
    pub fn with_bounds(placed: impl IntoIterator<Item = (Arc<MeshBvh>, Mat4, u32, Option<(Vec3, Vec3)>)>) -> Self {
        let mut meshes: Vec<Arc<MeshBvh>> = Vec::new();
        // Each distinct mesh's place in `meshes`, by its allocation.
        let mut laid_out: std::collections::HashMap<*const MeshBvh, usize> = std::collections::HashMap::new();
        let mut placed: Vec<(BvhInstance, (Vec3, Vec3))> = placed
            .into_iter()
            .filter(|(bvh, world_from_local, ..)| !bvh.nodes.is_empty() && world_from_local.is_finite() && world_from_local.determinant() != 0.0)
            .map(|(bvh, world_from_local, index, local_bounds)| {
                let mesh = *laid_out.entry(Arc::as_ptr(&bvh)).or_insert_with(|| {
                    meshes.push(bvh.clone());
                    meshes.len() - 1
                });
                let m = world_from_local.inverse().transpose();
                let local_from_world = [m.x_axis.to_array(), m.y_axis.to_array(), m.z_axis.to_array()];
                let flags = if world_from_local.determinant() < 0.0 { MIRRORED } else { 0 };
                let root = &bvh.nodes[0];
                let (lo, hi) = local_bounds.unwrap_or((Vec3::from_array(root.min), Vec3::from_array(root.max)));
                let world = (0..8)
                    .map(|k| world_from_local.transform_point3(Vec3::new([lo.x, hi.x][k & 1], [lo.y, hi.y][k >> 1 & 1], [lo.z, hi.z][k >> 2])))
                    .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(p), b.max(p)));
                (BvhInstance { local_from_world, ids: [mesh as u32, 0, index, flags] }, world)
            })
            .collect();
        let top = build_nodes(
            &mut placed,
            TOP_LEAF_SIZE,
            |items| items.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), (_, (lo, hi))| (a.min(*lo), b.max(*hi))),
            |(_, (lo, hi))| (*lo + *hi) * 0.5,
        );
        let mut instances: Vec<BvhInstance> = placed.into_iter().map(|(instance, _)| instance).collect();
        let instance_meshes: Vec<usize> = instances.iter().map(|i| i.ids[0] as usize).collect();
        let mut bvh = Self { meshes, top, instances: Vec::new(), instance_meshes };
        let starts = bvh.gpu_mesh_starts();
        for (instance, &mesh) in instances.iter_mut().zip(&bvh.instance_meshes) {
            [instance.ids[0], instance.ids[1]] = starts[mesh];
        }
        bvh.instances = instances;
        bvh
    }

    /// Where each of [`Self::meshes`] starts in the buffer, in `vec4`s: its nodes, its
    /// triangles. They lie past the top level and the instances.
    pub fn gpu_mesh_starts(&self) -> Vec<[u32; 2]> {
        let mut start = (2 * self.top.len() + 4 * self.instance_meshes.len()) as u32;
        self.meshes
            .iter()
            .map(|m| {
                let at = [start, start + 2 * m.nodes.len() as u32];
                start += m.gpu_len();
                at
            })
            .collect()
    }

    /// Meshes in world space, each its own instance with its place in the list as
    /// its mesh index.
    pub fn of_world_meshes<'a>(meshes: impl IntoIterator<Item = &'a TriMesh>) -> Self {
        Self::new(meshes.into_iter().enumerate().map(|(k, mesh)| (Arc::new(MeshBvh::of_mesh(mesh)), Mat4::IDENTITY, k as u32)))
    }

    /// Each generator of `scene` as its own instance, its index its mesh index: the CPU
    /// twin of the caustic maps' traced paths.
    pub fn of_scene(scene: &Scene) -> Self {
        Self::of_world_meshes(scene.generators.iter().map(|g| &g.mesh))
    }

    /// Each instance's world box (the top level's leaves).
    pub fn instance_bounds(&self) -> impl Iterator<Item = (Vec3, Vec3)> + '_ {
        self.top.iter().filter(|n| n.count > 0).map(|n| (Vec3::from_array(n.min), Vec3::from_array(n.max)))
    }

    /// The top level and the instances as `triangle_bvh.wgsl` reads them, which change
    /// when an instance moves (16 zero bytes without instances: a GPU binding may not
    /// be empty).
    pub fn gpu_top(&self) -> Vec<u8> {
        let bytes = [bytemuck::cast_slice(&self.top), bytemuck::cast_slice(&self.instances)].concat();
        if bytes.is_empty() { vec![0; 16] } else { bytes }
    }

    /// The meshes' BVHs, to lie after [`Self::gpu_top`] in the same buffer; they change
    /// only with the meshes.
    pub fn gpu_meshes(&self) -> Vec<u8> {
        self.meshes.iter().flat_map(|m| m.gpu_bytes()).collect()
    }

    /// Where the instances start in the buffer, in `vec4`s: two a top node; 0 without
    /// instances, which the GPU reads as no BVH.
    pub fn gpu_instance_offset(&self) -> u32 {
        if self.instances.is_empty() { 0 } else { 2 * self.top.len() as u32 }
    }

    /// How far a traced ray starts off the surface it leaves: 2·10⁻⁵ of the instances'
    /// world extent (the tracer's offset).
    pub fn ray_offset(&self) -> f32 {
        self.top.first().map_or(2e-5, |root| {
            let (lo, hi) = (Vec3::from_array(root.min), Vec3::from_array(root.max));
            2e-5 * (hi - lo).max_element().max(lo.abs().max_element()).max(hi.abs().max_element()).max(1e-6)
        })
    }

    /// The closest hit along `origin + t·dir` with `t` in `(t_min, t_max)`, passing
    /// through the instances of mesh index `skip` ([`NO_MESH`]: none).
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, skip: u32) -> Option<GeneratorHit> {
        let mut closest: Option<(f32, usize, usize, Vec2)> = None;
        walk(&self.top, origin, dir, t_min, t_max, |k, t_far| {
            let instance = &self.instances[k as usize];
            if instance.ids[2] == skip {
                return;
            }
            let mesh = &self.meshes[self.instance_meshes[k as usize]];
            if let Some((t, i, uv)) = mesh.closest(instance.point(origin), instance.direction(dir), t_min, *t_far) {
                *t_far = t;
                closest = Some((t, k as usize, i, uv));
            }
        });
        let (t, k, i, uv) = closest?;
        let instance = &self.instances[k];
        let (normal, geometric) = self.meshes[self.instance_meshes[k]].normals_at(i, uv);
        let geometric = instance.normal(geometric) * if instance.ids[3] & MIRRORED != 0 { -1.0 } else { 1.0 };
        Some(GeneratorHit::new(t, instance.ids[2], instance.normal(normal), geometric))
    }
}

/// Walks `nodes` (a BVH laid out by [`build_nodes`]) with a stack, as
/// `triangle_bvh.wgsl` does at either level: each item of each leaf whose box the ray
/// meets within `(t_min, t_far)` goes to `item`, which may shorten `t_far` to its hit.
fn walk(nodes: &[BvhNode], origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, mut item: impl FnMut(u32, &mut f32)) {
    if nodes.is_empty() {
        return;
    }
    let inv = dir.recip();
    let mut t_far = t_max;
    let mut stack = [0u32; STACK_DEPTH];
    let mut len = 1;
    while len > 0 {
        len -= 1;
        let node = nodes[stack[len] as usize];
        if !slab(origin, inv, &node, t_min, t_far) {
            continue;
        }
        if node.count > 0 {
            for i in node.first..node.first + node.count {
                item(i, &mut t_far);
            }
        } else if len + 2 <= STACK_DEPTH {
            stack[len] = node.first;
            stack[len + 1] = node.first + 1;
            len += 2;
        }
    }
}

/// A binary BVH over `items` by median splits along the centroids' widest axis, the
/// items reordered to its leaves (`bounds` of a range, `centroid` of one). The tree's
/// shape depends only on the number of items.
fn build_nodes<T>(items: &mut [T], leaf_size: usize, bounds: impl Fn(&[T]) -> (Vec3, Vec3), centroid: impl Fn(&T) -> Vec3) -> Vec<BvhNode> {
    if items.is_empty() {
        return Vec::new();
    }
    let mut nodes = vec![BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 }];
    // Each entry: the node to fill and its item range.
    let mut pending = vec![(0usize, 0usize, items.len())];
    while let Some((node, start, end)) = pending.pop() {
        let (lo, hi) = bounds(&items[start..end]);
        nodes[node].min = lo.to_array();
        nodes[node].max = hi.to_array();
        if end - start <= leaf_size {
            nodes[node].first = start as u32;
            nodes[node].count = (end - start) as u32;
            continue;
        }
        let (clo, chi) = items[start..end].iter().map(&centroid).fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), c| (a.min(c), b.max(c)));
        let axis = (chi - clo).to_array().iter().enumerate().fold(0, |best, (i, &e)| if e > (chi - clo)[best] { i } else { best });
        let mid = (start + end) / 2;
        items[start..end].select_nth_unstable_by(mid - start, |a, b| centroid(a)[axis].total_cmp(&centroid(b)[axis]));
        let left = nodes.len();
        nodes.push(BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 });
        nodes.push(BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 });
        nodes[node].first = left as u32;
        pending.push((left, start, mid));
        pending.push((left + 1, mid, end));
    }
    nodes
}

fn bounds<'a>(triangles: impl IntoIterator<Item = &'a BvhTriangle>) -> (Vec3, Vec3) {
    triangles.into_iter().flat_map(|t| (0..3).map(|i| t.corner(i))).fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(p), b.max(p)))
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
