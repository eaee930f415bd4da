//! The demo's pool against the ground-truth tracer, as the Caustics panel's "Compare
//! with reference" button measures it (`bevy_caustics::comparison`): the demo's scene
//! (`examples/demo.rs`, its plugin `Pool`) rendered headless to its last frame, then,
//! time stopped, the tracer traces that frame while every generator is asked for each
//! technique in turn.
//!
//! It takes about 4 minutes on lavapipe, so it is left out of `cargo test`:
//!
//!     cargo test --locked --test demo_comparison -- --ignored --nocapture
//!
//! prints a Markdown table of each technique's relative L2 and L1 against the tracer
//! over the receivers in view, its GPU time and its shader invocations beside Bevy's
//! main pass, and writes to `target/demo_comparison/` (or `$DEMO_COMPARISON_OUT`) the
//! frame traced (`frame.json`, which `caustics bench --scenes '' --scene` measures
//! again) and each technique's split view: left the technique, right the reference.

#[allow(dead_code)]
#[path = "../examples/demo.rs"]
mod demo;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_caustics::comparison::{ReferenceComparison, compare_headless};
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::{CausticGenerator, CausticTechnique};
use std::path::PathBuf;
use std::time::Duration;

/// The tracer's photons per light.
const PHOTONS: u64 = 1 << 23;

/// `Auto`'s relative L1 on the demo's frame must not grow past this (it reads 0.36).
const AUTO_L1: f32 = 0.40;

#[test]
#[ignore = "about 4 minutes on lavapipe: run it with --ignored"]
fn the_demo_against_the_reference() {
    let out = std::env::var_os("DEMO_COMPARISON_OUT").map_or_else(|| PathBuf::from("target/demo_comparison"), PathBuf::from);
    std::fs::create_dir_all(&out).unwrap();
    let mut renderer = HeadlessRenderer::timed_with_plugins(demo::WIDTH, demo::HEIGHT, demo::Pool).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    // The main view alone, drawn into the renderer's image, frames 50 ms apart as the
    // demo's headless run.
    let into_image = move |mut commands: Commands, cameras: Query<(Entity, Has<demo::UnderwaterView>), With<Camera>>| {
        for (camera, underwater) in &cameras {
            if underwater {
                commands.entity(camera).despawn();
            } else {
                commands.entity(camera).insert(target.clone());
            }
        }
    };
    renderer.app.add_systems(PostStartup, into_image);
    renderer.world_mut().insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(50)));
    renderer.render(demo::FRAMES).unwrap_or_else(|e| panic!("{e}"));
    let world = renderer.world_mut();
    let camera = world.query_filtered::<Entity, With<Camera3d>>().single(world).unwrap();
    compare_headless(&mut renderer, camera, (PHOTONS, 0)).unwrap_or_else(|e| panic!("{e}"));

    let adapter = renderer.adapter.name.clone();
    let comparison = renderer.world_mut().resource::<ReferenceComparison>();
    let rows = comparison.rows.clone();
    println!(
        "| asked of every generator | drawn with | relative L2 in view | relative L1 | caustics GPU ms ({adapter}) | caustics invocations (M) | caustics fragments (M) | main pass fragments (M) |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|");
    for row in &rows {
        let error = row.error.map_or("no receiver in view | –".into(), |e| format!("{:.3} | {:.3}", e.l2, e.l1));
        let w = &row.work;
        println!(
            "| {} | {} | {error} | {:.1} | {:.2} | {:.2} | {:.2} |",
            row.technique.label(),
            row.drawn.join("; "),
            w.caustics_ms(),
            w.caustics_invocations() / 1e6,
            w.caustics_fragments() / 1e6,
            w.main_pass.fragments.unwrap_or(0.0) / 1e6
        );
    }
    let noise = comparison.reference_noise.unwrap_or(f32::NAN);
    println!("\nThe reference's own noise: relative L2 {noise:.3}.");
    let frame = out.join("frame.json");
    comparison.save_frame(&frame).unwrap();
    eprintln!("wrote {}", frame.display());

    // The split view of each technique, as the panel shows it.
    renderer.world_mut().resource_mut::<ReferenceComparison>().split = true;
    for row in &rows {
        let world = renderer.world_mut();
        for mut generator in world.query::<&mut CausticGenerator>().iter_mut(world) {
            generator.technique = row.technique;
        }
        // Time stands still: a dozen frames let the volumes' build catch up.
        let mut image = renderer.render(12).unwrap_or_else(|e| panic!("{e}"));
        // A white line where the halves meet.
        let (width, middle) = (image.width as usize, image.width as usize / 2);
        image.pixels.iter_mut().skip(middle).step_by(width).for_each(|p| *p = Vec4::ONE);
        let path = out.join(format!("{}-vs-reference.png", row.technique.label().to_lowercase().replace(' ', "-")));
        image.save_png(&path, 1.0).unwrap();
        eprintln!("wrote {}", path.display());
    }

    // Every technique drew the receivers in view, and the default stays as near the
    // tracer as it is now.
    assert!(noise < 0.05, "the reference is too noisy to measure against ({noise})");
    for row in &rows {
        let error = row.error.unwrap_or_else(|| panic!("{}: no receiver in view", row.technique.label()));
        assert!(error.l2.is_finite() && error.l1.is_finite(), "{}: {error:?}", row.technique.label());
    }
    let auto = rows.iter().find(|r| r.technique == CausticTechnique::Auto).expect("an Auto row").error.unwrap();
    assert!(auto.l1 <= AUTO_L1, "Auto reads relative L1 {} on the demo's frame", auto.l1);
}
