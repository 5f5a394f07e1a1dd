# shellcheck shell=bash disable=SC2034  # variables here are used by the scripts that source this
# Helpers for the deploy/ tests (sourced after lib.sh and serve_lib.sh, whose status_of,
# expect_status and archive_bytes they use): render the checked-in nginx templates of
# deploy/nginx with this test's ports and paths, start nginx unprivileged under a prefix of the
# test's own (like bench/serve_bench.sh), start `vts serve` replicas on 127.0.0.1 port 0, and stop
# everything on exit.
require_tool curl
require_tool nginx
require_tool envsubst
require_tool openssl
require_tool ss

DEPLOY=${VTS_DEPLOY_DIR:-$(cd "$(dirname "${BASH_SOURCE[0]}")/../../deploy" && pwd)}
NGINX_PID=""
NGINX_DIR=""
declare -a REPLICA_PIDS=()
declare -a REPLICA_PORTS=()

deploy_cleanup() {
  local p
  for p in "${REPLICA_PIDS[@]}"; do
    [[ -n $p ]] || continue
    { kill -KILL "$p" && wait "$p"; } 2>/dev/null || true
  done
  if [[ -n $NGINX_PID ]] && kill -0 "$NGINX_PID" 2>/dev/null; then
    kill -QUIT "$NGINX_PID" 2>/dev/null || true
    local i
    for ((i = 0; i < 50; i++)); do
      kill -0 "$NGINX_PID" 2>/dev/null || break
      sleep 0.1
    done
    kill -KILL "$NGINX_PID" 2>/dev/null || true
  fi
  cleanup
}
trap deploy_cleanup EXIT

# elapsed_ms: milliseconds since $t_start (nanoseconds since the epoch, which the script sets).
elapsed_ms() { echo $((($(date +%s%N) - ${t_start:?set t_start first}) / 1000000)); }

# make_cert DIR: a throw-away self-signed certificate for 127.0.0.1: DIR/cert.pem, DIR/key.pem.
make_cert() {
  mkdir -p "$1"
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 \
    -subj /CN=127.0.0.1 -addext subjectAltName=IP:127.0.0.1 \
    -keyout "$1/key.pem" -out "$1/cert.pem" >"$LOGS/openssl.log" 2>&1 ||
    { cat "$LOGS/openssl.log" >&2; fail "openssl could not make a certificate"; }
}

# render TEMPLATE OUT VAR...: envsubst of exactly the named variables (nginx's own $variables stay);
# every ${VTS_...} placeholder must be among them.
render() {
  local template=$1 out=$2 list="" v
  shift 2
  for v in "$@"; do list+="\${$v} "; done
  envsubst "$list" <"$template" >"$out"
  # shellcheck disable=SC2016  # a literal ${
  if grep -n '\${VTS_' "$out" >&2; then fail "$out: placeholders left unrendered"; fi
}

# start_nginx DIR: DIR/conf.d/*.conf hold the rendered front; writes DIR/nginx.conf (the part a
# distribution's /etc/nginx/nginx.conf plays: pid, logs, temp paths, `include conf.d/*.conf`),
# checks it with nginx -t and starts nginx in the foreground of a background job. Sets NGINX_PID
# and NGINX_DIR. As root, workers run as nobody (as a packaged nginx's would, as www-data).
start_nginx() {
  local dir=$1 user_line=""
  NGINX_DIR=$dir
  mkdir -p "$dir/logs" "$dir/tmp"
  if ((EUID == 0)); then
    user_line="user nobody $(id -gn nobody);"
    chmod 0755 "$WORK" "$dir"
    chmod -R a+rX "$dir/conf.d"
    chown -R nobody "$dir/tmp"
  fi
  cat >"$dir/nginx.conf" <<CONF
$user_line
worker_processes 2;
daemon off;
pid $dir/nginx.pid;
error_log $dir/logs/error.log info;
events { worker_connections 4096; }
http {
  default_type application/octet-stream;
  client_body_temp_path $dir/tmp/body;
  proxy_temp_path $dir/tmp/proxy;
  fastcgi_temp_path $dir/tmp/fastcgi;
  uwsgi_temp_path $dir/tmp/uwsgi;
  scgi_temp_path $dir/tmp/scgi;
  include conf.d/*.conf;
}
CONF
  # -e: the log nginx writes before it has read its configuration (by default under /var/log).
  nginx -t -p "$dir" -e "$dir/logs/error.log" -c "$dir/nginx.conf" >"$LOGS/nginx-t.log" 2>&1 ||
    { cat "$LOGS/nginx-t.log" >&2; fail "nginx -t refused the rendered configuration"; }
  nginx -p "$dir" -e "$dir/logs/error.log" -c "$dir/nginx.conf" >"$dir/logs/stdout" \
    2>"$dir/logs/stderr" </dev/null &
  NGINX_PID=$!
}

# nginx_prepare DIR: two distinct free ports, HTTP_PORT and HTTPS_PORT, for a front's listeners;
# N=DIR, with DIR/conf.d for the rendered templates and a throw-away certificate for 127.0.0.1 in
# DIR/tls (cert.pem, key.pem).
nginx_prepare() {
  HTTP_PORT=$(free_port)
  HTTPS_PORT=$(free_port)
  while [[ $HTTPS_PORT == "$HTTP_PORT" ]]; do HTTPS_PORT=$(free_port); done
  N=$1
  mkdir -p "$N/conf.d"
  make_cert "$N/tls"
}

# start_static_nginx SRV: nginx from deploy/nginx/vts-static.conf.template, as checked in, serving
# the archives in folder SRV on HTTP_PORT and HTTPS_PORT (nginx_prepare "$WORK/nginx", then
# start_nginx). Sets S, the http:// base URL; the caller waits for it with wait_http.
start_static_nginx() {
  nginx_prepare "$WORK/nginx"
  export VTS_ARCHIVE_DIR="$1" VTS_SERVER_NAME=localhost \
    VTS_STATIC_HTTP_LISTEN="127.0.0.1:$HTTP_PORT" VTS_STATIC_HTTPS_LISTEN="127.0.0.1:$HTTPS_PORT" \
    VTS_TLS_CERT="$N/tls/cert.pem" VTS_TLS_KEY="$N/tls/key.pem"
  render "$DEPLOY/nginx/vts-static.conf.template" "$N/conf.d/vts-static.conf" VTS_ARCHIVE_DIR \
    VTS_SERVER_NAME VTS_STATIC_HTTP_LISTEN VTS_STATIC_HTTPS_LISTEN VTS_TLS_CERT VTS_TLS_KEY
  if ((EUID == 0)); then chmod -R a+rX "$1"; fi
  start_nginx "$N"
  S="http://127.0.0.1:$HTTP_PORT"
}

# wait_http URL [SECONDS]: until URL answers anything (nginx has no "listening" line to wait for).
wait_http() {
  local i n=$((${2:-10} * 20))
  for ((i = 0; i < n; i++)); do
    curl -s -o /dev/null -k --max-time 1 "$1" && return 0
    kill -0 "$NGINX_PID" 2>/dev/null || { cat "$NGINX_DIR/logs/stderr" "$NGINX_DIR/logs/error.log" >&2; fail "nginx exited"; }
    sleep 0.05
  done
  fail "$1 did not answer within ${2:-10} s"
}

# start_replica INDEX ARGS...: `vts serve ARGS` on 127.0.0.1 port 0 (or REPLICA_PORTS[INDEX] when
# set: a restart on the same port); sets REPLICA_PIDS[INDEX] and REPLICA_PORTS[INDEX].
start_replica() {
  local i=$1 n port=${REPLICA_PORTS[$1]:-0}
  shift
  local out="$LOGS/replica$i.out" err="$LOGS/replica$i.err"
  : >"$out"
  "$VTS" serve "$@" --listen "127.0.0.1:$port" --admin 127.0.0.1:0 >"$out" 2>>"$err" </dev/null &
  REPLICA_PIDS[i]=$!
  for ((n = 0; n < 200; n++)); do
    grep -q 'listening on' "$out" && break
    kill -0 "${REPLICA_PIDS[i]}" 2>/dev/null || { cat "$err" >&2; fail "replica $i exited"; }
    sleep 0.05
  done
  REPLICA_PORTS[i]=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+) .*|\1|p' "$out")
  [[ -n ${REPLICA_PORTS[i]} ]] || { cat "$out" "$err" >&2; fail "replica $i: no port"; }
}

# kill_replica INDEX: SIGKILL (a crash, not a drain) and reap it.
kill_replica() {
  local pid=${REPLICA_PIDS[$1]}
  { kill -KILL "$pid" && wait "$pid"; } 2>/dev/null || true
  REPLICA_PIDS[$1]=""
}

# header_of NAME ARGS...: the value of response header NAME (last response) for curl ARGS.
header_of() {
  local name=$1
  shift
  curl -s -o /dev/null -D - "$@" | tr -d '\r' |
    awk -v n="$(tr '[:upper:]' '[:lower:]' <<<"$name")" -F': ' 'tolower($1) == n { v = $2 } END { print v }'
}

# tilejson_version URL: the "version" of the TileJSON at URL (empty on failure).
tilejson_version() {
  curl -sf --max-time 5 "$1" | sed -nE 's/.*"version" *: *"([0-9a-f]+)".*/\1/p'
}
