//! Constant against interpolated intensity, close up on the ring's cardioid (Ernst,
//! Akenine-Möller & Jensen 2005, Fig. 8). One PNG, four panels left to right:
//! constant intensity with 64 segments, constant with 1024 (16× finer), the paper's
//! interpolation with 64, and the plugin's energy-conserving interpolation with 64.
//!
//! `cargo run --example volumes_compare` (always headless) writes
//! `target/volumes_compare.png` (`--out PATH`).

#[path = "support/mod.rs"]
mod support;

use bevy::camera::Exposure;
use bevy::prelude::*;
use bevy_caustics::caustics_core::{glam, mesh::TriMesh};
use bevy_caustics::headless::{HeadlessRenderer, RenderedImage};
use bevy_caustics::prelude::*;
use bevy_caustics::read_scene::bevy_mesh;
use std::process::ExitCode;

const PANEL: u32 = 320;
const PANELS: [(usize, VolumeIntensity); 4] = [
    (64, VolumeIntensity::Constant),
    (1024, VolumeIntensity::Constant),
    (64, VolumeIntensity::Interpolated),
    (64, VolumeIntensity::Conserving),
];

fn main() -> ExitCode {
    match run(&support::out_path("volumes_compare")) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("volumes_compare: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Renders the four panels in one headless renderer, the ring's mesh and the volumes'
/// intensity changed between them, and writes them side by side to `out`.
fn run(out: &std::path::Path) -> Result<(), String> {
    let mut renderer = HeadlessRenderer::new(PANEL, PANEL).map_err(|e| e.to_string())?;
    let target = renderer.render_target();
    let world = renderer.world_mut();
    support::ring_scene(world, PANELS[0].0, PANELS[0].1);
    // Straight down onto the cusp of the cardioid.
    world.spawn((
        Camera3d::default(),
        Caustics::default(),
        target,
        Exposure { ev100: 12.5 },
        Transform::from_xyz(0.35, 1.3, 0.0).looking_at(Vec3::new(0.35, 0.0, 0.0), Vec3::NEG_Z),
    ));
    let mut panels = Vec::new();
    for (segments, intensity) in PANELS {
        let world = renderer.world_mut();
        world.insert_resource(WarpedVolumesSettings { intensity, ..default() });
        let ring = bevy_mesh(&TriMesh::solid_ring(glam::Vec3::ZERO, 1.0, 1.05, 0.3, segments));
        let ring = world.resource_mut::<Assets<Mesh>>().add(ring);
        let generator = world.query_filtered::<Entity, With<CausticGenerator>>().single(world).map_err(|e| e.to_string())?;
        world.entity_mut(generator).insert(Mesh3d(ring));
        panels.push(renderer.render(4).map_err(|e| e.to_string())?);
        eprintln!("{segments} segments, {intensity:?}: rendered");
    }
    side_by_side(&panels).save_png(out, 1.0).map_err(|e| e.to_string())?;
    eprintln!("wrote {} (left to right: {PANELS:?})", out.display());
    Ok(())
}

/// The panels next to each other, with a dark 4-pixel gap.
fn side_by_side(panels: &[RenderedImage]) -> RenderedImage {
    const GAP: u32 = 4;
    let width = panels.iter().map(|p| p.width + GAP).sum::<u32>() - GAP;
    let height = panels.iter().map(|p| p.height).max().unwrap_or(0);
    let mut pixels = vec![Vec4::ZERO; (width * height) as usize];
    let mut x0 = 0;
    for panel in panels {
        for y in 0..panel.height {
            for x in 0..panel.width {
                pixels[(y * width + x0 + x) as usize] = panel.pixel(x, y);
            }
        }
        x0 += panel.width + GAP;
    }
    RenderedImage { width, height, pixels }
}
