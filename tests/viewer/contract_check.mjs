// The deployment contract in the page (SPEC 9), in headless Chromium (Debian's /usr/bin/chromium
// through playwright-core): for each (angle, load) request, the activations the page computes for
// it (window.persival.activationsFor, what setAngle draws) and the angle its in-browser
// deformation model then shows with the same load. Prints one JSON object; tests/deploy/test_contract.py judges it.
//
// usage: node contract_check.mjs URL REQUESTS_JSON   (REQUESTS_JSON: [[angle_deg, load_kg], ...])
import { createRequire } from 'node:module';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const require = createRequire(new URL('../../persival/deploy/web/package.json', import.meta.url));
const { chromium } = require('playwright-core');

const [url, requestsJson] = process.argv.slice(2);
const profile = mkdtempSync(join(tmpdir(), 'persival-chromium-'));
const result = { consoleErrors: [], pageErrors: [] };
const browser = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader'],
});
try {
  const page = await browser.newPage();
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.pageErrors.push(String(e)));
  await page.goto(url, { waitUntil: 'load' });
  await page.evaluate(() => window.persival.ready);
  result.answers = await page.evaluate(async (requests) => {
    const out = [];
    for (const [deg, load] of requests) {
      const a = Array.from(await window.persival.activationsFor(deg, load));
      out.push({ activations: a, angle: await window.persival.predictAngle(a, load) });
    }
    return out;
  }, JSON.parse(requestsJson));
  // and once through setAngle, the hook a user's page drives: the drawn angle
  const [deg, load] = JSON.parse(requestsJson)[0];
  await page.evaluate(([d, l]) => window.persival.setAngle(d, l), [deg, load]);
  result.setAngle = await page.evaluate(() => window.persival.stats());
  result.ok = true;
} catch (e) {
  result.ok = false;
  result.error = String(e && e.stack ? e.stack : e);
} finally {
  await browser.close();
  rmSync(profile, { recursive: true, force: true });
}
console.log(JSON.stringify(result));
