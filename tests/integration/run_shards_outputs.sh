#!/usr/bin/env bash
# The folders a planned build writes are checked before any work, naming the folder: a planet's
# shards run for hours before the merge, which must not be where a missing or read-only folder
# shows. deploy/batch/local/run-shards.sh creates the folders of --parts, --logs and --out (as
# `mkdir -p` would: what a user of `--out out/planet.pmtiles` expects) and refuses at once, exit
# 2, one that cannot be created or written; `vts build --plan` creates --out-dir likewise; `vts
# merge -o` and `vts build -o` want the archive's folder to exist (as every vts command that writes
# a file does) and to take a file. Each vts command also refuses at once (exit 4) a folder with
# less free space than the plan's estimate of what it writes there, naming the folder, the space
# and the estimate, unless given --no-space-check.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
RUNNER=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../deploy/batch/local" && pwd)/run-shards.sh

expect_ok "$VTS" plan --synthetic 1000x500 --shards 4 -o "$WORK/plan.json" --json
n=$(json_get "$OUT" "j.shards")
archive_est=$(json_get "$OUT" "j.estimated_bytes.archive")
shard_est=$(json_get "$OUT" "j.estimated_bytes.shard_max")
apex_est=$(json_get "$OUT" "j.estimated_bytes.apex")
mkdir -p "$WORK/ref"
expect_ok "$VTS" build --synthetic 1000x500 -o "$WORK/ref/x.pmtiles" -q
touch "$WORK/afile"

# refused WHAT CMD...: CMD fails cleanly at once (no part, no log, no archive), naming WHAT.
refused() {
  local what=$1
  shift
  expect_clean_failure "$@"
  grep -qF -- "$what" "$ERR" || { show_output; fail "'$*': the error does not name '$what'"; }
}

note "run-shards.sh --out out/x.pmtiles with no out/: the folder is created, the build runs"
expect_ok bash "$RUNNER" --vts "$VTS" --jobs 2 --out "$WORK/out/x.pmtiles" "$WORK/plan.json"
[[ $(sha "$WORK/out/x.pmtiles") == $(sha "$WORK/ref/x.pmtiles") ]] ||
  fail "run-shards.sh's archive differs from vts build's"
grep -q "^run-shards: $n shards, 0 with a part already, $n to build" "$OUT" || { show_output; fail "summary"; }
[[ -z $(find "$WORK/out" -name '.*') ]] || fail "run-shards.sh left hidden files in out/: $(ls -a "$WORK/out")"

note "run-shards.sh: a folder that cannot be made is refused before any shard (exit 2)"
for opt in --out --parts --logs; do
  args=(--out "$WORK/o2/x.pmtiles" --parts "$WORK/p2" --logs "$WORK/l2")
  case $opt in
    --out) args[1]=$WORK/afile/x.pmtiles want=$WORK/afile ;;
    --parts) args[3]=$WORK/afile/parts want=$WORK/afile/parts ;;
    --logs) args[5]=$WORK/afile/logs want=$WORK/afile/logs ;;
  esac
  refused "$want" bash "$RUNNER" --vts "$VTS" "${args[@]}" "$WORK/plan.json"
  ((RC == 2)) || fail "run-shards.sh with a bad $opt folder exited $RC, expected 2"
  if grep -q '^run-shards: shard' "$OUT"; then fail "run-shards.sh ran a shard before refusing $opt's folder"; fi
  [[ -z $(find "$WORK/p2" -name 'shard-*' 2>/dev/null) ]] || fail "a part was written before $opt was refused"
done
[[ ! -e $WORK/o2/x.pmtiles ]] || fail "an archive was written"

note "vts build --plan --out-dir: created when missing; refused at once when it cannot be"
expect_ok "$VTS" build --plan "$WORK/plan.json" --shard 0 --out-dir "$WORK/new/parts" -q
[[ -s $WORK/new/parts/shard-000000.part ]] || fail "no part in the created --out-dir"
refused "--out-dir $WORK/afile: not a folder" \
  "$VTS" build --plan "$WORK/plan.json" --shard 0 --out-dir "$WORK/afile"
refused "--out-dir $WORK/afile/parts: cannot create the folder" \
  "$VTS" build --plan "$WORK/plan.json" --shard 0 --out-dir "$WORK/afile/parts"
refused "--out-dir $WORK/afile: not a folder" \
  "$VTS" build --plan "$WORK/plan.json" --apex --out-dir "$WORK/afile"

note "vts merge -o and vts build -o: the archive's folder must exist; refused at once naming it"
refused "-o $WORK/nodir/x.pmtiles: not a file in an existing folder" \
  "$VTS" merge --plan "$WORK/plan.json" "$WORK/no-parts" -o "$WORK/nodir/x.pmtiles"
((RC == 2)) || fail "vts merge into a missing folder exited $RC, expected 2"
refused "-o $WORK/nodir/x.pmtiles: not a file in an existing folder" \
  "$VTS" build --synthetic 1000x500 -o "$WORK/nodir/x.pmtiles"
((RC == 2)) || fail "vts build into a missing folder exited $RC, expected 2"
[[ ! -e $WORK/nodir ]] || fail "a refused command created the folder"

# A folder that exists but takes no file: a read-only mount (root passes permission bits). Where
# this machine lets the test mount one (root with CAP_SYS_ADMIN, as CI's), it must be refused.
mkdir -p "$WORK/ro"
if mount -t tmpfs -o ro,size=1m tmpfs "$WORK/ro" 2>/dev/null; then
  note "a read-only folder: refused at once by all three, naming it"
  ro_status=0
  (
    trap 'umount "$WORK/ro"' EXIT
    refused "--out-dir $WORK/ro: cannot write in the folder" \
      "$VTS" build --plan "$WORK/plan.json" --shard 0 --out-dir "$WORK/ro"
    refused "-o's folder $WORK/ro: cannot write in the folder" \
      "$VTS" merge --plan "$WORK/plan.json" "$WORK/no-parts" -o "$WORK/ro/x.pmtiles"
    refused "cannot write in the folder $WORK/ro" \
      bash "$RUNNER" --vts "$VTS" --out "$WORK/ro/x.pmtiles" --parts "$WORK/p3" "$WORK/plan.json"
    [[ -z $(find "$WORK/p3" -name 'shard-*' 2>/dev/null) ]] || fail "a part was written"
  ) || ro_status=$?
  ((ro_status == 0)) || exit "$ro_status"
else
  note "SKIP the read-only folder: this machine does not let the test mount a tmpfs"
fi

# A folder with less free space than the plan's estimate: a 64 KiB tmpfs, below this plan's
# estimates of the archive, a shard's part and the apex's (the test's own premise, checked).
((archive_est > 65536 && shard_est > 65536 && apex_est > 65536)) ||
  fail "the plan's estimates ($archive_est, $shard_est, $apex_est bytes) fit in 64 KiB: no test"
mkdir -p "$WORK/tiny"
if mount -t tmpfs -o size=64k tmpfs "$WORK/tiny" 2>/dev/null; then
  note "less free space than the plan's estimate: refused at once (exit 4), naming it and both sizes"
  tiny_status=0
  (
    trap 'umount "$WORK/tiny"' EXIT
    refused "-o's folder $WORK/tiny: 64.0 KiB free, the merged archive needs about 370.4 KiB (the plan's estimate; --no-space-check to try anyway)" \
      "$VTS" merge --plan "$WORK/plan.json" "$WORK/parts" -o "$WORK/tiny/x.pmtiles"
    ((RC == 4)) || fail "vts merge into a folder too small exited $RC, expected 4 (io)"
    refused "--out-dir $WORK/tiny: 64.0 KiB free, the part needs about" \
      "$VTS" build --plan "$WORK/plan.json" --shard 0 --out-dir "$WORK/tiny"
    ((RC == 4)) || fail "vts build --plan --shard into a folder too small exited $RC, expected 4"
    refused "--out-dir $WORK/tiny: 64.0 KiB free, the apex part needs about" \
      "$VTS" build --plan "$WORK/plan.json" --apex --out-dir "$WORK/tiny"
    ((RC == 4)) || fail "vts build --plan --apex into a folder too small exited $RC, expected 4"
    [[ -z $(ls -A "$WORK/tiny") ]] || fail "a refused command wrote into the folder: $(ls -A "$WORK/tiny")"

    note "--no-space-check: the merge goes on (this archive is far smaller than the estimate)"
    expect_ok "$VTS" merge --plan "$WORK/plan.json" "$WORK/parts" -o "$WORK/tiny/x.pmtiles" \
      --no-space-check -q
    [[ $(sha "$WORK/tiny/x.pmtiles") == $(sha "$WORK/ref/x.pmtiles") ]] ||
      fail "the merge with --no-space-check differs from vts build's archive"
    rm -f "$WORK/tiny/x.pmtiles"

    note "--no-space-check on a full folder: the clean error of a full disk, nothing left behind"
    head -c 1m /dev/zero >"$WORK/tiny/fill" 2>/dev/null || true
    expect_clean_failure "$VTS" merge --plan "$WORK/plan.json" "$WORK/parts" \
      -o "$WORK/tiny/x.pmtiles" --no-space-check
    grep -q 'No space left on device' "$ERR" || { show_output; fail "the merge's error is not ENOSPC"; }
    if grep -q "the plan's estimate" "$ERR"; then fail "--no-space-check still checked"; fi
    expect_clean_failure "$VTS" build --plan "$WORK/plan.json" --shard 0 --out-dir "$WORK/tiny" \
      --no-space-check
    grep -q 'No space left on device' "$ERR" || { show_output; fail "the shard's error is not ENOSPC"; }
    [[ $(ls -A "$WORK/tiny") == fill ]] || fail "a failed command left files: $(ls -A "$WORK/tiny")"
  ) || tiny_status=$?
  ((tiny_status == 0)) || exit "$tiny_status"
else
  note "SKIP the folder too small: this machine does not let the test mount a tmpfs"
fi

note "--no-space-check needs --plan (vts build)"
refused "--no-space-check need --plan" \
  "$VTS" build --synthetic 1000x500 -o "$WORK/y.pmtiles" --no-space-check
note "PASS"
