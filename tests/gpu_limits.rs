//! Requests beyond the machine on lavapipe: a photon buffer and caustic maps of 4096²,
//! illumination textures of 16 planes at 4096² and a pool of 8192² texels, each far past
//! the adapter's storage bindings and a 32 MiB `CausticGpuBudget`. Each is lowered to
//! fit (a wgpu validation error would stop the frames, and an allocation past the budget
//! would show in the allocator's report), still renders finite caustics, and the GPU
//! memory the plugin holds stays within the budget. A warped-volumes generator whose
//! vertex rays no storage binding holds is skipped, and the frames go on.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::prelude::*;
use bevy::render::renderer::RenderDevice;
use bevy_caustics::convolution::{PoolRipples, PoolSurface};
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::hierarchical_maps::HierarchicalMapsSettings;
use bevy_caustics::illumination_textures::IlluminationTexturesSettings;
use bevy_caustics::warped_volumes::CausticVolumes;
use bevy_caustics::{CausticGenerator, CausticGpuBudget, CausticReceiver, CausticTechnique};
use support::{render, render_caustics};

const SIZE: u32 = 32;
const BUDGET: u64 = 32 << 20;
/// What the plugin holds besides a technique's lowered request: the view's irradiance
/// and receiver depth, uniforms, a generator's mesh-sized buffers.
const SLACK: u64 = 1 << 20;

/// The GPU memory in the plugin's own allocations (labelled `caustic_…`).
fn plugin_memory(renderer: &HeadlessRenderer) -> u64 {
    let memory = renderer.gpu_memory().expect("Vulkan's allocator reports its allocations");
    memory.iter().filter(|(label, _)| label.starts_with("caustic_")).map(|(_, bytes)| bytes).sum()
}

/// Renders the scene until its caustics are in, then checks that `pass` ran, the
/// caustics are finite and some light arrived, and the plugin's memory.
fn check(renderer: &mut HeadlessRenderer, camera: Entity, what: &str, pass: &str) {
    render_caustics(renderer, 2);
    assert!(renderer.pass_report().views(pass) > 0, "{what}: the pass {pass:?} did not run: {:?}", renderer.pass_report());
    let irradiance = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
    assert!(irradiance.iter().all(|e| e.is_finite() && e.min_element() >= 0.0), "{what}: a pixel is not finite");
    assert!(irradiance.iter().any(|e| e.max_element() > 0.0), "{what}: no caustic light arrived");
    let bytes = plugin_memory(renderer);
    eprintln!("{what}: the plugin holds {:.1} MiB of GPU memory", bytes as f64 / 1048576.0);
    assert!(bytes <= BUDGET + SLACK, "{what}: the plugin holds {bytes} bytes, past the budget of {BUDGET}");
}

fn despawn_generators(renderer: &mut HeadlessRenderer) {
    let world = renderer.world_mut();
    let generators: Vec<Entity> = world.query_filtered::<Entity, With<CausticGenerator>>().iter(world).collect();
    for entity in generators {
        world.despawn(entity);
    }
    render(renderer, 4);
}

#[test]
fn requests_beyond_the_gpu_and_the_budget_are_lowered_and_still_render() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let camera = renderer.world_mut().spawn((support::top_down_camera(target, 4.0, SIZE, Vec3::ZERO), Msaa::Off)).id();
    let world = renderer.world_mut();
    world.insert_resource(CausticGpuBudget { bytes: BUDGET });
    world.insert_resource(HierarchicalMapsSettings { photon_resolution: 4096, map_resolution: 4096, ..default() });
    world.insert_resource(IlluminationTexturesSettings { planes: 16, texture_size: 4096, cache_dir: None, ..default() });
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(8.0, 8.0));
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    world.spawn((Mesh3d(floor), MeshMaterial3d(white.clone()), CausticReceiver, Transform::from_xyz(0.0, -1.0, 0.0)));
    world.spawn((DirectionalLight { illuminance: 10_000.0, shadow_maps_enabled: true, ..default() }, Transform::default().looking_to(Vec3::NEG_Y, Vec3::X)));

    for (technique, what, pass) in [
        (CausticTechnique::HierarchicalMaps, "caustic maps of 4096² photons and texels", "caustic map projection"),
        (CausticTechnique::IlluminationTextures, "16 illumination textures of 4096²", "illumination textures projection"),
    ] {
        let world = renderer.world_mut();
        let ball = world.resource_mut::<Assets<Mesh>>().add(Sphere::new(0.5).mesh().ico(3).expect("an icosphere"));
        world.spawn((
            Mesh3d(ball),
            MeshMaterial3d(white.clone()),
            CausticGenerator { technique, ..CausticGenerator::refractive(1.5) },
            Transform::from_xyz(0.0, 0.5, 0.0),
        ));
        check(&mut renderer, camera, what, pass);
        despawn_generators(&mut renderer);
    }

    // Warped volumes over a mesh with more vertices than one storage binding holds the
    // rays of (112 bytes each): the generator is skipped with a warning, where binding
    // its rays would be a wgpu error, and the frames go on.
    let limits = renderer.world_mut().resource::<RenderDevice>().limits();
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    // A plane of `side` subdivisions has (side + 2)² vertices.
    let side = ((binding / 112) as f64).sqrt() as u32;
    assert!(side <= 2048, "this adapter binds {binding} bytes at once: a generator past it takes over 4 M vertices, too many for a test");
    let world = renderer.world_mut();
    let gathered = world.resource::<CausticVolumes>().gathered;
    let plane = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(8.0, 8.0).subdivisions(side));
    world.spawn((Mesh3d(plane), CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.333) }));
    render(&mut renderer, 3);
    let volumes = renderer.world_mut().resource::<CausticVolumes>();
    assert!(volumes.gathered > gathered, "the volumes' sources were not gathered again");
    assert_eq!(volumes.stats.volumes, 0, "a generator of {} vertices was built", (side + 2).pow(2));
    despawn_generators(&mut renderer);

    let world = renderer.world_mut();
    let asked = PoolRipples { columns: 8192, rows: 8192, cell_size: 4.0 / 8192.0, depth: 1.0, ..default() };
    // Water the camera sees the floor through (blended surfaces stay out of the depth prepass).
    let water = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(0.8, 0.9, 1.0, 0.2),
        alpha_mode: AlphaMode::Blend,
        ..default()
    });
    let pool =
        world.spawn((asked, CausticGenerator { technique: CausticTechnique::Convolution, ..CausticGenerator::refractive(1.333) }, MeshMaterial3d(water))).id();
    render(&mut renderer, 1);
    let world = renderer.world_mut();
    let water = world.get::<PoolSurface>(pool).expect("the pool has water").settings().clone();
    assert!(water.columns < 8192 && u64::from(water.columns) * u64::from(water.rows) * bevy_caustics::convolution::BYTES_PER_TEXEL <= BUDGET);
    eprintln!("a pool of 8192² texels runs at {}×{} texels of {} m", water.columns, water.rows, water.cell_size);
    world.write_message(bevy_caustics::DropPebble { position: Vec3::new(0.3, 0.0, -0.2), strength: 0.02 });
    check(&mut renderer, camera, "a pool of 8192² texels", "pool floor");
}
