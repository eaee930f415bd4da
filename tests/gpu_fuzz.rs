//! The scene fuzzer's extreme scenes (`caustics_core::fuzz::valid_scene`: degenerate
//! and huge or subnormal meshes, extreme scales, IORs and dispersion, grazing light,
//! lights inside generators, on receivers and far away, a focus on the receiver,
//! photon floods) through the plugin's GPU passes on lavapipe, thirty per technique:
//! every frame comes back (a wgpu validation error stops Bevy's rendering, and the
//! readback would not), every pixel of the caustic irradiance buffer is finite and
//! non-negative, and each technique's pass ran on some of them (a technique that does
//! not apply to a scene — illumination textures on an open surface — falls back).
//!
//! The same for convolution caustics with thirty of the fuzzer's adversarial pools.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::prelude::*;
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::reference::spawn_scene_content;
use bevy_caustics::{CausticGenerator, CausticReceiver, DropPebble, PoolRipples};
use bevy_caustics::{CausticPassReport, CausticTechnique};
use caustics_core::fuzz::{valid_pool, valid_scene};
use support::render;

const SCENES_PER_TECHNIQUE: usize = 30;
const SIZE: u32 = 32;

#[test]
fn extreme_scenes_give_finite_caustics_with_every_technique() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let camera = renderer.world_mut().spawn((support::top_down_camera(target, 4.0, SIZE, Vec3::ZERO), Msaa::Off)).id();
    for (technique, pass) in [
        (CausticTechnique::WarpedVolumes, "volumes"),
        (CausticTechnique::HierarchicalMaps, "caustic map projection"),
        (CausticTechnique::IlluminationTextures, "illumination textures projection"),
    ] {
        let scenes = (0..).filter_map(|index| valid_scene(11, index).map(|(c, s)| (index, c, s))).filter(|(.., s)| !s.generators.is_empty());
        let mut ran = 0;
        for (index, category, scene) in scenes.take(SCENES_PER_TECHNIQUE) {
            spawn_scene_content(renderer.world_mut(), &scene, scene.receivers.len(), Some(technique));
            render(&mut renderer, 3);
            let irradiance = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
            let bad = irradiance.iter().find(|e| !e.is_finite() || e.min_element() < 0.0);
            assert!(bad.is_none(), "{technique:?}, case {index} ({category:?}): a pixel holds {bad:?}");
            ran += usize::from(renderer.world_mut().resource::<CausticPassReport>().views(pass) > 0);
            let world = renderer.world_mut();
            let spawned: Vec<Entity> =
                world.query_filtered::<Entity, Or<(With<Mesh3d>, With<DirectionalLight>, With<PointLight>, With<SpotLight>)>>().iter(world).collect();
            for entity in spawned {
                world.despawn(entity);
            }
        }
        eprintln!("{technique:?}: its pass ran on {ran} of {SCENES_PER_TECHNIQUE} extreme scenes");
        assert!(ran > 0, "{technique:?}: its pass never ran");
    }
    extreme_pools_give_finite_floors(&mut renderer, camera);
}

/// Convolution caustics: thirty of the fuzzer's adversarial pools (`valid_pool`: one
/// texel to 64², cells from a micrometre to a kilometre, waves and damping at their
/// extremes, grazing to overhead suns from dark to 10³⁰ lux, indices from 1 to 50, from
/// none to two hundred pebbles on walls and corners), each under its sun with its floor
/// as a receiver, a few frames while the pebbles ripple.
fn extreme_pools_give_finite_floors(renderer: &mut HeadlessRenderer, camera: Entity) {
    let pools = (0..).filter_map(|index| valid_pool(11, index).map(|pool| (index, pool)));
    let mut ran = 0;
    for (index, case) in pools.take(SCENES_PER_TECHNIQUE) {
        let light = case.light;
        let pool = PoolRipples {
            columns: case.columns as u32,
            rows: case.rows as u32,
            cell_size: case.cell_size,
            wave_number: case.waves.wave_number,
            angular_frequency: case.waves.angular_frequency,
            time_damping: case.waves.time_damping,
            front_damping: case.waves.front_damping,
            expiry_height: case.waves.expiry_height,
            depth: light.depth,
            exponent: light.exponent,
            extinction: light.extinction,
            kernel_radius: light.kernel_radius as u32,
        };
        let size = pool.size();
        let world = renderer.world_mut();
        let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(size.x, size.y));
        let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
        let water = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { alpha_mode: AlphaMode::Blend, ..default() });
        let sun = Vec3::from_array(light.sun_direction.to_array());
        world.spawn((Mesh3d(floor), MeshMaterial3d(white), CausticReceiver, Transform::from_xyz(0.0, -light.depth, 0.0)));
        world.spawn((
            DirectionalLight { illuminance: light.sun_irradiance, ..default() },
            Transform::default().looking_to(sun, if sun.y.abs() > 0.9 { Vec3::X } else { Vec3::Y }),
        ));
        world.spawn((pool, MeshMaterial3d(water), CausticGenerator { technique: CausticTechnique::Convolution, ..CausticGenerator::refractive(light.ior) }));
        render(renderer, 1);
        for &(at, strength) in &case.pebbles {
            renderer.world_mut().write_message(DropPebble { position: Vec3::new(at.x - 0.5 * size.x, 0.0, at.y - 0.5 * size.y), strength });
        }
        render(renderer, 3);
        let irradiance = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
        let bad = irradiance.iter().find(|e| !e.is_finite() || e.min_element() < 0.0);
        assert!(bad.is_none(), "pool {index} ({case:?}): a pixel holds {bad:?}");
        ran += usize::from(renderer.pass_report().views("pool floor") > 0);
        let world = renderer.world_mut();
        let spawned: Vec<Entity> = world.query_filtered::<Entity, Or<(With<Mesh3d>, With<DirectionalLight>, With<PoolRipples>)>>().iter(world).collect();
        for entity in spawned {
            world.despawn(entity);
        }
    }
    eprintln!("Convolution: its pass ran on {ran} of {SCENES_PER_TECHNIQUE} extreme pools");
    assert!(ran > 0, "the convolution pass never ran");
}
