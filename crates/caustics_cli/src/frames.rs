//! `caustics bench --frames`: what each technique costs per frame as its work grows.
//!
//! Every technique renders a family of scenes of growing size in the headless
//! renderer at 1280 × 720 (an animated ocean and a mirror ring for the caustic volumes,
//! the ring and a glass ball's photon buffer for the caustic maps, the pool's texels for
//! convolution, the virtual planes' texels for illumination textures). Every generator
//! moves (the ocean's waves, the pool's ripples; the ring and the ball turn a little
//! each frame, [`Turning`]), so that each technique redoes its per-frame work, as for
//! a game's moving objects: a static scene's maps, volumes and textures are made once. After the
//! technique's first pass has run and its GPU times arrived, [`MEASURED_FRAMES`] frames
//! record the GPU time of the caustics passes (timestamp queries, by span), Bevy's own
//! main passes of the same view as the yardstick, and the plugin's CPU time in the
//! main and render worlds (`CausticsCpuTime`), and how often the caustic volumes'
//! sources were gathered on the CPU in those frames (`CausticVolumes::gathered`: none
//! for the ocean, whose waves move on the GPU). Writes `frames.csv`, `frames.md` (each
//! line's growth exponent, the slope of log cost against log size) and the log–log
//! plots `frames-gpu.png` and `frames-cpu.png`, one line per technique and scene.

use crate::plot::{Axes, Series, plot_log_log};
use bevy::camera::{Exposure, RenderTarget};
use bevy::prelude::*;
use caustics_bevy::headless::{HeadlessRenderer, is_caustic_span};
use caustics_bevy::prelude::*;
use caustics_bevy::warped_volumes::CausticVolumes;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// The frames averaged at each size, once the technique runs in steady state.
const MEASURED_FRAMES: usize = 3;
/// Updates to wait at most for the technique's first pass (pipelines compile, builds
/// finish on other threads) before a size counts as failed.
const MAX_WARM_UP: usize = 240;
const WIDTH: u32 = 1280;
const HEIGHT: u32 = 720;

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

const FAMILIES: [Family; 6] = [
    Family { technique: "volumes", scene: "ocean", unit: "water vertices", sizes: &[32, 64, 128, 256, 512], spawn: ocean, pass: "volumes" },
    Family { technique: "volumes", scene: "ring", unit: "mirror triangles", sizes: &RING_SIZES, spawn: ring_volumes, pass: "volumes" },
    Family { technique: "maps", scene: "ring", unit: "mirror triangles", sizes: &RING_SIZES, spawn: ring_maps, pass: "caustic map projection" },
    Family { technique: "maps", scene: "glass ball", unit: "photons", sizes: &[256, 512, 1024, 2048, 4096], spawn: ball_maps, pass: "caustic map projection" },
    Family { technique: "convolution", scene: "pool", unit: "pool texels", sizes: &[128, 256, 512, 1024], spawn: pool, pass: "pool floor" },
    Family { technique: "textures", scene: "glass ball", unit: "plane texels", sizes: &[128, 256, 512, 1024], spawn: ball_textures, pass: "illumination textures projection" },
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

/// One measured frame: GPU time by span (ms), the plugin's CPU time in the main and
/// render worlds (ms), wall time (s).
struct Frame {
    spans: Vec<(String, f64)>,
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
    /// The caustics passes' GPU time (ms), and by span.
    caustics_ms: f64,
    spans: Vec<(String, f64)>,
    /// Bevy's main passes of the same view (ms).
    main_pass_ms: f64,
    /// The plugin's CPU time (ms), main and render world.
    cpu_main_ms: f64,
    cpu_render_ms: f64,
    /// The frame's wall time in the headless renderer (s).
    frame_s: f64,
    /// The caustic volumes' CPU gatherings in the measured frames.
    volume_gathers: u64,
}

/// Runs every family of the techniques `runs` accepts (the first `sizes` sizes of
/// each when given) and writes the outputs to `out`. A family stops growing once a frame took longer than
/// `budget_s` of wall time: the larger sizes are listed as skipped.
pub fn run(out: &Path, runs: impl Fn(&str) -> bool, sizes: Option<usize>, budget_s: f64) -> Result<(), String> {
    let adapter = caustics_bevy::headless::probe_adapter().map_err(|e| e.to_string())?;
    if adapter.timestamps.is_empty() {
        return Err(format!("{} has no timestamp queries: the frame bench needs them", adapter.name));
    }
    let mut rows: Vec<FrameCost> = Vec::new();
    let mut skipped = Vec::new();
    for family in FAMILIES.iter().filter(|f| runs(f.technique)) {
        let first = rows.len();
        for &parameter in family.sizes.iter().take(sizes.unwrap_or(usize::MAX)) {
            if let Some(last) = rows[first..].last().filter(|r| r.frame_s > budget_s) {
                skipped.push(format!(
                    "{} on the {} at parameter {parameter}: a frame at {} {} took {:.0} s, past the {budget_s} s budget",
                    family.technique, family.scene, last.size, family.unit, last.frame_s
                ));
                eprintln!("skipped: {}", skipped[skipped.len() - 1]);
                continue;
            }
            let start = Instant::now();
            let row = measure(family, parameter)?;
            eprintln!(
                "{:>11} {:>10} {:>9} {}: caustics {:9.2} ms, main pass {:8.2} ms (GPU); plugin CPU {:.3} + {:.3} ms, {} volume gatherings; {:.0} s",
                family.technique,
                family.scene,
                row.size,
                family.unit,
                row.caustics_ms,
                row.main_pass_ms,
                row.cpu_main_ms,
                row.cpu_render_ms,
                row.volume_gathers,
                start.elapsed().as_secs_f64()
            );
            rows.push(row);
        }
    }
    write_outputs(out, &adapter.name, &rows, &skipped)
}

/// Renders one family's scene at one size until the technique runs, then averages
/// [`MEASURED_FRAMES`] frames.
fn measure(family: &Family, parameter: u32) -> Result<FrameCost, String> {
    let mut renderer = HeadlessRenderer::timed(WIDTH, HEIGHT).map_err(|e| e.to_string())?;
    let target = renderer.render_target();
    renderer.app.add_systems(Update, turn);
    let size = (family.spawn)(renderer.world_mut(), target, parameter);
    let failed = |what: &str| format!("{} on the {} at {size} {}: {what}", family.technique, family.scene, family.unit);
    // Warm up: the first pass, then two frames for its GPU times to arrive.
    let mut left = None;
    for _ in 0..MAX_WARM_UP {
        renderer.app.update();
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
        let spans = renderer.gpu_pass_times();
        let (cpu_main, cpu_render) = renderer.plugin_cpu_times().ok_or_else(|| failed("no CPU times"))?;
        frames.push(Frame { spans, cpu_main, cpu_render, seconds });
    }
    let mean = |f: &dyn Fn(&Frame) -> f64| frames.iter().map(f).sum::<f64>() / frames.len() as f64;
    let caustics_ms = mean(&|f| f.spans.iter().filter(|(s, _)| is_caustic_span(s)).map(|(_, ms)| ms).sum());
    let main_pass_ms = mean(&|f| f.spans.iter().filter(|(s, _)| s.starts_with("main_")).map(|(_, ms)| ms).sum());
    if main_pass_ms == 0.0 {
        return Err(failed("no GPU times arrived"));
    }
    let mut names: Vec<String> = frames.iter().flat_map(|f| f.spans.iter().map(|(s, _)| s.clone())).filter(|s| is_caustic_span(s)).collect();
    names.sort();
    names.dedup();
    let spans = names
        .into_iter()
        .map(|name| {
            let ms = mean(&|f| f.spans.iter().filter(|(s, _)| *s == name).map(|(_, ms)| ms).sum());
            (name, ms)
        })
        .collect();
    Ok(FrameCost {
        technique: family.technique,
        scene: family.scene,
        unit: family.unit,
        size,
        caustics_ms,
        spans,
        main_pass_ms,
        cpu_main_ms: mean(&|f| f.cpu_main),
        cpu_render_ms: mean(&|f| f.cpu_render),
        frame_s: mean(&|f| f.seconds),
        volume_gathers: gathered(&mut renderer) - gathered_before,
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

fn write_outputs(out: &Path, adapter: &str, rows: &[FrameCost], skipped: &[String]) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let mut csv = String::from(
        "adapter,technique,scene,unit,size,caustics_gpu_ms,main_pass_gpu_ms,caustics_over_main_pass,plugin_cpu_main_ms,plugin_cpu_render_ms,cpu_volume_gathers,frame_wall_s,spans\n",
    );
    for r in rows {
        let spans: Vec<String> = r.spans.iter().map(|(s, ms)| format!("{s}={ms:.3}")).collect();
        let _ = writeln!(
            csv,
            "\"{adapter}\",{},{},{},{},{:.3},{:.3},{:.3},{:.4},{:.4},{},{:.2},{}",
            r.technique,
            r.scene,
            r.unit,
            r.size,
            r.caustics_ms,
            r.main_pass_ms,
            r.caustics_ms / r.main_pass_ms,
            r.cpu_main_ms,
            r.cpu_render_ms,
            r.volume_gathers,
            r.frame_s,
            spans.join(";")
        );
    }
    let write = |name: &str, text: &str| std::fs::write(out.join(name), text).map_err(|e| format!("cannot write {name}: {e}"));
    write("frames.csv", &csv)?;
    let mut lines: Vec<(String, Vec<&FrameCost>)> = Vec::new();
    for r in rows {
        let label = format!("{} on the {} ({})", r.technique, r.scene, r.unit);
        match lines.iter_mut().find(|(l, _)| *l == label) {
            Some((_, members)) => members.push(r),
            None => lines.push((label, vec![r])),
        }
    }
    let mut md = format!(
        "# Frame cost as the work grows\n\nAdapter: {adapter}. {WIDTH} × {HEIGHT}, the mean of {MEASURED_FRAMES} frames in steady state.\n\n\
         | technique and scene | size range | GPU time ∝ size^k | caustics / main pass | plugin CPU (main + render) |\n|---|---|---|---|---|\n"
    );
    let series = |cost: fn(&FrameCost) -> f64| -> Vec<Series> {
        lines.iter().map(|(label, members)| Series { label: label.clone(), points: members.iter().map(|r| (r.size as f64, cost(r))).collect() }).collect()
    };
    let gpu = series(|r| r.caustics_ms);
    let cpu = series(|r| r.cpu_main_ms + r.cpu_render_ms);
    for ((label, members), (g, c)) in lines.iter().zip(gpu.iter().zip(&cpu)) {
        let (first, last) = (members[0], members[members.len() - 1]);
        let exponent = |s: &Series| growth_exponent(&s.points).map_or("—".to_string(), |k| format!("{k:.2}"));
        let _ = writeln!(
            md,
            "| {label} | {} – {} | k = {} | {:.2} – {:.2} | {:.2} – {:.2} ms (k = {}) |",
            first.size,
            last.size,
            exponent(g),
            first.caustics_ms / first.main_pass_ms,
            last.caustics_ms / last.main_pass_ms,
            first.cpu_main_ms + first.cpu_render_ms,
            last.cpu_main_ms + last.cpu_render_ms,
            exponent(c),
        );
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
    eprintln!("wrote frames.csv, frames.md, frames-gpu.png and frames-cpu.png to {}", out.display());
    Ok(())
}

/// A 12 m floor that shows caustics, lit by the sun from `direction`, and a camera at
/// `eye` looking at `at` with an exposure for it.
fn stage(world: &mut World, target: RenderTarget, direction: Vec3, (eye, at): (Vec3, Vec3)) {
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(12.0, 12.0));
    let sand = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { perceptual_roughness: 0.95, ..default() });
    world.spawn((Mesh3d(floor), MeshMaterial3d(sand), CausticReceiver));
    world.spawn((
        DirectionalLight { illuminance: 30_000.0, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(direction, Vec3::Y),
    ));
    world.spawn((Camera3d::default(), CausticsSettings::default(), target, Exposure { ev100: 12.0 }, Transform::from_translation(eye).looking_at(at, Vec3::Y)));
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
        ParticipatingMedium { scattering: 0.06, absorption: 0.04, asymmetry: 0.6 },
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
    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { base_color: Color::srgba(1.0, 1.0, 1.0, 0.2), alpha_mode: AlphaMode::Blend, ..default() });
    world.spawn((Mesh3d(mesh), MeshMaterial3d(glass), CausticGenerator { technique, ..CausticGenerator::refractive(1.5) }, Transform::from_xyz(0.0, 1.0, 0.0), Turning));
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
