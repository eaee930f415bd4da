//! What the techniques read of the ECS, as the core crate's types: Bevy's lights,
//! meshes and bounds converted, which meshes block caustic light, and what changed
//! since a system last read them ([`SceneChanges`]).

use crate::technique::CausticTechniqueChoice;
use crate::{CausticGenerator, CausticReceiver, InvalidCausticParams};
use bevy::asset::RenderAssetUsages;
use bevy::camera::primitives::Aabb;
use bevy::ecs::system::SystemParam;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use caustics_core::glam;
use caustics_core::mesh::TriMesh;
use caustics_core::scene::{Light, LightKind};
use std::f32::consts::PI;

/// Marks an entity whose mesh a compute pass (in `mesh_vertices::WriteMeshVertices`)
/// rewrites every frame on the GPU (an ocean, a rippling pool): its mesh asset does not
/// change, and whatever reads its vertices reads them again each frame.
#[derive(Component)]
pub(crate) struct MovesOnGpu;

/// A Bevy vector as the core crate's (the same glam, re-exported at another path).
pub fn to_core(v: Vec3) -> glam::Vec3 {
    glam::Vec3::from_array(v.to_array())
}

/// What the techniques read of a light: its kind, placement and visibility.
pub type LightComponents =
    (Option<&'static DirectionalLight>, Option<&'static PointLight>, Option<&'static SpotLight>, &'static GlobalTransform, &'static InheritedVisibility);

/// What the techniques read of a mesh entity: its mesh, placement, visibility and bounds.
pub type MeshComponents = (&'static Mesh3d, &'static GlobalTransform, &'static InheritedVisibility, Option<&'static Aabb>);

/// A mesh that is not a generator, and whether it receives caustics or opts out of
/// casting shadows.
pub type OccluderComponents = (MeshComponents, Has<CausticReceiver>, Has<bevy::light::NotShadowCaster>);

/// Whether a mesh that is not a generator blocks caustic light: a visible receiver, or
/// a visible mesh that casts Bevy's shadows (`NotShadowCaster` opts out of both).
pub fn blocks_caustic_light(visible: &InheritedVisibility, receiver: bool, no_shadows: bool) -> bool {
    visible.get() && (receiver || !no_shadows)
}

/// Any of Bevy's lights.
pub type AnyLight = Or<(With<DirectionalLight>, With<PointLight>, With<SpotLight>)>;

/// The visible lights that cast caustics, as the core crate's: a light that fails
/// [`Light::validate`] (a zero or non-finite direction or power) casts none.
pub fn core_lights(lights: &Query<LightComponents, AnyLight>) -> Vec<Light> {
    lights.iter().filter(|(.., visible)| visible.get()).filter_map(|(d, p, s, t, _)| core_light(d, p, s, t)).filter(|l| l.validate().is_ok()).collect()
}

type LightChanged = Or<(Changed<GlobalTransform>, Changed<DirectionalLight>, Changed<PointLight>, Changed<SpotLight>, Changed<InheritedVisibility>)>;
type OccluderChanged =
    Or<(Changed<GlobalTransform>, Changed<Aabb>, Changed<Mesh3d>, Changed<InheritedVisibility>, Added<CausticReceiver>, Added<bevy::light::NotShadowCaster>)>;
/// A generator moved, changed, got a new mesh, choice or visibility, or began to move
/// on the GPU.
pub(crate) type GeneratorChanged = Or<(
    Changed<GlobalTransform>,
    Changed<Mesh3d>,
    Changed<CausticGenerator>,
    Changed<CausticTechniqueChoice>,
    Changed<InheritedVisibility>,
    Added<MovesOnGpu>,
)>;

/// What changed in the scene the techniques read since the system holding this last
/// ran, from Bevy's change detection and removals: generators, meshes that receive or
/// block caustic light, lights. A technique gathers its inputs again only when one did,
/// instead of walking every caster each frame to compare. [`read_scene_changes`] reads
/// it once a frame into the [`ChangedParts`] every technique reads.
#[derive(SystemParam)]
pub struct SceneChanges<'w, 's> {
    generators: Query<'w, 's, (), (With<CausticGenerator>, GeneratorChanged)>,
    generator_bounds: Query<'w, 's, (), (With<CausticGenerator>, Changed<Aabb>)>,
    occluders: Query<'w, 's, (), (With<Mesh3d>, Without<CausticGenerator>, OccluderChanged)>,
    lights: Query<'w, 's, (), (AnyLight, LightChanged)>,
    removed_generators:
        (RemovedComponents<'w, 's, CausticTechniqueChoice>, RemovedComponents<'w, 's, InvalidCausticParams>, RemovedComponents<'w, 's, MovesOnGpu>),
    removed_occluders: (RemovedComponents<'w, 's, Mesh3d>, RemovedComponents<'w, 's, CausticReceiver>, RemovedComponents<'w, 's, bevy::light::NotShadowCaster>),
    removed_lights: (RemovedComponents<'w, 's, DirectionalLight>, RemovedComponents<'w, 's, PointLight>, RemovedComponents<'w, 's, SpotLight>),
}

/// Which parts of the scene [`SceneChanges::read`] found changed: as a resource, this
/// frame's, for the systems in [`crate::CausticSystems::ReadScene`].
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct ChangedParts {
    /// A generator moved, changed, was added or went away (or its choice or validity).
    pub generators: bool,
    /// A generator's bounds changed: its mesh loaded, or a surface moved on the GPU
    /// (`Ocean`, `PoolRipples`) was given bounds for its new waves.
    pub generator_bounds: bool,
    /// A mesh that is not a generator moved, changed, came, went, or began or stopped
    /// receiving caustics or casting shadows.
    pub occluders: bool,
    /// A light moved, changed, came or went.
    pub lights: bool,
}

impl ChangedParts {
    /// Whether anything changed.
    pub fn any(self) -> bool {
        self.generators || self.generator_bounds || self.occluders || self.lights
    }
}

impl SceneChanges<'_, '_> {
    /// What changed since the last call, consuming the removals seen so far.
    pub fn read(&mut self) -> ChangedParts {
        let (a, b, c) = &mut self.removed_generators;
        let removed_generators = a.read().count() + b.read().count() + c.read().count() > 0;
        let (a, b, c) = &mut self.removed_occluders;
        let removed_occluders = a.read().count() + b.read().count() + c.read().count() > 0;
        let (a, b, c) = &mut self.removed_lights;
        let removed_lights = a.read().count() + b.read().count() + c.read().count() > 0;
        ChangedParts {
            generators: removed_generators || !self.generators.is_empty(),
            generator_bounds: !self.generator_bounds.is_empty(),
            occluders: removed_occluders || !self.occluders.is_empty(),
            lights: removed_lights || !self.lights.is_empty(),
        }
    }
}

/// Reads this frame's [`ChangedParts`], once for every technique that reads the scene.
pub fn read_scene_changes(mut changes: SceneChanges, mut changed: ResMut<ChangedParts>) {
    *changed = changes.read();
}

/// The direction an entity faces (its −Z) under `transform`, zero when the transform
/// has none (a zero scale): `GlobalTransform::forward` would panic there.
pub fn facing(transform: &GlobalTransform) -> Vec3 {
    Vec3::from(transform.affine().matrix3 * bevy::math::Vec3A::NEG_Z).normalize_or_zero()
}

/// A Bevy light placed by `transform` as the core crate's light, with a point or spot
/// light's `range`. Bevy's point and spot intensities are luminous power (lm); the core
/// wants intensity per steradian, Φ/4π (Bevy's own convention, spots included).
pub fn core_light(directional: Option<&DirectionalLight>, point: Option<&PointLight>, spot: Option<&SpotLight>, transform: &GlobalTransform) -> Option<Light> {
    let color = |c: Color| {
        let c = c.to_linear();
        caustics_core::glam::Vec3::new(c.red, c.green, c.blue)
    };
    let position = to_core(transform.translation());
    // A light without a direction (a zero scale) fails `Light::validate`, which says so.
    let forward = to_core(facing(transform));
    Some(match (directional, point, spot) {
        (Some(d), ..) => Light { kind: LightKind::Directional { direction: forward, irradiance: d.illuminance }, color: color(d.color), range: f32::INFINITY },
        (_, Some(p), _) => Light { kind: LightKind::Point { position, intensity: p.intensity / (4.0 * PI) }, color: color(p.color), range: p.range },
        (_, _, Some(s)) => Light {
            kind: LightKind::Spot { position, direction: forward, intensity: s.intensity / (4.0 * PI), inner_angle: s.inner_angle, outer_angle: s.outer_angle },
            color: color(s.color),
            range: s.range,
        },
        _ => return None,
    })
}

/// A Bevy mesh placed by `transform` as a world-space core mesh. Meshes without
/// normals get smooth ones; malformed meshes (not a triangle list, no positions, bad
/// indices, NaN) and placements that flatten or overflow them (a zero scale, a
/// translation past `f32`) are an error that says why.
pub fn core_mesh(mesh: &Mesh, transform: &GlobalTransform) -> Result<TriMesh, String> {
    use bevy::mesh::VertexAttributeValues::Float32x3;
    if mesh.primitive_topology() != bevy::mesh::PrimitiveTopology::TriangleList {
        return Err(format!("is a {:?}, not a triangle list", mesh.primitive_topology()));
    }
    let affine = glam::Affine3A::from_cols_array(&transform.affine().to_cols_array());
    let determinant = affine.matrix3.determinant();
    if !(determinant.is_finite() && determinant != 0.0 && affine.translation.is_finite()) {
        return Err("is placed by a transform with a zero or non-finite scale or translation".into());
    }
    let positions = match mesh.try_attribute(Mesh::ATTRIBUTE_POSITION) {
        Ok(Float32x3(p)) => p.iter().map(|&p| glam::Vec3::from_array(p)).collect::<Vec<_>>(),
        _ => return Err("has no Float32x3 positions".into()),
    };
    let indices: Vec<u32> = match mesh.indices() {
        Some(Indices::U16(i)) => i.iter().map(|&i| i as u32).collect(),
        Some(Indices::U32(i)) => i.clone(),
        None => (0..positions.len() as u32).collect(),
    };
    let triangles: Vec<[u32; 3]> = indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let local = match mesh.try_attribute(Mesh::ATTRIBUTE_NORMAL) {
        Ok(Float32x3(n)) => TriMesh::new(positions, n.iter().map(|&n| glam::Vec3::from_array(n)).collect(), triangles),
        _ => TriMesh::with_smooth_normals(positions, triangles),
    }
    .map_err(|e| e.to_string())?;
    // Placed, it is checked again: a large scale may carry it past `MAX_COORDINATE`.
    let world = local.transformed(&affine);
    TriMesh::new(world.positions().to_vec(), world.normals().to_vec(), world.triangles().to_vec()).map_err(|e| format!("placed in the world: {e}"))
}

/// World-space bounds `(min, max)` of an entity's local `Aabb` placed by `transform`.
pub fn world_aabb(transform: &GlobalTransform, aabb: &Aabb) -> (Vec3, Vec3) {
    let (c, h) = (Vec3::from(aabb.center), Vec3::from(aabb.half_extents));
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for i in 0..8 {
        let corner = c + h * Vec3::new([-1.0, 1.0][i & 1], [-1.0, 1.0][(i >> 1) & 1], [-1.0, 1.0][i >> 2]);
        let p = transform.transform_point(corner);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    (lo, hi)
}

/// A core mesh as a Bevy triangle list with positions and normals.
pub fn bevy_mesh(mesh: &TriMesh) -> Mesh {
    let arrays = |v: &[glam::Vec3]| v.iter().map(|p| p.to_array()).collect::<Vec<_>>();
    Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, arrays(mesh.positions()))
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, arrays(mesh.normals()))
        .with_inserted_indices(Indices::U32(mesh.triangles().iter().flatten().copied().collect()))
}

/// A Bevy affine transform as the core crate's.
pub fn to_core_affine(a: &bevy::math::Affine3A) -> glam::Affine3A {
    glam::Affine3A::from_cols_array(&a.to_cols_array())
}
