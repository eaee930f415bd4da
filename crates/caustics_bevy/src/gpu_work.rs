//! What each render pass did on the GPU in a frame: its time (timestamp queries) and
//! its work (pipeline-statistics queries: vertex, fragment and compute shader
//! invocations), as Bevy's `RenderDiagnosticsPlugin` records them for every pass span.
//!
//! Invocation counts are the figure that carries between adapters: a software
//! rasteriser and a desktop GPU shade the same fragments, where their milliseconds
//! differ by orders of magnitude. Times are only ever read beside the adapter's name.

use bevy::diagnostic::DiagnosticsStore;
use bevy::render::render_resource::{ComputePass, ComputePipeline};

/// The prefixes of the caustics passes' spans: every technique's passes, the
/// projections into the irradiance buffer, the composite and the volumetric pass.
pub const CAUSTIC_SPANS: [&str; 3] = ["caustics/", "caustic_maps/", "illumination_textures/"];

/// Bevy's main opaque pass: the yardstick a caustics pass's work is read against.
pub const MAIN_OPAQUE_SPAN: &str = "main_opaque_pass_3d";

/// Whether a span (`caustics/volumes`, `main_opaque_pass_3d`…) is one of the caustics
/// passes' ([`CAUSTIC_SPANS`]).
pub fn is_caustic_span(span: &str) -> bool {
    CAUSTIC_SPANS.iter().any(|p| span.starts_with(p))
}

/// Dispatches `anchor` (an empty kernel under the bind groups already set) first in a
/// compute pass while timestamps are recorded. Lavapipe writes a compute pass's first
/// timestamp at the pass's first barrier and runs each dispatch at once (it bins only
/// draws), so a pass that follows other compute work would time without its first
/// dispatch; the barrier between `anchor` and that dispatch puts the timestamp before it.
pub fn anchor_first_timestamp(pass: &mut ComputePass, recording: bool, anchor: Option<&ComputePipeline>) {
    if let (true, Some(anchor)) = (recording, anchor) {
        pass.set_pipeline(anchor);
        pass.dispatch_workgroups(1, 1, 1);
    }
}

/// One pass's GPU work in one frame, summed over every span of that name in the frame
/// (one a view, one a light view). A figure is `None` where the adapter lacks its query
/// (`TIMESTAMP_QUERY`, `PIPELINE_STATISTICS_QUERY`) or the pass is of the other kind
/// (a compute pass has no fragments).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PassWork {
    /// The span's name: `caustics/volumes`, `caustic_maps/gather`, `main_opaque_pass_3d`…
    pub span: String,
    /// GPU time (ms).
    pub ms: Option<f64>,
    /// Vertex shader invocations (render passes).
    pub vertices: Option<f64>,
    /// Fragment shader invocations (render passes).
    pub fragments: Option<f64>,
    /// Compute shader invocations (compute passes).
    pub compute: Option<f64>,
}

impl PassWork {
    /// Every shader invocation of the pass: vertex, fragment and compute.
    pub fn invocations(&self) -> f64 {
        self.vertices.unwrap_or(0.0) + self.fragments.unwrap_or(0.0) + self.compute.unwrap_or(0.0)
    }

    /// Whether this is one of the caustics passes ([`is_caustic_span`]).
    pub fn is_caustic(&self) -> bool {
        is_caustic_span(&self.span)
    }
}

/// Where a figure goes in [`PassWork`].
type Figure = fn(&mut PassWork) -> &mut Option<f64>;

/// The figures `RenderDiagnosticsPlugin` records under `render/<span>/<figure>`, and
/// where each goes.
const FIGURES: [(&str, Figure); 4] = [
    ("elapsed_gpu", |w| &mut w.ms),
    ("vertex_shader_invocations", |w| &mut w.vertices),
    ("fragment_shader_invocations", |w| &mut w.fragments),
    ("compute_shader_invocations", |w| &mut w.compute),
];

/// Every pass's work in the newest frame whose diagnostics have arrived (a frame or two
/// behind), sorted by span. Spans of one name in one frame are added up: Bevy records
/// each as a measurement of the same diagnostic at the same instant.
pub fn newest_pass_work(store: &DiagnosticsStore) -> Vec<PassWork> {
    let figures: Vec<(&str, usize, &bevy::diagnostic::Diagnostic)> = store
        .iter()
        .filter_map(|d| {
            let path = d.path().as_str().strip_prefix("render/")?;
            let (span, figure) = path.rsplit_once('/')?;
            let k = FIGURES.iter().position(|(name, _)| *name == figure)?;
            Some((span, k, d))
        })
        .collect();
    let Some(newest) = figures.iter().filter_map(|(_, _, d)| Some(d.measurement()?.time)).max() else {
        return Vec::new();
    };
    let mut work: Vec<PassWork> = Vec::new();
    for (span, k, d) in figures {
        let values: Vec<f64> = d.measurements().filter(|m| m.time == newest).map(|m| m.value).collect();
        if values.is_empty() {
            continue;
        }
        let at = match work.iter().position(|w| w.span == span) {
            Some(at) => at,
            None => {
                work.push(PassWork { span: span.to_owned(), ..Default::default() });
                work.len() - 1
            }
        };
        *FIGURES[k].1(&mut work[at]) = Some(values.iter().sum());
    }
    work.sort_by(|a, b| a.span.cmp(&b.span));
    work
}

/// Every pass's GPU time (ms) over the frames Bevy keeps, oldest first, for the spans
/// in the newest frame: each frame's spans of one name added up.
pub fn pass_time_history(store: &DiagnosticsStore, span: &str) -> Vec<f64> {
    let Some(d) = store.iter().find(|d| d.path().as_str().strip_prefix("render/").and_then(|p| p.strip_suffix("/elapsed_gpu")) == Some(span)) else {
        return Vec::new();
    };
    let mut history: Vec<(bevy::platform::time::Instant, f64)> = Vec::new();
    for m in d.measurements() {
        match history.last_mut() {
            Some((time, ms)) if *time == m.time => *ms += m.value,
            _ => history.push((m.time, m.value)),
        }
    }
    history.into_iter().map(|(_, ms)| ms).collect()
}

/// The caustics passes' work added up, and Bevy's main opaque pass of the same frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameWork {
    /// The caustics passes, by span.
    pub caustics: Vec<PassWork>,
    /// Bevy's main opaque pass (every view's).
    pub main_pass: PassWork,
}

impl FrameWork {
    /// Splits a frame's passes into the caustics passes and the main pass.
    pub fn of(passes: Vec<PassWork>) -> Self {
        let main_pass = passes.iter().find(|w| w.span == MAIN_OPAQUE_SPAN).cloned().unwrap_or_default();
        Self { caustics: passes.into_iter().filter(PassWork::is_caustic).collect(), main_pass }
    }

    /// The caustics passes, then the main pass.
    pub fn passes(&self) -> impl Iterator<Item = &PassWork> {
        self.caustics.iter().chain(std::iter::once(&self.main_pass))
    }

    /// The caustics passes' summed GPU time (ms).
    pub fn caustics_ms(&self) -> f64 {
        self.caustics.iter().filter_map(|w| w.ms).sum()
    }

    /// The caustics passes' summed fragment shader invocations.
    pub fn caustics_fragments(&self) -> f64 {
        self.caustics.iter().filter_map(|w| w.fragments).sum()
    }

    /// The caustics passes' summed shader invocations.
    pub fn caustics_invocations(&self) -> f64 {
        self.caustics.iter().map(PassWork::invocations).sum()
    }
}
