// Stock MapLibre GL JS (the pinned npm maplibre-gl) in Debian's chromium, driven by
// puppeteer-core, on a raster TileJSON or a PMTiles archive read with the stock npm pmtiles
// protocol:
//   node maplibre.mjs ORIGIN SOURCE Z X0 Y0 SHOT.png
// SOURCE is a TileJSON URL, or pmtiles://URL. The page is served at ORIGIN/__maplibre.html by
// request interception (same origin as the tiles). The map is 512 x 384 CSS pixels showing tile
// level Z one to one (MapLibre's zoom Z - 1) with world pixel (X0, Y0) of that zoom at its top-left corner (tiles of 256 pixels, nearest
// resampling, no fade); once MapLibre is idle with every tile loaded, a screenshot is written and
// one JSON line printed: the tiles MapLibre loaded and every console error, page error, failed
// request and HTTP error met.
import { shootStockMap } from './stock_map_page.mjs';

const [origin, source, z, x0, y0, shot] = process.argv.slice(2);
const files = {
  '/__maplibre/maplibre-gl.js': ['text/javascript', 'maplibre-gl/dist/maplibre-gl.js'],
  '/__maplibre/maplibre-gl.css': ['text/css', 'maplibre-gl/dist/maplibre-gl.css'],
  '/__maplibre/pmtiles.js': ['text/javascript', 'pmtiles/dist/pmtiles.js'],
};
const html = `<!doctype html><html><head><meta charset="utf-8"><link rel="icon" href="data:,">
<link rel="stylesheet" href="/__maplibre/maplibre-gl.css">
<style>html,body{margin:0}#map{width:512px;height:384px}</style></head><body><div id="map"></div>
<script src="/__maplibre/maplibre-gl.js"></script><script src="/__maplibre/pmtiles.js"></script>
<script>
window.loaded = 0;
const source = ${JSON.stringify(source)};
if (source.startsWith('pmtiles://')) {
  const protocol = new pmtiles.Protocol();
  maplibregl.addProtocol('pmtiles', protocol.tile);
}
const z = ${Number(z)}, world = 256 * Math.pow(2, z);
const cx = (${Number(x0)} + 256) / world, cy = (${Number(y0)} + 192) / world;
const center = [cx * 360 - 180, Math.atan(Math.sinh(Math.PI * (1 - 2 * cy))) * 180 / Math.PI];
const map = new maplibregl.Map({
  container: 'map', center, zoom: z - 1, // MapLibre's zoom 0 is a world of 512 pixels pixelRatio: 1, fadeDuration: 0, interactive: false,
  attributionControl: false, renderWorldCopies: false,
  style: { version: 8, sources: { w: { type: 'raster', url: source, tileSize: 256 } },
    layers: [{ id: 'w', type: 'raster', source: 'w',
      paint: { 'raster-resampling': 'nearest', 'raster-fade-duration': 0 } }] },
});
map.on('data', (e) => { if (e.dataType === 'source' && e.tile) window.loaded++; });
map.on('error', (e) => console.error('maplibre: ' + (e.error ? e.error.message : e)));
map.once('idle', () => { window.idle = true; });
</script></body></html>`;

await shootStockMap({ origin, page: '/__maplibre.html', html, files, width: 512, height: 384,
  shot });
