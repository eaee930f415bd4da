//! Illumination textures on a real adapter (lavapipe in CI) against their CPU twin in
//! `caustics_core::illumination_textures`: the planes' textures the GPU draws, the
//! irradiance it projects into the view (caustics and the block's shadow), a glass slab
//! transmitting `E cos θ T₁T₂`, a ball's caustic carrying the flux the table says, the
//! table made once while the ball and the light move, and no work without generators.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

#![cfg(feature = "illumination-textures")]

mod support;

use bevy::camera::visibility::RenderLayers;
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::render_resource::TextureFormat;
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::illumination_textures::{IlluminationFrames, IlluminationTexturesGpu, IlluminationTexturesSettings, LightTransportTables};
use bevy_caustics::pixels::decode_rgba16f;
use bevy_caustics::read_scene::bevy_mesh;
use bevy_caustics::{CausticGenerator, CausticReceiver, CausticTechnique};
use caustics_core::glam::{Vec3 as V3, Vec4 as V4};
use caustics_core::illumination_textures::{Cosine, IlluminationTextures};
use caustics_core::mesh::TriMesh;
use caustics_core::metrics::relative_l2;
use caustics_core::optics::{fresnel_transmittance, refract};
use support::{read_buffer, render};

const SIZE: u32 = 96;
/// The view is `VIEW` metres across, centred on the origin, looking down.
const VIEW: f32 = 2.0;

/// World point seen at the centre of pixel (x, y) on the floor: screen right = +x,
/// screen up = −z.
fn world_at(x: u32, y: u32) -> V3 {
    V3::from_array(support::floor_point(x, y, SIZE, VIEW).to_array())
}

fn ball() -> TriMesh {
    TriMesh::uv_sphere(V3::ZERO, 0.35, 16, 32)
}

fn floor() -> TriMesh {
    TriMesh::quad(V3::ZERO, V3::Z * 3.0, V3::X * 3.0)
}

/// An opaque block that takes part of the ball's light, and shadows the floor behind it.
fn block() -> TriMesh {
    TriMesh::cuboid(V3::new(0.2, 0.0, -0.8), V3::new(0.45, 0.25, 0.8))
}

/// A floor that receives, a block that casts shadows, a glass ball on render layer 1
/// (the camera sees the floor through it) drawn with illumination textures, a point
/// light above and a camera looking straight down.
fn spawn_scene(renderer: &mut HeadlessRenderer) -> [Entity; 4] {
    let target = renderer.render_target();
    let world = renderer.world_mut();
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    world.insert_resource(IlluminationTexturesSettings { texture_size: 128, table_directions: 8, cache_dir: None, ..default() });
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 1.0, ..default() });
    let mesh = |world: &mut World, m: &TriMesh| world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(m));
    let floor_mesh = mesh(world, &floor());
    world.spawn((Mesh3d(floor_mesh), MeshMaterial3d(white.clone()), CausticReceiver));
    let block_mesh = mesh(world, &block());
    let block = world.spawn((Mesh3d(block_mesh), MeshMaterial3d(white.clone()))).id();
    let ball_mesh = mesh(world, &ball());
    let glass = CausticGenerator { technique: CausticTechnique::IlluminationTextures, ..CausticGenerator::refractive(1.5) };
    let ball = world.spawn((Mesh3d(ball_mesh), MeshMaterial3d(white), glass, RenderLayers::layer(1), Transform::from_xyz(0.0, 1.0, 0.0))).id();
    let light = PointLight { intensity: 4.0 * std::f32::consts::PI * 400.0, range: 100.0, shadow_maps_enabled: false, ..default() };
    let light = world.spawn((light, Transform::from_xyz(-0.3, 4.0, 0.2))).id();
    let camera = world.spawn(support::top_down_camera(target, VIEW, SIZE, Vec3::ZERO)).id();
    [ball, light, block, camera]
}

fn gpu(renderer: &mut HeadlessRenderer) -> &IlluminationTexturesGpu {
    renderer.app.sub_app_mut(RenderApp).world().resource::<IlluminationTexturesGpu>()
}

/// Renders until the textures of the current scene are drawn and projected (they are
/// set up off the frame), then `frames` more.
fn render_textures(renderer: &mut HeadlessRenderer, frames: u32) {
    let before = renderer.world_mut().resource::<IlluminationFrames>().generation;
    for _ in 0..100 {
        render(renderer, 1);
        let after = renderer.world_mut().resource::<IlluminationFrames>().generation;
        if after > before && renderer.pass_report().views("illumination textures projection") > 0 {
            break;
        }
    }
    render(renderer, frames);
}

/// Frame `index`'s texture array read back: every plane's texels, row-major.
fn read_textures(renderer: &mut HeadlessRenderer, index: usize) -> Vec<Vec<V4>> {
    let texture = gpu(renderer).textures(index).expect("the textures are on the GPU").clone();
    let bytes = renderer.read_texture(&texture).unwrap_or_else(|e| panic!("{e}"));
    let texels: Vec<V4> = match texture.format() {
        TextureFormat::Rgba32Float => {
            bytes.chunks_exact(16).map(|t| V4::from_array(std::array::from_fn(|c| f32::from_le_bytes(t[4 * c..4 * c + 4].try_into().unwrap())))).collect()
        }
        _ => decode_rgba16f(&bytes).into_iter().map(|e| V4::from_array(e.to_array())).collect(),
    };
    texels.chunks_exact((texture.width() * texture.height()) as usize).map(<[V4]>::to_vec).collect()
}

/// The main world's first frame, seen and drawn on the CPU: the twin.
fn twin(renderer: &mut HeadlessRenderer) -> IlluminationTextures {
    let frames = renderer.world_mut().resource::<IlluminationFrames>().clone();
    let mut frame = frames.frames[0].clone();
    assert!(frame.see(&frames.receivers), "the virtual camera sees the floor");
    frame.draw();
    frame
}

/// The GPU's depth map of frame 0 against the twin's, texel by texel: how many texels
/// see another surface (depth or normal) or other solid spans, of how many.
fn depth_map_against_twin(renderer: &mut HeadlessRenderer, twin: &IlluminationTextures) -> (usize, usize) {
    let (surface, _) = gpu(renderer).depth_map(0).expect("the depth map is on the GPU");
    let surface = surface.clone();
    let floats: Vec<f32> = read_buffer(renderer, &surface).chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
    let near = |a: f32, b: f32| (a - b).abs() <= 1e-5 * (1.0 + b.abs());
    let differ = twin
        .surface
        .iter()
        .zip(floats.chunks_exact(12))
        .filter(|(cpu, gpu)| match cpu {
            None => gpu[3] < 1e30,
            Some(s) => {
                let spans = s.solid.iter().flat_map(|&(a, b)| [a.min(1e30), b.min(1e30)]);
                !(near(gpu[3], s.depth) && V3::new(gpu[0], gpu[1], gpu[2]).dot(s.normal) > 0.9999 && gpu[4..].iter().zip(spans).all(|(&g, c)| near(g, c)))
            }
        })
        .count();
    (differ, twin.surface.len())
}

/// The floor's caustic irradiance in the view (the block's top left out: it is no
/// receiver), with the twin's at the same points.
fn floor_and_twin(renderer: &mut HeadlessRenderer, camera: Entity, twin: &IlluminationTextures) -> (Vec<f32>, Vec<f32>) {
    let image = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
    let on_block = |p: V3| (0.2..=0.45).contains(&p.x) && (-0.8..=0.8).contains(&p.z);
    (0..SIZE * SIZE)
        .map(|i| (world_at(i % SIZE, i / SIZE), image[i as usize].x))
        .filter(|(p, _)| !on_block(*p))
        .map(|(p, gpu)| (gpu, twin.irradiance_at(p, V3::Y, Cosine::Receiver).x))
        .unzip()
}

#[test]
fn illumination_textures_match_their_cpu_twin_on_a_real_adapter() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let [ball, light, block, camera] = spawn_scene(&mut renderer);

    // The textures are drawn once, then only projected while nothing changes.
    render_textures(&mut renderer, 0);
    let drawn: u32 = (0..4)
        .map(|_| {
            render(&mut renderer, 1);
            renderer.pass_report().views("illumination textures")
        })
        .sum();
    let report = renderer.pass_report();
    assert_eq!((drawn, report.views("illumination textures projection")), (0, 1), "{report:?}");
    assert_eq!(gpu(&mut renderer).frame_count(), 1);

    // What the virtual camera saw on the GPU against the twin: the floor, and the
    // block's solid spans.
    let twin = twin(&mut renderer);
    let (differ, texels) = depth_map_against_twin(&mut renderer, &twin);
    let solid = twin.surface.iter().flatten().filter(|s| s.solid[0].1 < f32::INFINITY).count();
    eprintln!("depth map: {differ} of {texels} texels differ from the twin's; {solid} see a solid span with a far side");
    assert!(solid > 100, "the block's spans are in the depth map");
    assert!(differ * 1000 <= texels, "{differ} of {texels} texels of the depth map differ");

    // The GPU's textures against the twin's, plane by plane: the light vector and eq. 3.
    let textures = read_textures(&mut renderer, 0);
    let format = gpu(&mut renderer).format().unwrap();
    eprintln!("illumination textures in {format:?}");
    assert_eq!(textures.len(), twin.planes.len());
    for (k, (gpu_plane, cpu_plane)) in textures.iter().zip(&twin.planes).enumerate() {
        // The light vector as a whole (its components change sign across the caustic),
        // and eq. 3.
        let vector = |t: &[V4]| t.iter().flat_map(|e| [e.x, e.y, e.z]).collect::<Vec<f32>>();
        let eq3 = |t: &[V4]| t.iter().map(|e| e.w).collect::<Vec<f32>>();
        let errors = [relative_l2(&vector(gpu_plane), &vector(&cpu_plane.texture)), relative_l2(&eq3(gpu_plane), &eq3(&cpu_plane.texture))];
        eprintln!("plane {k}: GPU vs twin relative L2 {:.2e} (light vector), {:.2e} (eq. 3)", errors[0], errors[1]);
        if std::env::var("DEBUG_TEXELS").is_ok() {
            let mut worst: Vec<usize> = (0..gpu_plane.len()).collect();
            worst.sort_by(|&a, &b| (gpu_plane[b].w - cpu_plane.texture[b].w).abs().total_cmp(&(gpu_plane[a].w - cpu_plane.texture[a].w).abs()));
            for &i in &worst[..10] {
                eprintln!("  texel ({}, {}): gpu {:?} cpu {:?}", i % 128, i / 128, gpu_plane[i], cpu_plane.texture[i]);
            }
            let (g, c): (f32, f32) = (gpu_plane.iter().map(|e| e.w).sum(), cpu_plane.texture.iter().map(|e| e.w).sum());
            eprintln!("  sums gpu {g} cpu {c}");
        }
        // 32-bit floats where the GPU blends them (lavapipe does), else half floats
        // rounded at every one of the hundreds of volumes a focal texel adds.
        let tolerance = if format == TextureFormat::Rgba32Float { 1e-4 } else { 3e-2 };
        assert!(errors.iter().all(|&e| e < tolerance), "plane {k}: {errors:?}");
    }

    // The irradiance the GPU projects against the twin's at each floor pixel: caustics
    // and the block's shadow from the same pass.
    let (floor_gpu, floor_cpu) = floor_and_twin(&mut renderer, camera, &twin);
    let error = relative_l2(&floor_gpu, &floor_cpu);
    let peak = floor_cpu.iter().copied().fold(0.0, f32::max);
    let dark = floor_cpu.iter().filter(|&&e| e == 0.0).count();
    eprintln!("floor: GPU vs twin relative L2 {error:.2e}, peak {peak:.1} lx, {dark} pixels dark in both");
    assert!(peak > 10.0 && dark > 100);
    assert!(error < 5e-3, "floor: {error}");

    // Moving the ball and the light sets the planes up again from the same table.
    for step in 1..=3 {
        renderer.world_mut().entity_mut(ball).get_mut::<Transform>().unwrap().translation.x = 0.05 * step as f32;
        renderer.world_mut().entity_mut(ball).get_mut::<Transform>().unwrap().rotate_y(0.3);
        renderer.world_mut().entity_mut(light).get_mut::<Transform>().unwrap().translation.z = 0.2 - 0.1 * step as f32;
        render_textures(&mut renderer, 0);
    }
    let tables = renderer.world_mut().resource::<LightTransportTables>();
    assert_eq!((tables.built, tables.loaded, tables.len()), (1, 0, 1), "the table is made once");
    let twin = self::twin(&mut renderer);
    let (floor_gpu, floor_cpu) = floor_and_twin(&mut renderer, camera, &twin);
    let moved = relative_l2(&floor_gpu, &floor_cpu);
    eprintln!("after moving the ball and the light: GPU vs twin {moved:.2e}");
    assert!(moved < 5e-3);

    // The ball's caustic carries the flux the table says: straight down onto the bare
    // floor, every volume's light lands in view.
    renderer.world_mut().entity_mut(light).despawn();
    renderer.world_mut().entity_mut(block).despawn();
    renderer
        .world_mut()
        .spawn((DirectionalLight { illuminance: 100.0, shadow_maps_enabled: false, ..default() }, Transform::default().looking_to(Vec3::NEG_Y, Vec3::Z)));
    render_textures(&mut renderer, 0);
    let twin = self::twin(&mut renderer);
    let image = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
    let pixel_area = (VIEW / SIZE as f32).powi(2);
    let landed: f64 = image.iter().map(|e| (e.x * pixel_area) as f64).sum();
    eprintln!("sun straight down: the floor takes {landed:.4} lm, the table sends {:.4}", twin.flux_out);
    // Pixels sample the caustic at their centres.
    assert!((landed / twin.flux_out - 1.0).abs() < 0.05, "{landed} of {}", twin.flux_out);

    // A glass slab passes E cos θ T₁T₂ to the floor under a tilted sun.
    renderer.world_mut().entity_mut(ball).despawn();
    let slab = TriMesh::tiled_box(V3::new(0.6, 0.1, 0.6), 0.2);
    let slab_mesh = renderer.world_mut().resource_mut::<Assets<Mesh>>().add(bevy_mesh(&slab));
    let glass = CausticGenerator { technique: CausticTechnique::IlluminationTextures, ..CausticGenerator::refractive(1.5) };
    renderer.world_mut().spawn((Mesh3d(slab_mesh), glass, Transform::from_xyz(-0.4, 1.0, 0.0)));
    let sun = V3::new(0.3, -1.0, 0.2).normalize();
    let mut suns = renderer.world_mut().query_filtered::<&mut Transform, With<DirectionalLight>>();
    for mut t in suns.iter_mut(renderer.world_mut()) {
        *t = Transform::default().looking_to(Vec3::from_array(sun.to_array()), Vec3::Z);
    }
    render_textures(&mut renderer, 0);
    let inside = refract(sun, V3::Y, 1.0 / 1.5).direction().unwrap();
    let expected = 100.0 * fresnel_transmittance(-sun.y, 1.0 / 1.5) * fresnel_transmittance(-inside.y, 1.5) * -sun.y;
    let image = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
    // Under the slab's middle (its light shifted along the sun by 1 m of height).
    let under: Vec<f32> = (0..SIZE * SIZE)
        .filter(|&i| {
            let p = world_at(i % SIZE, i / SIZE) - V3::new(-0.4 + 0.3, 0.0, 0.2);
            p.x.abs() < 0.3 && p.z.abs() < 0.3
        })
        .map(|i| image[i as usize].x)
        .collect();
    let worst = under.iter().map(|e| (e / expected - 1.0).abs()).fold(0.0, f32::max);
    eprintln!("slab: {} pixels within {worst:.2e} of E cos θ T₁T₂ = {expected:.3} lx", under.len());
    assert!(under.len() > 300 && worst < 1e-2, "{worst}");

    // No generator drawn with illumination textures: no illumination texture work.
    let mut generators = renderer.world_mut().query_filtered::<Entity, With<CausticGenerator>>();
    for e in generators.iter(renderer.world_mut()).collect::<Vec<_>>() {
        renderer.world_mut().entity_mut(e).despawn();
    }
    render(&mut renderer, 4);
    let report = renderer.pass_report();
    assert!(report.views("illumination textures") + report.views("illumination textures projection") == 0, "{report:?}");
    assert_eq!(gpu(&mut renderer).frame_count(), 0);
    assert!(renderer.world_mut().resource::<LightTransportTables>().is_empty(), "tables no generator uses are let go");
}
