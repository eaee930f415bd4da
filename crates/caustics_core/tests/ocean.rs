//! The FFT ocean (Tessendorf 2001): deterministic, a Hermitian spectrum (real fields,
//! checked against a direct sum), zero mean, wind-driven amplitude, the dispersion
//! relation (deep and shallow), exact normals (plain and choppy) against finite
//! differences, seamless tiling, clear errors and finite output at the extremes.

use caustics_core::ocean::{Complex32, GRAVITY, OceanSettings, OceanSpectrum, OceanSurface};
use caustics_core::params::ParamError;
use glam::{Vec2, Vec3};

fn surface(settings: &OceanSettings, t: f32) -> OceanSurface {
    OceanSpectrum::new(settings).unwrap().evaluate(t)
}

fn rms_height(s: &OceanSurface) -> f32 {
    (s.displacement.iter().map(|d| d.y * d.y).sum::<f32>() / s.displacement.len() as f32).sqrt()
}

fn finite(s: &OceanSurface) -> bool {
    s.displacement.iter().all(|d| d.is_finite()) && s.normals.iter().all(|n| n.is_finite())
}

#[test]
fn deterministic_for_a_seed_and_buffers_are_reused() {
    let settings = OceanSettings { choppiness: 0.5, ..Default::default() };
    assert_eq!(surface(&settings, 1.5), surface(&settings, 1.5));
    assert_ne!(surface(&settings, 1.5), surface(&OceanSettings { seed: 2, ..settings }, 1.5));

    let mut spectrum = OceanSpectrum::new(&settings).unwrap();
    let mut reused = OceanSurface::default();
    spectrum.evaluate_into(0.25, &mut reused);
    let buffer = reused.displacement.as_ptr();
    spectrum.evaluate_into(1.5, &mut reused);
    assert_eq!(reused, spectrum.evaluate(1.5));
    assert_eq!(reused.displacement.as_ptr(), buffer, "evaluate_into reallocated");
}

/// h(x) = Σₖ h̃(k) e^{ik·x} summed directly (f64), x from the patch's centre.
fn direct_sum(settings: &OceanSettings, spectrum: &[Complex32], x: Vec2, factor: impl Fn(Vec2) -> (f64, f64)) -> (f64, f64) {
    let n = settings.resolution;
    let (mut re, mut im) = (0.0f64, 0.0f64);
    for j in 0..n {
        for i in 0..n {
            let k = settings.wave_vector(i, j);
            let h = spectrum[j * n + i];
            let (fr, fi) = factor(k);
            // (fr + i fi) h̃ e^{ik·x}
            let (hr, hi) = (h.re as f64 * fr - h.im as f64 * fi, h.re as f64 * fi + h.im as f64 * fr);
            let phase = k.x as f64 * x.x as f64 + k.y as f64 * x.y as f64;
            let (c, s) = (phase.cos(), phase.sin());
            re += hr * c - hi * s;
            im += hr * s + hi * c;
        }
    }
    (re, im)
}

#[test]
fn the_spectrum_is_hermitian_so_the_fields_are_real() {
    let settings = OceanSettings { resolution: 32, size: 20.0, wind_speed: 7.0, ..Default::default() };
    let spectrum = OceanSpectrum::new(&settings).unwrap();
    let t = 2.3;
    let h = spectrum.height_spectrum(t);
    let n = settings.resolution;
    let largest = h.iter().map(|c| c.norm()).fold(0.0, f32::max);
    assert!(largest > 0.0);
    for j in 0..n {
        for i in 0..n {
            let opposite = h[((n - j) % n) * n + (n - i) % n];
            assert!((opposite - h[j * n + i].conj()).norm() <= 1e-6 * largest, "h̃(−k) ≠ h̃*(k) at ({i}, {j})");
        }
    }
    // The inverse transform, summed directly: its imaginary part vanishes, and its real
    // part is the surface's height; i k h̃ likewise gives the normal's slopes.
    let s = spectrum.evaluate(t);
    let scale = rms_height(&s) as f64;
    for (i, j) in [(0, 0), (1, 0), (5, 3), (16, 16), (31, 7), (12, 29), (31, 31)] {
        let x = s.rest_position(i, j);
        let x = Vec2::new(x.x, x.z);
        let (re, im) = direct_sum(&settings, &h, x, |_| (1.0, 0.0));
        assert!(im.abs() < 1e-5 * scale, "imaginary height {im} at ({i}, {j})");
        let height = s.displacement[j * n + i].y as f64;
        assert!((re - height).abs() < 1e-4 * scale, "height {height} vs direct sum {re} at ({i}, {j})");
        let (dhdx, im_x) = direct_sum(&settings, &h, x, |k| (0.0, k.x as f64));
        let (dhdz, im_z) = direct_sum(&settings, &h, x, |k| (0.0, k.y as f64));
        assert!(im_x.abs() < 1e-5 && im_z.abs() < 1e-5);
        let normal = Vec3::new(-dhdx as f32, 1.0, -dhdz as f32).normalize();
        assert!(normal.angle_between(s.normals[j * n + i]) < 1e-4, "normal at ({i}, {j})");
    }
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
fn every_wave_follows_the_dispersion_relation() {
    // h̃(k, t) = a e^{iωt} + b e^{−iωt} ⇒ h̃(t + τ) + h̃(t − τ) = 2 cos(ωτ) h̃(t), exactly.
    let omega_deep = |k: f32| (GRAVITY * k).sqrt();
    let omega_shallow = |k: f32| (GRAVITY * k * (k * 1.5).tanh()).sqrt();
    for (depth, omega) in [(None, &omega_deep as &dyn Fn(f32) -> f32), (Some(1.5), &omega_shallow)] {
        let settings = OceanSettings { resolution: 32, depth, ..Default::default() };
        let spectrum = OceanSpectrum::new(&settings).unwrap();
        let (t, tau) = (1.7, 0.3);
        let [before, now, after] = [t - tau, t, t + tau].map(|t| spectrum.height_spectrum(t));
        let largest = now.iter().map(|c| c.norm()).fold(0.0, f32::max);
        let n = settings.resolution;
        for j in 0..n {
            for i in 0..n {
                let idx = j * n + i;
                let expected = now[idx] * (2.0 * (omega(settings.wave_vector(i, j).length()) * tau).cos());
                let got = before[idx] + after[idx];
                assert!((got - expected).norm() < 1e-5 * largest, "depth {depth:?}, mode ({i}, {j})");
            }
        }
        // The surface moves.
        assert_ne!(spectrum.evaluate(t).displacement, spectrum.evaluate(t + 0.1).displacement);
    }
    // Shallow water slows the long waves, not the short ones.
    let shallow = OceanSettings { depth: Some(1.5), ..Default::default() };
    let deep = OceanSettings::default();
    assert!(shallow.dispersion(0.2) < 0.6 * deep.dispersion(0.2));
    assert!((shallow.dispersion(20.0) - deep.dispersion(20.0)).abs() < 1e-5);
}

/// The largest angle between the surface's normals and the normals of central
/// differences of its displaced positions (neighbours across the seam included).
fn worst_normal_error(s: &OceanSurface) -> f32 {
    let n = s.resolution;
    let p = |i: usize, j: usize| s.vertex(i, j).0;
    let mut worst = 0.0f32;
    for j in 0..n {
        for i in 0..n {
            // Points across the seam, one patch over, sit a patch width away.
            let (ip, im, jp, jm) = (i + 1, (i + n - 1) % n, j + 1, (j + n - 1) % n);
            let wrap_x = if i == 0 { Vec3::X * s.size } else { Vec3::ZERO };
            let wrap_z = if j == 0 { Vec3::Z * s.size } else { Vec3::ZERO };
            let along_x = p(ip, j) - (p(im, j) - wrap_x);
            let along_z = p(i, jp) - (p(i, jm) - wrap_z);
            let fd = along_z.cross(along_x).normalize();
            let spectral = s.normals[j * n + i];
            assert!((spectral.length() - 1.0).abs() < 1e-5);
            worst = worst.max(fd.angle_between(spectral));
        }
    }
    worst
}

#[test]
fn spectral_normals_agree_with_finite_differences() {
    // Fine grid relative to the shortest waves (the cutoff damps them), so central
    // differences approximate the exact spectral slopes closely.
    let settings = OceanSettings { resolution: 128, size: 16.0, wind_speed: 5.0, small_wave_cutoff: 0.5, ..Default::default() };
    let s = surface(&settings, 0.7);
    let worst = worst_normal_error(&s);
    assert!(worst < 0.02, "normals differ from the heights' slopes by up to {worst} rad");
    assert!(s.normals.iter().any(|n| n.angle_between(Vec3::Y) > 0.05), "the surface is too flat to test");

    // Choppy (short of folding over): the normals are those of the displaced surface,
    // not of the heights alone.
    let choppy = surface(&OceanSettings { choppiness: 1.0, ..settings }, 0.7);
    assert!(choppy.normals.iter().all(|n| n.y > 0.5), "the surface folds: finite differences fail there");
    let worst = worst_normal_error(&choppy);
    assert!(worst < 0.02, "choppy normals differ from the displaced surface's by up to {worst} rad");
    let n = choppy.resolution;
    let heights_only = (0..n * n).map(|idx| {
        let (i, j) = (idx % n, idx / n);
        let h = |i: usize, j: usize| choppy.displacement[(j % n) * n + (i % n)].y;
        let step = choppy.size / n as f32;
        let slope = Vec2::new(h(i + 1, j) - h(i + n - 1, j), h(i, j + 1) - h(i, j + n - 1)) / (2.0 * step);
        Vec3::new(-slope.x, 1.0, -slope.y).normalize().angle_between(choppy.normals[idx])
    });
    assert!(heights_only.fold(0.0f32, f32::max) > 0.05, "chop did not change the normals: the test says nothing");
}

#[test]
fn the_surface_tiles() {
    let settings = OceanSettings { choppiness: 0.8, ..Default::default() };
    let b = surface(&settings, 0.5);
    // Choppy waves move points sideways too.
    assert!(b.displacement.iter().any(|d| d.x.abs() > 1e-4));
    let mesh = b.mesh();
    let n = settings.resolution;
    assert_eq!(mesh.positions().len(), (n + 1) * (n + 1));
    assert_eq!(mesh.triangles().len(), 2 * n * n);
    // The last column (row) repeats the first one a patch width over: copies tile seamlessly.
    for j in 0..=n {
        let (first, last) = (mesh.positions()[j * (n + 1)], mesh.positions()[j * (n + 1) + n]);
        assert!((last - first - Vec3::X * settings.size).length() < 1e-4);
        let (first, last) = (mesh.positions()[j], mesh.positions()[n * (n + 1) + j]);
        assert!((last - first - Vec3::Z * settings.size).length() < 1e-4);
    }
    // Centred on the origin, y up, faces up (without chop, which may fold cells over).
    let centre = mesh.positions().iter().fold(Vec3::ZERO, |a, p| a + *p) / mesh.positions().len() as f32;
    assert!(centre.length() < 0.05 * settings.size, "centre {centre}");
    let plain = surface(&OceanSettings { choppiness: 0.0, ..settings }, 0.5).mesh();
    for t in 0..plain.triangles().len() {
        let [a, b, c] = plain.corners(t);
        assert!((b - a).cross(c - a).y > 0.0, "triangle {t} faces down");
    }
}

#[test]
fn invalid_settings_are_errors() {
    let d = OceanSettings::default();
    let bad = [
        ("ocean resolution", OceanSettings { resolution: 100, ..d }),
        ("ocean resolution", OceanSettings { resolution: 1, ..d }),
        ("ocean resolution", OceanSettings { resolution: 0, ..d }),
        ("ocean resolution", OceanSettings { resolution: 8192, ..d }),
        ("ocean size", OceanSettings { size: 0.0, ..d }),
        ("ocean size", OceanSettings { size: f32::INFINITY, ..d }),
        ("wind speed", OceanSettings { wind_speed: f32::NAN, ..d }),
        ("wind speed", OceanSettings { wind_speed: -1.0, ..d }),
        ("wind direction length", OceanSettings { wind_direction: Vec2::ZERO, ..d }),
        ("wind direction x", OceanSettings { wind_direction: Vec2::new(f32::NAN, 1.0), ..d }),
        ("ocean amplitude", OceanSettings { amplitude: -1.0, ..d }),
        ("choppiness", OceanSettings { choppiness: f32::NAN, ..d }),
        ("small-wave cutoff", OceanSettings { small_wave_cutoff: -0.1, ..d }),
        ("ocean depth", OceanSettings { depth: Some(0.0), ..d }),
        ("ocean depth", OceanSettings { depth: Some(f32::NAN), ..d }),
        // Valid one by one, but waves past any f32 surface.
        ("ocean wave height bound", OceanSettings { amplitude: 1e30, ..d }),
    ];
    for (name, settings) in bad {
        let error = OceanSpectrum::new(&settings).unwrap_err();
        match &error {
            ParamError::OutOfRange { name: got, .. } | ParamError::NotFinite { name: got, .. } => {
                assert_eq!(*got, name, "{settings:?}")
            }
            other => panic!("unexpected error {other:?}"),
        }
        assert!(error.to_string().contains(name), "{error}");
        if name != "ocean wave height bound" {
            assert_eq!(settings.validate().unwrap_err().to_string(), error.to_string());
        }
    }
    assert_eq!(d.validate(), Ok(()));
}

#[test]
fn extremes_stay_finite() {
    // No wind: a flat sea.
    let flat = surface(&OceanSettings { wind_speed: 0.0, choppiness: 1.0, ..Default::default() }, 3.0);
    assert!(flat.displacement.iter().all(|d| *d == Vec3::ZERO) && flat.normals.iter().all(|n| *n == Vec3::Y));
    // Only the direction of the wind counts, whatever its length.
    let d = OceanSettings::default();
    assert_eq!(
        surface(&OceanSettings { wind_direction: Vec2::splat(1e30), ..d }, 1.0),
        surface(&OceanSettings { wind_direction: Vec2::splat(1e-30), ..d }, 1.0)
    );
    for settings in [
        OceanSettings { wind_speed: 60.0, choppiness: 2.0, ..d },
        OceanSettings { wind_speed: 1e30, ..d },
        OceanSettings { wind_speed: f32::MAX, small_wave_cutoff: 0.0, ..d },
        OceanSettings { resolution: 2, ..d },
        OceanSettings { resolution: 2, choppiness: 1.0, ..d },
        OceanSettings { size: 1.0e4, resolution: 16, ..d },
        OceanSettings { size: 1e-3, resolution: 16, small_wave_cutoff: 0.0, ..d },
        OceanSettings { size: caustics_core::mesh::MAX_COORDINATE, resolution: 8, amplitude: 1e-30, ..d },
        OceanSettings { depth: Some(1e-6), choppiness: 1.0, ..d },
        OceanSettings { depth: Some(f32::MAX), ..d },
    ] {
        let mut spectrum = OceanSpectrum::new(&settings).unwrap_or_else(|e| panic!("{settings:?}: {e}"));
        for t in [0.0, 100.0, 1e7] {
            let mut s = OceanSurface::default();
            spectrum.evaluate_into(t, &mut s);
            assert!(finite(&s), "{settings:?} at t = {t}");
            s.mesh();
        }
    }
    // A patch wider than a mesh's coordinates may reach is refused.
    assert!(OceanSpectrum::new(&OceanSettings { size: 1e30, resolution: 8, amplitude: 1e-30, ..d }).is_err());
}
