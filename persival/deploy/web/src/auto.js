// The automatic mode: measure every (place, tier) once, then take the most accurate one whose
// latency fits the frame budget, preferring this device at equal accuracy (no network to lose).
// While running, a choice that keeps overrunning the budget is demoted and the next one taken.
export const FRAME_BUDGET_MS = 1000 / 60;
// Inference may take half a frame: the other half is colouring, normals and drawing.
export const INFERENCE_BUDGET_MS = FRAME_BUDGET_MS / 2;
const ORDER = ['float32', 'float16', 'int8'];

export async function median(fn, runs = 12, warm = 3) {
  for (let i = 0; i < warm; i++) await fn();
  const t = [];
  for (let i = 0; i < runs; i++) {
    const t0 = performance.now();
    await fn();
    t.push(performance.now() - t0);
  }
  t.sort((a, b) => a - b);
  return t[t.length >> 1];
}

export async function calibrate(engines, tiers, probe) {
  const out = [];
  for (const tier of ORDER.filter((t) => tiers.includes(t))) {
    for (const [place, engine] of Object.entries(engines)) {
      if (!engine) continue;
      try {
        out.push({ place, tier, ms: await median(() => engine.deform(probe, tier)) });
      } catch (e) {
        out.push({ place, tier, ms: Infinity, error: String(e) });
      }
    }
  }
  return out;
}

export function choose(measured, budget = INFERENCE_BUDGET_MS) {
  const rank = (m) => ORDER.indexOf(m.tier) * 2 + (m.place === 'wasm' ? 0 : 1);
  const sorted = [...measured].filter((m) => Number.isFinite(m.ms)).sort((a, b) => rank(a) - rank(b));
  const fits = sorted.find((m) => m.ms <= budget);
  if (fits) return fits;
  return sorted.reduce((best, m) => (m.ms < best.ms ? m : best), sorted[0]);
}

export class Monitor {
  // Exponential average of the latency; after `patience` consecutive overruns the choice is demoted.
  constructor(patience = 90) { this.patience = patience; this.reset(); }
  reset() { this.ema = null; this.over = 0; }
  add(ms, budget = INFERENCE_BUDGET_MS) {
    this.ema = this.ema === null ? ms : 0.9 * this.ema + 0.1 * ms;
    this.over = this.ema > budget ? this.over + 1 : 0;
    return this.over >= this.patience;
  }
}
