#!/usr/bin/env bash
# Fetches Nexuiz's levels (GPL-2+, Debian's nexuiz-data: 40 Quake III-format levels compiled by
# q3map2, with their PVS) and unpacks the ones named (default: a small, a middle and a large one)
# into tools/corpus/data/ as nexuiz-MAP.bsp, for `level-corpus`: another game's levels, by other
# mappers than OpenArena's. Needs apt (Debian's archive) and python3; the package is 267 MB.
# The data stays out of git (tools/corpus/data/ is ignored).
#
#   tools/corpus/nexuiz.sh [MAP ...]     e.g. downer ruiner basement toxic
set -euo pipefail
maps=("${@:-downer ruiner basement}")
read -r -a maps <<<"${maps[*]}"
exec "$(dirname "$0")/pk3-levels.sh" nexuiz-data ./usr/share/games/nexuiz/data/data.pk3 \
  ./usr/share/doc/nexuiz-data/copyright nexuiz- "${maps[@]}"
