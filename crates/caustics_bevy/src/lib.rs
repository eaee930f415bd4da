//! # bevy_caustics — the Bevy side
//!
//! Components ([`CausticGenerator`], [`CausticReceiver`], [`ParticipatingMedium`]),
//! the per-view caustic irradiance buffer and its composite onto receivers, a pass
//! report and glTF tagging. Tools live behind features: `reference` (the ground-truth
//! tracer as a caustics source, and the live comparison against it), `headless` (a
//! renderer without a window for tests and tools). The math lives in `caustics_core`; this crate is a thin layer
//! of components, systems and passes.
//!
//! Every buffer and texture the plugin makes is labelled `caustic_…`, so that a GPU
//! capture or wgpu's allocator report (`headless::HeadlessRenderer::gpu_memory`) tells
//! its memory from Bevy's; what it asks of the GPU is bounded by the adapter's limits
//! and [`CausticGpuBudget`].
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]

#[cfg(feature = "reference")]
pub mod comparison;
pub mod components;
#[cfg(feature = "convolution")]
pub mod convolution;
pub mod cpu_time;
#[cfg(feature = "egui")]
pub mod debug_panel;
pub mod gltf_tagging;
pub mod gpu_budget;
pub mod gpu_work;
#[cfg(any(feature = "ocean", feature = "convolution"))]
mod grid_mesh;
#[cfg(feature = "headless")]
pub mod headless;
#[cfg(feature = "hierarchical-maps")]
pub mod hierarchical_maps;
#[cfg(feature = "illumination-textures")]
pub mod illumination_textures;
pub mod irradiance;
pub mod lights;
pub mod medium_fog;
#[cfg(any(feature = "ocean", feature = "warped-volumes", feature = "convolution"))]
mod mesh_vertices;
#[cfg(feature = "ocean")]
pub mod ocean;
pub mod pixels;
pub mod quality;
pub mod read_scene;
#[cfg(feature = "reference")]
pub mod reference;
pub mod report;
pub mod technique;
#[cfg(feature = "warped-volumes")]
pub mod warped_volumes;

pub use components::{CausticGenerator, CausticReceiver, CausticTechnique, Caustics, GeneratorInteraction, InvalidCausticParams, ParticipatingMedium};
#[cfg(feature = "convolution")]
pub use convolution::{DropPebble, PoolImpulses, PoolRipples};
pub use cpu_time::CausticCpuTime;
pub use gltf_tagging::TagCausticsFromMaterials;
pub use gpu_budget::CausticGpuBudget;
pub use irradiance::{CAUSTIC_IRRADIANCE_FORMAT, CausticReceiverMaterialPlugin, InjectedIrradiance};
#[cfg(feature = "ocean")]
pub use ocean::Ocean;
pub use quality::{CausticQuality, QualityPreset};
pub use report::CausticPassReport;
pub use technique::{AvailableCausticTechniques, CausticTechniqueChoice};

use bevy::prelude::*;
use cpu_time::timed;

/// Where the plugin's main-world systems run.
#[derive(SystemSet, Clone, Debug, PartialEq, Eq, Hash)]
pub enum CausticSystems {
    /// In `PostUpdate`: systems that read the placed scene — after transforms are
    /// propagated, bounds computed, visibility inherited and parameters validated.
    ReadScene,
}

/// Adds caustics to the views of cameras with [`Caustics`]. Passes run only for
/// views and scenes that need them: a scene without generators (and without injected
/// irradiance) does no caustics work at all — see [`CausticPassReport`].
#[derive(Default)]
pub struct CausticsPlugin;

impl Plugin for CausticsPlugin {
    fn build(&self, app: &mut App) {
        let cpu = CausticCpuTime::of(app).main;
        app.register_type::<CausticGenerator>()
            .register_type::<CausticReceiver>()
            .register_type::<Caustics>()
            .register_type::<ParticipatingMedium>()
            .register_type::<TagCausticsFromMaterials>()
            .register_type::<CausticGpuBudget>()
            .register_type::<CausticQuality>()
            .init_resource::<CausticGpuBudget>()
            .add_plugins(bevy::render::extract_resource::ExtractResourcePlugin::<CausticGpuBudget>::default())
            .add_systems(Update, timed(&cpu, gltf_tagging::tag_from_materials))
            .add_systems(
                PostUpdate,
                (
                    timed(&cpu, components::validate_caustic_params).run_if(timed(&cpu, components::params_may_change)),
                    timed(&cpu, lights::warn_unsupported_lights),
                ),
            )
            .configure_sets(
                PostUpdate,
                CausticSystems::ReadScene
                    .after(bevy::transform::TransformSystems::Propagate)
                    .after(bevy::camera::visibility::VisibilitySystems::CalculateBounds)
                    .after(bevy::camera::visibility::VisibilitySystems::VisibilityPropagate)
                    .after(components::validate_caustic_params),
            )
            .init_resource::<read_scene::ChangedParts>()
            .add_systems(PostUpdate, timed(&cpu, read_scene::read_scene_changes).in_set(CausticSystems::ReadScene));
        technique::build(app);
        report::build(app);
        irradiance::build(app);
        medium_fog::build(app);
        #[cfg(feature = "reference")]
        comparison::build(app);
        #[cfg(feature = "warped-volumes")]
        warped_volumes::build(app);
        #[cfg(feature = "ocean")]
        app.add_plugins(ocean::OceanPlugin);
        #[cfg(feature = "convolution")]
        convolution::build(app);
        #[cfg(feature = "hierarchical-maps")]
        hierarchical_maps::build(app);
        #[cfg(feature = "illumination-textures")]
        illumination_textures::build(app);
    }
}

/// Everything a game needs: `use caustics_bevy::prelude::*`.
pub mod prelude {
    #[cfg(feature = "ocean")]
    pub use crate::Ocean;
    #[cfg(feature = "hierarchical-maps")]
    pub use crate::hierarchical_maps::{CausticMapGather, HierarchicalMapsSettings};
    #[cfg(feature = "illumination-textures")]
    pub use crate::illumination_textures::{IlluminationCosine, IlluminationTexturesSettings};
    #[cfg(feature = "warped-volumes")]
    pub use crate::warped_volumes::{ShaftIntegral, VolumeIntensity, WarpedVolumesSettings};
    pub use crate::{
        AvailableCausticTechniques, CausticGenerator, CausticGpuBudget, CausticPassReport, CausticQuality, CausticReceiver, CausticReceiverMaterialPlugin,
        CausticTechnique, CausticTechniqueChoice, Caustics, CausticsPlugin, GeneratorInteraction, InjectedIrradiance, ParticipatingMedium, QualityPreset,
        TagCausticsFromMaterials,
    };
    #[cfg(feature = "convolution")]
    pub use crate::{DropPebble, PoolRipples};
}
