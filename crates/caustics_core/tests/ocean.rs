//! The FFT ocean (Tessendorf 2001): deterministic, consistent heights and normals,
//! zero mean, wind-driven amplitude, motion, seamless tiling, and clear errors.

use caustics_core::ocean::{OceanSettings, OceanSpectrum, OceanSurface};
use caustics_core::params::ParamError;
use glam::{Vec2, Vec3};

fn surface(settings: &OceanSettings, t: f32) -> OceanSurface {
    OceanSpectrum::new(settings).unwrap().evaluate(t)
}

fn rms_height(s: &OceanSurface) -> f32 {
    (s.displacement.iter().map(|d| d.y * d.y).sum::<f32>() / s.displacement.len() as f32).sqrt()
}

#[test]
fn deterministic_for_a_seed() {
    let settings = OceanSettings::default();
    assert_eq!(surface(&settings, 1.5), surface(&settings, 1.5));
    assert_ne!(surface(&settings, 1.5), surface(&OceanSettings { seed: 2, ..settings }, 1.5));
}

#[test]
fn mean_height_is_zero_and_amplitude_follows_the_wind() {
    let calm = surface(&OceanSettings { wind_speed: 3.0, ..Default::default() }, 0.0);
    let windy = surface(&OceanSettings { wind_speed: 12.0, ..Default::default() }, 0.0);
    for s in [&calm, &windy] {
        let mean = s.displacement.iter().map(|d| d.y).sum::<f32>() / s.displacement.len() as f32;
        assert!(mean.abs() < 1e-4 * rms_height(s).max(1e-6), "mean height {mean}");
    }
    // Phillips: the spectrum's energy grows steeply with V (L = V²/g).
    assert!(rms_height(&windy) > 4.0 * rms_height(&calm), "{} vs {}", rms_height(&windy), rms_height(&calm));
    assert!(rms_height(&calm) > 0.0);
}

#[test]
fn spectral_normals_agree_with_finite_differences_of_the_heights() {
    // Fine grid relative to the shortest waves (the cutoff damps them), so central
    // differences approximate the exact spectral slopes closely.
    let settings =
        OceanSettings { resolution: 128, size: 16.0, wind_speed: 5.0, small_wave_cutoff: 0.5, ..Default::default() };
    let s = surface(&settings, 0.7);
    let n = s.resolution;
    let step = s.size / n as f32;
    let h = |i: usize, j: usize| s.displacement[(j % n) * n + (i % n)].y;
    let mut worst = 0.0f32;
    for j in 0..n {
        for i in 0..n {
            let dhdx = (h(i + 1, j) - h(i + n - 1, j)) / (2.0 * step);
            let dhdz = (h(i, j + 1) - h(i, j + n - 1)) / (2.0 * step);
            let fd = Vec3::new(-dhdx, 1.0, -dhdz).normalize();
            let spectral = s.normals[j * n + i];
            assert!((spectral.length() - 1.0).abs() < 1e-5);
            worst = worst.max(fd.angle_between(spectral));
        }
    }
    assert!(worst < 0.02, "normals differ from the heights' slopes by up to {worst} rad");
    assert!(s.normals.iter().any(|n| n.angle_between(Vec3::Y) > 0.02), "the surface is too flat to test");
}

#[test]
fn the_surface_moves_and_tiles() {
    let settings = OceanSettings { choppiness: 0.8, ..Default::default() };
    let spectrum = OceanSpectrum::new(&settings).unwrap();
    let (a, b) = (spectrum.evaluate(0.0), spectrum.evaluate(0.5));
    assert_ne!(a.displacement, b.displacement);
    // Choppy waves move points sideways too.
    assert!(b.displacement.iter().any(|d| d.x.abs() > 1e-4));
    let mesh = b.mesh();
    let n = settings.resolution;
    assert_eq!(mesh.positions().len(), (n + 1) * (n + 1));
    // The last column repeats the first one patch-width over: copies tile seamlessly.
    for j in 0..=n {
        let first = mesh.positions()[j * (n + 1)];
        let last = mesh.positions()[j * (n + 1) + n];
        assert!((last - first - Vec3::X * settings.size).length() < 1e-4);
    }
}

#[test]
fn invalid_settings_are_errors_and_extremes_stay_finite() {
    let bad = [
        OceanSettings { resolution: 100, ..Default::default() },
        OceanSettings { resolution: 1, ..Default::default() },
        OceanSettings { size: 0.0, ..Default::default() },
        OceanSettings { wind_speed: f32::NAN, ..Default::default() },
        OceanSettings { wind_direction: Vec2::ZERO, ..Default::default() },
        OceanSettings { amplitude: -1.0, ..Default::default() },
    ];
    for settings in bad {
        let error = OceanSpectrum::new(&settings).unwrap_err();
        assert!(!error.to_string().is_empty());
    }
    assert!(matches!(
        OceanSpectrum::new(&OceanSettings { resolution: 100, ..Default::default() }),
        Err(ParamError::OutOfRange { name: "ocean resolution", .. })
    ));
    // No wind: a flat sea. A gale, a tiny grid, a huge patch: finite.
    let flat = surface(&OceanSettings { wind_speed: 0.0, ..Default::default() }, 3.0);
    assert!(flat.displacement.iter().all(|d| *d == Vec3::ZERO) && flat.normals.iter().all(|n| *n == Vec3::Y));
    for settings in [
        OceanSettings { wind_speed: 60.0, choppiness: 2.0, ..Default::default() },
        OceanSettings { resolution: 2, ..Default::default() },
        OceanSettings { size: 1.0e4, resolution: 16, ..Default::default() },
    ] {
        let s = surface(&settings, 100.0);
        assert!(s.displacement.iter().all(|d| d.is_finite()) && s.normals.iter().all(|n| n.is_finite()));
        s.mesh();
    }
}
