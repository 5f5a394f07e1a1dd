#!/usr/bin/env bash
# Web tiles benchmark: `vts serve` transcoding its tiles to PNG / WebP on request, against nginx
# serving the same images written once by `vts export --layout xyz` (what go-pmtiles-style
# passthrough of an exported archive costs: no encode at request time). One run, this machine,
# wrk -t2 -c64 --latency over random existing tiles (bench/random_tiles.lua):
#   hot   the server's web tile cache holds every tile (a warm-up pass first): its req/s against
#         nginx's sendfile is the bar (>= 1.0x)
#   cold  the cache off ("cache_mib": 0): every request decodes our tile and encodes the image,
#         on --threads 1, so req/s is the transcoding throughput of one core per format
# Prints a markdown table with machine, date and commit.
#
#   bash bench/web_bench.sh [--vts PATH] [--duration 10s] [--input IMAGE] [--out FILE]
#
# Input: bench/.cache/earth_16384x8192.tif if present (see build_bench.sh), else the Earth JPEG
# upscaled 4x (8192x4096) with oiiotool; the archive is built once into bench/.cache.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG=""
DURATION=10s
INPUT=""
OUT_FILE=""
while (($#)); do
  case $1 in
    --duration) DURATION=$2; shift 2 ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
need wrk nginx curl
VTS=$(find_vts "$VTS_ARG")

[[ -n $INPUT ]] || INPUT=$(serve_input)
ARCHIVE=$CACHE/web_$(basename "${INPUT%.*}").pmtiles
build_once "$INPUT" "$ARCHIVE"
NAME=$(basename "${ARCHIVE%.pmtiles}")

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-web-bench.XXXXXX")
NGINX_PID=""
VTS_PID=""
stop_vts() {
  if [[ -n $VTS_PID ]]; then
    kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  fi
  VTS_PID=""
}
finish() {
  stop_vts
  [[ -n $NGINX_PID ]] && kill -QUIT "$NGINX_PID" 2>/dev/null && wait "$NGINX_PID" 2>/dev/null
  rm -rf "$T"
}
trap finish EXIT

# The peer's files: one export per format, with the server's default qualities.
for fmt in png webp; do
  echo "exporting $fmt tiles for nginx" >&2
  "$VTS" export "$ARCHIVE" --format "$fmt" --layout xyz -o "$T/static/$fmt" >/dev/null ||
    die "vts export --format $fmt failed"
done
(cd "$T/static/png" && find . -name '*.png' | sed 's|^\./||; s|\.png$||') | sort >"$T/zxy.txt"
NTILES=$(wc -l <"$T/zxy.txt")
((NTILES > 0)) || die "the export wrote no tiles"
start_nginx_static "$T/static" "$T" 1

# start_web CACHE_MIB: vts serve --threads 1 with the web tile cache at CACHE_MIB.
start_web() {
  echo "{\"web\": {\"cache_mib\": $1}}" >"$T/config.json"
  start_vts_serve "$ARCHIVE" "$T" 1 --config "$T/config.json"
  VTS_PORT=$PORT
}

to_ms() {
  awk -v v="$1" 'BEGIN { n = v + 0; if (v ~ /us$/) n /= 1000; else if (v ~ /ms$/) ; else if (v ~ /s$/) n *= 1000; printf "%.2f", n }'
}
declare -A RPS P99 ERR
run_wrk() { # KEY BASE LIST
  local log="$T/wrk_$1.txt"
  wrk -t2 -c64 -d"$DURATION" --latency -s "$BENCH_DIR/random_tiles.lua" "$2" -- "$3" tiles \
    >"$log" 2>&1 || die "wrk failed: $(cat "$log")"
  RPS[$1]=$(awk '/^Requests\/sec:/ { printf "%.0f", $2 }' "$log")
  P99[$1]=$(to_ms "$(awk '$1 == "99%" { print $2 }' "$log")")
  ERR[$1]=$(awk '/Non-2xx or 3xx/ { print $NF }' "$log")
  echo "$1: ${RPS[$1]} req/s, p99 ${P99[$1]} ms ${ERR[$1]:+non-2xx ${ERR[$1]}}" >&2
}

for fmt in png webp; do
  sed "s|^|/$fmt/|; s|\$|.$fmt|" "$T/zxy.txt" >"$T/nginx.$fmt"
  sed "s|^|/$NAME/|; s|\$|.$fmt|" "$T/zxy.txt" >"$T/vts.$fmt"
  run_wrk "nginx.$fmt" "http://127.0.0.1:$NGINX_PORT" "$T/nginx.$fmt"

  start_web 0
  # Sanity: same size and content class as the export (both encoded by the same library).
  p=$(head -1 "$T/zxy.txt")
  curl -sf -o "$T/one.$fmt" "http://127.0.0.1:$VTS_PORT/$NAME/$p.$fmt" || die "no $fmt tile $p"
  cmp -s "$T/one.$fmt" "$T/static/$fmt/$p.$fmt" || die "vts serve and vts export differ on $p.$fmt"
  run_wrk "cold.$fmt" "http://127.0.0.1:$VTS_PORT" "$T/vts.$fmt"
  stop_vts

  start_web 4096
  sed "s|^|url = \"http://127.0.0.1:$VTS_PORT|; s|\$|\"\noutput = \"/dev/null\"|" "$T/vts.$fmt" \
    >"$T/warm.cfg"
  curl -sSf --parallel --parallel-max 8 --no-progress-meter -K "$T/warm.cfg" || die "warm-up of the web cache failed"
  run_wrk "hot.$fmt" "http://127.0.0.1:$VTS_PORT" "$T/vts.$fmt"
  stop_vts
done

{
  echo "### Web tiles: vts serve transcoding vs nginx serving vts export's files ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- input: $(basename "$INPUT"), $NTILES tiles of 256x256; vts serve --threads 1, nginx 1 worker (sendfile)"
  echo "- wrk -t2 -c64 -d$DURATION --latency, bench/random_tiles.lua over every tile"
  echo
  echo "| format | server | req/s | p99 ms | req/s vs nginx | p99 vs nginx |"
  echo "|---|---|---:|---:|---:|---:|"
  for fmt in png webp; do
    for k in "nginx.$fmt" "hot.$fmt" "cold.$fmt"; do
      case ${k%%.*} in
        nginx) label="nginx, exported files" ;;
        hot) label="vts serve, cache hot" ;;
        cold) label="vts serve, no cache (1 core transcoding)" ;;
      esac
      echo "| $fmt | $label | ${RPS[$k]} | ${P99[$k]} | $(ratio "${RPS[$k]}" "${RPS[nginx.$fmt]}") | $(ratio "${P99[$k]}" "${P99[nginx.$fmt]}") |"
    done
  done
} | tee "${OUT_FILE:-/dev/null}"
