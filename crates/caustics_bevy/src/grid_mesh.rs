//! Grid meshes that animated surfaces (the ocean, the pool) rewrite in place every
//! frame: Bevy re-uploads a `Mesh` asset written through `Assets::get_mut` and
//! recomputes the entity's `Aabb`, and the caustic techniques see the asset change.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;

/// Whether `mesh` has a grid's shape: a triangle list with `index_count` indices and
/// `vertex_count` float positions, its data in the main world.
pub(crate) fn is_grid(mesh: &Mesh, index_count: usize, vertex_count: usize) -> bool {
    mesh.primitive_topology() == PrimitiveTopology::TriangleList
        && mesh.try_indices().is_ok_and(|indices| indices.len() == index_count)
        && matches!(mesh.try_attribute(Mesh::ATTRIBUTE_POSITION), Ok(VertexAttributeValues::Float32x3(p)) if p.len() == vertex_count)
}

/// Rewrites the `count` positions and normals of `mesh` if it has the grid's shape
/// ([`is_grid`]; the normals are added where it has none of that size); false, with
/// nothing changed, if not.
pub(crate) fn rewrite_grid(
    mesh: &mut Mesh,
    (index_count, count): (usize, usize),
    positions: impl Iterator<Item = [f32; 3]>,
    normals: impl Iterator<Item = [f32; 3]>,
) -> bool {
    if !is_grid(mesh, index_count, count) {
        return false;
    }
    if let Ok(VertexAttributeValues::Float32x3(slots)) = mesh.try_attribute_mut(Mesh::ATTRIBUTE_POSITION) {
        for (slot, position) in slots.iter_mut().zip(positions) {
            *slot = position;
        }
    }
    match mesh.try_attribute_mut(Mesh::ATTRIBUTE_NORMAL) {
        Ok(VertexAttributeValues::Float32x3(slots)) if slots.len() == count => {
            for (slot, normal) in slots.iter_mut().zip(normals) {
                *slot = normal;
            }
            true
        }
        // The data is in the main world (the positions were), so this cannot fail.
        _ => mesh.try_insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals.collect::<Vec<_>>()).is_ok(),
    }
}

/// A new grid mesh: positions, normals, UVs and triangle-list indices.
pub(crate) fn grid_mesh(positions: Vec<[f32; 3]>, normals: Vec<[f32; 3]>, uvs: Vec<[f32; 2]>, indices: Vec<u32>) -> Mesh {
    Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
        .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
        .with_inserted_indices(Indices::U32(indices))
}
