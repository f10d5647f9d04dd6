#!/usr/bin/env bash
# The FZK-Haus (KIT/IAI: a two-storey family house with an attic, as an IFC building model; "fine
# to redistribute", attribution kept) from Debian's assimp-testmodels, converted by assimp to an OBJ
# with one group per material, as exporters group a building: tools/corpus/data/fzk-haus.obj.
#
#   tools/corpus/fzk-haus.sh
set -euo pipefail
cd "$(dirname "$0")"
ifc=/usr/share/assimp/models/IFC/AC14-FZK-Haus.ifc
need=()
[ -f "$ifc" ] || need+=(assimp-testmodels)
command -v assimp >/dev/null 2>&1 || need+=(assimp-utils)
if [ ${#need[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
fi
mkdir -p data
assimp export "$ifc" data/fzk-haus-assimp.obj >/dev/null
# assimp writes one object with a material switch per part: each material becomes a group.
awk '/^usemtl /{ print "g " substr($0, 8) } { print }' data/fzk-haus-assimp.obj >data/fzk-haus.obj
cp "$(dirname "$ifc")/AC14-FZK-Haus.source.txt" data/fzk-haus.source.txt
echo data/fzk-haus.obj
