//! Convolution caustics on a real adapter (lavapipe in CI) against their CPU twin in
//! `caustics_core::convolution`: the heights of scripted pebbles' ripples and the floor
//! irradiance they make, the pass report (no pool work, no convolution pass) and
//! stiff cases that must leave every pixel finite.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

#![cfg(feature = "convolution")]

mod support;

use bevy::camera::visibility::RenderLayers;
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_caustics::convolution::{PoolGpu, PoolRipples, PoolSurface};
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::{CausticGenerator, CausticReceiver, CausticTechnique, DropPebble};
use caustics_core::convolution::ConvolutionCaustics;
use caustics_core::metrics::relative_l2;
use std::time::Duration;
use support::{caustic_irradiance, render, render_without_caustics};

const SIZE: u32 = 96;
/// The pool and the view are `VIEW` metres across, centred on the origin, seen from above.
const VIEW: f32 = 2.0;
const DEPTH: f32 = 0.5;
/// About 22° off zenith: the lobe is expanded about its refracted direction, and the
/// walls see the mirrored kernels.
const SUN: Vec3 = Vec3::new(0.35, -1.0, -0.2);
const ILLUMINANCE: f32 = 10.0;
const IOR: f32 = 1.333;

/// The pool point (x, z from 0 to `VIEW`) seen at the centre of pixel (x, y): screen
/// right = +x, screen up = −z.
fn pool_point(x: u32, y: u32) -> Vec2 {
    let s = VIEW / SIZE as f32;
    Vec2::new((x as f32 + 0.5) * s, (y as f32 + 0.5) * s)
}

fn pool() -> PoolRipples {
    PoolRipples { columns: 48, rows: 48, cell_size: VIEW / 48.0, depth: DEPTH, exponent: 40.0, extinction: 0.2, kernel_radius: 4, ..default() }
}

/// A floor receiver under the pool, the pool's water on render layer 1 (the camera
/// sees the floor through it), a sun and a camera looking straight down.
fn spawn_scene(renderer: &mut HeadlessRenderer) -> Entity {
    let target = renderer.render_target();
    let world = renderer.world_mut();
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    world.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(50)));
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(2.0)).mesh());
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 1.0, ..default() });
    world.spawn((Mesh3d(floor), MeshMaterial3d(white.clone()), CausticReceiver, Transform::from_xyz(0.0, -DEPTH, 0.0)));
    let water = CausticGenerator { technique: CausticTechnique::Convolution, ..CausticGenerator::refractive(IOR) };
    let pool = world.spawn((pool(), water, MeshMaterial3d(white), RenderLayers::layer(1))).id();
    world.spawn((DirectionalLight { illuminance: ILLUMINANCE, shadow_maps_enabled: false, ..default() }, Transform::default().looking_to(SUN, Vec3::Y)));
    world.spawn(support::top_down_camera(target, VIEW, SIZE, Vec3::new(0.0, -DEPTH, 0.0)));
    pool
}

/// The core's heights of the pool's water at this frame's time (the GPU moves the
/// water, so the main world evaluates none).
fn heights_now(world: &mut World, pool: Entity) -> caustics_core::convolution::Heightfield {
    let time = world.resource::<Time>().elapsed_secs();
    world.get::<PoolSurface>(pool).unwrap().ripples().heightfield(time).unwrap()
}

/// The CPU twin: the convolution of the main world's heights, interpolated between
/// texel centres at each pixel's floor point as the projection does.
fn cpu_twin(renderer: &mut HeadlessRenderer, pool_entity: Entity) -> Vec<f32> {
    let world = renderer.world_mut();
    let pool = world.get::<PoolRipples>(pool_entity).unwrap().clone();
    let heightfield = heights_now(world, pool_entity);
    let light = pool.light(IOR, SUN.normalize(), ILLUMINANCE);
    let floor = ConvolutionCaustics::new(&light, 48, 48, pool.cell_size).unwrap().irradiance(&heightfield).unwrap();
    let at = |c: i32, r: i32| floor[(r.clamp(0, 47) * 48 + c.clamp(0, 47)) as usize];
    (0..SIZE * SIZE)
        .map(|i| {
            let t = pool_point(i % SIZE, i / SIZE) / pool.cell_size - 0.5;
            let (base, f) = (t.floor(), t - t.floor());
            let (c, r) = (base.x as i32, base.y as i32);
            let lerp = |a: f32, b: f32, s: f32| a + (b - a) * s;
            lerp(lerp(at(c, r), at(c + 1, r), f.x), lerp(at(c, r + 1), at(c + 1, r + 1), f.x), f.y)
        })
        .collect()
}

/// The heights the GPU computed in the last frame, copied back from its buffer.
fn gpu_heights(renderer: &mut HeadlessRenderer, pool: Entity) -> Vec<f32> {
    let world = renderer.app.sub_app_mut(bevy::render::RenderApp).world_mut();
    let heights = world.resource::<PoolGpu>().heights(pool).expect("the pool's heights are on the GPU").clone();
    support::read_buffer(renderer, &heights).chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
}

#[test]
fn convolution_caustics_match_their_cpu_twin_on_a_real_adapter() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let pool = spawn_scene(&mut renderer);

    // No technique available: no convolution work, the baseline image.
    let without = render_without_caustics(&mut renderer, 3);
    let report = renderer.pass_report();
    assert_eq!((report.views("convolution"), report.views("pool floor")), (0, 0), "{report:?}");

    // Still water: the floor gets L·T(θ)·cos θ·e^(−ε d) away from the walls, computed
    // in the first frame; the frames after it keep that floor and compute nothing.
    let still = caustic_irradiance(&render(&mut renderer, 3), &without);
    let report = renderer.pass_report();
    assert_eq!((report.views("convolution"), report.views("pool floor")), (0, 1), "still water computed again: {report:?}");
    let cpu = cpu_twin(&mut renderer, pool);
    let error = relative_l2(&still, &cpu);
    eprintln!("GPU vs CPU twin, still water: relative L2 {error:.2e}");
    assert!(error < 0.01, "still water: relative L2 {error}");

    // Scripted pebbles, then time stops so that the image and the main world's heights
    // belong to the same instant.
    for (x, z) in [(0.3, -0.2), (-0.5, 0.4), (0.1, 0.6)] {
        renderer.world_mut().write_message(DropPebble { position: Vec3::new(x, 0.0, z), strength: 0.004 });
        render(&mut renderer, 4);
    }
    renderer.world_mut().insert_resource(TimeUpdateStrategy::ManualDuration(Duration::ZERO));
    let rippled = caustic_irradiance(&render(&mut renderer, 3), &without);
    assert_eq!(renderer.pass_report().views("convolution"), 1, "moving water is not computed every frame");
    // The same ripples on both sides: the GPU's f32 sums against the core's f64 ones.
    let gpu = gpu_heights(&mut renderer, pool);
    let cpu = heights_now(renderer.world_mut(), pool).heights().to_vec();
    let highest = cpu.iter().fold(0.0f32, |m, h| m.max(h.abs()));
    let worst = gpu.iter().zip(&cpu).map(|(g, c)| (g - c).abs()).fold(0.0f32, f32::max);
    eprintln!("GPU vs CPU heights: largest difference {worst:.2e} m, highest wave {highest:.2e} m");
    assert_eq!(gpu.len(), cpu.len());
    assert!(highest > 1e-4 && worst < 1e-4 * highest, "heights differ by {worst} (waves up to {highest})");
    let cpu = cpu_twin(&mut renderer, pool);
    assert!(rippled.iter().all(|e| e.is_finite()));
    let mean = cpu.iter().sum::<f32>() / cpu.len() as f32;
    let spread = (cpu.iter().map(|e| (e - mean).powi(2)).sum::<f32>() / cpu.len() as f32).sqrt();
    assert!(spread > 0.05 * mean, "the pebbles made no caustics (spread {spread}, mean {mean})");
    // The GPU sums the ripples in f32 where the CPU sums them in f64, and stores E·exposure
    // in half floats (11 significant bits): a few 10⁻³.
    let error = relative_l2(&rippled, &cpu);
    eprintln!("GPU vs CPU twin, rippled water: relative L2 {error:.2e} (mean {mean:.3} lux, spread {spread:.3})");
    assert!(error < 0.01, "rippled water: relative L2 {error}");
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("gpu_convolution_pool.png");
    render(&mut renderer, 1).save_png(&path, 0.5).unwrap();

    // A narrow lobe (n = 1000, the sliders' range) on steep ripples: the signed
    // kernels undershoot, and the GPU lifts the floor to non-negative like the twin.
    renderer.world_mut().insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(20)));
    for (x, z) in [(0.2, 0.1), (-0.3, -0.4)] {
        renderer.world_mut().write_message(DropPebble { position: Vec3::new(x, 0.0, z), strength: 0.05 });
        render(&mut renderer, 6);
    }
    renderer.world_mut().insert_resource(TimeUpdateStrategy::ManualDuration(Duration::ZERO));
    renderer.world_mut().get_mut::<PoolRipples>(pool).unwrap().exponent = 1000.0;
    let narrow = caustic_irradiance(&render(&mut renderer, 3), &without);
    let cpu = cpu_twin(&mut renderer, pool);
    let signed = {
        let world = renderer.world_mut();
        let settings = world.get::<PoolRipples>(pool).unwrap().light(IOR, SUN.normalize(), ILLUMINANCE);
        let heightfield = heights_now(world, pool);
        ConvolutionCaustics::new(&settings, 48, 48, heightfield.cell_size()).unwrap().signed_irradiance(&heightfield).unwrap()
    };
    let lowest = signed.iter().copied().fold(f32::INFINITY, f32::min);
    let error = relative_l2(&narrow, &cpu);
    eprintln!(
        "n = 1000: the signed sum reaches {lowest:.3} lux; GPU vs CPU twin relative L2 {error:.2e}, lowest GPU pixel {:.3}",
        narrow.iter().copied().fold(f32::INFINITY, f32::min)
    );
    assert!(lowest < 0.0, "the narrow lobe's signed sum stays positive: the case tests nothing");
    assert!(error < 0.01, "narrow lobe: relative L2 {error}");
    assert!(narrow.iter().all(|&e| e > -1e-3 * ILLUMINANCE), "the GPU subtracts light");

    // Stiff cases, each leaving every pixel finite: a kernel wider than the pool, three
    // hundred impulses at once, a grazing sun, extinction that absorbs everything and
    // a lobe at the largest exponent.
    renderer.world_mut().insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(20)));
    let finite = |renderer: &mut HeadlessRenderer, case: &str| {
        let image = render(renderer, 3);
        assert!(image.pixels.iter().all(|p| p.is_finite()), "{case}: a pixel is not finite");
        assert_eq!(renderer.pass_report().views("pool floor"), 1, "{case}: {:?}", renderer.pass_report());
    };
    // A kernel wider than the pool, on still time: the same floor as the twin's.
    renderer.world_mut().get_mut::<PoolRipples>(pool).unwrap().kernel_radius = 60;
    renderer.world_mut().insert_resource(TimeUpdateStrategy::ManualDuration(Duration::ZERO));
    finite(&mut renderer, "kernel wider than the pool");
    let wide = caustic_irradiance(&render(&mut renderer, 3), &without);
    let cpu = cpu_twin(&mut renderer, pool);
    let error = relative_l2(&wide, &cpu);
    eprintln!("GPU vs CPU twin, a kernel wider than the pool: relative L2 {error:.2e}");
    assert!(cpu.iter().sum::<f32>() > 0.0 && error < 0.01, "wide kernel: relative L2 {error}");
    renderer.world_mut().insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(20)));
    for i in 0..300 {
        let (x, z) = ((i % 17) as f32 / 17.0 - 0.5, (i % 23) as f32 / 23.0 - 0.5);
        renderer.world_mut().write_message(DropPebble { position: Vec3::new(1.9 * x, 0.0, 1.9 * z), strength: 0.01 });
    }
    finite(&mut renderer, "300 impulses");
    assert!(renderer.world_mut().get::<PoolSurface>(pool).unwrap().ripples().impulses().len() >= 300);
    let mut sun = renderer.world_mut().query_filtered::<&mut Transform, With<DirectionalLight>>();
    *sun.single_mut(renderer.world_mut()).unwrap() = Transform::default().looking_to(Vec3::new(1.0, -0.01, 0.0), Vec3::Y);
    finite(&mut renderer, "grazing sun");
    let mut settings = renderer.world_mut().get_mut::<PoolRipples>(pool).unwrap();
    (settings.extinction, settings.exponent) = (1.0e30, caustics_core::convolution::MAX_EXPONENT);
    finite(&mut renderer, "total extinction, narrowest lobe");
}
