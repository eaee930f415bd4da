//! Light shafts at a fixed cost per eye ray (`BeamGrid`) against the exact per-volume
//! integral of §3.5 (`in_scattered_radiance`) and against analytic beams; the exact
//! integral against the photon tracer's beams (`PhotonBeams`).

use caustics_core::estimate::PhotonBeams;
use caustics_core::glam::{Affine3A, Quat, Vec2, Vec3};
use caustics_core::mesh::TriMesh;
use caustics_core::metrics::relative_l2;
use caustics_core::ocean::{OceanSettings, OceanSpectrum};
use caustics_core::params::{MediumCoefficients, SpecularInteraction};
use caustics_core::scene::{Generator, Light, LightKind, Receiver, Scene};
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use caustics_core::view::PinholeCamera;
use caustics_core::volumes::{BeamGrid, MediumBox, VolumeSettings, build_scene_volumes, in_scattered_radiance};
use rayon::prelude::*;

fn floor(size: f32, y: f32) -> Receiver {
    Receiver { mesh: TriMesh::quad(Vec3::Y * y, Vec3::Z * (0.5 * size), Vec3::X * (0.5 * size)), albedo: Vec3::ONE }
}

/// A 1 m² sheet of IOR 1 at y = 2 under a unit sun straight down: a parallel beam to
/// the floor, in an 8 m medium.
fn beam(coefficients: MediumCoefficients) -> (Vec<caustics_core::volumes::CausticVolume>, MediumBox) {
    let mesh = TriMesh::heightfield(5, 1.0, |_, _| 2.0, |_, _| Vec3::Y).unwrap();
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction: Vec3::NEG_Y, irradiance: 1.0 })],
        generators: vec![Generator::new(mesh, SpecularInteraction::Refract { ior: 1.0, dispersion: None })],
        receivers: vec![floor(4.0, 0.0)],
    };
    let set = build_scene_volumes(&scene, &VolumeSettings::default());
    (set.volumes, MediumBox { world_from_local: Affine3A::from_scale(Vec3::splat(8.0)), coefficients })
}

#[test]
fn a_beam_deposits_its_flux_times_its_attenuated_length() {
    // ∫ S dV over the beam = Φ ∫₀² e^{−σₜ s} ds, Φ = 1 lux · 1 m², per channel.
    let coefficients = MediumCoefficients { scattering: 0.3, absorption: Vec3::new(0.1, 0.15, 0.2), asymmetry: 0.4 };
    let (volumes, medium) = beam(coefficients);
    let sigma_t = coefficients.extinction();
    let exact = (1.0 - (-2.0 * sigma_t).exp()) / sigma_t;
    for longest in [16, 64] {
        let mut grid = BeamGrid::new(medium, longest);
        grid.deposit_all(&volumes, &VolumeSettings::default());
        let total = grid.source.iter().sum::<Vec3>() * grid.cell().1;
        assert!(((total - exact).abs() / exact).max_element() < 3e-3, "{longest} cells: {total} against {exact}");
        // Straight down in every lit cell.
        for (s, d) in grid.source.iter().zip(&grid.direction) {
            if s.x > 0.0 {
                assert!(d.normalize().dot(Vec3::NEG_Y) > 0.9999, "{d}");
            }
        }
    }
}

#[test]
fn marching_the_grid_matches_the_exact_integral_across_and_along_a_beam() {
    let coefficients = MediumCoefficients { scattering: 0.3, absorption: Vec3::splat(0.2), asymmetry: 0.4 };
    let (volumes, medium) = beam(coefficients);
    let mut grid = BeamGrid::new(medium, 64);
    grid.deposit_all(&volumes, &VolumeSettings::default());
    let settings = VolumeSettings::default();
    // Across the beam (its 1 m width spans eight cells, blurred by one at each side)
    // and down its length.
    for (eye, end, bound) in [(Vec3::new(-3.0, 1.0, 0.1), Vec3::new(3.0, 1.0, 0.1), 0.06), (Vec3::new(0.1, 1.9, 0.1), Vec3::new(0.1, 0.0, 0.1), 0.02)] {
        let exact = in_scattered_radiance(&volumes, eye, end, &medium, &settings).x;
        let marched = grid.in_scattered_radiance(eye, end, 256).x;
        assert!((marched - exact).abs() < bound * exact, "{eye} → {end}: {marched} against {exact}");
    }
}

/// The shaft image of `camera` (its rays ending on the plane y = 0, or 20 m away) by
/// the exact integral and by the grid, each pixel the mean over its footprint, from
/// `sub.0²` and `sub.1²` rays: a pixel shows that mean, and beams are sharp, so that
/// a few rays a pixel alias them (the disco ball's exact shafts differ by 6 % between
/// 4² and 12² rays a pixel).
fn shaft_images(scene: &Scene, medium: MediumBox, camera: &PinholeCamera, (longest, steps): (u32, u32), sub: (u32, u32)) -> (Vec<f32>, Vec<f32>) {
    let settings = VolumeSettings::default();
    let set = build_scene_volumes(scene, &settings);
    assert!(set.volumes.len() > 100, "{} volumes", set.volumes.len());
    let mut grid = BeamGrid::new(medium, longest);
    grid.deposit_all(&set.volumes, &settings);
    let exact = footprint_image(camera, sub.0, &|o, e| in_scattered_radiance(&set.volumes, o, e, &medium, &settings));
    let marched = footprint_image(camera, sub.1, &|o, e| grid.in_scattered_radiance(o, e, steps));
    (exact, marched)
}

/// The image of `radiance(eye, end)` seen by `camera` (its rays ending on the plane
/// y = 0, or 20 m away), each pixel the mean of its channels over `sub²` rays.
fn footprint_image(camera: &PinholeCamera, sub: u32, radiance: &(dyn Fn(Vec3, Vec3) -> Vec3 + Sync)) -> Vec<f32> {
    let fine = PinholeCamera { width: camera.width * sub, height: camera.height * sub, ..*camera };
    (0..camera.width * camera.height)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % camera.width, i / camera.width);
            (0..sub * sub)
                .map(|k| {
                    let (o, d) = fine.ray(x * sub + k % sub, y * sub + k / sub);
                    let t = if d.y < 0.0 { (-o.y / d.y).min(20.0) } else { 20.0 };
                    radiance(o, o + t * d).element_sum()
                })
                .sum::<f32>()
                / (sub * sub) as f32
        })
        .collect()
}

/// The bench's sea, 12 m across, `resolution`² cells, 3 m up.
fn bench_sea(resolution: usize) -> TriMesh {
    let spectrum =
        OceanSpectrum::new(&OceanSettings { resolution, size: 12.0, wind_speed: 7.0, wind_direction: Vec2::X, amplitude: 4e-3, ..OceanSettings::default() })
            .unwrap();
    spectrum.evaluate(0.0).mesh().transformed(&Affine3A::from_translation(Vec3::Y * 3.0))
}

#[test]
fn ocean_shafts_from_the_grid_are_within_five_percent_of_the_exact_integral() {
    // The bench's ocean: 12 m of sea 3 m deep under a slanted sun, seen from the water.
    let sea = bench_sea(32);
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction: Vec3::new(0.35, -1.0, 0.2).normalize(), irradiance: 1.0 })],
        generators: vec![Generator::new(sea, SpecularInteraction::Refract { ior: 1.333, dispersion: None })],
        receivers: vec![floor(12.0, 0.0)],
    };
    let medium = MediumBox {
        world_from_local: Affine3A::from_scale_rotation_translation(Vec3::new(12.0, 3.0, 12.0), Quat::IDENTITY, Vec3::Y * 1.5),
        coefficients: MediumCoefficients { scattering: 0.06, absorption: Vec3::splat(0.04), asymmetry: 0.6 },
    };
    let camera = PinholeCamera { position: Vec3::new(-4.5, 1.6, 4.5), look_at: Vec3::new(0.5, 0.4, -0.5), up: Vec3::Y, fov_y: 0.8, width: 32, height: 18 };
    let (exact, marched) = shaft_images(&scene, medium, &camera, (96, 256), (8, 8));
    let error = relative_l2(&marched, &exact);
    eprintln!("ocean shafts, grid against exact: relative L2 {error:.4}");
    assert!(error < 0.05, "ocean shafts: relative L2 {error}");
}

#[test]
fn disco_ball_shafts_from_the_grid_are_within_five_percent_of_the_exact_integral() {
    // The disco ball example: flat mirror facets 2.6 m up in a 4 m room of haze, lit
    // by a spot from a corner, seen from the front.
    let ball = TriMesh::uv_sphere(Vec3::new(0.0, 2.6, 0.0), 0.35, 12, 24).faceted();
    let spot = Vec3::new(1.2, 3.4, 1.8);
    let walls = [
        TriMesh::quad(Vec3::ZERO, Vec3::Z * 2.0, Vec3::X * 2.0),
        TriMesh::quad(Vec3::new(0.0, 4.0, 0.0), Vec3::X * 2.0, Vec3::Z * 2.0),
        TriMesh::quad(Vec3::new(0.0, 2.0, -2.0), Vec3::X * 2.0, Vec3::Y * 2.0),
        TriMesh::quad(Vec3::new(-2.0, 2.0, 0.0), Vec3::Y * 2.0, Vec3::Z * 2.0),
        TriMesh::quad(Vec3::new(2.0, 2.0, 0.0), Vec3::Z * 2.0, Vec3::Y * 2.0),
    ];
    let scene = Scene {
        lights: vec![Light {
            range: 20.0,
            ..Light::white(LightKind::Spot {
                position: spot,
                direction: (Vec3::new(0.0, 2.6, 0.0) - spot).normalize(),
                intensity: 1.0,
                inner_angle: 0.1,
                outer_angle: 0.15,
            })
        }],
        generators: vec![Generator::new(ball, SpecularInteraction::Reflect)],
        receivers: walls.into_iter().map(|mesh| Receiver { mesh, albedo: Vec3::ONE }).collect(),
    };
    let medium = MediumBox {
        world_from_local: Affine3A::from_scale_rotation_translation(Vec3::splat(4.0), Quat::IDENTITY, Vec3::Y * 2.0),
        coefficients: MediumCoefficients { scattering: 0.08, absorption: Vec3::splat(0.01), asymmetry: 0.3 },
    };
    let camera = PinholeCamera { position: Vec3::new(0.0, 2.0, 6.2), look_at: Vec3::new(0.0, 2.0, 0.0), up: Vec3::Y, fov_y: 1.0, width: 32, height: 24 };
    let (exact, marched) = shaft_images(&scene, medium, &camera, (96, 256), (12, 12));
    let error = relative_l2(&marched, &exact);
    eprintln!("disco ball shafts, grid against exact: relative L2 {error:.4}");
    assert!(error < 0.05, "disco ball shafts: relative L2 {error}");
}

#[test]
fn shafts_under_rippled_water_match_the_tracers_photon_beams() {
    // A 2 m pond of rippled water whose surface is the top of a 1 m deep medium, under
    // a slanted sun, seen from the side: every ray crosses the shafts.
    let waves = |x: f32, z: f32| {
        (
            0.03 * (4.0 * x + 0.3).sin() * (3.0 * z).cos(),
            0.03 * 4.0 * (4.0 * x + 0.3).cos() * (3.0 * z).cos(),
            -0.03 * 3.0 * (4.0 * x + 0.3).sin() * (3.0 * z).sin(),
        )
    };
    let water = TriMesh::heightfield(
        33,
        2.0,
        |x, z| 1.0 + waves(x, z).0,
        |x, z| {
            let (_, dx, dz) = waves(x, z);
            Vec3::new(-dx, 1.0, -dz).normalize()
        },
    )
    .unwrap();
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction: Vec3::new(0.3, -1.0, 0.15).normalize(), irradiance: 1.0 })],
        generators: vec![Generator::new(water, SpecularInteraction::Refract { ior: 1.333, dispersion: None })],
        receivers: vec![floor(4.0, 0.0)],
    };
    let medium = MediumBox {
        world_from_local: Affine3A::from_scale_rotation_translation(Vec3::new(2.0, 1.0, 2.0), Quat::IDENTITY, Vec3::Y * 0.5),
        coefficients: MediumCoefficients { scattering: 0.3, absorption: Vec3::splat(0.2), asymmetry: 0.5 },
    };
    let camera = PinholeCamera { position: Vec3::new(0.4, 0.5, 3.0), look_at: Vec3::new(0.0, 0.5, 0.0), up: Vec3::Y, fov_y: 0.45, width: 16, height: 12 };
    let settings = VolumeSettings::default();
    let volumes = build_scene_volumes(&scene, &settings).volumes;
    let tracer = PhotonTracer::new(&scene).unwrap();
    let beams = |seed: u64| {
        let mut beams = PhotonBeams::new(medium);
        tracer.trace(&TraceSettings { photons_per_light: 1 << 18, seed, ..TraceSettings::default() }, &mut beams, &|_, _| {});
        beams
    };
    let (a, b) = (beams(1), beams(2));
    let exact = footprint_image(&camera, 8, &|o, e| in_scattered_radiance(&volumes, o, e, &medium, &settings));
    let radius = 0.02;
    let traced_a = footprint_image(&camera, 4, &|o, e| a.in_scattered_radiance(o, e, radius));
    let traced_b = footprint_image(&camera, 4, &|o, e| b.in_scattered_radiance(o, e, radius));
    let traced: Vec<f32> = traced_a.iter().zip(&traced_b).map(|(a, b)| 0.5 * (a + b)).collect();
    // The two halves differ by √2 of one half's noise: the mean's is half that.
    let noise = 0.5 * relative_l2(&traced_a, &traced_b);
    let error = relative_l2(&exact, &traced);
    let total = |image: &[f32]| image.iter().sum::<f32>();
    eprintln!(
        "rippled water's shafts against the tracer's beams: relative L2 {error:.4} (tracer noise {noise:.4}), totals {:.4} / {:.4}",
        total(&exact),
        total(&traced)
    );
    // Measured: 0.0056 against a noise of 0.0014 (the kernel's 2 cm blur and the
    // volumes' interpolated intensity); the Fresnel transmittance alone is 2 %.
    assert!(error < 0.015, "relative L2 {error}, tracer noise {noise}");
    assert!((total(&exact) / total(&traced) - 1.0).abs() < 0.01, "the shafts' light differs from the tracer's");
}

/// Water under a slanted sun whose triangles are finer than the grid's cells, its
/// medium's box and a view from the water: the bench's ocean of 256² (`Some(256)`) or a
/// rippled pool of 128², 8 m across and 2 m deep.
fn fine_water(ocean: Option<usize>) -> (Scene, MediumBox, PinholeCamera) {
    let (water, size, depth) = match ocean {
        Some(resolution) => (bench_sea(resolution), 12.0, 3.0),
        None => {
            let waves = |x: f32, z: f32| {
                (
                    0.02 * (4.0 * x + 0.3).sin() * (3.0 * z).cos(),
                    0.08 * (4.0 * x + 0.3).cos() * (3.0 * z).cos(),
                    -0.06 * (4.0 * x + 0.3).sin() * (3.0 * z).sin(),
                )
            };
            let normal = |x: f32, z: f32| Vec3::new(-waves(x, z).1, 1.0, -waves(x, z).2).normalize();
            (TriMesh::heightfield(129, 8.0, |x, z| 2.0 + waves(x, z).0, normal).unwrap(), 8.0, 2.0)
        }
    };
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction: Vec3::new(0.35, -1.0, 0.2).normalize(), irradiance: 1.0 })],
        generators: vec![Generator::new(water, SpecularInteraction::Refract { ior: 1.333, dispersion: None })],
        receivers: vec![floor(size, 0.0)],
    };
    let medium = MediumBox {
        world_from_local: Affine3A::from_scale_rotation_translation(Vec3::new(size, depth, size), Quat::IDENTITY, Vec3::Y * (0.5 * depth)),
        coefficients: MediumCoefficients { scattering: 0.06, absorption: Vec3::new(0.3, 0.1, 0.05), asymmetry: 0.6 },
    };
    let camera = PinholeCamera {
        position: Vec3::new(-0.375 * size, 0.5 * depth, 0.375 * size),
        look_at: Vec3::new(0.05 * size, 0.15 * depth, -0.05 * size),
        up: Vec3::Y,
        fov_y: 0.8,
        width: 48,
        height: 27,
    };
    (scene, medium, camera)
}

#[test]
fn bundles_of_thin_beams_keep_the_shafts_of_each_beam() {
    // Narrow beams entering the grid through one cell go as one bundle, whose spread
    // stands for theirs: most of the fine water's beams, and shafts within 1.5 % of
    // each beam deposited alone.
    for ocean in [None, Some(256)] {
        let (scene, medium, camera) = fine_water(ocean);
        let settings = VolumeSettings::default();
        let volumes = build_scene_volumes(&scene, &settings).volumes;
        let mut each = BeamGrid::new(medium, 96);
        each.deposit_each(&volumes, &settings);
        let mut bundled = BeamGrid::new(medium, 96);
        let joined = bundled.deposit_all(&volumes, &settings);
        let alone = footprint_image(&camera, 2, &|o, e| each.in_scattered_radiance(o, e, 256));
        let merged = footprint_image(&camera, 2, &|o, e| bundled.in_scattered_radiance(o, e, 256));
        let error = relative_l2(&merged, &alone);
        let total = |g: &BeamGrid| g.source.iter().sum::<Vec3>();
        let flux = ((total(&bundled) - total(&each)) / total(&each)).abs().max_element();
        eprintln!("{ocean:?}: {joined} of {} beams in bundles, shafts within {error:.4} of each beam's, the grid's light within {flux:.4}", volumes.len());
        assert!(joined as f32 > 0.8 * volumes.len() as f32, "{joined} of {} beams in bundles", volumes.len());
        assert!(error < 0.015, "{ocean:?}: bundled shafts differ by {error}");
        assert!(flux < 0.005, "{ocean:?}: the bundles' light differs by {flux}");
        // The directions' blocks cover every cell a bundle lit, so that none scatters
        // with no phase function.
        let aimless = bundled.source.iter().zip(&bundled.direction).filter(|(s, d)| s.element_sum() > 0.0 && **d == Vec3::ZERO).count();
        assert_eq!(aimless, 0, "{ocean:?}: {aimless} lit cells have no direction");
    }
}
