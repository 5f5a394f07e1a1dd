#!/usr/bin/env bash
# The main job: set up, build vtstream (RelWithDebInfo, into build/), and build a pyramid archive.
#
#   bash scripts/run.sh                  # Earth JPEG -> out/earth.pmtiles, then `vts info` on it
#   bash scripts/run.sh IN.tif -o X.pmtiles [vts build options...]   # your own `vts build` run
#
# Extra arguments are passed to `vts build` instead of the default ones.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh

echo "[run] configuring build/ (RelWithDebInfo, the same build the tests use)"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DVTS_BUILD_RENDERER="${VTS_BUILD_RENDERER:-OFF}" >/dev/null
echo "[run] building"
cmake --build build -j2 --target vts

VTS=build/cli/vts
if (($# > 0)); then
  echo "[run] vts build $*"
  exec "$VTS" build "$@"
fi

mkdir -p out
echo "[run] vts build /usr/share/xplanet/images/earth.jpg -o out/earth.pmtiles"
"$VTS" build /usr/share/xplanet/images/earth.jpg -o out/earth.pmtiles
echo "[run] vts info out/earth.pmtiles"
"$VTS" info out/earth.pmtiles
