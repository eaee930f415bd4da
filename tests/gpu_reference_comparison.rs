//! The comparison with the ground-truth tracer that the debug panel's button starts,
//! run for real on lavapipe: a glass ball over a floor under the sun, seen at a slant.
//!
//! - It stops time, reads back what each technique draws (through the GPU capture and
//!   Bevy's `Readback`) and traces the frame's scene on its own thread to the end.
//! - Each row has the caustic passes' GPU time (timestamp queries), and its irradiance is the view's caustic irradiance buffer, as the headless
//!   renderer reads it directly; its error is `view_error` against the trace.
//! - The split view shows the reference in the right half of the view and the
//!   technique in the left.
//! - Ending it gives the generators their techniques back and lets time run.
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::camera::Exposure;
use bevy::prelude::*;
use bevy_caustics::comparison::{ComparisonState, ReferenceComparison, ReferenceComparisonRequest};
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::irradiance::reference_view::ReferenceSplit;
use bevy_caustics::reference::view_error;
use bevy_caustics::{CausticGenerator, CausticReceiver, CausticTechnique, Caustics};
use caustics_core::metrics::relative_l2;

const WIDTH: u32 = 64;
const HEIGHT: u32 = 48;

/// The mean of RGB per pixel.
fn grey(values: impl IntoIterator<Item = Vec3>) -> Vec<f32> {
    values.into_iter().map(|e| (e.x + e.y + e.z) / 3.0).collect()
}

#[test]
fn the_reference_comparison_measures_every_technique_and_splits_the_view() {
    let mut renderer = HeadlessRenderer::timed(WIDTH, HEIGHT).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let world = renderer.world_mut();
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(2.0)).mesh());
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 1.0, ..default() });
    world.spawn((Mesh3d(floor), MeshMaterial3d(white), CausticReceiver));
    let ball = world.resource_mut::<Assets<Mesh>>().add(Sphere::new(0.3).mesh().ico(3).unwrap());
    let ball = world.spawn((Mesh3d(ball), CausticGenerator::refractive(1.5), Transform::from_xyz(0.0, 0.5, 0.0))).id();
    world.spawn((DirectionalLight { illuminance: 10_000.0, ..default() }, Transform::default().looking_to(Vec3::new(0.2, -1.0, 0.1), Vec3::Y)));
    let camera = world
        .spawn((
            Camera3d::default(),
            Caustics::default(),
            target,
            Exposure { ev100: 11.0 },
            Projection::from(PerspectiveProjection { fov: 0.8, ..default() }),
            Transform::from_xyz(0.0, 1.6, 1.6).looking_at(Vec3::new(0.0, 0.0, 0.2), Vec3::Y),
        ))
        .id();
    support::render_caustics(&mut renderer, 2);

    renderer.world_mut().write_message(ReferenceComparisonRequest::Start { camera, photons: 400_000, seed: 0 });
    let mut frames = 0;
    loop {
        support::render(&mut renderer, 1);
        frames += 1;
        let state = renderer.world_mut().resource::<ReferenceComparison>().state.clone();
        match state {
            ComparisonState::Done => break,
            ComparisonState::Failed(why) => panic!("the comparison failed: {why}"),
            _ => assert!(frames < 600, "the comparison is still at {state:?} after {frames} frames"),
        }
        // The scene holds still while it is measured.
        assert!(renderer.world_mut().resource::<Time<Virtual>>().is_paused());
    }
    let world = renderer.world_mut();
    let comparison = world.resource::<ReferenceComparison>();
    assert_eq!(comparison.progress(), 1.0);
    let techniques: Vec<CausticTechnique> = comparison.rows.iter().map(|r| r.technique).collect();
    assert_eq!(techniques, CausticTechnique::ALL.to_vec());
    let reference = comparison.reference.clone();
    let auto = comparison.rows[0].clone();
    // The frame traced, kept for `caustics bench`: the ball over the floor, from this camera.
    let frame = comparison.frame.as_ref().expect("the traced frame");
    assert_eq!((frame.scene.generators.len(), frame.scene.receivers.len(), frame.shown), (1, 1, 1));
    assert_eq!((frame.camera.width, frame.camera.height, frame.camera.fov_y), (WIDTH, HEIGHT, 0.8));
    let noise = comparison.reference_noise.expect("the reference's noise");
    eprintln!("the reference's own noise: {noise:.3}");
    assert!(noise > 0.0 && noise < 0.5, "noise {noise}");
    for row in &comparison.rows {
        let error = row.error.unwrap_or_else(|| panic!("{:?} has no error", row.technique));
        eprintln!(
            "{:?}: L2 {:.3}, L1 {:.3} over {} pixels, {:.2} GPU ms; {}",
            row.technique,
            error.l2,
            error.l1,
            error.pixels,
            row.work.caustics_ms(),
            row.drawn.join("; ")
        );
        assert!(error.pixels > 500 && error.l2.is_finite() && error.l1.is_finite(), "{:?} against the tracer: {error:?}", row.technique);
        assert!(row.work.caustics_ms() > 0.0, "{:?}: no GPU time for the caustic passes", row.technique);
    }
    assert_eq!(world.get::<CausticGenerator>(ball).unwrap().technique, CausticTechnique::Auto, "the ball's own technique is back");
    // Each row is its own technique's frame, not one still on screen from before the
    // switch: `Auto` picks the maps for the ball, and the volumes draw another pattern
    // than the textures.
    let row = |t: CausticTechnique| grey(comparison.rows.iter().find(|r| r.technique == t).unwrap().irradiance.iter().copied());
    let (maps, volumes, textures) =
        (row(CausticTechnique::HierarchicalMaps), row(CausticTechnique::WarpedVolumes), row(CausticTechnique::IlluminationTextures));
    assert!(relative_l2(&maps, &grey(auto.irradiance.iter().copied())) < 1e-3, "Auto's row is not the maps'");
    assert!(relative_l2(&volumes, &textures) > 0.05, "the volumes' row is the textures'");

    // The Auto row is the view's buffer as the renderer reads it.
    support::render(&mut renderer, 3);
    let direct = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
    let read_back = relative_l2(&grey(auto.irradiance.iter().copied()), &grey(direct.iter().copied()));
    eprintln!("Auto read back against the buffer read directly: relative L2 {read_back:.2e}");
    assert!(read_back < 1e-3, "the Auto row's irradiance is off the view's buffer by {read_back}");
    assert_eq!(auto.error, view_error(&auto.irradiance, &reference));

    // The split view: left the technique, right the reference.
    renderer.world_mut().resource_mut::<ReferenceComparison>().split = true;
    support::render(&mut renderer, 3);
    assert!(renderer.world_mut().get::<ReferenceSplit>(camera).is_some());
    let split = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{e}"));
    let half = |right: bool| move |i: &usize| ((*i as u32 % WIDTH) >= WIDTH / 2) == right;
    let pick = |values: &[Vec3], right: bool| grey((0..values.len()).filter(half(right)).map(|i| values[i]));
    let truth: Vec<Vec3> = reference.iter().map(|e| e.unwrap_or(Vec3::ZERO)).collect();
    let (right, left) = (relative_l2(&pick(&split, true), &pick(&truth, true)), relative_l2(&pick(&split, false), &pick(&direct, false)));
    eprintln!("split view: right half against the reference {right:.2e}, left half against the technique {left:.2e}");
    assert!(right < 2e-3, "the right half is off the reference by {right}");
    assert!(left < 1e-3, "the left half is off the technique by {left}");
    assert!(relative_l2(&pick(&direct, true), &pick(&truth, true)) > 10.0 * right, "the technique alone matches the reference as closely");

    renderer.world_mut().write_message(ReferenceComparisonRequest::End);
    support::render(&mut renderer, 1);
    let world = renderer.world_mut();
    assert!(!world.resource::<Time<Virtual>>().is_paused());
    assert!(world.get::<ReferenceSplit>(camera).is_none());
    assert_eq!(world.resource::<ReferenceComparison>().state, ComparisonState::Idle);
}
