//! An egui window showing what the caustics plugin does: the entities it sees, the
//! technique each generator draws with and why, with a switch to any other, the passes
//! that ran in the last frame with their GPU times and shader invocations (timestamp
//! and pipeline-statistics queries, through Bevy's `RenderDiagnosticsPlugin`) beside
//! Bevy's main opaque pass, and a running graph of the times, a "compare with reference"
//! button that measures every technique on the frame against the ground-truth tracer
//! ([`crate::comparison`]: a progress bar, relative L2 and L1 per technique, a split
//! view), and every invalid entity with its reason. Behind the `egui` cargo feature.

use crate::comparison::{ComparisonState, ReferenceComparison, ReferenceComparisonRequest};
use crate::gpu_work::{FrameWork, PassWork, newest_pass_work, pass_time_history};
use crate::technique::CausticTechniqueChoice;
use crate::{CausticGenerator, CausticPassReport, CausticReceiver, CausticTechnique, Caustics, InvalidCausticParams, ParticipatingMedium};
use bevy::diagnostic::DiagnosticsStore;
use bevy::prelude::*;
use bevy::render::diagnostic::RenderDiagnosticsPlugin;
/// The egui integration the panel uses, for applications that add windows of their own.
pub use bevy_egui;
use bevy_egui::{EguiContexts, EguiPlugin, EguiPrimaryContextPass, egui};

/// Adds the "Caustics" window, and `EguiPlugin` and `RenderDiagnosticsPlugin` if the
/// app has none. The GPU times need the adapter's `TIMESTAMP_QUERY` feature and the
/// invocation counts its `PIPELINE_STATISTICS_QUERY`, both of which Bevy requests by
/// default where the adapter has them.
pub struct CausticsDebugPanelPlugin;

impl Plugin for CausticsDebugPanelPlugin {
    fn build(&self, app: &mut App) {
        if !app.is_plugin_added::<EguiPlugin>() {
            app.add_plugins(EguiPlugin::default());
        }
        if !app.is_plugin_added::<RenderDiagnosticsPlugin>() {
            app.add_plugins(RenderDiagnosticsPlugin);
        }
        app.add_systems(EguiPrimaryContextPass, panel);
    }
}

/// Photons per light the panel's comparison traces: a few seconds to a minute on a
/// desktop CPU. The panel shows the reference's noise they leave.
pub const COMPARISON_PHOTONS: u64 = 1 << 22;

/// Where the panel's "save frame" button writes the traced frame: the working
/// directory, for `caustics bench --scenes '' --scene caustics-frame.json`.
pub const SAVED_FRAME: &str = "caustics-frame.json";

/// The spans the graph draws, one colour each in this order.
const COLOURS: [egui::Color32; 6] = [
    egui::Color32::from_rgb(102, 194, 165),
    egui::Color32::from_rgb(252, 141, 98),
    egui::Color32::from_rgb(141, 160, 203),
    egui::Color32::from_rgb(231, 138, 195),
    egui::Color32::from_rgb(166, 216, 84),
    egui::Color32::from_rgb(255, 217, 47),
];

#[allow(clippy::too_many_arguments)]
fn panel(
    mut contexts: EguiContexts,
    report: Res<CausticPassReport>,
    diagnostics: Option<Res<DiagnosticsStore>>,
    mut generators: Query<(Entity, &mut CausticGenerator, Option<&CausticTechniqueChoice>)>,
    receivers: Query<(), With<CausticReceiver>>,
    media: Query<(), With<ParticipatingMedium>>,
    invalid: Query<(Entity, &InvalidCausticParams)>,
    names: Query<&Name>,
    (mut comparison, mut requests, cameras, mut saved): Comparison,
    #[cfg(feature = "warped-volumes")] volumes: Option<Res<crate::warped_volumes::CausticVolumes>>,
) -> Result {
    let label = |entity: Entity| names.get(entity).map_or_else(|_| entity.to_string(), |n| n.to_string());
    let work = FrameWork::of(diagnostics.as_deref().map(newest_pass_work).unwrap_or_default());
    let passes = diagnostics.as_deref().map(|store| gpu_passes(store, &work)).unwrap_or_default();
    egui::Window::new("Caustics").default_width(320.0).show(contexts.ctx_mut()?, |ui| {
        ui.label(format!("{} generators, {} receivers, {} media", generators.iter().count(), receivers.iter().count(), media.iter().count()));
        ui.separator();
        let running = comparison.running();
        for (entity, mut generator, choice) in &mut generators {
            let asked = generator.technique;
            let mut technique = asked;
            ui.horizontal(|ui| {
                ui.label(label(entity));
                ui.add_enabled_ui(!running, |ui| {
                    egui::ComboBox::from_id_salt(entity).selected_text(asked.label()).show_ui(ui, |ui| {
                        for t in CausticTechnique::ALL {
                            ui.selectable_value(&mut technique, t, t.label());
                        }
                    });
                });
            });
            let drawn = choice.map_or_else(|| "no technique (see below)".to_string(), |c| c.to_string());
            ui.label(egui::RichText::new(format!("  {drawn}")).small());
            if technique != asked {
                generator.technique = technique;
            }
        }
        ui.separator();
        ui.label("Passes in the last frame:");
        if report.is_empty() {
            ui.label("  none");
        }
        for (pass, views) in &report.passes {
            ui.label(format!("  {pass}: {views} view(s)"));
        }
        ui.separator();
        if work.caustics.is_empty() {
            ui.label("GPU work: none (the adapter has no timestamp or statistics queries, or no pass ran)");
        } else {
            ui.label("GPU work this frame: time (ms), shader invocations (M)");
            for (i, pass) in work.caustics.iter().enumerate() {
                ui.colored_label(COLOURS[i % COLOURS.len()], format!("  {}", work_line(pass)));
            }
            ui.label(format!("  Bevy's {}", work_line(&work.main_pass)));
            #[cfg(feature = "warped-volumes")]
            if let Some(crate::warped_volumes::SurfaceWork { splatted, splatted_pixels, rasterised }) =
                volumes.as_ref().map(|v| v.surface).filter(|s| *s != default())
            {
                ui.label(format!("  volumes' surface pass: {splatted} lit by compute ({splatted_pixels} pixels), {rasterised} rasterised"));
            }
            graph(ui, &passes);
        }
        ui.separator();
        let camera = cameras.iter().filter(|(_, c)| c.is_active).min_by_key(|(_, c)| c.order).map(|(e, _)| e);
        comparison_section(ui, &mut comparison, &mut requests, camera, &mut saved);
        for (entity, InvalidCausticParams(reason)) in &invalid {
            ui.colored_label(egui::Color32::YELLOW, format!("{} skipped: {reason}", label(entity)));
        }
    });
    Ok(())
}

/// What the panel's comparison reads and writes: its state, its requests, the
/// cameras it can measure, and what saving its frame did.
type Comparison<'w, 's> = (
    ResMut<'w, ReferenceComparison>,
    MessageWriter<'w, ReferenceComparisonRequest>,
    Query<'w, 's, (Entity, &'static Camera), With<Caustics>>,
    Local<'s, Option<String>>,
);

/// The comparison with the ground-truth tracer: the button, the progress, the rows and
/// the split view's switch.
fn comparison_section(
    ui: &mut egui::Ui,
    comparison: &mut ReferenceComparison,
    requests: &mut MessageWriter<ReferenceComparisonRequest>,
    camera: Option<Entity>,
    saved: &mut Option<String>,
) {
    match comparison.state.clone() {
        ComparisonState::Idle | ComparisonState::Failed(_) => {
            if let ComparisonState::Failed(why) = &comparison.state {
                ui.colored_label(egui::Color32::YELLOW, format!("comparison failed: {why}"));
            }
            let button = ui.add_enabled(camera.is_some(), egui::Button::new("Compare with reference"));
            if let (true, Some(camera)) = (button.clicked(), camera) {
                requests.write(ReferenceComparisonRequest::Start { camera, photons: COMPARISON_PHOTONS, seed: 0 });
            }
            ui.label(egui::RichText::new("stops time and traces this frame with the ground-truth tracer").small());
        }
        ComparisonState::Measuring(_) | ComparisonState::Tracing => {
            let doing = match comparison.state {
                ComparisonState::Measuring(i) => format!("drawing with {} ({} of {})", CausticTechnique::ALL[i].label(), i + 1, CausticTechnique::ALL.len()),
                _ => "every technique read back".into(),
            };
            ui.label(doing);
            let text = if comparison.gathering() {
                "reference: gathering at every pixel".to_string()
            } else {
                format!("reference: {:.0} % of the photons", 100.0 * comparison.progress())
            };
            ui.add(egui::ProgressBar::new(comparison.progress()).text(text));
            if ui.button("Cancel").clicked() {
                requests.write(ReferenceComparisonRequest::End);
            }
        }
        ComparisonState::Done => {
            egui::Grid::new("comparison").striped(true).show(ui, |ui| {
                for header in ["asked of every generator", "rel. L2", "rel. L1", "GPU ms"] {
                    ui.label(egui::RichText::new(header).strong());
                }
                ui.end_row();
                for row in &comparison.rows {
                    ui.label(row.technique.label()).on_hover_text(row.drawn.join("\n"));
                    match row.error {
                        Some(e) => {
                            ui.label(format!("{:.3}", e.l2));
                            ui.label(format!("{:.3}", e.l1));
                        }
                        None => {
                            ui.label("no receiver");
                            ui.label("–");
                        }
                    }
                    ui.label(format!("{:.2}", row.work.caustics_ms())).on_hover_text(format!(
                        "{:.2} M fragments; Bevy's main pass {:.2} M",
                        row.work.caustics_fragments() / 1e6,
                        row.work.main_pass.fragments.unwrap_or(0.0) / 1e6
                    ));
                    ui.end_row();
                }
            });
            if let Some(noise) = comparison.reference_noise {
                ui.label(format!("the reference's own noise: {noise:.3} (relative L2)"));
            }
            ui.checkbox(&mut comparison.split, "split view: technique left, reference right");
            let button = ui
                .button("Save frame")
                .on_hover_text(format!("writes the traced frame to {SAVED_FRAME}; `caustics bench --scenes '' --scene {SAVED_FRAME}` measures it again"));
            if button.clicked() {
                *saved = Some(match comparison.save_frame(std::path::Path::new(SAVED_FRAME)) {
                    Ok(()) => format!("saved to {SAVED_FRAME}"),
                    Err(why) => why,
                });
            }
            if let Some(saved) = saved.as_ref() {
                ui.label(saved);
            }
            if ui.button("Resume").clicked() {
                *saved = None;
                requests.write(ReferenceComparisonRequest::End);
            }
        }
    }
}

/// A pass's time and invocations on one line: `caustics/volumes: 1.204 ms, 3.10 M
/// fragments`.
fn work_line(pass: &PassWork) -> String {
    let mut line = format!("{}:", pass.span);
    if let Some(ms) = pass.ms {
        line += &format!(" {ms:.3} ms");
    }
    for (count, what) in [(pass.vertices, "vertices"), (pass.fragments, "fragments"), (pass.compute, "compute")] {
        if let Some(count) = count.filter(|&c| c > 0.0) {
            line += &format!(", {:.2} M {what}", count / 1e6);
        }
    }
    line
}

/// A caustics pass's GPU times (ms), oldest first, ending with this frame's.
struct GpuPass {
    history: Vec<f64>,
}

/// The caustics passes of the newest frame whose timestamps have arrived, in the
/// order of `work`, with the history Bevy keeps of each.
fn gpu_passes(store: &DiagnosticsStore, work: &FrameWork) -> Vec<GpuPass> {
    work.caustics.iter().map(|w| GpuPass { history: pass_time_history(store, &w.span) }).collect()
}

/// Each pass's GPU time over the frames Bevy keeps, one line each, on a shared scale.
fn graph(ui: &mut egui::Ui, passes: &[GpuPass]) {
    let (response, painter) = ui.allocate_painter(egui::vec2(ui.available_width(), 90.0), egui::Sense::hover());
    let rect = response.rect;
    painter.rect_filled(rect, 2.0, egui::Color32::from_gray(24));
    let top = passes.iter().flat_map(|p| p.history.iter().copied()).fold(0.0, f64::max).max(1e-3);
    let frames = passes.iter().map(|p| p.history.len()).max().unwrap_or(0).max(2);
    for (i, pass) in passes.iter().enumerate() {
        // Right-aligned: the newest frame at the right edge for every span.
        let start = frames - pass.history.len();
        let points = pass
            .history
            .iter()
            .enumerate()
            .map(|(k, ms)| {
                let x = rect.left() + rect.width() * (start + k) as f32 / (frames - 1) as f32;
                egui::pos2(x, rect.bottom() - rect.height() * (ms / top) as f32)
            })
            .collect();
        painter.add(egui::Shape::line(points, egui::Stroke::new(1.5, COLOURS[i % COLOURS.len()])));
    }
    painter.text(rect.left_top() + egui::vec2(4.0, 2.0), egui::Align2::LEFT_TOP, format!("{top:.2} ms"), egui::FontId::monospace(10.0), egui::Color32::GRAY);
}
