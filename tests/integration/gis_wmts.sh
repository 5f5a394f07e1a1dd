#!/usr/bin/env bash
# WMTS 1.0.0 of `vts serve` (docs/PROTOCOL.md §15, docs/GIS.md) read by real clients: GDAL's WMTS
# driver lists a layer per tileset and tile matrix set, and gdal_translate of a region at a chosen
# tile matrix equals `vts extract`'s texels exactly (lossless archive, PNG) on WorldCRS84Quad and
# WebMercatorQuad; OWSLib reads layers, sets, formats, styles and bounds, and its KVP GetTile
# returns the RESTful tile's bytes; every tile is the web image route's bytes (no second encoder),
# the reprojected WebMercatorQuad tiles of a WorldCRS84Quad tileset too. The capabilities are
# well-formed XML in the WMTS and OWS namespaces, a protected tileset is neither listed nor served,
# and bad requests get OWS exception reports with the right code and status.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=gis_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/gis_lib.sh"
gis_setup
CAPS="$BASE/wmts/1.0.0/WMTSCapabilities.xml"

note "capabilities: RESTful and KVP alike, well-formed, namespaced, no protected layer"
curl -sf "$CAPS" -o "$WORK/caps.xml" || fail "GET $CAPS"
curl -sf "$BASE/wmts?SERVICE=WMTS&REQUEST=GetCapabilities" -o "$WORK/caps_kvp.xml" ||
  fail "KVP GetCapabilities"
cmp -s "$WORK/caps.xml" "$WORK/caps_kvp.xml" || fail "KVP and RESTful capabilities differ"
curl -sf "$BASE/wmts?service=WMTS&Request=GetCapabilities" | cmp -s - "$WORK/caps.xml" ||
  fail "KVP parameter names are not case-insensitive"
curl -sf "$BASE/wmts?service=wmts&request=GetCapabilities" -o /dev/null &&
  fail "SERVICE=wmts (not WMTS) accepted"
"$PY" - "$WORK/caps.xml" <<'PY' || fail "capabilities document"
import sys, xml.etree.ElementTree as ET
root = ET.parse(sys.argv[1]).getroot()
W, O = "{http://www.opengis.net/wmts/1.0}", "{http://www.opengis.net/ows/1.1}"
assert root.tag == W + "Capabilities" and root.get("version") == "1.0.0", root.tag
layers = [l.findtext(O + "Identifier") for l in root.iter(W + "Layer")]
assert layers == ["earth", "merc"], layers
sets = {s.findtext(O + "Identifier"): s for s in root.find(W + "Contents").findall(W + "TileMatrixSet")}
assert sorted(sets) == ["WebMercatorQuad", "WorldCRS84Quad"], sorted(sets)
assert sets["WebMercatorQuad"].findtext(W + "WellKnownScaleSet") == "urn:ogc:def:wkss:OGC:1.0:GoogleMapsCompatible"
assert [m.findtext(O + "Identifier") for m in sets["WorldCRS84Quad"].findall(W + "TileMatrix")] == ["0", "1", "2"]
assert len(sets["WebMercatorQuad"].findall(W + "TileMatrix")) == 4  # merc's levels 0..3
PY
grep -q secret "$WORK/caps.xml" && fail "the protected tileset is in the capabilities"
[[ $(curl -s -D - -o /dev/null "$CAPS" | tr -d '\r' | sed -nE 's/^Content-Type: (.*)/\1/Ip') == \
  application/xml ]] || fail "capabilities are not application/xml"
[[ $(curl -s -D - -o /dev/null "$CAPS" | tr -d '\r' |
  sed -nE 's/^Access-Control-Allow-Origin: (.*)/\1/Ip') == "*" ]] || fail "no CORS header"

note "GDAL's WMTS driver: one subdataset per layer and tile matrix set"
gdalinfo "WMTS:$CAPS" >"$WORK/info.txt" 2>&1 || fail "gdalinfo WMTS: $(cat "$WORK/info.txt")"
for sd in "layer=earth,tilematrixset=WorldCRS84Quad" "layer=earth,tilematrixset=WebMercatorQuad" \
  "layer=merc"; do
  grep -qF "$sd" "$WORK/info.txt" || fail "gdalinfo lists no $sd"
done
gdalinfo "WMTS:$CAPS,layer=earth,tilematrixset=WorldCRS84Quad" | grep -q "Size is 2048, 1024" ||
  fail "earth on WorldCRS84Quad is not 2048 x 1024 at its finest tile matrix"

note "gdal_translate of a region equals vts extract's texels"
gdal_translate -q -oo TILEMATRIX=2 -projwin -90 45 0 -45 \
  "WMTS:$CAPS,layer=earth,tilematrixset=WorldCRS84Quad" "$WORK/earth.tif" || fail "gdal_translate earth"
same_texels "$WORK/earth.tif" "$WORK/earth3.png" 512 256 --exact
H=$MERC_HALF
gdal_translate -q -oo TILEMATRIX=2 -projwin "-$H" "$H" "$H" "-$H" "WMTS:$CAPS,layer=merc" \
  "$WORK/merc.tif" || fail "gdal_translate merc"
same_texels "$WORK/merc.tif" "$WORK/merc2.png" 256 256 --exact

note "OWSLib reads the capabilities; its KVP GetTile is the RESTful tile"
"$PY" "$HERE/gis_owslib.py" "$CAPS" "$WORK/owslib.png" || fail "OWSLib"
curl -sf "$BASE/wmts/1.0.0/earth/default/WorldCRS84Quad/2/1/2.png" -o "$WORK/rest.png" || fail "REST tile"
cmp -s "$WORK/owslib.png" "$WORK/rest.png" || fail "OWSLib's GetTile differs from the RESTful tile"

note "every tile is the web image route's bytes: TMS level k is our level k+1 on WorldCRS84Quad"
for ext in png webp jpg; do
  curl -sf "$BASE/earth/3/2/1.$ext" -o "$WORK/web.$ext" || fail "web tile .$ext"
  curl -sf "$BASE/wmts/1.0.0/earth/default/WorldCRS84Quad/2/1/2.$ext" -o "$WORK/wmts.$ext" ||
    fail "WMTS .$ext"
  cmp -s "$WORK/web.$ext" "$WORK/wmts.$ext" || fail "WMTS .$ext is not the web tile"
done
curl -sf "$BASE/wmts?SERVICE=WMTS&REQUEST=GetTile&VERSION=1.0.0&LAYER=earth&STYLE=default&FORMAT=image%2Fjpeg&TILEMATRIXSET=WorldCRS84Quad&TILEMATRIX=2&TILEROW=1&TILECOL=2" \
  -o "$WORK/kvp.jpg" || fail "KVP GetTile"
cmp -s "$WORK/web.jpg" "$WORK/kvp.jpg" || fail "KVP JPEG is not the web tile"
curl -sf "$BASE/earth/WebMercatorQuad/2/1/1.png" -o "$WORK/wmq_web.png" || fail "reprojected web tile"
curl -sf "$BASE/wmts/1.0.0/earth/default/WebMercatorQuad/2/1/1.png" -o "$WORK/wmq.png" ||
  fail "WMTS WebMercatorQuad of earth"
cmp -s "$WORK/wmq_web.png" "$WORK/wmq.png" || fail "earth on WebMercatorQuad is not the reprojection"

note "protected tileset: not served, with or without its token"
expect_status 400 "$BASE/wmts/1.0.0/secret/default/WorldCRS84Quad/0/0/0.png"
expect_status 400 -H "Authorization: Bearer s3cret" \
  "$BASE/wmts/1.0.0/secret/default/WorldCRS84Quad/0/0/0.png"
expect_status 200 -H "Authorization: Bearer s3cret" "$BASE/secret/1/0/0.png" # its own route
body_has "$BASE/wmts/1.0.0/secret/default/WorldCRS84Quad/0/0/0.png" 'locator="LAYER"'

note "errors: OWS exception reports with their code and status"
K="$BASE/wmts?SERVICE=WMTS&REQUEST=GetTile&VERSION=1.0.0&LAYER=earth&STYLE=default&FORMAT=image/png"
expect_status 400 "$BASE/wmts?REQUEST=GetCapabilities"
body_has "$BASE/wmts?REQUEST=GetCapabilities" 'exceptionCode="MissingParameterValue" locator="SERVICE"'
body_has "$K&TILEMATRIXSET=WorldCRS84Quad&TILEMATRIX=2&TILEROW=1" 'locator="TILECOL"'
expect_status 400 "$K&TILEMATRIXSET=Nope&TILEMATRIX=2&TILEROW=1&TILECOL=1"
body_has "$K&TILEMATRIXSET=Nope&TILEMATRIX=2&TILEROW=1&TILECOL=1" \
  'exceptionCode="InvalidParameterValue" locator="TILEMATRIXSET"'
expect_status 404 "$K&TILEMATRIXSET=WorldCRS84Quad&TILEMATRIX=2&TILEROW=4&TILECOL=0"
body_has "$K&TILEMATRIXSET=WorldCRS84Quad&TILEMATRIX=2&TILEROW=4&TILECOL=0" \
  'exceptionCode="TileOutOfRange" locator="TILEROW"'
expect_status 404 "$BASE/wmts/1.0.0/earth/default/WorldCRS84Quad/3/0/0.png"
expect_status 400 "$BASE/wmts/1.0.0/earth/fancy/WorldCRS84Quad/2/0/0.png"
expect_status 400 "$BASE/wmts/1.0.0/earth/default/WorldCRS84Quad/2/0/0.gif"
expect_status 501 "$BASE/wmts?SERVICE=WMTS&REQUEST=GetFeatureInfo"
expect_status 400 "$BASE/wmts?SERVICE=WMTS&REQUEST=GetCapabilities&service=WMTS"

note "a tileset named wmts keeps its tile paths; the WMTS resources stay WMTS's"
[[ $(curl -s -o /dev/null -w '%{http_code} %{content_type}' "$BASE/wmts/1/1/0") == \
  "200 application/vnd.vtstream.tile" ]] || fail "/wmts/1/1/0 is not the wmts tileset's tile"
expect_status 200 "$BASE/wmts/1/1/0.png"
body_has "$CAPS" '<Capabilities'
body_has "$BASE/wmts?SERVICE=WMTS&REQUEST=GetCapabilities" '<Capabilities'
stop_server
