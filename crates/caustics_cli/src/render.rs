//! `caustics render`: one scene, one method, one image.

use crate::bench::{Auto, BenchMethod, CONVOLUTION_GRIDS, CONVOLUTION_METHODS, SUPERSAMPLE, volumes_irradiance};
use crate::images::{percentile_white, write_exr, write_png};
use crate::scenes::{LoadedScene, default_camera, open};
use crate::{prepare_output, progress};
use caustics_bevy::CausticQuality;
use caustics_bevy::CausticTechnique;
use caustics_bevy::headless::HeadlessRenderer;
use caustics_bevy::hierarchical_maps::HierarchicalMapsSettings;
use caustics_bevy::reference::{exposure_for, spawn_scene_content};
use caustics_bevy::warped_volumes::{VolumeIntensity, WarpedVolumesSettings};
use caustics_core::estimate::GridRegion;
use caustics_core::estimate::{IrradianceGrid, PhotonList, PhotonMap};
use caustics_core::glam::Vec3;
use caustics_core::scene::LightKind;
use caustics_core::scenes::BenchScene;
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use caustics_core::view::render_view;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// Which algorithm computes the caustics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// The ground-truth CPU photon tracer.
    Reference,
    /// Warped caustic volumes, energy-conserving interpolation (the plugin's default).
    Volumes,
    /// Warped caustic volumes, constant intensity per volume.
    VolumesConstant,
    /// Warped caustic volumes, the paper's interpolated intensity (§3.4).
    VolumesPaper,
    /// Convolution caustics (a heightfield pool only).
    Convolution,
    /// Hierarchical caustic maps as the plugin draws them by default: the full method
    /// (clustering, variable splats) with photons traced through the generators.
    Maps,
    /// Hierarchical caustic maps, the paper's full method: photons through the
    /// image-space pair of front and back maps.
    MapsImageSpace,
    /// Hierarchical caustic maps, the flat gather with fixed splats.
    MapsFlat,
    /// Illumination textures (a closed refractor only).
    IlluminationTextures,
    /// Each generator by the technique the plugin's `Auto` picks for it.
    Auto,
}

impl Method {
    /// The technique a generator asks for, `None` for the reference.
    fn technique(self) -> Option<CausticTechnique> {
        Some(match self {
            Method::Reference => return None,
            Method::Volumes | Method::VolumesConstant | Method::VolumesPaper => CausticTechnique::WarpedVolumes,
            Method::Convolution => CausticTechnique::Convolution,
            Method::Maps | Method::MapsImageSpace | Method::MapsFlat => CausticTechnique::HierarchicalMaps,
            Method::IlluminationTextures => CausticTechnique::IlluminationTextures,
            Method::Auto => CausticTechnique::Auto,
        })
    }

    /// The volumes' settings (intensity mode) and the caustic maps' (gather, splats).
    fn settings(self) -> (WarpedVolumesSettings, HierarchicalMapsSettings) {
        let intensity = match self {
            Method::VolumesConstant => VolumeIntensity::Constant,
            Method::VolumesPaper => VolumeIntensity::Interpolated,
            _ => VolumeIntensity::Conserving,
        };
        let maps = match self {
            Method::MapsFlat => HierarchicalMapsSettings::FLAT,
            Method::MapsImageSpace => HierarchicalMapsSettings::FULL,
            _ => HierarchicalMapsSettings::default(),
        };
        (WarpedVolumesSettings { intensity, ..Default::default() }, maps)
    }
}

/// What draws the view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Renderer {
    /// The CPU: direct light with shadows, caustics, and Whitted paths through the generators.
    Cpu,
    /// Bevy (headless, any wgpu adapter): its PBR lighting, and the caustics through the
    /// plugin's injection and composite.
    Bevy,
}

#[derive(Args)]
pub struct RenderArgs {
    /// A .gltf/.glb file, a .json scene description, or a built-in scene: pool, sphere, ring.
    pub scene: String,
    #[arg(long, value_enum, default_value_t = Method::Reference)]
    pub method: Method,
    /// What draws a camera view (ignored with --irradiance-plane).
    #[arg(long, value_enum, default_value_t = Renderer::Cpu)]
    pub renderer: Renderer,
    /// PNG to write (tone-mapped, sRGB).
    #[arg(long, default_value = "target/caustics/render.png")]
    pub out: PathBuf,
    /// Also write the linear float image as OpenEXR.
    #[arg(long)]
    pub exr: Option<PathBuf>,
    /// Image size, WIDTHxHEIGHT (the irradiance plane is square: WIDTH cells).
    #[arg(long, default_value = "640x480", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Write the caustic irradiance (light units per m²) of the scene's horizontal
    /// receiver region seen straight down, instead of a camera view.
    #[arg(long)]
    pub irradiance_plane: bool,
    /// Photons per light.
    #[arg(long, default_value_t = 1 << 22)]
    pub photons: u64,
    /// Seed of the photon streams.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// With --irradiance-plane: the method's CPU twin instead of its GPU passes.
    #[arg(long)]
    pub twin: bool,
    /// With --irradiance-plane: the square measured, `X0,Z0,SIZE[,Y]` (metres), for a
    /// scene of one's own; by default the scene's receiver region.
    #[arg(long, value_parser = parse_region, allow_hyphen_values = true)]
    pub region: Option<(f32, f32, f32, Option<f32>)>,
}

fn parse_region(s: &str) -> Result<(f32, f32, f32, Option<f32>), String> {
    let values: Vec<f32> =
        s.split(',').map(|v| v.trim().parse::<f32>().map_err(|_| format!("region {s:?}: {v:?} is not a number"))).collect::<Result<_, _>>()?;
    match values[..] {
        [x0, z0, size] | [x0, z0, size, _] if size > 0.0 && values.iter().all(|v| v.is_finite()) => Ok((x0, z0, size, values.get(3).copied())),
        _ => Err(format!("region {s:?} is not X0,Z0,SIZE[,Y] with a positive SIZE")),
    }
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("size {s:?} is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| v.trim().parse::<u32>().ok().filter(|&n| (1..=16384).contains(&n));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("size {s:?}: width and height must be whole numbers from 1 to 16384")),
    }
}

pub fn run(args: RenderArgs) -> Result<(), String> {
    let (width, height) = args.size;
    let cells = if args.irradiance_plane { width as usize } else { 128 };
    let LoadedScene { mut bench, camera } = open(&args.scene, cells)?;
    if let Some((x0, z0, size, y)) = args.region {
        bench.region = GridRegion::horizontal(x0, z0, y.unwrap_or(bench.region.origin.y), size, cells);
    }
    let tracer = PhotonTracer::new(&bench.scene).map_err(|e| format!("{}: {e}", args.scene))?;
    let settings = TraceSettings { photons_per_light: args.photons, seed: args.seed, ..Default::default() };
    let out = prepare_output(&args.out)?;
    let method = args.method;

    let (pixels, w, h) = if args.irradiance_plane {
        let pixels = match (method, args.twin) {
            (Method::Reference, _) => {
                let mut grid = IrradianceGrid::new(bench.region);
                tracer.trace(&settings, &mut grid, &progress("tracing"));
                grid.irradiance()
            }
            (_, true) => twin_plane(method, &args.scene, &bench)?.into_iter().map(Vec3::splat).collect(),
            (_, false) => gpu_run(method, &bench, None, None)?.irradiance,
        };
        (pixels, width, width)
    } else {
        let camera = camera.unwrap_or_else(|| default_camera(&bench, width, height));
        let camera = caustics_core::view::PinholeCamera { width, height, ..camera };
        match (args.renderer, method) {
            (Renderer::Cpu, Method::Reference) => {
                let map = photon_map(&tracer, &settings, &bench.region);
                eprintln!("shading {width}×{height} (kernel radius {:.4} m)", map.radius());
                (render_view(&tracer, &bench.scene, &camera, &map).radiance, width, height)
            }
            (Renderer::Cpu, _) => {
                return Err(format!("the CPU renderer draws the reference only: --method {method:?} needs --renderer bevy or --irradiance-plane"));
            }
            (Renderer::Bevy, _) => (render_with_bevy(&tracer, &settings, &bench, &camera, method)?, width, height),
        }
    };
    // Bevy's frame is already exposed (mid grey at 0.18); the CPU's is in light units.
    let white = match (args.renderer, args.irradiance_plane) {
        (Renderer::Bevy, false) => 1.0,
        _ => 2.5 * percentile_white(&pixels, 0.5),
    };
    write_png(&out, w, h, &pixels, white)?;
    eprintln!("wrote {}", out.display());
    if let Some(exr) = &args.exr {
        let exr = prepare_output(exr)?;
        write_exr(&exr, w, h, &pixels)?;
        eprintln!("wrote {}", exr.display());
    }
    Ok(())
}

/// The tracer's photons as a photon map for shading a view.
fn photon_map(tracer: &PhotonTracer, settings: &TraceSettings, region: &GridRegion) -> PhotonMap {
    let mut photons = PhotonList::default();
    tracer.trace(settings, &mut photons, &progress("tracing"));
    let radius = kernel_radius(&photons, region);
    PhotonMap::new(photons.0, radius)
}

/// A method's caustic irradiance per cell of the region by its CPU twin (the bench's).
fn twin_plane(method: Method, name: &str, bench: &BenchScene) -> Result<Vec<f32>, String> {
    let (image, _) = match method {
        Method::Reference => return Err("the reference is traced, not twinned".into()),
        Method::Volumes | Method::VolumesConstant | Method::VolumesPaper => {
            volumes_irradiance(&bench.scene, &bench.region, method.settings().0.core().intensity, SUPERSAMPLE)
        }
        Method::Convolution => {
            // The finest grid whose texel centres fall on the water's vertices.
            let mut run = Err(String::new());
            for grid in (0..CONVOLUTION_GRIDS.len() as u64).rev() {
                run = CONVOLUTION_METHODS[0].run(name, bench, grid, SUPERSAMPLE);
                if run.is_ok() {
                    break;
                }
            }
            run.map_err(|e| format!("--method convolution does not apply to {name}: {e}"))?
        }
        // The plugin's settings of the method, on its CPU twin.
        Method::Maps | Method::MapsImageSpace | Method::MapsFlat => crate::hierarchical::irradiance(bench, &method.settings().1.core(), SUPERSAMPLE)?,
        Method::IlluminationTextures => crate::illumination::irradiance(bench, &Default::default(), SUPERSAMPLE)?,
        Method::Auto => Auto.run(name, bench, 2, SUPERSAMPLE)?,
    };
    Ok(image)
}

/// Metres between the region and the top-down camera: it sees the receiver region
/// itself, not what stands over it (a roof, the water, a ball), as the tracer bins it.
const CAMERA_LIFT: f32 = 0.01;

/// What the plugin's GPU passes made of a method on a scene.
pub struct GpuRun {
    /// Caustic irradiance per cell of the region.
    pub irradiance: Vec<Vec3>,
    /// The adapter that ran it.
    pub adapter: String,
    /// GPU milliseconds, from timestamp queries, in the frame where the technique's
    /// passes cost most (the frame that made its maps or volumes): its own passes
    /// (spans `caustics/*`, `caustic_maps/*`, `illumination_textures/*`) and every timed pass of that frame,
    /// Bevy's included. `None` where the adapter has no timestamp queries.
    pub times: Option<GpuTimes>,
}

#[derive(Clone, Copy, Debug)]
pub struct GpuTimes {
    pub technique_ms: f64,
    pub timed_passes_ms: f64,
}

/// Frames to render after the technique's passes first ran: its GPU times arrive a
/// frame or two late.
const TIMING_FRAMES: u32 = 4;

/// A method's caustic irradiance on the region by the plugin's GPU passes in the
/// headless renderer, and their GPU time: the scene spawned with every generator
/// asking for the method's technique (`maps`: the caustic maps' photon buffer and map
/// sides, the plugin's when not given; `quality`: a preset over every technique's
/// settings, applied after them), a
/// top-down orthographic view of the region [`SUPERSAMPLE`]² pixels per cell, its
/// caustic irradiance buffer read back with the exposure divided out and averaged per
/// cell (the estimator of the twins and the tracer: cell means).
pub fn gpu_run(method: Method, bench: &BenchScene, maps: Option<(u32, u32)>, quality: Option<CausticQuality>) -> Result<GpuRun, String> {
    use bevy::core_pipeline::tonemapping::Tonemapping;
    use bevy::prelude::{Camera3d, OrthographicProjection, Projection, Transform};
    let technique = method.technique().ok_or("the reference is traced on the CPU")?;
    let region = &bench.region;
    let cells = region.nu;
    let pixels = (cells * SUPERSAMPLE) as u32;
    let mut renderer = HeadlessRenderer::timed(pixels, pixels).map_err(|e| e.to_string())?;
    let target = renderer.render_target();
    let world = renderer.world_mut();
    let (volumes, mut maps_settings) = method.settings();
    if let Some((photons, map)) = maps {
        (maps_settings.photon_resolution, maps_settings.map_resolution) = (photons, map);
    }
    world.insert_resource(volumes);
    world.insert_resource(maps_settings);
    if let Some(quality) = quality {
        world.insert_resource(quality);
    }
    spawn_scene_content(world, &bench.scene, bench.scene.receivers.len(), Some(technique));
    let size = region.edge_u.length();
    let centre = region.origin + 0.5 * (region.edge_u + region.edge_v);
    let camera = world
        .spawn((
            Camera3d::default(),
            target,
            caustics_bevy::Caustics::default(),
            Tonemapping::None,
            exposure_for(typical_irradiance(&bench.scene, centre)),
            Projection::from(OrthographicProjection { scale: size / pixels as f32, ..OrthographicProjection::default_3d() }),
            Transform::from_translation(to_bevy(centre) + CAMERA_LIFT * bevy::math::Vec3::Y).looking_at(to_bevy(centre), bevy::math::Vec3::NEG_Z),
        ))
        .id();
    // Frames until every technique has built its work (the volumes build
    // asynchronously), then a few for the GPU times to arrive.
    let mut times: Option<GpuTimes> = None;
    let mut left = None;
    for _ in 0..48 {
        renderer.app.update();
        let passes = renderer.gpu_pass_work();
        let technique_ms: f64 = passes.iter().filter(|w| w.is_caustic()).filter_map(|w| w.ms).sum();
        if passes.iter().any(|w| w.ms.is_some()) && times.is_none_or(|t| technique_ms > t.technique_ms) {
            times = Some(GpuTimes { technique_ms, timed_passes_ms: passes.iter().filter_map(|w| w.ms).sum() });
        }
        let report = renderer.pass_report();
        if left.is_none() && ["volumes", "caustic map projection", "pool floor", "illumination textures projection"].iter().any(|pass| report.views(pass) > 0) {
            left = Some(TIMING_FRAMES);
        }
        match &mut left {
            Some(0) => break,
            Some(n) => *n -= 1,
            None => {}
        }
    }
    let report = renderer.pass_report();
    if let Some((entity, choice)) = report.generators.iter().find(|(_, c)| technique != CausticTechnique::Auto && technique != c.technique()) {
        return Err(format!("--method {method:?} does not apply to generator {entity}: {choice}"));
    }
    for (entity, choice) in &report.generators {
        eprintln!("generator {entity}: {choice}");
    }
    let irradiance = renderer.caustic_irradiance(camera).map_err(|e| e.to_string())?;
    let cell_mean = |row: usize, column: usize| {
        let samples = (0..SUPERSAMPLE * SUPERSAMPLE).map(|k| {
            let (y, x) = (row * SUPERSAMPLE + k / SUPERSAMPLE, column * SUPERSAMPLE + k % SUPERSAMPLE);
            irradiance[y * pixels as usize + x]
        });
        Vec3::from_array((samples.sum::<bevy::math::Vec3>() / (SUPERSAMPLE * SUPERSAMPLE) as f32).to_array())
    };
    let irradiance = (0..cells * cells).map(|i| cell_mean(i / cells, i % cells)).collect();
    let adapter = renderer.adapter.name.clone();
    match times {
        Some(t) => eprintln!("GPU ({adapter}): {:.3} ms in the technique's passes, {:.3} ms in all timed passes", t.technique_ms, t.timed_passes_ms),
        None => eprintln!("GPU ({adapter}): no timestamp queries, no GPU times"),
    }
    Ok(GpuRun { irradiance, adapter, times })
}

/// The lights' own irradiance at `at` (normal incidence): what to expose for.
pub fn typical_irradiance(scene: &caustics_core::scene::Scene, at: Vec3) -> f32 {
    scene
        .lights
        .iter()
        .map(|light| match light.kind {
            LightKind::Directional { irradiance, .. } => irradiance,
            LightKind::Point { position, intensity } | LightKind::Spot { position, intensity, .. } => intensity / (position - at).length_squared().max(1e-6),
        })
        .sum()
}

fn to_bevy(v: Vec3) -> bevy::math::Vec3 {
    bevy::math::Vec3::from_array(v.to_array())
}

/// The view drawn by Bevy: the reference caustics injected into the plugin, or the
/// plugin's own technique live.
fn render_with_bevy(
    tracer: &PhotonTracer,
    settings: &TraceSettings,
    bench: &BenchScene,
    camera: &caustics_core::view::PinholeCamera,
    method: Method,
) -> Result<Vec<Vec3>, String> {
    use caustics_bevy::reference::{spawn_scene, view_irradiance};
    let r = &bench.region;
    let typical = typical_irradiance(&bench.scene, r.origin + 0.5 * (r.edge_u + r.edge_v));
    let mut renderer = HeadlessRenderer::new(camera.width, camera.height).map_err(|e| e.to_string())?;
    let target = renderer.render_target();
    let image = match method.technique() {
        None => {
            let map = photon_map(tracer, settings, r);
            eprintln!("shading {}×{} (kernel radius {:.4} m)", camera.width, camera.height, map.radius());
            let irradiance = view_irradiance(tracer, &map, camera);
            spawn_scene(renderer.world_mut(), (&bench.scene, bench.scene.receivers.len()), camera, target, Some(&irradiance), typical);
            renderer.render(8)
        }
        Some(technique) => {
            let world = renderer.world_mut();
            let (volumes, maps) = method.settings();
            world.insert_resource(volumes);
            world.insert_resource(maps);
            spawn_scene(world, (&bench.scene, bench.scene.receivers.len()), camera, target, None, typical);
            let mut generators = world.query::<&mut caustics_bevy::CausticGenerator>();
            generators.iter_mut(world).for_each(|mut g| g.technique = technique);
            renderer.render(24)
        }
    }
    .map_err(|e| e.to_string())?;
    Ok(image.pixels.iter().map(|p| Vec3::new(p.x, p.y, p.z)).collect())
}

/// A kernel radius that gathers about 64 photons where the caustic is average.
fn kernel_radius(photons: &PhotonList, region: &caustics_core::estimate::GridRegion) -> f32 {
    let in_region = photons.0.iter().filter(|p| region.cell_of(p.position, 1e-3).is_some()).count().max(1);
    let area = region.edge_u.cross(region.edge_v).length();
    (64.0 * area / (std::f32::consts::PI * in_region as f32)).sqrt()
}
