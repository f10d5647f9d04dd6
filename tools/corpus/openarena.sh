#!/usr/bin/env bash
# Fetches OpenArena's levels (GPL-2+, Debian's openarena-081-maps: 50 Quake III levels with their
# compiled PVS) and unpacks the ones named (default: a small, a middle and a large one) into
# tools/corpus/data/ as .bsp files, for `level-corpus`. Needs apt (Debian's archive) and unzip or
# python3. The data stays out of git (tools/corpus/data/ is ignored).
#
#   tools/corpus/openarena.sh [MAP ...]     e.g. oa_dm1 aggressor oa_ctf2
set -euo pipefail
cd "$(dirname "$0")"
maps=("${@:-oa_ctf2 aggressor oa_dm1}")
read -r -a maps <<<"${maps[*]}"
mkdir -p data
deb=$(ls data/openarena-081-maps_*.deb 2>/dev/null | head -1 || true)
if [ -z "$deb" ]; then
  if ! (cd data && apt-get download openarena-081-maps 2>/dev/null); then
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    (cd data && apt-get download openarena-081-maps)
  fi
  deb=$(ls data/openarena-081-maps_*.deb | head -1)
fi
pk3=data/pak1-maps.pk3
if [ ! -f "$pk3" ]; then
  dpkg-deb --fsys-tarfile "$deb" | tar -xO ./usr/share/games/openarena/baseoa/pak1-maps.pk3 >"$pk3.tmp"
  mv "$pk3.tmp" "$pk3"
  dpkg-deb --fsys-tarfile "$deb" | tar -xO ./usr/share/doc/openarena-081-maps/copyright >data/COPYRIGHT-openarena
fi
for m in "${maps[@]}"; do
  python3 -c "import sys, zipfile; open('data/'+sys.argv[1]+'.bsp','wb').write(zipfile.ZipFile('$pk3').read('maps/'+sys.argv[1]+'.bsp'))" "$m"
  echo "data/$m.bsp"
done
