//! The caustic volumes' intensity modes on a real adapter (lavapipe in CI), on Ernst,
//! Akenine-Möller & Jensen's ring (2005, Fig. 8): a metal ring's cardioid seen straight
//! down, drawn with constant intensity at 64 and 1024 segments, the paper's
//! interpolation (§3.4) at 64 and the plugin's energy-conserving interpolation at 64.
//! The conserving interpolation carries constant intensity's flux and stands nearer
//! the finely tessellated ring than constant intensity at the same tessellation.
//! Writes the four panels side by side (the caustic irradiance, left to right in that
//! order) to `$CARGO_TARGET_TMPDIR/volumes_compare.png`.

mod support;

use bevy::camera::visibility::RenderLayers;
use bevy::prelude::*;
use bevy_caustics::headless::{HeadlessRenderer, RenderedImage};
use bevy_caustics::read_scene::bevy_mesh;
use bevy_caustics::warped_volumes::{VolumeIntensity, WarpedVolumesSettings};
use bevy_caustics::{CausticGenerator, CausticTechnique};
use caustics_core::glam;
use caustics_core::mesh::TriMesh;
use caustics_core::metrics::relative_l1;
use support::{caustic_irradiance, render_caustics, render_without_caustics};

/// Pixels across the view, the view's width (m) and its centre: close up on the
/// cardioid's cusp.
const SIZE: u32 = 160;
const VIEW: f32 = 1.0;
const CENTRE: Vec3 = Vec3::new(0.4, 0.0, 0.0);
/// A low sun, as in the paper's figure.
const SUN: Vec3 = Vec3::new(1.0, -0.45, 0.0);
const ILLUMINANCE: f32 = 10.0;
/// The panels: segments around the ring and the volumes' intensity.
const PANELS: [(usize, VolumeIntensity); 4] =
    [(64, VolumeIntensity::Constant), (1024, VolumeIntensity::Constant), (64, VolumeIntensity::Interpolated), (64, VolumeIntensity::Conserving)];

#[test]
fn the_conserving_interpolation_keeps_the_flux_and_nears_the_fine_ring() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let world = renderer.world_mut();
    let white = support::white_floor_in_the_dark(world);
    // The ring reflects the sun but is not in the camera's layer: the view sees the
    // whole floor.
    let mirror = CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::mirror() };
    let ring = world.spawn((MeshMaterial3d(white), mirror, RenderLayers::layer(1))).id();
    world.spawn((DirectionalLight { illuminance: ILLUMINANCE, shadow_maps_enabled: false, ..default() }, Transform::default().looking_to(SUN, Vec3::Y)));
    world.spawn(support::top_down_camera(target, VIEW, SIZE, CENTRE));

    let mut panels = Vec::new();
    for (segments, intensity) in PANELS {
        let world = renderer.world_mut();
        world.insert_resource(WarpedVolumesSettings { intensity, ..default() });
        let mesh = bevy_mesh(&TriMesh::solid_ring(glam::Vec3::ZERO, 1.0, 1.05, 0.3, segments));
        let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
        world.entity_mut(ring).insert(Mesh3d(mesh));
        let without = render_without_caustics(&mut renderer, 2);
        let with = render_caustics(&mut renderer, 2);
        let irradiance = caustic_irradiance(&with, &without);
        assert!(irradiance.iter().all(|e| e.is_finite()), "{segments} segments, {intensity:?}: a pixel is not finite");
        panels.push(irradiance);
    }
    save_side_by_side(&panels);

    // Flux in view (lux × pixels), the cusp's share of the ring's: the conserving
    // interpolation and constant intensity both spread each volume's flux over its
    // caustic triangle, and the finer ring reflects nearly the same light there.
    let flux: Vec<f32> = panels.iter().map(|p| p.iter().sum()).collect();
    let (constant, fine, paper, conserving) = (flux[0], flux[1], flux[2], flux[3]);
    eprintln!("flux: constant 64 {constant:.0}, constant 1024 {fine:.0}, paper's 64 {paper:.0}, conserving 64 {conserving:.0}");
    assert!(constant > 100.0 * ILLUMINANCE, "too little caustic light to compare ({constant})");
    assert!((conserving / constant - 1.0).abs() < 0.02, "the conserving interpolation lost flux: {conserving} against {constant}");
    assert!((fine / constant - 1.0).abs() < 0.05, "the finer ring reflects other flux: {fine} against {constant}");

    // Against the finely tessellated ring, pixel by pixel: the conserving
    // interpolation stands nearer it than constant intensity at the same tessellation
    // (relative L1; L2 is ruled by the cusp's few brightest pixels). The paper's own
    // interpolation overshoots where a vertex fan's area passes through zero, at the
    // folds, and adds light (docs/warped-volumes.md).
    let l1 = |panel: usize| relative_l1(&panels[panel], &panels[1]);
    let (constant, paper, conserving) = (l1(0), l1(2), l1(3));
    eprintln!("relative L1 against constant 1024: constant 64 {constant:.3}, paper's 64 {paper:.3}, conserving 64 {conserving:.3}");
    assert!(conserving < constant, "the conserving interpolation ({conserving}) is no nearer the fine ring than constant intensity ({constant})");
}

/// The four panels' caustic irradiance side by side, a dark gap between them, scaled so
/// that 12.5 times the sun's illuminance is white.
fn save_side_by_side(panels: &[Vec<f32>]) {
    const GAP: u32 = 4;
    let width = PANELS.len() as u32 * (SIZE + GAP) - GAP;
    let mut image = RenderedImage { width, height: SIZE, pixels: vec![Vec4::ZERO; (width * SIZE) as usize] };
    for (i, panel) in panels.iter().enumerate() {
        let x0 = i as u32 * (SIZE + GAP);
        for (p, e) in panel.iter().enumerate() {
            let (x, y) = (p as u32 % SIZE, p as u32 / SIZE);
            image.pixels[(y * width + x0 + x) as usize] = Vec3::splat(*e).extend(1.0);
        }
    }
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("volumes_compare.png");
    image.save_png(&path, 0.08 / ILLUMINANCE).unwrap();
    eprintln!("wrote {}", path.display());
}
