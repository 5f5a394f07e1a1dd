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
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import puppeteer from 'puppeteer-core';

const [origin, source, z, x0, y0, shot] = process.argv.slice(2);
const here = path.dirname(fileURLToPath(import.meta.url));
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

const browser = await puppeteer.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  args: ['--no-sandbox', '--force-device-scale-factor=1', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader'],
});
const problems = [];
try {
  const page = await browser.newPage();
  await page.setViewport({ width: 512, height: 384, deviceScaleFactor: 1 });
  await page.setRequestInterception(true);
  page.on('request', (r) => {
    const u = new URL(r.url());
    if (u.origin === origin && u.pathname === '/__maplibre.html') {
      r.respond({ status: 200, contentType: 'text/html', body: html });
    } else if (u.origin === origin && files[u.pathname]) {
      const [type, file] = files[u.pathname];
      r.respond({ status: 200, contentType: type,
        body: fs.readFileSync(path.join(here, 'node_modules', file)) });
    } else {
      r.continue();
    }
  });
  page.on('console', (m) => {
    if (m.type() === 'error') problems.push('console: ' + m.text());
  });
  page.on('pageerror', (e) => problems.push('page error: ' + e.message));
  page.on('requestfailed', (r) => problems.push('request failed: ' + r.url()));
  page.on('response', (r) => { if (r.status() >= 400) problems.push(r.status() + ' ' + r.url()); });
  await page.goto(origin + '/__maplibre.html', { waitUntil: 'load', timeout: 30000 });
  await page.waitForFunction(() => window.idle === true, { timeout: 60000, polling: 50 });
  await page.screenshot({ path: shot, type: 'png' });
  const loaded = await page.evaluate(() => window.loaded);
  console.log(JSON.stringify({ loaded, problems }));
} finally {
  await browser.close();
}
