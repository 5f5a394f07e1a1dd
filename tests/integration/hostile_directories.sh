#!/usr/bin/env bash
# Hostile directories (pmtiles_hostile.py): leaf bombs, a root bomb, runs of 2^32 - 1 tiles and a
# header that lies about tile compression. `vts serve` stays within a memory bound however many
# bombs are touched, `vts info` and `vts verify` finish in seconds with the right counts, and
# every refusal is a clean error naming what was wrong. A verify whose decoder threads cannot all
# start fails cleanly too.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
require_tool python3
HOSTILE="$(dirname "${BASH_SOURCE[0]}")/pmtiles_hostile.py"

expect_ok "$VTS" build --synthetic 3000x1700 -o "$WORK/syn.pmtiles"  # 117 tiles, levels 0..4

# vm_rss_kib PID: resident memory of PID in KiB.
vm_rss_kib() { awk '/^VmRSS:/ { print $2 }' "/proc/$1/status"; }

note "runs of 2^32 - 1 tiles: info and verify count them with arithmetic"
python3 "$HOSTILE" runs "$WORK/syn.pmtiles" "$WORK/runs.pmtiles" 3
RUN=$(((1 << 32) - 1))
CMD_TIMEOUT=20 expect_ok "$VTS" info "$WORK/runs.pmtiles" --json
cp "$OUT" "$WORK/runs_info.json"
json_check "$WORK/runs_info.json" "j.tiles === 3 * $RUN" "info counts 3 runs of 2^32 - 1 tiles"
json_check "$WORK/runs_info.json" 'j.levels.map(l => l.tiles).join() === "1,4,16,64,256"' \
  "every level of the pyramid wholly addressed by the first run"
CMD_TIMEOUT=20 run "$VTS" verify "$WORK/runs.pmtiles" --json
((RC != 124)) || fail "vts verify did not finish a 2.6 KiB archive of runs within 20 s"
((RC > 0 && RC < 128)) || { show_output; fail "vts verify exited $RC, expected a clean failure"; }
cp "$OUT" "$WORK/runs_verify.json"
json_check "$WORK/runs_verify.json" "j.tiles_checked === 3 * $RUN" "verify checks 3 runs"
json_check "$WORK/runs_verify.json" "j.bad_tiles === 3 * $RUN - 117" \
  "each tile outside the pyramid is bad once; the 117 inside are good"

note "a root directory of 4M entries (16 KiB of gzip) is refused before it is decoded"
python3 "$HOSTILE" root-bomb "$WORK/syn.pmtiles" "$WORK/root_bomb.pmtiles" 4194304
for cmd in info verify; do
  (ulimit -v 1000000 && expect_clean_failure "$VTS" "$cmd" "$WORK/root_bomb.pmtiles")
  grep -q 'entries per directory' "$ERR" || { show_output; fail "vts $cmd: no entry-cap message"; }
done

note "a header declaring gzip tiles is refused, naming the field"
python3 "$HOSTILE" tile-compression "$WORK/syn.pmtiles" "$WORK/gzip_tiles.pmtiles" 2
for cmd in info verify extract serve; do
  args=("$WORK/gzip_tiles.pmtiles")
  [[ $cmd == extract ]] && args+=(0/0/0 -o "$WORK/t.png")
  [[ $cmd == serve ]] && args+=(--listen 127.0.0.1:0 --no-admin)
  expect_clean_failure "$VTS" "$cmd" "${args[@]}"
  grep -q 'tile_compression' "$ERR" || { show_output; fail "vts $cmd does not name tile_compression"; }
done

note "verify with decoder threads that cannot start fails cleanly"
(ulimit -v 1000000 && expect_clean_failure "$VTS" verify "$WORK/syn.pmtiles" --threads 1000)
grep -q 'cannot start decoder thread' "$ERR" || { show_output; fail "no thread-start message"; }

note "vts serve: leaves over the entry cap are refused, leaves under it cached within bytes"
mkdir -p "$WORK/served"
python3 "$HOSTILE" leaf-bombs "$WORK/syn.pmtiles" "$WORK/served/bombs.pmtiles" 4 4194304 \
  >"$WORK/bomb_tiles.txt"
# 40 leaves of 2^20 entries: 24 MiB each decoded, 960 MiB if every one were kept.
python3 "$HOSTILE" leaf-bombs "$WORK/syn.pmtiles" "$WORK/served/big.pmtiles" 40 1048576 \
  >"$WORK/big_tiles.txt"
start_server "$WORK/served"
while read -r t; do
  expect_status 500 "$BASE/bombs/$t"
done <"$WORK/bomb_tiles.txt"
rss=$(vm_rss_kib "$SERVER_PID")
note "vts serve resident after 4 leaves of 4M entries: $rss KiB"
((rss < 320000)) || fail "vts serve holds $rss KiB after 4 refused leaves"
while read -r t; do
  expect_status 200 "$BASE/big/$t"
done <"$WORK/big_tiles.txt"
rss=$(vm_rss_kib "$SERVER_PID")
note "vts serve resident after touching 40 big leaves: $rss KiB"
((rss < 400000)) || fail "vts serve holds $rss KiB after 40 leaves (the leaf cache is not bounded)"
stop_server

note "PASS"
