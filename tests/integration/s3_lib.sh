# shellcheck shell=bash disable=SC2034  # S3_PORT is used by the scripts that source this
# Helpers for the tests that run s3rver (npm, tests/integration/s3_js; sourced after lib.sh and
# deploy_lib.sh): start it on a free loopback port, upload objects with curl's own SigV4 signer,
# stop it (and a checking proxy) at exit.
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
S3_JS=${S3_JS:-$HERE/s3_js}
require_tool "$NODE"
[[ -f $S3_JS/node_modules/s3rver/package.json ]] ||
  fail "npm package s3rver is not installed in $S3_JS (run scripts/setup.sh)"

S3_PID="" PROXY_PID=""
store_cleanup() {
  local p
  for p in "$S3_PID" "$PROXY_PID"; do
    [[ -n $p ]] || continue
    kill -CONT "$p" 2>/dev/null || true
    { kill -KILL "$p" && wait "$p"; } 2>/dev/null || true
  done
  deploy_cleanup
}
trap store_cleanup EXIT

# wait_line FILE PATTERN [PID]: until FILE has a line matching PATTERN (PID, when given, alive).
wait_line() {
  local i
  for ((i = 0; i < 400; i++)); do
    grep -qE "$2" "$1" 2>/dev/null && return 0
    if [[ -n ${3:-} ]] && ! kill -0 "$3" 2>/dev/null; then cat "$1" >&2; fail "process $3 exited"; fi
    sleep 0.05
  done
  cat "$1" >&2
  fail "no line /$2/ in $1 within 20 s"
}

start_s3rver() {
  mkdir -p "$WORK/s3"
  "$NODE" "$S3_JS/serve.js" "$WORK/s3" tiles >"$LOGS/s3rver.log" 2>&1 </dev/null &
  S3_PID=$!
  wait_line "$LOGS/s3rver.log" '^port [0-9]+$' "$S3_PID"
  S3_PORT=$(sed -nE 's/^port ([0-9]+)$/\1/p' "$LOGS/s3rver.log")
}

# put_object FILE KEY [PORT]: uploads FILE to s3://tiles/KEY (KEY already URI-encoded) with curl's
# own SigV4 signer.
put_object() {
  local code
  code=$(curl -s -o "$LOGS/put.out" -w '%{http_code}' -X PUT -T "$1" \
    --aws-sigv4 aws:amz:us-east-1:s3 --user S3RVER:S3RVER \
    -H "x-amz-content-sha256: $(sha "$1")" "http://127.0.0.1:${3:-$S3_PORT}/tiles/$2")
  [[ $code == 200 ]] || { cat "$LOGS/put.out" >&2; fail "PUT $2 answered $code"; }
}
