# shellcheck shell=bash disable=SC2034  # variables here are used by the scripts that source this file
# Shared helpers for the integration tests (sourced, not run). Each test is one bash script run by
# ctest (see CMakeLists.txt here) with these variables in its environment:
#   VTS            the vts executable under test
#   PMTILES_DUMP   tests/integration/pmtiles_dump (our reader's view of an archive)
#   PMTILES_JS     tests/integration/pmtiles_js (dump.mjs + node_modules from scripts/setup.sh)
#   NODE, OIIOTOOL, IDIFF   real peers (from scripts/setup.sh)
#   EARTH          a real source image (xplanet-images' 2048x1024 Earth JPEG)
# Every test works in its own fresh temporary directory, removed on exit unless VTS_KEEP_TMP=1.
set -euo pipefail

: "${VTS:?VTS must name the vts executable}"
EARTH=${EARTH:-/usr/share/xplanet/images/earth.jpg}
NODE=${NODE:-node}
OIIOTOOL=${OIIOTOOL:-oiiotool}
IDIFF=${IDIFF:-idiff}
# Upper bound on any one command, so a hang fails the test instead of stalling CI.
CMD_TIMEOUT=${VTS_TEST_CMD_TIMEOUT:-300}

WORK=$(mktemp -d "${TMPDIR:-/tmp}/vts-it.XXXXXX")
cleanup() {
  local rc=$?
  if [[ ${VTS_KEEP_TMP:-0} == 1 || ( $rc -ne 0 && ${VTS_KEEP_TMP_ON_FAILURE:-0} == 1 ) ]]; then
    echo "(kept $WORK)" >&2
  else
    rm -rf "$WORK"
  fi
}
trap cleanup EXIT
# Command logs live outside the directories whose contents the tests inspect.
LOGS="$WORK/.logs"
mkdir -p "$LOGS"
OUT="$LOGS/stdout"
ERR="$LOGS/stderr"

note() { printf -- '-- %s\n' "$*"; }
fail() {
  printf 'FAIL: %s\n' "$*" >&2
  exit 1
}
require_tool() {
  command -v "$1" >/dev/null 2>&1 || fail "missing tool '$1' (run scripts/setup.sh)"
}
show_output() {
  if [[ -s $OUT ]]; then
    echo "---- stdout (last 40 lines):" >&2
    tail -n 40 "$OUT" >&2
  fi
  if [[ -s $ERR ]]; then
    echo "---- stderr (last 40 lines):" >&2
    tail -n 40 "$ERR" >&2
  fi
}

# run CMD...: runs CMD under a time limit with stdin closed, stdout/stderr to $OUT/$ERR; sets RC.
RC=0
run() {
  set +e
  timeout -k 10 "$CMD_TIMEOUT" "$@" >"$OUT" 2>"$ERR" </dev/null
  RC=$?
  set -e
}

# expect_ok CMD...: CMD must exit 0.
expect_ok() {
  run "$@"
  if ((RC != 0)); then
    show_output
    fail "'$*' exited $RC, expected 0"
  fi
}

# expect_clean_failure CMD...: CMD must fail the way a well-behaved tool fails on bad input:
# a non-zero exit code that is not a crash (a signal, 128+N) or a hang (timeout's 124), a message
# on stderr, and no sanitizer report.
expect_clean_failure() {
  run "$@"
  if ((RC == 0)); then
    show_output
    fail "'$*' succeeded, expected a failure"
  fi
  if ((RC == 124)); then
    fail "'$*' did not finish within ${CMD_TIMEOUT}s (hang?)"
  fi
  if ((RC >= 128)); then
    show_output
    fail "'$*' died with exit code $RC (signal $((RC - 128)): a crash, not a clean error)"
  fi
  if ! grep -q '[^[:space:]]' "$ERR"; then
    show_output
    fail "'$*' exited $RC with nothing on stderr; expected an error message"
  fi
  if grep -qE 'AddressSanitizer|runtime error:|LeakSanitizer' "$ERR"; then
    show_output
    fail "'$*' reported a sanitizer error"
  fi
}

# json_check FILE JS_EXPR [DESCRIPTION]: FILE must parse as JSON and JS_EXPR (with the parsed value
# bound to `j`) must be truthy.
json_check() {
  local file=$1 expr=$2 what=${3:-$2}
  if ! "$NODE" -e '
      const fs = require("fs");
      let j;
      try { j = JSON.parse(fs.readFileSync(process.argv[1], "utf8")); }
      catch (e) { console.error("not JSON: " + e.message); process.exit(2); }
      const ok = (new Function("j", "return (" + process.argv[2] + ");"))(j);
      process.exit(ok ? 0 : 1);' "$file" "$expr"; then
    echo "---- $file:" >&2
    head -c 4000 "$file" >&2
    echo >&2
    fail "JSON check failed: $what"
  fi
}

# json_get FILE JS_EXPR: prints the value of JS_EXPR (parsed JSON bound to `j`).
json_get() {
  "$NODE" -e '
    const j = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
    const v = (new Function("j", "return (" + process.argv[2] + ");"))(j);
    process.stdout.write(typeof v === "string" ? v : JSON.stringify(v));' "$1" "$2"
}

# image_dims FILE: prints "W H CHANNELS" as OpenImageIO reads the file.
image_dims() {
  "$OIIOTOOL" --info "$1" | sed -nE 's/.*: *([0-9]+) x *([0-9]+), ([0-9]+) channel.*/\1 \2 \3/p'
}

# expect_same_pixels IMAGE REFERENCE: every pixel of IMAGE equals REFERENCE exactly (idiff, zero
# tolerance). A 4-channel IMAGE is compared with REFERENCE plus an opaque alpha channel.
expect_same_pixels() {
  local img=$1 ref=$2 dims_i dims_r wi hi ci wr hr cr
  dims_i=$(image_dims "$img")
  dims_r=$(image_dims "$ref")
  [[ -n $dims_i ]] || fail "cannot read $img as an image"
  read -r wi hi ci <<<"$dims_i"
  read -r wr hr cr <<<"$dims_r"
  [[ $wi == "$wr" && $hi == "$hr" ]] || fail "$img is ${wi}x${hi}, expected ${wr}x${hr}"
  local cmp_ref=$ref
  if [[ $ci == 4 && $cr == 3 ]]; then
    cmp_ref="$LOGS/ref_rgba.$(basename "$ref").png"
    "$OIIOTOOL" "$ref" --ch R,G,B,A=1.0 -o "$cmp_ref"
  elif [[ $ci != "$cr" ]]; then
    fail "$img has $ci channels, reference has $cr"
  fi
  if ! "$IDIFF" -fail 0 -warn 0 "$img" "$cmp_ref" >"$LOGS/idiff.txt" 2>&1; then
    cat "$LOGS/idiff.txt" >&2
    fail "$img differs from $ref"
  fi
}

# crop_ref SRC W H X Y OUT: writes the WxH window at (X, Y) of SRC as a PNG with origin 0,0.
crop_ref() {
  "$OIIOTOOL" "$1" --cut "${2}x${3}+${4}+${5}" --origin +0+0 --fullpixels -o "$6"
}

# sha FILE: the file's SHA-256, in hex.
sha() { sha256sum "$1" | cut -d' ' -f1; }

# free_port: a TCP port no socket uses now (ss says; nginx and Slurm cannot listen on port 0 and
# tell us which), below the kernel's ephemeral range so outgoing connections do not take it in the
# meantime.
free_port() {
  local p lo
  lo=$(awk '{ print $1 }' /proc/sys/net/ipv4/ip_local_port_range 2>/dev/null || echo 32768)
  while :; do
    p=$((20000 + RANDOM % (lo - 20000)))
    ss -Htan "sport = :$p" | grep -q . || { echo "$p"; return; }
  done
}

# k8s_job_command JOB.yaml ROOT: the Job's container command, one word a line, with the volume's
# paths (/plan/..., /parts, /out/...) moved under ROOT: the command a rendered Job runs, to run
# here on a folder laid out like the volume.
k8s_job_command() {
  "${PYTHON3:-python3}" - "$1" "$2" <<'PYTHON'
import sys, yaml
c = yaml.safe_load(open(sys.argv[1]))["spec"]["template"]["spec"]["containers"][0]["command"]
for w in c:
    for m in ("/plan/", "/parts", "/out/"):
        if w == m or w.startswith(m if m.endswith("/") else m + "/"):
            w = sys.argv[2] + w
    print(w)
PYTHON
}

# dir_listing DIR: every entry in DIR (including dot files), one per line, sorted.
dir_listing() {
  (cd "$1" && find . -mindepth 1 | LC_ALL=C sort)
}

# build_earth OUT [EXTRA ARGS...]: builds the Earth JPEG into OUT with vts (must succeed).
build_earth() {
  local out=$1
  shift
  expect_ok "$VTS" build "$EARTH" -o "$out" "$@"
  [[ -s $out ]] || fail "vts build reported success but $out is missing or empty"
}

require_tool "$VTS"
[[ -r $EARTH ]] || fail "missing $EARTH (apt package xplanet-images; run scripts/setup.sh)"
