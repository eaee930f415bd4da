//! The live comparison (the debug panel's "compare with reference") and `caustics
//! bench` on the frame it saved give the same numbers, within their traces' noise.
//!
//! A game's scene, made of Bevy's own meshes (a floor and a wall that receive, a box
//! that only casts shadows, a rippling pool with two pebbles' impulses in it and a
//! participating medium in its water, a glass
//! ball and a tilted mirror under the sun, seen at a slant with Bevy's default MSAA),
//! is measured live on lavapipe; its frame is saved;
//! the `caustics` program rebuilds the scene from the file in a renderer of its own and
//! measures it again, with a photon stream of its own. Both read every technique at
//! the same pixels: the numbers may differ only by what the two references' noise
//! allows. One test function: a process holds one Bevy app with a render device at a
//! time.

use bevy::camera::Exposure;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use caustics_bevy::comparison::{ReferenceComparison, compare_headless};
use caustics_bevy::headless::HeadlessRenderer;
use caustics_bevy::{CausticGenerator, CausticReceiver, CausticTechnique, Caustics, DropPebble, ParticipatingMedium, PoolRipples};
use caustics_core::metrics::relative_l2;
use std::process::Command;
use std::time::Duration;

const WIDTH: u32 = 96;
const HEIGHT: u32 = 72;
/// Photons per light of the live trace: those of a quick bench's (`VIEW_PHOTONS`).
const PHOTONS: u64 = 1 << 20;

/// A row of `views.csv`: technique, what the generators drew with, pixels, L2, L1 and
/// the reference's noise.
struct Row {
    technique: String,
    drawn: Vec<String>,
    pixels: usize,
    l2: f32,
    l1: f32,
    noise: f32,
}

/// Splits a CSV line whose quoted fields hold no quotes.
fn fields(line: &str) -> Vec<String> {
    let (mut out, mut field, mut quoted) = (Vec::new(), String::new(), false);
    for c in line.chars() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => out.push(std::mem::take(&mut field)),
            c => field.push(c),
        }
    }
    out.push(field);
    out
}

/// Each generator's choice, in an order that does not depend on entity ids.
fn choices(drawn: &str) -> Vec<String> {
    let mut pieces: Vec<String> = drawn.split("; ").map(String::from).collect();
    pieces.sort();
    pieces
}

fn spawn_game_scene(renderer: &mut HeadlessRenderer) -> Entity {
    let target = renderer.render_target();
    let world = renderer.world_mut();
    world.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(50)));
    let mut mesh = |m: Mesh| world.resource_mut::<Assets<Mesh>>().add(m);
    let (floor, wall, block, ball, mirror) = (
        mesh(Plane3d::new(Vec3::Y, Vec2::splat(2.0)).mesh().build()),
        mesh(Plane3d::new(Vec3::Z, Vec2::new(2.0, 1.0)).mesh().build()),
        mesh(Cuboid::new(0.4, 0.3, 0.4).mesh().build()),
        mesh(Sphere::new(0.3).mesh().ico(3).unwrap()),
        mesh(Plane3d::new(Vec3::Y, Vec2::splat(0.25)).mesh().build()),
    );
    let tiles = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { base_color: Color::srgb(0.8, 0.85, 0.9), ..default() });
    world.spawn((Mesh3d(floor), MeshMaterial3d(tiles.clone()), CausticReceiver));
    world.spawn((Mesh3d(wall), MeshMaterial3d(tiles.clone()), Transform::from_xyz(0.0, 1.0, -1.5), CausticReceiver));
    // Casts the sun's shadow and blocks caustic light, shows none.
    world.spawn((Mesh3d(block), MeshMaterial3d(tiles), Transform::from_xyz(1.2, 0.15, 0.6)));
    // A rippling pool's water, 1.6 m square, half a metre over the floor.
    world.spawn((
        PoolRipples { columns: 32, rows: 32, cell_size: 0.05, depth: 0.5, ..default() },
        CausticGenerator::refractive(1.333),
        Transform::from_xyz(-1.0, 0.5, 0.0),
    ));
    // Its water scatters the focused light into shafts.
    world.spawn((
        ParticipatingMedium { scattering: 0.3, absorption: Vec3::splat(0.05), asymmetry: 0.5 },
        Transform::from_xyz(-1.0, 0.25, 0.0).with_scale(Vec3::new(1.6, 0.5, 1.6)),
    ));
    world.spawn((Mesh3d(ball), CausticGenerator::refractive(1.5), Transform::from_xyz(0.6, 0.6, 0.1)));
    // Tilted towards the wall, so that its reflection lands there.
    world.spawn((Mesh3d(mirror), CausticGenerator::mirror(), Transform::from_xyz(1.0, 0.4, -0.6).with_rotation(Quat::from_rotation_x(-0.5))));
    world.spawn((
        DirectionalLight { illuminance: 20_000.0, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::new(0.25, -1.0, -0.35), Vec3::Y),
    ));
    world
        .spawn((
            Camera3d::default(),
            Caustics::default(),
            target,
            Exposure { ev100: 12.0 },
            Projection::from(PerspectiveProjection { fov: 1.0, ..default() }),
            Transform::from_xyz(-0.2, 2.6, 2.8).looking_at(Vec3::new(-0.2, 0.2, -0.3), Vec3::Y),
        ))
        .id()
}

#[test]
fn the_live_comparison_and_the_bench_on_its_saved_frame_agree_within_the_noise() {
    let mut renderer = HeadlessRenderer::timed(WIDTH, HEIGHT).unwrap_or_else(|e| panic!("{e}"));
    let camera = spawn_game_scene(&mut renderer);
    // Two pebbles in the pool, a few frames apart, then the ripples spread a while.
    for position in [Vec3::new(-1.3, 0.5, 0.3), Vec3::new(-0.6, 0.5, -0.4)] {
        renderer.world_mut().write_message(DropPebble { position, strength: 0.01 });
        renderer.render(3).unwrap_or_else(|e| panic!("{e}"));
    }
    renderer.render(4).unwrap_or_else(|e| panic!("{e}"));
    compare_headless(&mut renderer, camera, (PHOTONS, 0)).unwrap_or_else(|e| panic!("the live comparison failed: {e}"));
    let dir = std::env::temp_dir().join(format!("caustics-comparison-frames-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let frame = dir.join("frame.json");
    let live = renderer.world_mut().resource::<ReferenceComparison>();
    live.save_frame(&frame).unwrap_or_else(|e| panic!("{e}"));
    let saved = live.frame.as_ref().unwrap();
    assert_eq!((saved.scene.generators.len(), saved.scene.receivers.len(), saved.shown), (3, 3, 2), "pool, ball and mirror; floor, wall, then the box");
    assert_eq!(saved.pools.len(), 1);
    assert_eq!(saved.pools[0].impulses.len(), 2, "the pool's live impulses");
    assert_eq!(saved.media.len(), 1);
    let live_noise = live.reference_noise.unwrap();

    let out = Command::new(env!("CARGO_BIN_EXE_caustics"))
        .args(["bench", "--quick", "--scenes", "", "--scene", frame.to_str().unwrap(), "--out", dir.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "caustics bench failed:\n{}", String::from_utf8_lossy(&out.stderr));
    let csv = std::fs::read_to_string(dir.join("views.csv")).unwrap();
    let bench: Vec<Row> = csv
        .lines()
        .skip(1)
        .map(|line| {
            let f = fields(line);
            let number = |i: usize| f[i].parse::<f32>().unwrap_or_else(|_| panic!("{line}"));
            Row { technique: f[1].clone(), drawn: choices(&f[2]), pixels: f[3].parse().unwrap(), l2: number(4), l1: number(5), noise: number(6) }
        })
        .collect();
    assert_eq!(bench.len(), live.rows.len(), "{csv}");
    // The same photon count: the two references are equally noisy.
    let bench_noise = bench[0].noise;
    eprintln!("the references' own noise: live {live_noise:.4}, bench {bench_noise:.4}");
    assert!((bench_noise / live_noise - 1.0).abs() < 0.25, "noise live {live_noise}, bench {bench_noise}");
    // The same scene: each technique draws the same light at the same pixels in both
    // programs, and the two references differ by their noise alone.
    let measured: Vec<bool> = live.reference.iter().map(Option::is_some).collect();
    let grey_of = |pixels: &[Vec3]| pixels.iter().zip(&measured).filter(|(_, m)| **m).map(|(e, _)| e.element_sum() / 3.0).collect::<Vec<f32>>();
    let exr = |label: &str| {
        let path = dir.join("views").join(format!("frame-{}.exr", label.replace(' ', "-")));
        let image = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).into_rgb32f();
        grey_of(&image.pixels().map(|p| Vec3::from_array(p.0)).collect::<Vec<_>>())
    };
    let live_reference = grey_of(&live.reference.iter().map(|e| e.unwrap_or(Vec3::ZERO)).collect::<Vec<_>>());
    let references_apart = relative_l2(&exr("reference"), &live_reference);
    let noise = (live_noise.powi(2) + bench_noise.powi(2)).sqrt();
    eprintln!("the references {references_apart:.4} apart, their noise {noise:.4}");
    assert!((references_apart / noise - 1.0).abs() < 0.3, "the references are {references_apart} apart, their noise {noise}");
    for row in &live.rows {
        let apart = relative_l2(&exr(row.technique.label()), &grey_of(&row.irradiance));
        eprintln!("{:<22} live and bench images {apart:.2e} apart", row.technique.label());
        assert!(apart < 5e-3, "{}: the bench draws another image, {apart} off the live one", row.technique.label());
    }
    // The two references are independent traces of one view: their relative L2 is
    // about √(σ₁² + σ₂²); an error against one moves against the other by at most that
    // times (1 + L2) (the triangle inequality, with each norm's own noise).
    for (row, b) in live.rows.iter().zip(&bench) {
        let e = row.error.unwrap_or_else(|| panic!("{:?}: no receiver in view", row.technique));
        eprintln!(
            "{:<22} live L2 {:.4} L1 {:.4} | bench L2 {:.4} L1 {:.4} | {} pixels | {}",
            b.technique,
            e.l2,
            e.l1,
            b.l2,
            b.l1,
            e.pixels,
            row.drawn.join("; ")
        );
        assert_eq!(row.technique.label(), b.technique);
        assert_eq!(choices(&row.drawn.join("; ")), b.drawn, "{}: the generators drew with other techniques", b.technique);
        assert_eq!(e.pixels, b.pixels, "{}: other pixels see a receiver", b.technique);
        if row.technique == CausticTechnique::Convolution {
            assert!(b.drawn.iter().any(|d| d == "convolution as set on the generator"), "the bench's pool is no pool: {:?}", b.drawn);
        }
        assert!((e.l2 - b.l2).abs() <= (1.0 + b.l2) * noise, "{}: L2 live {} against the bench's {} (noise {noise})", b.technique, e.l2, b.l2);
        assert!((e.l1 - b.l1).abs() <= (1.0 + b.l1) * noise, "{}: L1 live {} against the bench's {} (noise {noise})", b.technique, e.l1, b.l1);
    }
    std::fs::remove_dir_all(&dir).ok();
}
