//! Warped caustic volumes (Ernst, Akenine-Möller & Jensen 2005) on the GPU.
//!
//! Every frame in which a generator, a light or a receiver changed, the GPU builds one
//! caustic volume per lit generator triangle and light (and per colour channel for a
//! dispersive refractor), from the generator's vertices as that frame draws them
//! (`build.wgsl`, the twin of `caustics_core::volumes::build_generator_volumes`; the
//! paper builds them on the CPU, §3), reading the vertices from the buffers Bevy draws
//! the meshes from: an animated mesh's caustics follow it in the same frame, and the
//! CPU only gathers the sources when they change (`build.rs`). An ocean evaluated on
//! the GPU is built again every frame with no CPU work at all. An unchanged scene costs
//! nothing. The volumes the build keeps are counted
//! on the GPU and drawn indirectly; what it drops (unlit, shadowed, TIR, grazing,
//! degenerate) comes back in [`CausticVolumes`]. Then, for each caustics view:
//!
//! 1. **surface pass** (between the prepass and the main pass): at each pixel a
//!    volume's bounding shape (§4.3; where the rays land on one surface, the thin
//!    slice of it around that surface) covers, the receiver point is rebuilt from the
//!    depth prepass, the exact point-in-volume test (§3.3) run and the interpolated
//!    irradiance (§3.4), times the receiver's cosine from the normal prepass, added to
//!    the view's caustic irradiance buffer; the composite then shows it on receivers.
//!    A compute pass (`splat` in `volumes.wgsl`), one invocation a volume, projects the
//!    shape, skips it off the view and lights the pixels it covers itself where it
//!    covers at most [`WarpedVolumesSettings::splat_pixels`] (each workgroup shares
//!    out the rows of its 64 shapes among its invocations; added in fixed point,
//!    then to the buffer by a fullscreen pass); the larger shapes it lists for the
//!    rasteriser, which draws each one's outline on the view, grown by a pixel,
//!    indirectly and shades the pixels the compute pass would, once each (point-sampled, only where the
//!    receiver lies in front of the shape's farthest corner: a read-only test
//!    against a single-sampled copy of the depth prepass). Both paths shade with the
//!    same function;
//!    [`CausticVolumes::surface`] counts what each did;
//! 2. **volumetric pass** (after the main pass), only for views that see a
//!    [`crate::ParticipatingMedium`] and show shafts (`Caustics::shafts`): the
//!    single-scattering term of §3.5 added to the view's HDR image. By default
//!    ([`ShaftIntegral::Grid`]) a compute pass deposits every beam once per build on a
//!    grid over each medium's box (`beam_grid.wgsl`, the twin of
//!    `caustics_core::volumes::BeamGrid`), and a fullscreen pass marches each eye ray
//!    through it in a fixed number of steps; [`ShaftIntegral::Exact`] draws the prisms
//!    again and integrates the eye ray's exact path through each warped volume. Either
//!    runs at one pixel in every `shaft_downsample`² block, into a smaller texture that
//!    a fullscreen pass then adds to the image bilinearly
//!    ([`WarpedVolumesSettings::shaft_downsample`]).
//!
//! Both read Bevy's `DepthPrepass` and `NormalPrepass`, which
//! [`crate::Caustics`] requires on the camera. The WGSL in `build.wgsl` and
//! `volumes.wgsl` mirrors `caustics_core::volumes` line by line; the GPU tests hold the
//! two together.

mod beam_grid;
mod build;
mod compute;
mod pass;
mod render;

pub use build::{CausticVolumes, SurfaceWork};

use bevy::prelude::*;
use caustics_core::volumes::{IntensityMode, VolumeSettings};

/// How the caustic volumes pass computes irradiance: a resource, shared by all views.
#[derive(Resource, Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Resource)]
pub struct WarpedVolumesSettings {
    /// How a volume's intensity varies across it (§3.2).
    pub intensity: VolumeIntensity,
    /// Upper bound of the magnification `a/A(α)` near focal points; see
    /// [`VolumeSettings::max_magnification`].
    pub max_magnification: f32,
    /// Light shafts are integrated at the centre of every `shaft_downsample`² block of
    /// the view's pixels and upsampled bilinearly onto it (1, 2 or 4; others round
    /// down to one of these). The default, 4, shades one pixel in sixteen: shafts are
    /// smooth, and on the ocean example the image stays within 0.009 (relative L2) of
    /// every pixel's own, for a volumetric pass eleven times cheaper. 1 integrates every
    /// pixel.
    pub shaft_downsample: u32,
    /// How the shafts are integrated along each eye ray.
    pub shaft_integral: ShaftIntegral,
    /// [`ShaftIntegral::Grid`]'s cells along the longest side of each medium's box
    /// (fewer along the others, so that cells are about cubes): 96 by default, 32 bytes
    /// a cell (28 MiB for a cube). Finer grids keep narrower beams sharp.
    pub shaft_grid: u32,
    /// [`ShaftIntegral::Grid`]'s most steps along the part of each eye ray inside a
    /// medium, which it marches one step a cell (256 by default).
    pub shaft_steps: u32,
    /// The surface pass lights a volume whose bounding shape projects onto at most
    /// this many pixels (its area, not its box: a thin sliver across the view stays)
    /// in a compute pass, each workgroup sharing out the rows of pixels its 64 volumes'
    /// shapes cover, and rasterises the larger ones (4096, a 64 × 64 square, by default; 0
    /// rasterises every volume). A rasteriser shades a small shape
    /// in whole blocks of pixels (2 × 2 on most GPUs, 4 × 4 on lavapipe), most of them
    /// outside it, and a fine generator makes many small shapes.
    pub splat_pixels: u32,
    /// Whether each pixel shows the mean of the caustic light over its footprint on
    /// the receiver (the default) or the point sample at its centre; see
    /// [`VolumeSettings::footprint_filter`]; both paths filter.
    pub footprint_filter: bool,
}

/// How the volumetric pass integrates the light scattered out of the caustic beams.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum ShaftIntegral {
    /// Every beam deposited once per build on a grid over each medium's box, each
    /// eye ray marched through it one step a cell: a cost per pixel that does not
    /// grow with the volumes an eye ray crosses (the default). At the default 96
    /// cells, pixel means within 1.7 % (relative L2) of [`Self::Exact`]'s on the ocean
    /// example's shafts and 3.6 % on the disco ball's (`crates/caustics_core/tests/shafts.rs`).
    #[default]
    Grid,
    /// The exact integral through every volume the eye ray crosses (§3.5): each
    /// volume's bounding shape drawn, its cost growing with the volumes in view.
    Exact,
}

impl Default for WarpedVolumesSettings {
    fn default() -> Self {
        let core = VolumeSettings::default();
        Self {
            intensity: VolumeIntensity::Conserving,
            max_magnification: core.max_magnification,
            shaft_downsample: 4,
            shaft_integral: ShaftIntegral::Grid,
            shaft_grid: 96,
            shaft_steps: 256,
            splat_pixels: 4096,
            footprint_filter: core.footprint_filter,
        }
    }
}

/// [`IntensityMode`] for the ECS: how irradiance varies inside a caustic triangle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum VolumeIntensity {
    /// Smooth and energy-conserving (the default).
    #[default]
    Conserving,
    /// The paper's §3.4 formula.
    Interpolated,
    /// One value per caustic triangle.
    Constant,
}

/// The shafts: `Low` marches a 64-cell grid at one pixel in sixteen, `High` a
/// 128-cell grid at one pixel in four. The surface caustics are the same at every
/// preset: their accuracy is the generator's tessellation.
impl crate::QualityPreset for WarpedVolumesSettings {
    fn set_quality(&mut self, quality: crate::CausticQuality) {
        self.shaft_downsample = quality.pick([4, 4, 2]);
        self.shaft_grid = quality.pick([64, 96, 128]);
        self.shaft_steps = quality.pick([192, 256, 384]);
    }
}

impl WarpedVolumesSettings {
    /// The pixels a shaft sample stands for, across: [`Self::shaft_downsample`] as 1, 2 or 4.
    pub fn shaft_scale(&self) -> u32 {
        match self.shaft_downsample {
            0..=1 => 1,
            2..=3 => 2,
            _ => 4,
        }
    }

    /// The core crate's settings.
    pub fn core(&self) -> VolumeSettings {
        let intensity = match self.intensity {
            VolumeIntensity::Conserving => IntensityMode::Conserving,
            VolumeIntensity::Interpolated => IntensityMode::Interpolated,
            VolumeIntensity::Constant => IntensityMode::Constant,
        };
        VolumeSettings { intensity, max_magnification: self.max_magnification, footprint_filter: self.footprint_filter, ..VolumeSettings::default() }
    }
}

pub(crate) fn build(app: &mut App) {
    bevy::asset::embedded_asset!(app, "volumes.wgsl");
    bevy::asset::embedded_asset!(app, "upsample.wgsl");
    bevy::asset::embedded_asset!(app, "receiver_depth.wgsl");
    bevy::asset::embedded_asset!(app, "splat_resolve.wgsl");
    bevy::asset::embedded_asset!(app, "build.wgsl");
    bevy::asset::embedded_asset!(app, "beam_grid.wgsl");
    bevy::shader::load_shader_library!(app, "types.wgsl");
    app.register_type::<WarpedVolumesSettings>().init_resource::<WarpedVolumesSettings>();
    crate::quality::build::<WarpedVolumesSettings>(app);
    crate::mesh_vertices::build(app);
    build::build(app);
    render::build(app);
}
