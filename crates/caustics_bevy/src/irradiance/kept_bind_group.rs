//! Bind groups and uniforms kept across frames. A pass that binds the same buffers and
//! views frame after frame (their contents rewritten in place) makes its bind group
//! once, and again only when one of them is replaced: creating a bind group is a driver
//! call and validation on the render thread, every frame, for every pass. A uniform is
//! uploaded only when its value changed: each upload is a staging buffer and a copy. A
//! bind group layout is fetched from the pipeline cache once: each fetch clones, hashes
//! and looks up its descriptor under a lock.

use bevy::ecs::entity::Entity;
use bevy::platform::collections::HashMap;
use bevy::render::render_resource::encase::internal::WriteInto;
use bevy::render::render_resource::{
    BindGroup, BindGroupLayout, BindGroupLayoutDescriptor, BindGroupLayoutId, Buffer, BufferId, PipelineCache, ShaderType, TextureView, TextureViewId,
    UniformBuffer,
};
use bevy::render::renderer::{RenderDevice, RenderQueue};
use std::sync::OnceLock;

/// What a bind group binds, by identity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bound {
    /// A bind group layout.
    Layout(BindGroupLayoutId),
    /// A whole buffer.
    Buffer(BufferId),
    /// Part of a buffer: its offset and size in bytes.
    Slice(BufferId, u64, u64),
    /// A texture view.
    View(TextureViewId),
}

impl From<&BindGroupLayout> for Bound {
    fn from(layout: &BindGroupLayout) -> Self {
        Self::Layout(layout.id())
    }
}

impl From<&Buffer> for Bound {
    fn from(buffer: &Buffer) -> Self {
        Self::Buffer(buffer.id())
    }
}

impl From<&TextureView> for Bound {
    fn from(view: &TextureView) -> Self {
        Self::View(view.id())
    }
}

/// A bind group and what it was made from.
#[derive(Clone, Default)]
pub struct KeptBindGroup {
    bound: Vec<Bound>,
    bind_group: Option<BindGroup>,
}

impl KeptBindGroup {
    /// The bind group of `bound` (its layout and every buffer and view, in any fixed
    /// order): the one kept if it binds the same, else `make`'s.
    pub fn get(&mut self, bound: &[Bound], make: impl FnOnce() -> BindGroup) -> BindGroup {
        match &self.bind_group {
            Some(bind_group) if self.bound == bound => bind_group.clone(),
            _ => {
                let bind_group = make();
                self.bound = bound.to_vec();
                self.bind_group = Some(bind_group.clone());
                bind_group
            }
        }
    }

    /// The bind group last made or kept, if any.
    pub fn current(&self) -> Option<&BindGroup> {
        self.bind_group.as_ref()
    }
}

/// One source's bind group for each view it is projected into (a light view's, a
/// pool's, a light's planes'), kept with the source, so that it goes with the source's
/// buffers; a view that no longer exists is forgotten.
#[derive(Default)]
pub struct ViewBindGroups(HashMap<Entity, KeptBindGroup>);

impl ViewBindGroups {
    /// The bind group of `bound` for `view`, as [`KeptBindGroup::get`]; first forgets
    /// the views for which `exists` is false.
    pub fn get(&mut self, view: Entity, exists: impl Fn(Entity) -> bool, bound: &[Bound], make: impl FnOnce() -> BindGroup) -> BindGroup {
        self.0.retain(|&kept, _| kept == view || exists(kept));
        self.0.entry(view).or_default().get(bound, make)
    }
}

/// Sets `buffer` to `value` and uploads it, unless the buffer already holds it.
/// Whether it uploaded.
pub fn write_changed<T: ShaderType + WriteInto + PartialEq>(buffer: &mut UniformBuffer<T>, value: T, device: &RenderDevice, queue: &RenderQueue) -> bool {
    let changed = buffer.buffer().is_none() || *buffer.get() != value;
    if changed {
        buffer.set(value);
        buffer.write_buffer(device, queue);
    }
    changed
}

/// A bind group layout's descriptor, which pipelines name it by, and the layout itself,
/// fetched from the pipeline cache on first use and kept (the cache never drops one).
pub struct KeptLayout {
    /// What pipeline descriptors list.
    pub descriptor: BindGroupLayoutDescriptor,
    layout: OnceLock<BindGroupLayout>,
}

impl KeptLayout {
    /// The layout of `descriptor`, not fetched yet.
    pub fn new(descriptor: BindGroupLayoutDescriptor) -> Self {
        Self { descriptor, layout: OnceLock::new() }
    }

    /// The layout, from `cache` the first time.
    pub fn get(&self, cache: &PipelineCache) -> &BindGroupLayout {
        self.layout.get_or_init(|| cache.get_bind_group_layout(&self.descriptor))
    }
}
