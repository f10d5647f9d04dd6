#!/usr/bin/env bash
# Unpacks Quake III-format levels (.bsp) from a game's pk3 archive in one of Debian's packages
# into tools/corpus/data/ as PREFIXMAP.bsp, for `level-corpus`. The games' own scripts call it
# (openarena.sh, nexuiz.sh). Needs apt (Debian's archive) and python3. The package, the pk3 and
# the levels stay out of git (tools/corpus/data/ is ignored).
#
#   tools/corpus/pk3-levels.sh PACKAGE PK3_IN_PACKAGE COPYRIGHT_IN_PACKAGE PREFIX MAP...
set -euo pipefail
if [ $# -lt 5 ]; then
  echo "usage: $0 PACKAGE PK3_IN_PACKAGE COPYRIGHT_IN_PACKAGE PREFIX MAP..." >&2
  exit 2
fi
cd "$(dirname "$0")"
package=$1 inside=$2 copyright=$3 prefix=$4
shift 4
mkdir -p data
deb=$(ls data/"${package}"_*.deb 2>/dev/null | head -1 || true)
if [ -z "$deb" ]; then
  if ! (cd data && apt-get download "$package" 2>/dev/null); then
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    (cd data && apt-get download "$package")
  fi
  deb=$(ls data/"${package}"_*.deb | head -1)
fi
pk3=data/$package.pk3
if [ ! -f "$pk3" ]; then
  dpkg-deb --fsys-tarfile "$deb" | tar -xO "$inside" >"$pk3.tmp"
  mv "$pk3.tmp" "$pk3"
fi
[ -f "data/COPYRIGHT-$package" ] || dpkg-deb --fsys-tarfile "$deb" | tar -xO "$copyright" >"data/COPYRIGHT-$package"
for m in "$@"; do
  # Read before the output is opened: a map the archive lacks leaves no empty file behind.
  python3 -c "
import sys, zipfile
name = 'maps/' + sys.argv[2] + '.bsp'
try:
    b = zipfile.ZipFile(sys.argv[1]).read(name)
except KeyError:
    sys.exit(sys.argv[1] + ': no ' + name)
open(sys.argv[3], 'wb').write(b)" \
    "$pk3" "$m" "data/$prefix$m.bsp"
  echo "data/$prefix$m.bsp"
done
