#!/usr/bin/env bash
# Prepare the real-GPU check (issue 18) on this machine: the device machine reaches no network, so
# it gets a stripped release binary and the Vulkan loader here, in target/device/ (an ignored path
# the device tool carries: `run` with carry ["target/device"] and the command
# `bash ci/device-check.sh`). About 14 MB.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
mkdir -p target/device/lib
strip -o target/device/acetab target/release/acetab
loader=$(ldconfig -p | awk '/libvulkan.so.1 /{print $NF; exit}')
if [ -n "$loader" ]; then
  cp -L "$loader" target/device/lib/libvulkan.so.1
else
  echo "no Vulkan loader here to carry (bash ci/install-deps.sh installs one)" >&2
fi
# The EGL loader (glvnd) for wgpu's GL backend, the fallback where no Vulkan adapter comes up: it
# dispatches to the NVIDIA driver's own EGL library through the driver's vendor file.
for lib in libEGL.so.1 libGLdispatch.so.0; do
  path=$(ldconfig -p | awk -v l="$lib" '$1 == l {print $NF; exit}')
  if [ -n "$path" ]; then cp -L "$path" "target/device/lib/$lib"; else echo "no $lib here to carry" >&2; fi
done
git rev-parse --short=12 HEAD > target/device/commit
ls -la target/device target/device/lib
