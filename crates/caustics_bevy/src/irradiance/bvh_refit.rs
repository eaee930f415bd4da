//! Render world: the BVHs of meshes deformed on the GPU ([`crate::mesh_vertices::MovesOnGpu`]:
//! an ocean's waves, a pool's ripples), refit there each frame to the vertices the frame
//! draws (`bvh_refit.wgsl`, the twin of `MeshBvh::refit`), inside the
//! [`super::mesh_bvhs::InstancedBvhBuffer`] that holds them. The tree's shape is the one
//! built on the mesh asset; its top level holds the instance by the entity's `Aabb`,
//! which bounds every shape the surface takes. Nothing goes through the CPU.

use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::kept_bind_group::{Bound, KeptBindGroup, KeptLayout};
use crate::mesh_vertices::MeshVertices;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::{
    mesh::{RenderMesh, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_resource::{
        binding_types::{storage_buffer_read_only_sized, storage_buffer_sized, uniform_buffer},
        *,
    },
    renderer::{RenderDevice, RenderQueue},
};
use caustics_core::triangle_bvh::{InstancedBvh, MeshBvh};
use std::sync::Arc;

/// `RefitJob` in `bvh_refit.wgsl`: one mesh's triangles, or one level of its nodes.
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
struct GpuRefitJob {
    at: UVec4,
    level: UVec4,
    vertex: UVec4,
}

/// The refit's kernels (triangles, nodes, and the empty `anchor` of
/// [`anchor_first_timestamp`]) and their layout.
pub(crate) struct BvhRefitPipelines {
    layout: KeptLayout,
    pipelines: [CachedComputePipelineId; 3],
}

impl BvhRefitPipelines {
    pub fn new(cache: &PipelineCache, asset_server: &AssetServer) -> Self {
        let read = || storage_buffer_read_only_sized(false, None);
        let layout = BindGroupLayoutDescriptor::new(
            "caustic_bvh_refit_layout",
            &BindGroupLayoutEntries::sequential(
                ShaderStages::COMPUTE,
                (uniform_buffer::<GpuRefitJob>(true), read(), read(), read(), storage_buffer_sized(false, None)),
            ),
        );
        let shader = bevy::asset::load_embedded_asset!(asset_server, "bvh_refit.wgsl");
        Self {
            pipelines: super::compute_pipelines(cache, "caustic_bvh", &layout, &shader, ["refit_triangles", "refit_nodes", "anchor"]),
            layout: KeptLayout::new(layout),
        }
    }
}

/// One deformed mesh's buffers, made when its BVH is new: its triangles' vertices and
/// its nodes level by level, deepest first.
struct RefitMesh {
    bvh: Arc<MeshBvh>,
    corners: Buffer,
    levels: Buffer,
    /// Each level's first node in `levels` and its nodes, deepest first.
    spans: Vec<(u32, u32)>,
    /// The vertices its triangles read.
    vertices: u32,
    bind_group: KeptBindGroup,
}

impl RefitMesh {
    fn new(bvh: &Arc<MeshBvh>, device: &RenderDevice) -> Self {
        let storage = |label, words: &[u32]| {
            let contents: &[u8] = if words.is_empty() { &[0; 4] } else { bytemuck::cast_slice(words) };
            device.create_buffer_with_data(&BufferInitDescriptor { label: Some(label), contents, usage: BufferUsages::STORAGE })
        };
        let mut spans = Vec::new();
        let mut order = Vec::new();
        for level in bvh.levels().into_iter().rev() {
            spans.push((order.len() as u32, level.len() as u32));
            order.extend(level);
        }
        Self {
            corners: storage("caustic_bvh_refit_corners", bytemuck::cast_slice(&bvh.corners)),
            levels: storage("caustic_bvh_refit_levels", &order),
            spans,
            vertices: bvh.corners.iter().flatten().max().map_or(0, |&v| v + 1),
            bvh: bvh.clone(),
            bind_group: KeptBindGroup::default(),
        }
    }
}

/// A mesh's dispatches this frame: its bind group, then the triangles' job offset and
/// count and each level's, deepest first.
struct RefitDispatch {
    bind_group: BindGroup,
    triangles: (u32, u32),
    levels: Vec<(u32, u32)>,
}

/// The refit of an [`InstancedBvh`]'s deformed meshes, kept across frames.
#[derive(Default)]
pub(crate) struct BvhRefit {
    meshes: HashMap<AssetId<Mesh>, RefitMesh>,
    jobs: DynamicUniformBuffer<GpuRefitJob>,
    /// What `jobs` holds, and each one's offset.
    written: (Vec<GpuRefitJob>, Vec<u32>),
    dispatches: Vec<RefitDispatch>,
}

/// What reading meshes' vertices in Bevy's buffers takes.
pub(crate) type DrawnMeshes<'a> = (&'a RenderAssets<RenderMesh>, &'a MeshAllocator, &'a RenderDevice, &'a RenderQueue);

impl BvhRefit {
    /// Plans this frame's refit of `moving` (meshes deformed on the GPU, with their
    /// BVHs) where they lie in `buffer`, which holds `bvh`. A mesh that `bvh` does not
    /// hold, or whose vertices Bevy has not uploaded in a form a compute pass reads,
    /// keeps its tree as it stands.
    pub fn prepare(
        &mut self,
        bvh: &InstancedBvh,
        buffer: &Buffer,
        moving: &[(AssetId<Mesh>, Arc<MeshBvh>)],
        pipelines: &BvhRefitPipelines,
        (meshes, allocator, device, queue): DrawnMeshes,
        cache: &PipelineCache,
    ) {
        self.meshes.retain(|id, kept| moving.iter().any(|(m, b)| m == id && Arc::ptr_eq(b, &kept.bvh)));
        self.dispatches.clear();
        let starts = bvh.gpu_mesh_starts();
        let layout = pipelines.layout.get(cache);
        let mut jobs = Vec::new();
        let mut planned = Vec::new();
        for (id, mesh_bvh) in moving {
            let (Some(k), Some(vertices)) = (bvh.meshes.iter().position(|m| Arc::ptr_eq(m, mesh_bvh)), MeshVertices::of(*id, meshes, allocator, device)) else {
                continue;
            };
            let mesh = self.meshes.entry(*id).or_insert_with(|| RefitMesh::new(mesh_bvh, device));
            if vertices.count < mesh.vertices {
                continue;
            }
            let [nodes, triangles] = starts[k];
            let at = UVec4::new(nodes, triangles, mesh_bvh.triangles.len() as u32, 0);
            let first = jobs.len();
            jobs.push(GpuRefitJob { at, level: UVec4::ZERO, vertex: vertices.layout });
            jobs.extend(mesh.spans.iter().map(|&(start, count)| GpuRefitJob { at, level: UVec4::new(start, count, 0, 0), vertex: vertices.layout }));
            planned.push((*id, first, vertices));
        }
        if planned.is_empty() {
            return;
        }
        if self.jobs.buffer().is_none() || self.written.0 != jobs {
            self.jobs.clear();
            let offsets = jobs.iter().map(|job| self.jobs.push(job)).collect();
            self.jobs.set_label(Some("caustic_bvh_refit_jobs"));
            self.jobs.write_buffer(device, queue);
            self.written = (jobs, offsets);
        }
        let (Some(binding), Some(jobs_buffer)) = (self.jobs.binding(), self.jobs.buffer()) else { return };
        for (id, first, vertices) in planned {
            let Some(mesh) = self.meshes.get_mut(&id) else { continue };
            let bound: [Bound; 6] = [layout.into(), jobs_buffer.into(), vertices.bound(), (&mesh.corners).into(), (&mesh.levels).into(), buffer.into()];
            let (corners, levels) = (&mesh.corners, &mesh.levels);
            let bind_group = mesh.bind_group.get(&bound, || {
                device.create_bind_group(
                    "caustic_bvh_refit_bind_group",
                    layout,
                    &BindGroupEntries::sequential((
                        binding.clone(),
                        BindingResource::Buffer(vertices.binding()),
                        corners.as_entire_binding(),
                        levels.as_entire_binding(),
                        buffer.as_entire_binding(),
                    )),
                )
            });
            let offset = |j: usize| self.written.1[j];
            self.dispatches.push(RefitDispatch {
                bind_group,
                triangles: (offset(first), self.written.0[first].at.z),
                levels: mesh.spans.iter().enumerate().map(|(l, &(_, count))| (offset(first + 1 + l), count)).collect(),
            });
        }
    }

    /// Whether a refit is planned this frame.
    pub fn is_planned(&self) -> bool {
        !self.dispatches.is_empty()
    }

    /// The planned refit in `pass`: each mesh's triangles, then its levels, deepest first
    /// (after [`anchor_first_timestamp`] while timestamps are `recording`).
    pub fn dispatch(&mut self, pass: &mut ComputePass, pipelines: &BvhRefitPipelines, cache: &PipelineCache, recording: bool) {
        let [triangles, nodes, anchor] = pipelines.pipelines.map(|id| cache.get_compute_pipeline(id));
        let (Some(triangles), Some(nodes), Some(first)) = (triangles, nodes, self.dispatches.first()) else {
            return;
        };
        pass.set_bind_group(0, &first.bind_group, &[first.triangles.0]);
        anchor_first_timestamp(pass, recording, anchor);
        for dispatch in self.dispatches.drain(..) {
            pass.set_bind_group(0, &dispatch.bind_group, &[dispatch.triangles.0]);
            pass.set_pipeline(triangles);
            pass.dispatch_workgroups(dispatch.triangles.1.div_ceil(64), 1, 1);
            pass.set_pipeline(nodes);
            for (offset, count) in dispatch.levels {
                pass.set_bind_group(0, &dispatch.bind_group, &[offset]);
                pass.dispatch_workgroups(count.div_ceil(64), 1, 1);
            }
        }
    }
}
