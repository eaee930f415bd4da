//! Main world: the technique each generator gets. [`choose_techniques`] reads what a
//! generator is — mirror, rippling pool, ocean, closed or open refractor (its mesh
//! welded and checked for holes once per mesh asset), inside a participating medium or
//! not — and applies `caustics_core::technique`'s table. The result is a
//! [`CausticTechniqueChoice`] on the generator, which is all the techniques' own
//! systems read: a generator draws with exactly one technique, and never with none
//! without a warning.

use crate::components::{CausticGenerator, CausticTechnique, InvalidCausticParams, ParticipatingMedium};
use crate::read_scene::{GeneratorChanged, core_mesh, world_aabb};
use bevy::camera::primitives::Aabb;
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::Sides;
use caustics_core::technique::{GeneratorFacts, GeneratorShape, Technique, TechniqueChoice, choose};
use std::fmt;

/// The technique a generator draws with and why (`closed refractor → hierarchical
/// maps`), kept up to date by the plugin. Read it to see what `Auto` decided; its
/// `Display` gives the reason, and the techniques passed over and why.
#[derive(Component, Clone, Debug, PartialEq, Eq)]
pub struct CausticTechniqueChoice(TechniqueChoice);

impl CausticTechniqueChoice {
    /// The technique drawing the generator (never `Auto`).
    pub fn technique(&self) -> CausticTechnique {
        self.0.technique.into()
    }

    /// Whether the generator asked for this technique itself, rather than `Auto`
    /// picking it.
    pub fn requested(&self) -> bool {
        self.0.requested
    }

    /// What the choice read of the generator: its shape, sides, medium.
    #[cfg(any(feature = "warped-volumes", feature = "hierarchical-maps"))]
    pub(crate) fn facts(&self) -> &GeneratorFacts {
        &self.0.facts
    }
}

impl fmt::Display for CausticTechniqueChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

/// The techniques this app draws with: those compiled in (a cargo feature each), less
/// any the app takes out at run time — a game may drop the caustic maps on hardware
/// too slow for them. A generator that asks for a technique not listed gets `Auto`'s
/// choice among the rest, with a warning.
#[derive(Resource, Clone, Debug, PartialEq, Eq)]
pub struct AvailableCausticTechniques(pub HashSet<CausticTechnique>);

impl Default for AvailableCausticTechniques {
    /// Every technique this build contains.
    fn default() -> Self {
        let compiled = [
            (CausticTechnique::WarpedVolumes, cfg!(feature = "warped-volumes")),
            (CausticTechnique::Convolution, cfg!(feature = "convolution")),
            (CausticTechnique::HierarchicalMaps, cfg!(feature = "hierarchical-maps")),
            (CausticTechnique::IlluminationTextures, cfg!(feature = "illumination-textures")),
        ];
        Self(compiled.into_iter().filter_map(|(t, on)| on.then_some(t)).collect())
    }
}

impl CausticTechnique {
    /// `Auto`, then every technique.
    pub const ALL: [CausticTechnique; 5] = [
        CausticTechnique::Auto,
        CausticTechnique::WarpedVolumes,
        CausticTechnique::IlluminationTextures,
        CausticTechnique::Convolution,
        CausticTechnique::HierarchicalMaps,
    ];

    /// `Auto`, or the technique's name (`warped volumes`).
    pub fn label(self) -> &'static str {
        self.requested().map_or("Auto", Technique::label)
    }

    /// The technique asked for; `None` for `Auto`.
    pub(crate) fn requested(self) -> Option<Technique> {
        match self {
            CausticTechnique::Auto => None,
            CausticTechnique::WarpedVolumes => Some(Technique::WarpedVolumes),
            CausticTechnique::IlluminationTextures => Some(Technique::IlluminationTextures),
            CausticTechnique::Convolution => Some(Technique::Convolution),
            CausticTechnique::HierarchicalMaps => Some(Technique::HierarchicalMaps),
        }
    }
}

impl From<Technique> for CausticTechnique {
    fn from(technique: Technique) -> Self {
        match technique {
            Technique::WarpedVolumes => CausticTechnique::WarpedVolumes,
            Technique::IlluminationTextures => CausticTechnique::IlluminationTextures,
            Technique::Convolution => CausticTechnique::Convolution,
            Technique::HierarchicalMaps => CausticTechnique::HierarchicalMaps,
        }
    }
}

pub(crate) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).main;
    app.init_resource::<AvailableCausticTechniques>().add_systems(
        PostUpdate,
        crate::cpu_time::timed(&cpu, choose_techniques)
            .run_if(crate::cpu_time::timed(&cpu, choices_may_change))
            .after(crate::components::validate_caustic_params)
            .after(bevy::transform::TransformSystems::Propagate)
            .after(bevy::camera::visibility::VisibilitySystems::CalculateBounds)
            .before(crate::CausticSystems::ReadScene),
    );
}

/// What the choice reads of a generator entity. The pool and ocean markers are open
/// surfaces by construction (their meshes change every frame and are never welded).
type GeneratorQuery<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        &'static CausticGenerator,
        &'static Mesh3d,
        &'static GlobalTransform,
        Option<&'static Aabb>,
        Has<InvalidCausticParams>,
        Has<PoolMarker>,
        Has<OceanMarker>,
        Option<&'static CausticTechniqueChoice>,
    ),
>;

#[cfg(feature = "convolution")]
type PoolMarker = crate::PoolRipples;
#[cfg(not(feature = "convolution"))]
type PoolMarker = NeverPresent;
#[cfg(feature = "ocean")]
type OceanMarker = crate::Ocean;
#[cfg(not(feature = "ocean"))]
type OceanMarker = NeverPresent;

/// Stands in for a marker whose feature is off; never inserted.
#[cfg(any(not(feature = "convolution"), not(feature = "ocean")))]
#[derive(Component)]
pub struct NeverPresent;

/// Generators whose choice may differ from last frame's: changed as the techniques
/// read them ([`GeneratorChanged`]), given new bounds, found invalid, made a pool or an
/// ocean.
type ChangedGenerators =
    (With<CausticGenerator>, Or<(GeneratorChanged, Changed<Aabb>, Changed<InvalidCausticParams>, Changed<PoolMarker>, Changed<OceanMarker>)>);

/// Media that may have moved a generator in or out of one.
type ChangedMedia = (With<ParticipatingMedium>, Or<(Changed<ParticipatingMedium>, Changed<GlobalTransform>, Changed<InheritedVisibility>)>);

/// What was taken from an entity since the last frame that a choice reads.
type Removals<'w, 's> = (
    RemovedComponents<'w, 's, CausticGenerator>,
    RemovedComponents<'w, 's, CausticTechniqueChoice>,
    RemovedComponents<'w, 's, InvalidCausticParams>,
    RemovedComponents<'w, 's, ParticipatingMedium>,
    RemovedComponents<'w, 's, PoolMarker>,
    RemovedComponents<'w, 's, OceanMarker>,
);

/// Whether [`choose_techniques`] may choose differently this frame: anything it reads
/// changed, went, or is a mesh event (a mesh loaded, modified or removed). A scene
/// that holds still spends nothing on the choice.
fn choices_may_change(
    generators: Query<(), ChangedGenerators>,
    media: Query<(), ChangedMedia>,
    mut removed: Removals,
    mut mesh_events: MessageReader<AssetEvent<Mesh>>,
    available: Res<AvailableCausticTechniques>,
) -> bool {
    let (a, b, c, d, e, f) = &mut removed;
    let removed = a.read().count() + b.read().count() + c.read().count() + d.read().count() + e.read().count() + f.read().count() > 0;
    let meshes = mesh_events.read().count() > 0;
    removed || meshes || available.is_changed() || !generators.is_empty() || !media.is_empty()
}

/// The valid participating media, for whether a generator lies in one.
type Media<'w, 's> = Query<'w, 's, (&'static GlobalTransform, &'static InheritedVisibility), (With<ParticipatingMedium>, Without<InvalidCausticParams>)>;

/// Gives every valid generator a [`CausticTechniqueChoice`], updated when what it reads
/// changes (closedness is kept per mesh asset until the asset changes); warns once per
/// new choice that passed over the technique a generator asked for, or that found
/// nothing to draw with.
#[allow(clippy::too_many_arguments)]
pub fn choose_techniques(
    mut commands: Commands,
    generators: GeneratorQuery<'_, '_>,
    media: Media,
    mut removed: RemovedComponents<CausticGenerator>,
    mut mesh_events: MessageReader<AssetEvent<Mesh>>,
    meshes: Res<Assets<Mesh>>,
    available: Res<AvailableCausticTechniques>,
    mut closed: Local<HashMap<AssetId<Mesh>, bool>>,
    mut silent: Local<HashSet<Entity>>,
) {
    for event in mesh_events.read() {
        if let AssetEvent::Modified { id } | AssetEvent::Removed { id } = event {
            closed.remove(id);
        }
    }
    for entity in removed.read() {
        silent.remove(&entity);
        if let Ok(mut e) = commands.get_entity(entity) {
            e.try_remove::<CausticTechniqueChoice>();
        }
    }
    // Unit cubes of the media, as world bounds.
    let media: Vec<(Vec3, Vec3)> =
        media.iter().filter(|(_, visible)| visible.get()).map(|(t, _)| world_aabb(t, &Aabb::from_min_max(Vec3::splat(-0.5), Vec3::splat(0.5)))).collect();
    let mut facts = Vec::new();
    for (entity, generator, mesh3d, transform, aabb, invalid, pool, ocean, current) in &generators {
        if invalid {
            if current.is_some() {
                commands.entity(entity).remove::<CausticTechniqueChoice>();
            }
            continue;
        }
        let is_closed = if pool || ocean {
            false
        } else {
            let id = mesh3d.id();
            match closed.get(&id) {
                Some(&c) => c,
                None => {
                    // Not loaded yet: no choice, no work, until it is.
                    let Some(mesh) = meshes.get(id) else { continue };
                    // A malformed mesh counts as open: the volumes then report it.
                    let c = core_mesh(mesh, &GlobalTransform::IDENTITY).is_ok_and(|m| m.is_closed());
                    closed.insert(id, c);
                    c
                }
            }
        };
        let shape = match generator.specular_interaction() {
            SpecularInteraction::Reflect => GeneratorShape::Mirror,
            _ if pool => GeneratorShape::Pool,
            _ if is_closed => GeneratorShape::ClosedRefractor,
            _ => GeneratorShape::OpenRefractor,
        };
        let in_medium = aabb.is_some_and(|aabb| {
            let (lo, hi) = world_aabb(transform, aabb);
            media.iter().any(|&(mlo, mhi)| lo.cmple(mhi).all() && mlo.cmple(hi).all())
        });
        let sides = Sides::of(is_closed, generator.double_sided);
        facts.push((entity, generator, current, GeneratorFacts { shape, in_medium, sides, with_closed_refractor: false }));
    }
    let with_closed_refractor = facts.iter().any(|(.., f)| f.shape == GeneratorShape::ClosedRefractor);
    for (entity, generator, current, facts) in facts {
        let facts = GeneratorFacts { with_closed_refractor, ..facts };
        let shape = facts.shape;
        let requested = generator.technique.requested();
        match choose(requested, facts, |t| available.0.contains(&CausticTechnique::from(t))) {
            Some(choice) => {
                silent.remove(&entity);
                if current.map(|c| &c.0) == Some(&choice) {
                    continue;
                }
                if let Some(asked) = requested.filter(|&t| t != choice.technique) {
                    warn!("bevy_caustics: CausticGenerator {entity} asked for {asked}; it draws with {}: {choice}", choice.technique);
                } else if !choice.passed_over.is_empty() {
                    info!("bevy_caustics: CausticGenerator {entity}: {choice}");
                }
                commands.entity(entity).insert(CausticTechniqueChoice(choice));
            }
            None => {
                if silent.insert(entity) {
                    warn!(
                        "bevy_caustics: CausticGenerator {entity} casts no caustics: no technique in this app draws a {} (available: {:?})",
                        shape.label(),
                        available.0
                    );
                }
                if current.is_some() {
                    commands.entity(entity).remove::<CausticTechniqueChoice>();
                }
            }
        }
    }
}
