//! Illumination textures in `caustics bench`: the CPU twin at 1 to 16 planes and 128²
//! to 1024² textures on the `sphere` (a flat floor) and on `ball_bunny` (a glass ball
//! over the Stanford bunny: a curved receiver), against the tracer, beside the caustic
//! maps on the same points; the light transport table's size and build time; the GPU
//! pass at the default settings where the scene's receiver is flat.

use crate::bench::{Errors, Measurement, gpu_columns};
use crate::progress;
use crate::render::Method;
use caustics_core::estimate::{GridRegion, IrradianceGrid, surface_samples};
use caustics_core::glam::{Affine3A, Vec3};
use caustics_core::illumination_textures::{Cosine, DirectionGrid, IlluminationSettings, IlluminationTextures, LightTransportTable, TransportBuild};
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::Scene;
use caustics_core::scenes::{BenchScene, glass_ball_over_bunny, glass_sphere};
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use std::fmt::Write as _;
use std::time::Instant;

/// Each generator's light transport table (16² directions a vertex), and the seconds
/// the tables took.
fn tables(scene: &Scene, label: &str) -> Result<(Vec<LightTransportTable>, f64), String> {
    let clock = Instant::now();
    let tables = scene
        .generators
        .iter()
        .map(|g| {
            let SpecularInteraction::Refract { ior, .. } = g.interaction else {
                return Err("illumination textures: a generator is a mirror".to_string());
            };
            let build = TransportBuild { ior, grid: DirectionGrid::default() };
            LightTransportTable::build(&g.mesh, build, &progress(label)).map_err(|e| format!("illumination textures: {e}"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((tables, clock.elapsed().as_secs_f64()))
}

/// The caustic irradiance of every generator and light at `points` of normals
/// `normals` (mean of RGB), by the CPU twin: frames, drawing and lookups.
fn at_points(scene: &Scene, tables: &[LightTransportTable], settings: &IlluminationSettings, points: &[(Vec3, Vec3)]) -> Vec<f32> {
    let mut e = vec![0.0f32; points.len()];
    for (generator, table) in scene.generators.iter().zip(tables) {
        for light in &scene.lights {
            let frame =
                IlluminationTextures::frame(table, &generator.mesh, &Affine3A::IDENTITY, light, &scene.receivers, settings).map(IlluminationTextures::drawn);
            let Some(frame) = frame else { continue };
            for (e, &(p, n)) in e.iter_mut().zip(points) {
                *e += frame.irradiance_at(p, n, Cosine::Receiver).element_sum() / 3.0;
            }
        }
    }
    e
}

/// The twin's caustic irradiance per cell of `bench`'s flat region, `samples`² points
/// a cell (the bench's estimator for every method), at `settings`.
pub fn irradiance(bench: &BenchScene, settings: &IlluminationSettings, samples: usize) -> Result<(Vec<f32>, u64), String> {
    let (tables, _) = tables(&bench.scene, "light transport tables")?;
    let up = if bench.region.normal().y < 0.0 { -bench.region.normal() } else { bench.region.normal() };
    let points: Vec<(Vec3, Vec3)> = crate::bench::cell_sample_points(&bench.region, samples).into_iter().map(|p| (p, up)).collect();
    let e = at_points(&bench.scene, &tables, settings, &points);
    let volumes = tables.iter().map(|t| t.stats.entries as u64).sum();
    Ok((crate::bench::cell_means(&e, samples), volumes))
}

/// Points on the receivers of `region`'s cells ([`surface_samples`]) with the cell they
/// fall in and their weight, flattened.
struct SurfacePoints {
    points: Vec<(Vec3, Vec3)>,
    cells: Vec<(usize, f32)>,
    count: usize,
}

impl SurfacePoints {
    fn new(region: &GridRegion, scene: &Scene, per_cell: usize) -> Self {
        let mut points = Vec::new();
        let mut cells = Vec::new();
        let samples = surface_samples(region, &scene.receivers, per_cell);
        for (cell, list) in samples.iter().enumerate() {
            for &(p, n, w) in list {
                points.push((p, n));
                cells.push((cell, w));
            }
        }
        Self { points, cells, count: samples.len() }
    }

    /// Flux per cell area from irradiance at the points.
    fn cells(&self, e: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0f32; self.count];
        for (&(cell, w), e) in self.cells.iter().zip(e) {
            out[cell] += e * w;
        }
        out
    }
}

/// The bench's rows for illumination textures, and a note for `bench.md`.
pub fn bench_scenes(quick: bool, cpu_only: bool, rows: &mut Vec<Measurement>) -> Result<String, String> {
    let photons: u64 = if quick { 1 << 20 } else { 1 << 24 };
    let sweep: &[(u32, u32)] = if quick { &[(1, 256), (4, 256)] } else { &[(1, 512), (2, 512), (4, 512), (8, 512), (16, 512), (4, 128), (4, 256), (4, 1024)] };
    let mut md = String::from(
        "\nIllumination textures (CPU twin) against the tracer, on the glass sphere's flat floor and on a glass ball \
         over the Stanford bunny (`ball_bunny`, a curved receiver): every photon binned by the cell it lands over, \
         the techniques read on the receivers' surfaces cut at the cells' sides (`estimate::surface_samples`). \
         The caustic maps (full method, 1024² photons) on the same points for comparison.\n\n\
         | scene | light transport table | entries | MB | build (s) |\n|---|---|---:|---:|---:|\n",
    );
    for bench in [glass_sphere(64), glass_ball_over_bunny(64)] {
        let name = if bench.name == "glass_sphere" { "sphere".to_string() } else { bench.name.clone() };
        let label = format!("{name}: reference with {photons} photons (projected)");
        let tracer = PhotonTracer::new(&bench.scene).map_err(|e| e.to_string())?;
        let mut grid = IrradianceGrid::projected(bench.region);
        tracer.trace(&TraceSettings { photons_per_light: photons, seed: 1, ..TraceSettings::default() }, &mut grid, &progress(&label));
        let truth = grid.irradiance_mean();
        let surface = SurfacePoints::new(&bench.region, &bench.scene, if quick { 4 } else { 16 });
        let (tables, build_seconds) = tables(&bench.scene, &format!("{name}: light transport table"))?;
        for t in &tables {
            writeln!(
                md,
                "| {name} | {}² directions | {} | {:.1} | {build_seconds:.2} |",
                t.build_settings().grid.side(),
                t.stats.entries,
                t.bytes() as f64 / 1e6
            )
            .unwrap();
        }
        for &(planes, size) in sweep {
            let settings = IlluminationSettings { planes, texture_size: size };
            let clock = Instant::now();
            let image = surface.cells(&at_points(&bench.scene, &tables, &settings, &surface.points));
            let seconds = clock.elapsed().as_secs_f64();
            let error = Errors::between(&image, &truth);
            let quality = format!("{planes}×{size}²");
            eprintln!("{name:>8} {:>16} {quality:>10}: {seconds:8.3} s, relative L2 {:.4}", "textures", error.l2);
            let default = settings == IlluminationSettings::default();
            let gpu = (default && !cpu_only && name == "sphere").then(|| gpu_columns(Method::IlluminationTextures, &bench, None)).flatten();
            let work = tables.iter().map(|t| t.stats.entries as u64).sum();
            rows.push(Measurement { scene: name.clone(), method: "textures".into(), quality, work, seconds, gpu, error, error_vs_limit: None });
        }
        let clock = Instant::now();
        let maps =
            crate::hierarchical::irradiance_at(&bench, &crate::hierarchical::VARIANTS[4].settings(1024, crate::hierarchical::MAP_RESOLUTION), &surface.points)?;
        let seconds = clock.elapsed().as_secs_f64();
        let error = Errors::between(&surface.cells(&maps.0), &truth);
        eprintln!("{name:>8} {:>16} {:>10}: {seconds:8.3} s, relative L2 {:.4}", "maps (surface)", "1024", error.l2);
        rows.push(Measurement {
            scene: name,
            method: "maps-surface".into(),
            quality: "1024".into(),
            work: maps.1,
            seconds,
            gpu: None,
            error,
            error_vs_limit: None,
        });
    }
    Ok(md)
}
