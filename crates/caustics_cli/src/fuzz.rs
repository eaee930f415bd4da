//! `caustics fuzz`: adversarial scenes through every CPU twin (`caustics_core::fuzz`),
//! with a table per category: cases tried, passed, refused with a clear error, failed,
//! the largest energy ratio and the largest peak of memory. A failing case prints its
//! seed and index, which reproduce it alone (`--seed S --first I --cases 1`).

use caustics_core::fuzz::{CATEGORIES, CaseResult, Category, ENERGY_TOLERANCE, MEMORY_BOUND, Verdict, run_case};
use std::fmt::Write as _;
use std::time::Instant;

#[derive(clap::Args)]
pub struct FuzzArgs {
    /// How many cases to run.
    #[arg(long, default_value_t = 1000)]
    cases: u64,
    /// The seed every case is drawn from.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The index of the first case.
    #[arg(long, default_value_t = 0)]
    first: u64,
}

/// One category's tally.
#[derive(Default)]
struct Tally {
    cases: u64,
    passed: u64,
    refused: u64,
    failed: u64,
    energy_ratio: f64,
    peak_bytes: usize,
}

pub fn run(args: FuzzArgs) -> Result<(), String> {
    let start = Instant::now();
    // One case at a time, so that each one's peak memory is its own; the twins use
    // every core themselves.
    let step = (args.cases / 10).max(1);
    let results: Vec<CaseResult> = (args.first..args.first + args.cases)
        .enumerate()
        .map(|(n, index)| {
            let result = run_case(args.seed, index);
            if let Verdict::Failed(why) = &result.verdict {
                eprintln!("FAILED case {} of seed {} ({:?}): {why}", result.index, result.seed, result.category);
            }
            if (n as u64 + 1).is_multiple_of(step) {
                eprintln!("fuzz: {}/{} cases, {:.0} s", n + 1, args.cases, start.elapsed().as_secs_f64());
            }
            result
        })
        .collect();
    let seconds = start.elapsed().as_secs_f64();
    print!("{}", report(&results, seconds));
    let failed: Vec<String> =
        results.iter().filter(|r| matches!(r.verdict, Verdict::Failed(_))).map(|r| format!("--seed {} --first {} --cases 1", r.seed, r.index)).collect();
    if failed.is_empty() { Ok(()) } else { Err(format!("{} of {} cases failed; rerun one with {}", failed.len(), results.len(), failed[0])) }
}

/// The table: one line per category, then the totals.
fn report(results: &[CaseResult], seconds: f64) -> String {
    let mut tallies: Vec<(Category, Tally)> = CATEGORIES.iter().map(|&c| (c, Tally::default())).collect();
    for r in results {
        let Some((_, tally)) = tallies.iter_mut().find(|(c, _)| *c == r.category) else { continue };
        tally.cases += 1;
        tally.peak_bytes = tally.peak_bytes.max(r.peak_bytes);
        match &r.verdict {
            Verdict::Passed { energy_ratio } => {
                tally.passed += 1;
                tally.energy_ratio = tally.energy_ratio.max(*energy_ratio);
            }
            Verdict::Refused(_) => tally.refused += 1,
            Verdict::Failed(_) => tally.failed += 1,
        }
    }
    let mut out = String::from(
        "| category | cases | passed | refused (clear error) | failed | largest energy ratio | peak memory |\n|---|---:|---:|---:|---:|---:|---:|\n",
    );
    let mut total = Tally::default();
    for (category, t) in &tallies {
        let _ = writeln!(
            out,
            "| {category:?} | {} | {} | {} | {} | {:.4} | {:.1} MiB |",
            t.cases,
            t.passed,
            t.refused,
            t.failed,
            t.energy_ratio,
            t.peak_bytes as f64 / 1048576.0
        );
        total.cases += t.cases;
        total.passed += t.passed;
        total.refused += t.refused;
        total.failed += t.failed;
        total.energy_ratio = total.energy_ratio.max(t.energy_ratio);
        total.peak_bytes = total.peak_bytes.max(t.peak_bytes);
    }
    let _ = writeln!(
        out,
        "| all | {} | {} | {} | {} | {:.4} | {:.1} MiB |\n\n{} cases in {seconds:.1} s; energy may exceed what came in by {ENERGY_TOLERANCE} (rounding), memory is bounded at {} MiB a case.",
        total.cases,
        total.passed,
        total.refused,
        total.failed,
        total.energy_ratio,
        total.peak_bytes as f64 / 1048576.0,
        total.cases,
        MEMORY_BOUND >> 20
    );
    out
}
