#!/usr/bin/env bash
# The real-GPU check (issue 18). On a machine with an NVIDIA GPU: the kernels against their CPU
# twins (acetab bench; srvf_band is the studies' own DP) at batch sizes up to 4,096 problems and
# meshes up to 100,000 vertices, and a study's throughput on the GPU, its SRVF DPs on the device
# and on the host, against the CPU path on every core. Within 8 minutes; every step has its own
# time limit, and a step that fails is reported and skipped.
#
# Uses target/device/acetab and target/device/lib (ci/device-prepare.sh, run beforehand where
# the project builds), else builds with cargo if there is one. Writes to $OUT (the device tool's
# folder) or target/device-check. QUICK=1: small sizes, to test the script on a CPU (lavapipe).
set -uo pipefail
cd "$(dirname "$0")/.."
out=${OUT:-target/device-check}
mkdir -p "$out"
log() { echo "== $*" | tee -a "$out/check.log"; }
bin=target/device/acetab
if [ ! -x "$bin" ]; then
  if command -v cargo >/dev/null; then
    cargo build --release --quiet && bin=target/release/acetab
  else
    log "no target/device/acetab and no cargo: run ci/device-prepare.sh first"; exit 1
  fi
fi
[ -d target/device/lib ] && export LD_LIBRARY_PATH="$PWD/target/device/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
cores=$(nproc)
log "commit $(cat target/device/commit 2>/dev/null || git rev-parse --short=12 HEAD 2>/dev/null), $cores cores"
command -v nvidia-smi >/dev/null && nvidia-smi -L | tee -a "$out/check.log"
ls /usr/share/vulkan/icd.d /etc/vulkan/icd.d 2>/dev/null | tee -a "$out/check.log"
# Where the NVIDIA driver is mounted under /usr/local/nvidia (container hosts), its Vulkan ICD and
# EGL vendor files are not where the loaders look: point them there, unless set already.
nv=/usr/local/nvidia
if [ -z "${VK_DRIVER_FILES:-}" ] && ! ls /usr/share/vulkan/icd.d/nvidia* /etc/vulkan/icd.d/nvidia* >/dev/null 2>&1 \
  && [ -f "$nv/share/vulkan/icd.d/nvidia_icd.json" ]; then
  export VK_DRIVER_FILES=$nv/share/vulkan/icd.d/nvidia_icd.json
  log "Vulkan ICD: $VK_DRIVER_FILES"
fi
if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ] && [ -f "$nv/share/glvnd/egl_vendor.d/10_nvidia.json" ] \
  && ! ls /usr/share/glvnd/egl_vendor.d/*nvidia* >/dev/null 2>&1; then
  export __EGL_VENDOR_LIBRARY_FILENAMES=$nv/share/glvnd/egl_vendor.d/10_nvidia.json
  log "EGL vendor: $__EGL_VENDOR_LIBRARY_FILENAMES"
fi
for d in "$nv/lib64" "$nv/lib"; do
  [ -d "$d" ] && export LD_LIBRARY_PATH="${LD_LIBRARY_PATH:+$LD_LIBRARY_PATH:}$d"
done
if [ "${QUICK:-0}" = 1 ]; then
  meshes=1000,10000; batches=1,64,256; runs=8; repeats=2; study_batches=1,4
else
  meshes=1000,10000,100000; batches=1,64,256,1024,4096; runs=128; repeats=5
  study_batches=1,64,256,1024
fi
# Vulkan first; the GL backend (EGL) if no Vulkan adapter comes up.
backend=""
for b in vulkan gl; do
  if WGPU_BACKEND=$b timeout 60 "$bin" bench --quick --study-runs 0 --repeats 1 >"$out/probe-$b.txt" 2>&1; then
    backend=$b; break
  fi
done
if [ -z "$backend" ]; then
  log "no GPU adapter (see $out/probe-*.txt); only the CPU study runs"
else
  export WGPU_BACKEND=$backend
  log "adapter: $(grep adapter "$out/probe-$backend.txt")"
  log "kernels: acetab bench --mesh-sizes $meshes --dp-batches $batches --repeats $repeats"
  timeout 240 "$bin" bench --mesh-sizes "$meshes" --dp-batches "$batches" --repeats "$repeats" \
    --study-runs 0 2>"$out/bench.err" | tee "$out/bench.txt" || log "bench failed or ran out of time (see $out/bench.err)"
  # Study throughput: the CPU path on every core, the GPU backend, and the GPU with runs
  # batched (runs in flight at once, their kernel requests merged) at each batch size.
  log "study batches: acetab bench --study-runs $runs --threads $cores --study-batches $study_batches"
  timeout 200 "$bin" bench --mesh-sizes 1000 --dp-batches 1 --repeats 1 --study-runs "$runs" \
    --threads "$cores" --study-batches "$study_batches" --dp both 2>"$out/batches.err" | grep study \
    | tee "$out/batches.txt" | tee -a "$out/check.log" \
    || log "study batches failed or ran out of time (see $out/batches.err)"
fi
# The GPU study twice: its SRVF DPs on the device (--dp auto picks it on a real GPU) and on
# the host, so the DP kernel's share shows.
for be in cpu ${backend:+gpu gpu-dp-host}; do
  case $be in
    cpu) flags="--backend cpu" ;;
    gpu) flags="--backend gpu --dp device" ;;
    gpu-dp-host) flags="--backend gpu --dp host" ;;
  esac
  log "study: phantom, srvf, level 3, $runs runs, $cores threads, $flags"
  timeout 150 "$bin" simulate --gt phantom --levels 3 --runs "$runs" --methods srvf --threads "$cores" \
    --uncertainty-samples 0 $flags --out "$out/study-$be" >"$out/study-$be.txt" 2>&1 \
    || log "study on $be failed or ran out of time (see $out/study-$be.txt)"
  grep "runs in" "$out/study-$be.txt" | tee -a "$out/check.log"
  python3 -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))["study"]["engine"]))' \
    "$out/study-$be/summary.json" 2>/dev/null | tee -a "$out/check.log"
done
# The GPU studies against the CPU study, run by run (issue 18: MAE within 0.05 mm, cup within
# 0.1 mm).
for be in ${backend:+gpu gpu-dp-host}; do
  python3 - "$out/study-cpu/runs.csv" "$out/study-$be/runs.csv" <<'PY' 2>&1 | sed "s/^/agreement $be: /" | tee -a "$out/check.log"
import csv, sys
a, b = (list(csv.DictReader(open(f))) for f in sys.argv[1:3])
if len(a) != len(b) or not a:
    sys.exit(f"{len(a)} CPU runs against {len(b)}")
d = lambda k: max(abs(float(x[k]) - float(y[k])) for x, y in zip(a, b))
print(f"{len(a)} runs, largest difference: MAE {d('mae_mm'):.2e} mm, cup {d('cup_diameter_mm'):.2e} mm")
PY
done
log "done"
