//! The scene fuzzer (`caustics_core::fuzz`) on a few hundred cases, every category
//! alike, and the cases it once failed (kept as regressions): every CPU twin finishes
//! each case without a panic, with finite outputs, no more energy out than in and its
//! memory within the bound — or the input is refused with a clear message.

use caustics_core::fuzz::{CATEGORIES, CountingAllocator, Verdict, run_case};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Cases `caustics fuzz` once failed, as (seed, index): each must pass now. Seed 1's
/// LightAtInfinity cases 86 and 2257 (a point light of 3.4·10³⁸ cd: NaN irradiance
/// from the volumes; such lights are refused past `MAX_LIGHT_POWER` now). The first
/// failures, coordinates of 10²⁰ and 3·10³⁸ m (a panic in the BVH builder, an infinite
/// emitted flux), came from an earlier draw of the NonFinite category; `params.rs`
/// keeps them as plain tests.
const REGRESSIONS: &[(u64, u64)] = &[(1, 86), (1, 2257)];

/// Cases run here (`caustics fuzz --cases 10000` runs more).
const CASES: u64 = 390;

#[test]
fn every_twin_survives_adversarial_scenes() {
    let mut failures = Vec::new();
    let mut outcomes = vec![(0u32, 0u32); CATEGORIES.len()];
    let cases = REGRESSIONS.iter().copied().chain((0..CASES).map(|index| (7, index)));
    for (seed, index) in cases {
        let result = run_case(seed, index);
        let slot = CATEGORIES.iter().position(|&c| c == result.category).unwrap();
        match &result.verdict {
            Verdict::Passed { .. } => outcomes[slot].0 += 1,
            Verdict::Refused(message) => {
                assert!(message.len() > 10, "case {index} of seed {seed}: refused with {message:?}");
                outcomes[slot].1 += 1;
            }
            Verdict::Failed(why) => failures.push(format!("case {index} of seed {seed} ({:?}): {why}", result.category)),
        }
        assert!(result.peak_bytes > 0, "the counting allocator saw nothing");
    }
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
    // Each category both runs its twins and, where it makes inputs that cannot be
    // drawn, has them refused: no category is all refusals.
    for (category, (passed, refused)) in CATEGORIES.iter().zip(&outcomes) {
        eprintln!("{category:?}: {passed} passed, {refused} refused");
        assert!(*passed > 0, "{category:?}: no case reached the twins ({refused} refused)");
    }
}
