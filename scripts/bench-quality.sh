#!/usr/bin/env bash
# Quality at equal measured error (docs/BENCHMARKS.md): runs `mres bench` on every mesh in
# MESH_DIR and on generated cases, one JSON report per input in OUT_DIR, and writes the
# summary table OUT_DIR/quality.md:
#   scripts/bench-quality.sh [MESH_DIR] [OUT_DIR]
# MESH_DIR defaults to ../shared/meshes, OUT_DIR to target/bench-quality. Inputs run smallest
# first; one that fails is reported in the table and the others still run.
# Environment: SAMPLES (points per direction and cut, default 200000), MAX_BYTES (skip mesh
# files larger than this, default: none), GENERATED (0 to skip the generated cases),
# MRES (the mres binary; default: built here with cargo build --release).
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
# Defaults are relative to the repository root, arguments to the current directory.
mesh_dir=$(cd "$repo" && realpath -m "${1:-../shared/meshes}")
out=$(cd "$repo" && realpath -m "${2:-target/bench-quality}")
[ -z "${1:-}" ] || mesh_dir=$(realpath -m "$1")
[ -z "${2:-}" ] || out=$(realpath -m "$2")
samples=${SAMPLES:-200000}
max_bytes=${MAX_BYTES:-}
generated=${GENERATED:-1}
if [ -z "${MRES:-}" ]; then
  (cd "$repo" && cargo build --release --quiet -p mres-cli --bin mres)
  MRES=$repo/target/release/mres
fi
command -v jq >/dev/null || { echo "bench-quality.sh: needs jq" >&2; exit 2; }
[ -d "$mesh_dir" ] || { echo "bench-quality.sh: $mesh_dir is not a directory" >&2; exit 2; }
mkdir -p "$out"

# Generated cases of moderate size (scripts/generate-cases.sh writes larger ones; pass its
# directory as MESH_DIR to bench those).
if [ "$generated" != 0 ]; then
  mkdir -p "$out/generated"
  g() { [ -s "$out/generated/$3" ] || "$MRES" generate "$1" "$2" -o "$out/generated/$3" >/dev/null; }
  g sphere 64 sphere-49k.obj
  g terrain 160 terrain-51k.obj
  g boxes 250 city-250-boxes.obj
  g cards 5000 foliage-cards-5000.obj
  g seamed-sphere 48 uv-seams-6-materials.obj
  g defects 48 holes-fins-duplicates.obj
  g walls 80 walls-standing-inside-a-floor.obj
fi

inputs=()
while IFS= read -r line; do
  inputs+=("${line#* }")
done < <(
  {
    find "$mesh_dir" -maxdepth 1 -type f \( -iname '*.obj' -o -iname '*.glb' -o -iname '*.gltf' -o -iname '*.ply' \) \
      ${max_bytes:+-size -"${max_bytes}"c}
    [ "$generated" = 0 ] || find "$out/generated" -maxdepth 1 -type f -name '*.obj'
  } | while IFS= read -r f; do echo "$(stat -c %s "$f") $f"; done | sort -n
)

table=$out/quality.md
{
  echo "| mesh | input tris | ratio at equal mean error (geomean) | worst (at error) | ratio at equal max error (geomean) | worst (at error) | bake s mres | bake s clusterlod |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|"
} > "$table"
for f in "${inputs[@]}"; do
  name=$(basename "$f")
  json=$out/${name%.*}.${name##*.}.json
  echo "== $name" >&2
  if ! "$MRES" bench "$f" --samples "$samples" --report "$json" > "$out/${name}.txt" 2>&1; then
    echo "| $name | failed: $(tail -n 1 "$out/${name}.txt" | tr '|' '/') | | | | | | |" >> "$table"
    continue
  fi
  cat "$out/${name}.txt" >&2
  jq -r --arg name "$name" '
    def r: if . == null then "-" else (. * 1000 | round / 1000 | tostring) end;
    def e: if . == null then "" else " (" + (. | tostring) + ")" end;
    "| \($name) | \(.runs[0].input_triangles) | \(.quality.mean.geomean_ratio | r) over \(.quality.mean.compared) | \(.quality.mean.worst_ratio | r)\(.quality.mean.worst_target | e) | \(.quality.max.geomean_ratio | r) over \(.quality.max.compared) | \(.quality.max.worst_ratio | r)\(.quality.max.worst_target | e) | \(.runs[0].seconds * 100 | round / 100) | \(.runs[1].seconds * 100 | round / 100) |"
  ' "$json" >> "$table"
done
echo "Ratios are triangles mres / clusterlod at equal measured error (below 1: mres needs fewer), at most $samples samples per direction and cut." >> "$table"
cat "$table"
