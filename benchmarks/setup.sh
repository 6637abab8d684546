#!/usr/bin/env bash
# Install what benchmarks/bench_render.py compares against, if missing (not needed by the tests):
# Mitsuba 3 from PyPI (its llvm_ad_rgb variant loads Debian's libllvm19 at run time) and the Mesa
# EGL/llvmpipe packages (scripts/install-system-deps) for the OpenGL comparison.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-system-deps
if ! dpkg-query -W -f='${Status}' libllvm19 2>/dev/null | grep -q "install ok installed"; then
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    echo "benchmarks/setup.sh: installing libllvm19" >&2
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends libllvm19 >/dev/null
fi
python -m pip install --quiet '.[bench]' 2>/dev/null || python -m pip install --quiet 'mitsuba>=3.5'
python -c "import mitsuba as mi; mi.set_variant('llvm_ad_rgb'); print('mitsuba', mi.__version__, mi.variant())"
