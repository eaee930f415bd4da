//! `caustics render`: one scene, one method, one image.

use crate::images::{percentile_white, write_exr, write_png};
use crate::scenes::{LoadedScene, default_camera, open};
use crate::{prepare_output, progress};
use caustics_core::estimate::{IrradianceGrid, PhotonList, PhotonMap};
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use caustics_core::view::render_view;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// Which algorithm computes the caustics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// The ground-truth CPU photon tracer.
    Reference,
}

#[derive(Args)]
pub struct RenderArgs {
    /// A .gltf/.glb file, a .json scene description, or a built-in scene: pool, sphere, ring.
    pub scene: String,
    #[arg(long, value_enum, default_value_t = Method::Reference)]
    pub method: Method,
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
        (render_view(&tracer, &bench.scene, &camera, &map).radiance, width, height)
    };
    write_png(&out, w, h, &pixels, 2.5 * percentile_white(&pixels, 0.5))?;
    eprintln!("wrote {}", out.display());
    if let Some(exr) = &args.exr {
        let exr = prepare_output(exr)?;
        write_exr(&exr, w, h, &pixels)?;
        eprintln!("wrote {}", exr.display());
    }
    Ok(())
}

/// A kernel radius that gathers about 64 photons where the caustic is average.
fn kernel_radius(photons: &PhotonList, region: &caustics_core::estimate::GridRegion) -> f32 {
    let in_region = photons.0.iter().filter(|p| region.cell_of(p.position, 1e-3).is_some()).count().max(1);
    let area = region.edge_u.cross(region.edge_v).length();
    (64.0 * area / (std::f32::consts::PI * in_region as f32)).sqrt()
}

