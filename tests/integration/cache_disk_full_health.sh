#!/usr/bin/env bash
# `vts cache serve` on a cache folder whose disk fills up (a small tmpfs): the failed writes are
# logged on stderr rate-limited (one line for the first, not one per tile), counted in /metrics,
# and /health answers 503 "degraded: disk cache writes failing ... disk full ..." while tiles are
# still served (200 from the upstream); once the disk has room again (the tmpfs grown) and a tile
# is stored, /health is 200 "ok" again and stderr says writes succeed again. Needs to mount a
# tmpfs: where that is not allowed (not root), exits 77, which ctest reports as skipped.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"

MNT="$WORK/tmpfs"
mkdir -p "$MNT"
if ! mount -t tmpfs -o size=512k vts-cache-health "$MNT" 2>"$LOGS/mount.err"; then
  echo "SKIP: cannot mount a tmpfs to fill up (needs root): $(cat "$LOGS/mount.err")"
  exit 77
fi
DAEMON_PID=""
stop_all_then_cleanup() {
  local rc=$?
  set +e
  [[ -n $DAEMON_PID ]] && kill -KILL "$DAEMON_PID" 2>/dev/null && wait "$DAEMON_PID" 2>/dev/null
  umount "$MNT" 2>/dev/null || umount -l "$MNT" 2>/dev/null
  (exit "$rc")
  serve_cleanup
}
trap stop_all_then_cleanup EXIT

# metric NAME: the daemon's value of an unlabelled metric.
metric() { curl -s "$DADMIN/metrics" | sed -nE "s/^$1 ([0-9]+)$/\1/p"; }
health() { curl -s -w ' %{http_code}' "$DADMIN/health"; }

note "upstream: vts serve of a synthetic archive (noise-free tiles of a few KiB to tens of KiB)"
expect_ok "$VTS" build --synthetic 4096x4096 --tile 128 -o "$WORK/syn.pmtiles"
start_server "$WORK/syn.pmtiles"

note "the daemon, its cache on a 512 KiB tmpfs"
start_daemon cache "$VTS" cache serve --upstream "$BASE/syn" --cache-dir "$MNT/cache" --ram-size 0 \
  --listen 127.0.0.1:0 --admin 127.0.0.1:0
[[ -n $DADMIN ]] || fail "the daemon has no admin port"
[[ $(health) == "ok"*" 200" ]] || fail "a fresh daemon is not healthy: $(health)"
[[ $(metric vts_cache_disk_writes_failing) == 0 ]] || fail "failing before any write"

# Level 5 of 4096 / 128 has 32 x 32 tiles: fetch them one by one until the writes fail, and
# 20 more after that (a few hundred failed writes would each have been a line before).
note "fill the disk: fetch tiles until writes fail"
failed_at=""
n=0
for ((y = 0; y < 32; y++)); do
  for ((x = 0; x < 32; x++)); do
    n=$((n + 1))
    code=$(status_of "$D/syn/5/$x/$y")
    [[ $code == 200 ]] || fail "tile 5/$x/$y answered $code while the disk filled (tiles come from the upstream)"
    if [[ -z $failed_at ]] && (($(metric vts_cache_disk_write_errors_total) > 0)); then
      failed_at=$n
    fi
    [[ -n $failed_at ]] && ((n >= failed_at + 20)) && break 2
  done
done
[[ -n $failed_at ]] || fail "the 512 KiB disk never filled up after $n tiles"
errors=$(metric vts_cache_disk_write_errors_total)
note "writes failed from tile $failed_at on; $errors failed writes after $n tiles"
((errors >= 10)) || fail "only $errors failed writes: the test needs many to show the rate limit"

note "/health: 503 degraded, with the reason"
h=$(health)
note "$h"
[[ $h == "degraded: disk cache writes failing"*" 503" ]] || fail "/health during failing writes: $h"
[[ $h == *"disk full"* ]] || fail "/health does not name the disk full: $h"
[[ $(metric vts_cache_disk_writes_failing) == 1 ]] || fail "vts_cache_disk_writes_failing is not 1"

note "stderr: one line for the first failure, not one per failed write"
lines=$(grep -c 'disk cache write' "$LOGS/cache.err" || true)
grep 'disk cache write' "$LOGS/cache.err" | head -3 | cut -c1-300
((lines == 1)) || fail "$lines stderr lines about disk writes for $errors failures (want 1)"
grep -q 'warning: disk cache write failed; tiles are served but not kept.*disk full' \
  "$LOGS/cache.err" || fail "the first failure's line does not say what and why"

note "room again (the tmpfs grown to 16 MiB): the next stored tile makes the daemon healthy"
mount -o remount,size=16m "$MNT" || fail "cannot grow the tmpfs"
healthy=""
for ((y = 16; y < 32; y++)); do # rows the fill did not reach
  [[ -n $healthy ]] && break
  for ((x = 0; x < 32; x++)); do
    expect_status 200 "$D/syn/5/$x/$y"
    if [[ $(health) == "ok"*" 200" ]]; then
      healthy="5/$x/$y"
      break
    fi
  done
done
[[ -n $healthy ]] || fail "still degraded after the disk had room: $(health)"
note "healthy again after tile $healthy"
[[ $(metric vts_cache_disk_writes_failing) == 0 ]] || fail "vts_cache_disk_writes_failing is not 0"
grep -q 'disk cache writes succeed again, after [0-9]* failed writes' "$LOGS/cache.err" ||
  fail "no 'succeed again' line on stderr"

kill -TERM "$DAEMON_PID"
wait "$DAEMON_PID" || fail "vts cache serve exited $? after SIGTERM"
DAEMON_PID=""
if grep -qE 'AddressSanitizer|runtime error:' "$LOGS/cache.err"; then
  cat "$LOGS/cache.err" >&2
  fail "sanitizer report from vts cache serve"
fi
stop_server
note "PASS"
