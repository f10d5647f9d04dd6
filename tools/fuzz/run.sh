#!/usr/bin/env bash
# Runs every fuzz target of hdov (tools/fuzz: scene files, database files, URL queries) and of its storage
# crate (storage/fuzz: page files, blobs, layouts) for SECONDS each (default 30) with libFuzzer,
# coverage-guided, on stable Rust: `cargo fuzz --sanitizer none` passes only stable flags (no
# AddressSanitizer: panics, overflows, timeouts and memory blow-ups are what it finds).
#
#   tools/fuzz/run.sh [SECONDS | --runs N]
#
# Each target starts from its seeds (SEEDS_DIR/TARGET, in the repository) and grows a working
# corpus under fuzz/corpus/TARGET (ignored by git). A crash stops the run with its input saved in
# fuzz/artifacts/TARGET and a non-zero exit. Installs cargo-fuzz 0.13.2 if it is missing.
set -euo pipefail
cd "$(dirname "$0")/../.."
if [ "${1:-}" = --runs ]; then
  BOUND=(-runs="$2" -seed=1)
  what="$2 inputs (seed 1)"
else
  BOUND=(-max_total_time="${1:-30}")
  what="${1:-30} s"
fi
command -v cargo-fuzz >/dev/null 2>&1 || cargo install cargo-fuzz --version 0.13.2 --locked
run() {
  local crate=$1 target=$2
  local fuzz="$crate/fuzz"
  mkdir -p "$fuzz/corpus/$target" "$fuzz/seeds/$target"
  # Debug builds: minutes instead of half an hour for the library with wgpu, instrumented.
  local log="$fuzz/run-$target.log"
  if ! (cd "$crate" && cargo fuzz run --sanitizer none --dev "$target" "fuzz/corpus/$target" "fuzz/seeds/$target" -- \
    "${BOUND[@]}" -timeout=20 -rss_limit_mb=4096 -max_len=65536 -print_final_stats=1) >"$log" 2>&1; then
    tail -40 "$log" >&2
    echo "fuzz: $target failed (input in $fuzz/artifacts/$target; log $log)" >&2
    exit 1
  fi
  grep -E '^stat::(number_of_executed_units|new_units_added):' "$log" | tr '\n' ' '
  echo "fuzz: $target ran $what without a failure"
}
for t in pagefile blob layout; do run storage "$t"; done
for t in tree_node catalog database scene_gltf scene_obj scene_manifest url_query; do run tools "$t"; done
