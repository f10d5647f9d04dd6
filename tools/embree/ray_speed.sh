#!/bin/sh
# Per-ray speed of hdov's CPU backend against Intel Embree, side by side in one run, one thread
# each (docs/dov.md, "Per-ray speed against Embree"): hdov's tracers (tools/src/bin/ray-speed.rs),
# then Embree's own C API in both its modes (embree_c_speed.c: rtcIntersect1 and coherent 4 × 4
# rtcIntersect16; needs Debian's libembree-dev), then the Python binding if it is installed
# (embree_ray_speed.py; `pip install embreex numpy`).
#   tools/embree/ray_speed.sh SCENE OUT_DIR [RESOLUTION] [X,Y,Z]
# EMBREE_MAX_ISA=avx2 (say) caps Embree's kernels, to compare at hdov's vector width.
set -e
[ $# -ge 2 ] || { echo "usage: ray_speed.sh SCENE OUT_DIR [RESOLUTION] [X,Y,Z]" >&2; exit 2; }
cd "$(dirname "$0")/../.."
cargo run --release -q -p hdov-tools --bin ray-speed -- "$@"
if [ -f /usr/include/embree3/rtcore.h ]; then
  cc -O2 -march=native tools/embree/embree_c_speed.c -lembree3 -lm -o "$2/embree_c_speed"
  "$2/embree_c_speed" "$2"
else
  echo "embree C API: skipped (apt-get install libembree-dev)"
fi
if python3 -c "import embreex" 2>/dev/null; then
  python3 tools/embree/embree_ray_speed.py "$2"
else
  echo "embreex: skipped (pip install embreex numpy)"
fi
