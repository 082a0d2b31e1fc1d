#!/usr/bin/env bash
# Regenerates the checked-in SPIR-V next to each shader source:
#   preview/shaders/compile.sh            write NAME.spv for every NAME.glsl (but common.glsl),
#                                         and the variant select_naive.comp.spv
#   preview/shaders/compile.sh --check    compile into a temp dir and fail if a .spv is stale
# Needs glslangValidator (Debian: glslang-tools). `cargo build` needs only the .spv files.
set -euo pipefail
cd "$(dirname "$0")"
check=0
[ "${1:-}" = "--check" ] && check=1
out=.
if [ $check = 1 ]; then out=$(mktemp -d); trap 'rm -rf "$out"' EXIT; fi
status=0
# NAME.spv from NAME.glsl, plus variants: "source output defines...".
builds=()
for src in *.glsl; do
  [ "$src" = common.glsl ] && continue
  builds+=("$src ${src%.glsl}.spv")
done
builds+=("select.comp.glsl select_naive.comp.spv -DNAIVE_ARITHMETIC")
for b in "${builds[@]}"; do
  set -- $b
  src=$1 spv=$2
  shift 2
  glslangValidator -V --target-env vulkan1.3 "$@" -o "$out/$spv" "$src" >/dev/null
  if [ $check = 1 ] && ! cmp -s "$out/$spv" "$spv"; then
    echo "stale: preview/shaders/$spv (run preview/shaders/compile.sh)" >&2
    status=1
  fi
done
exit $status
