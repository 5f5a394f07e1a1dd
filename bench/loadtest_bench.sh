#!/usr/bin/env bash
# Streaming latency under simulated viewers: `vts loadtest` with N viewers on a camera
# path against `vts serve`, and against nginx serving the same tiles as static files (the peer),
# one after the other in one run, on loopback:
#   - request latency p50 / p99 (from the intended send time), requests/s;
#   - time to first visible tile and to full resolution after each camera move, p50 / p99;
#   - how hard the load generator itself worked (late frames, demand CPU per frame).
# The archive is the Earth at 16384x8192 (the benchmarks' image) in 256-texel tiles.
#
#   bash bench/loadtest_bench.sh [--vts PATH] [--paths flyover:64,jumps:16] [--duration 30]
#                                [--fps 30] [--feedback 16] [--report DIR] [--out FILE]
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG="" OUT_FILE="" REPORT="" LPATHS=flyover:64,jumps:16 DURATION=30 FPS=30 FEEDBACK=16
while (($#)); do
  case $1 in
    --vts) VTS_ARG=$2; shift 2 ;;
    --paths) LPATHS=$2; shift 2 ;;
    --duration) DURATION=$2; shift 2 ;;
    --fps) FPS=$2; shift 2 ;;
    --feedback) FEEDBACK=$2; shift 2 ;;
    --report) REPORT=$2; shift 2 ;;
    --out) OUT_FILE=$2; shift 2 ;;
    *) die "unknown argument '$1'" ;;
  esac
done
need nginx curl python3
VTS=$(find_vts "$VTS_ARG")
DUMP=$(dirname "$VTS")/../tests/integration/pmtiles_dump
[[ -x $DUMP ]] || die "no pmtiles_dump at $DUMP (build the tests)"

ARCHIVE=$(earth_archive serve_earth_16384x8192 16384x8192)
NAME=$(basename "${ARCHIVE%.pmtiles}")

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-loadtest-bench.XXXXXX")
VTS_PID="" NGINX_PID=""
finish() {
  [[ -n $VTS_PID ]] && kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  [[ -n $NGINX_PID ]] && kill -QUIT "$NGINX_PID" 2>/dev/null && wait "$NGINX_PID" 2>/dev/null
  rm -rf "$T"
}
trap finish EXIT
start_vts_serve "$ARCHIVE" "$T" 1
VTS_URL="http://127.0.0.1:$PORT/$NAME"

# The peer: every stored tile as a static file, and a TileJSON naming nginx's tile URLs.
extract_static "$ARCHIVE" "$T"
start_nginx_static "$T/static" "$T" 1
curl -sf "$VTS_URL.json" | python3 -c '
import json, sys
j = json.load(sys.stdin)
j["tiles"] = ["http://127.0.0.1:'"$NGINX_PORT"'/earth/{z}/{x}/{y}"]
json.dump(j, sys.stdout)' >"$T/static/earth.json" || die "no TileJSON from vts serve"
NGINX_URL="http://127.0.0.1:$NGINX_PORT/earth.json"

run() { # LABEL URL PATH VIEWERS
  local args=(loadtest "$2" --viewers "$4" --path "$3" --duration "$DURATION" --fps "$FPS"
    --feedback "$FEEDBACK" --json --quiet --max-error-rate 100%) # errors are reported, not fatal
  [[ -n $REPORT ]] && args+=(--report "$REPORT/$3-$1")
  echo "vts loadtest --path $3 against $1" >&2
  "$VTS" "${args[@]}" >"$T/$3-$1.json" || die "vts loadtest against $1 failed"
}

table() { # VTS.json NGINX.json: the markdown table of one path
  python3 - "$1" "$2" <<'PY'
import json, sys
v, n = (json.load(open(p)) for p in sys.argv[1:3])
def ms(j, h, p): return j["latency_ns"][h][p] / 1e6
def ratio(a, b): return f"{a / b:.2f}x" if b else "-"
rows = [
  ("requests/s", lambda j: j["totals"]["requests_per_s"], "{:.0f}"),
  ("request latency p50 (ms)", lambda j: ms(j, "total", "p50"), "{:.2f}"),
  ("request latency p99 (ms)", lambda j: ms(j, "total", "p99"), "{:.2f}"),
  ("time to first byte p99 (ms)", lambda j: ms(j, "ttfb", "p99"), "{:.2f}"),
  ("first visible tile after a move, p50 (ms)", lambda j: ms(j, "first_visible", "p50"), "{:.1f}"),
  ("full resolution after a move, p50 (ms)", lambda j: ms(j, "full_resolution", "p50"), "{:.1f}"),
  ("full resolution after a move, p99 (ms)", lambda j: ms(j, "full_resolution", "p99"), "{:.1f}"),
  ("errors", lambda j: j["totals"]["errors"], "{}"),
]
print("| measure | vts serve | nginx | vts / nginx |")
print("|---|---|---|---|")
for name, f, fmt in rows:
  a, b = f(v), f(n)
  print(f"| {name} | {fmt.format(a)} | {fmt.format(b)} | {ratio(a, b) if name != 'errors' else '-'} |")
s = v["simulation"]
print()
print(f"Load generator (vts run): {s['viewer_frames']} viewer-frames, {s['late_frames']} late frames, "
      f"demand {s['demand_cpu_ms_per_frame']:.2f} ms CPU per viewer-frame, "
      f"{v['totals']['camera_moves']} camera moves, {s['moves_incomplete']} not at full resolution in time.")
PY
}

IFS=, read -r -a PATHS <<<"$LPATHS"
for pv in "${PATHS[@]}"; do
  p=${pv%%:*} viewers=${pv##*:}
  [[ $viewers =~ ^[0-9]+$ ]] || die "--paths takes NAME:VIEWERS,... (got '$pv')"
  run vts "$VTS_URL" "$p" "$viewers"
  run nginx "$NGINX_URL" "$p" "$viewers"
  {
    echo
    echo "Path \`$p\`, $viewers viewers:"
    echo
    table "$T/$p-vts.json" "$T/$p-nginx.json"
  } >>"$T/table.md"
done

{
  echo "### Streaming latency: vts loadtest against vts serve and nginx ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- command: \`bash bench/loadtest_bench.sh --paths $LPATHS --duration $DURATION --fps $FPS --feedback $FEEDBACK\`"
  echo "- archive: Earth 16384x8192, 256-texel tiles; each viewer its own client stack, no client caches; 1 server worker each"
  cat "$T/table.md"
} | tee "${OUT_FILE:-/dev/null}"
