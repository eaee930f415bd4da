//! `caustics bench --frames`: what each technique costs per frame as its work grows.
//!
//! Every technique renders a family of scenes of growing size in the headless
//! renderer (1280 × 720 unless `--frame-size` says otherwise): an animated ocean, a
//! mirror ring and a rippling pool for the caustic volumes, the ring and a glass ball's
//! photon buffer for the caustic maps, the pool's texels for convolution, the virtual
//! planes' texels for illumination textures. Every generator moves (the ocean's waves,
//! the pool's ripples under a steady rain; the ring and the ball turn a little each
//! frame, [`Turning`]), so that each technique redoes its per-frame work, as for a
//! game's moving objects: a static scene's maps, volumes and textures are made once.
//! After the technique's first pass has run and its GPU figures arrived,
//! [`MEASURED_FRAMES`] frames record, per caustics pass, the GPU time (timestamp
//! queries) and the shader invocations (pipeline-statistics queries: the figure that
//! carries from a software rasteriser to any GPU), Bevy's main opaque pass of the same
//! view as the yardstick, the receiver pixels (the composite shades each once), the
//! plugin's CPU time in the main and render worlds (`CausticCpuTime`), and how often
//! the caustic volumes' sources were gathered on the CPU in those frames
//! (`CausticVolumes::gathered`: none for the ocean, whose waves move on the GPU).
//! Writes `frames.csv` (a row per size, a column per figure), `frames-passes.csv` (a
//! row per pass and size), `frames.md` (each line's growth exponent, the slope of log
//! cost against log size, and every pass at each family's largest size) and the
//! log–log plots `frames-gpu.png` and `frames-cpu.png`.

use crate::plot::{Axes, Series, plot_log_log};
use bevy::camera::{Exposure, RenderTarget};
use bevy::prelude::*;
use caustics_bevy::gpu_work::{FrameWork, PassWork};
use caustics_bevy::headless::HeadlessRenderer;
use caustics_bevy::prelude::*;
use caustics_bevy::warped_volumes::{CausticVolumes, SurfaceWork};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// The frames averaged at each size, once the technique runs in steady state: a whole
/// cycle of the caustic volumes' counter readback (every eighth frame while their
/// sources move), so that the plugin's CPU mean holds one mapping, as a game's does.
const MEASURED_FRAMES: usize = 8;
/// Updates to wait at most for the technique's first pass (pipelines compile, builds
/// finish on other threads) before a size counts as failed.
const MAX_WARM_UP: usize = 240;
/// The composite's span: it shades every receiver pixel of the view once, so its
/// fragment invocations count the receiver pixels.
const COMPOSITE_SPAN: &str = "caustics/composite";

/// How the frame bench runs.
pub struct FrameBench {
    /// The first this many sizes of each family, when given.
    pub sizes: Option<usize>,
    /// A family stops growing once a frame took longer than this (wall time, s).
    pub budget_s: f64,
    /// The view's width and height in pixels.
    pub view: (u32, u32),
    /// How the volumes' shafts are integrated.
    pub shafts: caustics_bevy::warped_volumes::ShaftIntegral,
    /// The volumes' `splat_pixels`, where not the default.
    pub splat_pixels: Option<u32>,
}

/// One technique on one scene at growing sizes.
struct Family {
    technique: &'static str,
    scene: &'static str,
    /// What the size counts.
    unit: &'static str,
    /// The scene's parameter at each size (a grid's resolution, a buffer's side…).
    sizes: &'static [u32],
    /// Spawns the scene at a parameter into a world and returns the work size.
    spawn: fn(&mut World, RenderTarget, u32) -> u64,
    /// The pass whose first run ends the warm-up (a [`CausticPassReport`] name).
    pass: &'static str,
}

const FAMILIES: [Family; 8] = [
    Family { technique: "volumes", scene: "ocean", unit: "water vertices", sizes: &[32, 64, 128, 256, 512], spawn: ocean, pass: "volumes" },
    Family { technique: "volumes", scene: "ring", unit: "mirror triangles", sizes: &RING_SIZES, spawn: ring_volumes, pass: "volumes" },
    Family { technique: "volumes", scene: "rippled pool", unit: "water vertices", sizes: &[32, 64, 128, 256], spawn: rippled_pool, pass: "volumes" },
    Family {
        technique: "volumes",
        scene: "moving occluder",
        unit: "occluder triangles",
        sizes: &[32, 64, 128, 256, 512],
        spawn: moving_occluder,
        pass: "volumes",
    },
    Family { technique: "maps", scene: "ring", unit: "mirror triangles", sizes: &RING_SIZES, spawn: ring_maps, pass: "caustic map projection" },
    Family { technique: "maps", scene: "glass ball", unit: "photons", sizes: &[256, 512, 1024, 2048, 4096], spawn: ball_maps, pass: "caustic map projection" },
    Family { technique: "convolution", scene: "pool", unit: "pool texels", sizes: &[128, 256, 512, 1024], spawn: pool, pass: "pool floor" },
    Family {
        technique: "textures",
        scene: "glass ball",
        unit: "plane texels",
        sizes: &[128, 256, 512, 1024],
        spawn: ball_textures,
        pass: "illumination textures projection",
    },
];

/// The ring's segments around (with a quarter as many rows up): 1 k to 100 k triangles.
const RING_SIZES: [u32; 5] = [64, 128, 256, 512, 640];

/// A generator the bench turns about its vertical axis every frame.
#[derive(Component)]
struct Turning;

fn turn(mut turning: Query<&mut Transform, With<Turning>>) {
    for mut transform in &mut turning {
        transform.rotate_y(0.01);
    }
}

/// One measured frame: every pass's GPU work, the plugin's CPU time in the main and
/// render worlds (ms), wall time (s).
struct Frame {
    work: Vec<PassWork>,
    cpu_main: f64,
    cpu_render: f64,
    seconds: f64,
}

/// One size's measurement, averaged over the measured frames.
struct FrameCost {
    technique: &'static str,
    scene: &'static str,
    unit: &'static str,
    size: u64,
    /// The caustics passes' summed work, and Bevy's main opaque pass beside it.
    work: FrameWork,
    /// Receiver pixels in view: the composite's fragment invocations.
    receiver_pixels: f64,
    /// The plugin's CPU time (ms), main and render world.
    cpu_main_ms: f64,
    cpu_render_ms: f64,
    /// The frame's wall time in the headless renderer (s).
    frame_s: f64,
    /// The caustic volumes' CPU gatherings in the measured frames.
    volume_gathers: u64,
    /// The caustic volumes of the last build: kept, drawn as surface slabs, escaping.
    volumes: (usize, usize, usize),
    /// How the volumes' surface pass shared them out: lit by its compute pass (and the
    /// pixels it shaded for them), rasterised.
    surface: SurfaceWork,
}

impl FrameCost {
    fn caustics_ms(&self) -> f64 {
        self.work.caustics_ms()
    }

    fn main_pass_ms(&self) -> f64 {
        self.work.main_pass.ms.unwrap_or(0.0)
    }

    /// A figure per receiver pixel, where the view shows any.
    fn per_receiver_pixel(&self, count: Option<f64>) -> Option<f64> {
        Some(count? / self.receiver_pixels).filter(|_| self.receiver_pixels > 0.0)
    }
}

/// Runs every family whose technique and scene `runs` accepts and writes the outputs
/// to `out`. A family stops growing once a frame took longer than the bench's budget
/// of wall time: the larger sizes are listed as skipped.
pub fn run(out: &Path, runs: impl Fn(&str, &str) -> bool, bench: &FrameBench) -> Result<(), String> {
    let adapter = caustics_bevy::headless::probe_adapter().map_err(|e| e.to_string())?;
    if !adapter.has_timestamps() && !adapter.has_pipeline_statistics() {
        return Err(format!("{} has neither timestamp nor pipeline-statistics queries: the frame bench needs them", adapter.name));
    }
    let mut rows: Vec<FrameCost> = Vec::new();
    let mut skipped = Vec::new();
    for family in FAMILIES.iter().filter(|f| runs(f.technique, f.scene)) {
        let first = rows.len();
        for &parameter in family.sizes.iter().take(bench.sizes.unwrap_or(usize::MAX)) {
            if let Some(last) = rows[first..].last().filter(|r| r.frame_s > bench.budget_s) {
                skipped.push(format!(
                    "{} on the {} at parameter {parameter}: a frame at {} {} took {:.0} s, past the {} s budget",
                    family.technique, family.scene, last.size, family.unit, last.frame_s, bench.budget_s
                ));
                eprintln!("skipped: {}", skipped[skipped.len() - 1]);
                continue;
            }
            let start = Instant::now();
            let row = measure(family, parameter, bench)?;
            eprintln!(
                "{:>11} {:>12} {:>9} {}: caustics {:9.2} ms, {:8.2} M invocations, {:6.2} fragments a receiver pixel; main pass {:8.2} ms, {:6.2} M fragments (GPU); plugin CPU {:.3} + {:.3} ms, {} volume gatherings; {} volumes, {} slabs, {} escaping; surface pass: {} splatted ({:.2} pixels shaded a receiver pixel), {} rasterised; {:.0} s",
                family.technique,
                family.scene,
                row.size,
                family.unit,
                row.caustics_ms(),
                row.work.caustics_invocations() / 1e6,
                row.per_receiver_pixel(Some(row.work.caustics_fragments())).unwrap_or(f64::NAN),
                row.main_pass_ms(),
                row.work.main_pass.fragments.unwrap_or(f64::NAN) / 1e6,
                row.cpu_main_ms,
                row.cpu_render_ms,
                row.volume_gathers,
                row.volumes.0,
                row.volumes.1,
                row.volumes.2,
                row.surface.splatted,
                row.per_receiver_pixel(Some(f64::from(row.surface.splatted_pixels))).unwrap_or(f64::NAN),
                row.surface.rasterised,
                start.elapsed().as_secs_f64()
            );
            rows.push(row);
        }
    }
    write_outputs(out, &adapter.name, bench.view, &rows, &skipped)
}

/// Renders one family's scene at one size until the technique runs, then averages
/// [`MEASURED_FRAMES`] frames.
fn measure(family: &Family, parameter: u32, bench: &FrameBench) -> Result<FrameCost, String> {
    let (width, height) = bench.view;
    let mut renderer = HeadlessRenderer::timed(width, height).map_err(|e| e.to_string())?;
    let defaults = WarpedVolumesSettings::default();
    let splat_pixels = bench.splat_pixels.unwrap_or(defaults.splat_pixels);
    renderer.world_mut().insert_resource(WarpedVolumesSettings { shaft_integral: bench.shafts, splat_pixels, ..defaults });
    let target = renderer.render_target();
    renderer.app.add_systems(Update, (turn, rain));
    let size = (family.spawn)(renderer.world_mut(), target, parameter);
    let failed = |what: &str| format!("{} on the {} at {size} {}: {what}", family.technique, family.scene, family.unit);
    // Warm up: the first pass, then two frames for its GPU figures to arrive.
    let mut left = None;
    // Bevy quits the app on a rendering error: nothing after it would be measured. A
    // pipeline that did not compile leaves its pass out of every frame.
    let quit = |renderer: &HeadlessRenderer| {
        let pipeline = renderer.failed_pipeline().map(|why| failed(&format!("a pipeline failed: {why}")));
        pipeline.or_else(|| renderer.app.should_exit().map(|_| failed("the app quit (a rendering error, logged above)")))
    };
    for _ in 0..MAX_WARM_UP {
        renderer.app.update();
        if let Some(error) = quit(&renderer) {
            return Err(error);
        }
        if left.is_none() && renderer.pass_report().views(family.pass) > 0 {
            left = Some(2);
        }
        match &mut left {
            Some(0) => break,
            Some(n) => *n -= 1,
            None => {}
        }
    }
    if left != Some(0) {
        return Err(failed(&format!("its pass did not run in {MAX_WARM_UP} frames")));
    }
    let gathered = |renderer: &mut HeadlessRenderer| renderer.world_mut().resource::<CausticVolumes>().gathered;
    let gathered_before = gathered(&mut renderer);
    let mut frames: Vec<Frame> = Vec::new();
    for _ in 0..MEASURED_FRAMES {
        let start = Instant::now();
        renderer.app.update();
        let seconds = start.elapsed().as_secs_f64();
        if let Some(error) = quit(&renderer) {
            return Err(error);
        }
        let work = renderer.gpu_pass_work();
        let (cpu_main, cpu_render) = renderer.plugin_cpu_times().ok_or_else(|| failed("no CPU times"))?;
        frames.push(Frame { work, cpu_main, cpu_render, seconds });
    }
    let mean = |f: &dyn Fn(&Frame) -> f64| frames.iter().map(f).sum::<f64>() / frames.len() as f64;
    let mut names: Vec<String> = frames.iter().flat_map(|f| f.work.iter().map(|w| w.span.clone())).collect();
    names.sort();
    names.dedup();
    // Each pass's figures averaged over the frames that ran it.
    let passes: Vec<PassWork> = names
        .into_iter()
        .map(|span| {
            let ran: Vec<&PassWork> = frames.iter().filter_map(|f| f.work.iter().find(|w| w.span == span)).collect();
            let average = |figure: fn(&PassWork) -> Option<f64>| {
                let values: Vec<f64> = ran.iter().filter_map(|w| figure(w)).collect();
                (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
            };
            PassWork { ms: average(|w| w.ms), vertices: average(|w| w.vertices), fragments: average(|w| w.fragments), compute: average(|w| w.compute), span }
        })
        .collect();
    let receiver_pixels = passes.iter().find(|w| w.span == COMPOSITE_SPAN).and_then(|w| w.fragments).unwrap_or(0.0);
    let work = FrameWork::of(passes);
    if work.main_pass.ms.is_none() && work.main_pass.fragments.is_none() {
        return Err(failed("no GPU figures arrived"));
    }
    Ok(FrameCost {
        technique: family.technique,
        scene: family.scene,
        unit: family.unit,
        size,
        work,
        receiver_pixels,
        cpu_main_ms: mean(&|f| f.cpu_main),
        cpu_render_ms: mean(&|f| f.cpu_render),
        frame_s: mean(&|f| f.seconds),
        volume_gathers: gathered(&mut renderer) - gathered_before,
        volumes: {
            let stats = renderer.world_mut().resource::<CausticVolumes>().stats;
            (stats.volumes, stats.surface_slabs, stats.escaping)
        },
        surface: renderer.world_mut().resource::<CausticVolumes>().surface,
    })
}

/// The slope of log `y` against log `x`, least squares: the growth exponent.
fn growth_exponent(points: &[(f64, f64)]) -> Option<f64> {
    let logs: Vec<(f64, f64)> = points.iter().filter(|(x, y)| *x > 0.0 && *y > 0.0).map(|(x, y)| (x.ln(), y.ln())).collect();
    if logs.len() < 2 {
        return None;
    }
    let n = logs.len() as f64;
    let (mx, my) = (logs.iter().map(|p| p.0).sum::<f64>() / n, logs.iter().map(|p| p.1).sum::<f64>() / n);
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// A count (millions) or `–` where the adapter gave none.
fn millions(count: Option<f64>) -> String {
    count.map_or("–".into(), |c| format!("{:.3}", c / 1e6))
}

/// A figure with `digits` decimals, or `–`.
fn figure(value: Option<f64>, digits: usize) -> String {
    value.filter(|v| v.is_finite()).map_or("–".into(), |v| format!("{v:.digits$}"))
}

fn write_outputs(out: &Path, adapter: &str, (width, height): (u32, u32), rows: &[FrameCost], skipped: &[String]) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let mut csv = String::from(
        "adapter,width,height,technique,scene,unit,size,caustics_gpu_ms,main_pass_gpu_ms,caustics_over_main_pass,\
         caustics_vertex_invocations,caustics_fragment_invocations,caustics_compute_invocations,main_pass_fragment_invocations,\
         receiver_pixels,caustics_fragments_per_receiver_pixel,plugin_cpu_main_ms,plugin_cpu_render_ms,cpu_volume_gathers,\
         volumes,volume_surface_slabs,volumes_escaping,volumes_splatted,splatted_pixels_per_receiver_pixel,volumes_rasterised,frame_wall_s,spans\n",
    );
    let mut passes_csv = String::from(
        "adapter,width,height,technique,scene,size,span,gpu_ms,vertex_invocations,fragment_invocations,compute_invocations,fragments_per_receiver_pixel\n",
    );
    let sum = |r: &FrameCost, figure: fn(&PassWork) -> Option<f64>| {
        let values: Vec<f64> = r.work.caustics.iter().filter_map(figure).collect();
        (!values.is_empty()).then(|| values.iter().sum::<f64>())
    };
    let number = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.0}"));
    for r in rows {
        let spans: Vec<String> = r.work.caustics.iter().map(|w| format!("{}={:.3}", w.span, w.ms.unwrap_or(f64::NAN))).collect();
        let _ = writeln!(
            csv,
            "\"{adapter}\",{width},{height},{},{},{},{},{:.3},{:.3},{:.3},{},{},{},{},{:.0},{},{:.4},{:.4},{},{},{},{},{},{},{},{:.2},{}",
            r.technique,
            r.scene,
            r.unit,
            r.size,
            r.caustics_ms(),
            r.main_pass_ms(),
            r.caustics_ms() / r.main_pass_ms(),
            number(sum(r, |w| w.vertices)),
            number(sum(r, |w| w.fragments)),
            number(sum(r, |w| w.compute)),
            number(r.work.main_pass.fragments),
            r.receiver_pixels,
            figure(r.per_receiver_pixel(sum(r, |w| w.fragments)), 3),
            r.cpu_main_ms,
            r.cpu_render_ms,
            r.volume_gathers,
            r.volumes.0,
            r.volumes.1,
            r.volumes.2,
            r.surface.splatted,
            figure(r.per_receiver_pixel(Some(f64::from(r.surface.splatted_pixels))), 3),
            r.surface.rasterised,
            r.frame_s,
            spans.join(";")
        );
        for w in r.work.passes() {
            let _ = writeln!(
                passes_csv,
                "\"{adapter}\",{width},{height},{},{},{},{},{},{},{},{},{}",
                r.technique,
                r.scene,
                r.size,
                w.span,
                w.ms.map_or(String::new(), |ms| format!("{ms:.4}")),
                number(w.vertices),
                number(w.fragments),
                number(w.compute),
                figure(r.per_receiver_pixel(w.fragments), 3)
            );
        }
    }
    let write = |name: &str, text: &str| std::fs::write(out.join(name), text).map_err(|e| format!("cannot write {name}: {e}"));
    write("frames.csv", &csv)?;
    write("frames-passes.csv", &passes_csv)?;
    let mut lines: Vec<(String, Vec<&FrameCost>)> = Vec::new();
    for r in rows {
        let label = format!("{} on the {} ({})", r.technique, r.scene, r.unit);
        match lines.iter_mut().find(|(l, _)| *l == label) {
            Some((_, members)) => members.push(r),
            None => lines.push((label, vec![r])),
        }
    }
    let mut md = format!(
        "# Frame cost as the work grows\n\nAdapter: {adapter}. {width} × {height}, the mean of {MEASURED_FRAMES} frames in steady state. \
         GPU times are this adapter's; shader invocations (pipeline statistics) carry to any GPU. \
         The frame's wall time is the whole `App::update` in the headless renderer, CPU and GPU: on lavapipe it also \
         holds GPU work the timestamps miss (lavapipe writes a compute pass's first timestamp at its first barrier, so a pass whose \
         first dispatch follows other compute work times without that dispatch; the plugin's compute passes that can follow \
         other compute work dispatch an empty kernel first, so that they are timed whole).\n\n\
         | technique and scene | size range | GPU time ∝ size^k | caustics / main pass (GPU time) | caustics / main pass (fragments) | plugin CPU (main + render) | frame wall time |\n|---|---|---|---|---|---|---|\n"
    );
    let series = |cost: fn(&FrameCost) -> f64| -> Vec<Series> {
        lines.iter().map(|(label, members)| Series { label: label.clone(), points: members.iter().map(|r| (r.size as f64, cost(r))).collect() }).collect()
    };
    let gpu = series(|r| r.caustics_ms());
    let cpu = series(|r| r.cpu_main_ms + r.cpu_render_ms);
    let fragment_ratio = |r: &FrameCost| Some(r.work.caustics_fragments() / r.work.main_pass.fragments?).filter(|v| v.is_finite());
    for ((label, members), (g, c)) in lines.iter().zip(gpu.iter().zip(&cpu)) {
        let (first, last) = (members[0], members[members.len() - 1]);
        let exponent = |s: &Series| growth_exponent(&s.points).map_or("—".to_string(), |k| format!("{k:.2}"));
        let _ = writeln!(
            md,
            "| {label} | {} – {} | k = {} | {:.2} – {:.2} | {} – {} | {:.2} – {:.2} ms (k = {}) | {:.2} – {:.2} s |",
            first.size,
            last.size,
            exponent(g),
            first.caustics_ms() / first.main_pass_ms(),
            last.caustics_ms() / last.main_pass_ms(),
            figure(fragment_ratio(first), 2),
            figure(fragment_ratio(last), 2),
            first.cpu_main_ms + first.cpu_render_ms,
            last.cpu_main_ms + last.cpu_render_ms,
            exponent(c),
            first.frame_s,
            last.frame_s,
        );
    }
    let _ = writeln!(
        md,
        "\nEvery pass at each family's largest size: GPU time, shader invocations (millions) and fragments per receiver pixel \
         (receiver pixels: the composite's fragments).\n\n\
         | family | size | pass | GPU ms | vertices (M) | fragments (M) | compute (M) | fragments / receiver pixel |\n|---|---|---|---:|---:|---:|---:|---:|"
    );
    for (label, members) in &lines {
        let r = members[members.len() - 1];
        for w in r.work.passes() {
            let _ = writeln!(
                md,
                "| {label} | {} | {} | {} | {} | {} | {} | {} |",
                r.size,
                w.span,
                figure(w.ms, 3),
                millions(w.vertices),
                millions(w.fragments),
                millions(w.compute),
                figure(r.per_receiver_pixel(w.fragments), 2)
            );
        }
    }
    if !skipped.is_empty() {
        let _ = writeln!(md, "\nSkipped (`--frame-budget`):\n");
        for line in skipped {
            let _ = writeln!(md, "- {line}");
        }
    }
    write("frames.md", &md)?;
    let gpu_axes = Axes { caption: "Caustics GPU time per frame", x: "work size (vertices, triangles, photons, texels)", y: "GPU time (ms)" };
    plot_log_log(&out.join("frames-gpu.png"), &gpu_axes, &gpu.iter().collect::<Vec<_>>())?;
    let cpu_axes = Axes { caption: "Plugin CPU time per frame", x: "work size (vertices, triangles, photons, texels)", y: "CPU time (ms)" };
    plot_log_log(&out.join("frames-cpu.png"), &cpu_axes, &cpu.iter().collect::<Vec<_>>())?;
    eprintln!("wrote frames.csv, frames-passes.csv, frames.md, frames-gpu.png and frames-cpu.png to {}", out.display());
    Ok(())
}

/// A 12 m floor that shows caustics, lit by the sun from `direction`, and a camera at
/// `eye` looking at `at` with an exposure for it.
fn stage(world: &mut World, target: RenderTarget, direction: Vec3, (eye, at): (Vec3, Vec3)) {
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(12.0, 12.0));
    let sand = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 0.95, ..default() });
    world.spawn((Mesh3d(floor), MeshMaterial3d(sand), CausticReceiver));
    world.spawn((DirectionalLight { illuminance: 30_000.0, shadow_maps_enabled: true, ..default() }, Transform::default().looking_to(direction, Vec3::Y)));
    world.spawn((Camera3d::default(), Caustics::default(), target, Exposure { ev100: 12.0 }, Transform::from_translation(eye).looking_at(at, Vec3::Y)));
}

/// The ocean example's sea at `resolution`² cells, 3 m deep, with a medium for shafts.
fn ocean(world: &mut World, target: RenderTarget, resolution: u32) -> u64 {
    stage(world, target, Vec3::new(0.35, -1.0, 0.2), (Vec3::new(-4.5, 1.6, 4.5), Vec3::new(0.5, 0.4, -0.5)));
    world.spawn((
        Ocean { resolution, size: 12.0, wind_speed: 7.0, amplitude: 4e-3, ..default() },
        CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.333) },
        Transform::from_xyz(0.0, 3.0, 0.0),
    ));
    world.spawn((
        ParticipatingMedium { scattering: 0.06, absorption: Vec3::splat(0.04), asymmetry: 0.6 },
        Transform::from_xyz(0.0, 1.5, 0.0).with_scale(Vec3::new(12.0, 3.0, 12.0)),
    ));
    u64::from(resolution + 1).pow(2)
}

/// A mirror ring (the inside of a cylinder, 1 m across and 0.5 m high) of `segments`
/// around and a quarter as many rows, under a low sun: the cardioid on the floor.
fn ring(world: &mut World, target: RenderTarget, segments: u32, technique: CausticTechnique) -> u64 {
    stage(world, target, Vec3::new(1.0, -0.55, 0.0), (Vec3::new(0.0, 2.6, 1.6), Vec3::ZERO));
    let rows = (segments / 4).max(1);
    let (mut positions, mut normals, mut indices) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..=segments {
        let angle = std::f32::consts::TAU * i as f32 / segments as f32;
        let (s, c) = angle.sin_cos();
        for j in 0..=rows {
            positions.push([c, 0.5 * j as f32 / rows as f32, s]);
            normals.push([-c, 0.0, -s]);
        }
    }
    for i in 0..segments {
        for j in 0..rows {
            let (a, b) = (i * (rows + 1) + j, (i + 1) * (rows + 1) + j);
            indices.extend([a, a + 1, b, b, a + 1, b + 1]);
        }
    }
    let mesh = Mesh::new(bevy::mesh::PrimitiveTopology::TriangleList, bevy::asset::RenderAssetUsages::default())
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
        .with_inserted_indices(bevy::mesh::Indices::U32(indices));
    let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
    let chrome = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { metallic: 1.0, perceptual_roughness: 0.1, ..default() });
    world.spawn((Mesh3d(mesh), MeshMaterial3d(chrome), CausticGenerator { technique, double_sided: true, ..CausticGenerator::mirror() }, Turning));
    2 * u64::from(segments) * u64::from(rows)
}

fn ring_volumes(world: &mut World, target: RenderTarget, segments: u32) -> u64 {
    ring(world, target, segments, CausticTechnique::WarpedVolumes)
}

fn ring_maps(world: &mut World, target: RenderTarget, segments: u32) -> u64 {
    ring(world, target, segments, CausticTechnique::HierarchicalMaps)
}

/// A glass ball 1 m across, 1 m above the floor, with `technique`.
fn ball(world: &mut World, target: RenderTarget, technique: CausticTechnique) {
    stage(world, target, Vec3::new(0.2, -1.0, 0.1), (Vec3::new(0.0, 2.4, 2.6), Vec3::new(0.0, 0.2, 0.0)));
    let mesh = world.resource_mut::<Assets<Mesh>>().add(Sphere::new(0.5).mesh().ico(4).unwrap_or_else(|_| Sphere::new(0.5).mesh().build()));
    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(1.0, 1.0, 1.0, 0.2),
        alpha_mode: AlphaMode::Blend,
        ..default()
    });
    world.spawn((
        Mesh3d(mesh),
        MeshMaterial3d(glass),
        CausticGenerator { technique, ..CausticGenerator::refractive(1.5) },
        Transform::from_xyz(0.0, 1.0, 0.0),
        Turning,
    ));
}

/// Two glass balls under the caustic volumes beside a sphere of `sectors` around and
/// half as many rows that turns every frame: a shadow caster, not a generator, whose
/// every move the volumes must see.
fn moving_occluder(world: &mut World, target: RenderTarget, sectors: u32) -> u64 {
    stage(world, target, Vec3::new(0.2, -1.0, 0.1), (Vec3::new(0.0, 2.4, 3.2), Vec3::new(0.0, 0.3, 0.0)));
    let ball = world.resource_mut::<Assets<Mesh>>().add(Sphere::new(0.35).mesh().ico(3).unwrap_or_else(|_| Sphere::new(0.35).mesh().build()));
    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(1.0, 1.0, 1.0, 0.2),
        alpha_mode: AlphaMode::Blend,
        ..default()
    });
    for x in [-0.6, 0.6] {
        let generator = CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.5) };
        world.spawn((Mesh3d(ball.clone()), MeshMaterial3d(glass.clone()), generator, Transform::from_xyz(x, 1.0, 0.0)));
    }
    let caster = Sphere::new(0.3).mesh().uv(sectors, (sectors / 2).max(2));
    let triangles = caster.indices().map_or(0, |i| i.len() / 3) as u64;
    let caster = world.resource_mut::<Assets<Mesh>>().add(caster);
    let grey = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    world.spawn((Mesh3d(caster), MeshMaterial3d(grey), Transform::from_xyz(0.0, 1.7, 0.3), Turning));
    triangles
}

/// The glass ball into caustic maps from a photon buffer `side`² (maps half as fine,
/// at least 1024²).
fn ball_maps(world: &mut World, target: RenderTarget, side: u32) -> u64 {
    world.insert_resource(HierarchicalMapsSettings { photon_resolution: side, map_resolution: (side / 2).max(1024), ..default() });
    ball(world, target, CausticTechnique::HierarchicalMaps);
    u64::from(side).pow(2)
}

/// The glass ball's illumination textures on planes `side`² texels.
fn ball_textures(world: &mut World, target: RenderTarget, side: u32) -> u64 {
    world.insert_resource(IlluminationTexturesSettings { texture_size: side, ..default() });
    ball(world, target, CausticTechnique::IlluminationTextures);
    u64::from(side).pow(2)
}

/// A 4 m pool 1 m deep at `texels`² texels, its floor the receiver.
fn pool(world: &mut World, target: RenderTarget, texels: u32) -> u64 {
    stage(world, target, Vec3::new(0.3, -1.0, -0.2), (Vec3::new(0.0, 4.8, 3.4), Vec3::new(0.0, -0.8, 0.1)));
    world.spawn((
        PoolRipples { columns: texels, rows: texels, cell_size: 4.0 / texels as f32, depth: 1.0, ..default() },
        CausticGenerator { technique: CausticTechnique::Convolution, ..CausticGenerator::refractive(1.333) },
        Transform::from_xyz(0.0, 1.0, 0.0),
    ));
    u64::from(texels).pow(2)
}

/// Pebbles a frame the rain drops into every rippling pool: with the ripples' lifetime,
/// about 50 live impulses.
const PEBBLES_A_FRAME: u32 = 1;

/// A marker on a pool the bench rains on.
#[derive(Component)]
struct Raining;

/// Drops [`PEBBLES_A_FRAME`] pebbles at reproducible places into each raining pool.
fn rain(pools: Query<(&PoolRipples, &GlobalTransform), With<Raining>>, mut seed: Local<u64>, mut pebbles: MessageWriter<DropPebble>) {
    for (pool, at) in &pools {
        let extent = Vec2::new(pool.columns as f32, pool.rows as f32) * pool.cell_size;
        for _ in 0..PEBBLES_A_FRAME {
            *seed += 1;
            let mut random = caustics_core::rng::Pcg32::for_photon(7, 0, *seed);
            let (u, v) = (random.next_f32() - 0.5, random.next_f32() - 0.5);
            let position = at.translation() + Vec3::new(0.9 * u * extent.x, 0.0, 0.9 * v * extent.y);
            pebbles.write(DropPebble { position, strength: 0.01 });
        }
    }
}

/// A 4 m pool 1 m deep of `resolution`² water cells under steady rain, drawn by the
/// caustic volumes with shafts in its water, seen at a slant as a swimmer by the side
/// sees it.
fn rippled_pool(world: &mut World, target: RenderTarget, resolution: u32) -> u64 {
    stage(world, target, Vec3::new(0.3, -1.0, -0.2), (Vec3::new(0.0, 2.6, 3.6), Vec3::new(0.0, 0.0, 0.0)));
    world.spawn((
        PoolRipples { columns: resolution, rows: resolution, cell_size: 4.0 / resolution as f32, depth: 1.0, ..default() },
        CausticGenerator { technique: CausticTechnique::WarpedVolumes, ..CausticGenerator::refractive(1.333) },
        Transform::from_xyz(0.0, 1.0, 0.0),
        Raining,
    ));
    world.spawn((
        ParticipatingMedium { scattering: 0.25, absorption: Vec3::splat(0.1), asymmetry: 0.6 },
        Transform::from_xyz(0.0, 0.5, 0.0).with_scale(Vec3::new(4.0, 1.0, 4.0)),
    ));
    u64::from(resolution + 1).pow(2)
}
