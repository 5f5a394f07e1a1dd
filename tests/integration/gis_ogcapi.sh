#!/usr/bin/env bash
# OGC API - Tiles of `vts serve` (docs/PROTOCOL.md §15, docs/GIS.md) read by GDAL's OGCAPI driver:
# from the landing page /ogcapi it lists a collection per tileset; gdal_translate of a region of
# a collection at a chosen tile matrix equals `vts extract`'s texels exactly as PNG on
# WorldCRS84Quad and WebMercatorQuad, and within JPEG's bound as JPEG. The landing page links
# conformance, data and tiling schemes; a tileset's metadata has tileMatrixSetLimits and templated
# tile links; tiles are the web image route's bytes; a protected tileset is neither listed nor
# served, and tiles outside a set's matrices are 404.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=gis_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/gis_lib.sh"
gis_setup
API="$BASE/ogcapi"

note "landing page, conformance, collections, tilesets, tile matrix sets"
for path in "" /conformance /collections /collections/earth /collections/earth/map/tiles \
  /collections/earth/map/tiles/WorldCRS84Quad /tileMatrixSets /tileMatrixSets/WebMercatorQuad; do
  curl -sf "$API$path" -o "$WORK/doc.json" || fail "GET $API$path"
  "$PY" -c 'import json, sys; json.load(open(sys.argv[1]))' "$WORK/doc.json" ||
    fail "$API$path is not JSON"
  cp "$WORK/doc.json" "$WORK/doc_${path//\//_}.json"
done
"$PY" - "$WORK" "$API" <<'PY' || fail "OGC API documents"
import json, sys
d, api = sys.argv[1], sys.argv[2]
doc = lambda p: json.load(open(f"{d}/doc_{p.replace('/', '_')}.json"))
rels = {l["rel"]: l["href"] for l in doc("")["links"]}
assert rels["data"] == api + "/collections", rels
assert rels["conformance"] == api + "/conformance"
assert rels["http://www.opengis.net/def/rel/ogc/1.0/tiling-schemes"] == api + "/tileMatrixSets"
assert "http://www.opengis.net/spec/ogcapi-tiles-1/1.0/conf/core" in doc("/conformance")["conformsTo"]
assert [c["id"] for c in doc("/collections")["collections"]] == ["earth", "merc"]
c = doc("/collections/earth")
assert c["extent"]["spatial"]["bbox"] == [[-180, -90, 180, 90]], c["extent"]
assert any(l["rel"] == "http://www.opengis.net/def/rel/ogc/1.0/tilesets-map" for l in c["links"])
sets = [t["tileMatrixSetURI"].rsplit("/", 1)[1] for t in doc("/collections/earth/map/tiles")["tilesets"]]
assert sets == ["WorldCRS84Quad", "WebMercatorQuad"], sets
ts = doc("/collections/earth/map/tiles/WorldCRS84Quad")
assert [l["tileMatrix"] for l in ts["tileMatrixSetLimits"]] == ["0", "1", "2"]
items = {l["type"]: l["href"] for l in ts["links"] if l["rel"] == "item"}
assert items["image/png"] == api + "/collections/earth/map/tiles/WorldCRS84Quad/{tileMatrix}/{tileRow}/{tileCol}.png", items
assert sorted(items) == ["image/jpeg", "image/png", "image/webp"]
assert [t["id"] for t in doc("/tileMatrixSets")["tileMatrixSets"]] == ["WebMercatorQuad", "WorldCRS84Quad"]
tms = doc("/tileMatrixSets/WebMercatorQuad")
assert tms["crs"] == "http://www.opengis.net/def/crs/EPSG/0/3857"
assert [m["id"] for m in tms["tileMatrices"]] == ["0", "1", "2", "3"]
assert abs(tms["tileMatrices"][0]["scaleDenominator"] - 559082264.0287178) < 1e-3
PY

note "GDAL's OGCAPI driver: a subdataset per collection, no protected one"
gdalinfo "OGCAPI:$API" >"$WORK/info.txt" 2>&1 || fail "gdalinfo OGCAPI: $(cat "$WORK/info.txt")"
grep -qF "OGCAPI:$API/collections/earth" "$WORK/info.txt" || fail "no earth subdataset"
grep -qF "OGCAPI:$API/collections/merc" "$WORK/info.txt" || fail "no merc subdataset"
grep -q secret "$WORK/info.txt" && fail "the protected tileset is listed"
gdalinfo -oo API=TILES "OGCAPI:$API/collections/earth" | grep -q "Size is 2048, 1024" ||
  fail "earth is not 2048 x 1024 at its finest tile matrix"

note "gdal_translate of a region equals vts extract's texels (PNG exact, JPEG within bound)"
gdal_translate -q -oo API=TILES -oo TILEMATRIX=2 -projwin -90 45 0 -45 \
  "OGCAPI:$API/collections/earth" "$WORK/earth.tif" || fail "gdal_translate earth"
same_texels "$WORK/earth.tif" "$WORK/earth3.png" 512 256 --exact
gdal_translate -q -oo API=TILES -oo IMAGE_FORMAT=JPEG -oo TILEMATRIX=2 -projwin -90 45 0 -45 \
  "OGCAPI:$API/collections/earth" "$WORK/earth_jpg.tif" || fail "gdal_translate earth JPEG"
same_texels "$WORK/earth_jpg.tif" "$WORK/earth3.png" 512 256 --min-psnr 30
# GDAL 3.6 takes a collection's bbox as coordinates of the tile matrix set's CRS: for
# WebMercatorQuad the bounds are given in metres (docs/GIS.md).
H=$MERC_HALF F=20037508.342789244
gdal_translate -q -oo API=TILES -oo TILEMATRIXSET=WebMercatorQuad -oo TILEMATRIX=2 \
  -oo "MINX=-$F" -oo "MINY=-$F" -oo "MAXX=$F" -oo "MAXY=$F" -projwin "-$H" "$H" "$H" "-$H" \
  "OGCAPI:$API/collections/merc" "$WORK/merc.tif" || fail "gdal_translate merc"
same_texels "$WORK/merc.tif" "$WORK/merc2.png" 256 256 --exact

note "tiles are the web image route's bytes"
curl -sf "$BASE/earth/3/2/1.webp" -o "$WORK/web.webp" || fail "web tile"
curl -sf "$API/collections/earth/map/tiles/WorldCRS84Quad/2/1/2.webp" -o "$WORK/ogc.webp" ||
  fail "OGC API tile"
cmp -s "$WORK/web.webp" "$WORK/ogc.webp" || fail "the OGC API tile is not the web tile"
curl -sf "$BASE/earth/WebMercatorQuad/1/1/0.png" -o "$WORK/wmq_web.png" || fail "reprojected"
curl -sf "$API/collections/earth/map/tiles/WebMercatorQuad/1/0/1.png" -o "$WORK/wmq.png" ||
  fail "OGC API WebMercatorQuad tile of earth"
cmp -s "$WORK/wmq_web.png" "$WORK/wmq.png" || fail "earth on WebMercatorQuad is not the reprojection"

note "protected tileset and out-of-range tiles"
expect_status 404 "$API/collections/secret"
expect_status 404 -H "Authorization: Bearer s3cret" \
  "$API/collections/secret/map/tiles/WorldCRS84Quad/0/0/0.png"
expect_status 404 "$API/collections/earth/map/tiles/WorldCRS84Quad/3/0/0.png"
expect_status 404 "$API/collections/earth/map/tiles/WorldCRS84Quad/2/4/0.png"
expect_status 400 "$API/collections/earth/map/tiles/WorldCRS84Quad/2/01/0.png"
expect_status 404 "$API/collections/earth/map/tiles/Nope"
expect_status 404 "$API/tileMatrixSets/WorldCRS84Quad-100"
note "a tileset named ogcapi keeps its tile paths; the OGC API resources stay OGC API's"
[[ $(curl -s -o /dev/null -w '%{http_code} %{content_type}' "$BASE/ogcapi/1/1/0") == \
  "200 application/vnd.vtstream.tile" ]] || fail "/ogcapi/1/1/0 is not the ogcapi tileset's tile"
body_has "$BASE/ogcapi/collections" '"collections"'
stop_server
