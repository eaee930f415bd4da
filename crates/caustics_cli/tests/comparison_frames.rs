//! The live comparison (the debug panel's "compare with reference") and `caustics
//! bench` on the frame it saved give the same numbers, within their traces' noise.
//!
//! A game's scene, made of Bevy's own meshes (a floor and a wall that receive, a box
//! that only casts shadows, a glass ball and a tilted mirror under the sun, seen at a
//! slant with Bevy's default MSAA), is measured live on lavapipe; its frame is saved;
//! the `caustics` program rebuilds the scene from the file in a renderer of its own and
//! measures it again, with a photon stream of its own. Both read every technique at
//! the same pixels: the numbers may differ only by what the two references' noise
//! allows. One test function: a process holds one Bevy app with a render device at a
//! time.

use bevy::camera::Exposure;
use bevy::prelude::*;
use caustics_bevy::comparison::{ReferenceComparison, compare_headless};
use caustics_bevy::headless::HeadlessRenderer;
use caustics_bevy::{CausticGenerator, CausticReceiver, CausticsSettings};
use std::process::Command;

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
    world.spawn((Mesh3d(block), MeshMaterial3d(tiles), Transform::from_xyz(-0.6, 0.15, 0.5)));
    world.spawn((Mesh3d(ball), CausticGenerator::refractive(1.5), Transform::from_xyz(0.4, 0.6, 0.1)));
    // Tilted towards the wall, so that its reflection lands there.
    world.spawn((
        Mesh3d(mirror),
        CausticGenerator::mirror(),
        Transform::from_xyz(-0.7, 0.5, -0.3).with_rotation(Quat::from_rotation_x(0.5)),
    ));
    world.spawn((
        DirectionalLight { illuminance: 20_000.0, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::new(0.25, -1.0, -0.35), Vec3::Y),
    ));
    world
        .spawn((
            Camera3d::default(),
            CausticsSettings::default(),
            target,
            Exposure { ev100: 12.0 },
            Projection::from(PerspectiveProjection { fov: 0.9, ..default() }),
            Transform::from_xyz(0.3, 2.0, 2.6).looking_at(Vec3::new(0.0, 0.3, -0.4), Vec3::Y),
        ))
        .id()
}

#[test]
fn the_live_comparison_and_the_bench_on_its_saved_frame_agree_within_the_noise() {
    let mut renderer = HeadlessRenderer::timed(WIDTH, HEIGHT).unwrap_or_else(|e| panic!("{e}"));
    let camera = spawn_game_scene(&mut renderer);
    renderer.render(4).unwrap_or_else(|e| panic!("{e}"));
    compare_headless(&mut renderer, camera, (PHOTONS, 0)).unwrap_or_else(|e| panic!("the live comparison failed: {e}"));
    let dir = std::env::temp_dir().join(format!("caustics-comparison-frames-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let frame = dir.join("frame.json");
    let live = renderer.world_mut().resource::<ReferenceComparison>();
    live.save_frame(&frame).unwrap_or_else(|e| panic!("{e}"));
    let saved = live.frame.as_ref().unwrap();
    assert_eq!((saved.scene.generators.len(), saved.scene.receivers.len(), saved.shown), (2, 3, 2), "ball and mirror; floor, wall, then the box");
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
    assert!((bench_noise / live_noise - 1.0).abs() < 0.1, "noise live {live_noise}, bench {bench_noise}");
    // The two references are independent traces of one view: their relative L2 is
    // about √(σ₁² + σ₂²); an error against one moves against the other by at most that
    // times (1 + L2) (the triangle inequality, with each norm's own noise).
    let noise = (live_noise.powi(2) + bench_noise.powi(2)).sqrt();
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
        assert!((e.l2 - b.l2).abs() <= (1.0 + b.l2) * noise, "{}: L2 live {} against the bench's {} (noise {noise})", b.technique, e.l2, b.l2);
        assert!((e.l1 - b.l1).abs() <= (1.0 + b.l1) * noise, "{}: L1 live {} against the bench's {} (noise {noise})", b.technique, e.l1, b.l1);
    }
    std::fs::remove_dir_all(&dir).ok();
}
