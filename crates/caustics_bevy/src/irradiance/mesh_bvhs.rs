//! The rays the plugin casts through the scene's triangles (the caustic maps' traced
//! paths, the caustic volumes' shadow and hit rays) go through one structure in two
//! levels (`caustics_core::triangle_bvh`): a [`MeshBvh`] per mesh asset, built the first
//! time a technique places that mesh and again only when the asset changes, and an
//! [`InstancedBvh`] over the placed meshes, rebuilt from their transforms when one
//! moves. A mesh that moves costs its instance's transform, not its triangles.

use crate::read_scene::core_mesh;
use bevy::camera::primitives::Aabb;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::render_resource::{Buffer, BufferInitDescriptor, BufferUsages};
use bevy::render::renderer::{RenderDevice, RenderQueue};
use caustics_core::triangle_bvh::{InstancedBvh, MeshBvh};
use std::sync::Arc;

/// Main world: each placed mesh asset's [`MeshBvh`] in its own space, by asset. A mesh
/// that is malformed (see [`core_mesh`]) has none and hits nothing.
#[derive(Resource, Default)]
pub struct MeshBvhs(HashMap<AssetId<Mesh>, Option<Arc<MeshBvh>>>);

impl MeshBvhs {
    /// The BVH of `mesh`, built now if it is loaded and was not built since it last
    /// changed; `None` while it is not loaded or if it is malformed.
    pub fn get(&mut self, mesh: AssetId<Mesh>, meshes: &Assets<Mesh>) -> Option<Arc<MeshBvh>> {
        if let Some(built) = self.0.get(&mesh) {
            return built.clone();
        }
        let built = core_mesh(meshes.get(mesh)?, &GlobalTransform::IDENTITY).ok().map(|m| Arc::new(MeshBvh::of_mesh(&m)));
        self.0.insert(mesh, built.clone());
        built
    }

    /// The instances `placed` (mesh, `world_from_local`, mesh index, and for a mesh
    /// deformed on the GPU the entity's `Aabb`, which holds every shape it takes) over
    /// their meshes' BVHs; a mesh not loaded or malformed is left out.
    pub fn place(&mut self, placed: impl IntoIterator<Item = (AssetId<Mesh>, Mat4, u32, Option<Aabb>)>, meshes: &Assets<Mesh>) -> InstancedBvh {
        let placed: Vec<_> = placed
            .into_iter()
            .filter_map(|(mesh, at, index, aabb)| Some((self.get(mesh, meshes)?, at, index, aabb.map(|a| (Vec3::from(a.min()), Vec3::from(a.max()))))))
            .collect();
        InstancedBvh::with_bounds(placed)
    }
}

/// Drops the BVHs of meshes that changed or went away, before anything places them.
pub(super) fn forget_changed_meshes(mut events: MessageReader<AssetEvent<Mesh>>, mut bvhs: ResMut<MeshBvhs>) {
    for event in events.read() {
        let (AssetEvent::Added { id }
        | AssetEvent::Modified { id }
        | AssetEvent::Removed { id }
        | AssetEvent::Unused { id }
        | AssetEvent::LoadedWithDependencies { id }) = event;
        bvhs.0.remove(id);
    }
}

/// Render world: an [`InstancedBvh`] in a storage buffer as `triangle_bvh.wgsl` reads
/// it. The meshes' BVHs are uploaded when they change; when only the instances moved,
/// their top level is written over the buffer's start.
#[derive(Default)]
pub struct InstancedBvhBuffer {
    buffer: Option<Buffer>,
    meshes: Vec<Arc<MeshBvh>>,
    top_bytes: usize,
}

impl InstancedBvhBuffer {
    /// The buffer holding `bvh`, written as little as it needs.
    pub fn write(&mut self, bvh: &InstancedBvh, label: &'static str, device: &RenderDevice, queue: &RenderQueue) -> Buffer {
        let top = bvh.gpu_top();
        let same_meshes = self.meshes.len() == bvh.meshes.len() && self.meshes.iter().zip(&bvh.meshes).all(|(a, b)| Arc::ptr_eq(a, b));
        match &self.buffer {
            Some(buffer) if same_meshes && top.len() == self.top_bytes => {
                queue.write_buffer(buffer, 0, &top);
                buffer.clone()
            }
            _ => {
                let contents = [top.as_slice(), &bvh.gpu_meshes()].concat();
                let buffer = device.create_buffer_with_data(&BufferInitDescriptor {
                    label: Some(label),
                    contents: &contents,
                    usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
                });
                (self.meshes, self.top_bytes) = (bvh.meshes.clone(), top.len());
                self.buffer = Some(buffer.clone());
                buffer
            }
        }
    }

    /// Its size in bytes (0 before the first write).
    pub fn size(&self) -> u64 {
        self.buffer.as_ref().map_or(0, |b| b.size())
    }
}
