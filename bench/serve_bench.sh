#!/usr/bin/env bash
# Tile serving benchmark: `vts serve` against nginx serving the same tiles
# extracted as static files (sendfile on, access_log off, 2 workers), on this machine in one run,
# with wrk -t2 -c64 --latency and bench/random_tiles.lua:
#   tiles  random existing tiles (GET /earth/z/x/y): vts answers a hot tile from its RAM tile cache
#          (tile_cache_mib, default 256 MiB; a miss reads it with pread), nginx sendfiles
#   304    the same with a matching If-None-Match (each server's own ETags)
#   range  random tile-sized Range reads of /earth.pmtiles (206)
# Prints a markdown table (req/s, MB/s, p50, p99, ratio vs nginx) with machine, date and commit.
#
#   bash bench/serve_bench.sh [--vts PATH] [--duration 10s] [--workers N] [--input IMAGE] [--out FILE]
#
# --workers N (default 1): nginx worker processes and vts serve --threads, the same for both. On
# this 2-core machine wrk needs about one core: with 2 workers each server's threads contend with
# wrk's and p99 measures that contention (ticks of preemption); with 1 it measures the server.
#
# Input: bench/.cache/earth_16384x8192.tif if present (see build_bench.sh), else the Earth JPEG
# upscaled 4x (8192x4096) with oiiotool. The archive is built once into bench/.cache.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG=""
DURATION=10s
WORKERS=1
INPUT=""
OUT_FILE=""
while (($#)); do
  case $1 in
    --duration) DURATION=$2; shift 2 ;;
    --workers) WORKERS=$2; shift 2 ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
[[ $WORKERS =~ ^[1-9][0-9]*$ ]] || die "--workers must be a positive integer, not '$WORKERS'"
need wrk nginx curl dd
VTS=$(find_vts "$VTS_ARG")
DUMP=${PMTILES_DUMP:-$(dirname "$VTS")/../tests/integration/pmtiles_dump}
[[ -x $DUMP ]] || die "no pmtiles_dump at $DUMP (build the tests, or set PMTILES_DUMP)"

[[ -n $INPUT ]] || INPUT=$(serve_input)
ARCHIVE=$CACHE/serve_$(basename "${INPUT%.*}").pmtiles
build_once "$INPUT" "$ARCHIVE"

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-serve-bench.XXXXXX")
NGINX_PID=""
VTS_PID=""
finish() {
  [[ -n $VTS_PID ]] && kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  [[ -n $NGINX_PID ]] && kill -QUIT "$NGINX_PID" 2>/dev/null && wait "$NGINX_PID" 2>/dev/null
  rm -rf "$T"
}
trap finish EXIT

# Static copy for nginx: every stored tile as the file earth/z/x/y, plus the archive itself.
extract_static "$ARCHIVE" "$T"
cp "$ARCHIVE" "$T/static/earth.pmtiles"
awk '{ print "/earth/" $2 "/" $3 "/" $4 }' "$T/offsets" >"$T/tiles.txt"
awk '{ print "/earth.pmtiles", $5, $5 + $6 - 1 }' "$T/offsets" >"$T/ranges.txt"
NTILES=$(wc -l <"$T/tiles.txt")
TILE_BYTES=$(awk '{ s += $6 } END { print s }' "$T/offsets")
start_nginx_static "$T/static" "$T" "$WORKERS"

"$VTS" serve "$ARCHIVE" --listen 127.0.0.1:0 --admin 127.0.0.1:0 --threads "$WORKERS" \
  >"$T/vts.out" 2>"$T/vts.err" &
VTS_PID=$!
for ((i = 0; i < 100; i++)); do
  grep -q 'listening on' "$T/vts.out" 2>/dev/null && break
  sleep 0.05
done
VTS_PORT=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+) .*|\1|p' "$T/vts.out")
VTS_ADMIN=$(sed -nE 's|.*admin http://[^ ]*:([0-9]+)\).*|\1|p' "$T/vts.out")
[[ -n $VTS_PORT ]] || die "vts serve did not start: $(cat "$T/vts.err")"
# The archive is named serve_<input>; serve it under /earth like nginx's copy.
VTS_NAME=$(basename "${ARCHIVE%.pmtiles}")
for ((i = 0; i < 100; i++)); do
  curl -sf -o /dev/null "http://127.0.0.1:$NGINX_PORT/earth.pmtiles" -r 0-0 && break
  sleep 0.05
done

declare -A BASE=([vts]="http://127.0.0.1:$VTS_PORT" [nginx]="http://127.0.0.1:$NGINX_PORT")
declare -A PREFIX=([vts]="/$VTS_NAME" [nginx]="/earth")

# Lists per server (path prefix differs; the tile set is the same), and each server's ETags.
for s in vts nginx; do
  sed "s|^/earth|${PREFIX[$s]}|" "$T/tiles.txt" >"$T/$s.tiles"
  sed "s|^/earth|${PREFIX[$s]}|" "$T/ranges.txt" >"$T/$s.ranges"
  sed "s|^|url = \"${BASE[$s]}|; s|\$|\"\noutput = \"/dev/null\"|" "$T/$s.tiles" >"$T/$s.curlcfg"
  curl -s -I -K "$T/$s.curlcfg" -w '%{url_effective} %header{etag}\n' |
    sed -E "s|^${BASE[$s]}||" >"$T/$s.inm"
  [[ $(awk 'NF == 2' "$T/$s.inm" | wc -l) == "$NTILES" ]] || die "$s: missing ETags"
done
# Sanity: the same bytes from both for a few tiles.
for p in $(shuf -n 20 "$T/tiles.txt"); do
  cmp -s <(curl -sf "${BASE[vts]}${p/#\/earth/${PREFIX[vts]}}") \
    <(curl -sf "${BASE[nginx]}$p") || die "vts and nginx differ on $p"
done

to_ms() { # wrk latency like 1.23ms / 456.00us / 1.20s
  awk -v v="$1" 'BEGIN { n = v + 0; if (v ~ /us$/) n /= 1000; else if (v ~ /ms$/) ; else if (v ~ /s$/) n *= 1000; printf "%.2f", n }'
}
to_mb() { # wrk Transfer/sec like 1.49GB / 600.00MB / 12.00KB
  awk -v v="$1" 'BEGIN { n = v + 0; if (v ~ /GB$/) n *= 1024; else if (v ~ /KB$/) n /= 1024; else if (v ~ /B$/ && v !~ /MB$/) n /= 1048576; printf "%.1f", n }'
}
# CPU time (user + system, clock ticks) used so far by a server: vts's process, or nginx's master
# and workers. Per request, it is the figure a busy shared machine disturbs least.
server_ticks() { # SERVER
  local pids
  if [[ $1 == vts ]]; then pids=$VTS_PID; else pids="$NGINX_PID $(pgrep -P "$NGINX_PID" | tr '\n' ' ')"; fi
  # shellcheck disable=SC2086
  for p in $pids; do awk '{ print $14 + $15 }' "/proc/$p/stat"; done | awk '{ s += $1 } END { print s }'
}
CLK_TCK=$(getconf CLK_TCK)
# vts's tile cache counters so far: "HITS MISSES".
tile_cache_counts() {
  curl -sf "http://127.0.0.1:$VTS_ADMIN/metrics" |
    awk '$1 == "vts_tile_cache_hits_total" { h = $2 } $1 == "vts_tile_cache_misses_total" { m = $2 }
         END { print h + 0, m + 0 }'
}
declare -A RPS MBS P50 P99 ERR CPU HITS
run_wrk() { # SERVER MODE LIST
  local s=$1 mode=$2 list=$3 log="$T/wrk_$1_$2.txt" t0 t1 n c0 c1
  [[ $s == vts ]] && c0=$(tile_cache_counts)
  t0=$(server_ticks "$s")
  wrk -t2 -c64 -d"$DURATION" --latency -s "$BENCH_DIR/random_tiles.lua" "${BASE[$s]}" -- \
    "$list" "$mode" >"$log" 2>&1 || die "wrk failed: $(cat "$log")"
  t1=$(server_ticks "$s")
  if [[ $s == vts ]]; then
    c1=$(tile_cache_counts)
    HITS[$mode]=$(awk -v a="$c0" -v b="$c1" 'BEGIN { split(a, x, " "); split(b, y, " ");
      h = y[1] - x[1]; m = y[2] - x[2]; printf "%.1f", (h + m) ? 100 * h / (h + m) : 0 }')
  fi
  n=$(awk '/requests in/ { print $1 }' "$log")
  CPU[$s.$mode]=$(awk -v a="$t0" -v b="$t1" -v n="$n" -v hz="$CLK_TCK" 'BEGIN { printf "%.1f", (b - a) / hz * 1e6 / n }')
  RPS[$s.$mode]=$(awk '/^Requests\/sec:/ { printf "%.0f", $2 }' "$log")
  MBS[$s.$mode]=$(to_mb "$(awk '/^Transfer\/sec:/ { print $2 }' "$log")")
  P50[$s.$mode]=$(to_ms "$(awk '$1 == "50%" { print $2 }' "$log")")
  P99[$s.$mode]=$(to_ms "$(awk '$1 == "99%" { print $2 }' "$log")")
  ERR[$s.$mode]=$(awk '/Non-2xx or 3xx/ { print $NF } /Socket errors/ { print }' "$log" | head -1)
  echo "$s $mode: ${HITS[$mode]:+tile cache hits ${HITS[$mode]}%, }${RPS[$s.$mode]} req/s, ${MBS[$s.$mode]} MB/s, p50 ${P50[$s.$mode]} ms, p99 ${P99[$s.$mode]} ms, ${CPU[$s.$mode]} us CPU/req ${ERR[$s.$mode]}" >&2
}
for mode in tiles inm range; do
  for s in nginx vts; do
    case $mode in
      tiles) run_wrk "$s" tiles "$T/$s.tiles" ;;
      inm) run_wrk "$s" inm "$T/$s.inm" ;;
      range) run_wrk "$s" range "$T/$s.ranges" ;;
    esac
  done
done

{
  echo "### Serving: vts serve vs nginx static ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- input: $(basename "$INPUT"), $NTILES tiles, $(mb "$TILE_BYTES") MiB of tile payloads (avg $((TILE_BYTES / NTILES)) B)"
  echo "- wrk -t2 -c64 -d$DURATION --latency, bench/random_tiles.lua; nginx $(nginx -v 2>&1 | sed 's|.*/||') ($WORKERS workers, sendfile), vts serve --threads $WORKERS"
  echo "- vts tile cache (default tile_cache_mib) hits: tiles ${HITS[tiles]}%, 304 ${HITS[inm]}% of lookups"
  echo
  echo "| workload | server | req/s | MB/s | p50 ms | p99 ms | server CPU µs/req | req/s vs nginx | p99 vs nginx | CPU/req vs nginx |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"
  for mode in tiles inm range; do
    label=$mode
    [[ $mode == tiles ]] && label="random tiles (200)"
    [[ $mode == inm ]] && label="If-None-Match (304)"
    [[ $mode == range ]] && label="Range on .pmtiles (206)"
    for s in nginx vts; do
      echo "| $label | $s | ${RPS[$s.$mode]} | ${MBS[$s.$mode]} | ${P50[$s.$mode]} | ${P99[$s.$mode]} | ${CPU[$s.$mode]} | $(ratio "${RPS[$s.$mode]}" "${RPS[nginx.$mode]}") | $(ratio "${P99[$s.$mode]}" "${P99[nginx.$mode]}") | $(ratio "${CPU[$s.$mode]}" "${CPU[nginx.$mode]}") |"
    done
  done
} | tee "${OUT_FILE:-/dev/null}"
