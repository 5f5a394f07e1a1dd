#!/usr/bin/env bash
# `vts warm` cold into a fresh cache against the simplest persistent cache: one
# `curl --parallel --parallel-max 32` writing each tile of the same URLs to its own file. Both
# fetch every tile of the 16384x8192 Earth archive (2,731 tiles) from the same `vts serve` on
# loopback, in the same run, and write under the same folder (--dir); before each timed run the
# previous output is removed and dirty pages are written back (`sync`). Best of N (3) each, wall
# and CPU (user + system of the client alone); prints markdown tables and the ratio warm / curl
# (the bar: <= 1.0 where creating files is cheap, e.g. a tmpfs: run it with --dir /dev/shm).
#
# Also measured in the same run:
# - the folder's file-creation rate: creating and writing one file per tile, of the average tile
#   size, with a tiny Python loop (no network), so the ratio can be read against how cheap files
#   are there;
# - a table of the cache's SQLite settings for `vts warm` (VTS_WARM_SQLITE_PRAGMAS run after the
#   shipped ones: WAL checkpoint size, page cache, mmap, and for reference the unsafe
#   synchronous=OFF and the single-process locking_mode=EXCLUSIVE); --no-settings skips it.
#
# Usage: bench/warm_bench.sh [--runs N] [--dir DIR] [--no-settings] [--vts PATH] [--out FILE]
#   --runs N        timed runs of each (default 3; the best counts)
#   --dir DIR       where curl's files and warm's cache go (default: a folder under $TMPDIR or /tmp)
#   --no-settings   skip the table of SQLite settings
#   --vts           the vts executable (default build/cli/vts)
#   --out           also write the markdown to FILE
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

RUNS=3 VTS_ARG="" OUT_FILE="" DIR_ARG="" SETTINGS=1
while (($#)); do
  case $1 in
    --runs | --dir)
      (($# >= 2)) || die "$1 needs a value"
      if [[ $1 == --runs ]]; then RUNS=$2; else DIR_ARG=$2; fi
      shift 2
      ;;
    --no-settings)
      SETTINGS=0
      shift
      ;;
    *)
      bench_option "$@"
      shift "$OPT_SHIFT"
      ;;
  esac
done
[[ $RUNS =~ ^[1-9][0-9]*$ ]] || die "--runs must be a positive integer"
need curl awk python3
VTS=$(find_vts "$VTS_ARG")
curl --help all 2>/dev/null | grep -q -- '--parallel-max' || die "curl lacks --parallel-max"

ARCHIVE=$(earth_archive earth_16384x8192 16384x8192)
WORK=$(mktemp -d "${TMPDIR:-/tmp}/vts-warm-bench.XXXXXX")
if [[ -n $DIR_ARG ]]; then
  [[ -d $DIR_ARG ]] || die "--dir $DIR_ARG is not a folder"
  OUTDIR=$(mktemp -d "$DIR_ARG/vts-warm-bench.XXXXXX")
else
  OUTDIR=$WORK/out
  mkdir -p "$OUTDIR"
fi
VTS_PID=""
trap '[[ -n $VTS_PID ]] && kill "$VTS_PID" 2>/dev/null; rm -rf "$WORK" "$OUTDIR"' EXIT
start_vts_serve "$ARCHIVE" "$WORK" 2
NAME=$(basename "$ARCHIVE" .pmtiles)
BASE="http://127.0.0.1:$PORT/$NAME"
FSTYPE=$(stat -f -c %T "$OUTDIR")

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
        "$BASE" "$z" "$x" "$y" "$OUTDIR" "$z" "$x" "$y" >>"$WORK/curl.cfg"
    done
  done
done
TILES=$(grep -c '^url' "$WORK/curl.cfg")

# now: seconds since the epoch, ns resolution.
now() { date +%s.%N; }
# timed NAME PREP CMD...: runs PREP, `sync`, then CMD (timed alone; user + system CPU from
# /usr/bin/time); sets T_WALL and T_CPU (seconds).
timed() {
  local name=$1 prep=$2 t0 t1
  shift 2
  eval "$prep"
  sync
  t0=$(now)
  measure_split "$WORK/$name.out" "$WORK/$name.err" "$@"
  t1=$(now)
  ((M_RC == 0)) || die "$name exited $M_RC: $(tail -c 300 "$WORK/$name.err")"
  T_WALL=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.3f", b - a }')
  T_CPU=$M_CPU2
}
# keep_best NAME: folds T_WALL / T_CPU into BEST_WALL[NAME] / BEST_CPU[NAME] (each its minimum).
declare -A BEST_WALL BEST_CPU
keep_best() {
  local name=$1
  echo "[bench] $name: ${T_WALL} s wall, ${T_CPU} s CPU" >&2
  if [[ -z ${BEST_WALL[$name]:-} ]] || awk -v a="$T_WALL" -v b="${BEST_WALL[$name]}" 'BEGIN { exit !(a < b) }'; then
    BEST_WALL[$name]=$T_WALL
  fi
  if [[ -z ${BEST_CPU[$name]:-} ]] || awk -v a="$T_CPU" -v b="${BEST_CPU[$name]}" 'BEGIN { exit !(a < b) }'; then
    BEST_CPU[$name]=$T_CPU
  fi
}

# shellcheck disable=SC2016  # PREP expands when timed evals it
CURL_PREP='rm -rf "$OUTDIR/files"; mkdir -p "$OUTDIR/files"'
# shellcheck disable=SC2016
WARM_PREP='rm -rf "$OUTDIR/cache"'
run_curl() {
  timed curl "$CURL_PREP" curl -sf --no-progress-meter --parallel --parallel-max 32 -K "$WORK/curl.cfg"
  keep_best curl
}
# run_warm NAME [PRAGMAS]: one fresh `vts warm` with VTS_WARM_SQLITE_PRAGMAS=PRAGMAS.
run_warm() {
  timed "$1" "$WARM_PREP" env VTS_WARM_SQLITE_PRAGMAS="${2:-}" \
    "$VTS" warm "$BASE" --cache-dir "$OUTDIR/cache" --concurrency 32 --json
  grep -q '"complete": true' "$WORK/$1.out" || die "vts warm ($1) did not complete"
  keep_best "$1"
}

# The file-creation rate of the folder: TILES files of the average tile size, written and closed
# one after another (what curl does, without the network), timed inside the loop (no interpreter
# start); sets FILES_S to the best of RUNS.
file_rate() {
  local i t
  FILES_S=""
  for ((i = 1; i <= RUNS; i++)); do
    rm -rf "$OUTDIR/synthetic"
    t=$(python3 -c '
import os, sys, time
d, n, size = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
buf = os.urandom(size)
os.mkdir(d)
t0 = time.perf_counter()
for i in range(n):
    with open(os.path.join(d, str(i)), "wb") as f:
        f.write(buf)
print("%.3f" % (time.perf_counter() - t0))
' "$OUTDIR/synthetic" "$TILES" "$AVG_BYTES")
    echo "[bench] creating $TILES files: $t s" >&2
    if [[ -z $FILES_S ]] || awk -v a="$t" -v b="$FILES_S" 'BEGIN { exit !(a < b) }'; then FILES_S=$t; fi
  done
  rm -rf "$OUTDIR/synthetic"
}

# Curl and warm alternate, so a burst of load elsewhere hits both.
for ((i = 1; i <= RUNS; i++)); do
  run_curl
  run_warm warm
done
FILES=$(find "$OUTDIR/files" -type f | wc -l)
((FILES == TILES)) || die "curl wrote $FILES of $TILES tiles"
BYTES=$(bytes_of "$OUTDIR/files")
AVG_BYTES=$((BYTES / TILES))
file_rate

# The settings table: label | PRAGMAs run after the shipped settings.
SETTINGS_ROWS=(
  "shipped: WAL checkpoint every 32 MiB, synchronous=NORMAL, 16 KiB pages|"
  "WAL checkpoint every 2 MiB (the cache's default)|PRAGMA wal_autocheckpoint = 128; PRAGMA journal_size_limit = 2097152"
  "WAL checkpoint every 8 MiB|PRAGMA wal_autocheckpoint = 512; PRAGMA journal_size_limit = 8388608"
  "WAL checkpoint every 128 MiB (none during the run)|PRAGMA wal_autocheckpoint = 8192; PRAGMA journal_size_limit = 134217728"
  "page cache 32 MiB (no spill inside a batch)|PRAGMA cache_size = -32768"
  "mmap_size 256 MiB|PRAGMA mmap_size = 268435456"
  "synchronous=OFF (reference only: a power cut may corrupt)|PRAGMA synchronous = OFF"
  "locking_mode=EXCLUSIVE (reference only: one process)|PRAGMA locking_mode = EXCLUSIVE"
)
if ((SETTINGS)); then
  for ((i = 1; i <= RUNS; i++)); do
    for ((r = 0; r < ${#SETTINGS_ROWS[@]}; r++)); do
      run_warm "setting$r" "${SETTINGS_ROWS[r]#*|}"
    done
  done
fi

per_s() { awk -v n="$1" -v s="$2" 'BEGIN { if (s + 0 == 0) print "-"; else printf "%.0f", n / s }'; }
{
  echo "### vts warm vs curl to files ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- load average at start: $(cut -d' ' -f1-3 /proc/loadavg) (a shared machine: figures vary run to run)"
  echo "- $TILES tiles, $(mb "$BYTES") MiB, from \`vts serve\` on 127.0.0.1; best of $RUNS, \`sync\` before each"
  echo "- written under $(dirname "$OUTDIR") ($FSTYPE): creating $TILES files of $AVG_BYTES bytes there" \
    "takes $FILES_S s, **$(per_s "$TILES" "$FILES_S") files/s**" \
    "($(per_s "$(mb "$BYTES")" "$FILES_S") MiB/s; best of $RUNS)"
  echo
  echo "| client | best wall (s) | best CPU (s) |"
  echo "|---|---:|---:|"
  echo "| curl --parallel --parallel-max 32, one file per tile | ${BEST_WALL[curl]} | ${BEST_CPU[curl]} |"
  echo "| vts warm --concurrency 32, fresh cache | ${BEST_WALL[warm]} | ${BEST_CPU[warm]} |"
  echo
  echo "warm / curl = **$(ratio "${BEST_WALL[warm]}" "${BEST_WALL[curl]}")x** wall," \
    "$(ratio "${BEST_CPU[warm]}" "${BEST_CPU[curl]}")x CPU (bar: <= 1.0x where creating files is cheap)"
  if ((SETTINGS)); then
    echo
    echo "SQLite settings of \`vts warm\` (each row: the shipped settings plus that change; same run):"
    echo
    echo "| setting | best wall (s) | best CPU (s) | wall / shipped |"
    echo "|---|---:|---:|---:|"
    for ((r = 0; r < ${#SETTINGS_ROWS[@]}; r++)); do
      echo "| ${SETTINGS_ROWS[r]%%|*} | ${BEST_WALL[setting$r]} | ${BEST_CPU[setting$r]} |" \
        "$(ratio "${BEST_WALL[setting$r]}" "${BEST_WALL[setting0]}") |"
    done
  fi
} | tee "${OUT_FILE:-/dev/null}"
