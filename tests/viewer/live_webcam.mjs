// The live webcam in headless Chromium: a fake camera plays a photograph of a person (a .y4m the
// test builds), the page's pose tracker finds her, and the arm follows her right elbow. Prints one
// JSON object: per tracked frame the tracker's angles (image plane and 3-D) and landmarks, the
// live and drawn angles, the messages, console errors. tests/deploy/test_live_webcam.py judges it.
//
// usage: node live_webcam.mjs URL OUT_DIR CONFIG_JSON   (CONFIG_JSON: {"video": "photo.y4m", "frames": 12})
import { createRequire } from 'node:module';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const require = createRequire(new URL('../../persival/deploy/web/package.json', import.meta.url));
const { chromium } = require('playwright-core');

const [url, outDir, configJson] = process.argv.slice(2);
const config = JSON.parse(configJson);
const profile = mkdtempSync(join(tmpdir(), 'persival-chromium-'));
const result = { consoleErrors: [], pageErrors: [], frames: [] };
// a picture for people to look at: on a busy machine it may time out, which fails nothing
const shot = (target, path) => target.screenshot({ path, timeout: 60000 }).catch((e) => { result.screenshotErrors = [...(result.screenshotErrors || []), String(e).slice(0, 200)]; });

const browser = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  viewport: { width: 1280, height: 800 },
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
    '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    '--use-fake-device-for-media-stream', '--use-fake-ui-for-media-stream', `--use-file-for-fake-video-capture=${config.video}`],
});

try {
  const page = await browser.newPage();
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.pageErrors.push(String(e)));
  await page.goto(url, { waitUntil: 'load' });
  await page.evaluate(() => window.persival.ready);
  await page.evaluate(() => window.persival.setBackend('wasm', 'float32'));
  // the photo's hand measurement lies in the image plane: compare like with like (the 3-D angle
  // is recorded as well)
  await page.selectOption('#live-geometry', config.geometry || 'image');
  // her wrist, at the picture's bottom edge under the glove's cuff, rates 0.2 to 0.6 in visibility:
  // the threshold lowered as a user would when the arm in full view is reported "not in view"
  await page.evaluate((v) => { const el = document.getElementById('live-visibility'); el.value = String(v);
    el.dispatchEvent(new Event('input')); }, config.visibility ?? 0.5);
  result.start = await page.evaluate(() => window.persival.live('webcam'));
  const t0 = Date.now();
  result.messages = [];
  while (Date.now() - t0 < 1000 * (config.seconds || 60)) {
    const w = await page.evaluate(() => ({ webcam: window.persival.webcam(), message: window.persival.stats().live.message }));
    if (result.messages[result.messages.length - 1] !== w.message) result.messages.push(w.message);
    if (w.webcam && w.webcam.history.length >= config.frames) break;
    await page.waitForTimeout(200);
  }
  await page.waitForTimeout(300); // the last sample drawn
  const webcam = await page.evaluate(() => window.persival.webcam());
  result.counts = webcam.counts;
  result.frames = webcam.history; // every frame with a person: the tracker's angles, visibility, landmarks
  result.final = await page.evaluate(() => window.persival.stats());
  result.log = await page.evaluate(() => window.persival.liveLog());
  result.privacy = await page.evaluate(() => document.querySelector('#live .note').textContent);
  result.preview = await page.evaluate(() => { const c = document.getElementById('webcam-view'); return { hidden: c.hidden, width: c.width, height: c.height }; });
  await shot(page, join(outDir, 'live_webcam.png'));
  await shot(page.locator('#webcam-view'), join(outDir, 'live_webcam_preview.png'));
  await page.evaluate(() => window.persival.live('off'));
  result.ok = true;
} catch (e) {
  result.ok = false;
  result.error = String((e && e.stack) || e);
} finally {
  await browser.close();
  rmSync(profile, { recursive: true, force: true });
}
console.log(JSON.stringify(result));
