#!/usr/bin/env bash
# Fetches OpenArena's levels (GPL-2+, Debian's openarena-081-maps: 50 Quake III levels with their
# compiled PVS) and unpacks the ones named (default: a small, a middle and a large one) into
# tools/corpus/data/ as .bsp files, for `level-corpus`. Needs apt (Debian's archive) and python3.
# The data stays out of git (tools/corpus/data/ is ignored).
#
#   tools/corpus/openarena.sh [MAP ...]     e.g. oa_dm1 aggressor oa_ctf2
set -euo pipefail
maps=("${@:-oa_ctf2 aggressor oa_dm1}")
read -r -a maps <<<"${maps[*]}"
exec "$(dirname "$0")/pk3-levels.sh" openarena-081-maps ./usr/share/games/openarena/baseoa/pak1-maps.pk3 \
  ./usr/share/doc/openarena-081-maps/copyright "" "${maps[@]}"
