// `persival bench viewer`: the viewer in headless Chromium (software GL, SwiftShader), the arm
// flexing and extending so the angle, the state and every vertex change every frame, and where
// the frame's time goes. Prints one JSON object (persival/deploy/bench_viewer.py reads it).
//
// usage: node bench.mjs '{"url": ..., "width": 1280, "height": 800, "seconds": 8, "trace": true}'
// Two phases: "shipped" (the page as it is, its resolution adapting to the frame rate) and
// "full resolution" (render scale held at 1), each after a warm-up. The profile: the page's own
// performance.now() breakdown (window.persival.profile) and, with "trace", a Chrome trace of the
// shipped phase summarised per thread (busy ms per frame) and per event (self time).
import { createRequire } from 'node:module';
import { readdirSync, readFileSync } from 'node:fs';

const require = createRequire(import.meta.url);
const { chromium } = require('playwright-core');

const opts = { width: 1280, height: 800, seconds: 8, warmup: 3, trace: true, ...JSON.parse(process.argv[2]) };
const CATEGORIES = ['toplevel', 'devtools.timeline', 'disabled-by-default-devtools.timeline', 'v8.execute', 'blink',
  'cc', 'gpu', 'viz', 'disabled-by-default-gpu.service'];

// Busy time and self time per thread from complete ("X") events; nested events are not counted twice.
function summariseTrace(events, frames) {
  const names = new Map();
  for (const e of events) {
    if (e.ph === 'M' && e.name === 'thread_name') names.set(`${e.pid}:${e.tid}`, e.args.name);
  }
  const threads = new Map();
  for (const e of events) {
    if (e.ph !== 'X' || !(e.dur > 0)) continue;
    const key = `${e.pid}:${e.tid}`;
    if (!threads.has(key)) threads.set(key, []);
    threads.get(key).push({ name: e.name, ts: e.ts, end: e.ts + e.dur, dur: e.dur, child: 0 });
  }
  const out = [];
  for (const [key, list] of threads) {
    list.sort((a, b) => a.ts - b.ts || b.dur - a.dur);
    const stack = [], self = new Map();
    let busy = 0, openEnd = -Infinity;
    for (const e of list) {
      while (stack.length && stack[stack.length - 1].end <= e.ts) stack.pop();
      if (stack.length && e.end <= stack[stack.length - 1].end) stack[stack.length - 1].child += e.dur;
      stack.push(e);
      if (e.ts >= openEnd) { busy += e.dur; openEnd = e.end; } else if (e.end > openEnd) { busy += e.end - openEnd; openEnd = e.end; }
    }
    for (const e of list) self.set(e.name, (self.get(e.name) || 0) + e.dur - e.child);
    const top = [...self].sort((a, b) => b[1] - a[1]).slice(0, 6)
      .map(([name, us]) => ({ name, msPerFrame: us / 1000 / frames }));
    out.push({ thread: names.get(key) || key, busyMsPerFrame: busy / 1000 / frames, top });
  }
  return out.sort((a, b) => b.busyMsPerFrame - a.busyMsPerFrame).slice(0, 6);
}

// CPU time (ms) of every process below this one (Chromium and its helpers, Linux /proc): the work a frame costs,
// which, unlike the frame rate, hardly depends on what else the machine is doing.
function cpuMs(root) {
  if (!root) return NaN;
  const tick = 100; // USER_HZ on Linux
  const procs = new Map();
  for (const d of readdirSync('/proc')) {
    if (!/^\d+$/.test(d)) continue;
    try {
      const stat = readFileSync(`/proc/${d}/stat`, 'utf8');
      const f = stat.slice(stat.lastIndexOf(')') + 2).split(' ');
      procs.set(Number(d), { ppid: Number(f[1]), cpu: Number(f[11]) + Number(f[12]) });
    } catch { /* gone */ }
  }
  let total = 0;
  for (const [pid, p] of procs) {
    let q = pid;
    while (q && q !== root) q = procs.get(q)?.ppid;
    if (q === root && pid !== root) total += p.cpu;
  }
  return (total * 1000) / tick;
}

async function phase(page, browser, name, trace) {
  await page.waitForTimeout(opts.warmup * 1000);
  await page.evaluate(() => window.persival.profile(true));
  if (trace) await browser.startTracing(page, { categories: CATEGORIES });
  const cpu0 = cpuMs(process.pid);
  await page.waitForTimeout(opts.seconds * 1000);
  const profile = await page.evaluate(() => window.persival.profile());
  profile.cpuMsPerFrame = (cpuMs(process.pid) - cpu0) / Math.max(profile.frames, 1);
  const stats = await page.evaluate(() => window.persival.stats());
  const result = { phase: name, ...profile, backend: stats.backend, tier: stats.tier, viewAlongHinge: stats.viewAlongHinge };
  if (trace) {
    const buffer = await browser.stopTracing();
    result.trace = summariseTrace(JSON.parse(buffer.toString()).traceEvents, profile.frames);
  }
  return result;
}

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
    '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    // frames are not tied to a 60 Hz display: the rate is what the page sustains
    '--disable-gpu-vsync', '--disable-frame-rate-limit'],
});
const result = { width: opts.width, height: opts.height, seconds: opts.seconds, phases: [], consoleErrors: [] };
try {
  const page = await browser.newPage({ viewport: { width: opts.width, height: opts.height } });
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.consoleErrors.push(String(e)));
  await page.goto(opts.url, { waitUntil: 'load' });
  await page.evaluate(() => window.persival.ready);
  result.chromium = browser.version();
  if (opts.screenshot) { // the default view, as a user first sees it (for the report)
    await page.waitForTimeout(1000);
    await page.screenshot({ path: opts.screenshot });
  }
  await page.evaluate(() => window.persival.play(true)); // the angle changes every frame from here on
  result.phases.push(await phase(page, browser, 'shipped (adaptive)', opts.trace));
  await page.evaluate(() => window.persival.viewer.scene.fixScale(1));
  result.phases.push(await phase(page, browser, 'full resolution', false));
  result.ok = true;
} catch (e) {
  result.ok = false;
  result.error = String((e && e.stack) || e);
} finally {
  await browser.close();
}
console.log(JSON.stringify(result));
