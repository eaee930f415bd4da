#!/usr/bin/env bash
# The frame-cost bench on the machine's GPU, at 1920 × 1080: the caustic volumes on the
# ocean, the mirror ring and the rippling pool, the caustic maps on the ring. Writes,
# under the folder given (target/gpu-bench by default), frames.md and frames.csv (each
# size's GPU time and shader invocations beside Bevy's main pass, the adapter named),
# frames-passes.csv (every pass) and the plots. Shader invocations carry between
# adapters; the times are this GPU's.
#
#   scripts/gpu_bench.sh [OUT [BENCH ARGS…]]
#                                         builds the CLI, then runs the bench (more
#                                         arguments go to `caustics bench`: --quick)
#   CAUSTICS_BIN=path scripts/gpu_bench.sh …
#                                         runs a CLI built elsewhere (a machine
#                                         with a GPU and no Rust toolchain)
#   GPU_BENCH_SIZE=960x540 scripts/gpu_bench.sh …
#                                         another view size
#
# The project's one build profile serves (dependencies optimised): the GPU's figures do
# not depend on it, and a second profile would build Bevy a second time. On a GPU the
# bench takes a few minutes; every family stops growing once a frame takes 20 s.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/gpu-bench}"
shift || true
bin="${CAUSTICS_BIN:-}"
if [ -z "$bin" ]; then
  # Every target of the workspace, as the tests build it: the one feature set Bevy is
  # built with, so no second build of it.
  cargo build --workspace --all-targets --locked
  bin="${CARGO_TARGET_DIR:-target}/debug/caustics"
fi
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
start=$(date +%s)
"$bin" bench --frames --frame-size "${GPU_BENCH_SIZE:-1920x1080}" --methods volumes,maps \
  --frame-scenes 'ocean,ring,rippled pool' --frame-budget 20 --out "$out" "$@"
echo "gpu_bench: $(( $(date +%s) - start )) s; $out/frames.md"
