//! Convolution caustics (Trendall & Stewart 2000): the light entering is Snell's with the
//! paper's Fresnel transmission; the flat surface lights the floor with
//! exactly L·T·cos θ in both forms; the convolution form approaches the direct integral
//! of eq. 2 where the paper's approximations hold (small slopes, d ≫ h, n = 2a, a high
//! sun); stiff and extreme inputs give finite irradiance or a clear error; the pond's
//! ripples are deterministic, reflect off the walls and expire.

use caustics_core::convolution::ripples::{PoolRipples, RippleSettings, mirror_images};
use caustics_core::convolution::*;
use caustics_core::optics::fresnel_transmittance;
use caustics_core::params::ParamError;
use glam::{Vec2, Vec3};

fn waves(texels: usize, cell: f32, amplitude: f32, offset: f32) -> Heightfield {
    let k = std::f32::consts::TAU / 0.6;
    Heightfield::from_fn(texels, texels, cell, |x, z| offset + amplitude * ((k * x).sin() + (0.7 * k * z + 0.3).cos())).unwrap()
}

fn both_forms(heightfield: &Heightfield, settings: &ConvolutionSettings) -> [Vec<f32>; 2] {
    [direct_irradiance(heightfield, settings).unwrap(), convolution_irradiance(heightfield, settings).unwrap()]
}

/// `L_s T(θi) cos θi` of flat water.
fn flat_irradiance(settings: &ConvolutionSettings) -> f32 {
    let cos_i = -settings.sun_unit().y;
    settings.sun_irradiance * fresnel_transmittance(cos_i, 1.0 / settings.ior) * cos_i
}

fn mean(values: &[f32]) -> f64 {
    values.iter().map(|&v| v as f64).sum::<f64>() / values.len() as f64
}

fn assert_finite(values: &[f32], case: &str) {
    assert!(values.iter().all(|v| v.is_finite()), "{case}: not finite");
}

#[test]
fn a_flat_surface_lights_the_floor_with_exactly_l_t_cos() {
    let flat = Heightfield::flat(24, 20, 0.05).unwrap();
    for sun in [Vec3::NEG_Y, Vec3::new(0.3, -1.0, 0.2), Vec3::new(-2.0, -1.0, 0.5)] {
        let settings = ConvolutionSettings {
            sun_direction: sun,
            sun_irradiance: 3.0,
            extinction: 0.0,
            kernel_radius: 5,
            boundary: Boundary::Periodic,
            ..Default::default()
        };
        let expected = flat_irradiance(&settings);
        for (form, irradiance) in ["direct", "convolution"].iter().zip(both_forms(&flat, &settings)) {
            for e in irradiance {
                assert!((e - expected).abs() <= 2.0 * f32::EPSILON * expected, "{form}, sun {sun}: {e} ≠ {expected}");
            }
        }
    }

    // Mirror walls under a high sun: the same, everywhere.
    let settings = ConvolutionSettings { extinction: 0.0, kernel_radius: 5, ..Default::default() };
    let expected = flat_irradiance(&settings);
    for irradiance in both_forms(&flat, &settings) {
        assert!(irradiance.iter().all(|e| (e - expected).abs() <= 2.0 * f32::EPSILON * expected));
    }
}

#[test]
fn mirror_walls_conserve_flux_and_cast_the_wall_shadow() {
    let (texels, radius) = (24, 5);
    let flat = Heightfield::flat(texels, texels, 0.05).unwrap();
    let settings = ConvolutionSettings { sun_direction: Vec3::new(0.5, -1.0, 0.0), extinction: 0.0, kernel_radius: radius, ..Default::default() };
    let expected = flat_irradiance(&settings);
    let direct = direct_irradiance(&flat, &settings).unwrap();
    assert!((mean(&direct) / expected as f64 - 1.0).abs() < 1e-6, "flux not conserved: {}", mean(&direct));
    let at = |column: usize| direct[texels / 2 * texels + column];
    for column in radius..texels - radius {
        assert!((at(column) - expected).abs() <= 2.0 * f32::EPSILON * expected, "interior {column}: {}", at(column));
    }
    // The light travels towards +x: dark along the wall at x = 0, bright along the other.
    assert!(at(0) < 0.5 * expected && at(texels - 1) > 1.5 * expected, "{} {}", at(0), at(texels - 1));

    // Rippled water: each texel still hands its whole flux to the floor.
    let rippled = waves(texels, 0.05, 0.01, 0.0);
    let light = transmitted_light(&rippled, &settings).unwrap();
    let entering = light.iter().map(|l| l.flux as f64).sum::<f64>() / light.len() as f64;
    for irradiance in both_forms(&rippled, &settings) {
        assert!((mean(&irradiance) / entering - 1.0).abs() < 1e-5, "{} vs {entering}", mean(&irradiance));
    }
}

#[test]
fn extinction_dims_the_flat_floor_uniformly_by_beer_lambert_along_the_refracted_ray() {
    let flat = Heightfield::flat(16, 16, 0.05).unwrap();
    let settings = ConvolutionSettings {
        sun_direction: Vec3::new(0.3, -1.0, 0.0),
        scattering: 200.0,
        exponent: 400.0,
        extinction: 0.5,
        kernel_radius: 12,
        boundary: Boundary::Periodic,
        ..Default::default()
    };
    let clear = flat_irradiance(&settings);
    let cos_t = -transmitted_light(&flat, &settings).unwrap()[0].direction.y;
    let beer_lambert = clear * (-settings.extinction * settings.depth / cos_t).exp();
    let [direct, convolution] = both_forms(&flat, &settings);
    for irradiance in [&direct, &convolution] {
        let first = irradiance[0];
        assert!(irradiance.iter().all(|e| (e - first).abs() <= 4.0 * f32::EPSILON * first));
    }
    assert!((direct[0] / beer_lambert - 1.0).abs() < 0.01, "{} vs {beer_lambert}", direct[0]);
    // The lobe expanded about the refracted sun follows the same path; the paper's,
    // expanded about the vertical, is centred straight down: its path is d.
    assert!((convolution[0] / beer_lambert - 1.0).abs() < 0.01, "{} vs {beer_lambert}", convolution[0]);
    let paper = convolution_irradiance(&flat, &ConvolutionSettings { lobe_axis: LobeAxis::Vertical, ..settings }).unwrap();
    let vertical = clear * (-settings.extinction * settings.depth).exp();
    assert!((paper[0] / vertical - 1.0).abs() < 0.01, "{} vs {vertical}", paper[0]);
}

#[test]
fn the_convolution_form_approaches_the_direct_integral_where_the_approximations_hold() {
    let settings = ConvolutionSettings { kernel_radius: 10, extinction: 0.0, ..Default::default() };
    let error = |heightfield: &Heightfield, settings: &ConvolutionSettings| convolution_error(heightfield, settings).unwrap();
    let decreasing = |errors: &[f32], what: &str| {
        assert!(errors.windows(2).all(|w| w[1] < w[0]), "{what}: {errors:?}");
    };

    // Small slopes: the first-order expansion in L̂t,x and L̂t,z.
    let slopes: Vec<f32> = [0.03, 0.01, 0.003, 0.001].iter().map(|&a| error(&waves(64, 0.05, a, 0.0), &settings)).collect();
    decreasing(&slopes, "slopes");
    assert!(slopes[0] > 0.03 && slopes[3] < 1e-3, "{slopes:?}");

    // d ≫ h: the same waves raised by a fraction of the depth.
    let raised: Vec<f32> = [0.3, 0.1, 0.03, 0.0].iter().map(|&f| error(&waves(64, 0.05, 0.002, f * settings.depth), &settings)).collect();
    decreasing(&raised, "d ≫ h");
    assert!(raised[0] > 2.0 * raised[3], "{raised:?}");

    // The cosine power best matches the Gaussian at n = 2a.
    let surface = waves(64, 0.05, 0.002, 0.0);
    let at = |exponent: f32| error(&surface, &ConvolutionSettings { exponent, ..settings });
    let matched = at(2.0 * settings.scattering);
    assert!(matched < 0.5 * at(settings.scattering) && matched < 0.5 * at(4.0 * settings.scattering));

    // About the vertical (the paper) the expansion needs L̂t,v ≫ L̂t,x: a high sun. About
    // the refracted sun it needs only gentle waves, whatever the sun's height.
    let tilted = |x: f32, lobe_axis: LobeAxis| {
        let sun_direction = Vec3::new(x, -1.0, 0.0);
        error(&surface, &ConvolutionSettings { sun_direction, lobe_axis, boundary: Boundary::Periodic, ..settings })
    };
    let suns: Vec<f32> = [0.4f32, 0.2, 0.1, 0.0].iter().map(|&x| tilted(x, LobeAxis::Vertical)).collect();
    decreasing(&suns, "sun angle");
    let refracted: Vec<f32> = [0.4f32, 0.2, 0.1, 0.0].iter().map(|&x| tilted(x, LobeAxis::RefractedSun)).collect();
    assert_eq!(refracted[3], suns[3], "overhead, both axes are the vertical");
    assert!(refracted.iter().all(|&e| e < 2.0 * refracted[3]), "{refracted:?}");
    assert!(refracted[0] < 0.2 * suns[0], "{refracted:?} against the paper's {suns:?}");
}

#[test]
fn a_kernel_wider_than_the_heightfield_sums_the_extended_surface() {
    // On a periodic patch, the floor under a 3 × 3 tiling of it is its own floor tiled.
    let (texels, radius) = (8, 20);
    let patch = Heightfield::from_fn(texels, texels, 0.05, |x, z| 0.01 * (x * 9.0).sin() * (z * 5.0).cos()).unwrap();
    let tiled = Heightfield::from_fn(3 * texels, 3 * texels, 0.05, |x, z| {
        let wrap = |v: f32| v.rem_euclid(texels as f32 * 0.05);
        0.01 * (wrap(x) * 9.0).sin() * (wrap(z) * 5.0).cos()
    })
    .unwrap();
    let settings = ConvolutionSettings { kernel_radius: radius, boundary: Boundary::Periodic, ..Default::default() };
    for (small, large) in both_forms(&patch, &settings).iter().zip(both_forms(&tiled, &settings)) {
        assert_finite(small, "patch");
        for (index, e) in large.iter().enumerate() {
            let (column, row) = (index % (3 * texels) % texels, index / (3 * texels) % texels);
            let expected = small[row * texels + column];
            assert!((e - expected).abs() < 1e-5 * expected, "{e} vs {expected}");
        }
    }

    // Mirror walls too: flat stays exact, and the forms stay close on gentle waves.
    let settings = ConvolutionSettings { kernel_radius: radius, extinction: 0.0, ..Default::default() };
    let expected = flat_irradiance(&settings);
    for irradiance in both_forms(&Heightfield::flat(texels, 5, 0.05).unwrap(), &settings) {
        assert!(irradiance.iter().all(|e| (e - expected).abs() <= 2.0 * f32::EPSILON * expected));
    }
    assert!(convolution_error(&patch, &settings).unwrap() < 0.02);
}

#[test]
fn stiff_and_extreme_inputs_give_finite_irradiance() {
    let gentle = waves(32, 0.05, 0.005, 0.0);
    let steep = Heightfield::from_fn(32, 32, 0.01, |x, z| 0.5 * (x * 370.0).sin() * (z * 530.0).cos()).unwrap();
    let checkerboard =
        Heightfield::from_fn(16, 16, 0.001, |x, z| if ((x * 1000.0) as usize + (z * 1000.0) as usize).is_multiple_of(2) { 1.0 } else { -1.0 }).unwrap();
    let ripples = waves(32, 0.05, 4e-5, 0.0);
    let still = Heightfield::flat(16, 16, 0.05).unwrap();
    let texel = Heightfield::new(1, 1, 0.05, vec![0.01]).unwrap();
    let base = ConvolutionSettings { depth: 2.0, kernel_radius: 4, ..Default::default() };
    let cases: Vec<(&str, &Heightfield, ConvolutionSettings)> = vec![
        ("steep slopes", &steep, base),
        ("cliffs", &checkerboard, base),
        ("grazing sun", &gentle, ConvolutionSettings { sun_direction: Vec3::new(1.0, -1e-3, 0.3), ..base }),
        ("horizontal sun", &steep, ConvolutionSettings { sun_direction: Vec3::X, ..base }),
        ("horizontal sun, IOR 1", &steep, ConvolutionSettings { sun_direction: Vec3::X, ior: 1.0, ..base }),
        ("huge sun vector", &gentle, ConvolutionSettings { sun_direction: Vec3::new(3e38, -3e38, 0.0), ..base }),
        ("deep", &gentle, ConvolutionSettings { depth: 1e4, ..base }),
        ("abyss", &gentle, ConvolutionSettings { depth: 3e38, extinction: 0.0, ..base }),
        ("shallow", &ripples, ConvolutionSettings { depth: 1e-4, ..base }),
        ("film", &still, ConvolutionSettings { depth: 1e-30, ..base }),
        ("a = 0, n = 0", &gentle, ConvolutionSettings { scattering: 0.0, exponent: 0.0, ..base }),
        ("huge a and n", &steep, ConvolutionSettings { scattering: 1e30, exponent: MAX_EXPONENT, ..base }),
        ("ε = 0", &steep, ConvolutionSettings { extinction: 0.0, ..base }),
        ("huge ε", &steep, ConvolutionSettings { extinction: 1e30, ..base }),
        ("huge everything", &checkerboard, ConvolutionSettings { scattering: 3e38, extinction: 3e38, exponent: MAX_EXPONENT, sun_irradiance: 1e6, ..base }),
        ("single texel", &texel, ConvolutionSettings { kernel_radius: 9, ..base }),
    ];
    for (case, heightfield, settings) in cases {
        for boundary in [Boundary::Mirror, Boundary::Periodic] {
            let settings = ConvolutionSettings { boundary, ..settings };
            let [direct, convolution] = both_forms(heightfield, &settings);
            assert_finite(&direct, case);
            assert_finite(&convolution, case);
            assert!(direct.iter().all(|&e| e >= 0.0), "{case}: negative direct irradiance");
        }
    }

    // What the limits mean: light put nowhere, or all absorbed.
    let flat = Heightfield::flat(8, 8, 0.05).unwrap();
    for settings in [ConvolutionSettings { sun_direction: Vec3::X, ..base }, ConvolutionSettings { extinction: 1e30, ..base }] {
        for irradiance in both_forms(&flat, &settings) {
            assert!(irradiance.iter().all(|&e| e == 0.0));
        }
    }
}

#[test]
fn hundreds_of_impulses_make_a_finite_surface_and_finite_caustics() {
    let mut pool = PoolRipples::new(48, 48, 0.05, RippleSettings::default()).unwrap();
    let mut seed = 12345u32;
    let mut next = || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32
    };
    for drop in 0..400 {
        let position = Vec2::new(next(), next()) * pool.size();
        pool.drop_pebble(position, 0.002 + 0.01 * next(), drop as f32 * 0.005).unwrap();
    }
    let surface = pool.heightfield(2.5).unwrap();
    assert_eq!(pool.impulses().len(), 400);
    assert!(surface.heights().iter().any(|h| h.abs() > 1e-3));
    let settings = ConvolutionSettings { kernel_radius: 6, ..Default::default() };
    for irradiance in both_forms(&surface, &settings) {
        assert_finite(&irradiance, "400 impulses");
    }
}

#[test]
fn bad_input_is_a_clear_error() {
    let flat = Heightfield::flat(8, 8, 0.05).unwrap();
    let ok = ConvolutionSettings::default();
    let bad = [
        ConvolutionSettings { ior: 0.5, ..ok },
        ConvolutionSettings { ior: f32::NAN, ..ok },
        ConvolutionSettings { ior: f32::INFINITY, ..ok },
        ConvolutionSettings { depth: -1.0, ..ok },
        ConvolutionSettings { depth: 0.0, ..ok },
        ConvolutionSettings { depth: f32::NAN, ..ok },
        ConvolutionSettings { sun_direction: Vec3::Y, ..ok },
        ConvolutionSettings { sun_direction: Vec3::ZERO, ..ok },
        ConvolutionSettings { sun_direction: Vec3::new(f32::NAN, -1.0, 0.0), ..ok },
        ConvolutionSettings { sun_irradiance: -1.0, ..ok },
        ConvolutionSettings { scattering: f32::NAN, ..ok },
        ConvolutionSettings { extinction: -0.1, ..ok },
        ConvolutionSettings { exponent: -1.0, ..ok },
        ConvolutionSettings { exponent: 2.0 * MAX_EXPONENT, ..ok },
        ConvolutionSettings { kernel_radius: MAX_KERNEL_RADIUS + 1, ..ok },
    ];
    for settings in bad {
        assert!(settings.validate().is_err(), "{settings:?}");
        assert!(direct_irradiance(&flat, &settings).is_err());
        assert!(convolution_irradiance(&flat, &settings).is_err());
    }
    assert_eq!(ConvolutionSettings { ior: 0.5, ..ok }.validate(), Err(ParamError::ImpossibleIor(0.5)));

    assert!(matches!(Heightfield::new(4, 4, 0.05, vec![0.0; 15]), Err(ParamError::OutOfRange { .. })));
    assert!(matches!(Heightfield::new(2, 2, 0.05, vec![0.0, f32::NAN, 0.0, 0.0]), Err(ParamError::NotFinite { .. })));
    assert!(Heightfield::new(0, 4, 0.05, vec![]).is_err());
    assert!(Heightfield::flat(4, 0, 0.05).is_err());
    assert!(Heightfield::flat(MAX_HEIGHTFIELD_SIDE + 1, 1, 0.05).is_err());
    for cell in [0.0, -0.05, f32::NAN, f32::INFINITY] {
        assert!(Heightfield::flat(4, 4, cell).is_err());
        assert!(ConvolutionCaustics::new(&ok, 4, 4, cell).is_err());
    }

    // The surface must stay above the floor.
    let touching = Heightfield::from_fn(8, 8, 0.05, |x, _| if x < 0.1 { -ok.depth } else { 0.0 }).unwrap();
    for result in [direct_irradiance(&touching, &ok), convolution_irradiance(&touching, &ok)] {
        assert!(matches!(result, Err(ParamError::OutOfRange { name: "lowest surface height", .. })));
    }
    // A plan serves its own size only.
    let mut plan = ConvolutionCaustics::new(&ok, 8, 8, 0.05).unwrap();
    assert!(plan.irradiance(&Heightfield::flat(8, 9, 0.05).unwrap()).is_err());
    assert!(plan.irradiance(&Heightfield::flat(8, 8, 0.04).unwrap()).is_err());
    assert!(plan.irradiance(&flat).is_ok());

    // Ripples.
    assert!(PoolRipples::new(8, 8, 0.05, RippleSettings { time_damping: 0.0, front_damping: 0.0, ..Default::default() }).is_err());
    for settings in [
        RippleSettings { wave_number: 0.0, ..Default::default() },
        RippleSettings { angular_frequency: f32::NAN, ..Default::default() },
        RippleSettings { time_damping: -1.0, ..Default::default() },
        RippleSettings { expiry_height: 0.0, ..Default::default() },
    ] {
        assert!(settings.validate().is_err(), "{settings:?}");
    }
    let mut pool = PoolRipples::new(8, 8, 0.05, RippleSettings::default()).unwrap();
    assert!(pool.drop_pebble(Vec2::new(0.5, 0.1), 0.01, 0.0).is_err(), "outside the 0.4 m pool");
    assert!(pool.drop_pebble(Vec2::new(0.1, -0.01), 0.01, 0.0).is_err());
    assert!(pool.drop_pebble(Vec2::new(f32::NAN, 0.1), 0.01, 0.0).is_err());
    assert!(pool.drop_pebble(Vec2::new(0.1, 0.1), f32::INFINITY, 0.0).is_err());
    assert!(pool.drop_pebble(Vec2::new(0.1, 0.1), 0.01, f32::NAN).is_err());
    assert!(pool.impulses().is_empty());
}

fn scripted_pool() -> PoolRipples {
    let mut pool = PoolRipples::new(32, 24, 0.05, RippleSettings::default()).unwrap();
    let drops = [(Vec2::new(0.4, 0.3), 0.01, 0.0), (Vec2::new(1.2, 0.9), -0.02, 0.35), (Vec2::new(0.1, 1.1), 0.015, 0.8)];
    for (position, strength, time) in drops {
        pool.drop_pebble(position, strength, time).unwrap();
    }
    pool
}

#[test]
fn ripples_from_scripted_drops_are_deterministic() {
    let (first, second) = (scripted_pool(), scripted_pool());
    for time in [0.0, 0.5, 1.3, 4.0] {
        assert_eq!(first.heightfield(time).unwrap(), second.heightfield(time).unwrap());
    }
    // Nothing before the first drop, waves after it.
    assert!(first.heightfield(0.0).unwrap().heights().iter().all(|&h| h == 0.0));
    assert!(first.heightfield(1.3).unwrap().heights().iter().any(|&h| h.abs() > 1e-3));
}

#[test]
fn the_wave_starts_at_its_front_and_moves_at_omega_over_k() {
    let settings = RippleSettings::default();
    let speed = (settings.angular_frequency / settings.wave_number) as f64;
    let t = 0.8;
    let front = settings.front_distance(t);
    assert!((front - speed * t).abs() < 1e-12);
    assert_eq!(settings.impulse_height(t, front + 1e-6), 0.0);
    assert_eq!(settings.impulse_height(-0.1, 0.0), 0.0);
    assert!(settings.impulse_height(t, front - 1e-9).abs() < 1e-6, "the wave starts at height 0");
    // Behind the front: a damped sine, |h| ≤ exp(−β(f − d)) exp(−αt).
    for d in [0.0, 0.1, 0.2, 0.35] {
        let bound = (-(settings.front_damping as f64) * (front - d) - settings.time_damping as f64 * t).exp();
        assert!(settings.impulse_height(t, d).abs() <= bound);
    }
}

#[test]
fn a_drop_near_a_wall_is_reflected_by_its_mirror_image() {
    let mut pool = PoolRipples::new(40, 40, 0.05, RippleSettings::default()).unwrap();
    let drop = Vec2::new(0.15, 0.3);
    pool.drop_pebble(drop, 0.01, 0.0).unwrap();
    let images = mirror_images(drop, pool.size());
    assert_eq!(images[0], drop.as_dvec2());
    assert!(images.contains(&Vec2::new(-0.15, 0.3).as_dvec2()) && images.contains(&Vec2::new(-0.15, -0.3).as_dvec2()));

    // Before the images beyond the far walls arrive (a pool's width away), the height is
    // the wave of the drop plus its images across the walls at x = 0 and z = 0.
    let settings = *pool.settings();
    let time = 1.2;
    assert!(settings.front_distance(time as f64) < 2.0 - 0.15);
    let point = Vec2::new(0.4, 0.5);
    let near_images = [Vec2::new(0.15, 0.3), Vec2::new(-0.15, 0.3), Vec2::new(0.15, -0.3), Vec2::new(-0.15, -0.3)];
    let expected: f64 = near_images.iter().map(|i| 0.01 * settings.impulse_height(time as f64, point.distance(*i) as f64)).sum();
    assert!((pool.height_at(point, time) as f64 - expected).abs() < 1e-8);
    let alone = 0.01 * settings.impulse_height(time as f64, point.distance(drop) as f64);
    assert!((expected - alone).abs() > 1e-4, "the reflection changes the height");

    // The normal derivative vanishes along both walls of the corner, the corner too.
    let delta = 1e-3;
    let mut steepest = 0.0f32;
    for step in 0..=40 {
        let along = step as f32 * 0.05;
        for (inside, outside) in [(Vec2::new(delta, along), Vec2::new(-delta, along)), (Vec2::new(along, delta), Vec2::new(along, -delta))] {
            let derivative = (pool.height_at(inside, time) - pool.height_at(outside, time)) / (2.0 * delta);
            assert!(derivative.abs() < 1e-5, "∂h/∂n = {derivative} at {inside}");
        }
        let tangential = (pool.height_at(Vec2::new(along + delta, 0.7), time) - pool.height_at(Vec2::new(along - delta, 0.7), time)) / (2.0 * delta);
        steepest = steepest.max(tangential.abs());
    }
    assert!(steepest > 0.01, "the waves have slopes ({steepest}) where the walls have none");
}

#[test]
fn faded_impulses_expire() {
    let mut pool = scripted_pool();
    let expiry = pool.settings().expiry_height as f64;
    assert_eq!(pool.remove_expired(0.5), 0);
    let last = pool.impulses()[2];
    // Find when the first impulse can no longer matter; the later ones still do.
    let mut time = 1.0f32;
    while pool.impulse_bound(&pool.impulses()[0], time) >= expiry {
        time += 0.25;
    }
    let before = pool.heightfield(time).unwrap();
    assert_eq!(pool.remove_expired(time), 1);
    assert_eq!(pool.impulses().len(), 2);
    assert_eq!(pool.impulses()[1], last, "order kept");
    let after = pool.heightfield(time).unwrap();
    for (b, a) in before.heights().iter().zip(after.heights()) {
        assert!(((b - a) as f64).abs() <= expiry);
    }
    // Eventually all fade; an impulse dropped later than `time` is never removed.
    pool.drop_pebble(Vec2::new(0.8, 0.6), 0.01, 1000.0).unwrap();
    assert_eq!(pool.remove_expired(100.0), 2);
    assert_eq!(pool.impulses().len(), 1);
    assert_eq!(pool.remove_expired(2000.0), 1);
    assert!(pool.heightfield(2000.0).unwrap().heights().iter().all(|&h| h == 0.0));
}

#[test]
fn the_kernels_are_the_expansion_of_eq_2() {
    let settings = ConvolutionSettings { kernel_radius: 2, exponent: 7.0, extinction: 0.3, ..Default::default() };
    let cell = 0.1;
    let kernels = ConvolutionKernels::new(&settings, cell).unwrap();
    assert_eq!(kernels.taps().len(), 25);
    // The centre tap is straight down; the horizontal kernels are odd, the vertical even.
    let centre = kernels.taps()[12];
    let attenuation = (-settings.extinction as f64 * settings.depth as f64).exp();
    assert_eq!(centre[0], 0.0);
    assert!((centre[2] - attenuation).abs() < 1e-12);
    let tap = |dx: isize, dz: isize| kernels.taps()[((dz + 2) * 5 + dx + 2) as usize];
    assert_eq!(tap(1, 2)[0], -tap(-1, 2)[0]);
    assert_eq!(tap(1, 2)[2], tap(-1, -2)[2]);
    // One tap against n P̂_vⁿ P̂_x e^{−ε‖P‖} by hand (the sun is overhead: the axis is
    // the vertical, whose tilt kernels are odd and need no share taken).
    let (x, z, d) = (2.0 * cell as f64, cell as f64, settings.depth as f64);
    let length = (x * x + z * z + d * d).sqrt();
    let expected = 7.0 * (d / length).powi(7) * (x / length) * (-(settings.extinction as f64) * length).exp();
    assert!((tap(2, 1)[0] / expected - 1.0).abs() < 1e-12);
    // Seen across a wall along x, the x kernel flips; the others do not.
    let mirrored = kernels.mirrored_taps(true, false)[((1 + 2) * 5 + 2 + 2) as usize];
    assert_eq!(mirrored, [-tap(2, 1)[0], tap(2, 1)[1], tap(2, 1)[2]]);

    // The per-texel terms: [L̂t,x / L̂t,v, L̂t,z / L̂t,v, 1] F / K.
    let light = TransmittedLight { flux: 2.0, direction: Vec3::new(0.1, -0.9, 0.2).normalize() };
    let terms = kernels.terms(&light);
    let scale = 2.0 / kernels.normaliser();
    assert!((terms[2] - scale).abs() < 1e-12);
    assert!((terms[0] / (scale * light.direction.x as f64 / -light.direction.y as f64) - 1.0).abs() < 1e-6);
    assert_eq!(kernels.terms(&TransmittedLight { flux: 0.0, direction: Vec3::NEG_Y }), [0.0; 3]);
}

#[test]
fn the_transmitted_light_is_snell_and_the_papers_fresnel_transmission() {
    let ior = 1.333f32;
    for sun in [Vec3::NEG_Y, Vec3::new(0.5, -1.0, 0.0), Vec3::new(-1.0, -0.3, 2.0)] {
        let settings = ConvolutionSettings { ior, sun_direction: sun, sun_irradiance: 2.0, ..Default::default() };
        let light = transmitted_light(&Heightfield::flat(2, 2, 0.1).unwrap(), &settings).unwrap()[0];
        let (cos_i, cos_t) = (-settings.sun_unit().y as f64, -light.direction.y as f64);
        // Snell (eq. 1): sin θi = n sin θt, in the plane of incidence.
        let (sin_i, sin_t) = ((1.0 - cos_i * cos_i).sqrt(), (1.0 - cos_t * cos_t).sqrt());
        assert!((sin_i - ior as f64 * sin_t).abs() < 1e-6);
        assert!(light.direction.x * sun.x >= 0.0 && light.direction.z * sun.z >= 0.0);
        // §4: T(θi) = 2 (n_t cos θt / n_i cos θi)([n_i cos θi / (n_i cos θi + n_t cos θt)]² + [n_i cos θi / (n_t cos θi + n_i cos θt)]²).
        let n_t = ior as f64;
        let paper = 2.0 * (n_t * cos_t / cos_i) * ((cos_i / (cos_i + n_t * cos_t)).powi(2) + (cos_i / (n_t * cos_i + cos_t)).powi(2));
        assert!((light.flux as f64 / (2.0 * paper * cos_i) - 1.0).abs() < 1e-5, "{} vs {}", light.flux, 2.0 * paper * cos_i);
    }
}

#[test]
fn narrow_lobes_never_subtract_light_and_keep_the_flux() {
    // The pool example's sliders reach n = 10 000 (a = n/2): there the tilt kernels
    // undershoot beside the foci of steep waves. The lift removes every negative texel,
    // keeps the floor's flux to rounding, and leaves the result no farther from the
    // direct integral (whose Gaussian lobe is positive everywhere) than the signed sum.
    for (amplitude, exponent) in [(0.02f32, 400.0f32), (0.05, 400.0), (0.05, 1000.0), (0.08, 1000.0), (0.05, 10_000.0), (0.02, 10_000.0)] {
        let surface = waves(64, 0.05, amplitude, 0.0);
        let settings = ConvolutionSettings { exponent, scattering: 0.5 * exponent, kernel_radius: 6, ..Default::default() };
        let mut plan = ConvolutionCaustics::new(&settings, 64, 64, 0.05).unwrap();
        let signed = plan.signed_irradiance(&surface).unwrap();
        let lifted = plan.irradiance(&surface).unwrap();
        let direct = direct_irradiance(&surface, &settings).unwrap();
        let negative: f64 = signed.iter().filter(|&&e| e < 0.0).map(|&e| -e as f64).sum();
        let flux = |e: &[f32]| e.iter().map(|&v| v as f64).sum::<f64>();
        let l2 = |e: &[f32]| caustics_core::metrics::relative_l2(e, &direct);
        eprintln!(
            "amplitude {amplitude}, n = {exponent}: negative flux {:.2} % of the floor's, relative L2 against the direct integral {:.4} signed, {:.4} lifted",
            100.0 * negative / flux(&signed),
            l2(&signed),
            l2(&lifted)
        );
        assert!(lifted.iter().all(|&e| e >= 0.0), "n = {exponent}: negative irradiance");
        assert!((flux(&lifted) / flux(&signed) - 1.0).abs() < 1e-5, "n = {exponent}: flux {} against {}", flux(&lifted), flux(&signed));
        assert!(l2(&lifted) <= l2(&signed) + 1e-6, "n = {exponent}");
    }
}
