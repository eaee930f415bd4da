//! Caustic volumes built on the GPU (`build.wgsl`) against their CPU build in
//! `caustics_core::volumes`, on water that moves every frame: an `Ocean` whose waves
//! are evaluated on the GPU (`waves.wgsl`) into the vertex buffer the build reads, held
//! to the core crate's evaluation of the same sea at the same time, and a pool rippled
//! by pebbles on the CPU, with stones lying on its floor (receivers that shadow and end
//! the rays). In each frame the GPU's irradiance matches the CPU build of the mesh that
//! frame drew (and not the frame before's); paused, the GPU keeps and drops the same
//! volumes as the CPU, with the same flux, lost light (total internal reflection,
//! grazing rays) included. A glass raft afloat on the sea is shadowed by the waves as
//! the frame draws them: the sea's BVH among the raft's occluders is refit on the GPU.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::camera::visibility::RenderLayers;
use bevy::light::GlobalAmbientLight;
use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;
use bevy_caustics::convolution::PoolSurface;
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::read_scene::{bevy_mesh, core_mesh, to_core};
use bevy_caustics::warped_volumes::CausticVolumes;
use bevy_caustics::{CausticGenerator, CausticPassReport, CausticReceiver, CausticTechnique, DropPebble, Ocean, PoolRipples};
use caustics_core::bvh::SceneBvh;
use caustics_core::glam::Vec3 as V;
use caustics_core::metrics::relative_l2;
use caustics_core::ocean::OceanSpectrum;
use caustics_core::scene::{Generator, Light, LightKind, Receiver, Scene};
use caustics_core::scenes::{Wave, wave_heightfield};
use caustics_core::volumes::{BuildStats, Footprint, VolumeSet, build_scene_volumes};
use support::render;

const SIZE: u32 = 96;
/// The view is `VIEW` metres across, centred on the origin, looking down.
const VIEW: f32 = 2.0;
const SUN: Vec3 = Vec3::new(0.25, -1.0, -0.15);
const ILLUMINANCE: f32 = 10.0;

/// A 4 m floor, a sun and a top-down camera; `more` adds the water and anything else.
fn spawn_stage(renderer: &mut HeadlessRenderer) -> Entity {
    let target = renderer.render_target();
    let world = renderer.world_mut();
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(2.0)).mesh());
    let material = white(world);
    world.spawn((Mesh3d(floor), MeshMaterial3d(material), CausticReceiver));
    world.spawn((DirectionalLight { illuminance: ILLUMINANCE, shadow_maps_enabled: false, ..default() }, Transform::default().looking_to(SUN, Vec3::Y)));
    // Single-sampled: a pixel's depth is the receiver at its centre, where the CPU looks.
    world.spawn((support::top_down_camera(target, VIEW, SIZE, Vec3::ZERO), Msaa::Off)).id()
}

fn white(world: &mut World) -> Handle<StandardMaterial> {
    world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 1.0, ..default() })
}

/// The scene as the app holds it now, for the CPU build: the generators' meshes as this
/// frame drew them (an ocean's evaluated by the core crate at the app's time: the twin
/// of the GPU's waves; with `as_assets`, as their mesh assets stand instead), every
/// receiver, the sun.
fn cpu_scene(renderer: &mut HeadlessRenderer, generators: &[Entity], as_assets: bool) -> Scene {
    let world = renderer.world_mut();
    let mesh = |world: &mut World, entity: Entity| {
        let (handle, transform) = (world.get::<Mesh3d>(entity).unwrap().0.clone(), *world.get::<GlobalTransform>(entity).unwrap());
        if let Some(ocean) = world.get::<Ocean>(entity).filter(|o| o.on_gpu && !as_assets) {
            let time = world.resource::<Time>().elapsed_secs() * ocean.time_scale;
            let sea = OceanSpectrum::new(&ocean.settings()).unwrap().evaluate(time).mesh();
            return core_mesh(&bevy_mesh(&sea), &transform).unwrap();
        }
        if let Some(surface) = world.get::<PoolSurface>(entity) {
            return core_mesh(&surface.mesh_at(world.resource::<Time>().elapsed_secs()).unwrap(), &transform).unwrap();
        }
        core_mesh(world.resource::<Assets<Mesh>>().get(&handle).unwrap(), &transform).unwrap()
    };
    let receivers: Vec<Entity> = world.query_filtered::<Entity, With<CausticReceiver>>().iter(world).collect();
    let sun = world.query_filtered::<&GlobalTransform, With<DirectionalLight>>().single(world).unwrap().forward();
    let generators = generators
        .iter()
        .map(|&g| {
            let generator = world.get::<CausticGenerator>(g).unwrap().clone();
            Generator { double_sided: generator.double_sided, ..Generator::new(mesh(world, g), generator.specular_interaction()) }
        })
        .collect();
    Scene {
        lights: vec![Light::white(LightKind::Directional { direction: to_core(sun.as_vec3()), irradiance: ILLUMINANCE })],
        generators,
        receivers: receivers.into_iter().map(|r| Receiver { mesh: mesh(world, r), albedo: V::ONE }).collect(),
    }
}

/// The CPU build's caustic irradiance over each pixel's footprint on the receiver
/// point it sees (straight down through the pixel's centre), with that surface's normal.
fn cpu_irradiance(scene: &Scene, set: &VolumeSet) -> Vec<f32> {
    let receivers = SceneBvh::build(&Scene { receivers: scene.receivers.clone(), ..Scene::default() });
    let step = VIEW / SIZE as f32;
    let pixels: Vec<_> = (0..SIZE * SIZE)
        .map(|i| {
            let top = to_core(support::floor_point(i % SIZE, i / SIZE, SIZE, VIEW)) + V::Y * 5.0;
            let hit = receivers.intersect(top, V::NEG_Y, 0.0, f32::INFINITY).expect("every pixel sees a receiver");
            let n = hit.geometric_normal * hit.geometric_normal.y.signum();
            (top + V::NEG_Y * hit.t, n, Footprint::seen(n, V::NEG_Y, V::X * step, V::Z * step))
        })
        .collect();
    set.irradiance_over_at(&pixels, &Default::default()).iter().map(|e| e.x).collect()
}

/// The irradiance the GPU's volumes left in the camera's buffer this frame.
fn gpu_irradiance(renderer: &mut HeadlessRenderer, camera: Entity) -> Vec<f32> {
    renderer.caustic_irradiance(camera).unwrap().iter().map(|e| e.x).collect()
}

/// Renders `frames` moving frames; in each, the GPU's irradiance against the CPU build
/// of the mesh drawn in that frame and in the frame before. Returns the worst error of
/// the first and the mean of the second.
fn follow(renderer: &mut HeadlessRenderer, camera: Entity, water: Entity, frames: usize, name: &str) -> (f32, f32) {
    let (mut worst, mut late) = (0.0f32, 0.0f32);
    let mut before: Option<Vec<f32>> = None;
    for frame in 0..frames {
        render(renderer, 1);
        let gpu = gpu_irradiance(renderer, camera);
        let scene = cpu_scene(renderer, &[water], false);
        let cpu = cpu_irradiance(&scene, &build_scene_volumes(&scene, &Default::default()));
        let mean = cpu.iter().sum::<f32>() / cpu.len() as f32;
        assert!(mean > 0.3 * ILLUMINANCE, "{name}, frame {frame}: the CPU build sees too little light ({mean})");
        let error = relative_l2(&gpu, &cpu);
        let lag = before.as_ref().map_or(0.0, |b| relative_l2(&gpu, b));
        eprintln!("{name}, frame {frame}: GPU vs CPU build of this frame's mesh {error:.2e}, of the frame before's {lag:.2e}");
        worst = worst.max(error);
        late += lag / (frames - 1) as f32;
        before = Some(cpu);
    }
    (worst, late)
}

/// A build's counts of volumes kept and dropped, by why.
fn counts(s: &BuildStats) -> [usize; 6] {
    [s.volumes, s.unlit, s.shadowed, s.total_internal_reflection, s.grazing, s.degenerate]
}

/// Paused, the GPU build's counts as read back against the CPU build's. Counts of
/// water that moves on the GPU come back every eighth frame: those of a build made
/// after the four frames rendered here first.
fn assert_same_volumes(renderer: &mut HeadlessRenderer, generators: &[Entity], name: &str) -> BuildStats {
    render(renderer, 4);
    let moving = generators.iter().any(|g| renderer.world_mut().get::<Ocean>(*g).is_some() || renderer.world_mut().get::<PoolRipples>(*g).is_some());
    let read = renderer.world_mut().resource::<CausticVolumes>().generation;
    for _ in 0..20 {
        if !moving || renderer.world_mut().resource::<CausticVolumes>().generation > read {
            break;
        }
        render(renderer, 1);
    }
    let gpu = renderer.world_mut().resource::<CausticVolumes>().stats;
    let scene = cpu_scene(renderer, generators, false);
    let cpu = build_scene_volumes(&scene, &Default::default()).stats;
    eprintln!("{name}: GPU {gpu:?}\n{name}: CPU {cpu:?}");
    // A shadow ray that grazes an occluder's edge may fall either way in f32: one
    // volume at most changes sides, and its flux with it.
    let moved: usize = counts(&gpu).iter().zip(counts(&cpu)).map(|(g, c)| g.abs_diff(c)).sum();
    assert!(moved <= 2, "{name}: the GPU keeps and drops other volumes than the CPU: {:?} against {:?}", counts(&gpu), counts(&cpu));
    assert!(cpu.volumes + cpu.total_internal_reflection + cpu.grazing + cpu.degenerate > 1000, "{name}: {cpu:?}");
    // f32 sums in different orders: a few 10⁻⁷ a term, ~10⁻⁵ over thousands.
    let total = (cpu.flux + cpu.dropped_flux).length();
    let bound = if moved == 0 { 1e-4 } else { 5e-3 };
    for (kept, gpu, cpu) in [("kept", gpu.flux, cpu.flux), ("dropped", gpu.dropped_flux, cpu.dropped_flux)] {
        assert!((gpu - cpu).length() <= bound * total, "{name}: {kept} flux {gpu:?} on the GPU, {cpu:?} on the CPU");
    }
    cpu
}

#[test]
fn caustic_volumes_built_on_the_gpu_match_the_cpu_build_frame_by_frame() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let camera = spawn_stage(&mut renderer);
    let volumes = CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.333) };
    // The camera sees the floor through the water (render layer 1).
    let ocean = renderer
        .world_mut()
        .spawn((
            Ocean { resolution: 32, size: 3.0, wind_speed: 6.0, amplitude: 2e-3, time_scale: 4.0, ..default() },
            volumes.clone(),
            Transform::from_xyz(0.0, 0.8, 0.0),
            RenderLayers::layer(1),
        ))
        .id();
    render(&mut renderer, 3);
    let passes = renderer.world_mut().resource::<CausticPassReport>().passes.clone();
    assert!(passes.iter().any(|(pass, _)| *pass == "ocean waves"), "the ocean's waves are not evaluated on the GPU: {passes:?}");
    // Half-float storage and depth-rebuilt points: ~10⁻³; the mesh a frame late is
    // far off (time runs four times fast: waves move a centimetre a frame).
    let built = |renderer: &mut HeadlessRenderer| renderer.world_mut().resource::<CausticVolumes>().clone();
    let before = built(&mut renderer);
    let (worst, late) = follow(&mut renderer, camera, ocean, 4, "ocean");
    let after = built(&mut renderer);
    assert_eq!(after.gathered, before.gathered, "the waves moved on the GPU, yet the volumes' sources were gathered on the CPU");
    assert!(after.generation > before.generation, "no counts came back as the waves moved");
    // The live comparison traces this frame's waves, not the mesh asset of the moment
    // the ocean was made.
    let traced = bevy_caustics::reference::scene_from_world(renderer.world_mut()).scene.generators[0].mesh.clone();
    assert_eq!(traced.positions(), cpu_scene(&mut renderer, &[ocean], false).generators[0].mesh.positions(), "the reference traces stale waves");
    assert!(worst < 0.01, "ocean: the GPU build's irradiance is {worst} from the CPU build's");
    assert!(late > 5.0 * worst, "ocean: a frame's caustics are as near the frame before's mesh ({late}) as to its own ({worst})");
    // Choppy waves: four transforms (the displacement and its derivatives) on the GPU.
    renderer.world_mut().get_mut::<Ocean>(ocean).unwrap().choppiness = 0.8;
    render(&mut renderer, 2);
    let (worst, _) = follow(&mut renderer, camera, ocean, 2, "choppy ocean");
    assert!(worst < 0.01, "choppy ocean: the GPU build's irradiance is {worst} from the CPU build's");
    renderer.world_mut().get_mut::<Ocean>(ocean).unwrap().time_scale = 0.0;
    assert_same_volumes(&mut renderer, &[ocean], "ocean");

    // A glass raft afloat on the waves, a second generator: the sea hides the raft's
    // vertices its waves rise over, and the raft the sea's beneath it. The sea's tree
    // among the occluders is refit on the GPU to the waves of the frame, which the
    // app's paused clock holds away from the mesh asset's.
    let raft = renderer.world_mut().resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(0.7)).mesh().subdivisions(23));
    let glass = CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.5) };
    let raft = renderer.world_mut().spawn((Mesh3d(raft), glass, Transform::from_xyz(0.1, 0.8, -0.1), RenderLayers::layer(1))).id();
    renderer.world_mut().get_mut::<Ocean>(ocean).unwrap().time_scale = 4.0;
    render(&mut renderer, 12);
    renderer.world_mut().resource_mut::<Time<Virtual>>().pause();
    let stats = assert_same_volumes(&mut renderer, &[ocean, raft], "raft on the sea");
    let passes = renderer.world_mut().resource::<CausticPassReport>().passes.clone();
    assert!(passes.iter().any(|(pass, _)| *pass == "occluder refit"), "the sea's tree was not refit: {passes:?}");
    let stale = build_scene_volumes(&cpu_scene(&mut renderer, &[ocean, raft], true), &Default::default()).stats;
    eprintln!("raft on the sea as the mesh asset stands: {stale:?}");
    assert_ne!(counts(&stale), counts(&stats), "the waves of the frame hide no other vertices than the mesh asset's: the test shows nothing");
    renderer.world_mut().resource_mut::<Time<Virtual>>().unpause();
    renderer.world_mut().despawn(raft);
    renderer.world_mut().despawn(ocean);

    // A pool rippled by two pebbles, three stones on its floor.
    let stone = renderer.world_mut().resource_mut::<Assets<Mesh>>().add(Cuboid::new(0.25, 0.12, 0.2));
    let material = white(renderer.world_mut());
    for (x, z) in [(-0.4, 0.3), (0.35, -0.2), (0.1, 0.55)] {
        renderer.world_mut().spawn((
            Mesh3d(stone.clone()),
            MeshMaterial3d(material.clone()),
            CausticReceiver,
            Transform::from_xyz(x, 0.06, z).with_rotation(Quat::from_rotation_y(x)),
        ));
    }
    let pool = renderer
        .world_mut()
        .spawn((
            PoolRipples { columns: 48, rows: 48, cell_size: 3.0 / 48.0, depth: 0.6, ..default() },
            volumes,
            Transform::from_xyz(0.0, 0.6, 0.0),
            RenderLayers::layer(1),
        ))
        .id();
    for position in [Vec3::new(-0.3, 0.6, -0.2), Vec3::new(0.4, 0.6, 0.3)] {
        renderer.world_mut().write_message(DropPebble { position, strength: 0.01 });
    }
    render(&mut renderer, 6);
    let passes = renderer.world_mut().resource::<CausticPassReport>().passes.clone();
    assert!(passes.iter().any(|(pass, _)| *pass == "pool water"), "the pool's water does not move on the GPU: {passes:?}");
    let before = built(&mut renderer);
    let (worst, late) = follow(&mut renderer, camera, pool, 4, "pool");
    assert_eq!(built(&mut renderer).gathered, before.gathered, "the water moved on the GPU, yet the volumes' sources were gathered on the CPU");
    assert!(worst < 0.01, "pool: the GPU build's irradiance is {worst} from the CPU build's");
    assert!(late > 5.0 * worst, "pool: a frame's caustics are as near the frame before's mesh ({late}) as to its own ({worst})");
    renderer.world_mut().entity_mut(pool).remove::<PoolRipples>();
    assert_same_volumes(&mut renderer, &[pool], "pool");
    renderer.world_mut().despawn(pool);

    // Dropped volumes are counted alike: light entering glass from its inside side
    // (the normals face down) 55° off vertical is lost to total internal reflection
    // where the waves tilt towards it; a mirror under a sun 89° off vertical sends its
    // rays too close to its plane (grazing).
    let waves = [Wave { kx: 5.0, kz: 1.0, amplitude: 0.06, phase: 0.3 }, Wave { kx: -1.0, kz: 6.0, amplitude: 0.05, phase: 1.1 }];
    let glass = wave_heightfield(24, 3.0, 0.8, &waves);
    let mut inverted = bevy_mesh(&glass);
    if let Some(VertexAttributeValues::Float32x3(normals)) = inverted.attribute_mut(Mesh::ATTRIBUTE_NORMAL) {
        normals.iter_mut().for_each(|n| *n = n.map(|c| -c));
    }
    let inverted = renderer.world_mut().resource_mut::<Assets<Mesh>>().add(inverted);
    let inside = CausticGenerator { double_sided: true, ..CausticGenerator::refractive(1.5) };
    let glass = renderer
        .world_mut()
        .spawn((Mesh3d(inverted.clone()), CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..inside }, RenderLayers::layer(1)))
        .id();
    let mut light = renderer.world_mut().query_filtered::<&mut Transform, With<DirectionalLight>>();
    *light.single_mut(renderer.world_mut()).unwrap() = Transform::default().looking_to(Vec3::new(1.43, -1.0, 0.0), Vec3::Y);
    let stats = assert_same_volumes(&mut renderer, &[glass], "inverted glass");
    assert!(stats.total_internal_reflection > 50 && stats.dropped_flux.x > 0.0, "{stats:?}");
    renderer.world_mut().entity_mut(glass).insert(CausticGenerator {
        technique: CausticTechnique::WarpedVolumes,
        double_sided: true,
        ..CausticGenerator::mirror()
    });
    let mut light = renderer.world_mut().query_filtered::<&mut Transform, With<DirectionalLight>>();
    *light.single_mut(renderer.world_mut()).unwrap() = Transform::default().looking_to(Vec3::new(57.0, -1.0, 0.0), Vec3::Y);
    let stats = assert_same_volumes(&mut renderer, &[glass], "grazing mirror");
    assert!(stats.grazing > 50, "{stats:?}");
}
