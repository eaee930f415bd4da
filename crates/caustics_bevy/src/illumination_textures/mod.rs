//! Illumination textures (Iwasaki, Dobashi, Yoshimoto & Nishita) on the GPU.
//!
//! For every [`crate::CausticGenerator`] that is a closed refractor drawn with
//! [`crate::CausticTechnique::IlluminationTextures`] (or that `Auto` gives them to),
//! the main world keeps one light transport table per mesh, index of refraction and
//! scale (`caustics_core::illumination_textures::LightTransportTable`, §3): built once
//! on the async compute pool, or read from the disk cache, and never again while the
//! object moves or turns or the light moves — [`LightTransportTables`] counts the
//! builds. When the object, a light or a receiver changed, the main world looks each
//! lit vertex up in its table and places each light's virtual camera (§4.2,
//! `IlluminationTextures::placed`): the illumination volumes, the camera's axis and
//! texture rectangle over the receivers — every visible [`crate::CausticReceiver`] and
//! shadow-casting mesh that is not a generator, placed over their meshes' BVHs
//! (`crate::irradiance::mesh_bvhs`). Then the render world:
//!
//! 1. **illumination textures** (once per change): the virtual camera casts a ray a
//!    texel through the receivers (`seen.wgsl`) into a depth map of solid spans, and
//!    the planes span the depths it saw; each volume's crossing with each plane is
//!    drawn into that plane's layer of an `Rgba16Float` texture array, with additive
//!    blending and each fragment's exact share of its texel (eq. 3 in `w`, the light
//!    vector in `xyz`);
//! 2. **projection** (every frame, between the prepass and the main pass): each view's
//!    receiver points take the two planes around their depth (§4.3), the cosine at
//!    their own normal from the view's normal prepass, and no light where the light,
//!    followed back through the depth map, crosses a receiver surface: caustics and
//!    shadows from the same pass. The irradiance goes into the view's caustic
//!    irradiance buffer like every other technique's.
//!
//! The shaders are the twins of `caustics_core::illumination_textures`;
//! `tests/gpu_illumination_textures.rs` holds them together. Limits: a dispersive
//! generator is drawn at its green index of refraction; light reflected inside the
//! object is left out (as the paper leaves it); a moving object costs the CPU the
//! lookup of its lit vertices in its table, a few operations a vertex.

mod build;
mod pass;
mod render;

pub use build::{IlluminationFrames, LightTransportTables};
pub use render::IlluminationTexturesGpu;

use bevy::prelude::*;
use caustics_core::illumination_textures::{Cosine, DirectionGrid, IlluminationSettings};
use std::path::PathBuf;

/// The most virtual planes a light's textures have.
pub const MAX_PLANES: u32 = 16;

/// Bytes a texel of the virtual camera's depth map takes (`seen.wgsl`): three `vec4`s,
/// (normal, depth) then the solid spans' (in, out) pairs.
const SURFACE_TEXEL_BYTES: u64 = 48;

/// How the illumination textures are made: a resource, shared by every generator.
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource)]
pub struct IlluminationTexturesSettings {
    /// Virtual planes per light, 1 to [`MAX_PLANES`] (the paper: 4).
    pub planes: u32,
    /// Texels along a side of each plane's texture, 16 to 4096 (the paper: 512).
    pub texture_size: u32,
    /// Directions along a side of each vertex's grid in the light transport table
    /// (`DirectionGrid`), 2 to 64.
    pub table_directions: u32,
    /// The most bytes one table may take: a mesh whose table at `table_directions`
    /// would not fit gets a coarser grid, with a warning saying which.
    pub max_table_bytes: usize,
    /// How the planes' texels weigh the light they receive.
    pub cosine: IlluminationCosine,
    /// Where tables are cached between runs, by their mesh's content; `None`: not
    /// cached.
    #[reflect(ignore)]
    pub cache_dir: Option<PathBuf>,
}

/// The planes' textures at 256², 512² or 1024² texels (the paper's four planes each).
impl crate::QualityPreset for IlluminationTexturesSettings {
    fn set_quality(&mut self, quality: crate::CausticQuality) {
        self.texture_size = quality.pick([256, 512, 1024]);
    }
}

impl Default for IlluminationTexturesSettings {
    /// The paper's 4 planes of 512², the table's 16² directions a vertex, at most
    /// 64 MB a table, cached in the system's temporary directory.
    fn default() -> Self {
        let core = IlluminationSettings::default();
        Self {
            planes: core.planes,
            texture_size: core.texture_size,
            table_directions: DirectionGrid::default().side(),
            max_table_bytes: 64 << 20,
            cosine: IlluminationCosine::default(),
            cache_dir: Some(std::env::temp_dir().join("bevy_caustics").join("light_transport")),
        }
    }
}

impl IlluminationTexturesSettings {
    /// The core crate's settings, or why these cannot be used.
    pub fn core(&self) -> Result<IlluminationSettings, String> {
        if !(1..=MAX_PLANES).contains(&self.planes) {
            return Err(format!("planes is {}, not 1 to {MAX_PLANES}", self.planes));
        }
        if !(16..=4096).contains(&self.texture_size) {
            return Err(format!("texture_size is {}, not 16 to 4096", self.texture_size));
        }
        if !(2..=64).contains(&self.table_directions) {
            return Err(format!("table_directions is {}, not 2 to 64", self.table_directions));
        }
        Ok(IlluminationSettings { planes: self.planes, texture_size: self.texture_size })
    }
}

/// [`Cosine`] for the ECS: which cosine turns the light crossing a texel into
/// irradiance on a receiver.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum IlluminationCosine {
    /// At each pixel's own normal (the default; past the paper, measured better).
    #[default]
    Receiver,
    /// The paper's per-texel `cos γ` from the virtual camera's normal map (eq. 3).
    VirtualCamera,
}

impl IlluminationCosine {
    /// The core crate's form.
    pub fn core(self) -> Cosine {
        match self {
            IlluminationCosine::Receiver => Cosine::Receiver,
            IlluminationCosine::VirtualCamera => Cosine::VirtualCamera,
        }
    }
}

pub(crate) fn build(app: &mut App) {
    bevy::shader::load_shader_library!(app, "types.wgsl");
    bevy::asset::embedded_asset!(app, "seen.wgsl");
    bevy::asset::embedded_asset!(app, "draw.wgsl");
    bevy::asset::embedded_asset!(app, "project.wgsl");
    app.register_type::<IlluminationTexturesSettings>().init_resource::<IlluminationTexturesSettings>();
    crate::quality::build::<IlluminationTexturesSettings>(app);
    build::build(app);
    render::build(app);
}
