//! Render world: a mesh's vertices where Bevy keeps them for drawing, read and written
//! by compute passes. The plugin adds `STORAGE` to the usages of Bevy's mesh vertex
//! buffers (`MeshAllocatorSettings::extra_buffer_usages`, as Bevy's wireframe plugin
//! does), so that the caustic volumes' build reads a generator's positions and normals
//! as this frame draws them, with no copy through the CPU, and an ocean evaluated on the
//! GPU writes its waves straight into the mesh every material draws.

use bevy::mesh::{MeshVertexAttribute, VertexFormat};
use bevy::prelude::*;
use bevy::render::{
    mesh::{RenderMesh, allocator::MeshAllocator},
    render_asset::RenderAssets,
    render_resource::{Buffer, BufferBinding},
    renderer::RenderDevice,
};
use std::num::NonZeroU64;

pub(crate) use crate::read_scene::MovesOnGpu;

/// In the `RenderGraph` schedule, before the cameras: the compute passes that write
/// meshes' vertices. Passes that read them run after it.
#[derive(SystemSet, Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) struct WriteMeshVertices;

/// Lets compute passes bind Bevy's mesh vertex buffers as storage, and orders the
/// passes that write them.
pub(crate) fn build(app: &mut App) {
    if let Some(render_app) = app.get_sub_app_mut(bevy::render::RenderApp) {
        let mut settings = render_app.world_mut().get_resource_or_init::<bevy::render::mesh::allocator::MeshAllocatorSettings>();
        settings.extra_buffer_usages |= bevy::render::render_resource::BufferUsages::STORAGE;
        render_app.configure_sets(
            bevy::render::renderer::RenderGraph,
            WriteMeshVertices.in_set(bevy::render::renderer::RenderGraphSystems::Render).before(bevy::core_pipeline::schedule::camera_driver),
        );
    }
}

/// A mesh's vertices in its vertex buffer, as a storage binding of `f32` words: the
/// part of the buffer that holds them (from an offset the device accepts), and, in
/// words from the binding's start, `layout` = (first vertex, vertex stride, position
/// within a vertex, normal within a vertex).
pub(crate) struct MeshVertices {
    pub buffer: Buffer,
    pub offset: u64,
    pub size: NonZeroU64,
    pub layout: UVec4,
    pub count: u32,
}

impl MeshVertices {
    /// The vertices of mesh `id` as uploaded this frame, when it has `Float32x3`
    /// positions and normals and fits one storage binding; `None` otherwise (not
    /// uploaded yet, another vertex format, or too large).
    pub fn of(id: AssetId<Mesh>, meshes: &RenderAssets<RenderMesh>, allocator: &MeshAllocator, device: &RenderDevice) -> Option<Self> {
        let mesh = meshes.get(id)?;
        let slice = allocator.mesh_vertex_slice(&id)?;
        let layout = mesh.layout.0.layout();
        let word = |attribute: MeshVertexAttribute| {
            let at = mesh.layout.0.attribute_ids().iter().position(|&a| a == attribute.id)?;
            let attribute = layout.attributes.get(at)?;
            (attribute.format == VertexFormat::Float32x3 && attribute.offset % 4 == 0).then_some((attribute.offset / 4) as u32)
        };
        let (position, normal) = (word(Mesh::ATTRIBUTE_POSITION)?, word(Mesh::ATTRIBUTE_NORMAL)?);
        let stride = layout.array_stride;
        if stride % 4 != 0 {
            return None;
        }
        let limits = device.limits();
        let start = u64::from(slice.range.start) * stride;
        let offset = start - start % u64::from(limits.min_storage_buffer_offset_alignment);
        let size = u64::from(slice.range.end) * stride - offset;
        if size > limits.max_storage_buffer_binding_size {
            return None;
        }
        Some(Self {
            buffer: slice.buffer.clone(),
            offset,
            size: NonZeroU64::new(size)?,
            layout: UVec4::new(((start - offset) / 4) as u32, (stride / 4) as u32, position, normal),
            count: slice.range.end - slice.range.start,
        })
    }

    /// What the binding binds, for a kept bind group.
    #[cfg(any(feature = "warped-volumes", feature = "convolution"))]
    pub fn bound(&self) -> crate::irradiance::kept_bind_group::Bound {
        crate::irradiance::kept_bind_group::Bound::Slice(self.buffer.id(), self.offset, self.size.get())
    }

    /// The storage binding of the vertices.
    pub fn binding(&self) -> BufferBinding<'_> {
        BufferBinding { buffer: &self.buffer, offset: self.offset, size: Some(self.size) }
    }
}
