#!/usr/bin/env bash
# Cold web-image floods (issue 29, item 2): what a client that pipelines many distinct cold images
# costs the other users of `vts serve`, and how much work the server does for requests nobody
# waits for any more. One `vts serve --threads 2` (two encode workers) over a synthetic
# 32768x32768 archive (16,384 tiles at level 7, so every request is a cold miss), driven by
# bench/web_flood.py:
#   at rest   a victim fetches 20 cold PNGs one after another (a new connection each)
#   abandon   500 connections each pipeline 16 distinct cold PNGs and close at once (8,000
#             requests); the victim's 20 cold PNGs meanwhile; the encodes the server still ran
#             for the flood, as a share of its requests (bar: under 5 %); victim p50 / max
#             against its p50 at rest (bar: within 5x)
#   heavy     32 connections each pipeline 16 cold PNGs and read every answer; the victim's
#             latency meanwhile (bar: within 5x of at rest)
#   nginx     the same abandon burst against nginx serving the same images as files (exported
#             once by `vts export --layout xyz`, ~2.5 min), with the same victim: the burst's cost
#             at the network layer alone, where nothing is encoded
# Prints a markdown table with machine, date and commit.
#
#   bash bench/web_flood_bench.sh [--vts PATH] [--out FILE]
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG=""
OUT_FILE=""
while (($#)); do
  bench_option "$@"
  shift "$OPT_SHIFT"
done
need python3 curl nginx
VTS=$(find_vts "$VTS_ARG")

ARCHIVE=$CACHE/flood_32768.pmtiles
if [[ ! -s $ARCHIVE ]]; then
  mkdir -p "$CACHE"
  echo "[bench] building $ARCHIVE (once, not timed)" >&2
  "$VTS" build --synthetic 32768x32768 -o "$ARCHIVE" >/dev/null || die "vts build failed"
fi

STATIC=$CACHE/flood_32768_png
if [[ ! -d $STATIC/flood_32768 ]]; then
  echo "[bench] exporting the PNG files nginx serves (once, not timed)" >&2
  rm -rf "$STATIC"
  "$VTS" export "$ARCHIVE" --format png --layout xyz -o "$STATIC/flood_32768" >/dev/null ||
    die "vts export failed"
fi

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-flood-bench.XXXXXX")
VTS_PID=""
NGINX_PID=""
finish() {
  [[ -n $VTS_PID ]] && kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  [[ -n $NGINX_PID ]] && kill -QUIT "$NGINX_PID" 2>/dev/null && wait "$NGINX_PID" 2>/dev/null
  rm -rf "$T"
}
trap finish EXIT

ulimit -n 4096 2>/dev/null || true  # 500 client sockets and as many server ones
# start_vts_serve's --no-admin is overridden: the flood's work is read from the admin /metrics.
start_vts_serve "$ARCHIVE" "$T" 2 --admin 127.0.0.1:0
ADMIN=$(sed -nE 's|.*\(admin http://[^ ]*:([0-9]+)\).*|\1|p' "$T/vts.out")
[[ -n $ADMIN ]] || die "vts serve printed no admin port: $(cat "$T/vts.out")"

start_nginx_static "$STATIC" "$T" 2
python3 "$BENCH_DIR/web_flood.py" --port "$PORT" --admin-port "$ADMIN" --tileset flood_32768 \
  --zoom 7 --cols 128 --rows 128 --peer-port "$NGINX_PORT" --json >"$T/flood.json" ||
  die "web_flood.py failed"

j() { python3 -c "import json,sys; d=json.load(open('$T/flood.json')); print($1)"; }
{
  echo "### Cold web-image floods (\`bash bench/web_flood_bench.sh\`)"
  echo
  machine_info
  echo
  echo "| run | requests | encodes for nobody | dropped | 503 shed | victim p50 | victim max | p50 / at rest | max / at rest |"
  echo "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
  echo "| at rest | 20 | - | - | - | $(j 'd["victim_at_rest"]["p50_ms"]') ms | $(j 'd["victim_at_rest"]["max_ms"]') ms | 1.00 | - |"
  echo "| abandon: 500 x 16 pipelined, closed | $(j 'd["abandon"]["requests"]') | $(j 'd["abandon"]["encodes_for_nobody"]') ($(j 'd["abandon"]["abandoned_work_percent"]') %) | $(j 'd["abandon"]["dropped"]') | $(j 'd["abandon"]["shed_503"]') | $(j 'd["abandon"]["victim"]["p50_ms"]') ms | $(j 'd["abandon"]["victim"]["max_ms"]') ms | $(j 'd["abandon"]["victim_ratio_p50"]') | $(j 'd["abandon"]["victim_ratio_max"]') |"
  echo "| heavy: 32 x 16 pipelined, read | $(j 'd["heavy"]["requests"]') | - | - | $(j 'd["heavy"]["statuses"].get("503", 0)') | $(j 'd["heavy"]["victim"]["p50_ms"]') ms | $(j 'd["heavy"]["victim"]["max_ms"]') ms | $(j 'd["heavy"]["victim_ratio_p50"]') | $(j 'd["heavy"]["victim_ratio_max"]') |"
  echo "| nginx over the PNG files: the same abandon burst | $(j 'd["abandon"]["requests"]') | - | - | - | $(j 'd["peer_abandon"]["victim"]["p50_ms"]') ms (at rest $(j 'd["peer_abandon"]["victim_at_rest"]["p50_ms"]') ms) | $(j 'd["peer_abandon"]["victim"]["max_ms"]') ms | $(j 'd["peer_abandon"]["victim_ratio_p50"]') | $(j 'd["peer_abandon"]["victim_ratio_max"]') |"
  echo
  echo "Victim answers: abandon $(j 'd["abandon"]["victim_statuses"]'), heavy $(j 'd["heavy"]["victim_statuses"]'); heavy client's answers by status: $(j 'd["heavy"]["statuses"]')."
} | tee "${OUT_FILE:-/dev/null}"
