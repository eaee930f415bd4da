//! `caustics render`: one scene, one method, one image.

use crate::images::{percentile_white, write_exr, write_png};
use crate::scenes::{LoadedScene, default_camera, open};
use crate::{prepare_output, progress};
use caustics_core::estimate::{IrradianceGrid, PhotonList, PhotonMap};
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use caustics_bevy::headless::HeadlessRenderer;
use caustics_core::glam::Vec3;
use caustics_core::scene::LightKind;
use caustics_core::view::render_view;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// Which algorithm computes the caustics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// The ground-truth CPU photon tracer.
    Reference,
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
    let LoadedScene { bench, camera } = open(&args.scene, cells)?;
    let Method::Reference = args.method;
    let tracer = PhotonTracer::new(&bench.scene).map_err(|e| format!("{}: {e}", args.scene))?;
    let settings = TraceSettings { photons_per_light: args.photons, seed: args.seed, ..Default::default() };
    let out = prepare_output(&args.out)?;

    let (pixels, w, h) = if args.irradiance_plane {
        let mut grid = IrradianceGrid::new(bench.region);
        tracer.trace(&settings, &mut grid, &progress("tracing"));
        (grid.irradiance(), width, width)
    } else {
        let mut photons = PhotonList::default();
        tracer.trace(&settings, &mut photons, &progress("tracing"));
        let radius = kernel_radius(&photons, &bench.region);
        let map = PhotonMap::new(photons.0, radius);
        let camera = camera.unwrap_or_else(|| default_camera(&bench, width, height));
        let camera = caustics_core::view::PinholeCamera { width, height, ..camera };
        eprintln!("shading {width}×{height} (kernel radius {radius:.4} m)");
        match args.renderer {
            Renderer::Cpu => (render_view(&tracer, &bench.scene, &camera, &map).radiance, width, height),
            Renderer::Bevy => {
                let r = &bench.region;
                let center = r.origin + 0.5 * (r.edge_u + r.edge_v);
                (render_with_bevy(&tracer, center, &bench.scene, &camera, &map)?, width, height)
            }
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

/// The view drawn by Bevy, with the reference caustics injected into the plugin.
fn render_with_bevy(
    tracer: &PhotonTracer,
    region_center: Vec3,
    scene: &caustics_core::scene::Scene,
    camera: &caustics_core::view::PinholeCamera,
    map: &PhotonMap,
) -> Result<Vec<Vec3>, String> {
    use caustics_bevy::reference::{spawn_scene, view_irradiance};
    let irradiance = view_irradiance(tracer, map, camera);
    // Expose for the lights' own irradiance where the caustic lands.
    let typical: f32 = scene
        .lights
        .iter()
        .map(|light| match light.kind {
            LightKind::Directional { irradiance, .. } => irradiance,
            LightKind::Point { position, intensity } | LightKind::Spot { position, intensity, .. } => {
                intensity / (position - region_center).length_squared().max(1e-6)
            }
        })
        .sum();
    let mut renderer = HeadlessRenderer::new(camera.width, camera.height).map_err(|e| e.to_string())?;
    let target = renderer.render_target();
    spawn_scene(renderer.world_mut(), scene, camera, target, Some(&irradiance), typical);
    let image = renderer.render(8).map_err(|e| e.to_string())?;
    Ok(image.pixels.iter().map(|p| Vec3::new(p.x, p.y, p.z)).collect())
}

/// A kernel radius that gathers about 64 photons where the caustic is average.
fn kernel_radius(photons: &PhotonList, region: &caustics_core::estimate::GridRegion) -> f32 {
    let in_region = photons.0.iter().filter(|p| region.cell_of(p.position, 1e-3).is_some()).count().max(1);
    let area = region.edge_u.cross(region.edge_v).length();
    (64.0 * area / (std::f32::consts::PI * in_region as f32)).sqrt()
}

