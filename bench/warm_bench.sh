#!/usr/bin/env bash
# `vts warm` cold into a fresh cache against the simplest persistent cache: one
# `curl --parallel --parallel-max 32` writing each tile of the same URLs to its own file. Both
# fetch every tile of the 16384x8192 Earth archive (2,731 tiles) from the same `vts serve` on
# loopback, in the same run; before each timed run the previous output is removed and dirty pages
# are written back (`sync`). Best of N (3) each; prints a markdown table and the ratio
# warm / curl (the bar: <= 1.5).
#
# Usage: bench/warm_bench.sh [--runs N] [--vts PATH] [--out FILE]
#   --runs N   timed runs of each (default 3; the best counts)
#   --vts      the vts executable (default build/cli/vts)
#   --out      also write the markdown to FILE
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

RUNS=3 VTS_ARG="" OUT_FILE=""
while (($#)); do
  case $1 in
    --runs)
      (($# >= 2)) || die "--runs needs a value"
      RUNS=$2
      shift 2
      ;;
    *)
      bench_option "$@"
      shift "$OPT_SHIFT"
      ;;
  esac
done
[[ $RUNS =~ ^[1-9][0-9]*$ ]] || die "--runs must be a positive integer"
need curl awk
VTS=$(find_vts "$VTS_ARG")
curl --help all 2>/dev/null | grep -q -- '--parallel-max' || die "curl lacks --parallel-max"

ARCHIVE=$(earth_archive earth_16384x8192 16384x8192)
WORK=$(mktemp -d "${TMPDIR:-/tmp}/vts-warm-bench.XXXXXX")
VTS_PID=""
trap '[[ -n $VTS_PID ]] && kill "$VTS_PID" 2>/dev/null; rm -rf "$WORK"' EXIT
start_vts_serve "$ARCHIVE" "$WORK" 2
NAME=$(basename "$ARCHIVE" .pmtiles)
BASE="http://127.0.0.1:$PORT/$NAME"

# Every tile of the pyramid (16384x8192, 256-texel tiles: levels 0-6), as curl's config lines.
W=16384 H=8192 T=256 MAXZ=6
: >"$WORK/curl.cfg"
for ((z = 0; z <= MAXZ; z++)); do
  s=$((MAXZ - z))
  nx=$(((((W + (1 << s) - 1) >> s) + T - 1) / T))
  ny=$(((((H + (1 << s) - 1) >> s) + T - 1) / T))
  for ((y = 0; y < ny; y++)); do
    for ((x = 0; x < nx; x++)); do
      printf 'url = "%s/%d/%d/%d"\noutput = "%s/files/%d_%d_%d"\n' \
        "$BASE" "$z" "$x" "$y" "$WORK" "$z" "$x" "$y" >>"$WORK/curl.cfg"
    done
  done
done
TILES=$(grep -c '^url' "$WORK/curl.cfg")

# now: seconds since the epoch, ns resolution.
now() { date +%s.%N; }
# best_of NAME PREP CMD...: runs PREP then CMD (timed alone) RUNS times; sets BEST (seconds).
best_of() {
  local name=$1 prep=$2 i t0 t1 t
  shift 2
  BEST=""
  for ((i = 1; i <= RUNS; i++)); do
    eval "$prep"
    sync
    t0=$(now)
    local rc=0
    "$@" >"$WORK/$name.out" 2>"$WORK/$name.err" || rc=$?
    ((rc == 0)) || die "$name exited $rc: $(tail -c 300 "$WORK/$name.err")"
    t1=$(now)
    t=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.3f", b - a }')
    echo "[bench] $name run $i: $t s" >&2
    if [[ -z $BEST ]] || awk -v a="$t" -v b="$BEST" 'BEGIN { exit !(a < b) }'; then BEST=$t; fi
  done
}

# shellcheck disable=SC2016  # PREP expands when best_of evals it
best_of curl 'rm -rf "$WORK/files"; mkdir -p "$WORK/files"' \
  curl -sf --parallel --parallel-max 32 -K "$WORK/curl.cfg"
CURL_S=$BEST
FILES=$(find "$WORK/files" -type f | wc -l)
((FILES == TILES)) || die "curl wrote $FILES of $TILES tiles"
# shellcheck disable=SC2016
best_of warm 'rm -rf "$WORK/cache"' \
  "$VTS" warm "$BASE" --cache-dir "$WORK/cache" --concurrency 32 --json
WARM_S=$BEST
grep -q '"complete": true' "$WORK/warm.out" || die "vts warm did not complete"
BYTES=$(bytes_of "$WORK/files")

{
  echo "### vts warm vs curl to files ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- load average at start: $(cut -d' ' -f1-3 /proc/loadavg) (a shared machine: figures vary run to run)"
  echo "- $TILES tiles, $(mb "$BYTES") MiB, from \`vts serve\` on 127.0.0.1; best of $RUNS, \`sync\` before each"
  echo
  echo "| client | best wall (s) |"
  echo "|---|---:|"
  echo "| curl --parallel --parallel-max 32, one file per tile | $CURL_S |"
  echo "| vts warm --concurrency 32, fresh cache | $WARM_S |"
  echo
  echo "warm / curl = **$(ratio "$WARM_S" "$CURL_S")x** (bar: <= 1.5x)"
} | tee "${OUT_FILE:-/dev/null}"
