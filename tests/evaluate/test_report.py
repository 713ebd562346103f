"""`persival report`: one self-contained page with every table and figure, opened in headless Chromium.

Reuses the session's tiny run of tests/evaluate/test_evaluate.py. The browser check (Debian's
/usr/bin/chromium through playwright-core from the web viewer's node_modules) loads the page
from disk at 1280 px, counts tables and decoded images, checks that no table is wider than its
box, records console errors and takes a full-page screenshot ($PERSIVAL_REPORT_SHOTS or the
test's tmp folder).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from test_evaluate import TABLES, evaluated, tiny_run  # noqa: F401  (the session's run)
from typer.testing import CliRunner

pytestmark = pytest.mark.slow  # a shared fixture of this module takes minutes (make test-fast skips it)

ROOT = Path(__file__).resolve().parents[2]
WEB = ROOT / "persival" / "deploy" / "web"
CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")

CHECK = r"""
import { createRequire } from 'node:module';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const [webPackage, url, shot] = process.argv.slice(2);
const { chromium } = createRequire(webPackage)('playwright-core');
const profile = mkdtempSync(join(tmpdir(), 'persival-report-'));
const result = { consoleErrors: [], pageErrors: [], failedRequests: [] };
const browser = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium', headless: true,
  viewport: { width: 1280, height: 900 }, args: ['--headless', '--no-sandbox', '--disable-gpu'] });
try {
  const page = await browser.newPage();
  page.on('console', (m) => { if (m.type() === 'error') result.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => result.pageErrors.push(String(e)));
  page.on('requestfailed', (r) => result.failedRequests.push(r.url().slice(0, 120)));
  await page.goto(url, { waitUntil: 'load' });
  Object.assign(result, await page.evaluate(() => ({
    tables: [...document.querySelectorAll('section.table')].map((s) => s.id),
    images: [...document.images].map((i) => ({ alt: i.alt, w: i.naturalWidth, h: i.naturalHeight })),
    // a table wider than its box hides columns behind a scroll bar at 1280 px
    wide: [...document.querySelectorAll('.scroll')].filter((d) => d.scrollWidth > d.clientWidth + 1)
      .map((d) => ({ table: d.closest('section')?.id, width: d.scrollWidth, box: d.clientWidth })),
    pageWidth: document.documentElement.scrollWidth })));
  await page.screenshot({ path: shot, fullPage: true });
  result.ok = true;
} catch (e) { result.ok = false; result.error = String(e); }
await browser.close();
rmSync(profile, { recursive: true, force: true });
console.log(JSON.stringify(result));
"""

missing = [what for what, ok in [("chromium", Path(CHROMIUM).exists()), ("node", shutil.which("node") is not None),
                                 ("playwright-core (make web)", (WEB / "node_modules" / "playwright-core").is_dir())]
           if not ok]


@pytest.fixture(scope="module")
def report(evaluated, tiny_run):  # noqa: F811
    from persival.cli import app

    result = CliRunner().invoke(app, ["report", "--run", str(tiny_run)])
    assert result.exit_code == 0, result.output
    return tiny_run / "report" / "index.html"


def test_report_is_self_contained_with_every_table_and_figure(report, tiny_run):  # noqa: F811
    page = report.read_text()
    for name in (*TABLES, "bench_nn"):
        assert f'id="table-{name}"' in page, name
    images = re.findall(r'<img alt="[^"]*" src="data:image/png;base64,', page)
    pngs = {p.name for p in (tiny_run / "evaluate").glob("*.png")}
    assert len(images) >= len(pngs) >= 4
    assert not re.search(r'(src|href)="(?!data:|#)', page), "the page links a file: not self-contained"
    for needle in ("cpu_count", "platform", "persival evaluate", "torch", "analytic stand-in"):
        assert needle in page, needle


def test_results_json_has_every_table(report):
    results = json.loads((report.parent / "results.json").read_text())
    assert set(results["tables"]) == {*TABLES, "bench_nn"}
    assert results["provenance"]["machine"]["cpu_count"] >= 1 and results["configuration"]["network_pod"]["config"]
    assert results["tables"]["random_angles"]["paper"][0]["max MaxAE_mm"] == 3.75


@pytest.mark.skipif(bool(missing), reason=f"needs {', '.join(missing)}")
def test_report_opens_in_headless_chromium(report, tmp_path):
    shots = Path(os.environ.get("PERSIVAL_REPORT_SHOTS") or tmp_path)
    shots.mkdir(parents=True, exist_ok=True)
    script = tmp_path / "report_check.mjs"
    script.write_text(CHECK)
    proc = subprocess.run(["node", str(script), str(WEB / "package.json"), report.resolve().as_uri(),
                           str(shots / "report.png")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["ok"], result.get("error")
    assert result["consoleErrors"] == [] and result["pageErrors"] == [] and result["failedRequests"] == []
    assert {t.removeprefix("table-") for t in result["tables"]} == {*TABLES, "bench_nn"}
    assert result["wide"] == [] and result["pageWidth"] <= 1280, f"wider than 1280 px: {result['wide']}"
    assert result["images"] and all(i["w"] > 100 and i["h"] > 100 for i in result["images"])
    print(f"\nreport: {len(result['tables'])} tables, {len(result['images'])} figures, screenshot {shots / 'report.png'}")
