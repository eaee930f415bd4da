//! The scene fuzzer's extreme scenes (`caustics_core::fuzz::valid_scene`: degenerate
//! and huge or subnormal meshes, extreme scales, IORs and dispersion, grazing light,
//! lights inside generators, on receivers and far away, a focus on the receiver,
//! photon floods) through the plugin's GPU passes on lavapipe, thirty per technique:
//! every frame comes back (a wgpu validation error stops Bevy's rendering, and the
//! readback would not), every pixel of the caustic irradiance buffer is finite and
//! non-negative, and each technique's pass ran on some of them (a technique that does
//! not apply to a scene — illumination textures on an open surface — falls back).
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::prelude::*;
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::reference::spawn_scene_content;
use bevy_caustics::{CausticPassReport, CausticTechnique};
use caustics_core::fuzz::valid_scene;
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
            spawn_scene_content(renderer.world_mut(), &scene, Some(technique));
            render(&mut renderer, 3);
            let irradiance = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
            let bad = irradiance.iter().find(|e| !e.is_finite() || e.min_element() < 0.0);
            assert!(bad.is_none(), "{technique:?}, case {index} ({category:?}): a pixel holds {bad:?}");
            ran += usize::from(renderer.world_mut().resource::<CausticPassReport>().views(pass) > 0);
            let world = renderer.world_mut();
            let spawned: Vec<Entity> = world
                .query_filtered::<Entity, Or<(With<Mesh3d>, With<DirectionalLight>, With<PointLight>, With<SpotLight>)>>()
                .iter(world)
                .collect();
            for entity in spawned {
                world.despawn(entity);
            }
        }
        eprintln!("{technique:?}: its pass ran on {ran} of {SCENES_PER_TECHNIQUE} extreme scenes");
        assert!(ran > 0, "{technique:?}: its pass never ran");
    }
}
