//! Receivers seen at a slant through a multisampled view, on lavapipe. Bevy's cameras
//! multisample by default (`Msaa::Sample4`): the depth prepass keeps sample 0 off the
//! pixel's centre, and a receiver point rebuilt at the centre from that depth leaves its
//! surface by the depth's slope over the offset — centimetres on a surface seen at a
//! slant. The caustic volumes then found it behind its own receiver (behind the
//! volumes' hit planes) and dropped it: the demo's shelf, just under the water, was dark.
//!
//! The scene has a known answer: still water over a block, under a sun. Every point of
//! the block's top gets the sun's horizontal irradiance times the water's Fresnel
//! transmittance (flux per horizontal area is kept through a flat interface). The block
//! is seen from the demo's camera, at a slant, with 4 samples per pixel; each technique
//! that draws the water must give that irradiance at every pixel that sees the block's
//! top.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

use bevy::camera::Exposure;
use bevy::prelude::*;
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::{CausticGenerator, CausticReceiver, CausticTechnique, Caustics, PoolRipples};
use caustics_core::optics::fresnel_transmittance;

mod support;

const SIZE: u32 = 96;
const SUN: Vec3 = Vec3::new(0.5, -0.8, -0.2);
const SUN_LUX: f32 = 10_000.0;
/// The block's top, 15 cm under the water (as the demo's shelf), and its half width.
const TOP: f32 = -0.15;
const HALF: f32 = 1.0;

#[test]
fn receivers_seen_at_a_slant_through_a_multisampled_view_get_their_caustics() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let world = renderer.world_mut();
    let block = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(2.0 * HALF, 0.1, 2.0 * HALF));
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 1.0, ..default() });
    world.spawn((Mesh3d(block), MeshMaterial3d(white), CausticReceiver, Transform::from_xyz(0.0, TOP - 0.05, 0.0)));
    // Drawn with transmission, the water is not in the depth prepass: the receiver
    // points are the block's.
    let water = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { specular_transmission: 0.9, thickness: 0.3, ior: 1.333, ..default() });
    let pool = PoolRipples { columns: 64, rows: 64, cell_size: 4.0 / 64.0, depth: 1.2, ..default() };
    let water = world.spawn((pool, CausticGenerator::refractive(1.333), MeshMaterial3d(water))).id();
    world.spawn((DirectionalLight { illuminance: SUN_LUX, ..default() }, Transform::default().looking_to(SUN, Vec3::Y)));
    let camera = world
        .spawn((
            Camera3d::default(),
            Caustics::default(),
            Msaa::Sample4,
            target,
            Exposure { ev100: 11.5 },
            Projection::from(PerspectiveProjection { fov: 0.9, ..default() }),
            Transform::from_xyz(-1.3, 1.8, 3.5).looking_at(Vec3::new(0.3, -0.9, -0.7), Vec3::Y),
        ))
        .id();

    let cos_i = -SUN.normalize().y;
    let expected = SUN_LUX * cos_i * fresnel_transmittance(cos_i, 1.0 / 1.333);
    for technique in [CausticTechnique::WarpedVolumes, CausticTechnique::HierarchicalMaps] {
        renderer.world_mut().get_mut::<CausticGenerator>(water).unwrap().technique = technique;
        support::render_caustics(&mut renderer, 3);
        let irradiance = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
        let world = renderer.world_mut();
        let (view, at) = world.query::<(&Camera, &GlobalTransform)>().get(world, camera).unwrap();
        // The pixels whose centre sees the block's top, 5 cm in from its edges.
        let top: Vec<f32> = (0..SIZE * SIZE)
            .filter(|&i| {
                let ray = view.viewport_to_world(at, Vec2::new((i % SIZE) as f32 + 0.5, (i / SIZE) as f32 + 0.5)).unwrap();
                let p = ray.get_point((TOP - ray.origin.y) / ray.direction.y);
                p.x.abs() < HALF - 0.05 && p.z.abs() < HALF - 0.05
            })
            .map(|i| irradiance[i as usize].x)
            .collect();
        let dark = top.iter().filter(|&&e| (e - expected).abs() > 0.02 * expected).count();
        eprintln!("{technique:?}: {} pixels see the block's top, {dark} off {expected:.0} lux by over 2 %", top.len());
        assert!(top.len() > 500, "the block's top fills only {} pixels", top.len());
        assert!(dark * 100 < top.len(), "{technique:?}: {dark} of {} pixels of the block's top are off {expected:.0} lux", top.len());
    }
}
