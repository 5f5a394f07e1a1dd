"""gis_owslib.py CAPABILITIES_URL TILE_OUT: OWSLib's WMTS client (the one QGIS's Python and many
scripts use) reads the capabilities of `vts serve`: layers earth and merc (and no other), their
tile matrix sets, formats, style and WGS84 bounds, and the sets' tile matrices; then GetTile
(KVP, from the capabilities' operation URL) of earth, WorldCRS84Quad 2/row 1/col 2 as PNG, written
to TILE_OUT. Exit 1 naming what is wrong."""
import sys

from owslib.wmts import WebMapTileService

wmts = WebMapTileService(sys.argv[1])
def check(cond, what):
    if not cond:
        sys.exit("OWSLib: " + what)

check(wmts.identification.type == "OGC WMTS", f"service type {wmts.identification.type}")
check(sorted(wmts.contents) == ["earth", "merc"], f"layers {sorted(wmts.contents)}")
earth, merc = wmts.contents["earth"], wmts.contents["merc"]
check(sorted(earth.tilematrixsetlinks) == ["WebMercatorQuad", "WorldCRS84Quad"],
      f"earth's sets {sorted(earth.tilematrixsetlinks)}")
check(sorted(merc.tilematrixsetlinks) == ["WebMercatorQuad"], f"merc's sets {sorted(merc.tilematrixsetlinks)}")
check(earth.formats == ["image/png", "image/webp", "image/jpeg"], f"formats {earth.formats}")
check(list(earth.styles) == ["default"], f"styles {list(earth.styles)}")
check(tuple(earth.boundingBoxWGS84) == (-180.0, -90.0, 180.0, 90.0), f"earth bounds {earth.boundingBoxWGS84}")
w, s, e, n = merc.boundingBoxWGS84
check(abs(w + 180) < 1e-9 and abs(e - 180) < 1e-9 and abs(n - 85.0511287798066) < 1e-9 and abs(s + n) < 1e-9,
      f"merc bounds {merc.boundingBoxWGS84}")
limits = earth.tilematrixsetlinks["WorldCRS84Quad"].tilematrixlimits
check(sorted(limits) == ["0", "1", "2"], f"earth's WorldCRS84Quad limits {sorted(limits)}")
check(limits["2"].maxtilecol == 7 and limits["2"].maxtilerow == 3, "earth's level 2 limits")
crs84 = wmts.tilematrixsets["WorldCRS84Quad"]
check(crs84.crs == "urn:ogc:def:crs:OGC:1.3:CRS84", f"crs {crs84.crs}")
m2 = crs84.tilematrix["2"]
check((m2.matrixwidth, m2.matrixheight, m2.tilewidth) == (8, 4, 256), "WorldCRS84Quad matrix 2")
check(tuple(m2.topleftcorner) == (-180.0, 90.0), f"top left {m2.topleftcorner}")
wmq = wmts.tilematrixsets["WebMercatorQuad"]
check(wmq.crs == "urn:ogc:def:crs:EPSG::3857", f"crs {wmq.crs}")
check(abs(wmq.tilematrix["0"].scaledenominator - 559082264.0287178) < 1e-3, "WebMercatorQuad scale 0")
tile = wmts.gettile(layer="earth", tilematrixset="WorldCRS84Quad", tilematrix="2", row=1, column=2,
                    format="image/png")
open(sys.argv[2], "wb").write(tile.read())
