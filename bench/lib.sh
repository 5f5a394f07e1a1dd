# shellcheck shell=bash disable=SC2034  # variables here are used by the scripts that source this file
# Shared helpers for the benchmark scripts (sourced, not run).
set -euo pipefail

BENCH_DIR="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$BENCH_DIR/.." && pwd)"
CACHE="$BENCH_DIR/.cache"
EARTH=/usr/share/xplanet/images/earth.jpg
TIME_BIN=/usr/bin/time

die() {
  printf '%s: %s\n' "$(basename "$0")" "$*" >&2
  exit 1
}
need() {
  local t
  for t in "$@"; do
    command -v "$t" >/dev/null 2>&1 || die "missing '$t' (run scripts/setup.sh)"
  done
}

# bench_option ARGS...: the options every benchmark script takes, read off the front of ARGS
# (the script's own options are matched before it): --vts PATH sets VTS_ARG, --out FILE sets
# OUT_FILE, --input IMAGE sets INPUT (only where the script set INPUT before, so it takes one),
# -h/--help prints the script's header comment and exits; anything else dies naming it. Sets
# OPT_SHIFT to the number of words used, for the caller's `shift "$OPT_SHIFT"`.
bench_option() {
  OPT_SHIFT=2
  case $1 in
    --vts | --out | --input) (($# >= 2)) || die "$1 needs a value" ;;
  esac
  case $1 in
    --vts) VTS_ARG=$2 ;;
    --out) OUT_FILE=$2 ;;
    --input)
      [[ -n ${INPUT+set} ]] || die "unknown argument '$1' (see --help)"
      INPUT=$2
      ;;
    -h | --help)
      sed -n '2,/^# shellcheck/p' "$0" | sed '$d; s/^# \{0,1\}//'
      exit 0
      ;;
    *) die "unknown argument '$1' (see --help)" ;;
  esac
}

# find_vts [PATH]: prints the vts executable to benchmark (default build/cli/vts from run.sh).
find_vts() {
  local vts=${1:-$ROOT/build/cli/vts}
  [[ -x $vts ]] || die "no vts executable at $vts (build it with: bash scripts/run.sh)"
  printf '%s\n' "$vts"
}

# measure LOG CMD...: runs CMD under /usr/bin/time -v (stdout+stderr to LOG) and sets
# M_RC (exit code), M_WALL (seconds), M_RSS_MB (peak resident set, MiB), M_CPU (user+sys seconds,
# to 0.1 s) and M_CPU2 (the same to 0.01 s, /usr/bin/time's resolution: for sums of short runs).
measure() {
  local log=$1
  shift
  measure_split "$log" "$log" "$@"
}

# measure_split OUT ERR CMD...: measure, with CMD's stdout to OUT and its stderr to ERR (e.g. the
# JSON a `--json` run prints, kept apart from its warnings).
measure_split() {
  local out=$1 err=$2 tf
  shift 2
  tf=$(mktemp)
  set +e
  if [[ $out == "$err" ]]; then
    "$TIME_BIN" -v -o "$tf" "$@" >"$out" 2>&1 </dev/null
  else
    "$TIME_BIN" -v -o "$tf" "$@" >"$out" 2>"$err" </dev/null
  fi
  M_RC=$?
  set -e
  M_WALL=$(awk -F': ' '/Elapsed \(wall clock\)/ {
      n = split($2, p, ":"); s = 0; for (i = 1; i <= n; i++) s = s * 60 + p[i]; printf "%.2f", s }' "$tf")
  M_RSS_MB=$(awk -F': ' '/Maximum resident set size/ { printf "%.0f", $2 / 1024 }' "$tf")
  M_CPU2=$(awk -F': ' '/User time/ { u = $2 } /System time/ { s = $2 } END { printf "%.2f", u + s }' "$tf")
  M_CPU=$(awk -v c="$M_CPU2" 'BEGIN { printf "%.1f", c }')
  rm -f "$tf"
}

# bytes_of PATH...: total size in bytes of files and directories.
bytes_of() {
  du -scb "$@" | awk 'END { print $1 }'
}

# machine_info: markdown lines describing this machine and the date.
machine_info() {
  local cpu mem
  cpu=$(awk -F': ' '/^model name/ { print $2; exit }' /proc/cpuinfo)
  mem=$(awk '/^MemTotal/ { printf "%.1f GiB", $2 / 1048576 }' /proc/meminfo)
  echo "- machine: $(nproc) cores ($cpu), $mem RAM, $(uname -sr)"
  echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "- vtstream: $(git -C "$ROOT" describe --always --dirty 2>/dev/null || echo 'no git revision')"
}

ratio() { # A B: A/B to 2 decimals, or "-" when B is 0/empty
  awk -v a="$1" -v b="$2" 'BEGIN { if (b + 0 == 0) print "-"; else printf "%.2f", a / b }'
}
mb() { awk -v b="$1" 'BEGIN { printf "%.1f", b / 1048576 }'; }

# earth_tif [WxH]: the Earth resized to WxH (default 8192x4096) as a TIFF in $CACHE, made once.
# Prints its path.
earth_tif() {
  local size=${1:-8192x4096} input
  mkdir -p "$CACHE"
  input=$CACHE/earth_$size.tif
  if [[ ! -r $input ]]; then
    need oiiotool
    oiiotool "$EARTH" --resize:filter=lanczos3 "$size" -d uint8 -o "$input" >&2 || die "resize failed"
  fi
  echo "$input"
}

# earth_16k_tif: $CACHE/earth_16384x8192.tif, made once: the Earth upscaled 8x with a Lanczos-3
# filter, stored as an uncompressed 8-bit RGB TIFF (so decoding it costs next to nothing). Prints
# its path.
earth_16k_tif() {
  local input=$CACHE/earth_16384x8192.tif
  mkdir -p "$CACHE"
  if [[ ! -s $input ]]; then
    echo "[bench] making $input (once): $EARTH upscaled 8x, Lanczos-3" >&2
    oiiotool "$EARTH" --resize:filter=lanczos3 16384x8192 -d uint8 --compression none \
      -o "$input.tmp.tif" >&2 || die "resize failed"
    mv "$input.tmp.tif" "$input"
  fi
  echo "$input"
}

# earth_100k_tif: $CACHE/earth_100000x50000.tif, made once: issue 20's size, the Earth upscaled
# 48.8x (bilinear) by vips into a tiled (256x256), JPEG-compressed (Q92) BigTIFF (streaming, ~300 MB
# on disk), the way large rasters ship; it also exercises the tiled-input path. About a minute to
# make. Prints its path.
earth_100k_tif() {
  local big=$CACHE/earth_100000x50000.tif
  mkdir -p "$CACHE"
  if [[ ! -s $big ]]; then
    need vips
    echo "[bench] making $big (once)" >&2
    vips resize "$EARTH" "$big.tmp.tif[tile,tile-width=256,tile-height=256,compression=jpeg,Q=92,bigtiff]" \
      48.828125 --kernel linear >&2 || die "vips resize failed"
    mv "$big.tmp.tif" "$big"
  fi
  echo "$big"
}

# serve_input: the image the serving benchmarks build their archive from: earth_16k_tif's image
# when it is there, else earth_tif 8192x4096. Prints its path.
serve_input() {
  if [[ -r $CACHE/earth_16384x8192.tif ]]; then
    echo "$CACHE/earth_16384x8192.tif"
  else
    earth_tif 8192x4096
  fi
}

# build_once INPUT ARCHIVE [BUILD ARGS...]: `$VTS build INPUT -o ARCHIVE` unless ARCHIVE exists
# and is newer than INPUT.
build_once() {
  local input=$1 archive=$2
  shift 2
  mkdir -p "$(dirname "$archive")"
  if [[ ! -s $archive || $input -nt $archive ]]; then
    echo "[bench] building $archive from $input (once, not timed)" >&2
    "$VTS" build "$input" -o "$archive" "$@" >/dev/null || die "vts build $input failed"
  fi
}

# earth_archive NAME [WxH [BUILD ARGS...]]: earth_tif WxH, and its archive $CACHE/NAME.pmtiles
# built by $VTS (with BUILD ARGS, e.g. --codec bc1: give each set of arguments its own NAME); both
# reused while current. Prints the archive.
earth_archive() {
  local name=$1 size=${2:-8192x4096} input
  shift $(($# < 2 ? $# : 2))
  input=$(earth_tif "$size")
  build_once "$input" "$CACHE/$name.pmtiles" "$@"
  echo "$CACHE/$name.pmtiles"
}

# start_vts_serve ARCHIVE DIR [THREADS [SERVE ARGS...]]: `$VTS serve` on a free loopback port
# (no admin listener; SERVE ARGS added, e.g. --config FILE), logs in DIR; sets VTS_PID and PORT
# (the caller's EXIT trap stops VTS_PID).
start_vts_serve() {
  local archive=$1 dir=$2 threads=${3:-2}
  shift $(($# < 3 ? $# : 3))
  "$VTS" serve "$archive" --listen 127.0.0.1:0 --no-admin --threads "$threads" "$@" \
    >"$dir/vts.out" 2>"$dir/vts.err" &
  VTS_PID=$!
  local i
  for ((i = 0; i < 100; i++)); do
    grep -q 'listening on' "$dir/vts.out" 2>/dev/null && break
    sleep 0.05
  done
  PORT=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+)[ ,].*|\1|p' "$dir/vts.out")
  [[ -n $PORT ]] || die "vts serve did not start: $(cat "$dir/vts.err")"
}

# free_port: a TCP port nobody listens on now on this machine.
free_port() {
  local p
  while :; do
    p=$((20000 + RANDOM % 30000))
    ss -ltn | awk '{ print $4 }' | grep -q ":$p\$" || { echo "$p"; return; }
  done
}

# extract_static ARCHIVE DIR: the peer's copy of an archive: every stored tile as the file
# DIR/static/earth/z/x/y (the archive's offsets listed in DIR/offsets by pmtiles_dump, $DUMP).
extract_static() {
  local archive=$1 dir=$2 _ z x y off len
  echo "extracting tiles for nginx" >&2
  mkdir -p "$dir/static/earth"
  "$DUMP" offsets "$archive" >"$dir/offsets" || die "pmtiles_dump offsets $archive failed"
  while read -r _ z x y off len; do
    mkdir -p "$dir/static/earth/$z/$x"
    dd if="$archive" of="$dir/static/earth/$z/$x/$y" iflag=skip_bytes,count_bytes skip="$off" \
      count="$len" status=none
  done <"$dir/offsets"
}

# start_nginx_static ROOT DIR WORKERS: nginx serving ROOT as static files on a free loopback port
# (sendfile on, access log off), unprivileged, its files in DIR/nginx; sets NGINX_PID and
# NGINX_PORT once it answers (the caller's EXIT trap stops NGINX_PID with SIGQUIT).
start_nginx_static() {
  local root=$1 dir=$2/nginx workers=$3 i
  chmod a+rX "$2"  # nginx's workers run as another user: they need to reach ROOT
  chmod -R a+rX "$root"
  NGINX_PORT=$(free_port)
  mkdir -p "$dir/logs"
  cat >"$dir/nginx.conf" <<CONF
worker_processes $workers;
daemon off;
pid $dir/nginx.pid;
error_log $dir/error.log warn;
events { worker_connections 4096; }
http {
  access_log off;
  sendfile on;
  tcp_nopush on;
  tcp_nodelay on;
  keepalive_requests 1000000;
  default_type application/octet-stream;
  client_body_temp_path $dir/body;
  proxy_temp_path $dir/proxy;
  fastcgi_temp_path $dir/fastcgi;
  uwsgi_temp_path $dir/uwsgi;
  scgi_temp_path $dir/scgi;
  server {
    listen 127.0.0.1:$NGINX_PORT;
    root $root;
    location / { }
  }
}
CONF
  nginx -p "$dir" -c "$dir/nginx.conf" 2>"$dir/stderr" &
  NGINX_PID=$!
  for ((i = 0; i < 100; i++)); do
    curl -s -o /dev/null "http://127.0.0.1:$NGINX_PORT/" && return
    sleep 0.05
  done
  die "nginx did not start: $(cat "$dir/stderr")"
}

# best_of NAME CMD...: runs CMD $RUNS times, after the caller's `before_run NAME` (to remove the
# previous run's output) when it defines one, and keeps the fastest run's figures: BEST[NAME] (wall
# seconds), CPU[NAME] and RSS[NAME] (of that run), in the global associative arrays BEST, CPU
# and RSS. Each run's output goes to $OUTDIR/NAME.log; a failed run stops the benchmark.
best_of() {
  local name=$1 i
  shift
  declare -gA BEST CPU RSS # the caller's, when it declared them (their values are kept)
  for ((i = 1; i <= RUNS; i++)); do
    if declare -F before_run >/dev/null; then before_run "$name"; fi
    measure "$OUTDIR/$name.log" "$@"
    ((M_RC == 0)) || die "$name failed (exit $M_RC): $(tail -n 5 "$OUTDIR/$name.log")"
    echo "[bench] $name run $i: ${M_WALL}s" >&2
    if [[ -z ${BEST[$name]:-} ]] || awk -v a="$M_WALL" -v b="${BEST[$name]}" 'BEGIN { exit !(a < b) }'; then
      BEST[$name]=$M_WALL CPU[$name]=$M_CPU RSS[$name]=$M_RSS_MB
    fi
  done
}

# emit_report: prints the caller's report() (the Markdown table) and, with JSON=1, its json() on
# stdout with the table on stderr; OUT_FILE, when set, receives a copy of the table.
emit_report() {
  if ((JSON)); then
    if [[ -n $OUT_FILE ]]; then report | tee "$OUT_FILE" >&2; else report >&2; fi
    json
  elif [[ -n $OUT_FILE ]]; then
    report | tee "$OUT_FILE"
  else
    report
  fi
}
