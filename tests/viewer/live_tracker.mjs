// Live input in the viewer, in headless Chromium (Debian's /usr/bin/chromium through
// playwright-core), one browser for all of it: bad input first (no camera, permission denied, a
// blank camera image, a tracker that sends garbage or stops), then a tracker's movement streamed
// through the server's relay by docs/examples/tracker_client.py (the frame rate measured
// meanwhile), then an exercise followed through the tracker, ended, and its CSV and summary
// taken. Prints one JSON object; tests/deploy/test_live_tracker.py judges it.
//
// usage: node live_tracker.mjs URL OUT_DIR CONFIG_JSON
//   CONFIG_JSON: {"video": "blank.y4m", "python": "/path/python", "client": "docs/examples/tracker_client.py",
//                 "movement": [args...], "exercise": {"plan": {...}, "client": [args...]}}
import { createRequire } from 'node:module';
import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const require = createRequire(new URL('../../persival/deploy/web/package.json', import.meta.url));
const { chromium } = require('playwright-core');

const [url, outDir, configJson] = process.argv.slice(2);
const config = JSON.parse(configJson);
const profile = mkdtempSync(join(tmpdir(), 'persival-chromium-'));
const result = { consoleErrors: [], pageErrors: [] };
// a picture for people to look at: on a busy machine it may time out, which fails nothing
const shot = (target, path) => target.screenshot({ path, timeout: 60000 }).catch((e) => { result.screenshotErrors = [...(result.screenshotErrors || []), String(e).slice(0, 200)]; });
const wsUrl = `${url.replace(/^http/, 'ws').replace(/\/$/, '')}/ws/tracker`;

const browser = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  viewport: { width: 1280, height: 800 },
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
    '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-gpu-vsync', '--disable-frame-rate-limit',
    '--use-fake-device-for-media-stream', '--use-fake-ui-for-media-stream', `--use-file-for-fake-video-capture=${config.video}`],
});

const client = (args) => new Promise((resolve, reject) => {
  const c = spawn(config.python, [config.client, '--url', wsUrl, ...args], { stdio: ['ignore', 'pipe', 'pipe'] });
  let out = '';
  c.stdout.on('data', (d) => { out += d; });
  c.stderr.on('data', (d) => { out += d; });
  c.on('exit', (code) => (code === 0 ? resolve(out) : reject(new Error(`tracker client exited ${code}: ${out}`))));
});
const stats = (page) => page.evaluate(() => window.persival.stats());
const message = (page) => page.evaluate(() => document.getElementById('live-note').textContent);

try {
  const page = await browser.newPage();
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.pageErrors.push(String(e)));
  await page.goto(url, { waitUntil: 'load' });
  await page.evaluate(() => window.persival.ready);
  await page.evaluate(() => window.persival.setBackend('wasm', 'float32'));

  // --- a camera that is missing, refused, then one that shows nobody ---------------------------
  result.camera = {};
  for (const name of ['NotFoundError', 'NotAllowedError']) {
    result.camera[name] = await page.evaluate(async (name) => {
      const real = navigator.mediaDevices.getUserMedia;
      navigator.mediaDevices.getUserMedia = () => Promise.reject(new DOMException('simulated', name));
      try { return await window.persival.live('webcam'); } finally { navigator.mediaDevices.getUserMedia = real; }
    }, name);
    result.camera[name].shown = await message(page);
    result.camera[name].source = (await stats(page)).live.source;
  }
  await page.evaluate(() => window.persival.setAngle(60));
  result.beforeBlank = (await stats(page)).elbowAngle;
  result.blank = await page.evaluate(() => window.persival.live('webcam'));
  const t0 = Date.now();
  while (Date.now() - t0 < 60000) {
    const w = await page.evaluate(() => window.persival.webcam());
    if (w && w.counts.frames >= 3) break;
    await page.waitForTimeout(250);
  }
  result.blankWebcam = await page.evaluate(() => window.persival.webcam());
  result.blankMessage = await message(page);
  result.afterBlank = (await stats(page)).elbowAngle;
  await shot(page, join(outDir, 'live_no_person.png'));
  await page.evaluate(() => window.persival.live('off'));

  // --- the tracker: a movement through the relay, the frame rate meanwhile ----------------------
  await page.evaluate(() => window.persival.live('tracker'));
  await page.waitForFunction(() => /no tracker is connected/.test(document.getElementById('live-note').textContent), null, { timeout: 10000 });
  result.waiting = await message(page);
  const frames = page.evaluate((ms) => new Promise((resolve) => {
    const times = [];
    const step = (t) => { times.push(t); if (t - times[0] < ms) requestAnimationFrame(step); else resolve(times); };
    requestAnimationFrame(step);
  }), config.movementMs);
  result.clientOutput = await client(config.movement);
  result.frameTimes = await frames;
  await page.waitForTimeout(300);
  result.log = await page.evaluate(() => window.persival.liveLog());
  result.afterMovement = await stats(page);
  await shot(page, join(outDir, 'live_tracker.png'));

  // --- a tracker that sends garbage, then quaternions, then stops --------------------------------
  result.garbage = await page.evaluate(async () => {
    const ws = new WebSocket(new URL('ws/tracker?role=publish', document.baseURI).href.replace(/^http/, 'ws'));
    await new Promise((resolve) => { ws.onopen = resolve; });
    const wait = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
    const state = () => window.persival.stats();
    const note = () => document.getElementById('live-note').textContent;
    const out = { before: state().elbowAngle, sent: [], shown: [] };
    for (const text of ['not json', '[1, 2]', '{"elbow_deg": "ninety"}', '{"elbow_deg": 1e9}', '{"elbow_deg": null}',
      '{"upper_arm": [1, 0, 0], "forearm": [1, 0, 0, 0]}', '{"hello": 1}']) {
      ws.send(text);
      await wait(150);
      out.sent.push(text); out.shown.push(note());
    }
    out.after = state().elbowAngle;
    out.counts = state().live.counts;
    // segment orientations: the upper arm hanging, the forearm at 90 degrees, twisted 40 degrees
    const q = (axis, deg) => { const h = (deg * Math.PI) / 360; return [Math.cos(h), ...axis.map((v) => v * Math.sin(h))]; };
    const mul = (a, b) => [a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3], a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
      a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1], a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]];
    const upper = q([0, 1, 0], 90);
    const t = 1000; // this tracker's clock counts from its boot: far behind the last one's, the page starts afresh
    for (let k = 0; k < 40; k++) {
      ws.send(JSON.stringify({ t: t + k / 60, upper_arm: upper, forearm: mul(mul(upper, q([0, 1, 0], -90)), q([1, 0, 0], 40)) }));
      await wait(16);
    }
    await wait(400);
    out.quaternion = { measured: window.persival.stats().live.sample.measured, angle: window.persival.stats().live.sample.angle };
    await wait(1500); // silent, still connected
    out.silent = note();
    ws.close();
    await wait(500);
    out.closed = note();
    out.end = state().elbowAngle;
    return out;
  });

  // --- an exercise followed through the tracker -----------------------------------------------
  await page.evaluate((plan) => {
    for (const [id, v] of [['ex-lo', plan.lo], ['ex-hi', plan.hi], ['ex-period', plan.period], ['ex-reps', plan.reps], ['ex-load', plan.load]]) {
      document.getElementById(id).value = String(v);
    }
  }, config.exercise.plan);
  // the exercise starts with the tracker's first sample (a busy machine starts the client late)
  const before = (await stats(page)).live.sample?.seq ?? 0;
  const running = client(config.exercise.client);
  await page.waitForFunction((seq) => (window.persival.stats().live.sample?.seq ?? 0) > seq, before, { timeout: 20000, polling: 'raf' });
  result.exerciseStart = await page.evaluate(() => window.persival.startExercise());
  await page.waitForTimeout(1000 * config.exercise.plan.period * 0.6);
  result.ghost = (await stats(page)).live.ghost;
  await shot(page, join(outDir, 'exercise_running.png'));
  await running;
  await page.waitForFunction(() => window.persival.exerciseResult() !== null, null, { timeout: 15000 });
  result.exercise = await page.evaluate(() => window.persival.exerciseResult());
  result.exerciseNote = await page.evaluate(() => document.getElementById('ex-note').textContent);
  result.exerciseTable = await page.evaluate(() => document.querySelectorAll('#ex-table tbody tr').length);
  await shot(page, join(outDir, 'exercise_summary.png'));
  await shot(page.locator('#ex-picture'), join(outDir, 'exercise_picture.png'));
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
