#!/usr/bin/env bash
# System packages the project needs on a fresh machine: the Mesa lavapipe Vulkan driver, so the
# GPU kernels and their tests (tests/gpu.rs) run on the CPU in CI (the plots' font ships inside
# the program). Idempotent.
set -euo pipefail
if ! ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends mesa-vulkan-drivers >/dev/null
fi
