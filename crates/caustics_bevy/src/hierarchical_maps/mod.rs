//! Hierarchical caustic maps (Wyman 2008) on the GPU.
//!
//! For every light that shines on a [`crate::CausticGenerator`] asking for
//! [`crate::CausticTechnique::HierarchicalMaps`], the main world plans the light's views
//! (`caustics_core::hierarchical::LightView`: one orthographic view of a directional
//! light across the scene, one perspective view of a spot, the cube faces of a point
//! light that see a generator). When anything they depend on changes — a light, a
//! generator or an occluder moved, a mesh was rewritten, the settings — the render
//! world redraws, once per frame and per light view:
//!
//! 1. **light maps**: the generators' nearest front faces and farthest back faces, and
//!    the receivers' nearest surfaces (every visible mesh that is not a generator and
//!    casts shadows, and every [`crate::CausticReceiver`]) rasterised from the light
//!    with Bevy's own meshes;
//! 2. **photon buffer**: a compute pass traces each texel's photon through the
//!    generator in image space (both faces of a closed refractor), or through the
//!    generators' triangles, onto the receivers; with Fresnel branches, stages 2–4 run
//!    again for each into the same map;
//! 3. **gather**: the validity pyramid, then the breadth-first traversal (§3.1) with
//!    indirect dispatches and compaction, clustering converging photons (§3.2), or the
//!    flat gather of every photon;
//! 4. **splats** into a multi-resolution caustic map (§3.3) with 64-bit fixed-point
//!    atomics, resolved by eq. 3.
//!
//! An unchanged scene keeps its maps and costs one projection per view and light view:
//! between the prepass and the main pass, each view's receiver points look the maps up
//! like shadow maps and add the irradiance to the view's caustic irradiance buffer,
//! which the composite shows on receivers. Every shader is the twin of a function in
//! `caustics_core::hierarchical`; `tests/gpu_hierarchical.rs` holds the two together.
//!
//! Limits, as in the paper: caustics land only on surfaces the light itself sees (the
//! caustic map is a light-space image); image-space refraction sees one entry and one
//! exit per photon (the nearest front face and the farthest back face), so several
//! refractors one behind the other from a light are not followed in turn; photons that
//! are totally internally reflected are dropped and counted.

mod pass;
mod plan;
mod render;

pub use plan::{CausticMapInstance, CausticMapPlan, PlannedLightView};
pub use render::{COUNTERS_PER_VIEW, CausticMapsGpu, MAX_GENERATORS, PROCESSED_COUNTER};

use bevy::prelude::*;
use caustics_core::hierarchical::{CausticMapSettings, Clustering, Gather, LevelOverflow, PhotonPaths, Splats};

/// How the caustic maps are made: a resource, shared by every light view. The presets
/// are the paper's comparison (§5): [`Self::FLAT`], [`Self::HIERARCHICAL`] and
/// [`Self::FULL`]; the default, [`Self::TRACED`], is the full method with photons
/// traced through the generators.
#[derive(Resource, Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Resource)]
pub struct HierarchicalMapsSettings {
    /// Photon buffer side per light view (a power of two, 16 to 4096).
    pub photon_resolution: u32,
    /// Caustic map side (a power of two, 16 to 4096). A point light's cube face that
    /// the scene extends past spreads its maps over four times its own image (they
    /// reach 63°, `caustics_core::hierarchical::light_view::CUBE_FACE_REACH`), so the
    /// plugin then draws every view's maps at twice this side (at most 4096;
    /// `CausticMapSettings::for_views`), four times the memory.
    pub map_resolution: u32,
    /// How the maps gather photons onto the receivers (§3.2).
    pub gather: CausticMapGather,
    /// Splat sizes from photon divergence into a multi-resolution map (§3.3); off:
    /// fixed splats of `fixed_splat_diameter` texels.
    pub variable_splats: bool,
    /// The splats' diameter in caustic-map texels when `variable_splats` is off.
    pub fixed_splat_diameter: f32,
    /// The caustic map's top level for variable splats (the paper: 3).
    pub top_splat_level: u32,
    /// Drop variable splats too wide for the top level, as the paper does, instead of
    /// clamping them into it (which keeps their energy; the bench measures the loss).
    pub drop_splats_above_top_level: bool,
    /// Refinements of each photon's exit point from a closed refractor (image space).
    pub exit_iterations: u32,
    /// Photons traced through the generators' triangles (past the paper: every
    /// interface of a concave body, light from one generator onto another) instead of
    /// the image-space pair of front and back maps (Wyman 2005).
    pub traced_paths: bool,
    /// Fresnel-reflected branches traced paths follow beside the transmitted light
    /// (past the paper, at most 3): each traces, gathers and splats one more photon
    /// buffer into the same map. Branch `k` takes the reflection at a photon's `k`-th
    /// refraction: 1 carries what glass throws back off its first face.
    pub fresnel_branches: u32,
}

/// How the photon buffer is gathered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Reflect)]
pub enum CausticMapGather {
    /// Every photon of the buffer (the baseline).
    Flat,
    /// The pyramid traversal (§3.1), without clustering.
    Hierarchical,
    /// The traversal, clustering converging photons at the last level (§3.2).
    ClusterLastLevel,
    /// The traversal, clustering at every level.
    ClusterAllLevels,
}

impl HierarchicalMapsSettings {
    /// Every photon processed, fixed splats.
    pub const FLAT: Self = Self {
        photon_resolution: 1024,
        map_resolution: 1024,
        gather: CausticMapGather::Flat,
        variable_splats: false,
        fixed_splat_diameter: 3.0,
        top_splat_level: 3,
        drop_splats_above_top_level: false,
        exit_iterations: 4,
        traced_paths: false,
        fresnel_branches: 0,
    };
    /// The traversal, fixed splats: the same map as [`Self::FLAT`], from fewer photons processed.
    pub const HIERARCHICAL: Self = Self { gather: CausticMapGather::Hierarchical, ..Self::FLAT };
    /// The traversal with clustering at the last level and variable splats.
    pub const FULL: Self = Self { gather: CausticMapGather::ClusterLastLevel, variable_splats: true, ..Self::FLAT };
    /// [`Self::FULL`] with photons traced through the generators' triangles (past the
    /// paper): right through concave glass and from one generator onto another, where
    /// the image-space pair sees one entry and the farthest exit, and the light glass
    /// reflects off its first face as one Fresnel branch (docs/choosing-a-technique.md, "Choosing a
    /// technique", has the measurements).
    pub const TRACED: Self = Self { traced_paths: true, fresnel_branches: 1, ..Self::FULL };

    /// The core crate's settings.
    pub fn core(&self) -> CausticMapSettings {
        let gather = match self.gather {
            CausticMapGather::Flat => Gather::Flat,
            CausticMapGather::Hierarchical => Gather::Hierarchical { clustering: Clustering::Off },
            CausticMapGather::ClusterLastLevel => Gather::Hierarchical { clustering: Clustering::LastLevel },
            CausticMapGather::ClusterAllLevels => Gather::Hierarchical { clustering: Clustering::AllLevels },
        };
        let splats = if self.variable_splats {
            let overflow = if self.drop_splats_above_top_level { LevelOverflow::Discard } else { LevelOverflow::Clamp };
            Splats::Variable { max_level: self.top_splat_level, overflow }
        } else {
            Splats::Fixed { diameter: self.fixed_splat_diameter }
        };
        CausticMapSettings {
            photon_resolution: self.photon_resolution,
            map_resolution: self.map_resolution,
            gather,
            splats,
            exit_iterations: self.exit_iterations,
            paths: if self.traced_paths { PhotonPaths::Traced } else { PhotonPaths::ImageSpace },
            fresnel_branches: self.fresnel_branches,
        }
    }
}

/// The photon buffer and the caustic maps at 512², 1024² or 2048² a light view; `Low`
/// follows no Fresnel-reflected branch.
impl crate::QualityPreset for HierarchicalMapsSettings {
    fn set_quality(&mut self, quality: crate::CausticQuality) {
        let side = quality.pick([512, 1024, 2048]);
        (self.photon_resolution, self.map_resolution) = (side, side);
        self.fresnel_branches = quality.pick([0, Self::TRACED.fresnel_branches, Self::TRACED.fresnel_branches]);
    }
}

impl Default for HierarchicalMapsSettings {
    fn default() -> Self {
        Self::TRACED
    }
}

pub(crate) fn build(app: &mut App) {
    bevy::shader::load_shader_library!(app, "types.wgsl");
    bevy::asset::embedded_asset!(app, "maps.wgsl");
    bevy::asset::embedded_asset!(app, "caustic_map.wgsl");
    bevy::asset::embedded_asset!(app, "project.wgsl");
    app.register_type::<HierarchicalMapsSettings>().init_resource::<HierarchicalMapsSettings>();
    crate::quality::build::<HierarchicalMapsSettings>(app);
    plan::build(app);
    render::build(app);
}
