//! The plugin's own CPU time per frame, in the main world and in the render world.
//!
//! Every per-frame system the plugin adds runs [`timed`] by its world's [`CpuClock`],
//! and the builds it hands to the async compute pool add their time when they end.
//! At the start of each frame the main world publishes the two sums as Bevy
//! diagnostics ([`CausticCpuTime::MAIN`], [`CausticCpuTime::RENDER`], in ms) and
//! starts them again. The times are wall-clock time on the thread that runs each
//! system or build: a build's parallel parts count once, not once per core.

use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::ecs::system::{Adapt, IntoAdapterSystem, RunSystemError, SystemIn, SystemInput};
use bevy::platform::time::Instant;
use bevy::prelude::*;
use bevy::render::RenderApp;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Time spent in the plugin's work of one world since the last frame began.
#[derive(Clone, Debug, Default)]
pub struct CpuClock(Arc<AtomicU64>);

impl CpuClock {
    /// Adds `elapsed` to this frame's sum.
    pub fn add(&self, elapsed: Duration) {
        self.0.fetch_add(u64::try_from(elapsed.as_nanos()).unwrap_or(u64::MAX), Ordering::Relaxed);
    }

    /// Runs `work` and adds the time it took.
    pub fn time<T>(&self, work: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = work();
        self.add(start.elapsed());
        out
    }

    /// This frame's sum so far, and a new sum from zero.
    fn take(&self) -> Duration {
        Duration::from_nanos(self.0.swap(0, Ordering::Relaxed))
    }
}

/// Runs a system and adds the time it took to the clock.
impl<S: System> Adapt<S> for CpuClock {
    type In = S::In;
    type Out = S::Out;

    fn adapt(
        &mut self,
        input: <Self::In as SystemInput>::Inner<'_>,
        run_system: impl FnOnce(SystemIn<'_, S>) -> Result<S::Out, RunSystemError>,
    ) -> Result<Self::Out, RunSystemError> {
        self.time(|| run_system(input))
    }
}

/// `system`, timed by `clock`.
pub(crate) fn timed<S>(clock: &CpuClock, system: S) -> IntoAdapterSystem<CpuClock, S> {
    IntoAdapterSystem::new(clock.clone(), system)
}

/// The plugin's two clocks (a main-world resource; the render world has a copy).
#[derive(Resource, Clone, Debug, Default)]
pub struct CausticCpuTime {
    /// The plugin's systems in the main world.
    pub main: CpuClock,
    /// The plugin's systems in the render world.
    pub render: CpuClock,
}

impl CausticCpuTime {
    /// The plugin's CPU time in the main world last frame (ms): its systems and the
    /// builds that ended.
    pub const MAIN: DiagnosticPath = DiagnosticPath::const_new("caustics/cpu_main");
    /// The plugin's CPU time in the render world last frame (ms): extraction,
    /// preparation and recording its passes.
    pub const RENDER: DiagnosticPath = DiagnosticPath::const_new("caustics/cpu_render");

    /// The clocks of `app` (made on first use): the main world's to time its systems
    /// with, and the render world's.
    pub(crate) fn of(app: &mut App) -> Self {
        if let Some(clocks) = app.world().get_resource::<Self>() {
            return clocks.clone();
        }
        let clocks = Self::default();
        app.insert_resource(clocks.clone())
            .register_diagnostic(Diagnostic::new(Self::MAIN).with_suffix("ms"))
            .register_diagnostic(Diagnostic::new(Self::RENDER).with_suffix("ms"))
            .add_systems(First, publish);
        if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
            render_app.insert_resource(clocks.clone());
        }
        clocks
    }
}

/// Publishes last frame's sums and starts new ones.
fn publish(clocks: Res<CausticCpuTime>, mut diagnostics: Diagnostics) {
    let (main, render) = (clocks.main.take(), clocks.render.take());
    diagnostics.add_measurement(&CausticCpuTime::MAIN, || main.as_secs_f64() * 1e3);
    diagnostics.add_measurement(&CausticCpuTime::RENDER, || render.as_secs_f64() * 1e3);
}
