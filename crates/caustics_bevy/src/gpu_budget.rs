//! What the plugin may ask of the GPU: the adapter's limits and a memory budget. A
//! request beyond either — a photon buffer or caustic maps too fine, a pool too large,
//! illumination textures too many or too fine, more caustic volumes than a buffer
//! binds — is lowered until it fits, with one warning saying to what; never a wgpu
//! validation error or a failed allocation.

use bevy::prelude::*;
use bevy::render::extract_resource::ExtractResource;
use bevy::render::renderer::RenderDevice;

/// The most GPU memory (bytes) one request of the plugin may take: the caustic maps'
/// photon buffer, maps and their pyramid; all the lights' illumination textures; one
/// pool's texel buffers and kernels; the caustic volumes' buffer. Each is lowered to
/// fit it as it is to fit the adapter's limits. Default: 1 GiB.
#[derive(Resource, ExtractResource, Reflect, Clone, Copy, Debug, PartialEq, Eq)]
#[reflect(Resource)]
pub struct CausticGpuBudget {
    /// The most bytes the plugin's GPU buffers and textures may take together.
    pub bytes: u64,
}

impl Default for CausticGpuBudget {
    fn default() -> Self {
        Self { bytes: 1 << 30 }
    }
}

/// The most bytes one storage binding may hold on `device`: its storage binding and
/// buffer size limits.
pub fn largest_binding(device: &RenderDevice) -> u64 {
    let limits = device.limits();
    limits.max_storage_buffer_binding_size.min(limits.max_buffer_size)
}

/// `bytes` in MiB, for warnings.
#[cfg(any(feature = "warped-volumes", feature = "convolution", feature = "illumination-textures", feature = "hierarchical-maps"))]
pub(crate) fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
}
