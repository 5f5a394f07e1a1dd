#!/usr/bin/env bash
# Streaming latency under simulated viewers: `vts loadtest` with N viewers on a camera path, the
# same viewers (paths, seeds) against each target one after the other in one run, on loopback,
# one server worker each:
#   nginx-png     nginx over a folder of PNG web tiles of the same Earth (`vts export --format png
#                 --layout xyz`, as gdal2tiles or any renderer leaves them), read through a
#                 TileJSON, the way any web map reads it;
#   vts-png-cold  `vts serve` transcoding its tiles to PNG on request (/{ts}/{z}/{x}/{y}.png, its
#                 web TileJSON), default settings (web cache 64 MiB), started afresh per path;
#   vts-png       the same route with every PNG already in its web cache (256 MiB, warmed by curl);
#   vts           `vts serve`, our native tiles;
#   nginx         nginx serving our native tiles as static files (the same bytes as `vts`).
# For each: requests/s, request latency p50 / p99, time to first visible tile and to full
# resolution after each camera move p50 / p99, errors, and the load generator's own CPU (user+sys
# of the `vts loadtest` process, /usr/bin/time) per request.
# Then the generator's throughput: `vts loadtest --threads 1` open loop (`--rate R`, each of
# --rates) against nginx-png: the achieved requests/s and requests per generator CPU-second
# (bar: one generator core sustains >= 5,000 requests/s).
# The archive is the Earth at 16384x8192 (the benchmarks' image) in 256-texel tiles. The viewers
# fly the same paths everywhere, but PNG tiles are on the WebMercatorQuad grid (the plain image in
# its top half, as `vts serve` places it) and native tiles on the archive's own grid, so the
# requests differ in number and size (the table says both).
#
#   bash bench/loadtest_bench.sh [--vts PATH] [--paths flyover:64,jumps:16] [--duration 30]
#                                [--fps 30] [--feedback 16] [--targets LIST] [--rates 5000,10000,20000]
#                                [--rate-viewers 256] [--rate-duration 20] [--report DIR]
#                                [--out FILE]
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG="" OUT_FILE="" REPORT="" LPATHS=flyover:64,jumps:16 DURATION=30 FPS=30 FEEDBACK=16
TARGETS=nginx-png,vts-png-cold,vts-png,vts,nginx RATES=5000,10000,20000 RATE_VIEWERS=256
RATE_DURATION=20 RATE_FPS=10
while (($#)); do
  case $1 in
    --paths) LPATHS=$2; shift 2 ;;
    --duration) DURATION=$2; shift 2 ;;
    --fps) FPS=$2; shift 2 ;;
    --feedback) FEEDBACK=$2; shift 2 ;;
    --targets) TARGETS=$2; shift 2 ;;
    --rates) RATES=$2; shift 2 ;;
    --rate-viewers) RATE_VIEWERS=$2; shift 2 ;;
    --rate-duration) RATE_DURATION=$2; shift 2 ;;
    --report) REPORT=$2; shift 2 ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
need nginx curl python3
LOAD_BEFORE=$(cut -d' ' -f1-3 /proc/loadavg)
VTS=$(find_vts "$VTS_ARG")
DUMP=$(dirname "$VTS")/../tests/integration/pmtiles_dump
[[ -x $DUMP ]] || die "no pmtiles_dump at $DUMP (build the tests)"
IFS=, read -r -a TARGET_LIST <<<"$TARGETS"
for t in "${TARGET_LIST[@]}"; do
  [[ $t =~ ^(nginx-png|vts-png-cold|vts-png|vts|nginx)$ ]] ||
    die "--targets takes nginx-png, vts-png-cold, vts-png, vts, nginx (got '$t')"
done

ARCHIVE=$(earth_archive serve_earth_16384x8192 16384x8192)
NAME=$(basename "${ARCHIVE%.pmtiles}")
# The PNG folder, exported once (the cold PNG encoder's output: byte for byte vts serve's PNGs).
PNG_DIR=$CACHE/${NAME}_png
if [[ ! -d $PNG_DIR || $ARCHIVE -nt $PNG_DIR ]]; then
  echo "[bench] exporting $PNG_DIR (once, not timed)" >&2
  rm -rf "$PNG_DIR"
  "$VTS" export "$ARCHIVE" --format png --layout xyz -o "$PNG_DIR.tmp" --quiet >&2 ||
    die "vts export --format png failed"
  mv "$PNG_DIR.tmp" "$PNG_DIR"
fi

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-loadtest-bench.XXXXXX")
SERVE_PIDS=() NGINX_PID=""
finish() {
  local p
  for p in "${SERVE_PIDS[@]}"; do kill -TERM "$p" 2>/dev/null && wait "$p" 2>/dev/null; done
  [[ -n $NGINX_PID ]] && kill -QUIT "$NGINX_PID" 2>/dev/null && wait "$NGINX_PID" 2>/dev/null
  rm -rf "$T"
}
trap finish EXIT
# The warm server: native tiles and PNGs, a web cache that holds every PNG.
mkdir -p "$T/hot" "$T/cold"
echo '{"web": {"cache_mib": 256}}' >"$T/hot/config.json"
start_vts_serve "$ARCHIVE" "$T/hot" 1 --config "$T/hot/config.json"
SERVE_PIDS+=("$VTS_PID")
HOT_PORT=$PORT
VTS_URL="http://127.0.0.1:$PORT/$NAME"

# nginx: our tiles as static files (earth/), the PNG folder (png/), and TileJSONs naming them.
extract_static "$ARCHIVE" "$T"
cp -r "$PNG_DIR" "$T/static/png"
start_nginx_static "$T/static" "$T" 1
retile() { # TEMPLATE: a TileJSON on stdin with its tiles replaced by TEMPLATE, on stdout
  python3 -c 'import json, sys; j = json.load(sys.stdin); j["tiles"] = [sys.argv[1]]; json.dump(j, sys.stdout)' "$1"
}
curl -sf "$VTS_URL.json" | retile "http://127.0.0.1:$NGINX_PORT/earth/{z}/{x}/{y}" \
  >"$T/static/earth.json" || die "no TileJSON from vts serve"
curl -sf "$VTS_URL.json?format=png" >"$T/static/vts-png.json" || die "no web TileJSON from vts serve"
retile "http://127.0.0.1:$NGINX_PORT/png/{z}/{x}/{y}.png" <"$T/static/vts-png.json" \
  >"$T/static/png.json"
chmod a+r "$T"/static/*.json
NGINX_BASE="http://127.0.0.1:$NGINX_PORT"
curl -sf -o "$T/one.png" "$NGINX_BASE/png/3/5/2.png" || die "nginx does not serve the PNG folder"
curl -sf "http://127.0.0.1:$HOT_PORT/$NAME/3/5/2.png" | cmp -s - "$T/one.png" ||
  die "vts serve's PNG of 3/5/2 is not the exported file"

# Every PNG into the warm server's web cache (encoded once each, before any run).
(cd "$PNG_DIR" && find . -name '*.png' | sed 's|^\./||') |
  sed "s|^|url = \"http://127.0.0.1:$HOT_PORT/$NAME/|; s|\$|\"\noutput = \"/dev/null\"|" >"$T/warm.cfg"
echo "warming the PNG cache of vts serve" >&2
curl -sSf --parallel --parallel-max 8 --no-progress-meter -K "$T/warm.cfg" ||
  die "warming the web cache failed"

url_of() { # TARGET: the URL vts loadtest is given
  case $1 in
    nginx-png) echo "$NGINX_BASE/png.json" ;;
    vts-png | vts-png-cold) echo "$NGINX_BASE/vts-png.json" ;;
    vts) echo "$VTS_URL" ;;
    nginx) echo "$NGINX_BASE/earth.json" ;;
  esac
}
# start_cold: a fresh vts serve with default settings on a new port; vts-png.json names it.
start_cold() {
  rm -f "$T/cold/vts.out"
  start_vts_serve "$ARCHIVE" "$T/cold" 1
  COLD_PID=$VTS_PID
  SERVE_PIDS+=("$COLD_PID")
  curl -sf "http://127.0.0.1:$PORT/$NAME.json?format=png" >"$T/static/vts-png.json" ||
    die "no web TileJSON from the cold vts serve"
}
stop_cold() {
  kill -TERM "$COLD_PID" 2>/dev/null && wait "$COLD_PID" 2>/dev/null
  SERVE_PIDS=("${SERVE_PIDS[0]}")
  curl -sf "$VTS_URL.json?format=png" >"$T/static/vts-png.json"
}

# run TARGET PATH VIEWERS: one run, its JSON in $T/PATH-TARGET.json and the generator's CPU
# (user+sys, s) and wall time in $T/PATH-TARGET.cpu.
run() {
  local args=(loadtest "$(url_of "$1")" --viewers "$3" --path "$2" --duration "$DURATION"
    --fps "$FPS" --feedback "$FEEDBACK" --json --quiet --max-error-rate 100%) # errors reported
  [[ -n $REPORT ]] && args+=(--report "$REPORT/$2-$1")
  echo "vts loadtest --path $2 --viewers $3 against $1" >&2
  measure_split "$T/$2-$1.json" "$T/$2-$1.err" "$VTS" "${args[@]}"
  ((M_RC == 0)) || die "vts loadtest against $1 failed ($M_RC): $(tail -3 "$T/$2-$1.err")"
  echo "$M_CPU2 $M_WALL" >"$T/$2-$1.cpu"
}

table() { # DIR PATH TARGET...: the markdown table of one path
  python3 - "$@" <<'PY'
import json, sys
d, path, targets = sys.argv[1], sys.argv[2], sys.argv[3:]
label = {"nginx-png": "nginx, PNG files", "vts-png-cold": "vts serve PNG, cold",
         "vts-png": "vts serve PNG, cached", "vts": "vts serve, native", "nginx": "nginx, native files"}
runs = {}
for t in targets:
  j = json.load(open(f"{d}/{path}-{t}.json"))
  cpu, wall = map(float, open(f"{d}/{path}-{t}.cpu").read().split())
  j["cpu"], j["wall"] = cpu, wall
  runs[t] = j
def ms(j, h, p): return j["latency_ns"][h][p] / 1e6
def per_req(j): return j["cpu"] / j["totals"]["requests"] * 1e6 if j["totals"]["requests"] else 0
rows = [
  ("requests", lambda j: j["totals"]["requests"], "{}"),
  ("requests/s", lambda j: j["totals"]["requests_per_s"], "{:.0f}"),
  ("KiB per request", lambda j: j["totals"]["bytes"] / max(1, j["totals"]["requests"]) / 1024, "{:.1f}"),
  ("request latency p50 (ms)", lambda j: ms(j, "total", "p50"), "{:.2f}"),
  ("request latency p99 (ms)", lambda j: ms(j, "total", "p99"), "{:.2f}"),
  ("first visible tile after a move, p50 (ms)", lambda j: ms(j, "first_visible", "p50"), "{:.1f}"),
  ("first visible tile after a move, p99 (ms)", lambda j: ms(j, "first_visible", "p99"), "{:.1f}"),
  ("full resolution after a move, p50 (ms)", lambda j: ms(j, "full_resolution", "p50"), "{:.1f}"),
  ("full resolution after a move, p99 (ms)", lambda j: ms(j, "full_resolution", "p99"), "{:.1f}"),
  ("moves not at full resolution in time", lambda j: j["simulation"]["moves_incomplete"], "{}"),
  ("errors", lambda j: j["totals"]["errors"], "{}"),
  ("generator CPU per request (µs, user+sys)", per_req, "{:.0f}"),
  ("generator late frames", lambda j: j["simulation"]["late_frames"], "{}"),
]
print("| measure | " + " | ".join(label[t] for t in targets) + " |")
print("|---|" + "---:|" * len(targets))
for name, f, fmt in rows:
  print(f"| {name} | " + " | ".join(fmt.format(f(runs[t])) for t in targets) + " |")
for t in targets:
  e = runs[t].get("errors_by_kind") or {}
  if e: print(f"\nErrors against {label[t]}: " + ", ".join(f"{k} {v}" for k, v in sorted(e.items())) + ".")
base = "nginx-png" if "nginx-png" in runs else None
if base:
  print()
  for t in targets:
    if t == base: continue
    a, b = runs[t], runs[base]
    def r(x, y): return f"{x / y:.2f}x" if y else "-"
    print(f"- {label[t]} / nginx PNG files: request p99 {r(ms(a, 'total', 'p99'), ms(b, 'total', 'p99'))}, "
          f"full resolution p50 {r(ms(a, 'full_resolution', 'p50'), ms(b, 'full_resolution', 'p50'))}, "
          f"p99 {r(ms(a, 'full_resolution', 'p99'), ms(b, 'full_resolution', 'p99'))}")
PY
}

IFS=, read -r -a PATHS <<<"$LPATHS"
for pv in "${PATHS[@]}"; do
  p=${pv%%:*} viewers=${pv##*:}
  [[ $viewers =~ ^[0-9]+$ ]] || die "--paths takes NAME:VIEWERS,... (got '$pv')"
  for t in "${TARGET_LIST[@]}"; do
    if [[ $t == vts-png-cold ]]; then
      start_cold
      run "$t" "$p" "$viewers"
      stop_cold
    else
      run "$t" "$p" "$viewers"
    fi
  done
  {
    echo
    echo "Path \`$p\`, $viewers viewers:"
    echo
    table "$T" "$p" "${TARGET_LIST[@]}"
  } >>"$T/table.md"
done

# Throughput of one generator: --threads 1, open loop at each rate, against nginx's PNG files.
# A run of 0.05 s with the same viewers measures the generator's start-up and shut-down CPU
# (256 client stacks), taken off for the steady-state figures.
IFS=, read -r -a RATE_LIST <<<"$RATES"
rate_run() { # NAME RATE DURATION: $T/NAME.json, M_CPU2 / M_WALL set
  measure_split "$T/$1.json" "$T/$1.err" "$VTS" loadtest "$NGINX_BASE/png.json" \
    --threads 1 --rate "$2" --viewers "$RATE_VIEWERS" --path jumps --fps "$RATE_FPS" \
    --duration "$3" --feedback "$FEEDBACK" --json --quiet --max-error-rate 100%
  ((M_RC == 0)) || die "vts loadtest --rate $2 failed ($M_RC): $(tail -3 "$T/$1.err")"
}
rate_run rate-startup 5000 0.05
STARTUP_CPU=$M_CPU2
{
  echo
  echo "Generator throughput: \`vts loadtest $NGINX_BASE/png.json --threads 1 --rate R --viewers $RATE_VIEWERS --path jumps --fps $RATE_FPS --duration $RATE_DURATION --feedback $FEEDBACK\` (start-up and shut-down: $STARTUP_CPU s CPU, from a 0.05 s run):"
  echo
  echo "| rate asked (req/s) | achieved (req/s) | idle slots | errors | request p99 (ms) | generator CPU s (user+sys) | wall s | cores used | CPU µs / request | same, net of start-up | requests / generator CPU-second, net | ≥ 5,000 per core |"
  echo "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
} >>"$T/table.md"
for r in "${RATE_LIST[@]}"; do
  [[ $r =~ ^[0-9]+$ ]] || die "--rates takes numbers (got '$r')"
  echo "vts loadtest --threads 1 --rate $r against nginx-png" >&2
  rate_run "rate-$r" "$r" "$RATE_DURATION"
  python3 - "$T/rate-$r.json" "$r" "$M_CPU2" "$M_WALL" "$STARTUP_CPU" <<'PY' >>"$T/table.md"
import json, sys
j = json.load(open(sys.argv[1]))
rate, cpu, wall, startup = (float(a) for a in sys.argv[2:6])
t = j["totals"]
n = max(1, t["requests"])
net = max(cpu - startup, 1e-9)
per_core = t["requests"] / net
# Met: the asked rate was kept (within 1%: the first slots pass while the viewers start) at
# 5,000 req/s or more, on at most one core's worth of CPU per 5,000 requests.
met = "yes" if rate >= 5000 and t["requests_per_s"] >= 0.99 * rate and per_core >= 5000 else "no"
print(f"| {rate:.0f} | {t['requests_per_s']:.0f} | {j['simulation']['idle_slots']} | {t['errors']} | "
      f"{j['latency_ns']['total']['p99'] / 1e6:.2f} | {cpu:.2f} | {wall:.2f} | {cpu / wall:.2f} | "
      f"{cpu / n * 1e6:.0f} | {net / n * 1e6:.0f} | {per_core:.0f} | {met} |")
PY
done

{
  echo "### Streaming latency: vts loadtest against nginx (PNG files), vts serve (PNG, native) ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- load before the run: $LOAD_BEFORE; after: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "- command: \`bash bench/loadtest_bench.sh --paths $LPATHS --duration $DURATION --fps $FPS --feedback $FEEDBACK --targets $TARGETS --rates $RATES --rate-viewers $RATE_VIEWERS --rate-duration $RATE_DURATION\`"
  echo "- archive: Earth 16384x8192, 256-texel tiles; PNG folder: \`vts export --format png --layout xyz\` ($(find "$PNG_DIR" -name '*.png' | wc -l) tiles, $(mb "$(bytes_of "$PNG_DIR")") MiB); each viewer its own client stack, no client caches; 1 server worker each; generator CPU: user+sys of the \`vts loadtest\` process (/usr/bin/time), start-up included"
  cat "$T/table.md"
} | tee "${OUT_FILE:-/dev/null}"
