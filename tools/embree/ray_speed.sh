#!/bin/sh
# Per-ray speed of hdov's CPU backend against Intel Embree, side by side in one run, one thread
# each (docs/dov.md, "Per-ray speed against Embree"). Needs `pip install embreex numpy`.
#   tools/embree/ray_speed.sh SCENE OUT_DIR [RESOLUTION] [X,Y,Z]
set -e
[ $# -ge 2 ] || { echo "usage: ray_speed.sh SCENE OUT_DIR [RESOLUTION] [X,Y,Z]" >&2; exit 2; }
cd "$(dirname "$0")/../.."
cargo run --release -q -p hdov-tools --bin ray-speed -- "$@"
python3 tools/embree/embree_ray_speed.py "$2"
