#!/usr/bin/env bash
# Vendors 3DTilesRendererJS (npm `3d-tiles-renderer`, Apache-2.0) for the viewer's 3D Tiles page as
# one ES module whose only import is `three` (the viewer's own three.js, through its import map):
# three's GLTFLoader and BufferGeometryUtils, which the package imports as `three/addons/…`, are
# bundled in (MIT, like the rest of three). Needs node and the npm registry; writes
# src/cli/viewer/3d-tiles-renderer.min.js and its licence beside it.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$here/../../src/cli/viewer"
TILES=0.5.3 THREE=0.181.2 ESBUILD=0.28.2
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
npm init -y >/dev/null
npm install --silent --no-audit --no-fund "3d-tiles-renderer@$TILES" "three@$THREE" "esbuild@$ESBUILD"
cat > entry.js <<'JS'
export { TilesRenderer } from '3d-tiles-renderer/three';
JS
cat > build.mjs <<JS
import * as esbuild from 'esbuild';
await esbuild.build({
  entryPoints: ['entry.js'], bundle: true, format: 'esm', minify: true, legalComments: 'none',
  banner: { js: '/* 3d-tiles-renderer $TILES (Apache-2.0: /3d-tiles-renderer-LICENSE.txt) with three $THREE GLTFLoader and BufferGeometryUtils (MIT: /three-LICENSE.txt); bundled by tools/viewer/vendor-3d-tiles.sh */' },
  outfile: 'bundle.min.js',
  plugins: [{ name: 'three-external', setup(b) { b.onResolve({ filter: /^three\$/ }, () => ({ path: 'three', external: true })); } }],
});
JS
node build.mjs
cp bundle.min.js "$out/3d-tiles-renderer.min.js"
cp node_modules/3d-tiles-renderer/LICENSE "$out/3d-tiles-renderer-LICENSE.txt"
echo "vendored 3d-tiles-renderer $TILES into $out"
