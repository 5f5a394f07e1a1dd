// Opens the viewer page of vts serve (GET /{tileset}/) in Debian's chromium, driven by
// puppeteer-core, and reports what a person would see:
//   node view.mjs URL Z PX PY SHOT.png MX MY
// waits for the viewer to read the TileJSON, shows image pixel (PX, PY) of level Z at the top-left
// corner of a 512 x 384 viewport (one image pixel per screen pixel), waits until every tile of
// that view is loaded and drawn (the page's window.vtsViewer state: no fixed sleep), writes a
// screenshot, moves the mouse to (MX, MY) and prints one JSON line: the cursor readout, the tile
// counts, and every console error, page error, failed request and HTTP error the page met.
import puppeteer from 'puppeteer-core';

const [url, z, px, py, shot, mx, my] = process.argv.slice(2);
const browser = await puppeteer.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  args: ['--no-sandbox', '--disable-gpu', '--force-device-scale-factor=1',
    '--font-render-hinting=none'],
});
const problems = [];
try {
  const page = await browser.newPage();
  await page.setViewport({ width: 512, height: 384, deviceScaleFactor: 1 });
  page.on('console', (m) => { if (m.type() === 'error') problems.push('console: ' + m.text()); });
  page.on('pageerror', (e) => problems.push('page error: ' + e.message));
  page.on('requestfailed', (r) => problems.push('request failed: ' + r.url() + ' ' +
    (r.failure() ? r.failure().errorText : '')));
  page.on('response', (r) => { if (r.status() >= 400) problems.push(r.status() + ' ' + r.url()); });
  const response = await page.goto(url, { waitUntil: 'load', timeout: 30000 });
  if (!response.ok()) throw new Error(url + ' answered ' + response.status());
  await page.waitForFunction(() => window.vtsViewer && window.vtsViewer.status !== 'loading',
    { timeout: 30000 });
  const status = await page.evaluate(() => [window.vtsViewer.status, window.vtsViewer.error]);
  if (status[0] !== 'ready') throw new Error('viewer: ' + status[1]);
  const before = await page.evaluate((a, b, c) => window.vtsViewer.setPixelView(a, b, c),
    Number(z), Number(px), Number(py));
  await page.waitForFunction((n) => window.vtsViewer.renders > n &&
    window.vtsViewer.tiles.loading === 0, { timeout: 30000, polling: 50 }, before);
  await page.screenshot({ path: shot, type: 'png' });
  await page.mouse.move(Number(mx), Number(my));
  await page.waitForFunction(() => window.vtsViewer.readout !== '', { timeout: 10000 });
  const state = await page.evaluate(() => ({
    kind: window.vtsViewer.kind,
    readout: document.getElementById('vts-readout').textContent,
    tiles: window.vtsViewer.tiles,
  }));
  console.log(JSON.stringify({ ...state, problems }));
} finally {
  await browser.close();
}
