// Recorded elbow movements in the browser: the same reading, resampling and smoothing as
// persival/deploy/recording.py (`persival motion play`), so a file plays here as it does there.
// CSV: header row, time (s), elbow angle (deg), optional load (kg). OpenSim .mot/.sto: header up
// to `endheader` (inDegrees=no: radians), then labelled whitespace-separated columns.
export const RATE_HZ = 100;
export const SIGMA_S = 0.025;
const TIME_NAMES = ['time', 'time_s', 't', 'time(s)', 'time (s)'];
const LOAD_NAMES = ['load', 'load_kg', 'load (kg)', 'load(kg)'];
const ANGLE_NAMES = ['angle', 'angle_deg', 'angle (deg)'];

function pickAngle(names, wanted) {
  const lower = names.map((n) => n.trim().toLowerCase());
  if (wanted) {
    const k = lower.indexOf(wanted.trim().toLowerCase());
    if (k < 0) throw new Error(`no column ${wanted} (columns: ${names.join(', ')})`);
    return k;
  }
  let elbow = lower.flatMap((n, k) => (n.includes('elbow') && n.includes('flex') ? [k] : []));
  if (!elbow.length) elbow = lower.flatMap((n, k) => (n.includes('elbow') ? [k] : []));
  if (elbow.length > 1) { // both arms: the right one (r_elbow_flex, elbow_flex_r)
    const right = elbow.filter((k) => /(^r_|_r$|right)/.test(lower[k]));
    if (right.length === 1) elbow = right;
  }
  if (elbow.length === 1) return elbow[0];
  const plain = lower.flatMap((n, k) => (ANGLE_NAMES.includes(n) ? [k] : []));
  if (!elbow.length && plain.length === 1) return plain[0];
  const found = elbow.length ? `several (${elbow.map((k) => names[k]).join(', ')})` : 'none';
  throw new Error(`which column is the elbow angle? by name: ${found} (columns: ${names.join(', ')})`);
}

export function parseRecording(text, fileName = 'recording', column = null) {
  const lines = text.split(/\r?\n/);
  let inDegrees = true, start = 0, format = 'csv';
  const end = lines.slice(0, 200).findIndex((l) => l.trim().toLowerCase() === 'endheader');
  if (/\.(mot|sto)$/i.test(fileName) || end >= 0) {
    format = 'opensim';
    if (end < 0) throw new Error(`${fileName}: an OpenSim motion file needs a header ending in a line 'endheader'`);
    for (const l of lines.slice(0, end)) {
      const [k, v] = l.split('=');
      if (v !== undefined && k.trim().toLowerCase() === 'indegrees') inDegrees = v.trim().toLowerCase() !== 'no';
    }
    start = end + 1;
  }
  const body = lines.slice(start).filter((l) => l.trim() && !l.trim().startsWith('#'));
  if (!body.length) throw new Error(`${fileName}: no column labels and no data`);
  const delimiter = format === 'opensim' ? null : [',', ';', '\t'].find((d) => body[0].includes(d)) || ',';
  const split = (l) => (delimiter ? l.split(delimiter) : l.trim().split(/\s+/));
  const names = split(body[0]).map((n) => n.trim());
  const lower = names.map((n) => n.toLowerCase());
  const tCol = lower.findIndex((n) => TIME_NAMES.includes(n));
  if (tCol < 0) throw new Error(`${fileName}: no time column (a column named time or time_s; columns: ${names.join(', ')})`);
  const aCol = pickAngle(names, column);
  const lCol = lower.findIndex((n) => LOAD_NAMES.includes(n));
  const time = [], angle = [], load = [];
  for (let r = 1; r < body.length; r++) {
    const cells = split(body[r]);
    const get = (j) => {
      const v = Number(cells[j]);
      if (cells[j] === undefined || cells[j].trim() === '' || !Number.isFinite(v)) {
        throw new Error(`${fileName}: row ${r}: ${names[j]} = ${cells[j]} is not a finite number`);
      }
      return v;
    };
    time.push(get(tCol));
    angle.push(inDegrees ? get(aCol) : (get(aCol) * 180) / Math.PI);
    if (lCol >= 0) load.push(get(lCol));
  }
  if (time.length < 2) throw new Error(`${fileName}: ${time.length} frame(s); a movement needs at least 2`);
  for (let k = 1; k < time.length; k++) {
    if (!(time[k] > time[k - 1])) throw new Error(`${fileName}: time does not increase at frame ${k + 1} (${time[k - 1]} s, then ${time[k]} s)`);
  }
  if (load.some((v) => v < 0)) throw new Error(`${fileName}: a load is negative`);
  return { time, angle, load: lCol >= 0 ? load : null, column: names[aCol], format, inDegrees, file: fileName };
}

// Gaussian-weighted local linear regression of y(t) at the grid times (window +-4 sigma).
function localLinear(t, y, grid, sigma) {
  const out = new Float64Array(grid.length);
  let a = 0;
  for (let k = 0; k < grid.length; k++) {
    const g = grid[k];
    while (a < t.length && t[a] < g - 4 * sigma) a++;
    let b = a;
    while (b < t.length && t[b] <= g + 4 * sigma) b++;
    let lo = Math.max(0, Math.min(a, t.length - 2)), hi = Math.max(b, lo + 2);
    let s0 = 0, s1 = 0, s2 = 0, r0 = 0, r1 = 0;
    for (let i = lo; i < hi; i++) {
      const dt = t[i] - g, w = Math.exp(-0.5 * (dt / sigma) ** 2);
      s0 += w; s1 += w * dt; s2 += w * dt * dt; r0 += w * y[i]; r1 += w * dt * y[i];
    }
    const det = s0 * s2 - s1 * s1;
    out[k] = det > 1e-12 * s0 * s2 ? (s2 * r0 - s1 * r1) / det : r0 / s0;
  }
  return out;
}

// numpy.gradient with second-order ends
function gradient(y, dt) {
  const n = y.length, g = new Float64Array(n);
  if (n < 2) return g;
  if (n === 2) { g[0] = g[1] = (y[1] - y[0]) / dt; return g; }
  for (let k = 1; k < n - 1; k++) g[k] = (y[k + 1] - y[k - 1]) / (2 * dt);
  g[0] = (-3 * y[0] + 4 * y[1] - y[2]) / (2 * dt);
  g[n - 1] = (3 * y[n - 1] - 4 * y[n - 2] + y[n - 3]) / (2 * dt);
  return g;
}

export function prepareRecording(rec, [lo, hi], loadKg = null) {
  const t = rec.time, n = Math.floor((t[t.length - 1] - t[0]) * RATE_HZ + 1e-9) + 1;
  const sigma = Math.max(SIGMA_S, median(t.slice(1).map((v, k) => v - t[k])));
  const grid = Float64Array.from({ length: n }, (_, k) => t[0] + k / RATE_HZ);
  const smooth = localLinear(t, rec.angle, grid, sigma);
  const clamped = Array.from(smooth, (v) => v < lo || v > hi);
  if (clamped.every(Boolean)) {
    const min = Math.min(...rec.angle), max = Math.max(...rec.angle);
    throw new Error(`${rec.file}: no frame lies inside the model's reachable range ${lo.toFixed(1)} to ${hi.toFixed(1)} deg ` +
      `(the recording's ${rec.column} spans ${min.toFixed(1)} to ${max.toFixed(1)} deg)`);
  }
  // velocity and acceleration from the recording itself, not from the clamped angle (no corner
  // where a recording enters the range moving)
  const velocity = gradient(smooth, 1 / RATE_HZ);
  const acceleration = gradient(velocity, 1 / RATE_HZ);
  const target = smooth.map((v) => Math.min(hi, Math.max(lo, v)));
  let load;
  if (loadKg !== null && loadKg !== undefined) load = new Float64Array(n).fill(loadKg);
  else if (rec.load) load = grid.map((g) => interp(g, t, rec.load));
  else load = new Float64Array(n);
  return { time: grid, target, velocity, acceleration, load, clamped, sigma,
    framesClamped: clamped.filter(Boolean).length, duration: grid[n - 1] - grid[0] };
}

function median(values) {
  const s = [...values].sort((x, y) => x - y), m = s.length >> 1;
  return s.length % 2 ? s[m] : 0.5 * (s[m - 1] + s[m]);
}

function interp(x, xs, ys) {
  if (x <= xs[0]) return ys[0];
  if (x >= xs[xs.length - 1]) return ys[ys.length - 1];
  let k = 1;
  while (xs[k] < x) k++;
  const f = (x - xs[k - 1]) / (xs[k] - xs[k - 1]);
  return ys[k - 1] * (1 - f) + ys[k] * f;
}
