// Honest load: the heaviest load the muscles can hold at each angle, from the motion-and-load
// model itself (its moment_deficit_Nmm output is zero exactly where the required moment lies in
// the muscles' reach). Tabulated once at start in one batched run: every whole degree of the
// range x loads from 0 to max_load_kg in steps of LOAD_STEP_KG.
export const LOAD_STEP_KG = 0.025;

export class Holdable {
  // angles: the whole degrees (plus the ends) of the range; kg[i]: largest load held at angles[i]
  constructor(angles, kg, maxLoad) { this.angles = angles; this.kg = kg; this.maxLoad = maxLoad; }

  static async build(engine, meta, [lo, hi]) {
    const m = meta.models.activation_motion;
    const maxLoad = m.max_load_kg ?? 5;
    const angles = [lo];
    for (let a = Math.ceil(lo + 1e-9); a < hi; a++) angles.push(a);
    angles.push(hi);
    const loads = [];
    for (let k = 0; k * LOAD_STEP_KG <= maxLoad + 1e-9; k++) loads.push(k * LOAD_STEP_KG);
    const rows = [];
    for (const a of angles) for (const kg of loads) rows.push([a, 0, 0, kg]);
    const { deficit } = await engine.motionWithDeficit(rows);
    if (!deficit) return null; // a graph without the deficit output: nothing to say about holding
    const kg = angles.map((_, i) => {
      let held = -1; // the last load of the unbroken feasible run from 0 kg
      for (let j = 0; j < loads.length && deficit[i * loads.length + j] === 0; j++) held = loads[j];
      return held; // -1: not even the unloaded arm is held here
    });
    return new Holdable(angles, Float64Array.from(kg), maxLoad);
  }

  // At an angle between two tabulated ones: the smaller of the two (never promise too much).
  at(deg) {
    const a = this.angles;
    if (deg <= a[0]) return this.kg[0];
    if (deg >= a[a.length - 1]) return this.kg[a.length - 1];
    let k = 1;
    while (a[k] < deg) k++;
    return a[k] === deg ? this.kg[k] : Math.min(this.kg[k - 1], this.kg[k]);
  }

  // The unbroken angle interval around `deg` (or, failing that, the widest one) where `load` is held.
  interval(load, deg) {
    const ok = Array.from(this.kg, (v) => v >= load - 1e-9);
    const runs = [];
    for (let i = 0; i < ok.length; i++) {
      if (!ok[i]) continue;
      let j = i;
      while (j + 1 < ok.length && ok[j + 1]) j++;
      runs.push([this.angles[i], this.angles[j]]);
      i = j;
    }
    if (!runs.length) return null;
    return runs.find(([a, b]) => deg >= a && deg <= b) ?? runs.reduce((w, r) => (r[1] - r[0] > w[1] - w[0] ? r : w));
  }
}

export function refusal(load, deg, held) {
  const where = `at ${deg.toFixed(0)}°`;
  if (held < 0) return `${where} not even the unloaded arm can be held (the model's muscles cannot reach that moment)`;
  return `${load.toFixed(1)} kg cannot be held ${where}: the muscles hold at most ${held.toFixed(2)} kg there`;
}
