#!/usr/bin/env bash
# Client stack benchmark: against `vts serve` on loopback, in one run,
#   curl   one `curl --parallel --parallel-max 32` fetching every tile URL of the pyramid
#   vts    the same tiles cold through the full client (fetch + checksum + disk cache write +
#          decode) with 32 requests in flight: bench/client_bench.cpp
#   disk / RAM hit latency p50/p99 of TileCache::get (same driver)
#   breakdown: the client's fetch alone, and the decode alone from memory (same driver)
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
    --vts) VTS_ARG=$2; shift 2 ;;
    --driver) DRIVER=$2; shift 2 ;;
    --out) OUT_FILE=$2; shift 2 ;;
    *) die "unknown argument '$1'" ;;
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

t0=$(date +%s.%N)
curl -s --parallel --parallel-max 32 -K "$T/curl.cfg" || die "curl failed"
t1=$(date +%s.%N)
CURL_S=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.3f", b - a }')
"$DRIVER" "$BASE" --cache-dir "$T/cache" --in-flight 32 >"$T/client.json" || die "driver failed"
J=$(cat "$T/client.json")
field() { python3 -c "import json,sys; print(json.loads(sys.argv[1])[sys.argv[2]])" "$J" "$1"; }
COLD=$(field cold_s)
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
  echo "| disk hit p50 / p99 | $(field disk_hit_p50_us) / $(field disk_hit_p99_us) us | p50 <= 100 us |"
  echo "| RAM hit p50 / p99 | $(field ram_hit_p50_us) / $(field ram_hit_p99_us) us | p50 <= 5 us |"
} | tee "${OUT_FILE:-/dev/null}"
