//! `caustics`: render a scene's caustics, write irradiance planes, run the
//! error-against-run-time bench, and fuzz every CPU twin with adversarial scenes. Errors are one line on stderr and a non-zero exit.

mod bench;
mod frames;
mod fuzz;
mod gltf;
mod hierarchical;
mod illumination;
mod images;
mod plot;
mod render;
mod scenes;
mod views;

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "caustics", version, about = "Caustics rendering and measurement for bevy_caustics")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a view of a scene (or its caustic irradiance plane) with one method.
    Render(render::RenderArgs),
    /// Run every method at several quality settings on the built-in scenes and write
    /// a CSV, a Markdown table and a PNG plot of error against run time; with
    /// `--frames`, each technique's cost per frame as its work grows instead.
    Bench(bench::BenchArgs),
    /// Run adversarial scenes (degenerate and non-finite meshes, extreme scales, IORs
    /// and lights, empty scenes, photon floods, adversarial pools) through every CPU
    /// twin and print, per category, the cases tried, refused and failed, the largest
    /// energy ratio and the peak memory.
    Fuzz(fuzz::FuzzArgs),
}

/// Counts the memory each fuzzed case takes.
#[global_allocator]
static ALLOCATOR: caustics_core::fuzz::CountingAllocator = caustics_core::fuzz::CountingAllocator;

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    let result = match cli.command {
        Command::Render(args) => render::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Fuzz(args) => fuzz::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("caustics: {message}");
            ExitCode::FAILURE
        }
    }
}

/// Creates the parent folder of an output file.
fn prepare_output(path: &std::path::Path) -> Result<PathBuf, String> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    Ok(path.to_path_buf())
}

/// Progress on stderr: a line rewritten in place on a terminal, else a line per 10 %.
fn progress(label: &str) -> impl Fn(u64, u64) + Sync + '_ {
    use std::io::IsTerminal;
    use std::sync::atomic::{AtomicU64, Ordering};
    let terminal = std::io::stderr().is_terminal();
    let step = if terminal { 1 } else { 10 };
    let last = AtomicU64::new(u64::MAX);
    move |done, total| {
        let percent = 100 * done / total.max(1);
        let bucket = percent / step;
        if last.swap(bucket, Ordering::Relaxed) == bucket {
            return;
        }
        if terminal {
            eprint!("\r{label}: {percent:3} % ({done}/{total} photons)");
            if done == total {
                eprintln!();
            }
        } else {
            eprintln!("{label}: {percent:3} % ({done}/{total} photons)");
        }
    }
}
