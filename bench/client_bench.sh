#!/usr/bin/env bash
# Client stack benchmark: against `vts serve` on loopback, in one run,
#   curl   one `curl --parallel --parallel-max 32` fetching every tile URL of the pyramid
#   vts    the same tiles cold through the full client (fetch + checksum + disk cache write +
#          decode) with 32 requests in flight: bench/client_bench.cpp
#   disk / RAM hit latency p50/p99 of TileCache::get (same driver)
#   breakdown: the client's fetch alone, and the decode alone from memory (same driver)
#   CPU    the CPU seconds (user + sys) of curl, of the client in each phase, and of the server
#          while each ran: on 2 cores, (client + server CPU) / 2 is the least wall time the cold
#          path can take, whatever the overlap; the table prints that floor next to the bar
# Bars: cold <= 1.2x curl's time; disk hit p50 <= 100 us; RAM hit p50 <= 5 us.
#
#   bash bench/client_bench.sh [--vts PATH] [--driver PATH] [--out FILE] [--codec lossless|bc1]
# --codec bc1 runs the same on a bc1 build of the Earth (decode = zstd to blocks, no unfilter).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG="" DRIVER="" OUT_FILE="" CODEC=lossless
while (($#)); do
  case $1 in
    --codec) CODEC=$2; shift 2 ;;
    --driver) DRIVER=$2; shift 2 ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
need curl
VTS=$(find_vts "$VTS_ARG")
DRIVER=${DRIVER:-$(dirname "$VTS")/../bench/vts_client_bench}
[[ -x $DRIVER ]] || die "no vts_client_bench at $DRIVER (build with VTS_BUILD_BENCH=ON)"

[[ $CODEC == lossless || $CODEC == bc1 ]] || die "--codec must be lossless or bc1"
SUFFIX="" BUILD_ARGS=()
[[ $CODEC == bc1 ]] && SUFFIX=_bc1 BUILD_ARGS=(--codec bc1)
if [[ -r $CACHE/earth_16384x8192.tif ]]; then
  ARCHIVE=$(earth_archive "serve_earth_16384x8192$SUFFIX" 16384x8192 "${BUILD_ARGS[@]}")
else
  ARCHIVE=$(earth_archive "serve_earth_8192x4096$SUFFIX" 8192x4096 "${BUILD_ARGS[@]}")
fi
NAME=$(basename "${ARCHIVE%.pmtiles}")

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-client-bench.XXXXXX")
VTS_PID=""
finish() {
  [[ -n $VTS_PID ]] && kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  rm -rf "$T"
}
trap finish EXIT
start_vts_serve "$ARCHIVE" "$T" 2
BASE="http://127.0.0.1:$PORT/$NAME"

# Every tile URL of the pyramid, as the client will ask for them.
"$VTS" info "$ARCHIVE" --json >"$T/info.json"
python3 - "$T/info.json" "$BASE" >"$T/curl.cfg" <<'PY'
import json, math, sys
info = json.load(open(sys.argv[1]))
t = info["tile_size"]
for lv in info["levels"]:
    for y in range(math.ceil(lv["height"] / t)):
        for x in range(math.ceil(lv["width"] / t)):
            print(f'url = "{sys.argv[2]}/{lv["z"]}/{x}/{y}"\noutput = "/dev/null"')
PY
NTILES=$(grep -c '^url' "$T/curl.cfg")

# CPU seconds (user + sys) a process has used so far, from /proc/PID/stat.
proc_cpu() {
  awk -v hz="$(getconf CLK_TCK)" '{ sub(/.*\) /, ""); printf "%.3f", ($12 + $13) / hz }' "/proc/$1/stat"
}
s0=$(proc_cpu "$VTS_PID")
t0=$(date +%s.%N)
"$TIME_BIN" -f '%U %S' -o "$T/curl.time" curl -s --parallel --parallel-max 32 -K "$T/curl.cfg" ||
  die "curl failed"
t1=$(date +%s.%N)
s1=$(proc_cpu "$VTS_PID")
CURL_S=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.3f", b - a }')
CURL_CPU=$(awk '{ printf "%.3f", $1 + $2 }' "$T/curl.time")
CURL_SERVER_CPU=$(awk -v a="$s0" -v b="$s1" 'BEGIN { printf "%.3f", b - a }')
"$DRIVER" "$BASE" --cache-dir "$T/cache" --in-flight 32 --server-pid "$VTS_PID" \
  >"$T/client.json" || die "driver failed"
J=$(cat "$T/client.json")
field() { python3 -c "import json,sys; print(json.loads(sys.argv[1])[sys.argv[2]])" "$J" "$1"; }
COLD=$(field cold_s)
# "vts-decode 1.23 s, vts-disk 0.20 s, ...": the cold phase's CPU by thread.
THREADS=$(python3 -c "import json,sys; t = json.loads(sys.argv[1])['cold_threads_cpu_s']
print(', '.join(f'{k} {v:.2f} s' for k, v in sorted(t.items(), key=lambda kv: -kv[1])))" "$J")
# The least wall time on this machine's cores: all the CPU work spread over all of them.
floor() { awk -v a="$1" -v b="$2" -v n="$(nproc)" 'BEGIN { printf "%.3f", (a + b) / n }'; }
COLD_FLOOR=$(floor "$(field cold_cpu_s)" "$(field cold_server_cpu_s)")
CURL_FLOOR=$(floor "$CURL_CPU" "$CURL_SERVER_CPU")
{
  echo "### Client stack vs curl --parallel ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- tileset: $NAME (codec $CODEC), $NTILES tiles, $(mb "$(field bytes)") MiB of payloads; vts serve on loopback (2 threads)"
  echo "- curl: one \`curl --parallel --parallel-max 32\` over every tile URL; client: TileClient, 32 in flight, 2 decode threads, disk cache in a new folder"
  echo
  echo "| measure | value | bar |"
  echo "|---|---:|---|"
  echo "| curl --parallel, all tiles | ${CURL_S} s | |"
  echo "| client cold (fetch + checksum + disk write + decode) | ${COLD} s ($(ratio "$COLD" "$CURL_S")x curl) | <= 1.2x |"
  echo "| breakdown: fetch alone (the client's source, nothing else) | $(field fetch_only_s) s ($(ratio "$(field fetch_only_s)" "$CURL_S")x curl) | |"
  echo "| breakdown: decode alone, from memory, 2 threads | $(field decode_only_s) s ($(ratio "$(field decode_only_s)" "$CURL_S")x curl) | |"
  echo
  echo "CPU seconds (user + sys); floor = (client + server CPU) / $(nproc) cores, the least wall time the work allows here:"
  echo
  echo "| run | wall | client CPU | server CPU | floor |"
  echo "|---|---:|---:|---:|---:|"
  echo "| curl --parallel | ${CURL_S} s | ${CURL_CPU} s | ${CURL_SERVER_CPU} s | ${CURL_FLOOR} s |"
  echo "| client cold | ${COLD} s | $(field cold_cpu_s) s | $(field cold_server_cpu_s) s | ${COLD_FLOOR} s ($(ratio "$COLD_FLOOR" "$CURL_S")x curl's wall) |"
  echo "| fetch alone | $(field fetch_only_s) s | $(field fetch_only_cpu_s) s | $(field fetch_only_server_cpu_s) s | |"
  echo "| decode alone ($(field decode_threads) threads) | $(field decode_only_s) s | $(field decode_only_cpu_s) s | - | |"
  echo
  echo "- client cold CPU by thread: $THREADS"
  echo "- cold: first tile decoded at $(field cold_first_event_s) s, last at $(field cold_last_event_s) s; the rest of ${COLD} s is the final disk flush"
  echo
  echo "| measure | value | bar |"
  echo "|---|---:|---|"
  echo "| disk hit p50 / p99 | $(field disk_hit_p50_us) / $(field disk_hit_p99_us) us | p50 <= 100 us |"
  echo "| RAM hit p50 / p99 | $(field ram_hit_p50_us) / $(field ram_hit_p99_us) us | p50 <= 5 us |"
} | tee "${OUT_FILE:-/dev/null}"
