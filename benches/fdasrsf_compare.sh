#!/usr/bin/env bash
# Benchmark against fdasrsf 2.7.3 in one run: a local virtual environment with fdasrsf, a release
# build of acetab, then the same curve pairs through both (benches/fdasrsf_compare.py).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/pip install -q "fdasrsf==2.7.3"
cargo build --release -q
.venv/bin/python benches/fdasrsf_compare.py target/release/acetab
