// A physiotherapy session in the viewer, in headless Chromium (Debian's /usr/bin/chromium through
// playwright-core): the default view, an honest load (a heavy one refused, the arm stays), the
// activation colours, a recorded movement opened, played at its speed with the live graphs,
// and the frame rate meanwhile. Prints one JSON object; tests/test_viewer.py judges it.
//
// usage: node viewer_session.mjs URL OUT_DIR CONFIG_JSON
//   CONFIG_JSON: {"recording": "<csv text>", "name": "cycle.csv", "angle": 90, "light": 1, "heavyOver": 1.5}
import { createRequire } from 'node:module';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const require = createRequire(new URL('../../persival/deploy/web/package.json', import.meta.url));
const { chromium } = require('playwright-core');

const [url, outDir, configJson] = process.argv.slice(2);
const config = JSON.parse(configJson);
const profile = mkdtempSync(join(tmpdir(), 'persival-chromium-'));
const result = { consoleErrors: [], pageErrors: [] };

const browser = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  viewport: { width: 1280, height: 800 },
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
    '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-gpu-vsync', '--disable-frame-rate-limit'],
});

const stats = (page) => page.evaluate(() => window.persival.stats());
// frames the page draws in `ms` (requestAnimationFrame callbacks), a rate independent of the HUD
const frameRate = (page, ms) => page.evaluate((ms) => new Promise((resolve) => {
  let n = 0;
  const t0 = performance.now();
  const step = (t) => { n++; if (t - t0 < ms) requestAnimationFrame(step); else resolve((1000 * n) / (t - t0)); };
  requestAnimationFrame(step);
}), ms);

try {
  const page = await browser.newPage();
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.pageErrors.push(String(e)));
  await page.goto(url, { waitUntil: 'load' });
  await page.evaluate(() => window.persival.ready);
  await page.evaluate(() => window.persival.setBackend('wasm', 'float32'));
  await page.waitForTimeout(500);
  result.initial = await stats(page);
  result.legend = await page.evaluate(() => document.querySelector('#legend .legend-title').textContent);
  await page.screenshot({ path: join(outDir, 'default_view.png') });

  // Honest load: hold the angle with a light load, ask for more than the muscles hold there.
  const { angle, light, heavyOver } = config;
  result.loadMax = await page.evaluate(() => Number(document.getElementById('load').max));
  result.setAngle = await page.evaluate((a) => window.persival.setAngle(a), angle);
  result.light = await page.evaluate((kg) => window.persival.setLoad(kg), light);
  result.beforeHeavy = await stats(page);
  const heavy = result.beforeHeavy.held + heavyOver;
  result.heavy = { kg: heavy, ...(await page.evaluate((kg) => window.persival.setLoad(kg), heavy)) };
  await page.waitForTimeout(400);
  result.afterHeavy = await stats(page);
  result.loadNote = await page.evaluate(() => document.getElementById('load-note').textContent);
  await page.screenshot({ path: join(outDir, 'load_refused.png') });
  // an angle where the light load is not held is refused too, with that angle's number
  result.farAngle = await page.evaluate((kg) => {
    const [lo, hi] = window.persival.viewer.range;
    for (let a = Math.floor(hi); a >= lo; a -= 1) if (window.persival.held(a) < kg) return a;
    return null;
  }, light);
  if (result.farAngle !== null) result.farAngleResult = await page.evaluate((a) => window.persival.setAngle(a), result.farAngle);

  // Play with the load: the cycle stays where the load is held and never freezes.
  await page.evaluate(() => window.persival.play(true));
  const angles = [];
  for (let i = 0; i < 12; i++) { await page.waitForTimeout(250); angles.push((await stats(page)).angle); }
  result.play = { angles, ...(await stats(page)) };
  await page.evaluate(() => window.persival.play(false));

  // Activation colours: each muscle in one colour by its activation.
  await page.evaluate(() => window.persival.setColourMode(true));
  result.colourStats = await stats(page);
  await page.screenshot({ path: join(outDir, 'activation_colours.png') });
  await page.evaluate(() => window.persival.setColourMode(false));
  await page.evaluate(() => window.persival.setLoad(0));

  // A recorded movement: open, play at its speed, the graphs follow; the frame rate meanwhile.
  result.opened = await page.evaluate(([text, name]) => window.persival.openRecording(text, name), [config.recording, config.name]);
  const progress = [];
  const t0 = Date.now();
  let fpsDuring = null;
  while (Date.now() - t0 < 1000 * (result.opened.duration + 6)) {
    const s = await stats(page);
    progress.push({ t: Date.now() - t0, played: s.recording.played, updates: s.recording.graphUpdates, fps: s.fps });
    if (!s.recording.playing) break;
    if (fpsDuring === null && s.recording.played > 0.25 * s.recording.frames) {
      await page.screenshot({ path: join(outDir, 'recording.png') });
      fpsDuring = await frameRate(page, 1000);
    }
    await page.waitForTimeout(200);
  }
  result.recording = { progress, fpsDuring, ...(await stats(page)).recording };
  result.curves = await page.evaluate(() => {
    const r = window.persival.viewer.player.rec;
    return { target: Array.from(r.target), achieved: Array.from(r.achieved), time: Array.from(r.time) };
  });
  await page.screenshot({ path: join(outDir, 'recording_end.png') });
  result.ok = true;
} catch (e) {
  result.ok = false;
  result.error = String((e && e.stack) || e);
} finally {
  await browser.close();
  rmSync(profile, { recursive: true, force: true });
}
console.log(JSON.stringify(result));
