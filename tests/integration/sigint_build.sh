#!/usr/bin/env bash
# A build interrupted with SIGINT stops promptly, exits 130 (cancelled), and leaves nothing on
# disk: no file under the output name and no temporary files beside it.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

D="$WORK/out"
mkdir -p "$D"
INT_AFTER=${VTS_TEST_SIGINT_AFTER:-2}

note "vts build --synthetic 60000x30000, SIGINT after ${INT_AFTER}s"
start=$(date +%s)
set +e
# --preserve-status: report the build's own exit status; -k: SIGKILL it if it ignores SIGINT.
timeout --preserve-status -s INT -k 30 "$INT_AFTER" \
  "$VTS" build --synthetic 60000x30000 -o "$D/big.pmtiles" >"$OUT" 2>"$ERR" </dev/null
RC=$?
set -e
elapsed=$(($(date +%s) - start))
note "exit code $RC after ${elapsed}s"

if ((RC == 0)); then
  fail "the build finished within ${INT_AFTER}s, so nothing was interrupted (raise the size)"
fi
if ((RC == 137)) || ((elapsed >= INT_AFTER + 30)); then
  show_output
  fail "vts build did not stop within 30 s of SIGINT and had to be killed"
fi
if grep -qE 'AddressSanitizer|runtime error:' "$ERR"; then
  show_output
  fail "sanitizer report during the interrupted build"
fi
((RC == 130)) || { show_output; fail "interrupted build exited $RC, expected 130 (cancelled)"; }

[[ ! -e $D/big.pmtiles ]] || fail "an interrupted build left $D/big.pmtiles behind"
left=$(dir_listing "$D")
if [[ -n $left ]]; then
  printf '%s\n' "$left" >&2
  fail "an interrupted build left temporary files in $D"
fi

note "an interrupted build leaves an existing archive untouched"
build_earth "$D/big.pmtiles"
cp "$D/big.pmtiles" "$WORK/orig.pmtiles"
set +e
timeout --preserve-status -s INT -k 30 "$INT_AFTER" \
  "$VTS" build --synthetic 60000x30000 -o "$D/big.pmtiles" >"$OUT" 2>"$ERR" </dev/null
RC=$?
set -e
((RC == 130)) || { show_output; fail "second interrupted build exited $RC, expected 130"; }
cmp -s "$D/big.pmtiles" "$WORK/orig.pmtiles" || fail "an interrupted build changed the existing archive"
[[ $(dir_listing "$D") == "./big.pmtiles" ]] || {
  dir_listing "$D" >&2
  fail "an interrupted build left temporary files in $D"
}

note "PASS"
