//! The ground-truth tracer on cases where physics gives the answer.
//!
//! Photons leave a light at random points/directions (stratified in emission order),
//! so binned irradiance carries at most Poisson noise: a cell receiving k photons of
//! equal flux has relative standard deviation ≤ 1/√k (stratification only lowers it). Tolerances below are stated in those standard deviations
//! (5σ per cell; the chance of a false failure over ~1000 cells is below 10⁻³).
//! Where photons are deterministic (normal incidence) the only error is f32 rounding.

use caustics_core::estimate::{GridRegion, IrradianceGrid, PhotonList};
use caustics_core::mesh::TriMesh;
use caustics_core::optics::{fresnel_reflectance, fresnel_transmittance, refract};
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{Generator, Light, LightKind, Receiver, Scene};
use caustics_core::scenes::floor;
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use glam::Vec3;

fn no_progress(_: u64, _: u64) {}

fn settings(photons: u64) -> TraceSettings {
    TraceSettings { photons_per_light: photons, ..Default::default() }
}

fn water_plane(y: f32, half: f32) -> Generator {
    Generator::new(TriMesh::quad(Vec3::Y * y, Vec3::Z * half, Vec3::X * half), SpecularInteraction::Refract { ior: 1.333, dispersion: None })
}

/// A flat water surface under an oblique sun: the floor receives E⊥·cos θᵢ·T(θᵢ)
/// everywhere (the refracted beam is parallel and the two planes are parallel, so
/// its cross-section is unchanged).
#[test]
fn flat_water_transmits_the_fresnel_fraction_uniformly() {
    let theta = 40f32.to_radians();
    let direction = Vec3::new(theta.sin(), -theta.cos(), 0.0);
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction, irradiance: 2.0 })],
        generators: vec![water_plane(1.0, 2.0)],
        receivers: vec![floor(20.0)],
    };
    let photons = 4_000_000;
    let region = GridRegion::horizontal(-1.0, -1.0, 0.0, 2.0, 32);
    let mut grid = IrradianceGrid::new(region);
    let stats = PhotonTracer::new(&scene).unwrap().trace(&settings(photons), &mut grid, &no_progress);

    let expected = 2.0 * theta.cos() * fresnel_transmittance(theta.cos(), 1.0 / 1.333);
    let e = grid.irradiance_mean();
    // Photons per cell: emitted flux per photon is E⊥·A/N; a cell gets expected·area/that.
    let per_photon = (stats.emitted.x / photons as f64) as f32;
    let per_cell = expected * region.cell_area() / per_photon / fresnel_transmittance(theta.cos(), 1.0 / 1.333);
    let sigma = 1.0 / per_cell.sqrt();
    for (i, v) in e.iter().enumerate() {
        assert!((v / expected - 1.0).abs() < 5.0 * sigma, "cell {i}: {v} vs {expected} (σ = {sigma})");
    }
    let mean = e.iter().sum::<f32>() / e.len() as f32;
    let sigma_mean = sigma / (e.len() as f32).sqrt();
    assert!((mean / expected - 1.0).abs() < 5.0 * sigma_mean, "mean {mean} vs {expected}");
}

/// A closed glass slab (n = 1.5) under a vertical sun: the floor receives the slab's
/// top area × E × T²·Σ R²ᵏ = (1 − R)/(1 + R) of the incident flux; nothing is absorbed,
/// so deposited + escaped + dropped = emitted.
#[test]
fn glass_slab_transmits_one_minus_r_over_one_plus_r() {
    let slab = {
        let mut m = TriMesh::quad(Vec3::Y * 1.0, Vec3::Z, Vec3::X); // top, facing +y
        m.append(&TriMesh::quad(Vec3::Y * 0.8, Vec3::X, Vec3::Z)); // bottom, facing −y
        for (c, u, v) in [
            // The sides, facing outwards (a closed, consistently wound mesh).
            (Vec3::new(1.0, 0.9, 0.0), Vec3::Y * 0.1, Vec3::Z),
            (Vec3::new(-1.0, 0.9, 0.0), Vec3::Z, Vec3::Y * 0.1),
            (Vec3::new(0.0, 0.9, 1.0), Vec3::X, Vec3::Y * 0.1),
            (Vec3::new(0.0, 0.9, -1.0), Vec3::Y * 0.1, Vec3::X),
        ] {
            m.append(&TriMesh::quad(c, u, v));
        }
        m
    };
    assert!(slab.is_closed());
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction: Vec3::NEG_Y, irradiance: 1.0 })],
        generators: vec![Generator::new(slab, SpecularInteraction::Refract { ior: 1.5, dispersion: None })],
        receivers: vec![floor(40.0)],
    };
    let mut photons = PhotonList::default();
    let stats = PhotonTracer::new(&scene).unwrap().trace(&settings(200_000), &mut photons, &no_progress);
    let r = fresnel_reflectance(1.0, 1.0 / 1.5);
    let on_top = 4.0; // the 2 × 2 m top, E = 1
    let expected = on_top * (1.0 - r) / (1.0 + r);
    let deposited: f64 = photons.0.iter().map(|p| p.flux.x as f64).sum();
    // The emitter's rectangle is padded beyond the top, so the number of photons that
    // hit the top is binomial: p ≈ 0.997, relative σ = √((1 − p)/(pN)) ≈ 1.2·10⁻⁴. Branches
    // cut by `min_weight` can only lower the result, by at most the dropped flux.
    let p_top = on_top as f64 / stats.emitted.x;
    let sigma = ((1.0 - p_top) / (p_top * 200_000.0)).sqrt();
    let dropped = stats.dropped.x / expected as f64;
    assert!((deposited / expected as f64 - 1.0).abs() < 5.0 * sigma + dropped, "{deposited} vs {expected}");
    // Each split rounds flux·R + flux·(1 − R) in f32 (≈ 1 ulp = 6·10⁻⁸ relative); a few
    // splits per photon keep the balance within 10⁻⁶.
    let balance = stats.deposited + stats.escaped + stats.dropped + stats.absorbed + stats.direct - stats.emitted;
    assert!(balance.abs().max_element() < 1e-6 * stats.emitted.x, "energy balance off by {balance}");
}

/// A horizontal mirror above a point light: the floor sees the light's mirror image
/// at height 2h − y₀, irradiance E(x) = I·(2h − y₀)/r³ (inverse square, cosine law).
#[test]
fn planar_mirror_reflects_the_inverse_square_pattern() {
    let (h, y0, intensity) = (1.0f32, 0.5f32, 3.0f32);
    let scene = Scene {
        lights: vec![Light::white(LightKind::Point { position: Vec3::Y * y0, intensity })],
        generators: vec![Generator::new(
            TriMesh::quad(Vec3::Y * h, Vec3::X * 3.0, Vec3::Z * 3.0), // faces −y
            SpecularInteraction::Reflect,
        )],
        receivers: vec![floor(20.0)],
    };
    let photons = 8_000_000;
    let region = GridRegion::horizontal(-0.5, -0.5, 0.0, 1.0, 16);
    let mut grid = IrradianceGrid::new(region);
    let stats = PhotonTracer::new(&scene).unwrap().trace(&settings(photons), &mut grid, &no_progress);
    let per_photon = (stats.emitted.x / photons as f64) as f32;
    let image = Vec3::Y * (2.0 * h - y0);
    let e = grid.irradiance_mean();
    for row in 0..16 {
        for col in 0..16 {
            let p = region.cell_center(row, col);
            let r = p - image;
            let expected = intensity * image.y / r.length().powi(3);
            let k = expected * region.cell_area() / per_photon;
            let got = e[row * 16 + col];
            // 5σ Poisson plus the cell-average vs centre difference (< 10⁻³ here).
            assert!((got / expected - 1.0).abs() < 5.0 / k.sqrt() + 1e-3, "({row},{col}): {got} vs {expected}");
        }
    }
}

/// Light refracted out of a denser medium past the critical angle is reflected in
/// full: photons from a point under a water surface above θc never cross it.
#[test]
fn total_internal_reflection_keeps_flux_inside() {
    let scene = Scene {
        lights: vec![Light::white(LightKind::Spot {
            position: Vec3::new(0.0, 0.5, 0.0),
            direction: Vec3::new(1.0, 0.2, 0.0).normalize(),
            intensity: 1.0,
            inner_angle: 0.05,
            outer_angle: 0.1,
        })],
        generators: vec![water_plane(1.0, 30.0)],
        receivers: vec![Receiver { mesh: TriMesh::quad(Vec3::Y * 3.0, Vec3::X * 30.0, Vec3::Z * 30.0), albedo: Vec3::ONE }],
    };
    // The cone is within 17° of grazing, past θc = 48.6° from the normal: no photon reaches y = 3.
    assert!(refract(Vec3::new(1.0, 0.3, 0.0).normalize(), Vec3::Y, 1.333).direction().is_none());
    let mut photons = PhotonList::default();
    PhotonTracer::new(&scene).unwrap().trace(&settings(50_000), &mut photons, &no_progress);
    assert!(photons.0.iter().all(|p| p.position.y < 1.0), "a photon crossed the surface past the critical angle");
}

/// Tracing is deterministic: the same seed gives bit-identical results whatever the
/// thread count.
#[test]
fn same_seed_same_result_on_any_thread_count() {
    let scene = caustics_core::scenes::glass_sphere(32);
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut grid = IrradianceGrid::new(scene.region);
            PhotonTracer::new(&scene.scene).unwrap().trace(&settings(100_000), &mut grid, &no_progress);
            grid.irradiance()
        })
    };
    assert_eq!(run(1), run(3));
}
