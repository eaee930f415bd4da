//! The frame a camera shows now, measured against the ground-truth tracer while the
//! game runs: what the debug panel's "compare with reference" button starts, and what
//! the demo comparison (`tests/demo_comparison.rs`) reports.
//!
//! A [`ReferenceComparisonRequest::Start`] stops virtual time, so the scene holds
//! still, and traces that scene ([`frame_of_world`], [`trace_view`]) on a thread of
//! its own, with its progress in [`ReferenceComparison::progress`]. Meanwhile every
//! generator is asked for each technique in turn ([`CausticTechnique::ALL`]), and the
//! view's caustic irradiance is read back from the GPU every frame
//! ([`CaptureCausticIrradiance`] and Bevy's `Readback`) until the frame has settled:
//! only the chosen techniques' passes ran, and two readbacks agree. The row keeps it,
//! with the caustic passes' GPU times and what each generator drew with. When the
//! trace is in, each row gets its relative L2 and L1 over the pixels that see a
//! receiver ([`view_error`]), the reference its own noise ([`TracedView::noise`]), and
//! the reference becomes an irradiance image that [`ReferenceComparison::split`] shows
//! in the right half of the view ([`ReferenceSplit`]).
//! [`ReferenceComparisonRequest::End`] restores the generators' techniques, takes the
//! split away and lets time run again.
//!
//! The frame traced is kept as a [`SceneView`] ([`ReferenceComparison::frame`]):
//! saved as JSON, `caustics bench --scene frame.json` measures the same view the same
//! way in a program of its own, with the scene rebuilt from the file, and its numbers
//! match these within the two traces' noise (`caustics_cli/tests/comparison_frames.rs`).

use crate::gpu_work::{FrameWork, newest_pass_work};
#[cfg(feature = "headless")]
use crate::headless::HeadlessRenderer;
use crate::irradiance::reference_view::{CaptureCausticIrradiance, ReferenceSplit, capture_image};
use crate::pixels::{decode_rgba16f, irradiance_image, unpad_rows};
use crate::reference::{TracedView, ViewError, frame_of_world, pinhole, trace_view, view_error};
use crate::{CausticGenerator, CausticPassReport, CausticTechnique};
use bevy::camera::Exposure;
use bevy::diagnostic::DiagnosticsStore;
use bevy::prelude::*;
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use caustics_core::metrics::relative_l2;
use caustics_core::view::SceneView;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Frames each technique draws before its irradiance is first read back.
pub const SETTLE_FRAMES: u32 = 2;

/// The most frames a technique is read back for before it is measured as it stands,
/// settled or not ([`techniques_drawing`], [`settled`]).
pub const MAX_WAIT_FRAMES: u32 = 120;

/// Frames a readback may lag behind the frame the main world last saw drawn.
const READBACK_LATENCY: u32 = 4;

/// Starts or ends the comparison ([`ReferenceComparison`]).
#[derive(Message, Clone, Copy, Debug)]
pub enum ReferenceComparisonRequest {
    /// Measure what `camera` (a perspective camera with [`crate::Caustics`])
    /// shows now against the tracer, with `photons` per light from photon stream `seed`.
    Start {
        /// The camera measured.
        camera: Entity,
        /// Photons traced per light.
        photons: u64,
        /// The photon stream: the same seed traces the same photons.
        seed: u64,
    },
    /// Restore the generators' techniques, take the split view away, let time run.
    End,
}

/// Where the comparison stands.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum ComparisonState {
    /// Nothing asked for, or the last comparison ended.
    #[default]
    Idle,
    /// Reading back what this technique (an index into [`CausticTechnique::ALL`]) draws;
    /// the tracer runs meanwhile.
    Measuring(usize),
    /// Every technique is read back; waiting for the tracer.
    Tracing,
    /// The rows have their errors; time stays stopped until [`ReferenceComparisonRequest::End`].
    Done,
    /// The comparison could not run, and why.
    Failed(String),
}

/// One technique asked of every generator, measured.
#[derive(Clone, Debug)]
pub struct ComparisonRow {
    /// The technique every generator was asked to draw with (`Auto` included).
    pub technique: CausticTechnique,
    /// What each generator drew with, and why (a technique that does not apply to a
    /// generator falls back to `Auto`'s pick).
    pub drawn: Vec<String>,
    /// The caustic passes' GPU time and shader invocations in the frame read back, and
    /// Bevy's main opaque pass beside them (timestamp and pipeline-statistics queries).
    pub work: FrameWork,
    /// The view's caustic irradiance (lux), row by row, top first.
    pub irradiance: Vec<Vec3>,
    /// Against the reference, once it is in; `None` before, or with no receiver in view.
    pub error: Option<ViewError>,
}

/// The newest bytes a readback entity's observer has received.
type ReadbackSlot = Arc<Mutex<Option<Vec<u8>>>>;

/// The comparison's state, rows and reference. Set [`Self::split`] to show the split
/// view once the reference is in.
#[derive(Resource, Default)]
pub struct ReferenceComparison {
    /// Where it stands.
    pub state: ComparisonState,
    /// The camera measured.
    pub camera: Option<Entity>,
    /// The view's size in pixels.
    pub size: UVec2,
    /// One row a technique measured so far, in [`CausticTechnique::ALL`] order.
    pub rows: Vec<ComparisonRow>,
    /// The tracer's irradiance at each pixel that sees a receiver.
    pub reference: Vec<Option<Vec3>>,
    /// The reference's own relative noise ([`TracedView::noise`]), once it is in.
    pub reference_noise: Option<f32>,
    /// The frame traced: its scene as the tracer sees it and the camera's view.
    pub frame: Option<SceneView>,
    /// Whether the camera shows the split view: left the techniques, right the reference.
    pub split: bool,
    /// Photons traced so far, and in all (every light's).
    traced: Arc<[AtomicU64; 2]>,
    tracer: Option<JoinHandle<Result<TracedView, String>>>,
    /// Each generator's own technique, restored at the end.
    asked: Vec<(Entity, CausticTechnique)>,
    frames_left: u32,
    waited: u32,
    /// Frames in a row whose view passes were those of the chosen techniques.
    drawing_frames: u32,
    previous: Option<Vec<Vec3>>,
    capture: Handle<Image>,
    reference_image: Option<Handle<Image>>,
    readback: Option<(Entity, ReadbackSlot)>,
}

impl ReferenceComparison {
    /// The share of the reference's photons traced so far, 0 to 1.
    pub fn progress(&self) -> f32 {
        let [done, total] = [0, 1].map(|i| self.traced[i].load(Ordering::Relaxed));
        if total == 0 { 0.0 } else { (done as f64 / total as f64).min(1.0) as f32 }
    }

    /// Whether every photon is traced and the tracer now gathers them at each pixel.
    pub fn gathering(&self) -> bool {
        self.progress() == 1.0 && self.tracer.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Whether a comparison is under way (time stopped, techniques switched).
    pub fn running(&self) -> bool {
        matches!(self.state, ComparisonState::Measuring(_) | ComparisonState::Tracing)
    }

    /// Writes [`Self::frame`] as JSON ([`SceneView::to_json`]) to `path`, making its
    /// folder if needed, for `caustics bench --scene`.
    pub fn save_frame(&self, path: &std::path::Path) -> Result<(), String> {
        let frame = self.frame.as_ref().ok_or("no frame has been traced")?;
        let cannot = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(cannot)?;
        }
        std::fs::write(path, frame.to_json()).map_err(cannot)
    }
}

pub(crate) fn build(app: &mut App) {
    app.add_message::<ReferenceComparisonRequest>()
        .init_resource::<ReferenceComparison>()
        // In `Last`: the scene it traces is the one this frame draws, after every
        // system has moved it and its transforms are propagated.
        .add_systems(Last, drive);
}

/// Runs the requests of this frame, then the comparison's next step.
fn drive(world: &mut World) {
    let requests: Vec<_> = world.resource_mut::<Messages<ReferenceComparisonRequest>>().drain().collect();
    for request in requests {
        match request {
            ReferenceComparisonRequest::Start { camera, photons, seed } => {
                if !world.resource::<ReferenceComparison>().running() {
                    end(world);
                    if let Err(why) = start(world, camera, (photons, seed)) {
                        warn!("bevy_caustics: no comparison with the reference: {why}");
                        end(world);
                        world.resource_mut::<ReferenceComparison>().state = ComparisonState::Failed(why);
                    }
                }
            }
            ReferenceComparisonRequest::End => end(world),
        }
    }
    step(world);
    show_split(world);
}

fn start(world: &mut World, camera: Entity, photons_and_seed: (u64, u64)) -> Result<(), String> {
    let mut cameras = world.query::<(&Camera, &GlobalTransform, &Projection)>();
    let (view, transform, projection) = cameras.get(world, camera).map_err(|_| format!("{camera} is not a camera"))?;
    let Projection::Perspective(perspective) = projection else {
        return Err("the tracer's camera is a pinhole: measure a perspective camera".into());
    };
    let size = view.physical_viewport_size().ok_or("the camera has no viewport size yet")?;
    let pinhole = pinhole(&transform.compute_transform(), perspective.fov, size.x, size.y);
    world.resource_mut::<Time<Virtual>>().pause();
    let (frame, skipped) = frame_of_world(world, pinhole);
    for s in skipped {
        warn!("bevy_caustics: left out of the reference: {s}");
    }
    let (scene, shown) = (frame.scene.clone(), frame.shown);
    let traced = Arc::new([AtomicU64::new(0), AtomicU64::new(0)]);
    let counter = traced.clone();
    let tracer = std::thread::spawn(move || {
        let progress = move |done: u64, total: u64| {
            counter[1].store(total, Ordering::Relaxed);
            counter[0].store(done, Ordering::Relaxed);
        };
        trace_view(&scene, shown, &pinhole, photons_and_seed, 0.015, &progress)
    });
    let capture = world.resource_mut::<Assets<Image>>().add(capture_image(size));
    world.entity_mut(camera).insert(CaptureCausticIrradiance(capture.clone()));
    let asked = world.query::<(Entity, &CausticGenerator)>().iter(world).map(|(e, g)| (e, g.technique)).collect();
    *world.resource_mut::<ReferenceComparison>() = ReferenceComparison {
        state: ComparisonState::Measuring(0),
        camera: Some(camera),
        size,
        traced,
        tracer: Some(tracer),
        frame: Some(frame),
        asked,
        capture,
        ..default()
    };
    ask_every_generator(world, CausticTechnique::ALL[0]);
    Ok(())
}

fn ask_every_generator(world: &mut World, technique: CausticTechnique) {
    for mut generator in world.query::<&mut CausticGenerator>().iter_mut(world) {
        generator.technique = technique;
    }
    let mut comparison = world.resource_mut::<ReferenceComparison>();
    comparison.frames_left = SETTLE_FRAMES;
    comparison.waited = 0;
    comparison.drawing_frames = 0;
    comparison.previous = None;
    // Readbacks of frames drawn before the switch go.
    drop_readback(world);
}

fn end(world: &mut World) {
    if world.resource::<ReferenceComparison>().state == ComparisonState::Idle {
        return;
    }
    stop_measuring(world);
    let comparison = std::mem::take(&mut *world.resource_mut::<ReferenceComparison>());
    if let Some(mut camera) = comparison.camera.and_then(|c| world.get_entity_mut(c).ok()) {
        camera.remove::<ReferenceSplit>();
    }
    // A trace still under way finishes on its thread and is dropped.
    world.resource_mut::<Time<Virtual>>().unpause();
}

fn step(world: &mut World) {
    let state = world.resource::<ReferenceComparison>().state.clone();
    match state {
        ComparisonState::Measuring(index) => measure(world, index),
        ComparisonState::Tracing => {
            let mut comparison = world.resource_mut::<ReferenceComparison>();
            if comparison.tracer.as_ref().is_some_and(|t| t.is_finished()) {
                let reference = comparison.tracer.take().map(|t| t.join().unwrap_or_else(|_| Err("the tracer panicked".into())));
                match reference {
                    Some(Ok(reference)) => finish(world, reference),
                    Some(Err(why)) => {
                        end(world);
                        world.resource_mut::<ReferenceComparison>().state = ComparisonState::Failed(why);
                    }
                    None => {}
                }
            }
        }
        _ => {}
    }
}

/// Counts down the settling frames, reads the view back every frame after, and takes
/// the row once the frame has settled ([`settled`]).
fn measure(world: &mut World, index: usize) {
    let comparison = world.resource::<ReferenceComparison>();
    let (frames_left, readback, capture, camera, size) =
        (comparison.frames_left, comparison.readback.clone(), comparison.capture.clone(), comparison.camera, comparison.size);
    if frames_left > 0 {
        world.resource_mut::<ReferenceComparison>().frames_left -= 1;
        return;
    }
    // Bevy reads the capture back every frame while the readback entity lives; the
    // slot keeps the newest.
    let Some((_, slot)) = readback else {
        let slot = Arc::new(Mutex::new(None));
        let filled = slot.clone();
        let entity = world
            .spawn(Readback::texture(capture))
            .observe(move |event: On<ReadbackComplete>| {
                if let Ok(mut slot) = filled.lock() {
                    *slot = Some(event.data.clone());
                }
            })
            .id();
        world.resource_mut::<ReferenceComparison>().readback = Some((entity, slot));
        return;
    };
    let drawing = techniques_drawing(world.resource::<CausticPassReport>());
    let mut comparison = world.resource_mut::<ReferenceComparison>();
    comparison.waited += 1;
    comparison.drawing_frames = if drawing { comparison.drawing_frames + 1 } else { 0 };
    let Some(bytes) = slot.lock().ok().and_then(|mut s| s.take()) else { return };
    let exposure = camera.and_then(|c| world.get::<Exposure>(c)).copied().unwrap_or_default().exposure();
    let irradiance: Vec<Vec3> = decode_rgba16f(&unpad_rows(&bytes, size.x as usize * 8)).into_iter().map(|e| e.truncate() / exposure).collect();
    let drawn = world.resource::<CausticPassReport>().generators.iter().map(|(_, choice)| choice.to_string()).collect();
    let work = FrameWork::of(world.get_resource::<DiagnosticsStore>().map_or_else(Vec::new, newest_pass_work));
    let mut comparison = world.resource_mut::<ReferenceComparison>();
    let technique = CausticTechnique::ALL[index];
    // A readback shows a frame some frames old: only those drawn after the passes have
    // matched the choice for a while count, and two in a row must agree.
    let fresh = comparison.drawing_frames >= READBACK_LATENCY;
    if !(fresh && comparison.previous.as_deref().is_some_and(|p| settled(p, &irradiance))) {
        if comparison.waited < MAX_WAIT_FRAMES {
            comparison.previous = fresh.then_some(irradiance);
            return;
        }
        warn!("bevy_caustics: {technique:?} did not settle in {MAX_WAIT_FRAMES} frames; measured as it stands");
    }
    comparison.rows.push(ComparisonRow { technique, drawn, work, irradiance, error: None });
    if let Some(&next) = CausticTechnique::ALL.get(index + 1) {
        comparison.state = ComparisonState::Measuring(index + 1);
        ask_every_generator(world, next);
        return;
    }
    comparison.state = ComparisonState::Tracing;
    stop_measuring(world);
}

/// Gives each generator back the technique it asked for, and stops reading the view
/// back.
fn stop_measuring(world: &mut World) {
    let (asked, camera) = {
        let mut comparison = world.resource_mut::<ReferenceComparison>();
        (std::mem::take(&mut comparison.asked), comparison.camera)
    };
    for (entity, technique) in asked {
        if let Some(mut generator) = world.get_mut::<CausticGenerator>(entity) {
            generator.technique = technique;
        }
    }
    drop_readback(world);
    if let Some(mut camera) = camera.and_then(|c| world.get_entity_mut(c).ok()) {
        camera.remove::<CaptureCausticIrradiance>();
    }
}

/// Despawns the readback entity; readbacks still on their way are dropped with it.
fn drop_readback(world: &mut World) {
    if let Some((entity, _)) = world.resource_mut::<ReferenceComparison>().readback.take() {
        world.despawn(entity);
    }
}

/// The pass that draws a technique's caustics into a view's buffer, as the pass report
/// names it (none for `Auto`, which is not a technique drawn).
fn view_pass(technique: CausticTechnique) -> Option<&'static str> {
    match technique {
        CausticTechnique::Auto => None,
        CausticTechnique::WarpedVolumes => Some("volumes"),
        CausticTechnique::IlluminationTextures => Some("illumination textures projection"),
        CausticTechnique::Convolution => Some("pool floor"),
        CausticTechnique::HierarchicalMaps => Some("caustic map projection"),
    }
}

/// Whether the last frame's view passes are those of the techniques the generators
/// draw with, and no others: a technique switched away from can still draw what it
/// built before for some frames (the volumes are built off the frame), and one
/// switched to can take some to build.
fn techniques_drawing(report: &CausticPassReport) -> bool {
    let chosen: Vec<&str> = report.generators.iter().filter_map(|(_, choice)| view_pass(choice.technique())).collect();
    CausticTechnique::ALL.iter().filter_map(|&t| view_pass(t)).all(|pass| chosen.contains(&pass) == (report.views(pass) > 0))
}

/// Whether two readbacks of the same still frame agree (relative L2 of their mean of
/// RGB within 10⁻³): the techniques' asynchronous work has caught up.
fn settled(previous: &[Vec3], newest: &[Vec3]) -> bool {
    let grey = |v: &[Vec3]| v.iter().map(|e| (e.x + e.y + e.z) / 3.0).collect::<Vec<f32>>();
    let (a, b) = (grey(previous), grey(newest));
    a == b || relative_l2(&b, &a) <= 1e-3
}

/// The rows' errors against `traced`, and the reference as an image for the split view.
fn finish(world: &mut World, TracedView { irradiance: reference, noise }: TracedView) {
    let size = world.resource::<ReferenceComparison>().size;
    let injected: Vec<Vec3> = reference.iter().map(|e| e.unwrap_or(Vec3::ZERO)).collect();
    let image = world.resource_mut::<Assets<Image>>().add(irradiance_image(size.x, size.y, &injected));
    let mut comparison = world.resource_mut::<ReferenceComparison>();
    for row in &mut comparison.rows {
        row.error = view_error(&row.irradiance, &reference);
    }
    comparison.reference = reference;
    comparison.reference_noise = Some(noise);
    comparison.reference_image = Some(image);
    comparison.state = ComparisonState::Done;
}

/// Puts [`ReferenceSplit`] on the measured camera while [`ReferenceComparison::split`]
/// is set and the reference is in, and takes it away otherwise.
fn show_split(world: &mut World) {
    let comparison = world.resource::<ReferenceComparison>();
    let (Some(camera), split) = (comparison.camera, comparison.split.then(|| comparison.reference_image.clone()).flatten()) else {
        return;
    };
    let Ok(mut camera) = world.get_entity_mut(camera) else { return };
    match split {
        Some(image) if camera.get::<ReferenceSplit>().is_none_or(|s| s.0 != image) => {
            camera.insert(ReferenceSplit(image));
        }
        None if camera.contains::<ReferenceSplit>() => {
            camera.remove::<ReferenceSplit>();
        }
        _ => {}
    }
}

/// Runs a comparison of `camera` in `renderer` to the end, one frame at a time, with
/// `photons` per light from photon stream `seed`, printing the tracer's progress:
/// what `tests/demo_comparison.rs` and `caustics bench` on a saved frame do. Afterwards
/// [`ReferenceComparison`] holds the rows; time stays stopped.
#[cfg(feature = "headless")]
pub fn compare_headless(renderer: &mut HeadlessRenderer, camera: Entity, (photons, seed): (u64, u64)) -> Result<(), String> {
    renderer.world_mut().write_message(ReferenceComparisonRequest::Start { camera, photons, seed });
    let mut reported = 0;
    loop {
        renderer.render(1).map_err(|e| e.to_string())?;
        let comparison = renderer.world_mut().resource::<ReferenceComparison>();
        // Eighths of the photons, then the gather.
        let step = (comparison.progress() * 8.0) as u32 + comparison.gathering() as u32;
        if step > reported {
            reported = step;
            let traced = if step > 8 { "gathering at every pixel".into() } else { format!("{:3} % of the photons traced", 100 * step / 8) };
            eprintln!("  reference: {traced} ({:?})", comparison.state);
        }
        match &comparison.state {
            ComparisonState::Done => return Ok(()),
            ComparisonState::Failed(why) => return Err(why.clone()),
            _ => {}
        }
    }
}
