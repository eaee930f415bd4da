//! The components a game adds: what makes caustics, what shows them, and the medium
//! light scatters in. Every value is checked when it is added or changed; an invalid
//! entity is reported once and skipped by every pass until it is fixed.

use bevy::camera::visibility::{self, VisibilityClass};
use bevy::prelude::*;
use caustics_core::optics::CauchyDispersion;
use caustics_core::params::{MediumCoefficients, ParamError, SpecularInteraction};

/// Caustics in this camera's view: the opt-in, as `Bloom`, `VolumetricFog` and
/// `ScreenSpaceAmbientOcclusion` are for Bevy's own effects. Only cameras with it get
/// caustics work; a minimap, portal or render-to-texture camera without it costs
/// nothing and is left as the game made it. It requires what the passes need: `Hdr`
/// (caustics are linear light, added before tonemapping) and the depth and normal
/// prepasses (receiver points and normals are read from them).
///
/// Per view is what a view shows of the caustics. How they are made stays shared —
/// [`crate::warped_volumes::WarpedVolumesSettings`] and
/// [`crate::hierarchical_maps::HierarchicalMapsSettings`] are resources, `PoolRipples`
/// a component of the pool — because volumes, photon maps and pool floors are built
/// once a frame per generator and light, in world space, for every view alike.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default)]
#[require(bevy::camera::Hdr, bevy::core_pipeline::prepass::DepthPrepass, bevy::core_pipeline::prepass::NormalPrepass)]
pub struct Caustics {
    /// Scales the caustic light this view shows, on receivers and in shafts: 1 is
    /// physical, 0 shows none. Negative or NaN reads as 0.
    pub intensity: f32,
    /// Light shafts: the caustic beams scattered towards the eye in a
    /// [`ParticipatingMedium`] (the volumetric pass, which this view skips when off).
    pub shafts: bool,
}

impl Default for Caustics {
    fn default() -> Self {
        Self { intensity: 1.0, shafts: true }
    }
}

impl Caustics {
    /// The intensity the passes apply: [`Self::intensity`] where it is a finite
    /// non-negative number, 0 otherwise.
    pub fn applied_intensity(&self) -> f32 {
        if self.intensity.is_finite() && self.intensity > 0.0 { self.intensity } else { 0.0 }
    }
}

/// Which published technique renders a generator's caustics.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum CausticTechnique {
    /// The plugin picks one from the generator and the scene.
    #[default]
    Auto,
    /// Ernst, Akenine-Möller & Jensen 2005: a caustic volume per generator triangle.
    WarpedVolumes,
    /// Iwasaki et al.: illumination textures on virtual planes around a receiver.
    IlluminationTextures,
    /// Trendall & Stewart 2000: pool-floor irradiance as convolutions of a heightfield.
    Convolution,
    /// Wyman 2008: hierarchical caustic maps from a photon buffer per light.
    HierarchicalMaps,
}

/// How a generator surface redirects light.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
pub enum GeneratorInteraction {
    /// A perfect mirror.
    Reflect,
    /// A dielectric boundary: air outside (the side the normals face), index `ior` inside.
    Refract {
        /// Index of refraction inside (≥ 1): water 1.333, glass 1.5, diamond 2.42.
        ior: f32,
        /// Cauchy coefficients `(A, B µm²)`; when set, the IOR varies per colour channel.
        dispersion: Option<Vec2>,
    },
}

/// A specular mesh that reflects or refracts light into caustics. Put it on an
/// entity with a `Mesh3d`; the mesh is read in world space every frame it changes.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component)]
pub struct CausticGenerator {
    /// Whether it reflects or refracts, and how much of the light it carries.
    pub interaction: GeneratorInteraction,
    /// The technique that draws its caustics; `Auto` (the default) picks by what the generator is ([`crate::CausticTechniqueChoice`] says which and why).
    pub technique: CausticTechnique,
    /// Whether an open surface reflects or refracts on its back too, like
    /// `StandardMaterial::double_sided` and glTF's `doubleSided` (which the glTF
    /// tagging copies here). `false`, the default, absorbs the light that reaches its
    /// back: a one-sided mirror is dark from behind. A closed mesh ignores it: light
    /// leaves a glass ball through its faces' backs ([`caustics_core::scene::Sides`]).
    pub double_sided: bool,
}

impl CausticGenerator {
    /// A one-sided mirror.
    pub fn mirror() -> Self {
        Self { interaction: GeneratorInteraction::Reflect, technique: CausticTechnique::Auto, double_sided: false }
    }

    /// A one-sided refracting surface of index `ior`, without dispersion.
    pub fn refractive(ior: f32) -> Self {
        Self { interaction: GeneratorInteraction::Refract { ior, dispersion: None }, technique: CausticTechnique::Auto, double_sided: false }
    }

    /// The interaction as the core algorithms see it.
    pub fn specular_interaction(&self) -> SpecularInteraction {
        match self.interaction {
            GeneratorInteraction::Reflect => SpecularInteraction::Reflect,
            GeneratorInteraction::Refract { ior, dispersion } => {
                SpecularInteraction::Refract { ior, dispersion: dispersion.map(|d| CauchyDispersion { a: d.x, b: d.y }) }
            }
        }
    }
}

/// A diffuse surface that shows caustics: its `StandardMaterial` albedo (base colour
/// times base-colour texture) multiplies the caustic irradiance that lands on it.
/// Surfaces without it never receive caustic light, but still block it.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default)]
#[require(VisibilityClass)]
#[component(on_add = visibility::add_visibility_class::<CausticReceiver>)]
pub struct CausticReceiver;

/// A homogeneous participating medium in which caustic light scatters into visible
/// shafts (Ernst et al. 2005 §3.5), with physical coefficients: σₛ and σₐ per metre
/// (σₐ per linear RGB channel, which colours what is seen through it) and a
/// Henyey–Greenstein phase. It brings a Bevy `FogVolume` of the same box and
/// coefficients ([`crate::medium_fog`]), so that Bevy's volumetric fog dims what is
/// seen through it and scatters the direct light of shadow-mapped suns, while the
/// plugin scatters the light the generators focus.
///
/// The medium fills the unit cube `[-½, ½]³` of its entity's transform (as a
/// `FogVolume` does): scale the transform to the water body or the room.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component)]
#[require(Transform, Visibility)]
pub struct ParticipatingMedium {
    /// Scattering coefficient σₛ (1/m).
    pub scattering: f32,
    /// Absorption coefficient σₐ per linear RGB channel (1/m): `Vec3::splat` for a grey
    /// medium; [`Self::WATER_ABSORPTION`] for clear water.
    pub absorption: Vec3,
    /// Henyey–Greenstein asymmetry g ∈ (−1, 1): > 0 scatters forwards.
    pub asymmetry: f32,
}

impl ParticipatingMedium {
    /// Roughly pure water's absorption at the red, green and blue primaries (about 620,
    /// 540 and 465 nm; Pope and Fry 1997), per metre: red is gone after a few metres,
    /// blue carries on, which is why deep clear water is blue-green.
    pub const WATER_ABSORPTION: Vec3 = Vec3::new(0.28, 0.045, 0.01);

    /// The coefficients as the core algorithms see them.
    pub fn coefficients(&self) -> MediumCoefficients {
        MediumCoefficients { scattering: self.scattering, absorption: self.absorption, asymmetry: self.asymmetry }
    }
}

/// Marks an entity whose caustics parameters are invalid; the message says why. Passes
/// skip it. It is removed as soon as the parameters are fixed.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct InvalidCausticParams(pub ParamError);

/// Entities whose generator or medium was added or changed since the last check.
type ParamsChanged = Or<(Changed<CausticGenerator>, Changed<ParticipatingMedium>)>;

/// Whether [`validate_caustic_params`] has anything to check this frame: a generator
/// or medium added, changed or removed.
pub(crate) fn params_may_change(
    changed: Query<(), ParamsChanged>,
    mut removed_generators: RemovedComponents<CausticGenerator>,
    mut removed_media: RemovedComponents<ParticipatingMedium>,
) -> bool {
    let removed = removed_generators.read().count() + removed_media.read().count() > 0;
    removed || !changed.is_empty()
}

/// Checks generators and media when they are added, changed or removed, per entity (a
/// water body may be both): an invalid one gets [`InvalidCausticParams`] and one
/// warning; a fixed one, or one that no longer has either component, loses the marker.
pub fn validate_caustic_params(
    mut commands: Commands,
    changed: Query<Entity, ParamsChanged>,
    mut removed_generators: RemovedComponents<CausticGenerator>,
    mut removed_media: RemovedComponents<ParticipatingMedium>,
    params: Query<(Option<&CausticGenerator>, Option<&ParticipatingMedium>, Option<&InvalidCausticParams>)>,
) {
    let candidates: bevy::platform::collections::HashSet<Entity> = changed.iter().chain(removed_generators.read()).chain(removed_media.read()).collect();
    for entity in candidates {
        let Ok((generator, medium, marker)) = params.get(entity) else { continue };
        let error = generator
            .and_then(|g| g.specular_interaction().validate().err().map(|e| ("CausticGenerator", e)))
            .or_else(|| medium.and_then(|m| m.coefficients().validate().err().map(|e| ("ParticipatingMedium", e))));
        match (error, marker) {
            (Some((kind, err)), previous) if previous.map(|p| &p.0) != Some(&err) => {
                warn!("bevy_caustics: {kind} on {entity} is skipped: {err}");
                commands.entity(entity).insert(InvalidCausticParams(err));
            }
            (None, Some(_)) => {
                commands.entity(entity).remove::<InvalidCausticParams>();
            }
            _ => {}
        }
    }
}
