// Three stock web maps, each given only a TileJSON URL the way their own docs show, in Debian's
// chromium driven by puppeteer-core:
//   node webmaps.mjs LIB ORIGIN TILEJSON SHOT.png
// LIB is maplibre (a raster source with `url`), leaflet (the TileJSON fetched, its first `tiles`
// template given to L.tileLayer, as Leaflet has no TileJSON reader) or openlayers
// (ol/source/TileJSON). Each map is 512 x 512 CSS pixels showing the whole Web Mercator square at
// web zoom 1 (512 pixels: MapLibre's zoom 0), from tiles of 256 pixels drawn one to one. The page
// is served at ORIGIN/__webmap.html by request interception (same origin as the tiles). Once the
// map has drawn every tile, a screenshot is written and one JSON line printed: the tiles loaded and
// every console error, page error, failed request and HTTP error met.
import { shootStockMap } from './stock_map_page.mjs';

const [lib, origin, tilejson, shot] = process.argv.slice(2);
const assets = {
  maplibre: { js: 'maplibre-gl/dist/maplibre-gl.js', css: 'maplibre-gl/dist/maplibre-gl.css' },
  leaflet: { js: 'leaflet/dist/leaflet.js', css: 'leaflet/dist/leaflet.css' },
  openlayers: { js: 'ol/dist/ol.js', css: 'ol/ol.css' },
}[lib];
if (!assets) throw new Error(`unknown map library "${lib}": maplibre, leaflet or openlayers`);

// Each script sets window.loaded (tiles drawn) and window.idle once every visible tile is drawn.
const scripts = {
  maplibre: `
const map = new maplibregl.Map({
  container: 'map', center: [0, 0], zoom: 0, pixelRatio: 1, fadeDuration: 0,
  interactive: false, attributionControl: false, renderWorldCopies: false,
  style: { version: 8, sources: { w: { type: 'raster', url: TILEJSON, tileSize: 256 } },
    layers: [{ id: 'w', type: 'raster', source: 'w',
      paint: { 'raster-resampling': 'nearest', 'raster-fade-duration': 0 } }] },
});
map.on('data', (e) => { if (e.dataType === 'source' && e.tile) window.loaded++; });
map.on('error', (e) => console.error('maplibre: ' + (e.error ? e.error.message : e)));
map.once('idle', () => { window.idle = true; });`,
  leaflet: `
fetch(TILEJSON).then((r) => r.json()).then((tj) => {
  const map = L.map('map', { center: [0, 0], zoom: 1, zoomControl: false,
    attributionControl: false, fadeAnimation: false, zoomAnimation: false });
  const layer = L.tileLayer(tj.tiles[0], { tileSize: tj.tileSize || 256, minZoom: tj.minzoom,
    maxZoom: tj.maxzoom, noWrap: true });
  layer.on('tileload', () => window.loaded++);
  layer.on('tileerror', (e) => console.error('leaflet: tile error ' + e.tile.src));
  layer.on('load', () => { window.idle = true; });
  layer.addTo(map);
}).catch((e) => console.error('leaflet: ' + e));`,
  openlayers: `
const source = new ol.source.TileJSON({ url: TILEJSON, crossOrigin: 'anonymous' });
source.on('tileloadend', () => window.loaded++);
source.on('tileloaderror', () => console.error('openlayers: tile error'));
const map = new ol.Map({ target: 'map', controls: [], interactions: [],
  layers: [new ol.layer.Tile({ source })],
  view: new ol.View({ center: [0, 0], resolution: 2 * 20037508.342789244 / 512 }) });
map.on('rendercomplete', () => { if (window.loaded > 0) window.idle = true; });`,
};

const html = `<!doctype html><html><head><meta charset="utf-8"><link rel="icon" href="data:,">
<link rel="stylesheet" href="/__webmap/lib.css">
<style>html,body{margin:0;background:#fff}#map{width:512px;height:512px}</style></head>
<body><div id="map"></div><script src="/__webmap/lib.js"></script>
<script>
window.loaded = 0;
const TILEJSON = ${JSON.stringify(tilejson)};
${scripts[lib]}
</script></body></html>`;

await shootStockMap({ origin, page: '/__webmap.html', html, width: 512, height: 512, shot,
  files: { '/__webmap/lib.js': ['text/javascript', assets.js],
    '/__webmap/lib.css': ['text/css', assets.css] } });
