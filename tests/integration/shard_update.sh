#!/usr/bin/env bash
# Incremental sharded builds (docs/PLANET.md, "Incremental updates"): a 2x2 --grid mosaic planned
# in 16 shards, built and merged; one input changes; `vts plan --update` lists exactly the shards
# whose window (core plus halo) meets that input's cell; rebuilding those and the apex and merging
# gives the archive a full `vts build` of the new inputs writes (sha256), without touching the
# other parts (mtimes); a listed shard left unbuilt, or an apex left unbuilt, makes `vts merge`
# fail naming the stale part. Prints the fraction of shards rebuilt.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool "$OIIOTOOL"

# A 2048 x 2048 mosaic of four 1024 x 1024 cells (the Earth's halves, twice): level 2 is 4 x 4
# tiles of 512 x 512 finest texels, so --shards 16 gives 16 shards.
for r in 0 1; do
  for c in 0 1; do
    crop_ref "$EARTH" 1024 1024 $((c * 1024)) 0 "$WORK/cell_$r$c.png"
  done
done
cells=("$WORK/cell_00.png" "$WORK/cell_01.png" "$WORK/cell_10.png" "$WORK/cell_11.png")
opts=(--grid 2x2 --name grid)
plan="$WORK/old.plan.json" parts="$WORK/parts"
mkdir -p "$WORK/old" "$WORK/merged"

build_shards() { # PLAN SHARD...
  local p=$1
  shift
  for i in "$@"; do
    expect_ok "$VTS" build --plan "$p" --shard "$i" --out-dir "$parts" --threads 2 -q
  done
}

note "plan 16 shards, build them all, the apex, and merge"
expect_ok "$VTS" plan "${cells[@]}" "${opts[@]}" -o "$plan" --shards 16 --json
json_check "$OUT" "j.shards === 16 && j.split_level === 2 && /^[0-9a-f]{16}$/.test(j.build_hash)"
build_shards "$plan" $(seq 0 15)
expect_ok "$VTS" build --plan "$plan" --apex --out-dir "$parts" -q
expect_ok "$VTS" merge --plan "$plan" "$parts" -o "$WORK/old/grid.pmtiles" -q

note "nothing changed: --update lists no shard"
expect_ok "$VTS" plan --update "$plan" -o "$WORK/same.plan.json" --json
json_check "$OUT" "j.changed_inputs.length === 0 && j.rebuild.length === 0 && j.apex === false"

note "change one input (the bottom right cell), --update"
"$OIIOTOOL" "$WORK/cell_11.png" --box:color=1,0,0:fill=1 100,200,400,500 -o "$WORK/cell_11.png"
new="$WORK/new.plan.json"
declare -A before
for f in "$parts"/*.part; do before[$f]=$(stat -c %Y.%y "$f"); done
expect_ok "$VTS" plan --update "$plan" "${cells[@]}" -o "$new" --json
cp "$OUT" "$WORK/update.json"
json_check "$OUT" "j.changed_inputs.length === 1 && j.changed_inputs[0].endsWith('cell_11.png')"
json_check "$OUT" "j.build_hash === JSON.parse(require('fs').readFileSync('$plan')).build_hash" \
  "the update keeps the build hash"
# Exactly the shards whose window meets the cell 1024..2048 x 1024..2048: level-2 tiles (x, y)
# with x, y >= 1 (tile 1's core ends at 1024, its halo reaches into the cell; tile 0's does not).
want=$("$NODE" -e '
  const p = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
  const w = [];
  p.shards.forEach(([x, y], i) => { if (x >= 1 && y >= 1) w.push(i); });
  console.log(JSON.stringify(w));' "$new")
got=$(json_get "$WORK/update.json" "JSON.stringify(j.rebuild)")
[[ $got == "$want" ]] || fail "update lists shards $got, want $want"
json_check "$WORK/update.json" "j.rebuild.length === 9 && j.shards === 16 && j.apex === true" \
  "9 of 16 shards and the apex"
mapfile -t rebuild < <(json_get "$WORK/update.json" "j.rebuild.join('\n')")
fraction=$(json_get "$WORK/update.json" "j.rebuild_fraction")
printf 'shards rebuilt: %s of 16 (fraction %s) for one changed cell of 4 (25%% of the texels)\n' \
  "${#rebuild[@]}" "$fraction"
"$VTS" plan --update "$plan" -o "$WORK/text.plan.json" >"$WORK/update.txt" 2>&1 ||
  fail "--update without inputs failed"
grep -q "rebuild 9 of 16 shards" "$WORK/update.txt" && grep -q "apex must be rebuilt" \
  "$WORK/update.txt" || fail "the update's summary does not list the shards and the apex"

note "the old parts are refused by the new plan: a listed shard not rebuilt is stale"
expect_clean_failure "$VTS" merge --plan "$new" "$parts" -o "$WORK/stale.pmtiles"
first=$(printf 'shard-%06d.part' "${rebuild[0]}")
grep -q "$first is stale: input .*cell_11.png changed since it was built; rebuild shard ${rebuild[0]}" \
  "$ERR" || fail "merge does not name the stale part, the input and the shard to rebuild"
[[ ! -e "$WORK/stale.pmtiles" ]] || fail "merge with a stale part wrote an output"
expect_clean_failure "$VTS" build --plan "$new" --apex --out-dir "$parts"
grep -q "is stale" "$ERR" || fail "the apex accepts a stale shard part"

note "rebuild all listed shards but the last: still refused, naming it"
last=${rebuild[-1]}
build_shards "$new" "${rebuild[@]:0:${#rebuild[@]}-1}"
expect_clean_failure "$VTS" merge --plan "$new" "$parts" -o "$WORK/stale.pmtiles"
grep -q "$(printf 'shard-%06d.part' "$last") is stale" "$ERR" || fail "the unbuilt shard $last is not named"
build_shards "$new" "$last"

note "every shard rebuilt but not the apex: the apex is stale"
expect_clean_failure "$VTS" merge --plan "$new" "$parts" -o "$WORK/stale.pmtiles"
grep -q "apex.part is stale" "$ERR" && grep -q "rebuild the apex" "$ERR" ||
  fail "merge does not say the apex is stale"
expect_ok "$VTS" build --plan "$new" --apex --out-dir "$parts" -q

note "merge: the archive a full vts build of the new inputs writes; other parts untouched"
expect_ok "$VTS" merge --plan "$new" "$parts" -o "$WORK/merged/grid.pmtiles" -q
expect_ok "$VTS" build "${cells[@]}" "${opts[@]}" -o "$WORK/grid.pmtiles" -q
[[ $(sha "$WORK/merged/grid.pmtiles") == $(sha "$WORK/grid.pmtiles") ]] ||
  fail "the updated merge differs from a full build of the new inputs"
[[ $(sha "$WORK/merged/grid.pmtiles") != $(sha "$WORK/old/grid.pmtiles") ]] ||
  fail "the changed input did not change the archive"
for i in $(seq 0 15); do
  f=$(printf '%s/shard-%06d.part' "$parts" "$i")
  if [[ " ${rebuild[*]} " == *" $i "* ]]; then
    [[ $(stat -c %Y.%y "$f") != "${before[$f]}" ]] || fail "listed shard $i was not rebuilt"
  else
    [[ $(stat -c %Y.%y "$f") == "${before[$f]}" ]] || fail "unaffected shard $i's part was touched"
  fi
done

note "an update that changes the build is refused, naming what"
expect_clean_failure "$VTS" plan --update "$plan" "${cells[@]:0:3}" -o "$WORK/bad.plan.json"
grep -q "3 inputs given, the plan has 4" "$ERR" || fail "a wrong input count is not named"
expect_clean_failure "$VTS" plan --update "$plan" -o "$WORK/bad.plan.json" --codec bc1
grep -q -- "--codec" "$ERR" || fail "a build option with --update is not named"
crop_ref "$EARTH" 1000 1024 0 0 "$WORK/narrow0.png"
crop_ref "$EARTH" 1000 1024 0 0 "$WORK/narrow1.png"
expect_clean_failure "$VTS" plan --update "$plan" "$WORK/narrow0.png" "${cells[1]}" \
  "$WORK/narrow1.png" "${cells[3]}" -o "$WORK/bad.plan.json"
grep -q "2024x2048 image, the plan's is 2048x2048" "$ERR" || fail "another image size is not named"
[[ ! -e "$WORK/bad.plan.json" ]] || fail "a refused update wrote a plan"
