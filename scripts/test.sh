#!/usr/bin/env bash
# Runs every test of the workspace, GPU tests included. Without a GPU they run on
# Mesa's software Vulkan (lavapipe), installed here when it is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! compgen -G "/usr/share/vulkan/icd.d/lvp_icd*.json" >/dev/null; then
  echo "scripts/test.sh: installing Mesa's software Vulkan (lavapipe) for the GPU tests"
  sudo_if_needed=""
  [ "$(id -u)" -eq 0 ] || sudo_if_needed="sudo"
  $sudo_if_needed apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_if_needed apt-get install -y -qq mesa-vulkan-drivers >/dev/null
fi

# Headless Vulkan loaders complain without a runtime dir; give them a private one.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"

cargo test --workspace --locked "$@"
