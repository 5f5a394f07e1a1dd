#!/usr/bin/env bash
# Sharded builds of georeferenced inputs (docs/PLANET.md, "Plans, shards and parts"): four small
# overlapping GeoTIFFs (three in EPSG:4326, one in UTM 33N, warped) planned with `vts plan`, every
# shard, the apex and `vts merge` write the very archive `vts build` writes (sha256): WorldCRS84Quad
# with 4 and 16 shards, lossless and bc1, WebMercatorQuad, --range auto (its percentiles pinned in
# the plan). A shard reports the inputs it opened ("inputs_opened"): one far from an input does not
# open it (it builds with that input moved away; one near it fails naming it). Synthetic
# --tiling/--bbox plans, and a sparse planet 2^25 texels wide, merge to their builds' bytes too.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool gdal_translate
require_tool gdalwarp

cd "$WORK"
T() { gdal_translate -q "$@" || fail "gdal_translate $*"; }
T -a_srs EPSG:4326 -a_ullr -180 90 180 -90 -outsize 256 128 "$EARTH" world.tif
T -a_srs EPSG:4326 -a_ullr 0 40 40 10 -srcwin 1000 300 400 300 -outsize 200 150 "$EARTH" a.tif
T -a_srs EPSG:4326 -a_ullr 20 50 60 20 -srcwin 1200 200 400 300 -outsize 200 150 "$EARTH" b.tif
gdalwarp -q -t_srs EPSG:32633 -te_srs EPSG:4326 -te 10 40 20 50 -ts 100 120 world.tif utm.tif ||
  fail "gdalwarp utm"

# sharded NAME SHARDS BUILD-ARGS...: plan, every shard (their --json reports in NAME.shards.json,
# one per line), the apex, the merge into merged/NAME.pmtiles.
sharded() {
  local name=$1 shards=$2
  shift 2
  local plan="$WORK/$name.plan.json" parts="$WORK/$name.parts"
  expect_ok "$VTS" plan "$@" -o "$plan" --shards "$shards" --json
  local n i
  n=$(json_get "$OUT" "j.shards")
  ((n >= shards)) || fail "$name: asked for $shards shards, the plan has $n"
  : >"$WORK/$name.shards.json"
  for ((i = 0; i < n; i++)); do
    expect_ok "$VTS" build --plan "$plan" --shard "$i" --out-dir "$parts" --threads 2 --json
    tr -d '\n' <"$OUT" >>"$WORK/$name.shards.json"
    echo >>"$WORK/$name.shards.json"
  done
  if [[ $(json_get "$WORK/$name.plan.json" "j.split_level") != 0 ]]; then
    expect_ok "$VTS" build --plan "$plan" --apex --out-dir "$parts" -q
  fi
  mkdir -p "$WORK/merged"
  expect_ok "$VTS" merge --plan "$plan" "$parts" -o "$WORK/merged/$name.pmtiles" -q
}

# same_as_build NAME SHARDS BUILD-ARGS...: the merged archive equals `vts build`'s, byte for byte.
same_as_build() {
  local name=$1 shards=$2
  shift 2
  local ref="$WORK/$name.pmtiles"
  expect_ok "$VTS" build "$@" -o "$ref" -q
  sharded "$name" "$shards" "$@"
  [[ $(sha "$WORK/merged/$name.pmtiles") == $(sha "$ref") ]] ||
    fail "$name with $shards shards: merged archive differs from vts build's"
}

INPUTS=(world.tif a.tif b.tif utm.tif)
note "georeferenced inputs, WorldCRS84Quad: 4 and 16 shards, lossless and bc1"
for codec in lossless bc1; do
  for n in 4 16; do
    same_as_build "geo_${codec}_$n" "$n" "${INPUTS[@]}" --codec "$codec"
  done
done
note "WebMercatorQuad, and --range auto (the plan pins the percentiles)"
same_as_build geo_web 4 "${INPUTS[@]}" --tiling WebMercatorQuad
same_as_build geo_auto 4 a.tif utm.tif b.tif --range auto --codec bc1
json_check "$WORK/geo_auto.plan.json" "j.georeference.value_ranges.length === 3 &&
  j.georeference.value_ranges.every(r => r[0] < r[1]) &&
  j.georeference.value_ranges.some(r => r[0] > 0 || r[1] < 255)" \
  "the plan records the percentiles --range auto chose"

note "a shard opens only the inputs meeting its window"
same_as_build geo_sparse 4 a.tif b.tif utm.tif
S="$WORK/geo_sparse.shards.json"
python3 - "$S" <<'PY' || fail "inputs_opened: $(cat "$S")"
import json, sys
opened = [json.loads(l)["inputs_opened"] for l in open(sys.argv[1]) if l.strip()]
assert min(opened) == 1 and max(opened) == 3 and sum(opened) < 3 * len(opened), opened
PY
# The shards that open one input only (its window meets neither of the others): with utm.tif moved
# away, one of them far from it still builds the same part; one that opens all three fails naming it.
far=$(python3 -c "
import json,sys
for i,l in enumerate(open('$S')):
  j=json.loads(l)
  if j['inputs_opened']==1 and j['root'].split('/')[2]=='1' and int(j['root'].split('/')[1])>=5: print(i); break")
near=$(python3 -c "
import json
for i,l in enumerate(open('$S')):
  if json.loads(l)['inputs_opened']==3: print(i); break")
[[ -n $far && -n $near ]] || fail "no shard far from utm.tif, or none opening all: $(cat "$S")"
mv utm.tif utm.moved
expect_ok "$VTS" build --plan "$WORK/geo_sparse.plan.json" --shard "$far" --out-dir again -q
part=$(printf 'shard-%06d.part' "$far")
cmp "again/$part" "$WORK/geo_sparse.parts/$part" || fail "shard $far: another part without utm.tif"
expect_clean_failure "$VTS" build --plan "$WORK/geo_sparse.plan.json" --shard "$near" \
  --out-dir again -q
grep -q "utm.tif" "$ERR" || fail "shard $near without utm.tif: the error does not name it: $(cat "$ERR")"
mv utm.moved utm.tif

note "synthetic --tiling --bbox plans; a sparse planet 2^25 texels wide"
same_as_build syn_geo 4 --synthetic 16384x8192 --tiling WorldCRS84Quad --bbox=-10.5,35.25,30.125,60.1
same_as_build syn_web 2 --synthetic 16384x16384 --tiling WebMercatorQuad --bbox=2.2,48.8,2.5,48.95
same_as_build syn_planet 4 --synthetic 33554432x16777216 --tiling WorldCRS84Quad \
  --bbox=2.30,48.84,2.36,48.88 --codec bc1
json_check "$WORK/syn_planet.plan.json" "j.geometry.width === 33554432" "a 2^25-wide plan"
