// Drives the viewer in headless Chromium (Debian's /usr/bin/chromium through playwright-core)
// and prints one JSON object: load, pixel change, predictions (browser and server path),
// inference timing, frame rate, console errors. tests/test_viewer.py runs it and judges it.
//
// usage: node viewer_check.mjs URL OUT_DIR ALPHAS_JSON [SECONDS]
import { createRequire } from 'node:module';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const require = createRequire(new URL('../../persival/deploy/web/package.json', import.meta.url));
const { chromium } = require('playwright-core');

const [url, outDir, alphasJson, secondsArg] = process.argv.slice(2);
const alphas = JSON.parse(alphasJson);
const seconds = Number(secondsArg || 3);
const profile = mkdtempSync(join(tmpdir(), 'persival-chromium-'));
const result = { consoleErrors: [], pageErrors: [] };

// A fresh profile per run (playwright passes it as --user-data-dir).
const browser = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  viewport: { width: 1280, height: 720 },
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
    '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    // rAF is not tied to a 60 Hz display here, so the measured rate is what the page sustains.
    '--disable-gpu-vsync', '--disable-frame-rate-limit'],
});

// A 1/4-scale grey copy of the canvas, to count the pixels a change of state altered. The page's
// drawing buffer is not preserved after it is shown, so draw and copy in the same task.
async function pixels(page) {
  return page.evaluate(async () => {
    const c = document.getElementById('view');
    window.persival.viewer.scene.render();
    const t = document.createElement('canvas');
    t.width = c.width >> 2; t.height = c.height >> 2;
    const ctx = t.getContext('2d');
    ctx.drawImage(c, 0, 0, t.width, t.height);
    const d = ctx.getImageData(0, 0, t.width, t.height).data;
    const g = new Array(d.length / 4);
    for (let i = 0; i < g.length; i++) g[i] = (d[4 * i] + d[4 * i + 1] + d[4 * i + 2]) / 3;
    return g;
  });
}
const changed = (a, b) => a.reduce((n, v, i) => n + (Math.abs(v - b[i]) > 8 ? 1 : 0), 0);

try {
  const page = await browser.newPage();
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.pageErrors.push(String(e)));
  const t0 = Date.now();
  await page.goto(url, { waitUntil: 'load' });
  await page.evaluate(() => window.persival.ready);
  result.loadMs = Date.now() - t0;
  result.auto = await page.evaluate(() => ({ stats: window.persival.stats(), measured: window.persival.viewer.measured,
    decision: document.getElementById('decision').textContent, ar: !document.getElementById('ar').hidden }));

  await page.evaluate(() => window.persival.setBackend('wasm', 'float32'));
  await page.evaluate(() => window.persival.setActivations([0, 0, 0, 0, 0]));
  const rest = await pixels(page);
  await page.screenshot({ path: join(outDir, 'rest.png') });
  await page.evaluate(() => window.persival.setActivations([1, 0.9, 0.8, 0, 0]));
  const flexed = await pixels(page);
  result.changedPixels = changed(rest, flexed);
  result.totalPixels = rest.length;
  result.flexedStats = await page.evaluate(() => window.persival.stats());
  await page.screenshot({ path: join(outDir, 'flexed.png') });

  result.browser = await page.evaluate(async (as) => {
    const out = [];
    for (const a of as) out.push(Array.from(await window.persival.predict(a)));
    return out;
  }, alphas);
  result.server = await page.evaluate(async (as) => {
    const out = [];
    for (const a of as) out.push(Array.from(await window.persival.predictServer(a)));
    return out;
  }, alphas);
  await page.evaluate(() => window.persival.setBackend('server', 'float32'));
  await page.evaluate(() => window.persival.setAngle(60));
  result.serverStats = await page.evaluate(() => window.persival.stats());

  // Inference per state in WASM: the float32 deformation model, batch 1, one after another.
  await page.evaluate(() => window.persival.setBackend('wasm', 'float32'));
  result.wasm = await page.evaluate(async () => {
    const v = window.persival.viewer, a = new Float32Array(5), t = [];
    for (let i = 0; i < 300; i++) {
      a.fill((i % 100) / 100);
      const t0 = performance.now();
      await v.local.deform(a, 'float32');
      t.push(performance.now() - t0);
    }
    t.sort((x, y) => x - y);
    return { meanMs: t.reduce((s, x) => s + x, 0) / t.length, medianMs: t[150], p99Ms: t[296] };
  });

  // Frame rate while playing: every frame computes a new state of all five muscles in WASM.
  await page.evaluate(() => window.persival.play(true));
  await page.waitForTimeout(1000);
  const s0 = await page.evaluate(() => ({ ...window.persival.stats(), t: performance.now() }));
  await page.waitForTimeout(seconds * 1000);
  const s1 = await page.evaluate(() => ({ ...window.persival.stats(), t: performance.now() }));
  await page.screenshot({ path: join(outDir, 'playing.png') });
  await page.evaluate(() => window.persival.play(false));
  result.play = { fps: s1.fps, inferenceMs: s1.inferenceMs, backend: s1.backend, renderScale: s1.renderScale,
    statesPerS: ((s1.states - s0.states) * 1000) / (s1.t - s0.t) };
  result.ok = true;
} catch (e) {
  result.ok = false;
  result.error = String(e && e.stack || e);
} finally {
  await browser.close();
  rmSync(profile, { recursive: true, force: true });
}
console.log(JSON.stringify(result));
