#!/usr/bin/env bash
# The main job: set up, build vtstream (RelWithDebInfo, into build/), cut the Earth into a pyramid,
# serve it with `vts serve` on loopback and stream it into the viewer through the client cache.
#
#   bash scripts/run.sh                  # Earth JPEG -> out/earth.pmtiles -> vts serve -> vts view
#   bash scripts/run.sh IN.tif -o X.pmtiles [vts build options...]   # your own `vts build` run
#
# Extra arguments are passed to `vts build` instead of the default ones. With a display the viewer
# opens a window (Esc quits); without one it renders headless under Xvfb and writes
# out/earth-view.png and the per-frame statistics out/earth-view.json.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh

echo "[run] configuring build/ (RelWithDebInfo, the same build the tests use)"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DVTS_BUILD_RENDERER="${VTS_BUILD_RENDERER:-ON}" >/dev/null
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

if [[ ${VTS_BUILD_RENDERER:-ON} != ON ]]; then
  exit 0
fi
# Serve it on a free loopback port, and stop the server whatever happens next.
LOG=$(mktemp)
"$VTS" serve out/earth.pmtiles --listen 127.0.0.1:0 --no-admin >"$LOG" 2>&1 &
SERVER=$!
trap 'kill -TERM $SERVER 2>/dev/null; wait $SERVER 2>/dev/null; rm -f "$LOG"' EXIT
for ((i = 0; i < 100; i++)); do
  grep -q 'listening on' "$LOG" && break
  sleep 0.05
done
PORT=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+)[ ,].*|\1|p' "$LOG")
[[ -n $PORT ]] || { cat "$LOG" >&2; echo "[run] vts serve did not start" >&2; exit 1; }
URL="http://127.0.0.1:$PORT/earth"
echo "[run] vts serve out/earth.pmtiles on $URL"

if [[ -n ${DISPLAY:-}${WAYLAND_DISPLAY:-} ]]; then
  echo "[run] vts view $URL --cache-dir out/cache   (drag to pan, scroll to zoom, Esc quits)"
  "$VTS" view "$URL" --cache-dir out/cache
else
  echo "[run] no display: vts view $URL --headless under Xvfb -> out/earth-view.png"
  xvfb-run -a -s "-screen 0 1280x1024x24" "$VTS" view "$URL" --cache-dir out/cache --headless \
    --frames 300 --until-complete --screenshot out/earth-view.png --json >out/earth-view.json
  python3 - out/earth-view.json <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
last = r["frames"][-1]
print(f"[run] {len(r['frames'])} frames, full resolution at frame {r['complete_at']}; "
      f"{last['resident']} tiles resident, mip bias {last['mip_bias']}; "
      f"screenshot {r['screenshot']}, statistics {sys.argv[1]}")
PY
fi
