#!/usr/bin/env bash
# Long commands stop and clean up, and a refused thread is an error, not an abort:
# - build and export under `ulimit -v` with --threads 1000 (the system refuses a thread's stack)
#   exit 4 naming the cause and write nothing (was: "terminate called without an active
#   exception", exit 134);
# - `--synthetic 4294967296x1` (one row of 16.7 million tiles) stops within seconds of SIGTERM
#   (was: about 10 s);
# - `extract --level` stopped by SIGTERM exits 130 and leaves no OUT.tmp;
# - an `export --layout xyz` killed outright (SIGKILL, or a second SIGTERM) leaves its hidden
#   partial folder, which the next export to the same folder removes (not one a running export
#   holds locked); what a killed extract leaves, OUT.tmp, the next extraction overwrites.
# Waits are on conditions (a signal handler installed, threads started, a file appearing), never
# on a fixed sleep.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

D="$WORK/out"
mkdir -p "$D"

# wait_for DESCRIPTION PID COMMAND...: polls COMMAND until it succeeds; fails if PID ends first or
# 60 s pass.
wait_for() {
  local what=$1 pid=$2
  shift 2
  local i
  for ((i = 0; i < 3000; i++)); do
    "$@" && return 0
    kill -0 "$pid" 2>/dev/null || fail "the command ended before $what"
    sleep 0.02
  done
  fail "no $what within 60 s"
}
# catches_sigterm PID: PID has a handler for SIGTERM (bit 15 of SigCgt).
catches_sigterm() {
  local mask
  mask=$(awk '/^SigCgt/ {print $2}' "/proc/$1/status" 2>/dev/null) || return 1
  [[ -n $mask ]] && (((0x$mask >> 14) & 1))
}

note "a thread the system refuses: exit 4 naming it, nothing written (ulimit -v)"
expect_ok "$VTS" build --synthetic 4096x4096 -o "$WORK/s.pmtiles" -q
# 2 GiB of address space: vts loads, 1000 threads' 8 MiB stacks do not fit.
for cmd in "build --synthetic 4096x4096 -o $D/t.pmtiles" \
  "export $WORK/s.pmtiles -o $D/t.pmtiles --format png" \
  "export $WORK/s.pmtiles -o $D/site --layout xyz --format png"; do
  # shellcheck disable=SC2086  # the words of $cmd are the arguments
  expect_clean_failure bash -c 'ulimit -v 2097152 && exec "$@"' sh "$VTS" $cmd --threads 1000
  ((RC == 4)) && grep -q 'cannot start a thread' "$ERR" ||
    { show_output; fail "'vts $cmd --threads 1000' under ulimit -v exited $RC"; }
  [[ -z $(dir_listing "$D") ]] || { dir_listing "$D" >&2; fail "'vts $cmd' left files"; }
done

note "--synthetic 4294967296x1: SIGTERM in its one long row stops it within 5 s"
"$VTS" build --synthetic 4294967296x1 --threads 2 -o "$D/wide.pmtiles" -q >"$OUT" 2>"$ERR" &
pid=$!
# The handler is installed a few milliseconds before the row starts (a synthetic build prepares
# nothing), and the row takes seconds: the signal lands in it.
wait_for "the SIGTERM handler" "$pid" catches_sigterm "$pid"
start=$(date +%s%N)
kill -TERM "$pid"
set +e
wait "$pid"
RC=$?
set -e
ms=$((($(date +%s%N) - start) / 1000000))
note "exit $RC after $ms ms"
((RC == 130)) || { show_output; fail "the interrupted build exited $RC, expected 130"; }
((ms < 5000)) || fail "the build took $ms ms to stop after SIGTERM"
[[ -z $(dir_listing "$D") ]] || { dir_listing "$D" >&2; fail "the interrupted build left files"; }

note "extract --level: SIGTERM exits 130 and leaves no OUT.tmp"
expect_ok "$VTS" build --synthetic 8192x8192 -o "$WORK/x.pmtiles" -q
"$VTS" extract "$WORK/x.pmtiles" --level 5 -o "$D/level.png" >"$OUT" 2>"$ERR" &
pid=$!
wait_for "level.png.tmp" "$pid" test -e "$D/level.png.tmp"
kill -TERM "$pid"
set +e
wait "$pid"
RC=$?
set -e
((RC == 130)) || { show_output; fail "the interrupted extract exited $RC, expected 130"; }
[[ -z $(dir_listing "$D") ]] || { dir_listing "$D" >&2; fail "the interrupted extract left files"; }
# What a SIGKILL leaves, OUT.tmp, is overwritten by the next extraction to OUT.
printf 'left by a killed extract' >"$D/level.png.tmp"
expect_ok "$VTS" extract "$WORK/x.pmtiles" --level 1 -o "$D/level.png"
[[ $(dir_listing "$D") == ./level.png ]] || { dir_listing "$D" >&2; fail "OUT.tmp was left"; }
rm "$D/level.png"

note "export --layout xyz killed outright: the next export removes the partial folder"
has_tile() { [[ -n $(find "$D" -path "$D/.site.partial-*/*/*/*.png" -print -quit) ]]; }
"$VTS" export "$WORK/x.pmtiles" -o "$D/site" --layout xyz --format png --threads 1 -q \
  >"$OUT" 2>"$ERR" &
pid=$!
wait_for "a tile in the partial folder" "$pid" has_tile
kill -KILL "$pid"
wait "$pid" || true
partial=$(find "$D" -maxdepth 1 -name '.site.partial-*')
[[ -n $partial && ! -e $D/site ]] || { dir_listing "$D" >&2; fail "expected only a partial folder"; }
expect_ok "$VTS" export "$WORK/s.pmtiles" -o "$D/site" --layout xyz --format png -q
[[ ! -e $partial ]] || fail "the next export left the killed one's $partial"
[[ -z $(find "$D" -maxdepth 1 -name '.site.partial-*') ]] || fail "a partial folder is left"
[[ -s $D/site/0/0/0.png && -s $D/site/metadata.json ]] || fail "the next export is incomplete"
# A partial folder whose export still runs (it holds a lock on it) is left alone.
rm -r "$D/site"
mkdir "$D/.site.partial-Running"
expect_ok flock "$D/.site.partial-Running" "$VTS" export "$WORK/s.pmtiles" -o "$D/site" \
  --layout xyz --format png -q
[[ -d $D/.site.partial-Running && -s $D/site/metadata.json ]] ||
  fail "an export removed a partial folder another export holds"

note "PASS"
