//! `caustics bench`: every method at several quality settings on the built-in scenes,
//! timed, with its error against a high-photon-count reference. Writes
//! `bench.csv`, `bench.md` and `bench.png` (error against run time, log–log).

use crate::plot::{Series, plot_error_vs_time};
use crate::{prepare_output, progress};
use caustics_core::estimate::IrradianceGrid;
use caustics_core::metrics::relative_l2;
use caustics_core::scenes::{BenchScene, wave_pool};
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct BenchArgs {
    /// Folder for bench.csv, bench.md and bench.png.
    #[arg(long, default_value = "target/bench")]
    pub out: PathBuf,
    /// Fewer photons everywhere (a smoke run of the whole bench in seconds).
    #[arg(long)]
    pub quick: bool,
    /// Built-in scenes to run, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = crate::scenes::BUILT_IN.map(String::from))]
    pub scenes: Vec<String>,
}

/// One quality setting of one method on one scene.
pub struct Measurement {
    pub scene: String,
    pub method: String,
    pub quality: String,
    /// Photons (or other work items) the run processed.
    pub work: u64,
    pub seconds: f64,
    /// Relative L2 of caustic irradiance on the scene's region against the reference.
    pub error: f32,
}

/// A caustics method the bench can run: it computes the caustic irradiance on the
/// scene's region at a given quality.
pub trait BenchMethod {
    fn name(&self) -> &'static str;
    /// Quality settings, cheapest first.
    fn qualities(&self, quick: bool) -> Vec<u64>;
    /// Irradiance per cell (mean of RGB, row-major) and the work done.
    fn run(&self, scene: &BenchScene, quality: u64) -> Result<(Vec<f32>, u64), String>;
}

/// The ground-truth tracer with `quality` photons per light.
pub struct ReferenceTracer;

impl BenchMethod for ReferenceTracer {
    fn name(&self) -> &'static str {
        "reference"
    }
    fn qualities(&self, quick: bool) -> Vec<u64> {
        let top = if quick { 18 } else { 22 };
        (12..=top).step_by(2).map(|k| 1u64 << k).collect()
    }
    fn run(&self, scene: &BenchScene, photons: u64) -> Result<(Vec<f32>, u64), String> {
        trace_grid(scene, photons, 2, &|_, _| {})
    }
}

/// Traces `photons` per light into the scene's grid, BVH build included.
fn trace_grid(
    scene: &BenchScene,
    photons: u64,
    seed: u64,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(Vec<f32>, u64), String> {
    let tracer = PhotonTracer::new(&scene.scene).map_err(|e| e.to_string())?;
    let mut grid = IrradianceGrid::new(scene.region);
    let settings = TraceSettings { photons_per_light: photons, seed, ..Default::default() };
    let stats = tracer.trace(&settings, &mut grid, progress);
    Ok((grid.irradiance_mean(), stats.photons))
}

pub fn run(args: BenchArgs) -> Result<(), String> {
    let methods: Vec<Box<dyn BenchMethod>> = vec![Box::new(ReferenceTracer)];
    let reference_photons: u64 = if args.quick { 1 << 21 } else { 1 << 26 };
    let mut rows = Vec::new();
    for name in &args.scenes {
        let scene = crate::scenes::built_in(name)
            .ok_or_else(|| format!("unknown scene {name:?} (built-in: {})", crate::scenes::BUILT_IN.join(", ")))?;
        let label = format!("{name}: reference with {reference_photons} photons");
        let (truth, _) = trace_grid(&scene, reference_photons, 1, &progress(&label))?;
        for method in &methods {
            for quality in method.qualities(args.quick) {
                let start = Instant::now();
                let (image, work) = method.run(&scene, quality)?;
                let seconds = start.elapsed().as_secs_f64();
                let error = relative_l2(&image, &truth);
                eprintln!("{name:>8} {:>12} {quality:>10}: {seconds:8.3} s, relative L2 {:.4}", method.name(), error);
                rows.push(Measurement {
                    scene: name.clone(),
                    method: method.name().into(),
                    quality: quality.to_string(),
                    work,
                    seconds,
                    error,
                });
            }
        }
    }
    let throughput = photon_throughput(if args.quick { 1 << 20 } else { 1 << 23 })?;
    write_outputs(&args.out, &rows, throughput)
}

/// Photons per second of the reference tracer on the 128 × 128-vertex rippled pool.
fn photon_throughput(photons: u64) -> Result<f64, String> {
    let scene = wave_pool(128, 128);
    let tracer = PhotonTracer::new(&scene.scene).map_err(|e| e.to_string())?;
    let mut grid = IrradianceGrid::new(scene.region);
    let settings = TraceSettings { photons_per_light: photons, ..Default::default() };
    let start = Instant::now();
    tracer.trace(&settings, &mut grid, &progress("throughput"));
    let rate = photons as f64 / start.elapsed().as_secs_f64();
    eprintln!(
        "reference tracer: {:.2} M photons/s on {} threads (128×128 heightfield over a floor)",
        rate / 1e6,
        rayon::current_num_threads()
    );
    Ok(rate)
}

/// Least-squares slope of log(error) against log(work): −½ for Monte Carlo.
fn convergence_slope(rows: &[&Measurement]) -> f64 {
    let pts: Vec<(f64, f64)> = rows.iter().map(|r| ((r.work as f64).ln(), (r.error as f64).ln())).collect();
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

fn write_outputs(dir: &std::path::Path, rows: &[Measurement], throughput: f64) -> Result<(), String> {
    let csv_path = prepare_output(&dir.join("bench.csv"))?;
    let mut csv = String::from("scene,method,quality,work,seconds,relative_l2\n");
    for r in rows {
        writeln!(csv, "{},{},{},{},{:.6},{:.6}", r.scene, r.method, r.quality, r.work, r.seconds, r.error).unwrap();
    }
    std::fs::write(&csv_path, csv).map_err(|e| format!("cannot write {}: {e}", csv_path.display()))?;

    let mut md = String::from("| scene | method | quality | photons | time (s) | relative L2 |\n|---|---|---|---:|---:|---:|\n");
    for r in rows {
        writeln!(md, "| {} | {} | {} | {} | {:.3} | {:.4} |", r.scene, r.method, r.quality, r.work, r.seconds, r.error)
            .unwrap();
    }
    let mut series: Vec<Series> = Vec::new();
    md.push('\n');
    for r in rows {
        let key = format!("{} / {}", r.scene, r.method);
        if !series.iter().any(|s| s.label == key) {
            let group: Vec<&Measurement> =
                rows.iter().filter(|m| m.scene == r.scene && m.method == r.method).collect();
            writeln!(md, "Convergence of {key}: error ∝ photons^{:.2}.  ", convergence_slope(&group)).unwrap();
            series.push(Series { label: key, points: group.iter().map(|m| (m.seconds, m.error as f64)).collect() });
        }
    }
    writeln!(md, "\nReference tracer throughput: {:.2} M photons/s on {} threads.", throughput / 1e6, rayon::current_num_threads())
        .unwrap();
    let md_path = dir.join("bench.md");
    std::fs::write(&md_path, md).map_err(|e| format!("cannot write {}: {e}", md_path.display()))?;
    let png_path = dir.join("bench.png");
    plot_error_vs_time(&png_path, &series)?;
    eprintln!("wrote {}, {} and {}", csv_path.display(), md_path.display(), png_path.display());
    Ok(())
}
