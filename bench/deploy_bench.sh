#!/usr/bin/env bash
# Deployment benchmark: the nginx cache front of deploy/nginx (rendered from the
# checked-in templates, as tests/integration/deploy_front.sh does) with two `vts serve` replicas
# behind it, the cache hot, against one replica directly. wrk -t2 -c64 --latency with
# bench/random_tiles.lua over every tile of the Earth archive (versioned URLs, the ones TileJSON
# hands out), on this machine in one run; and, to tell nginx's cache from nginx itself, the same
# nginx serving the same tiles as static files. Prints a markdown table.
#
#   bash bench/deploy_bench.sh [--vts PATH] [--duration 10s] [--workers N] [--out FILE]
#
# --workers N (default 1): nginx worker processes, and --threads of each replica. On this
# 2-core machine wrk itself needs about one core.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG=""
DURATION=10s
WORKERS=1
OUT_FILE=""
while (($#)); do
  case $1 in
    --vts) VTS_ARG=$2; shift 2 ;;
    --duration) DURATION=$2; shift 2 ;;
    --workers) WORKERS=$2; shift 2 ;;
    --out) OUT_FILE=$2; shift 2 ;;
    *) die "unknown argument '$1'" ;;
  esac
done
[[ $WORKERS =~ ^[1-9][0-9]*$ ]] || die "--workers must be a positive integer, not '$WORKERS'"
need wrk nginx curl envsubst openssl ss
VTS=$(find_vts "$VTS_ARG")
DUMP=${PMTILES_DUMP:-$(dirname "$VTS")/../tests/integration/pmtiles_dump}
[[ -x $DUMP ]] || die "no pmtiles_dump at $DUMP (build the tests, or set PMTILES_DUMP)"
ARCHIVE=$(earth_archive deploy_earth 8192x4096)
DEPLOY=${VTS_DEPLOY_DIR:-$ROOT/deploy}

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-deploy-bench.XXXXXX")
PIDS=()
NGINX_PID=""
STATIC_PID=""
finish() {
  local p
  for p in "${PIDS[@]}"; do { kill -TERM "$p" && wait "$p"; } 2>/dev/null || true; done
  for p in "$NGINX_PID" "$STATIC_PID"; do
    [[ -n $p ]] && { kill -QUIT "$p" && wait "$p"; } 2>/dev/null
  done
  rm -rf "$T"
}
trap finish EXIT

# Two replicas, each with its own copy of the archive.
declare -a RPORT
for r in 1 2; do
  mkdir -p "$T/r$r"
  cp "$ARCHIVE" "$T/r$r/earth.pmtiles"
  start_vts_serve "$T/r$r/earth.pmtiles" "$T/r$r" "$WORKERS"
  PIDS+=("$VTS_PID")
  RPORT[r]=$PORT
done

# The front, from the checked-in templates.
N=$T/nginx
mkdir -p "$N/conf.d" "$N/tls" "$N/tmp" "$N/logs"
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 \
  -subj /CN=127.0.0.1 -keyout "$N/tls/key.pem" -out "$N/tls/cert.pem" >/dev/null 2>&1 ||
  die "openssl failed"
FRONT_PORT=$(free_port)
TLS_PORT=$(free_port)
while [[ $TLS_PORT == "$FRONT_PORT" ]]; do TLS_PORT=$(free_port); done
export VTS_CACHE_DIR="$N/cache" VTS_CACHE_SIZE=4g VTS_SERVER_NAME=localhost \
  VTS_FRONT_HTTP_LISTEN="127.0.0.1:$FRONT_PORT" VTS_FRONT_HTTPS_LISTEN="127.0.0.1:$TLS_PORT" \
  VTS_TLS_CERT="$N/tls/cert.pem" VTS_TLS_KEY="$N/tls/key.pem"
# shellcheck disable=SC2016  # envsubst's list of variable names
envsubst '${VTS_CACHE_DIR} ${VTS_CACHE_SIZE} ${VTS_SERVER_NAME} ${VTS_FRONT_HTTP_LISTEN}
  ${VTS_FRONT_HTTPS_LISTEN} ${VTS_TLS_CERT} ${VTS_TLS_KEY}' \
  <"$DEPLOY/nginx/vts-front.conf.template" >"$N/conf.d/vts-front.conf"
for r in 1 2; do
  # shellcheck disable=SC2016
  VTS_REPLICA="127.0.0.1:${RPORT[r]}" envsubst '${VTS_REPLICA}' \
    <"$DEPLOY/nginx/vts-replicas.inc.template" >>"$N/conf.d/vts-replicas.inc"
done
user_line=""
if ((EUID == 0)); then
  user_line="user nobody $(id -gn nobody);"
  chmod 0755 "$T" "$N"
  chown -R nobody "$N/tmp"
fi
cat >"$N/nginx.conf" <<CONF
$user_line
worker_processes $WORKERS;
daemon off;
pid $N/nginx.pid;
error_log $N/logs/error.log warn;
events { worker_connections 4096; }
http {
  default_type application/octet-stream;
  sendfile on;
  tcp_nopush on;
  keepalive_requests 1000000;
  client_body_temp_path $N/tmp/body;
  proxy_temp_path $N/tmp/proxy;
  fastcgi_temp_path $N/tmp/fastcgi;
  uwsgi_temp_path $N/tmp/uwsgi;
  scgi_temp_path $N/tmp/scgi;
  include conf.d/*.conf;
}
CONF
nginx -p "$N" -e "$N/logs/error.log" -c "$N/nginx.conf" 2>"$N/logs/stderr" &
NGINX_PID=$!
FRONT="http://127.0.0.1:$FRONT_PORT"
for ((i = 0; i < 100; i++)); do
  curl -sf -o /dev/null "$FRONT/.front-health" && break
  sleep 0.05
done
curl -sf -o /dev/null "$FRONT/.front-health" || die "nginx did not start: $(cat "$N/logs/stderr")"

# The peer: the same nginx serving the same tiles as static files (bench/lib.sh, as in
# serve_bench.sh), to tell nginx's cache from nginx itself.
FRONT_PID=$NGINX_PID
extract_static "$ARCHIVE" "$T/static_peer"
start_nginx_static "$T/static_peer/static" "$T/static_peer" "$WORKERS"
STATIC_PID=$NGINX_PID
NGINX_PID=$FRONT_PID
STATIC="http://127.0.0.1:$NGINX_PORT"
awk '{ print "/earth/" $2 "/" $3 "/" $4 }' "$T/static_peer/offsets" >"$T/static_tiles.txt"

# Versioned tile paths, as TileJSON hands them out.
VERSION=$(curl -sf "$FRONT/earth.json" | sed -nE 's/.*"version" *: *"([0-9a-f]+)".*/\1/p')
[[ -n $VERSION ]] || die "no version in TileJSON"
"$DUMP" offsets "$ARCHIVE" | awk -v v="$VERSION" '{ print "/earth@" v "/" $2 "/" $3 "/" $4 }' >"$T/tiles.txt"
NTILES=$(wc -l <"$T/tiles.txt")
TILE_BYTES=$("$DUMP" offsets "$ARCHIVE" | awk '{ s += $6 } END { print s }')

# Hot cache: every tile through the front, twice; the second pass must be all HITs.
sed "s|^|url = \"$FRONT|; s|\$|\"\noutput = \"/dev/null\"|" "$T/tiles.txt" >"$T/front.cfg"
cold_start=$(date +%s%N)
curl -s --parallel --parallel-max 32 -K "$T/front.cfg" 2>/dev/null || die "warming the front failed"
cold_ms=$((($(date +%s%N) - cold_start) / 1000000))
hits=$(curl -s -I -K "$T/front.cfg" -w '%header{x-cache-status}\n' 2>/dev/null | grep -c '^HIT$' || true)
[[ $hits == "$NTILES" ]] || die "only $hits of $NTILES tiles are cache HITs after warming"

to_ms() {
  awk -v v="$1" 'BEGIN { n = v + 0; if (v ~ /us$/) n /= 1000; else if (v ~ /ms$/) ; else if (v ~ /s$/) n *= 1000; printf "%.2f", n }'
}
to_mb() {
  awk -v v="$1" 'BEGIN { n = v + 0; if (v ~ /GB$/) n *= 1024; else if (v ~ /KB$/) n /= 1024; else if (v ~ /B$/ && v !~ /MB$/) n /= 1048576; printf "%.1f", n }'
}
declare -A RPS MBS P50 P99 ERR
run_wrk() { # NAME BASE [LIST]
  local log="$T/wrk_$1.txt"
  wrk -t2 -c64 -d"$DURATION" --latency -s "$BENCH_DIR/random_tiles.lua" "$2" -- "${3:-$T/tiles.txt}" tiles \
    >"$log" 2>&1 || die "wrk failed: $(cat "$log")"
  RPS[$1]=$(awk '/^Requests\/sec:/ { printf "%.0f", $2 }' "$log")
  MBS[$1]=$(to_mb "$(awk '/^Transfer\/sec:/ { print $2 }' "$log")")
  P50[$1]=$(to_ms "$(awk '$1 == "50%" { print $2 }' "$log")")
  P99[$1]=$(to_ms "$(awk '$1 == "99%" { print $2 }' "$log")")
  ERR[$1]=$(awk '/Non-2xx or 3xx/ { print $NF }' "$log")
  echo "$1: ${RPS[$1]} req/s, ${MBS[$1]} MB/s, p50 ${P50[$1]} ms, p99 ${P99[$1]} ms ${ERR[$1]:+(${ERR[$1]} errors)}" >&2
}
run_wrk replica "http://127.0.0.1:${RPORT[1]}"
run_wrk front "$FRONT"
run_wrk static "$STATIC" "$T/static_tiles.txt"

# Streaming latency as viewers see it: `vts loadtest` with 64 viewers through the front (cache
# hot) and against one replica. Skipped when this vts has no loadtest command.
declare -A LT
run_loadtest() { # NAME BASE
  local json="$T/loadtest_$1.json"
  if "$VTS" loadtest "$2/earth" --viewers 64 --duration "${DURATION%s}" --json --quiet \
    --max-error-rate 100% >"$json" 2>"$T/loadtest_$1.err"; then
    LT[$1]=$(python3 - "$json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
lat = j["latency_ns"]
ms = lambda v: f"{v / 1e6:.1f}"
bad = sum(n for s, n in j.get("by_status", {}).items() if s != "200")
print(f'{ms(lat["total"]["p50"])} | {ms(lat["total"]["p99"])} | {ms(lat["full_resolution"]["p50"])} | '
      f'{lat["total"]["count"]} | {bad}')
PY
    ) || LT[$1]="- | - | - | - | -"
  else
    LT[$1]="- | - | - | - | -"
  fi
  echo "loadtest $1: ${LT[$1]}" >&2
}
if "$VTS" loadtest --help >/dev/null 2>&1; then
  run_loadtest replica "http://127.0.0.1:${RPORT[1]}"
  run_loadtest front "$FRONT"
fi

{
  echo "### Deployment: nginx cache front (hot) vs one vts serve replica ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- archive: Earth 8192x4096, $NTILES tiles, $(mb "$TILE_BYTES") MiB of tile payloads (avg $((TILE_BYTES / NTILES)) B); versioned URLs"
  echo "- front: deploy/nginx/vts-front.conf.template, nginx $(nginx -v 2>&1 | sed 's|.*/||'), $WORKERS worker(s), 2 replicas (--threads $WORKERS) behind it; cache filled in $cold_ms ms (curl --parallel-max 32, cold), then $hits/$NTILES HITs"
  echo "- wrk -t2 -c64 -d$DURATION --latency, bench/random_tiles.lua, plain HTTP/1.1 on loopback"
  echo
  echo "| target | req/s | MB/s | p50 ms | p99 ms | req/s vs replica |"
  echo "|---|---:|---:|---:|---:|---:|"
  for s in replica front static; do
    label=$s
    [[ $s == replica ]] && label="one vts serve replica, direct"
    [[ $s == front ]] && label="nginx cache front, hot (X-Cache-Status HIT)"
    [[ $s == static ]] && label="peer: the same nginx, the tiles as static files (sendfile)"
    echo "| $label | ${RPS[$s]} | ${MBS[$s]} | ${P50[$s]} | ${P99[$s]} | $(ratio "${RPS[$s]}" "${RPS[replica]}") |"
  done
  if [[ -n ${LT[front]:-} ]]; then
    echo
    echo "vts loadtest, 64 viewers (flyover, closed loop, no client cache), ${DURATION%s} s each:"
    echo
    echo "| target | request p50 ms | request p99 ms | time to full resolution p50 ms | requests | non-200 |"
    echo "|---|---:|---:|---:|---:|---:|"
    echo "| one vts serve replica, direct | ${LT[replica]} |"
    echo "| nginx cache front, hot | ${LT[front]} |"
  fi
} | tee "${OUT_FILE:-/dev/null}"
