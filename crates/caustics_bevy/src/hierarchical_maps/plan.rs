//! Main world: what the caustic maps are made of this frame — the light views, the
//! generator and occluder instances — and a generation that changes only when any of it
//! does, so that an unchanged scene keeps its maps.

use super::HierarchicalMapsSettings;
use crate::CausticTechnique;
use crate::components::{CausticGenerator, InvalidCausticParams};
use crate::irradiance::ActiveCausticTechniques;
use crate::irradiance::mesh_bvhs::MeshBvhs;
use crate::read_scene::{
    AnyLight, ChangedParts, LightComponents, MeshComponents, OccluderComponents, blocks_caustic_light, core_light, core_mesh, read_scene_changes, to_core,
    world_aabb,
};
use crate::technique::CausticTechniqueChoice;
use bevy::platform::collections::HashSet;
use bevy::prelude::*;
use caustics_core::bvh::SceneBvh;
use caustics_core::hierarchical::{CausticMapSettings, LightView, PhotonPaths, light_intensity};
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{Light, Receiver, Scene, Sides};
use caustics_core::triangle_bvh::InstancedBvh;
use rayon::prelude::*;
use std::sync::Arc;

/// One light view to make a caustic map for, with the light it belongs to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlannedLightView {
    /// The light's view: a directional light's box, or a point or spot light's face.
    pub view: LightView,
    /// Linear RGB colour times the light's intensity (irradiance across a parallel beam,
    /// intensity per steradian for point and spot lights).
    pub color: Vec3,
    /// The spot's cone `(axis, cos θₒ, 1 / (cos θᵢ − cos θₒ))`, `None` for other lights.
    pub cone: Option<(Vec3, f32, f32)>,
    /// `1/range²` of a point or spot light, 0 without a range
    /// (`Light::inverse_range_squared`).
    pub inverse_range_squared: f32,
}

/// One mesh drawn into the light maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CausticMapInstance {
    /// The mesh drawn.
    pub mesh: AssetId<Mesh>,
    /// Its placement.
    pub world_from_local: Mat4,
    /// A generator's index of refraction (the green channel's for a dispersive one),
    /// 0 for a mirror; unused for occluders.
    pub ior: f32,
    /// An open double-sided generator (`Sides::Both`): the front light map keeps its
    /// back faces. Unused for occluders, drawn from both sides.
    pub both_sides: bool,
    /// An open one-sided generator (`Sides::Front`): the back of its faces absorbs
    /// what a traced path brings there.
    pub one_sided: bool,
    /// Whether the caustic maps draw the light that falls on this generator first;
    /// with traced paths, the generators other techniques draw are planned too, to
    /// shadow, reflect and refract the photons that reach them (`PhotonMaterial`).
    pub drawn: bool,
}

/// What the caustic maps are made of. A new `generation` means new contents.
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct CausticMapPlan {
    /// A caustic map for each.
    pub views: Vec<PlannedLightView>,
    /// The generators, in the order the maps index them.
    pub generators: Vec<CausticMapInstance>,
    /// The meshes that receive or block the caustic light.
    pub occluders: Vec<CausticMapInstance>,
    /// Generators left out because the occluders hide every vertex of theirs from
    /// every light: a generator in full shadow costs no map work.
    pub shadowed: usize,
    /// The settings planned with, `None` before the first plan.
    pub settings: Option<CausticMapSettings>,
    /// The generators placed over their meshes' BVHs, each with its index in
    /// `generators`, where photons are traced through them; placed again when the plan
    /// changes, the meshes' BVHs built only when a mesh does.
    pub bvh: Option<Arc<InstancedBvh>>,
    /// Counts the plans; a new one means new contents.
    pub generation: u64,
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).main;
    app.init_resource::<CausticMapPlan>().add_systems(
        PostUpdate,
        crate::cpu_time::timed(&cpu, plan_caustic_maps)
            .run_if(crate::cpu_time::timed(&cpu, maps_wanted))
            .after(read_scene_changes)
            .in_set(crate::CausticSystems::ReadScene),
    );
}

/// Whether the maps have a plan to make or to clear: a generator drawn by them, or a
/// plan that still holds one. A scene without them spends nothing on their plan.
fn maps_wanted(choices: Query<&CausticTechniqueChoice>, plan: Res<CausticMapPlan>) -> bool {
    !plan.generators.is_empty() || !plan.views.is_empty() || choices.iter().any(|c| c.technique() == CausticTechnique::HierarchicalMaps)
}

/// The occluders' BVH, by `occluders` of [`CausticMapPlan`], for the shadow test.
fn occluder_bvh(occluders: &[CausticMapInstance], meshes: &Assets<Mesh>) -> SceneBvh {
    let receivers = occluders
        .iter()
        .filter_map(|o| meshes.get(o.mesh).and_then(|m| core_mesh(m, &GlobalTransform::from(o.world_from_local)).ok()))
        .map(|mesh| Receiver { mesh, albedo: caustics_core::glam::Vec3::ONE })
        .collect();
    SceneBvh::build(&Scene { receivers, ..Scene::default() })
}

/// Leaves out the generators whose every vertex the occluders hide from every light
/// (the CPU rays the volumes use, `SceneBvh::hides`), counting them in `shadowed`; the
/// photon kernel still drops the shadowed photons of the rest. A generator with every
/// vertex hidden but light through a gap between them would be lost: an occluder with
/// holes smaller than the generator's triangles. Returns whether any was left out.
fn leave_out_shadowed(plan: &mut CausticMapPlan, lights: &[Light], meshes: &Assets<Mesh>) -> bool {
    if plan.generators.is_empty() || plan.occluders.is_empty() {
        return false;
    }
    let occluders = occluder_bvh(&plan.occluders, meshes);
    let lit = |g: &CausticMapInstance| {
        !g.drawn
            || meshes
                .get(g.mesh)
                .and_then(|m| core_mesh(m, &GlobalTransform::from(g.world_from_local)).ok())
                .is_none_or(|mesh| lights.iter().any(|l| mesh.positions().par_iter().any(|&p| !occluders.hides(l, p))))
    };
    let before = plan.generators.len();
    plan.generators.retain(lit);
    plan.shadowed = before - plan.generators.len();
    plan.shadowed > 0
}

/// Main world: plans the caustic maps (light views, instances) and bumps the
/// generation when the plan, or a mesh it draws, changed. The plan is made again only
/// when change detection says a generator, occluder, light, mesh or the settings did.
/// The shadow test that leaves out generators in full shadow casts a ray from every
/// generator vertex, so it runs once the plan has held still for a frame, never while
/// anything moves: a moving scene keeps every generator, and the photon kernel drops
/// what the occluders hide.
#[allow(clippy::too_many_arguments)]
fn plan_caustic_maps(
    generators: Query<(Entity, &CausticGenerator, &CausticTechniqueChoice, MeshComponents), Without<InvalidCausticParams>>,
    occluders: Query<OccluderComponents, Without<CausticGenerator>>,
    lights: Query<LightComponents, AnyLight>,
    changed: Res<ChangedParts>,
    settings: Res<HierarchicalMapsSettings>,
    mut mesh_events: MessageReader<AssetEvent<Mesh>>,
    meshes: Res<Assets<Mesh>>,
    mut plan: ResMut<CausticMapPlan>,
    mut planned: Local<CausticMapPlan>,
    mut shadows_tested: Local<bool>,
    mut bvhs: ResMut<MeshBvhs>,
    mut active: ResMut<ActiveCausticTechniques>,
    mut warned: Local<bool>,
    mut warned_generators: Local<HashSet<Entity>>,
) {
    let core_settings = settings.core();
    let valid = match core_settings.validate() {
        Ok(()) => {
            *warned = false;
            true
        }
        Err(e) => {
            if !*warned {
                warn!("bevy_caustics: the caustic maps are skipped: {e}");
                *warned = true;
            }
            false
        }
    };
    // Generation 0 until it is planned: `planned` keeps what the last plan was made of.
    let mesh_changed = mesh_events.read().any(|e| match e {
        AssetEvent::Modified { id } | AssetEvent::Added { id } | AssetEvent::LoadedWithDependencies { id } => {
            planned.generators.iter().chain(&planned.occluders).any(|i| i.mesh == *id)
        }
        _ => false,
    });
    if !(changed.any() || mesh_changed || settings.is_changed()) && *shadows_tested {
        active.set_if_neq(ActiveCausticTechniques { hierarchical_maps: !plan.views.is_empty(), ..*active });
        return;
    }
    let mut next = CausticMapPlan::default();
    let mut generator_bounds: Option<(Vec3, Vec3)> = None;
    let traced = core_settings.paths == PhotonPaths::Traced;
    for (entity, generator, choice, (mesh, transform, visible, aabb)) in &generators {
        let drawn = choice.technique() == CausticTechnique::HierarchicalMaps;
        if !(drawn || traced && choice.facts().shape.traced_through()) || !visible.get() || !valid {
            continue;
        }
        if next.generators.len() == super::render::MAX_GENERATORS {
            if warned_generators.insert(entity) {
                warn!(
                    "bevy_caustics: CausticGenerator {entity} is left out of the caustic maps: they draw at most {} generators",
                    super::render::MAX_GENERATORS
                );
            }
            continue;
        }
        let Some(aabb) = aabb else { continue };
        if drawn {
            let bounds = world_aabb(transform, aabb);
            generator_bounds = Some(generator_bounds.map_or(bounds, |(lo, hi)| (lo.min(bounds.0), hi.max(bounds.1))));
        }
        let ior = match generator.specular_interaction() {
            SpecularInteraction::Reflect => 0.0,
            interaction => caustics_core::hierarchical::photons::photon_ior(&interaction).unwrap_or(1.0),
        };
        let (both_sides, one_sided) = (choice.facts().sides == Sides::Both, choice.facts().sides == Sides::Front);
        let world_from_local = transform.to_matrix();
        next.generators.push(CausticMapInstance { mesh: mesh.id(), world_from_local, ior, both_sides, one_sided, drawn });
    }
    let mut receiver_bounds: Option<(Vec3, Vec3)> = None;
    if generator_bounds.is_some() {
        for ((mesh, transform, visible, aabb), receiver, no_shadows) in &occluders {
            if !blocks_caustic_light(visible, receiver, no_shadows) {
                continue;
            }
            if receiver && let Some(aabb) = aabb {
                let bounds = world_aabb(transform, aabb);
                receiver_bounds = Some(receiver_bounds.map_or(bounds, |(lo, hi)| (lo.min(bounds.0), hi.max(bounds.1))));
            }
            let world_from_local = transform.to_matrix();
            let occluder = CausticMapInstance { mesh: mesh.id(), world_from_local, ior: 0.0, both_sides: false, one_sided: false, drawn: false };
            next.occluders.push(occluder);
        }
    }
    let mut core_lights = Vec::new();
    if let (Some(generators), Some(receivers)) = (generator_bounds, receiver_bounds) {
        let core_bounds = |(lo, hi): (Vec3, Vec3)| (to_core(lo), to_core(hi));
        for (d, p, s, t, visible) in &lights {
            let Some(light) = core_light(d, p, s, t).filter(|l| visible.get() && l.validate().is_ok()) else { continue };
            let color = Vec3::from_array(light.color.to_array()) * light_intensity(&light);
            let cone = s.map(|s| {
                let (cos_outer, cos_inner) = (s.outer_angle.cos(), s.inner_angle.min(s.outer_angle).cos());
                (crate::read_scene::facing(t), cos_outer, 1.0 / (cos_inner - cos_outer).max(1e-4))
            });
            for view in LightView::for_light(&light, core_bounds(generators), core_bounds(receivers)) {
                next.views.push(PlannedLightView { view, color, cone, inverse_range_squared: light.inverse_range_squared() });
            }
            core_lights.push(light);
        }
    }
    // The settings for these views: a cube face that reaches past its edge doubles the
    // maps' side (the CPU twin's rule).
    next.settings = Some(core_settings.for_views(next.views.iter().map(|v| &v.view)));
    let changed = mesh_changed || next != *planned;
    if changed {
        *planned = next.clone();
        *shadows_tested = false;
    } else if *shadows_tested {
        active.set_if_neq(ActiveCausticTechniques { hierarchical_maps: !plan.views.is_empty(), ..*active });
        return;
    }
    *shadows_tested = !changed;
    // A plan that held still since the last frame's: only its shadow test is new.
    if !changed && !leave_out_shadowed(&mut next, &core_lights, &meshes) {
        return;
    }
    if !next.generators.iter().any(|g| g.drawn) {
        next.views.clear();
    }
    if next.views.is_empty() {
        next.generators.clear();
        next.occluders.clear();
    }
    if traced && !next.views.is_empty() {
        // A light that moved, or a new occluder, leaves the generators' BVH as it was
        // (a generator whose mesh is not loaded is left out of it).
        next.bvh = match &plan.bvh {
            Some(bvh) if !mesh_changed && next.generators == plan.generators => Some(bvh.clone()),
            _ => Some(Arc::new(bvhs.place(next.generators.iter().enumerate().map(|(k, g)| (g.mesh, g.world_from_local, k as u32, None)), &meshes))),
        };
    }
    next.generation = plan.generation + 1;
    *plan = next;
    active.set_if_neq(ActiveCausticTechniques { hierarchical_maps: !plan.views.is_empty(), ..*active });
}
