#!/usr/bin/env bash
# A tileset as a set of archives (docs/FORMAT.md §7, docs/PLANET.md "The planet as a set"):
# `vts plan --archive-level K`, the shards, `vts merge -o DIR/` write one archive per level-K tile
# plus the top and tileset.json. Every tile lies in exactly one archive, byte for byte the
# one-file build's; each archive reads the same through the stock npm `pmtiles` library as through
# ours; merges run one archive at a time (as array tasks) and --manifest gives the same manifest;
# `vts merge --join` gives back the one-file archive byte for byte; `vts verify`, `vts info` and
# `vts serve` take the set as one tileset (every tile equal to the one-file archive's, one
# TileJSON, no /NAME.pmtiles), and a set replaced on disk is hot-reloaded as a whole. A sparse
# 2^25-texel planet makes a set too. Missing or foreign archives are clear errors.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"
: "${PMTILES_JS:?PMTILES_JS must name tests/integration/pmtiles_js}"
require_tool "$NODE"

# shards PLAN PARTS: every shard (two at a time, as an array job's workers) and the apex.
shards() {
  local plan=$1 parts=$2 n
  n=$(json_get "$plan" "j.shards.length")
  seq 0 $((n - 1)) | timeout -k 10 "$CMD_TIMEOUT" xargs -P 2 -I{} "$VTS" build --plan "$plan" \
    --shard {} --out-dir "$parts" --threads 1 -q --no-space-check 2>"$ERR" || {
    cat "$ERR" >&2
    fail "a shard of $plan failed"
  }
  expect_ok "$VTS" build --plan "$plan" --apex --out-dir "$parts" -q --no-space-check
}

# expect_error CODE PATTERN CMD...: CMD fails cleanly with exit code CODE and PATTERN on stderr.
expect_error() {
  local code=$1 pattern=$2
  shift 2
  expect_clean_failure "$@"
  ((RC == code)) || { show_output; fail "'$*' exited $RC, expected $code"; }
  grep -q -- "$pattern" "$ERR" || { show_output; fail "'$*': no '$pattern' in its error"; }
}

# tiles_of ARCHIVE...: the tiles the archives address ("tile_id z x y length hash"), sorted.
tiles_of() {
  local a
  for a in "$@"; do "$PMTILES_DUMP" tiles "$a" || fail "pmtiles_dump tiles $a failed"; done |
    sort -n
}

SYN=(--synthetic 3000x2000 --name t)
note "plan --archive-level 2: the plan says how many archives, the build hash is the one-file plan's"
expect_ok "$VTS" plan "${SYN[@]}" -o "$WORK/one.plan.json" --shards 4 --json
one_build_hash=$(json_get "$OUT" "j.build_hash")
expect_ok "$VTS" plan "${SYN[@]}" -o "$WORK/set.plan.json" --shards 4 --archive-level 2 --json
json_check "$OUT" "j.archive_level === 2 && j.archives === 7 && j.build_hash === '$one_build_hash'" \
  "a 3000x2000 image at level 2 is 3x2 tiles: 6 archives and the top"
json_check "$OUT" "j.estimated_bytes.archive_max > 0 && \
  j.estimated_bytes.archive_max < j.estimated_bytes.archive"
shards "$WORK/set.plan.json" "$WORK/parts"

note "merge -o DIR/: the archives and tileset.json"
mkdir -p "$WORK/ref"
expect_ok "$VTS" build "${SYN[@]}" -o "$WORK/ref/t.pmtiles" -q
expect_ok "$VTS" merge --plan "$WORK/set.plan.json" "$WORK/parts" -o "$WORK/set/" --json
json_check "$OUT" "j.archives === 7 && j.written === 7 && j.merged.length === 7 && \
  j.merged[0].name === 'top.pmtiles' && j.merged[0].tile === null && \
  j.merged.every(a => a.tiles > 0)"
[[ -s $WORK/set/tileset.json ]] || fail "no tileset.json"
mapfile -t archives < <(json_get "$WORK/set/tileset.json" "j.archives.map(a => a.name).join('\n')")
((${#archives[@]} == 7)) || fail "the manifest names ${#archives[@]} archives, not 7"

note "every tile in exactly one archive, byte for byte the one-file build's"
tiles_of "$WORK/ref/t.pmtiles" >"$WORK/ref.tiles"
(cd "$WORK/set" && tiles_of "${archives[@]}") >"$WORK/set.tiles"
cmp -s "$WORK/ref.tiles" "$WORK/set.tiles" || {
  diff "$WORK/ref.tiles" "$WORK/set.tiles" | head -20 >&2
  fail "the set's tiles are not the one-file archive's"
}

note "each archive is a PMTiles file of its own: the npm pmtiles library reads it as we do"
for a in "${archives[@]}"; do
  for mode in header tiles; do
    "$PMTILES_DUMP" "$mode" "$WORK/set/$a" >"$WORK/cpp.txt" || fail "pmtiles_dump $mode $a"
    "$NODE" "$PMTILES_JS/dump.mjs" "$mode" "$WORK/set/$a" >"$WORK/js.txt" ||
      fail "npm pmtiles cannot read $a ($mode)"
    cmp -s "$WORK/cpp.txt" "$WORK/js.txt" || fail "npm pmtiles and ours disagree on $a ($mode)"
  done
done
# Each header names its own zooms: the top 0..1, the others 2..4.
grep -qx 'min_zoom=0' <("$PMTILES_DUMP" header "$WORK/set/top.pmtiles") || fail "top min_zoom"
grep -qx 'max_zoom=1' <("$PMTILES_DUMP" header "$WORK/set/top.pmtiles") || fail "top max_zoom"
grep -qx 'min_zoom=2' <("$PMTILES_DUMP" header "$WORK/set/${archives[1]}") || fail "archive zooms"

note "merge --archive I, one at a time in any order, then --manifest: the same set"
for i in 6 0 3 1 5 2; do
  expect_ok "$VTS" merge --plan "$WORK/set.plan.json" "$WORK/parts" -o "$WORK/set2/" --archive "$i" \
    --json
  json_check "$OUT" "j.merged.length === 1 && j.merged[0].index === $i && j.manifest === undefined"
done
expect_error 3 "not been merged yet" \
  "$VTS" merge --plan "$WORK/set.plan.json" "$WORK/parts" -o "$WORK/set2/" --manifest
grep -q -- "--archive 4" "$ERR" || fail "the error does not name the --archive index to run"
[[ ! -e $WORK/set2/tileset.json ]] || fail "a manifest was written with an archive missing"
expect_ok "$VTS" merge --plan "$WORK/set.plan.json" "$WORK/parts" -o "$WORK/set2/" --archive 4 -q
expect_ok "$VTS" merge --plan "$WORK/set.plan.json" "$WORK/parts" -o "$WORK/set2/" --manifest -q
[[ $(sha "$WORK/set2/tileset.json") == $(sha "$WORK/set/tileset.json") ]] ||
  fail "the manifest of the archive-at-a-time merge differs"
expect_error 2 "outside the set's archives" \
  "$VTS" merge --plan "$WORK/set.plan.json" "$WORK/parts" -o "$WORK/set2/" --archive 7

note "merge --join: the one-file archive, byte for byte"
expect_ok "$VTS" merge --join "$WORK/set" -o "$WORK/joined.pmtiles" --json
json_check "$OUT" "j.tiles === $(wc -l <"$WORK/ref.tiles")"
[[ $(sha "$WORK/joined.pmtiles") == $(sha "$WORK/ref/t.pmtiles") ]] ||
  fail "the joined set differs from vts build's archive"

note "verify and info take the set (its folder or its manifest) as one tileset"
expect_ok "$VTS" verify "$WORK/set/tileset.json"
expect_ok "$VTS" info "$WORK/set" --json
json_check "$OUT" "j.tiles === $(wc -l <"$WORK/ref.tiles") || \
  j.addressed_tiles === $(wc -l <"$WORK/ref.tiles")" "info counts every archive's tiles"

note "export takes the set: the same web tiles as from the one-file archive"
expect_ok "$VTS" export "$WORK/set/" -o "$WORK/set_png.pmtiles" --format png -q
expect_ok "$VTS" export "$WORK/ref/t.pmtiles" -o "$WORK/ref_png.pmtiles" --format png -q
cmp -s <("$PMTILES_DUMP" tiles "$WORK/set_png.pmtiles") <("$PMTILES_DUMP" tiles "$WORK/ref_png.pmtiles") ||
  fail "the set's web tiles differ from the one-file archive's"

note "a damaged set: an archive replaced by another build's, a hostile manifest"
cp -r "$WORK/set" "$WORK/bad"
cp "$WORK/set/top.pmtiles" "$WORK/bad/${archives[2]}"
expect_error 75 "is not the one the set's manifest names" "$VTS" verify "$WORK/bad"
cp "$WORK/set/tileset.json" "$WORK/bad/tileset.json"
sed -i 's/"top.pmtiles"/"..\/top.pmtiles"/' "$WORK/bad/tileset.json"
expect_error 5 "not a plain file name" "$VTS" verify "$WORK/bad"

note "vts serve: a folder of archives and sets; the set is one tileset, tile for tile"
mkdir -p "$WORK/srv"
cp -r "$WORK/set" "$WORK/srv/planet"
cp "$WORK/ref/t.pmtiles" "$WORK/srv/one.pmtiles"
echo '{"reload_interval_ms": 200}' >"$WORK/serve.json"
start_server "$WORK/srv" --config "$WORK/serve.json"
curl -sf "$BASE/" >"$WORK/index.json"
json_check "$WORK/index.json" "j.length === 2 && j.find(t => t.name === 'planet').archive === undefined && \
  j.find(t => t.name === 'one').archive !== undefined" "a set has no one archive to download"
expect_status 404 "$BASE/planet.pmtiles"
set_version=$(json_get "$WORK/set/tileset.json" "j.version")
curl -sf "$BASE/planet.json" >"$WORK/planet.json"
json_check "$WORK/planet.json" "j.version === '$set_version' && \
  j.tiles[0].includes('/planet@$set_version/')"
while read -r _ z x y _; do
  [[ $(curl -sf "$BASE/planet/$z/$x/$y" | sha256sum) == $(curl -sf "$BASE/one/$z/$x/$y" | sha256sum) ]] ||
    fail "tile $z/$x/$y of the set differs from the one-file archive's"
done <"$WORK/ref.tiles"
expect_status 404 "$BASE/planet/4/200/0"

note "a set replaced on disk (folder renamed into place) is reloaded whole"
SYN2=(--synthetic 3000x2000 --name t --codec bc1)
expect_ok "$VTS" plan "${SYN2[@]}" -o "$WORK/bc1.plan.json" --shards 4 --archive-level 2 -q
shards "$WORK/bc1.plan.json" "$WORK/bc1parts"
expect_ok "$VTS" merge --plan "$WORK/bc1.plan.json" "$WORK/bc1parts" -o "$WORK/srv/.planet.new/" -q
new_version=$(json_get "$WORK/srv/.planet.new/tileset.json" "j.version")
[[ $new_version != "$set_version" ]] || fail "two builds' sets share a version"
mv "$WORK/srv/planet" "$WORK/srv/.planet.old"
mv "$WORK/srv/.planet.new" "$WORK/srv/planet"
# The reference beside it, picked up by the same reload loop: the set's tiles must be its tiles.
expect_ok "$VTS" build "${SYN2[@]}" -o "$WORK/srv/bc1ref.pmtiles" -q
served_version() { curl -sf "$BASE/planet.json" >"$WORK/planet.json" && json_get "$WORK/planet.json" "j.version"; }
for ((i = 0; i < 100; i++)); do
  [[ $(served_version) == "$new_version" ]] && curl -sf -o /dev/null "$BASE/bc1ref.json" && break
  sleep 0.1
done
[[ $(served_version) == "$new_version" ]] || fail "the replaced set was not reloaded"
"$PMTILES_DUMP" tiles "$WORK/srv/bc1ref.pmtiles" >"$WORK/bc1.tiles"
while read -r _ z x y _; do
  [[ $(curl -sf "$BASE/planet/$z/$x/$y" | sha256sum) == $(curl -sf "$BASE/bc1ref/$z/$x/$y" | sha256sum) ]] ||
    fail "tile $z/$x/$y of the reloaded set differs from the bc1 build's"
done <"$WORK/bc1.tiles"
expect_ok "$VTS" merge --join "$WORK/srv/planet" -o "$WORK/joined_bc1.pmtiles" -q
[[ $(sha "$WORK/joined_bc1.pmtiles") == $(sha "$WORK/srv/bc1ref.pmtiles") ]] ||
  fail "the bc1 set does not join to vts build's archive"
stop_server

note "--max-archive-size picks the archive level from the plan's estimate"
expect_ok "$VTS" plan "${SYN[@]}" -o "$WORK/cap.plan.json" --shards 4 --max-archive-size 1MiB --json
json_check "$OUT" "j.archive_level >= 1 && j.estimated_bytes.archive_max <= 1048576"
expect_error 2 "no archive level" \
  "$VTS" plan "${SYN[@]}" -o "$WORK/cap2.plan.json" --shards 4 --max-archive-size 1KiB

note "a sparse 2^25-texel planet as a set: the archives with tiles, the one-file merge's tiles"
region="1048000,1048000,1049200,1048800"
PLANET=(--synthetic 33554432x33554432 --region "$region" --region-level 3 --codec bc1 --name planet)
expect_ok "$VTS" plan "${PLANET[@]}" -o "$WORK/planet.plan.json" --split-level 4 --archive-level 5 \
  --json
json_check "$OUT" "j.max_zoom === 17 && j.archives === 5" \
  "the region spans level-5 tiles (0..1, 0..1): four archives and the top"
expect_ok "$VTS" plan "${PLANET[@]}" -o "$WORK/planet1.plan.json" --split-level 4 -q
shards "$WORK/planet.plan.json" "$WORK/pparts"
expect_ok "$VTS" merge --plan "$WORK/planet.plan.json" "$WORK/pparts" -o "$WORK/pset/" --json \
  --no-space-check
json_check "$OUT" "j.written === 5"
expect_ok "$VTS" merge --plan "$WORK/planet1.plan.json" "$WORK/pparts" -o "$WORK/planet.pmtiles" -q \
  --no-space-check
expect_ok "$VTS" merge --join "$WORK/pset" -o "$WORK/pjoined.pmtiles" -q
[[ $(sha "$WORK/pjoined.pmtiles") == $(sha "$WORK/planet.pmtiles") ]] ||
  fail "the planet set does not join to the one-file merge"
echo "ok"
