#!/usr/bin/env bash
# Sharded builds end to end through the CLI (docs/PLANET.md, "Plans, shards and parts"): `vts plan`,
# `vts build --plan --shard I` for every shard, `vts build --plan --apex`, `vts merge` write the very
# archive `vts build` writes (sha256), for 1, 4 and 16 shards, lossless and bc1, a plain image, a
# --grid mosaic (lanczos3: the widest halo) and synthetic sources (dense and sparse). A shard killed
# mid-way and run again, or run twice at once, leaves the same bytes; a missing or corrupt part makes
# `vts merge` fail naming it and write nothing; bad shard indexes are clear errors.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool "$OIIOTOOL"

# sharded NAME SHARDS BUILD-ARGS...: plans, builds every shard and the apex, merges into
# $WORK/merged/NAME.pmtiles (the same stem as `vts build -o $WORK/NAME.pmtiles`: the same name in
# the metadata); the plan is $WORK/NAME.plan.json, the parts in $WORK/NAME.parts/.
sharded() {
  local name=$1 shards=$2
  shift 2
  local plan="$WORK/$name.plan.json" parts="$WORK/$name.parts"
  # APEX_LEVELS: the plan's --apex-levels (unset: the default, 2).
  expect_ok "$VTS" plan "$@" -o "$plan" --shards "$shards" ${APEX_LEVELS:+--apex-levels "$APEX_LEVELS"} \
    --json
  local n
  n=$(json_get "$OUT" "j.shards")
  ((n >= shards)) || fail "$name: asked for $shards shards, the plan has $n"
  # Two at a time, as an array job's workers would run them.
  seq 0 $((n - 1)) | timeout -k 10 "$CMD_TIMEOUT" xargs -P 2 -I{} "$VTS" build --plan "$plan" \
    --shard {} --out-dir "$parts" --threads 1 -q 2>"$ERR" || {
    cat "$ERR" >&2
    fail "$name: a shard failed"
  }
  expect_ok "$VTS" build --plan "$plan" --apex --out-dir "$parts" -q
  mkdir -p "$WORK/merged"
  expect_ok "$VTS" merge --plan "$plan" "$parts" -o "$WORK/merged/$name.pmtiles" --json
  json_check "$OUT" "j.parts === $n + (j.parts > $n ? 1 : 0) && j.tiles > 0"
}

# same_as_build NAME SHARDS BUILD-ARGS...: the merged archive equals `vts build`'s, byte for byte.
same_as_build() {
  local name=$1 shards=$2
  shift 2
  local ref="$WORK/$name.pmtiles"
  [[ -s $ref ]] || expect_ok "$VTS" build "$@" -o "$ref" -q
  sharded "$name" "$shards" "$@"
  local got="$WORK/merged/$name.pmtiles"
  [[ $(sha "$got") == $(sha "$ref") ]] || {
    "$PMTILES_DUMP" "$ref" >"$LOGS/ref.dump" 2>&1 || true
    "$PMTILES_DUMP" "$got" >"$LOGS/got.dump" 2>&1 || true
    diff "$LOGS/ref.dump" "$LOGS/got.dump" | head -20 >&2 || true
    fail "$name with $shards shards: merged archive differs from vts build's"
  }
}

note "plain image, lossless and bc1, 1 / 4 / 16 shards"
for codec in lossless bc1; do
  for n in 1 4 16; do
    same_as_build "earth_${codec}_$n" "$n" "$EARTH" --codec "$codec"
  done
done

note "merge --no-verify (payloads copied by copy_file_range): the same bytes"
mkdir -p "$WORK/no_verify"  # the same file name: the name is in the metadata
expect_ok "$VTS" merge --plan "$WORK/earth_bc1_16.plan.json" "$WORK/earth_bc1_16.parts" \
  -o "$WORK/no_verify/earth_bc1_16.pmtiles" --no-verify -q
[[ $(sha "$WORK/no_verify/earth_bc1_16.pmtiles") == $(sha "$WORK/earth_bc1_16.pmtiles") ]] ||
  fail "merge --no-verify wrote other bytes than vts build"

note "a 2x2 --grid mosaic with lanczos3 (the widest halo), 4 shards"
for r in 0 1; do
  for c in 0 1; do
    crop_ref "$EARTH" 1024 512 $((c * 1024)) $((r * 512)) "$WORK/piece_$r$c.png"
  done
done
same_as_build grid 4 "$WORK/piece_00.png" "$WORK/piece_01.png" "$WORK/piece_10.png" \
  "$WORK/piece_11.png" --grid 2x2 --downsample lanczos3 --name grid --border 2

note "the apex levels: shards stopping at their split level (0), one level (1) or two above it"
for k in 0 1; do
  APEX_LEVELS=$k same_as_build "grid_k$k" 4 "$WORK/piece_00.png" "$WORK/piece_01.png" \
    "$WORK/piece_10.png" "$WORK/piece_11.png" --grid 2x2 --downsample lanczos3 --name grid \
    --border 2
  json_get "$WORK/grid_k$k.plan.json" "j.apex_level === j.split_level + $k" | grep -q true ||
    fail "--apex-levels $k: the plan's apex level is not its split level + $k"
  APEX_LEVELS=$k same_as_build "earth_k$k" 16 "$EARTH" --codec bc1
done
json_get "$WORK/grid.plan.json" "j.apex_level === Math.min(j.split_level + 2, j.geometry.max_zoom)" |
  grep -q true || fail "the default apex level is not min(split level + 2, max zoom)"

note "synthetic, dense and sparse (a region at levels >= 2), 16 shards"
same_as_build synth 16 --synthetic 3000x1700
same_as_build sparse 16 --synthetic 40000x20000 --region 1000,1000,3000,2500 --region-level 2 \
  --codec bc1

note "the shard's report states its halo overhead"
plan="$WORK/earth_lossless_4.plan.json"
expect_ok "$VTS" build --plan "$plan" --shard 0 --out-dir "$WORK/again" --json
json_check "$OUT" "j.texels_read > j.core_texels && j.halo_overhead > 1 && j.halo_overhead < 1.5" \
  "a shard reads its core plus a halo"
# Shard 2 is level-2 tile (1, 1): core 512..1024 x 512..1024 of the 2048 x 1024 image (max zoom
# 3). Its apex level is min(2 + 2, 3) = 3, the finest: its tiles' borders, B = 4 finest texels,
# are its whole halo (box), clipped below: 520 x 516 texels. Stopping at the split level 2
# (--apex-levels 0) it needed B texels at level 2 plus the box filter's reach below them, 8
# finest texels: 528 x 520.
expect_ok "$VTS" build --plan "$plan" --shard 2 --out-dir "$WORK/again" --json
json_check "$OUT" "j.root === '2/1/1' && j.core_texels === 512 * 512 && j.texels_read === 520 * 516" \
  "shard 2 reads 520 x 516 texels"
plan0="$WORK/earth_k0_4.plan.json"
expect_ok "$VTS" plan "$EARTH" -o "$plan0" --shards 4 --apex-levels 0 -q
expect_ok "$VTS" build --plan "$plan0" --shard 2 --out-dir "$WORK/again_k0" --json
json_check "$OUT" "j.root === '2/1/1' && j.texels_read === 528 * 520" \
  "with --apex-levels 0, shard 2 reads 528 x 520 texels"
cmp "$WORK/again/shard-000000.part" "$WORK/earth_lossless_4.parts/shard-000000.part" ||
  fail "building the same shard again gave different bytes"

note "the shard index from an array job's environment"
JOB_COMPLETION_INDEX=1 expect_ok "$VTS" build --plan "$plan" --out-dir "$WORK/env" -q
SLURM_ARRAY_TASK_ID=2 expect_ok "$VTS" build --plan "$plan" --out-dir "$WORK/env" -q
AWS_BATCH_JOB_ARRAY_INDEX=3 expect_ok "$VTS" build --plan "$plan" --out-dir "$WORK/env" -q
for i in 1 2 3; do
  cmp "$WORK/env/shard-00000$i.part" "$WORK/earth_lossless_4.parts/shard-00000$i.part" ||
    fail "shard $i from the environment differs"
done
unset JOB_COMPLETION_INDEX SLURM_ARRAY_TASK_ID AWS_BATCH_JOB_ARRAY_INDEX
expect_clean_failure "$VTS" build --plan "$plan" --out-dir "$WORK/env"
for v in JOB_COMPLETION_INDEX SLURM_ARRAY_TASK_ID AWS_BATCH_JOB_ARRAY_INDEX; do
  grep -q "$v" "$ERR" || fail "the error without a shard index does not name \$$v"
done

note "build options beside --plan are refused: the plan fixes them"
expect_clean_failure "$VTS" build --plan "$plan" --shard 0 --out-dir "$WORK/env" --codec bc1
grep -q -- "--codec" "$ERR" || fail "the error does not name --codec"
expect_clean_failure "$VTS" build "$EARTH" --plan "$plan" --shard 0 --out-dir "$WORK/env"
[[ ! -e "$WORK/env/shard-000000.part" ]] || fail "a refused shard wrote a part"

note "a shard index out of range"
expect_clean_failure "$VTS" build --plan "$plan" --shard 8 --out-dir "$WORK/env"
grep -q "out of range" "$ERR" && grep -q "8 shards" "$ERR" || fail "unclear out-of-range error"
[[ ! -e "$WORK/env/shard-000008.part" ]] || fail "an out-of-range shard wrote a part"

note "a shard killed mid-way (SIGKILL) and run again: the same bytes"
big="$WORK/big.plan.json"
expect_ok "$VTS" plan --synthetic 16384x8192 -o "$big" --shards 4 -q
expect_ok "$VTS" build --plan "$big" --shard 0 --out-dir "$WORK/big_ref" --threads 1 -q
mkdir -p "$WORK/big"
"$VTS" build --plan "$big" --shard 0 --out-dir "$WORK/big" --threads 1 -q &
pid=$!
# Mid-way: once it has spooled tiles, before the part exists. The spool is an unlinked file
# beside the part, and its only writes before the part are spooled tiles: /proc/PID/io's wchar
# tells (some kernels and sandboxes cannot stat an unlinked file through /proc/PID/fd).
spooled() {
  local written
  written=$(awk '/^wchar:/ { print $2 }' /proc/"$pid"/io 2>/dev/null)
  ((${written:-0} > 0))
}
deadline=$((SECONDS + 60))
until spooled; do
  ((SECONDS < deadline)) || fail "the shard spooled nothing within 60 s"
  kill -0 "$pid" 2>/dev/null || break
  sleep 0.01
done
kill -KILL "$pid" 2>/dev/null || true
wait "$pid" 2>/dev/null || true
[[ ! -e "$WORK/big/shard-000000.part" ]] || fail "the shard finished before it was killed"
expect_ok "$VTS" build --plan "$big" --shard 0 --out-dir "$WORK/big" --threads 1 -q
cmp "$WORK/big/shard-000000.part" "$WORK/big_ref/shard-000000.part" ||
  fail "the rerun after a kill gave different bytes"

note "the same shard twice at once: the same bytes"
"$VTS" build --plan "$big" --shard 1 --out-dir "$WORK/twice" --threads 1 -q &
p1=$!
"$VTS" build --plan "$big" --shard 1 --out-dir "$WORK/twice" --threads 1 -q &
p2=$!
wait "$p1" || fail "the first of two concurrent runs failed"
wait "$p2" || fail "the second of two concurrent runs failed"
expect_ok "$VTS" build --plan "$big" --shard 1 --out-dir "$WORK/big_ref" --threads 1 -q
cmp "$WORK/twice/shard-000001.part" "$WORK/big_ref/shard-000001.part" ||
  fail "two concurrent runs left different bytes"

note "a missing part: merge and apex name it and write nothing"
parts="$WORK/synth.parts"
splan="$WORK/synth.plan.json"
mv "$parts/shard-000002.part" "$WORK/held.part"
expect_clean_failure "$VTS" merge --plan "$splan" "$parts" -o "$WORK/missing.pmtiles"
grep -q "shard-000002.part" "$ERR" || fail "merge does not name the missing part"
[[ ! -e "$WORK/missing.pmtiles" ]] || fail "merge with a missing part wrote an output"
eplan="$WORK/earth_lossless_4.plan.json"
eparts="$WORK/earth_lossless_4.parts"
mv "$eparts/shard-000001.part" "$WORK/held_earth.part"
expect_clean_failure "$VTS" build --plan "$eplan" --apex --out-dir "$eparts"
grep -q "shard-000001.part" "$ERR" || fail "the apex does not name the missing part"
mv "$WORK/held_earth.part" "$eparts/shard-000001.part"
mv "$WORK/held.part" "$parts/shard-000002.part"

note "a corrupt part (a byte of its index flipped): merge names it and writes nothing"
cp "$parts/shard-000003.part" "$WORK/good.part"
# A synthetic shard has no attachment: its index ends where its manifest (JSON) begins.
python3 - "$parts/shard-000003.part" <<'EOF'
import sys
p = sys.argv[1]
d = bytearray(open(p, 'rb').read())
m = d.rfind(b'{"build_hash"')
assert m > 0, "no manifest found"
d[m - 3] ^= 0x40
open(p, 'wb').write(bytes(d))
EOF
expect_clean_failure "$VTS" merge --plan "$splan" "$parts" -o "$WORK/corrupt.pmtiles"
grep -q "shard-000003.part" "$ERR" || fail "merge does not name the corrupt part"
[[ ! -e "$WORK/corrupt.pmtiles" ]] || fail "merge with a corrupt part wrote an output"

note "a part of another plan: merge names it"
cp "$WORK/good.part" "$parts/shard-000003.part"
cp "$WORK/earth_lossless_16.parts/shard-000000.part" "$parts/shard-000000.part"
expect_clean_failure "$VTS" merge --plan "$splan" "$parts" -o "$WORK/other.pmtiles"
grep -q "shard-000000.part" "$ERR" && grep -q "plan" "$ERR" || fail "a foreign part is not named"
[[ ! -e "$WORK/other.pmtiles" ]] || fail "merge with a foreign part wrote an output"

note "split level 0 and no apex levels: no apex"
expect_ok "$VTS" plan "$EARTH" -o "$WORK/l0.plan.json" --split-level 0 --apex-levels 0 -q
expect_ok "$VTS" build --plan "$WORK/l0.plan.json" --apex --out-dir "$WORK/l0"
grep -q "no apex" "$OUT" || fail "--apex at apex level 0 does not say there is none"
