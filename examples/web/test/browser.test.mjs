// The browser demo in a real browser: Debian's Chromium, headless, driven
// by playwright-core, with WebGPU from its software adapter (SwiftShader) on
// a machine with no GPU. Serves the built folder (examples/web/dist, made by
// build.sh) on localhost. Saves the canvas as target/web-demo.png.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import { readFile, mkdir, writeFile } from 'node:fs/promises';
import { extname, join, dirname, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = dirname(fileURLToPath(import.meta.url));
const dist = resolve(process.env.YARNIFY_WEB_DIST ?? join(here, '..', 'dist'));
const artifact = resolve(here, '..', '..', '..', 'target', 'web-demo.png');
const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm', '.css': 'text/css' };

let server;
let browser;
let page;
const consoleErrors = [];

before(async () => {
  server = createServer(async (request, response) => {
    const path = new URL(request.url, 'http://localhost').pathname;
    const file = join(dist, path === '/' ? 'index.html' : path);
    try {
      const body = await readFile(file);
      response.writeHead(200, { 'content-type': TYPES[extname(file)] ?? 'application/octet-stream' });
      response.end(body);
    } catch {
      response.writeHead(404).end();
    }
  });
  await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
  browser = await chromium.launch({
    executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium',
    // WebGPU on SwiftShader's Vulkan, and a compositor on SwiftShader too, so
    // the canvas's swap chain can be shared with it (without the last four,
    // presenting the first frame loses the device).
    args: [
      '--no-sandbox', '--enable-unsafe-webgpu', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
      '--enable-gpu', '--use-angle=swiftshader', '--enable-features=Vulkan', '--use-vulkan=swiftshader',
      '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync',
    ],
  });
  page = await browser.newPage({ viewport: { width: 1000, height: 700 } });
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  await page.goto(`http://127.0.0.1:${server.address().port}/`);
  await page.waitForFunction(() => window.yarnify && (window.yarnify.ready || window.yarnify.error), null, { timeout: 120_000 });
});

after(async () => {
  await browser?.close();
  server?.close();
});

const status = () => page.evaluate(() => window.yarnify.status());
const waitFrames = async (frames) => {
  const start = (await status()).frames;
  await page.waitForFunction((n) => window.yarnify.status().frames >= n, start + frames, { timeout: 120_000 });
};

test('an adapter is found and frames advance', async () => {
  const error = await page.evaluate(() => window.yarnify.error);
  assert.equal(error, null, `the page found no WebGPU: ${error}`);
  const first = await status();
  assert.ok(first.adapter.length > 0);
  assert.equal(first.nodes, 16 * 16 * 8);
  await waitFrames(5);
  const later = await status();
  assert.ok(later.substeps >= first.substeps + 5 * 22, `substeps ${first.substeps} -> ${later.substeps}`);
  console.log(`adapter: ${later.adapterName || later.adapter}; ${later.nodes} nodes, ${later.contacts} contacts`);
});

test('the canvas is mostly yarn, not blank', async () => {
  await waitFrames(20);
  const png = await page.locator('#fabric').screenshot();
  await mkdir(dirname(artifact), { recursive: true });
  await writeFile(artifact, png);
  // Count yarn-coloured pixels (the tubes are shaded in warm reds and
  // oranges; the background is a cool grey), decoding the PNG in the page.
  const coverage = await page.evaluate(async (b64) => {
    const image = new Image();
    image.src = `data:image/png;base64,${b64}`;
    await image.decode();
    const canvas = new OffscreenCanvas(image.width, image.height);
    const context = canvas.getContext('2d');
    context.drawImage(image, 0, 0);
    const { data } = context.getImageData(0, 0, image.width, image.height);
    let yarn = 0;
    for (let i = 0; i < data.length; i += 4) {
      if (data[i] > data[i + 1] + 30 && data[i] > data[i + 2] + 30) yarn += 1;
    }
    return yarn / (data.length / 4);
  }, png.toString('base64'));
  console.log(`yarn covers ${(100 * coverage).toFixed(1)} % of the canvas; screenshot: ${artifact}`);
  assert.ok(coverage > 0.15 && coverage < 0.9, `yarn-coloured fraction ${coverage}`);
  // The rate over a few seconds of nothing else happening, and what the
  // status line says.
  const start = [await status(), Date.now()];
  await page.waitForTimeout(4000);
  const end = [await status(), Date.now()];
  const measured = (end[0].substeps - start[0].substeps) / ((end[1] - start[1]) / 1000);
  const shown = await page.evaluate(() => [window.yarnify.substepsPerSecond, window.yarnify.frameMs]);
  console.log(`over 4 s: ${Math.round(measured)} substeps/s; the status line: ${Math.round(shown[0])} substeps/s, ` +
    `frame ${shown[1].toFixed(1)} ms`);
  assert.ok(measured > 0 && shown[0] > 0);
});

test('a mouse drag on a loop moves the fabric', async () => {
  const before = await page.evaluate(() => window.yarnify.positions());
  // A node near the middle of the patch, projected to the screen by the demo.
  const box = await page.locator('#fabric').boundingBox();
  const [x, y] = [box.x + box.width / 2, box.y + box.height / 2];
  await page.mouse.move(x, y);
  await page.mouse.down();
  await page.waitForFunction(() => window.yarnify.status().grabbed !== null, null, { timeout: 30_000 });
  for (let k = 1; k <= 10; k++) {
    await page.mouse.move(x, y - 12 * k);
  }
  await waitFrames(10);
  await page.mouse.up();
  const after = await page.evaluate(() => window.yarnify.positions());
  assert.equal(after.length, before.length);
  let moved = 0;
  for (let i = 0; i < before.length; i += 3) {
    const d = Math.hypot(after[i] - before[i], after[i + 1] - before[i + 1], after[i + 2] - before[i + 2]);
    if (d > 0.5) moved += 1;
  }
  console.log(`the drag moved ${moved} of ${before.length / 3} nodes by more than 0.5`);
  assert.ok(moved > 10, `only ${moved} nodes moved`);
  assert.equal((await status()).grabbed, null);
});

test('unravel releases contacts', async () => {
  const before = await status();
  await page.click('#unravel');
  await waitFrames(12);
  const after = await status();
  assert.ok(after.unravelling);
  assert.ok(after.alive <= before.alive - 5, `alive ${before.alive} -> ${after.alive}`);
  await page.click('#unravel');
});

test('a refused setting is reported, not thrown', async () => {
  const errors = await page.evaluate(() => {
    window.yarnify.app.set('substeps', 30);
    try { window.yarnify.app.set('stretch', -1); } catch (e) { return String(e.message); }
    return 'no error';
  });
  assert.match(errors, /stretch|stiff|k_s/i);
});

test('the console shows no errors', () => {
  assert.deepEqual(consoleErrors, []);
});
