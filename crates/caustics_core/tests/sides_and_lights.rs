//! How generators and lights meet, as glTF and Bevy define them: glTF's `doubleSided`
//! (`Generator::double_sided`, `Sides`) — an open mirror lit from behind casts nothing
//! when one-sided and, when double-sided, exactly what it casts lit from the front, in
//! the tracer, the warped volumes and the hierarchical maps alike — and Bevy's light
//! `range` (`Light::range_attenuation`).

use caustics_core::estimate::{GridRegion, IrradianceGrid};
use caustics_core::hierarchical::{CausticMapSettings, scene_caustics};
use caustics_core::mesh::TriMesh;
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{Generator, Light, LightKind, Receiver, Scene, Sides};
use caustics_core::tracer::{PhotonTracer, TraceSettings, TraceStats};
use caustics_core::volumes::{VolumeSettings, build_scene_volumes};
use glam::Vec3;

/// The sun slanting 45° towards +x onto a 1 m square mirror that leans over the floor
/// (its normal 14° below the horizontal) and throws the light back down beside it;
/// the mirror faces the sun (`front`) or turns its back to it.
fn mirror_scene(front: bool, double_sided: bool) -> Scene {
    let (u, v) = (Vec3::Z * 0.5, Vec3::new(-0.235, 0.972, 0.0).normalize() * 0.5);
    let centre = Vec3::new(0.5, 1.0, 0.0);
    let mesh = if front { TriMesh::quad(centre, u, v) } else { TriMesh::quad(centre, v, u) };
    assert_eq!(mesh.normals()[0].dot(SUN) < 0.0, front, "the quad faces the sun when `front`");
    let floor = TriMesh::quad(Vec3::ZERO, Vec3::Z * 10.0, Vec3::X * 10.0);
    Scene {
        lights: vec![Light::white(LightKind::Directional { direction: SUN, irradiance: 1.0 })],
        generators: vec![Generator { mesh, interaction: SpecularInteraction::Reflect, double_sided }],
        receivers: vec![Receiver { mesh: floor, albedo: Vec3::ONE }],
    }
}

const SUN: Vec3 = Vec3::new(std::f32::consts::FRAC_1_SQRT_2, -std::f32::consts::FRAC_1_SQRT_2, 0.0);

fn traced(scene: &Scene) -> TraceStats {
    let region = GridRegion::horizontal(-1.0, -1.0, 0.0, 2.0, 8);
    let mut grid = IrradianceGrid::new(region);
    let settings = TraceSettings { photons_per_light: 1 << 20, seed: 3, ..Default::default() };
    PhotonTracer::new(scene).unwrap().trace(&settings, &mut grid, &|_, _| {})
}

fn volume_flux(scene: &Scene) -> f32 {
    build_scene_volumes(scene, &VolumeSettings::default()).flux().x
}

fn map_flux(scene: &Scene) -> f64 {
    let settings = CausticMapSettings { photon_resolution: 128, map_resolution: 128, ..Default::default() };
    scene_caustics(scene, &settings).iter().map(|view| view.map.total_flux()).sum()
}

#[test]
fn an_open_mirror_lit_from_behind_reflects_only_when_double_sided() {
    assert_eq!(mirror_scene(false, false).generators[0].sides(), Sides::Front);
    assert_eq!(mirror_scene(false, true).generators[0].sides(), Sides::Both);
    let front = mirror_scene(true, false);
    let (behind_one, behind_both) = (mirror_scene(false, false), mirror_scene(false, true));

    let (t_front, t_one, t_both) = (traced(&front), traced(&behind_one), traced(&behind_both));
    assert!(t_front.deposited.x > 0.1 * t_front.emitted.x, "{t_front:?}");
    assert_eq!(t_one.deposited.x, 0.0, "a one-sided mirror's back reflects: {t_one:?}");
    // Its back absorbs all it meets: E·A·|cos θ| of the 1 m² square.
    let met = f64::from(behind_one.generators[0].mesh.normals()[0].dot(SUN).abs());
    assert!((t_one.absorbed.x - met).abs() < 5e-3 * met, "its back absorbs what it meets: {t_one:?}");
    // The same photons (same seed) meet the same mirror, turned over.
    assert!((t_both.deposited.x - t_front.deposited.x).abs() < 1e-4 * t_front.deposited.x, "{t_both:?} vs {t_front:?}");

    let (v_front, v_one, v_both) = (volume_flux(&front), volume_flux(&behind_one), volume_flux(&behind_both));
    assert!(v_front > 0.0);
    assert_eq!(v_one, 0.0);
    assert!((v_both - v_front).abs() < 1e-4 * v_front, "volumes: {v_both} vs {v_front}");

    let (m_front, m_one, m_both) = (map_flux(&front), map_flux(&behind_one), map_flux(&behind_both));
    assert!(m_front > 0.0);
    assert_eq!(m_one, 0.0);
    assert!((m_both - m_front).abs() < 1e-4 * m_front, "maps: {m_both} vs {m_front}");
    eprintln!(
        "mirror lit from the front / behind, double-sided: tracer {:.4} / {:.4}, volumes {v_front:.4} / {v_both:.4}, maps {m_front:.4} / {m_both:.4}",
        t_front.deposited.x, t_both.deposited.x
    );
}

#[test]
fn closed_generators_ignore_double_sided() {
    // A glass ball's faces are crossed from inside whatever glTF says.
    let ball = TriMesh::uv_sphere(Vec3::Y, 0.5, 16, 32);
    let scene = |double_sided| Scene {
        lights: vec![Light::white(LightKind::Point { position: Vec3::Y * 4.0, intensity: 10.0 })],
        generators: vec![Generator { mesh: ball.clone(), interaction: SpecularInteraction::Refract { ior: 1.5, dispersion: None }, double_sided }],
        receivers: vec![Receiver { mesh: TriMesh::quad(Vec3::ZERO, Vec3::Z * 4.0, Vec3::X * 4.0), albedo: Vec3::ONE }],
    };
    let (one, both) = (scene(false), scene(true));
    assert_eq!((one.generators[0].sides(), both.generators[0].sides()), (Sides::Closed, Sides::Closed));
    let (t_one, t_both) = (traced(&one), traced(&both));
    assert_eq!(t_one.absorbed.x, 0.0);
    assert_eq!(t_one.deposited, t_both.deposited);
    assert_eq!(volume_flux(&one), volume_flux(&both));
    assert_eq!(map_flux(&one), map_flux(&both));
}

#[test]
fn a_point_lights_range_fades_its_caustic_as_bevy_fades_its_light() {
    // A mirror 0.5 m over a point light throws its light back onto the floor; with a
    // range the caustic fades by Bevy's window (1 − (d/range)⁴)² on its whole path
    // (about 1.5 m), in the tracer and the volumes alike, and a range short of the
    // mirror casts nothing.
    // 24² cells, facing down: the volumes sample the window at every vertex.
    let up = TriMesh::heightfield(25, 1.2, |_, _| 1.0, |_, _| Vec3::Y).unwrap();
    let down = |n: &Vec3| -*n;
    let mirror =
        TriMesh::new(up.positions().to_vec(), up.normals().iter().map(down).collect(), up.triangles().iter().map(|t| [t[0], t[2], t[1]]).collect()).unwrap();
    let scene = |range: f32| Scene {
        lights: vec![Light { range, ..Light::white(LightKind::Point { position: Vec3::Y * 0.5, intensity: 3.0 }) }],
        generators: vec![Generator::new(mirror.clone(), SpecularInteraction::Reflect)],
        receivers: vec![Receiver { mesh: TriMesh::quad(Vec3::ZERO, Vec3::Z * 10.0, Vec3::X * 10.0), albedo: Vec3::ONE }],
    };
    let light = scene(3.0).lights[0];
    assert_eq!(light.range_attenuation(3.0), 0.0);
    assert!((light.range_attenuation(1.5) - (1.0f32 - 0.5f32.powi(4)).powi(2)).abs() < 1e-6);
    // The caustic flux on the floor: the volumes integrated over it (their own flux is
    // the light crossing the mirror, before the path fades it).
    let on_floor = |scene: &Scene| {
        let set = build_scene_volumes(scene, &VolumeSettings::default());
        let (n, size) = (256, 4.0f32);
        let cell = size / n as f32;
        (0..n * n)
            .map(|i| {
                let p = Vec3::new(-0.5 * size + cell * ((i % n) as f32 + 0.5), 0.0, -0.5 * size + cell * ((i / n) as f32 + 0.5));
                set.irradiance(p, Vec3::Y, &VolumeSettings::default()).x as f64
            })
            .sum::<f64>()
            * (cell * cell) as f64
    };
    let (t_open, v_open) = (traced(&scene(f32::INFINITY)).deposited.x, on_floor(&scene(f32::INFINITY)));
    let (t_ranged, v_ranged) = (traced(&scene(3.0)).deposited.x, on_floor(&scene(3.0)));
    eprintln!("range 3 m: tracer {:.4} of its open flux, volumes {:.4}", t_ranged / t_open, v_ranged / v_open);
    assert!(t_ranged < 0.9 * t_open && t_ranged > 0.3 * t_open, "{t_ranged} of {t_open}");
    assert!((v_ranged / t_ranged - v_open / t_open).abs() < 0.01 * v_open / t_open, "the volumes fade as the tracer does");
    assert_eq!((traced(&scene(0.45)).deposited.x, on_floor(&scene(0.45))), (0.0, 0.0), "a range short of the mirror");
}
