//! Opt-in automatic tagging: meshes under an entity marked [`TagCausticsFromMaterials`]
//! (a glTF scene root, say) become generators or receivers from their
//! `StandardMaterial`, by the glTF convention of
//! [`caustics_core::scene::role_from_material`]: `KHR_materials_transmission` with
//! `KHR_materials_ior` refracts, smooth metal mirrors, everything else receives.

use crate::{CausticGenerator, CausticReceiver, CausticTechnique, GeneratorInteraction};
use bevy::pbr::{MeshMaterial3d, StandardMaterial};
use bevy::prelude::*;
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{SurfaceRole, role_from_material};

/// Put on a scene root: every mesh below it without a caustics component of its own
/// is tagged from its material once its material has loaded.
#[derive(Component, Reflect, Clone, Copy, Debug, Default)]
#[reflect(Component, Default)]
pub struct TagCausticsFromMaterials;

/// Marks a mesh the tagging has looked at, so that it is judged once.
#[derive(Component)]
pub struct CausticTagged;

/// Meshes with a `StandardMaterial` that neither the tagging nor the user has tagged.
type Untagged = (With<Mesh3d>, Without<CausticTagged>, Without<CausticGenerator>, Without<CausticReceiver>);

/// Tags untagged meshes below a [`TagCausticsFromMaterials`] root.
pub fn tag_from_materials(
    mut commands: Commands,
    candidates: Query<(Entity, &MeshMaterial3d<StandardMaterial>, Option<&Name>), Untagged>,
    roots: Query<(), With<TagCausticsFromMaterials>>,
    parents: Query<&ChildOf>,
    materials: Res<Assets<StandardMaterial>>,
) {
    if roots.is_empty() {
        return;
    }
    for (entity, material, name) in &candidates {
        let under_root = roots.contains(entity) || parents.iter_ancestors(entity).any(|a| roots.contains(a));
        if !under_root {
            continue;
        }
        let Some(material) = materials.get(&material.0) else { continue };
        let mut e = commands.entity(entity);
        e.insert(CausticTagged);
        match role_from_material(material.specular_transmission, material.ior, material.metallic, material.perceptual_roughness) {
            Ok(SurfaceRole::Receiver) => {
                e.insert(CausticReceiver);
            }
            Ok(SurfaceRole::Generator(interaction)) => {
                let interaction = match interaction {
                    SpecularInteraction::Refract { ior, .. } => GeneratorInteraction::Refract { ior, dispersion: None },
                    SpecularInteraction::Reflect => GeneratorInteraction::Reflect,
                };
                e.insert(CausticGenerator { interaction, technique: CausticTechnique::Auto, double_sided: material.double_sided });
            }
            Err(err) => {
                let label = name.map_or_else(|| entity.to_string(), |n| n.to_string());
                warn!("bevy_caustics: {label} is not tagged for caustics: {err}");
            }
        }
    }
}
