#!/usr/bin/env bash
# Sharded build of a generated city on this machine, measured: a whole build, a --no-visibility
# base, N shards on the base (--base: no LODs of their own) one after another, and the merge;
# prints each step's wall time and peak RSS (GNU time), the shards' bytes, and checks that the
# merged database equals the whole build, every data file byte for byte. Exits 1 if not.
#
#   tools/shards/merge-measure.sh [HDOV_BINARY] [SCALE] [SHARDS] [RESOLUTION] [WORK_DIR]
#   (defaults: target/release/hdov large 32 64 a new temporary folder, removed at the end)
set -euo pipefail
HDOV=$(realpath "${1:-target/release/hdov}")
SCALE=${2:-large}
N=${3:-32}
R=${4:-64}
KEEP=${5:-}
command -v /usr/bin/time >/dev/null || { echo "merge-measure: needs GNU time (/usr/bin/time)"; exit 1; }
if [ -n "$KEEP" ]; then mkdir "$KEEP"; W=$KEEP; else W=$(mktemp -d); trap 'rm -rf "$W"' EXIT; fi
measure() { # label, command...
  local label=$1; shift
  /usr/bin/time -f "$label: %e s, peak %M kB" "$@" >/dev/null 2>"$W/time.log" || { cat "$W/time.log"; exit 1; }
  tail -n 1 "$W/time.log"
}
"$HDOV" generate city --scale "$SCALE" --seed 1 --out "$W/city" >/dev/null
SCENE=$W/city/city.json
common=(--backend cpu --resolution "$R")
measure "whole build" "$HDOV" build "$SCENE" --out "$W/whole.hdov" "${common[@]}"
measure "base (--no-visibility)" "$HDOV" build "$SCENE" --out "$W/base.hdov" --no-visibility
t0=$(date +%s.%N)
for i in $(seq 0 $((N - 1))); do
  measure "shard $i/$N" "$HDOV" build "$SCENE" --out "$W/s$i.hdov" --shard "$i/$N" --base "$W/base.hdov" "${common[@]}"
done
t1=$(date +%s.%N)
printf 'the %d shards: %.1f s one after another, %s bytes in all\n' "$N" "$(echo "$t1 - $t0" | bc)" \
  "$(du -cb "$W"/s*.hdov | tail -1 | cut -f1)"
measure "merge" "$HDOV" merge "$W/base.hdov" $(for i in $(seq 0 $((N - 1))); do printf '%s ' "$W/s$i.hdov"; done) --out "$W/merged.hdov"
printf 'whole build %s bytes, merged %s bytes\n' "$(du -sb "$W/whole.hdov" | cut -f1)" "$(du -sb "$W/merged.hdov" | cut -f1)"
for f in "$W"/whole.hdov/*; do
  name=$(basename "$f")
  [ "$name" = manifest.json ] && continue
  cmp -s "$f" "$W/merged.hdov/$name" || { echo "merge-measure: $name differs from the whole build"; exit 1; }
done
echo "merge-measure: the merged database equals the whole build ($(ls "$W/whole.hdov" | wc -l) files, byte for byte)"
