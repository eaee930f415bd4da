//! Which caustics passes ran in the last rendered frame, and which technique draws
//! each generator and why, for tests, profiling overlays and "no generators, no work"
//! guarantees.

use crate::technique::CausticTechniqueChoice;
use bevy::prelude::*;
use bevy::render::{Render, RenderApp, RenderSystems};
use std::sync::{Arc, Mutex};

/// The passes that ran in the last frame the renderer finished, with the number of
/// views each ran for, and this frame's technique for every generator. `passes` is
/// empty when the scene needed no caustics work.
#[derive(Resource, Clone, Debug, Default, PartialEq, Eq)]
pub struct CausticPassReport {
    /// Passes by name (`"inject"`, `"composite"`, …) and how many views ran them.
    pub passes: Vec<(&'static str, u32)>,
    /// Each generator with a technique, by entity, with the choice and its reason
    /// (`closed refractor → hierarchical maps`).
    pub generators: Vec<(Entity, CausticTechniqueChoice)>,
}

impl CausticPassReport {
    /// How many views ran `pass` (0 if it did not run).
    pub fn views(&self, pass: &str) -> u32 {
        self.passes.iter().find(|(p, _)| *p == pass).map_or(0, |(_, n)| *n)
    }

    /// Whether no caustics pass ran at all.
    pub fn is_empty(&self) -> bool {
        self.passes.is_empty()
    }
}

/// Shared between the worlds: the render world fills `current` and publishes it to
/// `last` when its frame ends; the main world copies `last` into [`CausticPassReport`].
#[derive(Resource, Clone, Default)]
pub struct PassRecorder(Arc<Mutex<(CausticPassReport, CausticPassReport)>>);

impl PassRecorder {
    /// Records that `pass` ran for one more view this frame.
    pub fn record(&self, pass: &'static str) {
        if let Ok(mut g) = self.0.lock() {
            match g.0.passes.iter_mut().find(|(p, _)| *p == pass) {
                Some((_, n)) => *n += 1,
                None => g.0.passes.push((pass, 1)),
            }
        }
    }

    fn publish(&self) {
        if let Ok(mut g) = self.0.lock() {
            g.1 = std::mem::take(&mut g.0);
        }
    }

    fn last(&self) -> CausticPassReport {
        self.0.lock().map(|g| g.1.clone()).unwrap_or_default()
    }
}

pub(crate) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).main;
    let recorder = PassRecorder::default();
    app.insert_resource(recorder.clone())
        .init_resource::<CausticPassReport>()
        .add_systems(First, |recorder: Res<PassRecorder>, mut report: ResMut<CausticPassReport>| {
            let last = recorder.last().passes;
            if report.passes != last {
                report.passes = last;
            }
        })
        .add_systems(
            PostUpdate,
            crate::cpu_time::timed(&cpu, report_choices)
                .run_if(crate::cpu_time::timed(
                    &cpu,
                    any_match_filter::<Changed<CausticTechniqueChoice>>.or_else(any_component_removed::<CausticTechniqueChoice>),
                ))
                .in_set(crate::CausticSystems::ReadScene),
        );
    if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
        render_app.insert_resource(recorder).add_systems(Render, (|r: Res<PassRecorder>| r.publish()).in_set(RenderSystems::Cleanup));
    }
}

/// Copies every generator's [`CausticTechniqueChoice`] into the report.
fn report_choices(choices: Query<(Entity, &CausticTechniqueChoice)>, mut report: ResMut<CausticPassReport>) {
    let mut generators: Vec<(Entity, CausticTechniqueChoice)> = choices.iter().map(|(e, c)| (e, c.clone())).collect();
    generators.sort_by_key(|(e, _)| *e);
    if report.generators != generators {
        report.generators = generators;
    }
}
