#!/usr/bin/env bash
# Writes the large and nasty test cases into DIR (default /tmp/mres-cases), for benchmarks and
# for trying the CI job on meshes that are not in the repository:
#   scripts/generate-cases.sh [DIR] && target/release/bake-all DIR -o DIR/out --no-cache
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-/tmp/mres-cases}
mkdir -p "$dir"
cargo build --release --quiet -p mres-baker
g() { target/release/mres generate "$@"; }
g sphere 204 -o "$dir/sphere-0.5M.obj"          # closed, with normals
g sphere 408 -o "$dir/sphere-2M.obj"
g terrain 1000 -o "$dir/terrain-2M.obj"         # open height field with UVs
g boxes 1600 -o "$dir/city-1600-boxes.obj"      # 1,600 disconnected parts
g boxes 10000 -o "$dir/city-10000-boxes.obj"
g cards 20000 -o "$dir/foliage-cards.obj"       # aggregate geometry: 20,000 open quads
g seamed-sphere 100 -o "$dir/uv-seams-6-materials.obj"
g defects 100 -o "$dir/holes-fins-duplicates.obj"   # holes, non-manifold fins, duplicate triangles
