//! glTF 2.0 scenes through Bevy's own loader: the file is loaded as a Bevy world
//! asset (no renderer needed), then its meshes, materials, lights and camera are
//! turned into a core [`Scene`] with the glTF tagging convention of
//! [`caustics_core::scene::role_from_material`].

use crate::scenes::LoadedScene;
use bevy::asset::{AssetPlugin, LoadState, UnapprovedPathMode};
use bevy::camera::{Camera, Projection};
use bevy::gltf::GltfAssetLabel;
use bevy::light::{DirectionalLight, PointLight, SpotLight};
use bevy::mesh::{Mesh, Mesh3d};
use bevy::pbr::{MeshMaterial3d, StandardMaterial};
use bevy::prelude::*;
use bevy::render::{RenderPlugin, settings::WgpuSettings};
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use bevy::world_serialization::WorldAsset;
use caustics_bevy::read_scene::{core_light, core_mesh, to_core};
use caustics_core::estimate::GridRegion;
use caustics_core::glam;
use caustics_core::scene::{Generator, Receiver, Scene, SurfaceRole, role_from_material};
use caustics_core::scenes::BenchScene;
use caustics_core::view::PinholeCamera;
use std::path::Path;

/// Updates to wait for the file and its dependencies before giving up.
const MAX_UPDATES: usize = 2000;

/// Loads `path` and converts it; `cells` sets the irradiance-plane resolution.
pub fn load(path: &Path, cells: usize) -> Result<LoadedScene, String> {
    let name = path.display().to_string();
    let abs = std::fs::canonicalize(path).map_err(|e| format!("{name}: {e}"))?;
    precheck(&std::fs::read(&abs).map_err(|e| format!("{name}: {e}"))?).map_err(|e| format!("{name}: {e}"))?;
    let (dir, file) = (abs.parent().unwrap_or(Path::new("/")), abs.file_name().unwrap_or_default());

    let mut app = App::new();
    app.add_plugins(
        DefaultPlugins
            .set(AssetPlugin { file_path: dir.display().to_string(), unapproved_path_mode: UnapprovedPathMode::Deny, ..default() })
            .set(WindowPlugin { primary_window: None, exit_condition: ExitCondition::DontExit, ..default() })
            // Loading needs no GPU: no backend, no render world.
            .set(RenderPlugin { render_creation: WgpuSettings { backends: None, ..default() }.into(), ..default() })
            .disable::<WinitPlugin>()
            .disable::<bevy::log::LogPlugin>(),
    );
    app.finish();
    app.cleanup();
    let handle = app.world().resource::<AssetServer>().load::<WorldAsset>(GltfAssetLabel::Scene(0).from_asset(file.to_string_lossy().into_owned()));
    for _ in 0..MAX_UPDATES {
        app.update();
        let server = app.world().resource::<AssetServer>();
        if let LoadState::Failed(err) = server.load_state(&handle) {
            // Bevy's load errors carry the loader's backtrace on later lines.
            let err = err.to_string();
            return Err(format!("{name}: {}", err.lines().next().unwrap_or("failed to load")));
        }
        if server.is_loaded_with_dependencies(&handle) {
            let world = app.world_mut();
            // The glTF scene is a world of its own: read it in place, no spawning.
            let mut scene_world = std::mem::take(&mut world.resource_mut::<Assets<WorldAsset>>().get_mut(&handle).ok_or("scene asset vanished")?.world);
            return convert(&mut scene_world, world, &name, cells);
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    Err(format!("{name}: the scene did not finish loading"))
}

/// Faults that Bevy's glTF loader (through the `gltf` crate) meets with a panic in its
/// loading task rather than an error: an index accessor that is not of an unsigned
/// integer type (glTF 2.0 §3.7.2.1). A document that does not parse is left to the
/// loader, which says why.
fn precheck(bytes: &[u8]) -> Result<(), String> {
    // A GLB's JSON chunk follows its 12-byte header and 8-byte chunk header.
    let json = match bytes.get(..4) {
        Some(b"glTF") => {
            let length = bytes.get(12..16).map(|l| u32::from_le_bytes([l[0], l[1], l[2], l[3]]) as usize).unwrap_or(0);
            bytes.get(20..20 + length).unwrap_or_default()
        }
        _ => bytes,
    };
    let Ok(document) = serde_json::from_slice::<serde_json::Value>(json) else { return Ok(()) };
    let accessors = document["accessors"].as_array();
    for (m, mesh) in document["meshes"].as_array().into_iter().flatten().enumerate() {
        for (p, primitive) in mesh["primitives"].as_array().into_iter().flatten().enumerate() {
            let Some(indices) = primitive["indices"].as_u64() else { continue };
            let component = accessors.and_then(|a| a.get(indices as usize)).map(|a| &a["componentType"]);
            if let Some(component) = component.and_then(|c| c.as_u64()).filter(|c| ![5121, 5123, 5125].contains(c)) {
                return Err(format!(
                    "meshes[{m}].primitives[{p}]: its indices (accessor {indices}) have componentType {component}, not an unsigned byte, short or int"
                ));
            }
        }
    }
    Ok(())
}

/// World transform of an entity of the scene world, following `ChildOf` to the root.
fn global_transform(world: &World, entity: Entity) -> GlobalTransform {
    let local = world.get::<Transform>(entity).copied().unwrap_or_default();
    match world.get::<ChildOf>(entity) {
        Some(parent) => global_transform(world, parent.parent()).mul_transform(local),
        None => GlobalTransform::from(local),
    }
}

/// Converts the glTF scene's world; `app` holds its mesh and material assets.
fn convert(world: &mut World, app: &World, name: &str, cells: usize) -> Result<LoadedScene, String> {
    let mut scene = Scene::default();
    let mut query = world.query::<(Entity, &Mesh3d, &MeshMaterial3d<StandardMaterial>, Option<&Name>)>();
    let meshes = app.resource::<Assets<Mesh>>();
    let materials = app.resource::<Assets<StandardMaterial>>();
    for (entity, mesh, material, entity_name) in query.iter(world) {
        let transform = &global_transform(world, entity);
        let label = entity_name.map_or("unnamed mesh".to_string(), |n| n.to_string());
        let (Some(mesh), Some(material)) = (meshes.get(&mesh.0), materials.get(&material.0)) else {
            return Err(format!("{name}: {label}: its mesh or material did not load"));
        };
        let mesh = core_mesh(mesh, transform).map_err(|e| format!("{name}: {label}: {e}"))?;
        let role = role_from_material(material.specular_transmission, material.ior, material.metallic, material.perceptual_roughness)
            .map_err(|e| format!("{name}: {label}: {e}"))?;
        match role {
            SurfaceRole::Generator(interaction) => scene.generators.push(Generator { mesh, interaction, double_sided: material.double_sided }),
            SurfaceRole::Receiver => {
                let c = material.base_color.to_linear();
                scene.receivers.push(Receiver { mesh, albedo: glam::Vec3::new(c.red, c.green, c.blue) });
            }
        }
    }
    let mut lights = world.query::<(Entity, Option<&DirectionalLight>, Option<&PointLight>, Option<&SpotLight>)>();
    for (entity, directional, point, spot) in lights.iter(world) {
        if let Some(light) = core_light(directional, point, spot, &global_transform(world, entity)) {
            scene.lights.push(light);
        }
    }
    scene.validate().map_err(|e| format!("{name}: {e}"))?;
    let (lo, hi) = scene.generator_bounds().ok_or_else(|| format!("{name}: no caustic generators (transmissive or mirror materials)"))?;
    let floor_y = scene.receivers.iter().map(|r| r.mesh.bounds().0.y).fold(f32::INFINITY, f32::min);
    let size = (hi.x - lo.x).max(hi.z - lo.z);
    let region = GridRegion::horizontal(0.5 * (lo.x + hi.x - size), 0.5 * (lo.z + hi.z - size), floor_y.min(lo.y), size, cells);

    let mut cameras = world.query::<(Entity, &Camera, &Projection)>();
    let camera = cameras.iter(world).find_map(|(entity, _, p)| match p {
        Projection::Perspective(p) => Some((global_transform(world, entity), p)),
        _ => None,
    });
    let camera = camera.map(|(t, p)| PinholeCamera {
        position: to_core(t.translation()),
        look_at: to_core(t.translation() + caustics_bevy::read_scene::facing(&t)),
        up: to_core(Vec3::from(t.affine().matrix3 * bevy::math::Vec3A::Y).normalize_or(Vec3::Y)),
        fov_y: p.fov,
        width: 0,
        height: 0,
    });
    Ok(LoadedScene { bench: BenchScene { name: name.to_string(), scene, region }, camera })
}
