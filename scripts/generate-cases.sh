#!/usr/bin/env bash
# Writes the large and nasty test cases into DIR (default /tmp/mres-cases), for benchmarks and
# for trying the CI job on meshes that are not in the repository:
#   scripts/generate-cases.sh [DIR] && target/release/bake-all DIR -o DIR/out --no-cache
# With --huge, writes only the sharding cases: a 5M-triangle terrain (bakes whole or sharded)
# and a 50M-triangle terrain (3.8 GB of OBJ; the streaming importer and sharding bake it):
#   scripts/generate-cases.sh --huge [DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
huge=false
if [ "${1:-}" = "--huge" ]; then
  huge=true
  shift
fi
dir=${1:-/tmp/mres-cases}
mkdir -p "$dir"
cargo build --release --quiet -p mres-cli
g() { target/release/mres generate "$@"; }
if $huge; then
  g terrain 1582 -o "$dir/terrain-5M.obj"
  g terrain 5000 -o "$dir/terrain-50M.obj"
  exit 0
fi
g sphere 204 -o "$dir/sphere-0.5M.obj"          # closed, with normals
g sphere 408 -o "$dir/sphere-2M.obj"
g terrain 1000 -o "$dir/terrain-2M.obj"         # open height field with UVs
g boxes 1600 -o "$dir/city-1600-boxes.obj"      # 1,600 disconnected parts
g boxes 10000 -o "$dir/city-10000-boxes.obj"
g cards 20000 -o "$dir/foliage-cards.obj"       # aggregate geometry: 20,000 open quads
g seamed-sphere 100 -o "$dir/uv-seams-6-materials.obj"
g defects 100 -o "$dir/holes-fins-duplicates.obj"   # holes, non-manifold fins, duplicate triangles
