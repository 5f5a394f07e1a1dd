// What maplibre.mjs and webmaps.mjs share: Debian's chromium driven by puppeteer-core, a page of
// a stock web map served at ORIGIN/PAGE by request interception (same origin as the tiles, so no
// CORS setup) with the library's files from node_modules, every problem the page meets collected,
// and, once the page sets window.idle, a screenshot and one JSON line: {loaded, problems}, where
// loaded is the page's window.loaded (tiles drawn).
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import puppeteer from 'puppeteer-core';

const here = path.dirname(fileURLToPath(import.meta.url));

// shootStockMap({origin, page, html, files, width, height, shot}): files maps a URL path to
// [content type, file under node_modules].
export async function shootStockMap({ origin, page: pagePath, html, files, width, height, shot }) {
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: ['--no-sandbox', '--force-device-scale-factor=1', '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader'],
  });
  const problems = [];
  try {
    const page = await browser.newPage();
    await page.setViewport({ width, height, deviceScaleFactor: 1 });
    await page.setRequestInterception(true);
    page.on('request', (r) => {
      const u = new URL(r.url());
      if (u.origin === origin && u.pathname === pagePath) {
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
    page.on('response', (r) => {
      if (r.status() >= 400) problems.push(r.status() + ' ' + r.url());
    });
    await page.goto(origin + pagePath, { waitUntil: 'load', timeout: 30000 });
    await page.waitForFunction(() => window.idle === true, { timeout: 60000, polling: 50 });
    await page.screenshot({ path: shot, type: 'png' });
    const loaded = await page.evaluate(() => window.loaded);
    console.log(JSON.stringify({ loaded, problems }));
  } finally {
    await browser.close();
  }
}
