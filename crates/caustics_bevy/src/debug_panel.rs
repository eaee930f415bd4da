//! An egui window showing what the caustics plugin does: the entities it sees, the
//! technique each generator draws with and why, the passes that ran in the last frame,
//! and every invalid entity with its reason.
//! Behind the `egui` cargo feature.

use crate::{CausticGenerator, CausticPassReport, CausticReceiver, InvalidCausticParams, ParticipatingMedium};
use bevy::prelude::*;
/// The egui integration the panel uses, for applications that add windows of their own.
pub use bevy_egui;
use bevy_egui::{EguiContexts, EguiPlugin, EguiPrimaryContextPass, egui};

/// Adds the "Caustics" window (and `EguiPlugin` if the app has none).
pub struct CausticsDebugPanelPlugin;

impl Plugin for CausticsDebugPanelPlugin {
    fn build(&self, app: &mut App) {
        if !app.is_plugin_added::<EguiPlugin>() {
            app.add_plugins(EguiPlugin::default());
        }
        app.add_systems(EguiPrimaryContextPass, panel);
    }
}

fn panel(
    mut contexts: EguiContexts,
    report: Res<CausticPassReport>,
    generators: Query<(), With<CausticGenerator>>,
    receivers: Query<(), With<CausticReceiver>>,
    media: Query<(), With<ParticipatingMedium>>,
    invalid: Query<(Entity, &InvalidCausticParams)>,
    names: Query<&Name>,
) -> Result {
    let label = |entity: Entity| names.get(entity).map_or_else(|_| entity.to_string(), |n| n.to_string());
    egui::Window::new("Caustics").default_width(280.0).show(contexts.ctx_mut()?, |ui| {
        ui.label(format!(
            "{} generators, {} receivers, {} media",
            generators.iter().count(),
            receivers.iter().count(),
            media.iter().count()
        ));
        ui.separator();
        for (entity, choice) in &report.generators {
            ui.label(format!("{}: {choice}", label(*entity)));
        }
        ui.separator();
        ui.label("Passes in the last frame:");
        if report.is_empty() {
            ui.label("  none");
        }
        for (pass, views) in &report.passes {
            ui.label(format!("  {pass}: {views} view(s)"));
        }
        for (entity, InvalidCausticParams(reason)) in &invalid {
            ui.colored_label(egui::Color32::YELLOW, format!("{} skipped: {reason}", label(entity)));
        }
    });
    Ok(())
}
