#!/usr/bin/env bash
# The thesis's table 5.2 on our data: bytes per V-page layout for a city database.
# Usage: tools/storage-table.sh SCALE [extra hdov build flags...]
# Prints one markdown row per layout. Uses the release binary (cargo build --release first).
set -euo pipefail
scale=${1:-default}; shift || true
hdov=${HDOV:-target/release/hdov}
work=${WORK:-/tmp/hdov-storage-$scale}
mkdir -p "$work"
[ -f "$work/city/city.json" ] || "$hdov" generate city --scale "$scale" --out "$work/city" >/dev/null
"$hdov" build "$work/city/city.json" --out "$work/db" --force --layouts horizontal,vertical,indexed-vertical "$@" >/dev/null
"$hdov" info "$work/db" --json | python3 -c '
import json, sys
d = json.load(sys.stdin)
L = d["layouts"]; h = L["horizontal"]["bytes"]
print(f"| layout | bytes | V-page bytes | index bytes | × smaller than horizontal | visible nodes / cell | bytes per visible (node, cell) | flip pages (mean) |")
print("|---|---|---|---|---|---|---|---|")
for name in ["horizontal", "vertical", "indexed-vertical"]:
    l = L[name]
    row = [name, format(l["bytes"], ","), format(l["vpage_bytes"], ","), format(l["index_bytes"], ","),
           "%.1f" % (h / l["bytes"]), "%.1f of %d" % (l["visible_nodes_per_cell"]["mean"], d["nodes"]),
           "%.0f" % l["bytes_per_visible_vpage"], "%.2f" % l["flip_pages"]["mean"]]
    print("| " + " | ".join(row) + " |")
'
