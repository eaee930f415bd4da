//! Warped caustic volumes on a real adapter (lavapipe in CI) against their CPU twin in
//! `caustics_core::volumes`, the pass report (no medium, no volumetric pass; no
//! generators, no volume pass), and stiff cases that must leave every pixel finite.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::camera::visibility::RenderLayers;
use bevy::prelude::*;
use bevy_caustics::headless::{HeadlessRenderer, RenderedImage};
use bevy_caustics::irradiance::MAX_EXPOSED_IRRADIANCE;
use bevy_caustics::read_scene::{bevy_mesh, to_core};
use bevy_caustics::warped_volumes::{CausticVolumes, ShaftIntegral, WarpedVolumesSettings};
use bevy_caustics::{CausticGenerator, CausticTechnique, Caustics, GeneratorInteraction, ParticipatingMedium};
use caustics_core::mesh::TriMesh;
use caustics_core::metrics::relative_l2;
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{Generator, Light, LightKind, Receiver, Scene};
use caustics_core::scenes::{Wave, wave_heightfield};
use caustics_core::volumes::{BeamGrid, CausticVolume, Footprint, MediumBox, VolumeSet, build_scene_volumes, in_scattered_radiance};
use support::{caustic_irradiance, exposure, render, render_without_caustics};

const SIZE: u32 = 96;
/// The view is `VIEW` metres across, centred on the origin, looking down.
const VIEW: f32 = 2.0;
const SUN: Vec3 = Vec3::new(0.25, -1.0, -0.15);
const ILLUMINANCE: f32 = 10.0;

/// World point seen at the centre of pixel (x, y): screen right = +x, screen up = −z.
fn world_at(x: u32, y: u32) -> Vec3 {
    let s = VIEW / SIZE as f32;
    Vec3::new((x as f32 + 0.5 - SIZE as f32 / 2.0) * s, 0.0, (y as f32 + 0.5 - SIZE as f32 / 2.0) * s)
}

fn water_mesh() -> TriMesh {
    let waves = [Wave { kx: 6.0, kz: 1.0, amplitude: 0.05, phase: 0.3 }, Wave { kx: -1.0, kz: 7.0, amplitude: 0.04, phase: 1.1 }];
    wave_heightfield(24, 3.0, 0.8, &waves)
}

/// A floor receiver bigger than the view, a generator mesh on render layer 1 (the
/// camera sees layer 0 only: the floor is seen through it), a sun and a camera.
fn spawn_scene(renderer: &mut HeadlessRenderer, generator_mesh: &TriMesh, generator: CausticGenerator, sun: Vec3) -> Entity {
    let target = renderer.render_target();
    let world = renderer.world_mut();
    let white = support::white_floor_in_the_dark(world);
    let water = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(generator_mesh));
    let generator = world.spawn((Mesh3d(water), MeshMaterial3d(white), generator, RenderLayers::layer(1))).id();
    world.spawn((DirectionalLight { illuminance: ILLUMINANCE, shadow_maps_enabled: false, ..default() }, Transform::default().looking_to(sun, Vec3::Y)));
    world.spawn(support::top_down_camera(target, VIEW, SIZE, Vec3::ZERO));
    generator
}

/// The CPU twin's volumes for the scene `spawn_scene` builds.
fn cpu_volumes(mesh: &TriMesh, interaction: SpecularInteraction, sun: Vec3, settings: &WarpedVolumesSettings) -> VolumeSet {
    use caustics_core::glam::Vec3 as V;
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction: to_core(sun.normalize()), irradiance: ILLUMINANCE })],
        generators: vec![Generator::new(mesh.clone(), interaction)],
        receivers: vec![Receiver { mesh: TriMesh::quad(V::ZERO, V::Z * 2.0, V::X * 2.0), albedo: V::ONE }],
    };
    build_scene_volumes(&scene, &settings.core())
}

/// The CPU twin's caustic irradiance at every pixel's floor point, over the pixel's
/// footprint or at its centre as `settings` say.
fn cpu_twin(mesh: &TriMesh, interaction: SpecularInteraction, sun: Vec3, settings: &WarpedVolumesSettings) -> Vec<f32> {
    use caustics_core::glam::Vec3 as V;
    let set = cpu_volumes(mesh, interaction, sun, settings);
    let step = VIEW / SIZE as f32;
    let footprint = Footprint { du: V::X * step, dv: V::Z * step };
    let pixels: Vec<_> = (0..SIZE * SIZE).map(|i| (to_core(world_at(i % SIZE, i / SIZE)), V::Y, footprint)).collect();
    set.irradiance_over_at(&pixels, &settings.core()).iter().map(|e| e.x).collect()
}

fn save(image: &RenderedImage, name: &str) {
    image.save_png(&std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name), 1.0).unwrap();
}

#[test]
fn caustic_volumes_match_their_cpu_twin_on_a_real_adapter() {
    let auto_exposure = bevy::post_process::auto_exposure::AutoExposurePlugin;
    let mut renderer = HeadlessRenderer::with_plugins(SIZE, SIZE, auto_exposure).unwrap_or_else(|e| panic!("{e}"));
    let mesh = water_mesh();
    let water = CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.333) };
    let generator = spawn_scene(&mut renderer, &mesh, water.clone(), SUN);

    // No technique available: no volume pass (and nothing else to do).
    let without = render_without_caustics(&mut renderer, 4);
    assert_eq!(renderer.pass_report().views("volumes"), 0, "{:?}", renderer.pass_report());

    let settings = WarpedVolumesSettings::default();
    let with = render(&mut renderer, 4);
    save(&with, "gpu_volumes_pool.png");
    let report = renderer.pass_report();
    assert_eq!(report.views("volumes"), 1, "{report:?}");
    assert_eq!(report.views("volumetric"), 0, "no medium, no volumetric pass: {report:?}");
    let volumes = renderer.world_mut().resource::<CausticVolumes>().clone();
    assert!(volumes.stats.volumes > 900);
    // The surface pass lights small volumes in its compute pass, pixel by pixel, and
    // rasterises the others; the twin's agreement below holds for both.
    eprintln!("surface pass: {:?}", volumes.surface);
    assert!(volumes.surface.splatted > 0 && volumes.surface.splatted_pixels > 0, "{:?}", volumes.surface);

    // GPU against CPU: the same volumes, the same formula, at the same points. The GPU
    // reconstructs each point from a 32-bit depth and stores E·exposure in half floats
    // (11 significant bits, ~5·10⁻⁴), and pixel centres on a caustic triangle's edge
    // may fall on either side of it: a relative L2 of a few 10⁻³ is the expected
    // agreement; 1 % is the bound.
    let gpu = caustic_irradiance(&with, &without);
    let cpu = cpu_twin(&mesh, water.specular_interaction(), SUN, &settings);
    assert!(gpu.iter().all(|e| e.is_finite()));
    let mean = cpu.iter().sum::<f32>() / cpu.len() as f32;
    assert!(mean > 0.5 * ILLUMINANCE, "the CPU twin sees too little light ({mean})");
    let error = relative_l2(&gpu, &cpu);
    eprintln!("GPU vs CPU twin, pool, relative L2: {error:.2e} (mean irradiance {mean:.3} lux)");
    assert!(error < 0.01, "GPU and CPU caustic volumes differ: relative L2 {error}");
    // Each pixel is the mean over its footprint: the twin's point samples differ.
    let point = cpu_twin(&mesh, water.specular_interaction(), SUN, &WarpedVolumesSettings { footprint_filter: false, ..settings });
    let against_points = relative_l2(&gpu, &point);
    eprintln!("GPU (footprints) vs the twin's point samples: {against_points:.2e}");
    assert!(against_points > 3.0 * error, "the pixels are not footprint means: {against_points} vs {error}");

    // The other intensity modes and single-sampled prepasses follow the same path, and
    // every volume rasterised lights the same pixels as the compute pass, filtered and
    // point-sampled.
    for (intensity, msaa, splat_pixels, footprint_filter) in [
        (bevy_caustics::warped_volumes::VolumeIntensity::Constant, Msaa::Off, 1024, true),
        (bevy_caustics::warped_volumes::VolumeIntensity::Interpolated, Msaa::Sample4, 0, true),
        (bevy_caustics::warped_volumes::VolumeIntensity::Conserving, Msaa::Sample4, 0, false),
    ] {
        let settings = WarpedVolumesSettings { intensity, splat_pixels, footprint_filter, ..default() };
        renderer.world_mut().insert_resource(settings);
        let camera = renderer.world_mut().query_filtered::<Entity, With<Camera3d>>().single(renderer.world_mut()).unwrap();
        renderer.world_mut().entity_mut(camera).insert(msaa);
        let without = render_without_caustics(&mut renderer, 3);
        let gpu = caustic_irradiance(&render(&mut renderer, 3), &without);
        let error = relative_l2(&gpu, &cpu_twin(&mesh, water.specular_interaction(), SUN, &settings));
        let surface = renderer.world_mut().resource::<CausticVolumes>().surface;
        eprintln!("GPU vs CPU twin, {intensity:?}, {msaa:?}, {surface:?}: {error:.2e}");
        assert!(error < 0.01, "{intensity:?} {msaa:?} {surface:?}: relative L2 {error}");
        assert_eq!(surface.splatted == 0, splat_pixels == 0, "{surface:?}");
        assert_eq!(surface.rasterised > 0, splat_pixels == 0, "{surface:?}");
    }

    // A medium in view: the volumetric pass runs, and adds the CPU twin's
    // in-scattered radiance (§3.5) along each pixel's ray down to the floor, each
    // channel dimmed by its own σₜ. The floor turns black, so that the half-float image
    // holds the in-scattering alone.
    let mut materials = renderer.world_mut().resource_mut::<Assets<StandardMaterial>>();
    for (_, material) in materials.iter_mut() {
        material.base_color = Color::BLACK;
        material.reflectance = 0.0;
    }
    let clear = render(&mut renderer, 3);
    assert!(clear.pixels.iter().all(|p| p.x.abs() < 1e-4), "the black floor is not black");
    let medium = ParticipatingMedium { scattering: 0.3, absorption: Vec3::new(0.05, 0.3, 0.9), asymmetry: 0.5 };
    let medium_transform = Transform::from_xyz(0.0, 0.4, 0.0).with_scale(Vec3::new(4.0, 0.8, 4.0));
    let medium_entity = renderer.world_mut().spawn((medium, medium_transform)).id();
    // Every pixel integrated, to hold the pass to the twin pixel by pixel (the
    // default integrates one in sixteen, below), first through every volume.
    let exact = WarpedVolumesSettings { shaft_downsample: 1, shaft_integral: ShaftIntegral::Exact, ..default() };
    renderer.world_mut().insert_resource(exact);
    let foggy = render(&mut renderer, 3);
    save(&foggy, "gpu_volumes_medium.png");
    let report = renderer.pass_report();
    assert_eq!(report.views("volumetric"), 1, "{report:?}");
    assert!(foggy.pixels.iter().all(|p| p.is_finite()));
    let settings = *renderer.world_mut().resource::<WarpedVolumesSettings>();
    let set = cpu_volumes(&mesh, water.specular_interaction(), SUN, &settings);
    let medium_box = MediumBox {
        world_from_local: caustics_core::glam::Affine3A::from_cols_array(&medium_transform.compute_affine().to_cols_array()),
        coefficients: medium.coefficients(),
    };
    let cpu: Vec<f32> = (0..SIZE * SIZE)
        .flat_map(|i| {
            let floor = to_core(world_at(i % SIZE, i / SIZE));
            let eye = floor + caustics_core::glam::Vec3::Y * 5.0;
            in_scattered_radiance(&set.volumes, eye, floor, &medium_box, &settings.core()).to_array()
        })
        .collect();
    let added = |image: &RenderedImage| -> Vec<f32> {
        image.pixels.iter().zip(&clear.pixels).flat_map(|(a, b)| ((*a - *b).truncate() / exposure()).to_array()).collect()
    };
    let gpu = added(&foggy);
    let scattered = cpu.iter().sum::<f32>() / cpu.len() as f32;
    let error = relative_l2(&gpu, &cpu);
    eprintln!("GPU vs CPU twin, in-scattering: relative L2 {error:.2e} (mean radiance {scattered:.3})");
    // Order of magnitude: σs · 0.8 m · E · p(θ ≈ 105°, g = ½) ≈ 0.3 · 0.8 · 10 · 0.03 ≈ 0.07.
    assert!(scattered > 0.01, "too little in-scattering to compare ({scattered})");
    assert!(error < 0.01, "GPU and CPU in-scattering differ: relative L2 {error}");
    // The default: each beam deposited on a grid over the medium, each eye ray marched
    // through it in a fixed number of steps. Against its own twin pixel by pixel (the
    // deposit adds in whatever order the GPU runs it), and near the exact integral.
    let marched = WarpedVolumesSettings { shaft_downsample: 1, ..default() };
    renderer.world_mut().insert_resource(marched);
    let grid_image = render(&mut renderer, 3);
    save(&grid_image, "gpu_volumes_medium_grid.png");
    // The marched grid's CPU twin over the image, every pixel's three channels, on a
    // grid `longest` cells long, its thin beams in bundles or each alone; and how many
    // went in bundles.
    let grid_twin_of = |medium_box: MediumBox, volumes: &[CausticVolume], longest: u32, bundles: bool| -> (Vec<f32>, usize) {
        let mut grid = BeamGrid::new(medium_box, longest);
        let joined = if bundles {
            grid.deposit_all(volumes, &settings.core())
        } else {
            grid.deposit_each(volumes, &settings.core());
            0
        };
        let image = (0..SIZE * SIZE)
            .flat_map(|i| {
                let floor = to_core(world_at(i % SIZE, i / SIZE));
                grid.in_scattered_radiance(floor + caustics_core::glam::Vec3::Y * 5.0, floor, marched.shaft_steps).to_array()
            })
            .collect();
        (image, joined)
    };
    let marched_twin = |medium_box: MediumBox, volumes: &[CausticVolume]| grid_twin_of(medium_box, volumes, marched.shaft_grid, true).0;
    let grid_twin = marched_twin(medium_box, &set.volumes);
    let gpu_grid = added(&grid_image);
    let (against_twin, against_exact) = (relative_l2(&gpu_grid, &grid_twin), relative_l2(&gpu_grid, &cpu));
    eprintln!("shafts marched through the grid: relative L2 {against_twin:.2e} from its twin, {against_exact:.2e} from the exact integral's");
    assert!(against_twin < 0.01, "GPU and CPU beam grids differ: relative L2 {against_twin}");
    assert!(against_exact < 0.1, "the beam grid is far from the exact integral: relative L2 {against_exact}");
    // A grey medium, and every volume of one hue: the grid keeps the sum of the
    // channels, which the march shares out by the hue.
    let grey = ParticipatingMedium { absorption: Vec3::splat(0.3), ..medium };
    renderer.world_mut().entity_mut(medium_entity).insert(grey);
    let grey_image = render(&mut renderer, 3);
    let grey_twin = marched_twin(MediumBox { coefficients: grey.coefficients(), ..medium_box }, &set.volumes);
    let against_grey_twin = relative_l2(&added(&grey_image), &grey_twin);
    eprintln!("shafts of one hue in a grey medium: relative L2 {against_grey_twin:.2e} from the twin");
    assert!(against_grey_twin < 0.01, "GPU and CPU beam grids differ in a grey medium: relative L2 {against_grey_twin}");
    renderer.world_mut().entity_mut(medium_entity).insert(medium);
    // Two media side by side, each with its own grid, stacked in the textures: their
    // sum against their twins' (an eye ray straight down crosses one of them).
    let halves = [-1.0, 1.0].map(|x| Transform::from_xyz(x, 0.4, 0.0).with_scale(Vec3::new(2.0, 0.8, 4.0)));
    renderer.world_mut().entity_mut(medium_entity).insert(halves[0]);
    let second_medium = renderer.world_mut().spawn((medium, halves[1])).id();
    let two_media = added(&render(&mut renderer, 3));
    let twins = halves.map(|half| {
        let world_from_local = caustics_core::glam::Affine3A::from_cols_array(&half.compute_affine().to_cols_array());
        marched_twin(MediumBox { world_from_local, ..medium_box }, &set.volumes)
    });
    let two_twins: Vec<f32> = twins[0].iter().zip(&twins[1]).map(|(a, b)| a + b).collect();
    let total = two_twins.iter().sum::<f32>();
    assert!(twins.iter().all(|twin| twin.iter().sum::<f32>() > 0.25 * total), "a medium holds too little of the light to test its grid");
    let against_two_twins = relative_l2(&two_media, &two_twins);
    eprintln!("shafts in two media: relative L2 {against_two_twins:.2e} from their twins");
    assert!(against_two_twins < 0.01, "GPU and CPU beam grids differ in two media: relative L2 {against_two_twins}");
    renderer.world_mut().despawn(second_medium);
    renderer.world_mut().entity_mut(medium_entity).insert(medium_transform);
    // Cells wider than the water's triangles: beams entering a cell together go as one
    // bundle. The GPU's bundles against the twin's, nearer them than each beam alone.
    let coarse = WarpedVolumesSettings { shaft_grid: 24, ..marched };
    renderer.world_mut().insert_resource(coarse);
    let bundled = added(&render(&mut renderer, 3));
    let ((bundled_twin, joined), (each_twin, _)) = (grid_twin_of(medium_box, &set.volumes, 24, true), grid_twin_of(medium_box, &set.volumes, 24, false));
    let (against_bundles, against_each) = (relative_l2(&bundled, &bundled_twin), relative_l2(&bundled, &each_twin));
    eprintln!(
        "shafts from bundles ({joined} of {} beams): relative L2 {against_bundles:.2e} from the twin, {against_each:.2e} from each beam alone",
        set.volumes.len()
    );
    assert!(2 * joined > set.volumes.len(), "{joined} of {} beams in bundles", set.volumes.len());
    assert!(against_bundles < 0.01 && against_bundles < 0.5 * against_each, "bundled shafts: {against_bundles} from the twin, {against_each} from each beam");
    renderer.world_mut().insert_resource(marched);
    // Dispersive water: a volume a colour channel, each of its own hue, so the grid adds
    // three channels of light where one hue needs one; every channel against the twin.
    let dispersive = CausticGenerator {
        technique: CausticTechnique::WarpedVolumes,
        interaction: GeneratorInteraction::Refract { ior: 1.333, dispersion: Some(Vec2::new(1.32, 0.05)) },
        ..CausticGenerator::refractive(1.333)
    };
    renderer.world_mut().entity_mut(generator).insert(dispersive.clone());
    let coloured = render(&mut renderer, 3);
    let coloured_set = cpu_volumes(&mesh, dispersive.specular_interaction(), SUN, &settings);
    let (coloured_twin, coloured_gpu) = (marched_twin(medium_box, &coloured_set.volumes), added(&coloured));
    let channel_of = |pixels: &[f32], channel: usize| -> Vec<f32> { pixels.iter().skip(channel).step_by(3).copied().collect() };
    for channel in 0..3 {
        let (twin, gpu) = (channel_of(&coloured_twin, channel), channel_of(&coloured_gpu, channel));
        let error = relative_l2(&gpu, &twin);
        eprintln!("dispersive shafts, channel {channel}: relative L2 {error:.2e} from the twin");
        assert!(error < 0.01, "dispersive shafts, channel {channel}: relative L2 {error}");
    }
    let spread = |c: usize| coloured.pixels.iter().zip(&clear.pixels).map(|(a, b)| a[c] - b[c]).sum::<f32>();
    assert!((spread(0) - spread(2)).abs() > 1e-3 * spread(0).abs(), "the channels' shafts do not differ: no dispersion to test");
    renderer.world_mut().entity_mut(generator).insert(water.clone());
    let cpu = grid_twin;
    // The camera's Caustics: shafts at half intensity are half the twin's;
    // shafts off, no volumetric pass.
    let camera = renderer.world_mut().query_filtered::<Entity, With<Camera3d>>().single(renderer.app.world()).unwrap();
    renderer.world_mut().entity_mut(camera).insert(Caustics { intensity: 0.5, ..default() });
    let dimmed = render(&mut renderer, 3);
    let half: Vec<f32> = cpu.iter().map(|e| 0.5 * e).collect();
    let gpu = added(&dimmed);
    let error = relative_l2(&gpu, &half);
    eprintln!("GPU vs half the CPU twin, in-scattering at intensity ½: relative L2 {error:.2e}");
    assert!(error < 0.01, "shafts at intensity ½: relative L2 {error}");
    renderer.world_mut().entity_mut(camera).insert(Caustics::default());
    // The default: shafts integrated at one pixel in sixteen and spread bilinearly over
    // the image. Against every pixel's own (the GPU's, above, and the twin's).
    let full = gpu_grid;
    renderer.world_mut().insert_resource(WarpedVolumesSettings::default());
    let sampled = render(&mut renderer, 3);
    let gpu = added(&sampled);
    let (against_full, against_twin) = (relative_l2(&gpu, &full), relative_l2(&gpu, &cpu));
    eprintln!("shafts at one pixel in sixteen: relative L2 {against_full:.2e} from every pixel's, {against_twin:.2e} from the twin's");
    assert!(against_full > 0.0 && against_full < 0.03 && against_twin < 0.03, "shafts at one pixel in sixteen: {against_full}, {against_twin}");
    renderer.world_mut().entity_mut(camera).insert(Caustics { shafts: false, ..default() });
    let unlit = render(&mut renderer, 3);
    assert_eq!(renderer.pass_report().views("volumetric"), 0, "{:?}", renderer.pass_report());
    assert!(unlit.pixels.iter().zip(&clear.pixels).all(|(a, b)| (a.x - b.x).abs() < 1e-6), "shafts off, yet light in the medium");
    renderer.world_mut().entity_mut(camera).insert(Caustics::default());

    // Stiff: a glass lens 1 m up under an overhead sun, whose normals refract the light
    // exactly onto one point (n ∝ η₁ i − η₂ t, Snell's law in vector form): on the
    // floor, where the caustic triangles have zero area, and 5 cm under it, a spot
    // two pixels wide focused about 440-fold (under `max_magnification`, past which
    // the volumes leave slices out); then grazing light. The
    // floor is black and the medium still in view, so the surface pass is read from
    // its own buffer: finite everywhere, and the twin's light, peaking where the
    // twin's does.
    let down = caustics_core::glam::Vec3::NEG_Y;
    let lens_focusing_at = |focus: caustics_core::glam::Vec3| {
        TriMesh::heightfield(
            17,
            1.0,
            |_, _| 1.0,
            |x, z| {
                let to_focus = (focus - caustics_core::glam::Vec3::new(x, 1.0, z)).normalize();
                (down - 1.5 * to_focus).normalize()
            },
        )
        .unwrap()
    };
    let glass = CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.5) };
    renderer.world_mut().entity_mut(generator).insert(glass);
    let camera = renderer.world_mut().query_filtered::<Entity, With<Camera3d>>().single(renderer.app.world()).unwrap();
    let cases = [(0.0, Vec3::NEG_Y), (0.05, Vec3::NEG_Y), (0.0, Vec3::new(1.0, 1e-3, 0.0))];
    for (below, sun) in cases {
        // Off the pixel grid's symmetry, as below.
        let lens = lens_focusing_at(caustics_core::glam::Vec3::new(0.013, -below, 0.007));
        let lens_mesh = renderer.world_mut().resource_mut::<Assets<Mesh>>().add(bevy_mesh(&lens));
        renderer.world_mut().entity_mut(generator).insert(Mesh3d(lens_mesh));
        let mut lights = renderer.world_mut().query_filtered::<&mut Transform, With<DirectionalLight>>();
        for mut t in lights.iter_mut(renderer.world_mut()) {
            *t = Transform::default().looking_to(sun, Vec3::Z);
        }
        let image = render(&mut renderer, 3);
        let stored: Vec<f32> = renderer.caustic_irradiance(camera).unwrap().iter().map(|e| e.x).collect();
        assert!(image.pixels.iter().chain(&image.pixels).all(|p| p.is_finite()), "non-finite pixel with the light along {sun}");
        assert!(stored.iter().all(|e| e.is_finite() && *e >= 0.0), "non-finite or negative irradiance with the light along {sun}");
        if sun != Vec3::NEG_Y {
            continue;
        }
        let stats = renderer.world_mut().resource::<CausticVolumes>().stats;
        assert_eq!(stats.volumes, 2 * 16 * 16, "{stats:?}");
        let twin = cpu_twin(&lens, SpecularInteraction::Refract { ior: 1.5, dispersion: None }, Vec3::NEG_Y, &settings);
        if below == 0.0 {
            save(&image, "gpu_volumes_focus.png");
            // Zero-area caustic triangles hold no pixel centre: no light, in both.
            assert!(stored.iter().chain(&twin).all(|e| *e == 0.0), "light off a point focus");
            continue;
        }
        let (gpu_flux, twin_flux) = (stored.iter().sum::<f32>(), twin.iter().sum::<f32>());
        let brightest = |v: &[f32]| (0..v.len()).max_by(|&a, &b| v[a].total_cmp(&v[b])).unwrap() as u32;
        let (g, t) = (brightest(&stored), brightest(&twin));
        let apart = (g % SIZE).abs_diff(t % SIZE).max((g / SIZE).abs_diff(t / SIZE));
        let peak = twin[t as usize] / ILLUMINANCE;
        eprintln!(
            "focus 5 cm under the floor: peak {peak:.0}× the sun; the buffer holds {:.4} of the twin's light; brightest pixels {apart} apart",
            gpu_flux / twin_flux
        );
        assert!(peak > 100.0, "the spot is not focused: {peak}×");
        assert!((gpu_flux / twin_flux - 1.0).abs() < 0.01, "focus: light {gpu_flux} against the twin's {twin_flux}");
        assert!(apart <= 1, "focus: the brightest pixel is {apart} pixels from the twin's");
    }

    // Physical light: a 100 000 lux sun seen with Bevy's default exposure (EV100 9.7),
    // through lenses focusing 0.6 m below the floor (about 7-fold on it, under the cap)
    // and 0.15 m below it (about 56-fold: more than half floats hold as E·exposure).
    // The buffer holds E·exposure exactly up to MAX_EXPOSED_IRRADIANCE, the cap past it.
    // Then again with Bevy's auto exposure and bloom on the camera: auto exposure
    // scales the image after the passes (in tonemapping), so the buffer must not change,
    // and bloom must find nothing but finite light to spread.
    let mut lights = renderer.world_mut().query::<(&mut Transform, &mut DirectionalLight)>();
    for (mut t, mut light) in lights.iter_mut(renderer.world_mut()) {
        *t = Transform::default().looking_to(Vec3::NEG_Y, Vec3::Z);
        light.illuminance = bevy::light::light_consts::lux::DIRECT_SUNLIGHT;
    }
    renderer.world_mut().entity_mut(camera).insert(bevy::camera::Exposure::default());
    let cap = MAX_EXPOSED_IRRADIANCE / bevy::camera::Exposure::default().exposure();
    let scale = bevy::light::light_consts::lux::DIRECT_SUNLIGHT / ILLUMINANCE;
    for (depth, auto) in [(0.6, false), (0.6, true), (0.15, false), (0.15, true)] {
        use bevy::core_pipeline::tonemapping::Tonemapping;
        use bevy::post_process::{auto_exposure::AutoExposure, bloom::Bloom};
        let tonemapping = if auto { Tonemapping::default() } else { Tonemapping::None };
        renderer.world_mut().entity_mut(camera).remove::<(AutoExposure, Bloom)>().insert(tonemapping);
        let exposure_name = if auto { "auto exposure and bloom" } else { "default exposure" };
        // Off the pixel grid's symmetry: a pixel centre exactly on the shared side of two
        // volumes converging on a focus is a rounding tie between them.
        let focus = caustics_core::glam::Vec3::new(0.013, -depth, 0.007);
        let lens = lens_focusing_at(focus);
        let lens_mesh = renderer.world_mut().resource_mut::<Assets<Mesh>>().add(bevy_mesh(&lens));
        renderer.world_mut().entity_mut(generator).insert(Mesh3d(lens_mesh));
        let mut image = render(&mut renderer, 3);
        let mean = |image: &RenderedImage| image.pixels.iter().map(|p| p.x).sum::<f32>() / image.pixels.len() as f32;
        if auto {
            // Bevy's tonemapping with and without auto exposure, which adapts over time:
            // half a second at the headless renderer's 1/60 s a frame.
            let fixed = mean(&image);
            renderer.world_mut().entity_mut(camera).insert((AutoExposure::default(), Bloom::default()));
            image = render(&mut renderer, 30);
            eprintln!("100 000 lux, lens focusing {depth} m below: tonemapped image mean {fixed:.4}, with auto exposure {:.4}", mean(&image));
            assert!((mean(&image) - fixed).abs() > 0.1 * fixed, "auto exposure changed nothing: it did not run");
        }
        let stored: Vec<f32> = renderer.caustic_irradiance(camera).unwrap().iter().map(|e| e.x).collect();
        let twin: Vec<f32> =
            cpu_twin(&lens, SpecularInteraction::Refract { ior: 1.5, dispersion: None }, Vec3::NEG_Y, &settings).iter().map(|e| e * scale).collect();
        assert!(image.pixels.iter().all(|p| p.is_finite()) && stored.iter().all(|e| e.is_finite()), "100 000 lux, {exposure_name}: a value is not finite");
        let peak = twin.iter().copied().fold(0.0, f32::max);
        if depth > 0.5 {
            let error = relative_l2(&stored, &twin);
            eprintln!("100 000 lux, 7-fold, {exposure_name}: peak {peak:.3e} lux under the cap {cap:.3e}; GPU vs twin relative L2 {error:.2e}");
            assert!(peak > 0.2 * cap && peak < cap, "the weak lens's peak {peak} against the cap {cap}");
            assert!(error < 5e-3, "under the cap the buffer holds E: relative L2 {error}");
        } else {
            // Inside the clipped spot: a pixel and its four neighbours past the cap in the twin.
            let past = |x: u32, y: u32| twin[(y * SIZE + x) as usize] > cap;
            let inside: Vec<usize> = (SIZE + 1..SIZE * (SIZE - 1) - 1)
                .filter(|&i| {
                    let (x, y) = (i % SIZE, i / SIZE);
                    past(x, y) && past(x - 1, y) && past(x + 1, y) && past(x, y - 1) && past(x, y + 1)
                })
                .map(|i| i as usize)
                .collect();
            let held = inside.iter().map(|&i| stored[i]).fold(f32::INFINITY, f32::min);
            let most = stored.iter().copied().fold(0.0, f32::max);
            eprintln!(
                "100 000 lux, 56-fold, {exposure_name}: peak {peak:.3e} lux; the buffer holds {held:.4e} to {most:.4e} inside the spot ({} pixels)",
                inside.len()
            );
            assert!(!inside.is_empty() && held >= 0.99 * cap, "past the cap the buffer holds the cap: {held} of {cap}");
            assert!(most <= 1.001 * cap, "the buffer holds {most} lux, past the cap {cap}");
        }
    }

    // A roof over the lens (any mesh that casts shadows) hides every vertex from the
    // sun: no volumes, no volume pass; the roof gone, the lens casts again.
    let slab = renderer.world_mut().resource_mut::<Assets<Mesh>>().add(Cuboid::new(3.0, 0.1, 3.0));
    let roof = renderer.world_mut().spawn((Mesh3d(slab), Transform::from_xyz(0.0, 2.0, 0.0))).id();
    render(&mut renderer, 3);
    let stats = renderer.world_mut().resource::<CausticVolumes>().stats;
    assert_eq!((stats.volumes, stats.shadowed), (0, 2 * 16 * 16), "{stats:?}");
    assert_eq!(renderer.pass_report().views("volumes"), 0, "{:?}", renderer.pass_report());
    renderer.world_mut().despawn(roof);
    render(&mut renderer, 3);
    assert_eq!(renderer.world_mut().resource::<CausticVolumes>().stats.volumes, 2 * 16 * 16);
    assert_eq!(renderer.pass_report().views("volumes"), 1, "{:?}", renderer.pass_report());

    // The sun despawned: no light, no volumes.
    let world = renderer.world_mut();
    let suns: Vec<Entity> = world.query_filtered::<Entity, With<DirectionalLight>>().iter(world).collect();
    for sun in suns {
        renderer.world_mut().despawn(sun);
    }
    render(&mut renderer, 3);
    assert_eq!(renderer.pass_report().views("volumes"), 0, "a despawned light casts no caustics: {:?}", renderer.pass_report());

    // No generators at all: no volume pass.
    renderer.world_mut().entity_mut(generator).remove::<CausticGenerator>();
    render(&mut renderer, 3);
    let report = renderer.pass_report();
    assert_eq!(report.views("volumes"), 0, "{report:?}");
    assert_eq!(report.views("volumetric"), 0, "{report:?}");
}
